//! NRRD volumes (`.nrrd` with attached data, `.nhdr` with a detached data file), raw or gzip.
//!
//! No NRRD crate exists on crates.io (`cargo info nrrd`: not found), and the format is a short
//! text header, so it is parsed here. Reads 3-D scalar images: `type`, `dimension`, `sizes`,
//! `endian`, `encoding` (raw, gzip), `space` (LPS, RAS, LAS and their long names; anything
//! else is refused), `space directions`, `space origin`, `spacings` (no space), `data file`,
//! `line skip`, `byte skip`.

use std::collections::HashMap;
use std::path::Path;

use super::nifti::guess_unit;
use super::raw::{Scalar, decode, open_payload, read_exact_n, read_file, skip_n};
use super::{
    Volume, VolumeError, VolumeFormat, check_geometry, is_orthonormal, unit_columns, voxel_count,
};

pub(crate) fn load(path: &Path) -> Result<Volume, VolumeError> {
    parse(&read_file(path)?, path)
}

/// Parses a `.nrrd` / `.nhdr` file's bytes; a detached data file is looked up beside `path`.
pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<Volume, VolumeError> {
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
    for line in text.lines().skip(1) {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        // `key:=value` lines are key/value comments, not fields.
        if line.contains(":=") {
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
    if dimension != 3 {
        return Err(VolumeError::invalid(
            path,
            format!("NRRD dimension {dimension}: only 3-D scalar volumes are read"),
        ));
    }
    let sizes: Vec<usize> = need("sizes")?
        .split_whitespace()
        .map(|s| parse_num(s, path, "sizes"))
        .collect::<Result<_, _>>()?;
    if sizes.len() != 3 {
        return Err(VolumeError::invalid(path, "NRRD sizes must list 3 numbers"));
    }
    let dims = [sizes[0], sizes[1], sizes[2]];
    let n = voxel_count(path, dims)?;
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
    let (axes, origin) = match get("space") {
        Some(space) => {
            let signs = space_signs(space).ok_or_else(|| {
                VolumeError::invalid(path, format!("NRRD space {space:?} is not supported"))
            })?;
            let dirs = parse_vectors(need("space directions")?, path, "space directions")?;
            if dirs.len() != 3 {
                return Err(VolumeError::invalid(
                    path,
                    "NRRD space directions must list 3 vectors",
                ));
            }
            let origin = match get("space origin") {
                Some(o) => {
                    let v = parse_vectors(o, path, "space origin")?;
                    if v.len() != 1 {
                        return Err(VolumeError::invalid(path, "bad NRRD space origin"));
                    }
                    v[0]
                }
                None => [0.0; 3],
            };
            let axes = std::array::from_fn(|r| std::array::from_fn(|c| dirs[c][r] * signs[r]));
            (axes, std::array::from_fn(|r| origin[r] * signs[r]))
        }
        None => {
            warnings.push("NRRD has no space: orientation unknown, assuming LPS axes".into());
            let sp: Vec<f64> = match get("spacings") {
                Some(s) => s
                    .split_whitespace()
                    .map(|v| parse_num(v, path, "spacings"))
                    .collect::<Result<_, _>>()?,
                None => vec![1.0; 3],
            };
            if sp.len() != 3 {
                return Err(VolumeError::invalid(
                    path,
                    "NRRD spacings must list 3 numbers",
                ));
            }
            (
                std::array::from_fn(|r| std::array::from_fn(|c| if r == c { sp[c] } else { 0.0 })),
                [0.0; 3],
            )
        }
    };
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal".into());
    }

    let line_skip: usize = get("line skip").map_or(Ok(0), |v| parse_num(v, path, "line skip"))?;
    let byte_skip: i64 = get("byte skip").map_or(Ok(0), |v| parse_num(v, path, "byte skip"))?;
    let nbytes = n * scalar.size();
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
    let data_bytes = read_exact_n(&mut r, nbytes, path, "the NRRD voxel data")?;
    let data = decode(&data_bytes, scalar, big_endian, 1.0, 0.0);
    let unit = guess_unit(&data, scalar);
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::Nrrd,
        series: None,
        phase: Default::default(),
        warnings,
    })
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

/// `(a,b,c) (d,e,f) …` → vectors.
fn parse_vectors(s: &str, path: &Path, what: &str) -> Result<Vec<[f64; 3]>, VolumeError> {
    s.split(')')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| {
            let inner = t.trim_start_matches('(');
            if t == "none" || inner == t {
                return Err(VolumeError::invalid(
                    path,
                    format!("bad NRRD {what}: {s:?}"),
                ));
            }
            let v: Vec<f64> = inner
                .split(',')
                .map(|x| parse_num(x, path, what))
                .collect::<Result<_, _>>()?;
            <[f64; 3]>::try_from(v)
                .map_err(|_| VolumeError::invalid(path, format!("NRRD {what} needs 3-vectors")))
        })
        .collect()
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
