//! Micro-benchmarks of the kd-tree (criterion): both builders on the Stanford bunny (in
//! parallel, as they always run), and on one thread the CPU traversals over coherent (camera)
//! and incoherent (random, from the surface) rays, and the watertight triangle test alone.
//! `cargo bench -p raystream-accel` (a filter after `--` picks groups, e.g. `-- closest/`).
//!
//! Whole-program figures (rayon on every core, the GPU, nodes and triangles per ray) come from
//! `raystream bench`; these isolate one routine so that a change to it shows on its own.
//! The rays' hits are checked against the brute-force oracle before anything is timed.

use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use raystream_accel::{Builder, Hit, KdTree, Traversal, brute};
use raystream_io::{TriMesh, load_mesh};
use raystream_math::{Ray, Vec3};

const MESH: &str = "stanford_bunny.ply";
/// Camera rays: a SIDE × SIDE image of the mesh's bounding sphere.
const SIDE: usize = 64;

fn mesh() -> TriMesh {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/meshes")
        .join(MESH);
    load_mesh(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A small deterministic generator (xorshift64*), so that every run times the same rays.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A uniformly distributed unit vector.
    fn unit(&mut self) -> Vec3 {
        let z = 2.0 * self.next() - 1.0;
        let phi = std::f32::consts::TAU * self.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

/// Primary rays of a pinhole camera on +z looking at the bounding sphere, which fills the image.
fn camera_rays(mesh: &TriMesh) -> Vec<Ray> {
    let b = mesh.bounds();
    let (c, r) = (b.center(), b.radius());
    let eye = c + Vec3::new(0.0, 0.0, 3.0 * r);
    let half = r / (3.0 * r); // tan of the half angle at distance 3r
    let mut rays = Vec::with_capacity(SIDE * SIDE);
    for y in 0..SIDE {
        for x in 0..SIDE {
            let px = ((x as f32 + 0.5) / SIDE as f32 * 2.0 - 1.0) * half;
            let py = (1.0 - (y as f32 + 0.5) / SIDE as f32 * 2.0) * half;
            rays.push(Ray::new(eye, Vec3::new(px, py, -1.0), 0.0, f32::INFINITY));
        }
    }
    rays
}

/// Incoherent rays: from each camera hit, nudged back along its ray, in a random direction.
fn random_rays(tree: &KdTree, camera: &[Ray]) -> Vec<Ray> {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let eps = 1e-4 * tree.bounds.radius();
    camera
        .iter()
        .filter_map(|ray| {
            let hit = tree.intersect(ray, Traversal::Ropes)?;
            let d = ray.dir.normalize();
            let p = ray.at(hit.t) - d * eps;
            Some(Ray::new(p, rng.unit(), 0.0, f32::INFINITY))
        })
        .collect()
}

/// Panics unless the tree's closest hits on `rays` are the brute-force oracle's (t within a
/// relative 1e-5: a tie at a shared edge may pick either triangle).
fn check(tree: &KdTree, corners: &[[Vec3; 3]], rays: &[Ray], what: &str) {
    let mut out = vec![None; rays.len()];
    tree.intersect_many(rays, Traversal::Ropes, false, &mut out);
    for (i, (ray, got)) in rays.iter().zip(&out).enumerate() {
        let want: Option<Hit> = brute::closest(corners, ray);
        match (got, want) {
            (None, None) => {}
            (Some(g), Some(w)) if (g.t - w.t).abs() <= 1e-5 * w.t.abs().max(1e-6) => {}
            _ => panic!("{what} ray {i}: kd-tree {got:?}, brute force {want:?}"),
        }
    }
}

fn benches(c: &mut Criterion) {
    let mesh = mesh();
    let corners: Vec<[Vec3; 3]> = (0..mesh.len()).map(|i| mesh.corners(i)).collect();

    let mut g = c.benchmark_group("build");
    g.sample_size(10)
        .measurement_time(std::time::Duration::from_secs(8));
    for builder in [Builder::Sah, Builder::Median] {
        g.bench_function(BenchmarkId::new(builder.name(), MESH), |b| {
            b.iter(|| KdTree::build(black_box(&mesh), builder))
        });
    }
    g.finish();

    let tree = KdTree::build(&mesh, Builder::Sah);
    let camera = camera_rays(&mesh);
    let random = random_rays(&tree, &camera);
    assert!(
        random.len() > camera.len() / 4,
        "the camera sees too little of {MESH}: {} hits of {}",
        random.len(),
        camera.len()
    );
    check(&tree, &corners, &camera, "camera");
    check(&tree, &corners, &random, "random");

    for (set, rays) in [("camera", &camera), ("random", &random)] {
        let mut g = c.benchmark_group(format!("closest/{set}"));
        g.throughput(Throughput::Elements(rays.len() as u64));
        let mut out = vec![None; rays.len()];
        g.bench_function("ropes, one ray at a time", |b| {
            b.iter(|| {
                for (ray, o) in rays.iter().zip(out.iter_mut()) {
                    *o = tree.intersect(black_box(ray), Traversal::Ropes);
                }
            })
        });
        g.bench_function("ropes, eight interleaved", |b| {
            b.iter(|| tree.intersect_many(black_box(rays), Traversal::Ropes, false, &mut out))
        });
        g.bench_function("stack", |b| {
            b.iter(|| tree.intersect_many(black_box(rays), Traversal::Stack, false, &mut out))
        });
        g.finish();
    }

    let mut g = c.benchmark_group("any/random");
    g.throughput(Throughput::Elements(random.len() as u64));
    let mut out = vec![None; random.len()];
    for traversal in [Traversal::Ropes, Traversal::Stack] {
        g.bench_function(traversal.name(), |b| {
            b.iter(|| tree.intersect_many(black_box(&random), traversal, true, &mut out))
        });
    }
    g.finish();

    // The watertight test alone: one camera ray against every triangle reference of the tree.
    let mut g = c.benchmark_group("triangle");
    g.measurement_time(std::time::Duration::from_secs(8));
    g.throughput(Throughput::Elements(tree.tris.len() as u64));
    let wt = raystream_accel::intersect::WatertightRay::new(&camera[camera.len() / 2]);
    g.bench_function("watertight", |b| {
        b.iter(|| {
            tree.tris
                .iter()
                .filter(|t| wt.intersect_tri(black_box(t), 0.0, f32::INFINITY).is_some())
                .count()
        })
    });
    g.finish();
}

criterion_group!(kdtree, benches);
criterion_main!(kdtree);
