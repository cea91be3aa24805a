//! Host↔kernel structs of the intersection kernels (the tree's own structs live in
//! `raystream_accel::layout`). Each mirrors a WGSL struct in `kernels/intersect.wgsl`.

use bytemuck::{Pod, Zeroable};
use raystream_math::Ray;

/// `RayIn` in WGSL, 32 bytes: the RAYS.bin record.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuRay {
    /// World units (byte 0).
    pub origin: [f32; 3],
    /// Byte 12.
    pub t_min: f32,
    /// Not necessarily unit length (byte 16).
    pub dir: [f32; 3],
    /// Byte 28.
    pub t_max: f32,
}

impl From<&Ray> for GpuRay {
    fn from(r: &Ray) -> Self {
        GpuRay {
            origin: r.origin.to_array(),
            t_min: r.t_min,
            dir: r.dir.to_array(),
            t_max: r.t_max,
        }
    }
}

/// `HitOut` in WGSL, 16 bytes: the HITS.bin record.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuHit {
    /// +inf on a miss (byte 0).
    pub t: f32,
    /// `NO_PRIM` on a miss (byte 4).
    pub prim: u32,
    /// Weight of v1 (byte 8).
    pub u: f32,
    /// Weight of v2 (byte 12).
    pub v: f32,
}

/// `Params` in WGSL (uniform), 48 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Params {
    /// Rays in the queue (byte 0).
    pub ray_count: u32,
    /// Node reference of the root (byte 4).
    pub root: u32,
    /// Bound on leaf steps per ray: guards against a broken tree (byte 8).
    pub max_steps: u32,
    /// Triangle references in the tree; 0 = empty scene (byte 12).
    pub tri_count: u32,
    /// Scene box minimum, w unused (byte 16).
    pub scene_min: [f32; 4],
    /// Scene box maximum, w unused (byte 32).
    pub scene_max: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<GpuRay>() == 32);
const _: () = assert!(std::mem::size_of::<GpuHit>() == 16);
const _: () = assert!(std::mem::size_of::<Params>() == 48);
