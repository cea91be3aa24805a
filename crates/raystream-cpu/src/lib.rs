//! The CPU renderer: the stream stages of the research design, run as explicit queues depth by
//! depth (no recursion), each stage a data-parallel pass over work items on rayon:
//!
//! `generate_camera_rays` → for each depth: `intersect_closest` → (`march_volume` in scenes
//! with a volume, see [`medium`]) → `handle_misses` → `shade_hits` (local Phong term, shadow
//! work items, reflection/refraction rays for the next depth) → `intersect_any` on the shadow
//! queue → `accumulate`.
//!
//! Compositing follows the paper, C(n) = Σ_j M_j (Π_{i<j} r_i)(1 − r_j): every work item
//! carries the product of the coefficients along its path as `weight`; a hit adds its local
//! colour M_j times `weight · (1 − r_j − τ_j)` and passes `weight · r_j` to its reflection ray
//! and `weight · τ_j` to its refraction ray (with Fresnel, τ is split into reflected τF and
//! transmitted τ(1 − F)). With no transparency this is exactly the paper's sum.
//!
//! The result is deterministic: queues keep their order and `accumulate` adds in queue order.
//! Frames run in waves of whole pixels ([`WAVE_SAMPLES`]), each through all its depths; a
//! pixel's contributions are added in the same order whatever the waves, so the image does not
//! depend on them.
//!
//! # Example
//!
//! The built-in scene (Spot the cow between a glass and a mirror sphere on a reflective
//! floor), its kd-tree, and a small frame traced to four reflections and refractions deep:
//!
//! ```
//! use raystream_accel::{Builder, KdTree};
//! use raystream_cpu::{DepthStats, RenderOptions, render};
//! use raystream_scene::Scene;
//!
//! let scene = Scene::builtin_default();
//! let tree = KdTree::build(&scene.mesh, Builder::Sah);
//! let opt = RenderOptions { width: 64, height: 48, spp: 2, max_depth: 4, ..Default::default() };
//! let mut depths: Vec<DepthStats> = Vec::new();
//! let image = render(&scene, &tree, &opt, |d| depths.push(d));
//! assert_eq!(image.pixels.len(), 64 * 48);
//! // The host ran the queues depth by depth: every pixel sample at depth 0, then the rays
//! // the glass and the mirrors sent on.
//! assert_eq!(depths[0].rays, 64 * 48 * 2);
//! assert!(depths.iter().any(|d| d.depth > 0 && d.rays > 0));
//! // Deterministic: the same frame, bit for bit, on every run and any number of threads.
//! let again = render(&scene, &tree, &opt, |_| {});
//! assert!(image.pixels.iter().zip(&again.pixels).all(|(a, b)| a.to_array() == b.to_array()));
//! // As a viewer shows it: 8-bit sRGB, 3 bytes a pixel (`image.save_png(path)` writes it).
//! assert_eq!(image.to_srgb8().len(), 64 * 48 * 3);
//! ```

pub mod airway;
pub mod animation;
mod aov;
pub mod cinematic;
pub mod cpr;
pub mod denoise;
pub mod dvr;
mod image_out;
pub mod lumen;
pub mod mask;
pub mod medium;
mod passes;
pub mod pipeline;
pub mod sampling;
pub use raystream_volume::segments;
pub mod stenosis;
pub mod wall;

use rayon::prelude::*;
use raystream_accel::{Hit, KdTree, Traversal};
use raystream_math::{Ray, Vec3};
use raystream_scene::{Camera, Scene};

use passes::add_to_film;

pub use aov::{
    AOV_CHUNK, Aov, AovBuilder, AovImage, AovValues, NO_PRIM, aov_image, aov_rays, aov_rays_of,
    prim_colour,
};
pub use image_out::{
    ExrFile, ExrSamples, Image, ImageFormat, load_exr, save_exr, save_srgb8_png, srgb_to_linear,
    srgb8_diff,
};
pub use medium::Medium;

#[derive(Clone, Copy, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    /// Samples per pixel (stratified jitter; 1 = the pixel centre).
    pub spp: u32,
    /// Deepest reflection/refraction level; 0 = primary rays only.
    pub max_depth: u32,
    pub traversal: Traversal,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width: 800,
            height: 600,
            spp: 4,
            max_depth: 4,
            traversal: Traversal::Ropes,
        }
    }
}

/// A ray waiting to be traced: the pixel it adds to and the weight of its path.
#[derive(Clone, Copy, Debug)]
pub struct RayWorkItem {
    pub ray: Ray,
    pub pixel: u32,
    pub weight: Vec3,
}

/// A ray with its closest hit.
#[derive(Clone, Copy, Debug)]
pub struct HitWorkItem {
    pub item: RayWorkItem,
    pub hit: Hit,
}

/// A shadow ray toward a light, with the light's contribution if nothing blocks it.
#[derive(Clone, Copy, Debug)]
pub struct ShadowWorkItem {
    pub ray: Ray,
    pub pixel: u32,
    pub radiance: Vec3,
}

/// What one depth did, for progress reports and statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DepthStats {
    pub depth: u32,
    pub rays: usize,
    pub hits: usize,
    pub shadow_rays: usize,
    /// Volume samples taken by this depth's rays (scenes with a volume).
    pub volume_samples: u64,
}

/// Renders `scene` with the kd-tree built over `scene.mesh`; `progress` is told after each depth.
/// A scene's volume is prepared here ([`prepare_volume`]) and marched by every ray.
pub fn render(
    scene: &Scene,
    tree: &KdTree,
    opt: &RenderOptions,
    progress: impl FnMut(DepthStats),
) -> Image {
    let medium = prepare_volume(scene, tree, opt.traversal);
    render_prepared(scene, tree, medium.as_ref(), opt, progress)
}

/// A scene's volume prepared for its rays (brick table and light grids: they depend on the
/// scene, not on the camera, so frames of one scene share them); `None` without a volume.
pub fn prepare_volume<'a>(
    scene: &'a Scene,
    tree: &KdTree,
    traversal: Traversal,
) -> Option<Medium<'a>> {
    scene
        .volume
        .as_ref()
        .map(|v| Medium::new(v, scene, tree, traversal))
}

/// At most this many samples are traced at once: the frame is rendered in waves of whole
/// pixels, so that memory stays bounded at any size and sample count (a 1080p frame at 256 spp
/// would otherwise queue 531 M rays, 25 GB, at once). A pixel's sums run in the same order
/// whatever the wave, so the image is the same byte for byte. 2¹⁸: with the queues kept
/// ([`RenderQueues`]) larger waves were no faster (2²⁰: the same frame time at three times
/// the memory, BENCHMARKS.md, 2026-12-05), and every wave still has work for many cores.
pub const WAVE_SAMPLES: u32 = 1 << 18;

/// Pixels in one wave of `opt`'s frame.
pub fn wave_pixels(opt: &RenderOptions) -> u32 {
    pixels_a_wave(WAVE_SAMPLES, opt)
}

/// Waves the CPU renders `opt`'s frame in (each reports every depth it runs to the progress).
pub fn waves(opt: &RenderOptions) -> u32 {
    waves_of(wave_pixels(opt), opt)
}

/// Pixels in a wave of at most `samples` samples of `opt`'s frame (one at least).
fn pixels_a_wave(samples: u32, opt: &RenderOptions) -> u32 {
    (samples / opt.spp.max(1)).max(1)
}

/// Waves of `wave_pixels` pixels that `opt`'s frame takes.
fn waves_of(wave_pixels: u32, opt: &RenderOptions) -> u32 {
    (opt.width * opt.height).div_ceil(wave_pixels)
}

/// [`render`] with the scene's volume already prepared (`medium`, from [`prepare_volume`]).
pub fn render_prepared(
    scene: &Scene,
    tree: &KdTree,
    medium: Option<&Medium>,
    opt: &RenderOptions,
    progress: impl FnMut(DepthStats),
) -> Image {
    render_prepared_in(
        scene,
        tree,
        medium,
        opt,
        &mut RenderQueues::default(),
        progress,
    )
}

/// [`render_prepared`] through `queues`: frames rendered one after another (a turntable,
/// `--repeat`) keep them, and with them the memory their queues have touched.
pub fn render_prepared_in(
    scene: &Scene,
    tree: &KdTree,
    medium: Option<&Medium>,
    opt: &RenderOptions,
    queues: &mut RenderQueues,
    progress: impl FnMut(DepthStats),
) -> Image {
    let wave = queues.wave_pixels(opt);
    render_in_waves(scene, tree, medium, opt, wave, queues, progress)
}

/// [`render_prepared_in`] in waves of `wave_pixels` pixels (the same image for any wave size).
pub fn render_in_waves(
    scene: &Scene,
    tree: &KdTree,
    medium: Option<&Medium>,
    opt: &RenderOptions,
    wave_pixels: u32,
    queues: &mut RenderQueues,
    mut progress: impl FnMut(DepthStats),
) -> Image {
    let cam = scene.camera_for(opt.width as f32 / opt.height as f32);
    let mut film = vec![Vec3::ZERO; (opt.width * opt.height) as usize];
    let pixels = opt.width * opt.height;
    let wave_pixels = wave_pixels.max(1);
    for first in (0..pixels).step_by(wave_pixels as usize) {
        let wave = first..(first + wave_pixels).min(pixels);
        camera_rays_into(&cam, opt.width, opt.height, opt.spp, wave, &mut queues.rays);
        trace_wave(scene, tree, medium, opt, queues, &mut film, &mut progress);
    }
    let scale = 1.0 / opt.spp as f32;
    Image {
        width: opt.width,
        height: opt.height,
        pixels: film.into_par_iter().map(|c| c * scale).collect(),
    }
}

/// The renderer's queues and its stages' scratch, kept across the depths and waves of a frame
/// (and by [`render_prepared_in`] across frames): each stage clears and refills them, so that
/// their memory is touched once instead of allocated afresh at every depth. (glibc hands
/// blocks that large back to the kernel when they are freed, and the kernel faulted in and
/// zeroed every page of the next ones again: BENCHMARKS.md, 2026-12-05.)
#[derive(Default)]
pub struct RenderQueues {
    /// Samples a wave holds at most; 0: [`WAVE_SAMPLES`].
    wave_samples: u32,
    /// This depth's rays, then (swapped with `shaded.next` after each depth) the next
    /// depth's.
    rays: Vec<RayWorkItem>,
    hits: Vec<HitWorkItem>,
    misses: Vec<RayWorkItem>,
    /// The shading stage's queues (its `next` swapped with `rays` after each depth), and its
    /// runs of hits.
    shaded: Shaded,
    runs: Vec<Shaded>,
    scratch: QueryScratch,
}

impl RenderQueues {
    /// Queues for frames in waves of at most `samples` samples (whole pixels, one at least)
    /// instead of [`WAVE_SAMPLES`]: an experiment (the CLI's `RAYSTREAM_CPU_WAVE`), for the
    /// wave that suits a machine's cores. The image is the same for any wave.
    pub fn with_wave(samples: u32) -> Self {
        Self {
            wave_samples: samples,
            ..Self::default()
        }
    }

    /// Pixels in one wave of `opt`'s frame through these queues.
    pub fn wave_pixels(&self, opt: &RenderOptions) -> u32 {
        match self.wave_samples {
            0 => wave_pixels(opt),
            n => pixels_a_wave(n, opt),
        }
    }

    /// Waves `opt`'s frame takes through these queues.
    pub fn waves(&self, opt: &RenderOptions) -> u32 {
        waves_of(self.wave_pixels(opt), opt)
    }
}

/// What the query stages use on their way: the query, and what each shadow ray brings.
#[derive(Default)]
struct QueryScratch {
    query: Query,
    reaching: Vec<Option<Vec3>>,
}

/// A query's rays (as the kd-tree takes them) and their answers.
#[derive(Default)]
struct Query {
    rays: Vec<Ray>,
    found: Vec<Option<Hit>>,
}

impl Query {
    /// The closest (or, with `any`, some) hit of each ray of `rays`, in their order.
    fn run(
        &mut self,
        tree: &KdTree,
        rays: impl IndexedParallelIterator<Item = Ray>,
        traversal: Traversal,
        any: bool,
    ) -> &[Option<Hit>] {
        rays.collect_into_vec(&mut self.rays);
        tree.intersect_all_into(&self.rays, traversal, any, &mut self.found);
        &self.found
    }
}

/// One wave's camera rays (`q.rays`) through every depth, into `film`.
fn trace_wave(
    scene: &Scene,
    tree: &KdTree,
    medium: Option<&Medium>,
    opt: &RenderOptions,
    q: &mut RenderQueues,
    film: &mut [Vec3],
    progress: &mut impl FnMut(DepthStats),
) {
    for depth in 0..=opt.max_depth {
        if q.rays.is_empty() {
            break;
        }
        closest_into(
            tree,
            &q.rays,
            opt.traversal,
            &mut q.scratch.query,
            &mut q.hits,
            &mut q.misses,
        );
        let volume_samples = match medium {
            Some(m) => march_volume(m, &mut q.hits, &mut q.misses, film),
            None => 0,
        };
        // This frame's queues are in pixel order: the film's adds skip their order check.
        add_misses(&q.misses, scene.background, film, true);
        let spawn = depth < opt.max_depth;
        shade_hits_into(scene, &q.hits, spawn, &mut q.runs, &mut q.shaded);
        let shadows = &q.shaded.shadows;
        let reaching = shadows_reaching(tree, shadows, opt.traversal, medium, &mut q.scratch);
        add_contributions(film, &q.shaded.local, true);
        add_to_film(
            film,
            shadows.len(),
            true,
            |i| shadows[i].pixel,
            |i| reaching[i],
        );
        progress(DepthStats {
            depth,
            rays: q.rays.len(),
            hits: q.hits.len(),
            shadow_rays: shadows.len(),
            volume_samples,
        });
        std::mem::swap(&mut q.rays, &mut q.shaded.next);
    }
}

/// Strata per side of the sample grid for `spp` samples: ⌈√spp⌉.
pub fn strata(spp: u32) -> u32 {
    (spp as f32).sqrt().ceil() as u32
}

/// A deterministic hash → [0, 1): the jitter of sample `s` of pixel `p`.
fn jitter(p: u32, s: u32, k: u32) -> f32 {
    let mut x =
        p.wrapping_mul(0x9E37_79B9) ^ s.wrapping_mul(0x85EB_CA6B) ^ k.wrapping_mul(0xC2B2_AE35);
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^= x >> 16;
    (x >> 8) as f32 / (1u32 << 24) as f32
}

/// Stage 1: one ray per pixel sample, pixel-major. Sample `s` of `spp` lies in stratum `s` of an
/// `n×n` grid (n = ⌈√spp⌉), jittered; with one sample it is the pixel centre.
pub fn generate_camera_rays(cam: &Camera, width: u32, height: u32, spp: u32) -> Vec<RayWorkItem> {
    camera_rays_of(cam, width, height, spp, 0..width * height)
}

/// [`generate_camera_rays`] of the pixels `pixels` only (a wave).
fn camera_rays_of(
    cam: &Camera,
    width: u32,
    height: u32,
    spp: u32,
    pixels: std::ops::Range<u32>,
) -> Vec<RayWorkItem> {
    let mut rays = Vec::new();
    camera_rays_into(cam, width, height, spp, pixels, &mut rays);
    rays
}

/// [`camera_rays_of`] into `out` (cleared first; its memory kept), each sample written in
/// place by its index: pixel-major, `spp` samples a pixel.
fn camera_rays_into(
    cam: &Camera,
    width: u32,
    height: u32,
    spp: u32,
    pixels: std::ops::Range<u32>,
    out: &mut Vec<RayWorkItem>,
) {
    let n = strata(spp);
    let weight = Vec3::ONE;
    let count = pixels.len() * spp as usize;
    (0..count)
        .into_par_iter()
        .map(|i| {
            let pixel = pixels.start + (i / spp as usize) as u32;
            let s = (i % spp as usize) as u32;
            let (x, y) = ((pixel % width) as f32, (pixel / width) as f32);
            let (jx, jy) = if spp == 1 {
                (0.5, 0.5)
            } else {
                (
                    ((s % n) as f32 + jitter(pixel, s, 0)) / n as f32,
                    ((s / n) as f32 + jitter(pixel, s, 1)) / n as f32,
                )
            };
            RayWorkItem {
                ray: cam.ray(x + jx, y + jy, width, height),
                pixel,
                weight,
            }
        })
        .collect_into_vec(out);
}

/// Stage 2: closest hits; the queue is split into hits and misses (order kept).
pub fn intersect_closest(
    tree: &KdTree,
    queue: &[RayWorkItem],
    traversal: Traversal,
) -> (Vec<HitWorkItem>, Vec<RayWorkItem>) {
    let (mut hits, mut misses) = (Vec::new(), Vec::new());
    let query = &mut Query::default();
    closest_into(tree, queue, traversal, query, &mut hits, &mut misses);
    (hits, misses)
}

/// [`intersect_closest`] into `hits` and `misses` (cleared first), through `query`.
fn closest_into(
    tree: &KdTree,
    queue: &[RayWorkItem],
    traversal: Traversal,
    query: &mut Query,
    hits: &mut Vec<HitWorkItem>,
    misses: &mut Vec<RayWorkItem>,
) {
    let rays = queue.par_iter().map(|w| w.ray);
    let found = query.run(tree, rays, traversal, false);
    let pick = |i: usize| match found[i] {
        Some(hit) => Ok(HitWorkItem {
            item: queue[i],
            hit,
        }),
        None => Err(queue[i]),
    };
    raystream_accel::par::split_into(queue.len(), pick, hits, misses);
}

/// Stage 2½, in scenes with a volume: each ray's segment up to its hit (or out of the scene)
/// adds the volume's emission, weighted by the ray's path, to its pixel, and the segment's
/// transmittance scales the weight that its hit or the background gets. Every segment of a
/// pixel starts its sample lattice at the pixel's offset, as `--mode dvr` does (and the GPU).
/// Returns the samples taken.
pub fn march_volume(
    medium: &Medium,
    hits: &mut [HitWorkItem],
    misses: &mut [RayWorkItem],
    film: &mut [Vec3],
) -> u64 {
    let lights = medium.sample_lights();
    let through = |item: &mut RayWorkItem, t_end: f32| {
        let seg = medium.segment(&item.ray, t_end, dvr::start_jitter(item.pixel), &lights);
        let emitted = (item.pixel, item.weight * seg.color);
        item.weight *= seg.transmit;
        (emitted, seg.taken)
    };
    let mut emitted: Vec<(Contribution, u64)> = hits
        .par_iter_mut()
        .with_min_len(64)
        .map(|h| through(&mut h.item, h.hit.t))
        .collect();
    emitted.par_extend(
        misses
            .par_iter_mut()
            .with_min_len(64)
            .map(|m| through(m, m.ray.t_max)),
    );
    let samples = emitted.par_iter().map(|e| e.1).sum();
    // The hits' and then the misses' (the renderer's are each in pixel order, the two
    // together not; a caller's may be in any: checked).
    let (from_hits, from_misses) = emitted.split_at(hits.len());
    for part in [from_hits, from_misses] {
        add_to_film(
            film,
            part.len(),
            false,
            |i| part[i].0.0,
            |i| Some(part[i].0.1),
        );
    }
    samples
}

/// Stage 3: rays that leave the scene add the background.
pub fn handle_misses(misses: &[RayWorkItem], background: Vec3, film: &mut [Vec3]) {
    add_misses(misses, background, film, false);
}

/// [`handle_misses`], the misses' order checked unless `in_order` vouches for it.
fn add_misses(misses: &[RayWorkItem], background: Vec3, film: &mut [Vec3], in_order: bool) {
    let colour = |i: usize| Some(misses[i].weight * background);
    add_to_film(film, misses.len(), in_order, |i| misses[i].pixel, colour);
}

/// Schlick's approximation of the Fresnel reflectance for a ray from index `n1` into `n2`.
fn schlick(cos_i: f32, n1: f32, n2: f32) -> f32 {
    let r0 = ((n1 - n2) / (n1 + n2)).powi(2);
    r0 + (1.0 - r0) * (1.0 - cos_i).powi(5)
}

fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Refraction of unit `d` through unit `n` (facing against `d`) with `eta = n1/n2`; `None` on
/// total internal reflection.
fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -d.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    (k >= 0.0).then(|| eta * d + (eta * cos_i - k.sqrt()) * n)
}

/// The surface at a hit, seen from the ray's side.
struct Surface {
    /// The hit point, on the triangle's plane.
    p: Vec3,
    /// How far secondary rays start off the surface (the object's ray offset).
    offset: f32,
    /// Geometric normal, facing the ray.
    ng: Vec3,
    /// Interpolated shading normal, facing the ray.
    ns: Vec3,
    /// Whether the ray arrived on the outside (against the triangle's winding normal).
    outside: bool,
    dir: Vec3,
}

fn surface(scene: &Scene, h: &HitWorkItem) -> Surface {
    let prim = h.hit.prim as usize;
    let [a, b, c] = scene.mesh.corners(prim);
    let [ia, ib, ic] = scene.mesh.triangles[prim];
    let dir = h.item.ray.dir.normalize();
    let mut ng = (b - a).cross(c - a).normalize();
    let (u, v) = (h.hit.u, h.hit.v);
    let n = &scene.normals;
    let mut ns = (n[ia as usize] * (1.0 - u - v) + n[ib as usize] * u + n[ic as usize] * v)
        .normalize_or_zero();
    if ns == Vec3::ZERO {
        ns = ng;
    }
    let outside = ng.dot(dir) < 0.0;
    if !outside {
        ng = -ng;
        ns = -ns;
    }
    if ns.dot(dir) >= 0.0 {
        ns = ng;
    }
    Surface {
        p: on_plane(h.item.ray.at(h.hit.t), a, ng),
        offset: scene.ray_offsets[ia as usize],
        ng,
        ns,
        outside,
        dir,
    }
}

/// `p` moved along the unit normal `n` onto the plane through `a`. A hit point computed as
/// origin + t·direction is only good to the rounding of the ray's origin and length, which a
/// far camera makes larger than a small object's ray offset; its distance to the triangle's
/// own plane is good to the rounding of the triangle's coordinates, which the offset covers.
fn on_plane(p: Vec3, a: Vec3, n: Vec3) -> Vec3 {
    p - n * (p - a).dot(n)
}

/// The split of a hit's light: local (1 − r − τ), reflected, transmitted.
fn coefficients(m: &raystream_scene::Material, s: &Surface) -> (f32, f32, f32, Option<Vec3>) {
    let local = 1.0 - m.reflectivity - m.transparency;
    if m.transparency <= 0.0 {
        return (local, m.reflectivity, 0.0, None);
    }
    let (n1, n2) = if s.outside {
        (1.0, m.ior)
    } else {
        (m.ior, 1.0)
    };
    match refract(s.dir, s.ns, n1 / n2) {
        None => (local, m.reflectivity + m.transparency, 0.0, None),
        Some(t) => {
            let f = if m.fresnel {
                schlick(-s.dir.dot(s.ns), n1, n2)
            } else {
                0.0
            };
            (
                local,
                m.reflectivity + m.transparency * f,
                m.transparency * (1.0 - f),
                Some(t),
            )
        }
    }
}

type Contribution = (u32, Vec3);

/// Stage 4: local Phong terms (ambient now, diffuse and specular behind shadow rays), and the
/// next depth's reflection and refraction rays when `spawn`.
pub fn shade_hits(
    scene: &Scene,
    hits: &[HitWorkItem],
    spawn: bool,
) -> (Vec<Contribution>, Vec<ShadowWorkItem>, Vec<RayWorkItem>) {
    let mut all = Shaded::default();
    shade_hits_into(scene, hits, spawn, &mut Vec::new(), &mut all);
    (all.local, all.shadows, all.next)
}

/// Hits a run of [`shade_hits_into`] shades.
const SHADE_RUN: usize = 4096;

/// [`shade_hits`] into `out`'s three queues, cleared first, through `runs` (its runs'
/// queues, kept with their memory for the next call).
fn shade_hits_into(
    scene: &Scene,
    hits: &[HitWorkItem],
    spawn: bool,
    runs: &mut Vec<Shaded>,
    out: &mut Shaded,
) {
    // One pass: each hit's surface is found once, and its outputs go to the three queues of
    // its run of hits; the runs are joined in order, so the queues come out in hit order.
    // Runs are only added: a later depth's fewer hits leave the others' memory for the next
    // wave.
    let count = hits.len().div_ceil(SHADE_RUN);
    if runs.len() < count {
        runs.resize_with(count, Shaded::default);
    }
    let runs = &mut runs[..count];
    runs.par_iter_mut()
        .zip(hits.par_chunks(SHADE_RUN))
        .for_each(|(run, hits)| {
            run.clear();
            for h in hits {
                shade_hit(scene, h, spawn, run);
            }
        });
    let runs = &*runs;
    raystream_accel::par::concat_into(&mut out.local, runs.len(), |r| &runs[r].local);
    raystream_accel::par::concat_into(&mut out.shadows, runs.len(), |r| &runs[r].shadows);
    raystream_accel::par::concat_into(&mut out.next, runs.len(), |r| &runs[r].next);
}

/// What [`shade_hits`] makes of a run of hits: their local terms, shadow rays and next rays.
#[derive(Default)]
struct Shaded {
    local: Vec<Contribution>,
    shadows: Vec<ShadowWorkItem>,
    next: Vec<RayWorkItem>,
}

impl Shaded {
    fn clear(&mut self) {
        self.local.clear();
        self.shadows.clear();
        self.next.clear();
    }
}

/// An 8-bit sRGB colour in linear light, by the table the GPU's shading reads too.
fn linear_colour(c: raystream_io::Rgb8) -> Vec3 {
    let lut = &*raystream_io::SRGB_TO_LINEAR;
    Vec3::new(lut[c[0] as usize], lut[c[1] as usize], lut[c[2] as usize])
}

/// One hit: its ambient term, a shadow ray toward each light that can reach it, and (with
/// `spawn`) its reflection and refraction rays.
fn shade_hit(scene: &Scene, h: &HitWorkItem, spawn: bool, out: &mut Shaded) {
    let s = surface(scene, h);
    let m = &scene.materials[scene.material_of[h.hit.prim as usize] as usize];
    let (k, r, t, refr) = coefficients(m, &s);
    let pixel = h.item.pixel;
    // A texture tints the ambient and diffuse colours (MTL: `map_Kd` multiplies `Kd`), as do
    // the file's vertex colours.
    let (u, v) = (h.hit.u, h.hit.v);
    let mut tint = match m.texture {
        Some(i) => {
            let [a, b, c] = scene.uvs[h.hit.prim as usize];
            scene.textures[i as usize].sample(a * (1.0 - u - v) + b * u + c * v)
        }
        None => Vec3::ONE,
    };
    if let Some(corners) = scene.colours.get(h.hit.prim as usize) {
        let [a, b, c] = corners.map(linear_colour);
        tint *= a * (1.0 - u - v) + b * u + c * v;
    }
    let (ambient, diffuse) = (m.ambient * tint, m.diffuse * tint);
    out.local
        .push((pixel, h.item.weight * k * ambient * scene.ambient_light));
    let origin = s.p + s.ng * s.offset;
    let w = h.item.weight * k;
    for light in &scene.lights {
        let to_light = light.position - origin;
        let l = to_light.normalize();
        let cos = s.ns.dot(l);
        if cos <= 0.0 || s.ng.dot(to_light) <= 0.0 || k <= 0.0 {
            continue;
        }
        let spec = reflect(-l, s.ns).dot(-s.dir).max(0.0).powf(m.shininess);
        out.shadows.push(ShadowWorkItem {
            ray: Ray::new(origin, to_light, 0.0, 1.0 - 1e-4),
            pixel,
            radiance: w * (diffuse * cos + m.specular * spec) * light.color,
        });
    }
    if !spawn {
        return;
    }
    let w = h.item.weight;
    if r * w.max_element() > 1e-3 {
        let mut d = reflect(s.dir, s.ns);
        if d.dot(s.ng) <= 0.0 {
            d = reflect(s.dir, s.ng);
        }
        out.next.push(RayWorkItem {
            ray: Ray::new(s.p + s.ng * s.offset, d, 0.0, f32::INFINITY),
            pixel,
            weight: w * r,
        });
    }
    if let Some(d) = refr.filter(|_| t * w.max_element() > 1e-3) {
        out.next.push(RayWorkItem {
            ray: Ray::new(s.p - s.ng * s.offset, d, 0.0, f32::INFINITY),
            pixel,
            weight: w * t,
        });
    }
}

/// Stage 5: shadow rays; those that reach their light keep their contribution, times the
/// transmittance of the scene's volume (`medium`) along them.
pub fn intersect_any(
    tree: &KdTree,
    shadows: &[ShadowWorkItem],
    traversal: Traversal,
    medium: Option<&Medium>,
) -> Vec<Contribution> {
    let mut scratch = QueryScratch::default();
    let reaching = shadows_reaching(tree, shadows, traversal, medium, &mut scratch);
    shadows
        .iter()
        .zip(reaching)
        .filter_map(|(s, r)| Some((s.pixel, (*r)?)))
        .collect()
}

/// What each shadow ray of `shadows` brings its pixel, in their order: its radiance times the
/// volume's transmittance along it where nothing blocks it, else `None`.
fn shadows_reaching<'a>(
    tree: &KdTree,
    shadows: &[ShadowWorkItem],
    traversal: Traversal,
    medium: Option<&Medium>,
    scratch: &'a mut QueryScratch,
) -> &'a [Option<Vec3>] {
    let rays = shadows.par_iter().map(|s| s.ray);
    let blocked = scratch.query.run(tree, rays, traversal, true);
    shadows
        .par_iter()
        .zip(blocked)
        .with_min_len(256)
        .map(|(s, blocked)| {
            if blocked.is_some() {
                return None;
            }
            Some(match medium {
                Some(m) => s.radiance * m.transmittance(&s.ray, dvr::start_jitter(s.pixel)),
                None => s.radiance,
            })
        })
        .collect_into_vec(&mut scratch.reaching);
    &scratch.reaching
}

/// Stage 6: adds contributions to the film in queue order (deterministic).
pub fn accumulate(film: &mut [Vec3], contributions: &[Contribution]) {
    add_contributions(film, contributions, false);
}

/// [`accumulate`], the contributions' order checked unless `in_order` vouches for it.
fn add_contributions(film: &mut [Vec3], c: &[Contribution], in_order: bool) {
    add_to_film(film, c.len(), in_order, |i| c[i].0, |i| Some(c[i].1));
}

#[cfg(test)]
mod tests;
