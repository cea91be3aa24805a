// The film's 64-bit fixed-point sums (lo, hi words per channel, 6 words a pixel) as one f32 per
// channel, on the GPU: half the bytes to read back, and no 64-bit work on the host. The host
// scales by 1 / (FILM_SCALE * spp).

@group(0) @binding(0) var<storage, read> film: array<u32>;
@group(0) @binding(1) var<storage, read_write> image: array<f32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn resolve_film(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let p = gid.x + gid.y * groups.x * WORKGROUP_SIZE;
    if 6u * p + 5u >= arrayLength(&film) || 3u * p + 2u >= arrayLength(&image) {
        return;
    }
    for (var c = 0u; c < 3u; c++) {
        let lo = film[6u * p + 2u * c];
        let hi = film[6u * p + 2u * c + 1u];
        image[3u * p + c] = f32(hi) * 4294967296.0 + f32(lo);
    }
}

// The film as a viewer shows it: 8-bit sRGB, 3 bytes a pixel (4 pixels in 3 words, one thread
// each), each channel's sum scaled by `pack.scale` = 1 / (FILM_SCALE · spp): a quarter of the
// resolved film's bytes to read back, and nothing left to convert on the host.
struct PackParams {
    scale: f32,
    pixels: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(2) var<storage, read_write> packed: array<u32>;
@group(0) @binding(3) var<uniform> pack: PackParams;

@compute @workgroup_size(WORKGROUP_SIZE)
fn resolve_film_srgb8(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let g = gid.x + gid.y * groups.x * WORKGROUP_SIZE;
    if 4u * g >= pack.pixels || 3u * g + 2u >= arrayLength(&packed) {
        return;
    }
    var w = array<u32, 3>(0u, 0u, 0u);
    for (var k = 0u; k < 4u; k++) {
        let p = 4u * g + k;
        if p >= pack.pixels || 6u * p + 5u >= arrayLength(&film) {
            break;
        }
        for (var c = 0u; c < 3u; c++) {
            let lo = film[6u * p + 2u * c];
            let hi = film[6u * p + 2u * c + 1u];
            let byte = 3u * k + c;
            w[byte / 4u] |= srgb8((f32(hi) * 4294967296.0 + f32(lo)) * pack.scale) << (8u * (byte % 4u));
        }
    }
    packed[3u * g] = w[0];
    packed[3u * g + 1u] = w[1];
    packed[3u * g + 2u] = w[2];
}
