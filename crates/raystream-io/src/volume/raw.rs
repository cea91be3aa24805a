//! Raw voxel payloads shared by the NIfTI, NRRD and MetaImage readers: scalar types, byte order,
//! gzip, and reading exactly the bytes a header implies — never more, and never allocating for
//! bytes that are not there.

use std::io::Read;
use std::path::Path;

use super::VolumeError;

/// A voxel's stored type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
}

impl Scalar {
    pub fn size(self) -> usize {
        match self {
            Scalar::U8 | Scalar::I8 => 1,
            Scalar::U16 | Scalar::I16 => 2,
            Scalar::U32 | Scalar::I32 | Scalar::F32 => 4,
            Scalar::U64 | Scalar::I64 | Scalar::F64 => 8,
        }
    }
}

/// Reads `n` bytes from `r` (a file or a gzip stream). Errors if fewer are there; allocates as
/// the bytes arrive, so a header that lies about the size costs no memory.
pub(crate) fn read_exact_n(
    r: &mut dyn Read,
    n: usize,
    path: &Path,
    what: &str,
) -> Result<Vec<u8>, VolumeError> {
    let mut out = Vec::with_capacity(n.min(64 << 20));
    r.take(n as u64)
        .read_to_end(&mut out)
        .map_err(|e| VolumeError::invalid(path, format!("reading {what}: {e}")))?;
    if out.len() < n {
        return Err(VolumeError::invalid(
            path,
            format!(
                "{what} is truncated: the header implies {n} bytes, the file holds {}",
                out.len()
            ),
        ));
    }
    Ok(out)
}

/// Reads `n` bytes from `r` a chunk of `chunk` bytes at a time into one buffer, handing each to
/// `take` with its offset: a payload scanned as it streams, never held whole. Errors as
/// [`read_exact_n`] does if fewer are there.
pub(crate) fn read_in_chunks(
    r: &mut dyn Read,
    n: usize,
    chunk: usize,
    path: &Path,
    what: &str,
    mut take: impl FnMut(usize, &[u8]) -> Result<(), VolumeError>,
) -> Result<(), VolumeError> {
    let mut buffer = vec![0u8; chunk.min(n)];
    let mut at = 0;
    while at < n {
        let want = chunk.min(n - at);
        let mut got = 0;
        while got < want {
            match r.read(&mut buffer[got..want]) {
                Ok(0) => {
                    return Err(VolumeError::invalid(
                        path,
                        format!(
                            "{what} is truncated: the header implies {n} bytes, the file holds {}",
                            at + got
                        ),
                    ));
                }
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(VolumeError::invalid(path, format!("reading {what}: {e}")));
                }
            }
        }
        take(at, &buffer[..want])?;
        at += want;
    }
    Ok(())
}

/// Where the values of one phase lie in a 4-D payload: the phase axis has `count` positions,
/// the axes before it make runs of `inner` values, the axes after it `outer` such runs. Time
/// last (NIfTI, MetaImage, ITK's NRRD): `outer` = 1; a list axis first (3D Slicer's
/// sequences): `inner` = 1. A 3-D payload is one phase of `count` 1.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PhaseLayout {
    pub inner: usize,
    pub count: usize,
    pub outer: usize,
}

impl PhaseLayout {
    /// `count` volumes of `n` values one after another (time last); one is a 3-D payload.
    pub fn time_last(n: usize, count: usize) -> PhaseLayout {
        PhaseLayout {
            inner: n,
            count,
            outer: 1,
        }
    }
}

/// Reads the bytes of phase `index` (from 0) of `layout`, values of `size` bytes, streaming:
/// the other phases are skipped as they pass, and memory grows only with the bytes kept.
pub(crate) fn read_phase(
    r: &mut dyn Read,
    layout: PhaseLayout,
    index: usize,
    size: usize,
    path: &Path,
    what: &str,
) -> Result<Vec<u8>, VolumeError> {
    let run = layout.inner * size;
    // Byte counts of a header's lying sizes saturate: skipping them runs into the file's end.
    let bytes = |runs: usize| (runs as u64).saturating_mul(run as u64);
    if layout.outer == 1 {
        skip_n(r, bytes(index), path)?;
        return read_exact_n(r, run, path, what);
    }
    let truncated = || {
        VolumeError::invalid(
            path,
            format!(
                "{what} is truncated: the header implies {} bytes, the file holds fewer",
                bytes(layout.count).saturating_mul(layout.outer as u64)
            ),
        )
    };
    let mut r = std::io::BufReader::with_capacity(1 << 16, r);
    let mut out = Vec::with_capacity(run.saturating_mul(layout.outer).min(64 << 20));
    let group_bytes = bytes(layout.count);
    if group_bytes <= 1 << 16 {
        // Runs of a few values (a list axis first): a whole group of phases at a time.
        let mut group = vec![0u8; group_bytes as usize];
        for _ in 0..layout.outer {
            r.read_exact(&mut group).map_err(|_| truncated())?;
            out.extend_from_slice(&group[index * run..(index + 1) * run]);
        }
    } else {
        for _ in 0..layout.outer {
            skip_n(&mut r, bytes(index), path).map_err(|_| truncated())?;
            let kept = out.len();
            (&mut r)
                .take(run as u64)
                .read_to_end(&mut out)
                .map_err(|e| VolumeError::invalid(path, format!("reading {what}: {e}")))?;
            if out.len() - kept < run {
                return Err(truncated());
            }
            skip_n(&mut r, bytes(layout.count - 1 - index), path).map_err(|_| truncated())?;
        }
    }
    Ok(out)
}

/// Skips `n` bytes of `r`, erroring if the stream ends first.
pub(crate) fn skip_n(r: &mut dyn Read, n: u64, path: &Path) -> Result<(), VolumeError> {
    let skipped = std::io::copy(&mut r.take(n), &mut std::io::sink())
        .map_err(|e| VolumeError::invalid(path, format!("skipping to the voxel data: {e}")))?;
    if skipped < n {
        return Err(VolumeError::invalid(
            path,
            format!("file ends before the voxel data (offset {n})"),
        ));
    }
    Ok(())
}

/// One value of `scalar` from its bytes `c`, exactly (every stored type fits f64 but 8-byte
/// integers beyond 2⁵³).
#[inline(always)]
pub(crate) fn value(c: &[u8], scalar: Scalar, big_endian: bool) -> f64 {
    macro_rules! get {
        ($t:ty) => {{
            let a = c.try_into().unwrap();
            if big_endian {
                <$t>::from_be_bytes(a) as f64
            } else {
                <$t>::from_le_bytes(a) as f64
            }
        }};
    }
    match scalar {
        Scalar::U8 => c[0] as f64,
        Scalar::I8 => c[0] as i8 as f64,
        Scalar::U16 => get!(u16),
        Scalar::I16 => get!(i16),
        Scalar::U32 => get!(u32),
        Scalar::I32 => get!(i32),
        Scalar::U64 => get!(u64),
        Scalar::I64 => get!(i64),
        Scalar::F32 => get!(f32),
        Scalar::F64 => get!(f64),
    }
}

/// Decodes `bytes` (exactly `count` values of `scalar`) to `value·slope + intercept` as f32.
pub(crate) fn decode(
    bytes: &[u8],
    scalar: Scalar,
    big_endian: bool,
    slope: f64,
    intercept: f64,
) -> Vec<f32> {
    use rayon::prelude::*;
    let size = scalar.size();
    let convert = |c: &[u8]| value(c, scalar, big_endian);
    if slope == 1.0 && intercept == 0.0 {
        bytes
            .par_chunks_exact(size)
            .map(|c| convert(c) as f32)
            .collect()
    } else {
        bytes
            .par_chunks_exact(size)
            .map(|c| (convert(c) * slope + intercept) as f32)
            .collect()
    }
}

/// A reader over a file's bytes from `offset`, gunzipped when `gzip`.
pub(crate) fn open_payload<'a>(
    bytes: &'a [u8],
    offset: usize,
    gzip: bool,
    path: &Path,
) -> Result<Box<dyn Read + 'a>, VolumeError> {
    let rest = bytes.get(offset..).ok_or_else(|| {
        VolumeError::invalid(
            path,
            format!(
                "voxel data offset {offset} is past the end of the file ({} bytes)",
                bytes.len()
            ),
        )
    })?;
    Ok(if gzip {
        Box::new(flate2::read::MultiGzDecoder::new(rest))
    } else {
        Box::new(rest)
    })
}

/// Reads a whole file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, VolumeError> {
    std::fs::read(path).map_err(|e| VolumeError::io(path, e))
}

/// Fixed-offset numbers from a header of known byte order.
pub(crate) struct Bytes<'a> {
    pub data: &'a [u8],
    pub big_endian: bool,
}

macro_rules! bytes_getter {
    ($name:ident, $t:ty) => {
        pub fn $name(&self, o: usize) -> $t {
            let b = self.data[o..o + size_of::<$t>()].try_into().unwrap();
            if self.big_endian {
                <$t>::from_be_bytes(b)
            } else {
                <$t>::from_le_bytes(b)
            }
        }
    };
}

impl Bytes<'_> {
    bytes_getter!(u16, u16);
    bytes_getter!(i16, i16);
    bytes_getter!(u32, u32);
    bytes_getter!(i32, i32);
    bytes_getter!(i64, i64);
    bytes_getter!(f64, f64);
}
