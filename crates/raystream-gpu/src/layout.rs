//! Host↔kernel structs (the tree's own structs live in `raystream_accel::layout`). Each mirrors
//! a WGSL struct of `kernels/kdtree.wgsl` or `kernels/render.wgsl`; a naga test checks them.

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
            // +inf as the largest finite f32: the same hits (every hit's t is finite), and
            // shader compilers may assume arithmetic is finite (WGSL lets them).
            t_max: if r.t_max == f32::INFINITY {
                f32::MAX
            } else {
                r.t_max
            },
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

impl GpuHit {
    /// The hit as the CPU traversal reports it; `None` for a miss.
    pub fn hit(&self) -> Option<raystream_accel::Hit> {
        (self.prim != crate::NO_PRIM).then_some(raystream_accel::Hit {
            t: self.t,
            prim: self.prim,
            u: self.u,
            v: self.v,
        })
    }
}

/// `Params` in WGSL (uniform), 80 bytes.
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
    /// Scene box minimum (byte 16).
    pub scene_min: [f32; 3],
    /// The entry grid's margin (`EntryGrid::margin`, byte 28).
    pub entry_margin: f32,
    /// Scene box maximum (byte 32).
    pub scene_max: [f32; 3],
    /// The entry grid's largest coordinate magnitude (`EntryGrid::reach`, byte 44).
    pub entry_reach: f32,
    /// The entry grid's cells per world unit along each axis, w unused (byte 48).
    pub entry_scale: [f32; 4],
    /// The entry grid's cells along each axis, all 0 without a grid; w unused (byte 64).
    pub entry_res: [u32; 4],
}

/// `RayWork` in render.wgsl, 48 bytes: a ray of a render queue, the pixel it adds to and the
/// product of the coefficients along its path.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RayWork {
    pub ray: GpuRay,
    /// Byte 32.
    pub weight: [f32; 3],
    /// Byte 44.
    pub pixel: u32,
}

/// `ShadowWork` in render.wgsl, 48 bytes: a shadow ray and what its light adds if unblocked.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ShadowWork {
    pub ray: GpuRay,
    /// Byte 32.
    pub radiance: [f32; 3],
    /// Byte 44.
    pub pixel: u32,
}

/// `Vertex` in render.wgsl, 32 bytes: position (w unused) and unit shading normal, with its
/// object's ray offset (`Scene::ray_offsets`) in the normal's w.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 4],
    /// Byte 16.
    pub normal: [f32; 4],
}

/// `ShadeTri` in render.wgsl, 16 bytes: a triangle's vertex indices and material, by prim id.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ShadeTri {
    pub v: [u32; 3],
    /// Byte 12.
    pub material: u32,
}

/// `Material` in render.wgsl, 64 bytes: raystream_scene::Material.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    pub ambient: [f32; 3],
    /// Byte 12.
    pub reflectivity: f32,
    /// Byte 16.
    pub diffuse: [f32; 3],
    /// Byte 28.
    pub transparency: f32,
    /// Byte 32.
    pub specular: [f32; 3],
    /// Byte 44.
    pub shininess: f32,
    /// Byte 48.
    pub ior: f32,
    /// 1 = Schlick's Fresnel term splits transmitted light (byte 52).
    pub fresnel: u32,
    /// Its colour texture in the texture table, [`NO_TEXTURE`] for none (byte 56).
    pub texture: u32,
    pub pad: u32,
}

/// `GpuMaterial::texture` of a material without one.
pub const NO_TEXTURE: u32 = u32::MAX;

/// `TriCorners` in render.wgsl, 40 bytes: a triangle's corners' texture coordinates and
/// colours (8-bit sRGB packed R in the low byte, as the texels), by prim id.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TriCorners {
    pub a: [f32; 2],
    /// Byte 8.
    pub b: [f32; 2],
    /// Byte 16.
    pub c: [f32; 2],
    /// Bytes 24, 28, 32.
    pub colour_a: u32,
    pub colour_b: u32,
    pub colour_c: u32,
    pub pad: u32,
}

/// Where the texture table (`textures` in render.wgsl, one array of u32) keeps its parts: the
/// 256 words of [`raystream_io::SRGB_TO_LINEAR`] (f32 bits), then per texture
/// [`TEXTURE_INFO_WORDS`]: its first texel's word, width, height, clamp (0 or 1), and the f32
/// bits of its scale's u, v and offset's u, v; then the texels, RGBA8 packed with R in the low
/// byte.
pub const TEXTURE_INFO: u32 = 256;

/// Words per texture in the texture table's description part (see [`TEXTURE_INFO`]).
pub const TEXTURE_INFO_WORDS: u32 = 8;

/// `Light` in render.wgsl, 32 bytes (w unused).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    pub position: [f32; 4],
    /// Byte 16.
    pub color: [f32; 4],
}

/// `RenderParams` in render.wgsl (uniform), 128 bytes: camera, film, scene constants and the
/// current wave and depth.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RenderParams {
    pub eye: [f32; 3],
    /// tan of half the vertical field of view (byte 12).
    pub tan_y: f32,
    /// Byte 16.
    pub fwd: [f32; 3],
    /// Byte 28.
    pub width: u32,
    /// Byte 32.
    pub right: [f32; 3],
    /// Byte 44.
    pub height: u32,
    /// Byte 48.
    pub up: [f32; 3],
    /// Samples per pixel (byte 60).
    pub spp: u32,
    /// Byte 64.
    pub background: [f32; 3],
    /// Strata per side, ⌈√spp⌉ (byte 76).
    pub strata: u32,
    /// Byte 80.
    pub ambient_light: [f32; 3],
    /// `Camera::parallel`: half the view's height of a parallel projection, 0 for a
    /// perspective one (byte 92).
    pub parallel: f32,
    /// First sample (pixel · spp + s) of this wave (byte 96).
    pub sample_base: u32,
    /// Samples in this wave (byte 100).
    pub sample_count: u32,
    /// The last depth at which `shade_hits` spawns reflection/refraction rays is
    /// `max_depth - 1`: the current depth is the `counter::DEPTH` slot (byte 104).
    pub max_depth: u32,
    /// Byte 108.
    pub light_count: u32,
    /// Largest workgroup count per dispatch dimension (byte 112).
    pub max_groups: u32,
    /// Rows per band of the camera rays' pixel order: 1, row by row; more, bands of that
    /// many rows, each band column by column (byte 116; [`band_rows`]).
    pub band: u32,
    /// 1: triangles take their corners' colours ([`TriCorners`], `Scene::colours`), byte 120.
    pub coloured: u32,
    pub pad: u32,
}

/// The rows of a band of pixels whose column-by-column order puts the pixels of one subgroup
/// of `lanes` invocations, `spp` samples each, in a block about as tall as wide: the largest
/// power of two at most the square root of its pixels (32 lanes: 4 rows at 1 sample a pixel,
/// 8 × 4 pixels; 2 rows at 4 samples, 4 × 2), 1 (row by row) when they are fewer than 4.
pub fn band_rows(lanes: u32, spp: u32) -> u32 {
    let pixels = (lanes / spp.max(1)).max(1);
    1 << (pixels.ilog2() / 2)
}

/// Slots of the render kernels' counter buffer (`counters` in render.wgsl).
pub mod counter {
    /// Items in the queue being traced.
    pub const QUEUE: u32 = 0;
    /// Items appended to the next depth's queue.
    pub const NEXT: u32 = 1;
    /// Shadow rays appended this depth.
    pub const SHADOWS: u32 = 2;
    /// Rays of this depth that hit.
    pub const HITS: u32 = 3;
    /// The last finished depth's rays, hits and shadow rays (written by `advance`).
    pub const STAT_RAYS: u32 = 4;
    pub const STAT_HITS: u32 = 5;
    pub const STAT_SHADOWS: u32 = 6;
    /// The depth being traced: 0 at a wave's start, advanced by `advance`.
    pub const DEPTH: u32 = 7;
    /// Slots in all.
    pub const SLOTS: u32 = 8;
}

/// `MediumParams` in medium.wgsl (uniform), 144 bytes: a scene's volume for the render
/// kernels' volume stages — the world → index transform, the transfer function's sizes and
/// shading, the brick table's and light grids' sizes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct MediumParams {
    pub to_index0: [f32; 3],
    /// Step, mm (byte 12).
    pub step: f32,
    pub to_index1: [f32; 3],
    pub light_count: u32,
    pub to_index2: [f32; 3],
    pub skip_empty: u32,
    /// World position of voxel (0, 0, 0) (byte 48).
    pub origin: [f32; 3],
    pub opacity_count: u32,
    pub dims: [u32; 3],
    pub color_count: u32,
    pub bricks: [u32; 3],
    /// 1: volume samples lit through the light grids.
    pub shadows: u32,
    /// Ambient, diffuse, specular, specular power (byte 96).
    pub shading: [f32; 4],
    pub light_dims: [u32; 3],
    /// Values per light grid (byte 124).
    pub grid_points: u32,
    /// `Interpolation::kernel_code`: 0 trilinear, 1 the cubic B-spline, 2 its interpolating
    /// form, shaded by the voxels' spline (byte 128).
    pub interpolation: u32,
    /// 1: samples take a segmentation's colours (bindings 8 and 9; `SceneVolume::segments`),
    /// byte 132.
    pub segments: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// `DvrParams` in dvr.wgsl (uniform), 368 bytes: camera in LPS, the world → index transform,
/// the mode and its parameters, the shadow light, crop box and clip planes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct DvrParams {
    pub eye: [f32; 3],
    pub tan_y: f32,
    pub fwd: [f32; 3],
    pub width: u32,
    pub right: [f32; 3],
    pub height: u32,
    pub up: [f32; 3],
    /// 0 dvr, 1 mip, 2 minip, 3 average, 4 iso, 5 slice (byte 60).
    pub mode: u32,
    /// Rows of the world → index linear map (bytes 64, 80, 96).
    pub to_index0: [f32; 3],
    /// Step, mm (byte 76).
    pub step: f32,
    pub to_index1: [f32; 3],
    /// Iso threshold, HU (byte 92).
    pub iso: f32,
    pub to_index2: [f32; 3],
    pub window_width: f32,
    /// World position of voxel (0, 0, 0) (byte 112).
    pub origin: [f32; 3],
    pub window_level: f32,
    /// Byte 128.
    pub dims: [u32; 3],
    pub skip_empty: u32,
    /// Byte 144.
    pub bricks: [u32; 3],
    pub opacity_count: u32,
    /// Byte 160.
    pub background: [f32; 3],
    pub color_count: u32,
    /// Ambient, diffuse, specular, specular power (byte 176).
    pub shading: [f32; 4],
    /// Toward the key light (LPS, unit; byte 192), used when `shadows` is 1.
    pub light: [f32; 3],
    pub shadows: u32,
    /// Crop box, LPS mm (bytes 208, 224), used when `crop` is 1.
    pub crop_min: [f32; 3],
    pub crop: u32,
    pub crop_max: [f32; 3],
    pub plane_count: u32,
    /// Clip planes (n, c): keep n · p ≥ c (byte 240).
    pub planes: [[f32; 4]; 2],
    /// Light grid points per axis (byte 272), as `raystream_cpu::dvr::LightGrid`.
    pub light_dims: [u32; 3],
    /// Step of the light grid's shadow rays, mm (byte 284).
    pub shadow_step: f32,
    /// `Camera::parallel`: half the view's height (mm) of a parallel projection, 0 for a
    /// perspective one (byte 288).
    pub parallel: f32,
    /// `DvrOptions::hu_values`: 1 for the windowed modes' HU values unwindowed (byte 292).
    pub hu_values: u32,
    /// 1: premultiplied RGBA, no background: the pixels hold C and the second half of the
    /// pixel buffer the opacity 1 − T (byte 296).
    pub premultiplied: u32,
    /// 1: the pixels' rays come from the curved plane's rows (`cpr_rows`, [`GpuCprRow`]), not
    /// the camera (byte 300).
    pub curved: u32,
    /// A point of a slice's plane, LPS mm (byte 304); the plane faces `fwd`.
    pub slice_at: [f32; 3],
    /// A curved plane's slab: half its thickness, mm, 0 for the thin plane (byte 316).
    pub slab_half: f32,
    /// cinematic: paths per pixel (byte 320).
    pub spp: u32,
    /// cinematic: scatterings a path may take (byte 324).
    pub bounces: u32,
    /// cinematic: the first of the paths this dispatch traces, and how many (bytes 328,
    /// 332): a frame's paths run in dispatches of at most
    /// `GpuVolumeRenderer::paths_per_dispatch`.
    pub sample_first: u32,
    pub sample_count: u32,
    /// cinematic: the Henyey–Greenstein anisotropy g (byte 336) and the lights' scale
    /// 2^exposure (byte 340).
    pub anisotropy: f32,
    pub light_scale: f32,
    /// `Interpolation::kernel_code`: 0 trilinear, 1 the cubic B-spline, 2 its interpolating
    /// form, shaded by the voxels' spline (byte 344).
    pub interpolation: u32,
    /// 1: dvr, iso and cinematic samples take a segmentation's colours (bindings 14 and 15;
    /// `raystream_cpu::segments`), byte 348.
    pub segments: u32,
    /// 1: mip, minip and average of a volume kept to segments (byte 352): the texture holds
    /// the kept volume and its weights, and a sample is projected only within the segments
    /// (`raystream_cpu::dvr::Marcher::sample_kept`).
    pub kept: u32,
    pub pad_kept: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// `CprRow` in dvr.wgsl, 48 bytes: one image row of a curved planar reformation
/// (`raystream_cpu::cpr::CprRow`, LPS).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuCprRow {
    /// The path's point at the row's arc length, mm (byte 0).
    pub centre: [f32; 3],
    /// The pixels' side, mm (byte 12).
    pub pixel_mm: f32,
    /// Unit direction from pixel to pixel along the row (byte 16).
    pub lateral: [f32; 3],
    pub pad0: u32,
    /// Unit direction of the row's rays (byte 32).
    pub normal: [f32; 3],
    pub pad1: u32,
}

const _: () = assert!(std::mem::size_of::<GpuRay>() == 32);
const _: () = assert!(std::mem::size_of::<GpuHit>() == 16);
const _: () = assert!(std::mem::size_of::<Params>() == 80);
const _: () = assert!(std::mem::size_of::<RayWork>() == 48);
const _: () = assert!(std::mem::size_of::<ShadowWork>() == 48);
const _: () = assert!(std::mem::size_of::<Vertex>() == 32);
const _: () = assert!(std::mem::size_of::<ShadeTri>() == 16);
const _: () = assert!(std::mem::size_of::<GpuMaterial>() == 64);
const _: () = assert!(std::mem::size_of::<TriCorners>() == 40);
const _: () = assert!(std::mem::size_of::<GpuLight>() == 32);
const _: () = assert!(std::mem::size_of::<RenderParams>() == 128);
const _: () = assert!(std::mem::size_of::<DvrParams>() == 368);
const _: () = assert!(std::mem::size_of::<GpuCprRow>() == 48);
const _: () = assert!(std::mem::size_of::<MediumParams>() == 144);

/// `DenoiseParams` in denoise.wgsl (uniform), 48 bytes: the frame's size, a pass's gap and the
/// filter's settings (`raystream_cpu::denoise::DenoiseOptions`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct DenoiseParams {
    pub width: u32,
    pub height: u32,
    pub gap: u32,
    pub sigma_luminance: f32,
    pub sigma_depth: f32,
    pub sigma_normal: f32,
    pub sigma_albedo: f32,
    pub tolerance: f32,
    pub demodulate: f32,
    /// 1: the last pass puts the light over `background` (for a frame packed to sRGB on the
    /// GPU); 0: it stays premultiplied, the opacity beside it.
    pub over: u32,
    pub _pad1: u32,
    pub _pad2: u32,
    pub background: [f32; 3],
    pub _pad3: f32,
}
