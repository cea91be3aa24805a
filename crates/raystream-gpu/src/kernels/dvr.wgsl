// Direct volume rendering: one thread per pixel marches its ray through the CT volume, the same
// algorithm as raystream-cpu's dvr.rs (the reference) — world space (LPS mm), opacity per mm
// corrected for the step, the last segment clipped, jittered start, early termination, bricks
// of empty space skipped on the same sample lattice, gradient Phong with a headlight. The
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
}

// (HU, opacity per mm) and (HU, r, g, b) control points.
@group(0) @binding(0) var<uniform> dp: DvrParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var trilinear: sampler;
@group(0) @binding(3) var<storage, read> opacity_points: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> color_points: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> brick_visible: array<u32>;
@group(0) @binding(6) var<storage, read_write> pixels: array<vec4<f32>>;

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

// (diffuse factor, specular) of Phong with a headlight.
fn phong(n: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    let c = abs(dot(n, -d));
    var spec = 0.0;
    if c > 0.0 {
        spec = dp.shading.z * pow(c, dp.shading.w);
    }
    return vec2<f32>(dp.shading.x + dp.shading.y * c, spec);
}

fn window(v: f32) -> f32 {
    return clamp((v - (dp.window_level - 0.5 * dp.window_width)) / max(dp.window_width, 1e-6), 0.0, 1.0);
}

const FULL_SHADING_GRADIENT: f32 = 100.0;
const BRICK: u32 = BRICK_SIZE;

fn march(o_idx: vec3<f32>, d_idx: vec3<f32>, d: vec3<f32>, jit: f32) -> vec3<f32> {
    // Clip to the grid of voxel centres.
    var t0 = 0.0;
    var t1 = bitcast<f32>(0x7f800000u);
    for (var a = 0u; a < 3u; a++) {
        let hi = f32(dp.dims[a] - 1u);
        if d_idx[a] == 0.0 {
            if o_idx[a] < 0.0 || o_idx[a] > hi {
                return dp.background;
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
    if !(t0 <= t1) {
        return dp.background;
    }
    let step = dp.step;
    var k = 0u;
    if dp.mode == MODE_DVR {
        var c = vec3<f32>(0.0);
        var transmit = 1.0;
        loop {
            let start = t0 + f32(k) * step;
            if start >= t1 {
                break;
            }
            let t = min(t0 + (f32(k) + jit) * step, t1);
            let seg = min(step, t1 - start);
            let p = o_idx + d_idx * t;
            if dp.skip_empty != 0u {
                let b = min(vec3<u32>(max(p, vec3<f32>(0.0))) / BRICK, dp.bricks - 1u);
                if brick_visible[b.x + dp.bricks.x * (b.y + dp.bricks.y * b.z)] == 0u {
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
                    k = max(u32(max(ceil((t_exit - t0) / step - jit), 0.0)), k + 1u);
                    continue;
                }
            }
            k += 1u;
            let v = sample_at(p);
            var a = opacity_at(v);
            if a <= 0.0 {
                continue;
            }
            a = 1.0 - pow(1.0 - min(a, 1.0), seg);
            let base = color_at(v);
            let g = gradient_at(p);
            let gm = length(g);
            var shaded = base;
            if gm > 0.0 {
                let ph = phong(-g / gm, d);
                let w = min(gm / FULL_SHADING_GRADIENT, 1.0);
                shaded = base * (1.0 - w + w * ph.x) + vec3<f32>(w * ph.y);
            }
            c += transmit * a * shaded;
            transmit *= 1.0 - a;
            if transmit < 0.01 {
                break;
            }
        }
        return c + transmit * dp.background;
    }
    if dp.mode == MODE_ISO {
        var t_prev = 0.0;
        var has_prev = false;
        loop {
            let t = t0 + (f32(k) + jit) * step;
            if t > t1 {
                return dp.background;
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
                let ph = phong(n, d);
                return vec3<f32>(0.88, 0.84, 0.74) * ph.x + vec3<f32>(ph.y);
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
        return dp.background;
    }
    if dp.mode == MODE_AVERAGE {
        best = sum / f32(taken);
    }
    return vec3<f32>(window(best));
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
    let c = march(to_index(dp.eye - dp.origin), to_index(d), d, jitter(pixel, 0u, 7u));
    pixels[pixel] = vec4<f32>(c, 1.0);
}
