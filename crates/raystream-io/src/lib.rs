//! Mesh input: OBJ (tobj), PLY ascii and binary (ply-rs-bw), STL ascii and binary (stl_io),
//! each optionally gzip-compressed (`NAME.ply.gz`). Every reader yields a [`TriMesh`] whose
//! triangle `i` is the i-th triangle of the file's faces fan-triangulated in file order
//! (polygon v0..vk → (v0,v1,v2), (v0,v2,v3), …): that index is the `prim` id everywhere.
//!
//! Bad input never panics and never allocates in proportion to a size a header merely claims:
//! every error names the file and the problem ([`MeshError`]).

mod colour_table;
mod curve;
mod encapsulated_stl;
mod gltf;
mod label_map;
mod measurement_report;
mod ply;
mod secondary_capture;
mod segmentation;
mod shapes;
mod slicer_segmentation;
mod solid;
mod stl;
mod structure_set_write;
mod texture;
mod three_mf;
pub mod volume;
mod vtk_legacy;
mod vtk_mesh;
mod vtk_xml;
mod write;
pub use colour_table::read_colour_table;
pub use encapsulated_stl::{
    ENCAPSULATED_STL, ModelInfo, ModelRecord, is_encapsulated_stl, write_encapsulated_stl,
};
pub use structure_set_write::{
    StructureSetWritten, pixel_loops, structure_set_source, write_structure_set,
};
pub use write::{BONE, MeshPart, write_mesh, write_mesh_parts};

use std::io::{BufReader, Cursor, Read};
use std::path::{Path, PathBuf};

pub use curve::{MAX_CURVE_POINTS, read_curve, write_curve};
pub use label_map::{is_label_map_path, write_label_map, write_label_map_named};
pub use measurement_report::{
    COMPREHENSIVE_3D_SR, Measurement, MeasurementGroup, RAYSTREAM_SCHEME, ReadCode, ReadGroup,
    ReadMeasurement, ReadReport, Region, ReportInfo, ReportWritten, SegmentationReference,
    is_structured_report, measurement_report_source, read_measurement_report,
    write_measurement_report,
};
pub use raystream_math::{Aabb, Vec2, Vec3};
pub use secondary_capture::{
    CaptureInfo, CapturePixels, HU_PADDING, ImagePlane, new_uid, write_secondary_capture,
};
pub use segmentation::{
    Code, SEGMENTATION, Segment, SegmentationInfo, SegmentationWritten, cielab,
    is_segmentation_path, segmentation_source, srgb_from_cielab, write_segmentation,
};
pub use slicer_segmentation::{is_slicer_segmentation_path, write_slicer_segmentation};
pub use solid::SurfaceMeasures;
pub use texture::{MAX_TEXELS, SRGB_TO_LINEAR, Texture, TextureMapping, linear_to_srgb8};
pub use volume::{
    DicomSeriesInfo, DicomStudy, MAX_VOXELS, Phase, RT_STRUCTURE_SET, RasterNotes, Roi,
    SegmentLabel, SegmentTerms, SegmentVoxels, SourceImage, StructureSet, ValueUnit, Volume,
    VolumeError, VolumeFormat, VolumeSelect, WholeSegments, is_structure_set_file,
    is_structure_set_volume, is_volume_path, list_dicom_series, load_volume, whole_segments,
};

/// A triangle mesh: shared vertex positions and triangles as vertex-index triples.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// What went wrong reading a mesh, always with the file it came from.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read or written. (The I/O error is in the message, not a
    /// `source`: a chain printed in full would say it twice.)
    #[error("{path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

impl MeshError {
    pub fn invalid(path: &Path, problem: impl Into<String>) -> Self {
        MeshError::Invalid {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }
}

/// The mesh formats raystream reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    Obj,
    Ply,
    Stl,
    /// glTF 2.0, `.gltf` or `.glb`.
    Gltf,
    /// Legacy VTK polygonal data (`.vtk`, `DATASET POLYDATA`): 3D Slicer's models.
    Vtk,
    /// VTK XML polygonal data (`.vtp`): ParaView's surfaces.
    VtkXml,
    /// 3MF (`.3mf`): 3D printing's packages of parts.
    ThreeMf,
    /// A DICOM Encapsulated STL (a `.dcm`, or a DICOM file without an extension, of that SOP
    /// class): the STL a hospital files with its study, in its patient's LPS millimetres.
    DicomStl,
}

impl MeshFormat {
    /// The format named by a file's extension (a trailing `.gz` is looked through).
    pub fn from_path(path: &Path) -> Option<Self> {
        if encapsulated_stl::is_encapsulated_stl(path) {
            return Some(Self::DicomStl);
        }
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        let name = name.strip_suffix(".gz").unwrap_or(&name);
        match name.rsplit_once('.')?.1 {
            "obj" => Some(Self::Obj),
            "ply" => Some(Self::Ply),
            "stl" => Some(Self::Stl),
            "gltf" | "glb" => Some(Self::Gltf),
            "vtk" => Some(Self::Vtk),
            "vtp" => Some(Self::VtkXml),
            "3mf" => Some(Self::ThreeMf),
            _ => None,
        }
    }
}

/// Whether `path` names a mesh file raystream can read (by extension).
pub fn is_mesh_path(path: &Path) -> bool {
    MeshFormat::from_path(path).is_some()
}

/// Reads a mesh file, choosing the reader by extension.
pub fn load_mesh(path: &Path) -> Result<TriMesh, MeshError> {
    let (format, bytes) = read_mesh_file(path)?;
    parse_mesh_in(&bytes, format, path, path.parent())
}

/// Reads a mesh file with what it gives its surface besides the triangles: vertex normals (OBJ
/// `vn`, PLY `nx ny nz`) and, for an OBJ, the materials of the material libraries it names
/// (`mtllib`, looked up beside the file) and which triangle has which (`usemtl`). The
/// triangles are [`load_mesh`]'s, in the same order; an OBJ's vertices are split where a
/// position carries several normals or materials. A library that is missing or unreadable is a
/// warning, not an error: the geometry is still the file's.
pub fn load_mesh_with_shading(path: &Path) -> Result<(TriMesh, MeshShading), MeshError> {
    let (format, bytes) = read_mesh_file(path)?;
    let (format, bytes, dicom) = unwrapped(format, &bytes, path)?;
    let bytes = gunzip(&bytes, path)?;
    let (mesh, mut shading, normals) = match format {
        MeshFormat::Obj => parse_obj(&bytes, path, path.parent())?,
        MeshFormat::Ply => {
            let ply = ply::parse(&bytes, path)?;
            let shading = MeshShading {
                colours: ply.colours,
                ..Default::default()
            };
            (
                ply.mesh,
                shading,
                ply.normals.into_iter().map(Some).collect(),
            )
        }
        MeshFormat::Stl | MeshFormat::DicomStl => {
            let stl = stl::parse(&bytes, path)?;
            let shading = MeshShading {
                colours: stl.colours,
                ..Default::default()
            };
            (stl.mesh, shading, Vec::new())
        }
        MeshFormat::Gltf => {
            let g = gltf::parse(&bytes, path, path.parent(), true)?;
            let shading = MeshShading {
                materials: g.materials,
                material_of: g.material_of,
                uvs: g.uvs,
                colours: g.colours,
                warnings: g.warnings,
                ..Default::default()
            };
            (g.mesh, shading, g.normals)
        }
        MeshFormat::ThreeMf => {
            let m = three_mf::parse(&bytes, path)?;
            let shading = MeshShading {
                colours: m.colours,
                objects: m.objects,
                warnings: m.warnings,
                ..Default::default()
            };
            (m.mesh, shading, Vec::new())
        }
        MeshFormat::Vtk | MeshFormat::VtkXml => {
            let poly = if format == MeshFormat::Vtk {
                vtk_mesh::parse(&bytes, path)?
            } else {
                vtk_xml::parse_poly(&bytes, path)?
            };
            let shading = MeshShading {
                colours: poly.colours,
                warnings: poly.warnings,
                space: poly.space,
                ..Default::default()
            };
            (
                poly.mesh,
                shading,
                poly.normals.into_iter().map(Some).collect(),
            )
        }
    };
    mesh.check(path)?;
    shading.space = shading.space.or(declared_space(&bytes, format));
    if dicom.is_some() {
        // DICOM's patient coordinates are LPS millimetres, whatever the STL's header says.
        shading.space = Some(PatientSpace::Lps);
    }
    shading.dicom = dicom;
    shading.normals = file_normals(&mesh, normals, &mut shading.warnings);
    if format == MeshFormat::Obj {
        // An OBJ's textures are named by its libraries; a glTF file's come with it.
        load_textures(&mut shading, path.parent().unwrap_or(Path::new(".")));
    }
    Ok((mesh, shading))
}

/// Reads the images of the materials' textures (`map_Kd`), named relative to `dir`. One that
/// cannot be read, or that the mesh could not apply (no texture coordinates), is a warning and
/// is left out: its `Kd` stands in.
fn load_textures(shading: &mut MeshShading, dir: &Path) {
    let used: std::collections::HashSet<u32> =
        shading.material_of.iter().flatten().copied().collect();
    for (k, m) in shading.materials.iter_mut().enumerate() {
        let Some(name) = m.texture.as_deref() else {
            continue;
        };
        if !used.contains(&(k as u32)) {
            continue;
        }
        if shading.uvs.is_empty() {
            shading.warnings.push(format!(
                "material '{}': texture {name} is not applied: not every face corner gives texture coordinates (vt); its diffuse colour stands in",
                m.name
            ));
            continue;
        }
        // A file whose name looks like options is taken whole.
        let (file, mapping, ignored) = match dir.join(name).is_file() {
            true => (name, TextureMapping::default(), Vec::new()),
            false => texture_options(name),
        };
        let file = dir.join(file);
        for option in ignored {
            shading.warnings.push(format!(
                "material '{}': texture option {option} is not applied",
                m.name
            ));
        }
        match Texture::load(&file) {
            Ok(t) => m.image = Some(Texture { mapping, ..t }),
            Err(e) => shading.warnings.push(format!(
                "material '{}': texture {}: {e}; its diffuse colour stands in",
                m.name,
                file.display()
            )),
        }
    }
}

/// Reads `map_Kd`'s options (`-s u [v [w]]`, `-o u [v [w]]`, `-clamp on|off`; the others,
/// such as `-mm`, `-t` or `-blendu`, are skipped with their arguments and returned to be
/// warned of); the rest of the statement is the file name, spaces included.
fn texture_options(statement: &str) -> (&str, TextureMapping, Vec<String>) {
    let words: Vec<&str> = statement.split_whitespace().collect();
    let mut mapping = TextureMapping::default();
    let mut ignored = Vec::new();
    let mut i = 0;
    while let Some(&word) = words
        .get(i)
        .filter(|w| w.starts_with('-') && w.parse::<f32>().is_err())
    {
        let args = &words[i + 1..];
        // Up to three numbers follow -s, -o and -t; two -mm; one word the others.
        let numbers: Vec<f32> = args.iter().map_while(|w| w.parse().ok()).take(3).collect();
        let takes = match word {
            "-s" | "-o" | "-t" => numbers.len(),
            "-mm" => 2,
            _ => 1,
        }
        .min(args.len());
        match (word, &numbers[..]) {
            ("-s", [u, v, ..]) => mapping.scale = Vec2::new(*u, *v),
            ("-s", [u]) => mapping.scale = Vec2::new(*u, 1.0),
            ("-o", [u, v, ..]) => mapping.offset = Vec2::new(*u, *v),
            ("-o", [u]) => mapping.offset = Vec2::new(*u, 0.0),
            ("-clamp", _) => mapping.clamp = args.first() == Some(&"on"),
            _ => ignored.push(words[i..=i + takes].join(" ")),
        }
        i += 1 + takes;
    }
    // The file name runs from its first word to the end, inner spaces kept (the word's offset
    // in the statement, from the pointers of the same string); options and nothing after them
    // leave the whole statement, a file that will not be found.
    let file = match words.get(i) {
        Some(first) => {
            statement[first.as_ptr() as usize - statement.as_ptr() as usize..].trim_end()
        }
        None => statement.trim(),
    };
    (file, mapping, ignored)
}

/// A file's vertex normals (`None`: the file gives that vertex none) as unit vectors, the
/// face-averaged normal standing in for those missing, of zero length or not finite (these last
/// with a warning); empty when the file gives none at all.
fn file_normals(mesh: &TriMesh, given: Vec<Option<Vec3>>, warnings: &mut Vec<String>) -> Vec<Vec3> {
    if given.iter().all(Option::is_none) {
        return Vec::new();
    }
    let averaged = mesh.vertex_normals();
    let mut bad = 0;
    let normals = given
        .iter()
        .zip(&averaged)
        .map(|(n, &avg)| match n {
            None => avg,
            Some(n) => {
                let unit = n.normalize_or_zero();
                if unit == Vec3::ZERO || !unit.is_finite() {
                    bad += 1;
                    avg
                } else {
                    unit
                }
            }
        })
        .collect();
    if bad > 0 {
        warnings.push(format!(
            "{bad} vertex normal{} of zero length or not finite: the face-averaged normal stands in",
            if bad == 1 { " is" } else { "s are" }
        ));
    }
    normals
}

fn read_mesh_file(path: &Path) -> Result<(MeshFormat, Vec<u8>), MeshError> {
    let format = MeshFormat::from_path(path).ok_or_else(|| {
        MeshError::invalid(
            path,
            "unsupported format: not a mesh (.obj, .ply, .stl, optionally .gz, .gltf, .glb, .vtp, .3mf, or a .vtk of polygons) nor a volume (a DICOM folder, file or .zip, .nii, .nii.gz, .nrrd, .nhdr, .mha, .mhd, .vti, a .vtk of image data, or NAME_WxHxD_TYPE.raw)",
        )
    })?;
    let bytes = std::fs::read(path).map_err(|error| MeshError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    Ok((format, bytes))
}

/// A material of an OBJ's material library (`.mtl`): the statements raystream's Phong
/// materials take from it, as the file gives them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MtlMaterial {
    pub name: String,
    /// `Kd`, `Ks`, `Ns`.
    pub diffuse: Option<[f32; 3]>,
    pub specular: Option<[f32; 3]>,
    pub shininess: Option<f32>,
    /// `d`, or 1 − `Tr`: 1 is opaque.
    pub dissolve: Option<f32>,
    /// `Ni`, the index of refraction.
    pub ior: Option<f32>,
    /// `illum`, the illumination model: 3, 5 and 8 reflect as mirrors, 4, 6, 7 and 9 are
    /// transparent.
    pub illum: Option<u8>,
    /// `map_Kd`: the colour texture's file name, as the library gives it.
    pub texture: Option<String>,
    /// That texture's image, read from beside the library (`None`: there is none, or it could
    /// not be read or applied, which the warnings say); it multiplies `Kd`.
    pub image: Option<Texture>,
}

/// An 8-bit sRGB colour, as mesh files give their vertices' colours.
pub type Rgb8 = [u8; 3];

/// The colour a triangle is given where its file colours others but not it (a colour STL's,
/// a 3MF's): the default material's diffuse reflectance (0.7, linear light) in 8-bit sRGB, so
/// that it is drawn as it would be in a file without colours (raystream-scene's tests hold
/// the two together).
pub const UNCOLOURED_GREY: Rgb8 = [218; 3];

/// A display colour channel written as a number from 0 to 1 (a PLY's float `red`, an OBJ's
/// vertex colour) as 8 bits: rounded, clamped, NaN as 0.
pub(crate) fn unit_to_8bit(c: f64) -> u8 {
    if c.is_nan() {
        0
    } else {
        (c.clamp(0.0, 1.0) * 255.0).round() as u8
    }
}

/// Per triangle, its corners' colours from its vertices'.
pub(crate) fn corner_colours(triangles: &[[u32; 3]], of_vertex: &[Rgb8]) -> Vec<[Rgb8; 3]> {
    triangles
        .iter()
        .map(|t| t.map(|v| of_vertex[v as usize]))
        .collect()
}

/// What a mesh file gives its surface besides the triangles: vertex normals, and the materials
/// of an OBJ's `mtllib` and `usemtl`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshShading {
    /// Per vertex, the file's unit normal; empty when the file gives none. Where it gives some
    /// vertices none, or one of zero length or not finite, the face-averaged normal
    /// ([`TriMesh::vertex_normals`]) stands in (the latter with a warning).
    pub normals: Vec<Vec3>,
    pub materials: Vec<MtlMaterial>,
    /// Per triangle, its material's index in `materials`, `None` where the file names none (or
    /// one its libraries lack); empty when the file uses no material.
    pub material_of: Vec<Option<u32>>,
    /// Per triangle, its corners' texture coordinates (OBJ `vt`); empty when the file gives
    /// none, or not at every corner.
    pub uvs: Vec<[Vec2; 3]>,
    /// Per triangle, its corners' colours, 8-bit sRGB: a PLY's `red green blue` (per vertex or
    /// per face), an OBJ's `v x y z r g b`, a glTF primitive's `COLOR_0`, a VTK file's colour
    /// scalars (per point or per cell), a binary STL's triangle colours (Materialise's or
    /// VisCAM's); empty when the file gives none. They multiply the
    /// material's ambient and diffuse colours, as a texture does.
    pub colours: Vec<[Rgb8; 3]>,
    /// The file's objects, in its order, each with the triangles it holds: a 3MF's build items
    /// (named by their objects, or "object ID"); empty for the other formats.
    pub objects: Vec<(String, usize)>,
    /// What a user should know: a library missing or unreadable, a texture not applied.
    pub warnings: Vec<String>,
    /// The patient coordinate system the file says its coordinates are in, if it says one
    /// ([`declared_space`]).
    pub space: Option<PatientSpace>,
    /// A DICOM Encapsulated STL's title, patient, study and sources.
    pub dicom: Option<ModelRecord>,
}

/// A patient coordinate system a mesh's coordinates are in, millimetres: LPS (x to the
/// patient's left, y posterior, z superior: DICOM's, and raystream's volumes') or RAS (x right,
/// y anterior: NIfTI's, and 3D Slicer's models before Slicer 5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatientSpace {
    Lps,
    Ras,
}

impl PatientSpace {
    /// A point or direction of this space in LPS.
    pub fn to_lps(self, p: Vec3) -> Vec3 {
        match self {
            PatientSpace::Lps => p,
            PatientSpace::Ras => Vec3::new(-p.x, -p.y, p.z),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            PatientSpace::Lps => "LPS",
            PatientSpace::Ras => "RAS",
        }
    }
}

/// The coordinate system a mesh file declares with 3D Slicer's tag `SPACE=LPS` or `SPACE=RAS`
/// (as NRRD names it): in an STL's header (`solid 3D Slicer output. SPACE=RAS`, or a binary
/// STL's 80 bytes), a PLY's `comment` lines, an OBJ's `#` comments before its first vertex, a
/// legacy VTK file's title line.
/// Slicer writes it since 4.8 (RAS, then LPS from Slicer 5), and `iso` writes `SPACE=LPS`.
/// `None` where the file names none (glTF has its own axes).
pub fn declared_space(bytes: &[u8], format: MeshFormat) -> Option<PatientSpace> {
    let head = &bytes[..bytes.len().min(1 << 16)];
    let text = String::from_utf8_lossy(head);
    let tagged = |line: &str| -> Option<PatientSpace> {
        let upper = line.to_ascii_uppercase();
        let (before, after) = upper.split_once("SPACE=")?;
        if before.ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_') {
            return None;
        }
        match after.get(..3)? {
            "LPS" => Some(PatientSpace::Lps),
            "RAS" => Some(PatientSpace::Ras),
            _ => None,
        }
    };
    match format {
        // A binary STL's 80-byte header, or an ASCII STL's `solid` line (of any length).
        MeshFormat::Stl if head.starts_with(b"solid") => text.lines().next().and_then(tagged),
        MeshFormat::Stl => tagged(&String::from_utf8_lossy(&head[..head.len().min(80)])),
        MeshFormat::Ply => text
            .lines()
            .take_while(|l| l.trim() != "end_header")
            .filter(|l| l.starts_with("comment") || l.starts_with("obj_info"))
            .find_map(tagged),
        MeshFormat::Obj => text
            .lines()
            .map(str::trim_start)
            .take_while(|l| !l.starts_with("v ") && !l.starts_with("f "))
            .filter(|l| l.starts_with('#'))
            .find_map(tagged),
        // The title line, where 3D Slicer writes `3D Slicer output. SPACE=LPS`.
        MeshFormat::Vtk => text.lines().nth(1).and_then(tagged),
        MeshFormat::DicomStl => Some(PatientSpace::Lps),
        MeshFormat::Gltf | MeshFormat::VtkXml | MeshFormat::ThreeMf => None,
    }
}

/// Parses mesh bytes of a known format; `path` is only used in error messages and to notice
/// gzip compression (a `.gz` name or the gzip magic number). Materials are not read.
pub fn parse_mesh(bytes: &[u8], format: MeshFormat, path: &Path) -> Result<TriMesh, MeshError> {
    parse_mesh_in(bytes, format, path, None)
}

/// [`parse_mesh`], a glTF file's external buffers read from `dir` (none: only embedded ones).
fn parse_mesh_in(
    bytes: &[u8],
    format: MeshFormat,
    path: &Path,
    dir: Option<&Path>,
) -> Result<TriMesh, MeshError> {
    let (format, bytes, _) = unwrapped(format, bytes, path)?;
    let bytes = gunzip(&bytes, path)?;
    let mesh = match format {
        MeshFormat::Obj => parse_obj(&bytes, path, None)?.0,
        MeshFormat::Ply => ply::parse(&bytes, path)?.mesh,
        MeshFormat::Stl | MeshFormat::DicomStl => stl::parse(&bytes, path)?.mesh,
        MeshFormat::Gltf => gltf::parse(&bytes, path, dir, false)?.mesh,
        MeshFormat::Vtk => vtk_mesh::parse(&bytes, path)?.mesh,
        MeshFormat::VtkXml => vtk_xml::parse_poly(&bytes, path)?.mesh,
        MeshFormat::ThreeMf => three_mf::parse(&bytes, path)?.mesh,
    };
    mesh.check(path)?;
    Ok(mesh)
}

/// A mesh's bytes in their format, and what a DICOM wrapping said of it ([`unwrapped`]).
type MeshBytes<'a> = (MeshFormat, std::borrow::Cow<'a, [u8]>, Option<ModelRecord>);

/// The mesh a file's bytes hold, with its format: a DICOM Encapsulated STL's STL (and what
/// the DICOM says of it), else the file's own bytes.
fn unwrapped<'a>(
    format: MeshFormat,
    bytes: &'a [u8],
    path: &Path,
) -> Result<MeshBytes<'a>, MeshError> {
    Ok(match format {
        MeshFormat::DicomStl => {
            let (stl, record) = encapsulated_stl::stl_of(bytes, path)?;
            (MeshFormat::Stl, stl.into(), Some(record))
        }
        _ => (format, bytes.into(), None),
    })
}

/// `bytes`, unzipped if they start with the gzip magic number.
fn gunzip<'a>(bytes: &'a [u8], path: &Path) -> Result<std::borrow::Cow<'a, [u8]>, MeshError> {
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return Ok(std::borrow::Cow::Borrowed(bytes));
    }
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes)
        .read_to_end(&mut out)
        .map_err(|e| MeshError::invalid(path, format!("not a valid gzip stream ({e})")))?;
    Ok(std::borrow::Cow::Owned(out))
}

/// An OBJ's triangles, its materials with `libraries` (the folder its material libraries are
/// looked up in), and per vertex the normal the file gives it (if any).
fn parse_obj(
    bytes: &[u8],
    path: &Path,
    libraries: Option<&Path>,
) -> Result<(TriMesh, MeshShading, Vec<Option<Vec3>>), MeshError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are not part of the geometry: a missing .mtl must not stop the mesh loading.
    let warnings = std::cell::RefCell::new(Vec::new());
    let (models, libs) =
        tobj::load_obj_buf(&mut BufReader::new(Cursor::new(bytes)), &options, |lib| {
            let Some(dir) = libraries else {
                return Ok(Default::default());
            };
            let file = dir.join(lib);
            let read = std::fs::read(&file)
                .map_err(|e| e.to_string())
                .and_then(|b| {
                    let b = mtl_colours_in_threes(&b)?;
                    tobj::load_mtl_buf(&mut BufReader::new(Cursor::new(b)))
                        .map_err(|e| e.to_string())
                });
            read.map_err(|e| {
                warnings.borrow_mut().push(format!(
                    "material library {}: {e}; its materials are left out",
                    file.display()
                ));
                tobj::LoadError::OpenFileFailed
            })
        })
        .map_err(|e| MeshError::invalid(path, format!("cannot read OBJ: {e}")))?;
    let mut warnings = warnings.into_inner();
    let libs = libs.unwrap_or_default();
    // tobj makes up a normal for a corner that names none (its neighbour's): the file's normals
    // count only where every corner names one.
    let [uvs_given, normals_given] = obj_corners_all_name(bytes);
    if normals_given == Some(false) {
        warnings.push(
            "some faces name no normals: the file's normals are left out, and the face-averaged ones used".into(),
        );
    }
    let mut mesh = TriMesh::default();
    let mut material_of = Vec::new();
    let mut normals: Vec<Option<Vec3>> = Vec::new();
    let mut uvs: Vec<[Vec2; 3]> = Vec::new();
    let mut colours: Vec<[Rgb8; 3]> = Vec::new();
    for model in models {
        material_of.extend(std::iter::repeat_n(
            model
                .mesh
                .material_id
                .filter(|&m| m < libs.len())
                .map(|m| m as u32),
            model.mesh.indices.len() / 3,
        ));
        let m = model.mesh;
        if m.positions.len() % 3 != 0 || m.indices.len() % 3 != 0 || m.normals.len() % 3 != 0 {
            return Err(MeshError::invalid(path, "OBJ data is not in triples"));
        }
        if uvs_given == Some(true) && m.texcoord_indices.len() == m.indices.len() {
            let uv = |t: u32| {
                let t = t as usize * 2;
                m.texcoords
                    .get(t..t + 2)
                    .map(|c| Vec2::new(c[0], c[1]))
                    .ok_or_else(|| {
                        MeshError::invalid(
                            path,
                            format!(
                                "a face refers to texture coordinate {}, which the file lacks",
                                t / 2
                            ),
                        )
                    })
            };
            for c in m.texcoord_indices.chunks_exact(3) {
                uvs.push([uv(c[0])?, uv(c[1])?, uv(c[2])?]);
            }
        }
        // tobj gives a colour a position where the file's `v` lines give one.
        if m.vertex_color.len() == m.positions.len() {
            let colour = |i: u32| -> Rgb8 {
                let i = i as usize * 3;
                std::array::from_fn(|c| {
                    unit_to_8bit(m.vertex_color.get(i + c).copied().unwrap_or(0.0) as f64)
                })
            };
            colours.extend(
                m.indices
                    .chunks_exact(3)
                    .map(|t| [colour(t[0]), colour(t[1]), colour(t[2])]),
            );
        }
        let base = mesh.positions.len() as u32;
        let position = |i: u32| {
            let i = i as usize * 3;
            m.positions
                .get(i..i + 3)
                .map(|p| Vec3::new(p[0], p[1], p[2]))
        };
        if normals_given == Some(true) && m.normal_indices.len() == m.indices.len() {
            // A vertex per (position, normal) pair of this model, in the order corners use them.
            let mut vertex: std::collections::HashMap<(u32, u32), u32> = Default::default();
            let mut corners = Vec::with_capacity(m.indices.len());
            for (&pi, &ni) in m.indices.iter().zip(&m.normal_indices) {
                let next = mesh.positions.len() as u32;
                let v = *vertex.entry((pi, ni)).or_insert(next);
                if v == next {
                    let n = ni as usize * 3;
                    let (Some(p), Some(n)) = (position(pi), m.normals.get(n..n + 3)) else {
                        return Err(MeshError::invalid(
                            path,
                            format!(
                                "a face refers to position {pi} or normal {ni}, which the file lacks"
                            ),
                        ));
                    };
                    mesh.positions.push(p);
                    normals.push(Some(Vec3::new(n[0], n[1], n[2])));
                }
                corners.push(v);
            }
            mesh.triangles
                .extend(corners.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
        } else {
            mesh.positions.extend(
                m.positions
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2])),
            );
            normals.resize(mesh.positions.len(), None);
            mesh.triangles.extend(
                m.indices
                    .chunks_exact(3)
                    .map(|t| [base + t[0], base + t[1], base + t[2]]),
            );
        }
    }
    let materials: Vec<MtlMaterial> = libs
        .into_iter()
        .map(|m| MtlMaterial {
            dissolve: m.dissolve.or_else(|| {
                let tr = m.unknown_param.get("Tr")?.trim().parse::<f32>().ok()?;
                Some(1.0 - tr)
            }),
            name: m.name,
            diffuse: m.diffuse,
            specular: m.specular,
            shininess: m.shininess,
            ior: m.optical_density,
            illum: m.illumination_model,
            texture: m.diffuse_texture,
            image: None,
        })
        .collect();
    if material_of.iter().all(Option::is_none) {
        material_of.clear();
    }
    if uvs.len() != mesh.len() {
        uvs.clear();
    }
    if colours.len() != mesh.len() {
        colours.clear();
    }
    Ok((
        mesh,
        MeshShading {
            normals: Vec::new(),
            materials,
            material_of,
            uvs,
            colours,
            warnings,
            ..Default::default()
        },
        normals,
    ))
}

/// An MTL library's colour statements (`Ka`, `Kd`, `Ks`, `Ke`) with three numbers each: MTL
/// lets one number stand for all three (`Kd 0.5`), which tobj 4.0.5 does not read (it panics on
/// fewer than three), so the one is written out thrice here; two numbers, or none, are an error
/// naming the line.
fn mtl_colours_in_threes(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(bytes.len() + 64);
    for (i, line) in bytes.split_inclusive(|&b| b == b'\n').enumerate() {
        let text = String::from_utf8_lossy(line);
        let words: Vec<&str> = text.split_whitespace().collect();
        match words[..] {
            ["Ka" | "Kd" | "Ks" | "Ke", v] if v.parse::<f32>().is_ok() => {
                out.extend_from_slice(format!("{} {v} {v} {v}\n", words[0]).as_bytes());
            }
            ["Ka" | "Kd" | "Ks" | "Ke"] | ["Ka" | "Kd" | "Ks" | "Ke", _, _] => {
                return Err(format!(
                    "line {}: `{}` needs one or three numbers",
                    i + 1,
                    text.trim()
                ));
            }
            _ => out.extend_from_slice(line),
        }
    }
    Ok(out)
}

/// For texture coordinates (`vt`, slot 1 of `v/vt/vn`) and normals (`vn`, slot 2), in that
/// order: whether every corner of every face names one; `None` when the file declares none at
/// all. One pass over the file answers both.
fn obj_corners_all_name(bytes: &[u8]) -> [Option<bool>; 2] {
    let mut any = [false; 2];
    let mut all_corners = [true; 2];
    for line in bytes.split(|&b| b == b'\n') {
        let line = line.trim_ascii_start();
        if ![&b"f"[..], b"vt", b"vn"]
            .iter()
            .any(|k| line.starts_with(k))
        {
            continue;
        }
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("vt") => any[0] = true,
            Some("vn") => any[1] = true,
            Some("f") => {
                for corner in words {
                    let mut slots = corner.split('/').skip(1);
                    for named in &mut all_corners {
                        *named &= slots.next().is_some_and(|n| !n.is_empty());
                    }
                }
            }
            _ => {}
        }
    }
    std::array::from_fn(|k| any[k].then_some(all_corners[k]))
}

impl TriMesh {
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The three corners of triangle `i`.
    pub fn corners(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Bounds of the vertices that triangles use (stray unused points do not count).
    pub fn bounds(&self) -> Aabb {
        self.triangles
            .iter()
            .flatten()
            .fold(Aabb::EMPTY, |b, &i| b.grow(self.positions[i as usize]))
    }

    /// The checks every loaded mesh passes: at least one triangle, indices in range, finite
    /// coordinates within ±[`raystream_math::MAX_COORDINATE`], and not all triangles collapsed
    /// into one point.
    pub fn check(&self, path: &Path) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::invalid(path, "mesh has no triangles"));
        }
        let n = self.positions.len();
        if let Some((i, t)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= n))
        {
            return Err(MeshError::invalid(
                path,
                format!("triangle {i} refers to vertex {t:?}, but the mesh has {n} vertices"),
            ));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshError::invalid(
                path,
                format!(
                    "vertex {i} has a coordinate that is NaN or infinite ({:?})",
                    self.positions[i]
                ),
            ));
        }
        if let Some(i) = self
            .positions
            .iter()
            .position(|&p| !raystream_math::in_coordinate_range(p))
        {
            return Err(MeshError::invalid(
                path,
                format!(
                    "vertex {i} lies beyond ±{:e} ({:?}), too far from the origin for f32 triangle tests; scale or move the mesh",
                    raystream_math::MAX_COORDINATE,
                    self.positions[i]
                ),
            ));
        }
        if self.bounds().extent() == Vec3::ZERO {
            return Err(MeshError::invalid(
                path,
                "all triangles collapse into one point",
            ));
        }
        Ok(())
    }

    /// Appends another mesh, with its vertices moved by `transform`.
    pub fn append(&mut self, other: &TriMesh, transform: impl Fn(Vec3) -> Vec3) {
        let base = self.positions.len() as u32;
        self.positions
            .extend(other.positions.iter().map(|&p| transform(p)));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|v| v + base)));
    }
}

#[cfg(test)]
mod tests;
