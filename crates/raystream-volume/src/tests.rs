//! Isosurfaces against analytic volumes: closed, consistently oriented, on the true surface.

use std::collections::HashMap;

use raystream_io::Volume;
use raystream_math::Vec3;

use super::*;

/// A volume of `f(p_world)` on a grid with the given spacing, origin and (orthonormal) direction.
fn analytic(
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: [[f64; 3]; 3],
    f: impl Fn(raystream_math::DVec3) -> f32,
) -> Volume {
    let mut v = Volume {
        origin,
        direction,
        ..Volume::hounsfield(dims, spacing, Vec::new())
    };
    let mut data = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p = v.index_to_world(raystream_math::DVec3::new(i as f64, j as f64, k as f64));
                data.push(f(p));
            }
        }
    }
    v.data = data;
    v
}

/// Every undirected edge is used by exactly two triangles, once in each direction: a closed,
/// consistently oriented 2-manifold.
fn assert_closed_and_oriented(mesh: &raystream_io::TriMesh) {
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for i in 0..3 {
            *directed.entry((t[i], t[(i + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        assert_eq!(n, 1, "directed edge {a}->{b} used {n} times");
        assert_eq!(
            directed.get(&(b, a)),
            Some(&1),
            "edge {a}-{b} has no opposite: a crack or a flipped triangle"
        );
    }
}

fn rotation() -> [[f64; 3]; 3] {
    // 30° about z then 20° about x: an oblique grid, as a tilted acquisition gives.
    let m = raystream_math::DMat3::from_rotation_x(20f64.to_radians())
        * raystream_math::DMat3::from_rotation_z(30f64.to_radians());
    let c = m.to_cols_array_2d();
    std::array::from_fn(|r| std::array::from_fn(|col| c[col][r]))
}

fn tilted() -> [[f64; 3]; 3] {
    let (c, s) = (18.5f64.to_radians().cos(), 18.5f64.to_radians().sin());
    [[1.0, 0.0, 0.0], [0.0, c, 0.0], [0.0, -s, 1.0]]
}

#[test]
fn sphere_is_closed_oriented_and_within_half_a_voxel() {
    let centre = raystream_math::DVec3::new(3.0, -2.0, 5.0);
    let radius = 20.0;
    for (spacing, direction) in [
        (
            [1.0, 1.0, 1.0],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        ),
        ([0.8, 1.1, 1.7], rotation()),
        // A gantry-tilted CT's sheared grid: rows along x, columns tilted 18.5° about x, the
        // third axis along the table (z), as the GE head CT in ../shared reads.
        ([0.9, 0.9, 1.4], tilted()),
    ] {
        let dims = [64, 64, 48];
        let half =
            raystream_math::DVec3::new(32.0 * spacing[0], 32.0 * spacing[1], 24.0 * spacing[2]);
        let m = raystream_math::DMat3::from_cols_array_2d(&direction).transpose();
        let origin = (centre - m * half).to_array();
        // HU-like: 1000 at the centre, falling through 300 at the radius.
        let vol = analytic(dims, spacing, origin, direction, |p| {
            (300.0 + 40.0 * (radius - (p - centre).length())) as f32
        });
        let iso = extract_isosurface(&vol, 300.0);
        assert!(iso.mesh.len() > 1000);
        assert_closed_and_oriented(&iso.mesh);
        let max_spacing = spacing.iter().cloned().fold(0.0, f64::max);
        for (p, n) in iso.mesh.positions.iter().zip(&iso.normals) {
            let r = (p.as_dvec3() - centre).length();
            assert!(
                (r - radius).abs() < 0.5 * max_spacing,
                "vertex at radius {r}"
            );
            let outward = (p.as_dvec3() - centre).normalize().as_vec3();
            assert!(n.dot(outward) > 0.99, "normal {n} vs {outward}");
        }
        // Triangle windings point outward too.
        for t in &iso.mesh.triangles {
            let [a, b, c] = t.map(|i| iso.mesh.positions[i as usize]);
            let g = (b - a).cross(c - a);
            let out = (a + b + c) / 3.0 - centre.as_vec3();
            assert!(g.dot(out) >= 0.0, "triangle winds inward");
        }
    }
}

#[test]
fn surfaces_cut_by_the_border_are_capped() {
    // A slab filling the whole volume in x and y: without caps it would be two open sheets.
    let vol = analytic(
        [8, 9, 10],
        [1.0; 3],
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        |p| {
            if (2.5..6.5).contains(&p.z) {
                1000.0
            } else {
                -1000.0
            }
        },
    );
    let iso = extract_isosurface(&vol, 300.0);
    assert_closed_and_oriented(&iso.mesh);
    // Within the volume, reaching its border (the caps' rims); the caps' inner vertices (one a
    // border voxel inside: 9 × 4 a side) 1/512 voxel in from the border voxels' centres
    // (every vertex its own point).
    let b = iso.mesh.bounds();
    assert_eq!((b.min.x, b.max.y), (0.0, 8.0));
    let cap = |x: f32| iso.mesh.positions.iter().filter(|p| p.x == x).count();
    assert_eq!(cap(1.0 / 512.0), 9 * 4);
    assert_eq!(cap(7.0 - 1.0 / 512.0), 9 * 4);
}

/// A CT's integers at an integer threshold: voxels exactly at it (a ball of 60 HU steps about a
/// corner of the volume, 300 HU at every voxel 5 voxels out, rounded) put no two vertices on one
/// point and make no triangle of no area, at the border's caps too (three meet at the corner
/// voxel), and the surface stays closed.
#[test]
fn voxels_at_the_threshold_give_every_vertex_its_own_point() {
    let vol = analytic(
        [12, 12, 12],
        [0.7, 0.7, 1.5],
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        |p| {
            let r = (p / raystream_math::DVec3::new(0.7, 0.7, 1.5))
                .length()
                .round();
            (600.0 - 60.0 * r).max(-1000.0) as f32
        },
    );
    let at = vol.data.iter().filter(|&&v| v == 300.0).count();
    assert!(at > 20, "{at} voxels at the threshold");
    let iso = extract_isosurface(&vol, 300.0);
    assert_closed_and_oriented(&iso.mesh);
    let mut points: Vec<[u32; 3]> = iso
        .mesh
        .positions
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect();
    points.sort_unstable();
    points.dedup();
    assert_eq!(
        points.len(),
        iso.mesh.positions.len(),
        "vertices sharing a point"
    );
    for i in 0..iso.mesh.len() {
        let [a, b, c] = iso.mesh.corners(i);
        assert!(
            (b - a).cross(c - a).length() > 0.0,
            "triangle {i} has no area"
        );
    }
}

#[test]
fn every_case_is_closed_on_its_own() {
    // One cell per case, surrounded by outside: each case's surface plus the caps is closed.
    for case in 0..256usize {
        let vol = analytic(
            [2, 2, 2],
            [1.0; 3],
            [0.0; 3],
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            |p| {
                let c = p.x as usize | (p.y as usize) << 1 | (p.z as usize) << 2;
                if case >> c & 1 == 1 { 1000.0 } else { -1000.0 }
            },
        );
        let iso = extract_isosurface(&vol, 0.0);
        assert_closed_and_oriented(&iso.mesh);
    }
}

/// A volume of xorshift noise from `seed`, uniform over −1000 + `shift` .. 1000 + `shift`, on a
/// grid of these dimensions, spacing and direction.
fn noise(
    seed: u64,
    dims: [usize; 3],
    spacing: [f64; 3],
    direction: [[f64; 3]; 3],
    shift: f32,
) -> Volume {
    let mut s = seed | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s % 2000) as f32 - 1000.0 + shift
    };
    let mut vol = analytic(dims, spacing, [5.0, -3.0, 2.0], direction, |_| 0.0);
    vol.data.iter_mut().for_each(|v| *v = rnd());
    vol
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// Random noise volumes (every ambiguous configuration appears): always closed and oriented.
    #[test]
    fn random_volumes_give_closed_surfaces(seed in 0u64..u64::MAX, dims in (2usize..9, 2usize..9, 2usize..9)) {
        let vol = noise(seed, [dims.0, dims.1, dims.2], [1.0; 3], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 0.0);
        let iso = extract_isosurface(&vol, 0.5);
        assert_closed_and_oriented(&iso.mesh);
        for n in &iso.normals { proptest::prop_assert!(n.is_finite()); }
        let _ = Vec3::ZERO;
    }
}

#[test]
fn smoothing_keeps_the_sphere_closed_and_its_radius() {
    let centre = raystream_math::DVec3::new(32.0, 32.0, 32.0);
    let vol = analytic(
        [64, 64, 64],
        [1.0; 3],
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        |p| {
            if (p - centre).length() < 20.0 {
                1000.0
            } else {
                -1000.0
            }
        },
    );
    let mut iso = extract_isosurface(&vol, 0.0);
    let spread = |s: &IsoSurface| {
        let r: Vec<f64> = s
            .mesh
            .positions
            .iter()
            .map(|p| (p.as_dvec3() - centre).length())
            .collect();
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        (
            mean,
            r.iter().map(|x| (x - mean).abs()).sum::<f64>() / r.len() as f64,
        )
    };
    let (mean0, dev0) = spread(&iso);
    smooth(&mut iso, 5);
    let (mean1, dev1) = spread(&iso);
    assert_closed_and_oriented(&iso.mesh);
    // A binary sphere's stair-steps flatten out; Taubin's inflating step keeps the size.
    assert!(dev1 < 0.7 * dev0, "mean deviation {dev0} -> {dev1}");
    assert!(
        (mean1 - mean0).abs() < 0.2,
        "mean radius {mean0} -> {mean1}"
    );
    for (p, n) in iso.mesh.positions.iter().zip(&iso.normals) {
        assert!(n.dot((p.as_dvec3() - centre).normalize().as_vec3()) > 0.8);
    }
}

/// Transfer functions: piecewise-linear between control points, clamped outside; the brick
/// test's range maximum; the presets are valid; files load or fail naming the file.
#[test]
fn transfer_functions() {
    let tf = TransferFunction {
        opacity: vec![(0.0, 0.0), (100.0, 0.5), (200.0, 0.1)],
        color: vec![(0.0, [0.0, 0.0, 0.0]), (100.0, [1.0, 0.5, 0.0])],
        shading: Shading::default(),
    };
    assert_eq!(tf.opacity_at(-50.0), 0.0);
    assert_eq!(tf.opacity_at(50.0), 0.25);
    assert_eq!(tf.opacity_at(150.0), 0.3);
    assert_eq!(tf.opacity_at(1e6), 0.1);
    assert_eq!(tf.color_at(50.0), [0.5, 0.25, 0.0]);
    assert_eq!(tf.max_opacity_in(-10.0, -1.0), 0.0);
    assert_eq!(tf.max_opacity_in(50.0, 150.0), 0.5);
    assert_eq!(tf.max_opacity_in(150.0, 160.0), 0.3);
    for p in TfPreset::ALL {
        p.function()
            .validate()
            .unwrap_or_else(|e| panic!("{}: {e}", p.name()));
        // Air is transparent in every CT preset.
        assert_eq!(p.function().opacity_at(-1000.0), 0.0, "{}", p.name());
    }
    let scratch = tempfile::Builder::new()
        .prefix("raystream-tf-")
        .tempdir()
        .unwrap();
    let dir = scratch.path();
    let good = dir.join("good.toml");
    std::fs::write(
        &good,
        "opacity = [[-1000, 0], [300, 0.5]]\ncolor = [[0, 1, 0.9, 0.8]]\nspecular = 0.4\n",
    )
    .unwrap();
    let tf = TransferFunction::load(&good).unwrap();
    assert_eq!(tf.opacity, vec![(-1000.0, 0.0), (300.0, 0.5)]);
    assert_eq!(tf.shading.specular, 0.4);
    for (name, text, problem) in [
        (
            "order.toml",
            "opacity = [[300, 0], [0, 1]]\ncolor = [[0, 1, 1, 1]]\n",
            "increasing",
        ),
        (
            "range.toml",
            "opacity = [[0, 2]]\ncolor = [[0, 1, 1, 1]]\n",
            "[0, 1]",
        ),
        (
            "empty.toml",
            "opacity = []\ncolor = [[0, 1, 1, 1]]\n",
            "at least one",
        ),
        (
            "typo.toml",
            "opacity = [[0, 1]]\ncolour = [[0, 1, 1, 1]]\n",
            "not a transfer function",
        ),
    ] {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        let e = TransferFunction::load(&f).unwrap_err();
        assert!(e.contains(name) && e.contains(problem), "{name}: {e}");
    }
}

/// The farthest any vertex of `full` lies from the surface `simple`, brute force.
fn departure_brute(full: &raystream_io::TriMesh, simple: &raystream_io::TriMesh) -> f64 {
    distances_brute(&full.positions, simple, f64::INFINITY)
        .into_iter()
        .fold(0.0, f64::max)
}

/// The smoothed spheres of radius 20 and 20.5 (voxels of 1 mm, cut by the volume's border)
/// simplified within 0.2 and 0.5 mm: a sixth of the triangles or fewer, still closed and
/// oriented, its vertices original ones with their own normals (re-derived from the simplified
/// triangles, they were up to 72° off the radial on such spheres at 0.5 mm), every vertex
/// of the full surface within the bound of the simplified one (the departure `simplify`
/// measures through its grid equals brute force's), the volume within 3 × bound / radius, and
/// as few triangles as the fewest any of its tries keeps run alone to its end (the tries take
/// turns, each reported round that of its try alone). A bound of 0 changes nothing.
#[test]
fn simplifying_keeps_the_surface_within_its_bound() {
    for radius in [20.0, 20.5] {
        simplify_sphere(radius);
    }
}

fn simplify_sphere(radius: f64) {
    let centre = raystream_math::DVec3::new(32.0, 32.0, 32.0);
    let vol = analytic([64, 64, 64], [1.0; 3], [0.0; 3], rotation(), |p| {
        if (p - centre).length() < radius {
            1000.0
        } else {
            -1000.0
        }
    });
    let mut full = extract_isosurface(&vol, 0.0);
    smooth(&mut full, 10);
    let mut same = full.clone();
    let s = simplify(&mut same, 0.0);
    assert_eq!((s.triangles_after, s.departure), (full.mesh.len(), 0.0));
    for bound in [0.2, 0.5] {
        let mut simple = full.clone();
        let mut rounds = Vec::new();
        let s = simplify_reporting(&mut simple, bound, &mut |r| rounds.push(r));
        // Told every round measured: each try's in order, the tries begun in order, each
        // round's triangles those of its try run alone; the tries that kept within the bound,
        // run alone, kept no fewer than the surface has now, which one of them kept.
        let alone = crate::marching::each_try(&full, bound);
        assert_eq!((rounds[0].attempt, rounds[0].round), (1, 1));
        // Each try's rounds told so far.
        let mut told = vec![0usize; alone.len()];
        for r in &rounds {
            let a = r.attempt as usize - 1;
            assert!(a == 0 || told[a - 1] > 0, "{rounds:?}");
            assert_eq!(r.round, told[a] + 1, "{rounds:?}");
            assert_eq!(r.triangles, alone[a].0[r.round - 1], "{rounds:?} {alone:?}");
            told[a] += 1;
        }
        let fewest = (alone.iter())
            .filter(|(_, kept)| *kept)
            .map(|(r, _)| *r.last().unwrap())
            .min();
        assert_eq!(fewest, Some(simple.mesh.len()), "{alone:?}");
        assert!(
            rounds
                .iter()
                .any(|r| r.beyond == 0 && r.triangles == simple.mesh.len())
        );
        assert_eq!(s.triangles_before, full.mesh.len());
        assert_eq!(s.triangles_after, simple.mesh.len());
        assert!(
            s.triangles_after * 6 < s.triangles_before,
            "{} -> {} triangles",
            s.triangles_before,
            s.triangles_after
        );
        assert_closed_and_oriented(&simple.mesh);
        assert_eq!(pinched_vertices(&simple.mesh.triangles), [0u32; 0]);
        assert_eq!(simple.normals.len(), simple.mesh.positions.len());
        for (p, n) in simple.mesh.positions.iter().zip(&simple.normals) {
            let v = full.mesh.positions.iter().position(|q| q == p);
            let v = v.unwrap_or_else(|| panic!("{p} is no vertex of the full surface"));
            assert_eq!(*n, full.normals[v], "the normal of {p}");
        }
        let d = departure_brute(&full.mesh, &simple.mesh);
        assert!(
            d <= bound,
            "the full surface departs {d} mm from the simplified one"
        );
        assert!((d - s.departure).abs() < 1e-12, "{d} measured, {s:?}");
        let (v0, v1) = (full.mesh.enclosed_volume(), simple.mesh.enclosed_volume());
        // Within the bound of a sphere: the volume within 3 bound / radius.
        assert!(
            (v1 - v0).abs() < 3.0 * bound / radius * v0,
            "volume {v0} -> {v1}"
        );
    }
}

/// Beyond the reach asked, a vertex counts as infinitely far.
#[test]
fn departure_beyond_the_reach_is_infinite() {
    let far = raystream_io::TriMesh {
        positions: vec![Vec3::new(0.0, 0.0, 5.0)],
        triangles: vec![],
    };
    let tri = raystream_io::TriMesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        triangles: vec![[0, 1, 2]],
    };
    assert_eq!(departure(&far.positions, &tri, 4.0), f64::INFINITY);
    assert_eq!(departure(&far.positions, &tri, 6.0), 5.0);
}

/// Each point's distance from its nearest triangle, brute force: +∞ beyond `reach`.
fn distances_brute(points: &[Vec3], mesh: &raystream_io::TriMesh, reach: f64) -> Vec<f64> {
    use rayon::prelude::*;
    points
        .par_iter()
        .map(|p| {
            let d = (0..mesh.len())
                .map(|i| {
                    point_triangle_distance(p.as_dvec3(), mesh.corners(i).map(|c| c.as_dvec3()))
                })
                .fold(f64::INFINITY, f64::min);
            if d <= reach { d } else { f64::INFINITY }
        })
        .collect()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(96))]
    /// [`distances`]' grid search (passing over cells and triangles whose bounds are farther
    /// than the nearest triangle found so far) gives each point the
    /// same distance as brute force, to the bit, or +∞ alike: random triangles from slivers to
    /// ones spanning many cells, points on them, near them and far off, reaches from a
    /// hundredth of the triangles' spread to more than all of it.
    #[test]
    fn distances_equal_brute_force(seed in 0u64..u64::MAX, n in 1usize..60, reach_exp in -2.0f64..1.0) {
        let mut s = seed | 1;
        let mut rnd = move || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; (s >> 11) as f32 / (1u64 << 53) as f32 };
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for t in 0..n {
            let c = Vec3::new(rnd(), rnd(), rnd()) * 100.0;
            let size = 10f32.powf(rnd() * 3.0 - 1.0);
            for _ in 0..3 {
                positions.push(c + (Vec3::new(rnd(), rnd(), rnd()) - 0.5) * size);
            }
            let t = 3 * t as u32;
            triangles.push([t, t + 1, t + 2]);
        }
        let mesh = raystream_io::TriMesh { positions, triangles };
        let mut points: Vec<Vec3> = (0..200).map(|_| (Vec3::new(rnd(), rnd(), rnd()) - 0.1) * 120.0).collect();
        points.extend(mesh.positions.iter().map(|&p| p + (Vec3::new(rnd(), rnd(), rnd()) - 0.5)));
        let reach = 100.0 * 10f64.powf(reach_exp);
        let got = distances(&points, &mesh, reach);
        let want = distances_brute(&points, &mesh, reach);
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            proptest::prop_assert_eq!(g.to_bits(), w.to_bits(), "point {} at {}", i, points[i]);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]
    /// `compact` (meshoptimizer's triangles made a surface, less any two that are one triangle
    /// facing both ways) against a plain search: each triangle cancels the latest one still
    /// standing that is it reversed (in any rotation), else stands; the ones standing are kept
    /// in order, and only the vertices they use, in order, each with its index in the full
    /// surface. Few vertices, so that triangles repeat and reverse often.
    #[test]
    fn compact_equals_a_plain_search(tris in proptest::collection::vec(
        proptest::strategy::Strategy::prop_filter(
            (0u32..5, 0u32..5, 0u32..5),
            "three corners",
            |(a, b, c)| a != b && b != c && a != c,
        ),
        0..40,
    )) {
        let full = raystream_io::TriMesh {
            positions: (0..7).map(|v| Vec3::new(v as f32, (v * v) as f32, 1.0)).collect(),
            triangles: Vec::new(),
        };
        let kept: Vec<u32> = tris.iter().flat_map(|&(a, b, c)| [a, b, c]).collect();
        let (mesh, origin) = crate::marching::compact(&full, &kept);
        let cyclic = |t: [u32; 3]| [t, [t[1], t[2], t[0]], [t[2], t[0], t[1]]];
        let mut standing: Vec<bool> = Vec::new();
        let tris: Vec<[u32; 3]> = tris.iter().map(|&(a, b, c)| [a, b, c]).collect();
        for (i, &t) in tris.iter().enumerate() {
            let reverse = [t[0], t[2], t[1]];
            let j = (0..i).rev().find(|&j| standing[j] && cyclic(tris[j]).contains(&reverse));
            standing.push(j.is_none());
            if let Some(j) = j {
                standing[j] = false;
            }
        }
        let want: Vec<[u32; 3]> = (0..tris.len()).filter(|&i| standing[i]).map(|i| tris[i]).collect();
        let mut used: Vec<u32> = want.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        proptest::prop_assert_eq!(&origin, &used);
        let got: Vec<[u32; 3]> = mesh.triangles.iter().map(|t| t.map(|v| origin[v as usize])).collect();
        proptest::prop_assert_eq!(got, want);
        for (v, &o) in origin.iter().enumerate() {
            proptest::prop_assert_eq!(mesh.positions[v], full.positions[o as usize]);
        }
    }
}

/// A surface whose extent is more than 2²¹ of its cells (two small triangles 10⁸ apart,
/// measured within 10⁻³) widens the cells until the grid fits its keys, and still gives brute
/// force's distances.
#[test]
fn distances_over_a_vast_extent_equal_brute_force() {
    let far = Vec3::new(1e8, -1e8, 5e7);
    let mesh = raystream_io::TriMesh {
        positions: vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            far,
            far + Vec3::X,
            far + Vec3::Z,
        ],
        triangles: vec![[0, 1, 2], [3, 4, 5]],
    };
    let points = [
        Vec3::new(0.25, 0.25, 0.0005),
        Vec3::new(0.25, 0.25, 0.5),
        far + Vec3::new(0.5, 0.0, 0.5),
        far + Vec3::new(0.5, 0.0004, 0.5),
        far * 0.5,
    ];
    for reach in [1e-3, 1.0, 1e9] {
        let got = distances(&points, &mesh, reach);
        assert_eq!(
            got,
            distances_brute(&points, &mesh, reach),
            "within {reach}"
        );
    }
    assert!(distances(&points, &mesh, 1e-3)[1].is_infinite());
    // A surface of one point (a triangle of no area) measured within 10⁻³⁰⁰: cells that small
    // put a point 10¹⁰ off beyond any cell coordinate, which is still no panic and +∞.
    let dot = raystream_io::TriMesh {
        positions: vec![Vec3::ONE; 3],
        triangles: vec![[0, 1, 2]],
    };
    let points = [Vec3::ONE, Vec3::splat(1e10), Vec3::splat(-1e10)];
    assert_eq!(
        distances(&points, &dot, 1e-300),
        [0.0, f64::INFINITY, f64::INFINITY]
    );
}

/// [`not_manifold`] on surfaces built by hand: a tetrahedron has no such edge; with a face
/// turned, its three edges are each crossed twice the same way; a second tetrahedron on one
/// edge makes it join four triangles; a lone triangle's edges are a border, not listed. A
/// sphere's marching cubes surface has no such edge and no pinched vertex.
#[test]
fn edges_that_are_not_manifold() {
    let tetra = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let none: [[u32; 2]; 0] = [];
    assert_eq!(not_manifold(&tetra), none);
    let mut turned = tetra;
    turned[3] = [1, 3, 2];
    assert_eq!(not_manifold(&turned), [[1, 2], [1, 3], [2, 3]]);
    let mut two = tetra.to_vec();
    two.extend([[0, 4, 1], [0, 1, 5], [0, 5, 4], [1, 4, 5]]);
    assert_eq!(not_manifold(&two), [[0, 1]]);
    assert_eq!(not_manifold(&[[0, 1, 2]]), none);
    // The sphere's marching cubes surface: none, as the brute check finds it closed.
    let centre = raystream_math::DVec3::splat(8.0);
    let vol = analytic([16, 16, 16], [1.0; 3], [0.0; 3], rotation(), |p| {
        if (p - centre).length() < 5.0 {
            1000.0
        } else {
            -1000.0
        }
    });
    let s = extract_isosurface(&vol, 0.0);
    assert_closed_and_oriented(&s.mesh);
    assert_eq!(not_manifold(&s.mesh.triangles), none);
    assert_eq!(pinched_vertices(&s.mesh.triangles), [0u32; 0]);
}

/// [`pinched_vertices`] on surfaces built by hand: a tetrahedron has none; two tetrahedra
/// sharing one vertex only (tip to tip) are pinched there; sharing an edge, at its ends (an
/// edge joining four triangles); random volumes' marching cubes surfaces (every case of the
/// table) have none, as the sphere's has none ([`edges_that_are_not_manifold`]).
#[test]
fn vertices_where_a_surface_is_pinched() {
    let tetra = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let none: [u32; 0] = [];
    assert_eq!(pinched_vertices(&tetra), none);
    let mut tip = tetra.to_vec();
    tip.extend([[0, 5, 4], [0, 4, 6], [0, 6, 5], [4, 5, 6]]);
    assert_eq!(pinched_vertices(&tip), [0]);
    let mut edge = tetra.to_vec();
    edge.extend([[0, 4, 1], [0, 1, 5], [0, 5, 4], [1, 4, 5]]);
    assert_eq!(pinched_vertices(&edge), [0, 1]);
    let seed = std::cell::Cell::new(7u64);
    for _ in 0..4 {
        let vol = analytic([12, 11, 10], [1.0; 3], [0.0; 3], rotation(), |_| {
            let next = seed
                .get()
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            seed.set(next);
            if next >> 63 == 1 { 1000.0 } else { -1000.0 }
        });
        let s = extract_isosurface(&vol, 0.0);
        assert_closed_and_oriented(&s.mesh);
        assert_eq!(pinched_vertices(&s.mesh.triangles), none);
    }
}

/// A lone voxel's surface, smoothed to a speck (which quadric collapses alone take away
/// whole, it being next to flat), stays; a ball of radius 3 beside it is simplified within the
/// bound; every vertex of the full surface is within the bound of the simplified one.
#[test]
fn a_speck_beside_a_ball_stays() {
    let ball = raystream_math::DVec3::new(20.0, 20.0, 20.0);
    let lone = raystream_math::DVec3::new(6.0, 6.0, 6.0);
    let vol = analytic([32, 32, 32], [1.0; 3], [0.0; 3], rotation(), |p| {
        if (p - ball).length() < 3.0 || (vol_index(p) - lone).length() < 0.1 {
            1000.0
        } else {
            -1000.0
        }
    });
    let mut full = extract_isosurface(&vol, 0.0);
    smooth(&mut full, 10);
    let speck: Vec<Vec3> = full
        .mesh
        .positions
        .iter()
        .filter(|p| (p.as_dvec3() - ball).length() > 5.0)
        .copied()
        .collect();
    assert_eq!(speck.len(), 6, "a lone voxel's octahedron");
    let mut simple = full.clone();
    let s = simplify(&mut simple, 0.3);
    assert!(s.triangles_after < s.triangles_before, "{s:?}");
    assert_closed_and_oriented(&simple.mesh);
    for p in &speck {
        assert!(simple.mesh.positions.contains(p), "{p} of the speck");
    }
    let d = departure_brute(&full.mesh, &simple.mesh);
    assert!(d <= 0.3 && (d - s.departure).abs() < 1e-12, "{d} {s:?}");
}

/// The index of a world point of [`analytic`]'s grid with origin 0, unit spacing and
/// [`rotation`]'s axes.
fn vol_index(p: raystream_math::DVec3) -> raystream_math::DVec3 {
    let r = rotation();
    raystream_math::DVec3::from_array(std::array::from_fn(|c| {
        (0..3).map(|row| r[row][c] * p[row]).sum()
    }))
}

/// [`grid::trilinear`] and [`grid::trilinear_in`] give what the first form gave (cells and
/// fractions through usize, `f32::clamp`), bit for bit, on grids of 1 to 5 points an axis, inside and outside them, on grid points,
/// far out, and at NaN, ±0 and ±∞; and the corners' values at the corners.
#[test]
fn trilinear_is_its_first_form() {
    fn plain(dims: [usize; 3], p: Vec3, at: impl Fn(usize, usize, usize) -> f32) -> f32 {
        let [nx, ny, nz] = dims;
        let c = |x: f32, n: usize| x.clamp(0.0, (n - 1) as f32);
        let (x, y, z) = (c(p.x, nx), c(p.y, ny), c(p.z, nz));
        let (i, j, k) = (
            (x as usize).min(nx.saturating_sub(2)),
            (y as usize).min(ny.saturating_sub(2)),
            (z as usize).min(nz.saturating_sub(2)),
        );
        let (fx, fy, fz) = (x - i as f32, y - j as f32, z - k as f32);
        let v = |di: usize, dj: usize, dk: usize| {
            at(
                (i + di).min(nx - 1),
                (j + dj).min(ny - 1),
                (k + dk).min(nz - 1),
            )
        };
        let l = |a: f32, b: f32, w: f32| a + (b - a) * w;
        l(
            l(
                l(v(0, 0, 0), v(1, 0, 0), fx),
                l(v(0, 1, 0), v(1, 1, 0), fx),
                fy,
            ),
            l(
                l(v(0, 0, 1), v(1, 0, 1), fx),
                l(v(0, 1, 1), v(1, 1, 1), fx),
                fy,
            ),
            fz,
        )
    }
    let mut xs = vec![
        0.0,
        -0.0,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e30,
        -1e30,
        4.9999995,
    ];
    xs.extend((0..70).map(|k| k as f32 / 10.0 - 1.0));
    let mut compared = 0;
    for dims in [[1, 1, 1], [2, 3, 5], [5, 4, 2], [4, 1, 3]] {
        let at = |i: usize, j: usize, k: usize| ((i * 7 + j * 13 + k * 29) % 17) as f32 - 8.5;
        let data: Vec<f32> = (0..dims[2])
            .flat_map(|k| (0..dims[1]).flat_map(move |j| (0..dims[0]).map(move |i| at(i, j, k))))
            .collect();
        for (n, &x) in xs.iter().enumerate() {
            for &y in xs.iter().skip(n % 7).step_by(7) {
                for &z in xs.iter().skip(n % 5).step_by(5) {
                    let p = Vec3::new(x, y, z);
                    let (v, pv) = (grid::trilinear(dims, p, at), plain(dims, p, at));
                    assert_eq!(v.to_bits(), pv.to_bits(), "{dims:?} at {p}: {v} vs {pv}");
                    let g = grid::trilinear_in(dims, &data, p);
                    assert_eq!(g.to_bits(), pv.to_bits(), "{dims:?} at {p}: {g} vs {pv}");
                    compared += 1;
                }
            }
        }
        let last = dims.map(|n| n - 1);
        let corner = Vec3::new(last[0] as f32, last[1] as f32, last[2] as f32);
        assert_eq!(
            grid::trilinear(dims, corner, at),
            at(last[0], last[1], last[2])
        );
        assert_eq!(grid::trilinear(dims, Vec3::ZERO, at), at(0, 0, 0));
    }
    assert!(compared > 10_000, "{compared}");
}

/// [`grid::clamp_to_grid`] is `f32::clamp(x, 0, n − 1)` bit for bit: NaN, ±0, ±∞, and the
/// values around both ends.
#[test]
fn clamps_to_the_grid_as_f32_clamp() {
    let mut xs = vec![
        0.0,
        -0.0,
        f32::NAN,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    xs.extend((0..200).map(|k| k as f32 / 20.0 - 2.0));
    for n in [1usize, 2, 7] {
        let hi = (n - 1) as f32;
        xs.extend([hi, -hi, hi + 1e-6, f32::from_bits(hi.to_bits() + 1)]);
        for &x in &xs {
            let (c, want) = (grid::clamp_to_grid(x, n), x.clamp(0.0, hi));
            assert_eq!(
                c.to_bits(),
                want.to_bits(),
                "{x} on {n} points: {c} vs {want}"
            );
        }
    }
}

/// Each triangle of `s` by its corners' positions and normals, bit for bit.
fn triangle_set(s: &IsoSurface) -> std::collections::HashSet<[[u32; 6]; 3]> {
    (s.mesh.triangles.iter())
        .map(|t| {
            t.map(|v| {
                let (p, n) = (s.mesh.positions[v as usize], s.normals[v as usize]);
                [p.x, p.y, p.z, n.x, n.y, n.z].map(f32::to_bits)
            })
        })
        .collect()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
    /// Random noise volumes (many islands, touching along edges and at corners): keeping the k
    /// largest islands keeps some of the full surface's triangles, vertex for vertex and
    /// normal for normal, closed and oriented, more of them for each k, all of them for every
    /// island and none for no island; keeping those of at least n voxels is keeping the largest
    /// as many as are that large.
    #[test]
    fn kept_islands_are_the_full_surface_s_pieces(seed in 0u64..u64::MAX, dims in (2usize..9, 2usize..9, 2usize..9)) {
        // Mostly outside, so that the inside falls apart into islands.
        let vol = noise(seed, [dims.0, dims.1, dims.2], [0.7, 1.0, 1.3], rotation(), -500.0);
        let full = extract_isosurface(&vol, 0.5);
        let all = triangle_set(&full);
        let (_, islands) = extract_isosurface_keeping(&vol, 0.5, KeepIslands::AtLeast(0));
        let count = islands.sizes.len();
        proptest::prop_assert!(islands.sizes.windows(2).all(|w| w[0] >= w[1]));
        proptest::prop_assert_eq!(islands.sizes.iter().sum::<usize>(),
            vol.data.iter().filter(|&&v| v >= 0.5).count());
        let mut last = 0;
        for k in 0..=count + 1 {
            let (kept, found) = extract_isosurface_keeping(&vol, 0.5, KeepIslands::Largest(k));
            proptest::prop_assert_eq!(&found.sizes, &islands.sizes);
            proptest::prop_assert_eq!(found.kept, k.min(count));
            proptest::prop_assert_eq!(found.kept_voxels, islands.sizes[..k.min(count)].iter().sum::<usize>());
            let set = triangle_set(&kept);
            proptest::prop_assert_eq!(set.len(), kept.mesh.len());
            proptest::prop_assert!(set.is_subset(&all));
            proptest::prop_assert!(k == 0 || k > count || set.len() > last, "island {} added no triangle", k);
            if k >= count {
                proptest::prop_assert_eq!(set.len(), all.len());
            }
            if k > 0 {
                assert_closed_and_oriented(&kept.mesh);
            }
            last = set.len();
            if k > 0 && k <= count {
                let n = islands.sizes[k - 1];
                let ties = islands.sizes.iter().filter(|&&s| s == n).count();
                let at_least = extract_isosurface_keeping(&vol, 0.5, KeepIslands::AtLeast(n)).0;
                let as_many = islands.sizes.iter().filter(|&&s| s >= n).count();
                let largest = extract_isosurface_keeping(&vol, 0.5, KeepIslands::Largest(as_many)).0;
                proptest::prop_assert_eq!(triangle_set(&at_least), triangle_set(&largest), "{} ties", ties);
            }
        }
        proptest::prop_assert_eq!(last, all.len());
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    /// Random noise volumes, mostly inside (so that the outside falls apart into pockets, some
    /// touching along edges and at corners): filling the cavities takes away the full
    /// surface's triangles of the pockets closed all round and no others: what it takes away
    /// is as many closed shells as it filled cavities, each facing in; what is left is closed,
    /// oriented, with no shell facing in, and encloses the full surface's volume and the
    /// cavities'. The islands then hold the cavities' voxels.
    #[test]
    fn filled_cavities_are_the_full_surface_s_inward_shells(seed in 0u64..u64::MAX, dims in (2usize..9, 2usize..9, 2usize..9)) {
        let vol = noise(seed, [dims.0, dims.1, dims.2], [0.7, 1.0, 1.3], rotation(), 500.0);
        let full = extract_isosurface(&vol, 0.5);
        let fill = KeepSurface { islands: KeepIslands::AtLeast(0), fill_cavities: true };
        let (filled, found) = extract_isosurface_keeping(&vol, 0.5, fill);
        let (all, kept) = (triangle_set(&full), triangle_set(&filled));
        proptest::prop_assert!(kept.is_subset(&all));
        let inside = vol.data.iter().filter(|&&v| v >= 0.5).count();
        proptest::prop_assert_eq!(found.sizes.iter().sum::<usize>(), inside + found.cavity_voxels);
        proptest::prop_assert_eq!(found.cavities == 0, found.cavity_voxels == 0);
        // The triangles taken away, as a mesh of their own.
        let mut gone = raystream_io::TriMesh::default();
        for t in all.difference(&kept) {
            let base = gone.positions.len() as u32;
            gone.positions.extend(t.iter().map(|c| Vec3::new(f32::from_bits(c[0]), f32::from_bits(c[1]), f32::from_bits(c[2]))));
            gone.triangles.push([base, base + 1, base + 2]);
        }
        let g = gone.measure_surface();
        proptest::prop_assert_eq!(g.shells, found.cavities);
        for p in &g.pieces {
            proptest::prop_assert!(p.closed() && p.volume.unwrap() < 0.0, "{:?}", p);
        }
        if !filled.mesh.is_empty() {
            assert_closed_and_oriented(&filled.mesh);
        }
        let left = filled.mesh.measure_surface();
        proptest::prop_assert!(left.pieces.iter().all(|p| p.volume.unwrap() > 0.0), "{:?}", left.pieces);
        let before = full.mesh.measure_surface().volume.unwrap_or(0.0);
        let after = left.volume.unwrap_or(0.0);
        let holes = -g.volume.unwrap_or(0.0);
        proptest::prop_assert!((after - before - holes).abs() <= 1e-9 * before.abs().max(1.0), "{} {} {}", before, after, holes);
    }
}

/// A hollow ball (radii 8 and 4 voxels), a smaller ball and a speck: the largest island keeps
/// the hollow ball's two surfaces (outer and inner: one island, its hollow inside), enclosing
/// its shell's volume; at least 30 voxels, the smaller ball too; the speck goes with both.
#[test]
fn the_largest_island_keeps_its_hollow() {
    let d = raystream_math::DVec3::new;
    let (hollow, ball, speck) = (
        d(12.0, 12.0, 12.0),
        d(30.0, 12.0, 12.0),
        d(30.0, 30.0, 12.0),
    );
    let vol = analytic(
        [40, 40, 24],
        [1.0; 3],
        [0.0; 3],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        |p| {
            let r = (p - hollow).length();
            let shell = (8.0 - r).min(r - 4.0);
            let small = 3.0 - (p - ball).length();
            let tiny = 0.6 - (p - speck).length();
            shell.max(small).max(tiny) as f32
        },
    );
    let full = extract_isosurface(&vol, 0.0);
    let whole = full.mesh.measure_surface();
    assert_eq!(whole.shells, 4);
    let (one, islands) = extract_isosurface_keeping(&vol, 0.0, KeepIslands::Largest(1));
    assert_eq!(islands.sizes.len(), 3);
    assert_eq!(islands.sizes[2], 1, "the speck: {:?}", islands.sizes);
    let kept = one.mesh.measure_surface();
    assert!(kept.closed());
    assert_eq!((kept.shells, kept.genus()), (2, Some(0)));
    let pi = std::f64::consts::PI;
    let shell = 4.0 / 3.0 * pi * (8f64.powi(3) - 4f64.powi(3));
    let v = kept.volume.unwrap();
    assert!((v / shell - 1.0).abs() < 0.03, "{v} for {shell}");
    // Every kept vertex is the hollow ball's.
    for p in &one.mesh.positions {
        assert!((p.as_dvec3() - hollow).length() < 8.5, "{p}");
    }
    // Two voxels touching along an edge only: two surfaces, as the marching cubes part them
    // (an ambiguous face separates its inside corners), so two islands.
    let mut pair = Volume::hounsfield([4, 4, 4], [1.0; 3], vec![-1.0; 64]);
    pair.data[1 + 4 * (1 + 4)] = 1.0;
    pair.data[2 + 4 * (2 + 4)] = 1.0;
    let (both, found) = extract_isosurface_keeping(&pair, 0.0, KeepIslands::AtLeast(0));
    assert_eq!(
        (both.mesh.measure_surface().shells, found.sizes),
        (2, vec![1, 1])
    );
    let (two, islands) = extract_isosurface_keeping(&vol, 0.0, KeepIslands::AtLeast(30));
    assert_eq!((islands.kept, two.mesh.measure_surface().shells), (2, 3));
    let small = 4.0 / 3.0 * pi * 27.0;
    let v2 = two.mesh.measure_surface().volume.unwrap();
    assert!(
        ((v2 - v) / small - 1.0).abs() < 0.1,
        "{} for {small}",
        v2 - v
    );
}
