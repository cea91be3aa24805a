//! glTF 2.0 meshes (`.gltf`, its buffers embedded as data URIs or in files beside it, and
//! `.glb`), through the `gltf` crate: the triangles of every mesh instance in the default
//! scene (or the first; with no scene, every mesh once), placed by their nodes' transforms,
//! in f64 and rounded once, with their normals (turned as the transforms turn them) and each primitive's base colour
//! as its material.
//!
//! The crate validates the document and checks that every buffer holds the bytes it claims;
//! each accessor read is checked here too (its type, and its reach within its buffer view and
//! buffer, in checked arithmetic), so that a corrupt file is an error naming it, never a
//! panic or an allocation its bytes do not back. Points and lines are left out with a warning;
//! triangle strips and fans become triangles.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use raystream_math::{DMat3, DMat4, Vec2, Vec3};

use crate::{MeshError, MtlMaterial, Rgb8, Texture, TextureMapping, TriMesh};

/// The most triangles a glTF file may place, counting every instance of its meshes: a small
/// file whose nodes instance a mesh many times over could otherwise ask for any amount of
/// memory.
pub const MAX_TRIANGLES: usize = 100_000_000;
/// The deepest node hierarchy read (the document forbids cycles, and the crate's validation
/// does not look for them).
const MAX_NODE_DEPTH: usize = 256;
/// The most nodes waiting to be visited at once (each with its transform, 150 bytes): a node
/// that lists itself, or another, as a child thousands of times over would otherwise fill
/// the memory before the depth limit is reached.
const MAX_PENDING_NODES: usize = 1 << 20;

/// A glTF file's triangles and what it gives their surface.
pub(crate) struct Parsed {
    pub mesh: TriMesh,
    /// Per vertex, the file's normal, where its primitive has them.
    pub normals: Vec<Option<Vec3>>,
    /// The document's materials, in its order; per triangle, its primitive's material.
    pub materials: Vec<MtlMaterial>,
    pub material_of: Vec<Option<u32>>,
    /// Per triangle, its corners' texture coordinates (v up, as OBJ's), where its material
    /// has a base colour texture and its primitive those coordinates; empty when none has.
    pub uvs: Vec<[Vec2; 3]>,
    /// Per triangle, its corners' colours (`COLOR_0`; white where a primitive has none);
    /// empty when no primitive has them.
    pub colours: Vec<[Rgb8; 3]>,
    pub warnings: Vec<String>,
}

/// Parses a glTF document (JSON or GLB) read from `path`; external buffers are read from `dir`
/// (none: only embedded buffers are allowed). The base colour textures are decoded only
/// `with_textures` (a caller that wants the triangles alone reads no images).
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    dir: Option<&Path>,
    with_textures: bool,
) -> Result<Parsed, MeshError> {
    let bad = |problem: String| MeshError::invalid(path, problem);
    let not_gltf = |e: gltf::Error| bad(format!("not valid glTF 2.0 ({e})"));
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(not_gltf)?;
    // gltf-json 1.4's validation looks up each primitive's POSITION accessor without checking
    // that it exists (a panic on such a file): checked here, before it validates.
    let root = document.into_json();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(a) = prim
                .attributes
                .values()
                .find(|a| a.value() >= root.accessors.len())
            {
                return Err(bad(format!(
                    "mesh {m} primitive {p} names accessor {}, but the file has {}",
                    a.value(),
                    root.accessors.len()
                )));
            }
        }
    }
    let document = gltf::Document::from_json(root).map_err(not_gltf)?;
    // gltf 1.4 unwraps the percent-decoding of a buffer's relative URI (a panic on one that
    // decodes to bytes that are not UTF-8): checked here, before it reads the buffers.
    for b in document.buffers() {
        if let gltf::buffer::Source::Uri(uri) = b.source()
            && !uri.contains(':')
            && urlencoding::decode(uri).is_err()
        {
            return Err(bad(format!(
                "buffer {}: its URI '{uri}' is not a file name (its %-escapes are not UTF-8)",
                b.index()
            )));
        }
    }
    let buffers = gltf::import_buffers(&document, dir, blob)
        .map_err(|e| bad(format!("its buffers cannot be read ({e})")))?;
    let mut out = Parsed {
        mesh: TriMesh::default(),
        normals: Vec::new(),
        materials: document.materials().map(material).collect(),
        material_of: Vec::new(),
        uvs: Vec::new(),
        colours: Vec::new(),
        warnings: Vec::new(),
    };
    let mut coloured = false;
    // The materials whose texture some triangle has coordinates for.
    let mut textured = std::collections::BTreeSet::new();
    // The mesh instances, each with its world transform, in the scene's order (depth first).
    let mut instances: Vec<(gltf::Mesh, DMat4)> = Vec::new();
    match document
        .default_scene()
        .or_else(|| document.scenes().next())
    {
        Some(scene) => {
            let mut stack: Vec<(gltf::Node, DMat4, usize)> =
                scene.nodes().map(|n| (n, DMat4::IDENTITY, 0)).collect();
            stack.reverse();
            let mut visits = 0usize;
            while let Some((node, parent, depth)) = stack.pop() {
                visits += 1;
                if visits > MAX_TRIANGLES {
                    return Err(bad(format!(
                        "its scene visits over {MAX_TRIANGLES} nodes (nodes listed as children many times over?)"
                    )));
                }
                if depth >= MAX_NODE_DEPTH {
                    return Err(bad(format!(
                        "its node hierarchy is deeper than {MAX_NODE_DEPTH} (a cycle?)"
                    )));
                }
                let local = node.transform().matrix().map(|c| c.map(f64::from));
                let world = parent * DMat4::from_cols_array_2d(&local);
                if let Some(mesh) = node.mesh() {
                    instances.push((mesh, world));
                }
                let first = stack.len();
                stack.extend(node.children().map(|c| (c, world, depth + 1)));
                stack[first..].reverse();
                if stack.len() > MAX_PENDING_NODES {
                    return Err(bad(format!(
                        "its scene has over {MAX_PENDING_NODES} nodes waiting to be visited (nodes listed as children many times over?)"
                    )));
                }
            }
        }
        None => instances.extend(document.meshes().map(|m| (m, DMat4::IDENTITY))),
    }
    let mut lines = std::collections::BTreeSet::new();
    // Each primitive is read once, however many nodes place its mesh.
    let mut primitives: HashMap<(usize, usize), Primitive> = HashMap::new();
    for (mesh, world) in &instances {
        if !world.is_finite() {
            return Err(bad(format!(
                "mesh {} is placed by a transform that is not finite",
                mesh.index()
            )));
        }
        // Normals turn by the inverse transpose (a mirroring transform keeps them outward).
        let turn = DMat3::from_mat4(*world).inverse().transpose();
        for prim in mesh.primitives() {
            let key = (mesh.index(), prim.index());
            if !matches!(
                prim.mode(),
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                lines.insert(key);
                continue;
            }
            let local = match primitives.entry(key) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => {
                    let what = format!("mesh {} primitive {}", key.0, key.1);
                    e.insert(read_primitive(&prim, &buffers, &what).map_err(bad)?)
                }
            };
            let local = &*local;
            let base = out.mesh.positions.len();
            if base + local.positions.len() > u32::MAX as usize {
                return Err(bad(format!("over {} vertices", u32::MAX)));
            }
            if out.mesh.triangles.len() + local.triangles.len() > MAX_TRIANGLES {
                return Err(bad(format!(
                    "over {MAX_TRIANGLES} triangles once its meshes' instances are counted"
                )));
            }
            out.mesh.positions.extend(
                local
                    .positions
                    .iter()
                    .map(|p| world.transform_point3(p.as_dvec3()).as_vec3()),
            );
            match &local.normals {
                Some(normals) => out.normals.extend(
                    normals
                        .iter()
                        .map(|n| Some((turn * n.as_dvec3()).as_vec3())),
                ),
                None => out.normals.resize(out.mesh.positions.len(), None),
            }
            out.material_of
                .extend(std::iter::repeat_n(local.material, local.triangles.len()));
            if let (Some(m), false) = (local.material, local.uvs.is_empty()) {
                textured.insert(m as usize);
            }
            out.uvs.extend(
                local
                    .triangles
                    .iter()
                    .map(|t| t.map(|i| local.uvs.get(i as usize).copied().unwrap_or(Vec2::ZERO))),
            );
            coloured |= !local.colours.is_empty();
            out.colours.extend(
                local
                    .triangles
                    .iter()
                    .map(|t| t.map(|i| local.colours.get(i as usize).copied().unwrap_or([255; 3]))),
            );
            out.mesh
                .triangles
                .extend(local.triangles.iter().map(|t| t.map(|i| i + base as u32)));
        }
    }
    if !lines.is_empty() {
        out.warnings.push(format!(
            "{} primitive{} of points or lines left out",
            lines.len(),
            if lines.len() == 1 { "" } else { "s" }
        ));
    }
    if out.material_of.iter().all(Option::is_none) {
        out.material_of.clear();
    }
    if textured.is_empty() {
        out.uvs.clear();
    }
    if !coloured {
        out.colours.clear();
    }
    // Extensions the file uses (and does not require: the crate's validation refuses those it
    // does not know) are not read; what is drawn is the file without them.
    let unread: Vec<&str> = document
        .extensions_used()
        .filter(|e| *e != "KHR_texture_transform")
        .collect();
    if !unread.is_empty() {
        out.warnings.push(format!(
            "it uses {}, which raystream does not read: drawn without",
            unread.join(", ")
        ));
    }
    // The textures of the materials that some triangle has coordinates for.
    for (k, m) in document.materials().enumerate().filter(|_| with_textures) {
        let Some(info) = m.pbr_metallic_roughness().base_color_texture() else {
            continue;
        };
        let name = out.materials[k].name.clone();
        if !textured.contains(&k) {
            out.warnings.push(format!(
                "material '{name}': its base colour texture is not applied: its faces give no texture coordinates (TEXCOORD_{}); its base colour stands in",
                info.tex_coord()
            ));
            continue;
        }
        let texture = info.texture();
        match image(&document, texture.source().index(), &buffers, dir) {
            Ok(t) => {
                let (mut mapping, warning) = wrapping(&texture.sampler());
                if let Some(w) = warning {
                    out.warnings.push(format!("material '{name}': {w}"));
                }
                // KHR_texture_transform: glTF's coordinates scaled, then offset (in the
                // image's top-down v); on the renderers' v-up coordinates (1 − v) the same
                // lookup is a scale of s and an offset of (o_u, 1 − s_v − o_v).
                if let Some(t) = info.texture_transform() {
                    let ([su, sv], [ou, ov]) = (t.scale(), t.offset());
                    if t.rotation() != 0.0 {
                        out.warnings.push(format!(
                            "material '{name}': its texture transform turns the coordinates, which is not applied"
                        ));
                    } else {
                        mapping.scale = Vec2::new(su, sv);
                        mapping.offset = Vec2::new(ou, 1.0 - sv - ov);
                    }
                }
                out.materials[k].texture = Some(format!("image {}", texture.source().index()));
                out.materials[k].image = Some(Texture { mapping, ..t });
            }
            Err(e) => out.warnings.push(format!(
                "material '{name}': image {}: {e}; its base colour stands in",
                texture.source().index()
            )),
        }
    }
    Ok(out)
}

/// An image's texture: from a buffer view (a GLB's), or a file beside the document. Its
/// texels multiply the base colour factor, as glTF's base colour texture does.
///
/// Read from the document's JSON, not through `gltf::Image::source`, which unwraps a missing
/// MIME type, and a missing URI (a panic on such a file; the crate's validation lets both by).
fn image(
    document: &gltf::Document,
    index: usize,
    buffers: &[gltf::buffer::Data],
    dir: Option<&Path>,
) -> Result<Texture, String> {
    let json = document
        .as_json()
        .images
        .get(index)
        .ok_or("no such image")?;
    match (&json.buffer_view, &json.uri) {
        (Some(v), _) => {
            let view = document
                .views()
                .nth(v.value())
                .ok_or("no such buffer view")?;
            let data = buffers
                .get(view.buffer().index())
                .map_or(&[][..], |d| &d.0[..]);
            let bytes = view
                .offset()
                .checked_add(view.length())
                .and_then(|end| data.get(view.offset()..end))
                .ok_or("its buffer view runs past its buffer")?;
            Texture::decode(bytes)
        }
        (None, None) => Err("neither a buffer view nor a URI".into()),
        (None, Some(uri)) => {
            use base64::Engine;
            if let Some(data) = uri.strip_prefix("data:") {
                let (_, encoded) = data
                    .split_once(";base64,")
                    .ok_or("a data URI that is not base64")?;
                let bytes = base64::engine::general_purpose::STANDARD
                    .decode(encoded)
                    .map_err(|e| format!("a data URI that is not base64 ({e})"))?;
                return Texture::decode(&bytes);
            }
            if uri.contains(':') {
                return Err(format!(
                    "{uri}: only file names beside the document are read"
                ));
            }
            let name = urlencoding::decode(uri)
                .map_err(|_| format!("{uri}: its %-escapes are not UTF-8"))?;
            let dir = dir.ok_or("an image in a file, and no folder to look in")?;
            Texture::load(&dir.join(&*name)).map_err(|e| format!("{name}: {e}"))
        }
    }
}

/// How a sampler wraps: both ways clamped to the edge, or else repeating; a mirrored repeat,
/// or clamping one way only, repeats with a warning (the renderers have one wrap for both).
fn wrapping(sampler: &gltf::texture::Sampler) -> (TextureMapping, Option<String>) {
    use gltf::texture::WrappingMode::{ClampToEdge, Repeat};
    let (s, t) = (sampler.wrap_s(), sampler.wrap_t());
    let clamp = s == ClampToEdge && t == ClampToEdge;
    let warning = (!clamp && (s != Repeat || t != Repeat))
        .then(|| format!("its texture wraps {s:?} and {t:?}, which is read as repeating"));
    (
        TextureMapping {
            clamp,
            ..TextureMapping::default()
        },
        warning,
    )
}

/// A glTF material as the Phong materials take it: the base colour's RGB (linear, as glTF
/// gives it) as the diffuse colour, its alpha as the dissolve where the material blends.
fn material(m: gltf::Material) -> MtlMaterial {
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, a] = pbr.base_color_factor();
    MtlMaterial {
        name: m.name().map_or_else(
            || format!("material {}", m.index().unwrap_or(0)),
            str::to_string,
        ),
        diffuse: Some([r, g, b]),
        dissolve: (m.alpha_mode() == gltf::material::AlphaMode::Blend && a < 1.0).then_some(a),
        ..Default::default()
    }
}

/// A primitive's triangles as the file gives them, before a node places them.
struct Primitive {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    /// Indices into `positions`.
    triangles: Vec<[u32; 3]>,
    /// Per vertex, the base colour texture's coordinates (v up); empty where the material
    /// has no texture or the primitive no coordinates for it.
    uvs: Vec<Vec2>,
    /// Per vertex, `COLOR_0` as 8-bit sRGB; empty where the primitive has none.
    colours: Vec<Rgb8>,
    material: Option<u32>,
}

/// Reads a primitive of triangles (a list, a strip or a fan); errors begin with `what`.
fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    what: &str,
) -> Result<Primitive, String> {
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let positions = prim
        .get(&gltf::Semantic::Positions)
        .ok_or_else(|| format!("{what} has no POSITION"))?;
    check(&positions, &[DataType::F32], Dimensions::Vec3, buffers)
        .map_err(|e| format!("{what}: POSITION {e}"))?;
    let count = positions.count();
    let unreadable = |name: &str| format!("{what}: {name} cannot be read");
    let read = reader
        .read_positions()
        .ok_or_else(|| unreadable("POSITION"))?;
    let positions: Vec<Vec3> = read.map(Vec3::from_array).collect();
    // A per-vertex attribute: as `check` has it, and one item a position.
    let per_vertex = |a: &gltf::Accessor, types: &[DataType], dims, name: &str, items: &str| {
        check(a, types, dims, buffers).map_err(|e| format!("{what}: {name} {e}"))?;
        match a.count() {
            n if n == count => Ok(()),
            n => Err(format!("{what}: {n} {items} for {count} positions")),
        }
    };
    let normals = match prim.get(&gltf::Semantic::Normals) {
        Some(n) => {
            per_vertex(&n, &[DataType::F32], Dimensions::Vec3, "NORMAL", "normals")?;
            let read = reader.read_normals().ok_or_else(|| unreadable("NORMAL"))?;
            Some(read.map(Vec3::from_array).collect())
        }
        None => None,
    };
    // The corners, as the primitive lists them.
    let corners: Vec<u32> = match prim.indices() {
        Some(idx) => {
            check(
                &idx,
                &[DataType::U8, DataType::U16, DataType::U32],
                Dimensions::Scalar,
                buffers,
            )
            .map_err(|e| format!("{what}: its indices {e}"))?;
            let read = reader
                .read_indices()
                .ok_or_else(|| unreadable("its indices"))?;
            let corners: Vec<u32> = read.into_u32().collect();
            if let Some(&i) = corners.iter().find(|&&i| i as usize >= count) {
                return Err(format!("{what}: index {i}, but it has {count} vertices"));
            }
            corners
        }
        None => (0..count as u32).collect(),
    };
    // The texture's coordinates, where the material has a texture: glTF's v runs down the
    // image, OBJ's (and the renderers') up.
    let set = prim
        .material()
        .pbr_metallic_roughness()
        .base_color_texture()
        .map(|t| {
            let transform = t.texture_transform().and_then(|x| x.tex_coord());
            transform.unwrap_or(t.tex_coord())
        });
    let uvs = match set.and_then(|k| prim.get(&gltf::Semantic::TexCoords(k)).map(|a| (k, a))) {
        Some((k, a)) => {
            let name = format!("TEXCOORD_{k}");
            let types = [DataType::F32, DataType::U8, DataType::U16];
            per_vertex(&a, &types, Dimensions::Vec2, &name, "texture coordinates")?;
            let read = reader.read_tex_coords(k).ok_or_else(|| unreadable(&name))?;
            read.into_f32()
                .map(|[u, v]| Vec2::new(u, 1.0 - v))
                .collect()
        }
        None => Vec::new(),
    };
    // Vertex colours, linear light in glTF (RGB or RGBA; the alpha is not read).
    let colours = match prim.get(&gltf::Semantic::Colors(0)) {
        Some(a) => {
            let types = [DataType::F32, DataType::U8, DataType::U16];
            per_vertex(&a, &types, Dimensions::Vec3, "COLOR_0", "colours")
                .or_else(|_| per_vertex(&a, &types, Dimensions::Vec4, "COLOR_0", "colours"))?;
            let read = reader.read_colors(0).ok_or_else(|| unreadable("COLOR_0"))?;
            read.into_rgb_f32()
                .map(|c| c.map(|x| crate::texture::linear_to_srgb8(x as f64)))
                .collect()
        }
        None => Vec::new(),
    };
    Ok(Primitive {
        positions,
        normals,
        triangles: assemble(prim.mode(), &corners),
        uvs,
        colours,
        material: prim.material().index().map(|m| m as u32),
    })
}

/// Checks that `a` is of one of `types` and of `dims`, is not sparse, and lies within its
/// buffer view and its buffer: the reach the readers take for granted.
fn check(
    a: &gltf::Accessor,
    types: &[DataType],
    dims: Dimensions,
    buffers: &[gltf::buffer::Data],
) -> Result<(), String> {
    if !types.contains(&a.data_type()) || a.dimensions() != dims {
        return Err(format!(
            "is {:?} {:?}, not {dims:?} of {types:?}",
            a.dimensions(),
            a.data_type()
        ));
    }
    if a.sparse().is_some() {
        return Err("is sparse, which is not read".into());
    }
    let view = a.view().ok_or("has no buffer view")?;
    let size = a.size();
    let stride = view.stride().unwrap_or(size);
    let reach = match a.count() {
        0 => return Err("is empty".into()),
        n => (n - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(size))
            .and_then(|x| x.checked_add(a.offset())),
    };
    let buffer = buffers.get(view.buffer().index()).map_or(0, |d| d.0.len());
    let fits = reach.is_some_and(|r| r <= view.length())
        && view
            .offset()
            .checked_add(view.length())
            .is_some_and(|end| end <= buffer);
    if !fits {
        return Err(format!(
            "({} items of {size} bytes, {stride} apart, from byte {}) runs past its buffer view ({} bytes from byte {} of a buffer of {buffer})",
            a.count(),
            a.offset(),
            view.length(),
            view.offset()
        ));
    }
    Ok(())
}

/// The triangles of `corners` drawn as `mode` (a list, a strip or a fan), degenerate ones of
/// a strip's or fan's joins included as the file gives them.
fn assemble(mode: Mode, corners: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => (2..corners.len())
            .map(|k| {
                let (a, b, c) = (corners[k - 2], corners[k - 1], corners[k]);
                // Every other triangle of a strip is wound the other way: the specification's
                // order turns it back.
                if k % 2 == 0 { [a, b, c] } else { [a, c, b] }
            })
            .collect(),
        Mode::TriangleFan => (2..corners.len())
            .map(|k| [corners[k - 1], corners[k], corners[0]])
            .collect(),
        _ => corners
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MeshFormat, load_mesh_with_shading, parse_mesh};

    /// A GLB container of `json` and the binary chunk `bin`.
    fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
        let pad = |mut v: Vec<u8>, with: u8| {
            while !v.len().is_multiple_of(4) {
                v.push(with);
            }
            v
        };
        let (j, b) = (pad(json.as_bytes().to_vec(), b' '), pad(bin.to_vec(), 0));
        let total = 12 + 8 + j.len() + 8 + b.len();
        let mut out = b"glTF".to_vec();
        for x in [2u32, total as u32, j.len() as u32] {
            out.extend(x.to_le_bytes());
        }
        out.extend(b"JSON");
        out.extend(&j);
        out.extend((b.len() as u32).to_le_bytes());
        out.extend(b"BIN\0");
        out.extend(&b);
        out
    }

    /// A unit quad's four corners (z = 0), its normals (+z), list indices (u16) and strip
    /// indices (u8), as one buffer: bytes 0–47, 48–95, 96–107, 108–111.
    fn quad_bin() -> Vec<u8> {
        let mut b = Vec::new();
        for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]] {
            b.extend(p.iter().flat_map(|x| x.to_le_bytes()));
        }
        for _ in 0..4 {
            b.extend([0f32, 0., 1.].iter().flat_map(|x| x.to_le_bytes()));
        }
        b.extend([0u16, 1, 2, 2, 1, 3].iter().flat_map(|x| x.to_le_bytes()));
        b.extend([0u8, 1, 2, 3]);
        b
    }

    /// The quad's document: mesh 0 draws it as a list (material 0), as a strip (no
    /// material) and as lines; node 1 (scaled by 2) under node 0 (moved 10 along x) and
    /// node 2 (turned a quarter about z) place it. `position` replaces the positions'
    /// accessor, `nodes` the nodes.
    fn quad_json(position: &str, nodes: &str) -> String {
        format!(
            r#"{{"asset": {{"version": "2.0"}},
            "buffers": [{{"byteLength": 112}}],
            "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
                            {{"buffer": 0, "byteOffset": 48, "byteLength": 48}},
                            {{"buffer": 0, "byteOffset": 96, "byteLength": 12}},
                            {{"buffer": 0, "byteOffset": 108, "byteLength": 4}}],
            "accessors": [{position},
                          {{"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}},
                          {{"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}},
                          {{"bufferView": 3, "componentType": 5121, "count": 4, "type": "SCALAR"}}],
            "materials": [{{"name": "brick", "pbrMetallicRoughness": {{"baseColorFactor": [0.8, 0.2, 0.1, 1.0]}}}}],
            "meshes": [{{"primitives": [
                {{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2, "material": 0}},
                {{"attributes": {{"POSITION": 0}}, "indices": 3, "mode": 5}},
                {{"attributes": {{"POSITION": 0}}, "mode": 1}}]}}],
            "nodes": {nodes},
            "scenes": [{{"nodes": [0, 2]}}], "scene": 0}}"#
        )
    }

    const POSITION: &str = r#"{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#;
    const NODES: &str = r#"[{"translation": [10, 0, 0], "children": [1]},
                            {"scale": [2, 2, 2], "mesh": 0},
                            {"rotation": [0, 0, 0.70710677, 0.70710677], "mesh": 0}]"#;

    /// `bytes` written to `name` in the test's scratch folder `dir`.
    fn write(dir: &std::path::Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    /// The quad placed twice: every instance's triangles in the scene's order, list then
    /// strip (wound as the list is), the lines left out with a warning, the corners where the
    /// nodes' transforms put them, the normals turned (a scale leaves them as they are), and
    /// the list's material its base colour.
    #[test]
    fn a_scene_places_each_instance_of_its_meshes() {
        let scratch = crate::tests::scratch_dir("gltf");
        let dir = scratch.path();
        let path = write(
            dir,
            "quad.glb",
            &glb(&quad_json(POSITION, NODES), &quad_bin()),
        );
        let (mesh, shading) = load_mesh_with_shading(&path).unwrap();
        assert_eq!(mesh.triangles.len(), 8);
        assert_eq!(mesh.positions.len(), 16);
        // Each instance: the list's corners are its vertices 0–3, the strip's 4–7.
        let want: Vec<[u32; 3]> = [0u32, 8]
            .iter()
            .flat_map(|&b| [[0, 1, 2], [2, 1, 3], [4, 5, 6], [5, 7, 6]].map(|t| t.map(|i| i + b)))
            .collect();
        assert_eq!(mesh.triangles, want);
        let quad = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
        for (k, p) in mesh.positions.iter().enumerate() {
            let q = quad[k % 4];
            let want = if k < 8 {
                Vec3::new(10.0, 0.0, 0.0) + 2.0 * q
            } else {
                Vec3::new(-q.y, q.x, 0.0)
            };
            assert!((*p - want).length() < 1e-6, "vertex {k}: {p} for {want}");
        }
        // Every triangle faces +z, as the quad does.
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            assert!((b - a).cross(c - a).z > 0.0, "{t:?}");
        }
        // The list's vertices have the file's normals, the strip's the faces' (+z too).
        assert_eq!(shading.normals.len(), 16);
        for n in &shading.normals {
            assert!((*n - Vec3::Z).length() < 1e-6, "{n}");
        }
        assert_eq!(shading.materials.len(), 1);
        assert_eq!(shading.materials[0].name, "brick");
        assert_eq!(shading.materials[0].diffuse, Some([0.8, 0.2, 0.1]));
        let some = Some(0);
        assert_eq!(
            shading.material_of,
            [some, some, None, None, some, some, None, None]
        );
        assert_eq!(
            shading.warnings,
            ["1 primitive of points or lines left out"]
        );
        // The same triangles without the shading, and from a .gltf beside its .bin.
        assert_eq!(crate::load_mesh(&path).unwrap(), mesh);
        write(dir, "quad.bin", &quad_bin());
        let json = quad_json(POSITION, NODES).replace(
            r#""buffers": [{"byteLength": 112}]"#,
            r#""buffers": [{"byteLength": 112, "uri": "quad.bin"}]"#,
        );
        let text = write(dir, "quad.gltf", json.as_bytes());
        assert_eq!(crate::load_mesh(&text).unwrap(), mesh);
        // A base colour texture without texture coordinates is not applied: a warning, and
        // the factor stands in.
        let textured = quad_json(POSITION, NODES)
            .replace(
                r#""baseColorFactor": [0.8, 0.2, 0.1, 1.0]}"#,
                r#""baseColorFactor": [0.8, 0.2, 0.1, 1.0], "baseColorTexture": {"index": 0}}"#,
            )
            .replace(
                r#""meshes""#,
                r#""textures": [{"source": 0}], "images": [{"uri": "brick.png"}], "meshes""#,
            );
        let path = write(dir, "textured.glb", &glb(&textured, &quad_bin()));
        let (again, shading) = load_mesh_with_shading(&path).unwrap();
        assert_eq!(again, mesh);
        assert_eq!(shading.materials[0].diffuse, Some([0.8, 0.2, 0.1]));
        assert!(
            shading.warnings.iter().any(|w| w
                .contains("material 'brick': its base colour texture is not applied: its faces give no texture coordinates (TEXCOORD_0)")),
            "{:?}",
            shading.warnings
        );
        // An extension used is not read: a warning names it.
        let extended = quad_json(POSITION, NODES).replace(
            r#""asset""#,
            r#""extensionsUsed": ["KHR_materials_emissive_strength"], "asset""#,
        );
        let path = write(dir, "extended.glb", &glb(&extended, &quad_bin()));
        let (again, shading) = load_mesh_with_shading(&path).unwrap();
        assert_eq!(again, mesh);
        assert!(
            shading.warnings.contains(
                &"it uses KHR_materials_emissive_strength, which raystream does not read: drawn without"
                    .to_string()
            ),
            "{:?}",
            shading.warnings
        );
        // Parsed from bytes alone, an external buffer cannot be found.
        let err = parse_mesh(json.as_bytes(), MeshFormat::Gltf, &text).unwrap_err();
        assert!(
            err.to_string()
                .contains("quad.gltf: its buffers cannot be read"),
            "{err}"
        );
    }

    /// A base colour texture: its image from the binary chunk, its coordinates with v turned
    /// up (1 − glTF's), its sampler's wrap; an image that cannot be had (a data URI, a file
    /// that is missing) is a warning and the base colour stands in.
    #[test]
    fn base_colour_textures_are_read() {
        let scratch = crate::tests::scratch_dir("gltf");
        let dir = scratch.path();
        let mut png = Vec::new();
        image::RgbaImage::from_fn(2, 2, |x, y| {
            image::Rgba([100 * x as u8, 100 * y as u8, 7, 255])
        })
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
        let mut bin = quad_bin();
        let uv_at = bin.len();
        for [u, v] in [[0f32, 0.25], [1., 0.], [0., 1.], [1., 0.75]] {
            bin.extend([u, v].iter().flat_map(|x| x.to_le_bytes()));
        }
        let png_at = bin.len();
        bin.extend(&png);
        let doc = |image: &str, wrap: u32| {
            format!(
                r#"{{"asset": {{"version": "2.0"}},
                "buffers": [{{"byteLength": {}}}],
                "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
                                {{"buffer": 0, "byteOffset": 96, "byteLength": 12}},
                                {{"buffer": 0, "byteOffset": {uv_at}, "byteLength": 32}},
                                {{"buffer": 0, "byteOffset": {png_at}, "byteLength": {}}}],
                "accessors": [{POSITION},
                              {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}},
                              {{"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}}],
                "samplers": [{{"wrapS": {wrap}, "wrapT": {wrap}}}],
                "textures": [{{"source": 0, "sampler": 0}}],
                "images": [{image}],
                "materials": [{{"name": "paint", "pbrMetallicRoughness": {{"baseColorTexture": {{"index": 0}}}}}}],
                "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 2}}, "indices": 1, "material": 0}}]}}],
                "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]}}"#,
                bin.len(),
                png.len()
            )
        };
        let in_bin = r#"{"bufferView": 3, "mimeType": "image/png"}"#;
        let (clamp, mirror) = (33071, 33648);
        let path = write(dir, "textured-quad.glb", &glb(&doc(in_bin, clamp), &bin));
        let (_, shading) = load_mesh_with_shading(&path).unwrap();
        assert!(shading.warnings.is_empty(), "{:?}", shading.warnings);
        let t = shading.materials[0].image.as_ref().expect("the texture");
        let texels = t.texels.clone();
        assert_eq!((t.width, t.height), (2, 2));
        assert_eq!(t.texels[3], [100, 100, 7, 255]);
        assert!(t.mapping.clamp);
        let uv = |u: f32, v: f32| Vec2::new(u, v);
        assert_eq!(
            shading.uvs,
            [
                [uv(0.0, 0.75), uv(1.0, 1.0), uv(0.0, 0.0)],
                [uv(0.0, 0.0), uv(1.0, 1.0), uv(1.0, 0.25)]
            ]
        );
        // KHR_texture_transform: scaled by (2, 0.5) and moved by (0.5, 0.1) in glTF's
        // coordinates (repeating), the lookup at glTF's (0.125, 1.3) lands on (0.75, 0.75):
        // the centre of the bottom row's second texel.
        let repeat = 10497;
        let transformed = doc(in_bin, repeat)
            .replace(
                r#""baseColorTexture": {"index": 0}"#,
                r#""baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.1], "scale": [2, 0.5]}}}"#,
            )
            .replace(r#""asset""#, r#""extensionsUsed": ["KHR_texture_transform"], "asset""#);
        let path = write(dir, "transformed-quad.glb", &glb(&transformed, &bin));
        let (_, shading) = load_mesh_with_shading(&path).unwrap();
        assert!(shading.warnings.is_empty(), "{:?}", shading.warnings);
        let moved = shading.materials[0].image.as_ref().unwrap();
        assert_eq!(moved.mapping.scale, Vec2::new(2.0, 0.5));
        let lut = &*crate::SRGB_TO_LINEAR;
        let want = t.texels[3].map(|c| lut[c as usize]);
        let got = moved.sample(Vec2::new(0.125, 1.0 - 1.3));
        assert!(
            (got - Vec3::new(want[0], want[1], want[2])).length() < 1e-5,
            "{got} for {want:?}"
        );
        // A mirrored repeat repeats, with a warning.
        let path = write(dir, "mirrored-quad.glb", &glb(&doc(in_bin, mirror), &bin));
        let (_, shading) = load_mesh_with_shading(&path).unwrap();
        assert!(!shading.materials[0].image.as_ref().unwrap().mapping.clamp);
        assert!(
            shading.warnings[0].contains("MirroredRepeat"),
            "{:?}",
            shading.warnings
        );
        // Images that cannot be had.
        // An image in a data URI is read as it is from the binary chunk; a file name's
        // %-escapes are decoded.
        use base64::Engine;
        let data = format!(
            r#"{{"uri": "data:image/png;base64,{}"}}"#,
            base64::engine::general_purpose::STANDARD.encode(&png)
        );
        std::fs::write(dir.join("my paint.png"), &png).unwrap();
        // (The MIME type a view's image must name is not needed: the bytes say what they are.)
        let unnamed = r#"{"bufferView": 3}"#;
        for image in [data.as_str(), r#"{"uri": "my%20paint.png"}"#, unnamed] {
            let path = write(dir, "uri-image.glb", &glb(&doc(image, clamp), &bin));
            let (_, shading) = load_mesh_with_shading(&path).unwrap();
            assert!(shading.warnings.is_empty(), "{:?}", shading.warnings);
            assert_eq!(shading.materials[0].image.as_ref().unwrap().texels, texels);
        }
        for (image, want) in [
            (
                r#"{"uri": "data:image/png;base64,AAAA"}"#,
                "image 0: not a readable PNG or JPEG",
            ),
            (
                r#"{"uri": "data:image/png,AAAA"}"#,
                "a data URI that is not base64",
            ),
            (r#"{"uri": "missing.png"}"#, "image 0: missing.png: "),
            (
                r#"{"uri": "%FF.png"}"#,
                "%FF.png: its %-escapes are not UTF-8",
            ),
            (
                r#"{"uri": "https://example.com/x.png"}"#,
                "only file names beside the document",
            ),
            (r#"{"name": "nowhere"}"#, "neither a buffer view nor a URI"),
        ] {
            let path = write(dir, "lost-image.glb", &glb(&doc(image, clamp), &bin));
            let (_, shading) = load_mesh_with_shading(&path).unwrap();
            assert!(shading.materials[0].image.is_none());
            assert!(
                shading
                    .warnings
                    .iter()
                    .any(|w| w.contains(want) && w.contains("its base colour stands in")),
                "{:?}",
                shading.warnings
            );
        }
    }

    /// A corrupt file is an error naming it and the problem, never a panic.
    #[test]
    fn corrupt_gltf_is_a_clear_error() {
        let bin = quad_bin();
        let good = glb(&quad_json(POSITION, NODES), &bin);
        let problem = |bytes: &[u8]| {
            let e = parse_mesh(bytes, MeshFormat::Gltf, Path::new("bad.glb")).unwrap_err();
            let s = e.to_string();
            assert!(s.starts_with("bad.glb: "), "{s}");
            s
        };
        assert!(problem(&good[..good.len() / 2]).contains("not valid glTF"));
        assert!(problem(b"{\"asset\": ").contains("not valid glTF"));
        let position = |p: &str| glb(&quad_json(p, NODES), &bin);
        let far = POSITION.replace("\"count\": 4", "\"count\": 1000000000");
        assert!(
            problem(&position(&far)).contains("runs past its buffer view"),
            "{far}"
        );
        let shifted = POSITION.replace(
            "\"bufferView\": 0,",
            "\"bufferView\": 0, \"byteOffset\": 40,",
        );
        assert!(problem(&position(&shifted)).contains("runs past its buffer view"));
        let wrong = POSITION.replace("5126", "5123");
        assert!(problem(&position(&wrong)).contains("POSITION is Vec3 U16"));
        // An index beyond the vertices.
        let mut big = bin.clone();
        big[96..98].copy_from_slice(&9u16.to_le_bytes());
        assert!(
            problem(&glb(&quad_json(POSITION, NODES), &big))
                .contains("index 9, but it has 4 vertices")
        );
        // A NaN corner.
        let mut nan = bin.clone();
        nan[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(problem(&glb(&quad_json(POSITION, NODES), &nan)).contains("NaN"));
        // Nodes that are each other's children.
        let cycle = r#"[{"children": [1]}, {"children": [0], "mesh": 0}, {"mesh": 0}]"#;
        let s = problem(&glb(&quad_json(POSITION, cycle), &bin));
        assert!(
            s.contains("not valid glTF") || s.contains("deeper than"),
            "{s}"
        );
        // A node that lists itself as a child 8,192 times: refused before the nodes waiting
        // to be visited fill the memory.
        let zeros = vec!["0"; 8192].join(",");
        let fan =
            format!(r#"[{{"children": [{zeros}], "mesh": 0}}, {{"mesh": 0}}, {{"mesh": 0}}]"#);
        let s = problem(&glb(&quad_json(POSITION, &fan), &bin));
        assert!(
            s.contains("over 1048576 nodes waiting to be visited"),
            "{s}"
        );
        // A primitive naming an accessor the file lacks (which gltf-json's validation would
        // look up unchecked).
        let missing = quad_json(POSITION, NODES).replace(
            r#""POSITION": 0, "NORMAL": 1"#,
            r#""POSITION": 7, "NORMAL": 1"#,
        );
        assert!(problem(&glb(&missing, &bin)).contains("names accessor 7, but the file has 4"));
        // A buffer's file name whose %-escapes are not UTF-8 (the gltf crate unwraps them).
        let escaped = quad_json(POSITION, NODES).replace(
            r#""buffers": [{"byteLength": 112}]"#,
            r#""buffers": [{"byteLength": 112, "uri": "%FF.bin"}]"#,
        );
        assert!(problem(escaped.as_bytes()).contains("its URI '%FF.bin' is not a file name"));
        // A buffer shorter than it claims.
        let short = glb(&quad_json(POSITION, NODES), &bin[..64]);
        assert!(problem(&short).contains("its buffers cannot be read"));
    }
}
