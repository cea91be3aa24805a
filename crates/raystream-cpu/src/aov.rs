//! Arbitrary output variables (AOVs) of a scene's triangles: one ray through each pixel's
//! centre (the camera rays of a 1-spp frame) and, from its closest hit, an image of the
//! distance, the shading normal or the triangle's number, before any light is computed.
//! They show what a view sees and where two back-ends differ: the hits may come from the CPU
//! traversal or from the GPU's ray queries, and the images are made here from either.
//!
//! Reads: the scene, its camera and one hit (or miss) per pixel. Writes: a 16-bit grey image
//! (distance) or an 8-bit RGB one (normal, triangle), PNG; or the values themselves, OpenEXR.

use std::ops::Range;
use std::path::Path;

use raystream_accel::Hit;
use raystream_math::{Ray, Vec3};
use raystream_scene::{Camera, Scene};

use crate::{HitWorkItem, RayWorkItem, surface};

/// Which quantity an AOV image shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aov {
    /// Distance from the eye along the ray to the closest hit, in scene units (millimetres for
    /// CT): 16-bit grey, the nearest hit white (65535), the farthest 1, misses 0.
    Depth,
    /// Shading normal at the hit, world space, turned to face the eye (as shading uses it):
    /// RGB = 128 + 127 n (an axis 255 or 1, zero 128); misses black.
    Normal,
    /// The triangle hit (its number in file order, polygons fanned), as a colour hashed from
    /// the number, never black; misses black.
    Prim,
}

impl Aov {
    pub fn name(self) -> &'static str {
        match self {
            Aov::Depth => "depth",
            Aov::Normal => "normal",
            Aov::Prim => "prim",
        }
    }
}

/// What an AOV image holds, one value per pixel, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub enum AovValues {
    /// Distance from the eye to the closest hit, scene units; +∞ for a miss.
    Depth(Vec<f32>),
    /// The unit shading normal facing the eye; zero for a miss.
    Normal(Vec<Vec3>),
    /// The triangle hit; [`NO_PRIM`] for a miss.
    Prim(Vec<u32>),
}

/// The triangle number of a miss in [`AovValues::Prim`].
pub const NO_PRIM: u32 = u32::MAX;

/// An AOV image: its values ([`AovValues`]), written as PNG (quantized as [`Aov`] says) or as
/// OpenEXR (the values themselves).
#[derive(Clone, Debug, PartialEq)]
pub struct AovImage {
    pub width: u32,
    pub height: u32,
    pub values: AovValues,
}

impl AovImage {
    /// Depth: the nearest and the farthest hit's distance (white and grey level 1 in the PNG);
    /// `None` when no ray hit or for other AOVs.
    pub fn depth_range(&self) -> Option<(f32, f32)> {
        let AovValues::Depth(d) = &self.values else {
            return None;
        };
        d.iter()
            .filter(|d| d.is_finite())
            .fold(None, |acc, &d| match acc {
                None => Some((d, d)),
                Some((near, far)) => Some((f32::min(near, d), f32::max(far, d))),
            })
    }

    /// Depth as the PNG's 16-bit grey levels: the nearest hit 65535, the farthest 1, misses 0.
    pub fn gray16(&self) -> Option<Vec<u16>> {
        let AovValues::Depth(d) = &self.values else {
            return None;
        };
        let range = self.depth_range();
        Some(
            d.iter()
                .map(|&d| match range {
                    Some((near, far)) if d.is_finite() => depth_level(d, near, far),
                    _ => 0,
                })
                .collect(),
        )
    }

    /// Normal and triangle as the PNG's 8-bit RGB (3 bytes a pixel): RGB = 128 + 127 n, or the
    /// triangle's hashed colour ([`prim_colour`]); misses black.
    pub fn rgb8(&self) -> Option<Vec<u8>> {
        match &self.values {
            AovValues::Depth(_) => None,
            AovValues::Normal(n) => Some(
                n.iter()
                    .flat_map(|&n| {
                        if n == Vec3::ZERO {
                            return [0; 3];
                        }
                        (n * 127.0 + Vec3::splat(128.0))
                            .round()
                            .clamp(Vec3::ZERO, Vec3::splat(255.0))
                            .to_array()
                            .map(|c| c as u8)
                    })
                    .collect(),
            ),
            AovValues::Prim(p) => Some(
                p.iter()
                    .flat_map(|&p| if p == NO_PRIM { [0; 3] } else { prim_colour(p) })
                    .collect(),
            ),
        }
    }

    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        let (w, h) = (self.width, self.height);
        let result = match (self.gray16(), self.rgb8()) {
            (Some(grey), _) => image::save_buffer(
                path,
                // 16-bit samples go to the encoder in native byte order
                &grey
                    .iter()
                    .flat_map(|p| p.to_ne_bytes())
                    .collect::<Vec<u8>>(),
                w,
                h,
                image::ExtendedColorType::L16,
            ),
            (_, Some(rgb)) => image::save_buffer(path, &rgb, w, h, image::ExtendedColorType::Rgb8),
            (None, None) => unreachable!("every AOV is grey or RGB"),
        };
        result.map_err(|e| format!("{}: cannot write PNG: {e}", path.display()))
    }

    /// The values themselves as OpenEXR: depth as channel Z (32-bit float, scene units, +∞
    /// for a miss), the normal as N.X, N.Y, N.Z (float, zero for a miss), the triangle as
    /// channel prim (32-bit unsigned, 4294967295 for a miss). `units` names the scene unit
    /// (the file's comments say what the channels are).
    pub fn save_exr(&self, path: &Path, units: &str) -> Result<(), String> {
        use crate::ExrSamples::{F32, U32};
        let (channels, what) = match &self.values {
            AovValues::Depth(d) => (
                vec![("Z", F32(d.clone()))],
                format!("Z: distance from the eye to the closest hit, {units}; inf: no hit"),
            ),
            AovValues::Normal(n) => (
                ["N.X", "N.Y", "N.Z"]
                    .into_iter()
                    .enumerate()
                    .map(|(c, name)| (name, F32(n.iter().map(|v| v.to_array()[c]).collect())))
                    .collect(),
                "N: unit shading normal at the closest hit, world axes, facing the eye; 0: no hit"
                    .to_string(),
            ),
            AovValues::Prim(p) => (
                vec![("prim", U32(p.clone()))],
                "prim: the triangle hit first (file order, polygons fanned); 4294967295: no hit"
                    .to_string(),
            ),
        };
        crate::save_exr(path, self.width, self.height, channels, &what)
    }

    /// Writes PNG or EXR as `format` says.
    pub fn save(&self, path: &Path, format: crate::ImageFormat, units: &str) -> Result<(), String> {
        match format {
            crate::ImageFormat::Png => self.save_png(path),
            crate::ImageFormat::Exr => self.save_exr(path, units),
        }
    }
}

/// The rays of an AOV image: one through each pixel's centre, pixel-major from the top left
/// (the camera rays of a 1-spp frame).
pub fn aov_rays(cam: &Camera, width: u32, height: u32) -> Vec<Ray> {
    aov_rays_of(cam, width, height, 0..width * height)
}

/// [`aov_rays`] of the pixels `pixels` only.
pub fn aov_rays_of(cam: &Camera, width: u32, height: u32, pixels: Range<u32>) -> Vec<Ray> {
    crate::camera_rays_of(cam, width, height, 1, pixels)
        .into_iter()
        .map(|w| w.ray)
        .collect()
}

/// Pixels traced at once by [`AovBuilder`]'s callers: rays and hits stay bounded (tens of MB)
/// whatever the image size; the image itself is 4 bytes a pixel (12 for normals).
pub const AOV_CHUNK: u32 = 1 << 20;

/// An AOV image made chunk by chunk: each run of pixels, its rays and their closest hits, is
/// turned into pixel values as it comes, so only the image is held whole.
pub struct AovBuilder<'a> {
    scene: &'a Scene,
    width: u32,
    height: u32,
    values: AovValues,
}

impl<'a> AovBuilder<'a> {
    pub fn new(scene: &'a Scene, aov: Aov, width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        Self {
            scene,
            width,
            height,
            values: match aov {
                Aov::Depth => AovValues::Depth(Vec::with_capacity(n)),
                Aov::Normal => AovValues::Normal(Vec::with_capacity(n)),
                Aov::Prim => AovValues::Prim(Vec::with_capacity(n)),
            },
        }
    }

    /// The next pixels, in order: their rays (from [`aov_rays_of`]) and closest hits.
    pub fn add(&mut self, rays: &[Ray], hits: &[Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "one hit or miss per ray");
        match &mut self.values {
            AovValues::Depth(d) => d.extend(
                rays.iter()
                    .zip(hits)
                    .map(|(r, h)| h.map_or(f32::INFINITY, |h| h.t * r.dir.length())),
            ),
            AovValues::Prim(p) => p.extend(hits.iter().map(|h| h.map_or(NO_PRIM, |h| h.prim))),
            AovValues::Normal(n) => {
                let first = n.len();
                n.extend(rays.iter().zip(hits).enumerate().map(|(i, (ray, hit))| {
                    hit.map_or(Vec3::ZERO, |hit| {
                        let item = HitWorkItem {
                            item: RayWorkItem {
                                ray: *ray,
                                pixel: (first + i) as u32,
                                weight: Vec3::ONE,
                            },
                            hit,
                        };
                        surface(self.scene, &item).ns
                    })
                }))
            }
        }
    }

    /// The image, once every pixel has been added.
    pub fn finish(self) -> AovImage {
        let len = match &self.values {
            AovValues::Depth(v) => v.len(),
            AovValues::Normal(v) => v.len(),
            AovValues::Prim(v) => v.len(),
        };
        assert_eq!(
            len,
            (self.width * self.height) as usize,
            "every pixel added"
        );
        AovImage {
            width: self.width,
            height: self.height,
            values: self.values,
        }
    }
}

/// The `aov` image of `scene` from the closest hits of [`aov_rays`] (`rays`, one per pixel).
pub fn aov_image(
    scene: &Scene,
    rays: &[Ray],
    hits: &[Option<Hit>],
    width: u32,
    height: u32,
    aov: Aov,
) -> AovImage {
    assert_eq!(rays.len(), (width * height) as usize, "one ray per pixel");
    let mut b = AovBuilder::new(scene, aov, width, height);
    b.add(rays, hits);
    b.finish()
}

/// Distance `d` in `[near, far]` as a grey level: `near` → 65535, `far` → 1 (0 is a miss).
fn depth_level(d: f32, near: f32, far: f32) -> u16 {
    if far <= near {
        return u16::MAX;
    }
    let s = ((far - d) / (far - near)).clamp(0.0, 1.0);
    (1.0 + s * 65534.0).round() as u16
}

/// A colour for triangle `prim`: its number hashed (so that neighbours differ), each channel
/// at least 32 so that no triangle is black like a miss.
pub fn prim_colour(prim: u32) -> [u8; 3] {
    let mut x = prim.wrapping_add(0x9E37_79B9);
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846C_A68B);
    x ^= x >> 16;
    let b = x.to_le_bytes();
    [b[0], b[1], b[2]].map(|c| 32 + (c as u16 * 223 / 255) as u8)
}
