//! A folder of binary masks on one grid, a NIfTI file a structure: how TotalSegmentator hands
//! out its segmentation (`segmentations/aorta.nii.gz`, `liver.nii.gz`, … 117 of them, most
//! empty on any one CT), and how many other pipelines do. It is read as a label map: label n
//! for the n-th file in name order, named by the file (its name without `.nii.gz`). A voxel
//! two masks hold takes the first's label; [`whole`] then gives each mask whole, as a
//! DICOM Segmentation's overlapping segments are.

use std::path::{Path, PathBuf};

use super::structure_set::{SegmentVoxels, WholeSegments};
use super::{Phase, SegmentLabel, ValueUnit, Volume, VolumeError, VolumeFormat, nifti, raw};

/// How a warning of [`read`] begins where masks overlap: [`whole`] reads them again then.
const OVERLAP: &str = "masks overlap";

/// Whether `path` is a folder of NIfTI masks: a folder holding a `.nii` or `.nii.gz` file
/// and no DICOM file (which makes it a DICOM series' folder).
pub(crate) fn is_mask_folder(path: &Path) -> bool {
    path.is_dir() && mask_files(path).is_ok_and(|f| !f.is_empty()) && !holds_dicom(path)
}

/// Whether the folder `dir` holds a DICOM file (by its name or its preamble), its NIfTI files
/// apart.
fn holds_dicom(dir: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return false;
    };
    entries.flatten().map(|e| e.path()).any(|p| {
        p.is_file()
            && !is_nifti_name(&p)
            && super::VolumeFormat::from_path(&p) == Some(VolumeFormat::Dicom)
    })
}

fn is_nifti_name(path: &Path) -> bool {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let name = name.to_ascii_lowercase();
    name.ends_with(".nii") || name.ends_with(".nii.gz")
}

/// The folder's NIfTI files, in name order.
fn mask_files(dir: &Path) -> Result<Vec<PathBuf>, VolumeError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| VolumeError::io(dir, e))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file() && is_nifti_name(p))
        .collect();
    files.sort();
    Ok(files)
}

/// A mask's name: its file's, without `.nii` or `.nii.gz`.
fn mask_name(file: &Path) -> String {
    let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let lower = name.to_ascii_lowercase();
    let cut = if lower.ends_with(".nii.gz") { 7 } else { 4 };
    name[..name.len() - cut].to_string()
}

/// One mask file read: a NIfTI volume of 0s and 1s on `grid`'s grid (the first mask's),
/// refused otherwise, naming the file.
fn read_mask(file: &Path, grid: Option<&Volume>) -> Result<Volume, VolumeError> {
    let v = nifti::parse(&raw::read_file(file)?, file, None)?;
    v.check(file)?;
    if let Some(g) = grid {
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol;
        let same = v.dims == g.dims
            && (0..3).all(|a| close(v.spacing[a], g.spacing[a], 1e-4 * g.spacing[a]))
            && (0..3).all(|a| close(v.origin[a], g.origin[a], 1e-3))
            && (0..3).all(|r| (0..3).all(|c| close(v.direction[r][c], g.direction[r][c], 1e-4)));
        if !same {
            return Err(VolumeError::invalid(
                file,
                format!(
                    "a mask of this folder on another grid ({} x {} x {} voxels of {:?} mm at {:?}) than its first ({} x {} x {} of {:?} mm at {:?}): a folder's masks share their CT's grid",
                    v.dims[0],
                    v.dims[1],
                    v.dims[2],
                    v.spacing,
                    v.origin,
                    g.dims[0],
                    g.dims[1],
                    g.dims[2],
                    g.spacing,
                    g.origin
                ),
            ));
        }
    }
    if let Some(&x) = v.data.iter().find(|&&x| x != 0.0 && x != 1.0) {
        return Err(VolumeError::invalid(
            file,
            format!(
                "holds the value {x}: a folder of masks holds 0 and 1 in each (is a CT or a label map among them?)"
            ),
        ));
    }
    Ok(v)
}

/// The folder `dir` of masks as a label map (the module says how).
pub(crate) fn read(dir: &Path) -> Result<Volume, VolumeError> {
    let files = mask_files(dir)?;
    if files.len() >= u16::MAX as usize {
        return Err(VolumeError::invalid(
            dir,
            format!(
                "{} masks: a label map holds at most {}",
                files.len(),
                u16::MAX - 1
            ),
        ));
    }
    let mut labels: Option<Volume> = None;
    let mut overlaps = 0usize;
    let mut segments = Vec::with_capacity(files.len());
    for (n, file) in files.iter().enumerate() {
        let mask = read_mask(file, labels.as_ref())?;
        let label = (n + 1) as f32;
        let into = labels.get_or_insert_with(|| Volume {
            data: vec![0.0; mask.data.len()],
            unit: ValueUnit::Unknown,
            series: None,
            segments: Vec::new(),
            phase: Phase::default(),
            warnings: Vec::new(),
            ..mask.clone()
        });
        for (to, &m) in into.data.iter_mut().zip(&mask.data) {
            if m == 1.0 {
                if *to == 0.0 {
                    *to = label;
                } else {
                    overlaps += 1;
                }
            }
        }
        segments.push(SegmentLabel {
            number: (n + 1) as u16,
            label: mask_name(file),
            colour: None,
            terms: Default::default(),
        });
    }
    let mut v = labels.ok_or_else(|| VolumeError::invalid(dir, "no .nii or .nii.gz file"))?;
    v.format = VolumeFormat::Nifti;
    v.segments = segments;
    if overlaps > 0 {
        v.warnings.push(format!(
            "{OVERLAP}: {overlaps} voxels lie in two masks or more; in the label map each takes the first's label (in name order), and each mask is counted whole where segments are measured"
        ));
    }
    Ok(v)
}

/// Each mask of the folder `dir` whole, where its masks overlap (read again); `None` where
/// they do not (the label map holds each whole) or `labels` is not such a folder's.
pub(crate) fn whole(labels: &Volume, dir: &Path) -> Result<Option<WholeSegments>, VolumeError> {
    if !labels.warnings.iter().any(|w| w.starts_with(OVERLAP)) || !is_mask_folder(dir) {
        return Ok(None);
    }
    let [nx, ny, _] = labels.dims;
    let mut whole = WholeSegments::new();
    for (n, file) in mask_files(dir)?.iter().enumerate() {
        let mask = read_mask(file, Some(labels))?;
        let at = |v: usize| [v % nx, (v / nx) % ny, v / (nx * ny)];
        let held = || (mask.data.iter().enumerate()).filter(|&(_, &m)| m == 1.0);
        let Some((first, _)) = held().next() else {
            continue;
        };
        let (mut lo, mut hi) = (at(first), at(first));
        for (v, _) in held() {
            let ijk = at(v);
            lo = std::array::from_fn(|a| lo[a].min(ijk[a]));
            hi = std::array::from_fn(|a| hi[a].max(ijk[a]));
        }
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut s = SegmentVoxels {
            lo,
            dims,
            inside: vec![false; dims.iter().product()],
            voxels: 0,
        };
        for (v, _) in held() {
            let [i, j, k] = at(v);
            s.inside[(i - lo[0]) + dims[0] * ((j - lo[1]) + dims[1] * (k - lo[2]))] = true;
            s.voxels += 1;
        }
        whole.push(((n + 1) as u16, s));
    }
    Ok(Some(whole))
}
