//! `render -o OUT.exr`: the float values behind a picture. The shaded film before its sRGB
//! curve and 8-bit rounding, AOVs' distances, normals and triangle numbers, and the intensity
//! projections' Hounsfield units before the window. Each is checked against the PNG of the
//! same render (the PNG must follow from the EXR), against values known from the input, and
//! the GPU's against the CPU's.

mod common;
use std::path::Path;

use common::*;
use raystream_cpu::{ExrFile, Image};
use raystream_math::Vec3;

/// An EXR file that `render` wrote.
fn read_exr(path: &Path) -> ExrFile {
    raystream_cpu::load_exr(path).unwrap()
}

/// A float channel's samples.
fn floats<'a>(e: &'a ExrFile, name: &str) -> &'a [f32] {
    e.channels[name].as_f32().expect("a float channel")
}

/// The film of an EXR's R, G, B channels.
fn film(e: &ExrFile) -> Image {
    let (r, g, b) = (floats(e, "R"), floats(e, "G"), floats(e, "B"));
    Image {
        width: e.width,
        height: e.height,
        pixels: (0..r.len()).map(|i| Vec3::new(r[i], g[i], b[i])).collect(),
    }
}

/// A shaded frame's EXR is the film the PNG is made from: the PNG's bytes follow from it
/// exactly, and it keeps a highlight above 1 that the PNG clamps. The GPU's film is the
/// CPU's (mean difference < 0.5/255 once encoded, as the PNGs are checked).
#[test]
fn exr_holds_the_film_behind_the_png() {
    let spot = repo().join("crates/raystream/tests/scenes/spot.toml");
    let args = [spot.to_str().unwrap(), "--size", "64x48", "--spp", "2"];
    let mut films = Vec::new();
    for dev in devices() {
        let png = render_to(&format!("exr-spot-{dev}.png"), dev, &args);
        let exr = read_exr(&render_to(&format!("exr-spot-{dev}.exr"), dev, &args));
        assert_eq!((exr.width, exr.height), (64, 48));
        assert_eq!(exr.channels.len(), 3, "R, G, B");
        assert!(
            exr.comments.contains("linear RGB, 2 spp"),
            "{}",
            exr.comments
        );
        let f = film(&exr);
        assert_eq!(
            f.to_srgb8(),
            image::open(&png).unwrap().to_rgb8().into_raw(),
            "{dev}: the PNG is the EXR's film encoded"
        );
        let over = f.pixels.iter().filter(|p| p.max_element() > 1.0).count();
        assert!(over > 0, "{dev}: a highlight above 1 kept");
        assert!(
            f.pixels
                .iter()
                .all(|p| p.is_finite() && p.min_element() >= 0.0)
        );
        films.push(f);
    }
    if let [cpu, gpu] = &films[..] {
        let (mean, _) = cpu.srgb8_diff(gpu);
        assert!(mean < 0.5, "GPU film differs by {mean:.3}/255");
    }
}

/// AOVs as EXR hold the values the PNGs quantize: distances (+∞ where the PNG is 0), the unit
/// normal, the triangle's number; the GPU's equal the CPU's but at ties on shared edges.
#[test]
fn exr_aovs_hold_distances_normals_and_triangles() {
    let bunny = mesh("stanford_bunny.ply");
    // The bunny's 69,451 and the ground's two.
    let triangles = 69_453;
    let size = ["--size", "96x72"];
    let mut by_dev = Vec::new();
    for dev in devices() {
        let aov = |kind: &str, ext: &str| {
            let args = [&bunny[..], "--aov", kind, size[0], size[1]];
            render_to(&format!("exr-aov-{kind}-{dev}.{ext}"), dev, &args)
        };
        let depth = read_exr(&aov("depth", "exr"));
        let z = floats(&depth, "Z").to_vec();
        assert!(depth.comments.contains("distance from the eye"));
        let grey = image::open(aov("depth", "png")).unwrap().to_luma16();
        let hits: Vec<f32> = z.iter().copied().filter(|d| d.is_finite()).collect();
        assert!(hits.len() > z.len() / 4, "{dev}: {} hits", hits.len());
        let (near, far) = hits
            .iter()
            .fold((f32::MAX, 0.0f32), |(n, f), &d| (n.min(d), f.max(d)));
        for (d, &g) in z.iter().zip(grey.as_raw()) {
            if d.is_finite() {
                assert!(*d > 0.0);
                let level = 1.0 + 65534.0 * (far - d) / (far - near);
                assert!((level - g as f32).abs() <= 1.0, "{dev}: {d} is grey {g}");
            } else {
                assert_eq!((*d, g), (f32::INFINITY, 0), "{dev}: a miss");
            }
        }

        let normal = read_exr(&aov("normal", "exr"));
        let n: Vec<Vec3> = {
            let c = |name: &str| floats(&normal, name).to_vec();
            let (x, y, zz) = (c("N.X"), c("N.Y"), c("N.Z"));
            (0..x.len()).map(|i| Vec3::new(x[i], y[i], zz[i])).collect()
        };
        let rgb = image::open(aov("normal", "png")).unwrap().to_rgb8();
        for (i, (v, p)) in n.iter().zip(rgb.pixels()).enumerate() {
            if z[i].is_finite() {
                assert!(
                    (v.length() - 1.0).abs() < 1e-4,
                    "{dev}: normal {v} not unit"
                );
                let want = (*v * 127.0 + Vec3::splat(128.0)).round();
                assert_eq!(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32), want);
            } else {
                assert_eq!((*v, p.0), (Vec3::ZERO, [0; 3]), "{dev}: a miss");
            }
        }

        let prim = read_exr(&aov("prim", "exr"));
        let prims = prim.channels["prim"]
            .as_u32()
            .expect("triangle numbers are 32-bit integers");
        for (&p, d) in prims.iter().zip(&z) {
            assert_eq!(p == u32::MAX, !d.is_finite(), "{dev}: a miss in both");
            assert!(p == u32::MAX || p < triangles, "{dev}: triangle {p}");
        }
        let distinct: std::collections::BTreeSet<u32> = prims.iter().copied().collect();
        assert!(
            distinct.len() > 1000,
            "{dev}: {} triangles seen",
            distinct.len()
        );
        by_dev.push((z, n, prims.to_vec()));
    }
    if let [(zc, nc, pc), (zg, ng, pg)] = &by_dev[..] {
        let off = (0..zc.len())
            .filter(|&i| {
                pc[i] != pg[i]
                    || (zc[i] - zg[i]).abs() > 1e-5 * zc[i]
                    || (nc[i] - ng[i]).length() > 1e-5
            })
            .count();
        assert!(off * 1000 <= zc.len(), "{off} pixels differ, GPU to CPU");
    }
}

/// A MetaImage of `dims` voxels of `spacing` mm from `origin` (LPS, axis-aligned), each
/// voxel's value `f` of its centre's position (LPS mm), as 32-bit floats.
fn metaimage(
    name: &str,
    dims: [usize; 3],
    spacing: [f32; 3],
    origin: [f32; 3],
    f: impl Fn([f32; 3]) -> f32,
) -> std::path::PathBuf {
    let [nx, ny, nz] = dims;
    let mut bytes = format!(
        "ObjectType = Image\nNDims = 3\nDimSize = {nx} {ny} {nz}\nElementSpacing = {} {} {}\nOffset = {} {} {}\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nElementType = MET_FLOAT\nElementByteOrderMSB = False\nElementDataFile = LOCAL\n",
        spacing[0], spacing[1], spacing[2], origin[0], origin[1], origin[2]
    )
    .into_bytes();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let p = [i, j, k].map(|n| n as f32);
                let at = std::array::from_fn(|a| origin[a] + p[a] * spacing[a]);
                bytes.extend_from_slice(&f(at).to_le_bytes());
            }
        }
    }
    // Tests running at once write the same volume: each writes its own copy and renames it
    // into place, so that none reads a file another is still writing.
    let path = tmp(name);
    let part = tmp(&format!("{name}.{:?}.part", std::thread::current().id()));
    std::fs::write(&part, bytes).unwrap();
    std::fs::rename(&part, &path).unwrap();
    path
}

/// A 40 mm cube of air (−1000 HU) holding a block of bone (1000 HU), 10 × 30 × 10 mm: voxels
/// 1 mm, the block at x 10..20, y (posterior) 5..35, z 15..25.
fn block_volume() -> std::path::PathBuf {
    metaimage("exr-block.mha", [40; 3], [1.0; 3], [0.0; 3], |[x, y, z]| {
        let inside =
            (10.0..20.0).contains(&x) && (5.0..35.0).contains(&y) && (15.0..25.0).contains(&z);
        if inside { 1000.0 } else { -1000.0 }
    })
}

/// The pixel size ("pixels S mm square") an EXR's comments give.
fn pixel_mm(e: &ExrFile) -> f32 {
    e.comments
        .split("pixels ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no pixel size in '{}'", e.comments))
}

/// `--mode slice` shows the plane through `--slice-at` as radiology shows slices, with the
/// values themselves in the EXR. A grid whose voxels hold one coordinate of their position
/// (LPS mm: x to the patient's left, y posterior, z superior) gives, pixel by pixel:
/// - axial (`--view inferior`): z is the plane's height everywhere, and x grows left to right
///   by one pixel's size a column (the patient's right on the image's left);
/// - coronal (`--view anterior`): y is the plane's depth, z falls down the image;
/// - sagittal (`--view left`): x is the plane's offset, y grows left to right (anterior on
///   the left).
///
/// The GPU's values equal the CPU's (within a half-float's rounding).
#[test]
fn slices_show_the_plane_as_radiology_does() {
    let (dims, spacing, origin) = ([36, 30, 24], [0.9, 1.1, 1.5], [-20.0, -10.0, 40.0]);
    let grids = ["x", "y", "z"].map(|axis| {
        let a = ["x", "y", "z"].iter().position(|&n| n == axis).unwrap();
        metaimage(
            &format!("exr-slice-{axis}.mha"),
            dims,
            spacing,
            origin,
            move |p| p[a],
        )
    });
    let at = [-4.0f32, 3.5, 55.25];
    let at_arg = format!("{},{},{}", at[0], at[1], at[2]);
    // (view, constant axis, axis along the rows (+1: grows to the right), axis down the
    // columns (+1: grows downwards))
    let cases = [
        ("inferior", 2, (0, 1.0), (1, 1.0)),
        ("anterior", 1, (0, 1.0), (2, -1.0)),
        ("left", 0, (1, 1.0), (2, -1.0)),
    ];
    for dev in devices() {
        for (view, constant, (across, sign_x), (down, sign_y)) in cases {
            let slice = |grid: usize| {
                let vol = grids[grid].to_str().unwrap();
                let name = format!("exr-slice-{view}-{grid}-{dev}.exr");
                let args = [vol, "--mode", "slice", "--view", view, "--size", "48x40"];
                let args = [&args[..], &["--slice-at", &at_arg]].concat();
                read_exr(&render_to(&name, dev, &args))
            };
            let flat = slice(constant);
            let px = pixel_mm(&flat);
            let values = floats(&flat, "Y");
            let on = values.iter().filter(|v| !v.is_nan()).count();
            assert!(on > 48 * 40 / 4, "{dev} {view}: {on} pixels on the plane");
            for v in values.iter().filter(|v| !v.is_nan()) {
                assert!(
                    (v - at[constant]).abs() < 0.02,
                    "{dev} {view}: {v} off the plane"
                );
            }
            for (axis, sign, step) in [(across, sign_x, 1), (down, sign_y, 48)] {
                let e = slice(axis);
                let v = floats(&e, "Y");
                let mut steps = 0;
                for i in 0..v.len() - step {
                    if step == 1 && i % 48 == 47 {
                        continue;
                    }
                    let (a, b) = (v[i], v[i + step]);
                    if a.is_nan() || b.is_nan() {
                        continue;
                    }
                    steps += 1;
                    assert!(
                        (b - a - sign * px).abs() < 0.02,
                        "{dev} {view}: axis {axis} steps {} per pixel, want {}",
                        b - a,
                        sign * px
                    );
                }
                assert!(steps > 100, "{dev} {view}: {steps} steps");
            }
        }
    }
    let vol = grids[0].to_str().unwrap();
    for (args, want) in [
        (
            vec![vol, "--mode", "mip", "--slice-at", "0,0,0"],
            "--mode slice",
        ),
        (
            vec![vol, "--slice-at", "0,0,0"],
            "with --mode (direct volume rendering)",
        ),
        (vec![vol, "--mode", "slice", "--slice-at", "0,0"], "X,Y,Z"),
    ] {
        let out = tmp("refused-slice.png");
        let o = run(&[&["render"], &args[..], &["-o", out.to_str().unwrap()]].concat());
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
}

/// The projections as EXR hold Hounsfield units, before the window: seen from the front
/// (along the block's 30 mm), the MIP is exactly 1000 HU over the block's 10 × 10 mm face and
/// −1000 HU elsewhere, the MinIP −1000 HU everywhere, the average over the block (1000 × 30 −
/// 1000 × 9) / 39 = 538 HU (the rays run between the outer voxels' centres, 39 mm); rays
/// that miss the volume are NaN. The PNG is the window of
/// these values. The GPU (a half-float texture) agrees within a few HU.
#[test]
fn exr_projections_hold_hounsfield_units() {
    let vol = block_volume();
    let vol = vol.to_str().unwrap();
    let base = [vol, "--size", "64x64", "--parallel", "--view", "anterior"];
    let mut mips = Vec::new();
    for dev in devices() {
        let project = |mode: &str, ext: &str, window: &[&str]| {
            let args = [&base[..], &["--mode", mode], window].concat();
            render_to(&format!("exr-block-{mode}-{dev}.{ext}"), dev, &args)
        };
        let mip = read_exr(&project("mip", "exr", &[]));
        assert_eq!(mip.channels.len(), 1, "one channel, Y");
        assert!(
            mip.comments.contains("HU values") && mip.comments.contains("mm square"),
            "{}",
            mip.comments
        );
        let pixel_mm = pixel_mm(&mip);
        let y = floats(&mip, "Y").to_vec();
        let missed = y.iter().filter(|v| v.is_nan()).count();
        assert!(missed > 0 && missed < y.len() / 2, "{dev}: {missed} missed");
        assert!(
            y.iter()
                .filter(|v| !v.is_nan())
                .all(|v| (-1000.5..=1000.5).contains(v)),
            "{dev}: the values lie between air and bone"
        );
        let bone = y.iter().filter(|&&v| v >= 999.0).count();
        let air = y.iter().filter(|&&v| v <= -999.0).count();
        assert!(air > bone, "{dev}: air around the block");
        // The block's face, 10 × 10 mm, in pixels (its edges blur by a voxel).
        let face = 100.0 / (pixel_mm * pixel_mm);
        let over_half = y.iter().filter(|&&v| v > 0.0).count() as f32;
        assert!(
            (over_half - face).abs() < 0.25 * face && bone as f32 > 0.5 * face,
            "{dev}: {over_half} pixels over 0 HU, {bone} at 1000 HU; the face is {face:.0}"
        );

        let minip = read_exr(&project("minip", "exr", &[]));
        let m = floats(&minip, "Y");
        for (a, b) in m.iter().zip(&y) {
            assert_eq!(a.is_nan(), b.is_nan(), "{dev}: the same rays miss");
            assert!(a.is_nan() || (a + 1000.0).abs() < 0.5, "{dev}: MinIP {a}");
        }
        let avg = read_exr(&project("average", "exr", &[]));
        let top = floats(&avg, "Y")
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f32::MIN, f32::max);
        assert!(
            (top - 21_000.0 / 39.0).abs() < 2.0,
            "{dev}: the average through the block is {top} HU"
        );

        // The PNG is the window (here 0 to 1000 HU) of the EXR's values, linear in the grey
        // levels shown (as a DICOM viewer's VOI LUT): byte = 255 × (HU / 1000); misses are the
        // background.
        let window = ["--window", "1000", "--level", "500"];
        let png = image::open(project("mip", "png", &window))
            .unwrap()
            .to_rgb8();
        let bg = Image {
            width: 1,
            height: 1,
            pixels: vec![raystream_cpu::dvr::DvrOptions::default().background],
        }
        .to_srgb8();
        let mut greys = std::collections::BTreeSet::new();
        for (v, p) in y.iter().zip(png.pixels()) {
            if v.is_nan() {
                assert_eq!(p.0.to_vec(), bg, "{dev}: a miss shows the background");
                continue;
            }
            let want = 255.0 * (v / 1000.0).clamp(0.0, 1.0);
            assert!(
                p.0.iter().all(|&c| (c as f32 - want).abs() <= 1.0),
                "{dev}: {v} HU shows as {:?}, want {want}",
                p.0
            );
            greys.insert(p[0]);
        }
        assert!(
            greys.contains(&0) && greys.contains(&255) && greys.len() > 3,
            "{greys:?}"
        );
        mips.push(y);
    }
    if let [cpu, gpu] = &mips[..] {
        let mut diffs: Vec<f32> = Vec::new();
        for (c, g) in cpu.iter().zip(gpu) {
            assert_eq!(c.is_nan(), g.is_nan(), "the same rays miss on both");
            if !c.is_nan() {
                diffs.push((c - g).abs());
            }
        }
        diffs.sort_by(f32::total_cmp);
        let p99 = diffs[diffs.len() * 99 / 100];
        let max = diffs[diffs.len() - 1];
        // f16 holds ±1000 exactly; hardware filtering weighs neighbours to 1/256 at worst
        // (2000 HU apart: 8 HU).
        assert!(
            p99 <= 1.0 && max <= 10.0,
            "GPU MIP off by {p99} HU (p99), {max} (max)"
        );
    }
}

/// `--slab MM`: a slab MIP or average keeps only the slab about `--slice-at` facing the
/// camera. Seen from the front, a 4 mm slab through the bone block's middle gives 1000 HU over
/// its face (MIP and average alike: the slab lies wholly in bone there); one in front of the
/// block (y 0 to 4 mm, the block starting at 5) gives air, −1000 HU, everywhere, where the
/// whole-depth MIP shows the block. The GPU gives the same values.
#[test]
fn slabs_keep_only_their_thickness() {
    let vol = block_volume();
    let vol = vol.to_str().unwrap();
    for dev in devices() {
        let project = |name: &str, extra: &[&str]| {
            let args = [vol, "--size", "48x48", "--view", "anterior", "--parallel"];
            let args = [&args[..], extra].concat();
            let e = read_exr(&render_to(
                &format!("exr-slab-{name}-{dev}.exr"),
                dev,
                &args,
            ));
            floats(&e, "Y").to_vec()
        };
        let slab = ["--slab", "4"];
        let mid = ["--slice-at", "15,20,20"];
        let front = ["--slice-at", "15,2,20"];
        let whole = project("whole", &["--mode", "mip"]);
        let bone = whole.iter().filter(|&&v| v >= 999.0).count();
        assert!(bone > 20, "{dev}: {bone} pixels see the block");
        for mode in ["mip", "average"] {
            let m = ["--mode", mode];
            let inside = project(&format!("{mode}-mid"), &[&m[..], &slab, &mid].concat());
            for (a, w) in inside.iter().zip(&whole) {
                assert_eq!(a.is_nan(), w.is_nan(), "{dev} {mode}: the same rays miss");
                if *w >= 999.0 {
                    assert!(
                        (a - 1000.0).abs() < 0.5,
                        "{dev} {mode}: {a} in the block's slab"
                    );
                }
            }
            let before = project(&format!("{mode}-front"), &[&m[..], &slab, &front].concat());
            let sampled = before.iter().filter(|v| !v.is_nan()).count();
            assert!(
                sampled > 48 * 48 / 4,
                "{dev} {mode}: {sampled} pixels sampled"
            );
            for v in before.iter().filter(|v| !v.is_nan()) {
                assert!(
                    (v + 1000.0).abs() < 0.5,
                    "{dev} {mode}: {v} in front of the block"
                );
            }
        }
    }
    for (args, want) in [
        (
            vec!["--mode", "mip", "--slab", "0"],
            "positive number of mm",
        ),
        (vec!["--mode", "slice", "--slab", "4"], "the plane itself"),
        (
            vec!["--mode", "mip", "--slab", "4", "--clip-plane", "0,1,0,3"],
            "cannot be used with",
        ),
        (vec!["--slab", "4"], "with --mode (direct volume rendering)"),
    ] {
        let out = tmp("refused-slab.png");
        let o = run(&[&["render", vol], &args[..], &["-o", out.to_str().unwrap()]].concat());
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    }
}

/// `--mode dvr|iso` to an EXR: premultiplied RGBA. Composited over the default background it
/// is the PNG (within 1/255); rays that miss are transparent black; iso's surface is opaque
/// (A is 0 or 1), the rendering's bone nearly so and its soft parts in between. The GPU's
/// RGBA is the CPU's.
#[test]
fn volume_renderings_are_premultiplied_rgba() {
    let background = raystream_cpu::dvr::DvrOptions::default().background;
    for mode in ["dvr", "iso"] {
        let mut rgba = Vec::new();
        for dev in devices() {
            let args = ["--mode", mode, "--preset", "ct-bones", "--size", "64x48"];
            let png = render_to(&format!("exr-rgba-{mode}-{dev}.png"), dev, &args);
            let exr = read_exr(&render_to(
                &format!("exr-rgba-{mode}-{dev}.exr"),
                dev,
                &args,
            ));
            assert_eq!(exr.channels.len(), 4, "R, G, B, A");
            assert!(exr.comments.contains("premultiplied"), "{}", exr.comments);
            let (f, a) = (film(&exr), floats(&exr, "A").to_vec());
            assert!(
                a.iter().all(|a| (0.0..=1.0).contains(a)),
                "{dev} {mode}: A in 0..1"
            );
            let clear = a.iter().filter(|&&a| a == 0.0).count();
            let opaque = a.iter().filter(|&&a| a > 0.98).count();
            assert!(
                clear > 64 && opaque > 64,
                "{dev} {mode}: {clear} clear, {opaque} opaque"
            );
            for (p, a) in f.pixels.iter().zip(&a) {
                if *a == 0.0 {
                    assert_eq!(*p, Vec3::ZERO, "{dev} {mode}: a clear pixel is black");
                }
                if mode == "iso" {
                    assert!(*a < 1e-5 || *a > 1.0 - 1e-5, "{dev} iso: A {a}");
                }
            }
            if mode == "dvr" {
                let between = a.iter().filter(|&&a| a > 0.05 && a < 0.95).count();
                assert!(between > 16, "{dev} dvr: {between} translucent pixels");
            }
            let over = Image {
                pixels: f
                    .pixels
                    .iter()
                    .zip(&a)
                    .map(|(p, a)| *p + (1.0 - a) * background)
                    .collect(),
                ..f.clone()
            };
            let shown = image::open(&png).unwrap().to_rgb8().into_raw();
            let (mean, worst) = raystream_cpu::srgb8_diff(&over.to_srgb8(), &shown);
            assert!(
                mean < 0.1 && worst.iter().all(|&d| d <= 1),
                "{dev} {mode}: over the background it is the PNG (mean {mean})"
            );
            rgba.push((f, a));
        }
        if let [(fc, ac), (fg, ag)] = &rgba[..] {
            let (mean, _) = fc.srgb8_diff(fg);
            let da = ac.iter().zip(ag).map(|(x, y)| (x - y).abs()).sum::<f32>() / ac.len() as f32;
            assert!(
                mean < 1.0 && da < 0.01,
                "{mode}: GPU vs CPU {mean}/255, A {da}"
            );
        }
    }
}

/// `-o` must name a PNG or an EXR, refused before any work.
#[test]
fn output_names_its_format() {
    for bad in ["render.jpg", "render", "render.exr.tmp"] {
        let out = tmp(bad);
        let o = run(&["render", "--quiet", "-o", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        let e = stderr(&o);
        assert!(
            e.contains(bad) && e.contains(".png") && e.contains(".exr"),
            "{e}"
        );
        assert!(!out.exists());
    }
}

/// `--turntable N --format exr` writes frame_000.exr …: frame i is exactly the single EXR of
/// `--orbit 360·i/N,0` (the MIP's HU, a slice's HU on its turned plane with that plane named
/// in the comments, the DVR's premultiplied RGBA), and `--format` needs a turntable.
#[test]
fn turntables_write_exr_frames() {
    for dev in devices() {
        for mode in ["mip", "slice", "dvr"] {
            let dir = tmp(&format!("turntable-exr-{mode}-{dev}"));
            let _ = std::fs::remove_dir_all(&dir);
            let args = ["--mode", mode, "--size", "48x40", "--turntable", "3"];
            let mut all = vec!["render", "--quiet", "--device", dev];
            all.extend_from_slice(&args);
            all.extend_from_slice(&["--format", "exr", "-o", dir.to_str().unwrap()]);
            let o = run(&all);
            assert!(o.status.success(), "{all:?}: {}", stderr(&o));
            let mut names: Vec<_> = std::fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().into_string().unwrap())
                .collect();
            names.sort();
            assert_eq!(names, ["frame_000.exr", "frame_001.exr", "frame_002.exr"]);
            let mut frames = Vec::new();
            for (i, az) in ["0", "120", "240"].iter().enumerate() {
                let frame = read_exr(&dir.join(&names[i]));
                let orbit = format!("{az},0");
                let one = read_exr(&render_to(
                    &format!("turntable-exr-{mode}-{dev}-{i}.exr"),
                    dev,
                    &["--mode", mode, "--size", "48x40", "--orbit", &orbit],
                ));
                assert_eq!(frame.comments, one.comments, "{dev} {mode} frame {i}");
                assert_eq!(frame.channels.len(), one.channels.len());
                for (name, samples) in &one.channels {
                    let (a, b) = (floats(&frame, name), samples.as_f32().unwrap());
                    let same = a
                        .iter()
                        .zip(b)
                        .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()));
                    assert!(same, "{dev} {mode} frame {i}: channel {name} differs");
                }
                frames.push(frame);
            }
            let first = if mode == "dvr" { "A" } else { "Y" };
            assert_ne!(
                floats(&frames[0], first),
                floats(&frames[1], first),
                "{dev} {mode}: the frames turn"
            );
            if mode == "slice" {
                assert_ne!(frames[0].comments, frames[1].comments, "the plane turns");
            }
        }
    }
    let o = run(&["render", "--mode", "mip", "--format", "exr", "-o", "x.exr"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--turntable"), "{}", stderr(&o));
}

/// `render --mode mip|average|slice -o OUT.dcm` (and a turntable's `--format dcm` frames): the
/// EXR's Hounsfield units as 16-bit greyscale DICOM, rounded to 1 HU, the rays that missed as
/// the Pixel Padding Value, with the window it was shown in (the mode's unless given) as the
/// VOI LUT, so that a viewer can window it again; on each device, its own EXR's values. With
/// `--labels` the letters need the picture as seen: 8-bit RGB.
#[test]
fn dicom_projections_hold_the_exrs_hounsfield_units() {
    use dicom_dictionary_std::tags;
    use dicom_pixeldata::PixelDecoder;
    let vol = block_volume();
    let vol = vol.to_str().unwrap();
    let base = [vol, "--size", "48x40", "--parallel", "--view", "anterior"];
    for dev in devices() {
        for (mode, window, want_window) in [
            ("mip", &[][..], ("500", "2000")),
            (
                "average",
                &["--window", "1000", "--level", "500"][..],
                ("500", "1000"),
            ),
            (
                "slice",
                &["--window", "400", "--level", "40"][..],
                ("40", "400"),
            ),
        ] {
            let args = [&base[..], &["--mode", mode], window].concat();
            let exr = read_exr(&render_to(
                &format!("dcm-block-{mode}-{dev}.exr"),
                dev,
                &args,
            ));
            let hu = floats(&exr, "Y");
            let dcm = render_to(&format!("dcm-block-{mode}-{dev}.dcm"), dev, &args);
            let obj = dicom_object::open_file(&dcm).unwrap();
            let text = |tag| dicom_text(&obj, tag);
            assert_eq!(text(tags::PHOTOMETRIC_INTERPRETATION), "MONOCHROME2");
            assert_eq!(text(tags::RESCALE_TYPE), "HU");
            assert_eq!(text(tags::BURNED_IN_ANNOTATION), "NO");
            assert_eq!(
                (text(tags::WINDOW_CENTER), text(tags::WINDOW_WIDTH)),
                (want_window.0.to_string(), want_window.1.to_string()),
                "{dev} {mode}"
            );
            let got: Vec<f32> = obj.decode_pixel_data().unwrap().to_vec().unwrap();
            assert_eq!(got.len(), hu.len());
            let mut missed = 0;
            for (g, h) in got.iter().zip(hu) {
                if h.is_nan() {
                    assert_eq!(*g, -32768.0, "{dev} {mode}: a miss is the padding value");
                    missed += 1;
                } else {
                    assert_eq!(*g, h.round(), "{dev} {mode}: {h} HU");
                }
            }
            assert!(
                missed > 0 || mode == "slice",
                "{dev} {mode}: rays miss the block"
            );
        }
        // A turntable's frames are HU too; letters make an RGB picture.
        let frames = tmp(&format!("dcm-block-turntable-{dev}"));
        std::fs::remove_dir_all(&frames).ok();
        let args = [
            &base[..],
            &["--mode", "mip", "--turntable", "2", "--format", "dcm"],
        ]
        .concat();
        let mut all = vec!["render", "--quiet", "--device", dev];
        all.extend_from_slice(&args);
        all.extend_from_slice(&["-o", frames.to_str().unwrap()]);
        let o = run(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        for f in ["frame_000.dcm", "frame_001.dcm"] {
            let obj = dicom_object::open_file(frames.join(f)).unwrap();
            let p = obj.element(tags::PHOTOMETRIC_INTERPRETATION).unwrap();
            assert_eq!(p.to_str().unwrap().trim(), "MONOCHROME2", "{f}");
        }
        let labelled = [&base[..], &["--mode", "mip", "--labels"]].concat();
        let dcm = render_to(&format!("dcm-block-labels-{dev}.dcm"), dev, &labelled);
        let obj = dicom_object::open_file(&dcm).unwrap();
        let p = obj.element(tags::PHOTOMETRIC_INTERPRETATION).unwrap();
        assert_eq!(p.to_str().unwrap().trim(), "RGB");
    }
}

/// `--body-only` projections of the built-in CT, seen from the left (the table's top runs
/// along the back, on the picture's right): the MIP loses the table's line and keeps the
/// body's pixels (never lower: a sample at the skin blends the body's voxels alone, not the
/// air); the MinIP shows the bowel's gas within the body instead of the air around it. On
/// both devices.
#[test]
fn body_only_projections_leave_out_the_table() {
    for dev in devices() {
        let project = |mode: &str, more: &[&str]| {
            let name = format!("body-{mode}{}-{dev}.exr", more.len());
            let args = [&["--mode", mode, "--size", "96x96", "--view", "left"], more].concat();
            let e = read_exr(&render_to(&name, dev, &args));
            (e.width as usize, floats(&e, "Y").to_vec())
        };
        let (w, plain) = project("mip", &[]);
        let (_, body) = project("mip", &["--body-only"]);
        let seen: Vec<usize> = (0..body.len()).filter(|&n| !body[n].is_nan()).collect();
        let same = seen
            .iter()
            .filter(|&&n| (body[n] - plain[n]).abs() <= 2.0)
            .count();
        let lower = seen.iter().filter(|&&n| body[n] < plain[n] - 2.0).count();
        assert!(
            lower == 0 && same as f64 > 0.85 * seen.len() as f64,
            "{dev}: of {} pixels, {same} the same and {lower} lower",
            seen.len()
        );
        // Left out: the dense pixels of the whole CT's MIP that the body's misses, a line
        // down the picture, all behind the body.
        let lost: Vec<usize> = (0..body.len())
            .filter(|&n| body[n].is_nan() && plain[n] > -300.0)
            .collect();
        let back = seen.iter().map(|&n| n % w).max().unwrap();
        let first = lost.iter().map(|&n| n % w).min().unwrap();
        assert!(
            lost.len() > w / 2 && first > back,
            "{dev}: {} pixels lost, from column {first}; the body ends at {back}",
            lost.len()
        );
        // The MinIP: air (below -950 HU) in most of the whole CT's pixels, in few of the
        // body's.
        let air = |v: &[f32]| {
            let hit: Vec<f32> = v.iter().copied().filter(|x| !x.is_nan()).collect();
            hit.iter().filter(|&&x| x < -950.0).count() as f64 / hit.len() as f64
        };
        let (plain, body) = (
            air(&project("minip", &[]).1),
            air(&project("minip", &["--body-only"]).1),
        );
        assert!(
            plain > 0.8 && body < 0.1,
            "{dev}: air in {plain} and {body} of the pixels"
        );
    }
}

/// The chest CT is a crop within the body, whose lungs reach its border on both sides: with
/// `--body-only`, a MinIP from the front keeps them (nearly every pixel the whole CT's MinIP
/// reads as lung reads so still; the others lie by the air before the neck, which is left
/// out, or by the bowel's gas the border cuts, which reads as air), and leaves out the air.
#[test]
fn body_only_keeps_a_lung_the_field_of_view_cuts() {
    let chest = chest();
    for dev in devices() {
        let project = |more: &[&str]| {
            let name = format!("body-cut-minip{}-{dev}.exr", more.len());
            let args = [
                &[chest.as_str(), "--mode", "minip", "--size", "64x64"],
                more,
            ]
            .concat();
            floats(&read_exr(&render_to(&name, dev, &args)), "Y").to_vec()
        };
        let (plain, body) = (project(&[]), project(&["--body-only"]));
        let lung: Vec<usize> = (0..plain.len())
            .filter(|&n| plain[n] > -950.0 && plain[n] <= -600.0)
            .collect();
        let kept = lung
            .iter()
            .filter(|&&n| (body[n] - plain[n]).abs() <= 20.0)
            .count();
        let hit = plain.iter().filter(|x| !x.is_nan()).count();
        assert!(
            lung.len() > hit / 3 && kept as f64 > 0.95 * lung.len() as f64,
            "{dev}: {kept} of {} lung pixels kept",
            lung.len()
        );
        let air = |v: &[f32]| v.iter().filter(|&&x| x < -980.0).count();
        assert!(
            air(&body) * 2 < air(&plain),
            "{dev}: air in {} pixels, {} of the whole CT's",
            air(&body),
            air(&plain)
        );
    }
}
