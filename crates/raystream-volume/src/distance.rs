//! Exact Euclidean distance transforms on 2-D and 3-D grids (Felzenszwalb and Huttenlocher
//! 2012: a lower envelope of parabolas along each axis in turn), with a spacing per axis: the
//! lumen's opening on a cross-section and the centreline's medial cost in a CT volume use them.
//! Written here: they are a few dozen lines, and the image-processing crates that have one
//! would add a large dependency for them (and take no anisotropic voxels).

use rayon::prelude::*;

/// Per cell of a grid of `dims` (x fastest) with `spacing` per axis, the squared distance to
/// the nearest cell that is `target`, in the spacing's units squared (+∞ where there is none;
/// beyond the grid's border none is assumed). The lines along each axis are transformed in
/// parallel (a CT of 512 × 512 × 300 voxels has 78 million cells).
pub fn squared_distance<const N: usize>(
    dims: [usize; N],
    spacing: [f64; N],
    target: impl Fn(usize) -> bool + Sync,
) -> Vec<f64> {
    squared_distance_in(dims, spacing, target)
}

/// A cell of a distance grid: f64, or f32 for a grid half the size (a CT's, whose squared
/// distances in mm² are then kept to 24 bits, a few in 10⁸; each line is transformed in f64
/// all the same).
pub trait Cell: Copy + Send + Sync + 'static {
    const INFINITY: Self;
    const ZERO: Self;
    fn get(self) -> f64;
    fn put(x: f64) -> Self;
}

impl Cell for f64 {
    const INFINITY: f64 = f64::INFINITY;
    const ZERO: f64 = 0.0;
    fn get(self) -> f64 {
        self
    }
    fn put(x: f64) -> f64 {
        x
    }
}

impl Cell for f32 {
    const INFINITY: f32 = f32::INFINITY;
    const ZERO: f32 = 0.0;
    fn get(self) -> f64 {
        self as f64
    }
    fn put(x: f64) -> f32 {
        x as f32
    }
}

/// [`squared_distance`] on a grid of cells of type `T`.
pub fn squared_distance_in<T: Cell, const N: usize>(
    dims: [usize; N],
    spacing: [f64; N],
    target: impl Fn(usize) -> bool + Sync,
) -> Vec<T> {
    let total: usize = dims.iter().product();
    let mut d: Vec<T> = (0..total)
        .into_par_iter()
        .with_min_len(1 << 14)
        .map(|k| if target(k) { T::ZERO } else { T::INFINITY })
        .collect();
    if total == 0 {
        return d;
    }
    for axis in 0..N {
        let (n, h) = (dims[axis], spacing[axis]);
        let stride: usize = dims[..axis].iter().product();
        // A block of `stride` whole lines along `axis`, each starting at one of its first
        // `stride` cells: the blocks are apart in memory, and transformed each on a thread.
        let block = stride * n;
        if block < total {
            // Small grids (a vessel's cross-section) on one thread.
            d.par_chunks_mut(block)
                .with_min_len((1 << 14) / block + 1)
                .for_each_init(
                    || Lines::new(n),
                    |lines, chunk| {
                        for first in (0..stride).step_by(WIDE) {
                            lines.transform(chunk, first..(first + WIDE).min(stride), stride, h);
                        }
                    },
                );
        } else {
            // One block (the last axis): groups of its lines read, transformed and gathered
            // in parallel, then written back, a batch of groups at a time (so that the
            // copy is a batch's, not the grid's: 64 × 1024 lines of 135 cells on the head CT,
            // 71 MB, for a grid of 283 MB).
            const GROUP: usize = 1024;
            const BATCH: usize = 64;
            let groups = stride.div_ceil(GROUP);
            for batch in (0..groups).step_by(BATCH) {
                let done: Vec<Vec<T>> = (batch..(batch + BATCH).min(groups))
                    .into_par_iter()
                    .map_init(
                        || Lines::new(n),
                        |lines, g| {
                            let starts = g * GROUP..((g + 1) * GROUP).min(stride);
                            let mut out = Vec::with_capacity(starts.len() * n);
                            for first in starts.clone().step_by(WIDE) {
                                let wide = first..(first + WIDE).min(starts.end);
                                lines.gather(&d, wide.clone(), stride);
                                lines.envelopes(wide.len(), h);
                                out.extend(lines.out[..wide.len() * n].iter().map(|&x| T::put(x)));
                            }
                            out
                        },
                    )
                    .collect();
                for (g, out) in (batch..).zip(&done) {
                    for (l, line) in out.chunks_exact(n).enumerate() {
                        let start = g * GROUP + l;
                        for (q, &x) in line.iter().enumerate() {
                            d[start + q * stride] = x;
                        }
                    }
                }
            }
        }
    }
    d
}

/// How many adjacent lines a pass along a strided axis reads at once: their cells at one
/// position along the axis are side by side in memory, a cache line of f64s, where a line
/// alone would read 8 bytes of each cache line it touches.
const WIDE: usize = 8;

/// Up to [`WIDE`] lines' values, each line's cells together, and the lower envelope's scratch.
struct Lines {
    n: usize,
    f: Vec<f64>,
    out: Vec<f64>,
    v: Vec<usize>,
    z: Vec<f64>,
}

impl Lines {
    fn new(n: usize) -> Lines {
        Lines {
            n,
            f: vec![0.0; n * WIDE],
            out: vec![0.0; n * WIDE],
            v: vec![0; n],
            z: vec![0.0; n + 1],
        }
    }

    /// The lines of `d` starting at `starts` (adjacent cells), `stride` apart along them,
    /// into `f`, a line after another.
    fn gather<T: Cell>(&mut self, d: &[T], starts: std::ops::Range<usize>, stride: usize) {
        let (n, w) = (self.n, starts.len());
        for q in 0..n {
            let at = starts.start + q * stride;
            for (l, &x) in d[at..at + w].iter().enumerate() {
                self.f[l * n + q] = x.get();
            }
        }
    }

    /// The first `w` lines of `f` transformed into `out`.
    fn envelopes(&mut self, w: usize, h: f64) {
        let n = self.n;
        for l in 0..w {
            let line = l * n..(l + 1) * n;
            envelope(
                &self.f[line.clone()],
                h,
                &mut self.out[line],
                &mut self.v,
                &mut self.z,
            );
        }
    }

    /// The lines of `d` starting at `starts`, `stride` apart along them, transformed in place.
    fn transform<T: Cell>(
        &mut self,
        d: &mut [T],
        starts: std::ops::Range<usize>,
        stride: usize,
        h: f64,
    ) {
        self.gather(d, starts.clone(), stride);
        let (n, w) = (self.n, starts.len());
        self.envelopes(w, h);
        for q in 0..n {
            let at = starts.start + q * stride;
            for (l, x) in d[at..at + w].iter_mut().enumerate() {
                *x = T::put(self.out[l * n + q]);
            }
        }
    }
}

/// The 1-D squared distance transform of `f` (0 at targets, +∞ elsewhere, or the squared
/// distances of an earlier pass) with cells `h` apart, into `out`: min over q of
/// ((p − q)·h)² + f(q).
fn envelope(f: &[f64], h: f64, out: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let Some(first) = f.iter().position(|x| x.is_finite()) else {
        out.fill(f64::INFINITY);
        return;
    };
    let h2 = h * h;
    // Each parabola's f/h² + q², once a cell (`out` holds them until the envelope is found),
    // rather than twice a meeting of two (the same values: BENCHMARKS.md).
    for (q, (g, &fq)) in out.iter_mut().zip(f).enumerate() {
        let qf = q as f64;
        *g = fq / h2 + qf * qf;
    }
    // Where the parabolas of q and p (q > p) meet, in cells.
    let meet = |out: &[f64], q: usize, p: usize| {
        let (qf, pf) = (q as f64, p as f64);
        (out[q] - out[p]) / (2.0 * (qf - pf))
    };
    let mut k = 0;
    v[0] = first;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for (q, fq) in f.iter().enumerate().skip(first + 1) {
        if !fq.is_finite() {
            continue;
        }
        let mut s = meet(out, q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = meet(out, q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    let mut k = 0;
    for (p, o) in out.iter_mut().enumerate() {
        while z[k + 1] < p as f64 {
            k += 1;
        }
        let dq = (p as f64 - v[k] as f64) * h;
        *o = dq * dq + f[v[k]];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The brute-force squared distance from cell `k` to the nearest target.
    fn brute<const N: usize>(
        dims: [usize; N],
        spacing: [f64; N],
        target: &[bool],
        k: usize,
    ) -> f64 {
        let coords = |mut k: usize| {
            let mut c = [0usize; N];
            for a in 0..N {
                c[a] = k % dims[a];
                k /= dims[a];
            }
            c
        };
        let p = coords(k);
        (0..target.len())
            .filter(|&t| target[t])
            .map(|t| {
                let q = coords(t);
                (0..N)
                    .map(|a| ((q[a] as f64 - p[a] as f64) * spacing[a]).powi(2))
                    .sum::<f64>()
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn random(n: usize, density: f64, seed: &mut u64) -> Vec<bool> {
        (0..n)
            .map(|_| {
                *seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((*seed >> 33) as f64 / (1u64 << 31) as f64) < density
            })
            .collect()
    }

    #[test]
    fn two_dimensional_transforms_are_the_brute_force_ones() {
        let mut seed = 12345u64;
        for (n, density) in [(1usize, 1.0), (7, 0.2), (33, 0.05), (50, 0.01), (9, 0.0)] {
            let target = random(n * n, density, &mut seed);
            let d = squared_distance([n, n], [1.0, 1.0], |k| target[k]);
            for (k, &got) in d.iter().enumerate() {
                assert_eq!(
                    got,
                    brute([n, n], [1.0, 1.0], &target, k),
                    "n {n}, cell {k}"
                );
            }
        }
    }

    /// More lines along the last axis than a batch of groups holds (260 × 260 of them, in
    /// two batches): every 211th cell against brute force.
    #[test]
    fn a_wide_grid_s_last_axis_is_the_brute_force_one() {
        let mut seed = 4242u64;
        let (dims, spacing) = ([260usize, 260, 2], [0.5, 0.7, 3.0]);
        let target = random(dims.iter().product(), 0.0005, &mut seed);
        let d = squared_distance(dims, spacing, |k| target[k]);
        for k in (0..d.len()).step_by(211) {
            let want = brute(dims, spacing, &target, k);
            assert!(
                (d[k] - want).abs() <= 1e-9 * want.max(1.0),
                "cell {k}: {} for {want}",
                d[k]
            );
        }
    }

    /// A grid of f32 cells: the f64 grid's values, each within f32's rounding of three passes.
    #[test]
    fn an_f32_grid_holds_the_f64_grid_s_values() {
        let mut seed = 99u64;
        let (dims, spacing) = ([37usize, 29, 41], [0.48828125, 0.7, 1.13]);
        let target = random(dims.iter().product(), 0.0002, &mut seed);
        let wide: Vec<f64> = squared_distance(dims, spacing, |k| target[k]);
        let narrow: Vec<f32> = squared_distance_in(dims, spacing, |k| target[k]);
        assert!(wide.iter().any(|&d| d > 100.0));
        for (k, (&w, &n)) in wide.iter().zip(&narrow).enumerate() {
            assert!(
                (n as f64 - w).abs() <= 4.0 * f32::EPSILON as f64 * w,
                "cell {k}: {n} for {w}"
            );
        }
        let none: Vec<f32> = squared_distance_in([3, 3], [1.0, 1.0], |_| false);
        assert!(none.iter().all(|d| d.is_infinite()));
    }

    #[test]
    fn anisotropic_three_dimensional_transforms_are_the_brute_force_ones() {
        let mut seed = 777u64;
        for (dims, spacing, density) in [
            ([9usize, 7, 5], [0.7, 1.3, 3.0], 0.03),
            ([4, 11, 6], [2.0, 0.5, 1.0], 0.1),
            ([1, 1, 8], [1.0, 1.0, 0.25], 0.2),
            // More lines along the last axis than one group of them holds.
            ([40, 30, 3], [1.0, 0.8, 2.5], 0.01),
        ] {
            let total = dims.iter().product();
            let target = random(total, density, &mut seed);
            let d = squared_distance(dims, spacing, |k| target[k]);
            for (k, &got) in d.iter().enumerate() {
                let want = brute(dims, spacing, &target, k);
                assert!(
                    (got - want).abs() <= 1e-9 * want.max(1.0) || got == want,
                    "{dims:?} cell {k}: {got} for {want}"
                );
            }
        }
    }
}
