//! Legacy VTK image data (`.vtk`, `DATASET STRUCTURED_POINTS`): what VTK, ParaView and ITK write
//! for a volume, binary (big-endian) or ASCII. Written by hand: the VTK crates on crates.io read
//! meshes and VTK's XML formats, not legacy image data's scalars into a grid of this kind.
//!
//! The header's keywords (case aside) are `DIMENSIONS`, `SPACING` (or the older `ASPECT_RATIO`)
//! and `ORIGIN` (the format has no orientation: the axes are x, y, z); then `POINT_DATA n` and
//! the values, as `SCALARS name type [1]` with an optional `LOOKUP_TABLE`
//! line, or as the first array of a `FIELD`. Coordinates are read as LPS millimetres, as ITK
//! (and so SimpleITK and 3D Slicer's ITK readers) reads and writes them.

use std::path::Path;

use super::nifti::guess_unit;
use super::raw::decode;
use super::{Phase, Volume, VolumeError, VolumeFormat, check_geometry, unit_columns, voxel_count};
use crate::vtk_legacy::{Cursor, header, scalar_of};

/// Parses a legacy VTK file's bytes (a 3-D volume: `phase`, if given, must be 1).
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    let bad = |why: String| VolumeError::invalid(path, why);
    let h = header(bytes).map_err(bad)?;
    if h.dataset != "STRUCTURED_POINTS" {
        return Err(bad(format!(
            "VTK DATASET {}: a volume is image data (DATASET STRUCTURED_POINTS)",
            h.dataset
        )));
    }
    let (binary, mut c) = (h.binary, h.cursor);
    let (mut dims, mut spacing_v, mut origin) = (None, [1.0; 3], [0.0; 3]);
    let numbers = |words: &[&str], n: usize| -> Result<Vec<f64>, VolumeError> {
        let v: Option<Vec<f64>> = words[1..].iter().map(|w| w.parse().ok()).collect();
        v.filter(|v| v.len() == n && v.iter().all(|x: &f64| x.is_finite()))
            .ok_or_else(|| {
                bad(format!(
                    "VTK {} must give {n} finite numbers: {:?}",
                    words[0],
                    words[1..].join(" ")
                ))
            })
    };
    let points = loop {
        let words = c.words("POINT_DATA line").map_err(bad)?;
        match words[0].to_ascii_uppercase().as_str() {
            "DIMENSIONS" => {
                let d = numbers(&words, 3)?;
                if d.iter().any(|&x| x < 1.0 || x.fract() != 0.0 || x > 1e9) {
                    return Err(bad(format!("bad VTK DIMENSIONS {d:?}")));
                }
                dims = Some([d[0] as usize, d[1] as usize, d[2] as usize]);
            }
            "SPACING" | "ASPECT_RATIO" => {
                let s = numbers(&words, 3)?;
                spacing_v = [s[0], s[1], s[2]];
            }
            "ORIGIN" => {
                let o = numbers(&words, 3)?;
                origin = [o[0], o[1], o[2]];
            }
            "POINT_DATA" => {
                let n = numbers(&words, 1)?[0];
                break n;
            }
            "CELL_DATA" => {
                return Err(bad(
                    "VTK CELL_DATA before any POINT_DATA: a volume's values are point data".into(),
                ));
            }
            other => return Err(bad(format!("unexpected VTK header keyword {other:?}"))),
        }
    };
    let dims = dims.ok_or_else(|| bad("the VTK header has no DIMENSIONS".into()))?;
    let n = voxel_count(path, dims)?;
    if points != n as f64 {
        return Err(bad(format!(
            "VTK POINT_DATA {points} does not match DIMENSIONS {dims:?} ({n} points)"
        )));
    }
    // Legacy VTK image data has no orientation: its axes are x, y and z, each scaled by its
    // spacing, then split into unit direction and spacing as the other readers do (a negative
    // spacing turns its axis round).
    let axes = std::array::from_fn(|r| {
        std::array::from_fn(|col| if r == col { spacing_v[col] } else { 0.0 })
    });
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    let mut warnings = Vec::new();
    let phase = Phase::pick(path, phase, 1, &mut warnings)?;

    let scalar = values_header(&mut c, n).map_err(bad)?;
    let what = "the VTK voxel data";
    let data = if binary {
        decode(
            c.binary(n, scalar.size(), what).map_err(bad)?,
            scalar,
            true,
            1.0,
            0.0,
        )
    } else {
        let text = c.text(n, what).map_err(bad)?;
        text.into_iter().map(|v| v as f32).collect()
    };
    let unit = guess_unit(&data, scalar);
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::Vtk,
        series: None,
        segments: Vec::new(),
        phase,
        warnings,
    })
}

/// Reads the lines that announce the values (`SCALARS` and its `LOOKUP_TABLE`, or a `FIELD` and
/// its first array's line), leaving the cursor at the first value; returns their type.
fn values_header(c: &mut Cursor, n: usize) -> Result<crate::volume::raw::Scalar, String> {
    let words = c.words("SCALARS line")?;
    match words[0].to_ascii_uppercase().as_str() {
        "SCALARS" => {
            let type_name = words
                .get(2)
                .ok_or_else(|| format!("VTK {:?} names no type", words.join(" ")))?;
            let scalar = scalar_of(type_name)?;
            if let Some(k) = words.get(3).filter(|k| **k != "1") {
                return Err(format!(
                    "VTK SCALARS with {k} components: a volume has one value a point"
                ));
            }
            if c.next_line_starts_with("LOOKUP_TABLE") {
                c.line();
            }
            Ok(scalar)
        }
        "FIELD" => {
            let array = c.words("FIELD's first array")?;
            // NAME COMPONENTS TUPLES TYPE
            let [_, components, tuples, type_name] = array[..] else {
                return Err(format!(
                    "VTK FIELD array line {:?}: NAME COMPONENTS TUPLES TYPE expected",
                    array.join(" ")
                ));
            };
            if components != "1" || tuples.parse::<usize>().ok() != Some(n) {
                return Err(format!(
                    "VTK FIELD array {:?}: one component for each of the {n} points expected",
                    array.join(" ")
                ));
            }
            scalar_of(type_name)
        }
        other => Err(format!(
            "VTK point data {other:?}: raystream reads one SCALARS array (or a FIELD's first)"
        )),
    }
}
