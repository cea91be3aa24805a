//! Volume readers on the real CT data in ../shared/data/volumes (expected geometry from
//! SimpleITK 2.5 reading the same files: `scripts/sitk-geometry.py`), on small synthetic files
//! for the formats the data set lacks, and under truncation and bit flips.

use std::path::{Path, PathBuf};

use super::*;

fn shared(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/volumes")
        .join(rel)
}

struct Expected {
    path: &'static str,
    dims: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    direction: [f64; 9],
    range: (f32, f32),
}

const TS_DIR: &str = "dicom/ct_slice_transfer_syntaxes";
const LE_EXPLICIT: &str =
    "dicom/ct_slice_transfer_syntaxes/ct_1.2.840.10008.1.2.1_LittleEndianExplicit.dcm";

/// SimpleITK 2.5.7 `ReadImage` / `ImageSeriesReader` on the same files.
const EXPECTED: &[Expected] = &[
    Expected {
        path: "nifti/abdomen_pelvis_ct_totalseg.nii.gz",
        dims: [122, 101, 112],
        spacing: [3.0, 3.0, 3.0],
        origin: [177.95632934570312, -11.319000244140625, 94.3017578125],
        direction: [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
        range: (-1207.0, 3382.0),
    },
    Expected {
        path: "nifti/chest_ct_stents_totalseg.nii.gz",
        dims: [120, 126, 164],
        spacing: [1.5, 1.5, 1.5],
        origin: [-71.658203125, -255.658203125, 540.2000122070312],
        direction: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        range: (-1078.0, 3343.0),
    },
    Expected {
        path: "nifti/scivis_bonsai.nii.gz",
        dims: [256, 256, 256],
        spacing: [1.0, 1.0, 1.0],
        origin: [127.0, 127.0, -128.0],
        direction: [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
        range: (0.0, 255.0),
    },
    Expected {
        path: "nifti/scivis_engine.nii.gz",
        dims: [256, 256, 128],
        spacing: [1.0, 1.0, 1.0],
        origin: [127.0, 127.0, -64.0],
        direction: [-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0],
        range: (0.0, 255.0),
    },
    Expected {
        path: "dicom/abdomen_ct_j2k_totalseg",
        dims: [512, 512, 20],
        spacing: [0.9765625, 0.9765625, 2.0],
        origin: [-249.51171875, -437.51171875, -804.5],
        direction: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        range: (-1024.0, 1839.0),
    },
    Expected {
        path: LE_EXPLICIT,
        dims: [512, 512, 1],
        spacing: [0.675781, 0.675781, 6.5],
        origin: [-161.399994, -148.800003, 4.7],
        direction: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        range: (-3024.0, 1378.0),
    },
];

fn assert_geometry(v: &Volume, e: &Expected) {
    assert_eq!(v.dims, e.dims, "{}", e.path);
    for a in 0..3 {
        assert!(
            (v.spacing[a] - e.spacing[a]).abs() < 1e-3,
            "{} spacing {:?}",
            e.path,
            v.spacing
        );
        assert!(
            (v.origin[a] - e.origin[a]).abs() < 1e-3,
            "{} origin {:?}",
            e.path,
            v.origin
        );
    }
    let d = v.direction.concat();
    for i in 0..9 {
        assert!(
            (d[i] - e.direction[i]).abs() < 1e-6,
            "{} direction {d:?}",
            e.path
        );
    }
}

#[test]
fn geometry_and_values_match_simpleitk() {
    for e in EXPECTED {
        let v =
            load_volume(&shared(e.path), &Default::default()).unwrap_or_else(|err| panic!("{err}"));
        assert_geometry(&v, e);
        assert_eq!(v.value_range(), Some(e.range), "{}", e.path);
    }
}

#[test]
fn units_follow_the_data() {
    let ct = load_volume(&shared(EXPECTED[0].path), &Default::default()).unwrap();
    assert_eq!(ct.unit, ValueUnit::Hounsfield);
    let engine = load_volume(&shared("nifti/scivis_engine.nii.gz"), &Default::default()).unwrap();
    assert_eq!(engine.unit, ValueUnit::Unknown);
    let series = load_volume(
        &shared("dicom/abdomen_ct_j2k_totalseg"),
        &Default::default(),
    )
    .unwrap();
    assert_eq!(series.unit, ValueUnit::Hounsfield);
    let info = series.series.unwrap();
    assert_eq!(info.count, 20);
    assert_eq!(info.transfer_syntax, "1.2.840.10008.1.2.4.90");
}

#[test]
fn index_and_world_transforms_invert_each_other() {
    let v = load_volume(
        &shared("nifti/abdomen_pelvis_ct_totalseg.nii.gz"),
        &Default::default(),
    )
    .unwrap();
    let p = DVec3::new(10.0, 20.5, 30.25);
    let w = v.index_to_world(p);
    // RAS-stored file: i runs to the patient's right (−x in LPS), j to anterior (−y).
    assert!(
        (w - DVec3::new(
            177.95632934570312 - 30.0,
            -11.319000244140625 - 61.5,
            94.3017578125 + 90.75
        ))
        .length()
            < 1e-9
    );
    assert!((v.world_to_index(w) - p).length() < 1e-9);
    assert!((v.index_to_world_affine().transform_point3(p) - w).length() < 1e-9);
}

/// Copies the files of `src` into `dst` (made with its parents).
fn copy_folder(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
    }
}

/// `got` lies on `want`'s grid with its values.
fn assert_same_grid_and_values(got: &Volume, want: &Volume) {
    assert_eq!(
        (got.dims, got.origin, got.spacing),
        (want.dims, want.origin, want.spacing)
    );
    assert_eq!(got.data, want.data);
}

/// A folder that holds no file of its own (a CD's root: a DICOMDIR beside DICOM/ST000/SE000…)
/// is read through the folders below it, as viewers import such trees: the largest series, the
/// same volume as from its own folder, the others listed, a warning saying where the files
/// were. A folder with files of its own is read alone, as before; the search stops
/// `MAX_TREE_DEPTH` folders down, and an empty tree is an error that says it looked.
#[test]
fn a_cds_folder_tree_is_read_through_its_folders() {
    let series = shared("dicom/abdomen_ct_j2k_totalseg");
    let scratch = crate::tests::scratch_dir("cd");
    let cd = scratch.path().join("cd");
    copy_folder(&series, &cd.join("DICOM/ST000/SE000"));
    let other = cd.join("DICOM/ST000/SE001");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::copy(shared(LE_EXPLICIT), other.join("IM0000")).unwrap();
    std::fs::write(cd.join("DICOMDIR"), b"not read").unwrap();
    let want = load_volume(&series, &Default::default()).unwrap();
    let got = load_volume(&cd, &Default::default()).unwrap();
    assert_same_grid_and_values(&got, &want);
    assert!(
        got.warnings.iter().any(
            |w| w == "it holds no file of its own: read the 21 files in the 2 folders below it"
        ),
        "{:?}",
        got.warnings
    );
    let listed = list_dicom_series(&cd).unwrap();
    assert_eq!(listed.iter().map(|s| s.1).collect::<Vec<_>>(), [20, 1]);

    // A folder with a file of its own: that file alone.
    let own = scratch.path().join("own");
    copy_folder(&series, &own.join("sub"));
    std::fs::copy(shared(LE_EXPLICIT), own.join("slice.dcm")).unwrap();
    assert_eq!(
        load_volume(&own, &Default::default()).unwrap().dims,
        [512, 512, 1]
    );

    // Beyond the search's depth: not found.
    let mut deep = scratch.path().join("deep");
    for level in 0..=dicom::MAX_TREE_DEPTH {
        deep = deep.join(format!("level{level}"));
    }
    std::fs::create_dir_all(&deep).unwrap();
    std::fs::copy(shared(LE_EXPLICIT), deep.join("IM0000")).unwrap();
    let e = load_volume(&scratch.path().join("deep"), &Default::default()).unwrap_err();
    assert!(
        e.to_string()
            .ends_with("the folder is empty (and no folder below it holds a file)"),
        "{e}"
    );
}

/// A ZIP of a study, as a PACS or a web viewer hands it out, reads as its series' folder: its
/// folders flattened, DICOMDIR and macOS's `__MACOSX` left out, another file skipped with a
/// warning naming it inside the archive; a DICOM file without an extension is a volume too;
/// an archive that unpacks beyond the limit, and a file that is no ZIP, are errors naming it.
#[test]
fn a_zip_of_a_study_reads_as_its_folder() {
    use std::io::Write;
    let series = shared("dicom/abdomen_ct_j2k_totalseg");
    let scratch = crate::tests::scratch_dir("zip");
    let zip_path = scratch.path().join("Study.ZIP");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&zip_path).unwrap());
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let deflated = zip::write::SimpleFileOptions::default();
    let mut names: Vec<_> = std::fs::read_dir(&series)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    for (i, f) in names.iter().enumerate() {
        let name = format!("PATIENT/DICOM/ST000/SE000/IM{i:04}");
        zip.start_file(name, if i % 2 == 0 { stored } else { deflated })
            .unwrap();
        zip.write_all(&std::fs::read(f).unwrap()).unwrap();
    }
    for (name, bytes) in [
        ("PATIENT/DICOMDIR", &b"not read"[..]),
        ("__MACOSX/PATIENT/._IM0000", b"resource fork"),
        ("PATIENT/README.TXT", b"a note"),
    ] {
        zip.start_file(name, deflated).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();

    assert!(is_volume_path(&zip_path));
    let want = load_volume(&series, &Default::default()).unwrap();
    let got = load_volume(&zip_path, &Default::default()).unwrap();
    assert_same_grid_and_values(&got, &want);
    let skipped: Vec<&String> = got
        .warnings
        .iter()
        .filter(|w| w.starts_with("skipped"))
        .collect();
    assert_eq!(skipped.len(), 1, "{:?}", got.warnings);
    assert!(
        skipped[0].contains("Study.ZIP/PATIENT/README.TXT"),
        "{skipped:?}"
    );
    assert_eq!(list_dicom_series(&zip_path).unwrap()[0].1, names.len());

    // A DICOM file as a CD names it, without an extension.
    let bare = scratch.path().join("IM0000");
    std::fs::copy(&names[0], &bare).unwrap();
    assert!(is_volume_path(&bare));
    assert_eq!(
        load_volume(&bare, &Default::default()).unwrap().dims,
        [512, 512, 1]
    );

    let e = dicom::read_zip_within(&zip_path, 1 << 20)
        .map(|_| ())
        .unwrap_err();
    assert!(
        e.to_string().contains("unpack to more than 1048576 bytes"),
        "{e}"
    );
    let junk = scratch.path().join("junk.zip");
    std::fs::write(&junk, b"PK but no archive").unwrap();
    let e = load_volume(&junk, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("junk.zip") && e.contains("not a readable ZIP archive"),
        "{e}"
    );
}

/// A lone slice becomes a slab a spacing thick: two layers of its values half a spacing
/// either side of it along its axis (whatever the grid's direction), the rest of the geometry
/// unchanged; a volume of several slices is left as it is.
#[test]
fn a_lone_slice_becomes_a_slab_of_its_spacing() {
    let one = load_volume(&shared(LE_EXPLICIT), &Default::default()).unwrap();
    assert_eq!(one.dims, [512, 512, 1]);
    // An oblique lone slice along the first axis, and a single voxel, beside the real one.
    let mut side = Volume::hounsfield(
        [1, 3, 4],
        [2.5, 0.7, 1.3],
        (0..12).map(|v| v as f32).collect(),
    );
    let (c, s) = (0.6f64, 0.8f64);
    side.direction = [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]];
    side.origin = [10.0, -20.0, 30.0];
    let dot = Volume::hounsfield([1, 1, 1], [1.0, 2.0, 3.0], vec![700.0]);
    for v in [&one, &side, &dot] {
        let slab = v.slab_of_lone_slices().expect("a lone slice");
        assert_eq!(slab.dims, v.dims.map(|n| n.max(2)));
        assert_eq!((slab.spacing, slab.direction), (v.spacing, v.direction));
        assert_eq!(slab.data.len(), slab.voxel_count());
        // Each voxel of the slab: the slice's value, half a spacing off the slice along each
        // doubled axis.
        let [nx, ny, nz] = slab.dims;
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let at = [i, j, k];
                    let src: [usize; 3] =
                        std::array::from_fn(|a| if v.dims[a] == 1 { 0 } else { at[a] });
                    let off: [f64; 3] = std::array::from_fn(|a| {
                        if v.dims[a] == 1 {
                            at[a] as f64 - 0.5
                        } else {
                            0.0
                        }
                    });
                    let p = DVec3::from(src.map(|x| x as f64)) + DVec3::from(off);
                    let want = v.index_to_world(p);
                    let got = slab.index_to_world(DVec3::from(at.map(|x| x as f64)));
                    assert!((got - want).length() < 1e-9, "{at:?}: {got} vs {want}");
                    assert_eq!(slab.at(i, j, k), v.at(src[0], src[1], src[2]));
                }
            }
        }
        // The slab's middle plane is the slice's.
        let mid = DVec3::from(v.dims.map(|n| if n == 1 { 0.5 } else { 0.0 }));
        assert!((slab.index_to_world(mid) - v.index_to_world(DVec3::ZERO)).length() < 1e-9);
        // And the slab gives back its slice: the same grid, to rounding, and values.
        let back = slab.lone_slice_of_slab().expect("a slab");
        assert_eq!((back.dims, back.spacing), (v.dims, v.spacing));
        assert!((DVec3::from(back.origin) - DVec3::from(v.origin)).length() < 1e-9);
        assert_eq!(back.data, v.data);
    }
    // Only the axes whose two layers are equal are collapsed; layers that differ are no slab.
    let data = [0.0, 1.0, 2.0, 3.0].repeat(2);
    let two = Volume::hounsfield([2, 2, 2], [1.0; 3], data);
    let back = two
        .lone_slice_of_slab()
        .expect("the third axis's layers are equal");
    assert_eq!((back.dims, &back.data[..]), ([2, 2, 1], &two.data[..4]));
    let differ = Volume::hounsfield([2, 2, 2], [1.0; 3], (0..8).map(|v| v as f32).collect());
    assert!(differ.lone_slice_of_slab().is_none());
    let ct = load_volume(
        &shared("nifti/abdomen_pelvis_ct_totalseg.nii.gz"),
        &Default::default(),
    )
    .unwrap();
    assert!(ct.slab_of_lone_slices().is_none());
}

/// Resampling keeps the box of voxel centres and reproduces a field trilinear interpolation
/// is exact for (linear in each axis), at the new grid's world positions.
#[test]
fn resample_keeps_geometry_and_linear_fields() {
    let src = load_volume(
        &shared("nifti/abdomen_pelvis_ct_totalseg.nii.gz"),
        &Default::default(),
    )
    .unwrap();
    let [nx, ny, nz] = src.dims;
    let f = |p: DVec3| (2.0 * p.x + 3.0 * p.y - 1.5 * p.z + 0.01 * p.x * p.y * p.z + 5.0) as f32;
    let mut lin = src.resample(src.dims);
    assert_eq!(
        lin.data, src.data,
        "resampling to the same grid changes nothing"
    );
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                lin.data[i + nx * (j + ny * k)] = f(DVec3::new(i as f64, j as f64, k as f64));
            }
        }
    }
    let dims = [61, 47, 83];
    let r = lin.resample(dims);
    assert_eq!(r.dims, dims);
    assert_eq!(r.origin, src.origin);
    assert_eq!(r.direction, src.direction);
    let last = |v: &Volume| v.index_to_world(DVec3::from(v.dims.map(|n| (n - 1) as f64)));
    assert!(
        (last(&r) - last(&src)).length() < 1e-9,
        "the far corner moved"
    );
    for (i, j, k) in [(0, 0, 0), (60, 46, 82), (17, 33, 5), (31, 2, 77)] {
        let world = r.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let want = f(src.world_to_index(world));
        let got = r.at(i, j, k);
        assert!(
            (got - want).abs() <= 1e-3 * want.abs().max(1.0),
            "({i}, {j}, {k}): {got} vs {want}"
        );
    }
}

#[test]
fn every_decodable_transfer_syntax_gives_the_uncompressed_hu() {
    let reference = load_volume(&shared(LE_EXPLICIT), &Default::default()).unwrap();
    let max_diff = |v: &Volume| {
        v.data
            .iter()
            .zip(&reference.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max)
    };
    // Lossless: identical values.
    for ts in [
        "1.2", "1.2.1.99", "1.2.2", "1.2.5", "1.2.4.57", "1.2.4.70", "1.2.4.80", "1.2.4.90",
    ] {
        let v = load_ts(ts).unwrap_or_else(|e| panic!("{ts}: {e}"));
        assert_geometry(&v, &EXPECTED[5]);
        assert_eq!(max_diff(&v), 0.0, "transfer syntax 1.2.840.10008.{ts}");
    }
    // Near-lossless JPEG-LS (NEAR = 1): within 1 HU, and the very values CharLS decodes
    // (through GDCM in SimpleITK 2.x: 181945 pixels differ from the lossless slice, and these
    // sums; a decoder off by one anywhere would change them).
    let v = load_ts("1.2.4.81").unwrap();
    assert_geometry(&v, &EXPECTED[5]);
    assert_eq!(max_diff(&v), 1.0);
    let hu: Vec<i64> = v.data.iter().map(|&x| x as i64).collect();
    assert!(v.data.iter().zip(&hu).all(|(&x, &h)| x == h as f32));
    let differ = hu
        .iter()
        .zip(&reference.data)
        .filter(|&(&a, &b)| a as f32 != b)
        .count();
    assert_eq!(differ, 181_945);
    assert_eq!(hu.iter().sum::<i64>(), -248_761_732);
    let weighted: i64 = hu
        .iter()
        .enumerate()
        .map(|(i, &h)| (i as i64 % 1009) * h)
        .sum();
    assert_eq!(weighted, -124_640_169_588);
    // 12-bit lossy JPEG, with its own rescale (slope 2.0002442, intercept -4047): within 36 HU
    // of the lossless slice, and the very stored values libjpeg decodes (through GDCM in
    // SimpleITK 2.x: these sums of the stored values).
    let v = load_ts("1.2.4.51").unwrap();
    assert_geometry(&v, &EXPECTED[5]);
    assert!(max_diff(&v) < 36.0, "{}", max_diff(&v));
    let stored: Vec<i64> = v
        .data
        .iter()
        .map(|&h| ((h as f64 + 4047.0) / 2.0002442).round() as i64)
        .collect();
    assert_eq!(stored.iter().sum::<i64>(), 405_866_194);
    let weighted: i64 = stored
        .iter()
        .enumerate()
        .map(|(i, &r)| (i as i64 % 1009) * r)
        .sum();
    assert_eq!(weighted, 204_763_478_473);
    // Lossy JPEG 2000: within 5 HU (pydicom + pylibjpeg give the same bound).
    let v = load_ts("1.2.4.91").unwrap();
    assert!(max_diff(&v) <= 5.0, "{}", max_diff(&v));
    // Lossy 8-bit baseline JPEG with its own rescale: close on average only.
    let v = load_ts("1.2.4.50").unwrap();
    let mean: f64 = v
        .data
        .iter()
        .zip(&reference.data)
        .map(|(a, b)| (a - b).abs() as f64)
        .sum::<f64>()
        / v.data.len() as f64;
    assert!(mean < 20.0, "mean |ΔHU| {mean}");
}

#[test]
fn undecodable_transfer_syntaxes_are_clear_errors() {
    for (ts, says) in [("1.2.4.53", "retired JPEG"), ("1.2.4.55", "retired JPEG")] {
        let e = load_ts(ts).unwrap_err().to_string();
        assert!(
            e.contains(&format!("1.2.840.10008.{ts}")) && e.contains(says),
            "{e}"
        );
    }
}

/// A JPEG 2000 slice whose codestream declares a wider image than its header (9728 columns
/// for 512), or a second component: a clear error naming the file and both figures, where
/// dicom-pixeldata's decoder wrote the decoded samples past its buffer (a panic, found by
/// scripts/fuzz-inputs.py). The slice unchanged still decodes.
#[test]
fn jpeg2000_streams_that_contradict_the_header_are_refused() {
    let path = shared(TS_DIR).join("ct_1.2.840.10008.1.2.4.90_JPEG2000LosslessOnly.dcm");
    let bytes = std::fs::read(&path).unwrap();
    let soc = bytes
        .windows(4)
        .position(|w| w == [0xFF, 0x4F, 0xFF, 0x51])
        .unwrap();
    let scratch = crate::tests::scratch_dir("j2k");
    let dir = scratch.path();
    let patched = |at: usize, value: &[u8], name: &str| {
        let mut b = bytes.clone();
        b[soc + at..soc + at + value.len()].copy_from_slice(value);
        let p = dir.join(name);
        std::fs::write(&p, b).unwrap();
        p
    };
    // Xsiz (bytes 8-11 of the stream), then Csiz (bytes 40-41).
    let wide = patched(8, &9728u32.to_be_bytes(), "wide.dcm");
    let e = load_volume(&wide, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("wide.dcm")
            && e.contains("the codestream holds a 9728×512 image, the header says 512×512"),
        "{e}"
    );
    let two = patched(40, &2u16.to_be_bytes(), "two.dcm");
    let e = load_volume(&two, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("two.dcm") && e.contains("holds 2 components, the header says 1"),
        "{e}"
    );
    let v = load_volume(&path, &Default::default()).unwrap();
    assert_eq!(v.dims, [512, 512, 1]);
}

fn load_ts(ts: &str) -> Result<Volume, VolumeError> {
    let dir = shared(TS_DIR);
    let prefix = format!("ct_1.2.840.10008.{ts}_");
    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_str()
                .unwrap()
                .starts_with(&prefix)
        })
        .unwrap();
    load_volume(&file, &Default::default())
}

/// The GE head CT (../shared: gantry tilted 18.5°, 4 mm slices through the posterior fossa
/// then 7 mm ones, 28 files) against its own files read one by one: the grid's third axis is
/// the table's (z), each acquired slice lies in the grid where its file puts it, every grid
/// slice is the linear interpolation of the two acquired slices about it, every voxel is where
/// its pixel was imaged, and the landmark the issue names, the box of the skull (all ≥ 300 HU),
/// is the acquired pixels' box within 1 mm (46 mm off when stacked along the normal instead).
#[test]
fn a_tilted_unevenly_spaced_series_is_sheared_and_interpolated() {
    let dir = shared("dicom/head_ct_gantry_tilt_ge");
    let v = load_volume(&dir, &Default::default()).unwrap();
    let w = v.warnings.join("\n");
    assert!(
        w.contains("gantry tilt of 18.5°")
            && w.contains("uneven slice spacing, 1.14 to 7.38 mm")
            && w.contains("resampled to"),
        "{w}"
    );
    let mut files: Vec<Volume> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| load_volume(&e.unwrap().path(), &Default::default()).unwrap())
        .collect();
    files.sort_by(|a, b| a.origin[2].total_cmp(&b.origin[2]));
    assert_eq!(files.len(), 28);
    let (c, s) = (18.5f64.to_radians().cos(), 18.5f64.to_radians().sin());
    let col = |m: &[[f64; 3]; 3], a: usize| DVec3::new(m[0][a], m[1][a], m[2][a]);
    // Rows along x, columns tilted (ImageOrientationPatient), the third axis along the table.
    assert!((col(&v.direction, 0) - DVec3::X).length() < 1e-6);
    assert!((col(&v.direction, 1) - col(&files[0].direction, 1)).length() < 1e-9);
    assert!((col(&v.direction, 1) - DVec3::new(0.0, c, -s)).length() < 1e-3);
    assert!((col(&v.direction, 2) - DVec3::Z).length() < 1e-9);
    assert_eq!(v.origin, files[0].origin);
    assert_eq!(&v.spacing[..2], &files[0].spacing[..2]);
    assert_eq!(&v.dims[..2], &files[0].dims[..2]);
    // Acquired slice k sits at height t[k] along the table; the grid spans first to last at
    // a spacing no coarser than the smallest gap.
    let t: Vec<f64> = files
        .iter()
        .map(|f| f.origin[2] - files[0].origin[2])
        .collect();
    let h = v.spacing[2];
    assert!((h * (v.dims[2] - 1) as f64 - t[27]).abs() < 1e-6);
    let smallest = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    assert!(h <= smallest && h > 0.9 * smallest, "{h} vs {smallest}");
    for (f, tk) in files.iter().zip(&t) {
        let idx = v.world_to_index(DVec3::from(f.origin));
        assert!(
            (idx - DVec3::new(0.0, 0.0, tk / h)).length() < 1e-6,
            "{idx}"
        );
    }
    let per = v.dims[0] * v.dims[1];
    let last = v.dims[2] - 1;
    // The landmark: the box of everything at or above 300 HU (skull and head holder), in LPS,
    // from the acquired pixels where they were imaged and from the grid's voxels.
    let bone_box = |vols: &[&Volume]| {
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for v in vols {
            for k in 0..v.dims[2] {
                for j in 0..v.dims[1] {
                    for i in 0..v.dims[0] {
                        if v.at(i, j, k) >= 300.0 {
                            let p = v.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
                            (lo, hi) = (lo.min(p), hi.max(p));
                        }
                    }
                }
            }
        }
        (lo, hi)
    };
    let acquired = bone_box(&files.iter().collect::<Vec<_>>());
    let grid = bone_box(&[&v]);
    let off = |a: (DVec3, DVec3), b: (DVec3, DVec3)| (a.0 - b.0).abs().max((a.1 - b.1).abs());
    assert!(
        off(grid, acquired).max_element() < 1.0,
        "{grid:?} vs {acquired:?}"
    );
    // Read as if stacked along the normal (as SimpleITK's series reader does), the box is off
    // by centimetres: the landmark tells the geometries apart.
    let mut naive = v.clone();
    for (r, n) in naive.direction.iter_mut().zip([0.0, s, c]) {
        r[2] = n;
    }
    naive.spacing[2] = h * c;
    let wrong = off(bone_box(&[&naive]), acquired).max_element();
    assert!(wrong > 20.0, "{wrong} mm");
    for k in [0, 1, 7, 40, 55, 56, 90, last - 1, last] {
        let at = k as f64 * h;
        let a = t.iter().rposition(|&x| x <= at + 1e-9).unwrap().min(26);
        let wgt = ((at - t[a]) / (t[a + 1] - t[a])).clamp(0.0, 1.0);
        let (lo, hi) = (&files[a], &files[a + 1]);
        let grid = &v.data[k * per..][..per];
        for (p, g) in grid.iter().enumerate() {
            let want = lo.data[p] as f64 + (hi.data[p] as f64 - lo.data[p] as f64) * wgt;
            assert!(
                (*g as f64 - want).abs() < 1e-3,
                "slice {k}, pixel {p}: {g} vs {want}"
            );
        }
        // Each voxel lies between its two pixels, on the line the table moved them along.
        for (i, j) in [(0, 0), (511, 0), (0, 511), (511, 511), (200, 300)] {
            let ij = |z: f64| DVec3::new(i as f64, j as f64, z);
            let want = lo.index_to_world(ij(0.0))
                + (hi.index_to_world(ij(0.0)) - lo.index_to_world(ij(0.0))) * wgt;
            assert!(
                (v.index_to_world(ij(k as f64)) - want).length() < 1e-6,
                "slice {k}, ({i}, {j})"
            );
        }
    }
}

/// A stack's geometry from synthetic positions: even stacks stay as they are, a tilted one
/// follows its table, an uneven one is resampled (missing slices named), and positions that
/// are no stack are refused.
#[test]
fn stacks_of_slices() {
    let name = |k: usize| format!("s{k}.dcm");
    let z = [0.0, 0.0, 1.0];
    let at = |gaps: &[f64]| -> Vec<[f64; 3]> {
        let mut p = vec![[10.0, -20.0, 30.0]];
        for g in gaps {
            let l = *p.last().unwrap();
            p.push([l[0], l[1], l[2] + g]);
        }
        p
    };
    let stack = |p: &[[f64; 3]], normal: [f64; 3], skipped: bool| {
        dicom::Stack::new(Path::new("ser"), p, normal, 0.5, 3.0, skipped, name)
    };
    // Even, along the normal: the slices themselves.
    let s = stack(&at(&[2.5; 6]), z, false).unwrap();
    assert_eq!((s.count, s.resampled, s.axis), (7, false, z));
    assert!((s.spacing - 2.5).abs() < 1e-12 && s.warnings.is_empty());
    // One slice: the header's spacing.
    let s = stack(&at(&[]), z, false).unwrap();
    assert_eq!((s.count, s.spacing), (1, 3.0));
    // Tilted 18.5° about x, even steps of 4.22 mm along the table (z).
    let (c, sn) = (18.5f64.to_radians().cos(), 18.5f64.to_radians().sin());
    let tilted = [0.0, sn, c];
    let s = stack(&at(&[4.22; 9]), tilted, false).unwrap();
    assert_eq!((s.count, s.resampled), (10, false));
    assert!((DVec3::from(s.axis) - DVec3::Z).length() < 1e-12);
    assert!((s.spacing - 4.22).abs() < 1e-9);
    assert!(
        s.warnings[0].contains("gantry tilt of 18.5°"),
        "{:?}",
        s.warnings
    );
    // Uneven: resampled at the smallest gap; a field linear along the stack stays linear.
    let p = at(&[2.0, 2.0, 2.0, 3.0, 5.0, 5.0]);
    let s = stack(&p, z, false).unwrap();
    assert!(s.resampled && s.count == 11 && (s.spacing - 1.9).abs() < 1e-12);
    assert!(
        s.warnings[0].contains("2.00 to 5.00 mm (the widest between s4.dcm and s5.dcm)")
            && s.warnings[0].contains("resampled to 11 slices 1.900 mm apart")
            && !s.warnings[0].contains("missing"),
        "{:?}",
        s.warnings
    );
    let slices: Vec<Vec<f32>> =
        s.at.iter()
            .map(|t| vec![*t as f32 * 3.0 - 7.0, 1.5])
            .collect();
    let grid = s.regular(&slices);
    for k in 0..s.count {
        let want = (k as f64 * s.spacing * 3.0 - 7.0) as f32;
        assert!(
            (grid[2 * k] - want).abs() < 1e-4 && grid[2 * k + 1] == 1.5,
            "{k}"
        );
    }
    // An isolated gap of twice the spacing about it: a missing slice, named.
    let s = stack(&at(&[2.0, 2.0, 4.0, 2.0, 2.0]), z, false).unwrap();
    assert!(
        s.warnings[0].contains(
            "the gap between s2.dcm and s3.dcm is 2× the spacing about it: 1 missing slice?"
        ),
        "{:?}",
        s.warnings
    );
    // The same with an unreadable file in the folder: refused (the file is the gap).
    let e = stack(&at(&[2.0, 2.0, 4.0, 2.0, 2.0]), z, true)
        .err()
        .unwrap();
    assert!(
        e.to_string()
            .contains("uneven slice spacing (2.000 to 4.000 mm)"),
        "{e}"
    );
    // A close pair among wide gaps does not blow the grid up: no finer than a quarter of the
    // median gap.
    let s = stack(&at(&[8.0, 8.0, 0.1, 8.0, 8.0]), z, false).unwrap();
    assert!(
        (s.spacing - 32.1 / 17.0).abs() < 1e-12 && s.count == 18,
        "{} {}",
        s.spacing,
        s.count
    );
    // Not a stack: a slice off the line, two at one place, positions within the plane.
    let mut p = at(&[2.0; 4]);
    p[2][0] += 0.2;
    let e = stack(&p, z, false).err().unwrap().to_string();
    assert!(e.contains("s2.dcm is 0.200 mm off the line"), "{e}");
    let e = stack(&at(&[2.0, 0.0, 2.0]), z, false)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("two slices at the same position (s1.dcm and s2.dcm)"),
        "{e}"
    );
    let e = stack(&at(&[2.0; 3]), [0.0, 0.8, 0.6], false)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("53.1° to the slice normal"), "{e}");
}

#[test]
fn unknown_series_lists_the_ones_there() {
    let e = load_volume(
        &shared("dicom/abdomen_ct_j2k_totalseg"),
        &VolumeSelect::series(Some("1.2.3")),
    )
    .unwrap_err()
    .to_string();
    // These files carry no SeriesInstanceUID (SimpleITK's GDCM finds the same empty ID).
    assert!(
        e.contains("no series with UID 1.2.3")
            && e.contains("(no SeriesInstanceUID) (20 slices, \"CT Body 3.0\")"),
        "{e}"
    );
}

/// A series with a slice that cannot be read: the gap it leaves is refused, and the error names
/// the file that was skipped (the cause), not only the gap.
#[test]
fn a_gap_left_by_an_unreadable_slice_names_the_file() {
    let src = shared("dicom/abdomen_ct_j2k_totalseg");
    let scratch = crate::tests::scratch_dir("gap");
    let dir = scratch.path();
    let mut names: Vec<_> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    for n in &names {
        std::fs::copy(src.join(n), dir.join(n)).unwrap();
    }
    // Cut the slice in the middle of the stack (by position, not by name) to 3000 bytes.
    assert_eq!(
        load_volume(dir, &Default::default()).unwrap().dims[2],
        names.len()
    );
    let mut by_z: Vec<(f64, &std::ffi::OsString)> = names
        .iter()
        .map(|n| {
            let s = dicom::parse_file(&std::fs::read(dir.join(n)).unwrap(), Path::new("x"));
            (s.unwrap()[0].position[2], n)
        })
        .collect();
    by_z.sort_by(|a, b| a.0.total_cmp(&b.0));
    let cut = by_z[by_z.len() / 2].1;
    let bytes = std::fs::read(dir.join(cut)).unwrap();
    std::fs::write(dir.join(cut), &bytes[..3000]).unwrap();
    let e = load_volume(dir, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("uneven slice spacing")
            && e.contains("1 unreadable file was in the folder")
            && e.contains(cut.to_str().unwrap()),
        "{e}"
    );
}

/// A 4×3×2 int16 volume with values `i + 10 j + 100 k − 1000`.
fn ramp_i16() -> Vec<u8> {
    let mut out = Vec::new();
    for k in 0..2i16 {
        for j in 0..3i16 {
            for i in 0..4i16 {
                out.extend_from_slice(&(i + 10 * j + 100 * k - 1000).to_le_bytes());
            }
        }
    }
    out
}

fn check_ramp(v: &Volume) {
    assert_eq!(v.dims, [4, 3, 2]);
    assert_eq!(v.at(3, 2, 1), 3.0 + 20.0 + 100.0 - 1000.0);
    assert_eq!(v.at(0, 0, 0), -1000.0);
}

#[test]
fn nrrd_attached_raw_in_ras_is_turned_into_lps() {
    let mut bytes = b"NRRD0004\n# a comment\ntype: short\ndimension: 3\nspace: right-anterior-superior\nsizes: 4 3 2\nspace directions: (0.5,0,0) (0,0.7,0) (0,0,2.5)\nkinds: domain domain domain\nendian: little\nencoding: raw\nspace origin: (10,20,30)\n\n".to_vec();
    bytes.extend(ramp_i16());
    let v = nrrd::parse(&bytes, Path::new("t.nrrd"), None).unwrap();
    check_ramp(&v);
    assert_eq!(v.spacing, [0.5, 0.7, 2.5]);
    assert_eq!(v.origin, [-10.0, -20.0, 30.0]);
    assert_eq!(
        v.direction,
        [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
    );
}

#[test]
fn nrrd_gzip_and_detached_data() {
    use std::io::Write;
    let scratch = crate::tests::scratch_dir("nrrd");
    let dir = scratch.path();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&ramp_i16()).unwrap();
    std::fs::write(dir.join("ramp.raw.gz"), gz.finish().unwrap()).unwrap();
    let header = "NRRD0005\ntype: int16\ndimension: 3\nspace: LPS\nsizes: 4 3 2\nspace directions: (0,1,0) (1,0,0) (0,0,1)\nencoding: gzip\ndata file: ramp.raw.gz\n\n";
    std::fs::write(dir.join("ramp.nhdr"), header).unwrap();
    let v = load_volume(&dir.join("ramp.nhdr"), &Default::default()).unwrap();
    check_ramp(&v);
    assert_eq!(
        v.direction,
        [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    );
}

/// The ramp's three phases, `ramp + 100 t` for t = 0, 1, 2: one volume after another
/// (`time_last`), or interleaved, each voxel's phases side by side (a list axis first).
fn ramp_phases(time_last: bool) -> Vec<u8> {
    let phase = |t: i16| -> Vec<i16> {
        ramp_i16()
            .chunks_exact(2)
            .map(|c| i16::from_le_bytes([c[0], c[1]]) + 100 * t)
            .collect()
    };
    let p: Vec<Vec<i16>> = (0..3).map(phase).collect();
    let values: Vec<i16> = if time_last {
        p.concat()
    } else {
        (0..p[0].len())
            .flat_map(|v| p.iter().map(move |q| q[v]))
            .collect()
    };
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// 4-D NRRD and MetaImage: the phase asked for, whichever axis holds the phases (3D Slicer's
/// list axis first, `none` among the directions; ITK's time last in a 4-D space; MetaImage's
/// fourth axis), raw or compressed, with the 3-D geometry; a phase the file lacks and a cut
/// file are errors naming the problem.
#[test]
fn four_d_nrrd_and_metaimage_read_the_phase_asked_for() {
    use std::io::Write;
    let gzip = |b: &[u8]| {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(b).unwrap();
        gz.finish().unwrap()
    };
    let slicer = "NRRD0004\ntype: short\ndimension: 4\nspace: left-posterior-superior\nsizes: 3 4 3 2\nspace directions: none (0.5,0,0) (0,0.7,0) (0,0,2.5)\nkinds: list domain domain domain\nendian: little\nencoding: ENC\nspace origin: (10,20,30)\n\n";
    let itk = "NRRD0004\ntype: short\ndimension: 4\nspace dimension: 4\nsizes: 4 3 2 3\nspace directions: (0.5,0,0,0) (0,0.7,0,0) (0,0,2.5,0) (0,0,0,1)\nkinds: domain domain domain domain\nendian: little\nencoding: ENC\nspace origin: (10,20,30,0)\n\n";
    let mha = "ObjectType = Image\nNDims = 4\nBinaryData = True\nCompressedData = ENC\nTransformMatrix = 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\nOffset = 10 20 30 0\nElementSpacing = 0.5 0.7 2.5 1\nDimSize = 4 3 2 3\nElementType = MET_SHORT\nElementDataFile = LOCAL\n";
    let mut files = Vec::new();
    for (name, header, time_last) in [("t.nrrd", slicer, false), ("t.nrrd", itk, true)] {
        for packed in [false, true] {
            let enc = if packed { "gzip" } else { "raw" };
            let mut b = header.replace("ENC", enc).into_bytes();
            let data = ramp_phases(time_last);
            b.extend(if packed { gzip(&data) } else { data });
            files.push((name, b));
        }
    }
    for packed in [false, true] {
        let mut b = mha
            .replace("ENC", if packed { "True" } else { "False" })
            .into_bytes();
        let data = ramp_phases(true);
        b.extend(if packed {
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
            z.write_all(&data).unwrap();
            z.finish().unwrap()
        } else {
            data
        });
        files.push(("t.mha", b));
    }
    for (name, bytes) in &files {
        let parse = |phase: Option<usize>| {
            let path = Path::new(name);
            if name.ends_with(".mha") {
                mha::parse(bytes, path, phase)
            } else {
                nrrd::parse(bytes, path, phase)
            }
        };
        for t in 1..=3 {
            let v = parse(Some(t)).unwrap();
            assert_eq!(v.phase, Phase { index: t, count: 3 });
            assert_eq!(v.dims, [4, 3, 2]);
            assert_eq!(v.spacing, [0.5, 0.7, 2.5]);
            assert_eq!(v.origin, [10.0, 20.0, 30.0]);
            assert_eq!(
                v.direction,
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            );
            let shift = 100.0 * (t - 1) as f32;
            assert_eq!(v.at(0, 0, 0), -1000.0 + shift, "{name} phase {t}");
            assert_eq!(v.at(3, 2, 1), 3.0 + 20.0 + 100.0 - 1000.0 + shift, "{name}");
            assert!(
                !v.warnings.iter().any(|w| w.contains("temporal positions")),
                "{:?}",
                v.warnings
            );
        }
        let first = parse(None).unwrap();
        assert_eq!(first.phase, Phase { index: 1, count: 3 });
        assert!(
            first
                .warnings
                .iter()
                .any(|w| w.contains("3 temporal positions")),
            "{:?}",
            first.warnings
        );
        let e = parse(Some(4)).unwrap_err().to_string();
        assert!(
            e.contains("phase 4 requested, but the image has 3 temporal positions"),
            "{e}"
        );
        // Cut in the last phase's data (past a gzip stream's 8-byte trailer).
        let cut = &bytes[..bytes.len() - 40];
        let e = if name.ends_with(".mha") {
            mha::parse(cut, Path::new(name), Some(3))
        } else {
            nrrd::parse(cut, Path::new(name), Some(3))
        }
        .unwrap_err()
        .to_string();
        let cut_words = ["truncated", "ends before", "incomplete"];
        assert!(cut_words.iter().any(|w| e.contains(w)), "{name}: {e}");
    }
    // The ITK form names no space: taken as LPS, with a warning.
    assert!(
        nrrd::parse(&files[2].1, Path::new("t.nrrd"), Some(1))
            .unwrap()
            .warnings
            .iter()
            .any(|w| w.contains("taken as LPS")),
    );
    // Two axes that are not in space, and a time axis that moves in space, are refused.
    let slicer = slicer.replace("ENC", "raw");
    let two_lists = slicer
        .replace("sizes: 3 4 3 2", "sizes: 3 4 3 2 1")
        .replace("dimension: 4", "dimension: 5");
    let e = nrrd::parse(two_lists.as_bytes(), Path::new("t.nrrd"), None).unwrap_err();
    assert!(e.to_string().contains("NRRD dimension 5"), "{e}");
    let none_twice = slicer.replace("(0.5,0,0)", "none");
    let e = nrrd::parse(none_twice.as_bytes(), Path::new("t.nrrd"), None).unwrap_err();
    assert!(e.to_string().contains("2 axes in space"), "{e}");
    // A phase count whose bytes pass 2⁶⁴: an error, not an overflow.
    for (name, header) in [
        (
            "huge.nrrd",
            "NRRD0004\ntype: double\ndimension: 4\nspace: LPS\nsizes: 1024 1024 1024 4000000000\nspace directions: (1,0,0) (0,1,0) (0,0,1) none\nencoding: raw\nbyte skip: -1\n\n",
        ),
        (
            "huge.mha",
            "NDims = 4\nDimSize = 1024 1024 1024 1000000000\nElementType = MET_DOUBLE\nHeaderSize = -1\nElementDataFile = LOCAL\n",
        ),
    ] {
        let mut b = header.as_bytes().to_vec();
        b.extend([0u8; 64]);
        let e = if name.ends_with(".mha") {
            mha::parse(&b, Path::new(name), Some(999_999_999))
        } else {
            nrrd::parse(&b, Path::new(name), Some(3_999_999_999))
        }
        .unwrap_err()
        .to_string();
        assert!(e.contains("truncated") || e.contains("ends before"), "{e}");
    }
    let mixed = mha
        .replace("ENC", "False")
        .replace("0 0 0 1\nOffset", "0.5 0 0 1\nOffset");
    let e = mha::parse(mixed.as_bytes(), Path::new("t.mha"), None).unwrap_err();
    assert!(e.to_string().contains("mixes space and time"), "{e}");
}

/// A spacing below a picometre is a corrupt header's (the fuzzer's 7e-44 mm, which rendered
/// for hours): refused before anything is read, naming the spacing; a nanometre is accepted.
#[test]
fn a_spacing_below_a_picometre_is_refused() {
    let header = |spacing: &str| {
        let mut b = format!(
            "ObjectType = Image\nNDims = 3\nBinaryData = True\nElementSpacing = {spacing}\nDimSize = 4 3 2\nElementType = MET_SHORT\nElementDataFile = LOCAL\n"
        )
        .into_bytes();
        b.extend(ramp_i16());
        b
    };
    let e = mha::parse(&header("7.1e-44 0.8 2.5"), Path::new("t.mha"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("t.mha") && e.contains("7.1e-44") && e.contains("below 1e-9 mm"),
        "{e}"
    );
    let v = mha::parse(&header("1e-6 0.8 2.5"), Path::new("t.mha"), None).unwrap();
    assert_eq!(v.spacing, [1e-6, 0.8, 2.5]);
}

#[test]
fn metaimage_local_and_compressed() {
    use std::io::Write;
    let header = |compressed: bool| {
        format!(
            "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\nCompressedData = {}\nTransformMatrix = 0 1 0 -1 0 0 0 0 1\nOffset = 1 2 3\nElementSpacing = 0.5 0.25 2\nDimSize = 4 3 2\nElementType = MET_SHORT\nElementDataFile = LOCAL\n",
            if compressed { "True" } else { "False" }
        )
    };
    let mut raw = header(false).into_bytes();
    raw.extend(ramp_i16());
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    z.write_all(&ramp_i16()).unwrap();
    let mut packed = header(true).into_bytes();
    packed.extend(z.finish().unwrap());
    for bytes in [raw, packed] {
        let v = mha::parse(&bytes, Path::new("t.mha"), None).unwrap();
        check_ramp(&v);
        assert_eq!(v.spacing, [0.5, 0.25, 2.0]);
        assert_eq!(v.origin, [1.0, 2.0, 3.0]);
        // Axis i is the first triple (0, 1, 0), axis j the second (−1, 0, 0).
        assert_eq!(
            v.direction,
            [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        );
    }
}

/// A NIfTI-2 file, little- or big-endian, with an sform (RAS) and a 90° qform that must lose.
fn nifti2(big: bool) -> Vec<u8> {
    let mut h = vec![0u8; 544];
    let put = |h: &mut Vec<u8>, o: usize, b: &[u8]| h[o..o + b.len()].copy_from_slice(b);
    macro_rules! num {
        ($v:expr) => {
            if big {
                $v.to_be_bytes().to_vec()
            } else {
                $v.to_le_bytes().to_vec()
            }
        };
    }
    put(&mut h, 0, &num!(540i32));
    put(&mut h, 4, b"n+2\0\r\n\x1a\n");
    put(&mut h, 12, &num!(4i16)); // int16
    put(&mut h, 14, &num!(16i16));
    for (i, d) in [3i64, 4, 3, 2, 1, 1, 1, 1].iter().enumerate() {
        put(&mut h, 16 + 8 * i, &num!(*d));
    }
    for (i, d) in [1.0f64, 0.5, 0.7, 2.5, 0.0, 0.0, 0.0, 0.0]
        .iter()
        .enumerate()
    {
        put(&mut h, 104 + 8 * i, &num!(*d));
    }
    put(&mut h, 168, &num!(544i64));
    put(&mut h, 176, &num!(f64::NAN)); // scl_slope NaN: no scaling
    put(&mut h, 344, &num!(1i32)); // qform_code
    put(&mut h, 348, &num!(1i32)); // sform_code
    put(&mut h, 352 + 16, &num!(1.0f64)); // quatern_d = 1: 180° about z
    let srow = [
        [0.5f64, 0.0, 0.0, 10.0],
        [0.0, 0.7, 0.0, 20.0],
        [0.0, 0.0, 2.5, 30.0],
    ];
    for (r, row) in srow.iter().enumerate() {
        for (c, x) in row.iter().enumerate() {
            put(&mut h, 400 + 32 * r + 8 * c, &num!(*x));
        }
    }
    for chunk in ramp_i16().chunks(2) {
        let v = i16::from_le_bytes([chunk[0], chunk[1]]);
        h.extend(num!(v));
    }
    h
}

#[test]
fn nifti2_both_byte_orders_sform_wins() {
    for big in [false, true] {
        let v = nifti::parse(&nifti2(big), Path::new("t.nii"), None).unwrap();
        check_ramp(&v);
        assert_eq!(v.spacing, [0.5, 0.7, 2.5]);
        assert_eq!(v.origin, [-10.0, -20.0, 30.0]);
        assert_eq!(
            v.direction,
            [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
        );
    }
}

/// A 4-D NIfTI-2 (the ramp, then the ramp + 1000, then + 2000 along its fourth axis): each phase
/// is its own volume, the first by default with a warning; a phase beyond the file's, or one cut
/// off by its end, is an error naming the file; a NRRD (3-D only) has phase 1 alone.
#[test]
fn a_4d_nifti_reads_the_phase_asked_for() {
    let mut b = nifti2(false);
    b[16..24].copy_from_slice(&4i64.to_le_bytes()); // dim[0]: 4-D
    b[16 + 32..16 + 40].copy_from_slice(&3i64.to_le_bytes()); // dim[4]: 3 volumes
    for shift in [1000i16, 2000] {
        for c in ramp_i16().chunks(2) {
            b.extend((i16::from_le_bytes([c[0], c[1]]) + shift).to_le_bytes());
        }
    }
    let path = Path::new("t4.nii");
    for k in 1..=3 {
        let v = nifti::parse(&b, path, Some(k)).unwrap();
        assert_eq!(v.phase, Phase { index: k, count: 3 });
        assert!(v.warnings.is_empty(), "{:?}", v.warnings);
        let shift = 1000.0 * (k - 1) as f32;
        assert_eq!(v.at(0, 0, 0), -1000.0 + shift);
        assert_eq!(v.at(3, 2, 1), 3.0 + 20.0 + 100.0 - 1000.0 + shift);
        assert_eq!(v.spacing, [0.5, 0.7, 2.5]);
    }
    let v = nifti::parse(&b, path, None).unwrap();
    assert_eq!((v.phase.index, v.at(0, 0, 0)), (1, -1000.0));
    assert!(
        v.warnings.iter().any(|w| w.contains(
            "3 temporal positions (phases) in the image; reading phase 1; pick another with --phase K"
        )),
        "{:?}",
        v.warnings
    );
    let e = nifti::parse(&b, path, Some(4)).unwrap_err().to_string();
    assert!(
        e.starts_with("t4.nii")
            && e.contains(
                "phase 4 requested, but the image has 3 temporal positions (phases 1 to 3)"
            ),
        "{e}"
    );
    // Cut inside the third volume: the first two still read, the third is an error.
    let cut = &b[..b.len() - 10];
    assert!(nifti::parse(cut, path, Some(2)).is_ok());
    let e = nifti::parse(cut, path, Some(3)).unwrap_err().to_string();
    assert!(e.starts_with("t4.nii") && e.contains("truncated"), "{e}");

    let scratch = crate::tests::scratch_dir("phase");
    let dir = scratch.path();
    let mut nrrd_bytes = b"NRRD0004\ntype: short\ndimension: 3\nspace: LPS\nsizes: 4 3 2\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\n\n".to_vec();
    nrrd_bytes.extend(ramp_i16());
    let file = dir.join("ramp.nrrd");
    std::fs::write(&file, nrrd_bytes).unwrap();
    let pick = |phase| VolumeSelect {
        series: None,
        phase: Some(phase),
    };
    assert_eq!(
        load_volume(&file, &pick(1)).unwrap().phase,
        Phase::default()
    );
    let e = load_volume(&file, &pick(2)).unwrap_err().to_string();
    assert!(
        e.contains("ramp.nrrd")
            && e.contains("phase 2 requested, but the image has one temporal position (phase 1)"),
        "{e}"
    );
}

#[test]
fn absurd_headers_are_refused_before_allocating() {
    let mut bytes = b"NRRD0004\ntype: short\ndimension: 3\nspace: LPS\nsizes: 512 512 1000000\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\n\n".to_vec();
    bytes.extend(ramp_i16());
    let e = nrrd::parse(&bytes, Path::new("huge.nrrd"), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("huge.nrrd") && e.contains("limit"), "{e}");
    for (dirs, origin, says) in [
        ("(0,0,0) (0,1,0) (0,0,1)", "(0,0,0)", "spacing"),
        ("(nan,0,0) (0,1,0) (0,0,1)", "(0,0,0)", "spacing"),
        ("(1,0,0) (1,0,0) (0,0,1)", "(0,0,0)", "singular"),
        ("(1,0,0) (0,1,0) (0,0,1)", "(0,0,3e6)", "beyond ±1e6 mm"),
        ("(1e6,0,0) (0,1,0) (0,0,1)", "(0,0,0)", "beyond ±1e6 mm"),
    ] {
        let text = format!(
            "NRRD0004\ntype: short\ndimension: 3\nspace: LPS\nsizes: 4 3 2\nspace directions: {dirs}\nspace origin: {origin}\nencoding: raw\n\n"
        );
        let mut bytes = text.into_bytes();
        bytes.extend(ramp_i16());
        let e = nrrd::parse(&bytes, Path::new("bad.nrrd"), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains(says), "{dirs}: {e}");
    }
    // A NIfTI claiming 10⁶ slices in a 500-byte file: refused by the size limit, as reaching
    // 2.5 km, or as truncated.
    let mut n2 = nifti2(false);
    n2[16 + 24..16 + 32].copy_from_slice(&1_000_000i64.to_le_bytes());
    let e = nifti::parse(&n2, Path::new("t.nii"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("truncated") || e.contains("limit") || e.contains("beyond ±1e6 mm"),
        "{e}"
    );
}

/// The real explicit-VR slice cut down to its first 8×8 pixels (Rows, Columns and the pixel data
/// length rewritten in place), so that thousands of corrupted copies parse quickly.
fn tiny_dicom(full: &[u8]) -> Vec<u8> {
    let find = |pat: &[u8]| full.windows(pat.len()).position(|w| w == pat).unwrap();
    let mut b = full.to_vec();
    for tag in [[0x28u8, 0, 0x10, 0], [0x28, 0, 0x11, 0]] {
        let at = find(&[&tag[..], b"US\x02\x00"].concat()) + 8;
        b[at..at + 2].copy_from_slice(&8u16.to_le_bytes());
    }
    let at = find(&[0xe0, 0x7f, 0x10, 0x00, b'O', b'W', 0, 0]) + 8;
    b[at..at + 4].copy_from_slice(&128u32.to_le_bytes());
    b.truncate(at + 4 + 128);
    b
}

/// Truncations and bit flips of every format's header give errors (or a valid volume), never a
/// panic.
#[test]
fn truncated_and_bit_flipped_headers_never_panic() {
    let mut nrrd_bytes = b"NRRD0004\ntype: short\ndimension: 3\nspace: LPS\nsizes: 4 3 2\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: raw\nspace origin: (1,2,3)\n\n".to_vec();
    nrrd_bytes.extend(ramp_i16());
    let mut mha_bytes = b"ObjectType = Image\nNDims = 3\nBinaryData = True\nCompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = 1 2 3\nElementSpacing = 1 1 1\nDimSize = 4 3 2\nElementType = MET_SHORT\nElementDataFile = LOCAL\n".to_vec();
    mha_bytes.extend(ramp_i16());
    let dicom_bytes = std::fs::read(shared(LE_EXPLICIT)).unwrap();
    let nifti_gz = std::fs::read(shared("nifti/abdomen_pelvis_ct_totalseg.nii.gz")).unwrap();
    type Parse = fn(&[u8], &Path) -> Result<(), VolumeError>;
    let cases: [(&str, Vec<u8>, usize, Parse); 7] = [
        ("t.nii", nifti2(false), 544, |b, p| {
            nifti::parse(b, p, None).map(drop)
        }),
        ("t.nii", nifti2(true), 544, |b, p| {
            nifti::parse(b, p, None).map(drop)
        }),
        ("t.nrrd", nrrd_bytes, 160, |b, p| {
            nrrd::parse(b, p, None).map(drop)
        }),
        ("t.mha", mha_bytes, 220, |b, p| {
            mha::parse(b, p, None).map(drop)
        }),
        ("t.dcm", tiny_dicom(&dicom_bytes), 1400, |b, p| {
            decode_dicom(b, p).map(drop)
        }),
        ("t.vtk", vtk_ramp(VTK_BINARY), 200, |b, p| {
            vtk::parse(b, p, None).map(drop)
        }),
        ("t.vtk", vtk_ramp(VTK_ASCII), 260, |b, p| {
            vtk::parse(b, p, None).map(drop)
        }),
    ];
    for (name, bytes, header, parse) in cases {
        let path = Path::new(name);
        assert!(parse(&bytes, path).is_ok(), "{name} must parse intact");
        for cut in (0..bytes.len()).step_by((bytes.len() / 97).max(1)) {
            let r = parse(&bytes[..cut], path);
            if let Err(e) = r {
                assert!(e.to_string().starts_with(name), "{e}");
            }
        }
        for at in 0..header.min(bytes.len()) {
            for bit in [0x01u8, 0x10, 0x80] {
                let mut b = bytes.clone();
                b[at] ^= bit;
                let _ = parse(&b, path);
            }
        }
    }
    // Cut pixel data of the full slice.
    for cut in [
        dicom_bytes.len() - 1,
        dicom_bytes.len() - 1000,
        dicom_bytes.len() / 2,
    ] {
        let e = decode_dicom(&dicom_bytes[..cut], Path::new("cut.dcm"));
        assert!(e.unwrap_err().to_string().starts_with("cut.dcm"));
    }
    // A truncated gzip stream of the real CT.
    for cut in [10, 100, 1000, nifti_gz.len() / 2, nifti_gz.len() - 2000] {
        let e = nifti::parse(&nifti_gz[..cut], Path::new("cut.nii.gz"), None).unwrap_err();
        assert!(e.to_string().starts_with("cut.nii.gz"), "{e}");
    }
}

/// A damaged JPEG-LS or 12-bit JPEG stream (bits of its headers flipped, bytes of the
/// entropy-coded data turned into markers, the data cut short) decodes to some values or is an
/// error naming the file and the codec, never a panic; pure_jpegls runs with release
/// arithmetic (Cargo.toml), libjpeg-turbo-rs with overflow checks.
#[test]
fn damaged_jpeg_ls_and_12_bit_jpeg_are_errors_never_panics() {
    // (file, codec, header bytes: all 8 bits of each flipped, else one)
    for (ts, codec, header) in [("4.80", "JPEG-LS", 32), ("4.51", "12-bit JPEG", 0)] {
        let dir = shared(TS_DIR);
        let file = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.to_str().unwrap().contains(&format!("{ts}_")))
            .unwrap();
        let bytes = std::fs::read(&file).unwrap();
        let soi = bytes
            .windows(3)
            .position(|w| w == [0xFF, 0xD8, 0xFF])
            .expect("a JPEG stream");
        // The entropy-coded data starts after the SOS segment.
        let sos = soi
            + bytes[soi..]
                .windows(2)
                .position(|w| w == [0xFF, 0xDA])
                .unwrap();
        let scan = sos + 2 + u16::from_be_bytes([bytes[sos + 2], bytes[sos + 3]]) as usize;
        let decode = |b: &[u8]| {
            decode_dicom(b, Path::new("j.dcm"))
                .map(drop)
                .map_err(|e| e.to_string())
        };
        decode(&bytes).expect("the intact slice decodes");
        let mut errors = 0;
        let mut cases = 0;
        let mut check = |b: Vec<u8>, what: &str| {
            cases += 1;
            if let Err(e) = decode(&b) {
                assert!(
                    e.starts_with("j.dcm") && e.contains(codec),
                    "{ts} {what}: {e}"
                );
                errors += 1;
            }
        };
        for at in soi..scan + 8 {
            let bits = if at < soi + header {
                0..8
            } else {
                at % 8..at % 8 + 1
            };
            for bit in bits {
                let mut b = bytes.clone();
                b[at] ^= 1 << bit;
                check(b, &format!("bit {bit} of byte {}", at - soi));
            }
        }
        let end = bytes.len() - 8;
        for k in 0..24 {
            let at = scan + (end - scan) * k / 24;
            let mut b = bytes.clone();
            b[at] = 0xFF;
            b[at + 1] = [0xD9, 0xD0, 0xF7, 0x00][k % 4];
            check(b, &format!("a marker at scan byte {}", at - scan));
            let mut b = bytes.clone();
            b[at..end].fill(if k % 2 == 0 { 0 } else { 0xFF });
            check(b, &format!("the scan cut at byte {}", at - scan));
        }
        assert!(
            errors * 3 > cases,
            "{ts}: only {errors} of {cases} damaged streams were refused"
        );
    }
}

/// A DICOM file's frames, decoded as a volume's would be (each frame's modality values).
fn decode_dicom(bytes: &[u8], path: &Path) -> Result<Vec<Vec<f32>>, VolumeError> {
    let mut s = dicom::parse_file(bytes, path)?.swap_remove(0);
    let n = (s.rows * s.cols) as usize;
    dicom::decode_frames(&mut s, n, None)
}

/// The ramp as legacy VTK, with `header` (ending in its values' line) before its values: big-endian
/// binary when the header says BINARY, else text.
fn vtk_ramp(header: &str) -> Vec<u8> {
    let values: Vec<i16> = ramp_i16()
        .chunks_exact(2)
        .map(|c| i16::from_le_bytes([c[0], c[1]]))
        .collect();
    let mut bytes = header.as_bytes().to_vec();
    if header.contains("BINARY") {
        bytes.extend(values.iter().flat_map(|v| v.to_be_bytes()));
        bytes.push(b'\n');
    } else {
        let text: Vec<String> = values.iter().map(|v| v.to_string()).collect();
        bytes.extend(text.join(" ").into_bytes());
        bytes.push(b'\n');
    }
    bytes
}

/// As ITK writes it (SimpleITK's `WriteImage(…, "x.vtk")`).
const VTK_BINARY: &str = "# vtk DataFile Version 3.0\nVTK File Generated by Insight Segmentation and Registration Toolkit (ITK)\nBINARY\nDATASET STRUCTURED_POINTS\nDIMENSIONS 4 3 2 \nSPACING 5.0e-01 2.5e-01 2.0e+00 \nORIGIN 1 2 3 \nPOINT_DATA 24\nSCALARS scalars short 1\nLOOKUP_TABLE default\n";

/// Text, lower-case keywords, the older ASPECT_RATIO, a blank line and no lookup table.
const VTK_ASCII: &str = "# vtk DataFile Version 5.1\nramp\nascii\ndataset structured_points\ndimensions 4 3 2\naspect_ratio 0.5 0.25 2\norigin 1 2 3\n\npoint_data 24\nscalars ramp short\n";

#[test]
fn legacy_vtk_image_data_binary_text_and_field() {
    let field = VTK_BINARY.replace(
        "SCALARS scalars short 1\nLOOKUP_TABLE default\n",
        "FIELD FieldData 1\nramp 1 24 short\n",
    );
    for (what, header) in [
        ("binary", VTK_BINARY),
        ("ascii", VTK_ASCII),
        ("field", &field),
    ] {
        let v = vtk::parse(&vtk_ramp(header), Path::new("t.vtk"), None).unwrap();
        check_ramp(&v);
        assert_eq!(v.spacing, [0.5, 0.25, 2.0], "{what}");
        assert_eq!(v.origin, [1.0, 2.0, 3.0], "{what}");
        assert_eq!(v.format, VolumeFormat::Vtk);
        let axial = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(v.direction, axial, "{what}");
    }
    let refused = |bytes: &[u8], says: &str| {
        let e = vtk::parse(bytes, Path::new("bad.vtk"), None)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("bad.vtk") && e.contains(says), "{says}: {e}");
    };
    let ramp = vtk_ramp(VTK_BINARY);
    refused(&ramp[..ramp.len() - 3], "truncated");
    refused(&vtk_ramp(VTK_ASCII)[..VTK_ASCII.len() + 20], "truncated");
    refused(
        &vtk_ramp(&VTK_ASCII.replace("4 3 2", "4 3 1000000")),
        "does not match",
    );
    refused(
        &vtk_ramp(
            &VTK_BINARY
                .replace("4 3 2", "4 3 1000000")
                .replace("2.0e+00", "0.5")
                .replace("POINT_DATA 24", "POINT_DATA 12000000"),
        ),
        "truncated",
    );
    refused(
        &vtk_ramp(&VTK_BINARY.replace("4 3 2", "1000 1000 1000000")),
        "limit",
    );
    refused(
        &vtk_ramp(&VTK_BINARY.replace("STRUCTURED_POINTS", "POLYDATA")),
        "a volume is image data",
    );
    refused(&vtk_ramp(&VTK_BINARY.replace("short", "bit")), "\"bit\"");
    refused(
        &vtk_ramp(&VTK_BINARY.replace("short 1", "short 3")),
        "3 components",
    );
    refused(
        &vtk_ramp(&VTK_ASCII.replace("2 3", "nan 3")),
        "finite numbers",
    );
    refused(b"P6\n4 3\n255\n", "not a legacy VTK file");
    let mut word = vtk_ramp(VTK_ASCII);
    let at = VTK_ASCII.len() + 2;
    word[at] = b'x';
    refused(&word, "not a number");
}

#[test]
fn raw_files_named_by_size_and_type() {
    use std::io::Write;
    let scratch = crate::tests::scratch_dir("named-raw");
    let dir = scratch.path();
    std::fs::write(dir.join("ramp_4x3x2_int16.raw"), ramp_i16()).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&ramp_i16()).unwrap();
    let packed = gz.finish().unwrap();
    std::fs::write(dir.join("Ramp_4X3X2_INT16.raw.gz"), &packed).unwrap();
    for name in ["ramp_4x3x2_int16.raw", "Ramp_4X3X2_INT16.raw.gz"] {
        let v = load_volume(&dir.join(name), &Default::default()).unwrap();
        check_ramp(&v);
        assert_eq!(v.format, VolumeFormat::Raw);
        assert_eq!(v.spacing, [1.0; 3]);
        // RAS axes; the voxel centres from −n/2 to n/2 − 1 along each LPS axis.
        assert_eq!(
            v.direction,
            [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        assert_eq!(v.origin, [1.0, 0.5, -1.0]);
        let ends = [[0.0; 3], [3.0, 2.0, 1.0]].map(|p| v.index_to_world(p.into()).to_array());
        assert_eq!(ends, [[1.0, 0.5, -1.0], [-2.0, -1.5, 0.0]]);
    }
    // Infinite values (float32 here, and a float64 beyond f32's range) are read as missing.
    let floats: Vec<u8> = [
        1.0f32,
        f32::INFINITY,
        -2.0,
        f32::NEG_INFINITY,
        f32::NAN,
        7.0,
    ]
    .iter()
    .flat_map(|v| v.to_le_bytes())
    .collect();
    std::fs::write(dir.join("inf_3x2x1_float32.raw"), floats).unwrap();
    let doubles: Vec<u8> = [1.0f64, 1e300, -2.0, 5.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.join("inf_2x2x1_float64.raw"), doubles).unwrap();
    for (name, nan_at, count) in [
        (
            "inf_3x2x1_float32.raw",
            vec![1, 3, 4],
            "2 voxel values are infinite",
        ),
        (
            "inf_2x2x1_float64.raw",
            vec![1],
            "1 voxel value is infinite",
        ),
    ] {
        let v = load_volume(&dir.join(name), &Default::default()).unwrap();
        for (i, x) in v.data.iter().enumerate() {
            assert_eq!(x.is_nan(), nan_at.contains(&i), "{name}: {:?}", v.data);
        }
        assert!(
            v.warnings.iter().any(|w| w.contains(count)),
            "{:?}",
            v.warnings
        );
    }
    // The same name over a gzip stream with a byte more than the name implies.
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&[ramp_i16(), vec![0]].concat()).unwrap();
    std::fs::write(dir.join("more_4x3x2_int16.raw.gz"), gz.finish().unwrap()).unwrap();
    std::fs::write(
        dir.join("cut_4x3x2_int16.raw.gz"),
        &packed[..packed.len() - 12],
    )
    .unwrap();
    std::fs::write(dir.join("ramp_4x3_int16.raw"), ramp_i16()).unwrap();
    std::fs::write(dir.join("ramp_4x0x2_int16.raw"), ramp_i16()).unwrap();
    std::fs::write(dir.join("ramp_4x3x2_float16.raw"), ramp_i16()).unwrap();
    for (name, says) in [
        ("more_4x3x2_int16.raw.gz", "the wrong size or type"),
        ("cut_4x3x2_int16.raw.gz", "cut_4x3x2_int16.raw.gz"),
        ("ramp_4x3_int16.raw", "is not a size WxHxD"),
        ("ramp_4x0x2_int16.raw", "is not a size WxHxD"),
        ("ramp_4x3x2_float16.raw", "is not a voxel type"),
    ] {
        let e = load_volume(&dir.join(name), &Default::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains(name) && e.contains(says), "{name}: {e}");
    }
}
