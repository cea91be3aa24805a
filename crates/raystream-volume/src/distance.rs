//! Exact Euclidean distance transforms on 2-D and 3-D grids (Felzenszwalb and Huttenlocher
//! 2012: a lower envelope of parabolas along each axis in turn), with a spacing per axis: the
//! lumen's opening on a cross-section and the centreline's medial cost in a CT volume use them.
//! Written here: they are a few dozen lines, and the image-processing crates that have one
//! would add a large dependency for them (and take no anisotropic voxels).

/// Per cell of a grid of `dims` (x fastest) with `spacing` per axis, the squared distance to
/// the nearest cell that is `target`, in the spacing's units squared (+∞ where there is none;
/// beyond the grid's border none is assumed).
pub fn squared_distance<const N: usize>(
    dims: [usize; N],
    spacing: [f64; N],
    target: impl Fn(usize) -> bool,
) -> Vec<f64> {
    let total: usize = dims.iter().product();
    let mut d: Vec<f64> = (0..total)
        .map(|k| if target(k) { 0.0 } else { f64::INFINITY })
        .collect();
    let longest = dims.iter().copied().max().unwrap_or(0);
    let mut f = vec![0.0; longest];
    let mut out = vec![0.0; longest];
    let (mut v, mut z) = (vec![0usize; longest], vec![0.0f64; longest + 1]);
    for axis in 0..N {
        let n = dims[axis];
        let stride: usize = dims[..axis].iter().product();
        // Every line along `axis`: its first cell, for each cell of the other axes.
        for start in (0..total).filter(|k| (k / stride).is_multiple_of(n)) {
            for (q, x) in f[..n].iter_mut().enumerate() {
                *x = d[start + q * stride];
            }
            envelope(&f[..n], spacing[axis], &mut out[..n], &mut v, &mut z);
            for (q, &x) in out[..n].iter().enumerate() {
                d[start + q * stride] = x;
            }
        }
    }
    d
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
    // Where the parabolas of q and p (q > p) meet, in cells.
    let meet = |q: usize, p: usize| {
        let (qf, pf) = (q as f64, p as f64);
        ((f[q] / h2 + qf * qf) - (f[p] / h2 + pf * pf)) / (2.0 * (qf - pf))
    };
    let mut k = 0;
    v[0] = first;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for (q, fq) in f.iter().enumerate().skip(first + 1) {
        if !fq.is_finite() {
            continue;
        }
        let mut s = meet(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = meet(q, v[k]);
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

    #[test]
    fn anisotropic_three_dimensional_transforms_are_the_brute_force_ones() {
        let mut seed = 777u64;
        for (dims, spacing, density) in [
            ([9usize, 7, 5], [0.7, 1.3, 3.0], 0.03),
            ([4, 11, 6], [2.0, 0.5, 1.0], 0.1),
            ([1, 1, 8], [1.0, 1.0, 0.25], 0.2),
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
