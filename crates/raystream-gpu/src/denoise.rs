//! `--denoise` on the GPU: raystream-cpu's denoiser (`raystream_cpu::denoise`, the reference)
//! in `kernels/denoise.wgsl`, the same passes in the same f32 arithmetic, so that a GPU frame
//! is filtered where it was traced.

use raystream_cpu::Image;
use raystream_cpu::denoise::{DenoiseOptions, Guides, NoisyFilm};
use raystream_math::Vec3;

use crate::layout::DenoiseParams;
use crate::{GpuContext, GpuError, read_back};

const DENOISE_WGSL: &str = include_str!("kernels/denoise.wgsl");

/// The filter's pipelines.
pub struct GpuDenoiser {
    demodulate: wgpu::ComputePipeline,
    blur: wgpu::ComputePipeline,
    atrous: wgpu::ComputePipeline,
    remodulate: wgpu::ComputePipeline,
}

/// The filter's working buffers for frames of up to [`DenoiseBuffers::pixels`] pixels: the
/// ping-ponged light and variance, the depth slopes and the blurred variance. Every pass writes
/// each pixel of its frame before any pass reads it, so they are reused from frame to frame
/// without clearing (the volume renderer keeps one set across its denoised frames).
pub(crate) struct DenoiseBuffers {
    lights: [wgpu::Buffer; 2],
    vars: [wgpu::Buffer; 2],
    slopes: wgpu::Buffer,
    blurred: wgpu::Buffer,
    pixels: u64,
}

impl DenoiseBuffers {
    pub(crate) fn new(ctx: &GpuContext, pixels: u64) -> Result<DenoiseBuffers, GpuError> {
        let none = wgpu::BufferUsages::empty();
        let light = || ctx.work_buffer("denoised light", 16 * pixels, wgpu::BufferUsages::COPY_SRC);
        let var = || ctx.work_buffer("denoised variance", 4 * pixels, none);
        Ok(DenoiseBuffers {
            lights: [light()?, light()?],
            vars: [var()?, var()?],
            slopes: ctx.work_buffer("depth slopes", 8 * pixels, none)?,
            blurred: ctx.work_buffer("blurred variance", 4 * pixels, none)?,
            pixels,
        })
    }

    /// Whether these buffers hold a frame of `pixels` pixels.
    pub(crate) fn fits(&self, pixels: u64) -> bool {
        pixels <= self.pixels
    }
}

/// The WGSL source of the denoiser's kernels.
pub fn denoise_wgsl() -> &'static str {
    DENOISE_WGSL
}

impl GpuDenoiser {
    pub fn new(ctx: &GpuContext) -> GpuDenoiser {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("denoise.wgsl"),
                source: wgpu::ShaderSource::Wgsl(DENOISE_WGSL.into()),
            });
        GpuDenoiser {
            demodulate: ctx.auto_pipeline(&module, "demodulate"),
            blur: ctx.auto_pipeline(&module, "blur_variance"),
            atrous: ctx.auto_pipeline(&module, "atrous"),
            remodulate: ctx.auto_pipeline(&module, "remodulate"),
        }
    }

    /// `noisy` filtered along `guides` with `opt`, as `raystream_cpu::denoise::denoise`: the
    /// denoised premultiplied light and opacity.
    pub fn denoise(
        &self,
        ctx: &GpuContext,
        noisy: &NoisyFilm,
        guides: &Guides,
        opt: &DenoiseOptions,
    ) -> Result<(Image, Vec<f32>), GpuError> {
        assert_eq!(
            (guides.width, guides.height),
            (noisy.film.width, noisy.film.height),
            "guides are made for their frame's size"
        );
        let n = guides.depth.len();
        // (albedo, depth or −1), then (normal, 0).
        let g: Vec<[f32; 4]> = (0..n)
            .map(|p| {
                let (a, z) = (guides.albedo[p], guides.depth[p]);
                [a.x, a.y, a.z, if z.is_finite() { z } else { -1.0 }]
            })
            .chain(guides.normal.iter().map(|v| [v.x, v.y, v.z, 0.0]))
            .collect();
        let guide_buf = ctx.storage(
            "guides",
            bytemuck::cast_slice(&g),
            wgpu::BufferUsages::empty(),
        )?;
        // The frame as the volume renderer leaves it: (light, 0), then (opacity, variance, 0, 0).
        let frame: Vec<[f32; 4]> = noisy
            .film
            .pixels
            .iter()
            .map(|c| [c.x, c.y, c.z, 0.0])
            .chain(
                noisy
                    .alpha
                    .iter()
                    .zip(&noisy.variance)
                    .map(|(&a, &v)| [a, v, 0.0, 0.0]),
            )
            .collect();
        let frame = ctx.storage(
            "noisy frame",
            bytemuck::cast_slice(&frame),
            wgpu::BufferUsages::empty(),
        )?;
        let size = (noisy.film.width, noisy.film.height);
        let work = DenoiseBuffers::new(ctx, n as u64)?;
        self.filter(
            ctx,
            (&frame, size),
            (&guide_buf, guides.tolerance),
            opt,
            &work,
        )
    }

    /// [`Self::denoise`] of a frame already on the GPU, laid out as the volume renderer's
    /// premultiplied output (per pixel (light, samples), then (opacity, variance of its
    /// luminance, 0, 0)), `size` pixels, along guides laid out as `guide_volume` writes them
    /// (per pixel (albedo, depth or −1), then (normal, 0)), with their depth tolerance.
    /// The filter works in `work`, which must fit the frame.
    pub(crate) fn filter(
        &self,
        ctx: &GpuContext,
        (frame, (w, h)): (&wgpu::Buffer, (u32, u32)),
        guides: (&wgpu::Buffer, f32),
        opt: &DenoiseOptions,
        work: &DenoiseBuffers,
    ) -> Result<(Image, Vec<f32>), GpuError> {
        ctx.scoped(|| {
            let light = self.filter_on_gpu(ctx, (frame, (w, h)), guides, opt, None, work)?;
            let n = w as usize * h as usize;
            let mut out: Vec<[f32; 4]> = read_back(ctx, light)?;
            // The buffers may be larger than the frame.
            out.truncate(n);
            let film = Image {
                width: w,
                height: h,
                pixels: out.iter().map(|c| Vec3::new(c[0], c[1], c[2])).collect(),
            };
            Ok((film, out.iter().map(|c| c[3]).collect()))
        })
    }

    /// [`Self::filter`], its passes submitted and its output left on the GPU, in one of
    /// `work`'s buffers (which must fit the frame): per pixel (premultiplied light, opacity),
    /// or with `over` the light over that background (as `raystream_cpu::dvr::over_background`),
    /// for a frame packed to sRGB there.
    pub(crate) fn filter_on_gpu<'w>(
        &self,
        ctx: &GpuContext,
        (frame, (w, h)): (&wgpu::Buffer, (u32, u32)),
        (guide_buf, tolerance): (&wgpu::Buffer, f32),
        opt: &DenoiseOptions,
        over: Option<Vec3>,
        work: &'w DenoiseBuffers,
    ) -> Result<&'w wgpu::Buffer, GpuError> {
        assert!(
            work.fits(w as u64 * h as u64),
            "the denoiser's buffers fit the frame"
        );
        let DenoiseBuffers {
            lights,
            vars,
            slopes,
            blurred,
            ..
        } = work;
        let params = |gap: u32| {
            let p = DenoiseParams {
                width: w,
                height: h,
                gap,
                sigma_luminance: opt.sigma_luminance,
                sigma_depth: opt.sigma_depth,
                sigma_normal: opt.sigma_normal,
                sigma_albedo: opt.sigma_albedo,
                tolerance,
                demodulate: opt.demodulate,
                over: over.is_some() as u32,
                background: over.unwrap_or_default().to_array(),
                ..Default::default()
            };
            wgpu::util::DeviceExt::create_buffer_init(
                &ctx.device,
                &wgpu::util::BufferInitDescriptor {
                    label: Some("denoise params"),
                    contents: bytemuck::bytes_of(&p),
                    usage: wgpu::BufferUsages::UNIFORM,
                },
            )
        };
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("denoise"),
            });
        // One dispatch of `pipeline` over the frame with these bindings.
        let mut dispatch = |pipeline: &wgpu::ComputePipeline, bindings: &[(u32, &wgpu::Buffer)]| {
            let entries: Vec<_> = bindings
                .iter()
                .map(|&(binding, b)| wgpu::BindGroupEntry {
                    binding,
                    resource: b.as_entire_binding(),
                })
                .collect();
            let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("denoise"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("denoise"),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        };
        let first = params(1);
        dispatch(
            &self.demodulate,
            &[
                (0, &first),
                (2, &lights[0]),
                (4, &vars[0]),
                (5, guide_buf),
                (6, slopes),
                (8, frame),
            ],
        );
        let mut at = 0;
        let pass_params: Vec<wgpu::Buffer> = (0..opt.passes).map(|k| params(1 << k)).collect();
        for p in &pass_params {
            let (i, o) = (at, 1 - at);
            dispatch(&self.blur, &[(0, p), (3, &vars[i]), (7, blurred)]);
            dispatch(
                &self.atrous,
                &[
                    (0, p),
                    (1, &lights[i]),
                    (2, &lights[o]),
                    (3, &vars[i]),
                    (4, &vars[o]),
                    (5, guide_buf),
                    (6, slopes),
                    (7, blurred),
                ],
            );
            at = o;
        }
        dispatch(
            &self.remodulate,
            &[
                (0, &first),
                (1, &lights[at]),
                (2, &lights[1 - at]),
                (5, guide_buf),
            ],
        );
        ctx.queue.submit([enc.finish()]);
        Ok(&lights[1 - at])
    }
}
