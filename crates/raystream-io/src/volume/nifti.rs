//! NIfTI-1 and NIfTI-2 single-file volumes (`.nii`, `.nii.gz`).
//!
//! NIfTI-1 headers are parsed by the `nifti` crate. It does not know NIfTI-2 (540-byte header,
//! 64-bit fields), so that header is decoded here from the fixed offsets of the standard; the
//! voxel payload is read here for both, so that only the bytes actually present get allocated.
//! Orientation: the sform if `sform_code > 0`, else the qform if `qform_code > 0`, else pixdim
//! spacing on the identity (with a warning); NIfTI's RAS+ world is turned into LPS by negating x, y.

use std::io::Read;
use std::path::Path;

use super::raw::{
    Bytes, PhaseLayout, Scalar, decode, open_payload, read_exact_n, read_phase, skip_n,
};
use super::{
    Phase, SegmentLabel, ValueUnit, Volume, VolumeError, VolumeFormat, check_geometry,
    is_orthonormal, unit_columns, voxel_count,
};

/// The header fields raystream uses, widened to the NIfTI-2 types.
struct Header {
    dim: [i64; 8],
    datatype: i16,
    pixdim: [f64; 8],
    vox_offset: f64,
    scl_slope: f64,
    scl_inter: f64,
    qform_code: i32,
    sform_code: i32,
    quatern: [f64; 3],
    qoffset: [f64; 3],
    srow: [[f64; 4]; 3],
    big_endian: bool,
}

/// Parses a `.nii` / `.nii.gz` file's bytes; `path` names it in errors. Of a 4-D (or higher)
/// image, the 3-D volume `phase` (from 1, default 1) is read: the volumes follow each other in
/// the file, the fourth axis first.
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    let (mut v, x, mut r) = open(bytes, path, phase)?;
    v.data = x.values(&mut r, path)?;
    v.unit = guess_unit(&v.data, x.scalar);
    Ok(v)
}

/// Where a NIfTI file's voxels lie after its header and how they read: the phase asked among
/// the volumes that follow each other, and the payload's fields (its bytes not yet read).
pub(crate) struct Voxels {
    pub layout: PhaseLayout,
    /// The phase read, from 0.
    pub index: usize,
    pub scalar: Scalar,
    pub big_endian: bool,
    pub slope: f64,
    pub intercept: f64,
}

impl Voxels {
    /// Their values, scaled, read from `r` at the first of them (`path` names the file).
    pub fn values(&self, r: &mut dyn Read, path: &Path) -> Result<Vec<f32>, VolumeError> {
        let bytes = read_phase(r, self.layout, self.index, self.scalar.size(), path, VOXELS)?;
        Ok(decode(
            &bytes,
            self.scalar,
            self.big_endian,
            self.slope,
            self.intercept,
        ))
    }
}

/// What the voxels are named as in errors.
pub(crate) const VOXELS: &str = "the NIfTI voxel data";

/// [`parse`]'s volume without its values, how its voxels lie, and a reader at the first of
/// them (the file's bytes gunzipped as they are read): for one that streams them.
pub(crate) fn open<'a>(
    bytes: &'a [u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<(Volume, Voxels, Box<dyn Read + 'a>), VolumeError> {
    let gzip = bytes.starts_with(&[0x1f, 0x8b]);
    let mut r = open_payload(bytes, 0, gzip, path)?;
    let first = read_exact_n(&mut r, 4, path, "the NIfTI header")?;
    let size_le = i32::from_le_bytes(first[..4].try_into().unwrap());
    let size_be = i32::from_be_bytes(first[..4].try_into().unwrap());
    let (hdr_len, big_endian) = match (size_le, size_be) {
        (348, _) => (348, false),
        (_, 348) => (348, true),
        (540, _) => (540, false),
        (_, 540) => (540, true),
        _ => {
            return Err(VolumeError::invalid(
                path,
                format!("not a NIfTI file (header size field {size_le}, expected 348 or 540)"),
            ));
        }
    };
    let rest = read_exact_n(&mut r, hdr_len - 4, path, "the NIfTI header")?;
    let mut raw = first;
    raw.extend_from_slice(&rest);
    let h = if hdr_len == 348 {
        parse_nifti1(&raw, path)?
    } else {
        parse_nifti2(&raw, big_endian, path)?
    };
    let (v, x) = build(path, h, &mut r, hdr_len, phase)?;
    Ok((v, x, r))
}

fn parse_nifti1(raw: &[u8], path: &Path) -> Result<Header, VolumeError> {
    let h = nifti::NiftiHeader::from_reader(raw)
        .map_err(|e| VolumeError::invalid(path, format!("invalid NIfTI-1 header: {e}")))?;
    if &h.magic[..3] != b"n+1" {
        return Err(VolumeError::invalid(
            path,
            format!(
                "NIfTI-1 magic is {:?}, expected \"n+1\" (a .hdr/.img pair is not supported)",
                String::from_utf8_lossy(&h.magic[..3])
            ),
        ));
    }
    Ok(Header {
        dim: h.dim.map(|d| d as i16 as i64),
        datatype: h.datatype,
        pixdim: h.pixdim.map(f64::from),
        vox_offset: h.vox_offset as f64,
        scl_slope: h.scl_slope as f64,
        scl_inter: h.scl_inter as f64,
        qform_code: h.qform_code as i32,
        sform_code: h.sform_code as i32,
        quatern: [h.quatern_b, h.quatern_c, h.quatern_d].map(f64::from),
        qoffset: [h.quatern_x, h.quatern_y, h.quatern_z].map(f64::from),
        srow: [h.srow_x, h.srow_y, h.srow_z].map(|r| r.map(f64::from)),
        big_endian: h.endianness == nifti::Endianness::Big,
    })
}

/// NIfTI-2: offsets from the standard's `nifti2.h` (540 bytes, no padding).
fn parse_nifti2(raw: &[u8], big_endian: bool, path: &Path) -> Result<Header, VolumeError> {
    if &raw[4..7] != b"n+2" {
        return Err(VolumeError::invalid(
            path,
            "NIfTI-2 magic is not \"n+2\" (a .hdr/.img pair is not supported)",
        ));
    }
    let b = Bytes {
        data: raw,
        big_endian,
    };
    let (f64_at, i64_at, i32_at, i16_at) = (|o| b.f64(o), |o| b.i64(o), |o| b.i32(o), |o| b.i16(o));
    Ok(Header {
        datatype: i16_at(12),
        dim: std::array::from_fn(|i| i64_at(16 + 8 * i)),
        pixdim: std::array::from_fn(|i| f64_at(104 + 8 * i)),
        vox_offset: i64_at(168) as f64,
        scl_slope: f64_at(176),
        scl_inter: f64_at(184),
        qform_code: i32_at(344),
        sform_code: i32_at(348),
        quatern: std::array::from_fn(|i| f64_at(352 + 8 * i)),
        qoffset: std::array::from_fn(|i| f64_at(376 + 8 * i)),
        srow: std::array::from_fn(|r| std::array::from_fn(|c| f64_at(400 + 32 * r + 8 * c))),
        big_endian,
    })
}

fn scalar_of(datatype: i16) -> Option<Scalar> {
    Some(match datatype {
        2 => Scalar::U8,
        4 => Scalar::I16,
        8 => Scalar::I32,
        16 => Scalar::F32,
        64 => Scalar::F64,
        256 => Scalar::I8,
        512 => Scalar::U16,
        768 => Scalar::U32,
        1024 => Scalar::I64,
        1280 => Scalar::U64,
        _ => return None,
    })
}

/// The volume header `h` describes (its values not read) and how its voxels lie, its
/// extensions read from `r` (a label table among them), leaving `r` at the first voxel.
fn build(
    path: &Path,
    h: Header,
    r: &mut dyn Read,
    hdr_len: usize,
    phase: Option<usize>,
) -> Result<(Volume, Voxels), VolumeError> {
    let mut warnings = Vec::new();
    let ndim = h.dim[0];
    if !(1..=7).contains(&ndim) {
        return Err(VolumeError::invalid(
            path,
            format!("dim[0] = {ndim}, expected 1..7"),
        ));
    }
    let d = |i: usize| if (i as i64) <= ndim { h.dim[i] } else { 1 };
    if (1..=3).any(|i| d(i) < 1) {
        return Err(VolumeError::invalid(
            path,
            format!("dimensions {:?} are not positive", &h.dim[1..=3]),
        ));
    }
    let dims = [d(1), d(2), d(3)].map(|v| v as usize);
    // The 3-D volumes of a 4-D (or higher) image: dims 4 to 7 together, as one list.
    let volumes = (4..=7)
        .map(|i| d(i).max(1) as u64)
        .try_fold(1u64, u64::checked_mul)
        .filter(|&v| v <= u32::MAX as u64)
        .ok_or_else(|| {
            VolumeError::invalid(
                path,
                format!(
                    "dimensions {:?} claim too many volumes",
                    &h.dim[1..=ndim as usize]
                ),
            )
        })? as usize;
    let phase = Phase::pick(path, phase, volumes, &mut warnings)?;
    let n = voxel_count(path, dims)?;
    let scalar = scalar_of(h.datatype).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "NIfTI datatype {} is not a scalar raystream reads (RGB, complex, bit data are not CT)",
                h.datatype
            ),
        )
    })?;

    // Orientation, in RAS, as a 3×3 (columns = axis vectors incl. spacing) and a translation.
    let (axes_ras, offset_ras): ([[f64; 3]; 3], [f64; 3]) = if h.sform_code > 0 {
        let m: [[f64; 3]; 3] = std::array::from_fn(|r| std::array::from_fn(|c| h.srow[r][c]));
        (m, [h.srow[0][3], h.srow[1][3], h.srow[2][3]])
    } else if h.qform_code > 0 {
        let [b, c, dd] = h.quatern;
        let a = (1.0 - (b * b + c * c + dd * dd)).max(0.0).sqrt();
        let rot = [
            [
                a * a + b * b - c * c - dd * dd,
                2.0 * (b * c - a * dd),
                2.0 * (b * dd + a * c),
            ],
            [
                2.0 * (b * c + a * dd),
                a * a + c * c - b * b - dd * dd,
                2.0 * (c * dd - a * b),
            ],
            [
                2.0 * (b * dd - a * c),
                2.0 * (c * dd + a * b),
                a * a + dd * dd - c * c - b * b,
            ],
        ];
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let sp = [
            h.pixdim[1].abs(),
            h.pixdim[2].abs(),
            h.pixdim[3].abs() * qfac,
        ];
        let m = std::array::from_fn(|r| std::array::from_fn(|c| rot[r][c] * sp[c]));
        (m, h.qoffset)
    } else {
        warnings.push("no sform or qform: orientation unknown, assuming RAS axes".into());
        let sp = [h.pixdim[1].abs(), h.pixdim[2].abs(), h.pixdim[3].abs()];
        let m = std::array::from_fn(|r| std::array::from_fn(|c| if r == c { sp[c] } else { 0.0 }));
        (m, [0.0; 3])
    };
    // RAS → LPS: negate the first two rows.
    let lps = |r: usize| if r < 2 { -1.0 } else { 1.0 };
    let axes: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|c| axes_ras[r][c] * lps(r)));
    let origin = std::array::from_fn(|r| offset_ras[r] * lps(r));
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal (sheared sform)".into());
    }

    let offset = h.vox_offset.max(hdr_len as f64);
    if !offset.is_finite() || offset > u32::MAX as f64 {
        return Err(VolumeError::invalid(
            path,
            format!("vox_offset {} is invalid", h.vox_offset),
        ));
    }
    // The extensions between the header and the voxels: read (up to 16 MiB of them) for a
    // label table, else skipped.
    let gap = offset as u64 - hdr_len as u64;
    let mut segments = Vec::new();
    if gap <= MAX_EXTENSIONS {
        let ext = read_exact_n(r, gap as usize, path, "the NIfTI header's extensions")?;
        match label_table(&ext, h.big_endian) {
            Ok(table) => segments = table,
            Err(why) => warnings.push(format!(
                "its label table (a header extension) is not read: {why}"
            )),
        }
    } else {
        skip_n(r, gap, path)?;
    }
    // The volumes follow each other: those before the phase read are skipped, not kept.
    let layout = PhaseLayout::time_last(n, phase.count);
    // scl_slope 0 or NaN means "no scaling" (NIfTI-1 standard).
    let (slope, inter) = if h.scl_slope == 0.0 || !h.scl_slope.is_finite() {
        (1.0, 0.0)
    } else {
        (
            h.scl_slope,
            if h.scl_inter.is_finite() {
                h.scl_inter
            } else {
                0.0
            },
        )
    };
    let v = Volume {
        dims,
        spacing,
        origin,
        direction,
        data: Vec::new(),
        unit: ValueUnit::Unknown,
        format: VolumeFormat::Nifti,
        series: None,
        segments,
        phase,
        warnings,
    };
    let voxels = Voxels {
        layout,
        index: phase.index - 1,
        scalar,
        big_endian: h.big_endian,
        slope,
        intercept: inter,
    };
    Ok((v, voxels))
}

/// The most bytes of header extensions read for a label table; beyond, they are skipped.
const MAX_EXTENSIONS: u64 = 16 << 20;

/// The label names and colours a NIfTI header extension gives: the XML label table of
/// Connectome Workbench's (Caret's) label volumes, which TotalSegmentator writes into its
/// multi-label files (`--ml`): `<LabelTable><Label Key="1" Red="1" Green="0" Blue="0"
/// Alpha="1"><![CDATA[spleen]]></Label>…`. `ext`: the bytes from the header's end to the
/// voxels (the 4-byte extender, then extensions of esize, ecode and esize − 8 bytes of
/// content). None found: no labels; a table that cannot be read: why.
fn label_table(ext: &[u8], big_endian: bool) -> Result<Vec<SegmentLabel>, String> {
    if ext.len() < 4 || ext[0] == 0 {
        return Ok(Vec::new());
    }
    let i32_at = |at: usize| -> i32 {
        let b: [u8; 4] = ext[at..at + 4].try_into().unwrap_or_default();
        if big_endian {
            i32::from_be_bytes(b)
        } else {
            i32::from_le_bytes(b)
        }
    };
    let mut at = 4;
    while at + 8 <= ext.len() {
        let size = i32_at(at);
        if size < 8 || at + size as usize > ext.len() {
            // A lying size: no more extensions to read.
            break;
        }
        let content = &ext[at + 8..at + size as usize];
        at += size as usize;
        let text = String::from_utf8_lossy(content);
        let text = text.trim_end_matches(['\0', ' ', '\n']);
        if !text.contains("<LabelTable") {
            continue;
        }
        let doc = roxmltree::Document::parse(text).map_err(|e| format!("its XML: {e}"))?;
        let mut labels = Vec::new();
        for label in doc.descendants().filter(|n| n.has_tag_name("Label")) {
            let key = label.attribute("Key").unwrap_or("");
            let number = match key.trim().parse::<u16>() {
                Ok(0) => continue,
                Ok(n) => n,
                Err(_) => {
                    return Err(format!(
                        "a label's Key {key:?} is not a number from 0 to 65535"
                    ));
                }
            };
            let channel = |name: &str| -> Option<u8> {
                let v: f64 = label.attribute(name)?.trim().parse().ok()?;
                (0.0..=1.0).contains(&v).then(|| (v * 255.0).round() as u8)
            };
            let colour = match (channel("Red"), channel("Green"), channel("Blue")) {
                (Some(r), Some(g), Some(b)) => Some([r, g, b]),
                _ => None,
            };
            let name: String = label.text().unwrap_or("").trim().to_string();
            labels.push(SegmentLabel {
                number,
                label: if name.is_empty() {
                    format!("{number}")
                } else {
                    name
                },
                colour,
                terms: Default::default(),
            });
        }
        labels.sort_by_key(|l| l.number);
        if let Some(w) = labels.windows(2).find(|w| w[0].number == w[1].number) {
            return Err(format!("two labels have the Key {}", w[0].number));
        }
        return Ok(labels);
    }
    Ok(Vec::new())
}

/// NIfTI, NRRD and MetaImage do not state a unit. A signed volume that reaches air (≤ −900)
/// is taken to be CT in Hounsfield units; anything else is reported as unknown.
pub(crate) fn guess_unit(data: &[f32], scalar: Scalar) -> ValueUnit {
    let signed = !matches!(scalar, Scalar::U8 | Scalar::U16 | Scalar::U32 | Scalar::U64);
    let min = data.iter().copied().fold(f32::INFINITY, f32::min);
    if signed && (-4096.0..=-900.0).contains(&min) {
        ValueUnit::Hounsfield
    } else {
        ValueUnit::Unknown
    }
}
