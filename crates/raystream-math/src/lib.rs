//! Geometry shared by every raystream crate: glam's vectors, a [`Ray`] with its valid t-range,
//! and an axis-aligned box [`Aabb`]. No I/O and no GPU here.

pub use glam::{
    DAffine3, DMat3, DMat4, DVec2, DVec3, I64Vec3, Mat3, Mat4, Quat, UVec3, Vec2, Vec3, Vec3A, Vec4,
};

/// The largest coordinate a mesh, scene or volume may hold, in scene units (millimetres for
/// CT). The watertight triangle test (Woop et al. 2013) multiplies three coordinate differences
/// in f32 (its t, the plane's normal from two edges dotted with a third difference, up to 48
/// times the cube of the largest coordinate), which overflows from about 2·10¹² on, and the CPU
/// and GPU then disagree; 10¹⁰
/// leaves room for the ground and the camera placed around the objects (tens of times their
/// size). Inputs beyond it are refused with an error, not rendered wrong.
pub const MAX_COORDINATE: f32 = 1e10;

/// Whether `p` is finite and within ±[`MAX_COORDINATE`] on every axis.
pub fn in_coordinate_range(p: Vec3) -> bool {
    p.is_finite() && p.abs().max_element() <= MAX_COORDINATE
}

/// A ray `o + t·d` with the interval of t that counts, `t_min ≤ t ≤ t_max`. The direction need not
/// be unit length: t is measured in units of `|d|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub t_min: f32,
    pub dir: Vec3,
    pub t_max: f32,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Self {
        Self {
            origin,
            t_min,
            dir,
            t_max,
        }
    }

    /// From the 8 floats of the RAYS.bin layout: `ox oy oz t_min dx dy dz t_max`.
    pub fn from_array(a: [f32; 8]) -> Self {
        Self::new(
            Vec3::new(a[0], a[1], a[2]),
            Vec3::new(a[4], a[5], a[6]),
            a[3],
            a[7],
        )
    }

    pub fn to_array(self) -> [f32; 8] {
        let (o, d) = (self.origin, self.dir);
        [o.x, o.y, o.z, self.t_min, d.x, d.y, d.z, self.t_max]
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// Whether a query may hit anything: finite origin, direction and t_min, a t_max that is not
    /// NaN, a non-zero direction and `t_min ≤ t_max`. Every query treats an invalid ray as a miss.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && self.t_min.is_finite()
            && !self.t_max.is_nan()
            && self.t_min <= self.t_max
    }
}

/// An axis-aligned box. `Aabb::EMPTY` has min = +inf and max = −inf so that growing it by any
/// point gives that point's box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::INFINITY,
        max: Vec3::NEG_INFINITY,
    };

    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    pub fn from_points(points: &[Vec3]) -> Self {
        points.iter().fold(Self::EMPTY, |b, &p| b.grow(p))
    }

    #[must_use]
    pub fn grow(self, p: Vec3) -> Self {
        Self::new(self.min.min(p), self.max.max(p))
    }

    #[must_use]
    pub fn union(self, o: Aabb) -> Self {
        Self::new(self.min.min(o.min), self.max.max(o.max))
    }

    #[must_use]
    pub fn intersection(self, o: Aabb) -> Self {
        Self::new(self.min.max(o.min), self.max.min(o.max))
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn extent(&self) -> Vec3 {
        (self.max - self.min).max(Vec3::ZERO)
    }

    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Half the length of the diagonal: the scene "radius" used for offsets and framing.
    pub fn radius(&self) -> f32 {
        0.5 * self.extent().length()
    }

    /// Surface area; 0 for an empty or flat box.
    pub fn area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    pub fn largest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Parametric interval `[t0, t1]` of the ray inside the box (slab test), clipped to the
    /// ray's own range; `None` if the ray misses the box. Axes with a zero direction component
    /// only test that the origin lies within the slab.
    #[inline]
    pub fn clip_ray(&self, ray: &Ray) -> Option<(f32, f32)> {
        let mut t0 = ray.t_min;
        let mut t1 = ray.t_max;
        for a in 0..3 {
            let (o, d) = (ray.origin[a], ray.dir[a]);
            if d == 0.0 {
                if o < self.min[a] || o > self.max[a] {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d;
            let (mut near, mut far) = ((self.min[a] - o) * inv, (self.max[a] - o) * inv);
            if near > far {
                std::mem::swap(&mut near, &mut far);
            }
            t0 = t0.max(near);
            t1 = t1.min(far);
        }
        (t0 <= t1).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_ray_through_unit_box() {
        let b = Aabb::new(Vec3::ZERO, Vec3::ONE);
        let r = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(b.clip_ray(&r), Some((1.0, 2.0)));
        let miss = Ray::new(Vec3::new(-1.0, 2.0, 0.5), Vec3::X, 0.0, f32::INFINITY);
        assert_eq!(b.clip_ray(&miss), None);
        let short = Ray::new(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, 0.0, 0.5);
        assert_eq!(b.clip_ray(&short), None);
    }

    #[test]
    fn invalid_rays() {
        let ok = Ray::new(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY);
        assert!(ok.is_valid());
        assert!(
            !Ray {
                dir: Vec3::ZERO,
                ..ok
            }
            .is_valid()
        );
        assert!(
            !Ray {
                t_max: f32::NAN,
                ..ok
            }
            .is_valid()
        );
        assert!(
            !Ray {
                t_min: 2.0,
                t_max: 1.0,
                ..ok
            }
            .is_valid()
        );
        assert!(
            !Ray {
                origin: Vec3::new(f32::NAN, 0.0, 0.0),
                ..ok
            }
            .is_valid()
        );
    }

    #[test]
    fn empty_box_grows_to_point() {
        let b = Aabb::EMPTY.grow(Vec3::ONE);
        assert_eq!(b, Aabb::new(Vec3::ONE, Vec3::ONE));
        assert!(Aabb::EMPTY.is_empty());
        assert_eq!(b.area(), 0.0);
    }
}
