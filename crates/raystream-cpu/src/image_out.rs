//! The rendered film: linear RGB, written as 8-bit sRGB PNG.

use std::path::Path;

use raystream_math::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// Linear RGB, row-major from the top-left pixel.
    pub pixels: Vec<Vec3>,
}

fn srgb(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

impl Image {
    /// 8-bit sRGB, 3 bytes per pixel.
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.pixels
            .iter()
            .flat_map(|p| [srgb(p.x), srgb(p.y), srgb(p.z)])
            .collect()
    }

    /// How far `other` is from this image in 8-bit sRGB, as `rays.py imgdiff` measures: the
    /// mean absolute channel difference (of 255), and per pixel the largest channel difference.
    pub fn srgb8_diff(&self, other: &Image) -> (f64, Vec<u8>) {
        srgb8_diff(&self.to_srgb8(), &other.to_srgb8())
    }

    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        save_srgb8_png(path, &self.to_srgb8(), self.width, self.height)
    }
}

/// The difference of two 8-bit sRGB images (3 bytes a pixel) as [`Image::srgb8_diff`].
pub fn srgb8_diff(a: &[u8], b: &[u8]) -> (f64, Vec<u8>) {
    assert_eq!(a.len(), b.len(), "images of different sizes");
    let mean = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| x.abs_diff(y) as f64)
        .sum::<f64>()
        / a.len().max(1) as f64;
    let worst = a
        .chunks(3)
        .zip(b.chunks(3))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .map(|(&x, &y)| x.abs_diff(y))
                .max()
                .unwrap_or(0)
        })
        .collect();
    (mean, worst)
}

/// Writes 8-bit sRGB pixels (3 bytes a pixel) as a PNG.
pub fn save_srgb8_png(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<(), String> {
    image::save_buffer(path, rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| format!("{}: cannot write PNG: {e}", path.display()))
}
