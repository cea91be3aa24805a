//! `raystream info`: a mesh's size and bounds and its kd-tree statistics.

use anyhow::Result;
use raystream_accel::{KdTree, TreeStats};
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
        "mean_tris_per_leaf": round3(s.mean_tris_per_leaf),
        "references": s.references,
        "build_ms": round3(s.build_ms),
    })
}

pub fn run(a: &InfoArgs) -> Result<()> {
    let mesh = load_mesh(&a.input)?;
    let tree = KdTree::build(&mesh, a.builder.into());
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
