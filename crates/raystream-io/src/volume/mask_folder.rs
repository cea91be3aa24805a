//! A folder of binary masks on one grid, a NIfTI file a structure: how TotalSegmentator hands
//! out its segmentation (`segmentations/aorta.nii.gz`, `liver.nii.gz`, … 117 of them, most
//! empty on any one CT), and how many other pipelines do. It is read as a label map: label n
//! for the n-th file in name order, named by the file (its name without `.nii.gz`). A voxel
//! two masks hold takes the first's label; [`whole`] then gives each mask whole, as a
//! DICOM Segmentation's overlapping segments are.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::raw::Scalar;
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

/// One mask file read: its grid (a volume without values) and the voxels it holds (of 0s
/// and 1s; other values are refused, naming the file). A mask of bytes (TotalSegmentator's)
/// is scanned as it is gunzipped, a chunk at a time: never held whole (78 MB for a CT of
/// 512 × 512 × 300), nor widened to f32.
fn read_mask(file: &Path) -> Result<(Volume, Vec<u32>), VolumeError> {
    let contents = raw::read_file(file)?;
    let (grid, x, mut r) = nifti::open(&contents, file, None)?;
    let refuse = |x: f32| {
        VolumeError::invalid(
            file,
            format!(
                "holds the value {x}: a folder of masks holds 0 and 1 in each (is a CT or a label map among them?)"
            ),
        )
    };
    let n = x.layout.inner;
    let of_bytes = x.scalar == Scalar::U8 && x.slope == 1.0 && x.intercept == 0.0;
    if !(of_bytes && x.layout.count == 1) {
        let values = x.values(&mut r, file)?;
        if let Some(&x) = values.iter().find(|&&x| x != 0.0 && x != 1.0) {
            return Err(refuse(x));
        }
        let held = (values.iter().enumerate())
            .filter(|&(_, &x)| x == 1.0)
            .map(|(n, _)| n as u32)
            .collect();
        return Ok((grid, held));
    }
    let mut held = Vec::new();
    raw::read_in_chunks(&mut r, n, CHUNK, file, nifti::VOXELS, |at, chunk| {
        // A run of 64 bytes at a time, OR-ed together (which vectorises): most are all 0.
        for (k, run) in chunk.chunks(64).enumerate() {
            match run.iter().fold(0u8, |m, &x| m | x) {
                0 => {}
                1 => held.extend(
                    (run.iter().enumerate())
                        .filter(|&(_, &x)| x == 1)
                        .map(|(m, _)| (at + k * 64 + m) as u32),
                ),
                _ => return Err(refuse(run.iter().copied().max().unwrap_or(2) as f32)),
            }
        }
        Ok(())
    })?;
    Ok((grid, held))
}

/// How many bytes of a mask are gunzipped and scanned at a time: a multiple of the scan's runs
/// of 64, small enough to stay in a core's cache.
const CHUNK: usize = 256 << 10;

/// Refused unless `mask` (read from `file`) lies on `first`'s grid.
fn same_grid(file: &Path, mask: &Volume, first: &Volume) -> Result<(), VolumeError> {
    if first.same_grid(mask, 1e-4, 1e-4) {
        return Ok(());
    }
    let (v, g) = (mask, first);
    Err(VolumeError::invalid(
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
    ))
}

/// How many masks are read at once: each holds the list of its voxels until it is laid in
/// the label map (a mask that is not of bytes, its values whole), so not one a thread of a
/// many-core machine.
const AT_ONCE: usize = 8;

/// Each mask of `files` read, in parallel [`AT_ONCE`] at a time, checked against the first's
/// grid (`first`, else the first file's), and handed to `take` in name order with its index;
/// the grid (`None` for no file).
fn each_mask(
    files: &[PathBuf],
    mut first: Option<Volume>,
    mut take: impl FnMut(usize, &Volume, Vec<u32>),
) -> Result<Option<Volume>, VolumeError> {
    for (b, batch) in files.chunks(AT_ONCE).enumerate() {
        let read: Vec<_> = batch.par_iter().map(|f| read_mask(f)).collect();
        for (i, (file, mask)) in batch.iter().zip(read).enumerate() {
            let (grid, held) = mask?;
            let first = first.get_or_insert_with(|| grid.clone());
            same_grid(file, &grid, first)?;
            take(b * AT_ONCE + i, first, held);
        }
    }
    Ok(first)
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
    let mut data: Vec<f32> = Vec::new();
    let mut overlaps = 0usize;
    let grid = each_mask(&files, None, |n, grid, held| {
        if data.is_empty() {
            data = vec![0.0; grid.voxel_count()];
        }
        for v in held {
            let to = &mut data[v as usize];
            if *to == 0.0 {
                *to = (n + 1) as f32;
            } else {
                overlaps += 1;
            }
        }
    })?
    .ok_or_else(|| VolumeError::invalid(dir, "no .nii or .nii.gz file"))?;
    let segments = (files.iter().enumerate())
        .map(|(n, file)| SegmentLabel {
            number: (n + 1) as u16,
            label: mask_name(file),
            colour: None,
            terms: Default::default(),
        })
        .collect();
    let mut warnings = grid.warnings.clone();
    if overlaps > 0 {
        warnings.push(format!(
            "{OVERLAP}: {overlaps} voxels lie in two masks or more; in the label map each takes the first's label (in name order), and each mask is counted whole where segments are measured"
        ));
    }
    Ok(Volume {
        data,
        unit: ValueUnit::Unknown,
        format: VolumeFormat::Nifti,
        series: None,
        segments,
        phase: Phase::default(),
        warnings,
        ..grid
    })
}

/// Each mask of the folder `dir` whole, where its masks overlap (read again); `None` where
/// they do not (the label map holds each whole) or `labels` is not such a folder's.
pub(crate) fn whole(labels: &Volume, dir: &Path) -> Result<Option<WholeSegments>, VolumeError> {
    if !labels.warnings.iter().any(|w| w.starts_with(OVERLAP)) || !is_mask_folder(dir) {
        return Ok(None);
    }
    let [nx, ny, _] = labels.dims;
    let at = |v: u32| {
        let v = v as usize;
        [v % nx, (v / nx) % ny, v / (nx * ny)]
    };
    let mut whole = WholeSegments::new();
    // The label map's grid, without cloning its values.
    let first = Volume {
        dims: labels.dims,
        spacing: labels.spacing,
        origin: labels.origin,
        direction: labels.direction,
        data: Vec::new(),
        unit: ValueUnit::Unknown,
        format: VolumeFormat::Nifti,
        series: None,
        segments: Vec::new(),
        phase: Phase::default(),
        warnings: Vec::new(),
    };
    each_mask(&mask_files(dir)?, Some(first), |n, _, held| {
        let Some(&one) = held.first() else {
            return;
        };
        let (mut lo, mut hi) = (at(one), at(one));
        for &v in &held {
            let ijk = at(v);
            lo = std::array::from_fn(|a| lo[a].min(ijk[a]));
            hi = std::array::from_fn(|a| hi[a].max(ijk[a]));
        }
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut s = SegmentVoxels {
            lo,
            dims,
            inside: vec![false; dims.iter().product()],
            voxels: held.len(),
        };
        for &v in &held {
            let [i, j, k] = at(v);
            s.inside[(i - lo[0]) + dims[0] * ((j - lo[1]) + dims[1] * (k - lo[2]))] = true;
        }
        whole.push(((n + 1) as u16, s));
    })?;
    Ok(Some(whole))
}
