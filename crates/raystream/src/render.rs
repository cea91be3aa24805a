//! `raystream render`: a mesh, a scene file or the built-in scene to PNG.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use raystream_accel::{KdTree, Traversal};
use raystream_cpu::{DepthStats, RenderOptions, render};
use raystream_gpu::{GpuRenderer, GpuTracer};
use raystream_scene::Scene;

use crate::cli::RenderArgs;
use crate::common::{Backend, load_mesh, ms, open_device, spinner};
use crate::iso::{Bones, bones};

/// The built-in default: the abdomen/pelvis CT of TotalSegmentator's tests (see
/// `assets/README.md` for source and license), whose bones `render` shows without an input.
const DEFAULT_CT: &[u8] = include_bytes!("../assets/abdomen_pelvis_ct_totalseg.nii.gz");
const DEFAULT_CT_NAME: &str = "<built-in abdomen_pelvis_ct_totalseg.nii.gz>";

/// The scene named by INPUT: none → the built-in CT's bones, `.toml` → scene file, a volume →
/// its bones, else a mesh. Also says how the volume steps went, for volumes.
fn load_scene(a: &RenderArgs) -> Result<(Scene, Option<Bones>)> {
    let hu = a.threshold.hu();
    let volume_scene = |path: &Path, embedded: Option<&[u8]>| -> Result<(Scene, Option<Bones>)> {
        let mut b = bones(path, a.series.as_deref(), hu, a.smooth, a.quiet, embedded)?;
        let mesh = std::mem::take(&mut b.surface.mesh);
        let scene = Scene::for_bones(mesh, &b.surface.normals, path);
        Ok((scene, Some(b)))
    };
    match a.input.as_deref() {
        None => volume_scene(Path::new(DEFAULT_CT_NAME), Some(DEFAULT_CT)),
        Some(p)
            if p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("toml")) =>
        {
            Ok((Scene::load(p)?, None))
        }
        Some(p) if raystream_io::is_volume_path(p) => volume_scene(p, None),
        Some(p) => Ok((Scene::for_mesh(load_mesh(p)?, p), None)),
    }
}

pub fn run(a: &RenderArgs) -> Result<()> {
    let backend = open_device(a.accel.device, a.accel.adapter.as_deref(), a.quiet)?;
    if matches!(backend, Backend::Gpu(_)) && Traversal::from(a.accel.traversal) != Traversal::Ropes
    {
        bail!("--device gpu runs the rope traversal only (--traversal ropes)");
    }
    let t0 = Instant::now();
    let (scene, bones) = load_scene(a)?;
    let load_ms = ms(t0.elapsed());
    let pb = spinner(
        a.quiet,
        &format!("building kd-tree over {} triangles", scene.mesh.len()),
    );
    let tree = KdTree::build(&scene.mesh, a.accel.builder.into());
    pb.finish_and_clear();
    let opt = RenderOptions {
        width: a.size.0,
        height: a.size.1,
        spp: a.spp,
        max_depth: a.max_depth,
        traversal: a.accel.traversal.into(),
    };
    let t_setup = Instant::now();
    let gpu = match &backend {
        Backend::Gpu(ctx) => {
            let tracer = GpuTracer::new(ctx, &tree).with_context(|| ctx.describe())?;
            Some(tracer)
        }
        Backend::Cpu => None,
    };
    let renderer = match &gpu {
        Some(tracer) => Some(GpuRenderer::new(tracer, &scene)?),
        None => None,
    };
    let setup_ms = ms(t_setup.elapsed());
    // The progress bar counts depths (of every wave, on the GPU) over all repeats.
    let waves = match &renderer {
        Some(r) => r.waves(&opt),
        None => 1,
    };
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((opt.max_depth as u64 + 1) * waves as u64 * a.repeat as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} depth {pos}/{len} {msg} [{elapsed}]").unwrap(),
    );
    let mut frame_ms = Vec::new();
    let mut image = None;
    let mut total_rays = 0usize;
    let mut kernel_ms = None;
    for _ in 0..a.repeat {
        total_rays = 0;
        let mut on_depth = |s: DepthStats| {
            total_rays += s.rays + s.shadow_rays;
            bar.set_message(format!(
                "{} rays, {} hits, {} shadow rays",
                s.rays, s.hits, s.shadow_rays
            ));
            bar.inc(1);
        };
        let t1 = Instant::now();
        let img = match &renderer {
            Some(r) => {
                let (img, stats) = r.render(&opt, &mut on_depth)?;
                kernel_ms = stats.kernel_gpu_ms;
                img
            }
            None => render(&scene, &tree, &opt, &mut on_depth),
        };
        frame_ms.push(ms(t1.elapsed()));
        // Depths that ended early leave the bar short: count them as done.
        bar.set_position(
            bar.position()
                .max((opt.max_depth as u64 + 1) * waves as u64 * frame_ms.len() as u64),
        );
        image = Some(img);
    }
    bar.finish_and_clear();
    let image = image.expect("at least one frame");
    image.save_png(&a.output).map_err(anyhow::Error::msg)?;
    if !a.quiet {
        frame_ms.sort_by(f64::total_cmp);
        let median = frame_ms[frame_ms.len() / 2];
        eprintln!(
            "raystream: wrote {} ({}x{}, {} spp, depth {}) on {} ({}): load {:.0} ms, kd-tree {:.0} ms ({} triangles){}, render {:.1} ms{} ({:.2} Mrays/s over {} rays)",
            a.output.display(),
            opt.width,
            opt.height,
            opt.spp,
            opt.max_depth,
            backend.name(),
            backend.adapter(),
            load_ms,
            tree.stats.build_ms,
            scene.mesh.len(),
            if gpu.is_some() {
                format!(", GPU upload and pipelines {setup_ms:.0} ms")
            } else {
                String::new()
            },
            median,
            if a.repeat > 1 {
                format!(
                    " median of {} = {:.2} frames/s (min {:.1} ms)",
                    a.repeat,
                    1e3 / median,
                    frame_ms[0]
                )
            } else {
                String::new()
            },
            total_rays as f64 / median / 1e3,
            total_rays
        );
        if let Some(k) = kernel_ms {
            let parts: Vec<String> = k
                .iter()
                .map(|(name, ms)| format!("{name} {ms:.2}"))
                .collect();
            eprintln!(
                "raystream: GPU kernel time of the last frame (ms): {}",
                parts.join(", ")
            );
        }
        if let Some(b) = bones {
            eprintln!(
                "raystream: of the load: volume {:.0} ms, isosurface {:.0} ms ({} voxels at {} HU)",
                b.load_ms,
                b.iso_ms,
                b.voxels,
                a.threshold.hu()
            );
        }
    }
    Ok(())
}
