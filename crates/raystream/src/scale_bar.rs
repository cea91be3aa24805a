//! `render --scale-bar`: a bar of a round length (1, 2 or 5 × 10ᵏ mm) in the image's bottom
//! right corner with its length written above it, as radiology viewers show one on a slice, a
//! parallel projection or a straightened CPR, where every pixel spans the same millimetres.

/// The bar's length in mm for pixels of `mm_per_pixel` in an image `width` pixels wide: the
/// longest of 1, 2 or 5 × 10ᵏ mm that spans at most a fifth of the width.
pub fn length_mm(mm_per_pixel: f64, width: u32) -> f64 {
    let most = width as f64 / 5.0 * mm_per_pixel;
    let base = 10f64.powf(most.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * base)
        .find(|&l| l <= most * (1.0 + 1e-9))
        .unwrap_or(base)
}

/// A length as the bar's label says it: whole centimetres from 1 cm up, else millimetres,
/// without trailing zeros ("5 cm", "2 mm", "0.5 mm").
pub fn words(mm: f64) -> String {
    let number = |v: f64| {
        let s = format!("{v:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    };
    let cm = mm / 10.0;
    if mm >= 10.0 && (cm - cm.round()).abs() < 1e-9 {
        format!("{} cm", number(cm.round()))
    } else {
        format!("{} mm", number(mm))
    }
}

/// Where the bar lies in an image of `width`×`height`: its left and right pixel columns (the
/// bar covers `left..right`), its top row and its thickness, with its label's top-left
/// corner; the cell size of [`crate::labels::cell`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub left: u32,
    pub right: u32,
    pub top: u32,
    pub thick: u32,
    pub label: (u32, u32),
    pub cell: u32,
}

/// Places a bar `pixels` long with label `text`: two cells from the right and bottom edges,
/// the label right-aligned above it.
pub fn place(width: u32, height: u32, pixels: u32, text: &str) -> Placement {
    let s = crate::labels::cell(height);
    let margin = 2 * s;
    let right = width.saturating_sub(margin);
    let left = right.saturating_sub(pixels);
    let thick = s.max(2);
    // Room under the bar for its end ticks.
    let top = height.saturating_sub(margin + 2 * thick);
    let text_width = (text.chars().count() as u32 * 6).saturating_sub(1) * s;
    let label = (
        right.saturating_sub(text_width),
        top.saturating_sub(2 * s + 7 * s),
    );
    Placement {
        left,
        right,
        top,
        thick,
        label,
        cell: s,
    }
}

/// Draws the bar for pixels of `mm_per_pixel` into `rgb` (8-bit RGB, row-major): white, ringed
/// by black, with ticks down at both ends, and its length above it. Returns the length in mm
/// and in pixels.
pub fn draw(rgb: &mut [u8], width: u32, height: u32, mm_per_pixel: f64) -> (f64, u32) {
    let mm = length_mm(mm_per_pixel, width);
    let pixels = (mm / mm_per_pixel).round() as u32;
    let text = words(mm);
    let p = place(width, height, pixels, &text);
    let mut put = |x: i64, y: i64, v: u8| {
        if x >= 0 && y >= 0 && (x as u32) < width && (y as u32) < height {
            let i = 3 * (y as usize * width as usize + x as usize);
            rgb[i..i + 3].fill(v);
        }
    };
    // The bar and its two ticks as rectangles [x0, x1) × [y0, y1).
    let (l, r, t, k) = (p.left as i64, p.right as i64, p.top as i64, p.thick as i64);
    let rects = [
        (l, r, t, t + k),
        (l, l + k, t, t + 2 * k),
        (r - k, r, t, t + 2 * k),
    ];
    for pass in [0u8, 255] {
        let ring = if pass == 0 { 1 } else { 0 };
        for &(x0, x1, y0, y1) in &rects {
            for y in y0 - ring..y1 + ring {
                for x in x0 - ring..x1 + ring {
                    put(x, y, pass);
                }
            }
        }
    }
    crate::labels::draw_text(
        &mut put,
        (p.label.0 as i64, p.label.1 as i64),
        p.cell,
        &text,
    );
    (mm, pixels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bar_takes_a_round_length_of_at_most_a_fifth_of_the_width() {
        // 0.5 mm pixels, 512 wide: a fifth is 51.2 mm; 50 mm, 100 pixels.
        assert_eq!(length_mm(0.5, 512), 50.0);
        // 1.5 mm pixels, 120 wide: 36 mm → 20 mm.
        assert_eq!(length_mm(1.5, 120), 20.0);
        // Exactly a fifth is allowed: 1 mm pixels, 100 wide → 20 mm.
        assert_eq!(length_mm(1.0, 100), 20.0);
        // Micro-CT: 0.01 mm pixels, 300 wide → 0.6 mm → 0.5 mm.
        assert!((length_mm(0.01, 300) - 0.5).abs() < 1e-12);
        for (mm_px, w) in [(0.3, 800), (2.0, 64), (0.07, 1024), (11.0, 333)] {
            let l = length_mm(mm_px, w);
            let most = w as f64 / 5.0 * mm_px;
            assert!(
                l <= most * (1.0 + 1e-9) && l > most / 2.5 - 1e-9,
                "{mm_px} {w}: {l}"
            );
            let m = l / 10f64.powf(l.log10().floor());
            assert!([1.0, 2.0, 5.0].iter().any(|x| (m - x).abs() < 1e-9), "{l}");
        }
    }

    #[test]
    fn lengths_read_as_a_radiologist_writes_them() {
        assert_eq!(words(50.0), "5 cm");
        assert_eq!(words(100.0), "10 cm");
        assert_eq!(words(20.0), "2 cm");
        assert_eq!(words(5.0), "5 mm");
        assert_eq!(words(0.5), "0.5 mm");
        assert_eq!(words(0.02), "0.02 mm");
    }

    /// Drawn into a grey picture: the bar is white from `left` to `right` along its middle
    /// row and ringed by black, its label's glyphs white where they are set, and the rest of
    /// the picture untouched.
    #[test]
    fn the_drawn_bar_reads_back() {
        let (w, h) = (400u32, 300u32);
        let mut rgb = vec![90u8; (3 * w * h) as usize];
        // 1 mm pixels: a fifth of the width is 80 mm, so 5 cm, 50 pixels.
        let (mm, px) = draw(&mut rgb, w, h, 1.0);
        assert_eq!((mm, px), (50.0, 50));
        let p = place(w, h, px, "5 cm");
        let at = |x: u32, y: u32| rgb[(3 * (y * w + x)) as usize];
        let mid = p.top + p.thick / 2;
        for x in p.left..p.right {
            assert_eq!(at(x, mid), 255, "column {x}");
        }
        assert_eq!(at(p.left - 1, mid), 0);
        assert_eq!(at(p.right, mid), 0);
        assert_eq!(at(p.left - 3, mid), 90);
        // The label: each glyph's cells.
        let s = p.cell;
        for (k, ch) in "5 cm".chars().enumerate() {
            let g = crate::labels::glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..5u32 {
                    let x = p.label.0 + (6 * k as u32 + col) * s + s / 2;
                    let y = p.label.1 + row as u32 * s + s / 2;
                    assert_eq!(
                        at(x, y) == 255,
                        bits & (0x10 >> col) != 0,
                        "{ch} {row} {col}"
                    );
                }
            }
        }
        assert_eq!(at(w / 2, h / 2), 90);
        assert_eq!(at(5, h - 5), 90);
    }
}
