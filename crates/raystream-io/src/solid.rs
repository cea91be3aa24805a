//! What a triangle mesh makes as a surface, as a 3D printer's slicer or a mesh repair tool
//! asks it (`info MESH`): its area, its pieces (shells), whether it closes (every edge joining
//! two triangles that run it opposite ways), where it does not its holes and the edges that
//! break it, and where it does the volume it encloses; and each shell so, as if it were alone
//! (a bone of a CT's skeleton, a cavity's wall facing in, a part of a model), with the shell
//! each triangle is in (`render --colour-shells`).
//!
//! Corners at one position are one vertex here, whatever the file's indices: an STL repeats
//! every corner in each of its triangles, and an OBJ's reader splits a position by its
//! normals or texture coordinates, yet the surface is the same.
//!
//! Area and volume are three sums; the pieces are a union–find (petgraph's) over the pairs of
//! triangles that share an edge, and the edges are found by sorting the triangles' sides, which needs
//! no hash of every edge and gives the same counts in any order of the threads; each shell's
//! counts come from the same runs of sides, grouped by shell.

use petgraph::unionfind::UnionFind;
use rayon::prelude::*;
use raystream_math::{Aabb, DVec3, Vec3};

use crate::TriMesh;

/// [`TriMesh::measure_surface`]: the mesh as a surface, and each of its shells.
#[derive(Clone, Debug, PartialEq)]
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
    /// The box of the triangles counted in `faces`.
    pub bounds: Aabb,
    /// Each shell measured as if it were alone (its triangles' edges counted among its own
    /// triangles only: two closed shells touching along an edge are each closed, though the
    /// edge is of four triangles), the largest in area first (then the most triangles; then
    /// the first in the file), their own `pieces` empty. Empty where there is no face.
    pub pieces: Vec<SurfaceMeasures>,
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

    /// Nothing measured yet: the sums and counts at zero.
    fn empty(shells: usize) -> Self {
        SurfaceMeasures {
            area: 0.0,
            vertices: 0,
            edges: 0,
            faces: 0,
            shells,
            boundary_edges: 0,
            holes: 0,
            non_manifold_edges: 0,
            misoriented_edges: 0,
            volume: None,
            bounds: Aabb::EMPTY,
            pieces: Vec::new(),
        }
    }

    /// The counts of one edge of `sides` triangles, `backward` of which run it from its higher
    /// vertex to its lower; whether it is run as often one way as the other.
    fn count_edge(&mut self, sides: usize, backward: usize) -> bool {
        self.edges += 1;
        match sides {
            1 => self.boundary_edges += 1,
            2 if backward != 1 => self.misoriented_edges += 1,
            2 => {}
            _ => self.non_manifold_edges += 1,
        }
        2 * backward == sides
    }
}

/// Distinct values of `keys`, counted by their first part (`n` of them): vertices by shell,
/// say, each counted once in each shell it is in.
fn distinct_by_first(mut keys: Vec<(u32, u32)>, n: usize) -> Vec<usize> {
    keys.par_sort_unstable();
    keys.dedup();
    let mut counts = vec![0; n];
    for (first, _) in keys {
        counts[first as usize] += 1;
    }
    counts
}

/// The loops that rim edges `(group, p, q)` make within each of `n` groups (pieces of them
/// joined at their ends, in that group): the holes, by group.
fn loops_by_group(rims: &[(u32, u32, u32)], n: usize) -> Vec<usize> {
    let mut ends: Vec<(u32, u32)> = rims
        .iter()
        .flat_map(|&(g, p, q)| [(g, p), (g, q)])
        .collect();
    ends.sort_unstable();
    ends.dedup();
    let at = |g: u32, v: u32| ends.binary_search(&(g, v)).expect("an end of a rim edge");
    let mut joined = UnionFind::<usize>::new(ends.len());
    for &(g, p, q) in rims {
        joined.union(at(g, p), at(g, q));
    }
    let roots: Vec<(u32, u32)> = (ends.iter().enumerate())
        .map(|(i, &(g, _))| (g, joined.find(i) as u32))
        .collect();
    distinct_by_first(roots, n)
}

impl TriMesh {
    /// The mesh as a surface: area, shells, holes, the edges that keep it from closing, and
    /// where it closes its volume; and each shell so ([`SurfaceMeasures`]).
    pub fn measure_surface(&self) -> SurfaceMeasures {
        self.measure_shells().0
    }

    /// [`Self::measure_surface`], and each triangle's shell: its place in the measures'
    /// `pieces` (the largest first), or `u32::MAX` for a triangle without three corners apart
    /// (in no shell).
    pub fn measure_shells(&self) -> (SurfaceMeasures, Vec<u32>) {
        let id = self.welded();
        // Each triangle's sides by their vertices (lower first), with the triangle and
        // whether it runs the side from the higher to the lower, sorted so that a side's
        // triangles come together.
        let mut faces: Vec<usize> = Vec::with_capacity(self.triangles.len());
        let mut sides: Vec<(u64, u64)> = Vec::with_capacity(3 * self.triangles.len());
        for (f, t) in self.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|v| id[v as usize]);
            if a == b || b == c || c == a {
                continue;
            }
            faces.push(f);
            for (p, q) in [(a, b), (b, c), (c, a)] {
                let key = (u64::from(p.min(q)) << 32) | u64::from(p.max(q));
                sides.push((key, ((f as u64) << 1) | u64::from(p > q)));
            }
        }
        sides.par_sort_unstable();
        let ends = |key: u64| ((key >> 32) as u32, key as u32);
        let face_of = |side: u64| (side >> 1) as usize;

        // The shells: triangles joined through the edges of two.
        let mut pieces = UnionFind::<usize>::new(self.triangles.len());
        for run in sides.chunk_by(|x, y| x.0 == y.0) {
            if let [a, b] = run {
                pieces.union(face_of(a.1), face_of(b.1));
            }
        }
        let mut roots: Vec<usize> = faces.iter().map(|&f| pieces.find(f)).collect();
        roots.sort_unstable();
        roots.dedup();
        let shell_of = |f: usize| {
            roots
                .binary_search(&pieces.find(f))
                .expect("a face's shell") as u32
        };
        let shell: Vec<u32> = {
            let mut s = vec![u32::MAX; self.triangles.len()];
            for &f in &faces {
                s[f] = shell_of(f);
            }
            s
        };

        let mut m = SurfaceMeasures::empty(roots.len());
        let mut each: Vec<SurfaceMeasures> = vec![SurfaceMeasures::empty(1); roots.len()];
        m.faces = faces.len();
        let (mut balanced, mut each_balanced) = (true, vec![true; roots.len()]);
        let (mut rims, mut each_rims) = (Vec::new(), Vec::new());
        let mut by_shell: Vec<(u32, bool)> = Vec::new();
        for run in sides.chunk_by(|x, y| x.0 == y.0) {
            let (p, q) = ends(run[0].0);
            let backward = run.iter().filter(|s| s.1 & 1 == 1).count();
            balanced &= m.count_edge(run.len(), backward);
            if run.len() == 1 {
                rims.push((0, p, q));
            }
            // The edge as each shell with triangles on it sees it alone.
            by_shell.clear();
            by_shell.extend(run.iter().map(|s| (shell[face_of(s.1)], s.1 & 1 == 1)));
            by_shell.sort_unstable();
            for group in by_shell.chunk_by(|x, y| x.0 == y.0) {
                let k = group[0].0 as usize;
                let backward = group.iter().filter(|s| s.1).count();
                each_balanced[k] &= each[k].count_edge(group.len(), backward);
                if group.len() == 1 {
                    each_rims.push((k as u32, p, q));
                }
            }
        }
        m.holes = loops_by_group(&rims, 1)[0];
        for (s, holes) in each.iter_mut().zip(loops_by_group(&each_rims, roots.len())) {
            s.holes = holes;
        }
        let corners = |f: usize| self.triangles[f].map(|v| id[v as usize]);
        // The whole's vertices by a mark each (no sort needed); each shell's by a sort of
        // (shell, vertex), a vertex in two shells counting in both.
        let mut used = vec![false; self.positions.len()];
        for v in faces.iter().flat_map(|&f| corners(f)) {
            used[v as usize] = true;
        }
        m.vertices = used.iter().filter(|&&u| u).count();
        let vertices = distinct_by_first(
            (faces.iter())
                .flat_map(|&f| corners(f).map(|v| (shell[f], v)))
                .collect(),
            roots.len(),
        );
        for (s, v) in each.iter_mut().zip(vertices) {
            s.vertices = v;
        }

        // In f64, about the middle of the faces' box: the volume's sum cancels less there
        // (and is the same about any point where the surface closes). Every triangle's area
        // counts in the whole's (one with two corners at one position may still have some).
        m.bounds = (faces.iter())
            .flat_map(|&f| self.corners(f))
            .fold(Aabb::EMPTY, Aabb::grow);
        let centre = if faces.is_empty() {
            DVec3::ZERO
        } else {
            (m.bounds.min.as_dvec3() + m.bounds.max.as_dvec3()) / 2.0
        };
        let mut six_volumes = vec![0.0; roots.len()];
        let mut six_volume = 0.0;
        for f in 0..self.triangles.len() {
            let corners = self.corners(f);
            let [a, b, c] = corners.map(|p: Vec3| p.as_dvec3() - centre);
            let area = (b - a).cross(c - a).length() / 2.0;
            let six = a.dot(b.cross(c));
            m.area += area;
            six_volume += six;
            if let Some(s) = each.get_mut(shell[f] as usize) {
                s.area += area;
                s.faces += 1;
                s.bounds = corners.into_iter().fold(s.bounds, Aabb::grow);
                six_volumes[shell[f] as usize] += six;
            }
        }
        m.volume = (balanced && m.faces > 0).then_some(six_volume / 6.0);
        for ((s, six), ok) in each.iter_mut().zip(six_volumes).zip(each_balanced) {
            s.volume = ok.then_some(six / 6.0);
        }
        // The largest first; ties by triangles, then in an order the file fixes (the sort is
        // stable, and the shells are in the order of their union–find roots).
        let mut order: Vec<usize> = (0..each.len()).collect();
        order.sort_by(|&a, &b| {
            let (a, b) = (&each[a], &each[b]);
            b.area.total_cmp(&a.area).then(b.faces.cmp(&a.faces))
        });
        let mut rank = vec![0u32; each.len()];
        for (r, &k) in order.iter().enumerate() {
            rank[k] = r as u32;
        }
        let of_face = (shell.iter())
            .map(|&k| rank.get(k as usize).copied().unwrap_or(u32::MAX))
            .collect();
        m.pieces = order.into_iter().map(|k| each[k].clone()).collect();
        (m, of_face)
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
    /// map, each edge's uses listed, pieces and rims walked breadth first; and the triangles
    /// (their indices in `m`) of each piece.
    #[allow(clippy::type_complexity)]
    fn brute(
        m: &TriMesh,
    ) -> (
        (usize, usize, usize, usize, usize, usize, usize, usize, bool),
        Vec<Vec<usize>>,
    ) {
        use std::collections::{HashMap, HashSet, VecDeque};
        let key = |p: Vec3| p.to_array().map(|x| if x == 0.0 { 0 } else { x.to_bits() });
        let mut ids: HashMap<[u32; 3], usize> = HashMap::new();
        let id: Vec<usize> = (m.positions.iter())
            .map(|&p| {
                let n = ids.len();
                *ids.entry(key(p)).or_insert(n)
            })
            .collect();
        let (index, faces): (Vec<usize>, Vec<[usize; 3]>) = (m.triangles.iter().enumerate())
            .map(|(i, t)| (i, t.map(|v| id[v as usize])))
            .filter(|(_, [a, b, c])| a != b && b != c && c != a)
            .unzip();
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
            let mut found = Vec::new();
            for s in starts {
                if !seen.insert(s) {
                    continue;
                }
                let mut piece = vec![s];
                let mut queue = VecDeque::from([s]);
                while let Some(x) = queue.pop_front() {
                    for y in next(x) {
                        if seen.insert(y) {
                            queue.push_back(y);
                            piece.push(y);
                        }
                    }
                }
                found.push(piece);
            }
            found
        };
        let shells = pieces((0..faces.len()).collect(), &|f| joined[f].clone());
        let holes = pieces(rim.keys().copied().collect(), &|v| rim[&v].clone()).len();
        let volume = balanced && !faces.is_empty();
        let counts = (
            vertices.len(),
            uses.len(),
            faces.len(),
            shells.len(),
            boundary,
            holes,
            non_manifold,
            misoriented,
            volume,
        );
        let shells = (shells.into_iter())
            .map(|piece| piece.into_iter().map(|f| index[f]).collect())
            .collect();
        (counts, shells)
    }

    /// `m`'s triangles `which` alone, over all its positions.
    fn only(m: &TriMesh, which: &[usize]) -> TriMesh {
        TriMesh {
            positions: m.positions.clone(),
            triangles: which.iter().map(|&f| m.triangles[f]).collect(),
        }
    }

    /// The counts [`brute`] gives, as [`SurfaceMeasures`] holds them.
    fn counts(
        s: &SurfaceMeasures,
    ) -> (usize, usize, usize, usize, usize, usize, usize, usize, bool) {
        (
            s.vertices,
            s.edges,
            s.faces,
            s.shells,
            s.boundary_edges,
            s.holes,
            s.non_manifold_edges,
            s.misoriented_edges,
            s.volume.is_some(),
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
            let (whole, shells) = brute(&m);
            proptest::prop_assert_eq!(counts(&s), whole);
            if let Some(vol) = s.volume {
                let about_origin = m.enclosed_volume();
                proptest::prop_assert!((vol - about_origin).abs() < 1e-5, "{} {}", vol, about_origin);
            }
            // Each shell: the counts of its triangles alone, the plain way (the shells
            // compared as sets, their order aside); their areas the whole's.
            let mut alone: Vec<_> = shells.iter().map(|f| brute(&only(&m, f)).0).collect();
            let mut pieces: Vec<_> = s.pieces.iter().map(counts).collect();
            alone.sort_unstable();
            pieces.sort_unstable();
            proptest::prop_assert_eq!(pieces, alone);
            let area: f64 = s.pieces.iter().map(|p| p.area).sum();
            proptest::prop_assert!((area - s.area).abs() <= 1e-9 * s.area, "{} {}", area, s.area);
            proptest::prop_assert!(s.pieces.windows(2).all(|w| w[0].area >= w[1].area));
            proptest::prop_assert!(s.pieces.iter().all(|p| p.pieces.is_empty()));
            // Each triangle's shell: as many as its measures count, the same area.
            let of_face = m.measure_shells().1;
            for (k, p) in s.pieces.iter().enumerate() {
                let mine: Vec<usize> = (0..m.len()).filter(|&f| of_face[f] == k as u32).collect();
                proptest::prop_assert_eq!(mine.len(), p.faces);
                let area = only(&m, &mine).measure_surface().area;
                proptest::prop_assert!((area - p.area).abs() <= 1e-9 * p.area, "{} {}", area, p.area);
            }
            let none = of_face.iter().filter(|&&k| k == u32::MAX).count();
            proptest::prop_assert_eq!(none, m.len() - s.faces);
            // Where every shell closes so, the whole does, and encloses what they do.
            let each = s.pieces.iter().map(|p| p.volume).sum::<Option<f64>>();
            if let Some(each) = each.filter(|_| !s.pieces.is_empty()) {
                let whole = s.volume.unwrap_or(f64::NAN);
                proptest::prop_assert!((each - whole).abs() < 1e-5, "{} {}", each, whole);
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

    /// Each shell measured alone: a torus and a cube apart, the torus (larger) first with its
    /// handle; two cubes touching along an edge each closed though the whole is not; a cube
    /// with a face gone beside a whole one; a cavity's inner wall, facing in, enclosing less.
    #[test]
    fn each_shell_is_measured_alone() {
        let both = joined(&cube(), &moved(&torus(16), Vec3::new(10.0, 0.0, 0.0)));
        let s = both.measure_surface();
        assert_eq!((s.shells, s.genus()), (2, Some(1)));
        let [ring, block] = &s.pieces[..] else {
            panic!("{s:?}")
        };
        // Each triangle's shell: the cube's 12 (first in the file) are the second's.
        let of_face = both.measure_shells().1;
        assert_eq!(of_face[..12], [1; 12]);
        assert!(of_face[12..].iter().all(|&k| k == 0));
        assert_eq!(
            (ring.faces, ring.shells, ring.genus(), ring.euler()),
            (512, 1, Some(1), 0)
        );
        assert_eq!(
            (block.faces, block.genus(), block.area, block.volume),
            (12, Some(0), 6.0, Some(1.0))
        );
        assert_eq!((block.vertices, block.edges), (8, 18));
        assert_eq!(
            (block.bounds.min, block.bounds.max),
            (Vec3::ZERO, Vec3::ONE)
        );
        assert_eq!(ring.bounds.min.x, 7.0);
        assert!((ring.area + block.area - s.area).abs() < 1e-9);
        assert!((ring.volume.unwrap() + 1.0 - s.volume.unwrap()).abs() < 1e-9);

        let touching = joined(&cube(), &moved(&cube(), Vec3::new(1.0, 1.0, 0.0)));
        let s = touching.measure_surface();
        assert!(!s.closed());
        for p in &s.pieces {
            assert!(p.closed(), "{p:?}");
            assert_eq!(
                (p.non_manifold_edges, p.volume, p.genus()),
                (0, Some(1.0), Some(0))
            );
        }

        let mut open = cube();
        open.triangles.drain(0..2);
        let s = joined(&open, &moved(&cube(), Vec3::new(0.0, 0.0, 5.0))).measure_surface();
        let [whole, broken] = &s.pieces[..] else {
            panic!("{s:?}")
        };
        assert!(whole.closed() && !broken.closed());
        assert_eq!(
            (broken.boundary_edges, broken.holes, broken.volume),
            (4, 1, None)
        );
        assert_eq!((whole.boundary_edges, whole.holes, s.holes), (0, 0, 1));

        // A 4-unit cube with a unit cavity: its wall faces in, so the cavity's volume is
        // negative and the two add to the solid's 63.
        let outer = TriMesh {
            positions: cube().positions.iter().map(|&p| 4.0 * p).collect(),
            triangles: cube().triangles,
        };
        let mut cavity = moved(&cube(), Vec3::splat(1.5));
        cavity.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let s = joined(&outer, &cavity).measure_surface();
        let volumes: Vec<Option<f64>> = s.pieces.iter().map(|p| p.volume).collect();
        assert_eq!(volumes, [Some(64.0), Some(-1.0)]);
        assert_eq!(s.volume, Some(63.0));
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
