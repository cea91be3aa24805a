//! What a triangle mesh makes as a surface, as a 3D printer's slicer or a mesh repair tool
//! asks it (`info MESH`): its area, its pieces (shells), whether it closes (every edge joining
//! two triangles that run it opposite ways), where it does not its holes and the edges that
//! break it, and where it does the volume it encloses.
//!
//! Corners at one position are one vertex here, whatever the file's indices: an STL repeats
//! every corner in each of its triangles, and an OBJ's reader splits a position by its
//! normals or texture coordinates, yet the surface is the same.
//!
//! Area and volume are three sums; the pieces are a union–find (petgraph's) over the pairs of
//! triangles that share an edge, and the edges are found by sorting the triangles' sides, which needs
//! no hash of every edge and gives the same counts in any order of the threads.

use petgraph::unionfind::UnionFind;
use rayon::prelude::*;
use raystream_math::{DVec3, Vec3};

use crate::TriMesh;

/// [`TriMesh::measure_surface`]: the mesh as a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceMeasures {
    /// The triangles' area, in the mesh's units squared.
    pub area: f64,
    /// Vertices (corners at one position counted once) of the triangles that have three.
    pub vertices: usize,
    /// Their distinct edges.
    pub edges: usize,
    /// Triangles with three corners at distinct positions: the rest have no edge and bound
    /// nothing, and are left out of the counts below.
    pub faces: usize,
    /// Pieces: triangles joined through edges they alone share (two each: parts that touch
    /// along an edge of more, or at a corner, are pieces of their own, as trimesh counts).
    pub shells: usize,
    /// Edges of one triangle: a hole's rim (or an open sheet's).
    pub boundary_edges: usize,
    /// Loops those edges make (pieces of them joined at their ends): the holes.
    pub holes: usize,
    /// Edges of more than two triangles (a thin wall pinched against another, two parts
    /// touching along a line).
    pub non_manifold_edges: usize,
    /// Edges of two triangles that both run it the same way: one of the two is wound against
    /// the other, so their normals disagree on which side is out.
    pub misoriented_edges: usize,
    /// The volume enclosed, in the mesh's units cubed, where the surface closes in the sense
    /// the volume needs: every edge run as often one way as the other (so that the
    /// divergence theorem's sum does not depend on the origin). Positive where the triangles
    /// face out, negative where the surface is turned inside out; `None` where it does not
    /// close.
    pub volume: Option<f64>,
}

impl SurfaceMeasures {
    /// Closed and a manifold, one way round: every edge joins two triangles that run it
    /// opposite ways (what a printer's slicer calls watertight), and there is one at least.
    pub fn closed(&self) -> bool {
        self.faces > 0
            && self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.misoriented_edges == 0
    }

    /// The Euler characteristic V − E + F (2 for each sphere-like closed shell).
    pub fn euler(&self) -> i64 {
        self.vertices as i64 - self.edges as i64 + self.faces as i64
    }

    /// Where [`Self::closed`], its handles (tunnels through it) over all its shells: shells −
    /// χ/2 (a sphere's 0, a torus's 1).
    pub fn genus(&self) -> Option<i64> {
        self.closed().then(|| self.shells as i64 - self.euler() / 2)
    }
}

impl TriMesh {
    /// The mesh as a surface: area, shells, holes, the edges that keep it from closing, and
    /// where it closes its volume ([`SurfaceMeasures`]).
    pub fn measure_surface(&self) -> SurfaceMeasures {
        let id = self.welded();
        // Each triangle's sides by their vertices (lower first), with the triangle and
        // whether it runs the side from the higher to the lower, sorted so that a side's
        // triangles come together.
        let mut faces: Vec<usize> = Vec::with_capacity(self.triangles.len());
        let mut used = vec![false; self.positions.len()];
        let mut sides: Vec<(u64, u64)> = Vec::with_capacity(3 * self.triangles.len());
        for (f, t) in self.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|v| id[v as usize]);
            if a == b || b == c || c == a {
                continue;
            }
            faces.push(f);
            for (p, q) in [(a, b), (b, c), (c, a)] {
                used[p as usize] = true;
                let key = (u64::from(p.min(q)) << 32) | u64::from(p.max(q));
                sides.push((key, ((f as u64) << 1) | u64::from(p > q)));
            }
        }
        sides.par_sort_unstable();

        let mut pieces = UnionFind::<usize>::new(self.triangles.len());
        let mut rims = UnionFind::<u32>::new(self.positions.len());
        let mut on_rim = vec![false; self.positions.len()];
        let mut m = SurfaceMeasures {
            area: 0.0,
            vertices: used.iter().filter(|&&u| u).count(),
            edges: 0,
            faces: faces.len(),
            shells: 0,
            boundary_edges: 0,
            holes: 0,
            non_manifold_edges: 0,
            misoriented_edges: 0,
            volume: None,
        };
        let mut balanced = true;
        for run in sides.chunk_by(|x, y| x.0 == y.0) {
            m.edges += 1;
            let backward = run.iter().filter(|s| s.1 & 1 == 1).count();
            balanced &= 2 * backward == run.len();
            match run.len() {
                1 => {
                    m.boundary_edges += 1;
                    let (p, q) = ((run[0].0 >> 32) as u32, run[0].0 as u32);
                    rims.union(p, q);
                    on_rim[p as usize] = true;
                    on_rim[q as usize] = true;
                }
                2 if backward != 1 => m.misoriented_edges += 1,
                2 => {}
                _ => m.non_manifold_edges += 1,
            }
            if let [a, b] = run {
                pieces.union((a.1 >> 1) as usize, (b.1 >> 1) as usize);
            }
        }
        let mut roots: Vec<usize> = faces.iter().map(|&f| pieces.find(f)).collect();
        roots.sort_unstable();
        roots.dedup();
        m.shells = roots.len();
        let mut loops: Vec<u32> = (0..on_rim.len() as u32)
            .filter(|&v| on_rim[v as usize])
            .map(|v| rims.find(v))
            .collect();
        loops.sort_unstable();
        loops.dedup();
        m.holes = loops.len();

        // In f64, about the middle of the mesh's box: the volume's sum cancels less there
        // (and is the same about any point where the surface closes).
        let centre = if self.triangles.is_empty() {
            DVec3::ZERO
        } else {
            let b = self.bounds();
            (b.min.as_dvec3() + b.max.as_dvec3()) / 2.0
        };
        let mut six_volume = 0.0;
        for i in 0..self.triangles.len() {
            let [a, b, c] = self.corners(i).map(|p: Vec3| p.as_dvec3() - centre);
            let n = (b - a).cross(c - a);
            m.area += n.length() / 2.0;
            six_volume += a.dot(b.cross(c));
        }
        m.volume = (balanced && m.faces > 0).then_some(six_volume / 6.0);
        m
    }

    /// Each vertex's position's number: vertices at one position (the same bits, −0 and +0
    /// alike) share one.
    fn welded(&self) -> Vec<u32> {
        let bits = |v: u32| {
            let p = self.positions[v as usize].to_array();
            p.map(|x| if x == 0.0 { 0 } else { x.to_bits() })
        };
        let mut order: Vec<u32> = (0..self.positions.len() as u32).collect();
        order.par_sort_unstable_by_key(|&v| (bits(v), v));
        let mut id = vec![0u32; self.positions.len()];
        let mut next = 0u32;
        for (k, &v) in order.iter().enumerate() {
            if k > 0 && bits(order[k - 1]) != bits(v) {
                next += 1;
            }
            id[v as usize] = next;
        }
        id
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit cube [0, 1]³, outward, its 8 corners shared.
    fn cube() -> TriMesh {
        let positions = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32))
            .collect();
        // Each face's corners counter-clockwise seen from outside, as two triangles.
        let faces = [
            [0, 2, 3, 1], // z = 0
            [4, 5, 7, 6], // z = 1
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = 1
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = 1
        ];
        let triangles = faces
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect();
        TriMesh {
            positions,
            triangles,
        }
    }

    /// `m` with every triangle given corners of its own, as an STL has them.
    fn unshared(m: &TriMesh) -> TriMesh {
        TriMesh {
            positions: (0..m.len()).flat_map(|i| m.corners(i)).collect(),
            triangles: (0..m.len() as u32)
                .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
                .collect(),
        }
    }

    fn moved(m: &TriMesh, by: Vec3) -> TriMesh {
        TriMesh {
            positions: m.positions.iter().map(|&p| p + by).collect(),
            triangles: m.triangles.clone(),
        }
    }

    fn joined(a: &TriMesh, b: &TriMesh) -> TriMesh {
        let n = a.positions.len() as u32;
        TriMesh {
            positions: [a.positions.clone(), b.positions.clone()].concat(),
            triangles: (a.triangles.iter().copied())
                .chain(b.triangles.iter().map(|t| t.map(|v| v + n)))
                .collect(),
        }
    }

    /// A torus of `n × n` quads (radii 2 and 1), outward: closed, genus 1.
    fn torus(n: u32) -> TriMesh {
        let mut positions = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (u, v) = (
                    std::f32::consts::TAU * i as f32 / n as f32,
                    std::f32::consts::TAU * j as f32 / n as f32,
                );
                let r = 2.0 + v.cos();
                positions.push(Vec3::new(r * u.cos(), r * u.sin(), v.sin()));
            }
        }
        let at = |i: u32, j: u32| (i % n) * n + j % n;
        let mut triangles = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        TriMesh {
            positions,
            triangles,
        }
    }

    /// [`TriMesh::measure_surface`]'s counts the plain way: positions compared as values in a
    /// map, each edge's uses listed, pieces and rims walked breadth first.
    fn brute(m: &TriMesh) -> (usize, usize, usize, usize, usize, usize, usize, usize, bool) {
        use std::collections::{HashMap, HashSet, VecDeque};
        let key = |p: Vec3| p.to_array().map(|x| if x == 0.0 { 0 } else { x.to_bits() });
        let mut ids: HashMap<[u32; 3], usize> = HashMap::new();
        let id: Vec<usize> = (m.positions.iter())
            .map(|&p| {
                let n = ids.len();
                *ids.entry(key(p)).or_insert(n)
            })
            .collect();
        let faces: Vec<[usize; 3]> = (m.triangles.iter())
            .map(|t| t.map(|v| id[v as usize]))
            .filter(|[a, b, c]| a != b && b != c && c != a)
            .collect();
        let mut uses: HashMap<(usize, usize), Vec<(usize, bool)>> = HashMap::new();
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                let (p, q) = (t[k], t[(k + 1) % 3]);
                uses.entry((p.min(q), p.max(q)))
                    .or_default()
                    .push((f, p > q));
            }
        }
        let vertices: HashSet<usize> = faces.iter().flatten().copied().collect();
        let (mut boundary, mut non_manifold, mut misoriented) = (0, 0, 0);
        let mut balanced = true;
        let mut joined: Vec<Vec<usize>> = vec![Vec::new(); faces.len()];
        let mut rim: HashMap<usize, Vec<usize>> = HashMap::new();
        for (&(p, q), u) in &uses {
            let back = u.iter().filter(|x| x.1).count();
            balanced &= 2 * back == u.len();
            match u.len() {
                1 => {
                    boundary += 1;
                    rim.entry(p).or_default().push(q);
                    rim.entry(q).or_default().push(p);
                }
                2 => {
                    misoriented += usize::from(back != 1);
                    joined[u[0].0].push(u[1].0);
                    joined[u[1].0].push(u[0].0);
                }
                _ => non_manifold += 1,
            }
        }
        let pieces = |starts: Vec<usize>, next: &dyn Fn(usize) -> Vec<usize>| {
            let mut seen = HashSet::new();
            let mut count = 0;
            for s in starts {
                if !seen.insert(s) {
                    continue;
                }
                count += 1;
                let mut queue = VecDeque::from([s]);
                while let Some(x) = queue.pop_front() {
                    for y in next(x) {
                        if seen.insert(y) {
                            queue.push_back(y);
                        }
                    }
                }
            }
            count
        };
        let shells = pieces((0..faces.len()).collect(), &|f| joined[f].clone());
        let holes = pieces(rim.keys().copied().collect(), &|v| rim[&v].clone());
        let volume = balanced && !faces.is_empty();
        (
            vertices.len(),
            uses.len(),
            faces.len(),
            shells,
            boundary,
            holes,
            non_manifold,
            misoriented,
            volume,
        )
    }

    proptest::proptest! {
        /// Random triangles over a few points (some at one position under different indices,
        /// some at −0 and +0): the counts of the plain way, and where the surface closes, its
        /// volume's sum, whose value is the same about the origin.
        #[test]
        fn surface_counts_equal_the_plain_way(
            tris in proptest::collection::vec((0u32..9, 0u32..9, 0u32..9), 0..40),
            flip in proptest::collection::vec(proptest::bool::ANY, 40),
        ) {
            // Nine vertices at six positions: 6, 7 and 8 repeat 0, 1 and 2 (8 as −0).
            let at = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [2.0, 0.5, -1.0]];
            let mut positions: Vec<Vec3> = at.iter().map(|&p| Vec3::from_array(p)).collect();
            positions.extend([positions[0], positions[1], Vec3::new(-0.0, 1.0, -0.0)]);
            // Each triangle, and sometimes its reverse (closing what it opens).
            let mut triangles = Vec::new();
            for (i, &(a, b, c)) in tris.iter().enumerate() {
                triangles.push([a, b, c]);
                if flip[i % flip.len()] {
                    triangles.push([a, c, b]);
                }
            }
            let m = TriMesh { positions, triangles };
            let s = m.measure_surface();
            let (v, e, f, shells, boundary, holes, non_manifold, misoriented, volume) = brute(&m);
            proptest::prop_assert_eq!(
                (s.vertices, s.edges, s.faces, s.shells, s.boundary_edges, s.holes, s.non_manifold_edges, s.misoriented_edges, s.volume.is_some()),
                (v, e, f, shells, boundary, holes, non_manifold, misoriented, volume)
            );
            if let Some(vol) = s.volume {
                let about_origin = m.enclosed_volume();
                proptest::prop_assert!((vol - about_origin).abs() < 1e-5, "{} {}", vol, about_origin);
            }
        }
    }

    #[test]
    fn a_cube_is_closed_with_its_area_and_volume() {
        for m in [cube(), unshared(&cube())] {
            let s = m.measure_surface();
            assert_eq!(s.area, 6.0);
            assert_eq!(s.volume, Some(1.0));
            assert_eq!((s.vertices, s.edges, s.faces), (8, 18, 12));
            assert_eq!((s.shells, s.euler(), s.genus()), (1, 2, Some(0)));
            assert!(s.closed());
            assert_eq!((s.boundary_edges, s.holes), (0, 0));
        }
        // Far from the origin: the same volume (the sum is taken about the box's middle).
        let far = moved(&cube(), Vec3::new(1e5, -3e5, 2e5)).measure_surface();
        assert!((far.volume.unwrap() - 1.0).abs() < 1e-6, "{far:?}");
        // Turned inside out: the volume negative, still closed.
        let mut inside_out = cube();
        inside_out.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let s = inside_out.measure_surface();
        assert_eq!(s.volume, Some(-1.0));
        assert!(s.closed());
    }

    #[test]
    fn open_and_broken_surfaces_say_why() {
        // One face's two triangles gone: a square hole, 4 rim edges.
        let mut open = cube();
        open.triangles.drain(0..2);
        let s = open.measure_surface();
        assert_eq!((s.boundary_edges, s.holes, s.shells), (4, 1, 1));
        assert_eq!(s.volume, None);
        assert!(!s.closed());
        assert_eq!(s.genus(), None);
        // Two opposite faces gone: a tube, two holes.
        let mut tube = cube();
        tube.triangles.drain(0..4);
        let s = tube.measure_surface();
        assert_eq!((s.boundary_edges, s.holes), (8, 2));
        // One triangle wound the wrong way: its three edges run like their neighbours'.
        let mut flipped = cube();
        flipped.triangles[5].swap(1, 2);
        let s = flipped.measure_surface();
        assert_eq!((s.misoriented_edges, s.boundary_edges), (3, 0));
        assert_eq!(s.volume, None);
        // Two cubes touching along an edge: one edge of four triangles, still closing (run
        // both ways twice), two pieces, the two volumes.
        let two = joined(&cube(), &moved(&cube(), Vec3::new(1.0, 1.0, 0.0)));
        let s = two.measure_surface();
        assert_eq!((s.non_manifold_edges, s.shells), (1, 2));
        assert_eq!(s.volume, Some(2.0));
        assert!(!s.closed());
        // Apart: two shells, each a sphere.
        let apart = joined(&cube(), &moved(&cube(), Vec3::new(3.0, 0.0, 0.0)));
        let s = apart.measure_surface();
        assert_eq!((s.shells, s.euler(), s.genus()), (2, 4, Some(0)));
        assert_eq!(s.volume, Some(2.0));
        // A triangle with two corners at one position bounds nothing.
        let mut sliver = cube();
        sliver.triangles.push([0, 0, 1]);
        let s = sliver.measure_surface();
        assert_eq!((s.faces, s.area, s.volume), (12, 6.0, Some(1.0)));
        // Nothing at all.
        let s = TriMesh::default().measure_surface();
        assert_eq!((s.faces, s.shells, s.area, s.volume), (0, 0, 0.0, None));
        assert!(!s.closed());
    }

    /// A torus is one closed shell with a handle; its area and volume those of the
    /// polyhedron, near the smooth torus's (4π²Rr and 2π²Rr²) as it is divided finer.
    #[test]
    fn a_torus_has_one_handle() {
        let s = torus(64).measure_surface();
        assert!(s.closed());
        assert_eq!((s.shells, s.euler(), s.genus()), (1, 0, Some(1)));
        let pi2 = std::f64::consts::PI.powi(2);
        let (area, volume) = (8.0 * pi2, 4.0 * pi2);
        assert!((s.area / area - 1.0).abs() < 2e-3, "{} for {area}", s.area);
        let v = s.volume.unwrap();
        assert!(v < volume && v > 0.995 * volume, "{v} for {volume}");
        // Its volume is the divergence theorem's sum about the origin, moved or not.
        let about_origin = torus(64).enclosed_volume();
        assert!((v - about_origin).abs() < 1e-9 * v, "{v} {about_origin}");
    }
}
