//! Brute-force oracles: every ray against every triangle. `closest` uses the same watertight
//! test as the tree (so tree and oracle must agree exactly); `closest_f64` is an independent
//! Möller–Trumbore in f64 for checking the test itself; `verdict_f64` its answer with a margin,
//! and the huge turned ground quads that the tests of both devices check the test on.

use raystream_math::{DVec3, Mat3, Ray, Vec3};

use crate::Hit;
use crate::intersect::WatertightRay;

/// Closest hit over all triangles with the watertight test; ties go to the lowest prim.
pub fn closest(corners: &[[Vec3; 3]], ray: &Ray) -> Option<Hit> {
    if !ray.is_valid() {
        return None;
    }
    let wt = WatertightRay::new(ray);
    let mut best: Option<Hit> = None;
    for (i, c) in corners.iter().enumerate() {
        let t_max = best.map_or(ray.t_max, |h| h.t);
        if let Some((t, u, v)) = wt.intersect(c[0], c[1], c[2], ray.t_min, t_max)
            && best.is_none_or(|h| t < h.t)
        {
            best = Some(Hit {
                t,
                prim: i as u32,
                u,
                v,
            });
        }
    }
    best
}

/// Closest hit by Möller–Trumbore in f64 (edges inside). Returns `(t, prim)`.
pub fn closest_f64(corners: &[[Vec3; 3]], ray: &Ray) -> Option<(f64, u32)> {
    let mut best: Option<(f64, u32)> = None;
    for (i, t, u, v) in planes_f64(corners, ray) {
        if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, i as u32));
        }
    }
    best
}

/// What f64 says of a ray, where the f32 test's rounding cannot change the answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// The closest hit, at this t, lies more than the margin inside its triangle.
    Inside(f64),
    /// No hit in [t_min, t_max] within the margin of any triangle.
    Outside,
    /// Within the margin of some triangle's edges.
    Near,
}

/// [`closest_f64`] with a margin: whether the ray's closest hit in f64 lies more than `margin`
/// inside its triangle (every barycentric weight above it), misses every triangle by more than
/// that (some weight below −`margin`), or neither. For tests of the f32 test on geometry at
/// the edge of what f32 resolves, whose hits near edges may go either way.
pub fn verdict_f64(corners: &[[Vec3; 3]], ray: &Ray, margin: f64) -> Verdict {
    let mut best: Option<f64> = None;
    let mut near = false;
    for (_, t, u, v) in planes_f64(corners, ray) {
        let smallest = u.min(v).min(1.0 - u - v);
        if smallest < -margin {
            continue;
        }
        if smallest <= margin {
            near = true;
        } else if best.is_none_or(|bt| t < bt) {
            best = Some(t);
        }
    }
    match best {
        Some(t) if !near => Verdict::Inside(t),
        None if !near => Verdict::Outside,
        _ => Verdict::Near,
    }
}

/// Each triangle's `(index, t, u, v)` where the ray meets its plane within [t_min, t_max], by
/// Möller–Trumbore in f64 (`u`, `v` the weights of corners 1 and 2); none for an invalid ray.
fn planes_f64<'a>(
    corners: &'a [[Vec3; 3]],
    ray: &Ray,
) -> impl Iterator<Item = (usize, f64, f64, f64)> + 'a {
    let (valid, t_min, t_max) = (ray.is_valid(), ray.t_min as f64, ray.t_max as f64);
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    corners
        .iter()
        .enumerate()
        .filter(move |_| valid)
        .filter_map(move |(i, c)| {
            let [a, b, e] = c.map(|v| v.as_dvec3());
            let (e1, e2) = (b - a, e - a);
            let p = d.cross(e2);
            let det = e1.dot(p);
            if det == 0.0 {
                return None;
            }
            let inv = 1.0 / det;
            let s = o - a;
            let u = s.dot(p) * inv;
            let q: DVec3 = s.cross(e1);
            let v = d.dot(q) * inv;
            let t = e2.dot(q) * inv;
            (t >= t_min && t <= t_max).then_some((i, t, u, v))
        })
}

/// Quads `(w, l, degrees)` for [`turned_quad`] whose planes f32 cannot resolve where rays from
/// near their middle start: strips 10 wide and 10⁷ or 4 × 10⁷ long, and a square 2 × 10⁶ on
/// a side.
pub const BIG_TURNED_QUADS: [(f32, f32, f32); 4] = [
    (5.0, 5e6, 0.3),
    (5.0, 5e6, 3.0),
    (1e6, 1e6, 3.0),
    (5.0, 2e7, 3.0),
];

/// The margin for [`verdict_f64`] beyond which the f32 edge functions decide a hit on
/// [`turned_quad`] `w` × `l` as f64 does: their rounding, from the corners' reach of `l`, is
/// about 10⁻³ of a strip's width of 10 at 2 × 10⁷ (`scripts/sliver-model.py`: at 10⁹ they miss
/// a third of its hits).
pub fn turned_quad_margin(w: f32, l: f32) -> f64 {
    if l / w > 1e3 { 1e-2 } else { 1e-5 }
}

/// `ground_quad` stretched to `w` × `l` and turned `degrees` about y, then a seventh of that
/// about x (`scripts/sliver-model.py`'s strips).
pub fn turned_quad(w: f32, l: f32, degrees: f32) -> raystream_io::TriMesh {
    let turn = Mat3::from_rotation_x((degrees / 7.0).to_radians())
        * Mat3::from_rotation_y(degrees.to_radians());
    let mut mesh = raystream_io::TriMesh::ground_quad(1.0);
    for p in &mut mesh.positions {
        *p = turn * (*p * Vec3::new(2.0 * w, 1.0, 2.0 * l));
    }
    mesh
}

/// `width` × `height` rays from (0, 1, 5), 11° below the horizon ± 22° and ± 2.6° across.
pub fn turned_quad_rays(width: usize, height: usize) -> Vec<Ray> {
    let (pitch, tan) = ((-11f32).to_radians(), 22.5f32.to_radians().tan());
    let fwd = Vec3::new(0.0, pitch.sin(), -pitch.cos());
    let up = Vec3::X.cross(fwd);
    let aspect = width as f32 / height as f32;
    (0..width * height)
        .map(|k| {
            let (i, j) = ((k % width) as f32 + 0.5, (k / width) as f32 + 0.5);
            let x = (i / width as f32 * 2.0 - 1.0) * tan * aspect * 0.05;
            let y = (1.0 - j / height as f32 * 2.0) * tan;
            Ray::new(
                Vec3::new(0.0, 1.0, 5.0),
                (fwd + x * Vec3::X + y * up).normalize(),
                0.0,
                f32::INFINITY,
            )
        })
        .collect()
}
