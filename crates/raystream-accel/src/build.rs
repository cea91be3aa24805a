//! kd-tree construction on the CPU: the two builders produce a [`KdBuildNode`] tree over
//! triangle references with exact clipped bounds; `flat.rs` turns it into the flat layout.
//!
//! - `median`: the paper's builder — split axis cycles x→y→z with depth, split at the spatial
//!   median of the node, until few triangles are left or the depth limit is reached.
//! - `sah`: surface-area heuristic with perfect splits (Wald & Havran 2006, "On building fast
//!   kd-trees for ray tracing, and on doing that in O(N log N)"). Large nodes are binned (32 bins
//!   per axis, O(n) per node), small nodes sweep exact sorted events (planar triangles included);
//!   the empty-space bonus favours cutting off empty space; the two subtrees of large nodes are
//!   built in parallel with rayon. A traversal step costs [`DEFAULT_TRAVERSAL_COST`] triangle
//!   tests unless the caller prices it otherwise (`KdTree::build_with`): dearer steps make
//!   shallower trees with fuller leaves.

use rayon::prelude::*;
use raystream_math::{Aabb, Vec3};

use crate::clip::split_clipped_bounds;
use crate::layout::MAX_DEPTH;

/// Which kd-tree builder to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Builder {
    #[default]
    Sah,
    Median,
}

impl Builder {
    pub fn name(self) -> &'static str {
        match self {
            Builder::Sah => "sah",
            Builder::Median => "median",
        }
    }
}

impl std::str::FromStr for Builder {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sah" => Ok(Builder::Sah),
            "median" => Ok(Builder::Median),
            _ => Err(format!(
                "unknown kd-tree builder '{s}' (expected sah or median)"
            )),
        }
    }
}

/// The yardstick of `TreeStats::sah_cost`: cost of one traversal step and of one triangle test,
/// in the same units, whatever the build priced them at (so that trees compare).
pub const COST_TRAVERSAL: f32 = 1.0;
pub const COST_INTERSECT: f32 = 1.0;
/// What the SAH builder prices a traversal step at, in triangle tests, by default: the ratio
/// that traces fastest on the CPU (1 against 0.5, 2 and 4: BENCHMARKS.md).
pub const DEFAULT_TRAVERSAL_COST: f32 = 1.0;
/// The range of traversal costs the SAH builder accepts.
pub const TRAVERSAL_COST_RANGE: std::ops::RangeInclusive<f32> = 0.01..=1000.0;
/// Factor on the cost of a split that cuts off empty space (Wald & Havran's λ).
const EMPTY_BONUS: f32 = 0.9;
const BINS: usize = 32;
/// Nodes with at most this many references sweep exact events instead of bins.
const EXACT_MAX: usize = 12;
/// Nodes with more references than this build their two subtrees in parallel.
const PARALLEL_MIN: usize = 2048;
/// Nodes with at least this many references also bin and partition them in parallel, in runs
/// of [`SPLIT_RUN`].
const PARALLEL_SPLIT_MIN: usize = 1 << 16;
const SPLIT_RUN: usize = 1 << 13;
/// The median builder stops at this many references.
const MEDIAN_LEAF: usize = 8;

/// A node of the tree under construction (builder only).
#[derive(PartialEq)]
pub(crate) enum KdBuildNode {
    Leaf(Vec<u32>),
    Inner {
        axis: usize,
        split: f32,
        children: Box<[KdBuildNode; 2]>,
        /// What the subtree takes in the flat arrays, this node included.
        sizes: Sizes,
    },
}

/// Entries a subtree takes in each of the flat arrays (inner nodes, leaves, triangle
/// references); with them the subtrees can be written into disjoint slices in parallel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Sizes {
    pub inners: usize,
    pub leaves: usize,
    pub tris: usize,
}

impl Sizes {
    /// One inner node.
    pub const INNER: Sizes = Sizes {
        inners: 1,
        leaves: 0,
        tris: 0,
    };
}

impl std::ops::Add for Sizes {
    type Output = Sizes;
    fn add(self, o: Sizes) -> Sizes {
        Sizes {
            inners: self.inners + o.inners,
            leaves: self.leaves + o.leaves,
            tris: self.tris + o.tris,
        }
    }
}

impl KdBuildNode {
    pub fn sizes(&self) -> Sizes {
        match self {
            KdBuildNode::Leaf(prims) => Sizes {
                inners: 0,
                leaves: 1,
                tris: prims.len(),
            },
            KdBuildNode::Inner { sizes, .. } => *sizes,
        }
    }

    /// Whether the subtree is big enough to be worth a parallel task.
    pub fn is_big(&self) -> bool {
        self.sizes().tris >= PARALLEL_MIN
    }

    /// Frees the tree, large subtrees in parallel (the recursive drop of half a million
    /// boxed nodes is otherwise a serial tail of the build).
    pub fn free(self) {
        if let KdBuildNode::Inner { children, .. } = self {
            let [l, r] = *children;
            if l.is_big() || r.is_big() {
                rayon::join(|| l.free(), || r.free());
            } else {
                drop((l, r));
            }
        }
    }
}

#[derive(Clone, Copy)]
struct Ref {
    prim: u32,
    bounds: Aabb,
}

struct Ctx<'a> {
    corners: &'a [[Vec3; 3]],
    builder: Builder,
    max_depth: usize,
    /// A traversal step's cost in triangle tests (SAH).
    traversal_cost: f32,
    /// Nodes of this many references or more bin and partition them in parallel runs.
    split_min: usize,
}

/// The depth limit for `n` triangles: 8 + 1.3·log2(n) (as pbrt), at most [`MAX_DEPTH`].
pub fn depth_limit(n: usize) -> usize {
    ((8.0 + 1.3 * (n.max(1) as f64).log2()).round() as usize).min(MAX_DEPTH)
}

/// Builds over the given triangles (`corners[prim]`), skipping `prims` not listed; the SAH
/// builder prices a traversal step at `traversal_cost` triangle tests.
pub(crate) fn build(
    corners: &[[Vec3; 3]],
    prims: &[u32],
    bounds: Aabb,
    builder: Builder,
    traversal_cost: f32,
) -> KdBuildNode {
    build_splitting(
        corners,
        prims,
        bounds,
        builder,
        traversal_cost,
        PARALLEL_SPLIT_MIN,
    )
}

/// [`build`], nodes of `split_min` references or more binned and partitioned in parallel runs
/// (the same tree whatever `split_min`).
pub(crate) fn build_splitting(
    corners: &[[Vec3; 3]],
    prims: &[u32],
    bounds: Aabb,
    builder: Builder,
    traversal_cost: f32,
    split_min: usize,
) -> KdBuildNode {
    let ctx = Ctx {
        corners,
        builder,
        max_depth: depth_limit(prims.len()),
        traversal_cost,
        split_min,
    };
    let refs: Vec<Ref> = prims
        .par_iter()
        .map(|&prim| Ref {
            prim,
            bounds: Aabb::from_points(&corners[prim as usize]),
        })
        .collect();
    ctx.node(refs, bounds, 0)
}

/// A split candidate: plane and cost.
#[derive(Clone, Copy)]
struct Split {
    axis: usize,
    pos: f32,
    cost: f32,
}

fn split_box(b: &Aabb, axis: usize, pos: f32) -> (Aabb, Aabb) {
    let (mut l, mut r) = (*b, *b);
    l.max[axis] = pos;
    r.min[axis] = pos;
    (l, r)
}

impl Ctx<'_> {
    fn node(&self, refs: Vec<Ref>, bounds: Aabb, depth: usize) -> KdBuildNode {
        let split = if depth >= self.max_depth || refs.len() <= 1 {
            None
        } else {
            match self.builder {
                Builder::Sah => self.sah_split(&refs, &bounds),
                Builder::Median => self.median_split(&refs, &bounds, depth),
            }
        };
        let Some(s) = split else {
            return KdBuildNode::Leaf(refs.iter().map(|r| r.prim).collect());
        };
        let n = refs.len();
        let (lb, rb) = split_box(&bounds, s.axis, s.pos);
        let (left, right) = self.partition(refs, s);
        if self.builder == Builder::Median && left.len() == n && right.len() == n {
            // No triangle was separated: splitting again would only duplicate references.
            let mut prims: Vec<u32> = left.iter().map(|r| r.prim).collect();
            prims.sort_unstable();
            return KdBuildNode::Leaf(prims);
        }
        let (l, r) = if n >= PARALLEL_MIN {
            rayon::join(
                || self.node(left, lb, depth + 1),
                || self.node(right, rb, depth + 1),
            )
        } else {
            (
                self.node(left, lb, depth + 1),
                self.node(right, rb, depth + 1),
            )
        };
        KdBuildNode::Inner {
            axis: s.axis,
            split: s.pos,
            sizes: Sizes::INNER + l.sizes() + r.sizes(),
            children: Box::new([l, r]),
        }
    }

    fn median_split(&self, refs: &[Ref], b: &Aabb, depth: usize) -> Option<Split> {
        if refs.len() <= MEDIAN_LEAF {
            return None;
        }
        let axis = depth % 3;
        let pos = 0.5 * (b.min[axis] + b.max[axis]);
        (pos > b.min[axis] && pos < b.max[axis]).then_some(Split {
            axis,
            pos,
            cost: 0.0,
        })
    }

    fn sah_split(&self, refs: &[Ref], b: &Aabb) -> Option<Split> {
        let area = b.area();
        if area.is_nan() || area <= 0.0 {
            return None;
        }
        // In triangle tests: a leaf costs one per reference.
        let leaf_cost = refs.len() as f32;
        let kt = self.traversal_cost;
        let best = if refs.len() <= EXACT_MAX {
            (0..3)
                .filter_map(|a| exact_sweep(refs, b, a, kt))
                .min_by(|x, y| x.cost.total_cmp(&y.cost))
        } else {
            binned(refs, b, kt, self.split_min)
        }?;
        (best.cost < leaf_cost).then_some(best)
    }

    /// The references below and above the split, each side in the order of `refs`. The left
    /// side is written over `refs` (each reference gives it at most one, so it never overtakes
    /// the reading), and only the right side is allocated, to the size it can reach: a node
    /// no longer allocates twice its references, which page faults made a tenth of a build.
    /// Large nodes (`split_min`) split runs of them in parallel.
    fn partition(&self, mut refs: Vec<Ref>, s: Split) -> (Vec<Ref>, Vec<Ref>) {
        if refs.len() >= self.split_min {
            return self.partition_runs(&refs, s);
        }
        let reach_right = refs
            .iter()
            .filter(|r| !(r.bounds.max[s.axis] < s.pos))
            .count();
        let mut right = Vec::with_capacity(reach_right);
        let mut kept = 0;
        for i in 0..refs.len() {
            let (below, above) = self.sides(&refs[i], s);
            if let Some(r) = below {
                refs[kept] = r;
                kept += 1;
            }
            right.extend(above);
        }
        refs.truncate(kept);
        (refs, right)
    }

    /// [`Self::partition`] of a large node: runs of [`SPLIT_RUN`] references split in
    /// parallel, each into sides of its own, joined in order in parallel (the same sides as
    /// one pass). Above a build's first levels every subtree is a parallel task of its own;
    /// this keeps the cores busy in those levels too, whose nodes hold all the references.
    fn partition_runs(&self, refs: &[Ref], s: Split) -> (Vec<Ref>, Vec<Ref>) {
        let runs: Vec<(Vec<Ref>, Vec<Ref>)> = refs
            .par_chunks(SPLIT_RUN)
            .map(|run| {
                let (mut left, mut right) = (Vec::new(), Vec::new());
                for r in run {
                    let (below, above) = self.sides(r, s);
                    left.extend(below);
                    right.extend(above);
                }
                (left, right)
            })
            .collect();
        let (mut left, mut right) = (Vec::new(), Vec::new());
        crate::par::concat_into(&mut left, runs.len(), |r| &runs[r].0);
        crate::par::concat_into(&mut right, runs.len(), |r| &runs[r].1);
        (left, right)
    }

    /// Reference `r` below and above the split `s`, with its bounds on each side; `None` on a
    /// side it does not reach.
    #[inline]
    fn sides(&self, r: &Ref, s: Split) -> (Option<Ref>, Option<Ref>) {
        let a = s.axis;
        let (lo, hi) = (r.bounds.min[a], r.bounds.max[a]);
        if hi < s.pos {
            (Some(*r), None)
        } else if lo > s.pos {
            (None, Some(*r))
        } else if lo == hi {
            // In the plane: on both sides, for rays that start on it or run inside it.
            (Some(*r), Some(*r))
        } else {
            // Straddles or touches the plane. Children are closed boxes: a triangle that
            // touches a child's face is in it, so a ray starting on (or running in) a split
            // plane finds it from either side.
            // Clipping tightens the bounds in each child, and drops the triangle from a
            // child it only seemed to reach through its (outward-rounded) bounds.
            // The triangle is clipped to its bounds in this node once, then split.
            let tri = &self.corners[r.prim as usize];
            let [below, above] = split_clipped_bounds(tri, &r.bounds, a, s.pos);
            let with = |bounds| Ref {
                prim: r.prim,
                bounds,
            };
            (below.map(with), above.map(with))
        }
    }
}

/// Cost of splitting `b` at `pos` with `nl`, `nr` references on each side, in triangle tests
/// (a traversal step costs `kt`).
#[inline]
fn sah_cost(b: &Aabb, inv_area: f32, axis: usize, pos: f32, nl: usize, nr: usize, kt: f32) -> f32 {
    let e = b.extent();
    let (e1, e2) = (e[(axis + 1) % 3], e[(axis + 2) % 3]);
    // Area of a box with extent `len` along `axis`: 2(e1·e2 + len·(e1 + e2)).
    let cap = e1 * e2;
    let side = e1 + e2;
    let al = cap + (pos - b.min[axis]) * side;
    let ar = cap + (b.max[axis] - pos) * side;
    // The counts through u32 (a node's references number far below 2³²: 28 bytes each), whose
    // conversion to f32 is one instruction where usize's takes a test and two on x86-64.
    let c = kt + 2.0 * inv_area * (al * nl as u32 as f32 + ar * nr as u32 as f32);
    if nl == 0 || nr == 0 {
        c * EMPTY_BONUS
    } else {
        c
    }
}

/// The cheapest of the `BINS − 1` planes per axis, counting the references in one pass over
/// them for all three axes.
fn binned(refs: &[Ref], b: &Aabb, kt: f32, split_min: usize) -> Option<Split> {
    let ext = b.extent();
    let scale: [f32; 3] = std::array::from_fn(|a| BINS as f32 / ext[a]);
    // Through u32, not usize: the baseline x86-64 has no unsigned 64-bit conversion (two
    // conversions and a select each). The same bin: below 0 and NaN give 0 either way, and
    // beyond u32 saturates to the last bin as beyond usize did.
    let bin = |x: f32, a: usize| (((x - b.min[a]) * scale[a]) as u32).min(BINS as u32 - 1) as usize;
    // Counts per run of references, summed: the same counts in any order.
    let count = |run: &[Ref]| {
        let mut starts = [[0u32; BINS]; 3];
        let mut ends = [[0u32; BINS]; 3];
        for r in run {
            for a in 0..3 {
                starts[a][bin(r.bounds.min[a], a)] += 1;
                ends[a][bin(r.bounds.max[a], a)] += 1;
            }
        }
        (starts, ends)
    };
    let (starts, ends) = if refs.len() >= split_min {
        refs.par_chunks(SPLIT_RUN).map(count).reduce(
            || ([[0; BINS]; 3], [[0; BINS]; 3]),
            |(mut s, mut e), (s2, e2)| {
                for a in 0..3 {
                    for i in 0..BINS {
                        s[a][i] += s2[a][i];
                        e[a][i] += e2[a][i];
                    }
                }
                (s, e)
            },
        )
    } else {
        count(refs)
    };
    let inv_area = 1.0 / b.area();
    let mut best: Option<Split> = None;
    for axis in 0..3 {
        let lo = b.min[axis];
        if !(ext[axis] > 0.0) {
            continue;
        }
        let (mut nl, mut nr) = (0usize, refs.len());
        for i in 1..BINS as u32 {
            nl += starts[axis][i as usize - 1] as usize;
            nr -= ends[axis][i as usize - 1] as usize;
            let pos = lo + ext[axis] * (i as f32 / BINS as f32);
            if !(pos > b.min[axis] && pos < b.max[axis]) {
                continue;
            }
            let cost = sah_cost(b, inv_area, axis, pos, nl, nr, kt);
            if best.is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, pos, cost });
            }
        }
    }
    best
}

/// Wald & Havran's sweep over sorted events, with planar triangles sent to the cheaper side.
/// Only small nodes (at most [`EXACT_MAX`] references) sweep, so the events fit on the stack.
fn exact_sweep(refs: &[Ref], b: &Aabb, axis: usize, kt: f32) -> Option<Split> {
    const END: u8 = 0;
    const PLANAR: u8 = 1;
    const START: u8 = 2;
    assert!(refs.len() <= EXACT_MAX, "exact sweeps are for small nodes");
    // An event is one u64 whose order is (position, kind): the position's bits mapped so that
    // unsigned order is `f32::total_cmp` order, above the kind. Integer keys sort fastest.
    let key = |x: f32, kind: u8| {
        // −0 as +0, so that one position has one key.
        let bits = (x + 0.0).to_bits();
        let ordered = if bits & 0x8000_0000 != 0 {
            !bits
        } else {
            bits | 0x8000_0000
        };
        (ordered as u64) << 8 | kind as u64
    };
    let pos_of = |k: u64| {
        let ordered = (k >> 8) as u32;
        f32::from_bits(if ordered & 0x8000_0000 != 0 {
            ordered & 0x7fff_ffff
        } else {
            !ordered
        })
    };
    let mut buf = [0u64; 2 * EXACT_MAX];
    let mut n = 0;
    for r in refs {
        let (lo, hi) = (r.bounds.min[axis], r.bounds.max[axis]);
        if lo == hi {
            buf[n] = key(lo, PLANAR);
            n += 1;
        } else {
            buf[n] = key(lo, START);
            buf[n + 1] = key(hi, END);
            n += 2;
        }
    }
    let events = &mut buf[..n];
    events.sort_unstable();
    let inv_area = 1.0 / b.area();
    let (mut nl, mut nr) = (0usize, refs.len());
    let mut best: Option<Split> = None;
    let mut i = 0;
    while i < events.len() {
        // The events at one position, counted by kind (sorted: ends, planar, starts).
        let at = events[i] >> 8;
        let pos = pos_of(events[i]);
        let mut kinds = [0usize; 3];
        while i < events.len() && events[i] >> 8 == at {
            kinds[(events[i] & 0xff) as usize] += 1;
            i += 1;
        }
        let [ends, planar, starts] = [
            kinds[END as usize],
            kinds[PLANAR as usize],
            kinds[START as usize],
        ];
        // Closed children: everything touching the plane counts on both sides.
        if pos > b.min[axis] && pos < b.max[axis] {
            let cost = sah_cost(b, inv_area, axis, pos, nl + planar + starts, nr, kt);
            if best.is_none_or(|s| cost < s.cost) {
                best = Some(Split { axis, pos, cost });
            }
        }
        nr -= planar + ends;
        nl += starts + planar;
    }
    best
}
