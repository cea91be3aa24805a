//! A surface as a DICOM Encapsulated STL (SOP class 1.2.840.10008.5.1.4.1.1.104.3, DICOM
//! Supplement 205): the way a hospital's 3D-printing lab files a model in the PACS with the
//! study it was made from, in that series' patient coordinates (its Frame of Reference: the
//! STL's millimetres are the CT's LPS millimetres), referencing the images it was made from.
//! Read back as the STL it holds.
//!
//! Written through dicom-rs (`dicom-object`), as the other DICOM objects are; the STL inside
//! is the binary STL `iso` writes ([`crate::write_mesh`]).

use std::path::Path;

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;

use crate::measurement_report::{items_of, text_of};
use crate::secondary_capture::{
    Derived, derived_object, put, put_frame_and_content, truncate, write_dicom,
};
use crate::segmentation::{item, reference, seq, text};
use crate::volume::{DicomStudy, SourceImage, Volume};
use crate::write::MeshPart;
use crate::{MeshError, new_uid};

/// Encapsulated STL Storage.
pub const ENCAPSULATED_STL: &str = "1.2.840.10008.5.1.4.1.1.104.3";

/// What an Encapsulated STL says besides its model.
#[derive(Clone, Copy, Debug)]
pub struct ModelInfo<'a> {
    /// Its Document Title: what the model is ("bones at 300 HU", a segment's name).
    pub title: &'a str,
    /// Its series' description: how it was made.
    pub description: &'a str,
    /// raystream's version, as the equipment's software.
    pub version: &'a str,
    /// The series it joins and its number there (several models made together, a segment
    /// each); a new series and number 1 where `None`.
    pub series: Option<(&'a str, u32)>,
}

/// Writes `part` to `path` as a DICOM Encapsulated STL. Made from `source`'s DICOM series, it
/// files with that series' patient and study, shares its Frame of Reference and references
/// its images (Source Instance Sequence, Referenced Series Sequence); from anything else (a
/// NIfTI, a series without its UIDs) it opens a study and a frame of reference of its own.
pub fn write_encapsulated_stl(
    path: &Path,
    part: &MeshPart,
    source: Option<&Volume>,
    info: &ModelInfo,
) -> Result<(), MeshError> {
    let fail = |e: &dyn std::fmt::Display| {
        MeshError::invalid(path, format!("cannot write a DICOM Encapsulated STL: {e}"))
    };
    let mut stl = Vec::new();
    crate::write::write_stl(&mut stl, part).map_err(|e| fail(&e))?;
    // A binary STL is 84 + 50 bytes a triangle: even, as a DICOM value must be.
    debug_assert!(stl.len() % 2 == 0);
    let length = u32::try_from(stl.len()).map_err(|_| {
        fail(&format!(
            "{} bytes of STL: over the 4 GiB a DICOM value holds",
            stl.len()
        ))
    })?;
    let series = source
        .and_then(|v| v.series.as_ref())
        .filter(|s| !s.study.study_uid.is_empty());
    let own = DicomStudy {
        study_uid: new_uid(),
        ..Default::default()
    };
    let study = series.map_or(&own, |s| &s.study);
    let frame = match study.frame_of_reference_uid.as_str() {
        "" => new_uid(),
        uid => uid.to_string(),
    };
    let Derived {
        mut obj,
        sop_uid,
        date,
        time,
        ..
    } = derived_object(
        study,
        ENCAPSULATED_STL,
        ("M3D", "9006"),
        info.description,
        info.version,
    );
    let o = &mut obj;
    // Frame of Reference, Enhanced General Equipment, Encapsulated Document.
    put_frame_and_content(o, &frame, (&date, &time));
    if let Some((uid, number)) = info.series {
        put(o, tags::SERIES_INSTANCE_UID, VR::UI, uid);
        put(o, tags::INSTANCE_NUMBER, VR::IS, &number.to_string());
    }
    put(o, tags::ACQUISITION_DATE_TIME, VR::DT, "");
    put(o, tags::BURNED_IN_ANNOTATION, VR::CS, "NO");
    put(o, tags::DOCUMENT_TITLE, VR::ST, &truncate(info.title, 1024));
    o.put(seq(tags::CONCEPT_NAME_CODE_SEQUENCE, Vec::new()));
    put(
        o,
        tags::MIME_TYPE_OF_ENCAPSULATED_DOCUMENT,
        VR::LO,
        "model/stl",
    );
    o.put(DataElement::new(
        tags::ENCAPSULATED_DOCUMENT_LENGTH,
        VR::UL,
        PrimitiveValue::from(length),
    ));
    o.put(DataElement::new(
        tags::ENCAPSULATED_DOCUMENT,
        VR::OB,
        PrimitiveValue::U8(stl.into()),
    ));
    // Manufacturing 3D Model: the STL's unit.
    o.put(seq(
        tags::MEASUREMENT_UNITS_CODE_SEQUENCE,
        vec![item(vec![
            text(tags::CODE_VALUE, VR::SH, "mm"),
            text(tags::CODING_SCHEME_DESIGNATOR, VR::SH, "UCUM"),
            text(tags::CODE_MEANING, VR::LO, "millimeter"),
        ])],
    ));
    // The images it was made from (each once: an enhanced CT's frames share their file).
    if let Some(s) = series.filter(|s| !s.sources.is_empty()) {
        let mut images: Vec<&SourceImage> = Vec::new();
        for i in &s.sources {
            if !images
                .iter()
                .any(|j| j.sop_instance_uid == i.sop_instance_uid)
            {
                images.push(i);
            }
        }
        let refs = || images.iter().map(|i| item(reference(i, false))).collect();
        o.put(seq(tags::SOURCE_INSTANCE_SEQUENCE, refs()));
        o.put(seq(
            tags::REFERENCED_SERIES_SEQUENCE,
            vec![item(vec![
                text(tags::SERIES_INSTANCE_UID, VR::UI, &s.uid),
                seq(tags::REFERENCED_INSTANCE_SEQUENCE, refs()),
            ])],
        ));
    }
    write_dicom(obj, path, ENCAPSULATED_STL, &sop_uid).map_err(|e| fail(&e))
}

/// Whether `path` is a DICOM file holding an Encapsulated STL (by its file meta's SOP class,
/// from its first 64 KiB): a `.dcm`, or a file without an extension (as on a CD) or named by
/// its UID (digits after the last dot); files of other extensions are not opened.
pub fn is_encapsulated_stl(path: &Path) -> bool {
    use std::io::Read;
    let dicom_name = path.extension().is_none_or(|e| {
        e.eq_ignore_ascii_case("dcm") || e.to_string_lossy().bytes().all(|b| b.is_ascii_digit())
    });
    if !dicom_name || !path.is_file() {
        return false;
    }
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut head = Vec::new();
    if f.take(1 << 16).read_to_end(&mut head).is_err() {
        return false;
    }
    crate::volume::dicom::read_meta(&head, path).is_ok_and(|(m, _)| m.sop_class == ENCAPSULATED_STL)
}

/// The STL an Encapsulated STL's bytes hold (its Encapsulated Document, cut to its length),
/// and what it says of its model.
pub(crate) fn stl_of(bytes: &[u8], path: &Path) -> Result<(Vec<u8>, ModelRecord), MeshError> {
    let invalid = |e: String| MeshError::invalid(path, e);
    let (meta, obj) = crate::volume::dicom::parse_dataset(bytes, path).map_err(|e| match e {
        crate::VolumeError::Invalid { problem, .. } => invalid(problem),
        crate::VolumeError::Io { error, .. } => MeshError::Io {
            path: path.to_path_buf(),
            error,
        },
    })?;
    let class = meta.sop_class_of(&obj);
    if class != ENCAPSULATED_STL {
        return Err(invalid(format!(
            "not a DICOM Encapsulated STL (SOP class {class})"
        )));
    }
    let text = |o, tag| text_of(o, tag).unwrap_or_default();
    let mime = text(&obj, tags::MIME_TYPE_OF_ENCAPSULATED_DOCUMENT);
    if !mime.eq_ignore_ascii_case("model/stl") {
        return Err(invalid(format!(
            "an Encapsulated STL whose document is {mime:?}, not model/stl"
        )));
    }
    let document = obj
        .get(tags::ENCAPSULATED_DOCUMENT)
        .and_then(|e| e.to_bytes().ok())
        .ok_or_else(|| invalid("an Encapsulated STL without its document (0042,0011)".into()))?;
    // The document's own length where given (its value may carry a pad byte).
    let length = obj
        .get(tags::ENCAPSULATED_DOCUMENT_LENGTH)
        .and_then(|e| e.to_int::<u64>().ok());
    let keep = match length {
        Some(n) if n as usize <= document.len() => n as usize,
        Some(n) => {
            return Err(invalid(format!(
                "Encapsulated Document Length {n} for a document of {} bytes",
                document.len()
            )));
        }
        None => document.len(),
    };
    let record = ModelRecord {
        title: text(&obj, tags::DOCUMENT_TITLE),
        patient_name: text(&obj, tags::PATIENT_NAME),
        patient_id: text(&obj, tags::PATIENT_ID),
        study_uid: text(&obj, tags::STUDY_INSTANCE_UID),
        study_date: text(&obj, tags::STUDY_DATE),
        series_uid: text(&obj, tags::SERIES_INSTANCE_UID),
        frame_of_reference_uid: text(&obj, tags::FRAME_OF_REFERENCE_UID),
        source_series: (items_of(&obj, tags::REFERENCED_SERIES_SEQUENCE).iter())
            .map(|i| text(i, tags::SERIES_INSTANCE_UID))
            .collect(),
        source_images: items_of(&obj, tags::SOURCE_INSTANCE_SEQUENCE).len(),
    };
    Ok((document[..keep].to_vec(), record))
}

/// What an Encapsulated STL says about its model, as read (the mesh reader's
/// [`crate::MeshShading::dicom`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ModelRecord {
    pub title: String,
    pub patient_name: String,
    pub patient_id: String,
    pub study_uid: String,
    pub study_date: String,
    pub series_uid: String,
    pub frame_of_reference_uid: String,
    /// The series it was made from (Referenced Series Sequence), and its images referenced
    /// (Source Instance Sequence).
    pub source_series: Vec<String>,
    pub source_images: usize,
}
