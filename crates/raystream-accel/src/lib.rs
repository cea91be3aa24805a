//! kd-tree acceleration for triangle meshes: two builders (the paper's round-robin spatial
//! median and SAH with perfect splits), ropes for stackless traversal, the flat `#[repr(C)]`
//! layout shared with the GPU, and CPU queries over it (closest-hit and any-hit, with ropes or
//! a stack). `validate()` checks a built tree; `brute` is the oracle every query is tested
//! against.
//!
//! # Example
//!
//! A mesh from a file's bytes (a square in OBJ, fanned into two triangles), its SAH tree,
//! and closest-hit and any-hit queries, one ray and a batch, each checked against the
//! brute-force test of every triangle:
//!
//! ```
//! use std::path::Path;
//!
//! use raystream_accel::{Builder, KdTree, Traversal, brute};
//! use raystream_io::{MeshFormat, parse_mesh};
//! use raystream_math::{Ray, Vec3};
//!
//! let obj = b"v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n";
//! let mesh = parse_mesh(obj, MeshFormat::Obj, Path::new("square.obj"))?;
//! let tree = KdTree::build(&mesh, Builder::Sah);
//! let corners: Vec<[Vec3; 3]> = (0..mesh.len()).map(|i| mesh.corners(i)).collect();
//! tree.validate(&corners)?;
//!
//! // Down onto the square from 2 above it: t is in units of the direction's length.
//! let down = Ray::new(Vec3::new(0.5, 0.25, 2.0), Vec3::new(0.0, 0.0, -1.0), 0.0, f32::INFINITY);
//! let hit = tree.intersect(&down, Traversal::Ropes).expect("the ray meets the square");
//! // Triangle 0 is the face's first fan triangle, (v1, v2, v3) of the file; u and v weigh
//! // its second and third corners.
//! assert_eq!(hit.prim, 0);
//! assert!((hit.t - 2.0).abs() < 1e-6);
//! assert!((hit.u - 0.125).abs() < 1e-6 && (hit.v - 0.625).abs() < 1e-6);
//! assert_eq!(Some(hit), brute::closest(&corners, &down));
//!
//! // A batch (on every core, several rays' walks interleaved on each): rays over a grid,
//! // some passing beside the square; `any` asks only whether something lies in the way.
//! let rays: Vec<Ray> = (0..256)
//!     .map(|i| {
//!         let (x, y) = ((i % 16) as f32 / 5.0 - 1.5, (i / 16) as f32 / 5.0 - 1.5);
//!         Ray::new(Vec3::new(x, y, 1.0), Vec3::new(0.1, 0.0, -1.0), 0.0, f32::INFINITY)
//!     })
//!     .collect();
//! let closest = tree.intersect_all(&rays, Traversal::Ropes, false);
//! let blocked = tree.intersect_all(&rays, Traversal::Ropes, true);
//! for ((ray, hit), any) in rays.iter().zip(&closest).zip(&blocked) {
//!     assert_eq!(*hit, brute::closest(&corners, ray));
//!     assert_eq!(hit.is_some(), any.is_some());
//! }
//! assert!(closest.iter().any(|h| h.is_none()) && closest.iter().any(|h| h.is_some()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Comparisons are written so that NaN falls on the intended side (`!(x <= y)` is true for
// NaN); clippy's suggested rewrites would change that.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod brute;
mod build;
pub mod clip;
pub mod entry;
mod flat;
pub mod intersect;
pub mod isa;
pub mod layout;
pub mod par;
mod traverse;
mod validate;

use std::time::Instant;

use rayon::prelude::*;

pub use build::{Builder, DEFAULT_TRAVERSAL_COST, TRAVERSAL_COST_RANGE, depth_limit};
use raystream_io::TriMesh;
use raystream_math::{Aabb, DVec3, Ray, Vec3};
use traverse::RopeWalk;
pub use traverse::{Counters, Traversal};

use entry::EntryGrid;
pub use isa::Isa;
use layout::{KdInner, KdLeaf, KdTri};

/// A ray–triangle hit: distance in units of the ray direction's length, the triangle's prim id,
/// and the barycentric weights of its v1 (`u`) and v2 (`v`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

/// Statistics of a built tree, as `raystream info` reports them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeStats {
    pub builder: &'static str,
    pub nodes: usize,
    pub leaves: usize,
    pub empty_leaves: usize,
    pub max_depth: usize,
    /// Expected cost of a random ray by the surface-area heuristic (traversal step = 1, triangle
    /// test = 1, whatever the build priced a step at).
    pub sah_cost: f64,
    /// SAH builds: what the builder priced a traversal step at, in triangle tests.
    pub traversal_cost: Option<f32>,
    /// Mean triangle references per non-empty leaf.
    pub mean_tris_per_leaf: f64,
    /// Triangle references in all leaves (a triangle may sit in several).
    pub references: usize,
    /// Triangles in the tree (degenerate ones are left out: they can never be hit).
    pub triangles: usize,
    pub build_ms: f64,
}

/// A kd-tree over one mesh, in the flat layout.
#[derive(Clone, Debug)]
pub struct KdTree {
    /// The scene box: the root node's box.
    pub bounds: Aabb,
    /// The root's node reference.
    pub root: u32,
    pub inners: Vec<KdInner>,
    pub leaves: Vec<KdLeaf>,
    pub tris: Vec<KdTri>,
    /// Where rope walks start their first descent ([`entry`]).
    pub entry: EntryGrid,
    pub stats: TreeStats,
}

/// Whether a triangle has an area (computed in f64); degenerate triangles never get hit.
pub fn is_degenerate(c: &[Vec3; 3]) -> bool {
    let (a, b, d) = (c[0].as_dvec3(), c[1].as_dvec3(), c[2].as_dvec3());
    (b - a).cross(d - a) == DVec3::ZERO
}

impl KdTree {
    /// Builds a tree over a mesh's triangles with the chosen builder.
    pub fn build(mesh: &TriMesh, builder: Builder) -> KdTree {
        Self::build_with(mesh, builder, DEFAULT_TRAVERSAL_COST)
    }

    /// As [`KdTree::build`], the SAH builder pricing a traversal step at `traversal_cost`
    /// triangle tests (the median builder ignores it). Panics outside
    /// [`TRAVERSAL_COST_RANGE`] (callers check user input against it).
    pub fn build_with(mesh: &TriMesh, builder: Builder, traversal_cost: f32) -> KdTree {
        let corners: Vec<[Vec3; 3]> = (0..mesh.len()).map(|i| mesh.corners(i)).collect();
        Self::build_from_corners_with(&corners, builder, traversal_cost)
    }

    /// Builds over triangles given by their corners; triangle `i` gets prim id `i`.
    pub fn build_from_corners(corners: &[[Vec3; 3]], builder: Builder) -> KdTree {
        Self::build_from_corners_with(corners, builder, DEFAULT_TRAVERSAL_COST)
    }

    /// As [`KdTree::build_from_corners`], with the SAH's traversal cost (see
    /// [`KdTree::build_with`]).
    pub fn build_from_corners_with(
        corners: &[[Vec3; 3]],
        builder: Builder,
        traversal_cost: f32,
    ) -> KdTree {
        assert!(
            TRAVERSAL_COST_RANGE.contains(&traversal_cost),
            "SAH traversal cost {traversal_cost} outside {TRAVERSAL_COST_RANGE:?}"
        );
        let start = Instant::now();
        // In parallel, as every pass of the build over all the triangles (a serial one is a
        // part of the build that no core count shortens). Boxes grow by min and max, which
        // give the same box in any order but for the sign of a zero (min(−0, +0) may be
        // either): zeros are made +0, so that the tree's bytes never depend on the order.
        let prims: Vec<u32> = (0..corners.len() as u32)
            .into_par_iter()
            .filter(|&i| !is_degenerate(&corners[i as usize]))
            .collect();
        let bounds = prims
            .par_iter()
            .map(|&i| Aabb::from_points(&corners[i as usize]))
            .reduce(|| Aabb::EMPTY, Aabb::union);
        let bounds = Aabb::new(bounds.min + 0.0, bounds.max + 0.0);
        let root_node = build::build(corners, &prims, bounds, builder, traversal_cost);
        let (flat, root) = flat::flatten(&root_node, bounds, corners);
        root_node.free();
        let entry = EntryGrid::build(&bounds, root, &flat.inners, entry::DEFAULT_RES);
        let build_ms = start.elapsed().as_secs_f64() * 1e3;
        let empty_leaves = flat.leaves.iter().filter(|l| l.count == 0).count();
        let full = flat.leaves.len() - empty_leaves;
        let stats = TreeStats {
            builder: builder.name(),
            nodes: flat.inners.len() + flat.leaves.len(),
            leaves: flat.leaves.len(),
            empty_leaves,
            max_depth: flat.max_depth,
            sah_cost: flat.sah_cost,
            traversal_cost: (builder == Builder::Sah).then_some(traversal_cost),
            mean_tris_per_leaf: flat.tris.len() as f64 / full.max(1) as f64,
            references: flat.tris.len(),
            triangles: prims.len(),
            build_ms,
        };
        KdTree {
            bounds,
            root,
            inners: flat.inners,
            leaves: flat.leaves,
            tris: flat.tris,
            entry,
            stats,
        }
    }

    /// The closest hit in `[t_min, t_max]`.
    pub fn intersect(&self, ray: &Ray, traversal: Traversal) -> Option<Hit> {
        let mut c = Counters::default();
        match traversal {
            Traversal::Ropes => self.ropes::<false, false>(ray, &mut c),
            Traversal::Stack => self.stack::<false, false>(ray, &mut c),
        }
    }

    /// Some hit in `[t_min, t_max]` (occlusion); its `prim`, `u`, `v` are those of that hit.
    pub fn intersect_any(&self, ray: &Ray, traversal: Traversal) -> Option<Hit> {
        let mut c = Counters::default();
        match traversal {
            Traversal::Ropes => self.ropes::<true, false>(ray, &mut c),
            Traversal::Stack => self.stack::<true, false>(ray, &mut c),
        }
    }

    /// [`Self::intersect`] (or [`Self::intersect_any`] with `any`) of every ray, into `out`:
    /// the same answers, faster on many rays (eight rope walks interleaved; stack traversal
    /// ray by ray), in the instruction set [`Isa::current`].
    pub fn intersect_many(
        &self,
        rays: &[Ray],
        traversal: Traversal,
        any: bool,
        out: &mut [Option<Hit>],
    ) {
        self.intersect_many_in(Isa::current(), rays, traversal, any, out)
    }

    /// [`Self::intersect_many`] compiled for the instruction set `isa`; the baseline's where
    /// the processor lacks it ([`Isa::available`]). The answers are the same bytes in every
    /// instruction set.
    pub fn intersect_many_in(
        &self,
        isa: Isa,
        rays: &[Ray],
        traversal: Traversal,
        any: bool,
        out: &mut [Option<Hit>],
    ) {
        match isa {
            // SAFETY: the processor has every feature `queries_v3` is compiled for.
            #[cfg(target_arch = "x86_64")]
            Isa::X86_64V3 if isa.available() => unsafe {
                self.queries_v3(rays, traversal, any, out)
            },
            _ => self.queries(rays, traversal, any, out),
        }
    }

    /// [`Self::queries`] compiled for x86-64-v3 (see [`isa`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,movbe,f16c")]
    fn queries_v3(&self, rays: &[Ray], traversal: Traversal, any: bool, out: &mut [Option<Hit>]) {
        self.queries(rays, traversal, any, out)
    }

    /// The body of [`Self::intersect_many`], inlined into each instruction set's copy.
    #[inline(always)]
    fn queries(&self, rays: &[Ray], traversal: Traversal, any: bool, out: &mut [Option<Hit>]) {
        match (traversal, any) {
            (Traversal::Ropes, false) => self.walk_many::<RopeWalk, false>(rays, out),
            (Traversal::Ropes, true) => self.walk_many::<RopeWalk, true>(rays, out),
            // Interleaved, stack walks ran at half the speed of one at a time (each lane
            // carries its 780-byte stack; BENCHMARKS.md): they run ray by ray.
            (Traversal::Stack, _) => {
                assert_eq!(rays.len(), out.len(), "one result per ray");
                for (ray, o) in rays.iter().zip(out) {
                    *o = if any {
                        self.intersect_any(ray, traversal)
                    } else {
                        self.intersect(ray, traversal)
                    };
                }
            }
        }
    }

    /// [`Self::intersect_many`] over all rays in parallel (rayon, in chunks of 1024 rays).
    pub fn intersect_all(&self, rays: &[Ray], traversal: Traversal, any: bool) -> Vec<Option<Hit>> {
        let mut hits = Vec::new();
        self.intersect_all_into(rays, traversal, any, &mut hits);
        hits
    }

    /// [`Self::intersect_all`] into `out` (made one answer a ray, its memory kept): a caller
    /// that queries again and again allocates the answers once.
    pub fn intersect_all_into(
        &self,
        rays: &[Ray],
        traversal: Traversal,
        any: bool,
        out: &mut Vec<Option<Hit>>,
    ) {
        const CHUNK: usize = 1024;
        // Every answer is written by the query, so `out` only needs its length: entries it
        // already has are not set beforehand (a pass over all the answers, 20 bytes a ray,
        // which a caller that keeps `out` across queries would pay each time), and those it
        // gains are set in parallel.
        out.truncate(rays.len());
        let missing = rays.len() - out.len();
        out.par_extend((0..missing).into_par_iter().map(|_| None));
        rays.par_chunks(CHUNK)
            .zip(out.par_chunks_mut(CHUNK))
            .for_each(|(r, h)| self.intersect_many(r, traversal, any, h));
    }

    /// As [`Self::intersect`] / [`Self::intersect_any`], adding the work done to `counters`.
    pub fn intersect_counted(
        &self,
        ray: &Ray,
        traversal: Traversal,
        any: bool,
        counters: &mut Counters,
    ) -> Option<Hit> {
        match (traversal, any) {
            (Traversal::Ropes, false) => self.ropes::<false, true>(ray, counters),
            (Traversal::Ropes, true) => self.ropes::<true, true>(ray, counters),
            (Traversal::Stack, false) => self.stack::<false, true>(ray, counters),
            (Traversal::Stack, true) => self.stack::<true, true>(ray, counters),
        }
    }

    /// Rebuilds the entry grid with `res` cells along the scene box's longest side (0: none,
    /// every walk starting at the root; at most [`entry::MAX_RES`]). The hits do not change.
    pub fn set_entry_grid(&mut self, res: u32) {
        self.entry = EntryGrid::build(&self.bounds, self.root, &self.inners, res);
    }

    /// The box of a leaf.
    pub fn leaf_bounds(&self, leaf: usize) -> Aabb {
        let l = &self.leaves[leaf];
        Aabb::new(Vec3::from(l.min), Vec3::from(l.max))
    }
}

#[cfg(test)]
mod tests;
