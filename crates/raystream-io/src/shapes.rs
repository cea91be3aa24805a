//! Built-in shapes for scenes and tests: closed, consistently oriented (counter-clockwise seen
//! from outside) meshes with shared vertices.

use std::collections::HashMap;

use crate::{TriMesh, Vec3};

impl TriMesh {
    /// A unit sphere: an icosahedron subdivided `subdivisions` times, vertices on the sphere.
    /// It has 20·4^subdivisions triangles.
    pub fn icosphere(subdivisions: u32) -> TriMesh {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut positions: Vec<Vec3> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
        .collect();
        let mut triangles: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
            let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let p = (positions[a as usize] + positions[b as usize]).normalize();
                    positions.push(p);
                    positions.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(triangles.len() * 4);
            for [a, b, c] in triangles {
                let ab = midpoint(a, b, &mut positions);
                let bc = midpoint(b, c, &mut positions);
                let ca = midpoint(c, a, &mut positions);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            triangles = next;
        }
        TriMesh {
            positions,
            triangles,
        }
    }

    /// A square in the y = 0 plane, centred on the origin, side `size`, facing +y.
    pub fn ground_quad(size: f32) -> TriMesh {
        let h = 0.5 * size;
        TriMesh {
            positions: vec![
                Vec3::new(-h, 0.0, -h),
                Vec3::new(-h, 0.0, h),
                Vec3::new(h, 0.0, h),
                Vec3::new(h, 0.0, -h),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    /// A closed cylinder of radius 1 around the y axis from y = −1 to 1, `segments` around,
    /// outward-facing; the caps have their own vertices so that smooth normals keep the rims
    /// sharp (a rod, a screw shaft, a nail).
    pub fn cylinder(segments: u32) -> TriMesh {
        let n = segments.max(3);
        let ring = |y: f32| {
            (0..n).map(move |i| {
                let a = std::f32::consts::TAU * i as f32 / n as f32;
                Vec3::new(a.cos(), y, -a.sin())
            })
        };
        // Side rings (0..n bottom, n..2n top), cap rings (2n.. bottom, 3n.. top), centres.
        let mut positions: Vec<Vec3> = ring(-1.0).chain(ring(1.0)).collect();
        positions.extend(ring(-1.0).chain(ring(1.0)));
        positions.extend([Vec3::new(0.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)]);
        let (bottom, top) = (4 * n, 4 * n + 1);
        let mut triangles = Vec::with_capacity(4 * n as usize);
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([i, j, n + j]);
            triangles.push([i, n + j, n + i]);
            triangles.push([bottom, 2 * n + j, 2 * n + i]);
            triangles.push([top, 3 * n + i, 3 * n + j]);
        }
        TriMesh {
            positions,
            triangles,
        }
    }

    /// The volume the mesh encloses, in its units cubed: the divergence theorem over its
    /// triangles, in f64; for a closed, outward-facing surface its volume (inward-facing:
    /// negative).
    pub fn enclosed_volume(&self) -> f64 {
        (0..self.len())
            .map(|i| {
                let [a, b, c] = self.corners(i).map(|p| p.as_dvec3());
                a.dot(b.cross(c))
            })
            .sum::<f64>()
            / 6.0
    }

    /// Area-weighted vertex normals (unit length; zero for vertices of degenerate triangles only).
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut n = vec![Vec3::ZERO; self.positions.len()];
        for (i, t) in self.triangles.iter().enumerate() {
            let [a, b, c] = self.corners(i);
            let face = (b - a).cross(c - a);
            for &v in t {
                n[v as usize] += face;
            }
        }
        n.iter().map(|v| v.normalize_or_zero()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_and_outward() {
        let s = TriMesh::icosphere(2);
        assert_eq!(s.len(), 320);
        assert_closed_and_outward(&s);
    }

    /// The cylinder's faces point away from its axis (sides) or along it (caps); its side
    /// and cap rings are separate vertices, so it is closed by position, not by index.
    #[test]
    fn cylinder_is_closed_and_outward() {
        let c = TriMesh::cylinder(12);
        assert_eq!(c.len(), 48);
        let mut area = 0.0;
        for i in 0..c.len() {
            let [a, b, d] = c.corners(i);
            let face = (b - a).cross(d - a);
            let centre = (a + b + d) / 3.0;
            let outward = if face.y.abs() > 1e-4 {
                Vec3::new(0.0, centre.y, 0.0)
            } else {
                Vec3::new(centre.x, 0.0, centre.z)
            };
            assert!(face.dot(outward) > 0.0, "triangle {i} faces inward");
            area += 0.5 * face.length();
        }
        // 12 side rectangles of height 2 and one chord wide, and two caps of 12 triangles.
        let chord = 2.0 * (std::f32::consts::PI / 12.0).sin();
        let cap = 12.0 * 0.5 * (std::f32::consts::TAU / 12.0).sin();
        assert!(
            (area - (12.0 * 2.0 * chord + 2.0 * cap)).abs() < 1e-3,
            "{area}"
        );
    }

    fn assert_closed_and_outward(s: &TriMesh) {
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for (i, t) in s.triangles.iter().enumerate() {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
            let [a, b, c] = s.corners(i);
            assert!(
                (b - a).cross(c - a).dot(a + b + c) > 0.0,
                "triangle {i} faces inward"
            );
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
        }
    }
}
