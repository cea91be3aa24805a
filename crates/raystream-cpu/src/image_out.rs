//! The rendered film: linear RGB, written as 8-bit sRGB PNG or as the float film itself,
//! OpenEXR.

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
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

/// 8-bit sRGB's curve undone: the linear value that [`Image::to_srgb8`] encodes as `s`
/// (0 to 1) of full scale.
pub fn srgb_to_linear(s: f32) -> f32 {
    let s = s.clamp(0.0, 1.0);
    if s <= 0.040_45 {
        s / 12.92
    } else {
        ((s + 0.055) / 1.055).powf(2.4)
    }
}

impl Image {
    /// 8-bit sRGB, 3 bytes per pixel.
    pub fn to_srgb8(&self) -> Vec<u8> {
        let pixels: Vec<[u8; 3]> = self
            .pixels
            .par_iter()
            .map(|p| [srgb(p.x), srgb(p.y), srgb(p.z)])
            .collect();
        pixels.into_flattened()
    }

    /// How far `other` is from this image in 8-bit sRGB, as `rays.py imgdiff` measures: the
    /// mean absolute channel difference (of 255), and per pixel the largest channel difference.
    pub fn srgb8_diff(&self, other: &Image) -> (f64, Vec<u8>) {
        srgb8_diff(&self.to_srgb8(), &other.to_srgb8())
    }

    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        save_srgb8_png(path, &self.to_srgb8(), self.width, self.height)
    }

    /// The film itself as OpenEXR: channels R, G, B, 32-bit float, linear (no sRGB curve, no
    /// clamping: highlights above 1 keep their values). `what` says what the pixels are; it
    /// goes into the file's comments.
    pub fn save_exr(&self, path: &Path, what: &str) -> Result<(), String> {
        save_exr(path, self.width, self.height, self.exr_channels(), what)
    }

    /// The film's R, G and B as EXR channels (for [`save_exr`], with more channels beside).
    pub fn exr_channels(&self) -> Vec<(&'static str, ExrSamples)> {
        let channel =
            |c: usize| ExrSamples::F32(self.pixels.iter().map(|p| p.to_array()[c]).collect());
        vec![("R", channel(0)), ("G", channel(1)), ("B", channel(2))]
    }

    /// Writes PNG or EXR as `format` says ([`Self::save_png`], [`Self::save_exr`]).
    pub fn save(&self, path: &Path, format: ImageFormat, what: &str) -> Result<(), String> {
        match format {
            ImageFormat::Png => self.save_png(path),
            ImageFormat::Exr => self.save_exr(path, what),
        }
    }
}

/// The file format of a rendered image, from the output's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// 8 (or 16, for distances) bits a channel, as a viewer shows the picture.
    Png,
    /// OpenEXR, 32-bit float channels: the film's linear values, distances and normals as
    /// numbers, triangle numbers as 32-bit integers.
    Exr,
}

impl ImageFormat {
    /// `.png` or `.exr` (any case); anything else is an error naming the path.
    pub fn of(path: &Path) -> Result<ImageFormat, String> {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("png") => Ok(ImageFormat::Png),
            Some(e) if e.eq_ignore_ascii_case("exr") => Ok(ImageFormat::Exr),
            _ => Err(format!(
                "{}: name the image .png (8-bit sRGB, as a viewer shows it) or .exr (the float values)",
                path.display()
            )),
        }
    }
}

/// One channel's samples, one per pixel, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub enum ExrSamples {
    F32(Vec<f32>),
    U32(Vec<u32>),
}

impl ExrSamples {
    /// The samples of a float channel.
    pub fn as_f32(&self) -> Option<&[f32]> {
        match self {
            ExrSamples::F32(v) => Some(v),
            ExrSamples::U32(_) => None,
        }
    }

    /// The samples of an integer channel.
    pub fn as_u32(&self) -> Option<&[u32]> {
        match self {
            ExrSamples::U32(v) => Some(v),
            ExrSamples::F32(_) => None,
        }
    }
}

/// An OpenEXR image read back: its size, its channels by name, its comments.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrFile {
    pub width: u32,
    pub height: u32,
    pub channels: BTreeMap<String, ExrSamples>,
    pub comments: String,
}

/// Reads the first layer of an OpenEXR file, such as [`save_exr`] writes (half-float
/// channels come back as 32-bit floats).
pub fn load_exr(path: &Path) -> Result<ExrFile, String> {
    use exr::prelude::{FlatSamples, ReadChannels, ReadLayers, read};
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| format!("{}: cannot read EXR: {e}", path.display()))?;
    let layer = image.layer_data;
    let channels = layer
        .channel_data
        .list
        .into_iter()
        .map(|c| {
            let samples = match c.sample_data {
                FlatSamples::U32(v) => ExrSamples::U32(v),
                FlatSamples::F32(v) => ExrSamples::F32(v),
                FlatSamples::F16(v) => ExrSamples::F32(v.iter().map(|h| h.to_f32()).collect()),
            };
            (c.name.to_string(), samples)
        })
        .collect();
    Ok(ExrFile {
        width: layer.size.0 as u32,
        height: layer.size.1 as u32,
        channels,
        comments: layer
            .attributes
            .comments
            .map(|t| t.to_string())
            .unwrap_or_default(),
    })
}

/// Writes named channels as one OpenEXR image (scan lines, ZIP: lossless), with `comment` in
/// its comments attribute (ASCII; a non-ASCII comment is left out) and raystream as the
/// software. Channels are stored in name order, as the format requires.
pub fn save_exr(
    path: &Path,
    width: u32,
    height: u32,
    channels: Vec<(&str, ExrSamples)>,
    comment: &str,
) -> Result<(), String> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image as ExrImage, Layer, LayerAttributes,
        SmallVec, Text, WritableImage,
    };
    let n = width as usize * height as usize;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = channels
        .into_iter()
        .map(|(name, samples)| {
            let samples = match samples {
                ExrSamples::F32(v) => FlatSamples::F32(v),
                ExrSamples::U32(v) => FlatSamples::U32(v),
            };
            assert_eq!(samples.len(), n, "channel {name}: one sample a pixel");
            AnyChannel::new(name, samples)
        })
        .collect();
    let attributes = LayerAttributes {
        comments: Text::new_or_none(comment),
        software_name: Text::new_or_none(concat!("raystream ", env!("CARGO_PKG_VERSION"))),
        ..LayerAttributes::default()
    };
    let layer = Layer::new(
        (width as usize, height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(list),
    );
    ExrImage::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| format!("{}: cannot write EXR: {e}", path.display()))
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
