//! PLY through ply-rs-bw, into typed rows (not its map-per-row default element), accepting any
//! scalar type for x/y/z and any integer list type for the face indices. Colours (`red green
//! blue`, or the older `diffuse_red …`) are read from the vertices or the faces: 8-bit where
//! the file stores bytes, 0 to 1 where it stores floats (as MeshLab and VTK write them).

use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};

use crate::{MeshError, Rgb8, TriMesh, Vec3, unit_to_8bit};

/// A vertex row: x, y, z, then nx, ny, nz where the file has them; its colour.
#[derive(Default)]
struct Vertex([f64; 6], Rgb8);

/// A face row: its vertex indices, its colour.
#[derive(Default)]
struct Face(Vec<i64>, Rgb8);

/// The colour channel a property names (0–2), if it names one.
fn channel(name: &str) -> Option<usize> {
    match name.strip_prefix("diffuse_").unwrap_or(name) {
        "red" => Some(0),
        "green" => Some(1),
        "blue" => Some(2),
        _ => None,
    }
}

/// Whether an element's properties give a colour (all three channels).
fn coloured(def: &ply_rs_bw::ply::ElementDef) -> bool {
    let mut seen = [false; 3];
    for name in def.properties.keys() {
        if let Some(c) = channel(name) {
            seen[c] = true;
        }
    }
    seen == [true; 3]
}

/// A colour channel as 8 bits: bytes as they are, 16-bit integers scaled (65535 is 255),
/// other integers clamped, floats from 0–1.
fn channel_8bit(p: &Property) -> Option<u8> {
    Some(match *p {
        Property::UChar(v) => v,
        Property::Char(v) => v.max(0) as u8,
        Property::UShort(v) => (v as f64 / 257.0).round() as u8,
        Property::Short(v) => (v.max(0) as f64 / 128.5).round() as u8,
        Property::Int(v) => v.clamp(0, 255) as u8,
        Property::UInt(v) => v.min(255) as u8,
        Property::Float(v) => unit_to_8bit(v as f64),
        Property::Double(v) => unit_to_8bit(v),
        _ => return None,
    })
}

/// Sets `colour`'s channel from property `p`, as ply-rs-bw's accessor answers.
fn set_channel(colour: &mut Rgb8, c: usize, p: &Property) -> PropertyAccessResult {
    match channel_8bit(p) {
        Some(v) => {
            colour[c] = v;
            PropertyAccessResult::Set
        }
        None => PropertyAccessResult::UnsupportedType,
    }
}

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        if let Some(c) = channel(name) {
            return set_channel(&mut self.1, c, &p);
        }
        let axis = match name {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            "nx" => 3,
            "ny" => 4,
            "nz" => 5,
            _ => return PropertyAccessResult::Ignored,
        };
        match scalar(&p) {
            Some(v) => {
                self.0[axis] = v;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::UnsupportedType,
        }
    }
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, name: &str, p: Property) -> PropertyAccessResult {
        if let Some(c) = channel(name) {
            return set_channel(&mut self.1, c, &p);
        }
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.0 = match p {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// A PLY file's surface.
pub(crate) struct Ply {
    pub mesh: TriMesh,
    /// Per vertex, where the vertex element has nx, ny and nz (else empty; not yet checked or
    /// normalised).
    pub normals: Vec<Vec3>,
    /// Per triangle, its corners' colours: the vertices' where they have one, else the
    /// faces' (as VTK's mappers colour by point data first), else empty.
    pub colours: Vec<[Rgb8; 3]>,
}

pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<Ply, MeshError> {
    let bad = |e: &dyn std::fmt::Display| MeshError::invalid(path, format!("cannot read PLY: {e}"));
    let mut reader = Reader::new(std::io::BufReader::new(bytes));
    let header = Parser::<Vertex>::new()
        .read_header(&mut reader)
        .map_err(|e| bad(&e))?;
    let mut mesh = TriMesh::default();
    let mut normals = Vec::new();
    let mut vertex_colours: Vec<Rgb8> = Vec::new();
    let mut face_colours: Vec<Rgb8> = Vec::new();
    let mut saw_vertex = false;
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                saw_vertex = true;
                let rows = Parser::<Vertex>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
                mesh.positions = rows
                    .iter()
                    .map(|v| Vec3::new(v.0[0] as f32, v.0[1] as f32, v.0[2] as f32))
                    .collect();
                let has = |p: &str| def.properties.contains_key(p);
                if has("nx") && has("ny") && has("nz") {
                    normals = rows
                        .iter()
                        .map(|v| Vec3::new(v.0[3] as f32, v.0[4] as f32, v.0[5] as f32))
                        .collect();
                }
                if coloured(def) {
                    vertex_colours = rows.iter().map(|v| v.1).collect();
                }
            }
            "face" => {
                let rows = Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
                let face_coloured = coloured(def);
                for (f, face) in rows.iter().enumerate() {
                    if let Some(&i) = face.0.iter().find(|&&i| i < 0 || i > u32::MAX as i64) {
                        return Err(MeshError::invalid(
                            path,
                            format!("face {f} has the invalid vertex index {i}"),
                        ));
                    }
                    for k in 2..face.0.len() {
                        mesh.triangles
                            .push([face.0[0], face.0[k - 1], face.0[k]].map(|i| i as u32));
                        if face_coloured {
                            face_colours.push(face.1);
                        }
                    }
                }
            }
            // Other elements (edges, materials…) must still be read to reach later ones.
            _ => {
                Parser::<Vertex>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
            }
        }
    }
    if !saw_vertex {
        return Err(MeshError::invalid(path, "PLY has no vertex element"));
    }
    // (An index beyond the vertices is the mesh check's error, after this.)
    let indexed = mesh
        .triangles
        .iter()
        .flatten()
        .all(|&v| (v as usize) < vertex_colours.len());
    let colours = if vertex_colours.len() == mesh.positions.len() && indexed {
        crate::corner_colours(&mesh.triangles, &vertex_colours)
    } else {
        face_colours.iter().map(|&c| [c; 3]).collect()
    };
    Ok(Ply {
        mesh,
        normals,
        colours,
    })
}
