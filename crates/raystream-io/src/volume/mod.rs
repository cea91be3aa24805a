//! CT volumes: the [`Volume`] model (voxel values, spacing in mm, origin and orientation in the
//! DICOM patient system LPS) and its readers — DICOM series, NIfTI-1/2, NRRD, MetaImage, legacy
//! VTK image data, and raw files named by their size and type.
//!
//! World coordinates are **LPS millimetres**, as ITK/SimpleITK report them: `x` grows to the
//! patient's left, `y` to posterior, `z` to superior (head). A voxel index `(i, j, k)` (x fastest
//! in memory) maps to `p_world = origin + direction · (spacing ⊙ (i, j, k))`; `origin` is the centre
//! of voxel (0, 0, 0) and the columns of `direction` are the unit directions of the i, j, k axes.
//!
//! Every reader checks a header's claims (dimensions, spacing, direction) before allocating, caps
//! the voxel count at [`MAX_VOXELS`], reads at most the bytes the header implies, and names the
//! file in every error ([`VolumeError`]).

pub(crate) mod dicom;
mod mask_folder;
mod mha;
mod named_raw;
mod nifti;
mod nrrd;
pub(crate) mod raw;
mod segmentation;
mod slicer_seg;
mod structure_set;
mod vti;
mod vtk;

use std::path::{Path, PathBuf};

use raystream_math::DVec3;

pub use dicom::{
    DicomSeriesInfo, DicomStudy, SegmentLabel, SegmentTerms, SourceImage, list_dicom_series,
};
pub use structure_set::{
    RT_STRUCTURE_SET, RasterNotes, Roi, SegmentVoxels, StructureSet, WholeSegments,
    is_structure_set_file, is_structure_set_volume, whole_segments,
};

/// The largest volume raystream loads: 2³⁰ voxels (4 GiB of `f32`), e.g. 1024³ or 2048×2048×256.
pub const MAX_VOXELS: u64 = 1 << 30;

/// What the voxel values mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueUnit {
    /// CT attenuation in Hounsfield units (DICOM CT after RescaleSlope/Intercept, CT NIfTI).
    Hounsfield,
    /// Values whose unit the file does not state (e.g. 8-bit scientific-visualisation scans).
    Unknown,
}

/// The file format a volume came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VolumeFormat {
    Dicom,
    Nifti,
    Nrrd,
    MetaImage,
    /// Legacy VTK image data (`DATASET STRUCTURED_POINTS`).
    Vtk,
    /// VTK XML image data (`.vti`).
    VtkXml,
    /// Raw voxels named by their size and type: `NAME_WxHxD_TYPE.raw`.
    Raw,
}

impl VolumeFormat {
    /// The format named by a path: a directory is a DICOM series (or a folder of NIfTI masks,
    /// which [`load_volume`] reads as one label map); files go by extension
    /// (`.nii`, `.nii.gz`, `.nrrd`, `.nhdr`, `.mha`, `.mhd`, `.vtk`, `.vti`, `.raw`, `.raw.gz`,
    /// `.dcm`).
    pub fn from_path(path: &Path) -> Option<Self> {
        if path.is_dir() {
            return Some(Self::Dicom);
        }
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        if name.ends_with(".nii") || name.ends_with(".nii.gz") {
            Some(Self::Nifti)
        } else if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
            Some(Self::Nrrd)
        } else if name.ends_with(".mha") || name.ends_with(".mhd") {
            Some(Self::MetaImage)
        } else if name.ends_with(".vtk") {
            // Legacy VTK holds volumes (image data) and meshes (polygons): the mesh reader
            // takes the polygons.
            let mesh = crate::vtk_legacy::dataset_of(path).is_some_and(|d| d == "POLYDATA");
            (!mesh).then_some(Self::Vtk)
        } else if name.ends_with(".vti") {
            Some(Self::VtkXml)
        } else if name.ends_with(".raw") || name.ends_with(".raw.gz") {
            Some(Self::Raw)
        } else if crate::encapsulated_stl::is_encapsulated_stl(path) {
            // A 3D model filed as DICOM: a mesh.
            None
        } else if name.ends_with(".dcm") || name.ends_with(".zip") {
            // A ZIP: a DICOM study as a PACS or a web viewer hands it out.
            Some(Self::Dicom)
        } else if has_dicom_preamble(path) {
            // A DICOM file without the extension, as on a CD (DICOM/ST000/SE000/IM0000).
            Some(Self::Dicom)
        } else {
            None
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Dicom => "dicom",
            Self::Nifti => "nifti",
            Self::Nrrd => "nrrd",
            Self::MetaImage => "metaimage",
            Self::Vtk => "vtk",
            Self::VtkXml => "vti",
            Self::Raw => "raw",
        }
    }
}

/// Whether the file at `path` starts as a DICOM Part 10 file: a 128-byte preamble, then "DICM".
fn has_dicom_preamble(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|_| &head[128..] == b"DICM")
}

/// Whether `path` names something [`load_volume`] reads (a directory, a volume extension, a
/// ZIP, or a DICOM file by its preamble).
pub fn is_volume_path(path: &Path) -> bool {
    VolumeFormat::from_path(path).is_some()
}

/// Which image of a file or folder [`load_volume`] reads.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VolumeSelect {
    /// DICOM: the SeriesInstanceUID (default: the series with the most slices).
    pub series: Option<String>,
    /// The temporal position (phase) of a 4-D acquisition, from 1, in increasing order of the
    /// file's own numbering: a NIfTI's volumes along its fourth axis (and any further ones), a
    /// DICOM series' TemporalPositionIdentifier (0020,0100), an enhanced CT's
    /// TemporalPositionIndex (0020,9128). Default: the first, with a warning when there are
    /// more. Legacy VTK and raw files are 3-D: phase 1.
    pub phase: Option<usize>,
}

impl VolumeSelect {
    /// The series `uid` (if any), its first phase.
    pub fn series(uid: Option<&str>) -> Self {
        VolumeSelect {
            series: uid.map(str::to_string),
            phase: None,
        }
    }
}

/// Which temporal position (phase) of a 4-D acquisition a volume is: `index` of `count`, from 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Phase {
    pub index: usize,
    pub count: usize,
}

impl Default for Phase {
    /// A 3-D volume: phase 1 of 1.
    fn default() -> Self {
        Phase { index: 1, count: 1 }
    }
}

impl Phase {
    /// The phase `requested` (from 1; `None`: the first) of `count` in `path`, or an error
    /// naming the phases there are; a warning when the first of several is taken by default.
    pub(crate) fn pick(
        path: &Path,
        requested: Option<usize>,
        count: usize,
        warnings: &mut Vec<String>,
    ) -> Result<Phase, VolumeError> {
        match requested {
            Some(k) if k == 0 || k > count => Err(VolumeError::invalid(
                path,
                if count == 1 {
                    format!(
                        "phase {k} requested, but the image has one temporal position (phase 1)"
                    )
                } else {
                    format!(
                        "phase {k} requested, but the image has {count} temporal positions (phases 1 to {count})"
                    )
                },
            )),
            Some(k) => Ok(Phase { index: k, count }),
            None => {
                if count > 1 {
                    warnings.push(format!(
                        "{count} temporal positions (phases) in the image; reading phase 1; pick another with --phase K"
                    ));
                }
                Ok(Phase { index: 1, count })
            }
        }
    }
}

/// What went wrong reading a volume, always with the file (or folder) it came from.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// The file could not be read or written. (The I/O error is in the message, not a
    /// `source`: a chain printed in full would say it twice.)
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

impl VolumeError {
    pub fn invalid(path: &Path, problem: impl Into<String>) -> Self {
        VolumeError::Invalid {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }
    pub fn io(path: &Path, error: std::io::Error) -> Self {
        VolumeError::Io {
            path: path.to_path_buf(),
            error,
        }
    }
}

/// A scalar volume on a regular grid in LPS millimetres.
#[derive(Clone, Debug)]
pub struct Volume {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Voxel spacing along i, j, k in millimetres (all > 0).
    pub spacing: [f64; 3],
    /// Centre of voxel (0, 0, 0) in LPS millimetres.
    pub origin: [f64; 3],
    /// Row-major 3×3; column c is the unit LPS direction of index axis c (as SimpleITK's
    /// `GetDirection`).
    pub direction: [[f64; 3]; 3],
    /// `dims[0]·dims[1]·dims[2]` values, i fastest, then j, then k.
    pub data: Vec<f32>,
    pub unit: ValueUnit,
    pub format: VolumeFormat,
    /// For DICOM: the series read, and the others found in the folder.
    pub series: Option<DicomSeriesInfo>,
    /// The segments a label file names, each with its number (its voxels' value here), name
    /// and colour: a DICOM Segmentation's, an RT Structure Set's structures, a 3D Slicer
    /// segmentation's (`.seg.nrrd`). Empty for an image.
    pub segments: Vec<SegmentLabel>,
    /// The temporal position (phase) of a 4-D acquisition this volume is, and how many the
    /// file or series holds (1 of 1 for a 3-D one).
    pub phase: Phase,
    /// Things a user should know (e.g. "sform and qform disagree; used sform").
    pub warnings: Vec<String>,
}

impl Volume {
    /// A CT of Hounsfield units `data` on a `dims` grid of `spacing` mm, voxel (0, 0, 0) at
    /// the origin and the index axes along L, P, S: a phantom's volume, as tests build them.
    pub fn hounsfield(dims: [usize; 3], spacing: [f64; 3], data: Vec<f32>) -> Volume {
        Volume {
            dims,
            spacing,
            origin: [0.0; 3],
            direction: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            data,
            unit: ValueUnit::Hounsfield,
            format: VolumeFormat::Nifti,
            series: None,
            segments: Vec::new(),
            warnings: Vec::new(),
            phase: Default::default(),
        }
    }

    pub fn voxel_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// The length of the grid's diagonal, mm: dims × spacing along each axis (the farthest a
    /// straight line runs through an unsheared grid).
    pub fn diagonal_mm(&self) -> f64 {
        (0..3)
            .map(|i| (self.dims[i] as f64 * self.spacing[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Whether `other` lies on this volume's grid, voxel for voxel: the same dimensions,
    /// origins within 10⁻³ mm, spacings within `spacing_rel` of this one's, and direction
    /// cosines within `direction`.
    pub fn same_grid(&self, other: &Volume, spacing_rel: f64, direction: f64) -> bool {
        self.dims == other.dims
            && (0..3).all(|a| {
                (other.origin[a] - self.origin[a]).abs() < 1e-3
                    && (other.spacing[a] - self.spacing[a]).abs() < spacing_rel * self.spacing[a]
                    && (0..3)
                        .all(|b| (other.direction[a][b] - self.direction[a][b]).abs() < direction)
            })
    }

    /// A voxel's volume, millilitres (the grid's cell, sheared or not).
    pub fn voxel_ml(&self) -> f64 {
        self.index_to_world_affine().matrix3.determinant().abs() / 1000.0
    }

    /// The value at voxel `(i, j, k)`; indices must be in range.
    #[inline]
    pub fn at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    /// Index space (voxel centres at integers) → LPS millimetres.
    pub fn index_to_world(&self, p_voxel: DVec3) -> DVec3 {
        let s = p_voxel * DVec3::from(self.spacing);
        let d = &self.direction;
        DVec3::new(
            self.origin[0] + d[0][0] * s.x + d[0][1] * s.y + d[0][2] * s.z,
            self.origin[1] + d[1][0] * s.x + d[1][1] * s.y + d[1][2] * s.z,
            self.origin[2] + d[2][0] * s.x + d[2][1] * s.y + d[2][2] * s.z,
        )
    }

    /// LPS millimetres → index space; the inverse of [`Volume::index_to_world`] (the direction
    /// matrix is inverted in general, so sheared grids work too).
    pub fn world_to_index(&self, p_world: DVec3) -> DVec3 {
        let m = raystream_math::DMat3::from_cols_array_2d(&self.direction).transpose();
        let s = m.inverse() * (p_world - DVec3::from(self.origin));
        s / DVec3::from(self.spacing)
    }

    /// The 4×4 index → LPS affine, column-major (glam), for callers that transform many points.
    pub fn index_to_world_affine(&self) -> raystream_math::DAffine3 {
        let m = raystream_math::DMat3::from_cols_array_2d(&self.direction).transpose()
            * raystream_math::DMat3::from_diagonal(DVec3::from(self.spacing));
        raystream_math::DAffine3::from_mat3_translation(m, DVec3::from(self.origin))
    }

    /// A lone slice (one DICOM image, a 2-D NIfTI: the grid holds one voxel along some axis)
    /// as the slab of tissue it images: along each such axis, two layers of the same values
    /// half a spacing either side of the slice, so that the box of voxel centres, which
    /// renderers march through and frame, is a spacing thick instead of a plane no ray
    /// samples. Anywhere in the slab the values are the slice's (interpolation between equal
    /// layers), and the plane through its middle is the slice itself. `None` where every axis
    /// holds two voxels or more.
    pub fn slab_of_lone_slices(&self) -> Option<Volume> {
        if self.dims.iter().all(|&n| n > 1) {
            return None;
        }
        let lone = self.dims.map(|n| n == 1);
        // Both layers of a doubled axis are the slice; the first lies half a spacing before it
        // along its axis's direction.
        Some(self.relayered(self.dims.map(|n| n.max(2)), lone, -0.5))
    }

    /// The volume on `dims`, which differs from its own along the axes `along` only: there,
    /// every voxel reads the volume's first layer, and the first voxel lies `shift` spacings
    /// from the volume's first.
    fn relayered(&self, dims: [usize; 3], along: [bool; 3], shift: f64) -> Volume {
        let src = |x: usize, a: usize| if along[a] { 0 } else { x };
        let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(self.at(src(i, 0), src(j, 1), src(k, 2)));
                }
            }
        }
        let shift = along.map(|on| if on { shift } else { 0.0 });
        Volume {
            dims,
            origin: self.index_to_world(DVec3::from(shift)).to_array(),
            data,
            warnings: self.warnings.clone(),
            series: self.series.clone(),
            segments: self.segments.clone(),
            ..*self
        }
    }

    /// The lone slice a slab of [`Volume::slab_of_lone_slices`] was made from: along each
    /// axis of two layers holding the same values, one layer midway between them. `None` where
    /// no axis is such. (A two-slice volume whose slices are equal reads as a slab too: the
    /// field is the same.)
    pub fn lone_slice_of_slab(&self) -> Option<Volume> {
        let [nx, ny, _] = self.dims;
        let layers_equal = |a: usize| {
            self.dims[a] == 2
                && (0..self.data.len()).all(|n| {
                    let ijk = [n % nx, (n / nx) % ny, n / (nx * ny)];
                    ijk[a] == 1 || {
                        let mut other = ijk;
                        other[a] = 1;
                        self.data[n] == self.at(other[0], other[1], other[2])
                    }
                })
        };
        let lone: [bool; 3] = std::array::from_fn(layers_equal);
        if !lone.contains(&true) {
            return None;
        }
        let dims: [usize; 3] = std::array::from_fn(|a| if lone[a] { 1 } else { self.dims[a] });
        Some(self.relayered(dims, lone, 0.5))
    }

    /// The same field on a grid of `dims` voxels (each ≥ 2, or 1 where the volume has 1)
    /// spanning the same voxel-centre box: same origin and direction, spacing scaled so that
    /// the first and last centres stay put; values by trilinear interpolation. Used to bring a
    /// CT to the benchmark's 512³.
    pub fn resample(&self, dims: [usize; 3]) -> Volume {
        use rayon::prelude::*;
        let [nx, ny, nz] = self.dims;
        let scale: [f64; 3] = std::array::from_fn(|a| {
            if dims[a] > 1 {
                (self.dims[a] - 1) as f64 / (dims[a] - 1) as f64
            } else {
                0.0
            }
        });
        // Per output index along an axis: the lower source index and the weight of the next.
        let axis = |a: usize| -> Vec<(usize, f32)> {
            (0..dims[a])
                .map(|i| {
                    let x = i as f64 * scale[a];
                    let lo = (x.floor() as usize).min(self.dims[a].saturating_sub(2));
                    (lo, (x - lo as f64) as f32)
                })
                .collect()
        };
        let (ax, ay, az) = (axis(0), axis(1), axis(2));
        let mut data = vec![0f32; dims[0] * dims[1] * dims[2]];
        data.par_chunks_mut(dims[0] * dims[1])
            .zip(&az)
            .for_each(|(slab, &(k, fz))| {
                let k1 = (k + 1).min(nz - 1);
                for (row, &(j, fy)) in slab.chunks_mut(dims[0]).zip(&ay) {
                    let j1 = (j + 1).min(ny - 1);
                    for (v, &(i, fx)) in row.iter_mut().zip(&ax) {
                        let i1 = (i + 1).min(nx - 1);
                        let l = |a: f32, b: f32, w: f32| a + (b - a) * w;
                        let plane = |k: usize| {
                            l(
                                l(self.at(i, j, k), self.at(i1, j, k), fx),
                                l(self.at(i, j1, k), self.at(i1, j1, k), fx),
                                fy,
                            )
                        };
                        *v = l(plane(k), plane(k1), fz);
                    }
                }
            });
        Volume {
            dims,
            spacing: std::array::from_fn(|a| {
                if dims[a] > 1 {
                    self.spacing[a] * scale[a]
                } else {
                    self.spacing[a]
                }
            }),
            data,
            warnings: Vec::new(),
            series: None,
            segments: Vec::new(),
            ..*self
        }
    }

    /// Smallest and largest value (NaN voxels ignored); `None` for an all-NaN volume.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        use rayon::prelude::*;
        self.data
            .par_chunks(1 << 16)
            .map(|c| {
                c.iter()
                    .filter(|v| !v.is_nan())
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                        (lo.min(v), hi.max(v))
                    })
            })
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            )
            .into_finite()
    }

    /// Reads infinite voxel values (a float file's, or a double's beyond f32's range) as
    /// missing values, NaN, as a float file marks the voxels it has no value for; a warning
    /// says how many. An infinite value is no measurement, and it sent the CPU's cinematic
    /// paths off along a direction of NaN, tracked without end.
    pub(crate) fn infinities_missing(&mut self) {
        use rayon::prelude::*;
        let count: usize = self
            .data
            .par_chunks_mut(1 << 16)
            .map(|c| {
                c.iter_mut()
                    .filter(|v| v.is_infinite())
                    .map(|v| *v = f32::NAN)
                    .count()
            })
            .sum();
        if count > 0 {
            self.warnings.push(format!(
                "{count} voxel value{} infinite: read as missing (NaN)",
                if count == 1 { " is" } else { "s are" }
            ));
        }
    }

    /// Checks the invariants every reader guarantees; readers call it last.
    pub(crate) fn check(&self, path: &Path) -> Result<(), VolumeError> {
        check_geometry(path, self.dims, self.spacing, self.origin, &self.direction)?;
        if self.data.len() != self.voxel_count() {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "{} voxel values for dimensions {:?}",
                    self.data.len(),
                    self.dims
                ),
            ));
        }
        Ok(())
    }
}

trait IntoFinite {
    fn into_finite(self) -> Option<(f32, f32)>;
}
impl IntoFinite for (f32, f32) {
    fn into_finite(self) -> Option<(f32, f32)> {
        (self.0 <= self.1).then_some(self)
    }
}

/// How far from the origin of patient coordinates a volume's grid may reach: a kilometre. No
/// scanner's coordinates come near (a CT's lie within a few metres of its isocentre), so a
/// header beyond it is corrupt; and there f32 positions are still good to 1/16 mm, while the
/// renderings drift apart further out (the CPU and GPU differ at 10⁹ mm).
pub const MAX_GRID_REACH_MM: f64 = 1e6;
/// The smallest voxel spacing a volume may have, mm: a picometre, far below any imaging's
/// (electron microscopy's are nanometres); below it the spacing is a corrupt header's, and
/// as an f32 it would vanish into denormals.
pub const MIN_SPACING_MM: f64 = 1e-9;

/// Dimensions within [`MAX_VOXELS`], spacing finite and at least [`MIN_SPACING_MM`], origin
/// finite, the grid within ±[`MAX_GRID_REACH_MM`], direction finite with unit, linearly
/// independent columns.
/// Called on header values before any allocation, and again on the finished volume.
pub(crate) fn check_geometry(
    path: &Path,
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: &[[f64; 3]; 3],
) -> Result<(), VolumeError> {
    voxel_count(path, dims)?;
    if spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
        return Err(VolumeError::invalid(
            path,
            format!("voxel spacing {spacing:?} mm is not finite and positive"),
        ));
    }
    if spacing.iter().any(|s| *s < MIN_SPACING_MM) {
        return Err(VolumeError::invalid(
            path,
            format!(
                "voxel spacing {spacing:?} mm: below {MIN_SPACING_MM:e} mm (a picometre), no voxel of any imaging (a corrupt header?)"
            ),
        ));
    }
    if origin.iter().any(|o| !o.is_finite()) {
        return Err(VolumeError::invalid(
            path,
            format!("origin {origin:?} is not finite"),
        ));
    }
    // Unit direction columns: no point of the grid lies further from the origin than this.
    let reach = origin.iter().fold(0.0f64, |a, o| a.max(o.abs()))
        + (0..3).map(|i| spacing[i] * dims[i] as f64).sum::<f64>();
    if reach > MAX_GRID_REACH_MM {
        return Err(VolumeError::invalid(
            path,
            format!(
                "the grid reaches {reach:.3e} mm from the origin, beyond ±{MAX_GRID_REACH_MM:e} mm (a corrupt header?)"
            ),
        ));
    }
    let m = raystream_math::DMat3::from_cols_array_2d(direction).transpose();
    let det = m.determinant();
    if !det.is_finite() || det.abs() < 1e-6 {
        return Err(VolumeError::invalid(
            path,
            format!("direction matrix {direction:?} is not finite or is singular"),
        ));
    }
    Ok(())
}

/// `dims` product, refused if zero or over [`MAX_VOXELS`].
pub(crate) fn voxel_count(path: &Path, dims: [usize; 3]) -> Result<usize, VolumeError> {
    let n = dims
        .iter()
        .try_fold(1u64, |acc, &d| acc.checked_mul(d as u64));
    match n {
        Some(n) if n > 0 && n <= MAX_VOXELS => Ok(n as usize),
        _ => Err(VolumeError::invalid(
            path,
            format!(
                "dimensions {dims:?} are empty or exceed the {MAX_VOXELS}-voxel limit (a corrupt header?)"
            ),
        )),
    }
}

/// Reads a volume: a folder is a DICOM series (the largest, or the one `select` names) or, holding
/// NIfTI files and no DICOM, a folder of masks read as one label map; files go
/// by extension; of a 4-D acquisition, the phase `select` names.
pub fn load_volume(path: &Path, select: &VolumeSelect) -> Result<Volume, VolumeError> {
    let format = VolumeFormat::from_path(path).ok_or_else(|| {
        let polygons = crate::vtk_legacy::dataset_of(path).is_some_and(|d| d == "POLYDATA");
        VolumeError::invalid(
            path,
            if polygons {
                "a .vtk of polygons (DATASET POLYDATA) is a mesh, not a volume: a volume's .vtk holds image data (STRUCTURED_POINTS)"
            } else if crate::MeshFormat::from_path(path) == Some(crate::MeshFormat::VtkXml) {
                "a .vtp is VTK's polygonal data, a mesh, not a volume: a volume is VTK image data (.vti)"
            } else {
                "unsupported volume format (expected a DICOM folder, file or .zip, .nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd, .vti, a .vtk of image data, or NAME_WxHxD_TYPE.raw)"
            },
        )
    })?;
    if !path.exists() {
        return Err(VolumeError::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
        ));
    }
    let mut volume = match format {
        VolumeFormat::Dicom if mask_folder::is_mask_folder(path) => mask_folder::read(path)?,
        VolumeFormat::Dicom => dicom::load(path, select)?,
        VolumeFormat::Raw => named_raw::load(path, select.phase)?,
        VolumeFormat::Vtk => vtk::parse(&raw::read_file(path)?, path, select.phase)?,
        VolumeFormat::VtkXml => vti::parse(&raw::read_file(path)?, path, select.phase)?,
        file_format => {
            let parse = match file_format {
                VolumeFormat::Nifti => nifti::parse,
                VolumeFormat::Nrrd => nrrd::parse,
                _ => mha::parse,
            };
            parse(&raw::read_file(path)?, path, select.phase)?
        }
    };
    volume.infinities_missing();
    volume.check(path)?;
    Ok(volume)
}

/// Parses NIfTI bytes held in memory (an embedded volume), its volume `phase` (from 1; `None`:
/// the first) if 4-D; `path` names it in errors.
pub fn parse_nifti(bytes: &[u8], path: &Path, phase: Option<usize>) -> Result<Volume, VolumeError> {
    let mut v = nifti::parse(bytes, path, phase)?;
    v.infinities_missing();
    v.check(path)?;
    Ok(v)
}

/// Direction-matrix helpers shared by the readers.
pub(crate) fn unit_columns(m: [[f64; 3]; 3]) -> ([[f64; 3]; 3], [f64; 3]) {
    let mut dir = m;
    let mut len = [0.0; 3];
    for c in 0..3 {
        len[c] = (m[0][c] * m[0][c] + m[1][c] * m[1][c] + m[2][c] * m[2][c]).sqrt();
        for row in dir.iter_mut() {
            row[c] /= len[c];
        }
    }
    (dir, len)
}

/// Whether the direction columns are orthonormal to `tol` (a sheared grid is not).
pub(crate) fn is_orthonormal(d: &[[f64; 3]; 3], tol: f64) -> bool {
    (0..3).all(|a| {
        (0..3).all(|b| {
            let dot: f64 = (0..3).map(|r| d[r][a] * d[r][b]).sum();
            (dot - if a == b { 1.0 } else { 0.0 }).abs() < tol
        })
    })
}

#[cfg(test)]
mod multiframe_tests;
#[cfg(test)]
mod tests;
