//! A label volume written as a DICOM Segmentation (SOP class 1.2.840.10008.5.1.4.1.1.66.4), so
//! that it files with the CT series it was made from and a PACS viewer (OHIF, 3D Slicer's
//! QuantitativeReporting, Horos, …) lays it over that series: the series' patient and study,
//! its Frame of Reference, a new series of modality SEG, one binary segment a label with its
//! coded meaning, and one frame a segment and slice that holds it, each frame an acquired image
//! of the series (its position, and a reference to that image as its source). Explicit VR
//! Little Endian, one bit a pixel. Written through dicom-rs (`dicom-object`): no crate writes
//! the Segmentation IOD, so its modules are assembled here (PS3.3 A.51, C.8.20).

use std::path::Path;

use dicom_core::value::DataSetSequence;
use dicom_core::{DataElement, PrimitiveValue, Tag, VR};
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;

use crate::new_uid;
use crate::secondary_capture::{
    DEFLATED_EXPLICIT_VR_LE, Derived, decimal, decimals, derived_object, put,
    put_frame_and_content, truncate, write_dicom_as,
};
use crate::volume::{SourceImage, Volume, VolumeError};

/// Segmentation Storage.
pub const SEGMENTATION: &str = "1.2.840.10008.5.1.4.1.1.66.4";

/// A coded concept (a DICOM Code Sequence item): value, scheme, meaning.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Code {
    pub value: &'static str,
    pub scheme: &'static str,
    pub meaning: &'static str,
}

/// One segment: the voxels of one label value.
#[derive(Clone, Copy, Debug)]
pub struct Segment<'a> {
    /// Its label value in the label volume (1 to 255).
    pub value: u8,
    /// Segment Label and Segment Description.
    pub label: &'a str,
    pub description: &'a str,
    /// What it is: Segmented Property Category and Type (DICOM CID 7150, 7151).
    pub category: Code,
    pub kind: Code,
    /// How a viewer should show it (sRGB; written as Recommended Display CIELab Value).
    pub colour: [u8; 3],
    /// Its RT ROI Interpreted Type where it is written as a structure of an RT Structure Set
    /// (PS3.3 C.8.8.8): `ORGAN`, or `EXTERNAL` for the patient's outline, the one structure a
    /// planning system computes dose within.
    pub rt_type: &'a str,
}

/// What a Segmentation holds besides its labels.
#[derive(Clone, Copy, Debug)]
pub struct SegmentationInfo<'a> {
    /// The series' description and the derivation's.
    pub description: &'a str,
    /// The algorithm that made the segments (Segment Algorithm Name) and its version
    /// (Software Versions).
    pub algorithm: &'a str,
    pub version: &'a str,
}

/// What was written: the frames, each segment's voxels, and the instance and its series (for
/// a report that references its segments).
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentationWritten {
    pub frames: usize,
    pub voxels: Vec<usize>,
    pub sop_instance_uid: String,
    pub series_uid: String,
}

/// Whether `path` names a DICOM file (`.dcm`), which `--mask` writes as a Segmentation.
pub fn is_segmentation_path(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dcm"))
}

/// Why a Segmentation of `like` cannot be written, if it cannot: it must have been read from a
/// DICOM series whose grid slices are its acquired images (not resampled for uneven spacing),
/// with its Study, Series, SOP Instance and Frame of Reference UIDs, for a Segmentation
/// references them all and a viewer places it by them.
pub fn segmentation_source(like: &Volume) -> Result<(), String> {
    let nifti = "write a NIfTI label map, .nii.gz, instead";
    let series = series_to_reference(like, "DICOM Segmentation", nifti)?;
    if series.sources.len() != like.dims[2] {
        return Err(format!(
            "the CT's {} slices were interpolated from {} acquired ones (uneven spacing), so a slice is not an image of the series for a DICOM Segmentation to reference ({nifti})",
            like.dims[2], series.count
        ));
    }
    if let Some(k) = series
        .sources
        .iter()
        .position(|s| s.sop_instance_uid.is_empty())
    {
        return Err(format!(
            "slice {} of the CT series has no SOP Instance UID (anonymised?), which a DICOM Segmentation references ({nifti})",
            k + 1
        ));
    }
    Ok(())
}

/// `like`'s DICOM series, if it has the Study, Series and Frame of Reference UIDs that an
/// object derived from it (`what`: a Segmentation, a report) references; else why not, ending
/// with `instead`, the way out.
pub(crate) fn series_to_reference<'a>(
    like: &'a Volume,
    what: &str,
    instead: &str,
) -> Result<&'a crate::DicomSeriesInfo, String> {
    let series = like.series.as_ref().ok_or_else(|| {
        format!("the CT was not read from a DICOM series, so there is no series for a {what} to reference ({instead})")
    })?;
    for (name, uid) in [
        ("Study Instance UID", &series.study.study_uid),
        ("Series Instance UID", &series.uid),
        (
            "Frame of Reference UID",
            &series.study.frame_of_reference_uid,
        ),
    ] {
        if uid.is_empty() {
            return Err(format!(
                "the CT series has no {name} (anonymised?), which a {what} references ({instead})"
            ));
        }
    }
    Ok(series)
}

/// Writes `labels` (one a voxel of `like`, i fastest, as [`Volume::data`]) to `path` as a
/// DICOM Segmentation of `like`'s series, one segment each of `segments`, if
/// [`segmentation_source`] allows it.
pub fn write_segmentation(
    path: &Path,
    like: &Volume,
    labels: &[u8],
    segments: &[Segment],
    info: &SegmentationInfo,
) -> Result<SegmentationWritten, VolumeError> {
    let fail = |e: &dyn std::fmt::Display| {
        VolumeError::invalid(path, format!("cannot write a DICOM Segmentation: {e}"))
    };
    let [nx, ny, nz] = like.dims;
    labels_fit(like, labels).map_err(|e| fail(&e))?;
    if nx > 65535 || ny > 65535 {
        return Err(fail(&format!(
            "{nx}×{ny} pixels a slice: at most 65535 a side"
        )));
    }
    if segments.is_empty() || segments.len() > 255 {
        return Err(fail(&format!("{} segments: 1 to 255", segments.len())));
    }
    segmentation_source(like).map_err(|e| fail(&e))?;
    let series = like
        .series
        .as_ref()
        .expect("checked by segmentation_source");
    let study = &series.study;

    // The frames: each segment's slices that hold it, in segment then slice order, one bit a
    // pixel, the first pixel in the lowest bit, frames packed on without padding (PS3.5
    // 8.1.1).
    let per = nx * ny;
    let mut frames: Vec<(usize, usize)> = Vec::new();
    let mut voxels = vec![0usize; segments.len()];
    let mut bits: Vec<u8> = Vec::new();
    for (s, seg) in segments.iter().enumerate() {
        for k in 0..nz {
            let start = frames.len() * per;
            let mut n = 0;
            for (p, &l) in labels[k * per..(k + 1) * per].iter().enumerate() {
                if l == seg.value {
                    let b = start + p;
                    bits.resize(bits.len().max(b / 8 + 1), 0);
                    bits[b / 8] |= 1 << (b % 8);
                    n += 1;
                }
            }
            if n > 0 {
                frames.push((s, k));
                voxels[s] += n;
            }
        }
    }
    if frames.is_empty() {
        return Err(fail(&"no voxel holds any of the segments' labels"));
    }
    // The last frame's bits, and a pad byte to an even length.
    bits.resize((frames.len() * per).div_ceil(8).next_multiple_of(2), 0);

    // Patient and General Study (the series'), Segmentation Series.
    let Derived {
        mut obj,
        sop_uid,
        series_uid,
        date,
        time,
    } = derived_object(
        study,
        SEGMENTATION,
        ("SEG", "9002"),
        info.description,
        info.version,
    );
    let o = &mut obj;
    // Frame of Reference, General and Enhanced General Equipment; General Image, Segmentation
    // Image, Multi-frame Functional Groups.
    put_frame_and_content(o, &study.frame_of_reference_uid, (&date, &time));
    put(o, tags::IMAGE_TYPE, VR::CS, "DERIVED\\PRIMARY");
    put(o, tags::CONTENT_LABEL, VR::CS, "SEGMENTATION");
    put(
        o,
        tags::CONTENT_DESCRIPTION,
        VR::LO,
        &truncate(info.description, 64),
    );
    put(o, tags::CONTENT_CREATOR_NAME, VR::PN, "");
    put(
        o,
        tags::DERIVATION_DESCRIPTION,
        VR::ST,
        &truncate(info.description, 1024),
    );
    put(o, tags::SEGMENTATION_TYPE, VR::CS, "BINARY");
    put(o, tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "00");
    put(o, tags::BURNED_IN_ANNOTATION, VR::CS, "NO");
    put(o, tags::NUMBER_OF_FRAMES, VR::IS, &frames.len().to_string());
    put(o, tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2");
    for (tag, v) in [
        (tags::SAMPLES_PER_PIXEL, 1u16),
        (tags::ROWS, ny as u16),
        (tags::COLUMNS, nx as u16),
        (tags::BITS_ALLOCATED, 1),
        (tags::BITS_STORED, 1),
        (tags::HIGH_BIT, 0),
        (tags::PIXEL_REPRESENTATION, 0),
    ] {
        o.put(DataElement::new(tag, VR::US, PrimitiveValue::from(v)));
    }
    o.put(seq(
        tags::SEGMENT_SEQUENCE,
        segments
            .iter()
            .enumerate()
            .map(|(s, seg)| segment_item(s + 1, seg, info.algorithm))
            .collect(),
    ));
    // Multi-frame Dimension: frames indexed by segment, then by position.
    let organisation = new_uid();
    o.put(seq(
        tags::DIMENSION_ORGANIZATION_SEQUENCE,
        vec![item(vec![text(
            tags::DIMENSION_ORGANIZATION_UID,
            VR::UI,
            &organisation,
        )])],
    ));
    put(o, tags::DIMENSION_ORGANIZATION_TYPE, VR::CS, "3D");
    let dimension = |pointer: Tag, group: Tag, label: &str| {
        item(vec![
            text(tags::DIMENSION_ORGANIZATION_UID, VR::UI, &organisation),
            DataElement::new(
                tags::DIMENSION_INDEX_POINTER,
                VR::AT,
                PrimitiveValue::Tags(vec![pointer].into()),
            ),
            DataElement::new(
                tags::FUNCTIONAL_GROUP_POINTER,
                VR::AT,
                PrimitiveValue::Tags(vec![group].into()),
            ),
            text(tags::DIMENSION_DESCRIPTION_LABEL, VR::LO, label),
        ])
    };
    o.put(seq(
        tags::DIMENSION_INDEX_SEQUENCE,
        vec![
            dimension(
                tags::REFERENCED_SEGMENT_NUMBER,
                tags::SEGMENT_IDENTIFICATION_SEQUENCE,
                "ReferencedSegmentNumber",
            ),
            dimension(
                tags::IMAGE_POSITION_PATIENT,
                tags::PLANE_POSITION_SEQUENCE,
                "ImagePositionPatient",
            ),
        ],
    ));
    // Shared functional groups: the slices' orientation and pixel size, their spacing along
    // the slices' normal (a gantry-tilted series steps along the table, not the normal).
    let m = like.index_to_world_affine().matrix3;
    let (row, column, step) = (m.col(0).normalize(), m.col(1).normalize(), m.col(2));
    let between = step.dot(row.cross(column)).abs();
    o.put(seq(
        tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE,
        vec![item(vec![
            seq(
                tags::PLANE_ORIENTATION_SEQUENCE,
                vec![item(vec![text(
                    tags::IMAGE_ORIENTATION_PATIENT,
                    VR::DS,
                    &decimals(&[row.x, row.y, row.z, column.x, column.y, column.z]),
                )])],
            ),
            seq(
                tags::PIXEL_MEASURES_SEQUENCE,
                vec![item(vec![
                    text(
                        tags::PIXEL_SPACING,
                        VR::DS,
                        &decimals(&[like.spacing[1], like.spacing[0]]),
                    ),
                    text(tags::SLICE_THICKNESS, VR::DS, &decimal(between)),
                    text(tags::SPACING_BETWEEN_SLICES, VR::DS, &decimal(between)),
                ])],
            ),
        ])],
    ));
    // Per-frame functional groups: which segment, where, and from which image.
    let per_frame = frames
        .iter()
        .map(|&(s, k)| {
            let p = like.index_to_world(raystream_math::DVec3::new(0.0, 0.0, k as f64));
            item(vec![
                derivation(&series.sources[k]),
                seq(
                    tags::FRAME_CONTENT_SEQUENCE,
                    vec![item(vec![DataElement::new(
                        tags::DIMENSION_INDEX_VALUES,
                        VR::UL,
                        PrimitiveValue::U32(vec![s as u32 + 1, k as u32 + 1].into()),
                    )])],
                ),
                seq(
                    tags::PLANE_POSITION_SEQUENCE,
                    vec![item(vec![text(
                        tags::IMAGE_POSITION_PATIENT,
                        VR::DS,
                        &decimals(&[p.x, p.y, p.z]),
                    )])],
                ),
                seq(
                    tags::SEGMENT_IDENTIFICATION_SEQUENCE,
                    vec![item(vec![DataElement::new(
                        tags::REFERENCED_SEGMENT_NUMBER,
                        VR::US,
                        PrimitiveValue::from(s as u16 + 1),
                    )])],
                ),
            ])
        })
        .collect();
    o.put(seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, per_frame));
    // Common Instance Reference: every image of the series (a multi-frame one once).
    let mut instances: Vec<&SourceImage> = Vec::new();
    for s in &series.sources {
        if !instances
            .iter()
            .any(|i| i.sop_instance_uid == s.sop_instance_uid)
        {
            instances.push(s);
        }
    }
    o.put(seq(
        tags::REFERENCED_SERIES_SEQUENCE,
        vec![item(vec![
            text(tags::SERIES_INSTANCE_UID, VR::UI, &series.uid),
            seq(
                tags::REFERENCED_INSTANCE_SEQUENCE,
                instances
                    .iter()
                    .map(|s| item(reference(s, false)))
                    .collect(),
            ),
        ])],
    ));
    o.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PrimitiveValue::U8(bits.into()),
    ));
    // Deflated: bit frames mostly of zeros and their per-frame groups (the chest CT's aorta:
    // 467 KB to 26.7 KB; BENCHMARKS.md).
    write_dicom_as(obj, path, (SEGMENTATION, &sop_uid), DEFLATED_EXPLICIT_VR_LE)
        .map_err(|e| fail(&e))?;
    Ok(SegmentationWritten {
        frames: frames.len(),
        voxels,
        sop_instance_uid: sop_uid,
        series_uid,
    })
}

/// Why `labels` are not one a voxel of `like`, if they are not.
pub(crate) fn labels_fit(like: &Volume, labels: &[u8]) -> Result<(), String> {
    let [nx, ny, nz] = like.dims;
    if labels.len() == nx * ny * nz {
        Ok(())
    } else {
        Err(format!("{} labels for a {nx}×{ny}×{nz} grid", labels.len()))
    }
}

/// A Segment Sequence item: segment `number` (from 1), made automatically by `algorithm`.
fn segment_item(number: usize, seg: &Segment, algorithm: &str) -> InMemDicomObject {
    item(vec![
        DataElement::new(
            tags::SEGMENT_NUMBER,
            VR::US,
            PrimitiveValue::from(number as u16),
        ),
        text(tags::SEGMENT_LABEL, VR::LO, &truncate(seg.label, 64)),
        text(
            tags::SEGMENT_DESCRIPTION,
            VR::ST,
            &truncate(seg.description, 1024),
        ),
        text(tags::SEGMENT_ALGORITHM_TYPE, VR::CS, "AUTOMATIC"),
        text(
            tags::SEGMENT_ALGORITHM_NAME,
            VR::LO,
            &truncate(algorithm, 64),
        ),
        code(
            tags::SEGMENTED_PROPERTY_CATEGORY_CODE_SEQUENCE,
            seg.category,
        ),
        code(tags::SEGMENTED_PROPERTY_TYPE_CODE_SEQUENCE, seg.kind),
        DataElement::new(
            tags::RECOMMENDED_DISPLAY_CIE_LAB_VALUE,
            VR::US,
            PrimitiveValue::U16(cielab(seg.colour).to_vec().into()),
        ),
    ])
}

/// A frame's Derivation Image functional group: `source`, the image it segments.
fn derivation(source: &SourceImage) -> DataElement<InMemDicomObject> {
    let mut image = reference(source, true);
    // The frame's pixels lie where the source image's do.
    image.push(text(tags::SPATIAL_LOCATIONS_PRESERVED, VR::CS, "YES"));
    image.push(code(
        tags::PURPOSE_OF_REFERENCE_CODE_SEQUENCE,
        Code {
            value: "121322",
            scheme: "DCM",
            meaning: "Source image for image processing operation",
        },
    ));
    seq(
        tags::DERIVATION_IMAGE_SEQUENCE,
        vec![item(vec![
            seq(tags::SOURCE_IMAGE_SEQUENCE, vec![item(image)]),
            code(
                tags::DERIVATION_CODE_SEQUENCE,
                Code {
                    value: "113076",
                    scheme: "DCM",
                    meaning: "Segmentation",
                },
            ),
        ])],
    )
}

/// The SOP Instance Reference macro for `s`, with its frame where `frame` is asked and it has
/// one.
pub(crate) fn reference(s: &SourceImage, frame: bool) -> Vec<DataElement<InMemDicomObject>> {
    let mut r = vec![
        text(tags::REFERENCED_SOP_CLASS_UID, VR::UI, &s.sop_class_uid),
        text(
            tags::REFERENCED_SOP_INSTANCE_UID,
            VR::UI,
            &s.sop_instance_uid,
        ),
    ];
    if let (true, Some(n)) = (frame, s.frame) {
        r.push(text(tags::REFERENCED_FRAME_NUMBER, VR::IS, &n.to_string()));
    }
    r
}

/// A code sequence of one item.
pub(crate) fn code(tag: Tag, c: Code) -> DataElement<InMemDicomObject> {
    seq(
        tag,
        vec![item(vec![
            text(tags::CODE_VALUE, VR::SH, c.value),
            text(tags::CODING_SCHEME_DESIGNATOR, VR::SH, c.scheme),
            text(tags::CODE_MEANING, VR::LO, c.meaning),
        ])],
    )
}

/// A sequence item holding `elements`.
pub(crate) fn item(elements: Vec<DataElement<InMemDicomObject>>) -> InMemDicomObject {
    InMemDicomObject::from_element_iter(elements)
}

/// A sequence of `items`.
pub(crate) fn seq(tag: Tag, items: Vec<InMemDicomObject>) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, VR::SQ, DataSetSequence::from(items))
}

/// A text element.
pub(crate) fn text(tag: Tag, vr: VR, s: &str) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, vr, PrimitiveValue::from(s))
}

/// An sRGB colour as DICOM's scaled CIELab (PS3.3 C.10.7.1.1): L* 0–100 and a*, b* −128–127
/// onto 0–65535, through CIE XYZ under the D50 white of the ICC profile connection space
/// (sRGB's D50-adapted matrix).
pub fn cielab(rgb: [u8; 3]) -> [u16; 3] {
    let lin = rgb.map(|c| {
        let c = c as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    });
    let xyz = [
        [0.436_074_7, 0.385_064_9, 0.143_080_4],
        [0.222_504_5, 0.716_878_6, 0.060_616_9],
        [0.013_932_2, 0.097_104_5, 0.714_173_3],
    ]
    .map(|r| r[0] * lin[0] + r[1] * lin[1] + r[2] * lin[2]);
    let white = [0.964_2, 1.0, 0.824_9];
    let f = |t: f64| {
        let d: f64 = 6.0 / 29.0;
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let [fx, fy, fz] = [0, 1, 2].map(|a| f(xyz[a] / white[a]));
    let (l, a, b) = (116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz));
    let scale =
        |v: f64, lo: f64, hi: f64| ((v.clamp(lo, hi) - lo) / (hi - lo) * 65535.0).round() as u16;
    [
        scale(l, 0.0, 100.0),
        scale(a, -128.0, 127.0),
        scale(b, -128.0, 127.0),
    ]
}

/// DICOM's scaled CIELab (as [`cielab`] writes it) as the nearest sRGB colour: the inverse of
/// [`cielab`], colours outside sRGB's gamut clamped to it.
pub fn srgb_from_cielab(lab: [u16; 3]) -> [u8; 3] {
    let unscale = |v: u16, lo: f64, hi: f64| lo + v as f64 / 65535.0 * (hi - lo);
    let (l, a, b) = (
        unscale(lab[0], 0.0, 100.0),
        unscale(lab[1], -128.0, 127.0),
        unscale(lab[2], -128.0, 127.0),
    );
    let fy = (l + 16.0) / 116.0;
    let (fx, fz) = (fy + a / 500.0, fy - b / 200.0);
    let finv = |f: f64| {
        let d: f64 = 6.0 / 29.0;
        if f > d {
            f * f * f
        } else {
            3.0 * d * d * (f - 4.0 / 29.0)
        }
    };
    let white = [0.964_2, 1.0, 0.824_9];
    let xyz = [
        finv(fx) * white[0],
        finv(fy) * white[1],
        finv(fz) * white[2],
    ];
    // The inverse of `cielab`'s matrix (sRGB's D50-adapted primaries).
    let lin = [
        [3.133_856_1, -1.616_866_7, -0.490_614_6],
        [-0.978_768_4, 1.916_141_5, 0.033_454_0],
        [0.071_945_3, -0.228_991_4, 1.405_242_7],
    ]
    .map(|r| r[0] * xyz[0] + r[1] * xyz[1] + r[2] * xyz[2]);
    lin.map(crate::texture::linear_to_srgb8)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{DicomSeriesInfo, DicomStudy};

    /// A 3×3×4 grid read from a multi-frame image (one instance, frames 1–4), its UIDs.
    pub(crate) fn grid() -> Volume {
        let mut v = Volume::hounsfield([3, 3, 4], [0.5, 0.7, 2.0], vec![0.0; 36]);
        v.origin = [10.0, -20.0, 30.0];
        v.series = Some(DicomSeriesInfo {
            uid: "1.2.3.2".into(),
            count: 4,
            study: DicomStudy {
                study_uid: "1.2.3.1".into(),
                frame_of_reference_uid: "1.2.3.9".into(),
                ..Default::default()
            },
            sources: (1..=4)
                .map(|f| SourceImage {
                    sop_class_uid: "1.2.840.10008.5.1.4.1.1.2.1".into(),
                    sop_instance_uid: "1.2.3.4".into(),
                    frame: Some(f),
                })
                .collect(),
            ..Default::default()
        });
        v
    }

    fn segments() -> [Segment<'static>; 2] {
        let c = Code {
            value: "1",
            scheme: "99TEST",
            meaning: "test",
        };
        let s = |value, label| Segment {
            value,
            label,
            description: label,
            category: c,
            kind: c,
            colour: [255, 0, 0],
            rt_type: "ORGAN",
        };
        [s(1, "one"), s(2, "two")]
    }

    /// Frames of 9 pixels, so that frames after the first start within a byte: the bits run
    /// on across frames (PS3.5 8.1.1), each frame's first pixel in the bit after the last
    /// one's. Only slices holding a segment are frames; each references its slice's frame of
    /// the multi-frame source, and the instance is listed once.
    #[test]
    fn frames_packed_on_and_referenced() {
        let v = grid();
        let mut labels = vec![0u8; 36];
        labels[0] = 1; // slice 0, pixel (0, 0)
        labels[9 + 8] = 1; // slice 1, pixel (2, 2)
        labels[27 + 4] = 2; // slice 3, the centre
        labels[27 + 5] = 2;
        let path = crate::tests::scratch_file("seg.dcm");
        let info = SegmentationInfo {
            description: "test",
            algorithm: "test",
            version: "0",
        };
        let w = write_segmentation(&path, &v, &labels, &segments(), &info).unwrap();
        assert_eq!((w.frames, &w.voxels[..]), (3, &[2, 2][..]));
        let obj = dicom_object::open_file(&path).unwrap();
        let uid = |tag| obj.element(tag).unwrap().to_str().unwrap().to_string();
        assert_eq!(w.sop_instance_uid, uid(tags::SOP_INSTANCE_UID));
        assert_eq!(w.series_uid, uid(tags::SERIES_INSTANCE_UID));
        let bits = obj.element(tags::PIXEL_DATA).unwrap().to_bytes().unwrap();
        let set: Vec<usize> = (0..27)
            .filter(|&b| bits[b / 8] >> (b % 8) & 1 == 1)
            .collect();
        assert_eq!(set, [0, 9 + 8, 18 + 4, 18 + 5]);
        assert_eq!(bits.len(), 4, "27 bits in 4 bytes");
        let frames = obj
            .element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
            .unwrap()
            .items()
            .unwrap();
        let first = |item: &InMemDicomObject, path: &[Tag]| {
            let mut o = item.clone();
            for &t in &path[..path.len() - 1] {
                o = o.element(t).unwrap().items().unwrap()[0].clone();
            }
            o.element(path[path.len() - 1])
                .unwrap()
                .to_str()
                .unwrap()
                .trim()
                .to_string()
        };
        let got: Vec<[String; 3]> = frames
            .iter()
            .map(|f| {
                [
                    first(
                        f,
                        &[
                            tags::SEGMENT_IDENTIFICATION_SEQUENCE,
                            tags::REFERENCED_SEGMENT_NUMBER,
                        ],
                    ),
                    first(
                        f,
                        &[tags::PLANE_POSITION_SEQUENCE, tags::IMAGE_POSITION_PATIENT],
                    ),
                    first(
                        f,
                        &[
                            tags::DERIVATION_IMAGE_SEQUENCE,
                            tags::SOURCE_IMAGE_SEQUENCE,
                            tags::REFERENCED_FRAME_NUMBER,
                        ],
                    ),
                ]
            })
            .collect();
        let row = |s: &str, p: &str, f: &str| [s.to_string(), p.to_string(), f.to_string()];
        assert_eq!(
            got,
            [
                row("1", "10\\-20\\30", "1"),
                row("1", "10\\-20\\32", "2"),
                row("2", "10\\-20\\36", "4"),
            ]
        );
        let shared = &obj
            .element(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)
            .unwrap()
            .items()
            .unwrap()[0];
        assert_eq!(
            first(
                shared,
                &[tags::PIXEL_MEASURES_SEQUENCE, tags::PIXEL_SPACING]
            ),
            "0.7\\0.5",
            "rows apart, then columns"
        );
        let series = &obj
            .element(tags::REFERENCED_SERIES_SEQUENCE)
            .unwrap()
            .items()
            .unwrap()[0];
        assert_eq!(
            series
                .element(tags::REFERENCED_INSTANCE_SEQUENCE)
                .unwrap()
                .items()
                .unwrap()
                .len(),
            1
        );
        // Read back as a label volume on the frames' grid: slices 0 to 3, the labels where
        // they were.
        let back = crate::load_volume(&path, &Default::default()).unwrap();
        assert_eq!(back.dims, [3, 3, 4]);
        assert_eq!(back.origin, v.origin);
        assert_eq!(back.spacing, v.spacing);
        let want: Vec<f32> = labels.iter().map(|&l| l as f32).collect();
        assert_eq!(back.data, want);
        assert_eq!(
            back.segments,
            segments().map(|s| {
                // The codes written come back as the segment's terms.
                let code = |c: Code| crate::ReadCode {
                    value: c.value.into(),
                    scheme: c.scheme.into(),
                    meaning: c.meaning.into(),
                };
                crate::SegmentLabel {
                    number: s.value as u16,
                    label: s.label.to_string(),
                    colour: Some(s.colour),
                    terms: crate::SegmentTerms {
                        category: Some(code(s.category)),
                        kind: Some(code(s.kind)),
                        modifier: None,
                        region: None,
                        region_modifier: None,
                    },
                }
            })
        );
        // Damaged: a header claiming a million frames, pixel data short of its frames, a frame
        // naming no segment, the file cut short; each an error naming the file.
        let damaged = |name: &str, change: &dyn Fn(&mut dicom_object::DefaultDicomObject)| {
            let mut o = dicom_object::open_file(&path).unwrap();
            change(&mut o);
            let p = path.with_extension(format!("{name}.dcm"));
            o.write_to_file(&p).unwrap();
            let e = crate::load_volume(&p, &Default::default())
                .unwrap_err()
                .to_string();
            assert!(e.starts_with(&p.display().to_string()), "{e}");
            e
        };
        let e = damaged("frames", &|o| {
            o.put(DataElement::new(
                tags::NUMBER_OF_FRAMES,
                VR::IS,
                PrimitiveValue::from("1000000"),
            ));
        });
        assert!(
            e.contains("need 1125000 bytes of pixel data; it holds 4"),
            "{e}"
        );
        let e = damaged("short", &|o| {
            o.put(DataElement::new(
                tags::PIXEL_DATA,
                VR::OB,
                PrimitiveValue::U8(vec![0u8; 2].into()),
            ));
        });
        assert!(e.contains("it holds 2"), "{e}");
        let e = damaged("nosegment", &|o| {
            let mut frames = o
                .element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
                .unwrap()
                .items()
                .unwrap()
                .to_vec();
            frames[1].remove_element(tags::SEGMENT_IDENTIFICATION_SEQUENCE);
            o.put(seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, frames));
        });
        assert!(e.contains("frame 2 names no segment"), "{e}");
        // Cut short: an error naming the file wherever the cut loses data. The data set is
        // deflated, and a cut within the deflate stream's last bytes may lose only its end
        // marker: then the labels read back whole, never different ones.
        let bytes = std::fs::read(&path).unwrap();
        let whole = crate::load_volume(&path, &Default::default()).unwrap().data;
        let cut = path.with_extension("cut.dcm");
        let mut refused = 0;
        for n in [1, 3, 8, 40, bytes.len() / 2, bytes.len() * 9 / 10] {
            std::fs::write(&cut, &bytes[..bytes.len() - n]).unwrap();
            match crate::load_volume(&cut, &Default::default()) {
                Ok(v) => assert_eq!(v.data, whole, "{n} bytes cut: other labels"),
                Err(e) => {
                    let e = e.to_string();
                    assert!(e.starts_with(&cut.display().to_string()), "{e}");
                    refused += 1;
                }
            }
        }
        assert!(refused >= 3, "{refused} of 6 cuts refused");
        // Nothing labelled: an error naming the file, and nothing written.
        std::fs::remove_file(&path).ok();
        let e = write_segmentation(&path, &v, &[0; 36], &segments(), &info).unwrap_err();
        assert!(
            e.to_string().starts_with(&path.display().to_string()),
            "{e}"
        );
        assert!(e.to_string().contains("no voxel"), "{e}");
        assert!(!path.exists());
    }

    /// A gantry-tilted CT's grid (its third axis 15° off the slices' normal, along the table):
    /// the Segmentation's frames lie where the slices do, and it reads back on that sheared
    /// grid, label for label.
    #[test]
    fn a_sheared_grid_round_trip() {
        let mut v = grid();
        let (s, c) = 15f64.to_radians().sin_cos();
        v.direction = [[1.0, 0.0, 0.0], [0.0, 1.0, s], [0.0, 0.0, c]];
        let labels: Vec<u8> = (0..36u8).map(|i| [0, 1, 2, 0, 1][i as usize % 5]).collect();
        let path = crate::tests::scratch_file("seg-tilt.dcm");
        let info = SegmentationInfo {
            description: "test",
            algorithm: "test",
            version: "0",
        };
        write_segmentation(&path, &v, &labels, &segments(), &info).unwrap();
        let back = crate::load_volume(&path, &Default::default()).unwrap();
        assert_eq!(back.dims, v.dims);
        for a in 0..3 {
            assert!(
                (back.spacing[a] - v.spacing[a]).abs() < 1e-9,
                "{:?}",
                back.spacing
            );
            assert!((back.origin[a] - v.origin[a]).abs() < 1e-9);
            for b in 0..3 {
                assert!(
                    (back.direction[a][b] - v.direction[a][b]).abs() < 1e-9,
                    "{:?}",
                    back.direction
                );
            }
        }
        let want: Vec<f32> = labels.iter().map(|&l| l as f32).collect();
        assert_eq!(back.data, want);
    }

    /// What a Segmentation cannot reference is said: no series, a blank UID, slices
    /// interpolated between the acquired ones.
    #[test]
    fn sources_a_segmentation_cannot_reference() {
        assert!(segmentation_source(&grid()).is_ok());
        let mut v = grid();
        v.series = None;
        assert!(
            segmentation_source(&v)
                .unwrap_err()
                .contains("not read from a DICOM series")
        );
        let mut v = grid();
        v.series
            .as_mut()
            .unwrap()
            .study
            .frame_of_reference_uid
            .clear();
        assert!(
            segmentation_source(&v)
                .unwrap_err()
                .contains("no Frame of Reference UID")
        );
        let mut v = grid();
        v.series.as_mut().unwrap().sources.clear();
        let e = segmentation_source(&v).unwrap_err();
        assert!(
            e.contains("4 slices were interpolated from 4 acquired"),
            "{e}"
        );
        let mut v = grid();
        v.series.as_mut().unwrap().sources[2]
            .sop_instance_uid
            .clear();
        assert!(
            segmentation_source(&v)
                .unwrap_err()
                .contains("slice 3 of the CT series has no SOP Instance UID")
        );
    }

    /// White is L* 100 with no colour, black L* 0; red and blue on their sides of a* and b*
    /// (sRGB red is L* 54, a* +81, b* +70 under D50; blue L* 29, a* +68, b* −112).
    #[test]
    fn cielab_of_srgb() {
        let lab = |rgb| {
            let [l, a, b] = cielab(rgb);
            let s = |v: u16, lo: f64, hi: f64| lo + v as f64 / 65535.0 * (hi - lo);
            [s(l, 0.0, 100.0), s(a, -128.0, 127.0), s(b, -128.0, 127.0)]
        };
        let near = |got: [f64; 3], want: [f64; 3]| {
            assert!(
                got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1.0),
                "{got:?} vs {want:?}"
            )
        };
        near(lab([255, 255, 255]), [100.0, 0.0, 0.0]);
        near(lab([0, 0, 0]), [0.0, 0.0, 0.0]);
        near(lab([255, 0, 0]), [54.3, 80.8, 69.9]);
        near(lab([0, 0, 255]), [29.6, 68.3, -112.0]);
    }

    /// Every colour of a 16-level grid of sRGB comes back from its CIELab as itself, within
    /// one level (the matrices are each other's inverses to 7 digits; CIELab is rounded to
    /// 16 bits); a colour beyond sRGB's gamut comes back clamped, not wrapped.
    #[test]
    fn srgb_from_cielab_inverts_cielab() {
        let levels: Vec<u8> = (0..=255).step_by(17).collect();
        for &r in &levels {
            for &g in &levels {
                for &b in &levels {
                    let back = srgb_from_cielab(cielab([r, g, b]));
                    assert!(
                        back.iter().zip([r, g, b]).all(|(x, y)| x.abs_diff(y) <= 1),
                        "{:?} came back as {back:?}",
                        [r, g, b]
                    );
                }
            }
        }
        // L* 50, a* 127 (a green-magenta axis sRGB cannot reach): red and blue saturate.
        let outside = srgb_from_cielab([32768, 65535, 32896]);
        assert_eq!(outside[0], 255, "{outside:?}");
    }
}
