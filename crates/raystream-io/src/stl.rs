//! STL through stl_io. A binary STL states its triangle count in the header; it is checked
//! against the file size first, so a lying header is an error, not a huge allocation.

use std::path::Path;

use crate::{MeshError, TriMesh, Vec3};

const HEADER: usize = 80;
const TRIANGLE: usize = 50;

pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<TriMesh, MeshError> {
    let ascii = bytes.trim_ascii_start().starts_with(b"solid") && !looks_binary(bytes);
    if !ascii {
        if bytes.len() < HEADER + 4 {
            return Err(MeshError::invalid(
                path,
                format!(
                    "binary STL is truncated: {} bytes, shorter than its 84-byte header",
                    bytes.len()
                ),
            ));
        }
        let count = u32::from_le_bytes(bytes[HEADER..HEADER + 4].try_into().unwrap()) as usize;
        let need = HEADER + 4 + count * TRIANGLE;
        if bytes.len() < need {
            return Err(MeshError::invalid(
                path,
                format!(
                    "binary STL is truncated: header claims {count} triangles ({need} bytes), file has {} bytes",
                    bytes.len()
                ),
            ));
        }
    }
    let indexed = stl_io::read_stl(&mut std::io::Cursor::new(bytes))
        .map_err(|e| MeshError::invalid(path, format!("cannot read STL: {e}")))?;
    Ok(TriMesh {
        positions: indexed
            .vertices
            .iter()
            .map(|v| Vec3::new(v[0], v[1], v[2]))
            .collect(),
        triangles: indexed
            .faces
            .iter()
            .map(|f| f.vertices.map(|i| i as u32))
            .collect(),
    })
}

/// Many binary STL files start their 80-byte header with "solid" too; the size formula tells.
fn looks_binary(bytes: &[u8]) -> bool {
    bytes.len() >= HEADER + 4 && {
        let count = u32::from_le_bytes(bytes[HEADER..HEADER + 4].try_into().unwrap()) as usize;
        bytes.len() == HEADER + 4 + count * TRIANGLE
    }
}
