//! `measure --report FILE.dcm`: the findings as a DICOM Imaging Measurement Report (TID 1500)
//! of the CT's study, coded from DICOM's vascular context groups (CID 12119 Vascular
//! Ultrasound Property, CID 3481–3483 IVUS and stenosis measurements, SNOMED CT), so that a
//! PACS keeps them with the images and a reporting tool reads them without parsing a table:
//! - "Vessel along the path": its length (the path as a polyline), tortuosity, the widest
//!   lumen's largest diameter (its ends), the narrowest lumen's smallest diameter and area
//!   (its centroid), the widest outer wall's largest diameter (its ends), what the walls and
//!   their lumens hold, `--angle`'s angle;
//! - "Stenosis N" for each graded lesion: diameter and area stenosis against the reference,
//!   the lesion's smallest diameter and area, the reference diameter, the narrowed length,
//!   and against the outer wall, its diameter stenosis and plaque burden;
//! - with a DICOM Segmentation `--mask`, each segment's volume, the segment referenced.
//!
//! An airway's (`--dark`) is coded from DICOM's general measurements instead (CID 7470/7471's
//! diameter and area, DCM's wall thickness, SNOMED CT's airway structure and lumen):
//! - "Airway along the path": its length, tortuosity and `--angle`'s angle;
//! - "Airway lumen": the widest lumen's largest diameter, the narrowest's smallest diameter
//!   and area;
//! - with `--wall`, "Airway wall": its thickness (the mean over the sections with a wall, and
//!   the thickest section's), its share of the airway's area (WA %) and Pi10, which DICOM
//!   does not code (raystream's own codes);
//! - "Stenosis N" at the airway: diameter and area stenosis, the smallest diameter and area,
//!   the reference diameter, the narrowed length;
//! - with a Segmentation, the lumen's and the wall's volumes.

use std::path::Path;

use anyhow::Result;
use raystream_cpu::cpr::PathAngle;
use raystream_cpu::lumen::Section;
use raystream_cpu::stenosis::Stenosis;
use raystream_cpu::wall::{Wall, WallVolumes};
use raystream_io::{Code, Measurement, MeasurementGroup, RAYSTREAM_SCHEME, Region};
use raystream_math::DVec3;
use serde_json::json;

use crate::measure::{Findings, against_wall, extremes, wall_mean, wall_with_most, widest_wall};

/// What `--report` wrote.
pub(crate) struct ReportOut {
    file: String,
    groups: usize,
    measurements: usize,
}

impl ReportOut {
    pub fn text(&self) -> String {
        let plural = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
        format!(
            "report: {} (a DICOM Structured Report of the CT's study, TID 1500): {}, {}\n",
            self.file,
            plural(self.groups, "measurement group"),
            plural(self.measurements, "measurement")
        )
    }

    pub fn json(&self) -> serde_json::Value {
        json!({
            "file": self.file,
            "format": "dicom-sr",
            "groups": self.groups,
            "measurements": self.measurements,
        })
    }
}

const fn sct(value: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme: "SCT",
        meaning,
    }
}

const fn ucum(value: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme: "UCUM",
        meaning,
    }
}

const fn dcm(value: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme: "DCM",
        meaning,
    }
}

const fn own(value: &'static str, meaning: &'static str) -> Code {
    Code {
        value,
        scheme: RAYSTREAM_SCHEME,
        meaning,
    }
}

const MM: Code = ucum("mm", "millimeter");
const MM2: Code = ucum("mm2", "square millimeter");
const ML: Code = ucum("ml", "milliliter");
const PERCENT: Code = ucum("%", "percent");
const DEGREE: Code = ucum("deg", "degree");
const RATIO: Code = ucum("1", "no units");

const MAXIMUM: Code = sct("56851009", "Maximum");
const MINIMUM: Code = sct("255605001", "Minimum");

const BLOOD_VESSEL: Code = sct("59820001", "Blood vessel");
// An airway's: CID 7151/7192's airway, CID 7470's diameter, CID 7471's area, the lumen as
// the mask's segment is coded, DCM's wall thickness, and CID 7464's mean.
const AIRWAY: Code = sct("89187006", "Airway structure");
const LUMEN: Code = sct("91747007", "Lumen");
const DIAMETER: Code = sct("81827009", "Diameter");
const AREA: Code = sct("42798000", "Area");
const MEAN: Code = sct("373098007", "Mean");
const WALL_THICKNESS: Code = dcm("122445", "Wall Thickness");
const STENOSIS: Code = sct("415582006", "Stenosis");
const LENGTH: Code = sct("410668003", "Length");
const TORTUOSITY: Code = sct("15690004", "Tortuosity");
const ANGLE: Code = sct("1483009", "Angle");
const LUMEN_DIAMETER: Code = sct("397413000", "Vessel lumen diameter");
const LUMEN_AREA: Code = sct("397415007", "Vessel lumen cross-sectional area");
const OUTSIDE_DIAMETER: Code = sct("397414006", "Vessel outside diameter");
const DIAMETER_STENOSIS: Code = sct("408715008", "Lumen Diameter Stenosis");
const AREA_STENOSIS: Code = sct("408714007", "Lumen Area Stenosis");
const LESION_LENGTH: Code = sct("408716009", "Stenotic Lesion Length");
const VOLUME: Code = sct("118565006", "Volume");
// CID 3485's volumes: within the outer wall (as IVUS's external elastic membrane), and the
// lumen's.
const WALL_VOLUME: Code = dcm("122371", "EEM Volume");
const LUMEN_VOLUME: Code = dcm("122372", "Lumen Volume");
const PLAQUE_BURDEN: Code = dcm("122354", "Plaque Burden");

// raystream's own concepts and methods, where DICOM's groups have none.
const REFERENCE_DIAMETER: Code = own("RS-REFDIAM", "Reference vessel diameter");
const REFERENCE_AIRWAY_DIAMETER: Code = own("RS-REFAWDIAM", "Reference airway diameter");
const WALL_AREA_PERCENT: Code = own("RS-WAPCT", "Wall area percent of the airway (WA %)");
const PI10: Code = own(
    "RS-PI10",
    "Pi10: sqrt of wall area at 10 mm inner perimeter",
);
const PI10_FIT: Code = own(
    "RS-PI10FIT",
    "sqrt(wall area) against inner perimeter, a line fitted",
);
const HALF_MAXIMUM: Code = own(
    "RS-FWHM",
    "Wall edges at half maximum on rays (Nakano 2000)",
);
const WALL_INTEGRAL: Code = own(
    "RS-WALLINT",
    "Wall thickness from the HU summed across it on rays",
);
const AGAINST_REFERENCE: Code = own(
    "RS-REFERENCE",
    "D min against the reference diameter at the lesion",
);
const AGAINST_WALL: Code = own(
    "RS-OUTERWALL",
    "D min against the outer wall's equivalent diameter (as ECST)",
);
const DISTANCE_METRIC: Code = own(
    "RS-DISTMETRIC",
    "Distance metric: path length over its ends' distance",
);
const CHORD_ANGLE: Code = own(
    "RS-CHORDANGLE",
    "Between the chords' directions: 0 deg runs straight on",
);

/// A measurement of `value` (rounded to the thousandth, as the JSON report gives it).
fn measure(concept: Code, value: f64, unit: Code) -> Measurement {
    Measurement {
        concept,
        value: crate::common::round3(value),
        unit,
        derivation: None,
        method: None,
        region: None,
    }
}

/// The measurement groups of the findings on `sections`, in the report's order; `dark`: an
/// airway's.
pub(crate) fn groups(
    sections: &[Section],
    findings: &Findings,
    dark: bool,
) -> Vec<MeasurementGroup> {
    if dark {
        return airway_groups(sections, findings);
    }
    let mut vessel = path_measurements(sections, findings);
    vessel.extend(lumen_extremes(sections, [LUMEN_DIAMETER, LUMEN_AREA]));
    if let Some((_, w)) = widest_wall(sections) {
        vessel.push(Measurement {
            derivation: Some(MAXIMUM),
            region: Some(Region::Polyline(w.max_ends.to_vec())),
            ..measure(OUTSIDE_DIAMETER, w.max_diameter_mm, MM)
        });
    }
    // What the walls hold and their lumens, over the sections with a wall (the text's
    // `volume:` line).
    let step = findings.winding.length_mm / sections.len().max(1) as f64;
    if let Some(v) = WallVolumes::of(sections, step) {
        vessel.push(measure(WALL_VOLUME, v.wall_mm3 / 1000.0, ML));
        vessel.push(measure(LUMEN_VOLUME, v.lumen_mm3 / 1000.0, ML));
    }
    vessel.extend(findings.angle.map(angle_measurement));
    let mut groups = vec![MeasurementGroup {
        tracking_id: "Vessel along the path".into(),
        finding: BLOOD_VESSEL,
        finding_site: None,
        segment: None,
        measurements: vessel,
    }];

    for (k, g) in findings.lesions.iter().enumerate() {
        let s = &sections[g.lesion];
        let codes = [LUMEN_DIAMETER, LUMEN_AREA, REFERENCE_DIAMETER];
        let mut m = lesion_measurements(sections, g, codes);
        if let Some((d, a, _)) = against_wall(s) {
            let at = s.lumen.as_ref().map(|l| Region::Point(l.centroid));
            m.push(Measurement {
                method: Some(AGAINST_WALL),
                region: at.clone(),
                ..measure(DIAMETER_STENOSIS, d, PERCENT)
            });
            m.push(Measurement {
                region: at,
                ..measure(PLAQUE_BURDEN, a, PERCENT)
            });
        }
        groups.push(MeasurementGroup {
            tracking_id: format!("Stenosis {}", k + 1),
            finding: STENOSIS,
            finding_site: Some(BLOOD_VESSEL),
            segment: None,
            measurements: m,
        });
    }

    groups.extend(segment_groups(findings, false));
    groups
}

/// A graded lesion's measurements: diameter and area stenosis against the reference, the
/// smallest diameter and the area at the lesion, the reference diameter and the narrowed
/// length; `[diameter, area, reference]` code the lumen's diameter and area and the reference
/// diameter (a vessel's or an airway's).
fn lesion_measurements(
    sections: &[Section],
    g: &Stenosis,
    [diameter, area, reference]: [Code; 3],
) -> Vec<Measurement> {
    let s = &sections[g.lesion];
    let l = s.lumen.as_ref().expect("a graded lesion has a lumen");
    let at = || Some(Region::Point(l.centroid));
    let mut m = vec![
        Measurement {
            method: Some(AGAINST_REFERENCE),
            region: at(),
            ..measure(DIAMETER_STENOSIS, g.diameter_pct, PERCENT)
        },
        Measurement {
            method: Some(AGAINST_REFERENCE),
            region: at(),
            ..measure(AREA_STENOSIS, g.area_pct, PERCENT)
        },
        Measurement {
            derivation: Some(MINIMUM),
            region: at(),
            ..measure(diameter, l.min_diameter_mm, MM)
        },
        Measurement {
            region: at(),
            ..measure(area, l.area_mm2, MM2)
        },
        Measurement {
            region: Some(Region::Point(s.row.centre.as_dvec3())),
            ..measure(reference, g.at_lesion_mm, MM)
        },
    ];
    if let Some(n) = &g.narrowed {
        m.push(Measurement {
            region: Some(Region::Polyline(
                sections[n.sections[0]..=n.sections[1]]
                    .iter()
                    .map(|s| s.row.centre.as_dvec3())
                    .collect::<Vec<DVec3>>(),
            )),
            ..measure(LESION_LENGTH, n.mm[1] - n.mm[0], MM)
        });
    }
    m
}

/// The path through the sections' centres.
fn centres(sections: &[Section]) -> Region {
    Region::Polyline(sections.iter().map(|s| s.row.centre.as_dvec3()).collect())
}

/// The path's length (along the sections' centres) and its tortuosity.
fn path_measurements(sections: &[Section], findings: &Findings) -> Vec<Measurement> {
    let mut m = vec![Measurement {
        region: Some(centres(sections)),
        ..measure(LENGTH, findings.winding.length_mm, MM)
    }];
    if let Some(d) = findings.winding.distance_metric {
        m.push(Measurement {
            method: Some(DISTANCE_METRIC),
            ..measure(TORTUOSITY, d, RATIO)
        });
    }
    m
}

/// `--angle`'s angle, at its three points.
fn angle_measurement(g: &PathAngle) -> Measurement {
    Measurement {
        method: Some(CHORD_ANGLE),
        region: Some(Region::Polyline(g.points.to_vec())),
        ..measure(ANGLE, g.deviation_deg, DEGREE)
    }
}

/// The widest lumen's largest diameter (its ends) and the narrowest's smallest diameter and
/// area (its centroid), coded `[diameter, area]` (a vessel's or an airway's); none without a
/// closed lumen.
fn lumen_extremes(sections: &[Section], [diameter, area]: [Code; 2]) -> Vec<Measurement> {
    let Some((w, n)) = extremes(sections) else {
        return Vec::new();
    };
    let lumen = |i: usize| sections[i].lumen.as_ref().expect("a closed lumen");
    let (w, n) = (lumen(w), lumen(n));
    vec![
        Measurement {
            derivation: Some(MAXIMUM),
            region: Some(Region::Polyline(w.max_ends.to_vec())),
            ..measure(diameter, w.max_diameter_mm, MM)
        },
        Measurement {
            derivation: Some(MINIMUM),
            region: Some(Region::Point(n.centroid)),
            ..measure(diameter, n.min_diameter_mm, MM)
        },
        Measurement {
            derivation: Some(MINIMUM),
            region: Some(Region::Point(n.centroid)),
            ..measure(area, n.area_mm2, MM2)
        },
    ]
}

/// With a DICOM Segmentation `--mask`, each segment's volume, the segment referenced.
fn segment_groups(findings: &Findings, dark: bool) -> Vec<MeasurementGroup> {
    let Some(mask) = findings.mask.filter(|m| m.segmentation.is_some()) else {
        return Vec::new();
    };
    let segments = crate::measure::mask_segments(mask.wall.is_some(), dark);
    let volumes = std::iter::once(mask.lumen).chain(mask.wall);
    segments
        .iter()
        .zip(volumes)
        .enumerate()
        .map(|(number, (seg, (_, ml)))| MeasurementGroup {
            tracking_id: seg.label.to_string(),
            finding: seg.kind,
            finding_site: None,
            segment: Some(number as u16 + 1),
            measurements: vec![measure(VOLUME, ml, ML)],
        })
        .collect()
}

/// An airway's groups: along the path, the lumen, the wall, the stenoses, the segments.
fn airway_groups(sections: &[Section], findings: &Findings) -> Vec<MeasurementGroup> {
    let mut along = path_measurements(sections, findings);
    along.extend(findings.angle.map(angle_measurement));
    let group =
        |id: &str, finding: Code, site: Option<Code>, m: Vec<Measurement>| MeasurementGroup {
            tracking_id: id.into(),
            finding,
            finding_site: site,
            segment: None,
            measurements: m,
        };
    let mut groups = vec![group("Airway along the path", AIRWAY, None, along)];
    let lumen = lumen_extremes(sections, [DIAMETER, AREA]);
    if !lumen.is_empty() {
        groups.push(group("Airway lumen", AIRWAY, Some(LUMEN), lumen));
    }
    // The walls' figures as the text and the JSON report give them.
    let thickness = |w: &Wall| w.mean_thickness_mm;
    if let (Some(mean_mm), Some(percent), Some((i, thickest))) = (
        wall_mean(sections, thickness),
        wall_mean(sections, Wall::area_percent),
        wall_with_most(sections, thickness),
    ) {
        let method = if findings.wall_integral {
            WALL_INTEGRAL
        } else {
            HALF_MAXIMUM
        };
        let mut m = vec![
            Measurement {
                derivation: Some(MEAN),
                method: Some(method),
                region: Some(centres(sections)),
                ..measure(WALL_THICKNESS, mean_mm, MM)
            },
            Measurement {
                derivation: Some(MAXIMUM),
                method: Some(method),
                region: Some(Region::Point(sections[i].row.centre.as_dvec3())),
                ..measure(WALL_THICKNESS, thickest.mean_thickness_mm, MM)
            },
            Measurement {
                derivation: Some(MEAN),
                method: Some(method),
                ..measure(WALL_AREA_PERCENT, percent, PERCENT)
            },
        ];
        if let Some(Ok(p)) = findings.pi10 {
            m.push(Measurement {
                method: Some(PI10_FIT),
                ..measure(PI10, p.value_mm, MM)
            });
        }
        groups.push(group("Airway wall", AIRWAY, None, m));
    }
    for (k, g) in findings.lesions.iter().enumerate() {
        let codes = [DIAMETER, AREA, REFERENCE_AIRWAY_DIAMETER];
        let m = lesion_measurements(sections, g, codes);
        groups.push(group(
            &format!("Stenosis {}", k + 1),
            STENOSIS,
            Some(AIRWAY),
            m,
        ));
    }
    groups.extend(segment_groups(findings, true));
    groups
}

/// Writes the report of the findings on `sections` of `volume` to `out`.
pub(crate) fn write(
    out: &Path,
    volume: &raystream_io::Volume,
    sections: &[Section],
    findings: &Findings,
    dark: bool,
) -> Result<ReportOut> {
    let groups = groups(sections, findings, dark);
    let info = raystream_io::ReportInfo {
        description: if dark {
            "raystream measure: the airway along the path"
        } else {
            "raystream measure: the vessel along the path"
        },
        device: "raystream measure",
        version: env!("CARGO_PKG_VERSION"),
        segmentation: findings.mask.and_then(|m| m.segmentation.clone()),
    };
    let written = raystream_io::write_measurement_report(out, volume, &groups, &info)?;
    Ok(ReportOut {
        file: out.display().to_string(),
        groups: written.groups,
        measurements: written.measurements,
    })
}
