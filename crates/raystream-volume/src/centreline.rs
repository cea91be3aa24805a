//! A vessel's centreline from a few points placed in its lumen, as a vascular workstation
//! tracks one from clicks: the minimal path (Deschamps and Cohen 2001) through the lumen —
//! the voxels at or above a threshold (contrast-filled blood; or at or below it, an airway's
//! gas), closed over thin gaps — from
//! each point to the next, where a step costs its length over the fourth power of its distance
//! from the lumen's wall, so that the path keeps to the middle of the vessel and goes round its
//! bends rather than across them. The voxel path is then smoothed along its length and resampled as the
//! control points of a path (`render --path`, `measure --path`).
//!
//! The search runs on a box about the points (their extent and a margin), over its lumen
//! voxels with their 26 neighbours (Dijkstra's algorithm), the distances to the wall from an
//! exact Euclidean distance transform in millimetres (anisotropic voxels). A sheared grid
//! (gantry tilt) is searched in its own indices: distances across its slices are those of
//! the index axes, not exactly of the patient.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use raystream_io::Volume;
use raystream_math::DVec3;

use crate::distance::squared_distance;

/// How the centreline is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CentrelineOptions {
    /// Voxels at or above this are lumen, HU (or at or below it, with `dark`).
    pub threshold_hu: f32,
    /// The lumen is the voxels at or below the threshold: an airway's or a bowel's gas,
    /// darker than the wall round it, rather than contrast-filled blood, brighter.
    pub dark: bool,
    /// Each point placed is moved to the deepest lumen voxel within this distance, mm.
    pub seed_mm: f64,
    /// The box searched reaches this far beyond the points' extent, mm.
    pub margin_mm: f64,
    /// Gaps in the lumen narrower than twice this are closed, mm (a morphological closing).
    pub close_mm: f64,
    /// The path's smoothing window along its length, mm.
    pub smooth_mm: f64,
    /// The control points written are this far apart along the path, mm.
    pub step_mm: f64,
}

impl Default for CentrelineOptions {
    /// 150 HU (as `measure`'s lumen), points moved up to 5 mm, a 30 mm margin, gaps under
    /// 6 mm closed, smoothed over 5 mm, a control point every 2 mm. (The closing and the
    /// cost's power were chosen on the chest CT's aorta: 2 mm and the square left the path
    /// off the middle where a flap crosses its lumen.)
    fn default() -> CentrelineOptions {
        CentrelineOptions {
            threshold_hu: 150.0,
            dark: false,
            seed_mm: 5.0,
            margin_mm: 30.0,
            close_mm: 3.0,
            smooth_mm: 5.0,
            step_mm: 2.0,
        }
    }
}

/// A lumen's side of its threshold, in words: "at or above" (a bright lumen, contrast-filled
/// blood), or with `dark` "at or below" (an airway's gas); the centreline's and the sections'
/// (`raystream_cpu::lumen::LumenOptions::dark`) alike.
pub fn bound_words(dark: bool) -> &'static str {
    if dark { "at or below" } else { "at or above" }
}

/// The most voxels a search box may hold: about 40 bytes each at the most (the mask, the
/// closing's and the wall's distance transforms, the search's costs and links), 640 MiB. An
/// aorta from the arch to the iliac arteries in a 0.7 mm CTA fills about half of it.
pub const MAX_BOX_VOXELS: usize = 1 << 24;

/// A centreline found.
#[derive(Clone, Debug, PartialEq)]
pub struct Centreline {
    /// The control points (LPS mm), `step_mm` apart, from the first point placed to the last.
    pub points: Vec<DVec3>,
    /// Where each point placed was moved to (LPS mm: the deepest lumen voxel near it), and the
    /// distance to the wall there, mm.
    pub anchors: Vec<(DVec3, f64)>,
    /// The smoothed path's length, mm.
    pub length_mm: f64,
    /// The search box's voxels, and how many of them are lumen.
    pub box_voxels: usize,
    pub lumen_voxels: usize,
}

impl CentrelineOptions {
    /// Whether a voxel of value `v` is lumen.
    pub fn is_lumen(&self, v: f32) -> bool {
        if self.dark {
            v <= self.threshold_hu
        } else {
            v >= self.threshold_hu
        }
    }

    /// The lumen's side of the threshold, in words ([`bound_words`]).
    pub fn bound_words(&self) -> &'static str {
        bound_words(self.dark)
    }

    pub fn check(&self) -> Result<(), String> {
        if !self.threshold_hu.is_finite() {
            return Err(format!(
                "a threshold of {} HU: it must be a number",
                self.threshold_hu
            ));
        }
        for (what, v, zero_ok) in [
            ("seed radius", self.seed_mm, true),
            ("margin", self.margin_mm, true),
            ("closing radius", self.close_mm, true),
            ("smoothing window", self.smooth_mm, true),
            ("control-point step", self.step_mm, false),
        ] {
            if !(v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0))) || v > 1e4 {
                return Err(format!(
                    "a {what} of {v} mm: it must be {} and at most 10 m",
                    if zero_ok { "zero or more" } else { "positive" }
                ));
            }
        }
        Ok(())
    }
}

/// The centreline through the lumen of `vol` from `waypoints[0]` through each of the others
/// in turn (LPS mm, at least two), or why there is none: a point with no lumen near it, two
/// points the lumen does not join, a box too large.
pub fn centreline(
    vol: &Volume,
    waypoints: &[DVec3],
    opt: &CentrelineOptions,
) -> Result<Centreline, String> {
    opt.check()?;
    if waypoints.len() < 2 {
        return Err("a centreline needs two points, its ends".into());
    }
    let grid = Grid::about(vol, waypoints, opt.margin_mm)?;
    let mask: Vec<bool> = (0..grid.len())
        .map(|k| {
            let [i, j, l] = grid.ijk(k);
            opt.is_lumen(vol.at(i, j, l))
        })
        .collect();
    // Closed: gaps narrower than the disc (a dissection flap, a stent graft's fabric, noise
    // below the threshold) are lumen, so that the wall's distance is the vessel's.
    let mask = if opt.close_mm > 0.0 {
        let r2 = opt.close_mm * opt.close_mm;
        let near = squared_distance(grid.dims, vol.spacing, |k| mask[k]);
        let grown: Vec<bool> = near.iter().map(|&d| d <= r2).collect();
        let beyond = squared_distance(grid.dims, vol.spacing, |k| !grown[k]);
        beyond
            .iter()
            .map(|&d| d > r2)
            .zip(&mask)
            .map(|(c, &m)| c || m)
            .collect()
    } else {
        mask
    };
    let lumen_voxels = mask.iter().filter(|&&m| m).count();
    // The distance to the wall, mm; the box's faces count as wall (what lies beyond is not
    // known).
    let depth2 = squared_distance(grid.dims, vol.spacing, |k| !mask[k] || grid.on_face(k));
    let depth: Vec<f32> = depth2.iter().map(|&d| d.sqrt() as f32).collect();
    let mut anchors = Vec::with_capacity(waypoints.len());
    let mut starts = Vec::with_capacity(waypoints.len());
    for (n, &w) in waypoints.iter().enumerate() {
        let k = grid
            .deepest_near(vol, w, opt.seed_mm, &mask, &depth)
            .ok_or_else(|| {
                format!(
                    "point {} ({:.1}, {:.1}, {:.1}) mm LPS: no lumen {} {} HU within {} mm (a point off the vessel, or a scan without contrast: --lumen HU, --seed MM)",
                    n + 1,
                    w.x,
                    w.y,
                    w.z,
                    opt.bound_words(),
                    opt.threshold_hu,
                    opt.seed_mm
                )
            })?;
        anchors.push((grid.world(vol, k), depth[k] as f64));
        starts.push(k);
    }
    let mut voxels: Vec<usize> = vec![starts[0]];
    for (n, pair) in starts.windows(2).enumerate() {
        let leg = grid
            .minimal_path(vol, pair[0], pair[1], &mask, &depth)
            .ok_or_else(|| {
                format!(
                    "points {} and {}: the lumen {} {} HU does not join them within {} mm of the points (a gap, an occlusion or a stenosis beyond the threshold: another --lumen, or more points)",
                    n + 1,
                    n + 2,
                    opt.bound_words(),
                    opt.threshold_hu,
                    opt.margin_mm
                )
            })?;
        voxels.extend(leg.into_iter().skip(1));
    }
    if voxels.len() < 2 {
        return Err(format!(
            "the {} points placed all move to one voxel of the lumen: place the ends further apart",
            waypoints.len()
        ));
    }
    let raw: Vec<DVec3> = voxels.iter().map(|&k| grid.world(vol, k)).collect();
    let smoothed = smooth(&raw, opt.smooth_mm);
    let length_mm = smoothed.windows(2).map(|w| w[0].distance(w[1])).sum();
    let points = resample(&smoothed, opt.step_mm);
    Ok(Centreline {
        points,
        anchors,
        length_mm,
        box_voxels: grid.len(),
        lumen_voxels,
    })
}

/// The box of voxels searched: `lo` its first voxel's indices, `dims` its size.
struct Grid {
    lo: [usize; 3],
    dims: [usize; 3],
}

impl Grid {
    /// The box about `points` (their voxel indices' extent) and `margin_mm` on every side,
    /// within `vol`'s grid.
    fn about(vol: &Volume, points: &[DVec3], margin_mm: f64) -> Result<Grid, String> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for &p in points {
            let q = vol.world_to_index(p);
            for a in 0..3 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let mut out_lo = [0usize; 3];
        let mut dims = [0usize; 3];
        for a in 0..3 {
            let m = margin_mm / vol.spacing[a];
            let top = vol.dims[a] as f64 - 1.0;
            let (l, h) = ((lo[a] - m).floor().max(0.0), (hi[a] + m).ceil().min(top));
            if l.partial_cmp(&h).is_none_or(|o| o.is_gt()) {
                return Err(format!(
                    "the points lie outside the volume along its axis {} (`info` gives its extent): coordinates in LPS mm, or a markups file naming RAS",
                    ["i", "j", "k"][a]
                ));
            }
            out_lo[a] = l as usize;
            dims[a] = (h - l) as usize + 1;
        }
        let total = dims[0] as u128 * dims[1] as u128 * dims[2] as u128;
        if total > MAX_BOX_VOXELS as u128 {
            return Err(format!(
                "the points span {}x{}x{} voxels with the margin, over {} (place them along one vessel, or a smaller --margin)",
                dims[0], dims[1], dims[2], MAX_BOX_VOXELS
            ));
        }
        Ok(Grid { lo: out_lo, dims })
    }

    fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// The volume's indices of box cell `k`.
    fn ijk(&self, k: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [
            self.lo[0] + k % nx,
            self.lo[1] + k / nx % ny,
            self.lo[2] + k / (nx * ny),
        ]
    }

    fn on_face(&self, k: usize) -> bool {
        let [nx, ny, nz] = self.dims;
        let (i, j, l) = (k % nx, k / nx % ny, k / (nx * ny));
        let edge = |x: usize, n: usize| n > 1 && (x == 0 || x == n - 1);
        edge(i, nx) || edge(j, ny) || edge(l, nz)
    }

    fn world(&self, vol: &Volume, k: usize) -> DVec3 {
        let [i, j, l] = self.ijk(k);
        vol.index_to_world(DVec3::new(i as f64, j as f64, l as f64))
    }

    /// The lumen cell deepest inside within `radius` mm of `p` (ties: the nearest to it).
    fn deepest_near(
        &self,
        vol: &Volume,
        p: DVec3,
        radius: f64,
        mask: &[bool],
        depth: &[f32],
    ) -> Option<usize> {
        let q = vol.world_to_index(p);
        let mut best: Option<(f32, f64, usize)> = None;
        let reach: Vec<i64> = (0..3)
            .map(|a| (radius / vol.spacing[a]).ceil() as i64 + 1)
            .collect();
        let c: Vec<i64> = (0..3)
            .map(|a| q[a].round() as i64 - self.lo[a] as i64)
            .collect();
        for dl in -reach[2]..=reach[2] {
            for dj in -reach[1]..=reach[1] {
                for di in -reach[0]..=reach[0] {
                    let at = [c[0] + di, c[1] + dj, c[2] + dl];
                    if (0..3).any(|a| at[a] < 0 || at[a] >= self.dims[a] as i64) {
                        continue;
                    }
                    let k = at[0] as usize
                        + self.dims[0] * (at[1] as usize + self.dims[1] * at[2] as usize);
                    if !mask[k] {
                        continue;
                    }
                    let gap = self.world(vol, k).distance(p);
                    if gap > radius.max(0.5 * vol.spacing.iter().copied().fold(0.0, f64::max)) {
                        continue;
                    }
                    let better = match best {
                        None => true,
                        Some((d, g, bk)) => {
                            depth[k] > d || (depth[k] == d && (gap < g || (gap == g && k < bk)))
                        }
                    };
                    if better {
                        best = Some((depth[k], gap, k));
                    }
                }
            }
        }
        best.map(|b| b.2)
    }

    /// The cheapest path from cell `from` to cell `to` through lumen cells (26 neighbours), a
    /// step costing its length (mm) times the mean of its ends' 1 / (depth⁴ + 0.01 mm⁴).
    fn minimal_path(
        &self,
        vol: &Volume,
        from: usize,
        to: usize,
        mask: &[bool],
        depth: &[f32],
    ) -> Option<Vec<usize>> {
        let [nx, ny, nz] = self.dims;
        let weight = |k: usize| 1.0 / ((depth[k] as f64).powi(4) + 0.01);
        let mut steps = Vec::with_capacity(26);
        for dl in -1i64..=1 {
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    if (di, dj, dl) != (0, 0, 0) {
                        let len = ((di as f64 * vol.spacing[0]).powi(2)
                            + (dj as f64 * vol.spacing[1]).powi(2)
                            + (dl as f64 * vol.spacing[2]).powi(2))
                        .sqrt();
                        steps.push(([di, dj, dl], len));
                    }
                }
            }
        }
        let mut cost = vec![f64::INFINITY; self.len()];
        let mut prev = vec![u32::MAX; self.len()];
        let mut heap = BinaryHeap::new();
        cost[from] = 0.0;
        // Costs are non-negative finite f64: their bits order as the numbers do.
        heap.push(Reverse((0u64, from)));
        while let Some(Reverse((bits, k))) = heap.pop() {
            let c = f64::from_bits(bits);
            if c > cost[k] {
                continue;
            }
            if k == to {
                break;
            }
            let (i, j, l) = (
                (k % nx) as i64,
                (k / nx % ny) as i64,
                (k / (nx * ny)) as i64,
            );
            for &([di, dj, dl], len) in &steps {
                let (a, b, e) = (i + di, j + dj, l + dl);
                if a < 0 || b < 0 || e < 0 || a >= nx as i64 || b >= ny as i64 || e >= nz as i64 {
                    continue;
                }
                let q = a as usize + nx * (b as usize + ny * e as usize);
                if !mask[q] {
                    continue;
                }
                let next = c + len * 0.5 * (weight(k) + weight(q));
                if next < cost[q] {
                    cost[q] = next;
                    prev[q] = k as u32;
                    heap.push(Reverse((next.to_bits(), q)));
                }
            }
        }
        if !cost[to].is_finite() {
            return None;
        }
        let mut path = vec![to];
        let mut k = to;
        while k != from {
            k = prev[k] as usize;
            path.push(k);
        }
        path.reverse();
        Some(path)
    }
}

/// `p` resampled every 0.25 mm along its length and averaged over a window `window_mm` long
/// about each sample (narrower at the ends, so that the ends stay where they are).
fn smooth(p: &[DVec3], window_mm: f64) -> Vec<DVec3> {
    let fine = resample(p, 0.25);
    let half = (0.5 * window_mm / 0.25).round() as usize;
    if half == 0 || fine.len() < 3 {
        return fine;
    }
    let n = fine.len();
    let mut sum = vec![DVec3::ZERO; n + 1];
    for (i, &q) in fine.iter().enumerate() {
        sum[i + 1] = sum[i] + q;
    }
    (0..n)
        .map(|i| {
            let h = half.min(i).min(n - 1 - i);
            (sum[i + h + 1] - sum[i - h]) / (2 * h + 1) as f64
        })
        .collect()
}

/// Points along the polyline `p` every `step` of its length, its first and last included.
fn resample(p: &[DVec3], step: f64) -> Vec<DVec3> {
    let Some(&first) = p.first() else {
        return Vec::new();
    };
    let mut out = vec![first];
    let (mut next, mut s) = (step, 0.0);
    for w in p.windows(2) {
        let seg = w[0].distance(w[1]);
        while next <= s + seg {
            out.push(w[0].lerp(w[1], (next - s) / seg));
            next += step;
        }
        s += seg;
    }
    let last = *p.last().unwrap();
    if out.last().map(|q| q.distance(last)) > Some(1e-9) {
        out.push(last);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CT on a `h` mm grid, `n` voxels a side, whose HU fall linearly across the surface
    /// `f = 0` of `f` (mm, positive inside): 500 HU a mm, from −1000 to 1000.
    fn phantom(h: f64, n: usize, f: impl Fn(DVec3) -> f64) -> Volume {
        let mut data = Vec::with_capacity(n * n * n);
        for l in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = DVec3::new(i as f64, j as f64, l as f64) * h;
                    data.push((500.0 * f(p)).clamp(-1000.0, 1000.0) as f32);
                }
            }
        }
        Volume::hounsfield([n; 3], [h; 3], data)
    }

    /// The distance from `p` to the quarter circle of radius `r` about `c` in the x–z plane.
    fn off_arc(p: DVec3, c: DVec3, r: f64) -> f64 {
        let q = p - c;
        let a = q.z.atan2(q.x).clamp(0.0, std::f64::consts::FRAC_PI_2);
        (q - DVec3::new(r * a.cos(), 0.0, r * a.sin())).length()
    }

    #[test]
    fn a_curved_tube_is_followed_down_its_middle() {
        // A tube of radius 4 mm about a quarter circle of radius 30 mm, and its two ends
        // placed 2.5 mm off the axis: the centreline keeps within 0.3 mm of the axis between
        // them and is as long as the arc.
        let (c, r) = (DVec3::new(8.0, 24.0, 8.0), 30.0);
        let vol = phantom(1.0, 48, |p| 4.0 - off_arc(p, c, r));
        let ends = [
            c + DVec3::new(r, 2.5, 0.0),
            c + DVec3::new(1.5, 0.0, r + 2.0),
        ];
        let line = centreline(&vol, &ends, &CentrelineOptions::default()).unwrap();
        // The ends move onto the axis (the deepest voxels near them).
        for (a, depth) in &line.anchors {
            assert!(off_arc(*a, c, r) < 0.8, "{a}");
            assert!(*depth > 3.0, "{depth}");
        }
        let quarter = std::f64::consts::FRAC_PI_2 * r;
        assert!(
            (line.length_mm - quarter).abs() < 0.05 * quarter,
            "{} mm for {quarter}",
            line.length_mm
        );
        for (i, p) in line.points.iter().enumerate() {
            let off = off_arc(*p, c, r);
            assert!(
                off < 0.3 || (i < 3 || i + 3 > line.points.len()) && off < 0.8,
                "{i}: {p} {off}"
            );
        }
        // Control points 2 mm apart.
        for w in line.points.windows(2).take(line.points.len() - 2) {
            assert!((w[0].distance(w[1]) - 2.0).abs() < 0.01);
        }
    }

    #[test]
    fn the_path_goes_round_a_bend_not_across_a_neighbour() {
        // Two parallel tubes 16 mm apart joined at their lower ends (a U), the points at their
        // upper ends: the path runs down one tube and back up the other (about 2×36 + π·8 mm),
        // where the box reaches the bend (a 50 mm margin; the default 30 mm stops short of it,
        // and the points are then not joined).
        let vol = phantom(1.0, 56, |p| {
            let (x, y, z) = (p.x, p.y, p.z);
            let leg = |cx: f64| 3.0 - ((x - cx).powi(2) + (y - 28.0).powi(2)).sqrt();
            let straight = if (12.0..=50.0).contains(&z) {
                leg(20.0).max(leg(36.0))
            } else {
                -10.0
            };
            // The bend: a half torus of radius 8 about (28, 28, 12), below z = 12.
            let bend = if z < 12.0 {
                let q = ((x - 28.0).powi(2) + (z - 12.0).powi(2)).sqrt();
                3.0 - ((q - 8.0).powi(2) + (y - 28.0).powi(2)).sqrt()
            } else {
                -10.0
            };
            straight.max(bend)
        });
        let ends = [DVec3::new(20.0, 28.0, 48.0), DVec3::new(36.0, 28.0, 48.0)];
        let short = centreline(&vol, &ends, &CentrelineOptions::default()).unwrap_err();
        assert!(short.contains("does not join"), "{short}");
        let o = CentrelineOptions {
            margin_mm: 50.0,
            ..Default::default()
        };
        let line = centreline(&vol, &ends, &o).unwrap();
        let want = 2.0 * 36.0 + std::f64::consts::PI * 8.0;
        assert!(
            (line.length_mm - want).abs() < 0.05 * want,
            "{}",
            line.length_mm
        );
        // Its lowest point is the bend's bottom.
        let low = line
            .points
            .iter()
            .map(|p| p.z)
            .fold(f64::INFINITY, f64::min);
        assert!((low - 4.0).abs() < 0.8, "{low}");
    }

    /// A dark lumen (`dark`: an airway's gas in tissue) is tracked as its bright mirror is: the
    /// U of tubes with its values negated, at the negated threshold, gives the same
    /// centreline, point for point.
    #[test]
    fn a_dark_lumen_is_found_as_its_bright_mirror() {
        let u = |p: DVec3| {
            let leg = |cx: f64| 3.0 - ((p.x - cx).powi(2) + (p.y - 28.0).powi(2)).sqrt();
            let bend = if p.z < 12.0 {
                let q = ((p.x - 28.0).powi(2) + (p.z - 12.0).powi(2)).sqrt();
                3.0 - ((q - 8.0).powi(2) + (p.y - 28.0).powi(2)).sqrt()
            } else {
                -10.0
            };
            let straight = if (12.0..=50.0).contains(&p.z) {
                leg(20.0).max(leg(36.0))
            } else {
                -10.0
            };
            straight.max(bend)
        };
        let bright = phantom(1.0, 56, u);
        let dark = phantom(1.0, 56, |p| -u(p));
        let ends = [DVec3::new(20.0, 28.0, 48.0), DVec3::new(36.0, 28.0, 48.0)];
        let o = CentrelineOptions {
            margin_mm: 50.0,
            ..Default::default()
        };
        let want = centreline(&bright, &ends, &o).unwrap();
        let got = centreline(
            &dark,
            &ends,
            &CentrelineOptions {
                threshold_hu: -o.threshold_hu,
                dark: true,
                ..o
            },
        )
        .unwrap();
        assert_eq!(got, want);
        // Nothing below -2000 HU: the error says which side of the threshold it looked.
        let e = centreline(
            &dark,
            &ends,
            &CentrelineOptions {
                threshold_hu: -2000.0,
                dark: true,
                ..o
            },
        )
        .unwrap_err();
        assert!(e.contains("no lumen at or below -2000 HU"), "{e}");
    }

    #[test]
    fn a_thin_flap_inside_the_lumen_is_closed_over() {
        // A tube of radius 6 mm along z split by a flap 1 mm thick (as a dissection's): closed
        // over (by the default 3 mm, or 2 mm), the path runs down the tube's axis; not closed,
        // down the middle of one half, about 3 mm off it.
        let c = (24.0, 24.0);
        let vol = phantom(1.0, 48, |p| {
            let tube = 6.0 - ((p.x - c.0).powi(2) + (p.y - c.1).powi(2)).sqrt();
            let flap = (p.x - c.0).abs() - 0.5;
            tube.min(flap.max(-0.6))
        });
        let ends = [DVec3::new(c.0, c.1, 6.0), DVec3::new(c.0, c.1, 42.0)];
        let off = |close_mm: f64| {
            let o = CentrelineOptions {
                close_mm,
                ..Default::default()
            };
            let line = centreline(&vol, &ends, &o).unwrap();
            let n = line.points.len();
            line.points[3..n - 3]
                .iter()
                .map(|p| ((p.x - c.0).powi(2) + (p.y - c.1).powi(2)).sqrt())
                .fold(0.0, f64::max)
        };
        for r in [2.0, 3.0] {
            let closed = off(r);
            assert!(closed < 0.5, "closed by {r} mm: {closed} mm off the axis");
        }
        let split = off(0.0);
        assert!(split > 2.0, "not closed: {split} mm off the axis");
    }

    #[test]
    fn bad_points_are_errors() {
        let vol = phantom(1.0, 24, |p| {
            3.0 - ((p.x - 12.0).powi(2) + (p.y - 12.0).powi(2)).sqrt()
        });
        let o = CentrelineOptions::default();
        let on = |z: f64| DVec3::new(12.0, 12.0, z);
        let e = centreline(&vol, &[on(2.0), DVec3::new(2.0, 2.0, 20.0)], &o).unwrap_err();
        assert!(e.contains("point 2") && e.contains("no lumen"), "{e}");
        let e = centreline(&vol, &[on(2.0)], &o).unwrap_err();
        assert!(e.contains("two points"), "{e}");
        let e = centreline(&vol, &[on(2.0) + 1e4, on(20.0) + 1e4], &o).unwrap_err();
        assert!(e.contains("outside the volume"), "{e}");
        let e = centreline(&vol, &[on(10.0), on(10.2)], &o).unwrap_err();
        assert!(e.contains("one voxel"), "{e}");
        let bad = CentrelineOptions { step_mm: 0.0, ..o };
        assert!(
            centreline(&vol, &[on(2.0), on(20.0)], &bad)
                .unwrap_err()
                .contains("positive")
        );
        // Two tubes the lumen does not join.
        let two = phantom(1.0, 24, |p| {
            let a = 2.5 - ((p.x - 6.0).powi(2) + (p.y - 12.0).powi(2)).sqrt();
            let b = 2.5 - ((p.x - 18.0).powi(2) + (p.y - 12.0).powi(2)).sqrt();
            a.max(b)
        });
        let e = centreline(
            &two,
            &[DVec3::new(6.0, 12.0, 4.0), DVec3::new(18.0, 12.0, 20.0)],
            &o,
        )
        .unwrap_err();
        assert!(e.contains("does not join"), "{e}");
    }

    #[test]
    fn a_box_too_large_is_refused_before_it_is_searched() {
        // Points at opposite corners of a 1024×1024×17 grid: 17.8 M voxels.
        let mut vol = phantom(1.0, 2, |_| 1.0);
        vol.dims = [1024, 1024, 17];
        vol.data = vec![0.0; 1024 * 1024 * 17];
        let ends = [DVec3::ZERO, DVec3::new(1023.0, 1023.0, 16.0)];
        let e = centreline(&vol, &ends, &CentrelineOptions::default()).unwrap_err();
        assert!(e.contains("1024x1024x17") && e.contains("16777216"), "{e}");
    }

    #[test]
    fn resampling_keeps_its_ends_and_steps() {
        let p = [
            DVec3::ZERO,
            DVec3::new(3.0, 0.0, 0.0),
            DVec3::new(3.0, 4.5, 0.0),
        ];
        let r = resample(&p, 1.0);
        assert_eq!(r.len(), 9, "{r:?}");
        assert_eq!(r[0], DVec3::ZERO);
        assert_eq!(*r.last().unwrap(), p[2]);
        for w in r.windows(2).take(r.len() - 2) {
            let along: f64 = w[0].distance(w[1]);
            // Across the corner the chord is shorter than the arc.
            assert!(along <= 1.0 + 1e-9 && along > 0.7, "{along}");
        }
        // Smoothing a straight line leaves it straight, its ends in place.
        let s = smooth(&[DVec3::ZERO, DVec3::new(0.0, 0.0, 10.0)], 5.0);
        assert_eq!(s[0], DVec3::ZERO);
        assert!((s.last().unwrap().z - 10.0).abs() < 1e-9);
        assert!(s.iter().all(|q| q.x.abs() < 1e-12 && q.y.abs() < 1e-12));
    }
}
