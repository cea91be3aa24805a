//! Helpers for the command-line tests: run the built binary, find the shared data and the
//! Python tools (rays.py with Embree).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_raystream"))
}

pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("raystream runs")
}

/// Runs `raystream ARGS -o OUT` with environment variable `var` set to `value` (left unset
/// with `None`): its output, and the bytes OUT holds afterwards (none where it wrote none).
pub fn run_with_env(
    var: &str,
    value: Option<&str>,
    args: &[&str],
    out: &Path,
) -> (Output, Vec<u8>) {
    let mut cmd = bin();
    if let Some(v) = value {
        cmd.env(var, v);
    }
    let o = cmd
        .args(args)
        .arg("-o")
        .arg(out)
        .output()
        .expect("raystream runs");
    (o, std::fs::read(out).unwrap_or_default())
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

pub fn shared() -> PathBuf {
    repo().join("../shared")
}

/// The chest CT of `../shared`, with its stented descending aorta.
pub fn chest() -> String {
    shared()
        .join("data/volumes/nifti/chest_ct_stents_totalseg.nii.gz")
        .to_string_lossy()
        .into_owned()
}

/// `render`'s arguments for the HU on the curved plane along `path` through `vol` (a CPR,
/// `--mode slice --path`), then `more`.
pub fn cpr_args<'a>(vol: &'a str, path: &'a str, more: &[&'a str]) -> Vec<&'a str> {
    [&[vol, "--mode", "slice", "--path", path][..], more].concat()
}

/// The hand-made path down that aorta (the contrast lumen's centroids, smoothed).
pub fn aorta() -> String {
    repo()
        .join("examples/chest_aorta.mrk.json")
        .to_string_lossy()
        .into_owned()
}

pub fn mesh(name: &str) -> String {
    shared()
        .join("data/meshes")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

/// The CT the CLI embeds as its default (the repository's copy of it).
pub fn builtin_ct() -> String {
    repo()
        .join("crates/raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz")
        .to_str()
        .unwrap()
        .to_string()
}

pub fn tmp(name: &str) -> PathBuf {
    let dir = repo().join("target/test-tmp");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `render --quiet --device DEV ARGS -o NAME` (NAME under the test folder), which must succeed;
/// the output's path.
pub fn render_to(name: &str, dev: &str, args: &[&str]) -> PathBuf {
    let out = tmp(name);
    let mut all = vec!["render", "--quiet", "--device", dev];
    all.extend_from_slice(args);
    all.extend_from_slice(&["-o", out.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{all:?}: {}", stderr(&o));
    out
}

/// Runs `args`, which must be refused as bad input: exit status 2, `want` in the error, no
/// panic. The error.
pub fn refused(args: &[&str], want: &str) -> String {
    let o = run(args);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
    assert!(e.contains(want), "{args:?}: {e}");
    assert!(!e.contains("panicked"), "{e}");
    e
}

/// The pixel size (mm) an EXR's comments give ("… pixels 0.5 mm …").
pub fn exr_pixel_mm(exr: &Path) -> f64 {
    let comments = raystream_cpu::load_exr(exr).unwrap().comments;
    comments
        .split("pixels ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no pixel size in {comments:?}"))
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The Python that has rays.py's requirements: `$RAYSTREAM_PYTHON`, else the repo's `.venv`.
/// Without one the Embree checks skip, except under CI (`CI=true`), where they fail.
pub fn python() -> Option<PathBuf> {
    let p = std::env::var_os("RAYSTREAM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv/bin/python"));
    if p.exists() {
        return Some(p);
    }
    if in_ci() {
        panic!(
            "CI=true but no Python with rays.py's requirements at {} (set RAYSTREAM_PYTHON)",
            p.display()
        );
    }
    eprintln!(
        "skipping: no Python with rays.py's requirements at {}",
        p.display()
    );
    None
}

/// A Python that imports `module`, or `None` (a skip, except under CI, where it fails).
pub fn python_with(module: &str) -> Option<PathBuf> {
    let py = python()?;
    let has = Command::new(&py)
        .args(["-c", &format!("import {module}")])
        .status()
        .unwrap()
        .success();
    if !has {
        if in_ci() {
            panic!("CI=true but {module} is not installed in {}", py.display());
        }
        eprintln!("skipping: {module} is not installed in {}", py.display());
        return None;
    }
    Some(py)
}

pub fn rays_py(python: &Path, args: &[&str]) -> Output {
    Command::new(python)
        .arg(shared().join("tools/rays.py"))
        .args(args)
        .output()
        .expect("rays.py runs")
}

/// `rays.py gen MESH --kind KIND --size SIZE -o RAYS`.
pub fn gen_rays(python: &Path, mesh: &str, kind: &str, size: &str, rays: &Path) {
    let g = rays_py(
        python,
        &[
            "gen",
            mesh,
            "--kind",
            kind,
            "--size",
            size,
            "-o",
            rays.to_str().unwrap(),
        ],
    );
    assert!(
        g.status.success(),
        "rays.py gen {mesh} {kind}: {}",
        stderr(&g)
    );
}

/// `raystream trace MESH --rays RAYS -o HITS [--any] EXTRA… -q`, which must succeed.
pub fn trace_to(mesh: &str, rays: &Path, hits: &Path, any: bool, extra: &[&str]) {
    let mut args = vec![
        "trace",
        mesh,
        "--rays",
        rays.to_str().unwrap(),
        "-o",
        hits.to_str().unwrap(),
        "-q",
    ];
    if any {
        args.push("--any");
    }
    args.extend_from_slice(extra);
    let o = run(&args);
    assert!(o.status.success(), "trace {mesh} {extra:?}: {}", stderr(&o));
}

/// `rays.py check` of HITS against Embree (with the t floor rays.py advises for small sets);
/// panics with its report unless it ends in PASS.
pub fn embree_check(python: &Path, mesh: &str, rays: &Path, hits: &Path, any: bool, what: &str) {
    let mut check = vec![
        "check",
        mesh,
        rays.to_str().unwrap(),
        hits.to_str().unwrap(),
        "--t-floor",
        "1e-4",
    ];
    if any {
        check.push("--any");
    }
    let c = rays_py(python, &check);
    let out = stdout(&c);
    assert!(
        c.status.success() && out.lines().last().is_some_and(|l| l.starts_with("PASS")),
        "{what}: {out}{}",
        stderr(&c)
    );
}

/// `raystream trace --device gpu` of one ray at spot.obj (files `NAME.rays`, `NAME.hits`), with
/// `extra` arguments: a probe of the GPU path.
pub fn gpu_probe(name: &str, extra: &[&str]) -> Output {
    let probe = tmp(&format!("{name}.rays"));
    std::fs::write(
        &probe,
        f32s(&[0.0, 0.0, 5.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY]),
    )
    .unwrap();
    let hits = tmp(&format!("{name}.hits"));
    let mesh = mesh("spot.obj");
    let mut args = vec![
        "trace",
        &mesh,
        "--rays",
        probe.to_str().unwrap(),
        "-o",
        hits.to_str().unwrap(),
        "--device",
        "gpu",
    ];
    args.extend(extra);
    run(&args)
}

/// Whether `--device gpu` can open an adapter here; under CI it must (lavapipe at least).
pub fn gpu_available() -> bool {
    let o = gpu_probe("probe", &["-q"]);
    if o.status.success() {
        return true;
    }
    if in_ci() {
        panic!("CI=true but --device gpu fails: {}", stderr(&o));
    }
    eprintln!("skipping GPU test: {}", stderr(&o));
    false
}

/// The devices a test compares: the CPU, and the GPU when one is found (always under CI).
pub fn devices() -> &'static [&'static str] {
    if gpu_available() {
        &["cpu", "gpu"]
    } else {
        &["cpu"]
    }
}

/// Under CI (`CI=true`): the GPU is lavapipe, which has subgroups, and Python with rays.py's
/// requirements is installed; nothing that needs them may skip.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// What DCMTK's `dsrdump` finds wrong in the Structured Report `file` (its content tree
/// against the IOD's relationship constraints, its items' values): its errors and warnings, and
/// its failure to read it; none where dsrdump is missing, outside CI. Its one warning on every
/// UTF-8 file, that its VR checker does not know the character set, is left out.
pub fn sr_errors(file: &Path) -> Vec<String> {
    match Command::new("dsrdump").arg(file).output() {
        Ok(o) => {
            let mut e: Vec<String> = stderr(&o)
                .lines()
                .filter(|l| {
                    (l.starts_with("E:") || l.starts_with("W:") || l.starts_with("F:"))
                        && !l.contains("does not support this Specific Character Set")
                })
                .map(str::to_string)
                .collect();
            if !o.status.success() {
                e.push(format!("dsrdump failed: {}", o.status));
            }
            e
        }
        Err(_) if in_ci() => panic!("CI=true but no dsrdump (Debian's dcmtk)"),
        Err(_) => {
            eprintln!("skipping dsrdump: not installed (Debian's dcmtk)");
            Vec::new()
        }
    }
}

/// Little-endian bytes of `v`.
pub fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A DICOM file's text element, trimmed (its padding and spaces).
pub fn dicom_text(obj: &dicom_object::DefaultDicomObject, tag: dicom_object::Tag) -> String {
    obj.element(tag)
        .unwrap()
        .to_str()
        .unwrap()
        .trim()
        .to_string()
}

/// The chest CT written as a DICOM series (CT Image Storage, one file a slice, through
/// raystream-io's writer) into the empty folder `dir`: its HU, its geometry, and a study of a
/// patient with a name beyond ASCII. The series' study.
pub fn chest_series(dir: &Path) -> raystream_io::DicomStudy {
    use raystream_io::{CaptureInfo, CapturePixels, ImagePlane, write_secondary_capture};
    std::fs::remove_dir_all(dir).ok();
    std::fs::create_dir_all(dir).unwrap();
    let select = raystream_io::VolumeSelect::default();
    let ct = raystream_io::load_volume(Path::new(&chest()), &select).unwrap();
    let study = raystream_io::DicomStudy {
        patient_name: "MÜLLER^JÖRG".into(),
        patient_id: "RS-0042".into(),
        study_uid: raystream_io::new_uid(),
        study_date: "20261202".into(),
        accession_number: "ACC42".into(),
        frame_of_reference_uid: raystream_io::new_uid(),
        ..Default::default()
    };
    let series = raystream_io::new_uid();
    let [nx, ny, nz] = ct.dims;
    let d = ct.direction;
    assert_eq!(ct.spacing[0], ct.spacing[1], "square pixels");
    for k in 0..nz {
        let p = ct.index_to_world(raystream_math::DVec3::new(0.0, 0.0, k as f64));
        let info = CaptureInfo {
            study: Some(&study),
            series: Some((&series, k as u32 + 1)),
            description: "chest CT",
            plane: Some(ImagePlane {
                position: p.to_array(),
                row: [d[0][0], d[1][0], d[2][0]],
                column: [d[0][1], d[1][1], d[2][1]],
                spacing: ct.spacing[0],
                thickness: Some(ct.spacing[2]),
            }),
            ..Default::default()
        };
        let pixels = CapturePixels::Hu {
            values: &ct.data[k * nx * ny..(k + 1) * nx * ny],
            window: (400.0, 40.0),
        };
        let file = dir.join(format!("{:04}.dcm", k + 1));
        write_secondary_capture(&file, pixels, (nx as u32, ny as u32), &info).unwrap();
    }
    study
}

/// dicom3tools' `dciodvfy` on `file`: the errors it finds against the standard's IOD for the
/// file's SOP class (its warnings aside). Where it is not installed, none, and a note; under
/// CI (`CI=true`) that fails.
/// What highdicom (an independent reader) finds in a DICOM Structured Report
/// (tests/highdicom_sr.py read): its SOP class, study, devices and measurement groups; none
/// where Python has no highdicom.
pub fn highdicom_report(sr: &Path) -> Option<serde_json::Value> {
    let py = python_with("highdicom")?;
    let o = Command::new(&py)
        .arg(repo().join("crates/raystream/tests/highdicom_sr.py"))
        .arg("read")
        .arg(sr)
        .output()
        .unwrap();
    assert!(o.status.success(), "highdicom: {}", stderr(&o));
    Some(serde_json::from_str(&stdout(&o)).unwrap())
}

/// A numeric measurement as `info --json` reads it from a structured report: its concept's
/// code, value, unit's code and, where coded, derivation and method.
pub fn sr_measurement(
    concept: &str,
    value: f64,
    unit: &str,
    derivation: Option<&str>,
    method: Option<&str>,
) -> serde_json::Value {
    serde_json::json!({"concept": concept, "value": value, "unit": unit, "derivation": derivation, "method": method})
}

/// `measure --report SR`'s JSON line (`reported`) names `sr` with `want`'s groups and
/// measurements; and where highdicom is installed it reads from `sr` a Comprehensive 3D SR of
/// study `study_uid` by "raystream measure" whose groups are `want`, one for one.
pub fn check_report(
    reported: &serde_json::Value,
    sr: &Path,
    study_uid: &str,
    want: &[serde_json::Value],
) {
    let count: usize = want
        .iter()
        .map(|g| g["measurements"].as_array().unwrap().len())
        .sum();
    assert_eq!(
        *reported,
        serde_json::json!({"file": sr.to_str().unwrap(), "format": "dicom-sr", "groups": want.len(), "measurements": count})
    );
    if let Some(got) = highdicom_report(sr) {
        assert_eq!(got["sop_class"], raystream_io::COMPREHENSIVE_3D_SR);
        assert_eq!(got["study"], study_uid);
        assert_eq!(got["devices"], serde_json::json!(["raystream measure"]));
        let got = got["groups"].as_array().unwrap();
        assert_eq!(got.len(), want.len(), "{got:?}");
        for (g, w) in got.iter().zip(want) {
            assert_eq!(g, w);
        }
    }
}

/// The report groups (as [`highdicom_report`] gives them) that `measure --mask SEG.dcm
/// --report` writes for the lumen's and the wall's segments of the series in `series_dir`:
/// each its volume from `mask` (the JSON report's), the Segmentation and segment referenced.
/// `wall`: the wall segment's label and finding code.
pub fn segment_groups_want(
    seg: &Path,
    series_dir: &Path,
    mask: &serde_json::Value,
    (wall, wall_finding): (&str, &str),
) -> Vec<serde_json::Value> {
    use dicom_dictionary_std::tags;
    let seg_uid = dicom_text(
        &dicom_object::open_file(seg).unwrap(),
        tags::SOP_INSTANCE_UID,
    );
    let ct = dicom_object::open_file(series_dir.join("0001.dcm")).unwrap();
    let ct_series = dicom_text(&ct, tags::SERIES_INSTANCE_UID);
    [
        (1, "Lumen", "91747007", "lumen_ml"),
        (2, wall, wall_finding, "wall_ml"),
    ]
    .into_iter()
    .map(|(n, label, finding, ml)| {
        serde_json::json!({
                "template": "1411", "tracking_id": label, "finding": finding,
                "segmentation": seg_uid, "segment": [n], "source_series": ct_series,
                "measurements": [{"concept": "118565006", "value": mask[ml].as_f64().unwrap(),
                    "unit": "ml", "derivation": null, "method": null}]})
    })
    .collect()
}

pub fn iod_errors(file: &Path) -> Vec<String> {
    // dciodvfy cannot read a deflated data set (it says "Dicom dataset read failed"): DCMTK's
    // dcmconv writes it out inflated first.
    let inflated = tmp(&format!(
        "inflated-{}",
        file.file_name().unwrap().to_string_lossy()
    ));
    let deflated = dicom_object::open_file(file)
        .is_ok_and(|o| o.meta().transfer_syntax() == "1.2.840.10008.1.2.1.99");
    let file = if deflated {
        match Command::new("dcmconv")
            .arg("+te")
            .arg(file)
            .arg(&inflated)
            .output()
        {
            Ok(o) => {
                assert!(o.status.success(), "dcmconv: {}", stderr(&o));
                inflated.as_path()
            }
            Err(_) if in_ci() => panic!("CI=true but no dcmconv (Debian's dcmtk)"),
            Err(_) => {
                eprintln!("skipping dciodvfy of a deflated file: no dcmconv (Debian's dcmtk)");
                return Vec::new();
            }
        }
    } else {
        file
    };
    match Command::new("dciodvfy").arg(file).output() {
        Ok(o) => format!("{}{}", stdout(&o), stderr(&o))
            .lines()
            .filter(|l| l.starts_with("Error"))
            .map(str::to_string)
            .collect(),
        Err(_) if in_ci() => panic!("CI=true but no dciodvfy (Debian's dicom3tools)"),
        Err(_) => {
            eprintln!("skipping dciodvfy: not installed (Debian's dicom3tools)");
            Vec::new()
        }
    }
}

/// `data` (one value a voxel of `like`) written as a MetaImage on `like`'s grid under the test
/// folder.
pub fn write_like(name: &str, like: &raystream_io::Volume, data: &[f32]) -> std::path::PathBuf {
    let [nx, ny, nz] = like.dims;
    let ([sx, sy, sz], [ox, oy, oz], d) = (like.spacing, like.origin, like.direction);
    // TransformMatrix: the i axis' direction, then j's, then k's.
    let axes: Vec<String> = (0..3)
        .flat_map(|c| (0..3).map(move |r| d[r][c].to_string()))
        .collect();
    let mut bytes = format!(
        "ObjectType = Image\nNDims = 3\nDimSize = {nx} {ny} {nz}\nElementSpacing = {sx} {sy} {sz}\nOffset = {ox} {oy} {oz}\nTransformMatrix = {}\nElementType = MET_FLOAT\nElementByteOrderMSB = False\nElementDataFile = LOCAL\n",
        axes.join(" ")
    )
    .into_bytes();
    bytes.extend(data.iter().flat_map(|v| v.to_le_bytes()));
    let path = tmp(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Whether every edge of `mesh` joins two triangles that cross it opposite ways: the surface
/// is closed, a 2-manifold (no edge where two sheets pinch together, which a 3D printer's
/// slicer refuses), and its triangles turn one way.
pub fn closed_and_oriented(mesh: &raystream_io::TriMesh) -> bool {
    // Each edge's uses from its lesser end and from its greater: one each, exactly (an edge
    // two sheets pinch together has two each, which a signed sum alone would let through).
    let mut edges: std::collections::HashMap<(u32, u32), [u32; 2]> = Default::default();
    for t in &mesh.triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default()[usize::from(a > b)] += 1;
        }
    }
    edges.values().all(|&n| n == [1, 1])
}
