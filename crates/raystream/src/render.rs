//! `raystream render`: a mesh, a scene file or the built-in scene to PNG.

use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use raystream_accel::KdTree;
use raystream_cpu::{RenderOptions, render};
use raystream_scene::Scene;

use crate::cli::Device;
use crate::cli::RenderArgs;
use crate::common::{load_mesh, ms, spinner};
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
    // The GPU stream renderer is not built yet: rendering runs on the CPU path.
    let device = match a.accel.device {
        Device::Gpu => bail!(
            "render --device gpu: the GPU stream renderer is not implemented yet (GPU ray queries are: raystream trace --device gpu); use --device cpu or auto"
        ),
        _ => "cpu",
    };
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
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(opt.max_depth as u64 + 1)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} depth {pos}/{len} {msg} [{elapsed}]").unwrap(),
    );
    let t1 = Instant::now();
    let mut total_rays = 0usize;
    let image = render(&scene, &tree, &opt, |s| {
        total_rays += s.rays + s.shadow_rays;
        bar.set_message(format!(
            "{} rays, {} hits, {} shadow rays",
            s.rays, s.hits, s.shadow_rays
        ));
        bar.inc(1);
    });
    let render_ms = ms(t1.elapsed());
    bar.finish_and_clear();
    image.save_png(&a.output).map_err(anyhow::Error::msg)?;
    if !a.quiet {
        eprintln!(
            "raystream: wrote {} ({}x{}, {} spp, depth {}) on {device}: load {:.0} ms, kd-tree {:.0} ms ({} triangles), render {:.0} ms ({:.2} Mrays/s over {} rays)",
            a.output.display(),
            opt.width,
            opt.height,
            opt.spp,
            opt.max_depth,
            load_ms,
            tree.stats.build_ms,
            scene.mesh.len(),
            render_ms,
            total_rays as f64 / render_ms / 1e3,
            total_rays
        );
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
