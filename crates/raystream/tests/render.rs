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
}

#[test]
fn bench_json_lines() {
    let o = run(&[
        "bench",
        &mesh("spot.obj"),
        "--size",
        "64x48",
        "--repeat",
        "1",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<serde_json::Value> = stdout(&o)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let kinds: Vec<&str> = lines.iter().map(|l| l["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["primary", "shadow", "diffuse"]);
    for l in &lines {
        assert!(l["rays"].as_u64().unwrap() > 1000);
        assert!(l["mrays_per_s"].as_f64().unwrap() > 0.0);
        assert!(l["inner_per_ray"].as_f64().unwrap() > 0.0);
        assert!(l["hits"].as_u64().unwrap() > 0);
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
    let Some(py) = python() else { return };
    let path = |dev: &str| tmp(&format!("gpu-vs-cpu-{name}-{dev}.png"));
    for dev in ["cpu", "gpu"] {
        let out = path(dev);
        let mut all = vec!["render"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", out.to_str().unwrap(), "--quiet", "--device", dev]);
        let o = run(&all);
        assert!(o.status.success(), "{name} on {dev}: {}", stderr(&o));
    }
    let d = rays_py(
        &py,
        &[
            "imgdiff",
            path("cpu").to_str().unwrap(),
            path("gpu").to_str().unwrap(),
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

#[test]
fn gpu_render_matches_cpu_default_ct() {
    gpu_matches_cpu("default", &["--size", "96x72", "--spp", "1"], false);
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

#[test]
fn golden_direct_volume_rendering() {
    golden(
        "dvr_ct_bones",
        &["--mode", "dvr", "--preset", "ct-bones", "--size", "96x72"],
    );
    golden(
        "mip",
        &[
            "--mode", "mip", "--window", "1500", "--level", "300", "--size", "96x72",
        ],
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
