//! `raystream trace`: Embree-style ray streams from RAYS.bin to HITS.bin.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use raystream_accel::{Hit, Isa, KdTree, Traversal};
use raystream_math::Ray;
use serde_json::json;

use crate::cli::TraceArgs;
use raystream_gpu::{GpuTracer, Kernels, QueryStats};

use crate::common::{
    Backend, file_name, gpu_tracer, load_mesh, median, ms, open_device, print_line, round3, spinner,
};

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

/// Writes rays in the RAYS.bin layout (8 little-endian f32 per ray).
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<()> {
    let bytes: Vec<u8> = rays
        .iter()
        .flat_map(|r| r.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    std::fs::write(path, bytes).with_context(|| format!("{}: cannot write rays", path.display()))
}

/// Traces all rays in parallel.
pub fn trace_all(tree: &KdTree, rays: &[Ray], any: bool, traversal: Traversal) -> Vec<HitRecord> {
    tree.intersect_all(rays, traversal, any)
        .into_iter()
        .map(HitRecord::from)
        .collect()
}

/// Hits and timings of one traced ray set on either back-end.
pub struct Traced {
    pub hits: Vec<HitRecord>,
    pub build_ms: f64,
    pub upload_ms: f64,
    /// Median and minimum over the timed repeats (traversal and intersection only).
    pub trace_ms: f64,
    pub trace_ms_min: f64,
    /// GPU only, where the adapter has timestamp queries: median kernel time between the
    /// compute pass's timestamps.
    pub kernel_gpu_ms: Option<f64>,
    /// GPU only, not for split kernels: wall time per query of `repeat` queries queued in one
    /// submission and waited for once (a stream of queries: no host round trip between them).
    pub stream_ms: Option<f64>,
    /// GPU split kernels only: leaf steps with rays in them (the longest walk's leaves).
    pub split_steps: Option<u32>,
    /// GPU only: the median round trip of an empty submission (`repeat` of them), the floor
    /// under `trace_ms` that no kernel can lower.
    pub round_trip_ms: Option<f64>,
    /// GPU only: the median wall time of `repeat` queries run without timestamp queries, each
    /// after a timed one (`trace_ms`'s queries write, resolve and read back two timestamps).
    pub untimed_ms: Option<f64>,
}

/// Untimed GPU runs before the timed ones: until this much time has passed…
const GPU_WARM_UP: std::time::Duration = std::time::Duration::from_millis(200);
/// …or this many runs (the first included).
const GPU_WARM_UP_RUNS: u32 = 50;

/// Traces `rays` to warm up (once on the CPU; on a GPU for [`GPU_WARM_UP`], at most
/// [`GPU_WARM_UP_RUNS`] runs) and `repeat` times timed, on the CPU or, with `gpu` (the tracer
/// of `tree`), on the GPU.
pub fn trace_timed(
    gpu: Option<&GpuTracer>,
    tree: &KdTree,
    rays: &[Ray],
    any: bool,
    traversal: Traversal,
    kernels: Kernels,
    repeat: u32,
) -> Result<Traced> {
    let mut times = Vec::new();
    let mut gpu_times = Vec::new();
    let mut stream_ms = None;
    let mut split_steps = None;
    let mut round_trip_ms = None;
    let mut untimed = Vec::new();
    let (hits, upload_ms) = match gpu {
        None => {
            // The answers' memory is kept from query to query, as a renderer keeps its
            // queues: a timed query is the traversal and intersection, not the kernel's
            // faulting in and zeroing fresh pages for them, nor their conversion to records.
            let mut found = Vec::new();
            tree.intersect_all_into(rays, traversal, any, &mut found);
            for _ in 0..repeat {
                let t0 = Instant::now();
                tree.intersect_all_into(rays, traversal, any, &mut found);
                times.push(ms(t0.elapsed()));
            }
            (found.into_iter().map(HitRecord::from).collect(), 0.0)
        }
        Some(tracer) => {
            if traversal != Traversal::Ropes {
                bail!("--device gpu runs the rope traversal only (--traversal ropes)");
            }
            let warm_up = Instant::now();
            let (mut hits, first) = tracer.trace_with(rays, any, kernels)?;
            split_steps = first.split_steps;
            // A GPU left idle (while the CPU built the tree or generated rays) runs at low
            // clocks; keep it busy for a while before timing, as GPU benchmarks do.
            for _ in 1..GPU_WARM_UP_RUNS {
                if warm_up.elapsed() >= GPU_WARM_UP {
                    break;
                }
                tracer.trace_with(rays, any, kernels)?;
            }
            for _ in 0..repeat {
                let (h, t) = tracer.trace_with(rays, any, kernels)?;
                hits = h;
                times.push(t.kernel_ms);
                gpu_times.extend(t.kernel_gpu_ms);
                // The same query untimed, right after: what the timestamps cost the wall.
                let (h, t) = tracer.trace_untimed(rays, any, kernels)?;
                if h != hits {
                    bail!(
                        "{} rays: an untimed query's hits differ from a timed one's",
                        rays.len()
                    );
                }
                untimed.push(t.kernel_ms);
            }
            if let Some((h, ms)) = tracer.trace_streamed(rays, any, kernels, repeat)? {
                if h != hits {
                    bail!(
                        "{} rays: the streamed queries' hits differ from a lone query's",
                        rays.len()
                    );
                }
                stream_ms = Some(ms);
            }
            let mut trips = (0..repeat.max(1))
                .map(|_| tracer.context().round_trip_ms())
                .collect::<Result<Vec<_>, _>>()?;
            round_trip_ms = Some(median(&mut trips));
            let records = hits
                .iter()
                .map(|h| HitRecord {
                    t: h.t,
                    prim: h.prim,
                    u: h.u,
                    v: h.v,
                })
                .collect();
            (records, tracer.upload_ms + first.upload_ms)
        }
    };
    let trace_ms_min = times.iter().cloned().fold(f64::INFINITY, f64::min);
    let kernel_gpu_ms = (!gpu_times.is_empty()).then(|| median(&mut gpu_times));
    Ok(Traced {
        hits,
        build_ms: tree.stats.build_ms,
        upload_ms,
        trace_ms: median(&mut times),
        trace_ms_min,
        kernel_gpu_ms,
        stream_ms,
        split_steps,
        round_trip_ms,
        untimed_ms: (!untimed.is_empty()).then(|| median(&mut untimed)),
    })
}

/// A GPU query's own count of its work: steps per ray and SIMD efficiency, by kind of step, and
/// the most invocations (and subgroups) the GPU held at once.
pub fn gpu_stats_json(s: &QueryStats) -> serde_json::Value {
    let per_kind = |f: &dyn Fn(usize) -> f64| -> serde_json::Value {
        QueryStats::KINDS
            .iter()
            .enumerate()
            .map(|(k, name)| (name.to_string(), json!(round3(f(k)))))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    json!({
        "steps_per_ray": per_kind(&|k| s.per_ray(k)),
        "simd_efficiency": per_kind(&|k| s.simd_efficiency(k)),
        "subgroup_size": s.subgroup_size,
        "peak_resident_invocations": s.peak_resident,
        "peak_resident_subgroups": round3(s.peak_resident_subgroups()),
    })
}

pub fn kernels_name(k: Kernels) -> &'static str {
    match k {
        Kernels::Fused => "fused",
        Kernels::Split => "split",
        Kernels::Persistent => "persistent",
        Kernels::IfIf => "ifif",
        Kernels::Floor => "floor",
    }
}

pub fn run(a: &TraceArgs) -> Result<()> {
    let quiet = a.quiet || a.json;
    let backend = open_device(a.accel.device, a.accel.adapter.as_deref(), quiet)?;
    let mesh = load_mesh(&a.mesh)?;
    let rays = read_rays(&a.rays)?;
    let pb = spinner(
        quiet,
        &format!("building kd-tree over {} triangles", mesh.len()),
    );
    let tree = a.accel.tree.build(&mesh);
    pb.set_message(format!("tracing {} rays on {}", rays.len(), backend.name()));
    let traversal: Traversal = a.accel.traversal.into();
    let gpu = gpu_tracer(&backend, &tree, &a.mesh)?;
    let t = trace_timed(
        gpu.as_ref(),
        &tree,
        &rays,
        a.any,
        traversal,
        a.kernels.into(),
        a.repeat,
    )?;
    let stats = match (&gpu, a.stats) {
        (_, false) => None,
        (None, true) => bail!("--stats counts a GPU kernel's work: add --device gpu"),
        (Some(tracer), true) => {
            let Some(s) = tracer.query_stats_with(&rays, a.any, a.kernels.into())? else {
                bail!(
                    "--stats: '{}' has no subgroup operations, or --kernels {} has no statistics (fused and ifif have)",
                    backend.adapter(),
                    kernels_name(a.kernels.into())
                );
            };
            Some(s)
        }
    };
    // With --stats, the floor under the query's times on these rays (`Kernels::Floor`): what
    // of them is the dispatch, its memory traffic and the round trip, not the traversal.
    let floor = match (&gpu, &stats) {
        (Some(tracer), Some(_)) => Some(trace_timed(
            Some(tracer),
            &tree,
            &rays,
            a.any,
            traversal,
            Kernels::Floor,
            a.repeat,
        )?),
        _ => None,
    };
    pb.finish_and_clear();
    let bytes: &[u8] = bytemuck::cast_slice(&t.hits);
    // HITS.bin is little-endian; so is every target raystream builds for.
    const _: () = assert!(cfg!(target_endian = "little"));
    std::fs::write(&a.output, bytes)
        .with_context(|| format!("{}: cannot write hits", a.output.display()))?;
    let n_hits = t.hits.iter().filter(|h| h.t.is_finite()).count();
    let mrays = rays.len() as f64 / (t.trace_ms * 1e-3) / 1e6;
    if a.json {
        print_line(json!({
            "device": backend.name(),
            "adapter": backend.adapter(),
            "mesh": file_name(&a.mesh),
            "triangles": mesh.len(),
            "rays": rays.len(),
            "query": if a.any { "any" } else { "closest" },
            "builder": tree.stats.builder,
            "sah_traversal_cost": tree.stats.traversal_cost,
            "entry_grid": (!tree.entry.cells.is_empty()).then_some(tree.entry.res),
            "traversal": traversal.name(),
            "kernels": matches!(backend, Backend::Gpu(_)).then(|| kernels_name(a.kernels.into())),
            "query_workgroup": match &backend {
                Backend::Gpu(ctx) => Some(ctx.query_workgroup()),
                Backend::Cpu => None,
            },
            // The kd-tree kernels with wgpu's run-time checks (RAYSTREAM_GPU_CHECKS=on) or not.
            "run_time_checks": match &backend {
                Backend::Gpu(ctx) => Some(!ctx.unchecked_kernels()),
                Backend::Cpu => None,
            },
            // Huge triangles' planes in f64 (where the adapter has it) or f32
            // (RAYSTREAM_GPU_PLANES=f32); the CPU's are in f64.
            "f64_planes": match &backend {
                Backend::Gpu(ctx) => ctx.f64_planes(),
                Backend::Cpu => true,
            },
            // The instruction set of the CPU's queries (RAYSTREAM_CPU_ISA).
            "cpu_isa": matches!(backend, Backend::Cpu).then(|| Isa::current().name()),
            "build_ms": round3(t.build_ms),
            "upload_ms": round3(t.upload_ms),
            "trace_ms": round3(t.trace_ms),
            "trace_ms_min": round3(t.trace_ms_min),
            "gpu_kernel_ms": t.kernel_gpu_ms.map(round3),
            "stream_ms": t.stream_ms.map(round3),
            "round_trip_ms": t.round_trip_ms.map(round3),
            "untimed_ms": t.untimed_ms.map(round3),
            "split_steps": t.split_steps,
            "mrays_per_s": round3(mrays),
            "hits": n_hits,
            "gpu_stats": stats.as_ref().map(gpu_stats_json),
            "floor": floor.as_ref().map(|f| json!({
                "trace_ms": round3(f.trace_ms),
                "trace_ms_min": round3(f.trace_ms_min),
                "gpu_kernel_ms": f.kernel_gpu_ms.map(round3),
                "stream_ms": f.stream_ms.map(round3),
                "untimed_ms": f.untimed_ms.map(round3),
            })),
        }));
    } else if !a.quiet {
        eprintln!(
            "raystream: {} rays, {} hits, build {:.1} ms, upload {:.1} ms, trace {:.1} ms ({:.2} Mrays/s) on {} ({})",
            rays.len(),
            n_hits,
            t.build_ms,
            t.upload_ms,
            t.trace_ms,
            mrays,
            backend.name(),
            backend.adapter()
        );
        if let Some(ms) = t.stream_ms {
            eprintln!(
                "raystream: streamed: {ms:.2} ms a query ({:.2} Mrays/s), {} queued in one submission",
                rays.len() as f64 / (ms * 1e-3) / 1e6,
                a.repeat
            );
        }
        if let Some(ms) = t.untimed_ms {
            eprintln!(
                "raystream: untimed: {ms:.3} ms a query ({:.2} Mrays/s) without timestamp queries",
                rays.len() as f64 / (ms * 1e-3) / 1e6
            );
        }
        if let Some(ms) = t.round_trip_ms {
            eprintln!(
                "raystream: an empty submission's round trip: {ms:.3} ms (the floor under a query's time)"
            );
        }
        if let Some(s) = &stats {
            eprintln!(
                "raystream: GPU work and SIMD efficiency: {}",
                gpu_stats_json(s)
            );
        }
        if let Some(f) = &floor {
            let gpu_ms = f
                .kernel_gpu_ms
                .map_or(String::new(), |ms| format!(", {ms:.3} ms by timestamps"));
            let stream = f
                .stream_ms
                .map_or(String::new(), |ms| format!(", {ms:.3} ms streamed"));
            eprintln!(
                "raystream: the floor (each ray read, a miss written, no traversal): {:.3} ms{gpu_ms}{stream}",
                f.trace_ms
            );
        }
    }
    Ok(())
}
