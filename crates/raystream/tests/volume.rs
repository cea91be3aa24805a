//! CT volumes end to end: `info --json` against SimpleITK on every format, `iso`, and `render`
//! from a DICOM folder.

mod common;

use std::collections::{HashMap, HashSet};
use std::path::Path;

use common::*;
use raystream_math::{I64Vec3, Vec3};
use serde_json::Value;

fn info(path: &str) -> Value {
    let o = run(&["info", "--json", path]);
    assert!(o.status.success(), "{path}: {}", stderr(&o));
    serde_json::from_str(stdout(&o).trim()).unwrap()
}

fn volume(rel: &str) -> String {
    shared()
        .join("data/volumes")
        .join(rel)
        .to_string_lossy()
        .into_owned()
}

fn close(a: &Value, b: &Value, tol: f64, what: &str) {
    let (a, b) = (a.as_array().unwrap(), b.as_array().unwrap());
    assert_eq!(a.len(), b.len(), "{what}");
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
        assert!((x - y).abs() <= tol, "{what}: {a:?} vs {b:?}");
    }
}

#[test]
fn info_json_describes_a_dicom_series() {
    let v = info(&volume("dicom/abdomen_ct_j2k_totalseg"));
    assert_eq!(v["kind"], "volume");
    assert_eq!(v["dims"], serde_json::json!([512, 512, 20]));
    close(
        &v["spacing"],
        &serde_json::json!([0.9765625, 0.9765625, 2.0]),
        1e-6,
        "spacing",
    );
    close(
        &v["origin"],
        &serde_json::json!([-249.51171875, -437.51171875, -804.5]),
        1e-6,
        "origin",
    );
    close(
        &v["direction"],
        &serde_json::json!([1, 0, 0, 0, 1, 0, 0, 0, 1]),
        1e-9,
        "direction",
    );
    assert_eq!(v["hu_range"], serde_json::json!([-1024.0, 1839.0]));
    assert_eq!(v["series"]["count"], 20);
    assert_eq!(v["series"]["transfer_syntax"], "1.2.840.10008.1.2.4.90");
}

/// A Python with SimpleITK, or `None` (a skip, except under CI, where it fails).
fn python_with_simpleitk() -> Option<std::path::PathBuf> {
    python_with("SimpleITK")
}

#[test]
fn every_format_matches_simpleitk_on_an_oblique_grid() {
    let Some(py) = python_with_simpleitk() else {
        return;
    };
    let dir = tmp("sitk-formats");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/sitk_convert.py"))
        .arg(volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let lines = stdout(&o);
    assert_eq!(lines.lines().count(), 7);
    let nifti = raystream_io::load_volume(&dir.join("oblique.nii"), &Default::default()).unwrap();
    for line in lines.lines() {
        let e: Value = serde_json::from_str(line).unwrap();
        let file = e["file"].as_str().unwrap();
        let v = info(dir.join(file).to_str().unwrap());
        assert_eq!(v["dims"], e["dims"], "{file}");
        close(&v["spacing"], &e["spacing"], 1e-3, file);
        close(&v["origin"], &e["origin"], 1e-3, file);
        close(&v["direction"], &e["direction"], 1e-4, file);
        close(&v["value_range"], &e["range"], 0.0, file);
        // Every format holds the same voxels, in the same order.
        let read = raystream_io::load_volume(&dir.join(file), &Default::default()).unwrap();
        assert!(
            read.data == nifti.data,
            "{file}: its voxels differ from the NIfTI's"
        );
        let sum: f64 = read.data.iter().map(|&x| x as f64).sum();
        assert_eq!(sum, e["sum"].as_f64().unwrap(), "{file}");
    }
}

#[test]
fn iso_writes_a_closed_bone_surface() {
    let out = tmp("abdomen-bones.ply");
    let o = run(&[
        "iso",
        &volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz"),
        "--hu",
        "300",
        "-o",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mesh = raystream_io::load_mesh(&out).unwrap();
    assert!(mesh.len() > 50_000, "{} triangles", mesh.len());
    // Closed: every edge is shared by exactly two triangles.
    let mut edges = std::collections::HashMap::<(u32, u32), u32>::new();
    for t in &mesh.triangles {
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(edges.values().all(|&n| n == 2));
    // In LPS millimetres, inside the volume's extent (x: 177.96 − 3·121 … 177.96).
    let b = mesh.bounds();
    assert!(
        b.min.x >= 177.95 - 363.0 - 1e-3 && b.max.x <= 177.96,
        "{b:?}"
    );
    assert!(b.min.z >= 94.30 - 1e-3 && b.max.z <= 94.31 + 333.0, "{b:?}");
}

/// `iso --keep-largest N` and `--min-island ML` on the abdomen CT's bones: the kept surface is
/// the full one's triangles (each a triangle of the full STL, corner for corner), closed, in
/// as many pieces as islands kept or more (an island's hollows are surfaces of its own), the
/// largest island's alone with N = 1, more of them for each larger N, and the islands of at
/// least 1 ml with `--min-island 1` (where 13 of 1,222 hold one), fewer triangles than the full
/// surface's and more than the largest island's; `render` keeps them too. A label map's
/// segments keep their own islands: a segment of a ball and a speck keeps its ball, another
/// of one ball keeps it, and says its voxels are the ball's. Refused: an island size no island
/// reaches (naming the largest), 0, with `--mode` and for a mesh.
/// `iso CT -o NAME MORE…` (NAME in the tests' scratch folder): the mesh written, and what it
/// said.
fn iso_to(ct: &str, name: &str, more: &[&str]) -> (raystream_io::TriMesh, String) {
    let out = tmp(name);
    let mut args = vec!["iso", ct, "-o", out.to_str().unwrap()];
    args.extend_from_slice(more);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    (raystream_io::load_mesh(&out).unwrap(), stderr(&o))
}

/// `iso --body-only` of the J2K series (the upper abdomen, the arms at its sides, on a
/// curved table whose parts pass 300 HU): the bones are the whole CT's, triangle for
/// triangle, less the table's pieces, which `iso` says it left out: none of them within 5 mm
/// of a bone kept, the arms' bones kept at either side, the back 80 mm nearer.
#[test]
fn iso_body_only_leaves_out_the_table() {
    let ct = volume("dicom/abdomen_ct_j2k_totalseg");
    let (full, _) = iso_to(&ct, "body-full.stl", &[]);
    let (body, said) = iso_to(&ct, "body-only.stl", &["--body-only"]);
    assert!(
        said.contains(
            "the body, 3.33 l with what it encloses; left out above -500 HU: 2 pieces (135 ml, 63 ml)"
        ),
        "{said}"
    );
    let corners =
        |m: &raystream_io::TriMesh, i: usize| m.corners(i).map(|p| p.to_array().map(f32::to_bits));
    let all: HashSet<_> = (0..full.len()).map(|i| corners(&full, i)).collect();
    let kept: HashSet<_> = (0..body.len()).map(|i| corners(&body, i)).collect();
    assert!(kept.iter().all(|t| all.contains(t)));
    let gone: Vec<usize> = (0..full.len())
        .filter(|&i| !kept.contains(&corners(&full, i)))
        .collect();
    assert!(gone.len() > 1000, "{} triangles left out", gone.len());
    // The vertices kept, by 5 mm cell.
    let cell = |p: Vec3| (p / 5.0).floor().as_i64vec3();
    let mut cells: HashMap<I64Vec3, Vec<Vec3>> = HashMap::new();
    for &p in &body.positions {
        cells.entry(cell(p)).or_default().push(p);
    }
    for &i in &gone {
        for p in full.corners(i) {
            let c = cell(p);
            let near = (-1..=1).flat_map(|z| {
                (-1..=1).flat_map(move |y| (-1..=1).map(move |x| I64Vec3::new(x, y, z)))
            });
            for d in near {
                for q in cells.get(&(c + d)).into_iter().flatten() {
                    assert!(p.distance(*q) > 5.0, "{p} left out, {q} kept");
                }
            }
        }
    }
    let (lo, hi) = (
        |m: &raystream_io::TriMesh| m.bounds().min,
        |m: &raystream_io::TriMesh| m.bounds().max,
    );
    assert_eq!(
        (lo(&body).x, hi(&body).x),
        (lo(&full).x, hi(&full).x),
        "the arms' bones"
    );
    assert!(
        hi(&body).y < hi(&full).y - 80.0,
        "{} {}",
        hi(&body).y,
        hi(&full).y
    );
    // `render` of the bones finds the same body.
    let png = tmp("body-bones.png");
    let o = run(&[
        "render",
        &ct,
        "--body-only",
        "--size",
        "48x48",
        "--device",
        "cpu",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(
        o.status.success() && stderr(&o).contains("the body, 3.33 l"),
        "{}",
        stderr(&o)
    );
}

/// A lone slice's bones: the slab of tissue it images, a spacing thick about the slice,
/// closed and facing out, enclosing about its bone voxels' volume (its grid's own surface was
/// a sheet 1/256 of a spacing thick, turned inside out); its islands counted in its voxels.
#[test]
fn iso_of_a_lone_slice_is_its_slab() {
    let dir = shared().join("data/volumes/dicom/ct_slice_transfer_syntaxes");
    let slice = dir.join("ct_1.2.840.10008.1.2.1_LittleEndianExplicit.dcm");
    let slice = slice.to_str().unwrap();
    let v = raystream_io::load_volume(Path::new(slice), &Default::default()).unwrap();
    assert_eq!(v.dims[2], 1);
    let bone = v.data.iter().filter(|&&x| x >= 300.0).count();
    let bone_ml = bone as f64 * v.voxel_ml();
    let (mesh, said) = iso_to(slice, "lone-slice.stl", &["--min-island", "0.000001"]);
    assert!(
        said.contains(&format!("of {bone_ml:.1} ml of voxels)")),
        "{said} ({bone} voxels, {bone_ml} ml)"
    );
    let s = mesh.measure_surface();
    assert!(s.closed(), "{s:?}");
    let ml = s.volume.unwrap() / 1000.0;
    assert!((ml / bone_ml - 1.0).abs() < 0.1, "{ml} ml for {bone_ml}");
    let b = mesh.bounds();
    let z = v.origin[2] as f32;
    let half = v.spacing[2] as f32 / 2.0;
    assert!(
        (b.min.z - (z - half)).abs() < 1e-3 && (b.max.z - (z + half)).abs() < 1e-3,
        "{b:?}"
    );
    // Its body is the slice's, once, whether its bones are made or its slab is projected.
    // (its line less the time it took)
    let body = |said: &str| {
        (said.lines().find(|l| l.contains("the body, ")))
            .and_then(|l| l.rsplit_once(" ("))
            .map(|(words, _)| words.to_string())
    };

    let (_, bones) = iso_to(slice, "lone-slice-body.stl", &["--body-only"]);
    let png = tmp("lone-slice-body.png");
    let o = run(&[
        "render",
        slice,
        "--mode",
        "minip",
        "--body-only",
        "--size",
        "32x32",
        "--device",
        "cpu",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        body(&bones).is_some() && body(&bones) == body(&stderr(&o)),
        "{bones}\n{}",
        stderr(&o)
    );
}

/// `--fill-cavities` on the chest CT's bones: it fills as many cavities as the full surface has
/// closed shells facing in, and takes away their triangles and no others; what is left
/// encloses their volume more, and has none facing in. Then a label map's hollow ball: one
/// shell where it had two, and its voxels counted with the hollow's.
#[test]
fn iso_fills_cavities() {
    let ct = volume("nifti/chest_ct_stents_totalseg.nii.gz");
    let iso = |name: &str, more: &[&str]| {
        let (mesh, said) = iso_to(&ct, name, more);
        let j = run(&["info", tmp(name).to_str().unwrap(), "--json"]);
        let j: serde_json::Value = serde_json::from_str(stdout(&j).trim()).unwrap();
        (mesh, j["surface"].clone(), said)
    };
    let (full, whole, _) = iso("cavities-full.stl", &[]);
    let (solid, left, said) = iso("cavities-filled.stl", &["--fill-cavities"]);
    let inward: Vec<&serde_json::Value> = (whole["pieces"].as_array().unwrap().iter())
        .filter(|p| p["closed"] == true && p["volume"].as_f64().unwrap() < 0.0)
        .collect();
    assert!(inward.len() > 100, "{}", inward.len());
    assert!(
        said.contains(&format!("filled {} cavities (", inward.len())),
        "{said}"
    );
    let corners =
        |m: &raystream_io::TriMesh, i: usize| m.corners(i).map(|p| p.to_array().map(f32::to_bits));
    let all: std::collections::HashSet<_> = (0..full.len()).map(|i| corners(&full, i)).collect();
    assert!((0..solid.len()).all(|i| all.contains(&corners(&solid, i))));
    let gone: u64 = inward
        .iter()
        .map(|p| p["triangles"].as_u64().unwrap())
        .sum();
    assert_eq!(solid.len() as u64, full.len() as u64 - gone);
    let pieces = left["pieces"].as_array().unwrap();
    assert!(pieces.iter().all(|p| p["volume"].as_f64().unwrap() > 0.0));
    assert_eq!(
        pieces.len() + inward.len(),
        whole["pieces"].as_array().unwrap().len()
    );
    let hollows: f64 = inward.iter().map(|p| p["volume"].as_f64().unwrap()).sum();
    let (before, after) = (
        whole["volume"].as_f64().unwrap(),
        left["volume"].as_f64().unwrap(),
    );
    assert!(
        (after - before + hollows).abs() < 1e-6 * before,
        "{before} {after} {hollows}"
    );

    // A label map: segment 1 a ball of radius 6 voxels hollow within 3.
    let like = raystream_io::Volume::hounsfield([16, 16, 16], [1.0, 1.5, 2.0], Vec::new());
    let mut labels = vec![0.0f32; 16 * 16 * 16];
    for (v, l) in labels.iter_mut().enumerate() {
        let d = [v % 16, v / 16 % 16, v / 256].map(|x| x as f64 - 7.5);
        let r = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        *l = f32::from(u8::from((3.0..=6.0).contains(&r)));
    }
    let ball = labels.iter().filter(|&&l| l == 1.0).count();
    let hollow = (0..labels.len())
        .filter(|&v| {
            let d = [v % 16, v / 16 % 16, v / 256].map(|x| x as f64 - 7.5);
            d.iter().map(|x| x * x).sum::<f64>() < 9.0
        })
        .count();
    let map = write_like("cavities-labels.mha", &like, &labels);
    let shells = |more: &[&str]| {
        let out = tmp("cavities-segment.stl");
        let mut args = vec!["iso", map.to_str().unwrap(), "--segment", "1", "-o"];
        args.push(out.to_str().unwrap());
        args.extend_from_slice(more);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let s = raystream_io::load_mesh(&out).unwrap().measure_surface();
        let facing_in = s.pieces.iter().filter(|p| p.volume < Some(0.0)).count();
        (s.shells, facing_in, stderr(&o))
    };
    assert_eq!(shells(&[]).0, 2);
    assert_eq!(shells(&[]).1, 1);
    let (n, facing_in, said) = shells(&["--fill-cavities"]);
    assert_eq!((n, facing_in), (1, 0));
    assert!(
        said.contains(&format!(": {} voxels, ", ball + hollow))
            && said.contains(&format!("(filled 1 cavity ({:.1} ml", hollow as f64 * 3e-3)),
        "{said}"
    );
}

/// `iso --colour-shells`: the built-in CT's bones as its ten largest shells, a 3MF object each,
/// named and coloured, each the triangles `info` counts for that shell of the whole surface,
/// then the rest; refused for a label map's segments.
#[test]
fn iso_parts_the_bones_by_shell() {
    let ct = builtin_ct();
    let info = |file: &Path| {
        let o = run(&["info", file.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str::<serde_json::Value>(stdout(&o).trim()).unwrap()
    };
    let (whole, said) = iso_to(&ct, "shells-whole.stl", &[]);
    assert!(!said.contains(" shells, "), "{said}");
    let pieces = info(&tmp("shells-whole.stl"))["surface"]["pieces"].clone();
    let (parted, said) = iso_to(&ct, "shells.3mf", &["--colour-shells"]);
    assert!(
        said.contains(": 1223 shells, the 10 largest a part each"),
        "{said}"
    );
    assert_eq!(parted.len(), whole.len());
    let j = info(&tmp("shells.3mf"));
    let objects = j["objects"].as_array().unwrap();
    let names: Vec<&str> = objects
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    let want: Vec<String> = (1..=10)
        .map(|k| format!("shell {k}"))
        .chain(["bone".into()])
        .collect();
    assert_eq!(names, want);
    for (k, o) in objects.iter().take(10).enumerate() {
        assert_eq!(o["triangles"], pieces[k]["triangles"], "shell {}", k + 1);
    }
    assert_eq!(j["colours"]["distinct"], 11);
    // As DICOM models: one a part, titled by it, each passing dciodvfy.
    let dcm = tmp("shells.dcm");
    let o = run(&["iso", &ct, "--colour-shells", "-o", dcm.to_str().unwrap()]);
    let said = stderr(&o);
    let (first, last) = (tmp("shells-1.dcm"), tmp("shells-11.dcm"));
    assert!(
        said.contains(&format!(
            "wrote {} … {} (11 files)",
            first.display(),
            last.display()
        )),
        "{said}"
    );
    for (file, title) in [(&first, "shell 1"), (&last, "bone")] {
        assert_eq!(iod_errors(file), Vec::<String>::new());
        let o = run(&["info", file.to_str().unwrap()]);
        assert!(
            stdout(&o).contains(&format!("Encapsulated STL \"{title}\"")),
            "{}",
            stdout(&o)
        );
    }
    let map = write_like(
        "shells-labels.mha",
        &raystream_io::Volume::hounsfield([4, 4, 4], [1.0; 3], Vec::new()),
        &[1.0; 64],
    );
    refused(
        &[
            "iso",
            map.to_str().unwrap(),
            "--segment",
            "1",
            "--colour-shells",
            "-o",
            tmp("shells-labels.stl").to_str().unwrap(),
        ],
        "cannot be used with",
    );
}

#[test]
fn iso_keeps_the_largest_islands() {
    let ct = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    let iso = |name: &str, more: &[&str]| iso_to(&ct, name, more);
    let (full, _) = iso("islands-full.stl", &[]);
    let corners =
        |m: &raystream_io::TriMesh, i: usize| m.corners(i).map(|p| p.to_array().map(f32::to_bits));
    let all: std::collections::HashSet<_> = (0..full.len()).map(|i| corners(&full, i)).collect();
    let mut last = 0;
    for n in [1, 2, 5] {
        let (kept, said) = iso(
            &format!("islands-{n}.stl"),
            &["--keep-largest", &n.to_string()],
        );
        assert!(
            said.contains(&format!("kept {n} of 1222 islands (")),
            "{said}"
        );
        let s = kept.measure_surface();
        assert!(
            s.closed() && s.shells >= n && s.shells < n + 10,
            "{n}: {s:?}"
        );
        assert!(
            (0..kept.len()).all(|i| all.contains(&corners(&kept, i))),
            "{n}"
        );
        assert!(
            kept.len() > last && kept.len() < full.len(),
            "{n}: {}",
            kept.len()
        );
        last = kept.len();
    }
    let (one, _) = iso("islands-1.stl", &["--keep-largest", "1"]);
    let (big, said) = iso("islands-1ml.stl", &["--min-island", "1"]);
    assert!(said.contains("kept 13 of 1222 islands ("), "{said}");
    assert!(big.len() > one.len() && big.len() < full.len());
    assert!((0..big.len()).all(|i| all.contains(&corners(&big, i))));
    let png = render_to(
        "islands.png",
        "cpu",
        &[&ct, "--keep-largest", "2", "--size", "64x48"],
    );
    assert!(png.exists());
    // The cavities filled are out of sight: the bones look the same from outside (the abdomen
    // CT's one is 0.005 mm³).
    let look = |name: &str, more: &[&str]| {
        let mut args = vec![ct.as_str(), "--size", "64x48"];
        args.extend_from_slice(more);
        image::open(render_to(name, "cpu", &args))
            .unwrap()
            .to_rgb8()
            .into_raw()
    };
    let (hollow, solid) = (
        look("islands-all.png", &[]),
        look("islands-solid.png", &["--fill-cavities"]),
    );
    let same = hollow
        .iter()
        .zip(&solid)
        .filter(|(a, b)| a.abs_diff(**b) <= 2)
        .count();
    assert!(
        same as f64 >= 0.999 * hollow.len() as f64,
        "{same} of {}",
        hollow.len()
    );

    // A label map: segment 1 a ball of radius 4 voxels and a speck of one voxel, segment 2 a
    // ball of radius 3.
    let like = raystream_io::Volume::hounsfield([30, 20, 20], [1.0, 1.5, 2.0], Vec::new());
    let mut labels = vec![0.0f32; 30 * 20 * 20];
    let mut ball = |c: [f64; 3], r: f64, l: f32| {
        for k in 0..20 {
            for j in 0..20 {
                for i in 0..30 {
                    let d = [i as f64 - c[0], j as f64 - c[1], k as f64 - c[2]];
                    if d.iter().map(|x| x * x).sum::<f64>() <= r * r {
                        labels[i + 30 * (j + 20 * k)] = l;
                    }
                }
            }
        }
    };
    ball([7.0, 8.0, 9.0], 4.0, 1.0);
    ball([20.0, 8.0, 9.0], 3.0, 2.0);
    ball([3.0, 17.0, 17.0], 0.0, 1.0);
    let voxels = |l: f32| labels.iter().filter(|&&v| v == l).count();
    let (one_ball, speck, other) = (voxels(1.0) - 1, 1, voxels(2.0));
    let map = write_like("islands-labels.mha", &like, &labels);
    let out = tmp("islands-segments.ply");
    let o = run(&[
        "iso",
        map.to_str().unwrap(),
        "--segment",
        "1,2",
        "--keep-largest",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let said = stderr(&o);
    assert!(
        said.contains(&format!("segment 1 (label 1): {one_ball} voxels, "))
            && said.contains(&format!(
                "(kept 1 of 2 islands ({:.1} of {:.1} ml of voxels))",
                one_ball as f64 * 3e-3,
                (one_ball + speck) as f64 * 3e-3
            )),
        "{said}"
    );
    assert!(
        said.contains(&format!("segment 2 (label 2): {other} voxels, ")),
        "{said}"
    );
    let surfaces = raystream_io::load_mesh(&out).unwrap();
    assert_eq!(surfaces.measure_surface().shells, 2);
    // An island of exactly ML is kept (its ml, not a rounding of it, decides); one voxel more
    // and it is refused, naming the file and the segment.
    let exactly = format!("{}", other as f64 * 0.003);
    let out = tmp("islands-exact.stl");
    let (map_file, out_file) = (map.to_str().unwrap(), out.to_str().unwrap());
    let o = run(&[
        "iso",
        map_file,
        "--segment",
        "2",
        "--min-island",
        &exactly,
        "-o",
        out_file,
    ]);
    assert!(o.status.success(), "{exactly}: {}", stderr(&o));
    let more = format!("{}", (other + 1) as f64 * 0.003);
    let e = refused(
        &[
            "iso",
            map_file,
            "--segment",
            "2",
            "--min-island",
            &more,
            "-o",
            out_file,
        ],
        "segment 2 (label 2): --min-island: no island holds",
    );
    assert!(e.contains("islands-labels.mha"), "{e}");

    // Refused, naming what is wrong.
    let e = refused(
        &[
            "iso",
            &ct,
            "-o",
            tmp("x.stl").to_str().unwrap(),
            "--min-island",
            "500",
        ],
        "no island holds 500.0",
    );
    assert!(
        e.contains("abdomen_pelvis_ct_totalseg.nii.gz")
            && e.contains("the largest of 1222 holds 99.792 ml"),
        "{e}"
    );
    refused(
        &[
            "iso",
            &ct,
            "-o",
            tmp("x.stl").to_str().unwrap(),
            "--keep-largest",
            "0",
        ],
        "--keep-largest",
    );
    refused(
        &[
            "render",
            &ct,
            "--mode",
            "mip",
            "--keep-largest",
            "1",
            "-o",
            tmp("x.png").to_str().unwrap(),
        ],
        "--mode renders the volume itself",
    );
    refused(
        &[
            "render",
            &mesh("spot.obj"),
            "--min-island",
            "1",
            "-o",
            tmp("x.png").to_str().unwrap(),
        ],
        "a mesh or scene has none",
    );
}

/// `iso SERIES -o MODEL.dcm`: the bones as a DICOM Encapsulated STL, filed with the CT series'
/// patient and study, in its frame of reference, referencing every one of its images once;
/// dciodvfy finds no error in it. Read back (`info`, `render`, the mesh reader) it is the STL
/// `iso` writes of the same surface, triangle for triangle, in LPS; in the series' folder it is
/// skipped with a warning and the CT still reads. Made from a NIfTI it opens a study and a
/// frame of reference of its own and references no image. Two segments are two models in one
/// series (`-1.dcm`, `-2.dcm`), and a `.dcm` asked of the plain mesh writer is told how to
/// make one.
#[test]
fn iso_files_an_encapsulated_stl_with_its_study() {
    use raystream_io::{DicomStudy, load_mesh};
    let dir = tmp("estl-series");
    let study: DicomStudy = chest_series(&dir);
    let slices: Vec<dicom_object::DefaultDicomObject> = (1..)
        .map(|k| dir.join(format!("{k:04}.dcm")))
        .take_while(|f| f.exists())
        .map(|f| dicom_object::open_file(f).unwrap())
        .collect();
    let series = dicom_text(&slices[0], dicom_dictionary_std::tags::SERIES_INSTANCE_UID);
    let iso = |input: &str, out: &str, more: &[&str]| {
        let path = tmp(out);
        let mut args = vec![
            "iso",
            input,
            "--keep-largest",
            "1",
            "-o",
            path.to_str().unwrap(),
        ];
        args.extend_from_slice(more);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        path
    };
    let series_dir = dir.to_str().unwrap();
    let model = iso(series_dir, "estl-bones.dcm", &[]);
    let stl = iso(series_dir, "estl-bones.stl", &[]);
    assert_eq!(iod_errors(&model), Vec::<String>::new());
    let (a, b) = (load_mesh(&model).unwrap(), load_mesh(&stl).unwrap());
    assert!(a.len() > 1000 && a.positions == b.positions && a.triangles == b.triangles);
    let obj = dicom_object::open_file(&model).unwrap();
    use dicom_dictionary_std::tags;
    let t = |tag| dicom_text(&obj, tag);
    assert_eq!(t(tags::SOP_CLASS_UID), raystream_io::ENCAPSULATED_STL);
    assert_eq!(t(tags::MODALITY), "M3D");
    assert_eq!(t(tags::MIME_TYPE_OF_ENCAPSULATED_DOCUMENT), "model/stl");
    assert_eq!(t(tags::DOCUMENT_TITLE), "bones at 300 HU");
    assert_eq!(t(tags::STUDY_INSTANCE_UID), study.study_uid);
    assert_eq!(
        t(tags::FRAME_OF_REFERENCE_UID),
        study.frame_of_reference_uid
    );
    assert_eq!(t(tags::PATIENT_NAME), "MÜLLER^JÖRG");
    assert_ne!(t(tags::SERIES_INSTANCE_UID), series);
    let length = obj
        .element(tags::ENCAPSULATED_DOCUMENT_LENGTH)
        .unwrap()
        .to_int::<u64>()
        .unwrap();
    assert_eq!(length, std::fs::metadata(&stl).unwrap().len());
    let images: Vec<String> = (slices.iter())
        .map(|s| dicom_text(s, tags::SOP_INSTANCE_UID))
        .collect();
    let referenced = |items: &[dicom_object::InMemDicomObject]| -> Vec<String> {
        (items.iter())
            .map(|i| {
                assert_eq!(
                    i.element(tags::REFERENCED_SOP_CLASS_UID)
                        .unwrap()
                        .to_str()
                        .unwrap()
                        .trim_end_matches('\0'),
                    dicom_text(&slices[0], tags::SOP_CLASS_UID)
                );
                let uid = i
                    .element(tags::REFERENCED_SOP_INSTANCE_UID)
                    .unwrap()
                    .to_str()
                    .unwrap();
                uid.trim_end_matches('\0').to_string()
            })
            .collect()
    };
    let sources = referenced(
        obj.element(tags::SOURCE_INSTANCE_SEQUENCE)
            .unwrap()
            .items()
            .unwrap(),
    );
    assert_eq!(sources, images);
    let refs = obj
        .element(tags::REFERENCED_SERIES_SEQUENCE)
        .unwrap()
        .items()
        .unwrap();
    assert_eq!(refs.len(), 1);
    assert_eq!(
        refs[0]
            .element(tags::SERIES_INSTANCE_UID)
            .unwrap()
            .to_str()
            .unwrap()
            .trim_end_matches('\0'),
        series
    );
    assert_eq!(
        referenced(
            refs[0]
                .element(tags::REFERENCED_INSTANCE_SEQUENCE)
                .unwrap()
                .items()
                .unwrap()
        ),
        images
    );

    // `info` and `render` take it as a mesh in LPS millimetres.
    let o = run(&["info", model.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        (j["kind"].as_str(), j["space"].as_str()),
        (Some("mesh"), Some("LPS"))
    );
    assert_eq!(j["triangles"], a.len());
    let d = &j["dicom"];
    assert_eq!(d["title"], "bones at 300 HU");
    assert_eq!(
        (d["patient_name"].as_str(), d["patient_id"].as_str()),
        (Some("MÜLLER^JÖRG"), Some("RS-0042"))
    );
    assert_eq!(d["study_uid"], study.study_uid.as_str());
    assert_eq!(
        d["frame_of_reference_uid"],
        study.frame_of_reference_uid.as_str()
    );
    assert_eq!(d["source_series"], serde_json::json!([series]));
    assert_eq!(d["source_images"], slices.len());
    let text = stdout(&run(&["info", model.to_str().unwrap()]));
    assert!(text.contains(&format!("  dicom      Encapsulated STL \"bones at 300 HU\"; of patient MÜLLER^JÖRG, RS-0042; study {}, 20261202; made from {} images of series {series}\n", study.study_uid, slices.len())), "{text}");
    assert!(
        render_to(
            "estl.png",
            "cpu",
            &[model.to_str().unwrap(), "--size", "48x32"]
        )
        .exists()
    );
    // A scene lays it over its CT, in the patient's millimetres: its triangles, its LPS box in
    // the scene's frame (x the patient's left, y superior, z anterior), within the CT's.
    let b = a.bounds();
    let want = [[b.min.x, b.min.z, -b.max.y], [b.max.x, b.max.z, -b.min.y]];
    for volume in [false, true] {
        let scene = tmp("estl-scene.toml");
        let ct = format!(
            "[volume]\npath = {:?}\npreset = \"ct-aaa\"\n\n",
            dir.to_str().unwrap()
        );
        let object = format!("[[objects]]\nmesh = {:?}\n", model.to_str().unwrap());
        std::fs::write(&scene, if volume { ct + &object } else { object }).unwrap();
        let o = run(&["info", scene.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(j["triangles"], a.len());
        // The box: the model's alone, or the CT's around it.
        let got: [[f32; 3]; 2] = serde_json::from_value(j["bounds"].clone()).unwrap();
        if volume {
            assert!(
                (0..3).all(|k| got[0][k] <= want[0][k] && got[1][k] >= want[1][k]),
                "{j}"
            );
        } else {
            assert_eq!(got, want, "{j}");
        }
    }
    // In the series' folder, skipped: the CT still reads.
    std::fs::copy(&model, dir.join("model.dcm")).unwrap();
    let ct = raystream_io::load_volume(&dir, &Default::default()).unwrap();
    assert_eq!(ct.dims[2], slices.len());
    assert!(
        ct.warnings
            .iter()
            .any(|w| w.contains("model.dcm") && w.contains("Encapsulated STL")),
        "{:?}",
        ct.warnings
    );

    // From a NIfTI: a study and a frame of reference of its own, no image referenced.
    let own = iso(&chest(), "estl-nifti.dcm", &[]);
    assert_eq!(iod_errors(&own), Vec::<String>::new());
    let o2 = dicom_object::open_file(&own).unwrap();
    assert!(!dicom_text(&o2, tags::STUDY_INSTANCE_UID).is_empty());
    assert_ne!(dicom_text(&o2, tags::STUDY_INSTANCE_UID), study.study_uid);
    assert!(o2.element(tags::SOURCE_INSTANCE_SEQUENCE).is_err());
    let o = run(&["info", own.to_str().unwrap(), "--json"]);
    let j: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(
        (
            j["dicom"]["source_images"].as_u64(),
            j["dicom"]["source_series"].as_array().map(Vec::len)
        ),
        (Some(0), Some(0))
    );
    assert_eq!(load_mesh(&own).unwrap().triangles, a.triangles);

    // Several segments; the mesh writer points to iso.
    let like = raystream_io::Volume::hounsfield([8, 8, 8], [1.0; 3], Vec::new());
    let mut labels = vec![0.0f32; 512];
    labels[2 + 8 * (2 + 8 * 2)] = 1.0;
    labels[5 + 8 * (5 + 8 * 5)] = 2.0;
    let map = write_like("estl-labels.mha", &like, &labels);
    // Two segments: two models in one series, numbered, each titled by its segment.
    let two = tmp("estl-two.dcm");
    std::fs::remove_file(&two).ok();
    let o = run(&[
        "iso",
        map.to_str().unwrap(),
        "--segment",
        "all",
        "-o",
        two.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!two.exists());
    let models: Vec<dicom_object::DefaultDicomObject> = [1, 2]
        .map(|k| {
            let file = tmp(&format!("estl-two-{k}.dcm"));
            assert!(
                stderr(&o).contains(file.to_str().unwrap()),
                "{}",
                stderr(&o)
            );
            assert_eq!(iod_errors(&file), Vec::<String>::new());
            assert_eq!(load_mesh(&file).unwrap().measure_surface().shells, 1);
            dicom_object::open_file(&file).unwrap()
        })
        .into();
    let series: Vec<String> = (models.iter())
        .map(|m| dicom_text(m, tags::SERIES_INSTANCE_UID))
        .collect();
    assert_eq!(series[0], series[1]);
    for (k, m) in models.iter().enumerate() {
        assert_eq!(dicom_text(m, tags::INSTANCE_NUMBER), (k + 1).to_string());
        assert_eq!(
            dicom_text(m, tags::DOCUMENT_TITLE),
            format!("label {}", k + 1)
        );
    }
    let e = raystream_io::write_mesh(&tmp("plain.dcm"), &a, None).unwrap_err();
    assert!(
        e.to_string().contains("raystream iso VOLUME -o MODEL.dcm"),
        "{e}"
    );
}

/// The CT's integers at the integer threshold: where voxels are exactly 300 HU (110 are)
/// the raw surface still puts no two vertices on one point, and simplified within 0.3 and 1 mm
/// it stays closed and a 2-manifold by its indices, at its edges and its vertices (a 3D
/// printer's slicer and lib3mf take it),
/// each vertex one of the full surface's, which lies within the bound of it. So within 128 mm,
/// with fewer triangles than within 1 mm (with five tries, where none converged, the surface
/// was left whole).
#[test]
fn raw_ct_bones_simplify_to_a_closed_manifold() {
    let ct = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    let at = raystream_io::load_volume(Path::new(&ct), &Default::default())
        .unwrap()
        .data
        .iter()
        .filter(|&&v| v == 300.0)
        .count();
    assert!(at >= 100, "{at} voxels at 300 HU");
    let iso = |name: &str, more: &[&str]| {
        let out = tmp(name);
        let mut args = vec![
            "iso",
            &ct,
            "--smooth",
            "0",
            "-o",
            out.to_str().unwrap(),
            "--quiet",
        ];
        args.extend_from_slice(more);
        let o = run(&args);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        raystream_io::load_mesh(&out).unwrap()
    };
    let bits = |m: &raystream_io::TriMesh| -> std::collections::HashSet<[u32; 3]> {
        m.positions
            .iter()
            .map(|p| p.to_array().map(f32::to_bits))
            .collect()
    };
    let full = iso("abdomen-raw.ply", &[]);
    let points = bits(&full);
    assert_eq!(
        points.len(),
        full.positions.len(),
        "vertices sharing a point"
    );
    assert!(closed_and_oriented(&full));
    let mut kept = Vec::new();
    for mm in ["0.3", "1", "128"] {
        let simple = iso(&format!("abdomen-raw-{mm}.ply"), &["--simplify", mm]);
        kept.push(simple.len());
        assert!(
            simple.len() * 4 < full.len() * 3,
            "{mm} mm: {} of {}",
            simple.len(),
            full.len()
        );
        assert!(
            closed_and_oriented(&simple),
            "{mm} mm: not a closed 2-manifold"
        );
        let pinched = raystream_volume::pinched_vertices(&simple.triangles);
        assert!(
            pinched.is_empty(),
            "{mm} mm: pinched at vertices {pinched:?}"
        );
        assert!(
            bits(&simple).is_subset(&points),
            "{mm} mm: a vertex not the full surface's"
        );
        let bound: f64 = mm.parse().unwrap();
        let d = raystream_volume::departure(&full.positions, &simple, bound);
        assert!(d <= bound, "{mm} mm: departs {d} mm");
    }
    assert!(kept.is_sorted_by(|a, b| a > b), "triangles kept: {kept:?}");
}

#[test]
fn render_dicom_folders_a_tilted_one_too() {
    let out = tmp("j2k-bones.png");
    let o = run(&[
        "render",
        &volume("dicom/abdomen_ct_j2k_totalseg"),
        "--size",
        "64x48",
        "--spp",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("isosurface"), "{}", stderr(&o));
    let img = image::open(&out).unwrap().to_rgb8();
    // Bone is bright ivory: some pixels must be far brighter than the dark background.
    let bright = img.pixels().filter(|p| p[0] > 150 && p[1] > 140).count();
    assert!(bright > 50, "{bright} bright pixels");

    // A gantry-tilted head CT with uneven spacing renders, saying what was done to it.
    let out = tmp("tilted.png");
    let o = run(&[
        "render",
        &volume("dicom/head_ct_gantry_tilt_ge"),
        "--size",
        "64x48",
        "--spp",
        "1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("gantry tilt of 18.5°") && e.contains("uneven slice spacing, 1.14 to 7.38 mm"),
        "{e}"
    );
    let img = image::open(&out).unwrap().to_rgb8();
    let bright = img.pixels().filter(|p| p[0] > 150 && p[1] > 140).count();
    assert!(bright > 300, "{bright} bright pixels");
    let o = run(&[
        "iso",
        &volume("nifti/scivis_engine.nii.gz"),
        "--hu",
        "1000",
        "-o",
        tmp("none.ply").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no surface at 1000"), "{}", stderr(&o));
}

/// `--labels` marks the patient's directions at the edges: in the anterior MIP the patient's
/// left (L) on the image's right, R on its left, S above, I below, each letter exactly its
/// glyph in white cells; elsewhere the picture is the unlabelled one. A lateral view (from the
/// patient's left) puts A on the left and P on the right. Meshes, EXRs and AOVs are refused.
#[test]
fn labels_mark_the_patients_directions() {
    // 5×7 glyphs, a row a byte, the leftmost cell in bit 4 (the oracle: written out here).
    let glyphs = [
        ('L', [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f]),
        ('R', [0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11]),
        ('S', [0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e]),
        ('I', [0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e]),
        ('A', [0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11]),
        ('P', [0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10]),
    ];
    let (w, h) = (128u32, 96u32);
    let render = |name: &str, extra: &[&str]| {
        let out = tmp(&format!("labels-{name}.png"));
        let mut args = vec!["render", "--mode", "mip", "--size", "128x96", "--quiet"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        image::open(&out).unwrap().to_rgb8()
    };
    // Where each edge's letter sits at this size (a cell a pixel, two from the edge).
    let (mid_x, mid_y) = ((w - 5) / 2, (h - 7) / 2);
    let boxes = [(mid_x, 2), (mid_x, h - 9), (2, mid_y), (w - 7, mid_y)];
    for (name, view, letters) in [
        ("anterior", "anterior", ['S', 'I', 'R', 'L']),
        ("left", "left", ['S', 'I', 'A', 'P']),
    ] {
        let plain = render(&format!("{name}-plain"), &["--view", view]);
        let marked = render(name, &["--view", view, "--labels"]);
        for ((x0, y0), letter) in boxes.iter().zip(letters) {
            let g = glyphs.iter().find(|(c, _)| *c == letter).unwrap().1;
            for row in 0..7u32 {
                for col in 0..5u32 {
                    let set = g[row as usize] & (0x10 >> col) != 0;
                    let p = marked.get_pixel(x0 + col, y0 + row).0;
                    assert_eq!(p == [255; 3], set, "{name}: {letter} row {row} col {col}");
                }
            }
        }
        // Outside the letters and their rings, the pixels are the unlabelled frame's.
        let near = |x: u32, y: u32| {
            boxes
                .iter()
                .any(|&(bx, by)| x + 1 >= bx && x <= bx + 5 && y + 1 >= by && y <= by + 7)
        };
        for (x, y, p) in marked.enumerate_pixels() {
            if !near(x, y) {
                assert_eq!(p, plain.get_pixel(x, y), "{name}: ({x}, {y})");
            }
        }
    }
    for (args, why) in [
        (
            vec!["render", &mesh("spot.obj"), "--labels", "-o", "x.png"],
            "--labels marks a patient's directions",
        ),
        (
            vec!["render", "--mode", "mip", "--labels", "-o", "x.exr"],
            "--labels draws on a PNG",
        ),
        (
            vec!["render", "--aov", "depth", "--labels", "-o", "x.png"],
            "not an AOV's values",
        ),
    ] {
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2));
        assert!(stderr(&o).contains(why), "{}", stderr(&o));
    }
}

/// `--scale-bar`: on a parallel MIP of the built-in CT (its EXR's comments give the pixel size)
/// the bar's white run along its middle row is, in pixels, the round length its label says,
/// and at most a fifth of the width; elsewhere than the bottom right corner the picture is
/// the plain one. A sagittal slice, the bones seen in parallel and a CPR get one too; a
/// perspective view, an EXR, a mesh and an AOV are refused.
#[test]
fn a_scale_bar_measures_the_picture() {
    let (w, h) = (200u32, 150u32);
    let render = |name: &str, extra: &[&str]| {
        let args = [&["--size", "200x150"][..], extra].concat();
        render_to(&format!("scale-{name}"), "cpu", &args)
    };
    let mip = ["--mode", "mip", "--parallel"];
    let mm_px = exr_pixel_mm(&render("mip.exr", &mip));
    // The rule, written out: the longest 1, 2 or 5 x 10^k mm within a fifth of the width.
    let most = w as f64 / 5.0 * mm_px;
    let want_mm = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]
        .into_iter()
        .rfind(|&l| l <= most)
        .unwrap();
    let want_px = (want_mm / mm_px).round() as usize;
    let open = |p: &std::path::Path| image::open(p).unwrap().to_rgb8();
    let plain = open(&render("mip.png", &mip));
    let barred = open(&render(
        "mip-bar.png",
        &[&mip[..], &["--scale-bar"]].concat(),
    ));
    // The longest white run in the bottom fifth's rows.
    let run_of = |img: &image::RgbImage| {
        (h * 4 / 5..h)
            .map(|y| {
                let (mut best, mut cur) = (0, 0);
                for x in 0..w {
                    cur = if img.get_pixel(x, y).0 == [255; 3] {
                        cur + 1
                    } else {
                        0
                    };
                    best = best.max(cur);
                }
                best
            })
            .max()
            .unwrap()
    };
    eprintln!("{mm_px} mm a pixel: a {want_mm} mm bar of {want_px} pixels");
    assert_eq!(run_of(&barred), want_px);
    assert!(want_px as u32 <= w / 5 && want_px > 5);
    for (x, y, p) in barred.enumerate_pixels() {
        if x < w / 2 || y < h / 2 {
            assert_eq!(p, plain.get_pixel(x, y), "({x}, {y}) changed");
        }
    }
    // A slice, the bones in parallel, a CPR: a bar drawn, the picture changed only there.
    let path = aorta();
    let chest = chest();
    for (name, args) in [
        ("slice", vec!["--mode", "slice", "--view", "left"]),
        ("bones", vec!["--parallel", "--spp", "1"]),
        (
            "cpr",
            vec![&chest[..], "--mode", "slice", "--path", &path[..]],
        ),
    ] {
        let plain = open(&render(&format!("{name}.png"), &args));
        let barred = open(&render(
            &format!("{name}-bar.png"),
            &[&args[..], &["--scale-bar"]].concat(),
        ));
        let changed: Vec<(u32, u32)> = barred
            .enumerate_pixels()
            .filter(|(x, y, p)| *p != plain.get_pixel(*x, *y))
            .map(|(x, y, _)| (x, y))
            .collect();
        assert!(changed.len() > 20, "{name}: {} changed", changed.len());
        assert!(
            changed.iter().all(|&(x, y)| x >= w / 2 && y >= h / 2),
            "{name}: drawn outside the corner"
        );
    }
    for (args, why) in [
        (
            vec!["render", "--mode", "mip", "--scale-bar", "-o", "x.png"],
            "a perspective view has no one scale",
        ),
        (
            vec![
                "render",
                "--mode",
                "mip",
                "--parallel",
                "--scale-bar",
                "-o",
                "x.exr",
            ],
            "--scale-bar draws on a PNG",
        ),
        (
            vec![
                "render",
                &mesh("spot.obj"),
                "--parallel",
                "--scale-bar",
                "-o",
                "x.png",
            ],
            "--scale-bar measures millimetres",
        ),
        (
            vec!["render", "--aov", "depth", "--scale-bar", "-o", "x.png"],
            "not an AOV's values",
        ),
    ] {
        let o = run(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(why), "{args:?}: {}", stderr(&o));
    }
}

/// `-o OUT.dcm`: the PNG's pixels as a DICOM Secondary Capture image that GDCM (through
/// SimpleITK) reads, filed with the source series' patient and study, in a new series, with
/// its Patient Orientation (the anterior view: rows toward the patient's left, columns toward
/// the feet) and the letters drawn said as Burned In Annotation.
#[test]
fn renders_save_as_dicom_secondary_capture() {
    let Some(py) = python_with_simpleitk() else {
        return;
    };
    let head = volume("dicom/head_ct_gantry_tilt_ge");
    let (dcm, png, frames) = (tmp("sc-head.dcm"), tmp("sc-head.png"), tmp("sc-turntable"));
    std::fs::remove_dir_all(&frames).ok();
    // A frame as DICOM and PNG, and a turntable of DICOM frames (one series, numbered, frame 0
    // the single frame).
    for (out, extra) in [
        (&dcm, &[][..]),
        (&png, &[][..]),
        (&frames, &["--turntable", "3", "--format", "dcm"][..]),
    ] {
        let mut args = vec![
            "render", &head, "--mode", "mip", "--labels", "--size", "48x40",
        ];
        args.extend_from_slice(&["--quiet", "-o", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let script = r#"
import sys, json, glob, SimpleITK as sitk
def tags(path, keys):
    r = sitk.ImageFileReader(); r.SetFileName(path); r.ReadImageInformation()
    return {k: r.GetMetaData(k).strip() if r.HasMetaDataKey(k) else None for k in keys}
keys = ["0008|0016", "0008|0060", "0010|0010", "0010|0020", "0020|000d", "0020|000e",
        "0020|0020", "0028|0301", "0008|103e"]
src = tags(sorted(glob.glob(sys.argv[2] + "/*.dcm"))[0], keys)
out = tags(sys.argv[1], keys)
pixels = sitk.GetArrayFromImage(sitk.ReadImage(sys.argv[1])).reshape(-1).tolist()
frames = [tags(f, ["0020|000e", "0020|0013"]) for f in sorted(glob.glob(sys.argv[3] + "/*"))]
first = sitk.GetArrayFromImage(sitk.ReadImage(sys.argv[3] + "/frame_000.dcm")).reshape(-1).tolist()
print(json.dumps({"src": src, "out": out, "pixels": pixels, "frames": frames, "first": first}))
"#;
    let o = std::process::Command::new(&py)
        .args([
            "-c",
            script,
            dcm.to_str().unwrap(),
            &head,
            frames.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let (src, out) = (&v["src"], &v["out"]);
    assert_eq!(
        out["0008|0016"], "1.2.840.10008.5.1.4.1.1.7",
        "Secondary Capture"
    );
    assert_eq!(out["0008|0060"], "OT");
    assert_eq!(iod_errors(&dcm), Vec::<String>::new());
    for k in ["0010|0010", "0010|0020", "0020|000d"] {
        assert!(!src[k].as_str().unwrap().is_empty(), "{k}");
        assert_eq!(out[k], src[k], "{k}: the source's patient and study");
    }
    assert_ne!(out["0020|000e"], src["0020|000e"], "a series of its own");
    assert_eq!(out["0020|0020"], "L\\F");
    assert_eq!(out["0028|0301"], "YES");
    assert_eq!(
        out["0008|103e"],
        "raystream render --mode mip --labels --size 48x40 --quiet"
    );
    let want = image::open(&png).unwrap().to_rgb8().into_raw();
    let got: Vec<u8> = v["pixels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_u64().unwrap() as u8)
        .collect();
    assert_eq!(got, want, "the PNG's pixels");
    let f = v["frames"].as_array().unwrap();
    assert_eq!(f.len(), 3);
    for (i, frame) in f.iter().enumerate() {
        assert_eq!(frame["0020|000e"], f[0]["0020|000e"], "one series");
        assert_eq!(frame["0020|0013"], (i + 1).to_string(), "numbered from 1");
    }
    assert_ne!(f[0]["0020|000e"], out["0020|000e"]);
    assert_eq!(v["first"], v["pixels"], "frame 0 is the single frame");
    // An AOV is not written as DICOM.
    let o = run(&["render", "--aov", "depth", "-o", "x.dcm"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("not DICOM"), "{}", stderr(&o));
}

/// `--mode slice -o OUT.dcm` (and a slab's projection seen square on) is a reformatted CT
/// image, as scanners store reformats: CT Image Storage, DERIVED\SECONDARY\REFORMATTED, in the
/// source's frame of reference, with its plane. Read back as a volume, every pixel holds the
/// source's value (trilinear, rounded to 1 HU) at the point its plane puts it, for a sagittal
/// slice and an oblique one; a slab MIP's plane passes through its middle with its thickness.
/// GDCM (SimpleITK) reads the same plane. A whole-volume MIP lies on no plane: a Secondary
/// Capture.
#[test]
fn slices_save_as_reformatted_ct_where_their_pixels_lie() {
    // The tilted head CT: its grid is sheared, which the plane must not care about.
    let series = volume("dicom/head_ct_gantry_tilt_ge");
    let src =
        raystream_io::load_volume(std::path::Path::new(&series), &Default::default()).unwrap();
    let source_frame = "1.2.826.0.1.3680043.9.4245.7256807831338624888091981779758557877";
    for (name, args) in [
        ("sagittal", &["--view", "left"][..]),
        (
            "oblique",
            &["--orbit", "35,25", "--slice-at", "-20,10,70"][..],
        ),
    ] {
        let out = tmp(&format!("reformat-{name}.dcm"));
        let mut all = vec![
            "render", &series, "--mode", "slice", "--size", "64x56", "--device", "cpu",
        ];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--quiet", "-o", out.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        let v = info(out.to_str().unwrap());
        assert_eq!(v["series"]["modality"], "CT", "{name}");
        assert_eq!(iod_errors(&out), Vec::<String>::new(), "{name}");
        let img = raystream_io::load_volume(&out, &Default::default()).unwrap();
        assert_eq!(img.dims, [64, 56, 1], "{name}");
        let (matching, compared) = voxels_where_they_lie(&img, &src);
        assert!(
            compared > 64 * 56 / 4,
            "{name}: only {compared} pixels inside"
        );
        assert!(
            matching as f64 >= 0.99 * compared as f64,
            "{name}: {matching} of {compared} pixels hold the source's value where they lie"
        );
        let file = std::fs::read(&out).unwrap();
        let has = |s: &str| file.windows(s.len()).any(|w| w == s.as_bytes());
        assert!(
            has("DERIVED\\SECONDARY\\REFORMATTED") && has(source_frame),
            "{name}"
        );
        // GDCM's reading of the plane is ours.
        if let Some(py) = python_with_simpleitk() {
            let script = "import sys, json, SimpleITK as s; i = s.ReadImage(sys.argv[1]); \
                          print(json.dumps([i.GetOrigin(), i.GetDirection(), i.GetSpacing()[:2]]))";
            let o = std::process::Command::new(&py)
                .args(["-c", script, out.to_str().unwrap()])
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", stderr(&o));
            let g: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
            close(&g[0], &v["origin"], 1e-4, "origin");
            close(&g[1], &v["direction"], 1e-5, "direction");
            close(
                &g[2],
                &serde_json::json!(v["spacing"].as_array().unwrap()[..2]),
                1e-6,
                "spacing",
            );
        }
    }
    // A slab MIP, seen from the front: its plane through the slab's middle, 10 mm thick.
    let out = tmp("reformat-slab.dcm");
    let o = run(&[
        "render",
        &series,
        "--mode",
        "mip",
        "--slab",
        "10",
        "--slice-at",
        "0,-30,80",
        "--view",
        "anterior",
        "--parallel",
        "--size",
        "48x40",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = info(out.to_str().unwrap());
    let origin = v["origin"].as_array().unwrap()[1].as_f64().unwrap();
    assert!((origin + 30.0).abs() < 1e-3, "the plane is y = -30 mm: {v}");
    let obj = dicom_object::open_file(&out).unwrap();
    let text = |tag| dicom_text(&obj, tag);
    use dicom_dictionary_std::tags;
    assert_eq!(text(tags::SLICE_THICKNESS), "10");
    assert_eq!(text(tags::SOP_CLASS_UID), "1.2.840.10008.5.1.4.1.1.2");
    // A whole-volume MIP: a Secondary Capture.
    let out = tmp("reformat-mip.dcm");
    let o = run(&[
        "render",
        &series,
        "--mode",
        "mip",
        "--size",
        "48x40",
        "--quiet",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let file = std::fs::read(&out).unwrap();
    assert!(file.windows(25).any(|w| w == b"1.2.840.10008.5.1.4.1.1.7"));
}

/// `src`'s value at a world point, as the renderers sample it (trilinear in the index space),
/// or `None` outside its voxel-centre box.
fn sample(src: &raystream_io::Volume, p: raystream_math::DVec3) -> Option<f64> {
    use raystream_math::DVec3;
    let q = src.world_to_index(p);
    let d = src.dims.map(|n| n as f64 - 1.0);
    if (0..3).any(|a| q[a] < -1e-6 || q[a] > d[a] + 1e-6) {
        return None;
    }
    let q = DVec3::new(
        q.x.clamp(0.0, d[0]),
        q.y.clamp(0.0, d[1]),
        q.z.clamp(0.0, d[2]),
    );
    let i = q.floor().as_uvec3();
    let f = q - q.floor();
    let at = |a: u32, b: u32, c: u32| {
        let [x, y, z] = [i.x + a, i.y + b, i.z + c].map(|v| v as usize);
        src.at(
            x.min(src.dims[0] - 1),
            y.min(src.dims[1] - 1),
            z.min(src.dims[2] - 1),
        ) as f64
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(at(0, 0, 0), at(1, 0, 0), f.x);
    let x10 = lerp(at(0, 1, 0), at(1, 1, 0), f.x);
    let x01 = lerp(at(0, 0, 1), at(1, 0, 1), f.x);
    let x11 = lerp(at(0, 1, 1), at(1, 1, 1), f.x);
    Some(lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z))
}

/// How many of `img`'s voxels inside `src` hold `src`'s value where they lie (within 1 HU of
/// it rounded), of how many inside.
fn voxels_where_they_lie(img: &raystream_io::Volume, src: &raystream_io::Volume) -> (usize, usize) {
    let (mut matching, mut inside) = (0, 0);
    for k in 0..img.dims[2] {
        for j in 0..img.dims[1] {
            for i in 0..img.dims[0] {
                let p = raystream_math::DVec3::new(i as f64, j as f64, k as f64);
                if let Some(want) = sample(src, img.index_to_world(p)) {
                    inside += 1;
                    if (img.at(i, j, k) as f64 - want.round()).abs() <= 1.0 {
                        matching += 1;
                    }
                }
            }
        }
    }
    (matching, inside)
}

/// `--mode slice --slices N --slice-step MM --format dcm -o DIR`: a reformatted series (N
/// parallel planes, one DICOM series) that reads back as a volume: N slices MM apart along the
/// view, the pixels' size across, and every voxel the source's value where it lies, for a
/// coronal series and an oblique one of the tilted head CT; the GPU's series is the CPU's
/// (the same planes, the values within its half-float texture's error). Without a plane to
/// step (--mode mip alone) it is refused.
#[test]
fn a_slice_series_reads_back_as_the_reformatted_volume() {
    let series = volume("dicom/head_ct_gantry_tilt_ge");
    let src =
        raystream_io::load_volume(std::path::Path::new(&series), &Default::default()).unwrap();
    for (name, n, step, args) in [
        ("coronal", 12, 3.0, &["--view", "anterior"][..]),
        (
            "oblique",
            5,
            4.5,
            &["--orbit", "20,-15", "--slice-at", "0,0,90"][..],
        ),
    ] {
        let (n_arg, step_arg) = (n.to_string(), step.to_string());
        let all = [&["--slices", &n_arg, "--slice-step", &step_arg][..], args].concat();
        let img = reformat_series(&series, "cpu", name, &all);
        assert_eq!(img.dims, [48, 40, n], "{name}");
        assert!(
            (img.spacing[2] - step).abs() < 1e-6,
            "{name}: {:?}",
            img.spacing
        );
        assert!(img.warnings.is_empty(), "{name}: {:?}", img.warnings);
        let (matching, inside) = voxels_where_they_lie(&img, &src);
        assert!(
            inside > 48 * 40 * n / 4,
            "{name}: only {inside} voxels inside"
        );
        assert!(
            matching as f64 >= 0.99 * inside as f64,
            "{name}: {matching} of {inside} voxels hold the source's value where they lie"
        );
    }
    // The GPU writes the same series: the same planes, the same pixels outside the volume, the
    // values within a half-float texture's error (f16 steps 2 HU near 2000 HU; hardware
    // filtering weighs neighbours to 1/256, 3600 HU apart at most: 14 HU).
    if gpu_available() {
        let args = ["--slices", "4", "--view", "left"];
        let series_on = |dev: &str| reformat_series(&series, dev, dev, &args);
        let (cpu, gpu) = (series_on("cpu"), series_on("gpu"));
        assert_eq!((cpu.dims, cpu.origin), (gpu.dims, gpu.origin));
        assert_eq!((cpu.spacing, cpu.direction), (gpu.spacing, gpu.direction));
        let mut diffs: Vec<f32> = Vec::new();
        for (c, g) in cpu.data.iter().zip(&gpu.data) {
            assert_eq!(*c == -32768.0, *g == -32768.0, "the same pixels miss");
            if *c != -32768.0 {
                diffs.push((c - g).abs());
            }
        }
        diffs.sort_by(f32::total_cmp);
        let (p99, max) = (diffs[diffs.len() * 99 / 100], diffs[diffs.len() - 1]);
        assert!(
            p99 <= 2.0 && max <= 16.0,
            "GPU off by {p99} HU (p99), {max} (max)"
        );
    }
    let o = run(&[
        "render",
        &series,
        "--mode",
        "mip",
        "--slices",
        "3",
        "-o",
        tmp("refused-series").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--slices steps the plane"),
        "{}",
        stderr(&o)
    );
}

/// An enhanced CT written by pydicom (an independent writer): three frames stored out of order
/// with their own intercepts, as `scripts/fuzz-inputs.py` seeds it, reads as the volume its
/// functional groups describe. Skipped without pydicom, except under CI.
#[test]
fn an_enhanced_ct_written_by_pydicom_reads_as_described() {
    let Some(py) = python_with("pydicom") else {
        return;
    };
    let out = tmp("pydicom-enhanced.dcm");
    let script = "import sys, importlib.util as u\n\
        s = u.spec_from_file_location('f', sys.argv[1]); m = u.module_from_spec(s)\n\
        s.loader.exec_module(m); open(sys.argv[2], 'wb').write(m.enhanced_ct())";
    let o = std::process::Command::new(&py)
        .args(["-c", script])
        .arg(repo().join("scripts/fuzz-inputs.py"))
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v = info(out.to_str().unwrap());
    assert_eq!(v["dims"], serde_json::json!([8, 6, 3]));
    close(
        &v["spacing"],
        &serde_json::json!([0.8, 0.7, 2.0]),
        1e-9,
        "spacing",
    );
    close(
        &v["origin"],
        &serde_json::json!([-10.0, 20.0, 30.0]),
        1e-9,
        "origin",
    );
    // Sample n of the file holds (n·37) mod 3000; its frames, in file order, lie at z = 34,
    // 30, 32 (k = 2, 0, 1) with intercepts −1024 − k.
    assert_eq!(v["hu_range"], serde_json::json!([-1026.0, 1973.0]));
    let vol = raystream_io::load_volume(&out, &Default::default()).unwrap();
    for (f, k) in [(0, 2), (1, 0), (2, 1)] {
        for (i, j) in [(0, 0), (5, 0), (7, 5)] {
            let stored = ((f * 48 + j * 8 + i) * 37 % 3000) as i32;
            let want = (stored - 1024 - k as i32) as f32;
            assert_eq!(vol.at(i, j, k), want, "({i}, {j}) at z = {}", 30 + 2 * k);
        }
    }
}

/// `render SERIES --mode slice --size 48x40 --device DEV ARGS --format dcm` into a fresh folder
/// (named by `name`), read back as a volume.
fn reformat_series(series: &str, dev: &str, name: &str, args: &[&str]) -> raystream_io::Volume {
    let dir = tmp(&format!("reformat-series-{name}"));
    std::fs::remove_dir_all(&dir).ok();
    let mut all = vec![
        "render", series, "--mode", "slice", "--size", "48x40", "--device", dev, "--format", "dcm",
        "--quiet", "-o",
    ];
    all.push(dir.to_str().unwrap());
    all.extend_from_slice(args);
    let o = run(&all);
    assert!(o.status.success(), "{name}: {}", stderr(&o));
    raystream_io::load_volume(&dir, &Default::default()).unwrap()
}

/// A 4-D NIfTI written by SimpleITK (the abdomen CT, then +100 and +200 HU along its fourth
/// axis): `info` says which phase it read of how many and warns when it chose; `--phase K`
/// reads the K-th in `info`, `render` (a projection's HU in its EXR) and `iso`; a phase the file
/// lacks is an error naming it and how many there are.
#[test]
fn phase_picks_the_temporal_position_of_a_4d_ct() {
    let Some(py) = python_with_simpleitk() else {
        return;
    };
    let file = tmp("phases-4d.nii.gz");
    let script = "import sys, SimpleITK as sitk\n\
        im = sitk.Cast(sitk.ReadImage(sys.argv[1]), sitk.sitkInt16)\n\
        four = sitk.JoinSeries([im, im + 100, im + 200])\n\
        for out in sys.argv[2:]: sitk.WriteImage(four, out)";
    let o = std::process::Command::new(&py)
        .args(["-c", script])
        .arg(volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz"))
        .args([&file, &tmp("phases-4d.nrrd"), &tmp("phases-4d.mha")])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let path = file.to_str().unwrap();
    let src = info(&volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz"));
    let lo = src["hu_range"][0].as_f64().unwrap();
    let hi = src["hu_range"][1].as_f64().unwrap();
    let first = info(path);
    assert_eq!(first["phase"], serde_json::json!({"index": 1, "count": 3}));
    assert_eq!(first["dims"], src["dims"]);
    close(&first["spacing"], &src["spacing"], 1e-6, "spacing");
    close(&first["origin"], &src["origin"], 1e-3, "origin");
    assert_eq!(first["hu_range"], serde_json::json!([lo, hi]));
    assert!(
        first["warnings"]
            .to_string()
            .contains("3 temporal positions"),
        "{}",
        first["warnings"]
    );
    let o = run(&["info", "--json", "--phase", "3", path]);
    assert!(o.status.success(), "{}", stderr(&o));
    let third: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(third["phase"], serde_json::json!({"index": 3, "count": 3}));
    assert_eq!(
        third["hu_range"],
        serde_json::json!([lo + 200.0, hi + 200.0])
    );
    assert_eq!(third["warnings"], serde_json::json!([]));
    // The same series as ITK writes 4-D NRRD (time the fourth axis of a 4-D space) and
    // MetaImage: each phase with the NIfTI's geometry and values.
    for other in ["phases-4d.nrrd", "phases-4d.mha"] {
        let o = run(&[
            "info",
            "--json",
            "--phase",
            "3",
            tmp(other).to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{other}: {}", stderr(&o));
        let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(v["phase"], third["phase"], "{other}");
        assert_eq!(v["dims"], third["dims"], "{other}");
        close(&v["spacing"], &third["spacing"], 1e-6, other);
        close(&v["origin"], &third["origin"], 1e-3, other);
        close(&v["direction"], &third["direction"], 1e-6, other);
        assert_eq!(v["hu_range"], third["hu_range"], "{other}");
    }

    // A parallel MIP of phase 2 is phase 1's plus 100 HU wherever a ray met the volume.
    let render_mip = |input: &str, out: &std::path::Path, more: &[&str]| {
        let to = out.to_str().unwrap();
        let args = [
            "render",
            input,
            "--mode",
            "mip",
            "--parallel",
            "--size",
            "48x40",
            "-o",
            to,
        ];
        run(&[&args[..], more].concat())
    };
    let mip_of = |input: &str, phase: &str| {
        let out = tmp(&format!("phases-mip-{phase}.exr"));
        let o = render_mip(input, &out, &["--quiet", "--phase", phase]);
        assert!(o.status.success(), "{}", stderr(&o));
        let e = raystream_cpu::load_exr(&out).unwrap();
        e.channels["Y"].as_f32().unwrap().to_vec()
    };
    let mip = |phase: &str| mip_of(path, phase);
    let (one, two) = (mip("1"), mip("2"));
    // The NRRD's and the MetaImage's phase 2 is the NIfTI's, bit for bit.
    for other in ["phases-4d.nrrd", "phases-4d.mha"] {
        let got = mip_of(tmp(other).to_str().unwrap(), "2");
        assert!(
            got.iter()
                .zip(&two)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{other}"
        );
    }
    let hit = one.iter().filter(|v| !v.is_nan()).count();
    assert!(
        hit > one.len() / 2,
        "{hit} of {} pixels meet the CT",
        one.len()
    );
    for (a, b) in one.iter().zip(&two) {
        assert!(
            (a.is_nan() && b.is_nan()) || (b - a - 100.0).abs() < 1e-2,
            "phase 1 {a}, phase 2 {b}"
        );
    }

    for cmd in [
        vec!["info", "--phase", "4", path],
        vec!["render", "--quiet", "--phase", "4", path, "-o", "x.png"],
        vec!["iso", "--quiet", "--phase", "4", path, "-o", "x.ply"],
    ] {
        let o = run(&cmd);
        let e = stderr(&o);
        assert!(
            !o.status.success()
                && e.contains("phases-4d.nii.gz")
                && e.contains("phase 4 requested, but the image has 3 temporal positions"),
            "{cmd:?}: {e}"
        );
    }
    let o = run(&["info", "--phase", "0", path]);
    assert!(!o.status.success(), "phase 0 is refused");

    // --cine: a frame per phase, in order, each the very picture --phase K renders.
    let cine = tmp("phases-cine");
    let _ = std::fs::remove_dir_all(&cine);
    let o = render_mip(path, &cine, &["--cine", "--format", "exr"]);
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    assert!(
        e.contains("wrote 3 frames") && !e.contains("temporal positions"),
        "{e}"
    );
    for (k, want) in [one, two, mip("3")].iter().enumerate() {
        let f = raystream_cpu::load_exr(&cine.join(format!("frame_00{k}.exr"))).unwrap();
        let got = f.channels["Y"].as_f32().unwrap();
        assert!(
            got.iter()
                .zip(want)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "cine frame {k} is not phase {}'s picture",
            k + 1
        );
    }
    assert!(!cine.join("frame_003.exr").exists());
    // --cine --path: a CPR of each phase along the one path, each the very picture --phase K
    // with that path renders, and phase K's HU are phase 1's + 100 (K − 1) wherever sampled.
    let centre = {
        let [d, sp, o] = ["dims", "spacing", "origin"].map(|k| {
            first[k]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect::<Vec<f64>>()
        });
        let m: Vec<f64> = first["direction"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let half: Vec<f64> = (0..3).map(|a| 0.5 * (d[a] - 1.0) * sp[a]).collect();
        (0..3)
            .map(|r| o[r] + (0..3).map(|c| m[3 * r + c] * half[c]).sum::<f64>())
            .collect::<Vec<f64>>()
    };
    let curve = tmp("phases-path.txt");
    std::fs::write(
        &curve,
        format!(
            "{x} {y} {}\n{x} {} {}\n{x} {y} {}\n",
            centre[2] - 60.0,
            centre[1] + 10.0,
            centre[2],
            centre[2] + 60.0,
            x = centre[0],
            y = centre[1]
        ),
    )
    .unwrap();
    let curve = curve.to_str().unwrap();
    let cpr_cine = tmp("phases-cpr-cine");
    let _ = std::fs::remove_dir_all(&cpr_cine);
    let cpr = [
        "--mode", "slice", "--path", curve, "--size", "24x48", "--format", "exr",
    ];
    let o = run(&[
        &[
            "render",
            "-q",
            path,
            "--cine",
            "-o",
            cpr_cine.to_str().unwrap(),
        ][..],
        &cpr,
    ]
    .concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let frame = |k: usize| {
        let f = raystream_cpu::load_exr(&cpr_cine.join(format!("frame_00{k}.exr"))).unwrap();
        f.channels["Y"].as_f32().unwrap().to_vec()
    };
    let base = frame(0);
    assert!(base.iter().filter(|v| v.is_finite()).count() > base.len() / 2);
    for k in 0..3 {
        let single = tmp(&format!("phases-cpr-{k}.exr"));
        let phase = format!("{}", k + 1);
        let o = run(&[
            &[
                "render",
                "-q",
                path,
                "--phase",
                &phase,
                "-o",
                single.to_str().unwrap(),
            ][..],
            &cpr[..6],
        ]
        .concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let want = raystream_cpu::load_exr(&single).unwrap();
        let want = want.channels["Y"].as_f32().unwrap();
        let got = frame(k);
        assert!(
            got.iter()
                .zip(want)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "CPR cine frame {k} is not phase {}'s CPR",
            k + 1
        );
        for (a, b) in got.iter().zip(&base) {
            if a.is_finite() {
                assert!((a - b - 100.0 * k as f32).abs() < 1e-2, "{a} against {b}");
            }
        }
    }
    let o = run(&[
        &["render", "-q", path, "--cine", "--draw-lumen", "150", "-o"][..],
        &[
            cpr_cine.to_str().unwrap(),
            "--mode",
            "slice",
            "--path",
            curve,
        ][..],
    ]
    .concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--draw-lumen with --cine"),
        "{}",
        stderr(&o)
    );
    let src_path = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    for (args, want) in [
        (
            vec![src_path.as_str(), "--mode", "mip", "--cine"],
            "abdomen_pelvis_ct_totalseg.nii.gz: --cine renders each temporal position of a 4-D CT, and this image has one",
        ),
        (
            vec![path, "--mode", "mip", "--cine", "--phase", "2"],
            "cannot be used with",
        ),
        (vec![path, "--cine"], "--mode"),
    ] {
        let out = tmp("phases-cine-bad");
        let o = run(&[&["render", "-o", out.to_str().unwrap()], &args[..]].concat());
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains(want), "{args:?}: {e}");
    }

    // A scene file's volume takes `phase`, too.
    for (phase, ok) in [(3, true), (9, false)] {
        let scene = tmp(&format!("phases-{phase}.toml"));
        std::fs::write(
            &scene,
            format!(
                "[volume]\npath = \"phases-4d.nii.gz\"\nphase = {phase}\n\n[[objects]]\nshape = \"sphere\"\n"
            ),
        )
        .unwrap();
        let o = run(&["info", "--json", scene.to_str().unwrap()]);
        if ok {
            assert!(o.status.success(), "{}", stderr(&o));
            let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
            assert_eq!(
                v["volume"]["phase"],
                serde_json::json!({"index": 3, "count": 3})
            );
        } else {
            assert!(
                !o.status.success() && stderr(&o).contains("phase 9 requested"),
                "{}",
                stderr(&o)
            );
        }
    }
}

/// `iso -o BONES.glb`: the surface `-o BONES.ply` writes, under a node that turns LPS
/// millimetres into glTF's metres (+X left, +Y superior, +Z anterior). Read back here, its
/// triangles are the PLY's and each vertex the PLY's (x, z, −y) / 1000 with its normal turned
/// alike; trimesh (an independent reader) places the same vertices.
#[test]
fn iso_writes_glb_in_gltfs_metres_and_axes() {
    let vol = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    let out = |name: &str| {
        let p = tmp(name);
        let o = run(&[
            "iso",
            &vol,
            "--hu",
            "300",
            "-o",
            p.to_str().unwrap(),
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        p
    };
    let (ply, glb) = (out("bones-glb.ply"), out("bones.glb"));
    let (lps, lps_shading) = raystream_io::load_mesh_with_shading(&ply).unwrap();
    let (gl, gl_shading) = raystream_io::load_mesh_with_shading(&glb).unwrap();
    assert_eq!(gl.triangles, lps.triangles);
    let turn = |p: raystream_math::Vec3| raystream_math::Vec3::new(p.x, p.z, -p.y);
    for (a, b) in gl.positions.iter().zip(&lps.positions) {
        let want = turn(*b) / 1000.0;
        assert!(
            (*a - want).length() <= 1e-6 * want.length().max(1e-3),
            "{a} for {want}"
        );
    }
    assert_eq!(gl_shading.materials[0].name, "bone");
    for (a, b) in gl_shading.normals.iter().zip(&lps_shading.normals) {
        assert!((*a - turn(*b)).length() < 1e-5, "{a} for {b}");
    }
    let Some(py) = python() else { return };
    let o = std::process::Command::new(&py)
        .args([
            "-c",
            "import sys, trimesh, numpy as np\n\
             g = trimesh.load(sys.argv[1]).to_geometry()\n\
             sys.stdout.write(f'{len(g.faces)} {np.asarray(g.vertices).min(0).tolist()} {np.asarray(g.vertices).max(0).tolist()}')",
            glb.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let b = gl.bounds();
    let nums: Vec<f64> = stdout(&o)
        .replace(['[', ']', ','], " ")
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(nums[0] as usize, gl.triangles.len());
    for (got, want) in nums[1..]
        .iter()
        .zip(b.min.to_array().iter().chain(&b.max.to_array()))
    {
        assert!((got - *want as f64).abs() < 1e-6, "{got} for {want}");
    }
}

/// A lone slice (one DICOM image) is drawn as the slab of tissue it images, seen along its
/// axis unless `--view` says. Before, every mode but a slice seen from below drew an empty
/// picture of a plane no ray sampled, and said nothing. Every mode now draws it, the GPU as
/// the CPU; a MIP across the slab in parallel projection is the slice itself, HU for HU; the
/// default view is `--view inferior`'s (an axial image as it is read); and a label map of the
/// slice lies on the slab voxel for voxel.
#[test]
fn a_lone_slice_is_drawn_as_the_slab_it_images() {
    let one =
        volume("dicom/ct_slice_transfer_syntaxes/ct_1.2.840.10008.1.2.1_LittleEndianExplicit.dcm");
    let ct = raystream_io::load_volume(Path::new(&one), &Default::default()).unwrap();
    assert_eq!(ct.dims, [512, 512, 1]);
    let png = |p: &Path| image::open(p).unwrap().to_rgb8();
    for mode in [
        "dvr",
        "mip",
        "minip",
        "average",
        "iso",
        "slice",
        "cinematic",
    ] {
        let mut pictures = Vec::new();
        for dev in devices() {
            let args = [one.as_str(), "--mode", mode, "--size", "64x64"];
            let out = render_to(&format!("lone-{mode}-{dev}.png"), dev, &args);
            pictures.push(png(&out));
        }
        // Not a uniform background: the slice's tissue shows in many shades.
        let shades: std::collections::BTreeSet<[u8; 3]> =
            pictures[0].pixels().map(|p| p.0).collect();
        assert!(shades.len() > 20, "{mode}: {} shades", shades.len());
        if let [cpu, gpu] = &pictures[..] {
            let (mean, _) = raystream_cpu::srgb8_diff(cpu.as_raw(), gpu.as_raw());
            assert!(
                mean < 0.5,
                "{mode}: the GPU's picture is {mean}/255 off the CPU's"
            );
        }
    }

    // Across the slab, every sample of a ray in parallel projection holds the slice's value
    // where the ray crosses it: the MIP is the slice.
    let exr = |name: &str, mode: &str| {
        let args = [
            one.as_str(),
            "--mode",
            mode,
            "--parallel",
            "--size",
            "96x96",
        ];
        let e = raystream_cpu::load_exr(&render_to(name, "cpu", &args)).unwrap();
        e.channels["Y"].as_f32().unwrap().to_vec()
    };
    let (mip, slice) = (exr("lone-mip.exr", "mip"), exr("lone-slice.exr", "slice"));
    let inside = slice.iter().filter(|v| v.is_finite()).count();
    assert!(inside > 96 * 96 / 2, "{inside} pixels see the slice");
    for (i, (m, s)) in mip.iter().zip(&slice).enumerate() {
        assert!(
            m.is_nan() == s.is_nan() && (m.is_nan() || (m - s).abs() <= 1e-3 * s.abs().max(1.0)),
            "pixel {i}: MIP {m} HU, slice {s} HU"
        );
    }

    // Seen as --view inferior sees it, the bone surface too.
    for (name, more) in [("slice", &["--mode", "slice"][..]), ("bones", &[][..])] {
        let pair = ["default", "inferior"].map(|view| {
            let mut args = vec![one.as_str(), "--size", "64x64"];
            args.extend_from_slice(more);
            if view == "inferior" {
                args.extend_from_slice(&["--view", "inferior"]);
            }
            png(&render_to(&format!("lone-{name}-{view}.png"), "cpu", &args))
        });
        assert_eq!(
            pair[0], pair[1],
            "{name}: the default view is not --view inferior's"
        );
    }

    // A label map of the slice (its bone) colours the slab's two layers, matched voxel for voxel.
    let bone: Vec<u8> = ct.data.iter().map(|&v| (v >= 300.0) as u8).collect();
    let voxels = bone.iter().filter(|&&b| b == 1).count();
    let labels = tmp("lone-bone.nii.gz");
    raystream_io::write_label_map(&labels, &ct, &bone, "bone").unwrap();
    let args = [
        "render",
        one.as_str(),
        "--mode",
        "dvr",
        "--segmentation",
        labels.to_str().unwrap(),
        "--size",
        "64x64",
        "--device",
        "cpu",
        "-o",
    ];
    let out = tmp("lone-segmented.png");
    let o = run(&[&args[..], &[out.to_str().unwrap()]].concat());
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    let want = format!("({} voxels, matched on the CT's grid)", 2 * voxels);
    assert!(e.contains(&want), "{want} not in: {e}");

    // An RT Structure Set traced from that label map by rt-utils: its contours lie in the
    // slice's plane, midway between the slab's layers, and colour both, as the label map does
    // (the same picture), with no contour said to lie between slices. Named from the folder
    // above it or from its own (relative paths), it still finds its CT beside it.
    let Some(py) = python_with("rt_utils") else {
        return;
    };
    let root = tmp("lone-rt");
    std::fs::remove_dir_all(&root).ok();
    std::fs::create_dir_all(root.join("ct")).unwrap();
    std::fs::create_dir_all(root.join("rt")).unwrap();
    std::fs::copy(&one, root.join("ct/slice.dcm")).unwrap();
    let rt = root.join("rt/structures.dcm");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/rtutils_struct.py"))
        .args([root.join("ct"), labels.clone(), rt.clone()])
        // Label 1's colour where a label map names none (overlay::EDGE's cyan).
        .arg("Bone=1:0,230,255")
        .output()
        .unwrap();
    assert!(o.status.success(), "rt-utils: {}", stderr(&o));
    let traced = tmp("lone-segmented-rt.png");
    let rt_args = [&args[..5], &[rt.to_str().unwrap()], &args[6..]].concat();
    let o = run(&[&rt_args[..], &[traced.to_str().unwrap()]].concat());
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    let want = format!(
        "({} voxels, matched on structures laid on the CT's grid)",
        2 * voxels
    );
    assert!(
        e.contains(&want) && !e.contains("between slices"),
        "{want} not in: {e}"
    );
    assert!(
        png(&traced) == png(&out),
        "the structure set's picture is not the label map's"
    );
    for (dir, file) in [
        (&root, "rt/structures.dcm"),
        (&root.join("rt"), "structures.dcm"),
    ] {
        let o = bin()
            .current_dir(dir)
            .args(["info", "--json", file])
            .output()
            .unwrap();
        assert!(o.status.success(), "{file}: {}", stderr(&o));
        let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(v["labels"][0]["voxels"], voxels, "{file}");
    }
}

/// A volume whose values have no known unit (the 8-bit SciVis bonsai) takes its defaults from
/// its values. Before, `render` refused it (bone's 300 lies above its every value), dvr drew
/// CT-Bone's uniform box and the CT windows a grey one. Now the bone surface and iso mode
/// stand at its Otsu threshold; dvr's ramp leaves every ray that meets only values below it
/// transparent, as a MIP of the same rays tells; the windows span its range; the GPU draws
/// the CPU's pictures; and what the user gives (`--iso`, `--window`) still rules.
#[test]
fn values_of_no_known_unit_take_their_defaults_from_the_values() {
    let bonsai = volume("nifti/scivis_bonsai.nii.gz");
    let v = raystream_io::load_volume(Path::new(&bonsai), &Default::default()).unwrap();
    assert_eq!(v.unit, raystream_io::ValueUnit::Unknown);
    let t = raystream_volume::auto::otsu_threshold(&v.data).unwrap();
    let said = |args: &[&str], name: &str| {
        let out = tmp(name);
        let mut all = vec![
            "render",
            bonsai.as_str(),
            "--size",
            "48x48",
            "--device",
            "cpu",
        ];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", out.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{all:?}: {}", stderr(&o));
        stderr(&o)
    };
    let otsu = format!("the surface at {t}, their Otsu threshold");
    // `info` says where that surface stands; of a CT and of a label map it says nothing
    // (bone's threshold and the segments' surfaces rule there).
    assert_eq!(info(&bonsai)["default_surface"].as_f64(), Some(t as f64));
    let ct = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    assert!(info(&ct)["default_surface"].is_null());
    let labels = tmp("unit-free-labels.nrrd");
    let mut nrrd = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n\n".to_vec();
    nrrd.extend((0..512).map(|i| [0u8, 3, 5][(i % 8 / 3) as usize]));
    std::fs::write(&labels, nrrd).unwrap();
    let labels = labels.to_str().unwrap();
    assert!(info(labels)["default_surface"].is_null());
    let o = run(&["info", &bonsai]);
    let line = format!("surface    at {t}, the values' Otsu threshold");
    assert!(stdout(&o).contains(&line), "{}", stdout(&o));
    for (args, name) in [
        (&[][..], "unit-free-bones.png"),
        (&["--mode", "iso"][..], "unit-free-iso.png"),
    ] {
        let e = said(args, name);
        assert!(e.contains(&otsu), "{args:?}: {e}");
    }
    let e = said(&["--iso", "120"], "unit-free-120.png");
    assert!(
        !e.contains("Otsu") && e.contains("the threshold 120 applies to the raw values"),
        "{e}"
    );

    // dvr: a pixel whose ray meets only values below the threshold (its MIP) shows the
    // background, as the picture's corner, whose ray misses the volume, does.
    let args = [bonsai.as_str(), "--mode", "dvr", "--size", "64x64"];
    let mut pictures = Vec::new();
    for dev in devices() {
        let out = render_to(&format!("unit-free-dvr-{dev}.png"), dev, &args);
        pictures.push(image::open(out).unwrap().to_rgb8());
    }
    if let [cpu, gpu] = &pictures[..] {
        let (mean, _) = raystream_cpu::srgb8_diff(cpu.as_raw(), gpu.as_raw());
        assert!(mean < 0.5, "the GPU's picture is {mean}/255 off the CPU's");
    }
    let mip_args = [bonsai.as_str(), "--mode", "mip", "--size", "64x64"];
    let mip = raystream_cpu::load_exr(&render_to("unit-free-mip.exr", "cpu", &mip_args)).unwrap();
    let mip = mip.channels["Y"].as_f32().unwrap();
    assert!(mip[0].is_nan(), "the corner's ray meets the volume");
    let dvr = &pictures[0];
    let background = dvr.get_pixel(0, 0).0;
    let (mut clear, mut shown) = (0, 0);
    for (i, m) in mip.iter().enumerate() {
        let p = dvr.get_pixel(i as u32 % 64, i as u32 / 64).0;
        if m.is_nan() || *m < t {
            assert_eq!(
                p, background,
                "pixel {i}: MIP {m} below {t}, yet not the background"
            );
            clear += 1;
        } else if *m > 200.0 && p != background {
            shown += 1;
        }
    }
    assert!(
        clear > 64 * 64 / 4 && shown > 100,
        "{clear} clear, {shown} shown"
    );

    // The MIP's window spans its values: the largest is white; --window still rules.
    let brightest = |args: &[&str], name: &str| {
        let mut all = vec![bonsai.as_str(), "--size", "64x64"];
        all.extend_from_slice(args);
        let png = image::open(render_to(name, "cpu", &all))
            .unwrap()
            .to_luma8();
        png.pixels().map(|p| p.0[0]).max().unwrap()
    };
    assert_eq!(brightest(&["--mode", "mip"], "unit-free-mip.png"), 255);
    let narrow = ["--mode", "mip", "--window", "1000", "--level", "1000"];
    assert!(brightest(&narrow, "unit-free-mip-window.png") < 100);
}

/// A few outlying voxels of a volume of no known unit (a hot voxel of an MR, a metal clip in a
/// CT stored without its rescale) do not set its defaults: 100 voxels of 10,000 in the 8-bit
/// bonsai (one in 20,000 of its voxels) made its dvr ramp reach 10,000, so that the bonsai
/// itself was all but transparent, and its slice window 0 .. 10,000, so that it was black.
/// Now the pictures are the bonsai's own, and stderr gives the same ramp and window.
#[test]
fn a_few_outlying_voxels_do_not_set_the_defaults() {
    let v = raystream_io::load_volume(
        Path::new(&volume("nifti/scivis_bonsai.nii.gz")),
        &Default::default(),
    )
    .unwrap();
    let half = v.resample([128; 3]);
    let mut spiked = half.data.clone();
    // A block of 5 × 5 × 4 voxels in a corner of the box.
    for k in 0..4 {
        for j in 0..5 {
            for i in 0..5 {
                spiked[i + 128 * (j + 128 * k)] = 1e4;
            }
        }
    }
    let nrrd = |name: &str, data: &[f32]| {
        let path = tmp(name);
        let mut bytes = b"NRRD0004\ntype: float\ndimension: 3\nsizes: 128 128 128\nencoding: raw\nendian: little\n\n".to_vec();
        bytes.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        std::fs::write(&path, bytes).unwrap();
        path.to_str().unwrap().to_string()
    };
    let (clean, spiked) = (
        nrrd("outliers-clean.nrrd", &half.data),
        nrrd("outliers-spiked.nrrd", &spiked),
    );
    for mode in ["dvr", "slice"] {
        let mut seen = Vec::new();
        for (input, name) in [(&clean, "clean"), (&spiked, "spiked")] {
            let out = tmp(&format!("outliers-{mode}-{name}.png"));
            let o = run(&[
                "render",
                input,
                "--mode",
                mode,
                "--size",
                "64x64",
                "--device",
                "cpu",
                "-o",
                out.to_str().unwrap(),
            ]);
            let e = stderr(&o);
            assert!(o.status.success(), "{e}");
            // What was chosen, less the values' range (which the outliers do reach).
            let said = e
                .lines()
                .find(|l| l.contains("values of no known unit"))
                .and_then(|l| l.split_once("): "))
                .map(|(_, what)| what.to_string())
                .unwrap_or_else(|| panic!("{e}"));
            seen.push((said, image::open(out).unwrap().to_rgb8()));
        }
        let [(clean_said, a), (spiked_said, b)] = &seen[..] else {
            unreachable!()
        };
        // The same words, and numbers (the threshold, the ramp's top, the window's ends)
        // within 2 %: the outliers shift the ranks a little, no more.
        let numbers = |s: &str| -> (String, Vec<f32>) {
            let mut words = String::new();
            let mut found = Vec::new();
            for w in s.split([' ', ',', '(', ')']) {
                match w.parse::<f32>() {
                    Ok(x) => found.push(x),
                    _ => words += w,
                }
            }
            (words, found)
        };
        let ((wa, na), (wb, nb)) = (numbers(clean_said), numbers(spiked_said));
        assert_eq!(wa, wb, "{clean_said} / {spiked_said}");
        assert!(
            na.len() >= 2
                && na.len() == nb.len()
                && na
                    .iter()
                    .zip(&nb)
                    .all(|(x, y)| (x - y).abs() <= 0.02 * x.abs().max(1.0)),
            "{clean_said} / {spiked_said}"
        );
        let (mean, _) = raystream_cpu::srgb8_diff(a.as_raw(), b.as_raw());
        assert!(
            mean < 0.5,
            "{mode}: the outliers moved the picture {mean}/255"
        );
    }
}

/// A projection of values of no known unit is windowed on the values it projects, less 0.5 %
/// at each end (an image viewer's auto-contrast), not on the voxels' range: the bonsai's
/// average and minimum reach less than half its 0 .. 255, and a window over 0 .. 255 drew
/// them near black. At 64×64 the probe frame the window comes from is the frame itself, so
/// each byte is the window of its EXR value; the GPU's picture is the CPU's.
#[test]
fn a_projection_of_no_known_unit_is_windowed_on_what_it_projects() {
    let bonsai = volume("nifti/scivis_bonsai.nii.gz");
    for mode in ["average", "minip"] {
        let args = [bonsai.as_str(), "--mode", mode, "--size", "64x64"];
        let name = format!("unit-free-{mode}");
        let exr =
            raystream_cpu::load_exr(&render_to(&format!("{name}.exr"), "cpu", &args)).unwrap();
        let values = exr.channels["Y"].as_f32().unwrap().to_vec();
        let tail = raystream_volume::auto::CLIPPED_TAIL;
        let (lo, hi) = raystream_volume::auto::clipped_range(&values, tail).unwrap();
        assert!(lo < hi && hi < 128.0, "{mode}: {lo} .. {hi}");
        let mut pictures = Vec::new();
        for dev in devices() {
            let out = tmp(&format!("{name}-{dev}.png"));
            let all = ["render", "--device", dev, "-o", out.to_str().unwrap()];
            let o = run(&[&all[..], &args[..]].concat());
            let e = stderr(&o);
            assert!(o.status.success(), "{e}");
            let said = format!("the window spans the {mode}'s values less 0.5 % at each end");
            assert!(e.contains(&said), "{e}");
            pictures.push(image::open(out).unwrap().to_luma8());
        }
        let cpu = &pictures[0];
        let (mut black, mut white) = (0, 0);
        for (i, v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
            let byte = cpu.as_raw()[i];
            let want = 255.0 * ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
            assert!(
                (byte as f32 - want).abs() <= 1.0,
                "{mode}: pixel {i}, value {v}: {byte}, not {want} in the window {lo} .. {hi}"
            );
            black += (byte == 0) as usize;
            white += (byte == 255) as usize;
        }
        // Both ends of the grey scale are reached, white by the top 0.5 % (of 4096 pixels, at
        // least the values ranked above the 99.5th percentile).
        assert!(
            black > 0 && white >= 10,
            "{mode}: {black} black, {white} white"
        );
        if let [_, gpu] = &pictures[..] {
            let near = cpu
                .as_raw()
                .iter()
                .zip(gpu.as_raw())
                .filter(|(a, b)| a.abs_diff(**b) <= 2)
                .count();
            assert!(
                near as f64 >= 0.999 * cpu.as_raw().len() as f64,
                "{mode}: {near} of the GPU's pixels within 2/255 of the CPU's"
            );
        }
    }
}

/// A raw file named by its size and type, as the Open SciVis datasets are handed out
/// (`bonsai_256x256x256_uint8.raw`), reads as the NIfTI made of the same scan: the bonsai's
/// voxels written raw under that name have the NIfTI's geometry, values and defaults, and
/// render to the same picture. A file one byte short or long, or a name without the size and
/// type, is refused with an error that names the file and says why.
#[test]
fn a_raw_file_named_by_its_size_and_type_reads_as_its_nifti() {
    let nii = volume("nifti/scivis_bonsai.nii.gz");
    let src = raystream_io::load_volume(Path::new(&nii), &Default::default()).unwrap();
    let bytes: Vec<u8> = src.data.iter().map(|&v| v as u8).collect();
    assert!(src.data.iter().zip(&bytes).all(|(&v, &b)| v == b as f32));
    let dir = tmp("named-raw");
    std::fs::create_dir_all(&dir).unwrap();
    let raw = dir.join("bonsai_256x256x256_uint8.raw");
    std::fs::write(&raw, &bytes).unwrap();
    let raw_s = raw.to_str().unwrap();

    let (a, b) = (info(&nii), info(raw_s));
    for key in [
        "dims",
        "spacing",
        "origin",
        "direction",
        "value_range",
        "unit",
    ] {
        assert_eq!(a[key], b[key], "{key}");
    }
    assert_eq!(a["default_surface"], b["default_surface"]);
    assert_eq!(b["format"], "raw");
    let warned = b["warnings"].to_string();
    assert!(warned.contains("states no spacing"), "{warned}");

    let mut pictures = Vec::new();
    for (name, input) in [("nifti", nii.as_str()), ("raw", raw_s)] {
        let out = render_to(
            &format!("named-raw-{name}.png"),
            "cpu",
            &[input, "--mode", "mip", "--size", "64x64"],
        );
        pictures.push(std::fs::read(out).unwrap());
    }
    assert!(pictures[0] == pictures[1], "the raw file's picture differs");

    let refused_as = |name: &str, len: usize, want: &str| {
        let path = dir.join(name);
        std::fs::write(&path, &bytes[..len.min(bytes.len())]).unwrap();
        if len > bytes.len() {
            let mut f = std::fs::OpenOptions::new()
                .append(true)
                .open(&path)
                .unwrap();
            std::io::Write::write_all(&mut f, &vec![0; len - bytes.len()]).unwrap();
        }
        let e = refused(&["info", path.to_str().unwrap()], want);
        assert!(e.contains(name), "{e}");
    };
    let n = bytes.len();
    refused_as("short_256x256x256_uint8.raw", n - 1, "is truncated");
    refused_as(
        "long_256x256x256_uint8.raw",
        n + 1,
        "its name gives the wrong size or type",
    );
    refused_as("bonsai.raw", n, "NAME_WxHxD_TYPE.raw");
    refused_as("bonsai_256x256x256_uint12.raw", n, "is not a voxel type");
    // A name claiming 10⁶ slices is refused by the file's length, before anything is read.
    refused_as("huge_1000x1000x1000000_uint8.raw", n, "voxel limit");
}

/// Legacy VTK against VTK itself (the vtk wheel): `iso -o bones.vtk` writes 3D Slicer's
/// model format (polygonal data, tagged `SPACE=LPS` as Slicer tags its own), in which VTK's
/// reader finds the PLY's surface (its points, triangles and normals); the PLY written by VTK
/// in file versions 4.2 and 5.1, ASCII and binary, titled as Slicer titles a RAS model, reads
/// as the PLY (`info` says RAS), and VTK's image data, ASCII and binary, as its voxels; `info`
/// and `render` take a `.vtk` of polygons as a mesh, of image data as a volume.
#[test]
fn legacy_vtk_files_agree_with_vtk() {
    let Some(py) = python_with("vtkmodules") else {
        return;
    };
    let ct = volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz");
    let (ply, vtk) = (tmp("bones-model.ply"), tmp("bones-model.vtk"));
    for out in [&ply, &vtk] {
        let o = run(&["iso", &ct, "--quiet", "-o", out.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let (a, b) = (
        raystream_io::load_mesh(&ply).unwrap(),
        raystream_io::load_mesh(&vtk).unwrap(),
    );
    assert!(a.positions == b.positions && a.triangles == b.triangles);
    let dir = tmp("vtk-legacy");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/vtk_legacy.py"))
        .args([&vtk, &ply, &dir])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();

    // VTK reads raystream's model.
    let read = &v["read"];
    assert_eq!(read["points"], a.positions.len());
    assert_eq!(read["polygons"], a.len());
    assert_eq!(read["normals"], a.positions.len());
    let index_sum: u64 = a.triangles.iter().flatten().map(|&i| i as u64).sum();
    assert_eq!(read["index_sum"], index_sum);
    let coordinates = || a.positions.iter().flat_map(|p| p.to_array());
    let point_sum: f64 = coordinates().map(f64::from).sum();
    let theirs = read["point_sum"].as_f64().unwrap();
    assert!(
        (theirs - point_sum).abs() <= 1e-9 * point_sum.abs(),
        "{theirs} vs {point_sum}"
    );
    assert!(read["title"].as_str().unwrap().ends_with("SPACE=LPS"));
    let i = info(vtk.to_str().unwrap());
    assert_eq!(
        (i["kind"].as_str(), i["space"].as_str()),
        (Some("mesh"), Some("LPS"))
    );
    render_to(
        "bones-model.png",
        "cpu",
        &[vtk.to_str().unwrap(), "--size", "32x24"],
    );

    // raystream reads VTK's polygonal data of every version and encoding.
    let written = v["written"].as_array().unwrap();
    assert_eq!(written.len(), 4);
    for name in written {
        let file = dir.join(name.as_str().unwrap());
        let (m, shading) = raystream_io::load_mesh_with_shading(&file).unwrap();
        assert_eq!(m.triangles, a.triangles, "{file:?}");
        // Text is written to VTK's precision (6 significant digits: 5·10⁻⁶ relative, and f32's
        // rounding), binary exactly.
        let worst = m
            .positions
            .iter()
            .zip(&a.positions)
            .map(|(p, q)| ((*p - *q).abs() / q.abs().max(raystream_io::Vec3::ONE)).max_element())
            .fold(0.0f32, f32::max);
        let exact = file.to_string_lossy().contains("binary");
        assert!(
            if exact { worst == 0.0 } else { worst < 5.2e-6 },
            "{file:?}: {worst}"
        );
        assert_eq!(
            shading.space,
            Some(raystream_io::PatientSpace::Ras),
            "{file:?}"
        );
        assert_eq!(info(file.to_str().unwrap())["space"], "RAS");
    }

    // …and VTK's image data.
    let values: Vec<f32> = v["image_values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect();
    for name in v["images"].as_array().unwrap() {
        let file = dir.join(name.as_str().unwrap());
        let vol = raystream_io::load_volume(&file, &Default::default()).unwrap();
        assert_eq!(vol.dims, [5, 4, 3], "{file:?}");
        assert_eq!(vol.spacing, [0.5, 0.25, 2.0], "{file:?}");
        assert_eq!(vol.origin, [-10.0, 20.0, 30.5], "{file:?}");
        assert!(vol.data == values, "{file:?}: the voxels differ");
        assert_eq!(info(file.to_str().unwrap())["kind"], "volume");
    }
}

/// A segment's voxels (i, j, k) in `labels` (`number`'s), or whole where the file overlaps.
fn segment_voxels(
    labels: &raystream_io::Volume,
    whole: Option<&raystream_io::WholeSegments>,
    number: u16,
) -> Vec<[usize; 3]> {
    let [nx, ny, _] = labels.dims;
    match whole {
        Some(w) => {
            let (_, s) = w.iter().find(|(l, _)| *l == number).unwrap();
            let [dx, dy, _] = s.dims;
            (0..s.inside.len())
                .filter(|&n| s.inside[n])
                .map(|n| [n % dx, (n / dx) % dy, n / (dx * dy)])
                .map(|ijk| std::array::from_fn(|a| ijk[a] + s.lo[a]))
                .collect()
        }
        None => (0..labels.data.len())
            .filter(|&n| labels.data[n] == number as f32)
            .map(|n| [n % nx, (n / nx) % ny, n / (nx * ny)])
            .collect(),
    }
}

/// 3D Slicer segmentations (`.seg.nrrd`) read as slicerio, Slicer's own Python reader and
/// writer, reads them: two files Slicer wrote (a chest CT's segments on one layer; the same
/// with a sphere overlapping them on a second), an oblique one slicerio wrote (overlapping
/// segments on two layers, each layer's label values from 1), and one of Slicer before 4.11
/// (a layer for each segment, no label values).
/// - The grid lies where slicerio's voxel-to-LPS matrix puts it; each segment has its name
///   and colour, the voxels slicerio's mask holds (whole where segments overlap), and their
///   centroid. Segments numbered by their label values where those are distinct, else from 1
///   in the file's order, with a warning.
/// - The tissue's surface is the same from both of Slicer's files, though the sphere covers
///   part of it in the second's label volume; `iso` names and colours each surface as Slicer
///   does (in a GLB, the colour's linear value).
/// - The chest CT's values within each segment are numpy's, and so are the lungs'
///   densitometry (the share below -950 and -856 HU, the 15th and 2.5th percentiles), each
///   lung's and both together (`--combine`); each lung's clusters of voxels below -910 HU,
///   in 3D and within each slice, are scipy.ndimage.label's, their power law numpy.polyfit's.
/// - Each segment's mass is numpy's sum of (HU + 1000) / 1000 g/ml; `--adjust-to` takes the
///   lungs' Perc15 and mean to a predicted TLC by both lungs' volume (numpy's), keeping their
///   mass, leaves them as they are at their own volume, adjusts the lungs alone, and refuses
///   a region not there and a volume or height out of range.
/// - Each segment's Agatston score (lesions, slices, peak, score, volume) is that of a
///   scipy.ndimage.label reference over each slice.
/// - `render --segment NAME` draws that segment in its colour.
/// - A layer the file lacks, a label value 0 or not a number, or two segments with one label
///   value on one layer are refused, the file and field named.
#[test]
fn slicer_segmentations_read_as_slicerio_reads_them() {
    let Some(py) = python_with("slicerio") else {
        return;
    };
    let dir = tmp("slicer-seg");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/slicer_seg.py"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let files = v["files"].as_array().unwrap();
    assert_eq!(files.len(), 4);
    for f in files {
        let path = Path::new(f["path"].as_str().unwrap());
        let labels = raystream_io::load_volume(path, &Default::default()).unwrap();
        let whole = raystream_io::whole_segments(&labels, path).unwrap();
        let m: Vec<Vec<f64>> = serde_json::from_value(f["ijk_to_lps"].clone()).unwrap();
        let lps = |ijk: [usize; 3]| -> [f64; 3] {
            std::array::from_fn(|r| {
                labels.origin[r]
                    + (0..3)
                        .map(|c| labels.direction[r][c] * labels.spacing[c] * ijk[c] as f64)
                        .sum::<f64>()
            })
        };
        let [nx, ny, nz] = labels.dims;
        for ijk in [[0, 0, 0], [nx - 1, 0, 0], [0, ny - 1, 0], [0, 0, nz - 1]] {
            let got = lps(ijk);
            for r in 0..3 {
                let want = m[r][3] + (0..3).map(|c| m[r][c] * ijk[c] as f64).sum::<f64>();
                assert!((got[r] - want).abs() < 1e-6, "{path:?} {ijk:?}: {got:?}");
            }
        }
        let segments = f["segments"].as_array().unwrap();
        let names: Vec<&str> = segments
            .iter()
            .map(|s| s["name"].as_str().unwrap())
            .collect();
        let ours: Vec<&str> = labels.segments.iter().map(|k| k.label.as_str()).collect();
        assert_eq!(ours, names, "{path:?}");
        let shared_values = labels
            .warnings
            .iter()
            .any(|w| w.contains("share label values"));
        for (n, (k, s)) in labels.segments.iter().zip(segments).enumerate() {
            let colour: Option<[u8; 3]> = serde_json::from_value(s["colour"].clone()).unwrap();
            assert_eq!(k.colour, colour, "{path:?} {}", k.label);
            // Its terminology's category, type and modifier, and the anatomic region and its
            // modifier, as slicerio splits them.
            let t = &k.terms;
            for (ours, theirs) in [
                (&t.category, "category"),
                (&t.kind, "type"),
                (&t.modifier, "modifier"),
                (&t.region, "region"),
                (&t.region_modifier, "region_modifier"),
            ] {
                let want: Option<[String; 3]> = serde_json::from_value(s[theirs].clone()).unwrap();
                let got = ours
                    .as_ref()
                    .map(|c| [c.scheme.clone(), c.value.clone(), c.meaning.clone()]);
                assert_eq!(got, want, "{path:?} {} {theirs}", k.label);
            }
            if shared_values {
                assert_eq!(k.number as usize, n + 1, "{path:?} {}", k.label);
            }
            let voxels = segment_voxels(&labels, whole.as_ref(), k.number);
            assert_eq!(
                voxels.len() as u64,
                s["voxels"].as_u64().unwrap(),
                "{path:?} {}",
                k.label
            );
            let mut sum = [0.0; 3];
            for ijk in &voxels {
                let p = lps(*ijk);
                (0..3).for_each(|r| sum[r] += p[r] / voxels.len() as f64);
            }
            let want: [f64; 3] = serde_json::from_value(s["centroid"].clone()).unwrap();
            for r in 0..3 {
                assert!(
                    (sum[r] - want[r]).abs() < 1e-6,
                    "{path:?} {}: {sum:?}",
                    k.label
                );
            }
        }
        // Slicer's chest segments keep their label values; the files with a second layer
        // share them. Slicer coded each of its own (ribs: SNOMED CT's Rib).
        if f == &files[0] {
            assert!(labels.segments.iter().all(|k| k.terms.kind.is_some()));
            assert_eq!(
                labels.segments[0].terms.kind.as_ref().unwrap().meaning,
                "Rib"
            );
        }
        // The oblique file's ball: a mass in the right adrenal gland.
        if f == &files[2] {
            let t = &labels.segments[0].terms;
            assert_eq!(t.kind.as_ref().unwrap().meaning, "Mass");
            assert_eq!(t.region.as_ref().unwrap().value, "23451007");
            assert_eq!(t.region_modifier.as_ref().unwrap().meaning, "Right");
        }
        let layered = f != &files[0];
        assert_eq!(shared_values, layered, "{path:?}: {:?}", labels.warnings);
        assert_eq!(whole.is_some(), layered, "{path:?}");
    }

    // `info` says what each segment is coded as, in its text and its JSON.
    let first = files[0]["path"].as_str().unwrap();
    let j = info(first);
    assert_eq!(
        j["segments"][0]["type"],
        serde_json::json!({"value": "113197003", "scheme": "SCT", "meaning": "Rib"})
    );
    assert_eq!(
        j["segments"][0]["category"]["meaning"],
        "Anatomical Structure"
    );
    assert_eq!(j["segments"][0]["modifier"], Value::Null);
    let o = run(&["info", first]);
    assert!(
        stdout(&o).contains("1: ribs (the voxels of value 1, shown in #fde89e; coded Rib (SCT 113197003), in Anatomical Structure)"),
        "{}",
        stdout(&o)
    );

    // The tissue whole from both of Slicer's files: one surface.
    let (one, two) = (
        files[0]["path"].as_str().unwrap(),
        files[1]["path"].as_str().unwrap(),
    );
    let tissue = |input: &str, name: &str| {
        let out = tmp(name);
        let o = run(&[
            "iso",
            "--quiet",
            input,
            "--segment",
            "tissue",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        raystream_io::load_mesh(&out).unwrap()
    };
    let (a, b) = (
        tissue(one, "slicer-tissue-1.ply"),
        tissue(two, "slicer-tissue-2.ply"),
    );
    assert!(a.len() > 1000 && a.positions == b.positions && a.triangles == b.triangles);
    let all = tmp("slicer-segments.glb");
    let o = run(&["iso", "--quiet", two, "-o", all.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, shading) = raystream_io::load_mesh_with_shading(&all).unwrap();
    for (m, s) in shading
        .materials
        .iter()
        .zip(files[1]["segments"].as_array().unwrap())
    {
        assert_eq!(m.name, s["name"].as_str().unwrap());
        let colour: [f64; 3] = serde_json::from_value(s["colour"].clone()).unwrap();
        let diffuse = m.diffuse.unwrap();
        // glTF's colour factors are linear.
        let linear = |c: f64| {
            let c = c / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        };
        for c in 0..3 {
            assert!(
                (diffuse[c] as f64 - linear(colour[c])).abs() < 1e-5,
                "{}",
                m.name
            );
        }
    }
    assert_eq!(shading.materials.len(), 8);

    // `info --json CT --segmentation ONE` with more options: its JSON.
    let ct = v["ct"].as_str().unwrap();
    let info_with = |more: &[&str]| -> Value {
        let mut args = vec!["info", "--json", ct, "--segmentation", one];
        args.extend_from_slice(more);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str(stdout(&o).trim()).unwrap()
    };
    // The chest CT's values within each segment, and the lungs' densitometry: LAA-950
    // (normal lungs: under 1 %), the share below -856 HU, Perc15 and the 2.5th percentile.
    let info = info_with(&[
        "--below",
        "-950,-856",
        "--percentile",
        "15",
        "--percentile=2.5",
        "--combine",
        "lungs=right lung,LEFT LUNG",
    ]);
    let stats = info["segmentation"]["segments"].as_array().unwrap();
    let means = v["ct_means"].as_array().unwrap();
    assert_eq!(stats.len(), means.len());
    let lists = |v: &Value| -> Vec<Vec<f64>> { serde_json::from_value(v.clone()).unwrap() };
    let (below, percentiles) = (lists(&v["ct_below"]), lists(&v["ct_percentiles"]));
    for (n, (s, want)) in stats.iter().zip(means).enumerate() {
        let (got, want) = (s["mean"].as_f64().unwrap(), want.as_f64().unwrap());
        assert!(
            (got - want).abs() < 0.05,
            "{}: mean {got} vs {want}",
            s["name"]
        );
        let field = |list: &str, key: &str| -> Vec<f64> {
            let items = s[list].as_array().unwrap();
            items.iter().map(|b| b[key].as_f64().unwrap()).collect()
        };
        assert_eq!(field("below", "hu"), [-950.0, -856.0]);
        assert_eq!(field("percentiles", "p"), [15.0, 2.5]);
        for (got, want) in field("below", "percent").iter().zip(&below[n]) {
            assert!((got - want).abs() < 1e-9, "{}: {got} vs {want}", s["name"]);
        }
        for (got, want) in field("percentiles", "value").iter().zip(&percentiles[n]) {
            assert!((got - want).abs() < 1e-9, "{}: {got} vs {want}", s["name"]);
        }
    }
    let lung = |name: &str| stats.iter().find(|s| s["name"] == name).unwrap();
    for name in ["right lung", "left lung"] {
        let laa = lung(name)["below"][0]["percent"].as_f64().unwrap();
        let perc15 = lung(name)["percentiles"][0]["value"].as_f64().unwrap();
        assert!(laa > 0.0 && laa < 1.0, "{name}: LAA-950 {laa} %");
        assert!(
            (-910.0..-880.0).contains(&perc15),
            "{name}: Perc15 {perc15}"
        );
    }
    // Both lungs as one region: numpy's over the union of their masks.
    let lungs = &info["segmentation"]["combined"][0];
    let want: Vec<f64> = serde_json::from_value(v["ct_lungs"].clone()).unwrap();
    assert_eq!(lungs["name"], "lungs");
    assert_eq!(lungs["voxels"].as_f64().unwrap(), want[0]);
    let laa = lungs["below"][0]["percent"].as_f64().unwrap();
    assert!((laa - want[1]).abs() < 1e-9, "{laa} vs {}", want[1]);
    let perc15 = lungs["percentiles"][0]["value"].as_f64().unwrap();
    assert!((perc15 - want[2]).abs() < 1e-9, "{perc15} vs {}", want[2]);
    let lobes: Vec<u64> = serde_json::from_value(lungs["segments"].clone()).unwrap();
    assert_eq!(lobes.len(), 2);
    // Each segment's mass: numpy's sum of (HU + 1000) / 1000 g/ml over its voxels.
    let voxel_ml = v["ct_voxel_ml"].as_f64().unwrap();
    for (s, want) in stats.iter().zip(v["ct_masses"].as_array().unwrap()) {
        let (got, want) = (s["mass_g"].as_f64().unwrap(), want.as_f64().unwrap());
        assert!(
            (got - want).abs() < 1e-6 * want.abs().max(1.0),
            "{}: {got} g vs {want}",
            s["name"]
        );
    }

    // Each segment's Agatston score (its bones' calcium, on this CT): scipy's lesions in
    // each slice, joined at edges and corners, of 1 mm² or more, weighted by their peaks and
    // by the slices' 10 mm over 3 mm.
    let lesions = dir.join("lesions.nii.gz");
    let calcium = info_with(&["--agatston", "--agatston-mask", lesions.to_str().unwrap()]);
    let method = &calcium["segmentation"]["agatston"];
    assert!(
        (method["slice_factor"].as_f64().unwrap() - 10.0 / 3.0).abs() < 1e-6,
        "{method}"
    );
    let scored = calcium["segmentation"]["segments"].as_array().unwrap();
    let wants = v["ct_agatston"].as_array().unwrap();
    assert_eq!(scored.len(), wants.len());
    for (s, want) in scored.iter().zip(wants) {
        let got = &s["agatston"];
        for key in ["lesions", "slices", "peak_hu"] {
            assert_eq!(got[key], want[key], "{}: {key}", s["name"]);
        }
        for key in ["score", "volume_mm3"] {
            let (g, w) = (got[key].as_f64().unwrap(), want[key].as_f64().unwrap());
            assert!(
                (g - w).abs() <= 1e-9 * w.max(1.0),
                "{}: {key} {g} vs {w}",
                s["name"]
            );
        }
        // Each lesion: its slice, voxels and peak, as scipy's (in order of those).
        let mut each: Vec<(u64, u64, f64)> = (got["each"].as_array().unwrap().iter())
            .map(|l| {
                let n = |k: &str| l[k].as_u64().unwrap();
                (n("slice"), n("voxels"), l["peak_hu"].as_f64().unwrap())
            })
            .collect();
        each.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let want: Vec<(u64, u64, f64)> = serde_json::from_value(want["each"].clone()).unwrap();
        assert_eq!(each, want, "{}", s["name"]);
        let sum: f64 = (got["each"].as_array().unwrap().iter())
            .map(|l| l["score"].as_f64().unwrap())
            .sum();
        let score = got["score"].as_f64().unwrap();
        assert!((sum - score).abs() <= 1e-9 * score.max(1.0));
    }
    // The lesions written: each segment's voxels in them under its own label, named as it.
    let map = raystream_io::load_volume(&lesions, &Default::default()).unwrap();
    assert_eq!(calcium["segmentation"]["agatston_mask"]["segments"], 5);
    for s in scored {
        let l = s["value"].as_u64().unwrap() as f32;
        let want: u64 = (s["agatston"]["each"].as_array().unwrap().iter())
            .map(|l| l["voxels"].as_u64().unwrap())
            .sum();
        let got = map.data.iter().filter(|&&x| x == l).count() as u64;
        assert_eq!(got, want, "{}", s["name"]);
        if want > 0 {
            let named = map.segments.iter().find(|k| k.number as f32 == l).unwrap();
            assert_eq!(named.label, s["name"].as_str().unwrap());
        }
    }
    let ribs = scored.iter().find(|s| s["name"] == "ribs").unwrap();
    assert!(
        ribs["agatston"]["lesions"].as_u64().unwrap() > 100,
        "{ribs}"
    );
    assert_eq!(ribs["agatston"]["cac_drs"], "A3");
    let lung = scored.iter().find(|s| s["name"] == "left lung").unwrap();
    assert_eq!(lung["agatston"]["score"], 0.0);
    assert_eq!(lung["agatston"]["cac_drs"], "A0");

    // The density adjusted for the breath (the sponge model) to the TLC predicted for a man
    // of 1.80 m, 7.99 × 1.80 − 7.08 = 7.302 l: by both lungs' volume (numpy's voxel count),
    // each segment's Perc15 and mean; the lungs' mass at 7.302 l is their mass as scanned.
    let adjust = |to: &str| {
        let more = [
            "--percentile",
            "15",
            "--combine",
            "lungs=right lung,left lung",
            "--adjust-to",
            to,
        ];
        info_with(&more)["segmentation"].clone()
    };
    let lungs_ml = want[0] * voxel_ml;
    // By the lungs' two segments named, then by the --combine's name: the same.
    for to in ["right lung,LEFT LUNG=tlc:male:180", "Lungs=tlc:m:180"] {
        let got = adjust(to);
        let at = &got["adjusted_to"];
        assert_eq!(
            at["reference"]["predicted_tlc"]["sex"], "male",
            "{to}: {at}"
        );
        assert!((at["reference_ml"].as_f64().unwrap() - 7302.0).abs() < 1e-6);
        assert!((at["measured_ml"].as_f64().unwrap() - lungs_ml).abs() < 1e-6 * lungs_ml);
        let factor = lungs_ml / 7302.0;
        assert!((at["factor"].as_f64().unwrap() - factor).abs() < 1e-12);
        assert_eq!(at["segments"].as_array().unwrap().len(), 2);
        let segments = got["segments"].as_array().unwrap();
        for (n, s) in segments.iter().enumerate() {
            // Only the lungs: the sponge model is a lung's.
            if !s["name"].as_str().unwrap().ends_with(" lung") {
                assert!(s["adjusted"].is_null(), "{}", s["name"]);
                continue;
            }
            let p15 = s["adjusted"]["percentiles"][0]["value"].as_f64().unwrap();
            let want = (percentiles[n][0] + 1000.0) * factor - 1000.0;
            assert!(
                (p15 - want).abs() < 1e-6,
                "{to} {}: {p15} vs {want}",
                s["name"]
            );
            let mean = s["adjusted"]["mean"].as_f64().unwrap();
            let want = (means[n].as_f64().unwrap() + 1000.0) * factor - 1000.0;
            assert!(
                (mean - want).abs() < 0.05,
                "{to} {}: {mean} vs {want}",
                s["name"]
            );
        }
        let lungs = &got["combined"][0];
        let mean = lungs["adjusted"]["mean"].as_f64().unwrap();
        let mass = lungs["mass_g"].as_f64().unwrap();
        assert!((7302.0 * (mean + 1000.0) / 1000.0 - mass).abs() < 1e-6 * mass);
    }
    // To their own volume: nothing moves.
    let own = adjust(&format!("lungs={lungs_ml:.9}"));
    assert_eq!(own["adjusted_to"]["reference"], "given");
    let lung_segments = (own["segments"].as_array().unwrap().iter())
        .filter(|s| !s["adjusted"].is_null())
        .count();
    assert_eq!(lung_segments, 2);
    for s in (own["segments"].as_array().unwrap().iter()).filter(|s| !s["adjusted"].is_null()) {
        let (got, was) = (
            s["adjusted"]["percentiles"][0]["value"].as_f64().unwrap(),
            s["percentiles"][0]["value"].as_f64().unwrap(),
        );
        assert!((got - was).abs() < 1e-6, "{}: {got} vs {was}", s["name"]);
    }
    let adjust_refused = |to: &str, want: &str| {
        let args = ["info", ct, "--segmentation", one, "--adjust-to", to];
        refused(&args, want);
    };
    adjust_refused(
        "liver=6000",
        "--adjust-to \"liver\": no segment is named so",
    );
    adjust_refused(
        "lungs=50",
        "'lungs=50': REGION=ML (a volume, 100 to 20000 ml)",
    );
    adjust_refused("lungs=tlc:x:170", "REGION=tlc:SEX:CM");
    adjust_refused("lungs=tlc:female:20", "a height of 100 to 250 cm");
    let png = tmp("lesions.png");
    refused(
        &[
            "info",
            ct,
            "--segmentation",
            one,
            "--agatston",
            "--agatston-mask",
            png.to_str().unwrap(),
        ],
        "lesions.png: --agatston-mask writes a NIfTI label map: name it .nii or .nii.gz",
    );
    // Both take HU: a volume of other values is refused, named.
    let engine = volume("nifti/scivis_engine.nii.gz");
    for (option, want) in [
        (["--adjust-to", "a=5000"], "--adjust-to adjusts a CT's HU"),
        (["--agatston", "--json"], "--agatston scores a CT's HU"),
    ] {
        let mut args = vec!["info", &engine, "--segmentation", one];
        args.extend(option);
        let e = refused(&args, want);
        assert!(e.contains("scivis_engine.nii.gz: "), "{e}");
    }
    refused(
        &["info", ct, "--segmentation", one, "--combine", "x=liver"],
        "--combine x=\"liver\": no segment is named so",
    );
    refused(&["info", ct, "--below", "-950"], "--segmentation");
    refused(
        &["info", ct, "--segmentation", one, "--percentile", "101"],
        "'101': a percentile, from 0 to 100",
    );

    // `info CT --segmentation ONE --below=-910` with more options.
    fn below_with<'a>(ct: &'a str, one: &'a str, more: &[&'a str]) -> Vec<&'a str> {
        let mut args = vec!["info", ct, "--segmentation", one, "--below=-910"];
        args.extend_from_slice(more);
        args
    }
    let below = |more: &[&'static str]| below_with(ct, one, more);
    // Each lung's clusters of voxels below -910 HU, in 3D and within each slice: scipy's
    // (count, each size met with its count) and numpy.polyfit's power law.
    for how in ["3d", "2d"] {
        let o = run(&below(&["--json", "--clusters", how]));
        assert!(o.status.success(), "{}", stderr(&o));
        let info: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        let stats = info["segmentation"]["segments"].as_array().unwrap();
        for name in ["right lung", "left lung"] {
            let got = &stats.iter().find(|s| s["name"] == name).unwrap()["below"][0]["clusters"];
            let want = &v["lung_clusters"][name][how];
            assert_eq!(got["connectivity"], how);
            assert!(
                want["count"].as_u64().unwrap() > 500,
                "{name} {how}: {want}"
            );
            for key in ["count", "sizes"] {
                assert_eq!(got[key], want[key], "{name} {how}: {key}");
            }
            for key in ["d", "r2"] {
                let (g, w) = (got[key].as_f64().unwrap(), want[key].as_f64().unwrap());
                assert!((g - w).abs() < 1e-9, "{name} {how}: {key} {g} vs {w}");
            }
            let sizes: Vec<[u64; 2]> = serde_json::from_value(got["sizes"].clone()).unwrap();
            assert_eq!(got["largest_voxels"], sizes.last().unwrap()[0]);
        }
    }
    // The voxels below -910 HU written as a label map: each segment's count of them under its
    // own label, named and coloured as the segment is (its label table read back).
    let laa = dir.join("laa.nii.gz");
    let o = run(&below_with(
        ct,
        one,
        &["--json", "--below-mask", laa.to_str().unwrap()],
    ));
    assert!(o.status.success(), "{}", stderr(&o));
    let info: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let map = raystream_io::load_volume(&laa, &Default::default()).unwrap();
    let ct_labels = raystream_io::load_volume(Path::new(one), &Default::default()).unwrap();
    let mut written = 0;
    for s in info["segmentation"]["segments"].as_array().unwrap() {
        let l = s["value"].as_u64().unwrap();
        let want = s["below"][0]["voxels"].as_u64().unwrap() as usize;
        let got = map.data.iter().filter(|&&x| x == l as f32).count();
        assert_eq!(got, want, "{}", s["name"]);
        if want > 0 {
            written += 1;
            let named = map.segments.iter().find(|k| k.number as u64 == l).unwrap();
            let own = ct_labels
                .segments
                .iter()
                .find(|k| k.number as u64 == l)
                .unwrap();
            assert_eq!((&named.label, named.colour), (&own.label, own.colour));
        }
    }
    assert_eq!(map.segments.len(), written);
    assert_eq!(info["segmentation"]["below_mask"]["segments"], written);
    assert!(written >= 2, "{written}");
    refused(
        &below(&["--below-mask", "laa.stl"]),
        "laa.stl: --below-mask writes a NIfTI label map",
    );
    let o = run(&below(&["--clusters"]));
    let text = stdout(&o);
    let line = (text.lines())
        .find(|l| l.contains("density") && l.contains("right lung"))
        .unwrap();
    assert!(
        line.contains("621 clusters, largest") && line.contains(", D 1.17"),
        "{line}"
    );
    refused(
        &["info", ct, "--segmentation", one, "--clusters"],
        "--below",
    );

    // The right lung alone, in its green (#16c547): no pixel of the left lung's magenta.
    let png = render_to(
        "slicer-right-lung.png",
        "cpu",
        &[one, "--segment", "right lung", "--size", "48x40"],
    );
    let img = image::open(&png).unwrap().to_rgb8();
    let green = img
        .pixels()
        .filter(|p| p[1] > p[0] + 30 && p[1] > p[2] + 30)
        .count();
    let magenta = img
        .pixels()
        .filter(|p| p[0] > p[1] + 30 && p[2] > p[1] + 30)
        .count();
    assert!(
        green > 100 && magenta == 0,
        "{green} green, {magenta} magenta"
    );

    // An emphysema map: a coronal slice through both lungs, the segments tinted only where
    // the CT's voxel is below -910 HU. Its tinted pixels are some of those tinted without
    // --below, in the same colours; the others are the plain slice's.
    let coronal = |name: &str, extra: &[&str]| {
        let mut args = vec![
            ct,
            "--mode",
            "slice",
            "--view",
            "anterior",
            "--slice-at",
            "8,22,-150",
            "--window",
            "lung",
            "--size",
            "96x80",
        ];
        args.extend_from_slice(extra);
        image::open(render_to(name, "cpu", &args))
            .unwrap()
            .to_rgb8()
    };
    let plain = coronal("slicer-coronal.png", &[]);
    let all = coronal("slicer-coronal-all.png", &["--segmentation", one]);
    let low = coronal(
        "slicer-coronal-low.png",
        &["--segmentation", one, "--below=-910"],
    );
    let (mut tinted, mut tinted_low) = (0, 0);
    for ((p, a), l) in plain.pixels().zip(all.pixels()).zip(low.pixels()) {
        tinted += usize::from(a != p);
        if l != p {
            tinted_low += 1;
            assert_eq!(
                l, a,
                "a pixel tinted below -910 HU as it is tinted without --below"
            );
        }
    }
    assert!(
        tinted > 3000 && tinted_low > 20 && tinted_low * 10 < tinted,
        "{tinted_low} of {tinted} pixels tinted below -910 HU"
    );
    refused(
        &[
            "render",
            ct,
            "--mode",
            "dvr",
            "--segmentation",
            one,
            "--below=-910",
        ],
        "--below -910: tints a slice or a CPR's pixels",
    );
    // Nothing below -5000 HU: no segment in colour for --legend to name.
    let none = tmp("slicer-none.png");
    refused(
        &[
            "render",
            ct,
            "--mode",
            "slice",
            "--segmentation",
            one,
            "--below=-5000",
            "--legend",
            "-o",
            none.to_str().unwrap(),
        ],
        "Segmentation.seg.nrrd: --legend names the segments drawn in colour, and none of its segments is drawn in this image (none holds a voxel shown below -5000)",
    );

    // Bad files.
    let bad = |name: &str, fields: &str, want: &str| {
        let file = dir.join(name);
        let mut bytes = format!(
            "NRRD0004\ntype: uint8\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\nspace origin: (0,0,0)\n{fields}\n\n"
        )
        .into_bytes();
        bytes.extend([0, 1, 1, 2, 0, 0, 2, 1]);
        std::fs::write(&file, bytes).unwrap();
        refused(&["info", file.to_str().unwrap()], want);
    };
    bad(
        "layer.seg.nrrd",
        "Segment0_Name:=a\nSegment0_LabelValue:=1\nSegment0_Layer:=3",
        "layer.seg.nrrd: Segment0_Layer 3: the file holds 1 layer",
    );
    bad(
        "zero.seg.nrrd",
        "Segment0_LabelValue:=0",
        "zero.seg.nrrd: Segment0_LabelValue 0: label values run from 1",
    );
    bad(
        "word.seg.nrrd",
        "Segment0_LabelValue:=one",
        "word.seg.nrrd: Segment0_LabelValue \"one\" is not a whole number",
    );
    bad(
        "twice.seg.nrrd",
        "Segment0_Name:=a\nSegment0_LabelValue:=1\nSegment1_Name:=b\nSegment1_LabelValue:=1",
        "twice.seg.nrrd: segments \"a\" and \"b\" both have label value 1 on layer 0",
    );
}

/// VTK's XML formats against VTK itself (the `vtk` wheel): a block of the abdomen CT on an
/// oblique grid written as image data (`.vti`), and a sphere as polygonal data (`.vtp`, and as
/// triangle strips), in every way VTK writes them: ASCII, inline binary, appended raw and
/// base64, uncompressed and under zlib, LZ4 and LZMA (many blocks, the last one short), with
/// 32- and 64-bit headers, little- and big-endian.
/// - Every image reads as the NIfTI SimpleITK wrote of the same block: its grid (`Direction`
///   kept) and its voxels, exactly. An image whose extent starts away from 0 has its first
///   and last voxels where VTK puts them.
/// - Every surface has the triangles of the PLY VTK wrote of it, the same points (exactly,
///   but for ASCII's digits) and its normals; the strips make the same surface.
/// - `iso -o X.vtp` writes the PLY's surface; two segments are two pieces, which VTK reads
///   with their points, triangles, normals and colours.
/// - Damaged files (cut short, a lying header, a bad compressed block, a piece naming a point
///   it lacks, cell data only, vectors) are errors naming the file; a `.vtp` given as a volume
///   and a `.vti` as a mesh are named for what they are.
#[test]
fn vtk_xml_files_agree_with_vtk() {
    let Some(py) = python_with("vtkmodules") else {
        return;
    };
    let dir = tmp("vtk-xml");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/vtk_xml.py"))
        .arg(volume("nifti/abdomen_pelvis_ct_totalseg.nii.gz"))
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let select = raystream_io::VolumeSelect::default();
    let nifti = raystream_io::load_volume(&dir.join("ref.nii"), &select).unwrap();
    let images = v["images"].as_array().unwrap();
    assert_eq!(images.len(), 31);
    for name in images {
        let file = dir.join(name.as_str().unwrap());
        let read = raystream_io::load_volume(&file, &select).unwrap();
        assert_eq!(read.dims, nifti.dims, "{file:?}");
        for a in 0..3 {
            // NIfTI keeps f32 geometry.
            assert!(
                (read.spacing[a] - nifti.spacing[a]).abs() < 1e-5,
                "{file:?}"
            );
            assert!((read.origin[a] - nifti.origin[a]).abs() < 1e-4, "{file:?}");
            for b in 0..3 {
                assert!(
                    (read.direction[a][b] - nifti.direction[a][b]).abs() < 1e-6,
                    "{file:?}"
                );
            }
        }
        assert!(
            read.data == nifti.data,
            "{file:?}: its voxels differ from the NIfTI's"
        );
        assert_eq!(read.unit, nifti.unit, "{file:?}");
    }
    let i = info(dir.join("ct_raw_zlib_32_le.vti").to_str().unwrap());
    assert_eq!(i["format"], "vti");
    // A cropped extent: its first and last voxels where VTK puts them, the ramp in order.
    let crop = raystream_io::load_volume(&dir.join("cropped.vti"), &select).unwrap();
    assert_eq!(crop.dims, [6, 5, 4]);
    assert!(crop.data.iter().enumerate().all(|(i, &v)| v == i as f32));
    for (ijk, key) in [([0.0; 3], "first"), ([5.0, 4.0, 3.0], "last")] {
        let want: [f64; 3] = serde_json::from_value(v["cropped"][key].clone()).unwrap();
        let got = crop.index_to_world(raystream_math::DVec3::from(ijk));
        for a in 0..3 {
            assert!((got[a] - want[a]).abs() < 1e-9, "{key}: {got} vs {want:?}");
        }
    }

    let (ply, _) = raystream_io::load_mesh_with_shading(&dir.join("sphere.ply")).unwrap();
    let surfaces = v["surfaces"].as_array().unwrap();
    assert_eq!(surfaces.len(), 62);
    for name in surfaces {
        let name = name.as_str().unwrap();
        let file = dir.join(name);
        let (m, shading) = raystream_io::load_mesh_with_shading(&file).unwrap();
        // ASCII holds VTK's digits: within f32's rounding of 6 significant digits.
        let tol = if name.contains("ascii") { 1e-4 } else { 0.0 };
        let worst = m
            .positions
            .iter()
            .zip(&ply.positions)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0f32, f32::max);
        assert!(
            m.positions.len() == ply.positions.len() && worst <= tol,
            "{name}: {worst}"
        );
        // The sphere's normals: one a point, pointing away from its centre.
        assert_eq!(shading.normals.len(), m.positions.len(), "{name}");
        let centre = raystream_math::Vec3::new(10.0, -20.5, 300.25);
        for (n, p) in shading.normals.iter().zip(&m.positions) {
            let out = (*p - centre).normalize();
            assert!(n.dot(out) > 0.99, "{name}: normal {n} at {p}");
        }
        if name.starts_with("surface") {
            assert_eq!(m.triangles, ply.triangles, "{name}");
        } else {
            // Strips: as many triangles, the same area.
            assert_eq!(m.len(), ply.len(), "{name}");
            let area = |m: &raystream_io::TriMesh| -> f64 {
                (0..m.len())
                    .map(|t| {
                        let [a, b, c] = m.corners(t);
                        (b - a).cross(c - a).length() as f64 / 2.0
                    })
                    .sum()
            };
            assert!((area(&m) - area(&ply)).abs() < 1e-3 * area(&ply), "{name}");
        }
    }

    // `iso -o X.vtp`: the PLY's surface; two segments, a piece each, as VTK reads them.
    let ct = dir.join("ref.nii");
    let surface = |input: &std::path::Path, args: &[&str], out: &str| {
        let out = dir.join(out);
        let mut all = vec![
            "iso",
            "--quiet",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let o = run(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    };
    let (a, _) =
        raystream_io::load_mesh_with_shading(&surface(&ct, &["--iso", "300"], "bones.ply"))
            .unwrap();
    let (b, shading) =
        raystream_io::load_mesh_with_shading(&surface(&ct, &["--iso", "300"], "bones.vtp"))
            .unwrap();
    assert!(a.len() > 500 && a.positions == b.positions && a.triangles == b.triangles);
    assert_eq!(shading.normals.len(), b.positions.len());
    let labels: Vec<u8> = nifti
        .data
        .iter()
        .map(|&hu| {
            if hu > 300.0 {
                1
            } else {
                u8::from(hu > 100.0) * 2
            }
        })
        .collect();
    let label_map = dir.join("labels.nii.gz");
    raystream_io::write_label_map(&label_map, &nifti, &labels, "bone 1, soft 2").unwrap();
    let parts = surface(&label_map, &["--segment", "all"], "parts.vtp");
    let whole = raystream_io::load_mesh(&parts).unwrap();
    let one =
        raystream_io::load_mesh(&surface(&label_map, &["--segment", "1"], "part1.vtp")).unwrap();
    let two =
        raystream_io::load_mesh(&surface(&label_map, &["--segment", "2"], "part2.vtp")).unwrap();
    assert_eq!(
        (whole.positions.len(), whole.len()),
        (
            one.positions.len() + two.positions.len(),
            one.len() + two.len()
        )
    );
    let script = "import sys, json\n\
        from vtkmodules.vtkIOXML import vtkXMLPolyDataReader\n\
        r = vtkXMLPolyDataReader(); r.SetFileName(sys.argv[1]); r.Update(); m = r.GetOutput()\n\
        c = m.GetPointData().GetArray('Colors')\n\
        print(json.dumps([r.GetNumberOfPieces(), m.GetNumberOfPoints(), m.GetNumberOfPolys(),\
        m.GetPointData().GetNormals().GetNumberOfTuples(), c.GetTuple3(0), c.GetTuple3(m.GetNumberOfPoints() - 1),\
        m.GetFieldData().GetAbstractArray('SPACE').GetValue(0)]))";
    let o = std::process::Command::new(&py)
        .args(["-c", script, parts.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let got: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    // Label 1 cyan, 2 magenta, the tints of --segmentation and its legend's swatches.
    assert_eq!(
        got,
        serde_json::json!([
            2,
            whole.positions.len(),
            whole.len(),
            whole.positions.len(),
            [0.0, 230.0, 255.0],
            [255.0, 64.0, 220.0],
            "LPS"
        ])
    );
    // raystream reads them back so: the space 3D Slicer's field names, the two colours.
    let (_, shading) = raystream_io::load_mesh_with_shading(&parts).unwrap();
    assert_eq!(shading.space, Some(raystream_io::PatientSpace::Lps));
    let colours: std::collections::BTreeSet<[u8; 3]> =
        shading.colours.iter().flatten().copied().collect();
    assert_eq!(
        colours,
        std::collections::BTreeSet::from([[0, 230, 255], [255, 64, 220]])
    );

    // Damaged files.
    let damaged = |name: &str, bytes: &[u8], want: &str| {
        let file = dir.join(name);
        std::fs::write(&file, bytes).unwrap();
        refused(
            &["info", file.to_str().unwrap()],
            &format!("{name}: {want}"),
        );
    };
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    // The first byte of the appended data (after its '_').
    let appended = |b: &[u8]| {
        let tag = b.windows(13).position(|w| w == b"<AppendedData").unwrap();
        tag + b[tag..].iter().position(|&c| c == b'_').unwrap() + 1
    };
    let zlib = read("ct_raw_zlib_32_le.vti");
    damaged(
        "cut.vti",
        &zlib[..zlib.len() - 3000],
        "the VTK array \"HU\": the data is cut short in its compressed blocks",
    );
    let mut bad_block = zlib.clone();
    // Past the header: its block count, the block sizes, and each block's compressed size.
    let a = appended(&zlib);
    let blocks = u32::from_le_bytes(zlib[a..a + 4].try_into().unwrap()) as usize;
    let at = a + 4 * (3 + blocks) + 10;
    bad_block[at..at + 40].fill(0x55);
    damaged(
        "block.vti",
        &bad_block,
        "the VTK array \"HU\": block 0: zlib",
    );
    let mut lying = read("ct_raw_none_32_le.vti");
    let at = appended(&lying);
    lying[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    damaged(
        "lying.vti",
        &lying,
        "the VTK array \"HU\": its header gives 4294967295 bytes, 172800 expected",
    );
    let ascii = String::from_utf8(read("ct_ascii.vti")).unwrap();
    damaged(
        "cells.vti",
        ascii.replace("PointData", "CellData").as_bytes(),
        "the VTK image data holds cell data only",
    );
    damaged(
        "vectors.vti",
        ascii
            .replace("Name=\"HU\"", "Name=\"HU\" NumberOfComponents=\"3\"")
            .as_bytes(),
        "the VTK array \"HU\" has 3 components",
    );
    damaged(
        "huge.vti",
        ascii
            .replace(
                "WholeExtent=\"0 39 0 35 0 29\"",
                "WholeExtent=\"0 99999 0 99999 0 99999\"",
            )
            .replace(
                "Extent=\"0 39 0 35 0 29\"",
                "Extent=\"0 99999 0 99999 0 99999\"",
            )
            .as_bytes(),
        "dimensions [100000, 100000, 100000] are empty or exceed the 1073741824-voxel limit",
    );
    // The first number of the array `name` (a surface's polygons') in an ASCII file's text:
    // its byte range.
    let first_number = |text: &str, name: &str| {
        // Past the empty vertices' arrays of a surface.
        let from = text.find("<Polys>").unwrap_or(0);
        let tag = from + text[from..].find(&format!("Name=\"{name}\"")).unwrap();
        let start = tag + text[tag..].find('>').unwrap() + 1;
        let start = start
            + text[start..]
                .find(|c: char| c.is_ascii_digit() || c == '-')
                .unwrap();
        let end = start + text[start..].find(char::is_whitespace).unwrap();
        (start, end)
    };
    let (a, b) = first_number(&ascii, "HU");
    damaged(
        "short.vti",
        format!("{}{}", &ascii[..a], &ascii[b..]).as_bytes(),
        "the VTK array \"HU\" holds 43199 of its 43200 values",
    );
    let poly = String::from_utf8(read("surface_ascii.vtp")).unwrap();
    let (a, b) = first_number(&poly, "connectivity");
    damaged(
        "far.vtp",
        format!("{}999999{}", &poly[..a], &poly[b..]).as_bytes(),
        "a VTK Polys cell names point 999999, of 338 points",
    );
    let vtp = dir.join("surface_raw_zlib_32_le.vtp");
    let vtp = vtp.to_str().unwrap();
    refused(
        &["iso", vtp, "-o", tmp("x.ply").to_str().unwrap()],
        "a .vtp is VTK's polygonal data, a mesh, not a volume",
    );
}

/// `info --body` of the chest CT written as a DICOM series (a crop, every slice cut, the lungs
/// reaching its border): its figures are `raystream_volume::body`'s on the series, its
/// tissues and mean HU counted here voxel by voxel; the body written as a NIfTI label map, a
/// DICOM Segmentation and an RT Structure Set (one structure, of type EXTERNAL) reads back
/// as the body, voxel for voxel.
#[test]
fn info_body_measures_and_writes_the_body() {
    let root = tmp("info-body");
    let ct = root.join("ct");
    chest_series(&ct);
    let path = |name: &str| root.join(name).to_string_lossy().into_owned();
    let (nii, seg, rt) = (
        path("body.nii.gz"),
        path("body-seg.dcm"),
        path("body-rt.dcm"),
    );
    let ct = ct.to_str().unwrap();
    let o = run(&[
        "info",
        "--json",
        ct,
        "--body",
        "--mask",
        &seg,
        "--structures",
        &rt,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let j = &v["body"];
    let grid = raystream_io::load_volume(Path::new(ct), &Default::default()).unwrap();
    let b = raystream_volume::body::body(&grid, &Default::default()).unwrap();
    let voxel_ml = grid.voxel_ml();
    assert_eq!(j["voxels"], b.voxels);
    assert_eq!(j["cut_slices"].as_u64(), Some(grid.dims[2] as u64));
    assert!(j["border_tissue_ml"].as_f64().unwrap() > 2000.0, "{j}");
    // The tissues by HU and the mean, counted here.
    let mut counts = [0usize; 4];
    let mut sum = 0.0f64;
    for (&x, _) in grid.data.iter().zip(&b.inside).filter(|(_, i)| **i) {
        sum += x as f64;
        counts[if x < -190.0 {
            0
        } else if x <= -30.0 {
            1
        } else if x <= 150.0 {
            2
        } else {
            3
        }] += 1;
    }
    for (name, n) in ["air", "fat", "soft", "dense"].iter().zip(counts) {
        let ml = j["tissues_ml"][name].as_f64().unwrap();
        assert!(
            (ml - n as f64 * voxel_ml).abs() < 1e-3,
            "{name}: {ml} ml, {n} voxels"
        );
    }
    assert_eq!(counts.iter().sum::<usize>(), b.voxels);
    let mean = j["mean"].as_f64().unwrap();
    assert!((mean - sum / b.voxels as f64).abs() < 1e-6, "{mean}");
    // The RT Structure Set: one structure, EXTERNAL, laid back on the series as the body.
    let set = raystream_io::StructureSet::read(Path::new(&rt)).unwrap();
    assert_eq!(set.rois.len(), 1);
    assert_eq!(
        (set.rois[0].name.as_str(), set.rois[0].kind.as_str()),
        ("Body", "EXTERNAL")
    );
    let (regions, warnings) = set.regions(&grid);
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(regions[0].voxels, b.voxels);
    assert_eq!(j["structures"]["contours"], set.rois[0].contours.len());
    // The DICOM Segmentation, laid on the series by `info --segmentation`.
    let o = run(&["info", "--json", ct, "--segmentation", &seg]);
    assert!(o.status.success(), "{}", stderr(&o));
    let s: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let segments = s["segmentation"]["segments"].as_array().unwrap();
    assert_eq!(segments.len(), 1);
    assert_eq!(segments[0]["voxels"], b.voxels);
    assert_eq!(segments[0]["name"], "Body");
    // The NIfTI label map, on the series' grid: 1 exactly where the body is; and the words.
    let o = run(&["info", ct, "--body", "--mask", &nii]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    for want in [
        format!("label 1 the body on {} voxels", b.voxels),
        "tissues    below -190 HU: air, gas, lung".to_string(),
        "a lung it cuts".to_string(),
    ] {
        assert!(text.contains(&want), "{want}: {text}");
    }
    let map = raystream_io::load_volume(Path::new(&nii), &Default::default()).unwrap();
    assert_eq!(map.dims, grid.dims);
    let wrong = (map.data.iter().zip(&b.inside))
        .filter(|(l, i)| (**l == 1.0) != **i)
        .count();
    assert_eq!(wrong, 0);
}

/// A folder of NIfTI masks, a file a structure (as TotalSegmentator writes its
/// `segmentations/`), read as one segmentation of the CT they were drawn on:
/// - each mask a segment named by its file, numbered in name order; an empty mask (most of
///   TotalSegmentator's on any one CT) holds no voxel; a file that is no NIfTI is passed by;
/// - `info CT --segmentation DIR` measures each mask whole where masks overlap (the voxels
///   and mean HU computed here from the masks), with densitometry;
/// - `render --segmentation DIR --segment NAME` and `iso DIR --segment NAME` take them by name;
/// - a mask on another grid, or a file holding other values than 0 and 1 (the CT among its
///   masks), is refused, the file named.
#[test]
fn a_folder_of_masks_is_a_segmentation() {
    let ct_path = builtin_ct();
    let ct = raystream_io::load_volume(Path::new(&ct_path), &Default::default()).unwrap();
    let [nx, ny, nz] = ct.dims;
    let dir = tmp("mask-folder");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let ijk = |n: usize| (n % nx, (n / nx) % ny, n / (nx * ny));
    let mask = |f: &dyn Fn(usize, f32) -> bool| -> Vec<u8> {
        (ct.data.iter().enumerate())
            .map(|(n, &h)| u8::from(f(n, h)))
            .collect()
    };
    let bone = mask(&|_, h| h > 300.0);
    let gas = mask(&|n, h| h < -500.0 && ijk(n).2 < nz / 2);
    let block = mask(&|n, _| {
        let (i, j, k) = ijk(n);
        (40..80).contains(&i) && (30..70).contains(&j) && (20..60).contains(&k)
    });
    let empty = vec![0u8; ct.data.len()];
    for (name, m) in [
        ("bone.nii.gz", &bone),
        ("gas.nii", &gas),
        ("zz_block.nii.gz", &block),
        ("aorta.nii.gz", &empty),
    ] {
        raystream_io::write_label_map(&dir.join(name), &ct, m, "mask").unwrap();
    }
    std::fs::write(dir.join("statistics.json"), "{}").unwrap();
    // The gas as float32 (SimpleITK writes masks so when asked): NIfTI-1's datatype 16 and
    // bitpix 32 at bytes 70 and 72, its voxels after the header's vox_offset.
    let file = dir.join("gas.nii");
    let bytes = std::fs::read(&file).unwrap();
    let offset = f32::from_le_bytes(bytes[108..112].try_into().unwrap()) as usize;
    let mut float = bytes[..offset].to_vec();
    float[70..72].copy_from_slice(&16i16.to_le_bytes());
    float[72..74].copy_from_slice(&32i16.to_le_bytes());
    float.extend(gas.iter().flat_map(|&m| (m as f32).to_le_bytes()));
    std::fs::write(&file, float).unwrap();
    let overlap = (bone.iter().zip(&gas).zip(&block))
        .filter(|&((b, g), k)| b + g + k > 1)
        .count();
    assert!(overlap > 100, "{overlap}");

    // The folder alone: its masks as a label map's segments.
    let d = dir.to_str().unwrap();
    let labels = info(d);
    let names: Vec<&str> = (labels["segments"].as_array().unwrap().iter())
        .map(|s| s["label"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["aorta", "bone", "gas", "zz_block"], "{labels}");
    let warnings = labels["warnings"].to_string();
    assert!(
        warnings.contains(&format!("{overlap} voxels lie in two masks")),
        "{warnings}"
    );

    // The CT within each, whole.
    let o = run(&[
        "info",
        "--json",
        &ct_path,
        "--segmentation",
        d,
        "--below",
        "-500",
        "--percentile",
        "50",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let got: Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let segments = got["segmentation"]["segments"].as_array().unwrap();
    let ours: Vec<(u64, &str)> = segments
        .iter()
        .map(|s| (s["value"].as_u64().unwrap(), s["name"].as_str().unwrap()))
        .collect();
    assert_eq!(ours, [(2, "bone"), (3, "gas"), (4, "zz_block")]);
    for (s, m) in segments.iter().zip([&bone, &gas, &block]) {
        let held: Vec<f64> = (ct.data.iter().zip(m.iter()))
            .filter(|&(_, &m)| m == 1)
            .map(|(&h, _)| h as f64)
            .collect();
        assert_eq!(
            s["voxels"].as_u64().unwrap() as usize,
            held.len(),
            "{}",
            s["name"]
        );
        let mean = held.iter().sum::<f64>() / held.len() as f64;
        assert!(
            (s["mean"].as_f64().unwrap() - mean).abs() < 1e-6,
            "{}",
            s["name"]
        );
        let below = held.iter().filter(|&&h| h < -500.0).count();
        assert_eq!(s["below"][0]["voxels"].as_u64().unwrap() as usize, below);
    }
    assert_eq!(segments[1]["below"][0]["percent"].as_f64().unwrap(), 100.0);

    // By name, in a render and as a surface.
    render_to(
        "mask-folder-bone.png",
        "cpu",
        &[
            &ct_path,
            "--mode",
            "mip",
            "--segmentation",
            d,
            "--segment",
            "bone",
            "--size",
            "32x32",
        ],
    );
    let ply = tmp("mask-folder-gas.ply");
    let o = run(&[
        "iso",
        "--quiet",
        d,
        "--segment",
        "gas",
        "-o",
        ply.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(raystream_io::load_mesh(&ply).unwrap().len() > 100);

    // Refused: a mask on another grid; the CT among the masks.
    let other = tmp("mask-folder-other");
    let _ = std::fs::remove_dir_all(&other);
    std::fs::create_dir_all(&other).unwrap();
    raystream_io::write_label_map(&other.join("a.nii.gz"), &ct, &bone, "mask").unwrap();
    let small = raystream_io::Volume::hounsfield([8, 8, 8], [1.0; 3], vec![0.0; 512]);
    raystream_io::write_label_map(&other.join("b.nii.gz"), &small, &[1; 512], "mask").unwrap();
    refused(
        &["info", &ct_path, "--segmentation", other.to_str().unwrap()],
        "b.nii.gz: a mask of this folder on another grid (8 x 8 x 8 voxels",
    );
    std::fs::remove_file(other.join("b.nii.gz")).unwrap();
    std::fs::copy(&ct_path, other.join("ct.nii.gz")).unwrap();
    refused(
        &["info", other.to_str().unwrap()],
        "ct.nii.gz: holds the value",
    );
    // A mask of bytes is scanned as it streams: a 2 past its first chunks, and one cut short
    // (gzipped or not), are refused naming the file.
    std::fs::remove_file(other.join("ct.nii.gz")).unwrap();
    let mut two = bone.clone();
    let last = two.len() - 1;
    two[last] = 2;
    raystream_io::write_label_map(&other.join("b.nii.gz"), &ct, &two, "mask").unwrap();
    refused(
        &["info", other.to_str().unwrap()],
        "b.nii.gz: holds the value 2",
    );
    for name in ["b.nii.gz", "b.nii"] {
        let _ = std::fs::remove_file(other.join("b.nii.gz"));
        let b = other.join(name);
        raystream_io::write_label_map(&b, &ct, &bone, "mask").unwrap();
        let bytes = std::fs::read(&b).unwrap();
        std::fs::write(&b, &bytes[..bytes.len() * 2 / 3]).unwrap();
        // Plain, "is truncated"; gzipped, zlib's "incomplete deflate stream".
        let e = refused(&["info", other.to_str().unwrap()], &format!("{name}: "));
        let cut = e.contains("is truncated") || e.contains("incomplete deflate stream");
        assert!(e.contains("the NIfTI voxel data") && cut, "{e}");
        std::fs::remove_file(&b).unwrap();
    }
}

/// TotalSegmentator's multi-label NIfTI (`--ml`): its labels' names and colours in a header
/// extension, the XML label table of Connectome Workbench's label volumes. Its segments are
/// named and coloured by it (in `info`, and in `info CT --segmentation`'s statistics), from a
/// file laid out here and from one nibabel (TotalSegmentator's NIfTI library) writes; a table
/// that cannot be read is a warning, the labels then unnamed.
#[test]
fn a_multi_label_nifti_names_its_labels_from_its_label_table() {
    let ct_path = builtin_ct();
    let ct = raystream_io::load_volume(Path::new(&ct_path), &Default::default()).unwrap();
    let labels: Vec<u8> = (ct.data.iter())
        .map(|&h| match h {
            h if h > 300.0 => 2,
            h if h < -500.0 => 5,
            _ => 0,
        })
        .collect();
    let plain = tmp("ml-plain.nii");
    raystream_io::write_label_map(&plain, &ct, &labels, "labels").unwrap();
    let bytes = std::fs::read(&plain).unwrap();
    let offset = f32::from_le_bytes(bytes[108..112].try_into().unwrap()) as usize;
    let with_table = |name: &str, xml: &str| -> String {
        let mut content = xml.as_bytes().to_vec();
        // esize (a multiple of 16, its 8 bytes included) and ecode 0, as nibabel writes it.
        content.resize((content.len() + 8).div_ceil(16) * 16 - 8, b' ');
        let mut out = bytes[..348].to_vec();
        let voxels = 348 + 4 + 8 + content.len();
        out[108..112].copy_from_slice(&(voxels as f32).to_le_bytes());
        out.extend([1, 0, 0, 0]);
        out.extend(((content.len() + 8) as i32).to_le_bytes());
        out.extend(0i32.to_le_bytes());
        out.extend(content);
        out.extend(&bytes[offset..]);
        let file = tmp(name);
        std::fs::write(&file, out).unwrap();
        file.to_str().unwrap().to_string()
    };
    let table = "<?xml version=\"1.0\" encoding=\"UTF-8\"?> <CaretExtension>  <VolumeInformation Index=\"0\">   <LabelTable>\n<Label Key=\"2\" Red=\"0.0\" Green=\"1.0\" Blue=\"0.0\" Alpha=\"1\"><![CDATA[vertebrae_L1]]></Label>\n<Label Key=\"5\" Red=\"0.0\" Green=\"1.0\" Blue=\"1.0\" Alpha=\"1\"><![CDATA[colon]]></Label>\n<Label Key=\"7\" Red=\"1.0\" Green=\"0.5019607843137255\" Blue=\"0.0\" Alpha=\"1\"><![CDATA[liver]]></Label>\n  </LabelTable>  <VolumeType><![CDATA[Label]]></VolumeType>   </VolumeInformation></CaretExtension>\n              ";
    let named = with_table("ml-named.nii", table);
    let got = info(&named);
    let segments: Vec<(u64, &str, Value)> = (got["segments"].as_array().unwrap().iter())
        .map(|s| {
            let n = s["number"].as_u64().unwrap();
            (n, s["label"].as_str().unwrap(), s["colour"].clone())
        })
        .collect();
    assert_eq!(
        segments,
        [
            (2, "vertebrae_L1", serde_json::json!([0, 255, 0])),
            (5, "colon", serde_json::json!([0, 255, 255])),
            (7, "liver", serde_json::json!([255, 128, 0])),
        ],
        "{got}"
    );
    let o = run(&["info", &ct_path, "--segmentation", &named]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("segment    2 (vertebrae_L1): "), "{text}");
    assert!(text.contains("segment    5 (colon): "), "{text}");
    // The same table as nibabel (TotalSegmentator's NIfTI library) writes it, gzipped.
    if let Some(py) = python_with("nibabel") {
        let gz = tmp("ml-nibabel.nii.gz");
        let o = std::process::Command::new(&py)
            .arg(repo().join("crates/raystream/tests/nibabel_labels.py"))
            .args([&plain, &gz])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let theirs = info(gz.to_str().unwrap());
        assert_eq!(theirs["segments"], got["segments"], "{theirs}");
        assert_eq!(theirs["labels"], got["labels"]);
    }
    // The plain file: no names. A broken table: a warning, no names.
    assert!(
        info(plain.to_str().unwrap())["segments"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    let broken = with_table("ml-broken.nii", "<LabelTable><Label Key=\"1\">a</Lab>");
    let got = info(&broken);
    assert!(got["segments"].as_array().unwrap().is_empty());
    let warnings = got["warnings"].to_string();
    assert!(
        warnings.contains("its label table (a header extension) is not read"),
        "{warnings}"
    );
}
