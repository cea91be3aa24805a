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
