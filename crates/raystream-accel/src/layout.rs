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

/// A triangle as a leaf references it, 48 bytes: corners in world units and the prim id
/// (index in the mesh's file order) in `v0[3]`, stored as its bit pattern.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct KdTri {
    pub v0: [f32; 4],
    pub v1: [f32; 4],
    pub v2: [f32; 4],
}

impl KdTri {
    pub fn prim(&self) -> u32 {
        self.v0[3].to_bits()
    }
}

const _: () = assert!(std::mem::size_of::<KdInner>() == 16);
const _: () = assert!(std::mem::size_of::<KdLeaf>() == 64);
const _: () = assert!(std::mem::size_of::<KdTri>() == 48);
