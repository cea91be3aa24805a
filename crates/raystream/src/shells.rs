//! `render --colour-shells`: a mesh's or a CT's bone surface with its largest shells (pieces of
//! triangles joined through their edges, [`raystream_io::TriMesh::measure_shells`]: a CT's
//! islands of bone, a fracture's fragments, a model's parts) each in a colour of its own, so
//! that the pieces can be told apart and counted in the picture, `--legend` naming them.

use raystream_io::{Rgb8, SurfaceMeasures, TriMesh};
use raystream_math::Vec3;

use crate::legend::Entry;

/// The colours of the largest shells in turn (8-bit sRGB): Tableau's ten, a categorical
/// palette made to tell ten things apart, its grey (taken by the shells left over, drawn in
/// the surface's usual colour) swapped for a yellow.
pub const PALETTE: [Rgb8; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [188, 189, 34],
    [23, 190, 207],
    [255, 217, 47],
];

/// Which colour each of `mesh`'s triangles takes: its shell's place in [`PALETTE`] for the
/// largest shells (as many as it has colours), `None` for the others and for triangles in
/// no shell; with the legend's entries, a shell each, and the measures.
pub struct ShellColours {
    pub of_face: Vec<Option<usize>>,
    pub legend: Vec<Entry>,
    pub measures: SurfaceMeasures,
}

/// [`ShellColours`] of `mesh`; its volumes in ml where it is in millimetres (`mm`).
pub fn shell_colours(mesh: &TriMesh, mm: bool) -> ShellColours {
    let (measures, shell) = mesh.measure_shells();
    let of_face = (shell.iter())
        .map(|&k| (k as usize) < PALETTE.len())
        .zip(&shell)
        .map(|(coloured, &k)| coloured.then_some(k as usize))
        .collect();
    let legend = (measures.pieces.iter().zip(PALETTE).enumerate())
        .map(|(k, (p, colour))| {
            let size = match (p.volume, mm) {
                (Some(v), true) => format!("{:.1} ml", v / 1000.0),
                _ => format!("{} triangles", p.faces),
            };
            Entry {
                name: format!("shell {}: {size}", k + 1),
                colour,
            }
        })
        .collect();
    ShellColours {
        of_face,
        legend,
        measures,
    }
}

/// A part of a surface parted by [`shell_parts`]: a shell in its colour, or the rest.
pub struct ShellPart {
    /// "shell 1" …, or "bone" for the rest.
    pub name: String,
    /// Linear RGB; `None` for the rest, drawn in the surface's usual colour.
    pub colour: Option<[f32; 3]>,
    pub mesh: TriMesh,
    pub normals: Vec<Vec3>,
}

/// `mesh` and its vertex `normals` as [`shell_colours`]' `c` colours them: the largest shells
/// a part each, then the rest (where there is any).
pub fn shell_parts(mesh: &TriMesh, normals: &[Vec3], c: &ShellColours) -> Vec<ShellPart> {
    (parted(mesh, normals, &c.of_face).into_iter().enumerate())
        .filter(|(_, (mesh, _))| !mesh.is_empty())
        .map(|(k, (mesh, normals))| {
            let (name, colour) = match c.legend.get(k) {
                Some(e) => (
                    format!("shell {}", k + 1),
                    Some(e.colour.map(|c| raystream_io::SRGB_TO_LINEAR[c as usize])),
                ),
                None => ("bone".to_string(), None),
            };
            ShellPart {
                name,
                colour,
                mesh,
                normals,
            }
        })
        .collect()
}

/// `mesh` and its vertex `normals` parted by `group` (a triangle's group, `None` for the rest):
/// a mesh for each group from 0 up to the largest used, then one for the rest, each with the
/// vertices its triangles use.
fn parted(mesh: &TriMesh, normals: &[Vec3], group: &[Option<usize>]) -> Vec<(TriMesh, Vec<Vec3>)> {
    let groups = group.iter().flatten().max().map_or(0, |&g| g + 1);
    let mut parts: Vec<(TriMesh, Vec<Vec3>)> = vec![Default::default(); groups + 1];
    // Per part, each vertex's new index (`u32::MAX` until used).
    let mut index = vec![vec![u32::MAX; mesh.positions.len()]; groups + 1];
    for (t, g) in mesh.triangles.iter().zip(group) {
        let g = g.unwrap_or(groups);
        let (part, map) = (&mut parts[g], &mut index[g]);
        let corners = t.map(|v| {
            let v = v as usize;
            if map[v] == u32::MAX {
                map[v] = part.0.positions.len() as u32;
                part.0.positions.push(mesh.positions[v]);
                part.1.push(normals[v]);
            }
            map[v]
        });
        part.0.triangles.push(corners);
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cubes apart, the second twice the size: it is shell 1, in the palette's first
    /// colour; parted, each keeps its triangles and their corners.
    #[test]
    fn the_largest_shell_takes_the_first_colour() {
        let cube = |at: Vec3, size: f32| TriMesh {
            positions: (0..8)
                .map(|i| {
                    at + size * Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32)
                })
                .collect(),
            triangles: [
                [0, 2, 3, 1],
                [4, 5, 7, 6],
                [0, 1, 5, 4],
                [2, 6, 7, 3],
                [0, 4, 6, 2],
                [1, 3, 7, 5],
            ]
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect(),
        };
        let mut both = cube(Vec3::ZERO, 1.0);
        let big = cube(Vec3::new(5.0, 0.0, 0.0), 2.0);
        both.append(&big, |p| p);
        let c = shell_colours(&both, true);
        assert_eq!(c.of_face[..12], [Some(1); 12]);
        assert_eq!(c.of_face[12..], [Some(0); 12]);
        let names: Vec<&str> = c.legend.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["shell 1: 0.0 ml", "shell 2: 0.0 ml"]);
        assert_eq!(c.legend[0].colour, PALETTE[0]);
        let normals = vec![Vec3::Z; both.positions.len()];
        let parts = parted(&both, &normals, &c.of_face);
        assert_eq!(parts.len(), 3);
        assert_eq!(parts[0].0.len(), 12);
        assert_eq!(parts[0].0.bounds().min, Vec3::new(5.0, 0.0, 0.0));
        assert_eq!(parts[1].0.positions.len(), 8);
        assert!(parts[2].0.is_empty());
        // Past the palette, the rest.
        let mut many = TriMesh::default();
        for k in 0..12 {
            many.append(
                &cube(Vec3::new(3.0 * k as f32, 0.0, 0.0), 1.0 + k as f32 / 10.0),
                |p| p,
            );
        }
        let c = shell_colours(&many, false);
        assert_eq!(c.legend.len(), 10);
        assert_eq!(c.legend[9].name, "shell 10: 12 triangles");
        assert_eq!(c.of_face.iter().filter(|g| g.is_none()).count(), 24);
        assert_eq!(c.of_face[12 * 11], Some(0), "the largest, last in the file");
    }
}
