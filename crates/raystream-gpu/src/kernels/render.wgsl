// The stream renderer: the CPU renderer's stages (raystream-cpu/src/lib.rs) as compute kernels
// joined by ray queues on the device. Follows kdtree.wgsl (group 0: the tree and `trace`).
//
//   generate_camera_rays → per depth: intersect_closest → handle_misses → shade_hits
//   → prepare_shadows → intersect_any → accumulate → advance
//
// Queue counters never leave the device: kernels append with atomics, `prepare_shadows` and
// `advance` turn counts into indirect dispatch arguments (and `advance` counts the depth), and
// the host only chooses which queue is read and which written (the paper's "CPU control"),
// either submitting a whole wave's depths at once (an emptied queue dispatches nothing) or
// reading the counts back after each depth to stop early and size the next depth's queues.
//
// The film is deterministic whatever order the atomics give the queues: every contribution is
// rounded to 64-bit fixed point (FILM_SCALE steps per unit) and integer addition does not depend
// on order. FILM_SCALE, MAX_CONTRIBUTION and the counter slots come from the Rust prelude.

// The far end of camera and secondary rays: the largest finite f32 rather than +inf, which
// shader compilers may assume never occurs (the CPU's +inf gives the same hits).
const T_FAR: f32 = 3.40282347e38;

struct RayWork {
    ray: RayIn,
    weight: vec3<f32>,
    pixel: u32,
}

struct ShadowWork {
    ray: RayIn,
    radiance: vec3<f32>,
    pixel: u32,
}

// normal.w: the ray offset of the vertex's object.
struct Vertex {
    position: vec4<f32>,
    normal: vec4<f32>,
}

struct ShadeTri {
    v: vec3<u32>,
    material: u32,
}

struct Material {
    ambient: vec3<f32>,
    reflectivity: f32,
    diffuse: vec3<f32>,
    transparency: f32,
    specular: vec3<f32>,
    shininess: f32,
    ior: f32,
    fresnel: u32,
    // In the texture table; NO_TEXTURE: none.
    texture: u32,
    pad: u32,
}

struct TriCorners {
    a: vec2<f32>,
    b: vec2<f32>,
    c: vec2<f32>,
    // 8-bit sRGB, R in the low byte.
    colour_a: u32,
    colour_b: u32,
    colour_c: u32,
    pad: u32,
}

struct Light {
    position: vec4<f32>,
    color: vec4<f32>,
}

struct RenderParams {
    eye: vec3<f32>,
    tan_y: f32,
    fwd: vec3<f32>,
    width: u32,
    right: vec3<f32>,
    height: u32,
    up: vec3<f32>,
    spp: u32,
    background: vec3<f32>,
    strata: u32,
    ambient_light: vec3<f32>,
    // Half the view's height of a parallel projection; 0: perspective (Camera::parallel).
    parallel: f32,
    sample_base: u32,
    sample_count: u32,
    max_depth: u32,
    light_count: u32,
    max_groups: u32,
    // Rows per band of the camera rays' pixel order (1: row by row).
    band: u32,
    // 1: triangles take their corners' colours (tri_corners).
    coloured: u32,
    pad: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
@group(1) @binding(1) var<storage, read> vertices: array<Vertex>;
@group(1) @binding(2) var<storage, read> shade_tris: array<ShadeTri>;
@group(1) @binding(3) var<storage, read> materials: array<Material>;
@group(1) @binding(4) var<storage, read> lights: array<Light>;
@group(1) @binding(5) var<storage, read> tri_corners: array<TriCorners>;
// The sRGB table, each texture's (first texel, width, height, clamp, scale, offset) from
// TEXTURE_INFO, the texels (layout.rs says how).
@group(1) @binding(6) var<storage, read> textures: array<u32>;

@group(2) @binding(0) var<storage, read_write> counters: array<atomic<u32>, COUNTER_SLOTS>;
@group(2) @binding(1) var<storage, read_write> queue_in: array<RayWork>;
@group(2) @binding(2) var<storage, read_write> hits: array<HitOut>;
@group(2) @binding(3) var<storage, read_write> queue_out: array<RayWork>;
@group(2) @binding(4) var<storage, read_write> shadows: array<ShadowWork>;
@group(2) @binding(5) var<storage, read_write> film: array<atomic<u32>>;

// Only `prepare_shadows` and `advance` bind it: the other kernels are dispatched from it.
@group(3) @binding(0) var<storage, read_write> args: array<u32, 6>;

// Adds `c` to the pixel's 64-bit fixed-point sums (lo word, then a carry into the hi word).
fn add_film(pixel: u32, c: vec3<f32>) {
    for (var ch = 0u; ch < 3u; ch++) {
        let x = c[ch];
        if !(x > 0.0) || not_finite(x) {
            continue;
        }
        let v = u32(round(min(x, MAX_CONTRIBUTION) * FILM_SCALE));
        let slot = (pixel * 3u + ch) * 2u;
        let old = atomicAdd(&film[slot], v);
        if old + v < old {
            atomicAdd(&film[slot + 1u], 1u);
        }
    }
}

// Indirect dispatch arguments for `n` items at `at` in `args`.
fn write_args(at: u32, n: u32) {
    let groups = (n + WORKGROUP_SIZE - 1u) / WORKGROUP_SIZE;
    let gx = min(groups, rp.max_groups);
    var gy = 0u;
    if gx > 0u {
        gy = (groups + gx - 1u) / gx;
    }
    args[at] = gx;
    args[at + 1u] = gy;
    args[at + 2u] = 1u;
}

// The pixel that comes `k`th in the camera rays' order: row by row when rp.band is 1; else
// in bands of rp.band rows (the last band may be shorter), each band column by column, so that
// a subgroup's consecutive pixels form a block rather than a strip of one row.
fn pixel_in_order(k: u32) -> u32 {
    if rp.band <= 1u {
        return k;
    }
    let band_pixels = rp.width * rp.band;
    let band = k / band_pixels;
    let first_row = band * rp.band;
    let rows = min(rp.band, rp.height - first_row);
    let j = k - band * band_pixels;
    return (first_row + j % rows) * rp.width + j / rows;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn generate_camera_rays(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i >= rp.sample_count {
        return;
    }
    let idx = rp.sample_base + i;
    let pixel = pixel_in_order(idx / rp.spp);
    let s = idx % rp.spp;
    var j = vec2<f32>(0.5, 0.5);
    if rp.spp > 1u {
        let n = f32(rp.strata);
        j = vec2<f32>((f32(s % rp.strata) + jitter(pixel, s, 0u)) / n, (f32(s / rp.strata) + jitter(pixel, s, 1u)) / n);
    }
    let w = f32(rp.width);
    let h = f32(rp.height);
    let x = f32(pixel % rp.width) + j.x;
    let y = f32(pixel / rp.width) + j.y;
    // As raystream_scene::Camera::ray.
    if rp.parallel > 0.0 {
        let sx = (x / w * 2.0 - 1.0) * (w / h);
        let sy = 1.0 - y / h * 2.0;
        let o = rp.eye + (sx * rp.right + sy * rp.up) * rp.parallel;
        queue_in[i] = RayWork(RayIn(o, 0.0, rp.fwd, T_FAR), vec3<f32>(1.0), pixel);
        return;
    }
    let px = (x / w * 2.0 - 1.0) * rp.tan_y * (w / h);
    let py = (1.0 - y / h * 2.0) * rp.tan_y;
    let d = normalize(rp.fwd + px * rp.right + py * rp.up);
    queue_in[i] = RayWork(RayIn(rp.eye, 0.0, d, T_FAR), vec3<f32>(1.0), pixel);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_closest(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < atomicLoad(&counters[QUEUE]) {
        hits[i] = trace(queue_in[i].ray, false);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn handle_misses(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < atomicLoad(&counters[QUEUE]) && hits[i].prim == NO_PRIM {
        let w = queue_in[i];
        add_film(w.pixel, w.weight * rp.background);
    }
}

fn schlick(cos_i: f32, n1: f32, n2: f32) -> f32 {
    let r = (n1 - n2) / (n1 + n2);
    let r0 = r * r;
    let m = 1.0 - cos_i;
    return r0 + (1.0 - r0) * (m * m * m * m * m);
}

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 && !not_finite(l) {
        return v / l;
    }
    return vec3<f32>(0.0);
}

// A texel index along an axis of n texels: repeating, or clamped to the edge.
fn texel_index(i: i32, n: i32, cl: bool) -> i32 {
    if cl {
        return clamp(i, 0, n - 1);
    }
    return ((i % n) + n) % n;
}

// A texel of a texture (first texel `base`, w × h), in linear light.
fn texel(base: u32, w: i32, h: i32, cl: bool, i: i32, j: i32) -> vec3<f32> {
    let ii = texel_index(i, w, cl);
    let jj = texel_index(j, h, cl);
    return linear_rgb8(textures[base + u32(jj * w + ii)]);
}

// A packed 8-bit sRGB colour (R in the low byte) in linear light, by the table's start.
fn linear_rgb8(t: u32) -> vec3<f32> {
    return vec3<f32>(
        bitcast<f32>(textures[t & 0xffu]),
        bitcast<f32>(textures[(t >> 8u) & 0xffu]),
        bitcast<f32>(textures[(t >> 16u) & 0xffu]),
    );
}

fn fold_unit(t: f32, cl: bool) -> f32 {
    if not_finite(t) {
        return 0.0;
    }
    if cl {
        return clamp(t, 0.0, 1.0);
    }
    return t - floor(t);
}

// raystream_io::Texture::sample, step for step: texture `k`'s linear colour at `uv` (scaled
// and offset; repeating or clamped; v up; bilinear between texel centres).
fn texture_colour(k: u32, uv_in: vec2<f32>) -> vec3<f32> {
    let info = TEXTURE_INFO + TEXTURE_INFO_WORDS * k;
    let base = textures[info];
    let w = i32(textures[info + 1u]);
    let h = i32(textures[info + 2u]);
    let cl = textures[info + 3u] != 0u;
    let scale = vec2<f32>(bitcast<f32>(textures[info + 4u]), bitcast<f32>(textures[info + 5u]));
    let offset = vec2<f32>(bitcast<f32>(textures[info + 6u]), bitcast<f32>(textures[info + 7u]));
    let uv = uv_in * scale + offset;
    let x = fold_unit(uv.x, cl) * f32(w) - 0.5;
    let y = (1.0 - fold_unit(uv.y, cl)) * f32(h) - 0.5;
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let i0 = i32(x0);
    let j0 = i32(y0);
    let top = lerp3(texel(base, w, h, cl, i0, j0), texel(base, w, h, cl, i0 + 1, j0), fx);
    let bottom = lerp3(texel(base, w, h, cl, i0, j0 + 1), texel(base, w, h, cl, i0 + 1, j0 + 1), fx);
    return lerp3(top, bottom, fy);
}

struct Surface {
    p: vec3<f32>,
    offset: f32,
    ng: vec3<f32>,
    ns: vec3<f32>,
    outside: bool,
    dir: vec3<f32>,
}

// As raystream-cpu's `surface`: both normals face the ray; a shading normal facing away from
// the ray falls back to the geometric one.
fn surface(w: RayWork, h: HitOut) -> Surface {
    let t = shade_tris[h.prim];
    let a = vertices[t.v.x];
    let b = vertices[t.v.y];
    let c = vertices[t.v.z];
    let dir = normalize(w.ray.dir);
    var ng = normalize(cross(b.position.xyz - a.position.xyz, c.position.xyz - a.position.xyz));
    var ns = normalize_or_zero(a.normal.xyz * (1.0 - h.u - h.v) + b.normal.xyz * h.u + c.normal.xyz * h.v);
    if all(ns == vec3<f32>(0.0)) {
        ns = ng;
    }
    let outside = dot(ng, dir) < 0.0;
    if !outside {
        ng = -ng;
        ns = -ns;
    }
    if dot(ns, dir) >= 0.0 {
        ns = ng;
    }
    // The hit point moved onto the triangle's plane, as raystream-cpu's `on_plane`.
    let q = w.ray.origin + w.ray.dir * h.t;
    let p = q - ng * dot(q - a.position.xyz, ng);
    return Surface(p, a.normal.w, ng, ns, outside, dir);
}

// (local, reflected, transmitted) and the refracted direction (w = 1 when there is one).
struct Split {
    local: f32,
    r: f32,
    t: f32,
    refr: vec4<f32>,
}

fn coefficients(m: Material, s: Surface) -> Split {
    let local = 1.0 - m.reflectivity - m.transparency;
    if m.transparency <= 0.0 {
        return Split(local, m.reflectivity, 0.0, vec4<f32>(0.0));
    }
    var n1 = m.ior;
    var n2 = 1.0;
    if s.outside {
        n1 = 1.0;
        n2 = m.ior;
    }
    let eta = n1 / n2;
    let cos_i = -dot(s.dir, s.ns);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return Split(local, m.reflectivity + m.transparency, 0.0, vec4<f32>(0.0));
    }
    let d = eta * s.dir + (eta * cos_i - sqrt(k)) * s.ns;
    var f = 0.0;
    if m.fresnel != 0u {
        f = schlick(cos_i, n1, n2);
    }
    return Split(local, m.reflectivity + m.transparency * f, m.transparency * (1.0 - f), vec4<f32>(d, 1.0));
}

fn reflect_about(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - 2.0 * dot(d, n) * n;
}

fn max_element(v: vec3<f32>) -> f32 {
    return max(v.x, max(v.y, v.z));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn shade_hits(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i >= atomicLoad(&counters[QUEUE]) {
        return;
    }
    let h = hits[i];
    if h.prim == NO_PRIM {
        return;
    }
    // From here on every lane that hit appends together (`append`, from the Rust prelude,
    // may reserve a subgroup's slots at once): no lane leaves before the last append but all
    // together, at the depth limit.
    _ = append(HITS, 1u);
    let w = queue_in[i];
    let s = surface(w, h);
    let m = materials[shade_tris[h.prim].material];
    let split = coefficients(m, s);
    let k = split.local;
    // A texture tints the ambient and diffuse colours (MTL: `map_Kd` multiplies `Kd`), as do
    // the file's vertex colours.
    var tint = vec3<f32>(1.0);
    if m.texture != NO_TEXTURE {
        let uv = tri_corners[h.prim];
        tint = texture_colour(m.texture, uv.a * (1.0 - h.u - h.v) + uv.b * h.u + uv.c * h.v);
    }
    if rp.coloured != 0u {
        let k = tri_corners[h.prim];
        tint *= linear_rgb8(k.colour_a) * (1.0 - h.u - h.v) + linear_rgb8(k.colour_b) * h.u + linear_rgb8(k.colour_c) * h.v;
    }
    let ambient = m.ambient * tint;
    let diffuse = m.diffuse * tint;
    add_film(w.pixel, w.weight * k * ambient * rp.ambient_light);

    // Diffuse and specular, behind one shadow ray per light.
    let origin = s.p + s.ng * s.offset;
    let wk = w.weight * k;
    for (var li = 0u; li < rp.light_count; li++) {
        let light = lights[li];
        let to_light = light.position.xyz - origin;
        let l = normalize(to_light);
        let cos = dot(s.ns, l);
        let lit = !(cos <= 0.0 || dot(s.ng, to_light) <= 0.0 || k <= 0.0);
        let at = append(SHADOWS, select(0u, 1u, lit));
        if lit {
            let rd = max(dot(reflect_about(-l, s.ns), -s.dir), 0.0);
            var spec = 0.0;
            if rd > 0.0 {
                spec = pow(rd, m.shininess);
            }
            let radiance = wk * (diffuse * cos + m.specular * spec) * light.color.xyz;
            shadows[at] = ShadowWork(RayIn(origin, 0.0, to_light, 1.0 - 1e-4), radiance, w.pixel);
        }
    }

    // The same for every lane: the depth this dispatch shades.
    if atomicLoad(&counters[DEPTH]) >= rp.max_depth {
        return;
    }
    let strongest = max_element(w.weight);
    let reflects = split.r * strongest > 1e-3;
    let refracts = split.refr.w != 0.0 && split.t * strongest > 1e-3;
    var at = append(NEXT, select(0u, 1u, reflects) + select(0u, 1u, refracts));
    if reflects {
        var d = reflect_about(s.dir, s.ns);
        if dot(d, s.ng) <= 0.0 {
            d = reflect_about(s.dir, s.ng);
        }
        queue_out[at] = RayWork(RayIn(s.p + s.ng * s.offset, 0.0, d, T_FAR), w.weight * split.r, w.pixel);
        at += 1u;
    }
    if refracts {
        queue_out[at] = RayWork(RayIn(s.p - s.ng * s.offset, 0.0, split.refr.xyz, T_FAR), w.weight * split.t, w.pixel);
    }
}

@compute @workgroup_size(1)
fn prepare_shadows() {
    write_args(3u, atomicLoad(&counters[SHADOWS]));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn intersect_any(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < atomicLoad(&counters[SHADOWS]) {
        hits[i] = trace(shadows[i].ray, true);
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn accumulate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = ray_index(gid, groups);
    if i < atomicLoad(&counters[SHADOWS]) && hits[i].prim == NO_PRIM {
        let s = shadows[i];
        add_film(s.pixel, s.radiance);
    }
}

// Ends a depth: its counts go to the statistics slots, the next queue becomes the current one.
@compute @workgroup_size(1)
fn advance() {
    let next = atomicLoad(&counters[NEXT]);
    atomicStore(&counters[STAT_RAYS], atomicLoad(&counters[QUEUE]));
    atomicStore(&counters[STAT_HITS], atomicLoad(&counters[HITS]));
    atomicStore(&counters[STAT_SHADOWS], atomicLoad(&counters[SHADOWS]));
    atomicStore(&counters[QUEUE], next);
    atomicStore(&counters[NEXT], 0u);
    atomicStore(&counters[SHADOWS], 0u);
    atomicStore(&counters[HITS], 0u);
    atomicAdd(&counters[DEPTH], 1u);
    write_args(0u, next);
}
