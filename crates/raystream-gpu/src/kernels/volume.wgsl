// The volume core that direct volume rendering (dvr.wgsl) and volumes in mesh scenes
// (medium.wgsl) share: raystream-cpu's dvr.rs Marcher, LightGrid and shading, on an R16Float 3D
// texture of HU with hardware trilinear filtering.
//
// The including module declares the uniform `dp` with the fields used here (dims, bricks,
// to_index0..2, origin, step, skip_empty, opacity_count, color_count, shading, light_dims),
// the resources `volume`, `trilinear`, `opacity_points`, `color_points`, `brick_visible`,
// `light_values`, and the shading of a sample, `shade_sample(base, p, at, d)`: the light a
// sample of colour `base` at index `p` (world `at`, seen along unit `d`) sends back, as the
// CPU's shade_sample for the module's lights; `cubic_sampling()`: whether the volume is read by a
// cubic B-spline (raystream_cpu::sampling::Interpolation::Cubic or CubicInterpolating) rather than
// trilinearly; `smooth_shading()`: whether the texture's second channel holds the voxels
// whose spline's gradient shades it (CubicInterpolating); a segmentation's `segment_labels`
// (an R16Uint texture of the volume's grid) and `segment_colours`, read when dp.segments is
// 1; lerp3 is common.wgsl's, which every module holding this core includes.

const FULL_SHADING_GRADIENT: f32 = 100.0;

// Voxel (i, j, k)'s colour: its segment's, else base.
fn segment_voxel(i: u32, j: u32, k: u32, base: vec3<f32>) -> vec3<f32> {
    let c = segment_colours[textureLoad(segment_labels, vec3<u32>(i, j, k), 0).x];
    return select(base, c.xyz, c.w > 0.0);
}

// The colour of the sample at index p whose own colour (the transfer function's, or iso's
// material) is base: with a segmentation, the trilinear blend of its eight nearest voxels'
// segment colours, base for voxels of none, clamped to the grid, as the CPU's
// SegmentColours::colour_at (the same lerps in the same order).
fn painted(base: vec3<f32>, p: vec3<f32>) -> vec3<f32> {
    if dp.segments == 0u {
        return base;
    }
    let n = dp.dims;
    let q = clamp(p, vec3<f32>(0.0), vec3<f32>(n - 1u));
    let i = min(vec3<u32>(q), max(n, vec3<u32>(2u)) - 2u);
    let f = q - vec3<f32>(i);
    let e = min(i + 1u, n - 1u);
    let c000 = segment_voxel(i.x, i.y, i.z, base);
    let c100 = segment_voxel(e.x, i.y, i.z, base);
    let c010 = segment_voxel(i.x, e.y, i.z, base);
    let c110 = segment_voxel(e.x, e.y, i.z, base);
    let c001 = segment_voxel(i.x, i.y, e.z, base);
    let c101 = segment_voxel(e.x, i.y, e.z, base);
    let c011 = segment_voxel(i.x, e.y, e.z, base);
    let c111 = segment_voxel(e.x, e.y, e.z, base);
    let y0 = lerp3(lerp3(c000, c100, f.x), lerp3(c010, c110, f.x), f.y);
    let y1 = lerp3(lerp3(c001, c101, f.x), lerp3(c011, c111, f.x), f.y);
    return lerp3(y0, y1, f.z);
}

const BRICK: u32 = BRICK_SIZE;

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

// The texture's trilinear filter at continuous index `q` (voxel centres at integers; the
// sampler clamps to the edge, as the CPU clamps indices): both channels, the values the volume
// is read by and the second channel (the voxels whose gradient shades the interpolating
// spline's coefficients, or a kept volume's weights).
fn fetch_both(q: vec3<f32>) -> vec2<f32> {
    return textureSampleLevel(volume, trilinear, (q + 0.5) / vec3<f32>(dp.dims), 0.0).rg;
}

// The channel of `v` (fetch_both's) that the volume is read by, or with `shading` the one
// whose gradient shades it (the second, the voxels, where the first holds the interpolating
// spline's coefficients).
fn channel_of(v: vec2<f32>, shading: bool) -> f32 {
    return select(v.x, v.y, shading && smooth_shading());
}

fn fetch(q: vec3<f32>) -> f32 {
    return fetch_both(q).x;
}

// The cubic B-spline at one point, as the sums of eight trilinear fetches (Sigg & Hadwiger,
// GPU Gems 2 ch. 20): per axis, the weights of voxels i-1, i (g0 = w0 + w1) and i+1, i+2
// (g1 = w2 + w3) and the two fetch positions h0 = i - 1 + w1/g0, h1 = i + 1 + w3/g1 at which
// the filter's lerp gives those pairs' weighted means; and the same for the weights'
// derivatives (dg0 = w0' + w1' = -(w2' + w3'), never 0), whose fetches give the gradient.
struct Cubic {
    g0: vec3<f32>,
    h0: vec3<f32>,
    h1: vec3<f32>,
    dg0: vec3<f32>,
    dh0: vec3<f32>,
    dh1: vec3<f32>,
}

// raystream_cpu::sampling::bspline_weights, per axis, turned into fetch positions.
fn cubic_at(p: vec3<f32>) -> Cubic {
    let q = clamp(p, vec3<f32>(0.0), vec3<f32>(dp.dims) - 1.0);
    let i = floor(q);
    let t = q - i;
    let s = 1.0 - t;
    let t2 = t * t;
    let t3 = t2 * t;
    let w0 = s * s * s / 6.0;
    let w1 = (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0;
    let w2 = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0;
    let w3 = t3 / 6.0;
    let d0 = -0.5 * s * s;
    let d1 = 0.5 * (3.0 * t2 - 4.0 * t);
    let d2 = 0.5 * (-3.0 * t2 + 2.0 * t + 1.0);
    let d3 = 0.5 * t2;
    var c: Cubic;
    c.g0 = w0 + w1;
    c.h0 = i - 1.0 + w1 / c.g0;
    c.h1 = i + 1.0 + w3 / (w2 + w3);
    c.dg0 = d0 + d1;
    c.dh0 = i - 1.0 + d1 / c.dg0;
    c.dh1 = i + 1.0 + d3 / (d2 + d3);
    return c;
}

// Σ over the 2×2×2 fetch positions (x.x or x.y per axis, likewise y and z) of the product of
// their axes' weights (wx.x or wx.y, …) times the fetched values, both channels (fetch_both).
fn fetch8(x: vec2<f32>, wx: vec2<f32>, y: vec2<f32>, wy: vec2<f32>, z: vec2<f32>, wz: vec2<f32>) -> vec2<f32> {
    let p0 = wy.x * (wx.x * fetch_both(vec3<f32>(x.x, y.x, z.x)) + wx.y * fetch_both(vec3<f32>(x.y, y.x, z.x)))
           + wy.y * (wx.x * fetch_both(vec3<f32>(x.x, y.y, z.x)) + wx.y * fetch_both(vec3<f32>(x.y, y.y, z.x)));
    let p1 = wy.x * (wx.x * fetch_both(vec3<f32>(x.x, y.x, z.y)) + wx.y * fetch_both(vec3<f32>(x.y, y.x, z.y)))
           + wy.y * (wx.x * fetch_both(vec3<f32>(x.x, y.y, z.y)) + wx.y * fetch_both(vec3<f32>(x.y, y.y, z.y)));
    return wz.x * p0 + wz.y * p1;
}

// The cubic B-spline's value at continuous index `p`, clamped to the grid: both channels.
fn cubic_both(p: vec3<f32>) -> vec2<f32> {
    let c = cubic_at(p);
    let g1 = 1.0 - c.g0;
    return fetch8(vec2<f32>(c.h0.x, c.h1.x), vec2<f32>(c.g0.x, g1.x),
                  vec2<f32>(c.h0.y, c.h1.y), vec2<f32>(c.g0.y, g1.y),
                  vec2<f32>(c.h0.z, c.h1.z), vec2<f32>(c.g0.z, g1.z));
}

fn cubic_value(p: vec3<f32>) -> f32 {
    return cubic_both(p).x;
}

// The cubic B-spline's gradient per index unit at `p`, of the shading channel (the voxels'
// spline, for either spline): along each axis the derivative's pair of fetch positions and
// weights (dg0, -dg0), along the others the value's.
fn cubic_gradient(p: vec3<f32>) -> vec3<f32> {
    let c = cubic_at(p);
    let g1 = 1.0 - c.g0;
    let vx = vec2<f32>(c.h0.x, c.h1.x);
    let vy = vec2<f32>(c.h0.y, c.h1.y);
    let vz = vec2<f32>(c.h0.z, c.h1.z);
    let wx = vec2<f32>(c.g0.x, g1.x);
    let wy = vec2<f32>(c.g0.y, g1.y);
    let wz = vec2<f32>(c.g0.z, g1.z);
    return vec3<f32>(
        channel_of(fetch8(vec2<f32>(c.dh0.x, c.dh1.x), vec2<f32>(c.dg0.x, -c.dg0.x), vy, wy, vz, wz), true),
        channel_of(fetch8(vx, wx, vec2<f32>(c.dh0.y, c.dh1.y), vec2<f32>(c.dg0.y, -c.dg0.y), vz, wz), true),
        channel_of(fetch8(vx, wx, vy, wy, vec2<f32>(c.dh0.z, c.dh1.z), vec2<f32>(c.dg0.z, -c.dg0.z)), true));
}

// HU at continuous index `p`, clamped to the grid of voxel centres: trilinear, or the cubic
// B-spline.
fn sample_at(p: vec3<f32>) -> f32 {
    if cubic_sampling() {
        return cubic_value(p);
    }
    let d = vec3<f32>(dp.dims);
    let q = clamp(p, vec3<f32>(0.0), d - 1.0);
    return fetch(q);
}

// Both channels at continuous index `p`, clamped to the grid, as sample_at reads the first.
fn sample_both(p: vec3<f32>) -> vec2<f32> {
    if cubic_sampling() {
        return cubic_both(p);
    }
    let d = vec3<f32>(dp.dims);
    return fetch_both(clamp(p, vec3<f32>(0.0), d - 1.0));
}

// The world gradient (HU per mm) at index `p`, as the CPU's Marcher::gradient: central
// differences of trilinear samples, or the voxels' cubic B-spline's.
fn gradient_at(p: vec3<f32>) -> vec3<f32> {
    var g: vec3<f32>;
    if cubic_sampling() {
        g = cubic_gradient(p);
    } else {
        g = vec3<f32>(
            sample_at(p + vec3<f32>(1.0, 0.0, 0.0)) - sample_at(p - vec3<f32>(1.0, 0.0, 0.0)),
            sample_at(p + vec3<f32>(0.0, 1.0, 0.0)) - sample_at(p - vec3<f32>(0.0, 1.0, 0.0)),
            sample_at(p + vec3<f32>(0.0, 0.0, 1.0)) - sample_at(p - vec3<f32>(0.0, 0.0, 1.0))) * 0.5;
    }
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

// Where index point `p` (ray parameter t, lattice t0 + (k + jit) step) lies in a transparent
// brick: the first lattice index past it (at least k + 1); else k.
fn skip_brick(p: vec3<f32>, t: f32, t0: f32, d_idx: vec3<f32>, step: f32, jit: f32, k: u32) -> u32 {
    let b = min(vec3<u32>(max(p, vec3<f32>(0.0))) / BRICK, dp.bricks - 1u);
    if brick_visible[b.x + dp.bricks.x * (b.y + dp.bricks.y * b.z)] != 0u {
        return k;
    }
    let t_exit = cell_exit_t(p, t, d_idx, b, BRICK);
    return max(u32(max(ceil((t_exit - t0) / step - jit), 0.0)), k + 1u);
}

// Where the ray p + (s - t) d_idx leaves cell `b` of `cell`³ voxel spacings (as the CPU's
// raystream_cpu::dvr::cell_exit).
fn cell_exit_t(p: vec3<f32>, t: f32, d_idx: vec3<f32>, b: vec3<u32>, cell: u32) -> f32 {
    var t_exit = bitcast<f32>(0x7f800000u);
    for (var a = 0u; a < 3u; a++) {
        if d_idx[a] == 0.0 {
            continue;
        }
        var bound = f32(b[a] * cell);
        if d_idx[a] > 0.0 {
            bound = f32((b[a] + 1u) * cell);
        }
        t_exit = min(t_exit, t + (bound - p[a]) / d_idx[a]);
    }
    return t_exit;
}

// Transmittance over [t0, t1] (mm) of the ray o_idx + t d_idx on the lattice
// t0 + (k + jit) step, skipping transparent bricks, as the CPU's Marcher::absorb.
fn absorb(o_idx: vec3<f32>, d_idx: vec3<f32>, t0: f32, t1: f32, step: f32, jit: f32) -> f32 {
    var tr = 1.0;
    var k = 0u;
    loop {
        let start = t0 + f32(k) * step;
        if start >= t1 {
            break;
        }
        let t = min(t0 + (f32(k) + jit) * step, t1);
        let q = o_idx + d_idx * t;
        if dp.skip_empty != 0u {
            let next = skip_brick(q, t, t0, d_idx, step, jit, k);
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


fn light_value(base: u32, i: u32, j: u32, k: u32) -> f32 {
    let g = dp.light_dims;
    return light_values[base + min(i, g.x - 1u) + g.x * (min(j, g.y - 1u) + g.y * min(k, g.z - 1u))];
}

// The light reaching index `p` through the grid whose values start at `base`: trilinear
// between grid points, as LightGrid::at.
fn light_at(p: vec3<f32>, base: u32) -> f32 {
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
    let x0 = mix(light_value(base, lo.x, lo.y, lo.z), light_value(base, lo.x + 1u, lo.y, lo.z), f.x);
    let x1 = mix(light_value(base, lo.x, lo.y + 1u, lo.z), light_value(base, lo.x + 1u, lo.y + 1u, lo.z), f.x);
    let x2 = mix(light_value(base, lo.x, lo.y, lo.z + 1u), light_value(base, lo.x + 1u, lo.y, lo.z + 1u), f.x);
    let x3 = mix(light_value(base, lo.x, lo.y + 1u, lo.z + 1u), light_value(base, lo.x + 1u, lo.y + 1u, lo.z + 1u), f.x);
    return mix(mix(x0, x1, f.y), mix(x2, x3, f.y), f.z);
}

// What compositing a stretch of a ray gave: colour, transmittance, samples taken.
struct Composited {
    color: vec3<f32>,
    transmit: f32,
    taken: u32,
}

// Front-to-back emission-absorption over [t0, t1] (mm) of the world ray o + t d (unit d;
// o_idx, d_idx its index form) on the lattice t0 + (k + jit) step, as the CPU's
// Marcher::composite: opacity per mm corrected for the step, the last segment clipped,
// transparent bricks skipped, early termination below 1 % transmittance.
fn composite(o: vec3<f32>, d: vec3<f32>, o_idx: vec3<f32>, d_idx: vec3<f32>, t0: f32, t1: f32, jit: f32) -> Composited {
    let step = dp.step;
    var c = vec3<f32>(0.0);
    var transmit = 1.0;
    var taken = 0u;
    var k = 0u;
    loop {
        let start = t0 + f32(k) * step;
        if start >= t1 {
            break;
        }
        let t = min(t0 + (f32(k) + jit) * step, t1);
        let seg = min(step, t1 - start);
        let p = o_idx + d_idx * t;
        if dp.skip_empty != 0u {
            let next = skip_brick(p, t, t0, d_idx, step, jit, k);
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
        c += transmit * a * shade_sample(painted(color_at(v), p), p, o + d * t, d);
        transmit *= 1.0 - a;
        if transmit < 0.01 {
            break;
        }
    }
    return Composited(c, transmit, taken);
}
