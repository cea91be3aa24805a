//! A vessel's outer wall on a cross-section, about the lumen that `lumen` finds: the aorta's
//! whole width, which an aneurysm's or a dissection's surveillance reports ("outer wall to
//! outer wall") and which the contrast-filled lumen understates wherever thrombus, an
//! unenhanced false lumen or a thick wall lines it.
//!
//! The wall and what lines it (30–60 HU) differ from the contrast (≥ the lumen's threshold)
//! but not from the vessel's neighbours (the oesophagus, the crura, bowel, the heart's wall):
//! a region grown from the lumen runs into them. What does show the wall's edge is the fat or
//! lung about it (−100 HU and less). So rays are cast from the vessel's centre: each leaves the
//! lumen and is followed outwards to the first sample below the wall's threshold (default
//! −30 HU, halfway between soft tissue and fat), where the edge is placed between the two
//! samples. A ray that meets something as bright as the lumen first (bone, calcium, another
//! vessel), leaves the volume or reaches the field's edge finds no edge. A ray that runs
//! from the wall into a neighbour with no fat between them finds the neighbour's far edge,
//! always further out than the wall's; a fat edge is never found inside the vessel.
//!
//! A circle is fitted to the edges robustly (RANSAC over deterministic triples, then least
//! squares on the edges it agrees with): circles that hold the lumen are scored by the edges
//! on them (within 10 % of the radius, at least 1.5 mm) less thrice those inside them (fat
//! within the vessel: evidence against), and since every edge bounds the vessel from outside,
//! the smallest circle with at least 60 % of the best score is taken; it is refined by least
//! squares on the edges within half the tolerance of it, while that scores no worse (edges
//! just beyond the wall would otherwise pull it outwards). The rays are cast again from its
//! centre and the circle fitted again.
//!
//! Along a path the wall runs on from section to section, while what hides it on a few (a
//! neighbour pressed against it, a band of soft tissue wrapped round it) need not: the
//! sections' circles are first found each by itself a millimetre apart ([`Track`]), and a
//! section whose neighbours within 5 mm either way agree on a circle (their median; at least 4
//! with a wall) takes the circle nearest theirs, within an edge's tolerance, when it has at
//! least 30 % of the best score ([`Prior`]); else its own, as above.
//!
//! From the rays that agree with the circle, the wall's edge is followed round to each neighbouring
//! ray whose edge lies within 1 mm (a wall that is not round: an elliptic or lobed sac); a
//! neighbour's far edge jumps out by its width and is not followed. The outline is each such ray's
//! edge, and the circle where a ray's edge is not seen (hidden by a neighbour), never inside the
//! lumen; the figures (area, calliper diameters) are the outline's, as the lumen's are of its edge.
//! A section is left without a wall when fewer than 8 rays, or edges over less than a quarter of
//! the circle, agree on one.
//!
//! Written here: the geometry is a few dozen lines of 2-D fitting, and no crate does the
//! vessel-specific part (which rays to trust).

use raystream_io::Volume;
use raystream_math::{DVec2, DVec3};

use rayon::prelude::*;

use crate::cpr::{CprRow, CurvedPlane};
use crate::dvr::Marcher;
use crate::lumen::{self, Callipers, Lumen, LumenOptions, Segmented};

/// Where a wall's outer edge is placed on each ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WallEdge {
    /// A vessel's (about a bright lumen): where the HU first fall below this, the fat or lung
    /// about it (this module).
    Below(f32),
    /// An airway's (about a dark lumen): both its edges at half maximum ([`crate::airway`]).
    HalfMaximum,
    /// An airway's: its thickness from the HU summed across it, which the scanner's blur
    /// keeps, about the middle of its edges at half maximum ([`crate::airway`]).
    Integral,
}

impl WallEdge {
    /// An airway's wall (about a dark lumen), at half maximum or by the integral.
    pub fn is_airway(self) -> bool {
        matches!(self, WallEdge::HalfMaximum | WallEdge::Integral)
    }
}

/// How the outer wall is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallOptions {
    pub edge: WallEdge,
    /// How many rays are cast from the lumen's centre, evenly about it.
    pub rays: usize,
}

impl Default for WallOptions {
    /// A vessel's, below −30 HU (halfway between the wall's 30–60 HU and fat's −100), 180
    /// rays (2° apart).
    fn default() -> WallOptions {
        WallOptions::vessel(-30.0)
    }
}

impl WallOptions {
    /// A vessel's wall, its edge below `threshold_hu`, on 180 rays.
    pub fn vessel(threshold_hu: f32) -> WallOptions {
        WallOptions {
            edge: WallEdge::Below(threshold_hu),
            rays: 180,
        }
    }

    /// An airway's wall, at half maximum on 180 rays.
    pub fn airway() -> WallOptions {
        WallOptions {
            edge: WallEdge::HalfMaximum,
            rays: 180,
        }
    }

    /// An airway's wall, its thickness by the integral on 180 rays.
    pub fn airway_integral() -> WallOptions {
        WallOptions {
            edge: WallEdge::Integral,
            rays: 180,
        }
    }

    pub fn check(&self, lumen: &LumenOptions) -> Result<(), String> {
        match self.edge {
            WallEdge::Below(_) if lumen.dark => {
                return Err(
                    "a wall below a threshold lies about a bright lumen (a vessel's); an airway's (a dark lumen) is found at half maximum".into(),
                );
            }
            WallEdge::Below(hu) if !(hu.is_finite() && hu < lumen.threshold_hu) => {
                return Err(format!(
                    "a wall threshold of {hu} HU: it must be a number below the lumen's {} HU",
                    lumen.threshold_hu
                ));
            }
            e if e.is_airway() && !lumen.dark => {
                return Err(
                    "a wall at half maximum or by the integral lies about a dark lumen (an airway's); a vessel's is found below a threshold".into(),
                );
            }
            _ => {}
        }
        if !(16..=4096).contains(&self.rays) {
            return Err(format!("{} rays: between 16 and 4096", self.rays));
        }
        Ok(())
    }
}

/// Edges that must agree on a circle, at least.
const MIN_EDGES: usize = 8;
/// The largest gap between them about the circle, radians: they cover a quarter of it.
const MAX_GAP: f64 = 1.5 * std::f64::consts::PI;
/// An edge agrees with a circle of radius r within this fraction of r ...
const TOLERANCE: f64 = 0.1;
/// ... or this, mm, whichever is more.
const TOLERANCE_MM: f64 = 1.5;
/// A ray's edge is followed from its neighbour's when they lie within this, mm.
const CONTINUITY_MM: f64 = 1.0;
/// A circle is taken over a larger one with at least this fraction of its support.
const SUPPORT: f64 = 0.6;
/// What an edge inside a circle (fat within the vessel) counts against it, in edges on it.
const INSIDE_WEIGHT: i64 = 3;
/// A section's neighbours along the path are the track's sections this far from it, mm, either
/// way ([`Track`]) ...
const PRIOR_REACH_MM: f64 = 5.0;
/// ... at least this many of them with a wall; and the circle nearest the one they agree on
/// needs only this fraction of the best circle's support.
const PRIOR_MIN: usize = 4;
const PRIOR_SUPPORT: f64 = 0.3;
/// A circle is refined by least squares on the edges within this fraction of its tolerance.
const REFINE_BAND: f64 = 0.5;
/// The track's sections lie this far apart along the path, mm.
const TRACK_STEP_MM: f64 = 1.0;

/// The outer wall found on one cross-section.
#[derive(Clone, Debug, PartialEq)]
pub struct Wall {
    /// The outline's area, mm² (the lumen's included).
    pub area_mm2: f64,
    /// The diameter of a circle of the same area, mm.
    pub equivalent_diameter_mm: f64,
    /// The outline's longest chord, mm, and its ends (LPS mm).
    pub max_diameter_mm: f64,
    pub max_ends: [DVec3; 2],
    /// Its narrowest calliper width, mm, and the unit direction across it (LPS).
    pub min_diameter_mm: f64,
    pub min_direction: DVec3,
    /// The calliper width across the longest chord, mm.
    pub cross_diameter_mm: f64,
    /// The outline's greatest distance from the lumen's edge, mm: the thickest the wall and
    /// what lines it (thrombus, an unenhanced false lumen) are. An airway's: its thickest ray.
    pub max_thickness_mm: f64,
    /// The outline's mean distance from the lumen's edge, mm. An airway's: the mean of its
    /// rays' thicknesses, each between its edges at half maximum (or by the integral).
    pub mean_thickness_mm: f64,
    /// The area inside the wall's inner edge, mm²: a vessel's lumen's; an airway's, inside
    /// its rays' inner edges.
    pub inner_area_mm2: f64,
    /// The fitted circle's centre (LPS mm) and diameter, mm (an airway's: fitted by least
    /// squares to its outer edges).
    pub centre: DVec3,
    pub circle_diameter_mm: f64,
    /// The fraction of the rays whose edge was seen (on the circle, or followed along the
    /// wall from there): the outline there is the edges', and elsewhere the circle's.
    pub seen: f64,
    /// The circle is the one the section's neighbours along the path agree on ([`Prior`]),
    /// where the section by itself would have taken another.
    pub from_neighbours: bool,
}

impl Wall {
    /// A wall's figures from its `outline` on `row`'s section (mm, the section's own
    /// coordinates), the `thickness` measured at its points (or rays), the area inside its
    /// inner edge, its circle, the share of it seen, and whether the circle is the neighbours'.
    pub(crate) fn from_outline(
        row: &CprRow,
        outline: &[DVec2],
        thickness: &[f64],
        inner_area_mm2: f64,
        circle: Circle,
        seen: f64,
        from_neighbours: bool,
    ) -> Wall {
        let area = polygon_area(outline);
        let k = Callipers::of(outline);
        Wall {
            area_mm2: area,
            equivalent_diameter_mm: lumen::equivalent_diameter(area),
            max_diameter_mm: k.max_mm,
            max_ends: k.max_ends.map(|q| row.point(q)),
            min_diameter_mm: k.min_mm,
            min_direction: row.direction(k.min_across).normalize_or_zero(),
            cross_diameter_mm: k.cross_mm,
            max_thickness_mm: thickness.iter().copied().fold(0.0, f64::max),
            mean_thickness_mm: thickness.iter().sum::<f64>() / thickness.len().max(1) as f64,
            inner_area_mm2,
            centre: row.point(circle.o),
            circle_diameter_mm: 2.0 * circle.r,
            seen,
            from_neighbours,
        }
    }

    /// The share of the wall's area between its inner edge and its outline, %: an airway's
    /// wall area percentage (WA %); a vessel's plaque or thrombus burden.
    pub fn area_percent(&self) -> f64 {
        100.0 * (1.0 - self.inner_area_mm2 / self.area_mm2)
    }
}

/// What a section's neighbours along the path agree its wall's circle is: the median of the
/// circles found on their own on the [`Track`]'s sections within 5 mm of it, either way (not
/// the section itself), where at least 4 of them have one; their centres projected on the
/// section's plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// The centre, LPS mm (on the section's plane), and the radius, mm.
    pub centre: DVec3,
    pub radius_mm: f64,
}

/// The walls found along a path, each section by itself, a millimetre apart: what any section's
/// neighbours found, whatever the sections measured or drawn, so that a section's wall is the
/// same in `measure` and on every picture.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    /// Arc length (mm), circle centre (LPS mm) and radius (mm) of each section with a wall.
    found: Vec<(f64, DVec3, f64)>,
}

impl Track {
    /// The walls on sections a millimetre apart along the spline through `points` (the
    /// middles of equal parts of it, as `measure --every 1` places them), found with `opt` and
    /// `wall` and no prior.
    pub fn along(
        vol: &Volume,
        m: &Marcher,
        points: &[DVec3],
        opt: &LumenOptions,
        wall: &WallOptions,
    ) -> Result<Track, String> {
        // An airway's wall is found on each section by itself.
        if wall.edge.is_airway() {
            return Ok(Track { found: Vec::new() });
        }
        let length = crate::cpr::tortuosity(points)?.length_mm;
        let n = (length / TRACK_STEP_MM).round().clamp(1.0, 1e6) as u32;
        let plane = CurvedPlane::sections(points, DVec3::X, 0.0, n)?;
        let found = plane
            .rows
            .par_iter()
            .zip(&plane.arc_mm)
            .filter_map(|(row, &arc)| {
                let (w, _) = lumen::measure_with_wall(vol, m, row, opt, Some(wall), None)?.wall?;
                Some((arc, w.centre, 0.5 * w.circle_diameter_mm))
            })
            .collect();
        Ok(Track { found })
    }

    /// What the neighbours of the section at `arc_mm` along the path (framed by `row`) agree
    /// on; none where fewer than 4 of them have a wall.
    pub fn prior(&self, arc_mm: f64, row: &CprRow) -> Option<Prior> {
        let near: Vec<&(f64, DVec3, f64)> = self
            .found
            .iter()
            .filter(|(a, _, _)| {
                (0.5 * TRACK_STEP_MM..=PRIOR_REACH_MM).contains(&(a - arc_mm).abs())
            })
            .collect();
        if near.len() < PRIOR_MIN {
            return None;
        }
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            let k = v.len();
            0.5 * (v[(k - 1) / 2] + v[k / 2])
        };
        let offsets: Vec<DVec2> = near.iter().map(|(_, c, _)| row.offset_of(*c)).collect();
        let centre = DVec2::new(
            median(offsets.iter().map(|q| q.x).collect()),
            median(offsets.iter().map(|q| q.y).collect()),
        );
        Some(Prior {
            centre: row.point(centre),
            radius_mm: median(near.iter().map(|(_, _, r)| *r).collect()),
        })
    }
}

/// A wall's outline on its section (mm from the path's point, right and down), a point a
/// ray in order about the centre, and whether each was seen (the ray's edge) or is the
/// fitted circle's.
#[derive(Clone, Debug, PartialEq)]
pub struct Outline {
    pub points: Vec<DVec2>,
    pub seen: Vec<bool>,
}

/// The volumes that the walls found along a path hold, from sections `step_mm` apart (each
/// section's area times the step: by Pappus's theorem the volume of a tube about a curved
/// path, as long as it is narrower than the path's bends are tight).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallVolumes {
    /// The sections with a wall, and the length of path they stand for, mm.
    pub sections: usize,
    pub length_mm: f64,
    /// What their walls hold, and what their inner edges hold (a vessel's lumens), mm³.
    pub wall_mm3: f64,
    pub lumen_mm3: f64,
}

impl WallVolumes {
    /// Over the sections of `sections` with a wall (`step_mm` apart); none where none has.
    pub fn of(sections: &[crate::lumen::Section], step_mm: f64) -> Option<WallVolumes> {
        let with: Vec<(&Wall, &Lumen)> = sections
            .iter()
            .filter_map(|s| Some((s.wall.as_ref()?, s.lumen.as_ref()?)))
            .collect();
        (!with.is_empty()).then(|| WallVolumes {
            sections: with.len(),
            length_mm: with.len() as f64 * step_mm,
            wall_mm3: with.iter().map(|(w, _)| w.area_mm2).sum::<f64>() * step_mm,
            lumen_mm3: with.iter().map(|(w, _)| w.inner_area_mm2).sum::<f64>() * step_mm,
        })
    }
}

impl Outline {
    /// Where the outline meets the section's middle line (through the path's point along its
    /// right): its leftmost and rightmost crossings, mm along the line (left negative); none
    /// where it does not reach the line.
    pub fn across(&self) -> Option<[f64; 2]> {
        let n = self.points.len();
        let mut out: Option<[f64; 2]> = None;
        for k in 0..n {
            let (a, b) = (self.points[k], self.points[(k + 1) % n]);
            if (a.y < 0.0) == (b.y < 0.0) {
                continue;
            }
            let x = a.x + (b.x - a.x) * (a.y / (a.y - b.y));
            out = Some(out.map_or([x, x], |[lo, hi]| [lo.min(x), hi.max(x)]));
        }
        out
    }
}

/// What one ray from the centre finds, mm from the centre.
#[derive(Clone, Copy, Debug)]
struct Ray {
    dir: DVec2,
    /// Where the lumen ends along it: its last grid pixel on the ray, or beyond it where the
    /// HU fall through the lumen's threshold (0 where it meets none).
    lumen: f64,
    /// Where the fat begins, if the ray finds it before anything bright.
    edge: Option<f64>,
}

/// A circle on the section, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Circle {
    pub o: DVec2,
    pub r: f64,
}

impl Circle {
    fn tolerance(&self) -> f64 {
        (TOLERANCE * self.r).max(TOLERANCE_MM)
    }

    /// Through three points; none where they are (nearly) collinear.
    fn through(a: DVec2, b: DVec2, c: DVec2) -> Option<Circle> {
        let (u, v) = (b - a, c - a);
        let det = 2.0 * u.perp_dot(v);
        if det.abs() < 1e-9 * u.length_squared().max(v.length_squared()) {
            return None;
        }
        // The centre's offset from a: x with 2 u·x = |u|², 2 v·x = |v|².
        let (su, sv) = (u.length_squared(), v.length_squared());
        let x = DVec2::new(su * v.y - sv * u.y, sv * u.x - su * v.x) / det;
        Some(Circle {
            o: a + x,
            r: x.length(),
        })
    }

    /// The least-squares (Kåsa) circle through `pts`: x² + y² + a x + b y + c = 0 solved for
    /// a, b, c, about the points' mean (for conditioning).
    pub(crate) fn fitted(pts: &[DVec2]) -> Option<Circle> {
        let mean = pts.iter().copied().sum::<DVec2>() / pts.len() as f64;
        let mut m = [[0.0f64; 4]; 3];
        for &p in pts {
            let q = p - mean;
            let row = [q.x, q.y, 1.0];
            let rhs = -q.length_squared();
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += row[i] * row[j];
                }
                m[i][3] += row[i] * rhs;
            }
        }
        let [a, b, c] = solve3(m)?;
        let o = DVec2::new(-0.5 * a, -0.5 * b);
        let r2 = o.length_squared() - c;
        (r2 > 0.0).then(|| Circle {
            o: o + mean,
            r: r2.sqrt(),
        })
    }

    /// Where the ray from `from` along the unit `dir` leaves the circle, mm from `from`
    /// (`from` inside it).
    fn exit(&self, from: DVec2, dir: DVec2) -> f64 {
        let w = from - self.o;
        let b = w.dot(dir);
        let c = w.length_squared() - self.r * self.r;
        -b + (b * b - c).max(0.0).sqrt()
    }
}

/// The area a closed polygon holds (the shoelace formula).
pub(crate) fn polygon_area(pts: &[DVec2]) -> f64 {
    0.5 * pts
        .iter()
        .zip(pts.iter().cycle().skip(1))
        .map(|(a, b)| a.perp_dot(*b))
        .sum::<f64>()
        .abs()
}

/// Gaussian elimination with partial pivoting on an augmented 3×4 matrix.
fn solve3(mut m: [[f64; 4]; 3]) -> Option<[f64; 3]> {
    for c in 0..3 {
        let p = (c..3).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))?;
        if m[p][c].abs() < 1e-12 {
            return None;
        }
        m.swap(c, p);
        let pivot = m[c];
        for (r, row) in m.iter_mut().enumerate() {
            if r != c {
                let f = row[c] / pivot[c];
                for (x, p) in row.iter_mut().zip(pivot).skip(c) {
                    *x -= f * p;
                }
            }
        }
    }
    Some([m[0][3] / m[0][0], m[1][3] / m[1][1], m[2][3] / m[2][2]])
}

/// Follows the ray from `centre` along `dir` (mm on the section) in steps of `step` up to
/// `reach`: past the lumen (its last grid pixel on the ray, then on while the HU stay at or
/// above the lumen's threshold, two steps at most), then out to the first sample below the
/// wall's threshold.
fn cast(
    sample: &impl Fn(DVec2) -> f32,
    g: &Segmented,
    centre: DVec2,
    dir: DVec2,
    step: f64,
    reach: f64,
    hu: [f32; 2],
) -> Ray {
    let [lumen_hu, wall_hu] = hu;
    let n = (reach / step).floor() as usize;
    let at = |k: usize| centre + dir * (k as f64 * step);
    let last = (0..=n).rev().find(|&k| g.lumen_at(at(k)));
    let mut ray = Ray {
        dir,
        lumen: last.map_or(0.0, |k| k as f64 * step),
        edge: None,
    };
    let mut k = last.map_or(0, |k| k + 1);
    let mut prev = if k > 0 { sample(at(k - 1)) } else { f32::NAN };
    // The lumen's edge as the ray's samples see it, a step or two on; brighter beyond that is
    // a neighbour the lumen's opening cut off.
    let mut bright = 0;
    while k <= n {
        let v = sample(at(k));
        if v.is_nan() || v < lumen_hu {
            break;
        }
        bright += 1;
        if bright > 2 {
            return ray;
        }
        (prev, k) = (v, k + 1);
    }
    // The lumen's edge on the ray: where its HU fall through the lumen's threshold.
    if k > 0 && k <= n && prev >= lumen_hu {
        let v = sample(at(k));
        if v.is_finite() {
            let t = ((prev - lumen_hu) / (prev - v)).clamp(0.0, 1.0) as f64;
            ray.lumen = ray.lumen.max((k as f64 - 1.0 + t) * step);
        }
    }
    while k <= n {
        let v = sample(at(k));
        if v.is_nan() || v >= lumen_hu {
            break;
        }
        if v < wall_hu {
            if k > 0 && prev.is_finite() {
                let t = ((prev - wall_hu) / (prev - v)).clamp(0.0, 1.0) as f64;
                ray.edge = Some((k as f64 - 1.0 + t) * step);
            }
            break;
        }
        (prev, k) = (v, k + 1);
    }
    ray
}

/// The rays from `centre`, evenly about it, the first along the section's right.
fn cast_all(
    sample: &impl Fn(DVec2) -> f32,
    g: &Segmented,
    centre: DVec2,
    step: f64,
    reach: f64,
    hu: [f32; 2],
    count: usize,
) -> Vec<Ray> {
    (0..count)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / count as f64;
            let dir = DVec2::new(a.cos(), a.sin());
            cast(sample, g, centre, dir, step, reach, hu)
        })
        .collect()
}

/// The circle most edges agree on (see the module's comment), its edges' indices, and whether
/// it is `prior`'s choice over the section's own; none when too few agree or they bunch on too
/// little of it. `hull`: the lumen's convex hull, which the circle must hold.
fn fit(
    edges: &[DVec2],
    hull: &[DVec2],
    max_r: f64,
    prior: Option<Circle>,
) -> Option<(Circle, Vec<usize>, bool)> {
    let m = edges.len();
    if m < MIN_EDGES {
        return None;
    }
    let holds_lumen = |c: &Circle| {
        let reach = c.r + c.tolerance();
        hull.iter()
            .all(|q| q.distance_squared(c.o) <= reach * reach)
    };
    let agreeing = |c: &Circle| -> Vec<usize> {
        let t = c.tolerance();
        (0..m)
            .filter(|&i| (edges[i].distance(c.o) - c.r).abs() <= t)
            .collect()
    };
    let score = |c: &Circle| {
        let t = c.tolerance();
        edges.iter().fold(0i64, |s, q| {
            let d = q.distance(c.o) - c.r;
            s + if d.abs() <= t {
                1
            } else if d < -t {
                -INSIDE_WEIGHT
            } else {
                0
            }
        })
    };
    let plausible = |c: &Circle| c.r <= max_r && holds_lumen(c);
    // Triples a third, a quarter, a sixth and an eighth of the edges apart, from every edge;
    // and the neighbours' circle itself.
    let mut candidates: Vec<(i64, Circle)> = Vec::new();
    for f in [3, 4, 6, 8] {
        let s = (m / f).max(1);
        for a in 0..m {
            let Some(c) = Circle::through(edges[a], edges[(a + s) % m], edges[(a + 2 * s) % m])
            else {
                continue;
            };
            if plausible(&c) {
                candidates.push((score(&c), c));
            }
        }
    }
    // Every edge bounds the vessel from outside (a neighbour's far edge lies beyond the wall,
    // never inside it): of the circles nearly as well supported as the best, the smallest.
    let own = candidates.iter().map(|c| c.0).max().and_then(|top| {
        candidates
            .iter()
            .filter(|(sc, _)| *sc > 0 && *sc as f64 >= SUPPORT * top as f64)
            .min_by(|a, b| a.1.r.total_cmp(&b.1.r).then(b.0.cmp(&a.0)))
            .map(|c| c.1)
    });
    // Where the neighbours along the path agree on a circle, it is a candidate too, and the
    // one nearest theirs (within an edge's tolerance) is taken with half the support: the
    // wall runs on from section to section, while what hides it on a few (a neighbour pressed
    // against it, whose far edge makes a larger circle look better) need not.
    let apart = |a: &Circle, b: &Circle| a.o.distance(b.o) + (a.r - b.r).abs();
    let chosen = prior.and_then(|p| {
        if plausible(&p) {
            candidates.push((score(&p), p));
        }
        let top = candidates.iter().map(|c| c.0).max()?;
        candidates
            .iter()
            .filter(|(sc, c)| {
                *sc > 0 && *sc as f64 >= PRIOR_SUPPORT * top as f64 && apart(c, &p) <= p.tolerance()
            })
            .min_by(|a, b| apart(&a.1, &p).total_cmp(&apart(&b.1, &p)))
            .map(|c| c.1)
    });
    // Refined by least squares on the edges it agrees with most closely, while that changes
    // them and scores no worse (the edges beyond a circle are a neighbour's as often as the
    // wall's: fitted to all it agrees with, it would creep outwards).
    let refined = |mut c: Circle| {
        let mut on = agreeing(&c);
        for _ in 0..4 {
            let t = REFINE_BAND * c.tolerance();
            let pts: Vec<DVec2> = on
                .iter()
                .map(|&i| edges[i])
                .filter(|q| (q.distance(c.o) - c.r).abs() <= t)
                .collect();
            let Some(next) = Circle::fitted(&pts)
                .filter(|n| pts.len() >= 3 && plausible(n) && score(n) >= score(&c))
            else {
                break;
            };
            let next_on = agreeing(&next);
            if next_on.len() < MIN_EDGES {
                break;
            }
            let same = next_on == on;
            (c, on) = (next, next_on);
            if same {
                break;
            }
        }
        (c, on)
    };
    // Refined, with enough edges on it, spread far enough round it.
    let found = |c: Circle| {
        let (c, on) = refined(c);
        if on.len() < MIN_EDGES {
            return None;
        }
        let mut angles: Vec<f64> = on
            .iter()
            .map(|&i| {
                let v = edges[i] - c.o;
                v.y.atan2(v.x)
            })
            .collect();
        angles.sort_by(f64::total_cmp);
        let gap = angles.windows(2).map(|w| w[1] - w[0]).fold(
            angles[0] + std::f64::consts::TAU - angles[angles.len() - 1],
            f64::max,
        );
        (gap <= MAX_GAP).then_some((c, on))
    };
    // The neighbours' choice where it holds, and whether the section's own is another circle;
    // else the section's own.
    let own_found = || own.and_then(found);
    match chosen.and_then(found) {
        Some((c, on)) => {
            let other = own_found().is_none_or(|(o, _)| apart(&c, &o) > c.tolerance());
            Some((c, on, other))
        }
        None => own_found().map(|(c, on)| (c, on, false)),
    }
}

/// The circle fitted to the rays' edges, which rays agree with it, and whether it is the
/// `prior`'s choice ([`fit`]).
fn fit_rays(
    rays: &[Ray],
    centre: DVec2,
    hull: &[DVec2],
    max_r: f64,
    prior: Option<Circle>,
) -> Option<(Circle, Vec<bool>, bool)> {
    let (idx, edges): (Vec<usize>, Vec<DVec2>) = rays
        .iter()
        .enumerate()
        .filter_map(|(k, r)| r.edge.map(|e| (k, centre + r.dir * e)))
        .unzip();
    let (c, on, from_prior) = fit(&edges, hull, max_r, prior)?;
    let mut agrees = vec![false; rays.len()];
    for i in on {
        agrees[idx[i]] = true;
    }
    Some((c, agrees, from_prior))
}

/// Grows the rays that agree with the circle along the wall's edge: a ray beside one taken
/// whose edge lies within [`CONTINUITY_MM`] of that one's is taken too, so that a wall that
/// is not round (an elliptic or lobed sac) is followed where it is seen. A neighbour's far
/// edge is not: where a neighbour meets the wall the edge jumps out by its width.
fn follow_edges(rays: &[Ray], taken: &mut [bool]) {
    let n = rays.len();
    loop {
        let mut grew = false;
        for k in 0..n {
            let Some(e) = rays[k].edge.filter(|_| !taken[k]) else {
                continue;
            };
            let near = [(k + 1) % n, (k + n - 1) % n]
                .into_iter()
                .any(|j| taken[j] && rays[j].edge.is_some_and(|f| (e - f).abs() <= CONTINUITY_MM));
            if near {
                taken[k] = true;
                grew = true;
            }
        }
        if !grew {
            break;
        }
    }
}

/// The outer wall about the lumen segmented in `g` (measured as `lumen`, with `edge` its edge
/// points), and its outline, with what the section's neighbours agree on where known. None
/// where the lumen is open or too few rays agree on a wall.
pub(crate) fn wall_about(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
    (wall, prior): (&WallOptions, Option<&Prior>),
    g: &Segmented,
    (lumen, edge): (&Lumen, &[DVec2]),
) -> Option<(Wall, Outline)> {
    let wall_hu = match wall.edge {
        WallEdge::Below(hu) => hu,
        WallEdge::HalfMaximum | WallEdge::Integral => {
            return crate::airway::airway_wall(vol, m, row, opt, wall, g, lumen);
        }
    };
    if lumen.open {
        return None;
    }
    let sample = lumen::sampler(vol, m, row);
    let hull = lumen::convex_hull(edge);
    let reach = 0.5 * opt.field_mm;
    let hu = [opt.threshold_hu, wall_hu];
    let step = opt.pixel_mm;
    // From the lumen's centroid, then again from the circle's centre.
    let first = row.offset_of(lumen.centroid);
    let prior = prior.map(|p| Circle {
        o: row.offset_of(p.centre),
        r: p.radius_mm,
    });
    let rays = cast_all(&sample, g, first, step, reach, hu, wall.rays);
    let (circle, _, was_prior) = fit_rays(&rays, first, &hull, reach, prior)?;
    let o = circle.o;
    let rays = cast_all(&sample, g, o, step, reach, hu, wall.rays);
    let (circle, mut agrees, is_prior) = fit_rays(&rays, o, &hull, reach, prior)?;
    if circle.o.distance(o) >= circle.r {
        return None;
    }
    follow_edges(&rays, &mut agrees);
    let outline: Vec<DVec2> = rays
        .iter()
        .zip(&agrees)
        .map(|(ray, &on)| {
            let r = match ray.edge {
                Some(e) if on => e,
                _ => circle.exit(o, ray.dir),
            };
            o + ray.dir * r.max(ray.lumen)
        })
        .collect();
    let seen = agrees.iter().filter(|&&a| a).count() as f64 / rays.len() as f64;
    // Every outline point against every lumen edge point: a few hundred of each.
    let gaps: Vec<f64> = outline
        .iter()
        .map(|p| {
            edge.iter()
                .map(|q| p.distance_squared(*q))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .collect();
    Some((
        Wall::from_outline(
            row,
            &outline,
            &gaps,
            lumen.area_mm2,
            circle,
            seen,
            was_prior || is_prior,
        ),
        Outline {
            points: outline,
            seen: agrees,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lumen::{measure_path, measure_with_wall};

    /// HU `lo` on the negative side of a boundary and `hi` on its positive, rising linearly
    /// across 2 mm about it (`sd`: a signed distance, or anything with the same zero set), so
    /// that the midway value lies on the boundary.
    fn ramp(sd: f64, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (0.5 + 0.5 * sd).clamp(0.0, 1.0)
    }

    /// A CT 96 mm square and 8 mm deep on a 1 mm grid (LPS = index) whose HU at each (x, y)
    /// are `f`'s, the same on every slice.
    fn slab(f: impl Fn(DVec2) -> f64 + Sync) -> Volume {
        block(8, move |p| f(p.truncate()))
    }

    /// A CT 96 mm square and `nz` mm deep on a 1 mm grid (LPS = index), its HU `f`'s.
    fn block(nz: usize, f: impl Fn(DVec3) -> f64 + Sync) -> Volume {
        let n = 96;
        let data: Vec<f32> = (0..n * n * nz)
            .into_par_iter()
            .map(|k| {
                f(DVec3::new(
                    (k % n) as f64,
                    (k / n % n) as f64,
                    (k / (n * n)) as f64,
                )) as f32
            })
            .collect();
        Volume::hounsfield([n, n, nz], [1.0; 3], data)
    }

    const FAT: f64 = -100.0;
    const SAC: f64 = 40.0;
    const BLOOD: f64 = 300.0;

    /// A lumen of radius 9 mm about `lumen` in a sac (thrombus, 40 HU) whose boundary is the
    /// zero set of `sac` (positive inside), in fat.
    fn vessel(lumen: DVec2, sac: impl Fn(DVec2) -> f64 + Sync) -> impl Fn(DVec2) -> f64 + Sync {
        move |p| ramp(9.0 - p.distance(lumen), ramp(sac(p), FAT, SAC), BLOOD)
    }

    /// The lumen and wall on the section through `at`, with the lumen's and the wall's
    /// default thresholds and a 90 mm field, and the outline's points in LPS (x, y).
    fn measured(vol: &Volume, at: DVec2) -> (crate::lumen::Found, Vec<DVec2>) {
        let path = [at.extend(1.0), at.extend(6.0)];
        let opt = LumenOptions {
            field_mm: 90.0,
            ..LumenOptions::for_volume(vol)
        };
        let row = measure_path(vol, &path, 1, DVec3::X, &opt, None).unwrap()[0].row;
        let m = Marcher::new(vol, None);
        let found =
            measure_with_wall(vol, &m, &row, &opt, Some(&WallOptions::default()), None).unwrap();
        let points = found.wall.as_ref().map_or(Vec::new(), |(_, o)| {
            o.points.iter().map(|&q| row.point(q).truncate()).collect()
        });
        (found, points)
    }

    /// The lumen's equivalent diameter: a disc of 9 mm whose HU rise from the thrombus's 40
    /// to 300 across 2 mm, so that 150 HU lies 0.154 mm outside it.
    const LUMEN_D: f64 = 2.0 * (9.0 + 2.0 * (0.5 - (150.0 - SAC) / (BLOOD - SAC)));

    /// A round sac lined with thrombus about an eccentric lumen: the wall is the sac's circle,
    /// seen all round, though the path runs down the lumen 7 mm off the sac's centre.
    #[test]
    fn a_thrombus_lined_sac_measures_its_outer_wall() {
        let (centre, r) = (DVec2::new(47.3, 48.6), 24.0);
        let lumen = DVec2::new(53.5, 44.9);
        let vol = slab(vessel(lumen, |p| r - p.distance(centre)));
        let (found, outline) = measured(&vol, lumen);
        assert!((found.lumen.equivalent_diameter_mm - LUMEN_D).abs() < 0.05);
        let w = found.wall.expect("a wall").0;
        assert!(w.seen > 0.97, "{w:?}");
        assert!((w.circle_diameter_mm - 2.0 * r).abs() < 0.1, "{w:?}");
        assert!(w.centre.truncate().distance(centre) < 0.1, "{w:?}");
        let area = std::f64::consts::PI * r * r;
        assert!((w.area_mm2 - area).abs() < 0.005 * area, "{w:?}");
        for d in [
            w.equivalent_diameter_mm,
            w.max_diameter_mm,
            w.min_diameter_mm,
            w.cross_diameter_mm,
        ] {
            assert!((d - 2.0 * r).abs() < 0.15, "{d} for {}: {w:?}", 2.0 * r);
        }
        // Every point of the outline on the circle.
        for p in &outline {
            assert!((p.distance(centre) - r).abs() < 0.05, "{p}");
        }
        // Thickest opposite the lumen: the sac's radius and the lumen's offset, less the
        // lumen's radius (its edge at 150 HU).
        let thickest = r + lumen.distance(centre) - 0.5 * LUMEN_D;
        assert!(
            (w.max_thickness_mm - thickest).abs() < 0.1,
            "{thickest}: {w:?}"
        );
    }

    /// A neighbour of soft tissue pressed against the wall (no fat between them) and a
    /// vertebra touching it: the rays that run into them are not taken for the wall's edge,
    /// and the circle stands in for the wall there.
    #[test]
    fn neighbours_touching_the_wall_are_not_taken_for_it() {
        let (centre, r) = (DVec2::new(48.0, 48.0), 15.0);
        let lumen = DVec2::new(50.0, 47.0);
        let oesophagus = (DVec2::new(48.0 - 22.0, 46.0), 8.5);
        let bone = (DVec2::new(48.0, 48.0 + 25.5), 11.0);
        let vol = slab(move |p| {
            let soft = (r - p.distance(centre)).max(oesophagus.1 - p.distance(oesophagus.0));
            let v = vessel(lumen, |_| soft)(p);
            ramp(bone.1 - p.distance(bone.0), v, 700.0).max(v)
        });
        let (found, outline) = measured(&vol, lumen);
        let w = found.wall.expect("a wall").0;
        assert!((0.5..0.9).contains(&w.seen), "{w:?}");
        assert!((w.circle_diameter_mm - 2.0 * r).abs() < 0.3, "{w:?}");
        assert!(w.centre.truncate().distance(centre) < 0.3, "{w:?}");
        assert!((w.equivalent_diameter_mm - 2.0 * r).abs() < 0.3, "{w:?}");
        assert!((w.max_diameter_mm - 2.0 * r).abs() < 0.5, "{w:?}");
        // Nothing of the outline in the neighbours.
        for p in &outline {
            assert!((p.distance(centre) - r).abs() < 0.3, "{p}");
        }
    }

    /// A band 6 mm thick wrapped round part of the wall with no fat between: its far edge is
    /// as round as the wall's and further out, so the rays that run through it agree on a
    /// larger circle, off the wall's centre.
    /// - Soft tissue round 160° of it: where the fat is seen round the other 200°, the wall is
    ///   the smaller circle those edges agree on (every edge bounds the vessel from outside;
    ///   round more of it, the band would be read as thrombus, which looks the same).
    /// - Bone round 200° of it: rays that meet something as bright as the lumen find no edge,
    ///   so the band's far edge is not seen at all and the wall is the fat side's circle.
    #[test]
    fn a_band_wrapped_round_the_wall_is_not_taken_for_it() {
        let (centre, r) = (DVec2::new(48.0, 48.0), 15.0);
        let lumen = DVec2::new(47.0, 48.5);
        for (band, half_angle) in [(SAC, 80f64), (700.0, 100.0)] {
            let cos = half_angle.to_radians().cos();
            let vol = slab(move |p| {
                let q = p - centre;
                let d = q.length();
                let v = vessel(lumen, |_| r - d)(p);
                // The band: 15 to 21 mm from the centre, within half_angle of the right,
                // ending abruptly.
                let inside = ((d - r) * (r + 6.0 - d)).min(100.0 * (q.x / d - cos));
                ramp(inside, v, band).max(v.min(band))
            });
            let (found, outline) = measured(&vol, lumen);
            let w = found.wall.expect("a wall").0;
            assert!(
                (w.circle_diameter_mm - 2.0 * r).abs() < 0.3,
                "{band} HU: {w:?}"
            );
            assert!(
                w.centre.truncate().distance(centre) < 0.3,
                "{band} HU: {w:?}"
            );
            let fat = 1.0 - half_angle / 180.0;
            assert!((w.seen - fat).abs() < 0.1, "{band} HU: {w:?}");
            // Nothing of the outline in the band (blurred by a voxel where it ends).
            for p in &outline {
                assert!((p.distance(centre) - r).abs() < 0.5, "{band} HU: {p}");
            }
        }
    }

    /// A band of soft tissue wrapped round 240° of a 30 mm wall, 6 mm thick, for 4 mm of the
    /// vessel's length: a section through it, alone, takes the band for thrombus within the
    /// wall (a wider wall), but along the path the sections either side agree on the wall,
    /// and so does the section.
    #[test]
    fn a_band_round_the_wall_for_a_few_mm_is_not_taken_for_it() {
        let (centre, r) = (DVec2::new(48.0, 48.0), 15.0);
        let lumen = DVec2::new(47.0, 48.5);
        let cos = 120f64.to_radians().cos();
        let vol = block(24, move |p| {
            let q = p.truncate() - centre;
            let d = q.length();
            let v = vessel(lumen, |_| r - d)(p.truncate());
            // The band: 15 to 21 mm from the centre, within 120° of the right, from 10 to 14
            // mm along the vessel.
            let inside = ((d - r) * (r + 6.0 - d))
                .min(100.0 * (q.x / d - cos))
                .min(2.0 * (p.z - 10.0).min(14.0 - p.z));
            ramp(inside, v, SAC).max(v.min(SAC))
        });
        let opt = LumenOptions {
            field_mm: 90.0,
            ..LumenOptions::for_volume(&vol)
        };
        let path = [lumen.extend(1.0), lumen.extend(22.0)];
        let wall = WallOptions::default();
        let sections = measure_path(&vol, &path, 21, DVec3::X, &opt, Some(&wall)).unwrap();
        let m = Marcher::new(&vol, None);
        for s in &sections {
            let z = s.row.centre.z as f64;
            let w = s.wall.as_ref().expect("a wall");
            // A section half a millimetre from the band's end samples a quarter of it.
            assert!(
                (w.circle_diameter_mm - 2.0 * r).abs() < 0.5,
                "at {z} mm: {w:?}"
            );
            assert!(
                w.centre.truncate().distance(centre) < 0.3,
                "at {z} mm: {w:?}"
            );
            let banded = (10.5..=13.5).contains(&z);
            assert_eq!(w.from_neighbours, banded, "at {z} mm: {w:?}");
            // Alone, a section through the band takes its far edge.
            let alone = measure_with_wall(&vol, &m, &s.row, &opt, Some(&wall), None)
                .and_then(|f| f.wall)
                .expect("a wall")
                .0;
            if banded {
                assert!(
                    alone.equivalent_diameter_mm > 2.0 * r + 5.0,
                    "at {z} mm: {alone:?}"
                );
                // Seen where the fat is: a third of the way round.
                assert!((w.seen - 1.0 / 3.0).abs() < 0.05, "at {z} mm: {w:?}");
            } else {
                assert!(
                    (alone.circle_diameter_mm - w.circle_diameter_mm).abs() < 0.05
                        && alone.centre.distance(w.centre) < 0.05,
                    "at {z} mm: {alone:?} alone, {w:?}"
                );
            }
        }
    }

    /// The outline meets the middle line where its edges cross it.
    #[test]
    fn an_outline_across_the_middle_line() {
        let square = Outline {
            points: vec![
                DVec2::new(2.0, -1.0),
                DVec2::new(3.0, 1.0),
                DVec2::new(-4.0, 1.0),
                DVec2::new(-4.0, -1.0),
            ],
            seen: vec![true; 4],
        };
        assert_eq!(square.across(), Some([-4.0, 2.5]));
        let above = Outline {
            points: vec![
                DVec2::new(0.0, 1.0),
                DVec2::new(1.0, 2.0),
                DVec2::new(0.0, 2.0),
            ],
            seen: vec![false; 3],
        };
        assert_eq!(above.across(), None);
    }

    /// The volume a thrombus-lined sac holds, from its sections along a path: the cylinder's
    /// π r² L, and its lumen's.
    #[test]
    fn the_volumes_of_a_sac_and_its_lumen() {
        let (centre, r) = (DVec2::new(47.3, 48.6), 24.0);
        let lumen = DVec2::new(53.5, 44.9);
        let vol = slab(vessel(lumen, |p| r - p.distance(centre)));
        let path = [lumen.extend(1.0), lumen.extend(6.0)];
        let opt = LumenOptions {
            field_mm: 90.0,
            ..LumenOptions::for_volume(&vol)
        };
        let wall = WallOptions::default();
        let sections = measure_path(&vol, &path, 4, DVec3::X, &opt, Some(&wall)).unwrap();
        let v = WallVolumes::of(&sections, 5.0 / 4.0).unwrap();
        assert_eq!((v.sections, v.length_mm), (4, 5.0));
        let pi = std::f64::consts::PI;
        let sac = pi * r * r * 5.0;
        assert!((v.wall_mm3 - sac).abs() < 0.005 * sac, "{v:?}");
        let inner = pi * (0.5 * LUMEN_D).powi(2) * 5.0;
        assert!((v.lumen_mm3 - inner).abs() < 0.01 * inner, "{v:?}");
        // No walls, no volumes.
        let none = measure_path(&vol, &path, 4, DVec3::X, &opt, None).unwrap();
        assert!(WallVolumes::of(&none, 1.25).is_none());
    }

    /// An elliptic sac (56 × 40 mm): its edge, off the best circle by up to 8 mm, is followed
    /// round from where it agrees with the circle, and its axes are its calliper diameters.
    #[test]
    fn an_elliptic_sac_has_its_axes_as_diameters() {
        let (centre, a, b) = (DVec2::new(48.0, 48.0), 28.0, 20.0);
        let lumen = DVec2::new(44.0, 50.0);
        let vol = slab(vessel(lumen, move |p| {
            let q = p - centre;
            // Zero on the ellipse; about a mm a unit near it.
            b * (1.0 - ((q.x / a).powi(2) + (q.y / b).powi(2)).sqrt())
        }));
        let w = measured(&vol, lumen).0.wall.expect("a wall").0;
        assert!(w.seen > 0.97, "{w:?}");
        assert!((w.max_diameter_mm - 2.0 * a).abs() < 0.3, "{w:?}");
        assert!((w.min_diameter_mm - 2.0 * b).abs() < 0.3, "{w:?}");
        let area = std::f64::consts::PI * a * b;
        assert!((w.area_mm2 - area).abs() < 0.01 * area, "{w:?}");
    }

    /// A vessel in soft tissue with no fat about it shows no wall: none is reported, rather
    /// than a guess.
    #[test]
    fn no_fat_about_the_vessel_no_wall() {
        let lumen = DVec2::new(48.0, 48.0);
        let vol = slab(vessel(lumen, |_| 1.0));
        let found = measured(&vol, lumen).0;
        assert!((found.lumen.equivalent_diameter_mm - LUMEN_D).abs() < 0.05);
        assert!(found.wall.is_none());
    }

    #[test]
    fn circles_through_three_points_and_fitted_to_many() {
        let c = Circle::through(
            DVec2::new(3.0, 1.0),
            DVec2::new(-1.0, 5.0),
            DVec2::new(-5.0, 1.0),
        )
        .unwrap();
        assert!(c.o.distance(DVec2::new(-1.0, 1.0)) < 1e-12 && (c.r - 4.0).abs() < 1e-12);
        assert!(Circle::through(DVec2::ZERO, DVec2::X, DVec2::X * 2.0).is_none());
        // Points on an arc of a third of a circle far from the origin.
        let pts: Vec<DVec2> = (0..20)
            .map(|k| {
                let a = 0.1 * k as f64;
                DVec2::new(1000.0, -500.0) + 12.5 * DVec2::new(a.cos(), a.sin())
            })
            .collect();
        let f = Circle::fitted(&pts).unwrap();
        assert!(f.o.distance(DVec2::new(1000.0, -500.0)) < 1e-6, "{f:?}");
        assert!((f.r - 12.5).abs() < 1e-6);
        // A ray from inside leaves it where the circle is.
        let from = DVec2::new(1003.0, -501.0);
        let dir = DVec2::new(0.6, 0.8);
        let t = f.exit(from, dir);
        assert!(((from + t * dir).distance(f.o) - 12.5).abs() < 1e-6);
    }

    /// Outliers that lie outside the circle (a neighbour's far edge) do not move it; edges
    /// inside it (fat within) count against a circle too large.
    #[test]
    fn the_fit_ignores_edges_beyond_the_wall() {
        let truth = Circle {
            o: DVec2::new(2.0, -3.0),
            r: 15.0,
        };
        let edges: Vec<DVec2> = (0..90)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 90.0;
                let dir = DVec2::new(a.cos(), a.sin());
                // Half the rays run on into neighbours, 5 to 30 mm beyond the wall.
                let beyond = if (20..65).contains(&k) {
                    5.0 + (k * 7 % 25) as f64
                } else {
                    0.0
                };
                truth.o + dir * (truth.r + beyond)
            })
            .collect();
        let hull = [DVec2::new(2.0, 2.0), DVec2::new(-3.0, -3.0)];
        let (c, on, _) = fit(&edges, &hull, 50.0, None).unwrap();
        assert!(
            c.o.distance(truth.o) < 1e-6 && (c.r - truth.r).abs() < 1e-6,
            "{c:?}"
        );
        assert_eq!(on.len(), 45);
        // Too few edges, or all on a tenth of the circle: no wall.
        assert!(fit(&edges[..7], &hull, 50.0, None).is_none());
        let arc: Vec<DVec2> = (0..30)
            .map(|k| {
                let a = 0.02 * k as f64;
                truth.o + truth.r * DVec2::new(a.cos(), a.sin())
            })
            .collect();
        assert!(fit(&arc, &hull, 50.0, None).is_none());
        // A circle that would leave the lumen out is not taken.
        assert!(fit(&edges, &[DVec2::new(40.0, 0.0)], 50.0, None).is_none());
    }

    /// Edges just beyond the wall, within its tolerance (a neighbour's far edge a millimetre
    /// out, over 40 % of the way round), do not pull the circle out as it is refined.
    #[test]
    fn edges_just_beyond_the_wall_do_not_pull_it_out() {
        let truth = Circle {
            o: DVec2::new(-4.0, 7.0),
            r: 15.0,
        };
        let edges: Vec<DVec2> = (0..90)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 90.0;
                let beyond = if k < 36 { 1.2 } else { 0.0 };
                truth.o + DVec2::new(a.cos(), a.sin()) * (truth.r + beyond)
            })
            .collect();
        let hull = [DVec2::new(-6.0, 5.0), DVec2::new(-1.0, 9.0)];
        let (c, on, from_prior) = fit(&edges, &hull, 50.0, None).unwrap();
        assert!(
            c.o.distance(truth.o) < 1e-6 && (c.r - truth.r).abs() < 1e-6,
            "{c:?}"
        );
        assert_eq!(on.len(), 90);
        assert!(!from_prior);
    }
}
