use std::path::{Path, PathBuf};

use super::*;

/// A scratch folder of its own under the system's temporary one, removed when the test ends,
/// passed or failed (`tempfile`).
pub(crate) fn scratch_dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("raystream-io-{name}-"))
        .tempdir()
        .unwrap()
}

/// A file's path in a scratch folder of its own: the folder goes when this does.
pub(crate) struct ScratchFile {
    path: PathBuf,
    _dir: tempfile::TempDir,
}

impl std::ops::Deref for ScratchFile {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for ScratchFile {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

/// `name` in a scratch folder of its own ([`scratch_dir`]).
pub(crate) fn scratch_file(name: &str) -> ScratchFile {
    let dir = scratch_dir(name.split('.').next().unwrap_or(name));
    ScratchFile {
        path: dir.path().join(name),
        _dir: dir,
    }
}

fn shared_mesh(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/meshes")
        .join(name)
}

fn parse_str(text: &str, format: MeshFormat) -> Result<TriMesh, MeshError> {
    parse_mesh(text.as_bytes(), format, Path::new("test-input"))
}

fn problem(r: Result<TriMesh, MeshError>) -> String {
    let e = r.expect_err("bad input must be an error");
    let msg = e.to_string();
    assert!(
        msg.starts_with("test-input: "),
        "error must name the file: {msg}"
    );
    msg
}

#[test]
fn real_meshes_have_their_documented_sizes() {
    // Counts from ../shared/data/README.md (checked there with trimesh).
    for (name, triangles) in [
        ("spot.obj", 5_856),
        ("utah_teapot.obj", 6_320),
        ("goblet_vase.stl", 10_910),
        ("stanford_bunny.ply", 69_451),
        ("stanford_lucy_100k.ply", 99_970),
        ("turbine_blade.ply", 199_034),
    ] {
        let mesh = load_mesh(&shared_mesh(name)).unwrap();
        assert_eq!(mesh.len(), triangles, "{name}");
        let b = mesh.bounds();
        assert!(!b.is_empty() && b.radius() > 0.0, "{name}");
    }
}

#[test]
fn polygons_are_fans_in_file_order() {
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\n\
               f 1 2 3\nf 1 2 3 4 5\nf 2/1 3/1 4/1\n";
    let m = parse_str(obj, MeshFormat::Obj).unwrap();
    assert_eq!(
        m.triangles,
        vec![[0, 1, 2], [0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 2, 3]]
    );
    let ply = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
               property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n5 0 1 2 3 4\n3 4 3 1\n";
    let m = parse_str(ply, MeshFormat::Ply).unwrap();
    assert_eq!(
        m.triangles,
        vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [4, 3, 1]]
    );
}

#[test]
fn degenerate_triangles_keep_their_number() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 1 2 3\n";
    let m = parse_str(obj, MeshFormat::Obj).unwrap();
    assert_eq!(m.triangles, vec![[0, 0, 0], [0, 1, 2]]);
}

#[test]
fn stl_ascii_and_binary_agree() {
    let ascii = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n\
                 endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\n\
                 vertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
    let a = parse_str(ascii, MeshFormat::Stl).unwrap();
    let mut bin = vec![0u8; 80];
    bin.extend(2u32.to_le_bytes());
    for tri in [
        [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ] {
        bin.extend([0.0f32, 0.0, 1.0].iter().flat_map(|f| f.to_le_bytes()));
        bin.extend(tri.iter().flatten().flat_map(|f| f.to_le_bytes()));
        bin.extend([0u8, 0]);
    }
    let b = parse_mesh(&bin, MeshFormat::Stl, Path::new("test-input")).unwrap();
    assert_eq!(a.len(), 2);
    for i in 0..2 {
        assert_eq!(a.corners(i), b.corners(i));
    }
}

#[test]
fn gzip_is_looked_through() {
    use std::io::Write;
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(obj.as_bytes()).unwrap();
    let m = parse_mesh(
        &gz.finish().unwrap(),
        MeshFormat::Obj,
        Path::new("x.obj.gz"),
    )
    .unwrap();
    assert_eq!(m.len(), 1);
    assert_eq!(
        MeshFormat::from_path(Path::new("a/B.PLY.gz")),
        Some(MeshFormat::Ply)
    );
    assert_eq!(MeshFormat::from_path(Path::new("a/b.off")), None);
}

#[test]
fn nan_and_inf_coordinates_are_errors() {
    let msg = problem(parse_str(
        "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n",
        MeshFormat::Obj,
    ));
    assert!(msg.contains("vertex 1") && msg.contains("NaN"), "{msg}");
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0\n1 0 1e39\n0 1 0\n3 0 1 2\n";
    assert!(problem(parse_str(ply, MeshFormat::Ply)).contains("NaN or infinite"));
}

#[test]
fn out_of_range_indices_are_errors() {
    problem(parse_str(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
        MeshFormat::Obj,
    ));
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
               property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n";
    let msg = problem(parse_str(ply, MeshFormat::Ply));
    assert!(msg.contains("3 vertices"), "{msg}");
    let neg = ply.replace("3 0 1 3", "3 0 1 -1");
    assert!(problem(parse_str(&neg, MeshFormat::Ply)).contains("-1"));
}

#[test]
fn empty_meshes_are_errors() {
    assert!(problem(parse_str("v 0 0 0\nv 1 0 0\n", MeshFormat::Obj)).contains("no triangles"));
    assert!(problem(parse_str("", MeshFormat::Obj)).contains("no triangles"));
    let ply = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
               property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
    assert!(problem(parse_str(ply, MeshFormat::Ply)).contains("no triangles"));
    // all corners in one point
    problem(parse_str(
        "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n",
        MeshFormat::Obj,
    ));
}

#[test]
fn truncated_files_are_errors() {
    for name in [
        "stanford_lucy_100k.ply",
        "goblet_vase.stl",
        "stanford_bunny.ply",
    ] {
        let bytes = std::fs::read(shared_mesh(name)).unwrap();
        let format = MeshFormat::from_path(Path::new(name)).unwrap();
        for keep in [10, bytes.len() / 2, bytes.len() - 7] {
            let r = parse_mesh(&bytes[..keep], format, Path::new("test-input"));
            let msg = problem(r);
            assert!(!msg.is_empty(), "{name} cut at {keep}");
        }
    }
}

#[test]
fn lying_headers_do_not_allocate() {
    // A binary STL claiming 4 billion triangles in 84 + 50 bytes.
    let mut bin = vec![0u8; 80];
    bin.extend(u32::MAX.to_le_bytes());
    bin.extend([0u8; 50]);
    let msg = problem(parse_mesh(&bin, MeshFormat::Stl, Path::new("test-input")));
    assert!(msg.contains("truncated"), "{msg}");
    // A binary PLY claiming 10^9 vertices.
    let mut ply =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\n\
                    property float y\nproperty float z\nend_header\n"
            .to_vec();
    ply.extend([0u8; 24]);
    problem(parse_mesh(&ply, MeshFormat::Ply, Path::new("test-input")));
}

#[test]
fn unsupported_extension_and_missing_file() {
    let e = load_mesh(Path::new("scene.off")).unwrap_err().to_string();
    assert!(e.contains("scene.off") && e.contains("unsupported"), "{e}");
    let e = load_mesh(Path::new("does/not/exist.obj"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("does/not/exist.obj"), "{e}");
}

#[test]
fn garbage_is_an_error_not_a_panic() {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for len in [0usize, 1, 5, 84, 200, 1000] {
        let bytes: Vec<u8> = (0..len)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state as u8
            })
            .collect();
        for format in [MeshFormat::Obj, MeshFormat::Ply, MeshFormat::Stl] {
            assert!(parse_mesh(&bytes, format, Path::new("g")).is_err());
        }
    }
}

#[test]
fn written_meshes_read_back_identically() {
    let mesh = TriMesh::icosphere(2);
    let normals = mesh.vertex_normals();
    let scratch = scratch_dir("write");
    let dir = scratch.path();
    for name in ["m.ply", "m.obj", "m.stl", "m.vtk"] {
        let path = dir.join(name);
        write_mesh(&path, &mesh, Some(&normals)).unwrap();
        let back = load_mesh(&path).unwrap();
        assert_eq!(back.len(), mesh.len(), "{name}");
        for i in 0..mesh.len() {
            assert_eq!(back.corners(i), mesh.corners(i), "{name} triangle {i}");
        }
        // Each says its coordinates are LPS, as 3D Slicer reads the tag.
        let (_, shading) = load_mesh_with_shading(&path).unwrap();
        assert_eq!(shading.space, Some(PatientSpace::Lps), "{name}");
    }
    let e = write_mesh(&dir.join("m.off"), &mesh, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("m.off"), "{e}");
}

/// A binary STL of one triangle a value of `attributes`, `header` at the start of its 80 bytes.
fn binary_stl(header: &[u8], attributes: &[u16]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&(attributes.len() as u32).to_le_bytes());
    for (i, a) in attributes.iter().enumerate() {
        let x = i as f32;
        for v in [
            0.0,
            0.0,
            1.0,
            x,
            0.0,
            0.0,
            x + 1.0,
            0.0,
            0.0,
            x,
            1.0,
            0.0f32,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&a.to_le_bytes());
    }
    b
}

/// A binary STL's triangle colours (by Wikipedia's "STL (file format)"), read from `bytes`.
fn stl_colours(bytes: &[u8]) -> Vec<Rgb8> {
    let path = scratch_file("c.stl");
    std::fs::write(&path, bytes).unwrap();
    let (mesh, shading) = load_mesh_with_shading(&path).unwrap();
    assert!(shading.colours.is_empty() || shading.colours.len() == mesh.len());
    shading
        .colours
        .iter()
        .map(|c| {
            assert!(c[1] == c[0] && c[2] == c[0], "a colour a triangle");
            c[0]
        })
        .collect()
}

/// Colour in binary STL, by its two conventions: Materialise's (`COLOR=` in the header, a
/// triangle's own colour red-first where bit 15 is clear) and VisCAM's (no `COLOR=`, blue-first
/// where bit 15 is set); and `iso`'s STL, which carries its part's colour both ways.
#[test]
fn binary_stl_colours_by_both_conventions() {
    // The 5-bit channels: each of the 32 values comes back; 8 bits within half a step.
    for v in 0..32u16 {
        let c = ((u32::from(v) * 255 + 15) / 31) as u8;
        assert_eq!(stl::five_bits(c), v);
    }
    let (r5, g5, b5) = (31u16, 16u16, 1u16);
    let (r8, g8, b8) = (255u8, 132u8, 8u8);
    // VisCAM/SolidView: red in bits 10-14; bit 15 clear is no colour (the default grey).
    let viscam = binary_stl(
        b"solid? no: binary",
        &[0x8000 | r5 << 10 | g5 << 5 | b5, 0, 0x8000],
    );
    assert_eq!(
        stl_colours(&viscam),
        [[r8, g8, b8], UNCOLOURED_GREY, [0, 0, 0]]
    );
    // No triangle with bit 15 set and no COLOR=: no colours (netfabb's vase too, tested above).
    assert!(stl_colours(&binary_stl(b"plain", &[0, 0x7fff])).is_empty());
    // Materialise: red in bits 0-4 where bit 15 is clear; the part's colour where it is set.
    let mut header = b"Magics COLOR=".to_vec();
    header.extend_from_slice(&[40, 90, 200, 255]);
    let near_part = stl::five_bits(40) | stl::five_bits(90) << 5 | stl::five_bits(200) << 10;
    let cut_part = (40 >> 3) | (90 >> 3) << 5 | (200 >> 3) << 10;
    let magics = binary_stl(
        &header,
        &[r5 | g5 << 5 | b5 << 10, 0x8000, 0, near_part, cut_part],
    );
    assert_eq!(
        stl_colours(&magics),
        [
            [r8, g8, b8],
            [40, 90, 200],
            [0, 0, 0],
            // A triangle's own colour that is the part's at 5 bits, rounded or cut: the part's.
            [40, 90, 200],
            [40, 90, 200],
        ]
    );
    // A MATERIAL= after it: its diffuse colour is the part's.
    header.extend_from_slice(b",MATERIAL=");
    header.extend_from_slice(&[7, 8, 9, 255, 100, 100, 100, 255, 1, 1, 1, 255]);
    assert_eq!(stl_colours(&binary_stl(&header, &[0x8000])), [[7, 8, 9]]);
    // A header cut off after COLOR= (fewer than 4 bytes left): no part colour, VisCAM's way.
    let mut at_end = vec![b' '; 80];
    at_end[74..].copy_from_slice(b"COLOR=");
    assert!(stl_colours(&binary_stl(&at_end, &[0])).is_empty());

    // `write_mesh_parts`' STL: the part's colour in its header and in every triangle; read back
    // exactly (8 bits), its space still LPS.
    let mesh = TriMesh::icosphere(1);
    let path = scratch_file("part.stl");
    let colour = [0.8f32, 0.3, 0.05];
    let part = MeshPart {
        name: "part",
        mesh: &mesh,
        normals: None,
        colour,
    };
    write_mesh_parts(&path, &[part]).unwrap();
    let srgb = colour.map(|c| linear_to_srgb8(c as f64));
    let (_, shading) = load_mesh_with_shading(&path).unwrap();
    assert_eq!(shading.colours, vec![[srgb; 3]; mesh.len()]);
    assert_eq!(shading.space, Some(PatientSpace::Lps));
    let bytes = std::fs::read(&path).unwrap();
    let at = bytes[..80].windows(6).position(|w| w == b"COLOR=").unwrap() + 6;
    assert_eq!(bytes[at..at + 4], [srgb[0], srgb[1], srgb[2], 255]);
    let own = u16::from_le_bytes([bytes[84 + 48], bytes[84 + 49]]);
    assert_eq!(own & 0x8000, 0, "a triangle's own colour");
    assert_eq!(
        [own & 31, own >> 5 & 31, own >> 10 & 31],
        srgb.map(stl::five_bits)
    );
}

/// 3D Slicer's `SPACE=` tag, where each format carries it (Slicer's own headers and comments),
/// and where it is not one.
#[test]
fn the_patient_space_a_mesh_file_declares() {
    let some = |bytes: &[u8], format| declared_space(bytes, format);
    let (lps, ras) = (Some(PatientSpace::Lps), Some(PatientSpace::Ras));
    let mut binary = [b' '; 84].to_vec();
    binary[..27].copy_from_slice(b"3D Slicer output. SPACE=RAS");
    assert_eq!(some(&binary, MeshFormat::Stl), ras);
    let ascii = b"solid 3D Slicer output. SPACE=LPS\n facet normal 0 0 1\n";
    assert_eq!(some(ascii, MeshFormat::Stl), lps);
    assert_eq!(some(b"solid SPACE=lps", MeshFormat::Stl), lps);
    let ply = b"ply\nformat ascii 1.0\ncomment VTK generated PLY File\ncomment SPACE=RAS\nelement vertex 0\nend_header\n";
    assert_eq!(some(ply, MeshFormat::Ply), ras);
    let obj = b"# wavefront obj file written by the visualization toolkit\n\n# 3D Slicer output. SPACE=RAS\n\nmtllib m.mtl\nv 0 0 0\n";
    assert_eq!(some(obj, MeshFormat::Obj), ras);
    for (bytes, format) in [
        (&b"solid NOSPACE=RAS"[..], MeshFormat::Stl),
        (b"solid SPACE=XYZ", MeshFormat::Stl),
        (b"solid part\nfacet normal 0 0 1 SPACE=RAS", MeshFormat::Stl),
        (
            b"ply\nformat ascii 1.0\nend_header\ncomment SPACE=RAS\n",
            MeshFormat::Ply,
        ),
        (b"v 0 0 0\n# SPACE=RAS\n", MeshFormat::Obj),
        (
            b"{\"asset\": {\"extras\": \"SPACE=RAS\"}}",
            MeshFormat::Gltf,
        ),
    ] {
        assert_eq!(
            some(bytes, format),
            None,
            "{}",
            String::from_utf8_lossy(bytes)
        );
    }
    assert_eq!(
        PatientSpace::Ras.to_lps(Vec3::new(1.0, 2.0, 3.0)),
        Vec3::new(-1.0, -2.0, 3.0)
    );
}

/// The volume a closed mesh encloses: an icosphere's, a little under the unit ball's (its
/// flat faces cut inside the sphere), the same wherever it is moved, and negative turned
/// inside out.
#[test]
fn enclosed_volume_of_a_closed_mesh() {
    let mut m = TriMesh::icosphere(3);
    let ball = 4.0 / 3.0 * std::f64::consts::PI;
    let v = m.enclosed_volume();
    assert!(v < ball && v > 0.98 * ball, "{v} for {ball}");
    m.positions
        .iter_mut()
        .for_each(|p| *p += Vec3::new(100.0, -50.0, 20.0));
    assert!((m.enclosed_volume() - v).abs() < 1e-3 * v);
    m.triangles.iter_mut().for_each(|t| t.swap(1, 2));
    assert!((m.enclosed_volume() + v).abs() < 1e-3 * v);
}

/// Several surfaces in one file: each a glTF node and material (named, in its colour), an OBJ
/// object with its material in the library beside it, a PLY's vertices in its sRGB colour;
/// read back, each part's triangles are its own, in order; a 3MF object each. An STL refuses
/// two.
#[test]
fn mesh_parts_keep_their_names_and_colours() {
    let scratch = scratch_dir("parts");
    let dir = scratch.path();
    let a = TriMesh::icosphere(1);
    let mut b = TriMesh::icosphere(2);
    b.positions
        .iter_mut()
        .for_each(|p| *p += Vec3::new(3.0, 0.0, 0.0));
    let (na, nb) = (a.vertex_normals(), b.vertex_normals());
    let parts = [
        crate::MeshPart {
            name: "left lung",
            mesh: &a,
            normals: Some(&na),
            colour: [1.0, 0.5, 0.0],
        },
        crate::MeshPart {
            name: "heart",
            mesh: &b,
            normals: Some(&nb),
            colour: [0.2, 0.0, 1.0],
        },
    ];
    for name in ["m.glb", "m.obj"] {
        let path = dir.join(name);
        crate::write_mesh_parts(&path, &parts).unwrap();
        let (mesh, shading) = load_mesh_with_shading(&path).unwrap();
        let names: Vec<&str> = shading.materials.iter().map(|m| m.name.as_str()).collect();
        let want = if name == "m.obj" {
            ["left_lung", "heart"]
        } else {
            ["left lung", "heart"]
        };
        assert_eq!(names, want, "{name}");
        assert_eq!(
            shading.materials[0].diffuse,
            Some([1.0, 0.5, 0.0]),
            "{name}"
        );
        assert_eq!(
            shading.materials[1].diffuse,
            Some([0.2, 0.0, 1.0]),
            "{name}"
        );
        assert_eq!(mesh.len(), a.len() + b.len(), "{name}");
        // glTF's nodes turn LPS millimetres into metres, +Y superior, +Z anterior.
        let back = |p: Vec3| {
            if name == "m.glb" {
                Vec3::new(p.x, -p.z, p.y) * 1000.0
            } else {
                p
            }
        };
        for (i, part) in [&a, &b].iter().enumerate() {
            let mine: Vec<usize> = (0..mesh.len())
                .filter(|&t| shading.material_of[t] == Some(i as u32))
                .collect();
            assert_eq!(mine.len(), part.len(), "{name} part {i}");
            for (k, &t) in mine.iter().enumerate() {
                for (g, w) in mesh.corners(t).iter().zip(part.corners(k)) {
                    assert!(
                        (back(*g) - w).length() < 1e-5,
                        "{name} part {i}: {g} for {w}"
                    );
                }
            }
        }
    }
    // PLY: the header names the parts, each vertex carries its part's sRGB colour.
    let path = dir.join("m.ply");
    crate::write_mesh_parts(&path, &parts).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    assert!(
        text.contains("comment surface left_lung colour 255 188 0"),
        "{text:.400}"
    );
    assert!(text.contains("property uchar red"));
    let back = load_mesh(&path).unwrap();
    assert_eq!(back.len(), a.len() + b.len());
    assert_eq!(back.corners(a.len()), b.corners(0));
    // PLY, VTK and VTK XML read back with each part's triangles in its colour.
    for name in ["m.ply", "m.vtk", "m.vtp"] {
        let path = dir.join(name);
        crate::write_mesh_parts(&path, &parts).unwrap();
        let (mesh, shading) = load_mesh_with_shading(&path).unwrap();
        assert_eq!(mesh.corners(a.len()), b.corners(0), "{name}");
        assert_eq!(shading.space, Some(crate::PatientSpace::Lps), "{name}");
        assert_eq!(shading.normals.len(), mesh.positions.len(), "{name}");
        let (orange, violet) = ([255, 188, 0], [124, 0, 255]);
        for (t, corners) in shading.colours.iter().enumerate() {
            let want = if t < a.len() { orange } else { violet };
            assert_eq!(corners, &[want; 3], "{name} triangle {t}");
        }
        assert_eq!(shading.colours.len(), mesh.len(), "{name}");
    }
    // 3MF: an object each (named as it is, XML's special characters escaped), read back
    // with each part's triangles, exactly, in its colour.
    let path3 = dir.join("m.3mf");
    let mut odd = parts;
    odd[1].name = "heart & <great \"vessels\">";
    crate::write_mesh_parts(&path3, &odd).unwrap();
    let (mesh, shading) = load_mesh_with_shading(&path3).unwrap();
    assert_eq!(mesh.len(), a.len() + b.len());
    for t in 0..mesh.len() {
        let want = if t < a.len() {
            a.corners(t)
        } else {
            b.corners(t - a.len())
        };
        assert_eq!(mesh.corners(t), want, "3MF triangle {t}");
        let colour = if t < a.len() {
            [255, 188, 0]
        } else {
            [124, 0, 255]
        };
        assert_eq!(shading.colours[t], [colour; 3], "3MF triangle {t}");
    }
    // One part: the plain formats, as `write_mesh` writes them.
    crate::write_mesh_parts(&path, &parts[..1]).unwrap();
    let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
    assert!(!text.contains("uchar red"));
    let e = crate::write_mesh_parts(&dir.join("m.stl"), &parts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("m.stl: an STL file holds one surface here, not 2"),
        "{e}"
    );
}

const TWO_LIBRARIES_OBJ: &str = "mtllib paint.mtl
mtllib glass.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
usemtl red
f 1 2 3 4
usemtl glass
f 2 5 6
usemtl nowhere
f 2 6 3
usemtl red
f 1 2 4
";

/// An OBJ's texture coordinates are kept per triangle corner, as the fan triangulation takes
/// its polygon's; `map_Kd` (options before the file name allowed) reads the image beside the
/// library. A missing image, or faces without texture coordinates, are warnings that leave the
/// texture out; the geometry is the same either way.
#[test]
fn obj_textures_and_their_coordinates() {
    let scratch = scratch_dir("uv");
    let dir = scratch.path();
    let quad = "mtllib t.mtl\nusemtl painted\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\nf 1/1 2/2 3/3 4/4\nf 1/5 3/3 4/4\n";
    std::fs::write(dir.join("q.obj"), quad).unwrap();
    std::fs::write(
        dir.join("t.mtl"),
        "newmtl painted\nKd 1 1 1\nmap_Kd -s 1 1 1 tex.png\n",
    )
    .unwrap();
    image::RgbaImage::from_pixel(4, 2, image::Rgba([200, 100, 50, 255]))
        .save(dir.join("tex.png"))
        .unwrap();
    let (mesh, m) = load_mesh_with_shading(&dir.join("q.obj")).unwrap();
    assert_eq!(mesh.len(), 3);
    let uv = |x: f32, y: f32| Vec2::new(x, y);
    assert_eq!(
        m.uvs,
        [
            [uv(0.0, 0.0), uv(1.0, 0.0), uv(1.0, 1.0)],
            [uv(0.0, 0.0), uv(1.0, 1.0), uv(0.0, 1.0)],
            [uv(0.5, 0.5), uv(1.0, 1.0), uv(0.0, 1.0)],
        ]
    );
    let image = m.materials[0].image.as_ref().expect("the texture is read");
    assert_eq!((image.width, image.height), (4, 2));
    assert_eq!(image.texels[7], [200, 100, 50, 255]);
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    // The same triangles as the plain reader's.
    let plain = load_mesh(&dir.join("q.obj")).unwrap();
    assert!((0..3).all(|i| mesh.corners(i) == plain.corners(i)));

    // The image missing: a warning naming it; no image.
    std::fs::remove_file(dir.join("tex.png")).unwrap();
    let (_, m) = load_mesh_with_shading(&dir.join("q.obj")).unwrap();
    assert!(m.materials[0].image.is_none());
    assert!(
        m.warnings.len() == 1
            && m.warnings[0].contains("'painted': texture")
            && m.warnings[0].contains("tex.png"),
        "{:?}",
        m.warnings
    );
    // A face without texture coordinates: none are kept, and the texture is not applied.
    std::fs::write(dir.join("q.obj"), format!("{quad}f 1 2 3\n")).unwrap();
    let (mesh, m) = load_mesh_with_shading(&dir.join("q.obj")).unwrap();
    assert_eq!(mesh.len(), 4);
    assert!(m.uvs.is_empty());
    assert!(
        m.warnings.iter().any(|w| w.contains("not applied")),
        "{:?}",
        m.warnings
    );
}

/// An OBJ's materials from two libraries, in file order: a quad's two fan triangles share
/// their polygon's material, a material used again keeps its number, a name no library has
/// gives none; `Tr` stands for 1 − `d`; textures are named in a warning.
/// `map_Kd`'s options: scale, offset and clamp are read; the others are skipped with their
/// arguments and named; the file name is what follows, spaces and all.
#[test]
fn texture_options_are_read_or_named() {
    let (file, mapping, ignored) = texture_options("  wood grain.png ");
    assert_eq!(
        (file, mapping),
        ("wood grain.png", TextureMapping::default())
    );
    assert!(ignored.is_empty());
    let (file, mapping, ignored) =
        texture_options("-s 2 3 1 -blendu off -o 0.5 -0.25 -mm 0 1 -clamp on -t 1 1 wood.png");
    assert_eq!(
        (file, mapping),
        (
            "wood.png",
            TextureMapping {
                scale: Vec2::new(2.0, 3.0),
                offset: Vec2::new(0.5, -0.25),
                clamp: true,
            }
        )
    );
    assert_eq!(ignored, ["-blendu off", "-mm 0 1", "-t 1 1"]);
    // One number: u alone; a file name that is a number stays the file.
    let (file, mapping, _) = texture_options("-o 0.5 -s 4 7.png");
    assert_eq!(
        (file, mapping.offset, mapping.scale),
        ("7.png", Vec2::new(0.5, 0.0), Vec2::new(4.0, 1.0))
    );
    // Options and nothing after them: the statement is the (missing) file, never a panic.
    for s in ["-clamp", "-s", "-mm 1", "-o x"] {
        let (file, _, _) = texture_options(s);
        assert!(!file.is_empty(), "{s}");
    }
}

#[test]
fn obj_materials_follow_the_faces() {
    let scratch = scratch_dir("mtl");
    let dir = scratch.path();
    std::fs::write(dir.join("scene.obj"), TWO_LIBRARIES_OBJ).unwrap();
    std::fs::write(
        dir.join("paint.mtl"),
        "newmtl red\nKd 0.8 0.1 0.1\nKs 0.2 0.2 0.2\nNs 40\nillum 2\nmap_Kd red.png\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("glass.mtl"),
        "newmtl glass\nKd 0 0 0\nTr 0.9\nNi 1.5\nillum 7\n",
    )
    .unwrap();
    let (mesh, m) = load_mesh_with_shading(&dir.join("scene.obj")).unwrap();
    assert_eq!(mesh.len(), 5);
    let names: Vec<&str> = m.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["red", "glass"]);
    assert_eq!(m.material_of, [Some(0), Some(0), Some(1), None, Some(0)]);
    assert_eq!(
        m.materials[0],
        MtlMaterial {
            name: "red".into(),
            diffuse: Some([0.8, 0.1, 0.1]),
            specular: Some([0.2, 0.2, 0.2]),
            shininess: Some(40.0),
            illum: Some(2),
            texture: Some("red.png".into()),
            ..Default::default()
        }
    );
    let glass = &m.materials[1];
    assert!((glass.dissolve.unwrap() - 0.1).abs() < 1e-6 && glass.ior == Some(1.5));
    assert_eq!(m.warnings.len(), 1);
    assert!(m.warnings[0].contains("'red': texture red.png is not applied"));
    // The triangles are the same as without materials (each material's faces keep their own
    // copies of the vertices, as tobj splits the file there).
    let plain = load_mesh(&dir.join("scene.obj")).unwrap();
    assert!((0..5).all(|i| mesh.corners(i) == plain.corners(i)));

    // A library that is not there: a warning naming it; the faces have no material.
    std::fs::remove_file(dir.join("glass.mtl")).unwrap();
    let (_, m) = load_mesh_with_shading(&dir.join("scene.obj")).unwrap();
    assert_eq!(m.material_of, [Some(0), Some(0), None, None, Some(0)]);
    assert!(
        m.warnings
            .iter()
            .any(|w| w.contains("glass.mtl") && w.contains("left out")),
        "{:?}",
        m.warnings
    );
    // A malformed library likewise, and a gzipped OBJ finds its libraries beside it.
    std::fs::write(dir.join("glass.mtl"), "newmtl glass\nKd one two three\n").unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, TWO_LIBRARIES_OBJ.as_bytes()).unwrap();
    std::fs::write(dir.join("scene.obj.gz"), gz.finish().unwrap()).unwrap();
    let (mesh_gz, m) = load_mesh_with_shading(&dir.join("scene.obj.gz")).unwrap();
    assert!((0..5).all(|i| mesh_gz.corners(i) == plain.corners(i)));
    assert_eq!(m.material_of, [Some(0), Some(0), None, None, Some(0)]);
    assert!(
        m.warnings.iter().any(|w| w.contains("glass.mtl")),
        "{:?}",
        m.warnings
    );
    // One number for a colour stands for all three (MTL's short form); two are a warning
    // naming the line (tobj alone panicked on both).
    std::fs::write(dir.join("glass.mtl"), "newmtl glass\n  Kd 0.25\nKs 1\n").unwrap();
    let (_, m) = load_mesh_with_shading(&dir.join("scene.obj")).unwrap();
    assert_eq!(m.materials[1].diffuse, Some([0.25; 3]));
    assert_eq!(m.materials[1].specular, Some([1.0; 3]));
    std::fs::write(dir.join("glass.mtl"), "newmtl glass\nKd 0 0 0\nKs 1 2\n").unwrap();
    let (_, m) = load_mesh_with_shading(&dir.join("scene.obj")).unwrap();
    assert_eq!(m.material_of, [Some(0), Some(0), None, None, Some(0)]);
    assert!(
        m.warnings
            .iter()
            .any(|w| w.contains("glass.mtl: line 3: `Ks 1 2` needs one or three numbers")),
        "{:?}",
        m.warnings
    );
    // Other formats, and an OBJ without materials, have none (Spot has its texture
    // coordinates, a triangle's corners each).
    let (spot, m) = load_mesh_with_shading(&shared_mesh("spot.obj")).unwrap();
    assert_eq!(m.uvs.len(), spot.len());
    // Its first face is `f 739/1 735/2 736/3`.
    let vt = |u: f32, v: f32| Vec2::new(u, v);
    assert_eq!(
        m.uvs[0],
        [
            vt(0.800375, 0.667457),
            vt(0.789584, 0.668215),
            vt(0.799923, 0.663933)
        ]
    );
    assert_eq!(
        MeshShading {
            uvs: Vec::new(),
            ..m
        },
        MeshShading::default()
    );
    let (_, m) = load_mesh_with_shading(&shared_mesh("goblet_vase.stl")).unwrap();
    assert_eq!(m, MeshShading::default());
}

/// A cube with a normal per face (`vn`), as modelling tools write hard edges.
const HARD_CUBE_OBJ: &str =
    "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1
vn 0 0 -1\nvn 0 0 1\nvn -1 0 0\nvn 1 0 0\nvn 0 -1 0\nvn 0 2 0
f 1//1 4//1 3//1 2//1\nf 5//2 6//2 7//2 8//2\nf 1//3 5//3 8//3 4//3
f 2//4 3//4 7//4 6//4\nf 1//5 2//5 6//5 5//5\nf 4//6 8//6 7//6 3//6
";

/// Normals from the file: an OBJ's `vn` split its vertices where a position has several (a
/// hard-edged cube: 24 vertices, each with its face's unit normal), a PLY's nx ny nz are read;
/// normals of zero length stand in for the face average with a warning; the triangles are the
/// same as without normals; files without normals give none.
#[test]
fn file_normals_are_kept() {
    let scratch = scratch_dir("normals");
    let dir = scratch.path();
    std::fs::write(dir.join("cube.obj"), HARD_CUBE_OBJ).unwrap();
    let (mesh, s) = load_mesh_with_shading(&dir.join("cube.obj")).unwrap();
    // The same faces without their normals: 8 shared vertices.
    let bare: String = HARD_CUBE_OBJ
        .lines()
        .filter(|l| !l.starts_with("vn"))
        .map(|l| l.replace("//1", "").replace("//2", "").replace("//3", ""))
        .map(|l| l.replace("//4", "").replace("//5", "").replace("//6", "") + "\n")
        .collect();
    let plain = parse_str(&bare, MeshFormat::Obj).unwrap();
    assert_eq!((plain.positions.len(), mesh.positions.len()), (8, 24));
    assert_eq!(load_mesh(&dir.join("cube.obj")).unwrap(), mesh);
    assert_eq!(s.normals.len(), 24);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    for i in 0..mesh.len() {
        assert_eq!(mesh.corners(i), plain.corners(i));
        let [a, b, c] = mesh.corners(i);
        let face = (b - a).cross(c - a).normalize();
        for v in mesh.triangles[i] {
            assert!(
                (s.normals[v as usize] - face).length() < 1e-6,
                "triangle {i}"
            );
        }
    }
    // One face naming no normals: the file's normals are left out (tobj would make some up).
    let partial = HARD_CUBE_OBJ.replace("f 1//5 2//5 6//5 5//5", "f 1 2 6 5");
    std::fs::write(dir.join("partial.obj"), partial).unwrap();
    let (_, s) = load_mesh_with_shading(&dir.join("partial.obj")).unwrap();
    assert!(s.normals.is_empty() && s.warnings[0].starts_with("some faces name no normals"));
    // A PLY's normals, one of them zero: the face average stands in, with a warning.
    let ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
               property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
               element face 2\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0 0 0 3\n1 0 0 0.6 0 0.8\n1 1 0 0 0 0\n0 1 0 0 0 1\n3 0 1 2\n3 0 2 3\n";
    std::fs::write(dir.join("quad.ply"), ply).unwrap();
    let (_, s) = load_mesh_with_shading(&dir.join("quad.ply")).unwrap();
    assert_eq!(s.normals[0], Vec3::Z);
    assert!((s.normals[1] - Vec3::new(0.6, 0.0, 0.8)).length() < 1e-6);
    assert_eq!(s.normals[2], Vec3::Z, "averaged over its two faces");
    assert_eq!(s.warnings.len(), 1);
    assert!(
        s.warnings[0].starts_with("1 vertex normal is of zero length"),
        "{:?}",
        s.warnings
    );
    // Without normals in the file: none.
    for name in ["stanford_bunny.ply", "spot.obj", "goblet_vase.stl"] {
        let (_, s) = load_mesh_with_shading(&shared_mesh(name)).unwrap();
        assert!(s.normals.is_empty(), "{name}");
    }
}
