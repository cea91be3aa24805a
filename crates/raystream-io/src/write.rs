//! Mesh output: binary little-endian PLY (positions + normals), OBJ (`v`, `vn`, `f v//vn`),
//! binary STL (by hand: its header names the space) and binary glTF (`.glb`: the JSON through serde_json, the container
//! through the gltf crate). PLY and OBJ are written here: ply-rs-bw's writer builds a map of
//! properties per element, several times slower on the millions of vertices an isosurface has,
//! and no maintained crate writes OBJ. What is written reads back through [`crate::load_mesh`].

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::{MeshError, MeshFormat, TriMesh, Vec3};

/// One named surface of a mesh file that holds several (`iso --segment`'s segments).
#[derive(Clone, Copy, Debug)]
pub struct MeshPart<'a> {
    /// Its name: a glTF node, mesh and material's, an OBJ object and material's.
    pub name: &'a str,
    pub mesh: &'a TriMesh,
    /// Per-vertex unit normals (ignored unless one a vertex).
    pub normals: Option<&'a [Vec3]>,
    /// Linear RGB, 0–1: glTF's base colour and OBJ's `Kd`; a PLY's 8-bit vertex colours are
    /// its sRGB encoding.
    pub colour: [f32; 3],
}

/// The colour an isosurface of bone is written in (linear RGB).
pub const BONE: [f32; 3] = [0.89, 0.85, 0.79];

/// Writes `mesh` (with optional per-vertex `normals`) in the format named by `path`'s extension.
pub fn write_mesh(path: &Path, mesh: &TriMesh, normals: Option<&[Vec3]>) -> Result<(), MeshError> {
    let part = MeshPart {
        name: "bone",
        mesh,
        normals,
        colour: BONE,
    };
    write_mesh_parts(path, &[part])
}

/// Writes the surfaces `parts` into one file, in the format named by `path`'s extension: one
/// part as [`write_mesh`] writes a mesh; several as a glTF node each (named, with its colour
/// as its material), an OBJ object each (its colour in a material library beside it, `path`
/// with the extension `.mtl`), a PLY whose vertices carry their part's colour, or a 3MF object
/// each (named, its colour as its base material). An STL holds one surface, so several are
/// refused.
pub fn write_mesh_parts(path: &Path, parts: &[MeshPart]) -> Result<(), MeshError> {
    let named = |ext: &str| {
        path.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case(ext))
    };
    let format = MeshFormat::from_path(path);
    // A `.dcm`, or an existing Encapsulated STL without the extension: not overwritten with a
    // bare STL.
    if named("dcm") || format == Some(MeshFormat::DicomStl) {
        return Err(MeshError::invalid(
            path,
            "a DICOM Encapsulated STL is made from its CT or label map: `raystream iso VOLUME -o MODEL.dcm`",
        ));
    }
    let glb = named("glb");
    let format = format
        .filter(|f| (*f != MeshFormat::Gltf || glb) && !path.to_string_lossy().ends_with(".gz"))
        .ok_or_else(|| {
            MeshError::invalid(
                path,
                "output must end in .ply, .obj, .stl, .vtk, .vtp, .3mf or .glb",
            )
        })?;
    if parts.is_empty() {
        return Err(MeshError::invalid(path, "no surface to write"));
    }
    if format == MeshFormat::Stl && parts.len() > 1 {
        return Err(MeshError::invalid(
            path,
            format!(
                "an STL file holds one surface here, not {}: write .3mf, .glb, .obj, .ply, .vtk or .vtp, or one at a time",
                parts.len()
            ),
        ));
    }
    let vertices: usize = parts.iter().map(|p| p.mesh.positions.len()).sum();
    if vertices > u32::MAX as usize {
        return Err(MeshError::invalid(
            path,
            format!("{vertices} vertices: over the 2³² a file's indices reach"),
        ));
    }
    let parts: Vec<MeshPart> = parts
        .iter()
        .map(|p| MeshPart {
            normals: p.normals.filter(|n| n.len() == p.mesh.positions.len()),
            ..*p
        })
        .collect();
    let io = |error| MeshError::Io {
        path: path.to_path_buf(),
        error,
    };
    let create = |path: &Path| std::fs::File::create(path).map(BufWriter::new);
    let mut w = create(path).map_err(io)?;
    let r = match format {
        MeshFormat::Ply => write_ply(&mut w, &parts),
        MeshFormat::Obj if parts.len() > 1 => {
            let library = path.with_extension("mtl");
            let name = library
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let mut m = create(&library).map_err(|error| MeshError::Io {
                path: library.clone(),
                error,
            })?;
            write_mtl(&mut m, &parts)
                .and_then(|()| m.flush())
                .map_err(|error| MeshError::Io {
                    path: library.clone(),
                    error,
                })?;
            write_obj(&mut w, &parts, Some(&name))
        }
        MeshFormat::Obj => write_obj(&mut w, &parts, None),
        MeshFormat::Stl | MeshFormat::DicomStl => write_stl(&mut w, &parts[0]),
        MeshFormat::Gltf => write_glb(&mut w, &parts),
        MeshFormat::Vtk => write_vtk(&mut w, &parts),
        MeshFormat::VtkXml => write_vtp(&mut w, &parts),
        MeshFormat::ThreeMf => crate::three_mf::write(&mut w, &parts),
    };
    r.and_then(|()| w.flush()).map_err(io)
}

/// A name as one OBJ/MTL token: its whitespace as underscores (tobj, as most readers, splits
/// `usemtl` and `newmtl` lines at whitespace).
fn token(name: &str) -> String {
    let t: String = name
        .trim()
        .chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect();
    if t.is_empty() { "surface".into() } else { t }
}

/// Linear RGB (0–1) as 8-bit sRGB.
pub(crate) fn srgb8(linear: [f32; 3]) -> [u8; 3] {
    linear.map(|c| crate::texture::linear_to_srgb8(c as f64))
}

fn write_ply(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    let coloured = parts.len() > 1;
    let normals = parts.iter().all(|p| p.normals.is_some());
    writeln!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment raystream isosurface, LPS millimetres\ncomment SPACE=LPS"
    )?;
    if coloured {
        for p in parts {
            let [r, g, b] = srgb8(p.colour);
            writeln!(w, "comment surface {} colour {r} {g} {b}", token(p.name))?;
        }
    }
    let count = |f: fn(&TriMesh) -> usize| parts.iter().map(|p| f(p.mesh)).sum::<usize>();
    writeln!(w, "element vertex {}", count(|m| m.positions.len()))?;
    writeln!(w, "property float x\nproperty float y\nproperty float z")?;
    if normals {
        writeln!(w, "property float nx\nproperty float ny\nproperty float nz")?;
    }
    if coloured {
        writeln!(
            w,
            "property uchar red\nproperty uchar green\nproperty uchar blue"
        )?;
    }
    writeln!(w, "element face {}", count(TriMesh::len))?;
    writeln!(w, "property list uchar int vertex_indices\nend_header")?;
    for p in parts {
        let rgb = srgb8(p.colour);
        for (i, x) in p.mesh.positions.iter().enumerate() {
            for c in x.to_array() {
                w.write_all(&c.to_le_bytes())?;
            }
            if let Some(n) = p.normals.filter(|_| normals) {
                for c in n[i].to_array() {
                    w.write_all(&c.to_le_bytes())?;
                }
            }
            if coloured {
                w.write_all(&rgb)?;
            }
        }
    }
    let mut base = 0u32;
    for p in parts {
        for t in &p.mesh.triangles {
            w.write_all(&[3])?;
            for &v in t {
                w.write_all(&((base + v) as i32).to_le_bytes())?;
            }
        }
        base += p.mesh.positions.len() as u32;
    }
    Ok(())
}

/// A material library: a material a part, its colour as `Kd`.
fn write_mtl(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    writeln!(w, "# raystream surfaces' colours")?;
    for p in parts {
        let [r, g, b] = p.colour;
        writeln!(w, "newmtl {}\nKd {r} {g} {b}", token(p.name))?;
    }
    Ok(())
}

/// OBJ, with the material library `library` (and an object and material a part) when given.
fn write_obj(w: &mut impl Write, parts: &[MeshPart], library: Option<&str>) -> std::io::Result<()> {
    writeln!(w, "# raystream isosurface, LPS millimetres\n# SPACE=LPS")?;
    if let Some(l) = library {
        writeln!(w, "mtllib {l}")?;
    }
    let all_normals = parts.iter().all(|p| p.normals.is_some());
    let mut base = 1u32;
    for p in parts {
        let normals = p.normals.filter(|_| all_normals);
        if library.is_some() {
            let name = token(p.name);
            writeln!(w, "o {name}\nusemtl {name}")?;
        }
        for x in &p.mesh.positions {
            writeln!(w, "v {} {} {}", x.x, x.y, x.z)?;
        }
        if let Some(n) = normals {
            for n in n {
                writeln!(w, "vn {} {} {}", n.x, n.y, n.z)?;
            }
        }
        for t in &p.mesh.triangles {
            let [a, b, c] = t.map(|v| v + base);
            if normals.is_some() {
                writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
            } else {
                writeln!(w, "f {a} {b} {c}")?;
            }
        }
        base += p.mesh.positions.len() as u32;
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

/// Binary glTF: each part's positions (LPS mm, as the other formats hold them), normals and
/// u32 indices in one buffer, a mesh and a node each (named, with its colour as its material),
/// under one node whose matrix is [`LPS_MM_TO_GLTF`].
fn write_glb(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    use serde_json::{Value, json};
    let too_big = || std::io::Error::other("over the 4 GiB a GLB file can hold");
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut meshes, mut nodes, mut materials) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    // Appends `bytes` as a buffer view, returning its index.
    let mut push = |bin: &mut Vec<u8>, bytes: &mut dyn Iterator<Item = u8>| -> usize {
        let offset = bin.len();
        bin.extend(bytes);
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bin.len() - offset}));
        views.len() - 1
    };
    let vec3s = |v: &[Vec3]| -> Vec<u8> {
        v.iter()
            .flat_map(|p| p.to_array())
            .flat_map(f32::to_le_bytes)
            .collect()
    };
    for (k, p) in parts.iter().enumerate() {
        let n = p.mesh.positions.len();
        let b = p.mesh.bounds();
        let view = push(&mut bin, &mut vec3s(&p.mesh.positions).into_iter());
        accessors.push(json!({
            "bufferView": view, "componentType": 5126, "count": n, "type": "VEC3",
            "min": b.min.to_array(), "max": b.max.to_array()
        }));
        let mut attributes = json!({"POSITION": accessors.len() - 1});
        if let Some(normals) = p.normals {
            let view = push(&mut bin, &mut vec3s(normals).into_iter());
            accessors.push(json!({
                "bufferView": view, "componentType": 5126, "count": n, "type": "VEC3"
            }));
            attributes["NORMAL"] = (accessors.len() - 1).into();
        }
        let view = push(
            &mut bin,
            &mut p
                .mesh
                .triangles
                .iter()
                .flatten()
                .flat_map(|i| i.to_le_bytes()),
        );
        accessors.push(json!({
            "bufferView": view, "componentType": 5125,
            "count": 3 * p.mesh.triangles.len(), "type": "SCALAR"
        }));
        let [r, g, b] = p.colour;
        materials.push(json!({
            "name": p.name,
            "pbrMetallicRoughness": {"baseColorFactor": [r, g, b, 1.0], "metallicFactor": 0.0}
        }));
        meshes.push(json!({"name": p.name, "primitives": [{
            "attributes": attributes, "indices": accessors.len() - 1, "material": k
        }]}));
        nodes.push(json!({"name": p.name, "mesh": k}));
        if bin.len() > u32::MAX as usize - 4096 {
            return Err(too_big());
        }
    }
    let children: Vec<usize> = (1..=parts.len()).collect();
    nodes.insert(
        0,
        json!({
            "name": "LPS millimetres (this node turns them to glTF's metres, +Y superior, +Z anterior)",
            "matrix": LPS_MM_TO_GLTF,
            "children": children
        }),
    );
    let doc: Value = json!({
        "asset": {"version": "2.0", "generator": "raystream"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
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

/// Legacy VTK polygonal data, binary, in the file version 3D Slicer writes (4.2), its title
/// naming the space as Slicer's do: 3D Slicer's own model format. Several parts are one
/// surface whose points carry their part's colour (`COLOR_SCALARS`, 8-bit sRGB, the point
/// data's active scalars, as VTK draws them).
fn write_vtk(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    let points: usize = parts.iter().map(|p| p.mesh.positions.len()).sum();
    let triangles: usize = parts.iter().map(|p| p.mesh.len()).sum();
    write!(
        w,
        "# vtk DataFile Version 4.2\nraystream isosurface, LPS millimetres. SPACE=LPS\nBINARY\nDATASET POLYDATA\nPOINTS {points} float\n"
    )?;
    let big_endian = |w: &mut dyn Write, v: &[Vec3]| -> std::io::Result<()> {
        v.iter()
            .flat_map(|p| p.to_array())
            .try_for_each(|x| w.write_all(&x.to_be_bytes()))
    };
    for p in parts {
        big_endian(w, &p.mesh.positions)?;
    }
    write!(w, "\nPOLYGONS {triangles} {}\n", 4 * triangles)?;
    let mut base = 0;
    for p in parts {
        for t in &p.mesh.triangles {
            w.write_all(&3i32.to_be_bytes())?;
            for &v in t {
                w.write_all(&((base + v) as i32).to_be_bytes())?;
            }
        }
        base += p.mesh.positions.len() as u32;
    }
    let normals = parts.iter().all(|p| p.normals.is_some());
    if parts.len() > 1 || normals {
        write!(w, "\nPOINT_DATA {points}")?;
    }
    if parts.len() > 1 {
        w.write_all(b"\nCOLOR_SCALARS Colors 3\n")?;
        for p in parts {
            let colour = srgb8(p.colour);
            for _ in 0..p.mesh.positions.len() {
                w.write_all(&colour)?;
            }
        }
    }
    if normals {
        w.write_all(b"\nNORMALS Normals float\n")?;
        for p in parts {
            big_endian(w, p.normals.unwrap_or_default())?;
        }
    }
    writeln!(w)
}

/// VTK XML polygonal data (`.vtp`, ParaView's format): a piece a part (its points, its
/// triangles as polygons, its normals where given, and its colour on every point as 8-bit
/// sRGB `Colors`), the arrays appended raw and uncompressed after 64-bit byte counts, little
/// endian; its field data names its space as 3D Slicer does (a `SPACE` string, `LPS`). Written
/// by hand, as the reader is ([`crate::vtk_xml`]).
fn write_vtp(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    use std::fmt::Write as _;
    let mut xml = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <PolyData>\n\
         \x20   <FieldData>\n      <Array type=\"String\" Name=\"SPACE\" NumberOfTuples=\"1\" \
         format=\"ascii\">76 80 83 0</Array>\n    </FieldData>\n",
    );
    let mut data: Vec<u8> = Vec::new();
    let mut array = |xml: &mut String, ty: &str, name: &str, components: usize, bytes: &[u8]| {
        let _ = writeln!(
            xml,
            "        <DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{components}\" format=\"appended\" offset=\"{}\"/>",
            data.len()
        );
        data.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        data.extend_from_slice(bytes);
    };
    let floats = |v: &[Vec3]| -> Vec<u8> {
        v.iter()
            .flat_map(|p| p.to_array())
            .flat_map(f32::to_le_bytes)
            .collect()
    };
    for part in parts {
        let mesh = part.mesh;
        let (n, t) = (mesh.positions.len(), mesh.len());
        let _ = writeln!(
            xml,
            "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"{t}\">"
        );
        let normals = if part.normals.is_some() {
            " Normals=\"Normals\""
        } else {
            ""
        };
        let _ = writeln!(xml, "      <PointData Scalars=\"Colors\"{normals}>");
        let colour = srgb8(part.colour);
        let colours: Vec<u8> = (0..n).flat_map(|_| colour).collect();
        array(&mut xml, "UInt8", "Colors", 3, &colours);
        if let Some(normals) = part.normals {
            array(&mut xml, "Float32", "Normals", 3, &floats(normals));
        }
        xml.push_str("      </PointData>\n      <Points>\n");
        array(&mut xml, "Float32", "Points", 3, &floats(&mesh.positions));
        xml.push_str("      </Points>\n      <Polys>\n");
        let connectivity: Vec<u8> = mesh
            .triangles
            .iter()
            .flatten()
            .flat_map(|&v| (v as i64).to_le_bytes())
            .collect();
        array(&mut xml, "Int64", "connectivity", 1, &connectivity);
        let offsets: Vec<u8> = (1..=t as i64).flat_map(|k| (3 * k).to_le_bytes()).collect();
        array(&mut xml, "Int64", "offsets", 1, &offsets);
        xml.push_str("      </Polys>\n    </Piece>\n");
    }
    xml.push_str("  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _");
    w.write_all(xml.as_bytes())?;
    w.write_all(&data)?;
    w.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
}

/// Binary STL, written by hand rather than by stl_io, whose writer leaves the 80-byte header
/// blank: the header says the coordinates' space, as 3D Slicer reads it (`SPACE=LPS`), and the
/// part's colour as Materialise's software reads it (`COLOR=` and its sRGB bytes, opaque); each
/// triangle carries that colour as its own too, 5 bits a channel with bit 15 clear, so that a
/// reader taking a triangle's colour over the header's (Materialise's convention) and one
/// taking the header's where bit 15 is clear (Assimp's) show the same. A reader of VisCAM's
/// convention, which needs bit 15 set, sees no colours.
pub(crate) fn write_stl(w: &mut impl Write, part: &MeshPart) -> std::io::Result<()> {
    let mesh = part.mesh;
    let srgb = srgb8(part.colour);
    let mut header = [b' '; 80];
    let text = b"raystream isosurface, LPS millimetres. SPACE=LPS COLOR=";
    header[..text.len()].copy_from_slice(text);
    header[text.len()..text.len() + 4].copy_from_slice(&[srgb[0], srgb[1], srgb[2], 255]);
    w.write_all(&header)?;
    let count = u32::try_from(mesh.len()).map_err(std::io::Error::other)?;
    w.write_all(&count.to_le_bytes())?;
    let [r, g, b] = srgb.map(crate::stl::five_bits);
    let attribute = (r | g << 5 | b << 10).to_le_bytes();
    for i in 0..mesh.len() {
        let [a, b, c] = mesh.corners(i);
        let n = (b - a).cross(c - a).normalize_or_zero();
        for v in [n, a, b, c] {
            for x in v.to_array() {
                w.write_all(&x.to_le_bytes())?;
            }
        }
        w.write_all(&attribute)?;
    }
    Ok(())
}
