use std::path::Path;

use proptest::prelude::*;
use raystream_io::{TriMesh, load_mesh};
use raystream_math::{Aabb, Ray, Vec3};

use crate::build;
use crate::layout::KdTri;
use crate::{Builder, DEFAULT_TRAVERSAL_COST, Hit, Isa, KdTree, Traversal, brute};

const BUILDERS: [Builder; 2] = [Builder::Sah, Builder::Median];
const TRAVERSALS: [Traversal; 2] = [Traversal::Ropes, Traversal::Stack];

fn corners(mesh: &TriMesh) -> Vec<[Vec3; 3]> {
    (0..mesh.len()).map(|i| mesh.corners(i)).collect()
}

fn shared_mesh(name: &str) -> TriMesh {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/meshes")
        .join(name);
    load_mesh(&p).unwrap()
}

/// xorshift: deterministic, dependency-free numbers for ray sets.
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn unit(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(self.next(), self.next(), self.next()) * 2.0 - 1.0;
            if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

/// Compares a tree query with the brute-force oracle over the same watertight test: the same
/// distance exactly (it is the same arithmetic), the same prim unless two triangles tie.
fn check_ray(tree: &KdTree, c: &[[Vec3; 3]], ray: &Ray, what: &str) {
    let want = brute::closest(c, ray);
    for trav in TRAVERSALS {
        let got = tree.intersect(ray, trav);
        match (got, want) {
            (None, None) => {}
            (Some(g), Some(w)) => {
                assert_eq!(g.t, w.t, "{what} {trav:?}: t differs for {ray:?}");
                if g.prim != w.prim {
                    let tie = brute::closest(&[c[g.prim as usize]], &Ray { t_max: w.t, ..*ray });
                    assert!(
                        tie.is_some(),
                        "{what} {trav:?}: prim {} instead of {} for {ray:?}",
                        g.prim,
                        w.prim
                    );
                }
            }
            _ => panic!("{what} {trav:?}: tree {got:?}, brute force {want:?} for {ray:?}"),
        }
        let any = tree.intersect_any(ray, trav);
        assert_eq!(
            any.is_some(),
            want.is_some(),
            "{what} {trav:?}: any-hit for {ray:?}"
        );
        if let Some(h) = any {
            assert!(h.t >= ray.t_min && h.t <= ray.t_max);
        }
    }
}

fn rays_through(mesh: &TriMesh, n: usize, seed: u64) -> Vec<Ray> {
    let b = mesh.bounds();
    let mut rng = Rng(seed);
    (0..n)
        .map(|i| {
            let target = b.min + (b.max - b.min) * Vec3::new(rng.next(), rng.next(), rng.next());
            let origin = if i % 3 == 0 {
                // from inside the box: secondary-ray-like
                b.min + (b.max - b.min) * Vec3::new(rng.next(), rng.next(), rng.next())
            } else {
                b.center() + rng.unit() * 2.0 * b.radius()
            };
            let mut d = target - origin;
            if i % 7 == 0 {
                d[i % 3] = 0.0; // axis-parallel components
            }
            Ray::new(origin, d, 0.0, f32::INFINITY)
        })
        .collect()
}

#[test]
fn real_meshes_agree_with_brute_force_and_validate() {
    for name in ["spot.obj", "utah_teapot.obj", "goblet_vase.stl"] {
        let mesh = shared_mesh(name);
        let c = corners(&mesh);
        for builder in BUILDERS {
            let tree = KdTree::build(&mesh, builder);
            tree.validate(&c)
                .unwrap_or_else(|e| panic!("{name} {builder:?}: {e}"));
            for ray in rays_through(&mesh, 1500, 7) {
                check_ray(&tree, &c, &ray, name);
            }
        }
    }
}

/// The instruction sets this processor runs the batched queries in. Under `CI=true` an x86-64
/// machine must have x86-64-v3, so that its copy of the queries is tested there.
fn isas() -> Vec<Isa> {
    if cfg!(target_arch = "x86_64") && std::env::var("CI").is_ok_and(|v| v == "true") {
        assert!(
            Isa::X86_64V3.available(),
            "CI=true: this x86-64 processor lacks x86-64-v3, whose queries would go untested"
        );
    }
    Isa::ALL.into_iter().filter(|isa| isa.available()).collect()
}

/// A hit's bytes, so that a hit at −0 differs from one at +0.
fn hit_bits(h: &Option<Hit>) -> Option<[u32; 4]> {
    h.map(|h| [h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()])
}

/// An answer no query gives, set where a query's answers go before it runs.
const STALE: Hit = Hit {
    t: -1.0,
    prim: u32::MAX,
    u: 2.0,
    v: 2.0,
};

/// The batched queries (interleaved rope walks), in every instruction set the processor has,
/// answer every ray exactly as one-ray queries do, byte for byte, closest and any hit, with
/// both traversals.
fn check_batched(tree: &KdTree, rays: &[Ray], what: &str) {
    for trav in TRAVERSALS {
        for any in [false, true] {
            let all = tree.intersect_all(rays, trav, any);
            // Answers kept from other queries, longer and shorter: every ray's is written
            // over them (none is set before a query).
            for len in [rays.len() + 3, rays.len() / 2] {
                let mut kept = vec![Some(STALE); len];
                tree.intersect_all_into(rays, trav, any, &mut kept);
                let is = format!("{what} {trav:?} any={any}, over {len} stale answers");
                assert_eq!(kept.len(), rays.len(), "{is}");
                for (k, a) in kept.iter().zip(&all) {
                    assert_eq!(hit_bits(k), hit_bits(a), "{is}");
                }
            }
            for isa in isas() {
                let mut got = vec![Some(STALE); rays.len()];
                tree.intersect_many_in(isa, rays, trav, any, &mut got);
                for ((ray, g), a) in rays.iter().zip(&got).zip(&all) {
                    let want = if any {
                        tree.intersect_any(ray, trav)
                    } else {
                        tree.intersect(ray, trav)
                    };
                    let is = format!("{what} {trav:?} any={any} {}", isa.name());
                    assert_eq!(hit_bits(g), hit_bits(&want), "{is}: {ray:?}");
                    assert_eq!(hit_bits(a), hit_bits(&want), "{is}, all: {ray:?}");
                }
            }
        }
    }
}

#[test]
fn batched_queries_equal_one_ray_queries() {
    for name in ["stanford_bunny.ply", "utah_teapot.obj"] {
        let mesh = shared_mesh(name);
        let tree = KdTree::build(&mesh, Builder::Sah);
        let mut rays = rays_through(&mesh, 5003, 3);
        // Rays that cannot hit, mixed in: invalid, NaN, pointing away, empty interval.
        let b = mesh.bounds();
        let away = Ray::new(b.max + 1.0, Vec3::ONE, 0.0, f32::INFINITY);
        for (k, bad) in [
            Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, f32::INFINITY),
            Ray::new(Vec3::NAN, Vec3::X, 0.0, f32::INFINITY),
            away,
            Ray {
                t_max: -1.0,
                ..rays[0]
            },
        ]
        .into_iter()
        .enumerate()
        {
            rays.insert(k * 97, bad);
        }
        // Every length around the lane count, down to no rays at all.
        for n in [0, 1, 7, 8, 9, 100] {
            check_batched(&tree, &rays[..n], name);
        }
        check_batched(&tree, &rays, name);
        assert!(
            tree.intersect_all(&rays, Traversal::Ropes, false)
                .iter()
                .filter(|h| h.is_some())
                .count()
                > rays.len() / 4,
            "{name}: the rays should hit the mesh often"
        );
    }
}

#[test]
fn large_meshes_validate() {
    for name in ["stanford_bunny.ply", "turbine_blade.ply"] {
        let mesh = shared_mesh(name);
        let c = corners(&mesh);
        let tree = KdTree::build(&mesh, Builder::Sah);
        tree.validate(&c).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(
            tree.stats.triangles,
            mesh.len() - c.iter().filter(|t| crate::is_degenerate(t)).count()
        );
        for ray in rays_through(&mesh, 300, 11) {
            check_ray(&tree, &c, &ray, name);
        }
    }
}

/// Large nodes bin and partition their references in parallel runs; the tree is the one a
/// single pass over them builds, node for node and reference for reference (both builders,
/// every node of 512 references or more split in runs against none).
#[test]
fn parallel_splits_build_the_same_tree() {
    let mesh = shared_mesh("stanford_bunny.ply");
    let c = corners(&mesh);
    let prims: Vec<u32> = (0..c.len() as u32)
        .filter(|&i| !crate::is_degenerate(&c[i as usize]))
        .collect();
    let bounds = c.iter().flatten().fold(Aabb::EMPTY, |b, &p| b.grow(p));
    for builder in BUILDERS {
        let tree = |split_min| build::build_splitting(&c, &prims, bounds, builder, 1.0, split_min);
        assert!(
            tree(512) == tree(usize::MAX),
            "{builder:?}: runs in parallel changed the tree"
        );
    }
}

#[test]
fn a_scene_box_on_a_negative_zero_is_the_same_in_any_order() {
    // Corners at −0 and +0 on the box's faces: the parallel reduction may meet them in any
    // order, and min(−0, +0) may be either; the box (and so the tree's bytes) must not.
    let (n, p) = (-0.0f32, 0.0f32);
    let tri = |a: f32, b: f32| {
        [
            Vec3::new(a, b, 1.0),
            Vec3::new(1.0, a, b),
            Vec3::new(b, 1.0, a),
        ]
    };
    let forward: Vec<[Vec3; 3]> = (0..5000)
        .map(|i| if i % 2 == 0 { tri(n, p) } else { tri(p, n) })
        .collect();
    let backward: Vec<[Vec3; 3]> = forward.iter().rev().copied().collect();
    let bits = |t: &KdTree| [t.bounds.min, t.bounds.max].map(|v| v.to_array().map(f32::to_bits));
    let zero = bits(&KdTree::build_from_corners(&forward, Builder::Sah));
    assert_eq!(zero[0], [0; 3], "the box's low corner is +0");
    assert_eq!(
        zero,
        bits(&KdTree::build_from_corners(&backward, Builder::Sah))
    );
}

#[test]
fn sah_beats_median() {
    let mesh = shared_mesh("stanford_bunny.ply");
    let sah = KdTree::build(&mesh, Builder::Sah);
    let median = KdTree::build(&mesh, Builder::Median);
    assert!(
        sah.stats.sah_cost < 0.8 * median.stats.sah_cost,
        "SAH cost {} vs median {}",
        sah.stats.sah_cost,
        median.stats.sah_cost
    );
}

#[test]
fn empty_and_degenerate_scenes() {
    let flat = [[Vec3::ZERO, Vec3::X, Vec3::X * 2.0], [Vec3::ONE; 3]];
    let tree = KdTree::build_from_corners(&flat, Builder::Sah);
    tree.validate(&flat).unwrap();
    let ray = Ray::new(Vec3::new(0.5, 0.0, -1.0), Vec3::Z, 0.0, f32::INFINITY);
    assert_eq!(tree.intersect(&ray, Traversal::Ropes), None);
    let tree = KdTree::build_from_corners(&[], Builder::Median);
    assert_eq!(tree.intersect(&ray, Traversal::Stack), None);
}

#[test]
fn one_triangle_and_its_contract() {
    let tri = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    for builder in BUILDERS {
        let tree = KdTree::build_from_corners(&tri, builder);
        tree.validate(&tri).unwrap();
        for trav in TRAVERSALS {
            let ray = Ray::new(
                Vec3::new(0.25, 0.5, 2.0),
                Vec3::new(0.0, 0.0, -2.0),
                0.0,
                f32::INFINITY,
            );
            let h = tree.intersect(&ray, trav).unwrap();
            assert_eq!((h.t, h.prim, h.u, h.v), (1.0, 0, 0.25, 0.5));
            // t-range is inclusive on both ends, and exclusive beyond
            assert!(tree.intersect(&Ray { t_max: 1.0, ..ray }, trav).is_some());
            assert!(tree.intersect(&Ray { t_min: 1.0, ..ray }, trav).is_some());
            assert!(
                tree.intersect(
                    &Ray {
                        t_max: 0.999,
                        ..ray
                    },
                    trav
                )
                .is_none()
            );
            assert!(
                tree.intersect(
                    &Ray {
                        t_min: 1.001,
                        ..ray
                    },
                    trav
                )
                .is_none()
            );
            // invalid rays miss
            for bad in [
                Ray {
                    dir: Vec3::ZERO,
                    ..ray
                },
                Ray {
                    origin: Vec3::new(f32::NAN, 0.5, 2.0),
                    ..ray
                },
                Ray {
                    dir: Vec3::new(0.0, f32::NAN, -1.0),
                    ..ray
                },
                Ray {
                    t_max: f32::NAN,
                    ..ray
                },
                Ray {
                    t_min: f32::NEG_INFINITY,
                    ..ray
                },
                Ray {
                    origin: Vec3::new(f32::INFINITY, 0.5, 2.0),
                    ..ray
                },
            ] {
                assert_eq!(tree.intersect(&bad, trav), None, "{bad:?}");
                assert_eq!(tree.intersect_any(&bad, trav), None, "{bad:?}");
            }
            // edges and vertices count as inside
            let edge = Ray::new(Vec3::new(0.5, 0.0, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
            assert!(tree.intersect(&edge, trav).is_some());
            // a ray in the triangle's plane misses
            let planar = Ray::new(Vec3::new(-1.0, 0.25, 0.0), Vec3::X, 0.0, f32::INFINITY);
            assert!(tree.intersect(&planar, trav).is_none());
        }
    }
}

#[test]
fn rays_along_split_planes() {
    // A grid of unit quads: the SAH builder splits on the integer planes the rays run along.
    let mut c = Vec::new();
    for i in 0..8 {
        for j in 0..8 {
            let (x, y) = (i as f32, j as f32);
            let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, (i + j) as f32 * 0.1);
            c.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
            c.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
        }
    }
    for builder in BUILDERS {
        let tree = KdTree::build_from_corners(&c, builder);
        tree.validate(&c).unwrap();
        for i in 0..=8 {
            for j in 0..=8 {
                let o = Vec3::new(i as f32, j as f32, 5.0);
                check_ray(
                    &tree,
                    &c,
                    &Ray::new(o, -Vec3::Z, 0.0, f32::INFINITY),
                    "grid vertical",
                );
                let o = Vec3::new(-1.0, j as f32, 0.05 * i as f32);
                check_ray(
                    &tree,
                    &c,
                    &Ray::new(o, Vec3::new(1.0, 0.0, 0.1), 0.0, f32::INFINITY),
                    "grid slanted",
                );
                let o = Vec3::new(i as f32, -1.0, 0.5);
                check_ray(
                    &tree,
                    &c,
                    &Ray::new(o, Vec3::Y, 0.0, f32::INFINITY),
                    "grid axis-parallel",
                );
            }
        }
    }
}

#[test]
fn watertight_far_from_origin() {
    // Rays from inside a closed sphere never escape, also 1e5 units from the origin where a
    // float's spacing is ~0.008 and a non-watertight test leaks through edges.
    let sphere = TriMesh::icosphere(4);
    for offset in [Vec3::ZERO, Vec3::new(1e5, -3e4, 7e4)] {
        let mut m = TriMesh::default();
        m.append(&sphere, |p| p * 10.0 + offset);
        let tree = KdTree::build(&m, Builder::Sah);
        tree.validate(&corners(&m)).unwrap();
        let mut rng = Rng(99);
        let mut escaped = 0;
        for i in 0..20_000 {
            let origin = offset + rng.unit() * rng.next() * 5.0;
            let mut d = rng.unit();
            if i % 5 == 0 {
                // aim at vertices: the hardest case for cracks
                d = m.positions[i % m.positions.len()] - origin;
            }
            let ray = Ray::new(origin, d, 0.0, f32::INFINITY);
            for trav in TRAVERSALS {
                if tree.intersect(&ray, trav).is_none() {
                    escaped += 1;
                }
            }
        }
        assert_eq!(escaped, 0, "rays escaped the sphere at offset {offset}");
    }
}

#[test]
fn flat_layout_bytes_round_trip() {
    let mesh = shared_mesh("spot.obj");
    let tree = KdTree::build(&mesh, Builder::Sah);
    let bytes: &[u8] = bytemuck::cast_slice(&tree.tris);
    let back: &[KdTri] = bytemuck::cast_slice(bytes);
    assert_eq!(back[0].prim(), tree.tris[0].prim());
    assert!(tree.stats.nodes == tree.inners.len() + tree.leaves.len());
    assert!(tree.stats.max_depth <= crate::depth_limit(mesh.len()));
}

#[test]
fn validate_rejects_a_layout_out_of_depth_first_order() {
    let mesh = shared_mesh("spot.obj");
    let c = corners(&mesh);
    let tree = KdTree::build(&mesh, Builder::Sah);
    assert!(tree.validate(&c).is_ok());
    // Renumber two leaves (the first and the last): the same tree, boxes and ropes, but its
    // leaves are no longer stored in depth-first order.
    let mut swapped = tree.clone();
    let (a, b) = (
        crate::layout::leaf_ref(0),
        crate::layout::leaf_ref(tree.leaves.len() as u32 - 1),
    );
    let relabel = |r: &mut u32| {
        if *r == a {
            *r = b
        } else if *r == b {
            *r = a
        }
    };
    swapped.leaves.swap(0, tree.leaves.len() - 1);
    for n in &mut swapped.inners {
        relabel(&mut n.left);
        relabel(&mut n.right);
    }
    for l in &mut swapped.leaves {
        l.ropes.iter_mut().for_each(relabel);
    }
    let err = swapped.validate(&c).unwrap_err();
    assert!(err.contains("depth-first order"), "{err}");
}

/// The SAH builder's traversal cost shapes the tree (dearer steps: fewer, fuller leaves and
/// a shallower tree) but never the answers: every tree validates and agrees with brute force
/// ray for ray. (Not asserted: that the default tree has the lowest yardstick SAH cost. The
/// greedy builder stops early, and the tree built with steps at 0.5 scores 2 % lower.)
#[test]
fn traversal_cost_shapes_the_tree_not_the_hits() {
    let mesh = shared_mesh("stanford_bunny.ply");
    let c = corners(&mesh);
    let rays = rays_through(&mesh, 1500, 11);
    let trees: Vec<KdTree> = [0.5, DEFAULT_TRAVERSAL_COST, 4.0, 16.0]
        .into_iter()
        .map(|kt| KdTree::build_with(&mesh, Builder::Sah, kt))
        .collect();
    for t in &trees {
        let what = format!("traversal cost {:?}", t.stats.traversal_cost);
        t.validate(&c).unwrap_or_else(|e| panic!("{what}: {e}"));
        for ray in &rays {
            check_ray(t, &c, ray, &what);
        }
        check_batched(t, &rays[..300], &what);
    }
    for w in trees.windows(2) {
        let (a, b) = (&w[0].stats, &w[1].stats);
        assert!(
            b.leaves < a.leaves && b.mean_tris_per_leaf > a.mean_tris_per_leaf,
            "{:?} → {:?}: leaves {} → {}, triangles per leaf {} → {}",
            a.traversal_cost,
            b.traversal_cost,
            a.leaves,
            b.leaves,
            a.mean_tris_per_leaf,
            b.mean_tris_per_leaf
        );
        assert!(b.max_depth <= a.max_depth);
    }
    assert_eq!(
        KdTree::build_with(&mesh, Builder::Median, 4.0)
            .stats
            .traversal_cost,
        None
    );
}

#[test]
#[should_panic(expected = "SAH traversal cost")]
fn traversal_cost_out_of_range_is_refused() {
    KdTree::build_from_corners_with(&[[Vec3::ZERO, Vec3::X, Vec3::Y]], Builder::Sah, 0.0);
}

fn arb_vec(r: f32) -> impl Strategy<Value = Vec3> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_soups_agree_with_brute_force(
        tris in prop::collection::vec((arb_vec(10.0), arb_vec(3.0), arb_vec(3.0)), 1..120),
        rays in prop::collection::vec((arb_vec(15.0), arb_vec(1.0), 0u8..8, 0.0f32..2.0), 64),
    ) {
        let c: Vec<[Vec3; 3]> = tris.iter().map(|&(p, a, b)| [p, p + a, p + b]).collect();
        for builder in BUILDERS {
            let tree = KdTree::build_from_corners(&c, builder);
            prop_assert!(tree.validate(&c).is_ok(), "{:?}", tree.validate(&c));
            let mut soup_rays = Vec::new();
            for &(o, mut d, zero, t_min) in &rays {
                // zero some direction components: axis-parallel rays
                for a in 0..3 {
                    if zero & (1 << a) != 0 && zero != 7 {
                        d[a] = 0.0;
                    }
                }
                // start some rays exactly on a triangle's vertex
                let o = if zero == 7 { c[0][1] } else { o };
                let ray = Ray::new(o, d, if zero == 5 { t_min } else { 0.0 }, f32::INFINITY);
                check_ray(&tree, &c, &ray, "soup");
                soup_rays.push(ray);
            }
            check_batched(&tree, &soup_rays, "soup");
            if !tree.entry.cells.is_empty() {
                soup_rays.extend(rays_on_planes(&tree, 64, tris.len() as u64 + 1));
                check_entry_grid(&tree, &soup_rays, "soup");
            }
        }
    }

    #[test]
    fn watertight_test_agrees_with_f64(
        tri in (arb_vec(5.0), arb_vec(5.0), arb_vec(5.0)),
        o in arb_vec(10.0), d in arb_vec(1.0),
    ) {
        let c = [[tri.0, tri.1, tri.2]];
        let ray = Ray::new(o, d, 0.0, f32::INFINITY);
        if let (Some(h), Some((t, _))) = (brute::closest(&c, &ray), brute::closest_f64(&c, &ray)) {
            prop_assert!(((h.t as f64) - t).abs() <= 1e-3 * t.abs().max(1.0), "{} vs {}", h.t, t);
            let p = c[0][0] * (1.0 - h.u - h.v) + c[0][1] * h.u + c[0][2] * h.v;
            prop_assert!((p - ray.at(h.t)).length() <= 1e-3 * (1.0 + p.length()));
        }
    }
}

/// Ground planes made "infinite" by scaling, seen from 2 units above at angles down to 2° from
/// their plane: a square 10⁶ on a side and a strip 5 wide and 10⁶ long. The projection of a
/// triangle along such a ray is a sliver, where the paper's t (the corners' depths
/// interpolated by the edge functions, which cancel there) was off by up to 2 % on the square
/// and 25× on the strip, where it missed 16 % of the rays. Every ray whose f64 hit lies more
/// than 0.01 inside the quad hits it, through the tree and by the test alone, at the f64 t
/// within 1e-5; on the square its barycentrics give the hit point back within 10⁻⁶ of the
/// quad's size; none more than 0.01 outside the quad hits it, nor any that points away.
#[test]
fn long_ground_planes_are_hit_where_their_planes_are() {
    for (w, l) in [(5e5f32, 5e5f32), (2.5, 5e5)] {
        let mut mesh = TriMesh::ground_quad(1.0);
        for p in &mut mesh.positions {
            *p = *p * Vec3::new(2.0 * w, 1.0, 2.0 * l) - Vec3::Y;
        }
        let tree = KdTree::build(&mesh, Builder::Sah);
        let corners: Vec<[Vec3; 3]> = (0..2).map(|i| mesh.corners(i)).collect();
        let o = Vec3::new(0.0, 1.0, 5.0);
        let (mut hits, mut inside) = (0, 0);
        for i in 0..96 {
            for j in 0..64 {
                // Across the strip's width, 2° to 60° below the horizon, both ways along it.
                let x = -0.6 + 1.2 * i as f32 / 95.0;
                let down = (2.0f32 + 58.0 * j as f32 / 63.0).to_radians().tan();
                for along in [-1.0f32, 1.0] {
                    let d = Vec3::new(x, -down, along).normalize();
                    let ray = Ray::new(o, d, 0.0, f32::INFINITY);
                    let (od, dd) = (o.as_dvec3(), d.as_dvec3());
                    let t = (-1.0 - od.y) / dd.y;
                    let p = od + dd * t;
                    let got = tree.intersect(&ray, Traversal::Ropes);
                    let alone = brute::closest(&corners, &ray);
                    let (side, end) = (p.x.abs() - w as f64, p.z.abs() - l as f64);
                    if side < -0.01 && end < 0.0 {
                        inside += 1;
                        for (h, how) in [(got, "through the tree"), (alone, "alone")] {
                            let h = h.unwrap_or_else(|| panic!("{ray:?} misses {how} at {p:?}"));
                            let err = ((h.t as f64 - t) / t).abs();
                            assert!(err < 1e-5, "{ray:?} {how}: t {} against {t}", h.t);
                            if w == l {
                                let [a, b, c] = corners[h.prim as usize].map(|v| v.as_dvec3());
                                let (u, v) = (h.u as f64, h.v as f64);
                                let q = a * (1.0 - u - v) + b * u + c * v;
                                assert!((q - p).length() < 1e-6 * l as f64, "{ray:?}: {q:?}");
                            }
                        }
                        hits += 1;
                    } else if side > 0.01 {
                        assert!(got.is_none() && alone.is_none(), "{ray:?} hits at {p:?}");
                    }
                    // Pointing away from the plane, above it or below it: no hit.
                    let up = Ray::new(o, Vec3::new(d.x, -d.y, d.z), 0.0, f32::INFINITY);
                    assert!(tree.intersect(&up, Traversal::Ropes).is_none());
                    let below = Ray::new(Vec3::new(0.0, -3.0, 5.0), d, 0.0, f32::INFINITY);
                    assert!(tree.intersect_any(&below, Traversal::Ropes).is_none());
                }
            }
        }
        assert!(
            inside > 6000 && hits == inside,
            "{w} x {l}: {hits} of {inside}"
        );
    }
}

/// Ground quads too large for f32 planes, turned off the axes: the plane through a corner 5 ×
/// 10⁶ away, from the f32 normal, lay 0.3 off where the rays start, 1 above it, so that the
/// tree's t (before `PLANE_T_LEVER`) missed half the rays that hit a strip turned 0.3° and hit
/// a quarter of those that point away from it. From (0, 1, 5), 11° below the horizon ± 22°
/// and along a strip ± 2.6° (a narrow view, so that most rays meet it): every ray whose f64
/// hit lies 10⁻³ of a triangle inside it hits, at the f64 t within 1e-5, through the tree and
/// by the test alone; none whose f64 ray misses by that much does.
#[test]
fn huge_turned_ground_quads_are_hit_where_their_planes_are() {
    use brute::{BIG_TURNED_QUADS, turned_quad_margin};
    for (w, l, degrees) in BIG_TURNED_QUADS {
        let mesh = brute::turned_quad(w, l, degrees);
        let tree = KdTree::build(&mesh, Builder::Sah);
        let corners: Vec<[Vec3; 3]> = (0..2).map(|i| mesh.corners(i)).collect();
        let (mut inside, mut outside) = (0, 0);
        let rays = brute::turned_quad_rays(96, 64);
        // The batched queries in every instruction set, the f64 planes among them.
        check_batched(&tree, &rays, &format!("{w} x {l} turned {degrees}°"));
        for ray in rays {
            let what = format!("{w} x {l} turned {degrees}°: {ray:?}");
            let got = tree.intersect(&ray, Traversal::Ropes);
            let alone = brute::closest(&corners, &ray);
            match brute::verdict_f64(&corners, &ray, turned_quad_margin(w, l)) {
                brute::Verdict::Inside(t) => {
                    inside += 1;
                    for (h, how) in [(got, "through the tree"), (alone, "alone")] {
                        let h = h.unwrap_or_else(|| panic!("{what} misses {how}"));
                        let err = ((h.t as f64 - t) / t).abs();
                        assert!(err < 1e-5, "{what} {how}: t {} against {t}", h.t);
                    }
                    assert!(tree.intersect_any(&ray, Traversal::Ropes).is_some());
                }
                brute::Verdict::Outside => {
                    outside += 1;
                    assert!(got.is_none() && alone.is_none(), "{what} hits: {got:?}");
                    assert!(
                        tree.intersect_any(&ray, Traversal::Ropes).is_none(),
                        "{what}"
                    );
                }
                brute::Verdict::Near => {}
            }
        }
        eprintln!("{w} x {l}: {inside}, {outside}");
        assert!(
            inside > 300 && outside > 1000,
            "{w} x {l}: {inside}, {outside}"
        );
    }
}

/// The same tree's rope walks with its entry grid and without one (every walk from the root):
/// the same hits, bit for bit, the same leaves and triangles visited ray by ray (the walks
/// reach the same first leaf, so all later steps are the same), and never more inner steps.
/// Returns the inner steps with and without the grid.
fn check_entry_grid(tree: &KdTree, rays: &[Ray], what: &str) -> (u64, u64) {
    let mut rooted = tree.clone();
    rooted.set_entry_grid(0);
    assert!(rooted.entry.cells.is_empty());
    let bits =
        |h: Option<crate::Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.u.to_bits(), h.v.to_bits()));
    let (mut with, mut without) = (0, 0);
    for ray in rays {
        for any in [false, true] {
            let (mut a, mut b) = (crate::Counters::default(), crate::Counters::default());
            let ha = tree.intersect_counted(ray, Traversal::Ropes, any, &mut a);
            let hb = rooted.intersect_counted(ray, Traversal::Ropes, any, &mut b);
            assert_eq!(
                bits(ha),
                bits(hb),
                "{what} (any {any}): hits differ for {ray:?}"
            );
            assert_eq!(
                (a.leaves, a.triangles),
                (b.leaves, b.triangles),
                "{what} (any {any}): other leaves for {ray:?}"
            );
            assert!(a.inner <= b.inner, "{what}: more inner steps for {ray:?}");
            with += a.inner;
            without += b.inner;
        }
    }
    (with, without)
}

/// Rays whose entry points lie exactly on the tree's split planes and on the grid's cell
/// boundaries, from inside the box (t_min = 0 there, or a t_min that puts the entry point
/// there) and from outside it.
fn rays_on_planes(tree: &KdTree, n: usize, seed: u64) -> Vec<Ray> {
    let b = tree.bounds;
    let mut rng = Rng(seed);
    let g = &tree.entry;
    (0..n)
        .map(|i| {
            let mut p = b.min + (b.max - b.min) * Vec3::new(rng.next(), rng.next(), rng.next());
            let a = i % 3;
            if i % 2 == 0 {
                let node = &tree.inners[(i * 7919) % tree.inners.len()];
                p[node.axis as usize] = node.split;
            } else if g.res[a] > 0 {
                let cell = (rng.next() * g.res[a] as f32) as u32;
                p[a] = b.min[a] + cell as f32 / g.scale[a];
            }
            let mut d = rng.unit();
            if i % 5 == 0 {
                d[(a + 1) % 3] = 0.0;
            }
            match i % 4 {
                0 | 1 => Ray::new(p, d, 0.0, f32::INFINITY),
                2 => Ray::new(p - d * 3.0, d, 3.0, f32::INFINITY),
                _ => Ray::new(p - d * 2.0 * b.radius(), d, 0.0, f32::INFINITY),
            }
        })
        .collect()
}

#[test]
fn the_entry_grid_gives_the_same_walks_from_fewer_steps() {
    for name in ["stanford_bunny.ply", "spot.obj", "goblet_vase.stl"] {
        let mesh = shared_mesh(name);
        let c = corners(&mesh);
        for builder in BUILDERS {
            let tree = KdTree::build(&mesh, builder);
            tree.validate(&c).unwrap();
            assert!(!tree.entry.cells.is_empty(), "{name}: no entry grid");
            let mut rays = rays_through(&mesh, 3000, 17);
            rays.extend(rays_on_planes(&tree, 3000, 23));
            let (with, without) = check_entry_grid(&tree, &rays, name);
            // Half the rays start inside the box, where the descent is longest.
            assert!(
                (with as f64) < 0.8 * without as f64,
                "{name} {builder:?}: {with} inner steps with the grid, {without} without"
            );
        }
    }
}

#[test]
fn entry_grids_of_any_size_start_at_the_deepest_node_that_holds_the_cell() {
    let mesh = shared_mesh("utah_teapot.obj");
    let c = corners(&mesh);
    let mut tree = KdTree::build(&mesh, Builder::Sah);
    let rays = rays_through(&mesh, 500, 5);
    for res in [1, 2, 7, 32, 255, 256, 1000] {
        tree.set_entry_grid(res);
        let g = &tree.entry;
        assert_eq!(*g.res.iter().max().unwrap(), res.min(crate::entry::MAX_RES));
        tree.validate(&c).unwrap();
        // The one-pass fill against the definition, cell by cell.
        for (k, &node) in g.cells.iter().enumerate() {
            let ijk = g.cell(k);
            let span: [(f64, f64); 3] = std::array::from_fn(|a| g.grown(&tree.bounds, a, ijk[a]));
            let (lo, hi) = (span.map(|s| s.0), span.map(|s| s.1));
            assert_eq!(
                node,
                crate::entry::covering_node(tree.root, &tree.inners, &lo, &hi),
                "{res}: cell {ijk:?}"
            );
        }
        check_entry_grid(&tree, &rays, "teapot");
    }
    // Deeper starts with finer cells.
    tree.set_entry_grid(8);
    let coarse = tree.entry.mean_depth;
    tree.set_entry_grid(128);
    assert!(
        tree.entry.mean_depth > coarse + 3.0,
        "{coarse} → {}",
        tree.entry.mean_depth
    );
}

#[test]
fn entry_grid_edge_cases() {
    // A flat scene: one cell across its thin axis.
    let mut c = Vec::new();
    for i in 0..16 {
        for j in 0..16 {
            let p = |dx: f32, dy: f32| Vec3::new(i as f32 + dx, j as f32 + dy, 0.0);
            c.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
            c.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
        }
    }
    let tree = KdTree::build_from_corners(&c, Builder::Sah);
    tree.validate(&c).unwrap();
    assert_eq!(tree.entry.res, [128, 128, 1]);
    let mut rays = rays_on_planes(&tree, 2000, 3);
    for i in 0..=16 {
        // Straight down onto the quads' shared edges, and from within the plane.
        rays.push(Ray::new(
            Vec3::new(i as f32, 7.5, 3.0),
            -Vec3::Z,
            0.0,
            f32::INFINITY,
        ));
        rays.push(Ray::new(
            Vec3::new(i as f32, 7.5, 0.0),
            Vec3::X,
            0.0,
            f32::INFINITY,
        ));
    }
    check_entry_grid(&tree, &rays, "flat");
    // An origin far away starts at the root (the lookup's rounding could matter there).
    let g = &tree.entry;
    let start = |o: Vec3, t0: f32| {
        g.start(
            tree.root,
            tree.bounds.min.to_array(),
            o.to_array(),
            [0.0, 0.0, -1.0],
            t0,
        )
    };
    assert_ne!(start(Vec3::new(3.5, 3.5, 1.0), 1.0), tree.root);
    assert_eq!(start(Vec3::new(3.5, 3.5, 1e7), 1e7), tree.root);
    // One triangle: the root is a leaf, no grid.
    let one = KdTree::build_from_corners(&c[..1], Builder::Sah);
    assert!(one.entry.cells.is_empty() && one.entry.res == [0; 3]);
    // A corrupted cell is caught.
    let mut bad = tree.clone();
    let k = bad.entry.cells.len() / 2 + 5;
    bad.entry.cells[k] = bad.root;
    let err = bad.validate(&c).unwrap_err();
    assert!(
        err.contains("entry cell") && err.contains("child that holds"),
        "{err}"
    );
    let mut bad = tree.clone();
    let leaf = crate::layout::leaf_ref(0);
    bad.entry.cells[k] = leaf;
    assert!(
        bad.validate(&c)
            .unwrap_err()
            .contains("does not hold the cell")
    );
}

/// `check_links` passes every built tree (empty, one leaf, real meshes, both builders) and
/// catches each index a kernel without bounds checks would follow out of its array, or a
/// cycle that would keep a descent going; `validate` refuses the same trees.
#[test]
fn check_links_catches_every_index_out_of_range() {
    use crate::layout::{LEAF_BIT, NO_ROPE, leaf_ref};
    KdTree::build_from_corners(&[], Builder::Sah)
        .check_links()
        .unwrap();
    let mesh = shared_mesh("spot.obj");
    let c = corners(&mesh);
    KdTree::build_from_corners(&c[..1], Builder::Sah)
        .check_links()
        .unwrap();
    for builder in BUILDERS {
        KdTree::build(&mesh, builder).check_links().unwrap();
    }
    let tree = KdTree::build(&mesh, Builder::Sah);
    let (n, l, tris) = (
        tree.inners.len() as u32,
        tree.leaves.len() as u32,
        tree.tris.len() as u32,
    );
    let mid = tree.inners.len() / 2;
    let leaf = tree.leaves.len() / 2;
    type Break = Box<dyn Fn(&mut KdTree)>;
    let breaks: Vec<(&str, Break, &str)> = vec![
        ("root", Box::new(move |t| t.root = n), "root"),
        ("leaf root", Box::new(move |t| t.root = leaf_ref(l)), "root"),
        ("axis", Box::new(move |t| t.inners[mid].axis = 3), "axis 3"),
        ("child", Box::new(move |t| t.inners[mid].right = n), "child"),
        (
            "leaf child",
            Box::new(move |t| t.inners[mid].left = leaf_ref(l + 7)),
            "child",
        ),
        // A cycle: an inner node whose child is itself or an earlier node.
        (
            "cycle",
            Box::new(move |t| t.inners[mid].left = mid as u32),
            "child",
        ),
        ("back", Box::new(move |t| t.inners[mid].right = 0), "child"),
        (
            "range",
            Box::new(move |t| t.leaves[leaf].first = tris - t.leaves[leaf].count + 1),
            "triangles",
        ),
        (
            "overflow",
            Box::new(move |t| {
                t.leaves[leaf].first = u32::MAX;
                t.leaves[leaf].count = 2;
            }),
            "triangles",
        ),
        (
            "rope",
            Box::new(move |t| t.leaves[leaf].ropes[3] = LEAF_BIT | l),
            "rope",
        ),
        (
            "inner rope",
            Box::new(move |t| t.leaves[leaf].ropes[0] = n + 1),
            "rope",
        ),
        (
            "cell",
            Box::new(move |t| *t.entry.cells.last_mut().unwrap() = n),
            "entry cell",
        ),
        (
            "cells",
            Box::new(|t| {
                t.entry.cells.pop();
            }),
            "entry grid",
        ),
        (
            "res",
            Box::new(|t| t.entry.res[2] = crate::entry::MAX_RES + 1),
            "entry grid",
        ),
        (
            "scale",
            Box::new(|t| t.entry.scale[1] = f32::NAN),
            "entry grid",
        ),
        (
            "box",
            Box::new(|t| t.bounds.min.x = f32::NEG_INFINITY),
            "entry grid",
        ),
    ];
    for (what, break_it, says) in breaks {
        let mut bad = tree.clone();
        break_it(&mut bad);
        let err = bad.check_links().unwrap_err();
        assert!(err.contains(says), "{what}: {err}");
        assert!(bad.validate(&c).is_err(), "{what}");
    }
    // What stays in range passes, even where `validate` would object: a rope to the exit.
    let mut ok = tree.clone();
    ok.leaves[leaf].ropes[0] = NO_ROPE;
    ok.check_links().unwrap();
}
