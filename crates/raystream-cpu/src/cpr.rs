//! Curved planar reformation (CPR): a vessel, the spine or a dental arch straightened into one
//! picture, as radiology workstations show a centreline. The path's points (LPS mm) are joined
//! by a centripetal Catmull–Rom spline (Yuksel et al. 2011: no cusps or loops between close
//! points), which is then resampled by arc length: image row `y` is the spline's point at arc
//! length (y + ½)·p from the first point (p = length / rows, so the whole path fills the
//! image's height), and the row's pixels lie on the line through it along the row's lateral
//! direction, p apart, the path in the middle column: the *straightened* CPR, whose rows and
//! columns are both millimetre-true.
//!
//! The lateral direction starts as the view's image-right made perpendicular to the path (an
//! anterior view of a vessel running head to foot cuts it coronally; a view from the left,
//! sagittally), turned about the path as `--orbit` turns a camera about the image's up axis,
//! and is carried along the path by parallel transport (the double-reflection rotation
//! minimising frame, Wang et al. 2008), so that the cut does not twist where the path bends.
//! Each pixel's ray runs along the row's normal (lateral × tangent, away from the viewer)
//! through a slab about the curved surface: the thin CPR samples the surface itself, a slab a
//! curved slab MIP, MinIP or average.
//!
//! The *stretched* CPR (Kanitsar et al. 2002, [`CurvedPlane::stretched`]) keeps one direction
//! fixed instead, the vector of interest: every row's pixels step along it, and the rows are
//! spaced by the path's run across it, its run along it shifting the row, so the path is a
//! curve in the picture as long as itself and what lies about it keeps its shape.

use raystream_math::{DVec2, DVec3, Vec3};
use raystream_scene::Camera;

/// One image row of a curved plane (LPS, f32 as the renderers read it): the path's point, the
/// unit direction the row's pixels step along, and the unit normal its rays run along.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CprRow {
    pub centre: Vec3,
    pub lateral: Vec3,
    pub normal: Vec3,
}

impl CprRow {
    /// The point of the row's plane at offset `q` from its centre (mm along the lateral
    /// direction and the normal: right and down on a cross-section), LPS, in f64.
    pub fn point(&self, q: DVec2) -> DVec3 {
        self.centre.as_dvec3() + q.x * self.lateral.as_dvec3() + q.y * self.normal.as_dvec3()
    }

    /// The plane's vector `q` (lateral and normal parts) in LPS.
    pub fn direction(&self, q: DVec2) -> DVec3 {
        q.x * self.lateral.as_dvec3() + q.y * self.normal.as_dvec3()
    }

    /// The offset from the centre of `p`'s projection on the plane: [`CprRow::point`]'s
    /// inverse on it.
    pub fn offset_of(&self, p: DVec3) -> DVec2 {
        let v = p - self.centre.as_dvec3();
        DVec2::new(
            v.dot(self.lateral.as_dvec3()),
            v.dot(self.normal.as_dvec3()),
        )
    }
}

/// A curved plane through a volume, straightened or stretched, ready to be sampled row by
/// row.
#[derive(Clone, Debug)]
pub struct CurvedPlane {
    pub width: u32,
    pub height: u32,
    /// The pixels' side, mm: the path's length over the image's height (stretched: its length
    /// across the vector of interest).
    pub pixel_mm: f32,
    /// The spline's length, mm.
    pub length_mm: f64,
    /// The path's points after consecutive repeats are dropped.
    pub points: usize,
    /// `height` rows, the path's first point at the top.
    pub rows: Vec<CprRow>,
    /// Where the path crosses each row: `shift_mm[y]` mm along the row's lateral direction
    /// from its centre (all 0 when straightened: the path is the middle column).
    pub shift_mm: Vec<f32>,
    /// The arc length of the path's point on each row, mm from its first point (increasing).
    pub arc_mm: Vec<f64>,
    /// Stretched along this vector of interest (LPS, unit), or straightened.
    pub stretched: Option<DVec3>,
}

/// Where cross-sections of a path lie: `step_mm` apart (default: the path's length over their
/// count) about `centre_mm` along it (default: its middle).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spacing {
    pub step_mm: Option<f64>,
    pub centre_mm: Option<f64>,
}

/// Cross-sections are perpendicular to the chord this long, mm, about their point: the
/// spline's own direction there (between the dense samples' quarter millimetre and the bends
/// of a vessel).
pub const SECTION_CHORD_MM: f64 = 0.5;

/// Spline pieces are sampled about this finely for their arc length, mm (the chord of a
/// quarter millimetre strays from a 5 mm-radius bend by 1.6 µm).
const ARC_STEP_MM: f64 = 0.25;

/// The most dense samples of the spline (beyond this budget every piece gets the fewest).
const MAX_ARC_SAMPLES: usize = 1 << 22;

impl CurvedPlane {
    /// The curved plane along `points` (LPS mm, at least two apart) for a `width`×`height`
    /// image: its lateral direction from `image_right` (LPS) made perpendicular to the path at
    /// its start, turned `turn_deg` about the image's up axis there (the path's backward
    /// direction, right-handed: +90 shows what lay on the image's right… from there, as
    /// `--orbit` turns a camera).
    pub fn new(
        points: &[DVec3],
        image_right: DVec3,
        turn_deg: f64,
        width: u32,
        height: u32,
    ) -> Result<CurvedPlane, String> {
        Self::with_chord(points, image_right, turn_deg, (width, height), None)
    }

    /// The frames of `n` cross-sections of the path at the middle of `n` equal parts of it,
    /// as rows of a curved plane one pixel wide (so [`CurvedPlane::section_camera`] frames
    /// them), each perpendicular to the spline's own direction at its point (a chord of
    /// [`SECTION_CHORD_MM`] about it, however far apart they are).
    pub fn sections(
        points: &[DVec3],
        image_right: DVec3,
        turn_deg: f64,
        n: u32,
    ) -> Result<CurvedPlane, String> {
        Self::sections_spaced(points, image_right, turn_deg, n, Spacing::default())
    }

    /// [`CurvedPlane::sections`], spaced as `spacing` says (by default the middles of `n`
    /// equal parts): an error if they reach beyond the path's ends. The plane's `pixel_mm`
    /// is their spacing.
    pub fn sections_spaced(
        points: &[DVec3],
        image_right: DVec3,
        turn_deg: f64,
        n: u32,
        spacing: Spacing,
    ) -> Result<CurvedPlane, String> {
        Self::with_chord(
            points,
            image_right,
            turn_deg,
            (1, n),
            Some((SECTION_CHORD_MM, spacing)),
        )
    }

    /// A curved plane whose rows lie a row's height apart along the path about its middle,
    /// and whose tangents are chords a row's height long; or, with `sections` (a chord's
    /// length and a spacing), cross-sections' frames, their tangents chords that long.
    fn with_chord(
        points: &[DVec3],
        image_right: DVec3,
        turn_deg: f64,
        (width, height): (u32, u32),
        sections: Option<(f64, Spacing)>,
    ) -> Result<CurvedPlane, String> {
        let spline = Spline::new(points)?;
        if width == 0 || height == 0 {
            return Err("an empty image".into());
        }
        let length = spline.length();
        let spacing = sections.map(|s| s.1).unwrap_or_default();
        let pixel = match spacing.step_mm {
            Some(step) if !(step.is_finite() && step > 0.0) => {
                return Err(format!(
                    "cross-sections {step} mm apart: the spacing must be a positive number"
                ));
            }
            Some(step) => step,
            None => length / height as f64,
        };
        let span = pixel * (height - 1) as f64;
        let centre = spacing.centre_mm.unwrap_or(0.5 * length);
        // The rows about `centre`: (y + ½)·p when they fill the path.
        let first = centre - 0.5 * span;
        if !(first >= -1e-6 && first + span <= length + 1e-6) {
            let about = match spacing.centre_mm {
                Some(c) => format!("about {c} mm along it"),
                None => "about its middle".into(),
            };
            return Err(format!(
                "{height} cross-sections {pixel:.2} mm apart {about} run from {first:.1} to {:.1} mm: beyond the path's 0 to {length:.1} mm",
                first + span
            ));
        }
        let arcs: Vec<f64> = (0..height).map(|y| first + y as f64 * pixel).collect();
        let e = 0.5 * sections.map_or(pixel, |s| s.0);
        let rows = spline.frames(&arcs, e, image_right, turn_deg);
        Ok(CurvedPlane {
            width,
            height,
            pixel_mm: pixel as f32,
            length_mm: length,
            points: spline.points,
            shift_mm: vec![0.0; rows.len()],
            arc_mm: arcs,
            rows,
            stretched: None,
        })
    }

    /// The *stretched* CPR along `points` (Kanitsar et al. 2002) for a `width`×`height` image:
    /// the surface swept by the lines along `interest` (the vector of interest, LPS; the
    /// view's image-right) through the path, unrolled so that the path keeps its length. Row
    /// `y` is where the path has run (y + ½)·p across `interest` from its first point (its
    /// run along `interest` is the row's shift instead), p being that run across over the
    /// rows; its pixels lie p apart along `interest`, the middle of the image at the middle
    /// of the path's run along it, so the path is drawn as a curve whose length in the image
    /// is its length in the patient, and where it lies in a plane that holds `interest`, the
    /// picture is that plane's slice. Each ray runs along `interest` × the path's tangent.
    /// A path that runs along `interest` has no such surface: an error.
    pub fn stretched(
        points: &[DVec3],
        interest: DVec3,
        width: u32,
        height: u32,
    ) -> Result<CurvedPlane, String> {
        let spline = Spline::new(points)?;
        if width == 0 || height == 0 {
            return Err("an empty image".into());
        }
        let v = interest.normalize_or_zero();
        if v == DVec3::ZERO || !v.is_finite() {
            return Err(format!("a vector of interest {interest}: not a direction"));
        }
        let d = &spline.dense;
        // Per dense sample, the run across `v` (down the image) and along it (across).
        let mut down = Vec::with_capacity(d.len());
        down.push(0.0);
        for w in d.windows(2) {
            let step = w[1] - w[0];
            down.push(down.last().unwrap() + step.reject_from_normalized(v).length());
        }
        let total = *down.last().unwrap();
        let length = spline.length();
        if total.is_nan() || total <= 1e-3 * length {
            return Err(format!(
                "a path {length:.1} mm long that runs {total:.2} mm across the vector of interest ({:.3}, {:.3}, {:.3} LPS, the view's right): a stretched CPR unrolls the path across it; face the view across the path, or straighten it",
                v.x, v.y, v.z
            ));
        }
        let pixel = total / height as f64;
        // The middle of the path's run along `v`.
        let (lo, hi) = d
            .iter()
            .map(|&q| v.dot(q - d[0]))
            .fold((f64::MAX, f64::MIN), |(lo, hi), a| (lo.min(a), hi.max(a)));
        let middle = 0.5 * (lo + hi);
        // Tangents are chords a row's height long, as straightened.
        let e = 0.5 * pixel;
        let mut rows = Vec::with_capacity(height as usize);
        let mut shift_mm = Vec::with_capacity(height as usize);
        let mut arc_mm = Vec::with_capacity(height as usize);
        let mut last_normal = v.any_orthonormal_vector();
        for y in 0..height {
            let target = (y as f64 + 0.5) * pixel;
            // The dense piece that runs across `v` through the row.
            let k = down.partition_point(|&h| h < target).clamp(1, d.len() - 1);
            let (h0, h1) = (down[k - 1], down[k]);
            let f = if h1 > h0 {
                ((target - h0) / (h1 - h0)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let point = d[k - 1].lerp(d[k], f);
            let arc = spline.arc[k - 1] + f * (spline.arc[k] - spline.arc[k - 1]);
            let tangent = spline.at((arc + e).min(length)) - spline.at((arc - e).max(0.0));
            // Where the path runs along `v` here, the last row's normal.
            let normal = v.cross(tangent).normalize_or(last_normal);
            last_normal = normal;
            let shift = v.dot(point - d[0]) - middle;
            rows.push(CprRow {
                centre: (point - shift * v).as_vec3(),
                lateral: v.as_vec3(),
                normal: normal.as_vec3(),
            });
            shift_mm.push(shift as f32);
            arc_mm.push(arc);
        }
        Ok(CurvedPlane {
            width,
            height,
            pixel_mm: pixel as f32,
            length_mm: length,
            points: spline.points,
            rows,
            shift_mm,
            arc_mm,
            stretched: Some(v),
        })
    }

    /// Where the path is at arc length `s` (mm from its first point) in the picture: the
    /// fractional row (row y's centre at y + ½) and column, between the two rows whose points
    /// hold it (beyond the first or last, along those two rows' line); none off the picture.
    pub fn picture_at(&self, s: f64) -> Option<(f32, f32)> {
        let a = &self.arc_mm;
        let n = a.len();
        if n < 2 || !s.is_finite() {
            return None;
        }
        let k = a.partition_point(|&x| x <= s).clamp(1, n - 1);
        let gap = a[k] - a[k - 1];
        let f = if gap > 0.0 { (s - a[k - 1]) / gap } else { 0.0 };
        let row = (k - 1) as f64 + f + 0.5;
        if !(0.0..=self.height as f64).contains(&row) {
            return None;
        }
        let (s0, s1) = (self.shift_mm[k - 1] as f64, self.shift_mm[k] as f64);
        let column = 0.5 * self.width as f64 + (s0 + f * (s1 - s0)) / self.pixel_mm as f64;
        Some((row as f32, column as f32))
    }

    /// The path's point on row `y` (LPS).
    pub fn path_point(&self, y: u32) -> Vec3 {
        let r = &self.rows[y as usize];
        r.centre + self.shift_mm[y as usize] * r.lateral
    }

    /// The cross-section of the path at row `y`: a parallel camera (the scene frame of
    /// `dvr::volume_camera`) whose slice plane is perpendicular to the path there, centred on
    /// it, `half_height_mm` high on either side, looking back along the path (for a path run
    /// from head to foot, from below, as axial images are shown), the row's lateral direction
    /// to the image's right, from `reach_mm` before the plane.
    pub fn section_camera(&self, y: u32, half_height_mm: f32, reach_mm: f32) -> Camera {
        let r = &self.rows[y as usize];
        let tangent = r.normal.cross(r.lateral).normalize();
        let (fwd, right) = (-tangent, r.lateral);
        let scene = crate::dvr::lps_to_scene;
        Camera {
            eye: scene(r.centre + tangent * reach_mm),
            fwd: scene(fwd),
            right: scene(right),
            up: scene(right.cross(fwd)),
            tan_y: 0.0,
            parallel: half_height_mm,
        }
    }

    /// A fly-through's camera at row `y` (a virtual endoscopy's, `render --fly N`): at the
    /// path's point there, looking ahead along the path (the direction from its first point to
    /// its last), a perspective of `fov_deg` vertically (the scene frame of
    /// `dvr::volume_camera`); the image's up is the row's "up" (against its normal: a
    /// cross-section's up), which turns with the path without twisting about it, and its
    /// right the other side of [`Self::section_camera`]'s, which looks back.
    pub fn ahead_camera(&self, y: u32, fov_deg: f32) -> Camera {
        let r = &self.rows[y as usize];
        let tangent = r.normal.cross(r.lateral).normalize();
        let (fwd, right) = (tangent, -r.lateral);
        let scene = crate::dvr::lps_to_scene;
        Camera {
            eye: scene(self.path_point(y)),
            fwd: scene(fwd),
            right: scene(right),
            up: scene(right.cross(fwd)),
            tan_y: (0.5 * fov_deg.to_radians()).tan(),
            parallel: 0.0,
        }
    }

    /// How many rows' path points lie inside `vol`'s grid of voxel centres (none: the path
    /// misses the volume, as a path in the wrong coordinates does).
    pub fn rows_inside(&self, vol: &raystream_io::Volume) -> usize {
        let hi = vol.dims.map(|n| n.max(1) as f64 - 1.0);
        (0..self.height)
            .filter(|&y| {
                let q = vol.world_to_index(self.path_point(y).as_dvec3());
                (0..3).all(|a| (-1e-6..=hi[a] + 1e-6).contains(&q[a]))
            })
            .count()
    }

    /// Pixel (`x`, `y`)'s point on the curved surface and the unit normal its ray runs along
    /// (LPS), in f32 as the GPU computes it.
    pub fn point(&self, x: u32, y: u32) -> (Vec3, Vec3) {
        let r = &self.rows[y as usize];
        let off = (x as f32 + 0.5) - 0.5 * self.width as f32;
        (r.centre + off * self.pixel_mm * r.lateral, r.normal)
    }
}

/// The spline through `points` (LPS mm, repeats dropped) sampled densely, as a curved plane
/// follows it: for drawing the path over a picture. Fewer than two distinct points: them.
pub fn spline(points: &[DVec3]) -> Vec<DVec3> {
    let p = distinct(points);
    if p.len() < 2 {
        return p;
    }
    arc_samples(&p).0
}

/// How a path winds (Bullitt et al. 2003, "Measuring tortuosity of the intracerebral
/// vasculature from MRA images"): its spline's length, the distance between its ends, their
/// ratio (the distance metric: 1 for a straight path; none for a closed one), and the angle
/// its direction turns through per centimetre (the curvature part of their sum-of-angles
/// metric: 0 straight, 57.3°/r for a circle of r cm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tortuosity {
    pub length_mm: f64,
    pub chord_mm: f64,
    pub distance_metric: Option<f64>,
    pub turning_deg_per_cm: f64,
}

/// The tortuosity of the spline through `points` (LPS mm), as a curved plane follows it.
pub fn tortuosity(points: &[DVec3]) -> Result<Tortuosity, String> {
    let spline = Spline::new(points)?;
    let d = &spline.dense;
    let length_mm = spline.length();
    let chord_mm = d[0].distance(d[d.len() - 1]);
    // The dense pieces' turns, zero-length pieces (repeated samples) skipped.
    let steps: Vec<DVec3> = d
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|v| v.length() > 1e-9)
        .collect();
    let turned: f64 = steps
        .windows(2)
        .map(|w| w[0].angle_between(w[1]))
        .filter(|a| a.is_finite())
        .sum();
    Ok(Tortuosity {
        length_mm,
        chord_mm,
        distance_metric: (chord_mm > 1e-6 * length_mm).then(|| length_mm / chord_mm),
        turning_deg_per_cm: turned.to_degrees() / (0.1 * length_mm),
    })
}

/// The angle a path turns through at a point, measured on chords (as a stent-graft plan
/// measures an aortic neck's angulation on the centreline: the neck's axis against the
/// aneurysm's): the chord from the path's point at `arc_mm[0]` to that at `arc_mm[1]`
/// against the chord from there to `arc_mm[2]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathAngle {
    pub arc_mm: [f64; 3],
    /// The path's points there (LPS mm).
    pub points: [DVec3; 3],
    /// The angle between the chords' directions: 0° where the path runs straight on, 90° at
    /// a right-angled bend, 180° where it turns back.
    pub deviation_deg: f64,
}

/// The angle the spline through `points` (LPS mm, as a curved plane follows it) turns through
/// between its points at arc lengths `arc_mm` (increasing, on the path, each point apart from
/// the next).
pub fn path_angle(points: &[DVec3], arc_mm: [f64; 3]) -> Result<PathAngle, String> {
    let spline = Spline::new(points)?;
    let length = spline.length();
    for s in arc_mm {
        if !(s.is_finite() && (0.0..=length).contains(&s)) {
            return Err(format!(
                "an angle's point at {s} mm: not on the path (0 to {length:.1} mm along it)"
            ));
        }
    }
    if !(arc_mm[0] < arc_mm[1] && arc_mm[1] < arc_mm[2]) {
        return Err(format!(
            "an angle's points at {}, {} and {} mm: give them in order along the path, the vertex in the middle",
            arc_mm[0], arc_mm[1], arc_mm[2]
        ));
    }
    let p = arc_mm.map(|s| spline.at(s));
    let (u, v) = (p[1] - p[0], p[2] - p[1]);
    let tiny = 1e-6 * length;
    if u.length() < tiny || v.length() < tiny {
        return Err(format!(
            "an angle's points at {}, {} and {} mm: two of them coincide (the path returns on itself)",
            arc_mm[0], arc_mm[1], arc_mm[2]
        ));
    }
    Ok(PathAngle {
        arc_mm,
        points: p,
        deviation_deg: u.angle_between(v).to_degrees(),
    })
}

/// A path's spline, sampled densely by arc length: where its frames are taken.
#[derive(Clone, Debug)]
struct Spline {
    dense: Vec<DVec3>,
    arc: Vec<f64>,
    /// The path's points after consecutive repeats are dropped.
    points: usize,
}

impl Spline {
    /// The spline through `points` (LPS mm; at least two distinct, a micrometre or more long).
    fn new(points: &[DVec3]) -> Result<Spline, String> {
        let p = distinct(points);
        if p.len() < 2 {
            return Err("a path needs two distinct points".into());
        }
        let (dense, arc) = arc_samples(&p);
        let length = *arc.last().unwrap();
        if length.is_nan() || length < 1e-3 {
            return Err(format!(
                "a path {length:.2e} mm long: shorter than a micrometre"
            ));
        }
        Ok(Spline {
            dense,
            arc,
            points: p.len(),
        })
    }

    /// The spline's length, mm.
    fn length(&self) -> f64 {
        *self.arc.last().unwrap()
    }

    /// The point at arc length `s` (clamped to the ends).
    fn at(&self, s: f64) -> DVec3 {
        position(&self.dense, &self.arc, s)
    }

    /// The frames at arc lengths `arcs` (increasing): each its point, the unit tangent (the
    /// chord from `s − e` to `s + e`, within the ends), and the lateral direction, which starts
    /// as `image_right` made perpendicular to the first tangent, turned `turn_deg` about the
    /// image's up axis there (the path's backward direction, right-handed, as `--orbit` turns
    /// a camera), and is carried from frame to frame by parallel transport; the normal is
    /// lateral × tangent.
    fn frames(&self, arcs: &[f64], e: f64, image_right: DVec3, turn_deg: f64) -> Vec<CprRow> {
        let length = self.length();
        let centres: Vec<DVec3> = arcs.iter().map(|&s| self.at(s)).collect();
        let tangents: Vec<DVec3> = arcs
            .iter()
            .map(|&s| {
                (self.at((s + e).min(length)) - self.at((s - e).max(0.0))).normalize_or_zero()
            })
            .collect();
        let Some(&t0) = tangents.first() else {
            return Vec::new();
        };
        let mut n = image_right.reject_from(t0);
        if n.length() < 1e-6 * image_right.length().max(1e-30) {
            // The path starts along the image's right: any direction across it.
            n = t0.any_orthonormal_vector();
        }
        let n = n.normalize();
        // About the image's up axis at the start, -t0 (rows run down the image).
        let (s, c) = turn_deg.to_radians().sin_cos();
        let up = -t0;
        let mut lateral = n * c + up.cross(n) * s;
        let mut rows = Vec::with_capacity(arcs.len());
        for y in 0..arcs.len() {
            if y > 0 {
                lateral = transport(
                    (centres[y - 1], tangents[y - 1]),
                    (centres[y], tangents[y]),
                    lateral,
                );
            }
            let t = tangents[y];
            let l = lateral.reject_from(t).normalize_or(lateral);
            lateral = l;
            rows.push(CprRow {
                centre: centres[y].as_vec3(),
                lateral: l.as_vec3(),
                normal: l.cross(t).normalize_or_zero().as_vec3(),
            });
        }
        rows
    }
}

/// `points` without consecutive repeats.
fn distinct(points: &[DVec3]) -> Vec<DVec3> {
    let mut p: Vec<DVec3> = Vec::with_capacity(points.len());
    for &q in points {
        if p.last() != Some(&q) {
            p.push(q);
        }
    }
    p
}

/// The centripetal Catmull–Rom spline through `p` (distinct neighbours), sampled densely, and
/// the arc length at each sample. The ends continue straight (phantom points mirrored).
fn arc_samples(p: &[DVec3]) -> (Vec<DVec3>, Vec<f64>) {
    let n = p.len();
    let pt = |i: isize| -> DVec3 {
        if i < 0 {
            2.0 * p[0] - p[1]
        } else if i as usize >= n {
            2.0 * p[n - 1] - p[n - 2]
        } else {
            p[i as usize]
        }
    };
    let pieces = |i: usize| {
        ((p[i + 1] - p[i]).length() / ARC_STEP_MM)
            .ceil()
            .clamp(4.0, 256.0) as usize
    };
    let total: usize = (0..n - 1).map(pieces).sum();
    let budget = total <= MAX_ARC_SAMPLES;
    let mut dense = Vec::with_capacity(total.min(MAX_ARC_SAMPLES) + 1);
    dense.push(p[0]);
    for i in 0..n - 1 {
        let q = [-1isize, 0, 1, 2].map(|k| pt(i as isize + k));
        let m = if budget { pieces(i) } else { 4 };
        for j in 1..=m {
            dense.push(catmull_rom(q, j as f64 / m as f64));
        }
    }
    let mut arc = Vec::with_capacity(dense.len());
    let mut s = 0.0;
    arc.push(0.0);
    for w in dense.windows(2) {
        s += (w[1] - w[0]).length();
        arc.push(s);
    }
    (dense, arc)
}

/// The centripetal Catmull–Rom piece from `q[1]` to `q[2]` at `u` ∈ [0, 1] (Barry and
/// Goldman's pyramid over the knots t_{i+1} = t_i + |q_{i+1} − q_i|^½).
fn catmull_rom(q: [DVec3; 4], u: f64) -> DVec3 {
    let k = |a: DVec3, b: DVec3| (b - a).length().sqrt().max(1e-12);
    let t0 = 0.0;
    let t1 = t0 + k(q[0], q[1]);
    let t2 = t1 + k(q[1], q[2]);
    let t3 = t2 + k(q[2], q[3]);
    let t = t1 + u * (t2 - t1);
    let mix = |a: DVec3, b: DVec3, ta: f64, tb: f64| {
        a * ((tb - t) / (tb - ta)) + b * ((t - ta) / (tb - ta))
    };
    let a1 = mix(q[0], q[1], t0, t1);
    let a2 = mix(q[1], q[2], t1, t2);
    let a3 = mix(q[2], q[3], t2, t3);
    let b1 = mix(a1, a2, t0, t2);
    let b2 = mix(a2, a3, t1, t3);
    mix(b1, b2, t1, t2)
}

/// The dense polyline's point at arc length `s`.
fn position(dense: &[DVec3], arc: &[f64], s: f64) -> DVec3 {
    let i = arc.partition_point(|&a| a <= s).clamp(1, arc.len() - 1);
    let (a, b) = (arc[i - 1], arc[i]);
    let f = if b > a {
        ((s - a) / (b - a)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    dense[i - 1].lerp(dense[i], f)
}

/// `v` carried from the frame at (`r0`, tangent `t0`) to the one at (`r1`, `t1`) by the
/// double reflection of Wang et al. 2008: a reflection in the plane bisecting r0 r1, then one
/// that takes the reflected tangent onto t1.
fn transport((r0, t0): (DVec3, DVec3), (r1, t1): (DVec3, DVec3), v: DVec3) -> DVec3 {
    let reflect = |x: DVec3, n: DVec3| {
        let c = n.dot(n);
        if c < 1e-24 {
            x
        } else {
            x - (2.0 / c) * n.dot(x) * n
        }
    };
    let v1 = r1 - r0;
    let (vl, tl) = (reflect(v, v1), reflect(t0, v1));
    reflect(vl, t1 - tl)
}

#[cfg(test)]
mod tests {
    use raystream_io::Volume;

    use super::*;
    use crate::dvr::{DvrMode, DvrOptions, render_volume};

    /// Points every `step` degrees of a quarter circle of radius `r` in the x–z plane (LPS),
    /// from (r, 0, 0) towards (0, 0, −r): a bend downwards.
    fn arc(r: f64, step: f64) -> Vec<DVec3> {
        let n = (90.0 / step).round() as usize;
        (0..=n)
            .map(|i| {
                let a = (i as f64 * step).to_radians();
                DVec3::new(r * a.cos(), 0.0, -r * a.sin())
            })
            .collect()
    }

    #[test]
    fn a_straight_path_is_a_plane_at_even_steps() {
        let p = [DVec3::new(0.0, 0.0, 50.0), DVec3::new(0.0, 0.0, -50.0)];
        let c = CurvedPlane::new(&p, DVec3::X, 0.0, 40, 100).unwrap();
        assert!((c.length_mm - 100.0).abs() < 1e-9);
        assert!((c.pixel_mm - 1.0).abs() < 1e-6);
        for (y, r) in c.rows.iter().enumerate() {
            let want = Vec3::new(0.0, 0.0, 50.0 - (y as f32 + 0.5));
            assert!((r.centre - want).length() < 1e-4, "{y}: {}", r.centre);
            assert!((r.lateral - Vec3::X).length() < 1e-6);
            // lateral × tangent: x × (−z) = +y (posterior: an anterior view looks back).
            assert!((r.normal - Vec3::Y).length() < 1e-6);
        }
        // The path between the two middle columns, pixels a millimetre apart across it.
        let (a, _) = c.point(20, 10);
        let (b, _) = c.point(21, 10);
        assert!((a - Vec3::new(0.5, 0.0, 39.5)).length() < 1e-4, "{a}");
        assert!((b - a - Vec3::X).length() < 1e-5);
    }

    #[test]
    fn a_path_in_a_plane_holding_the_interest_stretches_into_that_plane() {
        // A quarter circle of 40 mm in the x–z plane, stretched along x: the swept surface is
        // the plane y = 0 itself, so the picture is its slice, rows 0.2 mm apart down z and
        // columns along x about the middle of the path's run (x = 20), and the path crosses
        // each row where the circle does.
        let r = 40.0;
        let c = CurvedPlane::stretched(&arc(r, 10.0), DVec3::X, 51, 200).unwrap();
        assert_eq!(c.stretched, Some(DVec3::X));
        assert!((c.pixel_mm - 0.2).abs() < 1e-6, "{}", c.pixel_mm);
        for y in 0..200 {
            let row = &c.rows[y as usize];
            let z = -(y as f32 + 0.5) * 0.2;
            assert!(
                (row.centre - Vec3::new(20.0, 0.0, z)).length() < 1e-4,
                "{y}: {}",
                row.centre
            );
            assert_eq!(row.lateral, Vec3::X);
            // lateral × tangent: away from an anterior viewer, as straightened.
            assert!(
                (row.normal - Vec3::Y).length() < 1e-3,
                "{y}: {}",
                row.normal
            );
            let p = c.path_point(y).as_dvec3();
            assert!((p.length() - r).abs() < 0.1, "{y}: {p}");
            assert!((p.z - z as f64).abs() < 1e-4);
        }
        // A pixel's point: the plane's, p apart.
        let (a, _) = c.point(0, 0);
        assert!(
            (a - Vec3::new(20.0 - 25.0 * 0.2, 0.0, -0.1)).length() < 1e-4,
            "{a}"
        );
    }

    #[test]
    fn a_path_across_the_interest_stretches_as_it_straightens() {
        // A quarter circle in the y–z plane (bending away from an anterior viewer), stretched
        // along x: nowhere does it run along x, so the stretched CPR is the straightened one.
        let pts: Vec<DVec3> = arc(40.0, 10.0)
            .iter()
            .map(|p| DVec3::new(0.0, p.x, p.z))
            .collect();
        let s = CurvedPlane::stretched(&pts, DVec3::X, 33, 300).unwrap();
        let t = CurvedPlane::new(&pts, DVec3::X, 0.0, 33, 300).unwrap();
        assert!((s.pixel_mm - t.pixel_mm).abs() < 1e-4 * t.pixel_mm);
        for (a, b) in s.rows.iter().zip(&t.rows) {
            assert!((a.centre - b.centre).length() < 1e-3, "{a:?} {b:?}");
            assert!((a.lateral - b.lateral).length() < 1e-5);
            assert!((a.normal - b.normal).length() < 1e-3, "{a:?} {b:?}");
        }
        assert!(s.shift_mm.iter().all(|&x| x.abs() < 1e-5));
        assert!(t.shift_mm.iter().all(|&x| x == 0.0));
    }

    #[test]
    fn a_stretched_path_keeps_its_length_in_the_picture() {
        // A helix about z (radius 10 mm, 30 mm a turn, one and a half turns), stretched along
        // x: the curve the path draws in the picture (its shift across, its row down) is as
        // long as the path, and each row's path point lies on the helix.
        let pts: Vec<DVec3> = (0..=54)
            .map(|i| {
                let a = (i as f64 * 10.0).to_radians();
                DVec3::new(
                    10.0 * a.cos(),
                    10.0 * a.sin(),
                    -30.0 * a / std::f64::consts::TAU,
                )
            })
            .collect();
        let c = CurvedPlane::stretched(&pts, DVec3::X, 64, 600).unwrap();
        let p = c.pixel_mm as f64;
        let drawn: f64 = c
            .shift_mm
            .windows(2)
            .map(|w| (w[1] as f64 - w[0] as f64).hypot(p))
            .sum::<f64>()
            + p;
        assert!(
            (drawn - c.length_mm).abs() < 0.01 * c.length_mm,
            "{drawn} mm drawn for {} mm",
            c.length_mm
        );
        for y in 0..600 {
            let q = c.path_point(y).as_dvec3();
            assert!((q.truncate().length() - 10.0).abs() < 0.1, "{y}: {q}");
            // Down the picture is across x: the run in y and z down to the row.
            assert_eq!(c.rows[y as usize].lateral, Vec3::X);
        }
        // The middle of the image is the middle of the path's run along x (−10 to 10 mm).
        let (lo, hi) = c
            .shift_mm
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
        assert!(
            (lo + 10.0).abs() < 0.1 && (hi - 10.0).abs() < 0.1,
            "{lo} {hi}"
        );
        // A path along the vector of interest has no stretched CPR.
        let e = CurvedPlane::stretched(&[DVec3::ZERO, DVec3::new(50.0, 0.0, 0.0)], DVec3::X, 8, 8)
            .unwrap_err();
        assert!(e.contains("across the vector of interest"), "{e}");
    }

    #[test]
    fn sections_spaced_lie_that_far_apart_about_the_middle() {
        // A straight path of 100 mm down z: five sections 10 mm apart about its middle, and
        // what cannot be spaced so.
        let p = [DVec3::new(0.0, 0.0, 50.0), DVec3::new(0.0, 0.0, -50.0)];
        let step = |mm| Spacing {
            step_mm: Some(mm),
            centre_mm: None,
        };
        let c = CurvedPlane::sections_spaced(&p, DVec3::X, 0.0, 5, step(10.0)).unwrap();
        assert_eq!(c.pixel_mm, 10.0);
        for (i, r) in c.rows.iter().enumerate() {
            let want = Vec3::new(0.0, 0.0, 20.0 - 10.0 * i as f32);
            assert!((r.centre - want).length() < 1e-4, "{i}: {}", r.centre);
            assert!((r.normal - Vec3::Y).length() < 1e-6);
        }
        // Without a spacing, the middles of equal parts, as `sections`.
        let even = CurvedPlane::sections_spaced(&p, DVec3::X, 0.0, 4, Spacing::default()).unwrap();
        assert_eq!(
            even.rows,
            CurvedPlane::sections(&p, DVec3::X, 0.0, 4).unwrap().rows
        );
        assert!((even.rows[0].centre.z - 37.5).abs() < 1e-4);
        // Exactly the path's length fits; beyond it, or no spacing, does not.
        let ends = CurvedPlane::sections_spaced(&p, DVec3::X, 0.0, 3, step(50.0)).unwrap();
        assert!((ends.rows[0].centre.z - 50.0).abs() < 1e-4);
        let err = |n, mm| CurvedPlane::sections_spaced(&p, DVec3::X, 0.0, n, step(mm));
        assert!(
            err(12, 10.0)
                .unwrap_err()
                .contains("run from -5.0 to 105.0 mm: beyond the path's 0 to 100.0 mm")
        );
        assert!(err(2, 0.0).unwrap_err().contains("positive"));
        assert!(err(2, f64::NAN).unwrap_err().contains("positive"));
        // About a point of the path: three 4 mm apart about 10 mm along it; one at either
        // end; none past them.
        let at = |n, step_mm, c| {
            let spacing = Spacing {
                step_mm,
                centre_mm: Some(c),
            };
            CurvedPlane::sections_spaced(&p, DVec3::X, 0.0, n, spacing)
        };
        let three = at(3, Some(4.0), 10.0).unwrap();
        let z: Vec<f32> = three.rows.iter().map(|r| r.centre.z).collect();
        for (a, b) in z.iter().zip([44.0, 40.0, 36.0]) {
            assert!((a - b).abs() < 1e-4, "{z:?}");
        }
        assert!((at(1, None, 0.0).unwrap().rows[0].centre.z - 50.0).abs() < 1e-4);
        assert!((at(1, None, 100.0).unwrap().rows[0].centre.z + 50.0).abs() < 1e-4);
        assert!(
            at(1, None, 100.5)
                .unwrap_err()
                .contains("about 100.5 mm along it")
        );
        assert!(at(3, Some(4.0), 2.0).is_err());
        assert!(at(1, None, f64::NAN).is_err());
    }

    #[test]
    fn tortuosity_of_a_line_and_a_quarter_circle() {
        let line = tortuosity(&[
            DVec3::ZERO,
            DVec3::new(3.0, 4.0, 0.0),
            DVec3::new(6.0, 8.0, 0.0),
        ])
        .unwrap();
        assert!((line.length_mm - 10.0).abs() < 1e-9 && (line.chord_mm - 10.0).abs() < 1e-9);
        assert!((line.distance_metric.unwrap() - 1.0).abs() < 1e-9);
        assert!(line.turning_deg_per_cm.abs() < 1e-6, "{line:?}");
        // A quarter circle of 40 mm: π r / 2 over r √2.
        let q = tortuosity(&arc(40.0, 10.0)).unwrap();
        let pi = std::f64::consts::PI;
        let metric = q.distance_metric.unwrap();
        assert!((metric - pi / 8f64.sqrt()).abs() < 1e-3, "{q:?}");
        // 90° over 6.28 cm, but for the spline's end spans: it starts and ends along its end
        // chords (mirrored end points), half a span's angle off the circle's tangents, and
        // turns about 2° less on points 5° apart (3.7° less on points 10° apart).
        let q = tortuosity(&arc(40.0, 5.0)).unwrap();
        let circle = 90.0 / (pi * 40.0 / 2.0 / 10.0);
        assert!(
            (q.turning_deg_per_cm - circle).abs() < 0.03 * circle,
            "{q:?} for {circle}"
        );
        // A closed path has no distance metric.
        let closed: Vec<DVec3> = (0..=12)
            .map(|i| {
                let a = (i as f64 * 30.0).to_radians();
                DVec3::new(10.0 * a.cos(), 10.0 * a.sin(), 0.0)
            })
            .collect();
        assert_eq!(tortuosity(&closed).unwrap().distance_metric, None);
    }

    /// A path's angle on chords: 0° on a line; on a quarter circle of 40 mm through points 5°
    /// apart, its two halves' chords are 45° apart (within 0.5°: the spline is not quite the
    /// circle), and the points are the circle's; a right-angled corner turns 90° exactly (the
    /// spline passes through its control points); what cannot be measured is refused.
    #[test]
    fn the_angle_a_path_turns_through() {
        let line = [
            DVec3::ZERO,
            DVec3::new(3.0, 4.0, 0.0),
            DVec3::new(6.0, 8.0, 0.0),
        ];
        let a = path_angle(&line, [1.0, 5.0, 9.0]).unwrap();
        assert!(a.deviation_deg.abs() < 1e-3, "{a:?}");
        assert!((a.points[1] - DVec3::new(3.0, 4.0, 0.0)).length() < 1e-6);
        let q = arc(40.0, 5.0);
        let length = tortuosity(&q).unwrap().length_mm;
        let a = path_angle(&q, [0.0, length / 2.0, length]).unwrap();
        assert!((a.deviation_deg - 45.0).abs() < 0.5, "{a:?}");
        for p in a.points {
            assert!((p.length() - 40.0).abs() < 0.05, "{p} off the circle");
        }
        let corner = [
            DVec3::ZERO,
            DVec3::new(10.0, 0.0, 0.0),
            DVec3::new(20.0, 0.0, 0.0),
            DVec3::new(20.0, 10.0, 0.0),
            DVec3::new(20.0, 20.0, 0.0),
        ];
        let l = tortuosity(&corner).unwrap().length_mm;
        let a = path_angle(&corner, [0.0, l / 2.0, l]).unwrap();
        assert!(
            (a.points[1] - DVec3::new(20.0, 0.0, 0.0)).length() < 1e-3,
            "{a:?}"
        );
        assert!((a.deviation_deg - 90.0).abs() < 1e-3, "{a:?}");
        let err = |arcs| path_angle(&line, arcs).unwrap_err();
        assert!(err([1.0, 5.0, 11.0]).contains("not on the path (0 to 10.0 mm"));
        assert!(err([1.0, f64::NAN, 9.0]).contains("not on the path"));
        assert!(err([5.0, 1.0, 9.0]).contains("in order"));
        assert!(err([1.0, 1.0, 9.0]).contains("in order"));
    }

    /// A fly-through's cameras along a quarter circle in the x–z plane: each on the path at
    /// its station, looking ahead (toward the next station, and along the circle's tangent),
    /// an orthonormal right-handed frame whose up is the station's up; the frame turns with the
    /// path without twisting (the image's right stays the plane's normal, +y or −y
    /// throughout); the field of view as asked.
    #[test]
    fn ahead_cameras_ride_the_path_looking_along_it() {
        use crate::dvr::scene_to_lps;
        let points = arc(40.0, 5.0);
        let n = 8;
        let c = CurvedPlane::sections(&points, DVec3::Y, 0.0, n).unwrap();
        let cams: Vec<Camera> = (0..n).map(|y| c.ahead_camera(y, 90.0)).collect();
        for (y, cam) in cams.iter().enumerate() {
            let (eye, fwd, right, up) = (
                scene_to_lps(cam.eye),
                scene_to_lps(cam.fwd),
                scene_to_lps(cam.right),
                scene_to_lps(cam.up),
            );
            assert!((eye - c.path_point(y as u32)).length() < 1e-4, "{y}: {eye}");
            // On the circle of 40 mm about the origin, looking along its tangent.
            let radial = eye.normalize();
            assert!((eye.length() - 40.0).abs() < 0.05, "{y}: {eye}");
            assert!(fwd.dot(radial).abs() < 0.02, "{y}: {fwd} against {radial}");
            if y + 1 < n as usize {
                let ahead = scene_to_lps(cams[y + 1].eye) - eye;
                assert!(
                    fwd.dot(ahead.normalize()) > 0.99,
                    "{y}: {fwd} against {ahead}"
                );
            }
            for (a, b) in [(fwd, right), (fwd, up), (right, up)] {
                assert!(a.dot(b).abs() < 1e-5);
            }
            for v in [fwd, right, up] {
                assert!((v.length() - 1.0).abs() < 1e-5);
            }
            assert!((right.cross(fwd) - up).length() < 1e-5, "{y}");
            assert!(
                (up + c.rows[y].normal).length() < 1e-5,
                "{y}: up against the normal"
            );
            assert!(
                (right.y.abs() - 1.0).abs() < 1e-5,
                "{y}: right {right} twisted"
            );
            assert_eq!(right.y.signum(), scene_to_lps(cams[0].right).y.signum());
            assert!((cam.tan_y - 1.0).abs() < 1e-6 && cam.parallel == 0.0);
        }
    }

    #[test]
    fn arc_lengths_are_found_in_the_picture() {
        // Straightened: row (s / p) at the middle column; stretched along x, a quarter circle
        // in the x–z plane puts arc s at depth r sin(s / r) and the path's x there.
        let p = [DVec3::new(0.0, 0.0, 50.0), DVec3::new(0.0, 0.0, -50.0)];
        let c = CurvedPlane::new(&p, DVec3::X, 0.0, 40, 100).unwrap();
        for s in [0.0, 0.5, 37.25, 99.5, 100.0] {
            let (row, col) = c.picture_at(s).unwrap();
            assert!(
                (row - s as f32).abs() < 1e-4 && (col - 20.0).abs() < 1e-4,
                "{s}"
            );
        }
        assert!(c.picture_at(100.5).is_none() && c.picture_at(-0.5).is_none());
        assert!(c.picture_at(f64::NAN).is_none());
        let r = 40.0;
        let c = CurvedPlane::stretched(&arc(r, 5.0), DVec3::X, 51, 400).unwrap();
        for s in [10.0, 31.4, 50.0] {
            let (row, col) = c.picture_at(s).unwrap();
            let a = s / r;
            // Depth down the picture, at 0.1 mm a row; the column from the middle (x = 20).
            let (z, x) = (r * a.sin(), r * a.cos());
            assert!((row as f64 * 0.1 - z).abs() < 0.1, "{s}: row {row} for {z}");
            let col_x = 20.0 + (col as f64 - 25.5) * c.pixel_mm as f64;
            assert!(
                (col_x - x).abs() < 0.1,
                "{s}: column {col} at {col_x} for {x}"
            );
        }
    }

    #[test]
    fn a_bend_is_followed_at_its_arc_length() {
        // A quarter circle of 40 mm from points 10 degrees apart: every row's centre lies on
        // the circle where its arc length puts it.
        let r = 40.0;
        let c = CurvedPlane::new(&arc(r, 10.0), DVec3::Y, 0.0, 33, 300).unwrap();
        let quarter = std::f64::consts::FRAC_PI_2 * r;
        assert!(
            (c.length_mm - quarter).abs() < 1e-3 * quarter,
            "{}",
            c.length_mm
        );
        for (y, row) in c.rows.iter().enumerate() {
            let a = (y as f64 + 0.5) * c.pixel_mm as f64 / r;
            let want = DVec3::new(r * a.cos(), 0.0, -r * a.sin());
            let err = (row.centre.as_dvec3() - want).length();
            // Within a twentieth of a millimetre but at the ends, whose pieces lean towards
            // their chords (0.05 mm at most here), within a tenth there.
            let within = if (10f64.to_radians()..80f64.to_radians()).contains(&a) {
                0.05
            } else {
                0.1
            };
            assert!(
                err < within,
                "row {y}: {} off the circle by {err} mm",
                row.centre
            );
            // The frame stays orthonormal, the lateral direction across the path's plane
            // (the bend does not twist it) and the normal in that plane, across the circle.
            // Between the first and last points the spline's direction is the circle's; at
            // the ends it runs along the first and last chords (5° off, by construction).
            let t = DVec3::new(-a.sin(), 0.0, -a.cos());
            let (l, n) = (row.lateral.as_dvec3(), row.normal.as_dvec3());
            assert!((l.length() - 1.0).abs() < 1e-6 && (n.length() - 1.0).abs() < 1e-6);
            assert!(l.dot(n).abs() < 1e-6 && l.dot(t).abs() < 1e-6);
            assert!((l - DVec3::Y).length() < 1e-6, "row {y}: {l}");
            let interior = (10f64.to_radians()..80f64.to_radians()).contains(&a);
            let off = if interior { 2e-3 } else { 0.09 };
            assert!(n.dot(t).abs() < off, "row {y}: {n} against {t}");
        }
    }

    #[test]
    fn parallel_transport_does_not_twist_a_helix_frame_beyond_its_torsion() {
        // A helix: the transported lateral direction stays perpendicular to the tangent and
        // moves smoothly from row to row (no flips).
        let pts: Vec<DVec3> = (0..=72)
            .map(|i| {
                let a = (i as f64 * 10.0).to_radians();
                DVec3::new(30.0 * a.cos(), 30.0 * a.sin(), -5.0 * a)
            })
            .collect();
        let c = CurvedPlane::new(&pts, DVec3::X, 0.0, 16, 800).unwrap();
        for w in c.rows.windows(2) {
            let (a, b) = (w[0].lateral, w[1].lateral);
            assert!(a.dot(b) > 0.99, "a jump: {a} to {b}");
        }
    }

    #[test]
    fn turning_follows_the_orbit_of_a_camera() {
        // A vessel running head to foot (LPS −z), seen from the front (image right = the
        // patient's left, +x): +90 looks from the patient's left, so the image's right is
        // posterior (+y) and the rays look towards the patient's right (−x).
        let p = [DVec3::new(0.0, 0.0, 50.0), DVec3::new(0.0, 0.0, -50.0)];
        let c = CurvedPlane::new(&p, DVec3::X, 90.0, 8, 8).unwrap();
        assert!(
            (c.rows[0].lateral - Vec3::Y).length() < 1e-6,
            "{}",
            c.rows[0].lateral
        );
        assert!(
            (c.rows[0].normal + Vec3::X).length() < 1e-6,
            "{}",
            c.rows[0].normal
        );
        // A path along the image's right takes any direction across it.
        let along = [DVec3::ZERO, DVec3::new(10.0, 0.0, 0.0)];
        let c = CurvedPlane::new(&along, DVec3::X, 0.0, 4, 4).unwrap();
        assert!(c.rows[0].lateral.dot(Vec3::X).abs() < 1e-6);
    }

    /// A CT phantom on a 1 mm grid (LPS = index): −1000 HU air holding a tube of 1000 HU,
    /// `radius` mm about the quarter circle of [`arc`] (radius 40) moved to `at`, and the
    /// quarter circle's points.
    fn tube(radius: f64, at: DVec3, extra: impl Fn(DVec3) -> Option<f32>) -> (Volume, Vec<DVec3>) {
        let dims = [64usize, 24, 64];
        let mut data = Vec::with_capacity(dims.iter().product());
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = DVec3::new(i as f64, j as f64, k as f64);
                    // Distance to the arc: to its nearest point at an angle in [0°, 90°].
                    let q = p - at;
                    let a = (-q.z).atan2(q.x).clamp(0.0, std::f64::consts::FRAC_PI_2);
                    let near = DVec3::new(40.0 * a.cos(), 0.0, -40.0 * a.sin());
                    let v = if (q - near).length() <= radius {
                        1000.0
                    } else {
                        -1000.0
                    };
                    data.push(extra(p).unwrap_or(v));
                }
            }
        }
        let vol = Volume::hounsfield(dims, [1.0; 3], data);
        let points = arc(40.0, 10.0).into_iter().map(|p| p + at).collect();
        (vol, points)
    }

    fn hu_options(mode: DvrMode, width: u32, height: u32, slab: Option<f32>) -> DvrOptions {
        DvrOptions {
            width,
            height,
            mode,
            hu_values: true,
            slab,
            ..Default::default()
        }
    }

    /// The straightened tube: in every row of the CPR along its centreline, whichever way the
    /// cut faces, the tube is one band 2r wide about the middle (the vessel straightened), in
    /// HU; outside the volume NaN.
    #[test]
    fn a_curved_vessel_comes_out_straight() {
        let at = DVec3::new(12.0, 12.0, 52.0);
        let (vol, points) = tube(4.0, at, |_| None);
        let tf = raystream_volume::TfPreset::CtBone.function();
        for reference in [DVec3::Y, DVec3::X] {
            // 0.5 mm pixels: 32 of them across, the arc's 62.8 mm down.
            let plane = CurvedPlane::new(&points, reference, 0.0, 32, 126).unwrap();
            assert!((plane.pixel_mm - 0.4987).abs() < 1e-3, "{}", plane.pixel_mm);
            let opt = hu_options(DvrMode::Slice, 32, 126, None);
            let (img, stats) = render_volume(&vol, &tf, &opt, &plane);
            assert!(stats.samples > 0);
            for y in 0..126 {
                let row = &img.pixels[y * 32..(y + 1) * 32];
                let inside: Vec<usize> = (0..32).filter(|&x| row[x].x > 0.0).collect();
                let (lo, hi) = (inside[0], *inside.last().unwrap());
                // One band: 8 mm = 16 pixels (±1 voxel at each edge), centred on the path
                // between columns 15 and 16 within half a voxel (the tube's voxel edges).
                assert_eq!(hi - lo + 1, inside.len(), "{reference} row {y}: {inside:?}");
                assert!(
                    (13..=19).contains(&inside.len()),
                    "{reference} row {y}: {inside:?}"
                );
                assert!(
                    (lo as f32 + hi as f32 - 31.0).abs() <= 2.0,
                    "{reference} row {y}: {inside:?}"
                );
                // Its core is the tube's value, the rest air.
                assert_eq!(row[15].x, 1000.0);
                assert_eq!(row[0].x, -1000.0);
            }
        }
        // A path outside the volume: no sample, NaN everywhere.
        let far: Vec<DVec3> = points.iter().map(|&p| p + DVec3::splat(500.0)).collect();
        let plane = CurvedPlane::new(&far, DVec3::Y, 0.0, 8, 8).unwrap();
        assert_eq!(plane.rows_inside(&vol), 0);
        let (img, _) = render_volume(&vol, &tf, &hu_options(DvrMode::Slice, 8, 8, None), &plane);
        assert!(img.pixels.iter().all(|p| p.x.is_nan()));
    }

    /// A slab about the curved plane reaches half its thickness to either side along the
    /// normal: a bright bead 3 mm beside the plane is missed by the plane itself and by a 4 mm
    /// slab's MIP, and found by an 8 mm slab's, at the bead's pixel only; MinIP and average of
    /// the 8 mm slab lie between.
    #[test]
    fn a_slab_reaches_half_its_thickness_about_the_curved_plane() {
        let at = DVec3::new(12.0, 12.0, 52.0);
        let (plain, points) = tube(4.0, at, |_| None);
        let plane = CurvedPlane::new(&points, DVec3::Y, 0.0, 32, 126).unwrap();
        // The bead: 3 mm along row 63's normal from its pixel 8 mm off the path.
        let (p, n) = plane.point(31, 63);
        let bead = (p + 3.0 * n).as_dvec3();
        let (vol, _) = tube(4.0, at, |q| ((q - bead).length() < 1.0).then_some(3000.0));
        assert_ne!(plain.data, vol.data);
        let tf = raystream_volume::TfPreset::CtBone.function();
        let hu = |mode, slab| render_volume(&vol, &tf, &hu_options(mode, 32, 126, slab), &plane).0;
        let value = |img: &crate::Image| img.pixels[63 * 32 + 31].x;
        assert!(value(&hu(DvrMode::Slice, None)) < 0.0);
        assert!(value(&hu(DvrMode::Mip, Some(4.0))) < 0.0);
        let mip = hu(DvrMode::Mip, Some(8.0));
        assert!(value(&mip) > 1500.0, "{}", value(&mip));
        // Away from the bead the 8 mm MIP is the thin plane's tube or air.
        assert_eq!(mip.pixels[20 * 32].x, -1000.0);
        assert_eq!(mip.pixels[20 * 32 + 15].x, 1000.0);
        let (min, avg) = (
            value(&hu(DvrMode::MinIp, Some(8.0))),
            value(&hu(DvrMode::Average, Some(8.0))),
        );
        assert!(
            min <= avg && avg <= value(&mip) && avg > -1000.0,
            "{min} {avg}"
        );
    }

    #[test]
    fn degenerate_paths_are_errors() {
        let q = DVec3::new(1.0, 2.0, 3.0);
        assert!(CurvedPlane::new(&[q, q, q], DVec3::X, 0.0, 4, 4).is_err());
        assert!(CurvedPlane::new(&[q], DVec3::X, 0.0, 4, 4).is_err());
        let tiny = [q, q + DVec3::splat(1e-5)];
        assert!(
            CurvedPlane::new(&tiny, DVec3::X, 0.0, 4, 4)
                .unwrap_err()
                .contains("micrometre")
        );
        // Repeats between distinct points are dropped, not a division by zero.
        let c = CurvedPlane::new(
            &[q, q, q + DVec3::X * 10.0, q + DVec3::X * 10.0],
            DVec3::Y,
            0.0,
            4,
            4,
        )
        .unwrap();
        assert_eq!(c.points, 2);
        assert!(
            c.rows
                .iter()
                .all(|r| r.centre.is_finite() && r.normal.is_finite())
        );
    }
}
