//! Calcium scoring: the Agatston score of a region of a non-contrast CT (the coronary
//! arteries', each artery's or their sum; the aortic valve's), as Agatston et al. defined it
//! (J Am Coll Cardiol 1990) and scanners' software computes it at 120 kVp:
//! - a lesion is a piece of the region's voxels at or above 130 HU within one slice (the
//!   grid's third axis), each voxel joined to the eight about it in the slice, and at least
//!   1 mm² in area (smaller ones are noise);
//! - its score is its area (mm²) times a weight from its peak: 1 for 130–199 HU, 2 for
//!   200–299, 3 for 300–399, 4 from 400;
//! - the score is the sum over every lesion of every slice. Agatston's slices were 3 mm;
//!   slices of another spacing are each weighted by spacing / 3 mm, so that the score stands
//!   for the same volume of calcium whatever the spacing.
//!
//! The volume score is the lesions' voxels' volume (mm³). The pieces are a union–find
//! (petgraph's, as [`crate::clusters`]) over the sorted candidates, neighbours found by
//! bisection.

use petgraph::unionfind::UnionFind;
use raystream_io::Volume;
use raystream_math::DVec3;

/// The lowest value of calcium, HU (at 120 kVp).
pub const THRESHOLD_HU: f64 = 130.0;
/// The smallest lesion, mm² within its slice.
pub const MIN_AREA_MM2: f64 = 1.0;
/// Agatston's slice spacing, mm.
pub const SLICE_MM: f64 = 3.0;

/// A region's Agatston score and what it is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct Agatston {
    /// The score (Agatston units), each slice's weighted by `slice_factor`.
    pub score: f64,
    /// The lesions' volume, mm³ (the volume score).
    pub volume_mm3: f64,
    /// The slice spacing over Agatston's 3 mm.
    pub slice_factor: f64,
    /// A pixel's area within its slice, mm².
    pub pixel_mm2: f64,
    /// Each lesion counted, by slice, then by its first voxel.
    pub each: Vec<Lesion>,
}

/// A lesion counted: one piece within one slice.
#[derive(Clone, Debug, PartialEq)]
pub struct Lesion {
    /// Its slice (the grid's third index).
    pub slice: usize,
    pub voxels: usize,
    pub area_mm2: f64,
    pub peak_hu: f64,
    /// 1 to 4, by its peak.
    pub weight: f64,
    /// area × weight × the slice factor.
    pub score: f64,
    /// The mean of its voxels' centres, LPS mm.
    pub centroid: [f64; 3],
}

impl Agatston {
    /// The lesions counted (each slice's apart).
    pub fn lesions(&self) -> usize {
        self.each.len()
    }

    /// The slices holding a lesion.
    pub fn slices(&self) -> usize {
        let mut slices: Vec<usize> = self.each.iter().map(|l| l.slice).collect();
        slices.dedup();
        slices.len()
    }

    /// The highest value of a lesion counted, HU; `None` for none.
    pub fn peak_hu(&self) -> Option<f64> {
        self.each.iter().map(|l| l.peak_hu).reduce(f64::max)
    }

    /// The CAC-DRS category of a total coronary score (Hecht et al., 2018): A0 for none,
    /// A1 below 100, A2 below 300, A3 from 300.
    pub fn cac_drs(&self) -> &'static str {
        match self.score {
            s if s <= 0.0 => "A0",
            s if s < 100.0 => "A1",
            s if s < 300.0 => "A2",
            _ => "A3",
        }
    }
}

/// A lesion's weight from its peak value, HU: 1 to 4.
pub fn weight(peak_hu: f64) -> f64 {
    match peak_hu {
        p if p >= 400.0 => 4.0,
        p if p >= 300.0 => 3.0,
        p if p >= 200.0 => 2.0,
        _ => 1.0,
    }
}

/// `volume`'s pixel area within a slice (mm²) and the distance between its slices (mm, across
/// them: a tilted gantry's slices lie closer than their step along the table).
pub fn slice_geometry(volume: &Volume) -> (f64, f64) {
    let m = volume.index_to_world_affine().matrix3;
    let pixel_mm2 = DVec3::cross(m.x_axis, m.y_axis).length();
    (pixel_mm2, m.determinant().abs() / pixel_mm2)
}

/// The Agatston score of `volume`'s voxels among `indices` (distinct, any order).
pub fn agatston(volume: &Volume, indices: &[usize]) -> Agatston {
    scored(volume, indices, false).0
}

/// [`agatston`], and the voxels of the lesions counted (in increasing order).
pub fn agatston_with_voxels(volume: &Volume, indices: &[usize]) -> (Agatston, Vec<usize>) {
    scored(volume, indices, true)
}

fn scored(volume: &Volume, indices: &[usize], with_voxels: bool) -> (Agatston, Vec<usize>) {
    let (pixel_mm2, slice_mm) = slice_geometry(volume);
    let voxel_mm3 = pixel_mm2 * slice_mm;
    let slice_factor = slice_mm / SLICE_MM;
    let mut hot: Vec<usize> = (indices.iter().copied())
        .filter(|&n| volume.data[n] as f64 >= THRESHOLD_HU)
        .collect();
    hot.sort_unstable();
    let [nx, ny, _] = volume.dims;
    let mut pieces = UnionFind::<u32>::new(hot.len());
    for (at, &n) in hot.iter().enumerate() {
        let (i, j) = (n % nx, n / nx % ny);
        // The four of the eight neighbours that come later in the slice.
        let right = i + 1 < nx;
        let below = j + 1 < ny;
        let ahead = [
            right.then_some(n + 1),
            (below && i > 0).then(|| n + nx - 1),
            below.then_some(n + nx),
            (below && right).then_some(n + nx + 1),
        ];
        for m in ahead.into_iter().flatten() {
            if let Ok(q) = hot[at + 1..].binary_search(&m) {
                pieces.union(at as u32, (at + 1 + q) as u32);
            }
        }
    }
    // Each piece's voxels, peak and sum of voxel indices (for its centroid), by its root.
    let mut size = vec![0usize; hot.len()];
    let mut peak = vec![f64::NEG_INFINITY; hot.len()];
    let mut sum = vec![DVec3::ZERO; hot.len()];
    let roots = pieces.into_labeling();
    for (at, &root) in roots.iter().enumerate() {
        let (r, n) = (root as usize, hot[at]);
        size[r] += 1;
        peak[r] = peak[r].max(volume.data[n] as f64);
        sum[r] += DVec3::new(
            (n % nx) as f64,
            (n / nx % ny) as f64,
            (n / (nx * ny)) as f64,
        );
    }
    let mut score = Agatston {
        score: 0.0,
        volume_mm3: 0.0,
        slice_factor,
        pixel_mm2,
        each: Vec::new(),
    };
    // A root is its piece's first voxel in sorted order: the lesions come by slice.
    for (r, &s) in size.iter().enumerate() {
        let area = s as f64 * pixel_mm2;
        if s == 0 || area < MIN_AREA_MM2 {
            continue;
        }
        let lesion = Lesion {
            slice: hot[r] / (nx * ny),
            voxels: s,
            area_mm2: area,
            peak_hu: peak[r],
            weight: weight(peak[r]),
            score: area * weight(peak[r]) * slice_factor,
            centroid: volume.index_to_world(sum[r] / s as f64).to_array(),
        };
        score.score += lesion.score;
        score.volume_mm3 += s as f64 * voxel_mm3;
        score.each.push(lesion);
    }
    score.each.sort_by_key(|l| l.slice);
    let voxels = match with_voxels {
        true => (hot.iter().zip(&roots))
            .filter(|&(_, &r)| size[r as usize] as f64 * pixel_mm2 >= MIN_AREA_MM2)
            .map(|(&n, _)| n)
            .collect(),
        false => Vec::new(),
    };
    (score, voxels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lesions_join_at_corners_within_slices_and_small_ones_drop() {
        // 0.5 mm pixels (0.25 mm²), 1.5 mm slices (factor 0.5); 8 × 6 × 3, all 0 HU.
        let (nx, ny) = (8, 6);
        let mut data = vec![0.0f32; nx * ny * 3];
        let mut put = |i: usize, j: usize, k: usize, hu: f32| data[i + nx * (j + ny * k)] = hu;
        // Slice 0: a 2×2 block, peak 250 (1 mm²: kept, weight 2), and 129.9 beside it, not
        // calcium; a pixel alone at 900 (0.25 mm²: dropped); two pairs at 500 across the
        // row's end, (7, 3)–(7, 4) and (0, 4)–(0, 5), not joined (each 0.5 mm²: dropped).
        put(1, 1, 0, 150.0);
        put(2, 1, 0, 250.0);
        put(1, 2, 0, 140.0);
        put(2, 2, 0, 130.0);
        put(0, 1, 0, 129.9);
        put(5, 4, 0, 900.0);
        for (i, j) in [(7, 3), (7, 4), (0, 4), (0, 5)] {
            put(i, j, 0, 500.0);
        }
        // Slice 1: a diagonal staircase of four pixels (joined at corners: 1 mm², peak 420,
        // weight 4).
        for (d, hu) in [(0, 200.0), (1, 420.0), (2, 150.0), (3, 131.0)] {
            put(3 + d, 1 + d, 1, hu);
        }
        // Slice 2: the other diagonal (1 mm², weight 3); over slice 0's block, one pixel at
        // 1000, not joined across slices (dropped).
        for d in 0..4 {
            put(6 - d, d, 2, 300.0);
        }
        put(1, 1, 2, 1000.0);
        let v = Volume::hounsfield([nx, ny, 3], [0.5, 0.5, 1.5], data);
        let all: Vec<usize> = (0..v.data.len()).rev().collect();
        let a = agatston(&v, &all);
        assert_eq!((a.lesions(), a.slices()), (3, 3));
        assert!((a.pixel_mm2 - 0.25).abs() < 1e-12 && (a.slice_factor - 0.5).abs() < 1e-12);
        // (1 mm² × 2 + 1 mm² × 4 + 1 mm² × 3) × 0.5.
        assert!((a.score - 4.5).abs() < 1e-12, "{a:?}");
        assert!((a.volume_mm3 - 12.0 * 0.375).abs() < 1e-12);
        assert_eq!(a.peak_hu(), Some(420.0));
        assert_eq!(a.cac_drs(), "A1");
        // Each lesion: its slice, area, peak, weight, score and centroid (index + 0 origin,
        // × 0.5 mm in-plane, × 1.5 mm across).
        let each: Vec<(usize, usize, f64, f64, f64)> = (a.each.iter())
            .map(|l| (l.slice, l.voxels, l.peak_hu, l.weight, l.score))
            .collect();
        assert_eq!(
            each,
            [
                (0, 4, 250.0, 2.0, 1.0),
                (1, 4, 420.0, 4.0, 2.0),
                (2, 4, 300.0, 3.0, 1.5)
            ]
        );
        assert_eq!(a.each[0].centroid, [0.75, 0.75, 0.0]);
        assert_eq!(a.each[1].centroid, [2.25, 1.25, 1.5]);
        assert!(a.each.iter().all(|l| l.area_mm2 == 1.0));
        // The lesions' voxels: the twelve, in order; the 900, 500 and 1000 HU pixels dropped.
        let (b, voxels) = agatston_with_voxels(&v, &all);
        assert_eq!(b, a);
        assert_eq!(voxels.len(), 12);
        assert!(voxels.windows(2).all(|w| w[0] < w[1]));
        assert!(voxels.iter().all(|&n| (130.0..=420.0).contains(&v.data[n])));
        // Only slice 0's block region: weight 2, 1 mm², factor 0.5.
        let block: Vec<usize> = [(1, 1), (2, 1), (1, 2), (2, 2)]
            .iter()
            .map(|&(i, j)| i + nx * j)
            .collect();
        assert!((agatston(&v, &block).score - 1.0).abs() < 1e-12);
        // Three of the block: 0.75 mm², dropped.
        let none = agatston(&v, &block[..3]);
        assert_eq!((none.score, none.lesions(), none.peak_hu()), (0.0, 0, None));
        assert_eq!(none.cac_drs(), "A0");
        assert_eq!(weight(199.9), 1.0);
        assert_eq!(weight(300.0), 3.0);
        assert_eq!(weight(3000.0), 4.0);
    }
}
