//! Bad input: a clear error naming the file and the problem, exit code 2, no panic.

mod common;
use common::*;

fn write(name: &str, bytes: &[u8]) -> String {
    let p = tmp(name);
    std::fs::write(&p, bytes).unwrap();
    p.to_string_lossy().into_owned()
}

fn assert_input_error(args: &[&str], file: &str, problem: &str) {
    let o = run(args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert!(
        err.contains(file),
        "{args:?}: error must name {file}: {err}"
    );
    assert!(
        err.contains(problem),
        "{args:?}: error must say '{problem}': {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn nan_coordinates() {
    let f = write("nan.obj", b"v 0 0 0\nv nan 1 0\nv 0 1 0\nf 1 2 3\n");
    for cmd in ["info", "render"] {
        assert_input_error(&[cmd, &f], "nan.obj", "NaN");
    }
}

#[test]
fn out_of_range_index() {
    let f = write("range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    assert_input_error(&["info", &f], "range.obj", "vertex");
}

#[test]
fn truncated_files() {
    let lucy = std::fs::read(mesh("stanford_lucy_100k.ply")).unwrap();
    let f = write("cut.ply", &lucy[..lucy.len() / 3]);
    assert_input_error(&["info", &f], "cut.ply", "PLY");
    let vase = std::fs::read(mesh("goblet_vase.stl")).unwrap();
    let f = write("cut.stl", &vase[..vase.len() - 100]);
    assert_input_error(&["info", &f], "cut.stl", "truncated");
    // A 3MF package cut short: its ZIP directory is gone.
    let whole = tmp("whole.3mf");
    let sphere = raystream_io::TriMesh::icosphere(2);
    raystream_io::write_mesh(&whole, &sphere, None).unwrap();
    let bytes = std::fs::read(&whole).unwrap();
    let f = write("cut.3mf", &bytes[..bytes.len() * 2 / 3]);
    for cmd in ["info", "render"] {
        assert_input_error(&[cmd, &f], "cut.3mf", "not a 3MF package");
    }
}

#[test]
fn empty_mesh() {
    let f = write("empty.obj", b"# nothing here\nv 0 0 0\n");
    assert_input_error(&["info", &f], "empty.obj", "no triangles");
}

#[test]
fn missing_and_unsupported_files() {
    assert_input_error(
        &["info", "no/such/mesh.ply"],
        "no/such/mesh.ply",
        "No such file",
    );
    let f = write("mesh.xyz", b"1 2 3\n");
    assert_input_error(&["info", &f], "mesh.xyz", "unsupported");
    // The reason is said once, not once more as the error's cause.
    for args in [
        &["info", "no/such/mesh.ply"][..],
        &["render", "no/such/mesh.ply", "--quiet"],
        &["info", "no/such/ct.nii"],
    ] {
        let e = stderr(&run(args));
        let reason = if e.contains("No such file") {
            "No such file"
        } else {
            "no such file"
        };
        assert_eq!(e.matches(reason).count(), 1, "{e}");
    }
}

#[test]
fn rays_file_of_wrong_size() {
    let rays = write("odd.rays", &[0u8; 33]);
    let out = tmp("odd.hits").to_string_lossy().into_owned();
    assert_input_error(
        &["trace", &mesh("spot.obj"), "--rays", &rays, "-o", &out],
        "odd.rays",
        "multiple of 32",
    );
}

#[test]
fn bad_scene_file() {
    let f = write("bad.toml", b"[[objects]]\nshape = \"dodecahedron\"\n");
    assert_input_error(
        &["render", &f, "-o", &tmp("x.png").to_string_lossy()],
        "bad.toml",
        "unknown shape",
    );
    let f = write("syntax.toml", b"[[objects]\n");
    assert_input_error(&["render", &f], "syntax.toml", "not a valid scene");
    let f = write("mat.toml", b"[materials.m]\nreflectivity = 0.8\ntransparency = 0.5\n[[objects]]\nshape = \"sphere\"\nmaterial = \"m\"\n");
    assert_input_error(&["render", &f], "mat.toml", "reflectivity");
}

/// Values a scene cannot be rendered with, each refused by name: light and background colours
/// below zero or infinite, a camera with no view or a field of view of 180° or more, objects
/// (or lights) pushed so far out that f32 triangle tests would overflow.
#[test]
fn scene_values_out_of_range() {
    let sphere = "[[objects]]\nshape = \"sphere\"\n";
    let cases: [(&str, &str, &str); 9] = [
        (
            "light-colour",
            "[[lights]]\nposition = [1, 2, 3]\ncolor = [1, -1, 1]\n",
            "light 0: color",
        ),
        (
            "light-far",
            "[[lights]]\nposition = [1, inf, 3]\n",
            "light 0: position",
        ),
        ("background", "background = [0.1, 0.1, -1]\n", "background"),
        ("ambient", "ambient = [nan, 0, 0]\n", "ambient"),
        (
            "eye-target",
            "[camera]\neye = [1, 1, 1]\ntarget = [1, 1, 1]\n",
            "must differ",
        ),
        (
            "up",
            "[camera]\neye = [0, 5, 0]\ntarget = [0, 0, 0]\n",
            "not along the view",
        ),
        (
            "fov",
            "[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 1e9\n",
            "fov",
        ),
        (
            "far-object",
            "[[objects]]\nshape = \"spot\"\nscale = 1e12\n",
            "beyond ±1e10",
        ),
        ("ground", "[ground]\nsize = -3\n", "ground: size"),
    ];
    for (name, text, problem) in cases {
        let body = if name == "far-object" {
            text.to_string()
        } else {
            format!("{text}{sphere}")
        };
        let f = write(&format!("range-{name}.toml"), body.as_bytes());
        assert_input_error(
            &["render", &f, "--size", "8x8"],
            &format!("range-{name}.toml"),
            problem,
        );
    }
}

/// Meshes and volumes so far from the origin that f32 triangle tests would overflow.
#[test]
fn coordinates_beyond_the_f32_range_of_the_tests() {
    let f = write("far.obj", b"v 0 0 0\nv 2e10 1 0\nv 0 1 0\nf 1 2 3\n");
    assert_input_error(&["info", &f], "far.obj", "beyond ±1e10");
    // Inside the limit, but the lights and floor placed around it would not be.
    let f = write(
        "near-limit.obj",
        b"v 9e9 0 0\nv 9.9e9 0 0\nv 9e9 5e9 0\nf 1 2 3\n",
    );
    assert_input_error(
        &["render", &f, "--size", "8x8"],
        "near-limit.obj",
        "placed a few times",
    );
}

/// A scene's volume: a truncated CT names the CT file; an unknown preset names the scene.
#[test]
fn bad_volume_in_a_scene() {
    let ct = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/abdomen_pelvis_ct_totalseg.nii.gz"),
    )
    .unwrap();
    write("cut_ct.nii.gz", &ct[..ct.len() / 2]);
    let f = write(
        "cut_ct.toml",
        b"[volume]\npath = \"cut_ct.nii.gz\"\n[[objects]]\nshape = \"sphere\"\n",
    );
    let out = tmp("x.png");
    assert_input_error(
        &["render", &f, "-o", &out.to_string_lossy()],
        "cut_ct.nii.gz",
        "NIfTI",
    );
    let f = write(
        "preset.toml",
        b"[volume]\npath = \"cut_ct.nii.gz\"\npreset = \"ct-teeth\"\n[[objects]]\nshape = \"sphere\"\n",
    );
    assert_input_error(&["render", &f], "preset.toml", "unknown preset 'ct-teeth'");
}

/// `render --device gpu` errors are clear: no matching adapter (naming what exists), and the
/// stack traversal, which only the CPU has.
#[test]
fn gpu_render_errors_are_clear() {
    let out = tmp("g.png");
    let o = run(&[
        "render",
        "--device",
        "gpu",
        "--adapter",
        "no-such-adapter-xyz",
        "-o",
        &out.to_string_lossy(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("no GPU adapter") && stderr(&o).contains("no-such-adapter-xyz")
            || stderr(&o).contains("driver"),
        "{}",
        stderr(&o)
    );
    if !gpu_available() {
        return;
    }
    let o = run(&[
        "render",
        "--device",
        "gpu",
        "--traversal",
        "stack",
        "--size",
        "16x16",
        "-o",
        &out.to_string_lossy(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--traversal ropes"), "{}", stderr(&o));
}

/// `render --mode`: wrong preset kind, a missing or bad transfer function, a mesh, a bad step.
#[test]
fn direct_volume_rendering_errors_are_clear() {
    let out = tmp("dvr.png");
    let out = out.to_string_lossy();
    let o = run(&["render", "--mode", "dvr", "--preset", "bone", "-o", &out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("ct-bone"), "{}", stderr(&o));
    let o = run(&[
        "render",
        "--mode",
        "dvr",
        "--tf",
        "no-such-tf.toml",
        "-o",
        &out,
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no-such-tf.toml"), "{}", stderr(&o));
    let f = write(
        "bad-tf.toml",
        b"opacity = [[0, 5]]\ncolor = [[0, 1, 1, 1]]\n",
    );
    let o = run(&["render", "--mode", "dvr", "--tf", &f, "-o", &out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("bad-tf.toml"), "{}", stderr(&o));
    let o = run(&["render", &mesh("spot.obj"), "--mode", "mip", "-o", &out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("spot.obj"), "{}", stderr(&o));
    let o = run(&["render", "--mode", "dvr", "--step", "0", "-o", &out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--step"), "{}", stderr(&o));
    let o = run(&["render", "--step", "1", "-o", &out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--mode"), "{}", stderr(&o));
}

/// A report printed into a pipe that has closed (`raystream info MESH | head -1`) ends the
/// process quietly, as Unix tools do: no panic (Rust's std ignores SIGPIPE, and `println!`
/// panicked on the broken pipe).
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_the_report_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let mut child = bin()
        .args(["info", &mesh("stanford_bunny.ply")])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Closed before the mesh is read and its report printed.
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = stderr(&o);
    assert!(!err.contains("panicked"), "{err}");
    // Ended by SIGPIPE (13 on Linux, the BSDs and macOS).
    assert_eq!(o.status.signal(), Some(13), "{:?}", o.status);
}

#[test]
fn segment_statistics_refuse_what_is_no_segmentation() {
    let ct = shared()
        .join("data/volumes/nifti/abdomen_pelvis_ct_totalseg.nii.gz")
        .to_string_lossy()
        .into_owned();
    let bunny = shared()
        .join("data/meshes/stanford_bunny.ply")
        .to_string_lossy()
        .into_owned();
    // A CT is no label map.
    refused(
        &["info", &ct, "--segmentation", &ct],
        "--segmentation takes a label map (whole numbers from 0); it holds",
    );
    // A mesh has no values to take.
    refused(&["info", &bunny, "--segmentation", &ct], "is not a volume");
    // A label map far from the CT: no segment holds a voxel of it.
    let far = tmp("far-labels.nii");
    let mut v = raystream_io::Volume::hounsfield([3, 3, 3], [1.0; 3], vec![0.0; 27]);
    v.origin = [1e4, 0.0, 0.0];
    raystream_io::write_label_map(&far, &v, &[1; 27], "far away").unwrap();
    refused(
        &["info", &ct, "--segmentation", far.to_str().unwrap()],
        "far-labels.nii: no segment holds a voxel of",
    );
}

/// `render CT --mode dvr --segmentation LABELS`: a label the GPU's 16-bit label texture cannot
/// hold, and a label map that lies nowhere near the CT, are refused, naming the file.
#[test]
fn segment_colours_refuse_what_they_cannot_draw() {
    // A 4×4×4 CT of bone and its label map on the same grid (MetaImage, 32-bit integers).
    let mha = |name: &str, kind: &str, bytes: Vec<u8>| {
        let path = tmp(name);
        let mut file = format!(
            "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\nElementSpacing = 1 1 1\nOffset = 0 0 0\nElementType = {kind}\nElementByteOrderMSB = False\nElementDataFile = LOCAL\n"
        )
        .into_bytes();
        file.extend(bytes);
        std::fs::write(&path, file).unwrap();
        path.to_string_lossy().into_owned()
    };
    let ct = mha(
        "paint-ct.mha",
        "MET_SHORT",
        [1000i16; 64].iter().flat_map(|v| v.to_le_bytes()).collect(),
    );
    let labels = mha(
        "paint-big.mha",
        "MET_INT",
        [70000i32; 64]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect(),
    );
    refused(
        &[
            "render",
            &ct,
            "--mode",
            "dvr",
            "--segmentation",
            &labels,
            "-o",
            "x.png",
        ],
        "paint-big.mha: label 70000: labels above 65535 are not rendered in colour",
    );
    let far = tmp("paint-far.nii");
    let mut v = raystream_io::Volume::hounsfield([3, 3, 3], [1.0; 3], vec![0.0; 27]);
    v.origin = [1e4, 0.0, 0.0];
    raystream_io::write_label_map(&far, &v, &[1; 27], "far away").unwrap();
    refused(
        &[
            "render",
            &ct,
            "--mode",
            "iso",
            "--segmentation",
            far.to_str().unwrap(),
            "-o",
            "x.png",
        ],
        "paint-far.nii: no segment holds a voxel of",
    );
}

/// A frame whose file cannot be written (its name taken by a folder) stops a series with an
/// error naming that file, though frames are saved on a thread of their own while the next one
/// renders; an animation that cannot be created is named likewise.
#[test]
fn a_frame_that_cannot_be_written_stops_the_series() {
    let dir = tmp("unwritable-frames");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("frame_001.png")).unwrap();
    let args = [
        "render", "--device", "cpu", "--mode", "slice", "--slices", "4", "--size", "32x32", "-q",
    ];
    refused(
        &[&args[..], &["-o", dir.to_str().unwrap()]].concat(),
        "frame_001.png: cannot write PNG",
    );
    let anim = tmp("unwritable-frames/sub");
    std::fs::create_dir_all(&anim).unwrap();
    let gif = anim.join("spin.gif");
    std::fs::create_dir_all(&gif).unwrap();
    let e = refused(
        &[&args[..], &["--format", "gif", "-o", gif.to_str().unwrap()]].concat(),
        "spin.gif",
    );
    assert!(e.contains("cannot create"), "{e}");
}

/// `--body-only` finds a CT's body by its HU: refused, naming the file, for a mesh, a volume
/// not in HU, a CT with no tissue, and one whose tissue is all thinner than the ball.
#[test]
fn body_only_refuses_what_has_no_body() {
    let out = tmp("body.png");
    let out = out.to_string_lossy();
    let teapot = mesh("utah_teapot.obj");
    assert_input_error(
        &["render", &teapot, "--body-only", "-o", &out],
        "utah_teapot.obj",
        "a mesh or a scene file has none to find",
    );
    let bonsai = shared().join("data/volumes/nifti/scivis_bonsai.nii.gz");
    let bonsai = bonsai.to_str().unwrap();
    for args in [
        &["render", bonsai, "--mode", "mip"][..],
        &["render", bonsai],
        &["iso", bonsai],
    ] {
        let args = [args, &["--body-only", "-o", &out]].concat();
        assert_input_error(
            &args,
            "scivis_bonsai.nii.gz",
            "this volume's values are not HU",
        );
    }
    // A scene file's [volume] too.
    let scene = write(
        "body-bonsai.toml",
        format!("[volume]\npath = {bonsai:?}\nbody_only = true\n[[objects]]\nshape = \"sphere\"\n")
            .as_bytes(),
    );
    assert_input_error(
        &["render", &scene, "-o", &out],
        "scivis_bonsai.nii.gz",
        "body_only finds the body by its HU",
    );
    // `info --body` likewise, and its files named for no form they write, or not from a
    // series a DICOM Segmentation or RT Structure Set could reference.
    assert_input_error(
        &["info", &teapot, "--body"],
        "utah_teapot.obj",
        "--body finds the patient's body in a CT volume",
    );
    assert_input_error(
        &["info", bonsai, "--body"],
        "scivis_bonsai.nii.gz",
        "--body finds the body by its HU",
    );
    let builtin = repo().join("crates/raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    let builtin = builtin.to_str().unwrap();
    let png = tmp("body-mask.png");
    assert_input_error(
        &["info", builtin, "--body", "--mask", png.to_str().unwrap()],
        "body-mask.png",
        "--mask writes a NIfTI label map (.nii or .nii.gz)",
    );
    let dcm = tmp("body-rt.dcm");
    assert_input_error(
        &[
            "info",
            builtin,
            "--body",
            "--structures",
            dcm.to_str().unwrap(),
        ],
        "body-rt.dcm",
        "--structures",
    );
    assert!(!dcm.exists());
    let o = run(&["info", builtin, "--mask", png.to_str().unwrap()]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "--mask without --body: {}",
        stderr(&o)
    );
    let like = raystream_io::Volume::hounsfield([24, 24, 24], [1.0; 3], Vec::new());
    let air = write_like("body-air.mha", &like, &vec![-1000.0; 24 * 24 * 24]);
    let air = air.to_str().unwrap();
    assert_input_error(
        &["render", air, "--mode", "dvr", "--body-only", "-o", &out],
        "body-air.mha",
        "--body-only: no voxel above -500 HU",
    );
    // A sheet 3 mm thick.
    let sheet: Vec<f32> = (0..24 * 24 * 24)
        .map(|n| {
            if (10..13).contains(&(n / 576)) {
                40.0
            } else {
                -1000.0
            }
        })
        .collect();
    let sheet = write_like("body-sheet.mha", &like, &sheet);
    let stl = tmp("body.stl");
    assert_input_error(
        &[
            "iso",
            sheet.to_str().unwrap(),
            "--body-only",
            "-o",
            stl.to_str().unwrap(),
        ],
        "body-sheet.mha",
        "nothing above -500 HU is thicker than 8 mm",
    );
    // A cine reads its phases one by one.
    let o = run(&[
        "render",
        "--mode",
        "mip",
        "--cine",
        "--body-only",
        "-o",
        &out,
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--cine"), "{}", stderr(&o));
}
