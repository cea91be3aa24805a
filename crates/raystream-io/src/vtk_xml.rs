//! VTK's XML formats, what ParaView and VTK save by default: their common part (the
//! `VTKFile` element, and `DataArray`s in every encoding VTK writes) and polygonal data
//! (`.vtp`). Image data (`.vti`) is read as a volume in `volume/vti.rs`.
//!
//! A `DataArray` is `ascii` (numbers as text), `binary` (base64 inside the element) or
//! `appended` (at its `offset` in the `AppendedData` section at the end of the file, `raw`
//! bytes or base64), each binary array led by a header of `header_type` words (UInt32 or
//! UInt64, the file's `byte_order`): its byte count, or, under the file's `compressor`
//! (zlib, LZ4 or LZMA), its blocks' count and sizes followed by the compressed blocks.
//!
//! Written by hand over `roxmltree` (the XML), `base64`, `flate2`, `lz4_flex` and `lzma-rs`:
//! vtkio 0.6.3, the VTK crate on crates.io, reads no appended raw data (an XML error),
//! returns an empty array for zlib-compressed binary data, and drops the `Direction` of image
//! data (tried on files the `vtk` wheel wrote).

use std::io::{Read, Write};
use std::path::Path;

use base64::Engine;

use crate::volume::raw::{Scalar, value};
use crate::{MeshError, Rgb8, TriMesh, Vec3};

/// A VTK XML file's text (up to its appended data) and where its appended data lies.
pub(crate) struct XmlFile<'a> {
    /// The XML, closed where the appended data was cut off.
    pub text: String,
    /// The bytes after the `_` that opens the `AppendedData` section, and whether they are
    /// base64.
    appended: Option<(&'a [u8], bool)>,
}

impl<'a> XmlFile<'a> {
    /// Splits `bytes` into the XML and the appended data.
    pub fn split(bytes: &'a [u8]) -> Result<XmlFile<'a>, String> {
        let tag = b"<AppendedData";
        let at = bytes.windows(tag.len()).position(|w| w == tag);
        let (xml, appended) = match at {
            Some(at) => {
                let open_end = bytes[at..]
                    .iter()
                    .position(|&b| b == b'>')
                    .map(|p| at + p)
                    .ok_or("the VTK AppendedData element is cut short")?;
                let open = String::from_utf8_lossy(&bytes[at..open_end]);
                let base64 = match attribute_in(&open, "encoding") {
                    Some("raw") => false,
                    Some("base64") | None => true,
                    Some(e) => return Err(format!("VTK appended data encoding {e:?}")),
                };
                let underscore = bytes[open_end..]
                    .iter()
                    .position(|&b| b == b'_')
                    .ok_or("the VTK appended data has no '_' before it")?;
                (
                    &bytes[..at],
                    Some((&bytes[open_end + underscore + 1..], base64)),
                )
            }
            None => (bytes, None),
        };
        let mut text = std::str::from_utf8(xml)
            .map_err(|_| "the VTK XML is not UTF-8 text".to_string())?
            .to_string();
        if appended.is_some() {
            text.push_str("</VTKFile>");
        }
        Ok(XmlFile { text, appended })
    }
}

/// The value of `name="…"` in an element's opening tag `open`.
fn attribute_in<'s>(open: &'s str, name: &str) -> Option<&'s str> {
    let key = format!("{name}=\"");
    let start = open.find(&key)? + key.len();
    let len = open[start..].find('"')?;
    Some(&open[start..start + len])
}

/// How a file's binary arrays are laid out: the `VTKFile` element's attributes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout<'a> {
    big_endian: bool,
    /// Bytes a header word: 4 (UInt32) or 8 (UInt64).
    word: usize,
    compressor: Compressor,
    appended: Option<(&'a [u8], bool)>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Compressor {
    None,
    Zlib,
    Lz4,
    Lzma,
}

/// The document's `VTKFile` element, checked to hold a data set of `kind` (`ImageData`,
/// `PolyData`), and its layout.
pub(crate) fn root<'a, 'd>(
    doc: &'d roxmltree::Document<'d>,
    file: &XmlFile<'a>,
    kind: &str,
) -> Result<(roxmltree::Node<'d, 'd>, Layout<'a>), String> {
    let root = doc.root_element();
    if root.tag_name().name() != "VTKFile" {
        return Err(format!(
            "not a VTK XML file (its root element is <{}>)",
            root.tag_name().name()
        ));
    }
    let found = root.attribute("type").unwrap_or("");
    if found != kind {
        return Err(format!("a VTK XML file of {found:?}, not {kind}"));
    }
    let big_endian = match root.attribute("byte_order") {
        Some("BigEndian") => true,
        Some("LittleEndian") | None => false,
        Some(o) => return Err(format!("VTK byte_order {o:?}")),
    };
    let word = match root.attribute("header_type") {
        Some("UInt32") | None => 4,
        Some("UInt64") => 8,
        Some(t) => return Err(format!("VTK header_type {t:?}")),
    };
    let compressor = match root.attribute("compressor") {
        None | Some("") => Compressor::None,
        Some("vtkZLibDataCompressor") => Compressor::Zlib,
        Some("vtkLZ4DataCompressor") => Compressor::Lz4,
        Some("vtkLZMADataCompressor") => Compressor::Lzma,
        Some(c) => return Err(format!("VTK compressor {c:?} is not supported")),
    };
    let layout = Layout {
        big_endian,
        word,
        compressor,
        appended: file.appended,
    };
    Ok((root, layout))
}

/// The child elements of `node` named `name`.
pub(crate) fn children<'d>(
    node: roxmltree::Node<'d, 'd>,
    name: &'static str,
) -> impl Iterator<Item = roxmltree::Node<'d, 'd>> {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == name)
}

/// `count` numbers from the attribute `name` of `node`, or `default` where it has none.
pub(crate) fn numbers_attribute<const N: usize>(
    node: roxmltree::Node,
    name: &str,
    default: Option<[f64; N]>,
) -> Result<[f64; N], String> {
    let Some(text) = node.attribute(name) else {
        return default
            .ok_or_else(|| format!("the VTK <{}> has no {name}", node.tag_name().name()));
    };
    let v: Option<Vec<f64>> = text.split_whitespace().map(|w| w.parse().ok()).collect();
    v.and_then(|v| v.try_into().ok())
        .ok_or_else(|| format!("VTK {name} {text:?} is not {N} numbers"))
}

/// A `DataArray`'s values, of its type `scalar`: read from text, or its bytes.
pub(crate) struct Values {
    pub scalar: Scalar,
    stored: Stored,
}

enum Stored {
    Text(Vec<f64>),
    Bytes { bytes: Vec<u8>, big_endian: bool },
}

impl Values {
    /// Value `i`, exactly.
    pub fn get(&self, i: usize) -> f64 {
        match &self.stored {
            Stored::Text(v) => v[i],
            Stored::Bytes { bytes, big_endian } => {
                let s = self.scalar.size();
                value(&bytes[i * s..(i + 1) * s], self.scalar, *big_endian)
            }
        }
    }

    /// Every value as f32.
    pub fn to_f32(&self) -> Vec<f32> {
        match &self.stored {
            Stored::Text(v) => v.iter().map(|&x| x as f32).collect(),
            Stored::Bytes { bytes, big_endian } => {
                crate::volume::raw::decode(bytes, self.scalar, *big_endian, 1.0, 0.0)
            }
        }
    }
}

/// The scalar type a `DataArray`'s `type` names.
fn scalar_type(t: &str) -> Option<Scalar> {
    Some(match t {
        "Int8" | "Char" => Scalar::I8,
        "UInt8" | "UnsignedChar" => Scalar::U8,
        "Int16" | "Short" => Scalar::I16,
        "UInt16" | "UnsignedShort" => Scalar::U16,
        "Int32" | "Int" => Scalar::I32,
        "UInt32" | "UnsignedInt" => Scalar::U32,
        "Int64" | "Long" | "LongLong" => Scalar::I64,
        "UInt64" | "UnsignedLong" | "UnsignedLongLong" => Scalar::U64,
        "Float32" | "Float" => Scalar::F32,
        "Float64" | "Double" => Scalar::F64,
        _ => return None,
    })
}

/// The `count` values (tuples × components) of the `DataArray` `node`; fewer or more is an
/// error, as is a byte count or a block size no array of `count` values has (checked before
/// anything is sized by it).
pub(crate) fn read_array(
    node: roxmltree::Node,
    layout: &Layout,
    count: usize,
) -> Result<Values, String> {
    let t = node.attribute("type").unwrap_or("");
    let scalar = scalar_type(t).ok_or_else(|| {
        let name = node.attribute("Name").unwrap_or("");
        format!("the VTK array {name:?}: type {t:?} is not supported")
    })?;
    read_array_as(node, layout, count, scalar)
}

/// As [`read_array`], its values taken as `scalar` whatever its type says (a `String` array's
/// bytes as `UInt8`).
fn read_array_as(
    node: roxmltree::Node,
    layout: &Layout,
    count: usize,
    scalar: Scalar,
) -> Result<Values, String> {
    let name = node.attribute("Name").unwrap_or("");
    let what = format!("the VTK array {name:?}");
    let format = node.attribute("format").unwrap_or("ascii");
    if format == "ascii" {
        let text = node.text().unwrap_or("");
        let mut v = Vec::with_capacity(count.min(1 << 20));
        for w in text.split_whitespace() {
            if v.len() == count {
                return Err(format!("{what} holds more than its {count} values"));
            }
            v.push(
                w.parse::<f64>()
                    .map_err(|_| format!("{what}: {w:?} is not a number"))?,
            );
        }
        if v.len() < count {
            return Err(format!("{what} holds {} of its {count} values", v.len()));
        }
        return Ok(Values {
            scalar,
            stored: Stored::Text(v),
        });
    }
    let need = count
        .checked_mul(scalar.size())
        .ok_or_else(|| format!("{what}: {count} values"))?;
    let owned;
    let bytes: &[u8] = match format {
        "binary" => {
            owned = base64_streams(node.text().unwrap_or("").as_bytes(), usize::MAX)
                .map_err(|e| format!("{what}: {e}"))?;
            &owned
        }
        "appended" => {
            let (data, base64) = layout
                .appended
                .ok_or_else(|| format!("{what} is appended, but the file has no appended data"))?;
            let offset: usize = node
                .attribute("offset")
                .and_then(|o| o.trim().parse().ok())
                .ok_or_else(|| format!("{what}: no offset into the appended data"))?;
            let rest = data
                .get(offset..)
                .ok_or_else(|| format!("{what}: offset {offset} lies past the file's end"))?;
            if base64 {
                owned = appended_base64(rest, layout, need).map_err(|e| format!("{what}: {e}"))?;
                &owned
            } else {
                rest
            }
        }
        f => return Err(format!("{what}: format {f:?}")),
    };
    let data = unpack(bytes, layout, need).map_err(|e| format!("{what}: {e}"))?;
    Ok(Values {
        scalar,
        stored: Stored::Bytes {
            bytes: data,
            big_endian: layout.big_endian,
        },
    })
}

/// Base64 text of one or more streams one after another (VTK may encode a header and the data
/// after it separately, each padded), whitespace ignored, up to the end of `text` or a `<` (the
/// appended section's closing tag), decoded group by group of four characters until at least
/// `most` bytes are out.
fn base64_streams(text: &[u8], most: usize) -> Result<Vec<u8>, String> {
    let engine = base64::engine::general_purpose::STANDARD;
    let mut out = Vec::new();
    let mut stream = Vec::with_capacity(4096);
    let flush = |stream: &mut Vec<u8>, out: &mut Vec<u8>| -> Result<(), String> {
        engine
            .decode_vec(&stream[..], out)
            .map_err(|e| format!("bad base64 data ({e})"))?;
        stream.clear();
        Ok(())
    };
    let chars = text.iter().take_while(|&&c| c != b'<');
    for &c in chars.filter(|c| !c.is_ascii_whitespace()) {
        stream.push(c);
        if stream.len().is_multiple_of(4) && (c == b'=' || stream.len() >= 4096) {
            flush(&mut stream, &mut out)?;
            if out.len() >= most {
                return Ok(out);
            }
        }
    }
    // Text cut short of a whole group: its whole groups (the caller finds the bytes short).
    stream.truncate(stream.len() / 4 * 4);
    flush(&mut stream, &mut out)?;
    Ok(out)
}

/// An appended array's bytes from base64 `text` (the rest of the section from its offset):
/// as far as its header says it runs, for an array of `need` bytes.
fn appended_base64(text: &[u8], layout: &Layout, need: usize) -> Result<Vec<u8>, String> {
    let w = layout.word;
    let head = base64_streams(text, w)?;
    if layout.compressor == Compressor::None {
        return base64_streams(text, w.saturating_add(need));
    }
    let blocks = head
        .get(..w)
        .map(|b| word_of(b, layout))
        .ok_or("the data is cut short in its header")?;
    // Every block but an empty array's holds a byte at least.
    if blocks > need as u64 + 1 {
        return Err(format!("its header gives {blocks} blocks for {need} bytes"));
    }
    let header = (3 + blocks as usize) * w;
    let head = base64_streams(text, header)?;
    let compressed: u64 = (3..3 + blocks as usize)
        .map(|k| {
            head.get(k * w..(k + 1) * w)
                .map_or(0, |b| word_of(b, layout))
        })
        .fold(0u64, u64::saturating_add);
    if compressed > text.len() as u64 {
        return Err(format!(
            "its blocks' sizes add up to {compressed} bytes, past the file's end"
        ));
    }
    base64_streams(text, header + compressed as usize)
}

/// A header word (`layout.word` bytes).
fn word_of(b: &[u8], layout: &Layout) -> u64 {
    if layout.word == 4 {
        value(b, Scalar::U32, layout.big_endian) as u64
    } else {
        let a: [u8; 8] = b.try_into().unwrap();
        if layout.big_endian {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        }
    }
}

/// A binary array's `need` bytes from `bytes` (its header, then its data or compressed
/// blocks).
fn unpack(bytes: &[u8], layout: &Layout, need: usize) -> Result<Vec<u8>, String> {
    let w = layout.word;
    let word = |i: usize| -> Result<u64, String> {
        bytes
            .get(i * w..(i + 1) * w)
            .map(|b| word_of(b, layout))
            .ok_or_else(|| "the data is cut short in its header".to_string())
    };
    if layout.compressor == Compressor::None {
        let n = word(0)?;
        if n != need as u64 {
            return Err(format!("its header gives {n} bytes, {need} expected"));
        }
        return bytes
            .get(w..w + need)
            .map(<[u8]>::to_vec)
            .ok_or_else(|| format!("the data is cut short: {need} bytes expected"));
    }
    let blocks = word(0)?;
    let block = word(1)?;
    let last = match word(2)? {
        0 => block,
        l => l,
    };
    let total = blocks
        .checked_sub(1)
        .and_then(|b| b.checked_mul(block))
        .and_then(|b| b.checked_add(last))
        .unwrap_or(0);
    if blocks == 0 && need == 0 {
        return Ok(Vec::new());
    }
    if total != need as u64 || last > block {
        return Err(format!(
            "its header gives {blocks} blocks of {block} bytes (the last {last}), {need} bytes expected"
        ));
    }
    let blocks = blocks as usize;
    let mut at = w * (3 + blocks);
    let mut out = Vec::with_capacity(need.min(64 << 20));
    for k in 0..blocks {
        let size = word(3 + k)? as usize;
        let input = bytes
            .get(at..at.saturating_add(size))
            .ok_or("the data is cut short in its compressed blocks")?;
        at += size;
        let want = if k + 1 == blocks { last } else { block } as usize;
        let got =
            decompress(input, layout.compressor, want).map_err(|e| format!("block {k}: {e}"))?;
        if got.len() != want {
            return Err(format!(
                "block {k} holds {} bytes, {want} expected",
                got.len()
            ));
        }
        out.extend_from_slice(&got);
    }
    Ok(out)
}

/// A `Write` that refuses to hold more than `left` more bytes (a compressed block that would
/// unpack beyond its size).
struct Capped {
    out: Vec<u8>,
    left: usize,
}

impl Write for Capped {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if buf.len() > self.left {
            return Err(std::io::Error::other("it unpacks beyond its size"));
        }
        self.left -= buf.len();
        self.out.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// One compressed block, `want` bytes unpacked (more is an error, read no further).
fn decompress(input: &[u8], compressor: Compressor, want: usize) -> Result<Vec<u8>, String> {
    match compressor {
        Compressor::None => Ok(input.to_vec()),
        Compressor::Zlib => {
            let mut out = Vec::with_capacity(want);
            flate2::read::ZlibDecoder::new(input)
                .take(want as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| format!("zlib: {e}"))?;
            Ok(out)
        }
        Compressor::Lz4 => {
            lz4_flex::block::decompress(input, want).map_err(|e| format!("LZ4: {e}"))
        }
        Compressor::Lzma => {
            let mut out = Capped {
                out: Vec::with_capacity(want),
                left: want,
            };
            lzma_rs::xz_decompress(&mut std::io::BufReader::new(input), &mut out)
                .map_err(|e| format!("LZMA: {e}"))?;
            Ok(out.out)
        }
    }
}

/// The most cell corners a piece's cells of one kind may hold (2³⁰), checked before the
/// connectivity is read: a lying offset costs no memory.
const MAX_CELL_POINTS: usize = 1 << 30;

/// A polygonal data file's surface (`.vtp`): each piece's points, its polygons (as triangle
/// fans) and triangle strips (as triangles), its point normals where every piece gives them;
/// vertices and lines are left out with a warning.
pub(crate) fn parse_poly(
    bytes: &[u8],
    path: &Path,
) -> Result<crate::vtk_mesh::PolyData, MeshError> {
    poly(bytes).map_err(|e| MeshError::invalid(path, e))
}

fn poly(bytes: &[u8]) -> Result<crate::vtk_mesh::PolyData, String> {
    let file = XmlFile::split(bytes)?;
    let doc = roxmltree::Document::parse(&file.text).map_err(|e| format!("bad VTK XML: {e}"))?;
    let (root, layout) = root(&doc, &file, "PolyData").map_err(|e| {
        if e.contains("\"ImageData\"") {
            format!("{e}: image data is read as a volume")
        } else {
            e
        }
    })?;
    let data = children(root, "PolyData")
        .next()
        .ok_or("the VTK file has no <PolyData>")?;
    let space = field_space(data, &layout);
    let mut positions: Vec<Vec3> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut colours: Vec<[Rgb8; 3]> = Vec::new();
    let mut left_out = [0usize; 2];
    let size = bytes.len();
    for piece in children(data, "Piece") {
        let number = |name: &str| -> Result<usize, String> {
            piece
                .attribute(name)
                .map_or(Ok(0), |v| v.trim().parse::<usize>().map_err(|_| ()))
                .ok()
                .filter(|&n| n <= size)
                .ok_or_else(|| format!("VTK {name} is not a whole number the file could hold"))
        };
        let n_points = number("NumberOfPoints")?;
        let base = positions.len();
        if base + n_points > u32::MAX as usize {
            return Err("more than 2³² points".into());
        }
        if n_points > 0 {
            let points = children(piece, "Points")
                .next()
                .and_then(|p| children(p, "DataArray").next())
                .ok_or("a VTK piece has no <Points> array")?;
            let v = read_array(points, &layout, 3 * n_points)?;
            for p in 0..n_points {
                let xyz: [f64; 3] = std::array::from_fn(|a| v.get(3 * p + a));
                if let Some(bad) = xyz.iter().find(|x| !x.is_finite()) {
                    return Err(format!(
                        "a VTK point has a coordinate that is not finite: {bad}"
                    ));
                }
                positions.push(Vec3::new(xyz[0] as f32, xyz[1] as f32, xyz[2] as f32));
            }
        }
        let first_triangle = triangles.len();
        // Each triangle's cell, by its id in the piece: VTK numbers vertices, lines, polygons,
        // then strips.
        let mut cell_of = Vec::new();
        let mut cell_id = 0;
        for (element, count) in [
            ("Verts", "NumberOfVerts"),
            ("Lines", "NumberOfLines"),
            ("Polys", "NumberOfPolys"),
            ("Strips", "NumberOfStrips"),
        ] {
            let n = number(count)?;
            match element {
                _ if n == 0 => {}
                // Left out unread: they are no surface.
                "Verts" => left_out[0] += n,
                "Lines" => left_out[1] += n,
                _ => {
                    for (k, cell) in cells(piece, element, n, n_points, &layout)?
                        .iter()
                        .enumerate()
                    {
                        let at = |k: usize| cell[k] + base as u32;
                        crate::vtk_mesh::triangulate(
                            element == "Strips",
                            cell.len(),
                            at,
                            &mut triangles,
                        );
                        cell_of.resize(triangles.len() - first_triangle, cell_id + k);
                    }
                }
            }
            cell_id += n;
        }
        let point_data = children(piece, "PointData").next();
        let normal_array = point_data.and_then(|d| {
            let name = d.attribute("Normals")?;
            children(d, "DataArray").find(|a| a.attribute("Name") == Some(name))
        });
        // Only while every piece before gave its points normals: else none are kept.
        if let Some(a) = normal_array
            && normals.len() == base
        {
            let v = read_array(a, &layout, 3 * n_points)?;
            normals.extend((0..n_points).map(|p| {
                Vec3::new(
                    v.get(3 * p) as f32,
                    v.get(3 * p + 1) as f32,
                    v.get(3 * p + 2) as f32,
                )
            }));
        }
        let point = active_colours(point_data, &layout, n_points)?;
        let cell = active_colours(children(piece, "CellData").next(), &layout, cell_id)?;
        let own = crate::vtk_mesh::triangle_colours(
            &triangles[first_triangle..],
            base as u32,
            &cell_of,
            &point,
            &cell,
        );
        if !own.is_empty() || !colours.is_empty() {
            // Pieces before without colours are white, as are those after.
            colours.resize(first_triangle, [[255; 3]; 3]);
            colours.extend(own);
        }
    }
    if !colours.is_empty() {
        colours.resize(triangles.len(), [[255; 3]; 3]);
    }
    let words: Vec<String> = [("vertices", left_out[0]), ("lines", left_out[1])]
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(w, n)| format!("{n} {w}"))
        .collect();
    let warnings = crate::vtk_mesh::left_out_warning(&words)
        .into_iter()
        .collect();
    if normals.len() != positions.len() {
        normals.clear();
    }
    Ok(crate::vtk_mesh::PolyData {
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

/// The patient space 3D Slicer names in a dataset's field data: a `String` array `SPACE`
/// holding `LPS` or `RAS` (what Slicer writes into a `.vtp` model, ASCII or appended and
/// compressed). A string of three letters is four bytes with its terminating zero: an array
/// of any other length names no space.
fn field_space(data: roxmltree::Node, layout: &Layout) -> Option<crate::PatientSpace> {
    let array = children(data, "FieldData")
        .flat_map(|f| children(f, "Array").chain(children(f, "DataArray")))
        .find(|a| a.attribute("Name") == Some("SPACE") && a.attribute("type") == Some("String"))?;
    let v = read_array_as(array, layout, 4, Scalar::U8).ok()?;
    match [0, 1, 2, 3].map(|i| v.get(i) as u8) {
        [b'L', b'P', b'S', 0] => Some(crate::PatientSpace::Lps),
        [b'R', b'A', b'S', 0] => Some(crate::PatientSpace::Ras),
        _ => None,
    }
}

/// The colours of `n` items in a `<PointData>` or `<CellData>`: its active scalars
/// (`Scalars="…"`) where those are RGB or RGBA (VTK draws unsigned char ones as they are);
/// empty otherwise.
fn active_colours(
    data: Option<roxmltree::Node>,
    layout: &Layout,
    n: usize,
) -> Result<Vec<Rgb8>, String> {
    let Some(array) = data.and_then(|d| {
        let name = d.attribute("Scalars")?;
        children(d, "DataArray").find(|a| a.attribute("Name") == Some(name))
    }) else {
        return Ok(Vec::new());
    };
    let components = array
        .attribute("NumberOfComponents")
        .and_then(|c| c.trim().parse::<usize>().ok())
        .unwrap_or(1);
    if n == 0 || !matches!(components, 3 | 4) || array.attribute("type") != Some("UInt8") {
        return Ok(Vec::new());
    }
    let v = read_array(array, layout, n * components)?;
    Ok(crate::vtk_mesh::colours_of(n, components, true, |i| v.get(i)).unwrap_or_default())
}

/// The `n` cells of a piece's `element` (`Polys`, `Strips`, …): its `connectivity` array cut
/// by its `offsets` (each cell's end), each point one of the piece's `n_points`.
fn cells(
    piece: roxmltree::Node,
    element: &str,
    n: usize,
    n_points: usize,
    layout: &Layout,
) -> Result<Vec<Vec<u32>>, String> {
    let node = piece
        .children()
        .find(|c| c.is_element() && c.tag_name().name() == element)
        .ok_or_else(|| format!("a VTK piece counts {n} {element} but has no <{element}>"))?;
    let array = |name: &str| {
        children(node, "DataArray")
            .find(|a| a.attribute("Name") == Some(name))
            .ok_or_else(|| format!("the VTK <{element}> has no {name} array"))
    };
    let offsets = read_array(array("offsets")?, layout, n)?;
    let whole = |v: f64, what: &str| -> Result<usize, String> {
        (v >= 0.0 && v.fract() == 0.0 && v < 9.0e15)
            .then_some(v as usize)
            .ok_or_else(|| format!("VTK {element}: {what} {v} is not a whole number"))
    };
    let total = whole(offsets.get(n - 1), "offset")?;
    if total > MAX_CELL_POINTS {
        return Err(format!(
            "VTK {element}: offsets run to {total} points (at most {MAX_CELL_POINTS} are read)"
        ));
    }
    let connectivity = read_array(array("connectivity")?, layout, total)?;
    let mut out = Vec::with_capacity(n);
    let mut start = 0;
    for c in 0..n {
        let end = whole(offsets.get(c), "offset")?;
        if end < start || end > total {
            return Err(format!(
                "VTK {element}: offsets {start}..{end} run past the connectivity"
            ));
        }
        let mut cell = Vec::with_capacity(end - start);
        for k in start..end {
            let i = whole(connectivity.get(k), "point")?;
            if i >= n_points {
                return Err(format!(
                    "a VTK {element} cell names point {i}, of {n_points} points"
                ));
            }
            cell.push(i as u32);
        }
        out.push(cell);
        start = end;
    }
    Ok(out)
}
