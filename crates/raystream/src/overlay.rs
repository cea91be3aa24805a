//! `render --mode … --draw-path FILE`: a centreline drawn over the picture of a volume, as a
//! vascular workstation shows the path of its curved reformation on the reference view: the
//! path's spline (the one `--path` follows) projected through the frame's camera, a yellow
//! line ringed in black, over whatever the rays saw (it is an overlay, not occluded).
//!
//! A line of one colour is all it draws, so it is drawn here rather than through a vector
//! graphics crate.

use raystream_cpu::cpr::CprRow;
use raystream_cpu::dvr::lps_to_scene;
use raystream_cpu::lumen::Lumen;
use raystream_cpu::wall::Outline;
use raystream_math::{DVec2, DVec3, Vec3};
use raystream_scene::Camera;

/// The line's colour (8-bit sRGB) and its ring's.
const LINE: [u8; 3] = [255, 214, 0];
const RING: [u8; 3] = [0, 0, 0];
/// A lumen's edge.
pub const EDGE: [u8; 3] = [0, 230, 255];
/// A vessel's outer wall.
pub const WALL: [u8; 3] = [255, 64, 220];

/// Where the LPS point `p` falls in a `width`×`height` frame of `cam` (scene frame), in pixel
/// coordinates (the top-left corner at 0, 0), as `Camera::ray` casts pixels; `None` behind a
/// perspective eye.
pub fn project(cam: &Camera, p: DVec3, width: u32, height: u32) -> Option<(f32, f32)> {
    let q = lps_to_scene(p.as_vec3()) - cam.eye;
    let (w, h) = (width as f32, height as f32);
    let aspect = w / h;
    let (x, y) = if cam.parallel > 0.0 {
        (
            q.dot(cam.right) / (cam.parallel * aspect),
            q.dot(cam.up) / cam.parallel,
        )
    } else {
        let z = q.dot(cam.fwd);
        if z <= 0.0 {
            return None;
        }
        (
            q.dot(cam.right) / (z * cam.tan_y * aspect),
            q.dot(cam.up) / (z * cam.tan_y),
        )
    };
    Some(((x + 1.0) * 0.5 * w, (1.0 - y) * 0.5 * h))
}

/// Draws the polyline `dense` (LPS mm, the spline's samples) seen by `cam` into the 8-bit RGB
/// `rgb`: about a pixel per 256 rows wide (at least one), ringed by a pixel of black.
pub fn draw_path(rgb: &mut [u8], width: u32, height: u32, cam: &Camera, dense: &[DVec3]) {
    let pts: Vec<Option<(f32, f32)>> = dense
        .iter()
        .map(|&p| project(cam, p, width, height))
        .collect();
    draw_polyline(rgb, width, height, &pts);
}

/// Marks `rows` (fractional, as [`raystream_cpu::cpr::CurvedPlane::picture_at`] gives them)
/// of a `width`×`height` curved reformation: a line across the picture at each, as
/// [`draw_path`] draws a line.
pub fn draw_row_marks(rgb: &mut [u8], width: u32, height: u32, rows: &[f32]) {
    for &y in rows {
        let ends = [Some((0.0, y)), Some((width as f32 - 0.5, y))];
        draw_polyline(rgb, width, height, &ends);
    }
}

/// Draws the polyline through `pts` (pixel coordinates; a `None` breaks it) into the 8-bit
/// RGB `rgb`: about a pixel per 256 rows wide (at least one), ringed by a pixel of black.
fn draw_polyline(rgb: &mut [u8], width: u32, height: u32, pts: &[Option<(f32, f32)>]) {
    let half = (height / 512) as i64;
    // The ring first, under the whole line, then the line.
    for (colour, grow) in [(RING, 1), (LINE, 0)] {
        let r = half + grow;
        let mut put = |x: f32, y: f32| {
            let (cx, cy) = (x.floor() as i64, y.floor() as i64);
            for py in cy - r..=cy + r {
                for px in cx - r..=cx + r {
                    if px >= 0 && py >= 0 && px < width as i64 && py < height as i64 {
                        let i = 3 * (py as usize * width as usize + px as usize);
                        rgb[i..i + 3].copy_from_slice(&colour);
                    }
                }
            }
        };
        for w in pts.windows(2) {
            let (Some(a), Some(b)) = (w[0], w[1]) else {
                continue;
            };
            // Half-pixel steps along the segment (clipped to a frame's reach: a point far
            // outside the picture draws nothing, however far).
            let (a, b) = (Vec3::new(a.0, a.1, 0.0), Vec3::new(b.0, b.1, 0.0));
            let steps = ((b - a).length() * 2.0)
                .ceil()
                .min(4.0 * (width + height) as f32);
            let n = steps.max(1.0) as u32;
            for k in 0..=n {
                let p = a.lerp(b, k as f32 / n as f32);
                put(p.x, p.y);
            }
        }
    }
}

/// Draws a cross-section's lumen (`measure_section`'s, on the plane of `row` seen by `cam`)
/// into the 8-bit RGB `rgb`: its edge points in cyan, a pixel each, then its largest diameter
/// as [`draw_path`] draws a line.
pub fn draw_lumen(
    rgb: &mut [u8],
    (width, height): (u32, u32),
    cam: &Camera,
    row: &CprRow,
    (lumen, edge): (&Lumen, &[DVec2]),
) {
    for &q in edge {
        let Some((x, y)) = project(cam, row.point(q), width, height) else {
            continue;
        };
        let (px, py) = (x.floor() as i64, y.floor() as i64);
        if px >= 0 && py >= 0 && px < width as i64 && py < height as i64 {
            let i = 3 * (py as usize * width as usize + px as usize);
            rgb[i..i + 3].copy_from_slice(&EDGE);
        }
    }
    draw_path(rgb, width, height, cam, &lumen.max_ends);
}

/// Draws a cross-section's outer wall (`measure --wall`'s outline on the plane of `row` seen by
/// `cam`) into the 8-bit RGB `rgb`: a magenta line a pixel wide between its points, solid where
/// the wall's edge was seen and dotted (every other pixel) where the fitted circle stands in
/// for it.
pub fn draw_wall(
    rgb: &mut [u8],
    (width, height): (u32, u32),
    cam: &Camera,
    row: &CprRow,
    outline: &Outline,
) {
    let at: Vec<Option<(f32, f32)>> = outline
        .points
        .iter()
        .map(|&q| project(cam, row.point(q), width, height))
        .collect();
    let n = at.len();
    let mut dot = 0u32;
    for k in 0..n {
        let (Some(a), Some(b)) = (at[k], at[(k + 1) % n]) else {
            continue;
        };
        let seen = outline.seen[k] && outline.seen[(k + 1) % n];
        let steps =
            ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as u32).clamp(1, 4 * (width + height));
        for s in 0..steps {
            let t = s as f32 / steps as f32;
            let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            let (px, py) = (x.floor() as i64, y.floor() as i64);
            dot += 1;
            if (seen || dot.is_multiple_of(2))
                && px >= 0
                && py >= 0
                && px < width as i64
                && py < height as i64
            {
                let i = 3 * (py as usize * width as usize + px as usize);
                rgb[i..i + 3].copy_from_slice(&WALL);
            }
        }
    }
}

/// Draws edges on each row of a `width`×`height` curved reformation of pixels `pixel_mm`
/// square: `edges[y]`, mm along row y from its middle (right positive), a pixel of `colour`
/// each (the lumen's [`EDGE`], the outer wall's [`WALL`]); whether any was drawn.
pub fn draw_row_edges(
    rgb: &mut [u8],
    (width, height): (u32, u32),
    pixel_mm: f64,
    edges: &[Option<[f64; 2]>],
    colour: [u8; 3],
) -> bool {
    let mut drawn = false;
    for (y, e) in edges.iter().enumerate().take(height as usize) {
        for u in e.iter().flatten() {
            let x = (0.5 * width as f64 + u / pixel_mm).floor();
            if (0.0..width as f64).contains(&x) {
                let i = 3 * (y * width as usize + x as usize);
                rgb[i..i + 3].copy_from_slice(&colour);
                drawn = true;
            }
        }
    }
    drawn
}

/// The colours `--segmentation` tints labels 1, 2, … with (then round again).
pub const LABEL_COLOURS: [[u8; 3]; 6] = [
    EDGE,
    WALL,
    LINE,
    [80, 220, 80],
    [255, 140, 0],
    [60, 120, 255],
];
/// How much of a tinted pixel is its label's colour.
pub const LABEL_ALPHA: f32 = 0.45;

/// `colour` over the pixel `base`: [`LABEL_ALPHA`] of it, rounded.
pub fn tint(base: [u8; 3], colour: [u8; 3]) -> [u8; 3] {
    std::array::from_fn(|i| {
        (base[i] as f32 * (1.0 - LABEL_ALPHA) + colour[i] as f32 * LABEL_ALPHA).round() as u8
    })
}

/// The colour `--segmentation` shows label `label` in when its segmentation gives none.
pub fn label_colour(label: u32) -> [u8; 3] {
    LABEL_COLOURS[(label as usize).saturating_sub(1) % LABEL_COLOURS.len()]
}

/// Label `l`'s colour among `known` segments: its own, else [`label_colour`]'s.
pub fn segment_colour(known: &[raystream_io::SegmentLabel], l: u32) -> [u8; 3] {
    known
        .iter()
        .find(|k| k.number as u32 == l)
        .and_then(|k| k.colour)
        .unwrap_or_else(|| label_colour(l))
}

/// A segmentation laid over pictures (`render --segmentation`): its label volume, the colour
/// of each label that has one of its own (a Segmentation's, a structure set's, a colour
/// table's), and a structure set's structures each whole (they overlap, and the label volume
/// holds the smallest where they do), the largest first.
pub struct SegmentOverlay {
    pub labels: raystream_io::Volume,
    pub colours: std::collections::BTreeMap<u32, [u8; 3]>,
    pub structures: Vec<(u32, raystream_io::SegmentVoxels)>,
    /// Each segment's edge drawn in its colour, not its inside tinted.
    pub outline: bool,
    /// The segments present, named (`--legend`).
    pub legend: Vec<crate::legend::Entry>,
    /// Only the points whose CT voxel is below this value are in a segment (`--below`).
    pub below: Option<f64>,
}

impl SegmentOverlay {
    /// Label `l`'s colour: its own, else [`label_colour`]'s.
    pub fn colour(&self, l: u32) -> [u8; 3] {
        self.colours
            .get(&l)
            .copied()
            .unwrap_or_else(|| label_colour(l))
    }
}

/// Lays `overlay` over the picture, `width` pixels a row, each pixel taking the segment of the
/// voxel nearest its point in the patient (`point(x, y)`, LPS mm; the label volume's grid):
/// - tinted: a pixel in a segment is [`LABEL_ALPHA`] its colour (the label volume's label,
///   the smallest structure where a structure set's overlap);
/// - outlined: a pixel of a segment beside one that is not of it (of the four beside it, or
///   the picture's edge) is its colour, each segment on its own, the larger first.
pub fn tint_labels(
    rgb: &mut [u8],
    width: u32,
    overlay: &SegmentOverlay,
    ct: &raystream_io::Volume,
    point: impl Fn(u32, u32) -> DVec3 + Sync,
) {
    use rayon::prelude::*;
    let labels = &overlay.labels;
    let (w, h) = (width as usize, rgb.len() / (3 * width as usize).max(1));
    let points: Vec<DVec3> = (0..w * h)
        .into_par_iter()
        .map(|n| point((n % w) as u32, (n / w) as u32))
        .collect();
    let mut voxel = nearest_voxels(labels, &points);
    // --below: a pixel whose CT voxel is not below the value is in no segment.
    if let Some(hu) = overlay.below {
        let of_ct = nearest_voxels(ct, &points);
        for (q, c) in voxel.iter_mut().zip(of_ct) {
            let low = c.is_some_and(|[i, j, k]| (ct.at(i, j, k) as f64) < hu);
            if !low {
                *q = None;
            }
        }
    }
    let label_at = |q: &Option<[usize; 3]>| {
        q.map(|[i, j, k]| labels.at(i, j, k))
            .filter(|&v| v >= 0.5)
            .map(|v| v.round() as u32)
    };
    if !overlay.outline {
        rgb.par_chunks_mut(3).zip(&voxel).for_each(|(px, q)| {
            if let Some(l) = label_at(q) {
                px.copy_from_slice(&tint([px[0], px[1], px[2]], overlay.colour(l)));
            }
        });
        return;
    }
    // Each segment's pixels: a structure set's structures whole, else each label's.
    let segments: Vec<(u32, Vec<bool>)> = if overlay.structures.is_empty() {
        let seen: Vec<Option<u32>> = voxel.iter().map(label_at).collect();
        let mut counts: std::collections::BTreeMap<u32, usize> = Default::default();
        for &l in seen.iter().flatten() {
            *counts.entry(l).or_default() += 1;
        }
        let mut present: Vec<(u32, usize)> = counts.into_iter().collect();
        present.sort_by_key(|&(l, n)| (std::cmp::Reverse(n), l));
        present
            .into_iter()
            .map(|(l, _)| (l, seen.iter().map(|&s| s == Some(l)).collect()))
            .collect()
    } else {
        overlay
            .structures
            .iter()
            .map(|(l, r)| {
                (
                    *l,
                    voxel
                        .iter()
                        .map(|q| q.is_some_and(|q| r.holds(q)))
                        .collect(),
                )
            })
            .collect()
    };
    for (l, held) in segments {
        let colour = overlay.colour(l);
        for (n, _) in held.iter().enumerate().filter(|(_, h)| **h) {
            let (x, y) = (n % w, n / w);
            let edge = x == 0
                || y == 0
                || x + 1 == w
                || y + 1 == h
                || !held[n - 1]
                || !held[n + 1]
                || !held[n - w]
                || !held[n + w];
            if edge {
                rgb[3 * n..3 * n + 3].copy_from_slice(&colour);
            }
        }
    }
}

/// Per voxel of `labels`: whether the voxel of `ct` nearest its centre is below `hu` (`--below`).
pub fn below_in(labels: &raystream_io::Volume, ct: &raystream_io::Volume, hu: f64) -> Vec<bool> {
    use crate::segments::nearest_voxel;
    use rayon::prelude::*;
    let to_ct = ct.index_to_world_affine().inverse() * labels.index_to_world_affine();
    let [nx, ny, _] = labels.dims;
    (0..labels.data.len())
        .into_par_iter()
        .map(|n| {
            let ijk = DVec3::new(
                (n % nx) as f64,
                (n / nx % ny) as f64,
                (n / (nx * ny)) as f64,
            );
            let c = nearest_voxel(&to_ct, ct.dims, ijk);
            c.is_some_and(|[i, j, k]| (ct.at(i, j, k) as f64) < hu)
        })
        .collect()
}

/// The voxel of `v` nearest each of `points` (LPS mm); `None` outside its grid.
fn nearest_voxels(v: &raystream_io::Volume, points: &[DVec3]) -> Vec<Option<[usize; 3]>> {
    use rayon::prelude::*;
    let to_index = v.index_to_world_affine().inverse();
    (points.par_iter())
        .map(|&p| crate::segments::nearest_voxel(&to_index, v.dims, p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn below_tints_only_the_pixels_whose_ct_voxel_is_below() {
        // A 4 × 3 × 2 CT of 1 mm voxels, values -1000 + 100·n; labels 1 on the first slice's
        // left half, 2 on its right half, none on the second slice; a pixel a voxel of the
        // first slice (the point its centre).
        let ct = raystream_io::Volume::hounsfield(
            [4, 3, 2],
            [1.0; 3],
            (0..24).map(|n| -1000.0 + 100.0 * n as f32).collect(),
        );
        let labels = raystream_io::Volume::hounsfield(
            [4, 3, 2],
            [1.0; 3],
            (0..24)
                .map(|n| match (n % 4, n < 12) {
                    (_, false) => 0.0,
                    (0 | 1, true) => 1.0,
                    _ => 2.0,
                })
                .collect(),
        );
        let overlay = |below| SegmentOverlay {
            labels: labels.clone(),
            colours: Default::default(),
            structures: Vec::new(),
            outline: false,
            legend: Vec::new(),
            below,
        };
        let grey = [100u8; 3];
        let point = |x: u32, y: u32| DVec3::new(x as f64, y as f64, 0.0);
        for (below, want) in [
            (None, 12),
            // Below -650: voxels 0..=3 (-1000 to -700), strictly.
            (Some(-650.0), 4),
            (Some(-700.0), 3),
            (Some(-5000.0), 0),
        ] {
            let mut rgb = [grey; 12].concat();
            tint_labels(&mut rgb, 4, &overlay(below), &ct, point);
            let tinted: Vec<usize> = (0..12).filter(|&n| rgb[3 * n..3 * n + 3] != grey).collect();
            assert_eq!(tinted.len(), want, "{below:?}");
            assert!(tinted.iter().all(|&n| n < want), "{below:?}: {tinted:?}");
            for &n in &tinted {
                let l = if n % 4 < 2 { 1 } else { 2 };
                assert_eq!(rgb[3 * n..3 * n + 3], tint(grey, label_colour(l)));
            }
        }
        // The legend's segments: of voxels whose CT voxel is below. A label grid of 2 mm
        // voxels from (0.4, 0.4, 0.4): its centres fall nearest CT voxels (0, 0, 0), (2, 0, 0),
        // (0, 2, 0) and (2, 2, 0) (values -1000, -800, -200, 0), and past the CT's last slice.
        let coarse = raystream_io::Volume {
            origin: [0.4; 3],
            ..raystream_io::Volume::hounsfield([2, 2, 2], [2.0; 3], vec![1.0; 8])
        };
        let low = below_in(&coarse, &ct, -500.0);
        assert_eq!(low, [true, true, false, false, false, false, false, false]);
    }

    #[test]
    fn points_project_where_the_camera_casts_their_pixels() {
        // Each pixel centre's ray passes through the point that projects to it.
        for cam in [
            Camera::look_at(Vec3::new(1.0, 2.0, 9.0), Vec3::ZERO, Vec3::Y, 50.0),
            Camera {
                parallel: 3.0,
                ..Camera::look_at(Vec3::new(-4.0, 1.0, 5.0), Vec3::ZERO, Vec3::Y, 60.0)
            },
        ] {
            for (x, y) in [(0.5, 0.5), (31.5, 12.5), (63.5, 47.5)] {
                let r = cam.ray(x, y, 64, 48);
                let p = r.origin + r.dir * 3.0;
                let lps = raystream_cpu::dvr::scene_to_lps(p).as_dvec3();
                let (px, py) = project(&cam, lps, 64, 48).unwrap();
                assert!(
                    (px - x).abs() < 1e-3 && (py - y).abs() < 1e-3,
                    "({x}, {y}): ({px}, {py})"
                );
            }
        }
    }

    #[test]
    fn a_line_is_drawn_ringed_and_nothing_beyond_the_frame() {
        let cam = Camera {
            parallel: 1.0,
            ..Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, Vec3::Y, 60.0)
        };
        // Scene y is LPS superior (z): a vertical line through the middle of a 33×33 frame.
        let line = [
            DVec3::new(0.0, 0.0, -0.5),
            DVec3::new(0.0, 0.0, 0.5),
            DVec3::new(0.0, 0.0, 1e9),
        ];
        let mut rgb = vec![100u8; 33 * 33 * 3];
        draw_path(&mut rgb, 33, 33, &cam, &line);
        let at = |x: usize, y: usize| {
            [
                rgb[3 * (y * 33 + x)],
                rgb[3 * (y * 33 + x) + 1],
                rgb[3 * (y * 33 + x) + 2],
            ]
        };
        assert_eq!(at(16, 16), LINE);
        assert_eq!(at(15, 16), RING);
        assert_eq!(at(17, 16), RING);
        assert_eq!(at(14, 16), [100; 3]);
        assert_eq!(at(16, 10), LINE);
        // Beyond the line's end (row 8.25) only the far point's segment starts, and stops.
        assert_eq!(at(16, 4), [100; 3]);
        assert_eq!(at(5, 5), [100; 3]);
    }
}
