//! A segmentation's colours on a CT's grid, what direct volume rendering (`dvr`, `iso`,
//! `cinematic`) colours its samples by in place of the transfer function's colour: each voxel's
//! segment, and each segment's colour. The opacity stays the transfer function's, so a
//! segment shows what the preset shows of it (the bone of a vertebra, the contrast of a
//! lumen), in the segment's colour.
//!
//! A sample's colour is the trilinear blend of its eight nearest voxels' colours, each the
//! colour of its segment or, for a voxel of none (label 0, or a label given no colour), the
//! transfer function's colour at the sample: segments meet in a blend a voxel wide rather than
//! in voxel-sized steps, and a segment's colour fades into the transfer function's over its
//! last voxel. The GPU's `painted` (raystream-gpu's kernels/volume.wgsl) computes the same.

use raystream_math::Vec3;

/// Labels above this are refused (the GPU holds them as 16-bit unsigned texels).
pub const MAX_LABEL: u32 = u16::MAX as u32;

/// Each voxel's segment on a volume's grid, and each segment's colour.
#[derive(Clone, Debug)]
pub struct SegmentColours {
    /// The volume's voxels per axis.
    pub dims: [usize; 3],
    /// Per voxel (x fastest), its segment's label; 0: none.
    pub labels: Vec<u16>,
    /// Per label 0..=the largest, its colour (linear RGB) and 1, or zeros where the label has
    /// none (label 0 never has one): the transfer function's colour shows there.
    pub colours: Vec<[f32; 4]>,
}

impl SegmentColours {
    /// `labels` per voxel of a grid of `dims`, and `(label, linear RGB)` for the labels
    /// coloured. Panics if `labels` is not one a voxel or a colour's label is 0 or above
    /// [`MAX_LABEL`] (the caller checks its input).
    pub fn new(dims: [usize; 3], labels: Vec<u16>, colours: &[(u32, Vec3)]) -> SegmentColours {
        assert_eq!(
            labels.len(),
            dims.iter().product::<usize>(),
            "a label a voxel"
        );
        let largest = labels
            .iter()
            .map(|&l| l as u32)
            .chain(colours.iter().map(|c| c.0))
            .max()
            .unwrap_or(0);
        let mut table = vec![[0.0; 4]; largest as usize + 1];
        for &(l, c) in colours {
            assert!((1..=MAX_LABEL).contains(&l), "label {l} out of range");
            table[l as usize] = [c.x, c.y, c.z, 1.0];
        }
        SegmentColours {
            dims,
            labels,
            colours: table,
        }
    }

    /// The colour of voxel (i, j, k): its segment's, else `base`.
    fn voxel(&self, i: usize, j: usize, k: usize, base: Vec3) -> Vec3 {
        let [nx, ny, _] = self.dims;
        let [r, g, b, a] = self.colours[self.labels[i + nx * (j + ny * k)] as usize];
        if a > 0.0 { Vec3::new(r, g, b) } else { base }
    }

    /// The colour at continuous index `p` (clamped to the grid): the trilinear blend of the
    /// colours of its eight nearest voxels, `base` (the transfer function's colour there) for
    /// those of no coloured segment.
    pub fn colour_at(&self, p: Vec3, base: Vec3) -> Vec3 {
        crate::grid::trilinear(self.dims, p, |i, j, k| self.voxel(i, j, k, base))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two voxels side by side along x, labels `a` and `b`, on a 2×1×1 grid.
    fn pair(a: u16, b: u16) -> SegmentColours {
        SegmentColours::new(
            [2, 1, 1],
            vec![a, b],
            &[(1, Vec3::new(1.0, 0.0, 0.0)), (2, Vec3::new(0.0, 0.0, 1.0))],
        )
    }

    #[test]
    fn a_voxel_takes_its_segments_colour_and_neighbours_blend() {
        let base = Vec3::new(0.2, 0.6, 0.2);
        let s = pair(1, 2);
        assert_eq!(s.colour_at(Vec3::ZERO, base), Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(s.colour_at(Vec3::X, base), Vec3::new(0.0, 0.0, 1.0));
        // A quarter of the way from red to blue.
        let q = s.colour_at(Vec3::new(0.25, 0.0, 0.0), base);
        assert!(
            (q - Vec3::new(0.75, 0.0, 0.25)).abs().max_element() < 1e-6,
            "{q}"
        );
        // Clamped beyond the grid: the edge voxel's colour.
        assert_eq!(s.colour_at(Vec3::new(-3.0, 2.0, 5.0), base), Vec3::X);
    }

    #[test]
    fn voxels_of_no_segment_keep_the_transfer_functions_colour() {
        let base = Vec3::new(0.2, 0.6, 0.2);
        // Label 0, and label 3 with no colour given, show the base colour.
        for none in [0, 3] {
            let s = pair(none, 2);
            assert_eq!(s.colour_at(Vec3::ZERO, base), base);
            let h = s.colour_at(Vec3::new(0.5, 0.0, 0.0), base);
            assert!(
                (h - (base + Vec3::Z) * 0.5).abs().max_element() < 1e-6,
                "{h}"
            );
        }
    }
}
