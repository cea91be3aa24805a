//! Watertight ray–triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)). Rays through a shared edge or vertex hit at least one of the
//! triangles sharing it, so closed meshes have no cracks.
//!
//! Contract: a hit needs a finite `t` with `t_min ≤ t ≤ t_max`; edges count as inside;
//! degenerate triangles and rays in the triangle's plane never hit. `u`, `v` are the weights of
//! v1 and v2.

use raystream_math::{Ray, Vec3};

use crate::layout::KdTri;

/// Per-ray constants of the watertight test: the axis permutation (kx, ky, kz), the origin in
/// its order and the shear.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    k: [usize; 3],
    /// The origin along kx, ky, kz.
    origin: [f32; 3],
    shear: [f32; 3],
}

impl WatertightRay {
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        // As arrays: glam's `Vec3` indexing by a run-time axis branches on it (a per-ray cost
        // callgrind counts: 0.9 M of the 17.8 M instructions of 19,200 primary rays' walks).
        let d = ray.dir.to_array();
        let a = ray.dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let o = ray.origin.to_array();
        Self {
            k: [kx, ky, kz],
            origin: [o[kx], o[ky], o[kz]],
            shear: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]],
        }
    }

    /// `(t, u, v)` of a hit with `t_min ≤ t ≤ t_max`, else `None`.
    #[inline(always)]
    pub fn intersect(
        &self,
        v0: Vec3,
        v1: Vec3,
        v2: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        // Arrays, as in `new`: no branch on the run-time axis.
        let (v0, v1, v2) = (v0.to_array(), v1.to_array(), v2.to_array());
        let along = |k: usize| [v0[k], v1[k], v2[k]];
        let [kx, ky, kz] = self.k;
        self.solve(along(kx), along(ky), along(kz), t_min, t_max)
    }

    /// [`Self::intersect`] of a leaf's triangle, its rows read in the ray's order of the axes.
    #[inline(always)]
    pub fn intersect_tri(&self, tri: &KdTri, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        // `min(2)`: k is below 3, and the compiler need not check it.
        let along = |k: usize| {
            let [a, b, c, _] = tri.axes[k.min(2)];
            [a, b, c]
        };
        let [kx, ky, kz] = self.k;
        self.solve(along(kx), along(ky), along(kz), t_min, t_max)
    }

    /// The test of a triangle given by its corners' coordinates along kx, ky and kz.
    #[inline(always)]
    fn solve(
        &self,
        x: [f32; 3],
        y: [f32; 3],
        z: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let [sx, sy, sz] = self.shear;
        let [ox, oy, oz] = self.origin;
        let (az, bz, cz) = (z[0] - oz, z[1] - oz, z[2] - oz);
        let ax = (x[0] - ox) - sx * az;
        let ay = (y[0] - oy) - sy * az;
        let bx = (x[1] - ox) - sx * bz;
        let by = (y[1] - oy) - sy * bz;
        let cx = (x[2] - ox) - sx * cz;
        let cy = (y[2] - oy) - sy * cz;
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // Non-short-circuit `|` and `&` below: these signs are unpredictable, so flags
        // combined without branches are faster than early exits.
        if (u == 0.0) | (v == 0.0) | (w == 0.0) {
            // On an edge in single precision: decide it in double, as the paper prescribes.
            let (ax, ay, bx, by, cx, cy) = (
                ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
            );
            u = (cx * by - cy * bx) as f32;
            v = (ax * cy - ay * cx) as f32;
            w = (bx * ay - by * ax) as f32;
        }
        if ((u < 0.0) | (v < 0.0) | (w < 0.0)) & ((u > 0.0) | (v > 0.0) | (w > 0.0)) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        // A ray all but parallel to the plane may reach it at infinity: no hit.
        let t = plane_t(x, y, z, [ox, oy, oz], [sx, sy, sz]);
        if !(t >= t_min && t <= t_max && t.is_finite()) {
            return None;
        }
        let inv = 1.0 / det;
        Some((t, v * inv, w * inv))
    }
}

/// How far `plane_t` trusts f32: where the corner's offset from the origin times the edges'
/// lengths exceeds this many times the plane's distance times the normal's length
/// (`|r|·|e1|·|e2| > L·|n·r|`, lengths by their largest component, all as the f32 test computes
/// them), the plane is computed again in f64 (`plane_t_f64`; on the GPU where the adapter has
/// f64, kdtree.wgsl). The f32 normal is only as good as its edges' rounding: the plane turns
/// by about one rounding about the corner it is taken through, and a corner 5 × 10⁶ away moves
/// it by about 0.3 where the ray starts, so that a huge ground quad turned 0.3° was hit at t
/// off by more than the camera's height above it, behind the camera or not at all
/// (`scripts/sliver-model.py`: 9,833 of 17,984 rays missed it, 4,051 that point away hit it).
/// The f32 t's relative error is a few 2⁻²⁴ of the ratio at most. On the standard 640×480
/// sets of the meshes in ../shared/data/meshes, 232 of 5.6 M tests exceed 2¹⁰ (secondary rays
/// leaving a surface, whose distance to its plane is small), so that a GPU's warp all but
/// never waits for f64.
pub const PLANE_T_LEVER: f32 = 1024.0;

/// The distance along the ray to the plane of the triangle with corners' coordinates `x`, `y`,
/// `z` along the ray's axes kx, ky, kz, from the origin `o` in that order, with the ray's
/// `shear` (its direction is `(sx, sy, 1) / sz` in that order): the plane's normal from the
/// corners' edges, `t = sz · n·(a − o) / n·(sx, sy, 1)`; in f64 where f32 cannot be trusted
/// ([`PLANE_T_LEVER`]).
///
/// Not the paper's `t = sz · (u·az + v·bz + w·cz) / det`: that interpolates the corners'
/// depths by the edge functions, which cancel where the triangle's projection along the ray
/// is a sliver, far longer than wide (a ground plane seen at a grazing angle: a 5 × 10⁶ quad
/// seen 7° from its plane had its edge functions 10⁻³ off and missed 16 % of the rays that
/// hit it, the others' t off by up to 25×, where Embree's plane-based t was right). The edge
/// functions still decide the hit, so the test stays watertight.
#[inline(always)]
fn plane_t(x: [f32; 3], y: [f32; 3], z: [f32; 3], o: [f32; 3], shear: [f32; 3]) -> f32 {
    let (along, facing, [e1, e2, r]) = plane_terms(x, y, z, o, shear);
    // The same products in the same order as kdtree.wgsl, so that both take the same path.
    // Lengths by their largest component: within the input's ±10¹⁰ nothing overflows, and a
    // scene scaled by a power of two takes the same path everywhere (squared lengths, cheaper
    // on lavapipe, overflow from about 10⁶, and the picture changed with the scale).
    if largest(e1) * largest(e2) * largest(r) > PLANE_T_LEVER * along.abs() {
        return plane_t_f64(x, y, z, o, shear);
    }
    shear[2] * (along / facing)
}

/// `plane_t`'s `n·(a − o)` and `n·(sx, sy, 1)`, with the edges e1, e2 and `r = a − o`, in
/// `T`'s arithmetic: f32 for the test, f64 where f32 cannot place the plane.
#[inline(always)]
fn plane_terms<T>(x: [T; 3], y: [T; 3], z: [T; 3], o: [T; 3], shear: [T; 3]) -> (T, T, [[T; 3]; 3])
where
    T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + std::ops::Mul<Output = T>,
{
    let e1 = [x[1] - x[0], y[1] - y[0], z[1] - z[0]];
    let e2 = [x[2] - x[0], y[2] - y[0], z[2] - z[0]];
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let r = [x[0] - o[0], y[0] - o[1], z[0] - o[2]];
    let along = n[0] * r[0] + n[1] * r[1] + n[2] * r[2];
    let facing = n[0] * shear[0] + n[1] * shear[1] + n[2];
    (along, facing, [e1, e2, r])
}

/// The largest of `v`'s magnitudes.
#[inline(always)]
fn largest(v: [f32; 3]) -> f32 {
    v[0].abs().max(v[1].abs()).max(v[2].abs())
}

/// [`plane_t`] in f64: the edges and the corner's offset from the origin are exact there, the
/// normal's products too, so that only the sums round, 2⁻⁵³ of their terms.
#[cold]
#[inline(never)]
fn plane_t_f64(x: [f32; 3], y: [f32; 3], z: [f32; 3], o: [f32; 3], shear: [f32; 3]) -> f32 {
    let wide = |v: [f32; 3]| v.map(f64::from);
    let (along, facing, _) = plane_terms(wide(x), wide(y), wide(z), wide(o), wide(shear));
    (f64::from(shear[2]) * (along / facing)) as f32
}
