//! `raystream bench`: build time, and throughput on the standard primary, shadow and diffuse
//! ray sets (the conventions of `../shared/tools/rays.py gen`), traversal and intersection
//! only, build time apart as the paper measures, on each `--device` in one run (GPU time from
//! the kernel's submission to its completion). Hits are validated against brute force on a
//! sample before any figure is printed. Nodes and triangles visited are counted by the CPU
//! traversal (the GPU runs the same algorithm over the same tree).

use std::f32::consts::PI;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use rayon::prelude::*;
use raystream_accel::{Counters, KdTree, Traversal, brute};
use raystream_cpu::ImageFormat;
use raystream_cpu::dvr::{DvrMode, DvrOptions, DvrStats, volume_camera, volume_camera_from};
use raystream_io::TriMesh;
use raystream_math::{Ray, Vec3};
use raystream_scene::{Camera, Projection, VOLUME_VIEW};
use serde_json::json;

use crate::cli::BenchArgs;
use crate::common::{
    Backend, file_name, gpu_tracer, load_mesh, median, ms, open_device, print_line, round3, spinner,
};
use crate::info::tree_json;
use crate::trace::{NO_PRIM, gpu_stats_json, kernels_name, trace_all, trace_timed, write_rays};
use raystream_gpu::Kernels;

const OFFSET: f32 = 1e-4;
const LIGHT_RADIUS: f32 = 0.05;
const MAX_PER_HIT: usize = 8;
const VALIDATE_RAYS: usize = 256;

/// xorshift64*: seeded, reproducible ray sets.
struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The standard ray sets of one mesh: primary rays through pixel centres, and per primary hit
/// K shadow rays (to a spherical light, t_max = 1) and K cosine-weighted diffuse rays, with K
/// chosen for about one secondary ray per pixel (at most 8).
pub fn ray_sets(
    mesh: &TriMesh,
    tree: &KdTree,
    width: u32,
    height: u32,
) -> Vec<(&'static str, Vec<Ray>)> {
    let used: Vec<Vec3> = mesh
        .triangles
        .iter()
        .flatten()
        .map(|&i| mesh.positions[i as usize])
        .collect();
    let cam = Camera::frame(&used, width as f32 / height as f32);
    let primary: Vec<Ray> = (0..width * height)
        .map(|p| {
            cam.ray(
                (p % width) as f32 + 0.5,
                (p / width) as f32 + 0.5,
                width,
                height,
            )
        })
        .collect();
    let hits = trace_all(tree, &primary, false, Traversal::Ropes);
    let b = mesh.bounds();
    let (center, radius) = (b.center(), b.radius());
    let surf: Vec<(Vec3, Vec3)> = primary
        .iter()
        .zip(&hits)
        .filter(|(_, h)| h.prim != NO_PRIM)
        .map(|(r, h)| {
            let [a, b, c] = mesh.corners(h.prim as usize);
            let mut n = (b - a).cross(c - a).normalize_or_zero();
            if n == Vec3::ZERO {
                n = -r.dir.normalize();
            }
            if n.dot(r.dir) > 0.0 {
                n = -n;
            }
            (r.at(h.t) + n * (OFFSET * radius), n)
        })
        .collect();
    let k =
        ((primary.len() as f64 / surf.len().max(1) as f64).round() as usize).clamp(1, MAX_PER_HIT);
    let light = center + radius * (1.2 * cam.up + 0.6 * cam.right - 0.8 * cam.fwd);
    let mut rng = Rng(1);
    let mut shadow = Vec::with_capacity(surf.len() * k);
    let mut diffuse = Vec::with_capacity(surf.len() * k);
    for &(p, n) in &surf {
        let (t1, t2) = n.any_orthonormal_pair();
        for _ in 0..k {
            let j = loop {
                let v = Vec3::new(rng.f(), rng.f(), rng.f()) * 2.0 - 1.0;
                if v.length_squared() <= 1.0 && v.length_squared() > 1e-6 {
                    break v.normalize();
                }
            };
            shadow.push(Ray::new(
                p,
                light + j * (LIGHT_RADIUS * radius) - p,
                0.0,
                1.0,
            ));
            let (u1, u2) = (rng.f(), rng.f());
            let (r, phi) = (u1.sqrt(), 2.0 * PI * u2);
            let d = t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt();
            diffuse.push(Ray::new(p, d.normalize(), 0.0, f32::INFINITY));
        }
    }
    vec![
        ("primary", primary),
        ("shadow", shadow),
        ("diffuse", diffuse),
    ]
}

/// The commit the binary was built from (see build.rs).
fn git_commit() -> String {
    env!("RAYSTREAM_COMMIT").to_string()
}

/// The name under which a query's GPU kernel time is reported.
fn kernel_label(kernels: Option<Kernels>, any: bool) -> &'static str {
    match (kernels, any) {
        (Some(Kernels::Split), _) => "split_traverse+split_intersect",
        (Some(Kernels::Persistent), true) => "intersect_any_persistent",
        (Some(Kernels::Persistent), false) => "intersect_closest_persistent",
        (Some(Kernels::IfIf), true) => "intersect_any_ifif",
        (Some(Kernels::IfIf), false) => "intersect_closest_ifif",
        (_, true) => "intersect_any",
        (_, false) => "intersect_closest",
    }
}

pub fn run(a: &BenchArgs) -> Result<()> {
    if raystream_io::is_volume_path(&a.input) {
        if a.save_rays.is_some() {
            bail!(
                "{}: --save-rays writes a mesh's ray sets; this is a volume",
                a.input.display()
            );
        }
        return match a.mode {
            Some(mode) => bench_dvr(a, mode.into()),
            None => bench_iso(a),
        };
    }
    if a.mode.is_some() || a.resample.is_some() {
        bail!(
            "{}: --mode and --resample measure volume rendering; this is a mesh",
            a.input.display()
        );
    }
    let quiet = a.quiet || a.json;
    let mesh = load_mesh(&a.input)?;
    let corners: Vec<[Vec3; 3]> = (0..mesh.len()).map(|i| mesh.corners(i)).collect();
    let traversal: Traversal = a.traversal.into();
    let commit = git_commit();
    for &dev in &a.device {
        let backend = open_device(dev, a.adapter.as_deref(), quiet)?;
        // Build time: median of 3 builds (the first also warms the thread pool).
        let mut builds = Vec::new();
        let mut tree = a.tree.build(&mesh);
        for _ in 0..3 {
            let t0 = Instant::now();
            tree = a.tree.build(&mesh);
            builds.push(ms(t0.elapsed()));
        }
        let build_ms = median(&mut builds);
        let pb = spinner(quiet, "generating ray sets");
        let sets = ray_sets(&mesh, &tree, a.size.0, a.size.1);
        pb.finish_and_clear();
        if let Some(dir) = &a.save_rays {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create the folder", dir.display()))?;
            for (kind, rays) in &sets {
                write_rays(&dir.join(format!("{kind}.rays")), rays)?;
            }
        }
        // On a GPU one tracer, the tree uploaded once, for every set and layout (and the
        // kernels' own count of their work, the statistics query).
        let gpu = gpu_tracer(&backend, &tree, &a.input)?;
        // The CPU has one way to trace; a GPU is measured with each kernel layout asked for.
        let layouts: Vec<Option<Kernels>> = match backend {
            Backend::Cpu => vec![None],
            Backend::Gpu(_) => a.kernels.iter().map(|&k| Some(k.into())).collect(),
        };
        for kernels in layouts {
            for (kind, rays) in &sets {
                let any = *kind == "shadow";
                let pb = spinner(
                    quiet,
                    &format!("{kind}: {} rays on {}", rays.len(), backend.name()),
                );
                let t = trace_timed(
                    gpu.as_ref(),
                    &tree,
                    rays,
                    any,
                    traversal,
                    kernels.unwrap_or_default(),
                    a.repeat,
                )?;
                pb.finish_and_clear();
                // Validate a spread-out sample against brute force before printing any figure.
                let step = (rays.len() / VALIDATE_RAYS).max(1);
                for (r, h) in rays.iter().zip(&t.hits).step_by(step) {
                    let want = brute::closest(&corners, r);
                    let ok = match want {
                        None => !h.t.is_finite(),
                        Some(_) if any => h.t.is_finite() && h.t >= r.t_min && h.t <= r.t_max,
                        Some(w) => (h.t - w.t).abs() <= 1e-5 * w.t.abs().max(1e-6),
                    };
                    if !ok {
                        bail!(
                            "{}: {kind} ray {r:?} on {}: kd-tree t {} prim {}, brute force {want:?}",
                            a.input.display(),
                            backend.name(),
                            h.t,
                            h.prim
                        );
                    }
                }
                let c = rays
                    .par_chunks(4096)
                    .map(|chunk| {
                        let mut c = Counters::default();
                        for r in chunk {
                            tree.intersect_counted(r, traversal, any, &mut c);
                        }
                        c
                    })
                    .reduce(Counters::default, |mut a, b| {
                        a += b;
                        a
                    });
                // The kernel's own count of its work, and its SIMD efficiency.
                let simd = match (&gpu, kernels) {
                    (Some(tracer), Some(k)) => tracer
                        .query_stats_with(rays, any, k)?
                        .map(|s| {
                            if (s.steps[0], s.steps[1], s.listed) != (c.inner, c.leaves, c.triangles) {
                                eprintln!(
                                    "raystream: {kind}: the GPU counted {:?} inner/leaf steps and {} listed triangles, the CPU {} / {} / {}",
                                    &s.steps[..2],
                                    s.listed,
                                    c.inner,
                                    c.leaves,
                                    c.triangles
                                );
                            }
                            gpu_stats_json(&s)
                        }),
                    _ => None,
                };
                let n = rays.len().max(1) as f64;
                let line = json!({
                    "bench": "trace",
                    "device": backend.name(),
                    "adapter": backend.adapter(),
                    "commit": commit,
                    "mesh": file_name(&a.input),
                    "triangles": mesh.len(),
                    "kind": kind,
                    "query": if any { "any" } else { "closest" },
                    "rays": rays.len(),
                    "size": format!("{}x{}", a.size.0, a.size.1),
                    "builder": tree.stats.builder,
                    "traversal": traversal.name(),
                    "kernels": kernels.map(kernels_name),
                    "build_ms": round3(build_ms),
                    "upload_ms": round3(t.upload_ms),
                    "kdtree": tree_json(&tree),
                    "trace_ms": round3(t.trace_ms),
                    "trace_ms_min": round3(t.trace_ms_min),
                    // Per-kernel GPU time from timestamp queries, by stage name.
                    "gpu_kernel_ms": t.kernel_gpu_ms.map(|k| json!({ kernel_label(kernels, any): round3(k) })),
                    // Wall time per query of --repeat queries queued in one submission.
                    "stream_ms": t.stream_ms.map(round3),
                    // Wall time per query without timestamp queries (each after a timed one).
                    "untimed_ms": t.untimed_ms.map(round3),
                    "mrays_per_s": round3(n / (t.trace_ms * 1e-3) / 1e6),
                    "inner_per_ray": round3(c.inner as f64 / n),
                    "leaves_per_ray": round3(c.leaves as f64 / n),
                    "tris_per_ray": round3(c.triangles as f64 / n),
                    "hits": t.hits.iter().filter(|h| h.t.is_finite()).count(),
                    // GPU, fused kernel, subgroups: steps per ray as the kernel counted them,
                    // and the share of each subgroup's lanes busy in its steps.
                    "gpu_stats": simd,
                });
                if a.json {
                    print_line(line);
                } else {
                    println!(
                        "{:<9} {:<8} {:>9} rays  {:>8.2} Mrays/s  ({:.1} ms)  {:.1} inner, {:.2} leaves, {:.1} triangles per ray  [build {:.0} ms, SAH cost {:.1}, {}; {}]",
                        match kernels {
                            Some(k) => format!("gpu/{}", kernels_name(k)),
                            None => backend.name().to_string(),
                        },
                        kind,
                        rays.len(),
                        line["mrays_per_s"].as_f64().unwrap(),
                        t.trace_ms,
                        line["inner_per_ray"].as_f64().unwrap(),
                        line["leaves_per_ray"].as_f64().unwrap(),
                        line["tris_per_ray"].as_f64().unwrap(),
                        build_ms,
                        tree.stats.sah_cost,
                        tree.stats.builder,
                        backend.adapter()
                    );
                    if let Some(ms) = t.stream_ms {
                        println!(
                            "          streamed: {:.2} Mrays/s ({ms:.2} ms a query, {} queued in one submission)",
                            n / (ms * 1e-3) / 1e6,
                            a.repeat
                        );
                    }
                    if let Some(s) = &line["gpu_stats"].as_object() {
                        println!(
                            "          SIMD efficiency (share of subgroup lanes busy): {}; at most {} invocations ({} subgroups) resident at once",
                            s["simd_efficiency"],
                            s["peak_resident_invocations"],
                            s["peak_resident_subgroups"]
                        );
                    }
                }
            }
        }
    }
    Ok(())
}

/// A volume: marching-cubes throughput at `--iso` HU (default 300), the median of `--repeat`
/// runs after a warm-up, validated first (a closed surface: every edge in two triangles).
fn bench_iso(a: &BenchArgs) -> Result<()> {
    let quiet = a.quiet || a.json;
    let hu = a.threshold.hu()?;
    let t0 = Instant::now();
    let pb = spinner(quiet, &format!("reading {}", a.input.display()));
    let volume = raystream_io::load_volume(&a.input, &Default::default())?;
    pb.finish_and_clear();
    let load_ms = ms(t0.elapsed());
    let pb = spinner(quiet, "marching cubes");
    let surface = raystream_volume::extract_isosurface(&volume, hu);
    let mut edges = std::collections::HashMap::<(u32, u32), u32>::new();
    for t in &surface.mesh.triangles {
        for i in 0..3 {
            let (p, q) = (t[i], t[(i + 1) % 3]);
            *edges.entry((p.min(q), p.max(q))).or_default() += 1;
        }
    }
    if edges.values().any(|&n| n != 2) {
        bail!(
            "{}: the isosurface is not closed (a bug)",
            a.input.display()
        );
    }
    let mut times = Vec::new();
    for _ in 0..a.repeat {
        let t = Instant::now();
        let s = raystream_volume::extract_isosurface(&volume, hu);
        times.push(ms(t.elapsed()));
        drop(s);
    }
    pb.finish_and_clear();
    let iso_ms = median(&mut times);
    let voxels = volume.voxel_count();
    let v = json!({
        "file": file_name(&a.input),
        "kind": "isosurface",
        "commit": git_commit(),
        "threads": rayon::current_num_threads(),
        "dims": volume.dims,
        "iso_hu": hu,
        "load_ms": round3(load_ms),
        "iso_ms": round3(iso_ms),
        "mvoxels_per_s": round3(voxels as f64 / iso_ms / 1e3),
        "vertices": surface.mesh.positions.len(),
        "triangles": surface.mesh.len(),
    });
    if a.json {
        print_line(v);
    } else {
        println!(
            "{}: {}x{}x{} voxels at {hu} HU: {:.1} ms ({:.0} M voxels/s), {} triangles; load {:.0} ms",
            file_name(&a.input),
            volume.dims[0],
            volume.dims[1],
            volume.dims[2],
            iso_ms,
            voxels as f64 / iso_ms / 1e3,
            surface.mesh.len(),
            load_ms
        );
    }
    Ok(())
}

/// A volume with `--mode`: frames of an orbit (`--frames`, one every 360/N degrees, after one
/// warm-up frame) on each device, dvr without and with shadows side by side. Before any GPU
/// figure, the GPU's first frame at 128×128 must match the CPU's (mean < 1/255).
fn bench_dvr(a: &BenchArgs, mode: DvrMode) -> Result<()> {
    let quiet = a.quiet || a.json;
    let t0 = Instant::now();
    let pb = spinner(quiet, &format!("reading {}", a.input.display()));
    let volume = raystream_io::load_volume(&a.input, &Default::default())?;
    pb.finish_and_clear();
    let source_dims = volume.dims;
    // As `render --mode` draws it: a lone slice as the slab it images.
    let mut volume = crate::common::slab_if_lone(volume, &a.input, quiet);
    let load_ms = ms(t0.elapsed());
    let mut resample_ms = None;
    if let Some(n) = a.resample {
        let n = n as usize;
        let t = Instant::now();
        let pb = spinner(quiet, &format!("resampling to {n}³"));
        volume = volume.resample([n; 3]);
        pb.finish_and_clear();
        resample_ms = Some(ms(t.elapsed()));
    }
    let (mut tf, mut base) = crate::dvr::options(&a.look, &a.threshold, mode, a.size)?;
    let unit_free = (&a.look, &a.threshold);
    let seen = (&volume, a.input.as_path());
    if let Some(w) = crate::dvr::unit_free_defaults(unit_free, seen, quiet, &mut tf, &mut base) {
        w.spanning_the_voxels(&mut base);
    }
    let asked = crate::segments::Asked {
        segmentation: a.segmentation.as_deref(),
        segment: a.segment.as_deref(),
        colour_table: None,
    };
    let (volume, colours, weights) = match crate::segments::paint(asked, mode, &volume, &a.input)? {
        Some(p) => (p.kept.unwrap_or(volume), p.colours, p.weights),
        None => (volume, None, None),
    };
    let (colours, weights) = (colours.as_ref(), weights.as_ref());
    let shadow_cases: &[bool] = if mode == DvrMode::Dvr {
        &[false, true]
    } else {
        &[false]
    };
    let commit = git_commit();
    let aspect = base.width as f32 / base.height as f32;
    for &dev in &a.device {
        let backend = open_device(dev, a.adapter.as_deref(), quiet)?;
        let t = Instant::now();
        let renderer = crate::dvr::Renderer::new(&backend, &volume, &tf, colours, weights)?;
        let upload_ms = ms(t.elapsed());
        // The interpolating spline's coefficients, timed apart from upload and frames.
        let t = Instant::now();
        renderer.prepare(base.interpolation)?;
        let coefficients_ms = base.interpolation.prefiltered().then(|| ms(t.elapsed()));
        for &shadows in shadow_cases {
            let opt = DvrOptions { shadows, ..base };
            let cam0 = volume_camera(&volume, aspect);
            if matches!(backend, Backend::Gpu(_)) {
                let small = DvrOptions {
                    width: 128,
                    height: 128,
                    ..opt
                };
                let cam = volume_camera(&volume, 1.0);
                let gpu = renderer
                    .frame(&small, &cam, ImageFormat::Png)?
                    .picture
                    .into_srgb8();
                let cpu = crate::dvr::Renderer::new(&Backend::Cpu, &volume, &tf, colours, weights)?
                    .frame(&small, &cam, ImageFormat::Png)?
                    .picture
                    .into_srgb8();
                let (mean, _) = raystream_cpu::srgb8_diff(&cpu, &gpu);
                if mean >= 1.0 {
                    bail!(
                        "{}: the GPU's frame differs from the CPU's by {mean:.2}/255 on average (a bug); no figures",
                        backend.adapter()
                    );
                }
            }
            let pb = if quiet {
                ProgressBar::hidden()
            } else {
                ProgressBar::new(a.frames as u64 + 1)
            };
            pb.set_message(format!("{} {}", backend.name(), mode.name()));
            // The warm-up frame also builds what frames keep (brick tables, majorants, light
            // grids): its time is the time to a first picture.
            let t = Instant::now();
            renderer.frame(&opt, &cam0, ImageFormat::Png)?;
            let first_frame_ms = ms(t.elapsed());
            pb.inc(1);
            let (mut frame_ms, mut kernel_ms, mut samples) = (Vec::new(), Vec::new(), 0u64);
            let mut stats = None;
            for i in 0..a.frames {
                let turn = VOLUME_VIEW.orbit(360.0 * i as f32 / a.frames as f32, 0.0);
                let cam = volume_camera_from(&volume, aspect, turn, Projection::Perspective);
                let f = renderer.frame(&opt, &cam, ImageFormat::Png)?;
                frame_ms.push(f.frame_ms);
                kernel_ms.extend(f.kernel_ms);
                samples += f.samples;
                stats = stats.or(f.stats);
                pb.inc(1);
            }
            pb.finish_and_clear();
            let estimated = stats.is_none();
            // A GPU frame counts its samples; the CPU's estimate of what it skipped would path
            // trace a frame (cinematic mode skips whole bricks, it does not count them).
            let stats = stats.unwrap_or_else(|| {
                if mode == DvrMode::Cinematic {
                    DvrStats::default()
                } else {
                    crate::dvr::estimate_stats(&volume, &tf, &opt, (&cam0).into())
                }
            });
            let frame_min = frame_ms.iter().cloned().fold(f64::INFINITY, f64::min);
            let frame = median(&mut frame_ms);
            let kernel = (!kernel_ms.is_empty()).then(|| median(&mut kernel_ms));
            let per_frame = samples as f64 / a.frames as f64;
            let v = json!({
                "file": file_name(&a.input),
                "kind": "volume",
                "mode": mode.name(),
                "shadows": shadows,
                "interpolation": opt.interpolation.name(),
                "segmentation": a.segmentation.as_ref().map(|f| file_name(f)),
                "segment": a.segment,
                "spp": (mode == DvrMode::Cinematic).then_some(opt.spp),
                "bounces": (mode == DvrMode::Cinematic).then_some(opt.bounces),
                "denoise": (mode == DvrMode::Cinematic).then_some(opt.denoise),
                "anisotropy": (mode == DvrMode::Cinematic).then_some(opt.anisotropy),
                "exposure": (mode == DvrMode::Cinematic).then_some(opt.exposure),
                "transfer_function": a.look.tf.as_ref().map(|p| p.display().to_string())
                    .unwrap_or_else(|| a.threshold.preset.map_or("ct-bone".into(), |p| p.name())),
                "commit": commit,
                "device": backend.name(),
                "adapter": backend.adapter(),
                "source_dims": source_dims,
                "dims": volume.dims,
                "size": format!("{}x{}", opt.width, opt.height),
                "step_mm": round3(stats.step_mm as f64),
                "skip_empty": opt.skip_empty,
                "frames": a.frames,
                "load_ms": round3(load_ms),
                "resample_ms": resample_ms.map(round3),
                "upload_ms": round3(upload_ms),
                "coefficients_ms": coefficients_ms.map(round3),
                "first_frame_ms": round3(first_frame_ms),
                "frame_ms": round3(frame),
                "frame_ms_min": round3(frame_min),
                "frames_per_s": round3(1e3 / frame),
                "kernel_ms": kernel.map(round3),
                "kernel_frames_per_s": kernel.map(|k| round3(1e3 / k)),
                "samples_per_frame": per_frame.round(),
                "msamples_per_s": round3(per_frame / frame / 1e3),
                "msamples_per_s_kernel": kernel.map(|k| round3(per_frame / k / 1e3)),
                "skipped_fraction": round3(stats.skipped as f64 / (stats.samples + stats.skipped).max(1) as f64),
                "shadow_samples_per_frame": stats.shadow_samples,
                "counts_estimated_on_cpu": estimated && mode != DvrMode::Cinematic,
            });
            if a.json {
                print_line(v);
            } else {
                println!(
                    "{} {}{} on {} ({}), {}x{}x{} voxels, {}x{}, {} frames: {:.2} ms/frame = {:.1} frames/s{}; {:.0} M samples/s ({:.1} M samples/frame){}",
                    file_name(&a.input),
                    mode.name(),
                    match mode {
                        _ if shadows => " --shadows".to_string(),
                        DvrMode::Cinematic =>
                            format!(" ({} paths a pixel, {} scatterings)", opt.spp, opt.bounces),
                        _ => String::new(),
                    },
                    backend.name(),
                    backend.adapter(),
                    volume.dims[0],
                    volume.dims[1],
                    volume.dims[2],
                    opt.width,
                    opt.height,
                    a.frames,
                    frame,
                    1e3 / frame,
                    kernel
                        .map(|k| format!(" (kernel {k:.2} ms = {:.1} frames/s)", 1e3 / k))
                        .unwrap_or_default(),
                    per_frame / frame / 1e3,
                    per_frame / 1e6,
                    if shadows {
                        format!(
                            ", {:.1} M shadow samples/frame",
                            stats.shadow_samples as f64 / 1e6
                        )
                    } else {
                        String::new()
                    }
                );
            }
        }
    }
    Ok(())
}
