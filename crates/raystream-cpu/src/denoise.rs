//! Denoising a path-traced frame (`render --mode cinematic --denoise`): the edge-avoiding
//! à-trous wavelet filter of Dammertz et al. 2010, steered as in SVGF's spatial filter (Schied
//! et al. 2017) by each pixel's own variance, so that it smooths the Monte Carlo noise and
//! keeps what the paths agree on.
//!
//! Passes of a 5×5 B3-spline kernel whose taps lie 1, 2, 4 … pixels apart (three by
//! default: a 29×29 footprint at 25 taps a pixel a pass), over the light divided by the guides'
//! albedo (multiplied back after: the colour's detail is then the guides', noise-free). Each
//! tap's weight is the kernel's times four edge-stopping terms:
//! - **luminance**: exp(−|ℓp − ℓq| / (σℓ·√(Var ℓp + Var ℓq) + ε)), the variances the pixels'
//!   own (from their paths, carried through the passes as Σw²·Var / (Σw)², blurred 3×3 before
//!   use): where the noise is small, only like values are averaged, so shadow edges and fine
//!   lighting stay. Symmetric in p and q: SVGF's one-sided σℓ·√Var ℓp let dark pixels whose few
//!   paths all missed the light (variance 0) refuse their bright neighbours while bright ones
//!   took dark ones in, darkening a frame of 8 paths a pixel by 14 %;
//! - **depth**: exp(−|zp − zq| / (σz·|∇zp·(q − p)| + δ)): a surface's depth may change as its
//!   slope says, δ being the guides' own depth resolution (their march step);
//! - **normal**: exp(−σn·|np − nq|²) on the guides' normals;
//! - **albedo**: exp(−|ap − aq|² / 2σa²) on the guides' colour.
//!
//! The guides ([`Guides`]) are noise-free: [`crate::cinematic::guides`] marches 2×2 rays a
//! pixel and composites, front to back, the colour, the normal and the depth of what they meet
//! by the light each step stops. The film's premultiplied light and its opacity are filtered
//! with the same weights, so the picture can still be laid over any background.
//!
//! This is the reference: raystream-gpu's `GpuDenoiser` runs the same passes in WGSL
//! (`kernels/denoise.wgsl`) on the GPU's frames, tested against it.
//!
//! Written here, not taken from a crate: Intel's Open Image Denoise (the `oidn` crate) needs
//! its C++ library, which Debian bookworm does not package, and no pure-Rust crate filters
//! with per-pixel variance and feature guides.

use rayon::prelude::*;
use raystream_math::Vec3;

use crate::Image;
use crate::cinematic::luminance;

/// A frame straight from the path tracer.
#[derive(Clone, Debug)]
pub struct NoisyFilm {
    /// Each pixel's mean light, premultiplied (background apart).
    pub film: Image,
    /// Each pixel's opacity 1 − T: over a background B it shows film + (1 − α)·B.
    pub alpha: Vec<f32>,
    /// The variance of each pixel's luminance as an estimate (its paths' sample variance over
    /// their count).
    pub variance: Vec<f32>,
}

/// What each pixel's ray meets, noise-free, each step weighted by the light it stops: the
/// denoiser's edges.
#[derive(Clone, Debug)]
pub struct Guides {
    pub width: u32,
    pub height: u32,
    /// The mean distance from the eye of the light stopped, mm; +∞ where too little is.
    pub depth: Vec<f32>,
    /// Unit normals facing the eye, weighted by the light stopped and by how surface-like
    /// each point is (0 in a homogeneous medium).
    pub normal: Vec<Vec3>,
    /// Colours weighted by the light stopped (premultiplied by the pixel's coverage).
    pub albedo: Vec<Vec3>,
    /// Depth differences this small are the guides' own resolution (mm).
    pub tolerance: f32,
}

/// What denoising a frame cost, milliseconds of wall time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DenoiseTimes {
    /// Marching the guides.
    pub guides_ms: f64,
    /// The filter's passes.
    pub filter_ms: f64,
}

/// The filter's settings; [`Default`] is what `--denoise` uses.
#[derive(Clone, Copy, Debug)]
pub struct DenoiseOptions {
    /// Passes (the n-th takes taps 2ⁿ⁻¹ pixels apart).
    pub passes: u32,
    /// σℓ: how many standard deviations of noise two luminances may differ by.
    pub sigma_luminance: f32,
    /// σz: how far, in multiples of the slope's prediction, two depths may differ.
    pub sigma_depth: f32,
    /// σn: the normals' sharpness.
    pub sigma_normal: f32,
    /// σa: how far two colours may differ.
    pub sigma_albedo: f32,
    /// Filter the light divided by the guides' albedo (plus this), and multiply it back
    /// afterwards: the albedo's detail is then kept as the guides show it. 0: off.
    pub demodulate: f32,
}

impl Default for DenoiseOptions {
    fn default() -> Self {
        // SVGF's σz = 1; σℓ, σn, σa, the albedo's offset and the passes chosen on the chest
        // CT (150×200, 16 and 64 paths a pixel, against 1024) and the abdomen CT (320×240, 8
        // and 32 against 256): BENCHMARKS.md "Denoising".
        DenoiseOptions {
            passes: 3,
            sigma_luminance: 3.0,
            sigma_depth: 1.0,
            sigma_normal: 8.0,
            sigma_albedo: 0.2,
            demodulate: 0.05,
        }
    }
}

/// The B3-spline's weights, taps −2…2.
const KERNEL: [f32; 5] = [1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0];

/// Keeps a zero variance from dividing by zero (SVGF's ε).
const EPSILON: f32 = 1e-10;

/// `noisy` filtered along `guides` (of the same size): the denoised premultiplied light and
/// opacity.
pub fn denoise(noisy: &NoisyFilm, guides: &Guides, opt: &DenoiseOptions) -> (Image, Vec<f32>) {
    let (w, h) = (noisy.film.width as usize, noisy.film.height as usize);
    assert_eq!(
        (guides.width as usize, guides.height as usize),
        (w, h),
        "guides are made for their frame's size"
    );
    let n = w * h;
    assert!(noisy.film.pixels.len() == n && noisy.alpha.len() == n && noisy.variance.len() == n);
    let slope = depth_slopes(guides);
    let modulate: Vec<Vec3> = if opt.demodulate > 0.0 {
        guides
            .albedo
            .iter()
            .map(|a| *a + Vec3::splat(opt.demodulate))
            .collect()
    } else {
        vec![Vec3::ONE; n]
    };
    let mut light: Vec<Vec3> = noisy
        .film
        .pixels
        .iter()
        .zip(&modulate)
        .map(|(c, m)| *c / *m)
        .collect();
    let mut alpha = noisy.alpha.clone();
    let mut variance: Vec<f32> = noisy
        .variance
        .iter()
        .zip(&modulate)
        .map(|(v, m)| v / luminance(*m).powi(2))
        .collect();
    for pass in 0..opt.passes {
        let gap = 1usize << pass;
        let blurred = blur3(&variance, w, h);
        let out: Vec<(Vec3, f32, f32)> = (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|p| {
                let (x, y) = (p % w, p / w);
                let lp = luminance(light[p]);
                let (zp, np, ap) = (guides.depth[p], guides.normal[p], guides.albedo[p]);
                let (mut sum_w, mut sum_l, mut sum_a, mut sum_v) = (0.0f32, Vec3::ZERO, 0.0, 0.0);
                for (j, ky) in KERNEL.iter().enumerate() {
                    let dy = (j as isize - 2) * gap as isize;
                    let qy = y as isize + dy;
                    if qy < 0 || qy >= h as isize {
                        continue;
                    }
                    for (i, kx) in KERNEL.iter().enumerate() {
                        let dx = (i as isize - 2) * gap as isize;
                        let qx = x as isize + dx;
                        if qx < 0 || qx >= w as isize {
                            continue;
                        }
                        let q = qx as usize + qy as usize * w;
                        let zq = guides.depth[q];
                        let w_depth = match (zp.is_finite(), zq.is_finite()) {
                            (true, true) => {
                                let predicted =
                                    (slope[p].0 * dx as f32 + slope[p].1 * dy as f32).abs();
                                (-(zp - zq).abs()
                                    / (opt.sigma_depth * predicted + guides.tolerance))
                                    .exp()
                            }
                            (false, false) => 1.0,
                            _ => 0.0,
                        };
                        if w_depth == 0.0 {
                            continue;
                        }
                        let w_normal =
                            (-opt.sigma_normal * (np - guides.normal[q]).length_squared()).exp();
                        let w_albedo = (-(ap - guides.albedo[q]).length_squared()
                            / (2.0 * opt.sigma_albedo * opt.sigma_albedo))
                            .exp();
                        let scale = opt.sigma_luminance * (blurred[p] + blurred[q]).max(0.0).sqrt()
                            + EPSILON;
                        let w_light = (-(lp - luminance(light[q])).abs() / scale).exp();
                        let wq = kx * ky * w_depth * w_normal * w_albedo * w_light;
                        sum_w += wq;
                        sum_l += light[q] * wq;
                        sum_a += alpha[q] * wq;
                        sum_v += wq * wq * variance[q];
                    }
                }
                // The centre tap always counts (all its terms are 1).
                (sum_l / sum_w, sum_a / sum_w, sum_v / (sum_w * sum_w))
            })
            .collect();
        for (p, (l, a, v)) in out.into_iter().enumerate() {
            light[p] = l;
            alpha[p] = a;
            variance[p] = v;
        }
    }
    (
        Image {
            width: noisy.film.width,
            height: noisy.film.height,
            pixels: light.iter().zip(&modulate).map(|(c, m)| *c * *m).collect(),
        },
        alpha,
    )
}

/// Each pixel's depth change a pixel to the right and a pixel down: the smaller of its two
/// one-sided differences (across a silhouette the other side is another surface), 0 where
/// neither neighbour has a depth.
fn depth_slopes(g: &Guides) -> Vec<(f32, f32)> {
    let (w, h) = (g.width as usize, g.height as usize);
    let z = &g.depth;
    let along = |p: usize, back: Option<usize>, ahead: Option<usize>| {
        let d = |q: Option<usize>| {
            q.map(|q| (z[q] - z[p]).abs())
                .filter(|d| d.is_finite())
                .unwrap_or(f32::INFINITY)
        };
        let s = d(back).min(d(ahead));
        if s.is_finite() { s } else { 0.0 }
    };
    (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            if !z[p].is_finite() {
                return (0.0, 0.0);
            }
            (
                along(p, (x > 0).then(|| p - 1), (x + 1 < w).then(|| p + 1)),
                along(p, (y > 0).then(|| p - w), (y + 1 < h).then(|| p + w)),
            )
        })
        .collect()
}

/// A 3×3 binomial blur (1 2 1 each way), normalised at the edges.
fn blur3(v: &[f32], w: usize, h: usize) -> Vec<f32> {
    (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            let (mut s, mut ws) = (0.0f32, 0.0f32);
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let (qx, qy) = (x as isize + dx, y as isize + dy);
                    if qx < 0 || qy < 0 || qx >= w as isize || qy >= h as isize {
                        continue;
                    }
                    let k = (2 - dx.abs()) as f32 * (2 - dy.abs()) as f32;
                    s += k * v[qx as usize + qy as usize * w];
                    ws += k;
                }
            }
            s / ws
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A normal deviate per (pixel, seed), from a hash (Box–Muller).
    fn gaussian(p: usize, seed: u32) -> f32 {
        let mut rng = crate::cinematic::PathRng::new(p as u32, seed);
        let (u, v) = (rng.uniform().max(1e-7), rng.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
    }

    /// A flat, surface-like frame of `w`×`h` at depth 100 mm facing the eye, grey `truth(x)`
    /// plus noise of standard deviation `sd`, every pixel told its variance sd².
    fn frame(
        (w, h): (usize, usize),
        truth: impl Fn(usize) -> f32,
        sd: f32,
        depth: impl Fn(usize) -> f32,
    ) -> (NoisyFilm, Guides) {
        let n = w * h;
        let film = NoisyFilm {
            film: Image {
                width: w as u32,
                height: h as u32,
                pixels: (0..n)
                    .map(|p| Vec3::splat(truth(p % w) + sd * gaussian(p, 1)))
                    .collect(),
            },
            alpha: vec![1.0; n],
            variance: vec![sd * sd; n],
        };
        let guides = Guides {
            width: w as u32,
            height: h as u32,
            depth: (0..n).map(|p| depth(p % w)).collect(),
            normal: vec![Vec3::new(0.0, 0.0, -1.0); n],
            albedo: vec![Vec3::splat(0.5); n],
            tolerance: 0.5,
        };
        (film, guides)
    }

    /// Root-mean-square error of a column range against the truth.
    fn rms(img: &Image, cols: std::ops::Range<usize>, truth: impl Fn(usize) -> f32) -> f32 {
        let w = img.width as usize;
        let (mut s, mut k) = (0.0f32, 0);
        for (p, c) in img.pixels.iter().enumerate() {
            if cols.contains(&(p % w)) {
                s += (c.x - truth(p % w)).powi(2);
                k += 1;
            }
        }
        (s / k as f32).sqrt()
    }

    /// Mean of a column.
    fn column(img: &Image, x: usize) -> f32 {
        let w = img.width as usize;
        let col: Vec<f32> = img.pixels.iter().skip(x).step_by(w).map(|c| c.x).collect();
        col.iter().sum::<f32>() / col.len() as f32
    }

    /// A frame of one value stays that value, whatever the guides and variances.
    #[test]
    fn a_flat_frame_is_unchanged() {
        let (mut film, guides) = frame((40, 30), |_| 0.3, 0.0, |x| 100.0 + x as f32);
        film.variance = (0..1200).map(|p| (p % 7) as f32 * 0.01).collect();
        let (out, alpha) = denoise(&film, &guides, &DenoiseOptions::default());
        for (c, a) in out.pixels.iter().zip(&alpha) {
            assert!(
                (c.x - 0.3).abs() < 1e-6 && (a - 1.0).abs() < 1e-6,
                "{c} {a}"
            );
        }
    }

    /// Noise on a plane tilted away from the eye (depth rising 2 mm a pixel) is smoothed 4×
    /// or more, and a step in depth (another surface) keeps its two sides apart though their
    /// greys differ by less than the noise.
    #[test]
    fn noise_is_smoothed_and_silhouettes_kept() {
        let truth = |x: usize| if x < 32 { 0.40 } else { 0.48 };
        let depth = |x: usize| {
            if x < 32 {
                100.0 + 2.0 * x as f32
            } else {
                400.0
            }
        };
        let (film, guides) = frame((64, 48), truth, 0.1, depth);
        let (out, _) = denoise(&film, &guides, &DenoiseOptions::default());
        let before = rms(&film.film, 0..64, truth);
        let after = rms(&out, 0..64, truth);
        assert!(after < before / 4.0, "rms {before:.4} → {after:.4}");
        // The columns either side of the step keep their side's grey.
        for x in [30, 31, 32, 33] {
            let m = column(&out, x);
            assert!((m - truth(x)).abs() < 0.015, "column {x}: {m:.4}");
        }
        // Blind to depth (any difference within tolerance), the step smears.
        let blind = Guides {
            tolerance: 1e6,
            ..guides.clone()
        };
        let (smeared, _) = denoise(&film, &blind, &DenoiseOptions::default());
        let worst = (30..34)
            .map(|x| (column(&smeared, x) - truth(x)).abs())
            .fold(0.0, f32::max);
        assert!(worst > 0.02, "{worst}");
    }

    /// A step in light alone (a shadow's edge on a flat surface: the guides see nothing)
    /// stays sharp where it stands out of the noise: the luminance term keeps the two sides
    /// apart; with that term switched off (σℓ huge), the edge smears.
    #[test]
    fn shadow_edges_stand_out_of_the_noise() {
        let truth = |x: usize| if x < 32 { 0.2 } else { 0.8 };
        let (film, guides) = frame((64, 48), truth, 0.02, |_| 100.0);
        let (out, _) = denoise(&film, &guides, &DenoiseOptions::default());
        for x in [30, 31, 32, 33] {
            let m = column(&out, x);
            assert!((m - truth(x)).abs() < 0.02, "column {x}: {m:.4}");
        }
        let blind = DenoiseOptions {
            sigma_luminance: 1e6,
            ..Default::default()
        };
        let (smeared, _) = denoise(&film, &guides, &blind);
        assert!((column(&smeared, 31) - 0.2).abs() > 0.1);
    }
}
