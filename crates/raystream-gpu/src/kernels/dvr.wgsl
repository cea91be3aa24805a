// Direct volume rendering: one thread per pixel marches its ray through the CT volume (the
// functions of volume.wgsl), the same algorithm as raystream-cpu's dvr.rs (the reference) — world space (LPS mm), opacity per mm
// corrected for the step, the last segment clipped, jittered start, early termination, bricks
// of empty space skipped on the same sample lattice, gradient Blinn-Phong with a headlight or,
// with shadows, a key light and a shadow ray per visible sample; crop box and clip planes. The
// volume is an R16Float 3D texture of HU sampled with hardware trilinear filtering.

struct DvrParams {
    eye: vec3<f32>,
    tan_y: f32,
    fwd: vec3<f32>,
    width: u32,
    right: vec3<f32>,
    height: u32,
    up: vec3<f32>,
    mode: u32,
    // World → continuous index: rows of the inverse direction·spacing matrix, and the origin.
    to_index0: vec3<f32>,
    step: f32,
    to_index1: vec3<f32>,
    iso: f32,
    to_index2: vec3<f32>,
    window_width: f32,
    origin: vec3<f32>,
    window_level: f32,
    dims: vec3<u32>,
    skip_empty: u32,
    bricks: vec3<u32>,
    opacity_count: u32,
    background: vec3<f32>,
    color_count: u32,
    // ambient, diffuse, specular, specular power
    shading: vec4<f32>,
    // Toward the key light (LPS, unit).
    light: vec3<f32>,
    shadows: u32,
    crop_min: vec3<f32>,
    crop: u32,
    crop_max: vec3<f32>,
    plane_count: u32,
    // Keep n . p >= c: (n, c).
    planes: array<vec4<f32>, 2>,
    // Light grid points per axis (raystream_cpu::dvr::LightGrid).
    light_dims: vec3<u32>,
    // Step of the light grid's shadow rays, mm (DvrOptions::shadow_step_for).
    shadow_step: f32,
    // Half the view's height (mm) of a parallel projection; 0: perspective (Camera::parallel).
    parallel: f32,
    // 1: mip, minip, average and slice give the HU value itself, no window
    // (DvrOptions::hu_values).
    hu_values: u32,
    // 1: premultiplied RGBA (no background): pixels[i] = (C, samples), pixels[n + i].x = 1 - T.
    premultiplied: u32,
    // 1: the pixels' rays come from cpr_rows (a curved planar reformation), not the camera.
    curved: u32,
    // A point of a slice's plane (LPS mm); the plane faces fwd.
    slice_at: vec3<f32>,
    // A curved plane's slab: half its thickness, mm (0: the thin plane).
    slab_half: f32,
    // cinematic (cinematic.wgsl): paths per pixel, scatterings a path may take, and the paths
    // [sample_first, sample_first + sample_count) this dispatch traces.
    spp: u32,
    bounces: u32,
    sample_first: u32,
    sample_count: u32,
    // cinematic: the Henyey-Greenstein anisotropy g, and the lights' scale 2^exposure.
    anisotropy: f32,
    light_scale: f32,
    // Interpolation::kernel_code of DvrOptions::interpolation: 0 trilinear, 1 cubic B-spline, 2 its
    // interpolating form (coefficients in the first channel, the voxels in the second).
    interpolation: u32,
    // 1: dvr, iso and cinematic samples take the colours of a segmentation (segment_labels,
    // segment_colours) in place of the transfer function's.
    segments: u32,
    // 1: mip, minip and average of a volume kept to segments: the texture's second channel
    // holds the kept voxels' weights (sample_kept).
    kept: u32,
    pad_kept: u32,
    pad0: u32,
    pad1: u32,
}

// One image row of a curved plane (raystream_cpu::cpr::CprRow, LPS): the path's point, the
// pixels' side (mm), the unit step along the row and the unit direction of its rays.
struct CprRow {
    centre: vec3<f32>,
    pixel_mm: f32,
    lateral: vec3<f32>,
    pad0: u32,
    normal: vec3<f32>,
    pad1: u32,
}

// (HU, opacity per mm) and (HU, r, g, b) control points.
@group(0) @binding(0) var<uniform> dp: DvrParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var trilinear: sampler;
@group(0) @binding(3) var<storage, read> opacity_points: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> color_points: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> brick_visible: array<u32>;
@group(0) @binding(6) var<storage, read_write> pixels: array<vec4<f32>>;
// Transmittance toward the light at the light grid's points (x fastest).
@group(0) @binding(7) var<storage, read_write> light_values: array<f32>;
// A curved plane's rows, top first (one placeholder row when the camera casts the rays).
@group(0) @binding(10) var<storage, read> cpr_rows: array<CprRow>;
// A segmentation on the volume's grid (raystream_cpu::segments::SegmentColours): each voxel's
// label, and per label its linear colour with w = 1, or w = 0 where it has none (a 1-voxel
// placeholder when dp.segments is 0).
@group(0) @binding(14) var segment_labels: texture_3d<u32>;
@group(0) @binding(15) var<storage, read> segment_colours: array<vec4<f32>>;

const MODE_DVR: u32 = 0u;
const MODE_MIP: u32 = 1u;
const MODE_MINIP: u32 = 2u;
const MODE_AVERAGE: u32 = 3u;
const MODE_ISO: u32 = 4u;
const MODE_SLICE: u32 = 5u;

// volume.wgsl's choice of reconstruction (Interpolation::kernel_code).
fn cubic_sampling() -> bool {
    return dp.interpolation != 0u;
}

fn smooth_shading() -> bool {
    return dp.interpolation == 2u;
}

// The crop box and clip planes applied to [t.x, t.y] of the world ray o + t d, as the CPU's
// clip_interval.
fn clip_world(o: vec3<f32>, d: vec3<f32>, t_in: vec2<f32>) -> vec2<f32> {
    var t = t_in;
    let empty = vec2<f32>(1.0, 0.0);
    if dp.crop != 0u {
        for (var a = 0u; a < 3u; a++) {
            if d[a] == 0.0 {
                if o[a] < dp.crop_min[a] || o[a] > dp.crop_max[a] {
                    return empty;
                }
                continue;
            }
            let n = (dp.crop_min[a] - o[a]) / d[a];
            let f = (dp.crop_max[a] - o[a]) / d[a];
            t.x = max(t.x, min(n, f));
            t.y = min(t.y, max(n, f));
        }
    }
    for (var i = 0u; i < dp.plane_count; i++) {
        let pl = dp.planes[i];
        let no = dot(pl.xyz, o);
        let nd = dot(pl.xyz, d);
        if nd == 0.0 {
            if no < pl.w {
                return empty;
            }
        } else if nd > 0.0 {
            t.x = max(t.x, (pl.w - no) / nd);
        } else {
            t.y = min(t.y, (pl.w - no) / nd);
        }
    }
    return t;
}

// A windowed pixel's film value, as raystream_cpu::dvr::windowed: linear light whose sRGB
// byte is 255 times where v falls in the window.
fn windowed(v: f32) -> f32 {
    return srgb_to_linear(clamp((v - (dp.window_level - 0.5 * dp.window_width)) / max(dp.window_width, 1e-6), 0.0, 1.0));
}

// Index position of light grid point j along an axis of n voxels and g points.
fn grid_position(j: u32, n: u32, g: u32) -> f32 {
    if g > 1u {
        return f32(j) * (f32(n - 1u) / f32(g - 1u));
    }
    return 0.0;
}

// One shadow ray per light grid point, as the CPU's LightGrid::new.
@compute @workgroup_size(64)
fn light_grid(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let g = dp.light_dims;
    let i = gid.x + gid.y * groups.x * 64u;
    if i >= g.x * g.y * g.z {
        return;
    }
    let j = vec3<u32>(i % g.x, i / g.x % g.y, i / (g.x * g.y));
    let p = vec3<f32>(
        grid_position(j.x, dp.dims.x, g.x),
        grid_position(j.y, dp.dims.y, g.y),
        grid_position(j.z, dp.dims.z, g.z));
    let l_idx = to_index(dp.light);
    let s = dp.shadow_step;
    light_values[i] = absorb(p, l_idx, s, clip_grid(p, l_idx).y, s, 0.5);
}

// dvr mode's shading (the CPU's shade_sample with one white light): the key light through
// the light grid with shadows, else a headlight. Scalar light on purpose: medium.wgsl's
// shading with a colour per light made this kernel 13 % slower on an H100 (2.53 against
// 2.23 ms, ct-bone, 512³, 1024²); this one matches the kernel from before the volume core.
fn shade_sample(base: vec3<f32>, p: vec3<f32>, at: vec3<f32>, d: vec3<f32>) -> vec3<f32> {
    var l = -d;
    var lit = 1.0;
    if dp.shadows != 0u {
        l = dp.light;
        lit = light_at(p, 0u);
    }
    let amb = dp.shading.x;
    let g = gradient_at(p);
    let gm = length(g);
    let w = min(gm / FULL_SHADING_GRADIENT, 1.0);
    var ph = vec2<f32>(amb, 0.0);
    if gm > 0.0 {
        ph = phong(-g / gm, d, l);
    }
    let unshaded = amb + (1.0 - amb) * lit;
    let surface = amb + (ph.x - amb) * lit;
    return base * ((1.0 - w) * unshaded + w * surface) + vec3<f32>(w * ph.y * lit);
}

// What one ray gave (raystream_cpu::dvr's Marched): the light it sends (premultiplied, no
// background), the fraction of the background it lets through, the samples taken (primary,
// as the CPU counts them).
struct Marched {
    color: vec3<f32>,
    transmit: f32,
    taken: f32,
}

fn missed(taken: f32) -> Marched {
    return Marched(vec3<f32>(0.0), 1.0, taken);
}

// The ray o + t d marched (as the CPU's march): a slice samples it where it crosses the plane
// through at with normal n, and no sample lies beyond t = reach.
fn march(o: vec3<f32>, d: vec3<f32>, jit: f32, at: vec3<f32>, n: vec3<f32>, reach: f32) -> Marched {
    let o_idx = to_index(o - dp.origin);
    let d_idx = to_index(d);
    var grid = clip_grid(o_idx, d_idx);
    grid.y = min(grid.y, reach);
    let tt = clip_world(o, d, grid);
    if !(tt.x <= tt.y) {
        return missed(0.0);
    }
    let t0 = tt.x;
    let t1 = tt.y;
    let step = dp.step;
    var k = 0u;
    if dp.mode == MODE_DVR {
        let c = composite(o, d, o_idx, d_idx, t0, t1, jit);
        return Marched(c.color, c.transmit, f32(c.taken));
    }
    if dp.mode == MODE_SLICE {
        // One sample, where the ray crosses the plane (as the CPU's march).
        let t = dot(at - o, n) / dot(d, n);
        if !(t >= t0 && t <= t1) {
            return missed(0.0);
        }
        let v = sample_at(o_idx + d_idx * t);
        if dp.hu_values != 0u {
            return Marched(vec3<f32>(v), 0.0, 1.0);
        }
        return Marched(vec3<f32>(windowed(v)), 0.0, 1.0);
    }
    if dp.mode == MODE_ISO {
        var t_prev = 0.0;
        var has_prev = false;
        loop {
            let t = t0 + (f32(k) + jit) * step;
            if t > t1 {
                return missed(f32(k));
            }
            k += 1u;
            if sample_at(o_idx + d_idx * t) >= dp.iso {
                var lo = t;
                var hi = t;
                if has_prev {
                    lo = t_prev;
                }
                for (var i = 0; i < 12; i++) {
                    let mid = 0.5 * (lo + hi);
                    if sample_at(o_idx + d_idx * mid) >= dp.iso {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let g = gradient_at(o_idx + d_idx * hi);
                var n = -d;
                if length(g) > 0.0 {
                    n = -normalize(g);
                }
                let ph = phong(n, d, -d);
                let bone = painted(ISO_COLOUR, o_idx + d_idx * hi);
                return Marched(bone * ph.x + vec3<f32>(ph.y), 0.0, f32(k));
            }
            t_prev = t;
            has_prev = true;
        }
    }
    // mip, minip, average
    var best = bitcast<f32>(0xff800000u);
    if dp.mode == MODE_MINIP {
        best = bitcast<f32>(0x7f800000u);
    }
    var sum = 0.0;
    var taken = 0u;
    // Samples projected: all, or of a volume kept to segments those within them.
    var projected = 0u;
    loop {
        let t = t0 + (f32(k) + jit) * step;
        if t > t1 {
            break;
        }
        // Of a volume kept to segments, the bricks outside them, whose samples are none (the
        // CPU's kept_brick_table).
        if dp.kept != 0u && dp.skip_empty != 0u {
            let next = skip_brick(o_idx + d_idx * t, t, t0, d_idx, step, jit, k);
            if next > k {
                k = next;
                continue;
            }
        }
        var v: f32;
        var within = true;
        if dp.kept != 0u {
            // The kept voxels' own blend where the weights' reach KEPT_WEIGHT, as the CPU's
            // Marcher::sample_kept: both channels filtered with the same weights.
            let s = sample_both(o_idx + d_idx * t);
            within = s.y >= KEPT_WEIGHT;
            v = s.x / s.y;
        } else {
            v = sample_at(o_idx + d_idx * t);
        }
        if within {
            if dp.mode == MODE_MIP {
                best = max(best, v);
            } else if dp.mode == MODE_MINIP {
                best = min(best, v);
            } else {
                sum += v;
            }
            projected += 1u;
        }
        taken += 1u;
        k += 1u;
    }
    if taken == 0u {
        return missed(0.0);
    }
    if projected == 0u {
        // Samples, but none within the kept segments: a miss counted negative, so that the
        // host tells it from a value (NaN with hu_values) and still counts its samples.
        return missed(-f32(taken));
    }
    if dp.mode == MODE_AVERAGE {
        best = sum / f32(projected);
    }
    if dp.hu_values != 0u {
        return Marched(vec3<f32>(best), 0.0, f32(taken));
    }
    return Marched(vec3<f32>(windowed(best)), 0.0, f32(taken));
}

@compute @workgroup_size(8, 8)
fn render_volume(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.width || gid.y >= dp.height {
        return;
    }
    let pixel = gid.x + gid.y * dp.width;
    let w = f32(dp.width);
    let jit = jitter(pixel, 0u, 7u);
    // No bound: the largest f32 (the compiler may assume arithmetic finite).
    let unbounded = 3.4028235e38;
    // A curved plane's pixel, as raystream_cpu::dvr::Sight::ray: its point on the surface,
    // the ray along the row's normal from half the slab before it to half the slab beyond.
    if dp.curved != 0u {
        let r = cpr_rows[gid.y];
        let p = r.centre + ((f32(gid.x) + 0.5) - 0.5 * w) * r.pixel_mm * r.lateral;
        store(pixel, march(p - dp.slab_half * r.normal, r.normal, jit, p, r.normal, 2.0 * dp.slab_half));
        return;
    }
    let r = camera_ray(f32(gid.x) + 0.5, f32(gid.y) + 0.5);
    store(pixel, march(r.o, r.d, jit, dp.slice_at, dp.fwd, unbounded));
}

struct CameraRay {
    o: vec3<f32>,
    d: vec3<f32>,
}

// The camera's ray through image point (x, y) (pixels), as raystream_scene::Camera::ray.
fn camera_ray(x: f32, y: f32) -> CameraRay {
    let w = f32(dp.width);
    let h = f32(dp.height);
    if dp.parallel > 0.0 {
        let sx = (x / w * 2.0 - 1.0) * (w / h);
        let sy = 1.0 - y / h * 2.0;
        return CameraRay(dp.eye + (sx * dp.right + sy * dp.up) * dp.parallel, dp.fwd);
    }
    let px = (x / w * 2.0 - 1.0) * dp.tan_y * (w / h);
    let py = (1.0 - y / h * 2.0) * dp.tan_y;
    return CameraRay(dp.eye, normalize(dp.fwd + px * dp.right + py * dp.up));
}

// A pixel over the background (opaque pixels keep their value, as the CPU's Marched::over),
// or premultiplied with its opacity in the buffer's second half.
fn store(pixel: u32, m: Marched) {
    if dp.premultiplied != 0u {
        pixels[pixel] = vec4<f32>(m.color, m.taken);
        pixels[dp.width * dp.height + pixel] = vec4<f32>(1.0 - m.transmit, 0.0, 0.0, 0.0);
        return;
    }
    var c = m.color;
    if m.transmit != 0.0 {
        c += m.transmit * dp.background;
    }
    pixels[pixel] = vec4<f32>(c, m.taken);
}

// The frame as a viewer shows it: 8-bit sRGB, 3 bytes a pixel (as the CPU's Image::to_srgb8),
// from the float pixels that stay on the GPU: a fifth of the bytes to read back. And the
// samples the rays took (pixel .w), summed per workgroup into a 64-bit count (lo, hi words).
@group(0) @binding(8) var<storage, read_write> packed: array<u32>;
@group(0) @binding(9) var<storage, read_write> sample_sum: array<atomic<u32>, 2>;
var<workgroup> group_samples: atomic<u32>;

// One thread per 4 pixels: their 12 bytes are 3 words.
@compute @workgroup_size(64)
fn pack_srgb8(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) li: u32, @builtin(num_workgroups) groups: vec3<u32>) {
    let g = gid.x + gid.y * groups.x * 64u;
    let n = dp.width * dp.height;
    if 4u * g < n && 3u * g + 2u < arrayLength(&packed) {
        var w = array<u32, 3>(0u, 0u, 0u);
        var taken = 0u;
        for (var k = 0u; k < 4u; k++) {
            let i = 4u * g + k;
            if i >= n {
                break;
            }
            let p = pixels[i];
            taken += u32(abs(p.w));
            for (var c = 0u; c < 3u; c++) {
                let byte = 3u * k + c;
                w[byte / 4u] |= srgb8(p[c]) << (8u * (byte % 4u));
            }
        }
        packed[3u * g] = w[0];
        packed[3u * g + 1u] = w[1];
        packed[3u * g + 2u] = w[2];
        atomicAdd(&group_samples, taken);
    }
    workgroupBarrier();
    if li == 0u {
        let s = atomicLoad(&group_samples);
        let old = atomicAdd(&sample_sum[0], s);
        if old + s < old {
            atomicAdd(&sample_sum[1], 1u);
        }
    }
}
