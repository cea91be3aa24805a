//! `raystream measure`: a vessel's lumen on cross-sections along a path through a CT volume, as
//! a vascular workstation tabulates an aorta for stent-graft sizing or a stenosis: per section
//! its area, the diameter of a circle of that area, its largest and smallest calliper
//! diameters and how far its centroid lies from the path (see `raystream_cpu::lumen`); with
//! `--wall`, the vessel's outer wall about it, the volumes the walls hold, and each lesion
//! graded against the wall at its section (see `raystream_cpu::wall`).

use std::fmt::Write as _;

use anyhow::{Context, Result, bail};
use raystream_cpu::airway::Pi10;
use raystream_cpu::cpr::{CurvedPlane, PathAngle, Tortuosity};
use raystream_cpu::dvr::Marcher;
use raystream_cpu::lumen::{self, LumenOptions, Section};
use raystream_cpu::stenosis::{self, ReferenceSource, Stenosis};
use raystream_cpu::wall::{Track, Wall, WallEdge, WallOptions, WallVolumes};
use raystream_math::DVec3;
use serde_json::json;

use crate::cli::{AirwayEdge, MeasureArgs};
use crate::common::{file_name, print_line, round3, spinner};
use crate::iso::read_volume;

/// The most sections one run measures.
const MAX_SECTIONS: usize = 100_000;

pub fn run(a: &MeasureArgs) -> Result<()> {
    if !(a.every.is_finite() && a.every > 0.0) {
        bail!(
            "--every {}: sections must be a positive number of mm apart",
            a.every
        );
    }
    for p in [&a.plot, &a.plot_pi10].into_iter().flatten() {
        crate::profile::PlotFormat::of(p)?;
    }
    if a.plot_pi10.is_some() && !(a.vessel.dark && a.wall.is_some()) {
        bail!(
            "--plot-pi10 draws an airway's walls: give it with --dark --wall (Pi10 is an airway's)"
        );
    }
    crate::mask_out::check_names(a.mask.as_deref(), a.structures.as_deref())?;
    if let Some(r) = &a.report
        && !raystream_io::is_segmentation_path(r)
    {
        bail!(
            "{}: --report writes a DICOM Structured Report (.dcm): name it so",
            r.display()
        );
    }
    if !a.angle.is_empty() && a.angle.len() != 3 {
        bail!(
            "--angle: {} arc lengths; give three, A,B,C (mm along the path, the vertex B between)",
            a.angle.len()
        );
    }
    let points = raystream_io::read_curve(&a.path)?;
    let (volume, _) = read_volume(&a.input, &a.pick.select(), a.quiet, None)?;
    // A Segmentation references the CT's series: one that cannot be is refused before any work.
    crate::mask_out::check_sources(a.mask.as_deref(), a.structures.as_deref(), &volume)?;
    if let Some(r) = &a.report {
        raystream_io::measurement_report_source(&volume)
            .map_err(|e| anyhow::anyhow!("{}: --report: {e}", r.display()))?;
    }
    let opt = LumenOptions {
        threshold_hu: a.vessel.lumen,
        dark: a.vessel.dark,
        field_mm: a.field,
        seed_mm: a.vessel.seed,
        open_mm: a.open,
        ..LumenOptions::for_volume(&volume)
    };
    opt.check()
        .map_err(|e| anyhow::anyhow!("--lumen/--field/--seed/--open: {e}"))?;
    if let (Some(Some(hu)), true) = (a.wall, opt.dark) {
        bail!(
            "--wall {hu} with --dark: an airway's wall is found at half maximum on each ray, with no threshold; give --wall alone"
        );
    }
    if a.wall_edge.is_some() && !(opt.dark && a.wall.is_some()) {
        bail!(
            "--wall-edge places an airway's wall: give it with --dark --wall (a vessel's wall is found below --wall HU)"
        );
    }
    let wall = wall_options(a, &opt);
    if let Some(w) = &wall {
        w.check(&opt).map_err(|e| anyhow::anyhow!("--wall: {e}"))?;
    }
    let file = a.path.display();
    // The check `render --path` makes: some of the path lies in the grid.
    let rows = CurvedPlane::new(&points, DVec3::X, 0.0, 1, 256)
        .map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    crate::render::inside(&a.path, &rows, &volume)?;
    if !a.quiet && volume.unit != raystream_io::ValueUnit::Hounsfield {
        eprintln!(
            "raystream: {}: values are not known to be Hounsfield units; --lumen {} applies to the raw values",
            a.input.display(),
            a.vessel.lumen
        );
    }
    let length = rows.length_mm;
    let n = match a.sections {
        Some(n) => n as usize,
        None => {
            let n = (length / a.every).round().max(1.0);
            if n > MAX_SECTIONS as f64 {
                bail!(
                    "{file}: a path {length:.1} mm long, a section every {} mm: over {MAX_SECTIONS} sections (give --every a larger step)",
                    a.every
                );
            }
            n as usize
        }
    };
    let pb = spinner(
        a.quiet,
        &format!("measuring the lumen on {n} sections of {file}"),
    );
    // Sections framed as `render --path --slices N` frames them from its default view (the
    // anterior one: the patient's left to the image's right).
    // The walls along the path, each section's by itself: what each section's neighbours
    // found, for the table and the mask alike.
    let track = match &wall {
        Some(w) => Some(
            Track::along(&volume, &Marcher::new(&volume, None), &points, &opt, w)
                .map_err(|e| anyhow::anyhow!("{file}: {e}"))?,
        ),
        None => None,
    };
    let wall = wall.as_ref().zip(track.as_ref());
    let sections = lumen::measure_along(&volume, &points, (n as u32, DVec3::X), &opt, wall)
        .map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    pb.finish_and_clear();
    let found = sections.iter().any(|s| s.lumen.is_some());
    // Graded before anything is written: a grade asked for and not given is an error.
    let lesions: Vec<Stenosis> = match a.stenosis() {
        Some(o) if found => match a.lesions {
            Some(n) => stenosis::grade_lesions(&sections, length, &o, n as usize),
            // Neither lesion nor reference placed: the most severe lesion, as `--lesions 1`.
            None if o.lesion_mm.is_none() && o.reference_mm.is_empty() => {
                stenosis::grade_lesions(&sections, length, &o, 1)
            }
            None => stenosis::grade(&sections, length, &o).map(|g| vec![g]),
        }
        .map_err(|e| anyhow::anyhow!("{file}: stenosis: {e}"))?,
        _ => Vec::new(),
    };
    let winding =
        raystream_cpu::cpr::tortuosity(&points).map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    let angle = match *a.angle {
        [p, q, r] => Some(
            raystream_cpu::cpr::path_angle(&points, [p, q, r])
                .map_err(|e| anyhow::anyhow!("{file}: --angle: {e}"))?,
        ),
        _ => None,
    };
    if let Some(out) = &a.output {
        std::fs::write(out, csv(&sections, lesions.first(), wall.is_some()))
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    if let Some(out) = &a.plot
        && found
    {
        let chart = crate::profile::Chart::Profile {
            sections: &sections,
            length_mm: length,
            graded: &lesions,
        };
        plot(a, out, "The lumen along the path", "the lumen", &chart)?;
    }
    let pi10 = wall
        .filter(|(w, _)| w.edge.is_airway())
        .map(|_| Pi10::of(&sections));
    if let (Some(out), Some(fit)) = (&a.plot_pi10, &pi10) {
        let fit = fit.as_ref().map_err(|why| {
            anyhow::anyhow!("{}: --plot-pi10: no Pi10 to draw: {why}", out.display())
        })?;
        let chart = crate::profile::Chart::Pi10 {
            sections: &sections,
            fit,
        };
        plot(
            a,
            out,
            "The airway's walls for Pi10",
            "the airway's walls for Pi10",
            &chart,
        )?;
    }
    let mask = if found && (a.mask.is_some() || a.structures.is_some()) {
        Some(write_mask(
            a,
            a.mask.as_deref(),
            (&volume, &points),
            &opt,
            wall,
        )?)
    } else {
        None
    };
    let report;
    let mut findings = Findings {
        winding: &winding,
        lesions: &lesions,
        angle: angle.as_ref(),
        mask: mask.as_ref(),
        report: None,
        pi10: pi10.as_ref(),
        wall_integral: wall.is_some_and(|(w, _)| w.edge == WallEdge::Integral),
    };
    if let Some(out) = &a.report
        && found
    {
        report = crate::structured_report::write(out, &volume, &sections, &findings, opt.dark)?;
        findings.report = Some(&report);
    }
    if a.json {
        print_line(report_json(a, &opt, &sections, &findings));
    } else {
        print_line(report_text(a, &opt, &sections, &findings));
    }
    if !found {
        bail!(
            "{file}: no lumen {} {} HU within {} mm of the path on any of its {n} sections (a non-contrast scan, or the path off the vessel: --lumen HU, --seed MM)",
            opt.bound_words(),
            a.vessel.lumen,
            a.vessel.seed
        );
    }
    Ok(())
}

/// Writes `chart` to `out`, headed `dicom_title` in a DICOM picture (whose burnt-in title
/// names no files: they may name the patient), and otherwise "INPUT: WHAT along PATH".
fn plot(
    a: &MeasureArgs,
    out: &std::path::Path,
    dicom_title: &str,
    what: &str,
    chart: &crate::profile::Chart,
) -> Result<()> {
    let title = if crate::common::is_dicom(out) {
        dicom_title.to_string()
    } else {
        format!(
            "{}: {what} along {}",
            file_name(&a.input),
            file_name(&a.path)
        )
    };
    let dicom = crate::common::DicomOut {
        annotated: true,
        description: crate::common::options_in_words(Some(&a.input), out),
        ..Default::default()
    };
    crate::profile::write(out, &title, chart, &dicom)
}

/// `--wall [HU]`'s options: a vessel's wall, below HU (-30 by default); with `--dark`, an
/// airway's, at half maximum or (`--wall-edge integral`) by the integral.
fn wall_options(a: &MeasureArgs, opt: &LumenOptions) -> Option<WallOptions> {
    a.wall.map(|hu| match hu {
        _ if opt.dark => AirwayEdge::options(a.wall_edge),
        Some(hu) => WallOptions::vessel(hu),
        None => WallOptions::default(),
    })
}

/// A section's state: its lumen closed, open (reaching the field's edge) or not found.
fn status(s: &Section) -> &'static str {
    match &s.lumen {
        Some(l) if l.open => "open",
        Some(_) => "closed",
        None => "none",
    }
}

/// The table as CSV, a section a row (LPS mm; empty fields where no lumen was found); with a
/// graded stenosis, the reference diameter where it is defined in a last column.
fn csv(sections: &[Section], graded: Option<&Stenosis>, walls: bool) -> String {
    let mut t = String::from(
        "section,arc_mm,x,y,z,tangent_x,tangent_y,tangent_z,status,area_mm2,equivalent_diameter_mm,max_diameter_mm,cross_diameter_mm,min_diameter_mm,centroid_x,centroid_y,centroid_z,offset_mm",
    );
    if walls {
        t += ",wall_area_mm2,wall_equivalent_diameter_mm,wall_max_diameter_mm,wall_cross_diameter_mm,wall_min_diameter_mm,wall_max_thickness_mm,wall_seen,wall_mean_thickness_mm,wall_inner_area_mm2,wall_area_percent";
    }
    t += if graded.is_some() {
        ",reference_diameter_mm\n"
    } else {
        "\n"
    };
    for (i, s) in sections.iter().enumerate() {
        let c = s.row.centre;
        let t3 = s.tangent();
        let _ = write!(
            t,
            "{},{:.3},{:.3},{:.3},{:.3},{:.6},{:.6},{:.6},{}",
            i + 1,
            s.arc_mm,
            c.x,
            c.y,
            c.z,
            t3.x,
            t3.y,
            t3.z,
            status(s)
        );
        match &s.lumen {
            Some(l) => {
                let _ = write!(
                    t,
                    ",{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3}",
                    l.area_mm2,
                    l.equivalent_diameter_mm,
                    l.max_diameter_mm,
                    l.cross_diameter_mm,
                    l.min_diameter_mm,
                    l.centroid.x,
                    l.centroid.y,
                    l.centroid.z,
                    l.offset_mm
                );
            }
            None => t.push_str(",,,,,,,,,"),
        }
        match (&s.wall, walls) {
            (Some(w), _) => {
                let _ = write!(
                    t,
                    ",{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3}",
                    w.area_mm2,
                    w.equivalent_diameter_mm,
                    w.max_diameter_mm,
                    w.cross_diameter_mm,
                    w.min_diameter_mm,
                    w.max_thickness_mm,
                    w.seen,
                    w.mean_thickness_mm,
                    w.inner_area_mm2,
                    w.area_percent()
                );
            }
            (None, true) => t.push_str(",,,,,,,,,,"),
            (None, false) => {}
        }
        if let Some(g) = graded {
            t.push(',');
            if let Some(d) = g.reference_at(s.arc_mm) {
                let _ = write!(t, "{d:.3}");
            }
        }
        t.push('\n');
    }
    t
}

/// The sections with the largest and the smallest lumen (by its largest diameter, and by its
/// equivalent one), closed lumens only.
pub(crate) fn extremes(sections: &[Section]) -> Option<(usize, usize)> {
    let closed = || {
        sections
            .iter()
            .enumerate()
            .filter_map(|(i, s)| s.lumen.as_ref().filter(|l| !l.open).map(|l| (i, l)))
    };
    let widest = closed().max_by(|a, b| a.1.max_diameter_mm.total_cmp(&b.1.max_diameter_mm))?;
    let narrowest = closed().min_by(|a, b| {
        a.1.equivalent_diameter_mm
            .total_cmp(&b.1.equivalent_diameter_mm)
    })?;
    Some((widest.0, narrowest.0))
}

/// The section whose outer wall has the most of `figure`, and its wall.
pub(crate) fn wall_with_most(
    sections: &[Section],
    figure: fn(&Wall) -> f64,
) -> Option<(usize, &Wall)> {
    sections
        .iter()
        .enumerate()
        .filter_map(|(i, s)| s.wall.as_ref().map(|w| (i, w)))
        .max_by(|a, b| figure(a.1).total_cmp(&figure(b.1)))
}

/// The section whose outer wall is widest (by its largest diameter, as an aneurysm's size
/// is reported), and its wall.
pub(crate) fn widest_wall(sections: &[Section]) -> Option<(usize, &Wall)> {
    wall_with_most(sections, |w| w.max_diameter_mm)
}

/// The outer wall's lines of the text report: the widest section, and on how many sections
/// a wall was found.
fn wall_text(
    sections: &[Section],
    wall: &WallOptions,
    step_mm: f64,
    pi10: Option<&Result<Pi10, String>>,
) -> String {
    let hu = match wall.edge {
        WallEdge::Below(hu) => hu,
        WallEdge::HalfMaximum | WallEdge::Integral => {
            return airway_text(sections, wall, step_mm, pi10);
        }
    };
    let closed = sections.iter().filter(|s| status(s) == "closed").count();
    let found = sections.iter().filter(|s| s.wall.is_some()).count();
    let mut t = String::new();
    if let Some((i, w)) = widest_wall(sections) {
        let s = &sections[i];
        let c = w.centre;
        let _ = writeln!(
            t,
            "widest wall: section {} at {:.1} mm, ({:.1}, {:.1}, {:.1}) mm LPS: D max {:.2} mm (across it {:.2} mm), D min {:.2} mm, D eq {:.2} mm, {:.1} mm2, its edge seen on {:.0} % of the outline; the lumen there D eq {:.2} mm",
            i + 1,
            s.arc_mm,
            c.x,
            c.y,
            c.z,
            w.max_diameter_mm,
            w.cross_diameter_mm,
            w.min_diameter_mm,
            w.equivalent_diameter_mm,
            w.area_mm2,
            100.0 * w.seen,
            s.lumen
                .as_ref()
                .map_or(f64::NAN, |l| l.equivalent_diameter_mm),
        );
    }
    if let Some((i, w)) = wall_with_most(sections, |w| w.max_thickness_mm) {
        let _ = writeln!(
            t,
            "thickest wall: section {} at {:.1} mm: {:.2} mm from the lumen's edge to the outer wall (wall, thrombus or unenhanced lumen)",
            i + 1,
            sections[i].arc_mm,
            w.max_thickness_mm
        );
    }
    let _ = writeln!(
        t,
        "wall: found on {found} of the {closed} sections with a closed lumen (its edge: fat or lung below {hu} HU about it; none where too little of it is seen); on {by} its circle is the one the sections within 5 mm agree on, where the section alone would take another",
        by = sections
            .iter()
            .filter(|s| s.wall.as_ref().is_some_and(|w| w.from_neighbours))
            .count()
    );
    if let Some(v) = WallVolumes::of(sections, step_mm) {
        let _ = writeln!(
            t,
            "volume: the walls hold {:.1} ml over the {} sections with one ({:.1} mm of the path), their lumens {:.1} ml: {:.1} ml of wall, thrombus and unenhanced lumen",
            v.wall_mm3 / 1000.0,
            v.sections,
            v.length_mm,
            v.lumen_mm3 / 1000.0,
            (v.wall_mm3 - v.lumen_mm3) / 1000.0
        );
    }
    t
}

/// An airway's wall's lines of the text report: on how many sections it was found, its mean
/// thickness and share of the airway's area over them, the thickest, and what the walls hold.
fn airway_text(
    sections: &[Section],
    wall: &WallOptions,
    step_mm: f64,
    pi10: Option<&Result<Pi10, String>>,
) -> String {
    let closed = sections.iter().filter(|s| status(s) == "closed").count();
    let walls: Vec<(usize, &Wall)> = sections
        .iter()
        .enumerate()
        .filter_map(|(i, s)| s.wall.as_ref().map(|w| (i, w)))
        .collect();
    let how = if wall.edge == WallEdge::Integral {
        format!(
            "its thickness from the HU summed across it on {} rays from the lumen's centroid (the scanner's blur keeps the sum; the wall's density taken as {} HU, or its peak where higher), about the middle of its edges at half maximum",
            wall.rays,
            raystream_cpu::airway::WALL_HU
        )
    } else {
        format!(
            "its inner and outer edges at half maximum on {} rays from the lumen's centroid (halfway between the gas and the wall's peak, and between the peak and the lung or fat beyond)",
            wall.rays
        )
    };
    let mut t = format!(
        "airway wall: found on {} of the {closed} sections with a closed lumen, {how}; none where fewer than a quarter of the rays see past the wall\n",
        walls.len(),
    );
    let (Some(thickness), Some(percent)) = (
        wall_mean(sections, |w| w.mean_thickness_mm),
        wall_mean(sections, Wall::area_percent),
    ) else {
        return t;
    };
    let range = |f: fn(&Wall) -> f64| {
        walls
            .iter()
            .map(|(_, w)| f(w))
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], x| {
                [lo.min(x), hi.max(x)]
            })
    };
    let [lo, hi] = range(|w| w.mean_thickness_mm);
    let [plo, phi] = range(Wall::area_percent);
    let _ = writeln!(
        t,
        "wall thickness: {thickness:.2} mm on average over them ({lo:.2} to {hi:.2} mm section by section); wall area {percent:.1} % of the airway's (WA %; {plo:.1} to {phi:.1} %)",
    );
    match pi10 {
        Some(Ok(p)) => {
            let [lo, hi] = p.perimeter_range_mm;
            let range = format!("the inner perimeters fitted, {lo:.1} to {hi:.1} mm");
            let (extrapolated, fitted) = if p.extrapolated() {
                (
                    format!(", extrapolated (10 mm lies outside {range})"),
                    String::new(),
                )
            } else {
                (String::new(), format!(" ({range})"))
            };
            let _ = writeln!(
                t,
                "Pi10: {:.2} mm{extrapolated}: the square root of the wall area of an airway 10 mm round inside, on the line √WA = {:.3} mm + {:.4} × Pi fitted over {} sections{fitted}, r² {:.2}",
                p.value_mm, p.intercept_mm, p.slope, p.sections, p.r2
            );
        }
        Some(Err(why)) => {
            let _ = writeln!(t, "Pi10: none: {why}");
        }
        None => {}
    }
    if let Some((i, w)) = wall_with_most(sections, |w| w.mean_thickness_mm) {
        let c = w.centre;
        let _ = writeln!(
            t,
            "thickest wall: section {} at {:.1} mm, ({:.1}, {:.1}, {:.1}) mm LPS: {:.2} mm on average (its thickest ray {:.2} mm), WA {:.1} %, the airway D eq {:.2} mm outside and {:.2} mm inside it, its edges seen on {:.0} % of the rays",
            i + 1,
            sections[i].arc_mm,
            c.x,
            c.y,
            c.z,
            w.mean_thickness_mm,
            w.max_thickness_mm,
            w.area_percent(),
            w.equivalent_diameter_mm,
            raystream_cpu::lumen::equivalent_diameter(w.inner_area_mm2),
            100.0 * w.seen
        );
    }
    if let Some(v) = WallVolumes::of(sections, step_mm) {
        let _ = writeln!(
            t,
            "volume: the walls hold {:.1} ml over the {} sections with one ({:.1} mm of the path), inside their inner edges {:.1} ml: {:.1} ml of wall",
            v.wall_mm3 / 1000.0,
            v.sections,
            v.length_mm,
            v.lumen_mm3 / 1000.0,
            (v.wall_mm3 - v.lumen_mm3) / 1000.0
        );
    }
    t
}

/// The mean of `figure` over the sections' walls; none without a wall.
pub(crate) fn wall_mean(sections: &[Section], figure: fn(&Wall) -> f64) -> Option<f64> {
    let walls: Vec<f64> = sections
        .iter()
        .filter_map(|s| s.wall.as_ref().map(figure))
        .collect();
    (!walls.is_empty()).then(|| walls.iter().sum::<f64>() / walls.len() as f64)
}

/// The path's angle at a point, in words.
fn angle_text(g: &PathAngle) -> String {
    let [a, b, c] = g.arc_mm;
    let p = g
        .points
        .map(|p| format!("({:.1}, {:.1}, {:.1})", p.x, p.y, p.z));
    format!(
        "angle: {:.1} deg at {b:.1} mm, between the chords from {a:.1} to {b:.1} mm and from {b:.1} to {c:.1} mm ({}, {} and {} mm LPS)\n",
        g.deviation_deg, p[0], p[1], p[2]
    )
}

/// The path's angle at a point as JSON.
fn angle_json(g: &PathAngle) -> serde_json::Value {
    json!({
        "arc_mm": g.arc_mm.map(round3),
        "points": g.points.map(|p| [round3(p.x), round3(p.y), round3(p.z)]),
        "deviation_deg": round3(g.deviation_deg),
    })
}

/// The path's tortuosity in words.
fn winding_words(w: &Tortuosity) -> String {
    format!(
        "path: {:.1} mm, its ends {:.1} mm apart: {}, turning {:.1} deg a cm",
        w.length_mm,
        w.chord_mm,
        match w.distance_metric {
            Some(m) => format!("distance metric (length over ends' distance) {m:.3}"),
            None => "closed (no distance metric)".into(),
        },
        w.turning_deg_per_cm
    )
}

/// What the report says beyond the table: the path's tortuosity, the lesions graded
/// (`--stenosis`'s, or `--lesions`', the most severe first) and `--angle`'s angle.
pub(crate) struct Findings<'a> {
    pub winding: &'a Tortuosity,
    pub lesions: &'a [Stenosis],
    pub angle: Option<&'a PathAngle>,
    pub mask: Option<&'a MaskWritten>,
    pub report: Option<&'a crate::structured_report::ReportOut>,
    /// With an airway's wall: Pi10 over the sections, or why there is none.
    pub pi10: Option<&'a Result<Pi10, String>>,
    /// The airway's wall was measured by the integral (`--wall-edge integral`), not at half
    /// maximum.
    pub wall_integral: bool,
}

/// What `--mask` wrote: the file, its labels' voxels and volumes, and the sections they came
/// from.
pub(crate) struct MaskWritten {
    /// `--mask`'s file (none where only `--structures` was asked for).
    file: Option<String>,
    /// The DICOM Segmentation's frames and instance, where it is one (else a NIfTI label
    /// map).
    frames: Option<usize>,
    pub segmentation: Option<raystream_io::SegmentationReference>,
    /// `--structures`: the RT Structure Set written, and each structure's contours.
    structures: Option<(String, Vec<usize>)>,
    /// Voxels and millilitres of each label.
    pub lumen: (usize, f64),
    pub wall: Option<(usize, f64)>,
    sections: usize,
    closed: usize,
    step_mm: f64,
}

/// The segments of a DICOM Segmentation `--mask`, as its labels: the lumen, and what the outer
/// wall holds beyond it (the vessel's wall, and any thrombus lining it).
pub(crate) fn mask_segments(wall: bool, dark: bool) -> Vec<raystream_io::Segment<'static>> {
    use raystream_cpu::mask::{LUMEN, WALL};
    use raystream_io::{Code, Segment};
    // DICOM CID 7150 (Segmentation Property Category), 7156 (Vascular Segmentation Type), 7166.
    let anatomy = Code {
        value: "123037004",
        scheme: "SCT",
        meaning: "Anatomical Structure",
    };
    let mut segments = vec![Segment {
        value: LUMEN,
        label: "Lumen",
        description: if dark {
            "The airway's lumen along the path"
        } else {
            "The vessel's lumen along the path"
        },
        category: anatomy,
        kind: Code {
            value: "91747007",
            scheme: "SCT",
            meaning: "Lumen",
        },
        // As scripts/label-overlay.py tints them.
        colour: [0, 255, 255],
        rt_type: "ORGAN",
    }];
    if wall {
        segments.push(Segment {
            value: WALL,
            label: if dark {
                "Airway wall"
            } else {
                "Wall and thrombus"
            },
            description: "Within the outer wall, beyond the lumen",
            category: anatomy,
            kind: if dark {
                // CID 7166's (the DICOM master list's) airway.
                Code {
                    value: "89187006",
                    scheme: "SCT",
                    meaning: "Airway structure",
                }
            } else {
                Code {
                    value: "59820001",
                    scheme: "SCT",
                    meaning: "Blood vessel",
                }
            },
            colour: [255, 0, 255],
            rt_type: "ORGAN",
        });
    }
    segments
}

/// `--mask FILE` (`out`) and `--structures FILE`: the lumen and the outer wall labelled on
/// the CT's grid ([`raystream_cpu::mask`]), written as NIfTI, as a 3D Slicer segmentation or
/// as a DICOM Segmentation of the CT's series, and as an RT Structure Set of it.
fn write_mask(
    a: &MeasureArgs,
    out: Option<&std::path::Path>,
    (volume, points): (&raystream_io::Volume, &[DVec3]),
    opt: &LumenOptions,
    wall: Option<(&WallOptions, &Track)>,
) -> Result<MaskWritten> {
    use raystream_cpu::mask::{LUMEN, WALL, label_path};
    let pb = spinner(
        a.quiet,
        &format!(
            "labelling the lumen{} on the CT's grid",
            if wall.is_some() { " and the wall" } else { "" }
        ),
    );
    let labels = label_path(volume, points, opt, wall)
        .map_err(|e| anyhow::anyhow!("{}: --mask: {e}", a.path.display()))?;
    pb.finish_and_clear();
    // What a DICOM Segmentation or RT Structure Set of them says made them, and their segments.
    let info = raystream_io::SegmentationInfo {
        description: if wall.is_some() {
            "raystream measure: lumen, outer wall beyond it"
        } else if opt.dark {
            "raystream measure: airway lumen"
        } else {
            "raystream measure: lumen"
        },
        algorithm: "raystream measure",
        version: env!("CARGO_PKG_VERSION"),
    };
    let segments = mask_segments(wall.is_some(), opt.dark);
    let what = if wall.is_some() {
        "raystream measure: 1 lumen, 2 outer wall beyond the lumen"
    } else {
        "raystream measure: 1 lumen"
    };
    let written = match out {
        Some(out) => {
            crate::mask_out::write_mask(out, volume, &labels.data, &segments, (&info, what))?
        }
        None => None,
    };
    let (frames, segmentation) = match written {
        Some(w) => (
            Some(w.frames),
            Some(raystream_io::SegmentationReference {
                sop_instance_uid: w.sop_instance_uid,
                series_uid: w.series_uid,
            }),
        ),
        None => (None, None),
    };
    let structures = match &a.structures {
        Some(file) => {
            let written =
                raystream_io::write_structure_set(file, volume, &labels.data, &segments, &info)?;
            Some((file.display().to_string(), written.contours))
        }
        None => None,
    };
    let voxel_ml = volume.voxel_ml();
    let of = |l: u8| {
        let n = labels.count(l);
        (n, n as f64 * voxel_ml)
    };
    Ok(MaskWritten {
        file: out.map(|o| o.display().to_string()),
        frames,
        segmentation,
        structures,
        lumen: of(LUMEN),
        wall: wall.map(|_| of(WALL)),
        sections: labels.sections,
        closed: labels.closed,
        step_mm: labels.step_mm,
    })
}

/// What `--mask` wrote, in words.
fn mask_text(m: &MaskWritten) -> String {
    let wall = match m.wall {
        Some((n, ml)) => format!(", 2 the outer wall beyond it on {n} voxels ({ml:.1} ml)"),
        None => String::new(),
    };
    let kind = match &m.file {
        Some(f) => crate::mask_out::mask_kind(std::path::Path::new(f), m.frames),
        None => String::new(),
    };
    let (file, kind) = match &m.file {
        Some(f) => (f.as_str(), kind),
        None => ("(none written)", "labels for --structures".to_string()),
    };
    let mut t = format!(
        "mask: {file} ({kind}): label 1 the lumen on {} voxels ({:.1} ml){wall}, from {} sections {:.2} mm apart ({} with a closed lumen)\n",
        m.lumen.0, m.lumen.1, m.sections, m.step_mm, m.closed
    );
    if let Some((file, contours)) = &m.structures {
        let list: Vec<String> = contours.iter().map(|c| c.to_string()).collect();
        t += &format!(
            "structures: {file} (a DICOM RT Structure Set of the CT's series: the same labels as {} closed contours)\n",
            list.join(" and ")
        );
    }
    t
}

/// What `--mask` wrote, as JSON.
fn mask_json(m: &MaskWritten) -> serde_json::Value {
    json!({
        "file": m.file,
        "format": match (&m.file, m.frames) {
            (None, _) => json!(null),
            (_, Some(_)) => json!("dicom-seg"),
            (_, None) => json!("nifti"),
        },
        "frames": m.frames,
        "lumen_voxels": m.lumen.0,
        "lumen_ml": round3(m.lumen.1),
        "wall_voxels": m.wall.map(|w| w.0),
        "wall_ml": m.wall.map(|w| round3(w.1)),
        "sections": m.sections,
        "closed_sections": m.closed,
        "step_mm": round3(m.step_mm),
        "structures": m.structures.as_ref().map(|(file, contours)| json!({
            "file": file,
            "contours": contours,
        })),
    })
}

fn report_text(
    a: &MeasureArgs,
    opt: &LumenOptions,
    sections: &[Section],
    findings: &Findings,
) -> String {
    let winding = findings.winding;
    let length = winding.length_mm;
    let n = sections.len();
    let mut t = format!(
        "{}: the lumen ({} {} HU, connected to the path within {} mm, opened by a {} mm disc) on {n} sections of {} ({length:.1} mm), {:.2} mm apart, sampled every {:.3} mm over {} mm\n",
        a.input.display(),
        if opt.dark { "<=" } else { ">=" },
        opt.threshold_hu,
        opt.seed_mm,
        opt.open_mm,
        a.path.display(),
        length / n as f64,
        opt.pixel_mm,
        opt.field_mm,
    );
    t += "section   arc mm         x         y         z   area mm2   D eq mm  D max mm  D cross mm  D min mm  offset mm  lumen";
    t += if a.wall.is_some() {
        "  wall mm2  wall D eq  wall D max  wall D cross  wall D min  seen %  WT mm  WA %\n"
    } else {
        "\n"
    };
    for (i, s) in sections.iter().enumerate() {
        let c = s.row.centre;
        let _ = write!(
            t,
            "{:>7} {:>8.1} {:>9.1} {:>9.1} {:>9.1}",
            i + 1,
            s.arc_mm,
            c.x,
            c.y,
            c.z
        );
        match &s.lumen {
            Some(l) => {
                let _ = write!(
                    t,
                    " {:>10.1} {:>9.2} {:>9.2} {:>11.2} {:>9.2} {:>10.2}  {:<6}",
                    l.area_mm2,
                    l.equivalent_diameter_mm,
                    l.max_diameter_mm,
                    l.cross_diameter_mm,
                    l.min_diameter_mm,
                    l.offset_mm,
                    status(s)
                );
            }
            None => {
                t += "          -         -         -           -         -          -  none  ";
            }
        }
        match (&s.wall, a.wall.is_some()) {
            (Some(w), _) => {
                let _ = write!(
                    t,
                    "{:>10.1} {:>10.2} {:>11.2} {:>13.2} {:>11.2} {:>7.0} {:>6.2} {:>5.1}",
                    w.area_mm2,
                    w.equivalent_diameter_mm,
                    w.max_diameter_mm,
                    w.cross_diameter_mm,
                    w.min_diameter_mm,
                    100.0 * w.seen,
                    w.mean_thickness_mm,
                    w.area_percent()
                );
            }
            (None, true) => {
                t += "         -          -           -             -           -       -      -     -";
            }
            (None, false) => {}
        }
        // (In place: a copy of the table a row would make a long table quadratic.)
        t.truncate(t.trim_end().len());
        t.push('\n');
    }
    if let Some((w, nw)) = extremes(sections) {
        let line = |what: &str, i: usize| {
            let s = &sections[i];
            let l = s.lumen.as_ref().unwrap();
            let c = l.centroid;
            format!(
                "{what}: section {} at {:.1} mm, ({:.1}, {:.1}, {:.1}) mm LPS: D max {:.2} mm (across it {:.2} mm), D min {:.2} mm, D eq {:.2} mm, {:.1} mm2\n",
                i + 1,
                s.arc_mm,
                c.x,
                c.y,
                c.z,
                l.max_diameter_mm,
                l.cross_diameter_mm,
                l.min_diameter_mm,
                l.equivalent_diameter_mm,
                l.area_mm2
            )
        };
        t += &line("widest", w);
        t += &line("narrowest", nw);
    }
    let open = sections.iter().filter(|s| status(s) == "open").count();
    let none = sections.iter().filter(|s| s.lumen.is_none()).count();
    if open > 0 {
        let _ = writeln!(
            t,
            "open: {open} of {n} sections, where the lumen reaches the {} mm field's edge (wider than the field, or joined to {} at this threshold): their figures are of the part in the field",
            opt.field_mm,
            if opt.dark {
                "a dark neighbour such as the lung, or another airway where it divides"
            } else {
                "a bright neighbour such as bone"
            }
        );
    }
    if none > 0 {
        let _ = writeln!(
            t,
            "none: {none} of {n} sections with no lumen {} {} HU within {} mm of the path",
            opt.bound_words(),
            opt.threshold_hu,
            opt.seed_mm
        );
    }
    if let Some(w) = wall_options(a, opt) {
        t += &wall_text(sections, &w, length / n as f64, findings.pi10);
    }
    t += &winding_words(winding);
    t.push('\n');
    if let Some(g) = findings.lesions.first() {
        t += &stenosis_text(sections, g, opt.dark);
    }
    if let (Some(n), [_, more @ ..]) = (a.lesions, findings.lesions) {
        let _ = writeln!(
            t,
            "lesions: {} (at most {n}), the most severe first by diameter stenosis: {}",
            findings.lesions.len(),
            findings
                .lesions
                .iter()
                .map(|g| format!("{:.1} mm ({:.1} %)", g.lesion_mm, g.diameter_pct))
                .collect::<Vec<_>>()
                .join(", ")
        );
        for g in more {
            t += &stenosis_text(sections, g, opt.dark);
        }
    }
    if let Some(g) = findings.angle {
        t += &angle_text(g);
    }
    if let Some(m) = findings.mask {
        t += &mask_text(m);
    }
    if let Some(r) = findings.report {
        t += &r.text();
    }
    t.trim_end().to_string()
}

/// Where a stenosis's reference came from, in words.
fn reference_words(sections: &[Section], g: &Stenosis) -> String {
    let at = |i: usize| format!("section {} at {:.1} mm", i + 1, sections[i].arc_mm);
    match &g.source {
        ReferenceSource::Fitted {
            used,
            dropped,
            dilated,
            sloped,
        } => format!(
            "{} {} sections within {:.1} to {:.1} mm ({dropped} narrowed{} left out){}",
            if *sloped {
                "a line fitted to"
            } else {
                "the mean of"
            },
            used.len(),
            g.domain_mm[0],
            g.domain_mm[1],
            if *dilated > 0 {
                format!(" and {dilated} dilated")
            } else {
                String::new()
            },
            if *sloped {
                format!(", {:+.3} mm a mm", g.slope)
            } else {
                ", all on one side of the lesion".into()
            }
        ),
        ReferenceSource::Placed(r) if r.len() == 1 => format!("placed: {}", at(r[0])),
        ReferenceSource::Placed(r) => format!(
            "placed: the line through {} and {}",
            at(r[0]),
            at(r[r.len() - 1])
        ),
    }
}

/// The graded stenosis, four lines of the text report.
fn stenosis_text(sections: &[Section], g: &Stenosis, dark: bool) -> String {
    let s = &sections[g.lesion];
    let l = s.lumen.as_ref().expect("a graded lesion has a lumen");
    let c = l.centroid;
    let pct = 100.0 * stenosis::NARROWED;
    let narrowed = match &g.narrowed {
        Some(n) => format!(
            "{:.1} to {:.1} mm ({:.1} mm, sections {} to {}), D eq below {pct:.0} % of the reference",
            n.mm[0],
            n.mm[1],
            n.mm[1] - n.mm[0],
            n.sections[0] + 1,
            n.sections[1] + 1,
        ),
        None => format!("none (the lesion's D eq is not below {pct:.0} % of the reference)"),
    };
    format!(
        "stenosis: section {} at {:.1} mm, ({:.1}, {:.1}, {:.1}) mm LPS: {:.1} mm2, D min {:.2} mm, D eq {:.2} mm\n\
         reference: {:.2} mm ({:.1} mm2) at the lesion, {}\n\
         grade: {:.1} % by diameter (D min against the reference), {:.1} % by area: {} (SCCT's words for {} by diameter)\n\
         narrowed: {narrowed}\n",
        g.lesion + 1,
        s.arc_mm,
        c.x,
        c.y,
        c.z,
        l.area_mm2,
        l.min_diameter_mm,
        l.equivalent_diameter_mm,
        g.at_lesion_mm,
        g.reference_area_mm2,
        reference_words(sections, g),
        g.diameter_pct,
        g.area_pct,
        stenosis::severity(g.diameter_pct),
        severity_band(g.diameter_pct),
    ) + &against_wall_text(s, dark)
}

/// A lesion graded against the outer wall at its own section (when `--wall` found one there):
/// its D min against the wall's D eq, as ECST grades a stenosis against the vessel's estimated
/// width at the lesion, and the share of the wall's area that is not lumen (plaque or
/// thrombus burden). None without a wall there.
pub(crate) fn against_wall(s: &Section) -> Option<(f64, f64, &Wall)> {
    let (l, w) = (s.lumen.as_ref()?, s.wall.as_ref()?);
    Some((
        100.0 * (1.0 - l.min_diameter_mm / w.equivalent_diameter_mm),
        100.0 * (1.0 - l.area_mm2 / w.area_mm2),
        w,
    ))
}

/// [`against_wall`] as a line of the text report (empty without a wall at the lesion); `dark`:
/// an airway's.
fn against_wall_text(s: &Section, dark: bool) -> String {
    match against_wall(s) {
        Some((d, a, w)) => format!(
            "against the wall: {d:.1} % by diameter (D min against the outer wall's D eq there, {:.2} mm, as ECST grades), {a:.1} % of the wall's {:.1} mm2 not lumen ({})\n",
            w.equivalent_diameter_mm,
            w.area_mm2,
            if dark {
                "the airway's wall"
            } else {
                "plaque or thrombus burden"
            }
        ),
        None => String::new(),
    }
}

/// The band of diameter stenosis that [`stenosis::severity`] names for `pct`.
fn severity_band(pct: f64) -> &'static str {
    match stenosis::severity(pct) {
        "none" => "under 1 %",
        "minimal" => "1-24 %",
        "mild" => "25-49 %",
        "moderate" => "50-69 %",
        _ => "70-99 %",
    }
}

/// The graded stenosis as JSON (sections numbered from 1, as in the table).
fn stenosis_json(sections: &[Section], g: &Stenosis) -> serde_json::Value {
    let l = sections[g.lesion]
        .lumen
        .as_ref()
        .expect("a graded lesion has a lumen");
    let (method, used, dropped, dilated, sloped) = match &g.source {
        ReferenceSource::Fitted {
            used,
            dropped,
            dilated,
            sloped,
        } => (
            "fitted",
            used,
            json!(dropped),
            json!(dilated),
            json!(sloped),
        ),
        ReferenceSource::Placed(r) => ("placed", r, json!(null), json!(null), json!(r.len() == 2)),
    };
    json!({
        "lesion_section": g.lesion + 1,
        "lesion_arc_mm": round3(g.lesion_mm),
        "area_mm2": round3(l.area_mm2),
        "min_diameter_mm": round3(l.min_diameter_mm),
        "equivalent_diameter_mm": round3(l.equivalent_diameter_mm),
        "reference": {
            "method": method,
            "sections": used.iter().map(|i| i + 1).collect::<Vec<_>>(),
            "dropped": dropped,
            "dilated": dilated,
            "sloped": sloped,
            "diameter_mm": round3(g.at_lesion_mm),
            "area_mm2": round3(g.reference_area_mm2),
            "slope": g.slope,
            "from_mm": round3(g.domain_mm[0]),
            "to_mm": round3(g.domain_mm[1]),
        },
        "diameter_stenosis_pct": round3(g.diameter_pct),
        "area_stenosis_pct": round3(g.area_pct),
        "severity": stenosis::severity(g.diameter_pct),
        "narrowed_below": stenosis::NARROWED,
        "dilated_above": stenosis::DILATED,
        "against_wall": against_wall(&sections[g.lesion]).map(|(d, a, w)| json!({
            "diameter_pct": round3(d),
            "area_pct": round3(a),
            "wall_equivalent_diameter_mm": round3(w.equivalent_diameter_mm),
            "wall_area_mm2": round3(w.area_mm2),
        })),
        "narrowed": g.narrowed.as_ref().map(|n| json!({
            "from_section": n.sections[0] + 1,
            "to_section": n.sections[1] + 1,
            "from_mm": round3(n.mm[0]),
            "to_mm": round3(n.mm[1]),
            "length_mm": round3(n.mm[1] - n.mm[0]),
        })),
    })
}

fn report_json(
    a: &MeasureArgs,
    opt: &LumenOptions,
    sections: &[Section],
    findings: &Findings,
) -> serde_json::Value {
    let (winding, graded) = (findings.winding, findings.lesions.first());
    let v3 = |v: DVec3| [round3(v.x), round3(v.y), round3(v.z)];
    let rows: Vec<serde_json::Value> = sections
        .iter()
        .map(|s| {
            let mut o = json!({
                "arc_mm": round3(s.arc_mm),
                "point": v3(s.row.centre.as_dvec3()),
                "tangent": s.tangent().as_dvec3().to_array(),
                "lumen": status(s),
            });
            if let Some(l) = &s.lumen {
                let m = o.as_object_mut().unwrap();
                m.insert("area_mm2".into(), json!(round3(l.area_mm2)));
                m.insert(
                    "equivalent_diameter_mm".into(),
                    json!(round3(l.equivalent_diameter_mm)),
                );
                m.insert("max_diameter_mm".into(), json!(round3(l.max_diameter_mm)));
                m.insert(
                    "max_diameter_ends".into(),
                    json!([v3(l.max_ends[0]), v3(l.max_ends[1])]),
                );
                m.insert(
                    "cross_diameter_mm".into(),
                    json!(round3(l.cross_diameter_mm)),
                );
                m.insert("min_diameter_mm".into(), json!(round3(l.min_diameter_mm)));
                m.insert(
                    "min_diameter_direction".into(),
                    json!(l.min_direction.to_array()),
                );
                m.insert("centroid".into(), json!(v3(l.centroid)));
                m.insert("offset_mm".into(), json!(round3(l.offset_mm)));
            }
            if a.wall.is_some() {
                o.as_object_mut().unwrap().insert(
                    "wall".into(),
                    s.wall.as_ref().map_or(json!(null), wall_json),
                );
            }
            if let Some(d) = graded.and_then(|g| g.reference_at(s.arc_mm)) {
                o.as_object_mut()
                    .unwrap()
                    .insert("reference_diameter_mm".into(), json!(round3(d)));
            }
            o
        })
        .collect();
    let (widest, narrowest) = match extremes(sections) {
        Some((w, n)) => (json!(w + 1), json!(n + 1)),
        None => (json!(null), json!(null)),
    };
    let mut report = json!({
        "input": file_name(&a.input),
        "path": file_name(&a.path),
        "length_mm": round3(winding.length_mm),
        "ends_distance_mm": round3(winding.chord_mm),
        "distance_metric": winding.distance_metric.map(round3),
        "turning_deg_per_cm": round3(winding.turning_deg_per_cm),
        "threshold_hu": opt.threshold_hu,
        "dark": opt.dark,
        "field_mm": opt.field_mm,
        "seed_mm": opt.seed_mm,
        "open_mm": opt.open_mm,
        "sample_mm": opt.pixel_mm,
        "widest_section": widest,
        "narrowest_section": narrowest,
        "sections": rows,
    });
    let m = report.as_object_mut().unwrap();
    if let Some(g) = graded {
        m.insert("stenosis".into(), stenosis_json(sections, g));
    }
    if a.lesions.is_some() && !findings.lesions.is_empty() {
        let all: Vec<_> = findings
            .lesions
            .iter()
            .map(|g| stenosis_json(sections, g))
            .collect();
        m.insert("stenoses".into(), json!(all));
    }
    if let Some(k) = findings.mask {
        m.insert("mask".into(), mask_json(k));
    }
    if let Some(r) = findings.report {
        m.insert("report".into(), r.json());
    }
    if let Some(g) = findings.angle {
        m.insert("angle".into(), angle_json(g));
    }
    if let Some(w) = wall_options(a, opt) {
        let mean = |f: fn(&Wall) -> f64| wall_mean(sections, f).map(round3);
        match w.edge {
            WallEdge::Below(hu) => m.insert("wall_threshold_hu".into(), json!(hu)),
            WallEdge::HalfMaximum => m.insert("wall_edge".into(), json!("half_maximum")),
            WallEdge::Integral => m.insert("wall_edge".into(), json!("integral")),
        };
        m.insert(
            "wall_mean_thickness_mm".into(),
            json!(mean(|w| w.mean_thickness_mm)),
        );
        m.insert("wall_area_percent".into(), json!(mean(Wall::area_percent)));
        if let Some(pi10) = findings.pi10 {
            if let Err(why) = pi10 {
                m.insert("pi10_why_none".into(), json!(why));
            }
            m.insert(
                "pi10".into(),
                match pi10 {
                    Ok(p) => json!({
                        "value_mm": round3(p.value_mm),
                        "intercept_mm": round3(p.intercept_mm),
                        "slope": (p.slope * 1e5).round() / 1e5,
                        "r2": round3(p.r2),
                        "sections": p.sections,
                        "perimeter_range_mm": p.perimeter_range_mm.map(round3),
                        "extrapolated": p.extrapolated(),
                    }),
                    Err(_) => json!(null),
                },
            );
        }
        m.insert(
            "widest_wall_section".into(),
            json!(widest_wall(sections).map(|(i, _)| i + 1)),
        );
        let step = winding.length_mm / sections.len() as f64;
        m.insert(
            "wall_volume".into(),
            json!(WallVolumes::of(sections, step).map(|v| json!({
                "sections": v.sections,
                "length_mm": round3(v.length_mm),
                "wall_ml": round3(v.wall_mm3 / 1000.0),
                "lumen_ml": round3(v.lumen_mm3 / 1000.0),
            }))),
        );
    }
    report
}

/// A section's outer wall as JSON.
fn wall_json(w: &Wall) -> serde_json::Value {
    let v3 = |v: DVec3| [round3(v.x), round3(v.y), round3(v.z)];
    json!({
        "area_mm2": round3(w.area_mm2),
        "equivalent_diameter_mm": round3(w.equivalent_diameter_mm),
        "max_diameter_mm": round3(w.max_diameter_mm),
        "max_diameter_ends": [v3(w.max_ends[0]), v3(w.max_ends[1])],
        "cross_diameter_mm": round3(w.cross_diameter_mm),
        "min_diameter_mm": round3(w.min_diameter_mm),
        "min_diameter_direction": w.min_direction.to_array(),
        "max_thickness_mm": round3(w.max_thickness_mm),
        "mean_thickness_mm": round3(w.mean_thickness_mm),
        "inner_area_mm2": round3(w.inner_area_mm2),
        "area_percent": round3(w.area_percent()),
        "centre": v3(w.centre),
        "circle_diameter_mm": round3(w.circle_diameter_mm),
        "seen": round3(w.seen),
        "from_neighbours": w.from_neighbours,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use raystream_cpu::cpr::CprRow;
    use raystream_cpu::lumen::Lumen;
    use raystream_math::Vec3;

    /// The report says how many sections a fitted reference left out as narrowed, and how
    /// many as dilated, in words and in the JSON.
    #[test]
    fn a_fitted_reference_reports_what_it_left_out() {
        let lumen = Lumen {
            area_mm2: 50.0,
            equivalent_diameter_mm: 7.98,
            max_diameter_mm: 9.0,
            max_ends: [DVec3::ZERO; 2],
            min_diameter_mm: 7.0,
            min_direction: DVec3::X,
            cross_diameter_mm: 7.0,
            centroid: DVec3::ZERO,
            offset_mm: 0.0,
            open: false,
        };
        let sections = vec![Section {
            arc_mm: 10.0,
            row: CprRow {
                centre: Vec3::ZERO,
                lateral: Vec3::X,
                normal: Vec3::Y,
            },
            lumen: Some(lumen),
            wall: None,
        }];
        let mut g = Stenosis {
            lesion: 0,
            lesion_mm: 10.0,
            at_lesion_mm: 12.0,
            slope: -0.05,
            domain_mm: [0.0, 30.0],
            source: ReferenceSource::Fitted {
                used: vec![],
                dropped: 3,
                dilated: 2,
                sloped: true,
            },
            reference_area_mm2: 113.1,
            diameter_pct: 41.7,
            area_pct: 55.8,
            narrowed: None,
        };
        let words = reference_words(&sections, &g);
        assert!(
            words.contains("(3 narrowed and 2 dilated left out)"),
            "{words}"
        );
        let j = stenosis_json(&sections, &g);
        assert_eq!(j["reference"]["dropped"], 3);
        assert_eq!(j["reference"]["dilated"], 2);
        assert_eq!(j["dilated_above"], stenosis::DILATED);
        g.source = ReferenceSource::Fitted {
            used: vec![],
            dropped: 3,
            dilated: 0,
            sloped: true,
        };
        assert!(reference_words(&sections, &g).contains("(3 narrowed left out)"));
    }
}
