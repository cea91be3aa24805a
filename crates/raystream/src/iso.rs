//! `raystream iso`: a CT volume's bone isosurface as a mesh file, and the volume → bones step
//! that `render VOLUME` and the built-in default share.

use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};
use raystream_io::{SegmentVoxels, ValueUnit, Volume, VolumeSelect};
use raystream_volume::{Islands, IsoSurface, KeepIslands, KeepSurface, extract_isosurface_keeping};

use crate::cli::IsoArgs;
use crate::common::{ms, spinner};

/// The bone surface of a volume, with the time each step took.
pub struct Bones {
    pub surface: IsoSurface,
    /// What the surface is, for a report: "at 300 HU", or the segments'.
    pub what: String,
    pub voxels: usize,
    pub load_ms: f64,
    pub iso_ms: f64,
    /// The segments' surfaces, named (`--legend`); none for bones.
    pub legend: Vec<crate::legend::Entry>,
    /// A lone slice's view along its axis ([`crate::common::lone_slice_view`]).
    pub lone_view: Option<(raystream_scene::PatientView, &'static str)>,
}

/// The threshold of `volume`'s surface: `--iso`'s or the preset's; for values of no known unit
/// given neither, their Otsu threshold ([`raystream_volume::auto::otsu_threshold`]: the edge
/// between the background and the object), since an HU preset means nothing there (bone's 300
/// lies above every value of an 8-bit scan); but not for a label map (whole numbers from 0,
/// piecewise constant: [`raystream_volume::auto::equal_neighbour_share`]), whose surfaces
/// are its segments'. Said unless `quiet`.
pub fn surface_threshold(
    volume: &Volume,
    threshold: &crate::cli::Threshold,
    path: &Path,
    quiet: bool,
) -> Result<f32> {
    let given = threshold.iso.is_some() || threshold.preset.is_some();
    let otsu = if given { None } else { default_surface(volume) };
    let Some(t) = otsu else {
        let hu = threshold.hu()?;
        if !quiet && volume.unit != ValueUnit::Hounsfield {
            eprintln!(
                "raystream: {}: values are not known to be Hounsfield units; the threshold {hu} applies to the raw values",
                path.display()
            );
        }
        return Ok(hu);
    };
    if !quiet {
        eprintln!(
            "raystream: {}: values of no known unit: the surface at {t}, their Otsu threshold (between the background and the object; --iso V sets another)",
            path.display()
        );
    }
    Ok(t)
}

/// Where the surface of a volume of no known unit stands unless `--iso` or `--preset` says:
/// its values' Otsu threshold. `None` for a CT (its surface is bone's, in HU), a label map (its
/// surfaces are its segments', `--segment`, not a split of its numbers) and a volume of fewer
/// than two distinct values.
pub fn default_surface(volume: &Volume) -> Option<f32> {
    let labels = || {
        crate::common::not_a_label(volume).is_none()
            && raystream_volume::auto::equal_neighbour_share(volume.dims, &volume.data) >= 0.5
    };
    if volume.unit == ValueUnit::Hounsfield || labels() {
        return None;
    }
    raystream_volume::auto::otsu_threshold(&volume.data)
}

/// `value` with its unit: "300 HU", or the bare number where the volume's unit is unknown.
pub fn value_words(volume: &Volume, value: f32) -> String {
    match volume.unit {
        ValueUnit::Hounsfield => format!("{value} HU"),
        ValueUnit::Unknown => format!("{value}"),
    }
}

/// The surface at `hu` of `volume`, read from `path` in `load_ms`.
pub fn bones_of(
    volume: &Volume,
    path: &Path,
    hu: f32,
    (smoothing, keep): (u32, KeepSurface),
    quiet: bool,
    load_ms: f64,
) -> Result<Bones> {
    let t1 = Instant::now();
    let pb = spinner(
        quiet,
        &format!(
            "marching cubes over {}x{}x{} voxels at {}",
            volume.dims[0],
            volume.dims[1],
            volume.dims[2],
            value_words(volume, hu)
        ),
    );
    let voxel_ml = volume.voxel_ml();
    let (mut surface, islands) = extract_isosurface_keeping(volume, hu, keep);
    pb.finish_and_clear();
    if islands.kept == 0 && !islands.sizes.is_empty() {
        bail!(
            "{}: {}",
            path.display(),
            no_island_kept(&islands, keep.islands, voxel_ml)
        );
    }
    if !keep.is_all() && !quiet {
        eprintln!(
            "raystream: {}: {} at {}",
            path.display(),
            islands_kept(&islands, keep, voxel_ml),
            value_words(volume, hu)
        );
    }
    raystream_volume::smooth(&mut surface, smoothing);
    if surface.mesh.is_empty() {
        let range = volume
            .value_range()
            .map_or("all NaN".to_string(), |(lo, hi)| format!("{lo} .. {hi}"));
        let hint = if crate::common::not_a_label(volume).is_none() {
            " (whole numbers from 0, as a label map's: give --segment)"
        } else {
            ""
        };
        bail!(
            "{}: no surface at {hu}: the values range over {range}{hint}",
            path.display()
        );
    }
    Ok(Bones {
        surface,
        what: format!("at {}", value_words(volume, hu)),
        voxels: volume.voxel_count(),
        load_ms,
        iso_ms: ms(t1.elapsed()),
        legend: Vec::new(),
        lone_view: None,
    })
}

/// Loads `path` (or takes `embedded` bytes as NIfTI), printing its warnings; also the time it
/// took, ms.
pub fn read_volume(
    path: &Path,
    select: &VolumeSelect,
    quiet: bool,
    embedded: Option<&[u8]>,
) -> Result<(Volume, f64)> {
    let t0 = Instant::now();
    let pb = spinner(quiet, &format!("reading {}", path.display()));
    let volume: Volume = match embedded {
        Some(bytes) => raystream_io::volume::parse_nifti(bytes, path, select.phase)?,
        None => raystream_io::load_volume(path, select)?,
    };
    pb.finish_and_clear();
    if let Some(series) = &volume.series {
        crate::common::set_source_study(&series.study);
    }
    if !quiet {
        for w in &volume.warnings {
            eprintln!("raystream: {}: {w}", path.display());
        }
    }
    Ok((volume, ms(t0.elapsed())))
}

/// Whether `iso` or `render` of `volume` makes its segments' surfaces rather than a
/// threshold's: asked for by `--segment` or `--colour-table`, or a DICOM Segmentation given
/// without `--iso` or `--preset`.
pub fn wants_segments(
    volume: &Volume,
    threshold: &crate::cli::Threshold,
    segment: Option<&str>,
    colour_table: Option<&Path>,
) -> bool {
    let segmentation = !volume.segments.is_empty();
    let thresholded = threshold.iso.is_some() || threshold.preset.is_some();
    segment.is_some() || colour_table.is_some() || (segmentation && !thresholded)
}

pub fn run(a: &IsoArgs) -> Result<()> {
    a.threshold.hu()?;
    let (mut volume, load_ms) = read_volume(&a.input, &a.pick.select(), a.quiet, None)?;
    if a.body_only {
        let b = crate::body::find(&volume, &a.input, a.quiet)?;
        b.hide_outside(&mut volume);
    }
    let segment = a.segment.as_deref();
    if wants_segments(&volume, &a.threshold, segment, a.colour_table.as_deref()) {
        if a.colour_shells {
            bail!(
                "{}: --colour-shells parts a threshold's surface by its shells; a segmentation's segments are parts of their own",
                a.input.display()
            );
        }
        return run_segments(a, &volume, load_ms);
    }
    let hu = surface_threshold(&volume, &a.threshold, &a.input, a.quiet)?;
    let mut b = bones_of(
        &volume,
        &a.input,
        hu,
        (a.smooth.unwrap_or(0), a.islands.keep(volume.voxel_ml())),
        a.quiet,
        load_ms,
    )?;
    simplify(&mut b.surface, a.simplify, "the surface", a.quiet);
    let t = Instant::now();
    // --colour-shells: the largest shells a part each, named and coloured, then the rest.
    let shells = a.colour_shells.then(|| {
        let c = crate::shells::shell_colours(&b.surface.mesh, true);
        if !a.quiet {
            eprintln!(
                "raystream: {}: {} shells, the {} largest a part each (shell 1 …), the rest one (bone)",
                a.input.display(),
                c.measures.shells,
                c.legend.len()
            );
        }
        crate::shells::shell_parts(&b.surface.mesh, &b.surface.normals, &c)
    });
    let parts: Vec<raystream_io::MeshPart> = match &shells {
        None => vec![raystream_io::MeshPart {
            name: "bone",
            mesh: &b.surface.mesh,
            normals: Some(&b.surface.normals),
            colour: raystream_io::BONE,
        }],
        Some(shells) => (shells.iter())
            .map(|p| raystream_io::MeshPart {
                name: &p.name,
                mesh: &p.mesh,
                normals: Some(&p.normals),
                colour: p.colour.unwrap_or(raystream_io::BONE),
            })
            .collect(),
    };
    let written = write_surfaces(&a.output, &parts, &volume, &format!("bones {}", b.what))?;
    if !a.quiet {
        eprintln!(
            "raystream: wrote {} ({} vertices, {} triangles at {}, enclosing {:.1} ml): load {:.0} ms, isosurface {:.0} ms ({:.0} M voxels/s), write {:.0} ms",
            match written.as_slice() {
                [first, .., last] => format!(
                    "{} … {} ({} files)",
                    first.display(),
                    last.display(),
                    written.len()
                ),
                _ => a.output.display().to_string(),
            },
            b.surface.mesh.positions.len(),
            b.surface.mesh.len(),
            value_words(&volume, hu),
            enclosed_ml(&b.surface.mesh),
            b.load_ms,
            b.iso_ms,
            b.voxels as f64 / b.iso_ms / 1e3,
            ms(t.elapsed())
        );
    }
    Ok(())
}

/// `--simplify MM`: simplifies `surface` (named `what` in the report) within `mm`, if given.
fn simplify(surface: &mut IsoSurface, mm: Option<f64>, what: &str, quiet: bool) {
    let Some(mm) = mm else { return };
    let pb = spinner(quiet, &format!("simplifying {what} within {mm} mm"));
    let t = Instant::now();
    let s = raystream_volume::simplify_reporting(surface, mm, &mut |r| {
        pb.set_message(format!(
            "simplifying {what} within {mm} mm: try {}, round {} kept {} triangles and left {} vertices beyond the bound or where the surface is pinched",
            r.attempt, r.round, r.triangles, r.beyond
        ))
    });
    pb.finish_and_clear();
    if !quiet {
        eprintln!(
            "raystream: {what} simplified within {mm} mm: {} → {} triangles (the full surface's vertices lie at most {:.3} mm from it), {:.0} ms",
            s.triangles_before,
            s.triangles_after,
            s.departure,
            ms(t.elapsed())
        );
    }
}

/// The smoothing iterations segments get unless `--smooth` says otherwise.
pub const SEGMENT_SMOOTHING: u32 = 10;

/// One segment's surface.
pub struct SegmentSurface {
    /// Its label value.
    pub label: u32,
    /// Its name: a Segmentation's Segment Label, else "label N".
    pub name: String,
    /// sRGB: a Segmentation's recommended colour, else `--segmentation`'s tint for the label.
    pub colour: [u8; 3],
    /// Its voxels (those of the islands kept, where some were dropped).
    pub voxels: usize,
    pub surface: IsoSurface,
    /// Its islands, where `--keep-largest` or `--min-island` chose among them.
    pub islands: Option<Islands>,
}

impl SegmentSurface {
    /// Its colour as linear RGB, as materials take it.
    pub fn linear_colour(&self) -> [f32; 3] {
        self.colour
            .map(|c| raystream_io::SRGB_TO_LINEAR[c as usize])
    }
}

/// `iso --segment`: the surfaces of the segments `list` names (see [`IsoArgs::segment`]) in
/// `labels`, written to one file.
fn run_segments(a: &IsoArgs, labels: &Volume, load_ms: f64) -> Result<()> {
    let t0 = Instant::now();
    let known = segment_names(labels, a.colour_table.as_deref())?;
    let whole = raystream_io::whole_segments(labels, &a.input)?;
    let keep = a.islands.keep(labels.voxel_ml());
    let mut surfaces = segment_surfaces(
        labels,
        whole.as_ref(),
        &a.input,
        (a.segment.as_deref().unwrap_or("all"), &known),
        (a.smooth.unwrap_or(SEGMENT_SMOOTHING), keep),
        a.quiet,
    )?;
    for s in &mut surfaces {
        let what = format!("segment {} ({})", s.label, s.name);
        simplify(&mut s.surface, a.simplify, &what, a.quiet);
    }
    let iso_ms = ms(t0.elapsed());
    let t = Instant::now();
    let parts: Vec<raystream_io::MeshPart> = surfaces
        .iter()
        .map(|s| raystream_io::MeshPart {
            name: &s.name,
            mesh: &s.surface.mesh,
            normals: Some(&s.surface.normals),
            colour: s.linear_colour(),
        })
        .collect();
    let titles: Vec<&str> = surfaces.iter().map(|s| s.name.as_str()).collect();
    let written = write_surfaces(&a.output, &parts, labels, &titles.join(", "))?;
    if !a.quiet {
        let voxel_ml = labels.voxel_ml();
        for s in &surfaces {
            let kept = (s.islands.as_ref()).map_or(String::new(), |i| {
                format!(" ({})", islands_kept(i, keep, voxel_ml))
            });
            eprintln!(
                "raystream: segment {} ({}): {} voxels, {:.1} ml{kept}; its surface {} triangles, enclosing {:.1} ml",
                s.label,
                s.name,
                s.voxels,
                s.voxels as f64 * voxel_ml,
                s.surface.mesh.len(),
                enclosed_ml(&s.surface.mesh)
            );
        }
        eprintln!(
            "raystream: wrote {} ({} surfaces): load {load_ms:.0} ms, surfaces {iso_ms:.0} ms, write {:.0} ms",
            (written.iter())
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            surfaces.len(),
            ms(t.elapsed())
        );
    }
    Ok(())
}

/// The labels `--segment LIST` names (numbers, a segmentation's segment labels in any case, or
/// `all`), in the order named, among those `present` (some voxel holds each); an unknown one is
/// refused, naming the file (`name`) and the option (`option`, its text before the list) and
/// listing the labels present by number and name.
pub fn pick_segments(
    name: &dyn std::fmt::Display,
    option: &str,
    list: &str,
    present: &[u32],
    known: &[raystream_io::SegmentLabel],
) -> Result<Vec<u32>> {
    let named = |l: u32| known.iter().find(|k| k.number as u32 == l);
    let listed = || {
        let list: Vec<String> = present
            .iter()
            .map(|&l| match named(l) {
                Some(k) if !k.label.is_empty() => format!("{l} ({})", k.label),
                _ => l.to_string(),
            })
            .collect();
        if list.is_empty() {
            "none".to_string()
        } else {
            list.join(", ")
        }
    };
    let mut wanted: Vec<u32> = Vec::new();
    for item in list.split(',').map(str::trim) {
        let found: Vec<u32> = if item.eq_ignore_ascii_case("all") {
            present.to_vec()
        } else if let Ok(l) = item.parse::<u32>() {
            if !present.contains(&l) {
                bail!(
                    "{name}: {option}{item}: no voxel holds label {l}; the labels present are {}",
                    listed()
                );
            }
            vec![l]
        } else {
            let by_name: Vec<u32> = known
                .iter()
                .filter(|k| k.label.eq_ignore_ascii_case(item))
                .map(|k| k.number as u32)
                .collect();
            match by_name.as_slice() {
                [] => bail!(
                    "{name}: {option}{item:?}: no segment is named so (nor is it a number); the labels present are {}",
                    listed()
                ),
                [l] if !present.contains(l) => bail!(
                    "{name}: {option}{item:?}: segment {l} holds no voxel; the labels present are {}",
                    listed()
                ),
                _ => by_name,
            }
        };
        for l in found {
            if !wanted.contains(&l) {
                wanted.push(l);
            }
        }
    }
    Ok(wanted)
}

/// Writes `parts` to `out`: a mesh file by its extension, or (`.dcm`) a DICOM Encapsulated STL
/// of `volume`'s study, titled `title`; several surfaces as as many models in one series,
/// `out` numbered (`MODEL-1.dcm`, `MODEL-2.dcm` …), each titled by its name. The files
/// written.
fn write_surfaces(
    out: &Path,
    parts: &[raystream_io::MeshPart],
    volume: &Volume,
    title: &str,
) -> Result<Vec<std::path::PathBuf>> {
    let dicom = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dcm"));
    if !dicom {
        raystream_io::write_mesh_parts(out, parts)?;
        return Ok(vec![out.to_path_buf()]);
    }
    let description = format!("raystream iso: {title}");
    let series = raystream_io::new_uid();
    let mut written = Vec::new();
    for (k, part) in parts.iter().enumerate() {
        let (file, title, joined) = match parts.len() {
            1 => (out.to_path_buf(), title, None),
            _ => {
                let stem = out.file_stem().unwrap_or_default().to_string_lossy();
                let file = out.with_file_name(format!("{stem}-{}.dcm", k + 1));
                (file, part.name, Some((series.as_str(), k as u32 + 1)))
            }
        };
        let info = raystream_io::ModelInfo {
            title,
            description: &description,
            version: env!("CARGO_PKG_VERSION"),
            series: joined,
        };
        raystream_io::write_encapsulated_stl(&file, part, Some(volume), &info)?;
        written.push(file);
    }
    Ok(written)
}

/// What `--fill-cavities` filled and `--keep-largest` or `--min-island` kept (as `keep` says)
/// of `islands`: "filled 217 cavities (0.9 ml of voxels), kept 1 of 1222 islands (99.8 of
/// 391.8 ml of voxels)", on a grid of voxels of `voxel_ml`.
pub fn islands_kept(islands: &Islands, keep: KeepSurface, voxel_ml: f64) -> String {
    use crate::common::plural;
    let mut said = Vec::new();
    if keep.fill_cavities {
        said.push(format!(
            "filled {} ({:.1} ml of voxels)",
            plural(islands.cavities, "cavity", "cavities"),
            islands.cavity_voxels as f64 * voxel_ml
        ));
    }
    if keep.islands != KeepIslands::All {
        let all: usize = islands.sizes.iter().sum();
        said.push(format!(
            "kept {} of {} ({:.1} of {:.1} ml of voxels)",
            islands.kept,
            plural(islands.sizes.len(), "island", "islands"),
            islands.kept_voxels as f64 * voxel_ml,
            all as f64 * voxel_ml
        ));
    }
    said.join(", ")
}

/// Why `keep` kept none of `islands` (only `--min-island` can): the largest's size.
fn no_island_kept(islands: &Islands, keep: KeepIslands, voxel_ml: f64) -> String {
    let least = match keep {
        KeepIslands::AtLeast(n) => n,
        _ => 0,
    };
    format!(
        "--min-island: no island holds {:.3} ml ({least} voxels); the largest of {} holds {:.3} ml ({} voxels)",
        least as f64 * voxel_ml,
        islands.sizes.len(),
        islands.sizes[0] as f64 * voxel_ml,
        islands.sizes[0]
    )
}

/// The volume a closed, outward-facing mesh in millimetres encloses, ml.
pub fn enclosed_ml(mesh: &raystream_io::TriMesh) -> f64 {
    mesh.enclosed_volume() / 1000.0
}

/// The segments' names and colours: a label file's own (a DICOM Segmentation's, a 3D Slicer
/// segmentation's), each label that
/// `--colour-table FILE` names taking the table's.
pub fn segment_names(
    labels: &Volume,
    table: Option<&Path>,
) -> Result<Vec<raystream_io::SegmentLabel>> {
    with_colour_table(labels.segments.clone(), table)
}

/// Segment names and colours `known`, each label that `--colour-table FILE` names taking the
/// table's.
pub fn with_colour_table(
    mut known: Vec<raystream_io::SegmentLabel>,
    table: Option<&Path>,
) -> Result<Vec<raystream_io::SegmentLabel>> {
    if let Some(t) = table {
        for l in raystream_io::read_colour_table(t)? {
            known.retain(|k| k.number != l.number);
            known.push(l);
        }
    }
    Ok(known)
}

/// The surfaces of the segments `list` names in the label volume `labels` (read from `path`;
/// with `whole`, its segments each whole, overlaps and all: [`raystream_io::whole_segments`]),
/// named and coloured by `known` (else "label N" in `--segmentation`'s tints):
/// each segment's voxels as an inside region, cut out of the grid with its bounding box and a
/// voxel around it, its surface at the half-way value between inside and outside (halfway
/// between the centres of a voxel of the segment and its neighbour not of it, the grid's
/// edge included), smoothed `smoothing` times.
pub fn segment_surfaces(
    labels: &Volume,
    whole_segments: Option<&raystream_io::WholeSegments>,
    path: &Path,
    (list, known): (&str, &[raystream_io::SegmentLabel]),
    (smoothing, keep): (u32, KeepSurface),
    quiet: bool,
) -> Result<Vec<SegmentSurface>> {
    let name = path.display();
    if let Some(v) = crate::common::not_a_label(labels) {
        bail!("{name}: --segment takes a label map (whole numbers from 0); it holds {v}");
    }
    // Each segment's voxels: whole where they may overlap (which the label volume cannot
    // hold), else each label's bounding box, found in one pass and cut out when wanted.
    let [nx, ny, _] = labels.dims;
    let mut whole: std::collections::BTreeMap<u32, &SegmentVoxels> = Default::default();
    let mut boxes: std::collections::BTreeMap<u32, ([usize; 3], [usize; 3], usize)> =
        Default::default();
    if let Some(segments) = whole_segments {
        for (l, v) in segments.iter().filter(|(_, v)| v.voxels > 0) {
            let hi = std::array::from_fn(|a| v.lo[a] + v.dims[a] - 1);
            boxes.insert(*l as u32, (v.lo, hi, v.voxels));
            whole.insert(*l as u32, v);
        }
    } else {
        for (n, &v) in labels.data.iter().enumerate() {
            if v > 0.0 {
                let ijk = [n % nx, (n / nx) % ny, n / (nx * ny)];
                let e = boxes.entry(v as u32).or_insert((ijk, ijk, 0));
                e.0 = std::array::from_fn(|a| e.0[a].min(ijk[a]));
                e.1 = std::array::from_fn(|a| e.1[a].max(ijk[a]));
                e.2 += 1;
            }
        }
    }
    let wanted = pick_segments(
        &name,
        "--segment ",
        list,
        &boxes.keys().copied().collect::<Vec<_>>(),
        known,
    )?;
    if wanted.is_empty() {
        bail!("{name}: no voxel holds a label (every voxel is 0)");
    }
    let pb = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(wanted.len() as u64).with_style(
            indicatif::ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} segments")
                .expect("a valid template"),
        )
    };
    pb.set_message("marching cubes");
    let mut out = Vec::with_capacity(wanted.len());
    for &l in &wanted {
        // A voxel of margin all round, beyond the grid too (no segment holds a voxel outside
        // it), so that the surface crosses between a voxel of the segment and its neighbour
        // halfway everywhere: the marching cubes would close a region at the grid's edge on
        // the edge voxels' centres, and a Segmentation's grid ends at its last frame.
        let (lo, hi, voxels) = boxes[&l];
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 3);
        let mut data = vec![0.0f32; dims[0] * dims[1] * dims[2]];
        let held = whole.remove(&l);
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                let at = 1 + dims[0] * (j + 1 - lo[1] + dims[1] * (k + 1 - lo[2]));
                let out = &mut data[at..at + hi[0] + 1 - lo[0]];
                if let Some(v) = &held {
                    let from = v.dims[0] * (j - lo[1] + v.dims[1] * (k - lo[2]));
                    for (d, &b) in out.iter_mut().zip(&v.inside[from..]) {
                        *d = if b { 1.0 } else { 0.0 };
                    }
                } else {
                    let row = nx * (j + ny * k);
                    for (d, &v) in out.iter_mut().zip(&labels.data[row + lo[0]..]) {
                        *d = if v as u32 == l { 1.0 } else { 0.0 };
                    }
                }
            }
        }
        let mut cut = Volume::hounsfield(dims, labels.spacing, data);
        cut.unit = ValueUnit::Unknown;
        cut.direction = labels.direction;
        cut.origin = labels
            .index_to_world(raystream_math::DVec3::from_array(
                lo.map(|x| x as f64 - 1.0),
            ))
            .to_array();
        let (mut surface, islands) = extract_isosurface_keeping(&cut, 0.5, keep);
        raystream_volume::smooth(&mut surface, smoothing);
        let segment = known.iter().find(|k| k.number as u32 == l);
        let name = segment
            .map(|k| k.label.clone())
            .filter(|n| !n.is_empty())
            .unwrap_or_else(|| format!("label {l}"));
        if islands.kept == 0 && !islands.sizes.is_empty() {
            bail!(
                "{}: segment {l} ({name}): {}",
                path.display(),
                no_island_kept(&islands, keep.islands, labels.voxel_ml())
            );
        }
        let islands = (!keep.is_all()).then_some(islands);
        let colour = crate::overlay::segment_colour(known, l);
        out.push(SegmentSurface {
            label: l,
            name,
            colour,
            voxels: match &islands {
                Some(i) if keep.islands != KeepIslands::All => i.kept_voxels,
                Some(i) => voxels + i.cavity_voxels,
                None => voxels,
            },
            surface,
            islands,
        });
        pb.inc(1);
    }
    pb.finish_and_clear();
    // Names are glTF nodes' and OBJ objects': two segments of one label get their numbers.
    let shared: Vec<bool> = out
        .iter()
        .map(|s| out.iter().filter(|o| o.name == s.name).count() > 1)
        .collect();
    for (s, shared) in out.iter_mut().zip(shared) {
        if shared {
            s.name = format!("{} ({})", s.name, s.label);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use raystream_math::{DVec3, Vec3};

    /// `--min-island ML` keeps an island of exactly ML: ML written as its voxels' volume (as a
    /// user copies it from `info`'s ml) asks for those voxels, not one more, whatever the
    /// rounding of the voxel's volume and of the decimal.
    #[test]
    fn min_island_counts_whole_voxels() {
        for spacing in [
            [1.0, 1.5, 2.0],
            [0.7, 0.7, 1.25],
            [3.0; 3],
            [0.488281, 0.488281, 0.625],
        ] {
            let voxel_ml = spacing.iter().product::<f64>() / 1000.0;
            for n in 1..3000usize {
                let ml: f64 = format!("{}", n as f64 * voxel_ml).parse().unwrap();
                let pick = crate::cli::IslandPick {
                    keep_largest: None,
                    min_island: Some(ml),
                    fill_cavities: false,
                };
                assert_eq!(
                    pick.keep(voxel_ml),
                    KeepIslands::AtLeast(n).into(),
                    "{n} voxels of {spacing:?}"
                );
            }
        }
    }

    /// A 3×3×4 label map on a turned, unevenly spaced grid: label 2 everywhere but voxel
    /// (0, 0, 0), which is label 1.
    fn labels() -> Volume {
        let mut data = vec![2.0; 36];
        data[0] = 1.0;
        let mut v = Volume::hounsfield([3, 3, 4], [0.5, 0.7, 2.0], data);
        v.unit = ValueUnit::Unknown;
        v.origin = [10.0, -20.0, 30.0];
        // 30° about z.
        let (s, c) = (0.5, 0.75f64.sqrt());
        v.direction = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        v
    }

    /// A segment that fills the grid is closed half a voxel beyond its edge voxels' centres,
    /// as inside it; a single voxel becomes the octahedron through its faces' centres (a sixth
    /// of the voxel); the segments come in the order asked, each once, and raw surfaces are
    /// closed.
    #[test]
    fn segments_are_closed_halfway_to_their_neighbours_the_grid_edge_too() {
        let v = labels();
        let path = Path::new("labels.nii");
        let s = segment_surfaces(
            &v,
            None,
            path,
            ("2, 1,2", &[]),
            (0, KeepSurface::default()),
            true,
        )
        .unwrap();
        assert_eq!(s.iter().map(|s| s.label).collect::<Vec<_>>(), [2, 1]);
        assert_eq!(s[0].name, "label 2");
        assert_eq!(s[1].voxels, 1);
        let index = |p: Vec3| v.world_to_index(p.as_dvec3());
        let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
        for &p in &s[0].surface.mesh.positions {
            lo = lo.min(index(p));
            hi = hi.max(index(p));
        }
        assert!((lo - DVec3::splat(-0.5)).abs().max_element() < 1e-5, "{lo}");
        assert!(
            (hi - DVec3::new(2.5, 2.5, 3.5)).abs().max_element() < 1e-5,
            "{hi}"
        );
        for &p in &s[1].surface.mesh.positions {
            let q = index(p);
            assert!((q.abs().element_sum() - 0.5).abs() < 1e-5, "{q}");
        }
        let voxel_ml = v.voxel_ml();
        assert!((enclosed_ml(&s[1].surface.mesh) - voxel_ml / 6.0).abs() < 1e-6 * voxel_ml);
        assert!(enclosed_ml(&s[0].surface.mesh) > 0.0);
        let all = segment_surfaces(
            &v,
            None,
            path,
            ("all", &[]),
            (3, KeepSurface::default()),
            true,
        )
        .unwrap();
        assert_eq!(all.iter().map(|s| s.label).collect::<Vec<_>>(), [1, 2]);
        let e = segment_surfaces(
            &v,
            None,
            path,
            ("3", &[]),
            (0, KeepSurface::default()),
            true,
        )
        .err()
        .unwrap();
        assert_eq!(
            e.to_string(),
            "labels.nii: --segment 3: no voxel holds label 3; the labels present are 1, 2"
        );
        let mut ct = v.clone();
        ct.data[5] = -1000.0;
        let e = segment_surfaces(
            &ct,
            None,
            path,
            ("all", &[]),
            (0, KeepSurface::default()),
            true,
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("it holds -1000"), "{e}");
    }
}
