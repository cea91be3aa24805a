//! Statistics of a volume's values over a set of its voxels (a segment's): what a radiologist
//! reads off a region of interest — its volume, the mean Hounsfield units and their spread,
//! the extremes and the median, and where its centre lies; and the densitometry a lung's CT is
//! read by (the share of voxels below a HU, as the emphysema index LAA-950; a percentile, as
//! Perc15).

use crate::clusters::{Clusters, Connectivity};
use raystream_io::Volume;
use raystream_math::DVec3;

/// A region's statistics. The values' are over its finite values (a NaN voxel counts in its
/// volume, not in its values); `sd` is the sample standard deviation (n − 1, as ITK's
/// LabelStatisticsImageFilter), the median the middle value (the mean of the two middle ones
/// for an even count, as numpy's).
#[derive(Clone, Debug, PartialEq)]
pub struct RegionStats {
    pub voxels: usize,
    /// Its volume, millilitres.
    pub ml: f64,
    pub mean: f64,
    pub sd: f64,
    pub min: f64,
    pub median: f64,
    pub max: f64,
    /// The mean of its voxels' centres, LPS millimetres.
    pub centroid: [f64; 3],
}

/// The statistics of `volume`'s values over the voxels `indices` (into [`Volume::data`]);
/// `None` for no voxel, or none with a finite value.
pub fn region_stats(volume: &Volume, indices: &[usize]) -> Option<RegionStats> {
    let [nx, ny, _] = volume.dims;
    let mut values = finite_values(volume, indices)?;
    let n = values.len() as f64;
    let mean = values.iter().map(|&v| v as f64).sum::<f64>() / n;
    let sd = if values.len() > 1 {
        (values
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0))
            .sqrt()
    } else {
        0.0
    };
    let (min, max) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v as f64), b.max(v as f64))
        });
    let half = values.len() / 2;
    let median = if values.len() % 2 == 1 {
        ranks(&mut values, half).0
    } else {
        let (lower, upper) = ranks(&mut values, half - 1);
        0.5 * (lower + upper)
    };
    let sum = indices.iter().fold(DVec3::ZERO, |s, &i| {
        s + DVec3::new(
            (i % nx) as f64,
            ((i / nx) % ny) as f64,
            (i / (nx * ny)) as f64,
        )
    });
    let centroid = volume.index_to_world(sum / indices.len() as f64).to_array();
    Some(RegionStats {
        voxels: indices.len(),
        ml: indices.len() as f64 * volume.voxel_ml(),
        mean,
        sd,
        min,
        median,
        max,
        centroid,
    })
}

/// The finite values of `volume` at `indices`; `None` for none. Kept as the volume holds them,
/// in f32 (half the memory of f64, for a region of a whole body; every sum is taken in f64).
fn finite_values(volume: &Volume, indices: &[usize]) -> Option<Vec<f32>> {
    let values: Vec<f32> = indices
        .iter()
        .map(|&n| volume.data[n])
        .filter(|v| v.is_finite())
        .collect();
    (!values.is_empty()).then_some(values)
}

/// The values at ranks `lo` and `lo + 1` of `values` in increasing order (at `lo` twice for
/// the last rank), found by selection, which reorders `values`: the median's two middle
/// values, a percentile's two nearest ranks.
fn ranks(values: &mut [f32], lo: usize) -> (f64, f64) {
    let (_, &mut at, above) = values.select_nth_unstable_by(lo, f32::total_cmp);
    let next = above.iter().copied().fold(f32::INFINITY, f32::min);
    let at = at as f64;
    (at, if above.is_empty() { at } else { next as f64 })
}

/// A region's densitometry: for each HU asked, the voxels below it; for each percentile asked,
/// the value there.
#[derive(Clone, Debug, PartialEq)]
pub struct Densitometry {
    pub below: Vec<Below>,
    /// (p, the value at p), p from 0 to 100.
    pub percentiles: Vec<(f64, f64)>,
}

/// The voxels of a region below a value: in COPD the emphysema index LAA-950 (the low
/// attenuation area, the share of a lung's voxels below −950 HU on an inspiratory CT), and
/// below −856 HU on an expiratory one, air trapping.
#[derive(Clone, Debug, PartialEq)]
pub struct Below {
    /// The value they are below (strictly: `hu` itself is not below).
    pub hu: f64,
    pub voxels: usize,
    pub ml: f64,
    /// Their share of the region's voxels with a finite value, per cent.
    pub percent: f64,
    /// The clusters they make, where asked.
    pub clusters: Option<Clusters>,
}

/// `volume`'s values over the voxels `indices`: for each of `below`, those below it; for each
/// of `percentiles` (0 to 100), the value at it, interpolated linearly between the two
/// nearest ranks (numpy's default, type 7 of Hyndman and Fan; Perc15, the lung densitometry
/// QIBA profiles, is the 15th); with `clusters`, the clusters the voxels below each value
/// make, so joined. `None` for no voxel with a finite value.
pub fn densitometry(
    volume: &Volume,
    indices: &[usize],
    below: &[f64],
    percentiles: &[f64],
    clusters: Option<Connectivity>,
) -> Option<Densitometry> {
    let mut values = finite_values(volume, indices)?;
    let n = values.len();
    let below = below
        .iter()
        .map(|&hu| {
            let voxels = values.iter().filter(|&&v| (v as f64) < hu).count();
            Below {
                hu,
                voxels,
                ml: voxels as f64 * volume.voxel_ml(),
                percent: 100.0 * voxels as f64 / n as f64,
                clusters: clusters.map(|c| crate::clusters::clusters(volume, indices, hu, c)),
            }
        })
        .collect();
    let percentiles = percentiles
        .iter()
        .map(|&p| {
            let rank = (n - 1) as f64 * p.clamp(0.0, 100.0) / 100.0;
            let lo = (rank.floor() as usize).min(n - 1);
            let (at, next) = ranks(&mut values, lo);
            let frac = rank - lo as f64;
            let value = if frac > 0.0 {
                at + frac * (next - at)
            } else {
                at
            };
            (p, value)
        })
        .collect();
    Some(Densitometry { below, percentiles })
}

/// A region's tissue mass in grams from its volume and mean HU, as lung weight is found from CT:
/// each voxel's density taken as (HU + 1000) / 1000 g/ml, water's 1 and air's 0 (Gattinoni's
/// lung weight; a fair measure for lung and soft tissue, not for bone, whose HU outgrow its
/// density).
pub fn mass_g(ml: f64, mean_hu: f64) -> f64 {
    ml * (mean_hu + 1000.0) / 1000.0
}

/// A lung's density adjusted for the depth of the breath by the sponge model (Shaker et al.,
/// Acta Radiologica 2004; the adjustment of the trials of alpha-1 antitrypsin augmentation):
/// the lung's tissue mass stays as it breathes, so that its density, HU + 1000 g/l, scales as
/// the inverse of its volume. A value measured at `measured_ml` is the one the lung would show
/// at `reference_ml` (its predicted total lung capacity, or its volume on an earlier CT).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inflation {
    pub measured_ml: f64,
    pub reference_ml: f64,
}

impl Inflation {
    /// measured / reference: below 1 for a breath short of the reference.
    pub fn factor(&self) -> f64 {
        self.measured_ml / self.reference_ml
    }

    /// `hu` measured, at the reference volume.
    pub fn adjust(&self, hu: f64) -> f64 {
        (hu + 1000.0) * self.factor() - 1000.0
    }
}

/// Sex, for a predicted lung volume.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sex {
    Male,
    Female,
}

/// The total lung capacity predicted for an adult of `height_cm` in ml, by the equations of
/// the ECSC and the ERS (Quanjer et al., Eur Respir J 1993; 6 Suppl 16: 5–40): 7.99 H − 7.08
/// litres for men, 6.60 H − 5.79 for women, H in metres (fit over heights of 1.55 to 1.95 m
/// for men and 1.45 to 1.80 m for women, ages 18 to 70).
pub fn predicted_tlc_ml(sex: Sex, height_cm: f64) -> f64 {
    let h = height_cm / 100.0;
    let litres = match sex {
        Sex::Male => 7.99 * h - 7.08,
        Sex::Female => 6.60 * h - 5.79,
    };
    litres * 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn densitometry_counts_below_and_interpolates_percentiles_as_numpy() {
        // 0..99 shuffled on a 10×10×1 grid of 2 × 2 × 2.5 mm voxels, one NaN (voxel 0, 0.0).
        let mut data: Vec<f32> = (0..100).map(|x| ((x * 37) % 100) as f32).collect();
        let nan = data.iter().position(|&x| x == 0.0).unwrap();
        data[nan] = f32::NAN;
        let v = Volume::hounsfield([10, 10, 1], [2.0, 2.0, 2.5], data);
        let all: Vec<usize> = (0..100).collect();
        let d = densitometry(
            &v,
            &all,
            &[15.0, 1.0, 1000.0],
            &[0.0, 15.0, 50.0, 100.0],
            None,
        )
        .unwrap();
        // 1..99: below 15 are 1..14, 14 of 99; below 1 none (strictly); below 1000 all.
        let counts: Vec<usize> = d.below.iter().map(|b| b.voxels).collect();
        assert_eq!(counts, [14, 0, 99]);
        assert!((d.below[0].percent - 1400.0 / 99.0).abs() < 1e-12);
        assert!((d.below[0].ml - 14.0 * 0.01).abs() < 1e-12);
        // numpy.percentile(np.arange(1, 100), [0, 15, 50, 100]) = 1, 15.7, 50, 99.
        let got: Vec<f64> = d.percentiles.iter().map(|&(_, x)| x).collect();
        for (g, want) in got.iter().zip([1.0, 15.7, 50.0, 99.0]) {
            assert!((g - want).abs() < 1e-9, "{got:?}");
        }
        assert_eq!(d.percentiles[1].0, 15.0);
        // One value: every percentile is it.
        let d = densitometry(&v, &[5], &[], &[0.0, 37.5, 100.0], None).unwrap();
        let x = v.data[5] as f64;
        assert!(d.percentiles.iter().all(|&(_, p)| p == x));
        assert!(densitometry(&v, &[nan], &[0.0], &[15.0], None).is_none());
        assert!(densitometry(&v, &[], &[0.0], &[15.0], None).is_none());
    }

    #[test]
    fn the_sponge_model_keeps_the_mass() {
        // A lung of 4 l at -850 HU: 600 g. Inflated to 6 l (factor 2/3) it keeps its 600 g,
        // at -900 HU; at its own volume nothing moves; air stays air.
        let at = Inflation {
            measured_ml: 4000.0,
            reference_ml: 6000.0,
        };
        assert!((mass_g(4000.0, -850.0) - 600.0).abs() < 1e-9);
        assert!((at.factor() - 2.0 / 3.0).abs() < 1e-15);
        assert!((at.adjust(-850.0) + 900.0).abs() < 1e-9);
        assert!((mass_g(6000.0, at.adjust(-850.0)) - 600.0).abs() < 1e-9);
        assert_eq!(at.adjust(-1000.0), -1000.0);
        let same = Inflation {
            measured_ml: 5123.4,
            reference_ml: 5123.4,
        };
        assert!((same.adjust(-912.25) + 912.25).abs() < 1e-12);
        // A breath deeper than the reference (factor above 1): at the reference the lung is
        // denser, 100 g/l × 1.25.
        let deep = Inflation {
            measured_ml: 5000.0,
            reference_ml: 4000.0,
        };
        assert!((deep.adjust(-900.0) + 875.0).abs() < 1e-9);
        // Quanjer 1993: a man of 1.80 m 7.302 l, a woman of 1.65 m 5.10 l.
        assert!((predicted_tlc_ml(Sex::Male, 180.0) - 7302.0).abs() < 1e-6);
        assert!((predicted_tlc_ml(Sex::Female, 165.0) - 5100.0).abs() < 1e-6);
    }

    #[test]
    fn stats_of_a_known_region() {
        // Values 0..24 on a 4×3×2 grid of 2 mm voxels; the region: the odd ones, and a NaN.
        let mut v = Volume::hounsfield(
            [4, 3, 2],
            [2.0, 2.0, 2.0],
            (0..24).map(|x| x as f32).collect(),
        );
        v.data[0] = f32::NAN;
        let odd: Vec<usize> = (0..24).filter(|i| i % 2 == 1).chain([0]).collect();
        let s = region_stats(&v, &odd).unwrap();
        assert_eq!(s.voxels, 13);
        assert!((s.ml - 13.0 * 0.008).abs() < 1e-12);
        // 1, 3, …, 23: mean 12, median 12 (the mean of 11 and 13), sample sd sqrt(52).
        assert_eq!((s.mean, s.min, s.median, s.max), (12.0, 1.0, 12.0, 23.0));
        assert!((s.sd - 52f64.sqrt()).abs() < 1e-12, "{}", s.sd);
        // The centres' mean: i 1 and 3 alternate rows (and voxel 0): over 13 voxels.
        let sum: DVec3 = odd
            .iter()
            .map(|&i| DVec3::new((i % 4) as f64, ((i / 4) % 3) as f64, (i / 12) as f64))
            .sum();
        let want = v.index_to_world(sum / 13.0).to_array();
        assert_eq!(s.centroid, want);
        // Odd count: the middle value.
        let s = region_stats(&v, &[5, 9, 7]).unwrap();
        assert_eq!((s.median, s.sd), (7.0, 2.0));
        assert!(region_stats(&v, &[]).is_none());
        assert!(region_stats(&v, &[0]).is_none());
    }
}
