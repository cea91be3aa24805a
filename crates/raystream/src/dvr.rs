//! Direct volume rendering for `render --mode` and `bench --mode`: the options from the command
//! line, and one frame on the CPU (the reference) or the GPU behind one call.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use anyhow::{Result, bail};
use raystream_cpu::denoise::DenoiseTimes;
use raystream_cpu::dvr::{
    CpuVolume, DvrMode, DvrOptions, DvrStats, Interpolation, Sight, over_background, render_volume,
};
use raystream_cpu::segments::SegmentColours;
use raystream_cpu::{Image, ImageFormat};
use raystream_gpu::GpuVolumeRenderer;
use raystream_io::Volume;
use raystream_math::Vec3;
use raystream_volume::{TfPreset, TransferFunction};

use crate::cli::{Threshold, VolumeLook, WindowArg};
use crate::common::{Backend, Picture, ms};

/// For a volume whose values have no known unit (an 8-bit scientific-visualisation scan, MR),
/// the defaults the user did not override come from its values
/// ([`raystream_volume::auto`]), since the HU presets' mean nothing there (CT-Bone made an
/// 8-bit scan a uniform pink box, the CT windows a grey one): dvr and cinematic take a ramp
/// from their Otsu threshold (the background transparent) to the top of their robust range
/// (their largest value but for one in 10⁴), and iso the surface at that threshold in the
/// ramp's colours, unless `--tf`, `--preset` or `--iso` says; a slice a window spanning
/// them less 0.5 % at each end, unless `--window` says. Said unless `quiet`.
/// The projections' (mip, minip, average) window is left to [`ProjectionWindow`]: they do not
/// span the voxels' range (an average of a scan mostly air reached a third of it).
pub fn unit_free_defaults(
    (look, threshold): (&VolumeLook, &Threshold),
    (volume, path): (&Volume, &std::path::Path),
    quiet: bool,
    tf: &mut TransferFunction,
    opt: &mut DvrOptions,
) -> Option<ProjectionWindow> {
    if volume.unit == raystream_io::ValueUnit::Hounsfield {
        return None;
    }
    let (lo, hi) = raystream_volume::auto::finite_range(&volume.data)?;
    let say = |what: String| {
        if !quiet {
            eprintln!(
                "raystream: {}: values of no known unit ({lo} .. {hi}): {what}",
                path.display()
            );
        }
    };
    let transfer = matches!(opt.mode, DvrMode::Dvr | DvrMode::Cinematic | DvrMode::Iso);
    if transfer && look.tf.is_none() && threshold.preset.is_none() {
        let (ramp, t) = raystream_volume::auto::unit_free_transfer(volume)?;
        *tf = ramp;
        if opt.mode == DvrMode::Iso {
            if threshold.iso.is_none() {
                opt.iso_hu = t;
                say(format!(
                    "the surface at {t}, their Otsu threshold (between the background and the object; --iso V sets another), in a ramp's colours"
                ));
            }
        } else {
            let top = tf.opacity.last().map_or(hi, |p| p.0);
            let beyond = if top < hi {
                ", their largest but for one in 10⁴ (so that a few outliers do not set it)"
            } else {
                ""
            };
            say(format!(
                "opacity ramped from 0 at {t}, their Otsu threshold (the background transparent), to {top}{beyond} (--tf FILE sets another)"
            ));
        }
    } else if opt.mode.is_projection() && opt.window.is_none() {
        return Some(ProjectionWindow {
            range: (lo, hi),
            robust: raystream_volume::auto::robust_range(&volume.data)?,
            path: path.to_owned(),
            quiet,
        });
    } else if opt.mode.is_windowed() && opt.window.is_none() && hi > lo {
        let tail = raystream_volume::auto::CLIPPED_TAIL;
        match raystream_volume::auto::clipped_range(&volume.data, tail) {
            Some((a, b)) if b > a => {
                opt.window = Some(spanning(a, b));
                say(format!(
                    "the window spans them less {} % at each end, {} .. {} (--window W --level L sets another)",
                    tail * 100.0,
                    four_figures(a),
                    four_figures(b)
                ));
            }
            _ => {
                opt.window = Some(spanning(lo, hi));
                say("the window spans them (--window W --level L sets another)".into());
            }
        }
    }
    None
}

/// The window (width, level) from `lo` to `hi`.
fn spanning(lo: f32, hi: f32) -> (f32, f32) {
    (hi - lo, 0.5 * (lo + hi))
}

/// `v` to four significant figures, without trailing zeros (85.19, 0.04172, 1235, 207).
fn four_figures(v: f32) -> String {
    if v == 0.0 || !v.is_finite() {
        return v.to_string();
    }
    let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Pixels along the longer side of the film [`ProjectionWindow::set_by_probe`] renders.
const PROBE_PIXELS: u32 = 128;

/// A projection's window for values of no known unit, still to be set: from the projection
/// itself, as an image viewer's auto-contrast sets it, since the projected values need not
/// span the voxels' (on the SciVis bonsai, an 8-bit scan, the average of the rays reached
/// 94 of its 255 and its minimum 44, which a window over 0 .. 255 showed near black).
#[must_use = "the window is still to be set"]
pub struct ProjectionWindow {
    /// The voxels' finite range.
    range: (f32, f32),
    /// Their robust range (`raystream_volume::auto::robust_range`), the window where the
    /// projection does not give one.
    robust: (f32, f32),
    path: std::path::PathBuf,
    quiet: bool,
}

impl ProjectionWindow {
    /// The window spanning the voxels' robust range, for frames nobody looks at (a
    /// benchmark's).
    pub fn spanning_the_voxels(self, opt: &mut DvrOptions) {
        opt.window = Some(spanning(self.robust.0, self.robust.1));
    }

    /// The window spanning the projected values of a probe frame seen by `sight` (at most
    /// [`PROBE_PIXELS`] along its longer side, the film's aspect kept), less
    /// [`raystream_volume::auto::CLIPPED_TAIL`] at each end; the voxels' robust range where
    /// the probe sees one value or none. Said unless quiet.
    pub fn set_by_probe<'s>(
        self,
        renderer: &Renderer,
        opt: &mut DvrOptions,
        sight: impl Into<Sight<'s>>,
    ) -> Result<()> {
        let scale = (PROBE_PIXELS as f32 / opt.width.max(opt.height) as f32).min(1.0);
        let side = |n: u32| ((n as f32 * scale).round() as u32).max(1);
        let probe = DvrOptions {
            width: side(opt.width),
            height: side(opt.height),
            hu_values: true,
            ..*opt
        };
        let (film, _) = renderer.film(&probe, sight.into())?;
        let values: Vec<f32> = film.pixels.iter().map(|p| p.x).collect();
        let tail = raystream_volume::auto::CLIPPED_TAIL;
        let (lo, hi) = self.range;
        let words = match raystream_volume::auto::clipped_range(&values, tail) {
            Some((a, b)) if b > a => {
                opt.window = Some(spanning(a, b));
                format!(
                    "the window spans the {}'s values less {} % at each end, {} .. {}",
                    opt.mode.name(),
                    tail * 100.0,
                    four_figures(a),
                    four_figures(b)
                )
            }
            _ => {
                let (a, b) = self.robust;
                opt.window = Some(spanning(a, b));
                format!(
                    "the {} sees one value or none: the window spans them but for one in 10⁴ at each end, {} .. {}",
                    opt.mode.name(),
                    four_figures(a),
                    four_figures(b)
                )
            }
        };
        if !self.quiet {
            eprintln!(
                "raystream: {}: values of no known unit ({lo} .. {hi}): {words} (--window W --level L sets another)",
                self.path.display()
            );
        }
        Ok(())
    }
}

/// The transfer function and options `--mode MODE` asks for, checked.
pub fn options(
    look: &VolumeLook,
    threshold: &Threshold,
    mode: DvrMode,
    (width, height): (u32, u32),
) -> Result<(TransferFunction, DvrOptions)> {
    let tf = match (&look.tf, threshold.preset) {
        (Some(f), _) => TransferFunction::load(f).map_err(anyhow::Error::msg)?,
        (None, Some(p)) => match p.transfer() {
            Some(t) => t.function(),
            None if mode == DvrMode::Iso => TfPreset::CtBone.function(),
            None => bail!(
                "--preset {}: a threshold; --mode {} takes a transfer function: ct-bone, ct-bones, ct-aaa, ct-muscle, ct-lung, mip-bone (or --tf FILE)",
                p.name(),
                mode.name()
            ),
        },
        (None, None) => TfPreset::CtBone.function(),
    };
    if let Some(s) = look.step
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--step {s}: the step must be a positive number of mm");
    }
    let window = match (look.window, look.level) {
        (None, _) => None,
        (Some(WindowArg::Named(name, ..)), Some(_)) => {
            bail!("--window {name} sets the level too; give --window W --level L for another level")
        }
        (Some(WindowArg::Named(_, w, l)), None) => Some((w, l)),
        (Some(WindowArg::Width(w)), None) => bail!(
            "--window {w} needs --level L (or name a window: {})",
            crate::cli::window_names()
        ),
        (Some(WindowArg::Width(w)), Some(_)) if !(w.is_finite() && w > 0.0) => {
            bail!("--window {w}: the window must be a positive number of HU")
        }
        (Some(WindowArg::Width(_)), Some(l)) if !l.is_finite() => {
            bail!("--level {l}: the level must be a finite number of HU")
        }
        (Some(WindowArg::Width(w)), Some(l)) => Some((w, l)),
    };
    if mode == DvrMode::Cinematic {
        if look.shadows {
            bail!(
                "--shadows: --mode cinematic always casts shadows (every scattering samples the key light through the volume)"
            );
        }
        if look.step.is_some() || look.no_skip {
            bail!(
                "--step and --no-skip set dvr's sample lattice; --mode cinematic has none (its free flights are exact, brick by brick)"
            );
        }
    }
    if mode != DvrMode::Cinematic {
        for (flag, given) in [
            ("--anisotropy", look.anisotropy.is_some()),
            ("--exposure", look.exposure.is_some()),
        ] {
            if given {
                bail!(
                    "{flag} sets the light of --mode cinematic's paths (--mode {} has none)",
                    mode.name()
                );
            }
        }
    }
    if let Some(g) = look.anisotropy
        && !(g.is_finite() && g.abs() <= 0.95)
    {
        bail!(
            "--anisotropy {g}: the mean cosine of the scattering angle, from -0.95 to 0.95 (0: isotropic)"
        );
    }
    if let Some(ev) = look.exposure
        && !(ev.is_finite() && ev.abs() <= 10.0)
    {
        bail!("--exposure {ev}: stops from -10 to 10");
    }
    if look.denoise && mode != DvrMode::Cinematic {
        bail!(
            "--denoise filters the noise of --mode cinematic's paths (--mode {} has none to filter)",
            mode.name()
        );
    }
    if look.light.is_some() && !(mode == DvrMode::Cinematic || look.shadows) {
        bail!(
            "--light places the key light of --mode dvr --shadows and --mode cinematic (--mode {} without it has a headlight or none)",
            mode.name()
        );
    }
    if look.shadows && mode != DvrMode::Dvr {
        bail!(
            "--shadows goes with --mode dvr (--mode {} has no lighting to shadow)",
            mode.name()
        );
    }
    if look.slice_at.is_some() && mode != DvrMode::Slice && look.slab.is_none() {
        bail!(
            "--slice-at places the plane of --mode slice or the middle of a --slab (not --mode {} alone)",
            mode.name()
        );
    }
    if let Some(t) = look.slab {
        if !(t.is_finite() && t > 0.0) {
            bail!("--slab {t}: the slab must be a positive number of mm thick");
        }
        if mode == DvrMode::Slice {
            bail!(
                "--slab thickens a plane for the other modes (a slab MIP, say); --mode slice is the plane itself"
            );
        }
    }
    if look.clip_planes.len() > 2 {
        bail!(
            "--clip-plane given {} times: at most two clip planes",
            look.clip_planes.len()
        );
    }
    let plane = |i: usize| {
        look.clip_planes
            .get(i)
            .map(|p| (Vec3::new(p[0], p[1], p[2]), p[3]))
    };
    let opt = DvrOptions {
        width,
        height,
        mode,
        step_mm: look.step,
        window,
        iso_hu: if mode == DvrMode::Iso {
            threshold
                .iso
                .unwrap_or(match threshold.preset.and_then(|p| p.threshold()) {
                    Some(t) => t.hu(),
                    None => raystream_volume::Preset::Bone.hu(),
                })
        } else {
            0.0
        },
        skip_empty: !look.no_skip,
        shadows: look.shadows,
        crop: look
            .crop
            .map(|c| [Vec3::new(c[0], c[1], c[2]), Vec3::new(c[3], c[4], c[5])]),
        clip_planes: [plane(0), plane(1)],
        slice_at: look.slice_at.map(Vec3::from_array),
        slab: look.slab,
        light: look.light,
        denoise: look.denoise,
        anisotropy: look.anisotropy.unwrap_or(0.0),
        exposure: look.exposure.unwrap_or(0.0),
        interpolation: look
            .interpolation
            .map_or_else(|| default_interpolation(mode), Into::into),
        ..Default::default()
    };
    Ok((tf, opt))
}

/// How `--mode MODE` reads the volume without `--interpolation`: the shaded modes by the cubic
/// B-spline, whose continuous gradient keeps a coarse CT's surfaces free of the wood-grain
/// rings that trilinear shading draws a voxel apart; the modes that show values themselves
/// (projections and slices, what a radiologist reads HU from) trilinearly, as a PACS viewer
/// does, so that a small bright structure keeps its peak.
pub fn default_interpolation(mode: DvrMode) -> Interpolation {
    match mode {
        DvrMode::Dvr | DvrMode::Iso | DvrMode::Cinematic => Interpolation::Cubic,
        DvrMode::Mip | DvrMode::MinIp | DvrMode::Average | DvrMode::Slice => Interpolation::Linear,
    }
}

/// Renders frames of one volume on the CPU or the GPU.
pub enum Renderer<'a> {
    Cpu {
        /// The volume, with its spline coefficients, brick tables and majorants kept from frame
        /// to frame.
        volume: Box<CpuVolume<'a>>,
        /// Cinematic paths traced so far (a progress bar's count).
        done: AtomicU64,
    },
    Gpu(Box<GpuVolumeRenderer<'a>>),
}

/// One frame, as it is written, and what it cost.
pub struct Frame {
    /// 8-bit sRGB for a PNG (converted on the GPU there: a fifth of the float pixels' bytes
    /// to read back); for an EXR the windowed modes' HU values, or dvr's and iso's
    /// premultiplied RGBA.
    pub picture: Picture,
    /// Wall time, milliseconds: the whole render on the CPU; submission to the pixels on the
    /// host on the GPU.
    pub frame_ms: f64,
    /// The GPU kernel's own time (timestamp queries).
    pub kernel_ms: Option<f64>,
    /// Samples taken by the primary rays (counted by the renderer that ran).
    pub samples: u64,
    /// The CPU path's full statistics (skipped and shadow samples too).
    pub stats: Option<DvrStats>,
    /// cinematic `--denoise`: what the guides and the filter took, on the device that drew the frame.
    pub denoise: Option<DenoiseTimes>,
}

impl<'a> Renderer<'a> {
    /// The frames of `volume` through `tf` on `backend`, their dvr, iso and cinematic samples
    /// coloured by `segments` where given; `weights`: mip, minip and average kept to segments
    /// ([`crate::segments::Painted::weights`]).
    pub fn new(
        backend: &'a Backend,
        volume: &'a Volume,
        tf: &'a TransferFunction,
        segments: Option<&'a SegmentColours>,
        weights: Option<&'a Volume>,
    ) -> Result<Renderer<'a>> {
        Ok(match backend {
            Backend::Gpu(ctx) => Renderer::Gpu(Box::new(GpuVolumeRenderer::segmented(
                ctx, volume, tf, segments, weights,
            )?)),
            Backend::Cpu => Renderer::Cpu {
                volume: Box::new(CpuVolume::new(volume, tf).painted(segments).kept(weights)),
                done: AtomicU64::new(0),
            },
        })
    }

    /// Makes what frames read as `interpolation` need before any frame does (the interpolating
    /// spline's coefficients, and on the GPU their texture).
    pub fn prepare(&self, interpolation: Interpolation) -> Result<()> {
        match self {
            Renderer::Gpu(g) => g.prepare(interpolation)?,
            Renderer::Cpu { volume, .. } => {
                volume.grid(interpolation);
            }
        }
        Ok(())
    }

    /// Cinematic paths traced so far, on either device (a progress bar's count).
    pub fn paths_done(&self) -> u64 {
        match self {
            Renderer::Cpu { done, .. } => done.load(Ordering::Relaxed),
            Renderer::Gpu(g) => g.paths_done.load(Ordering::Relaxed),
        }
    }

    /// One frame seen by `sight` (a camera or a curved plane), as `format` writes it: for an
    /// EXR, the windowed modes' film (their HU values with `opt.hu_values`), or dvr's and iso's
    /// premultiplied RGBA (one pass).
    pub fn frame<'s>(
        &self,
        opt: &DvrOptions,
        sight: impl Into<Sight<'s>>,
        format: ImageFormat,
    ) -> Result<Frame> {
        let sight: Sight = sight.into();
        let t = Instant::now();
        let hu = opt.mode.is_windowed() && opt.hu_values;
        if let (Renderer::Gpu(g), ImageFormat::Png, false) = (self, format, hu) {
            let (rgb, times) = g.render_srgb8(opt, sight)?;
            let picture = Picture::Srgb8 {
                rgb,
                width: opt.width,
                height: opt.height,
            };
            return Ok(Frame {
                picture,
                frame_ms: ms(t.elapsed()),
                kernel_ms: times.kernel_gpu_ms,
                samples: times.samples,
                stats: None,
                denoise: times.denoise,
            });
        }
        if format == ImageFormat::Exr && !opt.mode.is_windowed() {
            // dvr and iso to an EXR: premultiplied RGBA, for compositing, in one pass: each
            // pixel's light C and opacity 1 − T, so that over a background B it is C + T·B.
            let (film, alpha, kernel_ms, samples, stats, denoise) = match self {
                Renderer::Gpu(g) => {
                    let (film, alpha, times) = g.render_rgba(opt, sight)?;
                    let (k, n) = (times.kernel_gpu_ms, times.samples);
                    (film, alpha, k, n, None, times.denoise)
                }
                Renderer::Cpu { volume, done } => {
                    let (film, alpha, stats) = volume.render_rgba_counted(opt, sight, done);
                    (film, alpha, None, stats.samples, Some(stats), stats.denoise)
                }
            };
            return Ok(Frame {
                picture: Picture::Rgba { film, alpha },
                frame_ms: ms(t.elapsed()),
                kernel_ms,
                samples,
                stats,
                denoise,
            });
        }
        let (film, cost) = self.film(opt, sight)?;
        let picture = if hu {
            Picture::Values(film)
        } else {
            Picture::of_film(film, format)
        };
        Ok(Frame {
            picture,
            frame_ms: ms(t.elapsed()),
            kernel_ms: cost.kernel_ms,
            samples: cost.samples,
            stats: cost.stats,
            denoise: cost.denoise,
        })
    }
}

impl Renderer<'_> {
    fn film(&self, opt: &DvrOptions, sight: Sight) -> Result<(Image, FilmCost)> {
        Ok(match self {
            Renderer::Gpu(g) => {
                let (film, times) = g.render(opt, sight)?;
                let cost = FilmCost {
                    kernel_ms: times.kernel_gpu_ms,
                    samples: times.samples,
                    stats: None,
                    denoise: times.denoise,
                };
                (film, cost)
            }
            Renderer::Cpu { volume, done } if opt.mode == DvrMode::Cinematic => {
                // Counted as its paths are traced, laid over the background here.
                let (film, alpha, stats) = volume.render_rgba_counted(opt, sight, done);
                let film = over_background(film, &alpha, opt.background);
                (film, FilmCost::of_cpu(stats))
            }
            Renderer::Cpu { volume, .. } => {
                let (film, stats) = volume.render(opt, sight);
                (film, FilmCost::of_cpu(stats))
            }
        })
    }
}

/// What a frame's film cost: [`Frame`]'s figures but the wall time.
struct FilmCost {
    kernel_ms: Option<f64>,
    samples: u64,
    stats: Option<DvrStats>,
    denoise: Option<DenoiseTimes>,
}

impl FilmCost {
    /// The CPU's figures, from its statistics.
    fn of_cpu(stats: DvrStats) -> FilmCost {
        FilmCost {
            kernel_ms: None,
            samples: stats.samples,
            stats: Some(stats),
            denoise: stats.denoise,
        }
    }
}

/// The skipped and shadow samples of a frame the GPU rendered (it counts only the samples it
/// takes), estimated on the CPU path's marcher (the same lattice) at no more than 256×256; the
/// light grid's shadow samples are the same at any image size.
pub fn estimate_stats(
    volume: &Volume,
    tf: &TransferFunction,
    opt: &DvrOptions,
    sight: Sight,
) -> DvrStats {
    // A curved plane's rows are fixed to its image's size: it is counted as it is.
    if let Sight::Curved(_) = sight {
        return render_volume(volume, tf, opt, sight).1;
    }
    let small = DvrOptions {
        width: opt.width.min(256),
        height: opt.height.min(256),
        ..*opt
    };
    let (_, s) = render_volume(volume, tf, &small, sight);
    let scale = (opt.width as f64 * opt.height as f64) / (small.width as f64 * small.height as f64);
    let up = |n: u64| (n as f64 * scale) as u64;
    DvrStats {
        samples: up(s.samples),
        skipped: up(s.skipped),
        // The light grid does not depend on the image size.
        shadow_samples: s.shadow_samples,
        step_mm: s.step_mm,
        denoise: None,
    }
}

#[cfg(test)]
mod tests {
    use super::four_figures;

    #[test]
    fn four_figures_round_and_drop_trailing_zeros() {
        assert_eq!(four_figures(85.190025), "85.19");
        assert_eq!(four_figures(207.0), "207");
        assert_eq!(four_figures(1234.56), "1235");
        assert_eq!(four_figures(-0.041_723), "-0.04172");
        assert_eq!(four_figures(0.5), "0.5");
        assert_eq!(four_figures(123_456.0), "123456");
        assert_eq!(four_figures(0.0), "0");
    }
}
