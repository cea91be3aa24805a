//! Flattening a built tree into [`KdTree`]'s arrays and threading the leaves with ropes
//! (Popov, Günther, Seidel & Slusallek 2007, "Stackless KD-Tree Traversal for High Performance
//! GPU Ray Tracing"): each leaf face points to the deepest node that covers the whole face on
//! the other side, or `NO_ROPE` where that face lies on the scene boundary.

use bytemuck::Zeroable;
use raystream_math::{Aabb, Vec3};

use crate::build::{COST_INTERSECT, COST_TRAVERSAL, KdBuildNode, Sizes};
use crate::layout::{Face, KdInner, KdLeaf, KdTri, NO_ROPE, is_leaf, leaf_ref};

#[derive(Default)]
pub(crate) struct Flat {
    pub inners: Vec<KdInner>,
    pub leaves: Vec<KdLeaf>,
    pub tris: Vec<KdTri>,
    pub max_depth: usize,
    pub sah_cost: f64,
}

/// Writes the tree depth first (a node, then its left subtree, then its right one) into the
/// flat arrays and threads the ropes. The arrays are allocated at their final sizes and each
/// subtree fills its own slices of them, large subtrees in parallel; the bytes are those of
/// a serial depth-first walk.
pub(crate) fn flatten(root: &KdBuildNode, bounds: Aabb, corners: &[[Vec3; 3]]) -> (Flat, u32) {
    let sizes = root.sizes();
    let mut inners = vec![KdInner::zeroed(); sizes.inners];
    let mut leaves = vec![KdLeaf::zeroed(); sizes.leaves];
    let mut tris = vec![KdTri::zeroed(); sizes.tris];
    let inv_area = 1.0 / bounds.area().max(f32::MIN_POSITIVE) as f64;
    let out = Slices {
        inners: &mut inners,
        leaves: &mut leaves,
        tris: &mut tris,
        base: Sizes::default(),
    };
    let (root_ref, sah_cost, max_depth) = emit(root, bounds, corners, 0, inv_area, out);
    thread_ropes(&inners, root, root_ref, [NO_ROPE; 6], &mut leaves);
    let flat = Flat {
        inners,
        leaves,
        tris,
        max_depth,
        sah_cost,
    };
    (flat, root_ref)
}

/// The parts of the flat arrays that one subtree fills, and where they start in the arrays.
struct Slices<'a> {
    inners: &'a mut [KdInner],
    leaves: &'a mut [KdLeaf],
    tris: &'a mut [KdTri],
    base: Sizes,
}

impl<'a> Slices<'a> {
    /// Splits off the first `n` entries of each array (a subtree of sizes `n`) from the rest.
    fn split(self, n: Sizes) -> (Slices<'a>, Slices<'a>) {
        let (i0, i1) = self.inners.split_at_mut(n.inners);
        let (l0, l1) = self.leaves.split_at_mut(n.leaves);
        let (t0, t1) = self.tris.split_at_mut(n.tris);
        (
            Slices {
                inners: i0,
                leaves: l0,
                tris: t0,
                base: self.base,
            },
            Slices {
                inners: i1,
                leaves: l1,
                tris: t1,
                base: self.base + n,
            },
        )
    }
}

/// Writes `node`'s subtree into `out`; returns its node reference, its share of the SAH cost
/// and its deepest leaf's depth.
fn emit(
    node: &KdBuildNode,
    b: Aabb,
    corners: &[[Vec3; 3]],
    depth: usize,
    inv_area: f64,
    out: Slices,
) -> (u32, f64, usize) {
    match node {
        KdBuildNode::Leaf(prims) => {
            for (t, &p) in out.tris.iter_mut().zip(prims) {
                let [a, b, c] = corners[p as usize];
                *t = KdTri::new([a.to_array(), b.to_array(), c.to_array()], p);
            }
            out.leaves[0] = KdLeaf {
                min: b.min.to_array(),
                first: out.base.tris as u32,
                max: b.max.to_array(),
                count: prims.len() as u32,
                ropes: [NO_ROPE; 6],
                pad: [0; 2],
            };
            let cost = COST_INTERSECT as f64 * prims.len() as f64 * b.area() as f64 * inv_area;
            (leaf_ref(out.base.leaves as u32), cost, depth)
        }
        KdBuildNode::Inner {
            axis,
            split,
            children,
            ..
        } => {
            let index = out.base.inners;
            let (this, rest) = out.split(Sizes::INNER);
            let (lo, hi) = rest.split(children[0].sizes());
            let (mut lb, mut rb) = (b, b);
            lb.max[*axis] = *split;
            rb.min[*axis] = *split;
            let left = || emit(&children[0], lb, corners, depth + 1, inv_area, lo);
            let right = || emit(&children[1], rb, corners, depth + 1, inv_area, hi);
            let ((l, lc, ld), (r, rc, rd)) = if children[0].is_big() || children[1].is_big() {
                rayon::join(left, right)
            } else {
                (left(), right())
            };
            this.inners[0] = KdInner {
                split: *split,
                axis: *axis as u32,
                left: l,
                right: r,
            };
            let cost = COST_TRAVERSAL as f64 * b.area() as f64 * inv_area + lc + rc;
            (index as u32, cost, ld.max(rd))
        }
    }
}

/// Passes ropes down the subtree of `node` (its reference `node_ref`, its leaves `leaves`): a
/// child's rope on the face toward its sibling is the sibling; at the leaves each rope is
/// pushed down as far as the leaf's face allows. Large subtrees in parallel.
fn thread_ropes(
    inners: &[KdInner],
    node: &KdBuildNode,
    node_ref: u32,
    ropes: [u32; 6],
    leaves: &mut [KdLeaf],
) {
    let KdBuildNode::Inner { children, .. } = node else {
        let leaf = &mut leaves[0];
        let b = Aabb::new(Vec3::from(leaf.min), Vec3::from(leaf.max));
        for f in Face::ALL {
            leaf.ropes[f as usize] = push_down(inners, ropes[f as usize], f, &b);
        }
        return;
    };
    let n = inners[node_ref as usize];
    let a = n.axis as usize;
    let mut lr = ropes;
    lr[Face::new(a, true) as usize] = n.right;
    let mut rr = ropes;
    rr[Face::new(a, false) as usize] = n.left;
    let (ll, rl) = leaves.split_at_mut(children[0].sizes().leaves);
    let mut left = move || thread_ropes(inners, &children[0], n.left, lr, ll);
    let mut right = move || thread_ropes(inners, &children[1], n.right, rr, rl);
    if children[0].is_big() || children[1].is_big() {
        rayon::join(left, right);
    } else {
        left();
        right();
    }
}

/// Descends from `rope` while one child alone covers face `f` of the box `b`.
fn push_down(inners: &[KdInner], mut rope: u32, f: Face, b: &Aabb) -> u32 {
    while rope != NO_ROPE && !is_leaf(rope) {
        let n = &inners[rope as usize];
        let a = n.axis as usize;
        rope = if a == f.axis() {
            // The neighbour lies beyond the face: its near child is the adjacent one.
            if f.is_positive() { n.left } else { n.right }
        } else if n.split <= b.min[a] {
            n.right
        } else if n.split >= b.max[a] {
            n.left
        } else {
            break;
        };
    }
    rope
}
