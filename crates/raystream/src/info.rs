//! `raystream info`: a mesh's size and bounds and its kd-tree statistics, or a volume's geometry
//! (dims, spacing in mm, LPS origin and direction), value range and, for DICOM, its series.

use anyhow::Result;
use raystream_accel::TreeStats;
use serde_json::json;

use crate::cli::InfoArgs;
use crate::common::{file_name, load_mesh, print_line, round3};

pub fn tree_json(s: &TreeStats) -> serde_json::Value {
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
    })
}

pub fn run(a: &InfoArgs) -> Result<()> {
    if raystream_io::is_volume_path(&a.input) {
        return volume_info(a);
    }
    let mesh = load_mesh(&a.input)?;
    let tree = a.tree.build(&mesh);
    let b = mesh.bounds();
    let s = &tree.stats;
    if a.json {
        let v = json!({
            "kind": "mesh",
            "file": file_name(&a.input),
            "vertices": mesh.positions.len(),
            "triangles": mesh.len(),
            "degenerate_triangles": mesh.len() - s.triangles,
            "bounds": [b.min.to_array(), b.max.to_array()],
            "kdtree": tree_json(s),
        });
        print_line(v);
    } else {
        println!("{}: triangle mesh", a.input.display());
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
    }
    Ok(())
}

fn volume_info(a: &InfoArgs) -> Result<()> {
    let v = raystream_io::load_volume(&a.input, a.series.as_deref())?;
    let range = v.value_range();
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
            "file": file_name(&a.input),
            "format": v.format.name(),
            "dims": v.dims,
            "spacing": v.spacing,
            "origin": v.origin,
            "direction": v.direction.concat().iter().map(|d| d + 0.0).collect::<Vec<f64>>(),
            "unit": unit,
            "warnings": v.warnings,
        });
        out["hu_range"] = match (v.unit, range) {
            (raystream_io::ValueUnit::Hounsfield, Some((lo, hi))) => json!([lo, hi]),
            _ => serde_json::Value::Null,
        };
        out["value_range"] = match range {
            Some((lo, hi)) => json!([lo, hi]),
            None => serde_json::Value::Null,
        };
        if let Some(s) = series {
            out["series"] = s;
        }
        print_line(out);
    } else {
        println!("{}: {} volume", a.input.display(), v.format.name());
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
        if let Some(s) = &v.series {
            println!(
                "  series     {} ({} slices, {}, {} {})",
                s.uid, s.count, s.modality, s.transfer_syntax, s.transfer_syntax_name
            );
            for (u, n, d) in s.all.iter().filter(|(u, _, _)| *u != s.uid) {
                println!("  also       {u} ({n} slices) {d}");
            }
        }
        for w in &v.warnings {
            println!("  warning    {w}");
        }
    }
    Ok(())
}
