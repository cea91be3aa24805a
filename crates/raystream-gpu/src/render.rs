//! The GPU stream renderer: the CPU renderer's stages (`raystream-cpu`) as the compute kernels
//! of `kernels/render.wgsl`, joined by ray queues that stay on the device.
//!
//! The host is the paper's "CPU control". It splits the frame into waves of (by default)
//! [`DEFAULT_WAVE`] samples; for each wave it generates the camera rays, then records depth after
//! depth, swapping the two ray queues, each depth's kernels dispatched indirectly from counts
//! the kernels wrote themselves ([`Submit`]):
//! - [`Submit::Wave`] (where no hit can spawn two rays): all of a wave's depths go in one
//!   submission, and the next wave is queued before the host reads the last one's counters
//!   (copied aside after each depth), so the GPU never waits for the host inside a frame. A
//!   queue that empties makes the later depths dispatch no workgroups. No queue can outgrow
//!   the wave, so all are sized for it up front.
//! - [`Submit::Depth`]: one submission per depth; the host reads the counters back after each,
//!   stops when the queue is empty and sizes the next depth's queues exactly (a depth's queue
//!   is at most twice the previous one: one reflection and one refraction per hit), so nothing
//!   can overflow; where a queue would outgrow a buffer binding, the frame starts again in
//!   waves half as large.
//!
//! The film is 64-bit fixed point added with atomics: the same image every run, either way;
//! `kernels/film.wgsl` resolves it on the GPU before the readback.

use std::time::Instant;

use raystream_accel::{KdTree, Traversal};
use raystream_cpu::medium::Medium;
use raystream_cpu::{DepthStats, Image, RenderOptions, strata};
use raystream_math::Vec3;
use raystream_scene::{Camera, Light, Scene};

use crate::layout::{
    GpuLight, GpuMaterial, MediumParams, NO_TEXTURE, RayWork, RenderParams, ShadeTri, ShadowWork,
    TEXTURE_INFO, TEXTURE_INFO_WORDS, TriCorners, Vertex, band_rows, counter,
};
use crate::volume::{GpuVolume, volume_core_wgsl};
use crate::{
    GpuContext, GpuError, GpuHit, GpuTracer, Pixels, Timer, WORKGROUP_SIZE, kdtree_wgsl, read_back,
    read_back_after, read_words, u64_at,
};

const RENDER_WGSL: &str = include_str!("kernels/render.wgsl");
const MEDIUM_WGSL: &str = include_str!("kernels/medium.wgsl");
const FILM_WGSL: &str = include_str!("kernels/film.wgsl");

/// The WGSL source of the film-resolving kernel.
pub fn film_wgsl() -> String {
    format!("const WORKGROUP_SIZE: u32 = {WORKGROUP_SIZE}u;\n\n{COMMON_WGSL}\n{FILM_WGSL}")
}
pub(crate) const COMMON_WGSL: &str = include_str!("kernels/common.wgsl");

/// Samples generated and traced together by default: a 1920x1080 frame at 4 spp in one wave.
/// It bounds the queues' memory (272 bytes a sample with two lights: 2.3 GB at this size; a
/// device out of memory for them renders again in waves half as large). On the H200
/// (BENCHMARKS.md, 2026-12-04) the default scene at that size ran 52.7 frames/s in one wave
/// against 49.4 in two, 42.5 in four and 32.1 in eight (2^20): a dispatch's last workgroups
/// leave the GPU idle, and fewer, larger dispatches pay that less often. (An H100 run of
/// 2026-11, before the wave was one submission, had found 2^22 slower than 2^20.)
pub const DEFAULT_WAVE: u32 = 1 << 23;
/// The most samples a wave may be set to ([`crate::GpuContext::set_render_wave`]).
pub const MAX_WAVE: u32 = 1 << 23;
/// Fixed-point steps per unit of radiance in the film.
pub const FILM_SCALE: f32 = (1u32 << 24) as f32;
/// The largest single contribution the film takes (keeps one rounded step inside a u32).
pub const MAX_CONTRIBUTION: f32 = 255.0;

/// The WGSL source of the render kernels: the kd-tree code, the render constants, the kernels,
/// and the volume stages (the volume core and `kernels/medium.wgsl`). `subgroup_appends`:
/// `shade_hits` reserves queue slots a subgroup at a time (the device needs wgpu's SUBGROUP
/// feature; [`crate::GpuContext::set_subgroup_appends`]).
pub fn render_wgsl(subgroup_appends: bool) -> String {
    use counter::*;
    let append = crate::append_wgsl(subgroup_appends, "counters");
    format!(
        "{}\nconst FILM_SCALE: f32 = {FILM_SCALE:?};\nconst MAX_CONTRIBUTION: f32 = {MAX_CONTRIBUTION:?};\nconst COUNTER_SLOTS: u32 = {SLOTS}u;\nconst QUEUE: u32 = {QUEUE}u;\nconst NEXT: u32 = {NEXT}u;\nconst SHADOWS: u32 = {SHADOWS}u;\nconst HITS: u32 = {HITS}u;\nconst STAT_RAYS: u32 = {STAT_RAYS}u;\nconst STAT_HITS: u32 = {STAT_HITS}u;\nconst STAT_SHADOWS: u32 = {STAT_SHADOWS}u;\nconst DEPTH: u32 = {DEPTH}u;\nconst NO_TEXTURE: u32 = {NO_TEXTURE}u;\nconst TEXTURE_INFO: u32 = {TEXTURE_INFO}u;\nconst TEXTURE_INFO_WORDS: u32 = {TEXTURE_INFO_WORDS}u;\n\n{COMMON_WGSL}\n{RENDER_WGSL}\n{append}\n{}\n{MEDIUM_WGSL}",
        kdtree_wgsl(),
        volume_core_wgsl()
    )
}

/// The kernels: a wave's first depth runs `generate_camera_rays` and then what every depth
/// runs, in this order; `march_volume` and `attenuate_shadows` only in scenes with a volume.
pub const STAGES: [&str; 10] = [
    "generate_camera_rays",
    "intersect_closest",
    "march_volume",
    "handle_misses",
    "shade_hits",
    "prepare_shadows",
    "intersect_any",
    "attenuate_shadows",
    "accumulate",
    "advance",
];
const GENERATE: usize = 0;
const VOLUME_STAGES: [usize; 2] = [2, 7];
/// Byte offsets of the two dispatch argument triples in the args buffer.
const QUEUE_ARGS: u64 = 0;
const SHADOW_ARGS: u64 = 12;

/// How the host (the paper's "CPU control") submits a wave's depths.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Submit {
    /// One submission per depth. After each the host reads the counters back, stops at an
    /// empty queue and sizes the next depth's queues from the count: needed where a hit can
    /// spawn two rays (a transparent material), since the queue may then double every depth.
    #[default]
    Depth,
    /// One submission per wave holding all of its depths, and the next wave submitted before
    /// the host reads this one's counters, so that the GPU never waits for the host inside a
    /// frame (a round trip's wait costs the GPU idle time: BENCHMARKS.md).
    /// A queue that empties makes the later depths dispatch no workgroups, and each depth's
    /// counters are copied aside for the statistics. Only where no hit spawns two rays: no
    /// queue then outgrows the wave, and every queue is sized for it up front.
    Wave,
}

/// The buffers sized by the wave (their `work_buffer` names): the ray queue, and the queues
/// that [`Submit::Depth`] grows depth by depth. A smaller wave needs less of each.
const WAVE_SIZED: [&str; 4] = ["ray queue", "next ray queue", "shadow queue", "hits"];

/// The deepest frame run as [`Submit::Wave`] (max depth + 1): beyond it a wave's passes
/// outgrow one timestamp query set, and queues empty long before.
pub const MAX_WAVE_DEPTHS: u32 = 64;

/// What a GPU render did and how long its parts took.
#[derive(Clone, Debug, Default)]
pub struct GpuRenderStats {
    /// Per depth, summed over the waves.
    pub depths: Vec<DepthStats>,
    pub waves: u32,
    /// How the depths were submitted, and how many submissions the frame's rays took.
    pub submit: Submit,
    pub submissions: u32,
    /// Wall time of the frame (generation to film readback), milliseconds.
    pub render_ms: f64,
    /// Of `render_ms`: submitting the depths and waiting for them to finish (the GPU's work and
    /// the round trips; some drivers, lavapipe's, run the work inside the submission), and
    /// reading the film back and converting it.
    pub wait_ms: f64,
    pub film_ms: f64,
    /// Each kernel's own time summed over its passes, from timestamp queries; `None` where the
    /// adapter has none or writes equal stamps.
    pub kernel_gpu_ms: Option<Vec<(&'static str, f64)>>,
}

/// The scene's shading data on the GPU and the render pipelines, over a [`GpuTracer`]'s tree.
pub struct GpuRenderer<'a> {
    tracer: &'a GpuTracer<'a>,
    scene: &'a Scene,
    vertices: wgpu::Buffer,
    shade_tris: wgpu::Buffer,
    materials: wgpu::Buffer,
    lights: wgpu::Buffer,
    /// Per triangle its texture coordinates, and the texture table (layout::TEXTURE_INFO).
    tri_corners: wgpu::Buffer,
    /// Whether `tri_corners` holds the scene's colours.
    coloured: bool,
    textures: wgpu::Buffer,
    params: wgpu::Buffer,
    layouts: [wgpu::BindGroupLayout; 4],
    /// Per stage of [`STAGES`]; the volume stages only for scenes with a volume.
    pipelines: Vec<Option<wgpu::ComputePipeline>>,
    /// The scene's volume and its bind group (group 3 of the volume stages).
    medium: Option<(GpuVolume, wgpu::BindGroup)>,
    film_layout: wgpu::BindGroupLayout,
    film_pipeline: wgpu::ComputePipeline,
    /// The film straight to 8-bit sRGB, for [`GpuRenderer::render_srgb8`].
    srgb8_pipeline: wgpu::ComputePipeline,
    /// Samples per wave: [`DEFAULT_WAVE`] or as the context sets, less where the device's
    /// bindings need it.
    wave: u32,
    /// The submission asked for ([`Submit::Wave`] unless told), and whether a hit can spawn
    /// two rays (some material both reflects and refracts), which rules it out.
    submit: Submit,
    branches: bool,
    /// The last frame's work buffers and their (pixels, wave, lights), kept for the next frame:
    /// allocating them per frame cost most of a 1920x1080 frame on an H100.
    frame: std::sync::Mutex<Option<(FrameShape, Queues)>>,
    /// The camera of the next frames where [`GpuRenderer::set_view`] set one (a turntable's);
    /// else the scene's.
    camera: std::sync::Mutex<Option<Camera>>,
}

fn v3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

/// A light as the shading kernels read it.
fn gpu_light(l: &Light) -> GpuLight {
    GpuLight {
        position: l.position.extend(1.0).to_array(),
        color: l.color.extend(0.0).to_array(),
    }
}

/// What a frame's work buffers were made for: pixels, samples per wave, lights, and the
/// counter sets and timed passes one readback holds (one depth's, or a whole wave's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct FrameShape {
    pixels: u64,
    wave: u64,
    lights: u64,
    counter_sets: u64,
    passes: u64,
}

/// The bind groups of a frame's passes: `work[cur]` traces ray queue `cur`.
struct Groups {
    tree: wgpu::BindGroup,
    scene: wgpu::BindGroup,
    args: wgpu::BindGroup,
    work: [wgpu::BindGroup; 2],
}

/// The work buffers of one frame; queues grow as the depths need.
struct Queues {
    counters: wgpu::Buffer,
    args: wgpu::Buffer,
    /// The two ray queues: `rays[cur]` is traced, `rays[1 - cur]` receives the next depth.
    rays: [wgpu::Buffer; 2],
    hits: wgpu::Buffer,
    shadows: wgpu::Buffer,
    film: wgpu::Buffer,
    /// The film resolved to f32 per channel (`film.wgsl`), and its mappable copy.
    image: wgpu::Buffer,
    image_read: wgpu::Buffer,
    /// The film as 8-bit sRGB (3 bytes a pixel, in words), and its mappable copy.
    packed: wgpu::Buffer,
    packed_read: wgpu::Buffer,
    /// Counters (a set per depth of a wave, or one), then 2 timestamps per pass; two, so that
    /// the host reads one wave's while the GPU writes the next one's.
    readback: [wgpu::Buffer; 2],
    resolve: Option<Timer>,
}

impl Queues {
    /// Resolves the timestamps of the first `passes` passes into readback `slot` at `offset`.
    fn copy_stamps(&self, enc: &mut wgpu::CommandEncoder, passes: u32, slot: usize, offset: u64) {
        if let Some(t) = &self.resolve {
            enc.resolve_query_set(&t.set, 0..2 * passes, &t.resolve, 0);
            let bytes = passes as u64 * 16;
            enc.copy_buffer_to_buffer(&t.resolve, 0, &self.readback[slot], offset, bytes);
        }
    }
}

/// Each stage's kernel time summed over a frame, and whether the stamps are real (some
/// adapters write equal ones).
struct Tally {
    stage_ms: [f64; STAGES.len()],
    timed: bool,
}

impl Tally {
    /// Adds the timestamps `words` (two u64 a pass, as u32 pairs) of the passes `order`
    /// (indices into [`STAGES`]).
    fn stamps(&mut self, words: &[u32], order: &[usize], ctx: &GpuContext) {
        if !self.timed {
            return;
        }
        let period = ctx.queue.get_timestamp_period() as f64 * 1e-6;
        let mut any = false;
        for (j, &k) in order.iter().enumerate() {
            let ticks = u64_at(words, 2 * j + 1).wrapping_sub(u64_at(words, 2 * j));
            any |= ticks > 0;
            self.stage_ms[k] += ticks as f64 * period;
        }
        self.timed = any;
    }

    /// A finished depth's statistics from its counters `words`, added to `stats` and told to
    /// `progress`; returns the next depth's queue length.
    fn depth(
        &mut self,
        words: &[u32],
        depth: u32,
        stats: &mut GpuRenderStats,
        progress: &mut dyn FnMut(DepthStats),
    ) -> u64 {
        let s = DepthStats {
            depth,
            rays: words[counter::STAT_RAYS as usize] as usize,
            hits: words[counter::STAT_HITS as usize] as usize,
            shadow_rays: words[counter::STAT_SHADOWS as usize] as usize,
            volume_samples: 0,
        };
        if stats.depths.len() <= depth as usize {
            stats.depths.push(DepthStats {
                depth,
                ..Default::default()
            });
        }
        let d = &mut stats.depths[depth as usize];
        d.rays += s.rays;
        d.hits += s.hits;
        d.shadow_rays += s.shadow_rays;
        progress(s);
        words[counter::QUEUE as usize] as u64
    }

    /// A finished [`Submit::Wave`] wave, once its submission `index` is done: reads its
    /// readback `buf` (the wait counted in `stats.wait_ms`), then its depths' statistics up to
    /// the first whose next queue was empty (as [`Submit::Depth`] stops there), and its passes'
    /// timestamps.
    #[allow(clippy::too_many_arguments)]
    fn wave(
        &mut self,
        ctx: &GpuContext,
        buf: &wgpu::Buffer,
        index: wgpu::SubmissionIndex,
        shape: &FrameShape,
        passes: &[usize],
        stats: &mut GpuRenderStats,
        progress: &mut dyn FnMut(DepthStats),
    ) -> Result<(), GpuError> {
        let waited = Instant::now();
        let words: Vec<u32> = read_back_after(ctx, buf, Some(index))?;
        stats.wait_ms += waited.elapsed().as_secs_f64() * 1e3;
        let slots = counter::SLOTS as usize;
        for (d, set) in words
            .chunks_exact(slots)
            .take(shape.counter_sets as usize)
            .enumerate()
        {
            if self.depth(set, d as u32, stats, progress) == 0 {
                break;
            }
        }
        self.stamps(&words[shape.counter_sets as usize * slots..], passes, ctx);
        Ok(())
    }
}

const COUNTER_BYTES: u64 = counter::SLOTS as u64 * 4;

/// The scene's textures as render.wgsl's `textures` reads them (layout::TEXTURE_INFO): the sRGB
/// table, each texture's first texel, width and height, then the texels packed RGBA8.
fn texture_table(scene: &Scene) -> Vec<u32> {
    let infos = TEXTURE_INFO_WORDS * scene.textures.len() as u32;
    let mut table: Vec<u32> = raystream_io::SRGB_TO_LINEAR
        .iter()
        .map(|v| v.to_bits())
        .collect();
    // A table past u32 offsets is over 16 GiB, which no adapter binds (`storage` refuses it).
    let mut first = (TEXTURE_INFO + infos) as u64;
    for t in &scene.textures {
        table.extend([
            u32::try_from(first).unwrap_or(u32::MAX),
            t.width,
            t.height,
            t.mapping.clamp as u32,
            t.mapping.scale.x.to_bits(),
            t.mapping.scale.y.to_bits(),
            t.mapping.offset.x.to_bits(),
            t.mapping.offset.y.to_bits(),
        ]);
        first += t.texels.len() as u64;
    }
    for t in &scene.textures {
        table.extend(t.texels.iter().map(|&p| u32::from_le_bytes(p)));
    }
    table
}

/// Checks every index the render kernels follow from `scene`'s arrays (what kernels compiled
/// without bounds checks rely on: `GpuContext::set_unchecked_kernels`): one normal and ray
/// offset a vertex, vertex and material indices in range, texture coordinates for every
/// triangle where a material has a texture, texels filling each texture, and the tree's
/// `prims` (one past its largest primitive id) no more than the triangles. The scene loaders
/// make such scenes; a scene put together by hand may not.
fn scene_links(scene: &Scene, prims: u64) -> Result<(), String> {
    let (vertices, tris) = (scene.mesh.positions.len(), scene.mesh.triangles.len());
    if scene.normals.len() != vertices || scene.ray_offsets.len() != vertices {
        return Err(format!(
            "{vertices} vertices, {} normals, {} ray offsets",
            scene.normals.len(),
            scene.ray_offsets.len()
        ));
    }
    if let Some(t) = scene
        .mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&v| v as usize >= vertices))
    {
        return Err(format!("triangle {t}: a vertex beyond the {vertices}"));
    }
    if scene.material_of.len() != tris {
        return Err(format!(
            "{tris} triangles, {} material indices",
            scene.material_of.len()
        ));
    }
    if prims > tris as u64 {
        return Err(format!(
            "the kd-tree's primitive ids go up to {}, the scene has {tris} triangles",
            prims - 1
        ));
    }
    let materials = scene.materials.len();
    if let Some(t) = scene
        .material_of
        .iter()
        .position(|&m| m as usize >= materials)
    {
        return Err(format!("triangle {t}: a material beyond the {materials}"));
    }
    let textures = scene.textures.len();
    let mut textured = false;
    for (i, m) in scene.materials.iter().enumerate() {
        match m.texture {
            Some(k) if k as usize >= textures => {
                return Err(format!("material {i}: texture {k} of {textures}"));
            }
            Some(_) => textured = true,
            None => {}
        }
    }
    if textured && scene.uvs.len() != tris {
        return Err(format!(
            "{tris} textured triangles, {} with texture coordinates",
            scene.uvs.len()
        ));
    }
    if !scene.colours.is_empty() && scene.colours.len() != tris {
        return Err(format!(
            "{tris} triangles, {} with corner colours",
            scene.colours.len()
        ));
    }
    for (k, t) in scene.textures.iter().enumerate() {
        if t.width == 0
            || t.height == 0
            || t.texels.len() as u64 != t.width as u64 * t.height as u64
        {
            return Err(format!(
                "texture {k}: {}x{} with {} texels",
                t.width,
                t.height,
                t.texels.len()
            ));
        }
    }
    Ok(())
}

impl<'a> GpuRenderer<'a> {
    /// Uploads `scene`'s vertices, triangles, materials and lights, whose kd-tree `tree` is
    /// `tracer`'s, and builds the render pipelines. A scene's volume goes up as a texture
    /// with the light grids that the CPU computes from `tree` (as `raystream_cpu::render`).
    pub fn new(
        tracer: &'a GpuTracer<'a>,
        scene: &'a Scene,
        tree: &KdTree,
    ) -> Result<GpuRenderer<'a>, GpuError> {
        let ctx = tracer.ctx;
        scene_links(scene, tracer.prims)
            .map_err(|e| ctx.err(format!("the scene's links are broken: {e}")))?;
        let need = 3 + 6 + 6 + if scene.volume.is_some() { 4 } else { 1 };
        if ctx.limits.max_storage_buffers_per_shader_stage < need {
            return Err(ctx.err(format!(
                "the render kernels bind {need} storage buffers, the adapter allows {}",
                ctx.limits.max_storage_buffers_per_shader_stage
            )));
        }
        ctx.scoped(|| {
            let vertices: Vec<Vertex> = scene
                .mesh
                .positions
                .iter()
                .zip(&scene.normals)
                .zip(&scene.ray_offsets)
                .map(|((p, n), &offset)| Vertex {
                    position: p.extend(1.0).to_array(),
                    normal: n.extend(offset).to_array(),
                })
                .collect();
            let shade_tris: Vec<ShadeTri> = scene
                .mesh
                .triangles
                .iter()
                .zip(&scene.material_of)
                .map(|(&v, &material)| ShadeTri { v, material })
                .collect();
            let materials: Vec<GpuMaterial> = scene
                .materials
                .iter()
                .map(|m| GpuMaterial {
                    ambient: v3(m.ambient),
                    reflectivity: m.reflectivity,
                    diffuse: v3(m.diffuse),
                    transparency: m.transparency,
                    specular: v3(m.specular),
                    shininess: m.shininess,
                    ior: m.ior,
                    fresnel: m.fresnel as u32,
                    texture: m.texture.unwrap_or(NO_TEXTURE),
                    pad: 0,
                })
                .collect();
            let lights: Vec<GpuLight> = scene.lights.iter().map(gpu_light).collect();
            let none = wgpu::BufferUsages::empty();
            let vertices = ctx.storage("vertices", bytemuck::cast_slice(&vertices), none)?;
            let shade_tris =
                ctx.storage("shading triangles", bytemuck::cast_slice(&shade_tris), none)?;
            let materials = ctx.storage("materials", bytemuck::cast_slice(&materials), none)?;
            let lights = ctx.storage(
                "lights",
                bytemuck::cast_slice(&lights),
                wgpu::BufferUsages::COPY_DST,
            )?;
            // A triangle's texture coordinates (0 where the scene has none) and its corners'
            // colours (white where it has none).
            let packed = |c: raystream_io::Rgb8| u32::from_le_bytes([c[0], c[1], c[2], 255]);
            let corners: Vec<TriCorners> = (0..scene.uvs.len().max(scene.colours.len()))
                .map(|t| {
                    let [a, b, c] = scene.uvs.get(t).copied().unwrap_or_default();
                    let [ca, cb, cc] = scene.colours.get(t).copied().unwrap_or([[255; 3]; 3]);
                    TriCorners {
                        a: a.to_array(),
                        b: b.to_array(),
                        c: c.to_array(),
                        colour_a: packed(ca),
                        colour_b: packed(cb),
                        colour_c: packed(cc),
                        pad: 0,
                    }
                })
                .collect();
            // A scene without textures or colours binds a zeroed element it never reads.
            let tri_corners =
                ctx.storage("triangle corners", bytemuck::cast_slice(&corners), none)?;
            let textures = ctx.storage(
                "textures",
                bytemuck::cast_slice(&texture_table(scene)),
                none,
            )?;
            let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("render params"),
                size: std::mem::size_of::<RenderParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let uniform = wgpu::BufferBindingType::Uniform;
            let ro = wgpu::BufferBindingType::Storage { read_only: true };
            let rw = wgpu::BufferBindingType::Storage { read_only: false };
            let layouts = [
                ctx.buffer_layout("kd-tree", &[uniform, ro, ro, ro, ro]),
                ctx.buffer_layout("scene", &[uniform, ro, ro, ro, ro, ro, ro]),
                ctx.buffer_layout("queues", &[rw; 6]),
                ctx.buffer_layout("dispatch args", &[rw]),
            ];
            let medium_layout = scene.volume.as_ref().map(|_| medium_layout(ctx));
            let module = ctx.tree_module(
                "render.wgsl",
                render_wgsl(ctx.subgroup_appends()),
                scene.volume.is_some(),
            );
            // The kernels that write dispatch arguments see them as group 3; the others may not
            // (a buffer cannot be storage and indirect-argument source in one dispatch).
            let [tree_layout, scene_layout, queues, args] = &layouts;
            let work = ctx.pipeline_layout("render", &[tree_layout, scene_layout, queues]);
            let control = ctx.pipeline_layout("render", &[tree_layout, scene_layout, queues, args]);
            // The volume stages see the volume as group 3.
            let volume = medium_layout.as_ref().map(|m| {
                ctx.pipeline_layout(
                    "render volume stages",
                    &[tree_layout, scene_layout, queues, m],
                )
            });
            let pipelines = STAGES
                .iter()
                .enumerate()
                .map(|(k, &entry)| {
                    let layout = match entry {
                        "prepare_shadows" | "advance" => &control,
                        _ if VOLUME_STAGES.contains(&k) => volume.as_ref()?,
                        _ => &work,
                    };
                    Some(ctx.layout_pipeline(&module, entry, layout, &[]))
                })
                .collect();
            let medium = match (&scene.volume, &medium_layout) {
                (Some(v), Some(layout)) => {
                    let m = Medium::new(v, scene, tree, Traversal::Ropes);
                    let gpu = GpuVolume::new(ctx, &v.volume, &v.tf, m.marcher())?;
                    let group = medium_group(ctx, layout, &gpu, &m, v, scene.lights.len())?;
                    Some((gpu, group))
                }
                _ => None,
            };
            let film_layout = ctx.buffer_layout("film", &[ro, rw]);
            let film_module = ctx
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("film.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(film_wgsl().into()),
                });
            let film_pipeline = ctx.layout_pipeline(
                &film_module,
                "resolve_film",
                &ctx.pipeline_layout("film", &[&film_layout]),
                &[],
            );
            let srgb8_pipeline = ctx.auto_pipeline(&film_module, "resolve_film_srgb8");
            let per_sample = 48 * 2.max(scene.lights.len() as u64);
            let fit = (ctx.max_binding() / per_sample).min(u32::MAX as u64) as u32;
            // A hit spawns two rays only off a material that refracts and also reflects (by its
            // reflectivity or by Fresnel); scenes hold no NaN (desc.rs checks both lie in [0, 1]).
            let branches = scene
                .materials
                .iter()
                .any(|m| m.transparency > 0.0 && (m.reflectivity > 0.0 || m.fresnel));
            Ok(GpuRenderer {
                wave: ctx.render_wave.min(fit).max(1),
                submit: Submit::Wave,
                branches,
                tracer,
                scene,
                vertices,
                shade_tris,
                materials,
                lights,
                tri_corners,
                coloured: !scene.colours.is_empty(),
                textures,
                params,
                layouts,
                pipelines,
                medium,
                film_layout,
                film_pipeline,
                srgb8_pipeline,
                frame: std::sync::Mutex::new(None),
                camera: std::sync::Mutex::new(None),
            })
        })
    }

    /// Grows `buf` to hold `n` items of `T` (its old contents are not kept); returns whether it
    /// grew (a new buffer, to be bound anew).
    fn ensure<T>(
        &self,
        buf: &mut wgpu::Buffer,
        what: &'static str,
        n: u64,
    ) -> Result<bool, GpuError> {
        let need = n * std::mem::size_of::<T>() as u64;
        if buf.size() >= need {
            return Ok(false);
        }
        let ctx = self.tracer.ctx;
        let size = grown_size(need, ctx.max_binding());
        *buf = ctx.work_buffer(what, size, wgpu::BufferUsages::empty())?;
        Ok(true)
    }

    /// Asks for `submit` ([`Submit::Wave`] by default); [`GpuRenderer::submit_for`] says what
    /// a frame runs.
    pub fn with_submit(mut self, submit: Submit) -> Self {
        self.submit = submit;
        self
    }

    /// How a frame of `opt` is submitted: as asked, except that a scene where a hit can spawn
    /// two rays, or a max depth of [`MAX_WAVE_DEPTHS`] or more, runs [`Submit::Depth`].
    pub fn submit_for(&self, opt: &RenderOptions) -> Submit {
        if self.submit == Submit::Wave && !self.branches && opt.max_depth < MAX_WAVE_DEPTHS {
            Submit::Wave
        } else {
            Submit::Depth
        }
    }

    /// The stages that depth `depth` runs, in order: generation at depth 0 only, the volume
    /// stages only in a scene with a volume.
    fn passes(&self, depth: u32) -> Vec<usize> {
        (0..STAGES.len())
            .filter(|&k| (k != GENERATE || depth == 0) && self.pipelines[k].is_some())
            .collect()
    }

    /// Records the passes `order` (a depth's, [`GpuRenderer::passes`]) of a wave of `n`
    /// samples, tracing ray queue `cur`; pass j writes timestamps 2(first + j) and
    /// 2(first + j) + 1. Returns `first` plus the passes recorded.
    #[allow(clippy::too_many_arguments)]
    fn record_depth(
        &self,
        enc: &mut wgpu::CommandEncoder,
        order: &[usize],
        n: u32,
        g: &Groups,
        cur: usize,
        q: &Queues,
        first: u32,
    ) -> u32 {
        let ctx = self.tracer.ctx;
        for (j, &k) in order.iter().enumerate() {
            let stage = STAGES[k];
            let stamp = 2 * (first + j as u32);
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(stage),
                timestamp_writes: q
                    .resolve
                    .as_ref()
                    .map(|t| t.writes(Some(stamp), Some(stamp + 1))),
            });
            pass.set_pipeline(self.pipelines[k].as_ref().expect("a stage this scene runs"));
            pass.set_bind_group(0, &g.tree, &[]);
            pass.set_bind_group(1, &g.scene, &[]);
            pass.set_bind_group(2, &g.work[cur], &[]);
            if let Some((_, group)) = &self.medium
                && VOLUME_STAGES.contains(&k)
            {
                pass.set_bind_group(3, group, &[]);
            }
            match stage {
                "generate_camera_rays" => {
                    let [gx, gy, _] = ctx.dims(n);
                    pass.dispatch_workgroups(gx, gy, 1);
                }
                "prepare_shadows" | "advance" => {
                    pass.set_bind_group(3, &g.args, &[]);
                    pass.dispatch_workgroups(1, 1, 1);
                }
                "intersect_any" | "attenuate_shadows" | "accumulate" => {
                    pass.dispatch_workgroups_indirect(&q.args, SHADOW_ARGS)
                }
                _ => pass.dispatch_workgroups_indirect(&q.args, QUEUE_ARGS),
            }
        }
        first + order.len() as u32
    }

    /// How many waves a frame of `opt` takes.
    pub fn waves(&self, opt: &RenderOptions) -> u64 {
        (opt.width as u64 * opt.height as u64 * opt.spp as u64).div_ceil(self.wave as u64)
    }

    /// Traces at most `samples` samples at a time (the default is the most that fits, up to
    /// [`DEFAULT_WAVE`] or the context's wave); the image does not depend on it.
    pub fn with_wave(mut self, samples: u32) -> Self {
        self.wave = self.wave.min(samples.max(1));
        self
    }

    /// Renders the next frames from `camera`, lit by `lights` (the scene's, moved: as many, in
    /// its order), as a turntable turns the camera and its studio lights about the scene. A
    /// scene with a volume must keep its lights (its light grids were made for them): other
    /// lights are refused.
    pub fn set_view(&self, camera: Camera, lights: &[Light]) -> Result<(), GpuError> {
        let ctx = self.tracer.ctx;
        if lights.len() != self.scene.lights.len() {
            return Err(ctx.err(format!(
                "a view with {} lights for a scene of {}",
                lights.len(),
                self.scene.lights.len()
            )));
        }
        if self.medium.is_some() && lights != self.scene.lights.as_slice() {
            return Err(ctx.err(
                "a scene with a volume keeps its lights (its light grids were made for them)"
                    .to_string(),
            ));
        }
        let gpu: Vec<GpuLight> = lights.iter().map(gpu_light).collect();
        if !gpu.is_empty() {
            ctx.queue
                .write_buffer(&self.lights, 0, bytemuck::cast_slice(&gpu));
        }
        *self.camera.lock().unwrap() = Some(camera);
        Ok(())
    }

    /// Renders the scene with `opt` (its `traversal` is the CPU's; the GPU always uses ropes);
    /// `progress` is told after each depth of each wave.
    pub fn render(
        &self,
        opt: &RenderOptions,
        mut progress: impl FnMut(DepthStats),
    ) -> Result<(Image, GpuRenderStats), GpuError> {
        let (film, stats) = self.run(opt, &mut progress, false)?;
        Ok((film.into_linear(), stats))
    }

    /// Renders as [`Self::render`] and delivers the frame as a viewer shows it: 8-bit sRGB,
    /// 3 bytes a pixel (as [`Image::to_srgb8`]), converted from the film on the GPU so that a
    /// quarter of the resolved film's bytes come back.
    pub fn render_srgb8(
        &self,
        opt: &RenderOptions,
        mut progress: impl FnMut(DepthStats),
    ) -> Result<(Vec<u8>, GpuRenderStats), GpuError> {
        let (film, stats) = self.run(opt, &mut progress, true)?;
        Ok((film.into_srgb8(), stats))
    }

    /// Renders in waves of at most `self.wave` samples. Where a hit can spawn two rays the
    /// queues may double every depth; when one then needs more than a binding holds, or the
    /// device has no memory left for a wave's queues, the frame starts again in waves half as
    /// large (the image does not depend on the wave size).
    fn run(
        &self,
        opt: &RenderOptions,
        progress: &mut dyn FnMut(DepthStats),
        srgb8: bool,
    ) -> Result<(Pixels, GpuRenderStats), GpuError> {
        // Halved from the wave the frame runs in (no larger than the frame), not from the
        // renderer's most.
        let samples = opt.width as u64 * opt.height as u64 * opt.spp as u64;
        let mut wave = (self.wave as u64).min(samples.max(1)) as u32;
        loop {
            match self.run_in_waves(opt, progress, srgb8, wave) {
                Err(GpuError::TooLarge { what, .. } | GpuError::OutOfMemory { what, .. })
                    if WAVE_SIZED.contains(&what) && wave > 1 =>
                {
                    wave /= 2
                }
                r => return r,
            }
        }
    }

    /// One try of [`Self::run`] in waves of `wave` samples (at most the frame's: `run` sees
    /// to it).
    fn run_in_waves(
        &self,
        opt: &RenderOptions,
        progress: &mut dyn FnMut(DepthStats),
        srgb8: bool,
        wave: u32,
    ) -> Result<(Pixels, GpuRenderStats), GpuError> {
        let ctx = self.tracer.ctx;
        let scene = self.scene;
        let t0 = Instant::now();
        ctx.scoped(|| {
            let pixels = opt.width as u64 * opt.height as u64;
            let total = pixels * opt.spp as u64;
            if total > u32::MAX as u64 {
                return Err(ctx.err(format!(
                    "{}x{} pixels at {} samples is more than 2^32 samples",
                    opt.width, opt.height, opt.spp
                )));
            }
            let lights = scene.lights.len() as u64;
            let depths = opt.max_depth as u64 + 1;
            let submit = self.submit_for(opt);
            // Each depth's passes, and a whole wave's (what one readback's timestamps cover).
            let depth_passes: Vec<Vec<usize>> =
                (0..=opt.max_depth).map(|d| self.passes(d)).collect();
            let wave_passes = depth_passes.concat();
            let shape = FrameShape {
                pixels,
                wave: wave as u64,
                lights,
                counter_sets: if submit == Submit::Wave { depths } else { 1 },
                passes: match submit {
                    Submit::Wave => wave_passes.len() as u64,
                    Submit::Depth => STAGES.len() as u64,
                },
            };
            let kept = self.frame.lock().unwrap().take();
            let mut q = match kept {
                Some((k, q)) if k == shape => {
                    let mut enc =
                        ctx.device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("clear film"),
                            });
                    enc.clear_buffer(&q.film, 0, None);
                    ctx.queue.submit([enc.finish()]);
                    q
                }
                _ => self.queues(&shape)?,
            };
            let cam = self
                .camera
                .lock()
                .unwrap()
                .unwrap_or_else(|| scene.camera_for(opt.width as f32 / opt.height as f32));
            let mut params = RenderParams {
                eye: v3(cam.eye),
                tan_y: cam.tan_y,
                parallel: cam.parallel,
                fwd: v3(cam.fwd),
                width: opt.width,
                right: v3(cam.right),
                height: opt.height,
                up: v3(cam.up),
                spp: opt.spp,
                background: v3(scene.background),
                strata: strata(opt.spp),
                ambient_light: v3(scene.ambient_light),
                max_depth: opt.max_depth,
                light_count: lights as u32,
                max_groups: ctx.limits.max_compute_workgroups_per_dimension.max(1),
                band: if ctx.pixel_blocks() {
                    // A subgroup's lanes; an adapter that varies them runs at most this many.
                    band_rows(ctx.info.subgroup_max_size.clamp(1, 128), opt.spp)
                } else {
                    1
                },
                coloured: self.coloured as u32,
                ..Default::default()
            };
            let mut stats = GpuRenderStats {
                submit,
                ..Default::default()
            };
            let mut tally = Tally {
                stage_ms: [0.0; STAGES.len()],
                timed: q.resolve.is_some(),
            };
            let tree_group = self.tracer.bind_tree(&self.layouts[0]);
            let scene_group = ctx.bind_buffers(
                "scene",
                &self.layouts[1],
                &[
                    &self.params,
                    &self.vertices,
                    &self.shade_tris,
                    &self.materials,
                    &self.lights,
                    &self.tri_corners,
                    &self.textures,
                ],
            );
            let args_group = ctx.bind_buffers("args", &self.layouts[3], &[&q.args]);
            let work_group = |q: &Queues, cur: usize| {
                ctx.bind_buffers(
                    "queues",
                    &self.layouts[2],
                    &[
                        &q.counters,
                        &q.rays[cur],
                        &q.hits,
                        &q.rays[1 - cur],
                        &q.shadows,
                        &q.film,
                    ],
                )
            };
            let groups = |q: &Queues| Groups {
                tree: tree_group.clone(),
                scene: scene_group.clone(),
                args: args_group.clone(),
                work: [work_group(q, 0), work_group(q, 1)],
            };
            let stamp_offset = shape.counter_sets * COUNTER_BYTES;
            // The wave submitted last, whose counters are still to be read: (readback slot,
            // submission).
            let mut in_flight: Option<(usize, wgpu::SubmissionIndex)> = None;
            let mut slot = 0usize;
            // Bound anew only where a depth grows a queue ([`Submit::Depth`]).
            let mut g = groups(&q);
            let mut base = 0u64;
            while base < total {
                let n = (total - base).min(wave as u64) as u32;
                stats.waves += 1;
                params.sample_base = base as u32;
                params.sample_count = n;
                // With the last wave still queued: queue writes run at the start of the next
                // submission, and a queue's submissions run one after another (wgpu-hal's `submit`
                // contract), so the last wave reads its own parameters and counters.
                ctx.queue
                    .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
                let mut counters = [0u32; counter::SLOTS as usize];
                counters[counter::QUEUE as usize] = n;
                ctx.queue
                    .write_buffer(&q.counters, 0, bytemuck::cast_slice(&counters));
                ctx.queue
                    .write_buffer(&q.args, QUEUE_ARGS, bytemuck::cast_slice(&ctx.dims(n)));
                if submit == Submit::Wave {
                    // Every depth in one submission; the counters after each depth go aside.
                    let mut enc =
                        ctx.device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("wave"),
                            });
                    let mut pass = 0u32;
                    for (depth, order) in depth_passes.iter().enumerate() {
                        pass = self.record_depth(&mut enc, order, n, &g, depth % 2, &q, pass);
                        let at = depth as u64 * COUNTER_BYTES;
                        enc.copy_buffer_to_buffer(
                            &q.counters,
                            0,
                            &q.readback[slot],
                            at,
                            COUNTER_BYTES,
                        );
                    }
                    q.copy_stamps(&mut enc, pass, slot, stamp_offset);
                    let cmd = enc.finish();
                    let waited = Instant::now();
                    let index = ctx.queue.submit([cmd]);
                    stats.submissions += 1;
                    stats.wait_ms += waited.elapsed().as_secs_f64() * 1e3;
                    // The GPU has this wave queued while the host reads the last one's counters.
                    if let Some((s, i)) = in_flight.replace((slot, index)) {
                        let buf = &q.readback[s];
                        tally.wave(ctx, buf, i, &shape, &wave_passes, &mut stats, progress)?;
                    }
                    slot = 1 - slot;
                    base += n as u64;
                    continue;
                }
                let mut cur = 0usize;
                let mut count = n as u64;
                for (depth, order) in depth_passes.iter().enumerate() {
                    let grew = [
                        self.ensure::<RayWork>(&mut q.rays[1 - cur], "next ray queue", 2 * count)?,
                        self.ensure::<ShadowWork>(&mut q.shadows, "shadow queue", count * lights)?,
                        self.ensure::<GpuHit>(&mut q.hits, "hits", count.max(count * lights))?,
                    ];
                    if grew.contains(&true) {
                        g = groups(&q);
                    }
                    let mut enc =
                        ctx.device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("depth"),
                            });
                    let passes = self.record_depth(&mut enc, order, n, &g, cur, &q, 0);
                    q.copy_stamps(&mut enc, passes, 0, stamp_offset);
                    enc.copy_buffer_to_buffer(&q.counters, 0, &q.readback[0], 0, COUNTER_BYTES);
                    let cmd = enc.finish();
                    let waited = Instant::now();
                    ctx.queue.submit([cmd]);
                    stats.submissions += 1;
                    let words = read_words(ctx, &q.readback[0])?;
                    stats.wait_ms += waited.elapsed().as_secs_f64() * 1e3;
                    let stamps = &words[stamp_offset as usize / 4..];
                    tally.stamps(stamps, order, ctx);
                    count = tally.depth(&words, depth as u32, &mut stats, progress);
                    if count == 0 {
                        break;
                    }
                    cur = 1 - cur;
                }
                base += n as u64;
            }
            if let Some((s, i)) = in_flight {
                let buf = &q.readback[s];
                tally.wave(ctx, buf, i, &shape, &wave_passes, &mut stats, progress)?;
            }
            let (stage_ms, timed) = (tally.stage_ms, tally.timed);
            let film_t = Instant::now();
            let scale = 1.0 / (FILM_SCALE as f64 * opt.spp as f64);
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("resolve film"),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("resolve_film"),
                    timestamp_writes: None,
                });
                if srgb8 {
                    let pack = wgpu::util::DeviceExt::create_buffer_init(
                        &ctx.device,
                        &wgpu::util::BufferInitDescriptor {
                            label: Some("pack params"),
                            contents: bytemuck::cast_slice(&[
                                (scale as f32).to_bits(),
                                pixels as u32,
                                0,
                                0,
                            ]),
                            usage: wgpu::BufferUsages::UNIFORM,
                        },
                    );
                    let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("film to sRGB"),
                        layout: &self.srgb8_pipeline.get_bind_group_layout(0),
                        entries: &[
                            wgpu::BindGroupEntry {
                                binding: 0,
                                resource: q.film.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 2,
                                resource: q.packed.as_entire_binding(),
                            },
                            wgpu::BindGroupEntry {
                                binding: 3,
                                resource: pack.as_entire_binding(),
                            },
                        ],
                    });
                    pass.set_pipeline(&self.srgb8_pipeline);
                    pass.set_bind_group(0, &group, &[]);
                    let [gx, gy, _] = ctx.dims(pixels.div_ceil(4) as u32);
                    pass.dispatch_workgroups(gx, gy, 1);
                } else {
                    let group = ctx.bind_buffers("film", &self.film_layout, &[&q.film, &q.image]);
                    pass.set_pipeline(&self.film_pipeline);
                    pass.set_bind_group(0, &group, &[]);
                    let [gx, gy, _] = ctx.dims(pixels as u32);
                    pass.dispatch_workgroups(gx, gy, 1);
                }
            }
            let packed_bytes = pixels.div_ceil(4) * 12;
            if srgb8 {
                enc.copy_buffer_to_buffer(&q.packed, 0, &q.packed_read, 0, packed_bytes);
            } else {
                enc.copy_buffer_to_buffer(&q.image, 0, &q.image_read, 0, pixels * 12);
            }
            ctx.queue.submit([enc.finish()]);
            // The packed bytes straight into the frame's vector; the float film as words.
            let (mut bytes, words): (Vec<u8>, Vec<u32>) = if srgb8 {
                (read_back(ctx, &q.packed_read)?, Vec::new())
            } else {
                (Vec::new(), read_words(ctx, &q.image_read)?)
            };
            let film = if srgb8 {
                bytes.truncate(3 * pixels as usize);
                Pixels::Srgb8(bytes)
            } else {
                let sums: &[f32] = bytemuck::cast_slice(&words);
                Pixels::Linear(Image {
                    width: opt.width,
                    height: opt.height,
                    pixels: sums[..3 * pixels as usize]
                        .chunks_exact(3)
                        .map(|p| {
                            let ch = |c: usize| (p[c] as f64 * scale) as f32;
                            Vec3::new(ch(0), ch(1), ch(2))
                        })
                        .collect(),
                })
            };
            *self.frame.lock().unwrap() = Some((shape, q));
            stats.film_ms = film_t.elapsed().as_secs_f64() * 1e3;
            stats.render_ms = t0.elapsed().as_secs_f64() * 1e3;
            stats.kernel_gpu_ms = timed.then(|| {
                STAGES
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| self.pipelines[*k].is_some())
                    .map(|(k, &name)| (name, stage_ms[k]))
                    .collect()
            });
            Ok((film, stats))
        })
    }

    fn queues(&self, shape: &FrameShape) -> Result<Queues, GpuError> {
        let ctx = self.tracer.ctx;
        let FrameShape {
            pixels,
            wave,
            lights,
            ..
        } = *shape;
        let readback = || {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("counters readback"),
                size: shape.counter_sets * COUNTER_BYTES + shape.passes * 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let ray_bytes = std::mem::size_of::<RayWork>() as u64;
        let none = wgpu::BufferUsages::empty();
        Ok(Queues {
            counters: ctx.work_buffer("queue counters", COUNTER_BYTES, none)?,
            args: ctx.work_buffer("dispatch arguments", 24, wgpu::BufferUsages::INDIRECT)?,
            rays: [
                ctx.work_buffer("ray queue", wave * ray_bytes, none)?,
                ctx.work_buffer("next ray queue", 2 * wave * ray_bytes, none)?,
            ],
            hits: ctx.work_buffer("hits", wave * lights.max(1) * 16, none)?,
            shadows: ctx.work_buffer("shadow queue", wave * lights.max(1) * ray_bytes, none)?,
            film: ctx.work_buffer("film", pixels * 24, none)?,
            image: ctx.work_buffer("resolved film", pixels * 12, none)?,
            packed: ctx.work_buffer("sRGB film", pixels.div_ceil(4) * 12, none)?,
            packed_read: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sRGB film readback"),
                size: (pixels.div_ceil(4) * 12).max(64),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            image_read: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("resolved film readback"),
                size: (pixels * 12).max(64),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            readback: [readback(), readback()],
            resolve: ctx.timer(2 * shape.passes as u32),
        })
    }
}

/// The size a queue buffer grows to for `need` bytes: with headroom, so that a slowly growing
/// queue is not reallocated every depth, but never past what a binding holds (`limit`) when
/// `need` itself fits (the headroom made 640x480 at 8 spp fail on lavapipe's 128 MiB bindings).
fn grown_size(need: u64, limit: u64) -> u64 {
    (need + need / 2).min(limit.max(need))
}

/// Group 3 of the volume stages (medium.wgsl): binding 0 is left to the dispatch arguments of
/// the control kernels.
fn medium_layout(ctx: &crate::GpuContext) -> wgpu::BindGroupLayout {
    let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty,
        count: None,
    };
    let buffer = |ty| wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let ro = wgpu::BufferBindingType::Storage { read_only: true };
    ctx.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("scene volume"),
            entries: &[
                entry(1, buffer(wgpu::BufferBindingType::Uniform)),
                entry(
                    2,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D3,
                        multisampled: false,
                    },
                ),
                entry(
                    3,
                    wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                ),
                entry(4, buffer(ro)),
                entry(5, buffer(ro)),
                entry(6, buffer(ro)),
                entry(7, buffer(ro)),
                entry(
                    8,
                    wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D3,
                        multisampled: false,
                    },
                ),
                entry(9, buffer(ro)),
            ],
        })
}

/// The volume stages' bind group: `m`'s parameters, brick table and light grids (one per
/// light, back to back) with `gpu`'s texture and transfer function.
fn medium_group(
    ctx: &crate::GpuContext,
    layout: &wgpu::BindGroupLayout,
    gpu: &GpuVolume,
    m: &Medium,
    v: &raystream_scene::SceneVolume,
    lights: usize,
) -> Result<wgpu::BindGroup, GpuError> {
    let ([r0, r1, r2], origin) = gpu.to_index;
    let grid_dims = raystream_cpu::dvr::LightGrid::dims_for(v.volume.dims);
    let grids: Vec<f32> = m
        .light_grids()
        .iter()
        .flat_map(|g| g.values.iter().copied())
        .collect();
    let sh = v.tf.shading;
    let bricks = crate::volume::brick_buffer(ctx, m.marcher().brick_table().1)?;
    let params = MediumParams {
        to_index0: r0.to_array(),
        step: m.step,
        to_index1: r1.to_array(),
        light_count: lights as u32,
        to_index2: r2.to_array(),
        skip_empty: 1,
        origin: origin.to_array(),
        opacity_count: v.tf.opacity.len() as u32,
        dims: v.volume.dims.map(|n| n as u32),
        color_count: v.tf.color.len() as u32,
        bricks: gpu.brick_dims,
        shadows: v.shadows as u32,
        shading: [sh.ambient, sh.diffuse, sh.specular, sh.power],
        light_dims: grid_dims.map(|n| n as u32),
        grid_points: grid_dims.iter().product::<usize>() as u32,
        interpolation: v.interpolation.kernel_code(),
        segments: v.segments.is_some() as u32,
        pad1: 0,
        pad2: 0,
    };
    let (labels, colours) = crate::volume::segment_bindings(ctx, v.segments.as_ref())?;
    let none = wgpu::BufferUsages::empty();
    // A binding may not be empty: one value stands in when the volume is unshadowed.
    let grids = ctx.storage(
        "light grids",
        bytemuck::cast_slice(if grids.is_empty() { &[1.0f32] } else { &grids }),
        none,
    )?;
    let params = wgpu::util::DeviceExt::create_buffer_init(
        &ctx.device,
        &wgpu::util::BufferInitDescriptor {
            label: Some("scene volume params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        },
    );
    let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
    Ok(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("scene volume"),
        layout,
        entries: &[
            entry(1, params.as_entire_binding()),
            entry(2, wgpu::BindingResource::TextureView(&gpu.view)),
            entry(3, wgpu::BindingResource::Sampler(&gpu.sampler)),
            entry(4, gpu.opacity.as_entire_binding()),
            entry(5, gpu.color.as_entire_binding()),
            entry(6, bricks.as_entire_binding()),
            entry(7, grids.as_entire_binding()),
            entry(8, wgpu::BindingResource::TextureView(&labels)),
            entry(9, colours.as_entire_binding()),
        ],
    }))
}

#[cfg(test)]
mod tests {
    #[test]
    fn queues_grow_with_headroom_within_a_binding() {
        use super::grown_size;
        assert_eq!(grown_size(100, 1000), 150);
        // 2 x 0.97 M rays of 48 bytes under lavapipe's 128 MiB: the binding, not 146 MB.
        let (need, limit) = (2 * 970_000 * 48, 128 << 20);
        assert_eq!(grown_size(need, limit), limit);
        // Past the binding the need stands, and work_buffer refuses it by name.
        assert_eq!(grown_size(limit + 8, limit), limit + 8);
    }
}
