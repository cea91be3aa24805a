//! Measurements written as a DICOM Structured Report: a Comprehensive 3D SR (SOP class
//! 1.2.840.10008.5.1.4.1.1.88.34) holding DICOM's Imaging Measurement Report (TID 1500), as
//! quantitative tools file their results with the study (3D Slicer's QuantitativeReporting,
//! OHIF, highdicom): the series' patient and study, a new series of modality SR, a device as
//! the observer, and measurement groups, each a tracked finding with its coded measurements
//! in UCUM units. A measurement may say where it was taken (a point or a line in the CT's
//! Frame of Reference, SCOORD3D); a group may be of a segment of a DICOM Segmentation written
//! with it (TID 1411), else it is a group of measurements of the images (TID 1501).
//! Written through dicom-rs (`dicom-object`): no crate writes SR content trees, so the
//! template's items are assembled here (PS3.3 A.35.13, C.17; PS3.16 TID 1500).

use std::path::Path;

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;
use raystream_math::DVec3;

use crate::new_uid;
use crate::secondary_capture::{Derived, decimal, derived_object, put, truncate, write_dicom};
use crate::segmentation::{Code, SEGMENTATION, code, item, seq, series_to_reference, text};
use crate::volume::{Volume, VolumeError};

/// Comprehensive 3D SR Storage.
pub const COMPREHENSIVE_3D_SR: &str = "1.2.840.10008.5.1.4.1.1.88.34";

/// The coding scheme of raystream's own concepts, where DICOM's context groups have none
/// (PS3.16 8.2: a private scheme's designator starts "99"); the report identifies it.
pub const RAYSTREAM_SCHEME: &str = "99RAYSTREAM";

/// Where a measurement was taken, in the CT's patient coordinates (LPS mm).
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// A point (a section's centroid).
    Point(DVec3),
    /// An open polyline: a diameter's ends, an angle's three points, a path.
    Polyline(Vec<DVec3>),
}

/// One measurement (TID 300): a coded quantity, its value in `unit` (UCUM), how it was
/// derived from others (maximum, minimum), the method, and where it was taken.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    pub concept: Code,
    pub value: f64,
    pub unit: Code,
    pub derivation: Option<Code>,
    pub method: Option<Code>,
    pub region: Option<Region>,
}

/// One measurement group: a finding tracked by its identifier, with its measurements.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasurementGroup {
    /// Tracking Identifier (a reader's name for it); its Tracking UID is made new.
    pub tracking_id: String,
    pub finding: Code,
    pub finding_site: Option<Code>,
    /// The segment (its number) of the Segmentation written with the report that the
    /// measurements are of: a volumetric ROI group (TID 1411); `None`: TID 1501.
    pub segment: Option<u16>,
    pub measurements: Vec<Measurement>,
}

/// A Segmentation of the same series that groups may reference by segment.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentationReference {
    pub sop_instance_uid: String,
    pub series_uid: String,
}

/// What a report says besides its groups.
#[derive(Clone, Debug)]
pub struct ReportInfo<'a> {
    /// The series' description.
    pub description: &'a str,
    /// The device observer: its name (Device Observer Name, Model Name) and version.
    pub device: &'a str,
    pub version: &'a str,
    /// The Segmentation the groups' segments are of.
    pub segmentation: Option<SegmentationReference>,
}

/// What was written.
#[derive(Clone, Debug, PartialEq)]
pub struct ReportWritten {
    pub sop_instance_uid: String,
    pub groups: usize,
    pub measurements: usize,
}

/// Why a report of measurements on `like` cannot be written, if it cannot: it must have been
/// read from a DICOM series with its Study, Series and Frame of Reference UIDs, for the report
/// files with that study and places its coordinates in that frame.
pub fn measurement_report_source(like: &Volume) -> Result<(), String> {
    report_series(like).map(|_| ())
}

/// `like`'s series, which a report on it files with (see [`measurement_report_source`]).
fn report_series(like: &Volume) -> Result<&crate::DicomSeriesInfo, String> {
    let instead = "write the measurements as CSV (-o) or JSON (--json) instead";
    series_to_reference(like, "DICOM report", instead)
}

/// An SR content item: its relationship to its parent, concept name, value and children.
struct Node {
    relationship: &'static str,
    concept: Code,
    value: Value,
    children: Vec<Node>,
}

enum Value {
    Container {
        template: Option<&'static str>,
    },
    Text(String),
    Code(Code),
    UidRef(String),
    Num(f64, Code),
    /// An image (SOP class and instance), or a segment of a Segmentation.
    Image {
        class: String,
        instance: String,
        segment: Option<u16>,
    },
    Scoord3d(Region),
}

impl Node {
    fn new(relationship: &'static str, concept: Code, value: Value) -> Node {
        Node {
            relationship,
            concept,
            value,
            children: Vec::new(),
        }
    }

    fn with(mut self, children: Vec<Node>) -> Node {
        self.children = children;
        self
    }

    /// The content item, its coordinates in `frame` (a Frame of Reference UID).
    fn item(&self, frame: &str, root: bool) -> InMemDicomObject {
        let mut e = Vec::new();
        if !root {
            e.push(text(tags::RELATIONSHIP_TYPE, VR::CS, self.relationship));
        }
        let kind = match &self.value {
            Value::Container { .. } => "CONTAINER",
            Value::Text(_) => "TEXT",
            Value::Code(_) => "CODE",
            Value::UidRef(_) => "UIDREF",
            Value::Num(..) => "NUM",
            Value::Image { .. } => "IMAGE",
            Value::Scoord3d(_) => "SCOORD3D",
        };
        e.push(text(tags::VALUE_TYPE, VR::CS, kind));
        e.push(code(tags::CONCEPT_NAME_CODE_SEQUENCE, self.concept));
        match &self.value {
            Value::Container { template } => {
                e.push(text(tags::CONTINUITY_OF_CONTENT, VR::CS, "SEPARATE"));
                if let Some(t) = template {
                    e.push(seq(
                        tags::CONTENT_TEMPLATE_SEQUENCE,
                        vec![item(vec![
                            text(tags::MAPPING_RESOURCE, VR::CS, "DCMR"),
                            text(tags::TEMPLATE_IDENTIFIER, VR::CS, t),
                        ])],
                    ));
                }
            }
            Value::Text(s) => e.push(text(tags::TEXT_VALUE, VR::UT, s)),
            Value::Code(c) => e.push(code(tags::CONCEPT_CODE_SEQUENCE, *c)),
            Value::UidRef(u) => e.push(text(tags::UID, VR::UI, u)),
            Value::Num(v, unit) => e.push(seq(
                tags::MEASURED_VALUE_SEQUENCE,
                vec![item(vec![
                    text(tags::NUMERIC_VALUE, VR::DS, &decimal(*v)),
                    code(tags::MEASUREMENT_UNITS_CODE_SEQUENCE, *unit),
                ])],
            )),
            Value::Image {
                class,
                instance,
                segment,
            } => {
                let mut r = vec![
                    text(tags::REFERENCED_SOP_CLASS_UID, VR::UI, class),
                    text(tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, instance),
                ];
                if let Some(s) = segment {
                    r.push(DataElement::new(
                        tags::REFERENCED_SEGMENT_NUMBER,
                        VR::US,
                        PrimitiveValue::from(*s),
                    ));
                }
                e.push(seq(tags::REFERENCED_SOP_SEQUENCE, vec![item(r)]));
            }
            Value::Scoord3d(region) => {
                let (kind, points) = match region {
                    Region::Point(p) => ("POINT", std::slice::from_ref(p)),
                    Region::Polyline(p) => ("POLYLINE", p.as_slice()),
                };
                e.push(text(tags::REFERENCED_FRAME_OF_REFERENCE_UID, VR::UI, frame));
                e.push(text(tags::GRAPHIC_TYPE, VR::CS, kind));
                let data: Vec<f32> = points
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                    .collect();
                e.push(DataElement::new(
                    tags::GRAPHIC_DATA,
                    VR::FL,
                    PrimitiveValue::F32(data.into()),
                ));
            }
        }
        if !self.children.is_empty() {
            e.push(seq(
                tags::CONTENT_SEQUENCE,
                self.children.iter().map(|c| c.item(frame, false)).collect(),
            ));
        }
        item(e)
    }
}

/// A concept of DICOM's own coding scheme (PS3.16 Annex D).
const fn dcm(value: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme: "DCM",
        meaning,
    }
}

/// What an image or a measurement's coordinates are: its source (TID 1601, TID 320).
const SOURCE: Code = Code {
    value: "260753009",
    scheme: "SCT",
    meaning: "Source",
};

/// Writes `groups` to `path` as an Imaging Measurement Report on `like`'s series, if
/// [`measurement_report_source`] allows it.
pub fn write_measurement_report(
    path: &Path,
    like: &Volume,
    groups: &[MeasurementGroup],
    info: &ReportInfo,
) -> Result<ReportWritten, VolumeError> {
    let fail = |e: &dyn std::fmt::Display| {
        VolumeError::invalid(path, format!("cannot write a DICOM report: {e}"))
    };
    let series = report_series(like).map_err(|e| fail(&e))?;
    if let Some(g) = groups
        .iter()
        .find(|g| g.segment.is_some() && info.segmentation.is_none())
    {
        return Err(fail(&format!(
            "\"{}\" is of a segment, and no Segmentation is written with the report",
            g.tracking_id
        )));
    }
    if let Some(m) = groups
        .iter()
        .flat_map(|g| &g.measurements)
        .find(|m| !m.value.is_finite())
    {
        return Err(fail(&format!("{} is {}", m.concept.meaning, m.value)));
    }
    let study = &series.study;
    let has = |r: &'static str| move |c: Code, v: Value| Node::new(r, c, v);
    let (contains, obs, modifier, inferred) = (
        has("CONTAINS"),
        has("HAS OBS CONTEXT"),
        has("HAS CONCEPT MOD"),
        has("INFERRED FROM"),
    );

    // TID 1500's header: language (TID 1204), the device observer (TID 1001, 1004), the
    // procedure.
    let mut content = vec![
        modifier(
            dcm("121049", "Language of Content Item and Descendants"),
            Value::Code(Code {
                value: "en-US",
                scheme: "RFC5646",
                meaning: "English (United States)",
            }),
        ),
        obs(
            dcm("121005", "Observer Type"),
            Value::Code(dcm("121007", "Device")),
        ),
        obs(
            dcm("121012", "Device Observer UID"),
            Value::UidRef(new_uid()),
        ),
        obs(
            dcm("121013", "Device Observer Name"),
            Value::Text(info.device.to_string()),
        ),
        obs(
            dcm("121014", "Device Observer Manufacturer"),
            Value::Text("raystream".into()),
        ),
        obs(
            dcm("121015", "Device Observer Model Name"),
            Value::Text(info.device.to_string()),
        ),
        modifier(
            dcm("121058", "Procedure reported"),
            Value::Code(Code {
                value: "77477000",
                scheme: "SCT",
                meaning: "Computed Tomography",
            }),
        ),
    ];
    // TID 1600: the series' images the measurements were taken on (the acquired ones, where
    // the grid's slices are them).
    let mut library = Vec::new();
    let mut images: Vec<(&str, &str)> = Vec::new();
    for s in &series.sources {
        if !images.iter().any(|&(_, i)| i == s.sop_instance_uid) && !s.sop_instance_uid.is_empty() {
            images.push((&s.sop_class_uid, &s.sop_instance_uid));
        }
    }
    if !images.is_empty() {
        // What the images share (TID 1602): their modality and Frame of Reference.
        let acquisition = has("HAS ACQ CONTEXT");
        let mut entries = vec![
            acquisition(
                dcm("121139", "Modality"),
                Value::Code(dcm("CT", "Computed Tomography")),
            ),
            acquisition(
                dcm("112227", "Frame of Reference UID"),
                Value::UidRef(study.frame_of_reference_uid.clone()),
            ),
        ];
        entries.extend(images.iter().map(|&(class, instance)| {
            contains(
                SOURCE,
                Value::Image {
                    class: class.into(),
                    instance: instance.into(),
                    segment: None,
                },
            )
        }));
        library.push(
            contains(
                dcm("126200", "Image Library Group"),
                Value::Container { template: None },
            )
            .with(entries),
        );
    }
    content.push(
        contains(
            dcm("111028", "Image Library"),
            Value::Container { template: None },
        )
        .with(library),
    );

    let mut count = 0;
    let measurement_groups = groups
        .iter()
        .map(|g| {
            let mut items = vec![
                obs(
                    dcm("112039", "Tracking Identifier"),
                    Value::Text(truncate(&g.tracking_id, 64)),
                ),
                obs(
                    dcm("112040", "Tracking Unique Identifier"),
                    Value::UidRef(new_uid()),
                ),
                contains(dcm("121071", "Finding"), Value::Code(g.finding)),
            ];
            if let Some(site) = g.finding_site {
                items.push(modifier(
                    Code {
                        value: "363698007",
                        scheme: "SCT",
                        meaning: "Finding Site",
                    },
                    Value::Code(site),
                ));
            }
            if let (Some(number), Some(seg)) = (g.segment, &info.segmentation) {
                items.push(contains(
                    dcm("121191", "Referenced Segment"),
                    Value::Image {
                        class: SEGMENTATION.into(),
                        instance: seg.sop_instance_uid.clone(),
                        segment: Some(number),
                    },
                ));
                items.push(contains(
                    dcm("121232", "Source series for segmentation"),
                    Value::UidRef(series.uid.clone()),
                ));
            }
            for m in &g.measurements {
                let mut about = Vec::new();
                if let Some(method) = m.method {
                    about.push(modifier(
                        Code {
                            value: "370129005",
                            scheme: "SCT",
                            meaning: "Measurement Method",
                        },
                        Value::Code(method),
                    ));
                }
                if let Some(d) = m.derivation {
                    about.push(modifier(dcm("121401", "Derivation"), Value::Code(d)));
                }
                // A line needs two points: a path of one section is a point, of none nothing.
                let region = match &m.region {
                    Some(Region::Polyline(p)) if p.len() < 2 => {
                        p.first().map(|&q| Region::Point(q))
                    }
                    r => r.clone(),
                };
                if let Some(r) = region {
                    about.push(inferred(SOURCE, Value::Scoord3d(r)));
                }
                items.push(contains(m.concept, Value::Num(m.value, m.unit)).with(about));
                count += 1;
            }
            let template = if g.segment.is_some() { "1411" } else { "1501" };
            contains(
                dcm("125007", "Measurement Group"),
                Value::Container {
                    template: Some(template),
                },
            )
            .with(items)
        })
        .collect();
    content.push(
        contains(
            dcm("126010", "Imaging Measurements"),
            Value::Container { template: None },
        )
        .with(measurement_groups),
    );
    let root = Node::new(
        "",
        dcm("126000", "Imaging Measurement Report"),
        Value::Container {
            template: Some("1500"),
        },
    )
    .with(content);

    // Patient and General Study (the series'), SR Document Series.
    let Derived {
        mut obj,
        sop_uid,
        date,
        time,
        ..
    } = derived_object(
        study,
        COMPREHENSIVE_3D_SR,
        ("SR", "9003"),
        info.description,
        info.version,
    );
    let o = &mut obj;
    o.put(seq(
        tags::REFERENCED_PERFORMED_PROCEDURE_STEP_SEQUENCE,
        vec![],
    ));
    // SR Document General: made by a program, not verified by a reader.
    put(o, tags::INSTANCE_NUMBER, VR::IS, "1");
    put(o, tags::COMPLETION_FLAG, VR::CS, "COMPLETE");
    put(o, tags::VERIFICATION_FLAG, VR::CS, "UNVERIFIED");
    put(o, tags::CONTENT_DATE, VR::DA, &date);
    put(o, tags::CONTENT_TIME, VR::TM, &time);
    o.put(seq(tags::PERFORMED_PROCEDURE_CODE_SEQUENCE, vec![]));
    // The evidence: the series' images, and the Segmentation the groups reference.
    let mut evidence = Vec::new();
    if !images.is_empty() {
        evidence.push(referenced_series(&series.uid, &images));
    }
    if let Some(seg) = &info.segmentation {
        evidence.push(referenced_series(
            &seg.series_uid,
            &[(SEGMENTATION, &seg.sop_instance_uid)],
        ));
    }
    if !evidence.is_empty() {
        o.put(seq(
            tags::CURRENT_REQUESTED_PROCEDURE_EVIDENCE_SEQUENCE,
            vec![item(vec![
                text(tags::STUDY_INSTANCE_UID, VR::UI, &study.study_uid),
                seq(tags::REFERENCED_SERIES_SEQUENCE, evidence),
            ])],
        ));
    }
    // The private coding scheme, where a concept is raystream's.
    if groups
        .iter()
        .flat_map(|g| &g.measurements)
        .flat_map(|m| [Some(m.concept), m.method, m.derivation])
        .flatten()
        .any(|c| c.scheme == RAYSTREAM_SCHEME)
    {
        o.put(seq(
            tags::CODING_SCHEME_IDENTIFICATION_SEQUENCE,
            vec![item(vec![
                text(tags::CODING_SCHEME_DESIGNATOR, VR::SH, RAYSTREAM_SCHEME),
                text(tags::CODING_SCHEME_NAME, VR::ST, "raystream"),
                text(
                    tags::CODING_SCHEME_RESPONSIBLE_ORGANIZATION,
                    VR::ST,
                    "raystream",
                ),
            ])],
        ));
    }
    // SR Document Content: the root item's attributes in the data set itself.
    let top = root.item(&study.frame_of_reference_uid, true);
    for e in top.into_iter() {
        o.put(e);
    }
    write_dicom(obj, path, COMPREHENSIVE_3D_SR, &sop_uid).map_err(|e| fail(&e))?;
    Ok(ReportWritten {
        sop_instance_uid: sop_uid,
        groups: groups.len(),
        measurements: count,
    })
}

/// A Referenced Series Sequence item (Hierarchical Series Reference macro) of `instances`
/// (SOP class, instance).
fn referenced_series(series_uid: &str, instances: &[(&str, &str)]) -> InMemDicomObject {
    item(vec![
        text(tags::SERIES_INSTANCE_UID, VR::UI, series_uid),
        seq(
            tags::REFERENCED_SOP_SEQUENCE,
            instances
                .iter()
                .map(|&(class, instance)| {
                    item(vec![
                        text(tags::REFERENCED_SOP_CLASS_UID, VR::UI, class),
                        text(tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, instance),
                    ])
                })
                .collect(),
        ),
    ])
}

/// The SOP classes of Structured Report documents (Basic Text, Enhanced, Comprehensive,
/// Comprehensive 3D, Extensible SR, Key Object Selection, …).
const SR_CLASSES: &str = "1.2.840.10008.5.1.4.1.1.88.";

/// Whether `class` is a Structured Report document's SOP class.
pub(crate) fn is_report_class(class: &str) -> bool {
    class.starts_with(SR_CLASSES)
}

/// Whether `path` is a DICOM Structured Report, by its file meta's SOP class (read from the
/// file's first 64 KiB, so a large image is not read to find out).
pub fn is_structured_report(path: &Path) -> bool {
    use std::io::Read;
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut head = Vec::new();
    if f.take(1 << 16).read_to_end(&mut head).is_err() {
        return false;
    }
    crate::volume::dicom::read_meta(&head, path).is_ok_and(|(m, _)| is_report_class(&m.sop_class))
}

/// A coded concept as read.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ReadCode {
    pub value: String,
    pub scheme: String,
    pub meaning: String,
}

/// A measurement as read: its concept, value and unit, how it was derived and measured, and
/// where it was taken (the graphic type and its number of points).
#[derive(Clone, Debug, PartialEq)]
pub struct ReadMeasurement {
    pub concept: ReadCode,
    pub value: f64,
    pub unit: ReadCode,
    pub derivation: Option<ReadCode>,
    pub method: Option<ReadCode>,
    pub region: Option<(String, usize)>,
}

/// A measurement group as read: its template (1501, 1410, 1411, … where it says), tracking
/// identifier, finding and site, the region (graphic type, points) or segment it is of, its
/// measurements, and its qualitative evaluations (coded name and value).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReadGroup {
    pub template: Option<String>,
    pub tracking_id: Option<String>,
    pub finding: Option<ReadCode>,
    pub finding_site: Option<ReadCode>,
    pub region: Option<(String, usize)>,
    pub segment: Option<u16>,
    pub measurements: Vec<ReadMeasurement>,
    pub evaluations: Vec<(ReadCode, ReadCode)>,
}

/// A Structured Report as read: its SOP class, title and template, flags, observers (device or
/// person names) and measurement groups.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadReport {
    pub sop_class: String,
    pub title: ReadCode,
    pub template: Option<String>,
    pub completion: String,
    pub verification: String,
    pub observers: Vec<String>,
    pub groups: Vec<ReadGroup>,
}

/// How deep a report's content tree is followed (TID 1500 nests five levels).
const MAX_DEPTH: usize = 32;

/// Reads the Structured Report `path`: its measurement groups (DICOM's Measurement Group
/// containers, 125007, wherever they lie in the tree), as TID 1500 reports hold them.
pub fn read_measurement_report(path: &Path) -> Result<ReadReport, VolumeError> {
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    let (meta, obj) = crate::volume::dicom::parse_dataset(&bytes, path)?;
    let class = meta.sop_class_of(&obj);
    if !is_report_class(&class) {
        return Err(VolumeError::invalid(
            path,
            format!("not a DICOM Structured Report (SOP class {class})"),
        ));
    }
    let title = code_of(&obj, tags::CONCEPT_NAME_CODE_SEQUENCE).ok_or_else(|| {
        VolumeError::invalid(
            path,
            "a Structured Report without a title (Concept Name Code Sequence)",
        )
    })?;
    let mut report = ReadReport {
        sop_class: class,
        title,
        template: template_of(&obj),
        completion: text_of(&obj, tags::COMPLETION_FLAG).unwrap_or_default(),
        verification: text_of(&obj, tags::VERIFICATION_FLAG).unwrap_or_default(),
        observers: Vec::new(),
        groups: Vec::new(),
    };
    walk(&obj, 0, &mut report).map_err(|e| VolumeError::invalid(path, e))?;
    Ok(report)
}

/// A text element, trimmed; none where absent or empty.
pub(crate) fn text_of(o: &InMemDicomObject, tag: dicom_core::Tag) -> Option<String> {
    o.get(tag)
        .and_then(|e| e.to_str().ok())
        .map(|s| s.trim_end_matches(['\0', ' ']).trim().to_string())
        .filter(|s| !s.is_empty())
}

/// A sequence's items (none where absent or not a sequence).
pub(crate) fn items_of(o: &InMemDicomObject, tag: dicom_core::Tag) -> &[InMemDicomObject] {
    o.get(tag).and_then(|e| e.items()).unwrap_or(&[])
}

/// The first item of a code sequence.
pub(crate) fn code_of(o: &InMemDicomObject, tag: dicom_core::Tag) -> Option<ReadCode> {
    let c = items_of(o, tag).first()?;
    Some(ReadCode {
        value: text_of(c, tags::CODE_VALUE)
            .or_else(|| text_of(c, tags::LONG_CODE_VALUE))
            .or_else(|| text_of(c, tags::URN_CODE_VALUE))
            .unwrap_or_default(),
        scheme: text_of(c, tags::CODING_SCHEME_DESIGNATOR).unwrap_or_default(),
        meaning: text_of(c, tags::CODE_MEANING).unwrap_or_default(),
    })
}

fn template_of(o: &InMemDicomObject) -> Option<String> {
    text_of(
        items_of(o, tags::CONTENT_TEMPLATE_SEQUENCE).first()?,
        tags::TEMPLATE_IDENTIFIER,
    )
}

/// The concept name's code value of a content item.
fn concept_of(o: &InMemDicomObject) -> String {
    code_of(o, tags::CONCEPT_NAME_CODE_SEQUENCE)
        .map(|c| c.value)
        .unwrap_or_default()
}

/// Collects the observers and measurement groups under `o`.
fn walk(o: &InMemDicomObject, depth: usize, report: &mut ReadReport) -> Result<(), String> {
    if depth > MAX_DEPTH {
        return Err(format!(
            "its content tree is nested over {MAX_DEPTH} levels deep"
        ));
    }
    for c in items_of(o, tags::CONTENT_SEQUENCE) {
        let kind = text_of(c, tags::VALUE_TYPE).unwrap_or_default();
        let concept = concept_of(c);
        match (kind.as_str(), concept.as_str()) {
            ("CONTAINER", "125007") => report.groups.push(group(c)),
            // Device Observer Name, Person Observer Name.
            ("TEXT", "121013") => report.observers.extend(text_of(c, tags::TEXT_VALUE)),
            ("PNAME", "121008") => report.observers.extend(text_of(c, tags::PERSON_NAME)),
            _ => walk(c, depth + 1, report)?,
        }
    }
    Ok(())
}

/// A measurement group's findings and measurements.
fn group(o: &InMemDicomObject) -> ReadGroup {
    let mut g = ReadGroup {
        template: template_of(o),
        ..Default::default()
    };
    for c in items_of(o, tags::CONTENT_SEQUENCE) {
        let kind = text_of(c, tags::VALUE_TYPE).unwrap_or_default();
        let concept = concept_of(c);
        match (kind.as_str(), concept.as_str()) {
            ("TEXT", "112039") => g.tracking_id = text_of(c, tags::TEXT_VALUE),
            ("CODE", "121071") => g.finding = code_of(c, tags::CONCEPT_CODE_SEQUENCE),
            ("CODE", "363698007") => g.finding_site = code_of(c, tags::CONCEPT_CODE_SEQUENCE),
            ("IMAGE", "121191") => {
                g.segment = items_of(c, tags::REFERENCED_SOP_SEQUENCE)
                    .first()
                    .and_then(|r| r.get(tags::REFERENCED_SEGMENT_NUMBER))
                    .and_then(|e| e.to_int::<u16>().ok())
            }
            ("SCOORD" | "SCOORD3D", "111030") => g.region = region(c, &kind),
            ("NUM", _) => g.measurements.extend(measurement(c)),
            ("CODE", _) if text_of(c, tags::RELATIONSHIP_TYPE).as_deref() == Some("CONTAINS") => {
                if let (Some(name), Some(value)) = (
                    code_of(c, tags::CONCEPT_NAME_CODE_SEQUENCE),
                    code_of(c, tags::CONCEPT_CODE_SEQUENCE),
                ) {
                    g.evaluations.push((name, value));
                }
            }
            _ => {}
        }
    }
    g
}

/// A SCOORD or SCOORD3D item's graphic type and number of points.
fn region(o: &InMemDicomObject, kind: &str) -> Option<(String, usize)> {
    let per = if kind == "SCOORD" { 2 } else { 3 };
    let n = o
        .get(tags::GRAPHIC_DATA)
        .and_then(|e| e.to_multi_float32().ok())
        .map_or(0, |d| d.len() / per);
    text_of(o, tags::GRAPHIC_TYPE).map(|t| (t, n))
}

/// A NUM item's measurement; none where it holds no value (a qualifier in its place).
fn measurement(o: &InMemDicomObject) -> Option<ReadMeasurement> {
    let v = items_of(o, tags::MEASURED_VALUE_SEQUENCE).first()?;
    let value = v.get(tags::NUMERIC_VALUE)?.to_float64().ok()?;
    let mut m = ReadMeasurement {
        concept: code_of(o, tags::CONCEPT_NAME_CODE_SEQUENCE)?,
        value,
        unit: code_of(v, tags::MEASUREMENT_UNITS_CODE_SEQUENCE).unwrap_or_default(),
        derivation: None,
        method: None,
        region: None,
    };
    for c in items_of(o, tags::CONTENT_SEQUENCE) {
        let kind = text_of(c, tags::VALUE_TYPE).unwrap_or_default();
        match (kind.as_str(), concept_of(c).as_str()) {
            ("CODE", "121401") => m.derivation = code_of(c, tags::CONCEPT_CODE_SEQUENCE),
            ("CODE", "370129005") => m.method = code_of(c, tags::CONCEPT_CODE_SEQUENCE),
            ("SCOORD" | "SCOORD3D", _) => m.region = region(c, &kind),
            _ => {}
        }
    }
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::segmentation::tests::grid;
    use dicom_object::open_file;

    fn group(measurements: Vec<Measurement>, segment: Option<u16>) -> MeasurementGroup {
        MeasurementGroup {
            tracking_id: "test".into(),
            finding: dcm("1", "test"),
            finding_site: None,
            segment,
            measurements,
        }
    }

    fn length(value: f64, concept: Code) -> Measurement {
        Measurement {
            concept,
            value,
            unit: Code {
                value: "mm",
                scheme: "UCUM",
                meaning: "millimeter",
            },
            derivation: None,
            method: None,
            region: Some(Region::Point(DVec3::new(1.0, -2.5, 3.25))),
        }
    }

    fn info() -> ReportInfo<'static> {
        ReportInfo {
            description: "test",
            device: "test",
            version: "0",
            segmentation: None,
        }
    }

    fn path(name: &str) -> crate::tests::ScratchFile {
        crate::tests::scratch_file(&format!("sr-{name}.dcm"))
    }

    /// The tree's measurement: its value, unit and point, in the volume's frame of
    /// reference; a multi-frame source listed once in the image library and the evidence;
    /// raystream's coding scheme identified only where a concept is its own.
    #[test]
    fn a_measurement_with_its_point_and_the_image_it_was_taken_on() {
        let v = grid();
        for (concept, private) in [
            (dcm("2", "plain"), false),
            (
                Code {
                    value: "X",
                    scheme: RAYSTREAM_SCHEME,
                    meaning: "own",
                },
                true,
            ),
        ] {
            let p = path("one");
            let w = write_measurement_report(
                &p,
                &v,
                &[group(vec![length(12.5, concept)], None)],
                &info(),
            )
            .unwrap();
            assert_eq!((w.groups, w.measurements), (1, 1));
            let obj = open_file(&p).unwrap();
            let items =
                |o: &InMemDicomObject, tag| o.element(tag).unwrap().items().unwrap().to_vec();
            let text = |o: &InMemDicomObject, tag| {
                o.element(tag)
                    .unwrap()
                    .to_str()
                    .unwrap()
                    .trim_end_matches(['\0', ' '])
                    .to_string()
            };
            assert_eq!(
                obj.element(tags::CODING_SCHEME_IDENTIFICATION_SEQUENCE)
                    .is_ok(),
                private
            );
            assert_eq!(text(&obj, tags::SOP_INSTANCE_UID), w.sop_instance_uid);
            let content = items(&obj, tags::CONTENT_SEQUENCE);
            // Language, five observer items, procedure, image library, measurements.
            assert_eq!(content.len(), 9);
            let library = items(
                &items(&content[7], tags::CONTENT_SEQUENCE)[0],
                tags::CONTENT_SEQUENCE,
            );
            // Modality and Frame of Reference, then the one instance of frames 1-4.
            assert_eq!(library.len(), 3);
            let image = &items(&library[2], tags::REFERENCED_SOP_SEQUENCE)[0];
            assert_eq!(text(image, tags::REFERENCED_SOP_INSTANCE_UID), "1.2.3.4");
            let group = &items(&content[8], tags::CONTENT_SEQUENCE)[0];
            let num = items(group, tags::CONTENT_SEQUENCE).pop().unwrap();
            assert_eq!(text(&num, tags::VALUE_TYPE), "NUM");
            let value = &items(&num, tags::MEASURED_VALUE_SEQUENCE)[0];
            assert_eq!(text(value, tags::NUMERIC_VALUE), "12.5");
            let scoord = &items(&num, tags::CONTENT_SEQUENCE)[0];
            assert_eq!(text(scoord, tags::RELATIONSHIP_TYPE), "INFERRED FROM");
            assert_eq!(text(scoord, tags::GRAPHIC_TYPE), "POINT");
            assert_eq!(
                text(scoord, tags::REFERENCED_FRAME_OF_REFERENCE_UID),
                "1.2.3.9"
            );
            let at = scoord
                .element(tags::GRAPHIC_DATA)
                .unwrap()
                .to_multi_float32()
                .unwrap();
            assert_eq!(at, [1.0, -2.5, 3.25]);
            let evidence = items(&obj, tags::CURRENT_REQUESTED_PROCEDURE_EVIDENCE_SEQUENCE);
            let series = items(&evidence[0], tags::REFERENCED_SERIES_SEQUENCE);
            assert_eq!(items(&series[0], tags::REFERENCED_SOP_SEQUENCE).len(), 1);
        }
    }

    /// A line of one point is written as the point (a POLYLINE needs two).
    #[test]
    fn a_line_of_one_point_is_a_point() {
        let p = path("point");
        let mut m = length(1.0, dcm("2", "plain"));
        m.region = Some(Region::Polyline(vec![DVec3::new(4.0, 5.0, 6.0)]));
        write_measurement_report(&p, &grid(), &[group(vec![m], None)], &info()).unwrap();
        let obj = open_file(&p).unwrap();
        let last = |o: &InMemDicomObject| {
            o.element(tags::CONTENT_SEQUENCE)
                .unwrap()
                .items()
                .unwrap()
                .last()
                .unwrap()
                .clone()
        };
        let scoord = last(&last(&last(&last(&obj))));
        let kind = scoord
            .element(tags::GRAPHIC_TYPE)
            .unwrap()
            .to_str()
            .unwrap();
        assert_eq!(kind.trim(), "POINT");
        let at = scoord
            .element(tags::GRAPHIC_DATA)
            .unwrap()
            .to_multi_float32()
            .unwrap();
        assert_eq!(at, [4.0, 5.0, 6.0]);
    }

    /// Refused, naming the file and the problem: a value that is not a number, a segment's
    /// group with no Segmentation to reference, a CT that has no study.
    #[test]
    fn refusals() {
        let v = grid();
        let p = path("refused");
        let err = |groups: &[MeasurementGroup], v: &Volume| {
            let e = write_measurement_report(&p, v, groups, &info())
                .unwrap_err()
                .to_string();
            assert!(e.contains(&p.display().to_string()), "{e}");
            assert!(!p.exists());
            e
        };
        let e = err(
            &[group(vec![length(f64::NAN, dcm("2", "Width"))], None)],
            &v,
        );
        assert!(e.contains("Width is NaN"), "{e}");
        let e = err(&[group(vec![], Some(1))], &v);
        assert!(
            e.contains("no Segmentation is written with the report"),
            "{e}"
        );
        let mut anonymised = grid();
        anonymised
            .series
            .as_mut()
            .unwrap()
            .study
            .frame_of_reference_uid
            .clear();
        let e = err(&[], &anonymised);
        assert!(e.contains("no Frame of Reference UID"), "{e}");
        let e = err(&[], &Volume::hounsfield([1, 1, 1], [1.0; 3], vec![0.0]));
        assert!(e.contains("not read from a DICOM series"), "{e}");
    }
}
