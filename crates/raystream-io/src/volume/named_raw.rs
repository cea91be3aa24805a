//! Raw voxel files named by their size and type, as the Open SciVis Datasets collection hands
//! them out: `NAME_WxHxD_TYPE.raw` (e.g. `bonsai_256x256x256_uint8.raw`), the voxels one after
//! another, x fastest, little-endian, and nothing else; optionally gzipped (`.raw.gz`). Written
//! by hand: the format is a file name, and no crate reads that.
//!
//! Such a file states no spacing or orientation. It is read as the NIfTI versions of the same
//! scans are laid out (neurolabusc/VolumeRenderingData): 1 mm voxels, the i, j, k axes along
//! RAS (the patient's right, anterior, superior), the grid about the origin. A NRRD header
//! (`.nhdr`) that names the file as its `data file` gives it any other geometry.

use std::io::Read;
use std::path::Path;

use super::nifti::guess_unit;
use super::raw::{Scalar, decode, open_payload, read_exact_n, read_file};
use super::{Phase, Volume, VolumeError, VolumeFormat, voxel_count};

/// The voxel grid and type a raw file's name states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct NamedRaw {
    pub dims: [usize; 3],
    pub scalar: Scalar,
    pub gzip: bool,
}

/// What a raw file's name must look like, for errors.
const NAMING: &str = "a raw volume's name gives its size and type, as the Open SciVis datasets' \
     do: NAME_WxHxD_TYPE.raw, e.g. bonsai_256x256x256_uint8.raw (TYPE: uint8, int8, uint16, \
     int16, uint32, int32, uint64, int64, float32 or float64); or write a .nhdr header that \
     names it as its data file";

/// Reads the size and type from a file name `NAME_WxHxD_TYPE.raw` (or `.raw.gz`), case aside.
pub(crate) fn parse_name(path: &Path) -> Result<NamedRaw, VolumeError> {
    let bad = |why: String| VolumeError::invalid(path, format!("{why}: {NAMING}"));
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| bad("the file name is not text".into()))?
        .to_ascii_lowercase();
    let (stem, gzip) = if let Some(s) = name.strip_suffix(".raw.gz") {
        (s, true)
    } else if let Some(s) = name.strip_suffix(".raw") {
        (s, false)
    } else {
        return Err(bad("not a .raw file".into()));
    };
    let mut parts = stem.rsplitn(3, '_');
    let (type_name, size) = match (parts.next(), parts.next()) {
        (Some(t), Some(s)) => (t, s),
        _ => return Err(bad(format!("{name:?} does not name a size and a type"))),
    };
    let scalar = scalar_of(type_name)
        .ok_or_else(|| bad(format!("{type_name:?} in {name:?} is not a voxel type")))?;
    let sides: Vec<usize> = size
        .split('x')
        .map(|s| s.parse().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .filter(|v: &Vec<usize>| v.len() == 3)
        .ok_or_else(|| bad(format!("{size:?} in {name:?} is not a size WxHxD")))?;
    Ok(NamedRaw {
        dims: [sides[0], sides[1], sides[2]],
        scalar,
        gzip,
    })
}

fn scalar_of(t: &str) -> Option<Scalar> {
    Some(match t {
        "uint8" => Scalar::U8,
        "int8" => Scalar::I8,
        "uint16" => Scalar::U16,
        "int16" => Scalar::I16,
        "uint32" => Scalar::U32,
        "int32" => Scalar::I32,
        "uint64" => Scalar::U64,
        "int64" => Scalar::I64,
        "float32" => Scalar::F32,
        "float64" => Scalar::F64,
        _ => return None,
    })
}

/// Reads a raw volume named `NAME_WxHxD_TYPE.raw[.gz]`. Its bytes must be exactly the voxels the
/// name implies: a file shorter or longer is refused, since either means the name is wrong.
pub(crate) fn load(path: &Path, phase: Option<usize>) -> Result<Volume, VolumeError> {
    let named = parse_name(path)?;
    let mut warnings = vec![
        "a raw file states no spacing or orientation: 1 mm voxels, its axes along the patient's \
         right, anterior and superior (a .nhdr header naming it as its data file gives others)"
            .to_string(),
    ];
    let phase = Phase::pick(path, phase, 1, &mut warnings)?;
    let n = voxel_count(path, named.dims)?;
    let nbytes = n.saturating_mul(named.scalar.size());
    let what = "the raw voxel data";
    let bytes = if named.gzip {
        let file = read_file(path)?;
        let mut r = open_payload(&file, 0, true, path)?;
        let voxels = read_exact_n(&mut r, nbytes, path, what)?;
        let mut more = [0u8; 1];
        if r.read(&mut more).is_ok_and(|m| m > 0) {
            return Err(too_long(path, &named, nbytes, None));
        }
        voxels
    } else {
        // Checked before reading, so a name claiming 10⁶ slices costs no memory.
        let len = std::fs::metadata(path)
            .map_err(|e| VolumeError::io(path, e))?
            .len();
        if len != nbytes as u64 {
            return Err(if len < nbytes as u64 {
                VolumeError::invalid(
                    path,
                    format!(
                        "{what} is truncated: the name implies {nbytes} bytes ({} voxels of {} \
                         bytes), the file holds {len}",
                        dims_text(&named),
                        named.scalar.size()
                    ),
                )
            } else {
                too_long(path, &named, nbytes, Some(len))
            });
        }
        read_file(path)?
    };
    let data = decode(&bytes, named.scalar, false, 1.0, 0.0);
    let [nx, ny, nz] = named.dims.map(|d| d as f64);
    // RAS axes in LPS: i and j turn round, k stays. The voxel centres run from −n/2 to n/2 − 1
    // along each LPS axis, as in the NIfTI versions.
    let direction = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
    let origin = [nx / 2.0 - 1.0, ny / 2.0 - 1.0, -nz / 2.0];
    let unit = guess_unit(&data, named.scalar);
    Ok(Volume {
        dims: named.dims,
        spacing: [1.0; 3],
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::Raw,
        series: None,
        segments: Vec::new(),
        phase,
        warnings,
    })
}

fn dims_text(named: &NamedRaw) -> String {
    let [x, y, z] = named.dims;
    format!("{x}x{y}x{z}")
}

fn too_long(path: &Path, named: &NamedRaw, nbytes: usize, len: Option<u64>) -> VolumeError {
    let holds = len.map_or("more".to_string(), |l| l.to_string());
    VolumeError::invalid(
        path,
        format!(
            "the name implies {nbytes} bytes ({} voxels of {} bytes), the file holds {holds}: \
             a raw volume is its voxels alone, so its name gives the wrong size or type",
            dims_text(named),
            named.scalar.size()
        ),
    )
}
