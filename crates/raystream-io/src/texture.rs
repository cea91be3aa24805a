//! Colour textures of OBJ materials (`map_Kd`) and glTF ones (`baseColorTexture`): an image's texels, and the one lookup both
//! renderers make. The GPU's `texture_colour` (raystream-gpu's render.wgsl) is
//! [`Texture::sample`] step for step, with the same sRGB table ([`SRGB_TO_LINEAR`]), so that the
//! two back-ends shade a textured surface alike.
//!
//! The lookup: texture coordinates are scaled and offset (MTL's `-s` and `-o`: `uv·s + o`, as
//! three.js's MTLLoader reads them), then wrap (repeat), or with `-clamp on` stop at the
//! image's edges; `v` grows upward, as OBJ's `vt` does (the image's first row is `v` = 1);
//! texel centres are at half-integers; four texels are turned to linear light and blended
//! bilinearly. There is no mipmapping, so a texture seen from far away
//! aliases rather than blurs.

use std::path::Path;

use raystream_math::{Vec2, Vec3};

/// The most texels a texture may have: 2²⁶ (8192², 256 MiB of RGBA8).
pub const MAX_TEXELS: u64 = 1 << 26;

/// An image's texels as sRGB RGBA8, row by row from its top, and how a material maps it.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<[u8; 4]>,
    pub mapping: TextureMapping,
}

/// How a material lays its texture on the surface: MTL's `map_Kd` options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureMapping {
    /// `-s u v`: texture coordinates are multiplied by this (1, 1 by default)…
    pub scale: Vec2,
    /// … then `-o u v` is added (0, 0 by default).
    pub offset: Vec2,
    /// `-clamp on`: coordinates outside [0, 1] take the edge's texels instead of repeating.
    pub clamp: bool,
}

impl Default for TextureMapping {
    fn default() -> Self {
        TextureMapping {
            scale: Vec2::ONE,
            offset: Vec2::ZERO,
            clamp: false,
        }
    }
}

/// sRGB-encoded 8-bit values as linear light (IEC 61966-2-1), a table both renderers read.
pub static SRGB_TO_LINEAR: std::sync::LazyLock<[f32; 256]> = std::sync::LazyLock::new(|| {
    std::array::from_fn(|i| {
        let c = i as f64 / 255.0;
        (if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }) as f32
    })
});

/// Linear light (0–1, clamped) as an sRGB-encoded 8-bit value (IEC 61966-2-1): the inverse of
/// [`SRGB_TO_LINEAR`], rounded.
pub fn linear_to_srgb8(c: f64) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

impl Texture {
    /// Reads a PNG or JPEG file (by its content); an error says what is wrong, the caller names
    /// the file. Images over [`MAX_TEXELS`] are refused from their header, before decoding.
    pub fn load(path: &Path) -> Result<Texture, String> {
        Texture::decode(&std::fs::read(path).map_err(|e| e.to_string())?)
    }

    /// [`Texture::load`] of a PNG or JPEG image's bytes (a glTF file's embedded images).
    pub fn decode(bytes: &[u8]) -> Result<Texture, String> {
        let open = || {
            image::ImageReader::new(std::io::Cursor::new(bytes))
                .with_guessed_format()
                .map_err(|e| e.to_string())
        };
        let (w, h) = open()?
            .into_dimensions()
            .map_err(|e| format!("not a readable PNG or JPEG image ({e})"))?;
        if w == 0 || h == 0 || w as u64 * h as u64 > MAX_TEXELS {
            return Err(format!(
                "a {w}x{h} image: empty, or over the {MAX_TEXELS}-texel limit"
            ));
        }
        let img = open()?
            .decode()
            .map_err(|e| format!("not a readable PNG or JPEG image ({e})"))?
            .to_rgba8();
        Ok(Texture {
            width: img.width(),
            height: img.height(),
            texels: img.pixels().map(|p| p.0).collect(),
            mapping: TextureMapping::default(),
        })
    }

    /// The linear RGB colour at texture coordinates `uv` (see the module docs); a coordinate
    /// that is not finite reads as 0.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.width as i32, self.height as i32);
        let TextureMapping {
            scale,
            offset,
            clamp,
        } = self.mapping;
        let uv = uv * scale + offset;
        let fold = |t: f32| match t.is_finite() {
            false => 0.0,
            true if clamp => t.clamp(0.0, 1.0),
            true => t - t.floor(),
        };
        let index = |i: i32, n: i32| {
            if clamp {
                i.clamp(0, n - 1)
            } else {
                i.rem_euclid(n)
            }
        };
        let x = fold(uv.x) * w as f32 - 0.5;
        let y = (1.0 - fold(uv.y)) * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (i0, j0) = (x0 as i32, y0 as i32);
        let lut = &*SRGB_TO_LINEAR;
        let texel = |i: i32, j: i32| {
            let t = self.texels[(index(j, h) * w + index(i, w)) as usize];
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        };
        let top = texel(i0, j0).lerp(texel(i0 + 1, j0), fx);
        let bottom = texel(i0, j0 + 1).lerp(texel(i0 + 1, j0 + 1), fx);
        top.lerp(bottom, fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2×2 texture: red, green on the top row; blue, white below.
    fn quad() -> Texture {
        Texture {
            width: 2,
            height: 2,
            texels: vec![
                [255, 0, 0, 255],
                [0, 255, 0, 255],
                [0, 0, 255, 255],
                [255, 255, 255, 255],
            ],
            mapping: TextureMapping::default(),
        }
    }

    fn mapped(scale: f32, offset: f32, clamp: bool) -> Texture {
        Texture {
            mapping: TextureMapping {
                scale: Vec2::splat(scale),
                offset: Vec2::splat(offset),
                clamp,
            },
            ..quad()
        }
    }

    #[test]
    fn scale_offset_and_clamp_move_the_lookup() {
        let plain = quad();
        // Offset by half the image: each texel centre shows the diagonally opposite texel.
        let moved = mapped(1.0, 0.5, false);
        assert_eq!(moved.sample(Vec2::new(0.25, 0.75)), Vec3::ONE);
        assert_eq!(moved.sample(Vec2::new(0.75, 0.25)), Vec3::X);
        // Three times as large, one back: the quarters' centres fall outside [0, 1]; repeating
        // they wrap to the opposite texel, clamped they keep their own.
        let big = |clamp| mapped(3.0, -1.0, clamp);
        for (uv, own, opposite) in [
            (Vec2::new(0.25, 0.75), Vec3::X, Vec3::ONE),
            (Vec2::new(0.75, 0.25), Vec3::ONE, Vec3::X),
            (Vec2::new(0.25, 0.25), Vec3::Z, Vec3::Y),
        ] {
            assert_eq!(plain.sample(uv), own);
            assert_eq!(big(true).sample(uv), own);
            assert_eq!(big(false).sample(uv), opposite);
        }
        // Clamped, an edge's texel is not blended with the opposite edge's.
        assert_eq!(big(true).sample(Vec2::new(0.0, 1.0)), Vec3::X);
    }

    #[test]
    fn texel_centres_give_their_colour_and_v_grows_upward() {
        let t = quad();
        // Texel centres: u = 0.25 / 0.75, v = 0.75 (top row) / 0.25 (bottom row).
        assert_eq!(t.sample(Vec2::new(0.25, 0.75)), Vec3::X);
        assert_eq!(t.sample(Vec2::new(0.75, 0.75)), Vec3::Y);
        assert_eq!(t.sample(Vec2::new(0.25, 0.25)), Vec3::Z);
        assert_eq!(t.sample(Vec2::new(0.75, 0.25)), Vec3::ONE);
        // Repeats: one period on, or back.
        assert_eq!(t.sample(Vec2::new(1.25, -0.75)), Vec3::Z);
        // Halfway between red and green: the mean in linear light.
        let mid = t.sample(Vec2::new(0.5, 0.75));
        assert!((mid - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6, "{mid}");
        // The edge u = 0 blends the row's two texels, wrapping around.
        assert!((t.sample(Vec2::new(0.0, 0.75)) - mid).length() < 1e-6);
        // Not finite: as 0 (the corner texel blend), never a panic.
        let nan = t.sample(Vec2::new(f32::NAN, f32::INFINITY));
        assert!(nan.is_finite());
        assert!(t.sample(Vec2::new(1e30, -1e30)).is_finite());
    }

    #[test]
    fn the_srgb_table_is_the_standard_curve() {
        let lut = &*SRGB_TO_LINEAR;
        assert_eq!((lut[0], lut[255]), (0.0, 1.0));
        // 128/255 (about 50 % grey): 0.2159 linear; the linear segment at the bottom.
        assert!((lut[128] - 0.21586).abs() < 1e-4, "{}", lut[128]);
        assert!((lut[10] - 10.0 / 255.0 / 12.92).abs() < 1e-7);
        assert!(lut.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn bad_images_are_errors() {
        let scratch = crate::tests::scratch_dir("tex");
        let dir = scratch.path();
        let png = dir.join("t.png");
        image::RgbaImage::from_pixel(3, 2, image::Rgba([10, 20, 30, 255]))
            .save(&png)
            .unwrap();
        let t = Texture::load(&png).unwrap();
        assert_eq!((t.width, t.height, t.texels[5]), (3, 2, [10, 20, 30, 255]));
        let bytes = std::fs::read(&png).unwrap();
        std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
        assert!(Texture::load(&png).is_err());
        std::fs::write(&png, b"not an image").unwrap();
        assert!(Texture::load(&png).unwrap_err().contains("not a readable"));
        assert!(Texture::load(&dir.join("missing.png")).is_err());
        // A PNG header claiming 100000 × 100000 texels: refused before decoding.
        let mut huge = bytes.clone();
        huge[16..20].copy_from_slice(&100_000u32.to_be_bytes());
        huge[20..24].copy_from_slice(&100_000u32.to_be_bytes());
        let mut crc = flate2::Crc::new();
        crc.update(&huge[12..29]);
        huge[29..33].copy_from_slice(&crc.sum().to_be_bytes());
        std::fs::write(&png, &huge).unwrap();
        let e = Texture::load(&png).unwrap_err();
        assert!(
            e.contains("100000x100000 image") && e.contains("limit"),
            "{e}"
        );
    }
}
