//! The GPU back-end on wgpu (Vulkan, Metal, DX12): a [`GpuContext`] (adapter choice, full
//! adapter limits, clear errors) and a [`GpuTracer`] that uploads the CPU-built kd-tree's flat
//! layout unchanged and runs the `intersect_closest` / `intersect_any` kernels over ray queues.
//!
//! Every struct the kernels read has one home in Rust (`raystream-accel::layout` for the tree,
//! [`layout`] here for rays, hits and parameters); the constants the kernels use are emitted from
//! Rust into a WGSL prelude, and a naga-based test checks WGSL offsets and sizes.
//!
//! # Example
//!
//! The CPU builds the kd-tree; the GPU traces rays through it and renders the scene with the
//! stream kernels, to the CPU's hits and (within the renderers' agreed tolerance) its
//! picture. Without a GPU (no Vulkan, Metal or DX12 adapter) [`GpuContext::new`] says so and
//! the CPU path is the one to take:
//!
//! ```
//! use raystream_accel::{Builder, KdTree, Traversal};
//! use raystream_cpu::RenderOptions;
//! use raystream_gpu::{GpuContext, GpuRenderer, GpuTracer};
//! use raystream_math::Ray;
//! use raystream_scene::Scene;
//!
//! let scene = Scene::builtin_default();
//! let tree = KdTree::build(&scene.mesh, Builder::Sah);
//! let ctx = match GpuContext::new(None) {
//!     Ok(ctx) => ctx,
//!     Err(e) => {
//!         eprintln!("{e}: raystream_cpu::render is the path to take");
//!         return Ok(());
//!     }
//! };
//! println!("{}", ctx.describe());
//!
//! // Ray queries: the tree's flat layout goes up unchanged, and the GPU's closest hits are
//! // the CPU's (the same t; the prim too but for rays through an edge two triangles share).
//! let tracer = GpuTracer::new(&ctx, &tree)?;
//! let cam = scene.camera_for(1.0);
//! let rays: Vec<Ray> = (0..32 * 32)
//!     .map(|i| cam.ray((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5, 32, 32))
//!     .collect();
//! let (hits, times) = tracer.trace(&rays, false)?;
//! for (ray, gpu) in rays.iter().zip(&hits) {
//!     let (gpu, cpu) = (gpu.hit(), tree.intersect(ray, Traversal::Ropes));
//!     assert_eq!(gpu.is_some(), cpu.is_some());
//!     if let (Some(g), Some(c)) = (gpu, cpu) {
//!         assert!((g.t - c.t).abs() <= 1e-5 * c.t);
//!     }
//! }
//! println!("{} rays in {:.3} ms from submission to answer", rays.len(), times.kernel_ms);
//!
//! // Rendering: the same frame as the CPU reference, to under half a level of 255 on
//! // average.
//! let renderer = GpuRenderer::new(&tracer, &scene, &tree)?;
//! let opt = RenderOptions { width: 64, height: 48, spp: 1, max_depth: 4, ..Default::default() };
//! let (image, _stats) = renderer.render(&opt, |_| {})?;
//! let reference = raystream_cpu::render(&scene, &tree, &opt, |_| {});
//! let (mean, _) = image.srgb8_diff(&reference);
//! assert!(mean < 0.5, "mean difference {mean} of 255");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod denoise;
pub mod layout;
mod render;
mod split;
mod volume;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use layout::{GpuHit, GpuRay, Params};
use raystream_accel::KdTree;
use raystream_accel::entry::ERROR_SCALE as ENTRY_ERROR_SCALE;
use raystream_accel::intersect::{
    PLANE_T_LEVER, PLANE_T_MIN_FACING, PLANE_T_SLACK, PLANE_T_SLACK_OF_T,
};
use raystream_accel::layout::{LEAF_BIT, NO_ROPE};
use raystream_math::Ray;
use wgpu::util::DeviceExt;

pub use denoise::{GpuDenoiser, denoise_wgsl};
pub use render::{
    DEFAULT_WAVE, GpuRenderStats, GpuRenderer, MAX_WAVE, MAX_WAVE_DEPTHS, STAGES, Submit,
    render_wgsl,
};
pub use split::{ITERATIONS_PER_SUBMIT, split_wgsl};
pub use volume::{GpuDvrTimes, GpuVolumeRenderer, dvr_wgsl};

/// Threads per workgroup of every kernel.
pub const WORKGROUP_SIZE: u32 = 64;
/// `prim` of a miss.
pub const NO_PRIM: u32 = u32::MAX;
/// How long a submission may run before it is reported as hung.
const GPU_TIMEOUT: Duration = Duration::from_secs(120);

const KDTREE_WGSL: &str = include_str!("kernels/kdtree.wgsl");
const QUERIES_WGSL: &str = include_str!("kernels/queries.wgsl");
const STATS_WGSL: &str = include_str!("kernels/stats.wgsl");
const PLANE_F64_WGSL: &str = include_str!("kernels/plane_f64.wgsl");

/// The constants every kernel shares, from their Rust definitions, then the kd-tree code
/// (without its work counters).
fn kdtree_core_wgsl() -> String {
    kdtree_core_wgsl_sized(WORKGROUP_SIZE)
}

/// [`kdtree_core_wgsl`] with `workgroup` threads per workgroup.
fn kdtree_core_wgsl_sized(workgroup: u32) -> String {
    format!(
        "const LEAF_BIT: u32 = {LEAF_BIT:#x}u;\nconst NO_ROPE: u32 = {NO_ROPE:#x}u;\nconst NO_PRIM: u32 = {NO_PRIM:#x}u;\nconst WORKGROUP_SIZE: u32 = {workgroup}u;\nconst ENTRY_ERROR_SCALE: f32 = {ENTRY_ERROR_SCALE:?};\nconst PLANE_T_LEVER: f32 = {PLANE_T_LEVER:?};\nconst PLANE_T_SLACK: f32 = {PLANE_T_SLACK:?};\nconst PLANE_T_SLACK_OF_T: f32 = {PLANE_T_SLACK_OF_T:?};\nconst PLANE_T_MIN_FACING: f32 = {PLANE_T_MIN_FACING:?};\n\n{KDTREE_WGSL}"
    )
}

/// The kd-tree code for every kernel but the statistics query: work counters that count nothing.
fn kdtree_wgsl() -> String {
    kdtree_wgsl_sized(WORKGROUP_SIZE)
}

/// [`kdtree_wgsl`] with `workgroup` threads per workgroup.
fn kdtree_wgsl_sized(workgroup: u32) -> String {
    format!(
        "{}\nfn stat(k: u32) {{}}\nfn stat_listed(n: u32) {{}}\n",
        kdtree_core_wgsl_sized(workgroup)
    )
}

/// WGSL `fn append(slot: u32, n: u32) -> u32` over the queue counters `counters` (an
/// `array<atomic<u32>, _>` of the module), for kernels that append to queues (`shade_hits`, the
/// split kernels): it reserves `n` consecutive slots of the queue counted by `counters[slot]`
/// and returns the first. A lane at a time, that is an atomic add of `n`; with
/// `subgroups` (the device needs wgpu's SUBGROUP feature), the subgroup's first active lane
/// adds the subgroup's total (warp-aggregated atomics: one atomic on the shared counter a
/// subgroup instead of one a lane) and each lane takes its place after the lanes before it (a
/// prefix sum), so every active lane of a subgroup must call it together, `n` 0 where a lane
/// appends nothing.
fn append_wgsl(subgroups: bool, counters: &str) -> String {
    let body = if subgroups {
        // The first active lane (none before it) is the one subgroupBroadcastFirst reads;
        // naga has no subgroupElect.
        "    let total = subgroupAdd(n);
    var first = 0u;
    if subgroupExclusiveAdd(1u) == 0u && total != 0u {
        first = atomicAdd(&COUNTERS[slot], total);
    }
    return subgroupBroadcastFirst(first) + subgroupExclusiveAdd(n);"
    } else {
        "    if n == 0u {
        return 0u;
    }
    return atomicAdd(&COUNTERS[slot], n);"
    };
    format!(
        "\n// Reserves `n` consecutive slots of the queue counted by `{counters}[slot]`; returns the first.\nfn append(slot: u32, n: u32) -> u32 {{\n{}\n}}\n",
        body.replace("COUNTERS", counters)
    )
}

/// Kernel `source` (holding kdtree.wgsl) with its triangle test's `plane_t_wide` in f64
/// (plane_f64.wgsl) instead of f32; the module needs wgpu's SHADER_F64 feature.
pub(crate) fn with_f64_planes(source: &str) -> String {
    const BEGIN: &str = "// PLANE_T_WIDE:";
    const END: &str = "// END PLANE_T_WIDE";
    let (Some(begin), Some(end)) = (source.find(BEGIN), source.find(END)) else {
        unreachable!("kdtree.wgsl's plane_t_wide is marked by {BEGIN} and {END}");
    };
    format!(
        "{}{}{}",
        &source[..begin],
        PLANE_F64_WGSL.trim_end(),
        &source[end + END.len()..]
    )
}

/// The WGSL source of the statistics query (`stats_closest`, `stats_any`); needs subgroups.
pub fn stats_wgsl() -> String {
    format!(
        "{}\nconst STATS_WORDS: u32 = {STATS_WORDS}u;\nconst LIVE: u32 = {STATS_LIVE}u;\nconst PEAK: u32 = {STATS_PEAK}u;\nconst LANES: u32 = {STATS_LANES}u;\n{STATS_WGSL}",
        kdtree_core_wgsl()
    )
}

/// The WGSL source of the ray-query kernels (`intersect_closest`, `intersect_any`).
pub fn queries_wgsl() -> String {
    queries_wgsl_sized(WORKGROUP_SIZE)
}

/// [`queries_wgsl`] with `workgroup` threads per workgroup (see
/// [`GpuContext::set_query_workgroup`]).
pub fn queries_wgsl_sized(workgroup: u32) -> String {
    format!("{}\n{QUERIES_WGSL}", kdtree_wgsl_sized(workgroup))
}

#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter found{0}")]
    NoAdapter(String),
    #[error("GPU adapter '{adapter}': cannot open a device: {source}")]
    Device {
        adapter: String,
        source: wgpu::RequestDeviceError,
    },
    #[error(
        "GPU '{adapter}': {what} needs {need} bytes in one buffer, the device allows {limit} (--device cpu has no such limit)"
    )]
    TooLarge {
        adapter: String,
        what: &'static str,
        need: u64,
        limit: u64,
    },
    #[error(
        "GPU '{adapter}': out of memory for {what} ({need} bytes; --device cpu has no such limit)"
    )]
    OutOfMemory {
        adapter: String,
        what: &'static str,
        need: u64,
    },
    #[error("GPU '{adapter}': {0}", adapter = .1)]
    Wgpu(String, String),
    #[error("GPU '{0}': the device was lost ({1})")]
    Lost(String, String),
}

/// An open GPU device.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    lost: Arc<Mutex<Option<String>>>,
    /// The first GPU error outside every error scope (wgpu's default would panic); every wait
    /// after it fails with it.
    uncaptured: Arc<Mutex<Option<String>>>,
    /// Waits poll the fence in a loop for up to [`SPIN_WAIT`] before blocking (see
    /// [`GpuContext::wait`]).
    spin_wait: bool,
    /// Threads per workgroup of the ray-query kernels (fused, if-if, persistent).
    query_workgroup: u32,
    /// The stream renderer's camera rays in blocks of pixels rather than rows (see
    /// [`GpuContext::set_pixel_blocks`]).
    pixel_blocks: bool,
    /// The stream renderer's most samples a wave (see [`GpuContext::set_render_wave`]).
    render_wave: u32,
    /// The kd-tree kernels compiled without wgpu's run-time checks (see
    /// [`GpuContext::set_unchecked_kernels`]).
    unchecked: bool,
    /// Kernels time their passes with timestamp queries where the adapter has them (see
    /// [`GpuContext::set_timestamps`]).
    timestamps: bool,
    /// `shade_hits` and the split kernels reserve queue slots a subgroup at a time where the
    /// adapter has subgroup operations (see [`GpuContext::set_subgroup_appends`]).
    subgroup_appends: bool,
    /// The triangle test places huge triangles' planes in f64 where the adapter has it (see
    /// [`GpuContext::set_f64_planes`]).
    f64_planes: bool,
    /// Tests only: the work buffers by these names fail as out of memory, each once, while
    /// they are at least the given bytes.
    #[cfg(test)]
    fail_alloc: Mutex<Vec<(&'static str, u64)>>,
}

/// How long a spinning wait polls before it blocks.
const SPIN_WAIT: Duration = Duration::from_millis(5);

/// Every adapter wgpu finds (Vulkan, Metal, DX12), in the order `--device gpu` prefers them: a
/// discrete GPU, then an integrated one, then anything else (such as lavapipe).
fn adapters_by_preference() -> Vec<wgpu::Adapter> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::PRIMARY,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::PRIMARY));
    // Stable: adapters of one type keep the driver's order.
    adapters.sort_by_key(|a| match a.get_info().device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    });
    adapters
}

/// What an adapter offers raystream (`raystream info --gpu`).
#[derive(Clone, Debug)]
pub struct AdapterSummary {
    pub info: wgpu::AdapterInfo,
    /// Timestamp queries: per-kernel times.
    pub timestamps: bool,
    /// Subgroup operations: the statistics query (SIMD efficiency, residency).
    pub subgroups: bool,
    /// f64 in kernels: huge triangles' planes as the CPU places them
    /// ([`GpuContext::set_f64_planes`]).
    pub f64: bool,
    /// The largest storage buffer a kernel can bind, and the largest buffer, bytes.
    pub max_storage_binding: u64,
    pub max_buffer: u64,
    pub max_workgroups_per_dimension: u32,
}

/// Every adapter, in the order `--device gpu` (without `--adapter`) prefers them: it opens the
/// first.
pub fn list_adapters() -> Vec<AdapterSummary> {
    adapters_by_preference()
        .iter()
        .map(|a| {
            let (features, limits) = (a.features(), a.limits());
            AdapterSummary {
                info: a.get_info(),
                timestamps: features.contains(wgpu::Features::TIMESTAMP_QUERY),
                subgroups: features.contains(wgpu::Features::SUBGROUP),
                f64: features.contains(wgpu::Features::SHADER_F64),
                max_storage_binding: limits.max_storage_buffer_binding_size,
                max_buffer: limits.max_buffer_size,
                max_workgroups_per_dimension: limits.max_compute_workgroups_per_dimension,
            }
        })
        .collect()
}

impl GpuContext {
    /// Opens the first adapter whose name contains `adapter` (case-insensitive), preferring a
    /// discrete GPU, then an integrated one, then anything else (such as lavapipe).
    pub fn new(adapter: Option<&str>) -> Result<GpuContext, GpuError> {
        let mut adapters = adapters_by_preference();
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        if let Some(want) = adapter {
            let want = want.to_lowercase();
            adapters.retain(|a| a.get_info().name.to_lowercase().contains(&want));
        }
        let Some(chosen) = adapters.into_iter().next() else {
            let why = match (adapter, names.is_empty()) {
                (_, true) => " (no Vulkan, Metal or DX12 driver answered)".to_string(),
                (Some(w), false) => format!(" matching '{w}' (available: {})", names.join(", ")),
                (None, false) => String::new(),
            };
            return Err(GpuError::NoAdapter(why));
        };
        let info = chosen.get_info();
        let limits = chosen.limits();
        // Per-kernel times come from timestamp queries where the adapter has them.
        // Subgroups, where there are, for the statistics query's SIMD efficiency.
        // f64, where there is, for the planes of triangles too large for f32's
        // (`GpuContext::set_f64_planes`).
        let features = chosen.features()
            & (wgpu::Features::TIMESTAMP_QUERY
                | wgpu::Features::SUBGROUP
                | wgpu::Features::SHADER_F64);
        let (device, queue) = pollster::block_on(chosen.request_device(&wgpu::DeviceDescriptor {
            label: Some("raystream"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|source| GpuError::Device {
            adapter: info.name.clone(),
            source,
        })?;
        let lost = Arc::new(Mutex::new(None));
        let lost_cb = lost.clone();
        device.set_device_lost_callback(move |reason, msg| {
            *lost_cb.lock().unwrap() = Some(format!("{reason:?}: {msg}"));
        });
        let uncaptured = Arc::new(Mutex::new(None));
        let uncaptured_cb = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            uncaptured_cb.lock().unwrap().get_or_insert(e.to_string());
        }));
        Ok(GpuContext {
            device,
            queue,
            info,
            limits,
            lost,
            uncaptured,
            spin_wait: false,
            query_workgroup: WORKGROUP_SIZE,
            pixel_blocks: true,
            render_wave: render::DEFAULT_WAVE,
            unchecked: true,
            timestamps: true,
            subgroup_appends: true,
            f64_planes: true,
            #[cfg(test)]
            fail_alloc: Mutex::new(Vec::new()),
        })
    }

    /// Makes waits for the GPU spin (poll the fence) for up to 5 ms before they block; the
    /// CLI turns it on for hardware adapters (`RAYSTREAM_GPU_WAIT=spin` or `block` chooses);
    /// every wait for a submission obeys it.
    pub fn set_spin_wait(&mut self, on: bool) {
        self.spin_wait = on;
    }

    /// Sets the threads per workgroup of the ray-query kernels (fused, if-if, persistent) of
    /// tracers made after it: a power of two from 32 to 1024 that the adapter allows. The CLI
    /// sets it from `RAYSTREAM_GPU_WORKGROUP` (an experiment: BENCHMARKS.md); the default is
    /// [`WORKGROUP_SIZE`]. The statistics query and the renderer keep [`WORKGROUP_SIZE`].
    pub fn set_query_workgroup(&mut self, threads: u32) -> Result<(), GpuError> {
        let most = self.limits.max_compute_invocations_per_workgroup.min(1024);
        if !threads.is_power_of_two() || !(32..=most).contains(&threads) {
            return Err(GpuError::Wgpu(
                format!(
                    "a query workgroup of {threads} threads: it must be a power of two from 32 to {most}"
                ),
                self.info.name.clone(),
            ));
        }
        self.query_workgroup = threads;
        Ok(())
    }

    /// Makes the stream renderer generate its camera rays in blocks of pixels (bands of rows,
    /// each band column by column, the band as tall as a square block of one subgroup's
    /// pixels; the default) or row by row: blocks keep a subgroup's rays closer together (on
    /// the H200 the default scene's `intersect_closest` ran 2.5-6 % faster: BENCHMARKS.md). The
    /// film is the same either way (its sums do not depend on order). The CLI sets it from
    /// `RAYSTREAM_GPU_PIXELS=blocks|rows`.
    pub fn set_pixel_blocks(&mut self, on: bool) {
        self.pixel_blocks = on;
    }

    /// Whether the stream renderer's camera rays go in blocks of pixels.
    pub fn pixel_blocks(&self) -> bool {
        self.pixel_blocks
    }

    /// Sets the samples of a stream renderer's wave (made after it), from 1 to
    /// [`render::MAX_WAVE`] ([`render::DEFAULT_WAVE`] by default); the image does not depend
    /// on it. The CLI sets it from `RAYSTREAM_GPU_WAVE` (an experiment: BENCHMARKS.md).
    pub fn set_render_wave(&mut self, samples: u32) -> Result<(), GpuError> {
        if !(1..=render::MAX_WAVE).contains(&samples) {
            return Err(GpuError::Wgpu(
                format!(
                    "a wave of {samples} samples: from 1 to {}",
                    render::MAX_WAVE
                ),
                self.info.name.clone(),
            ));
        }
        self.render_wave = samples;
        Ok(())
    }

    /// Whether the kd-tree kernels made after it (the ray queries, and the stream renderer of
    /// a scene without a volume) compile without wgpu's run-time checks: no clamping of array
    /// and vector indices, no counters bounding every loop, no guards on integer division.
    /// Unchecked by default: on the H200 that made the fused kernel 1.12-1.27x faster on
    /// every ray set, with the same hits (BENCHMARKS.md, 2026-12-04); on lavapipe no difference
    /// beyond its noise. Sound because every index these kernels form is guarded by the ray
    /// or queue count (queues are sized so that none can overflow), or comes from a tree and a
    /// scene whose links [`GpuTracer::new`] ([`KdTree::check_links`]) and
    /// [`render::GpuRenderer::new`] check before they upload them (children, ropes, entry
    /// cells and triangle ranges in bounds, axes below 3, descents that end; vertex, material,
    /// texture and primitive indices in bounds), and every loop is bounded by `max_steps`, a
    /// leaf's count, a light count or the tree's depth. The CLI's `RAYSTREAM_GPU_CHECKS=on`
    /// restores the checks.
    pub fn set_unchecked_kernels(&mut self, on: bool) {
        self.unchecked = on;
    }

    /// Turns the kernels' timestamps off (or on again, where the adapter has timestamp
    /// queries): a query's or frame's wall time then holds no timestamp writes, resolve or
    /// readback, and no kernel time is reported. The CLI's `RAYSTREAM_GPU_TIMESTAMPS=off`:
    /// device-bench.sh's floor part measures what the timestamps add to a query's wall time.
    pub fn set_timestamps(&mut self, on: bool) {
        self.timestamps = on;
    }

    /// Whether the stream renderers and split kernels made after it reserve their queues'
    /// slots a subgroup at a time (`shade_hits`: one atomic add a subgroup for its hit count,
    /// each light's shadow rays and the next depth's rays; the split kernels: one for the rays
    /// going on to the next leaf step; the lanes' slots by prefix sums) or a lane at a time
    /// (an atomic add for every ray, all on the same few counters). Subgroups only where the
    /// adapter has subgroup operations; the film and the hits are the same either way (they
    /// do not depend on the queues' order). The CLI's `RAYSTREAM_GPU_APPENDS=subgroup|atomic`.
    pub fn set_subgroup_appends(&mut self, on: bool) {
        self.subgroup_appends = on;
    }

    /// Whether the stream renderers and split kernels made after now reserve queue slots a
    /// subgroup at a time: asked for ([`GpuContext::set_subgroup_appends`]) and possible on
    /// this adapter.
    pub fn subgroup_appends(&self) -> bool {
        self.subgroup_appends && self.device.features().contains(wgpu::Features::SUBGROUP)
    }

    /// Whether the kd-tree kernels made after now compute a triangle's plane again in f64 where
    /// the f32 one cannot place it (a triangle far larger than its distance from the ray's
    /// origin, such as a huge ground quad: raystream-accel's `PLANE_T_LEVER`), as the CPU does,
    /// or in f32 as before. f64 only where the adapter has it (wgpu's SHADER_F64: Vulkan and
    /// DX12 on most GPUs, lavapipe; not Metal); the test takes that path for about 4 in 10⁵
    /// triangles of the standard ray sets, so the hits are otherwise the same. The CLI's
    /// `RAYSTREAM_GPU_PLANES=f64|f32` (f64 by default: f32 to measure what the path costs).
    pub fn set_f64_planes(&mut self, on: bool) {
        self.f64_planes = on;
    }

    /// Whether the kd-tree kernels made after now place huge triangles' planes in f64: asked
    /// for ([`GpuContext::set_f64_planes`]) and possible on this adapter.
    pub fn f64_planes(&self) -> bool {
        self.f64_planes && self.device.features().contains(wgpu::Features::SHADER_F64)
    }

    /// Whether the kd-tree kernels made after now compile without wgpu's run-time checks
    /// ([`GpuContext::set_unchecked_kernels`]).
    pub fn unchecked_kernels(&self) -> bool {
        self.unchecked
    }

    /// A kd-tree kernel module from WGSL `source`: without wgpu's run-time checks where
    /// [`GpuContext::set_unchecked_kernels`] asked and `volume` is false (a volume's marching
    /// loops end only by their floats, so they keep wgpu's loop bounds).
    fn tree_module(&self, label: &str, source: String, volume: bool) -> wgpu::ShaderModule {
        let source = self.tree_source(source);
        let desc = wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        };
        if self.unchecked && !volume {
            // SAFETY: the kernels' indices and loops are bounded as `set_unchecked_kernels`
            // says.
            unsafe {
                self.device
                    .create_shader_module_trusted(desc, wgpu::ShaderRuntimeChecks::unchecked())
            }
        } else {
            self.device.create_shader_module(desc)
        }
    }

    /// Kernel `source` (holding kdtree.wgsl) as this context compiles it: its planes in f64
    /// where [`GpuContext::f64_planes`].
    fn tree_source(&self, source: String) -> String {
        if self.f64_planes() {
            with_f64_planes(&source)
        } else {
            source
        }
    }

    /// Threads per workgroup of the ray-query kernels.
    pub fn query_workgroup(&self) -> u32 {
        self.query_workgroup
    }

    /// Whether the adapter is a software rasterizer (lavapipe, WARP, SwiftShader).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// "NAME (BACKEND, DRIVER)".
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {} {})",
            self.info.name, self.info.backend, self.info.driver, self.info.driver_info
        )
        .trim()
        .to_string()
    }

    fn err(&self, e: impl std::fmt::Display) -> GpuError {
        if let Some(l) = self.lost.lock().unwrap().clone() {
            return GpuError::Lost(self.info.name.clone(), l);
        }
        GpuError::Wgpu(e.to_string(), self.info.name.clone())
    }

    /// Waits for all submitted work, failing instead of hanging past `GPU_TIMEOUT`.
    ///
    /// With spinning waits ([`GpuContext::set_spin_wait`]) it first polls the fence (without
    /// blocking) for up to [`SPIN_WAIT`]: on the H200 (under gVisor) a blocking fence wait
    /// cost 0.03-0.21 ms more wake-up latency than polling, up to a third of a 2 M-ray query's
    /// wall time (BENCHMARKS.md, 2026-12-04).
    fn wait(&self) -> Result<(), GpuError> {
        self.wait_for(None)
    }

    /// Waits for submission `index` (and those before it), or with `None` for all submitted
    /// work, as [`GpuContext::wait`]; spinning waits only for all work.
    fn wait_for(&self, index: Option<wgpu::SubmissionIndex>) -> Result<(), GpuError> {
        if self.spin_wait && index.is_none() {
            let start = Instant::now();
            while start.elapsed() < SPIN_WAIT {
                let status = self
                    .device
                    .poll(wgpu::PollType::Poll)
                    .map_err(|e| self.err(format!("polling the GPU: {e}")))?;
                if status.is_queue_empty() {
                    return self.check_uncaptured();
                }
                std::hint::spin_loop();
            }
        }
        // A wait that fails because its submission did (an earlier error that no scope
        // caught made it invalid) reports that error, the cause.
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: index,
                timeout: Some(GPU_TIMEOUT),
            })
            .map_err(|e| {
                self.check_uncaptured()
                    .err()
                    .unwrap_or_else(|| self.err(format!("waiting for the GPU: {e}")))
            })?;
        self.check_uncaptured()
    }

    /// The GPU error that no error scope caught, if one came.
    fn check_uncaptured(&self) -> Result<(), GpuError> {
        match self.uncaptured.lock().unwrap().clone() {
            Some(e) => Err(self.err(format!("an earlier GPU error: {e}"))),
            None => Ok(()),
        }
    }

    /// Runs the work wgpu holds for the next submission (the copies of buffers created with
    /// contents, from their staging buffers) and zeroes `clear` (which wgpu would otherwise
    /// zero lazily before their first use), then waits: a submission timed after this holds
    /// its own work alone.
    fn settle(&self, clear: &[&wgpu::Buffer]) -> Result<(), GpuError> {
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("settle"),
            });
        for buf in clear {
            enc.clear_buffer(buf, 0, None);
        }
        self.queue.submit([enc.finish()]);
        self.wait()
    }

    /// Milliseconds from submitting an empty command buffer to seeing it done (once earlier
    /// work has settled): the floor under any one query's wall time on this adapter, driver
    /// and host.
    pub fn round_trip_ms(&self) -> Result<f64, GpuError> {
        self.settle(&[])?;
        let t0 = Instant::now();
        self.settle(&[])?;
        Ok(t0.elapsed().as_secs_f64() * 1e3)
    }

    /// A zeroed storage buffer of `size` bytes (copyable both ways, plus `extra` usages),
    /// refused with a clear error beyond what a kernel can bind.
    fn work_buffer(
        &self,
        what: &'static str,
        size: u64,
        extra: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        let limit = self.max_binding();
        if size > limit {
            return Err(GpuError::TooLarge {
                adapter: self.info.name.clone(),
                what,
                need: size,
                limit,
            });
        }
        self.allocate(what, size, || {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(what),
                size: size.max(64).next_multiple_of(4),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC
                    | extra,
                mapped_at_creation: false,
            })
        })
    }

    /// Runs `work` inside an error scope of wgpu's validation errors, and returns the error the
    /// scope caught, if it caught one, even where `work` failed too: an invalid pipeline,
    /// binding or dispatch is the cause, and what `work` saw of it (a submission that failed, a
    /// wait for it) only its consequence.
    fn scoped<T>(&self, work: impl FnOnce() -> Result<T, GpuError>) -> Result<T, GpuError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let result = work();
        match pollster::block_on(scope.pop()) {
            Some(e) => Err(self.err(e)),
            None => result,
        }
    }

    /// Makes `what`, a buffer of `size` bytes, with `make`; out of memory is an error naming it
    /// (wgpu would otherwise report it to no one in particular).
    fn allocate(
        &self,
        what: &'static str,
        size: u64,
        make: impl FnOnce() -> wgpu::Buffer,
    ) -> Result<wgpu::Buffer, GpuError> {
        let out_of_memory = || GpuError::OutOfMemory {
            adapter: self.info.name.clone(),
            what,
            need: size,
        };
        #[cfg(test)]
        {
            let mut fail = self.fail_alloc.lock().unwrap();
            if let Some(k) = fail.iter().position(|&(w, at)| w == what && size >= at) {
                fail.remove(k);
                return Err(out_of_memory());
            }
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let buf = make();
        match pollster::block_on(scope.pop()) {
            Some(_) => Err(out_of_memory()),
            None => Ok(buf),
        }
    }

    /// A timestamp query set of `count` entries, the buffer to resolve it into and a mappable
    /// copy, where the adapter has timestamp queries and they are on
    /// ([`GpuContext::set_timestamps`]).
    fn timer(&self, count: u32) -> Option<Timer> {
        (self.timestamps
            && self
                .device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY))
        .then(|| {
            let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("kernel timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count,
            });
            let buffer = |label, usage| {
                self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: count as u64 * 8,
                    usage,
                    mapped_at_creation: false,
                })
            };
            Timer {
                resolve: buffer(
                    "resolved timestamps",
                    wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                ),
                readback: buffer(
                    "timestamps readback",
                    wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                ),
                set,
                count,
            }
        })
    }

    /// The compute pipeline of `entry` in `module`, its bind group layouts derived from what the
    /// entry point uses.
    fn auto_pipeline(&self, module: &wgpu::ShaderModule, entry: &str) -> wgpu::ComputePipeline {
        self.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
    }

    /// A pipeline layout of bind groups `groups` (group i laid out as `groups[i]`).
    fn pipeline_layout(
        &self,
        label: &str,
        groups: &[&wgpu::BindGroupLayout],
    ) -> wgpu::PipelineLayout {
        let groups: Vec<_> = groups.iter().map(|&g| Some(g)).collect();
        self.device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &groups,
                immediate_size: 0,
            })
    }

    /// The compute pipeline of `entry` in `module` with `layout` (shared by kernels that bind
    /// the same groups) and its override `constants`.
    fn layout_pipeline(
        &self,
        module: &wgpu::ShaderModule,
        entry: &str,
        layout: &wgpu::PipelineLayout,
        constants: &[(&str, f64)],
    ) -> wgpu::ComputePipeline {
        self.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(layout),
                module,
                entry_point: Some(entry),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants,
                    ..Default::default()
                },
                cache: None,
            })
    }

    /// The bind group layout of a ray query's group 0, as [`GpuTracer`] binds it: the
    /// parameters (uniform), the tree's inner nodes, leaves, triangles and entry cells and the
    /// rays (read-only), the hits.
    fn query_layout(&self, label: &str) -> wgpu::BindGroupLayout {
        use wgpu::BufferBindingType::{Storage, Uniform};
        let ro = Storage { read_only: true };
        let rw = Storage { read_only: false };
        self.buffer_layout(label, &[Uniform, ro, ro, ro, ro, ro, rw])
    }

    /// Workgroups (x, y, 1) for `n` items of one thread each, as the kernels' dispatch-argument
    /// writers compute them.
    fn dims(&self, n: u32) -> [u32; 3] {
        self.dims_sized(n, WORKGROUP_SIZE)
    }

    /// [`GpuContext::dims`] for workgroups of `workgroup` threads.
    fn dims_sized(&self, n: u32, workgroup: u32) -> [u32; 3] {
        let groups = n.div_ceil(workgroup);
        let gx = groups.min(self.limits.max_compute_workgroups_per_dimension.max(1));
        let gy = if gx == 0 { 0 } else { groups.div_ceil(gx) };
        [gx, gy, 1]
    }

    /// A compute bind group layout of buffers, binding i of type `types[i]`.
    fn buffer_layout(
        &self,
        label: &str,
        types: &[wgpu::BufferBindingType],
    ) -> wgpu::BindGroupLayout {
        let entries: Vec<_> = types
            .iter()
            .enumerate()
            .map(|(i, &ty)| wgpu::BindGroupLayoutEntry {
                binding: i as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        self.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &entries,
            })
    }

    /// A bind group of whole buffers, binding i = `buffers[i]`.
    fn bind_buffers(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let entries: Vec<_> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        })
    }

    /// The largest buffer a kernel can bind.
    fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    fn storage(
        &self,
        what: &'static str,
        bytes: &[u8],
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        let need = bytes.len().max(64) as u64;
        let limit = self.max_binding();
        if need > limit {
            return Err(GpuError::TooLarge {
                adapter: self.info.name.clone(),
                what,
                need,
                limit,
            });
        }
        let contents: Vec<u8>;
        let bytes = if bytes.is_empty() {
            // Bindings may not be empty: one zeroed element of the largest struct stands in.
            contents = vec![0u8; 64];
            &contents[..]
        } else {
            bytes
        };
        self.allocate(what, bytes.len() as u64, || {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(what),
                    contents: bytes,
                    usage: wgpu::BufferUsages::STORAGE | usage,
                })
        })
    }
}

/// The kd-tree on the GPU, with the intersection pipelines.
pub struct GpuTracer<'a> {
    ctx: &'a GpuContext,
    inners: wgpu::Buffer,
    leaves: wgpu::Buffer,
    tris: wgpu::Buffer,
    /// The entry grid's cells (`KdTree::entry`).
    entry: wgpu::Buffer,
    params: Params,
    closest: wgpu::ComputePipeline,
    any: wgpu::ComputePipeline,
    split: std::sync::OnceLock<split::SplitKernels>,
    /// The persistent-thread kernels (closest, any), built on first use.
    persistent: std::sync::OnceLock<[wgpu::ComputePipeline; 2]>,
    /// The "if-if" kernels (closest, any), built on first use.
    ifif: std::sync::OnceLock<[wgpu::ComputePipeline; 2]>,
    /// The floor kernel ([`Kernels::Floor`]), built on first use.
    floor: std::sync::OnceLock<wgpu::ComputePipeline>,
    /// The statistics query's kernels (closest, any; then the same as "if-if"), built on
    /// first use.
    stats: std::sync::OnceLock<[wgpu::ComputePipeline; 4]>,
    /// `queries.wgsl`, for the pipelines built on first use.
    module: wgpu::ShaderModule,
    /// The most rays one query binds: its rays (32 bytes each, its largest buffer) must fit in
    /// a storage binding (128 MiB on lavapipe, 2 GiB on an H100); more are traced in chunks.
    max_rays: usize,
    /// One past the largest primitive id in the tree (0 for none): the renderer indexes its
    /// per-triangle arrays with the hits' ids.
    prims: u64,
    /// Milliseconds spent uploading the tree.
    pub upload_ms: f64,
}

/// How a ray query runs on the GPU.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernels {
    /// One kernel per query: descend, intersect, follow the rope, in one loop per ray.
    #[default]
    Fused,
    /// The paper's layout: a traversal kernel writes (ray, leaf) work items, an intersection
    /// kernel consumes them and sends unfinished rays back, one leaf step per dispatch pair.
    Split,
    /// The fused loop in persistent threads (Aila & Laine 2009): a fixed grid of
    /// [`PERSISTENT_GROUPS`] workgroups whose threads fetch rays from a global counter.
    Persistent,
    /// The fused query as Aila & Laine's "if-if" loop: each iteration a thread takes at most
    /// one traversal step and one triangle step, so threads in different phases share
    /// iterations (the fused kernel runs "while-while": all inner steps, then all triangles).
    IfIf,
    /// No traversal: each thread reads its ray and writes a miss, so its hits are all misses.
    /// A diagnostic, not a query: its wall, kernel and streamed times are the floor under every
    /// query kernel's on the same rays (the dispatch over their grid, their memory traffic and
    /// the host's round trip); what a query takes beyond them is the traversal's.
    Floor,
}

/// The work of a fused query, counted on the GPU by the statistics kernels (`stats.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct QueryStats {
    pub rays: u64,
    /// Inner-node steps, leaf visits and triangle tests, summed over the rays.
    pub steps: [u64; 3],
    /// Triangles listed in the visited leaves (the CPU's `Counters::triangles`; `steps[2]`
    /// is smaller where any-hit queries stop inside a leaf).
    pub listed: u64,
    /// Per kind of step: the lanes that took part, summed over every step a subgroup took…
    pub active_lanes: [u64; 3],
    /// …and the lanes those steps could have used (the subgroup size, summed likewise).
    pub lane_slots: [u64; 3],
    /// The most invocations the GPU ran at once, between their entry into the kernel and
    /// their exit: the peak of achieved occupancy, in threads (divide by the GPU's thread
    /// slots, e.g. an H100's 132 SMs × 2048, for the fraction).
    pub peak_resident: u64,
    /// The subgroup (warp, wave) size the kernel ran with.
    pub subgroup_size: u32,
}

impl QueryStats {
    /// Inner steps, leaf steps and triangle tests: SIMD efficiency, the share of a subgroup's
    /// lanes busy in its steps of that kind (1 = no divergence).
    pub const KINDS: [&'static str; 3] = ["traversal", "leaf", "triangle"];

    /// The SIMD efficiency of steps of kind `k` (see [`QueryStats::KINDS`]).
    pub fn simd_efficiency(&self, k: usize) -> f64 {
        self.active_lanes[k] as f64 / self.lane_slots[k].max(1) as f64
    }

    /// Mean steps of kind `k` per ray.
    pub fn per_ray(&self, k: usize) -> f64 {
        self.steps[k] as f64 / self.rays.max(1) as f64
    }

    /// [`QueryStats::peak_resident`] in subgroups (warps).
    pub fn peak_resident_subgroups(&self) -> f64 {
        self.peak_resident as f64 / self.subgroup_size.max(1) as f64
    }
}

/// Rays per statistics dispatch: a whole 1920×1080 set in one (the counters of `stats.wgsl`
/// are 64-bit), so that the residency peak is that of a GPU filled as the timed kernel fills
/// it; larger sets (or more than a query binds) run in batches.
const STATS_BATCH: usize = 1 << 22;

/// Words of `stats.wgsl`'s counter buffer: ten 64-bit counters (a low and a high word each),
/// then LIVE (invocations inside the kernel now), PEAK (the most LIVE reached) and LANES (the
/// subgroup size), at these indices (the kernel gets them from its prelude).
const STATS_WORDS: usize = 23;
const STATS_LIVE: usize = 20;
const STATS_PEAK: usize = 21;
const STATS_LANES: usize = 22;

/// Workgroups of the persistent kernels: 4096 × 64 threads, about what an H100's 132 SMs hold
/// at once (2048 threads each); fewer when there are fewer rays.
pub const PERSISTENT_GROUPS: u32 = 4096;

/// One query's buffers, bind group and grid, ready to dispatch.
struct Query<'p> {
    ray_buf: wgpu::Buffer,
    hit_buf: wgpu::Buffer,
    hit_bytes: u64,
    param_buf: wgpu::Buffer,
    /// Binding 7, where the kernel has one: the persistent kernels' ray counter, the
    /// statistics query's counters.
    slot7: Option<wgpu::Buffer>,
    bind: wgpu::BindGroup,
    pipeline: &'p wgpu::ComputePipeline,
    label: &'static str,
    dims: [u32; 3],
}

/// Timings of one [`GpuTracer::trace`] call, milliseconds.
#[derive(Clone, Copy, Debug, Default)]
pub struct TraceTimes {
    pub upload_ms: f64,
    pub kernel_ms: f64,
    pub readback_ms: f64,
    /// The kernels' own time between their passes' timestamps, where the adapter has timestamp
    /// queries: the figure to compare kernels by.
    pub kernel_gpu_ms: Option<f64>,
    /// Split kernels: leaf steps (traverse/intersect dispatch pairs) run.
    pub split_steps: Option<u32>,
}

impl<'a> GpuTracer<'a> {
    /// The context the tracer runs in.
    pub fn context(&self) -> &'a GpuContext {
        self.ctx
    }

    /// Uploads `tree` and builds the query kernels; refuses a tree whose links
    /// ([`KdTree::check_links`]) would lead a kernel out of its arrays.
    pub fn new(ctx: &'a GpuContext, tree: &KdTree) -> Result<GpuTracer<'a>, GpuError> {
        let t0 = Instant::now();
        tree.check_links()
            .map_err(|e| ctx.err(format!("the kd-tree's links are broken: {e}")))?;
        let prims = tree
            .tris
            .iter()
            .map(|t| t.prim() as u64 + 1)
            .max()
            .unwrap_or(0);
        let b = tree.bounds;
        let g = &tree.entry;
        let params = Params {
            ray_count: 0,
            root: tree.root,
            max_steps: (tree.leaves.len() + tree.inners.len() + 1).min(u32::MAX as usize) as u32,
            tri_count: tree.tris.len() as u32,
            scene_min: b.min.to_array(),
            entry_margin: g.margin,
            scene_max: b.max.to_array(),
            entry_reach: g.reach,
            entry_scale: [g.scale[0], g.scale[1], g.scale[2], 0.0],
            entry_res: [g.res[0], g.res[1], g.res[2], 0],
        };
        let upload = |what, bytes: &[u8]| ctx.storage(what, bytes, wgpu::BufferUsages::empty());
        ctx.scoped(|| {
            let inners = upload("kd inner nodes", bytemuck::cast_slice(&tree.inners))?;
            let leaves = upload("kd leaves", bytemuck::cast_slice(&tree.leaves))?;
            let tris = upload("kd triangles", bytemuck::cast_slice(&tree.tris))?;
            let entry = upload("kd entry grid", bytemuck::cast_slice(&tree.entry.cells))?;
            let module = ctx.tree_module(
                "queries.wgsl",
                queries_wgsl_sized(ctx.query_workgroup),
                false,
            );
            let closest = ctx.auto_pipeline(&module, "intersect_closest");
            let any = ctx.auto_pipeline(&module, "intersect_any");
            ctx.wait()?;
            Ok(GpuTracer {
                ctx,
                inners,
                leaves,
                tris,
                entry,
                params,
                closest,
                any,
                split: std::sync::OnceLock::new(),
                persistent: std::sync::OnceLock::new(),
                ifif: std::sync::OnceLock::new(),
                floor: std::sync::OnceLock::new(),
                stats: std::sync::OnceLock::new(),
                module,
                max_rays: (ctx.max_binding() / std::mem::size_of::<GpuRay>() as u64).max(1)
                    as usize,
                prims,
                upload_ms: t0.elapsed().as_secs_f64() * 1e3,
            })
        })
    }

    /// The tree as bind group 0 of the render kernels (`layout`: params, inners, leaves, tris,
    /// entry cells).
    fn bind_tree(&self, layout: &wgpu::BindGroupLayout) -> wgpu::BindGroup {
        let params = self
            .ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("kd-tree params"),
                contents: bytemuck::bytes_of(&self.params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        self.ctx.bind_buffers(
            "kd-tree",
            layout,
            &[&params, &self.inners, &self.leaves, &self.tris, &self.entry],
        )
    }

    /// The query kernels' uniform parameters for a queue of `ray_count` rays.
    fn params_buffer(&self, ray_count: u32) -> wgpu::Buffer {
        let params = Params {
            ray_count,
            ..self.params
        };
        self.ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    fn ifif_kernels(&self) -> &[wgpu::ComputePipeline; 2] {
        self.ifif.get_or_init(|| {
            ["intersect_closest_ifif", "intersect_any_ifif"]
                .map(|entry| self.ctx.auto_pipeline(&self.module, entry))
        })
    }

    /// `query_floor`, laid out as the query kernels (it reads no tree, but binds a query's
    /// buffers).
    fn floor_kernel(&self) -> &wgpu::ComputePipeline {
        self.floor.get_or_init(|| {
            let ctx = self.ctx;
            let layout = ctx.pipeline_layout("query_floor", &[&ctx.query_layout("query_floor")]);
            ctx.layout_pipeline(&self.module, "query_floor", &layout, &[])
        })
    }

    fn persistent_kernels(&self) -> &[wgpu::ComputePipeline; 2] {
        self.persistent.get_or_init(|| {
            ["intersect_closest_persistent", "intersect_any_persistent"]
                .map(|entry| self.ctx.auto_pipeline(&self.module, entry))
        })
    }

    /// The fused query's work and SIMD efficiency on these rays, counted on the GPU (the hits
    /// are the fused kernel's); `None` where the device has no subgroup operations.
    pub fn query_stats(&self, rays: &[Ray], any: bool) -> Result<Option<QueryStats>, GpuError> {
        self.query_stats_with(rays, any, Kernels::Fused)
    }

    /// As [`GpuTracer::query_stats`] for the fused or the "if-if" loop; `None` for the other
    /// layouts too.
    pub fn query_stats_with(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
    ) -> Result<Option<QueryStats>, GpuError> {
        let ctx = self.ctx;
        let ifif = match kernels {
            Kernels::Fused => false,
            Kernels::IfIf => true,
            Kernels::Split | Kernels::Persistent | Kernels::Floor => return Ok(None),
        };
        if !ctx.device.features().contains(wgpu::Features::SUBGROUP) {
            return Ok(None);
        }
        ctx.scoped(|| {
            let pipeline = &self.stats.get_or_init(|| {
                let module = ctx
                    .device
                    .create_shader_module(wgpu::ShaderModuleDescriptor {
                        label: Some("stats.wgsl"),
                        source: wgpu::ShaderSource::Wgsl(ctx.tree_source(stats_wgsl()).into()),
                    });
                [
                    "stats_closest",
                    "stats_any",
                    "stats_closest_ifif",
                    "stats_any_ifif",
                ]
                .map(|entry| ctx.auto_pipeline(&module, entry))
            })[2 * ifif as usize + any as usize];
            let mut total = QueryStats {
                rays: rays.len() as u64,
                ..QueryStats::default()
            };
            for batch in rays.chunks(STATS_BATCH.min(self.max_rays)) {
                let stats_buf = ctx.work_buffer(
                    "query statistics",
                    4 * STATS_WORDS as u64,
                    wgpu::BufferUsages::empty(),
                )?;
                let dims = ctx.dims(batch.len() as u32);
                let q =
                    self.bind_query(batch, pipeline, "query statistics", dims, Some(stats_buf))?;
                self.run_fused(&q, None)?;
                let stats_buf = q.slot7.as_ref().expect("bound above");
                let w = read_words(ctx, stats_buf)?;
                let counter = |k: usize| u64_at(&w, k);
                for k in 0..3 {
                    total.steps[k] += counter(k);
                    total.active_lanes[k] += counter(4 + k);
                    total.lane_slots[k] += counter(7 + k);
                }
                total.listed += counter(3);
                // Every invocation that entered has left: the residency count balances.
                if w[STATS_LIVE] != 0 {
                    return Err(ctx.err(format!(
                        "the statistics query's residency count ended at {} instead of 0",
                        w[STATS_LIVE] as i32
                    )));
                }
                total.peak_resident = total.peak_resident.max(w[STATS_PEAK] as u64);
                total.subgroup_size = total.subgroup_size.max(w[STATS_LANES]);
            }
            Ok(Some(total))
        })
    }

    fn split_kernels(&self) -> &split::SplitKernels {
        self.split
            .get_or_init(|| split::SplitKernels::new(self.ctx))
    }

    /// Traces every ray (closest hit, or any hit with `any`) with the fused kernel, returning
    /// one record per ray.
    pub fn trace(&self, rays: &[Ray], any: bool) -> Result<(Vec<GpuHit>, TraceTimes), GpuError> {
        self.trace_with(rays, any, Kernels::Fused)
    }

    /// The buffers, bind group and grid of one query of `rays` with `kernels`.
    fn query(&self, rays: &[Ray], any: bool, kernels: Kernels) -> Result<Query<'_>, GpuError> {
        let ctx = self.ctx;
        let (pipeline, label) = match (kernels, any) {
            (Kernels::Persistent, _) => (
                &self.persistent_kernels()[any as usize],
                ["intersect_closest_persistent", "intersect_any_persistent"][any as usize],
            ),
            (Kernels::IfIf, _) => (
                &self.ifif_kernels()[any as usize],
                ["intersect_closest_ifif", "intersect_any_ifif"][any as usize],
            ),
            (Kernels::Floor, _) => (self.floor_kernel(), "query_floor"),
            (_, true) => (&self.any, "intersect_any"),
            (_, false) => (&self.closest, "intersect_closest"),
        };
        let n = rays.len() as u32;
        if kernels == Kernels::Persistent {
            // The persistent kernels' ray counter, from 0 (cleared between streamed queries).
            let next_ray = ctx.storage("next ray", &[0u8; 4], wgpu::BufferUsages::COPY_DST)?;
            let dims = [
                n.div_ceil(ctx.query_workgroup)
                    .min(PERSISTENT_GROUPS * WORKGROUP_SIZE / ctx.query_workgroup),
                1,
                1,
            ];
            self.bind_query(rays, pipeline, label, dims, Some(next_ray))
        } else {
            let dims = ctx.dims_sized(n, ctx.query_workgroup);
            self.bind_query(rays, pipeline, label, dims, None)
        }
    }

    /// The rays and hit buffers of a query of `rays` by `pipeline` over `dims` workgroups,
    /// bound with the tree (bindings 0-4), the rays (5), the hits (6) and `slot7` at binding 7
    /// where the kernel has one (the persistent kernels' ray counter, the statistics query's
    /// counters).
    fn bind_query<'p>(
        &self,
        rays: &[Ray],
        pipeline: &'p wgpu::ComputePipeline,
        label: &'static str,
        dims: [u32; 3],
        slot7: Option<wgpu::Buffer>,
    ) -> Result<Query<'p>, GpuError> {
        let ctx = self.ctx;
        let n = rays.len();
        let gpu_rays: Vec<GpuRay> = rays.iter().map(GpuRay::from).collect();
        let ray_buf = ctx.storage(
            "rays",
            bytemuck::cast_slice(&gpu_rays),
            wgpu::BufferUsages::empty(),
        )?;
        let hit_bytes = (n * std::mem::size_of::<GpuHit>()) as u64;
        let limit = ctx.max_binding();
        if hit_bytes > limit {
            return Err(GpuError::TooLarge {
                adapter: ctx.info.name.clone(),
                what: "hits",
                need: hit_bytes,
                limit,
            });
        }
        // Exactly one record a ray (readbacks take the whole buffer).
        let hit_buf = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hits"),
            size: hit_bytes,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let param_buf = self.params_buffer(n as u32);
        let mut buffers = vec![
            &param_buf,
            &self.inners,
            &self.leaves,
            &self.tris,
            &self.entry,
            &ray_buf,
            &hit_buf,
        ];
        buffers.extend(&slot7);
        let bind = ctx.bind_buffers(label, &pipeline.get_bind_group_layout(0), &buffers);
        Ok(Query {
            ray_buf,
            hit_buf,
            hit_bytes,
            param_buf,
            slot7,
            bind,
            pipeline,
            label,
            dims,
        })
    }

    /// Traces more rays than one query can bind, `chunk` at a time: the hits of all, the times
    /// summed.
    fn trace_chunked(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
        chunk: usize,
        timed: bool,
    ) -> Result<(Vec<GpuHit>, TraceTimes), GpuError> {
        let mut hits = Vec::with_capacity(rays.len());
        let mut total = TraceTimes::default();
        // A sum of optional figures: known only where every chunk knows it.
        fn add<T: std::ops::Add<Output = T>>(
            first: bool,
            sum: Option<T>,
            x: Option<T>,
        ) -> Option<T> {
            if first {
                x
            } else {
                sum.zip(x).map(|(a, b)| a + b)
            }
        }
        for (k, part) in rays.chunks(chunk).enumerate() {
            let (h, t) = self.trace_run(part, any, kernels, timed)?;
            hits.extend(h);
            total.upload_ms += t.upload_ms;
            total.kernel_ms += t.kernel_ms;
            total.readback_ms += t.readback_ms;
            total.kernel_gpu_ms = add(k == 0, total.kernel_gpu_ms, t.kernel_gpu_ms);
            total.split_steps = add(k == 0, total.split_steps, t.split_steps);
        }
        Ok((hits, total))
    }

    /// Milliseconds of wall time per query when `runs` queries of these rays are queued in
    /// one submission and waited for once: the throughput of a stream of queries, with no host
    /// round trip between them (each still waits for the one before), and the last query's
    /// hits (the hit buffer is cleared before it, within the stream, so that they are its
    /// own). `None` for the split kernels, which the host drives step by step, and for more
    /// rays than one query binds.
    pub fn trace_streamed(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
        runs: u32,
    ) -> Result<Option<(Vec<GpuHit>, f64)>, GpuError> {
        let ctx = self.ctx;
        if kernels == Kernels::Split || rays.is_empty() || runs == 0 || rays.len() > self.max_rays {
            return Ok(None);
        }
        ctx.scoped(|| {
            let q = self.query(rays, any, kernels)?;
            ctx.settle(&[&q.hit_buf])?;
            let t0 = Instant::now();
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("streamed queries"),
                });
            for run in 0..runs {
                // The persistent kernels' ray counter restarts for each query.
                if let Some(next_ray) = &q.slot7 {
                    enc.clear_buffer(next_ray, 0, None);
                }
                if run + 1 == runs {
                    enc.clear_buffer(&q.hit_buf, 0, None);
                }
                record_pass(&mut enc, &q, None);
            }
            ctx.queue.submit([enc.finish()]);
            ctx.wait()?;
            let ms = t0.elapsed().as_secs_f64() * 1e3 / runs as f64;
            let hits = read_back(ctx, &q.hit_buf)?;
            Ok(Some((hits, ms)))
        })
    }

    /// As [`GpuTracer::trace`], with the fused or the split kernels (same hits).
    pub fn trace_with(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
    ) -> Result<(Vec<GpuHit>, TraceTimes), GpuError> {
        self.trace_run(rays, any, kernels, true)
    }

    /// As [`GpuTracer::trace_with`] with no timestamp queries (no `kernel_gpu_ms`; the split
    /// kernels keep theirs): the wall time of a query as a program that does not time its
    /// kernels sees it, without the timestamps' writes, resolve and readback.
    pub fn trace_untimed(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
    ) -> Result<(Vec<GpuHit>, TraceTimes), GpuError> {
        self.trace_run(rays, any, kernels, false)
    }

    /// A query, its kernel timed where `timed` and the adapter can.
    fn trace_run(
        &self,
        rays: &[Ray],
        any: bool,
        kernels: Kernels,
        timed: bool,
    ) -> Result<(Vec<GpuHit>, TraceTimes), GpuError> {
        let ctx = self.ctx;
        let n = rays.len();
        if n == 0 {
            return Ok((Vec::new(), TraceTimes::default()));
        }
        let chunk = self.max_rays;
        if n > chunk {
            return self.trace_chunked(rays, any, kernels, chunk, timed);
        }
        let t0 = Instant::now();
        ctx.scoped(|| {
            let q = self.query(rays, any, kernels)?;
            let Query {
                ref ray_buf,
                ref hit_buf,
                hit_bytes,
                ref param_buf,
                ..
            } = q;
            let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hits readback"),
                size: hit_bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let timer = if timed { ctx.timer(2) } else { None };
            // The rays' copy and the hits' zeroing are the upload's, not the timed query's.
            ctx.settle(&[hit_buf])?;
            let upload_ms = t0.elapsed().as_secs_f64() * 1e3;

            // Submission to completion: one round trip (the timestamps travel back with it).
            let t1 = Instant::now();
            let (kernel_gpu_ms, split_steps) = match kernels {
                Kernels::Fused | Kernels::IfIf | Kernels::Persistent | Kernels::Floor => {
                    (self.run_fused(&q, timer.as_ref())?, None)
                }
                Kernels::Split => {
                    let r = split::run(self, param_buf, ray_buf, hit_buf, n as u32, any)?;
                    (r.kernel_gpu_ms, Some(r.steps))
                }
            };
            ctx.wait()?;
            let kernel_ms = t1.elapsed().as_secs_f64() * 1e3;

            let t2 = Instant::now();
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("readback"),
                });
            enc.copy_buffer_to_buffer(hit_buf, 0, &readback, 0, hit_bytes);
            ctx.queue.submit([enc.finish()]);
            let hits: Vec<GpuHit> = read_back(ctx, &readback)?;
            let readback_ms = t2.elapsed().as_secs_f64() * 1e3;
            Ok((
                hits,
                TraceTimes {
                    upload_ms,
                    kernel_ms,
                    readback_ms,
                    kernel_gpu_ms,
                    split_steps,
                },
            ))
        })
    }

    /// One dispatch of a query's kernel; its own time where timestamps exist.
    fn run_fused(&self, q: &Query, timer: Option<&Timer>) -> Result<Option<f64>, GpuError> {
        let ctx = self.ctx;
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("trace"),
            });
        record_pass(&mut enc, q, timer);
        if let Some(t) = timer {
            t.resolve(&mut enc);
        }
        ctx.queue.submit([enc.finish()]);
        match timer {
            Some(t) => read_elapsed_ms(ctx, t),
            None => ctx.wait().map(|_| None),
        }
    }
}

/// Records a query's dispatch as one compute pass, between `timer`'s two stamps where given.
fn record_pass(enc: &mut wgpu::CommandEncoder, q: &Query, timer: Option<&Timer>) {
    let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(q.label),
        timestamp_writes: timer.map(|t| t.writes(Some(0), Some(1))),
    });
    pass.set_pipeline(q.pipeline);
    pass.set_bind_group(0, &q.bind, &[]);
    let [gx, gy, gz] = q.dims;
    pass.dispatch_workgroups(gx, gy, gz);
}

/// A frame's pixels as the renderers read them back: linear floats (the reference's form) or
/// 8-bit sRGB, 3 bytes a pixel (converted on the GPU).
enum Pixels {
    Linear(raystream_cpu::Image),
    Srgb8(Vec<u8>),
    /// Left on the GPU, in the buffer the caller named.
    OnGpu,
}

impl Pixels {
    fn into_linear(self) -> raystream_cpu::Image {
        match self {
            Pixels::Linear(image) => image,
            _ => unreachable!("asked for linear pixels"),
        }
    }

    fn into_srgb8(self) -> Vec<u8> {
        match self {
            Pixels::Srgb8(rgb) => rgb,
            _ => unreachable!("asked for sRGB pixels"),
        }
    }
}

/// Timestamp queries of kernel passes. `resolve` resolves them and copies them to `readback` in
/// the encoder of the work they time, so reading them back costs no second round trip.
struct Timer {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    readback: wgpu::Buffer,
    count: u32,
}

impl Timer {
    /// Timestamps `begin` and `end` around one pass.
    fn writes(&self, begin: Option<u32>, end: Option<u32>) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: begin,
            end_of_pass_write_index: end,
        }
    }

    fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        enc.resolve_query_set(&self.set, 0..self.count, &self.resolve, 0);
        enc.copy_buffer_to_buffer(&self.resolve, 0, &self.readback, 0, self.count as u64 * 8);
    }
}

/// The 64-bit value `k` of `words`: words 2k (low) and 2k + 1 (high), as the kernels' 64-bit
/// counters and resolved timestamps lie.
pub(crate) fn u64_at(words: &[u32], k: usize) -> u64 {
    words[2 * k] as u64 | (words[2 * k + 1] as u64) << 32
}

/// Milliseconds between the first two timestamps of `timer`, once its submission is done;
/// `None` where the adapter wrote equal stamps: no measurement rather than a false 0.
fn read_elapsed_ms(ctx: &GpuContext, timer: &Timer) -> Result<Option<f64>, GpuError> {
    let w = read_words(ctx, &timer.readback)?;
    let ticks = u64_at(&w, 1).wrapping_sub(u64_at(&w, 0));
    let ms = ticks as f64 * ctx.queue.get_timestamp_period() as f64 * 1e-6;
    Ok((ms > 0.0).then_some(ms))
}

/// Waits for the GPU and reads a whole buffer as u32 words (through a staging copy unless `buf`
/// is mappable).
fn read_words(ctx: &GpuContext, buf: &wgpu::Buffer) -> Result<Vec<u32>, GpuError> {
    read_back(ctx, buf)
}

/// Waits for the GPU and reads a whole buffer as `T`s (through a staging copy unless `buf` is
/// mappable).
fn read_back<T: bytemuck::Pod>(ctx: &GpuContext, buf: &wgpu::Buffer) -> Result<Vec<T>, GpuError> {
    read_back_after(ctx, buf, None)
}

/// Reads a whole buffer as `T`s once submission `index` is done (`None`: all submitted work),
/// through a staging copy unless `buf` is mappable; work submitted after `index` may still run.
fn read_back_after<T: bytemuck::Pod>(
    ctx: &GpuContext,
    buf: &wgpu::Buffer,
    index: Option<wgpu::SubmissionIndex>,
) -> Result<Vec<T>, GpuError> {
    let mut index = index;
    let staging;
    let src = if buf.usage().contains(wgpu::BufferUsages::MAP_READ) {
        buf
    } else {
        staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: buf.size(),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        enc.copy_buffer_to_buffer(buf, 0, &staging, 0, buf.size());
        let copied = ctx.queue.submit([enc.finish()]);
        // Waiting for the copy waits for `index` too; `None` keeps waiting for all work (and
        // spinning where asked).
        index = index.map(|_| copied);
        &staging
    };
    let slice = src.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.wait_for(index)?;
    let mapped = match rx.try_recv() {
        Ok(r) => r,
        // Not mapped yet (`buf` was in a later submission than `index`): wait for everything
        // rather than for a callback that might not come.
        Err(_) => {
            ctx.wait()?;
            rx.recv().map_err(|e| ctx.err(e))?
        }
    };
    mapped.map_err(|e| ctx.err(e))?;
    let view = slice.get_mapped_range().map_err(|e| ctx.err(e))?;
    let words = bytemuck::cast_slice(&view[..]).to_vec();
    drop(view);
    src.unmap();
    Ok(words)
}

#[cfg(test)]
mod tests;
