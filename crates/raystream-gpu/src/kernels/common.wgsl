// Pieces the render and volume kernels share.

// The same hash as raystream-cpu's `jitter`.
fn jitter(p: u32, s: u32, k: u32) -> f32 {
    var x = (p * 0x9E3779B9u) ^ (s * 0x85EBCA6Bu) ^ (k * 0xC2B2AE35u);
    x ^= x >> 16u;
    x *= 0x7FEB352Du;
    x ^= x >> 15u;
    x *= 0x846CA68Bu;
    x ^= x >> 16u;
    return f32(x >> 8u) / 16777216.0;
}
