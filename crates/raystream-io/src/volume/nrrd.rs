//! NRRD volumes (`.nrrd` with attached data, `.nhdr` with a detached data file), raw or gzip.
//!
//! No NRRD crate exists on crates.io (`cargo info nrrd`: not found), and the format is a short
//! text header, so it is parsed here. Reads 3-D scalar images and 4-D series of them (the
//! phase axis: `none` among the space directions, as 3D Slicer writes sequences; the fourth
//! coordinate of ITK's 4-D space; or a non-`domain` kind): `type`, `dimension`, `sizes`,
//! `endian`, `encoding` (raw, gzip), `space` (LPS, RAS, LAS and their long names; anything
//! else is refused), `space directions`, `space origin`, `spacings` (no space), `data file`,
//! `line skip`, `byte skip`.

use std::collections::HashMap;
use std::path::Path;

use super::nifti::guess_unit;
use super::raw::{PhaseLayout, Scalar, decode, open_payload, read_phase, skip_n, value};
use super::{
    Phase, ValueUnit, Volume, VolumeError, VolumeFormat, WholeSegments, check_geometry,
    is_orthonormal, slicer_seg, unit_columns, voxel_count,
};

/// Parses a `.nrrd` / `.nhdr` file's bytes; a detached data file is looked up beside `path`.
/// Of a 4-D image, the 3-D volume `phase` (from 1, default 1) along its non-spatial axis.
/// A 3D Slicer segmentation (`.seg.nrrd`) is read as its label volume, every layer at once.
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    read(bytes, path, phase, false).map(|(v, _)| v)
}

/// A 3D Slicer segmentation's label volume and, where its segments lie on several layers (they
/// overlap), each segment's voxels whole; `None` for a single layer or a plain NRRD.
pub(crate) fn whole_segments(
    bytes: &[u8],
    path: &Path,
) -> Result<Option<WholeSegments>, VolumeError> {
    read(bytes, path, None, true).map(|(_, whole)| whole)
}

fn read(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
    whole: bool,
) -> Result<(Volume, Option<WholeSegments>), VolumeError> {
    if !bytes.starts_with(b"NRRD000") {
        return Err(VolumeError::invalid(
            path,
            "not a NRRD file (no NRRD000x magic)",
        ));
    }
    // The header ends at the first empty line.
    // A detached header (.nhdr) may simply end with the file.
    let (header_end, data_start) = find_blank_line(bytes).unwrap_or((bytes.len(), bytes.len()));
    let text = std::str::from_utf8(&bytes[..header_end])
        .map_err(|_| VolumeError::invalid(path, "NRRD header is not text"))?;
    let mut fields = HashMap::new();
    let mut key_values = Vec::new();
    for line in text.lines().skip(1) {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        // `key:=value` lines are key/value pairs, not fields (a Slicer segmentation's segments).
        if let Some((k, v)) = line.split_once(":=") {
            key_values.push((k.to_string(), v.to_string()));
            continue;
        }
        let (k, v) = line
            .split_once(": ")
            .ok_or_else(|| VolumeError::invalid(path, format!("bad NRRD header line {line:?}")))?;
        fields.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
    }
    let get = |k: &str| fields.get(k).map(String::as_str);
    let need = |k: &str| {
        get(k).ok_or_else(|| VolumeError::invalid(path, format!("NRRD header has no {k:?} field")))
    };

    let dimension: usize = parse_num(need("dimension")?, path, "dimension")?;
    if !(3..=4).contains(&dimension) {
        return Err(VolumeError::invalid(
            path,
            format!(
                "NRRD dimension {dimension}: 3-D scalar volumes, and 4-D series of them, are read"
            ),
        ));
    }
    let sizes: Vec<usize> = need("sizes")?
        .split_whitespace()
        .map(|s| parse_num(s, path, "sizes"))
        .collect::<Result<_, _>>()?;
    if sizes.len() != dimension {
        return Err(VolumeError::invalid(
            path,
            format!("NRRD sizes must list {dimension} numbers"),
        ));
    }
    let scalar = scalar_of(need("type")?).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!("NRRD type {:?} is not supported", get("type")),
        )
    })?;
    let big_endian = match get("endian") {
        Some("big") => true,
        Some("little") | None => false,
        Some(e) => return Err(VolumeError::invalid(path, format!("NRRD endian {e:?}"))),
    };
    let gzip = match need("encoding")? {
        "raw" => false,
        "gzip" | "gz" => true,
        e => {
            return Err(VolumeError::invalid(
                path,
                format!("NRRD encoding {e:?} is not supported (raw and gzip are)"),
            ));
        }
    };

    let mut warnings = Vec::new();
    let (steps, origin) = axis_steps(&fields, dimension, path, &mut warnings)?;
    // Three axes in space; a fourth, if any, holds the phases (time, or a list).
    let spatial: Vec<usize> = (0..dimension).filter(|&i| steps[i].is_some()).collect();
    let [i, j, k] = spatial[..] else {
        return Err(VolumeError::invalid(
            path,
            format!(
                "NRRD image has {} axes in space: 3 are read, and at most one other (phases)",
                spatial.len()
            ),
        ));
    };
    let dims = [sizes[i], sizes[j], sizes[k]];
    let n = voxel_count(path, dims)?;
    let phase_axis = (0..dimension).find(|&a| steps[a].is_none());
    let layout = match phase_axis {
        Some(p) => PhaseLayout {
            inner: sizes[..p].iter().product(),
            count: sizes[p],
            outer: sizes[p + 1..].iter().product(),
        },
        None => PhaseLayout::time_last(n, 1),
    };
    if layout.count == 0 || layout.count > u32::MAX as usize {
        return Err(VolumeError::invalid(
            path,
            format!("NRRD sizes {sizes:?}: {} phases", layout.count),
        ));
    }
    // A Slicer segmentation's fourth axis holds layers of segments, all read.
    let layers = if phase_axis.is_some() {
        layout.count
    } else {
        1
    };
    let segments = slicer_seg::segments(&key_values, layers, path, &mut warnings)?;
    let phases = if segments.is_some() { 1 } else { layout.count };
    let phase = Phase::pick(path, phase, phases, &mut warnings)?;
    let axes = std::array::from_fn(|r| std::array::from_fn(|c| steps[spatial[c]].unwrap()[r]));
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal".into());
    }

    let line_skip: usize = get("line skip").map_or(Ok(0), |v| parse_num(v, path, "line skip"))?;
    let byte_skip: i64 = get("byte skip").map_or(Ok(0), |v| parse_num(v, path, "byte skip"))?;
    // A lying phase count saturates: the data then runs short, a truncation error.
    let nbytes = (n * scalar.size()).saturating_mul(layout.count);
    let detached;
    let (payload, start): (&[u8], usize) = match get("data file").or_else(|| get("datafile")) {
        Some(name) => {
            if name.starts_with("LIST") || name.contains('%') {
                return Err(VolumeError::invalid(
                    path,
                    "NRRD multi-file data is not supported",
                ));
            }
            let file = path.parent().unwrap_or(Path::new(".")).join(name);
            detached = std::fs::read(&file).map_err(|e| {
                VolumeError::invalid(path, format!("data file {}: {e}", file.display()))
            })?;
            (&detached, 0)
        }
        None => (bytes, data_start),
    };
    let mut start = start;
    for _ in 0..line_skip {
        let nl = payload[start..]
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| VolumeError::invalid(path, "NRRD line skip runs past the data"))?;
        start += nl + 1;
    }
    if byte_skip == -1 {
        if gzip {
            return Err(VolumeError::invalid(
                path,
                "NRRD byte skip -1 with gzip encoding",
            ));
        }
        start = payload.len().checked_sub(nbytes).ok_or_else(|| {
            VolumeError::invalid(
                path,
                format!("NRRD data is truncated: {nbytes} bytes expected"),
            )
        })?;
    }
    let mut r = open_payload(payload, start, gzip, path)?;
    if byte_skip > 0 {
        skip_n(&mut r, byte_skip as u64, path)?;
    }
    let what = "the NRRD voxel data";
    let (data, labels, whole, unit) = match segments {
        Some(segments) => {
            let all = PhaseLayout::time_last(n * layers, 1);
            let data_bytes = read_phase(&mut r, all, 0, scalar.size(), path, what)?;
            let size = scalar.size();
            let value = |i: usize| value(&data_bytes[i * size..(i + 1) * size], scalar, big_endian);
            let labels = slicer_seg::label_volume(
                value,
                dims,
                (layers, layout.inner),
                &segments,
                whole && layers > 1,
                path,
                &mut warnings,
            )?;
            (
                labels.data,
                labels.segments,
                labels.whole,
                ValueUnit::Unknown,
            )
        }
        None => {
            let data_bytes =
                read_phase(&mut r, layout, phase.index - 1, scalar.size(), path, what)?;
            let data = decode(&data_bytes, scalar, big_endian, 1.0, 0.0);
            let unit = guess_unit(&data, scalar);
            (data, Vec::new(), None, unit)
        }
    };
    let volume = Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::Nrrd,
        series: None,
        segments: labels,
        phase,
        warnings,
    };
    Ok((volume, whole))
}

/// Byte offsets of the end of the header text and of the first data byte.
fn find_blank_line(bytes: &[u8]) -> Option<(usize, usize)> {
    let limit = bytes.len().min(1 << 20);
    (0..limit.saturating_sub(1)).find_map(|i| {
        if bytes[i] != b'\n' {
            return None;
        }
        if bytes[i + 1] == b'\n' {
            Some((i, i + 2))
        } else if bytes[i + 1] == b'\r' && bytes.get(i + 2) == Some(&b'\n') {
            Some((i, i + 3))
        } else {
            None
        }
    })
}

fn parse_num<T: std::str::FromStr>(s: &str, path: &Path, what: &str) -> Result<T, VolumeError> {
    s.trim()
        .parse()
        .map_err(|_| VolumeError::invalid(path, format!("bad number {s:?} in NRRD {what}")))
}

/// Each axis's step in LPS mm (`None`: the axis of a 4-D image's phases) and the origin, from
/// `space` (or ITK's bare `space dimension`), `space directions` and `space origin`, or, with
/// no space, `spacings` (and `kinds`, which may name the phase axis).
#[allow(clippy::type_complexity)]
fn axis_steps(
    fields: &HashMap<String, String>,
    dimension: usize,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Option<[f64; 3]>>, [f64; 3]), VolumeError> {
    let get = |k: &str| fields.get(k).map(String::as_str);
    let bad = |what: String| VolumeError::invalid(path, what);
    let (signs, space_dim) = match (get("space"), get("space dimension")) {
        (Some(space), _) => (
            space_signs(space)
                .ok_or_else(|| bad(format!("NRRD space {space:?} is not supported")))?,
            3,
        ),
        (None, Some(d)) => {
            let d: usize = parse_num(d, path, "space dimension")?;
            if !(3..=4).contains(&d) {
                return Err(bad(format!("NRRD space dimension {d} is not supported")));
            }
            warnings.push(
                "NRRD names no space: its coordinates are taken as LPS, as ITK writes them".into(),
            );
            ([1.0; 3], d)
        }
        (None, None) => {
            warnings.push("NRRD has no space: orientation unknown, assuming LPS axes".into());
            return spacings_only(fields, dimension, path);
        }
    };
    let lps = |v: &[f64]| -> [f64; 3] { std::array::from_fn(|r| v[r] * signs[r]) };
    let dirs = parse_vectors(
        get("space directions")
            .ok_or_else(|| bad("NRRD header has no \"space directions\" field".into()))?,
        space_dim,
        path,
        "space directions",
    )?;
    if dirs.len() != dimension {
        return Err(bad(format!(
            "NRRD space directions must list {dimension} entries"
        )));
    }
    let mut steps = Vec::new();
    for d in dirs {
        steps.push(match d {
            // In ITK's 4-D space the time axis steps along the fourth coordinate alone.
            Some(v) if space_dim == 4 && v[..3].iter().all(|&x| x == 0.0) => None,
            Some(v) if space_dim == 4 && v[3] != 0.0 => {
                return Err(bad(format!(
                    "NRRD space direction {v:?} mixes space and time"
                )));
            }
            Some(v) => Some(lps(&v)),
            None => None,
        });
    }
    let origin = match get("space origin") {
        Some(o) => match &parse_vectors(o, space_dim, path, "space origin")?[..] {
            [Some(v)] => lps(v),
            _ => return Err(bad("bad NRRD space origin".into())),
        },
        None => [0.0; 3],
    };
    Ok((steps, origin))
}

/// Axis steps from `spacings` alone (no space: the axes taken as L, P, S in turn); of a 4-D
/// image, the phase axis is the one whose kind is not `domain` or `space`, or whose spacing is
/// `nan`, else the last.
#[allow(clippy::type_complexity)]
fn spacings_only(
    fields: &HashMap<String, String>,
    dimension: usize,
    path: &Path,
) -> Result<(Vec<Option<[f64; 3]>>, [f64; 3]), VolumeError> {
    let sp: Vec<f64> = match fields.get("spacings") {
        Some(s) => s
            .split_whitespace()
            .map(|v| parse_num(v, path, "spacings"))
            .collect::<Result<_, _>>()?,
        None => vec![1.0; dimension],
    };
    if sp.len() != dimension {
        return Err(VolumeError::invalid(
            path,
            format!("NRRD spacings must list {dimension} numbers"),
        ));
    }
    let kinds: Vec<String> = fields
        .get("kinds")
        .map(|k| k.split_whitespace().map(str::to_ascii_lowercase).collect())
        .unwrap_or_default();
    let listed =
        |a: usize| sp[a].is_nan() || kinds.get(a).is_some_and(|k| k != "domain" && k != "space");
    let phase_axis = (dimension == 4).then(|| (0..4).find(|&a| listed(a)).unwrap_or(3));
    let mut next = 0;
    let steps = (0..dimension)
        .map(|a| {
            (Some(a) != phase_axis).then(|| {
                next += 1;
                std::array::from_fn(|r| if r == next - 1 { sp[a] } else { 0.0 })
            })
        })
        .collect();
    Ok((steps, [0.0; 3]))
}

/// `(a,b,c) none (d,e,f) …` → vectors of `len` numbers (`None` for `none`).
fn parse_vectors(
    s: &str,
    len: usize,
    path: &Path,
    what: &str,
) -> Result<Vec<Option<Vec<f64>>>, VolumeError> {
    let bad = || VolumeError::invalid(path, format!("bad NRRD {what}: {s:?}"));
    let mut out = Vec::new();
    let mut rest = s.trim_start();
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix("none") {
            out.push(None);
            rest = r.trim_start();
            continue;
        }
        let inner = rest.strip_prefix('(').ok_or_else(bad)?;
        let (inner, r) = inner.split_once(')').ok_or_else(bad)?;
        let v: Vec<f64> = inner
            .split(',')
            .map(|x| parse_num(x, path, what))
            .collect::<Result<_, _>>()?;
        if v.len() != len {
            return Err(VolumeError::invalid(
                path,
                format!("NRRD {what} needs {len}-vectors: {s:?}"),
            ));
        }
        out.push(Some(v));
        rest = r.trim_start();
    }
    Ok(out)
}

/// Per world axis, the sign that turns the NRRD space into LPS.
fn space_signs(space: &str) -> Option<[f64; 3]> {
    Some(match space.to_ascii_lowercase().as_str() {
        "left-posterior-superior" | "lps" => [1.0, 1.0, 1.0],
        "right-anterior-superior" | "ras" => [-1.0, -1.0, 1.0],
        "left-anterior-superior" | "las" => [1.0, -1.0, 1.0],
        _ => return None,
    })
}

fn scalar_of(t: &str) -> Option<Scalar> {
    Some(match t {
        "signed char" | "int8" | "int8_t" => Scalar::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Scalar::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            Scalar::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Scalar::U16,
        "int" | "signed int" | "int32" | "int32_t" => Scalar::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Scalar::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Scalar::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            Scalar::U64
        }
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return None,
    })
}
