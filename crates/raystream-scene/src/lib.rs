//! Scenes: a plain-data description ([`SceneDesc`], parsed from TOML) of camera, lights,
//! materials and objects, compiled into a [`Scene`]: one world-space mesh whose triangle `i`
//! has material `material_of[i]`, with smooth vertex normals, ready for the kd-tree.
//!
//! ```toml
//! [camera]            # optional: without it the camera frames the objects
//! eye = [0, 1, 4]
//! target = [0, 0.5, 0]
//! fov = 40            # vertical, degrees; or parallel_height = 3 (a parallel projection,
//!                     # the view that high in scene units)
//!
//! [[lights]]
//! position = [3, 5, 4]
//! color = [1, 1, 1]
//!
//! [materials.glass]
//! diffuse = [0.1, 0.1, 0.1]
//! transparency = 0.9
//! ior = 1.5
//!
//! [[objects]]
//! mesh = "bunny.ply"        # relative to this file; or shape = "sphere" / "quad" / "spot"
//! material = "glass"
//! translate = [0, 0, 0]
//! rotate = [0, 30, 0]       # degrees about x, y, z (applied in that order)
//! scale = 1.0               # or [sx, sy, sz]
//!
//! [ground]                  # optional plane under the objects
//! material = "floor"
//!
//! [volume]                  # optional CT volume among the meshes (see `SceneVolume`)
//! path = "ct.nii.gz"        # relative to this file
//! preset = "ct-bones"       # or tf = "tf.toml"
//! interpolation = "cubic"   # the default; or "linear", "cubic-interpolating"
//! ```
//!
//! With a volume, the scene frame is millimetres with x = the patient's left, y = superior,
//! z = anterior; objects with `frame = "lps"` or `"ras"` are given in patient coordinates.

mod camera;
mod desc;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

pub use camera::{Camera, FRAME_VIEW, Projection, View};
pub use desc::{
    CameraDesc, Frame, GroundDesc, LightDesc, MaterialDesc, ObjectDesc, Scale, SceneDesc,
    SegmentItem, SegmentList, VolumeDesc,
};
use raystream_io::{
    MeshError, MeshShading, MtlMaterial, Rgb8, Texture, TriMesh, Volume, VolumeError,
};
use raystream_math::{Aabb, DVec3, MAX_COORDINATE, Vec2, Vec3, in_coordinate_range};
use raystream_volume::segments::SegmentColours;
use raystream_volume::{Interpolation, TfPreset, TransferFunction};

/// What went wrong building a scene, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Volume(#[from] VolumeError),
    #[error("{path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
}

/// A point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    pub position: Vec3,
    pub color: Vec3,
}

/// Phong material with Whitted-style reflection and refraction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub ambient: Vec3,
    pub diffuse: Vec3,
    pub specular: Vec3,
    pub shininess: f32,
    /// Fraction of light reflected as a mirror (r_j in the paper's compositing).
    pub reflectivity: f32,
    /// Fraction of light transmitted (refracted).
    pub transparency: f32,
    /// Index of refraction of the inside.
    pub ior: f32,
    /// Whether transmitted light is split by Schlick's Fresnel term into reflection and
    /// refraction (otherwise the fixed coefficients apply).
    pub fresnel: bool,
    /// A colour texture ([`Scene::textures`]) that multiplies `ambient` and `diffuse` at each
    /// point, looked up at the triangle's texture coordinates ([`Scene::uvs`]).
    pub texture: Option<u32>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            ambient: Vec3::splat(0.08),
            diffuse: Vec3::splat(0.7),
            specular: Vec3::splat(0.3),
            shininess: 32.0,
            reflectivity: 0.0,
            transparency: 0.0,
            ior: 1.5,
            fresnel: true,
            texture: None,
        }
    }
}

/// A surface for [`Scene::for_surfaces`]: its triangles and per-vertex normals in LPS
/// millimetres (normals ignored unless one a vertex), and its colour (linear RGB, the
/// material's diffuse).
#[derive(Clone, Debug, Default)]
pub struct Surface {
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
    pub colour: [f32; 3],
}

/// The diffuse colour of bone (linear RGB).
pub const BONE: [f32; 3] = [0.88, 0.84, 0.74];

/// A scene ready to render.
#[derive(Clone, Debug)]
pub struct Scene {
    pub mesh: TriMesh,
    /// Unit vertex normals of `mesh` (for smooth shading).
    pub normals: Vec<Vec3>,
    /// Per vertex of `mesh`: how far secondary rays start off the surface of the triangles
    /// through it, its object's [`ray_offset`] (the ground takes the objects' box's).
    pub ray_offsets: Vec<f32>,
    pub material_of: Vec<u32>,
    pub materials: Vec<Material>,
    /// The materials' colour textures (an OBJ's `map_Kd`).
    pub textures: Vec<Texture>,
    /// Per triangle, its corners' texture coordinates: the file's where it gives them, else 0;
    /// empty when no material has a texture.
    pub uvs: Vec<[Vec2; 3]>,
    /// Per triangle, its corners' colours (8-bit sRGB) where its file gives them (white
    /// elsewhere); empty when no object's file gives colours. Undone to linear light and
    /// interpolated across the triangle, they multiply its material's ambient and diffuse
    /// colours (and its texture's), as MeshLab, ParaView and glTF's `COLOR_0` have them.
    pub colours: Vec<[Rgb8; 3]>,
    pub lights: Vec<Light>,
    /// The camera, or `None` to frame the scene's objects.
    pub camera: Option<Camera>,
    pub background: Vec3,
    /// Ambient light colour.
    pub ambient_light: Vec3,
    /// Bounds of the objects, without the ground plane.
    pub object_box: Aabb,
    /// The ground plane's triangles and vertices: the last ones of `mesh` (0 without one).
    pub ground_triangles: usize,
    pub ground_vertices: usize,
    /// Where a framing camera looks from, and how it projects, when `camera` is `None`.
    pub frame_view: View,
    pub frame_projection: Projection,
    /// A CT volume rendered directly among the meshes.
    pub volume: Option<SceneVolume>,
    /// What a user should know (a material library not found, a texture not applied).
    pub warnings: Vec<String>,
}

/// The CT volume of a scene, ready to render: values in HU on its LPS grid, which the scene
/// frame holds turned by `Frame::Lps` (x = L, y = S, z = A).
#[derive(Clone, Debug)]
pub struct SceneVolume {
    pub volume: Volume,
    pub tf: TransferFunction,
    /// Step in mm; `None`: half the smallest voxel spacing.
    pub step_mm: Option<f32>,
    /// Whether volume samples are lit through shadow rays (light grids).
    pub shadows: bool,
    /// How the volume is read between voxel centres.
    pub interpolation: Interpolation,
    /// The segmentation the scene file names, to be laid on the volume's grid by whoever
    /// renders it (the command line, which reads label maps, Segmentations and structure
    /// sets), who then sets `segments` (and keeps `volume` to the chosen segments).
    pub segmentation: Option<SceneSegmentation>,
    /// Each voxel's segment and each segment's colour: samples take them in place of the
    /// transfer function's colour (`raystream_volume::segments`).
    pub segments: Option<SegmentColours>,
}

/// `segmentation`, `segment` and `colour_table` of a scene's `[volume]`, paths resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSegmentation {
    pub path: PathBuf,
    /// Only these segments (as `--segment` takes them), or all.
    pub segment: Option<String>,
    pub colour_table: Option<PathBuf>,
}

impl SceneVolume {
    /// Loads `d`'s volume and transfer function, paths relative to `base_dir`.
    pub fn load(d: &VolumeDesc, base_dir: &Path) -> Result<SceneVolume, SceneError> {
        let tf = match (&d.tf, &d.preset) {
            (Some(_), Some(_)) => {
                return Err("volume: give 'tf' or 'preset', not both".to_string().into());
            }
            (Some(f), None) => {
                TransferFunction::load(&base_dir.join(f)).map_err(|e| format!("volume: {e}"))?
            }
            (None, p) => {
                let name = p.as_deref().unwrap_or("ct-bone");
                TfPreset::ALL
                    .into_iter()
                    .find(|t| t.name() == name)
                    .ok_or_else(|| {
                        let names: Vec<&str> = TfPreset::ALL.iter().map(|t| t.name()).collect();
                        format!("volume: unknown preset '{name}' ({})", names.join(", "))
                    })?
                    .function()
            }
        };
        if let Some(s) = d.step
            && !(s.is_finite() && s > 0.0)
        {
            return Err(format!("volume: step {s} must be a positive number of mm").into());
        }
        let interpolation = match d.interpolation.as_deref() {
            None => Interpolation::Cubic,
            Some(name) => Interpolation::ALL
                .into_iter()
                .find(|i| i.name() == name)
                .ok_or_else(|| {
                    let names: Vec<_> = Interpolation::ALL.iter().map(|i| i.name()).collect();
                    format!(
                        "volume: unknown interpolation '{name}' ({})",
                        names.join(", ")
                    )
                })?,
        };
        let volume = raystream_io::load_volume(
            &base_dir.join(&d.path),
            &raystream_io::VolumeSelect {
                series: d.series.clone(),
                phase: d.phase,
            },
        )?;
        let mut volume = volume;
        if d.body_only == Some(true) {
            let path = base_dir.join(&d.path);
            if volume.unit != raystream_io::ValueUnit::Hounsfield {
                return Err(format!(
                    "volume: body_only finds the body by its HU; {}'s values are not HU",
                    path.display()
                )
                .into());
            }
            let body = raystream_volume::body::body(&volume, &Default::default())
                .map_err(|e| format!("volume: body_only: {}: {e}", path.display()))?;
            body.hide_outside(&mut volume);
        }
        // A lone slice as the slab it images: a plane of no depth would take no sample.
        let volume = volume.slab_of_lone_slices().unwrap_or(volume);
        // Values of no known unit, given no transfer function: CT-Bone's HU mean nothing
        // there; a ramp from the values' own background up (raystream_volume::auto).
        let unit_free = (d.tf.is_none()
            && d.preset.is_none()
            && volume.unit != raystream_io::ValueUnit::Hounsfield)
            .then(|| raystream_volume::auto::unit_free_transfer(&volume))
            .flatten();
        let tf = unit_free.map_or(tf, |(ramp, _)| ramp);
        let segmentation = match &d.segmentation {
            Some(path) => Some(SceneSegmentation {
                path: base_dir.join(path),
                segment: d.segment.as_ref().map(|s| s.as_option()),
                colour_table: d.colour_table.as_ref().map(|t| base_dir.join(t)),
            }),
            None if d.segment.is_some() || d.colour_table.is_some() => {
                return Err("volume: 'segment' and 'colour_table' choose and colour the segments of a 'segmentation'; give one"
                    .to_string()
                    .into());
            }
            None => None,
        };
        Ok(SceneVolume {
            volume,
            tf,
            step_mm: d.step,
            shadows: d.shadows.unwrap_or(true),
            interpolation,
            segmentation,
            segments: None,
        })
    }

    /// The corners of the grid of voxel centres in the scene frame.
    pub fn corners(&self) -> [Vec3; 8] {
        let [nx, ny, nz] = self.volume.dims.map(|n| n.saturating_sub(1) as f64);
        std::array::from_fn(|c| {
            let idx = DVec3::new(
                if c & 1 != 0 { nx } else { 0.0 },
                if c & 2 != 0 { ny } else { 0.0 },
                if c & 4 != 0 { nz } else { 0.0 },
            );
            Frame::Lps.to_scene(self.volume.index_to_world(idx).as_vec3())
        })
    }
}

/// The embedded Spot mesh (CC0, see `assets/README.md`).
pub fn spot_mesh() -> TriMesh {
    raystream_io::parse_mesh(
        include_bytes!("../assets/spot.obj.gz"),
        raystream_io::MeshFormat::Obj,
        Path::new("<built-in spot.obj>"),
    )
    .expect("the embedded mesh is valid")
}

/// A problem with the lights or the floor that a mesh or a CT's bones get: they lie a few
/// times the object's size around it, so a mesh near the coordinate limit takes them past it.
fn around_the_mesh(e: SceneError) -> SceneError {
    match e {
        SceneError::Invalid { path, problem } => SceneError::Invalid {
            path,
            problem: format!(
                "{problem} (the lights and the floor are placed a few times the mesh's size around it)"
            ),
        },
        e => e,
    }
}

/// `p`, if finite and within ±[`MAX_COORDINATE`].
fn check_point(what: &str, p: Vec3) -> Result<Vec3, String> {
    if in_coordinate_range(p) {
        Ok(p)
    } else {
        Err(format!(
            "{what} {p} must be finite and within ±{MAX_COORDINATE:e}"
        ))
    }
}

/// `c`, if finite and non-negative.
fn check_colour(what: &str, c: Vec3) -> Result<Vec3, String> {
    if c.is_finite() && c.min_element() >= 0.0 {
        Ok(c)
    } else {
        Err(format!("{what} {c} must be finite and non-negative"))
    }
}

/// The camera a description gives, if it defines one: finite points, an eye apart from the
/// target, an up direction not along the view, a field of view between 0 and 180 degrees.
fn camera_of(c: &CameraDesc) -> Result<Camera, String> {
    let eye = check_point("eye", Vec3::from(c.eye))?;
    let target = check_point("target", Vec3::from(c.target))?;
    let up = c.up.map(Vec3::from).unwrap_or(Vec3::Y);
    if let (Some(_), Some(_)) = (c.fov, c.parallel_height) {
        return Err("give fov (perspective) or parallel_height (parallel), not both".into());
    }
    let fov = c.fov.unwrap_or(45.0);
    if !(fov > 0.0 && fov < 180.0) {
        return Err(format!("fov {fov} must be between 0 and 180 degrees"));
    }
    let view = target - eye;
    if view.length() <= 1e-6 * eye.abs().max_element().max(target.abs().max_element()) {
        return Err(format!("eye {eye} and target {target} must differ"));
    }
    if !up.is_finite() || view.normalize().cross(up).length() <= 1e-6 * up.length() {
        return Err(format!("up {up} must be finite and not along the view"));
    }
    let mut cam = Camera::look_at(eye, target, up, fov);
    if let Some(h) = c.parallel_height {
        if !(h > 0.0 && h <= 2.0 * MAX_COORDINATE) {
            return Err(format!(
                "parallel_height {h} must be a positive number of scene units up to {:e}",
                2.0 * MAX_COORDINATE
            ));
        }
        cam.parallel = 0.5 * h;
    }
    Ok(cam)
}

/// An OBJ's material (MTL) as a Phong material:
/// - `Kd` is the diffuse colour, and the ambient one follows it as the default material's does;
/// - `Ks` and `Ns` make the highlight, which the models without one (`illum` 0, 1) lack;
/// - the mirror models (`illum` 3, 5, 8) reflect the mean of `Ks`;
/// - 1 − `d` is the transparency, refracting by `Ni` (1, see-through, where the file gives none
///   or less), with Fresnel's split where it bends light; the mirror gives way where the two
///   would add up to more than 1.
///
/// The result passes the checks a scene file's materials pass (finite, non-negative colours,
/// fractions in [0, 1]).
fn mtl_material(m: &MtlMaterial) -> Result<Material, String> {
    let d = Material::default();
    let illum = m.illum.unwrap_or(2);
    let diffuse = m.diffuse.unwrap_or(d.diffuse.into());
    let specular = if illum < 2 {
        [0.0; 3]
    } else {
        m.specular.unwrap_or(d.specular.into())
    };
    let transparency = 1.0 - m.dissolve.unwrap_or(1.0);
    let mirror = if matches!(illum, 3 | 5 | 8) {
        (specular.iter().sum::<f32>() / 3.0).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let ior = m.ior.filter(|n| *n > 1.0).unwrap_or(1.0);
    MaterialDesc {
        ambient: Some(diffuse.map(|c| c * d.ambient.x / d.diffuse.x)),
        diffuse: Some(diffuse),
        specular: Some(specular),
        shininess: Some(m.shininess.unwrap_or(d.shininess)),
        reflectivity: Some(mirror.min((1.0 - transparency).max(0.0))),
        transparency: Some(transparency),
        ior: Some(ior),
        fresnel: Some(ior > 1.0),
    }
    .to_material()
}

impl Scene {
    /// Compiles a description; mesh paths are relative to `base_dir`, errors name `origin`.
    pub fn from_desc(
        desc: &SceneDesc,
        base_dir: &Path,
        origin: &Path,
    ) -> Result<Scene, SceneError> {
        let volume = match &desc.volume {
            Some(v) => Some(SceneVolume::load(v, base_dir).map_err(|e| match e {
                SceneError::Invalid { problem, .. } => SceneError::Invalid {
                    path: origin.to_path_buf(),
                    problem,
                },
                e => e,
            })?),
            None => None,
        };
        Self::compile(desc, origin, volume, |i, o| match (&o.mesh, &o.shape) {
            (Some(p), None) => Ok(raystream_io::load_mesh_with_shading(&base_dir.join(p))?),
            (None, Some(s)) => builtin_shape(s)
                .map(|m| (m, MeshShading::default()))
                .ok_or_else(|| {
                    format!("object {i}: unknown shape '{s}' (sphere, cylinder, quad, spot)").into()
                }),
            _ => Err(format!("object {i}: give exactly one of 'mesh' and 'shape'").into()),
        })
    }

    /// Builds the scene; a `volume` counts among the objects for the ground and the framing
    /// camera, which then looks at it from the patient's front as `render VOLUME` does.
    fn compile(
        desc: &SceneDesc,
        origin: &Path,
        volume: Option<SceneVolume>,
        mut load: impl FnMut(usize, &ObjectDesc) -> Result<(TriMesh, MeshShading), SceneError>,
    ) -> Result<Scene, SceneError> {
        let invalid = |problem: String| SceneError::Invalid {
            path: origin.to_path_buf(),
            problem,
        };
        let mut names: HashMap<&str, u32> = HashMap::new();
        let mut materials = Vec::new();
        let mut sorted: Vec<_> = desc.materials.iter().collect();
        sorted.sort_by_key(|(k, _)| k.as_str());
        for (name, m) in sorted {
            names.insert(name, materials.len() as u32);
            materials.push(
                m.to_material()
                    .map_err(|e| invalid(format!("material '{name}': {e}")))?,
            );
        }
        let default_material = materials.len() as u32;
        materials.push(Material::default());
        let lookup = |name: &Option<String>| -> Result<u32, SceneError> {
            match name {
                None => Ok(default_material),
                Some(n) => names
                    .get(n.as_str())
                    .copied()
                    .ok_or_else(|| invalid(format!("unknown material '{n}'"))),
            }
        };
        if desc.objects.is_empty() {
            return Err(invalid("the scene has no objects".into()));
        }
        let mut mesh = TriMesh::default();
        let mut normals = Vec::new();
        let mut material_of = Vec::new();
        let mut ray_offsets = Vec::new();
        let mut warnings = Vec::new();
        let mut textures = Vec::new();
        let mut uvs = Vec::new();
        let mut colours = Vec::new();
        // The material of a coloured mesh the scene and its file give none: white, so that the
        // colours are its own, with the default material's ambient share and highlights.
        let mut colour_material = None;
        for (i, o) in desc.objects.iter().enumerate() {
            let (source, mut shading) = load(i, o).map_err(|e| match e {
                SceneError::Invalid { problem, .. } => invalid(problem),
                e => e,
            })?;
            let m = o
                .matrix()
                .map_err(|e| invalid(format!("object {i}: {e}")))?;
            let t = o.translate.map(Vec3::from).unwrap_or(Vec3::ZERO);
            let (frame, overruled) = o
                .frame_of_file(shading.space)
                .map_err(|e| invalid(format!("object {i}: {e}")))?;
            shading.warnings.extend(overruled);
            let normal_m = m.inverse().transpose();
            // The file's normals where it gives them, else averaged over the faces.
            let own = if shading.normals.len() == source.positions.len() {
                std::mem::take(&mut shading.normals)
            } else {
                source.vertex_normals()
            };
            normals.extend(
                own.iter()
                    .map(|&n| frame.to_scene(normal_m * n).normalize_or_zero()),
            );
            let first_new = mesh.positions.len();
            mesh.append(&source, |p| frame.to_scene(m * p + t));
            if let Some(p) = mesh.positions[first_new..]
                .iter()
                .find(|&&p| !in_coordinate_range(p))
            {
                return Err(invalid(format!(
                    "object {i}: a vertex lands at {p} after scale, rotate and translate, beyond ±{MAX_COORDINATE:e} (f32 triangle tests overflow that far out)"
                )));
            }
            let own_colours = shading.colours.len() == source.len() && !source.is_empty();
            let chosen = if o.material.is_none() && own_colours {
                *colour_material.get_or_insert_with(|| {
                    let d = Material::default();
                    materials.push(Material {
                        ambient: d.ambient / d.diffuse,
                        diffuse: Vec3::ONE,
                        ..d
                    });
                    materials.len() as u32 - 1
                })
            } else {
                lookup(&o.material)?
            };
            if o.material.is_none() && !shading.material_of.is_empty() {
                // The file's own materials (an OBJ's MTL), where the scene names none.
                let first = materials.len() as u32;
                for m in &mut shading.materials {
                    let mut material = mtl_material(m)
                        .map_err(|e| invalid(format!("object {i}: material '{}': {e}", m.name)))?;
                    if let Some(image) = m.image.take() {
                        material.texture = Some(textures.len() as u32);
                        textures.push(image);
                    }
                    materials.push(material);
                }
                material_of.extend(
                    shading
                        .material_of
                        .iter()
                        .map(|m| m.map_or(chosen, |m| first + m)),
                );
            } else {
                material_of.extend(std::iter::repeat_n(chosen, source.len()));
            }
            if shading.uvs.len() == source.len() {
                uvs.append(&mut shading.uvs);
            } else {
                uvs.resize(material_of.len(), [Vec2::ZERO; 3]);
            }
            // White under the objects without colours, from the first with them on.
            if own_colours {
                colours.resize(material_of.len() - source.len(), [[255; 3]; 3]);
                colours.append(&mut shading.colours);
            } else if !colours.is_empty() {
                colours.resize(material_of.len(), [[255; 3]; 3]);
            }
            // A scene file's objects are named by their mesh; a mesh rendered alone is the
            // message's subject already.
            warnings.extend(shading.warnings.into_iter().map(|w| match &o.mesh {
                Some(p) => format!("object {i} ({p}): {w}"),
                None => w,
            }));
            let own = Aabb::from_points(&mesh.positions[first_new..]);
            let offset = ray_offset(own.radius(), farthest(own));
            ray_offsets.resize(mesh.positions.len(), offset);
        }
        let mut object_box = mesh.bounds();
        for c in volume.iter().flat_map(|v| v.corners()) {
            object_box = object_box.grow(c);
        }
        let (object_triangles, object_vertices) = (mesh.len(), mesh.positions.len());
        if let Some(g) = &desc.ground {
            if g.size.is_some_and(|s| !(s > 0.0 && s <= 1e4)) {
                return Err(invalid(format!(
                    "ground: size {} (in scene radii) must be in (0, 10000]",
                    g.size.unwrap_or_default()
                )));
            }
            if let Some(h) = g.height {
                check_point("ground height", Vec3::new(0.0, h, 0.0)).map_err(invalid)?;
            }
            let r = object_box.radius();
            let y = g.height.unwrap_or(object_box.min.y - 1e-3 * r);
            let c = object_box.center();
            let size = g.size.unwrap_or(40.0) * r;
            let first = lookup(&g.material)?;
            let (tiles, second) = match &g.checker {
                Some(name) => (
                    g.tiles.unwrap_or(40).clamp(1, 1000),
                    lookup(&Some(name.clone()))?,
                ),
                None => (1, first),
            };
            let tile = size / tiles as f32;
            let quad = TriMesh::ground_quad(tile);
            for i in 0..tiles {
                for j in 0..tiles {
                    let offset = Vec3::new(
                        c.x - 0.5 * size + (i as f32 + 0.5) * tile,
                        y,
                        c.z - 0.5 * size + (j as f32 + 0.5) * tile,
                    );
                    normals.extend(std::iter::repeat_n(Vec3::Y, quad.positions.len()));
                    mesh.append(&quad, |p| p + offset);
                    let m = if (i + j) % 2 == 0 { first } else { second };
                    material_of.extend(std::iter::repeat_n(m, quad.len()));
                }
            }
            // The ground is sized and placed in the objects' radii: it leaves its surface by
            // the objects' offset, or by its own rounding where that is larger.
            let ground = Aabb::from_points(&mesh.positions[object_vertices..]);
            let offset = ray_offset(
                object_box.radius(),
                farthest(object_box).max(farthest(ground)),
            );
            ray_offsets.resize(mesh.positions.len(), offset);
        }
        let mut lights = Vec::new();
        for (i, l) in desc.lights.iter().enumerate() {
            lights.push(Light {
                position: check_point(&format!("light {i}: position"), Vec3::from(l.position))
                    .map_err(invalid)?,
                color: check_colour(
                    &format!("light {i}: color"),
                    l.color.map(Vec3::from).unwrap_or(Vec3::ONE),
                )
                .map_err(invalid)?,
            });
        }
        let camera = match &desc.camera {
            Some(c) => Some(camera_of(c).map_err(|e| invalid(format!("camera: {e}")))?),
            None => None,
        };
        let background = check_colour(
            "background",
            desc.background
                .map(Vec3::from)
                .unwrap_or(Vec3::new(0.05, 0.06, 0.08)),
        )
        .map_err(invalid)?;
        let ambient_light = check_colour(
            "ambient",
            desc.ambient.map(Vec3::from).unwrap_or(Vec3::splat(0.6)),
        )
        .map_err(invalid)?;
        let ground_triangles = mesh.len() - object_triangles;
        let ground_vertices = mesh.positions.len() - object_vertices;
        if textures.is_empty() {
            uvs.clear();
        } else {
            uvs.resize(mesh.len(), [Vec2::ZERO; 3]);
        }
        if !colours.is_empty() {
            colours.resize(mesh.len(), [[255; 3]; 3]);
        }
        Ok(Scene {
            warnings,
            mesh,
            normals,
            ray_offsets,
            material_of,
            materials,
            textures,
            uvs,
            colours,
            lights,
            camera,
            background,
            ambient_light,
            object_box,
            ground_triangles,
            ground_vertices,
            frame_projection: Projection::Perspective,
            frame_view: if volume.is_some() {
                VOLUME_VIEW
            } else {
                FRAME_VIEW
            },
            volume,
        })
    }

    /// Reads a TOML scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let invalid = |problem: String| SceneError::Invalid {
            path: path.to_path_buf(),
            problem,
        };
        let text = std::fs::read_to_string(path).map_err(|e| invalid(e.to_string()))?;
        let desc: SceneDesc =
            toml::from_str(&text).map_err(|e| invalid(format!("not a valid scene: {e}")))?;
        Self::from_desc(&desc, path.parent().unwrap_or(Path::new(".")), path)
    }

    /// A mesh file alone, as [`Scene::for_mesh`] stages it, in its own materials where it has
    /// them (an OBJ's MTL), the default one elsewhere.
    pub fn for_mesh_file(path: &Path) -> Result<Scene, SceneError> {
        let (mesh, shading) = raystream_io::load_mesh_with_shading(path)?;
        Self::staged(mesh, shading, path)
    }

    /// [`Self::for_mesh_file`] of a mesh loaded already, with its `shading` (its colours,
    /// normals, materials and space) as the caller has it.
    pub fn for_mesh_shaded(
        mesh: TriMesh,
        shading: MeshShading,
        name: &Path,
    ) -> Result<Scene, SceneError> {
        Self::staged(mesh, shading, name)
    }

    /// A mesh alone: a key and a fill light, a slightly reflective ground plane under it, the
    /// camera framing it.
    pub fn for_mesh(mesh: TriMesh, name: &Path) -> Result<Scene, SceneError> {
        Self::staged(mesh, MeshShading::default(), name)
    }

    fn staged(
        mut mesh: TriMesh,
        mut shading: MeshShading,
        name: &Path,
    ) -> Result<Scene, SceneError> {
        // A mesh in a patient space (3D Slicer's `SPACE=` tag, `iso`'s output) stands as
        // anatomy does: the patient upright, seen from the front, as `render CT` shows bones.
        let patient = shading.space.take();
        if let Some(space) = patient {
            let frame = Frame::from(space);
            for p in mesh.positions.iter_mut().chain(&mut shading.normals) {
                *p = frame.to_scene(*p);
            }
        }
        let b = mesh.bounds();
        let (c, r) = (b.center(), b.radius());
        let mut desc = SceneDesc::default();
        desc.materials.insert(
            "floor".into(),
            MaterialDesc {
                diffuse: Some([0.55, 0.55, 0.58]),
                reflectivity: Some(0.15),
                specular: Some([0.1, 0.1, 0.1]),
                ..Default::default()
            },
        );
        desc.ground = Some(GroundDesc {
            material: Some("floor".into()),
            ..Default::default()
        });
        desc.lights = vec![
            LightDesc {
                position: (c + r * Vec3::new(2.0, 3.0, 2.5)).into(),
                color: Some([0.85, 0.85, 0.8]),
            },
            LightDesc {
                position: (c + r * Vec3::new(-3.0, 1.5, 1.0)).into(),
                color: Some([0.3, 0.32, 0.38]),
            },
        ];
        desc.objects.push(ObjectDesc::default());
        let mut object = Some((mesh, shading));
        let mut scene = Self::compile(&desc, name, None, |_, _| {
            Ok(object.take().expect("one object"))
        })
        .map_err(around_the_mesh)?;
        if patient.is_some() {
            scene.frame_view = VOLUME_VIEW;
        }
        Ok(scene)
    }

    /// A bone isosurface from CT: `mesh` and its `normals` in LPS millimetres are turned so that
    /// the patient stands upright facing the camera (scene x = patient's left, y = superior,
    /// z = anterior: the anterior view, patient's right on the image's left), in an ivory bone
    /// material on a dark, slightly reflective floor, with a key light above-front and a fill.
    pub fn for_bones(mesh: TriMesh, normals: &[Vec3], name: &Path) -> Scene {
        let bone = Surface {
            mesh,
            normals: normals.to_vec(),
            colour: BONE,
        };
        Self::for_surfaces(vec![bone], name)
    }

    /// Surfaces in LPS millimetres (a CT's bones, a segmentation's segments), each an object in
    /// a material of its colour (the first, alone, named `bone`), staged as
    /// [`Scene::for_bones`] stages the bones: the anterior view, a dark, slightly reflective
    /// floor, a key light and a fill. Each surface's own normals shade it where it has one a
    /// vertex.
    pub fn for_surfaces(mut surfaces: Vec<Surface>, name: &Path) -> Scene {
        let lps_to_scene = |p: Vec3| Frame::Lps.to_scene(p);
        let mut b = Aabb::EMPTY;
        for s in &mut surfaces {
            for p in &mut s.mesh.positions {
                *p = lps_to_scene(*p);
            }
            b = b.union(s.mesh.bounds());
        }
        let (c, r) = (b.center(), b.radius());
        let mut desc = SceneDesc::default();
        for (k, s) in surfaces.iter().enumerate() {
            let name = if k == 0 {
                "bone".to_string()
            } else {
                format!("surface {k}")
            };
            desc.materials.insert(
                name.clone(),
                MaterialDesc {
                    diffuse: Some(s.colour),
                    specular: Some([0.25, 0.25, 0.22]),
                    shininess: Some(24.0),
                    reflectivity: Some(0.04),
                    ..Default::default()
                },
            );
            desc.objects.push(ObjectDesc {
                material: Some(name),
                ..Default::default()
            });
        }
        desc.materials.insert(
            "floor".into(),
            MaterialDesc {
                diffuse: Some([0.22, 0.24, 0.28]),
                reflectivity: Some(0.25),
                specular: Some([0.1, 0.1, 0.1]),
                ..Default::default()
            },
        );
        desc.ground = Some(GroundDesc {
            material: Some("floor".into()),
            ..Default::default()
        });
        desc.lights = vec![
            LightDesc {
                position: (c + r * Vec3::new(1.2, 2.5, 3.0)).into(),
                color: Some([0.85, 0.83, 0.8]),
            },
            LightDesc {
                position: (c + r * Vec3::new(-2.5, 0.5, 2.0)).into(),
                color: Some([0.25, 0.27, 0.32]),
            },
        ];
        desc.ambient = Some([0.35, 0.35, 0.38]);
        desc.background = Some([0.02, 0.025, 0.035]);
        let normals: Vec<(usize, Vec<Vec3>)> = surfaces
            .iter_mut()
            .map(|s| (s.mesh.positions.len(), std::mem::take(&mut s.normals)))
            .collect();
        let mut meshes: Vec<Option<TriMesh>> = surfaces.into_iter().map(|s| Some(s.mesh)).collect();
        // A CT grid lies within ±1e6 mm, so its surfaces' lights and floor are far inside ±1e10.
        let mut scene = Self::compile(&desc, name, None, |i, _| {
            let mesh = meshes[i].take().expect("each object once");
            Ok((mesh, MeshShading::default()))
        })
        .expect("surfaces of a checked CT make a valid scene");
        // The volume's gradient normals shade an isosurface better than face-averaged ones;
        // the objects' vertices come first, in order.
        let mut at = 0;
        for (count, n) in &normals {
            if n.len() == *count {
                for (dst, &src) in scene.normals[at..at + count].iter_mut().zip(n) {
                    *dst = lps_to_scene(src);
                }
            }
            at += count;
        }
        scene.frame_view = VOLUME_VIEW;
        scene
    }

    /// The built-in default scene: Spot the cow between a glass sphere and a mirror sphere on a
    /// reflective floor, with shadows from two lights.
    pub fn builtin_default() -> Scene {
        let desc: SceneDesc = toml::from_str(DEFAULT_SCENE).expect("built-in scene parses");
        Scene::from_desc(&desc, Path::new("."), Path::new("<built-in default scene>"))
            .expect("built-in scene is valid")
    }

    /// Leaves the ground plane out (a view from below, where it would hide the objects).
    pub fn leave_out_ground(&mut self) {
        let (t, v) = (self.mesh.len(), self.mesh.positions.len());
        self.mesh.triangles.truncate(t - self.ground_triangles);
        self.material_of.truncate(t - self.ground_triangles);
        if !self.uvs.is_empty() {
            self.uvs.truncate(t - self.ground_triangles);
        }
        if !self.colours.is_empty() {
            self.colours.truncate(t - self.ground_triangles);
        }
        for n in [&mut self.mesh.positions, &mut self.normals] {
            n.truncate(v - self.ground_vertices);
        }
        self.ray_offsets.truncate(v - self.ground_vertices);
        (self.ground_triangles, self.ground_vertices) = (0, 0);
    }

    /// The camera to render with: the scene's, or one framing the objects (see [`Camera::frame`]).
    pub fn camera_for(&self, aspect: f32) -> Camera {
        self.camera
            .unwrap_or_else(|| self.framing_camera(self.frame_view, aspect))
    }

    /// The framing camera from `view` (the scene's projection), whatever camera the scene
    /// sets: a turntable's frames, one view each.
    pub fn framing_camera(&self, view: View, aspect: f32) -> Camera {
        Camera::framing(
            &self.mesh_points_for_framing(),
            aspect,
            view,
            self.frame_projection,
        )
    }

    fn mesh_points_for_framing(&self) -> Vec<Vec3> {
        let b = self.object_box;
        let mut used = vec![false; self.mesh.positions.len()];
        for t in &self.mesh.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        self.mesh
            .positions
            .iter()
            .zip(used)
            .filter(|&(p, u)| u && b.contains(*p))
            .map(|(p, _)| *p)
            .chain(self.volume.iter().flat_map(|v| v.corners()))
            .collect()
    }
}

/// Where a camera framing CT looks from: the patient's front, a little from above
/// (atan 0.12 ≈ 6.8°), head up, in the scene frame x = the patient's left, y = superior,
/// z = anterior.
pub const VOLUME_VIEW: View = View::from(Vec3::new(0.0, 0.12, 1.0));

/// The standard views of a patient, each from one side, straight on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatientView {
    /// From the front, head up: the patient's right on the image's left.
    Anterior,
    /// From the back, head up: the patient's right on the image's right.
    Posterior,
    /// From the patient's left side, head up: anterior on the image's left.
    Left,
    /// From the patient's right side, head up: anterior on the image's right.
    Right,
    /// From above the head, anterior up: the patient's right on the image's right.
    Superior,
    /// From below the feet, anterior up: the patient's right on the image's left (as axial
    /// slices are shown).
    Inferior,
}

impl PatientView {
    pub fn view(self) -> View {
        let from = |back: Vec3, up: Vec3| View { back, up };
        match self {
            PatientView::Anterior => from(Vec3::Z, Vec3::Y),
            PatientView::Posterior => from(Vec3::NEG_Z, Vec3::Y),
            PatientView::Left => from(Vec3::X, Vec3::Y),
            PatientView::Right => from(Vec3::NEG_X, Vec3::Y),
            PatientView::Superior => from(Vec3::Y, Vec3::Z),
            PatientView::Inferior => from(Vec3::NEG_Y, Vec3::Z),
        }
    }
}

/// How far secondary rays start off the surface of an object of `radius` whose largest
/// coordinate is `far`: 1e-4 of its radius, and at least 32 units in the last place of `far`.
/// The second term matters only for objects more than 26 radii from the origin (a CT with a
/// far-off origin): there a hit point is only good to its f32 rounding, and an offset below it
/// lets a shadow ray hit its own surface, differently on the CPU and the GPU.
///
/// Each object has its own offset, so that a small object beside a huge one is shaded as if
/// alone: one offset for the whole scene would start the small one's shadow and reflection
/// rays far off its surface.
pub fn ray_offset(radius: f32, far: f32) -> f32 {
    (1e-4 * radius)
        .max(far * (32.0 * f32::EPSILON))
        .max(f32::MIN_POSITIVE)
}

/// The largest coordinate of `b`, in magnitude.
fn farthest(b: Aabb) -> f32 {
    b.min.abs().max(b.max.abs()).max_element()
}

const SPHERE_SUBDIVISIONS: u32 = 4;
const CYLINDER_SEGMENTS: u32 = 64;

fn builtin_shape(name: &str) -> Option<TriMesh> {
    match name {
        "sphere" => Some(TriMesh::icosphere(SPHERE_SUBDIVISIONS)),
        "cylinder" => Some(TriMesh::cylinder(CYLINDER_SEGMENTS)),
        "spot" => Some(spot_mesh()),
        "quad" => Some(TriMesh::ground_quad(1.0)),
        _ => None,
    }
}

/// The default scene, in the same TOML a user writes.
pub const DEFAULT_SCENE: &str = include_str!("default_scene.toml");

impl From<String> for SceneError {
    /// A problem whose file the caller fills in.
    fn from(problem: String) -> Self {
        SceneError::Invalid {
            path: PathBuf::new(),
            problem,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch folder of its own under the system's temporary one, removed when the test
    /// ends, passed or failed.
    fn scratch(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("raystream-scene-{name}-"))
            .tempdir()
            .unwrap()
    }

    /// MTL statements → Phong materials: the highlight only where the model has one, the
    /// mirror only for the mirror models, `d` and `Ni` as glass, and bad values refused as a
    /// scene file's are.
    #[test]
    fn mtl_materials_become_phong_materials() {
        let m = |f: &dyn Fn(&mut MtlMaterial)| {
            let mut m = MtlMaterial {
                name: "m".into(),
                diffuse: Some([0.7, 0.35, 0.0]),
                specular: Some([0.9, 0.6, 0.3]),
                shininess: Some(80.0),
                ..Default::default()
            };
            f(&mut m);
            mtl_material(&m)
        };
        let plain = m(&|_| {}).unwrap();
        assert_eq!(plain.diffuse, Vec3::new(0.7, 0.35, 0.0));
        assert!((plain.ambient - Vec3::new(0.08, 0.04, 0.0)).length() < 1e-6);
        assert_eq!(
            (plain.specular, plain.shininess),
            (Vec3::new(0.9, 0.6, 0.3), 80.0)
        );
        assert_eq!((plain.reflectivity, plain.transparency), (0.0, 0.0));
        let matte = m(&|m| m.illum = Some(1)).unwrap();
        assert_eq!(matte.specular, Vec3::ZERO);
        let mirror = m(&|m| m.illum = Some(3)).unwrap();
        assert!((mirror.reflectivity - 0.6).abs() < 1e-6);
        let glass = m(&|m| {
            m.illum = Some(7);
            m.dissolve = Some(0.1);
            m.ior = Some(1.5);
        })
        .unwrap();
        assert!((glass.transparency - 0.9).abs() < 1e-6 && glass.ior == 1.5 && glass.fresnel);
        // Glass reflects by Fresnel's split alone; a mirror that is also transparent gives
        // way to the transparency (0.6 + 0.9 > 1).
        assert_eq!(glass.reflectivity, 0.0);
        let odd = m(&|m| {
            m.illum = Some(3);
            m.dissolve = Some(0.1);
        })
        .unwrap();
        assert!((odd.reflectivity - 0.1).abs() < 1e-6, "{odd:?}");
        // Dissolve alone is see-through without bending.
        let veil = m(&|m| m.dissolve = Some(0.5)).unwrap();
        assert!(veil.transparency == 0.5 && veil.ior == 1.0 && !veil.fresnel);
        let bad: [&dyn Fn(&mut MtlMaterial); 4] = [
            &|m| m.diffuse = Some([f32::NAN, 0.0, 0.0]),
            &|m| m.specular = Some([-1.0, 0.0, 0.0]),
            &|m| m.dissolve = Some(1.5),
            &|m| m.shininess = Some(f32::INFINITY),
        ];
        for bad in bad {
            assert!(m(bad).is_err());
        }
    }

    /// A scene's mesh object keeps its OBJ's materials unless the scene names one; a bad MTL
    /// value is an error naming the object and the material.
    #[test]
    fn scene_objects_keep_their_obj_materials() {
        let scratch = scratch("mtl");
        let dir = scratch.path();
        std::fs::write(
            dir.join("two.obj"),
            "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 2 0 0\nusemtl red\nf 1 2 3\nusemtl blue\nf 2 4 3\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("two.mtl"),
            "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n",
        )
        .unwrap();
        let scene = |text: &str| {
            let desc: SceneDesc = toml::from_str(text).unwrap();
            Scene::from_desc(&desc, dir, Path::new("s.toml"))
        };
        let own =
            scene("[[objects]]\nmesh = \"two.obj\"\n[[objects]]\nshape = \"quad\"\n").unwrap();
        let colour = |s: &Scene, t: usize| s.materials[s.material_of[t] as usize].diffuse;
        assert_eq!(colour(&own, 0), Vec3::X);
        assert_eq!(colour(&own, 1), Vec3::Z);
        assert_eq!(colour(&own, 2), Material::default().diffuse, "the quad");
        assert!(own.warnings.is_empty());
        let named = scene(
            "[materials.grey]\ndiffuse = [0.5, 0.5, 0.5]\n[[objects]]\nmesh = \"two.obj\"\nmaterial = \"grey\"\n",
        )
        .unwrap();
        assert_eq!(
            (colour(&named, 0), colour(&named, 1)),
            (Vec3::splat(0.5), Vec3::splat(0.5))
        );
        std::fs::write(
            dir.join("two.mtl"),
            "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 -1\n",
        )
        .unwrap();
        let e = scene("[[objects]]\nmesh = \"two.obj\"\n")
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.starts_with("s.toml: object 0: material 'blue': colours must be finite"),
            "{e}"
        );
        std::fs::remove_file(dir.join("two.mtl")).unwrap();
        let missing = scene("[[objects]]\nmesh = \"two.obj\"\n").unwrap();
        assert!(
            missing.warnings[0].starts_with("object 0 (two.obj): material library")
                && missing.warnings[0].contains("two.mtl"),
            "{:?}",
            missing.warnings
        );
    }

    /// A colour STL's uncoloured triangles are given the default material's diffuse colour, so
    /// that they look as a mesh without colours does (under the white a coloured mesh gets).
    #[test]
    fn uncoloured_stl_triangles_are_the_default_grey() {
        let d = Material::default().diffuse;
        assert_eq!(d, Vec3::splat(d.x));
        assert_eq!(
            raystream_io::UNCOLOURED_GREY,
            [raystream_io::linear_to_srgb8(d.x as f64); 3]
        );
    }

    /// A file's vertex colours: its triangles carry them, the objects before and after it (and
    /// the ground) white; without a scene material it is white under them (with the default
    /// material's highlight and ambient share), with one that material; a scene with no
    /// coloured object keeps no colours.
    #[test]
    fn vertex_colours_reach_their_triangles() {
        let scratch = scratch("colours");
        let dir = scratch.path();
        std::fs::write(
            dir.join("c.obj"),
            "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 2 0 0 1 1 1\nf 1 2 3\nf 2 4 3\n",
        )
        .unwrap();
        let scene = |text: &str| {
            let desc: SceneDesc = toml::from_str(text).unwrap();
            Scene::from_desc(&desc, dir, Path::new("s.toml")).unwrap()
        };
        let s = scene(
            "[[objects]]\nshape = \"quad\"\n[[objects]]\nmesh = \"c.obj\"\n\
             [[objects]]\nshape = \"quad\"\n[ground]\n",
        );
        let white = [[255u8; 3]; 3];
        assert_eq!(s.colours.len(), s.mesh.len());
        assert_eq!(&s.colours[..2], &[white; 2], "the quad before");
        assert_eq!(
            &s.colours[2..4],
            &[
                [[255, 0, 0], [0, 255, 0], [0, 0, 255]],
                [[0, 255, 0], [255, 255, 255], [0, 0, 255]]
            ]
        );
        assert!(s.colours[4..].iter().all(|c| *c == white), "quad, ground");
        let m = s.materials[s.material_of[2] as usize];
        let d = Material::default();
        assert_eq!((m.diffuse, m.specular), (Vec3::ONE, d.specular));
        assert!((m.ambient - d.ambient / d.diffuse).length() < 1e-6);
        assert_eq!(s.materials[s.material_of[0] as usize], d, "the quad's");
        let named = scene(
            "[materials.grey]\ndiffuse = [0.5, 0.5, 0.5]\n[[objects]]\nmesh = \"c.obj\"\nmaterial = \"grey\"\n",
        );
        assert_eq!(
            named.materials[named.material_of[0] as usize].diffuse,
            Vec3::splat(0.5)
        );
        assert_eq!(named.colours.len(), 2);
        assert!(scene("[[objects]]\nshape = \"quad\"\n").colours.is_empty());
    }

    /// A model that says which patient space it is in (3D Slicer's `SPACE=` tag) is read in
    /// it: the same tetrahedron written in RAS and tagged so, and in LPS and tagged so (an STL,
    /// a PLY, an OBJ), lands on the same points of the scene, where `frame = "lps"` puts the
    /// LPS numbers; the tag overrules a scene's other patient frame, with a word saying so;
    /// `frame = "scene"` keeps the numbers as they are. Alone, a tagged model is staged as
    /// anatomy: in the scene frame (x = L, y = S, z = A), seen from the front.
    #[test]
    fn a_model_is_read_in_the_patient_space_its_file_declares() {
        let scratch = scratch("space");
        let dir = scratch.path();
        let lps = [
            Vec3::new(10.0, -20.0, 30.0),
            Vec3::new(14.0, -20.0, 30.0),
            Vec3::new(10.0, -15.0, 30.0),
            Vec3::new(10.0, -20.0, 37.0),
        ];
        let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let ras = lps.map(|p| Vec3::new(-p.x, -p.y, p.z));
        let stl = |points: &[Vec3; 4], header: &str| {
            let mut text = format!("solid {header}\n");
            for f in faces {
                text += "facet normal 0 0 0\nouter loop\n";
                for v in f {
                    let p = points[v];
                    text += &format!("vertex {} {} {}\n", p.x, p.y, p.z);
                }
                text += "endloop\nendfacet\n";
            }
            text + &format!("endsolid {header}\n")
        };
        let obj = |points: &[Vec3; 4], comment: &str| {
            let mut text = format!("# {comment}\n");
            for p in points {
                text += &format!("v {} {} {}\n", p.x, p.y, p.z);
            }
            for [a, b, c] in faces {
                text += &format!("f {} {} {}\n", a + 1, b + 1, c + 1);
            }
            text
        };
        let ply = |points: &[Vec3; 4], comment: &str| {
            let mut text = format!(
                "ply\nformat ascii 1.0\ncomment {comment}\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
            );
            for p in points {
                text += &format!("{} {} {}\n", p.x, p.y, p.z);
            }
            for [a, b, c] in faces {
                text += &format!("3 {a} {b} {c}\n");
            }
            text
        };
        let files = [
            ("lps.stl", stl(&lps, "3D Slicer output. SPACE=LPS")),
            ("ras.stl", stl(&ras, "3D Slicer output. SPACE=RAS")),
            ("ras.obj", obj(&ras, "3D Slicer output. SPACE=RAS")),
            ("ras.ply", ply(&ras, "SPACE=RAS")),
            ("plain.stl", stl(&ras, "no space named")),
        ];
        for (name, text) in &files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        let scene = |object: &str| {
            let desc: SceneDesc = toml::from_str(&format!("[[objects]]\n{object}")).unwrap();
            Scene::from_desc(&desc, dir, Path::new("s.toml")).unwrap()
        };
        let sorted = |mut v: Vec<Vec3>| {
            v.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
            v
        };
        let sorted_want = sorted(lps.iter().map(|&p| Frame::Lps.to_scene(p)).collect());
        let placed = |s: &Scene| sorted(s.mesh.positions.clone());
        for object in [
            "mesh = \"lps.stl\"",
            "mesh = \"ras.stl\"",
            "mesh = \"ras.obj\"",
            "mesh = \"ras.ply\"",
            "mesh = \"ras.stl\"\nframe = \"ras\"",
            "mesh = \"plain.stl\"\nframe = \"ras\"",
        ] {
            let s = scene(object);
            assert_eq!(placed(&s), sorted_want, "{object}");
            assert!(s.warnings.is_empty(), "{object}: {:?}", s.warnings);
        }
        // The file's tag before the scene's frame, with a word; "scene" keeps the numbers.
        let overruled = scene("mesh = \"ras.stl\"\nframe = \"lps\"");
        assert_eq!(placed(&overruled), sorted_want);
        assert!(
            overruled.warnings[0].contains("SPACE=RAS")
                && overruled.warnings[0].contains("frame = \"lps\""),
            "{:?}",
            overruled.warnings
        );
        let raw = sorted(ras.to_vec());
        assert_eq!(placed(&scene("mesh = \"ras.stl\"\nframe = \"scene\"")), raw);
        assert_eq!(placed(&scene("mesh = \"plain.stl\"")), raw);
        // Alone: the RAS and the LPS model are staged alike, upright and seen from the front;
        // an untagged one keeps its numbers and the framing of any mesh.
        let lps_alone = Scene::for_mesh_file(&dir.join("lps.stl")).unwrap();
        let ras_alone = Scene::for_mesh_file(&dir.join("ras.obj")).unwrap();
        assert_eq!(lps_alone.frame_view, VOLUME_VIEW);
        assert_eq!(ras_alone.frame_view, VOLUME_VIEW);
        let objects = |s: &Scene| {
            sorted(s.mesh.positions[..s.mesh.positions.len() - s.ground_vertices].to_vec())
        };
        assert_eq!(objects(&lps_alone), sorted_want);
        assert_eq!(objects(&ras_alone), sorted_want);
        let plain = Scene::for_mesh_file(&dir.join("plain.stl")).unwrap();
        assert_eq!(objects(&plain), raw);
        assert_ne!(plain.frame_view, VOLUME_VIEW);
    }

    fn compile(text: &str) -> Result<Scene, SceneError> {
        let desc: SceneDesc = toml::from_str(text).map_err(|e| e.to_string())?;
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../raystream/assets");
        Scene::from_desc(&desc, &assets, Path::new("test.toml"))
    }

    const CT: &str = r#"
        [volume]
        path = "abdomen_pelvis_ct_totalseg.nii.gz"
    "#;

    /// Each object's vertices carry its own ray offset, 10⁻⁴ of its radius (or 32 ulps of its
    /// largest coordinate where that is more); the ground carries the objects' box's.
    #[test]
    fn every_vertex_carries_its_objects_ray_offset() {
        let s = compile(
            "[[objects]]\nshape = \"sphere\"\n[[objects]]\nshape = \"sphere\"\n\
             scale = 100\ntranslate = [300, 0, 0]\n[[objects]]\nshape = \"quad\"\n\
             translate = [3e6, 0, 0]\n[ground]\n",
        )
        .unwrap();
        let n = TriMesh::icosphere(SPHERE_SUBDIVISIONS).positions.len();
        assert_eq!(s.ray_offsets.len(), s.mesh.positions.len());
        let unit = Aabb::from_points(&s.mesh.positions[..n]).radius();
        assert!((unit - 3f32.sqrt()).abs() < 1e-3, "{unit}");
        let offsets = |r: std::ops::Range<usize>| {
            let mut v = s.ray_offsets[r].to_vec();
            v.dedup();
            v
        };
        assert_eq!(offsets(0..n), [1e-4 * unit]);
        assert_eq!(offsets(n..2 * n).len(), 1);
        assert!((s.ray_offsets[n] / (1e-2 * unit) - 1.0).abs() < 1e-5);
        // The quad: 3·10⁶ out, its f32 rounding (32 ulps ≈ 11) outweighs 10⁻⁴ of its size.
        let quad = 2 * n..2 * n + 4;
        assert_eq!(offsets(quad.clone()), [3_000_000.5 * 32.0 * f32::EPSILON]);
        let ground = Aabb::from_points(&s.mesh.positions[quad.end..]);
        assert_eq!(
            offsets(quad.end..s.ray_offsets.len()),
            [ray_offset(s.object_box.radius(), farthest(ground))]
        );
        assert!(farthest(ground) > farthest(s.object_box));
    }

    /// `parallel_height` makes the scene's camera a parallel projection of that height; it
    /// excludes `fov` and must be a positive size.
    #[test]
    fn a_scene_camera_may_project_in_parallel() {
        let base =
            "[[objects]]\nshape = \"sphere\"\n[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\n";
        let s = compile(&format!("{base}parallel_height = 3\n")).unwrap();
        let cam = s.camera_for(1.0);
        assert_eq!(cam.parallel, 1.5);
        let (a, b) = (cam.ray(0.5, 0.5, 10, 10), cam.ray(9.5, 9.5, 10, 10));
        assert_eq!((a.dir, b.dir), (cam.fwd, cam.fwd));
        assert!(((a.origin - b.origin).length() - 2.7 * 2f32.sqrt()).abs() < 1e-4);
        assert_eq!(compile(base).unwrap().camera_for(1.0).parallel, 0.0);
        for (extra, want) in [
            ("parallel_height = 3\nfov = 30\n", "not both"),
            ("parallel_height = -1\n", "positive"),
            ("parallel_height = inf\n", "positive"),
        ] {
            let e = compile(&format!("{base}{extra}")).unwrap_err().to_string();
            assert!(e.contains(want) && e.contains("test.toml"), "{extra}: {e}");
        }
    }

    /// The ground's triangles and vertices come last and are counted; leaving it out keeps
    /// the objects and every per-vertex and per-triangle array in step.
    #[test]
    fn the_ground_can_be_left_out() {
        let mut s = compile(
            "[[objects]]\nshape = \"sphere\"\n[ground]\nchecker = \"x\"\ntiles = 4\n\
             [materials.x]\n",
        )
        .unwrap();
        let sphere = TriMesh::icosphere(SPHERE_SUBDIVISIONS);
        assert_eq!(s.ground_triangles, s.mesh.len() - sphere.len());
        assert_eq!(
            s.ground_vertices,
            s.mesh.positions.len() - sphere.positions.len()
        );
        assert_eq!(s.ground_triangles, 4 * 4 * 2);
        let before = s.mesh.positions[..sphere.positions.len()].to_vec();
        s.leave_out_ground();
        assert_eq!(s.mesh.len(), sphere.len());
        assert_eq!(s.mesh.positions, before);
        assert_eq!(s.normals.len(), s.mesh.positions.len());
        assert_eq!(s.ray_offsets.len(), s.mesh.positions.len());
        assert_eq!(s.material_of.len(), s.mesh.len());
        assert_eq!((s.ground_triangles, s.ground_vertices), (0, 0));
        s.mesh.check(Path::new("left-out.toml")).unwrap();
    }

    /// A mesh given in LPS or RAS lands where the same patient point lies in the scene frame
    /// (x = L, y = S, z = A), and its normals turn with it.
    #[test]
    fn patient_frames_turn_into_the_scene_frame() {
        for (frame, at, want) in [
            ("scene", [1.0, 2.0, 3.0], Vec3::new(1.0, 2.0, 3.0)),
            ("lps", [10.0, -20.0, 30.0], Vec3::new(10.0, 30.0, 20.0)),
            ("ras", [-10.0, 20.0, 30.0], Vec3::new(10.0, 30.0, 20.0)),
        ] {
            let s = compile(&format!(
                "[[objects]]\nshape = \"quad\"\nframe = \"{frame}\"\ntranslate = {at:?}\nscale = 0.001"
            ))
            .unwrap();
            let c = s.mesh.bounds().center();
            assert!((c - want).length() < 1e-3, "{frame}: {c} vs {want}");
        }
        // The quad faces +y (posterior in LPS): anterior in the scene frame is +z, so −z.
        let s = compile("[[objects]]\nshape = \"quad\"\nframe = \"lps\"").unwrap();
        assert!((s.normals[0] - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        let e = compile("[[objects]]\nshape = \"quad\"\nframe = \"xyz\"").unwrap_err();
        assert!(e.to_string().contains("unknown frame 'xyz'"), "{e}");
    }

    /// A scene's volume loads with its preset; the ground goes under it and a framing camera
    /// sees all of it from the patient's front.
    #[test]
    fn a_volume_joins_the_scene() {
        let s = compile(&format!(
            "{CT}\npreset = \"ct-bones\"\n[[objects]]\nshape = \"sphere\"\nscale = 10\ntranslate = [0, 250, 160]\n[ground]\nsize = 2"
        ))
        .unwrap();
        let v = s.volume.as_ref().expect("a volume");
        assert_eq!(v.volume.dims, [122, 101, 112]);
        assert_eq!(v.tf, TfPreset::CtBones.function());
        assert!(v.shadows);
        let lowest = v.corners().iter().map(|c| c.y).fold(f32::MAX, f32::min);
        let ground = s.mesh.positions[s.mesh.positions.len() - 1].y;
        assert!(
            ground < lowest && ground > lowest - 1.0,
            "{ground} vs {lowest}"
        );
        let cam = s.camera_for(1.0);
        assert!(
            cam.fwd.z < -0.9,
            "looks at the patient's front: {}",
            cam.fwd
        );
        for c in v.corners() {
            let q = c - cam.eye;
            let z = q.dot(cam.fwd);
            assert!(
                z > 0.0 && q.dot(cam.up).abs() <= z * cam.tan_y * 1.001,
                "{c} out of view"
            );
        }
    }

    /// A scene's volume of no known unit, given no transfer function, takes the ramp of its
    /// own values (CT-Bone filled the SciVis bonsai's box); a preset named still rules, and a
    /// CT keeps CT-Bone; a lone slice joins as the slab it images.
    #[test]
    fn volumes_join_as_the_renderers_draw_them() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/volumes");
        let scene = |path: &Path, extra: &str| {
            let text = format!(
                "[volume]\npath = {:?}\n{extra}\n[[objects]]\nshape = \"sphere\"",
                path.to_str().unwrap()
            );
            compile(&text).unwrap().volume.unwrap()
        };
        let bonsai = data.join("nifti/scivis_bonsai.nii.gz");
        let v = scene(&bonsai, "");
        let (ramp, _) = raystream_volume::auto::unit_free_transfer(&v.volume).unwrap();
        assert_eq!(v.tf, ramp);
        let named = scene(&bonsai, "preset = \"ct-bone\"");
        assert_eq!(named.tf, TfPreset::CtBone.function());
        let ct = compile(&format!("{CT}\n[[objects]]\nshape = \"sphere\"")).unwrap();
        assert_eq!(ct.volume.unwrap().tf, TfPreset::CtBone.function());
        let slice = data.join(
            "dicom/ct_slice_transfer_syntaxes/ct_1.2.840.10008.1.2.1_LittleEndianExplicit.dcm",
        );
        assert_eq!(scene(&slice, "").volume.dims, [512, 512, 2]);
    }

    /// A scene's volume is read by the cubic B-spline unless it says "linear".
    #[test]
    fn volume_interpolation_defaults_to_cubic() {
        let obj = "[[objects]]\nshape = \"sphere\"";
        for (extra, want) in [
            ("", Interpolation::Cubic),
            ("interpolation = \"cubic\"", Interpolation::Cubic),
            ("interpolation = \"linear\"", Interpolation::Linear),
            (
                "interpolation = \"cubic-interpolating\"",
                Interpolation::CubicInterpolating,
            ),
        ] {
            let s = compile(&format!("{CT}{extra}\n{obj}")).unwrap();
            assert_eq!(s.volume.unwrap().interpolation, want, "{extra}");
        }
    }

    /// `segmentation`, `segment` (a string as `--segment` takes it, or an array of labels
    /// and names) and `colour_table` are kept for the renderer, paths against the scene's
    /// folder; the colours wait for it.
    #[test]
    fn a_volume_names_its_segmentation() {
        let obj = "[[objects]]\nshape = \"sphere\"";
        for (extra, segment) in [
            ("", None),
            ("segment = \"1, 2\"", Some("1, 2")),
            ("segment = [1, \"Lumen\", 3]", Some("1,Lumen,3")),
            ("segment = \"all\"\ncolour_table = \"t.ctbl\"", Some("all")),
        ] {
            let s = compile(&format!(
                "{CT}segmentation = \"seg/labels.nii.gz\"\n{extra}\n{obj}"
            ))
            .unwrap();
            let v = s.volume.unwrap();
            let g = v.segmentation.expect("a segmentation");
            let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../raystream/assets");
            assert_eq!(g.path, assets.join("seg/labels.nii.gz"));
            assert_eq!(g.segment.as_deref(), segment, "{extra}");
            assert_eq!(
                g.colour_table,
                extra.contains("ctbl").then(|| assets.join("t.ctbl"))
            );
            assert!(v.segments.is_none());
        }
    }

    /// Volume mistakes name the scene file and the problem.
    #[test]
    fn volume_mistakes_are_named() {
        let obj = "[[objects]]\nshape = \"sphere\"";
        for (extra, want) in [
            ("preset = \"ct-nothing\"", "unknown preset 'ct-nothing'"),
            (
                "preset = \"ct-bone\"\ntf = \"a.toml\"",
                "'tf' or 'preset', not both",
            ),
            ("step = -1", "step -1 must be a positive number"),
            (
                "interpolation = \"tricubic\"",
                "unknown interpolation 'tricubic' (linear, cubic, cubic-interpolating)",
            ),
            ("segment = [1]", "a 'segmentation'; give one"),
            ("colour_table = \"t.ctbl\"", "a 'segmentation'; give one"),
        ] {
            let e = compile(&format!("{CT}{extra}\n{obj}"))
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("test.toml: volume: ") && e.contains(want),
                "{e}"
            );
        }
        // A list of segments that is none.
        for extra in ["segment = 7", "segment = [1.5]"] {
            let e = compile(&format!("{CT}segmentation = \"l.nii\"\n{extra}\n{obj}"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("segments as \"1,2\", \"all\" or names"), "{e}");
        }
        let e = compile(&format!("[volume]\npath = \"missing.nii\"\n{obj}"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.nii"), "{e}");
    }
}
