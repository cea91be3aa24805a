// The denoiser of cinematic frames (`--denoise`), as raystream-cpu's denoise.rs (the reference,
// which says why each step is what it is): the light divided by the guides' albedo, its
// variance blurred 3×3, passes of the edge-avoiding à-trous filter, the albedo multiplied
// back. One thread a pixel; each pass reads one pair of buffers and writes the other.

struct DenoiseParams {
    width: u32,
    height: u32,
    // Taps this many pixels apart (this pass's).
    gap: u32,
    sigma_luminance: f32,
    sigma_depth: f32,
    sigma_normal: f32,
    sigma_albedo: f32,
    // The guides' depth resolution, mm.
    tolerance: f32,
    // Added to the albedo before dividing by it (0: no demodulation).
    demodulate: f32,
    // 1: `remodulate` puts the light over `background` (a frame packed to sRGB next).
    over: u32,
    _pad1: u32,
    _pad2: u32,
    background: vec3<f32>,
    _pad3: f32,
}

@group(0) @binding(0) var<uniform> prm: DenoiseParams;
// Per pixel (light, opacity), read and written by turns.
@group(0) @binding(1) var<storage, read> light_in: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> light_out: array<vec4<f32>>;
// Per pixel the variance of its luminance, read and written by turns.
@group(0) @binding(3) var<storage, read> var_in: array<f32>;
@group(0) @binding(4) var<storage, read_write> var_out: array<f32>;
// The guides: (albedo, depth or −1 for none), then (normal, 0) in the second half.
@group(0) @binding(5) var<storage, read> guides: array<vec4<f32>>;
// Per pixel the depth's change a pixel right and a pixel down; and the blurred variance.
@group(0) @binding(6) var<storage, read_write> slopes: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> blurred: array<f32>;
// The traced frame, as the volume renderer leaves it on the GPU (volume.rs, premultiplied
// output): per pixel (premultiplied light, samples), then per pixel (opacity, variance of its
// luminance, 0, 0). Only `demodulate` reads it.
@group(0) @binding(8) var<storage, read> frame: array<vec4<f32>>;

const EPSILON: f32 = 1e-10;

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

fn pixel_of(gid: vec3<u32>) -> i32 {
    if gid.x >= prm.width || gid.y >= prm.height {
        return -1;
    }
    return i32(gid.x + gid.y * prm.width);
}

fn modulation(p: u32) -> vec3<f32> {
    if prm.demodulate > 0.0 {
        return guides[p].xyz + vec3<f32>(prm.demodulate);
    }
    return vec3<f32>(1.0);
}

// The frame's light divided by the albedo (and its variance by the albedo's luminance
// squared), into the first pair; and the depth slopes (as the CPU's depth_slopes).
@compute @workgroup_size(8, 8)
fn demodulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let pi = pixel_of(gid);
    if pi < 0 {
        return;
    }
    let p = u32(pi);
    let m = modulation(p);
    let second = frame[prm.width * prm.height + p];
    light_out[p] = vec4<f32>(frame[p].xyz / m, second.x);
    let lm = luminance(m);
    var_out[p] = second.y / (lm * lm);
    let w = prm.width;
    let zp = guides[p].w;
    if zp < 0.0 {
        slopes[p] = vec2<f32>(0.0);
        return;
    }
    var s = vec2<f32>(0.0);
    for (var axis = 0u; axis < 2u; axis++) {
        var best = -1.0;
        for (var side = 0u; side < 2u; side++) {
            var q = -1;
            if axis == 0u {
                if side == 0u && gid.x > 0u {
                    q = i32(p) - 1;
                } else if side == 1u && gid.x + 1u < w {
                    q = i32(p) + 1;
                }
            } else {
                if side == 0u && gid.y > 0u {
                    q = i32(p) - i32(w);
                } else if side == 1u && gid.y + 1u < prm.height {
                    q = i32(p) + i32(w);
                }
            }
            if q >= 0 {
                let zq = guides[u32(q)].w;
                if zq >= 0.0 {
                    let d = abs(zq - zp);
                    if best < 0.0 || d < best {
                        best = d;
                    }
                }
            }
        }
        s[axis] = max(best, 0.0);
    }
    slopes[p] = s;
}

// The variance blurred 3×3 (1 2 1 each way), normalised at the edges, as the CPU's blur3.
@compute @workgroup_size(8, 8)
fn blur_variance(@builtin(global_invocation_id) gid: vec3<u32>) {
    let pi = pixel_of(gid);
    if pi < 0 {
        return;
    }
    var s = 0.0;
    var ws = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let qx = i32(gid.x) + dx;
            let qy = i32(gid.y) + dy;
            if qx < 0 || qy < 0 || qx >= i32(prm.width) || qy >= i32(prm.height) {
                continue;
            }
            let k = f32(2 - abs(dx)) * f32(2 - abs(dy));
            s += k * var_in[u32(qx) + u32(qy) * prm.width];
            ws += k;
        }
    }
    blurred[u32(pi)] = s / ws;
}

// One pass of the filter, as the CPU's denoise loop body.
@compute @workgroup_size(8, 8)
fn atrous(@builtin(global_invocation_id) gid: vec3<u32>) {
    let pi = pixel_of(gid);
    if pi < 0 {
        return;
    }
    let p = u32(pi);
    let n = prm.width * prm.height;
    let kernel = array<f32, 5>(1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);
    let lp = luminance(light_in[p].xyz);
    let gp = guides[p];
    let zp = gp.w;
    let n_p = guides[n + p].xyz;
    let ap = gp.xyz;
    let gap = i32(prm.gap);
    var sum_w = 0.0;
    var sum_l = vec4<f32>(0.0);
    var sum_v = 0.0;
    for (var j = 0; j < 5; j++) {
        let dy = (j - 2) * gap;
        let qy = i32(gid.y) + dy;
        if qy < 0 || qy >= i32(prm.height) {
            continue;
        }
        for (var i = 0; i < 5; i++) {
            let dx = (i - 2) * gap;
            let qx = i32(gid.x) + dx;
            if qx < 0 || qx >= i32(prm.width) {
                continue;
            }
            let q = u32(qx) + u32(qy) * prm.width;
            let gq = guides[q];
            let zq = gq.w;
            var w_depth = 0.0;
            if zp >= 0.0 && zq >= 0.0 {
                let predicted = abs(slopes[p].x * f32(dx) + slopes[p].y * f32(dy));
                w_depth = exp(-abs(zp - zq) / (prm.sigma_depth * predicted + prm.tolerance));
            } else if zp < 0.0 && zq < 0.0 {
                w_depth = 1.0;
            }
            if w_depth == 0.0 {
                continue;
            }
            let dn = n_p - guides[n + q].xyz;
            let w_normal = exp(-prm.sigma_normal * dot(dn, dn));
            let da = ap - gq.xyz;
            let w_albedo = exp(-dot(da, da) / (2.0 * prm.sigma_albedo * prm.sigma_albedo));
            let scale = prm.sigma_luminance * sqrt(max(blurred[p] + blurred[q], 0.0)) + EPSILON;
            let cq = light_in[q];
            let w_light = exp(-abs(lp - luminance(cq.xyz)) / scale);
            let wq = kernel[i] * kernel[j] * w_depth * w_normal * w_albedo * w_light;
            sum_w += wq;
            sum_l += cq * wq;
            sum_v += wq * wq * var_in[q];
        }
    }
    light_out[p] = sum_l / sum_w;
    var_out[p] = sum_v / (sum_w * sum_w);
}

// The albedo multiplied back; with `over`, the light put over the background (as the CPU's
// dvr::over_background).
@compute @workgroup_size(8, 8)
fn remodulate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let pi = pixel_of(gid);
    if pi < 0 {
        return;
    }
    let p = u32(pi);
    let c = light_in[p];
    var light = c.xyz * modulation(p);
    if prm.over != 0u {
        light += (1.0 - c.w) * prm.background;
    }
    light_out[p] = vec4<f32>(light, c.w);
}
