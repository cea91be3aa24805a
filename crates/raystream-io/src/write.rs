//! Mesh output: binary little-endian PLY (positions + normals), OBJ (`v`, `vn`, `f v//vn`),
//! binary STL (stl_io) and binary glTF (`.glb`: the JSON through serde_json, the container
//! through the gltf crate). PLY and OBJ are written here: ply-rs-bw's writer builds a map of
//! properties per element, several times slower on the millions of vertices an isosurface has,
//! and no maintained crate writes OBJ. What is written reads back through [`crate::load_mesh`].

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::{MeshError, MeshFormat, TriMesh, Vec3};

/// Writes `mesh` (with optional per-vertex `normals`) in the format named by `path`'s extension.
pub fn write_mesh(path: &Path, mesh: &TriMesh, normals: Option<&[Vec3]>) -> Result<(), MeshError> {
    let glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let format = MeshFormat::from_path(path)
        .filter(|f| (*f != MeshFormat::Gltf || glb) && !path.to_string_lossy().ends_with(".gz"))
        .ok_or_else(|| MeshError::invalid(path, "output must end in .ply, .obj, .stl or .glb"))?;
    let normals = normals.filter(|n| n.len() == mesh.positions.len());
    let file = std::fs::File::create(path).map_err(|error| MeshError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mut w = BufWriter::new(file);
    let r = match format {
        MeshFormat::Ply => write_ply(&mut w, mesh, normals),
        MeshFormat::Obj => write_obj(&mut w, mesh, normals),
        MeshFormat::Stl => write_stl(&mut w, mesh),
        MeshFormat::Gltf => write_glb(&mut w, mesh, normals),
    };
    r.and_then(|()| w.flush()).map_err(|error| MeshError::Io {
        path: path.to_path_buf(),
        error,
    })
}

fn write_ply(w: &mut impl Write, mesh: &TriMesh, normals: Option<&[Vec3]>) -> std::io::Result<()> {
    writeln!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment raystream isosurface, LPS millimetres"
    )?;
    writeln!(w, "element vertex {}", mesh.positions.len())?;
    writeln!(w, "property float x\nproperty float y\nproperty float z")?;
    if normals.is_some() {
        writeln!(w, "property float nx\nproperty float ny\nproperty float nz")?;
    }
    writeln!(w, "element face {}", mesh.triangles.len())?;
    writeln!(w, "property list uchar int vertex_indices\nend_header")?;
    for (i, p) in mesh.positions.iter().enumerate() {
        for c in p.to_array() {
            w.write_all(&c.to_le_bytes())?;
        }
        if let Some(n) = normals {
            for c in n[i].to_array() {
                w.write_all(&c.to_le_bytes())?;
            }
        }
    }
    for t in &mesh.triangles {
        w.write_all(&[3])?;
        for &v in t {
            w.write_all(&(v as i32).to_le_bytes())?;
        }
    }
    Ok(())
}

fn write_obj(w: &mut impl Write, mesh: &TriMesh, normals: Option<&[Vec3]>) -> std::io::Result<()> {
    writeln!(w, "# raystream isosurface, LPS millimetres")?;
    for p in &mesh.positions {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    if let Some(n) = normals {
        for n in n {
            writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
        }
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| v + 1);
        if normals.is_some() {
            writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
        } else {
            writeln!(w, "f {a} {b} {c}")?;
        }
    }
    Ok(())
}

/// The matrix of the node that holds the surface (column-major): LPS millimetres to glTF's
/// metres and axes, +X the patient's left, +Y superior, +Z anterior (right-handed, so a
/// viewer's front view is the anterior one, the patient's left on its right).
pub const LPS_MM_TO_GLTF: [f32; 16] = [
    0.001, 0.0, 0.0, 0.0, //
    0.0, 0.0, -0.001, 0.0, //
    0.0, 0.001, 0.0, 0.0, //
    0.0, 0.0, 0.0, 1.0,
];

/// Binary glTF: the surface's positions (LPS mm, as the other formats hold them), normals and
/// u32 indices in one buffer, under a node whose matrix is [`LPS_MM_TO_GLTF`], with a
/// bone-coloured material.
fn write_glb(w: &mut impl Write, mesh: &TriMesh, normals: Option<&[Vec3]>) -> std::io::Result<()> {
    let too_big = || std::io::Error::other("over the 4 GiB a GLB file can hold");
    let vec3s = |v: &[Vec3]| -> Vec<u8> {
        v.iter()
            .flat_map(|p| p.to_array())
            .flat_map(f32::to_le_bytes)
            .collect()
    };
    let mut bin = vec3s(&mesh.positions);
    let normals_at = bin.len();
    if let Some(n) = normals {
        bin.extend(vec3s(n));
    }
    let indices_at = bin.len();
    bin.extend(
        mesh.triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes()),
    );
    if bin.len() > u32::MAX as usize - 4096 {
        return Err(too_big());
    }
    let b = mesh.bounds();
    let n = mesh.positions.len();
    let view = |offset: usize, length: usize| serde_json::json!({"buffer": 0, "byteOffset": offset, "byteLength": length});
    let mut views = vec![view(0, normals_at)];
    let mut accessors = vec![serde_json::json!({
        "bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3",
        "min": b.min.to_array(), "max": b.max.to_array()
    })];
    let mut attributes = serde_json::json!({"POSITION": 0});
    if normals.is_some() {
        views.push(view(normals_at, indices_at - normals_at));
        accessors.push(serde_json::json!({
            "bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3"
        }));
        attributes["NORMAL"] = 1.into();
    }
    views.push(view(indices_at, bin.len() - indices_at));
    accessors.push(serde_json::json!({
        "bufferView": views.len() - 1, "componentType": 5125,
        "count": 3 * mesh.triangles.len(), "type": "SCALAR"
    }));
    let doc = serde_json::json!({
        "asset": {"version": "2.0", "generator": "raystream"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{
            "name": "isosurface (LPS mm; this node turns it to metres, +Y superior, +Z anterior)",
            "mesh": 0,
            "matrix": LPS_MM_TO_GLTF
        }],
        "meshes": [{"primitives": [{
            "attributes": attributes, "indices": accessors.len() - 1, "material": 0
        }]}],
        "materials": [{
            "name": "bone",
            "pbrMetallicRoughness": {"baseColorFactor": [0.89, 0.85, 0.79, 1.0], "metallicFactor": 0.0}
        }],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": views,
        "accessors": accessors,
    });
    let json = serde_json::to_vec(&doc).map_err(std::io::Error::other)?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: json.into(),
        bin: Some(bin.into()),
    };
    glb.to_writer(w).map_err(std::io::Error::other)
}

fn write_stl(w: &mut impl Write, mesh: &TriMesh) -> std::io::Result<()> {
    let tris = (0..mesh.len()).map(|i| {
        let [a, b, c] = mesh.corners(i);
        let n = (b - a).cross(c - a).normalize_or_zero();
        stl_io::Triangle {
            normal: stl_io::Vector::new(n.to_array()),
            vertices: [a, b, c].map(|p| stl_io::Vector::new(p.to_array())),
        }
    });
    stl_io::write_stl(w, tris)
}
