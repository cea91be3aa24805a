//! MetaImage volumes (`.mha` with the data after the header, `.mhd` with a separate data file),
//! raw or zlib-compressed, 3-D or 4-D (phases along the fourth axis). Written by hand: the only MetaImage crates on crates.io are
//! unmaintained. World coordinates are LPS (ITK's convention); `TransformMatrix` lists the axis
//! directions one axis after another (ITK's MetaImageIO reads axis i from elements 3i..3i+3).

use std::collections::HashMap;
use std::path::Path;

use super::nifti::guess_unit;
use super::raw::{PhaseLayout, Scalar, decode, read_phase, skip_n};
use super::{
    Phase, Volume, VolumeError, VolumeFormat, check_geometry, is_orthonormal, unit_columns,
    voxel_count,
};

/// Parses a `.mha` / `.mhd` file's bytes; a separate data file is looked up beside `path`. Of
/// a 4-D image, the 3-D volume `phase` (from 1, default 1) along its fourth axis.
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    let mut fields = HashMap::new();
    let mut pos = 0;
    let mut found_data_file = false;
    while pos < bytes.len() && pos < (1 << 20) {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| VolumeError::invalid(path, "MetaImage header is not text"))?
            .trim();
        pos = (end + 1).min(bytes.len());
        if line.is_empty() {
            continue;
        }
        let (k, v) = line.split_once('=').ok_or_else(|| {
            VolumeError::invalid(path, format!("not a MetaImage header line: {line:?}"))
        })?;
        let key = k.trim().to_string();
        fields.insert(key.clone(), v.trim().to_string());
        if key == "ElementDataFile" {
            found_data_file = true;
            break;
        }
    }
    if !found_data_file {
        return Err(VolumeError::invalid(
            path,
            "MetaImage header has no ElementDataFile line",
        ));
    }
    let get = |k: &str| fields.get(k).map(String::as_str);
    let need = |k: &str| {
        get(k).ok_or_else(|| VolumeError::invalid(path, format!("MetaImage header has no {k}")))
    };
    let nums = |k: &str, def: Option<Vec<f64>>| -> Result<Vec<f64>, VolumeError> {
        match get(k) {
            Some(v) => v
                .split_whitespace()
                .map(|x| {
                    x.parse::<f64>().map_err(|_| {
                        VolumeError::invalid(path, format!("bad number {x:?} in MetaImage {k}"))
                    })
                })
                .collect(),
            None => def
                .ok_or_else(|| VolumeError::invalid(path, format!("MetaImage header has no {k}"))),
        }
    };
    let nd = match nums("NDims", None)?[..] {
        [3.0] => 3,
        [4.0] => 4,
        ref d => {
            return Err(VolumeError::invalid(
                path,
                format!("MetaImage NDims {d:?}: 3-D volumes, and 4-D series of them, are read"),
            ));
        }
    };
    let dim = nums("DimSize", None)?;
    if dim.len() != nd || dim.iter().any(|d| *d < 1.0 || d.fract() != 0.0 || *d > 1e9) {
        return Err(VolumeError::invalid(
            path,
            format!("bad MetaImage DimSize {dim:?}"),
        ));
    }
    let dims = [dim[0] as usize, dim[1] as usize, dim[2] as usize];
    let n = voxel_count(path, dims)?;
    // A 4-D image's fourth axis holds the phases (time), one 3-D volume after another.
    let count = dim.get(3).map_or(1, |&t| t as usize);
    let mut warnings = Vec::new();
    let phase = Phase::pick(path, phase, count, &mut warnings)?;
    if get("ElementNumberOfChannels").is_some_and(|c| c.trim() != "1") {
        return Err(VolumeError::invalid(
            path,
            "multi-channel MetaImage is not supported",
        ));
    }
    let scalar = scalar_of(need("ElementType")?).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "MetaImage ElementType {:?} is not supported",
                get("ElementType")
            ),
        )
    })?;
    let big_endian = [get("BinaryDataByteOrderMSB"), get("ElementByteOrderMSB")]
        .into_iter()
        .flatten()
        .any(|v| v.eq_ignore_ascii_case("true"));
    let compressed = get("CompressedData").is_some_and(|v| v.eq_ignore_ascii_case("true"));
    let spacing_v = nums("ElementSpacing", Some(vec![1.0; nd]))?;
    let first_of = |keys: [&'static str; 3]| keys.into_iter().find(|k| get(k).is_some());
    let origin_v = match first_of(["Offset", "Origin", "Position"]) {
        Some(k) => nums(k, None)?,
        None => vec![0.0; nd],
    };
    let tm = match first_of(["TransformMatrix", "Rotation", "Orientation"]) {
        Some(k) => nums(k, None)?,
        None => (0..nd * nd)
            .map(|i| (i % (nd + 1) == 0) as u8 as f64)
            .collect(),
    };
    if spacing_v.len() != nd || origin_v.len() != nd || tm.len() != nd * nd {
        return Err(VolumeError::invalid(
            path,
            "MetaImage ElementSpacing/Offset/TransformMatrix have the wrong length",
        ));
    }
    // Time may not turn into space: the fourth axis and the fourth coordinate are their own.
    if nd == 4 && (0..3).any(|i| tm[4 * i + 3] != 0.0 || tm[12 + i] != 0.0) {
        return Err(VolumeError::invalid(
            path,
            format!("MetaImage TransformMatrix {tm:?} mixes space and time"),
        ));
    }
    // Axis c is tm[nd·c..nd·c+3]; scale by spacing, then split into unit direction and spacing.
    let axes = std::array::from_fn(|r| std::array::from_fn(|c| tm[nd * c + r] * spacing_v[c]));
    let (direction, spacing) = unit_columns(axes);
    let origin = [origin_v[0], origin_v[1], origin_v[2]];
    check_geometry(path, dims, spacing, origin, &direction)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal".into());
    }

    let nbytes = (n * scalar.size()).saturating_mul(count);
    let data_file = need("ElementDataFile")?;
    let detached;
    let payload: &[u8] = if data_file.eq_ignore_ascii_case("LOCAL") {
        &bytes[pos..]
    } else {
        if data_file.starts_with("LIST") || data_file.contains('%') {
            return Err(VolumeError::invalid(
                path,
                "MetaImage multi-file data is not supported",
            ));
        }
        let file = path.parent().unwrap_or(Path::new(".")).join(data_file);
        detached = std::fs::read(&file).map_err(|e| {
            VolumeError::invalid(path, format!("data file {}: {e}", file.display()))
        })?;
        &detached
    };
    let header_size: i64 = match get("HeaderSize") {
        Some(h) => h
            .parse()
            .map_err(|_| VolumeError::invalid(path, format!("bad MetaImage HeaderSize {h:?}")))?,
        None => 0,
    };
    let layout = PhaseLayout::time_last(n, count);
    let (index, what) = (phase.index - 1, "the MetaImage voxel data");
    let data_bytes = if compressed {
        let mut r = flate2::read::ZlibDecoder::new(payload);
        read_phase(&mut r, layout, index, scalar.size(), path, what)?
    } else {
        let start = if header_size == -1 {
            payload.len().saturating_sub(nbytes)
        } else {
            header_size.max(0) as usize
        };
        let mut r: &[u8] = payload;
        skip_n(&mut r, start as u64, path)?;
        read_phase(&mut r, layout, index, scalar.size(), path, what)?
    };
    let data = decode(&data_bytes, scalar, big_endian, 1.0, 0.0);
    let unit = guess_unit(&data, scalar);
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::MetaImage,
        series: None,
        segments: Vec::new(),
        phase,
        warnings,
    })
}

fn scalar_of(t: &str) -> Option<Scalar> {
    Some(match t {
        "MET_UCHAR" => Scalar::U8,
        "MET_CHAR" => Scalar::I8,
        "MET_USHORT" => Scalar::U16,
        "MET_SHORT" => Scalar::I16,
        "MET_UINT" => Scalar::U32,
        "MET_INT" => Scalar::I32,
        "MET_ULONG" => Scalar::U32,
        "MET_LONG" => Scalar::I32,
        "MET_ULONG_LONG" => Scalar::U64,
        "MET_LONG_LONG" => Scalar::I64,
        "MET_FLOAT" => Scalar::F32,
        "MET_DOUBLE" => Scalar::F64,
        _ => return None,
    })
}
