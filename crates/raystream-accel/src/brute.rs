//! Brute-force oracles: every ray against every triangle. `closest` uses the same watertight
//! test as the tree (so tree and oracle must agree exactly); `closest_f64` is an independent
//! Möller–Trumbore in f64 for checking the test itself.

use raystream_math::{DVec3, Ray, Vec3};

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
    if !ray.is_valid() {
        return None;
    }
    let o = ray.origin.as_dvec3();
    let d = ray.dir.as_dvec3();
    let mut best: Option<(f64, u32)> = None;
    for (i, c) in corners.iter().enumerate() {
        let [a, b, e] = c.map(|v| v.as_dvec3());
        let (e1, e2) = (b - a, e - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 {
            continue;
        }
        let inv = 1.0 / det;
        let s = o - a;
        let u = s.dot(p) * inv;
        let q: DVec3 = s.cross(e1);
        let v = d.dot(q) * inv;
        let t = e2.dot(q) * inv;
        if u >= 0.0
            && v >= 0.0
            && u + v <= 1.0
            && t >= ray.t_min as f64
            && t <= ray.t_max as f64
            && best.is_none_or(|(bt, _)| t < bt)
        {
            best = Some((t, i as u32));
        }
    }
    best
}
