use std::path::Path;

use raystream_accel::{Builder, KdTree};
use raystream_math::Vec3;
use raystream_scene::{Scene, SceneDesc};

use super::*;

/// The tests' random numbers: Marsaglia's xorshift64, fixed seeds, the same draws every run.
pub(crate) struct XorShift(pub u64);

impl XorShift {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform in [0, 1), 24 bits.
    pub(crate) fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [0, 1), 53 bits.
    pub(crate) fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The instruction sets this processor marches volumes in ([`raystream_accel::Isa`]). Under
/// `CI=true` an x86-64 machine must have x86-64-v3, so that its copies are tested there.
pub(crate) fn isas() -> Vec<raystream_accel::Isa> {
    use raystream_accel::Isa;
    if cfg!(target_arch = "x86_64") && std::env::var("CI").is_ok_and(|v| v == "true") {
        assert!(
            Isa::X86_64V3.available(),
            "CI=true: this x86-64 processor lacks x86-64-v3, whose volume renderers would go untested"
        );
    }
    Isa::ALL.into_iter().filter(|i| i.available()).collect()
}

/// Every pixel's bits, so that frames compare bit for bit (−0 against +0, NaN payloads).
pub(crate) fn pixel_bits(img: &Image) -> Vec<[u32; 3]> {
    img.pixels
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

fn scene(toml_text: &str) -> Scene {
    let desc: SceneDesc = toml::from_str(toml_text).unwrap();
    Scene::from_desc(&desc, Path::new("."), Path::new("test.toml")).unwrap()
}

fn render_scene(s: &Scene, w: u32, h: u32, max_depth: u32) -> Image {
    let tree = KdTree::build(&s.mesh, Builder::Sah);
    let opt = RenderOptions {
        width: w,
        height: h,
        spp: 1,
        max_depth,
        traversal: Traversal::Ropes,
    };
    render(s, &tree, &opt, |_| {})
}

/// Two parallel mirrors facing each other with the camera between them, no lights: every
/// bounce adds its ambient colour M weighted as the paper's C(n) = Σ_j M (Π_{i<j} r)(1 − r),
/// so the centre pixel is M·(1 − r^(n+1)) after n reflection levels.
#[test]
fn compositing_follows_the_papers_formula() {
    let r = 0.6f32;
    let m = 0.5f32; // ambient coefficient × ambient light
    let s = scene(&format!(
        r#"
        background = [0, 0, 0]
        ambient = [1, 1, 1]
        [camera]
        eye = [0, 0, 0]
        target = [0, 0, -1]
        fov = 10
        [materials.mirror]
        ambient = [{m}, {m}, {m}]
        diffuse = [0, 0, 0]
        specular = [0, 0, 0]
        reflectivity = {r}
        [[objects]]
        shape = "quad"
        material = "mirror"
        rotate = [90, 0, 0]
        scale = 50
        translate = [0, 0, -1]
        [[objects]]
        shape = "quad"
        material = "mirror"
        rotate = [-90, 0, 0]
        scale = 50
        translate = [0, 0, 1]
        "#
    ));
    for n in 0..6 {
        let img = render_scene(&s, 3, 3, n);
        let got = img.pixels[4].x;
        let want = m * (1.0 - r.powi(n as i32 + 1));
        assert!((got - want).abs() < 1e-5, "depth {n}: {got} vs {want}");
    }
}

/// A glass slab seen head-on passes τ(1 − F) of the background behind it at each face.
#[test]
fn refraction_passes_light_through_glass() {
    let s = scene(
        r#"
        background = [1, 1, 1]
        ambient = [0, 0, 0]
        [camera]
        eye = [0, 0, 5]
        target = [0, 0, 0]
        fov = 5
        [materials.glass]
        ambient = [0, 0, 0]
        diffuse = [0, 0, 0]
        specular = [0, 0, 0]
        transparency = 1.0
        ior = 1.5
        [[objects]]
        shape = "sphere"
        material = "glass"
        "#,
    );
    let img = render_scene(&s, 1, 1, 8);
    // Head-on through a sphere: two interfaces, each transmitting 1 − R0 = 0.96 at normal
    // incidence; reflected parts return to the background too (also white), so with enough
    // depth nearly all light arrives.
    let c = img.pixels[0].x;
    assert!(c > 0.95 && c <= 1.0 + 1e-5, "{c}");
    let shallow = render_scene(&s, 1, 1, 1).pixels[0].x;
    assert!(shallow < c, "deeper paths add light: {shallow} vs {c}");
}

/// A lit floor is darker where an occluder shadows it.
#[test]
fn shadows_darken_the_floor() {
    let s = scene(
        r#"
        background = [0, 0, 0]
        ambient = [0, 0, 0]
        [camera]
        eye = [0, 8, 0.001]
        target = [0, 0, 0]
        fov = 40
        [[lights]]
        position = [6, 10, 0]
        [materials.floor]
        reflectivity = 0.0
        [[objects]]
        shape = "sphere"
        scale = 0.5
        translate = [0, 2, 0]
        [[objects]]
        shape = "quad"
        material = "floor"
        scale = 20
        "#,
    );
    let img = render_scene(&s, 33, 33, 0);
    // The light at x = 6 throws the sphere's shadow to x = −1.5 on the floor (pixel ≈ 7.5);
    // the mirror point x = +1.5 (pixel ≈ 24.5) is lit at a similar angle.
    let at = |x: usize, y: usize| img.pixels[y * 33 + x].x;
    let (shadowed, lit) = (at(8, 16), at(25, 16));
    assert!(lit > 0.1, "lit floor {lit}");
    assert!(
        shadowed < 0.05 * lit,
        "shadowed floor {shadowed} vs lit {lit}"
    );
}

#[test]
fn renders_are_deterministic() {
    let s = Scene::builtin_default();
    let tree = KdTree::build(&s.mesh, Builder::Sah);
    let opt = RenderOptions {
        width: 40,
        height: 30,
        spp: 2,
        max_depth: 3,
        traversal: Traversal::Ropes,
    };
    let a = render(&s, &tree, &opt, |_| {});
    let b = render(&s, &tree, &opt, |_| {});
    assert_eq!(a, b);
    let stack = render(
        &s,
        &tree,
        &RenderOptions {
            traversal: Traversal::Stack,
            ..opt
        },
        |_| {},
    );
    assert_eq!(a, stack, "both traversals give the same image");
    assert!(a.pixels.iter().all(|p| p.is_finite()));
}

#[test]
fn srgb_encoding() {
    let img = Image {
        width: 3,
        height: 1,
        pixels: vec![Vec3::ZERO, Vec3::splat(0.5), Vec3::splat(2.0)],
    };
    assert_eq!(img.to_srgb8(), vec![0, 0, 0, 188, 188, 188, 255, 255, 255]);
}

/// `--aov`: a square seen head-on (some pixels miss it). Every pixel against the brute-force
/// closest hit of its ray: misses black; depth the distance's grey level (the nearest hit
/// white, the farthest 1, within a level); the normal facing the eye (0, 0, 1) → (128, 128,
/// 255); each triangle its own colour.
#[test]
fn aovs_follow_the_brute_force_hits() {
    let s = scene(
        r#"
        [camera]
        eye = [0, 0, 0]
        target = [0, 0, -1]
        fov = 90
        [[objects]]
        shape = "quad"
        rotate = [90, 0, 0]
        translate = [0.3, 0, -2]
        "#,
    );
    let (w, h) = (24u32, 16u32);
    let tree = KdTree::build(&s.mesh, Builder::Sah);
    let corners: Vec<[Vec3; 3]> = (0..s.mesh.len()).map(|i| s.mesh.corners(i)).collect();
    let rays = aov_rays(&s.camera_for(w as f32 / h as f32), w, h);
    let hits = tree.intersect_all(&rays, Traversal::Ropes, false);
    let want: Vec<Option<Hit>> = rays
        .iter()
        .map(|r| raystream_accel::brute::closest(&corners, r))
        .collect();
    let hit_count = want.iter().flatten().count();
    assert!(
        hit_count > 0 && hit_count < rays.len(),
        "{hit_count} of {} pixels hit: the test needs both",
        rays.len()
    );
    let prims: std::collections::BTreeSet<u32> = want.iter().flatten().map(|h| h.prim).collect();
    assert_eq!(prims.len(), 2, "both triangles of the square in view");
    let dist: Vec<Option<f32>> = rays
        .iter()
        .zip(&want)
        .map(|(r, h)| h.map(|h| h.t * r.dir.length()))
        .collect();
    let near = dist.iter().flatten().fold(f32::INFINITY, |a, &b| a.min(b));
    let far = dist.iter().flatten().fold(0.0f32, |a, &b| a.max(b));

    let depth = aov_image(&s, &rays, &hits, w, h, Aov::Depth);
    let (n, f) = depth.depth_range().expect("hits");
    assert!(
        (n - near).abs() < 1e-5 && (f - far).abs() < 1e-5,
        "range {n}..{f}"
    );
    let AovValues::Depth(values) = &depth.values else {
        panic!("a depth AOV holds distances")
    };
    let pixels = depth.gray16().expect("depth is 16-bit grey");
    for (i, d) in dist.iter().enumerate() {
        let want_level = d.map_or(0.0, |d| 1.0 + 65534.0 * (far - d) / (far - near));
        assert!(
            (pixels[i] as f32 - want_level).abs() <= 1.0,
            "depth pixel {i}: {} vs {want_level}",
            pixels[i]
        );
        match d {
            Some(d) => assert!((values[i] - d).abs() <= 1e-5 * d, "distance {i}"),
            None => assert_eq!(values[i], f32::INFINITY, "a miss's distance"),
        }
    }
    assert!(pixels.contains(&u16::MAX) && pixels.contains(&1));

    for aov in [Aov::Normal, Aov::Prim] {
        let img = aov_image(&s, &rays, &hits, w, h, aov);
        let pixels = img.rgb8().expect("RGB");
        for (i, hit) in want.iter().enumerate() {
            let rgb = &pixels[3 * i..3 * i + 3];
            let expect = match (hit, aov) {
                (None, _) => [0, 0, 0],
                (Some(_), Aov::Normal) => [128, 128, 255],
                (Some(h), _) => prim_colour(h.prim),
            };
            assert_eq!(rgb, expect, "{aov:?} pixel {i}");
            match (&img.values, hit) {
                (AovValues::Normal(n), None) => assert_eq!(n[i], Vec3::ZERO),
                (AovValues::Normal(n), Some(_)) => {
                    assert!((n[i] - Vec3::Z).length() < 1e-6, "normal {i}: {}", n[i])
                }
                (AovValues::Prim(p), h) => assert_eq!(p[i], h.map_or(NO_PRIM, |h| h.prim)),
                (v, _) => panic!("{aov:?} holds {v:?}"),
            }
        }
    }
    // Neighbouring triangles get different colours, never a miss's black.
    let colours: Vec<[u8; 3]> = (0..1000).map(prim_colour).collect();
    assert!(colours.windows(2).all(|c| c[0] != c[1]));
    assert!(colours.iter().all(|c| c.iter().all(|&v| v >= 32)));
}

/// An AOV made chunk by chunk (as `render --aov` makes it) equals the one made at once.
#[test]
fn aovs_in_chunks_equal_aovs_at_once() {
    let s = scene("[[objects]]\nshape = \"spot\"\n[ground]\n");
    let (w, h) = (19u32, 13u32);
    let tree = KdTree::build(&s.mesh, Builder::Sah);
    let cam = s.camera_for(w as f32 / h as f32);
    let rays = aov_rays(&cam, w, h);
    let hits = tree.intersect_all(&rays, Traversal::Ropes, false);
    for aov in [Aov::Depth, Aov::Normal, Aov::Prim] {
        let whole = aov_image(&s, &rays, &hits, w, h, aov);
        let mut b = AovBuilder::new(&s, aov, w, h);
        for first in (0..w * h).step_by(7) {
            let part = aov_rays_of(&cam, w, h, first..(first + 7).min(w * h));
            let part_hits = tree.intersect_all(&part, Traversal::Ropes, false);
            b.add(&part, &part_hits);
        }
        assert_eq!(b.finish(), whole, "{aov:?}");
    }
}

/// A 16-bit depth image survives the PNG round trip.
#[test]
fn depth_aov_png_round_trip() {
    let img = AovImage {
        width: 4,
        height: 1,
        values: AovValues::Depth(vec![f32::INFINITY, 2.0, 1.0, 1.5]),
    };
    let dir = scratch();
    let path = dir.path().join("aov.png");
    img.save_png(&path).unwrap();
    let back = image::open(&path).unwrap().to_luma16();
    assert_eq!(back.into_raw(), vec![0, 1, 65535, 32768]);
}

/// Every channel of an EXR file: name → samples.
fn read_exr(path: &Path) -> std::collections::BTreeMap<String, ExrSamples> {
    load_exr(path).unwrap().channels
}

/// EXR keeps the values themselves: the film's linear RGB above 1 and below the 8-bit step,
/// distances with +∞ for a miss, normals, triangle numbers as 32-bit integers.
#[test]
fn exr_round_trip_keeps_the_values() {
    let scratch = scratch();
    let dir = scratch.path();
    let film = Image {
        width: 3,
        height: 2,
        pixels: vec![
            Vec3::new(0.0, 1e-4, 7.25),
            Vec3::new(0.5, 0.25, 0.125),
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::splat(-0.0),
            Vec3::new(12345.678, 1e-30, 0.333),
            Vec3::ONE,
        ],
    };
    let path = dir.join("film.exr");
    film.save(&path, ImageFormat::Exr, "test film").unwrap();
    let ch = read_exr(&path);
    assert_eq!(ch.keys().collect::<Vec<_>>(), ["B", "G", "R"]);
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        let want: Vec<f32> = film.pixels.iter().map(|p| p.to_array()[c]).collect();
        assert_eq!(ch[*name], ExrSamples::F32(want), "{name}");
    }

    let depth = AovImage {
        width: 2,
        height: 2,
        values: AovValues::Depth(vec![f32::INFINITY, 1.5, 1e7, 3.25e-3]),
    };
    let path = dir.join("depth.exr");
    depth.save(&path, ImageFormat::Exr, "mm").unwrap();
    let ch = read_exr(&path);
    assert_eq!(ch.len(), 1);
    assert_eq!(
        ch["Z"],
        ExrSamples::F32(vec![f32::INFINITY, 1.5, 1e7, 3.25e-3])
    );

    let normals = vec![Vec3::ZERO, Vec3::X, Vec3::new(0.6, -0.8, 0.0), -Vec3::Z];
    let img = AovImage {
        width: 4,
        height: 1,
        values: AovValues::Normal(normals.clone()),
    };
    img.save(&path, ImageFormat::Exr, "mm").unwrap();
    let ch = read_exr(&path);
    assert_eq!(ch.len(), 3);
    for (c, name) in ["N.X", "N.Y", "N.Z"].iter().enumerate() {
        let want: Vec<f32> = normals.iter().map(|p| p.to_array()[c]).collect();
        assert_eq!(ch[*name], ExrSamples::F32(want), "{name}");
    }

    let prims = vec![NO_PRIM, 0, 16_777_217, 4_000_000_000];
    let img = AovImage {
        width: 2,
        height: 2,
        values: AovValues::Prim(prims.clone()),
    };
    img.save(&path, ImageFormat::Exr, "mm").unwrap();
    let ch = read_exr(&path);
    assert_eq!(ch.len(), 1);
    assert_eq!(
        ch["prim"],
        ExrSamples::U32(prims),
        "exact above 2^24, as no float is"
    );
}

/// A scratch folder of its own, removed when the test ends, passed or failed.
fn scratch() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("raystream-cpu-")
        .tempdir()
        .unwrap()
}

/// The format follows the output's extension; any other is refused by name.
#[test]
fn image_format_from_the_extension() {
    assert_eq!(ImageFormat::of(Path::new("a/b.png")), Ok(ImageFormat::Png));
    assert_eq!(ImageFormat::of(Path::new("b.EXR")), Ok(ImageFormat::Exr));
    for bad in ["b.jpg", "b", "b.png.tmp", "dir/"] {
        let e = ImageFormat::of(Path::new(bad)).unwrap_err();
        assert!(
            e.starts_with(bad.trim_end_matches('/')) && e.contains(".exr"),
            "{e}"
        );
    }
}

/// Waves of any size give the same image byte for byte, and the same rays per depth: glass
/// (reflection and refraction), a mirror, shadows, and the CT volume among meshes.
#[test]
fn waves_do_not_change_the_image() {
    let ct = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    let glass = scene(
        r#"
        [[lights]]
        position = [3, 5, 4]
        [materials.glass]
        transparency = 0.8
        reflectivity = 0.1
        [materials.mirror]
        reflectivity = 0.6
        [[objects]]
        shape = "sphere"
        material = "glass"
        [[objects]]
        shape = "spot"
        material = "mirror"
        translate = [1.5, 0, 0]
        [ground]
        "#,
    );
    let with_volume = scene(&format!(
        r#"
        [volume]
        path = "{}"
        preset = "ct-bones"
        [materials.mirror]
        reflectivity = 0.5
        [[objects]]
        shape = "cylinder"
        material = "mirror"
        scale = [4, 70, 4]
        translate = [0, 235, 140]
        [ground]
        material = "mirror"
        "#,
        ct.display()
    ));
    for (what, s, spp) in [("glass", &glass, 3), ("volume", &with_volume, 2)] {
        let tree = KdTree::build(&s.mesh, Builder::Sah);
        let medium = prepare_volume(s, &tree, Traversal::Ropes);
        let opt = RenderOptions {
            width: 24,
            height: 16,
            spp,
            max_depth: 3,
            traversal: Traversal::Ropes,
        };
        // One set of queues for every frame, as a turntable keeps them: what a frame leaves
        // in them, in waves of another size, must not reach the next.
        let mut queues = RenderQueues::default();
        let mut frame = |wave: u32| {
            let mut rays = vec![0usize; 4];
            let queues = &mut queues;
            let img = render_in_waves(s, &tree, medium.as_ref(), &opt, wave, queues, |d| {
                rays[d.depth as usize] += d.rays
            });
            (img.pixels, rays)
        };
        let whole = frame(24 * 16);
        assert!(whole.1[1] > 0, "{what}: secondary rays");
        for wave in [1, 7, 100] {
            let waved = frame(wave);
            assert!(
                whole.0 == waved.0,
                "{what}: waves of {wave} pixels change the image"
            );
            assert_eq!(whole.1, waved.1, "{what}: waves of {wave} pixels");
        }
    }
    let big = RenderOptions {
        width: 1920,
        height: 1080,
        spp: 256,
        ..RenderOptions::default()
    };
    assert_eq!(wave_pixels(&big), 1024);
    assert_eq!(waves(&big), 2025);
}

/// The cow and a small sphere, lit by two lights, with `extra` objects added.
fn cow_scene(extra: &str) -> Scene {
    scene(&format!(
        r#"
        background = [0, 0, 0]
        [camera]
        eye = [0.5, 1.2, 3.0]
        target = [0, 0.4, 0]
        fov = 35
        [[lights]]
        position = [3, 5, 4]
        [[lights]]
        position = [-4, 2, 1]
        color = [0.3, 0.3, 0.4]
        [materials.shiny]
        diffuse = [0.7, 0.5, 0.4]
        reflectivity = 0.3
        [materials.black]
        ambient = [0, 0, 0]
        diffuse = [0, 0, 0]
        specular = [0, 0, 0]
        [[objects]]
        shape = "spot"
        material = "shiny"
        [[objects]]
        shape = "sphere"
        scale = 0.3
        translate = [0.9, 0.3, 0.2]
        material = "shiny"
        {extra}
        "#
    ))
}

/// Secondary rays leave each object by its own offset: a black quad 10⁹ units wide, far
/// below the cow where it gives what the black background gives, leaves the cow's picture as
/// it was. (With one offset for the whole scene, 10⁻⁴ of its radius, the cow's shadow and
/// reflection rays started 10⁵ units off it: a mean difference of 27/255.)
#[test]
fn a_small_object_beside_a_huge_one_is_shaded_as_if_alone() {
    let alone = cow_scene("");
    let beside = cow_scene(
        r#"
        [[objects]]
        shape = "quad"
        scale = 1e9
        translate = [0, -1e8, 0]
        material = "black"
        "#,
    );
    let n = alone.mesh.positions.len();
    assert_eq!(alone.ray_offsets, beside.ray_offsets[..n]);
    assert!(beside.ray_offsets[n] > 1e3 * alone.ray_offsets[0]);
    let (a, b) = (
        render_scene(&alone, 48, 36, 3),
        render_scene(&beside, 48, 36, 3),
    );
    let lit = a.pixels.iter().filter(|p| p.max_element() > 0.05).count();
    assert!(lit > 300, "{lit} lit pixels");
    let off = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(p, q)| (**p - **q).abs().max_element() > 1e-3)
        .count();
    assert!(off <= 2, "{off} pixels differ");
}

/// A camera 10⁵ radii from a sphere, with the light beside it: every lit point faces the light
/// and the sphere is convex, so no shadow ray may hit the sphere. The hit point origin + t·dir
/// is good only to 10⁵ ulps there, more than the sphere's offset; moved onto its triangle's
/// plane it is good to the triangle's rounding.
#[test]
fn a_far_camera_does_not_let_a_surface_shadow_itself() {
    let s = scene(
        r#"
        [camera]
        eye = [0, 0, 1e5]
        target = [0, 0, 0]
        fov = 0.0015
        [[lights]]
        position = [0, 0, 1e5]
        [[objects]]
        shape = "sphere"
        "#,
    );
    let tree = KdTree::build(&s.mesh, Builder::Sah);
    let cam = s.camera_for(1.0);
    let rays = generate_camera_rays(&cam, 64, 64, 1);
    let (hits, _) = intersect_closest(&tree, &rays, Traversal::Ropes);
    assert!(hits.len() > 1500, "{} hits", hits.len());
    let (_, shadows, _) = shade_hits(&s, &hits, false);
    assert!(shadows.len() > 1500, "{} shadow rays", shadows.len());
    let lit = intersect_any(&tree, &shadows, Traversal::Ropes, None);
    assert_eq!(
        lit.len(),
        shadows.len(),
        "shadow rays hit the sphere itself"
    );
}

/// `--denoise` on real CT: a cinematic frame of the abdomen at 8 paths a pixel (192×144),
/// denoised along its guides, is closer to the same frame at 256 paths than the raw frame, by
/// a root-mean-square error under 0.7× the raw one's (measured 0.48× with ct-bones, 0.39× with
/// ct-muscle), and closer than a plain 5×5 box blur of it (which smears edges); it keeps the
/// frame's light (within 2 %), and the pixels' reported variances match the raw frame's actual
/// error (within 20 %; measured 0.92–0.96).
#[test]
fn denoised_cinematic_frames_approach_the_converged_one() {
    use crate::cinematic::{guides, luminance, render_film};
    use crate::denoise::{DenoiseOptions, denoise};
    use crate::dvr::{DvrMode, DvrOptions, volume_camera};
    let ct = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    let vol = raystream_io::load_volume(&ct, &Default::default()).unwrap();
    let (w, h) = (192u32, 144u32);
    let cam = volume_camera(&vol, w as f32 / h as f32);
    for preset in [
        raystream_volume::TfPreset::CtBones,
        raystream_volume::TfPreset::CtMuscle,
    ] {
        let tf = preset.function();
        let opt = |spp| DvrOptions {
            width: w,
            height: h,
            mode: DvrMode::Cinematic,
            spp,
            bounces: 3,
            ..Default::default()
        };
        let (noisy, _) = render_film(&vol, &tf, &opt(8), &cam);
        let (truth, _) = render_film(&vol, &tf, &opt(256), &cam);
        let g = guides(&vol, &tf, &opt(8), &cam);
        let (clean, alpha) = denoise(&noisy, &g, &DenoiseOptions::default());
        let rms = |img: &[Vec3]| {
            let s: f64 = img
                .iter()
                .zip(&truth.film.pixels)
                .map(|(a, b)| (*a - *b).length_squared() as f64)
                .sum();
            (s / img.len() as f64).sqrt()
        };
        let boxed: Vec<Vec3> = (0..(w * h) as i32)
            .map(|p| {
                let (x, y) = (p % w as i32, p / w as i32);
                let (mut s, mut k) = (Vec3::ZERO, 0.0);
                for qy in (y - 2).max(0)..(y + 3).min(h as i32) {
                    for qx in (x - 2).max(0)..(x + 3).min(w as i32) {
                        s += noisy.film.pixels[(qx + qy * w as i32) as usize];
                        k += 1.0;
                    }
                }
                s / k
            })
            .collect();
        let (raw, denoised, blurred) = (rms(&noisy.film.pixels), rms(&clean.pixels), rms(&boxed));
        let total = |img: &[Vec3]| img.iter().map(|c| c.element_sum() as f64).sum::<f64>();
        let kept = total(&clean.pixels) / total(&truth.film.pixels);
        // The raw frame's squared luminance error against the reported variances (the
        // reference's own, 128× smaller, apart).
        let err2: f64 = noisy
            .film
            .pixels
            .iter()
            .zip(&truth.film.pixels)
            .map(|(a, b)| ((luminance(*a) - luminance(*b)) as f64).powi(2))
            .sum();
        let var: f64 = noisy.variance.iter().map(|&v| v as f64).sum();
        eprintln!(
            "{}: rms raw {raw:.4}, denoised {denoised:.4}, 5x5 box {blurred:.4}; light kept {kept:.4}; squared error / variance {:.3}",
            preset.name(),
            err2 / var
        );
        assert!(
            denoised < 0.7 * raw,
            "{}: {raw} → {denoised}",
            preset.name()
        );
        assert!(denoised < blurred, "{}: box blur {blurred}", preset.name());
        assert!((kept - 1.0).abs() < 0.02, "{}: light {kept}", preset.name());
        assert!((0.8..1.25).contains(&(err2 / var)), "{}", preset.name());
        assert!(alpha.iter().all(|a| (-1e-6..=1.0 + 1e-6).contains(a)));
    }
}
