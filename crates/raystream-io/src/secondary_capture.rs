//! A rendering as a DICOM Secondary Capture image (SOP class 1.2.840.10008.5.1.4.1.1.7), so
//! that it can be sent to a PACS and filed with the study it was made from: the source series'
//! patient and study, a new series and instance, Explicit VR Little Endian: 8-bit RGB as the
//! picture is seen, or, for a projection or slice of a CT, its Hounsfield units as 16-bit
//! greyscale with the window it was shown in, so that a viewer can window it again.
//! Written through dicom-rs (`dicom-object`).

use std::hash::{BuildHasher, Hasher};
use std::path::Path;

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};

use crate::{DicomStudy, VolumeError};

/// Secondary Capture Image Storage.
pub const SECONDARY_CAPTURE: &str = "1.2.840.10008.5.1.4.1.1.7";

/// A new UID under the 2.25 root (ISO/IEC 9834-8: a 128-bit random number in decimal), its
/// bits from the process's randomly keyed hashers, the clock and the process id.
pub fn new_uid() -> String {
    let mut bits = 0u128;
    for half in 0..2 {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u128(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos()),
        );
        h.write_u32(std::process::id());
        h.write_u8(half);
        bits = (bits << 64) | h.finish() as u128;
    }
    format!("2.25.{bits}")
}

/// What a Secondary Capture image says besides its pixels.
#[derive(Clone, Debug, Default)]
pub struct CaptureInfo<'a> {
    /// The study it joins; a new one where `None` (or without a Study Instance UID).
    pub study: Option<&'a DicomStudy>,
    /// Its series' UID and its number in it (a turntable's frames share a series); a new
    /// series and number 1 where `None`.
    pub series: Option<(&'a str, u32)>,
    /// How it was made: the series' and the derivation's description.
    pub description: &'a str,
    /// The patient directions of its rows and columns (DICOM's Patient Orientation, e.g.
    /// `["L", "F"]`), where known.
    pub orientation: Option<[String; 2]>,
    /// Whether text was burnt into the pixels.
    pub annotated: bool,
    /// Where the pixels lie in the patient, for HU pixels sampled on a plane (a slice, a slab's
    /// projection seen square on): the image is then a derived CT image (CT Image Storage,
    /// DERIVED\SECONDARY\REFORMATTED) in the source's frame of reference, as scanners store
    /// reformats, rather than a Secondary Capture.
    pub plane: Option<ImagePlane>,
}

/// A reformatted image's plane in LPS millimetres (DICOM's Image Plane module).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImagePlane {
    /// The centre of the top-left pixel (Image Position (Patient)).
    pub position: [f64; 3],
    /// Unit directions of increasing column and of increasing row (Image Orientation
    /// (Patient)).
    pub row: [f64; 3],
    pub column: [f64; 3],
    /// The square pixels' size (Pixel Spacing).
    pub spacing: f64,
    /// A slab's thickness (Slice Thickness); `None` for a plane sampled once.
    pub thickness: Option<f64>,
}

/// CT Image Storage.
pub const CT_IMAGE: &str = "1.2.840.10008.5.1.4.1.1.2";

/// A Secondary Capture image's pixels, `width`×`height`, row-major from the top-left pixel.
#[derive(Clone, Copy, Debug)]
pub enum CapturePixels<'a> {
    /// 8-bit RGB, three bytes a pixel.
    Rgb8(&'a [u8]),
    /// Hounsfield units (NaN: no value, e.g. a ray that missed the volume), written as signed
    /// 16-bit MONOCHROME2 rounded to 1 HU, with `window` (width, level) as the VOI LUT.
    Hu {
        values: &'a [f32],
        window: (f32, f32),
    },
}

/// The stored value of a pixel without one: Pixel Padding Value, far below any HU.
pub const HU_PADDING: i16 = i16::MIN;

/// Writes `pixels` to `path` as a Secondary Capture image, as `info` says.
pub fn write_secondary_capture(
    path: &Path,
    pixels: CapturePixels,
    (width, height): (u32, u32),
    info: &CaptureInfo,
) -> Result<(), VolumeError> {
    let CaptureInfo {
        study,
        series,
        description,
        orientation,
        annotated,
        plane,
    } = info.clone();
    let fail =
        |e: &dyn std::fmt::Display| VolumeError::invalid(path, format!("cannot write DICOM: {e}"));
    let (len, per) = match pixels {
        CapturePixels::Rgb8(rgb) => (rgb.len(), 3),
        CapturePixels::Hu { values, .. } => (values.len(), 1),
    };
    if len != per * width as usize * height as usize || width > 65535 || height > 65535 {
        return Err(fail(&format!(
            "{len} values for {width}x{height} pixels of {per} (at most 65535 a side)"
        )));
    }
    if plane.is_some() && per != 1 {
        return Err(fail(&"a reformatted CT image holds HU, not RGB"));
    }
    let sop_class = if plane.is_some() {
        CT_IMAGE
    } else {
        SECONDARY_CAPTURE
    };
    // A reformat stays in its source's patient coordinates even where the source names no
    // study (an anonymised series).
    let source_frame = study.map_or("", |s| s.frame_of_reference_uid.as_str());
    let new_study = DicomStudy {
        study_uid: new_uid(),
        ..Default::default()
    };
    let study = match study {
        Some(s) if !s.study_uid.is_empty() => s,
        _ => &new_study,
    };
    let sop_uid = new_uid();
    let mut obj = InMemDicomObject::new_empty();
    let o = &mut obj;
    // Text as UTF-8, declared: a patient's name beyond ASCII is written as read.
    put(o, tags::SPECIFIC_CHARACTER_SET, VR::CS, "ISO_IR 192");
    put(o, tags::SOP_CLASS_UID, VR::UI, sop_class);
    put(o, tags::SOP_INSTANCE_UID, VR::UI, &sop_uid);
    match plane {
        Some(p) => {
            put(
                o,
                tags::IMAGE_TYPE,
                VR::CS,
                "DERIVED\\SECONDARY\\REFORMATTED",
            );
            put(o, tags::MODALITY, VR::CS, "CT");
            let frame = match source_frame {
                "" => new_uid(),
                uid => uid.to_string(),
            };
            put(o, tags::FRAME_OF_REFERENCE_UID, VR::UI, &frame);
            put(o, tags::POSITION_REFERENCE_INDICATOR, VR::LO, "");
            put(
                o,
                tags::IMAGE_POSITION_PATIENT,
                VR::DS,
                &decimals(&p.position),
            );
            let turn: Vec<f64> = p.row.iter().chain(&p.column).copied().collect();
            put(o, tags::IMAGE_ORIENTATION_PATIENT, VR::DS, &decimals(&turn));
            put(
                o,
                tags::PIXEL_SPACING,
                VR::DS,
                &decimals(&[p.spacing, p.spacing]),
            );
            let thickness = p.thickness.map(decimal).unwrap_or_default();
            put(o, tags::SLICE_THICKNESS, VR::DS, &thickness);
            put(o, tags::KVP, VR::DS, "");
            put(o, tags::ACQUISITION_NUMBER, VR::IS, "");
            // General Series' type 2C: unknown here, so present and empty.
            put(o, tags::PATIENT_POSITION, VR::CS, "");
        }
        None => {
            put(o, tags::IMAGE_TYPE, VR::CS, "DERIVED\\SECONDARY");
            put(o, tags::MODALITY, VR::CS, "OT");
            put(o, tags::CONVERSION_TYPE, VR::CS, "WSD");
        }
    }
    // The patient and the study it files with.
    put_patient_study(o, study);
    let (series_uid, instance) = match series {
        Some((uid, n)) => (uid.to_string(), n),
        None => (new_uid(), 1),
    };
    put(o, tags::SERIES_INSTANCE_UID, VR::UI, &series_uid);
    put(o, tags::SERIES_NUMBER, VR::IS, "9001");
    // General Series' type 2C, for a paired body part: unknown here, so present and empty.
    put(o, tags::LATERALITY, VR::CS, "");
    put(
        o,
        tags::SERIES_DESCRIPTION,
        VR::LO,
        &truncate(description, 64),
    );
    put(
        o,
        tags::DERIVATION_DESCRIPTION,
        VR::ST,
        &truncate(description, 1024),
    );
    put(o, tags::INSTANCE_NUMBER, VR::IS, &instance.to_string());
    put(
        o,
        tags::PATIENT_ORIENTATION,
        VR::CS,
        &orientation
            .map(|[r, c]| format!("{r}\\{c}"))
            .unwrap_or_default(),
    );
    put(
        o,
        tags::BURNED_IN_ANNOTATION,
        VR::CS,
        if annotated { "YES" } else { "NO" },
    );
    put(o, tags::MANUFACTURER, VR::LO, "raystream");
    // The Image Pixel module: RGB bytes as seen, or signed 16-bit HU.
    let (photometric, samples, bits, signed) = match pixels {
        CapturePixels::Rgb8(_) => ("RGB", 3, 8, 0),
        CapturePixels::Hu { .. } => ("MONOCHROME2", 1, 16, 1),
    };
    put(o, tags::PHOTOMETRIC_INTERPRETATION, VR::CS, photometric);
    for (tag, v) in [
        (tags::ROWS, height as u16),
        (tags::COLUMNS, width as u16),
        (tags::SAMPLES_PER_PIXEL, samples),
        (tags::BITS_ALLOCATED, bits),
        (tags::BITS_STORED, bits),
        (tags::HIGH_BIT, bits - 1),
        (tags::PIXEL_REPRESENTATION, signed),
    ] {
        o.put(DataElement::new(tag, VR::US, PrimitiveValue::from(v)));
    }
    match pixels {
        CapturePixels::Rgb8(rgb) => {
            o.put(DataElement::new(
                tags::PLANAR_CONFIGURATION,
                VR::US,
                PrimitiveValue::from(0u16),
            ));
            // A value's length is even: an odd pixel count gets a pad byte.
            let mut bytes = rgb.to_vec();
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            o.put(DataElement::new(
                tags::PIXEL_DATA,
                VR::OB,
                PrimitiveValue::U8(bytes.into()),
            ));
        }
        CapturePixels::Hu {
            values,
            window: (w, l),
        } => {
            put(o, tags::RESCALE_INTERCEPT, VR::DS, "0");
            put(o, tags::RESCALE_SLOPE, VR::DS, "1");
            put(o, tags::RESCALE_TYPE, VR::LO, "HU");
            put(o, tags::WINDOW_CENTER, VR::DS, &decimal(l as f64));
            put(o, tags::WINDOW_WIDTH, VR::DS, &decimal(w as f64));
            o.put(DataElement::new(
                tags::PIXEL_PADDING_VALUE,
                VR::SS,
                PrimitiveValue::from(HU_PADDING),
            ));
            let stored: Vec<i16> = values
                .iter()
                .map(|&v| {
                    if v.is_nan() {
                        HU_PADDING
                    } else {
                        // Above the padding value, so that no HU reads as "no value".
                        v.round().clamp(HU_PADDING as f32 + 1.0, i16::MAX as f32) as i16
                    }
                })
                .collect();
            o.put(DataElement::new(
                tags::PIXEL_DATA,
                VR::OW,
                PrimitiveValue::I16(stored.into()),
            ));
        }
    }
    write_dicom(obj, path, sop_class, &sop_uid).map_err(|e| fail(&e))
}

/// Explicit VR Little Endian.
pub(crate) const EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1";
/// Deflated Explicit VR Little Endian: the data set through deflate, which DCMTK, pydicom and
/// dicom-rs read (dicom3tools' dciodvfy does not: the tests inflate it with DCMTK first).
pub(crate) const DEFLATED_EXPLICIT_VR_LE: &str = "1.2.840.10008.1.2.1.99";

/// Writes `obj` to `path` as a DICOM file storing instance `sop_uid` of `sop_class`, Explicit
/// VR Little Endian.
pub(crate) fn write_dicom(
    obj: InMemDicomObject,
    path: &Path,
    sop_class: &str,
    sop_uid: &str,
) -> Result<(), String> {
    write_dicom_as(obj, path, (sop_class, sop_uid), EXPLICIT_VR_LE)
}

/// [`write_dicom`] in transfer syntax `ts` ([`EXPLICIT_VR_LE`] or [`DEFLATED_EXPLICIT_VR_LE`]).
pub(crate) fn write_dicom_as(
    obj: InMemDicomObject,
    path: &Path,
    (sop_class, sop_uid): (&str, &str),
    ts: &str,
) -> Result<(), String> {
    obj.with_meta(
        FileMetaTableBuilder::new()
            .transfer_syntax(ts)
            .media_storage_sop_class_uid(sop_class)
            .media_storage_sop_instance_uid(sop_uid),
    )
    .map_err(|e| e.to_string())?
    .write_to_file(path)
    .map_err(|e| e.to_string())
}

/// The Patient and General Study modules of an object derived from `study`'s series, which
/// files it with that study.
pub(crate) fn put_patient_study(o: &mut InMemDicomObject, study: &DicomStudy) {
    for (tag, vr, value) in [
        (tags::PATIENT_NAME, VR::PN, &study.patient_name),
        (tags::PATIENT_ID, VR::LO, &study.patient_id),
        (tags::PATIENT_BIRTH_DATE, VR::DA, &study.patient_birth_date),
        (tags::PATIENT_SEX, VR::CS, &study.patient_sex),
        (tags::STUDY_INSTANCE_UID, VR::UI, &study.study_uid),
        (tags::STUDY_DATE, VR::DA, &study.study_date),
        (tags::STUDY_TIME, VR::TM, &study.study_time),
        (tags::STUDY_ID, VR::SH, &study.study_id),
        (tags::ACCESSION_NUMBER, VR::SH, &study.accession_number),
        (
            tags::REFERRING_PHYSICIAN_NAME,
            VR::PN,
            &study.referring_physician,
        ),
        (tags::STUDY_DESCRIPTION, VR::LO, &study.study_description),
    ] {
        put(o, tag, vr, value);
    }
}

/// The start of a new object derived from `study`'s series (a Segmentation, a report): UTF-8
/// text, SOP class `sop_class` and a new instance, the Patient and General Study modules (so
/// that it files with that study), a new series of `modality`, numbered `number`, described
/// as `description`, dated now (UTC), and raystream `version` as the equipment.
pub(crate) struct Derived {
    pub obj: InMemDicomObject,
    pub sop_uid: String,
    pub series_uid: String,
    /// Now, as DA and TM.
    pub date: String,
    pub time: String,
}

pub(crate) fn derived_object(
    study: &DicomStudy,
    sop_class: &str,
    (modality, number): (&str, &str),
    description: &str,
    version: &str,
) -> Derived {
    let now = dicom_core::chrono::Utc::now();
    let (date, time) = (
        now.format("%Y%m%d").to_string(),
        now.format("%H%M%S").to_string(),
    );
    let (sop_uid, series_uid) = (crate::new_uid(), crate::new_uid());
    let mut obj = InMemDicomObject::new_empty();
    let o = &mut obj;
    put(o, tags::SPECIFIC_CHARACTER_SET, VR::CS, "ISO_IR 192");
    put(o, tags::SOP_CLASS_UID, VR::UI, sop_class);
    put(o, tags::SOP_INSTANCE_UID, VR::UI, &sop_uid);
    put(o, tags::TIMEZONE_OFFSET_FROM_UTC, VR::SH, "+0000");
    put_patient_study(o, study);
    put(o, tags::MODALITY, VR::CS, modality);
    put(o, tags::SERIES_INSTANCE_UID, VR::UI, &series_uid);
    put(o, tags::SERIES_NUMBER, VR::IS, number);
    put(o, tags::SERIES_DATE, VR::DA, &date);
    put(o, tags::SERIES_TIME, VR::TM, &time);
    put(
        o,
        tags::SERIES_DESCRIPTION,
        VR::LO,
        &truncate(description, 64),
    );
    put(o, tags::MANUFACTURER, VR::LO, "raystream");
    put(o, tags::MANUFACTURER_MODEL_NAME, VR::LO, "raystream");
    put(o, tags::SOFTWARE_VERSIONS, VR::LO, &truncate(version, 64));
    Derived {
        obj,
        sop_uid,
        series_uid,
        date,
        time,
    }
}

/// The Frame of Reference module (`frame`), the Enhanced General Equipment's serial number,
/// and the object as instance 1 of its series, made at `date` and `time`: what a derived
/// object in its source's patient coordinates (a Segmentation, a 3D model) carries.
pub(crate) fn put_frame_and_content(
    o: &mut InMemDicomObject,
    frame: &str,
    (date, time): (&str, &str),
) {
    put(o, tags::FRAME_OF_REFERENCE_UID, VR::UI, frame);
    put(o, tags::POSITION_REFERENCE_INDICATOR, VR::LO, "");
    put(o, tags::DEVICE_SERIAL_NUMBER, VR::LO, "1");
    put(o, tags::INSTANCE_NUMBER, VR::IS, "1");
    put(o, tags::CONTENT_DATE, VR::DA, date);
    put(o, tags::CONTENT_TIME, VR::TM, time);
}

pub(crate) fn put(obj: &mut InMemDicomObject, tag: dicom_core::Tag, vr: VR, value: &str) {
    obj.put(DataElement::new(tag, vr, PrimitiveValue::from(value)));
}

/// Numbers as a multi-valued DS: each [`decimal`], joined by backslashes.
pub(crate) fn decimals(v: &[f64]) -> String {
    v.iter().map(|&x| decimal(x)).collect::<Vec<_>>().join("\\")
}

/// `v` as a DS value: at most 16 characters, as many significant digits as fit.
pub(crate) fn decimal(v: f64) -> String {
    let s = format!("{v}");
    if s.len() <= 16 {
        return s;
    }
    // Fixed notation with fewer decimals, else scientific.
    let int = format!("{v:.0}").len();
    if int <= 14 {
        let s = format!("{v:.*}", 15 - int);
        if s.len() <= 16 {
            return s;
        }
    }
    format!("{v:.8e}")
}

/// `s` cut to at most `n` characters (a VR's length limit).
pub(crate) fn truncate(s: &str, n: usize) -> String {
    s.chars().take(n).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text_of(obj: &dicom_object::DefaultDicomObject, tag: dicom_core::Tag) -> String {
        let e = obj.element(tag).unwrap().to_str().unwrap();
        e.trim_end_matches(['\0', ' ']).to_string()
    }

    /// Written and read back with dicom-rs: the study's tags carried over, new UIDs under
    /// 2.25, the pixels byte for byte (an odd count padded), the orientation and annotation.
    #[test]
    fn secondary_capture_round_trip() {
        let scratch = crate::tests::scratch_dir("sc");
        let dir = scratch.path();
        let (w, h) = (5u32, 3u32);
        let rgb: Vec<u8> = (0..3 * w * h).map(|i| (i * 7) as u8).collect();
        let study = DicomStudy {
            patient_name: "DOE^JANE".into(),
            patient_id: "12345".into(),
            study_uid: "1.2.3.4.5".into(),
            accession_number: "A77".into(),
            ..Default::default()
        };
        let path = dir.join("sc.dcm");
        let info = CaptureInfo {
            study: Some(&study),
            description: "raystream mip",
            orientation: Some(["L".to_string(), "F".to_string()]),
            annotated: true,
            ..Default::default()
        };
        write_secondary_capture(&path, CapturePixels::Rgb8(&rgb), (w, h), &info).unwrap();
        let obj = dicom_object::open_file(&path).unwrap();
        let text = |tag| text_of(&obj, tag);
        assert_eq!(text(tags::SOP_CLASS_UID), SECONDARY_CAPTURE);
        assert_eq!(text(tags::PATIENT_NAME), "DOE^JANE");
        assert_eq!(text(tags::PATIENT_ID), "12345");
        assert_eq!(text(tags::STUDY_INSTANCE_UID), "1.2.3.4.5");
        assert_eq!(text(tags::ACCESSION_NUMBER), "A77");
        assert_eq!(text(tags::SERIES_DESCRIPTION), "raystream mip");
        assert_eq!(text(tags::PATIENT_ORIENTATION), "L\\F");
        assert_eq!(text(tags::BURNED_IN_ANNOTATION), "YES");
        assert_eq!(text(tags::PHOTOMETRIC_INTERPRETATION), "RGB");
        let series = text(tags::SERIES_INSTANCE_UID);
        let sop = text(tags::SOP_INSTANCE_UID);
        assert!(series.starts_with("2.25.") && sop.starts_with("2.25.") && series != sop);
        assert!(series.len() <= 64 && sop.len() <= 64);
        assert_eq!(
            obj.meta()
                .media_storage_sop_instance_uid()
                .trim_end_matches('\0'),
            sop
        );
        let int = |tag| obj.element(tag).unwrap().to_int::<u32>().unwrap();
        assert_eq!(
            (
                int(tags::ROWS),
                int(tags::COLUMNS),
                int(tags::SAMPLES_PER_PIXEL)
            ),
            (3, 5, 3)
        );
        let pixels = obj.element(tags::PIXEL_DATA).unwrap().to_bytes().unwrap();
        assert_eq!(&pixels[..rgb.len()], &rgb[..]);
        assert_eq!(pixels.len(), rgb.len() + 1, "45 bytes padded to 46");
        assert_eq!(text(tags::INSTANCE_NUMBER), "1");
        // Without a source study: a new one; a series given: that series and number; a wrong
        // pixel count is an error naming the file.
        let info = CaptureInfo {
            series: Some(("1.2.3.9", 7)),
            ..Default::default()
        };
        write_secondary_capture(&path, CapturePixels::Rgb8(&rgb), (w, h), &info).unwrap();
        let obj = dicom_object::open_file(&path).unwrap();
        let text = |tag| text_of(&obj, tag);
        assert!(text(tags::STUDY_INSTANCE_UID).starts_with("2.25."));
        assert_eq!(text(tags::SERIES_INSTANCE_UID), "1.2.3.9");
        assert_eq!(text(tags::INSTANCE_NUMBER), "7");
        assert_eq!(text(tags::BURNED_IN_ANNOTATION), "NO");
        let e = write_secondary_capture(&path, CapturePixels::Rgb8(&rgb[1..]), (w, h), &info)
            .unwrap_err();
        assert!(
            e.to_string().starts_with(&path.display().to_string()),
            "{e}"
        );
    }

    /// HU pixels: signed 16-bit MONOCHROME2 that dicom-pixeldata turns back into the values,
    /// rounded to 1 HU and clamped to 16 bits, NaN as the padding value, with the window.
    #[test]
    fn hu_pixels_round_trip() {
        use dicom_pixeldata::PixelDecoder;
        let scratch = crate::tests::scratch_dir("sc-hu");
        let dir = scratch.path();
        let path = dir.join("hu.dcm");
        let values = [-1000.4, -0.6, 0.0, 12.5, 1e6, -1e6, f32::NAN, 3071.0];
        let pixels = CapturePixels::Hu {
            values: &values,
            window: (400.0, 40.0),
        };
        write_secondary_capture(&path, pixels, (4, 2), &CaptureInfo::default()).unwrap();
        let obj = dicom_object::open_file(&path).unwrap();
        let text = |tag| text_of(&obj, tag);
        assert_eq!(text(tags::PHOTOMETRIC_INTERPRETATION), "MONOCHROME2");
        assert_eq!(text(tags::RESCALE_TYPE), "HU");
        assert_eq!(text(tags::WINDOW_CENTER), "40");
        assert_eq!(text(tags::WINDOW_WIDTH), "400");
        let int = |tag| obj.element(tag).unwrap().to_int::<i32>().unwrap();
        assert_eq!(int(tags::PIXEL_REPRESENTATION), 1);
        assert_eq!(int(tags::PIXEL_PADDING_VALUE), -32768);
        let got: Vec<f32> = obj.decode_pixel_data().unwrap().to_vec().unwrap();
        assert_eq!(
            got,
            [
                -1000.0, -1.0, 0.0, 13.0, 32767.0, -32767.0, -32768.0, 3071.0
            ]
        );
    }
}
