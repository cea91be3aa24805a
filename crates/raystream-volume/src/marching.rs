//! Marching cubes on a CT volume, in parallel over z-layers, with shared vertices.
//!
//! The volume is padded by one layer of "outside" on every side, so a structure cut by the
//! volume's border is closed by a flat cap there and every surface is closed. Vertices sit on
//! cell edges at the linear interpolation of the iso crossing (kept 1/256 voxel off the edge's
//! ends, so that no two share a point); each crossing edge gets exactly one vertex (keyed by
//! the edge), so neighbouring cells share vertices and the mesh has no cracks. Normals are the
//! negated value gradient (central differences in index space, taken into LPS by the inverse
//! transpose of the grid's matrix, so sheared grids too), interpolated along the edge: they
//! point out of the inside region.
//!
//! Three passes, each parallel over z: (1) the inside mask; (2) per layer, the vertices of the
//! edges leaving that layer's corners, in key order; (3) per layer of cells, the triangles, their
//! vertex keys resolved by binary search in the two layers' vertex lists.

use rayon::prelude::*;
use raystream_io::{TriMesh, Volume};
use raystream_math::{DVec3, I64Vec3, Vec3};

use crate::cases::{CASES, EDGE_START};
use crate::islands::{Islands, KeepIslands, KeepSurface, fill_cavities, keep_islands};

/// A triangle mesh in LPS millimetres with per-vertex unit normals (from the volume gradient,
/// pointing out of the region at or above the threshold).
#[derive(Clone, Debug, Default)]
pub struct IsoSurface {
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
}

/// How near, in voxels, a vertex may come to either end of its cell edge. A CT stores integers
/// and a threshold is often one of them (300 HU): a voxel exactly at it would put the vertex of
/// every crossing edge it starts on its centre, several vertices on one point and triangles of
/// no area, which a simplifier takes for a seam (meshoptimizer kept the chest CT's bones open
/// along such points) and a printer's slicer for a fault. Kept this far in, every vertex has a
/// point of its own (1/256 voxel: a few micrometres on a CT, some hundred f32 steps at half a
/// metre from the origin). The flat caps at the volume's border sit half this far inside it, so
/// that a border voxel's edges to the padding (up to three, at a corner) keep apart too.
const EDGE_MARGIN: f64 = 1.0 / 256.0;

struct Layer {
    keys: Vec<u64>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
}

/// Extracts the surface `value = iso` of `vol`, oriented out of the region `value ≥ iso`
/// (NaN voxels count as outside).
pub fn extract_isosurface(vol: &Volume, iso: f32) -> IsoSurface {
    extract_isosurface_keeping(vol, iso, KeepIslands::All).0
}

/// [`extract_isosurface`] of the islands of the region `value ≥ iso` that `keep` keeps (each
/// voxel joined to the six that share a face with it: [`KeepIslands`]), its cavities filled
/// first where it says so ([`KeepSurface`]), with the islands and cavities found. The surface
/// is the full one's triangles of those islands, vertex for vertex, less those of the
/// cavities filled.
pub fn extract_isosurface_keeping(
    vol: &Volume,
    iso: f32,
    keep: impl Into<KeepSurface>,
) -> (IsoSurface, Islands) {
    let keep: KeepSurface = keep.into();
    // A lone slice (one voxel along an axis): the surface of the slab of tissue it images, a
    // spacing thick (`Volume::slab_of_lone_slices`, as the volume renderers take it), where
    // its own grid's would be a sheet whose caps, each kept a hair inside its side, cross:
    // inside out. The slab holds each voxel `per` times (two equal layers along each such
    // axis), so the islands are counted in the slice's voxels.
    if let Some(slab) = vol.slab_of_lone_slices() {
        let per = 1usize << vol.dims.iter().filter(|&&n| n == 1).count();
        let islands = match keep.islands {
            KeepIslands::AtLeast(n) => KeepIslands::AtLeast(n.saturating_mul(per)),
            islands => islands,
        };
        let (surface, found) =
            extract_isosurface_keeping(&slab, iso, KeepSurface { islands, ..keep });
        let found = Islands {
            sizes: found.sizes.iter().map(|n| n / per).collect(),
            kept: found.kept,
            kept_voxels: found.kept_voxels / per,
            cavities: found.cavities,
            cavity_voxels: found.cavity_voxels / per,
        };
        return (surface, found);
    }
    let [nx, ny, nz] = vol.dims;
    // Padded grid: corner (I, J, K) is voxel (I − 1, J − 1, K − 1); the border is outside.
    let (px, py, pz) = (nx + 2, ny + 2, nz + 2);
    let layer_len = px * py;
    let mut mask = vec![0u8; layer_len * pz];
    mask.par_chunks_mut(layer_len)
        .enumerate()
        .for_each(|(kk, layer)| {
            if kk == 0 || kk == pz - 1 {
                return;
            }
            let k = kk - 1;
            for j in 0..ny {
                let row = &vol.data[nx * (j + ny * k)..][..nx];
                let out = &mut layer[px * (j + 1) + 1..][..nx];
                for (o, &v) in out.iter_mut().zip(row) {
                    *o = (v >= iso) as u8;
                }
            }
        });
    let (cavities, cavity_voxels) = match keep.fill_cavities {
        true => fill_cavities(&mut mask, [px, py, pz]),
        false => (0, 0),
    };
    let islands = match keep.islands {
        KeepIslands::All => Islands::default(),
        islands => keep_islands(&mut mask, [px, py, pz], islands),
    };
    let islands = Islands {
        cavities,
        cavity_voxels,
        ..islands
    };
    // Per padded row (J, K): whether any corner in it is inside. Most CT rows hold no bone, and
    // a cell or edge row can be skipped when the rows it touches are all empty.
    let row_any: Vec<bool> = mask
        .par_chunks(px)
        .map(|row| row.iter().any(|&m| m != 0))
        .collect();
    let row = |j: usize, k: usize| j < py && k < pz && row_any[j + py * k];
    let affine = vol.index_to_world_affine();
    // ∂f/∂world = (M⁻¹)ᵀ ∂f/∂index for the index → world matrix M (direction · spacing): right
    // for sheared grids too (a gantry-tilted CT), where rotating the per-mm differences is not.
    let index_to_world_grad = affine.matrix3.inverse().transpose();
    let value = |i: usize, j: usize, k: usize| vol.data[i + nx * (j + ny * k)];
    // Gradient at a voxel in LPS (value units per mm), one-sided at the border.
    let gradient = |i: usize, j: usize, k: usize| -> DVec3 {
        let d = |lo: f32, hi: f32, span: f64| (hi - lo) as f64 / span;
        let gi = d(
            value(i.saturating_sub(1), j, k),
            value((i + 1).min(nx - 1), j, k),
            ((i + 1).min(nx - 1) - i.saturating_sub(1)).max(1) as f64,
        );
        let gj = d(
            value(i, j.saturating_sub(1), k),
            value(i, (j + 1).min(ny - 1), k),
            ((j + 1).min(ny - 1) - j.saturating_sub(1)).max(1) as f64,
        );
        let gk = d(
            value(i, j, k.saturating_sub(1)),
            value(i, j, (k + 1).min(nz - 1)),
            ((k + 1).min(nz - 1) - k.saturating_sub(1)).max(1) as f64,
        );
        index_to_world_grad * DVec3::new(gi, gj, gk)
    };
    // The world normal of the grid's faces across index axis `a` (not unit length).
    let axis_world = |a: usize| index_to_world_grad.col(a);

    // Pass 2: vertices of the edges leaving each corner layer.
    let layers: Vec<Layer> = (0..pz)
        .into_par_iter()
        .map(|kk| {
            let mut l = Layer {
                keys: Vec::new(),
                positions: Vec::new(),
                normals: Vec::new(),
            };
            let m = |i: usize, j: usize, k: usize| mask[i + px * (j + py * k)];
            for jj in 0..py {
                if !row(jj, kk) && !row(jj + 1, kk) && !row(jj, kk + 1) {
                    continue;
                }
                for ii in 0..px {
                    let here = m(ii, jj, kk);
                    for a in 0..3 {
                        let (i2, j2, k2) = match a {
                            0 => (ii + 1, jj, kk),
                            1 => (ii, jj + 1, kk),
                            _ => (ii, jj, kk + 1),
                        };
                        if i2 >= px || j2 >= py || k2 >= pz || m(i2, j2, k2) == here {
                            continue;
                        }
                        let key = ((kk * py + jj) * px + ii) as u64 * 3 + a as u64;
                        let c0 = (ii as isize - 1, jj as isize - 1, kk as isize - 1);
                        let c1 = (i2 as isize - 1, j2 as isize - 1, k2 as isize - 1);
                        let inside_vox = |c: (isize, isize, isize)| {
                            c.0 >= 0
                                && c.1 >= 0
                                && c.2 >= 0
                                && (c.0 as usize) < nx
                                && (c.1 as usize) < ny
                                && (c.2 as usize) < nz
                        };
                        let (p, n) = if inside_vox(c0) && inside_vox(c1) {
                            let (a0, a1) = (
                                (c0.0 as usize, c0.1 as usize, c0.2 as usize),
                                (c1.0 as usize, c1.1 as usize, c1.2 as usize),
                            );
                            let (v0, v1) = (value(a0.0, a0.1, a0.2), value(a1.0, a1.1, a1.2));
                            // A crossing edge's ends differ (one at or above the threshold,
                            // the other below it or NaN); a NaN end puts the vertex midway.
                            let t = ((iso - v0) / (v1 - v0)) as f64;
                            let t = if t.is_nan() {
                                0.5
                            } else {
                                t.clamp(EDGE_MARGIN, 1.0 - EDGE_MARGIN)
                            };
                            let p0 = DVec3::new(a0.0 as f64, a0.1 as f64, a0.2 as f64);
                            let mut p = p0;
                            p[a] += t;
                            let g = gradient(a0.0, a0.1, a0.2) * (1.0 - t)
                                + gradient(a1.0, a1.1, a1.2) * t;
                            (p, -g)
                        } else {
                            // An edge to the padding: the vertex sits on the border voxel,
                            // half the margin into the volume (off the edges to the padding of
                            // a border voxel at a corner, and off the vertex of the edge into
                            // the volume, at least the margin in), its normal along the edge,
                            // out of the volume.
                            let (inner, sign) = if inside_vox(c0) {
                                (c0, 1.0)
                            } else {
                                (c1, -1.0)
                            };
                            let mut p = DVec3::new(inner.0 as f64, inner.1 as f64, inner.2 as f64);
                            p[a] -= sign * EDGE_MARGIN / 2.0;
                            (p, axis_world(a) * sign)
                        };
                        l.keys.push(key);
                        l.positions.push(affine.transform_point3(p).as_vec3());
                        l.normals.push(n.normalize_or_zero().as_vec3());
                    }
                }
            }
            l
        })
        .collect();
    let mut offsets = Vec::with_capacity(pz + 1);
    let mut total = 0u32;
    for l in &layers {
        offsets.push(total);
        total += l.keys.len() as u32;
    }

    // Pass 3: triangles per cell layer.
    let tris: Vec<Vec<[u32; 3]>> = (0..pz - 1)
        .into_par_iter()
        .map(|kk| {
            let mut out = Vec::new();
            let m = |i: usize, j: usize, k: usize| mask[i + px * (j + py * k)];
            for jj in 0..py - 1 {
                if !row(jj, kk) && !row(jj + 1, kk) && !row(jj, kk + 1) && !row(jj + 1, kk + 1) {
                    continue;
                }
                for ii in 0..px - 1 {
                    let mut case = 0usize;
                    for c in 0..8 {
                        let (dx, dy, dz) = (c & 1, c >> 1 & 1, c >> 2 & 1);
                        case |= (m(ii + dx, jj + dy, kk + dz) as usize) << c;
                    }
                    if case == 0 || case == 255 {
                        continue;
                    }
                    for t in &CASES[case] {
                        out.push(t.map(|e| {
                            let c = EDGE_START[e as usize] as usize;
                            let (dx, dy, dz) = (c & 1, c >> 1 & 1, c >> 2 & 1);
                            let layer = kk + dz;
                            let key = (((layer * py) + jj + dy) * px + ii + dx) as u64 * 3
                                + (e / 4) as u64;
                            let l = &layers[layer];
                            let local = l
                                .keys
                                .binary_search(&key)
                                .expect("every crossing edge has a vertex");
                            offsets[layer] + local as u32
                        }));
                    }
                }
            }
            out
        })
        .collect();

    let mut mesh = TriMesh::default();
    let mut normals = Vec::with_capacity(total as usize);
    mesh.positions.reserve(total as usize);
    for l in layers {
        mesh.positions.extend(l.positions);
        normals.extend(l.normals);
    }
    mesh.triangles = tris.into_iter().flatten().collect();
    (IsoSurface { mesh, normals }, islands)
}

/// Taubin λ|μ smoothing (Taubin 1995): `iterations` pairs of a shrinking and an inflating
/// umbrella step, which remove the voxel stair-steps of a coarse CT without shrinking the bone.
/// Vertex normals are re-derived from the smoothed surface (area-weighted), oriented as before.
pub fn smooth(surface: &mut IsoSurface, iterations: u32) {
    if iterations == 0 {
        return;
    }
    let mesh = &mut surface.mesh;
    let n = mesh.positions.len();
    // Vertex adjacency as CSR from the triangles' edges.
    let mut degree = vec![0u32; n + 1];
    for t in &mesh.triangles {
        for &v in t {
            degree[v as usize] += 2;
        }
    }
    let mut start = vec![0usize; n + 1];
    for v in 0..n {
        start[v + 1] = start[v] + degree[v] as usize;
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for t in &mesh.triangles {
        for i in 0..3 {
            let v = t[i] as usize;
            for o in [t[(i + 1) % 3], t[(i + 2) % 3]] {
                adj[fill[v]] = o;
                fill[v] += 1;
            }
        }
    }
    let step = |pos: &Vec<Vec3>, factor: f32| -> Vec<Vec3> {
        (0..n)
            .into_par_iter()
            .map(|v| {
                let nb = &adj[start[v]..start[v + 1]];
                if nb.is_empty() {
                    return pos[v];
                }
                let mean = nb.iter().map(|&o| pos[o as usize]).sum::<Vec3>() / nb.len() as f32;
                pos[v] + factor * (mean - pos[v])
            })
            .collect()
    };
    for _ in 0..iterations {
        let shrunk = step(&mesh.positions, 0.5);
        mesh.positions = step(&shrunk, -0.53);
    }
    surface.normals = mesh.vertex_normals();
}

/// What [`simplify`] did: the triangles before and after, how far the full surface departs
/// from the simplified one (the farthest any of its vertices lies from it), measured, in the
/// mesh's units (mm), and how many vertices had to be held in place to keep within the bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Simplified {
    pub triangles_before: usize,
    pub triangles_after: usize,
    pub departure: f64,
    pub held: usize,
}

/// The rounds a try of [`simplify`] may take.
const ROUNDS: usize = 16;
/// [`simplify`]'s tries, each at half the allowance of the one before.
const TRIES: usize = 8;

/// Simplifies `surface` by edge collapses so that every vertex of the full surface stays
/// within `max_error` (in the mesh's units, mm) of the simplified one, measured (but for
/// vertices of none but triangles of no area, which may go).
///
/// meshoptimizer's `simplify` collapses the edges (Garland–Heckbert error quadrics; collapses
/// that would flip a triangle refused) as far as its error estimate stays within an allowance.
/// The estimate is not a bound: on a smoothed sphere allowed 0.2 mm the
/// surface departed 0.46 mm, and a flat flake or a needle (a lone voxel barely over a CT
/// threshold), whose faces' planes run along it so that quadrics see no error, may be
/// collapsed away whole. So the departure of every vertex
/// of the full surface is measured ([`distances`]), and the full surface simplified again
/// with those beyond the bound held in place (meshoptimizer's vertex locks: a held vertex
/// cannot move, but its neighbours can collapse onto it, so one still beyond holds the
/// corners of its triangles too), until none is beyond it. The collapses may also pinch a
/// thin wall against its other side (an edge then joins four triangles: on 3D Slicer's chest
/// segmentation, 2 edges of the body's 70,000 triangles at 0.5 mm), which 3D printing's
/// slicers and lib3mf refuse as not manifold: the ends of such an edge are held the same way.
/// So is a vertex where they pinch the surface to a point, two fans of triangles meeting
/// there only ([`pinched_vertices`]; which mesh repair tools flag, and a slicer may part).
///
/// Holding is a try of up to 16 rounds, at an allowance. A high allowance lets the collapses
/// go far beyond the bound, so many vertices are held, and a lower one may end with fewer
/// triangles (with one try at the bound itself, the chest CT's smoothed bones kept more at
/// 4 mm than at 1 mm). So there are eight tries, at `max_error` and at each half of it down
/// to 1/128 of it, and the fewest triangles are kept (a try is begun only where it may end
/// with fewer than one has: on the chest CT's bones at 0.3 to 4 mm no more than five were;
/// with five tries the abdomen CT's raw bones at 64 mm kept 67,338 triangles, and at 128 mm
/// none converged, where eight keep 14,518 and 10,882). The tries take turns: a round keeps
/// more triangles than the one before it in its try (holding more only keeps more), and a
/// try's first round more than the first of the try at twice its allowance (every round
/// looked at did, on the chest CT's bones: BENCHMARKS.md), so what a try's last collapses
/// kept is the least it can end with, and the next try's is what the last one begun kept
/// first. The try that can end with the fewest goes next (its round's collapses, or their
/// measure), until one keeps within the bound no more triangles than any other can end with:
/// the fewest any try ends with, without running the others to their ends (where the rounds
/// do not grow so, it is still within the bound, and may not be the fewest). On the chest
/// CT's smoothed bones at 4 mm that took 21 collapses and 17 measures where the tries run one
/// after another took 45 rounds, and made the same surface (BENCHMARKS.md). A try still
/// holding after 16 rounds is given up; where every one is, the surface is left as it was.
/// (Lowering the allowance for the whole surface within a try instead, while many vertices
/// were beyond, kept within the bound as well, but on the chest CT's bones left 2.5 times the
/// triangles.) The vertices kept are original ones, with their normals; unused ones
/// are dropped.
///
/// Written through a crate: meshoptimizer is the maintained, widely used implementation
/// (glTF's `gltfpack`), with an absolute error allowance and vertex locks.
pub fn simplify(surface: &mut IsoSurface, max_error: f64) -> Simplified {
    simplify_reporting(surface, max_error, &mut |_| {})
}

/// Where [`simplify`] is: the try (from 1, at `max_error` halved one less times), its round
/// (from 1), the triangles that round kept, and how many vertices it left beyond the bound,
/// at a pinched edge or pinched themselves (to be held in its try's next). The tries' rounds
/// come interleaved, each try's in order, the tries begun in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SimplifyRound {
    pub attempt: u32,
    pub round: usize,
    pub triangles: usize,
    pub beyond: usize,
}

/// [`simplify`], telling `on_round` after each round.
pub fn simplify_reporting(
    surface: &mut IsoSurface,
    max_error: f64,
    on_round: &mut dyn FnMut(SimplifyRound),
) -> Simplified {
    let full = &surface.mesh;
    let before = full.triangles.len();
    let unchanged = Simplified {
        triangles_before: before,
        triangles_after: before,
        departure: 0.0,
        held: 0,
    };
    if before == 0 || max_error.is_nan() || max_error <= 0.0 {
        return unchanged;
    }
    let mut job = Holding::new(full, max_error);
    let mut tries: Vec<Try> = Vec::new();
    let mut best: Option<Kept> = None;
    loop {
        // The tries by the fewest triangles they can end with: those under way (the earliest
        // of those level first), and the next to begin, which keeps at least what the last
        // begun kept first.
        let mut order: Vec<(usize, usize)> = (tries.iter().enumerate())
            .filter(|(_, t)| t.live)
            .map(|(i, t)| (t.triangles, i))
            .collect();
        if tries.len() < TRIES {
            order.push((tries.last().map_or(0, |t| t.first), tries.len()));
        }
        order.sort_unstable();
        let fewest = best.as_ref().map_or(usize::MAX, |b| b.mesh.triangles.len());
        let order: Vec<usize> = (order.into_iter())
            .take_while(|&(least, _)| least < fewest)
            .map(|(_, i)| i)
            .collect();
        let Some(&i) = order.first() else { break };
        let begin = |tries: &mut Vec<Try>, j: usize| {
            if j == tries.len() {
                let allowance = max_error * 0.5f64.powi(j as i32);
                tries.push(Try::new(allowance, full.positions.len()));
            }
        };
        begin(&mut tries, i);
        // A round's collapses tell its triangles, the least its try can end with: it is
        // measured when it is its try's turn again. meshoptimizer runs on one thread, so
        // the next try in line collapses beside it where it is to collapse too (the same
        // turns on any number of threads).
        if tries[i].collapsed.is_none() {
            match order.get(1) {
                Some(&j) if j == tries.len() || tries[j].collapsed.is_none() => {
                    begin(&mut tries, j);
                    let [a, b] = tries.get_disjoint_mut([i, j]).expect("two tries");
                    rayon::join(|| job.collapse(a), || job.collapse(b));
                }
                _ => job.collapse(&mut tries[i]),
            }
            continue;
        }
        let t = &mut tries[i];
        let (beyond, kept) = job.measure(t);
        on_round(SimplifyRound {
            attempt: i as u32 + 1,
            round: t.rounds,
            triangles: t.triangles,
            beyond,
        });
        if let Some(kept) = kept
            && best
                .as_ref()
                .is_none_or(|b| kept.mesh.triangles.len() < b.mesh.triangles.len())
        {
            best = Some(kept);
        }
    }
    let Some(best) = best else {
        return unchanged;
    };
    // The kept vertices' own normals (the full surface's: the gradient's, or the smoothed
    // surface's), where it has them. Re-derived from the simplified surface, a fan of long
    // thin triangles tilts them: on spheres of radius 19.5 to 21 mm (1 mm voxels, cut by the
    // volume's border) simplified within 0.5 mm, up to 72° off the radial, where the full
    // surface's are 45° off at worst (at a cap's rim).
    surface.normals = if surface.normals.len() == surface.mesh.positions.len() {
        best.origin
            .iter()
            .map(|&v| surface.normals[v as usize])
            .collect()
    } else {
        best.mesh.vertex_normals()
    };
    surface.mesh = best.mesh;
    Simplified {
        triangles_before: before,
        triangles_after: surface.mesh.triangles.len(),
        departure: best.departure,
        held: best.held,
    }
}

/// A try of [`simplify`] that kept within the bound.
struct Kept {
    mesh: TriMesh,
    /// Each kept vertex's index in the full surface.
    origin: Vec<u32>,
    departure: f64,
    held: usize,
}

/// A try of [`simplify`]: its allowance and where it is.
struct Try {
    allowance: f64,
    /// The full surface's vertices it holds in place.
    held: Vec<bool>,
    /// The rounds it has measured, and the triangles its first and its last kept (its
    /// last collapsed, measured or not).
    rounds: usize,
    first: usize,
    triangles: usize,
    /// Its next round's surface, collapsed and not yet measured, with each of its vertices'
    /// index in the full surface.
    collapsed: Option<(TriMesh, Vec<u32>)>,
    /// Whether it goes on: its last round left vertices to hold, and it has rounds left.
    live: bool,
}

impl Try {
    fn new(allowance: f64, vertices: usize) -> Self {
        Try {
            allowance,
            held: vec![false; vertices],
            rounds: 0,
            first: 0,
            triangles: 0,
            collapsed: None,
            live: true,
        }
    }
}

/// What the tries of [`simplify`] share: the full surface as meshoptimizer takes it, the
/// points measured and the edges already not manifold.
struct Holding<'a> {
    full: &'a TriMesh,
    max_error: f64,
    indices: Vec<u32>,
    positions: Vec<[f32; 3]>,
    /// The measured vertices' indices in the full surface, and their points.
    index: Vec<usize>,
    points: Vec<Vec3>,
    /// The edges already joining other than two triangles facing opposite ways in the full
    /// surface, and its vertices already pinched (none in the marching cubes' surfaces): only
    /// new ones are the collapses' doing.
    bad_in_full: foldhash::HashSet<[u32; 2]>,
    pinched_in_full: foldhash::HashSet<u32>,
    /// Each vertex's triangles' corners, built when first needed.
    ring: Option<Vec<Vec<u32>>>,
}

impl<'a> Holding<'a> {
    fn new(full: &'a TriMesh, max_error: f64) -> Self {
        // The vertices of triangles of some area: those the departure is measured at. (The
        // marching cubes make none of no area, but a surface from elsewhere may: a piece of
        // such triangles alone is a point, which the collapses take away.)
        let mut measured = vec![false; full.positions.len()];
        for (i, t) in full.triangles.iter().enumerate() {
            let [a, b, c] = full.corners(i);
            if (b - a).cross(c - a) != Vec3::ZERO {
                for &v in t {
                    measured[v as usize] = true;
                }
            }
        }
        let index: Vec<usize> = (0..measured.len()).filter(|&v| measured[v]).collect();
        Holding {
            full,
            max_error,
            indices: full.triangles.iter().flatten().copied().collect(),
            positions: full.positions.iter().map(|p| p.to_array()).collect(),
            points: index.iter().map(|&v| full.positions[v]).collect(),
            index,
            bad_in_full: not_manifold(&full.triangles).into_iter().collect(),
            pinched_in_full: pinched_vertices(&full.triangles).into_iter().collect(),
            ring: None,
        }
    }

    /// The collapses of `t`'s next round: the full surface's, at its allowance, its vertices
    /// held.
    fn collapse(&self, t: &mut Try) {
        let adapter = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&self.positions), 12, 0)
            .expect("12-byte positions");
        let kept = meshopt::simplify_with_locks(
            &self.indices,
            &adapter,
            &t.held,
            0,
            t.allowance as f32,
            meshopt::SimplifyOptions::ErrorAbsolute,
            None,
        );
        let (simple, origin) = compact(self.full, &kept);
        t.triangles = simple.triangles.len();
        if t.rounds == 0 {
            t.first = t.triangles;
        }
        t.collapsed = Some((simple, origin));
    }

    /// Measures `t`'s round, collapsed ([`Holding::collapse`]). Returns how many vertices it
    /// left beyond the bound or pinched, and the surface where none: then, or where it was the
    /// last of [`ROUNDS`], `t` ends; else they are held for its next round.
    fn measure(&mut self, t: &mut Try) -> (usize, Option<Kept>) {
        let full = self.full;
        let (simple, origin) = t.collapsed.take().expect("a round collapsed");
        let d = distances(&self.points, &simple, self.max_error);
        let mut beyond: Vec<usize> = (0..d.len())
            .filter(|&i| d[i] > self.max_error)
            .map(|i| self.index[i])
            .collect();
        // Collapses that made an edge join more than two triangles, or two facing the
        // same way (meshoptimizer refuses those that would flip a triangle, but not all
        // that would pinch a thin wall against its other side: a surface a 3D printer's
        // slicer, or lib3mf, calls not manifold): its ends are held as a vertex beyond the
        // bound is.
        for e in not_manifold(&simple.triangles) {
            let e = e.map(|v| origin[v as usize]);
            if !self.bad_in_full.contains(&e) {
                beyond.extend(e.map(|v| v as usize));
            }
        }
        // So are the vertices where the collapses pinched the surface to a point (two
        // fans of triangles meeting there only: on the chest CT's raw bones at 0.3 mm, 428
        // of them, where the full surface had none).
        for v in pinched_vertices(&simple.triangles) {
            let v = origin[v as usize];
            if !self.pinched_in_full.contains(&v) {
                beyond.push(v as usize);
            }
        }
        t.rounds += 1;
        let count = beyond.len();
        if beyond.is_empty() {
            t.live = false;
            let kept = Kept {
                mesh: simple,
                origin,
                departure: d.iter().copied().fold(0.0, f64::max),
                held: t.held.iter().filter(|h| **h).count(),
            };
            return (0, Some(kept));
        }
        t.live = t.rounds < ROUNDS;
        // A vertex held and still beyond went with its piece, collapsed onto it, or its
        // triangles went flat (or its edge is still pinched): the vertices of its
        // triangles are held too, so that they stay.
        for v in beyond {
            if t.held[v] {
                let around = self.ring.get_or_insert_with(|| {
                    let mut around = vec![Vec::new(); full.positions.len()];
                    for tri in &full.triangles {
                        for &a in tri {
                            around[a as usize].extend_from_slice(tri);
                        }
                    }
                    around
                });
                for &w in &around[v] {
                    t.held[w as usize] = true;
                }
            }
            t.held[v] = true;
        }
        (count, None)
    }
}

/// Each try of [`simplify`] run alone to its end: the triangles of each of its rounds, and
/// whether it kept within the bound (what the turns [`simplify_reporting`] takes are checked
/// against).
#[cfg(test)]
pub(crate) fn each_try(surface: &IsoSurface, max_error: f64) -> Vec<(Vec<usize>, bool)> {
    let mut job = Holding::new(&surface.mesh, max_error);
    (0..TRIES)
        .map(|i| {
            let allowance = max_error * 0.5f64.powi(i as i32);
            let mut t = Try::new(allowance, surface.mesh.positions.len());
            let mut rounds = Vec::new();
            loop {
                job.collapse(&mut t);
                let (_, kept) = job.measure(&mut t);
                rounds.push(t.triangles);
                if kept.is_some() || !t.live {
                    return (rounds, kept.is_some());
                }
            }
        })
        .collect()
}

/// The vertices of `triangles` at which two or more fans of them meet (the surface pinched to
/// a point, as two cones tip to tip): where a closed surface, its edges each joining two
/// triangles, is still not a 2-manifold. A vertex's triangles, each giving the edge opposite
/// it (from its next corner to its previous), chain into a loop around it on a 2-manifold; a
/// vertex whose loop from its first triangle's edge closes before its triangles are spent, or
/// whose edge is another's start twice (an edge that is not manifold), is listed (on a surface
/// with borders, a border's vertices may be too). Each once, in order.
pub fn pinched_vertices(triangles: &[[u32; 3]]) -> Vec<u32> {
    // Every corner's edge opposite it, sorted by corner then by the edge's start.
    let mut around: Vec<[u32; 3]> = triangles
        .iter()
        .flat_map(|&[a, b, c]| [[a, b, c], [b, c, a], [c, a, b]])
        .collect();
    around.sort_unstable();
    let mut pinched = Vec::new();
    for fan in around.chunk_by(|x, y| x[0] == y[0]) {
        let next = |from: u32| {
            let i = fan.partition_point(|x| x[1] < from);
            (i < fan.len() && fan[i][1] == from).then(|| fan[i][2])
        };
        let twice = fan.windows(2).any(|w| w[0][1] == w[1][1]);
        let (start, mut at, mut steps) = (fan[0][1], fan[0][2], 1);
        while at != start && steps < fan.len() {
            match next(at) {
                Some(n) => at = n,
                None => break,
            }
            steps += 1;
        }
        if twice || steps < fan.len() {
            pinched.push(fan[0][0]);
        }
    }
    pinched
}

/// The edges (their ends, the lesser first) of `triangles` that join more than two of them,
/// or two facing the same way (each crossing the edge in the same direction), each once: where
/// a surface is not a closed, oriented 2-manifold (edges of one triangle, a border, are not
/// listed).
pub fn not_manifold(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    use foldhash::{HashMap, HashMapExt};
    // Each edge's uses: how many cross it from its lesser end, and from its greater.
    let mut uses: HashMap<[u32; 2], [u32; 2]> = HashMap::with_capacity(triangles.len() * 3 / 2);
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let u = uses.entry([a.min(b), a.max(b)]).or_default();
            u[usize::from(a > b)] += 1;
        }
    }
    let mut bad: Vec<[u32; 2]> = uses
        .into_iter()
        .filter(|(_, [up, down])| up + down > 2 || (up + down == 2 && up != down))
        .map(|(e, _)| e)
        .collect();
    bad.sort_unstable();
    bad
}

/// The triangles `kept` (indices into `full`'s vertices, three a triangle) with only the
/// vertices they use, in their old order, and each of those vertices' index in `full`; less
/// any two that are one triangle facing both ways (a fin of no volume that collapses next to
/// held vertices can leave: its two faces cancel, and without them the surface is a 2-manifold
/// again).
pub(crate) fn compact(full: &TriMesh, kept: &[u32]) -> (TriMesh, Vec<u32>) {
    use foldhash::{HashMap, HashMapExt};
    let tris: Vec<[u32; 3]> = kept.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    // Each triangle keyed by its corners, rotated to start at the least: a triangle and its
    // reverse have the same corners in the other cyclic order.
    let key = |t: [u32; 3]| {
        let r = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
        [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
    };
    // The triangles not yet cancelled, a stack a key (the last first): its top in `open`, each
    // one's next below it in `below` (a list through the triangles, not a vector a key: one
    // allocation a triangle was a tenth of a round's time on the chest CT's bones).
    const NONE: u32 = u32::MAX;
    let mut open: HashMap<[u32; 3], u32> = HashMap::with_capacity(tris.len());
    let mut below = vec![NONE; tris.len()];
    let mut gone = vec![false; tris.len()];
    for (i, &t) in tris.iter().enumerate() {
        let k = key(t);
        let reverse = [k[0], k[2], k[1]];
        match open.get_mut(&reverse) {
            Some(top) if *top != NONE => {
                let j = *top as usize;
                *top = below[j];
                gone[i] = true;
                gone[j] = true;
            }
            _ => {
                let top = open.entry(k).or_insert(NONE);
                below[i] = *top;
                *top = i as u32;
            }
        }
    }
    let kept: Vec<u32> = tris
        .iter()
        .zip(&gone)
        .filter(|(_, g)| !**g)
        .flat_map(|(t, _)| *t)
        .collect();
    let mut used = vec![false; full.positions.len()];
    for &i in &kept {
        used[i as usize] = true;
    }
    let mut remap = vec![u32::MAX; used.len()];
    let mut positions = Vec::new();
    let mut origin = Vec::new();
    for (v, _) in used.iter().enumerate().filter(|(_, u)| **u) {
        remap[v] = positions.len() as u32;
        positions.push(full.positions[v]);
        origin.push(v as u32);
    }
    let mesh = TriMesh {
        positions,
        triangles: kept
            .chunks_exact(3)
            .map(|t| [0, 1, 2].map(|k| remap[t[k] as usize]))
            .collect(),
    };
    (mesh, origin)
}

/// How far the `points` lie from the surface `simple`: the farthest any lies from its nearest
/// triangle, or +∞ where one has none within `reach` ([`distances`]'s largest).
pub fn departure(points: &[Vec3], simple: &TriMesh, reach: f64) -> f64 {
    distances(points, simple, reach)
        .into_iter()
        .fold(0.0, f64::max)
}

/// How far each of the `points` lies from the surface `simple` (from its nearest triangle),
/// +∞ where it has none within `reach`: a search of a grid of the triangles, nearest cells
/// first, in parallel over the points.
pub fn distances(points: &[Vec3], simple: &TriMesh, reach: f64) -> Vec<f64> {
    match Nearest::new(simple, reach) {
        Some(near) => points
            .par_iter()
            .map(|p| near.distance(p.as_dvec3()))
            .collect(),
        None => vec![f64::INFINITY; points.len()],
    }
}

/// A surface's triangles binned for the distance of points from it, up to a reach.
///
/// The triangles are binned by their bounds into a grid of cells at least `reach` wide (and as
/// wide as their mean edge), so that those within `reach` of a point are the 27 about its own.
/// A point looks at its own cell first, then the others, passing over a cell farther than the
/// nearest triangle found so far, and within a cell a triangle whose bounding box is. f64
/// throughout. (Written by hand: the search is a few lines, where a crate's nearest-point
/// query, parry's, would bring its own geometry types for this one use; it is checked against
/// brute force in the tests.)
struct Nearest {
    reach: f64,
    tris: Vec<[DVec3; 3]>,
    bounds: Vec<[DVec3; 2]>,
    /// The grid's corner and its cells' width.
    lo: DVec3,
    cell: f64,
    /// Each listed cell's triangles: `listed[grid[cell]]`.
    listed: Vec<u32>,
    grid: foldhash::HashMap<u64, std::ops::Range<usize>>,
}

/// The offsets of the 27 cells about a point's own, its own first, then those across a face,
/// an edge and a corner (the nearer first, where the point is in its cell's middle).
const AROUND: [[i64; 3]; 27] = {
    let mut around = [[0; 3]; 27];
    let mut n = 0;
    let mut ring = 0;
    while ring <= 3 {
        let mut i = 0;
        while i < 27 {
            let d = [i as i64 / 9 - 1, i as i64 / 3 % 3 - 1, i as i64 % 3 - 1];
            if d[0].abs() + d[1].abs() + d[2].abs() == ring {
                around[n] = d;
                n += 1;
            }
            i += 1;
        }
        ring += 1;
    }
    around
};

impl Nearest {
    /// `None` where `mesh` has no triangle or `reach` is not positive.
    fn new(mesh: &TriMesh, reach: f64) -> Option<Nearest> {
        if mesh.is_empty() || reach.is_nan() || reach <= 0.0 {
            return None;
        }
        let tris: Vec<[DVec3; 3]> = (0..mesh.len())
            .map(|i| mesh.corners(i).map(|p| p.as_dvec3()))
            .collect();
        let bounds: Vec<[DVec3; 2]> = tris
            .iter()
            .map(|t| [t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2])])
            .collect();
        let (lo, hi) = bounds
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b[0]), hi.max(b[1]))
            });
        let edge = tris
            .iter()
            .map(|t| (t[1] - t[0]).length() + (t[2] - t[1]).length() + (t[0] - t[2]).length())
            .sum::<f64>()
            / (3 * tris.len()) as f64;
        // Cells at least `reach` wide, so that a point looks at no more than the 27 about it;
        // widened until each axis has at most 2²¹ of them, so that a cell's three coordinates
        // pack into one key. Only cells a triangle's bounds reach are listed (a surface fills
        // few of a volume's cells), hashed by foldhash's fast hasher (as this file's other
        // maps are: far fewer cycles a key than the standard SipHash, and seeded all the same).
        let mut cell = reach.max(edge);
        while ((hi - lo) / cell).max_element() >= (1 << 21) as f64 {
            cell *= 2.0;
        }
        let mut near = Nearest {
            reach,
            tris,
            bounds,
            lo,
            cell,
            listed: Vec::new(),
            grid: foldhash::HashMapExt::new(),
        };
        let mut pairs: Vec<(u64, u32)> = Vec::new();
        for (t, b) in near.bounds.iter().enumerate() {
            let (a, z) = (near.key(b[0]), near.key(b[1]));
            for x in a.x..=z.x {
                for y in a.y..=z.y {
                    for w in a.z..=z.z {
                        if let Some(k) = packed(I64Vec3::new(x, y, w)) {
                            pairs.push((k, t as u32));
                        }
                    }
                }
            }
        }
        pairs.sort_unstable();
        near.listed = pairs.iter().map(|&(_, t)| t).collect();
        let mut from = 0;
        for run in pairs.chunk_by(|a, b| a.0 == b.0) {
            near.grid.insert(run[0].0, from..from + run.len());
            from += run.len();
        }
        Some(near)
    }

    /// The cell that holds `p`, its coordinates clamped to ±2⁴⁰: far off the grid's 2²¹ a
    /// side either way, so that a point so far still finds no cell within reach, and its
    /// neighbours' coordinates cannot overflow (cells of 10⁻³⁰⁰ put a point 10¹⁰ off at
    /// 10³¹⁰).
    fn key(&self, p: DVec3) -> I64Vec3 {
        let far = I64Vec3::splat(1 << 40);
        ((p - self.lo) / self.cell)
            .floor()
            .as_i64vec3()
            .clamp(-far, far)
    }

    /// How far `p` lies from its nearest triangle, +∞ where none is within the reach.
    fn distance(&self, p: DVec3) -> f64 {
        // The squared distance from `p` to the box `b`.
        let box_distance2 =
            |b: [DVec3; 2]| (b[0] - p).max(p - b[1]).max(DVec3::ZERO).length_squared();
        let own = self.key(p);
        let mut best = f64::INFINITY;
        for d in AROUND {
            let bound = best.min(self.reach);
            let c = own + I64Vec3::from_array(d);
            let lo = self.lo + c.as_dvec3() * self.cell;
            if box_distance2([lo, lo + self.cell]) > bound * bound {
                continue;
            }
            let Some(range) = packed(c).and_then(|k| self.grid.get(&k)) else {
                continue;
            };
            for &t in &self.listed[range.clone()] {
                let bound = best.min(self.reach);
                if box_distance2(self.bounds[t as usize]) > bound * bound {
                    continue;
                }
                best = best.min(point_triangle_distance(p, self.tris[t as usize]));
            }
        }
        if best <= self.reach {
            best
        } else {
            f64::INFINITY
        }
    }
}

/// A cell's three coordinates in one key, 21 bits each; `None` for a cell off the grid.
fn packed(c: I64Vec3) -> Option<u64> {
    (c.cmpge(I64Vec3::ZERO).all() && c.cmplt(I64Vec3::splat(1 << 21)).all())
        .then_some(((c.x as u64) << 42) | ((c.y as u64) << 21) | c.z as u64)
}

/// The distance from `p` to the triangle `t` (Ericson, Real-Time Collision Detection 5.1.5:
/// the closest point by the Voronoi region of the triangle it falls in).
pub fn point_triangle_distance(p: DVec3, t: [DVec3; 3]) -> f64 {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (p - a).length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (p - b).length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (p - c).length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).length();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (p - (a + ab * v + ac * w)).length()
}
