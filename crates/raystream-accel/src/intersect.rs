//! Watertight ray–triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)). Rays through a shared edge or vertex hit at least one of the
//! triangles sharing it, so closed meshes have no cracks.
//!
//! Contract: a hit needs `t_min ≤ t ≤ t_max`; edges count as inside; degenerate triangles and
//! rays in the triangle's plane never hit. `u`, `v` are the weights of v1 and v2.

use raystream_math::{Ray, Vec3};

use crate::layout::KdTri;

/// Per-ray constants of the watertight test: the axis permutation and the shear. Arrays of 4
/// indexed with `k & 3` keep bounds checks out of the hot loop.
#[derive(Clone, Copy, Debug)]
pub struct WatertightRay {
    origin: [f32; 4],
    k: [usize; 3],
    shear: [f32; 3],
}

impl WatertightRay {
    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let a = d.abs();
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
        let o = ray.origin;
        Self {
            origin: [o.x, o.y, o.z, 0.0],
            k: [kx, ky, kz],
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
        self.intersect4(
            &v0.extend(0.0).to_array(),
            &v1.extend(0.0).to_array(),
            &v2.extend(0.0).to_array(),
            t_min,
            t_max,
        )
    }

    #[inline(always)]
    pub fn intersect_tri(&self, tri: &KdTri, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        self.intersect4(&tri.v0, &tri.v1, &tri.v2, t_min, t_max)
    }

    #[inline(always)]
    fn intersect4(
        &self,
        v0: &[f32; 4],
        v1: &[f32; 4],
        v2: &[f32; 4],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let (kx, ky, kz) = (self.k[0] & 3, self.k[1] & 3, self.k[2] & 3);
        let [sx, sy, sz] = self.shear;
        let o = &self.origin;
        let (az, bz, cz) = (v0[kz] - o[kz], v1[kz] - o[kz], v2[kz] - o[kz]);
        let ax = (v0[kx] - o[kx]) - sx * az;
        let ay = (v0[ky] - o[ky]) - sy * az;
        let bx = (v1[kx] - o[kx]) - sx * bz;
        let by = (v1[ky] - o[ky]) - sy * bz;
        let cx = (v2[kx] - o[kx]) - sx * cz;
        let cy = (v2[ky] - o[ky]) - sy * cz;
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
        let t_scaled = sz * (u * az + v * bz + w * cz);
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        if !(t >= t_min && t <= t_max) {
            return None;
        }
        Some((t, v * inv, w * inv))
    }
}
