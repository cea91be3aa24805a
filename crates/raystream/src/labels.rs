//! `render --labels`: the patient directions at the image's edges, as radiology viewers mark
//! them (R/L, A/P, S/I; an oblique edge gets two or three letters, the strongest first).
//!
//! Six capital letters at one size, and for `--scale-bar` digits and "mm"/"cm", are all it
//! draws, so they are bitmaps here (5×7 cells, a cell a pixel or more) rather than a font file
//! and a rasteriser, which would be larger than the glyphs.

use raystream_math::Vec3;

/// 5×7 glyphs, a row a byte, the leftmost cell in bit 4.
const GLYPHS: [(char, [u8; 7]); 20] = [
    ('A', [0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11]),
    ('P', [0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10]),
    ('R', [0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11]),
    ('L', [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f]),
    ('S', [0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e]),
    ('I', [0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e]),
    ('0', [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e]),
    ('1', [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e]),
    ('2', [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f]),
    ('3', [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e]),
    ('4', [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02]),
    ('5', [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e]),
    ('6', [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e]),
    ('7', [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08]),
    ('8', [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e]),
    ('9', [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c]),
    ('.', [0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c]),
    ('m', [0x00, 0x00, 0x1a, 0x15, 0x15, 0x15, 0x15]),
    ('c', [0x00, 0x00, 0x0e, 0x10, 0x10, 0x11, 0x0e]),
    (' ', [0x00; 7]),
];

/// A direction's component counts toward its letters from this size up (11.5° off the plane
/// across the axis).
const LETTER_MIN: f32 = 0.2;

/// The patient direction `d` (LPS, unit) in letters: +x L(eft), −x R(ight), +y P(osterior),
/// −y A(nterior), +z S(uperior), −z I(nferior), the largest component first.
pub fn letters(d: Vec3) -> String {
    let mut axes: Vec<(f32, char)> = [('L', 'R'), ('P', 'A'), ('S', 'I')]
        .iter()
        .enumerate()
        .map(|(a, &(pos, neg))| (d[a], if d[a] >= 0.0 { pos } else { neg }))
        .filter(|(c, _)| c.abs() >= LETTER_MIN)
        .collect();
    axes.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
    axes.into_iter().map(|(_, l)| l).collect()
}

/// Cell size in pixels for an image `height` pixels high: a letter about 1/18 of it.
pub fn cell(height: u32) -> u32 {
    (height / 128).max(1)
}

/// Where each edge's text starts (top-left of its first glyph) and the text, for an image of
/// `width`×`height` whose right and up are the patient directions `right` and `up` (LPS):
/// the top and bottom centred, the left and right halfway down, two cells from the edge.
pub fn placements(width: u32, height: u32, right: Vec3, up: Vec3) -> Vec<(u32, u32, String)> {
    let s = cell(height);
    let text_width = |t: &str| (t.len() as u32 * 6).saturating_sub(1) * s;
    let margin = 2 * s;
    let mid_y = height.saturating_sub(7 * s) / 2;
    let mut out = Vec::new();
    for (dir, edge) in [(up, 0), (-up, 1), (-right, 2), (right, 3)] {
        let t = letters(dir.normalize_or_zero());
        if t.is_empty() {
            continue;
        }
        let w = text_width(&t);
        let (x, y) = match edge {
            0 => (width.saturating_sub(w) / 2, margin),
            1 => (
                width.saturating_sub(w) / 2,
                height.saturating_sub(margin + 7 * s),
            ),
            2 => (margin, mid_y),
            _ => (width.saturating_sub(margin + w), mid_y),
        };
        out.push((x, y, t));
    }
    out
}

/// Draws the four edges' letters into `rgb` (8-bit RGB, row-major): white cells, each ringed
/// by black so that they read on any image.
pub fn draw(rgb: &mut [u8], width: u32, height: u32, right: Vec3, up: Vec3) {
    let s = cell(height);
    let mut put = |x: i64, y: i64, v: u8| {
        if x >= 0 && y >= 0 && (x as u32) < width && (y as u32) < height {
            let i = 3 * (y as usize * width as usize + x as usize);
            rgb[i..i + 3].fill(v);
        }
    };
    for (x0, y0, text) in placements(width, height, right, up) {
        draw_text(&mut put, (x0 as i64, y0 as i64), s, &text);
    }
}

/// Draws `text` with its first glyph's top-left at `at`, in cells of `s` pixels, a glyph every
/// six cells, through `put(x, y, value)`: white cells, each ringed by black.
pub fn draw_text(put: &mut impl FnMut(i64, i64, u8), (x0, y0): (i64, i64), s: u32, text: &str) {
    let s = s as i64;
    for (k, ch) in text.chars().enumerate() {
        let glyph = glyph(ch);
        let gx = x0 + k as i64 * 6 * s;
        // The black ring first, then the letter over it.
        for pass in [0u8, 255] {
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) == 0 {
                        continue;
                    }
                    let (cx, cy) = (gx + col * s, y0 + row as i64 * s);
                    let ring = if pass == 0 { 1 } else { 0 };
                    for y in cy - ring..cy + s + ring {
                        for x in cx - ring..cx + s + ring {
                            put(x, y, pass);
                        }
                    }
                }
            }
        }
    }
}

/// The glyph of one of the letters and signs drawn (the six directions, digits, '.', 'm', 'c',
/// space).
pub fn glyph(ch: char) -> [u8; 7] {
    GLYPHS
        .iter()
        .find(|(c, _)| *c == ch)
        .map(|(_, g)| *g)
        .expect("a letter or sign with a glyph")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn letters_name_the_strongest_directions_first() {
        assert_eq!(letters(Vec3::X), "L");
        assert_eq!(letters(-Vec3::X), "R");
        assert_eq!(letters(Vec3::Y), "P");
        assert_eq!(letters(-Vec3::Y), "A");
        assert_eq!(letters(Vec3::Z), "S");
        assert_eq!(letters(-Vec3::Z), "I");
        // 30° from the patient's left toward the front, then a little up.
        let d = Vec3::new(0.866, -0.5, 0.1);
        assert_eq!(letters(d), "LA");
        assert_eq!(letters(Vec3::new(-0.6, 0.5, -0.62).normalize()), "IRP");
    }

    /// Drawn letters read back: each edge's cells are white exactly where its glyphs are set,
    /// ringed by black.
    #[test]
    fn drawn_letters_read_back() {
        let (w, h) = (300u32, 260u32);
        let mut rgb = vec![100u8; (3 * w * h) as usize];
        // The anterior view: the patient's left on the image's right, superior up.
        draw(&mut rgb, w, h, Vec3::X, Vec3::Z);
        let s = cell(h);
        let at = |x: u32, y: u32| rgb[(3 * (y * w + x)) as usize];
        let placed = placements(w, h, Vec3::X, Vec3::Z);
        let texts: Vec<&str> = placed.iter().map(|(_, _, t)| t.as_str()).collect();
        assert_eq!(texts, ["S", "I", "R", "L"]);
        for (x0, y0, t) in &placed {
            let g = glyph(t.chars().next().unwrap());
            for (row, bits) in g.iter().enumerate() {
                for col in 0..5u32 {
                    let (x, y) = (x0 + col * s + s / 2, y0 + row as u32 * s + s / 2);
                    let set = bits & (0x10 >> col) != 0;
                    if set {
                        assert_eq!(at(x, y), 255, "{t} row {row} col {col}");
                    } else {
                        assert_ne!(at(x, y), 255, "{t} row {row} col {col}");
                    }
                }
            }
        }
        // Away from the letters the picture is untouched.
        assert_eq!(at(w / 2, h / 2), 100);
    }
}
