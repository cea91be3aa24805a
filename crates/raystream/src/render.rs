//! `raystream render`: a mesh, a scene file or the built-in scene to PNG.

use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use raystream_accel::Traversal;
use raystream_accel::{Hit, KdTree};
use raystream_cpu::{
    AOV_CHUNK, Aov, AovBuilder, DepthStats, ImageFormat, RenderOptions, aov_rays_of,
    prepare_volume, render_prepared_in,
};
use raystream_gpu::GpuRenderer;
use raystream_scene::{Camera, PatientView, Projection, Scene, VOLUME_VIEW, View};

use raystream_cpu::cpr::CurvedPlane;
use raystream_cpu::dvr::{DvrMode, DvrOptions, Sight, volume_camera_from};
use raystream_cpu::lumen::LumenOptions;
use raystream_cpu::pipeline::Pipeline;
use raystream_cpu::wall::{Track, WallOptions};

use crate::cli::{AirwayEdge, CprArg, FrameFormat, RenderArgs};
use crate::common::{
    Backend, DicomOut, Picture, gpu_tracer, image_format, median as median_of, ms, open_device,
    spinner,
};
use crate::dvr;
use crate::iso::{Bones, read_volume};

/// The built-in default: the abdomen/pelvis CT of TotalSegmentator's tests (see
/// `assets/README.md` for source and license), whose bones `render` shows without an input.
const DEFAULT_CT: &[u8] = include_bytes!("../assets/abdomen_pelvis_ct_totalseg.nii.gz");
const DEFAULT_CT_NAME: &str = "<built-in abdomen_pelvis_ct_totalseg.nii.gz>";
/// Samples per pixel of meshes and scenes when `--spp` is not given.
const DEFAULT_SPP: u32 = 4;
/// The most samples per pixel of meshes and scenes.
const MAX_MESH_SPP: u32 = 1024;

/// INPUT, or the built-in CT's name.
fn input_name(a: &RenderArgs) -> PathBuf {
    a.input
        .clone()
        .unwrap_or_else(|| Path::new(DEFAULT_CT_NAME).to_path_buf())
}

/// Whether INPUT is a scene file (`.toml`).
fn is_scene_file(a: &RenderArgs) -> bool {
    a.input.as_deref().is_some_and(|p| {
        p.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
    })
}

/// `--colour-shells`: how many shells `path`'s surface has, and how many are coloured.
fn say_shells(a: &RenderArgs, path: &Path, c: &crate::shells::ShellColours) {
    if a.quiet {
        return;
    }
    let n = c.measures.shells;
    let rest = match n.saturating_sub(c.legend.len()) {
        0 => String::new(),
        k => format!(", the other {k} in the usual colour"),
    };
    eprintln!(
        "raystream: {}: {n} shell{}, the {} largest each in a colour of its own{rest} (--legend names them)",
        path.display(),
        if n == 1 { "" } else { "s" },
        c.legend.len()
    );
}

/// The scene named by INPUT: none → the built-in CT's bones, `.toml` → scene file, a volume →
/// its bones, else a mesh. Also says how the volume steps went, for volumes.
fn load_scene(a: &RenderArgs) -> Result<(Scene, Option<Bones>, Vec<crate::legend::Entry>)> {
    a.threshold.hu()?;
    if let Some(p) = a
        .input
        .as_deref()
        .filter(|p| a.body_only && !raystream_io::is_volume_path(p))
    {
        bail!(
            "{}: --body-only keeps a CT to the patient's body; a mesh or a scene file has none to find",
            p.display()
        );
    }
    let volume_scene = |path: &Path, embedded: Option<&[u8]>| -> Result<(Scene, Option<Bones>)> {
        let (mut volume, load_ms) = read_volume(path, &a.pick.select(), a.quiet, embedded)?;
        if a.body_only {
            let b = crate::body::find(&volume, path, a.quiet)?;
            b.hide_outside(&mut volume);
        }
        let (segment, table) = (a.segment.as_deref(), a.colour_table.as_deref());
        let lone_view = crate::common::lone_slice_view(&volume);
        if crate::iso::wants_segments(&volume, &a.threshold, segment, table) {
            if a.colour_shells {
                bail!(
                    "{}: --colour-shells colours a surface's shells; a segmentation's segments are drawn in their own colours",
                    path.display()
                );
            }
            let (scene, mut b) = segments_scene(a, path, &volume, load_ms)?;
            if let Some(b) = b.as_mut() {
                b.lone_view = lone_view;
            }
            return Ok((scene, b));
        }
        let smoothing = a.smooth.unwrap_or(0);
        let hu = crate::iso::surface_threshold(&volume, &a.threshold, path, a.quiet)?;
        let keep = a.islands.keep(volume.voxel_ml());
        let mut b = crate::iso::bones_of(&volume, path, hu, (smoothing, keep), a.quiet, load_ms)?;
        b.lone_view = lone_view;
        let mesh = std::mem::take(&mut b.surface.mesh);
        if !a.colour_shells {
            let scene = Scene::for_bones(mesh, &b.surface.normals, path);
            return Ok((scene, Some(b)));
        }
        let c = crate::shells::shell_colours(&mesh, true);
        say_shells(a, path, &c);
        let surfaces = (crate::shells::shell_parts(&mesh, &b.surface.normals, &c).into_iter())
            .map(|p| raystream_scene::Surface {
                colour: p.colour.unwrap_or(raystream_scene::BONE),
                mesh: p.mesh,
                normals: p.normals,
            })
            .collect();
        b.legend = c.legend;
        Ok((Scene::for_surfaces(surfaces, path), Some(b)))
    };
    let mut scene_legend = Vec::new();
    let loaded = match a.input.as_deref() {
        None => volume_scene(Path::new(DEFAULT_CT_NAME), Some(DEFAULT_CT)),
        Some(p) if is_scene_file(a) && a.colour_shells => bail!(
            "{}: --colour-shells colours a mesh's or a CT's bone surface; a scene file's objects have their materials",
            p.display()
        ),
        Some(p) if is_scene_file(a) => {
            let mut scene = Scene::load(p)?;
            if let Some((words, entries)) = crate::segments::paint_scene(&mut scene, p)? {
                if !a.quiet {
                    eprintln!(
                        "raystream: {}: the volume in the colours of {words}",
                        p.display()
                    );
                }
                scene_legend = entries;
            }
            Ok((scene, None))
        }
        Some(p) if raystream_io::is_volume_path(p) => volume_scene(p, None),
        Some(p) if a.colour_shells => {
            let (mesh, mut shading) = raystream_io::load_mesh_with_shading(p)?;
            let mm = shading.space.is_some() || shading.dicom.is_some();
            let c = crate::shells::shell_colours(&mesh, mm);
            say_shells(a, p, &c);
            let white = [255; 3];
            shading.colours = (c.of_face.iter())
                .map(|g| [g.map_or(white, |k| crate::shells::PALETTE[k]); 3])
                .collect();
            scene_legend = c.legend;
            Ok((Scene::for_mesh_shaded(mesh, shading, p)?, None))
        }
        Some(p) => Ok((Scene::for_mesh_file(p)?, None)),
    }?;
    // A label map's surfaces name their segments; a scene file's volume, its own.
    let (scene, mut bones) = loaded;
    let legend = match bones.as_mut() {
        Some(b) => std::mem::take(&mut b.legend),
        None => scene_legend,
    };
    let loaded = (scene, bones, legend);
    if !a.quiet {
        for w in &loaded.0.warnings {
            eprintln!(
                "raystream: {}: {w}",
                a.input.as_deref().unwrap_or(Path::new("")).display()
            );
        }
    }
    Ok(loaded)
}

/// `--segment LIST` (or a DICOM Segmentation alone): the segments' surfaces
/// ([`crate::iso::segment_surfaces`]), each in its colour, staged as the bones are.
fn segments_scene(
    a: &RenderArgs,
    path: &Path,
    labels: &raystream_io::Volume,
    load_ms: f64,
) -> Result<(Scene, Option<Bones>)> {
    let t = std::time::Instant::now();
    let known = crate::iso::segment_names(labels, a.colour_table.as_deref())?;
    let whole = raystream_io::whole_segments(labels, path)?;
    let surfaces = crate::iso::segment_surfaces(
        labels,
        whole.as_ref(),
        path,
        (a.segment.as_deref().unwrap_or("all"), &known),
        (
            a.smooth.unwrap_or(crate::iso::SEGMENT_SMOOTHING),
            a.islands.keep(labels.voxel_ml()),
        ),
        a.quiet,
    )?;
    let what = surfaces
        .iter()
        .map(|s| format!("{} ({})", s.label, s.name))
        .collect::<Vec<_>>()
        .join(", ");
    let drawn: Vec<u32> = surfaces.iter().map(|s| s.label).collect();
    let legend = crate::legend::entries(&drawn, &known);
    let parts = surfaces
        .into_iter()
        .map(|s| raystream_scene::Surface {
            colour: s.linear_colour(),
            mesh: s.surface.mesh,
            normals: s.surface.normals,
        })
        .collect();
    let scene = Scene::for_surfaces(parts, path);
    let b = Bones {
        lone_view: None,
        surface: Default::default(),
        what: format!("segments {what}"),
        voxels: labels.voxel_count(),
        load_ms,
        iso_ms: ms(t.elapsed()),
        legend,
    };
    Ok((scene, Some(b)))
}

/// The view `--view` starts from (`default` without it), before `--orbit`; `patient`: the
/// scene frame is the patient's (x = left, y = superior, z = anterior), so sides have names.
fn base_view(a: &RenderArgs, default: View, patient: bool) -> Result<View> {
    Ok(match a.view {
        Some(_) if !patient => bail!(
            "{}: --view names a side of the patient, for CT volumes and scenes with one; turn a mesh with --orbit AZ,EL",
            input_name(a).display()
        ),
        Some(v) => PatientView::from(v).view(),
        None => default,
    })
}

/// The view a volume is seen from without `--view`: a lone slice's, along its axis
/// ([`crate::common::lone_slice_view`], said unless `--quiet`), else `default`.
fn lone_or(a: &RenderArgs, lone: Option<(PatientView, &str)>, default: View) -> View {
    match lone {
        Some((view, name)) if a.view.is_none() => {
            if !a.quiet {
                eprintln!(
                    "raystream: {}: seen along the slice's axis, as with --view {name}",
                    input_name(a).display()
                );
            }
            view.view()
        }
        _ => default,
    }
}

/// What is drawn over a PNG frame seen by `cam` (scene frame: x = the patient's left,
/// y = superior, z = anterior): `--draw-path`'s `overlay`, then over it `--labels`' patient
/// directions at the edges, `--scale-bar`'s bar and `--legend`'s `legend`. Returns what a
/// DICOM picture of it says: its rows' and columns' patient directions (where `patient`), and
/// whether anything is drawn on it (these, or `--draw-lumen`'s lumen, drawn before).
fn label(
    a: &RenderArgs,
    picture: &mut Picture,
    cam: &Camera,
    (patient, overlay): (bool, Overlay),
    legend: &[crate::legend::Entry],
) -> DicomOut {
    let [right, up] = [cam.right, cam.up].map(raystream_cpu::dvr::scene_to_lps);
    let listed = draw_legend(picture, legend);
    if let Picture::Srgb8 { rgb, width, height } = &mut *picture {
        if let Some(dense) = overlay {
            crate::overlay::draw_path(rgb, *width, *height, cam, dense);
        }
        if a.labels {
            crate::labels::draw(rgb, *width, *height, right, up);
        }
    }
    if a.scale_bar && patient {
        if cam.parallel > 0.0 {
            draw_scale_bar(a, picture, |h| 2.0 * cam.parallel as f64 / h as f64);
        } else if !a.quiet {
            eprintln!(
                "raystream: --scale-bar: the scene's own camera is a perspective one, with no one scale; no bar drawn"
            );
        }
    }
    // DICOM's Patient Orientation says H(ead) and F(oot) for superior and inferior.
    let dicom = |d| {
        crate::labels::letters(d)
            .replace('S', "H")
            .replace('I', "F")
    };
    DicomOut {
        orientation: patient.then(|| [dicom(right), dicom(-up)]),
        annotated: a.labels || a.scale_bar || listed || overlay.is_some() || a.draw_lumen.is_some(),
        description: crate::common::options_in_words(a.input.as_deref(), &a.output),
        series: None,
        window: None,
        plane: None,
    }
}

/// What a frame of a direct volume rendering was seen by: a camera, or the curved plane of a
/// curved planar reformation.
#[derive(Clone)]
enum Seen {
    Camera(Camera),
    Curved(Box<CurvedPlane>),
}

impl Seen {
    fn sight(&self) -> Sight<'_> {
        match self {
            Seen::Camera(cam) => Sight::Camera(cam),
            Seen::Curved(plane) => Sight::Curved(plane),
        }
    }
}

/// What a DICOM picture of a direct volume rendering says ([`label`]'s, with the window it was
/// shown in and, for a slice or slab seen square on, its plane). A curved reformation's rows
/// follow the path, so it names no patient orientation and no plane.
fn volume_dicom(
    a: &RenderArgs,
    picture: &mut Picture,
    seen: &Seen,
    opt: &DvrOptions,
    (volume, overlay, track, labels): (&raystream_io::Volume, Overlay, Option<&Track>, Labels),
) -> DicomOut {
    // The segmentation first, the legend, lines and letters drawn over it.
    if let Some(l) = labels.overlay {
        tint_segmentation(picture, seen, opt, (volume, l));
    }
    let window = Some(opt.shown_window());
    match seen {
        Seen::Camera(cam) => DicomOut {
            window,
            plane: image_plane(opt, volume, cam),
            ..label(a, picture, cam, (true, overlay), labels.legend)
        },
        Seen::Curved(plane) => DicomOut {
            orientation: None,
            // The lumen's edges first, the marks and the scale over them.
            annotated: draw_cpr_lumen(a, picture, plane, (volume, track))
                | mark_path(a, picture, plane)
                | draw_scale_bar(a, picture, |_| plane.pixel_mm as f64)
                | draw_legend(picture, labels.legend),
            description: crate::common::options_in_words(a.input.as_deref(), &a.output),
            series: None,
            window,
            plane: None,
        },
    }
}

/// `--legend`'s list drawn into a PNG's picture (none to draw: nothing): whether it drew one.
fn draw_legend(picture: &mut Picture, legend: &[crate::legend::Entry]) -> bool {
    if let (false, Picture::Srgb8 { rgb, width, height }) = (legend.is_empty(), &mut *picture) {
        // Only the embedded font can fail to load; the picture stands without the legend.
        if let Err(e) = crate::legend::draw(rgb, *width, *height, legend) {
            eprintln!("raystream: --legend: {e}");
            return false;
        }
        return true;
    }
    false
}

/// `--scale-bar` on a PNG's picture whose square pixels are `mm_px(its height)` mm: whether it
/// drew one.
fn draw_scale_bar(a: &RenderArgs, picture: &mut Picture, mm_px: impl FnOnce(u32) -> f64) -> bool {
    if let (true, Picture::Srgb8 { rgb, width, height }) = (a.scale_bar, &mut *picture) {
        crate::scale_bar::draw(rgb, *width, *height, mm_px(*height));
        return true;
    }
    false
}

/// `--segmentation FILE`: its label volume, read and checked (whole numbers, none below 0),
/// the labels' colours (its own, or `--colour-table`'s), and its segments each whole where
/// they may overlap, for `--outline`. A structure set is laid on `ct`, the CT rendered.
fn segmentation(
    a: &RenderArgs,
    format: ImageFormat,
    ct: &raystream_io::Volume,
) -> Result<Option<crate::overlay::SegmentOverlay>> {
    let Some(file) = &a.segmentation else {
        if let Some(t) = &a.colour_table {
            bail!(
                "--colour-table {}: names the labels of --segment or --segmentation; give one",
                t.display()
            );
        }
        return Ok(None);
    };
    let name = file.display();
    if a.mode != Some(crate::cli::ModeArg::Slice) {
        if let Some(hu) = a.below {
            bail!(
                "--below {hu}: tints a slice or a CPR's pixels by the CT's voxel at each: give --mode slice"
            );
        }
        // The other modes colour or keep to segments: crate::segments::paint.
        return Ok(None);
    }
    if a.look.slab.is_some() {
        bail!(
            "--segmentation {name}: tints a slice or a CPR, each pixel a point: give --mode slice (no --slab)"
        );
    }
    if format == ImageFormat::Exr {
        bail!("--segmentation draws on a PNG; an EXR holds the values themselves");
    }
    let (labels, whole) = if raystream_io::is_structure_set_file(file) {
        let set = raystream_io::StructureSet::read(file)?;
        if let Some(why) = set.frame_mismatch(ct) {
            bail!("{name}: {why}");
        }
        // Its structures laid on the CT once: painted into the label volume, and whole for
        // --outline.
        let (regions, warnings) = set.regions(ct);
        let labels = set.paint(ct, &regions, warnings);
        (labels, a.outline.then(|| set.whole(regions)))
    } else {
        let labels = raystream_io::load_volume(file, &raystream_io::VolumeSelect::default())?;
        let whole = if a.outline {
            raystream_io::whole_segments(&labels, file)?
        } else {
            None
        };
        (labels, whole)
    };
    if let Some(v) = crate::common::not_a_label(&labels) {
        bail!("{name}: --segmentation takes a label map (whole numbers from 0); it holds {v}");
    }
    if !a.quiet {
        for w in &labels.warnings {
            eprintln!("raystream: {name}: {w}");
        }
    }
    let known = crate::iso::segment_names(&labels, a.colour_table.as_deref())?;
    let colours = known
        .iter()
        .filter_map(|k| Some((k.number as u32, k.colour?)))
        .collect();
    let legend = if a.legend {
        // With --below, the segments with a voxel whose CT voxel is below the value.
        let low = a.below.map(|hu| crate::overlay::below_in(&labels, ct, hu));
        let present: std::collections::BTreeSet<u32> = (labels.data.iter().enumerate())
            .filter(|&(n, &v)| v > 0.0 && low.as_ref().is_none_or(|low| low[n]))
            .map(|(_, &v)| v as u32)
            .collect();
        let present: Vec<u32> = present.into_iter().collect();
        let mut entries = crate::legend::entries(&present, &known);
        if let Some(hu) = a.below {
            for e in &mut entries {
                e.name = format!("{} below {hu} HU", e.name);
            }
        }
        entries
    } else {
        Vec::new()
    };
    let mut structures = Vec::new();
    if a.outline
        && let Some(whole) = whole
    {
        structures = whole
            .into_iter()
            .filter(|(_, v)| v.voxels > 0)
            .map(|(l, v)| (l as u32, v))
            .collect();
        structures.sort_by_key(|(_, v)| std::cmp::Reverse(v.voxels));
    }
    Ok(Some(crate::overlay::SegmentOverlay {
        labels,
        colours,
        structures,
        outline: a.outline,
        legend,
        below: a.below,
    }))
}

/// Tints the picture by `labels` at each pixel's point ([`crate::overlay::tint_labels`]): a
/// slice's plane or a CPR's curved surface.
fn tint_segmentation(
    picture: &mut Picture,
    seen: &Seen,
    opt: &DvrOptions,
    (volume, labels): (&raystream_io::Volume, &crate::overlay::SegmentOverlay),
) {
    let Picture::Srgb8 { rgb, width, .. } = picture else {
        return;
    };
    match seen {
        Seen::Camera(cam) => {
            let Some(p) = pixel_plane(opt, volume, cam) else {
                return;
            };
            use raystream_math::DVec3;
            let (o, r, c) = (
                DVec3::from(p.position),
                DVec3::from(p.row),
                DVec3::from(p.column),
            );
            crate::overlay::tint_labels(rgb, *width, labels, volume, |x, y| {
                o + (r * x as f64 + c * y as f64) * p.spacing
            })
        }
        Seen::Curved(plane) => crate::overlay::tint_labels(rgb, *width, labels, volume, |x, y| {
            plane.point(x, y).0.as_dvec3()
        }),
    }
}

/// `--draw-lumen HU`'s lumen options for `volume` (`measure`'s defaults at that threshold).
fn lumen_options(a: &RenderArgs, volume: &raystream_io::Volume) -> Result<Option<LumenOptions>> {
    let Some(hu) = a.draw_lumen else {
        return Ok(None);
    };
    let o = LumenOptions {
        threshold_hu: hu,
        dark: a.draw_dark,
        ..LumenOptions::for_volume(volume)
    };
    o.check()
        .map_err(|e| anyhow::anyhow!("--draw-lumen {hu}: {e}"))?;
    Ok(Some(o))
}

/// `--draw-wall [HU]`'s wall options (`measure --wall`'s at that threshold, -30 HU by
/// default; with `--draw-dark`, an airway's at half maximum, or by the integral with
/// `--draw-wall-edge integral`), checked against
/// `--draw-lumen`'s.
fn wall_options(a: &RenderArgs, volume: &raystream_io::Volume) -> Result<Option<WallOptions>> {
    let (Some(hu), Some(lumen)) = (a.draw_wall, lumen_options(a, volume)?) else {
        return Ok(None);
    };
    let w = match hu {
        Some(hu) if a.draw_dark => bail!(
            "--draw-wall {hu} with --draw-dark: an airway's wall is found at half maximum, with no threshold; give --draw-wall alone"
        ),
        _ if a.draw_dark => AirwayEdge::options(a.draw_wall_edge),
        _ if a.draw_wall_edge.is_some() => bail!(
            "--draw-wall-edge places an airway's wall: give it with --draw-dark (a vessel's wall is found below --draw-wall HU)"
        ),
        Some(hu) => WallOptions::vessel(hu),
        None => WallOptions::default(),
    };
    let what = hu.map_or("--draw-wall".to_string(), |hu| format!("--draw-wall {hu}"));
    w.check(&lumen)
        .map_err(|e| anyhow::anyhow!("{what}: {e}"))?;
    Ok(Some(w))
}

/// `--draw-lumen HU` on a curved reformation: on each row, where the lumen that `measure`
/// finds on the row's plane (through the path's point, along the row and its rays) meets the
/// row, a cyan pixel at each edge; with `--draw-wall`, the outer wall's too, chosen with
/// `track`'s neighbours; whether any was drawn.
fn draw_cpr_lumen(
    a: &RenderArgs,
    picture: &mut Picture,
    plane: &CurvedPlane,
    (volume, track): (&raystream_io::Volume, Option<&Track>),
) -> bool {
    let (Ok(Some(o)), Picture::Srgb8 { rgb, width, height }) = (lumen_options(a, volume), picture)
    else {
        return false;
    };
    let m = raystream_cpu::dvr::Marcher::new(volume, None);
    let wall = wall_options(a, volume).ok().flatten();
    let pb = spinner(
        a.quiet,
        &format!("finding the lumen on the CPR's {} rows", plane.height),
    );
    // Each row's lumen edges, and with --draw-wall the outer wall's.
    let edges: Vec<[Option<[f64; 2]>; 2]> = (0..plane.height)
        .into_par_iter()
        .map(|y| {
            let r = &plane.rows[y as usize];
            let row = raystream_cpu::cpr::CprRow {
                centre: plane.path_point(y),
                ..*r
            };
            let shift = |e: [f64; 2]| e.map(|u| u + plane.shift_mm[y as usize] as f64);
            let prior = track.and_then(|t| t.prior(plane.arc_mm[y as usize], &row));
            raystream_cpu::lumen::across_with_wall(
                volume,
                &m,
                &row,
                &o,
                wall.as_ref(),
                prior.as_ref(),
            )
            .map(|e| e.map(shift))
        })
        .collect();
    pb.finish_and_clear();
    let size = (*width, *height);
    let pixel = plane.pixel_mm as f64;
    let outer: Vec<Option<[f64; 2]>> = edges.iter().map(|e| e[1]).collect();
    let lumen: Vec<Option<[f64; 2]>> = edges.iter().map(|e| e[0]).collect();
    // The wall first, the lumen over it.
    let drawn = crate::overlay::draw_row_edges(rgb, size, pixel, &outer, crate::overlay::WALL);
    crate::overlay::draw_row_edges(rgb, size, pixel, &lumen, crate::overlay::EDGE) | drawn
}

/// `--draw-wall`'s walls along `--path`, each section's by itself ([`Track`]): what a drawn
/// section's neighbours found, as `measure --wall` uses them; found once a command. None
/// without `--path` and `--draw-wall`.
fn wall_track(
    a: &RenderArgs,
    volume: &raystream_io::Volume,
    curve: Option<&Curve>,
) -> Result<Option<Track>> {
    let (Some(curve), Some(o), Some(w)) =
        (curve, lumen_options(a, volume)?, wall_options(a, volume)?)
    else {
        return Ok(None);
    };
    let m = raystream_cpu::dvr::Marcher::new(volume, None);
    Track::along(volume, &m, &curve.points, &o, &w)
        .map(Some)
        .map_err(|e| anyhow::anyhow!("{}: {e}", curve.file.display()))
}

/// `--mark-at MM,…`: a line across a curved reformation's picture where the path is at each
/// arc length; whether any was drawn.
fn mark_path(a: &RenderArgs, picture: &mut Picture, plane: &CurvedPlane) -> bool {
    let rows: Vec<f32> = a
        .mark_at
        .iter()
        .filter_map(|&s| plane.picture_at(s).map(|(y, _)| y))
        .collect();
    if let Picture::Srgb8 { rgb, width, height } = picture {
        crate::overlay::draw_row_marks(rgb, *width, *height, &rows);
    }
    !rows.is_empty()
}

/// `--path FILE`: the curved plane along the path for `opt`'s image, straightened (its cut
/// facing `view`, turned `turn` degrees about the path) or stretched (along `view`'s right
/// turned `turn` degrees as `--orbit` turns it); an error where the path misses the volume
/// (where it leaves it, the picture shows so: no values there).
fn curved_plane(
    file: &Path,
    points: &[raystream_math::DVec3],
    volume: &raystream_io::Volume,
    opt: &DvrOptions,
    (view, turn, kind): (View, f32, CprArg),
    marks: &[f64],
) -> Result<CurvedPlane> {
    let plane = match kind {
        CprArg::Straightened => {
            let right = raystream_cpu::dvr::scene_to_lps(view.basis().col(0)).as_dvec3();
            CurvedPlane::new(points, right, turn as f64, opt.width, opt.height)
        }
        CprArg::Stretched => {
            // The vector of interest: the right of the view turned as --orbit AZ turns it.
            let right = view.orbit(turn, 0.0).basis().col(0);
            let interest = raystream_cpu::dvr::scene_to_lps(right).as_dvec3();
            CurvedPlane::stretched(points, interest, opt.width, opt.height)
        }
    }
    .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    inside(file, &plane, volume)?;
    for &s in marks {
        if plane.picture_at(s).is_none() {
            bail!(
                "--mark-at {s}: not on the path of {} (0 to {:.1} mm along it)",
                file.display(),
                plane.length_mm
            );
        }
    }
    Ok(plane)
}

/// An error where none of `plane`'s rows along the path in `file` lie in `volume`.
pub fn inside(file: &Path, plane: &CurvedPlane, volume: &raystream_io::Volume) -> Result<()> {
    if plane.rows_inside(volume) == 0 {
        let [x, y, z] = plane.rows[0].centre.to_array();
        bail!(
            "{}: the path lies outside the volume (its start ({x:.1}, {y:.1}, {z:.1}) mm LPS; `info` gives the volume's extent): coordinates in LPS mm, or a markups file naming RAS",
            file.display()
        );
    }
    Ok(())
}

/// A curved reformation in words, for the summary and an EXR's comments (ASCII, as an EXR's
/// comments must be).
fn curved_words(file: &Path, plane: &CurvedPlane, opt: &DvrOptions) -> String {
    let layout = match plane.stretched {
        None => format!(
            "straightened: row y at arc length (y + 0.5) * {p:.5} mm from its first point, column x (x + 0.5 - {}) * {p:.5} mm across it",
            0.5 * plane.width as f32,
            p = plane.pixel_mm
        ),
        Some(v) => format!(
            "stretched along ({:.4}, {:.4}, {:.4}) LPS: row y where the path has run (y + 0.5) * {p:.5} mm across that direction, column x (x + 0.5 - {}) * {p:.5} mm along it from the middle of the path's run along it",
            v.x,
            v.y,
            v.z,
            0.5 * plane.width as f32,
            p = plane.pixel_mm
        ),
    };
    format!(
        "; a curved planar reformation along {} ({} points, {:.1} mm) {layout}{}",
        file.display(),
        plane.points,
        plane.length_mm,
        match opt.slab {
            Some(t) => format!(", a slab {t} mm thick about the curved plane"),
            None => String::new(),
        },
    )
}

/// `--labels` needs a patient (a CT volume, its bones, a scene with one) and a PNG.
fn check_labels(a: &RenderArgs, patient: bool, format: ImageFormat) -> Result<()> {
    if a.labels && !patient {
        bail!(
            "{}: --labels marks a patient's directions, for CT volumes and scenes with one",
            input_name(a).display()
        );
    }
    if a.labels && format == ImageFormat::Exr {
        bail!("--labels draws on a PNG; an EXR holds the values themselves");
    }
    if a.legend && format == ImageFormat::Exr {
        bail!("--legend draws on a PNG; an EXR holds the values themselves");
    }
    if a.scale_bar {
        if !patient {
            bail!(
                "{}: --scale-bar measures millimetres: CT volumes, their bones and scenes with one",
                input_name(a).display()
            );
        }
        if format == ImageFormat::Exr {
            bail!("--scale-bar draws on a PNG; an EXR holds the values themselves");
        }
        if projection(a) == Projection::Perspective && a.path.is_none() {
            bail!(
                "--scale-bar: a perspective view has no one scale (near things look larger); give --parallel (--mode slice and a CPR have one)"
            );
        }
    }
    Ok(())
}

/// `--parallel` (and always for `--mode slice`, whose pixels then have one size): the framing
/// camera's projection.
fn projection(a: &RenderArgs) -> Projection {
    if a.parallel || a.mode == Some(crate::cli::ModeArg::Slice) {
        Projection::Parallel
    } else {
        Projection::Perspective
    }
}

/// For an EXR's comments: a parallel projection's pixel size (`height` pixels high), in the
/// scene's units (mm for CT); nothing for a perspective one, whose pixels have no one size.
fn pixel_size(cam: &Camera, height: u32, units: &str) -> String {
    if cam.parallel > 0.0 {
        format!(
            "; parallel projection, pixels {} {units} square",
            2.0 * cam.parallel / height as f32
        )
    } else {
        String::new()
    }
}

/// Where the pixels of a slice, or of a slab's projection, lie in the patient (LPS mm): on the
/// plane through the slice point facing the camera, each where its pixel's ray crosses it, as
/// the renderers sample it (parallel projection only; `None` for a whole-volume projection,
/// whose pixels lie on no one plane, and for HU not written as such).
fn image_plane(
    opt: &DvrOptions,
    volume: &raystream_io::Volume,
    cam: &Camera,
) -> Option<raystream_io::ImagePlane> {
    opt.hu_values
        .then(|| pixel_plane(opt, volume, cam))
        .flatten()
}

/// Where the pixels of a slice, or of a slab's projection, lie in the patient ([`image_plane`],
/// whatever the picture holds).
fn pixel_plane(
    opt: &DvrOptions,
    volume: &raystream_io::Volume,
    cam: &Camera,
) -> Option<raystream_io::ImagePlane> {
    let planar = opt.mode == DvrMode::Slice || (opt.mode.is_windowed() && opt.slab.is_some());
    if !planar || cam.parallel <= 0.0 {
        return None;
    }
    let lps = |v| raystream_cpu::dvr::scene_to_lps(v).as_dvec3();
    let (n, right, up, eye) = (
        lps(cam.fwd).normalize(),
        lps(cam.right),
        lps(cam.up),
        lps(cam.eye),
    );
    let (w, h, half) = (opt.width as f64, opt.height as f64, cam.parallel as f64);
    // The top-left pixel's ray, as Camera::ray casts it through the pixel's centre.
    let (px, py) = ((1.0 / w - 1.0) * (w / h), 1.0 - 1.0 / h);
    let origin = eye + (right * px + up * py) * half;
    let at = opt.slice_point(volume).as_dvec3();
    let position = origin + n * (at - origin).dot(n);
    Some(raystream_io::ImagePlane {
        position: position.to_array(),
        row: right.to_array(),
        column: (-up).to_array(),
        spacing: 2.0 * half / h,
        thickness: opt
            .slab
            .filter(|_| opt.mode != DvrMode::Slice)
            .map(f64::from),
    })
}

/// `--slab`, in words for the summary and an EXR's comments: its thickness and middle.
fn slab_words(opt: &DvrOptions, volume: &raystream_io::Volume) -> String {
    match opt.slab {
        Some(t) => {
            let [x, y, z] = opt.slice_point(volume).to_array();
            format!("; a slab {t} mm thick about ({x:.3}, {y:.3}, {z:.3}) mm LPS")
        }
        None => String::new(),
    }
}

/// The unit of the scene's coordinates: mm for a CT volume's bones.
fn units(bones: &Option<Bones>) -> &'static str {
    match bones {
        Some(_) => "mm",
        None => "scene units",
    }
}

/// `--orbit AZ,EL`, or no turn.
fn orbit_angles(a: &RenderArgs) -> [f32; 2] {
    a.orbit.unwrap_or([0.0; 2])
}

/// `render VOLUME --mode …`: direct volume rendering on the CPU (the reference path).
fn render_direct(a: &RenderArgs, mode: DvrMode) -> Result<()> {
    let backend = open_device(a.accel.device, a.accel.adapter.as_deref(), a.quiet)?;
    let (path, embedded) = match a.input.as_deref() {
        None => (Path::new(DEFAULT_CT_NAME), Some(DEFAULT_CT)),
        Some(p) if raystream_io::is_volume_path(p) => (p, None),
        Some(p) => bail!(
            "{}: --mode {} renders CT volumes (DICOM, NIfTI, NRRD, MetaImage, VTK, raw), not meshes or scenes",
            p.display(),
            mode.name()
        ),
    };
    let frames = a.turntable.is_some() || a.slices.is_some() || a.cine || a.fly.is_some();
    let format = picture_format(a, frames)?;
    check_labels(a, true, format)?;
    check_path(a, mode)?;
    // A curved reformation's path, read before the volume: a bad one fails at once.
    let curve = match &a.path {
        Some(file) => Some(Curve {
            file,
            points: raystream_io::read_curve(file)?,
        }),
        None => None,
    };
    let overlay = match &a.draw_path {
        Some(file) => Some(raystream_cpu::cpr::spline(&raystream_io::read_curve(file)?)),
        None => None,
    };
    let overlay = overlay.as_deref();
    if a.draw_path.is_some() && format == ImageFormat::Exr {
        bail!("--draw-path draws on a PNG; an EXR holds the values themselves");
    }
    if a.draw_lumen.is_some() && format == ImageFormat::Exr {
        bail!("--draw-lumen draws on a PNG; an EXR holds the values themselves");
    }
    if !a.mark_at.is_empty() && format == ImageFormat::Exr {
        bail!("--mark-at draws on a PNG; an EXR holds the values themselves");
    }
    // A cine reads its phases one by one, the first here (no warning that it chose one).
    let mut select = a.pick.select();
    if a.cine {
        select.phase = Some(1);
    }
    let (volume, load_ms) = read_volume(path, &select, a.quiet, embedded)?;
    let lone = crate::common::lone_slice_view(&volume);
    // The body of the CT as read (a lone slice's, not its slab's twice), then on the grid
    // drawn.
    let mut volume = volume;
    let body = match a.body_only {
        true => Some(crate::body::find(&volume, path, a.quiet)?),
        false => None,
    };
    if let Some(b) = body.as_ref().filter(|_| !mode.is_projection()) {
        b.hide_outside(&mut volume);
    }
    let body = body.map(|b| crate::body::on_slab(b, &volume));
    let volume = crate::common::slab_if_lone(volume, path, a.quiet);
    let labels = segmentation(a, format, &volume)?;
    // Every other mode colours (dvr, iso, cinematic) or keeps to segments (--segment).
    let painted = if mode == DvrMode::Slice {
        if let Some(list) = &a.segment {
            bail!(
                "--segment {list} with --mode slice: a slice is tinted by every segment of --segmentation (--segment keeps segments in dvr, iso, cinematic and mip)"
            );
        }
        None
    } else {
        if a.segmentation.is_some() && a.outline {
            bail!("--outline draws each segment's edge over a slice: give --mode slice");
        }
        if let Some(f) = a.segmentation.as_ref().filter(|_| a.cine) {
            bail!(
                "--segmentation {} with --cine: the segmentation is laid on one phase's grid; render phases one by one (--phase K)",
                f.display()
            );
        }
        crate::segments::paint(crate::segments::Asked::of_render(a), mode, &volume, path)?
    };
    let (mut volume, mut painted) = match painted {
        Some(mut p) => (p.kept.take().unwrap_or(volume), Some(p)),
        None => (volume, None),
    };
    if let Some(b) = body.as_ref().filter(|_| mode.is_projection()) {
        painted = Some(crate::body::projected(mode, &mut volume, painted, b));
    }
    let mut segment_words = painted
        .as_ref()
        .map_or(String::new(), |p| format!("; {}", p.words));
    if a.legend && matches!(mode, DvrMode::Mip | DvrMode::MinIp | DvrMode::Average) {
        bail!(
            "--legend names the colours of segments; --mode {} shows HU, with no segment in colour",
            mode.name()
        );
    }
    let legend: &[crate::legend::Entry] = match (&labels, a.legend) {
        (_, false) => &[],
        (Some(l), true) => &l.legend,
        (None, true) => painted.as_ref().map_or(&[], |p| &p.legend),
    };
    if a.legend && legend.is_empty() {
        match &a.segmentation {
            Some(file) => bail!(
                "{}: --legend names the segments drawn in colour, and none of its segments is drawn in this image (none holds a voxel shown{})",
                file.display(),
                match a.below {
                    Some(hu) => format!(" below {hu}"),
                    None => String::new(),
                }
            ),
            None => bail!(
                "--legend names the segments drawn in colour: give --segmentation LABELS (a label map, DICOM Segmentation or RT Structure Set)"
            ),
        }
    }
    let labels = Labels {
        overlay: labels.as_ref(),
        legend,
    };
    let track = wall_track(a, &volume, curve.as_ref())?;
    let (mut tf, mut opt) = dvr::options(&a.look, &a.threshold, mode, a.size)?;
    // An average kept to segments is windowed on their values unless --window says.
    if let Some((w, l)) = painted.as_ref().and_then(|p| p.window)
        && opt.window.is_none()
    {
        opt.window = Some((w, l));
        segment_words += &format!(
            ", window {w:.0}/{l:.0} HU (their voxels' median, twice their 10th to 90th percentile)"
        );
    }
    let unit_free = (&a.look, &a.threshold);
    let window_from_projection =
        dvr::unit_free_defaults(unit_free, (&volume, path), a.quiet, &mut tf, &mut opt);
    if mode == DvrMode::Cinematic {
        opt.spp = a.spp.unwrap_or(opt.spp);
        opt.bounces = a.max_depth;
        if opt.denoise && opt.spp < 2 {
            bail!(
                "--denoise with --spp {}: the filter is steered by each pixel's variance, which takes at least 2 paths a pixel",
                opt.spp
            );
        }
    } else if a.spp.is_some() {
        bail!(
            "--spp with --mode {}: one ray a pixel (--spp is for meshes, scenes and --mode cinematic)",
            mode.name()
        );
    }
    // An EXR keeps what the projections found, in HU; the window is for display. So does a
    // DICOM picture, with the window as its VOI LUT, unless letters are drawn into it.
    let dicom_out = if frames {
        a.format == FrameFormat::Dcm
    } else {
        crate::common::is_dicom(&a.output)
    };
    // Letters or a path drawn need the picture as seen.
    let drawn = a.labels
        || a.scale_bar
        || a.draw_path.is_some()
        || a.draw_lumen.is_some()
        || !a.mark_at.is_empty()
        || labels.overlay.is_some()
        || !labels.legend.is_empty();
    opt.hu_values = format == ImageFormat::Exr || (dicom_out && mode.is_windowed() && !drawn);
    let aspect = opt.width as f32 / opt.height as f32;
    let renderer = dvr::Renderer::new(
        &backend,
        &volume,
        &tf,
        painted.as_ref().and_then(|p| p.colours.as_ref()),
        painted.as_ref().and_then(|p| p.weights.as_ref()),
    )?;
    let view = base_view(a, lone_or(a, lone, VOLUME_VIEW), true)?;
    let [az, el] = orbit_angles(a);
    let cam = volume_camera_from(&volume, aspect, view.orbit(az, el), projection(a));
    if let Some(w) = window_from_projection {
        // From the first view: a turntable's or a cine's frames share the one window.
        w.set_by_probe(&renderer, &mut opt, &cam)?;
    }
    if let Some(n) = a.turntable {
        return turntable(
            a,
            (&renderer, &volume, overlay, track.as_ref()),
            labels,
            &opt,
            (view, curve.as_ref()),
            n,
            format,
        );
    }
    if let (Some(n), Some(curve)) = (a.fly, &curve) {
        return fly_through(
            a,
            (&renderer, &volume, labels),
            &opt,
            (view, curve),
            n,
            format,
        );
    }
    if let (Some(n), Some(curve)) = (a.slices, &curve) {
        return path_sections(
            a,
            (&renderer, &volume, track.as_ref()),
            labels,
            &opt,
            (view, curve),
            n,
            format,
        );
    }
    if let Some(n) = a.slices {
        return slice_series(
            a,
            (&renderer, &volume, overlay, labels),
            &opt,
            &cam,
            n,
            format,
        );
    }
    if a.cine {
        if a.draw_lumen.is_some() {
            bail!(
                "--draw-lumen with --cine: the lumen would be the first phase's on every frame; draw it on one (--phase K)"
            );
        }
        // A CPR of each phase, along the one path, or the one camera's view.
        let seen = seen_from(a, &volume, &opt, (view, curve.as_ref()), az)?;
        return cine(
            a,
            (path, &volume, renderer),
            (&backend, &tf, overlay, labels),
            &opt,
            &seen,
            format,
        );
    }
    let seen = seen_from(a, &volume, &opt, (view, curve.as_ref()), az)?;
    let what = format!(
        "{} of {}x{}x{} voxels",
        mode.name(),
        volume.dims[0],
        volume.dims[1],
        volume.dims[2]
    );
    // A path-traced frame may take minutes: a bar of its paths, fed as they finish (by pixel
    // on the CPU, by dispatch on the GPU). The other modes take seconds at most.
    let pb = if mode == DvrMode::Cinematic && !a.quiet {
        let total = opt.width as u64 * opt.height as u64 * opt.spp as u64 * a.repeat as u64;
        let pb = ProgressBar::new(total).with_style(
            ProgressStyle::with_template(
                "{bar:30} {percent} % of the paths, {msg} [{elapsed}, {eta} left]",
            )
            .unwrap(),
        );
        pb.set_message(what);
        pb
    } else {
        spinner(a.quiet, &what)
    };
    let mut frame_ms = Vec::new();
    let mut kernel_ms = Vec::new();
    let mut last = None;
    let start = renderer.paths_done();
    let finished = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| -> Result<()> {
        if mode == DvrMode::Cinematic && !a.quiet {
            s.spawn(|| {
                while !finished.load(std::sync::atomic::Ordering::Relaxed) {
                    pb.set_position(renderer.paths_done() - start);
                    std::thread::sleep(std::time::Duration::from_millis(200));
                }
            });
        }
        let frames = (|| {
            for _ in 0..a.repeat {
                let f = renderer.frame(&opt, seen.sight(), format)?;
                frame_ms.push(f.frame_ms);
                kernel_ms.extend(f.kernel_ms);
                last = Some(f);
            }
            Ok(())
        })();
        finished.store(true, std::sync::atomic::Ordering::Relaxed);
        frames
    })?;
    pb.finish_and_clear();
    let mut frame = last.expect("at least one frame");
    let slab = match (&seen, &a.path) {
        (Seen::Curved(plane), Some(file)) => curved_words(file, plane, &opt),
        _ => slab_words(&opt, &volume),
    };
    let dicom = volume_dicom(
        a,
        &mut frame.picture,
        &seen,
        &opt,
        (&volume, overlay, track.as_ref(), labels),
    );
    frame
        .picture
        .save(&a.output, &exr_comment(a, &opt, &volume, &seen), &dicom)?;
    if !a.quiet {
        let median = median_of(&mut frame_ms);
        let format_words = match format {
            _ if opt.hu_values && dicom_out => ", HU values with the window as VOI LUT",
            ImageFormat::Exr if mode.is_windowed() => ", HU values, no window",
            ImageFormat::Exr => ", premultiplied float RGBA",
            ImageFormat::Png => "",
        };
        // What was rendered, and what the samples were beyond their count.
        let (what, counts) = if mode == DvrMode::Cinematic {
            let what = format!(
                ", {} paths a pixel, up to {} scatterings{}{}{format_words}{slab}",
                opt.spp,
                opt.bounces,
                cinematic_words(&opt),
                match frame.denoise {
                    Some(d) => format!(
                        ", denoised (guides {:.0} ms, filter {:.0} ms)",
                        d.guides_ms, d.filter_ms
                    ),
                    None => String::new(),
                }
            );
            (what, String::new())
        } else {
            let gpu = frame.stats.is_none();
            let stats = frame
                .stats
                .unwrap_or_else(|| dvr::estimate_stats(&volume, &tf, &opt, seen.sight()));
            // Three decimals, or three significant digits for a step below 0.01 mm (a
            // microscope's voxels, or a march held to its sample budget).
            let step = if stats.step_mm >= 0.01 {
                format!("{:.3}", stats.step_mm)
            } else {
                format!("{:.3e}", stats.step_mm)
            };
            let what = format!("{format_words}{slab}, step {step} mm");
            let counts = format!(
                ", {} skipped as empty ({:.0} %{}){}",
                stats.skipped,
                100.0 * stats.skipped as f64 / (stats.samples + stats.skipped).max(1) as f64,
                if gpu { ", estimated on the CPU" } else { "" },
                if opt.shadows {
                    format!(
                        ", {} shadow-ray samples{}",
                        stats.shadow_samples,
                        if gpu { " (estimated on the CPU)" } else { "" }
                    )
                } else {
                    String::new()
                }
            );
            (what, counts)
        };
        eprintln!(
            "raystream: wrote {} ({}x{}, --mode {}{}, {}{what}{segment_words}) on {} ({}): load {:.0} ms, render {:.1} ms ({:.2} frames/s{}){}, {} samples{counts}, {:.1} M samples/s",
            a.output.display(),
            opt.width,
            opt.height,
            mode.name(),
            if opt.shadows { " --shadows" } else { "" },
            interpolation_words(opt.interpolation),
            backend.name(),
            backend.adapter(),
            load_ms,
            median,
            1e3 / median,
            median_words(a.repeat),
            kernel_words(&mut kernel_ms),
            frame.samples,
            frame.samples as f64 / median / 1e3
        );
    }
    Ok(())
}

/// How the volume was read between its voxels, as the summary line says it.
pub fn interpolation_words(i: raystream_cpu::dvr::Interpolation) -> &'static str {
    match i {
        raystream_cpu::dvr::Interpolation::Linear => "trilinear",
        raystream_cpu::dvr::Interpolation::Cubic => "cubic B-spline",
        raystream_cpu::dvr::Interpolation::CubicInterpolating => "interpolating cubic B-spline",
    }
}

/// ", anisotropy G, +E EV" for a cinematic frame's medium and lights other than the default.
fn cinematic_words(opt: &DvrOptions) -> String {
    let mut w = String::new();
    if opt.anisotropy != 0.0 {
        w += &format!(", anisotropy {}", opt.anisotropy);
    }
    if opt.exposure != 0.0 {
        w += &format!(", {:+} EV", opt.exposure);
    }
    w
}

/// ", median of N" after a time of N > 1 repeats.
fn median_words(repeat: u32) -> String {
    if repeat > 1 {
        format!(", median of {repeat}")
    } else {
        String::new()
    }
}

/// ", kernel X ms", the median of the GPU kernel's times, if it has any.
fn kernel_words(kernel_ms: &mut [f64]) -> String {
    if kernel_ms.is_empty() {
        String::new()
    } else {
        format!(", kernel {:.2} ms", median_of(kernel_ms))
    }
}

/// `--path`: a curved reformation samples the curved plane (`--mode slice`) or projects a slab
/// about it (mip, minip, average with `--slab`), turned about the path by `--orbit AZ` alone.
fn check_path(a: &RenderArgs, mode: DvrMode) -> Result<()> {
    let Some(file) = &a.path else {
        return Ok(());
    };
    let file = file.display();
    if a.fly.is_some() {
        if !matches!(mode, DvrMode::Dvr | DvrMode::Iso | DvrMode::Cinematic) {
            bail!(
                "--fly with --mode {}: a fly-through looks ahead from inside, through a transfer function (--mode dvr, iso or cinematic); a projection along the path is a CPR (--path with --slab)",
                mode.name()
            );
        }
        if !(a.fov > 0.0 && a.fov < 180.0) {
            bail!(
                "--fov {}: the field of view lies between 0 and 180 degrees",
                a.fov
            );
        }
        if a.orbit.is_some() || a.parallel || a.scale_bar {
            bail!(
                "--path {file} --fly: the camera rides the path, looking ahead in perspective (--orbit, --parallel and --scale-bar do not apply)"
            );
        }
        if !a.mark_at.is_empty() || a.draw_lumen.is_some() || a.cpr == CprArg::Stretched {
            bail!(
                "--path {file} --fly: a fly-through is no CPR (--mark-at, --draw-lumen and --cpr draw on one)"
            );
        }
        return Ok(());
    }
    match mode {
        DvrMode::Slice => {}
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average if a.look.slab.is_some() => {}
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average => bail!(
            "--path {file} with --mode {}: give the slab's thickness about the curved plane with --slab MM (or --mode slice for the plane itself)",
            mode.name()
        ),
        DvrMode::Dvr | DvrMode::Iso | DvrMode::Cinematic => bail!(
            "--path {file}: a curved reformation is --mode slice, or mip, minip, average with --slab (not --mode {})",
            mode.name()
        ),
    }
    if let Some([_, el]) = a.orbit
        && el != 0.0
    {
        bail!("--path {file} --orbit AZ,{el}: a curved reformation turns about its path (AZ) only");
    }
    if a.labels && a.slices.is_none() {
        bail!(
            "--path {file} --labels: a curved reformation's rows follow the path, no patient direction; its cross-sections (--slices N) take letters"
        );
    }
    if a.cpr == CprArg::Stretched && a.slices.is_some() {
        bail!(
            "--path {file} --slices N --cpr stretched: cross-sections are perpendicular to the path however its CPR is laid out; drop --cpr"
        );
    }
    Ok(())
}

/// What an EXR of a direct rendering holds, for its comments: the channels, the slab and, in a
/// parallel projection, the pixel size.
fn exr_comment(
    a: &RenderArgs,
    opt: &DvrOptions,
    volume: &raystream_io::Volume,
    seen: &Seen,
) -> String {
    let mode = opt.mode;
    let cam = match seen {
        Seen::Camera(cam) => cam,
        Seen::Curved(plane) => {
            let what = match mode {
                DvrMode::Slice => "HU on the curved plane".to_string(),
                _ => format!("the {} of the HU values along each ray", mode.name()),
            };
            let file = a.path.as_deref().unwrap_or(Path::new("?"));
            return format!(
                "Y: {what} (no window); NaN: outside the volume or its crop{}; pixels {} mm square; interpolation {}",
                curved_words(file, plane, opt),
                plane.pixel_mm,
                interpolation_words(opt.interpolation)
            );
        }
    };
    let what = if opt.hu_values && mode == DvrMode::Slice {
        let [x, y, z] = opt.slice_point(volume).to_array();
        let [nx, ny, nz] = raystream_cpu::dvr::scene_to_lps(cam.fwd).to_array();
        format!(
            "Y: HU on the plane through ({x:.3}, {y:.3}, {z:.3}) mm LPS, normal ({nx:.6}, {ny:.6}, {nz:.6}) (no window); NaN: outside the volume or its crop"
        )
    } else if opt.hu_values && mode.is_windowed() {
        format!(
            "Y: the {} of the HU values along each ray (no window); NaN: no sample",
            mode.name()
        )
    } else {
        format!(
            "premultiplied linear RGBA, --mode {}: the volume's light and opacity, no background",
            mode.name()
        )
    };
    format!(
        "{what}{}{}; interpolation {}",
        slab_words(opt, volume),
        pixel_size(cam, opt.height, "mm"),
        interpolation_words(opt.interpolation)
    )
}

/// `render --mode … --turntable N -o DIR`: N frames about `view`'s up axis (the patient's
/// superior axis unless the view is from above or below), from `--orbit`'s angles on.
fn turntable(
    a: &RenderArgs,
    (renderer, volume, overlay, track): (
        &dvr::Renderer,
        &raystream_io::Volume,
        Overlay,
        Option<&Track>,
    ),
    labels: Labels,
    opt: &DvrOptions,
    look: (View, Option<&Curve>),
    n: u32,
    format: ImageFormat,
) -> Result<()> {
    let [az, _] = orbit_angles(a);
    let drawn = (volume, overlay, track, labels);
    frame_series(a, drawn, n, format, "turntable", |i| {
        let seen = seen_from(a, volume, opt, look, az + 360.0 * i as f32 / n as f32)?;
        Ok((renderer.frame(opt, seen.sight(), format)?, seen, *opt))
    })
}

/// `render --mode dvr|iso|cinematic --path FILE --fly N -o DIR`: a fly-through, N frames
/// from cameras on the path at the middles of N equal parts of it (or `--slice-step` apart
/// about `--path-at`, as cross-sections are), each looking ahead along it
/// ([`CurvedPlane::ahead_camera`]), `--fov` degrees high: a virtual endoscopy of the lumen
/// the path runs in.
fn fly_through(
    a: &RenderArgs,
    (renderer, volume, labels): (&dvr::Renderer, &raystream_io::Volume, Labels),
    opt: &DvrOptions,
    (view, curve): (View, &Curve),
    n: u32,
    format: ImageFormat,
) -> Result<()> {
    let right = raystream_cpu::dvr::scene_to_lps(view.basis().col(0)).as_dvec3();
    let spacing = raystream_cpu::cpr::Spacing {
        step_mm: a.slice_step.map(f64::from),
        centre_mm: a.path_at,
    };
    let stations = CurvedPlane::sections_spaced(&curve.points, right, 0.0, n, spacing)
        .map_err(|e| anyhow::anyhow!("{}: {e}", curve.file.display()))?;
    inside(curve.file, &stations, volume)?;
    frame_series(
        a,
        (volume, None, None, labels),
        n,
        format,
        "fly-through",
        |i| {
            let cam = stations.ahead_camera(i, a.fov);
            let seen = Seen::Camera(cam);
            Ok((renderer.frame(opt, seen.sight(), format)?, seen, *opt))
        },
    )
}

/// `render --mode slice --path FILE --slices N -o DIR` (or a projection's `--slab`): N
/// cross-sections of the path, each perpendicular to it at the arc length (i + ½)·L/N (with
/// `--slice-step MM`, MM apart about its middle), centred on it at the volume's finest
/// spacing a pixel (or `--field MM` high), the CPR's lateral direction to the right: the
/// planes a vessel's diameter is measured on, as reformatted CT images with their planes.
fn path_sections(
    a: &RenderArgs,
    (renderer, volume, track): (&dvr::Renderer, &raystream_io::Volume, Option<&Track>),
    labels: Labels,
    opt: &DvrOptions,
    (view, curve): (View, &Curve),
    n: u32,
    format: ImageFormat,
) -> Result<()> {
    let [az, _] = orbit_angles(a);
    let right = raystream_cpu::dvr::scene_to_lps(view.basis().col(0)).as_dvec3();
    let spacing = raystream_cpu::cpr::Spacing {
        step_mm: a.slice_step.map(f64::from),
        centre_mm: a.path_at,
    };
    let stations = CurvedPlane::sections_spaced(&curve.points, right, az as f64, n, spacing)
        .map_err(|e| anyhow::anyhow!("{}: {e}", curve.file.display()))?;
    inside(curve.file, &stations, volume)?;
    let half_height = match a.field {
        Some(mm) if !(mm.is_finite() && mm > 0.0 && mm <= 1e5) => {
            bail!("--field {mm}: a cross-section's height must be above 0 mm, and at most 100 m")
        }
        Some(mm) => 0.5 * mm,
        None => 0.5 * raystream_cpu::dvr::min_spacing(volume) * opt.height as f32,
    };
    let reach = volume.diagonal_mm() as f32;
    let lumen =
        lumen_options(a, volume)?.map(|o| (o, raystream_cpu::dvr::Marcher::new(volume, None)));
    let wall = wall_options(a, volume)?;
    // Each section tinted here, under its lumen and wall (the legend drawn with the letters).
    let legend_only = Labels {
        overlay: None,
        ..labels
    };
    frame_series(
        a,
        (volume, None, None, legend_only),
        n,
        format,
        "slices",
        |i| {
            let cam = stations.section_camera(i, half_height, reach);
            let row = &stations.rows[i as usize];
            let opt = DvrOptions {
                slice_at: Some(row.centre),
                ..*opt
            };
            let mut f = renderer.frame(&opt, &cam, format)?;
            if let Some(l) = labels.overlay {
                tint_segmentation(&mut f.picture, &Seen::Camera(cam), &opt, (volume, l));
            }
            if let (Some((o, m)), crate::common::Picture::Srgb8 { rgb, width, height }) =
                (&lumen, &mut f.picture)
                && let Some(found) = raystream_cpu::lumen::measure_with_wall(
                    volume,
                    m,
                    row,
                    o,
                    wall.as_ref(),
                    track
                        .and_then(|t| t.prior(stations.arc_mm[i as usize], row))
                        .as_ref(),
                )
            {
                let size = (*width, *height);
                if let Some((_, outline)) = &found.wall {
                    crate::overlay::draw_wall(rgb, size, &cam, row, outline);
                }
                crate::overlay::draw_lumen(rgb, size, &cam, row, (&found.lumen, &found.edge));
            }
            Ok((f, Seen::Camera(cam), opt))
        },
    )
}

/// `--draw-path FILE`'s spline, sampled densely (LPS mm), drawn over every frame of a camera.
type Overlay<'a> = Option<&'a [raystream_math::DVec3]>;

/// `--segmentation FILE` over every frame: its segments laid over a slice or CPR, and
/// `--legend`'s list of the segments drawn (empty without it).
#[derive(Clone, Copy, Default)]
struct Labels<'a> {
    overlay: Option<&'a crate::overlay::SegmentOverlay>,
    legend: &'a [crate::legend::Entry],
}

/// `--path FILE`'s points, read once.
struct Curve<'a> {
    file: &'a Path,
    points: Vec<raystream_math::DVec3>,
}

/// What sees the volume from `view` turned `az` degrees (`--orbit`'s elevation kept): the
/// framing camera, or with a `curve` the curved plane along it.
fn seen_from(
    a: &RenderArgs,
    volume: &raystream_io::Volume,
    opt: &DvrOptions,
    (view, curve): (View, Option<&Curve>),
    az: f32,
) -> Result<Seen> {
    let [_, el] = orbit_angles(a);
    Ok(match curve {
        Some(c) => Seen::Curved(Box::new(curved_plane(
            c.file,
            &c.points,
            volume,
            opt,
            (view, az, a.cpr),
            &a.mark_at,
        )?)),
        None => Seen::Camera(volume_camera_from(
            volume,
            opt.width as f32 / opt.height as f32,
            view.orbit(az, el),
            projection(a),
        )),
    })
}

/// `render --mode slice --slices N [--slice-step MM] -o DIR` (or a projection's `--slab`): N
/// parallel planes facing the camera, `--slice-step` apart (default: the pixel size, for cubic
/// voxels), centred on `--slice-at` (default: the volume's centre), the first nearest the
/// camera: a reformatted series (coronal, sagittal, oblique; thin slices or slabs).
fn slice_series(
    a: &RenderArgs,
    (renderer, volume, overlay, labels): (&dvr::Renderer, &raystream_io::Volume, Overlay, Labels),
    opt: &DvrOptions,
    cam: &Camera,
    n: u32,
    format: ImageFormat,
) -> Result<()> {
    if opt.mode != DvrMode::Slice && opt.slab.is_none() {
        bail!(
            "--slices steps the plane of --mode slice, or a --slab, through the volume (not --mode {} alone)",
            opt.mode.name()
        );
    }
    let step = match a.slice_step {
        Some(s) if s.is_finite() && s > 0.0 => s,
        Some(s) => bail!("--slice-step {s}: the step must be a positive number of mm"),
        None if cam.parallel > 0.0 => 2.0 * cam.parallel / opt.height as f32,
        None => bail!("--slices without --parallel: give the step with --slice-step MM"),
    };
    let normal = raystream_cpu::dvr::scene_to_lps(cam.fwd).normalize();
    let centre = opt.slice_point(volume);
    frame_series(
        a,
        (volume, overlay, None, labels),
        n,
        format,
        "slices",
        |i| {
            let offset = (i as f32 - (n - 1) as f32 / 2.0) * step;
            let opt = DvrOptions {
                slice_at: Some(centre + normal * offset),
                ..*opt
            };
            Ok((renderer.frame(&opt, cam, format)?, Seen::Camera(*cam), opt))
        },
    )
}

/// `render --mode … --cine -o DIR`: a frame of each temporal position of a 4-D CT (`first` is
/// phase 1, read already, with its renderer), in order, all seen by `seen` with `opt` (the
/// camera, or with `--path` the one curved plane along it: a CPR of each phase): the heart's or
/// the lungs' motion as a loop. Each later phase is read, uploaded and rendered in
/// turn, one volume in memory at a time; all must share phase 1's grid.
fn cine(
    a: &RenderArgs,
    (path, first, renderer): (&Path, &raystream_io::Volume, dvr::Renderer),
    (backend, tf, overlay, labels): (
        &Backend,
        &raystream_volume::TransferFunction,
        Overlay,
        Labels,
    ),
    opt: &DvrOptions,
    seen: &Seen,
    format: ImageFormat,
) -> Result<()> {
    let n = first.phase.count;
    if n < 2 {
        bail!(
            "{}: --cine renders each temporal position of a 4-D CT, and this image has one (info shows a volume's phases)",
            path.display()
        );
    }
    let mut warnings = Vec::new();
    frame_series(
        a,
        (first, overlay, None, labels),
        n as u32,
        format,
        "cine",
        |i| {
            if i == 0 {
                return Ok((
                    renderer.frame(opt, seen.sight(), format)?,
                    seen.clone(),
                    *opt,
                ));
            }
            let select = raystream_io::VolumeSelect {
                phase: Some(i as usize + 1),
                ..a.pick.select()
            };
            let volume = raystream_io::load_volume(path, &select)?;
            let volume = volume.slab_of_lone_slices().unwrap_or(volume);
            let grid = |v: &raystream_io::Volume| (v.dims, v.spacing, v.origin, v.direction);
            if grid(&volume) != grid(first) {
                bail!(
                    "{}: phase {} lies on another grid than phase 1 ({:?} voxels of {:?} mm at {:?} against {:?} of {:?} at {:?}): a cine needs one",
                    path.display(),
                    i + 1,
                    volume.dims,
                    volume.spacing,
                    volume.origin,
                    first.dims,
                    first.spacing,
                    first.origin
                );
            }
            for w in volume
                .warnings
                .iter()
                .filter(|w| !first.warnings.contains(w))
            {
                warnings.push(format!("phase {}: {w}", i + 1));
            }
            let frame = dvr::Renderer::new(backend, &volume, tf, None, None)?.frame(
                opt,
                seen.sight(),
                format,
            )?;
            Ok((frame, seen.clone(), *opt))
        },
    )?;
    if !a.quiet {
        for w in warnings {
            eprintln!("raystream: {}: {w}", path.display());
        }
    }
    Ok(())
}

/// The pictures' format: a series of `frames` (a turntable's, a slice series', a cine's) are
/// files in a folder, in --format (DICOM frames are the PNGs' pictures); one picture, as `-o`
/// names it.
fn picture_format(a: &RenderArgs, frames: bool) -> Result<ImageFormat> {
    Ok(match (frames, a.format) {
        (true, FrameFormat::Png | FrameFormat::Dcm | FrameFormat::Apng | FrameFormat::Gif) => {
            ImageFormat::Png
        }
        (true, FrameFormat::Exr) => ImageFormat::Exr,
        (false, _) => image_format(&a.output)?,
    })
}

/// Where a series of frames goes: files in the folder `-o` names (the frames' extension, the
/// width of their numbers, the DICOM series they make for .dcm frames), or one animation `-o`
/// names (--format apng, gif); and the progress bar.
struct FrameFolder<'a> {
    dir: &'a Path,
    ext: &'static str,
    digits: usize,
    series: String,
    animation: Option<Animation>,
    /// The frames' files, written on a thread of their own while the next frame renders (a
    /// 1024² PNG's encoding takes as long as a slice's render); not for an animation.
    saver: Option<Pipeline<(PathBuf, Picture, String, DicomOut), ()>>,
    pb: ProgressBar,
}

/// A frame of a folder saved to its file (`FrameFolder::saver`'s work).
fn save_frame(
    _: &mut (),
    (path, picture, what, dicom): (PathBuf, Picture, String, DicomOut),
    _: usize,
) -> std::result::Result<(), String> {
    picture
        .save(&path, &what, &dicom)
        .map_err(|e| format!("{e:#}"))
}

/// An animation's container and rate, and its writer once the first frame gives its size.
struct Animation {
    kind: raystream_cpu::animation::AnimationKind,
    fps: u32,
    frames: u32,
    writer: Option<raystream_cpu::animation::AnimationWriter>,
}

impl<'a> FrameFolder<'a> {
    /// The folder for `n` frames of `--what` in `format` (`--format dcm`: DICOM), created; a
    /// name like an image's is refused. With --format apng or gif, the animation `-o` names,
    /// which must end as its container does.
    fn new(a: &'a RenderArgs, n: u32, format: ImageFormat, what: &str) -> Result<Self> {
        let dir = a.output.as_path();
        let animation = a.format.animation();
        let ext = match (format, a.format) {
            (_, FrameFormat::Dcm) => "dcm",
            (ImageFormat::Png, _) => "png",
            (ImageFormat::Exr, _) => "exr",
        };
        if let Some(kind) = animation {
            let named = dir
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case(kind.extension()));
            if !named {
                bail!(
                    "{}: --format {} writes one animation; name it NAME.{} with -o",
                    dir.display(),
                    kind.name(),
                    kind.extension()
                );
            }
            if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent)
                    .with_context(|| format!("{}: cannot create", parent.display()))?;
            }
        } else {
            if let Some(fps) = a.fps {
                bail!(
                    "--fps {fps}: the rate of an animation; give --format apng or gif (frames in a folder have none)"
                );
            }
            if crate::common::image_format(dir).is_ok() {
                bail!(
                    "{}: --{what} writes frame_000.{ext} … into a folder; name the folder with -o",
                    dir.display()
                );
            }
            std::fs::create_dir_all(dir)
                .with_context(|| format!("{}: cannot create", dir.display()))?;
        }
        let pb = if a.quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(n as u64).with_style(
                ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} frames")
                    .expect("valid template"),
            )
        };
        pb.set_message(what.to_string());
        Ok(FrameFolder {
            dir,
            ext,
            digits: ((n - 1).max(1).ilog10() as usize + 1).max(3),
            series: raystream_io::new_uid(),
            animation: animation.map(|kind| Animation {
                kind,
                fps: a.fps.unwrap_or(DEFAULT_FPS),
                frames: n,
                writer: None,
            }),
            saver: animation.is_none().then(|| Pipeline::spawn((), save_frame)),
            pb,
        })
    }

    /// Frame `i`'s file.
    fn path(&self, i: u32) -> PathBuf {
        self.dir
            .join(format!("frame_{i:0w$}.{}", self.ext, w = self.digits))
    }

    /// Writes frame `i` (in order): its own file, `what` in an EXR's comments and `dicom`
    /// describing a DICOM frame; or the animation's next frame. Both are written on a thread of
    /// their own: an error of an earlier frame's file is returned here or by `finish`.
    fn write(&mut self, i: u32, picture: Picture, what: String, dicom: DicomOut) -> Result<()> {
        match &mut self.animation {
            None => {
                let path = self.path(i);
                self.saver
                    .as_mut()
                    .expect("a folder's frames are saved")
                    .send((path, picture, what, dicom))
                    .map_err(anyhow::Error::msg)?;
            }
            Some(anim) => {
                let Picture::Srgb8 { rgb, width, height } = picture else {
                    unreachable!("an animation's frames are rendered as PNGs")
                };
                let writer = match &mut anim.writer {
                    Some(w) => w,
                    None => anim.writer.insert(
                        raystream_cpu::animation::AnimationWriter::create(
                            self.dir,
                            anim.kind,
                            (width, height),
                            anim.frames,
                            anim.fps,
                        )
                        .map_err(anyhow::Error::msg)?,
                    ),
                };
                writer.push(rgb).map_err(anyhow::Error::msg)?;
            }
        }
        self.pb.inc(1);
        Ok(())
    }

    /// Ends the series (an animation's file), and says what was written, unless --quiet:
    /// `how` the frames were made and `timing` the render's figures.
    fn finish(mut self, n: u32, how: &str, timing: &str, quiet: bool) -> Result<()> {
        if let Some(saver) = &mut self.saver {
            saver.finish().map_err(anyhow::Error::msg)?;
        }
        self.pb.finish_and_clear();
        let (to, format) = match self.animation {
            Some(anim) => {
                anim.writer
                    .expect("at least one frame")
                    .finish()
                    .map_err(anyhow::Error::msg)?;
                // A GIF's rate is seldom whole (15 asked plays at 14.286).
                let played = anim.kind.played_fps(anim.fps);
                let rate = if played.fract() == 0.0 {
                    format!("{played}")
                } else {
                    format!("{played:.3}")
                };
                (
                    format!("an animation {}", self.dir.display()),
                    format!(
                        "{}, {rate} frames/s, looping",
                        anim.kind.name().to_uppercase()
                    ),
                )
            }
            None => (self.dir.display().to_string(), self.ext.to_string()),
        };
        if !quiet {
            eprintln!("raystream: wrote {n} frames to {to} ({how}, {format}): {timing}");
        }
        Ok(())
    }
}

/// An animation's frames a second unless --fps says.
const DEFAULT_FPS: u32 = 10;

/// Writes `n` frames, the i-th `frame(i)`'s, rendered with the sight and options it returns
/// too, into the folder `-o` names (frame_000.png …, or .exr, or .dcm: then one series,
/// numbered from 1); `volume` is where the frames' DICOM descriptions come from, `track`
/// what `--draw-wall` draws a CPR's walls with.
fn frame_series(
    a: &RenderArgs,
    (volume, overlay, track, labels): (&raystream_io::Volume, Overlay, Option<&Track>, Labels),
    n: u32,
    format: ImageFormat,
    what: &str,
    mut frame: impl FnMut(u32) -> Result<(dvr::Frame, Seen, DvrOptions)>,
) -> Result<()> {
    let mut out = FrameFolder::new(a, n, format, what)?;
    let mut frame_ms = Vec::new();
    let mut base = None;
    for i in 0..n {
        let (mut f, seen, opt) = frame(i)?;
        base.get_or_insert(opt);
        frame_ms.push(f.frame_ms);
        let dicom = DicomOut {
            series: Some((out.series.clone(), i + 1)),
            ..volume_dicom(
                a,
                &mut f.picture,
                &seen,
                &opt,
                (volume, overlay, track, labels),
            )
        };
        let what = exr_comment(a, &opt, volume, &seen);
        out.write(i, f.picture, what, dicom)?;
    }
    // The frames differ in their camera, plane or phase only.
    let base = base.expect("at least one frame");
    let median = median_of(&mut frame_ms);
    out.finish(
        n,
        &format!(
            "{}x{}, --mode {}, {}",
            base.width,
            base.height,
            base.mode.name(),
            interpolation_words(base.interpolation)
        ),
        &format!(
            "median render {median:.1} ms ({:.2} frames/s, file writing apart)",
            1e3 / median
        ),
        a.quiet,
    )
}

/// What a mesh or scene render starts from: the device, the scene and its kd-tree.
struct Loaded {
    backend: Backend,
    scene: Scene,
    bones: Option<Bones>,
    /// `--legend`'s segments: a label map's surfaces', or a scene file's volume's.
    legend: Vec<crate::legend::Entry>,
    load_ms: f64,
    tree: KdTree,
    /// The scene's own framing view and lights, before --view and --orbit moved them.
    view0: View,
    lights0: Vec<raystream_scene::Light>,
}

/// What a turntable of the stream renderer turns: the scene (its kd-tree, the CPU's volume
/// light grids or the GPU's renderer) and its own framing view and lights.
struct Turn<'a> {
    scene: &'a Scene,
    tree: &'a KdTree,
    medium: Option<&'a raystream_cpu::medium::Medium<'a>>,
    renderer: Option<&'a GpuRenderer<'a>>,
    view0: View,
    lights0: &'a [raystream_scene::Light],
    /// `--legend`'s segments (the surfaces of `render LABELS --segment`), drawn on every frame.
    legend: &'a [crate::legend::Entry],
}

/// `render [INPUT] --turntable N -o DIR` of a mesh, a scene file or the bones (the stream
/// renderer): N frames, one every 360/N degrees about the framing view's up axis from --view
/// and --orbit, each the picture `--orbit` at its angle renders (a mesh's or the bones'
/// studio lights turning with the camera, a scene file's staying put), written as
/// DIR/frame_000.png … (or .exr, or .dcm: one series).
fn scene_turntable(
    a: &RenderArgs,
    n: u32,
    t: Turn,
    opt: &RenderOptions,
    (patient, overlay, units): (bool, Overlay, &str),
    format: ImageFormat,
) -> Result<()> {
    let mut out = FrameFolder::new(a, n, format, "turntable")?;
    let [az, el] = orbit_angles(a);
    let base = base_view(a, t.view0, patient)?;
    let aspect = opt.width as f32 / opt.height as f32;
    // The CPU renders from the scene's framing view and lights: a copy of the scene, made
    // once and turned frame by frame (the GPU's renderer takes the camera and lights).
    let mut cpu_scene: Option<Scene> = None;
    let mut queues = crate::common::cpu_queues()?;
    let mut frame_ms = Vec::new();
    let mut rays = 0usize;
    for i in 0..n {
        let view = base.orbit(az + 360.0 * i as f32 / n as f32, el);
        let lights = studio_lights(a, t.scene, t.view0, t.lights0, view);
        let cam = t.scene.framing_camera(view, aspect);
        let count = |s: DepthStats| rays += s.rays + s.shadow_rays;
        let t1 = Instant::now();
        let mut picture = if let Some(r) = t.renderer {
            r.set_view(cam, &lights)?;
            gpu_picture(r, opt, format, count)?.0
        } else {
            let s = cpu_scene.get_or_insert_with(|| t.scene.clone());
            s.frame_view = view;
            s.lights = lights;
            let film = render_prepared_in(s, t.tree, t.medium, opt, &mut queues, count);
            Picture::of_film(film, format)
        };
        frame_ms.push(ms(t1.elapsed()));
        let dicom = DicomOut {
            series: Some((out.series.clone(), i + 1)),
            ..label(a, &mut picture, &cam, (patient, overlay), t.legend)
        };
        out.write(
            i,
            picture,
            format!(
                "linear RGB, {} spp, depth {}{}",
                opt.spp,
                opt.max_depth,
                pixel_size(&cam, opt.height, units)
            ),
            dicom,
        )?;
    }
    let median = median_of(&mut frame_ms);
    out.finish(
        n,
        &format!(
            "{}x{}, {} spp, depth {}",
            opt.width, opt.height, opt.spp, opt.max_depth
        ),
        &format!(
            "median render {median:.1} ms ({:.2} frames/s, {:.2} Mrays/s; file writing apart)",
            1e3 / median,
            rays as f64 / n as f64 / (median * 1e3),
        ),
        a.quiet,
    )
}

/// A frame of the GPU's stream renderer as `format` keeps it (a PNG's 8-bit sRGB, converted on
/// the GPU; an EXR's film), and its figures.
fn gpu_picture(
    r: &GpuRenderer,
    opt: &RenderOptions,
    format: ImageFormat,
    progress: impl FnMut(DepthStats),
) -> Result<(Picture, raystream_gpu::GpuRenderStats)> {
    Ok(match format {
        ImageFormat::Png => {
            let (rgb, stats) = r.render_srgb8(opt, progress)?;
            let (width, height) = (opt.width, opt.height);
            (Picture::Srgb8 { rgb, width, height }, stats)
        }
        ImageFormat::Exr => {
            let (film, stats) = r.render(opt, progress)?;
            (Picture::Film(film), stats)
        }
    })
}

/// Opens the device (refusing the stack traversal on a GPU), loads INPUT's scene and builds its
/// kd-tree.
fn load(a: &RenderArgs) -> Result<Loaded> {
    let backend = open_device(a.accel.device, a.accel.adapter.as_deref(), a.quiet)?;
    if matches!(backend, Backend::Gpu(_)) && Traversal::from(a.accel.traversal) != Traversal::Ropes
    {
        bail!("--device gpu runs the rope traversal only (--traversal ropes)");
    }
    let t0 = Instant::now();
    let (mut scene, bones, legend) = load_scene(a)?;
    let (view0, lights0) = (scene.frame_view, scene.lights.clone());
    if a.turntable.is_some() && scene.camera.is_some() {
        bail!(
            "{}: the scene sets its camera; --turntable turns the framing camera of scenes without one",
            input_name(a).display()
        );
    }
    let lone = bones.as_ref().and_then(|b| b.lone_view);
    if a.view.is_some() || a.orbit.is_some() || a.parallel || lone.is_some() {
        if scene.camera.is_some() {
            bail!(
                "{}: the scene sets its camera; --view, --orbit and --parallel set the framing camera of scenes without one",
                input_name(a).display()
            );
        }
        scene.frame_projection = projection(a);
        let [az, el] = orbit_angles(a);
        let patient = bones.is_some() || scene.volume.is_some();
        scene.frame_view = base_view(a, lone_or(a, lone, view0), patient)?.orbit(az, el);
        scene.lights = studio_lights(a, &scene, view0, &lights0, scene.frame_view);
        if scene.frame_view.back.y < 0.0 && scene.ground_triangles > 0 {
            scene.leave_out_ground();
            if !a.quiet {
                eprintln!("raystream: a view from below: the ground is left out");
            }
        }
    }
    let load_ms = ms(t0.elapsed());
    let pb = spinner(
        a.quiet,
        &format!("building kd-tree over {} triangles", scene.mesh.len()),
    );
    let tree = a.accel.tree.build(&scene.mesh);
    pb.finish_and_clear();
    Ok(Loaded {
        backend,
        scene,
        bones,
        legend,
        load_ms,
        tree,
        view0,
        lights0,
    })
}

/// The lights of `scene` seen from `view`: a mesh's or the bones' lights are a studio's, and
/// keep their place beside the camera (`lights0` turned as `view` is turned from `view0`); a
/// scene file's stay where the file puts them.
fn studio_lights(
    a: &RenderArgs,
    scene: &Scene,
    view0: View,
    lights0: &[raystream_scene::Light],
    view: View,
) -> Vec<raystream_scene::Light> {
    let mut lights = lights0.to_vec();
    if !is_scene_file(a) && view != view0 {
        let turn = view.turn_from(view0);
        let c = scene.object_box.center();
        for l in &mut lights {
            l.position = c + turn * (l.position - c);
        }
    }
    lights
}

/// `render --aov …`: one ray through each pixel's centre, traced on the chosen device, and the
/// image of its closest hit (made on the host from either device's hits).
fn render_aov(a: &RenderArgs, aov: Aov) -> Result<()> {
    let format = image_format(&a.output)?;
    let Loaded {
        backend,
        scene,
        bones,
        load_ms,
        tree,
        ..
    } = load(a)?;
    check_labels(a, bones.is_some() || scene.volume.is_some(), format)?;
    let traversal = Traversal::from(a.accel.traversal);
    let (width, height) = a.size;
    let cam = scene.camera_for(width as f32 / height as f32);
    let pixels = width * height;
    let pb = spinner(a.quiet, &format!("tracing {pixels} rays"));
    let t1 = Instant::now();
    let gpu = gpu_tracer(&backend, &tree, &input_name(a))?;
    let mut image = AovBuilder::new(&scene, aov, width, height);
    let mut hit_count = 0;
    // In chunks, so that rays and hits stay small at any image size.
    for first in (0..pixels).step_by(AOV_CHUNK as usize) {
        let rays = aov_rays_of(&cam, width, height, first..(first + AOV_CHUNK).min(pixels));
        let hits: Vec<Option<Hit>> = match &gpu {
            Some(tracer) => {
                let (hits, _) = tracer.trace(&rays, false)?;
                hits.iter().map(|h| h.hit()).collect()
            }
            None => tree.intersect_all(&rays, traversal, false),
        };
        hit_count += hits.iter().flatten().count();
        image.add(&rays, &hits);
    }
    let trace_ms = ms(t1.elapsed());
    pb.finish_and_clear();
    let image = image.finish();
    let units = units(&bones);
    image
        .save(&a.output, format, units)
        .map_err(anyhow::Error::msg)?;
    if !a.quiet {
        let range = match (image.depth_range(), format) {
            (Some((near, far)), ImageFormat::Png) => {
                format!(", white = {near:.4}, grey level 1 = {far:.4} {units} from the eye")
            }
            (Some((near, far)), ImageFormat::Exr) => {
                format!(", distances {near:.4} to {far:.4} {units} from the eye")
            }
            _ => String::new(),
        };
        eprintln!(
            "raystream: wrote {} (--aov {}, {width}x{height}, one ray a pixel) on {} ({}): {} of {} rays hit{range}; load {load_ms:.0} ms, kd-tree {:.0} ms, trace {trace_ms:.1} ms",
            a.output.display(),
            aov.name(),
            backend.name(),
            backend.adapter(),
            hit_count,
            pixels,
            tree.stats.build_ms,
        );
        if scene.volume.is_some() {
            eprintln!("raystream: the scene's volume is left out of --aov (its triangles only)");
        }
    }
    Ok(())
}

pub fn run(a: &RenderArgs) -> Result<()> {
    if let Some(flag) = a.islands.flag() {
        if a.mode.is_some() {
            bail!(
                "{flag} works on the islands of a surface's voxels; --mode renders the volume itself (without --mode, its bones' or segments' surfaces)"
            );
        }
        if let Some(p) = (a.input.as_deref()).filter(|p| !raystream_io::is_volume_path(p)) {
            bail!(
                "{}: {flag} works on the islands of a CT volume's or label map's surface; a mesh or scene has none",
                p.display()
            );
        }
    }
    if let Some(mode) = a.mode {
        return render_direct(a, mode.into());
    }
    if let Some(f) = &a.segmentation {
        bail!(
            "--segmentation {}: lays a segmentation on a CT rendered with --mode (slice: tinted; dvr, iso, cinematic: coloured; mip and minip: kept to --segment's segments)",
            f.display()
        );
    }
    let l = &a.look;
    let given: Vec<&str> = [
        ("--tf", l.tf.is_some()),
        ("--step", l.step.is_some()),
        ("--window", l.window.is_some()),
        ("--no-skip", l.no_skip),
        ("--shadows", l.shadows),
        ("--light", l.light.is_some()),
        ("--denoise", l.denoise),
        ("--anisotropy", l.anisotropy.is_some()),
        ("--exposure", l.exposure.is_some()),
        ("--interpolation", l.interpolation.is_some()),
        ("--crop", l.crop.is_some()),
        ("--clip-plane", !l.clip_planes.is_empty()),
        ("--slice-at", l.slice_at.is_some()),
        ("--slab", l.slab.is_some()),
    ]
    .into_iter()
    .filter_map(|(flag, on)| on.then_some(flag))
    .collect();
    if !given.is_empty() {
        bail!(
            "{} {} with --mode (direct volume rendering); without it a volume is rendered as its bone surface's triangles",
            given.join(", "),
            if given.len() == 1 { "goes" } else { "go" }
        );
    }
    if let Some(aov) = a.aov {
        if a.turntable.is_some() {
            bail!("--turntable renders pictures; an AOV is one picture's hits");
        }
        if a.labels || a.draw_path.is_some() || a.scale_bar {
            bail!(
                "--labels, --scale-bar and --draw-path mark a rendered picture, not an AOV's values"
            );
        }
        if crate::common::is_dicom(&a.output) {
            bail!(
                "{}: an AOV is written as PNG or EXR, not DICOM",
                a.output.display()
            );
        }
        return render_aov(a, aov.into());
    }
    let format = picture_format(a, a.turntable.is_some())?;
    let Loaded {
        backend,
        scene,
        bones,
        legend,
        load_ms,
        tree,
        view0,
        lights0,
    } = load(a)?;
    if a.legend && legend.is_empty() {
        bail!(
            "--legend names the segments drawn in colour: give --segment LIST (a label map's surfaces), a CT with --segmentation and --mode, or a scene whose [volume] has a segmentation"
        );
    }
    let legend: &[crate::legend::Entry] = if a.legend { &legend } else { &[] };
    let patient = bones.is_some() || scene.volume.is_some();
    check_labels(a, patient, format)?;
    // `--draw-path`: over the bones or a scene with a CT volume, in its LPS millimetres.
    let overlay = match &a.draw_path {
        Some(file) if !patient => bail!(
            "--draw-path {}: a path through a CT volume, drawn over the volume (--mode …), its bones or a scene with one",
            file.display()
        ),
        Some(_) if format == ImageFormat::Exr => {
            bail!("--draw-path draws on a PNG; an EXR holds the values themselves")
        }
        Some(file) => Some(raystream_cpu::cpr::spline(&raystream_io::read_curve(file)?)),
        None => None,
    };
    let mut volume_samples = 0u64;
    if let Some(n) = a.spp.filter(|&n| n > MAX_MESH_SPP) {
        bail!(
            "--spp {n}: at most {MAX_MESH_SPP} samples a pixel for meshes and scenes (up to 4096 paths a pixel with --mode cinematic)"
        );
    }
    let opt = RenderOptions {
        width: a.size.0,
        height: a.size.1,
        spp: a.spp.unwrap_or(DEFAULT_SPP),
        max_depth: a.max_depth,
        traversal: a.accel.traversal.into(),
    };
    let t_setup = Instant::now();
    let gpu = gpu_tracer(&backend, &tree, &input_name(a))?;
    let renderer = match &gpu {
        Some(tracer) => Some(GpuRenderer::new(tracer, &scene, &tree)?.with_submit(a.submit.into())),
        None => None,
    };
    // The CPU prepares a scene's volume (its light grids) once for all repeats, as the GPU
    // renderer does above.
    let medium = match &gpu {
        Some(_) => None,
        None => prepare_volume(&scene, &tree, opt.traversal),
    };
    let setup_ms = ms(t_setup.elapsed());
    if let Some(n) = a.turntable {
        let turn = Turn {
            scene: &scene,
            tree: &tree,
            medium: medium.as_ref(),
            renderer: renderer.as_ref(),
            view0,
            lights0: &lights0,
            legend,
        };
        let marks = (patient, overlay.as_deref(), units(&bones));
        return scene_turntable(a, n, turn, &opt, marks, format);
    }
    // The CPU's queues, kept from frame to frame.
    let mut queues = crate::common::cpu_queues()?;
    // The progress bar counts depths (of every wave) over all repeats.
    let waves = match &renderer {
        Some(r) => r.waves(&opt),
        None => queues.waves(&opt) as u64,
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
    let mut split = None;
    for _ in 0..a.repeat {
        total_rays = 0;
        volume_samples = 0;
        let mut on_depth = |s: DepthStats| {
            total_rays += s.rays + s.shadow_rays;
            volume_samples += s.volume_samples;
            bar.set_message(format!(
                "{} rays, {} hits, {} shadow rays",
                s.rays, s.hits, s.shadow_rays
            ));
            bar.inc(1);
        };
        let t1 = Instant::now();
        // For a PNG a frame is 8-bit sRGB pixels on the host, as a viewer shows them (the GPU
        // converts its film itself); for an EXR the film.
        let img = match &renderer {
            Some(r) => {
                let (picture, stats) = gpu_picture(r, &opt, format, &mut on_depth)?;
                kernel_ms = stats.kernel_gpu_ms;
                split = Some((
                    stats.render_ms,
                    stats.wait_ms,
                    stats.film_ms,
                    stats.submissions,
                    stats.submit,
                ));
                picture
            }
            None => Picture::of_film(
                render_prepared_in(
                    &scene,
                    &tree,
                    medium.as_ref(),
                    &opt,
                    &mut queues,
                    &mut on_depth,
                ),
                format,
            ),
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
    let mut image = image.expect("at least one frame");
    let cam = scene.camera_for(opt.width as f32 / opt.height as f32);
    let dicom = label(a, &mut image, &cam, (patient, overlay.as_deref()), legend);
    image.save(
        &a.output,
        &format!(
            "linear RGB, {} spp, depth {}{}",
            opt.spp,
            opt.max_depth,
            pixel_size(&cam, opt.height, units(&bones))
        ),
        &dicom,
    )?;
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
            } else if medium.is_some() {
                format!(", volume light grids {setup_ms:.0} ms")
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
        if renderer.is_none() {
            eprintln!(
                "raystream: the CPU's frame in {waves} wave{} of {} pixels at most",
                if waves == 1 { "" } else { "s" },
                queues.wave_pixels(&opt)
            );
        }
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
        if let Some((all, wait, film, submissions, submit)) = split {
            let per = match submit {
                raystream_gpu::Submit::Wave => "wave",
                raystream_gpu::Submit::Depth => "depth",
            };
            eprintln!(
                "raystream: the last frame's {all:.1} ms: {wait:.1} submitting and waiting on {submissions} submission{}, one per {per} (kernels and round trips), {film:.1} {} reading it back, {:.1} on the host",
                if submissions == 1 { "" } else { "s" },
                match format {
                    ImageFormat::Png => "turning the film into 8-bit sRGB and",
                    ImageFormat::Exr => "resolving the float film and",
                },
                all - wait - film
            );
        }
        if let Some(v) = &scene.volume {
            eprintln!(
                "raystream: the scene's volume ({}x{}x{} voxels{}){}",
                v.volume.dims[0],
                v.volume.dims[1],
                v.volume.dims[2],
                if v.shadows {
                    ", lit through a light grid per light"
                } else {
                    ""
                },
                if gpu.is_some() {
                    String::new()
                } else {
                    format!(": {volume_samples} samples along the rays")
                }
            );
        }
        if let Some(b) = bones {
            eprintln!(
                "raystream: of the load: volume {:.0} ms, isosurface {:.0} ms ({} voxels, {})",
                b.load_ms, b.iso_ms, b.voxels, b.what
            );
        }
    }
    Ok(())
}
