//! `raystream trace`: Embree-style ray streams from RAYS.bin to HITS.bin.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use raystream_accel::{Hit, KdTree, Traversal};
use raystream_math::Ray;
use serde_json::json;

use crate::cli::TraceArgs;
use crate::common::{cpu_model, file_name, load_mesh, median, ms, resolve_device, round3, spinner};

pub const RAY_BYTES: usize = 32;
pub const NO_PRIM: u32 = u32::MAX;

/// One record of HITS.bin.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct HitRecord {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

impl From<Option<Hit>> for HitRecord {
    fn from(h: Option<Hit>) -> Self {
        match h {
            Some(h) => HitRecord {
                t: h.t,
                prim: h.prim,
                u: h.u,
                v: h.v,
            },
            None => HitRecord {
                t: f32::INFINITY,
                prim: NO_PRIM,
                u: 0.0,
                v: 0.0,
            },
        }
    }
}

pub fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    let bytes =
        std::fs::read(path).with_context(|| format!("{}: cannot read rays", path.display()))?;
    if bytes.len() % RAY_BYTES != 0 {
        bail!(
            "{}: {} bytes is not a multiple of {RAY_BYTES} (8 float32 per ray)",
            path.display(),
            bytes.len()
        );
    }
    Ok(bytes
        .chunks_exact(RAY_BYTES)
        .map(|c| {
            let mut a = [0f32; 8];
            for (k, f) in a.iter_mut().enumerate() {
                *f = f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap());
            }
            Ray::from_array(a)
        })
        .collect())
}

/// Traces all rays in parallel.
pub fn trace_all(tree: &KdTree, rays: &[Ray], any: bool, traversal: Traversal) -> Vec<HitRecord> {
    rays.par_iter()
        .with_min_len(1024)
        .map(|r| {
            if any {
                tree.intersect_any(r, traversal)
            } else {
                tree.intersect(r, traversal)
            }
            .into()
        })
        .collect()
}

pub fn run(a: &TraceArgs) -> Result<()> {
    let device = resolve_device(a.accel.device, a.quiet || a.json)?;
    let mesh = load_mesh(&a.mesh)?;
    let rays = read_rays(&a.rays)?;
    let pb = spinner(
        a.quiet || a.json,
        &format!("building kd-tree over {} triangles", mesh.len()),
    );
    let tree = KdTree::build(&mesh, a.accel.builder.into());
    pb.set_message(format!("tracing {} rays", rays.len()));
    let traversal: Traversal = a.accel.traversal.into();
    let mut hits = trace_all(&tree, &rays, a.any, traversal); // warm-up
    let mut times = Vec::new();
    for _ in 0..a.repeat {
        let t0 = Instant::now();
        hits = trace_all(&tree, &rays, a.any, traversal);
        times.push(ms(t0.elapsed()));
    }
    pb.finish_and_clear();
    let bytes: &[u8] = bytemuck::cast_slice(&hits);
    // HITS.bin is little-endian; so is every target raystream builds for.
    const _: () = assert!(cfg!(target_endian = "little"));
    std::fs::write(&a.output, bytes)
        .with_context(|| format!("{}: cannot write hits", a.output.display()))?;
    let trace_ms_min = times.iter().cloned().fold(f64::INFINITY, f64::min);
    let trace_ms = median(&mut times);
    let n_hits = hits
        .iter()
        .filter(|h| h.prim != NO_PRIM || (a.any && h.t.is_finite()))
        .count();
    let mrays = rays.len() as f64 / (trace_ms * 1e-3) / 1e6;
    if a.json {
        println!(
            "{}",
            json!({
                "device": device,
                "adapter": cpu_model(),
                "mesh": file_name(&a.mesh),
                "triangles": mesh.len(),
                "rays": rays.len(),
                "query": if a.any { "any" } else { "closest" },
                "builder": tree.stats.builder,
                "traversal": traversal.name(),
                "build_ms": round3(tree.stats.build_ms),
                "upload_ms": 0.0,
                "trace_ms": round3(trace_ms),
                "trace_ms_min": round3(trace_ms_min),
                "mrays_per_s": round3(mrays),
                "hits": n_hits,
            })
        );
    } else if !a.quiet {
        eprintln!(
            "raystream: {} rays, {} hits, build {:.1} ms, trace {:.1} ms ({:.2} Mrays/s) on {device}",
            rays.len(),
            n_hits,
            tree.stats.build_ms,
            trace_ms,
            mrays
        );
    }
    Ok(())
}
