//! Paths through a CT volume (a vessel's centreline, the spine's axis, a dental arch) for curved
//! planar reformation: the points in LPS millimetres, in order.
//!
//! Two formats:
//! - **3D Slicer markups** (`.json`, `.mrk.json`): the first markup of `markups` (a curve, a
//!   point list, a line), its `controlPoints`' `position`s in order, in its
//!   `coordinateSystem` (`LPS`, Slicer's default when absent, or `RAS`, turned to LPS). A
//!   `ClosedCurve` comes back to its first point. Points whose `positionStatus` is
//!   `undefined` or `missing` (not placed) are left out, as Slicer leaves them out of a
//!   curve.
//! - **Text** (any other name): one point a line, three numbers `x y z` (LPS mm) split by
//!   spaces, tabs or commas; `#` starts a comment. A first line naming its columns (Slicer's
//!   control-point table: `label,l,p,s,…` or `label,r,a,s,…`) says which columns hold the
//!   coordinates and in which system.
//!
//! Every error names the file and, for text, the line. A file larger than [`MAX_CURVE_BYTES`]
//! or with more than [`MAX_CURVE_POINTS`] points is refused before it is parsed in full.

use std::io::Read;
use std::path::Path;

use raystream_math::DVec3;

use crate::VolumeError;

/// The most points a path may have (a VMTK centreline of a whole aorta has a few thousand).
pub const MAX_CURVE_POINTS: usize = 100_000;

/// The largest path file read, in bytes.
pub const MAX_CURVE_BYTES: u64 = 64 << 20;

/// No point may lie further than this from the origin, mm (as a CT grid: a kilometre).
const MAX_COORDINATE_MM: f64 = 1e6;

/// Reads a path's points (LPS mm) from `path`: Slicer markups JSON or text (see the module).
/// At least two distinct points, each finite and within a kilometre of the origin.
pub fn read_curve(path: &Path) -> Result<Vec<DVec3>, VolumeError> {
    let file = std::fs::File::open(path).map_err(|e| VolumeError::io(path, e))?;
    let mut bytes = Vec::new();
    file.take(MAX_CURVE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| VolumeError::io(path, e))?;
    if bytes.len() as u64 > MAX_CURVE_BYTES {
        return Err(VolumeError::invalid(
            path,
            format!("a path file over {} MiB", MAX_CURVE_BYTES >> 20),
        ));
    }
    let text = String::from_utf8(bytes)
        .map_err(|_| VolumeError::invalid(path, "not a text file (not UTF-8)"))?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let points = if name.ends_with(".json") {
        markups(&text)
    } else {
        table(&text)
    }
    .map_err(|problem| VolumeError::invalid(path, problem))?;
    check(&points).map_err(|problem| VolumeError::invalid(path, problem))?;
    Ok(points)
}

/// RAS → LPS (and back): the first two axes flip.
fn ras_to_lps(p: DVec3) -> DVec3 {
    DVec3::new(-p.x, -p.y, p.z)
}

/// The points of Slicer's markups JSON.
fn markups(text: &str) -> Result<Vec<DVec3>, String> {
    let json: serde_json::Value =
        serde_json::from_str(text).map_err(|e| format!("not valid JSON ({e})"))?;
    let markup = json
        .get("markups")
        .and_then(|m| m.as_array())
        .and_then(|m| m.first())
        .ok_or("no 'markups' array with a markup (3D Slicer's markups JSON)")?;
    let ras = match markup.get("coordinateSystem").and_then(|c| c.as_str()) {
        None | Some("LPS") => false,
        Some("RAS") => true,
        Some(other) => {
            return Err(format!(
                "coordinateSystem '{other}': LPS or RAS (3D Slicer's markups JSON)"
            ));
        }
    };
    let list = markup
        .get("controlPoints")
        .and_then(|c| c.as_array())
        .ok_or("the markup has no 'controlPoints' array")?;
    if list.len() > MAX_CURVE_POINTS {
        return Err(format!(
            "{} control points: at most {MAX_CURVE_POINTS}",
            list.len()
        ));
    }
    let mut points = Vec::with_capacity(list.len());
    for (i, cp) in list.iter().enumerate() {
        let status = cp.get("positionStatus").and_then(|s| s.as_str());
        if matches!(status, Some("undefined" | "missing")) {
            continue;
        }
        let xyz: Option<Vec<f64>> = cp
            .get("position")
            .and_then(|p| p.as_array())
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect());
        let p = match xyz.as_deref() {
            Some(&[x, y, z]) => DVec3::new(x, y, z),
            _ => {
                return Err(format!(
                    "control point {} has no position of three numbers",
                    i + 1
                ));
            }
        };
        points.push(if ras { ras_to_lps(p) } else { p });
    }
    if markup.get("type").and_then(|t| t.as_str()) == Some("ClosedCurve")
        && let Some(&first) = points.first()
    {
        points.push(first);
    }
    Ok(points)
}

/// The points of a text table (see the module).
fn table(text: &str) -> Result<Vec<DVec3>, String> {
    // Which columns hold x, y, z, and whether they are RAS: three numbers from the first
    // column unless a header names them.
    let mut columns = ([0usize, 1, 2], false);
    let mut header_seen = false;
    let mut points = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|f| !f.is_empty())
            .collect();
        if !header_seen && points.is_empty() && fields.iter().any(|f| f.parse::<f64>().is_err()) {
            header_seen = true;
            columns = header(line)?;
            continue;
        }
        if points.len() == MAX_CURVE_POINTS {
            return Err(format!("more than {MAX_CURVE_POINTS} points"));
        }
        // A header's columns count the fields as the header splits them: by commas.
        let fields: Vec<&str> = if header_seen {
            line.split(',').map(str::trim).collect()
        } else {
            fields
        };
        let ([i, j, k], ras) = columns;
        if !header_seen && fields.len() != 3 {
            return Err(format!(
                "line {}: {} numbers; a point is three numbers x y z (LPS mm)",
                n + 1,
                fields.len()
            ));
        }
        let number = |c: usize| -> Result<f64, String> {
            let f = fields.get(c).copied().unwrap_or("");
            f.parse::<f64>()
                .map_err(|_| format!("line {}: '{f}' is not a number", n + 1))
        };
        let p = DVec3::new(number(i)?, number(j)?, number(k)?);
        points.push(if ras { ras_to_lps(p) } else { p });
    }
    Ok(points)
}

/// A header line's coordinate columns: `l,p,s` (LPS) or `r,a,s` (RAS), or `x,y,z` (LPS).
fn header(line: &str) -> Result<([usize; 3], bool), String> {
    let names: Vec<String> = line
        .split(',')
        .map(|f| f.trim().to_ascii_lowercase())
        .collect();
    let find = |n: &str| names.iter().position(|c| c == n);
    for (axes, ras) in [
        (["l", "p", "s"], false),
        (["r", "a", "s"], true),
        (["x", "y", "z"], false),
    ] {
        if let (Some(i), Some(j), Some(k)) = (find(axes[0]), find(axes[1]), find(axes[2])) {
            return Ok(([i, j, k], ras));
        }
    }
    Err(format!(
        "line 1 '{line}': neither three numbers nor a header naming the columns l,p,s or r,a,s (comma-separated, as 3D Slicer's control-point table)"
    ))
}

/// Every point finite and within reach, and at least two distinct ones.
fn check(points: &[DVec3]) -> Result<(), String> {
    for (i, p) in points.iter().enumerate() {
        if !p.is_finite() || p.abs().max_element() > MAX_COORDINATE_MM {
            return Err(format!(
                "point {} ({}, {}, {}): not a finite position within a kilometre of the origin",
                i + 1,
                p.x,
                p.y,
                p.z
            ));
        }
    }
    let first = points.first().copied().unwrap_or_default();
    if !points.iter().any(|&p| p != first) {
        return Err(format!(
            "{} point(s), none apart: a path needs two distinct points",
            points.len()
        ));
    }
    Ok(())
}

/// Writes `points` (LPS mm) as a path [`read_curve`] reads back: 3D Slicer markups JSON (an
/// open `Curve` in LPS, every point placed, `what` as its description) for a `.json` name, else
/// text, `x y z` a line under `#` lines saying what they are. Coordinates to the micrometre.
pub fn write_curve(path: &Path, points: &[DVec3], what: &str) -> Result<(), VolumeError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let micron = |v: f64| (v * 1e3).round() / 1e3;
    let text = if name.ends_with(".json") {
        let control: Vec<serde_json::Value> = points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                serde_json::json!({
                    "id": (i + 1).to_string(),
                    "label": format!("C-{}", i + 1),
                    "position": [micron(p.x), micron(p.y), micron(p.z)],
                    "positionStatus": "defined",
                })
            })
            .collect();
        let doc = serde_json::json!({
            "@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#",
            "markups": [{
                "type": "Curve",
                "coordinateSystem": "LPS",
                "coordinateUnits": "mm",
                "description": what,
                "controlPoints": control,
            }],
        });
        serde_json::to_string_pretty(&doc).expect("a JSON value serialises") + "\n"
    } else {
        let mut t = String::new();
        for line in what.lines() {
            t += &format!("# {line}\n");
        }
        t += "# x y z, LPS mm\n";
        for p in points {
            t += &format!("{:.3} {:.3} {:.3}\n", p.x, p.y, p.z);
        }
        t
    };
    std::fs::write(path, text).map_err(|e| VolumeError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(name: &str, text: &str) -> Result<Vec<DVec3>, String> {
        let scratch = crate::tests::scratch_dir("curve");
        let dir = scratch.path();
        let file = dir.join(name);
        std::fs::write(&file, text).unwrap();
        read_curve(&file).map_err(|e| e.to_string())
    }

    #[test]
    fn text_points_in_lps_with_comments_and_any_separator() {
        let p = read(
            "c.txt",
            "# a centreline\n1 2 3\n\n4,5,6   # second\n7\t8\t-9.5\n",
        )
        .unwrap();
        assert_eq!(
            p,
            [
                DVec3::new(1.0, 2.0, 3.0),
                DVec3::new(4.0, 5.0, 6.0),
                DVec3::new(7.0, 8.0, -9.5)
            ]
        );
    }

    #[test]
    fn a_slicer_table_names_its_columns_and_system() {
        let ras = "label,r,a,s,defined,selected,visible,locked,description\nF-1,1,2,3,1,1,1,0,\nF-2,4,5,6,1,1,1,0,\n";
        assert_eq!(
            read("c.csv", ras).unwrap(),
            [DVec3::new(-1.0, -2.0, 3.0), DVec3::new(-4.0, -5.0, 6.0)]
        );
        let lps = "label,l,p,s\nF-1,1,2,3\nF-2,4,5,6\n";
        assert_eq!(read("c.csv", lps).unwrap()[1], DVec3::new(4.0, 5.0, 6.0));
        let e = read("c.csv", "label,a,b,c\n1,2,3,4\n").unwrap_err();
        assert!(e.contains("c.csv") && e.contains("l,p,s"), "{e}");
    }

    #[test]
    fn slicer_markups_in_either_system() {
        let json = |system: &str, kind: &str| {
            format!(
                r#"{{"@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#",
                "markups": [{{"type": "{kind}", {system} "controlPoints": [
                  {{"label": "C-1", "position": [1.0, 2.0, 3.0], "positionStatus": "defined"}},
                  {{"label": "C-2", "position": [0.0, 0.0, 0.0], "positionStatus": "undefined"}},
                  {{"label": "C-3", "position": [4.0, 5.0, 6.0]}}]}}]}}"#
            )
        };
        let two = [DVec3::new(1.0, 2.0, 3.0), DVec3::new(4.0, 5.0, 6.0)];
        assert_eq!(read("c.mrk.json", &json("", "Curve")).unwrap(), two);
        let lps = json(r#""coordinateSystem": "LPS","#, "Curve");
        assert_eq!(read("c.mrk.json", &lps).unwrap(), two);
        let ras = json(r#""coordinateSystem": "RAS","#, "Curve");
        assert_eq!(
            read("c.mrk.json", &ras).unwrap(),
            two.map(|p| DVec3::new(-p.x, -p.y, p.z))
        );
        let closed = read("c.json", &json("", "ClosedCurve")).unwrap();
        assert_eq!(closed, [two[0], two[1], two[0]]);
        let odd = json(r#""coordinateSystem": "IJK","#, "Curve");
        assert!(read("c.json", &odd).unwrap_err().contains("IJK"));
    }

    #[test]
    fn bad_paths_are_errors_naming_the_file_and_place() {
        let cases = [
            ("a.txt", "1 2 3\n4 5\n", "line 2: 2 numbers"),
            ("a.txt", "1 2 3\n4 five 6\n", "'five' is not a number"),
            ("a.txt", "1 2 3\n", "two distinct points"),
            ("a.txt", "1 2 3\n1 2 3\n", "two distinct points"),
            ("a.txt", "", "two distinct points"),
            ("a.txt", "1 2 3\nNaN 0 0\n", "point 2"),
            ("a.txt", "1 2 3\n1e9 0 0\n", "within a kilometre"),
            ("a.json", "{\"markups\": [", "not valid JSON"),
            ("a.json", "{\"points\": []}", "'markups'"),
            (
                "a.json",
                "{\"markups\": [{\"type\": \"Curve\"}]}",
                "controlPoints",
            ),
            (
                "a.json",
                "{\"markups\": [{\"controlPoints\": [{\"position\": [1, 2]}]}]}",
                "control point 1",
            ),
        ];
        for (name, text, want) in cases {
            let e = read(name, text).unwrap_err();
            assert!(e.contains(name) && e.contains(want), "{text:?}: {e}");
        }
        let e = read_curve(Path::new("/nonexistent/path.txt")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/path.txt"), "{e}");
    }

    #[test]
    fn too_many_points_are_refused_before_they_are_kept() {
        let text = "0 0 0\n".repeat(MAX_CURVE_POINTS + 1);
        assert!(read("big.txt", &text).unwrap_err().contains("more than"));
    }

    #[test]
    fn a_written_path_reads_back_to_the_micrometre_in_either_format() {
        let scratch = crate::tests::scratch_dir("curve-w");
        let dir = scratch.path();
        let points = vec![
            DVec3::new(-12.3456789, 200.0001, -0.0004),
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(1e5, -1e5, 42.4242),
        ];
        for name in ["c.mrk.json", "c.txt"] {
            let file = dir.join(name);
            write_curve(&file, &points, "a test path\nof three points").unwrap();
            let back = read_curve(&file).unwrap();
            assert_eq!(back.len(), points.len(), "{name}");
            for (a, b) in back.iter().zip(&points) {
                assert!(
                    (*a - *b).abs().max_element() <= 5.0001e-4,
                    "{name}: {a} for {b}"
                );
            }
        }
        let e = write_curve(Path::new("/nonexistent/p.txt"), &points, "").unwrap_err();
        assert!(e.to_string().contains("/nonexistent/p.txt"), "{e}");
    }
}
