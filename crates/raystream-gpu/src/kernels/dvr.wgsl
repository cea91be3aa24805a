// Direct volume rendering: one thread per pixel marches its ray through the CT volume, the same
// algorithm as raystream-cpu's dvr.rs (the reference) — world space (LPS mm), opacity per mm
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
    pad0: u32,
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

const MODE_DVR: u32 = 0u;
const MODE_MIP: u32 = 1u;
const MODE_MINIP: u32 = 2u;
const MODE_AVERAGE: u32 = 3u;
const MODE_ISO: u32 = 4u;

fn opacity_at(hu: f32) -> f32 {
    let n = dp.opacity_count;
    if hu < opacity_points[0].x {
        return opacity_points[0].y;
    }
    for (var i = 1u; i < n; i++) {
        let b = opacity_points[i];
        if hu < b.x {
            let a = opacity_points[i - 1u];
            return a.y + (b.y - a.y) * (hu - a.x) / (b.x - a.x);
        }
    }
    return opacity_points[n - 1u].y;
}

fn color_at(hu: f32) -> vec3<f32> {
    let n = dp.color_count;
    if hu < color_points[0].x {
        return color_points[0].yzw;
    }
    for (var i = 1u; i < n; i++) {
        let b = color_points[i];
        if hu < b.x {
            let a = color_points[i - 1u];
            return a.yzw + (b.yzw - a.yzw) * (hu - a.x) / (b.x - a.x);
        }
    }
    return color_points[n - 1u].yzw;
}

// HU at continuous index `p`, clamped to the grid of voxel centres.
fn sample_at(p: vec3<f32>) -> f32 {
    let d = vec3<f32>(dp.dims);
    let q = clamp(p, vec3<f32>(0.0), d - 1.0);
    return textureSampleLevel(volume, trilinear, (q + 0.5) / d, 0.0).r;
}

// The world gradient (HU per mm) at index `p`, as the CPU's Marcher::gradient.
fn gradient_at(p: vec3<f32>) -> vec3<f32> {
    let g = vec3<f32>(
        sample_at(p + vec3<f32>(1.0, 0.0, 0.0)) - sample_at(p - vec3<f32>(1.0, 0.0, 0.0)),
        sample_at(p + vec3<f32>(0.0, 1.0, 0.0)) - sample_at(p - vec3<f32>(0.0, 1.0, 0.0)),
        sample_at(p + vec3<f32>(0.0, 0.0, 1.0)) - sample_at(p - vec3<f32>(0.0, 0.0, 1.0))) * 0.5;
    return dp.to_index0 * g.x + dp.to_index1 * g.y + dp.to_index2 * g.z;
}

fn to_index(v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(dp.to_index0, v), dot(dp.to_index1, v), dot(dp.to_index2, v));
}

// (ambient + diffuse, specular) of two-sided Blinn-Phong toward light `l` seen along `d`.
fn phong(n: vec3<f32>, d: vec3<f32>, l: vec3<f32>) -> vec2<f32> {
    var h = -d;
    let hl = length(l - d);
    if hl > 0.0 {
        h = (l - d) / hl;
    }
    let c = abs(dot(n, h));
    var spec = 0.0;
    if c > 0.0 {
        spec = dp.shading.z * pow(c, dp.shading.w);
    }
    return vec2<f32>(dp.shading.x + dp.shading.y * abs(dot(n, l)), spec);
}

// [t0, t1] of the ray o_idx + t d_idx inside the grid of voxel centres; empty when t0 > t1.
fn clip_grid(o_idx: vec3<f32>, d_idx: vec3<f32>) -> vec2<f32> {
    var t0 = 0.0;
    var t1 = bitcast<f32>(0x7f800000u);
    for (var a = 0u; a < 3u; a++) {
        let hi = f32(dp.dims[a] - 1u);
        if d_idx[a] == 0.0 {
            if o_idx[a] < 0.0 || o_idx[a] > hi {
                return vec2<f32>(1.0, 0.0);
            }
            continue;
        }
        var n = (0.0 - o_idx[a]) / d_idx[a];
        var f = (hi - o_idx[a]) / d_idx[a];
        if n > f {
            let t = n;
            n = f;
            f = t;
        }
        t0 = max(t0, n);
        t1 = min(t1, f);
    }
    return vec2<f32>(t0, t1);
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

// Where index point `p` (ray parameter t, lattice t0 + (k + jit) step) lies in a transparent
// brick: the first lattice index past it (at least k + 1); else k.
fn skip_brick(p: vec3<f32>, t: f32, t0: f32, d_idx: vec3<f32>, jit: f32, k: u32) -> u32 {
    let b = min(vec3<u32>(max(p, vec3<f32>(0.0))) / BRICK, dp.bricks - 1u);
    if brick_visible[b.x + dp.bricks.x * (b.y + dp.bricks.y * b.z)] != 0u {
        return k;
    }
    var t_exit = bitcast<f32>(0x7f800000u);
    for (var a = 0u; a < 3u; a++) {
        if d_idx[a] == 0.0 {
            continue;
        }
        var bound = f32(b[a] * BRICK);
        if d_idx[a] > 0.0 {
            bound = f32((b[a] + 1u) * BRICK);
        }
        t_exit = min(t_exit, t + (bound - p[a]) / d_idx[a]);
    }
    return max(u32(max(ceil((t_exit - t0) / dp.step - jit), 0.0)), k + 1u);
}

// Transmittance from index point `p` toward the light, as the CPU's Marcher::transmittance.
fn transmittance(p: vec3<f32>, l_idx: vec3<f32>, jit: f32) -> f32 {
    let t1 = clip_grid(p, l_idx).y;
    let step = dp.step;
    var tr = 1.0;
    var k = 1u;
    loop {
        let start = f32(k) * step;
        if start >= t1 {
            break;
        }
        let t = min((f32(k) + jit) * step, t1);
        let q = p + l_idx * t;
        if dp.skip_empty != 0u {
            let next = skip_brick(q, t, 0.0, l_idx, jit, k);
            if next != k {
                k = next;
                continue;
            }
        }
        let seg = min(step, t1 - start);
        k += 1u;
        let a = opacity_at(sample_at(q));
        if a > 0.0 {
            tr *= pow(1.0 - min(a, 1.0), seg);
            if tr < 0.01 {
                break;
            }
        }
    }
    return tr;
}

fn window(v: f32) -> f32 {
    return clamp((v - (dp.window_level - 0.5 * dp.window_width)) / max(dp.window_width, 1e-6), 0.0, 1.0);
}

const FULL_SHADING_GRADIENT: f32 = 100.0;
const BRICK: u32 = BRICK_SIZE;

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
    light_values[i] = transmittance(p, to_index(dp.light), 0.5);
}

fn light_value(i: u32, j: u32, k: u32) -> f32 {
    let g = dp.light_dims;
    return light_values[min(i, g.x - 1u) + g.x * (min(j, g.y - 1u) + g.y * min(k, g.z - 1u))];
}

// The light reaching index `p`: trilinear between grid points, as LightGrid::at.
fn light_at(p: vec3<f32>) -> f32 {
    let g = dp.light_dims;
    var scale = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        if dp.dims[a] > 1u && g[a] > 1u {
            scale[a] = f32(g[a] - 1u) / f32(dp.dims[a] - 1u);
        }
    }
    let q = clamp(p * scale, vec3<f32>(0.0), vec3<f32>(g - 1u));
    let lo = min(vec3<u32>(q), max(g, vec3<u32>(2u)) - 2u);
    let f = q - vec3<f32>(lo);
    let x0 = mix(light_value(lo.x, lo.y, lo.z), light_value(lo.x + 1u, lo.y, lo.z), f.x);
    let x1 = mix(light_value(lo.x, lo.y + 1u, lo.z), light_value(lo.x + 1u, lo.y + 1u, lo.z), f.x);
    let x2 = mix(light_value(lo.x, lo.y, lo.z + 1u), light_value(lo.x + 1u, lo.y, lo.z + 1u), f.x);
    let x3 = mix(light_value(lo.x, lo.y + 1u, lo.z + 1u), light_value(lo.x + 1u, lo.y + 1u, lo.z + 1u), f.x);
    return mix(mix(x0, x1, f.y), mix(x2, x3, f.y), f.z);
}

// Colour and the samples taken (primary, as the CPU counts them).
fn march(o: vec3<f32>, d: vec3<f32>, jit: f32) -> vec4<f32> {
    let o_idx = to_index(o - dp.origin);
    let d_idx = to_index(d);
    let tt = clip_world(o, d, clip_grid(o_idx, d_idx));
    if !(tt.x <= tt.y) {
        return vec4<f32>(dp.background, 0.0);
    }
    let t0 = tt.x;
    let t1 = tt.y;
    let step = dp.step;
    var k = 0u;
    if dp.mode == MODE_DVR {
        var c = vec3<f32>(0.0);
        var transmit = 1.0;
        var l = -d;
        if dp.shadows != 0u {
            l = dp.light;
        }
        let amb = dp.shading.x;
        var taken = 0u;
        loop {
            let start = t0 + f32(k) * step;
            if start >= t1 {
                break;
            }
            let t = min(t0 + (f32(k) + jit) * step, t1);
            let seg = min(step, t1 - start);
            let p = o_idx + d_idx * t;
            if dp.skip_empty != 0u {
                let next = skip_brick(p, t, t0, d_idx, jit, k);
                if next != k {
                    k = next;
                    continue;
                }
            }
            k += 1u;
            taken += 1u;
            let v = sample_at(p);
            var a = opacity_at(v);
            if a <= 0.0 {
                continue;
            }
            a = 1.0 - pow(1.0 - min(a, 1.0), seg);
            let base = color_at(v);
            var lit = 1.0;
            if dp.shadows != 0u {
                lit = light_at(p);
            }
            let g = gradient_at(p);
            let gm = length(g);
            let w = min(gm / FULL_SHADING_GRADIENT, 1.0);
            var ph = vec2<f32>(amb, 0.0);
            if gm > 0.0 {
                ph = phong(-g / gm, d, l);
            }
            let unshaded = amb + (1.0 - amb) * lit;
            let surface = amb + (ph.x - amb) * lit;
            let shaded = base * ((1.0 - w) * unshaded + w * surface) + vec3<f32>(w * ph.y * lit);
            c += transmit * a * shaded;
            transmit *= 1.0 - a;
            if transmit < 0.01 {
                break;
            }
        }
        return vec4<f32>(c + transmit * dp.background, f32(taken));
    }
    if dp.mode == MODE_ISO {
        var t_prev = 0.0;
        var has_prev = false;
        loop {
            let t = t0 + (f32(k) + jit) * step;
            if t > t1 {
                return vec4<f32>(dp.background, f32(k));
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
                return vec4<f32>(vec3<f32>(0.88, 0.84, 0.74) * ph.x + vec3<f32>(ph.y), f32(k));
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
    loop {
        let t = t0 + (f32(k) + jit) * step;
        if t > t1 {
            break;
        }
        let v = sample_at(o_idx + d_idx * t);
        if dp.mode == MODE_MIP {
            best = max(best, v);
        } else if dp.mode == MODE_MINIP {
            best = min(best, v);
        } else {
            sum += v;
        }
        taken += 1u;
        k += 1u;
    }
    if taken == 0u {
        return vec4<f32>(dp.background, 0.0);
    }
    if dp.mode == MODE_AVERAGE {
        best = sum / f32(taken);
    }
    return vec4<f32>(vec3<f32>(window(best)), f32(taken));
}

@compute @workgroup_size(8, 8)
fn render_volume(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.width || gid.y >= dp.height {
        return;
    }
    let pixel = gid.x + gid.y * dp.width;
    let w = f32(dp.width);
    let h = f32(dp.height);
    let px = ((f32(gid.x) + 0.5) / w * 2.0 - 1.0) * dp.tan_y * (w / h);
    let py = (1.0 - (f32(gid.y) + 0.5) / h * 2.0) * dp.tan_y;
    let d = normalize(dp.fwd + px * dp.right + py * dp.up);
    pixels[pixel] = march(dp.eye, d, jitter(pixel, 0u, 7u));
}
