//! CPU traversal of the flat kd-tree: stackless with ropes (the default, the algorithm the GPU
//! kernels run) and the classic front-to-back stack traversal, each for closest-hit and any-hit.
//!
//! Contract of every query: invalid rays (see `Ray::is_valid`, NaN included) miss; a hit needs
//! `t_min ≤ t ≤ t_max`; closest-hit returns the smallest such t (ties: the first triangle found);
//! any-hit returns some hit in the range.

use raystream_math::Ray;

use crate::intersect::WatertightRay;
use crate::layout::{KdLeaf, LEAF_BIT, MAX_DEPTH, NO_ROPE, is_leaf};
use crate::{Hit, KdTree};

/// Which traversal to run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Traversal {
    #[default]
    Ropes,
    Stack,
}

impl Traversal {
    pub fn name(self) -> &'static str {
        match self {
            Traversal::Ropes => "ropes",
            Traversal::Stack => "stack",
        }
    }
}

impl std::str::FromStr for Traversal {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "ropes" => Ok(Traversal::Ropes),
            "stack" => Ok(Traversal::Stack),
            _ => Err(format!("unknown traversal '{s}' (expected ropes or stack)")),
        }
    }
}

/// Work done by queries, summed: inner nodes and leaves visited, triangles tested.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub inner: u64,
    pub leaves: u64,
    pub triangles: u64,
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.inner += o.inner;
        self.leaves += o.leaves;
        self.triangles += o.triangles;
    }
}

/// Rope walks interleaved by [`KdTree::ropes_stream`].
pub const STREAM_LANES: usize = 8;

/// One ray's rope walk in progress: where it is and what it has found.
#[derive(Clone, Copy)]
struct RopeWalk {
    r: RayCtx,
    node: u32,
    t_entry: f32,
    t_best: f32,
    best: Option<Hit>,
    /// Leaves it may still visit (a guard against a broken tree).
    leaf_budget: usize,
}

/// Per-ray data of a traversal: the ray, its reciprocal direction with zero components made
/// +0 (so that +inf, never −inf, stands for "parallel") and the watertight-test constants.
#[derive(Clone, Copy)]
struct RayCtx {
    o: [f32; 4],
    inv: [f32; 4],
    neg: [bool; 4],
    t_min: f32,
    wt: WatertightRay,
}

impl RayCtx {
    fn new(ray: &Ray) -> Self {
        let d = ray.dir.map(|x| if x == 0.0 { 0.0 } else { x });
        Self {
            o: ray.origin.extend(0.0).to_array(),
            inv: d.recip().extend(0.0).to_array(),
            neg: [
                d.x.is_sign_negative(),
                d.y.is_sign_negative(),
                d.z.is_sign_negative(),
                false,
            ],
            t_min: ray.t_min,
            wt: WatertightRay::new(ray),
        }
    }
}

impl KdTree {
    #[inline(always)]
    fn test_leaf<const ANY: bool, const COUNT: bool>(
        &self,
        leaf: &KdLeaf,
        r: &RayCtx,
        best: &mut Option<Hit>,
        t_best: &mut f32,
        c: &mut Counters,
    ) -> bool {
        let tris = &self.tris[leaf.first as usize..(leaf.first + leaf.count) as usize];
        if COUNT {
            c.leaves += 1;
            c.triangles += tris.len() as u64;
        }
        for tri in tris {
            if let Some((t, u, v)) = r.wt.intersect_tri(tri, r.t_min, *t_best)
                && (ANY || t < *t_best || best.is_none())
            {
                *t_best = t;
                *best = Some(Hit {
                    t,
                    prim: tri.prim(),
                    u,
                    v,
                });
                if ANY {
                    return true;
                }
            }
        }
        false
    }

    /// The ray's interval inside the scene box and its traversal constants; `None` for a ray
    /// that cannot hit anything (invalid, empty scene, or missing the box).
    fn start(&self, ray: &Ray) -> Option<(f32, f32, RayCtx)> {
        if !ray.is_valid() || self.tris.is_empty() {
            return None;
        }
        let (t0, t1) = self.bounds.clip_ray(ray)?;
        Some((t0, t1, RayCtx::new(ray)))
    }

    /// Stackless traversal with ropes.
    pub(crate) fn ropes<const ANY: bool, const COUNT: bool>(
        &self,
        ray: &Ray,
        c: &mut Counters,
    ) -> Option<Hit> {
        let mut w = self.walk(ray)?;
        loop {
            while !is_leaf(w.node) {
                self.descend_once::<COUNT>(&mut w, c);
            }
            if self.leaf_step::<ANY, COUNT>(&mut w, c) {
                return w.best;
            }
        }
    }

    /// The start of one ray's rope walk; `None` for a ray that hits nothing.
    #[inline(always)]
    fn walk(&self, ray: &Ray) -> Option<RopeWalk> {
        let (t_entry, _, r) = self.start(ray)?;
        Some(RopeWalk {
            t_best: ray.t_max,
            r,
            node: self.root,
            t_entry,
            best: None,
            leaf_budget: self.leaves.len() + self.inners.len() + 1,
        })
    }

    /// One step down from the inner node `w.node` toward the leaf holding the entry point.
    #[inline(always)]
    fn descend_once<const COUNT: bool>(&self, w: &mut RopeWalk, c: &mut Counters) {
        let n = &self.inners[w.node as usize];
        let a = (n.axis & 3) as usize;
        let t_split = (n.split - w.r.o[a]) * w.r.inv[a];
        // The plane was crossed at or before the entry point: the point is on the far side.
        let far = t_split <= w.t_entry;
        w.node = if far != w.r.neg[a] { n.right } else { n.left };
        if COUNT {
            c.inner += 1;
        }
    }

    /// Tests the leaf `w.node` and follows the rope out of it; true when the walk is over
    /// (`w.best` is then the answer).
    #[inline(always)]
    fn leaf_step<const ANY: bool, const COUNT: bool>(
        &self,
        w: &mut RopeWalk,
        c: &mut Counters,
    ) -> bool {
        let leaf = &self.leaves[(w.node & !LEAF_BIT) as usize];
        if self.test_leaf::<ANY, COUNT>(leaf, &w.r, &mut w.best, &mut w.t_best, c) {
            return true;
        }
        // Exit face of the leaf.
        let r = &w.r;
        let mut t_exit = f32::INFINITY;
        let mut face = 0usize;
        for a in 0..3 {
            let bound = if r.neg[a] { leaf.min[a] } else { leaf.max[a] };
            let t = (bound - r.o[a]) * r.inv[a];
            if t < t_exit {
                t_exit = t;
                face = 2 * a + (!r.neg[a]) as usize;
            }
        }
        // Every step moves to a leaf strictly further along some axis, so the walk ends; the
        // budget only guards against a broken tree.
        w.leaf_budget -= 1;
        if w.t_best <= t_exit || w.leaf_budget == 0 {
            return true;
        }
        w.node = leaf.ropes[face];
        if w.node == NO_ROPE {
            return true;
        }
        w.t_entry = w.t_entry.max(t_exit);
        false
    }

    /// The rope traversal of many rays at once, [`STREAM_LANES`] walks interleaved a step at
    /// a time. The hits are those of [`Self::ropes`], ray for ray: each walk runs the same
    /// steps. What it gains is memory-level parallelism: a single walk is a chain of dependent
    /// node loads that mostly miss the caches, and the interleaved walks' loads overlap.
    pub(crate) fn ropes_stream<const ANY: bool>(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        let mut c = Counters::default();
        let mut next = 0;
        // Starts the next ray that can hit something in `lane` (answering the others), or
        // leaves the lane empty when the rays are used up.
        let mut refill = |lane: &mut Option<(usize, RopeWalk)>, out: &mut [Option<Hit>]| {
            *lane = None;
            while next < rays.len() {
                let i = next;
                next += 1;
                match self.walk(&rays[i]) {
                    Some(w) => {
                        *lane = Some((i, w));
                        return;
                    }
                    None => out[i] = None,
                }
            }
        };
        let mut lanes: [Option<(usize, RopeWalk)>; STREAM_LANES] = Default::default();
        for lane in &mut lanes {
            refill(lane, out);
        }
        loop {
            let mut active = false;
            for lane in &mut lanes {
                let Some((i, w)) = lane else { continue };
                active = true;
                if !is_leaf(w.node) {
                    self.descend_once::<false>(w, &mut c);
                } else if self.leaf_step::<ANY, false>(w, &mut c) {
                    out[*i] = w.best;
                    refill(lane, out);
                }
            }
            if !active {
                return;
            }
        }
    }

    /// Classic kd-tree traversal with a stack of far children.
    pub(crate) fn stack<const ANY: bool, const COUNT: bool>(
        &self,
        ray: &Ray,
        c: &mut Counters,
    ) -> Option<Hit> {
        let (mut t0, mut t1, r) = self.start(ray)?;
        let mut best = None;
        let mut t_best = ray.t_max;
        let mut stack = [(0u32, 0f32, 0f32); MAX_DEPTH + 1];
        let mut sp = 0;
        let mut node = self.root;
        loop {
            while !is_leaf(node) {
                let n = &self.inners[node as usize];
                let a = (n.axis & 3) as usize;
                let t_split = (n.split - r.o[a]) * r.inv[a];
                let (near, far) = if r.neg[a] {
                    (n.right, n.left)
                } else {
                    (n.left, n.right)
                };
                if COUNT {
                    c.inner += 1;
                }
                // NaN (a ray lying in the plane) goes to the near side, as in the rope traversal.
                if !(t_split <= t1) {
                    node = near;
                } else if t_split < t0 {
                    node = far;
                } else {
                    stack[sp] = (far, t_split, t1);
                    sp += 1;
                    node = near;
                    t1 = t_split;
                }
            }
            let leaf = &self.leaves[(node & !LEAF_BIT) as usize];
            if self.test_leaf::<ANY, COUNT>(leaf, &r, &mut best, &mut t_best, c) || t_best <= t1 {
                return best;
            }
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                (node, t0, t1) = stack[sp];
                if t0 <= t_best {
                    break;
                }
            }
        }
    }
}
