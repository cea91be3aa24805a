// A CT volume in a mesh scene: the render kernels' volume stages, as raystream-cpu's medium.rs
// (the reference). Follows render.wgsl and volume.wgsl in one module.
//
//   intersect_closest → march_volume → handle_misses → shade_hits → prepare_shadows
//   → intersect_any → attenuate_shadows → accumulate → advance
//
// `march_volume` composites each queued ray's segment up to its hit (or out of the volume) into
// its pixel and scales the ray's weight by the segment's transmittance; `attenuate_shadows`
// scales each unblocked shadow ray's radiance by the volume's transmittance toward its light.
// Volume samples are lit by the scene's lights through the light grids the CPU computed (their
// shadow rays meet both the volume and the meshes), one grid per light, back to back.

struct MediumParams {
    // World (LPS) → continuous index: rows of the linear map, and the origin.
    to_index0: vec3<f32>,
    step: f32,
    to_index1: vec3<f32>,
    light_count: u32,
    to_index2: vec3<f32>,
    skip_empty: u32,
    origin: vec3<f32>,
    opacity_count: u32,
    dims: vec3<u32>,
    color_count: u32,
    bricks: vec3<u32>,
    shadows: u32,
    // ambient, diffuse, specular, specular power
    shading: vec4<f32>,
    light_dims: vec3<u32>,
    // Values per light grid.
    grid_points: u32,
    // Interpolation::kernel_code of SceneVolume::interpolation: 0 trilinear, 1 cubic B-spline, 2
    // its interpolating form (coefficients in the first channel, the voxels in the second).
    interpolation: u32,
    // 1: samples take the colours of a segmentation (segment_labels, segment_colours) in place
    // of the transfer function's (SceneVolume::segments).
    segments: u32,
    pad1: u32,
    pad2: u32,
}

// Group 3 binding 0 is the dispatch arguments of render.wgsl's control kernels.
@group(3) @binding(1) var<uniform> dp: MediumParams;
@group(3) @binding(2) var volume: texture_3d<f32>;
@group(3) @binding(3) var trilinear: sampler;
@group(3) @binding(4) var<storage, read> opacity_points: array<vec2<f32>>;
@group(3) @binding(5) var<storage, read> color_points: array<vec4<f32>>;
@group(3) @binding(6) var<storage, read> brick_visible: array<u32>;
@group(3) @binding(7) var<storage, read> light_values: array<f32>;
// A segmentation on the volume's grid (raystream_cpu::segments::SegmentColours): each voxel's
// label, and per label its linear colour with w = 1, or w = 0 where it has none (a 1-voxel
// placeholder when dp.segments is 0).
@group(3) @binding(8) var segment_labels: texture_3d<u32>;
@group(3) @binding(9) var<storage, read> segment_colours: array<vec4<f32>>;

// volume.wgsl's choice of reconstruction (Interpolation::kernel_code).
fn cubic_sampling() -> bool {
    return dp.interpolation != 0u;
}

fn smooth_shading() -> bool {
    return dp.interpolation == 2u;
}

// The scene frame (x = L, y = S, z = A) → LPS.
fn scene_to_lps(p: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(p.x, -p.z, p.y);
}

// A light as a volume sample sees it: the unit direction toward it and the light arriving.
struct SampleLight {
    dir: vec3<f32>,
    lit: vec3<f32>,
}

// The scene's light i seen from a sample: toward its position, through its light grid.
fn sample_light(i: u32, p: vec3<f32>, at: vec3<f32>, d: vec3<f32>) -> SampleLight {
    let light = lights[i];
    let v = scene_to_lps(light.position.xyz) - at;
    let len = length(v);
    var l = -d;
    if len > 0.0 {
        l = v / len;
    }
    var lit = light.color.xyz;
    if dp.shadows != 0u {
        lit *= light_at(p, i * dp.grid_points);
    }
    return SampleLight(l, lit);
}

// The light a sample of colour `base` at index `p` (world `at`, seen along unit `d`) sends
// back, as the CPU's shade_sample: per light, two-sided Blinn-Phong on the gradient normal,
// weighted by gradient magnitude, times the light arriving.
fn shade_sample(base: vec3<f32>, p: vec3<f32>, at: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    let g = gradient_at(p);
    let gm = length(g);
    let amb = dp.shading.x;
    let w = min(gm / FULL_SHADING_GRADIENT, 1.0);
    var unshaded = vec3<f32>(amb);
    var surface = vec3<f32>(amb);
    var spec = vec3<f32>(0.0);
    let n = dp.light_count;
    for (var i = 0u; i < n; i++) {
        let l = sample_light(i, p, at, d);
        var ph = vec2<f32>(amb, 0.0);
        if gm > 0.0 {
            ph = phong(-g / gm, d, l.dir);
        }
        unshaded += (1.0 - amb) * l.lit;
        surface += (ph.x - amb) * l.lit;
        spec += ph.y * l.lit;
    }
    return base * ((1.0 - w) * unshaded + w * surface) + w * spec;
}

// A scene-frame ray in LPS (unit d, mm) and its part [t0, t1] inside the volume; empty when
// !(t0 < t1).
struct Entered {
    o: vec3<f32>,
    d: vec3<f32>,
    o_idx: vec3<f32>,
    d_idx: vec3<f32>,
    t0: f32,
    t1: f32,
}

// As the CPU's Medium::enter: the ray from t_min to t_end (units of its direction's length).
fn enter(r: RayIn, t_end: f32) -> Entered {
    let len = length(r.dir);
    if !(len > 0.0) {
        return Entered(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), 1.0, 0.0);
    }
    let o = scene_to_lps(r.origin);
    let d = scene_to_lps(r.dir) / len;
    let o_idx = to_index(o - dp.origin);
    let d_idx = to_index(d);
    let g = clip_grid(o_idx, d_idx);
    return Entered(o, d, o_idx, d_idx, max(g.x, r.t_min * len), min(g.y, t_end * len));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn march_volume(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i >= atomicLoad(&counters[QUEUE]) {
        return;
    }
    let w = queue_in[i];
    let h = hits[i];
    var t_end = w.ray.t_max;
    if h.prim != NO_PRIM {
        t_end = h.t;
    }
    let e = enter(w.ray, t_end);
    if !(e.t0 < e.t1) {
        return;
    }
    let c = composite(e.o, e.d, e.o_idx, e.d_idx, e.t0, e.t1, jitter(w.pixel, 0u, 7u));
    add_film(w.pixel, w.weight * c.color);
    queue_in[i].weight = w.weight * c.transmit;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn attenuate_shadows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i >= atomicLoad(&counters[SHADOWS]) || hits[i].prim != NO_PRIM {
        return;
    }
    let s = shadows[i];
    let e = enter(s.ray, s.ray.t_max);
    if !(e.t0 < e.t1) {
        return;
    }
    shadows[i].radiance = s.radiance * absorb(e.o_idx, e.d_idx, e.t0, e.t1, dp.step, jitter(s.pixel, 0u, 7u));
}
