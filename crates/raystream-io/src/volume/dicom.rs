//! DICOM CT series: a folder of slices, or one file (a slice, or an enhanced multi-frame image
//! whose functional groups place each frame) → one [`Volume`].
//!
//! Parsing and pixel decoding are dicom-rs (`dicom-object`, `dicom-pixeldata`: uncompressed,
//! deflate, RLE, JPEG via jpeg-decoder, JPEG 2000 via the pure-Rust `openjp2`). JPEG-LS is
//! decoded here with the pure-Rust `pure_jpegls` (dicom-rs's own JPEG-LS adapter needs the C++
//! CharLS, built with cmake), and 12-bit lossy JPEG, which jpeg-decoder refuses, with the
//! pure-Rust `libjpeg-turbo-rs`, into native pixel data that dicom-pixeldata then converts like
//! any other, so that sign, bits stored and rescale are handled in one place.
//!
//! The file meta group (group 0002) is read here rather than by dicom-rs's `open_file`, which
//! rejects meta elements whose value is longer than their VR allows (e.g. a 18-character
//! SourceApplicationEntityTitle, as 13 of the 15 transfer-syntax samples have): only the transfer
//! syntax UID is taken from it, and the data set is parsed with that syntax.
//!
//! Series assembly follows the standard's geometry, never file names or InstanceNumber: slices
//! are grouped by SeriesInstanceUID, sorted by ImagePositionPatient projected on the slice normal
//! (row × column of ImageOrientationPatient), and the slice spacing comes from those positions.
//! A gantry-tilted series (positions stacked along the table, not the normal) becomes a sheared
//! grid, and one with uneven spacing is interpolated onto a regular one ([`Stack`]); the volume's
//! warnings say which, so that no geometry is silently wrong or silently invented.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use dicom_pixeldata::PixelDecoder;
use dicom_transfer_syntax_registry::{TransferSyntaxIndex, TransferSyntaxRegistry};
use rayon::prelude::*;

use super::{
    Phase, ValueUnit, Volume, VolumeError, VolumeFormat, VolumeSelect, check_geometry, voxel_count,
};

/// The series a DICOM volume was read from, and the other series in its folder.
#[derive(Clone, Debug, Default)]
pub struct DicomSeriesInfo {
    pub uid: String,
    pub description: String,
    pub modality: String,
    /// Slices (files) in the series.
    pub count: usize,
    /// Transfer syntax UID and name of the series' files (the first file's, if they differ).
    pub transfer_syntax: String,
    pub transfer_syntax_name: String,
    /// Every series found in the folder: (UID, slice count, description).
    pub all: Vec<(String, usize, String)>,
    /// The patient and study the series belongs to (its first slice's).
    pub study: DicomStudy,
    /// The acquired image each of the volume's slices is, in the grid's order (k): what an
    /// object derived slice by slice (a segmentation) references. Empty where the grid's
    /// slices were interpolated between the acquired ones (uneven spacing).
    pub sources: Vec<SourceImage>,
}

/// A segment of a label file as read (a DICOM Segmentation's, an RT Structure Set's
/// structure, a 3D Slicer segmentation's): its number (its voxels' value in the label
/// volume), its name, the colour it recommends showing it in (sRGB; `None` where it gives
/// none), and what it is, coded (`None` where the file does not say).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SegmentLabel {
    pub number: u16,
    pub label: String,
    pub colour: Option<[u8; 3]>,
    pub terms: SegmentTerms,
}

/// What a segment is, as coded concepts (SNOMED CT's, mostly): a DICOM Segmentation's
/// Segmented Property Category, Type and Type Modifier, and the Anatomic Region it lies in with
/// that region's modifier; or the same five of a 3D Slicer segment's `TerminologyEntry` tag.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SegmentTerms {
    /// What kind of thing: "Anatomical Structure", "Tissue", "Morphologically Altered
    /// Structure"…
    pub category: Option<crate::ReadCode>,
    /// Which: "Rib", "Aorta", "Mass"…
    pub kind: Option<crate::ReadCode>,
    /// Its side or part: "Right", "Left"…
    pub modifier: Option<crate::ReadCode>,
    /// Where it lies, where its type does not say: a "Mass" in the "Liver", a "Calcification"
    /// in the "Aortic valve".
    pub region: Option<crate::ReadCode>,
    /// The region's side or part: the "Right" kidney.
    pub region_modifier: Option<crate::ReadCode>,
}

/// One acquired image of a series: a file's SOP instance, and its frame in a multi-frame one.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SourceImage {
    pub sop_class_uid: String,
    pub sop_instance_uid: String,
    /// The frame, numbered from 1 as DICOM's Referenced Frame Number; `None` in a single-frame
    /// image.
    pub frame: Option<u32>,
}

/// The patient and study of a DICOM series: what an image derived from it (a rendering saved
/// as DICOM) carries over so that it files with the study. Empty strings where the file has
/// nothing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DicomStudy {
    pub patient_name: String,
    pub patient_id: String,
    pub patient_birth_date: String,
    pub patient_sex: String,
    pub study_uid: String,
    pub study_date: String,
    pub study_time: String,
    pub study_id: String,
    pub accession_number: String,
    pub referring_physician: String,
    pub study_description: String,
    /// The series' Frame of Reference UID: a derived image in the same patient coordinates
    /// (a reformatted slice) shares it, so that viewers can cross-reference the two.
    pub frame_of_reference_uid: String,
}

impl DicomStudy {
    pub(crate) fn of(obj: &InMemDicomObject) -> DicomStudy {
        let text = |tag| {
            obj.get(tag)
                .and_then(|e| e.to_str().ok())
                .map(|s| s.trim_end_matches(['\0', ' ']).trim().to_string())
                .unwrap_or_default()
        };
        DicomStudy {
            patient_name: text(tags::PATIENT_NAME),
            patient_id: text(tags::PATIENT_ID),
            patient_birth_date: text(tags::PATIENT_BIRTH_DATE),
            patient_sex: text(tags::PATIENT_SEX),
            study_uid: text(tags::STUDY_INSTANCE_UID),
            study_date: text(tags::STUDY_DATE),
            study_time: text(tags::STUDY_TIME),
            study_id: text(tags::STUDY_ID),
            accession_number: text(tags::ACCESSION_NUMBER),
            referring_physician: text(tags::REFERRING_PHYSICIAN_NAME),
            study_description: text(tags::STUDY_DESCRIPTION),
            frame_of_reference_uid: text(tags::FRAME_OF_REFERENCE_UID),
        }
    }
}

/// One parsed slice: its header fields and the object to decode pixels from.
#[derive(Default)]
pub(crate) struct Slice {
    file: PathBuf,
    series_uid: String,
    description: String,
    modality: String,
    /// The Frame of Reference its positions are in.
    frame_of_reference: String,
    ts_uid: String,
    /// The instance it is in (SOP Class and Instance UIDs; the file meta's where the data set's
    /// are blank).
    sop_class: String,
    sop_instance: String,
    pub(crate) rows: u32,
    pub(crate) cols: u32,
    /// The frame of a multi-frame file this slice is, numbered from 0 (`None`: a single-frame
    /// file).
    frame: Option<u32>,
    pub(crate) position: [f64; 3],
    /// Its temporal position in a 4-D series: a single-frame file's TemporalPositionIdentifier
    /// (0020,0100), an enhanced image frame's TemporalPositionIndex (0020,9128).
    temporal: Option<u32>,
    orientation: [f64; 6],
    pixel_spacing: [f64; 2],
    between_slices: Option<f64>,
    thickness: Option<f64>,
    /// What the volume's warnings should say about this file (only some frames read).
    note: Option<String>,
    /// The parsed data set, until decoded: a single-frame file's, or a multi-frame file's, held
    /// by the first frame read from it, which decodes them all ([`decode_all`]).
    obj: Option<InMemDicomObject>,
}

/// Lists the series in a DICOM folder: (UID, slice count, description), largest first.
pub fn list_dicom_series(path: &Path) -> Result<Vec<(String, usize, String)>, VolumeError> {
    let (slices, _) = read_folder(path)?;
    Ok(group(&slices))
}

/// The series in a DICOM folder with their Frames of Reference: (UID, slice count, Frame of
/// Reference UID), largest first.
pub(crate) fn series_and_frames(path: &Path) -> Result<Vec<(String, usize, String)>, VolumeError> {
    let (slices, _) = read_folder(path)?;
    Ok(group(&slices)
        .into_iter()
        .map(|(uid, n, _)| {
            let frame = slices
                .iter()
                .find(|s| s.series_uid == uid)
                .map(|s| s.frame_of_reference.clone())
                .unwrap_or_default();
            (uid, n, frame)
        })
        .collect())
}

pub(crate) fn load(path: &Path, select: &VolumeSelect) -> Result<Volume, VolumeError> {
    // A file is read and parsed once: a Segmentation, or an image's slices.
    let (slices, mut warnings) = if is_zip(path) {
        read_zip(path)?
    } else if path.is_file() {
        let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
        let (meta, obj) = parse_dataset(&bytes, path)?;
        if super::segmentation::is_segmentation(&meta, &obj) {
            return super::segmentation::read(path, &meta, &obj);
        }
        if super::structure_set::is_structure_set(&meta, &obj) {
            return super::structure_set::read_labels(path, &meta, &obj);
        }
        (slices_of(&meta, obj, path)?, Vec::new())
    } else {
        read_folder(path)?
    };
    // So far the warnings are the files skipped as unreadable; a problem with the series (a
    // gap, above all) is often one of them, so its error names them.
    let skipped = warnings.clone();
    let all = group(&slices);
    let uid = match select.series.as_deref() {
        Some(s) => all
            .iter()
            .find(|(u, _, _)| u == s)
            .map(|(u, _, _)| u.clone())
            .ok_or_else(|| {
                VolumeError::invalid(
                    path,
                    format!(
                        "no series with UID {s}; the folder holds: {}",
                        all.iter()
                            .map(|(u, n, d)| {
                                let u = if u.is_empty() {
                                    "(no SeriesInstanceUID)"
                                } else {
                                    u
                                };
                                format!("{u} ({n} slices{})", describe(d))
                            })
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?,
        None => {
            if all.len() > 1 {
                warnings.push(format!(
                    "{} series in the folder; reading the largest ({} slices); pick another with --series UID",
                    all.len(),
                    all[0].1
                ));
            }
            all[0].0.clone()
        }
    };
    let chosen: Vec<Slice> = slices.into_iter().filter(|s| s.series_uid == uid).collect();
    let (mut chosen, phase) = keep_phase(path, chosen, select.phase, &mut warnings)?;
    let mut volume = assemble(path, &mut chosen, all, warnings, !skipped.is_empty())
        .map_err(|e| mention_skipped(e, &skipped))?;
    volume.phase = phase;
    Ok(volume)
}

/// The slices of one temporal position (phase) of a series: the `requested` one (from 1), else
/// the first. A series is 4-D when its slices repeat positions: it is then split by their
/// temporal positions ([`Slice::temporal`]), in increasing order. A series without repeated
/// positions is one phase whatever its tags say, as a 3-D series has always been read. A
/// multi-frame file's parsed data set moves to a frame of it that is kept, which decodes it.
fn keep_phase(
    path: &Path,
    slices: Vec<Slice>,
    requested: Option<usize>,
    warnings: &mut Vec<String>,
) -> Result<(Vec<Slice>, Phase), VolumeError> {
    // Positions to a thousandth of a millimetre, as the stacking check tells them apart.
    let key = |s: &Slice| s.position.map(|v| (v * 1e3).round() as i64);
    let mut seen = std::collections::HashSet::new();
    let repeats = !slices.iter().all(|s| seen.insert(key(s)));
    let mut times: Vec<Option<u32>> = if repeats {
        slices.iter().map(|s| s.temporal).collect()
    } else {
        vec![None]
    };
    times.sort_unstable();
    times.dedup();
    let phase = Phase::pick(path, requested, times.len(), warnings)?;
    if times.len() == 1 {
        return Ok((slices, phase));
    }
    let chosen = times[phase.index - 1];
    let mut kept = Vec::new();
    let mut spare: std::collections::HashMap<PathBuf, InMemDicomObject> = Default::default();
    for mut s in slices {
        if s.temporal == chosen {
            kept.push(s);
        } else if let Some(obj) = s.obj.take() {
            spare.insert(s.file.clone(), obj);
        }
    }
    for s in &mut kept {
        if s.obj.is_none() {
            s.obj = spare.remove(&s.file);
        }
    }
    Ok((kept, phase))
}

/// `e`, with the files of the folder that were skipped as unreadable (`skipped`: "skipped
/// FILE: PROBLEM") added to its problem.
fn mention_skipped(e: VolumeError, skipped: &[String]) -> VolumeError {
    match (e, skipped) {
        (VolumeError::Invalid { path, problem }, [first, rest @ ..]) => VolumeError::Invalid {
            path,
            problem: format!(
                "{problem}; {} unreadable file{} in the folder: {first}{}",
                skipped.len(),
                if rest.is_empty() { " was" } else { "s were" },
                if rest.is_empty() { "" } else { "; …" }
            ),
        },
        (e, _) => e,
    }
}

fn describe(d: &str) -> String {
    if d.is_empty() {
        String::new()
    } else {
        format!(", {d:?}")
    }
}

/// Series UIDs with their slice counts, largest first (ties by UID, for a stable choice).
fn group(slices: &[Slice]) -> Vec<(String, usize, String)> {
    let mut map: std::collections::BTreeMap<&str, (usize, &str)> = Default::default();
    for s in slices {
        map.entry(&s.series_uid).or_insert((0, &s.description)).0 += 1;
    }
    let mut v: Vec<_> = map
        .into_iter()
        .map(|(u, (n, d))| (u.to_string(), n, d.to_string()))
        .collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    v
}

/// At most this many files are read from the folders below a folder that holds none of its
/// own (a CD's or a PACS export's tree): more is an error asking for the series' own folder,
/// not minutes of parsing a disk.
pub const MAX_TREE_FILES: usize = 1 << 17;
/// How many folders deep below such a folder its tree is searched (a CD's DICOM/ST000/SE000
/// is three).
pub const MAX_TREE_DEPTH: usize = 8;

/// A folder's files (not DICOMDIR, not hidden ones) and its folders (not those behind links,
/// which could lead back up the tree), each in path order.
fn folder_entries(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>), VolumeError> {
    let (mut files, mut dirs) = (Vec::new(), Vec::new());
    for entry in std::fs::read_dir(dir).map_err(|e| VolumeError::io(dir, e))? {
        let Ok(entry) = entry else { continue };
        let p = entry.path();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') {
            continue;
        }
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            dirs.push(p);
        } else if p.is_file() && !name.eq_ignore_ascii_case("DICOMDIR") {
            files.push(p);
        }
    }
    files.sort();
    dirs.sort();
    Ok((files, dirs))
}

/// The files to read from folder `path`: its own; where it holds none (a CD's root, with a
/// DICOMDIR beside a tree such as DICOM/ST000/SE000, or an export's patient/study/series
/// folders), those of the folders below it, as viewers import such trees, with a warning that
/// says so.
fn files_to_read(path: &Path) -> Result<(Vec<PathBuf>, Option<String>), VolumeError> {
    let (files, dirs) = folder_entries(path)?;
    if !files.is_empty() || dirs.is_empty() {
        return Ok((files, None));
    }
    let (mut found, mut folders) = (Vec::new(), 0usize);
    let mut pending: Vec<(PathBuf, usize)> = dirs.into_iter().rev().map(|d| (d, 1)).collect();
    while let Some((dir, depth)) = pending.pop() {
        let (files, dirs) = folder_entries(&dir)?;
        if !files.is_empty() {
            folders += 1;
        }
        found.extend(files);
        if found.len() > MAX_TREE_FILES {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "the folders below it hold more than {MAX_TREE_FILES} files: give the series' own folder"
                ),
            ));
        }
        if depth < MAX_TREE_DEPTH {
            pending.extend(dirs.into_iter().rev().map(|d| (d, depth + 1)));
        }
    }
    let note = format!(
        "it holds no file of its own: read the {} files in the {folders} folder{} below it",
        found.len(),
        if folders == 1 { "" } else { "s" }
    );
    Ok((found, Some(note)))
}

/// Parses every DICOM file of a folder (or the one file given; a folder with no file of its
/// own, the folders below it: [`files_to_read`]); files that are not DICOM are skipped with a
/// warning, a folder without any DICOM image is an error.
fn read_folder(path: &Path) -> Result<(Vec<Slice>, Vec<String>), VolumeError> {
    if is_zip(path) {
        return read_zip(path);
    }
    let (files, tree) = if path.is_dir() {
        files_to_read(path)?
    } else {
        (vec![path.to_path_buf()], None)
    };
    let mut found = Found {
        warnings: tree.into_iter().collect(),
        ..Default::default()
    };
    found.add(
        files.par_iter().map(|f| read_file(f)).collect(),
        path.is_dir(),
    );
    found.finish(path, path.is_dir(), "the folder")
}

/// The slices parsed so far from a folder's or an archive's files, the files skipped, and the
/// first problem.
#[derive(Default)]
struct Found {
    slices: Vec<Slice>,
    warnings: Vec<String>,
    first_error: Option<VolumeError>,
}

impl Found {
    /// Files' parses; where `many` (a folder, an archive), the files that are not DICOM images
    /// are skipped with a warning.
    fn add(&mut self, parsed: Vec<Result<Vec<Slice>, VolumeError>>, many: bool) {
        for r in parsed {
            match r {
                Ok(s) => self.slices.extend(s),
                Err(e) => {
                    if many {
                        self.warnings.push(format!("skipped {e}"));
                    }
                    self.first_error.get_or_insert(e);
                }
            }
        }
    }

    /// The slices and warnings; an error where no image was found in `path` (`what`: "the
    /// folder", "the archive").
    fn finish(
        self,
        path: &Path,
        many: bool,
        what: &str,
    ) -> Result<(Vec<Slice>, Vec<String>), VolumeError> {
        if !self.slices.is_empty() {
            return Ok((self.slices, self.warnings));
        }
        Err(match self.first_error {
            Some(e) if !many => e,
            Some(e) => VolumeError::invalid(
                path,
                format!("no readable DICOM image in {what} (first problem: {e})"),
            ),
            None if what == "the folder" => VolumeError::invalid(
                path,
                "the folder is empty (and no folder below it holds a file)",
            ),
            None => VolumeError::invalid(path, format!("{what} holds no file")),
        })
    }
}

/// At most this many bytes are unpacked from a ZIP (its files' sizes summed, as they unpack,
/// not as they claim): a larger study is unpacked by its user, not into memory here.
pub const MAX_ZIP_BYTES: u64 = 1 << 32;
/// A ZIP's files unpacked, then parsed in parallel, at a time.
const ZIP_BATCH: usize = 64;

/// Whether `path` is a ZIP archive (by its name).
fn is_zip(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("zip"))
}

/// Parses every DICOM file of a ZIP archive, as [`read_folder`] a folder's: its folders
/// flattened, DICOMDIR, hidden files and macOS's `__MACOSX` resource forks left out, every
/// other file that is not a DICOM image skipped with a warning. Files are named in errors as
/// `ARCHIVE.zip/PATH/IN/IT`.
fn read_zip(path: &Path) -> Result<(Vec<Slice>, Vec<String>), VolumeError> {
    read_zip_within(path, MAX_ZIP_BYTES)
}

/// [`read_zip`], unpacking at most `limit` bytes.
pub(crate) fn read_zip_within(
    path: &Path,
    limit: u64,
) -> Result<(Vec<Slice>, Vec<String>), VolumeError> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file))
        .map_err(|e| VolumeError::invalid(path, format!("not a readable ZIP archive: {e}")))?;
    if zip.len() > MAX_TREE_FILES {
        return Err(VolumeError::invalid(
            path,
            format!(
                "the archive holds {} entries, more than {MAX_TREE_FILES}: unpack it and give the series' folder",
                zip.len()
            ),
        ));
    }
    let mut found = Found::default();
    let mut batch: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    let mut unpacked = 0u64;
    let parse = |batch: &mut Vec<(PathBuf, Vec<u8>)>, found: &mut Found| {
        let parsed = batch
            .par_iter()
            .map(|(name, bytes)| parse_file(bytes, name))
            .collect();
        found.add(parsed, true);
        batch.clear();
    };
    for i in 0..zip.len() {
        let mut entry = zip
            .by_index(i)
            .map_err(|e| VolumeError::invalid(path, format!("entry {i} of the archive: {e}")))?;
        let name = match entry.name() {
            Ok(n) => n.to_string(),
            Err(e) => {
                found.warnings.push(format!("skipped entry {i}: {e}"));
                continue;
            }
        };
        let base = name.rsplit('/').next().unwrap_or_default();
        if !entry.is_file()
            || base.is_empty()
            || base.starts_with('.')
            || base.eq_ignore_ascii_case("DICOMDIR")
            || name.starts_with("__MACOSX/")
        {
            continue;
        }
        let inner = path.join(&name);
        // Read no further than the room left: the size an entry claims is not trusted.
        let room = limit - unpacked;
        let mut bytes = Vec::new();
        let read = (&mut entry).take(room + 1).read_to_end(&mut bytes);
        unpacked += bytes.len() as u64;
        if unpacked > limit {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "its files unpack to more than {limit} bytes: unpack it and give the series' folder"
                ),
            ));
        }
        if let Err(e) = read {
            let e = VolumeError::invalid(&inner, format!("cannot be unpacked: {e}"));
            found.add(vec![Err(e)], true);
            continue;
        }
        batch.push((inner, bytes));
        if batch.len() == ZIP_BATCH {
            parse(&mut batch, &mut found);
        }
    }
    parse(&mut batch, &mut found);
    found.finish(path, true, "the archive")
}

/// What the file meta group says: the transfer syntax, and the instance it stores (Media Storage
/// SOP Class and Instance UIDs, empty where absent), which an anonymised data set may have
/// blanked in its own SOP Common module.
pub(crate) struct FileMeta {
    pub(crate) ts_uid: String,
    pub(crate) sop_class: String,
    sop_instance: String,
}

impl FileMeta {
    /// The SOP Class UID of `obj`, the data set this file meta heads: the data set's own, else
    /// (blank or absent, as anonymised) the file meta's.
    pub(crate) fn sop_class_of(&self, obj: &InMemDicomObject) -> String {
        obj.get(tags::SOP_CLASS_UID)
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim_end_matches(['\0', ' ']).trim().to_string())
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| self.sop_class.clone())
    }
}

/// The text of `tag` in `o`, trimmed of padding (spaces, NULs); empty where it is absent.
pub(crate) fn text_of(o: &InMemDicomObject, tag: dicom_core::Tag) -> String {
    o.get(tag)
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_end_matches(['\0', ' ']).trim().to_string())
        .unwrap_or_default()
}

/// The name of the transfer syntax `uid` (empty for one the registry does not know).
pub(crate) fn transfer_syntax_name(uid: &str) -> String {
    TransferSyntaxRegistry
        .get(uid)
        .map(|t| t.name().to_string())
        .unwrap_or_default()
}

/// Reads the file meta group by hand (see the module docs) and returns what it says and the
/// offset of the data set.
pub(crate) fn read_meta(bytes: &[u8], file: &Path) -> Result<(FileMeta, usize), VolumeError> {
    let mut pos = if bytes.len() >= 132 && &bytes[128..132] == b"DICM" {
        132
    } else if bytes.starts_with(&[0x02, 0x00]) {
        0
    } else {
        return Err(VolumeError::invalid(
            file,
            "not a DICOM file (no DICM marker at byte 128 and no file meta group)",
        ));
    };
    let (mut ts, mut sop_class, mut sop_instance) = (None, String::new(), String::new());
    while pos + 8 <= bytes.len() && bytes[pos] == 0x02 && bytes[pos + 1] == 0x00 {
        let elem = u16::from_le_bytes([bytes[pos + 2], bytes[pos + 3]]);
        let vr = &bytes[pos + 4..pos + 6];
        let long = has_long_length(vr);
        let (len, head) = if long {
            if pos + 12 > bytes.len() {
                break;
            }
            let l = u32::from_le_bytes(bytes[pos + 8..pos + 12].try_into().unwrap()) as usize;
            (l, 12)
        } else {
            (
                u16::from_le_bytes([bytes[pos + 6], bytes[pos + 7]]) as usize,
                8,
            )
        };
        let start = pos + head;
        let end = start
            .checked_add(len)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| VolumeError::invalid(file, "the DICOM file meta group is truncated"))?;
        let value = || {
            let s = String::from_utf8_lossy(&bytes[start..end]);
            s.trim_end_matches(['\0', ' ']).trim().to_string()
        };
        match elem {
            0x0002 => sop_class = value(),
            0x0003 => sop_instance = value(),
            0x0010 => ts = Some(value()),
            _ => {}
        }
        pos = end;
    }
    let ts = ts.ok_or_else(|| {
        VolumeError::invalid(
            file,
            "the DICOM file meta group has no transfer syntax (0002,0010)",
        )
    })?;
    let meta = FileMeta {
        ts_uid: ts,
        sop_class,
        sop_instance,
    };
    Ok((meta, pos))
}

fn read_file(file: &Path) -> Result<Vec<Slice>, VolumeError> {
    parse_file(
        &std::fs::read(file).map_err(|e| VolumeError::io(file, e))?,
        file,
    )
}

/// A DICOM file's file meta and data set, its lengths checked against the file's.
pub(crate) fn parse_dataset(
    bytes: &[u8],
    file: &Path,
) -> Result<(FileMeta, InMemDicomObject), VolumeError> {
    let (meta, start) = read_meta(bytes, file)?;
    let ts_uid = meta.ts_uid.clone();
    let ts = TransferSyntaxRegistry.get(&ts_uid).ok_or_else(|| {
        VolumeError::invalid(
            file,
            format!(
                "DICOM transfer syntax {ts_uid} is not supported{}",
                if matches!(
                    ts_uid.as_str(),
                    "1.2.840.10008.1.2.4.52"
                        | "1.2.840.10008.1.2.4.53"
                        | "1.2.840.10008.1.2.4.54"
                        | "1.2.840.10008.1.2.4.55"
                        | "1.2.840.10008.1.2.4.56"
                        | "1.2.840.10008.1.2.4.58"
                        | "1.2.840.10008.1.2.4.59"
                        | "1.2.840.10008.1.2.4.60"
                        | "1.2.840.10008.1.2.4.61"
                        | "1.2.840.10008.1.2.4.62"
                        | "1.2.840.10008.1.2.4.63"
                        | "1.2.840.10008.1.2.4.64"
                        | "1.2.840.10008.1.2.4.65"
                        | "1.2.840.10008.1.2.4.66"
                ) {
                    " (a retired JPEG process; convert the series, e.g. with dcmdjpeg or gdcmconv)"
                } else {
                    ""
                }
            ),
        )
    })?;
    check_lengths(&bytes[start..], &ts_uid).map_err(|p| VolumeError::invalid(file, p))?;
    let obj = InMemDicomObject::read_dataset_with_ts(&bytes[start..], ts)
        .map_err(|e| VolumeError::invalid(file, format!("cannot parse the DICOM data set: {e}")))?;
    Ok((meta, obj))
}

/// A DICOM file's slices: one for a single-frame image, one a frame for a multi-frame
/// (enhanced) one.
pub(crate) fn parse_file(bytes: &[u8], file: &Path) -> Result<Vec<Slice>, VolumeError> {
    let (meta, obj) = parse_dataset(bytes, file)?;
    slices_of(&meta, obj, file)
}

/// The slices of the parsed data set `obj` (with its file meta `meta`) of `file`.
fn slices_of(
    meta: &FileMeta,
    obj: InMemDicomObject,
    file: &Path,
) -> Result<Vec<Slice>, VolumeError> {
    let ts_uid = meta.ts_uid.clone();
    if super::segmentation::is_segmentation(meta, &obj) {
        return Err(VolumeError::invalid(
            file,
            "a DICOM Segmentation, not an image of a series (read it by its own name)",
        ));
    }
    if super::structure_set::is_structure_set(meta, &obj) {
        return Err(VolumeError::invalid(
            file,
            "a DICOM RT Structure Set, not an image of a series (read it by its own name)",
        ));
    }
    let sop_class = meta.sop_class_of(&obj);
    if sop_class == crate::ENCAPSULATED_STL {
        return Err(VolumeError::invalid(
            file,
            "a DICOM Encapsulated STL (a 3D model), not an image of a series (read it by its own name)",
        ));
    }
    if crate::measurement_report::is_report_class(&sop_class) {
        return Err(VolumeError::invalid(
            file,
            "a DICOM Structured Report (measurements), not an image (`raystream info` lists what it holds)",
        ));
    }
    let text = |tag| {
        obj.get(tag)
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim().to_string())
    };
    let int = |tag| obj.get(tag).and_then(|e| e.to_int::<u32>().ok());
    let missing = |what: &str| VolumeError::invalid(file, format!("DICOM image without {what}"));
    if obj.get(tags::PIXEL_DATA).is_none() {
        return Err(missing("pixel data (7FE0,0010)"));
    }
    let rows = int(tags::ROWS).ok_or_else(|| missing("Rows"))?;
    let cols = int(tags::COLUMNS).ok_or_else(|| missing("Columns"))?;
    let frames = int(tags::NUMBER_OF_FRAMES).unwrap_or(1).max(1);
    // dicom-pixeldata asserts these (a panic), so a damaged header is refused here.
    let allocated =
        int(tags::BITS_ALLOCATED).ok_or_else(|| missing("BitsAllocated (0028,0100)"))?;
    let stored = int(tags::BITS_STORED).unwrap_or(allocated);
    if ![8, 16, 32].contains(&allocated) || stored == 0 || stored > allocated {
        return Err(VolumeError::invalid(
            file,
            format!(
                "BitsAllocated {allocated}, BitsStored {stored}: expected 8, 16 or 32 bits allocated, and 1 to that many stored"
            ),
        ));
    }
    let (series_uid, description, modality) = (
        text(tags::SERIES_INSTANCE_UID).unwrap_or_default(),
        text(tags::SERIES_DESCRIPTION).unwrap_or_default(),
        text(tags::MODALITY).unwrap_or_default(),
    );
    let frame_of_reference = text(tags::FRAME_OF_REFERENCE_UID)
        .map(|s| s.trim_end_matches('\0').to_string())
        .unwrap_or_default();
    let uid_or = |tag, meta: &str| {
        text(tag)
            .map(|s| s.trim_end_matches('\0').to_string())
            .filter(|s| !s.is_empty())
            .unwrap_or_else(|| meta.to_string())
    };
    let sop_instance = uid_or(tags::SOP_INSTANCE_UID, &meta.sop_instance);
    let enhanced = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .is_some();
    let (geometry, mut warning) = if frames == 1 && !enhanced {
        (vec![FrameGeometry::of(&[], Some(&obj))], None)
    } else {
        multi_frame_geometry(&obj, frames).map_err(|p| VolumeError::invalid(file, p))?
    };
    let mut obj = Some(obj);
    let slices = geometry
        .into_iter()
        .map(|g| {
            let at = match g.frame {
                Some(k) => format!(" in frame {}", k + 1),
                None => String::new(),
            };
            let need = |what: &str| missing(&format!("a valid {what}{at}"));
            Ok(Slice {
                file: file.to_path_buf(),
                series_uid: series_uid.clone(),
                description: description.clone(),
                modality: modality.clone(),
                frame_of_reference: frame_of_reference.clone(),
                ts_uid: ts_uid.clone(),
                sop_class: sop_class.clone(),
                sop_instance: sop_instance.clone(),
                rows,
                cols,
                frame: g.frame,
                temporal: g.temporal,
                position: g
                    .position
                    .ok_or_else(|| need("ImagePositionPatient (0020,0032)"))?,
                orientation: g
                    .orientation
                    .ok_or_else(|| need("ImageOrientationPatient (0020,0037)"))?,
                pixel_spacing: g
                    .pixel_spacing
                    .ok_or_else(|| need("PixelSpacing (0028,0030)"))?,
                between_slices: g.between_slices,
                thickness: g.thickness,
                note: warning.take(),
                obj: obj.take(),
            })
        })
        .collect::<Result<Vec<_>, VolumeError>>()?;
    Ok(slices)
}

/// A frame's plane: where it is, how it is turned and its pixels' size, from the first of
/// several data sets that has each (a frame's functional groups, the shared ones, the top
/// level).
#[derive(Default)]
pub(crate) struct FrameGeometry {
    /// The frame (from 0) of a multi-frame image; `None` for a single-frame one.
    frame: Option<u32>,
    /// Its temporal position (see [`Slice::temporal`]).
    temporal: Option<u32>,
    pub(crate) position: Option<[f64; 3]>,
    pub(crate) orientation: Option<[f64; 6]>,
    pub(crate) pixel_spacing: Option<[f64; 2]>,
    pub(crate) between_slices: Option<f64>,
    pub(crate) thickness: Option<f64>,
}

impl FrameGeometry {
    /// From the first of `groups` (functional group items, holding the attributes in the
    /// standard's macros) that has each attribute, else from the top level of `top`.
    pub(crate) fn of(
        groups: &[&InMemDicomObject],
        top: Option<&InMemDicomObject>,
    ) -> FrameGeometry {
        let find = |tag, macro_tag| {
            groups
                .iter()
                .find_map(|g| {
                    g.get(macro_tag)?
                        .items()?
                        .first()?
                        .get(tag)?
                        .to_multi_float64()
                        .ok()
                })
                .or_else(|| top?.get(tag)?.to_multi_float64().ok())
        };
        FrameGeometry {
            frame: None,
            temporal: top
                .and_then(|t| t.get(tags::TEMPORAL_POSITION_IDENTIFIER))
                .and_then(|e| e.to_int::<u32>().ok()),
            position: find(tags::IMAGE_POSITION_PATIENT, tags::PLANE_POSITION_SEQUENCE)
                .and_then(|v| <[f64; 3]>::try_from(v).ok()),
            orientation: find(
                tags::IMAGE_ORIENTATION_PATIENT,
                tags::PLANE_ORIENTATION_SEQUENCE,
            )
            .and_then(|v| <[f64; 6]>::try_from(v).ok()),
            pixel_spacing: find(tags::PIXEL_SPACING, tags::PIXEL_MEASURES_SEQUENCE)
                .and_then(|v| <[f64; 2]>::try_from(v).ok()),
            between_slices: find(tags::SPACING_BETWEEN_SLICES, tags::PIXEL_MEASURES_SEQUENCE)
                .and_then(|v| v.first().copied()),
            thickness: find(tags::SLICE_THICKNESS, tags::PIXEL_MEASURES_SEQUENCE)
                .and_then(|v| v.first().copied()),
        }
    }
}

/// A multi-frame image's functional groups: an item a frame (there must be `frames`), and the
/// shared item where there is one.
pub(crate) fn functional_groups(
    obj: &InMemDicomObject,
    frames: usize,
) -> Result<(&[InMemDicomObject], Option<&InMemDicomObject>), String> {
    let per_frame = obj
        .get(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .ok_or_else(|| {
            format!(
                "multi-frame image ({frames} frames) without a per-frame functional groups sequence \
                 (5200,9230): where each frame lies is unknown"
            )
        })?;
    if per_frame.len() != frames {
        return Err(format!(
            "NumberOfFrames is {frames} but the per-frame functional groups sequence has {} items",
            per_frame.len()
        ));
    }
    let shared = obj
        .get(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)
        .and_then(|e| e.items())
        .and_then(|items| items.first());
    Ok((per_frame, shared))
}

/// The frames of a multi-frame (enhanced) image as planes, from its per-frame and shared
/// functional groups (PS3.3 C.7.6.16: Plane Position, Plane Orientation, Pixel Measures), with
/// the top level as the last resort (legacy multi-frame), each with its temporal position (Frame
/// Content), which [`keep_phase`] chooses among. A file holding several stacks gives the frames
/// of the first one only, and a warning.
fn multi_frame_geometry(
    obj: &InMemDicomObject,
    frames: u32,
) -> Result<(Vec<FrameGeometry>, Option<String>), String> {
    let (per_frame, shared) = functional_groups(obj, frames as usize)?;
    // Which stack and temporal position each frame belongs to (Frame Content macro).
    let content = |item: &InMemDicomObject| {
        let fc = item
            .get(tags::FRAME_CONTENT_SEQUENCE)
            .and_then(|e| e.items())
            .and_then(|items| items.first());
        let stack = fc
            .and_then(|fc| fc.get(tags::STACK_ID))
            .and_then(|e| e.to_str().ok())
            .map(|s| s.trim().to_string());
        let temporal = fc
            .and_then(|fc| fc.get(tags::TEMPORAL_POSITION_INDEX))
            .and_then(|e| e.to_int::<u32>().ok());
        (stack, temporal)
    };
    let first_stack = content(&per_frame[0]).0;
    let mut stacks: Vec<Option<String>> = Vec::new();
    let mut out = Vec::new();
    for (k, item) in per_frame.iter().enumerate() {
        let (stack, temporal) = content(item);
        if !stacks.contains(&stack) {
            stacks.push(stack.clone());
        }
        if stack == first_stack {
            let fgs: Vec<&InMemDicomObject> = [Some(item), shared].into_iter().flatten().collect();
            out.push(FrameGeometry {
                frame: Some(k as u32),
                temporal,
                ..FrameGeometry::of(&fgs, Some(obj))
            });
        }
    }
    let warning = (stacks.len() > 1).then(|| {
        let what = match &first_stack {
            Some(s) => format!("stack {s}"),
            None => "the frames without a stack".to_string(),
        };
        format!(
            "{} stacks in the multi-frame image; read {} of its {frames} frames, {what}",
            stacks.len(),
            out.len()
        )
    });
    Ok((out, warning))
}

/// Walks every data element, into sequences and their items, and refuses a defined length that
/// runs past the end of the file, before dicom-rs would allocate a buffer of that claimed size
/// (a bit flip in a length field, or in an item tag inside a sequence, otherwise costs
/// gigabytes and seconds). Primitive values and the fragments of encapsulated pixel data are
/// skipped by their lengths; sequences and items are entered. Deflated data sets are left to
/// dicom-rs, which bounds them itself.
fn check_lengths(data: &[u8], ts_uid: &str) -> Result<(), String> {
    use dicom_core::dictionary::{DataDictionary, DataDictionaryEntry, VirtualVr};
    if ts_uid == "1.2.840.10008.1.2.1.99" {
        return Ok(());
    }
    let implicit = ts_uid == "1.2.840.10008.1.2";
    let big = ts_uid == "1.2.840.10008.1.2.2";
    let b = super::raw::Bytes {
        data,
        big_endian: big,
    };
    let (u16_at, u32_at) = (|o| b.u16(o), |o| b.u32(o));
    let past_end = |what: String, len: u32, from: usize| {
        format!(
            "{what} claims {len} bytes but only {} remain (truncated or corrupt file)",
            data.len().saturating_sub(from)
        )
    };
    let mut pos = 0;
    // Inside encapsulated pixel data, whose items are fragments of bytes, not data sets.
    let mut fragments = false;
    while pos + 8 <= data.len() {
        let (group, elem) = (u16_at(pos), u16_at(pos + 2));
        if group == 0xFFFE {
            // Item, item delimiter, sequence delimiter: a tag and a 4-byte length in any syntax.
            let len = u32_at(pos + 4);
            pos += 8;
            match elem {
                0xE000 if len == u32::MAX => {}
                0xE000 => {
                    if pos + len as usize > data.len() {
                        return Err(past_end("an item".into(), len, pos));
                    }
                    if fragments {
                        pos += len as usize;
                    }
                }
                0xE00D => {}
                0xE0DD => fragments = false,
                _ => return Err(format!("invalid item tag (FFFE,{elem:04X}) (corrupt file)")),
            }
            continue;
        }
        let (sequence, len, head) = if implicit {
            let sq = dicom_dictionary_std::StandardDataDictionary
                .by_tag(dicom_core::Tag(group, elem))
                .is_some_and(|e| e.vr() == VirtualVr::Exact(dicom_core::VR::SQ));
            (sq, u32_at(pos + 4), 8)
        } else {
            let vr = &data[pos + 4..pos + 6];
            const SHORT: [&[u8; 2]; 21] = [
                b"AE", b"AS", b"AT", b"CS", b"DA", b"DS", b"DT", b"FL", b"FD", b"IS", b"LO", b"LT",
                b"PN", b"SH", b"SL", b"SS", b"ST", b"TM", b"UI", b"UL", b"US",
            ];
            let long = has_long_length(vr);
            if !long && !SHORT.iter().any(|v| &v[..] == vr) {
                return Err(format!(
                    "data element ({group:04X},{elem:04X}) has an invalid VR {:?} (corrupt file)",
                    String::from_utf8_lossy(vr)
                ));
            }
            if long {
                if pos + 12 > data.len() {
                    break;
                }
                (vr == b"SQ", u32_at(pos + 8), 12)
            } else {
                (false, u16_at(pos + 6) as u32, 8)
            }
        };
        if len == u32::MAX {
            // A sequence of undefined length (entered), or encapsulated pixel data.
            fragments = (group, elem) == (0x7FE0, 0x0010);
            pos += head;
            continue;
        }
        let end = pos + head + len as usize;
        if end > data.len() {
            return Err(past_end(
                format!("data element ({group:04X},{elem:04X})"),
                len,
                pos + head,
            ));
        }
        pos = if sequence { pos + head } else { end };
    }
    Ok(())
}

/// Explicit-VR elements whose length field is 4 bytes (after 2 reserved bytes).
fn has_long_length(vr: &[u8]) -> bool {
    matches!(
        vr,
        b"OB"
            | b"OW"
            | b"OF"
            | b"OD"
            | b"OL"
            | b"OV"
            | b"SQ"
            | b"UT"
            | b"UN"
            | b"UC"
            | b"UR"
            | b"SV"
            | b"UV"
    )
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn assemble(
    path: &Path,
    slices: &mut [Slice],
    all: Vec<(String, usize, String)>,
    mut warnings: Vec<String>,
    files_skipped: bool,
) -> Result<Volume, VolumeError> {
    warnings.extend(
        slices
            .iter()
            .filter_map(|s| Some(format!("{}: {}", s.file.display(), s.note.as_ref()?))),
    );
    let first = &slices[0];
    for s in slices.iter() {
        let same_grid = s.rows == first.rows
            && s.cols == first.cols
            && (0..6).all(|i| (s.orientation[i] - first.orientation[i]).abs() < 1e-4)
            && (0..2).all(|i| (s.pixel_spacing[i] - first.pixel_spacing[i]).abs() < 1e-4);
        if !same_grid {
            return Err(VolumeError::invalid(
                &s.file,
                format!(
                    "slice geometry differs within the series (rows/columns/orientation/pixel spacing vs {})",
                    first.file.display()
                ),
            ));
        }
    }
    let (o, first_file, pixel_spacing, rows, cols) = (
        first.orientation,
        first.file.clone(),
        first.pixel_spacing,
        first.rows,
        first.cols,
    );
    let row_dir = [o[0], o[1], o[2]];
    let col_dir = [o[3], o[4], o[5]];
    let normal = cross(row_dir, col_dir);
    let nlen = dot(normal, normal).sqrt();
    if !(0.99..=1.01).contains(&nlen) || dot(row_dir, col_dir).abs() > 1e-3 {
        return Err(VolumeError::invalid(
            &first_file,
            format!("ImageOrientationPatient {o:?} is not two orthogonal unit vectors"),
        ));
    }
    let normal = normal.map(|v| v / nlen);
    slices.sort_by(|a, b| dot(a.position, normal).total_cmp(&dot(b.position, normal)));

    voxel_count(path, [cols as usize, rows as usize, slices.len()])?;
    let positions: Vec<[f64; 3]> = slices.iter().map(|s| s.position).collect();
    let header_spacing = slices[0]
        .between_slices
        .or(slices[0].thickness)
        .filter(|s| *s > 0.0)
        .unwrap_or(1.0);
    let stack = Stack::new(
        path,
        &positions,
        normal,
        pixel_spacing[0].min(pixel_spacing[1]),
        header_spacing,
        files_skipped,
        // The folder is the message's subject: its files by name.
        |k| {
            let f = &slices[k].file;
            let name = f.file_name().unwrap_or(f.as_os_str()).to_string_lossy();
            match slices[k].frame {
                Some(frame) => format!("{name} frame {}", frame + 1),
                None => name.into_owned(),
            }
        },
    )?;
    warnings.extend(stack.warnings.iter().cloned());
    let dims = [cols as usize, rows as usize, stack.count];
    let spacing = [pixel_spacing[1], pixel_spacing[0], stack.spacing];
    let direction = std::array::from_fn(|r| [row_dir[r], col_dir[r], stack.axis[r]]);
    let origin = slices[0].position;
    check_geometry(path, dims, spacing, origin, &direction)?;

    let study = slices
        .iter()
        .find_map(|s| s.obj.as_ref())
        .map(DicomStudy::of)
        .unwrap_or_default();
    let sources = if stack.resampled {
        Vec::new()
    } else {
        slices
            .iter()
            .map(|s| SourceImage {
                sop_class_uid: s.sop_class.clone(),
                sop_instance_uid: s.sop_instance.clone(),
                frame: s.frame.map(|f| f + 1),
            })
            .collect()
    };
    let decoded = decode_all(slices, dims[0] * dims[1])?;
    let data = stack.regular(&decoded);
    let ts_name = transfer_syntax_name(&slices[0].ts_uid);
    let first = &slices[0];
    let unit = if first.modality == "CT" {
        ValueUnit::Hounsfield
    } else {
        ValueUnit::Unknown
    };
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::Dicom,
        series: Some(DicomSeriesInfo {
            uid: first.series_uid.clone(),
            description: first.description.clone(),
            modality: first.modality.clone(),
            count: slices.len(),
            transfer_syntax: first.ts_uid.clone(),
            transfer_syntax_name: ts_name,
            all,
            study,
            sources,
        }),
        segments: Vec::new(),
        phase: Phase::default(),
        warnings,
    })
}

/// Steeper than this, positions do not describe a tilted stack (CT gantries tilt by ±30° at most).
const MAX_TILT_DEG: f64 = 45.0;
/// Below this a stack's slant is rounding, not tilt: the stack is taken along its normal.
const MIN_TILT_DEG: f64 = 0.05;

/// Where a series' slices lie along the line they are stacked on, and the regular grid they
/// become.
///
/// A CT's slices are usually stacked along their normal, evenly: the grid is the slices
/// themselves. Two kinds of acquisition break that, and both are read rather than refused (as
/// 3D Slicer and dcm2niix read them), saying so in the volume's warnings:
/// - **Gantry tilt**: the table moves along the patient's axis while the image plane is tilted
///   about its row axis, so the positions step along the table, not along the normal. The
///   grid's third axis then follows the table: a sheared grid, exact with no resampling (each
///   voxel where its pixel was imaged), which the renderers handle as any affine grid.
/// - **Uneven spacing** (e.g. 4 mm slices through the posterior fossa, then 7 mm ones above):
///   the grid slices are interpolated, each linearly between the two acquired slices about it,
///   pixel by pixel along the stacking line (no in-plane interpolation), at the smallest gap but
///   no finer than a quarter of the median gap (a stray close pair must not blow the grid up).
///
/// An uneven series with an unreadable file in its folder is refused: the gap is most likely
/// that file. An isolated gap that is a whole multiple of the spacing about it is named in the
/// warning as possibly missing slices.
pub(crate) struct Stack {
    /// Unit LPS direction of the stacking line: the grid's third axis.
    pub(crate) axis: [f64; 3],
    /// Each acquired slice's distance from the first along `axis`, mm, increasing.
    pub(crate) at: Vec<f64>,
    /// Slices of the regular grid, and their spacing along `axis`, mm.
    pub(crate) count: usize,
    pub(crate) spacing: f64,
    /// Whether the grid's slices are interpolated (uneven spacing) rather than the acquired ones.
    pub(crate) resampled: bool,
    pub(crate) warnings: Vec<String>,
}

impl Stack {
    /// `positions`: each slice's ImagePositionPatient, sorted along the unit `normal`; `pixel`:
    /// the smaller pixel spacing (mm), the scale of how far off the line a slice may lie;
    /// `single`: the spacing of a one-slice series (from its header); `name(k)`: the k-th
    /// slice's file, for messages.
    pub(crate) fn new(
        path: &Path,
        positions: &[[f64; 3]],
        normal: [f64; 3],
        pixel: f64,
        single: f64,
        files_skipped: bool,
        name: impl Fn(usize) -> String,
    ) -> Result<Stack, VolumeError> {
        let n = positions.len();
        let mut stack = Stack {
            axis: normal,
            at: vec![0.0],
            count: 1,
            spacing: single,
            resampled: false,
            warnings: Vec::new(),
        };
        if n < 2 {
            return Ok(stack);
        }
        let from_first = |p: [f64; 3], axis: [f64; 3]| dot(sub(p, positions[0]), axis);
        let along_normal: Vec<f64> = positions.iter().map(|p| from_first(*p, normal)).collect();
        if let Some(i) = along_normal.windows(2).position(|w| w[1] - w[0] < 1e-3) {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "two slices at the same position ({} and {}): duplicate or mixed acquisitions; pick one series",
                    name(i),
                    name(i + 1)
                ),
            ));
        }
        // The line from the first slice to the last: the table's path.
        let span = sub(positions[n - 1], positions[0]);
        let line = span.map(|v| v / dot(span, span).sqrt());
        let tilt = dot(line, normal).clamp(-1.0, 1.0).acos().to_degrees();
        if tilt > MAX_TILT_DEG {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "the slice positions run at {tilt:.1}° to the slice normal: not a stack of slices (mixed acquisitions?)"
                ),
            ));
        }
        let (worst, off) = positions
            .iter()
            .map(|p| {
                let d = sub(*p, positions[0]);
                let a = dot(d, line);
                (dot(d, d) - a * a).max(0.0).sqrt()
            })
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .expect("two slices or more");
        if off > (0.1 * pixel).max(1e-3) {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "the slice positions do not lie on one line ({} is {off:.3} mm off the line from the first slice to the last): mixed acquisitions?",
                    name(worst)
                ),
            ));
        }
        if tilt > MIN_TILT_DEG {
            stack.axis = line;
            stack.at = positions.iter().map(|p| from_first(*p, line)).collect();
            stack.warnings.push(format!(
                "gantry tilt of {tilt:.1}°: the slices were stacked along the table, not their normal; \
                 the grid's third axis follows the table (a sheared grid: each voxel where its pixel was imaged)"
            ));
        } else {
            stack.at = along_normal;
        }
        let at = &stack.at;
        let gaps: Vec<f64> = at.windows(2).map(|w| w[1] - w[0]).collect();
        let (lo, hi) = gaps.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &g| {
            (lo.min(g), hi.max(g))
        });
        let last = at[n - 1];
        if hi - lo <= 1e-3 + 1e-3 * hi {
            stack.count = n;
            stack.spacing = last / (n - 1) as f64;
            return Ok(stack);
        }
        if files_skipped {
            return Err(VolumeError::invalid(
                path,
                format!("uneven slice spacing ({lo:.3} to {hi:.3} mm): missing slices?"),
            ));
        }
        let mut sorted = gaps.clone();
        sorted.sort_by(f64::total_cmp);
        let step = lo.max(sorted[sorted.len() / 2] / 4.0);
        stack.count = (last / step - 1e-9).ceil() as usize + 1;
        stack.spacing = last / (stack.count - 1) as f64;
        stack.resampled = true;
        // The first of the widest gaps (to rounding).
        let widest = gaps
            .iter()
            .position(|&g| g >= hi - 1e-3)
            .expect("one gap or more");
        let missing = (0..gaps.len())
            .find_map(|k| {
                let around: Vec<f64> = [k.checked_sub(1), Some(k + 1)]
                    .into_iter()
                    .flatten()
                    .filter_map(|i| gaps.get(i).copied())
                    .collect();
                let g = *around.first()?;
                let m = gaps[k] / g;
                let whole = m.round();
                (around.iter().all(|a| (a - g).abs() <= 0.01 * g)
                    && whole >= 2.0
                    && (m - whole).abs() <= 0.02 * whole)
                    .then(|| {
                        format!(
                            "; the gap between {} and {} is {whole}× the spacing about it: {} missing slice{}?",
                            name(k),
                            name(k + 1),
                            whole - 1.0,
                            if whole > 2.0 { "s" } else { "" }
                        )
                    })
            })
            .unwrap_or_default();
        stack.warnings.push(format!(
            "uneven slice spacing, {lo:.2} to {hi:.2} mm (the widest between {} and {}){missing}; \
             resampled to {} slices {:.3} mm apart, each interpolated linearly between the two acquired slices about it",
            name(widest),
            name(widest + 1),
            stack.count,
            stack.spacing
        ));
        Ok(stack)
    }

    /// The grid's values from the acquired slices' (`slices[k]` at `at[k]`, all the same
    /// length): the slices themselves, or interpolated onto the regular spacing.
    pub(crate) fn regular(&self, slices: &[Vec<f32>]) -> Vec<f32> {
        if !self.resampled {
            return slices.concat();
        }
        let per = slices[0].len();
        let n = slices.len();
        let mut data = vec![0f32; per * self.count];
        data.par_chunks_mut(per).enumerate().for_each(|(k, out)| {
            let t = k as f64 * self.spacing;
            let a = (self.at.partition_point(|&x| x <= t).max(1) - 1).min(n - 2);
            let w = ((t - self.at[a]) / (self.at[a + 1] - self.at[a])).clamp(0.0, 1.0);
            let (lo, hi) = (&slices[a], &slices[a + 1]);
            if w <= 1e-9 {
                out.copy_from_slice(lo);
            } else if w >= 1.0 - 1e-9 {
                out.copy_from_slice(hi);
            } else {
                let w = w as f32;
                for ((o, &l), &h) in out.iter_mut().zip(lo).zip(hi) {
                    *o = l + (h - l) * w;
                }
            }
        });
        data
    }
}

/// A codec run here, on the slice's encapsulated frame, rather than by dicom-pixeldata.
#[derive(Clone, Copy)]
enum OwnCodec {
    /// JPEG-LS, lossless or near-lossless (1.2.840.10008.1.2.4.80/81): pure_jpegls.
    JpegLs,
    /// 12-bit lossy JPEG (1.2.840.10008.1.2.4.51, precision 12): libjpeg-turbo-rs. The 8-bit
    /// variant of the same syntax stays with dicom-pixeldata's jpeg-decoder; a stream whose
    /// precision cannot be read comes here too, for libjpeg-turbo-rs's more precise error.
    Jpeg12,
}

impl OwnCodec {
    fn of(ts_uid: &str, obj: &InMemDicomObject) -> Option<OwnCodec> {
        match ts_uid {
            "1.2.840.10008.1.2.4.80" | "1.2.840.10008.1.2.4.81" => Some(OwnCodec::JpegLs),
            "1.2.840.10008.1.2.4.51" => {
                let frame = obj.get(tags::PIXEL_DATA)?.value().fragments()?.first()?;
                (jpeg_precision(frame) != Some(8)).then_some(OwnCodec::Jpeg12)
            }
            _ => None,
        }
    }
}

/// The sample precision in a JPEG stream's frame header (SOF0 to SOF15), or `None` if the
/// markers before it are malformed.
fn jpeg_precision(stream: &[u8]) -> Option<u8> {
    let mut at = 2;
    while at + 4 < stream.len() {
        if stream[at] != 0xFF {
            return None;
        }
        let marker = stream[at + 1];
        if (0xC0..=0xCF).contains(&marker) && ![0xC4, 0xC8, 0xCC].contains(&marker) {
            return Some(stream[at + 4]);
        }
        at += 2 + u16::from_be_bytes([stream[at + 2], stream[at + 3]]) as usize;
    }
    None
}

const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// Every slice's modality values, in `slices`' order: each file is decoded once, by the slice
/// that holds its data set, the frames of a multi-frame one that `slices` has (one phase's).
fn decode_all(slices: &mut [Slice], per_slice: usize) -> Result<Vec<Vec<f32>>, VolumeError> {
    let mut wanted: std::collections::HashMap<PathBuf, Vec<usize>> = Default::default();
    for s in slices.iter() {
        wanted
            .entry(s.file.clone())
            .or_default()
            .push(s.frame.unwrap_or(0) as usize);
    }
    let mut frames: Vec<Vec<Vec<f32>>> = slices
        .par_iter_mut()
        .map(|s| match s.obj {
            Some(_) => decode_frames(s, per_slice, Some(&wanted[&s.file])),
            None => Ok(Vec::new()),
        })
        .collect::<Result<_, _>>()?;
    let holder: std::collections::HashMap<&Path, usize> = slices
        .iter()
        .enumerate()
        .filter(|(k, _)| !frames[*k].is_empty())
        .map(|(k, s)| (s.file.as_path(), k))
        .collect();
    slices
        .iter()
        .map(|s| {
            let frame = s.frame.unwrap_or(0) as usize;
            holder
                .get(s.file.as_path())
                .and_then(|&k| frames[k].get_mut(frame))
                .filter(|v| !v.is_empty())
                .map(std::mem::take)
                .ok_or_else(|| {
                    VolumeError::invalid(&s.file, format!("no frame {} decoded", frame + 1))
                })
        })
        .collect()
}

/// Decodes the encapsulated (compressed) pixel data of `obj`, a multi-frame object of `file`
/// in transfer syntax `ts_uid` of `frames` frames of `cols`×`rows`, frame by frame to its
/// stored values, as the image reader decodes a CT's (a Segmentation's label map or fractions).
/// The frames must each have a fragment of their own before any is decoded, so a header
/// claiming more frames than the file holds sizes nothing.
pub(crate) fn decode_encapsulated(
    file: &Path,
    ts_uid: &str,
    obj: InMemDicomObject,
    (cols, rows, frames): (u32, u32, usize),
) -> Result<Vec<Vec<f32>>, VolumeError> {
    let fragments = obj
        .get(tags::PIXEL_DATA)
        .and_then(|e| e.value().fragments())
        .map_or(0, |f| f.len());
    if fragments < frames {
        return Err(VolumeError::invalid(
            file,
            format!("{frames} frames claimed, {fragments} compressed fragments held"),
        ));
    }
    let mut s = Slice {
        file: file.to_path_buf(),
        ts_uid: ts_uid.to_string(),
        rows,
        cols,
        obj: Some(obj),
        ..Default::default()
    };
    decode_frames(&mut s, rows as usize * cols as usize, None)
}

/// Decodes a file's frames to modality values (RescaleSlope/Intercept applied, a frame's own
/// in an enhanced image: HU for CT): the `wanted` ones (from 0; `None`: all), the others empty.
pub(crate) fn decode_frames(
    s: &mut Slice,
    per_slice: usize,
    wanted: Option<&[usize]>,
) -> Result<Vec<Vec<f32>>, VolumeError> {
    let is_wanted = |k: usize| wanted.is_none_or(|w| w.contains(&k));
    let ts = TransferSyntaxRegistry.get(&s.ts_uid).ok_or_else(|| {
        VolumeError::invalid(&s.file, format!("unknown transfer syntax {}", s.ts_uid))
    })?;
    let mut obj = s.obj.take().expect("each slice is decoded once");
    let own = OwnCodec::of(&s.ts_uid, &obj);
    if let Some(codec) = own {
        obj = decode_to_native(obj, s, codec, &is_wanted)?;
    } else if !ts.can_decode_all() {
        return Err(VolumeError::invalid(
            &s.file,
            format!(
                "pixel data in transfer syntax {} ({}) cannot be decoded by this build",
                s.ts_uid,
                ts.name(),
            ),
        ));
    }
    if s.ts_uid == RLE_LOSSLESS {
        check_rle(&obj, s.rows as usize * s.cols as usize)
            .map_err(|e| VolumeError::invalid(&s.file, format!("RLE Lossless pixel data: {e}")))?;
    }
    let obj = obj
        .with_meta(
            FileMetaTableBuilder::new().transfer_syntax(if own.is_some() {
                EXPLICIT_LE
            } else {
                s.ts_uid.as_str()
            }),
        )
        .map_err(|e| {
            VolumeError::invalid(&s.file, format!("cannot build the file meta table: {e}"))
        })?;
    if JPEG_2000.contains(&s.ts_uid.as_str()) {
        check_jpeg2000(&obj, s.rows as usize, s.cols as usize)
            .map_err(|e| VolumeError::invalid(&s.file, format!("JPEG 2000 pixel data: {e}")))?;
    }
    let pixels = obj.decode_pixel_data().map_err(|e| {
        VolumeError::invalid(
            &s.file,
            format!("cannot decode the pixel data ({}): {e}", ts.name()),
        )
    })?;
    (0..pixels.number_of_frames())
        .map(|k| {
            if !is_wanted(k as usize) {
                return Ok(Vec::new());
            }
            let values: Vec<f32> = pixels.to_vec_frame(k).map_err(|e| {
                VolumeError::invalid(
                    &s.file,
                    format!("cannot convert the pixel data of frame {}: {e}", k + 1),
                )
            })?;
            if values.len() != per_slice {
                return Err(VolumeError::invalid(
                    &s.file,
                    format!(
                        "{} pixel values decoded in frame {}, {per_slice} expected",
                        values.len(),
                        k + 1
                    ),
                ));
            }
            Ok(values)
        })
        .collect()
}

/// The transfer syntaxes dicom-pixeldata decodes with OpenJPEG: JPEG 2000 (Part 1 and 2,
/// lossless and lossy) and High-Throughput JPEG 2000.
const JPEG_2000: [&str; 7] = [
    "1.2.840.10008.1.2.4.90",
    "1.2.840.10008.1.2.4.91",
    "1.2.840.10008.1.2.4.92",
    "1.2.840.10008.1.2.4.93",
    "1.2.840.10008.1.2.4.201",
    "1.2.840.10008.1.2.4.202",
    "1.2.840.10008.1.2.4.203",
];

/// Checks that each frame's JPEG 2000 codestream (PS3.5 A.4.4: the frame's fragments, as the
/// decoder is given them) declares the image the DICOM header does: `cols` × `rows` samples
/// and at most Samples per Pixel components. dicom-pixeldata's adapter writes each decoded
/// component's samples into a buffer sized by the header without checking, so a stream that
/// declares a larger image (or one component more) panics it. Reads only the SIZ marker
/// segment (ITU-T T.800 A.5.1), through a JP2 file's boxes where a writer wrapped the stream
/// in one; written here because no Rust crate parses JPEG 2000 headers without decoding.
fn check_jpeg2000(
    obj: &dicom_object::DefaultDicomObject,
    rows: usize,
    cols: usize,
) -> Result<(), String> {
    use dicom_encoding::adapters::PixelDataObject;
    let frames = obj.number_of_frames().unwrap_or(1).max(1);
    let samples = obj.samples_per_pixel().unwrap_or(1) as usize;
    for k in 0..frames {
        // A frame the object cannot give is the decoder's own clear error.
        let Some(data) = obj.frame_pixel_data(k) else {
            continue;
        };
        let frame = k + 1;
        let siz = jpeg2000_siz(&data).map_err(|e| format!("frame {frame}: {e}"))?;
        if (siz.width, siz.height) != (cols, rows) {
            return Err(format!(
                "frame {frame}: the codestream holds a {}×{} image, the header says {cols}×{rows} (Columns × Rows)",
                siz.width, siz.height
            ));
        }
        if siz.components > samples {
            return Err(format!(
                "frame {frame}: the codestream holds {} components, the header says {samples} (Samples per Pixel)",
                siz.components
            ));
        }
    }
    Ok(())
}

/// What a JPEG 2000 codestream's SIZ marker segment declares.
#[derive(Debug, PartialEq)]
struct Jpeg2000Siz {
    width: usize,
    height: usize,
    components: usize,
}

/// The SIZ marker segment of a codestream (it follows the SOC marker), or of the contiguous
/// codestream box (`jp2c`) of a JP2 file.
fn jpeg2000_siz(data: &[u8]) -> Result<Jpeg2000Siz, String> {
    const SOC_SIZ: [u8; 4] = [0xFF, 0x4F, 0xFF, 0x51];
    const JP2_SIGNATURE: [u8; 12] = [0, 0, 0, 12, b'j', b'P', b' ', b' ', 0x0D, 0x0A, 0x87, 0x0A];
    let mut stream = data;
    if data.starts_with(&JP2_SIGNATURE) {
        // Boxes: a 4-byte length (1: an 8-byte length follows the type; 0: to the end), a type.
        let mut rest = data;
        stream = loop {
            let head = |n: usize| rest.get(..n).ok_or("a JP2 file without a codestream box");
            let len = u32::from_be_bytes(head(8)?[..4].try_into().unwrap()) as u64;
            let (header, len) = match len {
                0 => (8, rest.len() as u64),
                1 => (16, u64::from_be_bytes(head(16)?[8..].try_into().unwrap())),
                n => (8, n),
            };
            if &rest[4..8] == b"jp2c" {
                break &rest[header..];
            }
            if len < header as u64 || len > rest.len() as u64 {
                return Err(format!(
                    "a JP2 box of {len} bytes where {} remain",
                    rest.len()
                ));
            }
            rest = &rest[len as usize..];
        };
    }
    if !stream.starts_with(&SOC_SIZ) {
        return Err("no codestream header (SOC and SIZ markers) at the frame's start".into());
    }
    // Lsiz, Rsiz, Xsiz, Ysiz, XOsiz, YOsiz, 4 tile fields, Csiz: 38 bytes after the marker.
    let f = stream.get(4..42).ok_or("a truncated SIZ marker segment")?;
    let u32_at = |i: usize| u32::from_be_bytes(f[i..i + 4].try_into().unwrap()) as usize;
    let (x, y, x0, y0) = (u32_at(4), u32_at(8), u32_at(12), u32_at(16));
    let components = u16::from_be_bytes([f[36], f[37]]) as usize;
    let (Some(width), Some(height)) = (x.checked_sub(x0), y.checked_sub(y0)) else {
        return Err(format!(
            "an image origin ({x0}, {y0}) beyond its extent ({x}, {y})"
        ));
    };
    Ok(Jpeg2000Siz {
        width,
        height,
        components,
    })
}

/// RLE Lossless (PS3.5 Annex G).
const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// Checks that each frame of `obj`'s RLE Lossless pixel data (a fragment a frame) holds the
/// segments its samples need (one a byte of a sample, PS3.5 G.2), each inside the fragment and
/// decoding to at least `per_frame` bytes, before dicom-pixeldata decodes them: its decoder
/// indexes past a short segment's end (a panic). Written here because no RLE crate is used
/// otherwise; it only counts the PackBits runs (G.3.1), it decodes nothing.
fn check_rle(obj: &InMemDicomObject, per_frame: usize) -> Result<(), String> {
    let int = |tag| obj.get(tag).and_then(|e| e.to_int::<usize>().ok());
    let samples = int(tags::SAMPLES_PER_PIXEL).unwrap_or(1);
    let bytes = int(tags::BITS_ALLOCATED).unwrap_or(8).div_ceil(8);
    let frames = int(tags::NUMBER_OF_FRAMES).unwrap_or(1).max(1);
    let fragments = obj
        .get(tags::PIXEL_DATA)
        .and_then(|e| e.value().fragments())
        .ok_or("not encapsulated in fragments")?;
    if fragments.len() < frames {
        return Err(format!(
            "{frames} frames, {} fragments (one a frame)",
            fragments.len()
        ));
    }
    let needed = samples * bytes;
    for (k, f) in fragments.iter().take(frames).enumerate() {
        let frame = k + 1;
        if f.len() < 64 {
            return Err(format!(
                "frame {frame}: {} bytes, shorter than its header",
                f.len()
            ));
        }
        let word = |i: usize| u32::from_le_bytes(f[4 * i..4 * i + 4].try_into().unwrap()) as usize;
        let count = word(0);
        if !(needed..=15).contains(&count) {
            return Err(format!(
                "frame {frame}: {count} segments, {needed} needed (of at most 15)"
            ));
        }
        for i in 1..=needed {
            let (start, end) = (word(i), if i < count { word(i + 1) } else { f.len() });
            if start < 64 || start > end || end > f.len() {
                return Err(format!(
                    "frame {frame}: segment {i} at bytes {start} to {end} of {}",
                    f.len()
                ));
            }
            // PackBits: a header byte n then n + 1 literal bytes (n < 128), or one byte
            // repeated 257 − n times (n > 128); 128 does nothing.
            let (seg, mut at, mut out) = (&f[start..end], 0usize, 0usize);
            while at < seg.len() && out < per_frame {
                let n = seg[at] as usize;
                at += 1;
                match n {
                    0..=127 => {
                        at += n + 1;
                        out += n + 1;
                    }
                    128 => {}
                    _ => {
                        at += 1;
                        out += 257 - n;
                    }
                }
            }
            if out < per_frame || at > seg.len() {
                return Err(format!(
                    "frame {frame}: segment {i} decodes to {} of its {per_frame} bytes",
                    out.min(per_frame)
                ));
            }
        }
    }
    Ok(())
}

/// Replaces a slice's encapsulated pixel data with the samples `codec` decodes, as native
/// (uncompressed) pixel data of the slice's BitsAllocated. The samples are the stored bit
/// patterns (T.87 and T.81 code unsigned values), so a signed image is sign-extended from
/// BitsStored, and rescaled, by dicom-pixeldata afterwards, exactly as an uncompressed file.
/// Frames not `wanted` (another phase's) are left zero rather than decoded.
fn decode_to_native(
    mut obj: InMemDicomObject,
    s: &Slice,
    codec: OwnCodec,
    wanted: &(dyn Fn(usize) -> bool + Sync),
) -> Result<InMemDicomObject, VolumeError> {
    let name = match codec {
        OwnCodec::JpegLs => "JPEG-LS",
        OwnCodec::Jpeg12 => "12-bit JPEG",
    };
    let bad = |what: String| VolumeError::invalid(&s.file, format!("{name} pixel data: {what}"));
    let int = |tag| obj.get(tag).and_then(|e| e.to_int::<u32>().ok());
    let samples = int(tags::SAMPLES_PER_PIXEL).unwrap_or(1);
    if samples != 1 {
        return Err(bad(format!(
            "{samples} samples per pixel; only greyscale (1) is supported"
        )));
    }
    let allocated = int(tags::BITS_ALLOCATED).unwrap_or(16);
    let frames = int(tags::NUMBER_OF_FRAMES).unwrap_or(1).max(1) as usize;
    let value = obj
        .get(tags::PIXEL_DATA)
        .map(|e| e.value())
        .ok_or_else(|| bad("missing".into()))?;
    let fragments = value
        .fragments()
        .ok_or_else(|| bad("not encapsulated in fragments".into()))?;
    let streams =
        frame_streams(fragments, value.offset_table().unwrap_or(&[]), frames).map_err(&bad)?;
    // The frames of a multi-frame image decode in parallel.
    let values: Vec<u16> = streams
        .par_iter()
        .enumerate()
        .map(|(k, stream)| {
            if !wanted(k) {
                return Ok(vec![0; s.rows as usize * s.cols as usize]);
            }
            let frame = if frames > 1 {
                format!("frame {} ({}x{})", k + 1, s.cols, s.rows)
            } else {
                format!("the {}x{} frame", s.cols, s.rows)
            };
            decode_own(codec, stream, s, &frame)
        })
        .collect::<Result<Vec<Vec<u16>>, String>>()
        .map_err(&bad)?
        .concat();
    let value = match allocated {
        8 => PrimitiveValue::U8(
            values
                .iter()
                .map(|&v| u8::try_from(v))
                .collect::<Result<_, _>>()
                .map_err(|_| bad("a sample wider than BitsAllocated 8".into()))?,
        ),
        16 => PrimitiveValue::U16(values.into()),
        n => {
            return Err(bad(format!(
                "BitsAllocated {n}; only 8 and 16 are supported"
            )));
        }
    };
    let vr = if allocated == 8 { VR::OB } else { VR::OW };
    obj.put(DataElement::new(tags::PIXEL_DATA, vr, value));
    Ok(obj)
}

/// Each frame's compressed stream: the fragments split by the basic offset table, or one
/// fragment a frame, or all of them for a single frame (PS3.5 A.4); a frame of one fragment is
/// that fragment, not a copy.
fn frame_streams<'a>(
    fragments: &'a [Vec<u8>],
    offsets: &[u32],
    frames: usize,
) -> Result<Vec<Cow<'a, [u8]>>, String> {
    let joined = |parts: &'a [Vec<u8>]| match parts {
        [one] => Cow::Borrowed(one.as_slice()),
        many => Cow::Owned(many.concat()),
    };
    if frames == 1 {
        return Ok(vec![joined(fragments)]);
    }
    if offsets.len() == frames {
        // Offsets count bytes from the first fragment's item tag: 8 bytes of tag and length,
        // then the fragment, for each.
        let mut starts = Vec::with_capacity(fragments.len());
        let mut at = 0u64;
        for f in fragments {
            starts.push(at);
            at += 8 + f.len() as u64;
        }
        // The fragments from where the offset table puts a frame to where it puts the next.
        let first = |k: usize, o: u32| {
            starts.binary_search(&(o as u64)).map_err(|_| {
                format!(
                    "the offset table puts frame {} at byte {o}, where no fragment starts",
                    k + 1
                )
            })
        };
        return offsets
            .iter()
            .enumerate()
            .map(|(k, &o)| {
                let end = match offsets.get(k + 1) {
                    Some(&next) => first(k + 1, next)?,
                    None => fragments.len(),
                };
                let start = first(k, o)?;
                if start >= end {
                    return Err(format!(
                        "the offset table puts frame {} out of order",
                        k + 2
                    ));
                }
                Ok(joined(&fragments[start..end]))
            })
            .collect();
    }
    if fragments.len() == frames {
        return Ok(fragments
            .iter()
            .map(|f| Cow::Borrowed(f.as_slice()))
            .collect());
    }
    Err(format!(
        "{} fragments for {frames} frames, and no offset table to tell which belong to which",
        fragments.len()
    ))
}

/// One frame's stored samples, decoded by `codec`.
fn decode_own(codec: OwnCodec, stream: &[u8], s: &Slice, frame: &str) -> Result<Vec<u16>, String> {
    Ok(match codec {
        OwnCodec::JpegLs => {
            jpegls::decode(stream, s.cols, s.rows)
                .map_err(|e| format!("cannot decode {frame}: {e}"))?
                .0
        }
        OwnCodec::Jpeg12 => {
            let limits = libjpeg_turbo_rs::DecodeLimits {
                max_width: s.cols as usize,
                max_height: s.rows as usize,
                ..Default::default()
            };
            let im = libjpeg_turbo_rs::decompress_12bit_with_limits(stream, &limits)
                .map_err(|e| format!("cannot decode {frame}: {e}"))?;
            if (im.width, im.height, im.num_components) != (s.cols as usize, s.rows as usize, 1) {
                return Err(format!(
                    "{}x{} pixels of {} components instead of {frame}",
                    im.width, im.height, im.num_components
                ));
            }
            im.data.iter().map(|&v| v as u16).collect()
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dicom_core::value::PixelFragmentSequence;

    /// An 8-bit RLE frame's object: one fragment of a 64-byte header naming `count` segments
    /// at `offsets`, then `data`.
    fn rle(count: u32, offsets: &[u32], data: &[u8]) -> InMemDicomObject {
        let mut f: Vec<u8> = Vec::new();
        f.extend(count.to_le_bytes());
        for i in 0..15 {
            f.extend(offsets.get(i).copied().unwrap_or(0).to_le_bytes());
        }
        f.extend(data);
        let mut obj = InMemDicomObject::new_empty();
        obj.put(DataElement::new(
            tags::BITS_ALLOCATED,
            VR::US,
            PrimitiveValue::from(8u16),
        ));
        obj.put(DataElement::new(
            tags::PIXEL_DATA,
            VR::OB,
            PixelFragmentSequence::new(Vec::new(), vec![f]),
        ));
        obj
    }

    /// A codestream's SIZ marker segment: SOC, SIZ, then Lsiz .. Csiz and one component.
    fn siz(x: u32, y: u32, x0: u32, y0: u32, components: u16) -> Vec<u8> {
        let mut b = vec![0xFF, 0x4F, 0xFF, 0x51, 0, 41, 0, 0];
        for v in [x, y, x0, y0, 512, 512, 0, 0] {
            b.extend(v.to_be_bytes());
        }
        b.extend(components.to_be_bytes());
        b.extend([0x0F, 1, 1]);
        b
    }

    /// The image a codestream declares, raw or in a JP2 file's codestream box (after the
    /// signature, a 16-byte box of an 8-byte length, and a box to the end); and each way the
    /// header can be missing, cut or absurd, refused with what it is.
    #[test]
    fn jpeg2000_headers_are_read_before_decoding() {
        let want = |width, height, components| Jpeg2000Siz {
            width,
            height,
            components,
        };
        assert_eq!(jpeg2000_siz(&siz(512, 512, 0, 0, 1)), Ok(want(512, 512, 1)));
        assert_eq!(
            jpeg2000_siz(&siz(600, 520, 88, 8, 3)),
            Ok(want(512, 512, 3))
        );
        let mut jp2 = vec![0, 0, 0, 12, b'j', b'P', b' ', b' ', 0x0D, 0x0A, 0x87, 0x0A];
        jp2.extend([0, 0, 0, 1, b'f', b't', b'y', b'p', 0, 0, 0, 0, 0, 0, 0, 16]);
        jp2.extend([0, 0, 0, 0, b'j', b'p', b'2', b'c']);
        jp2.extend(siz(64, 32, 0, 0, 1));
        assert_eq!(jpeg2000_siz(&jp2), Ok(want(64, 32, 1)));
        let refused = |data: &[u8], says: &str| {
            let e = jpeg2000_siz(data).unwrap_err();
            assert!(e.contains(says), "{e}");
        };
        refused(&jp2[..28], "without a codestream box");
        let mut long_box = jp2.clone();
        long_box[15] = 255;
        refused(&long_box, "a JP2 box of 255 bytes where 69 remain");
        refused(&[0xFF, 0xD8, 0xFF, 0xE0], "no codestream header");
        refused(&siz(512, 512, 0, 0, 1)[..30], "truncated SIZ");
        refused(
            &siz(512, 512, 600, 0, 1),
            "origin (600, 0) beyond its extent (512, 512)",
        );
    }

    /// PackBits runs counted against the frame's bytes: literals (n + 1 bytes), repeats
    /// (257 − n), the no-op; and each way a frame can be short or misplaced, refused.
    #[test]
    fn rle_frames_are_checked_before_decoding() {
        // 3 literal bytes, then a byte repeated 4 times, a no-op: 7 bytes.
        let good = [2, 10, 11, 12, 253, 9, 128];
        assert_eq!(check_rle(&rle(1, &[64], &good), 7), Ok(()));
        let short = check_rle(&rle(1, &[64], &good), 8).unwrap_err();
        assert!(
            short.contains("segment 1 decodes to 7 of its 8 bytes"),
            "{short}"
        );
        // A literal run past the segment's end.
        let cut = check_rle(&rle(1, &[64], &[5, 1, 2]), 6).unwrap_err();
        assert!(cut.contains("decodes to"), "{cut}");
        let none = check_rle(&rle(0, &[], &good), 7).unwrap_err();
        assert!(none.contains("0 segments, 1 needed"), "{none}");
        let outside = check_rle(&rle(1, &[9999], &good), 7).unwrap_err();
        assert!(outside.contains("segment 1 at bytes 9999"), "{outside}");
        let inside_header = check_rle(&rle(1, &[8], &good), 7).unwrap_err();
        assert!(
            inside_header.contains("segment 1 at bytes 8"),
            "{inside_header}"
        );
    }
}
