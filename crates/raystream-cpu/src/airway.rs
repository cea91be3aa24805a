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
//! Written here: the method is a few dozen lines of 1-D profile analysis on the sections that
//! `lumen` samples, and no crate does it.

use raystream_io::Volume;
use raystream_math::DVec2;

use crate::cpr::CprRow;
use crate::dvr::Marcher;
use crate::lumen::{self, Lumen, LumenOptions, Segmented};
use crate::wall::{Circle, Outline, Wall, polygon_area};

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
/// mm from where the ray starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RayWall {
    pub inner: f64,
    pub outer: Option<f64>,
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
    Some(RayWall {
        inner,
        outer: if dip {
            outer_edge(v, peak, k, step)
        } else {
            None
        },
    })
}

/// The outer edge at half maximum on a ray's samples `v` past the wall's `peak`, the HU
/// having fallen [`DIP_HU`] below it at sample `k`: halfway from the peak to the lowest HU
/// beyond it; none where that is not fat or lung.
fn outer_edge(v: &[f32], peak: usize, k: usize, step: f64) -> Option<f64> {
    let reach = reach_samples(step);
    let top = v[peak];
    // The lowest HU beyond it, until they rise again by half the dip (a neighbour).
    let mut low = v[k];
    for &x in v
        .iter()
        .take((peak + reach).min(v.len() - 1) + 1)
        .skip(k + 1)
    {
        if !x.is_finite() || x > low + 0.5 * DIP_HU {
            break;
        }
        low = low.min(x);
    }
    if low > OUTSIDE_MAX_HU {
        return None;
    }
    let outer_half = 0.5 * (top + low);
    let o = (peak + 1..v.len()).find(|&j| v[j] <= outer_half)?;
    Some(crossing(v[o - 1], v[o], outer_half, o - 1, step))
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
    rays: usize,
    g: &Segmented,
    lumen: &Lumen,
) -> Option<(Wall, Outline)> {
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
    let thickness = |f: &RayWall| f.outer.map(|o| o - f.inner);
    let median = |mut t: Vec<f64>| {
        t.sort_by(f64::total_cmp);
        t.get(t.len() / 2).copied()
    };
    let all_seen = median(found.iter().flatten().filter_map(thickness).collect())?;
    for f in found.iter_mut().flatten() {
        if thickness(f).is_some_and(|t| t > OUTLIER * all_seen) {
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
    // Past an inner edge alone, the section's median thickness; neither edge seen, the
    // neighbours'.
    let typical = median(kept.clone())?;
    let edges: Vec<Option<Edges>> = found
        .iter()
        .map(|f| {
            f.map(|f| Edges {
                inner: f.inner,
                outer: f.outer.unwrap_or(f.inner + typical),
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

    /// An airway 14 mm across in lung (-850 HU), its wall 3 mm thick (40 HU), on a 1 mm grid
    /// 96 mm square and 8 deep (LPS = index), each change a ramp 1 mm wide; beside it at 0°,
    /// pressed into the wall (no lung between them), a vessel 10 mm across of `vessel` HU.
    fn bronchus(vessel: f64) -> Volume {
        let (n, nz) = (96, 8);
        let c = DVec2::new(48.3, 47.6);
        let ramp = |sd: f64| (0.5 + sd).clamp(0.0, 1.0);
        let data: Vec<f32> = (0..n * n * nz)
            .map(|k| {
                let p = DVec2::new((k % n) as f64, (k / n % n) as f64);
                let r = p.distance(c);
                let v = -1000.0 + 1040.0 * ramp(r - 7.0) - 890.0 * ramp(r - 10.0);
                let near = p.distance(c + DVec2::new(13.0, 0.0));
                (v + (vessel - v) * ramp(5.0 - near)) as f32
            })
            .collect();
        Volume::hounsfield([n, n, nz], [1.0; 3], data)
    }

    /// `measure --dark --lumen -500 --wall` on the section through the bronchus: its wall
    /// 3 mm thick, its inner and outer areas the circles' of 7 and 10 mm (WA % 51), whether
    /// the vessel beside it is unenhanced (as thick as the wall: one peak, too wide) or
    /// contrast-filled (brighter than a wall); the rays towards it see no edges of their own.
    #[test]
    fn a_bronchus_wall_is_measured_beside_a_vessel() {
        for vessel in [40.0, 400.0] {
            let vol = bronchus(vessel);
            let path = [DVec3::new(48.3, 47.6, 1.0), DVec3::new(48.3, 47.6, 6.0)];
            let opt = LumenOptions {
                threshold_hu: -500.0,
                dark: true,
                field_mm: 90.0,
                ..LumenOptions::for_volume(&vol)
            };
            let wall = crate::wall::WallOptions::airway();
            let s = &crate::lumen::measure_path(&vol, &path, 1, DVec3::X, &opt, Some(&wall))
                .unwrap()[0];
            let w = s.wall.as_ref().unwrap();
            let pi = std::f64::consts::PI;
            assert!((w.mean_thickness_mm - 3.0).abs() < 0.1, "{vessel}: {w:?}");
            assert!((w.inner_area_mm2 / (pi * 49.0) - 1.0).abs() < 0.03, "{w:?}");
            assert!((w.area_mm2 / (pi * 100.0) - 1.0).abs() < 0.03, "{w:?}");
            assert!((w.area_percent() - 51.0).abs() < 2.0, "{w:?}");
            assert!((w.circle_diameter_mm - 20.0).abs() < 0.3, "{w:?}");
            assert!((0.6..0.95).contains(&w.seen), "{vessel}: {w:?}");
            assert!(w.centre.truncate().distance(DVec2::new(48.3, 47.6)) < 0.3);
        }
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
        let airway = crate::wall::WallOptions::airway();
        let vessel = crate::wall::WallOptions::default();
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
