//! A CT volume among the meshes of a scene: every ray segment the stream renderer traces —
//! camera, reflection and refraction rays up to their mesh hit, shadow rays up to their light
//! — also passes through the volume.
//!
//! - A ray's segment adds the volume's emission (front-to-back compositing through the transfer
//!   function, as `--mode dvr`) to its pixel and passes on the segment's transmittance in its
//!   weight, so the surface it hits, or the background, shows through the volume: the volume
//!   stops at the nearest mesh, meshes show through it, and mirrors reflect it.
//! - A shadow ray from a mesh toward a light is attenuated by the volume's transmittance along
//!   it: the volume shadows the meshes.
//! - Volume samples are lit by the scene's point lights, each through a [`LightGrid`] of shadow
//!   rays toward the light that both the volume and the meshes stop: the meshes and the volume
//!   shadow the volume.
//!
//! The volume lives in the scene frame turned from LPS (x = L, y = S, z = A); rays are turned
//! to LPS millimetres for marching (a rotation: lengths and ray parameters keep their meaning).

use raystream_accel::{Isa, KdTree, Traversal};
use raystream_math::{Ray, Vec3};
use raystream_scene::{Scene, SceneVolume};
use raystream_volume::TransferFunction;

use crate::dvr::{
    Composited, LightGrid, Marcher, Ray3, SampleLight, Toward, lps_to_scene, scene_to_lps,
};

/// A scene's volume prepared for the renderer's rays.
pub struct Medium<'a> {
    marcher: Marcher<'a>,
    tf: &'a TransferFunction,
    /// Step in mm.
    pub step: f32,
    /// The scene's lights in LPS: position and colour.
    lights: Vec<(Vec3, Vec3)>,
    /// One light grid per light, when the volume is shadowed.
    grids: Vec<LightGrid>,
}

impl<'a> Medium<'a> {
    /// Prepares `v` (the volume of `scene`, whose meshes `tree` holds): brick table, and a
    /// light grid per light whose shadow rays meet the meshes and the volume.
    pub fn new(
        v: &'a SceneVolume,
        scene: &Scene,
        tree: &KdTree,
        traversal: Traversal,
    ) -> Medium<'a> {
        Medium::new_in(Isa::current(), v, scene, tree, traversal)
    }

    /// [`Medium::new`], its light grids built and its rays marched in the instruction set
    /// `isa` ([`Marcher::in_isa`]): the same bits in every one.
    pub fn new_in(
        isa: Isa,
        v: &'a SceneVolume,
        scene: &Scene,
        tree: &KdTree,
        traversal: Traversal,
    ) -> Medium<'a> {
        let marcher = Marcher::interpolated(&v.volume, Some(&v.tf), v.interpolation)
            .painted(v.segments.as_ref())
            .in_isa(isa);
        let step = crate::dvr::step_for(v.step_mm, &v.volume);
        let shadow_step = crate::dvr::shadow_step_for(v.step_mm, &v.volume);
        let lights: Vec<(Vec3, Vec3)> = scene
            .lights
            .iter()
            .map(|l| (scene_to_lps(l.position), l.color))
            .collect();
        let grids = if v.shadows {
            lights
                .iter()
                .map(|&(at, _)| {
                    LightGrid::toward_point(&marcher, &v.tf, at, shadow_step, |p, light| {
                        let ray =
                            Ray::new(lps_to_scene(p), lps_to_scene(light - p), 0.0, 1.0 - 1e-4);
                        tree.intersect_any(&ray, traversal).is_some()
                    })
                })
                .collect()
        } else {
            Vec::new()
        };
        Medium {
            marcher,
            tf: &v.tf,
            step,
            lights,
            grids,
        }
    }

    /// The volume prepared for marching (brick table, index transforms).
    pub fn marcher(&self) -> &Marcher<'a> {
        &self.marcher
    }

    /// The light grids (one per scene light) when the volume is shadowed.
    pub fn light_grids(&self) -> &[LightGrid] {
        &self.grids
    }

    /// The scene's lights as volume samples see them, for [`Medium::segment`]: built once per
    /// stage, not per ray.
    pub fn sample_lights(&self) -> Vec<SampleLight<'_>> {
        self.lights
            .iter()
            .enumerate()
            .map(|(i, &(at, color))| SampleLight {
                toward: Toward::Point(at),
                color,
                grid: self.grids.get(i),
            })
            .collect()
    }

    /// The volume along `ray` (scene frame) from `ray.t_min` to `t_end`, its sample lattice
    /// offset by `jitter` steps, lit by `lights` ([`Medium::sample_lights`]): emitted colour and
    /// transmittance, with the samples taken.
    pub fn segment(
        &self,
        ray: &Ray,
        t_end: f32,
        jitter: f32,
        lights: &[SampleLight],
    ) -> Composited {
        match self.enter(ray, t_end, jitter) {
            Some((r, idx, span)) => self
                .marcher
                .composite_ray(self.tf, r, idx, span, self.step, true, lights),
            None => Composited {
                transmit: 1.0,
                ..Default::default()
            },
        }
    }

    /// The volume's transmittance along the shadow ray `ray` (scene frame), from `t_min` to
    /// `t_max`, its sample lattice offset by `jitter` steps.
    pub fn transmittance(&self, ray: &Ray, jitter: f32) -> f32 {
        match self.enter(ray, ray.t_max, jitter) {
            Some((_, (o_idx, d_idx), span)) => {
                self.marcher
                    .absorb(self.tf, o_idx, d_idx, span, self.step, jitter)
                    .0
            }
            None => 1.0,
        }
    }

    /// `ray` in LPS with its jitter, its index form (origin, direction), and the part
    /// [t0, t1] (mm) of [t_min, t_end] inside the grid of voxel centres; `None` when it misses
    /// the volume.
    fn enter(&self, ray: &Ray, t_end: f32, jitter: f32) -> Option<(Ray3, (Vec3, Vec3), [f32; 2])> {
        let len = ray.dir.length();
        if len.is_nan() || len <= 0.0 {
            return None;
        }
        let r = Ray3 {
            o: scene_to_lps(ray.origin),
            d: scene_to_lps(ray.dir) / len,
            jitter,
        };
        let (o_idx, d_idx) = (self.marcher.index_of(r.o), self.marcher.index_dir(r.d));
        let (g0, g1) = self.marcher.clip(o_idx, d_idx)?;
        let t0 = g0.max(ray.t_min * len);
        let t1 = g1.min(t_end * len);
        (t0 < t1).then_some((r, (o_idx, d_idx), [t0, t1]))
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use raystream_accel::{Builder, KdTree};
    use raystream_io::Volume;
    use raystream_scene::{Scene, SceneDesc, SceneVolume};
    use raystream_volume::{Shading, TransferFunction};

    use super::*;
    use crate::{Image, RenderOptions, render};

    /// A homogeneous 21³ volume of 1 mm voxels at the LPS origin: in the scene frame it fills
    /// x ∈ [0, 20], y ∈ [0, 20], z ∈ [−20, 0].
    fn cube() -> Volume {
        Volume::hounsfield([21; 3], [1.0; 3], vec![40.0; 21 * 21 * 21])
    }

    /// Opacity `alpha` per mm everywhere, colour `c`, ambient `ambient`.
    fn uniform(alpha: f32, c: f32, ambient: f32) -> TransferFunction {
        TransferFunction {
            opacity: vec![(-5000.0, alpha), (5000.0, alpha)],
            color: vec![(0.0, [c; 3])],
            shading: Shading {
                ambient,
                ..Default::default()
            },
        }
    }

    /// `toml` compiled, with the cube volume through `tf` put in.
    fn scene_with(toml_text: &str, tf: Option<TransferFunction>, shadows: bool) -> Scene {
        let desc: SceneDesc = toml::from_str(toml_text).unwrap();
        let mut s = Scene::from_desc(&desc, Path::new("."), Path::new("test.toml")).unwrap();
        s.volume = tf.map(|tf| SceneVolume {
            volume: cube(),
            tf,
            step_mm: Some(0.25),
            shadows,
            interpolation: raystream_volume::Interpolation::Cubic,
            segmentation: None,
            segments: None,
        });
        s
    }

    fn draw(s: &Scene, w: u32, h: u32) -> Image {
        let tree = KdTree::build(&s.mesh, Builder::Sah);
        let opt = RenderOptions {
            width: w,
            height: h,
            spp: 1,
            max_depth: 2,
            traversal: Traversal::Ropes,
        };
        render(s, &tree, &opt, |_| {})
    }

    fn close(got: f32, want: f32, rel: f32) -> bool {
        (got - want).abs() <= rel * want.abs()
    }

    /// A camera ray stops at a mesh inside the volume: the wall 12 mm deep shows through
    /// exp(−σ·12) of the volume (a black volume: absorption only), and without the wall the
    /// background shows through the full 20 mm.
    #[test]
    fn volume_rays_stop_at_the_nearest_mesh() {
        let alpha = 0.03f32;
        let view = |wall: bool| {
            format!(
                r#"
                background = [1, 1, 1]
                ambient = [1, 1, 1]
                [camera]
                eye = [10, 10, 50]
                target = [10, 10, 0]
                fov = 10
                [materials.wall]
                ambient = [0.5, 0.5, 0.5]
                diffuse = [0, 0, 0]
                specular = [0, 0, 0]
                [[objects]]
                shape = "quad"
                material = "wall"
                rotate = [90, 0, 0]
                scale = 4
                translate = [10, 10, {}]
                "#,
                if wall { -12 } else { -500 }
            )
        };
        let s = scene_with(&view(true), Some(uniform(alpha, 0.0, 0.1)), false);
        let got = draw(&s, 3, 3).pixels[4].x;
        let want = 0.5 * (1.0 - alpha).powf(12.0);
        assert!(close(got, want, 0.01), "wall: {got} vs {want}");
        let s = scene_with(&view(false), Some(uniform(alpha, 0.0, 0.1)), false);
        let got = draw(&s, 3, 3).pixels[4].x;
        // The far wall is 500 mm away, outside the volume; the background is never reached.
        let want = 0.5 * (1.0 - alpha).powf(20.0);
        assert!(close(got, want, 0.01), "behind the volume: {got} vs {want}");
    }

    /// A floor under the volume, lit from straight above through it, receives exp(−σ·20) of
    /// the light: the volume shadows meshes.
    #[test]
    fn the_volume_shadows_meshes() {
        let alpha = 0.02f32;
        let text = r#"
            background = [0, 0, 0]
            ambient = [0, 0, 0]
            [camera]
            eye = [10, -2, 60]
            target = [10, -5, -10]
            fov = 5
            [[lights]]
            position = [10, 1000, -10]
            [materials.floor]
            ambient = [0, 0, 0]
            diffuse = [1, 1, 1]
            specular = [0, 0, 0]
            [[objects]]
            shape = "quad"
            material = "floor"
            scale = 200
            translate = [10, -5, -10]
        "#;
        let lit = draw(&scene_with(text, Some(uniform(0.0, 0.0, 0.1)), false), 3, 3).pixels[4].x;
        let shadowed = draw(
            &scene_with(text, Some(uniform(alpha, 0.0, 0.1)), false),
            3,
            3,
        )
        .pixels[4]
            .x;
        assert!(lit > 0.5, "{lit}");
        let want = lit * (1.0 - alpha).powf(20.0);
        assert!(close(shadowed, want, 0.01), "{shadowed} vs {want}");
    }

    /// A mirror beside the volume shows it as a direct view along the same line does: the
    /// emission of a homogeneous volume, c·ambient·(1 − (1 − α)^20), through reflection rays.
    #[test]
    fn mirrors_reflect_the_volume() {
        let (alpha, c, amb) = (0.05f32, 0.8f32, 0.5f32);
        let tf = || Some(uniform(alpha, c, amb));
        let mirror = r#"
            background = [0, 0, 0]
            ambient = [0, 0, 0]
            [camera]
            eye = [30, 10, -10]
            target = [40, 10, -10]
            fov = 5
            [materials.mirror]
            ambient = [0, 0, 0]
            diffuse = [0, 0, 0]
            specular = [0, 0, 0]
            reflectivity = 1.0
            [[objects]]
            shape = "quad"
            material = "mirror"
            rotate = [0, 0, 90]
            scale = 10
            translate = [40, 10, -10]
        "#;
        let direct = mirror.replace("target = [40, 10, -10]", "target = [0, 10, -10]");
        let want = c * amb * (1.0 - (1.0 - alpha).powf(20.0));
        let seen = draw(&scene_with(mirror, tf(), false), 3, 3).pixels[4].x;
        let looked = draw(&scene_with(&direct, tf(), false), 3, 3).pixels[4].x;
        assert!(close(looked, want, 0.01), "direct: {looked} vs {want}");
        assert!(close(seen, want, 0.01), "in the mirror: {seen} vs {want}");
    }

    /// A plate above the left half of the volume, between it and the light, darkens that half:
    /// the volume's light grid sees the meshes. Without shadows both halves are lit alike.
    #[test]
    fn meshes_shadow_the_volume() {
        let text = r#"
            background = [0, 0, 0]
            ambient = [0, 0, 0]
            [camera]
            eye = [10, 10, 80]
            target = [10, 10, 0]
            fov = 12
            [[lights]]
            position = [10, 1000, -10]
            [[objects]]
            shape = "quad"
            scale = 20
            translate = [0, 25, -10]
        "#;
        let tf = || Some(uniform(0.01, 1.0, 0.1));
        let halves = |img: &Image| {
            let (w, h) = (img.width as usize, img.height as usize);
            let mean = |cols: std::ops::Range<usize>| {
                let n = (cols.len() * h) as f32;
                cols.flat_map(|x| (0..h).map(move |y| x + w * y))
                    .map(|i| img.pixels[i].x)
                    .sum::<f32>()
                    / n
            };
            (mean(2..w / 2 - 3), mean(w / 2 + 3..w - 2))
        };
        let (left, right) = halves(&draw(&scene_with(text, tf(), true), 24, 16));
        assert!(left < 0.6 * right, "shadowed {left}, lit {right}");
        let m = scene_with(text, tf(), true);
        let tree = KdTree::build(&m.mesh, Builder::Sah);
        let medium = Medium::new(m.volume.as_ref().unwrap(), &m, &tree, Traversal::Ropes);
        let grid = &medium.light_grids()[0];
        // Grid points under the plate get no light; the others get exp(−σ·(distance to the
        // top)) through the volume.
        assert_eq!(grid.at(Vec3::new(4.0, 10.0, 10.0)), 0.0);
        let open = grid.at(Vec3::new(16.0, 10.0, 10.0));
        assert!(open > 0.85 && open <= 1.0, "{open}");
        let (left, right) = halves(&draw(&scene_with(text, tf(), false), 24, 16));
        assert!(close(left, right, 0.02), "unshadowed {left} vs {right}");
    }

    /// A scene's volume marched in x86-64-v3 ([`Medium::new_in`]: its light grids and its
    /// rays' segments) gives the baseline's frame and grid, bit for bit: a graded, grainy cube
    /// (cubic B-spline, shadows through a point light's grid) behind and around a quad.
    #[test]
    fn scene_volumes_are_the_same_in_every_instruction_set() {
        let text = r#"
            background = [0.1, 0.2, 0.3]
            [camera]
            eye = [30, 25, 60]
            target = [10, 10, -10]
            fov = 35
            [[lights]]
            position = [10, 60, 20]
            [[objects]]
            shape = "quad"
            scale = 14
            translate = [3, 8, 4]
        "#;
        let grainy = |i: usize, j: usize, k: usize| {
            (20 * i + 7 * j + 3 * k) as f32 + ((i * 31 + j * 17 + k * 7) % 13) as f32 * 9.0
        };
        let data: Vec<f32> = (0..21)
            .flat_map(|k| (0..21).flat_map(move |j| (0..21).map(move |i| grainy(i, j, k))))
            .collect();
        let tf = TransferFunction {
            opacity: vec![(100.0, 0.0), (300.0, 0.08), (500.0, 0.3)],
            color: vec![(100.0, [0.9, 0.4, 0.3]), (500.0, [1.0, 1.0, 0.8])],
            shading: Shading {
                ambient: 0.2,
                ..Default::default()
            },
        };
        let mut s = scene_with(text, Some(tf), true);
        s.volume.as_mut().unwrap().volume = Volume::hounsfield([21; 3], [1.0; 3], data);
        let tree = KdTree::build(&s.mesh, Builder::Sah);
        let opt = RenderOptions {
            width: 40,
            height: 30,
            spp: 2,
            max_depth: 2,
            traversal: Traversal::Ropes,
        };
        let probe = Vec3::new(6.5, 9.25, 12.75);
        let mut frames = Vec::new();
        for isa in crate::tests::isas() {
            let m = Medium::new_in(isa, s.volume.as_ref().unwrap(), &s, &tree, Traversal::Ropes);
            let img = crate::render_prepared(&s, &tree, Some(&m), &opt, |_| {});
            let grid = m.light_grids()[0].at(probe).to_bits();
            frames.push((isa, crate::tests::pixel_bits(&img), grid));
        }
        let (first, image, grid) = &frames[0];
        let background = Vec3::new(0.1, 0.2, 0.3).to_array().map(f32::to_bits);
        let shown = image.iter().filter(|p| **p != background).count();
        // Measured: 264 of the 1,200 pixels.
        assert!(shown > 200, "the volume and the quad: {shown} pixels");
        for (isa, img, g) in &frames[1..] {
            assert!(img == image, "{} differs from {}", isa.name(), first.name());
            assert_eq!(g, grid, "{}: the light grid", isa.name());
        }
    }

    /// A volume that the transfer function makes transparent changes nothing, bit for bit.
    #[test]
    fn a_transparent_volume_changes_nothing() {
        let s = Scene::builtin_default();
        let plain = draw(&s, 40, 30);
        let mut with = s.clone();
        with.volume = Some(SceneVolume {
            volume: cube(),
            tf: uniform(0.0, 1.0, 0.1),
            step_mm: None,
            shadows: true,
            interpolation: raystream_volume::Interpolation::Cubic,
            segmentation: None,
            segments: None,
        });
        assert_eq!(draw(&with, 40, 30), plain);
    }
}
