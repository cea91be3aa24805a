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

// a + (b - a) t, as the CPU's trilinear and texture lerps: exactly a where b is a (mix's
// a (1 - t) + b t is not), so that voxels of no segment leave the transfer function's colour
// as it is.
fn lerp3(a: vec3<f32>, b: vec3<f32>, t: f32) -> vec3<f32> {
    return a + (b - a) * t;
}

// 8-bit sRGB's curve undone, as raystream-cpu's srgb_to_linear.
fn srgb_to_linear(s: f32) -> f32 {
    let c = clamp(s, 0.0, 1.0);
    if c <= 0.04045 {
        return c / 12.92;
    }
    return pow((c + 0.055) / 1.055, 2.4);
}

// Linear [0, 1] → 8-bit sRGB, as raystream-cpu's Image::to_srgb8.
fn srgb8(x: f32) -> u32 {
    let c = clamp(x, 0.0, 1.0);
    var s = 12.92 * c;
    if c > 0.0031308 {
        s = 1.055 * pow(c, 1.0 / 2.4) - 0.055;
    }
    return u32(s * 255.0 + 0.5);
}
