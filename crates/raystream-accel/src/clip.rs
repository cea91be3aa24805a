//! Exact triangle–box geometry for the builder ("perfect splits": a triangle's bounds in a node
//! are the bounds of the triangle clipped to that node, Wald & Havran 2006) and for `validate()`.

use raystream_math::{Aabb, DVec3, Vec3};

/// A convex polygon in f64: a triangle clipped by a box's 6 planes has at most 9 corners, and
/// a clip may hold one more for a moment. Fixed arrays keep clipping allocation-free.
struct Polygon {
    corners: [[f64; 3]; 10],
    len: usize,
}

impl Polygon {
    fn triangle(tri: &[Vec3; 3]) -> Self {
        let mut corners = [[0f64; 3]; 10];
        for (k, v) in tri.iter().enumerate() {
            corners[k] = [v.x as f64, v.y as f64, v.z as f64];
        }
        Self { corners, len: 3 }
    }

    /// Keeps the part with `p[axis] >= plane` (`keep_above`) or `<= plane` (Sutherland–Hodgman).
    fn clip(&mut self, axis: usize, plane: f64, keep_above: bool) {
        let inside = |p: &[f64; 3]| {
            if keep_above {
                p[axis] >= plane
            } else {
                p[axis] <= plane
            }
        };
        let mut next = [[0f64; 3]; 10];
        let mut n = 0;
        let len = self.len;
        for i in 0..len {
            let (a, b) = (
                self.corners[i],
                self.corners[if i + 1 == len { 0 } else { i + 1 }],
            );
            let (ia, ib) = (inside(&a), inside(&b));
            if ia {
                next[n] = a;
                n += 1;
            }
            if ia != ib {
                next[n] = crossing(&a, &b, axis, plane);
                n += 1;
            }
        }
        self.corners = next;
        self.len = n;
    }

    /// The polygon's bounds rounded outwards to f32 and limited to `bx`; `None` when empty.
    fn bounds_in(&self, bx: &Aabb) -> Option<Aabb> {
        let mut b = Bounds64::EMPTY;
        for p in &self.corners[..self.len] {
            b.grow(p);
        }
        b.to_f32_in(bx)
    }
}

/// Where the edge from `a` to `b` meets the plane `p[axis] = plane` (exactly on it).
#[inline]
fn crossing(a: &[f64; 3], b: &[f64; 3], axis: usize, plane: f64) -> [f64; 3] {
    let s = (plane - a[axis]) / (b[axis] - a[axis]);
    let mut p = [
        a[0] + (b[0] - a[0]) * s,
        a[1] + (b[1] - a[1]) * s,
        a[2] + (b[2] - a[2]) * s,
    ];
    p[axis] = plane;
    p
}

/// A box in f64 being grown around points.
#[derive(Clone, Copy)]
struct Bounds64 {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Bounds64 {
    const EMPTY: Bounds64 = Bounds64 {
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
    };

    fn grow(&mut self, p: &[f64; 3]) {
        for ((lo, hi), x) in self.lo.iter_mut().zip(&mut self.hi).zip(p) {
            *lo = lo.min(*x);
            *hi = hi.max(*x);
        }
    }

    /// Rounded outwards to f32 and limited to `bx`; `None` when empty.
    fn to_f32_in(self, bx: &Aabb) -> Option<Aabb> {
        if !(self.lo[0] <= self.hi[0]) {
            return None;
        }
        let down = |x: f64| {
            let f = x as f32;
            if f as f64 > x { f.next_down() } else { f }
        };
        let up = |x: f64| {
            let f = x as f32;
            if (f as f64) < x { f.next_up() } else { f }
        };
        let (lo, hi) = (self.lo, self.hi);
        let b = Aabb::new(
            Vec3::new(down(lo[0]), down(lo[1]), down(lo[2])),
            Vec3::new(up(hi[0]), up(hi[1]), up(hi[2])),
        )
        .intersection(*bx);
        (!b.is_empty()).then_some(b)
    }
}

/// The triangle clipped to `bx`: `Err(bounds)` when no face of the box cuts it (the bounds of
/// the triangle within the box, `None` if empty), else `Ok(polygon)`.
fn clip_to_box(tri: &[Vec3; 3], bx: &Aabb) -> Result<Polygon, Option<Aabb>> {
    let own = Aabb::from_points(tri);
    // Planes the whole triangle lies inside cannot cut it: usually none or one plane is left.
    let mut poly: Option<Polygon> = None;
    for axis in 0..3 {
        for (cut, plane, keep_above) in [
            (own.min[axis] < bx.min[axis], bx.min[axis], true),
            (own.max[axis] > bx.max[axis], bx.max[axis], false),
        ] {
            if cut {
                let p = poly.get_or_insert_with(|| Polygon::triangle(tri));
                p.clip(axis, plane as f64, keep_above);
            }
        }
    }
    poly.ok_or_else(|| Some(own.intersection(*bx)).filter(|b| !b.is_empty()))
}

/// Bounds of the part of triangle `tri` inside `bx`, or `None` if the triangle misses the box.
/// Clipping runs in f64 and the result is rounded outwards to f32, then limited to `bx`, so it
/// never claims less than the true overlap nor more than the box.
pub fn clipped_bounds(tri: &[Vec3; 3], bx: &Aabb) -> Option<Aabb> {
    match clip_to_box(tri, bx) {
        Ok(poly) => poly.bounds_in(bx),
        Err(bounds) => bounds,
    }
}

/// [`clipped_bounds`] in the two halves of `bx` split at `pos` along `axis` (below, above),
/// clipping the triangle to `bx` once for both.
pub fn split_clipped_bounds(
    tri: &[Vec3; 3],
    bx: &Aabb,
    axis: usize,
    pos: f32,
) -> [Option<Aabb>; 2] {
    let (mut below, mut above) = (*bx, *bx);
    below.max[axis] = pos;
    above.min[axis] = pos;
    let poly = match clip_to_box(tri, bx) {
        Ok(poly) => poly,
        Err(None) => return [None, None],
        Err(Some(_)) => Polygon::triangle(tri),
    };
    // The two halves' corners are the polygon's corners on each side (those on the plane on
    // both) and the points where its edges cross the plane, computed as `Polygon::clip` does:
    // their bounds need no clipped polygons.
    let plane = pos as f64;
    let (mut lo, mut hi) = (Bounds64::EMPTY, Bounds64::EMPTY);
    let n = poly.len;
    for i in 0..n {
        let (a, b) = (
            poly.corners[i],
            poly.corners[if i + 1 == n { 0 } else { i + 1 }],
        );
        if a[axis] <= plane {
            lo.grow(&a);
        }
        if a[axis] >= plane {
            hi.grow(&a);
        }
        if (a[axis] < plane && b[axis] > plane) || (a[axis] > plane && b[axis] < plane) {
            let p = crossing(&a, &b, axis, plane);
            lo.grow(&p);
            hi.grow(&p);
        }
    }
    [lo.to_f32_in(&below), hi.to_f32_in(&above)]
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

    #[test]
    fn split_clipping_equals_clipping_each_half() {
        // Triangles of all sizes and slants against boxes that cut them on 0 to 6 faces, split
        // on every axis: clipping once and splitting gives each half's clipped bounds, up to
        // the f32 rounding of the last corner (the planes are applied in another order).
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 4.0 - 2.0
        };
        let mut cut = 0;
        for _ in 0..20_000 {
            let tri = [(); 3].map(|_| Vec3::new(next(), next(), next()));
            let (p, q) = (
                Vec3::new(next(), next(), next()),
                Vec3::new(next(), next(), next()),
            );
            let bx = Aabb::new(p.min(q), p.max(q));
            let axis = (next().abs() * 1.5) as usize % 3;
            let pos = bx.min[axis] + (bx.max[axis] - bx.min[axis]) * (next() + 2.0) / 4.0;
            let (mut below, mut above) = (bx, bx);
            below.max[axis] = pos;
            above.min[axis] = pos;
            let got = split_clipped_bounds(&tri, &bx, axis, pos);
            for (g, half) in got.into_iter().zip([below, above]) {
                let want = clipped_bounds(&tri, &half);
                assert_eq!(
                    g.is_some(),
                    want.is_some(),
                    "{tri:?} in {half:?}: {g:?} vs {want:?}"
                );
                if let (Some(g), Some(w)) = (g, want) {
                    let ulp = (w.max - w.min).max_element().max(1.0) * 4.0 * f32::EPSILON;
                    assert!(
                        (g.min - w.min).abs().max_element() <= ulp
                            && (g.max - w.max).abs().max_element() <= ulp,
                        "{tri:?} in {half:?}: {g:?} vs {w:?}"
                    );
                    cut += 1;
                }
            }
        }
        assert!(cut > 5_000, "too few triangles met the boxes: {cut}");
    }
}
