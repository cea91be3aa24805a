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

/// Walks interleaved by [`KdTree::walk_many`].
const STREAM_LANES: usize = 8;

/// One ray's rope walk in progress: where it is and what it has found.
#[derive(Clone, Copy)]
pub(crate) struct RopeWalk {
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
pub(crate) struct RayCtx {
    o: [f32; 4],
    inv: [f32; 4],
    neg: [bool; 4],
    t_min: f32,
    wt: WatertightRay,
}

impl RayCtx {
    #[inline(always)]
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
    #[inline(always)]
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
        self.walk_one::<RopeWalk, ANY, COUNT>(ray, c)
    }

    /// Classic kd-tree traversal with a stack of far children.
    pub(crate) fn stack<const ANY: bool, const COUNT: bool>(
        &self,
        ray: &Ray,
        c: &mut Counters,
    ) -> Option<Hit> {
        self.walk_one::<StackWalk, ANY, COUNT>(ray, c)
    }

    /// One ray's walk, from start to answer.
    #[inline(always)]
    fn walk_one<W: Walker, const ANY: bool, const COUNT: bool>(
        &self,
        ray: &Ray,
        c: &mut Counters,
    ) -> Option<Hit> {
        let mut w = W::start(self, ray)?;
        loop {
            while !is_leaf(w.node()) {
                w.descend_once::<COUNT>(self, c);
            }
            if w.leaf_step::<ANY, COUNT>(self, c) {
                return w.best();
            }
        }
    }

    /// Many rays' walks, [`STREAM_LANES`] of them interleaved a step at a time. The hits are
    /// those of [`Self::walk_one`], ray for ray: each walk runs the same steps. What it gains
    /// is memory-level parallelism: a single walk is a chain of dependent node loads that
    /// mostly miss the caches, and the interleaved walks' loads overlap.
    #[inline(always)]
    pub(crate) fn walk_many<W: Walker, const ANY: bool>(
        &self,
        rays: &[Ray],
        out: &mut [Option<Hit>],
    ) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        let mut c = Counters::default();
        let mut next = 0;
        let mut lanes: [Option<(usize, W)>; STREAM_LANES] = std::array::from_fn(|_| None);
        for lane in &mut lanes {
            *lane = self.next_walk(rays, &mut next, out);
        }
        loop {
            let mut active = false;
            for lane in &mut lanes {
                let Some((i, w)) = lane else { continue };
                active = true;
                if !is_leaf(w.node()) {
                    w.descend_once::<false>(self, &mut c);
                } else if w.leaf_step::<ANY, false>(self, &mut c) {
                    out[*i] = w.best();
                    *lane = self.next_walk(rays, &mut next, out);
                }
            }
            if !active {
                return;
            }
        }
    }

    /// The walk of the next ray from `*next` on that can hit something (the others before it
    /// answered as misses), or `None` when the rays are used up. A function rather than a
    /// closure, so that it is inlined into each instruction set's copy of the queries
    /// ([`crate::isa`]): as a closure it stayed a baseline function of its own, a third of
    /// the time of lucy's primary rays.
    #[inline(always)]
    fn next_walk<W: Walker>(
        &self,
        rays: &[Ray],
        next: &mut usize,
        out: &mut [Option<Hit>],
    ) -> Option<(usize, W)> {
        while *next < rays.len() {
            let i = *next;
            *next += 1;
            match W::start(self, &rays[i]) {
                Some(w) => return Some((i, w)),
                None => out[i] = None,
            }
        }
        None
    }
}

/// A traversal advanced a step at a time: one inner node down, or one leaf's triangles and
/// the way out of it. One-ray queries run the steps in a loop; [`KdTree::walk_many`]
/// interleaves several rays' walks.
pub(crate) trait Walker: Sized {
    /// The walk of `ray`; `None` for a ray that hits nothing.
    fn start(tree: &KdTree, ray: &Ray) -> Option<Self>;
    /// The node the next step works on.
    fn node(&self) -> u32;
    /// One step down from the inner node [`Walker::node`].
    fn descend_once<const COUNT: bool>(&mut self, tree: &KdTree, c: &mut Counters);
    /// Tests the leaf [`Walker::node`] and finds the next node; true when the walk is over.
    fn leaf_step<const ANY: bool, const COUNT: bool>(
        &mut self,
        tree: &KdTree,
        c: &mut Counters,
    ) -> bool;
    /// The answer so far (the answer once the walk is over).
    fn best(&self) -> Option<Hit>;
}

impl Walker for RopeWalk {
    #[inline(always)]
    fn start(tree: &KdTree, ray: &Ray) -> Option<Self> {
        let (t_entry, _, r) = tree.start(ray)?;
        let node = tree.entry.start(
            tree.root,
            tree.bounds.min.to_array(),
            ray.origin.to_array(),
            ray.dir.to_array(),
            t_entry,
        );
        Some(RopeWalk {
            t_best: ray.t_max,
            r,
            node,
            t_entry,
            best: None,
            leaf_budget: tree.leaves.len() + tree.inners.len() + 1,
        })
    }

    #[inline(always)]
    fn node(&self) -> u32 {
        self.node
    }

    /// Toward the leaf holding the entry point.
    #[inline(always)]
    fn descend_once<const COUNT: bool>(&mut self, tree: &KdTree, c: &mut Counters) {
        let n = &tree.inners[self.node as usize];
        let a = (n.axis & 3) as usize;
        let t_split = (n.split - self.r.o[a]) * self.r.inv[a];
        // The plane was crossed at or before the entry point: the point is on the far side.
        let far = t_split <= self.t_entry;
        self.node = if far != self.r.neg[a] {
            n.right
        } else {
            n.left
        };
        if COUNT {
            c.inner += 1;
        }
    }

    /// Tests the leaf and follows the rope out of it.
    #[inline(always)]
    fn leaf_step<const ANY: bool, const COUNT: bool>(
        &mut self,
        tree: &KdTree,
        c: &mut Counters,
    ) -> bool {
        let leaf = &tree.leaves[(self.node & !LEAF_BIT) as usize];
        if tree.test_leaf::<ANY, COUNT>(leaf, &self.r, &mut self.best, &mut self.t_best, c) {
            return true;
        }
        // Exit face of the leaf.
        let r = &self.r;
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
        self.leaf_budget -= 1;
        if self.t_best <= t_exit || self.leaf_budget == 0 {
            return true;
        }
        self.node = leaf.ropes[face];
        if self.node == NO_ROPE {
            return true;
        }
        self.t_entry = self.t_entry.max(t_exit);
        false
    }

    #[inline(always)]
    fn best(&self) -> Option<Hit> {
        self.best
    }
}

/// One ray's stack traversal in progress: the node and its ray interval, and the far children
/// still to visit with theirs.
#[derive(Clone, Copy)]
pub(crate) struct StackWalk {
    r: RayCtx,
    node: u32,
    t0: f32,
    t1: f32,
    t_best: f32,
    best: Option<Hit>,
    stack: [(u32, f32, f32); MAX_DEPTH + 1],
    sp: usize,
}

impl Walker for StackWalk {
    #[inline(always)]
    fn start(tree: &KdTree, ray: &Ray) -> Option<Self> {
        let (t0, t1, r) = tree.start(ray)?;
        Some(StackWalk {
            r,
            node: tree.root,
            t0,
            t1,
            t_best: ray.t_max,
            best: None,
            stack: [(0, 0.0, 0.0); MAX_DEPTH + 1],
            sp: 0,
        })
    }

    #[inline(always)]
    fn node(&self) -> u32 {
        self.node
    }

    /// To the near child, keeping the far one for later when the interval reaches it.
    #[inline(always)]
    fn descend_once<const COUNT: bool>(&mut self, tree: &KdTree, c: &mut Counters) {
        let r = &self.r;
        let n = &tree.inners[self.node as usize];
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
        if !(t_split <= self.t1) {
            self.node = near;
        } else if t_split < self.t0 {
            self.node = far;
        } else {
            self.stack[self.sp] = (far, t_split, self.t1);
            self.sp += 1;
            self.node = near;
            self.t1 = t_split;
        }
    }

    /// Tests the leaf, then takes the nearest far child the best hit does not rule out.
    #[inline(always)]
    fn leaf_step<const ANY: bool, const COUNT: bool>(
        &mut self,
        tree: &KdTree,
        c: &mut Counters,
    ) -> bool {
        let leaf = &tree.leaves[(self.node & !LEAF_BIT) as usize];
        if tree.test_leaf::<ANY, COUNT>(leaf, &self.r, &mut self.best, &mut self.t_best, c)
            || self.t_best <= self.t1
        {
            return true;
        }
        loop {
            if self.sp == 0 {
                return true;
            }
            self.sp -= 1;
            (self.node, self.t0, self.t1) = self.stack[self.sp];
            if self.t0 <= self.t_best {
                return false;
            }
        }
    }

    #[inline(always)]
    fn best(&self) -> Option<Hit> {
        self.best
    }
}
