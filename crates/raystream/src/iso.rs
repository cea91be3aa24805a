//! `raystream iso`: a CT volume's bone isosurface as a mesh file, and the volume → bones step
//! that `render VOLUME` and the built-in default share.

use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};
use raystream_io::{ValueUnit, Volume, VolumeSelect};
use raystream_volume::{IsoSurface, extract_isosurface};

use crate::cli::IsoArgs;
use crate::common::{ms, spinner};

/// The bone surface of a volume, with the time each step took.
pub struct Bones {
    pub surface: IsoSurface,
    /// The threshold, HU.
    pub hu: f32,
    pub voxels: usize,
    pub load_ms: f64,
    pub iso_ms: f64,
}

/// Loads `path` (or takes `embedded` bytes as NIfTI) and extracts the surface at `hu`.
pub fn bones(
    path: &Path,
    select: &VolumeSelect,
    hu: f32,
    smoothing: u32,
    quiet: bool,
    embedded: Option<&[u8]>,
) -> Result<Bones> {
    let (volume, load_ms) = read_volume(path, select, quiet, embedded)?;
    if !quiet && volume.unit != ValueUnit::Hounsfield {
        eprintln!(
            "raystream: {}: values are not known to be Hounsfield units; the threshold {hu} applies to the raw values",
            path.display()
        );
    }
    let t1 = Instant::now();
    let pb = spinner(
        quiet,
        &format!(
            "marching cubes over {}x{}x{} voxels at {hu} HU",
            volume.dims[0], volume.dims[1], volume.dims[2]
        ),
    );
    let mut surface = extract_isosurface(&volume, hu);
    raystream_volume::smooth(&mut surface, smoothing);
    pb.finish_and_clear();
    if surface.mesh.is_empty() {
        let range = volume
            .value_range()
            .map_or("all NaN".to_string(), |(lo, hi)| format!("{lo} .. {hi}"));
        bail!(
            "{}: no surface at {hu}: the values range over {range}",
            path.display()
        );
    }
    Ok(Bones {
        surface,
        hu,
        voxels: volume.voxel_count(),
        load_ms,
        iso_ms: ms(t1.elapsed()),
    })
}

/// Loads `path` (or takes `embedded` bytes as NIfTI), printing its warnings; also the time it
/// took, ms.
pub fn read_volume(
    path: &Path,
    select: &VolumeSelect,
    quiet: bool,
    embedded: Option<&[u8]>,
) -> Result<(Volume, f64)> {
    let t0 = Instant::now();
    let pb = spinner(quiet, &format!("reading {}", path.display()));
    let volume: Volume = match embedded {
        Some(bytes) => raystream_io::volume::parse_nifti(bytes, path, select.phase)?,
        None => raystream_io::load_volume(path, select)?,
    };
    pb.finish_and_clear();
    if let Some(series) = &volume.series {
        crate::common::set_source_study(&series.study);
    }
    if !quiet {
        for w in &volume.warnings {
            eprintln!("raystream: {}: {w}", path.display());
        }
    }
    Ok((volume, ms(t0.elapsed())))
}

pub fn run(a: &IsoArgs) -> Result<()> {
    let hu = a.threshold.hu()?;
    let b = bones(&a.input, &a.pick.select(), hu, a.smooth, a.quiet, None)?;
    let t = Instant::now();
    raystream_io::write_mesh(&a.output, &b.surface.mesh, Some(&b.surface.normals))?;
    if !a.quiet {
        eprintln!(
            "raystream: wrote {} ({} vertices, {} triangles at {hu} HU): load {:.0} ms, isosurface {:.0} ms ({:.0} M voxels/s), write {:.0} ms",
            a.output.display(),
            b.surface.mesh.positions.len(),
            b.surface.mesh.len(),
            b.load_ms,
            b.iso_ms,
            b.voxels as f64 / b.iso_ms / 1e3,
            ms(t.elapsed())
        );
    }
    Ok(())
}
