//! Marching cubes on a CT volume, in parallel over z-layers, with shared vertices.
//!
//! The volume is padded by one layer of "outside" on every side, so a structure cut by the
//! volume's border is closed by a flat cap there and every surface is closed. Vertices sit on
//! cell edges at the linear interpolation of the iso crossing; each crossing edge gets exactly
//! one vertex (keyed by the edge), so neighbouring cells share vertices and the mesh has no
//! cracks. Normals are the negated value gradient (central differences in index space, taken
//! into LPS by the inverse transpose of the grid's matrix, so sheared grids too), interpolated
//! along the edge: they point out of the inside region.
//!
//! Three passes, each parallel over z: (1) the inside mask; (2) per layer, the vertices of the
//! edges leaving that layer's corners, in key order; (3) per layer of cells, the triangles, their
//! vertex keys resolved by binary search in the two layers' vertex lists.

use rayon::prelude::*;
use raystream_io::{TriMesh, Volume};
use raystream_math::{DVec3, Vec3};

use crate::cases::{CASES, EDGE_START};

/// A triangle mesh in LPS millimetres with per-vertex unit normals (from the volume gradient,
/// pointing out of the region at or above the threshold).
#[derive(Clone, Debug, Default)]
pub struct IsoSurface {
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
}

struct Layer {
    keys: Vec<u64>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
}

/// Extracts the surface `value = iso` of `vol`, oriented out of the region `value ≥ iso`
/// (NaN voxels count as outside).
pub fn extract_isosurface(vol: &Volume, iso: f32) -> IsoSurface {
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
                            let t = if v1 != v0 {
                                ((iso - v0) / (v1 - v0)).clamp(0.0, 1.0) as f64
                            } else {
                                0.5
                            };
                            let t = if t.is_nan() { 0.5 } else { t };
                            let p0 = DVec3::new(a0.0 as f64, a0.1 as f64, a0.2 as f64);
                            let mut p = p0;
                            p[a] += t;
                            let g = gradient(a0.0, a0.1, a0.2) * (1.0 - t)
                                + gradient(a1.0, a1.1, a1.2) * t;
                            (p, -g)
                        } else {
                            // An edge to the padding: the vertex sits on the border voxel, its
                            // normal along the edge, out of the volume.
                            let (inner, sign) = if inside_vox(c0) {
                                (c0, 1.0)
                            } else {
                                (c1, -1.0)
                            };
                            let p = DVec3::new(inner.0 as f64, inner.1 as f64, inner.2 as f64);
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
    IsoSurface { mesh, normals }
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
