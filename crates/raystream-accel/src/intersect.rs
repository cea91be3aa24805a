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
        let [x, y, z] = self.rows(v0, v1, v2);
        self.finish(self.edges(x, y, z).uvw, x, y, z, t_min, t_max)
    }

    /// The corners' coordinates along kx, ky and kz, a row an axis.
    #[inline(always)]
    fn rows(&self, v0: Vec3, v1: Vec3, v2: Vec3) -> [[f32; 3]; 3] {
        // Arrays, as in `new`: no branch on the run-time axis.
        let (v0, v1, v2) = (v0.to_array(), v1.to_array(), v2.to_array());
        self.k.map(|k| [v0[k], v1[k], v2[k]])
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
        #[cfg(target_arch = "x86_64")]
        let uvw = self.edges_sse(tri)?;
        let (x, y, z) = (along(kx), along(ky), along(kz));
        #[cfg(not(target_arch = "x86_64"))]
        let uvw = self.edges(x, y, z).uvw;
        self.finish(uvw, x, y, z, t_min, t_max)
    }

    /// The corners sheared into the ray's frame (the origin at 0, the ray along kz) and their
    /// edge functions.
    #[inline(always)]
    fn edges(&self, x: [f32; 3], y: [f32; 3], z: [f32; 3]) -> Edges {
        let [sx, sy, _] = self.shear;
        let [ox, oy, oz] = self.origin;
        let (az, bz, cz) = (z[0] - oz, z[1] - oz, z[2] - oz);
        let ax = (x[0] - ox) - sx * az;
        let ay = (y[0] - oy) - sy * az;
        let bx = (x[1] - ox) - sx * bz;
        let by = (y[1] - oy) - sy * bz;
        let cx = (x[2] - ox) - sx * cz;
        let cy = (y[2] - oy) - sy * cz;
        Edges {
            uvw: [cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax],
            sheared: [[ax, bx, cx], [ay, by, cy]],
        }
    }

    /// [`Self::edges`]' edge functions of a leaf's triangle, its three corners a lane each
    /// (SSE, in x86-64's baseline, hand-written: LLVM vectorized the scalar form only in
    /// part), the same operations in the same order, so the same bits; `None` where the signs
    /// alone reject the triangle (none zero, some negative, some positive), as most of a walk's
    /// tests end. The scalar form's 30 subtractions and multiplications and nine comparisons
    /// are ten vector operations, four shuffles and three comparisons: 7–15 % fewer
    /// instructions a query, 3–14 % faster on the standard sets (BENCHMARKS.md).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn edges_sse(&self, tri: &KdTri) -> Option<[f32; 3]> {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = self.k;
        let [sx, sy, _] = self.shear;
        let [ox, oy, oz] = self.origin;
        // [1, 2, 0] and [2, 0, 1] in the first three lanes (lane 3 kept in place).
        const NEXT: i32 = 0b11_00_10_01;
        const PREV: i32 = 0b11_01_00_10;
        // SAFETY: SSE and SSE2 are in x86-64's baseline; each load reads a row's 16 bytes.
        unsafe {
            // The rows' fourth lanes (a prim id's bits in row 0) zeroed: no denormals.
            let three = _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1));
            let row = |k: usize| _mm_and_ps(_mm_loadu_ps(tri.axes[k.min(2)].as_ptr()), three);
            let (x, y, z) = (row(kx), row(ky), row(kz));
            let z = _mm_sub_ps(z, _mm_set1_ps(oz));
            let x = _mm_sub_ps(
                _mm_sub_ps(x, _mm_set1_ps(ox)),
                _mm_mul_ps(_mm_set1_ps(sx), z),
            );
            let y = _mm_sub_ps(
                _mm_sub_ps(y, _mm_set1_ps(oy)),
                _mm_mul_ps(_mm_set1_ps(sy), z),
            );
            // u = cx·by − cy·bx, v = ax·cy − ay·cx, w = bx·ay − by·ax.
            let uvw = _mm_sub_ps(
                _mm_mul_ps(_mm_shuffle_ps::<PREV>(x, x), _mm_shuffle_ps::<NEXT>(y, y)),
                _mm_mul_ps(_mm_shuffle_ps::<PREV>(y, y), _mm_shuffle_ps::<NEXT>(x, x)),
            );
            let zero = _mm_setzero_ps();
            let lanes = |m: __m128| _mm_movemask_ps(m) & 7;
            let below = lanes(_mm_cmplt_ps(uvw, zero));
            let above = lanes(_mm_cmpgt_ps(uvw, zero));
            let on = lanes(_mm_cmpeq_ps(uvw, zero));
            if (on == 0) & (below != 0) & (above != 0) {
                return None;
            }
            let mut a = [0f32; 4];
            _mm_storeu_ps(a.as_mut_ptr(), uvw);
            Some([a[0], a[1], a[2]])
        }
    }

    /// The rest of the test of a triangle given by its corners' coordinates along kx, ky and
    /// kz, from its edge functions `uvw` on.
    #[inline(always)]
    fn finish(
        &self,
        uvw: [f32; 3],
        x: [f32; 3],
        y: [f32; 3],
        z: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let [mut u, mut v, mut w] = uvw;
        // Non-short-circuit `|` and `&` below: these signs are unpredictable, so flags
        // combined without branches are faster than early exits.
        if (u == 0.0) | (v == 0.0) | (w == 0.0) {
            // On an edge in single precision: decide it in double, as the paper prescribes,
            // from the sheared corners (computed again: the same bits, and seldom needed).
            let sheared = self.edges(x, y, z).sheared;
            let [[ax, bx, cx], [ay, by, cy]] = sheared.map(|r| r.map(f64::from));
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
        let (o, shear) = (self.origin, self.shear);
        let t = match plane_t(x, y, z, o, shear, t_min, t_max) {
            PlaneT::Near(t) | PlaneT::Outside(t) => t,
            PlaneT::Wide(_) => plane_t_f64(x, y, z, o, shear),
        };
        if !(t >= t_min && t <= t_max && t.is_finite()) {
            return None;
        }
        let inv = 1.0 / det;
        Some((t, v * inv, w * inv))
    }
}

/// A triangle's edge functions u, v, w (the weights of its corners, unnormalized) and its
/// corners sheared into the ray's frame, `[[ax, bx, cx], [ay, by, cy]]`.
#[derive(Clone, Copy)]
struct Edges {
    uvw: [f32; 3],
    sheared: [[f32; 3]; 2],
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
/// never waits for f64. Renders have more: every shadow or reflected ray leaving the default
/// scene's floor (10⁴ wide) exceeds it for the floor it left, 45 % of the tests that passed
/// the edge functions; [`PLANE_T_SLACK`] rejects all but 0.1 % of those in f32.
pub const PLANE_T_LEVER: f32 = 1024.0;

/// What f32 makes of a triangle's plane.
#[derive(Clone, Copy, Debug, PartialEq)]
enum PlaneT {
    /// The t, good to a few 2⁻²⁴ of the lever (below [`PLANE_T_LEVER`]).
    Near(f32),
    /// A t beyond the lever, but outside `[t_min, t_max]` by more than twice its
    /// [`PLANE_T_SLACK`]: rejected, as f64's would be.
    Outside(f32),
    /// The f32 t, which f64 must place again.
    Wide(f32),
}

/// The distance along the ray to the plane of the triangle with corners' coordinates `x`, `y`,
/// `z` along the ray's axes kx, ky, kz, from the origin `o` in that order, with the ray's
/// `shear` (its direction is `(sx, sy, 1) / sz` in that order): the plane's normal from the
/// corners' edges, `t = sz · n·(a − o) / n·(sx, sy, 1)`; `Wide` where f32 cannot be trusted
/// ([`PLANE_T_LEVER`]) and f64 (`plane_t_f64`) must place the plane.
///
/// Not the paper's `t = sz · (u·az + v·bz + w·cz) / det`: that interpolates the corners'
/// depths by the edge functions, which cancel where the triangle's projection along the ray
/// is a sliver, far longer than wide (a ground plane seen at a grazing angle: a 5 × 10⁶ quad
/// seen 7° from its plane had its edge functions 10⁻³ off and missed 16 % of the rays that
/// hit it, the others' t off by up to 25×, where Embree's plane-based t was right). The edge
/// functions still decide the hit, so the test stays watertight.
///
/// Where the f32 t lies outside `[t_min, t_max]` by more than twice its error bound
/// ([`PLANE_T_SLACK`]), the test rejects it whatever f64 would say: `Outside`, and no f64.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn plane_t(
    x: [f32; 3],
    y: [f32; 3],
    z: [f32; 3],
    o: [f32; 3],
    shear: [f32; 3],
    t_min: f32,
    t_max: f32,
) -> PlaneT {
    let (along, facing, [e1, e2, r]) = plane_terms(x, y, z, o, shear);
    let t = shear[2] * (along / facing);
    // The same products in the same order as kdtree.wgsl, so that both take the same path.
    // Lengths by their largest component: within the input's ±10¹⁰ nothing overflows, and a
    // scene scaled by a power of two takes the same path everywhere (squared lengths, cheaper
    // on lavapipe, overflow from about 10⁶, and the picture changed with the scale).
    // (NaN stays in f32, as before.)
    if !(largest(e1) * largest(e2) * largest(r) > PLANE_T_LEVER * along.abs()) {
        return PlaneT::Near(t);
    }
    let slack = plane_t_slack(t, facing, [e1, e2, r], shear);
    // NaN (an overflow, a facing too small to bound) goes to f64.
    if t + 2.0 * slack < t_min || t - 2.0 * slack > t_max {
        PlaneT::Outside(t)
    } else {
        PlaneT::Wide(t)
    }
}

/// A bound on how far `plane_t`'s f32 t can lie from the t of the same corners and ray in
/// exact arithmetic, component by component. With u = 2⁻²⁴, the normal's component
/// n_i = p_i − q_i (p_i, q_i the edges' two products) and N_i = |p_i| + |q_i|:
/// - the edges and `r = a − o` are each off by u of themselves, n_i by 4u·N_i;
/// - `along = n·r` by Δa = 8u·A, A = Σ N_i·|r_i| (each term's inputs and product, two sums);
/// - `facing = n·(sx, sy, 1)` by Δf = 7u·F, F = Σ N_i·|s_i| with s = (sx, sy, 1);
/// - t = sz·along/facing by (|sz|·Δa + |t|·Δf)/(|facing| − Δf) + 2u·|t|, t the exact one.
///   Where |facing| > 2⁻¹⁵·F (Δf under 1/73 of it), that is at most
///   11u·|sz|·A/|facing| + 10u·F·|t|/|facing| + 2.1u·|t| with t the f32 one.
///
/// The slack is 16u·(|sz|·A + F·|t|)/|facing| + 4u·|t| (`PLANE_T_SLACK` = 16u and
/// [`PLANE_T_SLACK_OF_T`]; [`PLANE_T_MIN_FACING`] the 2⁻¹⁵ above): over 1.45
/// times that bound, and NaN where facing is too small for it (f64 decides). The test rejects
/// a t outside [t_min, t_max] by more than twice the slack, so the exact t lies outside by more
/// than 1.3 slack (at least 5u·|t|, more than half an f32 step at the range's end): f64's t,
/// rounded to f32, would be rejected too, and the hits are the same bytes without it.
///
/// The case is a ray leaving a surface, its origin a hair off the plane of the triangle it
/// left: the lever (a corner 5,000 away on a floor 10⁴ wide, a shadow ray 0.0125 above it)
/// sends it to f64, and in a render of the default scene 45 % of the triangles that passed
/// the edge test went there for a t behind the ray. Component by component the floor's
/// normal is one product and `along` does not cancel: the slack is a few u of t. (A bound by
/// the largest components, L(e1)·L(e2)·L(r), was as large as t itself there and skipped
/// nothing.)
pub const PLANE_T_SLACK: f32 = 1.0 / 1_048_576.0;

/// The slack's share of |t| itself (4u = 2⁻²²: the division and the product by sz).
pub const PLANE_T_SLACK_OF_T: f32 = 1.0 / 4_194_304.0;

/// The smallest |facing| the slack holds for, as a share of F (2⁻¹⁵: Δf under 1/73 of it).
pub const PLANE_T_MIN_FACING: f32 = 1.0 / 32_768.0;

/// [`PLANE_T_SLACK`]'s bound for `t`, given `facing` and the edges and the corner's offset
/// `[e1, e2, r]`; NaN where facing is too small for the bound to hold.
#[inline(always)]
fn plane_t_slack(t: f32, facing: f32, [e1, e2, r]: [[f32; 3]; 3], shear: [f32; 3]) -> f32 {
    let n = [
        (e1[1] * e2[2]).abs() + (e1[2] * e2[1]).abs(),
        (e1[2] * e2[0]).abs() + (e1[0] * e2[2]).abs(),
        (e1[0] * e2[1]).abs() + (e1[1] * e2[0]).abs(),
    ];
    let a = n[0] * r[0].abs() + n[1] * r[1].abs() + n[2] * r[2].abs();
    let f = n[0] * shear[0].abs() + n[1] * shear[1].abs() + n[2];
    let facing = facing.abs();
    if !(facing > f * PLANE_T_MIN_FACING) {
        return f32::NAN;
    }
    PLANE_T_SLACK * (shear[2].abs() * a + f * t.abs()) / facing + PLANE_T_SLACK_OF_T * t.abs()
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

#[cfg(test)]
mod tests {
    use super::*;

    use crate::tests::Rng;

    fn vec(rng: &mut Rng) -> Vec3 {
        Vec3::new(rng.next(), rng.next(), rng.next()) * 2.0 - 1.0
    }

    /// 10 to a power between `lo` and `hi`.
    fn pow10(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
        10f32.powf(lo + (hi - lo) * rng.next())
    }

    /// The SSE edge functions of a leaf's triangle are the scalar ones bit for bit (NaN for
    /// NaN), and reject exactly the triangles whose scalar signs reject them: corners from
    /// 10⁻³ to 10⁷ units, on the ray's axes, shared with the origin, the ray through a corner or
    /// along an edge (zeros), non-finite corners, and any prim id in the row's fourth lane.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sse_edge_functions_are_the_scalar_ones() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        let (mut rejected, mut passed, mut zeros) = (0, 0, 0);
        let odd = [0.0, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e-40];
        for case in 0..300_000u32 {
            let scale = pow10(&mut rng, -3.0, 7.0);
            let mut c = [vec(&mut rng), vec(&mut rng), vec(&mut rng)].map(|v| v * scale);
            let origin = vec(&mut rng) * scale * 2.0;
            let mut dir = vec(&mut rng);
            match case % 7 {
                // The ray through a corner, or along an edge's line: zero edge functions.
                0 => dir = c[(case / 7 % 3) as usize] - origin,
                1 => {
                    let t = rng.next();
                    dir = c[0] + (c[1] - c[0]) * t - origin;
                }
                // Coordinates shared with the origin, or on the ray's axes.
                2 => c[1] = origin,
                3 => dir = Vec3::new(0.0, 0.0, if rng.next() < 0.5 { 1.0 } else { -1.0 }),
                4 => {
                    let k = (case / 7 % 9) as usize;
                    c[k / 3][k % 3] = odd[(case / 63 % 6) as usize];
                }
                _ => {}
            }
            let ray = Ray::new(origin, dir, 0.0, f32::INFINITY);
            let prim = match case % 3 {
                0 => case,
                1 => u32::MAX - case,
                _ => (rng.next() * 4e9) as u32,
            };
            let tri = KdTri::new(c.map(|v| v.to_array()), prim);
            let wt = WatertightRay::new(&ray);
            let [x, y, z] = wt.k.map(|k| {
                let [a, b, c, _] = tri.axes[k];
                [a, b, c]
            });
            let want = wt.edges(x, y, z).uvw;
            let zero = want.contains(&0.0);
            let signs = want.iter().any(|&e| e < 0.0) && want.iter().any(|&e| e > 0.0);
            zeros += zero as u32;
            match wt.edges_sse(&tri) {
                None => {
                    assert!(!zero && signs, "case {case}: SSE rejected {want:?}");
                    rejected += 1;
                }
                Some(got) => {
                    assert!(zero || !signs, "case {case}: SSE kept {want:?}");
                    for (g, w) in got.iter().zip(want) {
                        assert!(
                            g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan()),
                            "case {case}: SSE {got:?}, scalar {want:?}"
                        );
                    }
                    passed += 1;
                }
            }
        }
        assert!(
            rejected > 100_000 && passed > 50_000 && zeros > 20_000,
            "{rejected} rejected, {passed} passed, {zeros} with a zero"
        );
    }

    /// Where f32 skips f64 (`Outside`: a t beyond the lever but outside the range by twice its
    /// slack), f64's t is outside the range too, so the test's answer is the same bytes. Rays
    /// leave triangles of 10⁻² to 10⁷ across, lying along the axes or turned, long or not, from
    /// 10⁻⁹ to 10⁻² of their size off their plane, toward it or away, and the range's ends lie
    /// within a few slacks of the f32 t, where a bound too tight would show. A ray leaving a
    /// floor 10⁴ wide 0.0125 above it (the default scene's shadow rays) is `Outside`.
    #[test]
    fn planes_f32_skips_are_rejected_by_f64_too() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (mut outside, mut wide, mut near) = (0, 0, 0);
        for case in 0..400_000 {
            let size = pow10(&mut rng, -2.0, 7.0);
            let (mut e1, mut e2) = (vec(&mut rng) * size, vec(&mut rng) * size);
            if case % 3 == 0 {
                // Along the axes: a floor.
                e1.y = 0.0;
                e2.y = 0.0;
            } else if case % 3 == 1 {
                // Long: a strip.
                e2 *= pow10(&mut rng, -6.0, 0.0);
            }
            let a = vec(&mut rng) * pow10(&mut rng, 0.0, 7.0);
            let (b, c) = (a + e1, a + e2);
            let n = e1.cross(e2).normalize_or_zero();
            let (u, v) = (rng.next(), rng.next());
            let (u, v) = if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            };
            let side = if rng.next() < 0.5 { 1.0 } else { -1.0 };
            let origin = a + e1 * u + e2 * v + n * side * size * pow10(&mut rng, -9.0, -2.0);
            let mut dir = vec(&mut rng);
            if case % 5 == 0 {
                // Grazing.
                dir -= n * n.dot(dir) * (1.0 - pow10(&mut rng, -6.0, 0.0));
            }
            let ray = Ray::new(origin, dir, 0.0, f32::INFINITY);
            if !ray.is_valid() || n == Vec3::ZERO {
                continue;
            }
            let wt = WatertightRay::new(&ray);
            let [x, y, z] = wt.rows(a, b, c);
            let t64 = plane_t_f64(x, y, z, wt.origin, wt.shear);
            let (lo, hi) = (f32::NEG_INFINITY, f32::INFINITY);
            let t32 = match plane_t(x, y, z, wt.origin, wt.shear, lo, hi) {
                PlaneT::Near(_) => {
                    near += 1;
                    continue;
                }
                PlaneT::Wide(t) if t.is_finite() => t,
                PlaneT::Wide(_) => continue,
                PlaneT::Outside(t) => panic!("outside an infinite range: {t}"),
            };
            // The range's ends a few slacks from the f32 t, on either side.
            let (_, facing, terms) = plane_terms(x, y, z, wt.origin, wt.shear);
            let slack = plane_t_slack(t32, facing, terms, wt.shear);
            let off = |rng: &mut Rng| slack * (1.5 + 3.0 * rng.next());
            for (t_min, t_max) in [
                (t32 + off(&mut rng), f32::INFINITY),
                (f32::NEG_INFINITY, t32 - off(&mut rng)),
                (0.0, f32::INFINITY),
            ] {
                match plane_t(x, y, z, wt.origin, wt.shear, t_min, t_max) {
                    PlaneT::Outside(t) => {
                        outside += 1;
                        assert!(!(t >= t_min && t <= t_max));
                        assert!(
                            !(t64 >= t_min && t64 <= t_max),
                            "case {case}: f32 {t} skipped f64's {t64} in [{t_min}, {t_max}] (slack {slack})"
                        );
                    }
                    PlaneT::Wide(_) => wide += 1,
                    PlaneT::Near(t) => panic!("the lever changed with the range: {t}"),
                }
            }
        }
        eprintln!("{near} near, {outside} outside, {wide} wide");
        assert!(
            outside > 100_000 && wide > 10_000,
            "{near} near, {outside} outside, {wide} wide"
        );
        // The default scene's floor: a shadow ray 0.0125 above a quad 10⁴ wide, 5,000 from its
        // corner, leaves it: f32 rejects the floor behind it.
        let (a, b, c) = (
            Vec3::new(-5000.0, 0.0, -5000.0),
            Vec3::new(5000.0, 0.0, -5000.0),
            Vec3::new(-5000.0, 0.0, 5000.0),
        );
        let ray = Ray::new(
            Vec3::new(-10.0, 0.0125, 3.0),
            Vec3::new(300.0, 800.0, -200.0),
            0.0,
            1.0,
        );
        let wt = WatertightRay::new(&ray);
        let [x, y, z] = wt.rows(a, b, c);
        let got = plane_t(x, y, z, wt.origin, wt.shear, 0.0, 1.0);
        assert!(matches!(got, PlaneT::Outside(t) if t < 0.0), "{got:?}");
        assert_eq!(wt.intersect(a, b, c, 0.0, 1.0), None);
    }
}
