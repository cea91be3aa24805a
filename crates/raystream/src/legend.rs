//! `render --legend`: the segments drawn in colour, each named beside a swatch of its colour in
//! the picture's top left corner, so that a reader of the picture knows which colour is which.
//! The names are laid out in the embedded DejaVu Sans through plotters, as `measure --plot`'s
//! text is.

use anyhow::{Result, anyhow};
use plotters::prelude::*;

/// One segment as the legend lists it.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The segment's name, or "label N" where it has none.
    pub name: String,
    /// Its colour as drawn, 8-bit sRGB.
    pub colour: [u8; 3],
}

/// The legend's entries for `labels` (in order) named as `known` names them.
pub fn entries(labels: &[u32], known: &[raystream_io::SegmentLabel]) -> Vec<Entry> {
    labels
        .iter()
        .map(|&l| {
            let name = known
                .iter()
                .find(|k| k.number as u32 == l && !k.label.trim().is_empty())
                .map(|k| format!("{l} {}", k.label.trim()))
                .unwrap_or_else(|| format!("label {l}"));
            Entry {
                name,
                colour: crate::overlay::segment_colour(known, l),
            }
        })
        .collect()
}

/// At most this many entries are listed; the rest are summed up in one more line.
pub const MAX_ENTRIES: usize = 16;

/// The text's height in pixels for an image `height` pixels high: about a 28th of it, at
/// least 12.
pub fn text_height(height: u32) -> u32 {
    (height / 28).max(12)
}

/// Where entry `i`'s swatch lies: its top-left corner and side, in pixels.
pub fn swatch(i: usize, height: u32) -> (u32, u32, u32) {
    let t = text_height(height);
    let (margin, row) = (t / 2, t + t / 3);
    (margin, margin + i as u32 * row, t)
}

/// Draws the legend into `rgb` (8-bit RGB, `width`×`height`, row-major): per entry a swatch of
/// its colour ringed in black and its name in white over a black shadow.
pub fn draw(rgb: &mut [u8], width: u32, height: u32, entries: &[Entry]) -> Result<()> {
    crate::profile::register_font()?;
    let root = BitMapBackend::with_buffer(rgb, (width, height)).into_drawing_area();
    let t = text_height(height);
    let font = ("sans-serif", t as f64).into_font();
    let shown = entries.len().min(MAX_ENTRIES);
    let more = entries.len() - shown;
    let lines = entries[..shown]
        .iter()
        .map(|e| (Some(e.colour), e.name.clone()))
        .chain((more > 0).then(|| (None, format!("… and {more} more"))));
    for (i, (colour, name)) in lines.enumerate() {
        let (x, y, side) = swatch(i, height);
        let (x, y, side) = (x as i32, y as i32, side as i32);
        if let Some([r, g, b]) = colour {
            root.draw(&Rectangle::new(
                [(x - 1, y - 1), (x + side, y + side)],
                BLACK.filled(),
            ))
            .and_then(|_| {
                root.draw(&Rectangle::new(
                    [(x, y), (x + side - 1, y + side - 1)],
                    RGBColor(r, g, b).filled(),
                ))
            })
            .map_err(|e| anyhow!("the legend: {e}"))?;
        }
        let at = (x + side + side / 2, y);
        for (dx, colour) in [(1, &BLACK), (0, &WHITE)] {
            root.draw(&Text::new(
                name.clone(),
                (at.0 + dx, at.1 + dx),
                font.clone().color(colour),
            ))
            .map_err(|e| anyhow!("the legend: {e}"))?;
        }
    }
    root.present().map_err(|e| anyhow!("the legend: {e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two entries drawn into a grey picture: each swatch's middle is its colour exactly,
    /// ringed by black; white (anti-aliased) text lies to the right of each swatch; the rest of the picture
    /// (its bottom right) is untouched.
    #[test]
    fn swatches_and_names_read_back() {
        let (w, h) = (320u32, 240u32);
        let mut rgb = vec![90u8; (3 * w * h) as usize];
        let list = [
            Entry {
                name: "1 Lumen".into(),
                colour: [0, 255, 255],
            },
            Entry {
                name: "2 Wall".into(),
                colour: [255, 0, 255],
            },
        ];
        draw(&mut rgb, w, h, &list).unwrap();
        let at = |x: u32, y: u32| {
            let i = (3 * (y * w + x)) as usize;
            [rgb[i], rgb[i + 1], rgb[i + 2]]
        };
        for (i, e) in list.iter().enumerate() {
            let (x, y, side) = swatch(i, h);
            assert_eq!(at(x + side / 2, y + side / 2), e.colour, "{}", e.name);
            assert_eq!(at(x - 1, y + side / 2), [0; 3], "{}: ringed", e.name);
            let white = (x + side..x + 12 * side)
                .flat_map(|px| (y..y + side).map(move |py| (px, py)))
                .filter(|&(px, py)| at(px, py).iter().all(|&c| c >= 200))
                .count();
            assert!(white > 10, "{}: {white} white pixels of text", e.name);
        }
        for y in h / 2..h {
            for x in w / 2..w {
                assert_eq!(at(x, y), [90; 3]);
            }
        }
    }

    #[test]
    fn entries_take_the_segments_names_and_colours() {
        let known = vec![raystream_io::SegmentLabel {
            number: 2,
            label: "Wall".into(),
            colour: Some([1, 2, 3]),
            ..Default::default()
        }];
        let e = entries(&[2, 5], &known);
        assert_eq!(
            e[0],
            Entry {
                name: "2 Wall".into(),
                colour: [1, 2, 3]
            }
        );
        assert_eq!(e[1].name, "label 5");
        assert_eq!(e[1].colour, crate::overlay::segment_colour(&known, 5));
    }
}
