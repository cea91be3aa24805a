//! Direct volume rendering on the GPU (`kernels/dvr.wgsl`): the CT volume as an R16Float 3D
//! texture of HU with hardware trilinear filtering (and the interpolating cubic B-spline's
//! coefficients beside the HU in a second, two-channel one, when a frame reads them), the transfer function's control points and
//! the CPU's brick table in storage buffers, one thread per pixel. The CPU path
//! (`raystream_cpu::dvr`) is the reference; the tests hold the two together.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use raystream_cpu::Image;
use raystream_cpu::cinematic::{
    ALPHA_MAX, GUIDE_MIN_COVERAGE, GUIDE_SUBPIXELS, GUIDE_TRANSMITTANCE_END, KEY_IRRADIANCE,
    MAJORANT_CELL, Majorants, SKY_RADIANCE,
};
use raystream_cpu::denoise::{DenoiseOptions, DenoiseTimes, Guides, NoisyFilm};
use raystream_cpu::dvr::{
    BRICK, DvrMode, DvrOptions, ISO_COLOUR, Interpolation, KEPT_WEIGHT, LightGrid, Marcher, Sight,
    SplineGrids, brick_table, kept_brick_table, over_background, scene_to_lps,
};
use raystream_cpu::segments::SegmentColours;
use raystream_io::Volume;
use raystream_math::Vec3;
use raystream_scene::Camera;
use raystream_volume::TransferFunction;
use wgpu::util::DeviceExt;

use crate::denoise::DenoiseBuffers;
use crate::layout::{DvrParams, GpuCprRow};
use crate::render::COMMON_WGSL;
use crate::{
    GpuContext, GpuDenoiser, GpuError, Pixels, Timer, read_back, read_elapsed_ms, read_words,
};

const DVR_WGSL: &str = include_str!("kernels/dvr.wgsl");
const VOLUME_WGSL: &str = include_str!("kernels/volume.wgsl");
const CINEMATIC_WGSL: &str = include_str!("kernels/cinematic.wgsl");

/// The volume core (`kernels/volume.wgsl`) that the volume kernels and the render kernels'
/// volume stages share, with its constants (cinematic mode's from `raystream_cpu::cinematic`).
pub(crate) fn volume_core_wgsl() -> String {
    format!(
        "const BRICK_SIZE: u32 = {BRICK}u;\nconst MAJORANT_CELL: u32 = {MAJORANT_CELL}u;\nconst ALPHA_MAX: f32 = {ALPHA_MAX:?};\nconst KEY_IRRADIANCE: f32 = {KEY_IRRADIANCE:?};\nconst SKY_RADIANCE: f32 = {SKY_RADIANCE:?};\nconst GUIDE_SUBPIXELS: u32 = {GUIDE_SUBPIXELS}u;\nconst GUIDE_TRANSMITTANCE_END: f32 = {GUIDE_TRANSMITTANCE_END:?};\nconst GUIDE_MIN_COVERAGE: f32 = {GUIDE_MIN_COVERAGE:?};\n\n{VOLUME_WGSL}"
    )
}

/// The WGSL source of the volume kernel.
pub fn dvr_wgsl() -> String {
    let [r, g, b] = ISO_COLOUR.to_array();
    format!(
        "{}\nconst ISO_COLOUR: vec3<f32> = vec3<f32>({r:?}, {g:?}, {b:?});\nconst KEPT_WEIGHT: f32 = {KEPT_WEIGHT:?};\n{COMMON_WGSL}\n{DVR_WGSL}\n{CINEMATIC_WGSL}",
        volume_core_wgsl()
    )
}

/// A volume and its transfer function on the GPU: the HU texture with its trilinear sampler
/// and the transfer function's control points. Direct volume rendering and the render kernels'
/// volume stages bind the same, each with the brick table of how it reads the volume
/// ([`brick_buffer`]).
pub(crate) struct GpuVolume {
    pub view: wgpu::TextureView,
    pub sampler: wgpu::Sampler,
    pub opacity: wgpu::Buffer,
    pub color: wgpu::Buffer,
    pub brick_dims: [u32; 3],
    /// World → continuous index (rows and origin), from the marcher.
    pub to_index: ([Vec3; 3], Vec3),
}

/// The texture the kernels read a volume of `dims` from: `grid`, the values it is read by
/// (its HU, or the interpolating spline's coefficients: [`Marcher::grid`]), as R16Float, or
/// with `second` as Rg16Float with `second` in the second channel: the voxels whose spline's
/// gradient shades the interpolating spline ([`shading_channel`]), or a volume kept to
/// segments' weights as the same interpolation reads them (dvr.wgsl's `sample_kept`).
pub(crate) fn volume_texture(
    ctx: &GpuContext,
    label: &str,
    dims: [usize; 3],
    grid: &[f32],
    second: Option<&[f32]>,
) -> Result<wgpu::TextureView, GpuError> {
    let max = ctx.limits.max_texture_dimension_3d as usize;
    if dims.iter().any(|&n| n > max) {
        return Err(ctx.err(format!(
            "a {}x{}x{} volume exceeds the adapter's 3D texture limit of {max} per side",
            dims[0], dims[1], dims[2]
        )));
    }
    let size = wgpu::Extent3d {
        width: dims[0] as u32,
        height: dims[1] as u32,
        depth_or_array_layers: dims[2] as u32,
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: if second.is_some() {
            wgpu::TextureFormat::Rg16Float
        } else {
            wgpu::TextureFormat::R16Float
        },
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let half = |v: f32| half::f16::from_f32(v).to_bits();
    let halves: Vec<u16> = match second {
        None => grid.iter().map(|&v| half(v)).collect(),
        Some(second) => grid
            .iter()
            .zip(second)
            .flat_map(|(&v, &s)| [half(v), half(s)])
            .collect(),
    };
    let channels = 1 + second.is_some() as u32;
    ctx.queue.write_texture(
        texture.as_image_copy(),
        bytemuck::cast_slice(&halves),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(2 * channels * size.width),
            rows_per_image: Some(size.height),
        },
        size,
    );
    Ok(texture.create_view(&Default::default()))
}

/// The second channel of a volume's texture as `interpolation` reads it: for the
/// interpolating spline, the voxels, whose spline's gradient shades it (volume.wgsl's
/// `smooth_shading`).
pub(crate) fn shading_channel(vol: &Volume, interpolation: Interpolation) -> Option<&[f32]> {
    interpolation.prefiltered().then_some(&vol.data[..])
}

impl GpuVolume {
    /// Uploads the grid `marcher` reads of `vol` (its HU as R16Float, or the interpolating
    /// spline's coefficients and the HU that shade them as Rg16Float) and `tf`'s control
    /// points; `marcher` gives the transforms and the bricks' count too.
    pub(crate) fn new(
        ctx: &GpuContext,
        vol: &Volume,
        tf: &TransferFunction,
        marcher: &Marcher,
    ) -> Result<GpuVolume, GpuError> {
        let view = volume_texture(
            ctx,
            "CT volume (HU, f16)",
            vol.dims,
            marcher.grid(),
            shading_channel(vol, marcher.interpolation()),
        )?;
        let sampler = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("trilinear"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let opacity: Vec<[f32; 2]> = tf.opacity.iter().map(|p| [p.0, p.1]).collect();
        let color: Vec<[f32; 4]> = tf
            .color
            .iter()
            .map(|p| [p.0, p.1[0], p.1[1], p.1[2]])
            .collect();
        let none = wgpu::BufferUsages::empty();
        let brick_dims = marcher.brick_table().0;
        Ok(GpuVolume {
            view,
            sampler,
            opacity: ctx.storage("opacity points", bytemuck::cast_slice(&opacity), none)?,
            color: ctx.storage("color points", bytemuck::cast_slice(&color), none)?,
            brick_dims: brick_dims.map(|b| b as u32),
            to_index: marcher.world_to_index(),
        })
    }
}

/// A segmentation's colours on the GPU (`raystream_cpu::segments`, volume.wgsl's `painted`):
/// each voxel's label as an R16Uint texture of the volume's grid, and the colour table; one
/// voxel of label 0 and one empty colour where there is none.
pub(crate) fn segment_bindings(
    ctx: &GpuContext,
    segments: Option<&SegmentColours>,
) -> Result<(wgpu::TextureView, wgpu::Buffer), GpuError> {
    let (dims, labels, colours) = match segments {
        Some(s) => (s.dims, &s.labels[..], &s.colours[..]),
        None => ([1; 3], &[0u16][..], &[[0.0f32; 4]][..]),
    };
    let size = wgpu::Extent3d {
        width: dims[0] as u32,
        height: dims[1] as u32,
        depth_or_array_layers: dims[2] as u32,
    };
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("segment labels"),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: wgpu::TextureFormat::R16Uint,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    ctx.queue.write_texture(
        texture.as_image_copy(),
        bytemuck::cast_slice(labels),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(2 * size.width),
            rows_per_image: Some(size.height),
        },
        size,
    );
    let table = ctx.storage(
        "segment colours",
        bytemuck::cast_slice(colours),
        wgpu::BufferUsages::empty(),
    )?;
    Ok((texture.create_view(&Default::default()), table))
}

/// A brick table (`raystream_cpu::dvr::brick_table`) on the GPU as the kernels read it: a word
/// a brick, 1 where it may be visible.
pub(crate) fn brick_buffer(ctx: &GpuContext, visible: &[bool]) -> Result<wgpu::Buffer, GpuError> {
    let words: Vec<u32> = visible.iter().map(|&v| v as u32).collect();
    ctx.storage(
        "brick table",
        bytemuck::cast_slice(&words),
        wgpu::BufferUsages::empty(),
    )
}

/// cinematic: paths a dispatch by default (1024² pixels, one path each): on lavapipe a 64×48
/// test frame is one dispatch; on a GPU a dispatch of 2²⁰ paths takes milliseconds to tens
/// of milliseconds.
pub const PATHS_PER_DISPATCH: u64 = 1 << 20;

/// What a frame reads back: 8-bit sRGB packed on the GPU, the float frame over the
/// background, or the float frame premultiplied (no background) with each pixel's opacity;
/// or nothing but its sample count, the premultiplied frame copied into a buffer on the GPU
/// (for the denoiser).
#[derive(Clone, Copy)]
enum Output<'b> {
    Srgb8,
    Linear,
    Premultiplied,
    OnGpu(&'b wgpu::Buffer),
}

/// A denoised frame as [`GpuVolumeRenderer::denoised`] delivers it.
enum Denoised {
    /// The premultiplied light and each pixel's opacity.
    Rgba(Image, Vec<f32>),
    /// Over the background, 8-bit sRGB (3 bytes a pixel).
    Srgb8(Vec<u8>),
}

impl Denoised {
    fn into_rgba(self) -> (Image, Vec<f32>) {
        match self {
            Denoised::Rgba(film, alpha) => (film, alpha),
            Denoised::Srgb8(_) => unreachable!("asked for the premultiplied frame"),
        }
    }

    fn into_srgb8(self) -> Vec<u8> {
        match self {
            Denoised::Srgb8(rgb) => rgb,
            Denoised::Rgba(..) => unreachable!("asked for sRGB bytes"),
        }
    }
}

/// A volume and its transfer function on the GPU, ready for direct volume rendering.
pub struct GpuVolumeRenderer<'a> {
    ctx: &'a GpuContext,
    vol: &'a Volume,
    tf: &'a TransferFunction,
    gpu: GpuVolume,
    pipeline: wgpu::ComputePipeline,
    /// `--mode cinematic`: the path tracer's kernel, and its majorant grid (made by the first
    /// cinematic frame).
    path_pipeline: wgpu::ComputePipeline,
    /// The denoiser's guides of cinematic frames.
    guide_pipeline: wgpu::ComputePipeline,
    /// The denoiser, made on first use.
    denoiser: std::sync::OnceLock<GpuDenoiser>,
    /// The last denoised frame's buffers, kept for the next one of the same size or smaller.
    denoise_work: Mutex<Option<DenoiseWork>>,
    /// Cinematic paths traced so far, added to as each dispatch completes (what a progress bar
    /// counts: `width · height · spp` a frame).
    pub paths_done: AtomicU64,
    /// The values each interpolation reads, and the interpolating cubic B-spline's
    /// coefficients' texture, made by the first frame that reads them.
    grids: SplineGrids,
    coefficient_view: std::sync::OnceLock<wgpu::TextureView>,
    /// The majorant grids, per interpolation (`Interpolation as usize`).
    majorants: [std::sync::OnceLock<wgpu::Buffer>; 3],
    /// The brick tables of dvr frames that skip empty space, per interpolation, made on first
    /// use (each interpolation bounds a brick's values its own way).
    bricks: [std::sync::OnceLock<wgpu::Buffer>; 3],
    /// cinematic: a frame's running sums between its dispatches.
    accum: Mutex<Option<wgpu::Buffer>>,
    /// cinematic: at most this many paths a dispatch (a frame's samples are split into
    /// dispatches of whole samples of every pixel, each submitted and waited for on its own),
    /// so that no kernel runs long enough for a display driver's watchdog (Windows' TDR: 2 s)
    /// and no submission past the GPU timeout; the picture is the same bit for bit.
    pub paths_per_dispatch: u64,
    /// `--shadows`: the light grid's kernel and values.
    light_pipeline: wgpu::ComputePipeline,
    /// Float pixels → 8-bit sRGB and the summed sample count, for [`Self::render_srgb8`].
    pack_pipeline: wgpu::ComputePipeline,
    light_values: wgpu::Buffer,
    light_dims: [u32; 3],
    /// The curved plane rows' binding of frames a camera casts (one placeholder row).
    no_rows: wgpu::Buffer,
    /// The last frame's output buffers, kept for the next frame of the same size or smaller.
    frame: Mutex<Option<FrameBuffers>>,
    /// A segmentation's labels and colours (bindings 14 and 15), or placeholders, and whether
    /// there is one.
    segment_labels: wgpu::TextureView,
    segment_colours: wgpu::Buffer,
    segmented: bool,
    /// mip, minip and average kept to segments: the kept voxels' weights
    /// ([`Self::segmented`]), what each interpolation reads of them, and the textures of the
    /// kept volume beside them (trilinear and the cubic B-spline; the interpolating spline).
    weights: Option<&'a Volume>,
    weight_grids: SplineGrids,
    kept_views: [std::sync::OnceLock<wgpu::TextureView>; 2],
    /// Per interpolation, the bricks a kept projection may see
    /// (`raystream_cpu::dvr::kept_brick_table`), made on first use.
    kept_bricks: [std::sync::OnceLock<wgpu::Buffer>; 3],
    /// Milliseconds spent uploading the volume and building the pipeline.
    pub upload_ms: f64,
}

/// A denoised frame's buffers on the GPU, for frames of up to `filter`'s pixels: the traced
/// frame, its guides and the filter's working buffers. Made for the first denoised frame (or a
/// larger one) and reused, so that a frame allocates (and wgpu zeroes) none of its 124 bytes a
/// pixel; every pixel of each is written before it is read.
struct DenoiseWork {
    film: wgpu::Buffer,
    guides: wgpu::Buffer,
    filter: DenoiseBuffers,
}

impl DenoiseWork {
    fn new(ctx: &GpuContext, pixels: u64) -> Result<DenoiseWork, GpuError> {
        Ok(DenoiseWork {
            film: ctx.work_buffer("cinematic frame", 32 * pixels, wgpu::BufferUsages::COPY_DST)?,
            guides: ctx.work_buffer("guides", 32 * pixels, wgpu::BufferUsages::COPY_SRC)?,
            filter: DenoiseBuffers::new(ctx, pixels)?,
        })
    }
}

struct FrameBuffers {
    pixels: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// 8-bit sRGB (3 bytes a pixel, in words), then the sample count, and their mappable copy.
    packed: wgpu::Buffer,
    sum: wgpu::Buffer,
    packed_read: wgpu::Buffer,
    timer: Option<Timer>,
}

/// Timings of one GPU volume frame, milliseconds.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuDvrTimes {
    /// Submission to readback, wall time.
    pub frame_ms: f64,
    /// The kernel's own time, from timestamp queries where the adapter has them.
    pub kernel_gpu_ms: Option<f64>,
    /// Samples the rays took (counted per pixel on the GPU, as the CPU counts them; shadow
    /// rays' samples not included).
    pub samples: u64,
    /// cinematic with `denoise`: what the guides and the filter took (in `frame_ms` too).
    pub denoise: Option<raystream_cpu::denoise::DenoiseTimes>,
}

impl<'a> GpuVolumeRenderer<'a> {
    pub fn new(
        ctx: &'a GpuContext,
        vol: &'a Volume,
        tf: &'a TransferFunction,
    ) -> Result<GpuVolumeRenderer<'a>, GpuError> {
        GpuVolumeRenderer::painted(ctx, vol, tf, None)
    }

    /// [`Self::new`], with dvr, iso and cinematic samples coloured by `segments` (on the
    /// volume's grid) where given, as `raystream_cpu::dvr::CpuVolume::painted` colours them.
    pub fn painted(
        ctx: &'a GpuContext,
        vol: &'a Volume,
        tf: &'a TransferFunction,
        segments: Option<&SegmentColours>,
    ) -> Result<GpuVolumeRenderer<'a>, GpuError> {
        GpuVolumeRenderer::segmented(ctx, vol, tf, segments, None)
    }

    /// [`Self::painted`], and with `weights` the volume kept to some of its segments for mip,
    /// minip and average, as `raystream_cpu::dvr::CpuVolume::kept` keeps it: `weights` on its
    /// grid, 1 at each kept voxel and 0 at each hidden one, whose value in `vol` must be 0.
    pub fn segmented(
        ctx: &'a GpuContext,
        vol: &'a Volume,
        tf: &'a TransferFunction,
        segments: Option<&SegmentColours>,
        weights: Option<&'a Volume>,
    ) -> Result<GpuVolumeRenderer<'a>, GpuError> {
        let t0 = Instant::now();
        if let Some(s) = segments {
            assert_eq!(s.dims, vol.dims, "segment colours on the volume's grid");
        }
        if let Some(w) = weights {
            raystream_cpu::dvr::check_kept(vol, w);
        }
        ctx.scoped(|| {
            let gpu = GpuVolume::new(ctx, vol, tf, &Marcher::new(vol, None))?;
            let (segment_labels, segment_colours) = segment_bindings(ctx, segments)?;
            let module = ctx
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("dvr.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(dvr_wgsl().into()),
                });
            let pipeline = ctx.auto_pipeline(&module, "render_volume");
            let path_pipeline = ctx.auto_pipeline(&module, "path_trace_volume");
            let guide_pipeline = ctx.auto_pipeline(&module, "guide_volume");
            let light_pipeline = ctx.auto_pipeline(&module, "light_grid");
            let pack_pipeline = ctx.auto_pipeline(&module, "pack_srgb8");
            let light_dims = LightGrid::dims_for(vol.dims);
            let light_values = ctx.work_buffer(
                "light grid",
                4 * light_dims.iter().product::<usize>() as u64,
                wgpu::BufferUsages::empty(),
            )?;
            let no_rows = ctx.storage(
                "no curved plane",
                bytemuck::bytes_of(&GpuCprRow::default()),
                wgpu::BufferUsages::empty(),
            )?;
            ctx.wait()?;
            Ok(GpuVolumeRenderer {
                ctx,
                vol,
                tf,
                gpu,
                pipeline,
                path_pipeline,
                guide_pipeline,
                denoiser: std::sync::OnceLock::new(),
                denoise_work: Mutex::new(None),
                paths_done: AtomicU64::new(0),
                grids: Default::default(),
                coefficient_view: Default::default(),
                majorants: Default::default(),
                bricks: Default::default(),
                accum: Mutex::new(None),
                paths_per_dispatch: PATHS_PER_DISPATCH,
                light_pipeline,
                pack_pipeline,
                light_values,
                light_dims: light_dims.map(|n| n as u32),
                no_rows,
                frame: Mutex::new(None),
                segment_labels,
                segment_colours,
                segmented: segments.is_some(),
                weights,
                weight_grids: Default::default(),
                kept_views: Default::default(),
                kept_bricks: Default::default(),
                upload_ms: t0.elapsed().as_secs_f64() * 1e3,
            })
        })
    }

    /// Renders one frame seen by `sight`: a camera (the scene frame of
    /// `raystream_cpu::dvr::volume_camera`) or a curved plane.
    pub fn render<'s>(
        &self,
        opt: &DvrOptions,
        sight: impl Into<Sight<'s>>,
    ) -> Result<(Image, GpuDvrTimes), GpuError> {
        let sight = sight.into();
        if let Some((out, times)) = self.denoised(opt, sight, false)? {
            let (film, alpha) = out.into_rgba();
            return Ok((over_background(film, &alpha, opt.background), times));
        }
        let (pixels, _, _, times) = self.run(opt, sight, Output::Linear)?;
        Ok((pixels.into_linear(), times))
    }

    /// Renders one frame with no background, in one pass, as
    /// `raystream_cpu::dvr::render_volume_rgba`: the premultiplied light of each pixel and its
    /// opacity 1 − T.
    pub fn render_rgba<'s>(
        &self,
        opt: &DvrOptions,
        sight: impl Into<Sight<'s>>,
    ) -> Result<(Image, Vec<f32>, GpuDvrTimes), GpuError> {
        let sight = sight.into();
        if let Some((out, times)) = self.denoised(opt, sight, false)? {
            let (film, alpha) = out.into_rgba();
            return Ok((film, alpha, times));
        }
        let (pixels, alpha, _, times) = self.run(opt, sight, Output::Premultiplied)?;
        Ok((pixels.into_linear(), alpha, times))
    }

    /// Renders one frame as a viewer shows it: 8-bit sRGB, 3 bytes a pixel (as
    /// [`Image::to_srgb8`]), converted on the GPU so that a fifth of the bytes come back.
    pub fn render_srgb8<'s>(
        &self,
        opt: &DvrOptions,
        sight: impl Into<Sight<'s>>,
    ) -> Result<(Vec<u8>, GpuDvrTimes), GpuError> {
        let sight = sight.into();
        if let Some((out, times)) = self.denoised(opt, sight, true)? {
            return Ok((out.into_srgb8(), times));
        }
        let (pixels, _, _, times) = self.run(opt, sight, Output::Srgb8)?;
        Ok((pixels.into_srgb8(), times))
    }

    /// A cinematic frame (`opt.mode` must be cinematic) as the denoiser takes it, as
    /// `raystream_cpu::cinematic::render_film`: the premultiplied light, the opacity and each
    /// pixel's variance of its luminance.
    pub fn render_film(
        &self,
        opt: &DvrOptions,
        cam: &Camera,
    ) -> Result<(NoisyFilm, GpuDvrTimes), GpuError> {
        assert_eq!(
            opt.mode,
            DvrMode::Cinematic,
            "render_film draws cinematic frames"
        );
        let (pixels, alpha, variance, times) =
            self.run(opt, Sight::Camera(cam), Output::Premultiplied)?;
        let film = NoisyFilm {
            film: pixels.into_linear(),
            alpha,
            variance,
        };
        Ok((film, times))
    }

    /// With `opt.denoise`, a cinematic frame denoised: traced here, its guides marched here
    /// ([`Self::guides`]) and filtered here ([`GpuDenoiser`], `raystream_cpu::denoise`'s passes
    /// in WGSL), the frame's time including the filter's: premultiplied with its opacity, or
    /// with `srgb8` put over the background and packed to sRGB on the GPU. `None` for any
    /// other frame.
    fn denoised(
        &self,
        opt: &DvrOptions,
        sight: Sight,
        srgb8: bool,
    ) -> Result<Option<(Denoised, GpuDvrTimes)>, GpuError> {
        if !(opt.denoise && opt.mode == DvrMode::Cinematic) {
            return Ok(None);
        }
        let Sight::Camera(cam) = sight else {
            panic!("cinematic rendering is seen by a camera, not a curved plane");
        };
        let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
        let t0 = Instant::now();
        // Compiled with the first denoised frame (in its frame time, not its filter's).
        let denoiser = self.denoiser.get_or_init(|| GpuDenoiser::new(self.ctx));
        // The frame, its variances and the guides stay on the GPU for the filter, in the
        // buffers of the frames before where they fit.
        let pixels = opt.width as u64 * opt.height as u64;
        let mut work = self.denoise_work.lock().unwrap();
        if work.as_ref().is_none_or(|w| !w.filter.fits(pixels)) {
            // The old buffers go first: two frames' worth need not fit at once.
            *work = None;
            *work = Some(DenoiseWork::new(self.ctx, pixels)?);
        }
        let DenoiseWork {
            film,
            guides,
            filter: buffers,
        } = work.as_ref().unwrap();
        let (_, _, _, mut times) = self.run(opt, sight, Output::OnGpu(film))?;
        let t = Instant::now();
        let tolerance = self.march_guides(opt, cam, guides)?;
        let guides_ms = ms(t);
        let t = Instant::now();
        let frame = (film, (opt.width, opt.height));
        let guides = (guides, tolerance);
        let settings = DenoiseOptions::default();
        let out = if srgb8 {
            let rgb = self.ctx.scoped(|| {
                let over = Some(opt.background);
                let light =
                    denoiser.filter_on_gpu(self.ctx, frame, guides, &settings, over, buffers)?;
                self.srgb8_of(opt, sight, light)
            })?;
            Denoised::Srgb8(rgb)
        } else {
            let (film, alpha) = denoiser.filter(self.ctx, frame, guides, &settings, buffers)?;
            Denoised::Rgba(film, alpha)
        };
        times.denoise = Some(DenoiseTimes {
            guides_ms,
            filter_ms: ms(t),
        });
        times.frame_ms = ms(t0);
        Ok(Some((out, times)))
    }

    /// Records `pack_srgb8` over `n` pixels with bindings `bind` (params, pixels, packed
    /// bytes, and the sample sum `sum`, cleared first).
    fn encode_pack(
        &self,
        enc: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        sum: &wgpu::Buffer,
        n: u64,
    ) {
        enc.clear_buffer(sum, 0, None);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("pack_srgb8"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pack_pipeline);
        pass.set_bind_group(0, bind, &[]);
        let groups = (n as u32).div_ceil(4 * 64);
        let gx = groups.min(self.ctx.limits.max_compute_workgroups_per_dimension.max(1));
        pass.dispatch_workgroups(gx, groups.div_ceil(gx), 1);
    }

    /// A frame of `opt`'s size on the GPU (per pixel a colour over the background, and a
    /// fourth float) as 8-bit sRGB, 3 bytes a pixel, packed there so that a fifth of the bytes
    /// come back: through the frame buffers' packed bytes and their mappable copy, which the
    /// frame just traced at this size has made.
    fn srgb8_of(
        &self,
        opt: &DvrOptions,
        sight: Sight,
        pixels: &wgpu::Buffer,
    ) -> Result<Vec<u8>, GpuError> {
        let ctx = self.ctx;
        let (params, _) = self.params(opt, sight, false)?;
        let param_buf = self.uniform("pack params", &params);
        let n = opt.width as u64 * opt.height as u64;
        let packed_bytes = n.div_ceil(4) * 12;
        let frame = self.frame.lock().unwrap();
        let FrameBuffers {
            packed,
            sum,
            packed_read,
            ..
        } = frame.as_ref().expect("a frame traced at this size");
        let entries: Vec<_> = [(0, &param_buf), (6, pixels), (8, packed), (9, sum)]
            .into_iter()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("pack sRGB"),
            layout: &self.pack_pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("pack_srgb8"),
            });
        self.encode_pack(&mut enc, &bind, sum, n);
        enc.copy_buffer_to_buffer(packed, 0, packed_read, 0, packed_bytes);
        ctx.queue.submit([enc.finish()]);
        let mut bytes: Vec<u8> = read_back(ctx, packed_read)?;
        bytes.truncate(3 * n as usize);
        Ok(bytes)
    }

    /// A uniform buffer holding `params`.
    fn uniform(&self, label: &str, params: &DvrParams) -> wgpu::Buffer {
        self.ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(params),
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// The majorant grid of cinematic frames read as `interpolation`, made on first use.
    fn majorant_buffer(&self, interpolation: Interpolation) -> Result<&wgpu::Buffer, GpuError> {
        let cell = &self.majorants[interpolation as usize];
        if let Some(b) = cell.get() {
            return Ok(b);
        }
        let grid = std::borrow::Cow::Borrowed(self.grid(interpolation));
        let m = Majorants::new(&Marcher::with_grid(self.vol, grid, interpolation), self.tf);
        let b = self.ctx.storage(
            "majorants",
            bytemuck::cast_slice(&m.values),
            wgpu::BufferUsages::empty(),
        )?;
        Ok(cell.get_or_init(|| b))
    }

    /// The brick table of frames read as `interpolation`, made on first use.
    fn brick_buffer(&self, interpolation: Interpolation) -> Result<&wgpu::Buffer, GpuError> {
        self.table_buffer(&self.bricks[interpolation as usize], || {
            brick_table(
                self.vol.dims,
                self.grid(interpolation),
                self.tf,
                interpolation,
            )
        })
    }

    /// The bricks a projection kept to `weights`' segments may see, read as `interpolation`,
    /// made on first use.
    fn kept_brick_buffer(
        &self,
        weights: &Volume,
        interpolation: Interpolation,
    ) -> Result<&wgpu::Buffer, GpuError> {
        self.table_buffer(&self.kept_bricks[interpolation as usize], || {
            kept_brick_table(
                self.vol.dims,
                self.weight_grids.get(weights, interpolation),
                interpolation,
            )
        })
    }

    /// The brick table in `cell`, uploaded from `table` the first time.
    fn table_buffer<'s>(
        &'s self,
        cell: &'s std::sync::OnceLock<wgpu::Buffer>,
        table: impl FnOnce() -> Vec<bool>,
    ) -> Result<&'s wgpu::Buffer, GpuError> {
        if let Some(b) = cell.get() {
            return Ok(b);
        }
        let b = brick_buffer(self.ctx, &table())?;
        Ok(cell.get_or_init(|| b))
    }

    /// The values frames read as `interpolation` read: the voxels, or the interpolating
    /// spline's coefficients (computed on first use).
    fn grid(&self, interpolation: Interpolation) -> &[f32] {
        self.grids.get(self.vol, interpolation)
    }

    /// Makes what frames read as `interpolation` need before any frame does: the interpolating
    /// spline's coefficients and their texture (a caller that times frames may call this
    /// first, to time it apart).
    pub fn prepare(&self, interpolation: Interpolation) -> Result<(), GpuError> {
        self.texture(interpolation)?;
        if let Some(weights) = self.weights {
            self.kept_texture(weights, interpolation)?;
        }
        self.ctx.wait()
    }

    /// The texture frames read as `interpolation` read: the HU, or the interpolating spline's
    /// coefficients beside the HU (uploaded on first use).
    fn texture(&self, interpolation: Interpolation) -> Result<&wgpu::TextureView, GpuError> {
        if !interpolation.prefiltered() {
            return Ok(&self.gpu.view);
        }
        if let Some(v) = self.coefficient_view.get() {
            return Ok(v);
        }
        let label = "interpolating spline coefficients and HU (f16)";
        let v = volume_texture(
            self.ctx,
            label,
            self.vol.dims,
            self.grid(interpolation),
            shading_channel(self.vol, interpolation),
        )?;
        Ok(self.coefficient_view.get_or_init(|| v))
    }

    /// The kept voxels' weights a frame of `mode` reads: a projection's, where there are any.
    fn kept_weights(&self, mode: DvrMode) -> Option<&'a Volume> {
        self.weights.filter(|_| mode.is_projection())
    }

    /// The texture a frame of `opt` reads: with weights ([`Self::segmented`]) and a projection,
    /// the kept volume beside its weights, each as `opt.interpolation` reads it (uploaded on
    /// first use: a texture for the trilinear and cubic B-spline, one for the interpolating
    /// spline's coefficients); else [`Self::texture`].
    fn texture_for(&self, opt: &DvrOptions) -> Result<&wgpu::TextureView, GpuError> {
        match self.kept_weights(opt.mode) {
            Some(weights) => self.kept_texture(weights, opt.interpolation),
            None => self.texture(opt.interpolation),
        }
    }

    /// The kept volume beside its `weights`, as interpolation `i` reads each.
    fn kept_texture(
        &self,
        weights: &Volume,
        i: Interpolation,
    ) -> Result<&wgpu::TextureView, GpuError> {
        let slot = &self.kept_views[i.prefiltered() as usize];
        if let Some(v) = slot.get() {
            return Ok(v);
        }
        let v = volume_texture(
            self.ctx,
            "kept volume and its weights (f16)",
            self.vol.dims,
            self.grid(i),
            Some(self.weight_grids.get(weights, i)),
        )?;
        Ok(slot.get_or_init(|| v))
    }

    /// The denoiser's guides of a cinematic frame seen by `cam`, as
    /// `raystream_cpu::cinematic::guides` marches them, marched here and read back.
    pub fn guides(&self, opt: &DvrOptions, cam: &Camera) -> Result<Guides, GpuError> {
        let n = opt.width as usize * opt.height as usize;
        let out = self
            .ctx
            .work_buffer("guides", 32 * n as u64, wgpu::BufferUsages::COPY_SRC)?;
        let tolerance = self.march_guides(opt, cam, &out)?;
        let floats: Vec<f32> = read_back(self.ctx, &out)?;
        let (first, second) = floats.split_at(4 * n);
        Ok(Guides {
            width: opt.width,
            height: opt.height,
            depth: first
                .chunks_exact(4)
                .map(|g| if g[3] < 0.0 { f32::INFINITY } else { g[3] })
                .collect(),
            albedo: first
                .chunks_exact(4)
                .map(|g| Vec3::new(g[0], g[1], g[2]))
                .collect(),
            normal: second
                .chunks_exact(4)
                .map(|g| Vec3::new(g[0], g[1], g[2]))
                .collect(),
            tolerance,
        })
    }

    /// Marches the guides into `out` (at least 32 bytes a pixel), laid out as
    /// [`GpuDenoiser`] reads them (per pixel (albedo, depth or −1), then (normal, 0)), and
    /// waits for them; their depth tolerance.
    fn march_guides(
        &self,
        opt: &DvrOptions,
        cam: &Camera,
        out: &wgpu::Buffer,
    ) -> Result<f32, GpuError> {
        let ctx = self.ctx;
        ctx.scoped(|| {
            let (params, _) = self.params(opt, Sight::Camera(cam), false)?;
            let param_buf = self.uniform("guide params", &params);
            let majorants = self.majorant_buffer(opt.interpolation)?;
            let texture = self.texture_for(opt)?;
            let entries: Vec<_> = [
                (0, param_buf.as_entire_binding()),
                (1, wgpu::BindingResource::TextureView(texture)),
                (2, wgpu::BindingResource::Sampler(&self.gpu.sampler)),
                (3, self.gpu.opacity.as_entire_binding()),
                (4, self.gpu.color.as_entire_binding()),
                (11, majorants.as_entire_binding()),
                (13, out.as_entire_binding()),
                (14, wgpu::BindingResource::TextureView(&self.segment_labels)),
                (15, self.segment_colours.as_entire_binding()),
            ]
            .into_iter()
            .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
            .collect();
            let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("guides"),
                layout: &self.guide_pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("guide_volume"),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("guide_volume"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.guide_pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(opt.width.div_ceil(8), opt.height.div_ceil(8), 1);
            }
            ctx.queue.submit([enc.finish()]);
            ctx.wait()?;
            Ok(params.step)
        })
    }

    /// The kernels' parameters of a frame seen by `sight`, and a curved plane's rows.
    fn params(
        &self,
        opt: &DvrOptions,
        sight: Sight,
        premultiplied: bool,
    ) -> Result<(DvrParams, Option<wgpu::Buffer>), GpuError> {
        let ctx = self.ctx;
        let ([r0, r1, r2], origin) = self.gpu.to_index;
        let (w, l) = opt.shown_window();
        let s = self.tf.shading;
        let v3 = |v: Vec3| v.to_array();
        let planes: Vec<(Vec3, f32)> = sight
            .planes(opt, self.vol)
            .iter()
            .flatten()
            .copied()
            .collect();
        // A curved plane has no camera: its rows cast the rays (the kernel reads no camera
        // field then; a placeholder fills them).
        let (cam, row_buf) = match sight {
            Sight::Camera(cam) => (*cam, None),
            Sight::Curved(plane) => {
                assert_eq!(
                    (plane.width, plane.height),
                    (opt.width, opt.height),
                    "a curved plane is made for its image's size"
                );
                let rows: Vec<GpuCprRow> = plane
                    .rows
                    .iter()
                    .map(|r| GpuCprRow {
                        centre: v3(r.centre),
                        pixel_mm: plane.pixel_mm,
                        lateral: v3(r.lateral),
                        normal: v3(r.normal),
                        ..Default::default()
                    })
                    .collect();
                let buf = ctx.storage(
                    "curved plane rows",
                    bytemuck::cast_slice(&rows),
                    wgpu::BufferUsages::empty(),
                )?;
                (
                    raystream_scene::Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Y, 60.0),
                    Some(buf),
                )
            }
        };
        let curved = row_buf.is_some();
        let params = DvrParams {
            eye: v3(scene_to_lps(cam.eye)),
            tan_y: cam.tan_y,
            fwd: v3(scene_to_lps(cam.fwd)),
            width: opt.width,
            right: v3(scene_to_lps(cam.right)),
            height: opt.height,
            up: v3(scene_to_lps(cam.up)),
            mode: match opt.mode {
                DvrMode::Dvr => 0,
                DvrMode::Mip => 1,
                DvrMode::MinIp => 2,
                DvrMode::Average => 3,
                DvrMode::Iso => 4,
                DvrMode::Slice => 5,
                DvrMode::Cinematic => {
                    assert!(!curved, "cinematic rendering is seen by a camera");
                    6
                }
            },
            to_index0: v3(r0),
            step: opt.step_for(self.vol),
            to_index1: v3(r1),
            iso: opt.iso_hu,
            to_index2: v3(r2),
            window_width: w,
            origin: v3(origin),
            window_level: l,
            dims: self.vol.dims.map(|n| n as u32),
            skip_empty: (opt.skip_empty
                && (opt.mode == DvrMode::Dvr || self.kept_weights(opt.mode).is_some()))
                as u32,
            bricks: self.gpu.brick_dims,
            opacity_count: self.tf.opacity.len() as u32,
            background: v3(opt.background),
            color_count: self.tf.color.len() as u32,
            shading: [s.ambient, s.diffuse, s.specular, s.power],
            light: v3(opt.key_light(&cam)),
            shadows: (opt.shadows && opt.mode == DvrMode::Dvr && !curved) as u32,
            crop_min: v3(opt.crop.map_or(Vec3::ZERO, |c| c[0])),
            crop: opt.crop.is_some() as u32,
            crop_max: v3(opt.crop.map_or(Vec3::ZERO, |c| c[1])),
            plane_count: planes.len() as u32,
            planes: [0, 1].map(|i| planes.get(i).map_or([0.0; 4], |(n, c)| [n.x, n.y, n.z, *c])),
            light_dims: self.light_dims,
            shadow_step: opt.shadow_step_for(self.vol),
            parallel: cam.parallel,
            hu_values: (opt.hu_values && opt.mode.is_windowed()) as u32,
            premultiplied: premultiplied as u32,
            curved: curved as u32,
            slice_at: v3(opt.slice_point(self.vol)),
            slab_half: if curved {
                0.5 * opt.slab.unwrap_or(0.0)
            } else {
                0.0
            },
            spp: opt.spp,
            bounces: opt.bounces,
            sample_first: 0,
            sample_count: opt.spp,
            anisotropy: opt.anisotropy,
            light_scale: opt.exposure_scale(),
            interpolation: opt.interpolation.kernel_code(),
            segments: self.segmented as u32,
            kept: self.kept_weights(opt.mode).is_some() as u32,
            pad_kept: 0,
            pad0: 0,
            pad1: 0,
        };
        Ok((params, row_buf))
    }

    /// One frame: its pixels, and with premultiplied output the opacities (and for a
    /// cinematic frame the variances) of the second plane.
    fn run(
        &self,
        opt: &DvrOptions,
        sight: Sight,
        output: Output,
    ) -> Result<(Pixels, Vec<f32>, Vec<f32>, GpuDvrTimes), GpuError> {
        let srgb8 = matches!(output, Output::Srgb8);
        let on_gpu = match output {
            Output::OnGpu(b) => Some(b),
            _ => None,
        };
        let premultiplied = matches!(output, Output::Premultiplied | Output::OnGpu(_));
        // The sample count comes from the packing kernel's sum where no floats come back.
        let count_on_gpu = srgb8 || on_gpu.is_some();
        let ctx = self.ctx;
        let t0 = Instant::now();
        ctx.scoped(|| {
            let (params, row_buf) = self.params(opt, sight, premultiplied)?;
            let row_buf = row_buf.as_ref().unwrap_or(&self.no_rows);
            let param_buf = self.uniform("dvr params", &params);
            let n = opt.width as u64 * opt.height as u64;
            // 4 pixels in 3 words.
            let packed_bytes = n.div_ceil(4) * 12;
            // 16 bytes a pixel; premultiplied, another 16 for its opacity.
            let pixel_bytes = n * 16 * (1 + premultiplied as u64);
            let mut frame = self.frame.lock().unwrap();
            if frame
                .as_ref()
                .is_none_or(|f| f.pixels.size() < pixel_bytes || f.packed.size() < packed_bytes)
            {
                *frame = Some(FrameBuffers {
                    pixels: ctx.work_buffer(
                        "volume pixels",
                        pixel_bytes,
                        wgpu::BufferUsages::empty(),
                    )?,
                    readback: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("volume pixels readback"),
                        size: pixel_bytes.max(64),
                        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }),
                    packed: ctx.work_buffer(
                        "sRGB pixels",
                        packed_bytes,
                        wgpu::BufferUsages::empty(),
                    )?,
                    sum: ctx.work_buffer("sample count", 8, wgpu::BufferUsages::empty())?,
                    packed_read: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("sRGB pixels readback"),
                        size: packed_bytes + 8,
                        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    }),
                    timer: ctx.timer(2),
                });
            }
            let FrameBuffers {
                pixels,
                readback,
                packed,
                sum,
                packed_read,
                timer,
            } = frame.as_ref().unwrap();
            let shadows = params.shadows != 0;
            // Bindings by number; the light grid's kernel uses no colour points (4) and no pixels
            // (6), and each pipeline's layout holds exactly the bindings its entry point uses.
            let cinematic = opt.mode == DvrMode::Cinematic;
            let majorants = if cinematic {
                Some(self.majorant_buffer(opt.interpolation)?)
            } else {
                None
            };
            // cinematic: the dispatches' samples, [first, first + count) each, their parameters,
            // and the running sums between them.
            let batches: Vec<(u32, u32)> = if cinematic {
                let per = self
                    .paths_per_dispatch
                    .div_ceil(n.max(1))
                    .clamp(1, opt.spp.max(1) as u64) as u32;
                (0..opt.spp)
                    .step_by(per as usize)
                    .map(|f| (f, per.min(opt.spp - f)))
                    .collect()
            } else {
                Vec::new()
            };
            let batch_params: Vec<wgpu::Buffer> = batches
                .iter()
                .map(|&(sample_first, sample_count)| {
                    let p = DvrParams {
                        sample_first,
                        sample_count,
                        ..params
                    };
                    self.uniform("cinematic dispatch params", &p)
                })
                .collect();
            let mut accum = self.accum.lock().unwrap();
            if batches.len() > 1 && accum.as_ref().is_none_or(|a| a.size() < 32 * n) {
                *accum =
                    Some(ctx.work_buffer("running sums", 32 * n, wgpu::BufferUsages::empty())?);
            }
            // The brick table is read only where dvr skips empty space, or a kept projection the
            // bricks outside its segments.
            let bricks = match self.kept_weights(opt.mode) {
                _ if params.skip_empty == 0 => &self.no_rows,
                Some(w) => self.kept_brick_buffer(w, opt.interpolation)?,
                None => self.brick_buffer(opt.interpolation)?,
            };
            // A frame of one dispatch binds a placeholder.
            let accum = accum.as_ref().unwrap_or(&self.no_rows);
            let texture = self.texture_for(opt)?;
            let resource = |b: u32| match b {
                0 => param_buf.as_entire_binding(),
                1 => wgpu::BindingResource::TextureView(texture),
                2 => wgpu::BindingResource::Sampler(&self.gpu.sampler),
                3 => self.gpu.opacity.as_entire_binding(),
                4 => self.gpu.color.as_entire_binding(),
                5 => bricks.as_entire_binding(),
                6 => pixels.as_entire_binding(),
                7 => self.light_values.as_entire_binding(),
                8 => packed.as_entire_binding(),
                9 => sum.as_entire_binding(),
                10 => row_buf.as_entire_binding(),
                11 => majorants.expect("a cinematic frame").as_entire_binding(),
                12 => accum.as_entire_binding(),
                14 => wgpu::BindingResource::TextureView(&self.segment_labels),
                _ => self.segment_colours.as_entire_binding(),
            };
            let group = |label, pipeline: &wgpu::ComputePipeline, bindings: &[u32]| {
                let entries: Vec<_> = bindings
                    .iter()
                    .map(|&binding| wgpu::BindGroupEntry {
                        binding,
                        resource: resource(binding),
                    })
                    .collect();
                ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(label),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &entries,
                })
            };
            // One bind group a dispatch: the volume kernel's, or the path tracer's with its
            // dispatch's parameters in binding 0.
            let (pipeline, binds) = if cinematic {
                let p = &self.path_pipeline;
                let binds = batch_params
                    .iter()
                    .map(|params| {
                        let entries: Vec<_> = [0, 1, 2, 3, 4, 6, 11, 12, 14, 15]
                            .into_iter()
                            .map(|binding| wgpu::BindGroupEntry {
                                binding,
                                resource: match binding {
                                    0 => params.as_entire_binding(),
                                    b => resource(b),
                                },
                            })
                            .collect();
                        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                            label: Some("path trace"),
                            layout: &p.get_bind_group_layout(0),
                            entries: &entries,
                        })
                    })
                    .collect();
                (p, binds)
            } else {
                let p = &self.pipeline;
                (
                    p,
                    vec![group("dvr", p, &[0, 1, 2, 3, 4, 5, 6, 7, 10, 14, 15])],
                )
            };
            let light_bind =
                shadows.then(|| group("light grid", &self.light_pipeline, &[0, 1, 2, 3, 5, 7]));
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("render_volume"),
                });
            if let Some(light_bind) = &light_bind {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("light_grid"),
                    timestamp_writes: timer.as_ref().map(|t| t.writes(Some(0), None)),
                });
                pass.set_pipeline(&self.light_pipeline);
                pass.set_bind_group(0, light_bind, &[]);
                let n = self.light_dims.iter().product::<u32>();
                let groups = n.div_ceil(64);
                let gx = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
                pass.dispatch_workgroups(gx, groups.div_ceil(gx), 1);
            }
            for (i, bind) in binds.iter().enumerate() {
                let (first, last) = (i == 0, i + 1 == binds.len());
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("render_volume"),
                    // With shadows the light grid's pass wrote the first stamp: the kernel time
                    // covers both; the path tracer's dispatches are timed from the first to the
                    // last.
                    timestamp_writes: timer
                        .as_ref()
                        .filter(|_| first || last)
                        .map(|t| t.writes((first && !shadows).then_some(0), last.then_some(1))),
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind, &[]);
                pass.dispatch_workgroups(opt.width.div_ceil(8), opt.height.div_ceil(8), 1);
                drop(pass);
                // A path-traced frame of several dispatches submits them one by one, each waited
                // for: a frame may take minutes, a submission no longer than the GPU timeout.
                if !last {
                    let done = std::mem::replace(
                        &mut enc,
                        ctx.device
                            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                                label: Some("render_volume"),
                            }),
                    );
                    ctx.queue.submit([done.finish()]);
                    ctx.wait()?;
                    self.paths_done
                        .fetch_add(batches[i].1 as u64 * n, Ordering::Relaxed);
                }
            }
            if count_on_gpu {
                let pack = group("pack sRGB", &self.pack_pipeline, &[0, 6, 8, 9]);
                self.encode_pack(&mut enc, &pack, sum, n);
            }
            // One submission: the kernels, their timestamps and the copy of the pixels to read.
            if let Some(t) = timer {
                t.resolve(&mut enc);
            }
            if srgb8 {
                enc.copy_buffer_to_buffer(packed, 0, packed_read, 0, packed_bytes);
            }
            if count_on_gpu {
                enc.copy_buffer_to_buffer(sum, 0, packed_read, packed_bytes, 8);
            }
            match on_gpu {
                Some(to) => enc.copy_buffer_to_buffer(pixels, 0, to, 0, pixel_bytes),
                None if !srgb8 => enc.copy_buffer_to_buffer(pixels, 0, readback, 0, pixel_bytes),
                None => {}
            }
            ctx.queue.submit([enc.finish()]);
            // The packed bytes (and the sample sum after them) straight into the frame's vector;
            // floats as words.
            let (mut bytes, words): (Vec<u8>, Vec<u32>) = if count_on_gpu {
                (read_back(ctx, packed_read)?, Vec::new())
            } else {
                (Vec::new(), read_words(ctx, readback)?)
            };
            if let Some(&(_, count)) = batches.last() {
                self.paths_done
                    .fetch_add(count as u64 * n, Ordering::Relaxed);
            }
            let kernel_gpu_ms = match timer {
                Some(t) => read_elapsed_ms(ctx, t)?,
                None => None,
            };
            let (mut alpha, mut variance) = (Vec::new(), Vec::new());
            let (out, samples) = if count_on_gpu {
                let at = packed_bytes as usize;
                let samples = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
                bytes.truncate(3 * n as usize);
                match on_gpu {
                    Some(_) => (Pixels::OnGpu, samples),
                    None => (Pixels::Srgb8(bytes), samples),
                }
            } else {
                let floats: &[f32] = bytemuck::cast_slice(&words);
                let px = &floats[..4 * n as usize];
                if premultiplied {
                    let a = &floats[4 * n as usize..8 * n as usize];
                    alpha = a.chunks_exact(4).map(|a| a[0]).collect();
                    if cinematic {
                        variance = a.chunks_exact(4).map(|a| a[1]).collect();
                    }
                }
                let samples = px.chunks_exact(4).map(|p| p[3].abs() as u64).sum();
                // A ray that took no sample has no HU value: NaN, as on the CPU (the kernel writes
                // the background there); nor has one that met no kept segment (samples counted
                // negative: dvr.wgsl's march).
                let none = params.hu_values != 0;
                let pixels = px
                    .chunks_exact(4)
                    .map(|p| {
                        if none && p[3] <= 0.0 {
                            Vec3::NAN
                        } else {
                            Vec3::new(p[0], p[1], p[2])
                        }
                    })
                    .collect();
                (
                    Pixels::Linear(Image {
                        width: opt.width,
                        height: opt.height,
                        pixels,
                    }),
                    samples,
                )
            };
            Ok((
                out,
                alpha,
                variance,
                GpuDvrTimes {
                    frame_ms: t0.elapsed().as_secs_f64() * 1e3,
                    kernel_gpu_ms,
                    samples,
                    denoise: None,
                },
            ))
        })
    }
}
