//! 3MF (the 3D Manufacturing Format of the 3MF Consortium: core specification 1.3, the
//! Materials and Properties extension's colour groups, and the Production extension's
//! `p:path`): what 3D printing software (Materialise, PrusaSlicer, Cura, Bambu Studio) saves,
//! and a multi-part model with each part's name and colour, in millimetres.
//!
//! A package is a ZIP archive; its root relationship (`_rels/.rels`) names the model part
//! (an XML document). The triangles drawn are the build's: each `<item>` places an object by
//! its transform, an object being a mesh or components (other objects, each placed by its own
//! transform, possibly in another model part of the package). Coordinates are scaled from the
//! model's `unit` to millimetres. A triangle's colour is its property (`pid`, `p1`, `p2`, `p3`)
//! or its object's (`pid`, `pindex`) in a `<basematerials>` group (each material's
//! `displaycolor`) or a `<colorgroup>` (each `<color>`); triangles with none are drawn the
//! default grey ([`crate::UNCOLOURED_GREY`]), and other kinds of properties (textures,
//! composites) are left undrawn with a warning.
//!
//! Written by hand over `zip` and `roxmltree`: threemf 0.8, the crate on crates.io, maps
//! elements by their namespace prefix through serde (a file that binds the materials namespace
//! to another prefix fails), and reads no components, colour groups or triangle properties.

use std::collections::HashMap;
use std::io::{Cursor, Read, Write};
use std::path::Path;

use raystream_math::{DAffine3, DVec3};

use crate::{MeshError, MeshPart, Rgb8, TriMesh};

const CORE: &str = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02";
const MATERIAL: &str = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02";
const PRODUCTION: &str = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06";
const MODEL_RELATIONSHIP: &str = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel";
/// The most bytes a model part may unpack to (a ZIP entry's claimed size is not trusted).
const MAX_PART_BYTES: u64 = 2 << 30;
/// The deepest nesting of components read (the specification forbids cycles).
const MAX_DEPTH: usize = 32;

/// A mesh read from a 3MF package, with its triangles' colours (empty: it gives none) and its
/// build's objects: each build item's object's name (or "object ID") and the triangles it
/// placed, in the build's order.
pub(crate) struct ThreeMf {
    pub mesh: TriMesh,
    pub colours: Vec<[Rgb8; 3]>,
    pub objects: Vec<(String, usize)>,
    pub warnings: Vec<String>,
}

/// A triangle's properties: its group's id and its corners' indices in it.
type Properties = Option<(u32, [u32; 3])>;

enum Shape {
    Mesh {
        positions: Vec<DVec3>,
        triangles: Vec<[u32; 3]>,
        properties: Vec<Properties>,
    },
    /// Its components, each placing an object.
    Components(Vec<Placement>),
}

/// Where a build item or a component places an object: the model part holding it (`None`:
/// the one naming it), its id, and its transform.
type Placement = (Option<String>, u32, DAffine3);

/// What a model part holds: its objects, its colour groups (base materials' display colours
/// too) and the ids of its other property groups (textures, composites), its unit (only the
/// root part's applies: the model has one) and its build.
struct Part {
    objects: HashMap<u32, Shape>,
    /// The objects' names, where they have one.
    names: HashMap<u32, String>,
    colours: HashMap<u32, Vec<Rgb8>>,
    other_groups: HashMap<u32, String>,
    /// Millimetres a unit.
    scale: f64,
    build: Vec<Placement>,
}

pub(crate) fn parse(bytes: &[u8], path: &Path) -> Result<ThreeMf, MeshError> {
    let bad = |m: String| MeshError::invalid(path, m);
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes))
        .map_err(|e| bad(format!("not a 3MF package (a ZIP archive): {e}")))?;
    let root = root_part_name(&mut zip).map_err(bad)?;
    let mut parts: HashMap<String, Part> = HashMap::new();
    let part = read_part(&mut zip, &root).map_err(bad)?;
    let scale = part.scale;
    let build = part.build.clone();
    parts.insert(root.clone(), part);
    let mut out = ThreeMf {
        mesh: TriMesh::default(),
        colours: Vec::new(),
        objects: Vec::new(),
        warnings: Vec::new(),
    };
    let mut coloured = false;
    let mut other_kinds = std::collections::BTreeSet::new();
    // Depth first, each object with its world transform (the unit's scale included) and its
    // build item.
    let mut stack: Vec<(String, u32, DAffine3, usize, usize)> = build
        .iter()
        .enumerate()
        .rev()
        .map(|(item, (p, id, m))| {
            let p = p.clone().unwrap_or_else(|| root.clone());
            (
                p,
                *id,
                DAffine3::from_scale(DVec3::splat(scale)) * *m,
                0,
                item,
            )
        })
        .collect();
    if stack.is_empty() {
        return Err(bad("its build places no object".into()));
    }
    let mut visits = 0usize;
    while let Some((part_name, id, world, depth, item)) = stack.pop() {
        visits += 1;
        if visits > crate::gltf::MAX_TRIANGLES {
            return Err(bad(format!(
                "its build visits over {} objects (components listed many times over?)",
                crate::gltf::MAX_TRIANGLES
            )));
        }
        if !parts.contains_key(&part_name) {
            let p = read_part(&mut zip, &part_name).map_err(bad)?;
            parts.insert(part_name.clone(), p);
        }
        let part = &parts[&part_name];
        let where_ = |id: u32| {
            if part_name == root {
                format!("object {id}")
            } else {
                format!("object {id} of {part_name}")
            }
        };
        let shape = part
            .objects
            .get(&id)
            .ok_or_else(|| bad(format!("{} is not defined", where_(id))))?;
        if depth == 0 {
            let name = part.names.get(&id).cloned().unwrap_or_else(|| where_(id));
            out.objects.push((name, 0));
        }
        match shape {
            Shape::Components(components) => {
                if depth >= MAX_DEPTH {
                    return Err(bad(format!(
                        "its components nest deeper than {MAX_DEPTH} (a cycle?), at {}",
                        where_(id)
                    )));
                }
                for (p, child, m) in components.iter().rev() {
                    let p = p.clone().unwrap_or_else(|| part_name.clone());
                    stack.push((p, *child, world * *m, depth + 1, item));
                }
            }
            Shape::Mesh {
                positions,
                triangles,
                properties,
            } => {
                if !world.is_finite() {
                    return Err(bad(format!(
                        "{} is placed by a transform that is not finite",
                        where_(id)
                    )));
                }
                let base = out.mesh.positions.len();
                if base + positions.len() > u32::MAX as usize
                    || out.mesh.triangles.len() + triangles.len() > crate::gltf::MAX_TRIANGLES
                {
                    return Err(bad(format!(
                        "over {} triangles once its objects' placements are counted",
                        crate::gltf::MAX_TRIANGLES
                    )));
                }
                out.mesh.positions.extend(
                    positions
                        .iter()
                        .map(|p| world.transform_point3(*p).as_vec3()),
                );
                out.objects[item].1 += triangles.len();
                // A mirroring transform turns the triangles inside out: turned back.
                let mirrored = world.matrix3.determinant() < 0.0;
                out.mesh.triangles.extend(triangles.iter().map(|t| {
                    let [a, b, c] = t.map(|v| v + base as u32);
                    if mirrored { [a, c, b] } else { [a, b, c] }
                }));
                for (k, p) in properties.iter().enumerate() {
                    let colour = match p {
                        None => None,
                        Some((group, corners)) => match part.colours.get(group) {
                            Some(colours) => {
                                let c = corners.map(|i| colours.get(i as usize).copied());
                                let [Some(a), Some(b), Some(c)] = c else {
                                    return Err(bad(format!(
                                        "{}, triangle {k}: a property index beyond group {group}'s {} entries",
                                        where_(id),
                                        colours.len()
                                    )));
                                };
                                Some(if mirrored { [a, c, b] } else { [a, b, c] })
                            }
                            None => match part.other_groups.get(group) {
                                Some(kind) => {
                                    other_kinds.insert(kind.clone());
                                    None
                                }
                                None => {
                                    return Err(bad(format!(
                                        "{}, triangle {k}: property group {group} is not defined",
                                        where_(id)
                                    )));
                                }
                            },
                        },
                    };
                    if colour.is_some() && !coloured {
                        coloured = true;
                        out.colours = vec![
                            [crate::UNCOLOURED_GREY; 3];
                            out.mesh.triangles.len() - triangles.len() + k
                        ];
                    }
                    if coloured {
                        out.colours
                            .push(colour.unwrap_or([crate::UNCOLOURED_GREY; 3]));
                    }
                }
            }
        }
    }
    if !other_kinds.is_empty() {
        out.warnings.push(format!(
            "its {} properties are not drawn (the triangles they cover are grey)",
            other_kinds.into_iter().collect::<Vec<_>>().join(", ")
        ));
    }
    Ok(out)
}

/// The model part the package's root relationships name (`3D/3dmodel.model` where it has
/// none).
fn root_part_name(zip: &mut zip::ZipArchive<Cursor<&[u8]>>) -> Result<String, String> {
    let Ok(text) = unpack(zip, "_rels/.rels") else {
        return Ok("3D/3dmodel.model".into());
    };
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| format!("its root relationships (_rels/.rels) are not XML: {e}"))?;
    doc.descendants()
        .find(|n| {
            n.tag_name().name() == "Relationship" && n.attribute("Type") == Some(MODEL_RELATIONSHIP)
        })
        .and_then(|n| n.attribute("Target"))
        .map(|t| t.trim_start_matches('/').to_string())
        .ok_or_else(|| "its root relationships (_rels/.rels) name no 3D model part".into())
}

/// The text of the package's part `name`, at most [`MAX_PART_BYTES`].
fn unpack(zip: &mut zip::ZipArchive<Cursor<&[u8]>>, name: &str) -> Result<String, String> {
    let entry = zip.by_name(name).map_err(|e| format!("part {name}: {e}"))?;
    let mut bytes = Vec::new();
    entry
        .take(MAX_PART_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("part {name} cannot be unpacked: {e}"))?;
    if bytes.len() as u64 > MAX_PART_BYTES {
        return Err(format!(
            "part {name} unpacks to more than {MAX_PART_BYTES} bytes"
        ));
    }
    String::from_utf8(bytes).map_err(|_| format!("part {name} is not UTF-8 text"))
}

/// A model part's objects, property groups, unit and build.
fn read_part(zip: &mut zip::ZipArchive<Cursor<&[u8]>>, name: &str) -> Result<Part, String> {
    let text = unpack(zip, name)?;
    let doc = roxmltree::Document::parse(&text).map_err(|e| format!("part {name}: {e}"))?;
    let model = doc.root_element();
    if !model.has_tag_name((CORE, "model")) {
        return Err(format!(
            "part {name} is not a 3MF model (its root is not a core <model>)"
        ));
    }
    let scale = match model.attribute("unit").unwrap_or("millimeter") {
        "micron" => 0.001,
        "millimeter" => 1.0,
        "centimeter" => 10.0,
        "inch" => 25.4,
        "foot" => 304.8,
        "meter" => 1000.0,
        u => return Err(format!("part {name}: unknown unit {u:?}")),
    };
    let mut part = Part {
        objects: HashMap::new(),
        names: HashMap::new(),
        colours: HashMap::new(),
        other_groups: HashMap::new(),
        scale,
        build: Vec::new(),
    };
    let id_of = |n: roxmltree::Node| -> Result<u32, String> {
        number(n, "id")
            .and_then(|id| id.ok_or_else(|| format!("a <{}> has no id", n.tag_name().name())))
            .map_err(|e| format!("part {name}: {e}"))
    };
    for res in children(model, (CORE, "resources")) {
        for r in res.children().filter(|c| c.is_element()) {
            let tag = r.tag_name();
            let ns = tag.namespace().unwrap_or_default();
            match (ns, tag.name()) {
                (CORE, "basematerials") | (MATERIAL, "colorgroup") => {
                    // A base material's colour is its display colour; a colour group's, its own.
                    let (entry, attr) = match ns {
                        CORE => ((CORE, "base"), "displaycolor"),
                        _ => ((MATERIAL, "color"), "color"),
                    };
                    let colours = children(r, entry)
                        .map(|b| colour(b.attribute(attr).unwrap_or_default()))
                        .collect::<Result<_, _>>()
                        .map_err(|e| {
                            format!(
                                "part {name}: {} {}: {e}",
                                tag.name(),
                                r.attribute("id").unwrap_or("?")
                            )
                        })?;
                    part.colours.insert(id_of(r)?, colours);
                }
                (CORE, "object") => {
                    let id = id_of(r)?;
                    let shape = object(r, name, id)?;
                    part.objects.insert(id, shape);
                    if let Some(n) = r.attribute("name").map(str::trim).filter(|n| !n.is_empty()) {
                        part.names.insert(id, n.to_string());
                    }
                }
                (_, kind) if r.attribute("id").is_some() => {
                    part.other_groups.insert(id_of(r)?, kind.to_string());
                }
                _ => {}
            }
        }
    }
    for build in children(model, (CORE, "build")) {
        for item in children(build, (CORE, "item")) {
            part.build
                .push(placement(item).map_err(|e| format!("part {name}: a build item: {e}"))?);
        }
    }
    Ok(part)
}

/// `n`'s child elements named `tag` (namespace, name).
fn children<'a, 'i>(
    n: roxmltree::Node<'a, 'i>,
    tag: (&'static str, &'static str),
) -> impl Iterator<Item = roxmltree::Node<'a, 'i>> {
    n.children().filter(move |c| c.has_tag_name(tag))
}

/// An `<object>`: its mesh (vertices, triangles and their properties, the object's own
/// property where a triangle has none) or its components.
fn object(o: roxmltree::Node, part: &str, id: u32) -> Result<Shape, String> {
    let at = |m: String| format!("part {part}, object {id}: {m}");
    let number = |n: roxmltree::Node, attr: &str| number(n, attr).map_err(at);
    if let Some(components) = children(o, (CORE, "components")).next() {
        return children(components, (CORE, "component"))
            .map(|c| placement(c).map_err(|e| at(format!("a component: {e}"))))
            .collect::<Result<_, _>>()
            .map(Shape::Components);
    }
    let mesh = children(o, (CORE, "mesh"))
        .next()
        .ok_or_else(|| at("neither a mesh nor components".into()))?;
    let own: Properties = match (number(o, "pid")?, number(o, "pindex")?) {
        (Some(pid), Some(i)) => Some((pid, [i; 3])),
        _ => None,
    };
    let mut positions = Vec::new();
    for (k, v) in children(mesh, (CORE, "vertices"))
        .flat_map(|vs| children(vs, (CORE, "vertex")))
        .enumerate()
    {
        let coordinate = |a: &str| -> Result<f64, String> {
            let s = v.attribute(a).unwrap_or_default();
            s.trim()
                .parse()
                .map_err(|_| at(format!("vertex {k}: {a}={s:?} is not a number")))
        };
        positions.push(DVec3::new(
            coordinate("x")?,
            coordinate("y")?,
            coordinate("z")?,
        ));
    }
    let (mut triangles, mut properties) = (Vec::new(), Vec::new());
    for (k, t) in children(mesh, (CORE, "triangles"))
        .flat_map(|ts| children(ts, (CORE, "triangle")))
        .enumerate()
    {
        let mut v = [0u32; 3];
        for (c, attr) in ["v1", "v2", "v3"].iter().enumerate() {
            v[c] = number(t, attr)?.ok_or_else(|| at(format!("triangle {k} has no {attr}")))?;
            if v[c] as usize >= positions.len() {
                return Err(at(format!(
                    "triangle {k} refers to vertex {}, but the object has {} vertices",
                    v[c],
                    positions.len()
                )));
            }
        }
        triangles.push(v);
        let p1 = number(t, "p1")?;
        properties.push(match (number(t, "pid")?, p1, own) {
            (Some(pid), Some(p1), _) => Some((
                pid,
                [
                    p1,
                    number(t, "p2")?.unwrap_or(p1),
                    number(t, "p3")?.unwrap_or(p1),
                ],
            )),
            // A triangle's group without indices takes the object's index in it.
            (Some(pid), None, Some((_, i))) => Some((pid, i)),
            (None, _, own) => own,
            (Some(_), None, None) => None,
        });
    }
    Ok(Shape::Mesh {
        positions,
        triangles,
        properties,
    })
}

/// The number `n`'s attribute `attr` holds (`None`: it has none).
fn number(n: roxmltree::Node, attr: &str) -> Result<Option<u32>, String> {
    n.attribute(attr)
        .map(|v| {
            v.trim()
                .parse()
                .map_err(|_| format!("{attr}={v:?} is not a number"))
        })
        .transpose()
}

/// The placement a build `<item>` or a `<component>` gives: its object (`objectid`, in the
/// part `p:path` names), and its transform.
fn placement(n: roxmltree::Node) -> Result<Placement, String> {
    let id = number(n, "objectid")?.ok_or("it names no object")?;
    let path = n
        .attribute((PRODUCTION, "path"))
        .map(|p| p.trim_start_matches('/').to_string());
    let transform =
        transform(n.attribute("transform")).map_err(|e| format!("its transform: {e}"))?;
    Ok((path, id, transform))
}

/// A `transform` attribute (twelve numbers, the 4×3 matrix of row vectors: `p' = p M`, its
/// last row the translation) as a column-vector matrix; the identity where there is none.
fn transform(attribute: Option<&str>) -> Result<DAffine3, String> {
    let Some(text) = attribute else {
        return Ok(DAffine3::IDENTITY);
    };
    let m: Vec<f64> = text
        .split_ascii_whitespace()
        .map(|x| {
            x.parse::<f64>()
                .map_err(|_| format!("{x:?} is not a number"))
        })
        .collect::<Result<_, _>>()?;
    if m.len() != 12 {
        return Err(format!("{} numbers, not 12", m.len()));
    }
    Ok(DAffine3::from_cols(
        DVec3::new(m[0], m[1], m[2]),
        DVec3::new(m[3], m[4], m[5]),
        DVec3::new(m[6], m[7], m[8]),
        DVec3::new(m[9], m[10], m[11]),
    ))
}

/// `#RRGGBB` or `#RRGGBBAA` (sRGB; the alpha is not read).
fn colour(text: &str) -> Result<Rgb8, String> {
    let hex = text.trim().strip_prefix('#').unwrap_or("");
    let byte = |i: usize| u8::from_str_radix(hex.get(i..i + 2).unwrap_or("?"), 16);
    match (hex.len(), byte(0), byte(2), byte(4)) {
        (6 | 8, Ok(r), Ok(g), Ok(b)) => Ok([r, g, b]),
        _ => Err(format!("{text:?} is not a colour (#RRGGBB or #RRGGBBAA)")),
    }
}

/// Writes `parts` as a 3MF package: an object each (its name, its triangles in millimetres),
/// each coloured by its own base material (its name, its colour in sRGB), all placed by the
/// build as they are.
pub(crate) fn write(w: &mut impl Write, parts: &[MeshPart]) -> std::io::Result<()> {
    use std::fmt::Write as _;
    // Writing into a String cannot fail: the results are dropped.
    let mut model = String::with_capacity(1 << 16);
    let _ = write!(
        model,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<model unit=\"millimeter\" xml:lang=\"en-US\" xmlns=\"{CORE}\">\n \
         <metadata name=\"Title\">raystream isosurface</metadata>\n \
         <metadata name=\"Application\">raystream {}</metadata>\n <resources>\n  <basematerials id=\"1\">\n",
        env!("CARGO_PKG_VERSION")
    );
    for p in parts {
        let [r, g, b] = crate::write::srgb8(p.colour);
        let _ = writeln!(
            model,
            "   <base name=\"{}\" displaycolor=\"#{r:02X}{g:02X}{b:02X}FF\"/>",
            xml_escape(p.name)
        );
    }
    model.push_str("  </basematerials>\n");
    for (k, p) in parts.iter().enumerate() {
        let _ = writeln!(
            model,
            "  <object id=\"{}\" type=\"model\" name=\"{}\" pid=\"1\" pindex=\"{k}\">\n   <mesh>\n    <vertices>",
            k + 2,
            xml_escape(p.name)
        );
        for v in &p.mesh.positions {
            // Shortest round-trip decimal forms: read back, the same f32.
            let _ = writeln!(
                model,
                "     <vertex x=\"{}\" y=\"{}\" z=\"{}\"/>",
                v.x, v.y, v.z
            );
        }
        model.push_str("    </vertices>\n    <triangles>\n");
        for [a, b, c] in &p.mesh.triangles {
            let _ = writeln!(model, "     <triangle v1=\"{a}\" v2=\"{b}\" v3=\"{c}\"/>");
        }
        model.push_str("    </triangles>\n   </mesh>\n  </object>\n");
    }
    model.push_str(" </resources>\n <build>\n");
    for k in 0..parts.len() {
        let _ = writeln!(model, "  <item objectid=\"{}\"/>", k + 2);
    }
    model.push_str(" </build>\n</model>\n");
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let deflated = zip::write::SimpleFileOptions::default();
    let files = [
        (
            "[Content_Types].xml",
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Types xmlns=\"http://schemas.openxmlformats.org/package/2006/content-types\">\n \
             <Default Extension=\"rels\" ContentType=\"application/vnd.openxmlformats-package.relationships+xml\"/>\n \
             <Default Extension=\"model\" ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/>\n</Types>\n"
                .to_string(),
        ),
        (
            "_rels/.rels",
            format!(
                "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Relationships xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\">\n \
                 <Relationship Target=\"/3D/3dmodel.model\" Id=\"rel0\" Type=\"{MODEL_RELATIONSHIP}\"/>\n</Relationships>\n"
            ),
        ),
        ("3D/3dmodel.model", model),
    ];
    for (name, text) in files {
        zip.start_file(name, deflated)
            .map_err(std::io::Error::other)?;
        zip.write_all(text.as_bytes())?;
    }
    let bytes = zip.finish().map_err(std::io::Error::other)?.into_inner();
    w.write_all(&bytes)
}

/// `text` with XML's five special characters escaped, for an attribute value.
fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::path::Path;

    use crate::{MeshFormat, load_mesh_with_shading, parse_mesh};

    /// A package of `model` (the model part's XML), its root relationships naming it.
    fn package(model: &str) -> Vec<u8> {
        package_with(model, &[])
    }

    /// [`package`], with `others` (name, XML) beside it.
    fn package_with(model: &str, others: &[(&str, &str)]) -> Vec<u8> {
        let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let options = zip::write::SimpleFileOptions::default();
        zip.start_file("_rels/.rels", options).unwrap();
        zip.write_all(format!("<Relationships xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\"><Relationship Target=\"/3D/m.model\" Id=\"r\" Type=\"{}\"/></Relationships>", super::MODEL_RELATIONSHIP).as_bytes()).unwrap();
        for (name, text) in [("3D/m.model", model)].iter().chain(others) {
            zip.start_file(*name, options).unwrap();
            zip.write_all(text.as_bytes()).unwrap();
        }
        zip.finish().unwrap().into_inner()
    }

    /// The Production extension's `p:path`: a component's object in another model part (as
    /// Bambu Studio and PrusaSlicer save their objects), in the root model's unit (the model
    /// has one; the other part's is not read); a part the package lacks is an error.
    #[test]
    fn components_in_other_model_parts() {
        let root = format!(
            "<model unit=\"millimeter\" xmlns=\"{}\" xmlns:p=\"{}\"><resources><object id=\"3\"><components>\
             <component p:path=\"/3D/Objects/o.model\" objectid=\"1\" transform=\"1 0 0 0 1 0 0 0 1 0 0 7\"/>\
             </components></object></resources><build><item objectid=\"3\"/></build></model>",
            super::CORE,
            super::PRODUCTION
        );
        let other = model(
            "centimeter",
            &format!(
                "<object id=\"1\"><mesh>{TRIANGLE}<triangles><triangle v1=\"0\" v2=\"1\" v3=\"2\"/></triangles></mesh></object>"
            ),
            "",
        );
        let bytes = package_with(&root, &[("3D/Objects/o.model", &other)]);
        let m = parse_mesh(&bytes, MeshFormat::ThreeMf, Path::new("t.3mf")).unwrap();
        assert_eq!(m.positions[1], crate::Vec3::new(1.0, 0.0, 7.0));
        // The build item's object, unnamed, holds its component's triangle.
        let read = super::parse(&bytes, Path::new("t.3mf")).unwrap();
        assert_eq!(read.objects, [("object 3".to_string(), 1)]);
        let missing = root.replace("o.model", "gone.model");
        let e = error(&package_with(&missing, &[("3D/Objects/o.model", &other)]));
        assert!(e.contains("part 3D/Objects/gone.model"), "{e}");
    }

    /// A model of `resources` and `build`, in `unit`; the materials namespace bound to `mat`.
    fn model(unit: &str, resources: &str, build: &str) -> String {
        format!(
            "<model unit=\"{unit}\" xmlns=\"{}\" xmlns:mat=\"{}\"><resources>{resources}</resources><build>{build}</build></model>",
            super::CORE,
            super::MATERIAL
        )
    }

    const TRIANGLE: &str = "<vertices><vertex x=\"0\" y=\"0\" z=\"0\"/><vertex x=\"1\" y=\"0\" z=\"0\"/><vertex x=\"0\" y=\"1\" z=\"0\"/></vertices>";

    fn error(bytes: &[u8]) -> String {
        let e = parse_mesh(bytes, MeshFormat::ThreeMf, Path::new("t.3mf"))
            .expect_err("bad input must be an error")
            .to_string();
        assert!(e.starts_with("t.3mf: "), "{e}");
        e
    }

    /// Units, a build item's transform (row vectors, its last row the translation), the
    /// materials namespace by its URI whatever its prefix, a triangle's group without indices,
    /// and other kinds of properties left grey with a warning.
    #[test]
    fn placement_units_and_colours() {
        let resources = format!(
            "<mat:colorgroup id=\"5\"><mat:color color=\"#102030\"/><mat:color color=\"#405060FF\"/></mat:colorgroup>\
             <mat:texture2dgroup id=\"6\" texid=\"9\"/>\
             <object id=\"1\" pid=\"5\" pindex=\"1\"><mesh>{TRIANGLE}<triangles>\
             <triangle v1=\"0\" v2=\"1\" v3=\"2\"/><triangle v1=\"0\" v2=\"2\" v3=\"1\" pid=\"5\" p1=\"0\"/>\
             <triangle v1=\"1\" v2=\"2\" v3=\"0\" pid=\"6\" p1=\"0\"/></triangles></mesh></object>"
        );
        let build = "<item objectid=\"1\" transform=\"0 1 0 -1 0 0 0 0 1 10 0 0\"/>";
        // Two build items, the same object twice: an object each, named by it (trimmed).
        let named = resources.replace("<object id=\"1\"", "<object name=\" Femur \" id=\"1\"");
        let twice = package(&model("millimeter", &named, &build.repeat(2)));
        let read = super::parse(&twice, Path::new("t.3mf")).unwrap();
        assert_eq!(
            read.objects,
            [("Femur".to_string(), 3), ("Femur".to_string(), 3)]
        );
        let scratch = crate::tests::scratch_file("t.3mf");
        std::fs::write(&scratch, package(&model("centimeter", &resources, build))).unwrap();
        let (mesh, shading) = load_mesh_with_shading(&scratch).unwrap();
        // (1, 0, 0) turned a quarter about z to (0, 1, 0), moved 10 along x: centimetres.
        assert_eq!(mesh.positions[1], crate::Vec3::new(100.0, 10.0, 0.0));
        assert_eq!(mesh.positions[2], crate::Vec3::new(90.0, 0.0, 0.0));
        let grey = crate::UNCOLOURED_GREY;
        assert_eq!(
            shading.colours,
            [[[64, 80, 96]; 3], [[16, 32, 48]; 3], [grey; 3]]
        );
        assert!(
            shading.warnings[0].contains("texture2dgroup"),
            "{:?}",
            shading.warnings
        );
        // A mirroring transform keeps the triangles facing out: their corners turned.
        let mirrored = "<item objectid=\"1\" transform=\"-1 0 0 0 1 0 0 0 1 0 0 0\"/>";
        let m = parse_mesh(
            &package(&model("millimeter", &resources, mirrored)),
            MeshFormat::ThreeMf,
            Path::new("t.3mf"),
        )
        .unwrap();
        assert_eq!(m.triangles[0], [0, 2, 1]);
    }

    /// Damaged packages are errors naming the file and what is wrong, never panics.
    #[test]
    fn damaged_packages_are_errors_naming_the_file() {
        let mesh = |triangles: &str| {
            format!(
                "<object id=\"1\"><mesh>{TRIANGLE}<triangles>{triangles}</triangles></mesh></object>"
            )
        };
        let one = mesh("<triangle v1=\"0\" v2=\"1\" v3=\"2\"/>");
        let item = "<item objectid=\"1\"/>";
        for (bytes, want) in [
            (b"PK not really".to_vec(), "not a 3MF package"),
            (package("<model"), "part 3D/m.model:"),
            (package("<other/>"), "not a 3MF model"),
            (
                package(&model("parsec", &one, item)),
                "unknown unit \"parsec\"",
            ),
            (
                package(&model("millimeter", &one, "")),
                "its build places no object",
            ),
            (
                package(&model("millimeter", &one, "<item objectid=\"7\"/>")),
                "object 7 is not defined",
            ),
            (
                package(&model(
                    "millimeter",
                    &mesh("<triangle v1=\"0\" v2=\"1\" v3=\"5\"/>"),
                    item,
                )),
                "triangle 0 refers to vertex 5, but the object has 3 vertices",
            ),
            (
                package(&model(
                    "millimeter",
                    &mesh("<triangle v1=\"0\" v2=\"1\" v3=\"2\" pid=\"9\" p1=\"0\"/>"),
                    item,
                )),
                "object 1, triangle 0: property group 9 is not defined",
            ),
            (
                package(&model(
                    "millimeter",
                    &format!(
                        "<basematerials id=\"9\"><base name=\"a\" displaycolor=\"#FFFFFF\"/></basematerials>{}",
                        mesh("<triangle v1=\"0\" v2=\"1\" v3=\"2\" pid=\"9\" p1=\"0\" p2=\"3\"/>")
                    ),
                    item,
                )),
                "a property index beyond group 9's 1 entries",
            ),
            (
                package(&model(
                    "millimeter",
                    "<basematerials id=\"9\"><base name=\"a\" displaycolor=\"white\"/></basematerials>",
                    item,
                )),
                "\"white\" is not a colour",
            ),
            (
                package(&model(
                    "millimeter",
                    &one,
                    "<item objectid=\"1\" transform=\"1 0 0 0 1 0 0 0 1 0 0\"/>",
                )),
                "11 numbers, not 12",
            ),
            (
                package(&model(
                    "millimeter",
                    "<object id=\"2\"><components><component objectid=\"2\"/></components></object>",
                    "<item objectid=\"2\"/>",
                )),
                "its components nest deeper than 32 (a cycle?)",
            ),
            (
                package(&model(
                    "millimeter",
                    &one.replace("x=\"1\"", "x=\"NaN\""),
                    item,
                )),
                "NaN",
            ),
            (
                package(&model(
                    "millimeter",
                    &one.replace("x=\"1\"", "x=\"one\""),
                    item,
                )),
                "vertex 1: x=\"one\" is not a number",
            ),
        ] {
            let e = error(&bytes);
            assert!(e.contains(want), "{e}: wanted {want:?}");
        }
    }
}
