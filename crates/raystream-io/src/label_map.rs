//! A label volume (one byte a voxel) written as NIfTI-1 on another volume's grid, so that a
//! viewer (3D Slicer, ITK-SNAP) lays it over that volume voxel for voxel: the same dimensions
//! and spacing, and the index → patient transform as the sform (scanner coordinates, RAS as
//! NIfTI has them: LPS with x and y negated), with intent "label". Written through the `nifti`
//! crate.

use std::path::Path;

use nifti::{NiftiHeader, NiftiType, writer::WriterOptions};

use crate::volume::{Volume, VolumeError};

/// NIFTI_INTENT_LABEL: the values are labels, not measurements.
const INTENT_LABEL: i16 = 1002;
/// NIFTI_UNITS_MM.
const UNITS_MM: u8 = 2;
/// NIFTI_XFORM_SCANNER_ANAT.
const XFORM_SCANNER: i16 = 1;

/// Whether `path` names a file [`write_label_map`] writes: `.nii` or `.nii.gz`.
pub fn is_label_map_path(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name.ends_with(".nii") || name.ends_with(".nii.gz")
}

/// Writes `labels` (one a voxel of `like`, i fastest, as [`Volume::data`]) to `path` (`.nii`,
/// or `.nii.gz` compressed) on `like`'s grid, `description` in its header (at most 79 bytes
/// kept).
pub fn write_label_map(
    path: &Path,
    like: &Volume,
    labels: &[u8],
    description: &str,
) -> Result<(), VolumeError> {
    write_label_map_named(path, like, labels, description, &[])
}

/// [`write_label_map`], with each label of `table` named and coloured (sRGB) in a header
/// extension: the XML label table of Connectome Workbench's label volumes, as
/// TotalSegmentator writes its multi-label files (`--ml`, through nibabel, extension code 0),
/// which raystream, nibabel-based tools and Workbench read back. No extension for an empty
/// table.
pub fn write_label_map_named(
    path: &Path,
    like: &Volume,
    labels: &[u8],
    description: &str,
    table: &[(u8, &str, [u8; 3])],
) -> Result<(), VolumeError> {
    if !is_label_map_path(path) {
        return Err(VolumeError::invalid(
            path,
            "a label map is written as NIfTI: name it .nii or .nii.gz",
        ));
    }
    one_a_voxel(path, like, labels)?;
    let [nx, ny, nz] = like.dims;
    let m = like.index_to_world_affine();
    let (a, t) = (m.matrix3, m.translation);
    // LPS → RAS: x and y negated.
    let row = |r: usize, sign: f64| {
        [
            (sign * a.col(0)[r]) as f32,
            (sign * a.col(1)[r]) as f32,
            (sign * a.col(2)[r]) as f32,
            (sign * t[r]) as f32,
        ]
    };
    let mut descrip: Vec<u8> = description.bytes().take(79).collect();
    descrip.resize(80, 0);
    let header = NiftiHeader {
        pixdim: [
            1.0,
            like.spacing[0] as f32,
            like.spacing[1] as f32,
            like.spacing[2] as f32,
            1.0,
            1.0,
            1.0,
            1.0,
        ],
        xyzt_units: UNITS_MM,
        intent_code: INTENT_LABEL,
        descrip,
        qform_code: 0,
        sform_code: XFORM_SCANNER,
        srow_x: row(0, -1.0),
        srow_y: row(1, -1.0),
        srow_z: row(2, 1.0),
        ..NiftiHeader::default()
    };
    // The array is indexed [k][j][i] (i fastest in memory); the writer takes it [i][j][k]
    // and writes it transposed, i fastest, as NIfTI lays voxels out.
    let data = ndarray::Array3::from_shape_vec((nz, ny, nx), labels.to_vec())
        .map_err(|e| VolumeError::invalid(path, e.to_string()))?
        .reversed_axes();
    // The writer names its file itself, from the name's stem (`a.b.nii` would become `a.nii`,
    // `M.NII.GZ` an uncompressed `M.nii`): so it writes a name of its own beside the one asked
    // for, renamed to it once written.
    let gz = path.to_string_lossy().to_ascii_lowercase().ends_with(".gz");
    let own = path.with_file_name(format!(
        "raystream-labels-{}.{}",
        std::process::id(),
        if gz { "nii.gz" } else { "nii" }
    ));
    let mut options = WriterOptions::new(&own).reference_header(&header);
    if !table.is_empty() {
        let extension = nifti::Extension::from_str(0, &label_table_xml(table));
        options = options.with_extensions(nifti::ExtensionSequence::new(
            nifti::Extender::from([1, 0, 0, 0]),
            vec![extension],
        ));
    }
    let written = options
        .write_nifti_with_type(&data, NiftiType::Uint8)
        .map_err(|e| match e {
            nifti::NiftiError::Io(e) => VolumeError::io(path, e),
            e => VolumeError::invalid(path, format!("cannot write it: {e}")),
        })
        .and_then(|()| std::fs::rename(&own, path).map_err(|e| VolumeError::io(path, e)));
    if written.is_err() {
        std::fs::remove_file(&own).ok();
    }
    written
}

/// The XML of a label table (Workbench's `CaretExtension`, as TotalSegmentator writes it):
/// each label's key, colour (0 to 1) and name (CDATA, a `]]>` within it split across two).
fn label_table_xml(table: &[(u8, &str, [u8; 3])]) -> String {
    let rows: String = (table.iter())
        .map(|&(key, name, [r, g, b])| {
            let c = |x: u8| x as f64 / 255.0;
            let name = name.replace("]]>", "]]]]><![CDATA[>");
            format!(
                "<Label Key=\"{key}\" Red=\"{}\" Green=\"{}\" Blue=\"{}\" Alpha=\"1\"><![CDATA[{name}]]></Label>\n",
                c(r),
                c(g),
                c(b)
            )
        })
        .collect();
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<CaretExtension><VolumeInformation Index=\"0\"><LabelTable>\n{rows}</LabelTable><VolumeType><![CDATA[Label]]></VolumeType></VolumeInformation></CaretExtension>\n"
    )
}

/// That `labels` hold one label a voxel of `like`'s grid (an error naming `path` if not).
pub(crate) fn one_a_voxel(path: &Path, like: &Volume, labels: &[u8]) -> Result<(), VolumeError> {
    let [nx, ny, nz] = like.dims;
    if labels.len() != nx * ny * nz {
        return Err(VolumeError::invalid(
            path,
            format!("{} labels for a {nx}×{ny}×{nz} grid", labels.len()),
        ));
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::volume::{VolumeSelect, load_volume};

    /// An oblique, anisotropic 5×4×3 grid and labels 0, 1, 2 on it, for the writers' tests.
    pub(crate) fn oblique_labels() -> (Volume, Vec<u8>) {
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let like = Volume {
            origin: [-120.5, 33.25, 710.0],
            spacing: [0.7, 0.8, 1.5],
            direction: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            ..Volume::hounsfield([5, 4, 3], [1.0; 3], vec![0.0; 60])
        };
        (like, (0..60).map(|k| (k * 7 % 3) as u8).collect())
    }

    /// Written on an oblique, anisotropic grid and read back: the same grid, the same labels.
    #[test]
    fn a_label_map_reads_back_on_its_grid() {
        let scratch = crate::tests::scratch_dir("label-test");
        let dir = scratch.path();
        let (like, labels) = oblique_labels();
        // Written to the name asked for, compressed as it says, whatever its case and dots.
        for name in ["m.nii", "m.nii.gz", "M.NII.GZ", "a.b.nii", "a.b.nii.gz"] {
            let path = dir.join(name);
            write_label_map(&path, &like, &labels, "raystream test").unwrap();
            let bytes = std::fs::read(&path).unwrap();
            let gz = name.to_ascii_lowercase().ends_with(".gz");
            assert_eq!(bytes[..2] == [0x1f, 0x8b], gz, "{name}");
            let v = load_volume(&path, &VolumeSelect::default()).unwrap();
            assert_eq!(v.dims, like.dims, "{name}");
            for i in 0..3 {
                assert!(
                    (v.spacing[i] - like.spacing[i]).abs() < 1e-5,
                    "{name}: {v:?}"
                );
                assert!((v.origin[i] - like.origin[i]).abs() < 1e-4, "{name}: {v:?}");
                for j in 0..3 {
                    assert!(
                        (v.direction[i][j] - like.direction[i][j]).abs() < 1e-5,
                        "{name}: {v:?}"
                    );
                }
            }
            let back: Vec<u8> = v.data.iter().map(|&x| x as u8).collect();
            assert_eq!(back, labels, "{name}");
        }
        // Nothing else was written beside them.
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            ["M.NII.GZ", "a.b.nii", "a.b.nii.gz", "m.nii", "m.nii.gz"]
        );
        let bad = dir.join("m.nrrd");
        let e = write_label_map(&bad, &like, &labels, "").unwrap_err();
        assert!(e.to_string().contains("m.nrrd"), "{e}");
        let e = write_label_map(&dir.join("n.nii"), &like, &labels[1..], "").unwrap_err();
        assert!(e.to_string().contains("59 labels"), "{e}");
    }

    /// Named labels read back with their names and colours (plain and gzipped), a name
    /// holding XML's own characters and CDATA's end among them; the labels unchanged.
    #[test]
    fn a_label_table_reads_back() {
        let scratch = crate::tests::scratch_dir("label-table-test");
        let (like, labels) = oblique_labels();
        let table = [
            (1, "lung_upper_lobe_left", [200, 100, 0]),
            (2, "a <b> & \"c\" ]]> d", [0, 255, 7]),
        ];
        for name in ["t.nii", "t.nii.gz"] {
            let path = scratch.path().join(name);
            write_label_map_named(&path, &like, &labels, "raystream test", &table).unwrap();
            let v = load_volume(&path, &VolumeSelect::default()).unwrap();
            let back: Vec<u8> = v.data.iter().map(|&x| x as u8).collect();
            assert_eq!(back, labels, "{name}");
            let got: Vec<(u16, &str, Option<[u8; 3]>)> = (v.segments.iter())
                .map(|k| (k.number, k.label.as_str(), k.colour))
                .collect();
            let want: Vec<(u16, &str, Option<[u8; 3]>)> = (table.iter())
                .map(|&(l, n, c)| (l as u16, n, Some(c)))
                .collect();
            assert_eq!(got, want, "{name}");
            assert!(v.warnings.is_empty(), "{name}: {:?}", v.warnings);
        }
    }
}
