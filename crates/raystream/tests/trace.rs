//! `raystream trace`: the file formats, the JSON line, and agreement with Intel Embree on the
//! standard ray sets (../shared/tools/rays.py).

mod common;
use common::*;
use std::path::Path;
use std::process::Output;

#[test]
fn formats_contract_and_json() {
    // One triangle in the z = 0 plane, and rays: a hit, a miss, a NaN ray, a hit beyond t_max,
    // an unnormalized direction.
    let m = tmp("tri.obj");
    std::fs::write(&m, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let rays = [
        [0.25, 0.5, 1.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY],
        [2.0, 2.0, 1.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY],
        [f32::NAN, 0.5, 1.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY],
        [0.25, 0.5, 1.0, 0.0, 0.0, 0.0, -1.0, 0.5],
        [0.25, 0.25, 1.0, 0.0, 0.0, 0.0, -4.0, 1.0],
    ];
    let r = tmp("contract.rays");
    std::fs::write(&r, f32s(&rays.concat())).unwrap();
    let h = tmp("contract.hits");
    for any in [false, true] {
        let mut args = vec![
            "trace",
            m.to_str().unwrap(),
            "--rays",
            r.to_str().unwrap(),
            "-o",
            h.to_str().unwrap(),
            "--json",
            "--device",
            "cpu",
        ];
        if any {
            args.push("--any");
        }
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        for key in [
            "device",
            "adapter",
            "mesh",
            "triangles",
            "rays",
            "builder",
            "traversal",
            "build_ms",
            "upload_ms",
            "trace_ms",
            "trace_ms_min",
            "mrays_per_s",
            "hits",
        ] {
            assert!(j.get(key).is_some(), "missing {key} in {j}");
        }
        assert_eq!(j["rays"], 5);
        assert_eq!(j["hits"], 2);
        assert_eq!(j["sah_traversal_cost"], 1.0);
        let bytes = std::fs::read(&h).unwrap();
        assert_eq!(bytes.len(), 5 * 16);
        let rec = |i: usize| {
            let f = |k: usize| {
                f32::from_le_bytes(
                    bytes[16 * i + 4 * k..16 * i + 4 * k + 4]
                        .try_into()
                        .unwrap(),
                )
            };
            (
                f(0),
                u32::from_le_bytes(bytes[16 * i + 4..16 * i + 8].try_into().unwrap()),
                f(2),
                f(3),
            )
        };
        assert_eq!(rec(0).0, 1.0);
        assert_eq!(rec(4).0, 0.25, "t is in units of the direction's length");
        for miss in [1, 2, 3] {
            assert_eq!(rec(miss).0, f32::INFINITY);
            if !any {
                assert_eq!(rec(miss).1, u32::MAX);
            }
        }
        if !any {
            assert_eq!(rec(0), (1.0, 0, 0.25, 0.5));
        }
    }
}

/// Generates each standard ray set with rays.py, traces it, and lets rays.py check the hits
/// against Embree. Small sizes keep the test fast; `--t-floor` as rays.py advises for them.
fn check_against_embree(mesh_name: &str, builder: &str, traversal: &str) {
    let Some(py) = python() else { return };
    let m = mesh(mesh_name);
    for kind in ["primary", "shadow", "diffuse", "random"] {
        let stem = format!("{mesh_name}-{kind}-{builder}-{traversal}");
        let rays = tmp(&format!("{stem}.rays"));
        let hits = tmp(&format!("{stem}.hits"));
        gen_rays(&py, &m, kind, "160x120", &rays);
        let any = kind == "shadow";
        trace_to(
            &m,
            &rays,
            &hits,
            any,
            &["--builder", builder, "--traversal", traversal],
        );
        embree_check(&py, &m, &rays, &hits, any, &stem);
    }
}

#[test]
fn agrees_with_embree_lucy_sah_ropes() {
    check_against_embree("stanford_lucy_100k.ply", "sah", "ropes");
}

#[test]
fn agrees_with_embree_bunny_median_stack() {
    check_against_embree("stanford_bunny.ply", "median", "stack");
}

#[test]
fn agrees_with_embree_vase_and_spot() {
    check_against_embree("goblet_vase.stl", "sah", "stack");
    check_against_embree("spot.obj", "median", "ropes");
}

fn read_hits(path: &std::path::Path) -> Vec<(f32, u32)> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(16)
        .map(|c| {
            (
                f32::from_le_bytes(c[0..4].try_into().unwrap()),
                u32::from_le_bytes(c[4..8].try_into().unwrap()),
            )
        })
        .collect()
}

/// `trace spot.obj --rays RAYS --device gpu -q EXTRA... -o OUT` with `var` set to `value`:
/// its output and the hits it wrote.
fn spot_on_gpu(
    var: &str,
    value: &str,
    rays: &Path,
    out: &Path,
    extra: &[&str],
) -> (Output, Vec<u8>) {
    let spot = mesh("spot.obj");
    let mut args = vec![
        "trace",
        &spot,
        "--rays",
        rays.to_str().unwrap(),
        "--device",
        "gpu",
        "-q",
    ];
    args.extend(extra);
    run_with_env(var, Some(value), &args, out)
}

/// `RAYSTREAM_GPU_WAIT`: the GPU's waits spin or block (a hardware GPU spins by default, a
/// software one blocks), the same hits either way; any other value is refused, saying which.
#[test]
fn gpu_waits_spin_or_block() {
    if !gpu_available() {
        return;
    }
    let hits = |wait: &str| {
        let (rays, out) = (tmp("wait.rays"), tmp(&format!("wait-{wait}.hits")));
        std::fs::write(
            &rays,
            f32s(&[0.0, 0.0, 5.0, 0.0, 0.0, 0.0, -1.0, f32::INFINITY]),
        )
        .unwrap();
        spot_on_gpu("RAYSTREAM_GPU_WAIT", wait, &rays, &out, &[])
    };
    let (spin, spun) = hits("spin");
    let (block, blocked) = hits("block");
    assert!(
        spin.status.success() && block.status.success(),
        "{}",
        stderr(&spin)
    );
    assert!(!spun.is_empty() && spun == blocked);
    let (bad, _) = hits("sometimes");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_WAIT=\"sometimes\": spin or block"),
        "{}",
        stderr(&bad)
    );
}

/// A RAYS.bin (temp file `name`) of an n × n fan of rays from (0, 0, 5) down at spot.obj,
/// most of them hitting it.
fn fan_at_spot(name: &str, n: usize) -> std::path::PathBuf {
    let rays = tmp(name);
    let step = (n - 1) as f32;
    let fan: Vec<f32> = (0..n * n)
        .flat_map(|k| {
            let (x, y) = ((k % n) as f32 / step - 0.5, (k / n) as f32 / step - 0.5);
            [0.0, 0.0, 5.0, 0.0, 0.3 * x, 0.3 * y, -1.0, f32::INFINITY]
        })
        .collect();
    std::fs::write(&rays, f32s(&fan)).unwrap();
    rays
}

/// `RAYSTREAM_CPU_ISA=baseline|x86-64-v3`: the CPU's queries in the build's baseline and in
/// x86-64-v3 (the default where the processor has it, as every x86-64 CI machine must) write
/// the same bytes for a 48 × 48 fan at spot, closest and any hit; the JSON and the adapter
/// say which ran; the CPU volume renderers (dvr, cinematic) write the same PNG in either; any
/// other value is refused, naming the variable.
#[test]
fn cpu_queries_in_either_instruction_set() {
    let rays = fan_at_spot("isa.rays", 48);
    let spot = mesh("spot.obj");
    let trace = |isa: Option<&str>, any: bool| {
        let name = format!("isa-{}-{any}.hits", isa.unwrap_or("default"));
        let mut args = vec!["trace", &spot, "--rays", rays.to_str().unwrap()];
        args.extend(["--device", "cpu", "--json", "-q"]);
        if any {
            args.push("--any");
        }
        let (o, hits) = run_with_env("RAYSTREAM_CPU_ISA", isa, &args, &tmp(&name));
        assert!(o.status.success(), "{isa:?}: {}", stderr(&o));
        let line: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        let adapter = line["adapter"].as_str().unwrap().to_string();
        (line["cpu_isa"].as_str().unwrap().to_string(), adapter, hits)
    };
    let v3 = cfg!(target_arch = "x86_64") && in_ci();
    for any in [false, true] {
        let (isa, adapter, default) = trace(None, any);
        assert!(adapter.ends_with(&format!(", {isa})")), "{adapter}");
        if v3 {
            assert_eq!(
                isa, "x86-64-v3",
                "CI=true: an x86-64 CI machine must have it"
            );
        }
        let (base, _, baseline) = trace(Some("baseline"), any);
        assert_eq!(base, "baseline");
        assert_eq!(baseline.len(), 48 * 48 * 16);
        assert!(baseline == default, "any={any}: the bytes differ");
        let hit = |h: &[u8]| h[4..8] != [0xff; 4];
        assert!(default.chunks_exact(16).filter(|h| hit(h)).count() > 500);
    }
    // The CPU volume renderers' pixels follow it too: the same PNG either way.
    let ct = builtin_ct();
    for mode in ["dvr", "cinematic"] {
        let mut args = vec!["render", &ct, "--mode", mode, "--size", "48x40"];
        if mode == "cinematic" {
            args.extend(["--spp", "2"]);
        }
        args.extend(["--device", "cpu", "-q"]);
        let png = |isa: Option<&str>| {
            let name = format!("isa-{mode}-{}.png", isa.unwrap_or("default"));
            let (o, png) = run_with_env("RAYSTREAM_CPU_ISA", isa, &args, &tmp(&name));
            assert!(o.status.success(), "{mode} {isa:?}: {}", stderr(&o));
            png
        };
        let (default, baseline) = (png(None), png(Some("baseline")));
        assert!(default.len() > 1000, "{mode}: {} bytes", default.len());
        assert!(default == baseline, "{mode}: the PNGs differ");
    }
    let (bad, _) = run_with_env(
        "RAYSTREAM_CPU_ISA",
        Some("avx-512"),
        &["trace", &spot, "--rays", rays.to_str().unwrap(), "-q"],
        &tmp("isa-bad.hits"),
    );
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_CPU_ISA=\"avx-512\": unknown instruction set"),
        "{}",
        stderr(&bad)
    );
}

/// `RAYSTREAM_GPU_CHECKS=on|off`: the kd-tree kernels with and without (the default) wgpu's
/// run-time checks trace the same hits (a 32 × 32 fan of rays at spot)
/// and render the same frame of a mesh, and `trace --json` says which ran; any other value is
/// refused.
#[test]
fn gpu_kernels_without_run_time_checks_agree() {
    if !gpu_available() {
        return;
    }
    let rays = fan_at_spot("checks.rays", 32);
    let spot = mesh("spot.obj");
    let run = |checks: &str| {
        let render = ["render", &spot, "--size", "64x48", "--device", "gpu", "-q"];
        let hits = tmp(&format!("checks-{checks}.hits"));
        let png = tmp(&format!("checks-{checks}.png"));
        let (trace, hits) = spot_on_gpu("RAYSTREAM_GPU_CHECKS", checks, &rays, &hits, &[]);
        let (render, png) = run_with_env("RAYSTREAM_GPU_CHECKS", Some(checks), &render, &png);
        (trace, render, hits, png)
    };
    let (t_on, r_on, hits_on, png_on) = run("on");
    let (t_off, r_off, hits_off, png_off) = run("off");
    for o in [&t_on, &r_on, &t_off, &r_off] {
        assert!(o.status.success(), "{}", stderr(o));
    }
    let hit = hits_on
        .chunks_exact(16)
        .filter(|h| f32::from_le_bytes(h[..4].try_into().unwrap()).is_finite())
        .count();
    assert!(hit > 300, "{hit} of 1024 rays hit");
    assert!(
        hits_on == hits_off,
        "the hits differ without run-time checks"
    );
    assert!(!png_on.is_empty() && png_on == png_off, "the frames differ");
    // `trace --json` says which kernels ran: without the checks unless asked for them.
    let spot = mesh("spot.obj");
    let rays = rays.to_str().unwrap();
    for (value, checked) in [(None, false), (Some("on"), true), (Some("off"), false)] {
        // The GPU says which it ran; the CPU has no kernels (null).
        for (device, want) in [
            ("gpu", serde_json::json!(checked)),
            ("cpu", serde_json::Value::Null),
        ] {
            let args = [
                "trace", &spot, "--rays", rays, "--json", "-q", "--device", device,
            ];
            let (o, _) = run_with_env(
                "RAYSTREAM_GPU_CHECKS",
                value,
                &args,
                &tmp("checks-json.hits"),
            );
            let line: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
            assert_eq!(line["run_time_checks"], want, "{device} {value:?}");
        }
    }
    let (bad, _, _, _) = run("maybe");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_CHECKS=\"maybe\": on or off"),
        "{}",
        stderr(&bad)
    );
}

/// `RAYSTREAM_GPU_TIMESTAMPS=off`: no timestamp queries, so no kernel time in `trace --json`
/// (the query's and the floor's, with `--stats`) while the wall times are still measured, the
/// same hits and the same frame as with them; any other value is refused.
#[test]
fn gpu_timestamps_can_be_turned_off() {
    if !gpu_available() {
        return;
    }
    let rays = fan_at_spot("stamps.rays", 16);
    let spot = mesh("spot.obj");
    let render = ["render", &spot, "--size", "48x32", "--device", "gpu", "-q"];
    let run = |value: &str| {
        let (trace, hits) = spot_on_gpu(
            "RAYSTREAM_GPU_TIMESTAMPS",
            value,
            &rays,
            &tmp(&format!("stamps-{value}.hits")),
            &["--json", "--stats"],
        );
        let (render, png) = run_with_env(
            "RAYSTREAM_GPU_TIMESTAMPS",
            Some(value),
            &render,
            &tmp(&format!("stamps-{value}.png")),
        );
        (trace, hits, render, png)
    };
    let (on, hits_on, r_on, png_on) = run("on");
    let (off, hits_off, r_off, png_off) = run("off");
    for o in [&on, &off, &r_on, &r_off] {
        assert!(o.status.success(), "{}", stderr(o));
    }
    assert!(!hits_on.is_empty() && hits_on == hits_off);
    assert!(!png_on.is_empty() && png_on == png_off, "the frames differ");
    let on: serde_json::Value = serde_json::from_str(stdout(&on).trim()).unwrap();
    let off: serde_json::Value = serde_json::from_str(stdout(&off).trim()).unwrap();
    // lavapipe has timestamps: on, the kernel times are there; off, they are not.
    assert!(on["gpu_kernel_ms"].as_f64().unwrap() > 0.0, "{on}");
    assert!(on["floor"]["gpu_kernel_ms"].as_f64().unwrap() > 0.0, "{on}");
    assert!(off["gpu_kernel_ms"].is_null(), "{off}");
    assert!(off["floor"]["gpu_kernel_ms"].is_null(), "{off}");
    for key in ["trace_ms", "stream_ms"] {
        assert!(off[key].as_f64().unwrap() > 0.0, "{key}: {off}");
        assert!(
            off["floor"][key].as_f64().unwrap() > 0.0,
            "floor {key}: {off}"
        );
    }
    let (bad, _, _, _) = run("sometimes");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_TIMESTAMPS=\"sometimes\": on or off"),
        "{}",
        stderr(&bad)
    );
}

/// `RAYSTREAM_GPU_PLANES`: a ground quad 10⁷ long turned 0.3°, whose plane f32 cannot place
/// where the rays start (raystream-accel's `huge_turned_ground_quads_are_hit_where_their_planes_are`),
/// traced from a PLY file: by default the GPU places it in f64 as the CPU does and hits the
/// same rays (t within 1e-6, `"f64_planes": true`); with `f32` (`false`, the kernels before)
/// over a tenth of the rays miss or move by more than 10⁻³ (on lavapipe 602 of 1,536 moved); any
/// other value is refused.
#[test]
fn gpu_planes_of_huge_triangles_in_f64_or_f32() {
    if !gpu_available() {
        return;
    }
    let quad = raystream_accel::brute::turned_quad(5.0, 5e6, 0.3);
    let obj = tmp("huge-quad.ply");
    raystream_io::write_mesh(&obj, &quad, None).unwrap();
    let rays = tmp("huge-quad.rays");
    let packed: Vec<f32> = raystream_accel::brute::turned_quad_rays(48, 32)
        .iter()
        .flat_map(|r| r.to_array())
        .collect();
    std::fs::write(&rays, f32s(&packed)).unwrap();
    let trace = |device: &str, planes: Option<&str>, name: &str| {
        let args = [
            "trace",
            obj.to_str().unwrap(),
            "--rays",
            rays.to_str().unwrap(),
            "--json",
            "-q",
            "--device",
            device,
        ];
        let (o, hits) = run_with_env("RAYSTREAM_GPU_PLANES", planes, &args, &tmp(name));
        let line = serde_json::from_str::<serde_json::Value>(stdout(&o).trim()).ok();
        (o, line.map(|l| l["f64_planes"].clone()), hits)
    };
    // (t, hit) of each record.
    let records = |hits: &[u8]| -> Vec<(f32, bool)> {
        hits.chunks_exact(16)
            .map(|h| {
                let t = f32::from_le_bytes(h[..4].try_into().unwrap());
                (
                    t,
                    u32::from_le_bytes(h[4..8].try_into().unwrap()) != u32::MAX,
                )
            })
            .collect()
    };
    let (cpu, cpu_f64, cpu_hits) = trace("cpu", None, "huge-quad-cpu.hits");
    let (gpu, gpu_f64, gpu_hits) = trace("gpu", None, "huge-quad-gpu.hits");
    let (f32, f32_f64, f32_hits) = trace("gpu", Some("f32"), "huge-quad-f32.hits");
    for o in [&cpu, &gpu, &f32] {
        assert!(o.status.success(), "{}", stderr(o));
    }
    assert_eq!(cpu_f64, Some(serde_json::json!(true)));
    assert_eq!(gpu_f64, Some(serde_json::json!(true)), "lavapipe has f64");
    assert_eq!(f32_f64, Some(serde_json::json!(false)));
    let (cpu, gpu, f32) = (records(&cpu_hits), records(&gpu_hits), records(&f32_hits));
    assert!(cpu.iter().filter(|h| h.1).count() > 500, "too few hits");
    for (k, (c, g)) in cpu.iter().zip(&gpu).enumerate() {
        assert_eq!(c.1, g.1, "ray {k}: hit on one device only");
        assert!(
            !c.1 || ((c.0 - g.0) / c.0).abs() < 1e-6,
            "ray {k}: {} against {}",
            g.0,
            c.0
        );
    }
    let changed = cpu
        .iter()
        .zip(&f32)
        .filter(|(c, f)| c.1 != f.1 || (c.1 && ((c.0 - f.0) / c.0).abs() > 1e-3))
        .count();
    eprintln!("{changed} of {} rays change in f32", cpu.len());
    assert!(
        changed * 10 > cpu.len(),
        "{changed} of {} rays change in f32",
        cpu.len()
    );
    let (bad, _, _) = trace("gpu", Some("f16"), "huge-quad-bad.hits");
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("RAYSTREAM_GPU_PLANES=\"f16\": f64 or f32"),
        "{}",
        stderr(&bad)
    );
}

/// GPU `trace` on the standard ray sets of every mesh in ../shared/data/meshes: passes
/// rays.py's Embree check, and equals the CPU's hits (prim, and t within 1e-5 relative; only
/// ties at shared edges may differ).
#[test]
fn gpu_trace_agrees_with_cpu_and_embree() {
    if !gpu_available() {
        return;
    }
    let Some(py) = python() else { return };
    let mut names: Vec<String> = std::fs::read_dir(shared().join("data/meshes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| [".obj", ".ply", ".stl"].iter().any(|x| n.ends_with(x)))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "meshes: {names:?}");
    for name in &names {
        let m = mesh(name);
        for kind in ["primary", "shadow", "diffuse", "random"] {
            let stem = format!("gpu-{name}-{kind}");
            let rays = tmp(&format!("{stem}.rays"));
            gen_rays(&py, &m, kind, "96x72", &rays);
            let any = kind == "shadow";
            let outs: Vec<_> = ["gpu", "cpu"]
                .iter()
                .map(|device| {
                    let hits = tmp(&format!("{stem}-{device}.hits"));
                    trace_to(&m, &rays, &hits, any, &["--device", device]);
                    hits
                })
                .collect();
            embree_check(&py, &m, &rays, &outs[0], any, &stem);
            let (gpu, cpu) = (read_hits(&outs[0]), read_hits(&outs[1]));
            let mut prim_diff = 0;
            for (i, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
                assert_eq!(
                    g.0.is_finite(),
                    c.0.is_finite(),
                    "{stem}: ray {i} hit/miss differs"
                );
                if !any && c.0.is_finite() {
                    assert!(
                        (g.0 - c.0).abs() <= 1e-5 * c.0.abs().max(1e-6),
                        "{stem}: ray {i} t {} vs {}",
                        g.0,
                        c.0
                    );
                    prim_diff += (g.1 != c.1) as usize;
                }
            }
            assert!(
                prim_diff * 1000 <= gpu.len(),
                "{stem}: {prim_diff} prim differences"
            );
            // The split kernels (traversal and intersection apart) and the persistent threads
            // write the same file.
            for kernels in ["split", "persistent", "ifif"] {
                if any && kernels == "split" {
                    continue;
                }
                let other = tmp(&format!("{stem}-{kernels}.hits"));
                trace_to(
                    &m,
                    &rays,
                    &other,
                    any,
                    &["--device", "gpu", "--kernels", kernels],
                );
                assert_eq!(
                    std::fs::read(&other).unwrap(),
                    std::fs::read(&outs[0]).unwrap(),
                    "{stem}: --kernels {kernels} differs from fused"
                );
            }
        }
    }
}

/// `trace --stats`: the GPU kernel's steps per ray, SIMD efficiency and residency peak in the
/// JSON line (where the adapter has subgroups), with the streamed queries' time; on the CPU a
/// clear error.
#[test]
fn trace_stats() {
    let m = mesh("spot.obj");
    let rays = tmp("stats.rays");
    let mut floats = Vec::new();
    for i in 0..4096 {
        let (x, y) = ((i % 64) as f32 / 63.0 - 0.5, (i / 64) as f32 / 63.0 - 0.5);
        floats.extend([0.0, 0.5, 3.0, 0.0, x, y - 0.3, -1.0, f32::INFINITY]);
    }
    std::fs::write(&rays, f32s(&floats)).unwrap();
    let hits = tmp("stats.hits");
    let args = |device: &'static str| {
        vec![
            "trace".to_string(),
            m.clone(),
            "--rays".into(),
            rays.to_str().unwrap().into(),
            "-o".into(),
            hits.to_str().unwrap().into(),
            "--stats".into(),
            "--json".into(),
            "--device".into(),
            device.into(),
        ]
    };
    let cpu = args("cpu");
    let o = run(&cpu.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--stats"), "{}", stderr(&o));
    if !gpu_available() {
        return;
    }
    let gpu = args("gpu");
    let o = run(&gpu.iter().map(String::as_str).collect::<Vec<_>>());
    if !o.status.success() {
        // Only an adapter without subgroups may refuse, and it must say so (CI's lavapipe
        // has them).
        assert!(!in_ci(), "{}", stderr(&o));
        assert!(stderr(&o).contains("subgroup"), "{}", stderr(&o));
        return;
    }
    let line: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let s = &line["gpu_stats"];
    assert!(line["hits"].as_u64().unwrap() > 100, "{line}");
    assert!(line["split_steps"].is_null(), "{line}");
    // The queued queries' wall time per query (their hits were checked against a lone one's).
    assert!(line["stream_ms"].as_f64().unwrap() > 0.0, "{line}");
    // An empty submission's round trip, measured. Not compared with the query's time: two
    // timings on a loaded machine can fall either way (CI once saw 1.74 ms against 0.55).
    let floor = line["round_trip_ms"].as_f64().unwrap();
    assert!(floor > 0.0 && floor.is_finite(), "{line}");
    // The wall time of untimed queries, each after a timed one.
    assert!(line["untimed_ms"].as_f64().unwrap() > 0.0, "{line}");
    // The floor kernel's times on the same rays (no traversal), measured and reported.
    for key in ["trace_ms", "trace_ms_min", "stream_ms", "untimed_ms"] {
        let ms = line["floor"][key].as_f64().unwrap_or(-1.0);
        assert!(ms > 0.0 && ms.is_finite(), "floor {key}: {line}");
    }
    assert!(
        s["steps_per_ray"]["traversal"].as_f64().unwrap() > 1.0,
        "{line}"
    );
    for kind in ["traversal", "leaf", "triangle"] {
        let e = s["simd_efficiency"][kind].as_f64().unwrap();
        assert!(e > 0.0 && e <= 1.0, "{kind}: {e}");
    }
    // The residency peak: at least one subgroup, in subgroups and invocations alike.
    let lanes = s["subgroup_size"].as_u64().unwrap();
    let peak = s["peak_resident_invocations"].as_u64().unwrap();
    assert!(lanes >= 1 && peak >= lanes, "{line}");
    let subgroups = s["peak_resident_subgroups"].as_f64().unwrap();
    assert!(
        (subgroups - peak as f64 / lanes as f64).abs() < 1e-3,
        "{line}"
    );
    // The split kernels report their leaf steps: these rays cross the spot mesh's leaves.
    let mut split = gpu.clone();
    split.retain(|a| a != "--stats");
    split.extend(["--kernels".into(), "split".into()]);
    let o = run(&split.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let line: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert!(line["split_steps"].as_u64().unwrap() > 1, "{line}");
}

#[test]
fn unknown_adapter_is_a_clear_error() {
    let o = gpu_probe("adapter", &["--adapter", "no-such-gpu-xyz"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("no GPU adapter") && !err.contains("panicked"),
        "{err}"
    );
}

/// scripts/summarize-device-bench.py on the lines device-bench.sh writes: Grays/s from the
/// times, the first bar judged by wall, streamed and kernel time against the issue's peers, a
/// failed rays.py check named, the render modes' frame times and `iso --simplify`'s by threads
/// side by side.
#[test]
fn device_bench_summary() {
    let Some(py) = python() else { return };
    let results = tmp("summary-results.jsonl");
    // lucy's primary rays as the H100 ran them: 2.25 Grays/s by wall time, 4.89 by kernel time
    // (half the best peer, Warp's 5.24, is 2.62); streamed 2.8.
    let n = 2_073_600.0;
    let ms = |grays: f64| n / grays / 1e6;
    let lines = [
        r#"{"machine": "16 cores, Intel(R) Xeon(R) Processor", "date": "2026-11-23T10:00:00Z"}"#
            .to_string(),
        format!(
            r#"{{"device": "gpu", "adapter": "NVIDIA H100 80GB HBM3", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}, "stream_ms": {}, "sah_traversal_cost": 1.0, "gpu_stats": {{"steps_per_ray": {{"traversal": 9.0, "leaf": 2.8, "triangle": 1.9}}, "simd_efficiency": {{"traversal": 0.5, "leaf": 0.7, "triangle": 0.25}}, "subgroup_size": 32, "peak_resident_invocations": 135168}}, "round_trip_ms": 0.02, "untimed_ms": 0.9, "floor": {{"trace_ms": 0.12, "gpu_kernel_ms": 0.05, "stream_ms": 0.07, "untimed_ms": 0.09}}}}"#,
            ms(2.25),
            ms(4.89),
            ms(2.8)
        ),
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "sah_traversal_cost": 4, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}}}"#,
            ms(2.5),
            ms(5.5)
        ),
        format!(
            r#"{{"device": "cpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-cpu", "rays": {n}, "trace_ms": {}}}"#,
            ms(0.05)
        ),
        r#"{"mesh": "stanford_lucy_100k", "kind": "primary", "check": "gpu-fused", "pass": false, "hit_agree": 0.99, "prim_agree": 0.98}"#.to_string(),
        // The entry part: two grid sizes, two rounds, work counted in the first.
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "entry_grid_res": 0, "round": 1, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}, "gpu_stats": {{"steps_per_ray": {{"traversal": 9.0}}}}}}"#,
            ms(3.6),
            ms(4.89)
        ),
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "entry_grid_res": 128, "round": 1, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}, "gpu_stats": {{"steps_per_ray": {{"traversal": 6.0}}}}}}"#,
            ms(3.9),
            ms(5.3)
        ),
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "entry_grid_res": 0, "round": 2, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}}}"#,
            ms(3.5),
            ms(4.9)
        ),
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "entry_grid_res": 128, "round": 2, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}}}"#,
            ms(4.0),
            ms(5.4)
        ),
        // The ab part: two binaries, base and new, a round each (apart from the tables above).
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "binary": "base", "round": 1, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}}}"#,
            ms(4.0),
            ms(5.0)
        ),
        format!(
            r#"{{"device": "gpu", "mesh": "stanford_lucy_100k", "kind": "primary", "tracer": "raystream-gpu-fused", "binary": "new", "round": 1, "rays": {n}, "trace_ms": {}, "gpu_kernel_ms": {}}}"#,
            ms(4.4),
            ms(5.5)
        ),
        // The simplify part: two rounds of the new binary, one of the base, at 16 threads.
        r#"{"ms": 3000, "triangles": 115076, "part": "simplify", "binary": "new", "threads": 16, "round": 1, "smooth": 10, "bound_mm": 4}"#.to_string(),
        r#"{"ms": 2000, "triangles": 115076, "part": "simplify", "binary": "new", "threads": 16, "round": 2, "smooth": 10, "bound_mm": 4}"#.to_string(),
        r#"{"ms": 10000, "triangles": 115076, "part": "simplify", "binary": "base", "threads": 16, "round": 1, "smooth": 10, "bound_mm": 4}"#.to_string(),
        r#"{"volume": "cinematic ct-bones", "kind": "volume", "mode": "cinematic", "interpolation": "cubic", "shadows": false, "spp": 64, "bounces": 4, "device": "gpu", "dims": [512, 512, 512], "size": "1024x1024", "frame_ms": 2000.0, "frames_per_s": 0.5, "kernel_frames_per_s": 0.51, "samples_per_frame": 2500000000.0, "msamples_per_s_kernel": 1275.0}"#.to_string(),
    ];
    std::fs::write(&results, lines.join("\n") + "\n").unwrap();
    let log = tmp("summary-render.log");
    let frame = |submit: &str, spp: u32, ms: f64| {
        format!(
            "[submit {submit}, {spp} spp] raystream: wrote /tmp/x.png (1920x1080, {spp} spp, depth 4) on gpu (H100): load 1 ms, render {ms} ms median of 20 = {:.2} frames/s (min {ms} ms)\n",
            1e3 / ms
        )
    };
    let text = [
        frame("depth", 4, 36.0),
        frame("wave", 4, 30.0),
        frame("depth", 4, 38.0),
        frame("wave", 4, 31.0),
        // device-bench.sh's two cinematic pictures, as render writes their lines.
        "raystream: wrote out/cinematic-gpu.png (1024x1024, --mode cinematic, 256 paths a pixel, up to 4 scatterings) on gpu (H100): load 900 ms, render 4210.5 ms (0.24 frames/s), kernel 4200.00 ms, 1 samples, 1.0 M samples/s\n".to_string(),
        "raystream: wrote out/cinematic-denoised-gpu.png (1024x1024, --mode cinematic, cubic B-spline, 16 paths a pixel, up to 4 scatterings, denoised (guides 12 ms, filter 7 ms)) on gpu (H100): load 900 ms, render 301.2 ms (3.32 frames/s), kernel 270.00 ms, 1 samples, 1.0 M samples/s\n".to_string(),
    ]
    .concat();
    std::fs::write(&log, text).unwrap();
    let o = std::process::Command::new(&py)
        .arg(repo().join("scripts/summarize-device-bench.py"))
        .arg(&results)
        .arg("--render")
        .arg(&log)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains(
            "| stanford_lucy_100k | primary | 2,073,600 | 2.25 | 4.89 | 2.8 | 3.62 | 5.24 | 2.62 | **missed** | met | met | 0.05 | – | 45× |"
        ),
        "{out}"
    );
    assert!(
        out.contains("First bar by wall time: met on 0 of 1 rows."),
        "{out}"
    );
    assert!(
        out.contains("First bar by kernel time: met on 1 of 1 rows."),
        "{out}"
    );
    // The leaf-size variant beside the fused kernel: 5.5 / 4.89 of its kernel time.
    assert!(
        out.contains("| raystream-gpu-fused (K=4) | 2.5 | 5.5 | 2.25 | 4.89 | 1.11 | 1.12 | – |"),
        "{out}"
    );
    // The entry grid's sizes side by side, neither in the tables above: 5.4 / 4.9.
    assert!(
        out.contains("| stanford_lucy_100k | primary | 128 | 5.3, 5.4 | 4 | 6 | 1.10 |"),
        "{out}"
    );
    assert!(
        out.contains("| stanford_lucy_100k | primary | none | 4.89, 4.9 | 3.6 | 9 | 1.00 |"),
        "{out}"
    );
    // The two binaries side by side: new over base, 5.5 / 5.0 by kernel, 4.4 / 4.0 by wall.
    assert!(
        out.contains("| stanford_lucy_100k | primary | 5 | 5.5 | 4 | 4.4 | 1.10 | 1.10 |"),
        "{out}"
    );
    // Where the wall time goes: the query and the floor kernel, in ms, timed and untimed
    // (0.922 - 0.424 = 0.498 beside the query; 0.424 - 0.050 = 0.374 of kernel time is the
    // traversal's).
    assert!(
        out.contains("| stanford_lucy_100k | primary | raystream-gpu-fused | on | 0.922 | 0.900 | 0.424 | 0.741 | 0.020 | 0.120 | 0.090 | 0.050 | 0.070 | 0.498 | 0.070 | 0.374 |"),
        "{out}"
    );
    // The cinematic pictures: the frame's time, and the denoiser's parts.
    assert!(
        out.contains("| cinematic-gpu.png | 1024x1024 | 256 | 4210.5 | – | – |"),
        "{out}"
    );
    assert!(
        out.contains("| cinematic-denoised-gpu.png | 1024x1024 | 16 | 301.2 | 12.0 | 7.0 |"),
        "{out}"
    );
    // A volume bench's orbit: 2.5 G samples a frame at 0.51 kernel frames/s.
    assert!(
        out.contains("| cinematic ct-bones | cinematic | cubic | no | 64 | gpu | 512×512×512 | 1024x1024 | 0.5 | 0.51 | 2,500 | 1.27 |"),
        "{out}"
    );
    // iso --simplify by threads: the new binary's median 2500 ms against the base's 10000.
    assert!(
        out.contains("| 10 | 4 | 16 | 10000 | 2500 | 0.25 | 115076 | 115076 |"),
        "{out}"
    );
    // Occupancy: 135,168 resident invocations are half of 132 SMs x 2048.
    assert!(out.contains("| 32 | 135168 | 0.50 |"), "{out}");
    assert!(
        out.contains("FAILED: stanford_lucy_100k primary gpu-fused"),
        "{out}"
    );
    // Medians 30.5 and 37.0.
    assert!(
        out.contains("| 4 | 36.0, 38.0 | 30.0, 31.0 | 0.82 |"),
        "{out}"
    );
}

/// glTF scenes from an independent writer (trimesh): the bunny placed twice by two nodes'
/// transforms (one turned, scaled and moved), as a `.glb` and as a `.gltf` with its buffers in
/// files beside it. The reference is the bunny placed with numpy in f64 by the file's f32
/// matrices, in the nodes' order, written as a PLY: on primary and diffuse rays, the hits of
/// both glTF files are the PLY's byte for byte, and pass Embree's check against it.
#[test]
fn gltf_scenes_trace_as_their_placed_triangles() {
    let Some(py) = python() else { return };
    let dir = tmp("gltf-bunnies");
    std::fs::create_dir_all(&dir).unwrap();
    let script = r#"
import sys, numpy as np, trimesh
src, out = sys.argv[1], sys.argv[2]
m = trimesh.load(src, process=False)
T = [trimesh.transformations.compose_matrix(scale=[2, 2, 2], angles=[0.3, 0.5, 0.1], translate=[0.1, -0.2, 0.3]),
     trimesh.transformations.translation_matrix([0.5, 0, 0])]
s = trimesh.Scene()
for k, t in enumerate(T):
    s.add_geometry(m, node_name=f"n{k}", geom_name=f"g{k}", transform=t)
s.export(out + "/two.glb")
for name, data in s.export(file_type="gltf").items():
    open(out + "/" + name, "wb").write(data)
V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces)
placed = [(np.c_[V, np.ones(len(V))] @ t.astype(np.float32).astype(np.float64).T)[:, :3] for t in T]
ref = trimesh.Trimesh(np.vstack(placed).astype(np.float32), np.vstack([F, F + len(V)]), process=False)
ref.export(out + "/ref.ply")
"#;
    let o = std::process::Command::new(&py)
        .args([
            "-c",
            script,
            &mesh("stanford_bunny.ply"),
            dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let file = |name: &str| dir.join(name).to_string_lossy().into_owned();
    let reference = file("ref.ply");
    for kind in ["primary", "diffuse"] {
        let rays = dir.join(format!("{kind}.rays"));
        gen_rays(&py, &reference, kind, "64x64", &rays);
        let want = dir.join(format!("{kind}-ref.hits"));
        trace_to(&reference, &rays, &want, false, &[]);
        for name in ["two.glb", "model.gltf"] {
            let hits = dir.join(format!("{kind}-{name}.hits"));
            trace_to(&file(name), &rays, &hits, false, &[]);
            assert!(
                std::fs::read(&hits).unwrap() == std::fs::read(&want).unwrap(),
                "{name}, {kind} rays: not the reference's hits"
            );
            embree_check(&py, &reference, &rays, &hits, false, name);
        }
    }
}

/// `--entry-grid N`: walks start at their entry point's cell in a grid of N cells along the
/// scene's longest side, or at the root with 0. The same hits, byte for byte, on every device
/// and every ray kind, and the same frame; `bench` counts fewer inner steps; sizes past 256
/// are refused.
#[test]
fn the_entry_grid_changes_no_hit_and_no_pixel() {
    let Some(py) = python() else { return };
    let m = mesh("stanford_bunny.ply");
    for kind in ["primary", "shadow", "diffuse"] {
        let rays = tmp(&format!("entry-{kind}.rays"));
        gen_rays(&py, &m, kind, "64x48", &rays);
        for &device in devices() {
            let files: Vec<Vec<u8>> = ["0", "128", "256"]
                .iter()
                .map(|res| {
                    let hits = tmp(&format!("entry-{kind}-{device}-{res}.hits"));
                    let extra = ["--device", device, "--entry-grid", res];
                    trace_to(&m, &rays, &hits, kind == "shadow", &extra);
                    std::fs::read(hits).unwrap()
                })
                .collect();
            assert!(
                files[0].len() > 1000 * 16,
                "{kind}: {} bytes of hits",
                files[0].len()
            );
            assert!(
                files[0] == files[1] && files[0] == files[2],
                "{kind} on the {device}: the hits depend on the entry grid"
            );
        }
    }
    for &device in devices() {
        let frames: Vec<Vec<u8>> = ["0", "32"]
            .iter()
            .map(|res| {
                let name = format!("entry-{device}-{res}.png");
                let args = ["--size", "64x48", "--entry-grid", res];
                std::fs::read(render_to(&name, device, &args)).unwrap()
            })
            .collect();
        assert!(
            frames[0] == frames[1],
            "the {device}'s frame depends on the entry grid"
        );
    }
    let steps = |res: &str| {
        let o = run(&[
            "bench",
            &m,
            "--size",
            "48x32",
            "--device",
            "cpu",
            "--json",
            "-q",
            "--entry-grid",
            res,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let lines: Vec<serde_json::Value> = stdout(&o)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        lines
            .iter()
            .find(|j| j["kind"] == "shadow")
            .unwrap()
            .clone()
    };
    let (with, without) = (steps("128"), steps("0"));
    let cells = with["kdtree"]["entry_grid"]["cells"]
        .as_array()
        .unwrap()
        .clone();
    assert_eq!(
        cells.iter().map(|c| c.as_u64().unwrap()).max(),
        Some(128),
        "{with}"
    );
    assert!(without["kdtree"]["entry_grid"].is_null(), "{without}");
    let inner = |j: &serde_json::Value| j["inner_per_ray"].as_f64().unwrap();
    assert!(inner(&with) < 0.8 * inner(&without), "{with} vs {without}");
    assert_eq!(with["leaves_per_ray"], without["leaves_per_ray"]);
    refused(
        &[
            "trace",
            &m,
            "--rays",
            "x.rays",
            "-o",
            "x.hits",
            "--entry-grid",
            "257",
        ],
        "257 is not in 0..=256",
    );
}
