//! `render --mode slice --path FILE` (and a slab's `mip`/`minip`/`average`): curved planar
//! reformation along a centreline, on the chest CT of `../shared` (its stented descending
//! aorta, `examples/chest_aorta.mrk.json`), on both devices.

mod common;
use std::path::Path;

use common::*;
use raystream_math::DVec3;

/// The HU of an EXR's one channel, and its comments.
fn hu(path: &Path) -> (Vec<f32>, String) {
    let e = raystream_cpu::load_exr(path).unwrap();
    (
        e.channels["Y"].as_f32().expect("floats").to_vec(),
        e.comments.clone(),
    )
}

/// GPU against CPU, as every HU picture: within 4 HU for 99 % of pixels, 16 HU for all (the
/// half-float texture's error), and NaN (no sample) on both or neither.
fn assert_hu_agree(cpu: &[f32], gpu: &[f32], what: &str) {
    let mut d: Vec<f32> = cpu.iter().zip(gpu).map(|(a, b)| (a - b).abs()).collect();
    assert!(
        d.iter().all(|x| !x.is_nan()),
        "{what}: NaN on one device only"
    );
    d.sort_by(f32::total_cmp);
    let (p99, max) = (d[d.len() * 99 / 100], d[d.len() - 1]);
    assert!(
        p99 <= 4.0 && max <= 16.0,
        "{what}: p99 {p99} HU, max {max} HU"
    );
}

/// The aorta straightened: down the middle of the CPR runs the contrast-filled lumen (and in
/// its upper part the stent graft's metal), whichever way the cut faces; the slab's MIP,
/// average and MinIP of the same samples are ordered pixel by pixel, and the 10 mm MIP shows
/// more of the graft's wire than the thin cut. The GPU's values are the CPU's within its
/// half-float texture's error.
#[test]
fn curved_reformation_straightens_the_stented_aorta() {
    let (vol, path) = (chest(), aorta());
    let (w, h) = (63usize, 180usize);
    let size = format!("{w}x{h}");
    let base = [&vol[..], "--path", &path, "--size", &size];
    let mut by_dev = Vec::new();
    for dev in devices() {
        for view in ["anterior", "left"] {
            let args = [&base[..], &["--mode", "slice", "--view", view]].concat();
            let (thin, comments) = hu(&render_to(&format!("cpr-{view}-{dev}.exr"), dev, &args));
            assert_eq!(thin.len(), w * h);
            assert!(
                comments.contains("curved planar reformation") && comments.contains("154."),
                "{comments}"
            );
            // The middle column is the path: contrast (> 150 HU) in nearly every row.
            let lumen = (0..h).filter(|&y| thin[y * w + w / 2] > 150.0).count();
            assert!(lumen * 100 >= 95 * h, "{dev} {view}: {lumen} of {h} rows");
            // The lumen is one band about the middle as wide as the aorta (its median width
            // over the rows), the same from the front and from the side: a round vessel cut
            // along its axis, not across.
            let mut widths: Vec<usize> = (0..h)
                .map(|y| {
                    let row = &thin[y * w..(y + 1) * w];
                    let c = w / 2;
                    let left = (0..=c).rev().take_while(|&x| row[x] > 150.0).count();
                    let right = (c + 1..w).take_while(|&x| row[x] > 150.0).count();
                    left + right
                })
                .collect();
            widths.sort();
            let pixel_mm = 154.2 / h as f32;
            by_dev.push((*dev, view, thin, widths[h / 2] as f32 * pixel_mm));
        }
        let slab = |mode: &str| {
            let args = [&base[..], &["--mode", mode, "--slab", "10"]].concat();
            hu(&render_to(&format!("cpr-{mode}-{dev}.exr"), dev, &args)).0
        };
        let (mip, avg, min) = (slab("mip"), slab("average"), slab("minip"));
        by_dev.push((*dev, "mip", mip.clone(), f32::NAN));
        for i in 0..w * h {
            assert!(
                min[i] <= avg[i] + 1e-3 && avg[i] <= mip[i] + 1e-3,
                "{dev} pixel {i}: {} {} {}",
                min[i],
                avg[i],
                mip[i]
            );
        }
        let wire = |v: &[f32]| v.iter().filter(|&&x| x > 1500.0).count();
        let thin = &by_dev
            .iter()
            .find(|b| b.0 == *dev && b.1 == "anterior")
            .unwrap()
            .2;
        assert!(
            wire(&mip) > 2 * wire(thin) && wire(thin) > 0,
            "{dev}: {} metal pixels in the slab, {} in the cut",
            wire(&mip),
            wire(thin)
        );
    }
    for b in by_dev.iter().filter(|b| b.1 != "mip") {
        assert!(
            (18.0..45.0).contains(&b.3),
            "{} {}: the lumen {} mm wide",
            b.0,
            b.1,
            b.3
        );
        let other = by_dev
            .iter()
            .find(|o| o.0 == b.0 && o.1 != b.1 && o.1 != "mip")
            .unwrap();
        assert!(
            (b.3 - other.3).abs() <= 0.2 * b.3,
            "{} mm against {} mm",
            b.3,
            other.3
        );
    }
    // GPU against CPU, the cuts and the slab's MIP.
    for view in ["anterior", "left", "mip"] {
        let of = |dev: &str| by_dev.iter().find(|b| b.0 == dev && b.1 == view);
        if let (Some(cpu), Some(gpu)) = (of("cpu"), of("gpu")) {
            assert_hu_agree(&cpu.2, &gpu.2, view);
        }
    }
}

/// `--cpr stretched` (Kanitsar 2002): the aorta's surface swept along the view's right,
/// unrolled. From the front and from the left, where the path crosses each row (as the
/// library's stretched plane along the direction the EXR names puts it) is contrast lumen in
/// nearly every row; from the left, where the arch and the descent bend along the view's
/// right, the path's column wanders more than 20 mm across the picture, the picture is not
/// the straightened one, and its rows are closer than the straightened ones (the path runs
/// shorter across that direction than along itself). From the front, a 6 mm slab about the
/// stretched surface gives MinIP ≤ average ≤ MIP per pixel, the MIP above the thin cut on
/// most. The GPU's values are the CPU's within its half-float texture's error.
#[test]
fn a_stretched_cpr_keeps_the_aortas_bend() {
    let (vol, path) = (chest(), aorta());
    let (w, h) = (101usize, 180usize);
    let size = format!("{w}x{h}");
    let points = raystream_io::read_curve(Path::new(&path)).unwrap();
    let mut by_dev = Vec::new();
    for dev in devices() {
        for view in ["anterior", "left"] {
            let args = [
                &vol[..],
                "--path",
                &path,
                "--size",
                &size,
                "--mode",
                "slice",
                "--view",
                view,
                "--cpr",
                "stretched",
            ];
            let name = format!("cpr-stretched-{view}-{dev}.exr");
            let (v, comments) = hu(&render_to(&name, dev, &args));
            // The vector of interest, as the comments name it.
            let at = comments.find("stretched along (").expect(&comments) + 17;
            let end = at + comments[at..].find(')').unwrap();
            let d: Vec<f64> = comments[at..end]
                .split(", ")
                .map(|x| x.parse().unwrap())
                .collect();
            let interest = DVec3::new(d[0], d[1], d[2]);
            let plane =
                raystream_cpu::cpr::CurvedPlane::stretched(&points, interest, w as u32, h as u32)
                    .unwrap();
            let columns: Vec<usize> = (0..h)
                .map(|y| {
                    let x = 0.5 * w as f32 + plane.shift_mm[y] / plane.pixel_mm;
                    (x.floor() as usize).min(w - 1)
                })
                .collect();
            let lumen = (0..h).filter(|&y| v[y * w + columns[y]] > 150.0).count();
            assert!(lumen * 100 >= 95 * h, "{dev} {view}: {lumen} of {h} rows");
            let wander = (columns.iter().max().unwrap() - columns.iter().min().unwrap()) as f32
                * plane.pixel_mm;
            if view == "left" {
                assert!(wander > 20.0, "{dev}: the path wanders {wander} mm");
                assert!(
                    plane.pixel_mm < 0.95 * 154.2 / h as f32,
                    "{}",
                    plane.pixel_mm
                );
                let name = format!("cpr-straightened-{view}-{dev}.exr");
                let (s, _) = hu(&render_to(&name, dev, &args[..9]));
                let differ = v.iter().zip(&s).filter(|(a, b)| (*a - *b).abs() > 50.0);
                assert!(differ.count() * 4 > w * h, "{dev}: as the straightened CPR");
            }
            if view == "anterior" {
                // A slab about the stretched surface, along its normal (the direction × the
                // path's tangent): per pixel MinIP ≤ average ≤ MIP.
                let slab = |mode: &str| {
                    let args = [
                        &args[..5],
                        &["--mode", mode, "--slab", "6", "--cpr", "stretched"],
                    ]
                    .concat();
                    hu(&render_to(
                        &format!("cpr-stretched-{mode}-{dev}.exr"),
                        dev,
                        &args,
                    ))
                    .0
                };
                let (mip, avg, min) = (slab("mip"), slab("average"), slab("minip"));
                for i in 0..w * h {
                    assert!(
                        min[i] <= avg[i] + 1e-3 && avg[i] <= mip[i] + 1e-3,
                        "{dev} pixel {i}"
                    );
                }
                assert!(mip.iter().zip(&v).filter(|(m, t)| *m > *t).count() * 2 > w * h);
            }
            by_dev.push((*dev, view, v));
        }
    }
    for view in ["anterior", "left"] {
        let of = |dev: &str| by_dev.iter().find(|b| b.0 == dev && b.1 == view);
        if let (Some(cpu), Some(gpu)) = (of("cpu"), of("gpu")) {
            assert_hu_agree(&cpu.2, &gpu.2, view);
        }
    }
}

/// A rotational CPR: `--turntable N` turns the cut about the path, each frame exactly the
/// picture `--orbit` gives at its angle, and the middle column of an odd-width image (the path
/// itself) the same in every frame; half a turn mirrors it. Stretched, the vector of interest
/// turns with the camera: a quarter turn from the front is the view from the left, half a
/// turn the mirror image.
#[test]
fn rotational_cpr_turns_about_the_path() {
    let (vol, path) = (chest(), aorta());
    for cpr in ["straightened", "stretched"] {
        let base = cpr_args(&vol, &path, &["--size", "31x90", "--cpr", cpr]);
        let dir = tmp(&format!("cpr-turntable-{cpr}"));
        std::fs::remove_dir_all(&dir).ok();
        let args = [&base[..], &["--turntable", "4", "--format", "exr"]].concat();
        let mut all = vec!["render", "--quiet", "--device", "cpu"];
        all.extend_from_slice(&args);
        all.extend_from_slice(&["-o", dir.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        let frames: Vec<Vec<f32>> = (0..4)
            .map(|i| hu(&dir.join(format!("frame_00{i}.exr"))).0)
            .collect();
        let orbit = [&base[..], &["--orbit", "90"]].concat();
        let single = hu(&render_to(&format!("cpr-orbit90-{cpr}.exr"), "cpu", &orbit)).0;
        assert_eq!(frames[1], single, "{cpr}: frame 1 is --orbit 90");
        assert_ne!(frames[0], frames[1]);
        if cpr == "straightened" {
            // The path itself, the middle column, whichever way the cut faces.
            let middle = |f: &[f32]| (0..90).map(|y| f[y * 31 + 15]).collect::<Vec<_>>();
            for f in &frames[1..] {
                assert_eq!(middle(f), middle(&frames[0]));
            }
        } else {
            // The anterior view turned a quarter is the view from the left: the vector of
            // interest turns with the camera.
            let left = [&base[..], &["--view", "left"]].concat();
            let left = hu(&render_to("cpr-stretched-left.exr", "cpu", &left)).0;
            let mut d: Vec<f32> = left
                .iter()
                .zip(&frames[1])
                .map(|(a, b)| (a - b).abs())
                .collect();
            d.sort_by(f32::total_cmp);
            assert!(
                d[d.len() * 999 / 1000] < 0.5 && d[d.len() - 1] < 5.0,
                "{d:?}"
            );
        }
        // Half a turn shows the same cut from behind: mirrored left to right.
        for y in 0..90 {
            for x in 0..31 {
                let (a, b) = (frames[0][y * 31 + x], frames[2][y * 31 + 30 - x]);
                assert!((a - b).abs() < 1e-2, "{cpr} ({x}, {y}): {a} {b}");
            }
        }
    }
}

/// `--mark-at MM,…` draws a line across the CPR where the path is at each arc length: on the
/// straightened CPR at row s / p (p = 154.2 mm over 180 rows), on the stretched one where
/// its rows' arc lengths hold s; only those rows and their rings change, each pixel yellow or
/// black. Off the path, on an EXR or with --slices it is refused.
#[test]
fn marks_lie_across_the_cpr_at_their_arc_lengths() {
    let (vol, path) = (chest(), aorta());
    let (w, h) = (40usize, 180usize);
    let size = format!("{w}x{h}");
    let png = |name: &str, extra: &[&str]| {
        let base = cpr_args(&vol, &path, &["--size", &size]);
        let out = render_to(name, "cpu", &[&base[..], extra].concat());
        image::open(out).unwrap().to_rgb8().into_raw()
    };
    for cpr in ["straightened", "stretched"] {
        let plain = png(&format!("cpr-plain-{cpr}.png"), &["--cpr", cpr]);
        let marks = [30.0, 100.5];
        let marked = png(
            &format!("cpr-marked-{cpr}.png"),
            &["--cpr", cpr, "--mark-at", "30,100.5"],
        );
        // Where the library's plane puts them.
        let points = raystream_io::read_curve(Path::new(&path)).unwrap();
        let plane = match cpr {
            "straightened" => {
                raystream_cpu::cpr::CurvedPlane::new(&points, DVec3::X, 0.0, w as u32, h as u32)
            }
            _ => raystream_cpu::cpr::CurvedPlane::stretched(&points, DVec3::X, w as u32, h as u32),
        }
        .unwrap();
        let rows: Vec<i64> = marks
            .iter()
            .map(|&s| plane.picture_at(s).unwrap().0.floor() as i64)
            .collect();
        if cpr == "straightened" {
            let p = 154.2 / h as f64;
            for (r, s) in rows.iter().zip(marks) {
                assert!((*r as f64 - s / p).abs() <= 1.0, "{r} for {s}");
            }
        }
        for y in 0..h {
            let near = rows.iter().any(|&r| (y as i64 - r).abs() <= 1);
            let line = |v: &[u8]| v[3 * w * y..3 * w * (y + 1)].to_vec();
            if near {
                let l = line(&marked);
                assert!(
                    l.chunks(3).all(|c| c == [255, 214, 0] || c == [0, 0, 0]),
                    "{cpr} row {y}"
                );
            } else {
                assert_eq!(line(&marked), line(&plain), "{cpr} row {y}");
            }
        }
    }
    let dir = tmp("cpr-marks-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("x.png");
    let exr = dir.join("x.exr");
    let base = ["render", &vol[..], "--mode", "slice", "--path", &path];
    for (extra, want) in [
        (
            vec!["--mark-at", "200", "-o", out.to_str().unwrap()],
            "--mark-at 200: not on the path",
        ),
        (
            vec!["--mark-at", "-5,20", "-o", out.to_str().unwrap()],
            "--mark-at -5: not on the path",
        ),
        (
            vec!["--mark-at", "20", "-o", exr.to_str().unwrap()],
            "--mark-at draws on a PNG",
        ),
        (
            vec![
                "--mark-at",
                "20",
                "--slices",
                "3",
                "-o",
                out.to_str().unwrap(),
            ],
            "cannot be used with",
        ),
    ] {
        refused(&[&base[..], &extra[..]].concat(), want);
    }
}

/// A CPR written as DICOM holds its HU as a Secondary Capture (its rows follow the path: no
/// plane, no patient orientation), the window as its VOI LUT.
#[test]
fn a_dicom_cpr_is_a_secondary_capture_of_hounsfield_units() {
    use dicom_dictionary_std::tags;
    use dicom_pixeldata::PixelDecoder;
    let (vol, path) = (chest(), aorta());
    let args = cpr_args(&vol, &path, &["--size", "32x96", "--window", "mediastinum"]);
    let (values, _) = hu(&render_to("cpr-dcm.exr", "cpu", &args));
    let obj = dicom_object::open_file(render_to("cpr.dcm", "cpu", &args)).unwrap();
    let text = |tag| dicom_text(&obj, tag);
    assert_eq!(text(tags::SOP_CLASS_UID), "1.2.840.10008.5.1.4.1.1.7");
    assert_eq!(text(tags::RESCALE_TYPE), "HU");
    assert_eq!(
        (text(tags::WINDOW_CENTER), text(tags::WINDOW_WIDTH)),
        ("50".into(), "350".into())
    );
    assert!(obj.element(tags::IMAGE_POSITION_PATIENT).is_err());
    assert!(
        obj.element(tags::PATIENT_ORIENTATION).is_err()
            || text(tags::PATIENT_ORIENTATION).is_empty()
    );
    let got: Vec<f32> = obj.decode_pixel_data().unwrap().to_vec().unwrap();
    assert_eq!(got.len(), values.len());
    for (g, v) in got.iter().zip(&values) {
        let want = if v.is_nan() { -32768.0 } else { v.round() };
        assert_eq!(*g, want);
    }
}

/// Each misuse of `--path` is an error that says what to do, before any work.
#[test]
fn curved_reformation_misuse_is_a_clear_error() {
    let (vol, path) = (chest(), aorta());
    let dir = tmp("cpr-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let far = dir.join("far.txt");
    std::fs::write(&far, "5000 5000 5000\n5100 5000 5000\n").unwrap();
    let broken = dir.join("broken.mrk.json");
    std::fs::write(&broken, "{\"markups\": [{\"controlPoints\": [").unwrap();
    let one = dir.join("one.txt");
    std::fs::write(&one, "1 2 3\n").unwrap();
    // Along the anterior view's right (the patient's left, LPS +x), through the volume.
    let along = dir.join("along.txt");
    std::fs::write(&along, "20 -110 690\n60 -110 690\n").unwrap();
    let (far, broken, one, along) = (
        far.to_str().unwrap(),
        broken.to_str().unwrap(),
        one.to_str().unwrap(),
        along.to_str().unwrap(),
    );
    let out = dir.join("x.png");
    let out = out.to_str().unwrap();
    for (args, want) in [
        (
            vec!["--mode", "dvr", "--path", &path],
            "--mode slice, or mip, minip, average with --slab",
        ),
        (vec!["--mode", "mip", "--path", &path], "--slab MM"),
        (
            vec!["--mode", "slice", "--path", &path, "--orbit", "10,20"],
            "turns about its path (AZ) only",
        ),
        (
            vec!["--mode", "slice", "--path", far],
            "lies outside the volume",
        ),
        (vec!["--mode", "slice", "--path", broken], "not valid JSON"),
        (
            vec!["--mode", "slice", "--path", one],
            "two distinct points",
        ),
        (
            vec!["--mode", "slice", "--path", "/nonexistent/c.txt"],
            "/nonexistent/c.txt",
        ),
        (
            vec!["--mode", "slice", "--path", &path, "--labels"],
            "its cross-sections (--slices N) take letters",
        ),
        (vec!["--path", &path], "--mode"),
        (
            vec!["--mode", "slice", "--path", along, "--cpr", "stretched"],
            "runs 0.00 mm across the vector of interest",
        ),
        (
            vec![
                "--mode",
                "slice",
                "--path",
                &path,
                "--slices",
                "4",
                "--cpr",
                "stretched",
            ],
            "drop --cpr",
        ),
        (
            vec!["--mode", "slice", "--cpr", "stretched"],
            "--path <FILE>",
        ),
    ] {
        let mut all = vec!["render", &vol[..], "--device", "cpu", "-o", out];
        all.extend(args.iter().copied());
        refused(&all, want);
    }
    assert!(!Path::new(out).exists());
}

/// A DICOM attribute's numbers (a backslash-separated list).
fn dicom_numbers(obj: &dicom_object::DefaultDicomObject, tag: dicom_object::Tag) -> Vec<f64> {
    dicom_text(obj, tag)
        .split('\\')
        .map(|x| x.trim().parse().unwrap())
        .collect()
}

/// A DICOM image's pixel (`k`, `k`) (LPS mm: the centre of an image 2k + 1 pixels square) and
/// its plane's normal, row × column.
fn plane_of(obj: &dicom_object::DefaultDicomObject, k: usize) -> (DVec3, DVec3) {
    use dicom_dictionary_std::tags;
    let iop = dicom_numbers(obj, tags::IMAGE_ORIENTATION_PATIENT);
    let (row, col) = (
        DVec3::new(iop[0], iop[1], iop[2]),
        DVec3::new(iop[3], iop[4], iop[5]),
    );
    let ipp = dicom_numbers(obj, tags::IMAGE_POSITION_PATIENT);
    let spacing = dicom_numbers(obj, tags::PIXEL_SPACING);
    let at = DVec3::new(ipp[0], ipp[1], ipp[2])
        + row * k as f64 * spacing[1]
        + col * k as f64 * spacing[0];
    (at, row.cross(col))
}

/// `render --mode slice --path PATH --slices N --size 9x9 --format dcm` of `vol` and `extra`
/// into the folder `name` (on the CPU): its N DICOM images.
fn dicom_sections(
    (vol, path): (&str, &str),
    (name, n): (&str, &str),
    extra: &[&str],
) -> Vec<dicom_object::DefaultDicomObject> {
    let dir = tmp(name);
    std::fs::remove_dir_all(&dir).ok();
    let args = [
        &[
            "render", "--quiet", "--device", "cpu", vol, "--mode", "slice", "--path", path,
            "--slices", n, "--size", "9x9", "--format", "dcm",
        ][..],
        extra,
        &["-o", dir.to_str().unwrap()],
    ]
    .concat();
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let count: usize = n.parse().unwrap();
    (0..count)
        .map(|i| dicom_object::open_file(dir.join(format!("frame_{i:03}.dcm"))).unwrap())
        .collect()
}

/// `--path --slices N --slice-step MM`: N cross-sections MM apart along the path about its
/// middle: their centres MM apart (chords of a gently curving path), the middle one the
/// single section `--slices 1` cuts at the path's middle, each plane perpendicular to the
/// chord to its neighbours; sections that would reach beyond the path's ends are refused.
/// With `--path-at MM` about that point of the path: the one `measure` gives at that arc
/// length.
#[test]
fn cross_sections_step_along_the_path() {
    let (vol, path) = (chest(), aorta());
    let sections = |n: &str, step: &[&str]| -> Vec<(DVec3, DVec3)> {
        dicom_sections((&vol, &path), (&format!("cpr-step-{n}"), n), step)
            .iter()
            .map(|obj| plane_of(obj, 4))
            .collect()
    };
    let s = sections("7", &["--slice-step", "5"]);
    let middle = sections("1", &[]);
    assert!(
        (s[3].0 - middle[0].0).length() < 0.01,
        "{:?} {:?}",
        s[3],
        middle[0]
    );
    for w in s.windows(2) {
        let chord = w[1].0 - w[0].0;
        assert!((chord.length() - 5.0).abs() < 0.05, "{}", chord.length());
        for (_, normal) in w {
            assert!(normal.dot(chord.normalize()).abs() > 0.98);
        }
    }
    let mut all = vec!["render", &vol[..], "--device", "cpu", "--mode", "slice"];
    all.extend([
        "--path",
        &path,
        "--slices",
        "40",
        "--slice-step",
        "5",
        "-o",
        "/tmp/x",
    ]);
    refused(
        &all,
        "40 cross-sections 5.00 mm apart about its middle run from -20.4 to 174.6 mm: beyond the path's 0 to 154.2 mm",
    );

    // `--path-at MM`: about the point `measure` gives a section's figures at.
    let o = run(&[
        "measure", "--quiet", &vol, "--path", &path, "--every", "10", "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let m: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let row = &m["sections"][3];
    let arc = row["arc_mm"].as_f64().unwrap().to_string();
    let p: Vec<f64> = row["point"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let point = DVec3::new(p[0], p[1], p[2]);
    let one = sections("1", &["--path-at", &arc]);
    assert!(
        (one[0].0 - point).length() < 0.01,
        "{:?} for {point}",
        one[0]
    );
    let three = sections("3", &["--slice-step", "5", "--path-at", &arc]);
    assert!(
        (three[1].0 - point).length() < 0.01,
        "{:?} for {point}",
        three[1]
    );
    assert!(((three[0].0 - point).length() - 5.0).abs() < 0.05);
    let far = [
        &all[..6],
        &[
            "--path",
            &path,
            "--slices",
            "1",
            "--path-at",
            "1000",
            "-o",
            "/tmp/x",
        ],
    ]
    .concat();
    refused(
        &far,
        "about 1000 mm along it run from 1000.0 to 1000.0 mm: beyond the path's",
    );
}

/// `--path --slices N --field MM`: each cross-section MM high about the same point of the
/// path, its pixels MM over the height (18 mm on 9 rows: 2 mm; by default the CT's 1.5 mm
/// spacing); a field that is not above 0 is refused, and one without --path --slices.
#[test]
fn a_cross_section_s_field_sets_its_pixels() {
    use dicom_dictionary_std::tags;
    let (vol, path) = (chest(), aorta());
    let section = |name: &str, field: &[&str]| {
        let at = [&["--path-at", "60"][..], field].concat();
        let obj = &dicom_sections((&vol, &path), (name, "1"), &at)[0];
        (plane_of(obj, 4), dicom_numbers(obj, tags::PIXEL_SPACING))
    };
    let ((centre, normal), spacing) = section("field-default", &[]);
    let ((zoomed, zoomed_normal), zoomed_spacing) = section("field-18", &["--field", "18"]);
    assert_eq!(spacing, [1.5, 1.5]);
    assert_eq!(zoomed_spacing, [2.0, 2.0]);
    assert!((centre - zoomed).length() < 0.01 && normal.dot(zoomed_normal) > 0.9999);
    let args = |field: &str| {
        [
            "render",
            &vol[..],
            "--mode",
            "slice",
            "--path",
            &path[..],
            "--slices",
            "1",
            "--field",
            field,
            "-o",
            "/tmp/never-written",
        ]
        .map(String::from)
    };
    for bad in ["0", "-5", "nan"] {
        let a = args(bad);
        let a: Vec<&str> = a.iter().map(|s| s.as_str()).collect();
        refused(&a, "a cross-section's height must be above 0 mm");
    }
    refused(
        &[
            "render",
            &vol,
            "--mode",
            "slice",
            "--field",
            "18",
            "-o",
            "/tmp/never-written",
        ],
        "--path",
    );
}

/// `--path --slices N`: cross-sections perpendicular to the path, evenly along it. Nearly each
/// is centred on the lumen (a few on the septum seen in the lumen below the graft), and its
/// centre pixel is the middle pixel of its row in the CPR of N rows: the same point of the
/// path. As DICOM each is a reformatted CT image whose plane's normal runs along the path
/// (within 11° of the chord to the next section, 2.6 mm on), the sections a sixtieth of its
/// length apart.
#[test]
fn cross_sections_cut_the_path_square() {
    use dicom_dictionary_std::tags;
    let (vol, path) = (chest(), aorta());
    let n = 60usize;
    let count = n.to_string();
    let mut all = vec![
        "render",
        "--quiet",
        "--device",
        "cpu",
        &vol[..],
        "--mode",
        "slice",
    ];
    all.extend(["--path", &path, "--slices", &count, "--size", "49x49"]);
    let exr_dir = tmp("cpr-sections-exr");
    let dcm_dir = tmp("cpr-sections-dcm");
    for (format, dir) in [("exr", &exr_dir), ("dcm", &dcm_dir)] {
        std::fs::remove_dir_all(dir).ok();
        let mut args = all.clone();
        args.extend(["--format", format, "-o", dir.to_str().unwrap()]);
        let o = run(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let size = format!("7x{n}");
    let cpr = cpr_args(&vol, &path, &["--size", &size]);
    let (cpr, _) = hu(&render_to("cpr-stations.exr", "cpu", &cpr));
    let mut centres = Vec::new();
    let mut normals = Vec::new();
    let mut lumen = 0;
    for i in 0..n {
        let (v, comments) = hu(&exr_dir.join(format!("frame_{i:03}.exr")));
        assert!(comments.contains("pixels 1.5 mm square"), "{comments}");
        let at = |x: usize, y: usize| v[y * 49 + x];
        assert!(
            (at(24, 24) - cpr[i * 7 + 3]).abs() < 0.5,
            "section {i}: {} HU, the CPR {} HU",
            at(24, 24),
            cpr[i * 7 + 3]
        );
        // Where the centre is lumen (not that septum), the lumen across is at least
        // 12 mm (the aorta), not a pinhole.
        if at(24, 24) > 150.0 {
            lumen += 1;
            let run =
                |step: &dyn Fn(usize) -> f32| (1..24).take_while(|&k| step(k) > 150.0).count();
            let width = 1 + run(&|k| at(24 - k, 24)) + run(&|k| at(24 + k, 24));
            assert!(width >= 8, "section {i}: the lumen {width} px wide");
        }
        let obj = dicom_object::open_file(dcm_dir.join(format!("frame_{i:03}.dcm"))).unwrap();
        let nums = |tag| dicom_numbers(&obj, tag);
        if i == 0 {
            // The first, at the top of the descending aorta (running to the feet), seen from
            // below as axial images are: the patient's left to the right, anterior up (its
            // columns run posterior), as the DICOM's patient orientation says.
            let o = dicom_text(&obj, tags::PATIENT_ORIENTATION);
            let (rows, cols) = o.split_once('\\').unwrap();
            assert!(rows.starts_with('L') && cols.starts_with('P'), "{o}");
        }
        let spacing = nums(tags::PIXEL_SPACING)[0];
        assert!((spacing - 1.5).abs() < 1e-6);
        let (centre, normal) = plane_of(&obj, 24);
        centres.push(centre);
        normals.push(normal);
    }
    assert!(
        lumen * 100 >= 90 * n,
        "{lumen} of {n} sections centred on the lumen"
    );
    for i in 0..n - 1 {
        let along = (centres[i + 1] - centres[i]).normalize();
        let (a, b) = (normals[i].dot(along).abs(), normals[i + 1].dot(along).abs());
        assert!(
            a > 0.98 && b > 0.98,
            "sections {i}, {}: normals at {a:.3}, {b:.3} to the path",
            i + 1
        );
        // 154.2 mm / 60 apart.
        let gap = (centres[i + 1] - centres[i]).length();
        assert!(
            (gap - 2.57).abs() < 0.2,
            "sections {i}, {}: {gap} mm apart",
            i + 1
        );
    }
}

/// `--draw-path FILE` draws the path over a camera's view of the volume, where the camera
/// sees it: a vertical line through the chest CT's centre, seen from the front in parallel,
/// is a yellow line down the middle column between the rows of its ends (the pixel size from
/// the EXR of the same view), and nothing else in the picture changes; as DICOM the picture
/// is RGB with Burned In Annotation YES; an EXR is refused.
#[test]
fn draw_path_marks_the_centreline_on_the_reference_view() {
    use dicom_dictionary_std::tags;
    let vol = chest();
    let line = tmp("cpr-line.txt");
    // The volume's centre: origin + 1.5 mm x (dims - 1) / 2, from z 600 to 720 mm.
    let (cx, cy, cz) = (-71.658203 + 89.25, -255.658203 + 93.75, 540.2 + 122.25);
    std::fs::write(&line, format!("{cx} {cy} 720\n{cx} {cy} 600\n")).unwrap();
    let line = line.to_str().unwrap();
    let view = [
        &vol[..],
        "--mode",
        "mip",
        "--parallel",
        "--view",
        "anterior",
        "--size",
        "97x97",
    ];
    let pixel_mm = exr_pixel_mm(&render_to("cpr-line.exr", "cpu", &view)) as f32;
    let plain = image::open(render_to("cpr-line-plain.png", "cpu", &view))
        .unwrap()
        .to_rgb8();
    let drawn = [&view[..], &["--draw-path", line]].concat();
    let marked = image::open(render_to("cpr-line.png", "cpu", &drawn))
        .unwrap()
        .to_rgb8();
    let row = |z: f32| 48.5 - (z - cz as f32) / pixel_mm;
    let (top, bottom) = (row(720.0), row(600.0));
    let mut yellow_rows = 0;
    for (x, y, p) in marked.enumerate_pixels() {
        if p != plain.get_pixel(x, y) {
            assert!(
                (46..=50).contains(&x) && (y as f32) >= top - 3.0 && (y as f32) <= bottom + 3.0,
                "({x}, {y}) changed, the line runs down column 48 from row {top} to {bottom}"
            );
        }
        if x == 48 && p.0 == [255, 214, 0] {
            yellow_rows += 1;
        }
    }
    let want = (bottom - top).floor() as i32;
    assert!(
        yellow_rows >= want,
        "{yellow_rows} yellow rows, want {want}"
    );
    let dcm = dicom_object::open_file(render_to("cpr-line.dcm", "cpu", &drawn)).unwrap();
    assert_eq!(dicom_text(&dcm, tags::PHOTOMETRIC_INTERPRETATION), "RGB");
    assert_eq!(dicom_text(&dcm, tags::BURNED_IN_ANNOTATION), "YES");
    let out = tmp("cpr-line-refused.exr");
    let mut args = vec!["render", "--device", "cpu"];
    args.extend_from_slice(&drawn);
    args.extend_from_slice(&["-o", out.to_str().unwrap()]);
    let o = run(&args);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("--draw-path draws on a PNG"),
        "{}",
        stderr(&o)
    );
}

/// `render --mode dvr --tf examples/angioscopy.toml --path FILE --fly N`: a fly-through down a
/// tube of contrast (300 HU, 10 mm radius, its edge a 1 mm ramp to the 40 HU wall round it),
/// open at the grid's far end, along a path on its axis. From inside, the wall stops every ray
/// but those that leave through the far end: a clear disc about the image's centre, whose
/// radius is the tube's over the distance to the end, in the perspective's terms
/// ((R / D) / tan(fov / 2) · half the height): each frame's camera on the axis at the middle
/// of its part of the path, looking ahead along it (the disc centred, and growing frame by
/// frame as the end nears), on both devices; and spaced as cross-sections are
/// (`--slice-step`, `--path-at`), the cameras where those put them.
#[test]
fn a_fly_through_looks_down_a_tube_from_its_axis() {
    let dims = [48usize, 48, 128];
    let axis = 23.5;
    let data: Vec<f32> = (0..dims[0] * dims[1] * dims[2])
        .map(|n| {
            let (x, y) = ((n % dims[0]) as f64, (n / dims[0] % dims[1]) as f64);
            let r = ((x - axis).powi(2) + (y - axis).powi(2)).sqrt();
            (300.0 - 260.0 * (r - 9.5).clamp(0.0, 1.0)) as f32
        })
        .collect();
    let like = raystream_io::Volume::hounsfield(dims, [1.0; 3], vec![0.0; data.len()]);
    let tube = write_like("fly-tube.mha", &like, &data);
    let path = tmp("fly-axis.txt");
    std::fs::write(&path, format!("{axis} {axis} 10\n{axis} {axis} 90\n")).unwrap();
    let tf = repo().join("examples/angioscopy.toml");
    // The wall: where the ramp crosses 145 HU, half-way through the transfer function's edge.
    let wall = 9.5 + (300.0 - 145.0) / 260.0;
    let (n, side) = (4u32, 160usize);
    let size = format!("{side}x{side}");
    // `--fly` down the tube on `dev` with `more`: each frame's EXR opacity.
    let fly = |name: &str, dev: &str, more: &[&str]| -> Vec<Vec<f32>> {
        let mut args = vec![
            tube.to_str().unwrap(),
            "--mode",
            "dvr",
            "--tf",
            tf.to_str().unwrap(),
            "--path",
            path.to_str().unwrap(),
            "--size",
            &size,
            "--format",
            "exr",
        ];
        args.extend_from_slice(more);
        let dir = render_to(name, dev, &args);
        let frames = more[more.iter().position(|&m| m == "--fly").unwrap() + 1];
        (0..frames.parse::<u32>().unwrap())
            .map(|i| {
                let exr = raystream_cpu::load_exr(&dir.join(format!("frame_{i:03}.exr"))).unwrap();
                exr.channels["A"].as_f32().unwrap().to_vec()
            })
            .collect()
    };
    // The clear disc's radius predicted from the eye's height on the axis (the end at z 127).
    let want = |eye: f64| wall / (127.0 - eye) * side as f64 / 2.0;
    let mut radii = Vec::new();
    for dev in devices() {
        let frames = fly(
            &format!("fly-{dev}"),
            dev,
            &["--fly", &n.to_string(), "--fov", "90"],
        );
        let mut got = Vec::new();
        for (i, alpha) in frames.iter().enumerate() {
            // The clear pixels: their count as a disc's area, and their centroid.
            let clear: Vec<(f64, f64)> = (0..side * side)
                .filter(|&p| alpha[p] < 0.5)
                .map(|p| ((p % side) as f64 + 0.5, (p / side) as f64 + 0.5))
                .collect();
            let radius = (clear.len() as f64 / std::f64::consts::PI).sqrt();
            let c = clear
                .iter()
                .fold((0.0, 0.0), |(x, y), p| (x + p.0, y + p.1));
            let centre = (c.0 / clear.len() as f64, c.1 / clear.len() as f64);
            // The eye at the middle of part i of the path (z 10 to 90).
            let want = want(10.0 + (i as f64 + 0.5) * 80.0 / n as f64);
            eprintln!(
                "{dev} frame {i}: clear disc radius {radius:.2} px (want {want:.2}), centre ({:.2}, {:.2})",
                centre.0, centre.1
            );
            assert!(
                (radius - want).abs() <= 0.04 * want + 0.5,
                "{dev} frame {i}: radius {radius} px, want {want}"
            );
            let mid = side as f64 / 2.0;
            assert!(
                (centre.0 - mid).abs() < 0.5 && (centre.1 - mid).abs() < 0.5,
                "{dev} frame {i}: disc centred at {centre:?}"
            );
            // Everything else is the wall, seen close.
            let wall_px = alpha.iter().filter(|&&a| a > 0.99).count();
            assert!(wall_px + clear.len() * 2 > side * side, "{dev} frame {i}");
            got.push(radius);
        }
        radii.push(got);
    }
    if let [cpu, gpu] = &radii[..] {
        for (c, g) in cpu.iter().zip(gpu) {
            assert!((c - g).abs() < 0.5, "the CPU's disc {c} px, the GPU's {g}");
        }
    }
    // Three cameras 10 mm apart about 40 mm along the path (z 50): at z 40, 50 and 60.
    let frames = fly(
        "fly-spaced",
        "cpu",
        &["--fly", "3", "--slice-step", "10", "--path-at", "40"],
    );
    for (i, (alpha, eye)) in frames.iter().zip([40.0, 50.0, 60.0]).enumerate() {
        let clear = alpha.iter().filter(|&&a| a < 0.5).count();
        let radius = (clear as f64 / std::f64::consts::PI).sqrt();
        let want = want(eye);
        assert!(
            (radius - want).abs() <= 0.04 * want + 0.5,
            "spaced frame {i}: radius {radius} px, want {want}"
        );
    }
}

/// A fly-through through the chest CT's aorta (its lumen enhanced, a stent graft in it), two
/// frames on the CPU: from inside the lumen the wall, pink under examples/angioscopy.toml,
/// surrounds the view (most pixels opaque and redder than they are blue); and what it refuses.
#[test]
fn a_fly_through_the_aorta_sees_its_wall_and_misuse_is_refused() {
    let (vol, path) = (chest(), aorta());
    let tf = repo().join("examples/angioscopy.toml");
    let tf = tf.to_str().unwrap();
    let dir = render_to(
        "fly-aorta",
        "cpu",
        &[
            &vol, "--mode", "dvr", "--tf", tf, "--path", &path, "--fly", "2", "--size", "48x48",
        ],
    );
    wall_round_most_of(&dir, 2);
    let fly = |more: &[&str], want: &str| {
        let mut args = vec!["render", &vol, "--path", &path, "--fly", "2"];
        args.extend_from_slice(more);
        args.extend_from_slice(&["-o", "/tmp/never-written"]);
        refused(&args, want);
    };
    fly(&["--mode", "mip"], "--fly with --mode mip");
    fly(&["--mode", "dvr", "--fov", "180"], "--fov 180");
    fly(
        &["--mode", "dvr", "--orbit", "30,0"],
        "the camera rides the path",
    );
    fly(&["--mode", "dvr", "--slices", "3"], "cannot be used with");
    fly(
        &["--mode", "dvr", "--mark-at", "10"],
        "a fly-through is no CPR",
    );
    fly(&["--mode", "dvr", "--slice-step", "200"], "beyond the path");
    refused(
        &[
            "render",
            &vol,
            "--mode",
            "dvr",
            "--fly",
            "2",
            "-o",
            "/tmp/never-written",
        ],
        "--path",
    );
}

/// A virtual bronchoscopy of the chest CT: `centreline --dark --lumen -950` from
/// examples/chest_airway_points.txt (the trachea, then the left main bronchus) tracks the
/// airway's gas, every control point of it in air (under -850 HU, the lung's parenchyma),
/// from within 5 mm of each point placed, 100 to 120 mm long; `measure --dark` along it gives
/// the trachea's and the left main bronchus's widths; and `render --fly` along it under
/// examples/bronchoscopy.toml sees the airway's wall, pink, round most of each frame.
#[test]
fn a_fly_through_the_airway_follows_a_dark_centreline() {
    let vol = chest();
    let points = repo().join("examples/chest_airway_points.txt");
    let line = tmp("airway.mrk.json");
    dark_centreline(&vol, &points, &line);
    let path = raystream_io::read_curve(&line).unwrap();
    let placed = raystream_io::read_curve(&points).unwrap();
    let ct = raystream_io::load_volume(Path::new(&vol), &Default::default()).unwrap();
    for p in &path {
        let q = ct.world_to_index(*p).round();
        let v = ct.at(q.x as usize, q.y as usize, q.z as usize);
        assert!(v < -850.0, "{p}: {v} HU on the airway's path");
    }
    assert!(path[0].distance(placed[0]) < 5.0 && path[path.len() - 1].distance(placed[1]) < 5.0);
    let length: f64 = path.windows(2).map(|w| w[0].distance(w[1])).sum();
    assert!((100.0..120.0).contains(&length), "{length} mm");
    // Measured along it (`measure --dark`, the gas at or below -500 HU, half-way to the wall):
    // the trachea's lumen 15 to 23 mm across over its first 45 mm, the left main bronchus's
    // 8 to 16 mm over its last 35; the carina between (where the two bronchi part, open).
    // With `--wall`, the airway's wall at half maximum: on the trachea, seen on a quarter to
    // three fifths of the rays (those into the right lung and the fat about it; the rest meet
    // the oesophagus, the aortic arch and the mediastinum's soft tissue), 2.0 to 3.6 mm thick
    // (measured 2.5-3.1: a thin wall blurred on this 1.5 mm grid, overstated as half maximum
    // overstates it), WA 30 to 50 % (measured 37-43), its inner edge's area the lumen's at -500
    // HU within 10 % (half-way between the gas and a peak near 0 HU); on the left main bronchus,
    // none: it runs between contrast-filled vessels and the stent graft, and no ray sees fat or
    // lung past its wall (a stent's wire is no wall). Its `--mask`: the lumen's voxels gas
    // (median under -900 HU), the wall's (label 2) the wall's tissue (median -600 to 100 HU;
    // measured -4), as many as the JSON counts.
    let mask = tmp("airway-mask.nii.gz");
    let m = dark_measure(
        &vol,
        &line,
        ("-500", "10"),
        &["--mask", mask.to_str().unwrap()],
    );
    assert_eq!(m["dark"], true);
    assert_eq!(m["wall_edge"], "half_maximum");
    for s in m["sections"].as_array().unwrap() {
        let arc = s["arc_mm"].as_f64().unwrap();
        let d = s["equivalent_diameter_mm"].as_f64();
        let want = if arc < 45.0 {
            15.0..23.0
        } else if arc > length - 35.0 {
            8.0..16.0
        } else {
            continue;
        };
        assert_eq!(s["lumen"], "closed", "{s}");
        assert!(d.is_some_and(|d| want.contains(&d)), "{s}");
        let w = &s["wall"];
        if arc > 45.0 {
            assert!(w.is_null(), "{s}");
            continue;
        }
        let num = |k: &str| w[k].as_f64().unwrap();
        assert!((0.25..0.6).contains(&num("seen")), "{s}");
        assert!((2.0..3.6).contains(&num("mean_thickness_mm")), "{s}");
        assert!((30.0..50.0).contains(&num("area_percent")), "{s}");
        let lumen = s["area_mm2"].as_f64().unwrap();
        assert!((num("inner_area_mm2") / lumen - 1.0).abs() < 0.1, "{s}");
    }
    // The wall's edges are placed on each ray's own profile, not at the lumen's threshold:
    // with the lumen at -950 HU (its gas alone) the same walls, their thickness within 0.2 mm
    // (measured within 0.11) and their WA within 1 % (within 0.4).
    let gas = dark_measure(&vol, &line, ("-950", "10"), &[]);
    let walls = |m: &serde_json::Value| -> Vec<serde_json::Value> {
        m["sections"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["wall"].clone())
            .collect()
    };
    let (at_500, at_950) = (walls(&m), walls(&gas));
    for (a, b) in at_500.iter().zip(&at_950) {
        assert_eq!(a.is_null(), b.is_null(), "{a} {b}");
        if a.is_null() {
            continue;
        }
        let d = |k: &str| (a[k].as_f64().unwrap() - b[k].as_f64().unwrap()).abs();
        assert!(
            d("mean_thickness_mm") < 0.2 && d("area_percent") < 1.0,
            "{a} {b}"
        );
    }
    let labels = raystream_io::load_volume(&mask, &Default::default()).unwrap();
    let median_hu = |label: f32| {
        let mut v: Vec<f32> = (labels.data.iter().zip(&ct.data))
            .filter(|(l, _)| **l == label)
            .map(|(_, hu)| *hu)
            .collect();
        v.sort_by(f32::total_cmp);
        (v.len(), v[v.len() / 2])
    };
    let ((gas_n, gas), (wall_n, wall)) = (median_hu(1.0), median_hu(2.0));
    assert_eq!(wall_n as u64, m["mask"]["wall_voxels"].as_u64().unwrap());
    assert!(gas_n > wall_n && gas < -900.0, "{gas_n} {gas}");
    assert!((-600.0..100.0).contains(&wall), "{wall_n} {wall}");
    refused(
        &[
            "measure",
            &vol,
            "--path",
            line.to_str().unwrap(),
            "--dark",
            "--wall",
            "-30",
        ],
        "--wall -30 with --dark: an airway's wall is found at half maximum",
    );
    // Drawn on four cross-sections (`render --draw-lumen -500 --draw-dark --draw-wall`, the
    // planes `measure --sections 4` measures): the wall's outline changes pixels on the
    // trachea's two, where a wall is found, and none on the left main bronchus's two.
    let line_str = line.to_str().unwrap();
    let on_sections = |n: &'static str| {
        [
            &vol[..],
            "--mode",
            "slice",
            "--path",
            line_str,
            "--slices",
            n,
        ]
    };
    let sections = |name: &str, wall: &[&str]| {
        let dir = tmp(name);
        std::fs::remove_dir_all(&dir).ok();
        let lumen = ["--size", "96x96", "--draw-lumen", "-500", "--draw-dark"];
        render_to(name, "cpu", &[&on_sections("4")[..], &lumen, wall].concat())
    };
    let (plain, drawn) = (
        sections("airway-lumen", &[]),
        sections("airway-wall", &["--draw-wall"]),
    );
    // By the integral too (`--draw-wall-edge integral`).
    let integral = sections(
        "airway-wall-integral",
        &["--draw-wall", "--draw-wall-edge", "integral"],
    );
    for i in 0..4 {
        let name = format!("frame_{i:03}.png");
        let a = image::open(plain.join(&name)).unwrap().to_rgb8();
        for with_wall in [&drawn, &integral] {
            let b = image::open(with_wall.join(&name)).unwrap().to_rgb8();
            let changed = a.pixels().zip(b.pixels()).filter(|(p, q)| p != q).count();
            assert_eq!(changed > 0, i < 2, "section {i}: {changed} pixels changed");
        }
    }
    let drawn_sections = |draw: &[&str], want: &str| {
        let args = [
            &["render"][..],
            &on_sections("2"),
            &["-o", "/tmp/never-written"],
            draw,
        ]
        .concat();
        refused(&args, want);
    };
    drawn_sections(
        &[
            "--draw-lumen",
            "150",
            "--draw-wall",
            "--draw-wall-edge",
            "integral",
        ],
        "--draw-wall-edge places an airway's wall",
    );
    drawn_sections(
        &["--draw-lumen", "-500", "--draw-dark", "--draw-wall", "-30"],
        "--draw-wall -30 with --draw-dark",
    );
    let tf = repo().join("examples/bronchoscopy.toml");
    let dir = render_to(
        "fly-airway",
        "cpu",
        &[
            &vol,
            "--mode",
            "dvr",
            "--tf",
            tf.to_str().unwrap(),
            "--path",
            line.to_str().unwrap(),
            "--fly",
            "2",
            "--size",
            "48x48",
        ],
    );
    wall_round_most_of(&dir, 2);
}

/// Down the right lung: `centreline --dark --lumen -950` from
/// examples/chest_right_airway_points.txt tracks the trachea, the right main and intermediate
/// bronchi and a lower-lobe bronchus, 150 to 185 mm; `measure --dark --lumen -950 --wall`
/// along it (20 sections) finds the wall on the trachea (WA 35-50 %, measured 39-43) and,
/// inside the lung, where rays see lung all round, on at least 5 of the last 6 sections (50 mm,
/// the lumen's gas 2-5 mm across), 2.0 to 3.6 mm thick (measured 2.4-3.1), seen on 30 % of the
/// rays or more, WA 55 to 85 % (measured 65-80); the small bronchi's WA at least 20 points
/// above the trachea's, as the wall's share of an airway grows as it narrows (and as half
/// maximum overstates a wall the more, the thinner it is against the blur).
#[test]
fn the_airway_wall_takes_more_of_the_smaller_bronchi() {
    let (vol, line) = right_airway("right-airway.mrk.json");
    let m = dark_measure(&vol, &line, ("-950", "20"), &[]);
    let length = m["length_mm"].as_f64().unwrap();
    assert!((150.0..185.0).contains(&length), "{length} mm");
    let wa = |s: &serde_json::Value| s["wall"]["area_percent"].as_f64();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let sections = m["sections"].as_array().unwrap();
    let trachea: Vec<f64> = sections
        .iter()
        .filter(|s| s["arc_mm"].as_f64().unwrap() < 40.0)
        .map(|s| wa(s).unwrap_or_else(|| panic!("no wall on the trachea: {s}")))
        .collect();
    assert!(
        trachea.iter().all(|w| (35.0..50.0).contains(w)),
        "{trachea:?}"
    );
    let distal: Vec<&serde_json::Value> = sections
        .iter()
        .filter(|s| s["arc_mm"].as_f64().unwrap() > length - 50.0)
        .collect();
    let walls: Vec<&serde_json::Value> = distal
        .iter()
        .map(|s| &s["wall"])
        .filter(|w| !w.is_null())
        .collect();
    assert!(
        walls.len() + 1 >= distal.len() && walls.len() >= 5,
        "{distal:?}"
    );
    let num = |w: &serde_json::Value, k: &str| w[k].as_f64().unwrap();
    for w in &walls {
        assert!((2.0..3.6).contains(&num(w, "mean_thickness_mm")), "{w}");
        assert!(num(w, "seen") >= 0.3, "{w}");
        assert!((55.0..85.0).contains(&num(w, "area_percent")), "{w}");
    }
    let small: Vec<f64> = walls.iter().map(|w| num(w, "area_percent")).collect();
    assert!(
        mean(&small) >= mean(&trachea) + 20.0,
        "{small:?} {trachea:?}"
    );
}

/// Down the right lung again (40 sections), the wall by the integral (`--wall-edge integral`)
/// against half maximum: about as thick on the trachea (within 0.8 mm a section, measured
/// 0.25-0.55 thinner), where the wall is thicker than the blur, and at least 0.5 mm thinner on
/// average over the last 50 mm (measured 1.1 mm, 0.8-2.8 mm against 2.2-3.2: at 1.5 mm
/// voxels half maximum reads the blur), none 3 mm thick there; Pi10 from each, over
/// every section with a wall, the integral's at least 1.5 mm below half maximum's (measured
/// 4.5 and 7.3 mm), extrapolated below the smallest bronchi (Pi 13-18 mm), and both lines
/// rising with the airway's size; the text says the same. `--wall-edge` is refused without
/// `--dark --wall`.
#[test]
fn the_integral_reads_the_small_bronchi_walls_thinner_than_half_maximum() {
    let (vol, line) = right_airway("right-airway-integral.mrk.json");
    let half = dark_measure(&vol, &line, ("-950", "40"), &[]);
    let integral = dark_measure(&vol, &line, ("-950", "40"), &["--wall-edge", "integral"]);
    assert_eq!(half["wall_edge"], "half_maximum");
    assert_eq!(integral["wall_edge"], "integral");
    let length = half["length_mm"].as_f64().unwrap();
    let thickness =
        |m: &serde_json::Value, i: usize| m["sections"][i]["wall"]["mean_thickness_mm"].as_f64();
    let (mut distal_half, mut distal_integral) = (Vec::new(), Vec::new());
    for (i, s) in half["sections"].as_array().unwrap().iter().enumerate() {
        let arc = s["arc_mm"].as_f64().unwrap();
        let (Some(h), Some(t)) = (thickness(&half, i), thickness(&integral, i)) else {
            continue;
        };
        if arc < 40.0 {
            assert!(t < h && h - t < 0.8, "section {}: {h} {t}", i + 1);
        } else if arc > length - 50.0 {
            assert!(t < 3.0, "section {}: {t}", i + 1);
            distal_half.push(h);
            distal_integral.push(t);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(distal_half.len() >= 8, "{distal_half:?}");
    assert!(
        mean(&distal_half) - mean(&distal_integral) >= 0.5,
        "{distal_half:?} {distal_integral:?}"
    );
    let walls = |m: &serde_json::Value| {
        m["sections"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| !s["wall"].is_null())
            .count() as u64
    };
    let (p_half, p_integral) = (&half["pi10"], &integral["pi10"]);
    for (m, p) in [(&half, p_half), (&integral, p_integral)] {
        assert_eq!(p["sections"].as_u64().unwrap(), walls(m), "{p}");
        assert_eq!(p["extrapolated"], true, "{p}");
        let lo = p["perimeter_range_mm"][0].as_f64().unwrap();
        assert!(
            (10.0..20.0).contains(&lo) && p["slope"].as_f64().unwrap() > 0.0,
            "{p}"
        );
    }
    let value = |p: &serde_json::Value| p["value_mm"].as_f64().unwrap();
    assert!(
        (3.5..6.0).contains(&value(p_integral)) && value(p_half) - value(p_integral) >= 1.5,
        "{p_half} {p_integral}"
    );
    let o = run(&[
        "measure",
        "--quiet",
        &vol,
        "--path",
        line.to_str().unwrap(),
        "--dark",
        "--lumen",
        "-950",
        "--sections",
        "40",
        "--wall",
        "--wall-edge",
        "integral",
    ]);
    let t = stdout(&o);
    assert!(
        t.contains(&format!("Pi10: {:.2} mm", value(p_integral)))
            && t.contains("extrapolated")
            && t.contains("its thickness from the HU summed across it"),
        "{t}"
    );
    for extra in [&["--wall"][..], &["--dark"]] {
        let args = [
            &[
                "measure",
                &vol[..],
                "--path",
                line.to_str().unwrap(),
                "--wall-edge",
                "integral",
            ][..],
            extra,
        ]
        .concat();
        refused(&args, "--wall-edge places an airway's wall");
    }
}

/// `measure --dark --wall --plot-pi10 FILE.svg` down the right lung: a dot a section with a
/// wall, each where its internal perimeter and √WA (from the JSON's areas) put it on one
/// linear scale per axis (within a pixel); the fitted line solid from the smallest perimeter
/// to the largest, dashed on to 10 mm, and Pi10 ringed there, on the same scales. Without a
/// Pi10 (three sections) it is refused, naming the file and why; and without --dark --wall.
#[test]
fn pi10_plot_draws_the_walls_and_their_line() {
    let (vol, line) = right_airway("right-airway-pi10.mrk.json");
    let svg = tmp("pi10.svg");
    let m = dark_measure(
        &vol,
        &line,
        ("-950", "40"),
        &[
            "--wall-edge",
            "integral",
            "--plot-pi10",
            svg.to_str().unwrap(),
        ],
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    // plotters writes one element a line: <circle cx=".." cy=".." r=".." .. fill="#RRGGBB" ../>
    let attr = |line: &str, k: &str| -> Option<String> {
        let at = line.find(&format!(" {k}=\""))? + k.len() + 3;
        Some(line[at..].split('"').next()?.to_string())
    };
    let num = |line: &str, k: &str| attr(line, k).unwrap().parse::<f64>().unwrap();
    let dots: Vec<[f64; 2]> = text
        .lines()
        .filter(|l| {
            l.trim_start().starts_with("<circle") && attr(l, "fill").as_deref() == Some("#1F77B4")
        })
        .map(|l| [num(l, "cx"), num(l, "cy")])
        .collect();
    let walls: Vec<[f64; 2]> = m["sections"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| {
            let w = &s["wall"];
            let (outer, inner) = (w["area_mm2"].as_f64()?, w["inner_area_mm2"].as_f64()?);
            Some([
                2.0 * (std::f64::consts::PI * inner).sqrt(),
                (outer - inner).sqrt(),
            ])
        })
        .collect();
    let fit = &m["pi10"];
    assert_eq!(dots.len(), walls.len());
    assert_eq!(dots.len() as u64, fit["sections"].as_u64().unwrap());
    // Each axis's scale from the two walls farthest apart on it.
    let scale = |axis: usize| {
        let by = |a: &&[f64; 2], b: &&[f64; 2]| a[axis].total_cmp(&b[axis]);
        let (i, j) = (
            walls
                .iter()
                .enumerate()
                .min_by(|a, b| by(&a.1, &b.1))
                .unwrap()
                .0,
            walls
                .iter()
                .enumerate()
                .max_by(|a, b| by(&a.1, &b.1))
                .unwrap()
                .0,
        );
        let k = (dots[j][axis] - dots[i][axis]) / (walls[j][axis] - walls[i][axis]);
        let (w0, d0) = (walls[i][axis], dots[i][axis]);
        move |v: f64| d0 + k * (v - w0)
    };
    let (px, py) = (scale(0), scale(1));
    for (d, w) in dots.iter().zip(&walls) {
        assert!(
            (d[0] - px(w[0])).abs() < 1.0 && (d[1] - py(w[1])).abs() < 1.0,
            "{d:?} {w:?}"
        );
    }
    let value = |k: &str| fit[k].as_f64().unwrap();
    let on_line = |pi: f64| [px(pi), py(value("intercept_mm") + value("slope") * pi)];
    let [lo, hi] = [0, 1].map(|i| fit["perimeter_range_mm"][i].as_f64().unwrap());
    let red: Vec<Vec<[f64; 2]>> = text
        .lines()
        .filter(|l| {
            l.trim_start().starts_with("<polyline")
                && attr(l, "stroke").as_deref() == Some("#D62728")
        })
        .map(|l| {
            attr(l, "points")
                .unwrap()
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    [x.parse().unwrap(), y.parse().unwrap()]
                })
                .collect()
        })
        .collect();
    let near = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).abs() < 1.5 && (p[1] - q[1]).abs() < 1.5;
    // The solid line (two points, the legend's swatch is a rectangle), and its dashes on to 10.
    assert!(
        red.iter()
            .any(|l| l.len() == 2 && near(l[0], on_line(lo)) && near(l[1], on_line(hi))),
        "{red:?}"
    );
    let dashes: Vec<&[f64; 2]> = red.iter().filter(|l| l.len() == 2).flatten().collect();
    assert!(
        dashes.iter().any(|&&p| near(p, on_line(10.0))),
        "{dashes:?}"
    );
    let ring = text
        .lines()
        .find(|l| {
            l.trim_start().starts_with("<circle") && attr(l, "stroke").as_deref() == Some("#9467BD")
        })
        .unwrap();
    let pi10 = [num(ring, "cx"), num(ring, "cy")];
    assert!(near(pi10, [px(10.0), py(value("value_mm"))]), "{pi10:?}");
    // Refused: no Pi10 from three sections, and without --dark --wall.
    let line_str = line.to_str().unwrap();
    let args = |extra: &[&'static str]| -> Vec<&str> {
        let plot = [
            "measure",
            &vol[..],
            "--path",
            line_str,
            "--plot-pi10",
            "/tmp/never.svg",
        ];
        [&plot[..], extra].concat()
    };
    refused(
        &args(&["--dark", "--lumen", "-950", "--wall", "--sections", "3"]),
        "/tmp/never.svg: --plot-pi10: no Pi10 to draw: ",
    );
    refused(&args(&["--dark"]), "--plot-pi10 draws an airway's walls");
}

/// The chest CT, and the centreline down its right lung from
/// examples/chest_right_airway_points.txt, written to `name`.
fn right_airway(name: &str) -> (String, std::path::PathBuf) {
    let vol = chest();
    let points = repo().join("examples/chest_right_airway_points.txt");
    let line = tmp(name);
    dark_centreline(&vol, &points, &line);
    (vol, line)
}

/// `centreline --dark --lumen -950` of `vol` through `points`, written to `line`.
fn dark_centreline(vol: &str, points: &Path, line: &Path) {
    let o = run(&[
        "centreline",
        "--quiet",
        vol,
        "--path",
        points.to_str().unwrap(),
        "--dark",
        "--lumen",
        "-950",
        "-o",
        line.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `measure --dark --lumen LUMEN --sections N --wall --json` of `vol` along `line`, and
/// `extra`: its JSON.
fn dark_measure(
    vol: &str,
    line: &Path,
    (lumen, sections): (&str, &str),
    extra: &[&str],
) -> serde_json::Value {
    let mut args = vec![
        "measure",
        "--quiet",
        vol,
        "--path",
        line.to_str().unwrap(),
        "--dark",
        "--lumen",
        lumen,
        "--sections",
        sections,
        "--wall",
        "--json",
    ];
    args.extend(extra);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

/// Each of a fly-through's `n` PNG frames in `dir` is mostly a wall seen from inside: over
/// half its pixels pink (red over blue by more than 40 levels).
fn wall_round_most_of(dir: &Path, n: u32) {
    for i in 0..n {
        let img = image::open(dir.join(format!("frame_{i:03}.png")))
            .unwrap()
            .to_rgb8();
        let pink = img
            .pixels()
            .filter(|p| p[0] as u32 > p[2] as u32 + 40)
            .count();
        let all = (img.width() * img.height()) as usize;
        assert!(pink * 2 > all, "frame {i}: {pink} of {all} pixels pink");
    }
}

/// `measure --dark --wall --report FILE.dcm` down the right lung, from the chest CT as a DICOM
/// series: an airway's findings as a DICOM Imaging Measurement Report, coded as an airway's
/// (airway structure, lumen, diameter and area, wall thickness; WA % and Pi10 in raystream's
/// own scheme), each figure the JSON report's of the same run as highdicom reads it back, the
/// segments `Lumen` and `Airway wall` referenced; dciodvfy and dsrdump find no error; `info`
/// reads the same groups.
#[test]
fn an_airways_findings_as_a_dicom_structured_report() {
    use serde_json::json;
    let dir = tmp("chest-series-airway-report");
    let study = chest_series(&dir);
    let series = dir.to_str().unwrap().to_string();
    let points = repo().join("examples/chest_right_airway_points.txt");
    let line = tmp("airway-report-line.txt");
    dark_centreline(&series, &points, &line);
    let (seg, sr) = (tmp("airway-report-seg.dcm"), tmp("airway-report.dcm"));
    let m = dark_measure(
        &series,
        &line,
        ("-950", "80"),
        &[
            "--lesions",
            "1",
            "--mask",
            seg.to_str().unwrap(),
            "--report",
            sr.to_str().unwrap(),
        ],
    );
    let num = |v: &serde_json::Value, key: &str| {
        v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
    };
    let sections = m["sections"].as_array().unwrap();
    let section = |key: &str| &sections[m[key].as_u64().unwrap() as usize - 1];
    let (widest, narrowest) = (section("widest_section"), section("narrowest_section"));
    let value = sr_measurement;
    let (maximum, minimum, mean) = (Some("56851009"), Some("255605001"), Some("373098007"));
    // The thickest wall: the sections' largest mean thickness.
    let thickest = sections
        .iter()
        .filter_map(|s| s["wall"]["mean_thickness_mm"].as_f64())
        .fold(f64::NEG_INFINITY, f64::max);
    let fwhm = Some("RS-FWHM");
    let pi10 = &m["pi10"];
    assert!(pi10.is_object(), "Pi10 down the right lung: {m}");
    let mut along = vec![value("410668003", num(&m, "length_mm"), "mm", None, None)];
    if let Some(d) = m["distance_metric"].as_f64() {
        along.push(value("15690004", d, "1", None, Some("RS-DISTMETRIC")));
    }
    let mut want = vec![
        json!({"template": "1501", "tracking_id": "Airway along the path", "finding": "89187006",
            "sites": [], "measurements": along}),
        json!({"template": "1501", "tracking_id": "Airway lumen", "finding": "89187006",
            "sites": ["91747007"], "measurements": [
            value("81827009", num(widest, "max_diameter_mm"), "mm", maximum, None),
            value("81827009", num(narrowest, "min_diameter_mm"), "mm", minimum, None),
            value("42798000", num(narrowest, "area_mm2"), "mm2", minimum, None),
        ]}),
        json!({"template": "1501", "tracking_id": "Airway wall", "finding": "89187006",
            "sites": [], "measurements": [
            value("122445", num(&m, "wall_mean_thickness_mm"), "mm", mean, fwhm),
            value("122445", thickest, "mm", maximum, fwhm),
            value("RS-WAPCT", num(&m, "wall_area_percent"), "%", mean, fwhm),
            value("RS-PI10", num(pi10, "value_mm"), "mm", None, Some("RS-PI10FIT")),
        ]}),
    ];
    for (k, g) in m["stenoses"].as_array().unwrap().iter().enumerate() {
        let reference = Some("RS-REFERENCE");
        let mut lesion = vec![
            value(
                "408715008",
                num(g, "diameter_stenosis_pct"),
                "%",
                None,
                reference,
            ),
            value(
                "408714007",
                num(g, "area_stenosis_pct"),
                "%",
                None,
                reference,
            ),
            value("81827009", num(g, "min_diameter_mm"), "mm", minimum, None),
            value("42798000", num(g, "area_mm2"), "mm2", None, None),
            value(
                "RS-REFAWDIAM",
                num(&g["reference"], "diameter_mm"),
                "mm",
                None,
                None,
            ),
        ];
        if g["narrowed"].is_object() {
            lesion.push(value(
                "408716009",
                num(&g["narrowed"], "length_mm"),
                "mm",
                None,
                None,
            ));
        }
        want.push(
            json!({"template": "1501", "tracking_id": format!("Stenosis {}", k + 1),
            "finding": "415582006", "sites": ["89187006"], "measurements": lesion}),
        );
    }
    assert_eq!(want.len(), 4, "one graded lesion: {m}");
    want.extend(segment_groups_want(
        &seg,
        &dir,
        &m["mask"],
        ("Airway wall", "89187006"),
    ));
    check_report(&m["report"], &sr, &study.study_uid, &want);
    let o = run(&["info", sr.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let got = info["groups"].as_array().unwrap();
    let ids: Vec<&str> = got
        .iter()
        .map(|g| g["tracking_id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "Airway along the path",
            "Airway lumen",
            "Airway wall",
            "Stenosis 1",
            "Lumen",
            "Airway wall"
        ]
    );
    assert_eq!(iod_errors(&sr), Vec::<String>::new());
    assert_eq!(sr_errors(&sr), Vec::<String>::new());
}
