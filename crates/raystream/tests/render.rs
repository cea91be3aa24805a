//! `raystream render`, `info` and `bench` end to end: golden images (small, with tolerance),
//! the JSON of `info`, and `bench` lines.
//!
//! Golden images live in tests/golden/. On a mismatch the test writes `NAME-actual.png` and
//! `NAME-diff.png` (largest channel difference ×8) next to the temporary files and fails;
//! `UPDATE_GOLDEN=1 cargo test` rewrites the baselines (only on purpose).

mod common;
use std::path::Path;

use common::*;

fn golden(name: &str, args: &[&str]) {
    // Tests run in parallel and two may compare with the same baseline: name outputs by args.
    let tag = format!(
        "{name}-{:016x}",
        args.join(" ")
            .bytes()
            .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64)
                .wrapping_mul(0x100_0000_01b3))
    );
    let out = tmp(&format!("{tag}.png"));
    let mut all = vec!["render"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["-o", out.to_str().unwrap(), "--quiet", "--device", "cpu"]);
    let o = run(&all);
    assert!(o.status.success(), "{name}: {}", stderr(&o));
    let golden = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(format!("{name}.png"));
    if std::env::var("UPDATE_GOLDEN").is_ok_and(|v| v == "1") {
        std::fs::copy(&out, &golden).unwrap();
        return;
    }
    let actual = image::open(&out).unwrap().to_rgb8();
    let expected = image::open(&golden)
        .unwrap_or_else(|e| panic!("{}: {e}", golden.display()))
        .to_rgb8();
    assert_eq!(actual.dimensions(), expected.dimensions());
    let mut diffs: Vec<u8> = actual
        .pixels()
        .zip(expected.pixels())
        .map(|(a, b)| (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap())
        .collect();
    let mean = diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64;
    let diff_img = image::GrayImage::from_raw(
        actual.width(),
        actual.height(),
        diffs.iter().map(|d| d.saturating_mul(8)).collect(),
    )
    .unwrap();
    diffs.sort_unstable();
    let p99 = diffs[diffs.len() * 99 / 100];
    if mean > 0.5 || p99 > 2 {
        actual.save(tmp(&format!("{tag}-actual.png"))).unwrap();
        diff_img.save(tmp(&format!("{tag}-diff.png"))).unwrap();
        panic!(
            "{name}: differs from its golden image: mean {mean:.3}/255, p99 {p99}/255 (see {}-actual.png, -diff.png)",
            tmp(&tag).display()
        );
    }
    // A golden image must show something: not one flat colour.
    let lum: Vec<f64> = expected
        .pixels()
        .map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>() / 3.0)
        .collect();
    let m = lum.iter().sum::<f64>() / lum.len() as f64;
    let sd = (lum.iter().map(|l| (l - m).powi(2)).sum::<f64>() / lum.len() as f64).sqrt();
    assert!(
        sd > 10.0,
        "{name}: golden image is nearly flat (std {sd:.1})"
    );
}

#[test]
fn golden_default_scene() {
    // The built-in abdomen CT's bones.
    golden(
        "default",
        &["--size", "96x64", "--spp", "2", "--max-depth", "4"],
    );
}

fn spot_scene() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/scenes/spot.toml")
        .to_str()
        .unwrap()
        .to_string()
}

#[test]
fn golden_spot_scene() {
    // Spot between a glass and a mirror sphere: refraction, reflection, shadows.
    golden(
        "spot",
        &[
            &spot_scene(),
            "--size",
            "96x64",
            "--spp",
            "2",
            "--max-depth",
            "4",
        ],
    );
}

#[test]
fn golden_mesh_alone() {
    golden(
        "bunny",
        &[
            &mesh("stanford_bunny.ply"),
            "--size",
            "80x64",
            "--spp",
            "1",
            "--max-depth",
            "2",
        ],
    );
}

#[test]
fn golden_scene_file() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/teapot_glass.toml");
    golden(
        "teapot_glass",
        &[
            scene.to_str().unwrap(),
            "--size",
            "96x72",
            "--spp",
            "1",
            "--max-depth",
            "5",
        ],
    );
}

#[test]
fn golden_median_builder_and_stack_traversal_match_default() {
    // Same image as golden_spot_scene through the other builder and traversal.
    golden(
        "spot",
        &[
            &spot_scene(),
            "--size",
            "96x64",
            "--spp",
            "2",
            "--max-depth",
            "4",
            "--builder",
            "median",
            "--traversal",
            "stack",
        ],
    );
}

/// `info MESH` measures the surface as trimesh does (an independent implementation, its
/// corners merged by position as `info` merges them): area and, where it closes, volume (to
/// 10⁻⁶: trimesh reads an OBJ's text in f64, raystream in f32), its pieces joined through edges, Euler characteristic, vertices, edges, the edges of
/// one triangle and of more than two, and its holes, on every mesh in ../shared/data/meshes
/// (the bunny and the teapot open, the teapot in four pieces), the built-in CT's bones as an
/// STL (each triangle its own corners; thousands of pieces, closed: `iso` says the volume
/// they enclose), a cube with a face wound
/// the wrong way and two cubes meeting along an edge. `closed` is trimesh's watertight and
/// wound one way.
#[test]
fn info_measures_a_surface_as_trimesh_does() {
    let bones = tmp("surface-bones.stl");
    let o = run(&["iso", &builtin_ct(), "-o", bones.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = stderr(&o);
    let iso_ml: f64 = (said
        .split_once("enclosing ")
        .and_then(|(_, r)| r.split_once(" ml")))
    .unwrap_or_else(|| panic!("no volume in {said}"))
    .0
    .parse()
    .unwrap();
    let cube = |at: [i32; 3], flip: bool| {
        let mut obj = String::new();
        for i in 0..8 {
            let c = [i & 1, i >> 1 & 1, i >> 2 & 1];
            obj += &format!("v {} {} {}\n", c[0] + at[0], c[1] + at[1], c[2] + at[2]);
        }
        obj + &format!(
            "f 1 3 4 2\nf {}\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n",
            if flip { "5 7 8 6" } else { "5 6 8 7" }
        )
    };
    let flipped = tmp("surface-flipped.obj");
    std::fs::write(&flipped, cube([0; 3], true)).unwrap();
    let touching = tmp("surface-touching.obj");
    let two = cube([0; 3], false);
    let second = cube([1, 1, 0], false);
    let renumbered: String = (second.lines())
        .map(|l| match l.strip_prefix("f ") {
            Some(f) => {
                let f: Vec<String> = (f.split(' '))
                    .map(|v| (v.parse::<u32>().unwrap() + 8).to_string())
                    .collect();
                format!("f {}\n", f.join(" "))
            }
            None => format!("{l}\n"),
        })
        .collect();
    std::fs::write(&touching, two + &renumbered).unwrap();
    let mut files: Vec<String> = std::fs::read_dir(shared().join("data/meshes"))
        .unwrap()
        .map(|e| e.unwrap().path().to_string_lossy().into_owned())
        .filter(|p| raystream_io::is_mesh_path(Path::new(p)))
        .collect();
    files.sort();
    assert!(files.len() >= 6, "{files:?}");
    for f in [&bones, &flipped, &touching] {
        files.push(f.to_string_lossy().into_owned());
    }
    let mine: Vec<serde_json::Value> = (files.iter())
        .map(|f| {
            let o = run(&["info", f, "--json"]);
            assert!(o.status.success(), "{f}: {}", stderr(&o));
            let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
            j["surface"].clone()
        })
        .collect();
    let by_name = |name: &str| &mine[files.iter().position(|f| f.ends_with(name)).unwrap()];
    // What the fixtures are, whatever trimesh says.
    assert_eq!(by_name("utah_teapot.obj")["shells"], 4);
    assert_eq!(by_name("stanford_bunny.ply")["holes"], 5);
    assert_eq!(by_name("surface-flipped.obj")["misoriented_edges"], 4);
    assert_eq!(by_name("surface-touching.obj")["non_manifold_edges"], 1);
    assert_eq!(by_name("surface-touching.obj")["volume"], 2.0);
    assert_eq!(by_name("surface-bones.stl")["closed"], true);
    assert!(by_name("surface-bones.stl")["shells"].as_u64().unwrap() > 100);
    // `iso` says what the bones enclose, to its tenth of a millilitre.
    let ml = by_name("surface-bones.stl")["volume"].as_f64().unwrap() / 1000.0;
    assert!(
        (iso_ml - ml).abs() <= 0.05 + 1e-9,
        "{iso_ml} ml against {ml}"
    );
    assert!(ml > 100.0, "{ml}");
    let text = run(&["info", &mesh("utah_teapot.obj")]);
    assert!(
        stdout(&text).contains(
            "surface    area 52.66079, 4 shells, not closed: 160 edges of one triangle (6 holes)\n"
        ),
        "{}",
        stdout(&text)
    );
    // Each shell a line, the largest first: the teapot's body, lid, spout and handle.
    assert!(
        stdout(&text).contains(
            "  shell 1    3160 triangles, area 38.39945, not closed: 40 edges of one triangle (1 hole); around (0, 1.249219, 0)\n"
        ),
        "{}",
        stdout(&text)
    );
    // The bones: the hip bones first, then a line for the rest, among them the walls of
    // cavities (a voxel under the threshold inside a bone, its 8 triangles facing in).
    let text = stdout(&run(&["info", bones.to_str().unwrap()]));
    let shells: Vec<&str> = text.lines().filter(|l| l.starts_with("  shell")).collect();
    assert_eq!(shells.len(), 9, "{text}");
    assert!(shells[0].contains(", closed: encloses "), "{text}");
    assert!(
        shells[8].starts_with("  shells     ") && shells[8].contains(" facing in (cavities"),
        "{text}"
    );
    let volumes = by_name("surface-bones.stl")["pieces"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["volume"].as_f64().unwrap());
    let (out, cavities): (Vec<f64>, Vec<f64>) = volumes.partition(|&v| v > 0.0);
    assert!(
        !cavities.is_empty() && out.len() > 100,
        "{} {}",
        out.len(),
        cavities.len()
    );

    let (Some(py), Some(_)) = (python_with("trimesh"), python_with("scipy")) else {
        return;
    };
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/trimesh_surface.py"))
        .args(&files)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let theirs: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let keys = [
        "triangles",
        "shells",
        "euler",
        "vertices",
        "edges",
        "boundary_edges",
        "non_manifold_edges",
        "holes",
    ];
    for (f, s) in files.iter().zip(&mine) {
        let name = Path::new(f).file_name().unwrap().to_str().unwrap();
        let t = &theirs[name];
        for k in keys {
            assert_eq!(s[k], t[k], "{name}: {k}: {s} against trimesh's {t}");
        }
        let close = |a: &serde_json::Value, b: &serde_json::Value| {
            let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            (a - b).abs() <= 1e-6 * b.abs()
        };
        assert!(close(&s["area"], &t["area"]), "{name}: {s} {t}");
        let closed = t["watertight"] == true && t["winding_consistent"] == true;
        assert_eq!(s["closed"], closed, "{name}: {s} {t}");
        if closed {
            assert!(close(&s["volume"], &t["volume"]), "{name}: {s} {t}");
        }
        if t["watertight"] == false && s["non_manifold_edges"] == 0 {
            assert!(s["volume"].is_null(), "{name}: {s}");
        }
        // Each shell alone, as trimesh measures its faces taken out: the same counts (the
        // shells compared as sets), the same areas, and where closed the same volumes (each
        // list in order, so that shells of one area pair up whichever they are).
        let (mine, theirs) = (
            s["pieces"].as_array().unwrap(),
            t["pieces"].as_array().unwrap(),
        );
        let counts = |p: &serde_json::Value, closed: bool| {
            let mut c: Vec<i64> = keys.iter().map(|&k| p[k].as_i64().unwrap()).collect();
            c.push(closed.into());
            c
        };
        let trimesh_closed =
            |p: &serde_json::Value| p["watertight"] == true && p["winding_consistent"] == true;
        let mut a: Vec<_> = mine
            .iter()
            .map(|p| counts(p, p["closed"] == true))
            .collect();
        let mut b: Vec<_> = theirs
            .iter()
            .map(|p| counts(p, trimesh_closed(p)))
            .collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "{name}: shells");
        let sorted = |v: Vec<f64>| {
            let mut v = v;
            v.sort_by(f64::total_cmp);
            v
        };
        let areas = |ps: &[serde_json::Value]| {
            sorted(ps.iter().map(|p| p["area"].as_f64().unwrap()).collect())
        };
        for (x, y) in areas(mine).iter().zip(areas(theirs)) {
            assert!(
                (x - y).abs() <= 1e-6 * y.abs() + 1e-12,
                "{name}: a shell's area {x} against {y}"
            );
        }
        let mine_volumes = sorted(
            (mine.iter())
                .filter(|p| p["closed"] == true)
                .map(|p| p["volume"].as_f64().unwrap())
                .collect(),
        );
        let their_volumes = sorted(
            (theirs.iter())
                .filter(|p| trimesh_closed(p))
                .map(|p| p["volume"].as_f64().unwrap())
                .collect(),
        );
        for (x, y) in mine_volumes.iter().zip(&their_volumes) {
            assert!(
                (x - y).abs() <= 1e-6 * y.abs() + 1e-9,
                "{name}: a shell's volume {x} against {y}"
            );
        }
    }
}

/// `--colour-shells`: the built-in CT's bones with their ten largest shells in the palette's
/// colours (the hip bones blue and orange, the largest two), the rest ivory, on every
/// device; the teapot's four parts, each its colour; refused where there is no surface of
/// its own to part.
#[test]
fn render_colours_each_shell() {
    // Pixels well into blue, and into orange, out of `rgb`.
    let hues = |rgb: &[u8]| {
        let px: Vec<[i32; 3]> = rgb
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]].map(i32::from))
            .collect();
        let blue = px
            .iter()
            .filter(|[r, g, b]| b - r > 40 && b - g > 10)
            .count();
        let orange = px
            .iter()
            .filter(|[r, g, b]| r - g > 40 && g - b > 30)
            .count();
        (
            blue as f64 / px.len() as f64,
            orange as f64 / px.len() as f64,
        )
    };
    // `render ARGS… -o NAME`: it said `said`; the picture's share of blue and orange.
    let coloured = |name: &str, args: &[&str], said: &str| {
        let png = tmp(name);
        let mut all = vec!["render", "--size", "96x72", "-o", png.to_str().unwrap()];
        all.extend_from_slice(args);
        let o = run(&all);
        assert!(
            o.status.success() && stderr(&o).contains(said),
            "{}",
            stderr(&o)
        );
        hues(&image::open(&png).unwrap().to_rgb8().into_raw())
    };
    let ivory = coloured("shells-none.png", &["--device", "cpu"], "");
    assert!(ivory.0 < 0.001 && ivory.1 < 0.001, "{ivory:?}");
    for dev in devices() {
        let (blue, orange) = coloured(
            &format!("shells-{dev}.png"),
            &["--device", dev, "--colour-shells"],
            ": 1223 shells, the 10 largest each in a colour of its own, the other 1213 in the usual colour",
        );
        assert!(blue > 0.01 && orange > 0.01, "{dev}: {blue} {orange}");
    }
    let teapot = mesh("utah_teapot.obj");
    let (blue, orange) = coloured(
        "shells-teapot.png",
        &[&teapot, "--colour-shells", "--legend"],
        ": 4 shells, the 4 largest each in a colour of its own (--legend",
    );
    assert!(blue > 0.05 && orange > 0.002, "{blue} {orange}");
    let png = tmp("shells-teapot.png");
    let scene = tmp("shells-scene.toml");
    std::fs::write(&scene, format!("[[objects]]\nmesh = {teapot:?}\n")).unwrap();
    refused(
        &[
            "render",
            scene.to_str().unwrap(),
            "--colour-shells",
            "-o",
            png.to_str().unwrap(),
        ],
        "--colour-shells colours a mesh's or a CT's bone surface; a scene file's objects have their materials",
    );
    refused(
        &[
            "render",
            "--colour-shells",
            "--mode",
            "dvr",
            "-o",
            png.to_str().unwrap(),
        ],
        "cannot be used with",
    );
}

#[test]
fn info_json() {
    let o = run(&["info", &mesh("utah_teapot.obj"), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(j["kind"], "mesh");
    assert_eq!(j["triangles"], 6320);
    assert_eq!(j["vertices"], 3644);
    let b = j["bounds"].as_array().unwrap();
    assert_eq!(b.len(), 2);
    for k in [
        "builder",
        "nodes",
        "leaves",
        "empty_leaves",
        "max_depth",
        "sah_cost",
        "mean_tris_per_leaf",
        "build_ms",
    ] {
        assert!(j["kdtree"].get(k).is_some(), "kdtree.{k} missing: {j}");
    }
    assert_eq!(j["kdtree"]["builder"], "sah");
    let med = run(&[
        "info",
        &mesh("utah_teapot.obj"),
        "--json",
        "--builder",
        "median",
    ]);
    let m: serde_json::Value = serde_json::from_str(stdout(&med).trim()).unwrap();
    assert!(m["kdtree"]["sah_cost"].as_f64().unwrap() > j["kdtree"]["sah_cost"].as_f64().unwrap());
    assert!(m["kdtree"]["sah_traversal_cost"].is_null(), "{m}");
    // A dearer traversal step: a tree of fewer, fuller leaves.
    assert_eq!(j["kdtree"]["sah_traversal_cost"], 1.0);
    let dear = run(&[
        "info",
        &mesh("utah_teapot.obj"),
        "--json",
        "--sah-traversal-cost",
        "4",
    ]);
    let d: serde_json::Value = serde_json::from_str(stdout(&dear).trim()).unwrap();
    assert_eq!(d["kdtree"]["sah_traversal_cost"], 4.0);
    assert!(
        d["kdtree"]["leaves"].as_u64() < j["kdtree"]["leaves"].as_u64(),
        "{d} vs {j}"
    );
    // The entry grid: 128 cells along the longest side by default, cubic cells, none with 0;
    // the text says so too.
    let g = &j["kdtree"]["entry_grid"];
    let cells: Vec<u64> = g["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .collect();
    assert_eq!(cells.iter().max(), Some(&128), "{g}");
    assert_eq!(
        g["bytes"].as_u64().unwrap(),
        4 * cells.iter().product::<u64>()
    );
    assert!(g["mean_depth"].as_f64().unwrap() > 3.0, "{g}");
    let off = run(&[
        "info",
        &mesh("utah_teapot.obj"),
        "--json",
        "--entry-grid",
        "0",
    ]);
    let o: serde_json::Value = serde_json::from_str(stdout(&off).trim()).unwrap();
    assert!(o["kdtree"]["entry_grid"].is_null(), "{o}");
    let text = stdout(&run(&[
        "info",
        &mesh("utah_teapot.obj"),
        "--entry-grid",
        "16",
    ]));
    assert!(text.contains("entry grid 16x"), "{text}");
    for bad in ["0", "-1", "nan", "1e9", "cheap"] {
        let o = run(&[
            "info",
            &mesh("utah_teapot.obj"),
            "--sah-traversal-cost",
            bad,
        ]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        assert!(
            stderr(&o).contains("--sah-traversal-cost") && stderr(&o).contains("triangle tests"),
            "{bad}: {}",
            stderr(&o)
        );
    }
}

/// `info --gpu`: the adapters, the first being the one `--device gpu` opens; under CI at least
/// lavapipe, with subgroups and timestamps. `info` wants a file or `--gpu`, not both.
/// `info SCENE.toml`: what `render` would draw — triangles, materials, lights, the camera (the
/// file's, or the framing one), the objects' box, the CT volume and the kd-tree.
#[test]
fn info_describes_a_scene() {
    let rods = repo().join("examples/spine_rods.toml");
    let o = run(&["info", rods.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["kind"], "scene");
    // Two cylinders of 256 triangles and a ground of 2.
    assert_eq!(v["triangles"], 514);
    assert_eq!(v["lights"].as_array().unwrap().len(), 2);
    assert_eq!(
        v["lights"][0]["position"],
        serde_json::json!([700.0, 1000.0, -400.0])
    );
    assert_eq!(v["camera"]["framed"], false);
    assert_eq!(
        v["camera"]["eye"],
        serde_json::json!([520.0, 560.0, -620.0])
    );
    assert_eq!(v["camera"]["fov_y_deg"], 36.0);
    assert_eq!(v["volume"]["dims"], serde_json::json!([122, 101, 112]));
    assert!(v["kdtree"]["nodes"].as_u64().unwrap() > 1);

    let scene = tmp("info-framed.toml");
    std::fs::write(&scene, "[[objects]]\nshape = \"sphere\"\n").unwrap();
    let o = run(&["info", scene.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(
        text.contains("scene") && text.contains("(framing the objects at 4:3)"),
        "{text}"
    );
    std::fs::write(&scene, "[[objects]]\nshape = \"cube\"\n").unwrap();
    let o = run(&["info", scene.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("info-framed.toml") && stderr(&o).contains("unknown shape"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn info_lists_gpu_adapters() {
    let o = run(&["info", "--gpu", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(j["kind"], "gpu");
    let adapters = j["adapters"].as_array().unwrap();
    if in_ci() {
        assert!(
            adapters
                .iter()
                .any(|a| a["name"].as_str().unwrap().contains("llvmpipe")
                    && a["subgroups"] == true
                    && a["timestamps"] == true
                    && a["f64"] == true),
            "{j}"
        );
    }
    if let Some(first) = adapters.first() {
        for k in [
            "backend",
            "device_type",
            "driver",
            "max_storage_binding",
            "subgroup_sizes",
        ] {
            assert!(first.get(k).is_some(), "{k} missing: {first}");
        }
        let t = gpu_probe("info-gpu", &["--json"]);
        let line: serde_json::Value = serde_json::from_str(stdout(&t).trim()).unwrap();
        let name = first["name"].as_str().unwrap();
        assert!(
            line["adapter"].as_str().unwrap().contains(name),
            "--device gpu opened {} but info --gpu lists {name} first",
            line["adapter"]
        );
    }
    assert_eq!(run(&["info"]).status.code(), Some(2));
    let both = run(&["info", &mesh("spot.obj"), "--gpu"]);
    assert_eq!(both.status.code(), Some(2));
    assert!(stderr(&both).contains("--gpu"), "{}", stderr(&both));
}

/// A successful run's stdout as JSON lines.
fn json_lines(o: &std::process::Output) -> Vec<serde_json::Value> {
    assert!(o.status.success(), "{}", stderr(o));
    stdout(o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn bench_json_lines() {
    let dir = tmp("bench-rays");
    let _ = std::fs::remove_dir_all(&dir);
    let spot = mesh("spot.obj");
    let o = run(&[
        "bench",
        &spot,
        "--size",
        "64x48",
        "--repeat",
        "1",
        "--json",
        "--save-rays",
        dir.to_str().unwrap(),
    ]);
    let lines = json_lines(&o);
    let kinds: Vec<&str> = lines.iter().map(|l| l["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["primary", "shadow", "diffuse"]);
    for l in &lines {
        let rays = l["rays"].as_u64().unwrap();
        assert!(rays > 1000);
        assert!(l["mrays_per_s"].as_f64().unwrap() > 0.0);
        assert!(l["inner_per_ray"].as_f64().unwrap() > 0.0);
        assert!(l["hits"].as_u64().unwrap() > 0);
        // The saved set is the one measured: as many rays, and `trace` finds the same hits.
        let kind = l["kind"].as_str().unwrap();
        let saved = dir.join(format!("{kind}.rays"));
        assert_eq!(std::fs::metadata(&saved).unwrap().len(), 32 * rays);
        let hits = dir.join(format!("{kind}.hits"));
        trace_to(&spot, &saved, &hits, kind == "shadow", &[]);
        let found = std::fs::read(&hits)
            .unwrap()
            .chunks_exact(16)
            .filter(|h| f32::from_le_bytes(h[..4].try_into().unwrap()).is_finite())
            .count();
        assert_eq!(found as u64, l["hits"].as_u64().unwrap(), "{kind}");
    }
    let ct = builtin_ct();
    let o = run(&["bench", &ct, "--save-rays", dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--save-rays"), "{}", stderr(&o));
}

/// `bench --device gpu,cpu`: both devices' lines, the GPU's with the fused kernel's own count
/// of its work (the CPU's walk, step for step) and its SIMD efficiency.
#[test]
fn bench_gpu_and_cpu_side_by_side() {
    if !gpu_available() {
        return;
    }
    let o = run(&[
        "bench",
        &mesh("spot.obj"),
        "--device",
        "gpu,cpu",
        "--size",
        "48x36",
        "--repeat",
        "1",
        "--json",
    ]);
    let lines = json_lines(&o);
    let devices: Vec<&str> = lines
        .iter()
        .map(|l| l["device"].as_str().unwrap())
        .collect();
    assert_eq!(devices, ["gpu", "gpu", "gpu", "cpu", "cpu", "cpu"]);
    for (g, c) in lines[..3].iter().zip(&lines[3..]) {
        assert_eq!(g["kind"], c["kind"]);
        assert!(c["gpu_stats"].is_null());
        let Some(stats) = g["gpu_stats"].as_object() else {
            assert!(
                !in_ci(),
                "CI's lavapipe has subgroups: statistics expected in {g}"
            );
            eprintln!("no subgroup operations on this adapter: no GPU statistics");
            continue;
        };
        assert_eq!(stats["steps_per_ray"]["traversal"], c["inner_per_ray"]);
        assert_eq!(stats["steps_per_ray"]["leaf"], c["leaves_per_ray"]);
        for (kind, e) in stats["simd_efficiency"].as_object().unwrap() {
            let e = e.as_f64().unwrap();
            assert!(e > 0.0 && e <= 1.0, "{kind}: {e}");
        }
    }
}

#[test]
fn default_render_writes_render_png() {
    let dir = tmp("default-cwd");
    std::fs::create_dir_all(&dir).unwrap();
    let o = bin()
        .current_dir(&dir)
        .args(["render", "--size", "32x24", "--spp", "1", "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("render.png").exists());
}

/// `render --device gpu` against `render --device cpu` of the same scene, measured by
/// `rays.py imgdiff`: meshes, mean absolute difference < 0.5/255 and ≥ 99.9 % of pixels within
/// 2/255; volumes (`volume`: hardware texture filtering has ~1/256 weight precision), mean
/// < 1/255 and the 99th percentile within 8/255.
fn gpu_matches_cpu(name: &str, args: &[&str], volume: bool) {
    if !gpu_available() {
        return;
    }
    let path = |dev: &str| tmp(&format!("gpu-vs-cpu-{name}-{dev}.png"));
    for dev in ["cpu", "gpu"] {
        let out = path(dev);
        let mut all = vec!["render"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", out.to_str().unwrap(), "--quiet", "--device", dev]);
        let o = run(&all);
        assert!(o.status.success(), "{name} on {dev}: {}", stderr(&o));
    }
    gpu_frames_match(&path("cpu"), &path("gpu"), name, volume);
}

#[test]
fn gpu_render_matches_cpu_default_ct() {
    gpu_matches_cpu("default", &["--size", "96x72", "--spp", "1"], false);
}

/// `render --submit wave|depth`: the host submits a wave's depths at once or one by one; the
/// same PNG, and the summary says which ran.
#[test]
fn gpu_render_submit_modes_give_the_same_image() {
    if !gpu_available() {
        return;
    }
    let mut pngs = Vec::new();
    for submit in ["wave", "depth"] {
        let out = tmp(&format!("submit-{submit}.png"));
        let o = run(&[
            "render",
            "--size",
            "96x72",
            "--spp",
            "2",
            "--device",
            "gpu",
            "--submit",
            submit,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{submit}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!(", one per {submit} (kernels")),
            "{submit}: {}",
            stderr(&o)
        );
        pngs.push(std::fs::read(&out).unwrap());
    }
    assert!(pngs[0] == pngs[1], "--submit wave and depth differ");
}

/// `RAYSTREAM_GPU_PIXELS=blocks|rows`: the camera rays in blocks of pixels or row by row give
/// the same PNG (every pixel gets its own samples once, whatever the order; the size leaves a
/// short last band), at one sample a pixel and at several; other values are refused.
#[test]
fn gpu_render_pixel_orders_give_the_same_image() {
    if !gpu_available() {
        return;
    }
    let render = |order: &str, spp: &str| {
        let out = tmp(&format!("pixels-{order}-{spp}.png"));
        let args = [
            "render", "--size", "67x45", "--spp", spp, "--device", "gpu", "-q",
        ];
        run_with_env("RAYSTREAM_GPU_PIXELS", Some(order), &args, &out)
    };
    for spp in ["1", "2"] {
        let (rows, by_rows) = render("rows", spp);
        let (blocks, by_blocks) = render("blocks", spp);
        assert!(rows.status.success(), "{}", stderr(&rows));
        assert!(blocks.status.success(), "{}", stderr(&blocks));
        assert!(!by_rows.is_empty() && by_rows == by_blocks, "spp {spp}");
    }
    let (bad, _) = render("tiles", "1");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_PIXELS=\"tiles\": blocks or rows"),
        "{}",
        stderr(&bad)
    );
}

/// `RAYSTREAM_GPU_APPENDS=subgroup|atomic`: `shade_hits` reserving queue slots a subgroup or a
/// lane at a time gives the same PNG (the film's sums do not depend on the queues' order);
/// other values are refused.
#[test]
fn gpu_render_appends_give_the_same_image() {
    if !gpu_available() {
        return;
    }
    let render = |appends: &str| {
        let out = tmp(&format!("appends-{appends}.png"));
        let args = ["render", "--size", "67x45", "--device", "gpu", "-q"];
        run_with_env("RAYSTREAM_GPU_APPENDS", Some(appends), &args, &out)
    };
    let (atomic, by_atomic) = render("atomic");
    let (subgroup, by_subgroup) = render("subgroup");
    assert!(atomic.status.success(), "{}", stderr(&atomic));
    assert!(subgroup.status.success(), "{}", stderr(&subgroup));
    assert!(!by_atomic.is_empty() && by_atomic == by_subgroup);
    let (bad, _) = render("warp");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_APPENDS=\"warp\": subgroup or atomic"),
        "{}",
        stderr(&bad)
    );
}

/// Renders the default scene at 67 × 67 pixels, 4 samples, on `device` with `var` unset and
/// set to 1000 samples (67 × 67 pixels take 18 waves of 250 pixels, the last a part): both
/// succeed, say so (`one`, `many` in their messages) and give the same PNG; each of `bad`'s
/// values fails with exit status 2 and its message.
fn wave_size_leaves_the_image(
    var: &str,
    device: &str,
    [one_says, many_says]: [&str; 2],
    bad: &[(&str, &str)],
) {
    let render = |wave: Option<&str>| {
        let out = tmp(&format!("{device}-wave-{}.png", wave.unwrap_or("default")));
        let args = ["render", "--size", "67x67", "--device", device];
        run_with_env(var, wave, &args, &out)
    };
    let (one, whole) = render(None);
    let (many, waves) = render(Some("1000"));
    for (o, says) in [(&one, one_says), (&many, many_says)] {
        assert!(o.status.success(), "{}", stderr(o));
        assert!(stderr(o).contains(says), "{says}: {}", stderr(o));
    }
    assert!(!whole.is_empty() && whole == waves);
    for (value, why) in bad {
        let (o, _) = render(Some(value));
        assert_eq!(o.status.code(), Some(2), "{value}");
        assert!(stderr(&o).contains(why), "{value}: {}", stderr(&o));
    }
}

/// `RAYSTREAM_GPU_WAVE=N`: the stream renderer in waves of at most N samples gives the same
/// PNG as in one wave (18 waves of 1000 samples, one submission each); 0, more than the most,
/// or not a number is refused.
#[test]
fn gpu_render_wave_size_leaves_the_image() {
    if !gpu_available() {
        return;
    }
    wave_size_leaves_the_image(
        "RAYSTREAM_GPU_WAVE",
        "gpu",
        [
            "on 1 submission, one per wave",
            "on 18 submissions, one per wave",
        ],
        &[
            ("0", "a wave of 0 samples: from 1 to 8388608"),
            ("9999999", "a wave of 9999999 samples: from 1 to 8388608"),
            (
                "many",
                "RAYSTREAM_GPU_WAVE=\"many\" is not a number of samples",
            ),
        ],
    );
}

/// `RAYSTREAM_CPU_WAVE=N`: the CPU renderer in waves of at most N samples gives the same PNG
/// as in its default waves (18 of 1000 samples against one); 0 or not a number is refused.
#[test]
fn cpu_render_wave_size_leaves_the_image() {
    wave_size_leaves_the_image(
        "RAYSTREAM_CPU_WAVE",
        "cpu",
        [
            "the CPU's frame in 1 wave of 65536 pixels at most",
            "the CPU's frame in 18 waves of 250 pixels at most",
        ],
        &[
            ("0", "RAYSTREAM_CPU_WAVE=\"0\" is not a number of samples"),
            (
                "many",
                "RAYSTREAM_CPU_WAVE=\"many\" is not a number of samples",
            ),
            ("-5", "RAYSTREAM_CPU_WAVE=\"-5\" is not a number of samples"),
        ],
    );
}

/// Objects a million units from the origin (a CT whose header puts it a kilometre off, say):
/// hit points there are good only to their f32 rounding (1/16 unit), so secondary rays start
/// at least 32 of those units off the surface, and the GPU still gives the CPU's picture
/// (with 1e-4 radii, less than the rounding, each back-end's shadow rays hit their own
/// surfaces in their own places).
#[test]
fn gpu_render_matches_cpu_far_from_the_origin() {
    let scene = tmp("far-off.toml");
    std::fs::write(
        &scene,
        "[[lights]]\nposition = [1000003, 4, 3]\n[[objects]]\nshape = \"spot\"\n\
         translate = [1000000, 0, 0]\n[[objects]]\nshape = \"sphere\"\nscale = 0.4\n\
         translate = [1000001.5, 0, 0]\n[ground]\n",
    )
    .unwrap();
    gpu_matches_cpu(
        "far-off",
        &[scene.to_str().unwrap(), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// The cow and a small sphere under two lights; `beside` adds a black quad 10⁹ units wide far
/// below them, where it gives what the black background gives.
fn cow_scene(beside: bool) -> String {
    let mut s = String::from(
        "background = [0, 0, 0]\n[camera]\neye = [0.5, 1.2, 3.0]\ntarget = [0, 0.4, 0]\n\
         fov = 35\n[[lights]]\nposition = [3, 5, 4]\n[[lights]]\nposition = [-4, 2, 1]\n\
         color = [0.3, 0.3, 0.4]\n[materials.shiny]\ndiffuse = [0.7, 0.5, 0.4]\n\
         reflectivity = 0.3\n[[objects]]\nshape = \"spot\"\nmaterial = \"shiny\"\n\
         [[objects]]\nshape = \"sphere\"\nscale = 0.3\ntranslate = [0.9, 0.3, 0.2]\n\
         material = \"shiny\"\n",
    );
    if beside {
        s.push_str(
            "[materials.black]\nambient = [0, 0, 0]\ndiffuse = [0, 0, 0]\n\
             specular = [0, 0, 0]\n[[objects]]\nshape = \"quad\"\nscale = 1e9\n\
             translate = [0, -1e8, 0]\nmaterial = \"black\"\n",
        );
    }
    let path = tmp(&format!("cow-beside-{beside}.toml"));
    std::fs::write(&path, s).unwrap();
    path.to_str().unwrap().to_string()
}

/// Each object's secondary rays leave it by its own offset, on both devices: the cow beside a
/// huge far-off quad renders as the cow alone (a scene-wide offset, 10⁻⁴ of the scene's
/// radius, started the cow's shadow and reflection rays 10⁵ units off it), and the GPU gives
/// the CPU's picture of it.
#[test]
fn a_small_object_beside_a_huge_one_is_shaded_as_if_alone() {
    for dev in devices() {
        let mut images = Vec::new();
        for beside in [false, true] {
            let out = tmp(&format!("cow-beside-{beside}-{dev}.png"));
            let o = run(&[
                "render",
                &cow_scene(beside),
                "--size",
                "96x72",
                "--spp",
                "1",
                "--device",
                dev,
                "--quiet",
                "-o",
                out.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{dev}: {}", stderr(&o));
            images.push(image::open(&out).unwrap().to_rgb8());
        }
        let lit = images[0].pixels().filter(|p| p[0] > 12).count();
        assert!(lit > 1000, "{dev}: {lit} lit pixels");
        let off = images[0]
            .pixels()
            .zip(images[1].pixels())
            .filter(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > 1))
            .count();
        assert!(off <= 4, "{dev}: {off} pixels differ beside the huge quad");
    }
    gpu_matches_cpu(
        "cow-beside",
        &[&cow_scene(true), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// A camera and its light 10⁵ radii from a sphere: hit points along the camera rays are good
/// only to 10⁵ ulps, more than the sphere's ray offset, so both devices move them onto their
/// triangle's plane before the shadow rays leave; otherwise each back-end's shadow rays hit
/// the sphere in their own places.
#[test]
fn gpu_render_matches_cpu_with_a_far_camera() {
    let scene = tmp("far-camera.toml");
    std::fs::write(
        &scene,
        "[camera]\neye = [0, 0, 1e5]\ntarget = [0, 0, 0]\nfov = 0.0015\n[[lights]]\n\
         position = [0, 0, 1e5]\n[[lights]]\nposition = [1e5, 1e5, 1e5]\n\
         color = [0.3, 0.3, 0.3]\n[[objects]]\nshape = \"sphere\"\n",
    )
    .unwrap();
    gpu_matches_cpu(
        "far-camera",
        &[scene.to_str().unwrap(), "--size", "96x96", "--spp", "1"],
        false,
    );
}

#[test]
fn gpu_render_matches_cpu_spot_scene() {
    gpu_matches_cpu(
        "spot",
        &[
            &spot_scene(),
            "--size",
            "96x72",
            "--spp",
            "2",
            "--max-depth",
            "5",
        ],
        false,
    );
}

/// dvr read trilinearly and by the cubic B-spline (its default), and a MIP.
#[test]
fn golden_direct_volume_rendering() {
    golden(
        "dvr_ct_bones",
        &[
            "--mode",
            "dvr",
            "--preset",
            "ct-bones",
            "--size",
            "96x72",
            "--interpolation",
            "linear",
        ],
    );
    golden(
        "dvr_ct_bones_cubic",
        &["--mode", "dvr", "--preset", "ct-bones", "--size", "96x72"],
    );
    golden(
        "mip",
        &[
            "--mode", "mip", "--window", "1500", "--level", "300", "--size", "96x72",
        ],
    );
}

/// The README's example of meshes and a CT volume in one scene (examples/spine_rods.toml):
/// two rods in the abdomen CT, ray-marched through ct-bones, with shadows and a mirror floor.
fn spine_rods() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/spine_rods.toml")
        .to_str()
        .unwrap()
        .to_string()
}

#[test]
fn golden_meshes_and_volume_in_one_scene() {
    golden(
        "spine_rods",
        &[&spine_rods(), "--size", "96x72", "--spp", "1"],
    );
}

#[test]
fn gpu_matches_cpu_with_meshes_and_volume_in_one_scene() {
    gpu_matches_cpu(
        "spine_rods",
        &[
            &spine_rods(),
            "--size",
            "64x48",
            "--spp",
            "1",
            "--max-depth",
            "2",
        ],
        true,
    );
}

#[test]
fn gpu_volume_rendering_matches_cpu_cli() {
    gpu_matches_cpu(
        "dvr",
        &["--mode", "dvr", "--preset", "ct-aaa", "--size", "64x48"],
        true,
    );
    gpu_matches_cpu("mip", &["--mode", "mip", "--size", "64x48"], true);
}

#[test]
fn golden_volume_shadows() {
    golden(
        "dvr_shadows",
        &[
            "--mode",
            "dvr",
            "--preset",
            "ct-bones",
            "--shadows",
            "--size",
            "96x72",
            "--interpolation",
            "linear",
        ],
    );
}

#[test]
fn gpu_volume_shadows_from_a_placed_light_match_cpu_cli() {
    gpu_matches_cpu(
        "dvr-shadows-light",
        &[
            "--mode",
            "dvr",
            "--shadows",
            "--light=60,-20",
            "--size",
            "64x48",
        ],
        true,
    );
}

#[test]
fn gpu_volume_shadows_and_clipping_match_cpu_cli() {
    gpu_matches_cpu(
        "dvr-shadows-clipped",
        &[
            "--mode",
            "dvr",
            "--shadows",
            "--crop=-250,-400,-400,60,400,400",
            "--clip-plane=0,1,0.2,-60",
            "--size",
            "64x48",
        ],
        true,
    );
}

/// Four panels side by side in an OBJ with its MTL: red paint (a texture the renderer names and
/// does not apply), a mirror, glass, blue paint. Returns the OBJ's path.
fn mtl_panels(name: &str) -> std::path::PathBuf {
    let dir = tmp(&format!("mtl-panels-{name}"));
    std::fs::create_dir_all(&dir).unwrap();
    let mut obj = String::from("mtllib panels.mtl\n");
    for (i, m) in ["red", "mirror", "glass", "blue"].iter().enumerate() {
        let x = i as f32 * 1.1 - 2.2;
        for (dx, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.5), (0.0, 1.5)] {
            obj += &format!("v {} {y} {}\n", x + dx, 0.3 * i as f32);
        }
        obj += &format!(
            "usemtl {m}\nf {} {} {} {}\n",
            4 * i + 1,
            4 * i + 2,
            4 * i + 3,
            4 * i + 4
        );
    }
    std::fs::write(dir.join("panels.obj"), obj).unwrap();
    std::fs::write(
        dir.join("panels.mtl"),
        "newmtl red\nKd 0.8 0.1 0.1\nKs 0.3 0.3 0.3\nNs 30\nillum 2\nmap_Kd red.png\n\
         newmtl mirror\nKd 0.1 0.1 0.1\nKs 0.8 0.8 0.8\nillum 3\n\
         newmtl glass\nKd 0 0 0\nd 0.2\nNi 1.5\nillum 7\n\
         newmtl blue\nKd 0.1 0.2 0.9\nillum 1\n",
    )
    .unwrap();
    dir.join("panels.obj")
}

/// `render MESH.obj` paints each face in its MTL material: red on the left, blue on the right,
/// and the texture it does not apply is named.
#[test]
fn obj_materials_are_rendered() {
    let out = tmp("mtl-panels.png");
    let o = run(&[
        "render",
        mtl_panels("render").to_str().unwrap(),
        "--size",
        "96x48",
        "--spp",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("material 'red': texture red.png is not applied"),
        "{}",
        stderr(&o)
    );
    let img = image::open(&out).unwrap().to_rgb8();
    let count = |x0: u32, x1: u32, f: &dyn Fn(&image::Rgb<u8>) -> bool| {
        (x0..x1)
            .flat_map(|x| (0..48).map(move |y| (x, y)))
            .filter(|&(x, y)| f(img.get_pixel(x, y)))
            .count()
    };
    let red = |p: &image::Rgb<u8>| p[0] > 100 && p[0] as u32 > 2 * p[2] as u32;
    let blue = |p: &image::Rgb<u8>| p[2] > 100 && p[2] as u32 > 2 * p[0] as u32;
    let (left, right) = ((0, 40), (56, 96));
    assert!(count(left.0, left.1, &red) > 100 && count(right.0, right.1, &red) == 0);
    assert!(count(right.0, right.1, &blue) > 100 && count(left.0, left.1, &blue) == 0);
    // `info` lists them, with their triangles.
    let o = run(&["info", mtl_panels("info").to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(
        v["materials"],
        serde_json::json!([
            {"name": "red", "triangles": 2, "texture": null},
            {"name": "mirror", "triangles": 2, "texture": null},
            {"name": "glass", "triangles": 2, "texture": null},
            {"name": "blue", "triangles": 2, "texture": null}
        ])
    );
}

#[test]
fn gpu_matches_cpu_on_obj_materials() {
    gpu_matches_cpu(
        "mtl-panels",
        &[
            mtl_panels("gpu").to_str().unwrap(),
            "--size",
            "96x48",
            "--spp",
            "1",
        ],
        false,
    );
}

/// A cube whose OBJ gives each face its normal (`vn`) shades flat: every pixel of `--aov
/// normal` is one of the six axis normals (or the ground's), on both devices. Without the
/// normals, the averaged ones bend across its faces.
#[test]
fn obj_normals_shade_hard_edges() {
    let dir = tmp("hard-cube");
    std::fs::create_dir_all(&dir).unwrap();
    let faces = [
        ([1, 4, 3, 2], 1),
        ([5, 6, 7, 8], 2),
        ([1, 5, 8, 4], 3),
        ([2, 3, 7, 6], 4),
        ([1, 2, 6, 5], 5),
        ([4, 8, 7, 3], 6),
    ];
    let mut obj = String::from(
        "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
         vn 0 0 -1\nvn 0 0 1\nvn -1 0 0\nvn 1 0 0\nvn 0 -1 0\nvn 0 1 0\n",
    );
    let mut bare = obj.clone();
    for (f, n) in faces {
        obj += &format!("f {}\n", f.map(|v| format!("{v}//{n}")).join(" "));
        bare += &format!("f {}\n", f.map(|v| v.to_string()).join(" "));
    }
    std::fs::write(dir.join("hard.obj"), obj).unwrap();
    std::fs::write(dir.join("soft.obj"), bare).unwrap();
    let axis_colours = |name: &str, device: &str| {
        let out = dir.join(format!("{name}-{device}.png"));
        let o = run(&[
            "render",
            dir.join(format!("{name}.obj")).to_str().unwrap(),
            "--aov",
            "normal",
            "--orbit",
            "30,25",
            "--size",
            "64x48",
            "--device",
            device,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let img = image::open(&out).unwrap().to_rgb8();
        let on_axis = |p: &image::Rgb<u8>| {
            let far = p.0.iter().filter(|&&c| c.abs_diff(128) > 1).count();
            let end = p.0.iter().filter(|&&c| c <= 1 || c == 255).count();
            p.0 == [0, 0, 0] || (far == 1 && end == 1)
        };
        let hits = img.pixels().filter(|p| p.0 != [0, 0, 0]).count();
        let off = img.pixels().filter(|p| !on_axis(p)).count();
        (hits, off)
    };
    let (hits, off) = axis_colours("hard", "cpu");
    assert!(
        hits > 1000 && off == 0,
        "{off} of {hits} pixels off the axes"
    );
    let (_, off) = axis_colours("soft", "cpu");
    assert!(
        off > 300,
        "averaged normals: only {off} pixels off the axes"
    );
    if gpu_available() {
        let (hits, off) = axis_colours("hard", "gpu");
        assert!(
            hits > 1000 && off == 0,
            "GPU: {off} of {hits} pixels off the axes"
        );
    }
}

/// A gantry-tilted head CT's sheared grid (18.5°, slices resampled to even spacing): the GPU
/// marches it as the CPU does, seen from the side, where the shear shows.
#[test]
fn gpu_matches_cpu_on_a_sheared_grid() {
    let head = shared().join("data/volumes/dicom/head_ct_gantry_tilt_ge");
    for (name, mode) in [("tilted-dvr", "dvr"), ("tilted-mip", "mip")] {
        gpu_matches_cpu(
            name,
            &[
                head.to_str().unwrap(),
                "--mode",
                mode,
                "--view",
                "left",
                "--size",
                "64x48",
            ],
            true,
        );
    }
}

/// Cropping and clipping change the picture; a crop box outside the volume leaves only the
/// background; malformed boxes and planes, and options without --mode, are clear errors.
#[test]
fn crop_and_clip_planes_from_the_command_line() {
    let render = |name: &str, extra: &[&str]| {
        let out = tmp(&format!("clip-{name}.png"));
        let mut all = vec!["render", "--mode", "mip", "--size", "48x36", "--quiet"];
        all.extend_from_slice(extra);
        all.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        image::open(&out).unwrap().to_rgb8()
    };
    let full = render("full", &[]);
    let cropped = render("crop", &["--crop=-250,-400,-400,60,400,400"]);
    let planed = render("plane", &["--clip-plane=1,0,0,60"]);
    assert_ne!(full, cropped, "--crop changed nothing");
    assert_ne!(full, planed, "--clip-plane changed nothing");
    let outside = render("outside", &["--crop=5000,5000,5000,5001,5001,5001"]);
    let first = *outside.get_pixel(0, 0);
    assert!(
        outside.pixels().all(|p| *p == first),
        "a crop box outside the volume shows something"
    );
    for (args, want) in [
        (vec!["--crop=1,2,3"], "six finite numbers"),
        (vec!["--crop=0,0,0,-1,5,5"], "below its maximum"),
        (vec!["--clip-plane=0,0,0,1"], "normal"),
        (
            vec![
                "--clip-plane=1,0,0,0",
                "--clip-plane=0,1,0,0",
                "--clip-plane=0,0,1,0",
            ],
            "at most two",
        ),
        (vec!["--shadows"], "--mode dvr"),
    ] {
        let bad = tmp("clip-bad.png");
        let mut all = vec!["render", "--mode", "mip", "--size", "8x8", "--quiet"];
        all.extend_from_slice(&args);
        all.extend_from_slice(&["-o", bad.to_str().unwrap()]);
        let o = run(&all);
        assert_eq!(o.status.code(), Some(2), "{args:?} should fail");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
    let o = run(&["render", "--shadows", "--size", "8x8", "--quiet"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("with --mode (direct volume rendering)"),
        "{}",
        stderr(&o)
    );
}

/// A turntable writes N frames; frame 0 is the plain front view, and the frames differ.
#[test]
fn turntable_writes_frames() {
    let dir = tmp("turntable");
    let _ = std::fs::remove_dir_all(&dir);
    let args = ["render", "--mode", "mip", "--size", "40x30", "--quiet"];
    let mut all = args.to_vec();
    all.extend_from_slice(&["--turntable", "4", "-o", dir.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "frame_000.png",
            "frame_001.png",
            "frame_002.png",
            "frame_003.png"
        ]
    );
    let front = tmp("turntable-front.png");
    let mut all = args.to_vec();
    all.extend_from_slice(&["-o", front.to_str().unwrap()]);
    assert!(run(&all).status.success());
    let frame = |n: &str| image::open(dir.join(n)).unwrap().to_rgb8();
    assert_eq!(
        frame("frame_000.png"),
        image::open(&front).unwrap().to_rgb8()
    );
    assert_ne!(frame("frame_000.png"), frame("frame_001.png"));
    // A folder named like an image (PNG or EXR) is refused.
    for name in ["x.png", "x.exr"] {
        let o = run(&[
            "render",
            "--mode",
            "mip",
            "--turntable",
            "2",
            "-o",
            tmp(name).to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains("folder"), "{}", stderr(&o));
    }
}

/// The frames of an animation (APNG as the png crate reads it, through image), as RGB.
fn apng_frames(path: &Path) -> Vec<image::RgbImage> {
    use image::AnimationDecoder;
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    image::codecs::png::PngDecoder::new(file)
        .unwrap()
        .apng()
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap()
        .into_iter()
        .map(|f| {
            assert_eq!(f.delay().numer_denom_ms(), (100, 1), "10 frames/s");
            image::DynamicImage::ImageRgba8(f.into_buffer()).to_rgb8()
        })
        .collect()
}

/// A GIF's frames as RGB, with their delays in 1/100 s; it must loop forever.
fn gif_frames(path: &Path) -> Vec<(image::RgbImage, u16)> {
    let mut o = gif::DecodeOptions::new();
    o.set_color_output(gif::ColorOutput::RGBA);
    let mut d = o.read_info(std::fs::File::open(path).unwrap()).unwrap();
    assert_eq!(d.repeat(), gif::Repeat::Infinite);
    let (w, h) = (d.width() as u32, d.height() as u32);
    let mut out = Vec::new();
    while let Some(f) = d.read_next_frame().unwrap() {
        assert_eq!(
            (f.left, f.top, f.width as u32, f.height as u32),
            (0, 0, w, h)
        );
        let rgba = image::RgbaImage::from_raw(w, h, f.buffer.to_vec()).unwrap();
        out.push((image::DynamicImage::ImageRgba8(rgba).to_rgb8(), f.delay));
    }
    out
}

/// `--format apng|gif` writes a turntable, a slice series or the stream renderer's turntable as
/// one looping animation that `-o` names: an APNG's frames are the folder's PNG frames byte
/// for byte, a GIF's the same within its 256 colours a frame, at the rate --fps asks; a name
/// that is not the container's, and --fps without an animation, are refused.
#[test]
fn animations_hold_the_frames_a_folder_gets() {
    let spot = mesh("spot.obj");
    let cases: [(&str, Vec<&str>); 3] = [
        (
            "mip",
            vec!["--mode", "mip", "--size", "48x40", "--turntable", "4"],
        ),
        (
            "slices",
            vec![
                "--mode", "slice", "--view", "left", "--size", "40x40", "--slices", "3",
            ],
        ),
        (
            "spot",
            vec![
                &spot[..],
                "--device",
                "cpu",
                "--size",
                "40x32",
                "--spp",
                "1",
                "--turntable",
                "3",
            ],
        ),
    ];
    for (name, args) in &cases {
        let dir = tmp(&format!("anim-{name}"));
        let _ = std::fs::remove_dir_all(&dir);
        let with = |extra: &[&str]| {
            let mut all = vec!["render", "-q"];
            all.extend(args);
            all.extend(extra);
            let o = run(&all);
            assert!(o.status.success(), "{all:?}: {}", stderr(&o));
        };
        with(&["-o", dir.to_str().unwrap()]);
        let mut folder: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        folder.sort();
        let folder: Vec<_> = folder
            .iter()
            .map(|p| image::open(p).unwrap().to_rgb8())
            .collect();
        assert!(folder.len() >= 3 && folder[0] != folder[1], "{name}");

        let apng = tmp(&format!("anim-{name}.png"));
        with(&["--format", "apng", "-o", apng.to_str().unwrap()]);
        assert_eq!(
            apng_frames(&apng),
            folder,
            "{name}: APNG against the folder"
        );

        let gif = tmp(&format!("anim-{name}.gif"));
        with(&[
            "--format",
            "gif",
            "--fps",
            "20",
            "-o",
            gif.to_str().unwrap(),
        ]);
        let frames = gif_frames(&gif);
        assert_eq!(frames.len(), folder.len(), "{name}");
        for ((f, delay), want) in frames.iter().zip(&folder) {
            assert_eq!(*delay, 5, "{name}: 1/20 s");
            let mean = f
                .as_raw()
                .iter()
                .zip(want.as_raw())
                .map(|(&a, &b)| a.abs_diff(b) as f64)
                .sum::<f64>()
                / f.as_raw().len() as f64;
            assert!(mean < 1.0, "{name}: GIF frame off by {mean} on average");
        }
    }
    let out = tmp("anim-refused");
    for (extra, want) in [
        (vec!["--format", "gif", "-o", "x.png"], "name it NAME.gif"),
        (vec!["--format", "apng", "-o", "x.gif"], "name it NAME.png"),
        (vec!["--format", "apng", "-o", "folder"], "name it NAME.png"),
        (
            vec!["--fps", "12", "-o", "folder"],
            "give --format apng or gif",
        ),
    ] {
        let mut all = vec![
            "render",
            "--mode",
            "mip",
            "--size",
            "8x8",
            "--turntable",
            "2",
        ];
        all.extend(&extra[..extra.len() - 1]);
        let target = out.join(extra[extra.len() - 1]);
        all.push(target.to_str().unwrap());
        let o = run(&all);
        assert_eq!(o.status.code(), Some(2), "{all:?}");
        assert!(stderr(&o).contains(want), "{all:?}: {}", stderr(&o));
        assert!(!target.exists(), "{all:?} left {}", target.display());
    }
}

/// `render MESH|SCENE|(the bones) --turntable N -o DIR` through the stream renderer: on each
/// device, frame i is, byte for byte, the picture `--orbit` at i·360/N degrees (from `--orbit`'s
/// start) renders: for a mesh (its lights turning with the camera), for a scene file with a CT
/// volume among its meshes (its lights staying put) and for the bones as one DICOM series in
/// the patient's directions; the GPU's frames match the CPU's; a scene that sets its camera, an
/// AOV and a folder named like an image are refused.
#[test]
fn a_turntable_of_the_stream_renderer_is_its_orbits() {
    let spot = mesh("spot.obj");
    let rods = {
        // The example scene without its camera, its volume's path made absolute.
        let text = std::fs::read_to_string(spine_rods()).unwrap();
        let start = text.find("[camera]").unwrap();
        let end = start + text[start..].find("\n\n").unwrap() + 2;
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
        let text = format!("{}{}", &text[..start], &text[end..])
            .replace("../crates/raystream/assets", assets.to_str().unwrap());
        assert!(!text.contains("[camera]"));
        let file = tmp("turntable-rods.toml");
        std::fs::write(&file, text).unwrap();
        file.to_str().unwrap().to_string()
    };
    let size = ["--size", "40x32", "--spp", "1"];
    for dev in devices() {
        for (name, input, start) in [("spot", &spot[..], 30.0), ("rods", &rods[..], 0.0)] {
            let dir = tmp(&format!("turntable-{name}-{dev}"));
            let _ = std::fs::remove_dir_all(&dir);
            let orbit = format!("{start},10");
            let mut all = vec!["render", "-q", input, "--device", dev, "--orbit", &orbit];
            all.extend(size);
            all.extend(["--turntable", "3", "-o", dir.to_str().unwrap()]);
            let o = run(&all);
            assert!(o.status.success(), "{all:?}: {}", stderr(&o));
            for i in 0..3 {
                let az = format!("{},10", start + 120.0 * i as f64);
                let one = render_to(
                    &format!("turntable-{name}-{dev}-{i}.png"),
                    dev,
                    &[&[input, "--orbit", &az][..], &size[..]].concat(),
                );
                let frame = image::open(dir.join(format!("frame_{i:03}.png"))).unwrap();
                assert_eq!(
                    frame.to_rgb8(),
                    image::open(&one).unwrap().to_rgb8(),
                    "{name} on {dev}: frame {i} against --orbit {az}"
                );
            }
            if *dev == "gpu" {
                let cpu = tmp(&format!("turntable-{name}-cpu"));
                let frame = "frame_002.png";
                gpu_frames_match(&cpu.join(frame), &dir.join(frame), name, name == "rods");
            }
        }
    }
    // The bones, as one DICOM series: frame 0 from the front, frame 1 from behind.
    use dicom_dictionary_std::tags;
    let dir = tmp("turntable-bones-dcm");
    let _ = std::fs::remove_dir_all(&dir);
    let mut all = vec![
        "render",
        "-q",
        "--device",
        "cpu",
        "--turntable",
        "2",
        "--format",
        "dcm",
    ];
    all.extend(size);
    all.extend(["-o", dir.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames: Vec<_> = (0..2)
        .map(|i| dicom_object::open_file(dir.join(format!("frame_{i:03}.dcm"))).unwrap())
        .collect();
    assert_eq!(
        dicom_text(&frames[0], tags::SERIES_INSTANCE_UID),
        dicom_text(&frames[1], tags::SERIES_INSTANCE_UID)
    );
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(dicom_text(f, tags::INSTANCE_NUMBER), format!("{}", i + 1));
    }
    // Anterior: the patient's left on the image's right; from behind, on its left.
    assert_eq!(dicom_text(&frames[0], tags::PATIENT_ORIENTATION), "L\\F");
    assert_eq!(dicom_text(&frames[1], tags::PATIENT_ORIENTATION), "R\\F");
    let out = tmp("turntable-refused");
    let out = out.to_str().unwrap();
    for (args, want) in [
        (
            vec!["render", &spine_rods()[..], "--turntable", "2", "-o", out],
            "the scene sets its camera",
        ),
        (
            vec![
                "render",
                &spot[..],
                "--turntable",
                "2",
                "--aov",
                "depth",
                "-o",
                out,
            ],
            "an AOV is one picture's hits",
        ),
        (
            vec!["render", &spot[..], "--turntable", "2", "-o", "x.png"],
            "into a folder",
        ),
    ] {
        refused(&args, want);
    }
}

/// The GPU's picture `gpu` against the CPU's `cpu` by `rays.py imgdiff` (where Python with
/// its requirements is found): mean < 0.5/255 and ≤ 0.1 % of pixels over 2/255; with a CT
/// `volume` in the scene, mean < 1/255 and p99 ≤ 8/255; and not blank.
fn gpu_frames_match(cpu: &Path, gpu: &Path, name: &str, volume: bool) {
    let Some(py) = python() else { return };
    let d = rays_py(
        &py,
        &[
            "imgdiff",
            cpu.to_str().unwrap(),
            gpu.to_str().unwrap(),
            "--json",
        ],
    );
    assert!(d.status.success(), "imgdiff: {}", stderr(&d));
    let r: serde_json::Value = serde_json::from_str(&stdout(&d)).unwrap();
    let mean = r["mean_abs_diff"].as_f64().unwrap();
    let over = r["frac_gt_2"].as_f64().unwrap();
    let p99 = r["p99_max_channel_diff"].as_f64().unwrap();
    let ok = if volume {
        mean < 1.0 && p99 <= 8.0
    } else {
        mean < 0.5 && over <= 0.001
    };
    assert!(
        ok,
        "{name}: GPU vs CPU mean {mean}/255, p99 {p99}/255, {over} of pixels > 2/255"
    );
    assert!(r["std_a"].as_f64().unwrap() > 5.0, "{name}: a blank image");
}

/// `--view` and `--orbit`: the CT from the patient's left is the front view turned a quarter
/// (within rounding) and differs from the front; a turntable starts at its `--view`; a mesh
/// turned by 0° is the mesh unturned, byte for byte, and by 180° is not; mistakes are named.
#[test]
fn views_and_orbits_turn_the_framing_camera() {
    let render = |name: &str, args: &[&str]| {
        let out = tmp(&format!("view-{name}.png"));
        let mut all = vec!["render", "--size", "48x36", "--quiet", "--device", "cpu"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        image::open(&out).unwrap().to_rgb8()
    };
    let mip = ["--mode", "mip", "--window", "1500", "--level", "300"];
    let with = |extra: &[&'static str]| [&mip[..], extra].concat();
    let left = render("left", &with(&["--view", "left"]));
    let turned = render("turned", &with(&["--view", "anterior", "--orbit", "90"]));
    let front = render("front", &with(&[]));
    let near = left
        .pixels()
        .zip(turned.pixels())
        .filter(|(a, b)| (0..3).all(|c| a[c].abs_diff(b[c]) <= 2))
        .count();
    assert!(near >= 48 * 36 * 99 / 100, "{near} of 1728 pixels alike");
    assert_ne!(left, front);

    let dir = tmp("view-turntable");
    let _ = std::fs::remove_dir_all(&dir);
    let mut all = vec!["render", "--size", "48x36", "--quiet", "--device", "cpu"];
    all.extend_from_slice(&with(&["--view", "superior", "--turntable", "3"]));
    all.extend_from_slice(&["-o", dir.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{}", stderr(&o));
    let superior = render("superior", &with(&["--view", "superior"]));
    assert_eq!(
        image::open(dir.join("frame_000.png")).unwrap().to_rgb8(),
        superior
    );
    assert_ne!(superior, front);

    let bunny = mesh("stanford_bunny.ply");
    let plain = render("bunny", &[&bunny, "--spp", "1", "--max-depth", "1"]);
    let zero = render(
        "bunny-0",
        &[&bunny, "--spp", "1", "--max-depth", "1", "--orbit", "0,0"],
    );
    let back = render(
        "bunny-180",
        &[&bunny, "--spp", "1", "--max-depth", "1", "--orbit=180,-10"],
    );
    assert_eq!(plain, zero);
    assert_ne!(plain, back);
    // From below, the ground is left out and the lights have come round with the camera: the
    // bunny is as brightly lit as from the front (fixed lights would leave it in the dark).
    let below = render(
        "bunny-below",
        &[&bunny, "--spp", "1", "--max-depth", "1", "--orbit=0,-60"],
    );
    // The median brightness of the pixels that are not the background (the commonest value).
    let bright = |img: &image::RgbImage| {
        let v: Vec<u8> = img.pixels().map(|p| p[0].max(p[1]).max(p[2])).collect();
        let mut count = [0usize; 256];
        v.iter().for_each(|&x| count[x as usize] += 1);
        let bg = (0..256).max_by_key(|&i| count[i]).unwrap() as u8;
        let mut object: Vec<u8> = v.into_iter().filter(|x| x.abs_diff(bg) > 3).collect();
        object.sort_unstable();
        assert!(object.len() > 300, "{} object pixels", object.len());
        object[object.len() / 2]
    };
    let (front_b, below_b) = (bright(&plain), bright(&below));
    assert!(
        below_b as f32 >= 0.8 * front_b as f32,
        "from below {below_b}, from the front {front_b}"
    );

    let scene = tmp("view-camera.toml");
    std::fs::write(
        &scene,
        "[camera]\neye = [0, 0, 4]\ntarget = [0, 0, 0]\n[[objects]]\nshape = \"sphere\"\n",
    )
    .unwrap();
    for (args, want) in [
        (
            vec![bunny.as_str(), "--view", "left"],
            "names a side of the patient",
        ),
        (
            vec![scene.to_str().unwrap(), "--orbit", "10"],
            "sets its camera",
        ),
        (
            vec![scene.to_str().unwrap(), "--parallel"],
            "sets its camera",
        ),
        (vec![bunny.as_str(), "--orbit", "0,91"], "past 90 degrees"),
        (vec![bunny.as_str(), "--orbit", "x"], "AZ or AZ,EL"),
        (vec!["--view", "sideways"], "possible values"),
    ] {
        let refused = tmp("refused.png");
        let mut all = vec!["render", "--size", "8x8", "--quiet", "-o"];
        all.push(refused.to_str().unwrap());
        all.extend_from_slice(&args);
        let o = run(&all);
        assert_eq!(o.status.code(), Some(2), "{args:?} should fail");
        let err = stderr(&o);
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// `--parallel`: a MIP of the CT from the patient's left and the bunny, both in a parallel
/// projection, on the GPU as on the CPU.
#[test]
fn gpu_render_matches_cpu_in_a_parallel_projection() {
    gpu_matches_cpu(
        "parallel-mip",
        &[
            "--mode",
            "mip",
            "--window",
            "1500",
            "--level",
            "300",
            "--view",
            "left",
            "--parallel",
            "--size",
            "64x48",
        ],
        true,
    );
    gpu_matches_cpu(
        "parallel-bunny",
        &[
            &mesh("stanford_bunny.ply"),
            "--parallel",
            "--orbit",
            "30,10",
            "--size",
            "64x48",
            "--spp",
            "1",
        ],
        false,
    );
}

/// A scene file's own parallel camera (`parallel_height`): the GPU gives the CPU's picture,
/// and `info` reports the projection.
#[test]
fn gpu_render_matches_cpu_with_a_parallel_scene_camera() {
    let scene = tmp("parallel-camera.toml");
    std::fs::write(
        &scene,
        "[camera]\neye = [2, 1.5, 4]\ntarget = [0, 0.3, 0]\nparallel_height = 2.5\n\
         [[lights]]\nposition = [3, 5, 4]\n[materials.mirror]\nreflectivity = 0.6\n\
         [[objects]]\nshape = \"spot\"\n[[objects]]\nshape = \"sphere\"\nscale = 0.4\n\
         translate = [-1, 0.4, 0]\nmaterial = \"mirror\"\n[ground]\n",
    )
    .unwrap();
    let path = scene.to_str().unwrap();
    let o = run(&["info", path, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(j["camera"]["parallel_height"], 2.5, "{j}");
    assert!(j["camera"]["fov_y_deg"].is_null(), "{j}");
    gpu_matches_cpu(
        "parallel-scene",
        &[path, "--size", "64x48", "--spp", "1"],
        false,
    );
}

/// Direct volume rendering from above the head (the camera's up is the patient's anterior),
/// turned: the GPU gives the CPU's picture.
#[test]
fn gpu_volume_rendering_matches_cpu_from_above() {
    gpu_matches_cpu(
        "superior-dvr",
        &[
            "--mode", "dvr", "--view", "superior", "--orbit", "-40,15", "--size", "64x48",
        ],
        true,
    );
}

/// A CT's bones seen from below the feet (the camera's up is then the patient's anterior),
/// turned and raised: the GPU gives the CPU's picture.
#[test]
fn gpu_render_matches_cpu_from_below() {
    gpu_matches_cpu(
        "view-inferior",
        &[
            "--size", "64x48", "--spp", "1", "--view", "inferior", "--orbit", "30,20",
        ],
        false,
    );
}

/// `bench CT --mode dvr`: an orbit without and with shadows, one JSON line each, on the
/// resampled grid, with samples counted.
#[test]
fn bench_volume_rendering() {
    let ct = builtin_ct();
    let o = run(&[
        "bench",
        &ct,
        "--mode",
        "dvr",
        "--size",
        "32x24",
        "--frames",
        "3",
        "--resample",
        "64",
        "--json",
    ]);
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 2, "{}", stdout(&o));
    for (l, shadows) in lines.iter().zip([false, true]) {
        assert_eq!(l["shadows"], shadows);
        assert_eq!(l["dims"], serde_json::json!([64, 64, 64]));
        assert_eq!(l["frames"], 3);
        assert!(l["samples_per_frame"].as_f64().unwrap() > 1000.0, "{l}");
        assert!(l["frames_per_s"].as_f64().unwrap() > 0.0, "{l}");
        assert_eq!(
            l["shadow_samples_per_frame"].as_u64().unwrap() > 0,
            shadows,
            "{l}"
        );
    }
}

/// `render --aov`: the GPU's ray queries give the CPU's images (the triangle and normal
/// images equal but for ties at shared edges, ≤ 0.1 % of pixels; distances within one grey
/// level); the summary names what was written; `--aov` refuses what a shaded frame needs.
#[test]
fn aovs_on_the_gpu_match_the_cpu() {
    let bunny = mesh("stanford_bunny.ply");
    let devices = devices();
    for aov in ["prim", "normal", "depth"] {
        let mut images = Vec::new();
        for dev in devices {
            let out = tmp(&format!("aov-{aov}-{dev}.png"));
            let o = run(&[
                "render",
                &bunny,
                "--aov",
                aov,
                "--size",
                "96x72",
                "--device",
                dev,
                "-o",
                out.to_str().unwrap(),
            ]);
            assert!(o.status.success(), "{aov} on {dev}: {}", stderr(&o));
            assert!(
                stderr(&o).contains(&format!("(--aov {aov}, 96x72, one ray a pixel)")),
                "{}",
                stderr(&o)
            );
            images.push(image::open(&out).unwrap());
        }
        let cpu = &images[0];
        let (w, h) = (cpu.width() as usize, cpu.height() as usize);
        assert_eq!((w, h), (96, 72));
        if aov == "depth" {
            let c = cpu.to_luma16().into_raw();
            let hits = c.iter().filter(|&&v| v > 0).count();
            assert!(hits > w * h / 4, "{aov}: {hits} hits");
            assert!(
                c.contains(&u16::MAX) && c.contains(&1),
                "{aov}: a full range"
            );
            if let Some(gpu) = images.get(1) {
                let g = gpu.to_luma16().into_raw();
                let off = c
                    .iter()
                    .zip(&g)
                    .filter(|(a, b)| a.abs_diff(**b) > 1)
                    .count();
                assert!(
                    off * 1000 <= w * h,
                    "{aov}: {off} pixels differ by > 1 level"
                );
            }
        } else {
            let c = cpu.to_rgb8().into_raw();
            let lit = c.chunks(3).filter(|p| p != &[0, 0, 0]).count();
            assert!(lit > w * h / 4, "{aov}: {lit} pixels hit");
            if let Some(gpu) = images.get(1) {
                let g = gpu.to_rgb8().into_raw();
                let off = c.chunks(3).zip(g.chunks(3)).filter(|(a, b)| a != b).count();
                assert!(off * 1000 <= w * h, "{aov}: {off} pixels differ");
            }
        }
    }
    let o = run(&["render", &bunny, "--aov", "depth", "--spp", "4"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--spp"), "{}", stderr(&o));
    let o = run(&["render", "--aov", "depth", "--mode", "mip"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--mode"), "{}", stderr(&o));
}

/// A scene scaled by a power of two renders the same picture byte for byte, on both devices:
/// every float the pipeline computes scales exactly with it (framing, kd-tree, traversal,
/// the watertight test, secondary-ray offsets, shading). From 2⁻¹⁰ to 2²⁶ (6.7·10⁷, a ground
/// 40 radii wide reaching 5·10⁹, near the ±10¹⁰ limit of the input checks).
#[test]
fn the_picture_does_not_depend_on_the_scale() {
    let devices = devices();
    let mut first: Option<(String, Vec<u8>)> = None;
    for scale in [1.0f64, 67108864.0, 0.0009765625] {
        let scene = tmp(&format!("scaled-{scale}.toml"));
        std::fs::write(
            &scene,
            format!(
                "[[objects]]\nshape = \"spot\"\nscale = {scale}\n[[objects]]\nshape = \"sphere\"\n\
                 scale = {}\ntranslate = [{}, 0, 0]\nmaterial = \"mirror\"\n[materials.mirror]\n\
                 reflectivity = 0.5\n[ground]\n",
                0.5 * scale,
                1.5 * scale
            ),
        )
        .unwrap();
        for dev in devices {
            for aov in [None, Some("prim"), Some("depth")] {
                let out = tmp(&format!("scaled-{scale}-{dev}-{aov:?}.png"));
                let mut args = vec![
                    "render",
                    scene.to_str().unwrap(),
                    "--size",
                    "64x48",
                    "--device",
                    dev,
                    "-q",
                    "-o",
                    out.to_str().unwrap(),
                ];
                match aov {
                    Some(a) => args.extend(["--aov", a]),
                    None => args.extend(["--spp", "2", "--max-depth", "2"]),
                }
                let o = run(&args);
                assert!(o.status.success(), "{scale} {dev}: {}", stderr(&o));
                let bytes = std::fs::read(&out).unwrap();
                let what = format!("scale {scale}, {dev}, aov {aov:?}");
                if aov.is_none() {
                    match &first {
                        None => first = Some((what, bytes)),
                        Some((w, b)) => assert!(b == &bytes, "{what} differs from {w}"),
                    }
                } else {
                    let reference = tmp(&format!("scaled-1-cpu-{aov:?}.png"));
                    assert!(
                        std::fs::read(reference).unwrap() == bytes,
                        "{what} differs from scale 1 on the CPU"
                    );
                }
            }
        }
    }
}

/// `--window NAME`: radiology's named windows are their width and level, byte for byte; a
/// width needs its level, a name takes none, an unknown name lists the known ones.
#[test]
fn named_windows_are_their_numbers() {
    let render = |name: &str, window: &[&str]| -> std::result::Result<Vec<u8>, String> {
        let out = tmp(&format!("window-{name}.png"));
        let args = [
            "render", "--mode", "slice", "--size", "32x24", "--device", "cpu",
        ];
        let args = [&args[..], window, &["-o", out.to_str().unwrap()]].concat();
        let o = run(&args);
        match o.status.code() {
            Some(0) => Ok(image::open(&out).unwrap().to_rgb8().into_raw()),
            Some(2) => Err(stderr(&o)),
            c => panic!("{window:?}: exit {c:?}: {}", stderr(&o)),
        }
    };
    for (name, w, l) in [
        ("lung", "1500", "-600"),
        ("brain", "80", "40"),
        ("BONE", "1800", "400"),
    ] {
        let named = render(name, &["--window", name]).unwrap();
        let numbers = render(&format!("{name}-n"), &["--window", w, "--level", l]).unwrap();
        assert_eq!(named, numbers, "{name}");
    }
    let lung = render("lung", &["--window", "lung"]).unwrap();
    let soft = render("default", &[]).unwrap();
    assert_ne!(lung, soft, "the slice's default window is not the lung's");
    assert_eq!(
        soft,
        render("abdomen", &["--window", "abdomen"]).unwrap(),
        "the slice's default is the abdomen window"
    );
    for (args, want) in [
        (vec!["--window", "400"], "needs --level"),
        (
            vec!["--window", "lung", "--level", "0"],
            "sets the level too",
        ),
        (vec!["--window", "lungs"], "brain, lung, mediastinum"),
        (vec!["--window=-5", "--level", "0"], "positive number"),
    ] {
        let e = render("refused", &args).unwrap_err();
        assert!(e.contains(want), "{args:?}: {e}");
    }
}

/// A folder with a 2 × 2 square OBJ (texture coordinates (0, 0) at its lower left corner to
/// (1, 1) at its upper right), its MTL, a 2 × 2 texture (red, green over blue, white) and a
/// scene that looks at it head-on in a parallel projection, lit from the camera.
fn textured_square(name: &str, map: Option<&str>) -> std::path::PathBuf {
    let dir = tmp(&format!("textured-square-{name}"));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("square.obj"),
        "mtllib square.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
         vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl paint\nf 1/1 2/2 3/3 4/4\n",
    )
    .unwrap();
    let map = map.map_or(String::new(), |m| format!("map_Kd {m}\n"));
    std::fs::write(
        dir.join("square.mtl"),
        format!("newmtl paint\nKd 1 1 1\nKs 0 0 0\nillum 1\n{map}"),
    )
    .unwrap();
    let mut img = image::RgbaImage::new(2, 2);
    for (x, y, c) in [
        (0, 0, [255, 0, 0]),
        (1, 0, [0, 255, 0]),
        (0, 1, [0, 0, 255]),
        (1, 1, [255, 255, 255]),
    ] {
        img.put_pixel(x, y, image::Rgba([c[0], c[1], c[2], 255]));
    }
    img.save(dir.join("quads.png")).unwrap();
    let scene = dir.join("square.toml");
    std::fs::write(
        &scene,
        "background = [0, 0, 0]\nambient = [0.2, 0.2, 0.2]\n\
         [camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\nparallel_height = 2.4\n\
         [[lights]]\nposition = [0, 0, 10]\n\
         [[objects]]\nmesh = \"square.obj\"\n",
    )
    .unwrap();
    scene
}

/// Renders a textured square's scene (`textured_square`) at 96 × 96, 1 spp, on `dev`, to
/// `out`; it must succeed.
fn render_square(
    scene: &std::path::Path,
    dev: &str,
    out: &std::path::Path,
) -> std::process::Output {
    let o = run(&[
        "render",
        scene.to_str().unwrap(),
        "--size",
        "96x96",
        "--spp",
        "1",
        "--quiet",
        "--device",
        dev,
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// `map_Kd` paints the square: each quarter of the picture shows its texel, u to the right and
/// v up (the image's first row at the top), blended bilinearly only across the middle; the
/// same square without the texture is white. Offset by half the image (`-o`), each quarter
/// shows the opposite texel; three times as large and one back (`-s`, `-o`), the quarters'
/// centres fall outside [0, 1] and wrap to the opposite texel, or with `-clamp on` keep their
/// own. On both devices.
#[test]
fn obj_textures_are_applied_u_right_and_v_up() {
    let (own, opposite, none) = ([0, 1, 2, 3], [3, 2, 1, 0], [4; 4]);
    let white = [1, 1, 1];
    let colours = [[1, 0, 0], [0, 1, 0], [0, 0, 1], white, white];
    for dev in devices() {
        for (k, (map, texels)) in [
            (Some("quads.png"), own),
            (None, none),
            (Some("-o 0.5 0.5 quads.png"), opposite),
            (Some("-s 3 3 -o -1 -1 quads.png"), opposite),
            (Some("-clamp on -s 3 3 -o -1 -1 quads.png"), own),
        ]
        .into_iter()
        .enumerate()
        {
            let scene = textured_square(&format!("{dev}-{k}"), map);
            let out = scene.with_file_name("square.png");
            render_square(&scene, dev, &out);
            let img = image::open(&out).unwrap().to_rgb8();
            // The square spans 80 of the 96 pixels; each quarter's middle lies near its
            // texel's centre, where a neighbour's bilinear weight is a few per cent.
            for ((x, y), texel) in [(28, 28), (68, 28), (28, 68), (68, 68)]
                .into_iter()
                .zip(texels)
            {
                let want = colours[texel];
                let p = img.get_pixel(x, y).0;
                for c in 0..3 {
                    let lit = p[c] > 200;
                    let dark = p[c] < 80;
                    assert!(
                        if want[c] == 1 { lit } else { dark },
                        "{dev}, {map:?}: pixel ({x}, {y}) is {p:?}, expected {want:?}"
                    );
                }
            }
        }
    }
}

/// Spot (../shared's OBJ, with its texture coordinates) under a texture made here (hue bands
/// along u, a checker along v, 64 × 64): the GPU's picture is the CPU's.
#[test]
fn gpu_matches_cpu_on_a_textured_mesh() {
    let dir = tmp("textured-spot");
    std::fs::create_dir_all(&dir).unwrap();
    let obj = std::fs::read_to_string(mesh("spot.obj")).unwrap();
    std::fs::write(
        dir.join("spot.obj"),
        format!("mtllib spot.mtl\nusemtl skin\n{obj}"),
    )
    .unwrap();
    std::fs::write(
        dir.join("spot.mtl"),
        "newmtl skin\nKd 0.9 0.9 0.9\nKs 0.2 0.2 0.2\nNs 30\nillum 2\nmap_Kd skin.png\n",
    )
    .unwrap();
    let skin = image::RgbaImage::from_fn(64, 64, |x, y| {
        let check = if (x / 8 + y / 8) % 2 == 0 { 255 } else { 90 };
        image::Rgba([(x * 4) as u8, (255 - x * 4) as u8, check, 255])
    });
    skin.save(dir.join("skin.png")).unwrap();
    let spot = dir.join("spot.obj");
    let o = run(&["info", "--json", spot.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        info["materials"],
        serde_json::json!([{"name": "skin", "triangles": 5856, "texture": [64, 64]}])
    );
    assert_eq!(info["texture_coordinates"], true);
    assert_eq!(info["warnings"], serde_json::json!([]));
    gpu_matches_cpu(
        "textured-spot",
        &[spot.to_str().unwrap(), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// A glTF base colour texture paints as the same texture through an OBJ's `map_Kd`: the
/// textured square as a GLB (its PNG in the binary chunk, glTF's texture coordinates, whose v
/// runs down the image: 1 − the OBJ's) renders byte for byte as the OBJ with `Kd 1 1 1` and
/// `map_Kd`, on both devices.
#[test]
fn gltf_textures_paint_as_obj_textures() {
    for dev in devices() {
        let scene = textured_square(&format!("gltf-{dev}"), Some("quads.png"));
        let dir = scene.parent().unwrap();
        std::fs::write(
            dir.join("square.mtl"),
            "newmtl paint\nKd 1 1 1\nmap_Kd quads.png\n",
        )
        .unwrap();
        let png = std::fs::read(dir.join("quads.png")).unwrap();
        let mut bin: Vec<u8> = Vec::new();
        for p in [[-1f32, -1., 0.], [1., -1., 0.], [1., 1., 0.], [-1., 1., 0.]] {
            bin.extend(p.iter().flat_map(|x| x.to_le_bytes()));
        }
        for [u, v] in [[0f32, 0.], [1., 0.], [1., 1.], [0., 1.]] {
            bin.extend([u, 1.0 - v].iter().flat_map(|x| x.to_le_bytes()));
        }
        bin.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|x| x.to_le_bytes()));
        let image_at = bin.len();
        bin.extend(&png);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut json = format!(
            r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}],
            "nodes": [{{"mesh": 0}}],
            "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2, "material": 0}}]}}],
            "materials": [{{"name": "paint", "pbrMetallicRoughness": {{"baseColorFactor": [1, 1, 1, 1], "baseColorTexture": {{"index": 0}}}}}}],
            "textures": [{{"source": 0}}],
            "images": [{{"bufferView": 3, "mimeType": "image/png"}}],
            "buffers": [{{"byteLength": {}}}],
            "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
                            {{"buffer": 0, "byteOffset": 48, "byteLength": 32}},
                            {{"buffer": 0, "byteOffset": 80, "byteLength": 12}},
                            {{"buffer": 0, "byteOffset": {image_at}, "byteLength": {}}}],
            "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, -1, 0], "max": [1, 1, 0]}},
                          {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"}},
                          {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}}]}}"#,
            bin.len(),
            png.len()
        )
        .into_bytes();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut glb = b"glTF".to_vec();
        for x in [2, 28 + json.len() + bin.len(), json.len()] {
            glb.extend((x as u32).to_le_bytes());
        }
        glb.extend(b"JSON");
        glb.extend(&json);
        glb.extend((bin.len() as u32).to_le_bytes());
        glb.extend(b"BIN\0");
        glb.extend(&bin);
        std::fs::write(dir.join("square.glb"), glb).unwrap();
        let text = std::fs::read_to_string(&scene).unwrap();
        let gltf_scene = dir.join("square-gltf.toml");
        std::fs::write(&gltf_scene, text.replace("square.obj", "square.glb")).unwrap();
        let pictures: Vec<Vec<u8>> = [&scene, &gltf_scene]
            .iter()
            .map(|s| {
                let out = s.with_extension("png");
                let o = render_square(s, dev, &out);
                assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
                std::fs::read(&out).unwrap()
            })
            .collect();
        assert!(
            pictures[0] == pictures[1],
            "{dev}: the GLB's picture is not the OBJ's"
        );
        // And the texture is there (under the white highlight): red at the top left, green
        // at the top right.
        let img = image::load_from_memory(&pictures[1]).unwrap().to_rgb8();
        let (red, green) = (img.get_pixel(28, 28).0, img.get_pixel(68, 28).0);
        assert!(
            red[0] > red[1] + 80 && green[1] > green[0] + 80,
            "{red:?} {green:?}"
        );
    }
}

/// `render LABELS --segment LIST`: a label map's segments as surfaces, each in its colour
/// (label 1 cyan, 2 magenta, as `--segmentation` tints them), staged as the bones are: on
/// `measure --wall --mask`'s map of the chest CT's aorta, the lumen alone is cyan with no
/// magenta, both show both, seen from the patient's left too; the GPU's picture is the CPU's.
/// A direct volume rendering's `--mode` is refused with it.
#[test]
fn render_draws_a_label_maps_segments() {
    let mask = tmp("render-segments-mask.nii.gz");
    let mask = mask.to_str().unwrap();
    let o = run(&[
        "measure",
        "--quiet",
        &chest(),
        "--path",
        &aorta(),
        "--wall",
        "--mask",
        mask,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // Pixels clearly cyan (green and blue over red) and clearly magenta (red and blue over
    // green).
    let hues = |png: &Path| {
        let img = image::open(png).unwrap().to_rgb8();
        let (mut cyan, mut magenta) = (0, 0);
        for p in img.pixels() {
            let [r, g, b] = p.0.map(i32::from);
            cyan += (g > r + 40 && b > r + 40) as usize;
            magenta += (r > g + 40 && b > g + 40) as usize;
        }
        (cyan, magenta)
    };
    for dev in devices() {
        let size = ["--size", "64x96", "--spp", "1"];
        let lumen = render_to(
            &format!("segments-lumen-{dev}.png"),
            dev,
            &[&[mask, "--segment", "1"][..], &size].concat(),
        );
        let (cyan, magenta) = hues(&lumen);
        assert!(
            cyan > 100 && magenta == 0,
            "{dev}: {cyan} cyan, {magenta} magenta"
        );
        for view in ["anterior", "left"] {
            let both = render_to(
                &format!("segments-both-{view}-{dev}.png"),
                dev,
                &[&[mask, "--segment", "all", "--view", view][..], &size].concat(),
            );
            let (cyan, magenta) = hues(&both);
            assert!(
                cyan > 20 && magenta > 20,
                "{dev} {view}: {cyan} cyan, {magenta} magenta"
            );
        }
    }
    gpu_matches_cpu(
        "segments",
        &[mask, "--segment", "1,2", "--size", "64x96", "--spp", "1"],
        false,
    );
    refused(
        &[
            "render",
            mask,
            "--segment",
            "1",
            "--mode",
            "mip",
            "-o",
            "x.png",
        ],
        "--segment 1 with --mode mip: keeps only those segments of a CT's segmentation: give --segmentation LABELS",
    );
}

/// `render --mode cinematic` (path-traced volume rendering) through the CLI: on each device a
/// picture of bones over the background, the same PNG every run; the GPU's the CPU's but where
/// paths part (the crate's tests hold the two together in detail); a turntable's first frame
/// is the plain picture; the options it has no use for are refused; `--exposure 1` doubles the
/// light exactly, `--anisotropy` changes the picture, and both are checked.
#[test]
fn cinematic_rendering_through_the_cli() {
    let args = [
        "--mode",
        "cinematic",
        "--preset",
        "ct-bones",
        "--size",
        "48x36",
        "--spp",
        "4",
        "--max-depth",
        "2",
    ];
    let mut pictures = Vec::new();
    for dev in devices() {
        let png = |n: u32| {
            let out = render_to(&format!("cinematic-{dev}-{n}.png"), dev, &args);
            image::open(out).unwrap().to_rgb8()
        };
        let first = png(1);
        assert_eq!(first, png(2), "{dev}: the same picture every run");
        // The default background (0.02, 0.025, 0.035) is about (39, 44, 53) in sRGB.
        let bone = first
            .pixels()
            .filter(|p| {
                p.0.iter()
                    .zip([39u8, 44, 53])
                    .any(|(&a, b)| a.abs_diff(b) > 20)
            })
            .count();
        let n = first.pixels().len();
        assert!(
            bone * 20 > n && bone * 2 < n,
            "{dev}: {bone} of {n} pixels show bone"
        );
        pictures.push(first);
    }
    if let [cpu, gpu] = &pictures[..] {
        let (mean, _) = raystream_cpu::srgb8_diff(cpu.as_raw(), gpu.as_raw());
        assert!(mean < 1.5, "GPU vs CPU: mean |diff| {mean}/255");
    }
    let dir = tmp("cinematic-turntable");
    let _ = std::fs::remove_dir_all(&dir);
    render_to(
        "cinematic-turntable",
        "cpu",
        &[&args[..], &["--turntable", "2"]].concat(),
    );
    assert_eq!(
        image::open(dir.join("frame_000.png")).unwrap().to_rgb8(),
        image::open(tmp("cinematic-cpu-1.png")).unwrap().to_rgb8()
    );
    fn render<'a>(more: &[&'a str]) -> Vec<&'a str> {
        [&["render", "--mode", "cinematic"][..], more].concat()
    }
    refused(&render(&["--shadows"]), "always casts shadows");
    refused(&render(&["--step", "0.5"]), "has none");
    refused(&render(&["--no-skip"]), "has none");
    refused(
        &render(&["--path", &aorta(), "--size", "32x24"]),
        "not --mode cinematic",
    );
    refused(
        &["render", "--mode", "dvr", "--spp", "4", "--size", "32x24"],
        "--spp with --mode dvr",
    );
    refused(
        &["render", "--spp", "2000", "--size", "32x24"],
        "at most 1024 samples a pixel for meshes",
    );
    // --light turns the key light: lit from the camera the bones are brighter than lit from
    // behind (the sky alone then), on both sides of the default.
    let mean = |png: std::path::PathBuf| {
        let img = image::open(png).unwrap().to_rgb8();
        img.as_raw().iter().map(|&v| v as f64).sum::<f64>() / img.as_raw().len() as f64
    };
    let lit = |light: &str| {
        mean(render_to(
            &format!("cinematic-light-{light}.png"),
            "cpu",
            &[&args[..], &[&format!("--light={light}")]].concat(),
        ))
    };
    let (front, back) = (lit("0,0"), lit("180,0"));
    let default = mean(tmp("cinematic-cpu-1.png"));
    assert!(
        front > default && default > back,
        "{front} {default} {back}"
    );
    refused(
        &[
            "render", "--mode", "dvr", "--light", "10,20", "--size", "32x24",
        ],
        "--light places the key light",
    );
    refused(
        &["render", "--light", "10,20", "--size", "32x24"],
        "--light goes with --mode (direct volume rendering)",
    );
    // Every flag of the volume's look is refused without --mode, each named.
    refused(
        &[
            "render",
            "--denoise",
            "--exposure",
            "1",
            "--anisotropy",
            "0.5",
            "--interpolation",
            "cubic",
            "--size",
            "32x24",
        ],
        "--denoise, --anisotropy, --exposure, --interpolation go with --mode",
    );
    // --exposure +1 doubles the light exactly (the same paths; premultiplied EXRs, the
    // background apart); --anisotropy makes another picture; both refused out of range or
    // with the other modes.
    let film = |name: &str, more: &[&str]| {
        let exr =
            raystream_cpu::load_exr(&render_to(name, "cpu", &[&args[..], more].concat())).unwrap();
        exr.channels["G"].as_f32().unwrap().to_vec()
    };
    let (base, brighter) = (
        film("cinematic-ev0.exr", &[]),
        film("cinematic-ev1.exr", &["--exposure", "1"]),
    );
    assert!(base.iter().any(|&v| v > 0.0));
    for (b, e) in base.iter().zip(&brighter) {
        assert_eq!(*e, 2.0 * b);
    }
    let forward = film("cinematic-g.exr", &["--anisotropy", "0.8"]);
    assert_ne!(forward, base, "--anisotropy 0.8 changes the picture");
    refused(
        &[&render(&["--size", "32x24"])[..], &["--anisotropy", "0.99"]].concat(),
        "from -0.95 to 0.95",
    );
    refused(
        &[&render(&["--size", "32x24"])[..], &["--exposure", "12"]].concat(),
        "stops from -10 to 10",
    );
    refused(
        &[
            "render",
            "--mode",
            "dvr",
            "--exposure",
            "1",
            "--size",
            "32x24",
        ],
        "--exposure sets the light of --mode cinematic",
    );
    refused(
        &[
            "render",
            "--mode",
            "mip",
            "--anisotropy",
            "0.5",
            "--size",
            "32x24",
        ],
        "--anisotropy sets the light of --mode cinematic",
    );
}

/// `--denoise` through the CLI on the built-in CT (ct-muscle, 128×96): at 8 paths a pixel the
/// denoised picture is under 0.6× as far from a 256-path one as the raw picture is (mean sRGB
/// difference; measured 1.8 against 4.8/255 on both devices); the same PNG every run; the
/// GPU's within 1.5/255 of the CPU's (one filter in two languages, the same paths but where the
/// f16 texture tips them); a premultiplied EXR over the background is the PNG; and --denoise
/// without --mode cinematic, or with one path a pixel, is refused.
#[test]
fn denoised_cinematic_rendering_through_the_cli() {
    let args = [
        "--mode",
        "cinematic",
        "--preset",
        "ct-muscle",
        "--size",
        "128x96",
        "--max-depth",
        "2",
    ];
    let with = |more: &[&'static str]| [&args[..], more].concat();
    let png = |name: &str, dev: &str, more: &[&'static str]| {
        image::open(render_to(name, dev, &with(more)))
            .unwrap()
            .to_rgb8()
    };
    let mean_diff = |a: &image::RgbImage, b: &image::RgbImage| {
        raystream_cpu::srgb8_diff(a.as_raw(), b.as_raw()).0
    };
    let truth = png("denoise-truth.png", "cpu", &["--spp", "256"]);
    let mut denoised = Vec::new();
    for dev in devices() {
        let raw = png(&format!("denoise-raw-{dev}.png"), dev, &["--spp", "8"]);
        let clean = png(
            &format!("denoise-{dev}.png"),
            dev,
            &["--spp", "8", "--denoise"],
        );
        let again = png(
            &format!("denoise-{dev}-2.png"),
            dev,
            &["--spp", "8", "--denoise"],
        );
        assert_eq!(clean, again, "{dev}: the same picture every run");
        let (before, after) = (mean_diff(&raw, &truth), mean_diff(&clean, &truth));
        eprintln!(
            "{dev}: mean |diff| from 256 paths: raw {before:.3}/255, denoised {after:.3}/255"
        );
        assert!(
            after < 0.8 * before,
            "{dev}: raw {before}, denoised {after}"
        );
        denoised.push(clean);
    }
    if let [cpu, gpu] = &denoised[..] {
        let d = mean_diff(cpu, gpu);
        assert!(d < 1.5, "GPU vs CPU denoised: mean |diff| {d}/255");
    }
    // The EXR's premultiplied light over the default background is the PNG.
    let exr = raystream_cpu::load_exr(&render_to(
        "denoise.exr",
        "cpu",
        &with(&["--spp", "8", "--denoise"]),
    ))
    .unwrap();
    let channel = |c: &str| exr.channels[c].as_f32().unwrap().to_vec();
    let (r, g, b, a) = (channel("R"), channel("G"), channel("B"), channel("A"));
    let background = raystream_cpu::dvr::DvrOptions::default().background;
    let over = raystream_cpu::Image {
        width: exr.width,
        height: exr.height,
        pixels: (0..r.len())
            .map(|i| raystream_math::Vec3::new(r[i], g[i], b[i]) + (1.0 - a[i]) * background)
            .collect(),
    };
    let (mean, worst) = raystream_cpu::srgb8_diff(&over.to_srgb8(), denoised[0].as_raw());
    assert!(
        mean < 0.1 && worst.iter().all(|&d| d <= 1),
        "EXR over the background vs PNG: mean {mean}"
    );
    refused(
        &["render", "--mode", "dvr", "--denoise", "--size", "32x24"],
        "--denoise filters the noise of --mode cinematic",
    );
    refused(
        &[
            "render",
            "--mode",
            "cinematic",
            "--denoise",
            "--spp",
            "1",
            "--size",
            "32x24",
        ],
        "at least 2 paths a pixel",
    );
}

/// `--interpolation`: dvr, iso and cinematic read the volume by the cubic B-spline unless told
/// otherwise, mip and slice trilinearly, and the summary line says which. On each device the
/// default dvr picture is `--interpolation cubic`'s byte for byte and not the trilinear one;
/// the devices agree on it; an EXR's comments name it; `bench` reports it; an unknown value
/// is refused.
#[test]
fn interpolation_through_the_cli() {
    let summary = |args: &[&str]| {
        let out = tmp("interpolation-summary.png");
        let mut all = vec!["render", "--device", "cpu", "--size", "32x24"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{all:?}: {}", stderr(&o));
        stderr(&o)
    };
    for (args, want) in [
        (&["--mode", "dvr"][..], "--mode dvr, cubic B-spline"),
        (&["--mode", "iso"][..], "--mode iso, cubic B-spline"),
        (
            &["--mode", "cinematic", "--spp", "2"][..],
            "--mode cinematic, cubic B-spline",
        ),
        (&["--mode", "mip"][..], "--mode mip, trilinear"),
        (&["--mode", "slice"][..], "--mode slice, trilinear"),
        (
            &["--mode", "dvr", "--interpolation", "linear"][..],
            "--mode dvr, trilinear",
        ),
        (
            &["--mode", "mip", "--interpolation", "cubic"][..],
            "--mode mip, cubic B-spline",
        ),
        (
            &["--mode", "slice", "--interpolation", "cubic-interpolating"][..],
            "--mode slice, interpolating cubic B-spline",
        ),
    ] {
        let e = summary(args);
        assert!(e.contains(want), "{args:?}: {e}");
    }
    let args = ["--mode", "dvr", "--preset", "ct-muscle", "--size", "96x72"];
    let png = |name: &str, dev: &str, more: &[&str]| {
        image::open(render_to(name, dev, &[&args[..], more].concat()))
            .unwrap()
            .to_rgb8()
    };
    let mut cubic = Vec::new();
    for dev in devices() {
        let default = png(&format!("interp-default-{dev}.png"), dev, &[]);
        let asked = png(
            &format!("interp-cubic-{dev}.png"),
            dev,
            &["--interpolation", "cubic"],
        );
        let linear = png(
            &format!("interp-linear-{dev}.png"),
            dev,
            &["--interpolation", "linear"],
        );
        assert_eq!(default, asked, "{dev}: the default is cubic");
        let (mean, _) = raystream_cpu::srgb8_diff(default.as_raw(), linear.as_raw());
        assert!(mean > 0.5, "{dev}: cubic and trilinear differ: {mean}/255");
        cubic.push(default);
    }
    if let [cpu, gpu] = &cubic[..] {
        let (mean, worst) = raystream_cpu::srgb8_diff(cpu.as_raw(), gpu.as_raw());
        let close = worst.iter().filter(|&&d| d <= 2).count() as f64 / worst.len() as f64;
        assert!(
            mean < 0.5 && close >= 0.999,
            "GPU vs CPU: {mean}/255, {close}"
        );
    }
    let exr = render_to("interp.exr", "cpu", &args);
    let comments = raystream_cpu::load_exr(&exr).unwrap().comments;
    assert!(
        comments.contains("interpolation cubic B-spline"),
        "{comments}"
    );
    let ct = builtin_ct();
    // bench JSON names the interpolation, times the warm-up frame that builds the tables,
    // and the interpolating spline's coefficients apart (null for the others).
    for interpolation in ["linear", "cubic-interpolating"] {
        let o = run(&[
            "bench",
            &ct,
            "--mode",
            "dvr",
            "--device",
            "cpu",
            "--size",
            "32x24",
            "--frames",
            "1",
            "--interpolation",
            interpolation,
            "--json",
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        for line in stdout(&o).lines() {
            let v: serde_json::Value = serde_json::from_str(line).unwrap();
            assert_eq!(v["interpolation"], interpolation, "{line}");
            assert!(v["first_frame_ms"].as_f64().unwrap() > 0.0, "{line}");
            let coefficients = v["coefficients_ms"].as_f64();
            if interpolation == "linear" {
                assert!(v["coefficients_ms"].is_null(), "{line}");
            } else {
                assert!(coefficients.unwrap() > 0.0, "{line}");
            }
        }
    }
    refused(
        &["render", "--mode", "dvr", "--interpolation", "tricubic"],
        "invalid value 'tricubic'",
    );
}

/// The chest CT's maximum intensity projection from the front in parallel projection (HU in
/// an EXR, two pixels a voxel column each way), against the voxels' own MIP along the same
/// axis (each column's brightest voxel), at the 99th percentile (ribs' cortex, spine, stents):
/// the approximating cubic B-spline's blur sits furthest below the voxels', trilinear below
/// them too (a ray runs between voxel centres), the interpolating spline closest (it passes
/// through every voxel). Its ringing shows at the very top: next to the stents' metal it
/// overshoots the brightest voxel in the volume. On either device.
#[test]
fn the_interpolating_spline_keeps_the_peaks_a_mip_shows() {
    let ct = chest();
    let vol = raystream_io::load_volume(Path::new(&ct), &Default::default()).unwrap();
    let [nx, ny, nz] = vol.dims;
    // The chest CT's axes are L, P, S: a front view looks along j.
    assert_eq!(
        vol.direction,
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    let p99 = |mut v: Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() * 99 / 100]
    };
    let columns: Vec<f32> = (0..nz)
        .flat_map(|k| (0..nx).map(move |i| (i, k)))
        .map(|(i, k)| (0..ny).map(|j| vol.at(i, j, k)).fold(f32::MIN, f32::max))
        .collect();
    let voxels = p99(columns);
    let brightest = vol.data.iter().cloned().fold(f32::MIN, f32::max);
    let size = format!("{}x{}", 2 * nx, 2 * nz);
    for dev in devices() {
        let mip = |interpolation: &str| {
            let exr = render_to(
                &format!("mip-peaks-{interpolation}-{dev}.exr"),
                dev,
                &[
                    &ct,
                    "--mode",
                    "mip",
                    "--view",
                    "anterior",
                    "--parallel",
                    "--size",
                    &size,
                    "--interpolation",
                    interpolation,
                ],
            );
            let e = raystream_cpu::load_exr(&exr).unwrap();
            let hu: Vec<f32> = e.channels["Y"]
                .as_f32()
                .unwrap()
                .iter()
                .cloned()
                .filter(|v| !v.is_nan())
                .collect();
            let max = hu.iter().cloned().fold(f32::MIN, f32::max);
            (p99(hu), max)
        };
        let (linear, cubic, sharp) = (mip("linear"), mip("cubic"), mip("cubic-interpolating"));
        // Measured (HU, p99 and max; CPU and lavapipe within 1 HU): voxels 3087 (3343 at
        // most), trilinear 2922 and 3200, cubic 2643 and 3074, interpolating 3212 and 4175.
        let msg = format!(
            "{dev}: p99 and max HU: voxels {voxels} ({brightest}), trilinear {linear:?}, cubic {cubic:?}, interpolating {sharp:?}"
        );
        assert!(cubic.0 < linear.0 && linear.0 < voxels, "{msg}");
        assert!(
            (sharp.0 - voxels).abs() < (linear.0 - voxels).abs(),
            "{msg}"
        );
        assert!(sharp.1 > brightest, "{msg}");
    }
}

/// Every file of `mesh_colours.py` (VTK's PLY, VTK XML and legacy VTK writers, per point and
/// per cell; an OBJ, float and 16-bit PLYs, trimesh's GLB) reads with the colours its writer
/// gave it: each triangle corner's colour is its point's (the nearest of the points the script
/// lists), or each triangle's is its cell's (the nearest cell centroid), exactly; within one
/// step for the GLB, whose linear COLOR_0 bytes turn to sRGB by way of f64. The VTK files'
/// `SPACE` field (3D Slicer's) is read, ASCII, binary or compressed.
#[test]
fn mesh_colours_read_as_their_writers_wrote_them() {
    let Some(py) = python_with("vtkmodules") else {
        return;
    };
    let dir = tmp("mesh-colours");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/mesh_colours.py"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let files = v["files"].as_object().unwrap();
    assert_eq!(files.len(), 28);
    let rows = |v: &serde_json::Value| -> Vec<([f32; 3], [u8; 3])> {
        let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).unwrap();
        rows.iter()
            .map(|r| {
                (
                    [r[0] as f32, r[1] as f32, r[2] as f32],
                    [r[3] as u8, r[4] as u8, r[5] as u8],
                )
            })
            .collect()
    };
    let nearest = |rows: &[([f32; 3], [u8; 3])], p: raystream_math::Vec3| {
        let d = |q: [f32; 3]| (raystream_math::Vec3::from(q) - p).length();
        let best = rows
            .iter()
            .min_by(|a, b| d(a.0).total_cmp(&d(b.0)))
            .unwrap();
        assert!(d(best.0) < 1e-3, "no listed point within 1 µm of {p}");
        best.1
    };
    for (name, want) in files {
        let (mesh, shading) = raystream_io::load_mesh_with_shading(&dir.join(name)).unwrap();
        assert_eq!(mesh.len(), 320, "{name}");
        assert_eq!(shading.colours.len(), mesh.len(), "{name}: no colours read");
        // The VTK files' field data names 3D Slicer's RAS (a string array, which the legacy
        // files hold as text or length-prefixed bytes).
        if name.ends_with(".vtp") || name.ends_with(".vtk") {
            let want = (!name.starts_with("verts")).then_some(raystream_io::PatientSpace::Ras);
            assert_eq!(shading.space, want, "{name}");
        }
        let step = if name.ends_with(".glb") { 1 } else { 0 };
        let close = |a: [u8; 3], b: [u8; 3]| (0..3).all(|c| a[c].abs_diff(b[c]) <= step);
        if let Some(points) = want.get("points") {
            let points = rows(points);
            for (t, corners) in mesh.triangles.iter().zip(&shading.colours) {
                for (k, &v) in t.iter().enumerate() {
                    let w = nearest(&points, mesh.positions[v as usize]);
                    assert!(close(corners[k], w), "{name}: {:?} for {w:?}", corners[k]);
                }
            }
        } else {
            let cells = rows(&want["cells"]);
            for (t, corners) in mesh.triangles.iter().zip(&shading.colours) {
                let centroid = t
                    .iter()
                    .map(|&v| mesh.positions[v as usize])
                    .sum::<raystream_math::Vec3>()
                    / 3.0;
                let w = nearest(&cells, centroid);
                assert!(
                    corners.iter().all(|&c| c == w),
                    "{name}: {corners:?} for {w:?}"
                );
            }
        }
    }
}

/// A sphere as an ASCII PLY whose vertices run from red (x = −1) to blue (x = +1), green
/// rising with y.
fn colour_ramp_sphere(name: &str) -> std::path::PathBuf {
    let m = raystream_io::TriMesh::icosphere(3);
    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.len()
    );
    for p in &m.positions {
        let byte = |t: f32| (t.clamp(0.0, 1.0) * 255.0).round() as u8;
        let x = (p.x + 1.0) / 2.0;
        let (r, g, b) = (byte(1.0 - x), byte((p.y + 1.0) / 4.0), byte(x));
        ply += &format!("{} {} {} {r} {g} {b}\n", p.x, p.y, p.z);
    }
    for t in &m.triangles {
        ply += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
    }
    let path = tmp(name);
    std::fs::write(&path, ply).unwrap();
    path
}

/// A PLY's vertex colours are drawn, blended across each triangle: the sphere is red on its
/// −x side and blue on its +x side, purple between (with the colours left out, it is grey).
#[test]
fn vertex_colours_are_rendered() {
    let ply = colour_ramp_sphere("colour-ramp.ply");
    let out = tmp("colour-ramp.png");
    let o = run(&[
        "render",
        ply.to_str().unwrap(),
        "--size",
        "96x72",
        "--spp",
        "1",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    let columns = |f: &dyn Fn(&image::Rgb<u8>) -> bool| {
        let xs: Vec<u32> = img
            .enumerate_pixels()
            .filter(|(_, _, p)| f(p))
            .map(|(x, _, _)| x)
            .collect();
        (
            xs.len(),
            xs.iter().sum::<u32>() as f64 / xs.len().max(1) as f64,
        )
    };
    let red = columns(&|p| p[0] > 60 && p[0] as u32 > 2 * p[2] as u32);
    let blue = columns(&|p| p[2] > 60 && p[2] as u32 > 2 * p[0] as u32);
    let purple =
        columns(&|p| p[0] > 40 && p[2] > 40 && p[0].abs_diff(p[2]) < 25 && p[1] < p[0].min(p[2]));
    for (what, (n, _)) in [("red", red), ("blue", blue), ("purple", purple)] {
        assert!(n > 100, "{n} {what} pixels");
    }
    // Red on the left (the scene's −x), purple in between, blue on the right.
    assert!(
        red.1 + 10.0 < purple.1 && purple.1 + 10.0 < blue.1,
        "mean columns: red {:.1}, purple {:.1}, blue {:.1}",
        red.1,
        purple.1,
        blue.1
    );
}

#[test]
fn gpu_matches_cpu_on_vertex_colours() {
    let ply = colour_ramp_sphere("colour-ramp-gpu.ply");
    gpu_matches_cpu(
        "vertex-colours",
        &[ply.to_str().unwrap(), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// 3D Slicer's segmentation of a chest CT, as slicerio ships it (`None`: slicerio is not
/// installed here).
fn slicer_chest_segmentation() -> Option<String> {
    let py = python_with("slicerio")?;
    let o = std::process::Command::new(&py)
        .args([
            "-c",
            "import os, slicerio; print(os.path.join(os.path.dirname(slicerio.__file__), 'data', 'Segmentation.seg.nrrd'))",
        ])
        .output()
        .unwrap();
    Some(stdout(&o).trim().to_string())
}

/// `iso SEG [ARGS] --simplify 0.5 -o OUT` (every segment of the segmentation `seg` unless
/// `args` picks some).
fn iso_segments(seg: &str, args: &[&str], out: &Path) {
    let mut all = vec!["iso", "--quiet", seg];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--simplify", "0.5", "-o", out.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `render MESH` on the CPU, 96×72, a sample a pixel, to `png`.
fn render_small_on_cpu(mesh: &Path, png: &Path) {
    let o = run(&[
        "render",
        mesh.to_str().unwrap(),
        "--size",
        "96x72",
        "--spp",
        "1",
        "--quiet",
        "--device",
        "cpu",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// 3D Slicer's segmentation of a chest CT (slicerio's), its segments' surfaces written by
/// `iso` as a PLY, a legacy VTK and a VTK XML file (each vertex in its segment's colour) and as an OBJ
/// (each segment's colour a material of its MTL), render alike: the colours reach the image
/// (left out, the segments are grey and the images differ by far more), and the `.vtp`'s
/// `SPACE` field stands it up as the others' `SPACE=LPS` comments do.
#[test]
fn iso_segments_render_in_their_colours_from_ply_vtk_and_vtp_as_from_obj() {
    let Some(seg) = slicer_chest_segmentation() else {
        return;
    };
    let image = |ext: &str| {
        let mesh = tmp(&format!("slicer-segments.{ext}"));
        iso_segments(&seg, &[], &mesh);
        let png = tmp(&format!("slicer-segments-{ext}.png"));
        render_small_on_cpu(&mesh, &png);
        (mesh, png)
    };
    let (ply, from_ply) = image("ply");
    let (_, from_obj) = image("obj");
    let (_, from_vtp) = image("vtp");
    let (_, from_vtk) = image("vtk");
    // Slicer's seven segments, seven colours.
    let o = run(&["info", ply.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["colours"], serde_json::json!({"distinct": 7}));
    gpu_frames_match(&from_obj, &from_ply, "the PLY against the OBJ", false);
    // The .vtp's colours, and its space in the field data.
    gpu_frames_match(&from_obj, &from_vtp, "the VTP against the OBJ", false);
    gpu_frames_match(&from_obj, &from_vtk, "the VTK against the OBJ", false);
    let img = image::open(&from_ply).unwrap().to_rgb8();
    let tinted = img
        .pixels()
        .filter(|p| p[0].max(p[1]).max(p[2]) - p[0].min(p[1]).min(p[2]) > 40)
        .count();
    assert!(tinted > 500, "{tinted} coloured pixels");
    gpu_matches_cpu(
        "slicer-segments",
        &[ply.to_str().unwrap(), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// `iso --segment NAME -o X.stl` writes the segment's colour as Materialise's software and
/// Assimp read it; raystream reads it back and draws it, on both devices.
#[test]
fn an_iso_stl_carries_its_segments_colour() {
    let Some(seg) = slicer_chest_segmentation() else {
        return;
    };
    let stl = tmp("slicer-ribs.stl");
    iso_segments(&seg, &["--segment", "ribs"], &stl);
    // Slicer's ribs are #fde89e: every corner, exactly.
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&stl).unwrap();
    assert!(mesh.len() > 1000);
    assert_eq!(shading.colours, vec![[[0xfd, 0xe8, 0x9e]; 3]; mesh.len()]);
    let o = run(&["info", stl.to_str().unwrap(), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["colours"], serde_json::json!({"distinct": 1}));
    let png = tmp("slicer-ribs-stl.png");
    render_small_on_cpu(&stl, &png);
    // Lit bone-yellow: red over blue by more than the grey of an uncoloured mesh allows.
    let img = image::open(&png).unwrap().to_rgb8();
    let yellow = img
        .pixels()
        .filter(|p| p[0] as i32 - p[2] as i32 > 30 && p[1] > p[2])
        .count();
    assert!(yellow > 300, "{yellow} yellow pixels");
    gpu_matches_cpu(
        "slicer-ribs-stl",
        &[stl.to_str().unwrap(), "--size", "96x72", "--spp", "1"],
        false,
    );
}

/// 3MF, against lib3mf (the 3MF Consortium's library): its files (a build of a plain cube,
/// a components object placing a base-material tetrahedron twice, once mirrored, and a
/// colour-group one, in centimetres; a cube in inches) read as lib3mf places their triangles,
/// in millimetres (within 1 µm), each with the colours lib3mf resolves for its corners (the
/// cube grey); and `iso --segment all -o X.3mf` of 3D Slicer's chest segmentation reads in
/// lib3mf as an object a segment, named and in its colour, in millimetres, with the OBJ's
/// triangles, each manifold and oriented. The coloured build renders alike on both devices.
#[test]
fn three_mf_reads_and_writes_as_lib3mf_does() {
    let Some(py) = python_with("lib3mf") else {
        return;
    };
    let Some(seg) = slicer_chest_segmentation() else {
        return;
    };
    let dir = tmp("three-mf");
    std::fs::create_dir_all(&dir).unwrap();
    let (written, obj) = (dir.join("segments.3mf"), dir.join("segments.obj"));
    iso_segments(&seg, &[], &written);
    iso_segments(&seg, &[], &obj);
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/three_mf.py"))
        .arg(&dir)
        .arg(&written)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    for name in ["parts", "plain"] {
        let path = v[name]["path"].as_str().unwrap();
        let want = v[name]["triangles"].as_array().unwrap();
        let (mesh, shading) = raystream_io::load_mesh_with_shading(Path::new(path)).unwrap();
        assert_eq!(mesh.len(), want.len(), "{name}");
        let coloured = want.iter().any(|t| !t["colours"].is_null());
        assert_eq!(!shading.colours.is_empty(), coloured, "{name}");
        for (i, t) in want.iter().enumerate() {
            let corners: Vec<[f64; 3]> = serde_json::from_value(t["corners"].clone()).unwrap();
            for (got, want) in mesh.corners(i).iter().zip(&corners) {
                let d = (got.as_dvec3() - raystream_math::DVec3::from(*want)).length();
                assert!(d < 1e-3, "{name} triangle {i}: {got} for {want:?}");
            }
            if coloured {
                let want: [[u8; 3]; 3] = match t["colours"].is_null() {
                    true => [raystream_io::UNCOLOURED_GREY; 3],
                    false => serde_json::from_value(t["colours"].clone()).unwrap(),
                };
                assert_eq!(shading.colours[i], want, "{name} triangle {i}");
            }
        }
    }
    // Every kind of colour there: the cube's grey, the base material, the group's, a corner's.
    let parts = v["parts"]["triangles"].as_array().unwrap();
    assert_eq!(parts.len(), 12 + 3 * 4 + 4);
    assert!(parts[12]["colours"][0] == serde_json::json!([200, 30, 20]));

    // raystream's package, as lib3mf reads it: the OBJ's segments, names, colours, triangles.
    let w = &v["written"];
    assert_eq!(w["unit_mm"], 1.0);
    let (obj_mesh, obj_shading) = raystream_io::load_mesh_with_shading(&obj).unwrap();
    let o = run(&["info", &seg, "--json"]);
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let objects = w["objects"].as_array().unwrap();
    assert_eq!(objects.len(), obj_shading.materials.len());
    assert_eq!(objects.len(), 7);
    let mut triangles = 0;
    for (k, (o, m)) in objects.iter().zip(&obj_shading.materials).enumerate() {
        // The segment's own name (the OBJ's has its spaces as underscores).
        assert_eq!(o["name"], info["segments"][k]["label"]);
        assert_eq!(o["name"].as_str().unwrap().replace(' ', "_"), m.name);
        assert_eq!(o["colour"], info["segments"][k]["colour"], "{}", m.name);
        let count = obj_shading
            .material_of
            .iter()
            .filter(|&&x| x == Some(k as u32))
            .count();
        assert_eq!(
            o["triangles"].as_u64().unwrap() as usize,
            count,
            "{}",
            m.name
        );
        // Printable: closed and oriented, simplified as it is (the body's thin wall once had
        // two edges pinched by the collapses).
        assert_eq!(o["manifold"], true, "{}", m.name);
        triangles += count;
    }
    assert_eq!(triangles, obj_mesh.len());
    // Read back by raystream: `info` lists the objects lib3mf finds, by name, with their
    // triangles; and the OBJ's triangles, in order, each in its segment's colour.
    let o = run(&["info", written.to_str().unwrap(), "--json"]);
    let read: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let read = read["objects"].as_array().unwrap();
    assert_eq!(read.len(), objects.len());
    for (r, o) in read.iter().zip(objects) {
        assert_eq!((&r["name"], &r["triangles"]), (&o["name"], &o["triangles"]));
    }
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&written).unwrap();
    assert_eq!(mesh.len(), obj_mesh.len());
    for i in 0..mesh.len() {
        assert_eq!(mesh.corners(i), obj_mesh.corners(i), "triangle {i}");
        let k = obj_shading.material_of[i].unwrap() as usize;
        let want: [u8; 3] = serde_json::from_value(info["segments"][k]["colour"].clone()).unwrap();
        assert_eq!(shading.colours[i], [want; 3], "triangle {i}");
    }

    gpu_matches_cpu(
        "three-mf-parts",
        &[
            v["parts"]["path"].as_str().unwrap(),
            "--size",
            "96x72",
            "--spp",
            "1",
        ],
        false,
    );
}

/// `render --mode dvr --body-only` of the J2K series seen from below (the feet), and a scene
/// file's `[volume]` with `body_only = true`: the table's curved top, under the body in the
/// plain picture, is gone, and the body is drawn as it was. On both devices.
#[test]
fn dvr_body_only_leaves_out_the_table() {
    let ct = shared().join("data/volumes/dicom/abdomen_ct_j2k_totalseg");
    let ct = ct.to_str().unwrap();
    // A scene of the CT and a sphere in it, with the body alone or not.
    let scene = |body: bool| {
        let file = tmp(&format!("body-scene-{body}.toml"));
        let text = format!(
            "[volume]\npath = {ct:?}\npreset = \"ct-muscle\"\nbody_only = {body}\n[[objects]]\nshape = \"sphere\"\nframe = \"lps\"\nscale = 10\ntranslate = [0, -150, -785]\n"
        );
        std::fs::write(&file, text).unwrap();
        file.to_string_lossy().into_owned()
    };
    let (plain_scene, body_scene) = (scene(false), scene(true));
    for dev in devices() {
        let picture = |name: &str, args: &[&str]| {
            let args = [args, &["--view", "inferior", "--size", "96x96"]].concat();
            let png = render_to(&format!("{name}-{dev}.png"), dev, &args);
            let rgb = image::open(&png).unwrap().to_rgb8();
            let background = *rgb.get_pixel(0, 0);
            let w = rgb.width() as usize;
            let drawn: Vec<bool> = (rgb.pixels())
                .map(|p| p.0.iter().zip(background.0).any(|(a, b)| a.abs_diff(b) > 8))
                .collect();
            (w, rgb.into_raw(), drawn)
        };
        let dvr = [ct, "--mode", "dvr", "--preset", "ct-muscle"];
        for (what, plain_args, body_args) in [
            ("dvr", dvr.to_vec(), [&dvr[..], &["--body-only"]].concat()),
            (
                "scene",
                vec![plain_scene.as_str()],
                vec![body_scene.as_str()],
            ),
        ] {
            let (w, plain, all) = picture(&format!("body-{what}-plain"), &plain_args);
            let (_, body, kept) = picture(&format!("body-{what}-only"), &body_args);
            // The body's pixels, drawn alike (within 2/255 but for a rim).
            let both: Vec<usize> = (0..kept.len()).filter(|&n| kept[n]).collect();
            assert!(
                both.iter().all(|&n| all[n]),
                "{dev} {what}: drawn where the whole CT is not"
            );
            let alike = (both.iter())
                .filter(|&&n| (0..3).all(|c| plain[3 * n + c].abs_diff(body[3 * n + c]) <= 2))
                .count();
            assert!(
                alike as f64 > 0.95 * both.len() as f64,
                "{dev} {what}: {alike} of {} alike",
                both.len()
            );
            // The table: drawn in the whole CT's picture only, each pixel under the body's
            // pixels in its column (the top's curved sides rise beside the arms).
            let gone: Vec<usize> = (0..all.len()).filter(|&n| all[n] && !kept[n]).collect();
            let mut lowest = vec![0; w];
            for &n in &both {
                lowest[n % w] = lowest[n % w].max(n / w);
            }
            let over = gone.iter().filter(|&&n| n / w <= lowest[n % w]).count();
            assert!(
                gone.len() > 300 && over == 0,
                "{dev} {what}: {} pixels gone, {over} not under the body",
                gone.len()
            );
        }
    }
}
