//! `validate()`: the invariants of a built, flattened, roped tree, checked from scratch.

use raystream_math::{Aabb, Vec3};

use crate::clip::{clipped_bounds, overlaps_interior};
use crate::entry::MAX_RES;
use crate::layout::{Face, LEAF_BIT, MAX_DEPTH, NO_ROPE, is_leaf};
use crate::{KdTree, is_degenerate};

impl KdTree {
    /// Checks the tree against the triangles it was built from:
    /// - the structure is a tree (every node reached once), depth ≤ `MAX_DEPTH`, splits lie
    ///   strictly inside their node, leaf boxes equal the boxes the splits define;
    /// - the arrays are laid out depth first, left subtrees before right ones;
    /// - every leaf entry is a real triangle (exact corners, prim id) that meets the leaf's box;
    /// - every non-degenerate triangle meeting the interior of a leaf's box is listed in it;
    /// - every rope leads to the deepest node whose box covers the leaf's face from the other
    ///   side, and `NO_ROPE` only on faces on the scene boundary;
    /// - every entry-grid cell starts at the deepest node whose box holds the grown cell.
    pub fn validate(&self, corners: &[[Vec3; 3]]) -> Result<(), String> {
        self.check_links()?;
        let mut inner_boxes = vec![None; self.inners.len()];
        let mut leaf_seen = vec![false; self.leaves.len()];
        if self.tris.is_empty() && self.inners.is_empty() {
            return Ok(());
        }
        let mut todo = vec![(self.root, self.bounds, 0usize)];
        while let Some((node, b, depth)) = todo.pop() {
            if depth > MAX_DEPTH {
                return Err(format!("node {node:#x} at depth {depth} > {MAX_DEPTH}"));
            }
            if is_leaf(node) {
                let i = (node & !LEAF_BIT) as usize;
                let seen = leaf_seen
                    .get_mut(i)
                    .ok_or(format!("leaf {i} out of range"))?;
                if std::mem::replace(seen, true) {
                    return Err(format!("leaf {i} reached twice"));
                }
                if self.leaf_bounds(i) != b {
                    return Err(format!(
                        "leaf {i} stores box {:?}, its splits give {b:?}",
                        self.leaf_bounds(i)
                    ));
                }
                continue;
            }
            let n = *self
                .inners
                .get(node as usize)
                .ok_or(format!("inner {node} out of range"))?;
            if inner_boxes[node as usize].replace(b).is_some() {
                return Err(format!("inner node {node} reached twice"));
            }
            let a = n.axis as usize;
            if a > 2 || !(n.split > b.min[a] && n.split < b.max[a]) {
                return Err(format!(
                    "inner node {node}: split {} on axis {a} not inside {b:?}",
                    n.split
                ));
            }
            let (mut lb, mut rb) = (b, b);
            lb.max[a] = n.split;
            rb.min[a] = n.split;
            todo.push((n.left, lb, depth + 1));
            todo.push((n.right, rb, depth + 1));
        }
        if let Some(i) = leaf_seen.iter().position(|s| !s) {
            return Err(format!("leaf {i} is not reachable"));
        }
        if let Some(i) = inner_boxes.iter().position(|s| s.is_none()) {
            return Err(format!("inner node {i} is not reachable"));
        }
        // Depth-first layout in every array: a node, then its left subtree, then its right
        // one; the leaves' triangle ranges follow one another and cover `tris`.
        let (mut next_inner, mut next_leaf, mut next_tri) = (0u32, 0u32, 0u32);
        let mut stack = vec![self.root];
        while let Some(node) = stack.pop() {
            if is_leaf(node) {
                let i = node & !LEAF_BIT;
                let leaf = &self.leaves[i as usize];
                if i != next_leaf || leaf.first != next_tri {
                    return Err(format!(
                        "leaf {i} (triangles from {}) out of depth-first order: expected leaf \
                         {next_leaf} from {next_tri}",
                        leaf.first
                    ));
                }
                next_leaf += 1;
                next_tri += leaf.count;
            } else {
                if node != next_inner {
                    return Err(format!(
                        "inner node {node} out of depth-first order: expected {next_inner}"
                    ));
                }
                next_inner += 1;
                let n = &self.inners[node as usize];
                stack.push(n.right);
                stack.push(n.left);
            }
        }
        if next_tri as usize != self.tris.len() {
            return Err(format!(
                "the leaves list {next_tri} triangle entries, `tris` holds {}",
                self.tris.len()
            ));
        }
        let node_box = |r: u32| {
            if is_leaf(r) {
                self.leaf_bounds((r & !LEAF_BIT) as usize)
            } else {
                inner_boxes[r as usize].unwrap()
            }
        };

        for (i, leaf) in self.leaves.iter().enumerate() {
            let b = self.leaf_bounds(i);
            let range = leaf.first as usize..(leaf.first + leaf.count) as usize;
            let tris = self
                .tris
                .get(range)
                .ok_or(format!("leaf {i}: triangle range out of bounds"))?;
            for t in tris {
                let c = corners
                    .get(t.prim() as usize)
                    .ok_or(format!("leaf {i}: prim {} out of range", t.prim()))?;
                let stored = [0, 1, 2].map(|k| Vec3::from_array(t.corner(k)));
                if stored != *c {
                    return Err(format!(
                        "leaf {i}: corners of prim {} differ from the mesh",
                        t.prim()
                    ));
                }
                if clipped_bounds(c, &b).is_none() {
                    return Err(format!(
                        "leaf {i}: prim {} does not meet the leaf's box",
                        t.prim()
                    ));
                }
            }
            for f in Face::ALL {
                let a = f.axis();
                let face = if f.is_positive() { b.max[a] } else { b.min[a] };
                let rope = leaf.ropes[f as usize];
                if rope == NO_ROPE {
                    let scene = if f.is_positive() {
                        self.bounds.max[a]
                    } else {
                        self.bounds.min[a]
                    };
                    if face != scene {
                        return Err(format!(
                            "leaf {i}: no rope on {f:?}, which is inside the scene"
                        ));
                    }
                    continue;
                }
                let t = node_box(rope);
                let other = if f.is_positive() { t.min[a] } else { t.max[a] };
                if other != face {
                    return Err(format!(
                        "leaf {i}: rope {f:?} leads to {rope:#x}, not adjacent"
                    ));
                }
                for o in (0..3).filter(|&o| o != a) {
                    if t.min[o] > b.min[o] || t.max[o] < b.max[o] {
                        return Err(format!(
                            "leaf {i}: rope {f:?} target does not cover the face"
                        ));
                    }
                }
                if !is_leaf(rope) {
                    let n = &self.inners[rope as usize];
                    let na = n.axis as usize;
                    if na == a || !(n.split > b.min[na] && n.split < b.max[na]) {
                        return Err(format!("leaf {i}: rope {f:?} could be pushed further down"));
                    }
                }
            }
        }

        // The entry grid: each cell starts at the deepest node whose box holds the cell grown
        // by two margins (within the scene box).
        let g = &self.entry;
        let cells: usize = g.res.iter().map(|&r| r as usize).product();
        if g.cells.len() != cells || (cells == 0) != (g.res == [0; 3]) {
            return Err(format!(
                "entry grid of {:?} cells holds {} entries",
                g.res,
                g.cells.len()
            ));
        }
        for (c, &node) in g.cells.iter().enumerate() {
            let ijk = g.cell(c);
            let span: [(f64, f64); 3] = std::array::from_fn(|a| {
                let (lo, hi) = g.grown(&self.bounds, a, ijk[a]);
                (
                    lo.max(self.bounds.min[a] as f64),
                    hi.min(self.bounds.max[a] as f64),
                )
            });
            if !is_leaf(node) && node as usize >= self.inners.len() {
                return Err(format!("entry cell {ijk:?}: node {node} out of range"));
            }
            let b = node_box(node);
            if (0..3).any(|a| (b.min[a] as f64) > span[a].0 || (b.max[a] as f64) < span[a].1) {
                return Err(format!(
                    "entry cell {ijk:?}: node {node:#x}'s box {b:?} does not hold the cell"
                ));
            }
            if !is_leaf(node) {
                let n = &self.inners[node as usize];
                let (lo, hi) = span[n.axis as usize];
                if !(n.split as f64 > lo && (n.split as f64) < hi) {
                    return Err(format!(
                        "entry cell {ijk:?}: node {node} has a child that holds the cell"
                    ));
                }
            }
        }

        // Completeness: walk the tree once per triangle, pruning by overlap.
        let margin = 1e-6 * self.bounds.extent().max_element().max(f32::MIN_POSITIVE) as f64;
        for (prim, c) in corners.iter().enumerate() {
            if is_degenerate(c) {
                continue;
            }
            let mut todo = vec![self.root];
            while let Some(node) = todo.pop() {
                let b: Aabb = node_box(node);
                if !overlaps_interior(c, &b, margin) {
                    continue;
                }
                if is_leaf(node) {
                    let l = &self.leaves[(node & !LEAF_BIT) as usize];
                    let tris = &self.tris[l.first as usize..(l.first + l.count) as usize];
                    if !tris.iter().any(|t| t.prim() == prim as u32) {
                        return Err(format!(
                            "prim {prim} meets leaf {:#x} but is not in it",
                            node
                        ));
                    }
                } else {
                    let n = &self.inners[node as usize];
                    todo.push(n.left);
                    todo.push(n.right);
                }
            }
        }
        Ok(())
    }

    /// Checks, in one pass over the arrays and without the triangles, every index a walk
    /// follows: what kernels compiled without bounds checks rely on (`raystream-gpu` runs it
    /// before it uploads a tree). The root, children, ropes and entry cells name nodes that
    /// exist, and an inner node's inner children come after it (so every descent ends);
    /// axes are below 3; leaves' triangle ranges lie inside `tris`; the entry grid's cells
    /// match its size, and the numbers that place a point in a cell are finite. A tree that
    /// passes [`KdTree::validate`] passes this; a tree built here always does.
    pub fn check_links(&self) -> Result<(), String> {
        let (inners, leaves) = (self.inners.len(), self.leaves.len());
        if leaves >= LEAF_BIT as usize || self.tris.len() > u32::MAX as usize {
            return Err(format!(
                "{leaves} leaves and {} triangle entries",
                self.tris.len()
            ));
        }
        let node = |r: u32| {
            if is_leaf(r) {
                ((r & !LEAF_BIT) as usize) < leaves
            } else {
                (r as usize) < inners
            }
        };
        if !node(self.root) {
            return Err(format!("root {:#x} out of range", self.root));
        }
        for (i, n) in self.inners.iter().enumerate() {
            if n.axis > 2 {
                return Err(format!("inner node {i}: axis {}", n.axis));
            }
            for c in [n.left, n.right] {
                if !node(c) || (!is_leaf(c) && c as usize <= i) {
                    return Err(format!("inner node {i}: child {c:#x} out of range"));
                }
            }
        }
        for (i, l) in self.leaves.iter().enumerate() {
            if l.first as u64 + l.count as u64 > self.tris.len() as u64 {
                return Err(format!(
                    "leaf {i}: triangles {}..{} of {}",
                    l.first,
                    l.first as u64 + l.count as u64,
                    self.tris.len()
                ));
            }
            if let Some(r) = l.ropes.iter().find(|&&r| r != NO_ROPE && !node(r)) {
                return Err(format!("leaf {i}: rope {r:#x} out of range"));
            }
        }
        let g = &self.entry;
        if g.res[0] == 0 {
            return Ok(());
        }
        let cells = g.res.iter().map(|&r| r as usize).product::<usize>();
        let finite = [g.margin, g.reach]
            .into_iter()
            .chain(g.scale)
            .chain(self.bounds.min.to_array())
            .chain(self.bounds.max.to_array())
            .all(f32::is_finite);
        if g.res.iter().any(|&r| r == 0 || r > MAX_RES) || g.cells.len() != cells || !finite {
            return Err(format!(
                "entry grid of {:?} cells holds {} entries (scale {:?}, scene box {:?})",
                g.res,
                g.cells.len(),
                g.scale,
                self.bounds
            ));
        }
        match g.cells.iter().position(|&c| !node(c)) {
            Some(c) => Err(format!(
                "entry cell {:?}: node {:#x} out of range",
                g.cell(c),
                g.cells[c]
            )),
            None => Ok(()),
        }
    }
}
