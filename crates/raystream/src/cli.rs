//! Command-line arguments.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use raystream_accel::{Builder, Traversal};

#[derive(Parser)]
#[command(
    name = "raystream",
    version,
    about = "Stream ray tracing of triangle meshes and CT volumes on the GPU and the CPU"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Render a mesh, a scene file (TOML), a CT volume's bones or, without INPUT, the built-in
    /// default (the bones of an abdomen/pelvis CT) to PNG.
    Render(Box<RenderArgs>),
    /// Trace a stream of rays (RAYS.bin) against a mesh and write the hits (HITS.bin).
    Trace(TraceArgs),
    /// Extract a bone isosurface from a CT volume, or a label map's or DICOM Segmentation's
    /// segments as closed surfaces, and write them as a mesh (PLY, OBJ, STL or GLB).
    Iso(IsoArgs),
    /// Measure a vessel's lumen on cross-sections along a path through a CT volume: area,
    /// equivalent, largest and smallest diameters, centroid.
    Measure(MeasureArgs),
    /// Find a vessel's centreline through a CT volume's contrast-filled lumen from a few points
    /// placed in it (its ends, and any points it must pass), as a path for `render --path` and
    /// `measure --path`.
    Centreline(CentrelineArgs),
    /// Describe a mesh and its kd-tree, or a CT volume's geometry and values.
    Info(InfoArgs),
    /// Measure build time and traversal throughput on standard ray sets.
    Bench(BenchArgs),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Device {
    Cpu,
    Gpu,
    Auto,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BuilderArg {
    Sah,
    Median,
}

impl From<BuilderArg> for Builder {
    fn from(b: BuilderArg) -> Self {
        match b {
            BuilderArg::Sah => Builder::Sah,
            BuilderArg::Median => Builder::Median,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TraversalArg {
    Ropes,
    Stack,
}

impl From<TraversalArg> for Traversal {
    fn from(t: TraversalArg) -> Self {
        match t {
            TraversalArg::Ropes => Traversal::Ropes,
            TraversalArg::Stack => Traversal::Stack,
        }
    }
}

/// GPU ray queries: one fused kernel, or traversal and intersection split (the paper's layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum KernelsArg {
    Fused,
    Split,
    Persistent,
    Ifif,
}

/// `info --below --clusters`: how the voxels below a value are joined into clusters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ClustersArg {
    /// In 3D: each voxel with its six face neighbours.
    #[value(name = "3d")]
    Faces,
    /// Within each slice (the grid's third axis): each voxel with its four face neighbours
    /// there, as Mishima et al. counted them.
    #[value(name = "2d")]
    InSlices,
}

impl From<ClustersArg> for raystream_volume::clusters::Connectivity {
    fn from(c: ClustersArg) -> Self {
        match c {
            ClustersArg::Faces => Self::Faces,
            ClustersArg::InSlices => Self::InSlices,
        }
    }
}

/// `measure --dark --wall --wall-edge`: how an airway's wall is placed on each ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AirwayEdge {
    /// Both its edges at half maximum: quantitative airway CT's standard, comparable with the
    /// published figures (Pi10 among them); it overstates a wall thinner than the scanner's blur.
    HalfMaximum,
    /// Its thickness from the HU summed across it, which the blur keeps (thin walls near their
    /// own thickness; the wall's density taken as soft tissue's 40 HU, or its peak where
    /// higher), about the middle of its edges at half maximum.
    Integral,
}

impl AirwayEdge {
    /// The airway wall's options `--wall-edge` (or `--draw-wall-edge`) asks for: at half
    /// maximum where it is not given.
    pub fn options(edge: Option<AirwayEdge>) -> raystream_cpu::wall::WallOptions {
        match edge {
            Some(AirwayEdge::Integral) => raystream_cpu::wall::WallOptions::airway_integral(),
            Some(AirwayEdge::HalfMaximum) | None => raystream_cpu::wall::WallOptions::airway(),
        }
    }
}

/// `render --path --cpr`: how the curved plane is laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CprArg {
    Straightened,
    Stretched,
}

/// `render --turntable --format`: the frames' file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FrameFormat {
    /// 8-bit sRGB, as shown.
    Png,
    /// 32-bit float OpenEXR: what `-o OUT.exr` writes for the mode (HU, or premultiplied RGBA).
    Exr,
    /// DICOM Secondary Capture images of the PNG frames, one series in the source's study.
    Dcm,
    /// One animated PNG (-o NAME.png), looping: the PNG frames exactly; browsers play it.
    Apng,
    /// One animated GIF (-o NAME.gif), looping: plays everywhere, each frame cut to its own 256
    /// colours.
    Gif,
}

impl FrameFormat {
    /// The animation this format writes into one file, if it is one.
    pub fn animation(self) -> Option<raystream_cpu::animation::AnimationKind> {
        use raystream_cpu::animation::AnimationKind;
        match self {
            FrameFormat::Apng => Some(AnimationKind::Apng),
            FrameFormat::Gif => Some(AnimationKind::Gif),
            FrameFormat::Png | FrameFormat::Exr | FrameFormat::Dcm => None,
        }
    }
}

/// `render --aov`: what the image of each pixel's closest hit shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AovArg {
    Depth,
    Normal,
    Prim,
}

impl From<AovArg> for raystream_cpu::Aov {
    fn from(a: AovArg) -> Self {
        match a {
            AovArg::Depth => raystream_cpu::Aov::Depth,
            AovArg::Normal => raystream_cpu::Aov::Normal,
            AovArg::Prim => raystream_cpu::Aov::Prim,
        }
    }
}

/// GPU rendering: how the host submits the depths of a wave of samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SubmitArg {
    /// One submission per wave with all its depths, the next wave queued before the host
    /// reads this one's counts (scenes whose hits can spawn two rays run `depth`).
    Wave,
    /// One submission per depth, the queue counts read back after each.
    Depth,
}

impl From<SubmitArg> for raystream_gpu::Submit {
    fn from(s: SubmitArg) -> Self {
        match s {
            SubmitArg::Wave => raystream_gpu::Submit::Wave,
            SubmitArg::Depth => raystream_gpu::Submit::Depth,
        }
    }
}

impl From<KernelsArg> for raystream_gpu::Kernels {
    fn from(k: KernelsArg) -> Self {
        match k {
            KernelsArg::Fused => raystream_gpu::Kernels::Fused,
            KernelsArg::Split => raystream_gpu::Kernels::Split,
            KernelsArg::Persistent => raystream_gpu::Kernels::Persistent,
            KernelsArg::Ifif => raystream_gpu::Kernels::IfIf,
        }
    }
}

#[derive(Args, Clone)]
pub struct Accel {
    #[command(flatten)]
    pub tree: TreeArgs,
    /// kd-tree traversal.
    #[arg(long, value_enum, default_value = "ropes")]
    pub traversal: TraversalArg,
    /// Where to run: the CPU, a GPU, or a GPU when there is one (a hardware GPU; software
    /// adapters such as lavapipe only with `--device gpu`).
    #[arg(long, value_enum, default_value = "auto")]
    pub device: Device,
    /// Use the first GPU adapter whose name contains this (case-insensitive).
    #[arg(long)]
    pub adapter: Option<String>,
}

/// How the kd-tree is built.
#[derive(Args, Clone, Copy)]
pub struct TreeArgs {
    /// kd-tree builder.
    #[arg(long, value_enum, default_value = "sah")]
    pub builder: BuilderArg,
    /// SAH builder: what a traversal step costs, in triangle tests. Dearer steps build
    /// shallower trees with fuller leaves.
    #[arg(long, default_value_t = raystream_accel::DEFAULT_TRAVERSAL_COST, value_parser = parse_traversal_cost, allow_negative_numbers = true)]
    pub sah_traversal_cost: f32,
    /// Rope walks start their first descent at the node of their entry point's cell in a grid
    /// over the scene box, with this many cells along its longest side (0: at the root; at
    /// most 256). The same hits at any size; larger grids skip more of the descent.
    #[arg(long, default_value_t = raystream_accel::entry::DEFAULT_RES, value_parser = clap::value_parser!(u32).range(0..=raystream_accel::entry::MAX_RES as i64))]
    pub entry_grid: u32,
}

impl TreeArgs {
    pub fn build(&self, mesh: &raystream_io::TriMesh) -> raystream_accel::KdTree {
        let mut tree =
            raystream_accel::KdTree::build_with(mesh, self.builder.into(), self.sah_traversal_cost);
        if self.entry_grid != raystream_accel::entry::DEFAULT_RES {
            tree.set_entry_grid(self.entry_grid);
        }
        tree
    }
}

fn parse_traversal_cost(s: &str) -> Result<f32, String> {
    let range = raystream_accel::TRAVERSAL_COST_RANGE;
    match s.parse::<f32>() {
        Ok(c) if range.contains(&c) => Ok(c),
        _ => Err(format!(
            "'{s}': a traversal step's cost in triangle tests, from {} to {}",
            range.start(),
            range.end()
        )),
    }
}

/// A distance in mm above 0 (and at most a metre).
fn parse_tolerance(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(mm) if mm > 0.0 && mm <= 1000.0 => Ok(mm),
        _ => Err(format!("'{s}': a distance in mm, above 0 and at most 1000")),
    }
}

/// `--min-island`: millilitres above 0.
fn parse_island_ml(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(ml) if ml > 0.0 && ml.is_finite() => Ok(ml),
        _ => Err(format!("'{s}': a volume in ml, above 0")),
    }
}

/// `--below`: a finite value (HU for a CT).
fn parse_below(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("'{s}': a value (HU for a CT), such as -950")),
    }
}

/// `--combine`: NAME=LIST, both not empty.
fn parse_combine(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((name, list)) if !name.trim().is_empty() && !list.trim().is_empty() => {
            Ok((name.trim().to_string(), list.trim().to_string()))
        }
        _ => Err(format!(
            "'{s}': NAME=LIST, a name for the segments LIST names together (numbers or names, comma-separated)"
        )),
    }
}

/// `--adjust-to`'s volume: given, or the total lung capacity predicted for a sex and height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AdjustTo {
    Ml(f64),
    Tlc {
        sex: raystream_volume::Sex,
        height_cm: f64,
    },
}

impl AdjustTo {
    /// The volume in ml.
    pub fn ml(&self) -> f64 {
        match *self {
            AdjustTo::Ml(ml) => ml,
            AdjustTo::Tlc { sex, height_cm } => raystream_volume::predicted_tlc_ml(sex, height_cm),
        }
    }
}

/// `--adjust-to`: REGION=ML (a volume from 100 ml to 20 l) or REGION=tlc:SEX:CM (male or
/// female, a height from 100 to 250 cm).
fn parse_adjust_to(s: &str) -> Result<(String, AdjustTo), String> {
    let fail = || {
        format!(
            "'{s}': REGION=ML (a volume, 100 to 20000 ml) or REGION=tlc:SEX:CM (SEX male or female, a height of 100 to 250 cm)"
        )
    };
    let (name, to) = s.split_once('=').ok_or_else(fail)?;
    let (name, to) = (name.trim(), to.trim());
    if name.is_empty() {
        return Err(fail());
    }
    let to = match to.strip_prefix("tlc:") {
        None => match to.parse::<f64>() {
            Ok(ml) if (100.0..=20000.0).contains(&ml) => AdjustTo::Ml(ml),
            _ => return Err(fail()),
        },
        Some(rest) => {
            let (sex, cm) = rest.split_once(':').ok_or_else(fail)?;
            let sex = match sex.to_ascii_lowercase().as_str() {
                "male" | "m" => raystream_volume::Sex::Male,
                "female" | "f" => raystream_volume::Sex::Female,
                _ => return Err(fail()),
            };
            match cm.parse::<f64>() {
                Ok(height_cm) if (100.0..=250.0).contains(&height_cm) => {
                    AdjustTo::Tlc { sex, height_cm }
                }
                _ => return Err(fail()),
            }
        }
    };
    Ok((name.to_string(), to))
}

/// `--percentile`: from 0 to 100.
fn parse_percentile(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(p) if (0.0..=100.0).contains(&p) => Ok(p),
        _ => Err(format!("'{s}': a percentile, from 0 to 100")),
    }
}

/// Which islands of a surface's inside keep their surface: `iso` and `render` of a CT's
/// threshold or of a label map's segments.
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct IslandPick {
    /// Keep the N largest islands (pieces of the voxels at or above the threshold, or of a
    /// segment's, each joined to the six that share a face with it, as the marching cubes and
    /// 3D Slicer's Islands effect join them) and drop the others' surfaces: the bones without
    /// the specks of noise, calcified vessels and the table; each segment's own with
    /// --segment.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub keep_largest: Option<u64>,
    /// Drop the islands (as --keep-largest has them) whose voxels hold less than ML
    /// millilitres, and their surfaces.
    #[arg(long, value_name = "ML", value_parser = parse_island_ml, conflicts_with = "keep_largest")]
    pub min_island: Option<f64>,
    /// Fill the cavities first: the pieces of voxels below the threshold (or outside a
    /// segment) that it encloses all round, so that the surface is the outer walls alone and
    /// the model solid, as Materialise Mimics's cavity fill makes a bone for printing (a
    /// marrow cavity closed all round, a voxel of noise inside a bone); before --keep-largest
    /// or --min-island, whose islands then hold the voxels they enclose.
    #[arg(long)]
    pub fill_cavities: bool,
}

impl IslandPick {
    /// The islands to keep on a grid of voxels of `voxel_ml` each, and whether the cavities
    /// are filled first.
    pub fn keep(&self, voxel_ml: f64) -> raystream_volume::KeepSurface {
        raystream_volume::KeepSurface {
            islands: self.islands(voxel_ml),
            fill_cavities: self.fill_cavities,
        }
    }

    /// The islands to keep on a grid of voxels of `voxel_ml` each.
    fn islands(&self, voxel_ml: f64) -> raystream_volume::KeepIslands {
        use raystream_volume::KeepIslands;
        match (self.keep_largest, self.min_island) {
            (Some(n), _) => KeepIslands::Largest(usize::try_from(n).unwrap_or(usize::MAX)),
            // A hair under, so that an island of exactly ML is not lost to rounding.
            (None, Some(ml)) => {
                KeepIslands::AtLeast((ml / voxel_ml * (1.0 - 1e-9)).ceil() as usize)
            }
            (None, None) => KeepIslands::All,
        }
    }

    /// The flag given, if any.
    pub fn flag(&self) -> Option<&'static str> {
        match (self.keep_largest, self.min_island) {
            (Some(_), _) => Some("--keep-largest"),
            (None, Some(_)) => Some("--min-island"),
            (None, None) => self.fill_cavities.then_some("--fill-cavities"),
        }
    }
}

/// Which image of a CT folder or file to read.
#[derive(Args, Clone, Debug, Default)]
pub struct VolumePick {
    /// DICOM: the SeriesInstanceUID to read (default: the series with the most slices).
    #[arg(long)]
    pub series: Option<String>,
    /// 4-D CT (cardiac phases, perfusion): the temporal position to read, from 1 (default: the
    /// first, with a warning): a NIfTI's volumes along its fourth axis, a DICOM series'
    /// temporal positions in increasing order. `info` says how many there are.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub phase: Option<u32>,
}

impl VolumePick {
    pub fn select(&self) -> raystream_io::VolumeSelect {
        raystream_io::VolumeSelect {
            series: self.series.clone(),
            phase: self.phase.map(|p| p as usize),
        }
    }
}

#[derive(Args)]
#[command(group(clap::ArgGroup::new("frames").args(["turntable", "slices", "cine", "fly"])))]
#[command(group(clap::ArgGroup::new("stations").args(["slices", "fly"]).multiple(false)))]
pub struct RenderArgs {
    /// Mesh (.obj, .ply, .stl, optionally .gz; .gltf, .glb; .vtp, a .vtk of polygons; .3mf), scene
    /// (.toml) or CT volume (DICOM folder, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .vti, a .vtk of
    /// image data, NAME_WxHxD_TYPE.raw); none: the built-in abdomen CT.
    pub input: Option<PathBuf>,
    #[command(flatten)]
    pub threshold: Threshold,
    #[command(flatten)]
    pub pick: VolumePick,
    /// Volumes: Taubin smoothing iterations of the bone surface (0: raw marching cubes with
    /// gradient normals; default 0, and 10 for `--segment`'s surfaces).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub smooth: Option<u32>,
    #[command(flatten)]
    pub islands: IslandPick,
    /// A label map or DICOM Segmentation: the surfaces of its segments, each in its colour,
    /// instead of bones (numbers or a Segmentation's labels, comma-separated, or `all`, the
    /// default for a Segmentation; as `iso --segment`). A CT with --mode dvr, iso, cinematic,
    /// mip, minip or average and --segmentation LABELS: only these segments of LABELS are
    /// drawn (an average: the mean of their voxels along each ray).
    #[arg(long, value_name = "LIST", conflicts_with = "iso")]
    pub segment: Option<String>,
    /// The label map's segments' names and colours, for `--segment` (which it implies) or
    /// `--segmentation`: a 3D Slicer colour table or an ITK-SNAP label description (as
    /// `iso --colour-table`).
    #[arg(
        long,
        alias = "color-table",
        value_name = "FILE",
        conflicts_with = "iso"
    )]
    pub colour_table: Option<PathBuf>,
    /// Output image: .png (8-bit sRGB as a viewer shows it; 16-bit grey for --aov depth) or
    /// .exr (32-bit float: the linear film; --aov depth Z, normal N.X/N.Y/N.Z, prim as 32-bit
    /// integers; --mode mip/minip/average/slice the HU values themselves, no window; dvr and
    /// iso premultiplied RGBA) or .dcm (the PNG's pixels as a DICOM Secondary Capture image in
    /// the source series' study).
    #[arg(short, long, default_value = "render.png")]
    pub output: PathBuf,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "800x600", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel (default 4, at most 1024; --mode cinematic: paths per pixel, default
    /// 64, at most 4096).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub spp: Option<u32>,
    /// Deepest reflection/refraction level (0: primary rays only); --mode cinematic: the
    /// scatterings a path may take.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(0..=64))]
    pub max_depth: u32,
    #[command(flatten)]
    pub accel: Accel,
    /// Volumes: direct volume rendering instead of the bone mesh: dvr (transfer function,
    /// --preset ct-bone… or --tf FILE), mip, minip, average (--window/--level), iso (the first
    /// crossing of --iso HU), slice (the HU on the plane through --slice-at facing the camera,
    /// in parallel projection: axial with --view superior/inferior, coronal with anterior,
    /// sagittal with left/right, oblique with --orbit), cinematic (Monte Carlo path tracing
    /// of the transfer function's medium under a key light and a sky: --spp paths a pixel,
    /// --max-depth scatterings a path).
    #[arg(long, value_enum)]
    pub mode: Option<ModeArg>,
    #[command(flatten)]
    pub look: VolumeLook,
    /// Instead of a shaded picture, one ray through each pixel's centre and an image of its
    /// closest hit: depth (distance from the eye, 16-bit grey, nearest white), normal (the
    /// shading normal facing the eye, RGB = 128 + 127 n) or prim (a colour per triangle);
    /// misses black. The triangles of meshes, volumes' bones and scenes (a scene's volume is
    /// left out).
    #[arg(long, value_enum, conflicts_with_all = ["mode", "spp", "max_depth", "repeat", "submit"])]
    pub aov: Option<AovArg>,
    /// CT volumes (and scenes with one): look at the patient straight on from this side
    /// (default: from the front, 7° from above). anterior and posterior: head up; left and
    /// right: from the patient's left or right side, head up; superior: from above the head,
    /// anterior up; inferior: from below the feet, anterior up, the patient's right on the
    /// image's left as axial slices are shown.
    #[arg(long, value_enum)]
    pub view: Option<ViewArg>,
    /// Turn the framing camera AZ degrees about the image's up axis (+90 looks from what was
    /// the image's right side; for a volume's front view, from the patient's left), then raise
    /// it EL degrees towards that axis (−90 to 90): AZ or AZ,EL. Meshes, volumes and scenes
    /// without a camera of their own.
    #[arg(long, value_parser = parse_orbit, allow_hyphen_values = true)]
    pub orbit: Option<[f32; 2]>,
    /// A parallel (orthographic) projection instead of the perspective one: every depth at
    /// one scale, as radiology shows MIPs and projections. Framed inputs (not a scene file's
    /// own camera).
    #[arg(long)]
    pub parallel: bool,
    /// Marks the patient directions at the image's edges, as radiology viewers do (R/L, A/P,
    /// S/I; two or three letters at an oblique edge): CT volumes, their bones and scenes with
    /// one, PNG output.
    #[arg(long)]
    pub labels: bool,
    /// A scale bar in the bottom right corner, its length (1, 2 or 5 × 10^k mm, at most a
    /// fifth of the width) written above it: views where every pixel spans the same
    /// millimetres (--parallel, --mode slice, a CPR) of CT volumes, their bones and scenes
    /// with one, PNG or DICOM output.
    #[arg(long)]
    pub scale_bar: bool,
    /// A turntable of N frames, one every 360/N degrees about the image's up axis (the
    /// patient's superior axis unless --view superior/inferior), starting from --view and
    /// --orbit, written as OUTPUT/frame_000.png … (-o names the folder; --format exr for EXRs,
    /// dcm for one DICOM series, apng or gif for one looping animation -o names): with --mode,
    /// of the volume; else of the mesh, the scene or the bones through the stream renderer, a
    /// mesh's or the bones' lights turning with the camera.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=3600))]
    pub turntable: Option<u32>,
    /// With --mode slice (or a --slab): N parallel planes facing the camera, --slice-step
    /// apart, centred on --slice-at, written as OUTPUT/frame_000.png … (-o names the folder):
    /// a reformatted series; with --format dcm, one DICOM series of reformatted CT images
    /// (apng or gif: one animation, scrolling through them).
    #[arg(
        long,
        requires = "mode",
        conflicts_with = "turntable",
        value_parser = clap::value_parser!(u32).range(1..=4096)
    )]
    pub slices: Option<u32>,
    /// With --mode, of a 4-D CT (cardiac phases, perfusion): a cine, one frame per temporal
    /// position in order, all from the same camera (with --path, the same curved plane: a CPR
    /// of each phase) with the same window or transfer function, written as
    /// OUTPUT/frame_000.png … (-o names the folder); with --format dcm, one series (apng or
    /// gif: one animation).
    #[arg(long, requires = "mode", conflicts_with_all = ["turntable", "slices", "phase"])]
    pub cine: bool,
    /// With --mode slice, or --mode mip/minip/average and a --slab: a curved planar
    /// reformation (CPR) along the path in FILE (3D Slicer markups .mrk.json, or text: x y z
    /// per line, LPS mm): the path straightened down the image's height, its first point at
    /// the top, square pixels (the path's length over the height), the cut facing --view and
    /// turned about the path by --orbit AZ (--turntable N: a rotational CPR; --slices N: N
    /// cross-sections perpendicular to the path, evenly along it). With --mode dvr, iso or
    /// cinematic and --fly N: a fly-through along it.
    #[arg(
        long,
        value_name = "FILE",
        requires = "mode",
        conflicts_with = "slice_at"
    )]
    pub path: Option<PathBuf>,
    /// With --path FILE and --mode dvr, iso or cinematic: a fly-through (virtual endoscopy,
    /// as of a vessel's lumen), N frames with the camera on the path at the middles of N
    /// equal parts of it (or --slice-step MM apart about --path-at MM, as cross-sections),
    /// looking ahead along it (from its first point toward its last), the
    /// image's up turning with the path without twisting about it, a perspective of --fov
    /// degrees; written as OUTPUT/frame_000.png … (-o names the folder; --format exr, dcm,
    /// apng or gif as for --turntable). A transfer function that lets the lumen's contrast
    /// through and stops at its wall shows the wall from inside (examples/angioscopy.toml).
    #[arg(
        long,
        requires = "path",
        conflicts_with_all = ["turntable", "slices", "cine"],
        value_parser = clap::value_parser!(u32).range(1..=3600)
    )]
    pub fly: Option<u32>,
    /// With --fly: the camera's vertical field of view, degrees (above 0, below 180).
    #[arg(long, value_name = "DEG", requires = "fly", default_value_t = 90.0)]
    pub fov: f32,
    /// With --path: the CPR straightened (the path down the middle column, rows at its arc
    /// length) or stretched (Kanitsar 2002: the surface swept through the path along the
    /// view's right, unrolled so that the path keeps its length, drawn as the curve it makes
    /// across that direction; a path in a plane holding it gives that plane's slice).
    #[arg(long, value_enum, requires = "path", default_value_t = CprArg::Straightened)]
    pub cpr: CprArg,
    /// A CT volume (--mode, or its bones) or a scene with one: draws the path in FILE (read
    /// as --path reads it) over the picture, a yellow line ringed in black, as a workstation
    /// shows a centreline on its reference view; PNG, or DICOM as the picture (RGB, Burned In
    /// Annotation YES).
    #[arg(long, value_name = "FILE", conflicts_with = "path")]
    pub draw_path: Option<PathBuf>,
    /// With --path FILE: draws the lumen `measure` finds at HU. On each cross-section
    /// (--slices N): its edge in cyan, its largest diameter as a yellow line ringed in black.
    /// On the CPR: where it meets each row (measured on the plane through the path's point
    /// along the row and its rays), a cyan pixel at either edge. PNG, or DICOM as the picture
    /// (RGB, Burned In Annotation YES).
    #[arg(
        long,
        value_name = "HU",
        requires = "path",
        allow_negative_numbers = true
    )]
    pub draw_lumen: Option<f32>,
    /// With --draw-lumen: also the vessel's outer wall that `measure --wall` finds (fat or
    /// lung below HU [default: -30] about it), in magenta. On cross-sections (--slices N) its
    /// outline, solid where its edge was seen and dotted where the fitted circle stands in for
    /// it; on a CPR, where it meets each row, a pixel at either edge. With --draw-dark, the
    /// airway's wall that `measure --dark --wall` finds at half maximum (no HU), solid where
    /// its outer edge was seen.
    #[arg(
        long,
        value_name = "HU",
        num_args = 0..=1,
        requires = "draw_lumen",
        allow_negative_numbers = true
    )]
    pub draw_wall: Option<Option<f32>>,
    /// With --draw-lumen: the lumen is the samples at or below HU, an airway's gas, as
    /// `measure --dark` finds it.
    #[arg(long, requires = "draw_lumen")]
    pub draw_dark: bool,
    /// With --draw-dark --draw-wall: how the airway's wall is placed on each ray, as `measure
    /// --wall-edge` [default: half-maximum].
    #[arg(long, value_enum, value_name = "EDGE", requires = "draw_wall")]
    pub draw_wall_edge: Option<AirwayEdge>,
    /// With --mode slice (a slice, or a CPR with --path, and their frames): tints each pixel by the
    /// label of a label map, DICOM Segmentation or RT Structure Set (FILE: NIfTI, NRRD (a 3D
    /// Slicer .seg.nrrd too), MetaImage, DICOM SEG or RTSTRUCT, or a folder of NIfTI masks, a
    /// file a segment, as TotalSegmentator writes them; `measure --mask` writes NIfTI,
    /// .seg.nrrd and SEG) at the
    /// pixel's point in the patient, as a viewer lays a segmentation over the CT, each segment
    /// in its own colour (a Segmentation's, a structure set's, `--colour-table`'s), else label
    /// 1 cyan, 2 magenta, then yellow, green, orange, blue; PNG, or DICOM as the picture. With
    /// --mode dvr, iso or cinematic: each sample in its segment's colour (the transfer
    /// function's opacity); with --segment LIST (mip, minip and average too) only those
    /// segments drawn.
    #[arg(long, value_name = "FILE")]
    pub segmentation: Option<PathBuf>,
    /// With --segmentation: each segment's edge drawn in its colour, as planning systems show
    /// structures, rather than its inside tinted (a structure set's structures each whole).
    #[arg(long, requires = "segmentation")]
    pub outline: bool,
    /// With --segmentation on a slice or a CPR: only the pixels whose CT voxel (the one nearest
    /// their point) is below HU are tinted, as `info --below` counts them: a lung's low
    /// attenuation areas, `--below -950` with a lung segmentation, an emphysema map.
    #[arg(
        long,
        value_name = "HU",
        requires = "segmentation",
        value_parser = parse_below,
        allow_hyphen_values = true
    )]
    pub below: Option<f64>,
    /// With --segmentation (dvr, iso and cinematic in its colours, or a slice tinted by it),
    /// or a label map's surfaces (--segment): each segment drawn, named beside a swatch of its
    /// colour in the top left corner; PNG, or DICOM as the picture.
    #[arg(long)]
    pub legend: bool,
    /// A mesh's or a CT's bone surface with its ten largest shells (pieces of triangles joined
    /// through their edges: a CT's islands of bone, a fracture's fragments, a model's parts)
    /// each in a colour of its own, the rest in the usual one; --legend names them, with the
    /// volume each encloses (ml, for a CT or a model in patient millimetres).
    #[arg(long, alias = "color-shells", conflicts_with_all = ["mode", "segment", "colour_table"])]
    pub colour_shells: bool,
    /// A CT with only the patient's body (and what it encloses: the lungs, the airway):
    /// the table, a head holder, cables and pads are left out, in every mode and in the bone
    /// surface. The body: above -500 HU, opened by a ball of 4 mm radius, its thin
    /// parts (the nose, the ears) joined back (`raystream_volume::body`).
    #[arg(long, conflicts_with = "cine")]
    pub body_only: bool,
    /// With --path FILE (not --slices): marks these points of the path, mm along it from its
    /// first point (as `measure` gives a lesion's and its references' arc lengths), each a
    /// line across the CPR, yellow ringed in black; PNG, or DICOM as the picture.
    #[arg(
        long,
        value_name = "MM[,MM...]",
        value_delimiter = ',',
        requires = "path",
        conflicts_with = "slices",
        allow_hyphen_values = true
    )]
    pub mark_at: Vec<f64>,
    /// With --path FILE --slices N (or --fly N): the cross-sections (the fly-through's
    /// cameras) lie about this point of the path, mm along it from its first point (default:
    /// its middle), as `measure` gives a section's arc length: `--slices 1 --path-at MM` is
    /// the cross-section there.
    #[arg(long, value_name = "MM", requires_all = ["path", "stations"], allow_negative_numbers = true)]
    pub path_at: Option<f64>,
    /// With --path FILE --slices N: each cross-section's height in mm (its width in
    /// proportion), about the path's point: a zoom on the vessel or airway, as a workstation's
    /// cross-section viewer shows it (default: the volume's finest spacing a pixel).
    #[arg(
        long,
        value_name = "MM",
        requires_all = ["path", "slices"],
        allow_negative_numbers = true
    )]
    pub field: Option<f32>,
    /// With --slices: the planes' spacing in mm (default: the pixel size, for cubic voxels);
    /// with --path, the cross-sections' (or with --fly the cameras') spacing along the path,
    /// about its middle (default: evenly along all of it).
    #[arg(long, value_name = "MM", requires = "stations")]
    pub slice_step: Option<f32>,
    /// With --turntable, --slices or --cine: the frames' format; `exr` writes frame_000.exr …
    /// holding what `-o OUT.exr` holds for the mode (HU before the window for mip, minip,
    /// average and slice; premultiplied float RGBA for dvr and iso); `dcm` one DICOM series;
    /// `apng` and `gif` one looping animation, -o naming the file (NAME.png, NAME.gif).
    #[arg(long, requires = "frames", value_enum, default_value_t = FrameFormat::Png)]
    pub format: FrameFormat,
    /// With --format apng or gif: the animation's frames a second, 1 to 50 (a GIF keeps
    /// delays in hundredths of a second: 15 plays at 14.3). Default 10.
    #[arg(long, requires = "frames", value_parser = clap::value_parser!(u32).range(1..=50))]
    pub fps: Option<u32>,
    /// Render the frame this many times and report the median frame time and frames per
    /// second (scene loading, kd-tree build and upload apart).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
    /// GPU: submit each wave of samples with all its depths at once (wave), or depth by
    /// depth, reading the queue counts back after each (depth). The same image either way.
    #[arg(long, value_enum, default_value = "wave")]
    pub submit: SubmitArg,
    /// No progress output.
    #[arg(short, long)]
    pub quiet: bool,
}

/// How `--mode` renders a volume: transfer function, sampling, lighting and clipping.
#[derive(Args, Clone)]
pub struct VolumeLook {
    /// Transfer function file (TOML: opacity = [[HU, a], …], color = [[HU, r, g, b], …]).
    #[arg(long, conflicts_with = "preset")]
    pub tf: Option<PathBuf>,
    /// Ray-marching step in mm (default: half the smallest voxel spacing).
    #[arg(long)]
    pub step: Option<f32>,
    /// Window for mip/minip/average/slice: a width in HU (with --level), or a named one:
    /// brain (80/40), lung (1500/−600), mediastinum (350/50), abdomen (400/50), liver
    /// (150/30), bone (1800/400).
    #[arg(long, value_parser = parse_window)]
    pub window: Option<WindowArg>,
    /// Window level (centre) in HU for mip/minip/average/slice.
    #[arg(long, requires = "window", allow_hyphen_values = true)]
    pub level: Option<f32>,
    /// Turn empty-space skipping off (to measure what it saves; the picture is the same).
    #[arg(long)]
    pub no_skip: bool,
    /// dvr: light from a key light above left of the camera and trace a shadow ray from every
    /// visible sample toward it through the transfer function.
    #[arg(long)]
    pub shadows: bool,
    /// dvr --shadows and cinematic: the key light AZ degrees to the right of the camera
    /// (negative: left) and EL degrees above it, turning with the camera (0,0: from the camera;
    /// 180,0: from behind). Default: above left, about -34,37.
    #[arg(long, value_parser = parse_orbit, allow_hyphen_values = true, value_name = "AZ,EL")]
    pub light: Option<[f32; 2]>,
    /// cinematic: filter the paths' noise, edge-aware (an à-trous wavelet filter steered by
    /// each pixel's variance and by noise-free guides: the colour, normal and depth its ray
    /// meets), on either device. 8 paths a pixel come out about as close to the converged
    /// picture as 32 without it.
    #[arg(long)]
    pub denoise: bool,
    /// cinematic: the medium's Henyey–Greenstein anisotropy, the mean cosine of its scattering
    /// angle, −0.95 to 0.95 (default 0: isotropic; above 0 light is carried on forward through
    /// tissue, below 0 sent back).
    #[arg(long, allow_hyphen_values = true, value_name = "G")]
    pub anisotropy: Option<f32>,
    /// cinematic: the lights' strength in photographic stops, −10 to 10 (+1 doubles the key
    /// light and the sky, −1 halves them; the background keeps its colour).
    #[arg(long, allow_hyphen_values = true, value_name = "EV")]
    pub exposure: Option<f32>,
    /// How the volume is read between voxel centres: linear (trilinear), cubic (the cubic
    /// B-spline, whose gradient is continuous: a coarse CT's shaded surfaces show no wood-grain
    /// rings; it smooths by about half a voxel, quietening noise but lowering thin structures'
    /// peaks, and costs more per sample) or cubic-interpolating (the same spline through every
    /// voxel's value: as smooth, no blur, keeps stent struts and thin cortex at full HU; it
    /// keeps the noise too, and its coefficients take a second copy of the volume). Default:
    /// cubic for dvr, iso and cinematic, linear for mip, minip, average and slice, whose values
    /// are read.
    #[arg(long, value_enum)]
    pub interpolation: Option<InterpolationArg>,
    /// Keep only the box XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (LPS mm, as `info` reports positions).
    #[arg(long, value_parser = parse_crop, allow_hyphen_values = true)]
    pub crop: Option<[f32; 6]>,
    /// Keep only points p with n·p ≥ c, given as NX,NY,NZ,C (LPS, mm); at most twice.
    #[arg(long = "clip-plane", value_parser = parse_plane, allow_hyphen_values = true)]
    pub clip_planes: Vec<[f32; 4]>,
    /// --mode slice: a point X,Y,Z of the slice's plane (LPS mm, as `info` reports positions;
    /// default: the volume's centre); with --slab, the slab's middle.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub slice_at: Option<[f32; 3]>,
    /// Keep only a slab MM thick about the plane through --slice-at facing the camera: a slab
    /// MIP, MinIP, average or rendering (not --mode slice, which is the plane itself).
    #[arg(long, value_name = "MM", conflicts_with = "clip_planes")]
    pub slab: Option<f32>,
}

fn parse_floats<const N: usize>(s: &str, what: &str) -> Result<[f32; N], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("'{s}': {e}; {what}"))?;
    if v.len() != N || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("'{s}': {what}"));
    }
    Ok(std::array::from_fn(|i| v[i]))
}

pub fn parse_crop(s: &str) -> Result<[f32; 6], String> {
    let what = "expected six finite numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (LPS mm)";
    let c = parse_floats::<6>(s, what)?;
    if (0..3).any(|a| c[a] >= c[a + 3]) {
        return Err(format!("'{s}': each minimum must be below its maximum"));
    }
    Ok(c)
}

pub fn parse_orbit(s: &str) -> Result<[f32; 2], String> {
    let what = "expected AZ or AZ,EL in degrees (EL from -90 to 90)";
    let [az, el] = match s.split(',').count() {
        1 => [parse_floats::<1>(s, what)?[0], 0.0],
        _ => parse_floats::<2>(s, what)?,
    };
    if el.abs() > 90.0 {
        return Err(format!("'{s}': elevation {el} is past 90 degrees; {what}"));
    }
    Ok([az, el])
}

/// `--window`: a width in HU, or a named window (width and level).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WindowArg {
    Width(f32),
    Named(&'static str, f32, f32),
}

/// Radiology's usual windows: name, width and level in HU (as Radiopaedia lists them).
pub const WINDOWS: [(&str, f32, f32); 6] = [
    ("brain", 80.0, 40.0),
    ("lung", 1500.0, -600.0),
    ("mediastinum", 350.0, 50.0),
    ("abdomen", 400.0, 50.0),
    ("liver", 150.0, 30.0),
    ("bone", 1800.0, 400.0),
];

pub fn parse_window(s: &str) -> Result<WindowArg, String> {
    if let Some(&(name, w, l)) = WINDOWS.iter().find(|(n, ..)| n.eq_ignore_ascii_case(s)) {
        return Ok(WindowArg::Named(name, w, l));
    }
    s.trim().parse::<f32>().map(WindowArg::Width).map_err(|_| {
        format!(
            "'{s}': a width in HU (with --level) or one of {}",
            window_names()
        )
    })
}

/// The named windows, comma-separated.
pub fn window_names() -> String {
    WINDOWS.map(|w| w.0).join(", ")
}

pub fn parse_point(s: &str) -> Result<[f32; 3], String> {
    parse_floats::<3>(s, "expected three finite numbers X,Y,Z (LPS mm)")
}

pub fn parse_plane(s: &str) -> Result<[f32; 4], String> {
    let p = parse_floats::<4>(s, "expected four finite numbers NX,NY,NZ,C (keeps n·p ≥ C)")?;
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    if n == 0.0 {
        return Err(format!("'{s}': the normal (NX, NY, NZ) is zero"));
    }
    Ok(p.map(|x| x / n))
}

/// The isosurface threshold: `--iso HU` or a `--preset` (default: bone, 300 HU).
#[derive(Args, Clone, Copy)]
pub struct Threshold {
    /// Isosurface threshold in Hounsfield units (volume value units for non-CT volumes).
    #[arg(long, alias = "hu", conflicts_with = "preset")]
    pub iso: Option<f32>,
    /// Threshold preset: bone (300 HU), thin-bone (226 HU), contrast (400 HU); with
    /// `render --mode dvr`, a transfer function (3D Slicer's): ct-bone, ct-bones, ct-aaa,
    /// ct-muscle, ct-lung, mip-bone.
    #[arg(long, value_enum)]
    pub preset: Option<PresetArg>,
}

impl Threshold {
    /// The threshold in HU (default: bone, 300 HU).
    pub fn hu(&self) -> anyhow::Result<f32> {
        if let Some(hu) = self.iso {
            return Ok(hu);
        }
        let p = self.preset.unwrap_or(PresetArg::Bone);
        match p.threshold() {
            Some(t) => Ok(t.hu()),
            None => anyhow::bail!(
                "--preset {}: a transfer function for --mode dvr; thresholds are bone, thin-bone, contrast",
                p.name()
            ),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PresetArg {
    Bone,
    ThinBone,
    Contrast,
    CtBone,
    CtBones,
    CtAaa,
    CtMuscle,
    CtLung,
    MipBone,
}

impl PresetArg {
    pub fn threshold(self) -> Option<raystream_volume::Preset> {
        use raystream_volume::Preset;
        match self {
            PresetArg::Bone => Some(Preset::Bone),
            PresetArg::ThinBone => Some(Preset::ThinBone),
            PresetArg::Contrast => Some(Preset::Contrast),
            _ => None,
        }
    }

    pub fn transfer(self) -> Option<raystream_volume::TfPreset> {
        use raystream_volume::TfPreset;
        match self {
            PresetArg::CtBone => Some(TfPreset::CtBone),
            PresetArg::CtBones => Some(TfPreset::CtBones),
            PresetArg::CtAaa => Some(TfPreset::CtAaa),
            PresetArg::CtMuscle => Some(TfPreset::CtMuscle),
            PresetArg::CtLung => Some(TfPreset::CtLung),
            PresetArg::MipBone => Some(TfPreset::MipBone),
            _ => None,
        }
    }

    pub fn name(self) -> String {
        self.to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default()
    }
}

/// `render --interpolation`: how a volume is read between voxel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum InterpolationArg {
    Linear,
    Cubic,
    CubicInterpolating,
}

impl From<InterpolationArg> for raystream_cpu::dvr::Interpolation {
    fn from(i: InterpolationArg) -> Self {
        match i {
            InterpolationArg::Linear => Self::Linear,
            InterpolationArg::Cubic => Self::Cubic,
            InterpolationArg::CubicInterpolating => Self::CubicInterpolating,
        }
    }
}

/// `render --view`: a side of the patient.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ViewArg {
    Anterior,
    Posterior,
    Left,
    Right,
    Superior,
    Inferior,
}

impl From<ViewArg> for raystream_scene::PatientView {
    fn from(v: ViewArg) -> Self {
        use raystream_scene::PatientView;
        match v {
            ViewArg::Anterior => PatientView::Anterior,
            ViewArg::Posterior => PatientView::Posterior,
            ViewArg::Left => PatientView::Left,
            ViewArg::Right => PatientView::Right,
            ViewArg::Superior => PatientView::Superior,
            ViewArg::Inferior => PatientView::Inferior,
        }
    }
}

/// `render --mode`: direct volume rendering modes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    Dvr,
    Mip,
    Minip,
    Average,
    Iso,
    Slice,
    Cinematic,
}

impl From<ModeArg> for raystream_cpu::dvr::DvrMode {
    fn from(m: ModeArg) -> Self {
        use raystream_cpu::dvr::DvrMode;
        match m {
            ModeArg::Dvr => DvrMode::Dvr,
            ModeArg::Mip => DvrMode::Mip,
            ModeArg::Minip => DvrMode::MinIp,
            ModeArg::Average => DvrMode::Average,
            ModeArg::Iso => DvrMode::Iso,
            ModeArg::Slice => DvrMode::Slice,
            ModeArg::Cinematic => DvrMode::Cinematic,
        }
    }
}

#[derive(Args)]
pub struct IsoArgs {
    /// CT volume (DICOM folder or file, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .vtk, .vti,
    /// NAME_WxHxD_TYPE.raw), or a label map, DICOM Segmentation, 3D Slicer segmentation or
    /// folder of NIfTI masks (TotalSegmentator's; with `--segment`).
    pub input: PathBuf,
    /// Output mesh in LPS millimetres: .ply (with normals), .obj (with normals), .stl, .vtk
    /// (3D Slicer's model format, legacy VTK polygonal data, with normals, and colours for
    /// several segments), .vtp (ParaView's: VTK XML polygonal data, a piece a segment, with
    /// normals and colours), .3mf (3D printing's package: an object a segment, named, in its
    /// colour, millimetres), or .glb (binary glTF with normals, under a node that turns it to
    /// glTF's metres, +Y superior, +Z anterior), or .dcm (a DICOM Encapsulated STL, filed with a
    /// DICOM series' study and frame of reference, referencing its images; several segments
    /// as MODEL-1.dcm, MODEL-2.dcm … in one series).
    /// The PLY, OBJ, STL, VTK and VTP say SPACE=LPS, as 3D Slicer reads a model's space.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub threshold: Threshold,
    #[command(flatten)]
    pub pick: VolumePick,
    /// Instead of a threshold, the surfaces of a label map's or DICOM Segmentation's segments:
    /// their numbers or names (a Segmentation's labels, or `--colour-table`'s),
    /// comma-separated, or `all` (the default for a DICOM Segmentation). Several go to one file: a glTF node each (named, in its colour),
    /// an OBJ object each (colours in a .mtl beside it), a VTP piece each (in its colour), or
    /// a PLY's or VTK file's vertex colours (an STL holds one).
    #[arg(long, value_name = "LIST", conflicts_with_all = ["iso", "preset"])]
    pub segment: Option<String>,
    /// The label map's segments' names and colours, for `--segment` (which it implies): a 3D
    /// Slicer colour table (`index name R G B A` a line) or an ITK-SNAP label description;
    /// over a DICOM Segmentation's own.
    #[arg(long, alias = "color-table", value_name = "FILE", conflicts_with_all = ["iso", "preset"])]
    pub colour_table: Option<PathBuf>,
    /// Taubin smoothing iterations (0: the raw marching-cubes surface, gradient normals;
    /// default 0 for a threshold, 10 for segments, whose voxel stair-steps are a voxel high).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub smooth: Option<u32>,
    /// Simplify each surface, as far as every vertex of the full one stays within MM of it
    /// (measured): far fewer triangles, for printing, the web and meshing for simulation.
    #[arg(long, value_name = "MM", value_parser = parse_tolerance)]
    pub simplify: Option<f64>,
    #[command(flatten)]
    pub islands: IslandPick,
    /// The bone surface's ten largest shells (pieces of triangles joined through their edges:
    /// its islands, a fracture's fragments) each a part of its own, "shell 1" the largest, in
    /// render --colour-shells's colours, and the rest one part, "bone": an OBJ's objects, a
    /// 3MF's or a GLB's, a VTP's pieces, a DICOM model each.
    #[arg(long, alias = "color-shells", conflicts_with_all = ["segment", "colour_table"])]
    pub colour_shells: bool,
    /// The bones of the patient's body alone: the table and a head holder left out, as
    /// `render --body-only` leaves them out.
    #[arg(long, conflicts_with_all = ["segment", "colour_table"])]
    pub body_only: bool,
    #[arg(short, long)]
    pub quiet: bool,
}

/// A vessel's lumen in a CT volume: `measure` and `centreline`.
#[derive(Args, Clone, Copy, Debug)]
pub struct LumenPick {
    /// Lumen: the voxels at or above this, HU (contrast-filled blood; the default sits above
    /// the vessel wall's and soft tissue's 30-60 HU).
    #[arg(
        long,
        value_name = "HU",
        default_value_t = 150.0,
        allow_negative_numbers = true
    )]
    pub lumen: f32,
    /// The lumen is the voxels at or below --lumen HU: an airway's gas (with --lumen -950,
    /// clear of the lung round the bronchi at about -850) or a bowel's, darker than the wall
    /// (`centreline`: for a fly-through, render --fly, of a virtual bronchoscopy; `measure`:
    /// the airway's lumen section by section).
    #[arg(long)]
    pub dark: bool,
    /// The lumen is looked for this far from the path's points, mm (`measure`: its sample
    /// nearest the point; `centreline`: its deepest voxel, where the point is moved).
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 5.0,
        allow_negative_numbers = true
    )]
    pub seed: f64,
}

#[derive(Args)]
pub struct MeasureArgs {
    /// CT volume (DICOM folder or file, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .vtk, .vti,
    /// NAME_WxHxD_TYPE.raw).
    pub input: PathBuf,
    /// The vessel's path: 3D Slicer markups (.mrk.json) or text (x y z per line, LPS mm), as
    /// `render --path` reads it.
    #[arg(long, value_name = "FILE")]
    pub path: PathBuf,
    /// A cross-section every MM along the path (at the middle of equal parts, as `render
    /// --path --slices` places them).
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 1.0,
        conflicts_with = "sections"
    )]
    pub every: f64,
    /// Exactly N cross-sections, evenly along the path.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub sections: Option<u32>,
    #[command(flatten)]
    pub vessel: LumenPick,
    /// The square sampled about the path's point on each section, mm (a lumen reaching its
    /// edge is reported open).
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 100.0,
        allow_negative_numbers = true
    )]
    pub field: f64,
    /// Open the lumen with a disc of this radius, mm: what the disc cannot reach from the
    /// path's side and runs on beyond its reach (a side branch, a neighbour joined by a
    /// narrower neck) is cut off; 0 keeps all that is connected.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 2.0,
        allow_negative_numbers = true
    )]
    pub open: f64,
    /// Also find the vessel's outer wall about the lumen ("outer wall to outer wall", as an
    /// aneurysm or a dissection is followed): rays from its centre out to the fat or lung
    /// about it, below HU [default: -30], a circle fitted to the edges they find (the one its
    /// neighbours along the path agree on, where they do), the outline where seen and the
    /// circle where a neighbour hides it. With --dark, an airway's wall instead (no HU): its
    /// inner and outer edges at half maximum on rays from the lumen's centre, as quantitative
    /// airway CT measures them (or by the integral: --wall-edge), with its mean thickness, its
    /// share of the airway's area (WA %) and Pi10 over the sections.
    #[arg(
        long,
        value_name = "HU",
        num_args = 0..=1,
        allow_negative_numbers = true
    )]
    pub wall: Option<Option<f32>>,
    /// With --dark --wall: how the airway's wall is placed on each ray [default: half-maximum].
    #[arg(long, value_enum, value_name = "EDGE")]
    pub wall_edge: Option<AirwayEdge>,
    /// Grade a stenosis: the lesion's area and smallest diameter against the reference, the
    /// vessel's diameter there without it (fitted to the sections about it, or --reference),
    /// and the narrowed segment's length.
    #[arg(long)]
    pub stenosis: bool,
    /// The lesion's arc length along the path, mm (the section nearest it); by default the
    /// most severe lesion by diameter stenosis (as --lesions 1; with --reference placed, the
    /// closed section of least area). Implies --stenosis.
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    pub lesion: Option<f64>,
    /// The reference: one section's diameter (distal, as NASCET), or the line through two
    /// (proximal and distal), at these arc lengths, mm; by default a line fitted to the
    /// sections within --span of the lesion, the narrowed ones left out. Implies --stenosis.
    #[arg(
        long,
        value_name = "MM[,MM]",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub reference: Vec<f64>,
    /// Grade the N most severe lesions (tandem stenoses), by diameter stenosis, the most
    /// severe first: of the closed section of least area and, by increasing area, each section
    /// outside the lesions found that is narrowed against its own fitted reference, its
    /// narrowed segment apart from theirs. Implies --stenosis.
    #[arg(
        long,
        value_name = "N",
        value_parser = clap::value_parser!(u32).range(1..=100),
        conflicts_with_all = ["lesion", "reference"]
    )]
    pub lesions: Option<u32>,
    /// The fitted reference uses the sections within this many mm of the lesion, either side
    /// [default: 20]. Implies --stenosis.
    #[arg(long, value_name = "MM", allow_negative_numbers = true)]
    pub span: Option<f64>,
    /// Write the table as CSV to FILE.
    #[arg(short, long, value_name = "FILE.csv")]
    pub output: Option<PathBuf>,
    /// The angle the path turns through at B: the chord from its point at arc length A to
    /// B's against the chord from B's to C's, mm along the path (A < B < C), as a stent-graft
    /// plan measures a neck's angulation on the centreline; 0 deg runs straight on.
    #[arg(
        long,
        value_name = "A,B,C",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub angle: Vec<f64>,
    /// Write the lumen (label 1) and, with --wall, what the outer wall holds beyond it (label
    /// 2) as a label map on the CT's own grid, for a viewer to lay over the CT: NIfTI (.nii
    /// or .nii.gz; 3D Slicer, ITK-SNAP), a 3D Slicer segmentation (.seg.nrrd: named, coloured
    /// segments in Slicer's Segment Editor), or, from a DICOM series, a DICOM Segmentation of
    /// it (.dcm; PACS viewers) that files with its study. From sections as far apart as the
    /// CT's finest voxel spacing, each voxel labelled by the nearest section's plane.
    #[arg(long, value_name = "FILE.nii.gz|FILE.seg.nrrd|FILE.dcm")]
    pub mask: Option<PathBuf>,
    /// From a DICOM series: the lumen and, with --wall, the wall beyond it (the labels --mask
    /// writes, with it or without) as a DICOM RT Structure Set of it (.dcm), for a
    /// radiotherapy planning system: each slice's regions as closed contours along their
    /// voxels' edges, which give back the labels voxel for voxel.
    #[arg(long, value_name = "FILE.dcm")]
    pub structures: Option<PathBuf>,
    /// Draw the diameters against arc length to FILE (.svg, .png, or .dcm: the PNG's pixels
    /// as a DICOM Secondary Capture of the input's study): D eq, D max and D min, open
    /// sections, and with --stenosis the reference, the lesion and the narrowed segment.
    #[arg(long, value_name = "FILE.svg|png|dcm")]
    pub plot: Option<PathBuf>,
    /// With --dark --wall: draw the airway's walls for Pi10 to FILE (.svg, .png or .dcm, as
    /// --plot): √WA against the internal perimeter, a dot a section, the line fitted to them
    /// and Pi10 ringed on it at 10 mm.
    #[arg(long, value_name = "FILE.svg|png|dcm")]
    pub plot_pi10: Option<PathBuf>,
    /// From a DICOM series, write the findings as a DICOM Structured Report that files with
    /// its study (Imaging Measurement Report, TID 1500, in a Comprehensive 3D SR: PACS,
    /// OHIF, 3D Slicer): the vessel's path length, widest and narrowest lumen and outer wall
    /// with where each was taken, each graded lesion, the angle, and with a DICOM
    /// Segmentation --mask, each segment's volume, referencing it. With --dark, the airway's:
    /// its lumen, and with --wall its wall's thickness, WA % and Pi10.
    #[arg(long, value_name = "FILE.dcm")]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub pick: VolumePick,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
    #[arg(short, long)]
    pub quiet: bool,
}

impl MeasureArgs {
    /// How to grade a stenosis, if one is asked for.
    pub fn stenosis(&self) -> Option<raystream_cpu::stenosis::StenosisOptions> {
        let asked = self.stenosis
            || self.lesions.is_some()
            || self.lesion.is_some()
            || !self.reference.is_empty()
            || self.span.is_some();
        let default = raystream_cpu::stenosis::StenosisOptions::default();
        asked.then(|| raystream_cpu::stenosis::StenosisOptions {
            lesion_mm: self.lesion,
            reference_mm: self.reference.clone(),
            span_mm: self.span.unwrap_or(default.span_mm),
        })
    }
}

#[derive(Args)]
pub struct CentrelineArgs {
    /// CT volume (DICOM folder or file, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .vtk, .vti,
    /// NAME_WxHxD_TYPE.raw).
    pub input: PathBuf,
    /// The points placed in the vessel, in order (its two ends, and any between that it must
    /// pass): 3D Slicer markups (.mrk.json) or text (x y z per line, LPS mm), as `render
    /// --path` reads a path.
    #[arg(long, value_name = "FILE")]
    pub path: PathBuf,
    /// Where to write the centreline: 3D Slicer markups (.mrk.json, .json) or text.
    #[arg(short, long, value_name = "FILE")]
    pub output: PathBuf,
    #[command(flatten)]
    pub vessel: LumenPick,
    /// The search reaches this far beyond the points' extent, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 30.0,
        allow_negative_numbers = true
    )]
    pub margin: f64,
    /// Gaps in the lumen narrower than twice this (a dissection flap, a graft's fabric, noise)
    /// are closed before its middle is found, mm (0: none).
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 3.0,
        allow_negative_numbers = true
    )]
    pub close: f64,
    /// The path is smoothed over this length of it, mm (0: the voxel path as found).
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 5.0,
        allow_negative_numbers = true
    )]
    pub smooth: f64,
    /// The control points written are this far apart along the path, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 2.0,
        allow_negative_numbers = true
    )]
    pub step: f64,
    #[command(flatten)]
    pub pick: VolumePick,
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Args)]
pub struct TraceArgs {
    /// Mesh file.
    pub mesh: PathBuf,
    /// Rays: per ray 8 little-endian f32, ox oy oz t_min dx dy dz t_max.
    #[arg(long)]
    pub rays: PathBuf,
    /// Hits: per ray t (f32, +inf on miss), prim (u32, 0xFFFFFFFF on miss), u, v (f32).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Occlusion queries: any hit in [t_min, t_max].
    #[arg(long)]
    pub any: bool,
    #[command(flatten)]
    pub accel: Accel,
    /// GPU: one fused query kernel, traversal and intersection kernels split (the paper's
    /// layout: (ray, leaf) work items between them), the fused loop in persistent threads
    /// fetching rays from a global counter (Aila & Laine 2009), or the fused loop in their
    /// "if-if" form (one traversal step and one triangle step per iteration).
    #[arg(long, value_enum, default_value = "fused")]
    pub kernels: KernelsArg,
    /// Timed runs after warming up; the median is reported. On a GPU the same number of
    /// queries is then queued in one submission and timed together (`stream_ms`).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
    /// GPU, fused or ifif kernels: also count the kernel's steps per ray, its SIMD efficiency
    /// (the share of subgroup lanes busy) and the most invocations resident at once, where
    /// the adapter has subgroups; and time the floor under the query on the same rays (a
    /// kernel that reads each ray and writes a miss, traversing nothing: `floor` in the JSON),
    /// so that what the traversal takes stands apart from the dispatch and its memory traffic.
    #[arg(long)]
    pub stats: bool,
    /// Print one JSON line of timings.
    #[arg(long)]
    pub json: bool,
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Args)]
pub struct InfoArgs {
    /// Mesh file, CT volume (DICOM folder or file, .nii/.nii.gz, .nrrd/.nhdr, .mha/.mhd, .vtk, .vti,
    /// NAME_WxHxD_TYPE.raw) or
    /// scene file (.toml).
    #[arg(required_unless_present = "gpu")]
    pub input: Option<PathBuf>,
    /// Instead of a file: the GPU adapters (Vulkan, Metal, DX12) found here, in the order
    /// `--device gpu` prefers them, with what each offers raystream.
    #[arg(long, conflicts_with = "input")]
    pub gpu: bool,
    #[command(flatten)]
    pub pick: VolumePick,
    #[command(flatten)]
    pub tree: TreeArgs,
    /// A label map's labels named from a colour table (3D Slicer's or ITK-SNAP's, as
    /// `iso --colour-table`), over a DICOM Segmentation's own.
    #[arg(long, alias = "color-table", value_name = "FILE")]
    pub colour_table: Option<PathBuf>,
    /// A CT volume: its values within each segment of LABELS (a label map, a DICOM
    /// Segmentation, an RT Structure Set or a folder of NIfTI masks, TotalSegmentator's, on
    /// any grid: each CT voxel takes the label at its centre): voxels, volume, mean, standard
    /// deviation, minimum, median, maximum, centroid.
    #[arg(long, value_name = "LABELS")]
    pub segmentation: Option<PathBuf>,
    /// With --segmentation: each segment's share of voxels below each of these values (HU;
    /// a list, or the option again): a lung's emphysema index LAA-950 is `--below -950` on an
    /// inspiratory CT, air trapping `--below -856` on an expiratory one.
    #[arg(
        long,
        value_name = "HU",
        requires = "segmentation",
        value_delimiter = ',',
        value_parser = parse_below,
        allow_hyphen_values = true
    )]
    pub below: Vec<f64>,
    /// With --below: the clusters each segment's voxels below each value make (in 3D, or
    /// `--clusters 2d` within each slice), and how their sizes are spread: the count of
    /// clusters at least X in size falls as X^-D (Mishima et al.), D lower where emphysema's
    /// small clusters have merged into larger ones, even with LAA-950 still normal.
    #[arg(
        long,
        value_name = "3d|2d",
        requires = "below",
        num_args = 0..=1,
        default_missing_value = "3d"
    )]
    pub clusters: Option<ClustersArg>,
    /// With --below: each segment's voxels below the first --below value written on the CT's
    /// grid as a NIfTI label map (.nii or .nii.gz), each labelled with its segment's number
    /// and named and coloured as it in a label table (a header extension, as
    /// TotalSegmentator's files carry one): the low attenuation areas, for `iso` and `render`
    /// (emphysema's clusters in 3D) or a viewer.
    #[arg(long, value_name = "FILE.nii.gz", requires = "below")]
    pub below_mask: Option<PathBuf>,
    /// With --segmentation: each segment's values at these percentiles (0 to 100; a list, or
    /// the option again), interpolated between the nearest ranks as numpy does: a lung's
    /// Perc15 is `--percentile 15`.
    #[arg(
        long,
        value_name = "P",
        requires = "segmentation",
        value_delimiter = ',',
        value_parser = parse_percentile
    )]
    pub percentile: Vec<f64>,
    /// With --segmentation: segments measured together as one region, NAME=LIST (LIST as
    /// --segment takes it: label numbers or segment names, comma-separated; the option again
    /// for another), densitometry included: a whole lung from its lobes,
    /// `--combine "left lung=lung_upper_lobe_left,lung_lower_lobe_left"`.
    #[arg(
        long,
        value_name = "NAME=LIST",
        requires = "segmentation",
        value_parser = parse_combine
    )]
    pub combine: Vec<(String, String)>,
    /// With --segmentation: each segment's calcium score as Agatston defined it, on a
    /// non-contrast CT at 120 kVp (the coronary arteries', each artery a segment, or the
    /// aortic valve's): lesions of 130 HU or more and 1 mm² or more within each slice, each
    /// its area times 1 to 4 by its peak (130, 200, 300, 400 HU), slices of other than 3 mm
    /// weighted by spacing / 3 mm; the volume score, and the CAC-DRS category (A0 to A3) of
    /// a total (--combine the arteries).
    #[arg(long, requires = "segmentation")]
    pub agatston: bool,
    /// With --agatston: each segment's lesions counted written on the CT's grid as a NIfTI
    /// label map (.nii or .nii.gz), each labelled with its segment's number, named and
    /// coloured as it in a label table: to check them over the CT (`render CT --mode slice
    /// --segmentation FILE --outline`).
    #[arg(long, value_name = "FILE.nii.gz", requires = "agatston")]
    pub agatston_mask: Option<PathBuf>,
    /// With --segmentation: the lungs' density adjusted for the depth of the breath,
    /// REGION=ML: the region (segment names or numbers, comma-separated, or a --combine's
    /// name: both lungs) taken to the volume ML (their volume on an earlier CT), or
    /// REGION=tlc:SEX:CM (male or female), to the total lung capacity predicted for that sex
    /// and height (ECSC/ERS 1993). By the sponge model, mass held (HU + 1000 scaled by the
    /// region's volume over ML): the mean and percentiles of the region and of each segment
    /// within it, as the trials of alpha-1 antitrypsin augmentation adjust Perc15.
    #[arg(
        long,
        value_name = "REGION=ML|REGION=tlc:SEX:CM",
        requires = "segmentation",
        value_parser = parse_adjust_to
    )]
    pub adjust_to: Option<(String, AdjustTo)>,
    /// A CT volume in HU: the patient's body as `render --body-only` finds it (the table, a
    /// head holder, cables left out; what it encloses kept): its volume, what was left out,
    /// and its tissues by HU (below -190 air, gas and lung; -190 to -30 fat; -29 to 150 soft
    /// tissue; above 150 bone and contrast).
    #[arg(long)]
    pub body: bool,
    /// With --body: the body (label 1) written on the CT's own grid as a NIfTI label map
    /// (.nii or .nii.gz), a 3D Slicer segmentation (.seg.nrrd) or, from a DICOM series, a
    /// DICOM Segmentation of it (.dcm).
    #[arg(
        long,
        value_name = "FILE.nii.gz|FILE.seg.nrrd|FILE.dcm",
        requires = "body"
    )]
    pub mask: Option<PathBuf>,
    /// With --body, from a DICOM series: the body as a DICOM RT Structure Set of it (.dcm),
    /// one structure of type EXTERNAL, the outline a planning system computes dose within.
    #[arg(long, value_name = "FILE.dcm", requires = "body")]
    pub structures: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Mesh file, or a CT volume (measures isosurface extraction, or with --mode direct
    /// volume rendering).
    pub input: PathBuf,
    /// Volumes: the isosurface threshold (--iso HU, default 300) or, with --mode dvr, the
    /// transfer function (--preset, default ct-bone).
    #[command(flatten)]
    pub threshold: Threshold,
    /// Volumes: measure direct volume rendering in this mode over an orbit of --frames
    /// frames (dvr: without and with --shadows, side by side).
    #[arg(long, value_enum)]
    pub mode: Option<ModeArg>,
    #[command(flatten)]
    pub look: VolumeLook,
    /// Volumes with --mode: frames of the orbit (one every 360/N degrees), after one warm-up.
    #[arg(long, default_value_t = 36, value_parser = clap::value_parser!(u32).range(1..=3600))]
    pub frames: u32,
    /// Volumes with --mode: resample the volume to N×N×N voxels first (the benchmark's 512;
    /// at most 1024: 4 GiB of f32 on the host).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=1024))]
    pub resample: Option<u32>,
    /// Volumes with --mode: frames coloured by a segmentation's segments (dvr, iso,
    /// cinematic), as `render --segmentation` colours them (laid on the resampled grid).
    #[arg(long, value_name = "FILE")]
    pub segmentation: Option<PathBuf>,
    /// With --segmentation: only these segments drawn (mip, minip and average too), as
    /// `render --segment`.
    #[arg(long, value_name = "LIST", requires = "segmentation")]
    pub segment: Option<String>,
    /// Devices to measure, comma-separated (cpu, gpu, auto).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "cpu")]
    pub device: Vec<Device>,
    /// Use the first GPU adapter whose name contains this (case-insensitive).
    #[arg(long)]
    pub adapter: Option<String>,
    #[command(flatten)]
    pub tree: TreeArgs,
    #[arg(long, value_enum, default_value = "ropes")]
    pub traversal: TraversalArg,
    /// GPU query kernels to measure, comma-separated (fused, split, persistent, ifif), side by side.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "fused")]
    pub kernels: Vec<KernelsArg>,
    /// Image size of the ray sets.
    #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Timed runs per ray set after one warm-up.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub repeat: u32,
    /// Meshes: also write the ray sets to this folder as primary.rays, shadow.rays and
    /// diffuse.rays (RAYS.bin format), for `trace` and `rays.py`.
    #[arg(long, value_name = "DIR")]
    pub save_rays: Option<PathBuf>,
    /// JSON lines only.
    #[arg(long)]
    pub json: bool,
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{s}' is not WIDTHxHEIGHT"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in '{s}'"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in '{s}'"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("size '{s}' must be between 1x1 and 16384x16384"));
    }
    Ok((w, h))
}
