//! Arbitrary output variables (AOVs) of a scene's triangles: one ray through each pixel's
//! centre (the camera rays of a 1-spp frame) and, from its closest hit, an image of the
//! distance, the shading normal or the triangle's number, before any light is computed.
//! They show what a view sees and where two back-ends differ: the hits may come from the CPU
//! traversal or from the GPU's ray queries, and the images are made here from either.
//!
//! Reads: the scene, its camera and one hit (or miss) per pixel. Writes: a 16-bit grey image
//! (distance) or an 8-bit RGB one (normal, triangle), PNG.

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

/// An AOV image, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub enum AovImage {
    /// Distances as 16-bit grey, with the distances that map to white (`near`) and to 1
    /// (`far`); `None` when no ray hit.
    Gray16 {
        width: u32,
        height: u32,
        pixels: Vec<u16>,
        range: Option<(f32, f32)>,
    },
    Rgb8 {
        width: u32,
        height: u32,
        pixels: Vec<u8>,
    },
}

impl AovImage {
    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        let result = match self {
            AovImage::Gray16 {
                width,
                height,
                pixels,
                ..
            } => image::save_buffer(
                path,
                // 16-bit samples go to the encoder in native byte order
                &pixels
                    .iter()
                    .flat_map(|p| p.to_ne_bytes())
                    .collect::<Vec<u8>>(),
                *width,
                *height,
                image::ExtendedColorType::L16,
            ),
            AovImage::Rgb8 {
                width,
                height,
                pixels,
            } => image::save_buffer(
                path,
                pixels,
                *width,
                *height,
                image::ExtendedColorType::Rgb8,
            ),
        };
        result.map_err(|e| format!("{}: cannot write PNG: {e}", path.display()))
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
/// whatever the image size; the image itself is 3 bytes a pixel (4 for distances, until the
/// end).
pub const AOV_CHUNK: u32 = 1 << 20;

/// An AOV image made chunk by chunk: each run of pixels, its rays and their closest hits, is
/// turned into pixel values as it comes, so only the image is held whole.
pub struct AovBuilder<'a> {
    scene: &'a Scene,
    aov: Aov,
    width: u32,
    height: u32,
    /// Depth: the distance of each pixel's hit so far, NaN for a miss.
    dist: Vec<f32>,
    /// Normal, triangle: RGB so far.
    rgb: Vec<u8>,
}

impl<'a> AovBuilder<'a> {
    pub fn new(scene: &'a Scene, aov: Aov, width: u32, height: u32) -> Self {
        let n = (width * height) as usize;
        Self {
            scene,
            aov,
            width,
            height,
            dist: Vec::with_capacity(if aov == Aov::Depth { n } else { 0 }),
            rgb: Vec::with_capacity(if aov == Aov::Depth { 0 } else { 3 * n }),
        }
    }

    /// The next pixels, in order: their rays (from [`aov_rays_of`]) and closest hits.
    pub fn add(&mut self, rays: &[Ray], hits: &[Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "one hit or miss per ray");
        if self.aov == Aov::Depth {
            self.dist.extend(
                rays.iter()
                    .zip(hits)
                    .map(|(r, h)| h.map_or(f32::NAN, |h| h.t * r.dir.length())),
            );
            return;
        }
        let first = self.rgb.len() / 3;
        for (i, (ray, hit)) in rays.iter().zip(hits).enumerate() {
            let rgb = match hit {
                None => [0; 3],
                Some(h) if self.aov == Aov::Prim => prim_colour(h.prim),
                Some(h) => {
                    let item = HitWorkItem {
                        item: RayWorkItem {
                            ray: *ray,
                            pixel: (first + i) as u32,
                            weight: Vec3::ONE,
                        },
                        hit: *h,
                    };
                    let n = surface(self.scene, &item).ns;
                    (n * 127.0 + Vec3::splat(128.0))
                        .round()
                        .clamp(Vec3::ZERO, Vec3::splat(255.0))
                        .to_array()
                        .map(|c| c as u8)
                }
            };
            self.rgb.extend_from_slice(&rgb);
        }
    }

    /// The image, once every pixel has been added.
    pub fn finish(self) -> AovImage {
        let (width, height) = (self.width, self.height);
        let n = (width * height) as usize;
        if self.aov != Aov::Depth {
            assert_eq!(self.rgb.len(), 3 * n, "every pixel added");
            return AovImage::Rgb8 {
                width,
                height,
                pixels: self.rgb,
            };
        }
        assert_eq!(self.dist.len(), n, "every pixel added");
        let range = self
            .dist
            .iter()
            .filter(|d| !d.is_nan())
            .fold(None, |acc, &d| match acc {
                None => Some((d, d)),
                Some((near, far)) => Some((f32::min(near, d), f32::max(far, d))),
            });
        let pixels = self
            .dist
            .iter()
            .map(|&d| match range {
                Some((near, far)) if !d.is_nan() => depth_level(d, near, far),
                _ => 0,
            })
            .collect();
        AovImage::Gray16 {
            width,
            height,
            pixels,
            range,
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
