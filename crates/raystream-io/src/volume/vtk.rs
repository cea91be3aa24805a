//! Legacy VTK image data (`.vtk`, `DATASET STRUCTURED_POINTS`): what VTK, ParaView and ITK write
//! for a volume, binary (big-endian) or ASCII. Written by hand: the VTK crates on crates.io read
//! meshes and VTK's XML formats, not legacy image data's scalars into a grid of this kind.
//!
//! The header's keywords (case aside) are `DIMENSIONS`, `SPACING` (or the older `ASPECT_RATIO`),
//! `ORIGIN` and, from VTK 9, `DIRECTION` (nine numbers, row-major, columns the axes); then
//! `POINT_DATA n` and the values, as `SCALARS name type [1]` with an optional `LOOKUP_TABLE`
//! line, or as the first array of a `FIELD`. Coordinates are read as LPS millimetres, as ITK
//! (and so SimpleITK and 3D Slicer's ITK readers) reads and writes them.

use std::path::Path;

use super::nifti::guess_unit;
use super::raw::{Scalar, decode};
use super::{
    Phase, Volume, VolumeError, VolumeFormat, check_geometry, is_orthonormal, unit_columns,
    voxel_count,
};

/// A cursor over the file's bytes: header tokens and lines, then the values.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Cursor<'a> {
    /// The next line, without its line end; `None` at the end of the file.
    fn line(&mut self) -> Option<&'a str> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        Some(
            std::str::from_utf8(&rest[..end])
                .unwrap_or("")
                .trim_end_matches('\r'),
        )
    }

    /// The next line with any text, split into words; an error at the end of the file.
    fn words(&mut self, wanted: &str) -> Result<Vec<&'a str>, VolumeError> {
        loop {
            let line = self.line().ok_or_else(|| {
                VolumeError::invalid(
                    self.path,
                    format!("the VTK header ends before its {wanted}"),
                )
            })?;
            let words: Vec<&str> = line.split_whitespace().collect();
            if !words.is_empty() {
                return Ok(words);
            }
        }
    }

    /// Whether the next line starts with `keyword` (case aside), without moving past it.
    fn next_line_starts_with(&self, keyword: &str) -> bool {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let n = keyword.len();
        rest.len() >= n && rest[..n].eq_ignore_ascii_case(keyword.as_bytes())
    }
}

/// Parses a legacy VTK file's bytes (a 3-D volume: `phase`, if given, must be 1).
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    let bad = |why: String| VolumeError::invalid(path, why);
    let mut c = Cursor {
        bytes,
        pos: 0,
        path,
    };
    let first = c.line().unwrap_or("");
    if !first.to_ascii_lowercase().starts_with("# vtk datafile") {
        return Err(bad(format!(
            "not a legacy VTK file: it starts {:?}, not \"# vtk DataFile Version\"",
            first.chars().take(40).collect::<String>()
        )));
    }
    let _title = c.line();
    let encoding = c.words("encoding (ASCII or BINARY)")?;
    let binary = match encoding[0].to_ascii_uppercase().as_str() {
        "BINARY" => true,
        "ASCII" => false,
        other => {
            return Err(bad(format!(
                "VTK encoding {other:?}: ASCII or BINARY expected"
            )));
        }
    };
    let dataset = c.words("DATASET line")?;
    let kind = dataset.get(1).map(|k| k.to_ascii_uppercase());
    if !dataset[0].eq_ignore_ascii_case("DATASET") || kind.as_deref() != Some("STRUCTURED_POINTS") {
        return Err(bad(format!(
            "VTK {}: raystream reads legacy VTK image data (DATASET STRUCTURED_POINTS) as a \
             volume; save a mesh as PLY, OBJ or STL",
            dataset.join(" ")
        )));
    }

    let (mut dims, mut spacing_v, mut origin) = (None, [1.0; 3], [0.0; 3]);
    let mut direction = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
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
        let words = c.words("POINT_DATA line")?;
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
            "DIRECTION" => {
                let m = numbers(&words, 9)?;
                direction = std::array::from_fn(|r| std::array::from_fn(|col| m[3 * r + col]));
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
    // Each axis scaled by its spacing, then split into unit direction and spacing, as the
    // other readers do (a negative spacing turns its axis round).
    let axes =
        std::array::from_fn(|r| std::array::from_fn(|col| direction[r][col] * spacing_v[col]));
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    let mut warnings = Vec::new();
    let phase = Phase::pick(path, phase, 1, &mut warnings)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal".into());
    }

    let scalar = values_header(&mut c, n)?;
    let data = if binary {
        let nbytes = n * scalar.size();
        let rest = &bytes[c.pos.min(bytes.len())..];
        if rest.len() < nbytes {
            return Err(bad(format!(
                "the VTK voxel data is truncated: the header implies {nbytes} bytes, the file \
                 holds {}",
                rest.len()
            )));
        }
        decode(&rest[..nbytes], scalar, true, 1.0, 0.0)
    } else {
        ascii_values(&bytes[c.pos.min(bytes.len())..], n, path)?
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
        phase,
        warnings,
    })
}

/// Reads the lines that announce the values (`SCALARS` and its `LOOKUP_TABLE`, or a `FIELD` and
/// its first array's line), leaving the cursor at the first value; returns their type.
fn values_header(c: &mut Cursor, n: usize) -> Result<Scalar, VolumeError> {
    let path = c.path;
    let bad = |why: String| VolumeError::invalid(path, why);
    let words = c.words("SCALARS line")?;
    match words[0].to_ascii_uppercase().as_str() {
        "SCALARS" => {
            let type_name = words
                .get(2)
                .ok_or_else(|| bad(format!("VTK {:?} names no type", words.join(" "))))?;
            let scalar = scalar_of(type_name, path)?;
            if let Some(k) = words.get(3).filter(|k| **k != "1") {
                return Err(bad(format!(
                    "VTK SCALARS with {k} components: a volume has one value a point"
                )));
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
                return Err(bad(format!(
                    "VTK FIELD array line {:?}: NAME COMPONENTS TUPLES TYPE expected",
                    array.join(" ")
                )));
            };
            if components != "1" || tuples.parse::<usize>().ok() != Some(n) {
                return Err(bad(format!(
                    "VTK FIELD array {:?}: one component for each of the {n} points expected",
                    array.join(" ")
                )));
            }
            scalar_of(type_name, path)
        }
        other => Err(bad(format!(
            "VTK point data {other:?}: raystream reads one SCALARS array (or a FIELD's first)"
        ))),
    }
}

/// The scalar type a VTK type name stands for. `long` is 8 bytes, as VTK writes it on the
/// 64-bit Linux and macOS machines that write nearly all such files.
fn scalar_of(name: &str, path: &Path) -> Result<Scalar, VolumeError> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "unsigned_char" => Scalar::U8,
        "char" | "signed_char" => Scalar::I8,
        "unsigned_short" => Scalar::U16,
        "short" => Scalar::I16,
        "unsigned_int" => Scalar::U32,
        "int" => Scalar::I32,
        "unsigned_long" | "vtktypeuint64" => Scalar::U64,
        "long" | "vtktypeint64" => Scalar::I64,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => {
            return Err(VolumeError::invalid(
                path,
                format!("VTK values of type {name:?} are not read"),
            ));
        }
    })
}

/// `n` numbers written as text, separated by white space.
fn ascii_values(text: &[u8], n: usize, path: &Path) -> Result<Vec<f32>, VolumeError> {
    let text = std::str::from_utf8(text)
        .map_err(|_| VolumeError::invalid(path, "the VTK ASCII values are not text"))?;
    let mut out = Vec::with_capacity(n.min(text.len() / 2 + 1));
    for word in text.split_ascii_whitespace().take(n) {
        let v: f64 = word.parse().map_err(|_| {
            VolumeError::invalid(
                path,
                format!("VTK value {} is not a number: {word:?}", out.len() + 1),
            )
        })?;
        out.push(v as f32);
    }
    if out.len() < n {
        return Err(VolumeError::invalid(
            path,
            format!(
                "the VTK voxel data is truncated: the header implies {n} values, the file holds {}",
                out.len()
            ),
        ));
    }
    Ok(out)
}
