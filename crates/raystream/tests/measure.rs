//! `raystream measure`: the lumen on cross-sections along a path, on the chest CT of
//! `../shared` (its stented descending aorta, `examples/chest_aorta.mrk.json`), checked against
//! the cross-sections `render --path --slices N` shows of the same planes; the text table and
//! the CSV and the plot, bad input, and `render --draw-lumen`; and `raystream centreline`, tracked from the
//! path's two ends.

mod common;

use common::*;
use raystream_math::DVec3;

/// `measure VOLUME --path PATH ARGS --json`, which must succeed: its JSON.
fn measure(vol: &str, path: &str, args: &[&str]) -> serde_json::Value {
    let mut all = vec!["measure", "--quiet", vol, "--path", path, "--json"];
    all.extend_from_slice(args);
    let o = run(&all);
    assert!(o.status.success(), "{all:?}: {}", stderr(&o));
    serde_json::from_str(&stdout(&o)).expect("JSON")
}

/// The chest CT and `measure --wall --mask`'s label map of its aorta (lumen 1, wall 2), written
/// as `name` under the test folder.
fn chest_and_mask(name: &str) -> (String, std::path::PathBuf) {
    let (vol, path) = (chest(), aorta());
    let mask = tmp(name);
    measure(&vol, &path, &["--wall", "--mask", mask.to_str().unwrap()]);
    (vol, mask)
}

/// `measure VOLUME --path PATH ARGS -o CSV`, which must succeed: its text report.
fn measure_text(vol: &str, path: &str, args: &[&str], csv: &std::path::Path) -> String {
    let mut all = vec!["measure", "--quiet", vol, "--path", path];
    all.extend_from_slice(args);
    all.extend_from_slice(&["-o", csv.to_str().unwrap()]);
    let o = run(&all);
    assert!(o.status.success(), "{all:?}: {}", stderr(&o));
    stdout(&o)
}

fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} in {v}"))
}

fn point(v: &serde_json::Value) -> DVec3 {
    let a: Vec<f64> = v
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    DVec3::new(a[0], a[1], a[2])
}

/// The area (mm²) of the lumen in a cross-section's EXR of HU (`side`² pixels of `pixel` mm,
/// the path at its centre), found the simple way: the pixels at or above `hu` 4-connected to
/// the one nearest the centre within `seed` mm, with what they enclose. None: no lumen there.
fn lumen_area(v: &[f32], side: usize, pixel: f64, hu: f32, seed: f64) -> Option<(f64, bool)> {
    let c = 0.5 * side as f64;
    let dist = |k: usize| {
        let (x, y) = ((k % side) as f64 + 0.5 - c, (k / side) as f64 + 0.5 - c);
        (x * x + y * y).sqrt() * pixel
    };
    let start = (0..side * side)
        .filter(|&k| v[k] >= hu && dist(k) <= seed)
        .min_by(|&a, &b| dist(a).total_cmp(&dist(b)))?;
    let neighbours = |k: usize, diagonal: bool| {
        let (x, y) = ((k % side) as i64, (k / side) as i64);
        let mut out = Vec::new();
        for dy in -1..=1i64 {
            for dx in -1..=1i64 {
                if (dx, dy) == (0, 0) || (!diagonal && dx != 0 && dy != 0) {
                    continue;
                }
                let (a, b) = (x + dx, y + dy);
                if a >= 0 && b >= 0 && a < side as i64 && b < side as i64 {
                    out.push(b as usize * side + a as usize);
                }
            }
        }
        out
    };
    let fill = |from: Vec<usize>, mark: &mut Vec<bool>, ok: &dyn Fn(usize) -> bool, diag| {
        let mut stack = from;
        for &k in &stack {
            mark[k] = true;
        }
        while let Some(k) = stack.pop() {
            for q in neighbours(k, diag) {
                if !mark[q] && ok(q) {
                    mark[q] = true;
                    stack.push(q);
                }
            }
        }
    };
    let mut region = vec![false; side * side];
    fill(vec![start], &mut region, &|k| v[k] >= hu, false);
    let border: Vec<usize> = (0..side * side)
        .filter(|&k| {
            let (x, y) = (k % side, k / side);
            (x == 0 || y == 0 || x == side - 1 || y == side - 1) && !region[k]
        })
        .collect();
    let mut outside = vec![false; side * side];
    fill(border, &mut outside, &|k| !region[k], true);
    let open = (0..side * side).any(|k| {
        let (x, y) = (k % side, k / side);
        region[k] && (x == 0 || y == 0 || x == side - 1 || y == side - 1)
    });
    let count = outside.iter().filter(|&&o| !o).count();
    Some((count as f64 * pixel * pixel, open))
}

/// On each of 40 sections of the aorta, `measure`'s lumen, not opened (sampled at a quarter
/// of the volume's 1.5 mm spacing, the area counted there, the diameters between sub-pixel
/// edge points), against the lumen counted on the EXR of the same plane that `render --path
/// --slices 40` writes at the 1.5 mm spacing, on each device: the areas agree within what
/// 1.5 mm pixels resolve of an edge, and the lumen is closed, open or missing alike, on all
/// but two sections (where a gap or a neck between the lumen and a neighbour is at the edge
/// of what 1.5 mm pixels resolve, one sampling joins them and the other does not). Opened (the
/// default), each lumen is at most the one not opened, its largest diameter too, some branch
/// is cut off (the largest diameter 5 mm shorter), and the descending aorta's lumen below the
/// arch is 12–40 mm across, its equivalent diameter at most its largest calliper diameter.
#[test]
fn the_lumen_measured_is_the_lumen_the_cross_sections_show() {
    let (vol, path) = (chest(), aorta());
    let n = 40usize;
    let count = n.to_string();
    let m = measure(&vol, &path, &["--sections", &count, "--open", "0"]);
    let sections = m["sections"].as_array().unwrap();
    assert_eq!(sections.len(), n);
    assert!(
        (num(&m, "length_mm") - 154.2).abs() < 0.1,
        "{}",
        m["length_mm"]
    );
    assert_eq!(num(&m, "sample_mm"), 0.375);
    // The field of 100 mm at the volume's spacing.
    let (side, pixel) = (67usize, 1.5);
    for dev in devices() {
        let dir = tmp(&format!("measure-sections-{dev}"));
        std::fs::remove_dir_all(&dir).ok();
        let size = format!("{side}x{side}");
        let args = [
            "render", "--quiet", "--device", dev, &vol, "--mode", "slice", "--path", &path,
            "--slices", &count, "--size", &size, "--format", "exr", "-o",
        ];
        let o = run(&[&args[..], &[dir.to_str().unwrap()]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let (mut compared, mut alike, mut agree) = (0, 0, 0);
        for (i, s) in sections.iter().enumerate() {
            let e = raystream_cpu::load_exr(&dir.join(format!("frame_{i:03}.exr"))).unwrap();
            let v = e.channels["Y"].as_f32().unwrap();
            let shown = lumen_area(v, side, pixel, 150.0, 5.0);
            let status = s["lumen"].as_str().unwrap();
            match (status, shown) {
                ("none", None) | ("open", Some((_, true))) => alike += 1,
                ("closed", Some((area, false))) => {
                    alike += 1;
                    let measured = num(s, "area_mm2");
                    // An edge pixel of 1.5 mm is in or out whole: the counts differ by a
                    // tenth of a pixel along the perimeter at most (1 % of the aorta's area
                    // was seen, 3 % allowed).
                    let perimeter = std::f64::consts::PI * num(s, "max_diameter_mm");
                    let within = 0.1 * perimeter * pixel;
                    if (area - measured).abs() <= within {
                        agree += 1;
                    } else {
                        eprintln!(
                            "{dev} section {}: measured {measured:.1} mm², shown {area:.1} mm² (within {within:.1})",
                            i + 1
                        );
                    }
                    compared += 1;
                }
                // Joined to a neighbour at one sampling and not at the other.
                (status, shown) => {
                    eprintln!(
                        "{dev} section {}: measured {status}, shown {shown:?}",
                        i + 1
                    )
                }
            }
        }
        assert!(alike + 2 >= n, "{dev}: {alike} of {n} sections alike");
        assert!(compared >= 30, "{dev}: {compared} closed sections compared");
        assert!(
            agree + 2 >= compared,
            "{dev}: {agree} of {compared} areas agree"
        );
    }
    let raw = sections;
    let m = measure(&vol, &path, &["--sections", &count]);
    let sections = m["sections"].as_array().unwrap();
    // Opening only takes away; on some section it cuts off a branch many mm long.
    let mut cut = 0;
    for (s, r) in sections.iter().zip(raw) {
        if s["lumen"] == "none" {
            continue;
        }
        assert!(num(s, "area_mm2") <= num(r, "area_mm2") + 1e-6, "{s} / {r}");
        // Its edge where a part was cut lies halfway between two samples.
        assert!(
            num(s, "max_diameter_mm") <= num(r, "max_diameter_mm") + 0.2,
            "{s} / {r}"
        );
        if num(r, "max_diameter_mm") - num(s, "max_diameter_mm") > 5.0 {
            cut += 1;
        }
    }
    assert!(cut >= 1, "no branch cut off");
    for s in sections {
        if s["lumen"] != "closed" {
            continue;
        }
        let (eq, max, min) = (
            num(s, "equivalent_diameter_mm"),
            num(s, "max_diameter_mm"),
            num(s, "min_diameter_mm"),
        );
        assert!(min <= max && eq <= max, "{s}");
        // A width across any direction lies between the narrowest and the longest chord.
        let cross = num(s, "cross_diameter_mm");
        assert!(min - 1e-3 <= cross && cross <= max + 1e-3, "{s}");
        let ends = s["max_diameter_ends"].as_array().unwrap();
        assert!(((point(&ends[0]) - point(&ends[1])).length() - max).abs() < 0.01);
        if num(s, "arc_mm") > 20.0 {
            assert!((12.0..=40.0).contains(&eq), "{s}");
        }
    }
}

/// The table as text names the widest and narrowest sections; as CSV a row per section with
/// the same figures as the JSON.
#[test]
fn the_table_as_text_and_csv() {
    let (vol, path) = (chest(), aorta());
    let csv = tmp("measure.csv");
    let text = measure_text(&vol, &path, &["--every", "10"], &csv);
    assert!(
        text.contains("widest: section") && text.contains("narrowest: section"),
        "{text}"
    );
    assert!(text.contains("D max mm"), "{text}");
    let json = measure(&vol, &path, &["--every", "10"]);
    let rows = json["sections"].as_array().unwrap();
    let csv = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), rows.len() + 1);
    let head: Vec<&str> = lines[0].split(',').collect();
    for (line, row) in lines[1..].iter().zip(rows) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), head.len(), "{line}");
        let col = |name: &str| f[head.iter().position(|&h| h == name).unwrap()];
        assert_eq!(col("status"), row["lumen"].as_str().unwrap());
        if row["lumen"] != "none" {
            let v: f64 = col("max_diameter_mm").parse().unwrap();
            assert!((v - num(row, "max_diameter_mm")).abs() < 1e-3);
        }
    }
    // The path's tortuosity: its ends' distance is the file's first and last points',
    // the distance metric the length over it, turning a few degrees a cm (a gently curving
    // aorta below the arch).
    let pts = raystream_io::read_curve(std::path::Path::new(&path)).unwrap();
    let ends = pts[0].distance(pts[pts.len() - 1]);
    assert!(
        (num(&json, "ends_distance_mm") - ends).abs() < 2e-3,
        "{ends}"
    );
    let metric = num(&json, "length_mm") / ends;
    assert!((num(&json, "distance_metric") - metric).abs() < 2e-3);
    assert!((1.0..=20.0).contains(&num(&json, "turning_deg_per_cm")));
    assert!(
        text.contains(&format!(
            "path: {:.1} mm, its ends {ends:.1} mm apart: distance metric (length over ends' distance) {:.3}",
            num(&json, "length_mm"),
            num(&json, "distance_metric")
        )),
        "{text}"
    );
    // Text lines name a section each, between the header and the summary.
    let widest = json["widest_section"].as_u64().unwrap();
    let w = &rows[widest as usize - 1];
    assert!(
        text.contains(&format!(
            "widest: section {widest} at {:.1} mm",
            num(w, "arc_mm")
        )),
        "{text}"
    );
}

/// `measure --angle A,B,C` at three sections' arc lengths: its points are those sections'
/// points on the path, its angle the one between the chords through them (worked out here
/// from the points), in the JSON and the text; three arc lengths, in order, on the path, or
/// an error.
#[test]
fn the_angle_at_a_point_of_the_path() {
    let (vol, path) = (chest(), aorta());
    let table = measure(&vol, &path, &["--every", "2"]);
    let rows = table["sections"].as_array().unwrap();
    let picked = [5, 40, 70].map(|i| &rows[i]);
    let arcs = picked.map(|r| format!("{}", num(r, "arc_mm")));
    let angle = format!("{},{},{}", arcs[0], arcs[1], arcs[2]);
    let m = measure(&vol, &path, &["--every", "2", "--angle", &angle]);
    let a = &m["angle"];
    let pts: Vec<DVec3> = a["points"].as_array().unwrap().iter().map(point).collect();
    for (p, r) in pts.iter().zip(picked) {
        assert!(
            p.distance(point(&r["point"])) < 0.01,
            "{p} for {}",
            r["point"]
        );
    }
    let (u, v) = (pts[1] - pts[0], pts[2] - pts[1]);
    let want = (u.dot(v) / (u.length() * v.length())).acos().to_degrees();
    assert!(
        (num(a, "deviation_deg") - want).abs() < 1e-2,
        "{a} for {want}"
    );
    assert!(want > 5.0, "the aorta bends: {want}");
    let csv = tmp("measure-angle.csv");
    let text = measure_text(&vol, &path, &["--every", "2", "--angle", &angle], &csv);
    let line = format!(
        "angle: {:.1} deg at {:.1} mm, between the chords from {:.1} to",
        num(a, "deviation_deg"),
        num(picked[1], "arc_mm"),
        num(picked[0], "arc_mm")
    );
    assert!(text.contains(&line), "{text}");
    for (bad, want) in [
        ("10,80", "--angle: 2 arc lengths; give three"),
        ("80,10,150", "in order along the path"),
        ("1,2,1e4", "not on the path (0 to 154.2 mm along it)"),
        // A leading minus is a value, not an option (clap took it for a flag before).
        (
            "-1,0,1",
            "point at -1 mm: not on the path (0 to 154.2 mm along it)",
        ),
    ] {
        refused(
            &[
                "measure",
                "-q",
                &vol[..],
                "--path",
                &path,
                "--every",
                "10",
                "--angle",
                bad,
            ],
            want,
        );
    }
}

/// A graded stenosis's figures against its table: the lesion's are its section's; the grades
/// follow from its smallest diameter and area and the reference there; a fitted reference
/// covers `span` mm either side, every closed section there but the lesion either used
/// (between 90 % and 120 % of the line) or left out (narrowed below it, or dilated above);
/// the narrowed segment is the run of closed
/// sections below 90 % of it about the lesion, as long as its sections' shares of the path.
fn check_grade(m: &serde_json::Value, span: f64) {
    let rows = m["sections"].as_array().unwrap();
    let st = &m["stenosis"];
    let lesion = st["lesion_section"].as_u64().unwrap() as usize - 1;
    let l = &rows[lesion];
    assert_eq!(l["lumen"], "closed");
    for k in ["area_mm2", "min_diameter_mm", "equivalent_diameter_mm"] {
        assert_eq!(num(st, k), num(l, k), "{k}");
    }
    let r = &st["reference"];
    let d_ref = num(r, "diameter_mm");
    assert_eq!(num(l, "reference_diameter_mm"), d_ref);
    let grade = 100.0 * (1.0 - num(l, "min_diameter_mm") / d_ref);
    assert!(
        (num(st, "diameter_stenosis_pct") - grade).abs() < 0.01,
        "{st}"
    );
    // SCCT's words for the diameter grade, written out here.
    let pct = num(st, "diameter_stenosis_pct");
    let words = [
        (1.0, "none"),
        (25.0, "minimal"),
        (50.0, "mild"),
        (70.0, "moderate"),
    ];
    let want = words
        .iter()
        .find(|(below, _)| pct < *below)
        .map_or("severe", |w| w.1);
    assert_eq!(st["severity"], want, "{st}");
    let ref_area = std::f64::consts::PI * d_ref * d_ref / 4.0;
    let grade = 100.0 * (1.0 - num(l, "area_mm2") / ref_area);
    assert!((num(st, "area_stenosis_pct") - grade).abs() < 0.01, "{st}");
    let narrowed = |i: usize| {
        num(&rows[i], "equivalent_diameter_mm") < 0.9 * num(&rows[i], "reference_diameter_mm")
    };
    if r["method"] == "fitted" {
        let used: Vec<usize> = r["sections"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize - 1)
            .collect();
        let (mut left_out, mut widened) = (0, 0);
        for (i, row) in rows.iter().enumerate() {
            let far = (num(row, "arc_mm") - num(l, "arc_mm")).abs();
            assert_eq!(
                row.get("reference_diameter_mm").is_some(),
                far <= span + 1e-6
            );
            if row["lumen"] != "closed" || i == lesion || far > span {
                assert!(!used.contains(&i));
                continue;
            }
            let dilated = num(&rows[i], "equivalent_diameter_mm")
                > 1.2 * num(&rows[i], "reference_diameter_mm");
            assert_eq!(
                used.contains(&i),
                !narrowed(i) && !dilated,
                "section {}",
                i + 1
            );
            left_out += usize::from(narrowed(i));
            widened += usize::from(dilated);
        }
        assert_eq!(left_out as u64, r["dropped"].as_u64().unwrap());
        assert_eq!(widened as u64, r["dilated"].as_u64().unwrap());
        let sides = [
            used.iter().any(|&i| i < lesion),
            used.iter().any(|&i| i > lesion),
        ];
        assert_eq!(r["sloped"], sides[0] && sides[1], "{r}");
    }
    let n = &st["narrowed"];
    if narrowed(lesion) {
        let (a, b) = (
            n["from_section"].as_u64().unwrap() as usize - 1,
            n["to_section"].as_u64().unwrap() as usize - 1,
        );
        assert!(a <= lesion && lesion <= b);
        assert!((a..=b).all(|i| rows[i]["lumen"] == "closed" && narrowed(i)));
        for edge in [a.wrapping_sub(1), b + 1] {
            if let Some(e) = rows.get(edge) {
                let defined = e.get("reference_diameter_mm").is_some();
                assert!(e["lumen"] != "closed" || !defined || !narrowed(edge), "{e}");
            }
        }
        let step = num(m, "length_mm") / rows.len() as f64;
        let length = num(n, "length_mm");
        assert!((length - (b - a + 1) as f64 * step).abs() < 0.01, "{n}");
    } else {
        assert!(n.is_null(), "{n}");
    }
}

/// `measure --stenosis` on the chest CT's aorta, a section every 2 mm: by default the lesion
/// is the closed section of least area (at the path's lower end, where the contrast-filled
/// lumen narrows: a reference from above it alone), and placed mid-path a line is fitted
/// through sections on both sides; both agree with their tables (`check_grade`). Placed
/// references: one gives its section's diameter, two the line through theirs. The text and
/// the CSV carry the same grade and reference.
#[test]
fn a_stenosis_is_graded_from_the_table() {
    let (vol, path) = (chest(), aorta());
    let m = measure(&vol, &path, &["--every", "2", "--stenosis"]);
    check_grade(&m, 20.0);
    let rows = m["sections"].as_array().unwrap();
    let st = &m["stenosis"];
    let lesion = st["lesion_section"].as_u64().unwrap() as usize - 1;
    let closed: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i]["lumen"] == "closed")
        .collect();
    let least = *closed
        .iter()
        .min_by(|&&a, &&b| num(&rows[a], "area_mm2").total_cmp(&num(&rows[b], "area_mm2")))
        .unwrap();
    assert_eq!(lesion, least, "{st}");
    assert_eq!(st["reference"]["method"], "fitted");

    // Placed, at a lesion placed mid-path: one reference (distal), then two either side.
    let mid = closed[closed.len() / 2];
    let (p, q) = (
        *closed.iter().rev().find(|&&i| i + 5 <= mid).unwrap(),
        *closed.iter().find(|&&i| i >= mid + 5).unwrap(),
    );
    let at = |i: usize| format!("{}", num(&rows[i], "arc_mm"));
    let fitted = measure(
        &vol,
        &path,
        &["--every", "2", "--lesion", &at(mid), "--span", "30"],
    );
    check_grade(&fitted, 30.0);
    assert_eq!(fitted["stenosis"]["reference"]["sloped"], true);
    let placed = |refs: &str| {
        let m = measure(
            &vol,
            &path,
            &["--every", "2", "--lesion", &at(mid), "--reference", refs],
        );
        assert_eq!(m["stenosis"]["lesion_section"], mid + 1);
        assert_eq!(m["stenosis"]["reference"]["method"], "placed");
        m["stenosis"]["reference"]["diameter_mm"].as_f64().unwrap()
    };
    assert_eq!(placed(&at(q)), num(&rows[q], "equivalent_diameter_mm"));
    let (sp, sq, sm) = (
        num(&rows[p], "arc_mm"),
        num(&rows[q], "arc_mm"),
        num(&rows[mid], "arc_mm"),
    );
    let (dp, dq) = (
        num(&rows[p], "equivalent_diameter_mm"),
        num(&rows[q], "equivalent_diameter_mm"),
    );
    let line = dp + (dq - dp) * (sm - sp) / (sq - sp);
    let two = placed(&format!("{},{}", at(p), at(q)));
    assert!((two - line).abs() < 2e-3, "{two} for {line}");

    // The text report, the CSV and the plot.
    let csv = tmp("measure-stenosis.csv");
    let plot = tmp("measure-stenosis.svg");
    let text = measure_text(
        &vol,
        &path,
        &[
            "--every",
            "2",
            "--stenosis",
            "--plot",
            plot.to_str().unwrap(),
        ],
        &csv,
    );
    // The plot's points are checked against the figures in `profile.rs`; here that the
    // command writes it, with the grade and the reference it reports.
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(svg.starts_with("<svg"));
    for want in [
        format!(
            "lesion at {:.1} mm (its D min ringed): {:.0} % by diameter ({}), {:.0} % by area",
            num(st, "lesion_arc_mm"),
            num(st, "diameter_stenosis_pct"),
            st["severity"].as_str().unwrap(),
            num(st, "area_stenosis_pct")
        ),
        format!(
            "reference (fitted): {:.2} mm at the lesion",
            num(&st["reference"], "diameter_mm")
        ),
    ] {
        assert!(svg.contains(&want), "{want}");
    }
    let want = format!(
        "grade: {:.1} % by diameter (D min against the reference), {:.1} % by area",
        num(st, "diameter_stenosis_pct"),
        num(st, "area_stenosis_pct")
    );
    assert!(text.contains(&want), "{text}");
    assert!(
        text.contains(&format!("stenosis: section {}", lesion + 1)),
        "{text}"
    );
    let csv = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].ends_with(",reference_diameter_mm"));
    for (line, row) in lines[1..].iter().zip(rows) {
        let last = line.rsplit(',').next().unwrap();
        match row.get("reference_diameter_mm") {
            Some(d) => assert!((last.parse::<f64>().unwrap() - d.as_f64().unwrap()).abs() < 1e-3),
            None => assert_eq!(last, ""),
        }
    }
}

/// `measure --lesions N` on the chest CT's aorta: the lesions come the most severe first (by
/// diameter stenosis), `--stenosis`'s (`--lesions 1`'s) among them; each lesion is
/// a closed section outside the others' narrowed segments, its grades following from its own
/// figures and reference; the segments are apart; the text lists them; a placed lesion or
/// reference, or N = 0, is refused.
#[test]
fn tandem_lesions_on_the_aorta() {
    let (vol, path) = (chest(), aorta());
    let one = measure(&vol, &path, &["--every", "2", "--stenosis"]);
    let m = measure(&vol, &path, &["--every", "2", "--lesions", "4"]);
    let rows = m["sections"].as_array().unwrap();
    let all = m["stenoses"].as_array().unwrap();
    assert!(!all.is_empty() && all.len() <= 4);
    assert_eq!(m["stenosis"], all[0]);
    let grades: Vec<f64> = all
        .iter()
        .map(|g| num(g, "diameter_stenosis_pct"))
        .collect();
    assert!(grades.windows(2).all(|w| w[0] >= w[1]), "{grades:?}");
    // `--stenosis` alone grades the most severe lesion, as `--lesions 1`; with a reference
    // placed and no lesion, the section of least area (here the same section).
    let first = measure(&vol, &path, &["--every", "2", "--lesions", "1"]);
    assert_eq!(one["stenosis"], first["stenosis"]);
    let placed = measure(&vol, &path, &["--every", "2", "--reference", "60"]);
    assert_eq!(
        placed["stenosis"]["lesion_section"],
        placed["narrowest_section"]
    );
    assert_eq!(
        one["stenosis"], all[0],
        "the most severe of N is the one alone"
    );
    let segment = |g: &serde_json::Value| {
        let n = &g["narrowed"];
        let at = g["lesion_section"].as_u64().unwrap();
        if n.is_null() {
            (at, at)
        } else {
            (
                n["from_section"].as_u64().unwrap(),
                n["to_section"].as_u64().unwrap(),
            )
        }
    };
    for (k, g) in all.iter().enumerate() {
        let i = g["lesion_section"].as_u64().unwrap() as usize - 1;
        assert_eq!(rows[i]["lumen"], "closed");
        for k in ["area_mm2", "min_diameter_mm", "equivalent_diameter_mm"] {
            assert_eq!(num(g, k), num(&rows[i], k), "{k}");
        }
        let d_ref = num(&g["reference"], "diameter_mm");
        let grade = 100.0 * (1.0 - num(g, "min_diameter_mm") / d_ref);
        assert!(
            (num(g, "diameter_stenosis_pct") - grade).abs() < 0.01,
            "{g}"
        );
        // Each but the section of least area (always a candidate) is narrowed.
        if g["lesion_section"] != m["narrowest_section"] {
            assert!(
                !g["narrowed"].is_null(),
                "a further lesion is narrowed: {g}"
            );
        }
        let (a, b) = segment(g);
        for other in &all[..k] {
            let (c, d) = segment(other);
            assert!(b < c || a > d, "lesions {k} and {other}: segments overlap");
        }
    }
    let csv = tmp("measure-lesions.csv");
    let text = measure_text(&vol, &path, &["--every", "2", "--lesions", "4"], &csv);
    assert!(
        text.contains(&format!(
            "lesions: {} (at most 4), the most severe first by diameter stenosis",
            all.len()
        )),
        "{text}"
    );
    assert_eq!(
        text.matches("\nstenosis: section").count(),
        all.len(),
        "{text}"
    );
    for (bad, want) in [
        (
            vec!["--lesions", "2", "--lesion", "50"],
            "cannot be used with",
        ),
        (
            vec!["--lesions", "2", "--reference", "50"],
            "cannot be used with",
        ),
        (vec!["--lesions", "0"], "0 is not in 1..=100"),
    ] {
        let mut args = vec![
            "measure",
            "-q",
            &vol[..],
            "--path",
            &path[..],
            "--every",
            "10",
        ];
        args.extend(bad);
        refused(&args, want);
    }
}

/// Bad input: clear errors naming what is wrong, a non-zero exit, no panic.
#[test]
fn bad_measurements_are_refused() {
    let (vol, path) = (chest(), aorta());
    let far = tmp("measure-far.txt");
    std::fs::write(&far, "5000 5000 5000\n5010 5000 5000\n").unwrap();
    let far = far.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--path", &path, "--lumen", "NaN"], "must be a number"),
        (
            vec!["--path", &path, "--every", "0"],
            "positive number of mm",
        ),
        (vec!["--path", &path, "--field", "-3"], "a field of -3"),
        (vec!["--path", &path, "--field", "1e6"], "at most 2048"),
        (vec!["--path", far], "outside the volume"),
        (
            vec!["--path", &path, "--lumen", "5000"],
            "no lumen at or above 5000 HU",
        ),
        (
            vec!["--path", "/nonexistent/path.txt"],
            "/nonexistent/path.txt",
        ),
        (
            vec!["--path", &path, "--every", "10", "--lesion", "1e4"],
            "stenosis: the lesion at 10000 mm: not on the path",
        ),
        (
            vec!["--path", &path, "--every", "10", "--reference", "1,2,3"],
            "3 references",
        ),
        (
            vec!["--path", &path, "--every", "10", "--reference", "-5,20"],
            "at -5 mm: not on the path",
        ),
        (
            vec!["--path", &path, "--every", "10", "--span", "0"],
            "a span of 0 mm",
        ),
        (
            vec!["--path", &path, "--every", "10", "--reference", "x"],
            "invalid value 'x'",
        ),
        (
            vec!["--path", &path, "--plot", "profile.jpg"],
            "--plot profile.jpg: the profile is drawn as SVG, PNG or DICOM; name the file .svg, .png or .dcm",
        ),
        (
            vec![
                "--path",
                &path,
                "--every",
                "10",
                "--plot",
                "/nonexistent/p.svg",
            ],
            "cannot write /nonexistent/p.svg",
        ),
    ];
    for (args, want) in cases {
        let mut all = vec!["measure", "--quiet", &vol[..]];
        all.extend(args);
        refused(&all, want);
    }
}

/// `render --path --slices N --draw-lumen HU`: the cross-sections with the lumen's edge and
/// largest diameter drawn over them, and nothing else changed; as DICOM the picture, marked
/// as annotated.
#[test]
fn draw_lumen_marks_the_cross_sections() {
    use dicom_dictionary_std::tags;
    let (vol, path) = (chest(), aorta());
    let base = cpr_args(&vol, &path, &["--slices", "4", "--size", "64x64"]);
    let frames = |name: &str, extra: &[&str]| {
        let dir = tmp(name);
        std::fs::remove_dir_all(&dir).ok();
        render_to(name, "cpu", &[&base[..], extra].concat());
        dir
    };
    let plain = frames("measure-draw-plain", &[]);
    let drawn = frames("measure-draw-lumen", &["--draw-lumen", "150"]);
    for i in 0..4 {
        let name = format!("frame_{i:03}.png");
        let a = image::open(plain.join(&name)).unwrap().to_rgb8();
        let b = image::open(drawn.join(&name)).unwrap().to_rgb8();
        let (mut edge, mut line) = (0, 0);
        for (p, q) in a.pixels().zip(b.pixels()) {
            if p == q {
                continue;
            }
            match q.0 {
                [0, 230, 255] => edge += 1,
                [255, 214, 0] => line += 1,
                [0, 0, 0] => {}
                other => panic!("frame {i}: a pixel changed to {other:?}"),
            }
        }
        // The aorta's edge is tens of pixels round at 1.5 mm; its diameter line too.
        assert!(
            edge >= 20 && line >= 8,
            "frame {i}: {edge} edge, {line} line pixels"
        );
    }
    let dcm = frames(
        "measure-draw-dcm",
        &["--draw-lumen", "150", "--format", "dcm"],
    );
    let obj = dicom_object::open_file(dcm.join("frame_000.dcm")).unwrap();
    assert_eq!(dicom_text(&obj, tags::BURNED_IN_ANNOTATION), "YES");
    assert_eq!(dicom_text(&obj, tags::PHOTOMETRIC_INTERPRETATION), "RGB");
    // An EXR holds values, not drawings.
    for (extra, want) in [
        (
            &["--slices", "2", "--format", "exr", "--draw-lumen", "150"][..],
            "--draw-lumen draws on a PNG",
        ),
        (
            &["--draw-lumen", "150", "--size", "8x8"][..],
            "--draw-lumen draws on a PNG",
        ),
    ] {
        let mut all = vec![
            "render",
            "--quiet",
            "--device",
            "cpu",
            &vol[..],
            "--mode",
            "slice",
        ];
        all.extend(["--path", &path]);
        all.extend(extra);
        let out = tmp(if extra.contains(&"--slices") {
            "measure-draw-bad"
        } else {
            "measure-draw-bad.exr"
        });
        all.extend(["-o", out.to_str().unwrap()]);
        refused(&all, want);
    }
    // Without a path there is no lumen to find.
    refused(
        &["render", &vol[..], "--mode", "slice", "--draw-lumen", "150"],
        "--path",
    );
}

/// `render --path FILE --draw-lumen HU` on the CPR of the chest CT's aorta, straightened from
/// the front and the left and stretched: only cyan pixels change, at most two a row, on at
/// least 85 % of rows; each lies where the HU on the same CPR (its EXR) crosses the threshold
/// within a pixel, for 97 % of them (the rest: where the lumen's 2-D segmentation cut it, at a
/// neck or a branch, or the samplings differ); where the path's pixel is lumen, the two edges
/// are either side of it.
#[test]
fn draw_lumen_marks_the_lumen_on_the_cpr() {
    let (vol, path) = (chest(), aorta());
    let (w, h) = (96usize, 288usize);
    let size = format!("{w}x{h}");
    for (name, extra) in [
        ("front", &["--view", "anterior"][..]),
        ("left", &["--view", "left"][..]),
        ("stretched", &["--cpr", "stretched"][..]),
    ] {
        let base = cpr_args(&vol, &path, &[&["--size", &size][..], extra].concat());
        let shot = |suffix: &str, more: &[&str]| {
            render_to(
                &format!("cpr-lumen-{name}{suffix}"),
                "cpu",
                &[&base[..], more].concat(),
            )
        };
        let plain = image::open(shot(".png", &[])).unwrap().to_rgb8();
        let drawn = image::open(shot("-drawn.png", &["--draw-lumen", "150"]))
            .unwrap()
            .to_rgb8();
        let exr = raystream_cpu::load_exr(&shot(".exr", &[])).unwrap();
        let hu = exr.channels["Y"].as_f32().unwrap();
        let (mut rows, mut edges, mut crossing, mut bracketed, mut centred) = (0, 0, 0, 0, 0);
        for y in 0..h {
            let xs: Vec<usize> = (0..w)
                .filter(|&x| {
                    let (p, q) = (
                        plain.get_pixel(x as u32, y as u32),
                        drawn.get_pixel(x as u32, y as u32),
                    );
                    if p != q {
                        assert_eq!(q.0, [0, 230, 255], "{name}: ({x}, {y}) changed to {q:?}");
                    }
                    p != q
                })
                .collect();
            assert!(xs.len() <= 2, "{name}: row {y}: {xs:?}");
            rows += usize::from(!xs.is_empty());
            let row = &hu[y * w..(y + 1) * w];
            for &x in &xs {
                edges += 1;
                let near = &row[x.saturating_sub(1)..(x + 2).min(w)];
                let lo = near.iter().copied().fold(f32::INFINITY, f32::min);
                let hi = near.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                crossing += usize::from(lo < 150.0 && hi >= 150.0);
            }
            // The path's own pixel (straightened: the middle column).
            if name != "stretched" && row[w / 2] >= 150.0 && xs.len() == 2 {
                centred += 1;
                bracketed += usize::from(xs[0] <= w / 2 && w / 2 <= xs[1]);
            }
        }
        eprintln!(
            "{name}: {rows} of {h} rows drawn, {crossing} of {edges} edges at a crossing, {bracketed} of {centred} about the path"
        );
        assert!(rows * 100 >= 85 * h, "{name}: {rows} of {h} rows");
        assert!(
            crossing * 100 >= 97 * edges,
            "{name}: {crossing} of {edges}"
        );
        assert!(
            bracketed * 100 >= 99 * centred,
            "{name}: {bracketed} of {centred}"
        );
    }
}

/// The middle column's lumen in a CPR's EXR (`w`×`h` HU): the rows whose middle pixel is lumen
/// (≥ 150 HU), and per such row how lopsided the lumen's run through it is: |left − right| over
/// their sum, the runs counted out from the middle pixel.
fn middle_lumen(v: &[f32], w: usize, h: usize) -> (usize, Vec<f64>) {
    let c = w / 2;
    let mut rows = 0;
    let mut lopsided = Vec::new();
    for y in 0..h {
        let row = &v[y * w..(y + 1) * w];
        if row[c] < 150.0 {
            continue;
        }
        rows += 1;
        let left = (0..c).rev().take_while(|&x| row[x] >= 150.0).count() as f64;
        let right = (c + 1..w).take_while(|&x| row[x] >= 150.0).count() as f64;
        lopsided.push((left - right).abs() / (left + right + 1.0));
    }
    (rows, lopsided)
}

/// `centreline` from the two ends of the hand-made aortic path (`examples/chest_aorta.mrk.json`):
/// the path it writes (3D Slicer markups) reads back, starts and ends within the seed radius
/// and a voxel of the points placed, and is as long as the aorta between them; straightened
/// along it, the CPR has lumen down its middle column in 98 % of rows, from the front and the
/// side, and the lumen lies about as evenly about it as about the hand-made path (made from
/// the lumen's centroids on the axial slices, smoothed): its runs to either side differ by
/// under 16 % of the lumen's width on average (0.115 from the front, 0.141 from the side were
/// seen; the hand-made path's 0.072 and 0.151).
#[test]
fn a_centreline_from_two_ends_runs_down_the_middle_of_the_lumen() {
    let (vol, path) = (chest(), aorta());
    let points = raystream_io::read_curve(std::path::Path::new(&path)).unwrap();
    let ends = tmp("centreline-ends.txt");
    let (first, last) = (points[0], *points.last().unwrap());
    std::fs::write(
        &ends,
        format!(
            "{} {} {}\n{} {} {}\n",
            first.x, first.y, first.z, last.x, last.y, last.z
        ),
    )
    .unwrap();
    let out = tmp("centreline.mrk.json");
    let o = run(&[
        "centreline",
        &vol,
        "--path",
        ends.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("a centreline"), "{}", stderr(&o));
    let line = raystream_io::read_curve(&out).unwrap();
    assert!(line[0].distance(first) < 5.0 + 1.5, "{}", line[0]);
    assert!(line.last().unwrap().distance(last) < 5.0 + 1.5);
    let m = measure(&vol, out.to_str().unwrap(), &["--every", "10"]);
    let length = num(&m, "length_mm");
    assert!((140.0..=165.0).contains(&length), "{length} mm");
    let (w, h) = (63usize, 180usize);
    let size = format!("{w}x{h}");
    for view in ["anterior", "left"] {
        let mut lop = Vec::new();
        for (name, p) in [("centreline", out.to_str().unwrap()), ("hand", &path[..])] {
            let args = [
                &vol[..],
                "--mode",
                "slice",
                "--path",
                p,
                "--size",
                &size,
                "--view",
                view,
            ];
            let exr = render_to(&format!("centreline-cpr-{name}-{view}.exr"), "cpu", &args);
            let e = raystream_cpu::load_exr(&exr).unwrap();
            let (rows, lopsided) = middle_lumen(e.channels["Y"].as_f32().unwrap(), w, h);
            let mean = lopsided.iter().sum::<f64>() / lopsided.len().max(1) as f64;
            eprintln!("{view} {name}: {rows} of {h} rows, lopsided {mean:.3}");
            if name == "centreline" {
                assert!(rows * 100 >= 98 * h, "{view}: {rows} of {h} rows lumen");
            }
            lop.push(mean);
        }
        assert!(lop[0] < 0.16 && lop[0] < lop[1] + 0.05, "{view}: {lop:?}");
    }
}

/// Bad input to `centreline`: errors naming the file and what is wrong.
#[test]
fn bad_centrelines_are_refused() {
    let vol = chest();
    let dir = tmp("centreline-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_string_lossy().into_owned()
    };
    // The aorta's top, then a point in the lung (−900 HU about it).
    let lung = write("lung.txt", "19.3 -139.2 763.7\n-80 -100 700\n");
    let one = write("one.txt", "19.3 -139.2 763.7\n");
    let ok = write("ok.txt", "19.3 -139.2 763.7\n25.7 -109.5 624.2\n");
    let out = dir.join("o.txt");
    let out = out.to_str().unwrap();
    for (args, want) in [
        (vec!["--path", &lung[..]], "point 2"),
        (vec!["--path", &one[..]], "two distinct points"),
        (
            vec!["--path", &ok[..], "--lumen", "5000"],
            "no lumen at or above 5000 HU",
        ),
        (vec!["--path", &ok[..], "--step", "0"], "must be positive"),
        (vec!["--path", &ok[..], "--margin", "-1"], "margin of -1"),
    ] {
        let mut all = vec!["centreline", "--quiet", &vol[..], "-o", out];
        all.extend(args);
        let e = refused(&all, want);
        if want != "two distinct points" {
            assert!(e.contains(".txt"), "{e}");
        }
    }
}

/// `render VOLUME --draw-path FILE` over the bones (here the contrast preset's surface, bones
/// and contrast-filled vessels): the picture of the same render with the path's line on it,
/// nothing else changed, the line within the projected path's extent; a mesh without a volume,
/// and an AOV, are refused.
#[test]
fn draw_path_over_the_bones_of_a_volume() {
    let (vol, path) = (chest(), aorta());
    let base = [
        &vol[..],
        "--preset",
        "contrast",
        "--size",
        "60x80",
        "--spp",
        "1",
    ];
    let plain = render_to("draw-bones-plain.png", "cpu", &base);
    let drawn = render_to(
        "draw-bones-path.png",
        "cpu",
        &[&base[..], &["--draw-path", &path]].concat(),
    );
    let (a, b) = (
        image::open(plain).unwrap().to_rgb8(),
        image::open(drawn).unwrap().to_rgb8(),
    );
    let mut line = Vec::new();
    for (x, y, q) in b.enumerate_pixels() {
        let p = a.get_pixel(x, y);
        if p == q {
            continue;
        }
        match q.0 {
            [255, 214, 0] => line.push((x, y)),
            [0, 0, 0] => {}
            other => panic!("({x}, {y}) changed to {other:?}"),
        }
    }
    // 154 mm of aorta in a view about 400 mm high: a line some 30 rows long.
    assert!(line.len() >= 20, "{} line pixels", line.len());
    let rows: Vec<u32> = line.iter().map(|p| p.1).collect();
    let (top, bottom) = (*rows.iter().min().unwrap(), *rows.iter().max().unwrap());
    assert!(bottom - top >= 15, "rows {top}..{bottom}");
    // Left of the image's middle is the patient's right: the descending aorta lies left of
    // the spine, on the image's right half.
    let mean_x = line.iter().map(|p| p.0 as f64).sum::<f64>() / line.len() as f64;
    assert!(mean_x > 30.0, "the line at x = {mean_x}");
    let out = tmp("draw-bad.png");
    let out = out.to_str().unwrap();
    let bunny = mesh("utah_teapot.obj");
    for (args, want) in [
        (
            vec![&bunny[..], "--draw-path", &path],
            "a path through a CT volume",
        ),
        (
            vec![&vol[..], "--aov", "depth", "--draw-path", &path],
            "not an AOV's values",
        ),
    ] {
        let mut all = vec!["render", "--quiet", "--device", "cpu", "-o", out];
        all.extend(args);
        refused(&all, want);
    }
}

/// `measure --plot` as pixels: a PNG of the plot, and a DICOM Secondary Capture of the same
/// pixels (but for the title, which in DICOM names no files) whose description gives the
/// options without the files' names, with the text marked as burnt in. That the pixels are
/// the SVG's plot is `profile.rs`'s test.
#[test]
fn the_profile_as_png_and_dicom() {
    use dicom_dictionary_std::tags;
    use dicom_pixeldata::PixelDecoder;
    let (vol, path) = (chest(), aorta());
    let plot = |name: &str| {
        let out = tmp(name);
        let o = run(&[
            "measure",
            "-q",
            &vol,
            "--path",
            &path,
            "--every",
            "4",
            "--stenosis",
            "--plot",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    };
    let png = image::open(plot("profile-pixels.png")).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (1000, 560));
    let obj = dicom_object::open_file(plot("profile-pixels.dcm")).unwrap();
    assert_eq!(iod_errors(&tmp("profile-pixels.dcm")), Vec::<String>::new());
    let text = |tag| dicom_text(&obj, tag);
    assert_eq!(text(tags::SOP_CLASS_UID), "1.2.840.10008.5.1.4.1.1.7");
    assert_eq!(text(tags::BURNED_IN_ANNOTATION), "YES");
    assert_eq!(
        text(tags::SERIES_DESCRIPTION),
        "raystream measure -q --path FILE --every 4 --stenosis"
    );
    assert_eq!(
        (text(tags::ROWS), text(tags::COLUMNS)),
        ("560".into(), "1000".into())
    );
    let got: Vec<u8> = obj.decode_pixel_data().unwrap().to_vec().unwrap();
    let want = png.as_raw();
    assert_eq!(got.len(), want.len());
    let row = 3 * 1000;
    // The title's band differs (the PNG's names the files), the rest is the same.
    assert_ne!(got[..40 * row], want[..40 * row]);
    assert_eq!(got[40 * row..], want[40 * row..]);
}

/// `measure --wall` on the chest CT's aorta: the outer wall holds the lumen, about the stent
/// graft a few mm wider than its lumen, and below it, where the false lumen of a dissection is
/// unenhanced and the lumen narrows to 12 mm, the aorta's own 29-34 mm. Checked against the
/// cross-sections `render --path --slices N --format dcm` writes of the same planes, read
/// back with their geometry: inside each wall's circle there is no fat, and beyond it there
/// is where its edge was seen.
/// `measure --mask`: the lumen (1) and the wall beyond it (2) labelled on the chest CT's own
/// grid, as NIfTI that both raystream and SimpleITK read on that grid; the labels' volumes
/// agree with the sections' (area × spacing), the lumen's voxels are contrast and the wall's
/// are soft tissue. As a 3D Slicer segmentation, the same labels, named and coloured, as
/// raystream and slicerio read it.
#[test]
fn the_mask_on_the_ct_grid() {
    let (vol, path) = (chest(), aorta());
    let out = tmp("measure-mask.nii.gz");
    std::fs::remove_file(&out).ok();
    let file = out.to_str().unwrap();
    let m = measure(&vol, &path, &["--wall", "--mask", file]);
    let k = &m["mask"];
    assert_eq!(k["file"], file);
    let select = raystream_io::VolumeSelect::default();
    let ct = raystream_io::load_volume(std::path::Path::new(&vol), &select).unwrap();
    let labels = raystream_io::load_volume(&out, &select).unwrap();
    assert_eq!(labels.dims, ct.dims);
    for i in 0..3 {
        assert!((labels.spacing[i] - ct.spacing[i]).abs() < 1e-5);
        assert!((labels.origin[i] - ct.origin[i]).abs() < 1e-3);
        for j in 0..3 {
            assert!((labels.direction[i][j] - ct.direction[i][j]).abs() < 1e-5);
        }
    }
    // The voxels of each label: as the JSON counts them, and their HU.
    let of = |l: f32| -> Vec<f32> {
        let mut hu: Vec<f32> = (0..ct.data.len())
            .filter(|&v| labels.data[v] == l)
            .map(|v| ct.data[v])
            .collect();
        hu.sort_by(f32::total_cmp);
        hu
    };
    let (lumen, wall) = (of(1.0), of(2.0));
    assert_eq!(lumen.len() as f64, num(k, "lumen_voxels"));
    assert_eq!(wall.len() as f64, num(k, "wall_voxels"));
    assert!(
        labels
            .data
            .iter()
            .all(|&l| l == 0.0 || l == 1.0 || l == 2.0)
    );
    let pct = |v: &[f32], p: f64| v[((v.len() - 1) as f64 * p) as usize];
    // Contrast in the lumen (its edge voxels part fat or wall); the wall's soft tissue and
    // unenhanced blood, a little contrast and fat where it meets them.
    assert!(
        pct(&lumen, 0.05) > 100.0 && pct(&lumen, 0.5) > 250.0,
        "{}",
        pct(&lumen, 0.05)
    );
    assert!(
        (-30.0..150.0).contains(&pct(&wall, 0.5)),
        "{}",
        pct(&wall, 0.5)
    );
    assert!(pct(&wall, 0.05) > -60.0, "{}", pct(&wall, 0.05));
    // Their volumes against the sections': the closed lumens', and the walls' beyond them.
    let sections = m["sections"].as_array().unwrap();
    let step = num(&m, "length_mm") / sections.len() as f64;
    let lumen_ml: f64 = sections
        .iter()
        .filter(|s| s["lumen"] == "closed")
        .map(|s| num(s, "area_mm2") * step / 1000.0)
        .sum();
    let wall_ml: f64 = sections
        .iter()
        .filter(|s| !s["wall"].is_null())
        .map(|s| (num(&s["wall"], "area_mm2") - num(s, "area_mm2")) * step / 1000.0)
        .sum();
    let voxel_ml = ct.spacing.iter().product::<f64>() / 1000.0;
    assert!((num(k, "lumen_ml") - lumen.len() as f64 * voxel_ml).abs() < 1e-3);
    assert!(
        (num(k, "lumen_ml") - lumen_ml).abs() < 0.04 * lumen_ml,
        "{k}: the sections' lumens {lumen_ml} ml"
    );
    assert!(
        (num(k, "wall_ml") - wall_ml).abs() < 0.04 * wall_ml,
        "{k}: the sections' walls {wall_ml} ml"
    );
    // SimpleITK reads it on the CT's grid, with the same labels.
    if let Some(py) = python() {
        let script = "import sys, json, SimpleITK as s, numpy as n\n\
            a, b = s.ReadImage(sys.argv[1]), s.ReadImage(sys.argv[2])\n\
            m = s.GetArrayViewFromImage(b)\n\
            print(json.dumps([a.GetSize() == b.GetSize(),\
            bool(n.allclose(a.GetOrigin(), b.GetOrigin(), atol=1e-3)),\
            bool(n.allclose(a.GetSpacing(), b.GetSpacing(), atol=1e-5)),\
            bool(n.allclose(a.GetDirection(), b.GetDirection(), atol=1e-5)),\
            int((m == 1).sum()), int((m == 2).sum())]))";
        let o = std::process::Command::new(py)
            .args(["-c", script, &vol, file])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let got: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(
            got,
            serde_json::json!([true, true, true, true, lumen.len(), wall.len()])
        );
    }
    // As a 3D Slicer segmentation: the same voxels on the same grid, the segments named and
    // coloured; slicerio (Slicer's own reader) finds the same, with their label values, their
    // DICOM codes and the CT's voxel-to-LPS matrix.
    let seg = tmp("measure-mask.seg.nrrd");
    let seg_file = seg.to_str().unwrap();
    let t = measure_text(
        &vol,
        &path,
        &["--wall", "--mask", seg_file],
        &tmp("measure-mask-seg.csv"),
    );
    assert!(
        t.contains(&format!(
            "mask: {seg_file} (a 3D Slicer segmentation): label 1 the lumen on {} voxels",
            lumen.len()
        )),
        "{t}"
    );
    let back = raystream_io::load_volume(&seg, &select).unwrap();
    assert_eq!(
        (back.dims, back.spacing, back.origin),
        (labels.dims, labels.spacing, labels.origin)
    );
    assert!(back.data == labels.data);
    let named: Vec<_> = back
        .segments
        .iter()
        .map(|k| {
            let kind = k.terms.kind.as_ref().map(|c| c.value.as_str());
            (k.number, k.label.as_str(), k.colour, kind)
        })
        .collect();
    // Each coded as written (its TerminologyEntry read back).
    assert_eq!(
        named,
        [
            (1, "Lumen", Some([0, 255, 255]), Some("91747007")),
            (
                2,
                "Wall and thrombus",
                Some([255, 0, 255]),
                Some("59820001")
            )
        ]
    );
    if let Some(py) = python_with("slicerio") {
        let script = "import sys, json, numpy as n, slicerio\n\
            s = slicerio.read_segmentation(sys.argv[1])\n\
            print(json.dumps({'ijk_to_lps': s['ijkToLPS'].tolist(), 'segments': [\
            {'name': g['name'], 'label': g['labelValue'], 'colour': [round(c * 255) for c in g['color']],\
            'type': g['terminology']['type'], 'voxels': int(slicerio.segment_mask(s, g['id']).sum())}\
            for g in s['segments']]}))";
        let o = std::process::Command::new(py)
            .args(["-c", script, seg_file])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let got: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(
            got["segments"],
            serde_json::json!([
                {"name": "Lumen", "label": 1, "colour": [0, 255, 255],
                 "type": ["SCT", "91747007", "Lumen"], "voxels": lumen.len()},
                {"name": "Wall and thrombus", "label": 2, "colour": [255, 0, 255],
                 "type": ["SCT", "59820001", "Blood vessel"], "voxels": wall.len()},
            ])
        );
        let m: Vec<Vec<f64>> = serde_json::from_value(got["ijk_to_lps"].clone()).unwrap();
        for r in 0..3 {
            assert!((m[r][3] - ct.origin[r]).abs() < 1e-9);
            for c in 0..3 {
                let want = ct.direction[r][c] * ct.spacing[c];
                assert!((m[r][c] - want).abs() < 1e-9, "{m:?}");
            }
        }
    }

    // The text says what was written; without --wall, the lumen alone, the same voxels.
    let t = measure_text(&vol, &path, &["--mask", file], &tmp("measure-mask.csv"));
    assert!(
        t.contains(&format!(
            "mask: {file} (a NIfTI label map): label 1 the lumen on {} voxels",
            lumen.len()
        )) && !t.contains("2 the outer wall"),
        "{t}"
    );
    let plain = raystream_io::load_volume(&out, &select).unwrap();
    assert!(plain.data.iter().all(|&l| l != 2.0));
    assert_eq!(
        plain.data.iter().filter(|&&l| l == 1.0).count(),
        lumen.len()
    );
    // Only NIfTI, and where it can be written.
    refused(
        &["measure", &vol, "--path", &path, "--mask", "m.nrrd"],
        "m.nrrd: --mask writes a NIfTI label map",
    );
    let nowhere = tmp("no-such-folder/m.nii.gz");
    let nowhere = nowhere.to_str().unwrap();
    refused(
        &[
            "measure", "--quiet", &vol, "--path", &path, "--mask", nowhere,
        ],
        &format!("{nowhere}: No such file or directory"),
    );
}

/// `--mask FILE.dcm` on a DICOM series: a DICOM Segmentation of that series, with the same
/// labels as the NIfTI label map of the same CT. The chest CT is written as a DICOM series
/// first; the Segmentation is read back with dicom-rs frame by frame (each frame placed by its
/// position and referencing the series' image at that position), by highdicom, and checked by
/// dicom3tools' `dciodvfy` against the standard's IOD (each where installed; under CI all).
/// A CT that a Segmentation cannot reference is refused before any work.
#[test]
fn the_mask_as_a_dicom_segmentation_of_the_series() {
    use dicom_dictionary_std::tags;
    let dir = tmp("chest-series");
    let study = chest_series(&dir);
    let series = dir.to_str().unwrap().to_string();
    let path = aorta();
    let (seg, nii) = (tmp("measure-seg.dcm"), tmp("measure-seg.nii.gz"));
    let seg_file = seg.to_str().unwrap();
    let m = measure(&series, &path, &["--wall", "--mask", seg_file]);
    let n = measure(
        &chest(),
        &path,
        &["--wall", "--mask", nii.to_str().unwrap()],
    );
    let (k, want) = (&m["mask"], &n["mask"]);
    assert_eq!(k["format"], "dicom-seg");
    assert_eq!(want["format"], "nifti");
    for key in ["lumen_voxels", "wall_voxels", "sections", "closed_sections"] {
        assert_eq!(k[key], want[key], "{key}");
    }
    // The labels the NIfTI map holds, and each series file's SOP instance by slice.
    let select = raystream_io::VolumeSelect::default();
    let labels = raystream_io::load_volume(&nii, &select).unwrap();
    let [nx, ny, nz] = labels.dims;
    let mut instance = vec![String::new(); nz];
    for e in std::fs::read_dir(&dir).unwrap() {
        let obj = dicom_object::open_file(e.unwrap().path()).unwrap();
        let z: Vec<f64> = obj
            .element(tags::IMAGE_POSITION_PATIENT)
            .unwrap()
            .to_multi_float64()
            .unwrap();
        let slice = ((z[2] - labels.origin[2]) / labels.spacing[2]).round() as usize;
        instance[slice] = dicom_text(&obj, tags::SOP_INSTANCE_UID);
    }
    // The Segmentation, frame by frame, back onto the grid.
    let obj = dicom_object::open_file(&seg).unwrap();
    let text = |tag| dicom_text(&obj, tag);
    // Deflated: its bit frames, mostly zeros, take a twentieth of their room.
    assert_eq!(obj.meta().transfer_syntax(), "1.2.840.10008.1.2.1.99");
    let frame_bytes =
        (nx * ny).div_ceil(8) as u64 * text(tags::NUMBER_OF_FRAMES).parse::<u64>().unwrap();
    let size = std::fs::metadata(&seg).unwrap().len();
    assert!(
        size * 10 < frame_bytes,
        "{size} bytes for {frame_bytes} of frames"
    );
    assert_eq!(text(tags::SOP_CLASS_UID), raystream_io::SEGMENTATION);
    assert_eq!(text(tags::MODALITY), "SEG");
    assert_eq!(text(tags::STUDY_INSTANCE_UID), study.study_uid);
    assert_eq!(
        text(tags::FRAME_OF_REFERENCE_UID),
        study.frame_of_reference_uid
    );
    assert_eq!(text(tags::PATIENT_NAME), "MÜLLER^JÖRG");
    assert_eq!(text(tags::ACCESSION_NUMBER), "ACC42");
    assert_eq!(text(tags::SEGMENTATION_TYPE), "BINARY");
    let segments = obj
        .element(tags::SEGMENT_SEQUENCE)
        .unwrap()
        .items()
        .unwrap();
    let kinds: Vec<(String, String)> = segments
        .iter()
        .map(|s| {
            let t = |tag| s.element(tag).unwrap().to_str().unwrap().trim().to_string();
            let code = s
                .element(tags::SEGMENTED_PROPERTY_TYPE_CODE_SEQUENCE)
                .unwrap()
                .items()
                .unwrap()[0]
                .element(tags::CODE_VALUE)
                .unwrap()
                .to_str()
                .unwrap()
                .trim()
                .to_string();
            (t(tags::SEGMENT_LABEL), code)
        })
        .collect();
    assert_eq!(
        kinds,
        [
            ("Lumen".to_string(), "91747007".to_string()),
            ("Wall and thrombus".to_string(), "59820001".to_string())
        ]
    );
    let frames = obj
        .element(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE)
        .unwrap()
        .items()
        .unwrap();
    assert_eq!(frames.len() as f64, num(k, "frames"));
    assert_eq!(
        obj.element(tags::NUMBER_OF_FRAMES)
            .unwrap()
            .to_int::<usize>()
            .unwrap(),
        frames.len()
    );
    let (rows, cols) = (
        obj.element(tags::ROWS).unwrap().to_int::<usize>().unwrap(),
        obj.element(tags::COLUMNS)
            .unwrap()
            .to_int::<usize>()
            .unwrap(),
    );
    assert_eq!((rows, cols), (ny, nx));
    let bits = obj.element(tags::PIXEL_DATA).unwrap().to_bytes().unwrap();
    assert_eq!(
        bits.len(),
        (frames.len() * nx * ny).div_ceil(8).next_multiple_of(2)
    );
    let first = |item: &dicom_object::InMemDicomObject, group, tag| {
        item.element(group).unwrap().items().unwrap()[0]
            .element(tag)
            .unwrap()
            .clone()
    };
    let mut got = vec![0u8; nx * ny * nz];
    for (f, item) in frames.iter().enumerate() {
        let segment = first(
            item,
            tags::SEGMENT_IDENTIFICATION_SEQUENCE,
            tags::REFERENCED_SEGMENT_NUMBER,
        )
        .to_int::<u8>()
        .unwrap();
        let p = first(
            item,
            tags::PLANE_POSITION_SEQUENCE,
            tags::IMAGE_POSITION_PATIENT,
        )
        .to_multi_float64()
        .unwrap();
        let z = (p[2] - labels.origin[2]) / labels.spacing[2];
        assert!((z - z.round()).abs() < 1e-3 && (p[0] - labels.origin[0]).abs() < 1e-3);
        let slice = z.round() as usize;
        let source = first(
            item,
            tags::DERIVATION_IMAGE_SEQUENCE,
            tags::SOURCE_IMAGE_SEQUENCE,
        );
        let source = &source.items().unwrap()[0];
        let uid = source
            .element(tags::REFERENCED_SOP_INSTANCE_UID)
            .unwrap()
            .to_str()
            .unwrap();
        assert_eq!(
            uid.trim_end_matches('\0'),
            instance[slice],
            "frame {}",
            f + 1
        );
        for p in 0..nx * ny {
            let b = f * nx * ny + p;
            if bits[b / 8] >> (b % 8) & 1 == 1 {
                let v = &mut got[slice * nx * ny + p];
                assert_eq!(*v, 0, "two segments on one voxel");
                *v = segment;
            }
        }
    }
    let want: Vec<u8> = labels.data.iter().map(|&l| l as u8).collect();
    let differ = got.iter().zip(&want).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "voxels labelled otherwise than the NIfTI map");
    // raystream reads a Segmentation back as a label volume on its frames' grid: the NIfTI
    // map's labels where they lie. `written_by`: who wrote it.
    let reads_as_the_map = |file: &std::path::Path, written_by: &str| {
        let v = raystream_io::load_volume(file, &select).unwrap();
        let s = v.series.as_ref().unwrap();
        assert_eq!(s.modality, "SEG", "{written_by}");
        let named = v.segments.iter().filter(|k| k.number > 0).count();
        assert_eq!(named, 2, "{written_by}");
        // What each segment is: SNOMED CT's Lumen and Blood vessel, Anatomical Structures (a
        // label map's segment 0 is its background).
        for (k, want) in v
            .segments
            .iter()
            .filter(|k| k.number > 0)
            .zip([("91747007", "Lumen"), ("59820001", "Blood vessel")])
        {
            let code = |c: &Option<raystream_io::ReadCode>| {
                c.as_ref()
                    .map(|c| (c.scheme.clone(), c.value.clone(), c.meaning.clone()))
            };
            let sct = |v: &str, m: &str| Some(("SCT".to_string(), v.to_string(), m.to_string()));
            assert_eq!(code(&k.terms.kind), sct(want.0, want.1), "{written_by}");
            assert_eq!(
                code(&k.terms.category),
                sct("123037004", "Anatomical Structure"),
                "{written_by}"
            );
            // highdicom's lumen lies in the right common iliac artery; raystream names no
            // region.
            let (region, side) = match (written_by.starts_with("highdicom"), k.number) {
                (true, 1) => (
                    sct("73634005", "Common iliac artery"),
                    sct("24028007", "Right"),
                ),
                _ => (None, None),
            };
            assert_eq!(code(&k.terms.region), region, "{written_by}");
            assert_eq!(code(&k.terms.region_modifier), side, "{written_by}");
        }
        assert_eq!(v.direction, labels.direction, "{written_by}");
        assert_eq!(v.spacing, labels.spacing, "{written_by}");
        let dz = (v.origin[2] - labels.origin[2]) / labels.spacing[2];
        assert!((dz - dz.round()).abs() < 1e-3 && v.origin[..2] == labels.origin[..2]);
        let per = nx * ny;
        let at = dz.round() as usize * per;
        assert_eq!(v.dims[..2], labels.dims[..2]);
        let differ = (0..v.data.len())
            .filter(|&q| v.data[q] != labels.data[at + q])
            .count();
        assert_eq!(differ, 0, "{written_by}");
        let held = |d: &[f32]| d.iter().filter(|&&l| l != 0.0).count();
        assert_eq!(
            held(&v.data),
            held(&labels.data),
            "{written_by}: labels beyond its grid"
        );
    };
    reads_as_the_map(&seg, "raystream");
    // `info` lists each label's voxels and volume, with the Segmentation's names for them;
    // a CT has no labels.
    let info = |file: &str| -> serde_json::Value {
        let o = run(&["info", file, "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_str(&stdout(&o)).unwrap()
    };
    for (file, names) in [
        (seg_file, ["Lumen", "Wall and thrombus"]),
        (nii.to_str().unwrap(), ["", ""]),
    ] {
        let got = info(file)["labels"].clone();
        let want = serde_json::json!([
            {"value": 1, "voxels": k["lumen_voxels"], "ml": k["lumen_ml"], "name": names[0]},
            {"value": 2, "voxels": k["wall_voxels"], "ml": k["wall_ml"], "name": names[1]},
        ]);
        assert_eq!(got, want, "{file}");
    }
    assert!(info(&chest())["labels"].is_null());
    // Beside the series' images it is skipped, named, and the CT read as before.
    std::fs::copy(&seg, dir.join("seg.dcm")).unwrap();
    let beside = raystream_io::load_volume(&dir, &select).unwrap();
    assert_eq!(beside.dims, labels.dims);
    assert!(
        beside
            .warnings
            .iter()
            .any(|w| w.contains("seg.dcm") && w.contains("a DICOM Segmentation, not an image")),
        "{:?}",
        beside.warnings
    );
    std::fs::remove_file(dir.join("seg.dcm")).unwrap();
    // highdicom parses it as a Segmentation of the series, with the same voxels a segment.
    if let Some(py) = python_with("highdicom") {
        let script = "import sys, json, highdicom as hd, numpy as n\n\
            s = hd.seg.segread(sys.argv[1])\n\
            ids = [int(f.SegmentIdentificationSequence[0].ReferencedSegmentNumber) for f in s.PerFrameFunctionalGroupsSequence]\n\
            a = s.pixel_array.reshape(len(ids), -1).sum(axis=1)\n\
            refs = s.get_source_image_uids()\n\
            print(json.dumps([[int(a[[i == g for i in ids]].sum()) for g in (1, 2)], len(refs), str(s.segmentation_type.value)]))";
        let o = std::process::Command::new(&py)
            .args(["-c", script, seg_file])
            .output()
            .unwrap();
        assert!(o.status.success(), "highdicom: {}", stderr(&o));
        let got: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
        assert_eq!(
            got,
            serde_json::json!([[k["lumen_voxels"], k["wall_voxels"]], nz, "BINARY"])
        );
        // And highdicom writes one of the NIfTI map on the series, which raystream reads.
        // As binary segments, and as a label map (DICOM 2024's, a frame a slice).
        // Native (the data set deflated too), and compressed as highdicom compresses each
        // type (RLE, JPEG-LS and JPEG 2000 frames, decoded by the CT reader's codecs).
        for (kind, ts) in [
            ("BINARY", "native"),
            ("BINARY", "deflated"),
            ("BINARY", "j2k"),
            ("FRACTIONAL", "rle"),
            ("LABELMAP", "native"),
            ("LABELMAP", "rle"),
            ("LABELMAP", "jpegls"),
            ("LABELMAP", "j2k"),
        ] {
            let theirs = tmp(&format!("highdicom-seg-{kind}-{ts}.dcm"));
            let o = std::process::Command::new(&py)
                .arg(repo().join("crates/raystream/tests/highdicom_seg.py"))
                .args([
                    &series,
                    nii.to_str().unwrap(),
                    theirs.to_str().unwrap(),
                    kind,
                    ts,
                ])
                .output()
                .unwrap();
            assert!(o.status.success(), "highdicom: {}", stderr(&o));
            reads_as_the_map(&theirs, &format!("highdicom {kind} {ts}"));
        }
        // Damaged compressed ones: more frames claimed than fragments held, and the file cut
        // short, are errors naming it.
        let rle = tmp("highdicom-seg-LABELMAP-rle.dcm");
        let mut obj = dicom_object::open_file(&rle).unwrap();
        obj.put(dicom_core::DataElement::new(
            tags::NUMBER_OF_FRAMES,
            dicom_core::VR::IS,
            dicom_core::PrimitiveValue::from("300"),
        ));
        let claimed = tmp("seg-rle-300-frames.dcm");
        obj.write_to_file(&claimed).unwrap();
        let e = raystream_io::load_volume(&claimed, &select)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("seg-rle-300-frames.dcm") && e.contains("300 frames claimed"),
            "{e}"
        );
        let bytes = std::fs::read(&rle).unwrap();
        let cut = tmp("seg-rle-cut.dcm");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let e = raystream_io::load_volume(&cut, &select)
            .unwrap_err()
            .to_string();
        assert!(e.contains("seg-rle-cut.dcm"), "{e}");
    }
    // The standard's IOD checker finds no error, nor in the series' CT images (written with a
    // patient's name beyond ASCII).
    assert_eq!(iod_errors(&seg), Vec::<String>::new());
    assert_eq!(iod_errors(&dir.join("0001.dcm")), Vec::<String>::new());
    // The text says what was written.
    let t = measure_text(
        &series,
        &path,
        &["--mask", seg_file],
        &tmp("measure-seg.csv"),
    );
    assert!(
        t.contains(&format!(
            "mask: {seg_file} (a DICOM Segmentation of the CT's series, "
        )),
        "{t}"
    );
    // Refused before any work: a CT not read from DICOM, a series anonymised of its UIDs.
    refuses_a_ct_it_cannot_reference("--mask", seg_file);
}

/// `measure OPTION FILE`, an object of the CT's study (a DICOM Segmentation, a report), is
/// refused before any work, naming FILE, for a CT not read from a DICOM series and for a series
/// anonymised of its Study Instance UID.
fn refuses_a_ct_it_cannot_reference(option: &str, file: &str) {
    let path = aorta();
    refused(
        &["measure", &chest(), "--path", &path, option, file],
        &format!("{file}: {option}: the CT was not read from a DICOM series"),
    );
    let abdomen = shared().join("data/volumes/dicom/abdomen_ct_j2k_totalseg");
    refused(
        &[
            "measure",
            abdomen.to_str().unwrap(),
            "--path",
            &path,
            option,
            file,
        ],
        "has no Study Instance UID (anonymised?)",
    );
}

/// `render --mode slice --segmentation LABELS`: each pixel tinted by the label at its point,
/// checked pixel by pixel on an axial slice through the aorta (each pixel's point from the
/// plane the same slice's DICOM names), and on a CPR along the path (lumen down its middle).
#[test]
fn render_tints_a_segmentation_over_a_slice_and_a_cpr() {
    use dicom_dictionary_std::tags;
    let (vol, path) = (chest(), aorta());
    let mask = tmp("tint-mask.nii.gz");
    measure(&vol, &path, &["--wall", "--mask", mask.to_str().unwrap()]);
    let labels = raystream_io::load_volume(&mask, &Default::default()).unwrap();
    let tint = |base: &[u8], label: u32| -> [u8; 3] {
        let c = [[0, 230, 255], [255, 64, 220]][label as usize - 1];
        std::array::from_fn(|i| (base[i] as f32 * 0.55 + c[i] as f32 * 0.45).round() as u8)
    };
    let axial = [
        vol.as_str(),
        "--mode",
        "slice",
        "--view",
        "superior",
        "--slice-at",
        "22,-112,716",
        "--size",
        "96x80",
    ];
    // Each pixel of a tinted slice (PNG) is the plain one's, or its tint by the label at the
    // point the plain slice's DICOM plane puts it at, exactly; the pixels of each label.
    let check = |plain: &std::path::Path, tinted: &std::path::Path, dcm: &std::path::Path| {
        let (plain, tinted) = (
            image::open(plain).unwrap().to_rgb8(),
            image::open(tinted).unwrap().to_rgb8(),
        );
        let obj = dicom_object::open_file(dcm).unwrap();
        let floats = |tag| obj.element(tag).unwrap().to_multi_float64().unwrap();
        let (o, turn, spacing) = (
            DVec3::from_slice(&floats(tags::IMAGE_POSITION_PATIENT)),
            floats(tags::IMAGE_ORIENTATION_PATIENT),
            floats(tags::PIXEL_SPACING)[0],
        );
        let (r, c) = (DVec3::from_slice(&turn[..3]), DVec3::from_slice(&turn[3..]));
        let mut held = [0; 3];
        for (x, y, px) in tinted.enumerate_pixels() {
            let p = o + (r * x as f64 + c * y as f64) * spacing;
            let q = labels.world_to_index(p).round();
            let inside = q.min_element() >= 0.0 && q.x < 120.0 && q.y < 126.0 && q.z < 164.0;
            let label = if inside {
                labels.at(q.x as usize, q.y as usize, q.z as usize) as u32
            } else {
                0
            };
            held[label as usize] += 1;
            let base = plain.get_pixel(x, y).0;
            let want = if label == 0 { base } else { tint(&base, label) };
            assert_eq!(
                px.0,
                want,
                "{}: pixel ({x}, {y}), label {label}",
                dcm.display()
            );
        }
        held
    };
    let seg = [&axial[..], &["--segmentation", mask.to_str().unwrap()]].concat();
    let held = check(
        &render_to("tint-plain.png", "cpu", &axial),
        &render_to("tint-axial.png", "cpu", &seg),
        &render_to("tint-plain.dcm", "cpu", &axial),
    );
    assert!(held[1] > 100 && held[2] > 10, "{held:?}");
    // Cross-sections down the path (frames, each tinted under what is drawn on it).
    let sections = cpr_args(&vol, &path, &["--size", "48x48", "--slices", "3"]);
    let out = |name: &str, more: &[&str]| {
        let dir = tmp(name);
        std::fs::remove_dir_all(&dir).ok();
        let mut all = vec!["render", "--quiet", "--device", "cpu"];
        all.extend_from_slice(&sections);
        all.extend_from_slice(more);
        all.extend_from_slice(&["-o", dir.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{all:?}: {}", stderr(&o));
        dir
    };
    let (plain, tinted, dcm) = (
        out("tint-sections-plain", &[]),
        out("tint-sections", &["--segmentation", mask.to_str().unwrap()]),
        out("tint-sections-dcm", &["--format", "dcm"]),
    );
    for i in 0..3 {
        let f = |d: &std::path::Path, ext: &str| d.join(format!("frame_{i:03}.{ext}"));
        let held = check(&f(&plain, "png"), &f(&tinted, "png"), &f(&dcm, "dcm"));
        assert!(held[1] > 100 && held[2] > 10, "section {i}: {held:?}");
    }
    // A CPR down the path: every pixel plain or tinted as a label; the lumen down its middle.
    let cpr = cpr_args(&vol, &path, &["--size", "64x160"]);
    let plain = image::open(render_to("tint-cpr-plain.png", "cpu", &cpr))
        .unwrap()
        .to_rgb8();
    let seg = [&cpr[..], &["--segmentation", mask.to_str().unwrap()]].concat();
    let tinted = image::open(render_to("tint-cpr.png", "cpu", &seg))
        .unwrap()
        .to_rgb8();
    let mut held = [0; 3];
    for (x, y, px) in tinted.enumerate_pixels() {
        let base = plain.get_pixel(x, y).0;
        let label = (0..3u32)
            .find(|&l| px.0 == if l == 0 { base } else { tint(&base, l) })
            .unwrap_or_else(|| panic!("pixel ({x}, {y}): {:?} over {base:?}", px.0));
        held[label as usize] += 1;
    }
    let middle = (0..160)
        .filter(|&y| tinted.get_pixel(32, y).0 != plain.get_pixel(32, y).0)
        .count();
    assert!(
        held[1] > 2000 && held[2] > 100 && middle > 100,
        "{held:?}, {middle} rows"
    );
    // Tinted: only a slice or a CPR, of a label map; a MIP shows no colours, only fewer
    // segments.
    refused(
        &[
            "render",
            &vol,
            "--mode",
            "mip",
            "--segmentation",
            mask.to_str().unwrap(),
            "-o",
            "x.png",
        ],
        "a projection shows HU, not colours; give --segment LIST",
    );
    refused(
        &[
            "render",
            &vol,
            "--mode",
            "slice",
            "--slab",
            "5",
            "--segmentation",
            mask.to_str().unwrap(),
            "-o",
            "x.png",
        ],
        "tints a slice or a CPR, each pixel a point: give --mode slice (no --slab)",
    );
    refused(
        &[
            "render",
            "--segmentation",
            mask.to_str().unwrap(),
            "-o",
            "x.png",
        ],
        "lays a segmentation on a CT rendered with --mode",
    );
    refused(
        &[
            "render",
            &vol,
            "--mode",
            "slice",
            "--segmentation",
            &vol,
            "-o",
            "x.png",
        ],
        "--segmentation takes a label map (whole numbers from 0); it holds -",
    );
}

/// The pixels (RGB, any scale) that differ between `plain` and `coloured`, which must be more
/// than `at_least`, at least 90 % of them bluer (blue less red grows: cyan lumen, magenta
/// wall over ct-aaa's red).
fn changed_and_bluer(
    dev: &str,
    plain: &[[f32; 3]],
    coloured: &[[f32; 3]],
    at_least: usize,
) -> Vec<usize> {
    let changed: Vec<usize> = (0..plain.len())
        .filter(|&i| plain[i] != coloured[i])
        .collect();
    let blue = |c: [f32; 3]| c[2] - c[0];
    let bluer = changed
        .iter()
        .filter(|&&i| blue(coloured[i]) > blue(plain[i]))
        .count();
    eprintln!("{dev}: {} pixels coloured, {bluer} bluer", changed.len());
    assert!(
        changed.len() > at_least && bluer * 10 >= changed.len() * 9,
        "{dev}: {} changed, {bluer} bluer",
        changed.len()
    );
    changed
}

/// `render CT --mode mip|minip|average --segmentation LABELS --segment LIST`: each pixel the
/// projection of the listed segments' voxels alone along its ray (their largest value, their
/// smallest, their mean). On the chest CT and the aorta's lumen, in each mode:
/// - with every lumen voxel set to 500 HU, every pixel that meets the lumen is 500: a hidden
///   voxel counted, or any fill value blended in at the lumen's edge (as hidden voxels set
///   just beyond the CT's range once were, a dark rim round a MIP), would move the pixels
///   there;
/// - with every voxel kept, it is the plain projection, bit for bit on the CPU;
/// - on the CT itself, it lies within the lumen voxels' range, is a miss where no sample came
///   near a lumen voxel, and the GPU's equals the CPU's;
/// - the average's PNG without `--window` is windowed on the lumen's voxels: grey levels, not
///   the white the average's own window gives.
#[test]
fn projections_kept_to_a_segment_see_its_voxels_alone() {
    let (vol, mask) = chest_and_mask("average-mask.nii.gz");
    let m = mask.to_str().unwrap();
    let load = |p: &std::path::Path| raystream_io::load_volume(p, &Default::default()).unwrap();
    let (ct, labels) = (load(std::path::Path::new(&vol)), load(&mask));
    assert_eq!(
        ct.dims, labels.dims,
        "measure --mask writes on the CT's grid"
    );
    let in_lumen = |i: usize| labels.data[i] == 1.0;
    let (lo, hi) = (0..ct.data.len())
        .filter(|&i| in_lumen(i))
        .fold((f32::MAX, f32::MIN), |(lo, hi), i| {
            (lo.min(ct.data[i]), hi.max(ct.data[i]))
        });
    let flat: Vec<f32> = (0..ct.data.len())
        .map(|i| if in_lumen(i) { 500.0 } else { ct.data[i] })
        .collect();
    let flat = write_like("average-flat-lumen.mha", &ct, &flat);
    // Every voxel kept: a label map of ones on the CT's grid.
    let ones = tmp("average-ones.nii");
    raystream_io::write_label_map(&ones, &ct, &vec![1; ct.voxel_count()], "all").unwrap();
    let channel = |f: &std::path::Path| -> Vec<f32> {
        let exr = raystream_cpu::load_exr(f).unwrap();
        exr.channels["Y"].as_f32().unwrap().to_vec()
    };
    let lumen = ["--segmentation", m, "--segment", "1"];
    let modes = ["mip", "minip", "average"];
    let mut films = Vec::new();
    for dev in devices() {
        // Where the mask's own MIP is 0, no sample came near a segment voxel.
        let mask_mip = channel(&render_to(
            &format!("average-{dev}-mip-of-mask.exr"),
            dev,
            &[m, "--mode", "mip", "--size", "60x80"],
        ));
        for mode in modes {
            let size = ["--mode", mode, "--size", "60x80"];
            let out = |name: &str, args: &[&[&str]]| {
                channel(&render_to(
                    &format!("average-{dev}-{mode}-{name}"),
                    dev,
                    &args.concat(),
                ))
            };
            let plain = out("plain.exr", &[&[&vol], &size]);
            let kept = out("lumen.exr", &[&[&vol], &size, &lumen]);
            let all = out(
                "all.exr",
                &[
                    &[&vol],
                    &size,
                    &["--segmentation", ones.to_str().unwrap(), "--segment", "1"],
                ],
            );
            let flat = out("flat.exr", &[&[flat.to_str().unwrap()], &size, &lumen]);
            // The GPU's texture holds half floats (0.25 HU apart below 512, 2 HU above 2048)
            // and filters with weights of its own precision; the CPU's weights of a volume
            // kept whole are exactly 1, so its projection is the plain one's, bit for bit.
            let gpu = *dev == "gpu";
            let (tol, same) = if gpu { (2.0, 1e-3) } else { (1e-3, 0.0) };
            let mut hit = 0;
            for i in 0..kept.len() {
                let (k, p) = (kept[i], plain[i]);
                assert!(
                    (all[i] - p).abs() <= same * p.abs().max(1.0) || all[i].is_nan() && p.is_nan(),
                    "{dev} {mode}: pixel {i}: every voxel kept {} against the plain {p}",
                    all[i]
                );
                assert_eq!(
                    k.is_nan(),
                    flat[i].is_nan(),
                    "{dev} {mode}: pixel {i}: {k} and {}",
                    flat[i]
                );
                if p.is_nan() || mask_mip[i] == 0.0 {
                    assert!(
                        k.is_nan(),
                        "{dev} {mode}: pixel {i}: {k} HU where no lumen voxel lies"
                    );
                }
                if k.is_nan() {
                    continue;
                }
                hit += 1;
                assert!(
                    (flat[i] - 500.0).abs() <= if gpu { 0.5 } else { 0.01 },
                    "{dev} {mode}: pixel {i}: {} HU through a lumen of 500 HU",
                    flat[i]
                );
                assert!(
                    (lo - tol..=hi + tol).contains(&k),
                    "{dev} {mode}: pixel {i}: {k} HU outside the lumen's {lo}..{hi}"
                );
            }
            let mean = kept.iter().filter(|v| !v.is_nan()).sum::<f32>() / hit as f32;
            eprintln!("{dev}: {mode} of the lumen: {hit} pixels, mean {mean:.1} HU");
            assert!(hit >= 60, "{dev} {mode}: {hit} pixels meet the lumen");
            // Contrast-filled blood; its brightest voxels the stent graft's metal.
            let blood = match mode {
                "mip" => 300.0..4000.0,
                _ => 100.0..500.0,
            };
            assert!(blood.contains(&mean), "{dev} {mode}: mean {mean} HU");
            films.push((mode, kept));
        }
    }
    let size = ["--mode", "average", "--size", "60x80"];
    // Shown without --window, on its voxels' window (median 348 HU, 10th to 90th percentile
    // 211 to 518 HU), the lumen spans grey levels; on the average's own (−800 to 200 HU) it
    // would be white.
    let png = tmp("average-lumen.png");
    let mut args = vec!["render", "--device", "cpu", &vol, "--size", "60x80"];
    args.extend_from_slice(&size[..2]);
    args.extend_from_slice(&lumen);
    args.extend_from_slice(&["-o", png.to_str().unwrap()]);
    let o = run(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("window 614/348 HU (their voxels' median"),
        "{}",
        stderr(&o)
    );
    let greys = |png: &std::path::Path| -> Vec<u8> {
        let img = image::open(png).unwrap().to_rgb8();
        let bg = *img.get_pixel(0, 0);
        img.pixels().filter(|p| **p != bg).map(|p| p[0]).collect()
    };
    let shown = greys(&png);
    let white = shown.iter().filter(|&&g| g == 255).count();
    let levels: std::collections::BTreeSet<u8> = shown.iter().copied().collect();
    assert!(
        shown.len() >= 60 && white * 20 < shown.len() && levels.len() >= 30,
        "{} pixels, {white} white, {} grey levels",
        shown.len(),
        levels.len()
    );
    args.truncate(args.len() - 2);
    let flat_png = tmp("average-lumen-default-window.png");
    args.extend_from_slice(&[
        "--window",
        "1000",
        "--level",
        "-300",
        "-o",
        flat_png.to_str().unwrap(),
    ]);
    assert!(run(&args).status.success());
    let white = greys(&flat_png).iter().filter(|&&g| g == 255).count();
    assert!(
        white * 10 >= shown.len() * 9,
        "{white} of {} white",
        shown.len()
    );

    let (cpu, gpu) = films.split_at(films.len().min(modes.len()));
    for ((mode, cpu), (_, gpu)) in cpu.iter().zip(gpu) {
        let (mut both, mut one, mut diff) = (0, 0, 0.0f64);
        for (c, g) in cpu.iter().zip(gpu) {
            match (c.is_nan(), g.is_nan()) {
                (false, false) => {
                    both += 1;
                    diff += (c - g).abs() as f64;
                }
                (true, true) => {}
                _ => one += 1,
            }
        }
        let mean = diff / both as f64;
        eprintln!(
            "the lumen's {mode}: {both} pixels on both devices, {one} on one, mean difference {mean:.3} HU"
        );
        assert!(
            one * 100 <= both,
            "{mode}: {one} pixels hit on one device only, {both} on both"
        );
        assert!(mean < 2.0, "{mode}: GPU against CPU: {mean} HU");
    }
}

/// `render CT --mode … --segmentation LABELS [--segment LIST]` on the chest CT with
/// `measure --wall --mask`'s lumen (1) and wall (2), on each device:
/// - a MIP kept to the lumen and the wall: every pixel within their voxels' range, the
///   contrast lumen bright, and the rays that meet no segment misses (NaN in the EXR, the
///   padding value in DICOM, the background in the PNG): every pixel where the MIP of the mask
///   itself is 0, and no pixel where it is 1 or more (a sample there blends the segments'
///   voxels by at least half); kept to the lumen, a MinIP likewise within the lumen's range,
///   the rays far from it misses;
/// - dvr from behind, coloured by both: the opacity (the EXR's A) is the plain frame's bit for
///   bit, and the pixels that change turn bluer (cyan lumen, magenta wall, where ct-aaa draws
///   contrast red); kept to the lumen, only pixels where the plain frame has some opacity
///   remain, and far fewer;
/// - the GPU's PNG is the CPU's (mean difference under 0.5/255);
/// - what makes no sense is refused, naming the option.
#[test]
fn render_colours_a_ct_by_its_segments_and_keeps_it_to_them() {
    let (vol, mask) = chest_and_mask("paint-mask.nii.gz");
    let m = mask.to_str().unwrap();
    let channel = |f: &std::path::Path, c: &str| -> Vec<f32> {
        let exr = raystream_cpu::load_exr(f).unwrap();
        exr.channels[c].as_f32().unwrap().to_vec()
    };
    // The range of the CT's values within the listed labels of the mask.
    let range_in = |keep: &[f32]| {
        let load = |p: &std::path::Path| raystream_io::load_volume(p, &Default::default());
        let (ct, labels) = (load(vol.as_ref()).unwrap(), load(&mask).unwrap());
        ct.data
            .iter()
            .zip(&labels.data)
            .filter(|(_, l)| keep.contains(l))
            .fold((f32::MAX, f32::MIN), |(lo, hi), (&v, _)| {
                (lo.min(v), hi.max(v))
            })
    };
    let (vessel_lo, vessel_hi) = range_in(&[1.0, 2.0]);
    let (lumen_lo, lumen_hi) = range_in(&[1.0]);
    let mip = [vol.as_str(), "--mode", "mip", "--size", "60x80"];
    let back = [
        vol.as_str(),
        "--mode",
        "dvr",
        "--preset",
        "ct-aaa",
        "--view",
        "posterior",
        "--size",
        "60x80",
    ];
    let both = ["--segmentation", m];
    let lumen = ["--segmentation", m, "--segment", "1"];
    let vessel = ["--segmentation", m, "--segment", "1,2"];
    let mut pngs = Vec::new();
    for dev in devices() {
        let out = |name: &str, args: &[&[&str]]| {
            render_to(&format!("paint-{dev}-{name}"), dev, &args.concat())
        };
        let plain = channel(&out("mip.exr", &[&mip]), "Y");
        let kept = channel(&out("mip-vessel.exr", &[&mip, &vessel]), "Y");
        // The mask's own MIP, on the same grid, framed and sampled as the CT: where it is 0
        // no sample came near a segment voxel.
        let mask_mip = channel(&out("mip-of-mask.exr", &[&[m], &mip[1..]]), "Y");
        let (mut none, mut lit) = (0, 0);
        for ((k, p), s) in kept.iter().zip(&plain).zip(&mask_mip) {
            if p.is_nan() {
                assert!(k.is_nan(), "{dev}: the same rays miss");
                continue;
            }
            if *s == 0.0 {
                assert!(k.is_nan(), "{dev}: {k} HU where the mask's MIP is 0");
            }
            if k.is_nan() {
                assert!(*s < 1.0, "{dev}: a miss where the mask's MIP is {s}");
                none += 1;
                continue;
            }
            assert!(
                (vessel_lo - 2.0..=vessel_hi + 2.0).contains(k),
                "{dev}: kept {k} outside the vessel's {vessel_lo}..{vessel_hi} (plain MIP {p})"
            );
            lit += (*k > 200.0) as usize;
        }
        let brightest = kept.iter().copied().fold(f32::MIN, f32::max);
        eprintln!(
            "{dev}: MIP of the vessel: {none} pixels meet no segment, {lit} over 200 HU, brightest {brightest}"
        );
        assert!(none > 1000 && lit > 40 && brightest > 400.0, "{dev}");
        // Its DICOM: the HU rounded, the misses the padding value, as for rays that miss the
        // CT (decode_pixel_data applies no rescale here: the stored values are the HU).
        {
            use dicom_pixeldata::PixelDecoder;
            let dcm = out("mip-vessel.dcm", &[&mip, &vessel]);
            let obj = dicom_object::open_file(&dcm).unwrap();
            let got: Vec<f32> = obj.decode_pixel_data().unwrap().to_vec().unwrap();
            assert_eq!(got.len(), kept.len());
            for (g, k) in got.iter().zip(&kept) {
                let want = if k.is_nan() { -32768.0 } else { k.round() };
                assert_eq!(*g, want, "{dev}: DICOM against the EXR");
            }
        }
        // Its PNG: the misses in the background's colour.
        let png = image::open(out("mip-vessel.png", &[&mip, &vessel]))
            .unwrap()
            .to_rgb8();
        let bg = raystream_cpu::dvr::DvrOptions::default().background;
        let bg = raystream_cpu::Image {
            width: 1,
            height: 1,
            pixels: vec![bg],
        }
        .to_srgb8();
        let misses = png.pixels().zip(&kept).filter(|(_, k)| k.is_nan());
        for (px, _) in misses {
            assert_eq!(px.0[..], bg[..], "{dev}: a miss drawn");
        }
        // A MinIP kept to the lumen: every pixel within the lumen's values, the rays far
        // from the lumen misses; over the lumen, its darkest, still contrast-filled blood
        // (over 0 HU).
        let minip = [vol.as_str(), "--mode", "minip", "--size", "60x80"];
        let plain = channel(&out("minip.exr", &[&minip]), "Y");
        let kept = channel(&out("minip-lumen.exr", &[&minip, &lumen]), "Y");
        let (mut far, mut blood) = (0, 0);
        for (k, p) in kept.iter().zip(&plain) {
            if k.is_nan() {
                far += !p.is_nan() as usize;
                continue;
            }
            assert!(
                (lumen_lo - 2.0..=lumen_hi + 2.0).contains(k),
                "{dev}: kept {k} outside the lumen's {lumen_lo}..{lumen_hi} (plain MinIP {p})"
            );
            blood += (*k > 0.0 && *k < 1000.0) as usize;
        }
        eprintln!("{dev}: MinIP of the lumen: {far} pixels far from it, {blood} of blood");
        assert!(far > 1000 && blood > 40, "{dev}");
        // Coloured: the same opacity, bluer where it changes.
        let plain = out("dvr.exr", &[&back]);
        let painted = out("dvr-both.exr", &[&back, &both]);
        assert_eq!(channel(&plain, "A"), channel(&painted, "A"), "{dev}");
        let rgb = |f: &std::path::Path| {
            let [r, g, b] = ["R", "G", "B"].map(|c| channel(f, c));
            (0..r.len())
                .map(move |i| [r[i], g[i], b[i]])
                .collect::<Vec<_>>()
        };
        changed_and_bluer(dev, &rgb(&plain), &rgb(&painted), 30);
        // Kept to the lumen: what remains had some opacity before, and far less shows.
        let alpha = channel(&plain, "A");
        let kept = channel(&out("dvr-lumen.exr", &[&back, &lumen]), "A");
        let shown = |a: &[f32]| a.iter().filter(|&&a| a > 0.05).count();
        for (k, a) in kept.iter().zip(&alpha) {
            assert!(*k <= 0.05 || *a > 0.0, "{dev}: lumen where nothing was");
        }
        assert!(
            shown(&kept) > 20 && shown(&kept) * 4 < shown(&alpha),
            "{dev}: {} of {} pixels",
            shown(&kept),
            shown(&alpha)
        );
        pngs.push(out("dvr-both.png", &[&back, &both]));
    }
    if let [cpu, gpu] = &pngs[..] {
        let (a, b) = (
            image::open(cpu).unwrap().to_rgb8(),
            image::open(gpu).unwrap().to_rgb8(),
        );
        let diff: u64 = a
            .as_raw()
            .iter()
            .zip(b.as_raw())
            .map(|(x, y)| x.abs_diff(*y) as u64)
            .sum();
        let mean = diff as f64 / a.as_raw().len() as f64;
        assert!(mean < 0.5, "GPU vs CPU: {mean}/255");
    }
    for (args, want) in [
        (
            &[&mip[..], &["--segmentation", m]].concat(),
            "with --mode mip: a projection shows HU, not colours; give --segment LIST",
        ),
        (
            &[&mip[..], &["--segment", "1"]].concat(),
            "--segment 1 with --mode mip: keeps only those segments of a CT's segmentation: give --segmentation LABELS",
        ),
        (
            &[&back[..], &["--segmentation", m, "--segment", "7"]].concat(),
            "--segment 7: no voxel holds label 7; the labels present are 1, 2",
        ),
        (
            &[&back[..], &["--segmentation", m, "--outline"]].concat(),
            "--outline draws each segment's edge over a slice",
        ),
        (
            &[vol.as_str(), "--mode", "minip", "--segmentation", m][..].to_vec(),
            "with --mode minip: a projection shows HU, not colours",
        ),
        (
            &[vol.as_str(), "--mode", "average", "--segmentation", m][..].to_vec(),
            "with --mode average: a projection shows HU, not colours; give --segment LIST",
        ),
        (
            &[
                vol.as_str(),
                "--mode",
                "slice",
                "--segmentation",
                m,
                "--segment",
                "1",
            ][..]
                .to_vec(),
            "--segment 1 with --mode slice",
        ),
        (
            &[&back[..], &["--segmentation", &vol]].concat(),
            "--segmentation takes a label map (whole numbers from 0)",
        ),
    ] {
        let mut all = vec!["render", "--device", "cpu"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", "x.png"]);
        refused(&all, want);
    }
}

/// A scene file's `[volume]` with `segmentation` (the chest CT with `measure --mask`'s lumen and
/// wall, beside a small sphere), on each device: the volume's pixels change and turn bluer
/// (cyan lumen, magenta wall, where ct-aaa draws contrast red), the sphere's and the
/// background's do not; `segment = [1]` keeps the lumen alone, far fewer pixels; the GPU's
/// frame is the CPU's within the render tests' tolerance; `--legend` lists the two segments;
/// `segment` without `segmentation`, a label not present and a segmentation that cannot be
/// read are refused, naming the scene.
#[test]
fn a_scene_volume_takes_its_segments_colours() {
    let (vol, mask) = chest_and_mask("scene-mask.nii.gz");
    let scene = |name: &str, extra: &str| {
        let file = tmp(&format!("scene-segments-{name}.toml"));
        let text = format!(
            "background = [0.1, 0.1, 0.12]\n[volume]\npath = {vol:?}\npreset = \"ct-aaa\"\n{extra}\n\n[[objects]]\nshape = \"sphere\"\nframe = \"lps\"\nscale = 12\ntranslate = [60, -300, 600]\n"
        );
        std::fs::write(&file, text).unwrap();
        file.to_str().unwrap().to_string()
    };
    let m = mask.to_str().unwrap();
    let plain = scene("plain", "");
    let both = scene("both", &format!("segmentation = {m:?}"));
    let lumen = scene("lumen", &format!("segmentation = {m:?}\nsegment = [1]"));
    let args = ["--size", "60x80", "--spp", "1", "--view", "posterior"];
    let mut frames = Vec::new();
    for dev in devices() {
        let img = |name: &str, s: &str| {
            let f = render_to(
                &format!("scene-seg-{dev}-{name}.png"),
                dev,
                &[&[s][..], &args].concat(),
            );
            image::open(&f).unwrap().to_rgb8()
        };
        let (p, b, l) = (
            img("plain", &plain),
            img("both", &both),
            img("lumen", &lumen),
        );
        let bg = p.get_pixel(0, 0).0;
        let floats = |x: &image::RgbImage| -> Vec<[f32; 3]> {
            x.pixels().map(|q| q.0.map(|c| c as f32)).collect()
        };
        let changed = changed_and_bluer(dev, &floats(&p), &floats(&b), 20);
        let blue = |px: &[u8]| px[2] as i32 - px[0] as i32;
        for &i in &changed {
            assert_ne!(
                p.as_raw()[3 * i..3 * i + 3],
                bg,
                "{dev}: the background coloured"
            );
        }
        // The lumen alone: what is left of the volume is the lumen's, far less of the frame.
        let drawn = |x: &image::RgbImage| x.pixels().filter(|q| q.0 != bg).count();
        eprintln!(
            "{dev}: {} pixels drawn, {} with the lumen alone",
            drawn(&p),
            drawn(&l)
        );
        let cyan = l.pixels().filter(|q| blue(&q.0) > 30).count();
        assert!(drawn(&l) * 4 < drawn(&p) && cyan > 20, "{dev}: {cyan} cyan");
        frames.push(img("both", &both));
    }
    // `--legend` lists the scene volume's segments, as for `--mode dvr` (swatches as
    // a_legend_names_the_segments_in_colour writes them out, at least 12 pixels high).
    let listed = render_to(
        "scene-seg-legend.png",
        "cpu",
        &[&[&both[..]][..], &args, &["--legend"]].concat(),
    );
    let listed = image::open(&listed).unwrap().to_rgb8();
    for (i, colour) in [[0, 230, 255], [255, 64, 220]].into_iter().enumerate() {
        let t = 12;
        let (x, y) = (t, t + i as u32 * (t + t / 3));
        assert_eq!(listed.get_pixel(x, y).0, colour, "swatch {i}");
    }
    let o = run(&["render", &plain, "-q", "--legend", "-o", "x.png"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("a scene whose [volume] has a segmentation"),
        "{}",
        stderr(&o)
    );
    // `info` lays the segmentation on the volume as render does, and says so.
    let o = run(&["info", &both, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let words = j["volume"]["segments"].as_str().unwrap();
    assert!(
        words.starts_with("segments 1, 2 of scene-mask.nii.gz"),
        "{words}"
    );
    if let [cpu, gpu] = &frames[..] {
        let mean = cpu
            .as_raw()
            .iter()
            .zip(gpu.as_raw())
            .map(|(a, b)| a.abs_diff(*b) as f64)
            .sum::<f64>()
            / cpu.as_raw().len() as f64;
        assert!(mean < 0.5, "GPU vs CPU: {mean}/255");
    }
    for (name, extra, want) in [
        (
            "no-file",
            "segment = \"1\"".to_string(),
            "choose and colour the segments of a 'segmentation'",
        ),
        (
            "absent",
            format!("segmentation = {m:?}\nsegment = [7]"),
            "no voxel holds label 7",
        ),
        (
            "unread",
            "segmentation = \"nowhere.nii.gz\"".to_string(),
            "nowhere.nii.gz",
        ),
    ] {
        let s = scene(name, &extra);
        let o = run(&[
            "render",
            &s,
            "-q",
            "--device",
            "cpu",
            "-o",
            tmp("x.png").to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{name}");
        let e = stderr(&o);
        assert!(
            e.contains(want) && e.contains(&format!("scene-segments-{name}.toml")),
            "{name}: {e}"
        );
    }
}

/// The outer wall a millimetre at a time down the chest CT's aorta: each section's circle
/// is chosen with what its neighbours found, so its width runs on from section to section.
/// Without the neighbours (or with a refinement that creeps outwards) sections 41 and 42
/// read 42–43 mm between sections of 38 (4.6 mm off their neighbours' median).
#[test]
fn the_wall_runs_on_along_the_path() {
    let (vol, path) = (chest(), aorta());
    let m = measure(&vol, &path, &["--every", "1", "--wall"]);
    let sections = m["sections"].as_array().unwrap();
    let widths: Vec<Option<f64>> = sections
        .iter()
        .map(|s| (!s["wall"].is_null()).then(|| num(&s["wall"], "equivalent_diameter_mm")))
        .collect();
    let (mut checked, mut off) = (0, 0);
    for (i, w) in widths.iter().enumerate() {
        let Some(w) = *w else { continue };
        let mut near: Vec<f64> = (i.saturating_sub(5)..(i + 6).min(widths.len()))
            .filter(|&j| j != i)
            .filter_map(|j| widths[j])
            .collect();
        if near.len() < 4 {
            continue;
        }
        near.sort_by(f64::total_cmp);
        let k = near.len();
        let median = 0.5 * (near[(k - 1) / 2] + near[k / 2]);
        let d = (w - median).abs();
        assert!(
            d < 3.5,
            "section {}: D eq {w} against {median} about it",
            i + 1
        );
        checked += 1;
        off += usize::from(d > 1.5);
    }
    assert!(checked > 100, "{checked}");
    assert!(off * 20 <= checked, "{off} of {checked} over 1.5 mm off");
    // The text says on how many sections the neighbours chose the circle.
    let by: Vec<usize> = sections
        .iter()
        .enumerate()
        .filter(|(_, s)| s["wall"]["from_neighbours"] == true)
        .map(|(i, _)| i + 1)
        .collect();
    assert!(!by.is_empty());
    let t = measure_text(
        &vol,
        &path,
        &["--every", "1", "--wall"],
        &tmp("measure-wall-runs-on.csv"),
    );
    assert!(
        t.contains(&format!(
            "; on {} its circle is the one the sections within 5 mm agree on",
            by.len()
        )),
        "{t}"
    );
}

#[test]
fn the_outer_wall_of_the_aorta() {
    let (vol, path) = (chest(), aorta());
    let n = 24usize;
    let count = n.to_string();
    let m = measure(&vol, &path, &["--sections", &count, "--wall"]);
    assert_eq!(num(&m, "wall_threshold_hu"), -30.0);
    let sections = m["sections"].as_array().unwrap();
    let dir = tmp("measure-wall-sections");
    std::fs::remove_dir_all(&dir).ok();
    let args = [
        "render", "--quiet", "--device", "cpu", &vol, "--mode", "slice", "--path", &path,
        "--slices", &count, "--size", "100x100", "--format", "dcm", "-o",
    ];
    let o = run(&[&args[..], &[dir.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let (mut closed, mut found) = (0, 0);
    let mut widths = Vec::new();
    for (i, s) in sections.iter().enumerate() {
        if s["lumen"] != "closed" {
            assert!(s["wall"].is_null(), "{s}");
            continue;
        }
        closed += 1;
        let w = &s["wall"];
        if w.is_null() {
            continue;
        }
        found += 1;
        let (arc, lumen_eq, eq) = (
            num(s, "arc_mm"),
            num(s, "equivalent_diameter_mm"),
            num(w, "equivalent_diameter_mm"),
        );
        // The wall holds the lumen; its figures are consistent.
        assert!(num(w, "area_mm2") >= num(s, "area_mm2"), "{s}");
        let (max, min, seen) = (
            num(w, "max_diameter_mm"),
            num(w, "min_diameter_mm"),
            num(w, "seen"),
        );
        // (A round outline's narrowest width may pass its D eq by a little: 180 chords.)
        assert!(
            min <= eq + 0.1 && eq <= max && max >= num(s, "max_diameter_mm") - 0.5,
            "{s}"
        );
        assert!((0.1..=1.0).contains(&seen), "{s}");
        // The thickest the wall is: no more than its width less the lumen's narrowest, and
        // where the lumen is well off the wall's middle, more than half their difference.
        let thick = num(w, "max_thickness_mm");
        assert!(
            thick > 0.0 && thick <= max - num(s, "min_diameter_mm") + 0.5,
            "{s}"
        );
        assert!(thick >= 0.5 * (eq - lumen_eq) - 0.5, "{s}");
        // Its mean thickness no more than its thickest; inside it, the lumen; the share of its
        // area beyond that, the burden.
        let mean = num(w, "mean_thickness_mm");
        assert!(mean > 0.0 && mean <= thick + 1e-3, "{s}");
        assert!(
            (num(w, "inner_area_mm2") - num(s, "area_mm2")).abs() < 2e-3,
            "{s}"
        );
        let burden = 100.0 * (1.0 - num(s, "area_mm2") / num(w, "area_mm2"));
        assert!((num(w, "area_percent") - burden).abs() < 0.01, "{s}");
        if (20.0..80.0).contains(&arc) {
            // About the stent graft: its wall (and what is left of the sac) a few mm wide.
            assert!((1.0..7.0).contains(&(eq - lumen_eq)), "{s}");
        }
        if arc > 100.0 {
            // Below it, the aorta is as wide as ever while its enhanced lumen narrows.
            assert!((28.0..35.0).contains(&eq) && eq > lumen_eq + 8.0, "{s}");
        }
        widths.push(eq);
        // On the cross-section: 72 points about the circle's centre at 80 % of its radius
        // and 3 mm beyond it, in the section's plane (the path's tangent its normal).
        let slice = raystream_io::load_volume(
            &dir.join(format!("frame_{i:03}.dcm")),
            &raystream_io::VolumeSelect::default(),
        )
        .unwrap();
        let tangent = point(&s["tangent"]);
        let u = tangent.any_orthonormal_vector();
        let v = tangent.cross(u);
        let (c, r) = (point(&w["centre"]), 0.5 * num(w, "circle_diameter_mm"));
        let hu = |p: DVec3| {
            let q = slice.world_to_index(p).round();
            assert!(q.z.abs() < 0.5, "{p} off the section");
            slice.at(q.x as usize, q.y as usize, 0)
        };
        let fat_at = |rad: f64| {
            (0..72)
                .filter(|k| {
                    let a = std::f64::consts::TAU * *k as f64 / 72.0;
                    hu(c + rad * (a.cos() * u + a.sin() * v)) < -30.0
                })
                .count() as f64
                / 72.0
        };
        let (inside, beyond) = (fat_at(0.8 * r), fat_at(r + 3.0));
        assert!(
            inside <= 0.03,
            "section {}: {inside} of the circle's inside is fat",
            i + 1
        );
        assert!(
            beyond >= 0.7 * seen,
            "section {}: fat beyond {beyond} of the circle, its edge seen on {seen}",
            i + 1
        );
    }
    assert!(
        found * 10 >= closed * 8,
        "walls on {found} of {closed} closed sections"
    );
    // The volumes: each section with a wall stands for its share of the path.
    let v = &m["wall_volume"];
    let step = num(&m, "length_mm") / n as f64;
    let (mut wall_ml, mut lumen_ml) = (0.0, 0.0);
    for s in sections.iter().filter(|s| !s["wall"].is_null()) {
        wall_ml += num(&s["wall"], "area_mm2") * step / 1000.0;
        lumen_ml += num(s, "area_mm2") * step / 1000.0;
    }
    assert_eq!(v["sections"], found);
    assert!(
        (num(v, "wall_ml") - wall_ml).abs() < 0.01 && (num(v, "lumen_ml") - lumen_ml).abs() < 0.01,
        "{v}"
    );
    assert!(num(v, "wall_ml") > num(v, "lumen_ml") + 10.0, "{v}");
    // From section to section (6.4 mm apart) the wall's width changes by under 4 mm, but where the
    // graft ends.
    let steps: Vec<f64> = widths.windows(2).map(|p| (p[1] - p[0]).abs()).collect();
    let smooth = steps.iter().filter(|&&d| d < 4.0).count();
    assert!(smooth + 1 >= steps.len(), "{widths:?}");
    // The text names the widest wall and how many were found.
    let t = measure_text(
        &vol,
        &path,
        &["--sections", &count, "--wall"],
        &dir.join("t.csv"),
    );
    assert!(t.contains("widest wall: section "), "{t}");
    assert!(t.contains("thickest wall: section "), "{t}");
    assert!(
        t.contains(&format!("wall: found on {found} of the {closed} sections")),
        "{t}"
    );
    assert!(
        t.contains(&format!(
            "volume: the walls hold {:.1} ml over the {found} sections with one",
            num(v, "wall_ml")
        )),
        "{t}"
    );
    // A lesion graded against the wall at its own section too (ECST's way), from its figures.
    let g = measure(&vol, &path, &["--every", "2", "--stenosis", "--wall"]);
    let st = &g["stenosis"];
    let row = &g["sections"][st["lesion_section"].as_u64().unwrap() as usize - 1];
    let (w, aw) = (&row["wall"], &st["against_wall"]);
    let ecst = 100.0 * (1.0 - num(row, "min_diameter_mm") / num(w, "equivalent_diameter_mm"));
    let burden = 100.0 * (1.0 - num(row, "area_mm2") / num(w, "area_mm2"));
    assert!((num(aw, "diameter_pct") - ecst).abs() < 0.01, "{aw} {row}");
    assert!((num(aw, "area_pct") - burden).abs() < 0.01, "{aw} {row}");
    // The lumen's D min is below the wall's width: graded worse than against its reference.
    assert!(
        num(aw, "diameter_pct") > num(st, "diameter_stenosis_pct"),
        "{st}"
    );
    let plain = measure(&vol, &path, &["--every", "2", "--stenosis"]);
    assert!(plain["stenosis"]["against_wall"].is_null());
    let t = measure_text(
        &vol,
        &path,
        &["--every", "2", "--stenosis", "--wall"],
        &dir.join("g.csv"),
    );
    assert!(
        t.contains(&format!(
            "against the wall: {:.1} % by diameter",
            num(aw, "diameter_pct")
        )),
        "{t}"
    );
    let csv = std::fs::read_to_string(dir.join("t.csv")).unwrap();
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .ends_with(",wall_max_thickness_mm,wall_seen,wall_mean_thickness_mm,wall_inner_area_mm2,wall_area_percent")
    );
}

/// `render --path --slices N --draw-lumen 150 --draw-wall` draws, beside the lumen, the outer
/// wall `measure --wall` finds on the same sections: only magenta pixels change, a ring as
/// wide as the wall's calliper diameters on each section with a wall, and nothing on one
/// without; it is refused where it cannot be drawn.
#[test]
fn draw_wall_outlines_the_outer_wall() {
    let (vol, path) = (chest(), aorta());
    let n = 6;
    let m = measure(&vol, &path, &["--sections", "6", "--wall"]);
    let sections = m["sections"].as_array().unwrap();
    let base = cpr_args(
        &vol,
        &path,
        &["--slices", "6", "--size", "100x100", "--draw-lumen", "150"],
    );
    let frames = |name: &str, extra: &[&str]| {
        let dir = tmp(name);
        std::fs::remove_dir_all(&dir).ok();
        render_to(name, "cpu", &[&base[..], extra].concat());
        dir
    };
    let lumen = frames("measure-wall-lumen", &[]);
    let wall = frames("measure-wall-drawn", &["--draw-wall"]);
    let mut with_wall = 0;
    for (i, s) in sections.iter().enumerate().take(n) {
        let name = format!("frame_{i:03}.png");
        let a = image::open(lumen.join(&name)).unwrap().to_rgb8();
        let b = image::open(wall.join(&name)).unwrap().to_rgb8();
        let mut xs = Vec::new();
        for (k, (p, q)) in a.pixels().zip(b.pixels()).enumerate() {
            if p != q {
                assert_eq!(q.0, [255, 64, 220], "frame {i}: a pixel changed to {q:?}");
                xs.push((k % 100) as f64);
            }
        }
        let w = &s["wall"];
        if w.is_null() {
            assert!(
                xs.is_empty(),
                "frame {i}: {} pixels without a wall",
                xs.len()
            );
            continue;
        }
        with_wall += 1;
        // At 1.5 mm a pixel, the ring is about π D / 1.5 pixels round (less where the
        // lumen's edge is drawn over it, or it is dotted) and as wide as the wall.
        let d = num(w, "equivalent_diameter_mm");
        assert!(
            xs.len() as f64 >= 0.5 * std::f64::consts::PI * d / 1.5,
            "frame {i}: {}",
            xs.len()
        );
        let across = 1.5
            * (xs.iter().copied().fold(0.0, f64::max) - xs.iter().copied().fold(1e9, f64::min)
                + 1.0);
        assert!(
            across >= num(w, "min_diameter_mm") - 3.0 && across <= num(w, "max_diameter_mm") + 3.0,
            "frame {i}: {across} mm across, {w}"
        );
    }
    assert!(with_wall >= 4, "{with_wall} walls drawn");
    // On a CPR, the wall's two edges on each row, outside the lumen's.
    for view in [&[][..], &["--orbit", "90"], &["--cpr", "stretched"]] {
        let cpr = cpr_args(
            &vol,
            &path,
            &[&["--size", "96x288", "--draw-lumen", "150"][..], view].concat(),
        );
        let a = image::open(render_to("measure-wall-cpr-lumen.png", "cpu", &cpr))
            .unwrap()
            .to_rgb8();
        let drawn = [&cpr[..], &["--draw-wall"]].concat();
        let b = image::open(render_to("measure-wall-cpr.png", "cpu", &drawn))
            .unwrap()
            .to_rgb8();
        let (mut rows, mut outside) = (0, 0);
        for y in 0..288 {
            let xs = |c: [u8; 3]| {
                (0..96)
                    .filter(|&x| b.get_pixel(x, y).0 == c)
                    .collect::<Vec<u32>>()
            };
            for x in 0..96 {
                let (p, q) = (a.get_pixel(x, y), b.get_pixel(x, y));
                assert!(
                    p == q || q.0 == [255, 64, 220],
                    "{view:?} ({x}, {y}): {q:?}"
                );
            }
            let (wall, lumen) = (xs([255, 64, 220]), xs([0, 230, 255]));
            assert!(wall.len() <= 2, "{view:?} row {y}: {wall:?}");
            if let ([l, .., r], [ll, .., lr]) = (&wall[..], &lumen[..]) {
                rows += 1;
                if l <= ll && r >= lr {
                    outside += 1;
                }
            }
        }
        // (A wall's edge on the lumen's pixel is drawn under it.)
        assert!(
            rows >= 100 && outside * 100 >= rows * 95,
            "{view:?}: {outside} of {rows} rows"
        );
    }
    // Not at or above the lumen's threshold, not without the lumen.
    let high_out = tmp("measure-wall-high");
    let high = [
        &["render", "--quiet"][..],
        &base,
        &["--draw-wall", "200", "-o", high_out.to_str().unwrap()],
    ]
    .concat();
    refused(&high, "--draw-wall 200");
    let bare = cpr_args(&vol, &path, &["--slices", "2", "--draw-wall"]);
    let bare = [
        &["render", "--quiet"][..],
        &bare,
        &["-o", high_out.to_str().unwrap()],
    ]
    .concat();
    refused(&bare, "--draw-lumen");
}

/// `measure --report FILE.dcm`: the findings as a DICOM Imaging Measurement Report (TID 1500)
/// of the CT's study. Each group's measurements are the JSON report's of the same run, read
/// back by highdicom (an independent reader); where each was taken (its SCOORD3D) lies in the
/// series' Frame of Reference at the JSON's points; the segments' groups reference the
/// Segmentation written with it; the image library lists the series' images. dciodvfy
/// finds no error in the IOD, nor DCMTK's dsrdump in the content tree. A CT the report
/// cannot file with is refused before any work.
#[test]
fn the_findings_as_a_dicom_structured_report() {
    use dicom_dictionary_std::tags;
    use dicom_object::InMemDicomObject;
    use serde_json::json;
    let dir = tmp("chest-series-report");
    let study = chest_series(&dir);
    let series = dir.to_str().unwrap().to_string();
    let path = aorta();
    let (seg, sr) = (tmp("report-seg.dcm"), tmp("report.dcm"));
    let (seg_file, sr_file) = (seg.to_str().unwrap(), sr.to_str().unwrap());
    let m = measure(
        &series,
        &path,
        &[
            "--wall",
            "--lesions",
            "2",
            "--angle",
            "20,60,100",
            "--mask",
            seg_file,
            "--report",
            sr_file,
        ],
    );
    // What the report must hold: the JSON report's figures, coded.
    let sections = m["sections"].as_array().unwrap();
    let section = |key: &str| &sections[m[key].as_u64().unwrap() as usize - 1];
    let (widest, narrowest) = (section("widest_section"), section("narrowest_section"));
    let wall = &section("widest_wall_section")["wall"];
    let value = sr_measurement;
    let (maximum, minimum) = (Some("56851009"), Some("255605001"));
    let mut want = vec![json!({
    "template": "1501", "tracking_id": "Vessel along the path", "finding": "59820001",
    "sites": [], "measurements": [
        value("410668003", num(&m, "length_mm"), "mm", None, None),
        value("15690004", num(&m, "distance_metric"), "1", None, Some("RS-DISTMETRIC")),
        value("397413000", num(widest, "max_diameter_mm"), "mm", maximum, None),
        value("397413000", num(narrowest, "min_diameter_mm"), "mm", minimum, None),
        value("397415007", num(narrowest, "area_mm2"), "mm2", minimum, None),
        value("397414006", num(wall, "max_diameter_mm"), "mm", maximum, None),
        value("122371", num(&m["wall_volume"], "wall_ml"), "ml", None, None),
        value("122372", num(&m["wall_volume"], "lumen_ml"), "ml", None, None),
        value("1483009", num(&m["angle"], "deviation_deg"), "deg", None, Some("RS-CHORDANGLE")),
    ]})];
    let lesions = m["stenoses"].as_array().unwrap();
    assert_eq!(lesions.len(), 2);
    for (k, g) in lesions.iter().enumerate() {
        let (w, reference) = (&g["against_wall"], Some("RS-REFERENCE"));
        want.push(json!({
        "template": "1501", "tracking_id": format!("Stenosis {}", k + 1),
        "finding": "415582006", "sites": ["59820001"], "measurements": [
            value("408715008", num(g, "diameter_stenosis_pct"), "%", None, reference),
            value("408714007", num(g, "area_stenosis_pct"), "%", None, reference),
            value("397413000", num(g, "min_diameter_mm"), "mm", minimum, None),
            value("397415007", num(g, "area_mm2"), "mm2", None, None),
            value("RS-REFDIAM", num(&g["reference"], "diameter_mm"), "mm", None, None),
            value("408716009", num(&g["narrowed"], "length_mm"), "mm", None, None),
            value("408715008", num(w, "diameter_pct"), "%", None, Some("RS-OUTERWALL")),
            value("122354", num(w, "area_pct"), "%", None, None),
        ]}));
    }
    want.extend(segment_groups_want(
        &seg,
        &dir,
        &m["mask"],
        ("Wall and thrombus", "59820001"),
    ));
    // The JSON line names it; highdicom reads the same groups and figures.
    check_report(&m["report"], &sr, &study.study_uid, &want);
    // raystream reads it back: `info` lists the same groups and figures.
    let o = run(&["info", sr_file, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(info["kind"], "report");
    assert_eq!(info["template"], "1500");
    assert_eq!(info["observers"], json!(["raystream measure"]));
    let got = info["groups"].as_array().unwrap();
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g["template"], w["template"]);
        assert_eq!(g["tracking_id"], w["tracking_id"]);
        assert_eq!(g["finding"]["value"], w["finding"]);
        let segment = w["segment"].get(0).cloned().unwrap_or(json!(null));
        assert_eq!(g["segment"], segment);
        let measured: Vec<serde_json::Value> = g["measurements"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                let keys = ["concept", "value", "unit", "derivation", "method"];
                json!(
                    keys.iter()
                        .map(|&k| (k.to_string(), m[k].clone()))
                        .collect::<serde_json::Map<_, _>>()
                )
            })
            .collect();
        assert_eq!(json!(measured), w["measurements"], "{}", w["tracking_id"]);
    }
    // The file itself: filed with the study, its points in the series' Frame of Reference.
    let obj = dicom_object::open_file(&sr).unwrap();
    let text = |tag| dicom_text(&obj, tag);
    assert_eq!(text(tags::MODALITY), "SR");
    assert_eq!(text(tags::STUDY_INSTANCE_UID), study.study_uid);
    assert_eq!(text(tags::PATIENT_NAME), "MÜLLER^JÖRG");
    assert_eq!(text(tags::VERIFICATION_FLAG), "UNVERIFIED");
    let items = |o: &InMemDicomObject, tag| -> Vec<InMemDicomObject> {
        o.element(tag)
            .map_or(Vec::new(), |e| e.items().unwrap().to_vec())
    };
    let code_of = |o: &InMemDicomObject, tag| {
        items(o, tag).first().map(|c| {
            c.element(tags::CODE_VALUE)
                .unwrap()
                .to_str()
                .unwrap()
                .trim()
                .to_string()
        })
    };
    let concept = |o: &InMemDicomObject| code_of(o, tags::CONCEPT_NAME_CODE_SEQUENCE).unwrap();
    let child = |o: &InMemDicomObject, code: &str| -> Vec<InMemDicomObject> {
        items(o, tags::CONTENT_SEQUENCE)
            .into_iter()
            .filter(|c| concept(c) == code)
            .collect()
    };
    let root: &InMemDicomObject = &obj;
    assert_eq!(concept(root), "126000");
    let groups = child(&child(root, "126010")[0], "125007");
    assert_eq!(groups.len(), want.len());
    let coordinates = |n: &InMemDicomObject| {
        let s = &child(n, "260753009")[0];
        let uid = s.element(tags::REFERENCED_FRAME_OF_REFERENCE_UID).unwrap();
        assert_eq!(
            uid.to_str().unwrap().trim_end_matches('\0'),
            study.frame_of_reference_uid
        );
        let kind = s.element(tags::GRAPHIC_TYPE).unwrap().to_str().unwrap();
        let data = s
            .element(tags::GRAPHIC_DATA)
            .unwrap()
            .to_multi_float64()
            .unwrap();
        let points: Vec<DVec3> = data
            .chunks(3)
            .map(|p| DVec3::new(p[0], p[1], p[2]))
            .collect();
        (kind.trim().to_string(), points)
    };
    let close = |a: &[DVec3], b: &[DVec3]| {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.distance(*q) < 2e-3)
    };
    let vessel = child(&groups[0], "397413000");
    let (kind, ends) = coordinates(&vessel[0]);
    assert_eq!(kind, "POLYLINE");
    let want_ends: Vec<DVec3> = widest["max_diameter_ends"]
        .as_array()
        .unwrap()
        .iter()
        .map(point)
        .collect();
    assert!(close(&ends, &want_ends), "{ends:?} {want_ends:?}");
    let (kind, at) = coordinates(&vessel[1]);
    assert_eq!(kind, "POINT");
    assert!(close(&at, &[point(&narrowest["centroid"])]));
    let (_, line) = coordinates(&child(&groups[0], "410668003")[0]);
    let centres: Vec<DVec3> = sections.iter().map(|s| point(&s["point"])).collect();
    assert!(close(&line, &centres), "the path, section by section");
    let (_, angle) = coordinates(&child(&groups[0], "1483009")[0]);
    let want_angle: Vec<DVec3> = m["angle"]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(point)
        .collect();
    assert!(close(&angle, &want_angle));
    // The image library: the series' 164 images, each once.
    let library = child(&child(root, "111028")[0], "126200");
    let mut listed: Vec<String> = child(&library[0], "260753009")
        .iter()
        .map(|i| {
            let r = &items(i, tags::REFERENCED_SOP_SEQUENCE)[0];
            r.element(tags::REFERENCED_SOP_INSTANCE_UID)
                .unwrap()
                .to_str()
                .unwrap()
                .trim_end_matches('\0')
                .to_string()
        })
        .collect();
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| {
            dicom_text(
                &dicom_object::open_file(e.unwrap().path()).unwrap(),
                tags::SOP_INSTANCE_UID,
            )
        })
        .collect();
    listed.sort();
    files.sort();
    assert_eq!(listed.len(), 164);
    assert_eq!(listed, files);
    // The standard's IOD checker and DCMTK's content-tree checks find nothing wrong.
    assert_eq!(iod_errors(&sr), Vec::<String>::new());
    assert_eq!(sr_errors(&sr), Vec::<String>::new());
    // The text says what was written.
    let t = measure_text(&series, &path, &["--report", sr_file], &tmp("report.csv"));
    assert!(
        t.contains(&format!("report: {sr_file} (a DICOM Structured Report of the CT's study, TID 1500): 1 measurement group, 5 measurements")),
        "{t}"
    );
    // A report another tool wrote (highdicom: a planar ROI and an image's measurements) is
    // read as it was written; a report is no image, and beside a series' images it is skipped,
    // named.
    if let Some(py) = python_with("highdicom") {
        let theirs = tmp("highdicom-report.dcm");
        let o = std::process::Command::new(&py)
            .arg(repo().join("crates/raystream/tests/highdicom_sr.py"))
            .args(["write", &series, theirs.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(o.status.success(), "highdicom: {}", stderr(&o));
        let o = run(&["info", theirs.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let got: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        assert_eq!(got["observers"], json!(["highdicom test"]));
        let groups = &got["groups"];
        assert_eq!(groups[0]["template"], "1410");
        assert_eq!(groups[0]["tracking_id"], "plaque 1");
        assert_eq!(groups[0]["finding"]["value"], "1522000");
        assert_eq!(groups[0]["finding_site"]["value"], "15825003");
        assert_eq!(
            groups[0]["region"],
            json!({"type": "POLYLINE", "points": 4})
        );
        assert_eq!(groups[0]["measurements"][0]["concept"], "42798000");
        assert_eq!(groups[0]["measurements"][0]["value"], 42.5);
        assert_eq!(groups[0]["measurements"][0]["unit"], "mm2");
        assert_eq!(
            groups[0]["evaluations"],
            json!([{"name": "Severity", "value": "Moderate"}])
        );
        assert_eq!(groups[1]["template"], "1501");
        assert_eq!(groups[1]["measurements"][0]["value"], 7.25);
        assert_eq!(groups[1]["measurements"][0]["derivation"], "56851009");
        assert_eq!(groups.as_array().unwrap().len(), 2);
    }
    std::fs::copy(&sr, dir.join("report.dcm")).unwrap();
    let beside = raystream_io::load_volume(&dir, &Default::default()).unwrap();
    std::fs::remove_file(dir.join("report.dcm")).unwrap();
    assert_eq!(beside.dims, [120, 126, 164]);
    assert!(
        beside
            .warnings
            .iter()
            .any(|w| w.contains("report.dcm") && w.contains("a DICOM Structured Report")),
        "{:?}",
        beside.warnings
    );
    refused(
        &["render", sr_file, "-o", tmp("report.png").to_str().unwrap()],
        "a DICOM Structured Report (measurements), not an image",
    );
    // Refused before any work: a name that is not .dcm, a CT not read from DICOM, a series
    // anonymised of its UIDs.
    refused(
        &[
            "measure",
            &series,
            "--path",
            &path,
            "--report",
            "findings.txt",
        ],
        "findings.txt: --report writes a DICOM Structured Report (.dcm)",
    );
    refuses_a_ct_it_cannot_reference("--report", sr_file);
}

/// The volume a closed, outward-facing mesh in millimetres encloses, ml.
fn enclosed_ml(mesh: &raystream_io::TriMesh) -> f64 {
    mesh.enclosed_volume() / 1000.0
}

/// `iso LABELS --segment`: the lumen and the wall that `measure --mask` labels on the chest CT,
/// as surfaces, from the NIfTI label map and from the DICOM Segmentation of the CT's series.
/// - The raw surface (`--smooth 0`) lies where the labels change: every vertex, taken back to
///   the label map's grid, is halfway between the centres of two neighbouring voxels, one of
///   the segment and one not, in the patient's millimetres.
/// - Every surface is closed and turns one way, outward: it encloses the segment's voxels'
///   volume (the lumen's within 1.5 %, raw and smoothed; the wall, a shell a voxel or two
///   thick whose every outer corner the marching cubes cut off, within 15 %). trimesh, an
///   independent reader, finds them watertight.
/// - The Segmentation gives the NIfTI's surfaces, named and coloured as its segments; a GLB
///   holds one node each, an OBJ an object each with its colour in a material library, a PLY
///   its vertices' colours.
/// - Simplified (`--simplify 0.3`), a surface keeps within 0.3 mm of the full one, closed,
///   with a third of its triangles or fewer.
/// - A colour table (3D Slicer's, ITK-SNAP's) names and colours the segments it lists, over a
///   Segmentation's own; `--segment` takes its names.
/// - A segment not there, a name no segment has, a CT, or two segments to one STL are refused.
#[test]
fn segments_become_closed_surfaces() {
    use raystream_math::Vec3;
    let dir = tmp("segsurf-series");
    chest_series(&dir);
    let path = aorta();
    let (seg, nii) = (tmp("segsurf.dcm"), tmp("segsurf.nii.gz"));
    let (seg_file, nii_file) = (seg.to_str().unwrap(), nii.to_str().unwrap());
    measure(
        dir.to_str().unwrap(),
        &path,
        &["--wall", "--mask", seg_file],
    );
    measure(&chest(), &path, &["--wall", "--mask", nii_file]);
    let labels = raystream_io::load_volume(&nii, &Default::default()).unwrap();
    let voxels = |l: f32| labels.data.iter().filter(|&&v| v == l).count();
    let voxel_ml = labels.voxel_ml();
    let iso = |input: &str, args: &[&str], name: &str| {
        let out = tmp(name);
        let mut all = vec!["iso", "--quiet", input, "-o", out.to_str().unwrap()];
        all.extend_from_slice(args);
        let o = run(&all);
        assert!(o.status.success(), "{all:?}: {}", stderr(&o));
        out
    };

    // The raw lumen: each vertex halfway between a lumen voxel and its neighbour outside it.
    let raw = raystream_io::load_mesh(&iso(
        nii_file,
        &["--segment", "1", "--smooth", "0"],
        "segsurf-raw.ply",
    ))
    .unwrap();
    assert!(raw.len() > 10_000, "{} triangles", raw.len());
    let [nx, ny, nz] = labels.dims;
    let label_at = |q: [i64; 3]| {
        let inside = (0..3).all(|a| q[a] >= 0 && (q[a] as usize) < labels.dims[a]);
        if inside {
            labels.at(q[0] as usize, q[1] as usize, q[2] as usize)
        } else {
            0.0
        }
    };
    for p in &raw.positions {
        let q = labels.world_to_index(p.as_dvec3()).to_array();
        let half: Vec<usize> = (0..3)
            .filter(|&a| (q[a] - q[a].floor() - 0.5).abs() < 1e-3)
            .collect();
        assert_eq!(half.len(), 1, "vertex {p} at voxel {q:?} of {nx}×{ny}×{nz}");
        let a = half[0];
        for (b, x) in q.iter().enumerate() {
            assert!(
                b == a || (x - x.round()).abs() < 1e-3,
                "vertex {p} at {q:?}"
            );
        }
        let lo = q.map(|x| x.round() as i64);
        let (mut below, mut above) = (lo, lo);
        below[a] = q[a].floor() as i64;
        above[a] = below[a] + 1;
        assert!(
            (label_at(below) == 1.0) != (label_at(above) == 1.0),
            "vertex {p} between voxels {below:?} and {above:?}, not on the lumen's edge"
        );
    }
    assert!(closed_and_oriented(&raw));
    let lumen_ml = voxels(1.0) as f64 * voxel_ml;
    let near = |got: f64, want: f64, within: f64, what: &str| {
        assert!(
            (got - want).abs() <= within * want,
            "{what}: {got:.2} ml for {want:.2} ml"
        )
    };
    near(enclosed_ml(&raw), lumen_ml, 0.015, "the raw lumen");

    // Simplified within 0.3 mm: a third of the triangles or fewer, each vertex one of the full
    // (smoothed) surface's, every vertex of which lies within 0.3 mm of it; still closed.
    let full =
        raystream_io::load_mesh(&iso(nii_file, &["--segment", "1"], "segsurf-full.ply")).unwrap();
    let simple = raystream_io::load_mesh(&iso(
        nii_file,
        &["--segment", "1", "--simplify", "0.3"],
        "segsurf-simple.ply",
    ))
    .unwrap();
    assert!(
        simple.len() * 3 < full.len(),
        "{} of {}",
        simple.len(),
        full.len()
    );
    let vertices: std::collections::HashSet<[u32; 3]> = full
        .positions
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect();
    assert!(
        simple
            .positions
            .iter()
            .all(|p| vertices.contains(&p.to_array().map(f32::to_bits)))
    );
    let d = raystream_volume::departure(&full.positions, &simple, 0.3);
    assert!(d <= 0.3, "departs {d} mm");
    assert!(closed_and_oriented(&simple));
    near(
        enclosed_ml(&simple),
        enclosed_ml(&full),
        0.02,
        "the simplified lumen",
    );
    refused(
        &[
            "iso",
            nii_file,
            "--segment",
            "1",
            "--simplify",
            "0",
            "-o",
            "x.ply",
        ],
        "'0': a distance in mm, above 0 and at most 1000",
    );

    // Both segments, smoothed (the default), one surface each: closed, outward, their volume.
    let both = iso(nii_file, &["--segment", "1,2"], "segsurf-nifti.glb");
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&both).unwrap();
    let names: Vec<&str> = shading.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["label 1", "label 2"]);
    let part = |mesh: &raystream_io::TriMesh, of: &[Option<u32>], k: u32| raystream_io::TriMesh {
        positions: mesh.positions.clone(),
        triangles: mesh
            .triangles
            .iter()
            .zip(of)
            .filter(|(_, m)| **m == Some(k))
            .map(|(t, _)| *t)
            .collect(),
    };
    // glTF's metres and axes back to LPS millimetres.
    let lps = |mesh: &raystream_io::TriMesh| raystream_io::TriMesh {
        positions: mesh
            .positions
            .iter()
            .map(|p| Vec3::new(p.x, -p.z, p.y) * 1000.0)
            .collect(),
        triangles: mesh.triangles.clone(),
    };
    let nifti_parts = [0, 1].map(|k| lps(&part(&mesh, &shading.material_of, k)));
    for (k, (p, within)) in nifti_parts.iter().zip([0.015, 0.15]).enumerate() {
        assert!(closed_and_oriented(p), "segment {}", k + 1);
        let want = voxels(k as f32 + 1.0) as f64 * voxel_ml;
        near(enclosed_ml(p), want, within, &format!("segment {}", k + 1));
    }

    // The Segmentation alone: all its segments, named and coloured as it says, the same
    // surfaces as the NIfTI's.
    let from_seg = iso(seg_file, &[], "segsurf-seg.glb");
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&from_seg).unwrap();
    let names: Vec<&str> = shading.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["Lumen", "Wall and thrombus"]);
    assert_eq!(shading.materials[0].diffuse, Some([0.0, 1.0, 1.0]));
    assert_eq!(shading.materials[1].diffuse, Some([1.0, 0.0, 1.0]));
    for (k, want) in nifti_parts.iter().enumerate() {
        let got = lps(&part(&mesh, &shading.material_of, k as u32));
        assert_eq!(got.len(), want.len(), "segment {}", k + 1);
        for i in 0..got.len() {
            for (a, b) in got.corners(i).iter().zip(want.corners(i)) {
                assert!((*a - b).length() < 1e-3, "segment {}: {a} for {b}", k + 1);
            }
        }
    }

    // `info` gives each segment's colour too, and what it is coded as.
    let o = run(&["info", seg_file, "--json"]);
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let sct = |value: &str, meaning: &str| serde_json::json!({"value": value, "scheme": "SCT", "meaning": meaning});
    let anatomy = sct("123037004", "Anatomical Structure");
    assert_eq!(
        info["segments"],
        serde_json::json!([
            {"number": 1, "label": "Lumen", "colour": [0, 255, 255], "category": anatomy,
             "type": sct("91747007", "Lumen"), "modifier": null, "region": null,
             "region_modifier": null},
            {"number": 2, "label": "Wall and thrombus", "colour": [255, 0, 255],
             "category": anatomy, "type": sct("59820001", "Blood vessel"), "modifier": null,
             "region": null, "region_modifier": null}
        ])
    );
    let text = stdout(&run(&["info", seg_file]));
    assert!(
        text.contains(
            "segment    1: Lumen (the voxels of value 1, shown in #00ffff; coded Lumen (SCT 91747007), in Anatomical Structure)"
        ),
        "{text}"
    );

    // OBJ: an object a segment, its colour in the library beside it; read back by name.
    let obj = iso(
        seg_file,
        &["--segment", "wall and thrombus,1"],
        "segsurf.obj",
    );
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&obj).unwrap();
    let names: Vec<&str> = shading.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["Wall_and_thrombus", "Lumen"]);
    assert_eq!(shading.materials[0].diffuse, Some([1.0, 0.0, 1.0]));
    let wall = part(&mesh, &shading.material_of, 0);
    assert_eq!(wall.len(), nifti_parts[1].len());

    // An independent reader: trimesh finds each GLB surface watertight, and a PLY's vertices in
    // their segment's colour.
    let ply = iso(seg_file, &[], "segsurf.ply");
    if let Some(py) = python_with("trimesh") {
        let o = std::process::Command::new(&py)
            .args([
                "-c",
                "import sys, trimesh\n\
                 s = trimesh.load(sys.argv[1])\n\
                 for name in sorted(s.geometry):\n\
                 \x20   g = s.geometry[name]\n\
                 \x20   print(name, g.is_watertight, g.is_winding_consistent, g.volume > 0)\n\
                 m = trimesh.load(sys.argv[2], process=False)\n\
                 print(sorted(set(map(tuple, m.visual.vertex_colors[:, :3].tolist()))))",
                from_seg.to_str().unwrap(),
                ply.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(
            stdout(&o),
            "Lumen True True True\nWall and thrombus True True True\n[(0, 255, 255), (255, 0, 255)]\n"
        );
    }

    // Names and colours from a colour table: 3D Slicer's over the NIfTI map, ITK-SNAP's over
    // the Segmentation's own; a segment named by it; a bad line refused, naming it.
    let slicer = tmp("segsurf.ctbl");
    std::fs::write(
        &slicer,
        "# Color table file\n0 Background 0 0 0 0\n1 aortic lumen 200 40 40 255\n2 aortic_wall 40 200 40 255\n",
    )
    .unwrap();
    let snap = tmp("segsurf-labels.txt");
    std::fs::write(
        &snap,
        "# ITK-SnAP Label Description File\n0 0 0 0 0 0 0 \"Clear Label\"\n2 10 20 30 1 1 1 \"wall\"\n",
    )
    .unwrap();
    let named = |input: &str, table: &std::path::Path, list: &str, name: &str| {
        let glb = iso(
            input,
            &["--colour-table", table.to_str().unwrap(), "--segment", list],
            name,
        );
        let (_, shading) = raystream_io::load_mesh_with_shading(&glb).unwrap();
        shading
            .materials
            .iter()
            .map(|m| (m.name.clone(), m.diffuse.unwrap()))
            .collect::<Vec<_>>()
    };
    let lin = |c: [u8; 3]| c.map(|c| raystream_io::SRGB_TO_LINEAR[c as usize]);
    assert_eq!(
        named(nii_file, &slicer, "all", "segsurf-slicer.glb"),
        [
            ("aortic lumen".to_string(), lin([200, 40, 40])),
            ("aortic_wall".to_string(), lin([40, 200, 40]))
        ]
    );
    assert_eq!(
        named(nii_file, &slicer, "Aortic_Wall", "segsurf-slicer-wall.glb"),
        [("aortic_wall".to_string(), lin([40, 200, 40]))]
    );
    // ITK-SNAP's table names label 2 only: label 1 keeps the Segmentation's name and colour.
    assert_eq!(
        named(seg_file, &snap, "all", "segsurf-snap.glb"),
        [
            ("Lumen".to_string(), [0.0, 1.0, 1.0]),
            ("wall".to_string(), lin([10, 20, 30]))
        ]
    );
    // `info` names the labels from the table too.
    let text = stdout(&run(&[
        "info",
        nii_file,
        "--colour-table",
        slicer.to_str().unwrap(),
    ]));
    let want = format!("label      1 (aortic lumen): {} voxels", voxels(1.0));
    assert!(text.contains(&want), "{text}");
    let bad = tmp("segsurf-bad.ctbl");
    std::fs::write(&bad, "1 lumen 1 2 3 255\n2 wall 1 2\n").unwrap();
    refused(
        &[
            "iso",
            nii_file,
            "--colour-table",
            bad.to_str().unwrap(),
            "-o",
            "x.glb",
        ],
        "segsurf-bad.ctbl: line 2: 4 fields",
    );

    // Refused, naming the file and what is there.
    let out = tmp("segsurf-refused.ply");
    let out = out.to_str().unwrap();
    refused(
        &["iso", nii_file, "--segment", "7", "-o", out],
        "--segment 7: no voxel holds label 7; the labels present are 1, 2",
    );
    refused(
        &["iso", seg_file, "--segment", "aorta", "-o", out],
        "--segment \"aorta\": no segment is named so (nor is it a number); the labels present are 1 (Lumen), 2 (Wall and thrombus)",
    );
    refused(
        &["iso", &chest(), "--segment", "1", "-o", out],
        "--segment takes a label map (whole numbers from 0)",
    );
    refused(
        &["iso", seg_file, "-o", tmp("segsurf.stl").to_str().unwrap()],
        "an STL file holds one surface here, not 2",
    );
    refused(
        &["iso", nii_file, "-o", out],
        "no surface at 300: the values range over 0 .. 2 (whole numbers from 0, as a label map's: give --segment)",
    );
}

/// An RT Structure Set written by rt-utils (each slice's boundary traced through its boundary
/// voxels' centres) from the lumen and wall label map, beside the CT series it was drawn on:
/// read back voxel for voxel, overlapping structures each whole; `info`, `iso` and `render`.
#[test]
fn structure_sets_are_laid_on_their_ct() {
    let Some(py) = python_with("rt_utils") else {
        return;
    };
    let root = tmp("rtstruct");
    std::fs::remove_dir_all(&root).ok();
    let ct = root.join("ct");
    chest_series(&ct);
    let nii = root.join("labels.nii.gz");
    measure(
        &chest(),
        &aorta(),
        &["--wall", "--mask", nii.to_str().unwrap()],
    );
    std::fs::create_dir_all(root.join("rt")).unwrap();
    let rt = root.join("rt/structures.dcm");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/rtutils_struct.py"))
        .args([&ct, &nii, &rt])
        .args(["Lumen=1:255,0,0", "Wall=2:0,0,255", "Aorta=1+2:200,200,0"])
        .output()
        .unwrap();
    assert!(o.status.success(), "rt-utils: {}", stderr(&o));
    let rt_file = rt.to_str().unwrap();

    // Each structure is exactly the voxels it was traced from: the wall's holes, and the
    // pieces one voxel wide, included.
    let labels = raystream_io::load_volume(&nii, &Default::default()).unwrap();
    let grid = raystream_io::load_volume(&ct, &Default::default()).unwrap();
    let set = raystream_io::StructureSet::read(&rt).unwrap();
    let (regions, warnings) = set.regions(&grid);
    assert!(warnings.is_empty(), "{warnings:?}");
    let [nx, ny, _] = grid.dims;
    let count = |l: &[f32]| labels.data.iter().filter(|v| l.contains(v)).count();
    for (roi, (region, held)) in
        set.rois
            .iter()
            .zip(regions.iter().zip([&[1.0][..], &[2.0], &[1.0, 2.0]]))
    {
        assert_eq!(region.voxels, count(held), "{}", roi.name);
        let [dx, dy, dz] = region.dims;
        for k in 0..dz {
            for j in 0..dy {
                for i in 0..dx {
                    let [a, b, c] = [i + region.lo[0], j + region.lo[1], k + region.lo[2]];
                    let want = held.contains(&labels.data[a + nx * (b + ny * c)]);
                    assert_eq!(
                        region.inside[i + dx * (j + dy * k)],
                        want,
                        "{} at {a} {b} {c}",
                        roi.name
                    );
                }
            }
        }
    }
    // As a label volume on the CT's grid: the aorta (the largest) painted first, the lumen and
    // the wall over it, which gives back the label map itself.
    let v = raystream_io::load_volume(&rt, &Default::default()).unwrap();
    assert_eq!(
        (v.dims, v.spacing, v.origin),
        (grid.dims, grid.spacing, grid.origin)
    );
    assert!(
        v.data == labels.data,
        "the label volume differs from the label map"
    );
    let both = count(&[1.0, 2.0]);
    assert!(
        v.warnings
            .iter()
            .any(|w| w.contains(&format!("{both} voxels lie in more than one structure"))),
        "{:?}",
        v.warnings
    );

    // `info`: each structure whole, named, in its colour.
    let o = run(&["info", "--json", rt_file]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let listed: Vec<(u64, u64, &str)> = info["labels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| {
            (
                l["value"].as_u64().unwrap(),
                l["voxels"].as_u64().unwrap(),
                l["name"].as_str().unwrap(),
            )
        })
        .collect();
    let (lumen, wall) = (count(&[1.0]) as u64, count(&[2.0]) as u64);
    assert_eq!(
        listed,
        [
            (1, lumen, "Lumen"),
            (2, wall, "Wall"),
            (3, lumen + wall, "Aorta")
        ]
    );
    let structures = &info["structure_set"]["structures"];
    assert_eq!(structures[2]["colour"], serde_json::json!([200, 200, 0]));
    assert_eq!(info["series"]["modality"], "RTSTRUCT");

    // `iso`: the aorta's surface encloses the lumen and the wall, though the label volume shows
    // none of its own voxels; each surface closed, in its structure's colour.
    let obj = root.join("structures.obj");
    let o = run(&[
        "iso",
        "--quiet",
        rt_file,
        "--smooth",
        "0",
        "-o",
        obj.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (mesh, shading) = raystream_io::load_mesh_with_shading(&obj).unwrap();
    let names: Vec<&str> = shading.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["Lumen", "Wall", "Aorta"]);
    for (m, srgb) in shading
        .materials
        .iter()
        .zip([[255, 0, 0], [0, 0, 255], [200, 200, 0]])
    {
        let linear = srgb.map(|c: usize| raystream_io::SRGB_TO_LINEAR[c]);
        let d = m.diffuse.unwrap();
        assert!(
            (0..3).all(|c| (d[c] - linear[c]).abs() < 1e-4),
            "{}: {d:?}",
            m.name
        );
    }
    let aorta_part = raystream_io::TriMesh {
        positions: mesh.positions.clone(),
        triangles: mesh
            .triangles
            .iter()
            .zip(&shading.material_of)
            .filter(|(_, m)| **m == Some(2))
            .map(|(t, _)| *t)
            .collect(),
    };
    assert!(closed_and_oriented(&aorta_part));
    let want = (lumen + wall) as f64 * grid.voxel_ml();
    let got = enclosed_ml(&aorta_part);
    assert!(
        (got - want).abs() < 0.015 * want,
        "{got:.2} ml for {want:.2}"
    );

    // `render --segment`: the aorta alone, in its colour.
    let png = root.join("aorta.png");
    let o = run(&[
        "render",
        "--quiet",
        "--device",
        "cpu",
        rt_file,
        "--segment",
        "aorta",
        "--size",
        "96x96",
        "--spp",
        "1",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let img = image::open(&png).unwrap().to_rgb8();
    let yellow = img
        .pixels()
        .filter(|p| p[0] > 60 && (p[0] as i32 - p[1] as i32).abs() < 8 && p[2] < p[0] / 3)
        .count();
    assert!(yellow > 300, "{yellow} yellow pixels");

    // `info CT --segmentation`: the CT's values in each segment. On the NIfTI CT and its map
    // (one grid) they are SimpleITK's label statistics, with numpy's median; through the
    // structure set laid on the CT's series they are the same, the aorta's those of the lumen
    // and the wall together; through the series' DICOM Segmentation (its own grid, cut to the
    // slices it holds: each CT voxel takes the nearest label voxel) too.
    let stats = |ct: &str, labels: &str| -> (Vec<serde_json::Value>, String) {
        let o = run(&["info", "--json", ct, "--segmentation", labels]);
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        let s = &v["segmentation"];
        (
            s["segments"].as_array().unwrap().clone(),
            s["matched_on"].as_str().unwrap().to_string(),
        )
    };
    let (from_map, how) = stats(&chest(), nii.to_str().unwrap());
    assert_eq!(how, "the CT's grid");
    let (from_rt, how) = stats(ct.to_str().unwrap(), rt_file);
    assert_eq!(how, "structures laid on the CT's grid");
    let seg = root.join("labels.dcm");
    let written = root.join("rt/written.dcm");
    let m = measure(
        ct.to_str().unwrap(),
        &aorta(),
        &[
            "--wall",
            "--mask",
            seg.to_str().unwrap(),
            "--structures",
            written.to_str().unwrap(),
        ],
    );
    // `--structures`: raystream's own structure set of the lumen and the wall. Read back, each
    // structure is its label's voxels exactly; each slice's contours (holes turning the other
    // way) enclose its voxels' area; it passes dciodvfy, and rt-utils reads its names.
    let set = raystream_io::StructureSet::read(&written).unwrap();
    let contours = &m["mask"]["structures"]["contours"];
    let (regions, notes) = set.regions(&grid);
    assert!(notes.is_empty(), "{notes:?}");
    let pixel_mm2 = grid.spacing[0] * grid.spacing[1];
    for (r, (roi, v)) in set.rois.iter().zip(&regions).enumerate() {
        let value = r as f32 + 1.0;
        assert_eq!(roi.contours.len() as u64, contours[r].as_u64().unwrap());
        assert_eq!(v.voxels, count(&[value]), "{}", roi.name);
        let [dx, dy, dz] = v.dims;
        for n in 0..dx * dy * dz {
            let (i, j, k) = (
                n % dx + v.lo[0],
                (n / dx) % dy + v.lo[1],
                n / (dx * dy) + v.lo[2],
            );
            assert_eq!(
                v.inside[n],
                labels.at(i, j, k) == value,
                "{} at {i} {j} {k}",
                roi.name
            );
        }
        let mut by_slice: std::collections::BTreeMap<i64, f64> = Default::default();
        for c in &roi.contours {
            let idx: Vec<DVec3> = c.iter().map(|&p| grid.world_to_index(p)).collect();
            let signed: f64 = (0..idx.len())
                .map(|n| {
                    let (a, b) = (idx[n], idx[(n + 1) % idx.len()]);
                    a.x * b.y - b.x * a.y
                })
                .sum();
            *by_slice.entry(idx[0].z.round() as i64).or_default() += 0.5 * signed * pixel_mm2;
        }
        for (k, area) in by_slice {
            let held = (0..grid.dims[1])
                .flat_map(|j| (0..grid.dims[0]).map(move |i| (i, j)))
                .filter(|&(i, j)| labels.at(i, j, k as usize) == value)
                .count();
            assert!(
                (area - held as f64 * pixel_mm2).abs() < 1e-6 * area.abs().max(1.0),
                "{} slice {k}: {area} mm² for {held} voxels",
                roi.name
            );
        }
    }
    let problems = iod_errors(&written);
    assert!(problems.is_empty(), "dciodvfy: {problems:?}");
    let o = std::process::Command::new(&py)
        .args([
            "-c",
            "import sys; from rt_utils import RTStructBuilder\n\
             rt = RTStructBuilder.create_from(dicom_series_path=sys.argv[1], rt_struct_path=sys.argv[2])\n\
             print(rt.get_roi_names())",
        ])
        .args([&ct, &written])
        .output()
        .unwrap();
    assert!(o.status.success(), "rt-utils: {}", stderr(&o));
    assert_eq!(stdout(&o).trim(), "['Lumen', 'Wall and thrombus']");
    // Without --mask, the same structures; from a NIfTI CT (no series to reference), refused.
    let alone_written = root.join("rt/written-alone.dcm");
    let m2 = measure(
        ct.to_str().unwrap(),
        &aorta(),
        &["--wall", "--structures", alone_written.to_str().unwrap()],
    );
    assert!(m2["mask"]["file"].is_null());
    assert_eq!(m2["mask"]["structures"]["contours"], *contours);
    let again = raystream_io::StructureSet::read(&alone_written).unwrap();
    assert!(
        again.regions(&grid).0 == regions,
        "the structures differ without --mask"
    );
    refused(
        &[
            "measure",
            &chest(),
            "--path",
            &aorta(),
            "--structures",
            alone_written.to_str().unwrap(),
        ],
        "no series for an RT Structure Set to reference",
    );
    let (from_series, how) = stats(ct.to_str().unwrap(), seg.to_str().unwrap());
    assert!(how.starts_with("the nearest label voxel"), "{how}");
    let close = |a: &serde_json::Value, b: &serde_json::Value, what: &str| {
        for k in ["voxels", "mean", "sd", "min", "median", "max"] {
            let (x, y) = (a[k].as_f64().unwrap(), b[k].as_f64().unwrap());
            assert!(
                (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                "{what} {k}: {x} vs {y}"
            );
        }
        for c in 0..3 {
            let (x, y) = (
                a["centroid"][c].as_f64().unwrap(),
                b["centroid"][c].as_f64().unwrap(),
            );
            assert!((x - y).abs() < 1e-6, "{what} centroid: {x} vs {y}");
        }
    };
    assert_eq!(
        (from_map.len(), from_rt.len(), from_series.len()),
        (2, 3, 2)
    );
    for l in 0..2 {
        close(&from_rt[l], &from_map[l], "structure set");
        close(&from_series[l], &from_map[l], "Segmentation");
    }
    if let Some(sitk) = python_with("SimpleITK") {
        let o = std::process::Command::new(&sitk)
            .args([
                "-c",
                "import sys, json, numpy as np, SimpleITK as sitk\n\
                 ct = sitk.ReadImage(sys.argv[1])\n\
                 lab = sitk.Cast(sitk.ReadImage(sys.argv[2]), sitk.sitkUInt8)\n\
                 union = sitk.Cast(lab > 0, sitk.sitkUInt8) * 3\n\
                 hu = sitk.GetArrayFromImage(ct).astype(float)\n\
                 out = []\n\
                 for img, l in [(lab, 1), (lab, 2), (union, 3)]:\n\
                 \x20   st = sitk.LabelStatisticsImageFilter(); st.Execute(ct, img)\n\
                 \x20   sh = sitk.LabelShapeStatisticsImageFilter(); sh.Execute(img)\n\
                 \x20   m = sitk.GetArrayFromImage(img) == l\n\
                 \x20   out.append(dict(voxels=st.GetCount(l), mean=st.GetMean(l), sd=st.GetSigma(l),\n\
                 \x20       min=st.GetMinimum(l), max=st.GetMaximum(l), median=float(np.median(hu[m])),\n\
                 \x20       centroid=list(sh.GetCentroid(l))))\n\
                 print(json.dumps(out))",
                &chest(),
                nii.to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        let want: Vec<serde_json::Value> = serde_json::from_str(&stdout(&o)).unwrap();
        close(&from_map[0], &want[0], "SimpleITK lumen");
        close(&from_map[1], &want[1], "SimpleITK wall");
        close(&from_rt[2], &want[2], "SimpleITK aorta");
    }

    // Laid over a slice of the CT (`render --segmentation`), each structure in its own
    // colour where the NIfTI map's labels tint it in the default ones; `--outline`: each
    // structure's edge in its colour, the pixels within unchanged.
    let slice = [
        ct.to_str().unwrap(),
        "--mode",
        "slice",
        "--view",
        "anterior",
        "--slice-at",
        "26,-113,700",
        "--size",
        "96x128",
    ];
    let picture = |name: &str, more: &[&str]| {
        image::open(render_to(name, "cpu", &[&slice[..], more].concat()))
            .unwrap()
            .to_rgb8()
    };
    let plain = picture("rt-slice.png", &[]);
    let by_map = picture(
        "rt-slice-map.png",
        &["--segmentation", nii.to_str().unwrap()],
    );
    let filled = picture("rt-slice-fill.png", &["--segmentation", rt_file]);
    let outlined = picture(
        "rt-slice-outline.png",
        &["--segmentation", rt_file, "--outline"],
    );
    let own = [[255, 0, 0], [0, 0, 255]];
    let (w, h) = plain.dimensions();
    // Each pixel's label, read off the map's tint.
    let label: Vec<u32> = plain
        .pixels()
        .zip(by_map.pixels())
        .map(|(b, t)| {
            (0..3u32)
                .find(|&l| {
                    t.0 == match l {
                        0 => b.0,
                        l => blend(b.0, [[0, 230, 255], [255, 64, 220]][l as usize - 1]),
                    }
                })
                .unwrap_or_else(|| panic!("{:?} over {:?}", t.0, b.0))
        })
        .collect();
    let (mut inside, mut edges) = (0, 0);
    for n in 0..(w * h) as usize {
        let (x, y) = (n as u32 % w, n as u32 / w);
        let (b, l) = (plain.get_pixel(x, y).0, label[n]);
        let want = if l == 0 {
            b
        } else {
            blend(b, own[l as usize - 1])
        };
        assert_eq!(
            filled.get_pixel(x, y).0,
            want,
            "filled ({x}, {y}), label {l}"
        );
        let beside = [(-1, 0), (1, 0), (0, -1), (0, 1)].map(|(dx, dy)| {
            let (a, b) = (x as i64 + dx, y as i64 + dy);
            ((0..w as i64).contains(&a) && (0..h as i64).contains(&b))
                .then(|| label[(a + b * w as i64) as usize])
        });
        let edge = l > 0 && beside.iter().any(|&m| m != Some(l));
        let want = if edge { own[l as usize - 1] } else { b };
        assert_eq!(
            outlined.get_pixel(x, y).0,
            want,
            "outlined ({x}, {y}), label {l}"
        );
        inside += usize::from(l > 0 && !edge);
        edges += usize::from(edge);
    }
    assert!(
        inside > 300 && edges > 100,
        "{inside} inside, {edges} on edges"
    );
    // A colour table's colours over the map's defaults (label 2 it leaves alone); without a
    // segmentation to name, refused.
    let table = root.join("colours.ctbl");
    std::fs::write(&table, "1 lumen 40 200 40 255\n").unwrap();
    let tabled = picture(
        "rt-slice-table.png",
        &[
            "--segmentation",
            nii.to_str().unwrap(),
            "--colour-table",
            table.to_str().unwrap(),
        ],
    );
    for (n, (px, b)) in tabled.pixels().zip(plain.pixels()).enumerate() {
        let want = match label[n] {
            0 => b.0,
            1 => blend(b.0, [40, 200, 40]),
            _ => blend(b.0, [255, 64, 220]),
        };
        assert_eq!(px.0, want, "pixel {n} with the table's colours");
    }
    refused(
        &[
            &["render"][..],
            &slice,
            &["--colour-table", table.to_str().unwrap(), "-o", "x.png"],
        ]
        .concat(),
        "names the labels of --segment or --segmentation",
    );

    // A DICOM Segmentation whose segments overlap (highdicom's: lumen, wall, and the vessel
    // over both) is taken whole as the structure set is: `info` counts, `info --segmentation`
    // statistics, `iso` surfaces.
    if let Some(hd) = python_with("highdicom") {
        let seg = root.join("overlap.dcm");
        let o = std::process::Command::new(&hd)
            .arg(repo().join("crates/raystream/tests/highdicom_seg.py"))
            .args([&ct, &nii, &seg])
            .arg("OVERLAP")
            .output()
            .unwrap();
        assert!(o.status.success(), "highdicom: {}", stderr(&o));
        let seg_file = seg.to_str().unwrap();
        let o = run(&["info", "--json", seg_file]);
        assert!(o.status.success(), "{}", stderr(&o));
        let info: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        let counts: Vec<u64> = info["labels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| l["voxels"].as_u64().unwrap())
            .collect();
        assert_eq!(counts, [lumen, wall, lumen + wall]);
        assert!(
            info["warnings"][0]
                .as_str()
                .unwrap()
                .contains("held by more than one segment"),
            "{}",
            info["warnings"]
        );
        // The lumen's Anatomic Region and its modifier, in the JSON and the text.
        let sct = |value: &str, meaning: &str| serde_json::json!({"value": value, "scheme": "SCT", "meaning": meaning});
        assert_eq!(
            info["segments"][0]["region"],
            sct("73634005", "Common iliac artery")
        );
        assert_eq!(
            info["segments"][0]["region_modifier"],
            sct("24028007", "Right")
        );
        assert_eq!(info["segments"][1]["region"], serde_json::Value::Null);
        let text = stdout(&run(&["info", seg_file]));
        assert!(
            text.contains(
                "coded Lumen (SCT 91747007), site Common iliac artery, Right (SCT 73634005), in Anatomical Structure)"
            ),
            "{text}"
        );
        let (from_seg, _) = stats(ct.to_str().unwrap(), seg_file);
        for l in 0..3 {
            close(&from_seg[l], &from_rt[l], "overlapping Segmentation");
        }
        let vessel = root.join("vessel.obj");
        let o = run(&[
            "iso",
            "--quiet",
            seg_file,
            "--segment",
            "vessel",
            "--smooth",
            "0",
            "-o",
            vessel.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let mesh = raystream_io::load_mesh(&vessel).unwrap();
        assert!(closed_and_oriented(&mesh));
        let got = enclosed_ml(&mesh);
        assert!(
            (got - want).abs() < 0.015 * want,
            "{got:.2} ml for {want:.2}"
        );
    }

    // Laid on a scan of another Frame of Reference: refused.
    let other = shared().join("data/volumes/dicom/abdomen_ct_j2k_totalseg");
    refused(
        &["info", other.to_str().unwrap(), "--segmentation", rt_file],
        "they were drawn on another scan",
    );

    // Its series' UID blanked (as some anonymisers do): found by its Frame of Reference.
    let blank = root.join("rt/blank.dcm");
    let o = std::process::Command::new(&py)
        .arg(repo().join("crates/raystream/tests/rtutils_struct.py"))
        .args([&ct, &nii, &blank])
        .args(["--blank-series", "Lumen=1:255,0,0"])
        .output()
        .unwrap();
    assert!(o.status.success(), "rt-utils: {}", stderr(&o));
    let v = raystream_io::load_volume(&blank, &Default::default()).unwrap();
    assert_eq!(v.data.iter().filter(|&&x| x == 1.0).count(), lumen as usize);
    assert!(
        v.warnings[0].contains("found by its Frame of Reference: it names no series"),
        "{:?}",
        v.warnings
    );

    // Without its CT beside it, it is refused, saying where it looked; over a CT given, it is
    // laid on that CT (the same picture), and refused over a scan of another Frame of
    // Reference.
    let alone = tmp("rtstruct-alone/rt/structures.dcm");
    std::fs::create_dir_all(alone.parent().unwrap()).unwrap();
    std::fs::copy(&rt, &alone).unwrap();
    let o = run(&["info", alone.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("structures.dcm")
            && stderr(&o).contains("neither in its folder nor in a folder beside it"),
        "{}",
        stderr(&o)
    );
    let over_given = picture(
        "rt-slice-alone.png",
        &["--segmentation", alone.to_str().unwrap()],
    );
    assert!(
        over_given == filled,
        "laid on the CT given, the picture differs"
    );
    let mut abdomen = slice.to_vec();
    let other = shared().join("data/volumes/dicom/abdomen_ct_j2k_totalseg");
    abdomen[0] = other.to_str().unwrap();
    refused(
        &[
            &["render"][..],
            &abdomen,
            &["--segmentation", alone.to_str().unwrap(), "-o", "x.png"],
        ]
        .concat(),
        "they were drawn on another scan",
    );
}

/// `colour` over `base` as `render --segmentation` tints a pixel: 45 % of it, rounded.
fn blend(base: [u8; 3], colour: [u8; 3]) -> [u8; 3] {
    std::array::from_fn(|i| (base[i] as f32 * 0.55 + colour[i] as f32 * 0.45).round() as u8)
}

/// `--legend`: the segments drawn in colour listed in the top left corner, a swatch of each
/// segment's colour (label 1 cyan, 2 magenta: `--segmentation`'s tints) beside its name, on
/// a dvr frame coloured by `measure --mask`'s lumen and wall, on a slice tinted by them and on
/// the mask's own surfaces; nothing outside the top left quarter changes. Without segments
/// in colour, in a projection and into an EXR it is refused.
#[test]
fn a_legend_names_the_segments_in_colour() {
    let (vol, mask) = chest_and_mask("legend-mask.nii.gz");
    let m = mask.to_str().unwrap();
    let (w, h) = (240u32, 320u32);
    // Where the swatches lie, written out: text a 28th of the height (at least 12 pixels),
    // swatches that high, half of it from the edges, a row a third more apart.
    let t = (h / 28).max(12);
    let swatch = |i: u32| (t / 2 + t / 2, t / 2 + i * (t + t / 3) + t / 2);
    let cases: [(&str, Vec<&str>); 3] = [
        (
            "dvr",
            vec![
                &vol[..],
                "--mode",
                "dvr",
                "--preset",
                "ct-aaa",
                "--view",
                "posterior",
                "--segmentation",
                m,
            ],
        ),
        (
            "slice",
            vec![
                &vol[..],
                "--mode",
                "slice",
                "--view",
                "left",
                "--segmentation",
                m,
            ],
        ),
        ("surfaces", vec![m, "--segment", "all", "--spp", "1"]),
    ];
    for (name, args) in &cases {
        let size = ["--size", "240x320"];
        let plain = render_to(
            &format!("legend-{name}-plain.png"),
            "cpu",
            &[&args[..], &size].concat(),
        );
        let listed = render_to(
            &format!("legend-{name}.png"),
            "cpu",
            &[&args[..], &size, &["--legend"]].concat(),
        );
        let (p, l) = (
            image::open(&plain).unwrap().to_rgb8(),
            image::open(&listed).unwrap().to_rgb8(),
        );
        for (i, colour) in [[0, 230, 255], [255, 64, 220]].into_iter().enumerate() {
            let (x, y) = swatch(i as u32);
            assert_eq!(l.get_pixel(x, y).0, colour, "{name}: swatch {i}");
        }
        let mut changed = 0;
        for (x, y, q) in l.enumerate_pixels() {
            if q != p.get_pixel(x, y) {
                changed += 1;
                assert!(x < w / 2 && y < h / 4, "{name}: ({x}, {y}) changed");
            }
        }
        assert!(changed > 2 * t * t, "{name}: {changed} pixels");
    }
    for (args, why) in [
        (
            vec![&vol[..], "--mode", "dvr", "--legend"],
            "give --segmentation LABELS",
        ),
        (
            vec![
                &vol[..],
                "--mode",
                "mip",
                "--segmentation",
                m,
                "--segment",
                "1",
                "--legend",
            ],
            "--mode mip shows HU",
        ),
        (
            vec![
                &vol[..],
                "--mode",
                "average",
                "--segmentation",
                m,
                "--segment",
                "1",
                "--legend",
            ],
            "--mode average shows HU",
        ),
        (
            vec![
                &vol[..],
                "--mode",
                "dvr",
                "--segmentation",
                m,
                "--legend",
                "-o",
                "x.exr",
            ],
            "--legend draws on a PNG",
        ),
        (vec![&vol[..], "--legend"], "give --segment LIST"),
    ] {
        let mut all = vec!["render", "-q"];
        all.extend(&args);
        if !args.contains(&"-o") {
            all.extend(["-o", "x.png"]);
        }
        let o = run(&all);
        assert_eq!(o.status.code(), Some(2), "{all:?}");
        assert!(stderr(&o).contains(why), "{all:?}: {}", stderr(&o));
    }
}
