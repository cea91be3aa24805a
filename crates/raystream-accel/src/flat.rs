//! Flattening a built tree into [`KdTree`]'s arrays and threading the leaves with ropes
//! (Popov, Günther, Seidel & Slusallek 2007, "Stackless KD-Tree Traversal for High Performance
//! GPU Ray Tracing"): each leaf face points to the deepest node that covers the whole face on
//! the other side, or `NO_ROPE` where that face lies on the scene boundary.

use raystream_math::{Aabb, Vec3};

use crate::build::{COST_INTERSECT, COST_TRAVERSAL, KdBuildNode};
use crate::layout::{Face, KdInner, KdLeaf, KdTri, NO_ROPE, is_leaf, leaf_ref};

#[derive(Default)]
pub(crate) struct Flat {
    pub inners: Vec<KdInner>,
    pub leaves: Vec<KdLeaf>,
    pub tris: Vec<KdTri>,
    pub max_depth: usize,
    pub sah_cost: f64,
}

pub(crate) fn flatten(root: &KdBuildNode, bounds: Aabb, corners: &[[Vec3; 3]]) -> (Flat, u32) {
    let mut flat = Flat::default();
    let inv_area = 1.0 / bounds.area().max(f32::MIN_POSITIVE) as f64;
    let root_ref = flat.emit(root, bounds, corners, 0, inv_area);
    flat.thread_ropes(root_ref, [NO_ROPE; 6]);
    (flat, root_ref)
}

impl Flat {
    fn emit(
        &mut self,
        node: &KdBuildNode,
        b: Aabb,
        corners: &[[Vec3; 3]],
        depth: usize,
        inv_area: f64,
    ) -> u32 {
        self.max_depth = self.max_depth.max(depth);
        match node {
            KdBuildNode::Leaf(prims) => {
                self.sah_cost +=
                    COST_INTERSECT as f64 * prims.len() as f64 * b.area() as f64 * inv_area;
                let first = self.tris.len() as u32;
                self.tris.extend(prims.iter().map(|&p| {
                    let [a, b, c] = corners[p as usize];
                    KdTri {
                        v0: [a.x, a.y, a.z, f32::from_bits(p)],
                        v1: [b.x, b.y, b.z, 0.0],
                        v2: [c.x, c.y, c.z, 0.0],
                    }
                }));
                self.leaves.push(KdLeaf {
                    min: b.min.to_array(),
                    first,
                    max: b.max.to_array(),
                    count: prims.len() as u32,
                    ropes: [NO_ROPE; 6],
                    pad: [0; 2],
                });
                leaf_ref(self.leaves.len() as u32 - 1)
            }
            KdBuildNode::Inner {
                axis,
                split,
                children,
            } => {
                self.sah_cost += COST_TRAVERSAL as f64 * b.area() as f64 * inv_area;
                let index = self.inners.len();
                self.inners.push(KdInner {
                    split: *split,
                    axis: *axis as u32,
                    left: 0,
                    right: 0,
                });
                let (mut lb, mut rb) = (b, b);
                lb.max[*axis] = *split;
                rb.min[*axis] = *split;
                let left = self.emit(&children[0], lb, corners, depth + 1, inv_area);
                let right = self.emit(&children[1], rb, corners, depth + 1, inv_area);
                self.inners[index].left = left;
                self.inners[index].right = right;
                index as u32
            }
        }
    }

    /// Passes ropes down: a child's rope on the face toward its sibling is the sibling; at the
    /// leaves each rope is pushed down as far as the leaf's face allows.
    fn thread_ropes(&mut self, node: u32, ropes: [u32; 6]) {
        if is_leaf(node) {
            let i = (node & !crate::layout::LEAF_BIT) as usize;
            let leaf = self.leaves[i];
            let b = Aabb::new(Vec3::from(leaf.min), Vec3::from(leaf.max));
            for f in Face::ALL {
                self.leaves[i].ropes[f as usize] = self.push_down(ropes[f as usize], f, &b);
            }
            return;
        }
        let n = self.inners[node as usize];
        let a = n.axis as usize;
        let mut lr = ropes;
        lr[Face::new(a, true) as usize] = n.right;
        let mut rr = ropes;
        rr[Face::new(a, false) as usize] = n.left;
        self.thread_ropes(n.left, lr);
        self.thread_ropes(n.right, rr);
    }

    /// Descends from `rope` while one child alone covers face `f` of the box `b`.
    fn push_down(&self, mut rope: u32, f: Face, b: &Aabb) -> u32 {
        while rope != NO_ROPE && !is_leaf(rope) {
            let n = &self.inners[rope as usize];
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
}
