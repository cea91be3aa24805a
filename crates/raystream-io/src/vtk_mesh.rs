//! Legacy VTK polygonal data (`.vtk`, `DATASET POLYDATA`): 3D Slicer's default model format,
//! and what VTK and ParaView write for a surface. Binary (big-endian) or ASCII; the cells as
//! file versions up to 4.2 write them (`POLYGONS n size`, each cell its count then its points)
//! or as 5.1 does (`OFFSETS` and `CONNECTIVITY` arrays). Polygons become triangle fans and
//! strips triangles (every other one turned, as VTK turns them); vertices and lines are left
//! out with a warning. Point normals (`POINT_DATA` … `NORMALS`) are kept. Written by hand (see
//! [`crate::vtk_legacy`]).

use std::path::Path;

use crate::volume::raw::{Scalar, value};
use crate::vtk_legacy::{Cursor, header, scalar_of};
use crate::{MeshError, TriMesh, Vec3};

/// A polygonal data file's surface: its triangles, its point normals where it gives them (one
/// a point), and warnings.
pub(crate) struct PolyData {
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
    pub warnings: Vec<String>,
}

/// The numbers of `n` values of `scalar`: binary (big-endian) or text.
fn numbers(
    c: &mut Cursor,
    n: usize,
    scalar: Scalar,
    binary: bool,
    what: &str,
) -> Result<Vec<f64>, String> {
    if !binary {
        return c.text(n, what);
    }
    let bytes = c.binary(n, scalar.size(), what)?;
    // Each value exactly (an index beyond f32's 2²⁴ stays whole).
    Ok(bytes
        .chunks_exact(scalar.size())
        .map(|b| value(b, scalar, true))
        .collect())
}

/// A count from a header word: a whole number no larger than the file could hold.
fn count(word: Option<&&str>, bytes: usize, what: &str) -> Result<usize, String> {
    word.and_then(|w| w.parse::<usize>().ok())
        .filter(|&n| n <= bytes)
        .ok_or_else(|| {
            format!(
                "VTK {what} count {:?} is not a whole number the file could hold",
                word.copied().unwrap_or("")
            )
        })
}

/// Parses a legacy VTK file's bytes as polygonal data.
pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<PolyData, MeshError> {
    parse_poly(bytes).map_err(|e| MeshError::invalid(path, e))
}

fn parse_poly(bytes: &[u8]) -> Result<PolyData, String> {
    let h = header(bytes)?;
    if h.dataset != "POLYDATA" {
        return Err(format!(
            "VTK DATASET {}: a mesh is polygonal data (DATASET POLYDATA); image data \
             (STRUCTURED_POINTS) is read as a volume",
            h.dataset
        ));
    }
    let (binary, mut c) = (h.binary, h.cursor);
    let mut points: Option<Vec<Vec3>> = None;
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut normals = Vec::new();
    let mut left_out = Vec::new();
    let size = bytes.len();
    while let Some(words) = c.next_words() {
        let keyword = words[0].to_ascii_uppercase();
        match keyword.as_str() {
            "POINTS" => {
                let n = count(words.get(1), size, "POINTS")?;
                let scalar = scalar_of(words.get(2).copied().unwrap_or("float"))?;
                let v = numbers(&mut c, 3 * n, scalar, binary, "the VTK points")?;
                if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                    return Err(format!(
                        "a VTK point has a coordinate that is not finite: {bad}"
                    ));
                }
                points = Some(
                    v.chunks_exact(3)
                        .map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32))
                        .collect(),
                );
            }
            "POLYGONS" | "TRIANGLE_STRIPS" | "VERTICES" | "LINES" => {
                let cells = cells(&mut c, &words, binary, size)?;
                let n_points = points.as_ref().map_or(0, Vec::len);
                for cell in &cells {
                    if let Some(&i) = cell.iter().find(|&&i| i >= n_points as u64) {
                        return Err(format!(
                            "a VTK {keyword} cell names point {i}, of {n_points} points"
                        ));
                    }
                    if matches!(keyword.as_str(), "POLYGONS" | "TRIANGLE_STRIPS") {
                        let strip = keyword == "TRIANGLE_STRIPS";
                        triangulate(strip, cell.len(), |k| cell[k] as u32, &mut triangles);
                    }
                }
                if matches!(keyword.as_str(), "VERTICES" | "LINES") && !cells.is_empty() {
                    left_out.push(format!("{} {}", cells.len(), keyword.to_lowercase()));
                }
            }
            "METADATA" => skip_metadata(&mut c),
            "FIELD" => skip_field(&mut c, &words, binary, size)?,
            "POINT_DATA" => {
                let n = count(words.get(1), size, "POINT_DATA")?;
                normals = point_normals(&mut c, n, binary)?;
                break;
            }
            // Cell data (per polygon) holds nothing a surface is drawn with here.
            "CELL_DATA" => break,
            other => return Err(format!("unexpected VTK keyword {other:?}")),
        }
    }
    let positions = points.ok_or("the VTK file has no POINTS")?;
    let warnings = left_out_warning(&left_out).into_iter().collect();
    if normals.len() != positions.len() {
        normals.clear();
    }
    Ok(PolyData {
        mesh: TriMesh {
            positions,
            triangles,
        },
        normals,
        warnings,
    })
}

/// The triangles of a polygon of `n` points (a fan about its first), or of a triangle strip's
/// (every other one turned, as VTK turns them), its `k`-th point `at(k)`, onto `out`.
pub(crate) fn triangulate(
    strip: bool,
    n: usize,
    at: impl Fn(usize) -> u32,
    out: &mut Vec<[u32; 3]>,
) {
    if strip {
        out.extend((2..n).map(|k| {
            if k % 2 == 0 {
                [at(k - 2), at(k - 1), at(k)]
            } else {
                [at(k - 1), at(k - 2), at(k)]
            }
        }));
    } else {
        out.extend((2..n).map(|k| [at(0), at(k - 1), at(k)]));
    }
}

/// The warning for the cells a surface leaves out (`["2 vertices", "1 lines"]`), if any.
pub(crate) fn left_out_warning(left_out: &[String]) -> Option<String> {
    (!left_out.is_empty()).then(|| {
        format!(
            "{} left out: only polygons and triangle strips are surfaces",
            left_out.join(" and ")
        )
    })
}

/// The cells after a `POLYGONS` (or strips, vertices, lines) line: as versions up to 4.2 write
/// them (`n size`, then each cell's count and points, 4-byte integers) or as 5.1 does (`n+1 m`,
/// then `OFFSETS type` and `CONNECTIVITY type` arrays).
fn cells(
    c: &mut Cursor,
    words: &[&str],
    binary: bool,
    size: usize,
) -> Result<Vec<Vec<u64>>, String> {
    let what = words[0];
    let first = count(words.get(1), size, what)?;
    let second = count(words.get(2), size, what)?;
    let whole = |v: f64| -> Result<u64, String> {
        (v >= 0.0 && v.fract() == 0.0 && v < 9.0e15)
            .then_some(v as u64)
            .ok_or_else(|| format!("VTK {what}: {v} is not a point's index"))
    };
    if c.next_line_starts_with("OFFSETS") {
        // `KEYWORD type`, then `n` values of that type.
        let array = |c: &mut Cursor, keyword: &str, n: usize| -> Result<Vec<f64>, String> {
            let line = c.words(&format!("{keyword} line"))?;
            if !line[0].eq_ignore_ascii_case(keyword) {
                return Err(format!("VTK {what}: {keyword} expected"));
            }
            let scalar = scalar_of(line.get(1).copied().unwrap_or("vtktypeint64"))?;
            let v = numbers(c, n, scalar, binary, &format!("the VTK {what} {keyword}"))?;
            skip_metadata_if_any(c);
            Ok(v)
        };
        let offsets = array(c, "OFFSETS", first)?;
        let connectivity = array(c, "CONNECTIVITY", second)?;
        let offsets: Vec<u64> = offsets.into_iter().map(whole).collect::<Result<_, _>>()?;
        let mut out = Vec::with_capacity(first.saturating_sub(1));
        for w in offsets.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            if a > b || b > connectivity.len() {
                return Err(format!(
                    "VTK {what}: offsets {a}..{b} run past the connectivity"
                ));
            }
            out.push(
                connectivity[a..b]
                    .iter()
                    .map(|&v| whole(v))
                    .collect::<Result<_, _>>()?,
            );
        }
        return Ok(out);
    }
    let flat = numbers(c, second, Scalar::I32, binary, "the VTK cells")?;
    skip_metadata_if_any(c);
    let mut out = Vec::with_capacity(first.min(flat.len()));
    let mut at = 0;
    for _ in 0..first {
        let k = whole(
            *flat
                .get(at)
                .ok_or_else(|| format!("VTK {what}: fewer cells than {first}"))?,
        )? as usize;
        let cell = flat
            .get(at + 1..at + 1 + k)
            .ok_or_else(|| format!("VTK {what}: a cell of {k} points runs past the list"))?;
        out.push(cell.iter().map(|&v| whole(v)).collect::<Result<_, _>>()?);
        at += 1 + k;
    }
    Ok(out)
}

/// Skips a `METADATA` block (VTK 8.1 and later write one after an array): its lines up to the
/// first empty one.
fn skip_metadata(c: &mut Cursor) {
    while let Some(line) = c.line() {
        if line.trim().is_empty() {
            break;
        }
    }
}

fn skip_metadata_if_any(c: &mut Cursor) {
    // A binary array ends with a line end of its own, before any METADATA line.
    while c.next_line_starts_with("\n") || c.next_line_starts_with("\r\n") {
        c.line();
    }
    if c.next_line_starts_with("METADATA") {
        c.line();
        skip_metadata(c);
    }
}

/// Skips a `FIELD name k` block: its arrays (`NAME COMPONENTS TUPLES TYPE`, then the values).
fn skip_field(c: &mut Cursor, words: &[&str], binary: bool, size: usize) -> Result<(), String> {
    for _ in 0..count(words.get(2), size, "FIELD")? {
        let array = c.words("FIELD array")?;
        let [_, components, tuples, type_name] = array[..] else {
            return Err(format!("VTK FIELD array line {:?}", array.join(" ")));
        };
        let n = count(Some(&components), size, "FIELD")?
            .checked_mul(count(Some(&tuples), size, "FIELD")?)
            .ok_or("VTK FIELD array too large")?;
        numbers(c, n, scalar_of(type_name)?, binary, "a VTK FIELD array")?;
        skip_metadata_if_any(c);
    }
    Ok(())
}

/// The point normals among the point attributes, if any (`n` points): `SCALARS` are passed
/// over, and reading stops at any other attribute, since nothing else is drawn with.
fn point_normals(c: &mut Cursor, n: usize, binary: bool) -> Result<Vec<Vec3>, String> {
    while let Some(words) = c.next_words() {
        match words[0].to_ascii_uppercase().as_str() {
            "NORMALS" => {
                let scalar = scalar_of(words.get(2).copied().unwrap_or("float"))?;
                let v = numbers(c, 3 * n, scalar, binary, "the VTK normals")?;
                return Ok(v
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32))
                    .collect());
            }
            "SCALARS" => {
                let scalar = scalar_of(words.get(2).copied().unwrap_or("float"))?;
                let k: usize = words.get(3).and_then(|k| k.parse().ok()).unwrap_or(1);
                if c.next_line_starts_with("LOOKUP_TABLE") {
                    c.line();
                }
                numbers(c, n.saturating_mul(k), scalar, binary, "VTK scalars")?;
                skip_metadata_if_any(c);
            }
            _ => break,
        }
    }
    Ok(Vec::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square (a quad polygon, two triangles as a fan), a triangle strip of four points
    /// (two triangles, the second turned), a line (left out), as file version 4.2 writes it, in
    /// ASCII and in binary; and as version 5.1 does (offsets and connectivity, METADATA after
    /// the points), with point normals.
    const POINTS: [[f32; 3]; 8] = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 2.0],
        [1.0, 0.0, 2.0],
        [0.0, 1.0, 2.0],
        [1.0, 1.0, 2.0],
    ];
    const WANT: [[u32; 3]; 4] = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [6, 5, 7]];

    fn ascii_42() -> String {
        let points: Vec<String> = POINTS
            .iter()
            .map(|p| format!("{} {} {}", p[0], p[1], p[2]))
            .collect();
        format!(
            "# vtk DataFile Version 4.2\n3D Slicer output. SPACE=RAS\nASCII\nDATASET POLYDATA\nPOINTS 8 float\n{}\n\nPOLYGONS 1 5\n4 0 1 2 3\nTRIANGLE_STRIPS 1 5\n4 4 5 6 7\nLINES 1 3\n2 0 7\n",
            points.join("\n")
        )
    }

    fn binary_42() -> Vec<u8> {
        let mut b =
            b"# vtk DataFile Version 4.2\nvtk output\nBINARY\nDATASET POLYDATA\nPOINTS 8 float\n"
                .to_vec();
        b.extend(POINTS.iter().flatten().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nPOLYGONS 1 5\n");
        b.extend([4i32, 0, 1, 2, 3].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nTRIANGLE_STRIPS 1 5\n");
        b.extend([4i32, 4, 5, 6, 7].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nLINES 1 3\n");
        b.extend([2i32, 0, 7].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nPOINT_DATA 8\nSCALARS s unsigned_char 1\nLOOKUP_TABLE default\n");
        b.extend([9u8; 8]);
        b.extend(b"\nNORMALS Normals float\n");
        b.extend(
            (0..8)
                .flat_map(|_| [0.0f32, 0.0, 1.0])
                .flat_map(|x| x.to_be_bytes()),
        );
        b.push(b'\n');
        b
    }

    fn binary_51() -> Vec<u8> {
        let mut b =
            b"# vtk DataFile Version 5.1\nvtk output\nBINARY\nDATASET POLYDATA\nPOINTS 8 double\n"
                .to_vec();
        b.extend(
            POINTS
                .iter()
                .flatten()
                .flat_map(|&x| (x as f64).to_be_bytes()),
        );
        b.extend(b"\nMETADATA\nINFORMATION 0\n\nPOLYGONS 2 4\nOFFSETS vtktypeint64\n");
        b.extend([0i64, 4].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nCONNECTIVITY vtktypeint64\n");
        b.extend([0i64, 1, 2, 3].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nTRIANGLE_STRIPS 2 4\nOFFSETS vtktypeint64\n");
        b.extend([0i64, 4].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nCONNECTIVITY vtktypeint64\n");
        b.extend([4i64, 5, 6, 7].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nCELL_DATA 2\nSCALARS c int 1\nLOOKUP_TABLE default\n");
        b.extend([1i32, 2].iter().flat_map(|x| x.to_be_bytes()));
        b.push(b'\n');
        b
    }

    #[test]
    fn polygonal_data_of_every_version_and_encoding() {
        for (what, bytes, normals, lines) in [
            ("ascii 4.2", ascii_42().into_bytes(), false, true),
            ("binary 4.2", binary_42(), true, true),
            ("binary 5.1", binary_51(), false, false),
        ] {
            let poly = parse(&bytes, Path::new("m.vtk")).unwrap_or_else(|e| panic!("{what}: {e}"));
            let points: Vec<[f32; 3]> = poly.mesh.positions.iter().map(|p| p.to_array()).collect();
            assert_eq!(points, POINTS, "{what}");
            assert_eq!(poly.mesh.triangles, WANT, "{what}");
            assert_eq!(poly.normals.len(), if normals { 8 } else { 0 }, "{what}");
            assert_eq!(
                poly.warnings.iter().any(|w| w.contains("1 lines left out")),
                lines,
                "{what}: {:?}",
                poly.warnings
            );
        }
        assert_eq!(
            crate::declared_space(ascii_42().as_bytes(), crate::MeshFormat::Vtk),
            Some(crate::PatientSpace::Ras)
        );
        // Named where a volume is wanted, it is called a mesh.
        let scratch = crate::tests::scratch_dir("vtk-mesh");
        let file = scratch.path().join("model.vtk");
        std::fs::write(&file, ascii_42()).unwrap();
        let e = crate::load_volume(&file, &Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("model.vtk") && e.contains("is a mesh, not a volume"),
            "{e}"
        );
    }

    #[test]
    fn damaged_polygonal_data_is_an_error_naming_the_file() {
        let refused = |bytes: &[u8], says: &str| {
            let e = parse(bytes, Path::new("bad.vtk"))
                .err()
                .unwrap()
                .to_string();
            assert!(e.starts_with("bad.vtk") && e.contains(says), "{says}: {e}");
        };
        let ascii = ascii_42();
        refused(
            ascii.replace("4 0 1 2 3", "4 0 1 2 8").as_bytes(),
            "names point 8, of 8",
        );
        refused(ascii.replace("1 1 0", "1 nan 0").as_bytes(), "not finite");
        refused(ascii.replace("0 1 0", "0 x 0").as_bytes(), "not a number");
        refused(
            ascii.replace("POINTS 8", "POINTS 99999999999").as_bytes(),
            "count",
        );
        refused(
            ascii.replace("POLYDATA", "STRUCTURED_POINTS").as_bytes(),
            "read as a volume",
        );
        refused(
            ascii.replace("POLYGONS 1 5", "POLYGONS 3 5").as_bytes(),
            "fewer cells",
        );
        refused(
            ascii
                .replace("POLYGONS 1 5\n4", "POLYGONS 1 5\n9")
                .as_bytes(),
            "runs past",
        );
        let b = binary_42();
        refused(&b[..120], "truncated");
        let b = binary_51();
        let at = b.windows(8).position(|w| w == b"OFFSETS ").unwrap();
        let mut cut = b[..at].to_vec();
        cut.extend(b"OFFSETS vtktypeint64\n");
        cut.extend([0i64, 9].iter().flat_map(|x| x.to_be_bytes()));
        cut.extend(b"\nCONNECTIVITY vtktypeint64\n");
        cut.extend([0i64, 1, 2, 3].iter().flat_map(|x| x.to_be_bytes()));
        refused(&cut, "run past the connectivity");
        // Truncated anywhere, and bit-flipped headers: errors or a mesh, never a panic.
        for cut in 0..b.len() {
            if let Err(e) = parse(&b[..cut], Path::new("cut.vtk")) {
                assert!(e.to_string().starts_with("cut.vtk"), "{e}");
            }
        }
        for at in 0..b.len() {
            for bit in [0x01u8, 0x20, 0x80] {
                let mut flipped = b.clone();
                flipped[at] ^= bit;
                let _ = parse(&flipped, Path::new("flip.vtk"));
            }
        }
    }
}
