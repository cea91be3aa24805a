use std::path::Path;

use raystream_accel::layout::{KdInner, KdLeaf, KdTri};
use raystream_accel::{Builder, KdTree, Traversal};
use raystream_io::TriMesh;
use raystream_math::{Ray, Vec3};

use super::*;

/// Parses and validates a WGSL source with naga.
fn naga_module(src: &str, what: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("{what}: {e}"));
    let mut validator = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    );
    validator
        .validate(&module)
        .unwrap_or_else(|e| panic!("{what} does not validate: {e:?}"));
    module
}

#[test]
fn stats_wgsl_validates() {
    naga_module(&stats_wgsl(), "stats.wgsl");
    naga_module(&queries_wgsl(), "queries.wgsl");
}

#[test]
fn film_wgsl_validates() {
    naga_module(&render::film_wgsl(), "film.wgsl");
}

/// Every kernel module wgpu compiles, by name.
fn all_kernel_modules() -> Vec<(&'static str, String)> {
    vec![
        ("queries.wgsl", queries_wgsl()),
        ("stats.wgsl", stats_wgsl()),
        ("split.wgsl", split_wgsl(false)),
        ("split.wgsl, subgroup appends", split_wgsl(true)),
        ("render.wgsl", render_wgsl(false)),
        ("render.wgsl, subgroup appends", render_wgsl(true)),
        ("film.wgsl", render::film_wgsl()),
        ("dvr.wgsl", volume::dvr_wgsl()),
    ]
}

/// The kd-tree kernels as a context with f64 compiles them (`GpuContext::f64_planes`): the f32
/// `plane_t_wide` replaced by plane_f64.wgsl's, once, in every module that traces; each
/// validates with f64 and needs it.
#[test]
fn f64_plane_kernels_validate() {
    let mut modules = 0;
    for (what, src) in all_kernel_modules() {
        if !src.contains("fn plane_t_wide(") {
            continue;
        }
        modules += 1;
        let wide = with_f64_planes(&src);
        assert_eq!(wide.matches("fn plane_t_wide(").count(), 1, "{what}");
        assert!(wide.contains("let xd = vec3<f64>(x);"), "{what}");
        naga_module(&wide, what);
        let module = naga::front::wgsl::parse_str(&wide).unwrap();
        let without = naga::valid::Capabilities::all() - naga::valid::Capabilities::FLOAT64;
        let checked = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), without)
            .validate(&module);
        assert!(checked.is_err(), "{what} validates without f64");
    }
    assert_eq!(modules, 6);
}

/// The kernels run on Vulkan here (SPIR-V), but raystream claims Metal and DX12 too: each
/// entry point of every module goes through the same translation wgpu's Metal and DX12
/// back-ends make (naga to MSL 2.4, to HLSL shader model 6.0), validated against only the
/// capabilities those writers support. What the Metal and DXC compilers make of the text is
/// not checked here (no such machine); a construct naga cannot express there is.
#[test]
fn kernels_translate_for_metal_and_dx12() {
    use naga::back::{hlsl, msl, pipeline_constants::process_overrides};
    use naga::valid::{ValidationFlags, Validator};
    let mut entry_points = 0;
    for (what, src) in all_kernel_modules() {
        let module = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{what}: {e}"));
        for (target, caps) in [
            ("MSL", msl::supported_capabilities()),
            ("HLSL", hlsl::supported_capabilities()),
        ] {
            let info = Validator::new(ValidationFlags::all(), caps)
                .validate(&module)
                .unwrap_or_else(|e| panic!("{what} needs more than {target} offers: {e:?}"));
            for ep in &module.entry_points {
                let (m, i) = process_overrides(
                    &module,
                    &info,
                    Some((ep.stage, &ep.name)),
                    &Default::default(),
                )
                .unwrap_or_else(|e| panic!("{what}::{}: overrides: {e:?}", ep.name));
                let entry_point = Some((ep.stage, ep.name.clone()));
                let text = if target == "MSL" {
                    let options = msl::Options {
                        lang_version: (2, 4),
                        ..Default::default()
                    };
                    let pipeline = msl::PipelineOptions {
                        entry_point,
                        ..Default::default()
                    };
                    msl::write_string(&m, &i, &options, &pipeline)
                        .map(|(text, _)| text)
                        .map_err(|e| format!("{e:?}"))
                } else {
                    let options = hlsl::Options {
                        shader_model: hlsl::ShaderModel::V6_0,
                        // where wgpu's DX12 back-end passes num_workgroups
                        special_constants_binding: Some(hlsl::BindTarget {
                            space: 255,
                            ..Default::default()
                        }),
                        ..Default::default()
                    };
                    let pipeline = hlsl::PipelineOptions { entry_point };
                    let mut text = String::new();
                    hlsl::Writer::new(&mut text, &options, &pipeline)
                        .write(&m, &i, None)
                        .map(|_| text)
                        .map_err(|e| format!("{e:?}"))
                };
                let text = text.unwrap_or_else(|e| {
                    panic!("{what}::{} does not translate to {target}: {e}", ep.name)
                });
                assert!(
                    text.contains(&ep.name),
                    "{what}::{}: the {target} text lacks its entry point",
                    ep.name
                );
                entry_points += 1;
            }
        }
    }
    // queries 8, stats 2, split 4+, render 6+, film 2+, dvr 1+: each for both targets
    eprintln!("{entry_points}");
    assert!(entry_points >= 2 * 20, "only {entry_points} translations");
}

/// Checks a WGSL struct's size and member offsets, from naga's own layout.
fn check_struct(module: &naga::Module, name: &str, size: usize, offsets: &[(&str, usize)]) {
    let ty = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("WGSL struct {name} missing"))
        .1;
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        panic!("{name} is not a struct")
    };
    assert_eq!(*span as usize, size, "size of {name}");
    assert_eq!(members.len(), offsets.len(), "member count of {name}");
    for (m, (field, off)) in members.iter().zip(offsets) {
        assert_eq!(m.name.as_deref(), Some(*field), "{name}: member order");
        assert_eq!(m.offset as usize, *off, "{name}.{field} offset");
    }
}

/// Offsets and sizes of every WGSL struct of the ray-query kernels shared with Rust.
#[test]
fn wgsl_structs_match_rust() {
    let module = naga_module(&queries_wgsl(), "queries.wgsl");
    naga_module(&split_wgsl(false), "split.wgsl");
    let check = |name: &str, size: usize, offsets: &[(&str, usize)]| {
        check_struct(&module, name, size, offsets)
    };
    use std::mem::{offset_of, size_of};
    check(
        "KdInner",
        size_of::<KdInner>(),
        &[
            ("split", offset_of!(KdInner, split)),
            ("axis", offset_of!(KdInner, axis)),
            ("left", offset_of!(KdInner, left)),
            ("right", offset_of!(KdInner, right)),
        ],
    );
    check(
        "KdLeaf",
        size_of::<KdLeaf>(),
        &[
            ("bmin", offset_of!(KdLeaf, min)),
            ("first", offset_of!(KdLeaf, first)),
            ("bmax", offset_of!(KdLeaf, max)),
            ("count", offset_of!(KdLeaf, count)),
            ("ropes", offset_of!(KdLeaf, ropes)),
            ("pad", offset_of!(KdLeaf, pad)),
        ],
    );
    check(
        "KdTri",
        size_of::<KdTri>(),
        &[("axes", offset_of!(KdTri, axes))],
    );
    check(
        "RayIn",
        size_of::<GpuRay>(),
        &[
            ("origin", offset_of!(GpuRay, origin)),
            ("t_min", offset_of!(GpuRay, t_min)),
            ("dir", offset_of!(GpuRay, dir)),
            ("t_max", offset_of!(GpuRay, t_max)),
        ],
    );
    check(
        "HitOut",
        size_of::<GpuHit>(),
        &[
            ("t", offset_of!(GpuHit, t)),
            ("prim", offset_of!(GpuHit, prim)),
            ("u", offset_of!(GpuHit, u)),
            ("v", offset_of!(GpuHit, v)),
        ],
    );
    check(
        "Params",
        size_of::<Params>(),
        &[
            ("ray_count", offset_of!(Params, ray_count)),
            ("root", offset_of!(Params, root)),
            ("max_steps", offset_of!(Params, max_steps)),
            ("tri_count", offset_of!(Params, tri_count)),
            ("scene_min", offset_of!(Params, scene_min)),
            ("entry_margin", offset_of!(Params, entry_margin)),
            ("scene_max", offset_of!(Params, scene_max)),
            ("entry_reach", offset_of!(Params, entry_reach)),
            ("entry_scale", offset_of!(Params, entry_scale)),
            ("entry_res", offset_of!(Params, entry_res)),
        ],
    );
}

/// Offsets and sizes of the render kernels' structs shared with Rust.
#[test]
fn render_wgsl_structs_match_rust() {
    use layout::*;
    use std::mem::{offset_of, size_of};
    let module = naga_module(&render_wgsl(false), "render.wgsl");
    let check = |name: &str, size: usize, offsets: &[(&str, usize)]| {
        check_struct(&module, name, size, offsets)
    };
    check(
        "RayWork",
        size_of::<RayWork>(),
        &[
            ("ray", offset_of!(RayWork, ray)),
            ("weight", offset_of!(RayWork, weight)),
            ("pixel", offset_of!(RayWork, pixel)),
        ],
    );
    check(
        "ShadowWork",
        size_of::<ShadowWork>(),
        &[
            ("ray", offset_of!(ShadowWork, ray)),
            ("radiance", offset_of!(ShadowWork, radiance)),
            ("pixel", offset_of!(ShadowWork, pixel)),
        ],
    );
    check(
        "Vertex",
        size_of::<Vertex>(),
        &[
            ("position", offset_of!(Vertex, position)),
            ("normal", offset_of!(Vertex, normal)),
        ],
    );
    check(
        "ShadeTri",
        size_of::<ShadeTri>(),
        &[
            ("v", offset_of!(ShadeTri, v)),
            ("material", offset_of!(ShadeTri, material)),
        ],
    );
    let pad = offset_of!(GpuMaterial, pad);
    check(
        "Material",
        size_of::<GpuMaterial>(),
        &[
            ("ambient", offset_of!(GpuMaterial, ambient)),
            ("reflectivity", offset_of!(GpuMaterial, reflectivity)),
            ("diffuse", offset_of!(GpuMaterial, diffuse)),
            ("transparency", offset_of!(GpuMaterial, transparency)),
            ("specular", offset_of!(GpuMaterial, specular)),
            ("shininess", offset_of!(GpuMaterial, shininess)),
            ("ior", offset_of!(GpuMaterial, ior)),
            ("fresnel", offset_of!(GpuMaterial, fresnel)),
            ("texture", offset_of!(GpuMaterial, texture)),
            ("pad", pad),
        ],
    );
    check(
        "TriCorners",
        size_of::<TriCorners>(),
        &[
            ("a", offset_of!(TriCorners, a)),
            ("b", offset_of!(TriCorners, b)),
            ("c", offset_of!(TriCorners, c)),
            ("colour_a", offset_of!(TriCorners, colour_a)),
            ("colour_b", offset_of!(TriCorners, colour_b)),
            ("colour_c", offset_of!(TriCorners, colour_c)),
            ("pad", offset_of!(TriCorners, pad)),
        ],
    );
    check(
        "Light",
        size_of::<GpuLight>(),
        &[
            ("position", offset_of!(GpuLight, position)),
            ("color", offset_of!(GpuLight, color)),
        ],
    );
    check(
        "MediumParams",
        size_of::<MediumParams>(),
        &[
            ("to_index0", offset_of!(MediumParams, to_index0)),
            ("step", offset_of!(MediumParams, step)),
            ("to_index1", offset_of!(MediumParams, to_index1)),
            ("light_count", offset_of!(MediumParams, light_count)),
            ("to_index2", offset_of!(MediumParams, to_index2)),
            ("skip_empty", offset_of!(MediumParams, skip_empty)),
            ("origin", offset_of!(MediumParams, origin)),
            ("opacity_count", offset_of!(MediumParams, opacity_count)),
            ("dims", offset_of!(MediumParams, dims)),
            ("color_count", offset_of!(MediumParams, color_count)),
            ("bricks", offset_of!(MediumParams, bricks)),
            ("shadows", offset_of!(MediumParams, shadows)),
            ("shading", offset_of!(MediumParams, shading)),
            ("light_dims", offset_of!(MediumParams, light_dims)),
            ("grid_points", offset_of!(MediumParams, grid_points)),
            ("interpolation", offset_of!(MediumParams, interpolation)),
            ("segments", offset_of!(MediumParams, segments)),
            ("pad1", offset_of!(MediumParams, pad1)),
            ("pad2", offset_of!(MediumParams, pad2)),
        ],
    );
    let pad = offset_of!(RenderParams, pad);
    check(
        "RenderParams",
        size_of::<RenderParams>(),
        &[
            ("eye", offset_of!(RenderParams, eye)),
            ("tan_y", offset_of!(RenderParams, tan_y)),
            ("fwd", offset_of!(RenderParams, fwd)),
            ("width", offset_of!(RenderParams, width)),
            ("right", offset_of!(RenderParams, right)),
            ("height", offset_of!(RenderParams, height)),
            ("up", offset_of!(RenderParams, up)),
            ("spp", offset_of!(RenderParams, spp)),
            ("background", offset_of!(RenderParams, background)),
            ("strata", offset_of!(RenderParams, strata)),
            ("ambient_light", offset_of!(RenderParams, ambient_light)),
            ("parallel", offset_of!(RenderParams, parallel)),
            ("sample_base", offset_of!(RenderParams, sample_base)),
            ("sample_count", offset_of!(RenderParams, sample_count)),
            ("max_depth", offset_of!(RenderParams, max_depth)),
            ("light_count", offset_of!(RenderParams, light_count)),
            ("max_groups", offset_of!(RenderParams, max_groups)),
            ("band", offset_of!(RenderParams, band)),
            ("coloured", offset_of!(RenderParams, coloured)),
            ("pad", pad),
        ],
    );
}

/// The camera rays' bands: one subgroup's pixels (its lanes over the samples a pixel) form a
/// block about as tall as wide: h² ≤ pixels < 4h², h a power of two; row by row (h = 1) once a
/// subgroup holds fewer than 4 pixels.
#[test]
fn pixel_bands_make_square_blocks() {
    use crate::layout::band_rows;
    assert_eq!(band_rows(32, 1), 4); // 8 × 4 pixels
    assert_eq!(band_rows(32, 4), 2); // 4 × 2
    assert_eq!(band_rows(64, 1), 8);
    assert_eq!(band_rows(32, 16), 1);
    assert_eq!(band_rows(32, 64), 1);
    for lanes in [1, 4, 8, 16, 32, 64, 128] {
        for spp in [0, 1, 2, 3, 4, 5, 9, 16, 100] {
            let h = band_rows(lanes, spp);
            let pixels = (lanes / spp.max(1)).max(1);
            assert!(h.is_power_of_two(), "{lanes} lanes, {spp} spp: {h}");
            assert!(h * h <= pixels && pixels < 4 * h * h, "{lanes}, {spp}: {h}");
        }
    }
}

/// Every kernel layout that traces (all but the floor).
const LAYOUTS: [Kernels; 4] = [
    Kernels::Fused,
    Kernels::Split,
    Kernels::Persistent,
    Kernels::IfIf,
];

/// Whether the tests run under CI (`CI=true`), where skipping is a failure.
fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// The GPU, or `None` (skip) where there is none — except under CI, where GPU tests must run.
fn gpu() -> Option<GpuContext> {
    match GpuContext::new(None) {
        Ok(ctx) => Some(ctx),
        Err(e) if in_ci() => panic!(
            "CI=true but no GPU adapter: {e} (install lavapipe: ../shared/tools/install-lavapipe.sh)"
        ),
        Err(e) => {
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

/// A mesh of `../shared/data/meshes`.
fn shared_mesh(name: &str) -> TriMesh {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/meshes");
    raystream_io::load_mesh(&dir.join(name)).unwrap()
}

/// A tree larger than what one buffer binding of the device holds is refused before any
/// upload, with the buffer, both sizes and the way out named (here a device whose bindings
/// are cut to 1 MiB: the bunny's inner nodes, the first buffer, take 1.3 MB).
#[test]
fn a_tree_too_large_for_a_binding_is_a_clear_error() {
    let Some(mut ctx) = gpu() else { return };
    ctx.limits.max_storage_buffer_binding_size = 1 << 20;
    let tree = KdTree::build(&shared_mesh("stanford_bunny.ply"), Builder::Sah);
    let e = GpuTracer::new(&ctx, &tree)
        .err()
        .expect("too large")
        .to_string();
    let need = std::mem::size_of_val(tree.inners.as_slice());
    assert!(
        e.contains(&format!("kd inner nodes needs {need} bytes"))
            && e.contains("allows 1048576")
            && e.contains("--device cpu"),
        "{e}"
    );
}

/// The kd-tree kernels compile without wgpu's checks by default, so a tree or a scene whose
/// links would lead them out of their arrays is refused before anything is uploaded, saying
/// which link; the scene loaders' scenes and built trees pass.
#[test]
fn broken_trees_and_scenes_are_refused_before_upload() {
    let Some(ctx) = gpu() else { return };
    assert!(
        ctx.unchecked,
        "the kd-tree kernels are unchecked by default"
    );
    let scene = raystream_scene::Scene::builtin_default();
    let tree = KdTree::build(&scene.mesh, Builder::Sah);
    let mut bad = tree.clone();
    let mid = bad.inners.len() / 2;
    bad.inners[mid].axis = 3;
    let e = GpuTracer::new(&ctx, &bad)
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("the kd-tree's links are broken") && e.contains("axis 3"),
        "{e}"
    );
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    // A 2 × 2 texture on the first material, with or without texture coordinates.
    let texture = |s: &mut raystream_scene::Scene, texels: usize, uvs: bool| {
        s.textures.push(raystream_io::Texture {
            width: 2,
            height: 2,
            texels: vec![[255; 4]; texels],
            mapping: Default::default(),
        });
        s.materials[0].texture = Some(0);
        if uvs {
            s.uvs = vec![[raystream_math::Vec2::ZERO; 3]; s.mesh.triangles.len()];
        }
    };
    let mut s = scene.clone();
    texture(&mut s, 4, true);
    GpuRenderer::new(&tracer, &s, &tree).unwrap();
    type Break = Box<dyn Fn(&mut raystream_scene::Scene)>;
    let breaks: Vec<(Break, &str)> = vec![
        (Box::new(|s| s.normals.truncate(1)), "normals"),
        (
            Box::new(|s| s.mesh.triangles[3][1] = 1 << 30),
            "triangle 3: a vertex",
        ),
        (
            Box::new(|s| s.material_of[5] = 99),
            "triangle 5: a material",
        ),
        (Box::new(|s| s.material_of.truncate(1)), "material indices"),
        // The tree's primitives beyond the scene's triangles.
        (
            Box::new(|s| {
                s.mesh.triangles.truncate(1);
                s.material_of.truncate(1);
            }),
            "primitive ids go up to",
        ),
        (Box::new(|s| s.materials[0].texture = Some(7)), "texture 7"),
        (
            Box::new(move |s| texture(s, 4, false)),
            "with texture coordinates",
        ),
        (
            Box::new(move |s| texture(s, 3, true)),
            "texture 0: 2x2 with 3 texels",
        ),
    ];
    for (break_it, says) in breaks {
        let mut s = scene.clone();
        break_it(&mut s);
        let e = GpuRenderer::new(&tracer, &s, &tree)
            .err()
            .expect(says)
            .to_string();
        assert!(
            e.contains("the scene's links are broken") && e.contains(says),
            "{says}: {e}"
        );
    }
}

struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Camera rays through a grid over the mesh's box, random rays from inside the box, and rays
/// with zero direction components.
fn test_rays(mesh: &TriMesh, n: usize) -> Vec<Ray> {
    let b = mesh.bounds();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let eye = b.center() + Vec3::new(0.35, 0.25, 1.0).normalize() * 3.0 * b.radius();
    (0..n)
        .map(|i| {
            let target = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
            match i % 4 {
                0 | 1 => Ray::new(eye, target - eye, 0.0, f32::INFINITY),
                2 => {
                    let o = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
                    Ray::new(o, target - o, 0.0, 1.0)
                }
                _ => {
                    let mut d = target - eye;
                    d[i % 3] = 0.0;
                    Ray::new(eye.with_y(target.y), d, 0.0, f32::INFINITY)
                }
            }
        })
        .collect()
}

/// Rays with absurd numbers (±0, ±inf, NaN, ±1e30, a denormal, f32::MAX, 1e7 in a sixth of
/// their components), and rays from 10^3 to 10^5 times the mesh's size away, through the
/// kd-tree kernels compiled without wgpu's checks: the CPU's hits and misses, closest and any,
/// and (where the adapter counts them) the CPU's steps; no fault.
#[test]
fn rays_of_absurd_numbers_trace_as_on_the_cpu() {
    let Some(ctx) = gpu() else { return };
    assert!(ctx.unchecked);
    let mesh = shared_mesh("spot.obj");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let absurd = [
        0.0,
        -0.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        1e30,
        -1e30,
        1e-40,
        f32::MAX,
        1e7,
    ];
    let mut rng = Rng(0x5eed_1604);
    let mut rays = test_rays(&mesh, 4096);
    for r in &mut rays {
        let mut v = [
            r.origin.x, r.origin.y, r.origin.z, r.t_min, r.dir.x, r.dir.y, r.dir.z, r.t_max,
        ];
        for x in &mut v {
            if rng.f() < 1.0 / 6.0 {
                *x = absurd[(rng.f() * absurd.len() as f32) as usize % absurd.len()];
            }
        }
        *r = Ray {
            origin: Vec3::new(v[0], v[1], v[2]),
            t_min: v[3],
            dir: Vec3::new(v[4], v[5], v[6]),
            t_max: v[7],
        };
    }
    // And valid rays from far off (10^3 to 10^5 times the mesh's size), where the entry
    // grid's lookup would round into the wrong cell: they start at the root.
    let b = mesh.bounds();
    for k in 0..1024 {
        let target = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
        let away = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5).normalize_or(Vec3::Z);
        let far = b.radius() * 10f32.powi(3 + k % 3);
        rays.push(Ray::new(target + away * far, -away, 0.0, f32::INFINITY));
    }
    for any in [false, true] {
        let (hits, _) = tracer.trace(&rays, any).unwrap();
        compare(&tree, &rays, &hits, any, &format!("absurd rays, any={any}"));
        let hit = hits.iter().filter(|h| h.prim != NO_PRIM).count();
        assert!(hit > 500, "{hit} of {} absurd rays hit", rays.len());
        // Where the adapter counts the walks' steps: the far rays take the CPU's steps, to 1 %
        // (their descents from the root, not from a cell their rounding put them in: without
        // that guard the GPU skips a third of the inner steps). Not step for step: that far
        // off, the GPU's and the CPU's rounding send a few rays through other leaves to the
        // same hit (measured on lavapipe: 5 of 17,954 inner steps). Nor the absurd rays: a GPU
        // flushes a denormal direction to 0.
        let far = &rays[rays.len() - 1024..];
        if let Some(stats) = tracer.query_stats_with(far, any, Kernels::Fused).unwrap() {
            let mut c = raystream_accel::Counters::default();
            for r in far {
                tree.intersect_counted(r, Traversal::Ropes, any, &mut c);
            }
            let gpu = [stats.steps[0], stats.steps[1], stats.listed];
            for (k, (g, c)) in gpu
                .into_iter()
                .zip([c.inner, c.leaves, c.triangles])
                .enumerate()
            {
                assert!(
                    g.abs_diff(c) * 100 <= c,
                    "any={any}: GPU {g} against the CPU's {c} {}",
                    ["inner steps", "leaves", "triangles"][k]
                );
            }
        }
    }
}

/// GPU hits against the CPU's ropes traversal: same hit/miss, same prim (or a tie at a shared
/// edge: the CPU's triangle at the GPU's distance), t within 1e-5 relative.
fn compare(tree: &KdTree, rays: &[Ray], gpu: &[GpuHit], any: bool, what: &str) {
    let mut ties = 0;
    for (r, g) in rays.iter().zip(gpu) {
        let cpu = if any {
            tree.intersect_any(r, Traversal::Ropes)
        } else {
            tree.intersect(r, Traversal::Ropes)
        };
        match cpu {
            None => assert!(
                g.t == f32::INFINITY && g.prim == NO_PRIM,
                "{what}: GPU hit {g:?}, CPU miss, ray {r:?}"
            ),
            Some(c) => {
                assert!(
                    g.t.is_finite() && g.prim != NO_PRIM,
                    "{what}: GPU miss, CPU {c:?}, ray {r:?}"
                );
                if any {
                    assert!(
                        g.t >= r.t_min && g.t <= r.t_max,
                        "{what}: any-hit t {} outside the ray's range",
                        g.t
                    );
                    continue;
                }
                assert!(
                    (g.t - c.t).abs() <= 1e-5 * c.t.abs().max(1e-6),
                    "{what}: t {} vs CPU {} for {r:?}",
                    g.t,
                    c.t
                );
                if g.prim != c.prim {
                    ties += 1;
                }
            }
        }
    }
    assert!(
        ties * 1000 <= rays.len(),
        "{what}: {ties} prim differences of {} rays",
        rays.len()
    );
}

#[test]
fn gpu_hits_equal_cpu_hits_on_every_mesh() {
    let Some(ctx) = gpu() else { return };
    eprintln!("adapter: {}", ctx.describe());
    for name in [
        "spot.obj",
        "utah_teapot.obj",
        "goblet_vase.stl",
        "stanford_bunny.ply",
        "stanford_lucy_100k.ply",
        "turbine_blade.ply",
    ] {
        let mesh = shared_mesh(name);
        for builder in [Builder::Sah, Builder::Median] {
            let tree = KdTree::build(&mesh, builder);
            let tracer = GpuTracer::new(&ctx, &tree).unwrap();
            let rays = test_rays(&mesh, 4096);
            for any in [false, true] {
                let (hits, _) = tracer.trace(&rays, any).unwrap();
                let what = format!("{name} {builder:?} any={any}");
                compare(&tree, &rays, &hits, any, &what);
                // The split kernels walk the same leaves: the very same records.
                let (split, times) = tracer.trace_with(&rays, any, Kernels::Split).unwrap();
                // One leaf a step for every ray still walking: as many steps as the longest
                // walk has leaves, however the host batched its submissions.
                let longest = rays
                    .iter()
                    .map(|r| {
                        let mut c = raystream_accel::Counters::default();
                        tree.intersect_counted(r, Traversal::Ropes, any, &mut c);
                        c.leaves
                    })
                    .max()
                    .unwrap();
                assert_eq!(
                    times.split_steps,
                    Some(longest as u32),
                    "{what}: split steps"
                );
                if any {
                    compare(&tree, &rays, &split, any, &format!("{what} split"));
                } else {
                    assert_eq!(hits, split, "{what}: split kernels differ from fused");
                }
                // Persistent threads trace each ray with the same loop: the same records.
                let (persistent, _) = tracer.trace_with(&rays, any, Kernels::Persistent).unwrap();
                if any {
                    compare(
                        &tree,
                        &rays,
                        &persistent,
                        any,
                        &format!("{what} persistent"),
                    );
                } else {
                    assert_eq!(hits, persistent, "{what}: persistent kernels differ");
                }
                // The "if-if" loop takes the same steps in the same order: the same records.
                let (ifif, _) = tracer.trace_with(&rays, any, Kernels::IfIf).unwrap();
                if any {
                    compare(&tree, &rays, &ifif, any, &format!("{what} ifif"));
                } else {
                    assert_eq!(hits, ifif, "{what}: if-if kernels differ");
                }
            }
        }
    }
}

/// Ground planes made "infinite" by scaling, seen at grazing angles (raystream-accel's
/// `long_ground_planes_are_hit_where_their_planes_are`): a square 10⁶ on a side and a strip 5
/// wide and 10⁶ long. The kernels' t comes from the triangle's plane, as the CPU's does, so
/// every ray whose f64 hit lies 0.01 inside the quad hits it at the f64 t within 1e-5 (closest
/// and any hit), and none 0.01 outside it does.
#[test]
fn long_ground_planes_are_hit_where_their_planes_are() {
    let Some(ctx) = gpu() else { return };
    // From 2 units above them, 2° to 60° below the horizon, both ways along them.
    let rays: Vec<Ray> = (0..64 * 48 * 2)
        .map(|k| {
            let (x, down) = ((k / 96) as f32 / 63.0, (k / 2 % 48) as f32 / 47.0);
            let down = (2.0 + 58.0 * down).to_radians().tan();
            let along = if k % 2 == 0 { -1.0 } else { 1.0 };
            let d = Vec3::new(-0.6 + 1.2 * x, -down, along).normalize();
            Ray::new(Vec3::new(0.0, 1.0, 5.0), d, 0.0, f32::INFINITY)
        })
        .collect();
    for (w, l) in [(5e5f32, 5e5f32), (2.5, 5e5)] {
        // The unit ground quad stretched and lowered to y = -1.
        let mut mesh = TriMesh::ground_quad(1.0);
        for p in &mut mesh.positions {
            *p = *p * Vec3::new(2.0 * w, 1.0, 2.0 * l) - Vec3::Y;
        }
        let tree = KdTree::build(&mesh, Builder::Sah);
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        for any in [false, true] {
            let (hits, _) = tracer.trace(&rays, any).unwrap();
            let mut inside = 0;
            for (ray, h) in rays.iter().zip(&hits) {
                let (od, dd) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
                let t = (-1.0 - od.y) / dd.y;
                let p = od + dd * t;
                let what = format!("{w} x {l}, any {any}: {ray:?}");
                let side = p.x.abs() - w as f64;
                if side < -0.01 && p.z.abs() < l as f64 {
                    inside += 1;
                    assert!(h.prim != NO_PRIM, "{what} misses at {p:?}");
                    let err = ((h.t as f64 - t) / t).abs();
                    assert!(err < 1e-5, "{what}: t {} against {t}", h.t);
                } else if side > 0.01 {
                    assert_eq!(h.prim, NO_PRIM, "{what} hits at {p:?}");
                }
            }
            assert!(inside > 3000, "{inside}");
        }
    }
}

/// The GPU context where the adapter has f64 (wgpu's SHADER_F64, which the huge triangles'
/// planes need); `None`, skipping, on an adapter without it, but never in CI: lavapipe has it.
fn gpu_with_f64() -> Option<GpuContext> {
    let ctx = gpu()?;
    assert!(
        ctx.f64_planes() || !in_ci(),
        "{}: no f64 (wgpu's SHADER_F64)",
        ctx.info.name
    );
    if !ctx.f64_planes() {
        eprintln!("skipping: {} has no f64", ctx.info.name);
        return None;
    }
    Some(ctx)
}

/// Huge ground quads turned off the axes (raystream-accel's
/// `huge_turned_ground_quads_are_hit_where_their_planes_are`), whose planes f32 cannot place
/// where the rays start: with f64 planes every kernel layout hits every ray whose f64 hit lies
/// inside by the margin at the f64 t within 1e-5, closest and any hit, and none that misses
/// by it; the CPU hits the same rays (t within 1e-6, which its f64 and the GPU's agree to).
/// With f32 planes (`set_f64_planes(false)`, the kernels before) the 5 × 10⁶ strip turned 0.3°
/// fails that, as the CPU's test did. lavapipe has f64: CI fails without it.
#[test]
fn huge_turned_ground_quads_are_hit_where_their_planes_are() {
    use raystream_accel::brute::{self, BIG_TURNED_QUADS, Verdict};
    let Some(mut ctx) = gpu_with_f64() else {
        return;
    };
    let rays = brute::turned_quad_rays(64, 48);
    // Whether every ray the f64 verdict is sure of agrees with it, `trace`d with `kernels`.
    let agrees = |tracer: &GpuTracer, corners: &[[Vec3; 3]], margin: f64, kernels, any| {
        let (hits, _) = tracer.trace_with(&rays, any, kernels).unwrap();
        rays.iter().zip(&hits).all(|(ray, h)| {
            match brute::verdict_f64(corners, ray, margin) {
                // An any-hit query may report the other triangle where both are hit.
                Verdict::Inside(t) => {
                    h.prim != NO_PRIM && (any || ((h.t as f64 - t) / t).abs() < 1e-5)
                }
                Verdict::Outside => h.prim == NO_PRIM,
                Verdict::Near => true,
            }
        })
    };
    for (w, l, degrees) in BIG_TURNED_QUADS {
        let mesh = brute::turned_quad(w, l, degrees);
        let tree = KdTree::build(&mesh, Builder::Sah);
        let corners: Vec<[Vec3; 3]> = (0..2).map(|i| mesh.corners(i)).collect();
        let margin = brute::turned_quad_margin(w, l);
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        for kernels in LAYOUTS {
            for any in [false, true] {
                let what = format!("{w} x {l} turned {degrees}°, {kernels:?}, any {any}");
                assert!(agrees(&tracer, &corners, margin, kernels, any), "{what}");
            }
        }
        let (hits, _) = tracer.trace(&rays, false).unwrap();
        for (ray, h) in rays.iter().zip(&hits) {
            // Either triangle where a ray meets their shared edge (a tie): the same t.
            let cpu = tree.intersect(ray, Traversal::Ropes);
            assert_eq!(cpu.is_some(), h.prim != NO_PRIM, "{ray:?}");
            if let Some(c) = cpu {
                assert!(
                    ((c.t - h.t) / c.t).abs() < 1e-6,
                    "{ray:?}: {} against {}",
                    h.t,
                    c.t
                );
            }
        }
    }
    ctx.set_f64_planes(false);
    let mesh = brute::turned_quad(5.0, 5e6, 0.3);
    let tree = KdTree::build(&mesh, Builder::Sah);
    let corners: Vec<[Vec3; 3]> = (0..2).map(|i| mesh.corners(i)).collect();
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    assert!(!agrees(&tracer, &corners, 1e-2, Kernels::Fused, false));
}

/// Rays leaving large quads a hair off their planes (a floor 10⁴ wide, as in the default scene,
/// and the huge turned quads), up or down, some grazing, from 10⁻⁷ to 10⁻² of the quad's size
/// above or below it: beyond the plane lever, where the f32 t lies outside the ray's range by
/// twice its slack the GPU rejects it in f32 as the CPU does (`PLANE_T_SLACK`), and elsewhere
/// places the plane in f64. Every kernel layout, closest and any hit: the CPU's hits and
/// misses, at its t within 1e-6.
#[test]
fn rays_leaving_large_quads_agree_with_the_cpu() {
    use raystream_accel::brute::{self, BIG_TURNED_QUADS};
    let Some(ctx) = gpu_with_f64() else { return };
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut quads = vec![(5e3f32, 5e3f32, 0.0f32)];
    quads.extend(BIG_TURNED_QUADS);
    let (mut hits, mut misses) = (0, 0);
    for (w, l, degrees) in quads {
        let mesh = brute::turned_quad(w, l, degrees);
        let tree = KdTree::build(&mesh, Builder::Sah);
        let [a, b, c] = mesh.corners(0).map(|v| v.as_dvec3());
        let n = (b - a).cross(c - a).normalize();
        let size = (b - a).length().max((c - a).length());
        let rays: Vec<Ray> = (0..2048)
            .map(|k| {
                let (u, v) = (next() as f64, next() as f64);
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let side = if k % 2 == 0 { 1.0 } else { -1.0 };
                let off = side * size * 10f64.powf(-7.0 + 5.0 * next() as f64);
                let o = a + (b - a) * u + (c - a) * v + n * off;
                let mut d = Vec3::new(next(), next(), next()) * 2.0 - 1.0;
                if k % 3 == 0 {
                    let nf = n.as_vec3();
                    d -= nf * nf.dot(d) * (1.0 - 10f32.powf(-4.0 * next()));
                }
                let t_max = [f32::INFINITY, 1.0, 1e-3][k % 3];
                Ray::new(o.as_vec3(), d, 0.0, t_max)
            })
            .collect();
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        for any in [false, true] {
            let cpu = tree.intersect_all(&rays, Traversal::Ropes, any);
            for kernels in LAYOUTS {
                let (gpu, _) = tracer.trace_with(&rays, any, kernels).unwrap();
                for ((ray, c), g) in rays.iter().zip(&cpu).zip(&gpu) {
                    let what = format!("{w} x {l} turned {degrees}°, {kernels:?}, any {any}");
                    assert_eq!(c.is_some(), g.prim != NO_PRIM, "{what}: {ray:?}");
                    if let Some(c) = c {
                        let err = ((c.t - g.t) / c.t).abs();
                        assert!(err < 1e-6, "{what}: {ray:?}: {} against {}", g.t, c.t);
                    }
                }
            }
            hits += cpu.iter().filter(|h| h.is_some()).count();
            misses += cpu.iter().filter(|h| h.is_none()).count();
        }
    }
    assert!(hits > 1000 && misses > 2000, "{hits} hits, {misses} misses");
}

/// The split kernels' lists filled a lane at a time or a subgroup at a time (the default where
/// the adapter has subgroups): the lists' order differs, the hits and the steps do not.
#[test]
fn split_kernels_give_the_same_hits_however_their_lists_fill() {
    let Some(mut ctx) = gpu() else { return };
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let rays = test_rays(&mesh, 4096);
    let mut runs = Vec::new();
    for subgroups in [true, false] {
        ctx.set_subgroup_appends(subgroups);
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        let (fused, _) = tracer.trace(&rays, false).unwrap();
        for any in [false, true] {
            let (split, times) = tracer.trace_with(&rays, any, Kernels::Split).unwrap();
            if !any {
                assert_eq!(
                    fused, split,
                    "subgroup appends {subgroups}: split differs from fused"
                );
            }
            runs.push((split, times.split_steps));
        }
    }
    assert!(runs[0].1.is_some_and(|s| s > 1));
    assert_eq!(runs[0], runs[2], "closest hits");
    assert_eq!(runs[1], runs[3], "any hits");
}

/// The statistics query walks the same nodes as the CPU's rope traversal, step for step: the
/// same inner nodes, leaves and listed triangles summed over the rays; SIMD efficiencies are
/// shares of lanes, and coherent rays keep more lanes busy than incoherent ones.
#[test]
fn query_statistics_count_the_cpu_walk() {
    let Some(ctx) = gpu() else { return };
    let has_subgroups = ctx.device.features().contains(wgpu::Features::SUBGROUP);
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let rays = test_rays(&mesh, 20_000);
    for (any, kernels) in [false, true]
        .into_iter()
        .flat_map(|any| [(any, Kernels::Fused), (any, Kernels::IfIf)])
    {
        let Some(stats) = tracer.query_stats_with(&rays, any, kernels).unwrap() else {
            assert!(!has_subgroups);
            eprintln!("skipping: '{}' has no subgroup operations", ctx.info.name);
            return;
        };
        let mut c = raystream_accel::Counters::default();
        for r in &rays {
            tree.intersect_counted(r, Traversal::Ropes, any, &mut c);
        }
        assert_eq!(stats.rays, rays.len() as u64);
        assert_eq!(
            (stats.steps[0], stats.steps[1], stats.listed),
            (c.inner, c.leaves, c.triangles),
            "any={any} {kernels:?}: GPU (inner, leaves, triangles) vs the CPU's"
        );
        assert!(stats.steps[2] <= stats.listed && stats.steps[2] > 0);
        // Residency: at least one subgroup ran, and never more invocations than dispatched
        // (rays rounded up to whole workgroups). The kernel also checked that every
        // invocation booked in was booked out.
        let lanes = stats.subgroup_size;
        assert!(lanes.is_power_of_two(), "subgroup size {lanes}");
        let [gx, gy, _] = ctx.dims(rays.len() as u32);
        let dispatched = (gx * gy * crate::WORKGROUP_SIZE) as u64;
        assert!(
            (lanes as u64..=dispatched).contains(&stats.peak_resident),
            "peak resident invocations {} (subgroup {lanes}, dispatched {dispatched})",
            stats.peak_resident
        );
        for k in 0..3 {
            let e = stats.simd_efficiency(k);
            assert!(
                e > 0.0 && e <= 1.0,
                "any={any} {}: {e}",
                QueryStats::KINDS[k]
            );
        }
    }
    // Camera rays through neighbouring pixels (coherent) against rays in random directions
    // from random points (incoherent): divergence shows in the traversal's efficiency.
    let b = mesh.bounds();
    let eye = b.center() + Vec3::new(0.2, 0.3, 1.0).normalize() * 2.5 * b.radius();
    let coherent: Vec<Ray> = (0..128 * 128)
        .map(|p| {
            let (x, y) = ((p % 128) as f32 / 127.0, (p / 128) as f32 / 127.0);
            let target = b.min + (b.max - b.min) * Vec3::new(x, y, 0.5);
            Ray::new(eye, target - eye, 0.0, f32::INFINITY)
        })
        .collect();
    let mut rng = Rng(7);
    let incoherent: Vec<Ray> = (0..128 * 128)
        .map(|_| {
            let o = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
            let d = Vec3::new(rng.f(), rng.f(), rng.f()) * 2.0 - 1.0;
            Ray::new(o, d, 0.0, f32::INFINITY)
        })
        .collect();
    let eff = |rays: &[Ray]| {
        let s = tracer.query_stats(rays, false).unwrap().unwrap();
        s.simd_efficiency(0)
    };
    let (c, i) = (eff(&coherent), eff(&incoherent));
    eprintln!("SIMD efficiency of traversal steps: coherent {c:.3}, incoherent {i:.3}");
    assert!(c > i, "coherent {c} vs incoherent {i}");
}

/// The entry grid on the GPU: the kernels start each walk at the node the CPU's lookup gives
/// (the statistics query's inner steps equal the CPU's, with the grid and without it), and the
/// hits are the same records as without it, also for rays that enter on split planes.
#[test]
fn the_entry_grid_changes_no_gpu_hit() {
    let Some(ctx) = gpu() else { return };
    let has_subgroups = ctx.device.features().contains(wgpu::Features::SUBGROUP);
    let mesh = shared_mesh("stanford_bunny.ply");
    let with = KdTree::build(&mesh, Builder::Sah);
    assert!(!with.entry.cells.is_empty());
    let mut without = with.clone();
    without.set_entry_grid(0);
    let mut rays = test_rays(&mesh, 6000);
    // Entry points on split planes: from inside the box, and from outside through them.
    let b = with.bounds;
    let mut rng = Rng(11);
    for (i, n) in with.inners.iter().enumerate().step_by(7).take(3000) {
        let mut p = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
        p[n.axis as usize] = n.split;
        let d = Vec3::new(rng.f(), rng.f(), rng.f()) * 2.0 - 1.0;
        rays.push(if i % 2 == 0 {
            Ray::new(p, d, 0.0, f32::INFINITY)
        } else {
            Ray::new(p - d * 4.0 * b.radius(), d, 0.0, f32::INFINITY)
        });
    }
    let (gw, gwo) = (
        GpuTracer::new(&ctx, &with).unwrap(),
        GpuTracer::new(&ctx, &without).unwrap(),
    );
    for any in [false, true] {
        let (a, _) = gw.trace(&rays, any).unwrap();
        let (o, _) = gwo.trace(&rays, any).unwrap();
        assert!(a == o, "any={any}: the grid changed GPU hits");
        compare(&with, &rays, &a, any, "entry grid");
        let mut steps = Vec::new();
        for (tree, tracer) in [(&with, &gw), (&without, &gwo)] {
            let Some(stats) = tracer.query_stats(&rays, any).unwrap() else {
                assert!(!has_subgroups);
                continue;
            };
            let mut c = raystream_accel::Counters::default();
            for r in &rays {
                tree.intersect_counted(r, Traversal::Ropes, any, &mut c);
            }
            assert_eq!(
                (stats.steps[0], stats.steps[1], stats.listed),
                (c.inner, c.leaves, c.triangles),
                "any={any}: GPU (inner, leaves, triangles) vs the CPU's"
            );
            steps.push(c.inner);
        }
        if let [w, wo] = steps[..] {
            eprintln!("any={any}: {w} inner steps with the grid, {wo} without");
            assert!((w as f64) < 0.8 * wo as f64, "{w} vs {wo}");
        }
    }
}

/// `stats.wgsl`'s 64-bit counters carry into their high word: 256 invocations, in many
/// subgroups at once, each add 2^28 to one counter (2^36 in all: the low word wraps 16 times)
/// and 2^28 − 1 to another (wrapping at uneven points).
#[test]
fn statistics_counters_carry_past_32_bits() {
    let Some(ctx) = gpu() else { return };
    let source = stats_wgsl();
    let add64 = &source[source.find("fn add64").unwrap()..];
    let add64 = &add64[..add64.find("\n}\n").unwrap() + 3];
    let module = format!(
        "@group(0) @binding(0) var<storage, read_write> stats: array<atomic<u32>, 4>;\n{add64}\n\
         @compute @workgroup_size(64) fn main() {{ add64(0u, 1u << 28u); add64(1u, (1u << 28u) - 1u); }}"
    );
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("add64 check"),
            source: wgpu::ShaderSource::Wgsl(module.into()),
        });
    let pipeline = ctx.auto_pipeline(&module, "main");
    let buf = ctx
        .work_buffer("counters", 16, wgpu::BufferUsages::empty())
        .unwrap();
    let bind = ctx.bind_buffers("counters", &pipeline.get_bind_group_layout(0), &[&buf]);
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(4, 1, 1);
    }
    ctx.queue.submit([enc.finish()]);
    let w = read_words(&ctx, &buf).unwrap();
    let counter = |k: usize| u64_at(&w, k);
    assert_eq!(counter(0), 256 << 28);
    assert_eq!(counter(1), 256 * ((1 << 28) - 1));
}

#[test]
fn spinning_waits_give_the_same_results() {
    let Some(mut ctx) = gpu() else { return };
    let mesh = shared_mesh("spot.obj");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let rays = test_rays(&mesh, 4096);
    let blocking: Vec<_> = [false, true]
        .map(|any| {
            GpuTracer::new(&ctx, &tree)
                .unwrap()
                .trace(&rays, any)
                .unwrap()
                .0
        })
        .into();
    ctx.set_spin_wait(true);
    for (any, want) in [false, true].into_iter().zip(&blocking) {
        // Twice: the second run reuses the tracer's buffers after a spinning readback.
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        for _ in 0..2 {
            let (hits, _) = tracer.trace(&rays, any).unwrap();
            assert_eq!(&hits, want, "any={any}: spinning waits changed the hits");
        }
    }
}

/// The ray-query kernels give the same records at every workgroup size
/// (`RAYSTREAM_GPU_WORKGROUP`), on a ray count that leaves the last workgroup part-filled;
/// sizes that are not a power of two from 32 to the adapter's limit are refused.
#[test]
fn query_workgroup_sizes_give_the_same_hits() {
    let Some(mut ctx) = gpu() else { return };
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let rays = test_rays(&mesh, 5000);
    let kernels = [Kernels::Fused, Kernels::IfIf, Kernels::Persistent];
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let want: Vec<Vec<GpuHit>> = [false, true]
        .iter()
        .flat_map(|&any| kernels.map(|k| tracer.trace_with(&rays, any, k).unwrap().0))
        .collect();
    drop(tracer);
    compare(&tree, &rays, &want[0], false, "default workgroup");
    for bad in [0, 16, 48, 2048] {
        assert!(
            ctx.set_query_workgroup(bad).is_err(),
            "{bad} threads accepted"
        );
    }
    assert_eq!(ctx.query_workgroup(), crate::WORKGROUP_SIZE);
    for threads in [32, 128, 256] {
        ctx.set_query_workgroup(threads).unwrap();
        let tracer = GpuTracer::new(&ctx, &tree).unwrap();
        let got = [false, true]
            .iter()
            .flat_map(|&any| kernels.map(|k| tracer.trace_with(&rays, any, k).unwrap().0));
        for (i, hits) in got.enumerate() {
            assert_eq!(
                hits, want[i],
                "{threads} threads, query {i}: the hits differ"
            );
        }
    }
}

/// Queries queued back to back in one submission each trace every ray: the last one's hits
/// (its hit buffer cleared just before it) equal a lone query's, for every kernel layout the
/// host does not drive step by step; persistent threads restart their ray counter each time.
/// An untimed query traces the same hits, timed by the wall clock alone.
#[test]
fn streamed_queries_each_trace_every_ray() {
    let Some(ctx) = gpu() else { return };
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let rays = test_rays(&mesh, 4096);
    for any in [false, true] {
        for kernels in [Kernels::Fused, Kernels::IfIf, Kernels::Persistent] {
            let (want, timed) = tracer.trace_with(&rays, any, kernels).unwrap();
            let (hits, ms) = tracer
                .trace_streamed(&rays, any, kernels, 3)
                .unwrap()
                .unwrap();
            assert!(ms > 0.0);
            assert_eq!(hits, want, "any={any} {kernels:?}: streamed hits differ");
            // Untimed: the same hits, a wall time and no kernel time.
            let (hits, untimed) = tracer.trace_untimed(&rays, any, kernels).unwrap();
            assert_eq!(hits, want, "any={any} {kernels:?}: untimed hits differ");
            let stamps = ctx
                .device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY);
            assert_eq!(timed.kernel_gpu_ms.is_some(), stamps);
            assert!(untimed.kernel_gpu_ms.is_none() && untimed.kernel_ms > 0.0);
        }
        assert!(
            tracer
                .trace_streamed(&rays, any, Kernels::Split, 3)
                .unwrap()
                .is_none()
        );
    }
}

/// The floor kernel traverses nothing: every valid ray's record is the miss record, every
/// invalid one's is marked (u = 1, so that the whole ray was read), lone and streamed alike, and
/// its times are measured.
#[test]
fn the_floor_kernel_reads_every_ray_and_traverses_nothing() {
    let Some(ctx) = gpu() else { return };
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let mut rays = test_rays(&mesh, 4096);
    // Invalid rays, each by one field: a NaN origin, an infinite direction, t_min > t_max.
    rays[7].origin.y = f32::NAN;
    rays[100].dir.z = f32::INFINITY;
    (rays[2000].t_min, rays[2000].t_max) = (2.0, 1.0);
    let (closest, _) = tracer.trace(&rays, false).unwrap();
    assert!(
        closest.iter().any(|h| h.prim != NO_PRIM),
        "the rays hit the bunny"
    );
    let (hits, times) = tracer.trace_with(&rays, false, Kernels::Floor).unwrap();
    assert!(times.kernel_ms > 0.0);
    for (i, h) in hits.iter().enumerate() {
        let invalid = [7, 100, 2000].contains(&i);
        assert_eq!(h.prim, NO_PRIM, "ray {i}");
        assert_eq!(h.t, f32::INFINITY, "ray {i}");
        assert_eq!((h.u, h.v), (invalid as u32 as f32, 0.0), "ray {i}");
    }
    let (streamed, ms) = tracer
        .trace_streamed(&rays, true, Kernels::Floor, 3)
        .unwrap()
        .unwrap();
    assert!(ms > 0.0);
    assert_eq!(streamed, hits);
    assert!(
        tracer
            .query_stats_with(&rays, false, Kernels::Floor)
            .unwrap()
            .is_none()
    );
}

/// More rays than one query can bind are traced in chunks: the same hits as one query, for
/// every kernel layout, the chunks' times summed; a stream of such queries is not measured.
#[test]
fn oversized_queries_are_traced_in_chunks() {
    let Some(ctx) = gpu() else { return };
    let mesh = shared_mesh("stanford_bunny.ply");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let whole = GpuTracer::new(&ctx, &tree).unwrap();
    let mut chunked = GpuTracer::new(&ctx, &tree).unwrap();
    // As if the device bound 1000 rays at most (4096 rays: four chunks, the last short).
    chunked.max_rays = 1000;
    let rays = test_rays(&mesh, 4096);
    let has_timestamps = ctx
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY);
    for any in [false, true] {
        for kernels in LAYOUTS {
            let (want, _) = whole.trace_with(&rays, any, kernels).unwrap();
            let (got, times) = chunked.trace_with(&rays, any, kernels).unwrap();
            assert_eq!(got, want, "any={any} {kernels:?}: chunked hits differ");
            assert_eq!(times.kernel_gpu_ms.is_some(), has_timestamps);
            assert_eq!(times.split_steps.is_some(), kernels == Kernels::Split);
            assert!(
                chunked
                    .trace_streamed(&rays, any, kernels, 2)
                    .unwrap()
                    .is_none()
            );
        }
        // The statistics query batches likewise: the same steps, summed over the batches.
        if let (Some(a), Some(b)) = (
            whole.query_stats(&rays, any).unwrap(),
            chunked.query_stats(&rays, any).unwrap(),
        ) {
            assert_eq!((a.steps, a.listed), (b.steps, b.listed), "any={any}");
        }
    }
}

#[test]
fn gpu_contract_edge_cases() {
    let Some(ctx) = gpu() else { return };
    let tri = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    let tree = KdTree::build_from_corners(&tri, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let hit = Ray::new(
        Vec3::new(0.25, 0.5, 2.0),
        Vec3::new(0.0, 0.0, -2.0),
        0.0,
        f32::INFINITY,
    );
    let rays = [
        hit,
        Ray {
            t_max: 0.999,
            ..hit
        },
        Ray { t_min: 1.0, ..hit },
        Ray {
            dir: Vec3::ZERO,
            ..hit
        },
        Ray {
            origin: Vec3::new(f32::NAN, 0.5, 2.0),
            ..hit
        },
        Ray {
            t_max: f32::NAN,
            ..hit
        },
        Ray {
            origin: Vec3::new(f32::INFINITY, 0.5, 2.0),
            ..hit
        },
    ];
    let (h, times) = tracer.trace(&rays, false).unwrap();
    // Timestamps, where the adapter resolves them, lie within the wall time of the submission.
    if let Some(k) = times.kernel_gpu_ms {
        assert!(k > 0.0 && k <= times.kernel_ms + 1e-3, "{times:?}");
    }
    assert_eq!((h[0].t, h[0].prim, h[0].u, h[0].v), (1.0, 0, 0.25, 0.5));
    assert_eq!(h[1].prim, NO_PRIM);
    assert_eq!(h[2].t, 1.0);
    for (i, m) in h.iter().enumerate().skip(3) {
        assert_eq!((m.t, m.prim), (f32::INFINITY, NO_PRIM), "ray {i}");
    }
    // An empty scene misses everything.
    let empty = KdTree::build_from_corners(&[], Builder::Sah);
    let (h, _) = GpuTracer::new(&ctx, &empty)
        .unwrap()
        .trace(&[hit], false)
        .unwrap();
    assert_eq!(h[0].prim, NO_PRIM);
}

#[test]
fn adapter_filter_reports_what_exists() {
    match GpuContext::new(Some("no-such-adapter-xyz")) {
        Err(GpuError::NoAdapter(msg)) => assert!(
            msg.contains("no-such-adapter-xyz") || msg.contains("driver"),
            "{msg}"
        ),
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("an adapter matched a made-up name"),
    }
}

/// The mean absolute difference (of 255) and the fraction of pixels whose largest channel
/// difference exceeds 2/255, in 8-bit sRGB as `rays.py imgdiff` measures them.
fn image_diff(a: &raystream_cpu::Image, b: &raystream_cpu::Image) -> (f64, f64) {
    let (mean, worst) = a.srgb8_diff(b);
    let over = worst.iter().filter(|&&d| d > 2).count();
    (mean, over as f64 / worst.len() as f64)
}

/// The GPU stream renderer against the CPU reference on the same scene: the issue's bar (mean
/// absolute difference < 0.5/255, ≥ 99.9 % of pixels within 2/255), the same ray, hit and shadow
/// counts per depth (up to ties), and the same image on every run, in any wave size, submitted
/// wave by wave (`expect`: what the scene runs by default) or depth by depth.
fn gpu_render_matches_cpu(
    ctx: &GpuContext,
    scene: &raystream_scene::Scene,
    opt: &raystream_cpu::RenderOptions,
    expect: Submit,
    what: &str,
) {
    let volume = scene.volume.is_some();
    let tree = KdTree::build(&scene.mesh, Builder::Sah);
    let mut cpu_depths = Vec::new();
    let cpu = raystream_cpu::render(scene, &tree, opt, |s| cpu_depths.push(s));
    let tracer = GpuTracer::new(ctx, &tree).unwrap();
    let renderer = GpuRenderer::new(&tracer, scene, &tree).unwrap();
    let mut told = Vec::new();
    let (gpu, stats) = renderer.render(opt, |s| told.push(s)).unwrap();
    assert_eq!(stats.submit, expect, "{what}: submission");
    assert_eq!(renderer.submit_for(opt), expect, "{what}: submission");
    // Progress hears of every depth of every wave: their sums are the frame's counts.
    let mut summed = vec![raystream_cpu::DepthStats::default(); stats.depths.len()];
    for t in &told {
        let d = &mut summed[t.depth as usize];
        d.depth = t.depth;
        d.rays += t.rays;
        d.hits += t.hits;
        d.shadow_rays += t.shadow_rays;
    }
    assert_eq!(summed, stats.depths, "{what}: progress");
    let (mean, over) = image_diff(&cpu, &gpu);
    eprintln!(
        "{what}: mean |diff| {mean:.4}/255, {:.4} % of pixels > 2/255",
        over * 100.0
    );
    if volume {
        // The volume's tolerance (#5): the GPU's hardware filtering of an f16 texture.
        let (mean, mut worst) = cpu.srgb8_diff(&gpu);
        worst.sort_unstable();
        let p99 = worst[worst.len() * 99 / 100];
        assert!(
            mean < 1.0 && p99 <= 8,
            "{what}: GPU vs CPU mean {mean}/255, p99 {p99}/255"
        );
    } else {
        assert!(mean < 0.5, "{what}: mean absolute difference {mean}/255");
        assert!(
            over <= 0.001,
            "{what}: {} % of pixels differ by more than 2/255",
            over * 100.0
        );
    }
    assert!(
        cpu.pixels.iter().map(|p| p.length()).fold(0.0, f32::max) > 0.1,
        "{what}: the image is black"
    );
    assert_eq!(stats.depths.len(), cpu_depths.len(), "{what}: depths run");
    for (g, c) in stats.depths.iter().zip(&cpu_depths) {
        let close = |x: usize, y: usize| x.abs_diff(y) * 1000 <= y.max(1);
        assert!(
            close(g.rays, c.rays) && close(g.hits, c.hits) && close(g.shadow_rays, c.shadow_rays),
            "{what}: GPU {g:?} vs CPU {c:?}"
        );
    }
    let (again, _) = renderer.render(opt, |_| {}).unwrap();
    assert_eq!(gpu, again, "{what}: a second GPU render differs");
    // The frame as a viewer gets it (the film to sRGB on the GPU): the float frame's bytes, up
    // to 1/255 where f32 scaling and the GPU's pow round differently.
    let (rgb, _) = renderer.render_srgb8(opt, |_| {}).unwrap();
    let want = gpu.to_srgb8();
    let off = srgb8_within_one(&rgb, &want, what);
    assert!(
        off * 100 <= want.len(),
        "{what}: the GPU's sRGB film differs from its float film in {off} of {} bytes",
        want.len()
    );
    // Many small waves give the very same film and statistics, whether the host submits a
    // wave at a time (the next queued while it reads the last one's counts) or a depth at a
    // time (growing the queues depth by depth); so does one wave submitted depth by depth.
    let mut depth_by_depth = None;
    for (wave, submit) in [
        (999, Submit::Wave),
        (999, Submit::Depth),
        (u32::MAX, Submit::Depth),
    ] {
        let other = GpuRenderer::new(&tracer, scene, &tree)
            .unwrap()
            .with_wave(wave)
            .with_submit(submit);
        let mut told_here = Vec::new();
        let (image, s) = other.render(opt, |s| told_here.push(s)).unwrap();
        let ran = if submit == Submit::Wave {
            expect
        } else {
            submit
        };
        let how = format!("waves of {wave} samples submitted by {submit:?}");
        assert_eq!(s.submit, ran, "{what}, {how}");
        assert_eq!(gpu, image, "{what}: the film of {how} differs");
        assert_eq!(stats.depths, s.depths, "{what}: the counts of {how} differ");
        match ran {
            Submit::Wave => assert_eq!(s.submissions, s.waves, "{what}, {how}"),
            Submit::Depth => assert!(s.submissions >= s.waves, "{what}, {how}"),
        }
        if wave == 999 {
            assert!(s.waves > 1, "{what}, {how}");
            // The same depths of the same waves reported, in the same order.
            match &depth_by_depth {
                None => depth_by_depth = Some(told_here),
                Some(t) => assert_eq!(t, &told_here, "{what}: progress of {how}"),
            }
        } else {
            assert_eq!(told, told_here, "{what}: progress of {how}");
        }
    }
    // Queue slots reserved a lane at a time or a subgroup at a time (the default where the
    // adapter has subgroups): the queues' order differs, the film and the counts do not.
    let mut other_ctx = self::gpu().unwrap();
    other_ctx.set_subgroup_appends(!ctx.subgroup_appends());
    let has_subgroups = ctx.device.features().contains(wgpu::Features::SUBGROUP);
    assert_eq!(
        ctx.subgroup_appends() || other_ctx.subgroup_appends(),
        has_subgroups,
        "{what}: subgroup appends wherever the adapter has subgroups"
    );
    let other_tracer = GpuTracer::new(&other_ctx, &tree).unwrap();
    let other = GpuRenderer::new(&other_tracer, scene, &tree).unwrap();
    let (image, s) = other.render(opt, |_| {}).unwrap();
    let how = if other_ctx.subgroup_appends() {
        "a subgroup"
    } else {
        "a lane"
    };
    assert_eq!(
        gpu, image,
        "{what}: the film of slots reserved {how} at a time differs"
    );
    assert_eq!(
        stats.depths, s.depths,
        "{what}: the counts of slots reserved {how} at a time differ"
    );
}

#[test]
fn gpu_render_matches_cpu_on_the_builtin_scene() {
    let Some(ctx) = gpu() else { return };
    let scene = raystream_scene::Scene::builtin_default();
    // Glass (refraction with Fresnel) and a mirror: every depth spawns rays.
    for (spp, max_depth) in [(1, 4), (4, 2)] {
        let opt = raystream_cpu::RenderOptions {
            width: 96,
            height: 72,
            spp,
            max_depth,
            traversal: Traversal::Ropes,
        };
        gpu_render_matches_cpu(
            &ctx,
            &scene,
            &opt,
            Submit::Depth,
            &format!("built-in scene, {spp} spp, depth {max_depth}"),
        );
    }
}

/// Meshes and a CT volume in one scene (examples/spine_rods.toml: rods in the abdomen CT, a
/// mirror floor, two lights with light grids): the render kernels' volume stages against the
/// CPU's, the volume read by the cubic B-spline (the scene's default), trilinearly and by the
/// interpolating cubic B-spline.
#[test]
fn gpu_render_matches_cpu_with_a_volume_in_the_scene() {
    let Some(ctx) = gpu() else { return };
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/spine_rods.toml");
    let mut scene = raystream_scene::Scene::load(&path).unwrap();
    let opt = raystream_cpu::RenderOptions {
        width: 64,
        height: 48,
        spp: 1,
        max_depth: 2,
        traversal: Traversal::Ropes,
    };
    use raystream_volume::Interpolation;
    assert_eq!(
        scene.volume.as_ref().unwrap().interpolation,
        Interpolation::Cubic
    );
    gpu_render_matches_cpu(&ctx, &scene, &opt, Submit::Wave, "spine rods");
    scene.volume.as_mut().unwrap().interpolation = Interpolation::Linear;
    gpu_render_matches_cpu(&ctx, &scene, &opt, Submit::Wave, "spine rods, trilinear");
    scene.volume.as_mut().unwrap().interpolation = Interpolation::CubicInterpolating;
    gpu_render_matches_cpu(
        &ctx,
        &scene,
        &opt,
        Submit::Wave,
        "spine rods, interpolating cubic",
    );
}

#[test]
fn gpu_render_matches_cpu_on_a_scanned_mesh() {
    let Some(ctx) = gpu() else { return };
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/meshes/stanford_bunny.ply");
    let scene =
        raystream_scene::Scene::for_mesh(raystream_io::load_mesh(&path).unwrap(), &path).unwrap();
    let opt = raystream_cpu::RenderOptions {
        width: 80,
        height: 64,
        spp: 2,
        max_depth: 3,
        traversal: Traversal::Ropes,
    };
    gpu_render_matches_cpu(&ctx, &scene, &opt, Submit::Wave, "bunny");
}

#[test]
fn dvr_wgsl_params_match_rust() {
    use layout::DvrParams;
    use std::mem::{offset_of, size_of};
    let module = naga_module(&dvr_wgsl(), "dvr.wgsl");
    let names = [
        ("eye", offset_of!(DvrParams, eye)),
        ("tan_y", offset_of!(DvrParams, tan_y)),
        ("fwd", offset_of!(DvrParams, fwd)),
        ("width", offset_of!(DvrParams, width)),
        ("right", offset_of!(DvrParams, right)),
        ("height", offset_of!(DvrParams, height)),
        ("up", offset_of!(DvrParams, up)),
        ("mode", offset_of!(DvrParams, mode)),
        ("to_index0", offset_of!(DvrParams, to_index0)),
        ("step", offset_of!(DvrParams, step)),
        ("to_index1", offset_of!(DvrParams, to_index1)),
        ("iso", offset_of!(DvrParams, iso)),
        ("to_index2", offset_of!(DvrParams, to_index2)),
        ("window_width", offset_of!(DvrParams, window_width)),
        ("origin", offset_of!(DvrParams, origin)),
        ("window_level", offset_of!(DvrParams, window_level)),
        ("dims", offset_of!(DvrParams, dims)),
        ("skip_empty", offset_of!(DvrParams, skip_empty)),
        ("bricks", offset_of!(DvrParams, bricks)),
        ("opacity_count", offset_of!(DvrParams, opacity_count)),
        ("background", offset_of!(DvrParams, background)),
        ("color_count", offset_of!(DvrParams, color_count)),
        ("shading", offset_of!(DvrParams, shading)),
        ("light", offset_of!(DvrParams, light)),
        ("shadows", offset_of!(DvrParams, shadows)),
        ("crop_min", offset_of!(DvrParams, crop_min)),
        ("crop", offset_of!(DvrParams, crop)),
        ("crop_max", offset_of!(DvrParams, crop_max)),
        ("plane_count", offset_of!(DvrParams, plane_count)),
        ("planes", offset_of!(DvrParams, planes)),
        ("light_dims", offset_of!(DvrParams, light_dims)),
        ("shadow_step", offset_of!(DvrParams, shadow_step)),
        ("parallel", offset_of!(DvrParams, parallel)),
        ("hu_values", offset_of!(DvrParams, hu_values)),
        ("premultiplied", offset_of!(DvrParams, premultiplied)),
        ("curved", offset_of!(DvrParams, curved)),
        ("slice_at", offset_of!(DvrParams, slice_at)),
        ("slab_half", offset_of!(DvrParams, slab_half)),
        ("spp", offset_of!(DvrParams, spp)),
        ("bounces", offset_of!(DvrParams, bounces)),
        ("sample_first", offset_of!(DvrParams, sample_first)),
        ("sample_count", offset_of!(DvrParams, sample_count)),
        ("anisotropy", offset_of!(DvrParams, anisotropy)),
        ("light_scale", offset_of!(DvrParams, light_scale)),
        ("interpolation", offset_of!(DvrParams, interpolation)),
        ("segments", offset_of!(DvrParams, segments)),
        ("kept", offset_of!(DvrParams, kept)),
        ("pad_kept", offset_of!(DvrParams, pad_kept)),
        ("pad0", offset_of!(DvrParams, pad0)),
        ("pad1", offset_of!(DvrParams, pad1)),
    ];
    check_struct(&module, "DvrParams", size_of::<DvrParams>(), &names);
    use layout::GpuCprRow;
    let names = [
        ("centre", offset_of!(GpuCprRow, centre)),
        ("pixel_mm", offset_of!(GpuCprRow, pixel_mm)),
        ("lateral", offset_of!(GpuCprRow, lateral)),
        ("pad0", offset_of!(GpuCprRow, pad0)),
        ("normal", offset_of!(GpuCprRow, normal)),
        ("pad1", offset_of!(GpuCprRow, pad1)),
    ];
    check_struct(&module, "CprRow", size_of::<GpuCprRow>(), &names);
    use layout::DenoiseParams;
    let module = naga_module(denoise_wgsl(), "denoise.wgsl");
    let names = [
        ("width", offset_of!(DenoiseParams, width)),
        ("height", offset_of!(DenoiseParams, height)),
        ("gap", offset_of!(DenoiseParams, gap)),
        (
            "sigma_luminance",
            offset_of!(DenoiseParams, sigma_luminance),
        ),
        ("sigma_depth", offset_of!(DenoiseParams, sigma_depth)),
        ("sigma_normal", offset_of!(DenoiseParams, sigma_normal)),
        ("sigma_albedo", offset_of!(DenoiseParams, sigma_albedo)),
        ("tolerance", offset_of!(DenoiseParams, tolerance)),
        ("demodulate", offset_of!(DenoiseParams, demodulate)),
        ("over", offset_of!(DenoiseParams, over)),
        ("_pad1", offset_of!(DenoiseParams, _pad1)),
        ("_pad2", offset_of!(DenoiseParams, _pad2)),
        ("background", offset_of!(DenoiseParams, background)),
        ("_pad3", offset_of!(DenoiseParams, _pad3)),
    ];
    check_struct(&module, "DenoiseParams", size_of::<DenoiseParams>(), &names);
}

/// The built-in abdomen CT.
fn abdomen_ct() -> raystream_io::Volume {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    raystream_io::load_volume(&path, &Default::default()).unwrap()
}

/// `base` cropped to the pelvis's left half, its front cut off by a plane (LPS mm).
fn pelvis_left_half(base: raystream_cpu::dvr::DvrOptions) -> raystream_cpu::dvr::DvrOptions {
    raystream_cpu::dvr::DvrOptions {
        crop: Some([
            Vec3::new(-250.0, -400.0, -400.0),
            Vec3::new(60.0, 400.0, 400.0),
        ]),
        clip_planes: [Some((Vec3::new(0.0, 1.0, 0.2).normalize(), -60.0)), None],
        ..base
    }
}

/// Cinematic rendering on the GPU against the CPU reference on the abdomen CT (ct-bones and
/// ct-muscle, whole and cropped, ct-muscle in a forward-scattering medium, g 0.6, at +0.5 EV,
/// and ct-bones read by the cubic B-spline; 64×48, 32 paths a pixel). Both draw the same random numbers,
/// so most paths are the same path; where the f16 texture's values tip a decision they part,
/// and the pixel differs by that path's noise: the sample counts, the mean difference, the
/// pixels within 2/255 and every 8×8 block's mean light agree. The same picture every run and
/// in dispatches of a few paths each, and the premultiplied film over the background is the
/// frame.
#[test]
fn gpu_cinematic_rendering_matches_cpu() {
    use raystream_cpu::dvr::{DvrMode, DvrOptions, Interpolation, render_volume, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let plain = DvrOptions {
        width: 64,
        height: 48,
        mode: DvrMode::Cinematic,
        spp: 32,
        bounces: 3,
        ..Default::default()
    };
    let cropped = pelvis_left_half(plain);
    let forward = DvrOptions {
        anisotropy: 0.6,
        exposure: 0.5,
        ..plain
    };
    let cubic = DvrOptions {
        interpolation: Interpolation::Cubic,
        ..plain
    };
    let sharp = DvrOptions {
        interpolation: Interpolation::CubicInterpolating,
        ..plain
    };
    let cam = volume_camera(&vol, 64.0 / 48.0);
    for (preset, opt, what) in [
        (TfPreset::CtBones, plain, ""),
        (TfPreset::CtMuscle, plain, ""),
        (TfPreset::CtBones, cropped, " crop+plane"),
        (TfPreset::CtMuscle, forward, " g 0.6, +0.5 EV"),
        (TfPreset::CtBones, cubic, " cubic"),
        (TfPreset::CtMuscle, sharp, " cubic-interpolating"),
    ] {
        let name = format!("{}{what}", preset.name());
        let tf = preset.function();
        let (cpu, stats) = render_volume(&vol, &tf, &opt, &cam);
        let gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
        let (img, times) = gpu.render(&opt, &cam).unwrap();
        let (again, _) = gpu.render(&opt, &cam).unwrap();
        assert_eq!(
            img.pixels, again.pixels,
            "{name}: the same picture every run"
        );
        // In dispatches of 5 paths a pixel (5, 5, …, 2), summed across them: the same
        // picture bit for bit.
        let mut split = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
        split.paths_per_dispatch = 5 * 64 * 48;
        let (parts, parts_times) = split.render(&opt, &cam).unwrap();
        assert_eq!(parts.pixels, img.pixels, "{name}: in dispatches of 5 paths");
        assert_eq!(parts_times.samples, times.samples, "{name}");
        let (a, b) = (stats.samples as f64, times.samples as f64);
        let (mean, worst) = cpu.srgb8_diff(&img);
        let close = worst.iter().filter(|&&d| d <= 2).count() as f64 / worst.len() as f64;
        // 8×8 blocks' mean linear light.
        let block = |im: &raystream_cpu::Image, bx: u32, by: u32| {
            let mut s = Vec3::ZERO;
            for y in 8 * by..8 * by + 8 {
                for x in 8 * bx..8 * bx + 8 {
                    s += im.pixels[(x + y * im.width) as usize];
                }
            }
            s / 64.0
        };
        let total = |im: &raystream_cpu::Image| {
            im.pixels
                .iter()
                .map(|p| p.element_sum() as f64)
                .sum::<f64>()
        };
        let (lc, lg) = (total(&cpu), total(&img));
        let mut block_worst = 0.0f32;
        for by in 0..6 {
            for bx in 0..8 {
                let d = (block(&cpu, bx, by) - block(&img, bx, by))
                    .abs()
                    .max_element();
                block_worst = block_worst.max(d);
            }
        }
        eprintln!(
            "{name}: samples CPU {a} GPU {b}; light GPU/CPU − 1 = {:.4}; sRGB mean |diff| {mean:.3}/255, {:.1} % within 2/255; worst 8x8 block {block_worst:.4}",
            lg / lc - 1.0,
            100.0 * close
        );
        // Measured on lavapipe: samples within 0.2 %, the frame's light within 0.16 %, mean
        // 0.04–0.29/255, 92–99 % within 2/255, blocks within 0.003. (An isotropic phase
        // function 8 % too bright on the GPU put the light 0.5–1.2 % off.)
        assert!(
            (lg / lc - 1.0).abs() < 0.004,
            "{name}: light CPU {lc} GPU {lg}"
        );
        assert!(
            (a - b).abs() <= 0.02 * a,
            "{name}: CPU took {a} samples, GPU {b}"
        );
        assert!(mean < 1.0, "{name}: mean |diff| {mean}/255");
        assert!(close >= 0.85, "{name}: {close} within 2/255");
        assert!(
            block_worst < 0.01,
            "{name}: an 8x8 block off by {block_worst}"
        );
        let (film, alpha, _) = gpu.render_rgba(&opt, &cam).unwrap();
        assert_over_background_is(&film, &alpha, &opt, &img, &name);
    }
}

/// `--denoise`'s input from the GPU, against the CPU's: the same paths give each pixel the
/// same variance (within 0.1 % for over 80 % of the pixels, the frame's mean within 5 %); the
/// variances are the same bit for bit in dispatches of 5 paths; the film over the background is
/// the plain frame; every path is counted once in `paths_done` (a progress bar's count),
/// however the frame is split; the GPU's guides are the CPU's (depth within a step, colour within 0.02,
/// normal within 0.05, on all but 2 % of the pixels; measured: all); and the one denoiser run on
/// each device's film along its guides gives pictures within 0.5/255 of each other (mean sRGB
/// difference).
#[test]
fn gpu_cinematic_film_for_the_denoiser_matches_cpu() {
    use raystream_cpu::cinematic::{guides, render_film};
    use raystream_cpu::denoise::{DenoiseOptions, denoise};
    use raystream_cpu::dvr::{DvrMode, DvrOptions, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let opt = DvrOptions {
        width: 64,
        height: 48,
        mode: DvrMode::Cinematic,
        spp: 16,
        bounces: 3,
        ..Default::default()
    };
    let cam = volume_camera(&vol, 64.0 / 48.0);
    let tf = TfPreset::CtBones.function();
    let (cpu, _) = render_film(&vol, &tf, &opt, &cam);
    let gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    let (film, _) = gpu.render_film(&opt, &cam).unwrap();
    let mut split = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    split.paths_per_dispatch = 5 * 64 * 48;
    let (parts, _) = split.render_film(&opt, &cam).unwrap();
    assert_eq!(parts.variance, film.variance, "in dispatches of 5 paths");
    // Every path counted once, dispatch by dispatch (a progress bar's count).
    let paths = 64 * 48 * opt.spp as u64;
    assert_eq!(
        split.paths_done.load(std::sync::atomic::Ordering::Relaxed),
        paths
    );
    assert_eq!(
        gpu.paths_done.load(std::sync::atomic::Ordering::Relaxed),
        paths
    );
    assert_eq!(parts.film.pixels, film.film.pixels);
    let (plain, _) = gpu.render(&opt, &cam).unwrap();
    assert_over_background_is(&film.film, &film.alpha, &opt, &plain, "film");
    let mean = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
    let (vc, vg) = (mean(&cpu.variance), mean(&film.variance));
    let same = cpu
        .variance
        .iter()
        .zip(&film.variance)
        .filter(|(c, g)| (*c - *g).abs() <= 1e-3 * c.abs().max(g.abs()) + 1e-9)
        .count() as f64
        / film.variance.len() as f64;
    // The GPU's guides against the CPU's: the same rays through the f16 texture.
    let g = guides(&vol, &tf, &opt, &cam);
    let gg = gpu.guides(&opt, &cam).unwrap();
    assert_eq!(gg.tolerance, g.tolerance);
    let (mut depth_off, mut colour_off, mut normal_off, mut hits) = (0, 0, 0, 0);
    for p in 0..g.depth.len() {
        let (zc, zg) = (g.depth[p], gg.depth[p]);
        if zc.is_finite() != zg.is_finite() {
            depth_off += 1;
            continue;
        }
        if zc.is_finite() {
            hits += 1;
            depth_off += ((zc - zg).abs() > g.tolerance) as u32;
        }
        colour_off += ((g.albedo[p] - gg.albedo[p]).abs().max_element() > 0.02) as u32;
        normal_off += ((g.normal[p] - gg.normal[p]).length() > 0.05) as u32;
    }
    let px = g.depth.len() as f64;
    eprintln!(
        "guides: {hits} pixels with a depth; GPU off the CPU: depth {depth_off}, colour {colour_off}, normal {normal_off}"
    );
    assert!(hits > 300, "{hits}");
    for (what, off) in [
        ("depth", depth_off),
        ("colour", colour_off),
        ("normal", normal_off),
    ] {
        assert!(off as f64 <= 0.02 * px, "{what}: {off} pixels off");
    }
    let denoised = |f, g| {
        let (img, alpha) = denoise(f, g, &DenoiseOptions::default());
        let mut img: raystream_cpu::Image = img;
        for (c, a) in img.pixels.iter_mut().zip(&alpha) {
            *c += (1.0 - a) * opt.background;
        }
        img
    };
    let (dc, dg) = (denoised(&cpu, &g), denoised(&film, &gg));
    let (diff, _) = dc.srgb8_diff(&dg);
    eprintln!(
        "variance GPU/CPU − 1 = {:.4}, {:.1} % of pixels the same; denoised mean |diff| {diff:.3}/255",
        vg / vc - 1.0,
        100.0 * same
    );
    // Measured on lavapipe: the mean −1.7 %, 90.4 % of pixels the same (within 0.1 %), the
    // denoised pictures 0.23/255 apart. A variance is a heavy-tailed statistic: one path of
    // sixteen that the f16 texture sends elsewhere moves an 8×8 block's by up to 18 %.
    assert!((vg / vc - 1.0).abs() < 0.05, "variance CPU {vc} GPU {vg}");
    assert!(same > 0.8, "{same} of the pixels' variances the same");
    assert!(diff < 0.5, "denoised pictures differ by {diff}/255");
}

/// A small cinematic frame for the denoiser's tests: 8 paths a pixel, 2 scatterings.
fn cinematic(width: u32, height: u32) -> raystream_cpu::dvr::DvrOptions {
    raystream_cpu::dvr::DvrOptions {
        width,
        height,
        mode: raystream_cpu::dvr::DvrMode::Cinematic,
        spp: 8,
        bounces: 2,
        ..Default::default()
    }
}

/// A denoised cinematic frame filters the traced frame where it lies on the GPU: the same
/// light and opacity, bit for bit, as the frame and guides read back and denoised from the
/// host (`GpuDenoiser::denoise`), in one dispatch and in several; put over the background and
/// packed to sRGB there, the host's bytes of that frame within 1/255; the same sample count as
/// the frame without the denoiser, and the filter's times reported. A renderer that keeps its
/// denoising buffers from frame to frame (a smaller frame in a larger one's, then the larger
/// again) gives each frame bit for bit as a new renderer does.
#[test]
fn a_denoised_frame_is_filtered_where_it_was_traced() {
    use raystream_cpu::denoise::DenoiseOptions;
    use raystream_cpu::dvr::{DvrOptions, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let tf = TfPreset::CtBones.function();
    let gd = GpuDenoiser::new(&ctx);
    let mut reused = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    let mut first = None;
    for (w, h, per) in [(64, 48, 0), (61, 45, 3 * 61 * 45)] {
        let opt = DvrOptions {
            denoise: true,
            background: raystream_math::Vec3::new(0.9, 0.5, 0.2),
            ..cinematic(w, h)
        };
        let cam = volume_camera(&vol, w as f32 / h as f32);
        let mut gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
        if per > 0 {
            gpu.paths_per_dispatch = per;
        }
        let (img, alpha, times) = gpu.render_rgba(&opt, &cam).unwrap();
        let (film, film_times) = gpu.render_film(&opt, &cam).unwrap();
        let guides = gpu.guides(&opt, &cam).unwrap();
        let (want, want_alpha) = gd
            .denoise(&ctx, &film, &guides, &DenoiseOptions::default())
            .unwrap();
        assert_eq!((img.width, img.height), (w, h));
        assert!(img.pixels == want.pixels, "{w}x{h}: the light differs");
        assert!(alpha == want_alpha, "{w}x{h}: the opacity differs");
        assert_eq!(times.samples, film_times.samples, "{w}x{h}");
        assert!(times.samples > 0);
        let d = times.denoise.expect("the filter's times");
        assert!(d.filter_ms > 0.0 && d.guides_ms > 0.0 && times.frame_ms >= d.filter_ms);
        // Put over the background and packed to sRGB on the GPU: the bytes of the frame
        // above put over it on the host, within 1/255 where the GPU rounds differently.
        let (rgb, rgb_times) = gpu.render_srgb8(&opt, &cam).unwrap();
        let over = raystream_cpu::dvr::over_background(img, &alpha, opt.background);
        let what = format!("{w}x{h} sRGB");
        let off = srgb8_within_one(&rgb, &over.to_srgb8(), &what);
        assert!(off * 100 <= rgb.len(), "{what}: {off} bytes differ");
        assert_eq!(rgb_times.samples, times.samples, "{what}");
        assert!(rgb_times.denoise.is_some(), "{what}");
        // The renderer that keeps its buffers: the frames above, bit for bit.
        reused.paths_per_dispatch = gpu.paths_per_dispatch;
        let (again, again_alpha, _) = reused.render_rgba(&opt, &cam).unwrap();
        assert!(
            again.pixels == want.pixels,
            "{w}x{h}: the kept buffers' light differs"
        );
        assert!(
            again_alpha == want_alpha,
            "{w}x{h}: the kept buffers' opacity differs"
        );
        assert!(
            reused.render_srgb8(&opt, &cam).unwrap().0 == rgb,
            "{what}: kept buffers"
        );
        first.get_or_insert((opt, cam, rgb));
    }
    // Back to the first, larger frame after the smaller one filled part of its buffers.
    let (opt, cam, rgb) = first.unwrap();
    assert!(
        reused.render_srgb8(&opt, &cam).unwrap().0 == rgb,
        "the first frame again"
    );
}

/// The GPU's denoiser against the CPU's (the reference) on the same noisy abdomen frame and
/// guides: the same light and opacity within 1e-5 (relative, or absolute below 1), with the
/// default settings, without demodulation, with five passes, and on a frame whose size is no
/// multiple of the workgroup's.
#[test]
fn gpu_denoiser_matches_cpu() {
    use raystream_cpu::cinematic::{guides, render_film};
    use raystream_cpu::denoise::{DenoiseOptions, denoise};
    use raystream_cpu::dvr::volume_camera;
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let tf = TfPreset::CtMuscle.function();
    let gd = GpuDenoiser::new(&ctx);
    for (w, h) in [(64, 48), (61, 45)] {
        let opt = cinematic(w, h);
        let cam = volume_camera(&vol, w as f32 / h as f32);
        let (noisy, _) = render_film(&vol, &tf, &opt, &cam);
        let g = guides(&vol, &tf, &opt, &cam);
        for settings in [
            DenoiseOptions::default(),
            DenoiseOptions {
                demodulate: 0.0,
                ..Default::default()
            },
            DenoiseOptions {
                passes: 5,
                ..Default::default()
            },
        ] {
            let (cpu, cpu_alpha) = denoise(&noisy, &g, &settings);
            let (gpu, gpu_alpha) = gd.denoise(&ctx, &noisy, &g, &settings).unwrap();
            let off = |a: f32, b: f32| (a - b).abs() / a.abs().max(b.abs()).max(1.0);
            let worst = cpu
                .pixels
                .iter()
                .zip(&gpu.pixels)
                .map(|(a, b)| (0..3).map(|c| off(a[c], b[c])).fold(0.0, f32::max))
                .chain(cpu_alpha.iter().zip(&gpu_alpha).map(|(a, b)| off(*a, *b)))
                .fold(0.0, f32::max);
            eprintln!("{w}x{h} {settings:?}: worst {worst:.2e}");
            // Measured 4e-7; the variance blur weighed flat puts it 2e-2 off.
            assert!(
                worst < 1e-5,
                "{w}x{h} {settings:?}: GPU off the CPU by {worst}"
            );
        }
    }
}

/// The premultiplied `film` with opacity `alpha`, over `opt`'s background, is `frame`.
fn assert_over_background_is(
    film: &raystream_cpu::Image,
    alpha: &[f32],
    opt: &raystream_cpu::dvr::DvrOptions,
    frame: &raystream_cpu::Image,
    name: &str,
) {
    for ((c, a), want) in film.pixels.iter().zip(alpha).zip(&frame.pixels) {
        let over = *c + (1.0 - a) * opt.background;
        assert!(
            (over - *want).abs().max_element() < 1e-5,
            "{name}: {over} vs {want}"
        );
    }
}

/// GPU volume rendering against the CPU reference on the abdomen CT, every mode, and dvr and
/// iso read by the cubic B-spline: mean absolute difference < 1/255 and the 99th percentile
/// within 8/255 (8-bit sRGB; the GPU samples an f16 texture with hardware filtering).
#[test]
fn gpu_volume_rendering_matches_cpu() {
    use raystream_cpu::dvr::{DvrMode, DvrOptions, Interpolation, render_volume, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let plain = DvrOptions {
        width: 64,
        height: 48,
        ..Default::default()
    };
    let clipped = pelvis_left_half(plain);
    // Read by the cubic B-spline: eight hardware-filtered fetches a value on the GPU, the
    // 4³ voxels summed on the CPU.
    let cubic = DvrOptions {
        interpolation: Interpolation::Cubic,
        ..plain
    };
    // The interpolating spline: the same fetches from the coefficients' texture.
    let sharp = DvrOptions {
        interpolation: Interpolation::CubicInterpolating,
        ..plain
    };
    for (mode, preset, base, what) in [
        (DvrMode::Dvr, TfPreset::CtBones, plain, ""),
        (DvrMode::Dvr, TfPreset::CtMuscle, plain, ""),
        (DvrMode::Mip, TfPreset::MipBone, plain, ""),
        (DvrMode::MinIp, TfPreset::MipBone, plain, ""),
        (DvrMode::Average, TfPreset::MipBone, plain, ""),
        (DvrMode::Iso, TfPreset::CtBone, plain, ""),
        (DvrMode::Slice, TfPreset::CtBone, plain, ""),
        (
            DvrMode::Dvr,
            TfPreset::CtBone,
            DvrOptions {
                shadows: true,
                ..plain
            },
            " shadows",
        ),
        (DvrMode::Dvr, TfPreset::CtBones, clipped, " crop+plane"),
        (DvrMode::Mip, TfPreset::MipBone, clipped, " crop+plane"),
        (DvrMode::Dvr, TfPreset::CtBones, cubic, " cubic"),
        (
            DvrMode::Dvr,
            TfPreset::CtBones,
            sharp,
            " cubic-interpolating",
        ),
        (
            DvrMode::Iso,
            TfPreset::CtBone,
            sharp,
            " cubic-interpolating",
        ),
        (
            DvrMode::Dvr,
            TfPreset::CtMuscle,
            DvrOptions {
                shadows: true,
                ..cubic
            },
            " cubic shadows",
        ),
        (DvrMode::Iso, TfPreset::CtBone, cubic, " cubic"),
        (
            DvrMode::Dvr,
            TfPreset::CtBones,
            pelvis_left_half(cubic),
            " cubic crop+plane",
        ),
    ] {
        let tf = preset.function();
        let opt = DvrOptions { mode, ..base };
        let cam = volume_camera(&vol, 64.0 / 48.0);
        let (cpu, stats) = render_volume(&vol, &tf, &opt, &cam);
        let gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
        let (img, times) = gpu.render(&opt, &cam).unwrap();
        // The same lattice: the same sample count, but for rays that stop (early termination,
        // the iso crossing) a sample apart where f16 texels round differently.
        let (a, b) = (stats.samples as f64, times.samples as f64);
        assert!(
            (a - b).abs() <= 0.01 * a.max(1.0),
            "{} {}{what}: CPU took {a} samples, GPU {b}",
            mode.name(),
            preset.name()
        );
        // The frame as a viewer gets it (sRGB converted on the GPU): the float frame's bytes,
        // up to 1/255 where the GPU's pow rounds differently, and the same sample count.
        let (rgb, packed) = gpu.render_srgb8(&opt, &cam).unwrap();
        let want = img.to_srgb8();
        let name = format!("{} {}{what}", mode.name(), preset.name());
        let off = srgb8_within_one(&rgb, &want, &name);
        assert!(
            off * 100 <= want.len(),
            "{} {}{what}: the GPU's sRGB bytes differ from its float pixels' in {off} of {}",
            mode.name(),
            preset.name(),
            want.len()
        );
        assert_eq!(packed.samples, times.samples, "{}{what}", mode.name());
        // Premultiplied RGBA in one pass (no background): over the background it is the
        // frame above, and its opacity is the CPU's.
        let (film, alpha, rgba_times) = gpu.render_rgba(&opt, &cam).unwrap();
        assert_eq!(rgba_times.samples, times.samples, "{name}");
        assert_over_background_is(&film, &alpha, &opt, &img, &name);
        if mode != DvrMode::Dvr {
            for a in &alpha {
                assert!(*a == 0.0 || *a == 1.0, "{name}: opaque or clear, not {a}");
            }
        }
        let (_, cpu_alpha, _) = raystream_cpu::dvr::render_volume_rgba(&vol, &tf, &opt, &cam);
        assert_opacity_close(&alpha, &cpu_alpha, &name);
        let (mean, mut worst) = cpu.srgb8_diff(&img);
        worst.sort_unstable();
        let p99 = worst[worst.len() * 99 / 100];
        let what = format!("{} {}{what}", mode.name(), preset.name());
        eprintln!("{what}: mean {mean:.3}/255, p99 {p99}/255");
        assert!(
            mean < 1.0 && p99 <= 8,
            "{what}: GPU vs CPU mean {mean}/255, p99 {p99}/255"
        );
    }
}

/// mip, minip and average of the abdomen kept to its bones (voxels over 200 HU; the rest 0,
/// their weights 0) on the GPU (dvr.wgsl's kept samples, both channels of one texture
/// filtered alike) against the CPU's (`CpuVolume::kept`), trilinear, cubic and interpolating:
/// the same rays miss (all but 1 %), the others within 4 HU on average, every value within
/// the bones' range (the interpolating spline's, which overshoots, within a tenth of it beyond);
/// and with every bone voxel 500 HU, every ray that meets them is 500 — no hidden voxel's
/// value blends in at their edge. Skipping the bricks outside the bones changes no pixel.
#[test]
fn gpu_kept_projections_match_cpu() {
    use raystream_cpu::dvr::{CpuVolume, DvrMode, DvrOptions, Interpolation, volume_camera};
    let Some(ctx) = gpu() else { return };
    let ct = abdomen_ct();
    let bone = |v: f32| v > 200.0;
    let like = |data: Vec<f32>| raystream_io::Volume {
        origin: ct.origin,
        direction: ct.direction,
        ..raystream_io::Volume::hounsfield(ct.dims, ct.spacing, data)
    };
    let weights = like(ct.data.iter().map(|&v| bone(v) as u8 as f32).collect());
    let kept = like(
        ct.data
            .iter()
            .map(|&v| if bone(v) { v } else { 0.0 })
            .collect(),
    );
    let flat = like(
        ct.data
            .iter()
            .map(|&v| if bone(v) { 500.0 } else { 0.0 })
            .collect(),
    );
    let (lo, hi) = ct
        .data
        .iter()
        .filter(|&&v| bone(v))
        .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let tf = raystream_volume::TfPreset::MipBone.function();
    let cam = volume_camera(&ct, 64.0 / 48.0);
    for interpolation in [
        Interpolation::Linear,
        Interpolation::Cubic,
        Interpolation::CubicInterpolating,
    ] {
        for mode in [DvrMode::Mip, DvrMode::MinIp, DvrMode::Average] {
            let opt = DvrOptions {
                width: 64,
                height: 48,
                mode,
                interpolation,
                hu_values: true,
                ..Default::default()
            };
            let name = format!("{} {interpolation:?}", mode.name());
            let (cpu, _) = CpuVolume::new(&kept, &tf)
                .kept(Some(&weights))
                .render(&opt, &cam);
            let gpu = GpuVolumeRenderer::segmented(&ctx, &kept, &tf, None, Some(&weights)).unwrap();
            let (img, _) = gpu.render(&opt, &cam).unwrap();
            // The bricks outside the bones skipped (`kept_brick_table`), or not: the same
            // pixels, bit for bit.
            let every = DvrOptions {
                skip_empty: false,
                ..opt
            };
            let (all, _) = gpu.render(&every, &cam).unwrap();
            let differ = (img.pixels.iter().zip(&all.pixels))
                .filter(|(a, b)| a.x.to_bits() != b.x.to_bits())
                .count();
            assert_eq!(differ, 0, "{name}: skipping changed {differ} pixels");
            let (mut both, mut one, mut diff) = (0, 0, 0.0f64);
            // The interpolating spline overshoots between voxels, past their range.
            let reach = if interpolation.prefiltered() {
                0.1 * (hi - lo)
            } else {
                4.0
            };
            for (c, g) in cpu.pixels.iter().zip(&img.pixels) {
                match (c.x.is_nan(), g.x.is_nan()) {
                    (false, false) => {
                        both += 1;
                        diff += (c.x - g.x).abs() as f64;
                        assert!(
                            (lo - reach..=hi + reach).contains(&g.x),
                            "{name}: {} HU outside the bones' {lo}..{hi}",
                            g.x
                        );
                    }
                    (true, true) => {}
                    _ => one += 1,
                }
            }
            let mean = diff / both.max(1) as f64;
            eprintln!("{name}: {both} pixels on both, {one} on one, mean difference {mean:.2} HU");
            assert!(
                both > 300 && one * 100 <= both,
                "{name}: {both} on both, {one} on one"
            );
            assert!(mean < 4.0, "{name}: GPU against CPU: {mean} HU");
            // The interpolating spline rings at the block's edge, but its values' and its
            // weights' alike (its prefilter is linear): only their half floats round apart.
            let gpu = GpuVolumeRenderer::segmented(&ctx, &flat, &tf, None, Some(&weights)).unwrap();
            let (img, _) = gpu.render(&opt, &cam).unwrap();
            let tol = if interpolation.prefiltered() {
                2.0
            } else {
                0.5
            };
            for g in img.pixels.iter().filter(|g| !g.x.is_nan()) {
                assert!((g.x - 500.0).abs() <= tol, "{name}: {} HU through 500", g.x);
            }
        }
    }
}

/// The GPU's opacities `gpu` within 0.01 of the CPU's `cpu` on average.
fn assert_opacity_close(gpu: &[f32], cpu: &[f32], name: &str) {
    let da = gpu.iter().zip(cpu).map(|(g, c)| (g - c).abs()).sum::<f32>();
    assert!(
        da < 0.01 * gpu.len() as f32,
        "{name}: opacity off by {da} in all"
    );
}

/// A segmentation's colours on the GPU (dvr.wgsl's `painted`) against the CPU's, on the
/// abdomen: the patient's right red, the left blue, the densest bone (over 1000 HU) of a
/// third label given no colour (the transfer function's shows there). dvr (trilinear and
/// cubic), iso and cinematic (32 paths) frames within the tolerances of the unpainted ones
/// (`gpu_volume_rendering_matches_cpu`, `gpu_cinematic_rendering_matches_cpu`), their opacity
/// the unpainted frame's on the same device, and the denoiser's guides' colour the CPU's;
/// and the colours show: the image's left half redder than its right.
#[test]
fn gpu_segment_colours_match_cpu() {
    use raystream_cpu::dvr::{CpuVolume, DvrMode, DvrOptions, Interpolation, volume_camera};
    use raystream_cpu::segments::SegmentColours;
    use raystream_volume::TfPreset;
    use std::sync::atomic::AtomicU64;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let [nx, ..] = vol.dims;
    let lps_x = |i: usize| vol.index_to_world(raystream_math::DVec3::X * i as f64).x;
    let middle = 0.5 * (lps_x(0) + lps_x(nx - 1));
    let labels = vol
        .data
        .iter()
        .enumerate()
        .map(|(i, &hu)| match hu {
            hu if hu > 1000.0 => 3,
            _ => 1 + (lps_x(i % nx) > middle) as u16,
        })
        .collect();
    let segments = SegmentColours::new(vol.dims, labels, &[(1, Vec3::X), (2, Vec3::Z)]);
    let nothing = SegmentColours::new(vol.dims, vec![0; vol.data.len()], &[(1, Vec3::X)]);
    let plain = DvrOptions {
        width: 64,
        height: 48,
        ..Default::default()
    };
    let cam = volume_camera(&vol, 64.0 / 48.0);
    for (mode, preset, interpolation) in [
        (DvrMode::Dvr, TfPreset::CtBones, Interpolation::Linear),
        (DvrMode::Dvr, TfPreset::CtMuscle, Interpolation::Cubic),
        (DvrMode::Iso, TfPreset::CtBone, Interpolation::Linear),
        (DvrMode::Cinematic, TfPreset::CtBones, Interpolation::Linear),
    ] {
        let opt = DvrOptions {
            mode,
            interpolation,
            spp: 32,
            bounces: 3,
            ..plain
        };
        let name = format!("{} {} {interpolation:?}", mode.name(), preset.name());
        let tf = preset.function();
        let done = AtomicU64::new(0);
        let cpu = CpuVolume::new(&vol, &tf).painted(Some(&segments));
        let (film, cpu_alpha, _) = cpu.render_rgba_counted(&opt, &cam, &done);
        let gpu = GpuVolumeRenderer::painted(&ctx, &vol, &tf, Some(&segments)).unwrap();
        let (gpu_film, alpha, _) = gpu.render_rgba(&opt, &cam).unwrap();
        let unpainted = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
        let (plain_film, plain_alpha, _) = unpainted.render_rgba(&opt, &cam).unwrap();
        if mode != DvrMode::Cinematic {
            assert_eq!(
                alpha, plain_alpha,
                "{name}: the opacity is the unpainted frame's"
            );
        }
        // No voxel of a segment: the unpainted frame bit for bit.
        let none = GpuVolumeRenderer::painted(&ctx, &vol, &tf, Some(&nothing)).unwrap();
        let (same, same_alpha, _) = none.render_rgba(&opt, &cam).unwrap();
        assert!(
            same.pixels == plain_film.pixels && same_alpha == plain_alpha,
            "{name}: no segment, no change"
        );
        assert_opacity_close(&alpha, &cpu_alpha, &name);
        let over = |film: &raystream_cpu::Image, alpha: &[f32]| {
            raystream_cpu::dvr::over_background(film.clone(), alpha, opt.background)
        };
        let (c, g) = (over(&film, &cpu_alpha), over(&gpu_film, &alpha));
        let (mean, mut worst) = c.srgb8_diff(&g);
        worst.sort_unstable();
        let p99 = worst[worst.len() * 99 / 100];
        let close = worst.iter().filter(|&&d| d <= 2).count() as f64 / worst.len() as f64;
        eprintln!(
            "{name}: mean {mean:.3}/255, p99 {p99}/255, {:.1} % within 2/255",
            100.0 * close
        );
        if mode == DvrMode::Cinematic {
            assert!(mean < 1.0 && close >= 0.85, "{name}: {mean}/255, {close}");
        } else {
            assert!(mean < 1.0 && p99 <= 8, "{name}: {mean}/255, p99 {p99}/255");
        }
        // Red on the image's left (the patient's right), blue on its right.
        let side = |right: bool| {
            g.pixels
                .iter()
                .enumerate()
                .filter(|(i, _)| (i % 64 >= 32) == right)
                .fold(Vec3::ZERO, |s, (_, p)| s + *p)
        };
        let (l, r) = (side(false), side(true));
        assert!(l.x / l.z > 1.5 * r.x / r.z, "{name}: left {l}, right {r}");
    }
    // The denoiser's guides carry the colours too.
    let opt = DvrOptions {
        mode: DvrMode::Cinematic,
        ..plain
    };
    let tf = TfPreset::CtBones.function();
    let gpu = GpuVolumeRenderer::painted(&ctx, &vol, &tf, Some(&segments)).unwrap();
    let got = gpu.guides(&opt, &cam).unwrap();
    let want = raystream_cpu::cinematic::guides_painted(&vol, &tf, &opt, &cam, Some(&segments));
    let off = got
        .albedo
        .iter()
        .zip(&want.albedo)
        .filter(|(g, w)| (**g - **w).abs().max_element() > 0.02)
        .count();
    let red = want
        .albedo
        .iter()
        .filter(|a| a.x > 2.0 * a.z + 0.01)
        .count();
    assert!(
        off * 50 <= want.albedo.len() && red > 50,
        "{off} guides off, {red} red"
    );
}

/// One GPU renderer draws frames read any way, in any order (each interpolation has its own
/// brick table and majorants, and the interpolating spline its coefficients' texture): dvr
/// and cinematic frames, trilinear, cubic, interpolating cubic and trilinear again, each the
/// same bit for bit as a fresh renderer's.
#[test]
fn one_gpu_renderer_draws_either_interpolation() {
    use raystream_cpu::dvr::{DvrMode, DvrOptions, Interpolation, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let vol = abdomen_ct();
    let tf = TfPreset::CtBones.function();
    let cam = volume_camera(&vol, 48.0 / 32.0);
    let shared = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    for mode in [DvrMode::Dvr, DvrMode::Cinematic] {
        for interpolation in [
            Interpolation::Linear,
            Interpolation::Cubic,
            Interpolation::CubicInterpolating,
            Interpolation::Linear,
        ] {
            let opt = DvrOptions {
                width: 48,
                height: 32,
                mode,
                spp: 4,
                interpolation,
                ..Default::default()
            };
            let fresh = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
            let (want, want_times) = fresh.render(&opt, &cam).unwrap();
            let (got, got_times) = shared.render(&opt, &cam).unwrap();
            assert_eq!(got.pixels, want.pixels, "{mode:?} {interpolation:?}");
            assert_eq!(
                got_times.samples, want_times.samples,
                "{mode:?} {interpolation:?}"
            );
        }
    }
}

/// The windowed modes' HU values (`hu_values`, for EXR: the projections and a slice) on the
/// GPU against the CPU's on the abdomen CT, whole, cropped and read by the cubic B-spline: the same rays take no sample (NaN); the values within 4 HU
/// for 99 % of pixels and 16 HU for all (the GPU samples a half-float texture, exact to 1 HU
/// below 2048 HU and 2 HU above, with hardware filter weights).
#[test]
fn gpu_projections_give_the_cpus_hounsfield_units() {
    use raystream_cpu::dvr::{DvrMode, DvrOptions, render_volume, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    let vol = raystream_io::load_volume(&path, &Default::default()).unwrap();
    let tf = TfPreset::MipBone.function();
    let gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    let cam = volume_camera(&vol, 64.0 / 48.0);
    let plain = DvrOptions {
        width: 64,
        height: 48,
        hu_values: true,
        ..Default::default()
    };
    let cropped = DvrOptions {
        crop: Some([
            Vec3::new(-250.0, -400.0, -400.0),
            Vec3::new(60.0, 400.0, 400.0),
        ]),
        ..plain
    };
    // The cubic B-splines' values: eight filtered fetches a sample on the GPU, of the HU or
    // of the interpolating spline's coefficients (f16 too).
    let cubic = DvrOptions {
        interpolation: raystream_cpu::dvr::Interpolation::Cubic,
        ..plain
    };
    let sharp = DvrOptions {
        interpolation: raystream_cpu::dvr::Interpolation::CubicInterpolating,
        ..plain
    };
    for (base, what) in [
        (plain, ""),
        (cropped, " cropped"),
        (cubic, " cubic"),
        (sharp, " cubic-interpolating"),
    ] {
        for mode in [
            DvrMode::Mip,
            DvrMode::MinIp,
            DvrMode::Average,
            DvrMode::Slice,
        ] {
            let opt = DvrOptions { mode, ..base };
            let name = format!("{}{what}", mode.name());
            let (cpu, _) = render_volume(&vol, &tf, &opt, &cam);
            let (img, _) = gpu.render(&opt, &cam).unwrap();
            let mut diffs = Vec::new();
            for (c, g) in cpu.pixels.iter().zip(&img.pixels) {
                assert_eq!(
                    c.x.is_nan(),
                    g.x.is_nan(),
                    "{name}: a miss on one device only"
                );
                if !c.x.is_nan() {
                    assert!(g.x == g.y && g.y == g.z, "{name}: one value a pixel");
                    diffs.push((c.x - g.x).abs());
                }
            }
            assert!(
                diffs.len() > 64 * 48 / 10,
                "{name}: {} sampled",
                diffs.len()
            );
            diffs.sort_by(f32::total_cmp);
            let (p99, max) = (diffs[diffs.len() * 99 / 100], diffs[diffs.len() - 1]);
            eprintln!("{name}: GPU vs CPU p99 {p99} HU, max {max} HU");
            assert!(
                p99 <= 4.0 && max <= 16.0,
                "{name}: p99 {p99} HU, max {max} HU"
            );
        }
    }
}

/// The GPU's sRGB frame packs 4 pixels in 3 words: an image whose pixel count is not a
/// multiple of 4 keeps its last pixels, and matches the float frame's bytes.
#[test]
fn gpu_srgb8_frames_of_any_size() {
    use raystream_cpu::dvr::{DvrOptions, volume_camera};
    use raystream_volume::TfPreset;
    let Some(ctx) = gpu() else { return };
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../raystream/assets/abdomen_pelvis_ct_totalseg.nii.gz");
    let vol = raystream_io::load_volume(&path, &Default::default()).unwrap();
    let tf = TfPreset::CtBones.function();
    let gpu = GpuVolumeRenderer::new(&ctx, &vol, &tf).unwrap();
    for (w, h) in [(13, 7), (31, 9), (2, 1)] {
        let opt = DvrOptions {
            width: w,
            height: h,
            ..Default::default()
        };
        let cam = volume_camera(&vol, w as f32 / h as f32);
        let (img, t) = gpu.render(&opt, &cam).unwrap();
        let (rgb, t8) = gpu.render_srgb8(&opt, &cam).unwrap();
        srgb8_within_one(&rgb, &img.to_srgb8(), &format!("{w}x{h}"));
        assert_eq!(t8.samples, t.samples, "{w}x{h}");
    }
}

/// Bytes the GPU converted to sRGB against its float frame's: the same length, each within
/// 1/255 (f32 scaling and the GPU's pow round differently). Returns how many differ.
fn srgb8_within_one(got: &[u8], want: &[u8], what: &str) -> usize {
    assert_eq!(got.len(), want.len(), "{what}");
    assert!(
        got.iter().zip(want).all(|(a, b)| a.abs_diff(*b) <= 1),
        "{what}: sRGB bytes differ from the float frame's by more than 1/255"
    );
    got.iter().zip(want).filter(|(a, b)| a != b).count()
}

/// A scene all of glass (a sphere on a glass floor): every hit spawns a reflection and a
/// refraction, so the queues may double depth by depth. Where they outgrow a binding (lavapipe's
/// 128 MiB, from a 2^20-sample wave at the third depth) the frame starts again in smaller
/// waves, and the image is the one rendered in small waves from the start.
#[test]
fn queues_past_a_binding_render_again_in_smaller_waves() {
    let Some(ctx) = gpu() else { return };
    let mut scene =
        raystream_scene::Scene::for_mesh(TriMesh::icosphere(3), Path::new("glass.obj")).unwrap();
    for m in &mut scene.materials {
        m.transparency = 0.9;
        m.reflectivity = 0.05;
        m.fresnel = true;
    }
    let opt = raystream_cpu::RenderOptions {
        width: 1024,
        height: 1024,
        spp: 1,
        max_depth: 2,
        traversal: Traversal::Ropes,
    };
    let tree = KdTree::build(&scene.mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    assert_eq!(renderer.submit_for(&opt), Submit::Depth);
    let (image, stats) = renderer.render(&opt, |_| {}).unwrap();
    let rays = stats.depths[2].rays as u64;
    let ray_bytes = std::mem::size_of::<crate::layout::RayWork>() as u64;
    eprintln!(
        "{} waves, depth 2: {rays} rays (the next queue needs {} MB at one wave)",
        stats.waves,
        (2 * rays * ray_bytes) >> 20
    );
    if 2 * rays * ray_bytes > ctx.max_binding() {
        assert!(stats.waves > 1, "{} waves", stats.waves);
    }
    let small = GpuRenderer::new(&tracer, &scene, &tree)
        .unwrap()
        .with_wave(1 << 17);
    let (want, _) = small.render(&opt, |_| {}).unwrap();
    assert!(image == want, "the frame rendered again differs");
}

/// A GPU error outside every error scope (a buffer both mappable for reading and for writing)
/// does not panic, as wgpu's default handler would: the next wait fails with it, as do the
/// ones after. Out of memory for an upload (injected here) is an error naming the buffer.
#[test]
fn uncaught_gpu_errors_and_full_memory_are_errors() {
    let Some(ctx) = gpu() else { return };
    let tree = KdTree::build(&TriMesh::icosphere(1), Builder::Sah);
    *ctx.fail_alloc.lock().unwrap() = vec![("kd triangles", 0)];
    let e = GpuTracer::new(&ctx, &tree).err().unwrap().to_string();
    assert!(e.contains("out of memory for kd triangles ("), "{e}");
    assert!(ctx.wait().is_ok());
    let _bad = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("both ways"),
        size: 16,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::MAP_WRITE,
        mapped_at_creation: false,
    });
    for _ in 0..2 {
        let e = ctx.wait().unwrap_err().to_string();
        assert!(
            e.contains("an earlier GPU error") && e.contains("both ways"),
            "{e}"
        );
    }
}

/// A device without the memory for a wave's queues renders the frame again in waves half as
/// large (here the ray queue and then the shadow queue fail while they are as large as the whole
/// frame's or half of it): the same image as in one wave, in four. Out of memory for the film,
/// which no wave size shrinks, is an error that names it.
#[test]
fn a_wave_out_of_memory_renders_again_in_halves() {
    let Some(ctx) = gpu() else { return };
    let scene =
        raystream_scene::Scene::for_mesh(TriMesh::icosphere(2), Path::new("ball.obj")).unwrap();
    let opt = raystream_cpu::RenderOptions {
        width: 40,
        height: 30,
        spp: 2,
        max_depth: 2,
        traversal: Traversal::Ropes,
    };
    let samples = 40 * 30 * 2;
    let ray_bytes = std::mem::size_of::<crate::layout::RayWork>() as u64;
    let tree = KdTree::build(&scene.mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    let (whole, one) = renderer.render(&opt, |_| {}).unwrap();
    assert_eq!(one.waves, 1);
    // One wave of all samples, then one of half: both fail; a quarter of the frame fits.
    let lights = scene.lights.len().max(1) as u64;
    *ctx.fail_alloc.lock().unwrap() = vec![
        ("ray queue", samples * ray_bytes),
        ("shadow queue", samples / 2 * lights * ray_bytes),
    ];
    let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    let (halved, stats) = renderer.render(&opt, |_| {}).unwrap();
    assert!(
        ctx.fail_alloc.lock().unwrap().is_empty(),
        "both failures were met"
    );
    assert_eq!(stats.waves, 4, "waves of a quarter of the frame");
    assert!(halved == whole, "the frame in smaller waves differs");
    // The film does not shrink with the wave: its failure is the frame's.
    *ctx.fail_alloc.lock().unwrap() = vec![("film", 0)];
    let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    let e = renderer.render(&opt, |_| {}).unwrap_err().to_string();
    assert!(e.contains("out of memory for film ("), "{e}");
}

/// `GpuRenderer::set_view`: the frame after it is, bit for bit, the frame of a renderer over
/// the scene with that view and those lights; a view with another number of lights is refused.
#[test]
fn a_view_set_renders_as_a_scene_with_it() {
    let Some(ctx) = gpu() else { return };
    let mut scene =
        raystream_scene::Scene::for_mesh(TriMesh::icosphere(2), Path::new("ball.obj")).unwrap();
    let opt = raystream_cpu::RenderOptions {
        width: 48,
        height: 32,
        spp: 1,
        max_depth: 2,
        traversal: Traversal::Ropes,
    };
    let tree = KdTree::build(&scene.mesh, Builder::Sah);
    let tracer = GpuTracer::new(&ctx, &tree).unwrap();
    let view = scene.frame_view.orbit(100.0, 20.0);
    let cam = scene.framing_camera(view, 1.5);
    let lights: Vec<raystream_scene::Light> = scene
        .lights
        .iter()
        .map(|l| raystream_scene::Light {
            position: l.position + Vec3::new(3.0, -1.0, 2.0),
            ..*l
        })
        .collect();
    let (front, turned) = {
        let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
        let (front, _) = renderer.render(&opt, |_| {}).unwrap();
        assert!(renderer.set_view(cam, &lights[..lights.len() - 1]).is_err());
        renderer.set_view(cam, &lights).unwrap();
        let (turned, _) = renderer.render(&opt, |_| {}).unwrap();
        (front, turned)
    };
    scene.frame_view = view;
    scene.lights = lights;
    let renderer = GpuRenderer::new(&tracer, &scene, &tree).unwrap();
    let (want, _) = renderer.render(&opt, |_| {}).unwrap();
    assert!(turned == want, "the view set differs from the scene's");
    assert!(turned != front, "the view did not change the frame");
}

/// A query whose kernel is invalid (here one that failed to compile, as a driver may fail one)
/// reports the kernel's error, the cause, and not what followed from it: the split query
/// reported only that its wait for a submission failed ("a submission index that has not been
/// returned by a successful submission"). A scoped piece of work that failed on its own keeps
/// its own error where the scope caught none.
#[test]
fn an_invalid_kernel_is_the_error_reported() {
    let Some(mut ctx) = gpu() else { return };
    let tree = KdTree::build(&TriMesh::icosphere(1), Builder::Sah);
    let rays = [Ray::new(
        Vec3::new(0.0, 0.0, 5.0),
        Vec3::new(0.0, 0.0, -1.0),
        0.0,
        f32::INFINITY,
    )];
    for timestamps in [true, false] {
        ctx.set_timestamps(timestamps);
        let mut tracer = GpuTracer::new(&ctx, &tree).unwrap();
        let want = tracer.trace(&rays, false).unwrap().0[0];
        assert_ne!(want.prim, NO_PRIM);
        assert_eq!(
            tracer.trace_with(&rays, false, Kernels::Split).unwrap().0[0],
            want
        );
        // A kernel that failed to compile, in the fused and the split query.
        let broken = |entry: &str| {
            let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
            let module = ctx
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("broken.wgsl"),
                    source: wgpu::ShaderSource::Wgsl(
                        format!("@compute @workgroup_size(1) fn {entry}() {{ let x: u32 = 1.5; }}")
                            .into(),
                    ),
                });
            let pipeline = ctx.auto_pipeline(&module, entry);
            assert!(pollster::block_on(scope.pop()).is_some());
            pipeline
        };
        // One at a time: the split query binds the fused kernel's layout too.
        let closest = std::mem::replace(&mut tracer.closest, broken("intersect_closest"));
        let e = tracer.trace(&rays, false).err().unwrap().to_string();
        assert!(
            e.contains("'intersect_closest' label is invalid") && !e.contains("submission index"),
            "{e}"
        );
        tracer.closest = closest;
        let split = tracer.split.get_mut().unwrap();
        let traverse = std::mem::replace(&mut split.traverse, broken("split_traverse"));
        let e = tracer
            .trace_with(&rays, false, Kernels::Split)
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("'split_traverse' label is invalid") && !e.contains("submission index"),
            "{e}"
        );
        tracer.split.get_mut().unwrap().traverse = traverse;
        // The context stays usable: the errors were the queries'.
        assert_eq!(tracer.trace(&rays, false).unwrap().0[0], want);
        assert_eq!(
            tracer.trace_with(&rays, false, Kernels::Split).unwrap().0[0],
            want
        );
    }
    let own = ctx.scoped(|| -> Result<(), GpuError> { Err(ctx.err("the work's own failure")) });
    assert!(
        own.unwrap_err()
            .to_string()
            .contains("the work's own failure")
    );
    assert_eq!(ctx.scoped(|| Ok(7)).unwrap(), 7);
}
