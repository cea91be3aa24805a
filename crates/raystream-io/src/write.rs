//! Mesh output: binary little-endian PLY (positions + normals), OBJ (`v`, `vn`, `f v//vn`) and
//! binary STL (stl_io). PLY and OBJ are written here: ply-rs-bw's writer builds a map of
//! properties per element, several times slower on the millions of vertices an isosurface has,
//! and no maintained crate writes OBJ. What is written reads back through [`crate::load_mesh`].

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::{MeshError, MeshFormat, TriMesh, Vec3};

/// Writes `mesh` (with optional per-vertex `normals`) in the format named by `path`'s extension.
pub fn write_mesh(path: &Path, mesh: &TriMesh, normals: Option<&[Vec3]>) -> Result<(), MeshError> {
    let format = MeshFormat::from_path(path)
        .filter(|f| *f != MeshFormat::Gltf && !path.to_string_lossy().ends_with(".gz"))
        .ok_or_else(|| MeshError::invalid(path, "output must end in .ply, .obj or .stl"))?;
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
        MeshFormat::Gltf => unreachable!("refused above"),
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
