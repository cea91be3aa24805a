//! PLY through ply-rs-bw, into typed rows (not its map-per-row default element), accepting any
//! scalar type for x/y/z and any integer list type for the face indices.

use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};

use crate::{MeshError, TriMesh, Vec3};

/// A vertex row: x, y, z, then nx, ny, nz where the file has them.
#[derive(Default)]
struct Vertex([f64; 6]);

#[derive(Default)]
struct Face(Vec<i64>);

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

/// The mesh, and its vertex normals where the vertex element has nx, ny and nz (else empty;
/// not yet checked or normalised).
pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<(TriMesh, Vec<Vec3>), MeshError> {
    let bad = |e: &dyn std::fmt::Display| MeshError::invalid(path, format!("cannot read PLY: {e}"));
    let mut reader = Reader::new(std::io::BufReader::new(bytes));
    let header = Parser::<Vertex>::new()
        .read_header(&mut reader)
        .map_err(|e| bad(&e))?;
    let mut mesh = TriMesh::default();
    let mut normals = Vec::new();
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
            }
            "face" => {
                let rows = Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| bad(&e))?;
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
    Ok((mesh, normals))
}
