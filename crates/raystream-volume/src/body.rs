//! The patient's body in a CT, apart from what lies outside it: the table, a head holder, a
//! pad's cover, tubes and blankets, which a MIP shows as bright as bone and a skin rendering
//! as a second body. `render --body-only` and `iso --body-only` leave them out.
//!
//! Found in five steps, each a plain morphological one (a workstation's "table removal" is a
//! threshold, an opening and the largest piece; the fourth step keeps what an opening alone
//! would trim: the nose, the ears, the fingers):
//! 1. **Dense**: the voxels above [`BodyOptions::threshold_hu`] (−500 HU, between air and
//!    fat). A table's carbon fibre and a holder's plastic are dense too, and often touch the
//!    body (a head resting in its holder, the back on the table's top).
//! 2. **Core**: the dense voxels further than [`BodyOptions::opening_mm`] from any other
//!    (the dense region eroded by a ball), in pieces joined through faces. A piece is body
//!    where it holds a ball of radius [`BodyOptions::core_depth_mm`] (the trunk, the head, an
//!    arm at the side), or is the largest; a table's shell or a holder, a few mm thick, leaves
//!    no core, or specks.
//! 3. **Opening**: the dense voxels within the opening's radius and a voxel of the body's
//!    core (its dilation by the ball): the body less what is thinner than the ball, and less
//!    what touches it but for a sliver within that reach of the core (where the back rests on
//!    the table, the table's top closes the body from below, and the core reaches the skin).
//! 4. **Thin parts**: the other dense voxels, in pieces joined through faces. A piece that
//!    touches the opening, reaches no further than [`BodyOptions::thin_part_mm`] from the
//!    body's core and holds at most [`BodyOptions::thin_part_ml`] is joined back (on the CTs
//!    in ../shared: the nose and lips, 23 ml reaching 19 mm; skin folds, up to 23 mm);
//!    the others are left out (a table's top along the back, 117 ml reaching 32 mm; a head
//!    holder's sides, 42 and 52 ml reaching 48 and 52 mm; a table not touching the body).
//!    The reach tells a table's wing, which the sliver where the body rests may cut from the
//!    rest of the table, from a part of the body.
//! 5. **Enclosed**: in each slice of the grid (a plane of constant k), whatever the slice's
//!    border does not reach without crossing the body (the lungs, the airway, the bowel's gas,
//!    which are below the threshold but inside).
//!
//! Where the field of view cuts the body (a cropped CT, a cardiac CT's small field, a large
//! patient's flanks), the border is not all air around the body: a lung reaches it too, and
//! would be left out with its vessels. In such a slice, each region the border reaches is
//! judged by its HU: air around a body reads −1000 to −900 HU (noise and beam hardening
//! raise it), lung parenchyma −900 to −700. A region at least half of whose voxels are at or
//! below [`BodyOptions::air_hu`] is air (each region of air around the built-in CT's flanks:
//! 65 to 97 %); the others are tissue within the body (the chest crop's lungs: at most 9 %),
//! counted in [`Body::border_tissue_ml`], and so is a small pocket of partial volume between
//! the skin and the border. What the border cuts and is mostly below −900 HU reads as air: an
//! emphysematous lung, or the bowel's gas (the chest crop's splenic flexure, in its lowest
//! slices).
//!
//! Distances are in mm (anisotropic voxels are common: 0.49 × 0.49 × 1.13 mm on the head
//! CT), by the exact transform of [`crate::distance`], kept on grids of f32 (half the memory
//! of f64's, and the same bodies on the four CTs tested); the grid's border is not taken for air,
//! so a body cut off by the scan's ends keeps its full depth there. On a sheared grid (a
//! gantry tilt) the axes are taken as square, which errs by the shear's cosine at most (0.95
//! for the head CT's 18.5°).

use rayon::prelude::*;
use raystream_io::Volume;

use crate::distance::squared_distance_in;

/// What [`body`] takes for the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyOptions {
    /// HU above which a voxel is dense (tissue, or a device).
    pub threshold_hu: f32,
    /// The radius of the ball the dense region is opened by, mm: a device thinner than twice
    /// this separates from the body.
    pub opening_mm: f64,
    /// How deep a piece of the core must reach to be body (unless it is the largest), mm.
    pub core_depth_mm: f64,
    /// The largest thin part (thinner than the ball) joined back to the body, ml, and how far
    /// from the body's core it may reach, mm.
    pub thin_part_ml: f64,
    pub thin_part_mm: f64,
    /// HU at or below which a voxel is air: where the field of view cuts the body, a region
    /// reaching the slice's border is the air around the body when at least half of it is
    /// air, and a lung the border cuts otherwise.
    pub air_hu: f32,
}

impl BodyOptions {
    /// −500 HU, a ball of 4 mm radius, a core 15 mm deep, thin parts of 60 ml reaching 30 mm,
    /// air at −900 HU.
    pub const DEFAULT: BodyOptions = BodyOptions {
        threshold_hu: -500.0,
        opening_mm: 4.0,
        core_depth_mm: 15.0,
        thin_part_ml: 60.0,
        thin_part_mm: 30.0,
        air_hu: -900.0,
    };
}

impl Default for BodyOptions {
    fn default() -> Self {
        BodyOptions::DEFAULT
    }
}

/// The body [`body`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    /// Per voxel (as [`Volume::data`]), whether it is the body or lies within it.
    pub inside: Vec<bool>,
    /// How many voxels are inside.
    pub voxels: usize,
    /// The pieces of dense voxels left out, in ml, the largest first.
    pub left_out_ml: Vec<f64>,
    /// The thin parts joined back: how many, and their ml.
    pub thin_parts: usize,
    pub thin_part_ml: f64,
    /// The slices whose border the body reaches: the field of view cuts it there.
    pub cut_slices: usize,
    /// In those slices, the ml of the regions reaching the border that were judged tissue
    /// rather than air (a lung the field of view cuts), and kept.
    pub border_tissue_ml: f64,
}

impl Body {
    /// The body and every voxel next to it (sharing a face, an edge or a corner): every cell
    /// of the grid with a corner inside reads all eight of its voxels as they are, so that a
    /// volume kept to this is sampled as the whole one up to the skin and just beyond it.
    pub fn with_margin(&self, dims: [usize; 3]) -> Vec<bool> {
        let [nx, ny, nz] = dims;
        let inside = &self.inside;
        per_voxel(dims, |(i, j, k)| {
            (k.saturating_sub(1)..(k + 2).min(nz)).any(|kk| {
                (j.saturating_sub(1)..(j + 2).min(ny)).any(|jj| {
                    (i.saturating_sub(1)..(i + 2).min(nx))
                        .any(|ii| inside[ii + nx * (jj + ny * kk)])
                })
            })
        })
    }

    /// The body less its rim: the voxels inside whose six neighbours across a face are all
    /// inside too (or beyond the grid). The skin's outer voxels hold partly air (−500 to
    /// −100 HU where the skin crosses them), which would be the lowest values of a MinIP
    /// through the body, as rings following the grid's steps, rather than what is within.
    pub fn without_rim(&self, dims: [usize; 3]) -> Vec<bool> {
        let [nx, ny, _] = dims;
        let inside = &self.inside;
        per_voxel(dims, |(i, j, k)| {
            inside[i + nx * (j + ny * k)] && neighbours(dims, (i, j, k)).all(|q| inside[q])
        })
    }
}

/// The tissues within a body by their HU, in voxels (the ranges body-composition studies
/// use: adipose tissue −190 to −30 HU, muscle −29 to 150).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tissues {
    /// Below −190 HU: air, gas, lung.
    pub air: usize,
    /// −190 to −30 HU: fat.
    pub fat: usize,
    /// Above −30 to 150 HU: muscle, organs, blood, water.
    pub soft: usize,
    /// Above 150 HU: bone, contrast, calcium, metal.
    pub dense: usize,
}

impl Body {
    /// The voxels inside the body, by their HU in `vol` (the volume the body was found in; a
    /// NaN voxel counts in none).
    pub fn tissues(&self, vol: &Volume) -> Tissues {
        (vol.data.par_iter().zip(&self.inside))
            .filter(|(_, inside)| **inside)
            .fold(Tissues::default, |mut t, (&v, _)| {
                match v {
                    v if v.is_nan() => {}
                    v if v < -190.0 => t.air += 1,
                    v if v <= -30.0 => t.fat += 1,
                    v if v <= 150.0 => t.soft += 1,
                    _ => t.dense += 1,
                }
                t
            })
            .reduce(Tissues::default, |a, b| Tissues {
                air: a.air + b.air,
                fat: a.fat + b.fat,
                soft: a.soft + b.soft,
                dense: a.dense + b.dense,
            })
    }
}

impl Body {
    /// `vol` (the volume the body was found in) with every voxel beyond the body's margin
    /// ([`Body::with_margin`]) set to its lowest value: air, which renderings and isosurfaces
    /// read as nothing, while the skin is sampled as before.
    pub fn hide_outside(&self, vol: &mut Volume) {
        let lowest = vol.value_range().map_or(-1024.0, |(lo, _)| lo);
        for (v, keep) in vol.data.iter_mut().zip(self.with_margin(vol.dims)) {
            if !keep {
                *v = lowest;
            }
        }
    }
}

/// `f` of each voxel (i, j, k) of a grid of `dims`, slice by slice in parallel.
fn per_voxel(dims: [usize; 3], f: impl Fn((usize, usize, usize)) -> bool + Sync) -> Vec<bool> {
    let [nx, ny, nz] = dims;
    let mut out = vec![false; nx * ny * nz];
    out.par_chunks_mut((nx * ny).max(1))
        .enumerate()
        .for_each(|(k, slice)| {
            for (m, o) in slice.iter_mut().enumerate() {
                *o = f((m % nx, m / nx, k));
            }
        });
    out
}

/// The body in `vol` (a CT, in HU), as the module describes; an error saying why when there is
/// none (no voxel dense, or none deeper than the ball's radius).
pub fn body(vol: &Volume, opt: &BodyOptions) -> Result<Body, String> {
    let dims = vol.dims;
    let spacing = vol.spacing;
    let voxel_ml = vol.voxel_ml();
    let t = opt.threshold_hu;
    // Dense: above the threshold, read off the values where needed rather than kept (a byte
    // a voxel).
    let dense = |n: usize| vol.data[n] > t;
    if !vol.data.par_iter().any(|&v| v > t) {
        return Err(format!("no voxel above {t} HU: no body to find"));
    }
    // 2. The core, its pieces, and how deep each reaches (squared mm). Each voxel's piece is
    // not kept (four bytes a voxel): a piece is its first voxel, filled again to take it.
    let r2 = opt.opening_mm * opt.opening_mm;
    let len = vol.data.len();
    let mut flood = Flood::new(dims);
    let depth2: Vec<f32> = squared_distance_in(dims, spacing, |n| !dense(n));
    let core = |n: usize| depth2[n] as f64 > r2;
    let mut marks = vec![0u8; len];
    let (mut sizes, mut depths, mut firsts) = (Vec::new(), Vec::new(), Vec::new());
    for first in 0..len {
        if marks[first] == 0 && core(first) {
            let (mut size, mut deepest) = (0usize, 0.0f64);
            flood.fill(first, &mut marks, (0, 1), &core, |n| {
                size += 1;
                deepest = deepest.max(depth2[n] as f64);
            });
            sizes.push(size);
            depths.push(deepest);
            firsts.push(first);
        }
    }
    let Some(largest) = (0..sizes.len()).max_by_key(|&p| (sizes[p], std::cmp::Reverse(p))) else {
        return Err(format!(
            "nothing above {t} HU is thicker than {} mm: no body to find",
            2.0 * opt.opening_mm
        ));
    };
    let deep2 = opt.core_depth_mm * opt.core_depth_mm;
    // 3. The opening: dense voxels within the radius and a voxel of the body's core (its
    // pieces marked 2).
    for p in (0..sizes.len()).filter(|&p| p == largest || depths[p] >= deep2) {
        flood.fill(firsts[p], &mut marks, (1, 2), &core, |_| {});
    }
    drop(depth2);
    let reach = opt.opening_mm + spacing.iter().copied().fold(0.0, f64::max);
    let near2: Vec<f32> = squared_distance_in(dims, spacing, |n| marks[n] == 2);
    let mut kept: Vec<bool> = (near2.par_iter().zip(&vol.data))
        .map(|(&d, &v)| v > t && d as f64 <= reach * reach)
        .collect();
    // 4. The thin parts: pieces of the rest (marked 1, then 2 once found), joined back where
    // small and touching.
    (marks.par_iter_mut().zip(vol.data.par_iter().zip(&kept)))
        .for_each(|(m, (&v, &k))| *m = u8::from(v > t && !k));
    let all = |_: usize| true;
    let [nx, ny, nz] = dims;
    let (mut sizes, mut farthest2, mut touching, mut firsts) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for first in 0..len {
        if marks[first] == 1 {
            let (mut size, mut farthest, mut touches) = (0usize, 0.0f64, false);
            flood.fill(first, &mut marks, (1, 2), &all, |n| {
                size += 1;
                farthest = farthest.max(near2[n] as f64);
                if !touches {
                    let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
                    touches = neighbours(dims, (i, j, k)).any(|m| kept[m]);
                }
            });
            sizes.push(size);
            farthest2.push(farthest);
            touching.push(touches);
            firsts.push(first);
        }
    }
    drop(near2);
    let span2 = opt.thin_part_mm * opt.thin_part_mm;
    let join: Vec<bool> = (0..sizes.len())
        .map(|p| {
            touching[p] && sizes[p] as f64 * voxel_ml <= opt.thin_part_ml && farthest2[p] <= span2
        })
        .collect();
    for p in (0..sizes.len()).filter(|&p| join[p]) {
        flood.fill(firsts[p], &mut marks, (2, 3), &all, |n| kept[n] = true);
    }
    let thin: Vec<usize> = (0..sizes.len()).filter(|&p| join[p]).collect();
    let thin_part_ml = thin.iter().map(|&p| sizes[p] as f64 * voxel_ml).sum();
    // 5. What each slice's border cannot reach without crossing the body.
    let mut inside = vec![false; kept.len()];
    let slice = (nx * ny).max(1);
    let (cut_slices, border_tissue) = (inside.par_chunks_mut(slice))
        .zip(kept.par_chunks(slice).zip(vol.data.par_chunks(slice)))
        .map(|(out, (wall, hu))| enclosed_in_slice([nx, ny], wall, hu, opt.air_hu, out))
        .map(|(cut, tissue)| (usize::from(cut), tissue))
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    debug_assert_eq!(inside.len(), nx * ny * nz);
    let voxels = inside.iter().filter(|&&b| b).count();

    // What is left of the pieces not joined once the body's enclosures are in (a speck
    // within a slice's ring of skin is).
    let mut left_out_ml = Vec::new();
    for p in (0..sizes.len()).filter(|&p| !join[p]) {
        let mut out = 0usize;
        flood.fill(firsts[p], &mut marks, (2, 3), &all, |n| {
            out += usize::from(!inside[n])
        });
        if out > 0 {
            left_out_ml.push(out as f64 * voxel_ml);
        }
    }
    left_out_ml.sort_by(|a, b| b.total_cmp(a));
    Ok(Body {
        inside,
        voxels,
        left_out_ml,
        thin_parts: thin.len(),
        thin_part_ml,
        cut_slices,
        border_tissue_ml: border_tissue as f64 * voxel_ml,
    })
}

/// The voxels of a grid of `dims` that share a face with voxel (i, j, k).
fn neighbours(
    [nx, ny, nz]: [usize; 3],
    (i, j, k): (usize, usize, usize),
) -> impl Iterator<Item = usize> {
    let at = move |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    [
        (i > 0).then(|| at(i - 1, j, k)),
        (i + 1 < nx).then(|| at(i + 1, j, k)),
        (j > 0).then(|| at(i, j - 1, k)),
        (j + 1 < ny).then(|| at(i, j + 1, k)),
        (k > 0).then(|| at(i, j, k - 1)),
        (k + 1 < nz).then(|| at(i, j, k + 1)),
    ]
    .into_iter()
    .flatten()
}

/// The pieces of `member` (voxels joined through faces): per voxel its piece from 1 (0 for
/// none, the pieces numbered in the order their first voxels come, i fastest), and each
/// piece's voxels.
fn pieces(dims: [usize; 3], member: &[bool]) -> (Vec<u32>, Vec<usize>) {
    let mut labels = vec![0u32; member.len()];
    let mut marks = vec![0u8; member.len()];
    let mut sizes = Vec::new();
    let mut flood = Flood::new(dims);
    for first in 0..member.len() {
        if member[first] && marks[first] == 0 {
            let (l, mut size) = (sizes.len() as u32 + 1, 0usize);
            flood.fill(first, &mut marks, (0, 1), &|m| member[m], |n| {
                labels[n] = l;
                size += 1;
            });
            sizes.push(size);
        }
    }
    (labels, sizes)
}

/// Flood fills over a grid's voxels joined through faces, by hand as the islands' are
/// (`crate::islands` says why), here on the grid itself, which has no padding. A piece is
/// taken by its first voxel and filled again where it is needed again, so that no voxel
/// keeps a number of its piece (four bytes a voxel). Each voxel's grid coordinates travel
/// with it on the stack: dividing its index to find them cost about a quarter of the fill
/// (the head CT's core: 0.62–0.67 s so, 0.48–0.56 s; BENCHMARKS.md).
struct Flood {
    dims: [usize; 3],
    stack: Vec<[u32; 3]>,
}

impl Flood {
    fn new(dims: [usize; 3]) -> Flood {
        Flood {
            dims,
            stack: Vec::new(),
        }
    }

    /// Fills the piece through `first` of the voxels marked `from` for which `member` holds,
    /// marking them `to` (`marks`, a byte a voxel) and handing each to `visit` once. `first`
    /// must be such a voxel; `from` and `to` differ.
    fn fill(
        &mut self,
        first: usize,
        marks: &mut [u8],
        (from, to): (u8, u8),
        member: &impl Fn(usize) -> bool,
        mut visit: impl FnMut(usize),
    ) {
        let [nx, ny, nz] = self.dims;
        let sxy = nx * ny;
        let stack = &mut self.stack;
        debug_assert!(marks[first] == from && member(first) && from != to);
        marks[first] = to;
        stack.push([first % nx, (first / nx) % ny, first / sxy].map(|c| c as u32));
        while let Some(c) = stack.pop() {
            let [i, j, k] = c.map(|x| x as usize);
            let n = i + nx * j + sxy * k;
            visit(n);
            let mut go = |near: bool, m: usize, at: [usize; 3]| {
                if near && marks[m] == from && member(m) {
                    marks[m] = to;
                    stack.push(at.map(|x| x as u32));
                }
            };
            go(i > 0, n.wrapping_sub(1), [i.wrapping_sub(1), j, k]);
            go(i + 1 < nx, n + 1, [i + 1, j, k]);
            go(j > 0, n.wrapping_sub(nx), [i, j.wrapping_sub(1), k]);
            go(j + 1 < ny, n + nx, [i, j + 1, k]);
            go(k > 0, n.wrapping_sub(sxy), [i, j, k.wrapping_sub(1)]);
            go(k + 1 < nz, n + sxy, [i, j, k + 1]);
        }
    }
}

/// Into `out`, per pixel of a slice of `dims`: whether it is `wall`, or lies within it.
/// Whether `wall` touches the slice's border (the field of view cuts the body there), and how
/// many pixels reaching the border were judged tissue.
///
/// What is not wall falls into regions (pixels joined to the four sharing an edge). A region
/// the border does not reach is within the body (the airway, the bowel's gas, the lungs of an
/// uncut slice). Where the body touches the border, a region that reaches the border may be
/// a lung the field of view cuts, as well as the air around the body: the region is taken for
/// air when at least half its pixels (`hu`) are at or below `air_hu`, and for tissue within
/// the body otherwise (lung parenchyma with its vessels).
fn enclosed_in_slice(
    [nx, ny]: [usize; 2],
    wall: &[bool],
    hu: &[f32],
    air_hu: f32,
    out: &mut [bool],
) -> (bool, usize) {
    // The border's pixels, each once (none in an empty slice).
    let mut border: Vec<usize> = (0..nx)
        .flat_map(|i| [i, i + nx * ny.saturating_sub(1)])
        .chain((0..ny).flat_map(|j| [nx * j, nx * j + nx.saturating_sub(1)]))
        .filter(|&n| n < nx * ny)
        .collect();
    border.sort_unstable();
    border.dedup();
    let cut = border.iter().any(|&n| wall[n]);
    // The regions: the pieces of what is not wall on a grid one voxel deep. Those the border
    // reaches, and how many of their pixels are air.
    let open: Vec<bool> = wall.iter().map(|&w| !w).collect();
    let (labels, sizes) = pieces([nx, ny, 1], &open);
    let mut reached = vec![false; sizes.len()];
    for &n in &border {
        if labels[n] > 0 {
            reached[labels[n] as usize - 1] = true;
        }
    }
    let mut air = vec![0usize; sizes.len()];
    for (&l, &v) in labels.iter().zip(hu) {
        if l > 0 && v <= air_hu {
            air[l as usize - 1] += 1;
        }
    }
    let outside: Vec<bool> = (0..sizes.len())
        .map(|r| reached[r] && (!cut || 2 * air[r] >= sizes[r]))
        .collect();
    let tissue = (0..sizes.len())
        .filter(|&r| reached[r] && !outside[r])
        .map(|r| sizes[r])
        .sum();
    for (o, &l) in out.iter_mut().zip(&labels) {
        *o = l == 0 || !outside[l as usize - 1];
    }
    (cut, tissue)
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::*;
    use crate::distance::squared_distance;

    /// A phantom on a 2 mm grid of 80 × 50 × 30 voxels (x across, y up from the table, z
    /// along it): its parts' voxels.
    struct Phantom {
        vol: Volume,
        trunk: Vec<usize>,
        lung: Vec<usize>,
        ear: Vec<usize>,
        arm: Vec<usize>,
        table: Vec<usize>,
        cable: Vec<usize>,
    }

    /// A trunk (an elliptic cylinder 70 × 50 mm, 40 HU) with a lung inside (−850 HU) and an
    /// ear (a flap 2 mm thick, 8 × 8 mm, 40 HU) on its side; an arm beside it (a cylinder
    /// 36 mm across, 12 mm away); under them a table's top (a plate 4 mm thick, 300 HU, as
    /// wide and long as the grid) that the trunk rests on along its whole length; a cable
    /// across the air above (2 mm, 1000 HU).
    fn phantom() -> Phantom {
        let dims = [80usize, 50, 30];
        let at = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        let mut data = vec![-1000.0f32; dims.iter().product()];
        let mut p = Phantom {
            vol: Volume::hounsfield(dims, [2.0; 3], Vec::new()),
            trunk: Vec::new(),
            lung: Vec::new(),
            ear: Vec::new(),
            arm: Vec::new(),
            table: Vec::new(),
            cable: Vec::new(),
        };
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let n = at(i, j, k);
                    // mm from the trunk's axis (x 60, y 40): its lowest voxels are in row 8,
                    // on the table's top row 7.
                    let (x, y) = (i as f64 * 2.0 - 60.0, j as f64 * 2.0 - 40.0);
                    if (x / 35.0).powi(2) + (y / 25.0).powi(2) <= 1.0 {
                        let lung =
                            (x / 20.0).powi(2) + (y / 12.0).powi(2) <= 1.0 && k > 3 && k < 26;
                        data[n] = if lung { -850.0 } else { 40.0 };
                        if lung { &mut p.lung } else { &mut p.trunk }.push(n);
                    } else if j == 20 && (48..52).contains(&i) && (10..14).contains(&k) {
                        data[n] = 40.0;
                        p.ear.push(n);
                    } else if (x - 65.0).powi(2) + (y - 5.0).powi(2) <= 18.0f64.powi(2) {
                        data[n] = 40.0;
                        p.arm.push(n);
                    } else if j == 6 || j == 7 {
                        data[n] = 300.0;
                        p.table.push(n);
                    } else if j == 45 && i == 30 {
                        data[n] = 1000.0;
                        p.cable.push(n);
                    }
                }
            }
        }
        p.vol.data = data;
        p
    }

    #[test]
    fn a_phantom_s_body_is_kept_and_its_table_left_out() {
        let p = phantom();
        let b = body(&p.vol, &BodyOptions::default()).unwrap();
        for (part, voxels) in [
            ("trunk", &p.trunk),
            ("lung", &p.lung),
            ("ear", &p.ear),
            ("arm", &p.arm),
        ] {
            let out = voxels.iter().filter(|&&n| !b.inside[n]).count();
            assert_eq!(
                out,
                0,
                "{out} of the {part}'s {} voxels left out",
                voxels.len()
            );
        }
        assert!(p.cable.iter().all(|&n| !b.inside[n]), "the cable kept");
        // The table is left out but for a sliver where the trunk rests on it: the voxels
        // within the opening's radius and a voxel (4 + 2 mm) of the trunk's core, which
        // reaches the trunk's lowest row there (the table closes it from below).
        let dims = p.vol.dims;
        let trunk_distance2 = squared_distance(dims, [2.0; 3], |n| {
            p.trunk.contains(&n) || p.lung.contains(&n)
        });
        for &n in &p.table {
            let mm = trunk_distance2[n].sqrt();
            assert!(
                mm <= 6.0 || !b.inside[n],
                "table voxel {n}, {mm} mm from the trunk, kept"
            );
        }
        let kept = p.table.iter().filter(|&&n| b.inside[n]).count();
        // The air around is out: the body is its parts and the sliver.
        let parts = p.trunk.len() + p.lung.len() + p.ear.len() + p.arm.len();
        assert_eq!(b.voxels, parts + kept);
        // Its tissues: the lung (−850 HU), the soft parts (40 HU), the table's sliver (300).
        let soft = p.trunk.len() + p.ear.len() + p.arm.len();
        assert_eq!(
            b.tissues(&p.vol),
            Tissues {
                air: p.lung.len(),
                fat: 0,
                soft,
                dense: kept
            }
        );
        // Left out: the table's two wings, which the sliver cuts apart, and the cable; the
        // ear joined back.
        let ml = 0.008;
        let table_ml = (p.table.len() - kept) as f64 * ml;
        let cable_ml = p.cable.len() as f64 * ml;
        assert_eq!(b.left_out_ml.len(), 3, "{:?}", b.left_out_ml);
        assert!((b.left_out_ml[0] + b.left_out_ml[1] - table_ml).abs() < 1e-9);
        assert!(
            (b.left_out_ml[2] - cable_ml).abs() < 1e-9,
            "{:?}",
            b.left_out_ml
        );
        assert_eq!(b.thin_parts, 1);
        // The ear's far part (its near one lies within the opening's reach).
        assert!(b.thin_part_ml > 0.0 && b.thin_part_ml < p.ear.len() as f64 * ml);
    }

    /// The phantom cut by the field of view through its lung (the columns up to 66 mm from
    /// the grid's side, 6 mm past the trunk's axis), with a vessel along the lung (a line of
    /// 40 HU voxels, thinner than the ball, reaching no wall): the lung reaches the border in
    /// every slice that has it, the air around the trunk too.
    #[test]
    fn a_lung_the_field_of_view_cuts_is_kept_and_the_air_left_out() {
        let mut p = phantom();
        let [nx, ny, nz] = p.vol.dims;
        let (cx, at) = (34, |i: usize, j: usize, k: usize| i + nx * (j + ny * k));
        let vessel: Vec<usize> = (6..24).map(|k| at(28, 20, k)).collect();
        for &n in &vessel {
            p.vol.data[n] = 40.0;
        }
        let lung: Vec<usize> = p
            .lung
            .iter()
            .copied()
            .filter(|n| !vessel.contains(n))
            .collect();
        // The crop, and each part's voxels in it.
        let cropped = |n: usize| (n % nx < cx).then(|| n % nx + cx * (n / nx));
        let mut data = vec![0.0f32; cx * ny * nz];
        for (n, &v) in p.vol.data.iter().enumerate() {
            if let Some(c) = cropped(n) {
                data[c] = v;
            }
        }
        let part = |v: &[usize]| -> Vec<usize> { v.iter().filter_map(|&n| cropped(n)).collect() };
        let (trunk, lung, vessel) = (part(&p.trunk), part(&lung), part(&vessel));
        let (table, cable) = (part(&p.table), part(&p.cable));
        let mut vol = Volume::hounsfield([cx, ny, nz], [2.0; 3], data);
        let b = body(&vol, &BodyOptions::default()).unwrap();
        assert_eq!(b.cut_slices, nz);
        for (name, v) in [("trunk", &trunk), ("lung", &lung), ("vessel", &vessel)] {
            let out = v.iter().filter(|&&n| !b.inside[n]).count();
            assert_eq!(out, 0, "{out} of the {name}'s {} voxels left out", v.len());
        }
        // The lung and its vessel are the tissue reaching the border; the air and the table
        // and cable in it are left out, but for the table's sliver under the trunk.
        let ml = 0.008;
        let tissue = (lung.len() + vessel.len()) as f64 * ml;
        assert!(
            (b.border_tissue_ml - tissue).abs() < 1e-9,
            "{}",
            b.border_tissue_ml
        );
        assert!(cable.iter().all(|&n| !b.inside[n]), "the cable kept");
        let mut of_trunk = vec![false; vol.data.len()];
        for &n in trunk.iter().chain(&lung) {
            of_trunk[n] = true;
        }
        let near2 = squared_distance(vol.dims, [2.0; 3], |n| of_trunk[n]);
        let kept = table.iter().filter(|&&n| b.inside[n]).count();
        assert!(
            table.iter().all(|&n| !b.inside[n] || near2[n] <= 36.0) && kept < table.len() / 2,
            "{kept} of {} table voxels kept",
            table.len()
        );
        assert_eq!(b.voxels, trunk.len() + lung.len() + vessel.len() + kept);
        // The limit the module states: a lung mostly below −900 HU reads as air, and is left
        // out with its vessel.
        for &n in &lung {
            vol.data[n] = -950.0;
        }
        let b = body(&vol, &BodyOptions::default()).unwrap();
        assert_eq!(b.border_tissue_ml, 0.0);
        assert!(lung.iter().chain(&vessel).all(|&n| !b.inside[n]));
    }

    /// The tissues' ranges at their edges: −190 and −30 HU are fat, 150 soft tissue; a NaN
    /// voxel counts in none, and a voxel outside the body in none.
    #[test]
    fn tissues_are_counted_by_their_ranges() {
        let data = vec![-191.0, -190.0, -30.0, -29.5, 150.0, 150.5, f32::NAN, 40.0];
        let vol = Volume::hounsfield([8, 1, 1], [1.0; 3], data);
        let mut inside = vec![true; 8];
        inside[7] = false;
        let b = Body {
            inside,
            voxels: 7,
            left_out_ml: Vec::new(),
            thin_parts: 0,
            thin_part_ml: 0.0,
            cut_slices: 0,
            border_tissue_ml: 0.0,
        };
        let want = Tissues {
            air: 1,
            fat: 2,
            soft: 2,
            dense: 1,
        };
        assert_eq!(b.tissues(&vol), want);
    }

    /// The pieces against a union of each voxel with its neighbours along +i, +j and +k, on
    /// random grids (a few, a half and most voxels members), numbered by their first voxels.
    #[test]
    fn pieces_are_those_of_a_union_find() {
        let mut seed = 7u64;
        let mut next = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for (dims, per_mille) in [
            ([9, 7, 5], 200),
            ([6, 11, 8], 500),
            ([13, 4, 9], 800),
            ([1, 1, 1], 1000),
        ] {
            let len: usize = dims.iter().product();
            let member: Vec<bool> = (0..len).map(|_| next() % 1000 < per_mille).collect();
            let mut parent: Vec<usize> = (0..len).collect();
            fn root(parent: &mut [usize], mut n: usize) -> usize {
                while parent[n] != n {
                    parent[n] = parent[parent[n]];
                    n = parent[n];
                }
                n
            }
            let [nx, ny, _] = dims;
            for n in 0..len {
                let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
                for (near, m) in [
                    (i + 1 < nx, n + 1),
                    (j + 1 < ny, n + nx),
                    (k + 1 < dims[2], n + nx * ny),
                ] {
                    if near && member[n] && member[m] {
                        let (a, b) = (root(&mut parent, n), root(&mut parent, m));
                        parent[a.max(b)] = a.min(b);
                    }
                }
            }
            let (mut want, mut sizes) = (vec![0u32; len], Vec::<usize>::new());
            let mut number = std::collections::HashMap::new();
            for n in (0..len).filter(|&n| member[n]) {
                let r = root(&mut parent, n);
                let l = *number.entry(r).or_insert_with(|| {
                    sizes.push(0);
                    sizes.len() as u32
                });
                want[n] = l;
                sizes[l as usize - 1] += 1;
            }
            assert_eq!(pieces(dims, &member), (want, sizes), "{dims:?}");
        }
    }

    #[test]
    fn no_body_is_an_error() {
        let air = Volume::hounsfield([8, 8, 8], [1.0; 3], vec![-1000.0; 512]);
        let e = body(&air, &BodyOptions::default()).unwrap_err();
        assert!(e.contains("no voxel above -500 HU"), "{e}");
        // A plate 3 mm thick: nothing deeper than the ball.
        let mut data = vec![-1000.0; 20 * 20 * 20];
        data[20 * 20 * 10..20 * 20 * 13].fill(0.0);
        let plate = Volume::hounsfield([20, 20, 20], [1.0; 3], data);
        let e = body(&plate, &BodyOptions::default()).unwrap_err();
        assert!(e.contains("thicker than 8 mm"), "{e}");
    }

    /// The margin and the body less its rim, against their definitions voxel by voxel.
    #[test]
    fn the_margin_and_the_rim_are_the_voxels_beside_the_body() {
        let dims = [7usize, 5, 4];
        let mut seed = 99u64;
        let inside: Vec<bool> = (0..140)
            .map(|_| {
                seed = (seed.wrapping_mul(6364136223846793005)).wrapping_add(1442695040888963407);
                (seed >> 62) != 0
            })
            .collect();
        let b = Body {
            voxels: 0,
            inside: inside.clone(),
            left_out_ml: Vec::new(),
            thin_parts: 0,
            thin_part_ml: 0.0,
            cut_slices: 0,
            border_tissue_ml: 0.0,
        };
        let (margin, core) = (b.with_margin(dims), b.without_rim(dims));
        let at = |[i, j, k]: [i64; 3]| {
            let inside_grid = (0..7).contains(&i) && (0..5).contains(&j) && (0..4).contains(&k);
            inside_grid.then(|| (i + 7 * (j + 5 * k)) as usize)
        };
        let mut counts = [0; 2];
        for n in 0..140i64 {
            let p = [n % 7, n / 7 % 5, n / 35];
            let around = |keep: &dyn Fn(i64) -> bool| {
                (0..27)
                    .map(|d| [d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1])
                    .filter(|d| keep(d.iter().map(|x: &i64| x.abs()).sum()))
                    .filter_map(|d| at([p[0] + d[0], p[1] + d[1], p[2] + d[2]]))
                    .collect::<Vec<usize>>()
            };
            let near = around(&|_| true).iter().any(|&q| inside[q]);
            let whole = around(&|s| s <= 1).iter().all(|&q| inside[q]);
            assert_eq!(margin[n as usize], near, "margin at {p:?}");
            assert_eq!(core[n as usize], whole, "rim at {p:?}");
            counts[0] += usize::from(near && !inside[n as usize]);
            counts[1] += usize::from(inside[n as usize] && !whole);
        }
        assert!(counts[0] > 0 && counts[1] > 0, "{counts:?}");
    }

    fn ct(path: &str) -> Volume {
        let p: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join(path);
        raystream_io::load_volume(&p, &Default::default()).unwrap()
    }

    /// The CTs in ../shared and the built-in one: what is left out lies behind the body or
    /// beside the head (the table, the holder), the skeleton is kept whole, and so is
    /// nearly all the dense tissue.
    #[test]
    fn real_ct_bodies_leave_out_the_table_and_the_holder() {
        // The chest CT is a crop within the body: every slice is cut, and the lungs reach
        // the border on both sides. They read as tissue, and are kept with their vessels:
        // nearly every voxel of lung parenchyma (−900 to −700 HU) and every one above
        // −500 HU but for specks; the air before the neck is left out.
        let chest = ct("../../../shared/data/volumes/nifti/chest_ct_stents_totalseg.nii.gz");
        let b = body(&chest, &BodyOptions::default()).unwrap();
        assert_eq!(b.cut_slices, chest.dims[2]);
        assert!(b.border_tissue_ml > 2000.0, "{} ml", b.border_tissue_ml);
        let share = |lo: f32, hi: f32| {
            let (mut all, mut kept) = (0usize, 0usize);
            for (&v, &inside) in chest.data.iter().zip(&b.inside) {
                if v > lo && v <= hi {
                    all += 1;
                    kept += usize::from(inside);
                }
            }
            kept as f64 / all as f64
        };
        let lung = share(-900.0, -700.0);
        assert!(lung > 0.98, "{lung} of the lung parenchyma kept");
        let air = share(f32::MIN, -980.0);
        assert!(air < 0.5, "{air} of the air kept");
        assert!(
            b.left_out_ml.iter().sum::<f64>() < 1.0,
            "{:?}",
            b.left_out_ml
        );
        assert!(
            b.left_out_ml.iter().all(|&ml| ml < 1.0),
            "{:?}",
            b.left_out_ml
        );
        // Each with the slices whose border the body reaches: the built-in CT is cropped
        // close about the body, which its flanks touch.
        for (path, at_least_ml, cut) in [
            (
                "../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz",
                250.0,
                76,
            ),
            (
                "../../../shared/data/volumes/dicom/abdomen_ct_j2k_totalseg",
                150.0,
                0,
            ),
            (
                "../../../shared/data/volumes/dicom/head_ct_gantry_tilt_ge",
                80.0,
                0,
            ),
        ] {
            let vol = ct(path);
            let b = body(&vol, &BodyOptions::default()).unwrap();
            assert_eq!(b.cut_slices, cut, "{path}");
            let ml: f64 = b.left_out_ml.iter().sum();
            assert!(ml >= at_least_ml, "{path}: {ml} ml left out");
            // The big pieces left out are the devices: the thin parts kept are small.
            assert!(
                b.left_out_ml.iter().filter(|&&x| x > 1.0).count() >= 2,
                "{path}"
            );
            assert!(
                b.thin_part_ml < 30.0,
                "{path}: {} ml of thin parts",
                b.thin_part_ml
            );
            // The skeleton whole, and all but the devices' share of the dense voxels.
            let (mut dense, mut dense_in) = (0usize, 0usize);
            for (&v, &inside) in vol.data.iter().zip(&b.inside) {
                assert!(v <= 700.0 || inside, "{path}: bone left out");
                if v > -500.0 {
                    dense += 1;
                    dense_in += usize::from(inside);
                }
            }
            let out_ml = (dense - dense_in) as f64 * vol.voxel_ml();
            assert!(
                (out_ml - ml).abs() < 1e-6 * ml,
                "{path}: {out_ml} ml out for {ml}"
            );
        }
    }
}
