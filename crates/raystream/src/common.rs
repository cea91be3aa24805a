//! Pieces the commands share: device choice, inputs, progress, timing, machine description.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use raystream_accel::{Isa, KdTree};
use raystream_cpu::{ExrSamples, Image, ImageFormat, RenderQueues};
use raystream_gpu::{GpuContext, GpuError, GpuTracer};
use raystream_io::TriMesh;

use crate::cli::Device;

/// Where a command runs.
pub enum Backend {
    Cpu,
    Gpu(Box<GpuContext>),
}

impl Backend {
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu(_) => "gpu",
        }
    }

    /// The adapter's or the CPU's description.
    pub fn adapter(&self) -> String {
        match self {
            Backend::Cpu => cpu_model(),
            Backend::Gpu(ctx) => ctx.describe(),
        }
    }
}

/// Environment variable `name` set to `on` (true) or `off` (false); `None` where it is unset;
/// any other value refused, naming both.
fn env_switch(
    ctx: &GpuContext,
    name: &str,
    [on, off]: [&str; 2],
) -> Result<Option<bool>, GpuError> {
    match std::env::var(name) {
        Err(_) => Ok(None),
        Ok(v) if v == on => Ok(Some(true)),
        Ok(v) if v == off => Ok(Some(false)),
        Ok(v) => Err(GpuError::Wgpu(
            format!("{name}={v:?}: {on} or {off}"),
            ctx.info.name.clone(),
        )),
    }
}

/// Environment variable `name` as a number of `what`; `None` where it is unset.
fn env_count(ctx: &GpuContext, name: &str, what: &str) -> Result<Option<u32>, GpuError> {
    match std::env::var(name) {
        Err(_) => Ok(None),
        Ok(v) => v.trim().parse().map(Some).map_err(|_| {
            GpuError::Wgpu(
                format!("{name}={v:?} is not a number of {what}"),
                ctx.info.name.clone(),
            )
        }),
    }
}

/// Opens the device: `gpu` fails clearly when no adapter opens; `auto` takes a hardware GPU
/// when there is one and otherwise the CPU path (a software adapter such as lavapipe is far
/// slower than the CPU path), and says which it used.
pub fn open_device(d: Device, adapter: Option<&str>, quiet: bool) -> Result<Backend> {
    // Waits for a hardware GPU poll its fence before they block: on the H200 that made every
    // `trace` row 2-45 % faster by wall time (BENCHMARKS.md, 2026-12-04); a software adapter
    // blocks, since the CPU that would spin is the one rendering. `RAYSTREAM_GPU_WAIT=spin` or
    // `block` chooses either. `RAYSTREAM_GPU_PIXELS=blocks|rows`: the stream renderer's camera
    // rays in blocks of pixels or row by row (GpuContext::set_pixel_blocks; the same image).
    // `RAYSTREAM_GPU_WAVE=N`: at most N samples a wave of the stream renderer (an experiment).
    // `RAYSTREAM_GPU_CHECKS=on`: the kd-tree kernels with wgpu's run-time checks (off by
    // default: 1.12-1.27x faster on the H200; GpuContext::set_unchecked_kernels says why it is
    // sound).
    // `RAYSTREAM_GPU_WORKGROUP=N`: the ray-query kernels' threads per
    // workgroup (an experiment for `trace`; see BENCHMARKS.md).
    // `RAYSTREAM_GPU_TIMESTAMPS=off`: no timestamp queries (no kernel times; what they add to
    // a query's wall time, device-bench.sh's floor part).
    // `RAYSTREAM_GPU_APPENDS=subgroup|atomic`: the stream renderer's `shade_hits` and the split
    // kernels reserve queue slots a subgroup at a time (the default where the adapter has
    // subgroups) or a lane at a time (GpuContext::set_subgroup_appends; the same image and hits).
    // `RAYSTREAM_GPU_PLANES=f64|f32`: the triangle test places the planes of triangles too large
    // for f32 in f64 (the default where the adapter has f64, as the CPU does) or leaves them in
    // f32 (GpuContext::set_f64_planes: what the path costs).
    let open = |adapter| {
        GpuContext::new(adapter).and_then(|mut ctx| {
            let spin = env_switch(&ctx, "RAYSTREAM_GPU_WAIT", ["spin", "block"])?;
            ctx.set_spin_wait(spin.unwrap_or(!ctx.is_software()));
            if let Some(blocks) = env_switch(&ctx, "RAYSTREAM_GPU_PIXELS", ["blocks", "rows"])? {
                ctx.set_pixel_blocks(blocks);
            }
            if let Some(checked) = env_switch(&ctx, "RAYSTREAM_GPU_CHECKS", ["on", "off"])? {
                ctx.set_unchecked_kernels(!checked);
            }
            if let Some(samples) = env_count(&ctx, "RAYSTREAM_GPU_WAVE", "samples")? {
                ctx.set_render_wave(samples)?;
            }
            if let Some(on) = env_switch(&ctx, "RAYSTREAM_GPU_TIMESTAMPS", ["on", "off"])? {
                ctx.set_timestamps(on);
            }
            if let Some(on) = env_switch(&ctx, "RAYSTREAM_GPU_APPENDS", ["subgroup", "atomic"])? {
                ctx.set_subgroup_appends(on);
            }
            if let Some(on) = env_switch(&ctx, "RAYSTREAM_GPU_PLANES", ["f64", "f32"])? {
                ctx.set_f64_planes(on);
            }
            if let Some(threads) = env_count(&ctx, "RAYSTREAM_GPU_WORKGROUP", "threads")? {
                ctx.set_query_workgroup(threads)?;
            }
            Ok(ctx)
        })
    };
    match d {
        Device::Cpu => Ok(Backend::Cpu),
        Device::Gpu => Ok(Backend::Gpu(Box::new(
            open(adapter).context("--device gpu")?,
        ))),
        Device::Auto => {
            let backend = match open(adapter) {
                Ok(ctx) if !ctx.is_software() => Backend::Gpu(Box::new(ctx)),
                Ok(ctx) => {
                    if !quiet {
                        eprintln!(
                            "raystream: '{}' is a software adapter; using the CPU path (--device gpu forces it)",
                            ctx.info.name
                        );
                    }
                    Backend::Cpu
                }
                Err(e) => {
                    if !quiet {
                        eprintln!("raystream: {e}; using the CPU path");
                    }
                    Backend::Cpu
                }
            };
            if !quiet {
                eprintln!(
                    "raystream: device: {} ({})",
                    backend.name(),
                    backend.adapter()
                );
            }
            Ok(backend)
        }
    }
}

/// The GPU tracer of `tree`, built from `input` (the tree uploaded once, for every query on
/// it), or `None` on the CPU. A tree too large for the GPU's buffers is an error naming the
/// input and the adapter.
pub fn gpu_tracer<'a>(
    backend: &'a Backend,
    tree: &KdTree,
    input: &Path,
) -> Result<Option<GpuTracer<'a>>> {
    Ok(match backend {
        Backend::Gpu(ctx) => Some(GpuTracer::new(ctx, tree).with_context(|| {
            format!(
                "{}: its kd-tree ({} triangle references) on {}",
                input.display(),
                tree.tris.len(),
                ctx.describe()
            )
        })?),
        Backend::Cpu => None,
    })
}

/// A frame as it is written: 8-bit sRGB (3 bytes a pixel) for a PNG, or for an EXR the
/// linear float film (R, G, B) or, for the windowed modes (projections, slices), their HU
/// values (Y).
pub enum Picture {
    Srgb8 {
        rgb: Vec<u8>,
        width: u32,
        height: u32,
    },
    Film(Image),
    /// Premultiplied colour and opacity (R, G, B, A): what a volume sends toward the eye and
    /// how much of what lies behind it hides.
    Rgba {
        film: Image,
        alpha: Vec<f32>,
    },
    /// One value a pixel (the film's first channel), written as channel Y.
    Values(Image),
}

impl Picture {
    /// `film` as `format` writes it: 8-bit sRGB for a PNG, the film itself for an EXR.
    pub fn of_film(film: Image, format: ImageFormat) -> Picture {
        match format {
            ImageFormat::Png => Picture::Srgb8 {
                rgb: film.to_srgb8(),
                width: film.width,
                height: film.height,
            },
            ImageFormat::Exr => Picture::Film(film),
        }
    }

    /// Writes the picture to `path`: PNG for 8-bit sRGB, else EXR, `what` saying what the
    /// values are in the EXR's comments; where `path` ends in `.dcm`, a DICOM Secondary Capture
    /// image of the input's study ([`set_source_study`]), as `dicom` describes it: the 8-bit
    /// sRGB frame, or a projection's or slice's HU values as 16-bit greyscale with its window.
    pub fn save(&self, path: &Path, what: &str, dicom: &DicomOut) -> Result<()> {
        match self {
            Picture::Srgb8 { rgb, width, height } if is_dicom(path) => dicom.write(
                path,
                raystream_io::CapturePixels::Rgb8(rgb),
                (*width, *height),
            ),
            Picture::Values(film) if is_dicom(path) => {
                let values: Vec<f32> = film.pixels.iter().map(|p| p.x).collect();
                let window = dicom
                    .window
                    .expect("a projection's DICOM picture is given its window");
                dicom.write(
                    path,
                    raystream_io::CapturePixels::Hu {
                        values: &values,
                        window,
                    },
                    (film.width, film.height),
                )
            }
            Picture::Srgb8 { rgb, width, height } => {
                raystream_cpu::save_srgb8_png(path, rgb, *width, *height)
            }
            Picture::Film(film) => film.save_exr(path, what),
            Picture::Rgba { film, alpha } => {
                let mut channels = film.exr_channels();
                channels.push(("A", ExrSamples::F32(alpha.clone())));
                raystream_cpu::save_exr(path, film.width, film.height, channels, what)
            }
            Picture::Values(film) => raystream_cpu::save_exr(
                path,
                film.width,
                film.height,
                vec![(
                    "Y",
                    ExrSamples::F32(film.pixels.iter().map(|p| p.x).collect()),
                )],
                what,
            ),
        }
        .map_err(anyhow::Error::msg)
    }

    /// 8-bit sRGB pixels (3 bytes a pixel), as a viewer shows the frame.
    pub fn into_srgb8(self) -> Vec<u8> {
        match self {
            Picture::Srgb8 { rgb, .. } => rgb,
            Picture::Film(film) | Picture::Values(film) | Picture::Rgba { film, .. } => {
                film.to_srgb8()
            }
        }
    }
}

/// The image format `-o` names (`.png` or `.exr`, or `.dcm`: a PNG's pixels as a DICOM
/// Secondary Capture image), checked before any work.
pub fn image_format(output: &Path) -> Result<ImageFormat> {
    if is_dicom(output) {
        return Ok(ImageFormat::Png);
    }
    ImageFormat::of(output)
        .map_err(|e| anyhow::anyhow!("{e}, or .dcm (a DICOM Secondary Capture image)"))
}

/// Whether `path` names a DICOM file (`.dcm`, any case).
pub fn is_dicom(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("dcm"))
}

/// What a DICOM picture says beyond its pixels.
#[derive(Clone, Debug, Default)]
pub struct DicomOut {
    /// Patient Orientation: the patient directions of the rows and the columns.
    pub orientation: Option<[String; 2]>,
    /// Whether letters were drawn into the pixels (Burned In Annotation).
    pub annotated: bool,
    /// How the picture was made (the series' and the derivation's description).
    pub description: String,
    /// The series (UID) it belongs to and its number there: a turntable's frames; a series of
    /// its own where `None`.
    pub series: Option<(String, u32)>,
    /// HU pictures (projections, slices): the window (width, level) they were shown in.
    pub window: Option<(f32, f32)>,
    /// HU pictures sampled on a plane (a slice, a slab seen square on): where their pixels lie,
    /// which makes them a reformatted CT image.
    pub plane: Option<raystream_io::ImagePlane>,
}

impl DicomOut {
    fn write(
        &self,
        path: &Path,
        pixels: raystream_io::CapturePixels,
        size: (u32, u32),
    ) -> std::result::Result<(), String> {
        raystream_io::write_secondary_capture(
            path,
            pixels,
            size,
            &raystream_io::CaptureInfo {
                study: SOURCE_STUDY.get(),
                series: self.series.as_ref().map(|(uid, n)| (uid.as_str(), *n)),
                description: &self.description,
                orientation: self.orientation.clone(),
                annotated: self.annotated,
                plane: self.plane,
            },
        )
        .map_err(|e| e.to_string())
    }
}

/// This run's options as words, for a DICOM picture's description: `raystream render --mode
/// mip …`, without the paths of the input and the output (they may name the patient).
pub fn options_in_words(input: Option<&Path>, output: &Path) -> String {
    let args: Vec<String> = std::env::args_os()
        .skip(1)
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    words_without_paths(&args, input, output)
}

/// `raystream` and `args`, without the input, the output and the option that names the output
/// (`-o OUT`, `--plot OUT`, `--plot=OUT`) or any `-o`/`--output`, and with every other file or
/// folder named (a path, a transfer function) as `FILE`.
fn words_without_paths(args: &[String], input: Option<&Path>, output: &Path) -> String {
    let names = |a: &str, p: &Path| Path::new(a) == p;
    let mut words = vec!["raystream".to_string()];
    let mut k = 0;
    while k < args.len() {
        let a = &args[k];
        let (option, value) = match a.split_once('=') {
            Some((o, v)) if o.starts_with("--") => (Some(o), Some(v)),
            _ => (None, None),
        };
        // `-o X`, or an option whose value is the output (`--plot OUT`): both words go.
        let drops_next = matches!(a.as_str(), "-o" | "--output")
            || a.starts_with('-') && args.get(k + 1).is_some_and(|n| names(n, output));
        if option.is_none() && drops_next {
            k += 2;
            continue;
        }
        k += 1;
        if let (Some(o), Some(v)) = (option, value) {
            if names(v, output) || o == "--output" {
                continue;
            }
            let v = if Path::new(v).exists() { "FILE" } else { v };
            words.push(format!("{o}={v}"));
        } else if names(a, output) || input.is_some_and(|p| names(a, p)) {
            continue;
        } else if !a.starts_with('-') && Path::new(a).exists() {
            words.push("FILE".to_string());
        } else {
            words.push(a.clone());
        }
    }
    words.join(" ")
}

/// The study of the DICOM series this run read, which a `.dcm` output joins (one input a run).
static SOURCE_STUDY: std::sync::OnceLock<raystream_io::DicomStudy> = std::sync::OnceLock::new();

/// Records the study of the DICOM series read, for a `.dcm` output.
pub fn set_source_study(study: &raystream_io::DicomStudy) {
    let _ = SOURCE_STUDY.set(study.clone());
}

pub fn load_mesh(path: &Path) -> Result<TriMesh> {
    Ok(raystream_io::load_mesh(path)?)
}

pub fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// The first value of `v` that a label map cannot hold (a whole number from 0), if any.
pub fn not_a_label(v: &raystream_io::Volume) -> Option<f32> {
    v.data
        .iter()
        .copied()
        .find(|v| !(v.is_finite() && *v >= 0.0 && v.fract() == 0.0))
}

/// A spinner with a message, hidden with `--quiet`.
pub fn spinner(quiet: bool, msg: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} [{elapsed}]").unwrap());
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

/// The CPU's model name and thread count.
pub fn cpu_model() -> String {
    let name = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    format!(
        "{name} ({} threads, {})",
        rayon::current_num_threads(),
        Isa::current().name()
    )
}

/// `RAYSTREAM_CPU_ISA=x86-64-v3|baseline`: the instruction set of the CPU ray queries and
/// volume renderers' pixels (the best this processor has by default; `baseline` measures what
/// x86-64-v3 gains, in the same binary). Any other value, or one the processor cannot run, is
/// refused.
pub fn choose_cpu_isa() -> Result<()> {
    const NAME: &str = "RAYSTREAM_CPU_ISA";
    match std::env::var(NAME) {
        Err(_) => Ok(()),
        Ok(v) => v
            .parse::<Isa>()
            .and_then(Isa::choose)
            .map_err(|e| anyhow::anyhow!("{NAME}={v:?}: {e}")),
    }
}

/// The CPU renderer's queues: in waves of `RAYSTREAM_CPU_WAVE=N` samples where it is set (an
/// experiment, for the wave that suits a machine's cores; the same image for any wave), else
/// of [`raystream_cpu::WAVE_SAMPLES`]. Any other value than a positive number is refused.
pub fn cpu_queues() -> Result<RenderQueues> {
    const NAME: &str = "RAYSTREAM_CPU_WAVE";
    match std::env::var(NAME) {
        Err(_) => Ok(RenderQueues::default()),
        Ok(v) => match v.trim().parse::<u32>() {
            Ok(n) if n > 0 => Ok(RenderQueues::with_wave(n)),
            _ => Err(anyhow::anyhow!(
                "{NAME}={v:?} is not a number of samples (1 to {})",
                u32::MAX
            )),
        },
    }
}

pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

pub fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

pub fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Prints one line to stdout; a closed pipe (`raystream … --json | head`) ends quietly instead
/// of panicking as `println!` would.
pub fn print_line(line: impl std::fmt::Display) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = writeln!(out, "{line}")
        && e.kind() != std::io::ErrorKind::BrokenPipe
    {
        eprintln!("raystream: cannot write to stdout: {e}");
    }
}

/// A lone slice's view (`volume`'s grid holds one voxel along an axis: one DICOM image, a 2-D
/// NIfTI): along that axis, as such images are read (an axial slice from below, the patient's
/// right on the image's left; a coronal one from the front; a sagittal one from the patient's
/// left), with its `--view` name; `None` for a volume of several slices along every axis.
pub fn lone_slice_view(
    volume: &raystream_io::Volume,
) -> Option<(raystream_scene::PatientView, &'static str)> {
    use raystream_scene::PatientView;
    let axis = volume.dims.iter().rposition(|&n| n == 1)?;
    // The patient axis (L, P, S) the index axis runs closest to.
    let column = volume.direction.map(|row| row[axis].abs());
    let lps = (0..3).max_by(|&a, &b| column[a].total_cmp(&column[b]))?;
    Some(match lps {
        0 => (PatientView::Left, "left"),
        1 => (PatientView::Anterior, "anterior"),
        _ => (PatientView::Inferior, "inferior"),
    })
}

/// `volume` from `path`, a lone slice made the slab of tissue it images
/// ([`raystream_io::Volume::slab_of_lone_slices`]) so that rays through it meet its values
/// over its thickness; said unless `quiet`.
pub fn slab_if_lone(
    volume: raystream_io::Volume,
    path: &Path,
    quiet: bool,
) -> raystream_io::Volume {
    let Some(slab) = volume.slab_of_lone_slices() else {
        return volume;
    };
    if !quiet {
        let [x, y, z] = volume.dims;
        let thick: Vec<String> = (0..3)
            .filter(|&a| volume.dims[a] == 1)
            .map(|a| format!("{} mm", volume.spacing[a]))
            .collect();
        eprintln!(
            "raystream: {}: a lone slice ({x} × {y} × {z} voxels): drawn as the slab of tissue it images, {} thick",
            path.display(),
            thick.join(" × ")
        );
    }
    slab
}

/// `n` and the word for it: "1 shell", "3 shells".
pub fn plural(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A DICOM picture's description names the options, not the files: the input, the output
    /// and the option naming it are left out, other files and folders become FILE.
    #[test]
    fn descriptions_leave_the_files_out() {
        let here = env!("CARGO_MANIFEST_DIR");
        let words = |args: &[&str], output: &str| {
            let args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
            words_without_paths(&args, Some(Path::new("ct/Doe^John")), Path::new(output))
        };
        assert_eq!(
            words(
                &[
                    "render",
                    "ct/Doe^John",
                    "--mode",
                    "mip",
                    "-o",
                    "out.dcm",
                    "--size",
                    "8x8"
                ],
                "out.dcm"
            ),
            "raystream render --mode mip --size 8x8"
        );
        assert_eq!(
            words(
                &[
                    "measure",
                    "ct/Doe^John",
                    "--path",
                    here,
                    "--every",
                    "2",
                    "-o",
                    "table.csv",
                    "--plot",
                    "p.dcm",
                    "--stenosis"
                ],
                "p.dcm"
            ),
            "raystream measure --path FILE --every 2 --stenosis"
        );
        assert_eq!(
            words(
                &[
                    "measure",
                    "ct/Doe^John",
                    &format!("--path={here}"),
                    "--plot=p.dcm",
                    "--output=t.csv"
                ],
                "p.dcm"
            ),
            "raystream measure --path=FILE"
        );
        // Not a file: a value stays.
        assert_eq!(
            words(
                &["render", "--tf", "no/such/tf.json", "-o", "x.dcm"],
                "x.dcm"
            ),
            "raystream render --tf no/such/tf.json"
        );
    }
}
