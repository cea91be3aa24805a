//! `raystream info`: a mesh's size and bounds and its kd-tree statistics, a volume's geometry
//! (dims, spacing in mm, LPS origin and direction), value range and, for DICOM, its series, or
//! a scene file as `render` would draw it.

use anyhow::{Result, bail};
use raystream_accel::KdTree;
use raystream_io::SurfaceMeasures;
use serde_json::json;

use crate::cli::InfoArgs;
use crate::common::{file_name, print_line, round3};

pub fn tree_json(tree: &KdTree) -> serde_json::Value {
    let s = &tree.stats;
    let g = &tree.entry;
    json!({
        "builder": s.builder,
        "nodes": s.nodes,
        "leaves": s.leaves,
        "empty_leaves": s.empty_leaves,
        "max_depth": s.max_depth,
        "sah_cost": round3(s.sah_cost),
        "sah_traversal_cost": s.traversal_cost,
        "mean_tris_per_leaf": round3(s.mean_tris_per_leaf),
        "references": s.references,
        "build_ms": round3(s.build_ms),
        "entry_grid": (!g.cells.is_empty()).then(|| json!({
            "cells": g.res,
            "bytes": g.bytes(),
            "mean_depth": round3(g.mean_depth),
        })),
    })
}

/// The entry grid in words, as `info` prints it.
fn entry_grid_line(g: &raystream_accel::entry::EntryGrid) -> String {
    if g.cells.is_empty() {
        return "none: walks start at the root".into();
    }
    let [x, y, z] = g.res;
    format!(
        "{x}x{y}x{z} cells ({:.2} MB); walks start {:.1} levels below the root on average over the cells",
        g.bytes() as f64 / 1e6,
        g.mean_depth
    )
}

pub fn run(a: &InfoArgs) -> Result<()> {
    let Some(input) = &a.input else {
        gpu_info(a.json);
        return Ok(());
    };
    if input.is_file() && raystream_io::is_structured_report(input) {
        return report_info(a, input);
    }
    if raystream_io::is_volume_path(input) {
        crate::mask_out::check_names(a.mask.as_deref(), a.structures.as_deref())?;
        return volume_info(a, input);
    }
    if let Some(labels) = &a.segmentation {
        bail!(
            "--segmentation {}: gives the values of a CT volume within its segments; {} is not a volume",
            labels.display(),
            input.display()
        );
    }
    if a.body {
        bail!(
            "--body finds the patient's body in a CT volume; {} is not a volume",
            input.display()
        );
    }
    if input
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    {
        return scene_info(a, input);
    }
    // The mesh with its materials (an OBJ's MTL), each with the triangles that use it, and its
    // objects (a 3MF's build items).
    let (mesh, materials) = raystream_io::load_mesh_with_shading(input)?;
    let mut counts = vec![0usize; materials.materials.len()];
    for m in materials.material_of.iter().flatten() {
        counts[*m as usize] += 1;
    }
    // Each with the size of the texture it applies, if any.
    let used: Vec<(&str, usize, Option<[u32; 2]>)> = materials
        .materials
        .iter()
        .zip(counts)
        .map(|(m, n)| {
            let texture = m.image.as_ref().map(|t| [t.width, t.height]);
            (m.name.as_str(), n, texture)
        })
        .collect();
    // The file's colours (per vertex or per face), counted distinct.
    let colours = (!materials.colours.is_empty()).then(|| {
        let distinct: std::collections::HashSet<_> =
            materials.colours.iter().flatten().copied().collect();
        distinct.len()
    });
    let tree = a.tree.build(&mesh);
    let surface = mesh.measure_surface();
    // A DICOM Encapsulated STL: the patient, study and images it was made from.
    let record = &materials.dicom;
    let b = mesh.bounds();
    let s = &tree.stats;
    if a.json {
        let v = json!({
            "kind": "mesh",
            "file": file_name(input),
            "vertices": mesh.positions.len(),
            "triangles": mesh.len(),
            "degenerate_triangles": mesh.len() - s.triangles,
            "bounds": [b.min.to_array(), b.max.to_array()],
            "surface": surface_json(&surface),
            "dicom": record.as_ref().map(|r| json!({
                "title": r.title,
                "patient_name": r.patient_name,
                "patient_id": r.patient_id,
                "study_uid": r.study_uid,
                "study_date": r.study_date,
                "series_uid": r.series_uid,
                "frame_of_reference_uid": r.frame_of_reference_uid,
                "source_series": r.source_series,
                "source_images": r.source_images,
            })),
            "kdtree": tree_json(&tree),
            "materials": used.iter().map(|(name, n, t)| json!({"name": name, "triangles": n, "texture": t})).collect::<Vec<_>>(),
            "objects": materials.objects.iter().map(|(name, n)| json!({"name": name, "triangles": n})).collect::<Vec<_>>(),
            "texture_coordinates": !materials.uvs.is_empty(),
            "colours": colours.map(|n| json!({"distinct": n})),
            "space": materials.space.map(|s| s.name()),
            "warnings": materials.warnings,
        });
        print_line(v);
    } else {
        println!("{}: triangle mesh", input.display());
        println!("  vertices   {}", mesh.positions.len());
        println!(
            "  triangles  {} ({} degenerate, never hit)",
            mesh.len(),
            mesh.len() - s.triangles
        );
        println!(
            "  bounds     {:?} .. {:?}",
            b.min.to_array(),
            b.max.to_array()
        );
        if let Some(r) = record {
            let said = |what: &str, parts: &[&str]| {
                let parts: Vec<&str> = parts.iter().copied().filter(|p| !p.is_empty()).collect();
                (!parts.is_empty()).then(|| format!("{what} {}", parts.join(", ")))
            };
            let sources = match r.source_series.as_slice() {
                _ if r.source_images == 0 => String::new(),
                [one] => format!("made from {} images of series {one}", r.source_images),
                _ => format!("made from {} images", r.source_images),
            };
            let words: Vec<String> = [
                Some(format!("Encapsulated STL \"{}\"", r.title)),
                said("of patient", &[&r.patient_name, &r.patient_id]),
                said("study", &[&r.study_uid, &r.study_date]),
                (!sources.is_empty()).then_some(sources),
            ]
            .into_iter()
            .flatten()
            .collect();
            println!("  dicom      {}", words.join("; "));
            println!(
                "  space      LPS: patient millimetres, a DICOM Encapsulated STL's (frame of reference {}); render shows it from the front, head up",
                r.frame_of_reference_uid
            );
        } else if let Some(space) = materials.space {
            println!(
                "  space      {}: patient millimetres, as the file says (SPACE={0}, 3D Slicer's tag); render shows it from the front, head up",
                space.name()
            );
        }
        let mm = materials.space.is_some() || record.is_some();
        println!("  surface    {}", surface_line(&surface, mm, false));
        if surface.shells > 1 {
            shell_lines(&surface, mm);
        }
        println!(
            "  kd-tree    {}: {} nodes, {} leaves ({} empty), depth {}, SAH cost {:.2}, {:.2} triangles/leaf, {} references, built in {:.1} ms",
            s.builder,
            s.nodes,
            s.leaves,
            s.empty_leaves,
            s.max_depth,
            s.sah_cost,
            s.mean_tris_per_leaf,
            s.references,
            s.build_ms
        );
        println!("  entry grid {}", entry_grid_line(&tree.entry));
        if let Some(n) = colours {
            println!(
                "  colours    {n} distinct: the file's, per vertex or per face, which render draws"
            );
        }
        for (name, n) in &materials.objects {
            println!("  object     {name}: {n} triangles");
        }
        for (name, n, texture) in &used {
            match texture {
                Some([w, h]) => println!("  material   {name}: {n} triangles, a {w}x{h} texture"),
                None => println!("  material   {name}: {n} triangles"),
            }
        }
        for w in &materials.warnings {
            println!("  warning    {w}");
        }
    }
    Ok(())
}

/// A mesh's [`SurfaceMeasures`] as `info --json` gives them, with each shell's the same way
/// in `pieces`, the largest first.
fn surface_json(s: &SurfaceMeasures) -> serde_json::Value {
    let mut v = piece_json(s);
    v["pieces"] = s.pieces.iter().map(piece_json).collect();
    v
}

/// [`surface_json`] of the whole or of one shell.
fn piece_json(s: &SurfaceMeasures) -> serde_json::Value {
    let b = s.bounds;
    json!({
        "triangles": s.faces,
        "bounds": (s.faces > 0).then(|| [b.min.to_array(), b.max.to_array()]),
        "area": s.area,
        "shells": s.shells,
        "closed": s.closed(),
        "volume": s.volume,
        "genus": s.genus(),
        "euler": s.euler(),
        "vertices": s.vertices,
        "edges": s.edges,
        "boundary_edges": s.boundary_edges,
        "holes": s.holes,
        "non_manifold_edges": s.non_manifold_edges,
        "misoriented_edges": s.misoriented_edges,
    })
}

/// The largest of a mesh's shells, a line each, and the rest summed.
fn shell_lines(s: &SurfaceMeasures, mm: bool) {
    const LISTED: usize = 8;
    for (i, p) in s.pieces.iter().take(LISTED).enumerate() {
        let label = format!("shell {}", i + 1);
        println!("  {label:<10} {}", surface_line(p, mm, true));
    }
    let rest = s.pieces.get(LISTED..).unwrap_or_default();
    if !rest.is_empty() {
        let triangles: usize = rest.iter().map(|p| p.faces).sum();
        let area: f64 = rest.iter().map(|p| p.area).sum();
        let closed = rest.iter().filter(|p| p.closed()).count();
        // Closed shells facing in: the walls of cavities (a voxel below the threshold inside
        // a bone is an octahedron of 8), or shells turned inside out.
        let inward: Vec<f64> = (rest.iter())
            .filter(|p| p.closed())
            .filter_map(|p| p.volume.filter(|&v| v < 0.0))
            .collect();
        let inward = match inward.len() {
            0 => String::new(),
            n => {
                let v = volume_words(-inward.iter().sum::<f64>(), mm);
                format!(", {n} facing in (cavities or turned inside out, enclosing {v})")
            }
        };
        println!(
            "  shells     {} more: {triangles} triangles, area {} ({:.2} % of the whole), {closed} of them closed{inward}",
            rest.len(),
            area_words(area, mm),
            100.0 * area / s.area
        );
    }
}

/// A volume, in ml where the file is in millimetres (`mm`), or mm³ where under half a
/// thousandth of a ml (a voxel's cavity).
fn volume_words(volume: f64, mm: bool) -> String {
    match mm {
        true if volume.abs() < 0.5 => format!("{volume:.3} mm³"),
        true => format!("{:.3} ml", volume / 1000.0),
        false => significant(volume),
    }
}

/// An area, in mm² where the file is in millimetres (`mm`).
fn area_words(area: f64, mm: bool) -> String {
    if mm {
        format!("{area:.1} mm²")
    } else {
        significant(area)
    }
}

/// A mesh's [`SurfaceMeasures`] in words: its area, shells, and whether it closes (what it
/// encloses) or what keeps it from closing; in mm² and ml where the file is in millimetres
/// (`mm`). One shell's (`piece`) begins with its triangles and ends with where its box's
/// middle is.
fn surface_line(s: &SurfaceMeasures, mm: bool, piece: bool) -> String {
    use crate::common::plural;
    let area = area_words(s.area, mm);
    if s.faces == 0 {
        return format!("area {area}: no triangle has three corners apart");
    }
    let mut line = if piece {
        format!("{}, area {area}", plural(s.faces, "triangle", "triangles"))
    } else {
        format!("area {area}, {}", plural(s.shells, "shell", "shells"))
    };
    let centre = (s.bounds.min + s.bounds.max) / 2.0;
    let place = if !piece {
        String::new()
    } else if mm {
        format!(
            "; around ({:.1}, {:.1}, {:.1}) mm",
            centre.x, centre.y, centre.z
        )
    } else {
        let [x, y, z] = centre.to_array().map(|c| significant(f64::from(c)));
        format!("; around ({x}, {y}, {z})")
    };
    let volume = |v: f64| {
        let turned = match (v < 0.0, piece) {
            (false, _) => "",
            (true, false) => " (turned inside out: its triangles face in)",
            (true, true) => " (its triangles face in: a cavity's wall, or turned inside out)",
        };
        format!("encloses {}{turned}", volume_words(v.abs(), mm))
    };
    if s.closed() {
        line += ", closed";
        if let Some(v) = s.volume {
            line += &format!(": {}", volume(v));
        }
        if let Some(g) = s.genus() {
            line += &format!(", genus {g}");
        }
        return line + &place;
    }
    let mut why = Vec::new();
    if s.boundary_edges > 0 {
        why.push(format!(
            "{} of one triangle ({})",
            plural(s.boundary_edges, "edge", "edges"),
            plural(s.holes, "hole", "holes")
        ));
    }
    if s.non_manifold_edges > 0 {
        why.push(format!(
            "{} of more than two triangles",
            plural(s.non_manifold_edges, "edge", "edges")
        ));
    }
    if s.misoriented_edges > 0 {
        why.push(format!(
            "{} whose two triangles are wound against each other",
            plural(s.misoriented_edges, "edge", "edges")
        ));
    }
    line += &format!(", not closed: {}", why.join(", "));
    if let Some(v) = s.volume {
        line += &format!("; {}", volume(v));
    }
    line + &place
}

/// `x` to seven significant digits, written out (no exponent).
fn significant(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let decimals = (6 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.decimals$}")
}

/// The aspect ratio `info` frames a scene's camera for: `render`'s default 800x600.
const INFO_ASPECT: f32 = 4.0 / 3.0;

/// A scene file as `render` would draw it: its triangles (objects and ground), materials,
/// lights, camera, the objects' bounds, its CT volume and the kd-tree over the triangles.
fn scene_info(a: &InfoArgs, input: &std::path::Path) -> Result<()> {
    let mut scene = raystream_scene::Scene::load(input)?;
    // The volume's segmentation laid on it, as `render` lays it: a mistake shows here too.
    let segments = crate::segments::paint_scene(&mut scene, input)?.map(|(words, _)| words);
    let tree = a.tree.build(&scene.mesh);
    let b = scene.object_box;
    let cam = scene.camera_for(INFO_ASPECT);
    let fov = 2.0 * cam.tan_y.atan().to_degrees();
    if a.json {
        let lights: Vec<_> = scene
            .lights
            .iter()
            .map(|l| json!({"position": l.position.to_array(), "color": l.color.to_array()}))
            .collect();
        let volume = scene.volume.as_ref().map(|v| {
            json!({
                "dims": v.volume.dims,
                "spacing": v.volume.spacing,
                "step_mm": v.step_mm,
                "shadows": v.shadows,
                "phase": {"index": v.volume.phase.index, "count": v.volume.phase.count},
                "segments": segments,
            })
        });
        print_line(json!({
            "kind": "scene",
            "file": file_name(input),
            "triangles": scene.mesh.len(),
            "materials": scene.materials.len(),
            "lights": lights,
            "camera": {
                "eye": cam.eye.to_array(),
                "forward": cam.fwd.to_array(),
                "up": cam.up.to_array(),
                "fov_y_deg": (cam.parallel == 0.0).then(|| round3(fov as f64)),
                "parallel_height": (cam.parallel > 0.0).then_some(2.0 * cam.parallel),
                "framed": scene.camera.is_none(),
            },
            "bounds": [b.min.to_array(), b.max.to_array()],
            "volume": volume,
            "kdtree": tree_json(&tree),
        }));
        return Ok(());
    }
    println!("{}: scene", input.display());
    println!(
        "  triangles  {} (objects and ground), {} materials",
        scene.mesh.len(),
        scene.materials.len()
    );
    for (i, l) in scene.lights.iter().enumerate() {
        println!(
            "  light {i}    at {:?}, colour {:?}",
            l.position.to_array(),
            l.color.to_array()
        );
    }
    println!(
        "  camera     eye {:?} looking along {:?}, {}{}",
        cam.eye.to_array(),
        cam.fwd.to_array(),
        if cam.parallel > 0.0 {
            format!("parallel, {} high", 2.0 * cam.parallel)
        } else {
            format!("{fov:.1}° vertical")
        },
        if scene.camera.is_none() {
            " (framing the objects at 4:3)"
        } else {
            ""
        }
    );
    println!(
        "  bounds     {:?} .. {:?} (the objects, the ground apart)",
        b.min.to_array(),
        b.max.to_array()
    );
    if let Some(v) = &scene.volume {
        println!(
            "  volume     {} x {} x {} voxels of {:?} mm{}{}",
            v.volume.dims[0],
            v.volume.dims[1],
            v.volume.dims[2],
            v.volume.spacing,
            if v.volume.phase.count > 1 {
                format!(
                    ", phase {} of {}",
                    v.volume.phase.index, v.volume.phase.count
                )
            } else {
                String::new()
            },
            if v.shadows {
                ", lit through shadow rays"
            } else {
                ""
            }
        );
        if let Some(words) = &segments {
            println!("  segments   {words}");
        }
    }
    let s = &tree.stats;
    println!(
        "  kd-tree    {}: {} nodes, {} leaves, SAH cost {:.2}, built in {:.1} ms",
        s.builder, s.nodes, s.leaves, s.sah_cost, s.build_ms
    );
    println!("  entry grid {}", entry_grid_line(&tree.entry));
    Ok(())
}

/// A label map holds at most this many labels (besides 0) for `info` to list them.
const MAX_LABELS: usize = 64;

/// A label map's labels, each with its voxels: none where the volume is not one (Hounsfield
/// units, a value that is not a whole number from 0, or over [`MAX_LABELS`] labels).
fn label_counts(v: &raystream_io::Volume) -> Option<Vec<(u32, usize)>> {
    if v.unit == raystream_io::ValueUnit::Hounsfield {
        return None;
    }
    let mut counts = std::collections::BTreeMap::new();
    for &x in &v.data {
        if !(x.is_finite() && x >= 0.0 && x.fract() == 0.0) {
            return None;
        }
        if x > 0.0 {
            *counts.entry(x as u32).or_insert(0usize) += 1;
            if counts.len() > MAX_LABELS {
                return None;
            }
        }
    }
    Some(counts.into_iter().collect())
}

/// A region's statistics: a segment's (one label), or `--combine`'s (its labels together);
/// its name, the CT's values in it, and its densitometry (`--below`, `--percentile`: empty
/// lists when neither is asked).
struct SegmentStats {
    labels: Vec<u32>,
    name: String,
    stats: raystream_volume::RegionStats,
    density: raystream_volume::Densitometry,
    /// `--agatston`: its calcium score.
    calcium: Option<raystream_volume::calcium::Agatston>,
}

/// `--segmentation`'s regions: each segment's, then each `--combine`'s, and how the CT's
/// voxels were matched to the segmentation's.
struct Within {
    segments: Vec<SegmentStats>,
    combined: Vec<SegmentStats>,
    how: &'static str,
    /// `--below-mask`: the file written, and how many segments it holds.
    below_mask: Option<(String, usize)>,
    /// `--agatston-mask`: the file written, and how many segments it holds.
    agatston_mask: Option<(String, usize)>,
    /// `--adjust-to`: the region named, and its inflation against the volume asked.
    adjusted: Option<Adjusted>,
}

/// `--adjust-to REGION=…`: the region and its segments, its inflation, the volume asked.
struct Adjusted {
    region: String,
    labels: Vec<u32>,
    inflation: raystream_volume::Inflation,
    to: crate::cli::AdjustTo,
}

impl Adjusted {
    /// The inflation for a region of the segments `labels`: the region's, for those within
    /// it (a lung of both, a lobe), none for the others (the sponge model is a lung's).
    fn of(&self, labels: &[u32]) -> Option<&raystream_volume::Inflation> {
        labels
            .iter()
            .all(|l| self.labels.contains(l))
            .then_some(&self.inflation)
    }
}

impl SegmentStats {
    /// The CT `ct`'s values over `list` (CT voxels), as `a` asks; `None` for no finite value.
    fn of(
        a: &InfoArgs,
        ct: &raystream_io::Volume,
        labels: Vec<u32>,
        name: String,
        list: &[usize],
    ) -> Option<SegmentStats> {
        let stats = raystream_volume::region_stats(ct, list)?;
        let density = match a.below.is_empty() && a.percentile.is_empty() {
            true => raystream_volume::Densitometry {
                below: Vec::new(),
                percentiles: Vec::new(),
            },
            false => raystream_volume::densitometry(
                ct,
                list,
                &a.below,
                &a.percentile,
                a.clusters.map(Into::into),
            )?,
        };
        let calcium = a
            .agatston
            .then(|| raystream_volume::calcium::agatston(ct, list));
        Some(SegmentStats {
            labels,
            name,
            stats,
            density,
            calcium,
        })
    }

    /// Its statistics as JSON fields (its labels apart): its mass where the CT is in HU
    /// (`hu`), its mean and percentiles adjusted by `inflation` where asked.
    fn json(&self, hu: bool, inflation: Option<&raystream_volume::Inflation>) -> serde_json::Value {
        let (s, d) = (&self.stats, &self.density);
        let mut out = json!({
            "name": self.name,
            "voxels": s.voxels,
            "ml": s.ml,
            "mean": s.mean,
            "sd": s.sd,
            "min": s.min,
            "median": s.median,
            "max": s.max,
            "centroid": s.centroid,
            "below": d.below.iter().map(|b| json!({
                "hu": b.hu,
                "voxels": b.voxels,
                "ml": b.ml,
                "percent": b.percent,
                "clusters": b.clusters.as_ref().map(|c| clusters_json(c, s.ml / s.voxels as f64)),
            })).collect::<Vec<_>>(),
            "percentiles": d.percentiles.iter().map(|&(p, value)| json!({
                "p": p,
                "value": value,
            })).collect::<Vec<_>>(),
        });
        if hu {
            out["mass_g"] = json!(raystream_volume::mass_g(s.ml, s.mean));
        }
        if let Some(c) = &self.calcium {
            out["agatston"] = json!({
                "score": c.score,
                "volume_mm3": c.volume_mm3,
                "lesions": c.lesions(),
                "slices": c.slices(),
                "peak_hu": c.peak_hu(),
                "cac_drs": c.cac_drs(),
                "slice_factor": c.slice_factor,
                "each": c.each.iter().map(|l| json!({
                    "slice": l.slice,
                    "voxels": l.voxels,
                    "area_mm2": l.area_mm2,
                    "peak_hu": l.peak_hu,
                    "weight": l.weight,
                    "score": l.score,
                    "centroid": l.centroid,
                })).collect::<Vec<_>>(),
            });
        }
        if let Some(at) = inflation {
            out["adjusted"] = json!({
                "mean": at.adjust(s.mean),
                "percentiles": d.percentiles.iter().map(|&(p, value)| json!({
                    "p": p,
                    "value": at.adjust(value),
                })).collect::<Vec<_>>(),
            });
        }
        out
    }

    /// Its lines: `head` (what it is) and its statistics (its mass where the CT is in HU),
    /// then its densitometry if asked, and that adjusted by `inflation` where asked.
    fn print(
        &self,
        kind: &str,
        head: &str,
        unit: &str,
        inflation: Option<&raystream_volume::Inflation>,
    ) {
        let s = &self.stats;
        let [x, y, z] = s.centroid;
        let mass = match unit {
            "HU" => format!(", {:.0} g", raystream_volume::mass_g(s.ml, s.mean)),
            _ => String::new(),
        };
        println!(
            "  {kind:<10} {head}: {} voxels, {:.1} ml{mass}; {unit} mean {:.1}, sd {:.1}, min {}, median {}, max {}; centroid ({x:.1}, {y:.1}, {z:.1}) mm LPS",
            s.voxels, s.ml, s.mean, s.sd, s.min, s.median, s.max
        );
        let voxel_ml = s.ml / s.voxels as f64;
        let below = self.density.below.iter().map(|b| {
            let clusters = b.clusters.as_ref().map(|c| {
                let d = (c.power_law).map_or(String::new(), |p| format!(", D {:.2}", p.d));
                let how = match c.connectivity {
                    raystream_volume::clusters::Connectivity::Faces => "",
                    raystream_volume::clusters::Connectivity::InSlices => " in slices",
                };
                match c.count {
                    0 => format!("; no clusters{how}"),
                    n => format!(
                        "; {n} clusters{how}, largest {:.2} ml{d}",
                        c.largest() as f64 * voxel_ml
                    ),
                }
            });
            format!(
                "{:.2} % below {} {unit} ({} voxels, {:.1} ml{})",
                b.percent,
                b.hu,
                b.voxels,
                b.ml,
                clusters.unwrap_or_default()
            )
        });
        let at = (self.density.percentiles.iter())
            .map(|&(p, x)| format!("{} percentile {} {unit}", ordinal(p), round3(x)));
        let parts: Vec<String> = below.chain(at).collect();
        if !parts.is_empty() {
            println!("  density    {head}: {}", parts.join("; "));
        }
        if let Some(c) = &self.calcium {
            let peak = c
                .peak_hu()
                .map_or(String::new(), |p| format!(", peak {p:.0} {unit}"));
            println!(
                "  calcium    {head}: Agatston {:.1} (CAC-DRS {}), volume {:.1} mm³, {} lesions in {} slices{peak}",
                c.score,
                c.cac_drs(),
                c.volume_mm3,
                c.lesions(),
                c.slices()
            );
        }
        if let Some(at) = inflation {
            let mean = format!("mean {:.1} {unit}", at.adjust(s.mean));
            let at = (self.density.percentiles.iter())
                .map(|&(p, x)| format!("{} percentile {:.1} {unit}", ordinal(p), at.adjust(x)));
            let parts: Vec<String> = [mean].into_iter().chain(at).collect();
            println!("  adjusted   {head}: {}", parts.join("; "));
        }
    }
}

/// The clusters of voxels below a value as JSON: how joined, how many, the largest (voxels,
/// ml at `voxel_ml` a voxel), the power law's D and r² (null for fewer than two sizes), and
/// each size met with its count, for a fit of one's own.
fn clusters_json(c: &raystream_volume::clusters::Clusters, voxel_ml: f64) -> serde_json::Value {
    json!({
        "connectivity": match c.connectivity {
            raystream_volume::clusters::Connectivity::Faces => "3d",
            raystream_volume::clusters::Connectivity::InSlices => "2d",
        },
        "count": c.count,
        "largest_voxels": c.largest(),
        "largest_ml": c.largest() as f64 * voxel_ml,
        "d": c.power_law.map(|p| p.d),
        "r2": c.power_law.map(|p| p.r2),
        "sizes": c.sizes.iter().map(|&(voxels, count)| [voxels, count]).collect::<Vec<_>>(),
    })
}

/// `--segmentation LABELS`: the CT `ct`'s values within each segment of LABELS, and how its
/// voxels were matched to the CT's (the same grid, the nearest label voxel, or a structure
/// set's contours laid on the CT's grid).
fn segment_stats(
    a: &InfoArgs,
    ct: &raystream_io::Volume,
    input: &std::path::Path,
) -> Result<Option<Within>> {
    let Some(file) = &a.segmentation else {
        return Ok(None);
    };
    for (option, out) in [
        ("--below-mask", &a.below_mask),
        ("--agatston-mask", &a.agatston_mask),
    ] {
        if let Some(out) = out
            && !raystream_io::is_label_map_path(out)
        {
            anyhow::bail!(
                "{}: {option} writes a NIfTI label map: name it .nii or .nii.gz",
                out.display()
            );
        }
    }
    let need_hu = [
        (
            a.adjust_to.is_some(),
            "--adjust-to adjusts a CT's HU (HU + 1000 being a density in g/l)",
        ),
        (
            a.agatston,
            "--agatston scores a CT's HU (calcium from 130 HU)",
        ),
    ];
    if let Some((_, why)) = need_hu.iter().find(|(asked, _)| *asked)
        && ct.unit != raystream_io::ValueUnit::Hounsfield
    {
        anyhow::bail!(
            "{}: {why}; this volume's values are not in HU",
            input.display()
        );
    }
    let on = crate::segments::on_ct(file, a.colour_table.as_deref(), ct, input)?;
    let name_of = |l: u32| {
        (on.known.iter())
            .find(|k| k.number as u32 == l)
            .map(|k| k.label.clone())
            .unwrap_or_default()
    };
    let present: Vec<u32> = on.members.keys().copied().collect();
    let mut combined = Vec::new();
    for (name, list) in &a.combine {
        let option = format!("--combine {name}=");
        let labels =
            crate::iso::pick_segments(&file.display(), &option, list, &present, &on.known)?;
        let voxels = union(&on, &labels);
        combined.extend(SegmentStats::of(a, ct, labels, name.clone(), &voxels));
    }
    let segments = (on.members.iter())
        .filter_map(|(&l, list)| SegmentStats::of(a, ct, vec![l], name_of(l), list))
        .collect();
    let below_mask = match &a.below_mask {
        Some(out) => {
            let hu = a.below[0];
            let what = format!("raystream info --below-mask: each segment's voxels below {hu} HU");
            let below = |list: &[usize]| -> Vec<usize> {
                (list.iter().copied())
                    .filter(|&n| (ct.data[n] as f64) < hu)
                    .collect()
            };
            Some(write_segment_mask(
                out,
                "--below-mask",
                ct,
                &on,
                below,
                &what,
            )?)
        }
        None => None,
    };
    let agatston_mask = match &a.agatston_mask {
        Some(out) => {
            let what = "raystream info --agatston-mask: each segment's calcium lesions counted (130 HU, 1 mm² within a slice)";
            let lesions = |list: &[usize]| -> Vec<usize> {
                raystream_volume::calcium::agatston_with_voxels(ct, list).1
            };
            Some(write_segment_mask(
                out,
                "--agatston-mask",
                ct,
                &on,
                lesions,
                what,
            )?)
        }
        None => None,
    };
    let adjusted = match &a.adjust_to {
        Some((region, to)) => {
            let named =
                (combined.iter()).find(|r: &&SegmentStats| r.name.eq_ignore_ascii_case(region));
            let (labels, ml) = match named {
                Some(r) => (r.labels.clone(), r.stats.ml),
                None => {
                    let option = "--adjust-to ";
                    let labels = crate::iso::pick_segments(
                        &file.display(),
                        option,
                        region,
                        &present,
                        &on.known,
                    )?;
                    let ml = union(&on, &labels).len() as f64 * ct.voxel_ml();
                    (labels, ml)
                }
            };
            let inflation = raystream_volume::Inflation {
                measured_ml: ml,
                reference_ml: to.ml(),
            };
            Some(Adjusted {
                region: region.clone(),
                labels,
                inflation,
                to: *to,
            })
        }
        None => None,
    };
    Ok(Some(Within {
        segments,
        combined,
        how: on.how,
        below_mask,
        agatston_mask,
        adjusted,
    }))
}

/// The CT voxels of the segments `labels`, in order, each once.
fn union(on: &crate::segments::OnCt, labels: &[u32]) -> Vec<usize> {
    let mut voxels: Vec<usize> = (labels.iter())
        .flat_map(|l| on.members[l].iter().copied())
        .collect();
    voxels.sort_unstable();
    voxels.dedup();
    voxels
}

/// `--below-mask FILE` and `--agatston-mask FILE` (`option`): each segment's voxels that
/// `voxels_of` gives (CT voxels) labelled with its number on the CT `ct`'s grid, the larger
/// segments laid first (so that one within another keeps its own voxels), named and coloured
/// in the file's label table, `what` in its header. The file, and how many segments it holds.
fn write_segment_mask(
    out: &std::path::Path,
    option: &str,
    ct: &raystream_io::Volume,
    on: &crate::segments::OnCt,
    voxels_of: impl Fn(&[usize]) -> Vec<usize>,
    what: &str,
) -> Result<(String, usize)> {
    if let Some(l) = on.members.keys().find(|&&l| l > 255) {
        anyhow::bail!(
            "{}: {option}: segment {l}: a label map of bytes holds labels 1 to 255",
            out.display()
        );
    }
    let mut order: Vec<u32> = on.members.keys().copied().collect();
    order.sort_by_key(|l| std::cmp::Reverse(on.members[l].len()));
    let mut labels = vec![0u8; ct.data.len()];
    for &l in &order {
        for n in voxels_of(&on.members[&l]) {
            labels[n] = l as u8;
        }
    }
    let mut present = [false; 256];
    for &l in &labels {
        present[l as usize] = true;
    }
    let entries: Vec<(u8, String, [u8; 3])> = (1..=255u8)
        .filter(|&l| present[l as usize])
        .map(|l| {
            let known = on.known.iter().find(|k| k.number == l as u16);
            let name = known.map_or_else(|| format!("label {l}"), |k| k.label.clone());
            (l, name, crate::overlay::segment_colour(&on.known, l as u32))
        })
        .collect();
    let table: Vec<(u8, &str, [u8; 3])> = (entries.iter())
        .map(|(l, n, c)| (*l, n.as_str(), *c))
        .collect();
    raystream_io::write_label_map_named(out, ct, &labels, what, &table)?;
    Ok((out.display().to_string(), table.len()))
}

fn volume_info(a: &InfoArgs, input: &std::path::Path) -> Result<()> {
    let v = raystream_io::load_volume(input, &a.pick.select())?;
    crate::mask_out::check_sources(a.mask.as_deref(), a.structures.as_deref(), &v)?;
    let stats = segment_stats(a, &v, input)?;
    let body = if a.body {
        Some(body_info(a, &v, input)?)
    } else {
        None
    };
    let range = v.value_range();
    // A label map's labels, their voxels and volumes, and their names: a Segmentation's, or
    // `--colour-table`'s.
    let voxel_ml = v.voxel_ml();
    let known = crate::iso::segment_names(&v, a.colour_table.as_deref())?;
    // A structure set's structures and a Segmentation's segments are counted whole,
    // overlaps and all.
    let structures = if raystream_io::is_structure_set_volume(&v) {
        Some(raystream_io::StructureSet::read(input)?)
    } else {
        None
    };
    // The structure set already read is laid on its CT here, not read again.
    let whole = match &structures {
        Some(set) => Some(set.whole(set.regions(&v).0)),
        None => raystream_io::whole_segments(&v, input)?,
    };
    let whole = whole.map(|w| {
        w.into_iter()
            .filter(|(_, r)| r.voxels > 0)
            .map(|(l, r)| (l as u32, r.voxels))
            .collect()
    });
    let labels: Option<Vec<(u32, usize, f64, String)>> =
        whole.or_else(|| label_counts(&v)).map(|counts| {
            counts
                .into_iter()
                .map(|(l, n)| {
                    let name = known
                        .iter()
                        .find(|k| k.number as u32 == l)
                        .map(|k| k.label.clone())
                        .unwrap_or_default();
                    (l, n, n as f64 * voxel_ml, name)
                })
                .collect()
        });
    // Where render and iso draw the surface of values of no known unit.
    let surface = crate::iso::default_surface(&v);
    let unit = match v.unit {
        raystream_io::ValueUnit::Hounsfield => "HU",
        raystream_io::ValueUnit::Unknown => "unknown",
    };
    let series = v.series.as_ref().map(|s| {
        json!({
            "uid": s.uid,
            "description": s.description,
            "modality": s.modality,
            "count": s.count,
            "transfer_syntax": s.transfer_syntax,
            "transfer_syntax_name": s.transfer_syntax_name,
            "all": s.all.iter().map(|(u, n, d)| json!({"uid": u, "count": n, "description": d})).collect::<Vec<_>>(),
        })
    });
    if a.json {
        let mut out = json!({
            "kind": "volume",
            "file": file_name(input),
            "format": v.format.name(),
            "dims": v.dims,
            "spacing": v.spacing,
            "origin": v.origin,
            "direction": v.direction.concat().iter().map(|d| d + 0.0).collect::<Vec<f64>>(),
            "unit": unit,
            "phase": {"index": v.phase.index, "count": v.phase.count},
            "segments": v.segments.iter().map(|k| json!({
                "number": k.number,
                "label": k.label,
                "colour": k.colour,
                "category": code_json(&k.terms.category),
                "type": code_json(&k.terms.kind),
                "modifier": code_json(&k.terms.modifier),
                "region": code_json(&k.terms.region),
                "region_modifier": code_json(&k.terms.region_modifier),
            })).collect::<Vec<_>>(),
            "warnings": v.warnings,
        });
        if let Some(labels) = &labels {
            out["labels"] = labels
                .iter()
                .map(|(l, n, ml, name)| {
                    json!({"value": l, "voxels": n, "ml": (ml * 1e3).round() / 1e3, "name": name})
                })
                .collect();
        }
        out["hu_range"] = match (v.unit, range) {
            (raystream_io::ValueUnit::Hounsfield, Some((lo, hi))) => json!([lo, hi]),
            _ => serde_json::Value::Null,
        };
        out["value_range"] = match range {
            Some((lo, hi)) => json!([lo, hi]),
            None => serde_json::Value::Null,
        };
        out["default_surface"] = json!(surface);
        if let Some(s) = series {
            out["series"] = s;
        }
        if let Some(w) = &stats {
            let hu = v.unit == raystream_io::ValueUnit::Hounsfield;
            let with = |r: &SegmentStats, key: &str, value: serde_json::Value| {
                let inflation = w.adjusted.as_ref().and_then(|a| a.of(&r.labels));
                let mut j = r.json(hu, inflation);
                j[key] = value;
                j
            };
            out["segmentation"] = json!({
                "file": a.segmentation.as_deref().map(file_name),
                "matched_on": w.how,
                "segments": (w.segments.iter())
                    .map(|r| with(r, "value", json!(r.labels[0])))
                    .collect::<Vec<_>>(),
                "combined": (w.combined.iter())
                    .map(|r| with(r, "segments", json!(r.labels)))
                    .collect::<Vec<_>>(),
                "below_mask": w.below_mask.as_ref().map(|(file, segments)| json!({
                    "file": file,
                    "hu": a.below[0],
                    "segments": segments,
                })),
                "agatston_mask": w.agatston_mask.as_ref().map(|(file, segments)| json!({
                    "file": file,
                    "segments": segments,
                })),
                "agatston": a.agatston.then(|| {
                    let (pixel_mm2, slice_mm) = raystream_volume::calcium::slice_geometry(&v);
                    json!({
                        "threshold_hu": raystream_volume::calcium::THRESHOLD_HU,
                        "min_area_mm2": raystream_volume::calcium::MIN_AREA_MM2,
                        "connectivity": "8 within each slice",
                        "pixel_mm2": pixel_mm2,
                        "slice_mm": slice_mm,
                        "slice_factor": slice_mm / raystream_volume::calcium::SLICE_MM,
                    })
                }),
                "adjusted_to": w.adjusted.as_ref().map(|adj| json!({
                    "region": adj.region,
                    "segments": adj.labels,
                    "measured_ml": adj.inflation.measured_ml,
                    "reference_ml": adj.inflation.reference_ml,
                    "reference": match adj.to {
                        crate::cli::AdjustTo::Ml(_) => json!("given"),
                        crate::cli::AdjustTo::Tlc { sex, height_cm } => json!({
                            "predicted_tlc": {
                                "sex": match sex {
                                    raystream_volume::Sex::Male => "male",
                                    raystream_volume::Sex::Female => "female",
                                },
                                "height_cm": height_cm,
                                "equations": "ECSC/ERS 1993 (Quanjer)",
                            },
                        }),
                    },
                    "factor": adj.inflation.factor(),
                    "model": "sponge: mass held, HU + 1000 scaled by measured / reference",
                })),
            });
        }
        if let Some(b) = &body {
            out["body"] = body_json(b);
        }
        if let Some(set) = &structures {
            out["structure_set"] = json!({
                "label": set.label,
                "frame_of_reference_uid": set.frame_of_reference_uid,
                "referenced_series": set.referenced_series,
                "structures": set.rois.iter().map(|r| json!({
                    "number": r.number,
                    "name": r.name,
                    "kind": r.kind,
                    "colour": r.colour,
                    "contours": r.contours.len(),
                    "other_contours": r.other_contours,
                })).collect::<Vec<_>>(),
            });
        }
        print_line(out);
    } else {
        println!("{}: {} volume", input.display(), v.format.name());
        println!(
            "  dims       {} x {} x {} voxels",
            v.dims[0], v.dims[1], v.dims[2]
        );
        println!("  spacing    {:?} mm", v.spacing);
        println!("  origin     {:?} mm (LPS)", v.origin);
        println!(
            "  direction  {:?} (columns: i, j, k axes in LPS)",
            v.direction
        );
        match range {
            Some((lo, hi)) => println!("  values     {lo} .. {hi} ({unit})"),
            None => println!("  values     all NaN"),
        }
        if let Some(t) = surface {
            println!(
                "  surface    at {t}, the values' Otsu threshold (render's and iso's, unless --iso V)"
            );
        }
        for (l, n, ml, name) in labels.iter().flatten() {
            let name = if name.is_empty() {
                String::new()
            } else {
                format!(" ({name})")
            };
            println!("  label      {l}{name}: {n} voxels, {ml:.1} ml");
        }
        if v.phase.count > 1 {
            println!(
                "  phase      {} of {} (temporal positions; --phase K reads another)",
                v.phase.index, v.phase.count
            );
        }
        if let Some(s) = &v.series {
            // Some files carry no SeriesInstanceUID; their slices form one series with an
            // empty one.
            let uid = |u: &str| {
                if u.is_empty() {
                    "(no SeriesInstanceUID)".to_string()
                } else {
                    u.to_string()
                }
            };
            // A Segmentation's count is its frames (a segment and slice each).
            let what = if v.segments.is_empty() {
                "slices"
            } else if structures.is_some() {
                "file"
            } else {
                "frames"
            };
            println!(
                "  series     {} ({} {what}, {}, {} {})",
                uid(&s.uid),
                s.count,
                s.modality,
                s.transfer_syntax,
                s.transfer_syntax_name
            );
            for (u, n, d) in s.all.iter().filter(|(u, _, _)| *u != s.uid) {
                println!("  also       {} ({n} slices) {d}", uid(u));
            }
        }
        for k in &v.segments {
            let colour = k
                .colour
                .map(|[r, g, b]| format!(", shown in #{r:02x}{g:02x}{b:02x}"))
                .unwrap_or_default()
                + &terms_text(&k.terms);
            let roi = structures
                .as_ref()
                .and_then(|set| set.rois.iter().find(|r| r.number == k.number));
            match roi {
                Some(r) => println!(
                    "  structure  {n}: {} ({}{} closed contours{colour})",
                    k.label,
                    if r.kind.is_empty() {
                        String::new()
                    } else {
                        format!("{}, ", r.kind)
                    },
                    r.contours.len(),
                    n = k.number
                ),
                None => println!(
                    "  segment    {n}: {} (the voxels of value {n}{colour})",
                    k.label,
                    n = k.number
                ),
            }
        }
        if let Some(w) = &stats {
            println!(
                "  within     {} (matched on {}):",
                a.segmentation.as_deref().unwrap_or(input).display(),
                w.how
            );
            let inflation = |labels: &[u32]| w.adjusted.as_ref().and_then(|a| a.of(labels));
            if a.agatston {
                let (pixel_mm2, slice_mm) = raystream_volume::calcium::slice_geometry(&v);
                println!(
                    "  agatston   lesions from {} HU and {} mm² within each slice (pixels {pixel_mm2:.3} mm², joined at edges and corners); slices {slice_mm:.2} mm apart, weighted {:.3} (Agatston's 3 mm)",
                    raystream_volume::calcium::THRESHOLD_HU,
                    raystream_volume::calcium::MIN_AREA_MM2,
                    slice_mm / raystream_volume::calcium::SLICE_MM
                );
            }
            if let Some(adj) = &w.adjusted {
                let (region, at) = (&adj.region, &adj.inflation);
                let reference = match adj.to {
                    crate::cli::AdjustTo::Ml(_) => "given".to_string(),
                    crate::cli::AdjustTo::Tlc { sex, height_cm } => format!(
                        "the total lung capacity predicted for a {} of {height_cm} cm, ECSC/ERS 1993",
                        match sex {
                            raystream_volume::Sex::Male => "man",
                            raystream_volume::Sex::Female => "woman",
                        }
                    ),
                };
                println!(
                    "  adjusting  to {:.1} ml ({reference}): {region}: {:.1} ml, factor {:.4}; the sponge model, mass held",
                    at.reference_ml,
                    at.measured_ml,
                    at.factor()
                );
            }
            for r in &w.segments {
                let head = match r.name.is_empty() {
                    true => format!("{}", r.labels[0]),
                    false => format!("{} ({})", r.labels[0], r.name),
                };
                r.print("segment", &head, unit, inflation(&r.labels));
            }
            for r in &w.combined {
                let list: Vec<String> = r.labels.iter().map(|l| l.to_string()).collect();
                let head = format!("{} (segments {})", r.name, list.join(", "));
                r.print("combined", &head, unit, inflation(&r.labels));
            }
            if let Some((file, segments)) = &w.below_mask {
                println!(
                    "  wrote      {file}: the voxels below {} {unit} of {segments} segments, a NIfTI label map",
                    a.below[0]
                );
            }
            if let Some((file, segments)) = &w.agatston_mask {
                println!(
                    "  wrote      {file}: the calcium lesions counted of {segments} segments, a NIfTI label map"
                );
            }
        }
        if let Some(b) = &body {
            body_lines(b);
        }
        for w in &v.warnings {
            println!("  warning    {w}");
        }
    }
    Ok(())
}

/// A percentile in words: "15th", "1st", "22nd", "2.5th".
fn ordinal(p: f64) -> String {
    if p.fract() != 0.0 {
        return format!("{p}th");
    }
    let n = p as u64;
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// `--body`: what was found, and what `--mask` and `--structures` wrote.
struct BodyInfo {
    body: raystream_volume::body::Body,
    ms: f64,
    voxel_ml: f64,
    tissues: raystream_volume::body::Tissues,
    stats: raystream_volume::RegionStats,
    /// `--mask`: the file, and its frames if a DICOM Segmentation.
    mask: Option<(String, String)>,
    /// `--structures`: the file, and the body's contours.
    structures: Option<(String, usize)>,
}

/// `--body`: the body in `v` (read from `input`), its tissues and HU, and the files
/// `--mask` and `--structures` name, written.
fn body_info(a: &InfoArgs, v: &raystream_io::Volume, input: &std::path::Path) -> Result<BodyInfo> {
    let (body, ms) = crate::body::find_timed(v, input, "--body", a.json)?;
    let tissues = body.tissues(v);
    let members: Vec<usize> = (0..body.inside.len()).filter(|&n| body.inside[n]).collect();
    let stats = raystream_volume::region_stats(v, &members)
        .ok_or_else(|| anyhow::anyhow!("{}: --body: no finite value inside", input.display()))?;
    drop(members);
    // Label 1 on the CT's grid, for the files alone.
    let labels: Vec<u8> = match a.mask.is_some() || a.structures.is_some() {
        true => body.inside.iter().map(|&b| u8::from(b)).collect(),
        false => Vec::new(),
    };
    let segments = [raystream_io::Segment {
        value: 1,
        label: "Body",
        description: "The patient's body and what it encloses, the table and devices left out",
        category: raystream_io::Code {
            value: "123037004",
            scheme: "SCT",
            meaning: "Anatomical Structure",
        },
        kind: raystream_io::Code {
            value: "38266002",
            scheme: "SCT",
            meaning: "Entire body as a whole",
        },
        colour: [177, 122, 101],
        rt_type: "EXTERNAL",
    }];
    let info = raystream_io::SegmentationInfo {
        description: "raystream info --body: the patient's body",
        algorithm: "raystream body",
        version: env!("CARGO_PKG_VERSION"),
    };
    let mask = match &a.mask {
        Some(out) => {
            let what = "raystream info --body: 1 the body";
            let written = crate::mask_out::write_mask(out, v, &labels, &segments, (&info, what))?;
            let kind = crate::mask_out::mask_kind(out, written.map(|w| w.frames));
            Some((out.display().to_string(), kind))
        }
        None => None,
    };
    let structures = match &a.structures {
        Some(out) => {
            let written = raystream_io::write_structure_set(out, v, &labels, &segments, &info)?;
            Some((out.display().to_string(), written.contours[0]))
        }
        None => None,
    };
    Ok(BodyInfo {
        body,
        ms,
        voxel_ml: v.voxel_ml(),
        tissues,
        stats,
        mask,
        structures,
    })
}

/// The tissues of [`BodyInfo`]: each range's name, HU and voxels.
fn tissue_rows(t: &raystream_volume::body::Tissues) -> [(&'static str, &'static str, usize); 4] {
    [
        ("air", "below -190 HU: air, gas, lung", t.air),
        ("fat", "-190 to -30 HU: fat", t.fat),
        ("soft", "-29 to 150 HU: soft tissue", t.soft),
        ("dense", "above 150 HU: bone, contrast", t.dense),
    ]
}

/// `info --body`'s lines.
fn body_lines(b: &BodyInfo) {
    println!(
        "  body       {} (found in {:.0} ms)",
        crate::body::words(&b.body, b.voxel_ml).trim_start_matches("the body, "),
        b.ms
    );
    let s = &b.stats;
    let [x, y, z] = s.centroid;
    println!(
        "  body HU    mean {:.1}, sd {:.1}, median {}; centroid ({x:.1}, {y:.1}, {z:.1}) mm LPS",
        s.mean, s.sd, s.median
    );
    let rows: Vec<String> = tissue_rows(&b.tissues)
        .iter()
        .map(|(_, what, n)| {
            format!(
                "{what} {:.2} l ({:.1} %)",
                *n as f64 * b.voxel_ml / 1000.0,
                100.0 * *n as f64 / b.body.voxels.max(1) as f64
            )
        })
        .collect();
    println!("  tissues    {}", rows.join("; "));
    if let Some((file, kind)) = &b.mask {
        println!(
            "  mask       {file} ({kind}): label 1 the body on {} voxels",
            b.body.voxels
        );
    }
    if let Some((file, contours)) = &b.structures {
        println!(
            "  structures {file} (a DICOM RT Structure Set of the CT's series): Body, EXTERNAL, {contours} closed contours"
        );
    }
}

/// `info --body --json`'s `body`.
fn body_json(b: &BodyInfo) -> serde_json::Value {
    let ml = |n: usize| (n as f64 * b.voxel_ml * 1e3).round() / 1e3;
    let s = &b.stats;
    let mut tissues = json!({});
    for (name, _, n) in tissue_rows(&b.tissues) {
        tissues[name] = json!(ml(n));
    }
    json!({
        "voxels": b.body.voxels,
        "ml": ml(b.body.voxels),
        "left_out_ml": b.body.left_out_ml,
        "thin_parts": b.body.thin_parts,
        "thin_part_ml": b.body.thin_part_ml,
        "cut_slices": b.body.cut_slices,
        "border_tissue_ml": b.body.border_tissue_ml,
        "tissues_ml": tissues,
        "mean": s.mean,
        "sd": s.sd,
        "median": s.median,
        "centroid": s.centroid,
        "ms": b.ms,
        "mask": b.mask.as_ref().map(|(file, kind)| json!({"file": file, "kind": kind})),
        "structures": b.structures.as_ref().map(|(file, contours)| json!({"file": file, "contours": contours})),
    })
}

/// `info --gpu`: the adapters, in the order `--device gpu` prefers them (it opens the first).
fn gpu_info(json: bool) {
    let adapters = raystream_gpu::list_adapters();
    if json {
        let list: Vec<serde_json::Value> = adapters
            .iter()
            .map(|a| {
                json!({
                    "name": a.info.name,
                    "backend": format!("{:?}", a.info.backend),
                    "device_type": format!("{:?}", a.info.device_type),
                    "driver": a.info.driver,
                    "driver_info": a.info.driver_info,
                    "timestamps": a.timestamps,
                    "subgroups": a.subgroups,
                    "subgroup_sizes": [a.info.subgroup_min_size, a.info.subgroup_max_size],
                    "f64": a.f64,
                    "max_storage_binding": a.max_storage_binding,
                    "max_buffer": a.max_buffer,
                    "max_workgroups_per_dimension": a.max_workgroups_per_dimension,
                })
            })
            .collect();
        print_line(json!({ "kind": "gpu", "adapters": list }));
        return;
    }
    if adapters.is_empty() {
        println!(
            "no GPU adapter: no Vulkan, Metal or DX12 driver answered (without a GPU, Mesa's lavapipe gives a software one)"
        );
        return;
    }
    for (k, a) in adapters.iter().enumerate() {
        println!(
            "{}{} ({:?}, {:?}, {} {})",
            if k == 0 { "* " } else { "  " },
            a.info.name,
            a.info.backend,
            a.info.device_type,
            a.info.driver,
            a.info.driver_info
        );
        println!(
            "    timestamps {}, subgroups {} ({}–{} lanes), f64 {}, storage binding up to {} MiB, buffers up to {} MiB",
            if a.timestamps { "yes" } else { "no" },
            if a.subgroups { "yes" } else { "no" },
            a.info.subgroup_min_size,
            a.info.subgroup_max_size,
            if a.f64 {
                "yes"
            } else {
                "no (huge triangles' planes in f32)"
            },
            a.max_storage_binding >> 20,
            a.max_buffer >> 20
        );
    }
    println!("(* the adapter --device gpu opens; --adapter SUBSTRING picks another)");
}

/// A coded concept as JSON (`null` where there is none).
fn code_json(c: &Option<raystream_io::ReadCode>) -> serde_json::Value {
    c.as_ref().map_or(
        serde_json::Value::Null,
        |c| json!({"value": c.value, "scheme": c.scheme, "meaning": c.meaning}),
    )
}

/// What a segment is coded as, for `info`'s line: `; coded Lung, Right (SCT 39607008), in
/// Anatomical Structure` (its type, then its category), with `, site Kidney, Right (SCT
/// 64033007)` after the type where it names the region it lies in; empty where the file codes
/// nothing.
fn terms_text(t: &raystream_io::SegmentTerms) -> String {
    let Some(kind) = &t.kind else {
        return String::new();
    };
    let with_modifier = |c: &raystream_io::ReadCode, m: &Option<raystream_io::ReadCode>| {
        let m = m
            .as_ref()
            .map(|m| format!(", {}", m.meaning))
            .unwrap_or_default();
        format!("{}{m} ({} {})", c.meaning, c.scheme, c.value)
    };
    let category = t
        .category
        .as_ref()
        .map(|c| format!(", in {}", c.meaning))
        .unwrap_or_default();
    let region = t
        .region
        .as_ref()
        .map(|r| format!(", site {}", with_modifier(r, &t.region_modifier)))
        .unwrap_or_default();
    format!(
        "; coded {}{region}{category}",
        with_modifier(kind, &t.modifier)
    )
}

/// A DICOM Structured Report's measurement groups (`measure --report`'s, or another tool's
/// TID 1500 report), each with its finding and measurements.
fn report_info(a: &InfoArgs, input: &std::path::Path) -> Result<()> {
    use raystream_io::ReadCode;
    let r = raystream_io::read_measurement_report(input)?;
    let code = code_json;
    let value = |c: &Option<ReadCode>| c.as_ref().map(|c| c.value.clone());
    if a.json {
        let groups: Vec<serde_json::Value> = r
            .groups
            .iter()
            .map(|g| {
                json!({
                    "template": g.template,
                    "tracking_id": g.tracking_id,
                    "finding": code(&g.finding),
                    "finding_site": code(&g.finding_site),
                    "region": g.region.as_ref().map(|(t, n)| json!({"type": t, "points": n})),
                    "segment": g.segment,
                    "measurements": g.measurements.iter().map(|m| json!({
                        "concept": m.concept.value,
                        "name": m.concept.meaning,
                        "value": m.value,
                        "unit": m.unit.value,
                        "derivation": value(&m.derivation),
                        "method": value(&m.method),
                        "region": m.region.as_ref().map(|(t, n)| json!({"type": t, "points": n})),
                    })).collect::<Vec<_>>(),
                    "evaluations": g.evaluations.iter().map(|(n, v)| json!({
                        "name": n.meaning, "value": v.meaning,
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        print_line(json!({
            "kind": "report",
            "file": file_name(input),
            "sop_class": r.sop_class,
            "title": r.title.meaning,
            "template": r.template,
            "completion": r.completion,
            "verification": r.verification,
            "observers": r.observers,
            "groups": groups,
        }));
        return Ok(());
    }
    let template = |t: &Option<String>| t.as_ref().map_or(String::new(), |t| format!(" (TID {t})"));
    let mut t = format!(
        "{}: DICOM Structured Report, {}{}, {}, {}\n",
        file_name(input),
        r.title.meaning,
        template(&r.template),
        r.completion,
        r.verification
    );
    for o in &r.observers {
        t += &format!("  observer   {o}\n");
    }
    for (k, g) in r.groups.iter().enumerate() {
        let name = g
            .tracking_id
            .as_deref()
            .unwrap_or("(no tracking identifier)");
        let mut what: Vec<String> = g.finding.iter().map(|c| c.meaning.clone()).collect();
        what.extend(g.finding_site.iter().map(|c| format!("in {}", c.meaning)));
        what.extend(g.segment.map(|s| format!("segment {s}")));
        what.extend(
            g.region
                .as_ref()
                .map(|(t, n)| format!("a {t} of {n} points")),
        );
        t += &format!(
            "  group {:<4} {name}{}: {}\n",
            k + 1,
            template(&g.template),
            what.join(", ")
        );
        for m in &g.measurements {
            let unit = match m.unit.value.as_str() {
                "1" | "" => String::new(),
                u => format!(" {u}"),
            };
            let derivation = m
                .derivation
                .as_ref()
                .map_or(String::new(), |d| format!(" ({})", d.meaning));
            let method = m
                .method
                .as_ref()
                .map_or(String::new(), |d| format!(" [{}]", d.meaning));
            t += &format!(
                "             {}{derivation}: {}{unit}{method}\n",
                m.concept.meaning, m.value
            );
        }
        for (n, v) in &g.evaluations {
            t += &format!("             {}: {}\n", n.meaning, v.meaning);
        }
    }
    if r.groups.is_empty() {
        t += "  no measurement groups\n";
    }
    print_line(t.trim_end());
    Ok(())
}
