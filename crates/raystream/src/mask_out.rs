//! Labels on a CT's grid written out: `measure --mask/--structures` (a vessel's lumen and wall)
//! and `info --body --mask/--structures` (the patient's body). The file's name picks the form:
//! a NIfTI label map, a 3D Slicer segmentation, a DICOM Segmentation or an RT Structure Set
//! of the CT's series.

use std::path::Path;

use anyhow::{Result, bail};
use raystream_io::{Segment, SegmentationInfo, SegmentationWritten, Volume};

/// Refuses, before any work, a `--mask` or `--structures` file named for no form they write.
pub fn check_names(mask: Option<&Path>, structures: Option<&Path>) -> Result<()> {
    if let Some(m) = mask
        && !raystream_io::is_label_map_path(m)
        && !raystream_io::is_slicer_segmentation_path(m)
        && !raystream_io::is_segmentation_path(m)
    {
        bail!(
            "{}: --mask writes a NIfTI label map (.nii or .nii.gz), a 3D Slicer segmentation (.seg.nrrd) or a DICOM Segmentation (.dcm): name it so",
            m.display()
        );
    }
    if let Some(r) = structures
        && !raystream_io::is_segmentation_path(r)
    {
        bail!(
            "{}: --structures writes a DICOM RT Structure Set (.dcm): name it so",
            r.display()
        );
    }
    Ok(())
}

/// Refuses, before the labels are made, a DICOM Segmentation (`--mask` .dcm) or RT Structure
/// Set of `volume` when it cannot reference the CT's series (a NIfTI CT, a resampled one).
pub fn check_sources(
    mask: Option<&Path>,
    structures: Option<&Path>,
    volume: &Volume,
) -> Result<()> {
    if let Some(m) = mask
        && raystream_io::is_segmentation_path(m)
    {
        raystream_io::segmentation_source(volume)
            .map_err(|e| anyhow::anyhow!("{}: --mask: {e}", m.display()))?;
    }
    if let Some(r) = structures {
        raystream_io::structure_set_source(volume)
            .map_err(|e| anyhow::anyhow!("{}: --structures: {e}", r.display()))?;
    }
    Ok(())
}

/// Writes `labels` (a voxel of `volume` each) to `out` in the form its name gives: a DICOM
/// Segmentation (what it wrote returned), a 3D Slicer segmentation, or a NIfTI label map
/// (`what` in its header: the labels' meanings, which NIfTI has no place for otherwise).
pub fn write_mask(
    out: &Path,
    volume: &Volume,
    labels: &[u8],
    segments: &[Segment],
    (info, what): (&SegmentationInfo, &str),
) -> Result<Option<SegmentationWritten>> {
    if raystream_io::is_segmentation_path(out) {
        return Ok(Some(raystream_io::write_segmentation(
            out, volume, labels, segments, info,
        )?));
    }
    if raystream_io::is_slicer_segmentation_path(out) {
        raystream_io::write_slicer_segmentation(out, volume, labels, segments)?;
    } else {
        raystream_io::write_label_map(out, volume, labels, what)?;
    }
    Ok(None)
}

/// What a `--mask` file is, in words: `frames` from [`write_mask`]'s Segmentation.
pub fn mask_kind(out: &Path, frames: Option<usize>) -> String {
    match frames {
        Some(n) => format!("a DICOM Segmentation of the CT's series, {n} frames"),
        None if raystream_io::is_slicer_segmentation_path(out) => {
            "a 3D Slicer segmentation".to_string()
        }
        None => "a NIfTI label map".to_string(),
    }
}
