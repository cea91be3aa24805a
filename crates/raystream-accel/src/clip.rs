//! Exact triangle–box geometry for the builder ("perfect splits": a triangle's bounds in a node
//! are the bounds of the triangle clipped to that node, Wald & Havran 2006) and for `validate()`.

use raystream_math::{Aabb, DVec3, Vec3};

/// Bounds of the part of triangle `tri` inside `bx`, or `None` if the triangle misses the box.
/// Clipping runs in f64 and the result is rounded outwards to f32, then limited to `bx`, so it
/// never claims less than the true overlap nor more than the box.
pub fn clipped_bounds(tri: &[Vec3; 3], bx: &Aabb) -> Option<Aabb> {
    let own = Aabb::from_points(tri);
    // Planes the whole triangle lies inside cannot cut it: usually none or one plane is left.
    let mut cuts = [(0usize, 0f64, false); 6];
    let mut n_cuts = 0;
    for axis in 0..3 {
        if own.min[axis] < bx.min[axis] {
            cuts[n_cuts] = (axis, bx.min[axis] as f64, true);
            n_cuts += 1;
        }
        if own.max[axis] > bx.max[axis] {
            cuts[n_cuts] = (axis, bx.max[axis] as f64, false);
            n_cuts += 1;
        }
    }
    if n_cuts == 0 {
        return Some(own.intersection(*bx)).filter(|b| !b.is_empty());
    }
    // A triangle clipped by 6 planes has at most 9 corners; fixed arrays keep this allocation-free.
    let mut poly = [[0f64; 3]; 10];
    let mut next = [[0f64; 3]; 10];
    for (k, v) in tri.iter().enumerate() {
        poly[k] = [v.x as f64, v.y as f64, v.z as f64];
    }
    let mut len = 3;
    for &(axis, plane, keep_above) in &cuts[..n_cuts] {
        let inside = |p: &[f64; 3]| {
            if keep_above {
                p[axis] >= plane
            } else {
                p[axis] <= plane
            }
        };
        let mut n = 0;
        for i in 0..len {
            let (a, b) = (poly[i], poly[if i + 1 == len { 0 } else { i + 1 }]);
            let (ia, ib) = (inside(&a), inside(&b));
            if ia {
                next[n] = a;
                n += 1;
            }
            if ia != ib {
                let s = (plane - a[axis]) / (b[axis] - a[axis]);
                let mut p = [
                    a[0] + (b[0] - a[0]) * s,
                    a[1] + (b[1] - a[1]) * s,
                    a[2] + (b[2] - a[2]) * s,
                ];
                p[axis] = plane;
                next[n] = p;
                n += 1;
            }
        }
        std::mem::swap(&mut poly, &mut next);
        len = n;
        if len == 0 {
            return None;
        }
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &poly[..len] {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let down = |x: f64| {
        let f = x as f32;
        if f as f64 > x { f.next_down() } else { f }
    };
    let up = |x: f64| {
        let f = x as f32;
        if (f as f64) < x { f.next_up() } else { f }
    };
    let b = Aabb::new(
        Vec3::new(down(lo[0]), down(lo[1]), down(lo[2])),
        Vec3::new(up(hi[0]), up(hi[1]), up(hi[2])),
    )
    .intersection(*bx);
    (!b.is_empty()).then_some(b)
}

/// Whether the triangle meets the box's interior shrunk by `margin` on every side (separating
/// axis test in f64). Used by `validate()`: a triangle that only grazes a leaf's boundary need
/// not be listed in that leaf.
pub fn overlaps_interior(tri: &[Vec3; 3], bx: &Aabb, margin: f64) -> bool {
    let lo = bx.min.as_dvec3() + margin;
    let hi = bx.max.as_dvec3() - margin;
    if lo.cmpge(hi).any() {
        return false;
    }
    let c = (lo + hi) * 0.5;
    let h = (hi - lo) * 0.5;
    let v = tri.map(|p| p.as_dvec3() - c);
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let sep = |axis: DVec3| {
        if axis.length_squared() == 0.0 {
            return false;
        }
        let p = v.map(|x| x.dot(axis));
        let r = h.x * axis.x.abs() + h.y * axis.y.abs() + h.z * axis.z.abs();
        p.iter().cloned().fold(f64::INFINITY, f64::min) >= r
            || p.iter().cloned().fold(f64::NEG_INFINITY, f64::max) <= -r
    };
    for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
        if sep(axis) {
            return false;
        }
        for edge in e {
            if sep(axis.cross(edge)) {
                return false;
            }
        }
    }
    !sep(e[0].cross(e[1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_a_triangle_to_half_a_box() {
        let tri = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
        ];
        let b = Aabb::new(Vec3::new(1.0, -1.0, -1.0), Vec3::splat(3.0));
        let c = clipped_bounds(&tri, &b).unwrap();
        assert_eq!(
            c,
            Aabb::new(Vec3::new(1.0, 0.0, 0.0), Vec3::new(2.0, 1.0, 0.0))
        );
        let far = Aabb::new(Vec3::new(1.5, 1.5, -1.0), Vec3::splat(3.0));
        assert_eq!(
            clipped_bounds(&tri, &far),
            None,
            "box beyond the hypotenuse"
        );
        assert!(!overlaps_interior(&tri, &far, 0.0));
        assert!(overlaps_interior(&tri, &b, 0.0));
    }
}
