//! `raystream centreline`: a vessel's centreline through a CT volume's contrast-filled lumen
//! (or, `--dark`, an airway's) from a few points placed in it (see `raystream_volume::centreline`), written as a path that
//! `render --path` and `measure --path` read.

use std::time::Instant;

use anyhow::Result;
use raystream_volume::centreline::{CentrelineOptions, centreline};

use crate::cli::CentrelineArgs;
use crate::common::{file_name, ms, spinner};
use crate::iso::read_volume;

pub fn run(a: &CentrelineArgs) -> Result<()> {
    let file = a.path.display();
    let points = raystream_io::read_curve(&a.path)?;
    let (volume, _) = read_volume(&a.input, &a.pick.select(), a.quiet, None)?;
    if !a.quiet && volume.unit != raystream_io::ValueUnit::Hounsfield {
        eprintln!(
            "raystream: {}: values are not known to be Hounsfield units; --lumen {} applies to the raw values",
            a.input.display(),
            a.vessel.lumen
        );
    }
    let opt = CentrelineOptions {
        threshold_hu: a.vessel.lumen,
        dark: a.vessel.dark,
        seed_mm: a.vessel.seed,
        margin_mm: a.margin,
        close_mm: a.close,
        smooth_mm: a.smooth,
        step_mm: a.step,
    };
    let t0 = Instant::now();
    let pb = spinner(
        a.quiet,
        &format!(
            "tracking the lumen through the {} points of {file}",
            points.len()
        ),
    );
    let line = centreline(&volume, &points, &opt).map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
    pb.finish_and_clear();
    let what = format!(
        "raystream centreline: the lumen ({} {} HU) of {} through the {} points of {}, {:.1} mm",
        if a.vessel.dark { "<=" } else { ">=" },
        a.vessel.lumen,
        file_name(&a.input),
        points.len(),
        file_name(&a.path),
        line.length_mm
    );
    raystream_io::write_curve(&a.output, &line.points, &what)?;
    if !a.quiet {
        let moved: Vec<String> = points
            .iter()
            .zip(&line.anchors)
            .map(|(p, (q, _))| format!("{:.1}", p.distance(*q)))
            .collect();
        // The path just written has two distinct points; a closed one has no metric.
        let winding = raystream_cpu::cpr::tortuosity(&line.points)
            .ok()
            .and_then(|w| w.distance_metric.map(|m| (m, w.turning_deg_per_cm)))
            .map_or(String::new(), |(m, t)| {
                format!(" (distance metric {m:.3}, turning {t:.1} deg a cm)")
            });
        eprintln!(
            "raystream: wrote {}: a centreline {:.1} mm long{winding}, {} control points {} mm apart, through the {} points of {file} (moved onto the lumen's centre by {} mm); {} voxels searched, {} of them lumen, in {:.0} ms",
            a.output.display(),
            line.length_mm,
            line.points.len(),
            a.step,
            points.len(),
            moved.join(", "),
            line.box_voxels,
            line.lumen_voxels,
            ms(t0.elapsed())
        );
    }
    Ok(())
}
