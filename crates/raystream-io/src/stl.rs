//! STL through stl_io. A binary STL states its triangle count in the header; it is checked
//! against the file size first, so a lying header is an error, not a huge allocation.
//!
//! Colours, which stl_io does not read (it skips each triangle's two attribute bytes), are read
//! here by the two conventions in use (Wikipedia's "STL (file format)", "Colour in binary
//! STL"):
//! - **Materialise Magics** (and Mimics, the medical one; SolidWorks writes it too): the
//!   header holds `COLOR=` and four bytes, the part's RGBA colour (`,MATERIAL=` and three
//!   RGBA colours may follow: diffuse, specular, ambient; the diffuse one is the part's colour
//!   then, "material settings are preferred over colour"). A triangle whose attribute's bit 15
//!   is clear has its own colour, 5 bits a channel, red in bits 0–4, green 5–9, blue 10–14;
//!   one whose bit 15 is set is the part's colour.
//! - **VisCAM and SolidView** (no `COLOR=` in the header): a triangle whose bit 15 is set has
//!   its own colour, blue in bits 0–4, green 5–9, red 10–14; the others have none, and are drawn
//!   as an uncoloured mesh is ([`crate::UNCOLOURED_GREY`]).

use std::path::Path;

use crate::{MeshError, Rgb8, TriMesh, Vec3};

const HEADER: usize = 80;
const TRIANGLE: usize = 50;

/// A mesh read from an STL file, with its triangles' colours (empty: the file has none).
pub(crate) struct Stl {
    pub mesh: TriMesh,
    pub colours: Vec<[Rgb8; 3]>,
}

pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<Stl, MeshError> {
    let ascii = bytes.trim_ascii_start().starts_with(b"solid") && !looks_binary(bytes);
    let mut count = 0;
    if !ascii {
        if bytes.len() < HEADER + 4 {
            return Err(MeshError::invalid(
                path,
                format!(
                    "binary STL is truncated: {} bytes, shorter than its 84-byte header",
                    bytes.len()
                ),
            ));
        }
        count = u32::from_le_bytes(bytes[HEADER..HEADER + 4].try_into().unwrap()) as usize;
        let need = HEADER + 4 + count * TRIANGLE;
        if bytes.len() < need {
            return Err(MeshError::invalid(
                path,
                format!(
                    "binary STL is truncated: header claims {count} triangles ({need} bytes), file has {} bytes",
                    bytes.len()
                ),
            ));
        }
    }
    let indexed = stl_io::read_stl(&mut std::io::Cursor::new(bytes))
        .map_err(|e| MeshError::invalid(path, format!("cannot read STL: {e}")))?;
    // stl_io keeps the file's triangles, in its order.
    let colours = if ascii || indexed.faces.len() != count {
        Vec::new()
    } else {
        colours(bytes, count)
    };
    Ok(Stl {
        mesh: TriMesh {
            positions: indexed
                .vertices
                .iter()
                .map(|v| Vec3::new(v[0], v[1], v[2]))
                .collect(),
            triangles: indexed
                .faces
                .iter()
                .map(|f| f.vertices.map(|i| i as u32))
                .collect(),
        },
        colours,
    })
}

/// A 5-bit channel (the low bits of `bits`) as 8 bits, rounded.
fn channel(bits: u16) -> u8 {
    ((u32::from(bits & 31) * 255 + 15) / 31) as u8
}

/// An 8-bit channel as 5 bits, rounded: [`channel`]'s inverse.
pub(crate) fn five_bits(c: u8) -> u16 {
    ((u32::from(c) * 31 + 127) / 255) as u16
}

/// The colours of a binary STL's `count` triangles (checked to be in `bytes`), by the
/// convention its header shows; empty where it gives none.
fn colours(bytes: &[u8], count: usize) -> Vec<[Rgb8; 3]> {
    let header = &bytes[..HEADER];
    let after = |tag: &[u8], n: usize| {
        header
            .windows(tag.len())
            .position(|w| w == tag)
            .and_then(|at| header.get(at + tag.len()..at + tag.len() + n))
    };
    // Materialise's part colour; its material's diffuse colour before it.
    let part: Option<Rgb8> = after(b"MATERIAL=", 12)
        .or_else(|| after(b"COLOR=", 4))
        .map(|c| [c[0], c[1], c[2]]);
    let attribute = |i: usize| {
        let at = HEADER + 4 + i * TRIANGLE + 48;
        u16::from_le_bytes([bytes[at], bytes[at + 1]])
    };
    let own = |a: u16, red_low: bool| {
        let [low, mid, high] = [a, a >> 5, a >> 10].map(channel);
        if red_low {
            [low, mid, high]
        } else {
            [high, mid, low]
        }
    };
    let colour = |a: u16| -> Option<Rgb8> {
        match part {
            // A triangle's own colour that is the part's at 5 bits (rounded or cut: within
            // a step, 255/31, on every channel) is the part's, kept at 8 bits.
            Some(part) if a & 0x8000 == 0 => {
                let c = own(a, true);
                let near = (0..3).all(|k| c[k].abs_diff(part[k]) <= 8);
                Some(if near { part } else { c })
            }
            Some(part) => Some(part),
            None => (a & 0x8000 != 0).then(|| own(a, false)),
        }
    };
    if part.is_none() && !(0..count).any(|i| attribute(i) & 0x8000 != 0) {
        return Vec::new();
    }
    (0..count)
        .map(|i| [colour(attribute(i)).unwrap_or(crate::UNCOLOURED_GREY); 3])
        .collect()
}

/// Many binary STL files start their 80-byte header with "solid" too; the size formula tells.
fn looks_binary(bytes: &[u8]) -> bool {
    bytes.len() >= HEADER + 4 && {
        let count = u32::from_le_bytes(bytes[HEADER..HEADER + 4].try_into().unwrap()) as usize;
        bytes.len() == HEADER + 4 + count * TRIANGLE
    }
}
