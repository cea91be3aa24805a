//! Entry nodes: where a rope walk starts its first descent.
//!
//! A rope walk first descends from the root to the leaf that holds the ray's point at its entry
//! parameter `t0` (where it enters the scene box, or its origin inside it). That descent is
//! most of a secondary ray's traversal steps (on turbine_blade 20 of a shadow ray's 22 inner
//! nodes) and a third of a camera ray's. The entry grid divides the scene box into cubic cells
//! and keeps, for each, the deepest node whose box holds the whole cell grown by two margins
//! on every side: a walk starts at the node of its entry point's cell. (Reshetov, Soupikov &
//! Hurley 2005 start a packet of rays at an entry node they share; the grid finds one per ray
//! with one lookup.)
//!
//! **The same leaf as from the root.** Every split plane above a cell's node lies beyond the
//! grown cell, so at least a margin from any point that the lookup maps to the cell (it
//! places points to within a margin). The lookup is used only where its bound on the rounding
//! of the entry point, of the cell index and of the descent's comparison `(split − o)·inv ≤
//! t0` ([`ERROR_SCALE`] times the magnitudes involved) is below the margin; then every plane
//! above the cell's node is far enough from the entry point that the descent from the root
//! decides it as geometry does, and takes the same children down to the cell's node. Below it
//! the steps are the same steps. So the walk reaches the same leaf and finds the same hits,
//! bit for bit; only the steps above the cell's node are skipped. A ray whose bound is not
//! below the margin (an origin very far from a small scene) starts at the root.
//!
//! Written by hand: a lookup table over this crate's own node layout.

use raystream_math::Aabb;

use crate::layout::{KdInner, is_leaf};

/// Cells along the scene box's longest side by default: on turbine_blade 128 cut a shadow
/// ray's inner steps from 21.7 to 11.8 (32: 17.7, 64: 14.4), in a 1.6 MB table.
pub const DEFAULT_RES: u32 = 128;
/// The most cells along the longest side (256³ cells are 64 MiB).
pub const MAX_RES: u32 = 256;
/// The margin, as a share of the scene box's longest side: 2⁻¹², an eighth of a cell at
/// [`MAX_RES`], so the grown cells are little larger than the cells.
const MARGIN_SHARE: f64 = 1.0 / 4096.0;
/// The lookup's bound on its rounding, relative to the magnitudes involved: 2⁻¹⁸, about 64
/// units in the last place of an f32, five times what the entry point, the cell index and the
/// descent's comparison can lose between them (with a GPU division's 2.5 ulp). With the
/// margin above, a walk starts in the grid when its origin and entry point lie within about
/// 64 times the scene's size of the world origin.
pub const ERROR_SCALE: f32 = 1.0 / 262_144.0;
/// Margins below this (a scene of subnormal size, where a GPU may flush to zero) get no grid.
const MIN_MARGIN: f64 = 1e-30;

/// The cells of the scene box and the node each starts at. Without cells (`res` all 0) every
/// walk starts at the root.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EntryGrid {
    /// Cells along x, y and z (1 along an axis where the scene box is flat).
    pub res: [u32; 3],
    /// Cells per world unit along each axis (0 where flat).
    pub scale: [f32; 3],
    /// How far outside its cell a point may lie and still start at the cell's node, in world
    /// units; walks start at the root unless their rounding bound is below it.
    pub margin: f32,
    /// The largest coordinate magnitude of the scene box (a term of the rounding bound).
    pub reach: f32,
    /// Node reference of each cell, x fastest, then y, then z.
    pub cells: Vec<u32>,
    /// The cells' mean node depth: the descent steps a walk starting there skips.
    pub mean_depth: f64,
}

impl EntryGrid {
    /// The grid of a tree over `bounds` (root `root`, inner nodes `inners`) with `res` cubic
    /// cells along its longest side (at most [`MAX_RES`]); none for `res` 0, a root leaf, or an
    /// empty or degenerate box.
    pub fn build(bounds: &Aabb, root: u32, inners: &[KdInner], res: u32) -> EntryGrid {
        let min = bounds.min.as_dvec3().to_array();
        let max = bounds.max.as_dvec3().to_array();
        let ext: [f64; 3] = std::array::from_fn(|a| max[a] - min[a]);
        let longest = ext.iter().cloned().fold(0.0, f64::max);
        let res = res.min(MAX_RES);
        let margin = (longest * MARGIN_SHARE) as f32;
        if res == 0 || is_leaf(root) || !longest.is_finite() || !(margin as f64 >= MIN_MARGIN) {
            return EntryGrid::default();
        }
        let side = longest / res as f64;
        let res: [u32; 3] = std::array::from_fn(|a| ((ext[a] / side).ceil() as u32).clamp(1, res));
        let reach = min.iter().chain(&max).map(|x| x.abs()).fold(0.0, f64::max);
        let mut grid = EntryGrid {
            res,
            scale: std::array::from_fn(|a| {
                if ext[a] > 0.0 {
                    (res[a] as f64 / ext[a]) as f32
                } else {
                    0.0
                }
            }),
            margin,
            reach: reach as f32,
            cells: Vec::new(),
            mean_depth: 0.0,
        };
        let mut fill = Fill {
            inners,
            res: res.map(|r| r as usize),
            spans: std::array::from_fn(|a| (0..res[a]).map(|i| grid.grown(bounds, a, i)).collect()),
            cells: vec![root; res.iter().map(|&r| r as usize).product()],
            depth_sum: 0.0,
        };
        fill.node(root, 0, res.map(|r| 0..r as usize));
        grid.mean_depth = fill.depth_sum / fill.cells.len() as f64;
        grid.cells = fill.cells;
        grid
    }

    /// Cell `i` along axis `a` of the grid over `bounds`, grown by two margins on each side:
    /// the span along that axis that the cell's node must hold.
    pub fn grown(&self, bounds: &Aabb, a: usize, i: u32) -> (f64, f64) {
        let (min, max) = (bounds.min[a] as f64, bounds.max[a] as f64);
        let cell = (max - min) / self.res[a] as f64;
        let m = 2.0 * self.margin as f64;
        (min + i as f64 * cell - m, min + (i + 1) as f64 * cell + m)
    }

    /// The node where a walk whose entry point is `o + t0·d` starts: its cell's, or `root`
    /// without a grid or where the lookup's rounding could matter.
    #[inline(always)]
    pub fn start(&self, root: u32, scene_min: [f32; 3], o: [f32; 3], d: [f32; 3], t0: f32) -> u32 {
        if self.cells.is_empty() {
            return root;
        }
        let big = |v: [f32; 3]| v[0].abs().max(v[1].abs()).max(v[2].abs());
        let err = ERROR_SCALE * (big(o) + t0.abs() * big(d) + self.reach);
        if !(err < self.margin) {
            return root;
        }
        let mut index = 0;
        for a in (0..3).rev() {
            let p = o[a] + t0 * d[a];
            // Clamped, then truncated: the floor of the clamped value, which is not negative
            // (`floor` is a call into libm on x86-64's baseline, which has no rounding
            // instruction before SSE4.1). Through u32, below `res` there: x86-64 has no
            // conversion from f32 to an unsigned 64-bit integer before AVX-512.
            let i = ((p - scene_min[a]) * self.scale[a]).clamp(0.0, (self.res[a] - 1) as f32) as u32
                as usize;
            index = index * self.res[a] as usize + i;
        }
        self.cells[index]
    }

    /// Cell `k` of [`Self::cells`] as its (x, y, z) indices.
    pub fn cell(&self, k: usize) -> [u32; 3] {
        let [rx, ry, _] = self.res.map(|r| r as usize);
        [k % rx, (k / rx) % ry, k / (rx * ry)].map(|i| i as u32)
    }

    /// The table's size in bytes.
    pub fn bytes(&self) -> usize {
        self.cells.len() * std::mem::size_of::<u32>()
    }
}

/// The grid being filled: each cell's grown span along each axis ([`EntryGrid::grown`]), the
/// cells.
struct Fill<'a> {
    inners: &'a [KdInner],
    res: [usize; 3],
    spans: [Vec<(f64, f64)>; 3],
    cells: Vec<u32>,
    depth_sum: f64,
}

impl Fill<'_> {
    /// Gives the block of cells `block` (index ranges along x, y, z), all held by `node` at
    /// `depth`, the deepest node that holds each: below an inner node, the cells wholly below
    /// its plane go to its left child, those wholly above to its right, and those it cuts
    /// stay with it. The same answer as [`covering_node`] cell by cell, in one pass.
    fn node(&mut self, node: u32, depth: usize, block: [std::ops::Range<usize>; 3]) {
        if block.iter().any(|r| r.is_empty()) {
            return;
        }
        if is_leaf(node) {
            self.give(node, depth, block);
            return;
        }
        let n = self.inners[node as usize];
        let a = n.axis as usize;
        let split = n.split as f64;
        let r = block[a].clone();
        // Cells are in order along the axis: those below the plane, those it cuts, those above.
        let spans = &self.spans[a][r.clone()];
        let below = r.start + spans.iter().take_while(|&&(_, hi)| split >= hi).count();
        let above = below.max(
            r.end
                - spans
                    .iter()
                    .rev()
                    .take_while(|&&(lo, _)| split <= lo)
                    .count(),
        );
        let part = |range: std::ops::Range<usize>| {
            let mut b = block.clone();
            b[a] = range;
            b
        };
        self.node(n.left, depth + 1, part(r.start..below));
        self.give(node, depth, part(below..above));
        self.node(n.right, depth + 1, part(above..r.end));
    }

    fn give(&mut self, node: u32, depth: usize, block: [std::ops::Range<usize>; 3]) {
        let [rx, ry, _] = self.res;
        for k in block[2].clone() {
            for j in block[1].clone() {
                let row = (k * ry + j) * rx;
                for i in block[0].clone() {
                    self.cells[row + i] = node;
                    self.depth_sum += depth as f64;
                }
            }
        }
    }
}

/// The deepest node under `root` whose box holds the whole box `lo`–`hi`: down the child that
/// holds it while one does (the grid's definition, cell by cell; tests check the fill by it).
pub fn covering_node(root: u32, inners: &[KdInner], lo: &[f64; 3], hi: &[f64; 3]) -> u32 {
    let mut node = root;
    while !is_leaf(node) {
        let n = &inners[node as usize];
        let a = n.axis as usize;
        let split = n.split as f64;
        node = if split >= hi[a] {
            n.left
        } else if split <= lo[a] {
            n.right
        } else {
            break;
        };
    }
    node
}
