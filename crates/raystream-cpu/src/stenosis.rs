//! A stenosis graded from the lumen measured along a vessel's path ([`crate::lumen`]): how
//! much narrower the lumen is at the lesion than the vessel would be there without it, by
//! diameter and by area, and how long the narrowed segment is, as a CT angiography
//! workstation reports it.
//!
//! - The lesion is the closed section of least area (the minimal lumen area), or the one a
//!   reader places.
//! - The reference is what the vessel measures where it is healthy. Placed by the reader, it
//!   is one section's equivalent diameter (NASCET's distal reference), or the line through
//!   two sections' (proximal and distal, the lesion between them). Otherwise it is the
//!   *interpolated reference* of quantitative angiography: a straight line fitted to the
//!   equivalent diameters against arc length over the closed sections within a span either
//!   side of the lesion that lie between [`NARROWED`] and [`DILATED`] of it (fitted to all,
//!   then to those in that band about the last line, until the set no longer changes), so
//!   that neither the lesion pulls it down nor a post-stenotic dilatation (or an aneurysmal
//!   bulge, a bifurcation's bulb) pushes it up, while a vessel's gentle taper is followed.
//!   With sections on one side of
//!   the lesion only, the line is flat (their mean): a slope from one side would be
//!   extrapolated across the lesion. The lesion's shoulders, narrowed by less than
//!   [`NARROWED`], stay in the fit and draw it down a little (under 1 % for a smooth lesion
//!   8 mm either side in a 40 mm span: tested).
//! - Diameter stenosis = 1 − D min / D ref, the lesion's smallest calliper diameter (the
//!   narrowest width of the residual lumen, as NASCET measures) against the reference
//!   diameter; area stenosis = 1 − area / (π D ref² / 4). A lumen wider than its reference
//!   grades negative (a dilatation), and is reported as such.
//! - The narrowed segment: the closed sections on either side of the lesion, in a row, whose
//!   equivalent diameter is below [`NARROWED`] of the reference there.
//!
//! A reference fitted by the vessel's own figures cannot tell a diffusely diseased vessel, or a
//! dilatation of less than [`DILATED`], from health, nor follow a step in the vessel's width
//! (a stent graft's end): placed references are the reader's answer.

use crate::lumen::{Lumen, Section};

/// Below this fraction of the reference diameter a section is narrowed: left out of the
/// fitted reference, and counted in the narrowed segment.
pub const NARROWED: f64 = 0.9;

/// Above this fraction of the fitted reference a section is dilated (a post-stenotic
/// dilatation, an aneurysmal bulge, a bifurcation's bulb): left out of the fit as well. An
/// ectasia or aneurysm is 1.5 times the normal diameter; 1.2 leaves the fit the sections
/// within a fifth of it, well beyond a healthy vessel's taper over a span.
pub const DILATED: f64 = 1.2;

/// A diameter stenosis in words, on the scale the SCCT grades CT angiography by (Cury et al.
/// 2016, CAD-RADS; the words, not the coronary report): none (under 1 %, or wider than the
/// reference), minimal (1–24 %), mild (25–49 %), moderate (50–69 %), severe (70–99 %). A
/// lesion graded here has a contrast-filled lumen, so never an occlusion (100 %).
pub fn severity(diameter_pct: f64) -> &'static str {
    match diameter_pct {
        p if p < 1.0 => "none",
        p if p < 25.0 => "minimal",
        p if p < 50.0 => "mild",
        p if p < 70.0 => "moderate",
        _ => "severe",
    }
}

/// Fits of the reference before it must have settled, or be refused.
const MAX_ROUNDS: usize = 64;

/// How to grade a stenosis.
#[derive(Clone, Debug, PartialEq)]
pub struct StenosisOptions {
    /// The lesion's arc length along the path, mm (the section nearest it); none: the closed
    /// section of least area.
    pub lesion_mm: Option<f64>,
    /// The reference sections' arc lengths, mm: none (fitted), one, or two with the lesion
    /// between them.
    pub reference_mm: Vec<f64>,
    /// A fitted reference uses the closed sections within this many mm of the lesion.
    pub span_mm: f64,
}

impl Default for StenosisOptions {
    fn default() -> Self {
        StenosisOptions {
            lesion_mm: None,
            reference_mm: Vec::new(),
            span_mm: 20.0,
        }
    }
}

/// Where the reference came from.
#[derive(Clone, Debug, PartialEq)]
pub enum ReferenceSource {
    /// Fitted to these sections (indices), those between [`NARROWED`] and [`DILATED`] of
    /// the line; of the others within the span, `dropped` lie below it and `dilated` above;
    /// `sloped`: a line through sections on both sides of the lesion, else flat.
    Fitted {
        used: Vec<usize>,
        dropped: usize,
        dilated: usize,
        sloped: bool,
    },
    /// The reader's sections (indices).
    Placed(Vec<usize>),
}

/// A graded stenosis.
#[derive(Clone, Debug, PartialEq)]
pub struct Stenosis {
    /// The lesion's section (an index into the sections) and its arc length, mm.
    pub lesion: usize,
    pub lesion_mm: f64,
    /// The reference diameter along the path: `at_lesion_mm + slope · (arc − lesion's arc)`,
    /// mm, defined over `domain_mm` (arc lengths).
    pub at_lesion_mm: f64,
    pub slope: f64,
    pub domain_mm: [f64; 2],
    pub source: ReferenceSource,
    /// The reference area at the lesion, mm² (of a circle of the reference diameter).
    pub reference_area_mm2: f64,
    /// 1 − D min / D ref and 1 − area / reference area, in percent.
    pub diameter_pct: f64,
    pub area_pct: f64,
    /// The narrowed segment, if the lesion is narrowed.
    pub narrowed: Option<Narrowed>,
}

/// The closed sections in a row about a lesion whose equivalent diameter is below
/// [`NARROWED`] of the reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Narrowed {
    /// Its first and last sections (indices).
    pub sections: [usize; 2],
    /// The arc lengths it covers, mm, each section standing for its share of the path.
    pub mm: [f64; 2],
}

impl Stenosis {
    /// The reference diameter at arc length `s` (mm), where the reference is defined.
    pub fn reference_at(&self, s: f64) -> Option<f64> {
        (self.domain_mm[0] - 1e-9..=self.domain_mm[1] + 1e-9)
            .contains(&s)
            .then_some(self.at_lesion_mm + self.slope * (s - self.lesion_mm))
    }
}

/// A section's lumen, if it is closed (an open one's figures are of the part in the field).
fn closed(s: &Section) -> Option<&Lumen> {
    s.lumen.as_ref().filter(|l| !l.open)
}

/// The section nearest arc length `s`, which must lie on the path of `length_mm`.
fn nearest(sections: &[Section], s: f64, length_mm: f64, what: &str) -> Result<usize, String> {
    if !(s.is_finite() && (0.0..=length_mm).contains(&s)) {
        return Err(format!(
            "{what} at {s} mm: not on the path (0 to {length_mm:.1} mm along it)"
        ));
    }
    let i = sections
        .iter()
        .enumerate()
        .min_by(|a, b| (a.1.arc_mm - s).abs().total_cmp(&(b.1.arc_mm - s).abs()))
        .map(|(i, _)| i)
        .ok_or("no sections")?;
    match &sections[i].lumen {
        Some(l) if !l.open => Ok(i),
        other => Err(format!(
            "{what} at {s} mm: its section ({} at {:.1} mm) has {}",
            i + 1,
            sections[i].arc_mm,
            if other.is_some() {
                "a lumen open to the field's edge, which cannot be measured whole"
            } else {
                "no lumen"
            }
        )),
    }
}

/// The least-squares line `d = a + b (s − s0)` through `(s, d)` pairs; flat (their mean) when
/// `sloped` is false.
pub(crate) fn fit(points: &[(f64, f64)], s0: f64, sloped: bool) -> (f64, f64) {
    let n = points.len() as f64;
    let ms = points.iter().map(|p| p.0 - s0).sum::<f64>() / n;
    let md = points.iter().map(|p| p.1).sum::<f64>() / n;
    if !sloped {
        return (md, 0.0);
    }
    let sxx: f64 = points.iter().map(|p| (p.0 - s0 - ms).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - s0 - ms) * (p.1 - md)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (md - b * ms, b)
}

/// The reference diameter along the path: `at_lesion + slope · (arc − the lesion's arc)` over
/// the arc lengths `domain`, and where it came from.
struct Line {
    at_lesion: f64,
    slope: f64,
    domain: [f64; 2],
    source: ReferenceSource,
}

/// A closed section's equivalent diameter.
fn equivalent(sections: &[Section], i: usize) -> Option<f64> {
    closed(&sections[i]).map(|l| l.equivalent_diameter_mm)
}

/// The interpolated reference: the line fitted to the closed sections within `span` mm of the
/// lesion that lie between [`NARROWED`] and [`DILATED`] of it (a fixed point: fitted to all of
/// them, then to those in that band about the last line, until that set stops changing).
fn fitted(sections: &[Section], lesion: usize, length_mm: f64, span: f64) -> Result<Line, String> {
    let s0 = sections[lesion].arc_mm;
    let eq = |i: usize| equivalent(sections, i).expect("closed sections only");
    let candidates: Vec<usize> = (0..sections.len())
        .filter(|&i| i != lesion && (sections[i].arc_mm - s0).abs() <= span)
        .filter(|&i| equivalent(sections, i).is_some())
        .collect();
    let mut used = candidates.clone();
    for _ in 0..MAX_ROUNDS {
        if used.len() < 2 {
            return Err(format!(
                "no reference: fewer than two closed sections within {span} mm of the lesion (section {} at {s0:.1} mm) are free of narrowing; place the reference (--reference MM[,MM]) or widen the span",
                lesion + 1
            ));
        }
        let sloped = used.iter().any(|&i| i < lesion) && used.iter().any(|&i| i > lesion);
        let pts: Vec<(f64, f64)> = used.iter().map(|&i| (sections[i].arc_mm, eq(i))).collect();
        let (a, b) = fit(&pts, s0, sloped);
        let line = |i: usize| a + b * (sections[i].arc_mm - s0);
        let next: Vec<usize> = candidates
            .iter()
            .copied()
            .filter(|&i| (NARROWED * line(i)..=DILATED * line(i)).contains(&eq(i)))
            .collect();
        if next == used {
            let dilated = candidates
                .iter()
                .filter(|&&i| eq(i) > DILATED * line(i))
                .count();
            let dropped = candidates.len() - used.len() - dilated;
            return Ok(Line {
                at_lesion: a,
                slope: b,
                domain: [(s0 - span).max(0.0), (s0 + span).min(length_mm)],
                source: ReferenceSource::Fitted {
                    used,
                    dropped,
                    dilated,
                    sloped,
                },
            });
        }
        used = next;
    }
    Err(format!(
        "the fitted reference does not settle within {span} mm of the lesion (section {} at {s0:.1} mm); place it (--reference MM[,MM])",
        lesion + 1
    ))
}

/// The reader's reference: one section's equivalent diameter, or the line through two with the
/// lesion between them.
fn placed(
    sections: &[Section],
    lesion: usize,
    length_mm: f64,
    refs: &[f64],
) -> Result<Line, String> {
    let s0 = sections[lesion].arc_mm;
    let eq = |i: usize| equivalent(sections, i).expect("closed sections only");
    match *refs {
        [r] => {
            let i = nearest(sections, r, length_mm, "the reference")?;
            if i == lesion {
                return Err(format!(
                    "the reference at {r} mm is the lesion's own section ({})",
                    lesion + 1
                ));
            }
            let s = sections[i].arc_mm;
            Ok(Line {
                at_lesion: eq(i),
                slope: 0.0,
                domain: [s0.min(s), s0.max(s)],
                source: ReferenceSource::Placed(vec![i]),
            })
        }
        [r1, r2] => {
            let i = nearest(sections, r1, length_mm, "the first reference")?;
            let j = nearest(sections, r2, length_mm, "the second reference")?;
            let (i, j) = (i.min(j), i.max(j));
            let (si, sj) = (sections[i].arc_mm, sections[j].arc_mm);
            if !(i < lesion && lesion < j) {
                return Err(format!(
                    "the lesion (section {} at {s0:.1} mm) must lie between the two references (sections {} and {}, at {si:.1} and {sj:.1} mm)",
                    lesion + 1,
                    i + 1,
                    j + 1,
                ));
            }
            let (a, b) = fit(&[(si, eq(i)), (sj, eq(j))], s0, true);
            Ok(Line {
                at_lesion: a,
                slope: b,
                domain: [si, sj],
                source: ReferenceSource::Placed(vec![i, j]),
            })
        }
        _ => Err(format!(
            "{} references: give one (distal, as NASCET) or two (proximal and distal)",
            refs.len()
        )),
    }
}

/// Grades the stenosis on `sections` (as [`crate::lumen::measure_path`] returns them) of a
/// path `length_mm` long.
pub fn grade(
    sections: &[Section],
    length_mm: f64,
    opt: &StenosisOptions,
) -> Result<Stenosis, String> {
    if !(opt.span_mm.is_finite() && opt.span_mm > 0.0) {
        return Err(format!(
            "a span of {} mm: it must be a positive number",
            opt.span_mm
        ));
    }
    let lesion = match opt.lesion_mm {
        Some(s) => nearest(sections, s, length_mm, "the lesion")?,
        None => sections
            .iter()
            .enumerate()
            .filter_map(|(i, s)| closed(s).map(|l| (i, l.area_mm2)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
            .ok_or("no section has a closed lumen: nothing to grade")?,
    };
    grade_at(sections, length_mm, lesion, opt)
}

/// [`grade`] at the closed section `lesion` (an index; `opt`'s lesion is not read).
fn grade_at(
    sections: &[Section],
    length_mm: f64,
    lesion: usize,
    opt: &StenosisOptions,
) -> Result<Stenosis, String> {
    let line = if opt.reference_mm.is_empty() {
        fitted(sections, lesion, length_mm, opt.span_mm)?
    } else {
        placed(sections, lesion, length_mm, &opt.reference_mm)?
    };
    let d_ref = line.at_lesion;
    if !(d_ref.is_finite() && d_ref > 0.0) {
        return Err(format!(
            "a reference diameter of {d_ref:.2} mm at the lesion: the vessel's figures do not give one; place the reference (--reference MM[,MM])"
        ));
    }
    let s0 = sections[lesion].arc_mm;
    let l = closed(&sections[lesion]).expect("the lesion's lumen is closed");
    let reference_area_mm2 = std::f64::consts::PI * d_ref * d_ref / 4.0;
    let mut st = Stenosis {
        lesion,
        lesion_mm: s0,
        at_lesion_mm: d_ref,
        slope: line.slope,
        domain_mm: line.domain,
        source: line.source,
        reference_area_mm2,
        diameter_pct: 100.0 * (1.0 - l.min_diameter_mm / d_ref),
        area_pct: 100.0 * (1.0 - l.area_mm2 / reference_area_mm2),
        narrowed: None,
    };
    let is_narrowed =
        |i: usize| match (equivalent(sections, i), st.reference_at(sections[i].arc_mm)) {
            (Some(d), Some(r)) => d < NARROWED * r,
            _ => false,
        };
    if is_narrowed(lesion) {
        let [mut first, mut last] = [lesion, lesion];
        while first > 0 && is_narrowed(first - 1) {
            first -= 1;
        }
        while last + 1 < sections.len() && is_narrowed(last + 1) {
            last += 1;
        }
        // Sections lie at the middle of equal parts of the path.
        let half = 0.5 * length_mm / sections.len() as f64;
        st.narrowed = Some(Narrowed {
            sections: [first, last],
            mm: [sections[first].arc_mm - half, sections[last].arc_mm + half],
        });
    }
    Ok(st)
}

/// The most candidate sections [`grade_lesions`] grades in its search for further lesions.
pub const MAX_CANDIDATES: usize = 10_000;

/// The `n` most severe lesions on `sections` (by diameter stenosis, the most severe first),
/// each graded as [`grade`] grades one with a fitted reference (`opt` must place neither
/// lesion nor reference). The lesions are found as tandem lesions are read: first the closed
/// section of least area; then, by increasing area, each closed section outside the lesions
/// found so far (their sections and narrowed segments) that is narrowed against its own
/// reference, with a narrowed segment apart from theirs. The search looks at up to
/// [`MAX_CANDIDATES`] candidates; one that cannot be graded (no reference free of narrowing
/// about it) is passed over. Ranked by severity, a focal stenosis comes before the least
/// area where the vessel merely tapers.
pub fn grade_lesions(
    sections: &[Section],
    length_mm: f64,
    opt: &StenosisOptions,
    n: usize,
) -> Result<Vec<Stenosis>, String> {
    if opt.lesion_mm.is_some() || !opt.reference_mm.is_empty() {
        return Err("several lesions are found and referenced by the search itself: place neither a lesion nor a reference".into());
    }
    let mut found = vec![grade(sections, length_mm, opt)?];
    let mut order: Vec<(usize, f64)> = sections
        .iter()
        .enumerate()
        .filter_map(|(i, s)| closed(s).map(|l| (i, l.area_mm2)))
        .collect();
    order.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    // The sections a lesion takes: its narrowed segment, or the lesion alone.
    let span = |g: &Stenosis| g.narrowed.as_ref().map_or([g.lesion; 2], |n| n.sections);
    for &(i, _) in order.iter().take(MAX_CANDIDATES) {
        if found.iter().any(|g| (span(g)[0]..=span(g)[1]).contains(&i)) {
            continue;
        }
        let Ok(g) = grade_at(sections, length_mm, i, opt) else {
            continue;
        };
        let Some(seg) = g.narrowed.as_ref().map(|n| n.sections) else {
            continue;
        };
        if found
            .iter()
            .all(|f| seg[1] < span(f)[0] || seg[0] > span(f)[1])
        {
            found.push(g);
        }
    }
    // The most severe first; of equal grades, the one found first (the smaller area).
    found.sort_by(|a, b| b.diameter_pct.total_cmp(&a.diameter_pct));
    found.truncate(n);
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpr::CprRow;
    use raystream_math::{DVec3, Vec3};
    use std::f64::consts::PI;

    /// A section at `arc` mm whose lumen is closed, `d` mm across (a circle's area) and
    /// `d_min` at its narrowest; none where `d` is 0, open where it is negative.
    fn section(arc: f64, d: f64, d_min: f64) -> Section {
        let lumen = (d != 0.0).then(|| Lumen {
            area_mm2: PI * d * d / 4.0,
            equivalent_diameter_mm: d.abs(),
            max_diameter_mm: d.abs(),
            max_ends: [DVec3::ZERO; 2],
            min_diameter_mm: d_min,
            min_direction: DVec3::X,
            cross_diameter_mm: d_min,
            centroid: DVec3::ZERO,
            offset_mm: 0.0,
            open: d < 0.0,
        });
        Section {
            arc_mm: arc,
            row: CprRow {
                centre: Vec3::ZERO,
                lateral: Vec3::X,
                normal: Vec3::Y,
            },
            lumen,
            wall: None,
        }
    }

    /// A fitted reference's sections used, narrowed and dilated counts, and whether sloped.
    fn fitted(st: &Stenosis) -> (&[usize], usize, usize, bool) {
        match &st.source {
            ReferenceSource::Fitted {
                used,
                dropped,
                dilated,
                sloped,
            } => (used, *dropped, *dilated, *sloped),
            other => panic!("not fitted: {other:?}"),
        }
    }

    /// The healthy vessel: 10 mm across at the path's start, tapering by 0.05 mm a mm.
    fn healthy(s: f64) -> f64 {
        10.0 - 0.05 * s
    }

    /// A path 60 mm long cut every mm; the vessel tapers, and at `at` mm a lesion
    /// `w` mm long either side narrows it smoothly (a raised cosine) to `1 − depth` of its
    /// width, `d_min` scaled by `ecc` (an eccentric lumen's narrowest calliper).
    fn vessel(at: f64, w: f64, depth: f64, ecc: f64) -> Vec<Section> {
        (0..60)
            .map(|i| {
                let s = i as f64 + 0.5;
                let u = (s - at) / w;
                let k = if u.abs() < 1.0 {
                    1.0 - 0.5 * depth * (1.0 + (PI * u).cos())
                } else {
                    1.0
                };
                let d = healthy(s) * k;
                section(s, d, d * if u.abs() < 1.0 { ecc } else { 1.0 })
            })
            .collect()
    }

    #[test]
    fn a_fitted_reference_follows_the_taper_past_the_lesion() {
        // Half the width at 30.5 mm: 50 % by diameter, 75 % by area, against the taper's
        // 8.475 mm there (not the 10 mm at the start, nor the 7 mm at the end).
        let v = vessel(30.5, 8.0, 0.5, 1.0);
        let st = grade(&v, 60.0, &StenosisOptions::default()).unwrap();
        assert_eq!(st.lesion, 30);
        assert_eq!(st.lesion_mm, 30.5);
        let want = healthy(30.5);
        // The shoulders less than 10 % narrow stay in the fit and draw it down a little.
        assert!((st.at_lesion_mm - want).abs() < 0.01 * want, "{st:?}");
        assert!((st.slope + 0.05).abs() < 0.005, "{st:?}");
        assert!((st.diameter_pct - 50.0).abs() < 0.5, "{st:?}");
        assert!((st.area_pct - 75.0).abs() < 0.5, "{st:?}");
        let (used, dropped, dilated, sloped) = fitted(&st);
        assert!(sloped);
        assert_eq!(dilated, 0);
        // 41 sections within 20 mm of it, the lesion's own apart; what was dropped is the
        // narrowed segment, whose width below 90 % of the taper runs |u| < acos(−0.6)/π.
        assert_eq!(used.len() + dropped, 40);
        let half = 8.0 * (-0.6f64).acos() / PI;
        let n = st.narrowed.as_ref().unwrap();
        let [a, b] = n.mm;
        assert!(
            (a - (30.5 - half)).abs() <= 1.0 && (b - (30.5 + half)).abs() <= 1.0,
            "{a} {b}"
        );
        assert_eq!(n.sections[1] - n.sections[0] + 1, dropped + 1);
        for &i in used {
            let d = v[i].lumen.as_ref().unwrap().equivalent_diameter_mm;
            assert!(d >= NARROWED * st.reference_at(v[i].arc_mm).unwrap());
        }
        // Defined over the span alone.
        assert!(st.reference_at(5.0).is_none() && st.reference_at(50.5).is_some());
    }

    /// A post-stenotic dilatation: 6 mm past the lesion the vessel widens to 1.45 times its
    /// taper (a raised cosine 5 mm either side). The sections above 1.2 times the line are
    /// left out of the fit, which then follows the taper within 2 % (the bulge's shoulders stay
    /// in), and the grade is within a point; fitted with them, the line would be pulled up by
    /// more than 3 %.
    #[test]
    fn a_post_stenotic_dilatation_is_left_out_of_the_reference() {
        let mut v = vessel(30.5, 6.0, 0.5, 1.0);
        for sec in &mut v {
            let u = (sec.arc_mm - 42.5) / 5.0;
            if u.abs() < 1.0 {
                let d = healthy(sec.arc_mm) * (1.0 + 0.225 * (1.0 + (PI * u).cos()));
                *sec = section(sec.arc_mm, d, d);
            }
        }
        let st = grade(&v, 60.0, &StenosisOptions::default()).unwrap();
        assert_eq!(st.lesion, 30);
        let want = healthy(30.5);
        // The bulge's shoulders (under 1.2 times) stay in, and push it up a little.
        assert!((st.at_lesion_mm - want).abs() < 0.02 * want, "{st:?}");
        assert!((st.diameter_pct - 50.0).abs() < 1.0, "{st:?}");
        let (used, dropped, dilated, sloped) = fitted(&st);
        assert!(sloped);
        // Each section within the span is used, narrowed or dilated as the final line says.
        let d = |i: usize| v[i].lumen.as_ref().unwrap().equivalent_diameter_mm;
        let (mut below, mut above) = (0, vec![]);
        for i in (0..60).filter(|&i| i != 30 && (v[i].arc_mm - 30.5).abs() <= 20.0) {
            let r = st.reference_at(v[i].arc_mm).unwrap();
            let band = d(i) >= NARROWED * r && d(i) <= DILATED * r;
            assert_eq!(used.contains(&i), band, "section {i}");
            below += usize::from(d(i) < NARROWED * r);
            if d(i) > DILATED * r {
                above.push(i);
            }
        }
        assert_eq!((dropped, dilated), (below, above.len()));
        // The bulge is above 1.2 × the taper where 1 + 0.225 (1 + cos πu) > 1.2: |u| < 0.63,
        // 6.3 mm of it.
        assert!((5..=7).contains(&dilated), "{dilated}");
        let with: Vec<(f64, f64)> = used
            .iter()
            .chain(&above)
            .map(|&i| (v[i].arc_mm, d(i)))
            .collect();
        let (pulled, _) = fit(&with, 30.5, true);
        assert!(pulled > 1.03 * want, "{pulled} against {want}");
    }

    /// The narrower of two vessels at each section: both lesions.
    fn both(a: &[Section], b: &[Section]) -> Vec<Section> {
        a.iter()
            .zip(b)
            .map(|(a, b)| {
                let d = |s: &Section| s.lumen.as_ref().unwrap().equivalent_diameter_mm;
                if d(a) <= d(b) { a.clone() } else { b.clone() }
            })
            .collect()
    }

    /// A 40 % lesion where the vessel is wide and a 30 % one of less area where it has
    /// tapered: the severe one first, though the milder is the section of least area (which
    /// `grade` takes); asked for one, the severe one.
    #[test]
    fn tandem_lesions_come_the_most_severe_first() {
        let v = both(&vessel(15.5, 6.0, 0.4, 1.0), &vessel(45.5, 6.0, 0.3, 1.0));
        let opt = StenosisOptions::default();
        assert_eq!(grade(&v, 60.0, &opt).unwrap().lesion, 45, "least area");
        let found = grade_lesions(&v, 60.0, &opt, 5).unwrap();
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!((found[0].lesion, found[1].lesion), (15, 45));
        assert!((found[0].diameter_pct - 40.0).abs() < 1.0, "{:?}", found[0]);
        assert!((found[1].diameter_pct - 30.0).abs() < 1.0, "{:?}", found[1]);
        let one = grade_lesions(&v, 60.0, &opt, 1).unwrap();
        assert_eq!(one, vec![found[0].clone()]);
    }

    /// Two lesions 30 mm apart on the tapering vessel, narrowing it by half and by 30 %: both
    /// are found, the deeper first, each graded against the taper as a lesion alone is
    /// (within a point), their narrowed segments apart; asked for more, no third is made up;
    /// placed lesions or references are refused.
    #[test]
    fn tandem_lesions_are_found_and_graded_each() {
        let deep = vessel(20.5, 6.0, 0.5, 1.0);
        let mild = vessel(45.5, 6.0, 0.3, 1.0);
        let both = both(&deep, &mild);
        let opt = StenosisOptions::default();
        let found = grade_lesions(&both, 60.0, &opt, 5).unwrap();
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!((found[0].lesion, found[1].lesion), (20, 45));
        assert!((found[0].diameter_pct - 50.0).abs() < 1.0, "{:?}", found[0]);
        assert!((found[1].diameter_pct - 30.0).abs() < 1.0, "{:?}", found[1]);
        let [a, b] = [0, 1].map(|k| found[k].narrowed.as_ref().unwrap().sections);
        assert!(a[1] < b[0], "{a:?} {b:?}");
        // One asked for: the first, as grade gives it.
        let one = grade_lesions(&both, 60.0, &opt, 1).unwrap();
        assert_eq!(one, vec![grade(&both, 60.0, &opt).unwrap()]);
        // A healthy tapering vessel with one lesion: one.
        assert_eq!(grade_lesions(&deep, 60.0, &opt, 5).unwrap().len(), 1);
        let placed = StenosisOptions {
            lesion_mm: Some(20.0),
            ..Default::default()
        };
        assert!(
            grade_lesions(&both, 60.0, &placed, 2)
                .unwrap_err()
                .contains("place neither")
        );
    }

    #[test]
    fn severity_in_the_scct_words() {
        for (pct, want) in [
            (-12.0, "none"),
            (0.5, "none"),
            (1.0, "minimal"),
            (24.9, "minimal"),
            (25.0, "mild"),
            (49.9, "mild"),
            (50.0, "moderate"),
            (69.9, "moderate"),
            (70.0, "severe"),
            (99.0, "severe"),
        ] {
            assert_eq!(severity(pct), want, "{pct}");
        }
    }

    #[test]
    fn an_eccentric_lesion_grades_worse_by_diameter() {
        // The same area, but a slit: its narrowest calliper is 60 % of the equivalent
        // diameter, and the diameter stenosis is taken across it.
        let v = vessel(30.5, 8.0, 0.5, 0.6);
        let st = grade(&v, 60.0, &StenosisOptions::default()).unwrap();
        assert!((st.area_pct - 75.0).abs() < 0.5, "{st:?}");
        assert!((st.diameter_pct - 70.0).abs() < 0.5, "{st:?}");
    }

    #[test]
    fn placed_references_are_taken_as_they_are() {
        let v = vessel(30.5, 8.0, 0.5, 1.0);
        // One (distal, as NASCET): that section's diameter.
        let one = StenosisOptions {
            reference_mm: vec![44.8],
            ..Default::default()
        };
        let st = grade(&v, 60.0, &one).unwrap();
        assert_eq!(st.source, ReferenceSource::Placed(vec![44]));
        assert_eq!(st.at_lesion_mm, healthy(44.5));
        assert_eq!(st.slope, 0.0);
        let d_min = v[30].lumen.as_ref().unwrap().min_diameter_mm;
        assert!((st.diameter_pct - 100.0 * (1.0 - d_min / healthy(44.5))).abs() < 1e-9);
        // Two, either way round: the line through them, here the taper itself.
        let two = StenosisOptions {
            reference_mm: vec![50.5, 10.5],
            ..Default::default()
        };
        let st = grade(&v, 60.0, &two).unwrap();
        assert_eq!(st.source, ReferenceSource::Placed(vec![10, 50]));
        assert!((st.at_lesion_mm - healthy(30.5)).abs() < 1e-9);
        assert!((st.diameter_pct - 50.0).abs() < 1e-9);
        assert_eq!(st.domain_mm, [10.5, 50.5]);
        // The narrowed segment is measured against the same line.
        let half = 8.0 * (-0.6f64).acos() / PI;
        let [a, b] = st.narrowed.unwrap().mm;
        assert!((b - a - 2.0 * half).abs() <= 1.0, "{a} {b}");
    }

    #[test]
    fn a_placed_lesion_and_a_lesion_at_the_end() {
        let v = vessel(30.5, 8.0, 0.5, 1.0);
        // A reader's lesion elsewhere: a healthy section grades near 0 and is not narrowed.
        let st = grade(
            &v,
            60.0,
            &StenosisOptions {
                lesion_mm: Some(5.2),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(st.lesion, 5);
        assert!(st.diameter_pct.abs() < 1.0, "{st:?}");
        assert_eq!(st.narrowed, None);
        // A lesion with healthy vessel on one side only: a flat reference, their mean.
        let v = vessel(58.5, 6.0, 0.5, 1.0);
        let st = grade(&v, 60.0, &StenosisOptions::default()).unwrap();
        assert_eq!(st.lesion, 58);
        let (used, _, _, sloped) = fitted(&st);
        assert!(!sloped && used.iter().all(|&i| i < 58));
        let d = |i: usize| v[i].lumen.as_ref().unwrap().equivalent_diameter_mm;
        let mean = used.iter().map(|&i| d(i)).sum::<f64>() / used.len() as f64;
        assert!((st.at_lesion_mm - mean).abs() < 1e-9);
        assert_eq!(st.slope, 0.0);
    }

    #[test]
    fn what_cannot_be_graded_is_refused() {
        let mut v = vessel(30.5, 8.0, 0.5, 1.0);
        v[12] = section(12.5, -9.0, 9.0);
        v[13] = section(13.5, 0.0, 0.0);
        let err = |o: StenosisOptions, v: &[Section]| grade(v, 60.0, &o).unwrap_err();
        let lesion = |s| StenosisOptions {
            lesion_mm: Some(s),
            ..Default::default()
        };
        let reference = |r: Vec<f64>| StenosisOptions {
            reference_mm: r,
            ..Default::default()
        };
        assert!(err(lesion(61.0), &v).contains("not on the path"));
        assert!(err(lesion(f64::NAN), &v).contains("not on the path"));
        assert!(err(lesion(12.4), &v).contains("open to the field's edge"));
        assert!(err(lesion(13.4), &v).contains("no lumen"));
        assert!(err(reference(vec![30.6]), &v).contains("the lesion's own section"));
        assert!(err(reference(vec![40.0, 50.0]), &v).contains("must lie between"));
        assert!(err(reference(vec![1.0, 2.0, 3.0]), &v).contains("3 references"));
        assert!(err(reference(vec![12.5, 50.0]), &v).contains("first reference"));
        let narrow_span = StenosisOptions {
            span_mm: 0.5,
            ..Default::default()
        };
        assert!(err(narrow_span, &v).contains("no reference"));
        let no_span = StenosisOptions {
            span_mm: 0.0,
            ..Default::default()
        };
        assert!(err(no_span, &v).contains("positive"));
        let none: Vec<Section> = (0..5).map(|i| section(i as f64 + 0.5, 0.0, 0.0)).collect();
        assert!(
            grade(&none, 5.0, &StenosisOptions::default())
                .unwrap_err()
                .contains("no section has a closed lumen")
        );
    }
}
