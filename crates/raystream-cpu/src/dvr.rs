//! Direct volume rendering on the CPU, the reference for the GPU: rays marched front to back
//! through a CT volume in world space (LPS millimetres), sampled trilinearly or by the cubic
//! B-spline ([`Interpolation`]).
//!
//! - `dvr`: emission–absorption with a [`TransferFunction`]; opacity is per millimetre and
//!   corrected for the step (α_step = 1 − (1 − α)^Δs, the last step of a ray clipped to the
//!   volume), so pictures do not depend on `--step`;
//!   gradient (per mm, through the volume's direction: central differences of trilinear
//!   samples, or the cubic B-spline's own) Phong shading with a headlight, blended in by
//!   gradient magnitude so that homogeneous regions stay unshaded;
//!   early termination at 99 % opacity; empty-space skipping over 8³ bricks whose HU range the
//!   transfer function maps to zero opacity. Skipping keeps the sample lattice, so the picture is
//!   the same with and without it.
//! - `mip`, `minip`, `average`: the largest, smallest or mean HU along the ray, shown through a
//!   window/level.
//! - `iso`: the first crossing of an HU threshold, refined by bisection, shaded with the
//!   gradient normal (the mesh-free isosurface).
//!
//! Every ray starts at a per-pixel jittered offset along the step (a fixed hash: the same
//! picture every run) so that the sampling lattice does not show as wood-grain rings. (The
//! rings trilinear reconstruction draws on coarse grids, a voxel of depth apart, are another
//! matter: [`crate::sampling`].)
//!
//! # Example
//!
//! A CT (the abdomen/pelvis CT in the repository's `../shared/data`; a DICOM folder, NRRD or
//! MetaImage loads the same way) in Hounsfield units and LPS millimetres; its bones as a
//! marching-cubes surface for the kd-tree tracer; then the volume itself, directly rendered
//! with a bone preset and as a maximum intensity projection whose pixels hold HU:
//!
//! ```
//! use std::path::Path;
//!
//! use raystream_accel::{Builder, KdTree};
//! use raystream_cpu::dvr::{DvrMode, DvrOptions, render_volume, volume_camera};
//! use raystream_cpu::{RenderOptions, render};
//! use raystream_io::{VolumeSelect, load_volume};
//! use raystream_scene::Scene;
//! use raystream_volume::{TfPreset, extract_isosurface};
//!
//! let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
//! let path = data.join("volumes/nifti/abdomen_pelvis_ct_totalseg.nii.gz");
//! let ct = load_volume(&path, &VolumeSelect::default())?;
//! assert_eq!((ct.dims, ct.spacing), ([122, 101, 112], [3.0, 3.0, 3.0]));
//! let hu_max = ct.data.iter().copied().fold(f32::MIN, f32::max);
//!
//! // Bone at 300 HU: triangles in LPS mm with gradient normals, inside the volume's box.
//! let bones = extract_isosurface(&ct, 300.0);
//! assert_eq!(bones.normals.len(), bones.mesh.positions.len());
//! let far = ct.index_to_world([121.0, 100.0, 111.0].into());
//! let near = ct.index_to_world([0.0; 3].into());
//! for p in &bones.mesh.positions {
//!     for a in 0..3 {
//!         let (lo, hi) = (near[a].min(far[a]), near[a].max(far[a]));
//!         assert!(p[a] as f64 >= lo - 1e-3 && p[a] as f64 <= hi + 1e-3);
//!     }
//! }
//! let scene = Scene::for_bones(bones.mesh, &bones.normals, &path);
//! let tree = KdTree::build(&scene.mesh, Builder::Sah);
//! let opt = RenderOptions { width: 64, height: 64, spp: 1, ..Default::default() };
//! let surface = render(&scene, &tree, &opt, |_| {});
//!
//! // The volume itself: front-to-back emission and absorption through a transfer function.
//! let cam = volume_camera(&ct, 1.0);
//! let dvr = DvrOptions { width: 64, height: 64, ..Default::default() };
//! let (picture, stats) = render_volume(&ct, &TfPreset::CtBone.function(), &dvr, &cam);
//! // Bricks the preset leaves transparent (air, soft tissue) were skipped, not sampled.
//! assert!(stats.samples > 0 && stats.skipped > 0);
//! assert_eq!((surface.pixels.len(), picture.pixels.len()), (64 * 64, 64 * 64));
//!
//! // A MIP in HU (no window): every pixel the largest value its ray met, so none above the
//! // volume's largest, and some in cortical bone.
//! let mip = DvrOptions { mode: DvrMode::Mip, hu_values: true, ..dvr };
//! let (hu, _) = render_volume(&ct, &TfPreset::CtBone.function(), &mip, &cam);
//! let met = hu.pixels.iter().map(|p| p.x).filter(|x| x.is_finite());
//! let brightest = met.fold(f32::MIN, f32::max);
//! assert!(brightest <= hu_max && brightest > 1000.0, "{brightest} HU");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::sync::atomic::AtomicU64;

use rayon::prelude::*;
use raystream_accel::Isa;
use raystream_io::Volume;
use raystream_math::Vec3;
use raystream_scene::{Camera, Projection, VOLUME_VIEW, View};
use raystream_volume::TransferFunction;

use crate::Image;
use crate::cpr::CurvedPlane;
pub use crate::sampling::Interpolation;
use crate::sampling::{
    block_bound, bspline_coefficients, tricubic, tricubic_value, trilinear, trilinear_in,
};
use crate::segments::SegmentColours;

/// What a ray computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DvrMode {
    Dvr,
    Mip,
    MinIp,
    Average,
    Iso,
    /// Multiplanar reformation: the volume's HU on one plane, through `slice_at`, facing the
    /// camera (with a parallel camera, an axial, coronal, sagittal or oblique slice).
    Slice,
    /// Monte Carlo path tracing of the volume as a participating medium (cinematic rendering,
    /// [`crate::cinematic`]).
    Cinematic,
}

impl DvrMode {
    pub fn name(self) -> &'static str {
        match self {
            DvrMode::Dvr => "dvr",
            DvrMode::Mip => "mip",
            DvrMode::MinIp => "minip",
            DvrMode::Average => "average",
            DvrMode::Iso => "iso",
            DvrMode::Slice => "slice",
            DvrMode::Cinematic => "cinematic",
        }
    }

    /// Whether a pixel is one HU value seen through a window (mip, minip, average, slice)
    /// rather than shaded.
    pub fn is_windowed(self) -> bool {
        matches!(
            self,
            DvrMode::Mip | DvrMode::MinIp | DvrMode::Average | DvrMode::Slice
        )
    }

    /// Whether a pixel projects the samples along its ray to one HU value (mip, minip,
    /// average): the modes a volume kept to segments projects only the segments in
    /// ([`CpuVolume::kept`]).
    pub fn is_projection(self) -> bool {
        matches!(self, DvrMode::Mip | DvrMode::MinIp | DvrMode::Average)
    }

    /// The usual window (width, level) in HU of the windowed modes: bone for MIP, lung for
    /// MinIP, soft tissue for slices.
    pub fn default_window(self) -> (f32, f32) {
        match self {
            DvrMode::MinIp => (1500.0, -600.0),
            DvrMode::Average => (1000.0, -300.0),
            DvrMode::Slice => (400.0, 50.0),
            _ => (2000.0, 500.0),
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct DvrOptions {
    pub width: u32,
    pub height: u32,
    pub mode: DvrMode,
    /// Step in mm; `None`: half the smallest voxel spacing.
    pub step_mm: Option<f32>,
    /// (width, level) in HU for mip/minip/average; `None`: the mode's default.
    pub window: Option<(f32, f32)>,
    /// Threshold of `iso` mode, HU.
    pub iso_hu: f32,
    /// Skip bricks the transfer function makes transparent (dvr mode), and of a volume kept
    /// to segments, the bricks outside them (its projections: [`kept_brick_table`]).
    pub skip_empty: bool,
    pub background: Vec3,
    /// dvr mode: light from a key light above left of the camera ([`key_light`]) instead of a
    /// headlight, attenuated by shadow rays through the same transfer function ([`LightGrid`]).
    pub shadows: bool,
    /// Keep only the part of the volume inside this axis-aligned box, LPS mm (min, max).
    pub crop: Option<[Vec3; 2]>,
    /// Keep only points p with n · p ≥ c (n, c in LPS mm): up to two clip planes.
    pub clip_planes: [Option<(Vec3, f32)>; 2],
    /// mip, minip, average, slice: every channel of a pixel holds the HU value itself (no
    /// window: the film for an EXR), and a ray that takes no sample holds NaN.
    pub hu_values: bool,
    /// slice: a point of the plane, LPS mm; `None`: the volume's centre. Also the middle of
    /// `slab`.
    pub slice_at: Option<Vec3>,
    /// Keep only a slab this many mm thick about the plane through `slice_at` facing the
    /// camera (a slab MIP, say), in place of `clip_planes` ([`Self::planes_for`]).
    pub slab: Option<f32>,
    /// cinematic: paths per pixel.
    pub spp: u32,
    /// cinematic: scatterings a path may take.
    pub bounces: u32,
    /// dvr with shadows, and cinematic: where the key light stands, (azimuth, elevation) in
    /// degrees from the camera ([`key_light_from`]); `None`: above left ([`key_light`]).
    pub light: Option<[f32; 2]>,
    /// cinematic: the anisotropy g of the medium's Henyey–Greenstein phase function, the mean
    /// cosine of its scattering angle in (−1, 1): 0 isotropic, > 0 forward scattering (light
    /// carried on through tissue), < 0 back toward where it came from.
    pub anisotropy: f32,
    /// cinematic: the key light's and the sky's strength is 2^`exposure` times the default
    /// ([`crate::cinematic::KEY_IRRADIANCE`], [`crate::cinematic::SKY_RADIANCE`]); the
    /// background is not lit and keeps its colour.
    pub exposure: f32,
    /// cinematic: filter the frame's Monte Carlo noise ([`crate::denoise`], along [`crate::cinematic::guides`]), on
    /// either device.
    pub denoise: bool,
    /// How the volume is sampled between voxel centres: trilinear, or the cubic B-spline whose
    /// continuous gradient keeps coarse grids' surfaces free of wood-grain rings
    /// ([`crate::sampling`]).
    pub interpolation: Interpolation,
}

/// mip, minip and average of a volume kept to some of its segments ([`CpuVolume::kept`]): a
/// sample lies within the segments where the interpolated weights reach this, the half-way
/// surface between kept voxels (weight 1) and hidden ones (0), as a binary mask's isosurface
/// at ½ bounds it; samples short of it are not projected.
pub const KEPT_WEIGHT: f32 = 0.5;

impl Default for DvrOptions {
    fn default() -> Self {
        DvrOptions {
            width: 800,
            height: 600,
            mode: DvrMode::Dvr,
            step_mm: None,
            window: None,
            iso_hu: 300.0,
            skip_empty: true,
            background: Vec3::new(0.02, 0.025, 0.035),
            shadows: false,
            crop: None,
            clip_planes: [None; 2],
            hu_values: false,
            slice_at: None,
            slab: None,
            spp: 64,
            bounces: 4,
            light: None,
            denoise: false,
            anisotropy: 0.0,
            exposure: 0.0,
            interpolation: Interpolation::Linear,
        }
    }
}

impl DvrOptions {
    /// The factor 2^`exposure` the lights of a cinematic frame are scaled by.
    pub fn exposure_scale(&self) -> f32 {
        self.exposure.exp2()
    }

    /// The step in mm: `step_mm`, or half the smallest voxel spacing (never below 1/1000 of it).
    pub fn step_for(&self, vol: &Volume) -> f32 {
        step_for(self.step_mm, vol)
    }

    /// The window (width, level) in HU the windowed modes are shown in: `window`, or the
    /// mode's own ([`DvrMode::default_window`]).
    pub fn shown_window(&self) -> (f32, f32) {
        self.window.unwrap_or(self.mode.default_window())
    }

    /// The plane of a slice passes through this point (LPS mm): `slice_at`, or the centre of
    /// the volume's voxel-centre box.
    pub fn slice_point(&self, vol: &Volume) -> Vec3 {
        self.slice_at.unwrap_or_else(|| {
            let centre = vol.dims.map(|n| (n.max(1) - 1) as f64 / 2.0);
            vol.index_to_world(raystream_math::DVec3::from_array(centre))
                .as_vec3()
        })
    }

    /// The clip planes (n, c: keep n · p ≥ c, LPS) that rays seen by `cam` are cut to:
    /// `clip_planes`, or with `slab` the two faces of the slab about the plane through
    /// [`Self::slice_point`] facing the camera (then `clip_planes` must be empty).
    pub fn planes_for(&self, vol: &Volume, cam: &Camera) -> [Option<(Vec3, f32)>; 2] {
        let Some(thickness) = self.slab else {
            return self.clip_planes;
        };
        assert!(
            self.clip_planes.iter().all(Option::is_none),
            "a slab takes both clip planes"
        );
        let n = scene_to_lps(cam.fwd).normalize();
        let c = n.dot(self.slice_point(vol));
        [
            Some((n, c - 0.5 * thickness)),
            Some((-n, -(c + 0.5 * thickness))),
        ]
    }

    /// The direction toward the key light (LPS, unit) of a picture seen by `cam`: `light`'s,
    /// or above left of the camera.
    pub fn key_light(&self, cam: &Camera) -> Vec3 {
        match self.light {
            Some([az, el]) => key_light_from(cam, az, el),
            None => key_light(cam),
        }
    }

    /// The step of the light grid's shadow rays ([`shadow_step_for`]).
    pub fn shadow_step_for(&self, vol: &Volume) -> f32 {
        shadow_step_for(self.step_mm, vol)
    }
}

/// The smallest voxel spacing, mm.
pub fn min_spacing(vol: &Volume) -> f32 {
    vol.spacing.iter().cloned().fold(f64::INFINITY, f64::min) as f32
}

/// The most samples a ray takes across a volume's box (its diagonal): 2^20, as many as a
/// 512³ volume crossed at the smallest step `--step-mm` may ask (1/1000 of a voxel); the
/// default step takes about 1,800 there.
pub const MAX_SAMPLES_PER_RAY: f64 = 1_048_576.0;

/// The march's step in mm: `step_mm`, or half the smallest voxel spacing (never below 1/1000
/// of it), and never so small that a ray across the box's diagonal would take more than
/// [`MAX_SAMPLES_PER_RAY`] samples: a volume whose spacings differ by many orders (a corrupt
/// header's 1e-6 beside 2.5 mm) would otherwise march for hours, a lone ray for billions of
/// steps.
pub fn step_for(step_mm: Option<f32>, vol: &Volume) -> f32 {
    let s = min_spacing(vol);
    let budget = (vol.diagonal_mm() / MAX_SAMPLES_PER_RAY) as f32;
    step_mm.unwrap_or(0.5 * s).max(1e-3 * s).max(budget)
}

/// The step of the light grids' shadow rays: the march's step, but at least one voxel (the
/// smallest spacing). The grid points lie two or more voxels apart, so the light field they
/// sample is already smoother than the data, and opacity correction keeps the transmittance
/// independent of the step: on an H100 this halved the shadow samples of the 512³ benchmark.
pub fn shadow_step_for(step_mm: Option<f32>, vol: &Volume) -> f32 {
    step_for(step_mm, vol).max(min_spacing(vol))
}

/// What a render did.
#[derive(Clone, Copy, Debug, Default)]
pub struct DvrStats {
    /// Samples taken (transfer-function lookups).
    pub samples: u64,
    /// Samples not taken because their brick was transparent.
    pub skipped: u64,
    /// Samples taken by shadow rays (`--shadows`).
    pub shadow_samples: u64,
    pub step_mm: f32,
    /// cinematic with `denoise`: what the denoiser took.
    pub denoise: Option<crate::denoise::DenoiseTimes>,
}

/// Bricks of `BRICK`³ cells: a brick holds whether the transfer function may show any of its
/// samples (from the range of its corner voxels trilinearly; from the spline's Bézier control
/// points with the cubic B-splines: `cell_opacities`).
pub const BRICK: usize = 8;

/// The volume prepared for marching: index-space transforms in f32 and the brick table.
pub struct Marcher<'a> {
    vol: &'a Volume,
    /// The values the interpolation reads: the voxels, or the interpolating spline's
    /// coefficients ([`spline_grid`]).
    grid: std::borrow::Cow<'a, [f32]>,
    /// World (LPS mm) → continuous index: p_idx = m · (p − origin).
    to_index: [Vec3; 3],
    origin: Vec3,
    /// d(world)/d(index) per index axis, to turn index gradients into world ones.
    grad_to_world: [Vec3; 3],
    bricks: [usize; 3],
    /// Per brick: whether anything in it is visible (dvr mode) — empty-space skipping.
    visible: std::borrow::Cow<'a, [bool]>,
    interpolation: Interpolation,
    /// The instruction set [`Self::absorb`], [`Self::composite_ray`] and the frames' pixels
    /// run in ([`Self::in_isa`]).
    isa: Isa,
    /// A segmentation's colours, which the samples take in place of the transfer function's.
    segments: Option<&'a SegmentColours>,
    /// mip, minip and average kept to segments: the kept voxels' weights as the interpolation
    /// reads them ([`Self::kept`]).
    weights: Option<std::borrow::Cow<'a, [f32]>>,
}

/// Cells of `cell`³ voxel spacings over the grid of `dims` voxel centres: cells per axis.
pub(crate) fn cell_dims(dims: [usize; 3], cell: usize) -> [usize; 3] {
    dims.map(|n| n.saturating_sub(1).div_ceil(cell).max(1))
}

/// Per cell of `cell`³ (x fastest; [`cell_dims`]) of the grid `grid` (`dims`, the values
/// `interpolation` reads: [`spline_grid`]), the greatest opacity `tf` gives any of its
/// samples, interpolated as `interpolation`, or a bound just above it. Trilinear: over the
/// range of the voxels they read, the cell's own corners (exact: the samples take every value
/// in it). The cubic B-splines: over the convex hull of the spline's Bézier control points
/// over the cells, refined where that may be loose ([`block_bound`]).
pub(crate) fn cell_opacities(
    dims: [usize; 3],
    grid: &[f32],
    cell: usize,
    interpolation: Interpolation,
    tf: &TransferFunction,
) -> Vec<f32> {
    cell_worst(dims, grid, cell, interpolation, |lo, hi| {
        tf.max_opacity_in(lo, hi)
    })
}

/// Per cell as [`cell_opacities`], the greatest `worst` of a range of values that holds the
/// cell's samples.
fn cell_worst(
    dims: [usize; 3],
    grid: &[f32],
    cell: usize,
    interpolation: Interpolation,
    worst: impl Fn(f32, f32) -> f32 + Sync,
) -> Vec<f32> {
    let [nx, ny, _] = dims;
    let cells = cell_dims(dims, cell);
    (0..cells[0] * cells[1] * cells[2])
        .into_par_iter()
        .map(|b| {
            let (lo, hi) = cell_corners(dims, cell, b);
            match interpolation {
                Interpolation::Linear => {
                    let (mut low, mut high) = (f32::INFINITY, f32::NEG_INFINITY);
                    for k in lo[2]..=hi[2] {
                        for j in lo[1]..=hi[1] {
                            for i in lo[0]..=hi[0] {
                                let v = grid[i + nx * (j + ny * k)];
                                low = low.min(v);
                                high = high.max(v);
                            }
                        }
                    }
                    worst(low, high)
                }
                Interpolation::Cubic | Interpolation::CubicInterpolating => {
                    block_bound(dims, grid, lo, hi, &worst)
                }
            }
        })
        .collect()
}

/// The corner voxels of cell `b` of `cell`³ (x fastest; [`cell_dims`]) over a grid of `dims`:
/// `lo[a]..=hi[a]` along each axis.
pub(crate) fn cell_corners(dims: [usize; 3], cell: usize, b: usize) -> ([usize; 3], [usize; 3]) {
    let cells = cell_dims(dims, cell);
    let c = [
        b % cells[0],
        b / cells[0] % cells[1],
        b / (cells[0] * cells[1]),
    ];
    (
        c.map(|c| c * cell),
        [0, 1, 2].map(|a| ((c[a] + 1) * cell).min(dims[a] - 1)),
    )
}

/// The cell of `cell`³ (of `cells` per axis) holding index `p`, and the ray parameter where
/// the ray p + (s − t)·d_idx leaves it.
#[inline(always)]
pub(crate) fn cell_exit(
    p: Vec3,
    t: f32,
    d_idx: Vec3,
    cell: usize,
    cells: [usize; 3],
) -> (usize, f32) {
    // Through u32: x86-64's baseline has no unsigned 64-bit conversion, so `as usize` takes
    // two conversions and selects (perf put 8 % of a cinematic frame on this line). An index
    // past u32's range saturates, and is clamped to the last cell as before; a face's index
    // (at most the grid's size) goes to f32 through u32 too. The cells are spelled out rather
    // than `[0, 1, 2].map(…)`, whose closure the compiler may leave out of line (in the
    // baseline's code) inside an x86-64-v3 copy. Every axis's exit is computed and kept where
    // the ray moves along it, without branches.
    let cell_of = |a: usize| ((p[a].max(0.0) as u32 as usize) / cell).min(cells[a] - 1);
    let b = [cell_of(0), cell_of(1), cell_of(2)];
    let mut t_exit = f32::INFINITY;
    for a in 0..3 {
        let bound = (b[a] + (d_idx[a] > 0.0) as usize) * cell;
        let exit = t + (bound as u32 as f32 - p[a]) / d_idx[a];
        if d_idx[a] != 0.0 {
            t_exit = t_exit.min(exit);
        }
    }
    (b[0] + cells[0] * (b[1] + cells[1] * b[2]), t_exit)
}

/// The values `interpolation` reads of `vol`: its voxels, or for the interpolating cubic
/// B-spline their coefficients ([`bspline_coefficients`], computed here).
pub fn spline_grid(vol: &Volume, interpolation: Interpolation) -> std::borrow::Cow<'_, [f32]> {
    if interpolation.prefiltered() {
        std::borrow::Cow::Owned(bspline_coefficients(vol.dims, &vol.data))
    } else {
        std::borrow::Cow::Borrowed(&vol.data)
    }
}

/// The values each interpolation reads of a volume, kept: the voxels themselves, or the
/// interpolating spline's coefficients, computed by the first caller that needs them (what
/// the CPU's and the GPU's volume renderers share).
#[derive(Default)]
pub struct SplineGrids {
    coefficients: std::sync::OnceLock<Vec<f32>>,
}

impl SplineGrids {
    /// The values `interpolation` reads of `vol` (always the same volume for one
    /// `SplineGrids`).
    pub fn get<'v>(&'v self, vol: &'v Volume, interpolation: Interpolation) -> &'v [f32] {
        if interpolation.prefiltered() {
            self.coefficients
                .get_or_init(|| bspline_coefficients(vol.dims, &vol.data))
        } else {
            &vol.data
        }
    }

    /// Whether the coefficients have been computed.
    pub fn has_coefficients(&self) -> bool {
        self.coefficients.get().is_some()
    }
}

/// Per brick of `BRICK`³ cells (x fastest), whether `tf` may show anything in it, as
/// `interpolation` reads the grid `grid` of `dims` ([`spline_grid`]): what empty-space
/// skipping skips.
pub fn brick_table(
    dims: [usize; 3],
    grid: &[f32],
    tf: &TransferFunction,
    interpolation: Interpolation,
) -> Vec<bool> {
    cell_opacities(dims, grid, BRICK, interpolation, tf)
        .into_iter()
        .map(|opacity| opacity > 0.0)
        .collect()
}

/// Per brick of `BRICK`³ cells (x fastest), whether any sample of a volume kept to segments
/// may lie within them: the kept weights `weights` ([`Marcher::kept`]) reach [`KEPT_WEIGHT`]
/// somewhere in it, as `interpolation` reads them (each interpolation is a blend of the values
/// it reads with non-negative weights, so a brick whose values stay under it has no sample
/// that reaches it). What a kept projection skips. A thousandth below it: the GPU reads the
/// weights in half precision (an interpolating spline's coefficient just under ½ may round
/// up to it).
pub fn kept_brick_table(
    dims: [usize; 3],
    weights: &[f32],
    interpolation: Interpolation,
) -> Vec<bool> {
    cell_worst(dims, weights, BRICK, interpolation, |_, hi| {
        if hi >= KEPT_WEIGHT - 1e-3 { 1.0 } else { 0.0 }
    })
    .into_iter()
    .map(|w| w > 0.0)
    .collect()
}

impl<'a> Marcher<'a> {
    /// `vol` sampled trilinearly; with `tf`, its bricks that `tf` makes transparent known.
    pub fn new(vol: &'a Volume, tf: Option<&TransferFunction>) -> Marcher<'a> {
        Marcher::interpolated(vol, tf, Interpolation::Linear)
    }

    /// `vol` sampled as `interpolation`; with `tf`, its bricks that `tf` makes transparent
    /// known.
    pub fn interpolated(
        vol: &'a Volume,
        tf: Option<&TransferFunction>,
        interpolation: Interpolation,
    ) -> Marcher<'a> {
        let grid = spline_grid(vol, interpolation);
        match tf {
            Some(tf) => {
                let visible = brick_table(vol.dims, &grid, tf, interpolation);
                Marcher::with_bricks(vol, grid, std::borrow::Cow::Owned(visible), interpolation)
            }
            None => Marcher::with_grid(vol, grid, interpolation),
        }
    }

    /// `vol` sampled as `interpolation` from `grid` (its [`spline_grid`]), every brick taken
    /// as visible.
    pub fn with_grid(
        vol: &'a Volume,
        grid: std::borrow::Cow<'a, [f32]>,
        interpolation: Interpolation,
    ) -> Marcher<'a> {
        let bricks = cell_dims(vol.dims, BRICK);
        let visible = std::borrow::Cow::Owned(vec![true; bricks[0] * bricks[1] * bricks[2]]);
        Marcher::with_bricks(vol, grid, visible, interpolation)
    }

    /// `vol` sampled as `interpolation` from `grid` (its [`spline_grid`]), with the brick
    /// table `visible` ([`brick_table`] of the same, or all true).
    pub fn with_bricks(
        vol: &'a Volume,
        grid: std::borrow::Cow<'a, [f32]>,
        visible: std::borrow::Cow<'a, [bool]>,
        interpolation: Interpolation,
    ) -> Marcher<'a> {
        assert_eq!(grid.len(), vol.data.len(), "a grid of the volume's voxels");
        let m = vol.index_to_world_affine();
        let inv = m.inverse();
        let rows = |a: raystream_math::DMat3| {
            let t = a.transpose();
            [t.x_axis, t.y_axis, t.z_axis].map(|r| r.as_vec3())
        };
        let to_index = rows(inv.matrix3);
        // ∂f/∂world = (M⁻¹)ᵀ ∂f/∂index: the columns of (M⁻¹)ᵀ are the rows of M⁻¹.
        let grad_to_world = to_index;
        let bricks = cell_dims(vol.dims, BRICK);
        assert_eq!(
            visible.len(),
            bricks[0] * bricks[1] * bricks[2],
            "a brick table of the volume's bricks"
        );
        Marcher {
            vol,
            grid,
            to_index,
            origin: m.translation.as_vec3(),
            grad_to_world,
            bricks,
            visible,
            interpolation,
            isa: Isa::current(),
            segments: None,
            weights: None,
        }
    }

    /// The marcher whose shadow rays ([`Self::absorb`]) and mesh scenes' segments
    /// ([`Self::composite_ray`]) run in the instruction set `isa` (by default
    /// [`Isa::current`]; the baseline's where the processor lacks it): the same bits in every
    /// one.
    pub fn in_isa(mut self, isa: Isa) -> Marcher<'a> {
        self.isa = isa;
        self
    }

    /// The instruction set it runs in ([`Self::in_isa`]).
    pub(crate) fn isa(&self) -> Isa {
        self.isa
    }

    /// The marcher with its samples coloured by `segments` (on the volume's grid), where
    /// given.
    pub fn painted(mut self, segments: Option<&'a SegmentColours>) -> Marcher<'a> {
        if let Some(s) = segments {
            assert_eq!(
                s.dims, self.vol.dims,
                "segment colours on the volume's grid"
            );
        }
        self.segments = segments;
        self
    }

    /// The colour of the sample at index `p` whose transfer-function colour (or, for an
    /// isosurface, material) is `base`: the segments' colours blended there, where the
    /// marcher has them ([`SegmentColours::colour_at`]).
    pub fn albedo(&self, base: Vec3, p: Vec3) -> Vec3 {
        match self.segments {
            Some(s) => s.colour_at(p, base),
            None => base,
        }
    }

    /// How the volume is sampled.
    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// The volume sampled.
    pub fn volume(&self) -> &Volume {
        self.vol
    }

    /// The values the interpolation reads ([`spline_grid`]): the voxels, or the interpolating
    /// spline's coefficients.
    pub fn grid(&self) -> &[f32] {
        &self.grid
    }

    /// World (LPS mm) → continuous index as rows of the linear part, and the world origin:
    /// p_idx = (row_a · (p − origin))_a.
    pub fn world_to_index(&self) -> ([Vec3; 3], Vec3) {
        (self.to_index, self.origin)
    }

    /// Bricks per axis and, per brick (x fastest), whether it may be visible.
    pub fn brick_table(&self) -> ([usize; 3], &[bool]) {
        (self.bricks, &self.visible)
    }

    /// Continuous index → world (LPS mm).
    fn world_of(&self, p: Vec3) -> Vec3 {
        self.vol.index_to_world(p.as_dvec3()).as_vec3()
    }

    /// World (LPS mm) → continuous index.
    pub(crate) fn index_of(&self, p: Vec3) -> Vec3 {
        let q = p - self.origin;
        Vec3::new(
            self.to_index[0].dot(q),
            self.to_index[1].dot(q),
            self.to_index[2].dot(q),
        )
    }

    /// A world direction → index units per world unit along it.
    pub(crate) fn index_dir(&self, d: Vec3) -> Vec3 {
        Vec3::new(
            self.to_index[0].dot(d),
            self.to_index[1].dot(d),
            self.to_index[2].dot(d),
        )
    }

    /// The value at continuous index `p` (clamped to the grid), interpolated trilinearly or
    /// by the cubic B-spline (of the voxels, or of the coefficients that interpolate them).
    #[inline(always)]
    pub fn sample(&self, p: Vec3) -> f32 {
        let dims = self.vol.dims;
        match self.interpolation {
            Interpolation::Linear => trilinear_in(dims, &self.grid, p),
            Interpolation::Cubic | Interpolation::CubicInterpolating => {
                tricubic_value(dims, &self.grid, p)
            }
        }
    }

    /// The marcher of a volume kept to some segments, for mip, minip and average: `weights`,
    /// on the volume's grid as the interpolation reads it ([`spline_grid`] of a volume of 1 at
    /// each kept voxel and 0 at each hidden one, whose value in the volume is 0), where
    /// given ([`Self::sample_kept`]).
    pub fn kept(mut self, weights: Option<std::borrow::Cow<'a, [f32]>>) -> Marcher<'a> {
        if let Some(w) = &weights {
            assert_eq!(w.len(), self.grid.len(), "weights on the volume's grid");
        }
        self.weights = weights;
        self
    }

    /// The value at `p` of a volume kept to segments ([`Self::kept`]): the kept voxels' own
    /// blend, Σ wᵢ·mᵢ·vᵢ / Σ wᵢ·mᵢ (the volume's interpolation over the weights' with the same
    /// weights wᵢ), where the weights' interpolation Σ wᵢ·mᵢ is at least [`KEPT_WEIGHT`];
    /// `None` elsewhere (outside the segments), so that no hidden voxel's value and no fill
    /// value reaches a projection, not even blended at a segment's edge. Without weights,
    /// [`Self::sample`].
    #[inline(always)]
    pub fn sample_kept(&self, p: Vec3) -> Option<f32> {
        let Some(w) = &self.weights else {
            return Some(self.sample(p));
        };
        let dims = self.vol.dims;
        let (v, k) = match self.interpolation {
            // Both grids at once: one set of weights, the same lerps as `sample`'s.
            Interpolation::Linear => {
                let b = trilinear(dims, p, |i, j, k| {
                    let n = i + dims[0] * (j + dims[1] * k);
                    raystream_math::Vec2::new(self.grid[n], w[n])
                });
                (b.x, b.y)
            }
            Interpolation::Cubic | Interpolation::CubicInterpolating => {
                (self.sample(p), tricubic_value(dims, w, p))
            }
        };
        (k >= KEPT_WEIGHT).then(|| v / k)
    }

    /// The HU gradient per mm in world space at index `p`, what shading takes: central
    /// differences of trilinear samples one voxel apart, or the gradient of the cubic B-spline
    /// of the voxels, for either spline. The interpolating spline's own gradient carries the
    /// CT's noise that its prefilter amplifies (on the abdomen's skin under ct-muscle, a grain of
    /// 0.125 against trilinear's 0.040), so it is shaded by the approximating spline's, which
    /// turns smoothly: its values keep their peaks, and its normals are `cubic`'s at the same
    /// points.
    #[inline(always)]
    pub fn gradient(&self, p: Vec3) -> Vec3 {
        let g = match self.interpolation {
            Interpolation::Linear => {
                Vec3::new(
                    self.sample(p + Vec3::X) - self.sample(p - Vec3::X),
                    self.sample(p + Vec3::Y) - self.sample(p - Vec3::Y),
                    self.sample(p + Vec3::Z) - self.sample(p - Vec3::Z),
                ) * 0.5
            }
            Interpolation::Cubic | Interpolation::CubicInterpolating => {
                tricubic(self.vol.dims, &self.vol.data, p).1
            }
        };
        // world gradient = Σ_axis g_axis · ∂index_axis/∂world
        self.grad_to_world[0] * g.x + self.grad_to_world[1] * g.y + self.grad_to_world[2] * g.z
    }

    /// The ray's [t0, t1] (mm along unit `d`) inside the grid of voxel centres.
    #[inline(always)]
    pub(crate) fn clip(&self, o_idx: Vec3, d_idx: Vec3) -> Option<(f32, f32)> {
        let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
        for a in 0..3 {
            let hi = (self.vol.dims[a] - 1) as f32;
            if d_idx[a] == 0.0 {
                if o_idx[a] < 0.0 || o_idx[a] > hi {
                    return None;
                }
                continue;
            }
            let (mut n, mut f) = ((0.0 - o_idx[a]) / d_idx[a], (hi - o_idx[a]) / d_idx[a]);
            if n > f {
                std::mem::swap(&mut n, &mut f);
            }
            t0 = t0.max(n);
            t1 = t1.min(f);
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// Transmittance from index point `p` toward the light (`l_idx`: index units per mm along
    /// the unit light direction), through the transfer function's opacity on the lattice of
    /// the primary ray's step (from one step out, so that a sample does not shadow itself),
    /// skipping transparent bricks; and the samples taken.
    fn transmittance(
        &self,
        tf: &TransferFunction,
        p: Vec3,
        l_idx: Vec3,
        step: f32,
        jitter: f32,
    ) -> (f32, u64) {
        let Some((_, t1)) = self.clip(p, l_idx) else {
            return (1.0, 0);
        };
        self.absorb(tf, p, l_idx, [step, t1], step, jitter)
    }

    /// Transmittance over `[t0, t1]` (mm) of the ray `o_idx + t·d_idx` through the transfer
    /// function's opacity on the lattice t0 + (k + jitter)·step, skipping transparent bricks;
    /// and the samples taken. Stops below 1 % (nothing visible gets through).
    pub fn absorb(
        &self,
        tf: &TransferFunction,
        o_idx: Vec3,
        d_idx: Vec3,
        span: [f32; 2],
        step: f32,
        jitter: f32,
    ) -> (f32, u64) {
        match self.isa {
            // SAFETY: the processor has every feature `absorb_v3` is compiled for.
            #[cfg(target_arch = "x86_64")]
            Isa::X86_64V3 if self.isa.available() => unsafe {
                self.absorb_v3(tf, o_idx, d_idx, span, step, jitter)
            },
            _ => self.absorb_here(tf, o_idx, d_idx, span, step, jitter),
        }
    }

    /// [`Self::absorb`] compiled for x86-64-v3 (`raystream_accel::isa`), as [`march_v3`].
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,movbe,f16c")]
    fn absorb_v3(
        &self,
        tf: &TransferFunction,
        o_idx: Vec3,
        d_idx: Vec3,
        span: [f32; 2],
        step: f32,
        jitter: f32,
    ) -> (f32, u64) {
        self.absorb_here(tf, o_idx, d_idx, span, step, jitter)
    }

    /// [`Self::absorb`] in the instruction set of its caller.
    #[inline(always)]
    fn absorb_here(
        &self,
        tf: &TransferFunction,
        o_idx: Vec3,
        d_idx: Vec3,
        [t0, t1]: [f32; 2],
        step: f32,
        jitter: f32,
    ) -> (f32, u64) {
        let (mut transmit, mut taken, mut k) = (1.0f32, 0u64, 0u64);
        loop {
            let start = t0 + k as f32 * step;
            if start >= t1 {
                break;
            }
            let t = (t0 + (k as f32 + jitter) * step).min(t1);
            let q = o_idx + d_idx * t;
            if let Some(next) = self.skip_brick(q, t, t0, d_idx, step, jitter, k) {
                k = next;
                continue;
            }
            let seg = step.min(t1 - start);
            taken += 1;
            k += 1;
            let a = tf.opacity_at(self.sample(q));
            if a > 0.0 {
                transmit *= (1.0 - a.min(1.0)).powf(seg);
                if transmit < 0.01 {
                    break;
                }
            }
        }
        (transmit, taken)
    }

    /// [`Self::composite`] in the marcher's instruction set ([`Self::in_isa`]), for callers
    /// outside a march (a mesh scene's segments of a ray through its volume).
    #[allow(clippy::too_many_arguments)]
    pub fn composite_ray(
        &self,
        tf: &TransferFunction,
        ray: Ray3,
        idx: (Vec3, Vec3),
        span: [f32; 2],
        step: f32,
        skip: bool,
        lights: &[SampleLight],
    ) -> Composited {
        match self.isa {
            // SAFETY: the processor has every feature `composite_v3` is compiled for.
            #[cfg(target_arch = "x86_64")]
            Isa::X86_64V3 if self.isa.available() => unsafe {
                self.composite_v3(tf, ray, idx, span, step, skip, lights)
            },
            _ => self.composite(tf, ray, idx, span, step, skip, lights),
        }
    }

    /// [`Self::composite`] compiled for x86-64-v3 (`raystream_accel::isa`), as [`march_v3`].
    #[cfg(target_arch = "x86_64")]
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,movbe,f16c")]
    fn composite_v3(
        &self,
        tf: &TransferFunction,
        ray: Ray3,
        idx: (Vec3, Vec3),
        span: [f32; 2],
        step: f32,
        skip: bool,
        lights: &[SampleLight],
    ) -> Composited {
        self.composite(tf, ray, idx, span, step, skip, lights)
    }

    /// Front-to-back emission–absorption over `[t0, t1]` (mm) of `ray` (LPS, unit direction;
    /// `o_idx`, `d_idx` its index form) on the lattice t0 + (k + jitter)·step, each sample lit
    /// by `lights` (`shade_sample`); early termination below 1 % transmittance, transparent
    /// bricks skipped when `skip`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn composite(
        &self,
        tf: &TransferFunction,
        ray: Ray3,
        (o_idx, d_idx): (Vec3, Vec3),
        [t0, t1]: [f32; 2],
        step: f32,
        skip: bool,
        lights: &[SampleLight],
    ) -> Composited {
        let mut out = Composited {
            transmit: 1.0,
            ..Default::default()
        };
        let mut k = 0u64;
        // Sample k stands for the segment [t0 + kΔs, t0 + (k + 1)Δs) clipped to [t0, t1]
        // (the last one is shorter), so that the segments add up to the ray's length.
        loop {
            let start = t0 + k as f32 * step;
            if start >= t1 {
                break;
            }
            let t = (t0 + (k as f32 + ray.jitter) * step).min(t1);
            let seg = step.min(t1 - start);
            let p = o_idx + d_idx * t;
            if skip && let Some(next) = self.skip_brick(p, t, t0, d_idx, step, ray.jitter, k) {
                out.skipped += next - k;
                k = next;
                continue;
            }
            out.taken += 1;
            k += 1;
            let v = self.sample(p);
            let a = tf.opacity_at(v);
            if a <= 0.0 {
                continue;
            }
            let a = 1.0 - (1.0 - a.min(1.0)).powf(seg);
            let base = self.albedo(Vec3::from(tf.color_at(v)), p);
            let shaded = shade_sample(self, tf, base, p, ray.o + ray.d * t, ray.d, lights);
            out.color += out.transmit * a * shaded;
            out.transmit *= 1.0 - a;
            if out.transmit < 0.01 {
                break;
            }
        }
        out
    }

    /// Where index point `q` (ray parameter `t`) lies in a transparent brick: the index of the
    /// first sample of the lattice t0 + (k + jitter)·step past that brick (at least k + 1).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn skip_brick(
        &self,
        q: Vec3,
        t: f32,
        t0: f32,
        d_idx: Vec3,
        step: f32,
        jitter: f32,
        k: u64,
    ) -> Option<u64> {
        let (b, t_exit) = self.brick_exit(q, t, d_idx);
        (!self.visible[b])
            .then(|| (((t_exit - t0) / step - jitter).ceil().max(0.0) as u64).max(k + 1))
    }

    /// The brick holding index `p`, and the ray parameter where the ray leaves it.
    fn brick_exit(&self, p: Vec3, t: f32, d_idx: Vec3) -> (usize, f32) {
        cell_exit(p, t, d_idx, BRICK, self.bricks)
    }
}

/// The camera that shows a volume from the front (anterior view, a little from above, head up,
/// the patient's right on the image's left), framing its box, in the scene frame x = L,
/// y = S, z = A.
pub fn volume_camera(vol: &Volume, aspect: f32) -> Camera {
    volume_camera_from(vol, aspect, VOLUME_VIEW, Projection::Perspective)
}

/// A camera framing the whole volume from `view` (in the scene frame; a turntable turns
/// [`VOLUME_VIEW`] about the patient's superior axis: 90° looks from the patient's left).
pub fn volume_camera_from(vol: &Volume, aspect: f32, view: View, projection: Projection) -> Camera {
    let [nx, ny, nz] = vol.dims;
    let corners: Vec<Vec3> = (0..8)
        .map(|c| {
            let idx = raystream_math::DVec3::new(
                if c & 1 != 0 { (nx - 1) as f64 } else { 0.0 },
                if c & 2 != 0 { (ny - 1) as f64 } else { 0.0 },
                if c & 4 != 0 { (nz - 1) as f64 } else { 0.0 },
            );
            lps_to_scene(vol.index_to_world(idx).as_vec3())
        })
        .collect();
    Camera::framing(&corners, aspect, view, projection)
}

/// Light grid points per axis at most: 128³ shadow rays a frame.
pub const LIGHT_GRID_MAX: usize = 128;

/// `--shadows`: the transmittance toward the light on a grid of about every other voxel (at
/// most [`LIGHT_GRID_MAX`] per axis) spanning the voxel-centre box, one shadow ray from each
/// grid point ([`Marcher`]'s `transmittance`), read back at every visible sample by trilinear
/// interpolation: a shadow ray per grid point instead of one per sample (166 per primary
/// sample on the 512³ benchmark with ct-bone). The GPU computes the same grid the same way.
pub struct LightGrid {
    pub dims: [usize; 3],
    /// Volume index → grid coordinate, per axis.
    scale: Vec3,
    pub values: Vec<f32>,
    /// Samples the grid's shadow rays took.
    pub samples: u64,
}

impl LightGrid {
    /// Grid points per axis for a volume of `dims` voxels.
    pub fn dims_for(dims: [usize; 3]) -> [usize; 3] {
        dims.map(|n| {
            if n <= 1 {
                1
            } else {
                n.div_ceil(2).clamp(2, LIGHT_GRID_MAX.min(n))
            }
        })
    }

    /// Index position of grid point `j` along an axis of `n` voxels and `g` grid points.
    fn position(j: usize, n: usize, g: usize) -> f32 {
        if g > 1 {
            j as f32 * ((n - 1) as f32 / (g - 1) as f32)
        } else {
            0.0
        }
    }

    /// The grid of a directional light (`light`: unit LPS direction toward it).
    pub fn new(m: &Marcher, tf: &TransferFunction, light: Vec3, step: f32) -> LightGrid {
        let l_idx = m.index_dir(light);
        Self::from_rays(m, |p| m.transmittance(tf, p, l_idx, step, 0.5))
    }

    /// The grid of a point light at LPS `light` (mm): shadow rays end at the light, and
    /// `blocked(p, light)` (LPS points) says whether something else (a mesh) stops them.
    pub fn toward_point(
        m: &Marcher,
        tf: &TransferFunction,
        light: Vec3,
        step: f32,
        blocked: impl Fn(Vec3, Vec3) -> bool + Sync,
    ) -> LightGrid {
        Self::from_rays(m, |p| {
            let world = m.world_of(p);
            let to_light = light - world;
            let dist = to_light.length();
            if dist == 0.0 || blocked(world, light) {
                return (if dist == 0.0 { 1.0 } else { 0.0 }, 0);
            }
            let l_idx = m.index_dir(to_light / dist);
            match m.clip(p, l_idx) {
                Some((_, t1)) => m.absorb(tf, p, l_idx, [step, t1.min(dist)], step, 0.5),
                None => (1.0, 0),
            }
        })
    }

    /// The grid whose point at volume index `p` holds `shadow_ray(p)` = (transmittance,
    /// samples taken).
    fn from_rays(m: &Marcher, shadow_ray: impl Fn(Vec3) -> (f32, u64) + Sync) -> LightGrid {
        let n = m.vol.dims;
        let dims = Self::dims_for(n);
        let rays: Vec<(f32, u64)> = (0..dims[0] * dims[1] * dims[2])
            .into_par_iter()
            .map(|i| {
                let j = [i % dims[0], i / dims[0] % dims[1], i / (dims[0] * dims[1])];
                shadow_ray(Vec3::new(
                    Self::position(j[0], n[0], dims[0]),
                    Self::position(j[1], n[1], dims[1]),
                    Self::position(j[2], n[2], dims[2]),
                ))
            })
            .collect();
        let scale = Vec3::from(std::array::from_fn::<f32, 3, _>(|a| {
            if n[a] > 1 && dims[a] > 1 {
                (dims[a] - 1) as f32 / (n[a] - 1) as f32
            } else {
                0.0
            }
        }));
        LightGrid {
            dims,
            scale,
            samples: rays.iter().map(|r| r.1).sum(),
            values: rays.into_iter().map(|r| r.0).collect(),
        }
    }

    /// The light reaching volume index `p` (trilinear between grid points).
    pub fn at(&self, p: Vec3) -> f32 {
        let [gx, gy, _] = self.dims;
        trilinear(self.dims, p * self.scale, |i, j, k| {
            self.values[i + gx * (j + gy * k)]
        })
    }
}

/// The direction toward the key light of `--shadows` (LPS, unit): above the camera, to its
/// left and in front of the volume, so that shadows fall down and to the right.
pub fn key_light(cam: &Camera) -> Vec3 {
    scene_to_lps((cam.up * 0.6 - cam.right * 0.45 - cam.fwd * 0.66).normalize())
}

/// The direction toward a key light `az` degrees to the right of the camera (negative: to its
/// left) and `el` degrees above it, as seen from the volume (LPS, unit): (0, 0) lights from
/// the camera, (90, 0) from the image's right, (0, 90) from the image's top, (180, 0) from
/// behind. [`key_light`] is about (−34.3, 36.9).
pub fn key_light_from(cam: &Camera, az: f32, el: f32) -> Vec3 {
    let (az, el) = (az.to_radians(), el.to_radians());
    let d = cam.right * (el.cos() * az.sin()) + cam.up * el.sin() - cam.fwd * (el.cos() * az.cos());
    scene_to_lps(d.normalize())
}

/// The part [t0, t1] of the ray o + t·d (LPS, unit d) that the crop box and the clip planes
/// keep.
pub fn clip_interval(opt: &DvrOptions, o: Vec3, d: Vec3, t0: f32, t1: f32) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (t0, t1);
    if let Some([lo, hi]) = opt.crop {
        for a in 0..3 {
            if d[a] == 0.0 {
                if o[a] < lo[a] || o[a] > hi[a] {
                    return None;
                }
                continue;
            }
            let (n, f) = ((lo[a] - o[a]) / d[a], (hi[a] - o[a]) / d[a]);
            t0 = t0.max(n.min(f));
            t1 = t1.min(n.max(f));
        }
    }
    for (n, c) in opt.clip_planes.iter().flatten() {
        // n · (o + t d) ≥ c
        let (no, nd) = (n.dot(o), n.dot(d));
        if nd == 0.0 {
            if no < *c {
                return None;
            }
        } else if nd > 0.0 {
            t0 = t0.max((c - no) / nd);
        } else {
            t1 = t1.min((c - no) / nd);
        }
    }
    (t0 <= t1).then_some((t0, t1))
}

/// LPS → the scene frame of [`volume_camera`] (and of `Scene::for_bones`).
pub fn lps_to_scene(p: Vec3) -> Vec3 {
    raystream_scene::Frame::Lps.to_scene(p)
}

/// The scene frame of [`volume_camera`] → LPS.
pub fn scene_to_lps(p: Vec3) -> Vec3 {
    Vec3::new(p.x, -p.z, p.y)
}

/// The per-pixel start offset in [0, 1) steps of a sample lattice.
pub fn start_jitter(pixel: u32) -> f32 {
    crate::jitter(pixel, 0, 7)
}

/// Where `v` falls in the window (width, level): 0 at its bottom, 1 at its top.
fn window(v: f32, (w, l): (f32, f32)) -> f32 {
    ((v - (l - 0.5 * w)) / w.max(1e-6)).clamp(0.0, 1.0)
}

/// The film value of a windowed pixel: a window maps HU linearly to the grey levels shown (as
/// a DICOM viewer's VOI LUT does), so the film holds the linear light whose 8-bit sRGB byte is
/// 255 × (v − (l − w/2)) / w, clamped: fat in a soft-tissue window is dark grey, not mid-grey.
pub fn windowed(v: f32, win: (f32, f32)) -> f32 {
    crate::srgb_to_linear(window(v, win))
}

/// A volume and its transfer function as the CPU draws frames of them: the brick tables of
/// dvr's empty-space skipping and the majorant grids of cinematic tracking, per interpolation,
/// are built by the first frame that needs them and kept, so that a turntable or a `bench`
/// orbit builds them once, as the GPU renderer does (a 512³ CT's brick table took 0.25 s of
/// every 64×64 dvr frame on the 2-core machine, BENCHMARKS.md).
pub struct CpuVolume<'a> {
    pub vol: &'a Volume,
    pub tf: &'a TransferFunction,
    /// The values each interpolation reads.
    grids: SplineGrids,
    /// Per interpolation (`Interpolation as usize`).
    bricks: [std::sync::OnceLock<Vec<bool>>; 3],
    majorants: [std::sync::OnceLock<crate::cinematic::Majorants>; 3],
    /// A segmentation's colours, which dvr, iso and cinematic samples take.
    segments: Option<&'a SegmentColours>,
    /// mip, minip and average kept to segments: the kept voxels' weights ([`Self::kept`]),
    /// and what each interpolation reads of them.
    weights: Option<&'a Volume>,
    weight_grids: SplineGrids,
    /// Per interpolation, the bricks a kept projection may see ([`kept_brick_table`]).
    kept_bricks: [std::sync::OnceLock<Vec<bool>>; 3],
    /// The instruction set its pixels are marched in ([`Self::in_isa`]).
    isa: Isa,
}

impl<'a> CpuVolume<'a> {
    pub fn new(vol: &'a Volume, tf: &'a TransferFunction) -> CpuVolume<'a> {
        CpuVolume {
            vol,
            tf,
            grids: Default::default(),
            bricks: Default::default(),
            majorants: Default::default(),
            segments: None,
            weights: None,
            weight_grids: Default::default(),
            kept_bricks: Default::default(),
            isa: Isa::current(),
        }
    }

    /// The volume with its pixels marched in the instruction set `isa` (by default the one
    /// the CPU ray queries run in, [`Isa::current`]; the baseline's where the processor lacks
    /// `isa`): the same pixels, bit for bit, in every one.
    pub fn in_isa(mut self, isa: Isa) -> CpuVolume<'a> {
        self.isa = isa;
        self
    }

    /// The volume with its dvr, iso and cinematic samples coloured by `segments` (on its
    /// grid), where given.
    pub fn painted(mut self, segments: Option<&'a SegmentColours>) -> CpuVolume<'a> {
        self.segments = segments;
        self
    }

    /// The volume kept to some of its segments, for mip, minip and average, where `weights`
    /// is given: on the volume's grid, 1 at each kept voxel and 0 at each hidden one, whose
    /// value in the volume must be 0. Each sample is then the kept voxels' own blend where it
    /// lies within the segments, and projects nothing elsewhere ([`Marcher::sample_kept`]): a
    /// MIP of a vessel without the bones in front of it, with no rim where its edge would
    /// blend with what is hidden; a ray that meets no segment is a miss.
    pub fn kept(mut self, weights: Option<&'a Volume>) -> CpuVolume<'a> {
        if let Some(w) = weights {
            check_kept(self.vol, w);
        }
        self.weights = weights;
        self
    }

    /// The values frames read as `interpolation` read: the voxels, or the interpolating
    /// spline's coefficients, computed here the first time (what a caller that times frames
    /// may call first, to time this apart), and likewise the kept weights'.
    pub fn grid(&self, interpolation: Interpolation) -> &[f32] {
        if let Some(w) = self.weights {
            self.weight_grids.get(w, interpolation);
        }
        self.grids.get(self.vol, interpolation)
    }

    /// The marcher of frames `opt` describes: the brick table when dvr skips empty space, or
    /// a kept projection the bricks outside its segments.
    fn marcher(&self, opt: &DvrOptions) -> Marcher<'_> {
        use std::borrow::Cow;
        let i = opt.interpolation;
        let grid = self.grid(i);
        let weights = self
            .weights
            .filter(|_| opt.mode.is_projection())
            .map(|w| self.weight_grids.get(w, i));
        let table = match weights {
            _ if !opt.skip_empty => None,
            Some(w) => Some(
                self.kept_bricks[i as usize].get_or_init(|| kept_brick_table(self.vol.dims, w, i)),
            ),
            None if opt.mode == DvrMode::Dvr => Some(
                self.bricks[i as usize]
                    .get_or_init(|| brick_table(self.vol.dims, grid, self.tf, i)),
            ),
            None => None,
        };
        match table {
            Some(t) => Marcher::with_bricks(self.vol, Cow::Borrowed(grid), Cow::Borrowed(t), i),
            None => Marcher::with_grid(self.vol, Cow::Borrowed(grid), i),
        }
        .painted(self.segments)
        .kept(weights.map(Cow::Borrowed))
        .in_isa(self.isa)
    }

    /// The majorant grid of cinematic frames read as `m` reads the volume.
    fn majorants(&self, m: &Marcher) -> &crate::cinematic::Majorants {
        self.majorants[m.interpolation() as usize]
            .get_or_init(|| crate::cinematic::Majorants::new(m, self.tf))
    }

    /// One frame over `opt.background` (with `opt.hu_values`, a windowed mode's pixels
    /// without a sample are NaN).
    pub fn render<'s>(&self, opt: &DvrOptions, sight: impl Into<Sight<'s>>) -> (Image, DvrStats) {
        let (rays, stats) = march_frame(self, opt, sight.into(), None);
        let background = if opt.hu_values && opt.mode.is_windowed() {
            Vec3::NAN
        } else {
            opt.background
        };
        let pixels = rays.iter().map(|c| c.over(background)).collect();
        (
            Image {
                width: opt.width,
                height: opt.height,
                pixels,
            },
            stats,
        )
    }

    /// One frame with no background, in one pass: the premultiplied light each pixel sends
    /// (C) and its opacity α = 1 − T, so that over any background B the pixel is
    /// C + (1 − α)·B, exactly [`Self::render`]'s; adding to `done` the paths of a cinematic
    /// frame as its pixels finish (what a progress bar counts: `width · height · spp` in all;
    /// other modes add nothing).
    pub fn render_rgba_counted<'s>(
        &self,
        opt: &DvrOptions,
        sight: impl Into<Sight<'s>>,
        done: &AtomicU64,
    ) -> (Image, Vec<f32>, DvrStats) {
        let (rays, stats) = march_frame(self, opt, sight.into(), Some(done));
        let film = Image {
            width: opt.width,
            height: opt.height,
            pixels: rays.iter().map(|c| c.color).collect(),
        };
        (film, rays.iter().map(|c| 1.0 - c.transmit).collect(), stats)
    }
}

/// Panics unless `weights` can keep `vol` to segments ([`CpuVolume::kept`], and the GPU's
/// renderer likewise): on its grid, and 0 wherever `vol` is not (a hidden voxel holds 0).
pub fn check_kept(vol: &Volume, weights: &Volume) {
    assert_eq!(weights.dims, vol.dims, "weights on the volume's grid");
    assert!(
        weights
            .data
            .iter()
            .zip(&vol.data)
            .all(|(w, v)| *w != 0.0 || *v == 0.0),
        "a kept volume's hidden voxels hold 0"
    );
}

/// Renders `vol` (HU) with `tf` (dvr mode; `None` elsewhere is fine) over `opt.background`
/// (with `opt.hu_values`, a windowed mode's pixels without a sample are NaN): one frame of a
/// [`CpuVolume`].
pub fn render_volume<'a>(
    vol: &Volume,
    tf: &TransferFunction,
    opt: &DvrOptions,
    sight: impl Into<Sight<'a>>,
) -> (Image, DvrStats) {
    CpuVolume::new(vol, tf).render(opt, sight)
}

/// Renders `vol` with no background, in one pass: the premultiplied light each pixel sends
/// (C) and its opacity α = 1 − T (T: the fraction of what lies behind that it lets through),
/// so that over any background B the pixel is C + (1 − α)·B, exactly [`render_volume`]'s.
pub fn render_volume_rgba<'a>(
    vol: &Volume,
    tf: &TransferFunction,
    opt: &DvrOptions,
    sight: impl Into<Sight<'a>>,
) -> (Image, Vec<f32>, DvrStats) {
    CpuVolume::new(vol, tf).render_rgba_counted(opt, sight, &AtomicU64::new(0))
}

/// Premultiplied `film` of opacity `alpha` laid over `background`: C + (1 − α)·B.
pub fn over_background(mut film: Image, alpha: &[f32], background: Vec3) -> Image {
    for (c, a) in film.pixels.iter_mut().zip(alpha) {
        *c += (1.0 - a) * background;
    }
    film
}

/// Where a frame's rays come from: a camera's pixels, or a curved plane's (a CPR: each
/// pixel's ray runs along the plane's normal through the `slab` about its point).
#[derive(Clone, Copy)]
pub enum Sight<'a> {
    Camera(&'a Camera),
    Curved(&'a CurvedPlane),
}

impl<'a> From<&'a Camera> for Sight<'a> {
    fn from(cam: &'a Camera) -> Self {
        Sight::Camera(cam)
    }
}

impl<'a> From<&'a CurvedPlane> for Sight<'a> {
    fn from(plane: &'a CurvedPlane) -> Self {
        Sight::Curved(plane)
    }
}

impl Sight<'_> {
    /// The clip planes its rays are cut to (`opt.planes_for` a camera; a curved plane's slab is
    /// its rays' own reach, so only the user's planes).
    pub fn planes(&self, opt: &DvrOptions, vol: &Volume) -> [Option<(Vec3, f32)>; 2] {
        match self {
            Sight::Camera(cam) => opt.planes_for(vol, cam),
            Sight::Curved(_) => opt.clip_planes,
        }
    }

    /// Pixel `pixel`'s ray and the plane a slice samples on it (with how far the ray reaches,
    /// mm): a camera's ray and the plane through `slice_at` facing it; a curved plane's ray
    /// from half the slab (`half_slab`, mm) before the pixel's point, along the normal there,
    /// to half the slab beyond, and the plane through that point.
    fn ray(&self, opt: &DvrOptions, pixel: u32, slice_at: Vec3, half_slab: f32) -> (Ray3, Slice) {
        let (x, y) = (pixel % opt.width, pixel / opt.width);
        let jitter = start_jitter(pixel);
        match self {
            Sight::Camera(cam) => {
                let r = cam.ray(x as f32 + 0.5, y as f32 + 0.5, opt.width, opt.height);
                let (o, d) = (scene_to_lps(r.origin), scene_to_lps(r.dir));
                let slice = Slice {
                    at: slice_at,
                    normal: scene_to_lps(cam.fwd),
                    reach: f32::INFINITY,
                };
                (Ray3 { o, d, jitter }, slice)
            }
            Sight::Curved(plane) => {
                let (p, n) = plane.point(x, y);
                let slice = Slice {
                    at: p,
                    normal: n,
                    reach: 2.0 * half_slab,
                };
                let o = p - half_slab * n;
                (Ray3 { o, d: n, jitter }, slice)
            }
        }
    }
}

/// `opt` as a frame seen by `sight` is marched: cut to the clip planes its view adds, its slab
/// (the rays' own reach by then) taken off.
pub(crate) fn frame_options(vol: &Volume, opt: &DvrOptions, sight: Sight) -> DvrOptions {
    DvrOptions {
        clip_planes: sight.planes(opt, vol),
        slab: None,
        ..*opt
    }
}

/// Every pixel's ray, marched.
fn march_frame(
    cv: &CpuVolume,
    opt: &DvrOptions,
    sight: Sight,
    done: Option<&AtomicU64>,
) -> (Vec<Marched>, DvrStats) {
    let (vol, tf) = (cv.vol, cv.tf);
    if let Sight::Curved(plane) = sight {
        assert_eq!(
            (plane.width, plane.height),
            (opt.width, opt.height),
            "a curved plane is made for its image's size"
        );
    }
    let half_slab = 0.5 * opt.slab.unwrap_or(0.0);
    let opt = &frame_options(vol, opt, sight);
    let marcher = cv.marcher(opt);
    if opt.mode == DvrMode::Cinematic {
        let Sight::Camera(cam) = sight else {
            panic!("cinematic rendering is seen by a camera, not a curved plane");
        };
        let majorants = cv.majorants(&marcher);
        let (paths, denoised) = crate::cinematic::frame(&marcher, tf, majorants, opt, cam, done);
        let mut rays: Vec<Marched> = paths
            .iter()
            .map(|p| Marched {
                color: p.light,
                transmit: p.escaped,
                taken: p.taken,
                skipped: 0,
            })
            .collect();
        let mut denoise = None;
        if let Some((film, alpha, times)) = denoised {
            for ((r, c), a) in rays.iter_mut().zip(film.pixels).zip(alpha) {
                r.color = c;
                r.transmit = 1.0 - a;
            }
            denoise = Some(times);
        }
        let stats = DvrStats {
            samples: rays.iter().map(|c| c.taken).sum(),
            step_mm: 0.0,
            denoise,
            ..Default::default()
        };
        return (rays, stats);
    }
    let step = opt.step_for(vol);
    let win = opt.shown_window();
    let light = match sight {
        Sight::Camera(cam) if opt.shadows && opt.mode == DvrMode::Dvr => Some(opt.key_light(cam)),
        _ => None,
    };
    let grid = light.map(|l| LightGrid::new(&marcher, tf, l, opt.shadow_step_for(vol)));
    let slice_at = opt.slice_point(vol);
    let rays: Vec<Marched> = (0..opt.width * opt.height)
        .into_par_iter()
        .with_min_len(64)
        .map(|pixel| {
            let (ray, slice) = sight.ray(opt, pixel, slice_at, half_slab);
            let light = light.zip(grid.as_ref());
            march_in(&marcher, tf, opt, (win, step, slice), light, ray)
        })
        .collect();
    let stats = DvrStats {
        samples: rays.iter().map(|c| c.taken).sum(),
        skipped: rays.iter().map(|c| c.skipped).sum(),
        shadow_samples: grid.as_ref().map_or(0, |g| g.samples),
        step_mm: step,
        denoise: None,
    };
    (rays, stats)
}

/// A ray in LPS (unit `d`, mm) and its start offset in steps.
#[derive(Clone, Copy)]
pub struct Ray3 {
    pub o: Vec3,
    pub d: Vec3,
    pub jitter: f32,
}

/// What compositing a stretch of a ray gave: emitted colour, transmittance, samples taken and
/// skipped.
#[derive(Clone, Copy, Debug, Default)]
pub struct Composited {
    pub color: Vec3,
    pub transmit: f32,
    pub taken: u64,
    pub skipped: u64,
}

/// Where a light lies from a volume sample.
#[derive(Clone, Copy, Debug)]
pub enum Toward {
    /// A unit LPS direction (a headlight, the key light).
    Direction(Vec3),
    /// An LPS point (mm): a scene's point light.
    Point(Vec3),
}

/// A light that shades volume samples: where it is, its colour, and the light grid of its
/// shadow rays (`None`: unshadowed).
#[derive(Clone, Copy)]
pub struct SampleLight<'a> {
    pub toward: Toward,
    pub color: Vec3,
    pub grid: Option<&'a LightGrid>,
}

/// The light a sample of colour `base` at index `p` (world `at`, seen along unit `d`) sends
/// back: per light, two-sided Blinn–Phong on the gradient normal, weighted by gradient
/// magnitude so that homogeneous regions stay unshaded (lit without a normal), times the
/// light's colour and what its light grid lets through. With one white unshadowed light this
/// is the classic headlight shading.
#[inline(always)]
fn shade_sample(
    m: &Marcher,
    tf: &TransferFunction,
    base: Vec3,
    p: Vec3,
    at: Vec3,
    d: Vec3,
    lights: &[SampleLight],
) -> Vec3 {
    let g = m.gradient(p);
    let gm = g.length();
    let amb = tf.shading.ambient;
    // Weight of surface shading: gradient magnitude; the rest lit without a normal.
    let w = (gm / FULL_SHADING_GRADIENT).min(1.0);
    let (mut unshaded, mut surface, mut spec) = (Vec3::splat(amb), Vec3::splat(amb), Vec3::ZERO);
    for light in lights {
        let l = match light.toward {
            Toward::Direction(l) => l,
            Toward::Point(q) => (q - at).normalize_or(-d),
        };
        let lit = light.color * light.grid.map_or(1.0, |grid| grid.at(p));
        let (diff, sp) = if gm > 0.0 {
            phong(tf, -g / gm, d, l)
        } else {
            (amb, 0.0)
        };
        unshaded += (1.0 - amb) * lit;
        surface += (diff - amb) * lit;
        spec += sp * lit;
    }
    base * ((1.0 - w) * unshaded + w * surface) + w * spec
}

/// What one ray gave: the light it sends toward the eye (premultiplied, no background), the
/// fraction of the background it lets through, and the samples it took and skipped.
#[derive(Clone, Copy)]
struct Marched {
    color: Vec3,
    transmit: f32,
    taken: u64,
    skipped: u64,
}

impl Marched {
    /// A ray that reached nothing: all background.
    const MISS: Marched = Marched {
        color: Vec3::ZERO,
        transmit: 1.0,
        taken: 0,
        skipped: 0,
    };

    /// An opaque value (a projection's, a slice's, an isosurface's) after `taken` samples.
    fn opaque(color: Vec3, taken: u64) -> Marched {
        Marched {
            color,
            transmit: 0.0,
            taken,
            skipped: 0,
        }
    }

    /// The pixel over `background` (which may be NaN, for "no value": opaque pixels keep
    /// theirs).
    fn over(&self, background: Vec3) -> Vec3 {
        if self.transmit == 0.0 {
            self.color
        } else {
            self.color + self.transmit * background
        }
    }
}

/// Two-sided Blinn–Phong toward light `l` seen along `d`: (ambient + diffuse, specular). With
/// a headlight (l = −d) the half vector is −d.
fn phong(tf: &TransferFunction, n: Vec3, d: Vec3, l: Vec3) -> (f32, f32) {
    let s = tf.shading;
    let h = (l - d).normalize_or(-d);
    (
        s.ambient + s.diffuse * n.dot(l).abs(),
        s.specular * n.dot(h).abs().powf(s.power),
    )
}

/// The colour of `--mode iso`'s surface (bone), where no segment colours it.
pub const ISO_COLOUR: Vec3 = Vec3::new(0.88, 0.84, 0.74);

/// Gradient magnitude (HU/mm) at which shading is fully on.
pub(crate) const FULL_SHADING_GRADIENT: f32 = 100.0;

/// The plane of a slice: a point and its normal (LPS), and how far along its ray a sample may
/// lie (mm; a curved plane's slab, else unbounded).
#[derive(Clone, Copy, Debug)]
struct Slice {
    at: Vec3,
    normal: Vec3,
    reach: f32,
}

/// [`march`] compiled for the marcher's instruction set where the processor has it, else the
/// baseline's: the same pixel, bit for bit (Rust contracts no multiply and add into an FMA).
fn march_in(
    m: &Marcher,
    tf: &TransferFunction,
    opt: &DvrOptions,
    frame: ((f32, f32), f32, Slice),
    light: Option<(Vec3, &LightGrid)>,
    ray: Ray3,
) -> Marched {
    match m.isa {
        // SAFETY: the processor has every feature `march_v3` is compiled for.
        #[cfg(target_arch = "x86_64")]
        Isa::X86_64V3 if m.isa.available() => unsafe { march_v3(m, tf, opt, frame, light, ray) },
        _ => march(m, tf, opt, frame, light, ray),
    }
}

/// [`march`] compiled for x86-64-v3 (`raystream_accel::isa`): every function of a sample's
/// path is `#[inline(always)]` into it, or it would run the baseline's code.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,movbe,f16c")]
fn march_v3(
    m: &Marcher,
    tf: &TransferFunction,
    opt: &DvrOptions,
    frame: ((f32, f32), f32, Slice),
    light: Option<(Vec3, &LightGrid)>,
    ray: Ray3,
) -> Marched {
    march(m, tf, opt, frame, light, ray)
}

/// One ray: colour, samples taken, samples skipped; `win`, `step` and `slice` resolved from
/// `opt` once a frame.
#[inline(always)]
fn march(
    m: &Marcher,
    tf: &TransferFunction,
    opt: &DvrOptions,
    (win, step, slice): ((f32, f32), f32, Slice),
    light: Option<(Vec3, &LightGrid)>,
    Ray3 { o, d, jitter }: Ray3,
) -> Marched {
    let miss = Marched::MISS;
    let (o_idx, d_idx) = (m.index_of(o), m.index_dir(d));
    let Some((t0, t1)) = m
        .clip(o_idx, d_idx)
        .and_then(|(t0, t1)| clip_interval(opt, o, d, t0, t1.min(slice.reach)))
    else {
        return miss;
    };
    let mut k = 0u64;
    let at = |k: u64| t0 + (k as f32 + jitter) * step;
    let mut taken = 0u64;
    match opt.mode {
        DvrMode::Dvr => {
            let ray = Ray3 { o, d, jitter };
            // A headlight, or the key light through its light grid.
            let lights = [SampleLight {
                toward: Toward::Direction(light.map_or(-d, |(l, _)| l)),
                color: Vec3::ONE,
                grid: light.map(|(_, g)| g),
            }];
            let c = m.composite(
                tf,
                ray,
                (o_idx, d_idx),
                [t0, t1],
                step,
                opt.skip_empty,
                &lights,
            );
            Marched {
                color: c.color,
                transmit: c.transmit,
                taken: c.taken,
                skipped: c.skipped,
            }
        }
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average => {
            let (mut best, mut sum) = (
                if opt.mode == DvrMode::Mip {
                    f32::NEG_INFINITY
                } else {
                    f32::INFINITY
                },
                0.0f64,
            );
            // Samples projected: all that are taken, or of a volume kept to segments those
            // within them (a plain projection reads its samples as directly as ever).
            let mut projected = 0u64;
            let kept = m.weights.is_some();
            let mut skipped = 0u64;
            loop {
                let t = at(k);
                if t > t1 {
                    break;
                }
                let p = o_idx + d_idx * t;
                // Of a volume kept to segments, the bricks outside them, whose samples are
                // none (`kept_brick_table`).
                if kept
                    && opt.skip_empty
                    && let Some(next) = m.skip_brick(p, t, t0, d_idx, step, jitter, k)
                {
                    skipped += next - k;
                    k = next;
                    continue;
                }
                taken += 1;
                k += 1;
                let v = if kept {
                    match m.sample_kept(p) {
                        Some(v) => v,
                        None => continue,
                    }
                } else {
                    m.sample(p)
                };
                match opt.mode {
                    DvrMode::Mip => best = best.max(v),
                    DvrMode::MinIp => best = best.min(v),
                    _ => sum += v as f64,
                }
                projected += 1;
            }
            if projected == 0 {
                // No sample, or none within the kept segments.
                return Marched {
                    taken,
                    skipped,
                    ..miss
                };
            }
            let v = if opt.mode == DvrMode::Average {
                (sum / projected as f64) as f32
            } else {
                best
            };
            Marched {
                skipped,
                ..Marched::opaque(
                    Vec3::splat(if opt.hu_values { v } else { windowed(v, win) }),
                    taken,
                )
            }
        }
        DvrMode::Slice => {
            // One sample, where the ray crosses the plane (rays parallel to it see nothing).
            let t = (slice.at - o).dot(slice.normal) / d.dot(slice.normal);
            if !(t0..=t1).contains(&t) {
                return miss;
            }
            let v = m.sample(o_idx + d_idx * t);
            Marched::opaque(
                Vec3::splat(if opt.hu_values { v } else { windowed(v, win) }),
                1,
            )
        }
        DvrMode::Iso => {
            let iso = opt.iso_hu;
            let mut prev: Option<(f32, f32)> = None;
            loop {
                let t = at(k);
                if t > t1 {
                    return Marched { taken, ..miss };
                }
                let v = m.sample(o_idx + d_idx * t);
                taken += 1;
                k += 1;
                if v >= iso {
                    // Bisection between the last sample below and this one.
                    let (mut lo, mut hi) = match prev {
                        Some((tp, _)) => (tp, t),
                        None => (t, t),
                    };
                    for _ in 0..12 {
                        let mid = 0.5 * (lo + hi);
                        if m.sample(o_idx + d_idx * mid) >= iso {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    let g = m.gradient(o_idx + d_idx * hi);
                    let n = if g.length() > 0.0 { -g.normalize() } else { -d };
                    let (diff, spec) = phong(tf, n, d, -d);
                    let bone = m.albedo(ISO_COLOUR, o_idx + d_idx * hi);
                    return Marched::opaque(bone * diff + Vec3::splat(spec), taken);
                }
                prev = Some((t, v));
            }
        }
        DvrMode::Cinematic => unreachable!("march_frame traces cinematic paths"),
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use raystream_volume::TfPreset;

    use super::*;

    /// A kept projection skips the bricks its segments' weights do not reach
    /// (`kept_brick_table`) and gives the same pixels, bit for bit, as one that samples every
    /// brick: a block of 6 voxels kept in a 40³ CT, from the front and from an oblique view,
    /// each interpolation, each projection.
    #[test]
    fn kept_projections_skip_the_bricks_outside_their_segments() {
        let inside = |x: usize, y: usize, z: usize| {
            (17..23).contains(&x) && (14..20).contains(&y) && (9..15).contains(&z)
        };
        let n = [40; 3];
        let weights = volume(n, [1.0; 3], |x, y, z| inside(x, y, z) as u8 as f32);
        let kept = volume(n, [1.0; 3], |x, y, z| {
            if inside(x, y, z) {
                100.0 + ((x * 7 + y * 3 + z) % 11) as f32
            } else {
                0.0
            }
        });
        let tf = grey(0.0);
        let cv = CpuVolume::new(&kept, &tf).kept(Some(&weights));
        for interpolation in [
            Interpolation::Linear,
            Interpolation::Cubic,
            Interpolation::CubicInterpolating,
        ] {
            let table = kept_brick_table(
                n,
                cv.weight_grids.get(&weights, interpolation),
                interpolation,
            );
            let seen = table.iter().filter(|&&b| b).count();
            assert!(
                seen >= 1 && seen * 4 <= table.len(),
                "{interpolation:?}: {seen}"
            );
            for mode in [DvrMode::Mip, DvrMode::MinIp, DvrMode::Average] {
                for view in [VOLUME_VIEW, VOLUME_VIEW.orbit(35.0, 25.0)] {
                    let cam = volume_camera_from(&kept, 1.0, view, Projection::Perspective);
                    let opt = DvrOptions {
                        width: 32,
                        height: 32,
                        mode,
                        hu_values: true,
                        interpolation,
                        ..DvrOptions::default()
                    };
                    let (skipping, with) = cv.render(&opt, &cam);
                    let every = DvrOptions {
                        skip_empty: false,
                        ..opt
                    };
                    let (all, without) = cv.render(&every, &cam);
                    let what = format!("{interpolation:?} {mode:?} {view:?}");
                    let differ = (skipping.pixels.iter().zip(&all.pixels))
                        .filter(|(a, b)| a.x.to_bits() != b.x.to_bits())
                        .count();
                    assert_eq!(differ, 0, "{what}: skipping changed {differ} pixels");
                    assert!(all.pixels.iter().any(|p| !p.x.is_nan()), "{what}");
                    assert_eq!(without.skipped, 0);
                    assert!(
                        with.skipped > 2 * with.samples,
                        "{what}: {} skipped, {} taken",
                        with.skipped,
                        with.samples
                    );
                }
            }
        }
    }

    /// mip, minip and average of a volume kept to a block (the rest hidden: 0 in the volume,
    /// 0 in the weights), trilinear and cubic:
    /// - a ray is a miss exactly where the weights' own MIP stays under [`KEPT_WEIGHT`] (no
    ///   sample within the block), NaN with `hu_values` and the background without;
    /// - a block of one value projects that value on every ray that meets it, rim included
    ///   (a fill value blended at its edge, as hidden voxels set just below the range once
    ///   were, darkens a MIP's rim and brightens a MinIP's);
    /// - a block of varied values projects within their range;
    /// - kept whole (weights all 1), every pixel is the plain frame's, bit for bit when
    ///   trilinear.
    #[test]
    fn projections_kept_to_a_block_see_its_voxels_alone() {
        let inside = |x: usize, y: usize, z: usize| {
            (6..10).contains(&x) && (6..10).contains(&y) && (4..12).contains(&z)
        };
        let varied = |x: usize, y: usize, z: usize| 100.0 + (x + y + z) as f32;
        let weights = volume([16; 3], [1.0; 3], |x, y, z| inside(x, y, z) as u8 as f32);
        let ones = volume([16; 3], [1.0; 3], |_, _, _| 1.0);
        let tf = grey(0.0);
        for interpolation in [Interpolation::Linear, Interpolation::Cubic] {
            for mode in [DvrMode::Mip, DvrMode::MinIp, DvrMode::Average] {
                let opt = DvrOptions {
                    width: 24,
                    height: 24,
                    mode,
                    hu_values: true,
                    interpolation,
                    ..DvrOptions::default()
                };
                let cam = volume_camera(&weights, 1.0);
                let (reach, _) = CpuVolume::new(&weights, &tf).render(
                    &DvrOptions {
                        mode: DvrMode::Mip,
                        ..opt
                    },
                    &cam,
                );
                let what = format!("{mode:?}, {interpolation:?}");
                for (f, (lo, hi)) in [
                    (
                        &(|_, _, _| 100.0f32) as &dyn Fn(usize, usize, usize) -> f32,
                        (100.0, 100.0),
                    ),
                    (&varied, (116.0, 129.0)),
                ] {
                    let kept = volume([16; 3], [1.0; 3], |x, y, z| {
                        if inside(x, y, z) { f(x, y, z) } else { 0.0 }
                    });
                    let (film, _) = CpuVolume::new(&kept, &tf)
                        .kept(Some(&weights))
                        .render(&opt, &cam);
                    let mut values = 0;
                    for (v, r) in film.pixels.iter().zip(&reach.pixels) {
                        // NaN where the ray missed the volume.
                        let within = r.x >= KEPT_WEIGHT;
                        assert_eq!(
                            v.x.is_nan(),
                            !within,
                            "{what}: {v:?} where the weights' MIP is {r:?}"
                        );
                        if !v.x.is_nan() {
                            values += 1;
                            let tol = 1e-4 * hi;
                            assert!(
                                (lo - tol..=hi + tol).contains(&v.x),
                                "{what}: {} outside {lo}..{hi}",
                                v.x
                            );
                        }
                    }
                    assert!(values > 20 && values < 400, "{what}: {values} values");
                    // Shown: the misses take the background.
                    let shown = DvrOptions {
                        hu_values: false,
                        ..opt
                    };
                    let (png, _) = CpuVolume::new(&kept, &tf)
                        .kept(Some(&weights))
                        .render(&shown, &cam);
                    for (s, v) in png.pixels.iter().zip(&film.pixels) {
                        if v.x.is_nan() {
                            assert_eq!(*s, shown.background, "{what}");
                        }
                    }
                }
                let whole = volume([16; 3], [1.0; 3], |x, y, z| {
                    if inside(x, y, z) {
                        varied(x, y, z)
                    } else {
                        -1000.0
                    }
                });
                let (plain, _) = CpuVolume::new(&whole, &tf).render(&opt, &cam);
                let (kept, _) = CpuVolume::new(&whole, &tf)
                    .kept(Some(&ones))
                    .render(&opt, &cam);
                // Trilinear weights of ones sum to 1 exactly; the spline's to within rounding.
                let same = if interpolation == Interpolation::Linear {
                    0.0
                } else {
                    1e-6
                };
                for (p, k) in plain.pixels.iter().zip(&kept.pixels) {
                    assert!(
                        (p.x - k.x).abs() <= same * p.x.abs() || p.x.is_nan() && k.x.is_nan(),
                        "{what}: {p:?} {k:?}"
                    );
                }
            }
        }
    }

    fn volume(
        dims: [usize; 3],
        spacing: [f64; 3],
        f: impl Fn(usize, usize, usize) -> f32,
    ) -> Volume {
        let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(f(i, j, k));
                }
            }
        }
        Volume::hounsfield(dims, spacing, data)
    }

    /// A camera (scene frame) whose centre pixel of a 3×3 image looks along LPS +y (anterior to
    /// posterior) through the LPS point `target`.
    fn axis_camera(target: Vec3) -> Camera {
        let t = lps_to_scene(target);
        Camera::look_at(t + Vec3::new(0.0, 0.0, 500.0), t, Vec3::Y, 10.0)
    }

    fn grey(opacity: f32) -> TransferFunction {
        TransferFunction {
            opacity: vec![(-5000.0, opacity), (5000.0, opacity)],
            color: vec![(0.0, [0.0; 3])],
            shading: Default::default(),
        }
    }

    /// `--light AZ,EL`: (0, 0) lights from the camera, (90, 0) from the image's right, (0, 90)
    /// from its top, (180, 0) from behind, in LPS; the default key light is about (−34.3, 36.9).
    #[test]
    fn key_light_directions_turn_with_the_camera() {
        let cam = Camera::look_at(
            Vec3::new(3.0, 1.0, 9.0),
            Vec3::new(0.5, 0.0, -1.0),
            Vec3::Y,
            40.0,
        );
        let close = |a: Vec3, b: Vec3, what: &str| {
            assert!((a - b).length() < 1e-5, "{what}: {a} vs {b}");
        };
        for (az, el, want, what) in [
            (0.0, 0.0, -cam.fwd, "0,0"),
            (90.0, 0.0, cam.right, "90,0"),
            (-90.0, 0.0, -cam.right, "-90,0"),
            (0.0, 90.0, cam.up, "0,90"),
            (180.0, 0.0, cam.fwd, "180,0"),
        ] {
            close(key_light_from(&cam, az, el), scene_to_lps(want), what);
        }
        let default = key_light(&cam);
        assert!(
            (key_light_from(&cam, -34.29, 36.87) - default).length() < 1e-3,
            "{default}"
        );
        let opt = DvrOptions {
            light: Some([90.0, 0.0]),
            ..Default::default()
        };
        close(
            opt.key_light(&cam),
            scene_to_lps(cam.right),
            "DvrOptions::key_light",
        );
        close(DvrOptions::default().key_light(&cam), default, "no --light");
    }

    /// A homogeneous slab of opacity α per mm: transmittance (1 − α)^L = exp(−σL), within 1 %,
    /// for steps from 0.3 to 1.7 mm (opacity correction), and step-independent within 2 %.
    #[test]
    fn homogeneous_slab_transmits_exp_minus_sigma_l() {
        let vol = volume([24, 81, 24], [1.0, 0.8, 1.0], |_, _, _| 40.0);
        let length = 80.0 * 0.8;
        let alpha = 0.02f32;
        let want = (-(-(1.0 - alpha).ln()) * length).exp();
        let cam = axis_camera(Vec3::new(11.5, 32.0, 11.5));
        let mut got = Vec::new();
        for step in [0.3, 0.5, 0.8, 1.7] {
            let opt = DvrOptions {
                width: 3,
                height: 3,
                step_mm: Some(step),
                background: Vec3::ONE,
                ..Default::default()
            };
            let (img, _) = render_volume(&vol, &grey(alpha), &opt, &cam);
            let t = img.pixels[4].x;
            assert!(
                (t - want).abs() <= 0.01 * want,
                "step {step}: transmittance {t}, exp(-σL) = {want}"
            );
            got.push(t);
        }
        let (lo, hi) = got
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &t| (a.min(t), b.max(t)));
        assert!(hi / lo - 1.0 < 0.02, "{got:?}");
    }

    /// Crop box and clip planes shorten the path through a homogeneous slab exactly: the
    /// transmittance becomes exp(−σL) of the kept length, and a crop box beside the ray leaves
    /// the background.
    #[test]
    fn crop_and_clip_planes_keep_exactly_their_part() {
        let vol = volume([24, 81, 24], [1.0, 0.8, 1.0], |_, _, _| 40.0);
        let alpha = 0.02f32;
        let cam = axis_camera(Vec3::new(11.5, 32.0, 11.5));
        let t_of = |opt: DvrOptions| {
            let (img, _) = render_volume(&vol, &grey(alpha), &opt, &cam);
            img.pixels[4].x
        };
        let base = DvrOptions {
            width: 3,
            height: 3,
            step_mm: Some(0.4),
            background: Vec3::ONE,
            ..Default::default()
        };
        let want = |len: f32| (1.0 - alpha).powf(len);
        // The slab spans y ∈ [0, 64] mm; keep y ∈ [10, 30] (20 mm).
        let crop = t_of(DvrOptions {
            crop: Some([
                Vec3::new(-100.0, 10.0, -100.0),
                Vec3::new(100.0, 30.0, 100.0),
            ]),
            ..base
        });
        assert!(
            (crop - want(20.0)).abs() <= 0.01 * want(20.0),
            "crop: {crop}"
        );
        // Planes y ≥ 5 and −y ≥ −45: 40 mm.
        let planes = t_of(DvrOptions {
            clip_planes: [Some((Vec3::Y, 5.0)), Some((-Vec3::Y, -45.0))],
            ..base
        });
        assert!(
            (planes - want(40.0)).abs() <= 0.01 * want(40.0),
            "planes: {planes}"
        );
        let beside = t_of(DvrOptions {
            crop: Some([Vec3::new(50.0, 0.0, 0.0), Vec3::new(60.0, 64.0, 24.0)]),
            ..base
        });
        assert_eq!(
            beside, 1.0,
            "a crop box beside the ray leaves the background"
        );
    }

    /// A shadow ray through a homogeneous slab transmits exp(−σL) of the length between the
    /// sample and where the light direction leaves the grid, within 1 %, for several steps.
    #[test]
    fn shadow_rays_transmit_exp_minus_sigma_l() {
        let vol = volume([40, 40, 40], [1.0, 1.0, 1.0], |_, _, _| 40.0);
        let alpha = 0.03f32;
        let m = Marcher::new(&vol, Some(&grey(alpha)));
        let p = Vec3::new(10.0, 20.0, 5.0);
        let l = Vec3::new(0.6, 0.0, 0.8);
        // Leaves through x = 39 (t = 29/0.6 = 48.3) or z = 39 (t = 34/0.8 = 42.5).
        let len = 42.5f32;
        let want = (1.0 - alpha).powf(len);
        for step in [0.3f32, 0.5, 1.1] {
            let (t, n) = m.transmittance(&grey(alpha), p, m.index_dir(l), step, 0.37);
            // The first step is left out (no self-shadowing): up to one step less absorption.
            let lo = want;
            let hi = (1.0 - alpha).powf(len - step);
            assert!(
                t >= lo * 0.99 && t <= hi * 1.01,
                "step {step}: {t} outside [{lo}, {hi}]"
            );
            assert!(n as f32 >= len / step - 2.0, "step {step}: {n} samples");
        }
        // An opaque slab between the sample and the light: nothing arrives.
        let wall = volume([40, 40, 40], [1.0; 3], |i, _, _| {
            if i == 20 { 1000.0 } else { -1000.0 }
        });
        let tf = TransferFunction {
            opacity: vec![(0.0, 0.0), (500.0, 1.0)],
            color: vec![(0.0, [1.0; 3])],
            shading: Default::default(),
        };
        let m = Marcher::new(&wall, Some(&tf));
        let (t, _) = m.transmittance(&tf, Vec3::new(5.0, 20.0, 20.0), Vec3::X, 0.5, 0.5);
        assert!(t < 0.02, "behind the wall: {t}");
        let (t, _) = m.transmittance(&tf, Vec3::new(25.0, 20.0, 20.0), Vec3::X, 0.5, 0.5);
        assert_eq!(t, 1.0, "in front of the wall");
    }

    /// Shadow rays of the light grid step at least one voxel; the march keeps its own step.
    #[test]
    fn shadow_step_is_at_least_a_voxel() {
        let vol = volume([4, 4, 4], [0.6, 0.8, 3.0], |_, _, _| 0.0);
        assert_eq!(step_for(None, &vol), 0.3);
        assert_eq!(shadow_step_for(None, &vol), 0.6);
        assert_eq!(shadow_step_for(Some(0.2), &vol), 0.6);
        assert_eq!(shadow_step_for(Some(1.5), &vol), 1.5);
    }

    /// A ray takes at most MAX_SAMPLES_PER_RAY samples across the box, however small one
    /// spacing is beside the others (the fuzzer's hang: 1e-6 mm beside 2.5 mm); real volumes
    /// keep their steps, the smallest `--step-mm` of a 512³ one included.
    #[test]
    fn a_ray_takes_a_bounded_number_of_samples() {
        let vol = volume([6, 5, 4], [1e-6, 0.8, 2.5], |_, _, _| 0.0);
        let diagonal = (4.0f64.powi(2) + 10.0f64.powi(2) + 6e-6f64.powi(2)).sqrt();
        let step = step_for(None, &vol) as f64;
        assert!(diagonal / step <= MAX_SAMPLES_PER_RAY * 1.0001, "{step}");
        assert!(diagonal / step >= MAX_SAMPLES_PER_RAY * 0.9999, "{step}");
        // A 512³ CT's grid (step_for reads no voxel).
        let ct = Volume {
            dims: [512, 512, 512],
            spacing: [0.7, 0.7, 1.0],
            ..vol.clone()
        };
        assert_eq!(step_for(None, &ct), 0.35);
        assert!((step_for(Some(1e-9), &ct) - 7e-4).abs() < 1e-9);
    }

    /// The light grid holds each grid point's shadow ray exactly, and between grid points
    /// interpolates the transmittance field within 4 %: the field is smooth but for steps of
    /// one lattice sample's absorption (here ≈ 1 %) where a ray's sample count changes.
    #[test]
    fn light_grid_interpolates_shadow_rays() {
        let vol = volume([41, 33, 25], [1.0, 1.2, 2.0], |_, _, _| 40.0);
        let tf = grey(0.02);
        let m = Marcher::new(&vol, Some(&tf));
        let light = Vec3::new(0.6, -0.3, 0.74).normalize();
        let step = 0.5;
        let grid = LightGrid::new(&m, &tf, light, step);
        assert_eq!(grid.dims, [21, 17, 13]);
        let l_idx = m.index_dir(light);
        // Grid point (3, 5, 7) sits at index (6, 10, 14).
        let exact = m
            .transmittance(&tf, Vec3::new(6.0, 10.0, 14.0), l_idx, step, 0.5)
            .0;
        assert_eq!(grid.at(Vec3::new(6.0, 10.0, 14.0)), exact);
        let mut rng = crate::tests::XorShift(0x2545_f491);
        for _ in 0..200 {
            let mut r = || rng.f32();
            let p = Vec3::new(r() * 40.0, r() * 32.0, r() * 24.0);
            let want = m.transmittance(&tf, p, l_idx, step, 0.5).0;
            let got = grid.at(p);
            assert!(
                (got - want).abs() <= 0.04 * want.max(0.05),
                "{p}: grid {got}, shadow ray {want}"
            );
        }
        assert!(grid.samples > 0);
    }

    /// With --shadows the abdomen CT darkens (its light grid's shadow rays take samples and
    /// take light away).
    #[test]
    fn shadows_darken_the_abdomen() {
        let vol = abdomen();
        let tf = TfPreset::CtBone.function();
        let opt = DvrOptions {
            width: 48,
            height: 36,
            ..Default::default()
        };
        let cam = volume_camera(&vol, 48.0 / 36.0);
        let (plain, _) = render_volume(&vol, &tf, &opt, &cam);
        let shadowed = DvrOptions {
            shadows: true,
            ..opt
        };
        let (shadow, stats) = render_volume(&vol, &tf, &shadowed, &cam);
        assert!(stats.shadow_samples > 0, "{stats:?}");
        let sum = |i: &Image| i.pixels.iter().map(|p| p.x + p.y + p.z).sum::<f32>();
        assert!(
            sum(&shadow) < 0.95 * sum(&plain),
            "{} vs {}",
            sum(&shadow),
            sum(&plain)
        );
    }

    /// Premultiplied RGBA in one pass: over any background B, C + (1 − α)·B is the frame
    /// rendered over B, in every mode (translucent DVR with shadows and a crop, opaque
    /// projections, slices and isosurfaces), and α is 0 exactly where a ray reaches nothing.
    #[test]
    fn one_pass_rgba_is_the_frame_over_any_background() {
        let vol = abdomen();
        let cam = volume_camera(&vol, 1.2);
        let base = DvrOptions {
            width: 40,
            height: 32,
            ..Default::default()
        };
        let crop = Some([Vec3::splat(-400.0), Vec3::new(40.0, 400.0, 400.0)]);
        for (mode, preset, shadows) in [
            (DvrMode::Dvr, TfPreset::CtBones, true),
            (DvrMode::Dvr, TfPreset::CtMuscle, false),
            (DvrMode::Mip, TfPreset::MipBone, false),
            (DvrMode::Slice, TfPreset::CtBone, false),
            (DvrMode::Iso, TfPreset::CtBone, false),
        ] {
            let tf = preset.function();
            let opt = DvrOptions {
                mode,
                shadows,
                crop,
                ..base
            };
            let (film, alpha, stats) = render_volume_rgba(&vol, &tf, &opt, &cam);
            assert_eq!(alpha.len(), film.pixels.len());
            let clear = alpha.iter().filter(|&&a| a == 0.0).count();
            assert!(
                clear > 0 && clear < alpha.len(),
                "{}: {clear} clear",
                mode.name()
            );
            if mode == DvrMode::Dvr {
                let between = alpha.iter().filter(|&&a| a > 0.05 && a < 0.95).count();
                assert!(between > 0, "{}: translucent pixels", preset.name());
            } else {
                assert!(
                    alpha.iter().all(|&a| a == 0.0 || a == 1.0),
                    "{}",
                    mode.name()
                );
            }
            for background in [Vec3::ZERO, Vec3::ONE, Vec3::new(0.2, 0.5, 0.9)] {
                let (want, s) = render_volume(&vol, &tf, &DvrOptions { background, ..opt }, &cam);
                assert_eq!(s.samples, stats.samples);
                for ((c, a), w) in film.pixels.iter().zip(&alpha).zip(&want.pixels) {
                    let over = *c + (1.0 - a) * background;
                    assert!((over - *w).abs().max_element() < 1e-6, "{over} vs {w}");
                    if *a == 0.0 {
                        assert_eq!(*w, background, "a clear pixel is the background");
                    }
                }
            }
        }
    }

    /// `hu_values`: on the abdomen CT the projections' films hold HU whose window is the
    /// windowed film, pixel for pixel; per pixel MinIP ≤ average ≤ MIP (the same samples);
    /// the rays that take no sample are NaN in all three and the background without it.
    #[test]
    fn projections_give_hounsfield_units_before_the_window() {
        let vol = abdomen();
        let base = DvrOptions {
            width: 48,
            height: 40,
            ..Default::default()
        };
        let cam = volume_camera(&vol, 1.2);
        let tf = grey(0.0);
        let mut hu = Vec::new();
        for mode in [DvrMode::MinIp, DvrMode::Average, DvrMode::Mip] {
            let opt = DvrOptions { mode, ..base };
            let (shown, _) = render_volume(&vol, &tf, &opt, &cam);
            let values = DvrOptions {
                hu_values: true,
                ..opt
            };
            let (film, _) = render_volume(&vol, &tf, &values, &cam);
            let win = mode.default_window();
            for (v, s) in film.pixels.iter().zip(&shown.pixels) {
                if v.x.is_nan() {
                    assert!(v.is_nan() && *s == opt.background, "{}", mode.name());
                } else {
                    assert!(v.x == v.y && v.y == v.z, "one value a pixel");
                    assert_eq!(Vec3::splat(windowed(v.x, win)), *s, "{}", mode.name());
                }
            }
            hu.push(film.pixels.iter().map(|p| p.x).collect::<Vec<f32>>());
        }
        let sampled = hu[0].iter().filter(|v| !v.is_nan()).count();
        assert!(sampled > 48 * 40 / 2, "{sampled} pixels sampled");
        for ((&lo, &mean), &hi) in hu[0].iter().zip(&hu[1]).zip(&hu[2]) {
            if lo.is_nan() {
                assert!(mean.is_nan() && hi.is_nan());
                continue;
            }
            assert!(lo <= mean + 1e-3 && mean <= hi + 1e-3, "{lo} {mean} {hi}");
        }
        // Bone and air both in view: the values span the CT's range, beyond any window.
        let top = hu[2]
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f32::MIN, f32::max);
        let bottom = hu[0]
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f32::MAX, f32::min);
        assert!(
            top > 1500.0 && bottom < -900.0,
            "MIP up to {top}, MinIP down to {bottom}"
        );
    }

    /// `--mode slice` samples the plane through `slice_at` facing the camera, at the pixels'
    /// positions. The grid is oblique and anisotropic and holds linear fields, which trilinear
    /// interpolation reproduces exactly: the field n·p (n the view direction) is the plane's
    /// offset at every pixel, and right·p and up·p are the pixel's position across the image
    /// (one pixel's size a column and a row). Six patient views and an oblique orbit, on an
    /// oblique grid and on a sheared one (a gantry-tilted CT's).
    #[test]
    fn slices_sample_their_plane_at_the_pixels() {
        let turn = raystream_math::DMat3::from_rotation_z(20f64.to_radians())
            * raystream_math::DMat3::from_rotation_x(10f64.to_radians());
        // The third axis leans 18.5° towards the second.
        let lean =
            raystream_math::DVec3::new(0.0, 18.5f64.to_radians().sin(), 18.5f64.to_radians().cos());
        let shear = raystream_math::DMat3::from_cols(
            raystream_math::DVec3::X,
            raystream_math::DVec3::Y,
            lean,
        );
        for m in [turn, turn * shear] {
            slices_sample_their_plane(m);
        }
    }

    fn slices_sample_their_plane(m: raystream_math::DMat3) {
        use raystream_scene::PatientView as V;
        let mut vol = volume([30, 26, 22], [0.8, 1.1, 1.6], |_, _, _| 0.0);
        vol.direction = std::array::from_fn(|r| std::array::from_fn(|c| m.col(c)[r]));
        vol.origin = [-12.0, 5.0, 30.0];
        let (w, h) = (40u32, 30u32);
        let views = [
            V::Anterior,
            V::Posterior,
            V::Left,
            V::Right,
            V::Superior,
            V::Inferior,
        ]
        .map(|v| v.view());
        for (i, view) in views
            .into_iter()
            .chain([VOLUME_VIEW.orbit(30.0, 20.0)])
            .enumerate()
        {
            let cam = volume_camera_from(&vol, w as f32 / h as f32, view, Projection::Parallel);
            let [n, right, up] = [cam.fwd, cam.right, cam.up].map(scene_to_lps);
            let at = DvrOptions::default().slice_point(&vol) + 2.0 * n - 1.5 * right;
            for (axis, what) in [(n, "depth"), (right, "across"), (up, "up")] {
                let mut field = vol.clone();
                for k in 0..vol.dims[2] {
                    for j in 0..vol.dims[1] {
                        for i in 0..vol.dims[0] {
                            let p = vol.index_to_world(raystream_math::DVec3::new(
                                i as f64, j as f64, k as f64,
                            ));
                            field.data[i + vol.dims[0] * (j + vol.dims[1] * k)] =
                                axis.dot(p.as_vec3());
                        }
                    }
                }
                let opt = DvrOptions {
                    width: w,
                    height: h,
                    mode: DvrMode::Slice,
                    hu_values: true,
                    slice_at: Some(at),
                    ..Default::default()
                };
                let (img, stats) = render_volume(&field, &grey(0.0), &opt, &cam);
                let eye = scene_to_lps(cam.eye);
                let mut seen = 0;
                for (pixel, v) in img.pixels.iter().enumerate() {
                    if v.x.is_nan() {
                        continue;
                    }
                    seen += 1;
                    let (x, y) = ((pixel as u32 % w) as f32, (pixel as u32 / w) as f32);
                    let sx = ((x + 0.5) / w as f32 * 2.0 - 1.0) * (w as f32 / h as f32);
                    let sy = 1.0 - (y + 0.5) / h as f32 * 2.0;
                    let want = match what {
                        "depth" => n.dot(at),
                        "across" => right.dot(eye) + sx * cam.parallel,
                        _ => up.dot(eye) + sy * cam.parallel,
                    };
                    assert!(
                        (v.x - want).abs() < 2e-3 * (1.0 + want.abs()),
                        "view {i}, {what}, pixel ({x}, {y}): {} HU, want {want}",
                        v.x
                    );
                }
                assert_eq!(stats.samples, seen, "one sample a pixel on the plane");
                assert!(
                    seen > (w * h / 4) as u64,
                    "view {i}: {seen} pixels on the plane"
                );
            }
        }
    }

    /// A slab is the two clip planes about its middle facing the camera: the same picture as
    /// those planes given by hand, and the planes are the slab's faces.
    #[test]
    fn a_slab_is_two_planes_facing_the_camera() {
        let vol = abdomen();
        let cam = volume_camera_from(
            &vol,
            1.0,
            VOLUME_VIEW.orbit(25.0, 10.0),
            Projection::Parallel,
        );
        let at = Vec3::new(0.0, 60.0, 150.0);
        let slab = DvrOptions {
            width: 40,
            height: 40,
            mode: DvrMode::Mip,
            slice_at: Some(at),
            slab: Some(12.0),
            ..Default::default()
        };
        let n = scene_to_lps(cam.fwd).normalize();
        let planes = slab.planes_for(&vol, &cam);
        assert_eq!(
            planes,
            [Some((n, n.dot(at) - 6.0)), Some((-n, -n.dot(at) - 6.0))]
        );
        let by_hand = DvrOptions {
            slab: None,
            clip_planes: planes,
            ..slab
        };
        let tf = grey(0.0);
        let (a, sa) = render_volume(&vol, &tf, &slab, &cam);
        let (b, sb) = render_volume(&vol, &tf, &by_hand, &cam);
        assert_eq!(a, b);
        assert_eq!(sa.samples, sb.samples);
        let whole = render_volume(&vol, &tf, &DvrOptions { slab: None, ..slab }, &cam);
        assert!(
            sa.samples * 5 < whole.1.samples,
            "a 12 mm slab takes a fraction of the samples"
        );
    }

    /// MIP of a volume with one hot voxel shows it where the camera projects its centre.
    #[test]
    fn mip_shows_a_hot_voxel_at_its_projection() {
        let hot = [13usize, 7, 21];
        let vol = volume([30, 25, 40], [0.9, 1.1, 1.4], |i, j, k| {
            if [i, j, k] == hot { 3000.0 } else { -1000.0 }
        });
        let opt = DvrOptions {
            width: 97,
            height: 83,
            mode: DvrMode::Mip,
            step_mm: Some(0.1),
            ..Default::default()
        };
        let cam = volume_camera(&vol, opt.width as f32 / opt.height as f32);
        let (img, _) = render_volume(&vol, &grey(0.0), &opt, &cam);
        let brightest = (0..img.pixels.len())
            .max_by(|&a, &b| img.pixels[a].x.total_cmp(&img.pixels[b].x))
            .unwrap();
        let (bx, by) = (brightest as u32 % opt.width, brightest as u32 / opt.width);
        let p = lps_to_scene(
            vol.index_to_world(raystream_math::DVec3::new(13.0, 7.0, 21.0))
                .as_vec3(),
        );
        let q = p - cam.eye;
        let z = q.dot(cam.fwd);
        let (w, h) = (opt.width as f32, opt.height as f32);
        let px = (q.dot(cam.right) / z / (cam.tan_y * w / h) + 1.0) * 0.5 * w;
        let py = (1.0 - q.dot(cam.up) / z / cam.tan_y) * 0.5 * h;
        assert!(
            (bx as f32 + 0.5 - px).abs() <= 1.0 && (by as f32 + 0.5 - py).abs() <= 1.0,
            "brightest pixel ({bx}, {by}), projection ({px}, {py})"
        );
        assert!(img.pixels[brightest].x > 0.9);
    }

    /// Each named view shows the patient the right way round: a hot block in the patient's
    /// left-anterior-superior corner (LPS: high x, low y, high z) lands in the image quarter the
    /// view's conventions put it in, by the brightest pixels' centre in a MIP.
    #[test]
    fn every_patient_view_shows_the_patient_the_right_way_round() {
        use raystream_scene::PatientView as V;
        let vol = volume([20, 24, 28], [1.0, 0.9, 1.2], |i, j, k| {
            if i >= 14 && j < 6 && k >= 20 {
                2000.0
            } else {
                0.0
            }
        });
        let opt = DvrOptions {
            width: 48,
            height: 48,
            mode: DvrMode::Mip,
            window: Some((100.0, 1950.0)),
            ..Default::default()
        };
        // (view, on the image's right, at the image's top)
        let want = [
            (V::Anterior, true, true),   // the patient's left on the image's right
            (V::Posterior, false, true), // … on the image's left
            (V::Left, false, true),      // anterior on the image's left
            (V::Right, true, true),      // anterior on the image's right
            (V::Superior, false, true),  // the patient's left on the image's left, anterior up
            (V::Inferior, true, true),   // as axial slices: the left on the right, anterior up
        ];
        for (view, right, top) in want {
            let cam = volume_camera_from(&vol, 1.0, view.view(), Projection::Perspective);
            let (img, _) = render_volume(&vol, &grey(0.0), &opt, &cam);
            let hot: Vec<(f32, f32)> = (0..img.pixels.len())
                .filter(|&i| img.pixels[i].x > 0.5)
                .map(|i| ((i % 48) as f32 + 0.5, (i / 48) as f32 + 0.5))
                .collect();
            assert!(hot.len() > 20, "{view:?}: {} hot pixels", hot.len());
            let n = hot.len() as f32;
            let x = hot.iter().map(|p| p.0).sum::<f32>() / n;
            let y = hot.iter().map(|p| p.1).sum::<f32>() / n;
            assert_eq!(
                (x > 24.0, y < 24.0),
                (right, top),
                "{view:?}: hot block at ({x}, {y})"
            );
            assert!(
                (x - 24.0).abs() > 6.0 && (y - 24.0).abs() > 6.0,
                "{view:?}: ({x}, {y})"
            );
        }
        // The front view turned a quarter about the superior axis is the view from the left.
        let turned = volume_camera_from(
            &vol,
            1.0,
            V::Anterior.view().orbit(90.0, 0.0),
            Projection::Perspective,
        );
        let left = volume_camera_from(&vol, 1.0, V::Left.view(), Projection::Perspective);
        assert!(
            (turned.fwd - left.fwd).length() < 1e-6,
            "{turned:?} vs {left:?}"
        );
        assert!((turned.right - left.right).length() < 1e-6);
        assert!((turned.eye - left.eye).length() < 1e-3);
    }

    /// Two equal hot cubes, one near the front of the volume and one near the back, side by
    /// side as seen from the front: a parallel projection draws them the same size, a
    /// perspective one draws the nearer larger.
    #[test]
    fn a_parallel_projection_draws_every_depth_at_one_scale() {
        // LPS: x to the patient's left, y to posterior; cube A anterior (low y), B posterior.
        let vol = volume([40, 40, 40], [1.0; 3], |i, j, k| {
            let a = (6..12).contains(&i) && (2..8).contains(&j);
            let b = (28..34).contains(&i) && (32..38).contains(&j);
            if (a || b) && (17..23).contains(&k) {
                2000.0
            } else {
                0.0
            }
        });
        let opt = DvrOptions {
            width: 64,
            height: 64,
            mode: DvrMode::Mip,
            window: Some((100.0, 1950.0)),
            ..Default::default()
        };
        let front = raystream_scene::PatientView::Anterior.view();
        let areas = |projection| {
            let cam = volume_camera_from(&vol, 1.0, front, projection);
            let (img, _) = render_volume(&vol, &grey(0.0), &opt, &cam);
            // Cube A (the patient's right) on the image's left, B on its right.
            let hot = |right: bool| {
                (0..img.pixels.len())
                    .filter(|&i| ((i % 64) >= 32) == right && img.pixels[i].x > 0.5)
                    .count() as f32
            };
            (hot(false), hot(true))
        };
        let (a, b) = areas(Projection::Parallel);
        assert!(
            a > 20.0 && (a / b - 1.0).abs() < 0.2,
            "parallel: {a} vs {b} pixels"
        );
        let (a, b) = areas(Projection::Perspective);
        assert!(
            b > 4.0 && a / b > 1.5,
            "perspective: the nearer {a} vs the farther {b} pixels"
        );
    }

    /// The abdomen CT that the CLI embeds as its default.
    fn abdomen() -> Volume {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
        raystream_io::load_volume(&p, &Default::default()).expect("the embedded CT loads")
    }

    /// Empty-space skipping keeps the sample lattice: the same picture, fewer samples; with
    /// the cubic B-splines too, whose samples reach a voxel further (their tables bound the
    /// spline's control points, not the corner voxels), the interpolating one's taken over
    /// its coefficients.
    #[test]
    fn empty_space_skipping_changes_nothing_but_the_cost() {
        let vol = abdomen();
        let tf = TfPreset::CtBones.function();
        for interpolation in Interpolation::ALL {
            let mut opt = DvrOptions {
                width: 64,
                height: 48,
                interpolation,
                ..Default::default()
            };
            let cam = volume_camera(&vol, 64.0 / 48.0);
            let (skip, s1) = render_volume(&vol, &tf, &opt, &cam);
            opt.skip_empty = false;
            let (full, s2) = render_volume(&vol, &tf, &opt, &cam);
            assert_eq!(skip, full, "{interpolation:?}");
            assert!(s1.skipped > 0 && s2.skipped == 0);
            assert!(s1.samples < s2.samples);
        }
    }

    /// A segmentation's colours change the colour and nothing else. On the abdomen with
    /// ct-bones' opacity in white, every voxel of one segment coloured red: dvr's red channel
    /// is the plain frame's bit for bit (iso's no less, its bone colour replaced), green and
    /// blue are the white specular highlight alone, and the opacity is the plain frame's; with no voxel
    /// coloured (label 0, or a label given no colour) the frame is the plain one. With the
    /// left half of the grid red and the right half blue, the image's two halves (the
    /// patient's right on its left, anterior view) take the two colours.
    #[test]
    fn segment_colours_change_the_colour_and_nothing_else() {
        use crate::segments::SegmentColours;
        let vol = abdomen();
        let mut tf = TfPreset::CtBones.function();
        tf.color = vec![(0.0, [1.0; 3])];
        let (red, blue) = (Vec3::X, Vec3::Z);
        let n = vol.data.len();
        let everywhere = |l: u16| SegmentColours::new(vol.dims, vec![l; n], &[(1, red)]);
        // The patient's right (LPS x below the grid's middle) red, the left blue.
        let [nx, ..] = vol.dims;
        let lps_x = |i: usize| vol.index_to_world(raystream_math::DVec3::X * i as f64).x;
        let middle = 0.5 * (lps_x(0) + lps_x(nx - 1));
        let halves = SegmentColours::new(
            vol.dims,
            (0..n)
                .map(|i| 1 + (lps_x(i % nx) > middle) as u16)
                .collect(),
            &[(1, red), (2, blue)],
        );
        let cam = volume_camera(&vol, 64.0 / 48.0);
        for (mode, interpolation) in [
            (DvrMode::Dvr, Interpolation::Linear),
            (DvrMode::Dvr, Interpolation::Cubic),
            (DvrMode::Iso, Interpolation::Linear),
        ] {
            let opt = DvrOptions {
                width: 64,
                height: 48,
                mode,
                interpolation,
                ..Default::default()
            };
            let frame = |s: Option<&SegmentColours>| {
                let done = AtomicU64::new(0);
                CpuVolume::new(&vol, &tf)
                    .painted(s)
                    .render_rgba_counted(&opt, &cam, &done)
            };
            let what = format!("{} {interpolation:?}", mode.name());
            let (plain, plain_alpha, _) = frame(None);
            let (painted, alpha, _) = frame(Some(&everywhere(1)));
            assert_eq!(
                alpha, plain_alpha,
                "{what}: the opacity is the plain frame's"
            );
            let mut lit = 0;
            for (p, q) in painted.pixels.iter().zip(&plain.pixels) {
                if mode == DvrMode::Dvr {
                    assert_eq!(p.x, q.x, "{what}: red is the plain frame's red");
                } else {
                    // Red (1, 0, 0) in place of the bone's (0.88, 0.84, 0.74).
                    assert!(p.x >= q.x, "{what}: red in place of the bone's");
                }
                assert_eq!(p.y, p.z, "{what}: green and blue, the highlight");
                assert!(p.y <= q.y, "{what}: no more green than the plain frame's");
                lit += (p.x > 0.05) as usize;
            }
            assert!(lit > 200, "{what}: {lit} pixels show bone");
            for none in [0, 2] {
                let (same, _, _) = frame(Some(&everywhere(none)));
                assert_eq!(same, plain, "{what}: label {none} colours nothing");
            }
            // The patient's right on the image's left: red there.
            let (split, _, _) = frame(Some(&halves));
            let side = |right: bool| {
                split
                    .pixels
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| if right { i % 64 >= 40 } else { i % 64 < 24 })
                    .fold(Vec3::ZERO, |s, (_, p)| s + *p)
            };
            let (left, right) = (side(false), side(true));
            assert!(
                left.x > 2.0 * left.z && right.z > 2.0 * right.x,
                "{what}: the image's left {left}, right {right}"
            );
        }
    }

    /// A [`CpuVolume`] draws frames of either interpolation in any order, each the one-shot
    /// render's bit for bit, building each brick table and majorant grid once and only for
    /// the frames that need them.
    #[test]
    fn a_cpu_volume_keeps_its_tables_between_frames() {
        // Which brick tables and majorant grids (per interpolation) are built, and whether
        // the interpolating spline's coefficients are.
        let built = |cv: &CpuVolume| {
            (
                [0, 1, 2].map(|i| cv.bricks[i].get().is_some()),
                [0, 1, 2].map(|i| cv.majorants[i].get().is_some()),
                cv.grids.has_coefficients(),
            )
        };
        let vol = abdomen();
        let tf = TfPreset::CtBones.function();
        let cv = CpuVolume::new(&vol, &tf);
        let cam = volume_camera(&vol, 48.0 / 32.0);
        let frames = [
            (DvrMode::Mip, Interpolation::Linear),
            (DvrMode::Dvr, Interpolation::Linear),
            (DvrMode::Dvr, Interpolation::Cubic),
            (DvrMode::Cinematic, Interpolation::Cubic),
            (DvrMode::Dvr, Interpolation::Linear),
            (DvrMode::Cinematic, Interpolation::CubicInterpolating),
            (DvrMode::Dvr, Interpolation::CubicInterpolating),
        ];
        for (k, (mode, interpolation)) in frames.into_iter().enumerate() {
            let opt = DvrOptions {
                width: 48,
                height: 32,
                mode,
                spp: 2,
                interpolation,
                ..Default::default()
            };
            let (want, want_stats) = render_volume(&vol, &tf, &opt, &cam);
            let (got, got_stats) = cv.render(&opt, &cam);
            assert_eq!(got, want, "{mode:?} {interpolation:?}");
            assert_eq!(got_stats.samples, want_stats.samples);
            assert_eq!(got_stats.skipped, want_stats.skipped);
            if k == 0 {
                // A MIP needs none.
                assert_eq!(built(&cv), ([false; 3], [false; 3], false));
            }
            if k == 4 {
                assert_eq!(
                    built(&cv),
                    ([true, true, false], [false, true, false], false)
                );
            }
        }
        assert_eq!(built(&cv), ([true, true, true], [false, true, true], true));
    }

    /// Every sample inside a brick the table calls transparent is transparent, and every
    /// sample's extinction is within its cell's majorant (cinematic tracking), on the abdomen
    /// under two presets, read trilinearly and by either cubic B-spline. The points are drawn
    /// mostly in the voxel layers along the cells' faces, where a sample reads the next
    /// cell's voxels (cubic tables built with the trilinear reach fail: checked).
    #[test]
    fn cell_tables_bound_every_sample() {
        use crate::cinematic::{MAJORANT_CELL, Majorants, sigma_of};
        let vol = abdomen();
        for preset in [TfPreset::CtBones, TfPreset::CtMuscle] {
            let tf = preset.function();
            for interpolation in Interpolation::ALL {
                let m = Marcher::interpolated(&vol, Some(&tf), interpolation);
                let (bricks, visible) = m.brick_table();
                let majorants = Majorants::new(&m, &tf);
                let tables: [(usize, [usize; 3], Vec<f32>); 2] = [
                    (
                        BRICK,
                        bricks,
                        visible
                            .iter()
                            .map(|&v| if v { f32::INFINITY } else { 0.0 })
                            .collect(),
                    ),
                    (MAJORANT_CELL, majorants.dims, majorants.values.clone()),
                ];
                let mut rng = crate::tests::XorShift(0x9e37_79b9_7f4a_7c15);
                let mut uniform = || rng.f32();
                for (cell, cells, bound) in tables {
                    let mut tight = 0;
                    for _ in 0..200_000 {
                        let b = [0, 1, 2]
                            .map(|a| ((uniform() * cells[a] as f32) as usize).min(cells[a] - 1));
                        let limit = bound[b[0] + cells[0] * (b[1] + cells[1] * b[2])];
                        if limit.is_infinite() {
                            continue;
                        }
                        let p = Vec3::from_array([0, 1, 2].map(|a| {
                            let u = uniform();
                            let offset = match (uniform() * 4.0) as u32 {
                                0 => u * cell as f32,
                                1 => u,
                                _ => cell as f32 - u,
                            };
                            ((b[a] * cell) as f32 + offset).min((vol.dims[a] - 1) as f32)
                        }));
                        let sigma = sigma_of(tf.opacity_at(m.sample(p)));
                        tight += (sigma > 0.5 * limit) as u32;
                        assert!(
                            sigma <= limit * (1.0 + 1e-6),
                            "{preset:?} {interpolation:?}, cells of {cell}: σ {sigma} at {p} above its cell's bound {limit}"
                        );
                    }
                    // The majorants are met closely somewhere (not bounds of nothing).
                    assert!(cell == BRICK || tight > 100, "{tight}");
                }
            }
        }
    }

    /// The interpolating spline's tables hug its values, not its coefficients' ringing: on
    /// the abdomen under ct-bones, every brick trilinear's table shows it shows too (the spline
    /// passes through the voxels, so it takes every value between its corners'), and it shows
    /// 1.22× as many (677 against 555 of 2912), where its bricks' hulls alone show 4.0×; its
    /// majorants' mean is 1.04× trilinear's, where the hulls' is 5.7×.
    #[test]
    fn the_interpolating_splines_tables_hug_its_values() {
        use crate::cinematic::{MAJORANT_CELL, sigma_of};
        use crate::sampling::{block_hull, widened_by};
        let vol = abdomen();
        let tf = TfPreset::CtBones.function();
        let coefficients = spline_grid(&vol, Interpolation::CubicInterpolating);
        let grid = |i: Interpolation| match i {
            Interpolation::CubicInterpolating => &coefficients[..],
            _ => &vol.data[..],
        };
        // Per cell of `cell`³: σ of the greatest opacity over the hull alone.
        let hulls = |cell: usize| -> Vec<f32> {
            (0..cell_dims(vol.dims, cell).iter().product::<usize>())
                .map(|b| {
                    let (lo, hi) = cell_corners(vol.dims, cell, b);
                    let b = block_hull(vol.dims, &coefficients, lo, hi);
                    let (l, h) = widened_by(b.hull, b.scale);
                    sigma_of(tf.max_opacity_in(l, h))
                })
                .collect()
        };
        let visible = |i| brick_table(vol.dims, grid(i), &tf, i);
        let (linear, spline) = (
            visible(Interpolation::Linear),
            visible(Interpolation::CubicInterpolating),
        );
        let count = |t: &[bool]| t.iter().filter(|&&v| v).count();
        let hull_count = hulls(BRICK).iter().filter(|&&o| o > 0.0).count();
        assert!(linear.iter().zip(&spline).all(|(&l, &s)| !l || s));
        let msg = format!(
            "visible bricks: trilinear {}, interpolating {}, its hulls alone {hull_count} of {}",
            count(&linear),
            count(&spline),
            linear.len()
        );
        let mean = |v: &[f32]| v.iter().map(|&v| v as f64).sum::<f64>() / v.len() as f64;
        let majorants = |i| {
            let sigma: Vec<f32> = cell_opacities(vol.dims, grid(i), MAJORANT_CELL, i, &tf)
                .into_iter()
                .map(sigma_of)
                .collect();
            mean(&sigma)
        };
        let (m_linear, m_spline, m_hull) = (
            majorants(Interpolation::Linear),
            majorants(Interpolation::CubicInterpolating),
            mean(&hulls(MAJORANT_CELL)),
        );
        assert!(
            count(&spline) as f64 <= 1.25 * count(&linear) as f64,
            "{msg}"
        );
        assert!(hull_count as f64 > 3.0 * count(&linear) as f64, "{msg}");
        assert!(
            m_spline <= 1.1 * m_linear && m_hull > 4.0 * m_linear,
            "mean majorant /mm: trilinear {m_linear}, interpolating {m_spline}, hulls {m_hull}"
        );
    }

    /// The built-in abdomen CT (3 mm voxels) from the front under ct-muscle, whose skin
    /// trilinear sampling draws with wood-grain rings a voxel of depth apart: the grain, as the
    /// mean absolute Laplacian of the luminance over the body (pixels whose 3×3 neighbourhood
    /// is opaque), falls below 0.4× with the cubic B-spline, while the body keeps its
    /// outline (coverage) and its brightness. The interpolating spline keeps them too, and
    /// shaded by the voxels' spline's gradient its grain stays within 1.3× trilinear's.
    #[test]
    fn cubic_sampling_takes_the_wood_grain_off_the_skin() {
        let vol = abdomen();
        let tf = TfPreset::CtMuscle.function();
        let (w, h) = (256usize, 192usize);
        let cam = volume_camera(&vol, w as f32 / h as f32);
        let picture = |interpolation| {
            let opt = DvrOptions {
                width: w as u32,
                height: h as u32,
                interpolation,
                ..Default::default()
            };
            let (film, alpha, _) = render_volume_rgba(&vol, &tf, &opt, &cam);
            let lum: Vec<f32> = film
                .pixels
                .iter()
                .map(|c| crate::cinematic::luminance(*c))
                .collect();
            let (mut grain, mut body) = (0.0f64, 0usize);
            for y in 1..h - 1 {
                for x in 1..w - 1 {
                    let at = |dx: isize, dy: isize| {
                        (x as isize + dx) as usize + w * (y as isize + dy) as usize
                    };
                    let opaque = (-1..=1).all(|dy| (-1..=1).all(|dx| alpha[at(dx, dy)] > 0.99));
                    if opaque {
                        let l = lum[at(-1, 0)] + lum[at(1, 0)] + lum[at(0, -1)] + lum[at(0, 1)]
                            - 4.0 * lum[at(0, 0)];
                        grain += l.abs() as f64;
                        body += 1;
                    }
                }
            }
            let coverage = alpha.iter().filter(|&&a| a > 0.5).count();
            let mean = lum.iter().map(|&l| l as f64).sum::<f64>() / lum.len() as f64;
            (grain / body as f64, coverage, mean)
        };
        let (linear, cubic, sharp) = (
            picture(Interpolation::Linear),
            picture(Interpolation::Cubic),
            picture(Interpolation::CubicInterpolating),
        );
        // Measured (grain, pixels covered, mean luminance): trilinear (0.040, 17947, 0.130),
        // cubic (0.012, 17758, 0.127): a B-spline's smoothing pulls the outline in by about a
        // pixel here. The interpolating spline (0.045, 18085, 0.130) keeps the outline and the
        // brightness but not the cubic's calm: it passes through every voxel, noise included,
        // so its surface is as rough as the voxels. Shaded by its own analytic gradient, which
        // carries the noise its prefilter amplifies, it measured 0.125.
        assert!(
            linear.1 > w * h / 4,
            "the body fills the picture: {linear:?}"
        );
        assert!(cubic.0 < 0.4 * linear.0, "{linear:?} vs {cubic:?}");
        assert!(
            (cubic.1 as f64 / linear.1 as f64 - 1.0).abs() < 0.02,
            "{linear:?} vs {cubic:?}"
        );
        assert!(
            (cubic.2 / linear.2 - 1.0).abs() < 0.03,
            "{linear:?} vs {cubic:?}"
        );
        assert!(
            (sharp.1 as f64 / linear.1 as f64 - 1.0).abs() < 0.02
                && (sharp.2 / linear.2 - 1.0).abs() < 0.03,
            "{linear:?} vs {sharp:?}"
        );
        assert!(sharp.0 < 1.3 * linear.0, "{linear:?} vs {sharp:?}");
    }

    /// A ball of soft tissue in air, its edge a smooth ramp about a voxel wide, on a coarse
    /// (3 mm) oblique grid: the gradient's direction at points of the ball's surface against
    /// the true radial one. Trilinear central differences tilt back and forth as the surface
    /// crosses voxel layers (what shading draws as wood grain); the cubic B-spline's gradient
    /// follows the ball, and the interpolating spline is shaded by the same.
    #[test]
    fn the_cubic_gradient_follows_a_curved_surface() {
        let (c, s) = (0.8f64, 0.6f64);
        let mut vol = volume([24, 24, 24], [3.0; 3], |_, _, _| 0.0);
        vol.direction = [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]];
        let centre = raystream_math::DVec3::new(1.3, 2.1, -0.7);
        // The grid's middle (index 11.5 on each axis) 0.4 voxel off the ball's centre.
        let middle = raystream_math::DVec3::new(c - s, 1.0, s + c) * 3.0 * 11.1;
        vol.origin = (centre - middle).to_array();
        let radius = 22.0;
        for k in 0..24 {
            for j in 0..24 {
                for i in 0..24 {
                    let p = vol
                        .index_to_world(raystream_math::DVec3::new(i as f64, j as f64, k as f64));
                    let r = p.distance(centre);
                    vol.data[i + 24 * (j + 24 * k)] =
                        (-1000.0 + 1040.0 / (1.0 + ((r - radius) / 1.5).exp())) as f32;
                }
            }
        }
        let error_deg = |interpolation| {
            let m = Marcher::interpolated(&vol, None, interpolation);
            // Points of the sphere by a Fibonacci spiral.
            let n = 2000;
            let errors: Vec<f64> = (0..n)
                .map(|i| {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                    let phi = i as f64 * 2.399_963_229_728_653;
                    let r = (1.0 - z * z).sqrt();
                    let radial = raystream_math::DVec3::new(r * phi.cos(), r * phi.sin(), z);
                    let p = centre + radial * radius;
                    let g = m.gradient(m.index_of(p.as_vec3())).as_dvec3();
                    (-g).normalize()
                        .dot(radial)
                        .clamp(-1.0, 1.0)
                        .acos()
                        .to_degrees()
                })
                .collect();
            let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
            let max = errors.iter().cloned().fold(0.0, f64::max);
            (rms, max)
        };
        let (linear, cubic, sharp) = (
            error_deg(Interpolation::Linear),
            error_deg(Interpolation::Cubic),
            error_deg(Interpolation::CubicInterpolating),
        );
        // Measured (rms, max): trilinear 2.2° and 4.1°, cubic 0.37° and 0.76°. The
        // interpolating spline's own gradient measured 0.94° and 1.78°; it is shaded by the
        // voxels' spline's, the same directions.
        assert!(cubic.0 < 0.25 * linear.0, "{linear:?} vs {cubic:?}");
        assert!(cubic.1 < 1.0, "{linear:?} vs {cubic:?}");
        assert_eq!(sharp, cubic);
    }

    /// Every preset and mode renders the abdomen CT to a picture with something in it.
    #[test]
    fn every_preset_and_mode_renders_the_abdomen() {
        let vol = abdomen();
        let cam = volume_camera(&vol, 48.0 / 36.0);
        let spread = |img: &Image| {
            let l: Vec<f32> = img.pixels.iter().map(|p| p.x + p.y + p.z).collect();
            let mean = l.iter().sum::<f32>() / l.len() as f32;
            (l.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / l.len() as f32).sqrt()
        };
        let mut opt = DvrOptions {
            width: 48,
            height: 36,
            ..Default::default()
        };
        for p in TfPreset::ALL {
            let (img, _) = render_volume(&vol, &p.function(), &opt, &cam);
            assert!(spread(&img) > 0.05, "{}: a flat picture", p.name());
        }
        for mode in [DvrMode::Mip, DvrMode::Average, DvrMode::Iso] {
            opt.mode = mode;
            let (img, _) = render_volume(&vol, &grey(0.0), &opt, &cam);
            assert!(spread(&img) > 0.05, "{}: a flat picture", mode.name());
        }
    }

    /// The world gradient of a linear ramp on an oblique, anisotropic grid is the ramp's slope;
    /// on a sheared grid (a gantry-tilted CT's: columns tilted 18.5°, the third axis along the
    /// table) too.
    #[test]
    fn gradient_is_per_mm_in_world_space() {
        let (c, s) = (0.6f64, 0.8f64);
        let (tc, ts) = (18.5f64.to_radians().cos(), 18.5f64.to_radians().sin());
        for direction in [
            [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.0, tc, 0.0], [0.0, -ts, 1.0]],
        ] {
            let mut vol = volume([12, 12, 12], [0.7, 1.3, 2.1], |_, _, _| 0.0);
            vol.direction = direction;
            vol.origin = [5.0, -3.0, 2.0];
            let slope = raystream_math::DVec3::new(3.0, -2.0, 5.0);
            for k in 0..12 {
                for j in 0..12 {
                    for i in 0..12 {
                        let p = vol.index_to_world(raystream_math::DVec3::new(
                            i as f64, j as f64, k as f64,
                        ));
                        vol.data[i + 12 * (j + 12 * k)] = slope.dot(p) as f32;
                    }
                }
            }
            let m = Marcher::new(&vol, None);
            let g = m.gradient(Vec3::new(5.3, 6.1, 4.7));
            assert!((g - slope.as_vec3()).length() < 1e-3, "{g} vs {slope}");
        }
    }

    /// Every mode's pixels marched in x86-64-v3 ([`CpuVolume::in_isa`]) are the baseline's, bit
    /// for bit, and so are their sample counts: the abdomen CT in dvr (each interpolation, a
    /// crop, shadows through the light grid), cinematic (each interpolation), mip, minip,
    /// average, iso and slice. Under `CI=true` an x86-64 machine must have x86-64-v3, so that
    /// the copy is tested there.
    #[test]
    fn volume_pixels_are_the_same_in_every_instruction_set() {
        let vol = abdomen();
        let cam = volume_camera(&vol, 1.25);
        let base = DvrOptions {
            width: 40,
            height: 32,
            ..Default::default()
        };
        let crop = Some([Vec3::splat(-400.0), Vec3::new(40.0, 400.0, 400.0)]);
        let mut runs = Vec::new();
        for interpolation in [
            Interpolation::Linear,
            Interpolation::Cubic,
            Interpolation::CubicInterpolating,
        ] {
            for (mode, preset) in [
                (DvrMode::Dvr, TfPreset::CtBones),
                (DvrMode::Dvr, TfPreset::CtMuscle),
                (DvrMode::Cinematic, TfPreset::CtBones),
                (DvrMode::Mip, TfPreset::MipBone),
                (DvrMode::MinIp, TfPreset::CtBone),
                (DvrMode::Average, TfPreset::CtBone),
                (DvrMode::Iso, TfPreset::CtBone),
                (DvrMode::Slice, TfPreset::CtBone),
            ] {
                let opt = DvrOptions {
                    mode,
                    interpolation,
                    spp: 4,
                    shadows: preset == TfPreset::CtBones,
                    crop: (preset == TfPreset::CtMuscle).then_some(crop).flatten(),
                    ..base
                };
                runs.push((preset, opt));
            }
        }
        let isas = crate::tests::isas();
        for (preset, opt) in runs {
            let tf = preset.function();
            let what = format!(
                "{} {} {:?}",
                opt.mode.name(),
                preset.name(),
                opt.interpolation
            );
            let frames: Vec<(Image, DvrStats)> = isas
                .iter()
                .map(|&isa| CpuVolume::new(&vol, &tf).in_isa(isa).render(&opt, &cam))
                .collect();
            let (first, stats) = &frames[0];
            assert!(stats.samples > 0, "{what}");
            let bits = crate::tests::pixel_bits;
            for ((im, s), isa) in frames.iter().zip(&isas).skip(1) {
                assert!(
                    bits(im) == bits(first),
                    "{what}: {} differs from {}",
                    isa.name(),
                    isas[0].name()
                );
                assert_eq!(s.samples, stats.samples, "{what}: {}", isa.name());
            }
        }
    }

    /// [`cell_exit`] as it was written first: the cell by a conversion to `usize`, each axis's
    /// exit behind a branch on its direction's sign. The fast form must give the same bits.
    fn cell_exit_plain(
        p: Vec3,
        t: f32,
        d_idx: Vec3,
        cell: usize,
        cells: [usize; 3],
    ) -> (usize, f32) {
        let b = [0, 1, 2].map(|a| ((p[a].max(0.0) as usize) / cell).min(cells[a] - 1));
        let mut t_exit = f32::INFINITY;
        for a in 0..3 {
            if d_idx[a] == 0.0 {
                continue;
            }
            let bound = if d_idx[a] > 0.0 {
                (b[a] + 1) * cell
            } else {
                b[a] * cell
            } as f32;
            t_exit = t_exit.min(t + (bound - p[a]) / d_idx[a]);
        }
        (b[0] + cells[0] * (b[1] + cells[1] * b[2]), t_exit)
    }

    /// The cell walk of empty-space skipping and of cinematic tracking gives the plain form's
    /// cell and exit, bit for bit, inside and around the grid, on cell faces, past u32's range
    /// and at NaN, ±0 and ±∞, along every axis, diagonals and axis-parallel rays.
    #[test]
    fn cell_exits_are_the_plain_walks() {
        let mut rng = crate::tests::XorShift(0x9e37_79b9_7f4a_7c15);
        let mut next = move || rng.next_u64();
        let special = [
            0.0,
            -0.0,
            4.0,
            8.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            4.294_967e9,
            1e20,
            -1e20,
            -3.5,
        ];
        let coordinate = |next: &mut dyn FnMut() -> u64| -> f32 {
            let r = next();
            match r % 4 {
                0 => special[(r >> 8) as usize % special.len()],
                1 => ((r >> 8) % 40) as f32,
                _ => ((r >> 8) % 1_000_000) as f32 / 1e4 - 10.0,
            }
        };
        let mut compared = 0;
        for cell in [1usize, 4, 8] {
            for cells in [[1, 1, 1], [3, 5, 7], [30, 26, 28]] {
                for _ in 0..20_000 {
                    let p = Vec3::new(
                        coordinate(&mut next),
                        coordinate(&mut next),
                        coordinate(&mut next),
                    );
                    let d = Vec3::new(
                        coordinate(&mut next) / 7.0,
                        coordinate(&mut next) / 7.0,
                        coordinate(&mut next) / 7.0,
                    );
                    let t = coordinate(&mut next);
                    let (c, e) = cell_exit(p, t, d, cell, cells);
                    let (pc, pe) = cell_exit_plain(p, t, d, cell, cells);
                    assert!(
                        c == pc && e.to_bits() == pe.to_bits(),
                        "p {p} t {t} d {d} cell {cell} cells {cells:?}: ({c}, {e}) vs ({pc}, {pe})"
                    );
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, 180_000);
    }
}
