//! Defaults for volumes whose values have no known unit (8-bit scientific-visualisation scans,
//! MR, a CT stored without its rescale): the HU presets mean nothing there (a bone threshold of
//! 300 lies above an 8-bit scan's every value, and CT-Bone's ramp makes it a uniform pink box),
//! so the thresholds, transfer functions and windows come from the values themselves.

use rayon::prelude::*;

use raystream_io::Volume;

use crate::tf::{Shading, TransferFunction};

/// Bins of [`otsu_threshold`]'s histogram: one a value for 8-bit data.
pub const OTSU_BINS: usize = 256;

/// The finite values' range, `None` where there are none.
pub fn finite_range(values: &[f32]) -> Option<(f32, f32)> {
    let (lo, hi) = values
        .par_iter()
        .filter(|v| v.is_finite())
        .fold(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |(lo, hi), &v| (lo.min(v), hi.max(v)),
        )
        .reduce(
            || (f32::INFINITY, f32::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    (lo <= hi).then_some((lo, hi))
}

/// Share of the finite values [`clipped_range`] leaves out at each end of an auto-contrast
/// window: 0.5 %, a few saturated pixels either way (ImageJ's auto-contrast saturates 0.35 % in
/// all), so that a handful of outliers (a metal clip, a hot pixel) do not set the span.
pub const CLIPPED_TAIL: f64 = 0.005;

/// Share of the finite values left out at each end of the span the defaults take as the
/// values' range ([`robust_range`]): one in 10⁴, so that a few outlying voxels (one hot voxel
/// of 10,000 in an 8-bit scan made its ramp transparent and its window black) do not set it,
/// while a scan's brightest structures, whose voxels are many more, still do.
pub const OUTLIER_TAIL: f64 = 1e-4;

/// Bins of each pass of [`order_statistic`]'s histogram.
const RANK_BINS: usize = 4096;

/// Values few enough for [`order_statistic`] to gather and select among.
const RANK_GATHER: usize = 1 << 16;

/// The finite value of rank `rank` (0 the smallest) among `values`, NaN and ±∞ left out:
/// exactly the value a sort of the finite values puts there. `None` where `rank` is not below
/// their count. Found without copying the values (a 512³ volume's would be 0.5 GB): each pass
/// bins the values still in play into `RANK_BINS` bins over their range, keeps the bin
/// holding the rank (binning is monotonic, so a bin holds a run of ranks, and its smallest
/// and largest values bound it exactly), and stops when the values in play are all one or
/// few enough (`RANK_GATHER`) to select among. Each pass narrows the range at least
/// `RANK_BINS`-fold, for its smallest and largest values fall in the first and last bins.
pub fn order_statistic(values: &[f32], rank: usize) -> Option<f32> {
    rank_within(values, finite_range(values)?, rank)
}

/// [`order_statistic`], the finite values' range `(lo, hi)` known.
fn rank_within(values: &[f32], (mut lo, mut hi): (f32, f32), mut rank: usize) -> Option<f32> {
    loop {
        if lo == hi {
            // All in play are one value; the first pass checks that the rank lies among them.
            return (rank < values.par_iter().filter(|v| **v == lo).count()).then_some(lo);
        }
        let in_play = |v: &f32| *v >= lo && *v <= hi;
        let width = (hi as f64 - lo as f64) / RANK_BINS as f64;
        let bin = |v: f32| (((v as f64 - lo as f64) / width) as usize).min(RANK_BINS - 1);
        // Each bin's count, smallest and largest value.
        let empty = || vec![(0usize, f32::INFINITY, f32::NEG_INFINITY); RANK_BINS];
        let bins = values
            .par_chunks(1 << 16)
            .map(|run| {
                let mut b = empty();
                for &v in run.iter().filter(|v| in_play(v)) {
                    let e = &mut b[bin(v)];
                    *e = (e.0 + 1, e.1.min(v), e.2.max(v));
                }
                b
            })
            .reduce(empty, |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    *x = (x.0 + y.0, x.1.min(y.1), x.2.max(y.2));
                }
                a
            });
        let count: usize = bins.iter().map(|b| b.0).sum();
        if rank >= count {
            return None;
        }
        if count <= RANK_GATHER {
            let mut run: Vec<f32> = values.par_iter().copied().filter(in_play).collect();
            return Some(*run.select_nth_unstable_by(rank, f32::total_cmp).1);
        }
        let mut seen = 0;
        for &(n, min, max) in &bins {
            if rank < seen + n {
                rank -= seen;
                (lo, hi) = (min, max);
                break;
            }
            seen += n;
        }
    }
}

/// The range of the finite values less a `tail` share at each end: from the value of rank
/// ⌊tail·(n − 1)⌋ to that of rank ⌈(1 − tail)·(n − 1)⌉ in ascending order (exact order
/// statistics, [`order_statistic`]; `tail` in 0 .. ½). `None` where no value is finite.
pub fn clipped_range(values: &[f32], tail: f64) -> Option<(f32, f32)> {
    let range = finite_range(values)?;
    let last = values.par_iter().filter(|v| v.is_finite()).count() - 1;
    let tail = tail.clamp(0.0, 0.5);
    let lo_rank = (tail * last as f64).floor() as usize;
    let hi_rank = (((1.0 - tail) * last as f64).ceil() as usize).clamp(lo_rank, last);
    Some((
        rank_within(values, range, lo_rank)?,
        rank_within(values, range, hi_rank)?,
    ))
}

/// The span the defaults take as the finite values' range: [`clipped_range`] less
/// [`OUTLIER_TAIL`] at each end (fewer than 10⁴ values: their whole range).
pub fn robust_range(values: &[f32]) -> Option<(f32, f32)> {
    clipped_range(values, OUTLIER_TAIL)
}

/// Otsu's threshold of the finite values (NaN and ±∞ left out): the value that splits them
/// into the two classes (below it, and at or above it) whose between-class variance is
/// largest, over a histogram of [`OTSU_BINS`] bins spanning their [`robust_range`] (values
/// beyond it counted in the end bins, so that a few outliers neither widen the bins nor
/// weigh as far as they lie; a class boundary is a bin's edge). The background and the object
/// of a scan are such classes. `None` where that range is one value.
pub fn otsu_threshold(values: &[f32]) -> Option<f32> {
    otsu_threshold_within(values, robust_range(values)?)
}

/// [`otsu_threshold`] over a histogram spanning `(lo, hi)`, values beyond it counted in the end
/// bins.
fn otsu_threshold_within(values: &[f32], (lo, hi): (f32, f32)) -> Option<f32> {
    if hi <= lo {
        return None;
    }
    let width = (hi as f64 - lo as f64) / OTSU_BINS as f64;
    let bin = |v: f32| (((v.clamp(lo, hi) as f64 - lo as f64) / width) as usize).min(OTSU_BINS - 1);
    let counts = values
        .par_chunks(1 << 16)
        .map(|run| {
            let mut c = vec![0u64; OTSU_BINS];
            for v in run.iter().filter(|v| v.is_finite()) {
                c[bin(*v)] += 1;
            }
            c
        })
        .reduce(
            || vec![0u64; OTSU_BINS],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        );
    // Each bin's values stand at its centre.
    let centre = |k: usize| lo as f64 + (k as f64 + 0.5) * width;
    let n: f64 = counts.iter().map(|&c| c as f64).sum();
    let sum: f64 = (0..OTSU_BINS).map(|k| counts[k] as f64 * centre(k)).sum();
    let (mut w0, mut sum0) = (0.0f64, 0.0f64);
    let mut best: Option<(f64, usize)> = None;
    // The split after bin k: bins 0..=k below, the rest at or above.
    for (k, &c) in counts.iter().enumerate().take(OTSU_BINS - 1) {
        w0 += c as f64;
        sum0 += c as f64 * centre(k);
        let w1 = n - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let d = sum0 / w0 - (sum - sum0) / w1;
        let between = w0 * w1 * d * d;
        if best.is_none_or(|(b, _)| between > b) {
            best = Some((between, k));
        }
    }
    best.map(|(_, k)| (lo as f64 + (k + 1) as f64 * width) as f32)
}

/// Of the pairs of neighbouring voxels along the first axis of a `dims` grid holding at
/// least one non-zero value, the share holding equal values: near 1 for a label map (piecewise
/// constant: only its segments' borders differ), near 0 for a scan (its noise differs voxel to
/// voxel: 0.12 on the 8-bit SciVis bonsai and engine, 0.03 on a CT). 0 where no pair holds a
/// non-zero value.
pub fn equal_neighbour_share(dims: [usize; 3], data: &[f32]) -> f64 {
    let (equal, pairs) = data
        .par_chunks(dims[0].max(1))
        .map(|row| {
            row.windows(2)
                .filter(|w| w[0] != 0.0 || w[1] != 0.0)
                .fold((0u64, 0u64), |(e, n), w| (e + (w[0] == w[1]) as u64, n + 1))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if pairs == 0 {
        0.0
    } else {
        equal as f64 / pairs as f64
    }
}

impl TransferFunction {
    /// For values of no known unit: opacity rising linearly from 0 at `lo` to `opacity` (per
    /// mm) at `hi` (as ParaView's default ramps opacity over the data's range), the colour from
    /// a dark warm brown through ochre to near-white over the same span (CT-Bone's palette), and
    /// CT-Bone's shading. `lo < hi`.
    pub fn ramp(lo: f32, hi: f32, opacity: f32) -> TransferFunction {
        let at = |f: f32| lo + f * (hi - lo);
        TransferFunction {
            opacity: vec![(lo, 0.0), (hi, opacity)],
            color: vec![
                (lo, [0.45, 0.2, 0.12]),
                (at(0.35), [0.85, 0.55, 0.3]),
                (at(0.7), [0.95, 0.85, 0.65]),
                (hi, [1.0, 1.0, 0.95]),
            ],
            shading: Shading::default(),
        }
    }
}

/// The transfer function for `volume` when its unit is unknown: [`TransferFunction::ramp`]
/// from its values' Otsu threshold (the background transparent) to the top of their
/// [`robust_range`], which lets half the light through a voxel's depth (its smallest
/// spacing); and the threshold. `None` where that range is one value.
pub fn unit_free_transfer(volume: &Volume) -> Option<(TransferFunction, f32)> {
    let range = robust_range(&volume.data)?;
    let t = otsu_threshold_within(&volume.data, range)?;
    let hi = range.1;
    let spacing = volume.spacing.iter().copied().fold(f64::INFINITY, f64::min);
    let opacity = 1.0 - 0.5f64.powf(1.0 / spacing.max(1e-6));
    Some((TransferFunction::ramp(t, hi, opacity as f32), t))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Marsaglia's xorshift64 from `seed`: the tests' reproducible random numbers.
    fn xorshift(mut seed: u64) -> impl FnMut() -> u64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        }
    }

    /// The exact Otsu split of integer values by brute force in f64: over every split between
    /// two distinct values, the largest between-class variance.
    fn best_between_class_variance(values: &[f32]) -> f64 {
        let mut sorted: Vec<f64> = values.iter().map(|&v| v as f64).collect();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len() as f64;
        let mut best: f64 = 0.0;
        for i in 1..sorted.len() {
            if sorted[i] == sorted[i - 1] {
                continue;
            }
            let (a, b) = sorted.split_at(i);
            let (ma, mb) = (
                a.iter().sum::<f64>() / a.len() as f64,
                b.iter().sum::<f64>() / b.len() as f64,
            );
            let between = (a.len() as f64) * (b.len() as f64) * (ma - mb).powi(2) / (n * n);
            best = best.max(between);
        }
        best
    }

    fn between_class_variance(values: &[f32], t: f32) -> f64 {
        let (a, b): (Vec<f64>, Vec<f64>) = values
            .iter()
            .map(|&v| v as f64)
            .partition(|&v| v < t as f64);
        let n = values.len() as f64;
        let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
        (a.len() as f64) * (b.len() as f64) * (mean(&a) - mean(&b)).powi(2) / (n * n)
    }

    /// Every rank's order statistic is the sorted finite values' entry there, on data past
    /// the gathering size (several passes), with heavy ties, NaN and infinities, negative
    /// zeros and values a few ulps apart; a rank past the count is `None`.
    #[test]
    fn order_statistics_are_the_sorted_values() {
        let mut next = xorshift(0x9e37_79b9_7f4a_7c15);
        for case in 0..6 {
            let n = [10, 1000, 70_000, 200_000, 300_000, 150_000][case];
            let values: Vec<f32> = (0..n)
                .map(|_| {
                    let r = next();
                    match (case, r % 10) {
                        (_, 0) if case > 1 => f32::NAN,
                        (_, 1) if case > 2 => f32::INFINITY,
                        // 70 % one value: a bin that never thins out.
                        (3, 2..=8) => 0.0,
                        (3, _) => -0.0,
                        // Values a few ulps apart around 1000.
                        (4, _) => f32::from_bits(1000f32.to_bits() + (r >> 40) as u32 % 97),
                        _ => ((r >> 11) as f64 / (1u64 << 53) as f64 * 2e6 - 1e6) as f32,
                    }
                })
                .collect();
            let mut sorted: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
            sorted.sort_by(f32::total_cmp);
            let ranks = [0, 1, sorted.len() / 3, sorted.len() / 2, sorted.len() - 1];
            for rank in ranks
                .into_iter()
                .chain((0..20).map(|_| next() as usize % sorted.len()))
            {
                let got = order_statistic(&values, rank).unwrap();
                // -0.0 and 0.0 are equal; compare as values.
                assert!(
                    got == sorted[rank],
                    "case {case}, rank {rank}: {got} vs {}",
                    sorted[rank]
                );
            }
            assert_eq!(order_statistic(&values, sorted.len()), None);
        }
        assert_eq!(order_statistic(&[f32::NAN, 2.0, 2.0], 1), Some(2.0));
        assert_eq!(order_statistic(&[f32::NAN, 2.0, 2.0], 2), None);
        assert_eq!(order_statistic(&[], 0), None);
    }

    /// A few outliers move neither Otsu's threshold (by more than a bin) nor the robust range,
    /// where the whole range would have spread 8-bit values over 40 times the bins' width.
    #[test]
    fn outliers_do_not_set_the_defaults() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        let mut values: Vec<f32> = (0..100_000)
            .map(|i| {
                let seed = next();
                let base = if i % 5 == 0 { 180.0 } else { 40.0 };
                (base + (seed % 61) as f32 - 30.0).clamp(0.0, 255.0)
            })
            .collect();
        values.extend([0.0; 20]);
        values.extend([255.0; 20]);
        let clean = otsu_threshold(&values).unwrap();
        assert_eq!(robust_range(&values), Some((0.0, 255.0)));
        let mut spiked = values.clone();
        spiked.extend([1e4, 2e4, -5e3]);
        assert_eq!(finite_range(&spiked), Some((-5e3, 2e4)));
        assert_eq!(robust_range(&spiked), Some((0.0, 255.0)));
        let t = otsu_threshold(&spiked).unwrap();
        assert!((t - clean).abs() <= 1.0, "{t} vs {clean}");
        assert!((70.0..150.0).contains(&t), "{t}");
    }

    /// The clipped range is the sorted values' order statistics at the tail's ranks, NaN and
    /// infinities left out, and with no tail the finite range.
    #[test]
    fn a_clipped_range_leaves_out_its_tails() {
        let mut values: Vec<f32> = (0..1000).map(|i| ((i * 7919) % 1000) as f32).collect();
        values.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
        // 1000 finite values 0 .. 999: ranks ⌊0.005 · 999⌋ = 4 and ⌈0.995 · 999⌉ = 995.
        assert_eq!(clipped_range(&values, CLIPPED_TAIL), Some((4.0, 995.0)));
        assert_eq!(clipped_range(&values, 0.0), finite_range(&values));
        assert_eq!(clipped_range(&values, 0.5), Some((499.0, 500.0)));
        // Three outliers at each end stay within the tails (1006 values: ranks 5 and 1000,
        // the values 2 and 997 after the three below).
        let mut spiked = values.clone();
        spiked.extend([1e9; 3]);
        spiked.extend([-1e9; 3]);
        assert_eq!(clipped_range(&spiked, CLIPPED_TAIL), Some((2.0, 997.0)));
        assert_eq!(clipped_range(&[7.0], CLIPPED_TAIL), Some((7.0, 7.0)));
        assert_eq!(clipped_range(&[f32::NAN], CLIPPED_TAIL), None);
        assert_eq!(clipped_range(&[], CLIPPED_TAIL), None);
    }

    /// On 8-bit values (one bin a value over 0 .. 255) the histogram's split is the exact one:
    /// its between-class variance is brute force's best, on bimodal, skewed and uniform data.
    #[test]
    fn otsu_on_8_bit_values_is_the_exact_split() {
        let mut next = xorshift(0x2545_f491_4f6c_dd1d);
        for case in 0..40 {
            let n = 500 + (next() % 3000) as usize;
            let (m0, m1) = ((next() % 100) as f64, 120.0 + (next() % 120) as f64);
            let share = (next() % 90 + 5) as f64 / 100.0;
            let mut values: Vec<f32> = (0..n)
                .map(|_| {
                    let u = (next() % 10_000) as f64 / 10_000.0;
                    let spread = ((next() % 2001) as f64 / 1000.0 - 1.0) * 30.0;
                    let v = match case % 4 {
                        3 => (next() % 256) as f64,
                        _ if u < share => m0 + spread,
                        _ => m1 + spread,
                    };
                    v.round().clamp(0.0, 255.0) as f32
                })
                .collect();
            // Span 0 .. 255 exactly, so that each integer has a bin of its own.
            values.extend([0.0, 255.0]);
            let t = otsu_threshold(&values).unwrap();
            let got = between_class_variance(&values, t);
            let want = best_between_class_variance(&values);
            assert!(
                (got - want).abs() <= 1e-9 * want,
                "case {case}: threshold {t} gives {got}, the best split {want}"
            );
        }
    }

    #[test]
    fn otsu_separates_two_populations_and_ignores_non_finite_values() {
        let mut v: Vec<f32> = (0..1000).map(|i| 10.0 + (i % 7) as f32).collect();
        v.extend((0..300).map(|i| 200.0 + (i % 11) as f32));
        v.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY]);
        let t = otsu_threshold(&v).unwrap();
        assert!(t > 16.0 && t <= 200.0, "{t}");
        assert_eq!(otsu_threshold(&[3.0; 10]), None);
        assert_eq!(otsu_threshold(&[f32::NAN, 1.0]), None);
        assert_eq!(finite_range(&[f32::NAN]), None);
    }

    /// A label map's neighbours mostly agree, a noisy scan's mostly differ.
    #[test]
    fn labels_are_piecewise_constant_and_scans_are_not() {
        let dims = [40, 30, 20];
        let n = dims[0] * dims[1] * dims[2];
        let (mut labels, mut scan) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut seed = 12345u32;
        for idx in 0..n {
            let (i, j) = (idx % dims[0], (idx / dims[0]) % dims[1]);
            let label = if i < 12 {
                0
            } else if j < 15 {
                1
            } else {
                2
            };
            labels.push(label as f32);
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            scan.push((50 * label + (seed >> 28) as i32) as f32);
        }
        assert!(equal_neighbour_share(dims, &labels) > 0.95);
        assert!(equal_neighbour_share(dims, &scan) < 0.2);
        assert_eq!(equal_neighbour_share(dims, &vec![0.0; n]), 0.0);
    }

    #[test]
    fn the_unit_free_ramp_hides_the_background_and_shows_the_top() {
        let mut v: Vec<f32> = vec![5.0; 5000];
        v.extend(vec![180.0; 1000]);
        v.push(250.0);
        let n = v.len();
        let (tf, t) = unit_free_transfer(&Volume::hounsfield([n, 1, 1], [2.0; 3], v)).unwrap();
        assert!(t > 5.0 && t <= 180.0, "{t}");
        assert_eq!(tf.opacity_at(5.0), 0.0);
        assert_eq!(tf.opacity_at(t), 0.0);
        // Half the light through a voxel's 2 mm at the top value.
        let top = tf.opacity_at(250.0);
        assert!(((1.0 - top).powf(2.0) - 0.5).abs() < 1e-6, "{top}");
        tf.validate().unwrap();
    }
}
