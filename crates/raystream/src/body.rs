//! `--body-only`: a CT kept to the patient's body ([`raystream_volume::body`]), the table, a
//! head holder, cables and pads left out: for the bones and the volume modes, every voxel
//! beyond the body's margin set to the CT's lowest value (air); for the projections (mip,
//! minip, average), the body's voxels alone projected, as a segment kept (`--segment`) is.

use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};
use raystream_cpu::dvr::DvrMode;
use raystream_io::{ValueUnit, Volume};
use raystream_volume::body::{Body, BodyOptions, body};

use crate::segments::Painted;

/// How the body is found.
const OPTIONS: BodyOptions = BodyOptions::DEFAULT;

/// The body in `volume` (read from `path`), said on stderr unless `quiet`; refused for a
/// volume not in HU.
pub fn find(volume: &Volume, path: &Path, quiet: bool) -> Result<Body> {
    let (b, ms) = find_timed(volume, path, "--body-only", quiet)?;
    if !quiet {
        eprintln!(
            "raystream: {}: {} ({ms:.0} ms)",
            path.display(),
            words(&b, volume.voxel_ml()),
        );
    }
    Ok(b)
}

/// The body in `volume` and the ms it took, a spinner shown unless `quiet`; refused, naming
/// `path` and `flag`, for a volume not in HU or without a body.
pub fn find_timed(volume: &Volume, path: &Path, flag: &str, quiet: bool) -> Result<(Body, f64)> {
    if volume.unit != ValueUnit::Hounsfield {
        bail!(
            "{}: {flag} finds the body by its HU (above {} HU); this volume's values are not HU",
            path.display(),
            OPTIONS.threshold_hu
        );
    }
    let t = Instant::now();
    let pb = crate::common::spinner(quiet, &format!("finding the body in {}", path.display()));
    let b =
        body(volume, &OPTIONS).map_err(|e| anyhow::anyhow!("{}: {flag}: {e}", path.display()))?;
    pb.finish_and_clear();
    Ok((b, t.elapsed().as_secs_f64() * 1e3))
}

/// What the summary says of `b`: the body's size, what was left out, the thin parts joined.
pub fn words(b: &Body, voxel_ml: f64) -> String {
    let big: Vec<String> = (b.left_out_ml.iter().filter(|&&ml| ml >= 1.0))
        .map(|ml| format!("{ml:.0} ml"))
        .collect();
    let small = &b.left_out_ml[big.len()..];
    let mut out = Vec::new();
    if !big.is_empty() {
        out.push(format!(
            "{} ({})",
            crate::common::plural(big.len(), "piece", "pieces"),
            big.join(", ")
        ));
    }
    if !small.is_empty() {
        out.push(format!(
            "{} ({:.1} ml)",
            crate::common::plural(small.len(), "speck", "specks"),
            small.iter().sum::<f64>()
        ));
    }
    format!(
        "the body, {:.2} l with what it encloses; left out above {} HU: {}{}{}",
        b.voxels as f64 * voxel_ml / 1000.0,
        OPTIONS.threshold_hu,
        if out.is_empty() {
            "nothing".to_string()
        } else {
            out.join(" and ")
        },
        match b.thin_parts {
            0 => String::new(),
            n => format!(
                "; {} thinner than the {} mm ball joined back ({:.1} ml)",
                crate::common::plural(n, "part", "parts"),
                2.0 * OPTIONS.opening_mm,
                b.thin_part_ml
            ),
        },
        match (b.cut_slices, b.border_tissue_ml) {
            (0, _) => String::new(),
            (n, ml) if ml > 0.0 => format!(
                "; the field of view cuts the body in {}, where {:.0} ml reaching its border \
                 reads as tissue, not air (less than half at or below {} HU: a lung it cuts, a \
                 pocket by the skin), and is kept",
                crate::common::plural(n, "slice", "slices"),
                ml,
                OPTIONS.air_hu
            ),
            (n, _) => format!(
                "; the field of view cuts the body in {}, where all else reaching its border \
                 reads as air",
                crate::common::plural(n, "slice", "slices")
            ),
        }
    )
}

/// `b`, found on `volume`, on the grid a lone slice is drawn on (`Volume::slab_of_lone_slices`:
/// two layers of it), else as it is.
pub fn on_slab(mut b: Body, volume: &Volume) -> Body {
    let mask = Volume {
        origin: volume.origin,
        direction: volume.direction,
        ..Volume::hounsfield(
            volume.dims,
            volume.spacing,
            b.inside.iter().map(|&i| f32::from(u8::from(i))).collect(),
        )
    };
    if let Some(slab) = mask.slab_of_lone_slices() {
        b.inside = slab.data.iter().map(|&x| x > 0.5).collect();
    }
    b
}

/// A projection (mip, minip, average) of `volume` kept to the body, and to the segments
/// `painted` keeps it to (if any): its weights ([`keep_projected`]), and an average's window
/// spanning the body's values where none was set.
pub fn projected(
    mode: DvrMode,
    volume: &mut Volume,
    painted: Option<Painted>,
    b: &Body,
) -> Painted {
    let mut p = painted.unwrap_or_else(|| Painted {
        colours: None,
        kept: None,
        weights: None,
        window: None,
        words: "the body alone".to_string(),
        legend: Vec::new(),
    });
    let weights = keep_projected(mode, volume, p.weights.take(), b);
    if mode == DvrMode::Average && p.window.is_none() {
        let mut values: Vec<f32> = (volume.data.iter().zip(&weights.data))
            .filter(|&(_, &w)| w > 0.0)
            .map(|(&v, _)| v)
            .collect();
        p.window = crate::segments::spanning_window(&mut values);
    }
    p.weights = Some(weights);
    p
}

/// A projection (mip, minip, average) kept to the body: `weights` (1 at each voxel kept, 0
/// at each hidden one: a segment's, or none) and `b`'s voxels together, and `volume`'s
/// voxels hidden set to 0, as `raystream_cpu::dvr::CpuVolume::kept` takes them. So a MinIP
/// shows the bowel's gas, the lungs and the airway rather than the air around the body; it
/// takes the body less its rim ([`Body::without_rim`]: the skin's outer voxels, partly air,
/// would be its lowest values), a MIP and an average the whole body (a MIP's silhouette is
/// the skin's).
pub fn keep_projected(
    mode: DvrMode,
    volume: &mut Volume,
    weights: Option<Volume>,
    b: &Body,
) -> Volume {
    let mut w = weights.unwrap_or_else(|| Volume {
        origin: volume.origin,
        direction: volume.direction,
        ..Volume::hounsfield(volume.dims, volume.spacing, vec![1.0; volume.data.len()])
    });
    let rimless;
    let inside = match mode {
        DvrMode::MinIp => {
            rimless = b.without_rim(volume.dims);
            &rimless
        }
        _ => &b.inside,
    };
    for ((x, v), &inside) in w.data.iter_mut().zip(volume.data.iter_mut()).zip(inside) {
        if !inside {
            *x = 0.0;
        }
        if *x == 0.0 {
            *v = 0.0;
        }
    }
    w
}
