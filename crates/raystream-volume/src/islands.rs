//! Islands of a threshold's inside region: the pieces of voxels at or above it, each voxel
//! joined to the six that share a face with it, as 3D Slicer's Islands effect keeps the
//! largest or removes the small ones (its default, not fully connected). A CT's bones at
//! 300 HU come with hundreds to thousands of specks (noise, calcified vessels, contrast, the
//! table's parts): 1,223 pieces of surface on the built-in abdomen CT's bones.
//!
//! Why faces: the marching cubes join the inside corners of a cell through its edges alone (a
//! face whose corners alternate separates its inside ones: `cases`), so voxels that touch
//! along an edge or at a corner only have surfaces of their own, and each triangle belongs to
//! one island. Dropping the others' voxels changes none of the kept ones' triangles: the kept
//! surface is the full one's triangles, vertex for vertex (its vertices interpolate values
//! along edges from a kept voxel, and the normals take the values, which are left as they
//! are).
//!
//! A flood fill by hand: the padded mask the marching cubes build is the one the islands are
//! cut from, and a labelling crate would want a volume type of its own and a label a voxel
//! (four bytes each, where the fill keeps the islands' voxels alone).

/// Which islands of the inside region (voxels at or above the threshold, each joined to the six
/// that share a face with it) keep their surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KeepIslands {
    /// Every island.
    #[default]
    All,
    /// The this many with the most voxels (of islands as large, the first met, scanning i,
    /// then j, then k).
    Largest(usize),
    /// Those of at least this many voxels.
    AtLeast(usize),
}

/// What [`crate::extract_isosurface_keeping`] keeps of the inside region: its islands, and
/// whether its cavities are filled first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KeepSurface {
    pub islands: KeepIslands,
    /// Fill the cavities first: the pieces of the voxels below the threshold that the inside
    /// region encloses wholly (those that no path through them reaches the volume's border
    /// from, a voxel joined to the 18 that share a face or an edge with it), as
    /// Materialise Mimics's cavity fill makes a bone solid for printing: the marrow inside a
    /// cortex closed all round, a voxel of noise. A cavity's surface is then gone, triangle for
    /// triangle, and the island around it holds its voxels.
    pub fill_cavities: bool,
}

impl From<KeepIslands> for KeepSurface {
    fn from(islands: KeepIslands) -> Self {
        KeepSurface {
            islands,
            fill_cavities: false,
        }
    }
}

impl KeepSurface {
    /// The whole surface: every island, no cavity filled.
    pub fn is_all(&self) -> bool {
        self.islands == KeepIslands::All && !self.fill_cavities
    }
}

/// What [`crate::extract_isosurface_keeping`] found and kept.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Islands {
    /// Every island's voxels, the largest first (after any cavity was filled).
    pub sizes: Vec<usize>,
    /// How many of them were kept, and their voxels.
    pub kept: usize,
    pub kept_voxels: usize,
    /// Where the cavities were filled: how many, and their voxels.
    pub cavities: usize,
    pub cavity_voxels: usize,
}

/// Fills the cavities of `mask` (0 outside, 1 inside, on a grid `dims` with a layer of 0 all
/// around): the pieces of its 0s, each joined to the 18 that share a face or an edge with it,
/// that the border's do not reach ([`KeepSurface::fill_cavities`]). Returns how many there
/// were, and their voxels.
///
/// Why 18: the marching cubes join inside voxels through faces alone, so where two outside
/// voxels share an edge (on a face whose corners alternate) the outside runs between them, and
/// where two share a corner only, each has a cap of its own. So a cavity filled is closed all
/// round by the surface, and once filled, every cell with a voxel of it has its other corners
/// inside, or one outside across a corner, whose cap is the triangle it had: the cavity's
/// triangles go and every other stays. (Joined through corners too, a cavity touching the
/// outside at a corner would be left, its surface facing in; joined through faces alone, one
/// touching it along an edge would be filled, changing the outside's surface there: the
/// proptest in the crate's tests tells both apart.)
pub(crate) fn fill_cavities(mask: &mut [u8], dims: [usize; 3]) -> (usize, usize) {
    let [px, py, pz] = dims;
    assert_eq!(mask.len(), px * py * pz, "a mask of the grid");
    let (sx, layer) = (px as isize, (px * py) as isize);
    let around: Vec<isize> = (-1isize..=1)
        .flat_map(|k| (-1isize..=1).flat_map(move |j| (-1isize..=1).map(move |i| (i, j, k))))
        .filter(|&(i, j, k)| matches!(i.abs() + j.abs() + k.abs(), 1 | 2))
        .map(|(i, j, k)| i + sx * j + layer * k)
        .collect();
    // Marks the 0s joined to `seeds` (0s, none in the padding) as `to`, by their 18
    // neighbours; how many. The padding is marked outside first, so a fill never enters it,
    // and every neighbour of a voxel within it is in the grid.
    let mut stack: Vec<usize> = Vec::new();
    let mut flood = |mask: &mut [u8], seeds: &mut dyn Iterator<Item = usize>, to: u8| {
        let mut count = 0;
        for seed in seeds {
            if mask[seed] == 0 {
                mask[seed] = to;
                stack.push(seed);
            }
        }
        while let Some(v) = stack.pop() {
            count += 1;
            for &o in &around {
                let n = (v as isize + o) as usize;
                if mask[n] == 0 {
                    mask[n] = to;
                    stack.push(n);
                }
            }
        }
        count
    };
    // The padding, and the voxels next to it (one step in along some axis), by index.
    let (mut padding, mut next_to_padding) = (Vec::new(), Vec::new());
    for k in 0..pz {
        for j in 0..py {
            let row = px * (j + py * k);
            let edge = |x: usize, n: usize| (x == 0 || x == n - 1, x == 1 || x == n - 2);
            let ((pj, nj), (pk, nk)) = (edge(j, py), edge(k, pz));
            if pj || pk {
                padding.extend(row..row + px);
            } else if nj || nk {
                padding.extend([row, row + px - 1]);
                next_to_padding.extend(row + 1..row + px - 1);
            } else {
                padding.extend([row, row + px - 1]);
                next_to_padding.extend([row + 1, row + px - 2]);
            }
        }
    }
    for &v in &padding {
        mask[v] = 2;
    }
    // The outside: every 0 the padding reaches.
    flood(mask, &mut next_to_padding.into_iter(), 2);
    let (mut cavities, mut voxels) = (0, 0);
    for v in 0..mask.len() {
        if mask[v] == 0 {
            cavities += 1;
            voxels += flood(mask, &mut std::iter::once(v), 3);
        }
    }
    for m in mask.iter_mut() {
        *m = match *m {
            2 => 0,
            3 => 1,
            m => m,
        };
    }
    (cavities, voxels)
}

/// Finds the islands of `mask` (0 outside, 1 inside, on a grid `dims` with a layer of 0 all
/// around, as the marching cubes pad it) and clears the voxels of those `keep` leaves out.
pub(crate) fn keep_islands(mask: &mut [u8], dims: [usize; 3], keep: KeepIslands) -> Islands {
    let [px, py, pz] = dims;
    assert_eq!(mask.len(), px * py * pz, "a mask of the grid");
    // Offsets to the six neighbours across a face; an inside voxel is never in the zero
    // border, so they stay within the grid.
    let (px, layer) = (px as isize, (px * py) as isize);
    let around = [-1, 1, -px, px, -layer, layer];
    // Each island's voxels, one island after another (`starts` says where each begins); a
    // voxel met is marked 2.
    let mut voxels: Vec<u32> = Vec::new();
    let mut starts: Vec<usize> = Vec::new();
    let mut stack: Vec<u32> = Vec::new();
    for seed in 0..mask.len() {
        if mask[seed] != 1 {
            continue;
        }
        starts.push(voxels.len());
        mask[seed] = 2;
        stack.push(seed as u32);
        while let Some(v) = stack.pop() {
            voxels.push(v);
            for &o in &around {
                let n = (v as isize + o) as usize;
                if mask[n] == 1 {
                    mask[n] = 2;
                    stack.push(n as u32);
                }
            }
        }
    }
    starts.push(voxels.len());
    let count = starts.len() - 1;
    let size = |i: usize| starts[i + 1] - starts[i];
    let mut order: Vec<usize> = (0..count).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(size(i)), i));
    let kept: Vec<bool> = {
        let mut kept = vec![false; count];
        for (rank, &i) in order.iter().enumerate() {
            kept[i] = match keep {
                KeepIslands::All => true,
                KeepIslands::Largest(n) => rank < n,
                KeepIslands::AtLeast(n) => size(i) >= n,
            };
        }
        kept
    };
    for i in 0..count {
        for &v in &voxels[starts[i]..starts[i + 1]] {
            mask[v as usize] = u8::from(kept[i]);
        }
    }
    Islands {
        sizes: order.iter().map(|&i| size(i)).collect(),
        kept: kept.iter().filter(|&&k| k).count(),
        kept_voxels: (0..count).filter(|&i| kept[i]).map(size).sum(),
        ..Islands::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A padded 6×5×5 grid with the inside voxels at these (unpadded) places.
    fn grid(inside: &[[usize; 3]]) -> (Vec<u8>, [usize; 3]) {
        let dims = [8, 7, 7];
        let mut mask = vec![0u8; 8 * 7 * 7];
        for &[i, j, k] in inside {
            mask[(i + 1) + 8 * ((j + 1) + 7 * (k + 1))] = 1;
        }
        (mask, dims)
    }

    #[test]
    fn islands_join_through_faces() {
        // Three voxels in a row, and an L of three (faces); a pair touching along an edge and a
        // pair at a corner (each two islands); a voxel alone: seven islands.
        let inside = [
            [0, 0, 0],
            [1, 0, 0],
            [2, 0, 0],
            [4, 2, 2],
            [5, 2, 2],
            [5, 3, 2],
            [5, 0, 0],
            [4, 1, 0],
            [0, 4, 4],
            [1, 3, 3],
            [3, 4, 4],
        ];
        let (mut mask, dims) = grid(&inside);
        let all = keep_islands(&mut mask.clone(), dims, KeepIslands::All);
        assert_eq!(all.sizes, [3, 3, 1, 1, 1, 1, 1]);
        assert_eq!((all.kept, all.kept_voxels), (7, 11));
        // The largest: the row alone is left (as large as the L, and met first).
        let before = mask.clone();
        let one = keep_islands(&mut mask, dims, KeepIslands::Largest(1));
        assert_eq!((one.kept, one.kept_voxels), (1, 3));
        let left: Vec<usize> = (0..mask.len()).filter(|&v| mask[v] == 1).collect();
        let row: Vec<usize> = (0..3).map(|i| (i + 1) + 8 * (1 + 7)).collect();
        assert_eq!(left, row);
        assert!(mask.iter().all(|&m| m <= 1));
        // At least two voxels: the row and the L.
        let mut m = before.clone();
        let two = keep_islands(&mut m, dims, KeepIslands::AtLeast(2));
        assert_eq!((two.kept, two.kept_voxels), (2, 6));
        assert_eq!(m[(5 + 1) + 8 * ((3 + 1) + 7 * (2 + 1))], 1, "the L");
        assert_eq!(m[(4 + 1) + 8 * (1 + 1 + 7)], 0, "the edge pair");
        // Nothing inside: no island.
        let (mut empty, dims) = grid(&[]);
        assert!(
            keep_islands(&mut empty, dims, KeepIslands::Largest(1))
                .sizes
                .is_empty()
        );
    }
}
