//! `raystream measure`: a vessel's lumen on cross-sections along a path through a CT volume, as
//! a vascular workstation tabulates an aorta for stent-graft sizing or a stenosis: per section
//! its area, the diameter of a circle of that area, its largest and smallest calliper
//! diameters and how far its centroid lies from the path (see `raystream_cpu::lumen`).

use std::fmt::Write as _;

use anyhow::{Context, Result, bail};
use raystream_cpu::cpr::CurvedPlane;
use raystream_cpu::lumen::{self, LumenOptions, Section};
use raystream_math::DVec3;
use serde_json::json;

use crate::cli::MeasureArgs;
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
    let points = raystream_io::read_curve(&a.path)?;
    let (volume, _) = read_volume(&a.input, &a.pick.select(), a.quiet, None)?;
    let opt = LumenOptions {
        threshold_hu: a.vessel.lumen,
        field_mm: a.field,
        seed_mm: a.vessel.seed,
        open_mm: a.open,
        ..LumenOptions::for_volume(&volume)
    };
    opt.check()
        .map_err(|e| anyhow::anyhow!("--lumen/--field/--seed/--open: {e}"))?;
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
    let sections = lumen::measure_path(&volume, &points, n as u32, DVec3::X, &opt)
        .map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    pb.finish_and_clear();
    if let Some(out) = &a.output {
        std::fs::write(out, csv(&sections))
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    if a.json {
        print_line(report_json(a, &opt, length, &sections));
    } else {
        print_line(report_text(a, &opt, length, &sections));
    }
    if sections.iter().all(|s| s.lumen.is_none()) {
        bail!(
            "{file}: no lumen at or above {} HU within {} mm of the path on any of its {n} sections (a non-contrast scan, or the path off the vessel: --lumen HU, --seed MM)",
            a.vessel.lumen,
            a.vessel.seed
        );
    }
    Ok(())
}

/// A section's state: its lumen closed, open (reaching the field's edge) or not found.
fn status(s: &Section) -> &'static str {
    match &s.lumen {
        Some(l) if l.open => "open",
        Some(_) => "closed",
        None => "none",
    }
}

/// The table as CSV, a section a row (LPS mm; empty fields where no lumen was found).
fn csv(sections: &[Section]) -> String {
    let mut t = String::from(
        "section,arc_mm,x,y,z,tangent_x,tangent_y,tangent_z,status,area_mm2,equivalent_diameter_mm,max_diameter_mm,cross_diameter_mm,min_diameter_mm,centroid_x,centroid_y,centroid_z,offset_mm\n",
    );
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
                let _ = writeln!(
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
            None => t.push_str(",,,,,,,,,\n"),
        }
    }
    t
}

/// The sections with the largest and the smallest lumen (by its largest diameter, and by its
/// equivalent one), closed lumens only.
fn extremes(sections: &[Section]) -> Option<(usize, usize)> {
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

fn report_text(a: &MeasureArgs, opt: &LumenOptions, length: f64, sections: &[Section]) -> String {
    let n = sections.len();
    let mut t = format!(
        "{}: the lumen (>= {} HU, connected to the path within {} mm, opened by a {} mm disc) on {n} sections of {} ({length:.1} mm), {:.2} mm apart, sampled every {:.3} mm over {} mm\n",
        a.input.display(),
        opt.threshold_hu,
        opt.seed_mm,
        opt.open_mm,
        a.path.display(),
        length / n as f64,
        opt.pixel_mm,
        opt.field_mm,
    );
    t += "section   arc mm         x         y         z   area mm2   D eq mm  D max mm  D cross mm  D min mm  offset mm  lumen\n";
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
                let _ = writeln!(
                    t,
                    " {:>10.1} {:>9.2} {:>9.2} {:>11.2} {:>9.2} {:>10.2}  {}",
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
                let _ = writeln!(
                    t,
                    "          -         -         -           -         -          -  none"
                );
            }
        }
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
            "open: {open} of {n} sections, where the lumen reaches the {} mm field's edge (wider than the field, or joined to a bright neighbour such as bone at this threshold): their figures are of the part in the field",
            opt.field_mm
        );
    }
    if none > 0 {
        let _ = writeln!(
            t,
            "none: {none} of {n} sections with no lumen at or above {} HU within {} mm of the path",
            opt.threshold_hu, opt.seed_mm
        );
    }
    t.trim_end().to_string()
}

fn report_json(
    a: &MeasureArgs,
    opt: &LumenOptions,
    length: f64,
    sections: &[Section],
) -> serde_json::Value {
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
            o
        })
        .collect();
    let (widest, narrowest) = match extremes(sections) {
        Some((w, n)) => (json!(w + 1), json!(n + 1)),
        None => (json!(null), json!(null)),
    };
    json!({
        "input": file_name(&a.input),
        "path": file_name(&a.path),
        "length_mm": round3(length),
        "threshold_hu": opt.threshold_hu,
        "field_mm": opt.field_mm,
        "seed_mm": opt.seed_mm,
        "open_mm": opt.open_mm,
        "sample_mm": opt.pixel_mm,
        "widest_section": widest,
        "narrowest_section": narrowest,
        "sections": rows,
    })
}
