//! The scene file's plain data (serde), as a user writes it in TOML.

use std::collections::HashMap;

use raystream_io::PatientSpace;
use raystream_math::{Mat3, Vec3};
use serde::Deserialize;

use crate::Material;

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDesc {
    pub camera: Option<CameraDesc>,
    #[serde(default)]
    pub lights: Vec<LightDesc>,
    #[serde(default)]
    pub materials: HashMap<String, MaterialDesc>,
    #[serde(default)]
    pub objects: Vec<ObjectDesc>,
    pub ground: Option<GroundDesc>,
    pub background: Option<[f32; 3]>,
    pub ambient: Option<[f32; 3]>,
    /// One CT volume rendered directly among the meshes.
    pub volume: Option<VolumeDesc>,
}

/// A CT volume in a scene: direct volume rendering through a transfer function, in the scene
/// frame of `render VOLUME` (x = patient's left, y = superior, z = anterior, mm).
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeDesc {
    /// A DICOM folder or a NIfTI, NRRD or MetaImage file, relative to the scene file.
    pub path: String,
    /// DICOM series UID (default: the largest series).
    pub series: Option<String>,
    /// The temporal position (phase) of a 4-D CT, from 1 (default: the first).
    pub phase: Option<usize>,
    /// Transfer-function preset: ct-bone (default), ct-bones, ct-aaa, ct-muscle, ct-lung,
    /// mip-bone. Without it or `tf`, values of no known unit take a ramp from their own
    /// background up ([`raystream_volume::auto::unit_free_transfer`]).
    pub preset: Option<String>,
    /// A transfer-function TOML file, relative to the scene file (instead of `preset`).
    pub tf: Option<String>,
    /// Step in mm (default: half the smallest voxel spacing).
    pub step: Option<f32>,
    /// Whether the volume is lit through shadow rays (its own and the meshes' shadows; default
    /// true). Meshes always see the volume in their shadow rays.
    pub shadows: Option<bool>,
    /// How the volume is read between voxel centres: "linear" (trilinear), "cubic" (the cubic
    /// B-spline, the default, as `render --mode dvr`'s) or "cubic-interpolating" (the cubic
    /// B-spline through every voxel's value).
    pub interpolation: Option<String>,
    /// A segmentation of the volume (a label map, DICOM Segmentation or RT Structure Set,
    /// relative to the scene file): each sample in its segment's colour, as `render CT --mode
    /// dvr --segmentation`.
    pub segmentation: Option<String>,
    /// Only these segments of `segmentation` drawn: "1,2", "all", names, or an array of
    /// labels or names (as `--segment`).
    pub segment: Option<SegmentList>,
    /// The segmentation's names and colours: a 3D Slicer colour table or an ITK-SNAP label
    /// description, relative to the scene file (as `--colour-table`).
    pub colour_table: Option<String>,
    /// The CT kept to the patient's body, the table and a head holder left out (as
    /// `--body-only`; default false).
    pub body_only: Option<bool>,
}

/// `segment = "1,2"` or `segment = [1, 2]` (numbers or names).
#[derive(Clone, Debug, Deserialize)]
#[serde(
    untagged,
    expecting = "segments as \"1,2\", \"all\" or names, or an array such as [1, \"Lumen\"]"
)]
pub enum SegmentList {
    Text(String),
    Items(Vec<SegmentItem>),
}

/// A segment named in a list: its label or its name.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged, expecting = "a segment's label (a whole number) or its name")]
pub enum SegmentItem {
    Label(u32),
    Name(String),
}

impl SegmentList {
    /// The list as `--segment` takes it: comma-separated.
    pub fn as_option(&self) -> String {
        match self {
            SegmentList::Text(s) => s.clone(),
            SegmentList::Items(items) => items
                .iter()
                .map(|i| match i {
                    SegmentItem::Label(l) => l.to_string(),
                    SegmentItem::Name(n) => n.clone(),
                })
                .collect::<Vec<_>>()
                .join(","),
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraDesc {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: Option<[f32; 3]>,
    /// Vertical field of view in degrees (perspective).
    pub fov: Option<f32>,
    /// The height of the view in scene units: a parallel (orthographic) projection through
    /// the eye's plane instead of a perspective one (give it or `fov`, not both).
    pub parallel_height: Option<f32>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightDesc {
    pub position: [f32; 3],
    pub color: Option<[f32; 3]>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialDesc {
    pub ambient: Option<[f32; 3]>,
    pub diffuse: Option<[f32; 3]>,
    pub specular: Option<[f32; 3]>,
    pub shininess: Option<f32>,
    pub reflectivity: Option<f32>,
    pub transparency: Option<f32>,
    pub ior: Option<f32>,
    pub fresnel: Option<bool>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum Scale {
    Uniform(f32),
    Axes([f32; 3]),
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectDesc {
    /// Mesh file, relative to the scene file.
    pub mesh: Option<String>,
    /// Built-in shape: "sphere" (unit radius), "quad" (unit square in y = 0 facing +y) or "spot".
    pub shape: Option<String>,
    pub material: Option<String>,
    pub translate: Option<[f32; 3]>,
    /// Rotation in degrees about x, then y, then z.
    pub rotate: Option<[f32; 3]>,
    pub scale: Option<Scale>,
    /// The frame the mesh (after its transform) is given in: "scene", or "lps" / "ras",
    /// patient millimetres as DICOM / NIfTI and 3D Slicer use them, converted to the scene
    /// frame so that the mesh sits where it belongs in the scene's CT volume. Default: the
    /// patient space the mesh file declares (3D Slicer's `SPACE=` tag), else "scene".
    pub frame: Option<String>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundDesc {
    pub material: Option<String>,
    /// Height (y) of the plane; default just under the objects.
    pub height: Option<f32>,
    /// Side length in scene radii (default 40).
    pub size: Option<f32>,
    /// A second material: the plane becomes a checkerboard of the two.
    pub checker: Option<String>,
    /// Checkerboard tiles per side (default 40).
    pub tiles: Option<u32>,
}

impl MaterialDesc {
    pub fn to_material(&self) -> Result<Material, String> {
        let d = Material::default();
        let m = Material {
            ambient: self.ambient.map(Vec3::from).unwrap_or(d.ambient),
            diffuse: self.diffuse.map(Vec3::from).unwrap_or(d.diffuse),
            specular: self.specular.map(Vec3::from).unwrap_or(d.specular),
            shininess: self.shininess.unwrap_or(d.shininess),
            reflectivity: self.reflectivity.unwrap_or(d.reflectivity),
            transparency: self.transparency.unwrap_or(d.transparency),
            ior: self.ior.unwrap_or(d.ior),
            fresnel: self.fresnel.unwrap_or(d.fresnel),
            texture: None,
        };
        let unit = |x: f32| (0.0..=1.0).contains(&x);
        if !unit(m.reflectivity) || !unit(m.transparency) || m.reflectivity + m.transparency > 1.0 {
            return Err(
                "reflectivity and transparency must lie in [0, 1] and add up to at most 1".into(),
            );
        }
        if !(m.ior >= 1.0 && m.ior.is_finite() && m.shininess >= 0.0 && m.shininess.is_finite()) {
            return Err("ior must be ≥ 1 and shininess ≥ 0".into());
        }
        if ![m.ambient, m.diffuse, m.specular]
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0)
        {
            return Err("colours must be finite and non-negative".into());
        }
        Ok(m)
    }
}

/// Patient coordinate frames a mesh may be given in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    Scene,
    Lps,
    Ras,
}

impl From<PatientSpace> for Frame {
    fn from(space: PatientSpace) -> Frame {
        match space {
            PatientSpace::Lps => Frame::Lps,
            PatientSpace::Ras => Frame::Ras,
        }
    }
}

impl Frame {
    /// The frame's point in the scene frame (x = L, y = S, z = A): a rotation.
    pub fn to_scene(self, p: Vec3) -> Vec3 {
        match self {
            Frame::Scene => p,
            Frame::Lps => Vec3::new(p.x, p.z, -p.y),
            Frame::Ras => Vec3::new(-p.x, p.z, p.y),
        }
    }
}

impl ObjectDesc {
    pub fn frame(&self) -> Result<Frame, String> {
        match self.frame.as_deref() {
            None | Some("scene") => Ok(Frame::Scene),
            Some("lps") => Ok(Frame::Lps),
            Some("ras") => Ok(Frame::Ras),
            Some(f) => Err(format!("unknown frame '{f}' (scene, lps, ras)")),
        }
    }

    /// The frame the object's mesh is read in, given the patient space its file declares
    /// (`declared`: 3D Slicer's `SPACE=` tag), and a word where the file overrules the scene.
    /// As 3D Slicer reads a model, the file's tag comes first: where the object names a
    /// patient frame or none, the declared space is taken; `frame = "scene"` keeps the file's
    /// numbers as they are.
    pub fn frame_of_file(
        &self,
        declared: Option<PatientSpace>,
    ) -> Result<(Frame, Option<String>), String> {
        let named = self.frame()?;
        let Some(space) = declared else {
            return Ok((named, None));
        };
        let file = Frame::from(space);
        Ok(match (self.frame.as_deref(), named) {
            (Some("scene"), _) => (Frame::Scene, None),
            (Some(_), named) if named != file => (
                file,
                Some(format!(
                    "its file says SPACE={} (3D Slicer's tag), so its coordinates are read as {}, not as the frame = \"{}\" the scene gives",
                    space.name(),
                    space.name(),
                    self.frame.as_deref().unwrap_or_default()
                )),
            ),
            _ => (file, None),
        })
    }

    /// The linear part of the object's transform (rotation then scale applied to the mesh).
    pub fn matrix(&self) -> Result<Mat3, String> {
        let s = match self.scale {
            None => Vec3::ONE,
            Some(Scale::Uniform(s)) => Vec3::splat(s),
            Some(Scale::Axes(a)) => Vec3::from(a),
        };
        if !s.is_finite() || s.abs().min_element() == 0.0 {
            return Err(format!("scale {s} must be finite and non-zero"));
        }
        let r = self.rotate.map(Vec3::from).unwrap_or(Vec3::ZERO);
        if !r.is_finite()
            || !self
                .translate
                .map(Vec3::from)
                .unwrap_or(Vec3::ZERO)
                .is_finite()
        {
            return Err("rotate and translate must be finite".into());
        }
        let rot = Mat3::from_rotation_z(r.z.to_radians())
            * Mat3::from_rotation_y(r.y.to_radians())
            * Mat3::from_rotation_x(r.x.to_radians());
        Ok(rot * Mat3::from_diagonal(s))
    }
}
