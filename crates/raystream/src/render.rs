//! `raystream render`: a mesh, a scene file or the built-in scene to PNG.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use raystream_accel::{KdTree, Traversal};
use raystream_cpu::{DepthStats, RenderOptions, render};
use raystream_gpu::{GpuRenderer, GpuTracer, GpuVolumeRenderer};
use raystream_scene::Scene;

use raystream_cpu::dvr::{DvrMode, DvrOptions, DvrStats, render_volume, volume_camera};
use raystream_volume::{TfPreset, TransferFunction};

use crate::cli::RenderArgs;
use crate::common::{Backend, load_mesh, median as median_of, ms, open_device, spinner};
use crate::iso::{Bones, bones, read_volume};

/// The built-in default: the abdomen/pelvis CT of TotalSegmentator's tests (see
/// `assets/README.md` for source and license), whose bones `render` shows without an input.
const DEFAULT_CT: &[u8] = include_bytes!("../assets/abdomen_pelvis_ct_totalseg.nii.gz");
const DEFAULT_CT_NAME: &str = "<built-in abdomen_pelvis_ct_totalseg.nii.gz>";

/// The scene named by INPUT: none → the built-in CT's bones, `.toml` → scene file, a volume →
/// its bones, else a mesh. Also says how the volume steps went, for volumes.
fn load_scene(a: &RenderArgs) -> Result<(Scene, Option<Bones>)> {
    let hu = a.threshold.hu()?;
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

/// `render VOLUME --mode …`: direct volume rendering on the CPU (the reference path).
fn render_direct(a: &RenderArgs, mode: DvrMode) -> Result<()> {
    let backend = open_device(a.accel.device, a.accel.adapter.as_deref(), a.quiet)?;
    let (path, embedded) = match a.input.as_deref() {
        None => (Path::new(DEFAULT_CT_NAME), Some(DEFAULT_CT)),
        Some(p) if raystream_io::is_volume_path(p) => (p, None),
        Some(p) => bail!(
            "{}: --mode {} renders CT volumes (DICOM, NIfTI, NRRD, MetaImage), not meshes or scenes",
            p.display(),
            mode.name()
        ),
    };
    let (volume, load_ms) = read_volume(path, a.series.as_deref(), a.quiet, embedded)?;
    let tf = match (&a.tf, a.threshold.preset) {
        (Some(f), _) => TransferFunction::load(f).map_err(anyhow::Error::msg)?,
        (None, Some(p)) => match p.transfer() {
            Some(t) => t.function(),
            None if mode == DvrMode::Iso => TfPreset::CtBone.function(),
            None => bail!(
                "--preset {}: a threshold; --mode {} takes a transfer function: ct-bone, ct-bones, ct-aaa, ct-muscle, ct-lung, mip-bone (or --tf FILE)",
                p.name(),
                mode.name()
            ),
        },
        (None, None) => TfPreset::CtBone.function(),
    };
    if let Some(s) = a.step
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--step {s}: the step must be a positive number of mm");
    }
    if let Some(w) = a.window
        && !(w.is_finite() && w > 0.0)
    {
        bail!("--window {w}: the window must be a positive number of HU");
    }
    let opt = DvrOptions {
        width: a.size.0,
        height: a.size.1,
        mode,
        step_mm: a.step,
        window: a.window.zip(a.level),
        iso_hu: if mode == DvrMode::Iso {
            a.threshold
                .iso
                .unwrap_or(match a.threshold.preset.and_then(|p| p.threshold()) {
                    Some(t) => t.hu(),
                    None => raystream_volume::Preset::Bone.hu(),
                })
        } else {
            0.0
        },
        skip_empty: !a.no_skip,
        ..Default::default()
    };
    let cam = volume_camera(&volume, opt.width as f32 / opt.height as f32);
    let pb = spinner(
        a.quiet,
        &format!(
            "{} of {}x{}x{} voxels",
            mode.name(),
            volume.dims[0],
            volume.dims[1],
            volume.dims[2]
        ),
    );
    let gpu = match &backend {
        Backend::Gpu(ctx) => Some(GpuVolumeRenderer::new(ctx, &volume, &tf)?),
        Backend::Cpu => None,
    };
    let mut frame_ms = Vec::new();
    let mut kernel_ms = Vec::new();
    let mut out = None;
    // The CPU path counts its samples; the GPU's are estimated below.
    let mut cpu_stats = None;
    for _ in 0..a.repeat {
        let t = Instant::now();
        out = Some(match &gpu {
            Some(g) => {
                let (img, times) = g.render(&opt, &cam)?;
                kernel_ms.extend(times.kernel_gpu_ms);
                img
            }
            None => {
                let (img, stats) = render_volume(&volume, &tf, &opt, &cam);
                cpu_stats = Some(stats);
                img
            }
        });
        frame_ms.push(ms(t.elapsed()));
    }
    pb.finish_and_clear();
    let image = out.expect("at least one frame");
    image.save_png(&a.output).map_err(anyhow::Error::msg)?;
    if !a.quiet {
        // The work a GPU frame does, estimated on the CPU path's marcher (the same lattice)
        // at no more than 256×256.
        let stats = cpu_stats.unwrap_or_else(|| {
            let small = DvrOptions {
                width: opt.width.min(256),
                height: opt.height.min(256),
                ..opt
            };
            let (_, s) = render_volume(&volume, &tf, &small, &cam);
            let scale =
                (opt.width as f64 * opt.height as f64) / (small.width as f64 * small.height as f64);
            DvrStats {
                samples: (s.samples as f64 * scale) as u64,
                skipped: (s.skipped as f64 * scale) as u64,
                ..s
            }
        });
        let median = median_of(&mut frame_ms);
        eprintln!(
            "raystream: wrote {} ({}x{}, --mode {}, step {:.3} mm) on {} ({}): load {:.0} ms, render {:.1} ms ({:.2} frames/s{}){}, {} samples{}, {} skipped as empty ({:.0} %), {:.1} M samples/s",
            a.output.display(),
            opt.width,
            opt.height,
            mode.name(),
            stats.step_mm,
            backend.name(),
            backend.adapter(),
            load_ms,
            median,
            1e3 / median,
            if a.repeat > 1 {
                format!(", median of {}", a.repeat)
            } else {
                String::new()
            },
            if kernel_ms.is_empty() {
                String::new()
            } else {
                format!(", kernel {:.2} ms", median_of(&mut kernel_ms))
            },
            stats.samples,
            if gpu.is_some() { " (estimated)" } else { "" },
            stats.skipped,
            100.0 * stats.skipped as f64 / (stats.samples + stats.skipped).max(1) as f64,
            stats.samples as f64 / median / 1e3
        );
    }
    Ok(())
}

pub fn run(a: &RenderArgs) -> Result<()> {
    if let Some(mode) = a.mode {
        return render_direct(a, mode.into());
    }
    if a.tf.is_some() || a.step.is_some() || a.window.is_some() || a.no_skip {
        bail!(
            "--tf, --step, --window/--level and --no-skip go with --mode (direct volume rendering)"
        );
    }
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
        let median = median_of(&mut frame_ms);
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
                b.load_ms, b.iso_ms, b.voxels, b.hu
            );
        }
    }
    Ok(())
}
