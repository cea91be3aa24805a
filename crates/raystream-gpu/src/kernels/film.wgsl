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
