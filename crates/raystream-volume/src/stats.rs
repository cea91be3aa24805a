//! Statistics of a volume's values over a set of its voxels (a segment's): what a radiologist
//! reads off a region of interest — its volume, the mean Hounsfield units and their spread,
//! the extremes and the median, and where its centre lies.

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
    let mut values: Vec<f64> = indices
        .iter()
        .map(|&n| volume.data[n] as f64)
        .filter(|v| v.is_finite())
        .collect();
    if values.is_empty() {
        return None;
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let sd = if values.len() > 1 {
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    let (min, max) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let (half, odd) = (values.len() / 2, values.len() % 2 == 1);
    let (below, &mut upper, _) = values.select_nth_unstable_by(half, f64::total_cmp);
    let median = if odd {
        upper
    } else {
        let lower = below.iter().copied().fold(f64::NEG_INFINITY, f64::max);
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

#[cfg(test)]
mod tests {
    use super::*;

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
