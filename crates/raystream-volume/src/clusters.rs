//! Low-attenuation clusters: the pieces that a region's voxels below a value (a lung's below
//! −950 HU, its emphysema) make, and how their sizes are spread. LAA-950 says how much of a
//! lung is emphysema; the clusters say how it is laid out. Mishima et al. (PNAS 1999) found
//! that the number of clusters at least X in size falls as a power of X, Y = K·X^−D, and
//! that D is lower where the walls between small clusters have broken and they have merged
//! into larger ones, in early emphysema with LAA% still normal. Their clusters were cut in
//! each slice; later work (Tanabe, Nambu) counts them in 3D, which is the default here.
//!
//! The pieces are a union–find (petgraph's) over the region's voxels below the value, each
//! joined to those of its six face neighbours that are too (in 2D, the four within its slice):
//! scipy.ndimage.label's default connectivity, and what a wall one voxel thick separates.

use petgraph::unionfind::UnionFind;
use raystream_io::Volume;

/// How a cluster's voxels are joined.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Connectivity {
    /// Through the six faces of a voxel: clusters in 3D.
    #[default]
    Faces,
    /// Through the four faces within its slice (the grid's third axis): clusters cut in each
    /// slice, as Mishima et al. counted them.
    InSlices,
}

/// The clusters of a region's voxels below a value.
#[derive(Clone, Debug, PartialEq)]
pub struct Clusters {
    pub connectivity: Connectivity,
    /// How many.
    pub count: usize,
    /// Each size met (voxels), with how many clusters have it; smallest first.
    pub sizes: Vec<(usize, usize)>,
    /// The power law's exponent D and the fit's r²: the least-squares line through
    /// (ln X, ln Y) for each size X met, Y the clusters of at least X voxels, as Mishima et
    /// al. fit it (D is the line's slope, negated). `None` with fewer than two sizes met.
    pub power_law: Option<PowerLaw>,
}

/// A fitted cumulative power law, Y = K·X^−D.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowerLaw {
    pub d: f64,
    pub r2: f64,
}

impl Clusters {
    /// The largest cluster's voxels (0 for none).
    pub fn largest(&self) -> usize {
        self.sizes.last().map_or(0, |&(s, _)| s)
    }
}

/// The clusters that `volume`'s voxels among `indices` (distinct, any order) whose values are
/// below `hu` (strictly; a NaN is not) make, joined as `connectivity` says.
pub fn clusters(
    volume: &Volume,
    indices: &[usize],
    hu: f64,
    connectivity: Connectivity,
) -> Clusters {
    let mut low: Vec<usize> = (indices.iter().copied())
        .filter(|&n| (volume.data[n] as f64) < hu)
        .collect();
    low.sort_unstable();
    let [nx, ny, nz] = volume.dims;
    let mut pieces = UnionFind::<u32>::new(low.len());
    for (at, &n) in low.iter().enumerate() {
        let (i, j, k) = (n % nx, n / nx % ny, n / (nx * ny));
        let ahead = [
            (i + 1 < nx).then_some(n + 1),
            (j + 1 < ny).then_some(n + nx),
            (connectivity == Connectivity::Faces && k + 1 < nz).then_some(n + nx * ny),
        ];
        // A neighbour ahead comes later in the sorted list, its place found by bisection.
        for m in ahead.into_iter().flatten() {
            if let Ok(q) = low[at + 1..].binary_search(&m) {
                pieces.union(at as u32, (at + 1 + q) as u32);
            }
        }
    }
    let mut voxels = vec![0usize; low.len()];
    for root in pieces.into_labeling() {
        voxels[root as usize] += 1;
    }
    let mut by_size = std::collections::BTreeMap::new();
    for s in voxels.into_iter().filter(|&s| s > 0) {
        *by_size.entry(s).or_insert(0usize) += 1;
    }
    let sizes: Vec<(usize, usize)> = by_size.into_iter().collect();
    Clusters {
        connectivity,
        count: sizes.iter().map(|&(_, c)| c).sum(),
        power_law: power_law(&sizes),
        sizes,
    }
}

/// The least-squares line through (ln X, ln Y(X)) for each size X of `sizes` (X, clusters of
/// that size), Y(X) the clusters of size X or more.
fn power_law(sizes: &[(usize, usize)]) -> Option<PowerLaw> {
    if sizes.len() < 2 {
        return None;
    }
    let mut at_least = sizes.iter().map(|&(_, c)| c).sum::<usize>();
    let points: Vec<(f64, f64)> = (sizes.iter())
        .map(|&(s, c)| {
            let p = ((s as f64).ln(), (at_least as f64).ln());
            at_least -= c;
            p
        })
        .collect();
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x / n, b + y / n));
    let (sxx, sxy, syy) = points.iter().fold((0.0, 0.0, 0.0), |(a, b, c), &(x, y)| {
        let (dx, dy) = (x - mx, y - my);
        (a + dx * dx, b + dx * dy, c + dy * dy)
    });
    let slope = sxy / sxx;
    // Y falls with X, so syy > 0 wherever two sizes were met.
    Some(PowerLaw {
        d: -slope,
        r2: sxy * sxy / (sxx * syy),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6×5×3 grid of −1000 (air) and 0 (tissue), 1 mm voxels.
    fn grid(air: &[[usize; 3]]) -> Volume {
        let mut data = vec![0.0f32; 6 * 5 * 3];
        for &[i, j, k] in air {
            data[i + 6 * (j + 5 * k)] = -1000.0;
        }
        Volume::hounsfield([6, 5, 3], [1.0; 3], data)
    }

    #[test]
    fn clusters_join_faces_not_edges_and_in_slices_not_across() {
        // A column of three through the slices; a pair along i at the row's end and the
        // grid's edge (i = 5 and the next row's i = 0 are not neighbours); two voxels sharing
        // an edge only; one alone.
        let v = grid(&[
            [1, 1, 0],
            [1, 1, 1],
            [1, 1, 2],
            [4, 3, 0],
            [5, 3, 0],
            [0, 4, 0],
            [3, 0, 2],
            [4, 1, 2],
            [0, 0, 1],
        ]);
        let all: Vec<usize> = (0..v.data.len()).rev().collect();
        let c = clusters(&v, &all, -950.0, Connectivity::Faces);
        // Sizes: 3 (the column), 2 (the pair), 1 ×4 (the row's next, the edge pair, alone).
        assert_eq!(c.sizes, [(1, 4), (2, 1), (3, 1)]);
        assert_eq!((c.count, c.largest()), (6, 3));
        let c2 = clusters(&v, &all, -950.0, Connectivity::InSlices);
        assert_eq!(c2.sizes, [(1, 7), (2, 1)]);
        // Strictly below: nothing is below −1000.
        assert_eq!(clusters(&v, &all, -1000.0, Connectivity::Faces).count, 0);
        // Only the region's voxels count: the column's middle left out splits it.
        let some: Vec<usize> = all.iter().copied().filter(|&n| n != 1 + 6 + 30).collect();
        let c = clusters(&v, &some, -950.0, Connectivity::Faces);
        assert_eq!(c.sizes, [(1, 6), (2, 1)]);
        // Two sizes met make a line; one does not.
        assert!(c2.power_law.is_some());
        assert!(
            clusters(&v, &[1 + 6], -950.0, Connectivity::Faces)
                .power_law
                .is_none()
        );
    }

    #[test]
    fn the_power_law_is_the_least_squares_line_of_the_cumulative_counts() {
        // Y(X) = 64·X^−2 exactly at X = 1, 2, 4, 8: 64, 16, 4, 1 clusters of at least X, so 48
        // of size 1, 12 of 2, 3 of 4, 1 of 8.
        let p = power_law(&[(1, 48), (2, 12), (4, 3), (8, 1)]).unwrap();
        assert!(
            (p.d - 2.0).abs() < 1e-12 && (p.r2 - 1.0).abs() < 1e-12,
            "{p:?}"
        );
        // numpy.polyfit(log([1, 2, 3]), log([3, 2, 1]), 1)[0] and numpy.corrcoef's r².
        let p = power_law(&[(1, 1), (2, 1), (3, 1)]).unwrap();
        assert!((p.d - 0.955307917036525).abs() < 1e-12, "{p:?}");
        assert!((p.r2 - 0.912613216352663).abs() < 1e-12, "{p:?}");
        assert!(power_law(&[(5, 10)]).is_none());
    }
}
