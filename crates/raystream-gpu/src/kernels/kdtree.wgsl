// The kd-tree on the GPU: its flat layout (uploaded unchanged) and `trace`, the stackless
// traversal with ropes and the watertight triangle test, the same algorithm as raystream-accel's
// CPU `ropes` traversal (traverse.rs, intersect.rs). Shared by the ray-query kernels
// (queries.wgsl) and the stream renderer (render.wgsl), which bind the tree as group 0.
// The struct layouts mirror raystream-accel's layout.rs and this crate's layout.rs; a
// naga-based test checks every offset and size.

// LEAF_BIT, NO_ROPE, NO_PRIM and WORKGROUP_SIZE come from the prelude that lib.rs generates
// from the Rust constants.

struct KdInner {
    split: f32,
    axis: u32,
    left: u32,
    right: u32,
}

struct KdLeaf {
    bmin: vec3<f32>,
    first: u32,
    bmax: vec3<f32>,
    count: u32,
    ropes: array<u32, 6>,
    pad: array<u32, 2>,
}

// By axis: axes[k] = the three corners' coordinates along axis k, axes[0].w the prim id's bits.
struct KdTri {
    axes: array<vec4<f32>, 3>,
}

struct RayIn {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
}

struct HitOut {
    t: f32,
    prim: u32,
    u: f32,
    v: f32,
}

struct Params {
    ray_count: u32,
    root: u32,
    max_steps: u32,
    tri_count: u32,
    scene_min: vec3<f32>,
    entry_margin: f32,
    scene_max: vec3<f32>,
    entry_reach: f32,
    entry_scale: vec4<f32>,
    entry_res: vec4<u32>,
}

// The tree: bindings 0-4 of group 0 in every kernel that traces.
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> inners: array<KdInner>;
@group(0) @binding(2) var<storage, read> leaves: array<KdLeaf>;
@group(0) @binding(3) var<storage, read> tris: array<KdTri>;
// The entry grid's cells (raystream-accel's entry.rs), x fastest.
@group(0) @binding(4) var<storage, read> entry_cells: array<u32>;


// NaN and infinity by their bits: shader compilers may assume float arithmetic is finite.
fn not_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) == 0x7f800000u;
}

fn is_nan(x: f32) -> bool {
    return not_finite(x) && (bitcast<u32>(x) & 0x007fffffu) != 0u;
}

fn ray_is_valid(r: RayIn) -> bool {
    let o = r.origin;
    let d = r.dir;
    if not_finite(o.x) || not_finite(o.y) || not_finite(o.z) || not_finite(d.x) || not_finite(d.y)
        || not_finite(d.z) || not_finite(r.t_min) || is_nan(r.t_max) {
        return false;
    }
    if d.x == 0.0 && d.y == 0.0 && d.z == 0.0 {
        return false;
    }
    return r.t_min <= r.t_max;
}

// The watertight test's per-ray constants: the axis permutation (kx, ky, kz), the origin along
// kx, ky, kz, and the shear.
struct Watertight {
    k: vec3<u32>,
    o: vec3<f32>,
    shear: vec3<f32>,
}

fn watertight_ray(r: RayIn) -> Watertight {
    let a = abs(r.dir);
    var kz = 2u;
    if a.x >= a.y && a.x >= a.z {
        kz = 0u;
    } else if a.y >= a.z {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kx + 1u) % 3u;
    if r.dir[kz] < 0.0 {
        let t = kx;
        kx = ky;
        ky = t;
    }
    let d = r.dir;
    let o = r.origin;
    return Watertight(vec3<u32>(kx, ky, kz), vec3<f32>(o[kx], o[ky], o[kz]),
        vec3<f32>(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]));
}

// (t, u, v, 1) of a hit of triangle entry `i` with t_min <= t <= t_max, or w = 0 on a miss
// (Woop, Benthin & Wald 2013). Its rows are read in the ray's order of the axes, each with the
// ray's axis as its index, and each holds the three corners: the arithmetic is the CPU's
// (intersect.rs), three corners at a time.
fn intersect_triangle(w: Watertight, i: u32, t_min: f32, t_max: f32) -> vec4<f32> {
    let rx = tris[i].axes[w.k.x].xyz;
    let ry = tris[i].axes[w.k.y].xyz;
    let rz = tris[i].axes[w.k.z].xyz;
    let z = rz - w.o.z;
    let x = (rx - w.o.x) - w.shear.x * z;
    let y = (ry - w.o.y) - w.shear.y * z;
    // Corners a, b, c are components x, y, z of each.
    let u = x.z * y.y - y.z * x.y;
    let v = x.x * y.z - y.x * x.z;
    let ww = x.y * y.x - y.y * x.x;
    if (u < 0.0 || v < 0.0 || ww < 0.0) && (u > 0.0 || v > 0.0 || ww > 0.0) {
        return vec4<f32>(0.0);
    }
    let det = u + v + ww;
    if det == 0.0 {
        return vec4<f32>(0.0);
    }
    // A ray all but parallel to the plane may reach it at infinity: no hit.
    let t = plane_t(rx, ry, rz, w, t_min, t_max);
    if !(t >= t_min && t <= t_max) || not_finite(t) {
        return vec4<f32>(0.0);
    }
    // One reciprocal for both weights, as the CPU computes them.
    let inv = 1.0 / det;
    return vec4<f32>(t, v * inv, ww * inv, 1.0);
}

// The distance along the ray to the triangle's plane, from its corners' coordinates along kx,
// ky, kz (rows x, y, z): t = sz · n·(a − o) / n·(sx, sy, 1), n from the corners' edges, as
// the CPU computes it (intersect.rs `plane_t`, which says why not the paper's depths
// interpolated by the edge functions: they cancel where the triangle's projection along the
// ray is a sliver, such as a long ground plane seen at a grazing angle). Where the corner's
// offset from the origin times the edges' lengths exceeds PLANE_T_LEVER times |n·r| (a huge
// triangle near the ray's origin: intersect.rs says why), the f32 normal cannot place the
// plane, and `plane_t_wide` computes it again: in f64 where the adapter has it (lib.rs puts
// plane_f64.wgsl's in place of the f32 one below), as the CPU does. Unless the f32 t lies
// outside [t_min, t_max] by more than twice its error bound (PLANE_T_SLACK, intersect.rs):
// the test rejects it whatever f64 says (a ray leaving a surface, its origin a hair off the
// plane of the triangle it left).
fn plane_t(x: vec3<f32>, y: vec3<f32>, z: vec3<f32>, w: Watertight, t_min: f32, t_max: f32) -> f32 {
    let e1 = vec3<f32>(x.y - x.x, y.y - y.x, z.y - z.x);
    let e2 = vec3<f32>(x.z - x.x, y.z - y.x, z.z - z.x);
    let n = vec3<f32>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
    let r = vec3<f32>(x.x - w.o.x, y.x - w.o.y, z.x - w.o.z);
    let along = n.x * r.x + n.y * r.y + n.z * r.z;
    let facing = n.x * w.shear.x + n.y * w.shear.y + n.z;
    var t = w.shear.z * (along / facing);
    if largest(e1) * largest(e2) * largest(r) > PLANE_T_LEVER * abs(along) {
        // The CPU's plane_t_slack; a facing too small to bound, or an overflow (NaN), goes to f64.
        let nb = vec3<f32>(abs(e1.y * e2.z) + abs(e1.z * e2.y), abs(e1.z * e2.x) + abs(e1.x * e2.z),
            abs(e1.x * e2.y) + abs(e1.y * e2.x));
        let ab = nb.x * abs(r.x) + nb.y * abs(r.y) + nb.z * abs(r.z);
        let fb = nb.x * abs(w.shear.x) + nb.y * abs(w.shear.y) + nb.z;
        let f = abs(facing);
        let slack = PLANE_T_SLACK * (abs(w.shear.z) * ab + fb * abs(t)) / f + PLANE_T_SLACK_OF_T * abs(t);
        let outside = t + 2.0 * slack < t_min || t - 2.0 * slack > t_max;
        if !(f > fb * PLANE_T_MIN_FACING && outside) {
            t = plane_t_wide(x, y, z, w, t);
        }
    }
    return t;
}

// The largest of v's magnitudes, as the CPU's.
fn largest(v: vec3<f32>) -> f32 {
    let a = abs(v);
    return max(max(a.x, a.y), a.z);
}

// PLANE_T_WIDE: `plane_t` again, where f32 cannot place the plane, given its f32 `t`; on an
// adapter without f64 that `t` (lib.rs replaces this function up to its closing brace).
fn plane_t_wide(x: vec3<f32>, y: vec3<f32>, z: vec3<f32>, w: Watertight, t: f32) -> f32 {
    return t;
}
// END PLANE_T_WIDE

fn miss_record() -> HitOut {
    return HitOut(bitcast<f32>(0x7f800000u), NO_PRIM, 0.0, 0.0);
}

// A ray prepared for traversal: -0 direction components made +0 (so that "negative" means
// strictly negative, as on the CPU), their inverses, and the watertight test's shear. The
// traversal loop reads a direction's sign from its inverse (1/d < 0 exactly where d < 0, +0
// giving +inf), so that `d` need not stay in registers past the walk's start.
struct Walk {
    o: vec3<f32>,
    d: vec3<f32>,
    inv: vec3<f32>,
    wt: Watertight,
}

fn walk_of(r: RayIn) -> Walk {
    let d = select(r.dir, vec3<f32>(0.0), r.dir == vec3<f32>(0.0));
    return Walk(r.origin, d, 1.0 / d, watertight_ray(r));
}

// The ray's [t0, t1] inside the scene box; t0 > t1 (or NaN) when it misses the box or is invalid.
// The CPU's `Aabb::clip_ray`, its loop over x, y, z on all three axes at once: an axis the ray
// runs parallel to misses the box when its origin lies outside the slab and bounds nothing
// otherwise.
fn clip_to_scene(r: RayIn, w: Walk) -> vec2<f32> {
    let none = vec2<f32>(1.0, 0.0);
    if !ray_is_valid(r) || params.tri_count == 0u {
        return none;
    }
    let parallel = w.d == vec3<f32>(0.0);
    if any(parallel & ((w.o < params.scene_min) | (w.o > params.scene_max))) {
        return none;
    }
    let near = (params.scene_min - w.o) * w.inv;
    let far = (params.scene_max - w.o) * w.inv;
    let swap = near > far;
    let inf = bitcast<f32>(0x7f800000u);
    let lo = select(select(near, far, swap), vec3<f32>(-inf), parallel);
    let hi = select(select(far, near, swap), vec3<f32>(inf), parallel);
    let t0 = max(max(max(r.t_min, lo.x), lo.y), lo.z);
    let t1 = min(min(min(r.t_max, hi.x), hi.y), hi.z);
    return vec2<f32>(t0, t1);
}

// The node where a walk entering at `t0` starts its first descent: its entry point's cell's,
// or the root without a grid or where the lookup's rounding could matter. The same leaf as the
// descent from the root, bit for bit (entry.rs says why); ENTRY_ERROR_SCALE comes from there.
fn entry_node(w: Walk, t0: f32) -> u32 {
    if params.entry_res.x == 0u {
        return params.root;
    }
    let ao = abs(w.o);
    let ad = abs(w.d);
    let err = ENTRY_ERROR_SCALE * (max(max(ao.x, ao.y), ao.z) + abs(t0) * max(max(ad.x, ad.y), ad.z)
        + params.entry_reach);
    if !(err < params.entry_margin) {
        return params.root;
    }
    let res = params.entry_res.xyz;
    let p = w.o + t0 * w.d;
    let c = vec3<u32>(clamp(floor((p - params.scene_min) * params.entry_scale.xyz), vec3<f32>(0.0),
        vec3<f32>(res - 1u)));
    return entry_cells[(c.z * res.y + c.y) * res.x + c.x];
}

// One step from the inner node `node` toward the leaf that holds the ray's point at `t_entry`,
// as the CPU takes it: the plane crossed at or before the entry point puts the point on the far
// side. A ray parallel to the plane (inv = +inf) crosses it at -inf (beyond it: far), +inf or
// NaN (on it or before it: near, unless t_entry is +inf, as on the CPU), so it needs no branch
// of its own.
fn descend_step(node: u32, w: Walk, t_entry: f32) -> u32 {
    stat(STAT_INNER);
    let n = inners[node];
    let a = n.axis;
    let far = (n.split - w.o[a]) * w.inv[a] <= t_entry;
    // far side = right for a positive direction, left for a negative one
    return select(n.left, n.right, far != (w.inv[a] < 0.0));
}

// From `start` down to the leaf that holds the ray's point at `t_entry`.
fn descend(start: u32, w: Walk, t_entry: f32) -> u32 {
    var node = start;
    while (node & LEAF_BIT) == 0u {
        node = descend_step(node, w, t_entry);
    }
    return node;
}

// Tests triangle entry `i` against `best` (whose t, or t_max before any hit, bounds it);
// returns whether `best` changed (with `any_hit`, any hit in range changes it).
fn test_triangle(i: u32, r: RayIn, w: Walk, any_hit: bool, best: ptr<function, HitOut>) -> bool {
    stat(STAT_TRIANGLE);
    var t_best = (*best).t;
    if (*best).prim == NO_PRIM {
        t_best = r.t_max;
    }
    let h = intersect_triangle(w.wt, i, r.t_min, t_best);
    if h.w != 0.0 && (any_hit || h.x < t_best || (*best).prim == NO_PRIM) {
        *best = HitOut(h.x, bitcast<u32>(tris[i].axes[0].w), h.y, h.z);
        return true;
    }
    return false;
}

// A leaf is read field by field where each is needed (its triangle range, then its box, then
// one rope), never as the whole 64-byte struct: loading the struct at once cost lavapipe 5-13 %
// (BENCHMARKS.md), its compiler fetching all 64 bytes.

// Tests the triangles of leaf `li` against `best`; with `any_hit` stops at the first hit.
// Returns whether `best` changed.
fn intersect_leaf(li: u32, r: RayIn, w: Walk, any_hit: bool, best: ptr<function, HitOut>) -> bool {
    var changed = false;
    let first = leaves[li].first;
    let end = first + leaves[li].count;
    for (var i = first; i < end; i++) {
        if test_triangle(i, r, w, any_hit, best) {
            changed = true;
            if any_hit {
                return true;
            }
        }
    }
    return changed;
}

// Where the ray leaves the leaf: (t_exit, the rope to follow), the rope NO_ROPE when the ray
// is done: it left the scene, or its best hit lies inside the leaf.
struct Exit {
    t: f32,
    next: u32,
}

fn leaf_exit(li: u32, w: Walk, best: HitOut, t_max: f32) -> Exit {
    // All three axes at once, as the CPU's loop over x, y, z takes them: an axis the ray runs
    // parallel to (inv = +inf) gives +inf or NaN (the descent keeps the origin inside the
    // leaf's slab of that axis), which never bound the exit, and a tie goes to the first axis
    // (strict <).
    let neg = w.inv < vec3<f32>(0.0);
    let t = (select(leaves[li].bmax, leaves[li].bmin, neg) - w.o) * w.inv;
    let faces = vec3<u32>(1u, 3u, 5u) - vec3<u32>(neg);
    var t_exit = bitcast<f32>(0x7f800000u);
    var face = 0u;
    if t.x < t_exit {
        t_exit = t.x;
        face = faces.x;
    }
    if t.y < t_exit {
        t_exit = t.y;
        face = faces.y;
    }
    if t.z < t_exit {
        t_exit = t.z;
        face = faces.z;
    }
    var t_best = best.t;
    if best.prim == NO_PRIM {
        t_best = t_max;
    }
    if t_best <= t_exit {
        return Exit(t_exit, NO_ROPE);
    }
    return Exit(t_exit, leaves[li].ropes[face]);
}

// The fused query: descend, intersect, follow the rope, in one loop per ray.
fn trace(r: RayIn, any_hit: bool) -> HitOut {
    var best = miss_record();
    let w = walk_of(r);
    let span = clip_to_scene(r, w);
    if !(span.x <= span.y) {
        return best;
    }
    var t_entry = span.x;
    var node = entry_node(w, t_entry);
    for (var step = 0u; step < params.max_steps; step++) {
        node = descend(node, w, t_entry);
        let li = node & ~LEAF_BIT;
        stat(STAT_LEAF);
        stat_listed(leaves[li].count);
        if intersect_leaf(li, r, w, any_hit, &best) && any_hit {
            return best;
        }
        let exit = leaf_exit(li, w, best, r.t_max);
        if exit.next == NO_ROPE {
            return best;
        }
        node = exit.next;
        t_entry = max(t_entry, exit.t);
    }
    return best;
}

// The same query as `trace` in Aila & Laine's "if-if" form: each iteration a lane takes at
// most one traversal step (an inner node, or entering the leaf reached) and at most one
// triangle step (a test, or leaving the leaf by its rope), so lanes in different phases share
// iterations instead of waiting for each other's inner loops ("while-while", `trace`).
// The same steps in the same order: the same hits.
fn trace_ifif(r: RayIn, any_hit: bool) -> HitOut {
    var best = miss_record();
    let w = walk_of(r);
    let span = clip_to_scene(r, w);
    if !(span.x <= span.y) {
        return best;
    }
    var t_entry = span.x;
    var node = entry_node(w, t_entry);
    var li = 0u;
    var next_tri = 0u;
    var end_tri = 0u;
    var in_leaf = false;
    var leaves_left = params.max_steps;
    loop {
        if !in_leaf {
            if (node & LEAF_BIT) == 0u {
                node = descend_step(node, w, t_entry);
            } else {
                li = node & ~LEAF_BIT;
                next_tri = leaves[li].first;
                end_tri = next_tri + leaves[li].count;
                stat(STAT_LEAF);
                stat_listed(end_tri - next_tri);
                in_leaf = true;
            }
        }
        if in_leaf {
            if next_tri < end_tri {
                if test_triangle(next_tri, r, w, any_hit, &best) && any_hit {
                    return best;
                }
                next_tri++;
            } else {
                let exit = leaf_exit(li, w, best, r.t_max);
                leaves_left--;
                if exit.next == NO_ROPE || leaves_left == 0u {
                    return best;
                }
                node = exit.next;
                t_entry = max(t_entry, exit.t);
                in_leaf = false;
            }
        }
    }
    return best;
}

// The work item of invocation `gid` in a dispatch of `groups` (x-major; y when one dimension
// cannot hold the queue).
fn ray_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * WORKGROUP_SIZE;
}

// Work counters of `trace` (`stat(k)` at each inner step, leaf visit and triangle test;
// `stat_listed(n)` with each visited leaf's triangle count). Every module but the statistics
// query (stats.wgsl) defines them as nothing.
const STAT_INNER: u32 = 0u;
const STAT_LEAF: u32 = 1u;
const STAT_TRIANGLE: u32 = 2u;
