//! A segmentation laid on a CT's grid: `info CT --segmentation LABELS`' regions, and
//! `render CT --mode dvr|iso|cinematic|mip --segmentation LABELS [--segment LIST]`'s segment
//! colours and the CT kept to the chosen segments.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};
use raystream_cpu::dvr::DvrMode;
use raystream_cpu::segments::{MAX_LABEL, SegmentColours};
use raystream_io::Volume;
use raystream_math::Vec3;

use crate::cli::RenderArgs;

/// A segmentation's segments on a CT's grid.
pub struct OnCt {
    /// Per label, the CT voxels (x fastest) it holds; each segment whole where segments may
    /// overlap (a structure set's structures, a Segmentation's segments).
    pub members: BTreeMap<u32, Vec<usize>>,
    /// The segments' names and colours (the segmentation's own, `--colour-table`'s over them).
    pub known: Vec<raystream_io::SegmentLabel>,
    /// How the CT's voxels were matched to the segmentation's.
    pub how: &'static str,
}

/// The segments of `file` (a label map, a DICOM Segmentation or an RT Structure Set) on the
/// grid of `ct` (read from `input`), named and coloured with `colour_table` over their own;
/// refused when it is no label map, a structure set of another Frame of Reference, or none of
/// its segments holds a voxel of the CT.
pub fn on_ct(file: &Path, colour_table: Option<&Path>, ct: &Volume, input: &Path) -> Result<OnCt> {
    let name = file.display();
    let [nx, ny, _] = ct.dims;
    let mut members: BTreeMap<u32, Vec<usize>> = Default::default();
    let (how, known) = if raystream_io::is_structure_set_file(file) {
        // Each structure whole, laid on this CT's grid (not the series it names).
        let set = raystream_io::StructureSet::read(file)?;
        if let Some(why) = set.frame_mismatch(ct) {
            bail!("{name}: {why} ({})", input.display());
        }
        let known = crate::iso::with_colour_table(set.segments(), colour_table)?;
        for roi in &set.rois {
            let (r, _) = set.rasterise(roi, ct);
            let [dx, dy, _] = r.dims;
            let list = members.entry(roi.number as u32).or_default();
            for (n, _) in r.inside.iter().enumerate().filter(|(_, held)| **held) {
                let (i, j, k) = (n % dx, (n / dx) % dy, n / (dx * dy));
                list.push(r.lo[0] + i + nx * (r.lo[1] + j + ny * (r.lo[2] + k)));
            }
        }
        members.retain(|_, v| !v.is_empty());
        ("structures laid on the CT's grid", known)
    } else {
        let labels = raystream_io::load_volume(file, &raystream_io::VolumeSelect::default())?;
        // A lone slice's labels on the slab its CT was made (crate::common::slab_if_lone).
        let labels = match labels.slab_of_lone_slices() {
            Some(slab) if same_grid(&slab, ct) => slab,
            _ => labels,
        };
        if let Some(v) = crate::common::not_a_label(&labels) {
            bail!("{name}: --segmentation takes a label map (whole numbers from 0); it holds {v}");
        }
        let known = crate::iso::segment_names(&labels, colour_table)?;
        let whole = raystream_io::whole_segments(&labels, file)?;
        (
            labels_on_ct(ct, (&labels, whole.as_ref()), &mut members),
            known,
        )
    };
    if members.is_empty() {
        bail!(
            "{name}: no segment holds a voxel of {} (is it this CT's segmentation?)",
            input.display()
        );
    }
    Ok(OnCt {
        members,
        known,
        how,
    })
}

impl OnCt {
    /// The segments `chosen` laid on the CT's grid (`len` voxels) as one label volume, at the
    /// voxels where `keep` holds; the largest laid first, so that a segment inside another (a
    /// tumour in its organ) keeps its own voxels.
    pub fn laid(&self, chosen: &[u32], len: usize, keep: impl Fn(usize) -> bool) -> Vec<u16> {
        let mut order = chosen.to_vec();
        order.sort_by_key(|l| std::cmp::Reverse(self.members[l].len()));
        let mut labels = vec![0u16; len];
        for &l in &order {
            for &n in self.members[&l].iter().filter(|&&n| keep(n)) {
                labels[n] = l as u16;
            }
        }
        labels
    }
}

/// Whether `labels` lie on the CT's grid, voxel for voxel.
fn same_grid(labels: &Volume, ct: &Volume) -> bool {
    ct.same_grid(labels, 1e-6, 1e-6)
}

/// The voxel of a grid of `dims` nearest the point `p` that `to_index` maps into the grid's
/// index space (from LPS mm, or from another grid's indices); `None` outside the grid.
pub fn nearest_voxel(
    to_index: &raystream_math::DAffine3,
    [nx, ny, nz]: [usize; 3],
    p: raystream_math::DVec3,
) -> Option<[usize; 3]> {
    let q = to_index.transform_point3(p).round();
    let inside = q.min_element() >= 0.0 && q.x < nx as f64 && q.y < ny as f64 && q.z < nz as f64;
    inside.then_some([q.x as usize, q.y as usize, q.z as usize])
}

/// Each CT voxel's segments in `labels` (a label volume; with `whole`, its segments each
/// whole, overlaps and all), gathered as the CT voxels of each label into `members`; how they
/// were matched: voxel for voxel on the CT's own grid, else the label voxel nearest each CT
/// voxel's centre.
fn labels_on_ct(
    ct: &Volume,
    (labels, whole): (&Volume, Option<&raystream_io::WholeSegments>),
    members: &mut BTreeMap<u32, Vec<usize>>,
) -> &'static str {
    let [nx, ny, nz] = ct.dims;
    let same = same_grid(labels, ct);
    let to_labels = labels.index_to_world_affine().inverse() * ct.index_to_world_affine();
    // Slice by slice in parallel (a 512³ CT on another grid took 2.9 s on one thread), each
    // slice's (label, voxel within the slice) pairs in voxel order, gathered in slice order:
    // the same lists. A batch of slices at a time, so that the pairs (8 bytes a voxel) are a
    // batch's, not the whole CT's beside its lists (a voxel's index within its slice fits in
    // a u32: a volume holds at most raystream_io::MAX_VOXELS, 2³⁰).
    use rayon::prelude::*;
    const BATCH: usize = 16;
    let slice = nx * ny;
    for first in (0..nz).step_by(BATCH) {
        let slices: Vec<Vec<(u32, u32)>> = (first..(first + BATCH).min(nz))
            .into_par_iter()
            .map(|k| {
                let mut found = Vec::new();
                for j in 0..ny {
                    for i in 0..nx {
                        let q = if same {
                            [i, j, k]
                        } else {
                            let ijk = raystream_math::DVec3::new(i as f64, j as f64, k as f64);
                            match nearest_voxel(&to_labels, labels.dims, ijk) {
                                Some(q) => q,
                                None => continue,
                            }
                        };
                        let m = (i + nx * j) as u32;
                        match whole {
                            Some(segments) => {
                                for (l, v) in segments {
                                    if v.holds(q) {
                                        found.push((*l as u32, m));
                                    }
                                }
                            }
                            None => {
                                let l = labels.at(q[0], q[1], q[2]);
                                if l > 0.0 {
                                    found.push((l as u32, m));
                                }
                            }
                        }
                    }
                }
                found
            })
            .collect();
        for (k, found) in (first..).zip(slices) {
            for (l, m) in found {
                members.entry(l).or_default().push(k * slice + m as usize);
            }
        }
    }
    if same {
        "the CT's grid"
    } else {
        "the nearest label voxel to each CT voxel's centre"
    }
}

/// What `--segmentation` (and `--segment`) make of a CT rendered directly: the segments'
/// colours on its grid (dvr, iso, cinematic), and the CT kept to the chosen segments.
pub struct Painted {
    pub colours: Option<SegmentColours>,
    /// `--segment LIST`: the CT with every voxel outside the chosen segments set to the CT's
    /// lowest value (air), so that only they are drawn; for mip, minip and average to 0, which
    /// `weights` leaves out.
    pub kept: Option<Volume>,
    /// mip, minip and average kept to segments: 1 at each kept voxel, 0 at each hidden one,
    /// on the CT's grid (`CpuVolume::kept`): each sample is the kept voxels' own blend within
    /// the segments and projects nothing outside them, so that no hidden voxel counts and no
    /// fill value blends in at a segment's edge (rays that meet no segment are misses: NaN
    /// in an EXR, padding in DICOM).
    pub weights: Option<Volume>,
    /// An average kept to segments: the window (width, level) in HU of the kept voxels' values
    /// ([`spanning_window`]), for a picture without `--window` (the average's own window, −800
    /// to 200 HU, is made for whole-body rays of air and tissue, and leaves an organ or a
    /// contrast lumen one flat grey or white).
    pub window: Option<(f32, f32)>,
    /// What the summary line says of it.
    pub words: String,
    /// The segments drawn in colour, named (`--legend`): none for mip and minip.
    pub legend: Vec<crate::legend::Entry>,
}

/// What `--segmentation`, `--segment` and `--colour-table` ask of a CT rendered directly.
#[derive(Clone, Copy)]
pub struct Asked<'a> {
    pub segmentation: Option<&'a Path>,
    pub segment: Option<&'a str>,
    pub colour_table: Option<&'a Path>,
}

impl<'a> Asked<'a> {
    pub fn of_render(a: &'a RenderArgs) -> Asked<'a> {
        Asked {
            segmentation: a.segmentation.as_deref(),
            segment: a.segment.as_deref(),
            colour_table: a.colour_table.as_deref(),
        }
    }
}

/// `render|bench CT --mode MODE --segmentation LABELS [--segment LIST]` (every mode but
/// slice, whose pixels `--segmentation` tints instead): with dvr, iso and cinematic each sample
/// takes its segment's colour, blended between voxels (`raystream_cpu::segments`), and the
/// transfer function's opacity; `--segment LIST` keeps only the segments listed (mip, minip
/// and average too: a MIP of the aorta without the bones in front of it, a MinIP of the lungs'
/// airways without the air around the chest, the liver's mean HU along each ray). `None`
/// without `--segmentation`.
pub fn paint(a: Asked, mode: DvrMode, ct: &Volume, input: &Path) -> Result<Option<Painted>> {
    let Some(file) = a.segmentation else {
        if let Some(list) = a.segment {
            bail!(
                "--segment {list} with --mode {}: keeps only those segments of a CT's segmentation: give --segmentation LABELS (a label map, DICOM Segmentation or RT Structure Set)",
                mode.name()
            );
        }
        return Ok(None);
    };
    let name = file.display();
    match mode {
        DvrMode::Dvr | DvrMode::Iso | DvrMode::Cinematic => {}
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average if a.segment.is_some() => {}
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average => bail!(
            "--segmentation {name} with --mode {}: a projection shows HU, not colours; give --segment LIST to project only those segments",
            mode.name()
        ),
        DvrMode::Slice => bail!(
            "--segmentation {name} with --mode slice: a slice is tinted by its segments, not kept to them"
        ),
    }
    let on = on_ct(file, a.colour_table, ct, input)?;
    let present: Vec<u32> = on.members.keys().copied().collect();
    let chosen = match a.segment {
        Some(list) => crate::iso::pick_segments(&name, "--segment ", list, &present, &on.known)?,
        None => present.clone(),
    };
    if let Some(&l) = chosen.iter().find(|&&l| l > MAX_LABEL) {
        bail!("{name}: label {l}: labels above {MAX_LABEL} are not rendered in colour");
    }
    let labels = on.laid(&chosen, ct.data.len(), |_| true);
    // Each segment's name and colour, once: the legend's, and linear, the samples'.
    let entries = crate::legend::entries(&chosen, &on.known);
    let colours: Vec<(u32, Vec3)> = chosen
        .iter()
        .zip(&entries)
        .map(|(&l, e)| {
            let c = e.colour.map(|c| raystream_io::SRGB_TO_LINEAR[c as usize]);
            (l, Vec3::from(c))
        })
        .collect();
    let range = ct.value_range().unwrap_or((-1024.0, 3071.0));
    let projected = mode.is_projection() && a.segment.is_some();
    let kept = a.segment.map(|_| {
        let fill = if projected { 0.0 } else { range.0 };
        let mut kept = ct.clone();
        for (v, &l) in kept.data.iter_mut().zip(&labels) {
            if l == 0 {
                *v = fill;
            }
        }
        kept
    });
    let weights = projected.then(|| {
        let data = labels
            .iter()
            .map(|&l| if l > 0 { 1.0 } else { 0.0 })
            .collect();
        Volume {
            origin: ct.origin,
            direction: ct.direction,
            ..Volume::hounsfield(ct.dims, ct.spacing, data)
        }
    });
    let window = if mode == DvrMode::Average && a.segment.is_some() {
        let mut values: Vec<f32> = ct
            .data
            .iter()
            .zip(&labels)
            .filter(|&(_, &l)| l > 0)
            .map(|(&v, _)| v)
            .collect();
        spanning_window(&mut values)
    } else {
        None
    };
    let voxels = labels.iter().filter(|&&l| l > 0).count();
    let list: Vec<String> = chosen.iter().map(|l| l.to_string()).collect();
    let words = format!(
        "{} {} of {} ({voxels} voxels, matched on {}){}",
        if chosen.len() == 1 {
            "segment"
        } else {
            "segments"
        },
        list.join(", "),
        crate::common::file_name(file),
        on.how,
        if kept.is_some() {
            ", the rest hidden"
        } else {
            ""
        }
    );
    let coloured = matches!(mode, DvrMode::Dvr | DvrMode::Iso | DvrMode::Cinematic);
    let legend = if coloured { entries } else { Vec::new() };
    let colours = coloured.then(|| SegmentColours::new(ct.dims, labels, &colours));
    Ok(Some(Painted {
        colours,
        kept,
        weights,
        window,
        words,
        legend,
    }))
}

/// A window (width, level) for `values` (reordered): centred on their median, twice as wide as
/// their 10th to 90th percentile (about ±2.5 standard deviations of a normal spread, so that
/// a mean along a ray, which varies less than the voxels, still spans grey levels, and a few
/// voxels of metal, such as a stent's 5–8 % of a lumen, do not stretch it), at least 1 HU wide;
/// `None` for no values.
pub fn spanning_window(values: &mut [f32]) -> Option<(f32, f32)> {
    if values.is_empty() {
        return None;
    }
    let last = values.len() - 1;
    let mut at = |q: f32| {
        let k = (q * last as f32).round() as usize;
        *values.select_nth_unstable_by(k, f32::total_cmp).1
    };
    let (p10, median, p90) = (at(0.1), at(0.5), at(0.9));
    Some(((2.0 * (p90 - p10)).max(1.0), median))
}

/// A scene file's `[volume]` with `segmentation` (and `segment`, `colour_table`): the
/// segmentation laid on the volume's grid as `render CT --mode dvr --segmentation` lays it, its
/// colours set on the volume (`SceneVolume::segments`) and the volume kept to the chosen
/// segments; what the summary says of it and `--legend`'s entries, or `None` for a scene
/// without one.
pub fn paint_scene(
    scene: &mut raystream_scene::Scene,
    file: &Path,
) -> Result<Option<(String, Vec<crate::legend::Entry>)>> {
    let Some(v) = scene.volume.as_mut() else {
        return Ok(None);
    };
    let Some(s) = v.segmentation.clone() else {
        return Ok(None);
    };
    let asked = Asked {
        segmentation: Some(&s.path),
        segment: s.segment.as_deref(),
        colour_table: s.colour_table.as_deref(),
    };
    let painted = paint(asked, DvrMode::Dvr, &v.volume, file)
        .with_context(|| format!("{}: [volume] segmentation", file.display()))?
        .expect("a segmentation given");
    if let Some(kept) = painted.kept {
        v.volume = kept;
    }
    v.segments = painted.colours;
    Ok(Some((painted.words, painted.legend)))
}

#[cfg(test)]
mod tests {
    use super::spanning_window;

    #[test]
    fn a_window_is_centred_on_the_median_and_ignores_the_tails() {
        // 0..=100 HU in any order: median 50, 10th and 90th percentiles 10 and 90.
        let mut v: Vec<f32> = (0..=100).rev().map(|x| x as f32).collect();
        assert_eq!(spanning_window(&mut v), Some((160.0, 50.0)));
        // A tenth of the voxels metal does not move it.
        let mut v: Vec<f32> = (0..=100).map(|x| x as f32).collect();
        v.extend([3000.0; 9]);
        let (w, l) = spanning_window(&mut v).unwrap();
        assert!(w < 200.0 && (50.0..=60.0).contains(&l), "{w}/{l}");
        // One value: a window 1 HU wide on it; none: no window.
        assert_eq!(spanning_window(&mut [42.0]), Some((1.0, 42.0)));
        assert_eq!(spanning_window(&mut []), None);
    }
}
