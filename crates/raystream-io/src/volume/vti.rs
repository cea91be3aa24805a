//! VTK XML image data (`.vti`): what ParaView and VTK save a volume as by default. The grid is
//! the `ImageData` element's: `WholeExtent` (index ranges), `Origin` (where index (0, 0, 0)
//! lies), `Spacing` and, since VTK 9, `Direction` (row-major, its columns the axes); the values
//! are the point data's active `Scalars` array (else its first), one component, in any
//! encoding VTK writes ([`crate::vtk_xml`]). One piece, as VTK's serial writer writes it.
//! Coordinates are read as LPS millimetres, as the legacy VTK reader reads them.

use std::path::Path;

use super::nifti::guess_unit;
use super::{
    Phase, Volume, VolumeError, VolumeFormat, check_geometry, is_orthonormal, unit_columns,
    voxel_count,
};
use crate::vtk_xml::{XmlFile, children, numbers_attribute, read_array, root};

/// Parses a `.vti` file's bytes (a 3-D volume: `phase`, if given, must be 1).
pub(crate) fn parse(
    bytes: &[u8],
    path: &Path,
    phase: Option<usize>,
) -> Result<Volume, VolumeError> {
    let mut warnings = Vec::new();
    let phase = Phase::pick(path, phase, 1, &mut warnings)?;
    let bad = |e: String| VolumeError::invalid(path, e);
    let file = XmlFile::split(bytes).map_err(bad)?;
    let doc =
        roxmltree::Document::parse(&file.text).map_err(|e| bad(format!("bad VTK XML: {e}")))?;
    let (root, layout) = root(&doc, &file, "ImageData").map_err(|e| {
        bad(if e.contains("\"PolyData\"") {
            format!("{e}: polygonal data is a mesh, not a volume")
        } else {
            e
        })
    })?;
    let image = children(root, "ImageData")
        .next()
        .ok_or_else(|| bad("the VTK file has no <ImageData>".into()))?;
    let pieces: Vec<_> = children(image, "Piece").collect();
    let [piece] = pieces[..] else {
        return Err(bad(format!(
            "the VTK image data has {} pieces: one is read (as VTK's serial writer writes it)",
            pieces.len()
        )));
    };
    let whole = numbers_attribute::<6>(image, "WholeExtent", None).map_err(bad)?;
    let extent = numbers_attribute::<6>(piece, "Extent", Some(whole)).map_err(bad)?;
    let origin0 = numbers_attribute::<3>(image, "Origin", Some([0.0; 3])).map_err(bad)?;
    let spacing = numbers_attribute::<3>(image, "Spacing", Some([1.0; 3])).map_err(bad)?;
    let d = numbers_attribute::<9>(
        image,
        "Direction",
        Some([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
    )
    .map_err(bad)?;
    let mut dims = [0usize; 3];
    for a in 0..3 {
        let (lo, hi) = (extent[2 * a], extent[2 * a + 1]);
        if lo.fract() != 0.0 || hi.fract() != 0.0 || hi < lo || hi - lo >= 1e9 {
            return Err(bad(format!(
                "VTK extent {lo} {hi} along axis {a} is no range of whole numbers"
            )));
        }
        dims[a] = (hi - lo) as usize + 1;
    }
    let n = voxel_count(path, dims)?;
    // Index (i, j, k) lies at Origin + Direction · (Spacing ⊙ (i, j, k)); the piece's first
    // voxel at its extent's low corner.
    let axes: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|c| d[3 * r + c] * spacing[c]));
    let origin: [f64; 3] = std::array::from_fn(|r| {
        origin0[r] + (0..3).map(|c| axes[r][c] * extent[2 * c]).sum::<f64>()
    });
    let (direction, spacing) = unit_columns(axes);
    check_geometry(path, dims, spacing, origin, &direction)?;
    if !is_orthonormal(&direction, 1e-4) {
        warnings.push("the voxel axes are not orthogonal".into());
    }

    let point_data = children(piece, "PointData").next();
    let arrays: Vec<_> = point_data
        .map(|p| children(p, "DataArray").collect())
        .unwrap_or_default();
    let active = point_data.and_then(|p| p.attribute("Scalars"));
    let array = active
        .and_then(|name| arrays.iter().find(|a| a.attribute("Name") == Some(name)))
        .or(arrays.first())
        .copied()
        .ok_or_else(|| {
            let cells = children(piece, "CellData")
                .next()
                .is_some_and(|c| children(c, "DataArray").next().is_some());
            bad(if cells {
                "the VTK image data holds cell data only: a volume's values are point data (one at each voxel centre)".into()
            } else {
                "the VTK image data holds no point data array".into()
            })
        })?;
    let components: usize = array
        .attribute("NumberOfComponents")
        .map_or(Some(1), |c| c.trim().parse().ok())
        .ok_or_else(|| bad("bad VTK NumberOfComponents".into()))?;
    if components != 1 {
        return Err(bad(format!(
            "the VTK array {:?} has {components} components: a volume is one value a voxel",
            array.attribute("Name").unwrap_or("")
        )));
    }
    let values = read_array(array, &layout, n).map_err(bad)?;
    let data = values.to_f32();
    let unit = guess_unit(&data, values.scalar);
    Ok(Volume {
        dims,
        spacing,
        origin,
        direction,
        data,
        unit,
        format: VolumeFormat::VtkXml,
        series: None,
        segments: Vec::new(),
        phase,
        warnings,
    })
}
