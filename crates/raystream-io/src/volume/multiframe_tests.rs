//! Enhanced (multi-frame) CT: the 20-slice abdomen series of ../shared rewritten as one
//! multi-frame file in the layouts scanners write (frames out of order, each with its own
//! rescale; uncompressed, or JPEG-LS a frame or split by an offset table; two temporal
//! positions), read back as the series itself, voxel for voxel; and what is wrong in one named.
//! Also the 4-D series of single-frame files: the same slices at two temporal positions.

use std::path::Path;

use dicom_core::value::PixelFragmentSequence;
use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};

use super::*;
use crate::segmentation::{item, seq, text};

fn series() -> Volume {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/volumes/dicom/abdomen_ct_j2k_totalseg");
    load_volume(&dir, &Default::default()).unwrap()
}

/// How a test file departs from the plain layout.
#[derive(Clone, Copy, Default)]
struct Layout {
    /// JPEG-LS (1.2.840.10008.1.2.4.80), one fragment a frame; with `split`, two fragments a
    /// frame and a basic offset table.
    jpeg_ls: bool,
    split: bool,
    /// Every slice twice, at temporal positions 1 and 2 (the second 100 HU brighter).
    temporal: bool,
    /// NumberOfFrames one more than the frames described.
    wrong_count: bool,
    /// Frame 3 (in file order) without its Plane Position.
    no_position: bool,
}

fn decimals(tag: dicom_core::Tag, v: &[f64]) -> DataElement<InMemDicomObject> {
    let s: Vec<String> = v.iter().map(|x| format!("{x}")).collect();
    DataElement::new(tag, VR::DS, PrimitiveValue::Strs(s.into()))
}

/// `v` as an enhanced CT file: each slice a frame, stored as HU + 1024 + k with its own
/// intercept (frame k in the series), the frames in a shuffled order.
fn write_enhanced(v: &Volume, layout: Layout, name: &str) -> crate::tests::ScratchFile {
    let [nx, ny, nz] = v.dims;
    let col = |a: usize| [v.direction[0][a], v.direction[1][a], v.direction[2][a]];
    let (row, colv, axis) = (col(0), col(1), col(2));
    // A fixed shuffle: 7 is prime to 20.
    let order: Vec<usize> = (0..nz).map(|i| (i * 7 + 3) % nz).collect();
    let times: &[u16] = if layout.temporal { &[1, 2] } else { &[1] };
    let mut per_frame = Vec::new();
    let mut stored: Vec<Vec<u16>> = Vec::new();
    for &t in times {
        for (n, &k) in order.iter().enumerate() {
            let p: Vec<f64> = (0..3)
                .map(|r| v.origin[r] + axis[r] * v.spacing[2] * k as f64)
                .collect();
            let offset = 1024.0 + k as f64;
            let shift = if t == 2 { 100.0 } else { 0.0 };
            stored.push(
                v.data[k * nx * ny..(k + 1) * nx * ny]
                    .iter()
                    .map(|&h| (h as f64 + shift + offset) as u16)
                    .collect(),
            );
            let mut groups = vec![
                seq(
                    tags::PIXEL_VALUE_TRANSFORMATION_SEQUENCE,
                    vec![item(vec![
                        decimals(tags::RESCALE_INTERCEPT, &[-offset]),
                        decimals(tags::RESCALE_SLOPE, &[1.0]),
                        text(tags::RESCALE_TYPE, VR::LO, "HU"),
                    ])],
                ),
                seq(
                    tags::FRAME_CONTENT_SEQUENCE,
                    vec![item(vec![
                        text(tags::STACK_ID, VR::SH, "1"),
                        DataElement::new(
                            tags::TEMPORAL_POSITION_INDEX,
                            VR::UL,
                            PrimitiveValue::from(t as u32),
                        ),
                    ])],
                ),
            ];
            if !(layout.no_position && n == 2) {
                groups.push(seq(
                    tags::PLANE_POSITION_SEQUENCE,
                    vec![item(vec![decimals(tags::IMAGE_POSITION_PATIENT, &p)])],
                ));
            }
            per_frame.push(item(groups));
        }
    }
    let frames = per_frame.len() + layout.wrong_count as usize;
    let orientation: Vec<f64> = row.iter().chain(&colv).copied().collect();
    let shared = item(vec![
        seq(
            tags::PIXEL_MEASURES_SEQUENCE,
            vec![item(vec![
                decimals(tags::PIXEL_SPACING, &[v.spacing[1], v.spacing[0]]),
                decimals(tags::SLICE_THICKNESS, &[v.spacing[2]]),
            ])],
        ),
        seq(
            tags::PLANE_ORIENTATION_SEQUENCE,
            vec![item(vec![decimals(
                tags::IMAGE_ORIENTATION_PATIENT,
                &orientation,
            )])],
        ),
    ]);
    let us = |tag, x: u16| DataElement::new(tag, VR::US, PrimitiveValue::from(x));
    let mut obj = item(vec![
        text(tags::SOP_CLASS_UID, VR::UI, "1.2.840.10008.5.1.4.1.1.2.1"),
        text(tags::SOP_INSTANCE_UID, VR::UI, "2.25.1"),
        text(tags::MODALITY, VR::CS, "CT"),
        text(tags::SERIES_INSTANCE_UID, VR::UI, "2.25.2"),
        text(tags::NUMBER_OF_FRAMES, VR::IS, &frames.to_string()),
        us(tags::SAMPLES_PER_PIXEL, 1),
        text(tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "MONOCHROME2"),
        us(tags::ROWS, ny as u16),
        us(tags::COLUMNS, nx as u16),
        us(tags::BITS_ALLOCATED, 16),
        us(tags::BITS_STORED, 16),
        us(tags::HIGH_BIT, 15),
        us(tags::PIXEL_REPRESENTATION, 0),
        seq(tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE, vec![shared]),
        seq(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, per_frame),
    ]);
    let ts = if layout.jpeg_ls {
        let mut fragments = Vec::new();
        let mut offsets = Vec::new();
        let mut at = 0u32;
        for frame in &stored {
            let mut jls = Vec::new();
            jpegls::encode(frame, nx as u32, ny as u32, &mut jls).unwrap();
            if jls.len() % 2 == 1 {
                jls.push(0);
            }
            offsets.push(at);
            let parts = if layout.split {
                let half = jls.len() / 4 * 2;
                vec![jls[..half].to_vec(), jls[half..].to_vec()]
            } else {
                vec![jls]
            };
            for p in parts {
                at += 8 + p.len() as u32;
                fragments.push(p);
            }
        }
        let offsets = if layout.split { offsets } else { Vec::new() };
        obj.put(DataElement::new(
            tags::PIXEL_DATA,
            VR::OB,
            PixelFragmentSequence::new(offsets, fragments),
        ));
        "1.2.840.10008.1.2.4.80"
    } else {
        obj.put(DataElement::new(
            tags::PIXEL_DATA,
            VR::OW,
            PrimitiveValue::U16(stored.concat().into()),
        ));
        "1.2.840.10008.1.2.1"
    };
    let path = crate::tests::scratch_file(name);
    obj.with_meta(
        FileMetaTableBuilder::new()
            .transfer_syntax(ts)
            .media_storage_sop_class_uid("1.2.840.10008.5.1.4.1.1.2.1")
            .media_storage_sop_instance_uid("2.25.1"),
    )
    .unwrap()
    .write_to_file(&path)
    .unwrap();
    path
}

fn assert_same(got: &Volume, want: &Volume, what: &str) {
    assert_eq!(got.dims, want.dims, "{what}");
    for i in 0..3 {
        assert!(
            (got.spacing[i] - want.spacing[i]).abs() < 1e-9,
            "{what}: spacing"
        );
        assert!(
            (got.origin[i] - want.origin[i]).abs() < 1e-9,
            "{what}: origin"
        );
        for j in 0..3 {
            assert!(
                (got.direction[i][j] - want.direction[i][j]).abs() < 1e-9,
                "{what}: direction"
            );
        }
    }
    assert_eq!(got.unit, ValueUnit::Hounsfield, "{what}");
    let differ = got
        .data
        .iter()
        .zip(&want.data)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(differ, 0, "{what}: voxels differ");
}

#[test]
fn an_enhanced_ct_reads_as_the_series_it_was_made_from() {
    let want = series();
    for (name, layout) in [
        ("plain.dcm", Layout::default()),
        (
            "jpeg-ls.dcm",
            Layout {
                jpeg_ls: true,
                ..Default::default()
            },
        ),
        (
            "jpeg-ls-split.dcm",
            Layout {
                jpeg_ls: true,
                split: true,
                ..Default::default()
            },
        ),
    ] {
        let file = write_enhanced(&want, layout, name);
        let got = load_volume(&file, &Default::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_same(&got, &want, name);
        assert!(got.warnings.is_empty(), "{name}: {:?}", got.warnings);
        assert_eq!(got.series.as_ref().unwrap().count, 20, "{name}");
    }
}

/// A 4-D enhanced CT (every slice at two temporal positions, the second 100 HU brighter), plain
/// and JPEG-LS split by an offset table: phase 1 by default, with a warning; `--phase 2` the
/// brighter one, only its frames decoded; a phase beyond the file's an error saying how many
/// there are.
#[test]
fn a_4d_enhanced_ct_reads_the_phase_asked_for() {
    let first = series();
    let second = Volume {
        data: first.data.iter().map(|v| v + 100.0).collect(),
        ..first.clone()
    };
    for (name, jpeg_ls) in [("4d.dcm", false), ("4d-ls.dcm", true)] {
        let layout = Layout {
            temporal: true,
            jpeg_ls,
            split: jpeg_ls,
            ..Default::default()
        };
        let file = write_enhanced(&first, layout, name);
        let read = |phase| {
            load_volume(
                &file,
                &VolumeSelect {
                    series: None,
                    phase,
                },
            )
        };
        let got = read(None).unwrap();
        assert_same(&got, &first, name);
        assert_eq!(got.phase, Phase { index: 1, count: 2 }, "{name}");
        let w = got.warnings.join("\n");
        assert!(
            w.contains("2 temporal positions (phases) in the image; reading phase 1"),
            "{name}: {w}"
        );
        let got = read(Some(2)).unwrap();
        assert_same(&got, &second, name);
        assert_eq!(got.phase, Phase { index: 2, count: 2 }, "{name}");
        assert!(got.warnings.is_empty(), "{name}: {:?}", got.warnings);
        assert_eq!(got.series.as_ref().unwrap().count, 20, "{name}");
        let e = read(Some(3)).unwrap_err().to_string();
        assert!(
            e.starts_with(file.to_str().unwrap())
                && e.contains("phase 3 requested, but the image has 2 temporal positions"),
            "{name}: {e}"
        );
    }
}

/// The abdomen series' files copied twice into one folder, TemporalPositionIdentifier 1 and 2,
/// the second 100 HU brighter (its RescaleIntercept raised): one 4-D series, read phase by phase.
/// The same files once, each slice with its own TemporalPositionIdentifier but no position
/// repeated, stay one 3-D series, as before.
#[test]
fn a_4d_series_of_single_frame_files_reads_the_phase_asked_for() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/volumes/dicom/abdomen_ct_j2k_totalseg");
    let first = series();
    let second = Volume {
        data: first.data.iter().map(|v| v + 100.0).collect(),
        ..first.clone()
    };
    let scratch = crate::tests::scratch_dir("4d");
    let dir = scratch.path().to_path_buf();
    let flat = dir.join("3d");
    std::fs::create_dir_all(&flat).unwrap();
    let mut names: Vec<_> = std::fs::read_dir(&src)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    for (k, file) in names.iter().enumerate() {
        let name = file.file_name().unwrap().to_str().unwrap();
        for (t, to) in [
            (1, dir.join(format!("b{name}"))),
            (2, dir.join(format!("a{name}"))),
            (k + 1, flat.join(name)),
        ] {
            let mut obj = dicom_object::open_file(file).unwrap();
            let intercept = obj
                .element(tags::RESCALE_INTERCEPT)
                .unwrap()
                .to_float64()
                .unwrap();
            let shift = if to.parent() == Some(&dir) && t == 2 {
                100.0
            } else {
                0.0
            };
            obj.put(decimals(tags::RESCALE_INTERCEPT, &[intercept + shift]));
            obj.put(text(
                tags::TEMPORAL_POSITION_IDENTIFIER,
                VR::IS,
                &t.to_string(),
            ));
            obj.write_to_file(&to).unwrap();
        }
    }
    let read = |phase| {
        load_volume(
            &dir,
            &VolumeSelect {
                series: None,
                phase,
            },
        )
    };
    let got = read(None).unwrap();
    assert_same(&got, &first, "phase 1");
    assert_eq!(got.phase, Phase { index: 1, count: 2 });
    assert!(
        got.warnings
            .iter()
            .any(|w| w.contains("2 temporal positions")),
        "{:?}",
        got.warnings
    );
    let got = read(Some(2)).unwrap();
    assert_same(&got, &second, "phase 2");
    assert_eq!(got.phase, Phase { index: 2, count: 2 });
    assert_eq!(got.series.as_ref().unwrap().count, 20);
    let e = read(Some(3)).unwrap_err().to_string();
    assert!(e.contains("phase 3 requested, but the image has 2"), "{e}");
    let got = load_volume(&flat, &Default::default()).unwrap();
    assert_same(&got, &first, "3-D");
    assert_eq!(got.phase, Phase::default());
}

#[test]
fn a_broken_enhanced_ct_is_an_error_naming_the_file_and_frame() {
    let v = series();
    for (name, layout, says) in [
        (
            "count.dcm",
            Layout {
                wrong_count: true,
                ..Default::default()
            },
            "NumberOfFrames is 21 but the per-frame functional groups sequence has 20 items",
        ),
        (
            "position.dcm",
            Layout {
                no_position: true,
                ..Default::default()
            },
            "ImagePositionPatient (0020,0032) in frame 3",
        ),
    ] {
        let file = write_enhanced(&v, layout, name);
        let e = load_volume(&file, &Default::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with(file.to_str().unwrap()) && e.contains(says),
            "{e}"
        );
    }
}

/// A 16×12×4 corner of the series as enhanced CT files, plain and JPEG-LS split by an offset
/// table, cut short and bit-flipped: every result is frames or an error naming the file,
/// never a panic.
#[test]
fn damaged_enhanced_ct_files_are_errors_never_panics() {
    let v = series();
    let (nx, ny, nz) = (16, 12, 4);
    let mut data = Vec::with_capacity(nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            let at = 256 + 512 * (200 + j) + 512 * 512 * k;
            data.extend_from_slice(&v.data[at..at + nx]);
        }
    }
    let small = Volume {
        dims: [nx, ny, nz],
        data,
        series: None,
        warnings: Vec::new(),
        ..v
    };
    for (name, layout) in [
        ("tiny.dcm", Layout::default()),
        (
            "tiny-ls.dcm",
            Layout {
                jpeg_ls: true,
                split: true,
                ..Default::default()
            },
        ),
    ] {
        let file = write_enhanced(&small, layout, name);
        let bytes = std::fs::read(&file).unwrap();
        let path = Path::new("mf.dcm");
        let decode = |b: &[u8]| -> Result<usize, VolumeError> {
            let mut slices = dicom::parse_file(b, path)?;
            let n = (slices[0].rows * slices[0].cols) as usize;
            Ok(dicom::decode_frames(&mut slices[0], n, None)?.len())
        };
        assert_eq!(decode(&bytes).unwrap(), nz, "{name}");
        let mut errors = 0;
        let mut check = |b: &[u8]| {
            if let Err(e) = decode(b) {
                assert!(e.to_string().starts_with("mf.dcm"), "{name}: {e}");
                errors += 1;
            }
        };
        for cut in (0..bytes.len()).step_by(7) {
            check(&bytes[..cut]);
        }
        for at in 0..bytes.len() {
            let mut b = bytes.clone();
            b[at] ^= 1 << (at % 8);
            check(&b);
        }
        assert!(errors > bytes.len() / 7, "{name}: only {errors} errors");
    }
}
