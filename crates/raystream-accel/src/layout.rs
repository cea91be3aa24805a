//! The flat kd-tree: the bytes the CPU traverses here are the bytes the GPU kernels read.
//!
//! A node reference is a `u32`: bit 31 clear → index into `inners`, bit 31 set → index into
//! `leaves` (low 31 bits). `NO_ROPE` (`u32::MAX`) means "the ray leaves the scene".
//! Worked example: `0x0000_0007` is inner node 7; `0x8000_0002` is leaf 2.

use bytemuck::{Pod, Zeroable};

/// Set in a node reference that names a leaf.
pub const LEAF_BIT: u32 = 0x8000_0000;
/// Rope target where the ray leaves the scene box.
pub const NO_ROPE: u32 = u32::MAX;
/// Upper bound on the tree depth; the stack traversal sizes its stack with it.
pub const MAX_DEPTH: usize = 64;

/// The faces of a box, indexing `KdLeaf::ropes`: `2·axis` is the −axis face, `2·axis+1` the +axis face.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Face {
    NegX = 0,
    PosX = 1,
    NegY = 2,
    PosY = 3,
    NegZ = 4,
    PosZ = 5,
}

impl Face {
    pub const ALL: [Face; 6] = [
        Face::NegX,
        Face::PosX,
        Face::NegY,
        Face::PosY,
        Face::NegZ,
        Face::PosZ,
    ];
    pub fn axis(self) -> usize {
        self as usize / 2
    }
    pub fn is_positive(self) -> bool {
        self as usize % 2 == 1
    }
    pub fn new(axis: usize, positive: bool) -> Face {
        Face::ALL[2 * axis + positive as usize]
    }
}

pub fn is_leaf(node: u32) -> bool {
    node & LEAF_BIT != 0
}

pub fn leaf_ref(index: u32) -> u32 {
    index | LEAF_BIT
}

/// Inner node, 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct KdInner {
    /// Split plane position along `axis`, world units (byte 0).
    pub split: f32,
    /// 0 = x, 1 = y, 2 = z (byte 4).
    pub axis: u32,
    /// Node reference of the child below the plane (byte 8).
    pub left: u32,
    /// Node reference of the child above the plane (byte 12).
    pub right: u32,
}

/// Leaf, 64 bytes: its box (the ray's exit face is found from it), its triangle range in
/// `KdTree::tris`, and one rope per face.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct KdLeaf {
    /// Box minimum, world units (byte 0).
    pub min: [f32; 3],
    /// First entry of this leaf in `tris` (byte 12).
    pub first: u32,
    /// Box maximum, world units (byte 16).
    pub max: [f32; 3],
    /// Number of entries in `tris` (byte 28).
    pub count: u32,
    /// Node reference across each face, indexed by [`Face`], or `NO_ROPE` (byte 32).
    pub ropes: [u32; 6],
    /// Padding to 64 bytes (byte 56).
    pub pad: [u32; 2],
}

/// A triangle as a leaf references it, 48 bytes, by axis: `axes[k]` holds its three corners'
/// coordinates along axis k (corners 0, 1, 2, in world units), and `axes[0][3]` the prim id
/// (index in the mesh's file order) as its bit pattern. By axis, so that the watertight test,
/// which reads the corners along the ray's own order of the axes, loads each row with the
/// ray's axis as its index instead of picking components out of three corners (GPU kernels
/// pay for such picks with selects; BENCHMARKS.md, 2026-12-04, seventeenth session).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct KdTri {
    pub axes: [[f32; 4]; 3],
}

impl KdTri {
    /// The entry of triangle `prim` with these corners.
    pub fn new(corners: [[f32; 3]; 3], prim: u32) -> KdTri {
        let [a, b, c] = corners;
        KdTri {
            axes: [
                [a[0], b[0], c[0], f32::from_bits(prim)],
                [a[1], b[1], c[1], 0.0],
                [a[2], b[2], c[2], 0.0],
            ],
        }
    }

    pub fn prim(&self) -> u32 {
        self.axes[0][3].to_bits()
    }

    /// Corner `i` (0, 1 or 2).
    pub fn corner(&self, i: usize) -> [f32; 3] {
        [self.axes[0][i], self.axes[1][i], self.axes[2][i]]
    }
}

const _: () = assert!(std::mem::size_of::<KdInner>() == 16);
const _: () = assert!(std::mem::size_of::<KdLeaf>() == 64);
const _: () = assert!(std::mem::size_of::<KdTri>() == 48);
