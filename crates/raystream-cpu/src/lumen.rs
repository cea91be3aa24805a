//! A vessel's lumen measured on cross-sections of its path, as a vascular workstation sizes an
//! aorta for a stent graft or grades a stenosis: on each plane perpendicular to the path, the
//! contrast-filled lumen is the region at or above a threshold (HU) connected to the path's
//! point, its holes filled, and opened with a small disc (a side branch or a neighbour joined by
//! a narrow neck is cut off); from it come the area, the diameter of a circle of that area, the
//! largest and smallest calliper diameters (the Feret diameters: the longest chord, and the
//! narrowest gap between two parallel lines that hold it), and the centroid and its distance
//! from the path.
//!
//! The section is sampled on a square grid of `pixel_mm` (trilinear, in the volume's own
//! orientation, as `--mode slice`); the area counts the grid's pixels (a pixel's worth of error
//! along the edge averages out), the diameters run between sub-pixel edge points where the
//! interpolated HU crosses the threshold between a lumen pixel and its neighbour. This is the
//! lumen, not the outer wall: a thrombus-lined aneurysm is wider than its lumen.

use rayon::prelude::*;
use raystream_io::Volume;
use raystream_math::{DVec2, DVec3, Vec3};

use crate::cpr::{CprRow, CurvedPlane};
use crate::dvr::Marcher;
use crate::wall::{Outline, Prior, Track, Wall, WallOptions, wall_about};

/// How the lumen is found on a section.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LumenOptions {
    /// Samples at or above this are lumen, HU (at or below it, with `dark`).
    pub threshold_hu: f32,
    /// The lumen is the samples at or below the threshold: an airway's gas, darker than its
    /// wall, rather than contrast-filled blood, brighter. Found as the bright lumen of the
    /// values negated about the negated threshold, so that every step (the seed, the flood,
    /// the edge's crossing between samples) is the same.
    pub dark: bool,
    /// The side of the square sampled about the path's point, mm: the widest lumen measured
    /// whole (a lumen that reaches its edge is reported as open).
    pub field_mm: f64,
    /// The grid's spacing, mm.
    pub pixel_mm: f64,
    /// How far from the path's point the lumen's nearest sample may lie, mm.
    pub seed_mm: f64,
    /// The radius of the disc the lumen is opened with, mm (0: not opened): parts it cannot
    /// reach from inside (side branches, a neighbour joined by a narrower neck) are cut off.
    pub open_mm: f64,
}

impl LumenOptions {
    /// Defaults for `vol`: 150 HU (contrast-filled blood, above the 30–60 HU of the vessel's
    /// wall and the unenhanced soft tissue about it), a 100 mm field (an aortic aneurysm's
    /// lumen fits), a quarter of the finest voxel spacing (at most 1024 samples across), the
    /// lumen within 5 mm, opened with a disc of 2 mm (branches under 4 mm across cut off).
    pub fn for_volume(vol: &Volume) -> LumenOptions {
        LumenOptions {
            threshold_hu: 150.0,
            dark: false,
            field_mm: 100.0,
            pixel_mm: (crate::dvr::min_spacing(vol) as f64 / 4.0).max(100.0 / 1024.0),
            seed_mm: 5.0,
            open_mm: 2.0,
        }
    }

    /// The lumen's side of the threshold, in words: "at or above" (or "at or below").
    pub fn bound_words(&self) -> &'static str {
        raystream_volume::centreline::bound_words(self.dark)
    }

    /// The grid's side in pixels.
    fn side(&self) -> usize {
        (self.field_mm / self.pixel_mm).ceil().max(1.0) as usize
    }

    pub fn check(&self) -> Result<(), String> {
        if !self.threshold_hu.is_finite() {
            return Err(format!(
                "a threshold of {} HU: it must be a number",
                self.threshold_hu
            ));
        }
        if !(self.pixel_mm.is_finite() && self.pixel_mm > 0.0) {
            return Err(format!(
                "a sample spacing of {} mm: it must be positive",
                self.pixel_mm
            ));
        }
        if !(self.field_mm.is_finite() && self.field_mm >= self.pixel_mm) {
            return Err(format!(
                "a field of {} mm: it must be at least a sample ({} mm) wide",
                self.field_mm, self.pixel_mm
            ));
        }
        if self.side() > MAX_SIDE {
            return Err(format!(
                "a field of {} mm at {} mm a sample is {} samples across; at most {MAX_SIDE}",
                self.field_mm,
                self.pixel_mm,
                self.side()
            ));
        }
        if !(self.open_mm.is_finite() && self.open_mm >= 0.0) {
            return Err(format!(
                "an opening radius of {} mm: it must be zero or more",
                self.open_mm
            ));
        }
        if !(self.seed_mm.is_finite() && self.seed_mm >= 0.0) {
            return Err(format!(
                "a seed radius of {} mm: it must be zero or more",
                self.seed_mm
            ));
        }
        Ok(())
    }
}

/// The most samples across a section's field: 2048² samples. A section is segmented on the
/// window about its lumen, but a lumen that fills the field needs all of it: about 200 MiB of
/// working grids (values, masks, three distance transforms in f64) for each section measured
/// at once, one per core.
pub const MAX_SIDE: usize = 2048;

/// The lumen found on one cross-section.
#[derive(Clone, Debug, PartialEq)]
pub struct Lumen {
    /// mm², holes included.
    pub area_mm2: f64,
    /// The diameter of a circle of the same area, mm.
    pub equivalent_diameter_mm: f64,
    /// The longest chord between two edge points, mm, and its ends (LPS mm).
    pub max_diameter_mm: f64,
    pub max_ends: [DVec3; 2],
    /// The narrowest calliper width, mm (the gap between the closest pair of parallel lines
    /// that hold the lumen between them), and the unit direction it is measured along (LPS).
    pub min_diameter_mm: f64,
    pub min_direction: DVec3,
    /// The calliper width across the largest diameter (perpendicular to it, in the section),
    /// mm: the second of the two diameters an aneurysm is reported by.
    pub cross_diameter_mm: f64,
    /// The centroid (LPS mm) and its distance from the path's point, mm.
    pub centroid: DVec3,
    pub offset_mm: f64,
    /// The lumen reaches the field's edge (it is wider than the field, or it leaks into a
    /// neighbouring bright structure): its figures are then of the part in the field.
    pub open: bool,
}

/// One station along the path.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// Arc length from the path's first point, mm.
    pub arc_mm: f64,
    /// The section's frame: the path's point, its image-right (lateral) and down (normal)
    /// directions; the plane's normal is the path's tangent.
    pub row: CprRow,
    /// The lumen, or none within `seed_mm` of the path's point.
    pub lumen: Option<Lumen>,
    /// The outer wall about it, when asked for and found.
    pub wall: Option<Wall>,
}

impl Section {
    /// The path's tangent (LPS), the section plane's normal.
    pub fn tangent(&self) -> Vec3 {
        self.row.normal.cross(self.row.lateral).normalize()
    }
}

/// The lumen on `n` cross-sections of the path through `points`, at the middle of `n` equal
/// parts of it, framed from `image_right` ([`CurvedPlane::sections`]: the planes `render
/// --path --slices N` shows); with `wall`, the outer wall too, chosen with its neighbours
/// along the path ([`Track`]).
pub fn measure_path(
    vol: &Volume,
    points: &[DVec3],
    n: u32,
    image_right: DVec3,
    opt: &LumenOptions,
    wall: Option<&WallOptions>,
) -> Result<Vec<Section>, String> {
    let track = match wall {
        Some(w) => Some(Track::along(vol, &Marcher::new(vol, None), points, opt, w)?),
        None => None,
    };
    measure_along(vol, points, (n, image_right), opt, wall.zip(track.as_ref()))
}

/// [`measure_path`] with the track along the path already found (for the same path, `opt`
/// and wall options), as `measure --mask` shares it.
pub fn measure_along(
    vol: &Volume,
    points: &[DVec3],
    (n, image_right): (u32, DVec3),
    opt: &LumenOptions,
    wall: Option<(&WallOptions, &Track)>,
) -> Result<Vec<Section>, String> {
    let plane = CurvedPlane::sections(points, image_right, 0.0, n)?;
    let m = Marcher::new(vol, None);
    let step = plane.length_mm / n as f64;
    let (wall, track) = (wall.map(|w| w.0), wall.map(|w| w.1));
    Ok(plane
        .rows
        .into_par_iter()
        .enumerate()
        .map(|(i, row)| {
            let arc_mm = (i as f64 + 0.5) * step;
            let prior = track.and_then(|t| t.prior(arc_mm, &row));
            let (lumen, wall) = match measure_with_wall(vol, &m, &row, opt, wall, prior.as_ref()) {
                Some(f) => (Some(f.lumen), f.wall.map(|(w, _)| w)),
                None => (None, None),
            };
            Section {
                arc_mm,
                row,
                lumen,
                wall,
            }
        })
        .collect())
}

/// What [`measure_with_wall`] finds on a section: the lumen, its edge points, and the outer
/// wall with its outline (when asked for and found), in the section's own coordinates (mm
/// from the path's point, right and down).
pub struct Found {
    pub lumen: Lumen,
    pub edge: Vec<DVec2>,
    pub wall: Option<(Wall, Outline)>,
}

/// [`measure_section`], and with `wall`, the outer wall about the lumen ([`crate::wall`]),
/// with what its neighbours along the path agree on where known ([`Track::prior`]).
pub fn measure_with_wall(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
    wall: Option<&WallOptions>,
    prior: Option<&Prior>,
) -> Option<Found> {
    let g = segment(vol, m, row, opt)?;
    let (lumen, edge) = measure_segmented(&g, row);
    let wall = wall.and_then(|w| wall_about(vol, m, row, opt, (w, prior), &g, (&lumen, &edge)));
    Some(Found { lumen, edge, wall })
}

/// A rectangle of a section's `n`×`n` grid: columns `i0..i0 + w`, rows `j0..j0 + h`. The
/// lumen is segmented on the smallest one that holds it with a sample to spare on each side
/// (or that reaches the grid's edge), not on the whole field: a 25 mm aorta in the 100 mm field
/// takes a tenth of its samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Window {
    i0: usize,
    j0: usize,
    w: usize,
    h: usize,
}

impl Window {
    fn dims(&self) -> [usize; 2] {
        [self.w, self.h]
    }

    fn len(&self) -> usize {
        self.w * self.h
    }

    /// The grid pixel (i, j) of the window's pixel `k` (row by row).
    fn pixel(&self, k: usize) -> (usize, usize) {
        (self.i0 + k % self.w, self.j0 + k / self.w)
    }

    /// The window's index of grid pixel (i, j), if it lies in the window.
    fn index(&self, i: usize, j: usize) -> Option<usize> {
        let inside =
            (self.i0..self.i0 + self.w).contains(&i) && (self.j0..self.j0 + self.h).contains(&j);
        inside.then(|| (j - self.j0) * self.w + (i - self.i0))
    }
}

/// A section's samples and the lumen segmented on them: on a window of an `n`×`n` grid of
/// `p` mm about the path's point (grid pixel (i, j) at [`Segmented::offset`]), its HU (NaN
/// outside the volume) and the lumen's pixels, row by row; the lumen lies within the window
/// and every grid pixel beside it too.
pub(crate) struct Segmented {
    n: usize,
    p: f64,
    win: Window,
    values: Vec<f32>,
    mask: Vec<bool>,
    threshold: f32,
}

/// Pixel (i, j)'s offset from the path's point on an `n`×`n` grid of `p` mm, mm, right
/// (lateral) and down (normal).
fn grid_offset(n: usize, p: f64, i: usize, j: usize) -> DVec2 {
    let half = 0.5 * n as f64;
    DVec2::new((i as f64 + 0.5 - half) * p, (j as f64 + 0.5 - half) * p)
}

impl Segmented {
    /// The lumen alone, its samples dropped (to be kept for many sections at once).
    pub(crate) fn without_values(self) -> Segmented {
        Segmented {
            values: Vec::new(),
            ..self
        }
    }

    /// Whether the grid pixel that holds the offset `q` from the path's point (mm) is lumen.
    pub(crate) fn lumen_at(&self, q: DVec2) -> bool {
        let half = 0.5 * self.n as f64;
        let (i, j) = ((q.x / self.p + half).floor(), (q.y / self.p + half).floor());
        i >= 0.0
            && j >= 0.0
            && self
                .win
                .index(i as usize, j as usize)
                .is_some_and(|k| self.mask[k])
    }

    /// Grid pixel (i, j)'s offset from the path's point, mm.
    fn offset(&self, i: usize, j: usize) -> DVec2 {
        grid_offset(self.n, self.p, i, j)
    }

    /// The window's index of grid pixel (i, j), which lies beside the lumen or in it.
    fn near(&self, i: usize, j: usize) -> usize {
        self.win
            .index(i, j)
            .expect("the window holds the lumen and the pixels beside it")
    }

    /// Where the lumen's edge lies between lumen pixel `k` and its neighbour `o` outside it
    /// (window indices), as a fraction of the way from `k`: where the HU falls through the
    /// threshold; where the region was cut (the neighbour is lumen, off beyond a neck) or
    /// leaves the volume, halfway.
    fn crossing(&self, k: usize, o: usize) -> f64 {
        let (vi, vo, t) = (self.values[k], self.values[o], self.threshold);
        if vi.is_finite() && vo.is_finite() && vi >= t && vo < t {
            ((vi - t) / (vi - vo)).clamp(0.0, 1.0) as f64
        } else {
            0.5
        }
    }
}

/// The HU of the plane of `row` at an offset `q` from the path's point (mm, right and down:
/// along `row.lateral` and `row.normal`), trilinear as `--mode slice` samples it; NaN outside
/// the volume.
pub(crate) fn sampler<'a>(
    vol: &Volume,
    m: &'a Marcher,
    row: &CprRow,
) -> impl Fn(DVec2) -> f32 + 'a {
    let (row, last) = (*row, vol.dims.map(|k| k.max(1) as f32 - 1.0));
    move |q: DVec2| {
        let i = m.index_of(row.point(q).as_vec3());
        let inside = (0..3).all(|a| (-1e-3..=last[a] + 1e-3).contains(&i[a]));
        if inside { m.sample(i) } else { f32::NAN }
    }
}

/// Where a section is segmented.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fit {
    /// On the window about the lumen, sampling only what the seed's search, the region's
    /// flood and that window need (what `measure` and `render` use).
    Lumen,
    /// On the whole field, every sample taken first: the simple way, which the tests hold
    /// [`Fit::Lumen`] to, pixel for pixel.
    Field,
}

/// Samples the plane of `row` and segments the lumen on it: the pixels at or above the
/// threshold 4-connected to the one nearest the path's point within `seed_mm`, holes filled,
/// opened; none when no lumen pixel lies that near.
pub(crate) fn segment(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
) -> Option<Segmented> {
    segment_on(vol, m, row, opt, Fit::Lumen)
}

/// [`segment`], on the window `fit` says.
///
/// Why a window gives the field's lumen exactly: its pixels are the field's (the same grid
/// points), the seed's search covers every pixel within `seed_mm`, and the flood ends where it
/// ends on the field. The window is the region's bounds grown by a pixel, so the pixels on its
/// border that are not on the field's are outside the region and joined, outside it, to the
/// field's border: the holes filled on the window are the field's. The opening's distances
/// are too: from a pixel of the window, the nearest pixel outside the filled region is never
/// beyond the window (moving one beyond it onto the window's border only brings it closer,
/// and that border pixel is outside the region), and its other distances are to pixels of the
/// region. Every tie is broken by the pixels' order row by row, which the window keeps.
fn segment_on(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
    fit: Fit,
) -> Option<Segmented> {
    let (n, p) = (opt.side(), opt.pixel_mm);
    let offset = |k: usize| grid_offset(n, p, k % n, k / n);
    let at = sampler(vol, m, row);
    // A dark lumen: the bright lumen of the values negated (`LumenOptions::dark`).
    let sign = if opt.dark { -1.0 } else { 1.0 };
    let sample = |k: usize| sign * at(offset(k));
    // The grid's samples, each taken when first needed.
    let mut values = vec![0f32; n * n];
    let mut taken = vec![false; n * n];
    let mut value = |k: usize| {
        if !taken[k] {
            values[k] = sample(k);
            taken[k] = true;
        }
        values[k]
    };
    let threshold = sign * opt.threshold_hu;
    // The seed: the lumen pixel nearest the path's point, within seed_mm (with Fit::Lumen
    // only the square about the grid's middle that holds that disc is searched).
    let reach = opt.seed_mm.max(0.5 * p * std::f64::consts::SQRT_2);
    let (lo, hi) = match fit {
        Fit::Field => (0, n - 1),
        Fit::Lumen => {
            let middle = 0.5 * n as f64 - 0.5;
            let lo = (middle - reach / p).floor() - 1.0;
            let hi = (middle + reach / p).ceil() + 1.0;
            (lo.max(0.0) as usize, (hi.max(0.0) as usize).min(n - 1))
        }
    };
    let seed = (lo..=hi)
        .flat_map(|j| (lo..=hi).map(move |i| j * n + i))
        .map(|k| (offset(k).length(), k))
        .filter(|&(r, k)| r <= reach && value(k) >= threshold)
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))?
        .1;
    if fit == Fit::Field {
        for k in 0..n * n {
            value(k);
        }
    }
    // The region: 4-connected lumen pixels from the seed.
    let mut region = vec![false; n * n];
    let reached = flood([n, n], seed, &mut region, |k| value(k) >= threshold, false);
    let win = match fit {
        Fit::Field => Window {
            i0: 0,
            j0: 0,
            w: n,
            h: n,
        },
        Fit::Lumen => {
            let (mut i0, mut j0, mut i1, mut j1) = (n, n, 0, 0);
            for &k in &reached {
                let (i, j) = (k % n, k / n);
                (i0, i1, j0, j1) = (i0.min(i), i1.max(i), j0.min(j), j1.max(j));
            }
            let (i0, j0) = (i0.saturating_sub(1), j0.saturating_sub(1));
            let (i1, j1) = ((i1 + 1).min(n - 1), (j1 + 1).min(n - 1));
            Window {
                i0,
                j0,
                w: i1 + 1 - i0,
                h: j1 + 1 - j0,
            }
        }
    };
    let at = |k: usize| {
        let (i, j) = win.pixel(k);
        j * n + i
    };
    let values: Vec<f32> = (0..win.len()).map(|k| value(at(k))).collect();
    let region: Vec<bool> = (0..win.len()).map(|k| region[at(k)]).collect();
    let seed = win
        .index(seed % n, seed / n)
        .expect("the seed is in the region");
    // Its holes filled, and opened: the parts a disc of `open_mm` cannot reach from the seed's
    // side of the lumen are cut off where they run on beyond the disc's reach (a side branch,
    // a neighbour joined by a neck narrower than the disc); a tip or corner too sharp for the
    // disc stays.
    let mut mask = fill_holes(win.dims(), &region);
    let r = opt.open_mm / p;
    if r > 0.0 {
        mask = opened(win.dims(), &mask, r, seed);
    }
    Some(Segmented {
        n,
        p,
        win,
        values,
        mask,
        threshold,
    })
}

/// The lumen on the plane through `row.centre` spanned by `row.lateral` and `row.normal`, and
/// its edge points in the section's own coordinates (mm from the path's point along the
/// lateral direction and the normal: as the cross-section's image has them, right and down).
pub fn measure_section(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
) -> Option<(Lumen, Vec<DVec2>)> {
    measure_with_wall(vol, m, row, opt, None, None).map(|f| (f.lumen, f.edge))
}

/// [`measure_section`]'s figures of a segmented section.
pub(crate) fn measure_segmented(g: &Segmented, row: &CprRow) -> (Lumen, Vec<DVec2>) {
    let (n, p) = (g.n, g.p);
    let mut count = 0usize;
    let mut sum = DVec2::ZERO;
    let mut open = false;
    let mut edge = Vec::new();
    for k in 0..g.win.len() {
        if !g.mask[k] {
            continue;
        }
        let (i, j) = g.win.pixel(k);
        count += 1;
        let q = g.offset(i, j);
        sum += q;
        open |= i == 0 || j == 0 || i == n - 1 || j == n - 1;
        // Edge points: where the lumen ends towards each neighbour outside it.
        for (di, dj) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
            let (a, b) = (i as i64 + di, j as i64 + dj);
            if a < 0 || b < 0 || a >= n as i64 || b >= n as i64 {
                continue;
            }
            let (a, b) = (a as usize, b as usize);
            let o = g.near(a, b);
            if g.mask[o] {
                continue;
            }
            let t = g.crossing(k, o);
            edge.push(q + t * (g.offset(a, b) - q));
        }
    }
    let area = count as f64 * p * p;
    let centre = sum / count as f64;
    let k = Callipers::of(&edge);
    let lumen = Lumen {
        area_mm2: area,
        equivalent_diameter_mm: equivalent_diameter(area),
        max_diameter_mm: k.max_mm,
        max_ends: k.max_ends.map(|q| row.point(q)),
        min_diameter_mm: k.min_mm,
        min_direction: row.direction(k.min_across).normalize_or_zero(),
        cross_diameter_mm: k.cross_mm,
        centroid: row.point(centre),
        offset_mm: centre.length(),
        open,
    };
    (lumen, edge)
}

/// The diameter of a circle of `area_mm2`, mm.
pub fn equivalent_diameter(area_mm2: f64) -> f64 {
    2.0 * (area_mm2 / std::f64::consts::PI).sqrt()
}

/// The calliper (Feret) figures of a set of points on a section (mm, in its own coordinates).
pub(crate) struct Callipers {
    /// The longest chord, and its ends.
    pub max_mm: f64,
    pub max_ends: [DVec2; 2],
    /// The narrowest width, and the unit direction across it.
    pub min_mm: f64,
    pub min_across: DVec2,
    /// The width across the longest chord.
    pub cross_mm: f64,
}

impl Callipers {
    pub fn of(pts: &[DVec2]) -> Callipers {
        let hull = convex_hull(pts);
        let (max_mm, max_ends) = max_chord(&hull);
        let (min_mm, min_across) = min_width(&hull);
        let perp = (max_ends[1] - max_ends[0]).normalize_or_zero().perp();
        let (lo, hi) = hull
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| {
                let t = q.dot(perp);
                (lo.min(t), hi.max(t))
            });
        Callipers {
            max_mm,
            max_ends,
            min_mm,
            min_across,
            cross_mm: if hull.is_empty() { 0.0 } else { hi - lo },
        }
    }
}

/// Where the lumen that [`measure_section`] finds on `row`'s plane meets the line through
/// `row.centre` along `row.lateral`: its two edges on that line, mm along it from the path's
/// point (left negative), the lumen's run along the line through the pixel nearest the point
/// (or, where the point is not lumen, the lumen pixel nearest it on the line). The line is the
/// grid's middle row (with an even number of rows, the one half a sample below it). None
/// where no lumen is found, or none lies on the line.
pub fn lumen_across(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
) -> Option<[f64; 2]> {
    across_with_wall(vol, m, row, opt, None, None)[0]
}

/// [`lumen_across`], and with `wall`, where the outer wall's outline meets the line through
/// `row.centre` along `row.lateral` ([`Outline::across`]), with what its neighbours along the
/// path agree on where known: the lumen segmented once for both.
pub fn across_with_wall(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
    wall: Option<&WallOptions>,
    prior: Option<&Prior>,
) -> [Option<[f64; 2]>; 2] {
    let Some(g) = segment(vol, m, row, opt) else {
        return [None, None];
    };
    let outer = wall.and_then(|w| {
        let (lumen, edge) = measure_segmented(&g, row);
        wall_about(vol, m, row, opt, (w, prior), &g, (&lumen, &edge))?
            .1
            .across()
    });
    [across_segmented(&g), outer]
}

/// [`lumen_across`] on a segmented section.
fn across_segmented(g: &Segmented) -> Option<[f64; 2]> {
    let n = g.n;
    // The middle row, and the column nearest the path's point.
    let j = n / 2;
    let on_line = |i: usize| g.win.index(i, j).is_some_and(|k| g.mask[k]);
    let start = (g.win.i0..g.win.i0 + g.win.w)
        .filter(|&i| on_line(i))
        .min_by_key(|&i| (i.abs_diff(j), i))?;
    let (mut lo, mut hi) = (start, start);
    while lo > 0 && on_line(lo - 1) {
        lo -= 1;
    }
    while hi + 1 < n && on_line(hi + 1) {
        hi += 1;
    }
    // Each end: the crossing towards the neighbour beyond it, or the grid's edge.
    let end = |i: usize, beyond: Option<usize>| {
        let q = g.offset(i, j).x;
        match beyond {
            Some(o) => q + g.crossing(g.near(i, j), g.near(o, j)) * (g.offset(o, j).x - q),
            None => q + (if i == 0 { -0.5 } else { 0.5 }) * g.p,
        }
    };
    Some([
        end(lo, lo.checked_sub(1)),
        end(hi, (hi + 1 < n).then_some(hi + 1)),
    ])
}

/// Marks in `mark` the pixels of a grid of `dims` (row by row) reached from `seed` through
/// pixels that are `passable` (4-connected, or 8-connected with `diagonal`), and returns them.
/// A stack, not recursion.
fn flood(
    dims: [usize; 2],
    seed: usize,
    mark: &mut [bool],
    mut passable: impl FnMut(usize) -> bool,
    diagonal: bool,
) -> Vec<usize> {
    let [w, h] = dims;
    let steps: &[(i64, i64)] = if diagonal {
        &[
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ]
    } else {
        &[(1, 0), (-1, 0), (0, 1), (0, -1)]
    };
    mark[seed] = true;
    let mut reached = vec![seed];
    let mut stack = vec![seed];
    while let Some(k) = stack.pop() {
        let (i, j) = ((k % w) as i64, (k / w) as i64);
        for &(di, dj) in steps {
            let (a, b) = (i + di, j + dj);
            if a < 0 || b < 0 || a >= w as i64 || b >= h as i64 {
                continue;
            }
            let q = b as usize * w + a as usize;
            if !mark[q] && passable(q) {
                mark[q] = true;
                reached.push(q);
                stack.push(q);
            }
        }
    }
    reached
}

/// `mask` (a grid of `dims`, row by row) opened about `seed` with a disc of radius `r`
/// pixels: its core (the pixels deeper than `r` inside it) has parts; the one nearest the
/// seed, grown back by `r` and a pixel, is the body. What is left of `mask` is cut off where a
/// part of it reaches further than `r` from the body, and kept where it does not (a tip too
/// sharp for the disc). A mask with no core (narrower than the disc everywhere) comes back as
/// it is.
fn opened(dims: [usize; 2], mask: &[bool], r: f64, seed: usize) -> Vec<bool> {
    let (w, len) = (dims[0], mask.len());
    let depth = distance_to(dims, |k| !mask[k]);
    let core: Vec<bool> = depth.iter().map(|&d2| d2 > r * r).collect();
    let (si, sj) = ((seed % w) as f64, (seed / w) as f64);
    let gap = |k: usize| ((k % w) as f64 - si).powi(2) + ((k / w) as f64 - sj).powi(2);
    let Some(start) = (0..len)
        .filter(|&k| core[k])
        .min_by(|&a, &b| gap(a).total_cmp(&gap(b)).then(a.cmp(&b)))
    else {
        return mask.to_vec();
    };
    let mut part = vec![false; len];
    flood(dims, start, &mut part, |k| core[k], true);
    let reach = distance_to(dims, |k| part[k]);
    let grown = (r + 1.0) * (r + 1.0);
    let body: Vec<bool> = (0..len).map(|k| mask[k] && reach[k] <= grown).collect();
    let beyond = distance_to(dims, |k| body[k]);
    let mut out = body.clone();
    let mut seen = vec![false; len];
    for k in 0..len {
        if mask[k] && !body[k] && !seen[k] {
            let piece = flood(dims, k, &mut seen, |q| mask[q] && !body[q], false);
            let far = piece.iter().map(|&q| beyond[q]).fold(0.0, f64::max);
            for q in piece {
                out[q] = far <= r * r;
            }
        }
    }
    fill_holes(dims, &out)
}

/// `region` (a grid of `dims`, row by row) with its holes filled: all but what the outside
/// reaches from the grid's border (8-connected, as the complement of a 4-connected region is).
fn fill_holes(dims: [usize; 2], region: &[bool]) -> Vec<bool> {
    let [w, h] = dims;
    let mut outside = vec![false; region.len()];
    for k in 0..region.len() {
        let (i, j) = (k % w, k / w);
        if (i == 0 || j == 0 || i == w - 1 || j == h - 1) && !region[k] && !outside[k] {
            flood(dims, k, &mut outside, |q| !region[q], true);
        }
    }
    outside.iter().map(|&o| !o).collect()
}

/// Per pixel of a grid of `dims` (row by row), the squared distance (pixels²) to the nearest
/// pixel that is `target` (+∞ where there is none).
fn distance_to(dims: [usize; 2], target: impl Fn(usize) -> bool + Sync) -> Vec<f64> {
    raystream_volume::distance::squared_distance(dims, [1.0, 1.0], target)
}

/// The convex hull of `pts`, counter-clockwise, without collinear points (Andrew's monotone
/// chain). Written here: a few lines, and no crate for 2-D hulls is worth the dependency.
pub fn convex_hull(pts: &[DVec2]) -> Vec<DVec2> {
    let mut p: Vec<DVec2> = pts.to_vec();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The longest chord between two of `hull`'s points, and its ends (every pair: hulls of a
/// lumen's edge hold hundreds of points, not millions).
fn max_chord(hull: &[DVec2]) -> (f64, [DVec2; 2]) {
    let mut best = (0.0, [hull.first().copied().unwrap_or_default(); 2]);
    for (a, &p) in hull.iter().enumerate() {
        for &q in &hull[a + 1..] {
            let d = p.distance(q);
            if d > best.0 {
                best = (d, [p, q]);
            }
        }
    }
    best
}

/// The convex polygon `hull`'s narrowest width and the unit direction across it: the
/// narrowest pair of parallel supporting lines has one of them along an edge of the hull, so
/// each edge's farthest point gives a candidate (every edge against every point).
fn min_width(hull: &[DVec2]) -> (f64, DVec2) {
    if hull.len() < 3 {
        let along = if hull.len() == 2 {
            (hull[1] - hull[0]).normalize_or_zero()
        } else {
            DVec2::X
        };
        return (0.0, along.perp());
    }
    let mut best = (f64::INFINITY, DVec2::X);
    for (a, &p) in hull.iter().enumerate() {
        let q = hull[(a + 1) % hull.len()];
        let Some(u) = (q - p).try_normalize() else {
            continue;
        };
        let across = u.perp();
        let w = hull
            .iter()
            .map(|&r| (r - p).dot(across).abs())
            .fold(0.0, f64::max);
        if w < best.0 {
            best = (w, across);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CT on a grid of `h` mm (LPS = index·h) 64 mm square and `nz` voxels deep whose HU
    /// fall linearly across the surface `f = 0` of `f` (mm, positive inside): 500 HU a mm,
    /// from −1000 to 1000, so that the 0 HU crossing lies on the surface within trilinear
    /// error.
    fn phantom_at(h: f64, nz: usize, f: impl Fn(DVec3) -> f64 + Sync) -> Volume {
        let n = (64.0 / h).round() as usize;
        let dims = [n, n, nz];
        let data: Vec<f32> = (0..dims.iter().product::<usize>())
            .into_par_iter()
            .map(|k| {
                let p = DVec3::new((k % n) as f64, (k / n % n) as f64, (k / (n * n)) as f64);
                (500.0 * f(p * h)).clamp(-1000.0, 1000.0) as f32
            })
            .collect();
        Volume::hounsfield(dims, [h; 3], data)
    }

    /// [`phantom_at`] on a 1 mm grid.
    fn phantom(nz: usize, f: impl Fn(DVec3) -> f64 + Sync) -> Volume {
        phantom_at(1.0, nz, f)
    }

    fn opt(vol: &Volume) -> LumenOptions {
        LumenOptions {
            threshold_hu: 0.0,
            field_mm: 60.0,
            ..LumenOptions::for_volume(vol)
        }
    }

    #[test]
    fn a_round_tube_measures_its_radius() {
        // A tube of radius 7.3 mm along z through (31.6, 32.2): every section's area is
        // π r², its diameters 2r, its centroid on the axis.
        let (r, axis) = (7.3, DVec2::new(31.6, 32.2));
        let vol = phantom(24, |p| r - (p.truncate() - axis).length());
        let path = [DVec3::new(31.0, 33.0, 2.0), DVec3::new(31.0, 33.0, 21.0)];
        let sections = measure_path(&vol, &path, 5, DVec3::X, &opt(&vol), None).unwrap();
        assert_eq!(sections.len(), 5);
        for s in &sections {
            let l = s.lumen.as_ref().expect("the tube");
            let area = std::f64::consts::PI * r * r;
            assert!(
                (l.area_mm2 - area).abs() < 0.01 * area,
                "{} mm² for {area}",
                l.area_mm2
            );
            assert!((l.equivalent_diameter_mm - 2.0 * r).abs() < 0.05, "{l:?}");
            assert!(
                (l.max_diameter_mm - 2.0 * r).abs() < 0.05,
                "{}",
                l.max_diameter_mm
            );
            assert!(
                (l.min_diameter_mm - 2.0 * r).abs() < 0.08,
                "{}",
                l.min_diameter_mm
            );
            assert!(
                (l.centroid.truncate() - axis).length() < 0.02,
                "{}",
                l.centroid
            );
            assert!((l.offset_mm - (axis - DVec2::new(31.0, 33.0)).length()).abs() < 0.02);
            assert!(!l.open);
            // Every edge point on the circle.
            let m = Marcher::new(&vol, None);
            let (again, edge) = measure_section(&vol, &m, &s.row, &opt(&vol)).unwrap();
            assert_eq!(&again, l);
            for &q in &edge {
                let w = s.row.point(q);
                assert!(((w.truncate() - axis).length() - r).abs() < 0.03, "{w}");
            }
        }
    }

    /// `lumen_across` on a round tube: the chord of the circle along the row's lateral line
    /// (the grid's middle row, half a sample off the path's point when the grid's side is
    /// even), within 0.03 mm, from a path on the axis, off it, and outside the tube within the
    /// seed radius (the run is then the lumen's on the line, wholly to one side); none when
    /// the line misses the tube.
    /// A dark lumen (`dark`: an airway's gas in its wall) measures as its bright mirror does:
    /// a tube of radius 7.3 mm and a side branch cut off by the opening, its values negated,
    /// at the negated threshold, gives every section's lumen bit for bit (area, diameters,
    /// centroid, outline); read as bright at that threshold, it is another lumen.
    #[test]
    fn a_dark_lumen_measures_as_its_bright_mirror() {
        let (r, axis) = (7.3, DVec2::new(31.6, 32.2));
        let f = |p: DVec3| {
            let tube = r - (p.truncate() - axis).length();
            let branch = 1.2 - ((p.y - 32.2).powi(2) + (p.z - 12.0).powi(2)).sqrt();
            tube.max(if p.x > axis.x { branch } else { -10.0 })
        };
        let bright = phantom(24, f);
        let dark = phantom(24, |p| -f(p));
        let path = [DVec3::new(31.0, 33.0, 2.0), DVec3::new(31.0, 33.0, 21.0)];
        let o = LumenOptions {
            threshold_hu: 30.0,
            ..opt(&bright)
        };
        let want = measure_path(&bright, &path, 7, DVec3::X, &o, None).unwrap();
        let mirrored = LumenOptions {
            threshold_hu: -30.0,
            dark: true,
            ..o
        };
        let got = measure_path(&dark, &path, 7, DVec3::X, &mirrored, None).unwrap();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert!(w.lumen.is_some(), "the tube");
            assert_eq!(format!("{:?}", g.lumen), format!("{:?}", w.lumen));
        }
        let other = measure_path(
            &dark,
            &path,
            7,
            DVec3::X,
            &LumenOptions {
                dark: false,
                ..mirrored
            },
            None,
        )
        .unwrap();
        assert_ne!(
            format!("{:?}", other[3].lumen),
            format!("{:?}", want[3].lumen)
        );
    }

    #[test]
    fn the_lumen_across_a_row_is_the_chord_of_the_tube() {
        let (r, axis) = (7.3, DVec2::new(31.6, 32.2));
        let vol = phantom(24, |p| r - (p.truncate() - axis).length());
        let m = Marcher::new(&vol, None);
        let o = opt(&vol);
        let n = (o.field_mm / o.pixel_mm).ceil() as usize;
        let v0 = if n.is_multiple_of(2) {
            0.5 * o.pixel_mm
        } else {
            0.0
        };
        for (x, y) in [(31.6, 32.2), (33.0, 36.0), (40.9, 32.5)] {
            let path = [DVec3::new(x, y, 2.0), DVec3::new(x, y, 21.0)];
            let row = measure_path(&vol, &path, 1, DVec3::X, &o, None).unwrap()[0].row;
            let (c, l, d) = (
                row.centre.as_dvec3().truncate(),
                row.lateral.as_dvec3().truncate(),
                row.normal.as_dvec3().truncate(),
            );
            // |c + u l + v0 d − axis| = r, l a unit vector: u = −b ± √(b² − k).
            let q = c + v0 * d - axis;
            let (b, k) = (q.dot(l), q.length_squared() - r * r);
            let root = (b * b - k).sqrt();
            let got = lumen_across(&vol, &m, &row, &o).expect("the tube on the line");
            for (g, want) in got.iter().zip([-b - root, -b + root]) {
                assert!((g - want).abs() < 0.03, "{got:?} for {want} at ({x}, {y})");
            }
        }
        // 4 mm above the tube (the line along x misses it), its wall within the seed radius.
        let path = [
            DVec3::new(31.6, 32.2 - r - 4.0, 2.0),
            DVec3::new(31.6, 32.2 - r - 4.0, 21.0),
        ];
        let row = measure_path(&vol, &path, 1, DVec3::X, &o, None).unwrap()[0].row;
        assert!(measure_section(&vol, &m, &row, &o).is_some());
        assert_eq!(lumen_across(&vol, &m, &row, &o), None);
    }

    #[test]
    fn an_elliptic_lumen_has_its_axes_as_feret_diameters() {
        // Semi-axes 9 and 4 mm, the long one at 30° to x: max 18, min 8, area π·36. On a
        // half-millimetre grid: at its tips the edge bends with a radius of 1.8 mm, and on a
        // 1 mm grid trilinear interpolation would draw each tip in by 0.07 mm.
        let (a, b) = (9.0, 4.0);
        let (s, c) = 30f64.to_radians().sin_cos();
        let centre = DVec2::new(32.0, 32.0);
        let vol = phantom_at(0.5, 24, |p| {
            let q = p.truncate() - centre;
            let (u, v) = (q.x * c + q.y * s, -q.x * s + q.y * c);
            // Scaled so that its gradient is about 1 mm⁻¹ at the surface.
            4.0 * (1.0 - ((u / a).powi(2) + (v / b).powi(2)).sqrt())
        });
        let path = [DVec3::new(32.0, 32.0, 1.0), DVec3::new(32.0, 32.0, 10.0)];
        let sections = measure_path(&vol, &path, 1, DVec3::X, &opt(&vol), None).unwrap();
        let l = sections[0].lumen.as_ref().unwrap();
        assert!(
            (l.max_diameter_mm - 2.0 * a).abs() < 0.1,
            "{}",
            l.max_diameter_mm
        );
        assert!(
            (l.min_diameter_mm - 2.0 * b).abs() < 0.1,
            "{}",
            l.min_diameter_mm
        );
        let area = std::f64::consts::PI * a * b;
        assert!((l.area_mm2 - area).abs() < 0.01 * area, "{}", l.area_mm2);
        // The long chord along the long axis, the narrow width across it.
        let long = (l.max_ends[1] - l.max_ends[0]).truncate().normalize();
        assert!(long.dot(DVec2::new(c, s)).abs() > 0.999, "{long}");
        assert!(l.min_direction.truncate().dot(DVec2::new(-s, c)).abs() > 0.999);
    }

    #[test]
    fn holes_are_filled_and_a_lumen_beyond_the_seed_radius_is_missed() {
        // A ring (a tube with a dark core of radius 2 inside radius 6): the area is the
        // disc's; a path 12 mm from it finds no lumen within 5 mm.
        let centre = DVec2::new(30.0, 30.0);
        let vol = phantom(8, |p| {
            let d = (p.truncate() - centre).length();
            (6.0 - d).min(d - 2.0)
        });
        let o = LumenOptions {
            seed_mm: 5.0,
            ..opt(&vol)
        };
        let at = |x: f64| {
            let path = [DVec3::new(x, 30.0, 1.0), DVec3::new(x, 30.0, 6.0)];
            measure_path(&vol, &path, 1, DVec3::X, &o, None)
                .unwrap()
                .remove(0)
        };
        // The path through the dark core: the ring is found 2 mm away, its hole filled.
        let l = at(30.0).lumen.expect("the ring about the path");
        let disc = std::f64::consts::PI * 36.0;
        assert!((l.area_mm2 - disc).abs() < 0.01 * disc, "{}", l.area_mm2);
        assert!(l.offset_mm < 0.02);
        assert!(at(42.0).lumen.is_none());
    }

    #[test]
    fn a_lumen_wider_than_the_field_is_open() {
        let vol = phantom(8, |p| 25.0 - (p.truncate() - DVec2::splat(32.0)).length());
        let o = LumenOptions {
            field_mm: 30.0,
            ..opt(&vol)
        };
        let path = [DVec3::new(32.0, 32.0, 1.0), DVec3::new(32.0, 32.0, 6.0)];
        let s = measure_path(&vol, &path, 1, DVec3::X, &o, None).unwrap();
        let l = s[0].lumen.as_ref().unwrap();
        assert!(l.open);
        // All of the field, which the lumen fills.
        assert!((l.area_mm2 - 900.0).abs() < 1.0, "{}", l.area_mm2);
    }

    #[test]
    fn sections_are_the_rows_of_a_curved_plane_as_high_as_they_are_many() {
        // measure's sections are the planes `render --path --slices N` shows.
        let pts: Vec<DVec3> = (0..=6)
            .map(|i| {
                let a = (i as f64 * 15.0).to_radians();
                DVec3::new(10.0 + 30.0 * a.cos(), 32.0, 10.0 + 30.0 * a.sin())
            })
            .collect();
        let vol = phantom(8, |_| -1.0);
        let s = measure_path(&vol, &pts, 7, DVec3::X, &opt(&vol), None).unwrap();
        let c = CurvedPlane::sections(&pts, DVec3::X, 0.0, 7).unwrap();
        assert_eq!(s.len(), 7);
        for (a, b) in s.iter().zip(&c.rows) {
            assert_eq!(a.row, *b);
            assert!(a.lumen.is_none());
        }
    }

    #[test]
    fn a_side_branch_is_cut_off_by_the_opening() {
        // A tube of radius 8 mm along z with a branch 2.4 mm across leaving it along +x to the
        // field's edge: opened, the lumen is the tube's (16 mm across, closed); not opened, the
        // branch joins it and runs out of the field.
        let c = DVec2::new(28.0, 32.0);
        let vol = phantom_at(0.5, 16, |p| {
            let q = p.truncate() - c;
            let tube = 8.0 - q.length();
            let branch = if q.x > 0.0 { 1.2 - q.y.abs() } else { -10.0 };
            tube.max(branch)
        });
        let path = [DVec3::new(c.x, c.y, 1.0), DVec3::new(c.x, c.y, 6.0)];
        let at = |open_mm| {
            let o = LumenOptions {
                open_mm,
                ..opt(&vol)
            };
            measure_path(&vol, &path, 1, DVec3::X, &o, None)
                .unwrap()
                .remove(0)
                .lumen
                .unwrap()
        };
        let opened = at(2.0);
        assert!(!opened.open);
        // Across the branch the tube's 16 mm; along it a little more, the branch's root
        // (where the two meet, the lumen is deeper than the disc a little further out).
        assert!(
            (opened.min_diameter_mm - 16.0).abs() < 0.1,
            "{}",
            opened.min_diameter_mm
        );
        assert!(
            (16.0..16.8).contains(&opened.max_diameter_mm),
            "{}",
            opened.max_diameter_mm
        );
        let disc = std::f64::consts::PI * 64.0;
        // The branch's stub within the disc's reach of the tube stays: a sliver.
        assert!(
            (opened.area_mm2 - disc).abs() < 0.02 * disc,
            "{}",
            opened.area_mm2
        );
        let raw = at(0.0);
        assert!(raw.open && raw.max_diameter_mm > 30.0, "{raw:?}");
    }

    #[test]
    fn a_stenosis_in_a_tapering_tube_is_graded_against_its_taper() {
        // A tube along z whose radius tapers from 6 mm at z = 0 to 4 mm at z = 60, narrowed
        // about z = 31.5 (a raised cosine 8 mm either side) to half its width: measured a
        // section every mm and graded with a fitted reference, it is 50 % by diameter and
        // 75 % by area against the taper's 9.9 mm there, narrowed below 90 % of it over
        // 2·8·acos(−0.6)/π = 11.3 mm.
        use crate::stenosis::{StenosisOptions, grade};
        use std::f64::consts::PI;
        let axis = DVec2::new(32.0, 31.5);
        let taper = |z: f64| 6.0 - z / 30.0;
        let radius = |z: f64| {
            let u = (z - 31.5) / 8.0;
            let k = if u.abs() < 1.0 {
                1.0 - 0.25 * (1.0 + (PI * u).cos())
            } else {
                1.0
            };
            taper(z) * k
        };
        let vol = phantom(64, |p| radius(p.z) - (p.truncate() - axis).length());
        let path = [DVec3::new(32.0, 31.5, 1.0), DVec3::new(32.0, 31.5, 61.0)];
        let sections = measure_path(&vol, &path, 60, DVec3::X, &opt(&vol), None).unwrap();
        let st = grade(&sections, 60.0, &StenosisOptions::default()).unwrap();
        // The lesion's section: arc 30.5 mm, z = 31.5.
        assert_eq!(st.lesion, 30, "{st:?}");
        let z = 1.0 + st.lesion_mm;
        let d_ref = 2.0 * taper(z);
        // Against the line through the healthy tube's own measured sections in the span, the
        // shoulders (less than 10 % narrowed, so kept in the fit) draw it down under 1 %;
        // against the true taper, a little more: a tube of 8-12 mm measures 0.5 % narrow on
        // 1 mm voxels.
        let healthy: Vec<(f64, f64)> = sections
            .iter()
            .filter(|s| (s.arc_mm - st.lesion_mm).abs() <= 20.0)
            .filter(|s| (s.arc_mm + 1.0 - 31.5).abs() >= 8.0)
            .map(|s| (s.arc_mm, s.lumen.as_ref().unwrap().equivalent_diameter_mm))
            .collect();
        let (line, slope) = crate::stenosis::fit(&healthy, st.lesion_mm, true);
        assert!(
            (st.at_lesion_mm - line).abs() < 0.01 * line,
            "{st:?} for {line}"
        );
        assert!(
            (st.at_lesion_mm - d_ref).abs() < 0.015 * d_ref,
            "{st:?} for {d_ref}"
        );
        assert!((st.slope - slope).abs() < 0.005, "{st:?} for {slope}");
        let (d, a) = (2.0 * radius(z), PI * radius(z).powi(2));
        assert!(
            (st.diameter_pct - 100.0 * (1.0 - d / d_ref)).abs() < 1.0,
            "{st:?}"
        );
        assert!(
            (st.area_pct - 100.0 * (1.0 - a / (PI * d_ref * d_ref / 4.0))).abs() < 1.0,
            "{st:?}"
        );
        let [a, b] = st.narrowed.unwrap().mm;
        let length = b - a;
        let want = 16.0 * (-0.6f64).acos() / PI;
        assert!((length - want).abs() <= 1.0, "{length} for {want}");
        assert!((0.5 * (a + b) + 1.0 - 31.5).abs() <= 0.5);
    }

    /// Segments `row`'s plane on the lumen's window and on the whole field, and checks that
    /// they agree: the window's samples are the field's, the field's lumen lies in the window
    /// and is the window's, and the figures and the run across the middle row are the same,
    /// bit for bit; the window is smaller than the field unless the lumen is open. Returns
    /// the lumen's figures, if one was found.
    fn same_on_the_window(vol: &Volume, row: &CprRow, o: &LumenOptions) -> Option<Lumen> {
        let m = Marcher::new(vol, None);
        let (a, b) = (
            segment_on(vol, &m, row, o, Fit::Lumen),
            segment_on(vol, &m, row, o, Fit::Field),
        );
        let (a, b) = match (a, b) {
            (None, None) => return None,
            (Some(a), Some(b)) => (a, b),
            (a, b) => panic!("a lumen on one: {} {}", a.is_some(), b.is_some()),
        };
        assert_eq!(b.win.len(), b.n * b.n);
        let mut inside = 0;
        for k in 0..b.win.len() {
            let (i, j) = b.win.pixel(k);
            match a.win.index(i, j) {
                Some(q) => {
                    inside += 1;
                    assert_eq!(a.mask[q], b.mask[k], "pixel ({i}, {j})");
                    assert_eq!(a.values[q].to_bits(), b.values[k].to_bits());
                }
                None => assert!(
                    !b.mask[k],
                    "the field's lumen at ({i}, {j}) is off the window"
                ),
            }
        }
        assert_eq!(inside, a.win.len());
        let (la, ea) = measure_segmented(&a, row);
        let (lb, eb) = measure_segmented(&b, row);
        assert_eq!(la, lb);
        assert_eq!(ea, eb);
        assert_eq!(across_segmented(&a), across_segmented(&b));
        assert!(la.open || a.win.len() < b.win.len(), "{:?}", a.win);
        Some(la)
    }

    /// The window gives the field's lumen on every kind of section: a tube from on its axis,
    /// off it, from outside it and from too far; a ring's hole; a side branch cut off and not;
    /// a lumen wider than the field; a neighbour joined by a neck; a tube running off the
    /// volume's edge; slanted sections; and tubes of many sizes and places.
    #[test]
    fn the_lumen_on_its_window_is_the_lumen_on_the_field() {
        let row_at = |vol: &Volume, a: DVec3, b: DVec3, o: &LumenOptions| {
            measure_path(vol, &[a, b], 1, DVec3::X, o, None).unwrap()[0].row
        };
        let (r, axis) = (7.3, DVec2::new(31.6, 32.2));
        let tube = phantom(24, |p| r - (p.truncate() - axis).length());
        let o = opt(&tube);
        let mut found = 0;
        for (x, y) in [
            (31.6, 32.2),
            (33.0, 36.0),
            (40.9, 32.5),
            (31.6, 32.2 - r - 4.0),
        ] {
            let row = row_at(&tube, DVec3::new(x, y, 2.0), DVec3::new(x, y, 21.0), &o);
            found += same_on_the_window(&tube, &row, &o).is_some() as usize;
        }
        assert_eq!(found, 4);
        let far = row_at(
            &tube,
            DVec3::new(50.0, 50.0, 2.0),
            DVec3::new(50.0, 50.0, 21.0),
            &o,
        );
        assert!(same_on_the_window(&tube, &far, &o).is_none());
        // Slanted through the tube: elliptic sections.
        for tilt in [3.0, 9.0] {
            let row = row_at(
                &tube,
                DVec3::new(31.6 - tilt, 32.2, 2.0),
                DVec3::new(31.6 + tilt, 32.0, 21.0),
                &o,
            );
            assert!(same_on_the_window(&tube, &row, &o).is_some());
        }
        // A ring: the path in its dark core, the hole filled.
        let centre = DVec2::new(30.0, 30.0);
        let ring = phantom(8, |p| {
            let d = (p.truncate() - centre).length();
            (6.0 - d).min(d - 2.0)
        });
        let row = row_at(
            &ring,
            DVec3::new(30.0, 30.0, 1.0),
            DVec3::new(30.0, 30.0, 6.0),
            &o,
        );
        let l = same_on_the_window(&ring, &row, &o).unwrap();
        assert!(l.area_mm2 > std::f64::consts::PI * 30.0);
        // A side branch to the field's edge, cut off (closed) and not (open).
        let c = DVec2::new(28.0, 32.0);
        let branch = phantom_at(0.5, 16, |p| {
            let q = p.truncate() - c;
            let branch = if q.x > 0.0 { 1.2 - q.y.abs() } else { -10.0 };
            (8.0 - q.length()).max(branch)
        });
        let ob = opt(&branch);
        let row = row_at(
            &branch,
            DVec3::new(c.x, c.y, 1.0),
            DVec3::new(c.x, c.y, 6.0),
            &ob,
        );
        for (open_mm, open) in [(2.0, false), (0.0, true)] {
            let o = LumenOptions { open_mm, ..ob };
            assert_eq!(same_on_the_window(&branch, &row, &o).unwrap().open, open);
        }
        // Wider than the field.
        let wide = phantom(8, |p| 25.0 - (p.truncate() - DVec2::splat(32.0)).length());
        let o30 = LumenOptions {
            field_mm: 30.0,
            ..opt(&wide)
        };
        let row = row_at(
            &wide,
            DVec3::new(32.0, 32.0, 1.0),
            DVec3::new(32.0, 32.0, 6.0),
            &o30,
        );
        assert!(same_on_the_window(&wide, &row, &o30).unwrap().open);
        // Two tubes joined by a neck 1.6 mm wide: the opening cuts the neighbour off.
        let (a, b) = (DVec2::new(24.0, 32.0), DVec2::new(42.0, 32.0));
        let pair = phantom_at(0.5, 12, |p| {
            let q = p.truncate();
            let neck = if (a.x..b.x).contains(&q.x) {
                0.8 - (q.y - 32.0).abs()
            } else {
                -10.0
            };
            (6.0 - (q - a).length())
                .max(5.0 - (q - b).length())
                .max(neck)
        });
        let op = opt(&pair);
        let row = row_at(
            &pair,
            DVec3::new(a.x, a.y, 1.0),
            DVec3::new(a.x, a.y, 5.0),
            &op,
        );
        let l = same_on_the_window(&pair, &row, &op).unwrap();
        assert!(!l.open && l.max_diameter_mm < 13.0, "{l:?}");
        // A tube running off the volume's edge (samples beyond it are NaN).
        let edge = phantom(8, |p| 6.0 - (p.truncate() - DVec2::new(2.0, 30.0)).length());
        let row = row_at(
            &edge,
            DVec3::new(3.0, 30.0, 1.0),
            DVec3::new(3.0, 30.0, 6.0),
            &o,
        );
        assert!(same_on_the_window(&edge, &row, &o).is_some());
        // Tubes of many sizes and places, paths near and off their axes.
        let mut rng = crate::tests::XorShift(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.f64();
        for _ in 0..12 {
            let (r, cx, cy) = (
                1.5 + 12.0 * next(),
                20.0 + 24.0 * next(),
                20.0 + 24.0 * next(),
            );
            let vol = phantom(6, |p| r - (p.truncate() - DVec2::new(cx, cy)).length());
            let o = LumenOptions {
                open_mm: 3.0 * next(),
                ..opt(&vol)
            };
            let (x, y) = (cx + 8.0 * (next() - 0.5), cy + 8.0 * (next() - 0.5));
            let row = row_at(
                &vol,
                DVec3::new(x, y, 1.0),
                DVec3::new(x + 4.0 * next(), y, 4.0),
                &o,
            );
            same_on_the_window(&vol, &row, &o);
        }
    }

    /// On the chest CT's aorta, a section every 5 mm (the arch's open sections among them):
    /// the window gives the field's lumen on each.
    #[test]
    fn the_aortas_sections_on_their_windows_are_those_on_the_field() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let vol = raystream_io::load_volume(
            &root.join("../shared/data/volumes/nifti/chest_ct_stents_totalseg.nii.gz"),
            &Default::default(),
        )
        .unwrap();
        let points = raystream_io::read_curve(&root.join("examples/chest_aorta.mrk.json")).unwrap();
        let o = LumenOptions::for_volume(&vol);
        let plane = CurvedPlane::sections(&points, DVec3::X, 0.0, 31).unwrap();
        let found: Vec<Lumen> = plane
            .rows
            .par_iter()
            .filter_map(|row| same_on_the_window(&vol, row, &o))
            .collect();
        assert!(found.len() >= 28, "{} of 31", found.len());
        assert!(found.iter().any(|l| l.open) && found.iter().any(|l| !l.open));
    }

    #[test]
    fn the_hull_and_callipers_of_a_square() {
        let pts = [
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 2.0),
            DVec2::new(0.0, 2.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0, 0.0),
        ];
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4, "{h:?}");
        let (d, _) = max_chord(&h);
        assert!((d - 8f64.sqrt()).abs() < 1e-12);
        let (w, _) = min_width(&h);
        assert!((w - 2.0).abs() < 1e-12);
    }
}
