//! A DICOM RT Structure Set (SOP class 1.2.840.10008.5.1.4.1.1.481.3), the contours a
//! radiotherapy planning system or a contouring tool draws on a CT series, read as a label
//! volume on that series' grid. A structure set holds no grid: each structure (ROI) is a stack
//! of closed planar polygons in LPS millimetres, drawn on the CT's slices, so the CT series it
//! references is found beside it (its folder, then the folders beside that) and each polygon is
//! laid on the slice whose plane it lies in.
//!
//! A voxel belongs to a structure when its centre lies inside the structure's polygons on its
//! slice by the even-odd rule over all of them (a polygon inside another is a hole, the way
//! planning systems store a ring; two apart are two pieces), or on one of their edges (within
//! [`ON_EDGE`] of a voxel). The edges count because structure sets made from voxel masks
//! (rt-utils, and so TotalSegmentator's DICOM output: OpenCV's border following) trace each
//! slice's boundary through the centres of its boundary voxels, the holes' too: those voxels
//! are the structure's, and with them its mask comes back whole. A contour drawn in millimetres
//! passes through a centre only by chance. Rasterised by hand: scanline filling on a slice's
//! pixel centres is a few lines, and the rasterising crates fill the pixels a polygon touches
//! or covers, not centres by the even-odd rule.
//!
//! Structures overlap as a matter of course (the body outline holds every organ), which a label
//! volume cannot hold: the label volume paints the largest structures first, so that a smaller
//! one stays whole over a larger, and says how many voxels were painted over; each structure's
//! own voxels, whole, are [`StructureSet::rasterise`]'s.

use std::path::{Path, PathBuf};

use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;
use raystream_math::DVec3;

use super::dicom::{DicomStudy, FileMeta, text_of, transfer_syntax_name};
use super::{DicomSeriesInfo, Phase, SegmentLabel, ValueUnit, Volume, VolumeError, VolumeFormat};

/// RT Structure Set Storage.
pub const RT_STRUCTURE_SET: &str = "1.2.840.10008.5.1.4.1.1.481.3";
/// The most contour points a structure set may hold (each three decimal strings in the file).
const MAX_POINTS: usize = 50_000_000;

/// Whether the data set is an RT Structure Set.
pub(crate) fn is_structure_set(meta: &FileMeta, obj: &InMemDicomObject) -> bool {
    meta.sop_class_of(obj) == RT_STRUCTURE_SET
}

/// An RT Structure Set as read: its structures and the CT series it was drawn on.
#[derive(Clone, Debug, Default)]
pub struct StructureSet {
    /// The file it was read from.
    pub file: PathBuf,
    /// Structure Set Label.
    pub label: String,
    /// Its own series, description and study (for `info`, and a label volume's series).
    pub series_uid: String,
    pub description: String,
    pub study: DicomStudy,
    pub transfer_syntax: String,
    /// The Frame of Reference its contours are in.
    pub frame_of_reference_uid: String,
    /// The image series its contours were drawn on (RT Referenced Series).
    pub referenced_series: Vec<String>,
    pub rois: Vec<Roi>,
}

/// One structure (ROI) of a structure set.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Roi {
    /// ROI Number: its voxels' value in the label volume.
    pub number: u16,
    /// ROI Name.
    pub name: String,
    /// ROI Display Color (sRGB), if it has one.
    pub colour: Option<[u8; 3]>,
    /// RT ROI Interpreted Type (ORGAN, PTV, EXTERNAL, …), if the observations give one.
    pub kind: String,
    /// Its closed planar contours, each a polygon of LPS points.
    pub contours: Vec<Vec<DVec3>>,
    /// Contours of other kinds (POINT, OPEN_PLANAR, OPEN_NONPLANAR), which hold no voxel.
    pub other_contours: usize,
}

/// The voxels of a structure on a grid: a box of the grid (its lowest voxel `lo` and its size
/// `dims`) and which of the box's voxels it holds, i fastest.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SegmentVoxels {
    pub lo: [usize; 3],
    pub dims: [usize; 3],
    pub inside: Vec<bool>,
    /// How many voxels it holds.
    pub voxels: usize,
}

impl SegmentVoxels {
    /// The voxels on a grid of `from` voxels, one layer along some axes, on a grid of `to`
    /// that repeats that layer along them (a lone slice's slab,
    /// [`Volume::slab_of_lone_slices`]): each voxel held on every layer.
    fn thickened(&self, from: [usize; 3], to: [usize; 3]) -> SegmentVoxels {
        if self.voxels == 0 {
            return self.clone();
        }
        let wide: [bool; 3] = std::array::from_fn(|a| from[a] == 1 && to[a] > 1);
        let lo = std::array::from_fn(|a| if wide[a] { 0 } else { self.lo[a] });
        let size: [usize; 3] = std::array::from_fn(|a| if wide[a] { to[a] } else { self.dims[a] });
        let src = |x: usize, a: usize| if wide[a] { 0 } else { x };
        let mut inside = Vec::with_capacity(size[0] * size[1] * size[2]);
        for k in 0..size[2] {
            for j in 0..size[1] {
                for i in 0..size[0] {
                    let (i, j, k) = (src(i, 0), src(j, 1), src(k, 2));
                    inside.push(self.inside[i + self.dims[0] * (j + self.dims[1] * k)]);
                }
            }
        }
        let voxels = inside.iter().filter(|&&b| b).count();
        SegmentVoxels {
            lo,
            dims: size,
            inside,
            voxels,
        }
    }

    /// Whether it holds the grid's voxel `ijk`.
    pub fn holds(&self, ijk: [usize; 3]) -> bool {
        let at: [Option<usize>; 3] =
            std::array::from_fn(|a| ijk[a].checked_sub(self.lo[a]).filter(|&d| d < self.dims[a]));
        match at {
            [Some(i), Some(j), Some(k)] => self.inside[i + self.dims[0] * (j + self.dims[1] * k)],
            _ => false,
        }
    }
}

/// How a structure's contours met the grid, for the warnings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterNotes {
    /// Contours whose points do not lie in one slice's plane (not drawn on this grid).
    pub off_plane: usize,
    /// Contours whose plane lies beyond the first or the last slice.
    pub beyond: usize,
    /// Contours laid on their nearest slice from over a quarter of the spacing away.
    pub between: usize,
}

impl StructureSet {
    /// Reads the structure set in `file` (an RT Structure Set, or an error saying what the file
    /// is instead).
    pub fn read(file: &Path) -> Result<StructureSet, VolumeError> {
        let bytes = std::fs::read(file).map_err(|e| VolumeError::io(file, e))?;
        let (meta, obj) = super::dicom::parse_dataset(&bytes, file)?;
        if !is_structure_set(&meta, &obj) {
            return Err(VolumeError::invalid(
                file,
                format!(
                    "not a DICOM RT Structure Set (SOP class {})",
                    meta.sop_class_of(&obj)
                ),
            ));
        }
        parse(file, &meta, &obj)
    }

    /// Why its contours cannot be laid on `ct`, if they cannot: the CT names a Frame of
    /// Reference (a DICOM series does) and it is not theirs, so it is another scan.
    pub fn frame_mismatch(&self, ct: &Volume) -> Option<String> {
        let theirs = &self.frame_of_reference_uid;
        let ct_frame = ct
            .series
            .as_ref()
            .map(|s| s.study.frame_of_reference_uid.as_str())
            .unwrap_or("");
        (!ct_frame.is_empty() && !theirs.is_empty() && ct_frame != theirs).then(|| {
            format!(
                "its contours are in the Frame of Reference {theirs}, and the CT in {ct_frame}: they were drawn on another scan"
            )
        })
    }

    /// The structures as a label volume's segments: number, name and colour.
    pub fn segments(&self) -> Vec<SegmentLabel> {
        self.rois
            .iter()
            .map(|r| SegmentLabel {
                number: r.number,
                label: r.name.clone(),
                colour: r.colour,
                ..Default::default()
            })
            .collect()
    }

    /// The folder holding the image series the contours were drawn on, and that series' UID:
    /// the structure set's own folder, else a folder beside it (the usual layout of an export:
    /// a folder a series). The series it references by UID, else (an anonymised export may
    /// blank the UIDs it references) the largest series in its Frame of Reference.
    pub fn find_images(&self) -> Result<(PathBuf, String), VolumeError> {
        let file = &self.file;
        if self.referenced_series.is_empty() && self.frame_of_reference_uid.is_empty() {
            return Err(VolumeError::invalid(
                file,
                "DICOM RT Structure Set: it names no image series (RT Referenced Series Sequence) and no Frame of Reference, so there is no grid to lay its contours on",
            ));
        }
        let own = match file.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let mut folders = vec![own.to_path_buf()];
        // The folder above, found from the real path: a relative `rt/structures.dcm`'s folder
        // has the empty path for parent (which read_dir refuses), and `structures.dcm`'s is
        // "." (whose parent is empty too). Its own folder is not read twice.
        let own_real = std::fs::canonicalize(own).ok();
        if let Some(Ok(entries)) = own_real
            .as_deref()
            .and_then(Path::parent)
            .map(std::fs::read_dir)
        {
            let mut beside: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir() && std::fs::canonicalize(p).ok() != own_real)
                .collect();
            beside.sort();
            folders.extend(beside);
        }
        let mut same_frame: Option<(PathBuf, String, usize)> = None;
        for folder in &folders {
            // A folder of anything but DICOM images is passed over.
            let Ok(series) = super::dicom::series_and_frames(folder) else {
                continue;
            };
            for (uid, n, frame) in series {
                if self.referenced_series.contains(&uid) {
                    return Ok((folder.clone(), uid));
                }
                if !frame.is_empty()
                    && frame == self.frame_of_reference_uid
                    && same_frame.as_ref().is_none_or(|s| s.2 < n)
                {
                    same_frame = Some((folder.clone(), uid, n));
                }
            }
        }
        if let Some((folder, uid, _)) = same_frame {
            return Ok((folder, uid));
        }
        let wanted = if self.referenced_series.is_empty() {
            format!("in its Frame of Reference {}", self.frame_of_reference_uid)
        } else {
            format!("({})", self.referenced_series.join(", "))
        };
        Err(VolumeError::invalid(
            file,
            format!(
                "DICOM RT Structure Set: the image series its contours were drawn on {wanted} is neither in its folder nor in a folder beside it ({} folders looked in); put the structure set beside its CT series",
                folders.len()
            ),
        ))
    }

    /// The voxels of `roi` on `grid`'s slices (see the module docs), and how its contours met
    /// the grid.
    pub fn rasterise(&self, roi: &Roi, grid: &Volume) -> (SegmentVoxels, RasterNotes) {
        let (region, notes) = self.rasterise_on_slices(roi, grid);
        if notes.between == 0 || grid.dims[2] != 2 {
            return (region, notes);
        }
        // A lone slice drawn as the slab it images (Volume::slab_of_lone_slices): contours
        // drawn on the slice lie midway between the slab's two layers, which are both the
        // slice, so they are laid on the slice and it is thickened as the CT was, rather than
        // on one layer arbitrarily.
        if let Some(slice) = grid.lone_slice_of_slab().filter(|s| s.dims[2] == 1) {
            let (on_slice, n) = self.rasterise_on_slices(roi, &slice);
            if n.between == 0 && n.beyond <= notes.beyond && n.off_plane <= notes.off_plane {
                return (on_slice.thickened(slice.dims, grid.dims), n);
            }
        }
        (region, notes)
    }

    /// [`Self::rasterise`] on `grid`'s slices as they stand.
    fn rasterise_on_slices(&self, roi: &Roi, grid: &Volume) -> (SegmentVoxels, RasterNotes) {
        let [nx, ny, nz] = grid.dims;
        let to_index = grid.index_to_world_affine().inverse();
        let mut notes = RasterNotes::default();
        // Each slice's polygons, in index coordinates (i, j).
        let mut slices: std::collections::BTreeMap<usize, Vec<Vec<[f64; 2]>>> = Default::default();
        for contour in &roi.contours {
            let idx: Vec<DVec3> = contour
                .iter()
                .map(|&p| to_index.transform_point3(p))
                .collect();
            let (lo, hi) = idx
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.z), b.max(p.z))
                });
            if hi - lo > 0.5 {
                notes.off_plane += 1;
                continue;
            }
            let k = 0.5 * (lo + hi);
            let slice = k.round();
            if slice < 0.0 || slice >= nz as f64 {
                notes.beyond += 1;
                continue;
            }
            if (k - slice).abs() > 0.25 {
                notes.between += 1;
            }
            slices
                .entry(slice as usize)
                .or_default()
                .push(idx.iter().map(|p| [p.x, p.y]).collect());
        }
        // Each slice's spans of voxels: (k, j, first i, past the last i). The edges are put
        // in the rows they cross (an edge table), so that a slice costs its edges and the rows
        // they cross, not every edge on every row.
        let mut spans: Vec<(usize, usize, usize, usize)> = Vec::new();
        for (&k, polygons) in &slices {
            let (ylo, yhi) = polygons
                .iter()
                .flatten()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p[1]), b.max(p[1]))
                });
            let j0 = (ylo - ON_EDGE).ceil().max(0.0);
            let j1 = (yhi + ON_EDGE).floor().min(ny as f64 - 1.0);
            if j0.is_nan() || j1.is_nan() || j0 > j1 {
                continue;
            }
            let (j0, j1) = (j0 as usize, j1 as usize);
            // The rows from `lo` to `hi`, as indices from j0.
            let rows = |lo: f64, hi: f64| -> std::ops::Range<usize> {
                let (a, b) = (lo.ceil().max(j0 as f64), hi.floor().min(j1 as f64));
                if a <= b {
                    a as usize - j0..b as usize - j0 + 1
                } else {
                    0..0
                }
            };
            let mut crossings: Vec<Vec<f64>> = vec![Vec::new(); j1 - j0 + 1];
            let mut edges: Vec<Vec<(f64, f64)>> = vec![Vec::new(); j1 - j0 + 1];
            for polygon in polygons {
                for (n, &a) in polygon.iter().enumerate() {
                    let b = polygon[(n + 1) % polygon.len()];
                    let (ymin, ymax) = (a[1].min(b[1]), a[1].max(b[1]));
                    for r in rows(ymin, ymax) {
                        let y = (j0 + r) as f64;
                        if (a[1] <= y) != (b[1] <= y) {
                            crossings[r].push(a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
                        }
                    }
                    // Centres on the edge: the stretch of each row within ON_EDGE of it.
                    for r in rows(ymin - ON_EDGE, ymax + ON_EDGE) {
                        if let Some(stretch) = on_edge(a, b, (j0 + r) as f64) {
                            edges[r].push(stretch);
                        }
                    }
                }
            }
            for (r, (row, on)) in crossings.iter_mut().zip(&edges).enumerate() {
                let j = j0 + r;
                let mut span = |x0: f64, x1: f64| {
                    // Voxels whose centre x lies in [x0, x1).
                    let (i0, i1) = (x0.ceil().max(0.0), x1.ceil().min(nx as f64));
                    if i0 < i1 {
                        spans.push((k, j, i0 as usize, i1 as usize));
                    }
                };
                row.sort_by(f64::total_cmp);
                for pair in row.chunks_exact(2) {
                    span(pair[0], pair[1]);
                }
                for &(x0, x1) in on {
                    span(x0, x1.floor() + 1.0);
                }
            }
        }
        let mut region = SegmentVoxels::default();
        if spans.is_empty() {
            return (region, notes);
        }
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        for &(k, j, i0, i1) in &spans {
            for (a, (l, h)) in [(i0, i1 - 1), (j, j), (k, k)].into_iter().enumerate() {
                lo[a] = lo[a].min(l);
                hi[a] = hi[a].max(h);
            }
        }
        let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
        let mut inside = vec![false; dims[0] * dims[1] * dims[2]];
        for &(k, j, i0, i1) in &spans {
            let row = dims[0] * (j - lo[1] + dims[1] * (k - lo[2]));
            inside[row + i0 - lo[0]..row + i1 - lo[0]].fill(true);
        }
        region.voxels = inside.iter().filter(|&&b| b).count();
        region.lo = lo;
        region.dims = dims;
        region.inside = inside;
        (region, notes)
    }

    /// Every structure's voxels on `grid`, in the order of [`StructureSet::rois`], with the
    /// warnings their contours call for.
    pub fn regions(&self, grid: &Volume) -> (Vec<SegmentVoxels>, Vec<String>) {
        let mut warnings = Vec::new();
        let regions = self
            .rois
            .iter()
            .map(|roi| {
                let (region, n) = self.rasterise(roi, grid);
                let name = format!("structure {} ({})", roi.number, roi.name);
                if n.off_plane > 0 {
                    warnings.push(format!(
                        "{name}: {} contours do not lie in a slice of the CT; they are left out",
                        n.off_plane
                    ));
                }
                if n.beyond > 0 {
                    warnings.push(format!(
                        "{name}: {} contours lie beyond the CT's first or last slice; they are left out",
                        n.beyond
                    ));
                }
                if n.between > 0 {
                    warnings.push(format!(
                        "{name}: {} contours lie between slices of the CT, each laid on its nearest",
                        n.between
                    ));
                }
                region
            })
            .collect();
        (regions, warnings)
    }

    /// `regions` (its structures' voxels, as [`StructureSet::regions`] gives them) labelled
    /// with their structures' numbers, the empty ones left out, in increasing order.
    pub fn whole(&self, regions: Vec<SegmentVoxels>) -> WholeSegments {
        let mut whole: WholeSegments = self
            .rois
            .iter()
            .map(|r| r.number)
            .zip(regions)
            .filter(|(_, v)| v.voxels > 0)
            .collect();
        whole.sort_by_key(|(l, _)| *l);
        whole
    }

    /// The structures as a label volume on `grid` (the series they were drawn on), each voxel
    /// the number of the structure holding it, the largest painted first (see the module docs).
    pub fn label_volume(&self, grid: &Volume) -> Volume {
        let (regions, warnings) = self.regions(grid);
        self.paint(grid, &regions, warnings)
    }

    /// Its structures' voxels on `grid` ([`StructureSet::regions`]) as a label volume, the
    /// largest painted first, with `warnings`.
    pub fn paint(
        &self,
        grid: &Volume,
        regions: &[SegmentVoxels],
        mut warnings: Vec<String>,
    ) -> Volume {
        let [nx, ny, _] = grid.dims;
        let mut order: Vec<usize> = (0..regions.len()).collect();
        order.sort_by_key(|&r| std::cmp::Reverse(regions[r].voxels));
        let mut data = vec![0f32; grid.voxel_count()];
        let mut over = 0usize;
        for r in order {
            let (region, label) = (&regions[r], self.rois[r].number as f32);
            let [dx, dy, dz] = region.dims;
            for k in 0..dz {
                for j in 0..dy {
                    let at = region.lo[0] + nx * (region.lo[1] + j + ny * (region.lo[2] + k));
                    let from = dx * (j + dy * k);
                    for (v, &held) in data[at..at + dx]
                        .iter_mut()
                        .zip(&region.inside[from..from + dx])
                    {
                        if held {
                            over += usize::from(*v != 0.0);
                            *v = label;
                        }
                    }
                }
            }
        }
        if over > 0 {
            warnings.push(format!(
                "{over} voxels lie in more than one structure; the label volume holds the smallest's there (iso --segment and info take each structure whole)"
            ));
        }
        Volume {
            dims: grid.dims,
            spacing: grid.spacing,
            origin: grid.origin,
            direction: grid.direction,
            data,
            unit: ValueUnit::Unknown,
            format: VolumeFormat::Dicom,
            series: Some(DicomSeriesInfo {
                uid: self.series_uid.clone(),
                description: self.description.clone(),
                modality: "RTSTRUCT".into(),
                count: 1,
                transfer_syntax: self.transfer_syntax.clone(),
                transfer_syntax_name: transfer_syntax_name(&self.transfer_syntax),
                all: Vec::new(),
                study: self.study.clone(),
                sources: Vec::new(),
            }),
            segments: self.segments(),
            phase: Phase::default(),
            warnings,
        }
    }
}

/// Segments each whole: each one's label and voxels, in increasing order of label.
pub type WholeSegments = Vec<(u16, SegmentVoxels)>;

/// Each label's voxels whole, overlaps and all, in increasing order of label: `visit` hands
/// its argument each voxel a label holds (the label, and the voxel's i, j, k). It is run
/// twice, once to find each label's box and once to fill it.
pub(crate) fn gather_whole(
    mut visit: impl FnMut(&mut dyn FnMut(u16, [usize; 3])),
) -> WholeSegments {
    let mut boxes: std::collections::BTreeMap<u16, ([usize; 3], [usize; 3])> = Default::default();
    visit(&mut |label, ijk| {
        let e = boxes.entry(label).or_insert((ijk, ijk));
        e.0 = std::array::from_fn(|a| e.0[a].min(ijk[a]));
        e.1 = std::array::from_fn(|a| e.1[a].max(ijk[a]));
    });
    let mut whole: WholeSegments = boxes
        .iter()
        .map(|(&l, &(lo, hi))| {
            let dims = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
            let v = SegmentVoxels {
                lo,
                dims,
                inside: vec![false; dims[0] * dims[1] * dims[2]],
                voxels: 0,
            };
            (l, v)
        })
        .collect();
    visit(&mut |label, ijk| {
        let Ok(s) = whole.binary_search_by_key(&label, |(l, _)| *l) else {
            return;
        };
        let v = &mut whole[s].1;
        let [i, j, k] = std::array::from_fn(|a| ijk[a] - v.lo[a]);
        let at = i + v.dims[0] * (j + v.dims[1] * k);
        v.voxels += usize::from(!v.inside[at]);
        v.inside[at] = true;
    });
    whole
}

/// How near an edge, in voxels, a voxel's centre counts as on it.
pub const ON_EDGE: f64 = 1e-3;

/// The stretch `[x0, x1]` of the row at `y` whose points lie within about [`ON_EDGE`] of the
/// edge from `a` to `b` (the band of that width about its line, clipped to its ends), if any.
fn on_edge(a: [f64; 2], b: [f64; 2], y: f64) -> Option<(f64, f64)> {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let (xlo, xhi) = (a[0].min(b[0]) - ON_EDGE, a[0].max(b[0]) + ON_EDGE);
    if dy.abs() <= ON_EDGE {
        let near = (y - a[1]).abs().min((y - b[1]).abs()) <= ON_EDGE
            || (a[1].min(b[1])..=a[1].max(b[1])).contains(&y);
        return near.then_some((xlo, xhi));
    }
    let t = (y - a[1]) / dy;
    let width = ON_EDGE * dx.hypot(dy) / dy.abs();
    let slack = ON_EDGE / dy.abs();
    if !(-slack..=1.0 + slack).contains(&t) {
        return None;
    }
    let x = a[0] + t * dx;
    let (x0, x1) = ((x - width).max(xlo), (x + width).min(xhi));
    (x0 <= x1).then_some((x0, x1))
}

/// Whether `path` is a DICOM file holding an RT Structure Set (read and parsed to tell).
pub fn is_structure_set_file(path: &Path) -> bool {
    if super::VolumeFormat::from_path(path) != Some(VolumeFormat::Dicom) || !path.is_file() {
        return false;
    }
    let Ok(bytes) = std::fs::read(path) else {
        return false;
    };
    super::dicom::parse_dataset(&bytes, path).is_ok_and(|(meta, obj)| is_structure_set(&meta, &obj))
}

/// Each segment of the label volume `labels` (read from `path`) whole, where its segments may
/// overlap, which a label volume cannot hold: an RT Structure Set's structures laid on
/// `labels`' grid, a DICOM Segmentation's segments, a 3D Slicer segmentation's on several
/// layers, a folder's masks that overlap (each read again); `None` for other label volumes, whose voxels each hold one label. Each with its label, in increasing order.
pub fn whole_segments(labels: &Volume, path: &Path) -> Result<Option<WholeSegments>, VolumeError> {
    if is_structure_set_volume(labels) {
        let set = StructureSet::read(path)?;
        return Ok(Some(set.whole(set.regions(labels).0)));
    }
    if labels.format == VolumeFormat::Nifti && path.is_dir() {
        return super::mask_folder::whole(labels, path);
    }
    if labels.format == VolumeFormat::Nrrd && !labels.segments.is_empty() && path.is_file() {
        let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
        return super::nrrd::whole_segments(&bytes, path);
    }
    let modality = labels.series.as_ref().map(|s| s.modality.as_str());
    if modality != Some("SEG") || !path.is_file() {
        return Ok(None);
    }
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    let (meta, obj) = super::dicom::parse_dataset(&bytes, path)?;
    if !super::segmentation::is_segmentation(&meta, &obj) {
        return Ok(None);
    }
    let (_, whole) = super::segmentation::read_segments(path, &meta, &obj, true)?;
    Ok(Some(whole))
}

/// Whether a label volume was read from an RT Structure Set (whose structures may overlap).
pub fn is_structure_set_volume(v: &Volume) -> bool {
    v.series.as_ref().is_some_and(|s| s.modality == "RTSTRUCT")
}

/// The structure set in `file` laid on the image series it references, as a label volume.
pub(crate) fn read_labels(
    file: &Path,
    meta: &FileMeta,
    obj: &InMemDicomObject,
) -> Result<Volume, VolumeError> {
    let set = parse(file, meta, obj)?;
    let (folder, uid) = set.find_images()?;
    let grid = super::dicom::load(&folder, &super::VolumeSelect::series(Some(&uid)))?;
    let mut labels = set.label_volume(&grid);
    let [nx, ny, nz] = grid.dims;
    let by = if set.referenced_series.contains(&uid) {
        ""
    } else if set.referenced_series.is_empty() {
        " (found by its Frame of Reference: it names no series)"
    } else {
        " (found by its Frame of Reference: the series it names is not there)"
    };
    let uid = if uid.is_empty() {
        "without a Series Instance UID"
    } else {
        uid.as_str()
    };
    labels.warnings.insert(
        0,
        format!(
            "its contours laid on the series {uid} ({nx}×{ny}×{nz} voxels) in {}{by}",
            folder.display()
        ),
    );
    Ok(labels)
}

/// The structure set in `obj` (read from `file`).
fn parse(
    file: &Path,
    meta: &FileMeta,
    obj: &InMemDicomObject,
) -> Result<StructureSet, VolumeError> {
    let bad =
        |problem: String| VolumeError::invalid(file, format!("DICOM RT Structure Set: {problem}"));
    let text = text_of;
    let items = |o: &InMemDicomObject, tag| -> Vec<InMemDicomObject> {
        o.get(tag)
            .and_then(|e| e.items())
            .map(|i| i.to_vec())
            .unwrap_or_default()
    };
    let number = |o: &InMemDicomObject, tag, what: &str| -> Result<u16, VolumeError> {
        let v = o
            .get(tag)
            .and_then(|e| e.to_int::<i64>().ok())
            .ok_or_else(|| bad(format!("{what} without its number")))?;
        u16::try_from(v)
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| bad(format!("{what} numbered {v} (1 to 65535 are read)")))
    };
    let mut rois: Vec<Roi> = Vec::new();
    for item in items(obj, tags::STRUCTURE_SET_ROI_SEQUENCE) {
        let n = number(&item, tags::ROI_NUMBER, "a structure")?;
        if rois.iter().any(|r| r.number == n) {
            return Err(bad(format!("two structures are numbered {n}")));
        }
        rois.push(Roi {
            number: n,
            name: text(&item, tags::ROI_NAME),
            ..Default::default()
        });
    }
    if rois.is_empty() {
        return Err(bad(
            "it holds no structure (Structure Set ROI Sequence)".into()
        ));
    }
    let mut points = 0usize;
    for item in items(obj, tags::ROI_CONTOUR_SEQUENCE) {
        let n = number(&item, tags::REFERENCED_ROI_NUMBER, "a contour set")?;
        let roi = rois
            .iter_mut()
            .find(|r| r.number == n)
            .ok_or_else(|| bad(format!("contours of structure {n}, which it does not list")))?;
        roi.colour = item
            .get(tags::ROI_DISPLAY_COLOR)
            .and_then(|e| e.to_multi_int::<i64>().ok())
            .and_then(|v| <[i64; 3]>::try_from(v).ok())
            .map(|c| c.map(|v| v.clamp(0, 255) as u8));
        let name = roi.name.clone();
        for (c, contour) in items(&item, tags::CONTOUR_SEQUENCE).iter().enumerate() {
            let what = || format!("structure {n} ({name}), contour {}", c + 1);
            let kind = text(contour, tags::CONTOUR_GEOMETRIC_TYPE);
            if kind != "CLOSED_PLANAR" {
                roi.other_contours += 1;
                continue;
            }
            let data: Vec<f64> = match contour.get(tags::CONTOUR_DATA) {
                Some(e) => e
                    .to_multi_float64()
                    .map_err(|e| bad(format!("{}: Contour Data: {e}", what())))?
                    .to_vec(),
                None => Vec::new(),
            };
            if !data.len().is_multiple_of(3) {
                return Err(bad(format!(
                    "{}: {} values of Contour Data, not a whole number of points",
                    what(),
                    data.len()
                )));
            }
            let count = data.len() / 3;
            if let Some(said) = contour
                .get(tags::NUMBER_OF_CONTOUR_POINTS)
                .and_then(|e| e.to_int::<i64>().ok())
                && said != count as i64
            {
                return Err(bad(format!(
                    "{}: Number of Contour Points says {said}; its Contour Data holds {count}",
                    what()
                )));
            }
            if let Some(v) = data.iter().find(|v| !v.is_finite()) {
                return Err(bad(format!("{}: a coordinate is {v}", what())));
            }
            points += count;
            if points > MAX_POINTS {
                return Err(bad(format!("over {MAX_POINTS} contour points")));
            }
            if count >= 1 {
                roi.contours.push(
                    data.chunks_exact(3)
                        .map(|p| DVec3::new(p[0], p[1], p[2]))
                        .collect(),
                );
            }
        }
    }
    for item in items(obj, tags::RTROI_OBSERVATIONS_SEQUENCE) {
        let n = item
            .get(tags::REFERENCED_ROI_NUMBER)
            .and_then(|e| e.to_int::<i64>().ok());
        if let Some(roi) = rois.iter_mut().find(|r| Some(r.number as i64) == n) {
            roi.kind = text(&item, tags::RTROI_INTERPRETED_TYPE);
        }
    }
    let mut frame_of_reference_uid = String::new();
    let mut referenced_series = Vec::new();
    for frame in items(obj, tags::REFERENCED_FRAME_OF_REFERENCE_SEQUENCE) {
        if frame_of_reference_uid.is_empty() {
            frame_of_reference_uid = text(&frame, tags::FRAME_OF_REFERENCE_UID);
        }
        for study in items(&frame, tags::RT_REFERENCED_STUDY_SEQUENCE) {
            for series in items(&study, tags::RT_REFERENCED_SERIES_SEQUENCE) {
                let uid = text(&series, tags::SERIES_INSTANCE_UID);
                if !uid.is_empty() && !referenced_series.contains(&uid) {
                    referenced_series.push(uid);
                }
            }
        }
    }
    Ok(StructureSet {
        file: file.to_path_buf(),
        label: text(obj, tags::STRUCTURE_SET_LABEL),
        series_uid: text(obj, tags::SERIES_INSTANCE_UID),
        description: text(obj, tags::SERIES_DESCRIPTION),
        study: DicomStudy::of(obj),
        transfer_syntax: meta.ts_uid.clone(),
        frame_of_reference_uid,
        referenced_series,
        rois,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::secondary_capture::write_dicom;
    use crate::segmentation::{item, seq, text};
    use dicom_core::{DataElement, PrimitiveValue, VR};

    /// One contour: its geometric type and its points, given in `grid`'s index space.
    type Contour = (&'static str, Vec<[f64; 3]>);

    /// A grid turned 30° about an oblique axis, voxels 0.8 × 0.7 × 2.5 mm.
    fn grid() -> Volume {
        let mut v = Volume::hounsfield([40, 30, 6], [0.8, 0.7, 2.5], vec![0.0; 40 * 30 * 6]);
        let r = raystream_math::DMat3::from_axis_angle(
            DVec3::new(1.0, 2.0, 3.0).normalize(),
            30f64.to_radians(),
        );
        v.direction = r.transpose().to_cols_array_2d();
        v.origin = [-10.0, 5.0, 30.0];
        v
    }

    /// Writes a structure set of `rois` (number, name, contours in `g`'s index space) to `name`.
    fn write(
        name: &str,
        g: &Volume,
        rois: &[(i64, &str, Vec<Contour>)],
    ) -> crate::tests::ScratchFile {
        let path = crate::tests::scratch_file(name);
        let decimals = |tag, v: Vec<f64>| {
            let s: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
            DataElement::new(tag, VR::DS, PrimitiveValue::Strs(s.into()))
        };
        let int = |tag, v: i64| DataElement::new(tag, VR::IS, PrimitiveValue::from(v.to_string()));
        let listed = rois
            .iter()
            .map(|(n, name, _)| {
                item(vec![
                    int(tags::ROI_NUMBER, *n),
                    text(tags::ROI_NAME, VR::LO, name),
                ])
            })
            .collect();
        let contours = rois
            .iter()
            .map(|(n, _, contours)| {
                let cs = contours
                    .iter()
                    .map(|(kind, points)| {
                        let world: Vec<f64> = points
                            .iter()
                            .flat_map(|&p| g.index_to_world(DVec3::from(p)).to_array())
                            .collect();
                        item(vec![
                            text(tags::CONTOUR_GEOMETRIC_TYPE, VR::CS, kind),
                            int(tags::NUMBER_OF_CONTOUR_POINTS, points.len() as i64),
                            decimals(tags::CONTOUR_DATA, world),
                        ])
                    })
                    .collect();
                item(vec![
                    int(tags::REFERENCED_ROI_NUMBER, *n),
                    DataElement::new(
                        tags::ROI_DISPLAY_COLOR,
                        VR::IS,
                        PrimitiveValue::Strs(["255".into(), "128".into(), "0".into()][..].into()),
                    ),
                    seq(tags::CONTOUR_SEQUENCE, cs),
                ])
            })
            .collect();
        let observations = rois
            .iter()
            .map(|(n, _, _)| {
                item(vec![
                    int(tags::REFERENCED_ROI_NUMBER, *n),
                    text(tags::RTROI_INTERPRETED_TYPE, VR::CS, "ORGAN"),
                ])
            })
            .collect();
        let series = item(vec![text(tags::SERIES_INSTANCE_UID, VR::UI, "1.2.3.4")]);
        let study = item(vec![seq(tags::RT_REFERENCED_SERIES_SEQUENCE, vec![series])]);
        let frame = item(vec![
            text(tags::FRAME_OF_REFERENCE_UID, VR::UI, "1.2.3.5"),
            seq(tags::RT_REFERENCED_STUDY_SEQUENCE, vec![study]),
        ]);
        let obj = InMemDicomObject::from_element_iter([
            text(tags::SOP_CLASS_UID, VR::UI, RT_STRUCTURE_SET),
            text(tags::SOP_INSTANCE_UID, VR::UI, "1.2.3.6"),
            text(tags::MODALITY, VR::CS, "RTSTRUCT"),
            text(tags::SERIES_INSTANCE_UID, VR::UI, "1.2.3.7"),
            text(tags::STRUCTURE_SET_LABEL, VR::SH, "test"),
            seq(tags::REFERENCED_FRAME_OF_REFERENCE_SEQUENCE, vec![frame]),
            seq(tags::STRUCTURE_SET_ROI_SEQUENCE, listed),
            seq(tags::ROI_CONTOUR_SEQUENCE, contours),
            seq(tags::RTROI_OBSERVATIONS_SEQUENCE, observations),
        ]);
        write_dicom(obj, &path, RT_STRUCTURE_SET, "1.2.3.6").unwrap();
        path
    }

    fn circle(c: [f64; 2], r: f64, k: f64, n: usize) -> Contour {
        let points = (0..n)
            .map(|s| {
                let a = std::f64::consts::TAU * s as f64 / n as f64;
                [c[0] + r * a.cos(), c[1] + r * a.sin(), k]
            })
            .collect();
        ("CLOSED_PLANAR", points)
    }

    fn rect(lo: [f64; 2], hi: [f64; 2], k: f64) -> Contour {
        let p = vec![
            [lo[0], lo[1], k],
            [hi[0], lo[1], k],
            [hi[0], hi[1], k],
            [lo[0], hi[1], k],
        ];
        ("CLOSED_PLANAR", p)
    }

    /// Brute force: whether the centre of voxel (i, j) lies within [`ON_EDGE`] of an edge of
    /// `polygons` (its distance to each segment), else inside them by the even-odd rule (an
    /// odd count of the edges crossing its row left of it).
    fn inside(polygons: &[&Vec<[f64; 3]>], i: usize, j: usize) -> bool {
        let q = DVec3::new(i as f64, j as f64, 0.0);
        let mut odd = false;
        for p in polygons {
            for (n, a) in p.iter().enumerate() {
                let b = p[(n + 1) % p.len()];
                let (a, b) = (DVec3::new(a[0], a[1], 0.0), DVec3::new(b[0], b[1], 0.0));
                let t = ((q - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
                if (a + t * (b - a)).distance(q) <= 0.5 * ON_EDGE {
                    return true;
                }
                if (a.y <= q.y) != (b.y <= q.y) {
                    odd ^= a.x + (q.y - a.y) * (b.x - a.x) / (b.y - a.y) <= q.x;
                }
            }
        }
        odd
    }

    #[test]
    fn contours_become_the_voxels_whose_centres_they_hold() {
        let g = grid();
        let ring: Vec<Contour> = (1..=3)
            .flat_map(|k| {
                let k = k as f64;
                [
                    circle([20.3, 14.6], 10.0, k, 64),
                    circle([20.3, 14.6], 4.0, k, 32),
                ]
            })
            .collect();
        // Two rectangles sharing the edge x = 12, corners on voxel centres.
        let squares = vec![
            rect([5.0, 5.0], [12.0, 9.0], 4.0),
            rect([12.0, 5.0], [16.0, 9.0], 4.0),
        ];
        let mut tilted = circle([10.0, 10.0], 3.0, 2.0, 12);
        tilted.1[0][2] = 2.8;
        let odd = vec![
            tilted,
            circle([30.0, 20.0], 3.0, 7.0, 12),
            circle([33.0, 25.0], 3.4, 2.4, 12),
            ("POINT", vec![[1.0, 1.0, 1.0]]),
            // A polygon reaching past the grid's edge (clipped to it), its sides between centres.
            rect([-5.5, 25.5], [3.5, 40.0], 5.0),
        ];
        let path = write(
            "shapes.dcm",
            &g,
            &[
                (1, "Ring", ring.clone()),
                (7, "Squares", squares.clone()),
                (3, "Odd", odd.clone()),
            ],
        );
        let set = StructureSet::read(&path).unwrap();
        assert_eq!(set.referenced_series, ["1.2.3.4"]);
        assert_eq!(set.frame_of_reference_uid, "1.2.3.5");
        assert_eq!(set.label, "test");
        let names: Vec<(u16, &str, &str)> = set
            .rois
            .iter()
            .map(|r| (r.number, r.name.as_str(), r.kind.as_str()))
            .collect();
        assert_eq!(
            names,
            [
                (1, "Ring", "ORGAN"),
                (7, "Squares", "ORGAN"),
                (3, "Odd", "ORGAN")
            ]
        );
        assert_eq!(set.rois[0].colour, Some([255, 128, 0]));
        assert_eq!(
            (set.rois[2].contours.len(), set.rois[2].other_contours),
            (4, 1)
        );

        let [nx, ny, nz] = g.dims;
        // Each structure's contours by slice, as drawn (the tilted one, off its plane, and the
        // one beyond the last slice, hold none; the one at k = 2.4 lies on slice 2).
        fn on(contours: &[Contour], k: usize) -> Vec<&Vec<[f64; 3]>> {
            contours
                .iter()
                .filter(|(kind, p)| {
                    *kind == "CLOSED_PLANAR"
                        && p.iter().all(|q| q[2] == p[0][2])
                        && p[0][2].round() as usize == k
                })
                .map(|(_, p)| p)
                .collect()
        }
        for (roi, contours) in set.rois.iter().zip([&ring, &squares, &odd]) {
            let (v, notes) = set.rasterise(roi, &g);
            let mut count = 0;
            for k in 0..nz {
                let polygons = on(contours, k);
                for j in 0..ny {
                    for i in 0..nx {
                        let want = inside(&polygons, i, j);
                        let r = [i, j, k].map(|x| x as isize);
                        let at = |a: usize| r[a] - v.lo[a] as isize;
                        let got = (0..3).all(|a| (0..v.dims[a] as isize).contains(&at(a)))
                            && v.inside[(at(0)
                                + v.dims[0] as isize * (at(1) + v.dims[1] as isize * at(2)))
                                as usize];
                        assert_eq!(got, want, "{} voxel {i} {j} {k}", roi.name);
                        count += usize::from(want);
                    }
                }
            }
            assert_eq!(v.voxels, count, "{}", roi.name);
            match roi.number {
                1 => {
                    // π (10² − 4²) voxels a slice, three slices.
                    let area = std::f64::consts::PI * (100.0 - 16.0) * 3.0;
                    assert!(
                        (count as f64 - area).abs() < 0.03 * area,
                        "{count} vs {area}"
                    );
                    assert_eq!(notes, RasterNotes::default());
                }
                7 => {
                    // 5..=16 by 5..=9: the centres on the edges, the shared one's too.
                    assert_eq!(count, 12 * 5);
                    assert_eq!((v.lo, v.dims), ([5, 5, 4], [12, 5, 1]));
                }
                _ => {
                    assert_eq!(
                        notes,
                        RasterNotes {
                            off_plane: 1,
                            beyond: 1,
                            between: 1
                        }
                    );
                    // The clipped rectangle: i 0..=3, j 26..=29.
                    assert!(count > 16);
                }
            }
        }

        // As a label volume: the largest painted first, so the squares and the ring keep theirs.
        let labels = set.label_volume(&g);
        let held = |l: f32| labels.data.iter().filter(|&&v| v == l).count();
        assert_eq!(held(7.0), 60);
        assert_eq!(held(1.0), set.rasterise(&set.rois[0], &g).0.voxels);
        let series = labels.series.as_ref().unwrap();
        assert_eq!(series.modality, "RTSTRUCT");
        assert!(is_structure_set_volume(&labels));
        assert_eq!(labels.segments[1].label, "Squares");
        assert!(
            labels
                .warnings
                .iter()
                .any(|w| w.contains("do not lie in a slice"))
        );
        assert!(labels.warnings.iter().any(|w| w.contains("beyond the CT")));
        assert!(labels.warnings.iter().any(|w| w.contains("between slices")));
    }

    /// Contours drawn on a lone slice lie midway between the two layers of the slab it is
    /// drawn as (`Volume::slab_of_lone_slices`): each is laid on both, held there as on the
    /// slice and with no contour "between slices"; a contour on a layer of a two-slice CT
    /// stays on that layer alone.
    #[test]
    fn a_lone_slices_structures_lie_through_its_slab() {
        let mut slice = grid();
        slice.dims[2] = 1;
        slice.data.truncate(40 * 30);
        slice.data[7] = 100.0;
        let ring = vec![
            circle([20.0, 15.0], 9.0, 0.0, 64),
            circle([20.0, 15.0], 4.0, 0.0, 64),
        ];
        let bar = vec![rect([1.0, 2.0], [1.0, 25.0], 0.0)];
        let path = write("lone.dcm", &slice, &[(1, "Ring", ring), (2, "Bar", bar)]);
        let set = StructureSet::read(&path).unwrap();
        let slab = slice.slab_of_lone_slices().unwrap();
        for roi in &set.rois {
            let (on_slice, notes) = set.rasterise(roi, &slice);
            assert_eq!(notes, RasterNotes::default());
            assert!(on_slice.voxels > 0, "{}", roi.name);
            let (through, notes) = set.rasterise(roi, &slab);
            assert_eq!(notes, RasterNotes::default(), "{}", roi.name);
            assert_eq!(through.voxels, 2 * on_slice.voxels, "{}", roi.name);
            for k in 0..2 {
                for j in 0..30 {
                    for i in 0..40 {
                        assert_eq!(
                            through.holds([i, j, k]),
                            on_slice.holds([i, j, 0]),
                            "{} voxel {i} {j} {k}",
                            roi.name
                        );
                    }
                }
            }
        }
        // A contour on a layer of the slab is that layer's; one midway between the slices of
        // a CT whose two slices differ is laid on its nearest, as anywhere else.
        let mut two = slab.clone();
        two.data[40 * 30 + 7] = -5.0;
        assert!(two.lone_slice_of_slab().is_none());
        let boxes = vec![
            (1, "First", vec![rect([3.0, 3.0], [9.0, 8.0], 0.0)]),
            (2, "Midway", vec![rect([3.0, 3.0], [9.0, 8.0], 0.5)]),
        ];
        let path = write("layers.dcm", &two, &boxes);
        let set = StructureSet::read(&path).unwrap();
        let (first, notes) = set.rasterise(&set.rois[0], &slab);
        assert_eq!(notes, RasterNotes::default());
        assert_eq!((first.lo[2], first.dims[2], first.voxels), (0, 1, 7 * 6));
        let (midway, notes) = set.rasterise(&set.rois[1], &two);
        assert_eq!(notes.between, 1);
        assert_eq!((midway.dims[2], midway.voxels), (1, 7 * 6));
    }

    #[test]
    fn overlapping_structures_are_each_whole() {
        let g = grid();
        let big = vec![rect([2.0, 2.0], [30.0, 20.0], 3.0)];
        let small = vec![rect([10.0, 10.0], [14.0, 14.0], 3.0)];
        let path = write("overlap.dcm", &g, &[(1, "Body", big), (2, "Organ", small)]);
        let set = StructureSet::read(&path).unwrap();
        let (regions, _) = set.regions(&g);
        assert_eq!(regions[0].voxels, 29 * 19);
        assert_eq!(regions[1].voxels, 25);
        let labels = set.label_volume(&g);
        let held = |l: f32| labels.data.iter().filter(|&&v| v == l).count();
        assert_eq!((held(1.0), held(2.0)), (29 * 19 - 25, 25));
        assert!(
            labels
                .warnings
                .iter()
                .any(|w| w.contains("25 voxels lie in more than one structure")),
            "{:?}",
            labels.warnings
        );
    }

    #[test]
    fn bad_structure_sets_are_refused() {
        let g = grid();
        let square = || vec![rect([2.0, 2.0], [5.0, 5.0], 1.0)];
        let refused = |name: &str, rois: &[(i64, &str, Vec<Contour>)], want: &str| {
            let path = write(name, &g, rois);
            let e = crate::load_volume(&path, &Default::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains(name) && e.contains(want), "{e}");
        };
        refused("none.dcm", &[], "holds no structure");
        refused(
            "twice.dcm",
            &[(2, "A", square()), (2, "B", square())],
            "two structures are numbered 2",
        );
        refused("zero.dcm", &[(0, "A", square())], "numbered 0");
        let mut nan = rect([2.0, 2.0], [5.0, 5.0], 1.0);
        nan.1[2][0] = f64::NAN;
        refused("nan.dcm", &[(1, "A", vec![nan])], "a coordinate is NaN");
        // Its CT is nowhere near it.
        refused(
            "alone.dcm",
            &[(1, "A", square())],
            "neither in its folder nor in a folder beside it",
        );
    }
}
