//! CT volume processing: isosurface extraction ([`extract_isosurface`]) and the HU presets
//! ([`Preset`]) that `raystream iso` and `raystream render VOLUME` use.

pub mod auto;
pub mod body;
pub mod calcium;
mod cases;
pub mod centreline;
pub mod clusters;
pub mod distance;
mod grid;
mod islands;
mod marching;
pub mod segments;
mod stats;
mod tf;

pub use grid::{clamp_to_grid, trilinear, trilinear_in};
pub use islands::{Islands, KeepIslands, KeepSurface};
pub use marching::{
    IsoSurface, Simplified, SimplifyRound, departure, distances, extract_isosurface,
    extract_isosurface_keeping, not_manifold, pinched_vertices, point_triangle_distance, simplify,
    simplify_reporting, smooth,
};
pub use stats::{
    Below, Densitometry, Inflation, RegionStats, Sex, densitometry, mass_g, predicted_tlc_ml,
    region_stats,
};
pub use tf::{Shading, TfPreset, TransferFunction};

/// How a volume is sampled between voxel centres (raystream-cpu's `sampling` module evaluates
/// them, and says why the cubic ones exist).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Interpolation {
    /// Trilinear: the 2³ voxels around the point; the gradient by central differences one
    /// voxel apart.
    #[default]
    Linear,
    /// The uniform cubic B-spline over the 4³ voxels around the point, and its analytic
    /// gradient: smooth (C²), but it approximates the voxels rather than passing through them,
    /// a light blur (σ ≈ 0.58 voxel) that quietens noise and lowers thin structures' peaks.
    Cubic,
    /// The interpolating cubic B-spline: the same spline over prefiltered coefficients, which
    /// passes through every voxel's value (as smooth, no blur; it may ring a little past sharp
    /// edges, and it keeps the noise).
    CubicInterpolating,
}

impl Interpolation {
    pub const ALL: [Interpolation; 3] = [
        Interpolation::Linear,
        Interpolation::Cubic,
        Interpolation::CubicInterpolating,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Interpolation::Linear => "linear",
            Interpolation::Cubic => "cubic",
            Interpolation::CubicInterpolating => "cubic-interpolating",
        }
    }

    /// Whether the spline reads prefiltered coefficients rather than the voxels themselves.
    pub fn prefiltered(self) -> bool {
        self == Interpolation::CubicInterpolating
    }

    /// The number the GPU kernels' parameters hold: 0 trilinear, 1 the cubic B-spline of the
    /// texture's one channel, 2 the cubic B-spline of its first channel (the interpolating
    /// spline's coefficients), shaded by the gradient of its second (the voxels': see
    /// `raystream_cpu::dvr::Marcher::gradient`).
    pub fn kernel_code(self) -> u32 {
        match self {
            Interpolation::Linear => 0,
            Interpolation::Cubic => 1,
            Interpolation::CubicInterpolating => 2,
        }
    }
}

/// Bone thresholds in Hounsfield units.
///
/// - `Bone` 300 HU: cortical and most trabecular bone while excluding contrast-free soft
///   tissue (≤ ~100 HU); the usual bone threshold in CT volume rendering (e.g. 3D Slicer's
///   "CT-Bone" volume-rendering preset ramps up from ~150–300 HU; Hounsfield-unit tables list
///   cancellous bone at +300…+400 and cortical bone at +500…+1900).
/// - `ThinBone` 226 HU: the lower bone threshold of 3D Slicer's Segment Editor "Threshold"
///   bone default (226 HU), keeping thin structures (skull base, ribs, osteoporotic vertebrae).
/// - `Contrast` 400 HU: contrast-enhanced scans, where iodinated vessels reach 200–400 HU and
///   would otherwise merge with bone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    Bone,
    ThinBone,
    Contrast,
}

impl Preset {
    pub fn hu(self) -> f32 {
        match self {
            Preset::Bone => 300.0,
            Preset::ThinBone => 226.0,
            Preset::Contrast => 400.0,
        }
    }
}

#[cfg(test)]
mod tests;
