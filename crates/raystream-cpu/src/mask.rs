//! The lumen and the outer wall that `measure` finds along a path, as labels on the CT's own
//! grid (`measure --mask`): [`LUMEN`] where the lumen is, [`WALL`] where the outer wall holds
//! more than the lumen (the wall, thrombus, an unenhanced false lumen), for a viewer (3D
//! Slicer, ITK-SNAP) to lay over the CT, to check the measurement by or to take further.
//!
//! The sections lie as far apart as the CT's finest voxel spacing, each segmented as `measure`
//! segments it (its lumen grid, and with a wall its outline, chosen with its neighbours along
//! the path as [`crate::wall::Track`] does). A voxel takes the labels of the section whose
//! plane is nearest its centre, among those within a section's spacing of it whose field
//! holds it (on a bend's outer side, where the planes fan apart, no voxel falls between two;
//! the choice is the geometry's alone, so the lumen's labels are the same with a wall or
//! without); projected on that plane, it is lumen where the section's lumen grid is, wall
//! where the outline holds it. Sections whose lumen is open (it
//! reaches the field's edge) or missing label nothing; so do voxels beyond the path's ends.

use rayon::prelude::*;
use raystream_io::Volume;
use raystream_math::{DVec2, DVec3};

use crate::cpr::{CprRow, CurvedPlane};
use crate::dvr::Marcher;
use crate::lumen::{LumenOptions, Segmented, measure_segmented, segment};
use crate::wall::{Track, WallOptions, wall_about};

/// The label of the lumen's voxels.
pub const LUMEN: u8 = 1;
/// The label of the voxels within the outer wall that are not lumen.
pub const WALL: u8 = 2;

/// The most sections a mask is made from (a path 10 m long at 0.5 mm voxels): each keeps its
/// lumen grid and outline until the voxels are labelled.
pub const MAX_MASK_SECTIONS: usize = 20_000;

/// Labels on a volume's grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Labels {
    /// One a voxel, i fastest (as [`Volume::data`]).
    pub data: Vec<u8>,
    /// The sections they come from, how many of them had a closed lumen, and how far apart
    /// they lie, mm.
    pub sections: usize,
    pub closed: usize,
    pub step_mm: f64,
}

impl Labels {
    /// How many voxels carry `label`.
    pub fn count(&self, label: u8) -> usize {
        self.data.iter().filter(|&&l| l == label).count()
    }
}

/// One section's lumen and outline, kept to label voxels by.
struct Cut {
    row: CprRow,
    tangent: DVec3,
    lumen: Segmented,
    /// The outline (section coordinates), its centre, and the nearest and farthest of its
    /// points from that centre.
    outline: Option<(Vec<DVec2>, DVec2, f64, f64)>,
    /// How far from the path's point anything it labels lies, mm.
    reach: f64,
}

impl Cut {
    /// The label of the point at offset `q` on the section's plane.
    fn label(&self, q: DVec2) -> u8 {
        if self.lumen.lumen_at(q) {
            return LUMEN;
        }
        match &self.outline {
            Some((pts, o, lo, hi)) => {
                let d = q.distance(*o);
                if d <= *lo || (d <= *hi && inside(pts, q)) {
                    WALL
                } else {
                    0
                }
            }
            None => 0,
        }
    }
}

/// Whether `q` lies inside the closed polygon `pts` (even–odd crossings).
fn inside(pts: &[DVec2], q: DVec2) -> bool {
    let mut inside = false;
    for (a, b) in pts.iter().zip(pts.iter().cycle().skip(1)) {
        if (a.y > q.y) != (b.y > q.y) {
            let x = a.x + (q.y - a.y) / (b.y - a.y) * (b.x - a.x);
            if q.x < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// The lumen (and with `wall`, the outer wall, chosen with `track`'s neighbours: the track
/// along the same path, for `opt` and those wall options) along the spline through `points`,
/// labelled on `vol`'s grid (see the module's comment).
pub fn label_path(
    vol: &Volume,
    points: &[DVec3],
    opt: &LumenOptions,
    wall: Option<(&WallOptions, &Track)>,
) -> Result<Labels, String> {
    let step = crate::dvr::min_spacing(vol) as f64;
    let length = crate::cpr::tortuosity(points)?.length_mm;
    let n = (length / step).ceil().max(1.0);
    if n > MAX_MASK_SECTIONS as f64 {
        return Err(format!(
            "a path {length:.1} mm long at the volume's {step} mm spacing needs {n} sections for a mask; at most {MAX_MASK_SECTIONS}"
        ));
    }
    let plane = CurvedPlane::sections(points, DVec3::X, 0.0, n as u32)?;
    let step = plane.length_mm / n;
    let m = Marcher::new(vol, None);
    let (wall, track) = (wall.map(|w| w.0), wall.map(|w| w.1));
    let cuts: Vec<Cut> = plane
        .rows
        .par_iter()
        .zip(&plane.arc_mm)
        .filter_map(|(row, &arc)| {
            let g = segment(vol, &m, row, opt)?;
            let (lumen, edge) = measure_segmented(&g, row);
            if lumen.open {
                return None;
            }
            let prior = track.and_then(|t| t.prior(arc, row));
            let outline = wall
                .and_then(|w| {
                    wall_about(vol, &m, row, opt, (w, prior.as_ref()), &g, (&lumen, &edge))
                })
                .map(|(w, o)| {
                    let c = row.offset_of(w.centre);
                    let d: Vec<f64> = o.points.iter().map(|p| p.distance(c)).collect();
                    let lo = d.iter().copied().fold(f64::INFINITY, f64::min);
                    let hi = d.iter().copied().fold(0.0, f64::max);
                    (o.points, c, lo, hi)
                });
            // The lumen's edge and the outline, and a grid pixel beyond (the lumen's pixels
            // reach half a pixel past their edge points).
            let reach = edge
                .iter()
                .chain(outline.iter().flat_map(|o| o.0.iter()))
                .map(|p| p.length())
                .fold(0.0, f64::max)
                + opt.pixel_mm;
            Some(Cut {
                tangent: row.normal.cross(row.lateral).normalize().as_dvec3(),
                row: *row,
                lumen: g.without_values(),
                outline,
                reach,
            })
        })
        .collect();
    let closed = cuts.len();
    // A plane holds a voxel within its section's field, corner to corner.
    let field = opt.field_mm * std::f64::consts::FRAC_1_SQRT_2;
    let data = label_voxels(vol, &cuts, step, field);
    Ok(Labels {
        data,
        sections: n as usize,
        closed,
        step_mm: step,
    })
}

/// Each voxel's label from the nearest section's plane whose field holds it (see the module's
/// comment). Only the voxels some cut labels can be labelled: each cut lists those of its slab
/// (within a section's spacing of its plane, `step`), then each of them is given the labels
/// of the nearest plane among all the cuts' that hold it within `field` of the path (ties: the
/// earlier section), which may be none. The work is the labelled voxels', not the fields'.
fn label_voxels(vol: &Volume, cuts: &[Cut], step: f64, field: f64) -> Vec<u8> {
    let [nx, ny, nz] = vol.dims;
    let world =
        |i: usize, j: usize, k: usize| vol.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
    // One step along i, in LPS mm.
    let di = world(1, 0, 0) - world(0, 0, 0);
    let mut candidates: Vec<usize> = cuts
        .par_iter()
        .flat_map_iter(|cut| {
            let c = cut.row.centre.as_dvec3();
            // The index box of the ball of `reach` about the path's point.
            let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
            for corner in 0..8 {
                let s = DVec3::new(
                    if corner & 1 == 0 { -1.0 } else { 1.0 },
                    if corner & 2 == 0 { -1.0 } else { 1.0 },
                    if corner & 4 == 0 { -1.0 } else { 1.0 },
                );
                let q = vol.world_to_index(c + s * cut.reach);
                (lo, hi) = (lo.min(q), hi.max(q));
            }
            let span = |a: f64, b: f64, n: usize| -> (usize, usize) {
                let a = a.floor().max(0.0);
                let b = b.ceil().min(n as f64 - 1.0);
                if a > b {
                    (0, 0)
                } else {
                    (a as usize, b as usize + 1)
                }
            };
            let (ri, rj, rk) = (
                span(lo.x, hi.x, nx),
                span(lo.y, hi.y, ny),
                span(lo.z, hi.z, nz),
            );
            let slope = di.dot(cut.tangent);
            let mut out = Vec::new();
            for k in rk.0..rk.1 {
                for j in rj.0..rj.1 {
                    // The run of i whose distance from the plane, d0 + i·slope, is at most
                    // `step`.
                    let d0 = (world(0, j, k) - c).dot(cut.tangent);
                    let (mut i0, mut i1) = ri;
                    if slope.abs() > 1e-12 {
                        let (a, b) = ((-step - d0) / slope, (step - d0) / slope);
                        let (a, b) = (a.min(b), a.max(b));
                        i0 = i0.max(a.ceil().max(0.0) as usize);
                        i1 = i1.min((b.floor() + 1.0).max(0.0) as usize);
                    } else if d0.abs() > step {
                        continue;
                    }
                    for i in i0..i1 {
                        let q = cut.row.offset_of(world(i, j, k));
                        if q.length() <= cut.reach && cut.label(q) != 0 {
                            out.push(i + nx * (j + ny * k));
                        }
                    }
                }
            }
            out
        })
        .collect();
    candidates.par_sort_unstable();
    candidates.dedup();
    let labels: Vec<(usize, u8)> = candidates
        .par_iter()
        .map(|&v| {
            let p = world(v % nx, v / nx % ny, v / (nx * ny));
            let nearest = cuts
                .iter()
                .filter_map(|cut| {
                    let d = (p - cut.row.centre.as_dvec3()).dot(cut.tangent).abs();
                    let q = cut.row.offset_of(p);
                    (d <= step && q.length() <= field).then_some((d, cut, q))
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            (v, nearest.map_or(0, |(_, cut, q)| cut.label(q)))
        })
        .collect();
    let mut data = vec![0u8; nx * ny * nz];
    for (v, label) in labels {
        data[v] = label;
    }
    data
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight vessel down z: a lumen 9 mm in radius (300 HU, its edge blurred over 2 mm)
    /// in a sac 15 mm in radius (40 HU) in fat, on a 1 mm grid. Every slice within the path
    /// holds the lumen's disc and the sac's ring, and none beyond its ends holds anything.
    #[test]
    fn a_straight_vessel_labelled_slice_by_slice() {
        let (n, nz) = (64usize, 30usize);
        let centre = DVec2::new(31.3, 32.6);
        let ramp = |sd: f64, lo: f64, hi: f64| lo + (hi - lo) * (0.5 + 0.5 * sd).clamp(0.0, 1.0);
        let data: Vec<f32> = (0..n * n * nz)
            .map(|k| {
                let p = DVec2::new((k % n) as f64, (k / n % n) as f64);
                let d = p.distance(centre);
                ramp(9.0 - d, ramp(15.0 - d, -100.0, 40.0), 300.0) as f32
            })
            .collect();
        let vol = Volume::hounsfield([n, n, nz], [1.0; 3], data);
        let opt = LumenOptions {
            field_mm: 60.0,
            ..LumenOptions::for_volume(&vol)
        };
        let path = [centre.extend(5.0), centre.extend(24.0)];
        let wall = WallOptions::default();
        let track = Track::along(&vol, &Marcher::new(&vol, None), &path, &opt, &wall).unwrap();
        let labels = label_path(&vol, &path, &opt, Some((&wall, &track))).unwrap();
        assert_eq!((labels.sections, labels.closed), (19, 19));
        // The lumen's edge at 150 HU lies 0.154 mm beyond 9 mm (the ramp), the sac's at −30
        // HU right on 15 mm.
        let r_lumen = 9.0 + 2.0 * (0.5 - (150.0 - 40.0) / (300.0 - 40.0));
        let (disc, ring) = (
            std::f64::consts::PI * r_lumen * r_lumen,
            std::f64::consts::PI * (15.0f64.powi(2) - r_lumen * r_lumen),
        );
        for z in 0..nz {
            let slice = &labels.data[z * n * n..(z + 1) * n * n];
            let count = |l: u8| slice.iter().filter(|&&x| x == l).count() as f64;
            let (lumen, wall) = (count(LUMEN), count(WALL));
            if (5..=24).contains(&z) {
                assert!(
                    (lumen - disc).abs() < 0.03 * disc,
                    "z {z}: {lumen} against {disc}"
                );
                assert!(
                    (wall - ring).abs() < 0.03 * ring,
                    "z {z}: {wall} against {ring}"
                );
            } else {
                assert_eq!((lumen, wall), (0.0, 0.0), "z {z}");
            }
            // Lumen inside, wall about it: by each voxel's distance from the axis.
            for (k, &l) in slice.iter().enumerate() {
                let d = DVec2::new((k % n) as f64, (k / n) as f64).distance(centre);
                match l {
                    LUMEN => assert!(d < r_lumen + 0.8, "z {z}: lumen at {d}"),
                    WALL => assert!(d > r_lumen - 0.8 && d < 15.8, "z {z}: wall at {d}"),
                    _ => {}
                }
            }
        }
        // Without a wall, the lumen alone, the same.
        let plain = label_path(&vol, &path, &opt, None).unwrap();
        assert_eq!(plain.count(WALL), 0);
        assert_eq!(plain.count(LUMEN), labels.count(LUMEN));
    }

    #[test]
    fn inside_a_polygon() {
        let square = [
            DVec2::new(-1.0, -1.0),
            DVec2::new(1.0, -1.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(-1.0, 1.0),
        ];
        assert!(inside(&square, DVec2::new(0.2, -0.7)));
        assert!(!inside(&square, DVec2::new(1.2, 0.0)));
        assert!(!inside(&square, DVec2::new(0.0, -1.5)));
    }
}
