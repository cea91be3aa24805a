//! Cinematic rendering (`--mode cinematic`): Monte Carlo path tracing of the CT volume as a
//! participating medium, the physically based volume rendering of Kroes, Post & Botha 2012
//! ("Exposure Render") that workstations sell as *cinematic rendering*. The CPU reference; the
//! GPU's `path_trace_volume` (kernels/cinematic.wgsl in raystream-gpu) draws the same random
//! numbers and follows the same paths.
//!
//! - **The medium**: the transfer function's opacity α per millimetre is an extinction
//!   coefficient σ = −ln(1 − α) per mm (so that a straight ray's transmittance is dvr mode's
//!   (1 − α)^Δs), capped at α = [`ALPHA_MAX`]; its colour is the single-scattering albedo.
//! - **Free flights** by delta tracking (Woodcock) against a grid of majorants (the largest σ
//!   the transfer function gives the samples of each [`MAJORANT_CELL`]³ cell, [`Majorants`]),
//!   cell by cell: a transparent cell is crossed in one step, and a tentative collision past a
//!   cell's far side restarts there (exponential distances are memoryless), so the estimate is
//!   exact whatever the majorants; tighter ones only take fewer samples.
//! - **Scattering** (Kroes et al.'s hybrid): at a collision a surface-like bounce about the
//!   gradient's normal with probability min(|∇HU| / 100 HU/mm, 1) (the weight dvr mode shades
//!   surfaces with), else a volume scattering by the Henyey–Greenstein phase function of
//!   `opt.anisotropy` (isotropic at 0). A surface reflects the transfer
//!   function's `specular` share by a white normalised Blinn–Phong lobe of its `specular_power`
//!   and the rest diffusely (Lambert) in its colour.
//! - **Light**: a directional key light above left of the camera, or where `--light` puts it
//!   ([`DvrOptions::key_light`], dvr `--shadows`' light), of irradiance [`KEY_IRRADIANCE`],
//!   sampled at every collision with a shadow ray whose transmittance comes from ratio
//!   tracking (Russian roulette below 0.1), and a uniform sky of radiance [`SKY_RADIANCE`]
//!   that scattered rays reach when they leave the volume, both scaled by 2^`opt.exposure`.
//!   Camera rays that leave without a collision show the background.
//! - **Paths** end after `bounces` scatterings (the last one still samples the key light);
//!   a pixel is the mean of `spp` paths, each through a random point of its pixel.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;
use raystream_accel::Isa;
use raystream_io::Volume;
use raystream_math::Vec3;
use raystream_scene::Camera;
use raystream_volume::TransferFunction;

use crate::Image;
use crate::denoise::{DenoiseTimes, Guides, NoisyFilm};
use crate::dvr::{
    DvrOptions, FULL_SHADING_GRADIENT, Marcher, Sight, cell_dims, cell_exit, cell_opacities,
    clip_interval, frame_options, scene_to_lps,
};

/// Opacity per mm is capped here before it becomes an extinction coefficient: σ ≤ 6.9 / mm.
pub const ALPHA_MAX: f32 = 0.999;
/// Irradiance of the key light (on a plane facing it): a white Lambertian surface facing it
/// sends back `KEY_IRRADIANCE / π` ≈ 0.8.
pub const KEY_IRRADIANCE: f32 = 2.5;
/// Radiance of the uniform sky that scattered rays leaving the volume see.
pub const SKY_RADIANCE: f32 = 0.35;

/// The light of a cinematic picture: a directional key light and a uniform sky.
#[derive(Clone, Copy, Debug)]
pub struct Lighting {
    /// Toward the key light (LPS, unit).
    pub key: Vec3,
    /// The key light's irradiance on a plane facing it.
    pub key_irradiance: f32,
    /// The sky's radiance.
    pub sky: f32,
}

impl Lighting {
    /// The key light of `opt` seen by `cam` ([`DvrOptions::key_light`]: above left unless
    /// placed) and the sky, at [`KEY_IRRADIANCE`] and [`SKY_RADIANCE`] (the GPU's constants)
    /// times 2^`opt.exposure`.
    pub fn studio(opt: &DvrOptions, cam: &Camera) -> Lighting {
        let scale = opt.exposure_scale();
        Lighting {
            key: opt.key_light(cam),
            key_irradiance: KEY_IRRADIANCE * scale,
            sky: SKY_RADIANCE * scale,
        }
    }
}

/// Below this transmittance a shadow ray plays Russian roulette (survives half the time,
/// doubled).
const ROULETTE_BELOW: f32 = 0.1;

/// The extinction coefficient (per mm) of opacity `alpha` per mm.
#[inline(always)]
pub fn sigma_of(alpha: f32) -> f32 {
    -(1.0 - alpha.clamp(0.0, ALPHA_MAX)).ln()
}

/// A path's random numbers: PCG's 32-bit output permutation (RXS-M-XS) over a 32-bit LCG,
/// seeded from the pixel and the sample by a hash. The GPU's `rng_seed` and `rng_next`
/// compute the same integers, so both devices draw the same numbers for the same path.
#[derive(Clone, Copy, Debug)]
pub struct PathRng {
    state: u32,
}

impl PathRng {
    pub fn new(pixel: u32, sample: u32) -> PathRng {
        let mut x =
            pixel.wrapping_mul(0x9E37_79B9) ^ sample.wrapping_mul(0x85EB_CA6B) ^ 0x2545_F491;
        x ^= x >> 16;
        x = x.wrapping_mul(0x7FEB_352D);
        x ^= x >> 15;
        x = x.wrapping_mul(0x846C_A68B);
        x ^= x >> 16;
        PathRng { state: x }
    }

    /// The next number in [0, 1), a multiple of 2⁻²⁴.
    #[inline(always)]
    pub fn uniform(&mut self) -> f32 {
        self.state = self
            .state
            .wrapping_mul(747_796_405)
            .wrapping_add(2_891_336_453);
        let s = self.state;
        let word = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277_803_737);
        let x = (word >> 22) ^ word;
        (x >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// A direction drawn uniformly on the unit sphere.
#[inline(always)]
fn uniform_sphere(rng: &mut PathRng) -> Vec3 {
    let z = 1.0 - 2.0 * rng.uniform();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * rng.uniform();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The Henyey–Greenstein phase function of anisotropy `g` (the mean cosine of the scattering
/// angle; 0: isotropic) at the cosine between the ray's way in and its way out, per steradian.
#[inline(always)]
fn henyey_greenstein(g: f32, cos: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * std::f32::consts::PI * denom * denom.sqrt())
}

/// Below this |g| the phase function is taken as isotropic (and sampled as
/// [`uniform_sphere`] samples, the paths of an isotropic medium unchanged).
const ISOTROPIC_BELOW: f32 = 1e-3;

/// A direction scattered from travel direction `d` by [`henyey_greenstein`]'s lobe (the cosine
/// by inverting its distribution, the azimuth uniform): its density is the phase function, so
/// a scattered path keeps its weight.
#[inline(always)]
fn phase_sample(g: f32, d: Vec3, rng: &mut PathRng) -> Vec3 {
    if g.abs() < ISOTROPIC_BELOW {
        return uniform_sphere(rng);
    }
    let u = rng.uniform();
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    let cos = ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0);
    about(d, cos, rng.uniform())
}

/// The phase function's value toward `wi` for a ray travelling along `d`.
#[inline(always)]
fn phase(g: f32, d: Vec3, wi: Vec3) -> f32 {
    if g.abs() < ISOTROPIC_BELOW {
        return 0.25 * std::f32::consts::FRAC_1_PI;
    }
    henyey_greenstein(g, d.dot(wi))
}

/// Two unit vectors that make an orthonormal basis with the unit `n` (Duff et al. 2017).
#[inline(always)]
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The unit direction at polar angle θ (its cosine) and azimuth 2π·`u` about the unit `n`.
#[inline(always)]
fn about(n: Vec3, cos_theta: f32, u: f32) -> Vec3 {
    let (t, bt) = basis(n);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * u;
    (t * (sin_theta * phi.cos()) + bt * (sin_theta * phi.sin()) + n * cos_theta).normalize()
}

/// A direction drawn about the unit normal `n` with density cos θ / π (Malley's method).
#[inline(always)]
fn cosine_hemisphere(n: Vec3, rng: &mut PathRng) -> Vec3 {
    let u = rng.uniform();
    about(n, (1.0 - u).max(0.0).sqrt(), rng.uniform())
}

/// The glossy lobe of a surface: the normalised Blinn–Phong BRDF (p + 2)/8π · (n·h)^p toward
/// unit `wi` seen from unit `wo` (both away from the surface), with h their half vector.
#[inline(always)]
fn blinn(n: Vec3, wo: Vec3, wi: Vec3, p: f32) -> f32 {
    let h = (wo + wi).normalize_or_zero();
    (p + 2.0) / (8.0 * std::f32::consts::PI) * n.dot(h).max(0.0).powf(p)
}

/// A direction drawn from [`blinn`]'s lobe (the half vector with density (p + 1)/2π ·
/// (n·h)^p, reflected), and its weight BRDF · cos θᵢ / pdf = (p + 2)/(p + 1) · cos θᵢ · (wo·h);
/// zero below the surface.
#[inline(always)]
fn glossy_sample(n: Vec3, wo: Vec3, p: f32, rng: &mut PathRng) -> (Vec3, f32) {
    let cos_h = rng.uniform().powf(1.0 / (p + 1.0));
    let h = about(n, cos_h, rng.uniform());
    let wo_h = wo.dot(h);
    let wi = h * (2.0 * wo_h) - wo;
    let cos_i = n.dot(wi);
    if cos_i <= 0.0 || wo_h <= 0.0 {
        return (wi, 0.0);
    }
    (wi, (p + 2.0) / (p + 1.0) * cos_i * wo_h)
}

/// The part of the ray o + t·d (LPS, unit d) inside the volume's voxel-centre box, the crop
/// box and the clip planes, restarted where it enters: its index form (origin, direction per
/// mm), its length inside (mm), and where it enters (t0).
#[inline(always)]
fn inside(m: &Marcher, opt: &DvrOptions, o: Vec3, d: Vec3) -> Option<((Vec3, Vec3, f32), f32)> {
    let (o_idx, d_idx) = (m.index_of(o), m.index_dir(d));
    let (t0, t1) = m.clip(o_idx, d_idx)?;
    let (t0, t1) = clip_interval(opt, o, d, t0, t1)?;
    Some(((o_idx + d_idx * t0, d_idx, t1 - t0), t0))
}

/// Cells of this many voxel spacings a side hold a majorant: finer than dvr's 8³ bricks, since
/// a majorant is only as tight as the densest voxel in its cell (on the chest CT with ct-aaa,
/// 8³ → 4³ cells took 45 % fewer samples and 29 % less time; 2³ a further 49 % fewer samples
/// for 6 % less time, at 8× the memory: BENCHMARKS.md).
pub const MAJORANT_CELL: usize = 4;

/// The majorant grid of cinematic mode's tracking: per cell of [`MAJORANT_CELL`]³ (x fastest),
/// the largest extinction coefficient (per mm) the transfer function gives any of the cell's
/// samples, as the marcher interpolates (or a bound just above it: `cell_opacities`). Zero
/// where the cell is transparent.
pub struct Majorants {
    pub dims: [usize; 3],
    pub values: Vec<f32>,
}

impl Majorants {
    /// The majorants of `tf` over the volume `m` samples, as `m` interpolates it.
    pub fn new(m: &Marcher, tf: &TransferFunction) -> Majorants {
        let vol = m.volume();
        Majorants {
            dims: cell_dims(vol.dims, MAJORANT_CELL),
            values: cell_opacities(vol.dims, m.grid(), MAJORANT_CELL, m.interpolation(), tf)
                .into_iter()
                .map(sigma_of)
                .collect(),
        }
    }

    /// The cell holding index `p` and where the ray leaves it (t, mm).
    #[inline(always)]
    fn exit(&self, p: Vec3, t: f32, d_idx: Vec3) -> (usize, f32) {
        cell_exit(p, t, d_idx, MAJORANT_CELL, self.dims)
    }
}

/// What cinematic paths walk through: the volume, its transfer function and their majorants.
pub struct Tracker<'a> {
    pub m: &'a Marcher<'a>,
    pub tf: &'a TransferFunction,
    pub majorants: &'a Majorants,
}

impl Tracker<'_> {
    /// Walks the ray o_idx + t·d_idx (t in mm) over [0, len] cell by cell, drawing tentative
    /// collisions at each cell's majorant rate; at each one `stop(hu, σ/σ̄, rng)` says whether
    /// the walk ends there. Returns where it ended (t, HU), or `None` past `len`; counts the
    /// volume's samples in `taken`.
    #[inline(always)]
    fn track(
        &self,
        (o_idx, d_idx, len): (Vec3, Vec3, f32),
        rng: &mut PathRng,
        taken: &mut u64,
        mut stop: impl FnMut(f32, f32, &mut PathRng) -> bool,
    ) -> Option<(f32, f32)> {
        let mut t = 0.0f32;
        // A ray of no finite length (a direction of NaN) would be tracked without end.
        if !len.is_finite() {
            return None;
        }
        while t < len {
            let (c, exit) = self.majorants.exit(o_idx + d_idx * t, t, d_idx);
            // A point on a cell's near face can find that cell again: step on regardless.
            let end = exit.min(len).max(t + 1e-4);
            let majorant = self.majorants.values[c];
            if majorant <= 0.0 {
                t = end;
                continue;
            }
            let tc = t - (1.0 - rng.uniform()).ln() / majorant;
            if tc >= end {
                t = end;
                continue;
            }
            t = tc;
            let hu = self.m.sample(o_idx + d_idx * t);
            *taken += 1;
            let ratio = (sigma_of(self.tf.opacity_at(hu)) / majorant).min(1.0);
            if stop(hu, ratio, rng) {
                return Some((t, hu));
            }
        }
        None
    }

    /// Delta tracking: the first real collision along the ray, (t, HU).
    #[inline(always)]
    fn free_flight(
        &self,
        ray: (Vec3, Vec3, f32),
        rng: &mut PathRng,
        taken: &mut u64,
    ) -> Option<(f32, f32)> {
        self.track(ray, rng, taken, |_, ratio, rng| rng.uniform() < ratio)
    }

    /// Ratio tracking: the transmittance along the ray (an unbiased estimate).
    #[inline(always)]
    fn transmittance_estimate(
        &self,
        ray: (Vec3, Vec3, f32),
        rng: &mut PathRng,
        taken: &mut u64,
    ) -> f32 {
        let mut tr = 1.0f32;
        let stopped = self.track(ray, rng, taken, |_, ratio, rng| {
            tr *= 1.0 - ratio;
            if tr <= 0.0 {
                return true;
            }
            if tr < ROULETTE_BELOW {
                if rng.uniform() < 0.5 {
                    return true;
                }
                tr *= 2.0;
            }
            false
        });
        if stopped.is_some() { 0.0 } else { tr }
    }
}

/// What one path brought back: the light it carries to the eye (the background apart) and
/// whether its camera ray left the volume without a collision (it then shows the background).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PathSample {
    pub light: Vec3,
    pub escaped: bool,
}

/// One path from LPS `o` along unit `d`: up to `opt.bounces` scatterings, each lit by the key
/// light through a shadow ray, and the sky where a scattered ray leaves.
#[inline(always)]
pub(crate) fn path(
    tracker: &Tracker,
    opt: &DvrOptions,
    (mut o, mut d): (Vec3, Vec3),
    lighting: &Lighting,
    rng: &mut PathRng,
    taken: &mut u64,
) -> PathSample {
    let mut throughput = Vec3::ONE;
    let mut light = Vec3::ZERO;
    let mut depth = 0u32;
    loop {
        let Tracker { m, tf, .. } = *tracker;
        let hit = inside(m, opt, o, d)
            .and_then(|(r, t0)| tracker.free_flight(r, rng, taken).map(|h| (r, t0, h)));
        let Some(((o_idx, d_idx, _), t0, (t, hu))) = hit else {
            if depth > 0 {
                light += throughput * lighting.sky;
            }
            return PathSample {
                light,
                escaped: depth == 0,
            };
        };
        let p_idx = o_idx + d_idx * t;
        let x = o + d * (t0 + t);
        let albedo = m.albedo(Vec3::from(tf.color_at(hu)), p_idx);
        let g = m.gradient(p_idx);
        let gm = g.length();
        // A gradient that is not finite (a NaN voxel among those it reads) gives no normal:
        // the sample scatters as the medium does. (Its normal of NaN sent the path on along a
        // direction of NaN, tracked without end.) The number is drawn either way, as the GPU
        // draws it.
        let u = rng.uniform();
        let surface = gm.is_finite() && u < (gm / FULL_SHADING_GRADIENT).min(1.0);
        // The gradient's normal, facing where the ray came from.
        let n = if surface {
            let n = -g / gm;
            if n.dot(d) > 0.0 { -n } else { n }
        } else {
            Vec3::ZERO
        };
        let key = lighting.key;
        // A surface reflects a `gloss` share of the light by the glossy lobe (white, as a
        // wet or polished surface does) and the rest diffusely in its colour.
        let shading = tf.shading;
        let gloss = if surface {
            shading.specular.clamp(0.0, 1.0)
        } else {
            0.0
        };
        let cos_l = n.dot(key);
        let f = if !surface {
            albedo * phase(opt.anisotropy, d, key)
        } else if cos_l > 0.0 {
            (albedo * ((1.0 - gloss) * std::f32::consts::FRAC_1_PI)
                + Vec3::splat(gloss * blinn(n, -d, key, shading.power)))
                * cos_l
        } else {
            Vec3::ZERO
        };
        if f.max_element() > 0.0 {
            // A match, not `Option::map_or`: a generic of the standard library's that the
            // compiler left out of line would run the shadow ray's tracking in the baseline's
            // code outside `pixel_v3` (35 % of a frame, by perf).
            let tr = match inside(m, opt, x, key) {
                Some((r, _)) => tracker.transmittance_estimate(r, rng, taken),
                None => 1.0,
            };
            light += throughput * f * (lighting.key_irradiance * tr);
        }
        if depth == opt.bounces {
            return PathSample {
                light,
                escaped: false,
            };
        }
        depth += 1;
        // The next direction: a lobe chosen by its share, weighted by BRDF · cos / pdf.
        if surface && rng.uniform() < gloss {
            let (wi, weight) = glossy_sample(n, -d, shading.power, rng);
            if weight <= 0.0 {
                return PathSample {
                    light,
                    escaped: false,
                };
            }
            throughput *= weight;
            d = wi;
        } else {
            throughput *= albedo;
            d = if surface {
                cosine_hemisphere(n, rng)
            } else {
                phase_sample(opt.anisotropy, d, rng)
            };
        }
        o = x;
    }
}

/// Luminance of linear Rec. 709 RGB: what the denoiser's variance and edge-stopping measure.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// A pixel's paths, summed up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PixelPaths {
    /// Their mean light (background apart).
    pub light: Vec3,
    /// The fraction of camera rays that left without a collision.
    pub escaped: f32,
    /// The variance of `light`'s luminance as an estimate of its mean (the paths' sample
    /// variance over their count); 0 for a single path.
    pub variance: f32,
    /// Volume samples taken.
    pub taken: u64,
}

/// The variance of the mean of `n` paths whose luminances sum to `sum` and whose squares sum to
/// `sum_sq` (the GPU computes it in the same f32 steps).
pub fn variance_of_mean(sum: f32, sum_sq: f32, n: u32) -> f32 {
    if n < 2 {
        return 0.0;
    }
    let n = n as f32;
    let mean = sum / n;
    (sum_sq / n - mean * mean).max(0.0) / (n - 1.0)
}

/// [`pixel`] compiled for the marcher's instruction set ([`Marcher::in_isa`]) where the
/// processor has it, else the baseline's: the same paths, bit for bit.
fn pixel_in(
    tracker: &Tracker,
    opt: &DvrOptions,
    cam: &Camera,
    lighting: &Lighting,
    px: u32,
) -> PixelPaths {
    let isa = tracker.m.isa();
    match isa {
        // SAFETY: the processor has every feature `pixel_v3` is compiled for.
        #[cfg(target_arch = "x86_64")]
        Isa::X86_64V3 if isa.available() => unsafe { pixel_v3(tracker, opt, cam, lighting, px) },
        _ => pixel(tracker, opt, cam, lighting, px),
    }
}

/// [`pixel`] compiled for x86-64-v3 (`raystream_accel::isa`), as `dvr::march_v3`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,movbe,f16c")]
fn pixel_v3(
    tracker: &Tracker,
    opt: &DvrOptions,
    cam: &Camera,
    lighting: &Lighting,
    px: u32,
) -> PixelPaths {
    pixel(tracker, opt, cam, lighting, px)
}

/// Pixel `pixel`'s `opt.spp` paths seen by `cam`, each through a random point of the pixel.
#[inline(always)]
pub(crate) fn pixel(
    tracker: &Tracker,
    opt: &DvrOptions,
    cam: &Camera,
    lighting: &Lighting,
    pixel: u32,
) -> PixelPaths {
    let (x, y) = (pixel % opt.width, pixel / opt.width);
    let (mut sum, mut escaped, mut taken) = (Vec3::ZERO, 0u32, 0u64);
    let mut sum_sq = 0.0f32;
    for s in 0..opt.spp {
        let mut rng = PathRng::new(pixel, s);
        let (u, v) = (rng.uniform(), rng.uniform());
        let r = cam.ray(x as f32 + u, y as f32 + v, opt.width, opt.height);
        let ray = (scene_to_lps(r.origin), scene_to_lps(r.dir));
        let p = path(tracker, opt, ray, lighting, &mut rng, &mut taken);
        sum += p.light;
        let l = luminance(p.light);
        sum_sq += l * l;
        escaped += p.escaped as u32;
    }
    let n = opt.spp.max(1) as f32;
    PixelPaths {
        light: sum / n,
        escaped: escaped as f32 / n,
        variance: variance_of_mean(luminance(sum), sum_sq, opt.spp),
        taken,
    }
}

/// A denoised frame: the premultiplied light, the opacity, and what denoising took.
pub(crate) type Denoised = (Image, Vec<f32>, DenoiseTimes);

/// A cinematic frame (`opt` as `dvr::march_frame` prepares it: the clip planes the camera's
/// view adds, no slab): every pixel's paths, each pixel's added to `done` as it finishes, and
/// with `opt.denoise` the frame denoised along its [`guides`] (the premultiplied light, the
/// opacity, and what the guides and the filter took). One majorant grid serves the paths and
/// the guides.
pub(crate) fn frame(
    m: &Marcher,
    tf: &TransferFunction,
    majorants: &Majorants,
    opt: &DvrOptions,
    cam: &Camera,
    done: Option<&AtomicU64>,
) -> (Vec<PixelPaths>, Option<Denoised>) {
    let lighting = Lighting::studio(opt, cam);
    let tracker = Tracker { m, tf, majorants };
    let paths: Vec<PixelPaths> = (0..opt.width * opt.height)
        .into_par_iter()
        .map(|px| {
            let p = pixel_in(&tracker, opt, cam, &lighting, px);
            if let Some(done) = done {
                done.fetch_add(opt.spp as u64, Ordering::Relaxed);
            }
            p
        })
        .collect();
    let denoised = opt.denoise.then(|| {
        let ms = |t: std::time::Instant| t.elapsed().as_secs_f64() * 1e3;
        let t = std::time::Instant::now();
        let g = guides_along(&tracker, opt, cam, opt.step_for(m.volume()));
        let guides_ms = ms(t);
        let t = std::time::Instant::now();
        let (film, alpha) = crate::denoise::denoise(
            &film_of(opt, &paths),
            &g,
            &crate::denoise::DenoiseOptions::default(),
        );
        let times = DenoiseTimes {
            guides_ms,
            filter_ms: ms(t),
        };
        (film, alpha, times)
    });
    (paths, denoised)
}

/// A cinematic frame as the denoiser takes it ([`crate::denoise`]): the premultiplied light,
/// the opacity 1 − (escaped fraction) and each pixel's variance of its luminance, and the
/// volume samples taken.
pub fn render_film(
    vol: &Volume,
    tf: &TransferFunction,
    opt: &DvrOptions,
    cam: &Camera,
) -> (NoisyFilm, u64) {
    let opt = &DvrOptions {
        denoise: false,
        ..frame_options(vol, opt, Sight::Camera(cam))
    };
    let m = Marcher::interpolated(vol, None, opt.interpolation);
    let (paths, _) = frame(&m, tf, &Majorants::new(&m, tf), opt, cam, None);
    (film_of(opt, &paths), paths.iter().map(|p| p.taken).sum())
}

/// A frame's pixels as the denoiser takes them.
pub(crate) fn film_of(opt: &DvrOptions, paths: &[PixelPaths]) -> NoisyFilm {
    NoisyFilm {
        film: Image {
            width: opt.width,
            height: opt.height,
            pixels: paths.iter().map(|p| p.light).collect(),
        },
        alpha: paths.iter().map(|p| 1.0 - p.escaped).collect(),
        variance: paths.iter().map(|p| p.variance).collect(),
    }
}

/// Below this share of the light stopped, a pixel's guides have no depth (+∞): what little it
/// shows lies at no distance worth comparing.
pub const GUIDE_MIN_COVERAGE: f32 = 0.02;

/// Guide rays a pixel, per side: the film's paths go through random points of the pixel, and
/// guides from its centre alone alias against it on fine detail. On the chest CT (ct-aaa,
/// 300×400, 16 paths a pixel against 1024) the denoised picture was 3.62/255 off with one ray,
/// 3.21 with 2×2 and 3.15 with 3×3 at 2.3× 2×2's time: BENCHMARKS.md "Denoising".
pub const GUIDE_SUBPIXELS: u32 = 2;

/// A guide ray stops once this little light gets through.
pub const GUIDE_TRANSMITTANCE_END: f32 = 0.01;

/// The denoiser's guides ([`crate::denoise::Guides`]) of a cinematic frame, noise-free: in
/// each pixel a grid of [`GUIDE_SUBPIXELS`]² rays marched in steps of `opt.step_for(vol)`
/// (cell by cell over the majorant grid, transparent cells crossed at once), composited front
/// to back as dvr mode composites colour: every step weighted by the light it stops, w =
/// T·(1 − e^(−σ·step)). Per pixel the mean over its rays of the weighted sums of the transfer
/// function's colour (its albedo, premultiplied by the coverage Σw) and of the gradient's
/// normal facing the eye scaled by the surface weight min(|∇HU| / 100 HU/mm, 1) the paths
/// scatter by, and the weighted mean distance from the eye (+∞ below a mean coverage of 2 %).
/// A first-surface guide would miss what semi-transparent tissue shows.
pub fn guides(vol: &Volume, tf: &TransferFunction, opt: &DvrOptions, cam: &Camera) -> Guides {
    guides_painted(vol, tf, opt, cam, None)
}

/// [`guides`] with the samples coloured by `segments` where given, as a painted frame's
/// ([`crate::dvr::CpuVolume::painted`]).
pub fn guides_painted(
    vol: &Volume,
    tf: &TransferFunction,
    opt: &DvrOptions,
    cam: &Camera,
    segments: Option<&crate::segments::SegmentColours>,
) -> Guides {
    let opt = &frame_options(vol, opt, Sight::Camera(cam));
    let m = Marcher::interpolated(vol, None, opt.interpolation).painted(segments);
    let majorants = Majorants::new(&m, tf);
    let tracker = Tracker {
        m: &m,
        tf,
        majorants: &majorants,
    };
    guides_along(&tracker, opt, cam, opt.step_for(vol))
}

/// [`guides`] through `tracker`'s volume and majorants (`opt` prepared as for a frame), in
/// steps of `step` mm.
fn guides_along(tracker: &Tracker, opt: &DvrOptions, cam: &Camera, step: f32) -> Guides {
    let Tracker { m, tf, majorants } = *tracker;
    let k = GUIDE_SUBPIXELS;
    let seen: Vec<(f32, Vec3, Vec3)> = (0..opt.width * opt.height)
        .into_par_iter()
        .with_min_len(64)
        .map(|px| {
            let (x, y) = (px % opt.width, px / opt.width);
            let mut sum = GuideSum::default();
            for j in 0..k {
                for i in 0..k {
                    let (u, v) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                    let r = cam.ray(x as f32 + u, y as f32 + v, opt.width, opt.height);
                    let (o, d) = (scene_to_lps(r.origin), scene_to_lps(r.dir));
                    guide_ray(m, majorants, tf, opt, step, (o, d), &mut sum);
                }
            }
            let n = (k * k) as f32;
            let depth = if sum.coverage >= GUIDE_MIN_COVERAGE * n {
                sum.depth / sum.coverage
            } else {
                f32::INFINITY
            };
            (depth, sum.normal / n, sum.albedo / n)
        })
        .collect();
    Guides {
        width: opt.width,
        height: opt.height,
        depth: seen.iter().map(|f| f.0).collect(),
        normal: seen.iter().map(|f| f.1).collect(),
        albedo: seen.iter().map(|f| f.2).collect(),
        tolerance: step,
    }
}

/// A guide ray's sums, weighted by the light each step stops.
#[derive(Default)]
struct GuideSum {
    albedo: Vec3,
    normal: Vec3,
    /// Σ w·t.
    depth: f32,
    /// Σ w.
    coverage: f32,
}

/// Marches the ray o + t·d through the medium and adds what it meets to `sum`.
fn guide_ray(
    m: &Marcher,
    majorants: &Majorants,
    tf: &TransferFunction,
    opt: &DvrOptions,
    step: f32,
    (o, d): (Vec3, Vec3),
    sum: &mut GuideSum,
) {
    let Some(((o_idx, d_idx, len), t0)) = inside(m, opt, o, d) else {
        return;
    };
    let mut transmit = 1.0f32;
    let mut t = 0.5 * step;
    while t < len && transmit > GUIDE_TRANSMITTANCE_END {
        let (c, exit) = majorants.exit(o_idx + d_idx * t, t, d_idx);
        if majorants.values[c] <= 0.0 {
            // On to the first lattice point past the cell.
            t = (t + step).max(t + ((exit - t) / step).ceil() * step);
            continue;
        }
        let p = o_idx + d_idx * t;
        let hu = m.sample(p);
        let sigma = sigma_of(tf.opacity_at(hu));
        if sigma > 0.0 {
            let w = transmit * -(-sigma * step).exp_m1();
            let g = m.gradient(p);
            let gm = g.length();
            if gm > 0.0 {
                let n = -g / gm;
                let facing = if n.dot(d) > 0.0 { -n } else { n };
                sum.normal += facing * ((gm / FULL_SHADING_GRADIENT).min(1.0) * w);
            }
            sum.albedo += m.albedo(Vec3::from(tf.color_at(hu)), p) * w;
            sum.depth += (t0 + t) * w;
            sum.coverage += w;
            transmit -= w;
        }
        t += step;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn volume(dims: [usize; 3], spacing: [f64; 3], f: impl Fn(f32, f32, f32) -> f32) -> Volume {
        let mut data = Vec::with_capacity(dims.iter().product());
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    data.push(f(i as f32, j as f32, k as f32));
                }
            }
        }
        Volume::hounsfield(dims, spacing, data)
    }

    /// A transfer function of one colour and matte surfaces (no glossy lobe).
    fn tf(opacity: Vec<(f32, f32)>, albedo: f32) -> TransferFunction {
        TransferFunction {
            opacity,
            color: vec![(0.0, [albedo; 3])],
            shading: raystream_volume::Shading {
                specular: 0.0,
                ..Default::default()
            },
        }
    }

    fn tracker<'a>(
        m: &'a Marcher<'a>,
        tf: &'a TransferFunction,
        majorants: &'a Majorants,
    ) -> Tracker<'a> {
        Tracker { m, tf, majorants }
    }

    /// Mean and standard error of `n` draws of `draw(s)`.
    fn mean_and_error(n: u32, draw: impl Fn(u32) -> f64) -> (f64, f64) {
        let (mut sum, mut sq) = (0.0, 0.0);
        for s in 0..n {
            let x = draw(s);
            sum += x;
            sq += x * x;
        }
        let mean = sum / n as f64;
        let var = (sq / n as f64 - mean * mean).max(0.0);
        (mean, (var / n as f64).sqrt())
    }

    /// Through a medium whose HU climbs from air (transparent bricks) to bone along x, on an
    /// anisotropic grid, thin and four times denser (where shadow rays play roulette): the
    /// fraction of delta-tracking flights that pass, and the mean ratio-tracking estimate, are
    /// exp(−∫σ) from a 200,000-step f64 quadrature of the same samples (within 4 standard
    /// errors: a shadow ray's roulette that doubled its survivors 1.9 times would be 4.7 off);
    /// and every cell's majorant bounds σ there.
    #[test]
    fn tracking_gives_the_transmittance_of_a_heterogeneous_medium() {
        let vol = volume([60, 10, 12], [0.7, 1.0, 1.3], |i, j, k| {
            -1000.0 + 2500.0 * i / 59.0 + 20.0 * j - 15.0 * k
        });
        for density in [1.0, 4.0] {
            let tf = tf(
                vec![
                    (-200.0, 0.0),
                    (400.0, 0.02 * density),
                    (1500.0, 0.08 * density),
                ],
                1.0,
            );
            transmittances_agree(&vol, &tf);
        }
    }

    fn transmittances_agree(vol: &Volume, tf: &TransferFunction) {
        let m = Marcher::new(vol, Some(tf));
        let majorants = Majorants::new(&m, tf);
        let tracker = tracker(&m, tf, &majorants);
        assert!(
            majorants.values.contains(&0.0),
            "some cells are transparent"
        );
        let opt = DvrOptions::default();
        let rays = [
            (Vec3::new(-5.0, 4.5, 6.3), Vec3::X),
            (
                Vec3::new(-3.0, -1.0, 2.0),
                Vec3::new(1.0, 0.25, 0.3).normalize(),
            ),
        ];
        for (o, d) in rays {
            let (ray @ (o_idx, d_idx, len), _) = inside(&m, &opt, o, d).expect("the ray meets it");
            let n = 200_000;
            let h = len as f64 / n as f64;
            let mut tau = 0.0f64;
            for i in 0..n {
                let t = ((i as f64 + 0.5) * h) as f32;
                let p = o_idx + d_idx * t;
                let sigma = sigma_of(tf.opacity_at(m.sample(p)));
                let (c, _) = majorants.exit(p, t, d_idx);
                assert!(
                    sigma <= majorants.values[c] * (1.0 + 1e-6),
                    "σ {sigma} above its cell's majorant"
                );
                tau += sigma as f64 * h;
            }
            let want = (-tau).exp();
            assert!(
                (0.005..0.9).contains(&want),
                "a telling transmittance: {want}"
            );
            let runs = 400_000;
            let flights = mean_and_error(runs, |s| {
                let mut rng = PathRng::new(7, s);
                tracker.free_flight(ray, &mut rng, &mut 0).is_none() as u32 as f64
            });
            let binomial = (want * (1.0 - want) / runs as f64).sqrt();
            assert!(
                (flights.0 - want).abs() < 4.0 * binomial,
                "delta tracking passes {:.4}, exp(-τ) = {want:.4}",
                flights.0
            );
            let ratio = mean_and_error(runs, |s| {
                let mut rng = PathRng::new(11, s);
                tracker.transmittance_estimate(ray, &mut rng, &mut 0) as f64
            });
            assert!(
                (ratio.0 - want).abs() < 4.0 * ratio.1,
                "ratio tracking {:.4} ± {:.4}, exp(-τ) = {want:.4}",
                ratio.0,
                ratio.1
            );
            assert!(ratio.1 < binomial, "ratio tracking is the quieter estimate");
        }
    }

    /// The white furnace: a non-absorbing (white) haze holding a denser ball, under a white sky
    /// and no key light, isotropic and Henyey–Greenstein (g 0.7 and −0.5). Every path that
    /// leaves after scattering carries exactly the sky's radiance back (surface bounces at the
    /// ball's rim and volume scatterings alike keep their weight), every camera ray that meets nothing shows the background, and almost no path
    /// runs out of bounces.
    #[test]
    fn a_white_medium_under_a_white_sky_sends_back_all_the_light() {
        let vol = volume([32, 32, 32], [1.0; 3], |i, j, k| {
            let r = Vec3::new(i, j, k).distance(Vec3::splat(15.5));
            if r < 8.0 { 400.0 } else { 0.0 }
        });
        let tf = tf(vec![(-100.0, 0.02), (400.0, 0.3)], 1.0);
        let m = Marcher::new(&vol, Some(&tf));
        let majorants = Majorants::new(&m, &tf);
        let tracker = tracker(&m, &tf, &majorants);
        let lighting = Lighting {
            key: Vec3::Z,
            key_irradiance: 0.0,
            sky: 1.0,
        };
        // The ball's rim scatters as a surface (full gradient weight).
        let rim = m.gradient(Vec3::new(15.5 + 8.0, 15.5, 15.5)).length();
        assert!(rim >= FULL_SHADING_GRADIENT, "rim gradient {rim}");
        // Isotropic, and forward- and back-scattering Henyey–Greenstein media.
        for anisotropy in [0.0, 0.7, -0.5] {
            let opt = DvrOptions {
                bounces: 512,
                anisotropy,
                ..Default::default()
            };
            let (mut scattered, mut escaped, mut truncated) = (0, 0, 0);
            for s in 0..20_000u32 {
                let mut rng = PathRng::new(3, s);
                // Rays from the −y side toward random points of the volume's face.
                let o = Vec3::new(31.0 * rng.uniform(), -20.0, 31.0 * rng.uniform());
                let d =
                    (Vec3::new(31.0 * rng.uniform(), 31.0, 31.0 * rng.uniform()) - o).normalize();
                let p = path(&tracker, &opt, (o, d), &lighting, &mut rng, &mut 0);
                match (p.escaped, p.light) {
                    (true, l) if l == Vec3::ZERO => escaped += 1,
                    (false, l) if l == Vec3::ONE => scattered += 1,
                    (false, l) if l == Vec3::ZERO => truncated += 1,
                    other => panic!("g {anisotropy}: path {s} brought back {other:?}"),
                }
            }
            assert!(
                scattered > 5_000 && escaped > 300,
                "g {anisotropy}: {scattered} {escaped}"
            );
            assert!(
                truncated * 1000 < scattered,
                "g {anisotropy}: {truncated} paths ran out of bounces"
            );
        }
    }

    /// Single scattering in a homogeneous grey medium lit by the key light alone: the mean of
    /// 200,000 paths equals ∫ σe^{−σt} · a·p(θ) · E · e^{−σ s(t)} dt (s: the way out toward the
    /// light, p the phase function at the angle between the ray and the light: 1/4π, and
    /// Henyey–Greenstein's for g 0.6 and −0.4 in f64), by f64 quadrature, within 5 standard
    /// errors.
    #[test]
    fn single_scattering_matches_its_integral() {
        for anisotropy in [0.0f32, 0.6, -0.4] {
            single_scattering(anisotropy);
        }
    }

    fn single_scattering(anisotropy: f32) {
        let vol = volume([40, 30, 50], [1.0, 1.2, 0.8], |_, _, _| 100.0);
        let (alpha, albedo, irradiance) = (0.04f32, 0.8f32, 2.0f32);
        let tf = tf(vec![(0.0, alpha)], albedo);
        let m = Marcher::new(&vol, Some(&tf));
        let majorants = Majorants::new(&m, &tf);
        let tracker = tracker(&m, &tf, &majorants);
        let opt = DvrOptions {
            bounces: 0,
            anisotropy,
            ..Default::default()
        };
        let key = Vec3::new(0.3, -0.5, 0.8).normalize();
        // The phase function between the ray (along +x) and the light, in f64.
        let (g, cos) = (anisotropy as f64, key.x as f64);
        let phase =
            (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5));
        let lighting = Lighting {
            key,
            key_irradiance: irradiance,
            sky: 0.0,
        };
        let hi = [39.0, 29.0 * 1.2, 49.0 * 0.8];
        let (o, y, z) = (-10.0, 17.4, 19.6);
        let sigma = -(1.0 - alpha as f64).ln();
        let out_toward_key = |x: f64| {
            let p = [x, y, z];
            (0..3)
                .map(|a| {
                    let k = key[a] as f64;
                    if k > 0.0 {
                        (hi[a] - p[a]) / k
                    } else {
                        -p[a] / k
                    }
                })
                .fold(f64::INFINITY, f64::min)
        };
        let n = 100_000;
        let h = hi[0] / n as f64;
        let want: f64 = (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * h;
                sigma
                    * (-sigma * t).exp()
                    * (albedo as f64 * phase)
                    * irradiance as f64
                    * (-sigma * out_toward_key(t)).exp()
                    * h
            })
            .sum();
        let ray = (Vec3::new(o as f32, y as f32, z as f32), Vec3::X);
        let (got, err) = mean_and_error(200_000, |s| {
            let mut rng = PathRng::new(5, s);
            let p = path(&tracker, &opt, ray, &lighting, &mut rng, &mut 0);
            assert!(!p.escaped || p.light == Vec3::ZERO);
            p.light.x as f64
        });
        assert!(
            (got - want).abs() < 5.0 * err,
            "g {anisotropy}: single scattering {got:.5} ± {err:.5}, integral {want:.5}"
        );
    }

    /// Cosine-weighted directions about any normal (the poles included) lie in its hemisphere
    /// with E[cos θ] = 2/3 and E[cos² θ] = 1/2 and no tangential drift; uniform ones have
    /// E[d] = 0 and E[z²] = 1/3; all unit length.
    #[test]
    fn directions_follow_their_densities() {
        let n = 100_000;
        let normals = [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.8, 0.52).normalize(),
            Vec3::new(1e-7, 0.0, -1.0).normalize(),
        ];
        for normal in normals {
            let mut rng = PathRng::new(9, 0);
            let (mut c1, mut c2, mut mean) = (0.0f64, 0.0f64, Vec3::ZERO);
            for _ in 0..n {
                let d = cosine_hemisphere(normal, &mut rng);
                assert!((d.length() - 1.0).abs() < 1e-5);
                let c = d.dot(normal);
                assert!(c >= -1e-6, "{d} below {normal}");
                c1 += c as f64;
                c2 += (c * c) as f64;
                mean += d - normal * c;
            }
            let (c1, c2) = (c1 / n as f64, c2 / n as f64);
            // sd(cos θ) = √(1/2 − 4/9) ≈ 0.236; sd(cos² θ) = √(1/3 − 1/4) ≈ 0.289.
            assert!(
                (c1 - 2.0 / 3.0).abs() < 4.0 * 0.236 / (n as f64).sqrt(),
                "{normal}: E[cos] {c1}"
            );
            assert!(
                (c2 - 0.5).abs() < 4.0 * 0.289 / (n as f64).sqrt(),
                "{normal}: E[cos²] {c2}"
            );
            assert!((mean / n as f32).length() < 0.01, "{normal}: drift {mean}");
        }
        let mut rng = PathRng::new(9, 1);
        let (mut mean, mut z2) = (Vec3::ZERO, 0.0f64);
        for _ in 0..n {
            let d = uniform_sphere(&mut rng);
            assert!((d.length() - 1.0).abs() < 1e-5);
            mean += d;
            z2 += (d.z * d.z) as f64;
        }
        assert!((mean / n as f32).length() < 0.01, "drift {mean}");
        assert!((z2 / n as f64 - 1.0 / 3.0).abs() < 0.005);
    }

    /// The glossy lobe's sampled weights average to its directional albedo ∫ f cos θᵢ dωᵢ by
    /// f64 quadrature (within 4 standard errors), for views from the normal to 75° and
    /// exponents 1 to 50: what the key light's samples evaluate and what the bounces draw are
    /// one lobe.
    #[test]
    fn glossy_directions_follow_their_lobe() {
        let n = Vec3::new(0.2, -0.3, 0.93).normalize();
        let (t, bt) = basis(n);
        let dir = |theta: f64, phi: f64| {
            (n * theta.cos() as f32
                + (t * phi.cos() as f32 + bt * phi.sin() as f32) * theta.sin() as f32)
                .normalize()
        };
        for p in [1.0f32, 10.0, 50.0] {
            for view in [0.0f64, 45.0, 75.0] {
                let wo = dir(view.to_radians(), 0.3);
                let (nt, np) = (1000, 360);
                let (dt, dp) = (
                    std::f64::consts::FRAC_PI_2 / nt as f64,
                    std::f64::consts::TAU / np as f64,
                );
                let mut albedo = 0.0f64;
                for i in 0..nt {
                    let th = (i as f64 + 0.5) * dt;
                    for j in 0..np {
                        let wi = dir(th, (j as f64 + 0.5) * dp);
                        albedo += blinn(n, wo, wi, p) as f64 * th.cos() * th.sin() * dt * dp;
                    }
                }
                let (mean, err) = mean_and_error(200_000, |s| {
                    let mut rng = PathRng::new(13, s);
                    let (wi, w) = glossy_sample(n, wo, p, &mut rng);
                    assert!(w == 0.0 || wi.dot(n) > 0.0);
                    w as f64
                });
                assert!(
                    (mean - albedo).abs() < 4.0 * err + 1e-3,
                    "p {p}, view {view}°: sampled {mean:.4} ± {err:.4}, quadrature {albedo:.4}"
                );
            }
        }
    }

    /// The same pixel every run, and the picture is the mean of its paths.
    #[test]
    fn pictures_are_deterministic() {
        let vol = volume([16, 16, 16], [1.0; 3], |i, _, _| 100.0 * i);
        let tf = tf(vec![(0.0, 0.0), (1500.0, 0.2)], 0.9);
        let m = Marcher::new(&vol, Some(&tf));
        let majorants = Majorants::new(&m, &tf);
        let tracker = tracker(&m, &tf, &majorants);
        let opt = DvrOptions {
            width: 8,
            height: 8,
            spp: 16,
            ..Default::default()
        };
        let cam = crate::dvr::volume_camera(&vol, 1.0);
        let lighting = Lighting::studio(&opt, &cam);
        for px in [0, 27, 63] {
            let a = pixel(&tracker, &opt, &cam, &lighting, px);
            assert_eq!(a, pixel(&tracker, &opt, &cam, &lighting, px));
        }
    }

    /// The guides against a fine quadrature: along each of a pixel's guide rays through a
    /// fuzzy ball on an anisotropic grid, the light stopped (1 − e^(−∫σ), integrated in steps
    /// of a sixteenth of the guides' step in f64, as far as the guides march: until 1 % gets
    /// through); its mean over the rays is the coverage the guide's albedo carries (its colour
    /// 0.7 times the coverage, within 0.01), and the mean depth of all the stopped light matches
    /// the guide's within one step. Rays that stop under 2 % have no depth. A normal is no longer than
    /// the coverage (a weighted sum of unit normals times weights up to 1).
    /// Normals face the eye, and where the ray meets the ball squarely (covered over 90 %, the
    /// radius within 60° of the ray) lie along its radius within 20°.
    #[test]
    fn guides_composite_what_the_rays_meet() {
        let spacing = [0.8, 1.0, 1.5];
        let centre = Vec3::new(12.0 * 0.8, 12.0, 9.0 * 1.5);
        let vol = volume([24, 24, 18], spacing, |i, j, k| {
            let p = Vec3::new(i * 0.8, j, k * 1.5);
            let r = (p - centre).length();
            1000.0 / (1.0 + ((r - 8.5) / 0.6).exp())
        });
        let tf = tf(vec![(0.0, 0.0), (1000.0, 0.3)], 0.7);
        let opt = DvrOptions {
            width: 48,
            height: 36,
            mode: crate::dvr::DvrMode::Cinematic,
            ..Default::default()
        };
        let cam = crate::dvr::volume_camera(&vol, 48.0 / 36.0);
        let g = guides(&vol, &tf, &opt, &cam);
        let m = Marcher::new(&vol, None);
        let step = opt.step_for(&vol);
        let origin = Vec3::from_array(vol.origin.map(|v| v as f32));
        let (mut hits, mut misses, mut square) = (0, 0, 0);
        for px in 0..opt.width * opt.height {
            let (x, y) = (px % opt.width, px / opt.width);
            let fine = step as f64 / 16.0;
            let (mut coverage, mut depth) = (0.0f64, 0.0f64);
            // The pixel's grid of rays, each integrated finely.
            let k = GUIDE_SUBPIXELS;
            let ray = |i: u32, j: u32| {
                let (u, v) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                let r = cam.ray(x as f32 + u, y as f32 + v, opt.width, opt.height);
                (scene_to_lps(r.origin), scene_to_lps(r.dir))
            };
            for (i, j) in (0..k).flat_map(|j| (0..k).map(move |i| (i, j))) {
                let (o, d) = ray(i, j);
                let Some(((o_idx, d_idx, len), t0)) = inside(&m, &opt, o, d) else {
                    continue;
                };
                let mut tau = 0.0f64;
                let mut t = 0.5 * fine;
                while t < len as f64 && tau < -(0.01f64.ln()) {
                    let sigma = sigma_of(tf.opacity_at(m.sample(o_idx + d_idx * t as f32)));
                    let before = tau;
                    tau += sigma as f64 * fine;
                    let stopped = (-before).exp() - (-tau).exp();
                    coverage += stopped;
                    depth += stopped * (t0 as f64 + t);
                    t += fine;
                }
            }
            let depth = depth / coverage;
            let coverage = coverage / (k * k) as f64;
            // The pixel's centre ray.
            let r = cam.ray(x as f32 + 0.5, y as f32 + 0.5, opt.width, opt.height);
            let (o, d) = (scene_to_lps(r.origin), scene_to_lps(r.dir));
            let px = px as usize;
            let (albedo, n, z) = (g.albedo[px], g.normal[px], g.depth[px]);
            assert!(
                (albedo.x as f64 - 0.7 * coverage).abs() < 0.01,
                "pixel {px}: albedo {albedo}, coverage {coverage:.4}"
            );
            assert!(
                n.length() as f64 <= coverage + 1e-3,
                "pixel {px}: normal {n}"
            );
            if (coverage - 0.02).abs() < 0.005 {
                continue;
            }
            if coverage < 0.02 {
                misses += 1;
                assert!(!z.is_finite(), "pixel {px}: depth {z}");
                continue;
            }
            hits += 1;
            let want = depth;
            assert!(
                (z as f64 - want).abs() < step as f64,
                "pixel {px}: guide depth {z}, quadrature {want:.3} (step {step})"
            );
            assert!(n.dot(d) <= 0.0, "pixel {px}: normal {n} faces away");
            let out = (o + d * z - origin - centre).normalize();
            if coverage > 0.9 && out.dot(d) < -0.5 {
                square += 1;
                assert!(
                    n.normalize().dot(out) > 20f32.to_radians().cos(),
                    "pixel {px}: normal {n}, out of the ball {out}"
                );
            }
        }
        assert!(
            hits > 200 && misses > 200 && square > 50,
            "{hits} hits, {misses} misses, {square} square"
        );
    }

    /// A pixel's variance is its paths' sample variance over their count: against the spread
    /// of pixels rendered from other paths (independent seeds), on a foggy cube, the mean
    /// variance reported and the mean squared difference between two renders (twice the
    /// variance) agree within 15 %.
    #[test]
    fn pixel_variance_is_the_spread_of_the_mean() {
        let vol = volume([16, 16, 16], [1.0; 3], |i, j, _| 30.0 * (i + j));
        let tf = tf(vec![(0.0, 0.0), (900.0, 0.15)], 0.8);
        let m = Marcher::new(&vol, None);
        let majorants = Majorants::new(&m, &tf);
        let tracker = tracker(&m, &tf, &majorants);
        let opt = DvrOptions {
            width: 16,
            height: 16,
            spp: 16,
            bounces: 2,
            mode: crate::dvr::DvrMode::Cinematic,
            ..Default::default()
        };
        let cam = crate::dvr::volume_camera(&vol, 1.0);
        let lighting = Lighting::studio(&opt, &cam);
        // Pixel p's paths, and the same pixel's paths seeded as pixel p + 65536 would be: the
        // same distribution, other random numbers (the camera ray through the same pixel).
        let (mut reported, mut spread, mut n) = (0.0f64, 0.0f64, 0);
        for px in 0..256u32 {
            let a = pixel(&tracker, &opt, &cam, &lighting, px);
            let mut sum = Vec3::ZERO;
            let (x, y) = (px % 16, px / 16);
            for s in 0..opt.spp {
                let mut rng = PathRng::new(px + 65536, s);
                let (u, v) = (rng.uniform(), rng.uniform());
                let r = cam.ray(x as f32 + u, y as f32 + v, 16, 16);
                let ray = (scene_to_lps(r.origin), scene_to_lps(r.dir));
                sum += path(&tracker, &opt, ray, &lighting, &mut rng, &mut 0).light;
            }
            let b = luminance(sum / opt.spp as f32);
            reported += a.variance as f64;
            spread += ((luminance(a.light) - b) as f64).powi(2);
            n += 1;
        }
        let (reported, spread) = (reported / n as f64, spread / n as f64 / 2.0);
        assert!(
            reported > 0.0 && (reported / spread - 1.0).abs() < 0.15,
            "reported variance {reported:.3e}, measured {spread:.3e}"
        );
    }

    /// A progress bar's count: rendering a cinematic frame adds each of its paths once to the
    /// counter; the other modes add nothing.
    #[test]
    fn frames_count_their_paths() {
        use std::sync::atomic::{AtomicU64, Ordering};
        let vol = volume([12, 12, 12], [1.0; 3], |i, _, _| 100.0 * i);
        let tf = tf(vec![(0.0, 0.0), (1100.0, 0.2)], 0.8);
        let cam = crate::dvr::volume_camera(&vol, 1.5);
        for (mode, spp, want) in [
            (crate::dvr::DvrMode::Cinematic, 5, 12 * 8 * 5),
            (crate::dvr::DvrMode::Dvr, 5, 0),
        ] {
            let opt = DvrOptions {
                width: 12,
                height: 8,
                mode,
                spp,
                ..Default::default()
            };
            let done = AtomicU64::new(7);
            crate::dvr::CpuVolume::new(&vol, &tf).render_rgba_counted(&opt, &cam, &done);
            assert_eq!(done.load(Ordering::Relaxed), 7 + want, "{mode:?}");
        }
    }

    /// NaN voxels (a float file's missing values) among dense ones, every third along x,
    /// fifth along y and seventh along z: every path of a frame ends, read either way, and
    /// every pixel is finite. A collision whose gradient read a NaN voxel took its normal of
    /// NaN for a surface's and sent the path on along a direction of NaN, tracked without end;
    /// a frame that has not ended in two minutes fails the test rather than hanging it.
    #[test]
    fn nan_voxels_end_every_path() {
        use crate::dvr::Interpolation;
        for interpolation in [Interpolation::Linear, Interpolation::Cubic] {
            let (sent, got) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let vol = volume([16, 16, 16], [1.0; 3], |i, j, k| {
                    let (i, j, k) = (i as usize, j as usize, k as usize);
                    if i % 3 == 0 && j % 5 == 0 && k % 7 == 0 {
                        f32::NAN
                    } else {
                        200.0 + 60.0 * i as f32
                    }
                });
                let tf = tf(vec![(0.0, 0.0), (1100.0, 0.3)], 0.8);
                let cam = crate::dvr::volume_camera(&vol, 1.5);
                let opt = DvrOptions {
                    width: 16,
                    height: 16,
                    mode: crate::dvr::DvrMode::Cinematic,
                    spp: 8,
                    interpolation,
                    ..Default::default()
                };
                let (film, alpha, _) = crate::dvr::CpuVolume::new(&vol, &tf).render_rgba_counted(
                    &opt,
                    &cam,
                    &AtomicU64::new(0),
                );
                let _ = sent.send((film, alpha));
            });
            let (film, alpha) = got
                .recv_timeout(std::time::Duration::from_secs(120))
                .unwrap_or_else(|_| panic!("{interpolation:?}: the frame did not end"));
            assert!(
                film.pixels.iter().all(|p| p.is_finite()) && alpha.iter().all(|a| a.is_finite()),
                "{interpolation:?}: a pixel is not finite"
            );
            let lit = film.pixels.iter().filter(|p| p.max_element() > 0.0).count();
            assert!(lit > 100, "{interpolation:?}: {lit} pixels lit");
        }
    }

    /// Henyey–Greenstein directions have the phase function's first two Legendre moments,
    /// E[cos θ] = g and E[cos² θ] = (1 + 2g²)/3, about any travel direction (within 4 standard
    /// errors of 200,000 draws), stay unit length, and the function integrates to 1 over the
    /// sphere (f64 quadrature of the f32 function). |g| below 10⁻³ draws exactly what the
    /// isotropic sampler draws.
    #[test]
    fn phase_directions_follow_henyey_greenstein() {
        let d = Vec3::new(-0.4, 0.7, 0.2).normalize();
        for g in [-0.6f32, 0.3, 0.8, 0.95] {
            let n = 200_000;
            let (m1, e1) = mean_and_error(n, |s| {
                let w = phase_sample(g, d, &mut PathRng::new(17, s));
                assert!((w.length() - 1.0).abs() < 1e-4);
                d.dot(w) as f64
            });
            let (m2, e2) = mean_and_error(n, |s| {
                (d.dot(phase_sample(g, d, &mut PathRng::new(17, s))) as f64).powi(2)
            });
            let g = g as f64;
            assert!((m1 - g).abs() < 4.0 * e1, "g {g}: E[cos] {m1} ± {e1}");
            let want = (1.0 + 2.0 * g * g) / 3.0;
            assert!((m2 - want).abs() < 4.0 * e2, "g {g}: E[cos²] {m2} ± {e2}");
            let k = 20_000;
            let total: f64 = (0..k)
                .map(|i| {
                    let cos = -1.0 + (i as f64 + 0.5) * 2.0 / k as f64;
                    henyey_greenstein(g as f32, cos as f32) as f64
                        * std::f64::consts::TAU
                        * (2.0 / k as f64)
                })
                .sum();
            assert!((total - 1.0).abs() < 1e-3, "g {g}: ∫p dω = {total}");
        }
        for s in 0..100 {
            let (mut a, mut b) = (PathRng::new(1, s), PathRng::new(1, s));
            assert_eq!(phase_sample(5e-4, d, &mut a), uniform_sphere(&mut b));
        }
    }

    /// Exposure scales the lights: a pixel at +1 EV is exactly twice the pixel at 0 (the same
    /// paths; light is linear in its sources and doubling is exact in f32), its variance four
    /// times; −2 EV a quarter.
    #[test]
    fn exposure_scales_the_light() {
        let vol = volume([16, 16, 16], [1.0; 3], |i, j, _| 40.0 * (i + j));
        let tf = tf(vec![(0.0, 0.0), (1200.0, 0.2)], 0.8);
        let m = Marcher::new(&vol, None);
        let majorants = Majorants::new(&m, &tf);
        let tracker = tracker(&m, &tf, &majorants);
        let cam = crate::dvr::volume_camera(&vol, 1.0);
        let at = |exposure: f32, px: u32| {
            let opt = DvrOptions {
                width: 8,
                height: 8,
                spp: 8,
                exposure,
                mode: crate::dvr::DvrMode::Cinematic,
                ..Default::default()
            };
            pixel(&tracker, &opt, &cam, &Lighting::studio(&opt, &cam), px)
        };
        let mut lit = 0;
        for px in 0..64 {
            let (base, up, down) = (at(0.0, px), at(1.0, px), at(-2.0, px));
            assert_eq!(up.light, base.light * 2.0, "pixel {px}");
            assert_eq!(down.light, base.light * 0.25, "pixel {px}");
            assert_eq!(up.variance, base.variance * 4.0, "pixel {px}");
            assert_eq!((up.escaped, up.taken), (base.escaped, base.taken));
            lit += (base.light.max_element() > 0.0) as u32;
        }
        assert!(lit > 16, "{lit} pixels lit");
    }
}
