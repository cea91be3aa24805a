//! An airway's wall on a cross-section, about the dark lumen that `lumen` finds (`dark`): the
//! bronchial wall's thickness and area that quantitative airway CT reports (in COPD, asthma,
//! bronchiectasis: the mean wall thickness, and the wall area as a percentage of the airway's,
//! WA %).
//!
//! A vessel's outer wall is found at a fixed threshold (`wall`), since fat shows where it ends.
//! An airway's wall is a thin bright band between the gas in its lumen and the lung, fat or
//! soft tissue about it, and on CT it is blurred into a peak lower than the wall's own HU the
//! thinner it is: no one threshold fits thin and thick walls alike. So each ray from the
//! lumen's centroid places the wall's edges at half maximum, as the standard full width at half
//! maximum method does (Nakano et al., Am J Respir Crit Care Med 2000): the wall's peak is the
//! highest sample past the lumen, confirmed where the HU beyond it fall [`DIP_HU`] below it;
//! the inner edge is where the HU cross halfway between the lumen's gas (its lowest sample on
//! the ray) and the peak, and the outer edge where they cross halfway between the peak and the
//! lowest sample beyond it (before the HU rise again into a neighbour), which must be fat or
//! lung ([`OUTSIDE_MAX_HU`]). A ray that meets no such dip within [`REACH_MM`] of the lumen (the
//! wall pressed against a vessel, the oesophagus or the mediastinum's soft tissue), or meets
//! something brighter than a wall first ([`WALL_MAX_HU`]: contrast-filled blood, calcium, a
//! stent), finds no outer edge.
//!
//! A neighbour with a narrow gap of lung between it and the wall (the bronchus's own artery)
//! can still give a ray the two of them as one peak: rays over twice the median thickness are
//! left out. The rest must be at least a quarter of the rays, and eight. A ray that finds the
//! wall's inner edge but does not see past the wall is given the median thickness of those
//! that do beyond it (its peak is then the highest sample within reach, short of anything
//! brighter than a wall); one that finds neither edge takes its neighbours' by angle. A lumen
//! whose centroid lies outside it, or whose largest diameter is over twice its smallest (two
//! bronchi at once, where the airway divides), has no wall measured. The inner and outer
//! outlines give the areas; the thickness is the mean over the rays with their own edges. Like
//! every half-maximum method this overstates a wall much thinner than the scanner's blur
//! (there the peak's width is the blur's), and it reads the wall's thickness along rays from
//! the centroid, across the wall where the airway is round.
//!
//! [`WallEdge::Integral`] measures the thin walls too: a blur (any point spread function that
//! is symmetric and sums to one) moves the HU about but keeps their sum, so the wall's HU
//! summed across it above the background (the gas up to the wall's middle, the lung or fat past
//! it) is its thickness times its density's rise above that background, however blurred (the
//! idea behind integral-based measures of thin walls, and behind the partial-volume corrections
//! that scale a thin wall by its HU, as Conradi et al., Acad Radiol 2010, do on an airway
//! phantom). The sum runs between the points where the HU come within 5 % of the rise from the
//! gas, and of the fall to the lung past the peak; the wall's density is taken as soft
//! tissue's, [`WALL_HU`] (or the peak, where it is higher: a thick wall's plateau); the middle
//! is the middle of the edges at half maximum, and the inner and outer edges lie half the
//! thickness either side of it; rays over twice the median thickness are left out by this
//! thickness (a vessel past a thin wall stands out against the wall's millimetre, where beside
//! the blur-widened half-maximum widths it need not). Under a Gaussian blur of 0.8 mm that
//! gives walls from 0.4 to 3 mm within 0.06 mm, where half maximum reads a 0.4 mm wall as 1.9
//! mm (the unit tests).
//!
//! Written here: the method is a few dozen lines of 1-D profile analysis on the sections that
//! `lumen` samples, and no crate does it.

use raystream_io::Volume;
use raystream_math::DVec2;

use crate::cpr::CprRow;
use crate::dvr::Marcher;
use crate::lumen::{self, Lumen, LumenOptions, Segmented};
use crate::wall::{Circle, Outline, Wall, WallEdge, WallOptions, polygon_area};

/// The wall's peak is looked for within this of the lumen's last sample on the ray, mm, and
/// the lung beyond it within this of the peak.
pub const REACH_MM: f64 = 8.0;
/// The HU must fall this far below the peak beyond it for the peak to be the wall's, and the
/// peak rise twice this above the lumen's gas.
pub const DIP_HU: f32 = 100.0;
/// Brighter than this, HU, is not an airway's wall (blurred, or soft tissue at 30–60 HU) but
/// what lies beyond it: contrast-filled blood, calcium, bone, a stent's metal.
pub const WALL_MAX_HU: f32 = 250.0;
/// The lowest HU beyond the wall must be at most this, HU: fat (about −100) or lung (about
/// −850), not soft tissue or contrast.
pub const OUTSIDE_MAX_HU: f32 = -50.0;
/// The wall's own density that the integral assumes, HU: soft tissue's (or the wall's peak,
/// where that is higher). The integral divides by its rise above the gas and the lung, about
/// 950 HU, so that 50 HU either way moves the thickness by about 5 %.
pub const WALL_HU: f32 = 40.0;
/// The integral runs from where the HU lie within this fraction of the rise from the gas to
/// the peak, to where they fall within it of the lung or fat beyond: under a Gaussian blur
/// the tails past that hold about 1.4 % of a thin wall's sum.
const TAIL: f32 = 0.05;
/// A lumen whose largest diameter is over this many times its smallest is not one round
/// airway.
const MAX_ELONGATION: f64 = 2.0;
/// A ray whose thickness is over this many times the median is a neighbour's too.
const OUTLIER: f64 = 2.0;
/// A wall needs its own edges on at least this fraction of the rays ...
const MIN_SEEN: f64 = 0.25;
/// ... and on at least this many.
const MIN_RAYS: usize = 8;

/// A ray's wall: its inner and outer edges, mm from where it starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Edges {
    pub inner: f64,
    pub outer: f64,
}

/// [`REACH_MM`] in samples `step` mm apart.
fn reach_samples(step: f64) -> usize {
    (REACH_MM / step).ceil() as usize
}

/// Where the HU cross `level` between samples `i` and `i + 1` (`a` and `b`), mm.
fn crossing(a: f32, b: f32, level: f32, i: usize, step: f64) -> f64 {
    let t = if a == b {
        0.5
    } else {
        ((level - a) / (b - a)).clamp(0.0, 1.0) as f64
    };
    (i as f64 + t) * step
}

/// What one ray finds of the wall: its inner edge, and its outer where it sees past the wall,
/// mm from where the ray starts; and there, its thickness by the integral, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RayWall {
    pub inner: f64,
    pub outer: Option<f64>,
    pub integral: Option<f64>,
}

/// The wall's edges at half maximum on a ray's samples `v`, `step` mm apart from its start
/// (NaN outside the volume), of which `last` is the lumen's last (see the module's comment):
/// the inner edge against the highest sample past the lumen (before anything brighter than a
/// wall, the volume's edge or the reach), and the outer edge where a dip confirms that peak;
/// none where nothing rises past the lumen.
pub(crate) fn half_maximum(v: &[f32], last: usize, step: f64) -> Option<RayWall> {
    let reach = reach_samples(step);
    let air = v[..=last.min(v.len() - 1)]
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(f32::INFINITY, f32::min);
    if !air.is_finite() {
        return None;
    }
    // The peak: the running maximum past the lumen, until the HU fall DIP_HU below it.
    let end = (last + reach).min(v.len() - 1);
    let mut peak = last;
    let mut k = last + 1;
    let dip = loop {
        if k > end || !v[k].is_finite() || v[k] > WALL_MAX_HU {
            break false;
        }
        if v[k] > v[peak] {
            peak = k;
        } else if v[k] <= v[peak] - DIP_HU {
            break true;
        }
        k += 1;
    };
    let top = v[peak];
    if top - air < 2.0 * DIP_HU {
        return None;
    }
    let inner_half = 0.5 * (air + top);
    let i = (0..peak).rev().find(|&j| v[j] < inner_half)?;
    let inner = crossing(v[i], v[i + 1], inner_half, i, step);
    let beyond = if dip {
        outer_edge(v, peak, k, step)
    } else {
        None
    };
    Some(RayWall {
        inner,
        outer: beyond.map(|b| b.edge),
        integral: beyond.and_then(|b| {
            integral_thickness(v, [air, top, b.low], peak, [inner, b.edge], b.low_at, step)
        }),
    })
}

/// What lies past a wall's peak on a ray: its outer edge at half maximum (mm from the ray's
/// start), and the lowest HU beyond it and their sample.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Beyond {
    edge: f64,
    low: f32,
    low_at: usize,
}

/// The wall's thickness on a ray's samples `v` from the HU summed across it (see the module's
/// comment), mm: the gas's, the peak's and the lowest beyond's HU `[air, top, low]`, the
/// peak's sample and the lowest's, its edges at half maximum; none where a sample is missing
/// or the sum is not above the background.
fn integral_thickness(
    v: &[f32],
    [air, top, low]: [f32; 3],
    peak: usize,
    [inner, outer]: [f64; 2],
    low_at: usize,
    step: f64,
) -> Option<f64> {
    let start = (0..peak)
        .rev()
        .find(|&j| v[j] <= air + TAIL * (top - air))?;
    let end = (peak + 1..=low_at).find(|&j| v[j] <= low + TAIL * (top - low))?;
    let w = &v[start..=end];
    if w.iter().any(|x| !x.is_finite()) {
        return None;
    }
    // The trapezoids' sum, less the background: the gas up to the wall's middle, the lung or
    // fat past it.
    let sum: f64 = w
        .windows(2)
        .map(|p| 0.5 * (p[0] + p[1]) as f64)
        .sum::<f64>()
        * step;
    let (x0, x1) = (start as f64 * step, end as f64 * step);
    let middle = (0.5 * (inner + outer)).clamp(x0, x1);
    let excess = sum - air as f64 * (middle - x0) - low as f64 * (x1 - middle);
    let rise = top.max(WALL_HU) as f64 - 0.5 * (air + low) as f64;
    (excess > 0.0 && rise > 0.0).then(|| excess / rise)
}

/// The outer edge at half maximum on a ray's samples `v` past the wall's `peak`, the HU
/// having fallen [`DIP_HU`] below it at sample `k`: halfway from the peak to the lowest HU
/// beyond it; none where that is not fat or lung.
fn outer_edge(v: &[f32], peak: usize, k: usize, step: f64) -> Option<Beyond> {
    let reach = reach_samples(step);
    let top = v[peak];
    // The lowest HU beyond it, until they rise again by half the dip (a neighbour).
    let (mut low, mut low_at) = (v[k], k);
    for (j, &x) in v
        .iter()
        .enumerate()
        .take((peak + reach).min(v.len() - 1) + 1)
        .skip(k + 1)
    {
        if !x.is_finite() || x > low + 0.5 * DIP_HU {
            break;
        }
        if x < low {
            (low, low_at) = (x, j);
        }
    }
    if low > OUTSIDE_MAX_HU {
        return None;
    }
    let outer_half = 0.5 * (top + low);
    let o = (peak + 1..v.len()).find(|&j| v[j] <= outer_half)?;
    Some(Beyond {
        edge: crossing(v[o - 1], v[o], outer_half, o - 1, step),
        low,
        low_at,
    })
}

/// Fills the rays without edges (`None`) from the nearest with them on either side, by
/// angle (the rays are evenly about the centre, in order); `edges` holds at least one.
fn interpolated(edges: &[Option<Edges>]) -> Vec<Edges> {
    let n = edges.len();
    let seen: Vec<usize> = (0..n).filter(|&k| edges[k].is_some()).collect();
    (0..n)
        .map(|k| {
            if let Some(e) = edges[k] {
                return e;
            }
            // The nearest seen ray before k and after it, about the circle.
            let after = seen.iter().copied().find(|&j| j > k).unwrap_or(seen[0] + n);
            let before = seen
                .iter()
                .copied()
                .rev()
                .find(|&j| j < k)
                .map_or(seen[seen.len() - 1] as isize - n as isize, |j| j as isize);
            let (a, b) = (
                edges[before.rem_euclid(n as isize) as usize],
                edges[after % n],
            );
            let (a, b) = (a.expect("seen"), b.expect("seen"));
            let t = (k as isize - before) as f64 / (after as isize - before) as f64;
            Edges {
                inner: a.inner + (b.inner - a.inner) * t,
                outer: a.outer + (b.outer - a.outer) * t,
            }
        })
        .collect()
}

/// The airway's wall about the lumen segmented in `g` (measured as `lumen`), cast on `rays`
/// rays from its centroid, and its outer outline; none where the lumen is open or too few
/// rays find the wall.
pub(crate) fn airway_wall(
    vol: &Volume,
    m: &Marcher,
    row: &CprRow,
    opt: &LumenOptions,
    wall: &WallOptions,
    g: &Segmented,
    lumen: &Lumen,
) -> Option<(Wall, Outline)> {
    let rays = wall.rays;
    let o = row.offset_of(lumen.centroid);
    // Rays from a centroid outside the lumen, or in one over twice as long as it is wide (two
    // bronchi at once, where the airway divides), would cross the wall obliquely or not at all.
    if lumen.open
        || !g.lumen_at(o)
        || lumen.max_diameter_mm > MAX_ELONGATION * lumen.min_diameter_mm
    {
        return None;
    }
    let sample = lumen::sampler(vol, m, row);
    let step = opt.pixel_mm;
    let n = (0.5 * opt.field_mm / step).floor() as usize;
    let reach = 2 * reach_samples(step);
    let dirs: Vec<DVec2> = (0..rays)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / rays as f64;
            DVec2::new(a.cos(), a.sin())
        })
        .collect();
    let mut found: Vec<Option<RayWall>> = dirs
        .iter()
        .map(|&d| {
            let at = |k: usize| o + d * (k as f64 * step);
            let last = (0..=n).rev().find(|&k| g.lumen_at(at(k)))?;
            let v: Vec<f32> = (0..=(last + reach).min(n)).map(|k| sample(at(k))).collect();
            half_maximum(&v, last, step)
        })
        .collect();
    let width = |f: &RayWall| f.outer.map(|o| o - f.inner);
    let median = |mut t: Vec<f64>| {
        t.sort_by(f64::total_cmp);
        t.get(t.len() / 2).copied()
    };
    // Each ray's thickness as asked for: at half maximum, or by the integral.
    let integral = wall.edge == WallEdge::Integral;
    let thickness = |f: &RayWall| {
        let w = width(f)?;
        if integral { f.integral } else { Some(w) }
    };
    let all_seen = median(found.iter().flatten().filter_map(thickness).collect())?;
    for f in found.iter_mut().flatten() {
        if thickness(f).is_none_or(|t| t > OUTLIER * all_seen) {
            f.outer = None;
        }
    }
    let seen: Vec<bool> = found
        .iter()
        .map(|f| f.is_some_and(|f| f.outer.is_some()))
        .collect();
    let kept: Vec<f64> = found.iter().flatten().filter_map(thickness).collect();
    let count = kept.len();
    if count < MIN_RAYS || (count as f64) < MIN_SEEN * rays as f64 {
        return None;
    }
    // Each ray's edges about the middle of its edges at half maximum, its thickness apart;
    // past an inner edge alone, the section's median half-maximum width and thickness; neither
    // edge seen, the neighbours'.
    let typical_width = median(found.iter().flatten().filter_map(width).collect())?;
    let typical = median(kept.clone())?;
    let edges: Vec<Option<Edges>> = found
        .iter()
        .map(|f| {
            f.map(|f| {
                let (middle, t) = match (width(&f), thickness(&f)) {
                    (Some(w), Some(t)) => (f.inner + 0.5 * w, t),
                    _ => (f.inner + 0.5 * typical_width, typical),
                };
                Edges {
                    inner: middle - 0.5 * t,
                    outer: middle + 0.5 * t,
                }
            })
        })
        .collect();
    let all = interpolated(&edges);
    let inner: Vec<DVec2> = dirs
        .iter()
        .zip(&all)
        .map(|(d, e)| o + *d * e.inner)
        .collect();
    let outer: Vec<DVec2> = dirs
        .iter()
        .zip(&all)
        .map(|(d, e)| o + *d * e.outer)
        .collect();
    let seen_outer: Vec<DVec2> = outer
        .iter()
        .zip(&seen)
        .filter(|(_, s)| **s)
        .map(|(q, _)| *q)
        .collect();
    let circle = Circle::fitted(&seen_outer)?;
    Some((
        Wall::from_outline(
            row,
            &outer,
            &kept,
            polygon_area(&inner),
            circle,
            count as f64 / rays as f64,
            false,
        ),
        Outline {
            points: outer,
            seen,
        },
    ))
}

/// An airway wall's internal perimeter, mm, as [`Pi10`] takes it: the circle's of its inner
/// edge's area.
fn inner_perimeter(w: &Wall) -> f64 {
    2.0 * (std::f64::consts::PI * w.inner_area_mm2).sqrt()
}

/// The points [`Pi10`] fits its line to: each wall on `sections`, its internal perimeter and
/// the square root of its area (mm), `[Pi, √WA]`.
pub fn pi10_points(sections: &[crate::lumen::Section]) -> Vec<[f64; 2]> {
    sections
        .iter()
        .filter_map(|s| s.wall.as_ref())
        .map(|w| {
            [
                inner_perimeter(w),
                (w.area_mm2 - w.inner_area_mm2).max(0.0).sqrt(),
            ]
        })
        .collect()
}

/// Pi10 is fitted over at least this many sections ...
const PI10_MIN_SECTIONS: usize = 5;
/// ... whose largest inner perimeter is at least this many times their smallest (airways of
/// more than one size: the line's slope is what carries √WA to 10 mm).
const PI10_MIN_SPREAD: f64 = 1.5;

/// Pi10 (Nakano et al., Am J Respir Crit Care Med 2005): the square root of the wall area of a
/// hypothetical airway with an internal perimeter of 10 mm, read off the straight line fitted
/// by least squares to √WA (the wall's area, mm², between its inner and outer edges) against
/// Pi (the internal perimeter, mm) over the sections with an airway's wall: one figure for the
/// wall thickness of airways of every size, which COPD studies compare between patients and
/// over time (it rises with airway disease).
///
/// Pi is taken as the perimeter of the circle of the inner edge's area: the rays' inner edges
/// are jagged where a ray's peak is a neighbour's as well as the wall's, and a polygon's length
/// counts every jag (up to 1.6 times the circle's on the chest CT's distal bronchi, against
/// 1.02 on the trachea), while the walls measured are round (no more than twice as long as
/// they are wide: an ellipse of that shape is 9 % longer about than its circle). Each section
/// is one point, so that a long airway weighs more than a short one, where the studies take
/// one point an airway; and the walls are the half-maximum method's, which overstates the
/// thinnest (smaller airways, coarser voxels) and so raises Pi10 with them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pi10 {
    /// √WA at Pi = 10 mm, mm.
    pub value_mm: f64,
    /// The line: √WA = intercept + slope × Pi.
    pub intercept_mm: f64,
    pub slope: f64,
    /// How much of √WA's variance the line explains (r²).
    pub r2: f64,
    /// The sections it was fitted over.
    pub sections: usize,
    /// Their inner perimeters' range, mm.
    pub perimeter_range_mm: [f64; 2],
}

impl Pi10 {
    /// Pi10 of the airway walls on `sections` (measured at half maximum); or why there is
    /// none.
    pub fn of(sections: &[crate::lumen::Section]) -> Result<Pi10, String> {
        let points = pi10_points(sections);
        let n = points.len();
        if n < PI10_MIN_SECTIONS {
            return Err(format!(
                "{n} sections with an airway wall, fewer than the {PI10_MIN_SECTIONS} a line needs"
            ));
        }
        let lo = points.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let hi = points.iter().map(|p| p[0]).fold(0.0, f64::max);
        if hi < PI10_MIN_SPREAD * lo {
            return Err(format!(
                "the inner perimeters span only {lo:.1} to {hi:.1} mm: airways of one size, \
                 no slope to carry √WA to 10 mm (a path through airways of more than one size \
                 is needed)"
            ));
        }
        let k = n as f64;
        let mx = points.iter().map(|p| p[0]).sum::<f64>() / k;
        let my = points.iter().map(|p| p[1]).sum::<f64>() / k;
        let sxx: f64 = points.iter().map(|p| (p[0] - mx).powi(2)).sum();
        let sxy: f64 = points.iter().map(|p| (p[0] - mx) * (p[1] - my)).sum();
        let syy: f64 = points.iter().map(|p| (p[1] - my).powi(2)).sum();
        let slope = sxy / sxx;
        let intercept = my - slope * mx;
        Ok(Pi10 {
            value_mm: intercept + 10.0 * slope,
            intercept_mm: intercept,
            slope,
            r2: if syy > 0.0 {
                sxy * sxy / (sxx * syy)
            } else {
                1.0
            },
            sections: n,
            perimeter_range_mm: [lo, hi],
        })
    }

    /// 10 mm lies outside the inner perimeters fitted: the figure is the line's, extended.
    pub fn extrapolated(&self) -> bool {
        !(self.perimeter_range_mm[0]..=self.perimeter_range_mm[1]).contains(&10.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use raystream_math::DVec3;

    /// A profile `step` mm apart out to 20 mm: the lumen's gas (-1000 HU) to `r`, a wall of
    /// `hu` to `r + t`, and `beyond` past it, each change a linear ramp `blur` mm wide.
    fn profile(r: f64, t: f64, hu: f64, beyond: f64, blur: f64, step: f64) -> (Vec<f32>, usize) {
        let ramp = |x: f64, at: f64| (0.5 + (x - at) / blur).clamp(0.0, 1.0);
        let v: Vec<f32> = (0..=(20.0 / step) as usize)
            .map(|k| {
                let x = k as f64 * step;
                (-1000.0 + (hu + 1000.0) * ramp(x, r) + (beyond - hu) * ramp(x, r + t)) as f32
            })
            .collect();
        // The lumen at -500 HU, as `measure --dark --lumen -500` finds it.
        let last = v.iter().position(|&x| x > -500.0).unwrap() - 1;
        (v, last)
    }

    /// A wall with a plateau: its edges where the ramps are halfway, to the sample's
    /// rounding, whether lung, fat or something between lies beyond.
    #[test]
    fn a_wall_is_found_at_half_maximum() {
        for beyond in [-850.0, -100.0, -500.0] {
            for step in [0.25, 0.375, 0.4] {
                let (v, last) = profile(6.0, 3.0, 40.0, beyond, 1.0, step);
                let e = half_maximum(&v, last, step).unwrap();
                assert!((e.inner - 6.0).abs() < 1e-3, "{beyond} {step}: {e:?}");
                assert!(
                    (e.outer.unwrap() - 9.0).abs() < 1e-3,
                    "{beyond} {step}: {e:?}"
                );
            }
        }
    }

    /// A wall thinner than the blur: its peak (-256.67 HU at 4.75 mm) is far below its 40 HU,
    /// and the half maximum of that peak overstates it as the method does: worked by hand on
    /// the ramps, the inner edge at 3.7861 mm (-628.33 HU), the outer at 5.25 (-553.33).
    #[test]
    fn a_thin_wall_is_measured_from_its_blurred_peak() {
        let (v, last) = profile(4.0, 1.0, 40.0, -850.0, 1.5, 0.25);
        let top = v.iter().copied().fold(f32::MIN, f32::max);
        assert!((top + 256.667).abs() < 0.01, "{top}");
        let e = half_maximum(&v, last, 0.25).unwrap();
        assert!((e.inner - 3.786058).abs() < 1e-3, "{e:?}");
        assert!((e.outer.unwrap() - 5.25).abs() < 1e-3, "{e:?}");
    }

    /// A profile `step` mm apart out to 20 mm as a scanner blurs it (a Gaussian of `sigma`
    /// mm, summed numerically): the lumen's gas (-1000 HU) to `r`, a wall of `hu` to `r + t`,
    /// lung (-850) past it; and the lumen's last sample.
    fn blurred(r: f64, t: f64, hu: f64, sigma: f64, step: f64) -> (Vec<f32>, usize) {
        let sharp = |x: f64| {
            if x < r {
                -1000.0
            } else if x < r + t {
                hu
            } else {
                -850.0
            }
        };
        let du = sigma / 50.0;
        let (mut v, mut weight) = (Vec::new(), 0.0);
        for k in -250..=250 {
            weight += (-0.5 * (k as f64 * du / sigma).powi(2)).exp();
        }
        for i in 0..=(20.0 / step) as usize {
            let x = i as f64 * step;
            let sum: f64 = (-250..=250)
                .map(|k| {
                    let u = k as f64 * du;
                    sharp(x + u) * (-0.5 * (u / sigma).powi(2)).exp()
                })
                .sum();
            v.push((sum / weight) as f32);
        }
        // The lumen at -900 HU: at -500 the thinnest wall (its peak -726 HU) would be lumen.
        let last = v.iter().position(|&x| x > -900.0).unwrap() - 1;
        (v, last)
    }

    /// Under a Gaussian blur of 0.8 mm (a soft kernel's, 1.9 mm at half maximum) the wall's
    /// sum gives its thickness within 0.06 mm from 0.4 mm to 3 mm, where half maximum reads
    /// the thinnest over 1.3 mm too thick; a wall denser than the 40 HU assumed (100 HU)
    /// comes out at most the densities' ratio (6 %) thicker; and the integral's edges lie about
    /// the half-maximum edges' middle, which stays within 0.15 mm of the wall's (the lung's
    /// rise over the gas pulls it out by 0.13 mm on the thinnest).
    #[test]
    fn the_integral_measures_a_wall_thinner_than_the_blur() {
        for t in [0.4, 0.7, 1.0, 1.5, 3.0] {
            let (v, last) = blurred(5.0, t, 40.0, 0.8, 0.25);
            let e = half_maximum(&v, last, 0.25).unwrap();
            let integral = e.integral.unwrap();
            let width = e.outer.unwrap() - e.inner;
            assert!((integral - t).abs() < 0.06, "{t}: {e:?}");
            let middle = (e.inner + e.outer.unwrap()) / 2.0;
            assert!((middle - (5.0 + t / 2.0)).abs() < 0.15, "{t}: {e:?}");
            if t < 0.5 {
                assert!(width > t + 1.3, "{t}: {e:?}");
            }
            let (v, last) = blurred(5.0, t, 100.0, 0.8, 0.25);
            let dense = half_maximum(&v, last, 0.25).unwrap().integral.unwrap();
            assert!(dense > t - 0.06 && dense < t * 1.065 + 0.06, "{t}: {dense}");
        }
    }

    /// The inner edge alone where no dip follows the peak within reach (the wall against
    /// soft tissue), where the ray leaves the volume first, where something brighter than a
    /// wall comes first (its peak then the wall's plateau short of it), or where the dip is not
    /// to fat or lung; nothing where nothing rises past the lumen.
    #[test]
    fn no_outer_edge_without_a_dip_to_fat_or_lung() {
        let only_inner = |v: &[f32], last: usize| {
            let e = half_maximum(v, last, 0.25).unwrap();
            assert!((e.inner - 6.0).abs() < 1e-3 && e.outer.is_none(), "{e:?}");
        };
        let (v, last) = profile(6.0, 3.0, 40.0, 20.0, 1.0, 0.25);
        only_inner(&v, last);
        let (mut v, last) = profile(6.0, 3.0, 40.0, -850.0, 1.0, 0.25);
        for x in &mut v[(8.0 / 0.25) as usize..] {
            *x = f32::NAN;
        }
        only_inner(&v, last);
        // Something brighter than a wall within reach (contrast, a stent's wire), then lung.
        let (mut v, last) = profile(6.0, 3.0, 40.0, -850.0, 1.0, 0.25);
        for x in &mut v[(8.0 / 0.25) as usize..(10.0 / 0.25) as usize] {
            *x = 400.0;
        }
        only_inner(&v, last);
        // A dip below the peak into soft tissue, not fat or lung.
        let (v, last) = profile(6.0, 3.0, 150.0, 20.0, 1.0, 0.25);
        only_inner(&v, last);
        let v = vec![-1000.0f32; 80];
        assert_eq!(half_maximum(&v, 40, 0.25), None);
    }

    /// A neighbour past a gap of lung narrower than the dip's half: the lowest HU between
    /// them is the outer level, and the edge is still the wall's.
    #[test]
    fn a_neighbour_beyond_the_lung_is_not_the_wall() {
        let step = 0.25;
        let (mut v, last) = profile(6.0, 2.0, 40.0, -850.0, 1.0, step);
        for (k, x) in v.iter_mut().enumerate() {
            if k as f64 * step >= 11.0 {
                *x = 40.0;
            }
        }
        let e = half_maximum(&v, last, step).unwrap();
        assert!((e.outer.unwrap() - 8.0).abs() < 1e-3, "{e:?}");
    }

    /// A CT on a 1 mm grid `n` mm square and `nz` deep (LPS = index) whose HU at each voxel
    /// are `hu(its distance from c across z, its (x, y), its z)`.
    fn grid(n: usize, nz: usize, c: DVec2, hu: impl Fn(f64, DVec2, f64) -> f64) -> Volume {
        let data: Vec<f32> = (0..n * n * nz)
            .map(|k| {
                let p = DVec2::new((k % n) as f64, (k / n % n) as f64);
                hu(p.distance(c), p, (k / (n * n)) as f64) as f32
            })
            .collect();
        Volume::hounsfield([n, n, nz], [1.0; 3], data)
    }

    /// 0 to 1 across a boundary, over a ramp 1 mm wide about it (`sd`: signed distance, mm).
    fn ramp(sd: f64) -> f64 {
        (0.5 + sd).clamp(0.0, 1.0)
    }

    /// The airway's lumen centre in [`bronchus`] and [`tapered`].
    const BRONCHUS: DVec2 = DVec2::new(48.3, 47.6);
    const TAPERED: DVec2 = DVec2::new(24.3, 23.6);

    /// An airway 14 mm across in lung (-850 HU), its wall 3 mm thick (40 HU), on a 1 mm grid
    /// 96 mm square and 8 deep, each change a ramp 1 mm wide; beside it at 0°, pressed into the
    /// wall (no lung between them), a vessel 10 mm across of `vessel` HU.
    fn bronchus(vessel: f64) -> Volume {
        grid(96, 8, BRONCHUS, |r, p, _| {
            let v = -1000.0 + 1040.0 * ramp(r - 7.0) - 890.0 * ramp(r - 10.0);
            let near = p.distance(BRONCHUS + DVec2::new(13.0, 0.0));
            v + (vessel - v) * ramp(5.0 - near)
        })
    }

    /// `measure --dark --lumen -500 --field FIELD --wall` of `vol`'s `n` sections along z
    /// through `c`, from `z0` to `z1`, with `wall`.
    fn along_z(
        (vol, field_mm): (&Volume, f64),
        c: DVec2,
        [z0, z1]: [f64; 2],
        n: u32,
        wall: &WallOptions,
    ) -> Vec<crate::lumen::Section> {
        let opt = LumenOptions {
            threshold_hu: -500.0,
            dark: true,
            field_mm,
            ..LumenOptions::for_volume(vol)
        };
        let path = [c.extend(z0), c.extend(z1)];
        crate::lumen::measure_path(vol, &path, n, DVec3::X, &opt, Some(wall)).unwrap()
    }

    /// `measure --dark --lumen -500 --wall` on the section through the bronchus, at half
    /// maximum or by the integral: its wall 3 mm thick, its inner and outer areas the circles'
    /// of 7 and 10 mm (WA % 51), whether the vessel beside it is unenhanced (as thick as the
    /// wall: one peak, too wide) or contrast-filled (brighter than a wall); the rays towards it
    /// see no edges of their own.
    #[test]
    fn a_bronchus_wall_is_measured_beside_a_vessel() {
        for (vessel, wall) in [40.0, 400.0].into_iter().flat_map(|v| {
            [
                (v, WallOptions::airway()),
                (v, WallOptions::airway_integral()),
            ]
        }) {
            let vol = bronchus(vessel);
            let s = &along_z((&vol, 90.0), BRONCHUS, [1.0, 6.0], 1, &wall)[0];
            let w = s.wall.as_ref().unwrap();
            let pi = std::f64::consts::PI;
            let what = format!("{vessel} {:?}: {w:?}", wall.edge);
            assert!((w.mean_thickness_mm - 3.0).abs() < 0.1, "{what}");
            assert!(
                (w.inner_area_mm2 / (pi * 49.0) - 1.0).abs() < 0.03,
                "{what}"
            );
            assert!((w.area_mm2 / (pi * 100.0) - 1.0).abs() < 0.03, "{what}");
            assert!((w.area_percent() - 51.0).abs() < 2.0, "{what}");
            assert!((w.circle_diameter_mm - 20.0).abs() < 0.3, "{what}");
            assert!((0.6..0.95).contains(&w.seen), "{what}");
            assert!(w.centre.truncate().distance(BRONCHUS) < 0.3);
        }
    }

    /// An airway along z in lung (-850 HU) on a 1 mm grid 48 mm square and 44 deep,
    /// narrowing as it goes up: its lumen's radius 1.2 + 0.12 z mm, its wall (40 HU)
    /// 0.8 + 0.04 z mm thick, each change a ramp 1 mm wide.
    fn tapered() -> Volume {
        grid(48, 44, TAPERED, |d, _, z| {
            let (r, t) = (1.2 + 0.12 * z, 0.8 + 0.04 * z);
            -1000.0 + 1040.0 * ramp(d - r) - 890.0 * ramp(d - r - t)
        })
    }

    /// Pi10 of the tapered airway, by the integral, within 0.15 mm of the line fitted to its
    /// true walls on the same sections (Pi 2π r, WA π((r + t)² − r²)), 10 mm among the
    /// perimeters fitted; at half maximum its walls under 1.3 mm read too thick, and Pi10 over
    /// 0.3 mm too high.
    #[test]
    fn pi10_is_read_off_the_line_through_the_walls() {
        let vol = tapered();
        let measured = |wall: WallOptions| {
            let s = along_z((&vol, 40.0), TAPERED, [2.0, 40.0], 19, &wall);
            (Pi10::of(&s).unwrap(), s)
        };
        let (by_integral, sections) = measured(WallOptions::airway_integral());
        let (at_half, _) = measured(WallOptions::airway());
        // The true walls on the sections with one, and the line through them by hand.
        let truth: Vec<[f64; 2]> = sections
            .iter()
            .filter(|s| s.wall.is_some())
            .map(|s| {
                let z = s.row.centre.z as f64;
                let (r, t) = (1.2 + 0.12 * z, 0.8 + 0.04 * z);
                let pi = std::f64::consts::PI;
                [2.0 * pi * r, (pi * ((r + t).powi(2) - r * r)).sqrt()]
            })
            .collect();
        assert!(truth.len() >= 17, "{}", truth.len());
        let k = truth.len() as f64;
        let [mx, my] = [0, 1].map(|i| truth.iter().map(|p| p[i]).sum::<f64>() / k);
        let sxy: f64 = truth.iter().map(|p| (p[0] - mx) * (p[1] - my)).sum();
        let sxx: f64 = truth.iter().map(|p| (p[0] - mx).powi(2)).sum();
        let ideal = my + (10.0 - mx) * sxy / sxx;
        assert!(
            (by_integral.value_mm - ideal).abs() < 0.15,
            "{ideal}: {by_integral:?}"
        );
        assert!(
            !by_integral.extrapolated() && by_integral.r2 > 0.95,
            "{by_integral:?}"
        );
        assert_eq!(by_integral.sections, truth.len());
        assert!(at_half.value_mm > ideal + 0.3, "{ideal}: {at_half:?}");
        for s in &sections {
            let w = s.wall.as_ref().unwrap();
            let t = 0.8 + 0.04 * s.row.centre.z as f64;
            assert!((w.mean_thickness_mm - t).abs() < 0.15, "{t}: {w:?}");
        }
    }

    /// Pi10 needs five sections with a wall, of more than one size.
    #[test]
    fn pi10_needs_airways_of_more_than_one_size() {
        let vol = bronchus(40.0);
        let wall = WallOptions::airway();
        let few = along_z((&vol, 90.0), BRONCHUS, [1.0, 6.0], 3, &wall);
        assert!(Pi10::of(&few).unwrap_err().contains("3 sections"));
        let one = along_z((&vol, 90.0), BRONCHUS, [1.0, 6.0], 5, &wall);
        assert!(Pi10::of(&one).unwrap_err().contains("one size"));
    }

    /// A bright lumen's options, or a wall at half maximum about one, are refused; and a
    /// vessel's wall about a dark lumen.
    #[test]
    fn a_wall_at_half_maximum_is_an_airway_s() {
        let vol = bronchus(40.0);
        let bright = LumenOptions::for_volume(&vol);
        let dark = LumenOptions {
            threshold_hu: -500.0,
            dark: true,
            ..bright
        };
        let airway = WallOptions::airway();
        let vessel = WallOptions::default();
        assert!(airway.check(&dark).is_ok() && vessel.check(&bright).is_ok());
        assert!(airway.check(&bright).unwrap_err().contains("dark lumen"));
        assert!(vessel.check(&dark).unwrap_err().contains("bright lumen"));
    }

    /// Rays without edges take their neighbours', by angle, round the circle's end too.
    #[test]
    fn missing_edges_are_interpolated_by_angle() {
        let e = |r: f64| {
            Some(Edges {
                inner: r,
                outer: r + 2.0,
            })
        };
        let filled = interpolated(&[None, e(4.0), None, None, e(7.0), None]);
        let inner: Vec<f64> = filled.iter().map(|e| e.inner).collect();
        assert_eq!(inner, [5.0, 4.0, 5.0, 6.0, 7.0, 6.0]);
        assert!(filled.iter().all(|e| e.outer - e.inner == 2.0));
    }
}
