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

    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        image::save_buffer(
            path,
            &self.to_srgb8(),
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| format!("{}: cannot write PNG: {e}", path.display()))
    }
}
