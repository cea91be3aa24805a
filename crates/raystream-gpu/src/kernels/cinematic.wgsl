// Cinematic rendering (`--mode cinematic`): Monte Carlo path tracing of the CT volume as a
// participating medium, as raystream-cpu's cinematic.rs (the reference), which says why each
// step is what it is. One thread per pixel runs its `spp` paths; the random numbers are the
// CPU's (the same PCG stream per pixel and sample), so both devices follow the same paths but
// where the f16 texture's values tip a decision. Follows dvr.wgsl (store, Marched, clip_world,
// camera_ray) and volume.wgsl (sample_at, gradient_at, opacity_at, color_at, clip_grid,
// to_index).

// Per cell of MAJORANT_CELL³ (x fastest), the largest extinction (per mm) the transfer function
// gives over its HU range (raystream_cpu::cinematic::Majorants).
@group(0) @binding(11) var<storage, read> majorants: array<f32>;

// A frame drawn in several dispatches keeps its running sums here: per pixel (light, escaped
// camera rays), then (samples taken as u32 bits, the paths' squared luminances, 0, 0).
@group(0) @binding(12) var<storage, read_write> accum: array<vec4<f32>>;

const ROULETTE_BELOW: f32 = 0.1;
const INV_PI: f32 = 0.31830988618;
const PI: f32 = 3.14159265359;
const TAU: f32 = 6.28318530718;

var<private> rng_state: u32;
// Volume samples this thread took.
var<private> path_taken: u32;

// As the CPU's PathRng::new.
fn rng_seed(pixel: u32, sample: u32) {
    var x = (pixel * 0x9E3779B9u) ^ (sample * 0x85EBCA6Bu) ^ 0x2545F491u;
    x ^= x >> 16u;
    x *= 0x7FEB352Du;
    x ^= x >> 15u;
    x *= 0x846CA68Bu;
    x ^= x >> 16u;
    rng_state = x;
}

// As the CPU's PathRng::uniform: PCG's RXS-M-XS output of a 32-bit LCG, in [0, 1).
fn rng_next() -> f32 {
    rng_state = rng_state * 747796405u + 2891336453u;
    let s = rng_state;
    let word = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    let x = (word >> 22u) ^ word;
    return f32(x >> 8u) / 16777216.0;
}

fn sigma_of(alpha: f32) -> f32 {
    return -log(1.0 - clamp(alpha, 0.0, ALPHA_MAX));
}

fn uniform_sphere() -> vec3<f32> {
    let z = 1.0 - 2.0 * rng_next();
    let r = sqrt(max(1.0 - z * z, 0.0));
    let phi = TAU * rng_next();
    return vec3<f32>(r * cos(phi), r * sin(phi), z);
}

// As the CPU's phase: the Henyey-Greenstein phase function of anisotropy dp.anisotropy toward
// wi for a ray travelling along d (isotropic below |g| = 1e-3).
fn phase(d: vec3<f32>, wi: vec3<f32>) -> f32 {
    let g = dp.anisotropy;
    if abs(g) < 1e-3 {
        return 0.25 * INV_PI;
    }
    let denom = 1.0 + g * g - 2.0 * g * dot(d, wi);
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
}

// As the CPU's phase_sample: a direction drawn from the phase function about d.
fn phase_sample(d: vec3<f32>) -> vec3<f32> {
    let g = dp.anisotropy;
    if abs(g) < 1e-3 {
        return uniform_sphere();
    }
    let u = rng_next();
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    let cos_theta = clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
    return about(d, cos_theta, rng_next());
}

// The unit direction at polar angle θ (its cosine) and azimuth 2π u about the unit n, on the
// basis of Duff et al. 2017 (as the CPU's basis and about).
fn about(n: vec3<f32>, cos_theta: f32, u: f32) -> vec3<f32> {
    var sign = -1.0;
    if n.z >= 0.0 {
        sign = 1.0;
    }
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bt = vec3<f32>(b, sign + n.y * n.y * a, -n.y);
    let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    let phi = TAU * u;
    return normalize(t * (sin_theta * cos(phi)) + bt * (sin_theta * sin(phi)) + n * cos_theta);
}

fn cosine_hemisphere(n: vec3<f32>) -> vec3<f32> {
    let u = rng_next();
    return about(n, sqrt(max(1.0 - u, 0.0)), rng_next());
}

// The normalised Blinn-Phong lobe, as the CPU's blinn.
fn blinn(n: vec3<f32>, wo: vec3<f32>, wi: vec3<f32>, p: f32) -> f32 {
    let s = wo + wi;
    var h = vec3<f32>(0.0);
    if length(s) > 0.0 {
        h = normalize(s);
    }
    return (p + 2.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), p);
}

// A direction from the glossy lobe and its weight (xyz, w), as the CPU's glossy_sample.
fn glossy_sample(n: vec3<f32>, wo: vec3<f32>, p: f32) -> vec4<f32> {
    let cos_h = pow(rng_next(), 1.0 / (p + 1.0));
    let h = about(n, cos_h, rng_next());
    let wo_h = dot(wo, h);
    let wi = h * (2.0 * wo_h) - wo;
    let cos_i = dot(n, wi);
    if cos_i <= 0.0 || wo_h <= 0.0 {
        return vec4<f32>(wi, 0.0);
    }
    return vec4<f32>(wi, (p + 2.0) / (p + 1.0) * cos_i * wo_h);
}

// The part of the world ray o + t d inside the grid, the crop box and the clip planes,
// restarted where it enters (as the CPU's inside): index origin and direction, length, entry.
struct Inside {
    o_idx: vec3<f32>,
    len: f32,
    d_idx: vec3<f32>,
    t0: f32,
    ok: bool,
}

fn inside(o: vec3<f32>, d: vec3<f32>) -> Inside {
    let o_idx = to_index(o - dp.origin);
    let d_idx = to_index(d);
    var r = Inside(o_idx, 0.0, d_idx, 0.0, false);
    let g = clip_grid(o_idx, d_idx);
    if !(g.x <= g.y) {
        return r;
    }
    let tt = clip_world(o, d, g);
    if !(tt.x <= tt.y) {
        return r;
    }
    r.o_idx = o_idx + d_idx * tt.x;
    r.len = tt.y - tt.x;
    r.t0 = tt.x;
    r.ok = true;
    return r;
}

// What a walk found: where it stopped (t, HU) if it did, and ratio tracking's transmittance.
struct Tracked {
    stopped: bool,
    t: f32,
    hu: f32,
    tr: f32,
}

// The majorant cell holding index p (its index's bits) and where the ray leaves it, as the
// CPU's Majorants::exit; the cells per axis as raystream_cpu::dvr::cell_dims.
fn cell_exit(p: vec3<f32>, t: f32, d_idx: vec3<f32>) -> vec2<f32> {
    let cells = max((dp.dims - 1u + MAJORANT_CELL - 1u) / MAJORANT_CELL, vec3<u32>(1u));
    let b = min(vec3<u32>(max(p, vec3<f32>(0.0))) / MAJORANT_CELL, cells - 1u);
    let t_exit = cell_exit_t(p, t, d_idx, b, MAJORANT_CELL);
    return vec2<f32>(bitcast<f32>(b.x + cells.x * (b.y + cells.y * b.z)), t_exit);
}

// As the CPU's Marcher::track with free_flight's rule (ratio = false: stop at a real
// collision) or transmittance_estimate's (ratio = true: ratio tracking with roulette).
fn track(r: Inside, ratio_tracking: bool) -> Tracked {
    var t = 0.0;
    var tr = 1.0;
    loop {
        if !(t < r.len) {
            break;
        }
        let ce = cell_exit(r.o_idx + r.d_idx * t, t, r.d_idx);
        let end = max(min(ce.y, r.len), t + 1e-4);
        let majorant = majorants[bitcast<u32>(ce.x)];
        if majorant <= 0.0 {
            t = end;
            continue;
        }
        let tc = t - log(1.0 - rng_next()) / majorant;
        if tc >= end {
            t = end;
            continue;
        }
        t = tc;
        let hu = sample_at(r.o_idx + r.d_idx * t);
        path_taken += 1u;
        let ratio = min(sigma_of(opacity_at(hu)) / majorant, 1.0);
        if ratio_tracking {
            tr *= 1.0 - ratio;
            if tr <= 0.0 {
                return Tracked(true, t, hu, 0.0);
            }
            if tr < ROULETTE_BELOW {
                if rng_next() < 0.5 {
                    return Tracked(true, t, hu, 0.0);
                }
                tr *= 2.0;
            }
        } else if rng_next() < ratio {
            return Tracked(true, t, hu, tr);
        }
    }
    return Tracked(false, t, 0.0, tr);
}

struct PathSample {
    light: vec3<f32>,
    escaped: bool,
}

// One path, as the CPU's cinematic::path.
fn trace_path(o_in: vec3<f32>, d_in: vec3<f32>, key: vec3<f32>) -> PathSample {
    var o = o_in;
    var d = d_in;
    var throughput = vec3<f32>(1.0);
    var light = vec3<f32>(0.0);
    var depth = 0u;
    loop {
        let r = inside(o, d);
        var hit = Tracked(false, 0.0, 0.0, 1.0);
        if r.ok {
            hit = track(r, false);
        }
        if !hit.stopped {
            if depth > 0u {
                light += throughput * (SKY_RADIANCE * dp.light_scale);
            }
            return PathSample(light, depth == 0u);
        }
        let p_idx = r.o_idx + r.d_idx * hit.t;
        let x = o + d * (r.t0 + hit.t);
        let albedo = painted(color_at(hit.hu), p_idx);
        let g = gradient_at(p_idx);
        let gm = length(g);
        // As on the CPU: a gradient that is not finite (a NaN voxel among those it reads)
        // gives no normal. (NaN and infinity fail `gm <= 3.0e38`.)
        let u = rng_next();
        let surface = gm <= 3.0e38 && u < min(gm / FULL_SHADING_GRADIENT, 1.0);
        var n = vec3<f32>(0.0);
        var gloss = 0.0;
        var f = albedo * phase(d, key);
        if surface {
            n = -g / gm;
            if dot(n, d) > 0.0 {
                n = -n;
            }
            gloss = clamp(dp.shading.z, 0.0, 1.0);
            let cos_l = dot(n, key);
            f = vec3<f32>(0.0);
            if cos_l > 0.0 {
                f = (albedo * ((1.0 - gloss) * INV_PI) + vec3<f32>(gloss * blinn(n, -d, key, dp.shading.w))) * cos_l;
            }
        }
        if max(f.x, max(f.y, f.z)) > 0.0 {
            let s = inside(x, key);
            var tr = 1.0;
            if s.ok {
                tr = track(s, true).tr;
            }
            light += throughput * f * (KEY_IRRADIANCE * dp.light_scale * tr);
        }
        if depth == dp.bounces {
            return PathSample(light, false);
        }
        depth += 1u;
        if surface && rng_next() < gloss {
            let gs = glossy_sample(n, -d, dp.shading.w);
            if gs.w <= 0.0 {
                return PathSample(light, false);
            }
            throughput *= gs.w;
            d = gs.xyz;
        } else {
            throughput *= albedo;
            if surface {
                d = cosine_hemisphere(n);
            } else {
                d = phase_sample(d);
            }
        }
        o = x;
    }
    return PathSample(light, false);
}

@compute @workgroup_size(8, 8)
fn path_trace_volume(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.width || gid.y >= dp.height {
        return;
    }
    let pixel = gid.x + gid.y * dp.width;
    let n = dp.width * dp.height;
    // The sums so far, added to in the CPU's order (the same f32 sums).
    var sum = vec3<f32>(0.0);
    var escaped = 0.0;
    var sum_sq = 0.0;
    path_taken = 0u;
    if dp.sample_first > 0u {
        let a = accum[pixel];
        sum = a.xyz;
        escaped = a.w;
        let b = accum[n + pixel];
        path_taken = bitcast<u32>(b.x);
        sum_sq = b.y;
    }
    let end = dp.sample_first + dp.sample_count;
    for (var s = dp.sample_first; s < end; s++) {
        rng_seed(pixel, s);
        let x = f32(gid.x) + rng_next();
        let y = f32(gid.y) + rng_next();
        let r = camera_ray(x, y);
        let p = trace_path(r.o, r.d, dp.light);
        sum += p.light;
        let l = luminance(p.light);
        sum_sq += l * l;
        if p.escaped {
            escaped += 1.0;
        }
    }
    if end < dp.spp {
        accum[pixel] = vec4<f32>(sum, escaped);
        accum[n + pixel] = vec4<f32>(bitcast<f32>(path_taken), sum_sq, 0.0, 0.0);
        return;
    }
    let paths = f32(max(dp.spp, 1u));
    store(pixel, Marched(sum / paths, escaped / paths, f32(path_taken)));
    // The premultiplied output's second plane holds (opacity, variance, 0, 0): the denoiser's.
    if dp.premultiplied != 0u {
        pixels[n + pixel].y = variance_of_mean(luminance(sum), sum_sq, dp.spp);
    }
}

// Luminance of linear Rec. 709 RGB (as the CPU's cinematic::luminance).
fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// As the CPU's cinematic::variance_of_mean: the variance of the mean of n paths.
fn variance_of_mean(sum: f32, sum_sq: f32, n: u32) -> f32 {
    if n < 2u {
        return 0.0;
    }
    let k = f32(n);
    let mean = sum / k;
    return max(sum_sq / k - mean * mean, 0.0) / (k - 1.0);
}

// The denoiser's guides, as the CPU's cinematic::guides (which says why): in each pixel a grid
// of GUIDE_SUBPIXELS² rays marched in dp.step steps, cell by cell over the majorants, each step
// weighted by the light it stops. guide_out[pixel] = (albedo, mean depth or −1 for none),
// guide_out[n + pixel] = (normal, 0).
@group(0) @binding(13) var<storage, read_write> guide_out: array<vec4<f32>>;

@compute @workgroup_size(8, 8)
fn guide_volume(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= dp.width || gid.y >= dp.height {
        return;
    }
    let pixel = gid.x + gid.y * dp.width;
    let n = dp.width * dp.height;
    let k = GUIDE_SUBPIXELS;
    let step = dp.step;
    var albedo = vec3<f32>(0.0);
    var normal = vec3<f32>(0.0);
    var depth = 0.0;
    var coverage = 0.0;
    for (var j = 0u; j < k; j++) {
        for (var i = 0u; i < k; i++) {
            let r = camera_ray(f32(gid.x) + (f32(i) + 0.5) / f32(k), f32(gid.y) + (f32(j) + 0.5) / f32(k));
            let g = inside(r.o, r.d);
            if !g.ok {
                continue;
            }
            var transmit = 1.0;
            var t = 0.5 * step;
            loop {
                if !(t < g.len && transmit > GUIDE_TRANSMITTANCE_END) {
                    break;
                }
                let ce = cell_exit(g.o_idx + g.d_idx * t, t, g.d_idx);
                if majorants[bitcast<u32>(ce.x)] <= 0.0 {
                    // On to the first lattice point past the cell.
                    t = max(t + step, t + ceil((ce.y - t) / step) * step);
                    continue;
                }
                let p = g.o_idx + g.d_idx * t;
                let hu = sample_at(p);
                let sigma = sigma_of(opacity_at(hu));
                if sigma > 0.0 {
                    let w = transmit * (1.0 - exp(-sigma * step));
                    let gr = gradient_at(p);
                    let gm = length(gr);
                    if gm > 0.0 {
                        var facing = -gr / gm;
                        if dot(facing, r.d) > 0.0 {
                            facing = -facing;
                        }
                        normal += facing * (min(gm / FULL_SHADING_GRADIENT, 1.0) * w);
                    }
                    albedo += painted(color_at(hu), p) * w;
                    depth += (g.t0 + t) * w;
                    coverage += w;
                    transmit -= w;
                }
                t += step;
            }
        }
    }
    let m = f32(k * k);
    var z = -1.0;
    if coverage >= GUIDE_MIN_COVERAGE * m {
        z = depth / coverage;
    }
    guide_out[pixel] = vec4<f32>(albedo / m, z);
    guide_out[n + pixel] = vec4<f32>(normal / m, 0.0);
}
