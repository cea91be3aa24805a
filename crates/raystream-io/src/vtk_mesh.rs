//! Legacy VTK polygonal data (`.vtk`, `DATASET POLYDATA`): 3D Slicer's default model format,
//! and what VTK and ParaView write for a surface. Binary (big-endian) or ASCII; the cells as
//! file versions up to 4.2 write them (`POLYGONS n size`, each cell its count then its points)
//! or as 5.1 does (`OFFSETS` and `CONNECTIVITY` arrays). Polygons become triangle fans and
//! strips triangles (every other one turned, as VTK turns them); vertices and lines are left
//! out with a warning. Point normals (`POINT_DATA` … `NORMALS`) are kept, and colours (the
//! point or cell data's first scalars, where RGB bytes). Written by hand (see
//! [`crate::vtk_legacy`]).

use std::path::Path;

use crate::volume::raw::{Scalar, value};
use crate::vtk_legacy::{Cursor, header, scalar_of};
use crate::{MeshError, Rgb8, TriMesh, Vec3};

/// A polygonal data file's surface: its triangles, its point normals where it gives them (one
/// a point), its triangles' corners' colours where it gives colours, and warnings.
pub(crate) struct PolyData {
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
    pub colours: Vec<[Rgb8; 3]>,
    /// The patient space the file names outside its title (a `.vtp`'s `SPACE` field, as 3D
    /// Slicer writes it).
    pub space: Option<crate::PatientSpace>,
    pub warnings: Vec<String>,
}

/// The colours of `n` items from an attribute array of `components` values an item, `value(i)`
/// the i-th: RGB or RGBA (the alpha not read), 8-bit where the array holds bytes, else 0 to 1
/// (a legacy file's ASCII `COLOR_SCALARS`). `None` for other component counts: those are no
/// colours (VTK maps them through a lookup table).
pub(crate) fn colours_of(
    n: usize,
    components: usize,
    bytes: bool,
    value: impl Fn(usize) -> f64,
) -> Option<Vec<Rgb8>> {
    if !matches!(components, 3 | 4) {
        return None;
    }
    let channel = |v: f64| {
        if bytes {
            v.clamp(0.0, 255.0) as u8
        } else {
            crate::unit_to_8bit(v)
        }
    };
    Some(
        (0..n)
            .map(|i| std::array::from_fn(|c| channel(value(i * components + c))))
            .collect(),
    )
}

/// Per triangle, its corners' colours: its points' where the points have colours (`point[v -
/// base]` for vertex `v`: a `.vtp` piece's points follow those of the pieces before), else its
/// cell's (`cell_of`: each triangle's cell, by its id in VTK's order), as VTK's mappers colour
/// by point scalars first; else none.
pub(crate) fn triangle_colours(
    triangles: &[[u32; 3]],
    base: u32,
    cell_of: &[usize],
    point: &[Rgb8],
    cell: &[Rgb8],
) -> Vec<[Rgb8; 3]> {
    if !point.is_empty() {
        triangles
            .iter()
            .map(|t| t.map(|v| point[(v - base) as usize]))
            .collect()
    } else if !cell.is_empty() {
        cell_of.iter().map(|&c| [cell[c]; 3]).collect()
    } else {
        Vec::new()
    }
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
    // Each triangle's cell: its section (0 vertices, 1 lines, 2 polygons, 3 strips) and its
    // place there, numbered as VTK numbers cells (those sections in that order) at the end.
    let mut cell_at: Vec<(usize, usize)> = Vec::new();
    let mut section_cells = [0usize; 4];
    let mut normals = Vec::new();
    let (mut point_colours, mut cell_colours) = (Vec::new(), Vec::new());
    let mut space = None;
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
                let section = ["VERTICES", "LINES", "POLYGONS", "TRIANGLE_STRIPS"]
                    .iter()
                    .position(|k| *k == keyword)
                    .unwrap_or(0);
                section_cells[section] = cells.len();
                for (k, cell) in cells.iter().enumerate() {
                    if let Some(&i) = cell.iter().find(|&&i| i >= n_points as u64) {
                        return Err(format!(
                            "a VTK {keyword} cell names point {i}, of {n_points} points"
                        ));
                    }
                    if section >= 2 {
                        triangulate(section == 3, cell.len(), |k| cell[k] as u32, &mut triangles);
                        cell_at.resize(triangles.len(), (section, k));
                    }
                }
                if section < 2 && !cells.is_empty() {
                    left_out.push(format!("{} {}", cells.len(), keyword.to_lowercase()));
                }
            }
            "METADATA" => skip_metadata(&mut c),
            "FIELD" => space = skip_field(&mut c, &words, binary, size)?.or(space),
            "POINT_DATA" | "CELL_DATA" => {
                let n = count(words.get(1), size, &keyword)?;
                let a = attributes(&mut c, n, binary, size)?;
                if keyword == "POINT_DATA" {
                    normals = a.normals;
                    point_colours = a.colours;
                } else {
                    cell_colours = a.colours;
                }
                if a.stopped {
                    break;
                }
            }
            other => return Err(format!("unexpected VTK keyword {other:?}")),
        }
    }
    let positions = points.ok_or("the VTK file has no POINTS")?;
    let warnings = left_out_warning(&left_out).into_iter().collect();
    if normals.len() != positions.len() {
        normals.clear();
    }
    if point_colours.len() != positions.len() {
        point_colours.clear();
    }
    let mut first_of = [0usize; 4];
    for s in 1..4 {
        first_of[s] = first_of[s - 1] + section_cells[s - 1];
    }
    let cell_of: Vec<usize> = cell_at.iter().map(|&(s, k)| first_of[s] + k).collect();
    if cell_colours.len() != first_of[3] + section_cells[3] {
        cell_colours.clear();
    }
    let colours = triangle_colours(&triangles, 0, &cell_of, &point_colours, &cell_colours);
    Ok(PolyData {
        mesh: TriMesh {
            positions,
            triangles,
        },
        normals,
        colours,
        space,
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

/// Skips a `FIELD name k` block: its arrays (`NAME COMPONENTS TUPLES TYPE`, then the values),
/// returning the patient space a `SPACE` string array names (`LPS` or `RAS`), if one does.
fn skip_field(
    c: &mut Cursor,
    words: &[&str],
    binary: bool,
    size: usize,
) -> Result<Option<crate::PatientSpace>, String> {
    let mut space = None;
    for _ in 0..count(words.get(2), size, "FIELD")? {
        let array = c.words("FIELD array")?;
        let [name, components, tuples, type_name] = array[..] else {
            return Err(format!("VTK FIELD array line {:?}", array.join(" ")));
        };
        let n = count(Some(&components), size, "FIELD")?
            .checked_mul(count(Some(&tuples), size, "FIELD")?)
            .ok_or("VTK FIELD array too large")?;
        if type_name.eq_ignore_ascii_case("string") || type_name.eq_ignore_ascii_case("utf8_string")
        {
            let strings = strings(c, n, binary)?;
            if name == "SPACE" {
                space = match strings.first().map(String::as_str) {
                    Some("LPS") => Some(crate::PatientSpace::Lps),
                    Some("RAS") => Some(crate::PatientSpace::Ras),
                    _ => space,
                };
            }
        } else {
            numbers(c, n, scalar_of(type_name)?, binary, "a VTK FIELD array")?;
        }
        skip_metadata_if_any(c);
    }
    Ok(space)
}

/// The `n` strings of a string array: a line each in an ASCII file; in a binary one, each its
/// length (big-endian, in 1, 2, 4 or 8 bytes, the first byte's top two bits saying which: 11,
/// 10, 01, 00) then its bytes, as VTK's writer puts them.
fn strings(c: &mut Cursor, n: usize, binary: bool) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for _ in 0..n {
        if !binary {
            let line = c.line().ok_or("the VTK file ends in a string array")?;
            out.push(line.to_string());
            continue;
        }
        let first = c.binary(1, 1, "a VTK string's length")?[0];
        let extra = match first >> 6 {
            3 => 0,
            2 => 1,
            1 => 3,
            _ => 7,
        };
        let mut len = u64::from(first & 0x3f);
        for &b in c.binary(extra, 1, "a VTK string's length")? {
            len = len << 8 | u64::from(b);
        }
        let len = usize::try_from(len).map_err(|_| "a VTK string's length is too large")?;
        let bytes = c.binary(len, 1, "a VTK string")?;
        out.push(String::from_utf8_lossy(bytes).into_owned());
    }
    Ok(out)
}

/// What a `POINT_DATA` or `CELL_DATA` section gives a surface.
struct Attributes {
    /// `NORMALS` (one an item), or empty.
    normals: Vec<Vec3>,
    /// The section's first scalars (VTK's active ones) where they are colours: `COLOR_SCALARS`,
    /// or `SCALARS` of unsigned char in three or four components; else empty.
    colours: Vec<Rgb8>,
    /// Whether reading stopped at an attribute it does not pass over (nothing after it is
    /// read).
    stopped: bool,
}

/// The attributes of `n` items, up to the next `POINT_DATA` or `CELL_DATA` line or the end of
/// the file. Vectors, texture coordinates, tensors, lookup tables and fields are passed over;
/// reading stops at anything else.
fn attributes(c: &mut Cursor, n: usize, binary: bool, size: usize) -> Result<Attributes, String> {
    let mut out = Attributes {
        normals: Vec::new(),
        colours: Vec::new(),
        stopped: false,
    };
    let mut scalars_seen = false;
    loop {
        let at = c.pos;
        let Some(words) = c.next_words() else {
            return Ok(out);
        };
        let keyword = words[0].to_ascii_uppercase();
        let scalar = |k: usize| scalar_of(words.get(k).copied().unwrap_or("float"));
        let components = |k: usize, default: usize| -> Result<usize, String> {
            match words.get(k) {
                None => Ok(default),
                Some(w) => w
                    .parse::<usize>()
                    .ok()
                    .filter(|&m| (1..=16).contains(&m))
                    .ok_or_else(|| format!("VTK {keyword}: {w:?} components")),
            }
        };
        match keyword.as_str() {
            "POINT_DATA" | "CELL_DATA" => {
                c.pos = at;
                return Ok(out);
            }
            "NORMALS" => {
                let v = numbers(c, 3 * n, scalar(2)?, binary, "the VTK normals")?;
                out.normals = v
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32))
                    .collect();
                skip_metadata_if_any(c);
            }
            "SCALARS" | "COLOR_SCALARS" => {
                // COLOR_SCALARS: bytes in a binary file, 0 to 1 in an ASCII one.
                let (kind, k) = if keyword == "SCALARS" {
                    (scalar(2)?, components(3, 1)?)
                } else if binary {
                    (Scalar::U8, components(2, 4)?)
                } else {
                    (Scalar::F32, components(2, 4)?)
                };
                if keyword == "SCALARS" && c.next_line_starts_with("LOOKUP_TABLE") {
                    c.line();
                }
                let v = numbers(c, n.saturating_mul(k), kind, binary, "VTK scalars")?;
                skip_metadata_if_any(c);
                let colour = keyword == "COLOR_SCALARS" || kind == Scalar::U8;
                if !scalars_seen && colour {
                    let bytes = kind == Scalar::U8;
                    out.colours = colours_of(n, k, bytes, |i| v[i]).unwrap_or_default();
                }
                scalars_seen = true;
            }
            "VECTORS" | "TENSORS" | "TEXTURE_COORDINATES" => {
                let (k, kind) = match keyword.as_str() {
                    "VECTORS" => (3, scalar(2)?),
                    "TENSORS" => (9, scalar(2)?),
                    _ => (components(2, 2)?, scalar(3)?),
                };
                numbers(
                    c,
                    n.saturating_mul(k),
                    kind,
                    binary,
                    &format!("VTK {keyword}"),
                )?;
                skip_metadata_if_any(c);
            }
            "LOOKUP_TABLE" => {
                let entries = count(words.get(2), size, "LOOKUP_TABLE")?;
                let kind = if binary { Scalar::U8 } else { Scalar::F32 };
                numbers(c, 4 * entries, kind, binary, "a VTK lookup table")?;
            }
            "FIELD" => {
                skip_field(c, &words, binary, size)?;
            }
            _ => {
                out.stopped = true;
                return Ok(out);
            }
        }
    }
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

    /// Field data of strings (binary: lengths in one, two and four bytes) is passed over, its
    /// `SPACE` read; vectors, texture coordinates and a lookup table before the colours are
    /// passed over; cell colours reach the triangles by VTK's cell numbering (the line first).
    #[test]
    fn strings_attributes_and_cell_colours() {
        let mut b = binary_42();
        let cut = b.windows(10).position(|w| w == b"POINT_DATA").unwrap();
        b.truncate(cut);
        let long = "x".repeat(300);
        let huge = "y".repeat(20_000);
        b.extend(b"CELL_DATA 3\nVECTORS v float\n");
        b.extend([0.5f32; 9].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nTEXTURE_COORDINATES t 2 float\n");
        b.extend([0.25f32; 6].iter().flat_map(|x| x.to_be_bytes()));
        b.extend(b"\nSCALARS c unsigned_char 3\nLOOKUP_TABLE default\n");
        b.extend([1u8, 2, 3, 10, 20, 30, 40, 50, 60]);
        b.extend(b"\nLOOKUP_TABLE default 2\n");
        b.extend([0u8; 8]);
        // The dataset's field data, before its points, as VTK writes it; and the cells'.
        let mut field = b"FIELD FieldData 2\nnotes 1 2 string\n".to_vec();
        field.push(0x80 | (long.len() >> 8) as u8);
        field.push(long.len() as u8);
        field.extend(long.as_bytes());
        field.extend([0x40, 0, (huge.len() >> 8) as u8, huge.len() as u8]);
        field.extend(huge.as_bytes());
        field.extend(b"\nSPACE 1 1 string\n\xc3LPS\n");
        // The cells' field data names RAS, which is not the dataset's space.
        let mut cells = field.clone();
        let n = cells.len();
        cells[n - 4..n - 1].copy_from_slice(b"RAS");
        b.extend(b"\n");
        b.extend(cells);
        let at = b.windows(7).position(|w| w == b"POINTS ").unwrap();
        b.splice(at..at, field);
        let poly = parse(&b, Path::new("m.vtk")).unwrap();
        assert_eq!(poly.mesh.triangles, WANT);
        assert_eq!(poly.space, Some(crate::PatientSpace::Lps));
        // Cells: the line (0), the quad's fan (1), the strip (2).
        assert_eq!(
            poly.colours,
            [
                [[10, 20, 30]; 3],
                [[10, 20, 30]; 3],
                [[40, 50, 60]; 3],
                [[40, 50, 60]; 3]
            ]
        );
        // In ASCII, a string a line; COLOR_SCALARS are 0 to 1, point colours before cell ones.
        let ascii = ascii_42().replace("POINTS", "FIELD f 1\nSPACE 1 1 string\nRAS\nPOINTS")
            + "CELL_DATA 3\nCOLOR_SCALARS c 3\n0 0 0\n1 1 1\n0.5 0.5 0.5\n\
               POINT_DATA 8\nCOLOR_SCALARS p 4\n"
            + &"1 0.5 0 0.25\n".repeat(8);
        let poly = parse(ascii.as_bytes(), Path::new("m.vtk")).unwrap();
        assert_eq!(poly.space, Some(crate::PatientSpace::Ras));
        assert_eq!(poly.colours, vec![[[255, 128, 0]; 3]; 4]);
        // A string longer than the file is an error naming it.
        let mut cut = b.clone();
        let at = cut.windows(4).position(|w| w == b"\xc3LPS").unwrap();
        cut[at] = 0x3f;
        let e = parse(&cut, Path::new("bad.vtk")).err().unwrap().to_string();
        assert!(e.starts_with("bad.vtk") && e.contains("truncated"), "{e}");
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
