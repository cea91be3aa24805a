//! A DICOM Segmentation (SOP class 1.2.840.10008.5.1.4.1.1.66.4, as `measure --mask FILE.dcm`
//! writes it, or another tool) read as a label volume: each voxel the number of the segment
//! that holds it, 0 where none does, on the grid its frames lie on (the frames' common
//! orientation and pixel spacing; slices from the first frame's plane to the last's, as far
//! apart as the Segmentation says, or as its frames' nearest planes lie, stacked along the
//! line through them: a gantry-tilted CT's Segmentation on its sheared grid). BINARY segments
//! (one bit a pixel) and FRACTIONAL ones (8 bits; a voxel held where the fraction reaches half
//! the maximum), and DICOM 2024's LABELMAP Segmentations (SOP class …66.7: a frame a slice,
//! each pixel its segment's number, 8 or 16 bits). Native pixel data, and for FRACTIONAL and
//! LABELMAP ones compressed frames too (RLE, JPEG-LS, JPEG 2000: the CT reader's decoders).

use std::path::Path;

use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;

use super::dicom::{
    DicomStudy, FileMeta, FrameGeometry, cross, dot, functional_groups, sub, text_of,
    transfer_syntax_name,
};
use super::structure_set::gather_whole;
use super::{DicomSeriesInfo, Phase, SegmentLabel, ValueUnit, Volume, VolumeError, VolumeFormat};
use super::{check_geometry, voxel_count};

const SEGMENTATION: &str = "1.2.840.10008.5.1.4.1.1.66.4";
/// Label Map Segmentation Storage (DICOM 2024): a frame a slice, each pixel its segment.
const LABEL_MAP_SEGMENTATION: &str = "1.2.840.10008.5.1.4.1.1.66.7";

/// How a Segmentation's pixels say which segment holds them.
#[derive(Clone, Copy)]
enum Pixels {
    /// One bit a pixel: its frame's segment, or none.
    Binary,
    /// 8 bits: its frame's segment from this fraction (half the maximum) on.
    Fractional(u8),
    /// 8 or 16 bits (this many bytes): the segment's number itself, 0 none.
    LabelMap(usize),
}

/// Whether the data set is a DICOM Segmentation.
pub(crate) fn is_segmentation(meta: &FileMeta, obj: &InMemDicomObject) -> bool {
    let class = meta.sop_class_of(obj);
    class == SEGMENTATION || class == LABEL_MAP_SEGMENTATION
}

/// The Segmentation in `obj` (read from `file`) as a label volume.
pub(crate) fn read(
    file: &Path,
    meta: &FileMeta,
    obj: &InMemDicomObject,
) -> Result<Volume, VolumeError> {
    read_segments(file, meta, obj, false).map(|(v, _)| v)
}

/// The Segmentation in `obj` (read from `file`) as a label volume, and with `whole` each
/// segment's voxels whole too (BINARY and FRACTIONAL segments may overlap, which the label
/// volume cannot hold: there each voxel takes the last frame's segment).
pub(crate) fn read_segments(
    file: &Path,
    meta: &FileMeta,
    obj: &InMemDicomObject,
    whole: bool,
) -> Result<(Volume, super::WholeSegments), VolumeError> {
    let bad =
        |problem: String| VolumeError::invalid(file, format!("DICOM Segmentation: {problem}"));
    let text = text_of;
    let int = |o: &InMemDicomObject, tag| o.get(tag).and_then(|e| e.to_int::<u32>().ok());
    let need = |tag, what: &str| int(obj, tag).ok_or_else(|| bad(format!("no {what}")));
    let rows = need(tags::ROWS, "Rows")? as usize;
    let cols = need(tags::COLUMNS, "Columns")? as usize;
    let frames = need(tags::NUMBER_OF_FRAMES, "Number of Frames")? as usize;
    let bits = need(tags::BITS_ALLOCATED, "Bits Allocated")?;
    let kind = text(obj, tags::SEGMENTATION_TYPE);
    let mut kind = match (kind.as_str(), bits) {
        ("BINARY", 1) => Pixels::Binary,
        ("FRACTIONAL", 8) => {
            let max = int(obj, tags::MAXIMUM_FRACTIONAL_VALUE)
                .unwrap_or(255)
                .clamp(1, 255);
            Pixels::Fractional(max.div_ceil(2) as u8)
        }
        ("LABELMAP", 8 | 16) => Pixels::LabelMap(bits as usize / 8),
        _ => {
            return Err(bad(format!(
                "segmentation type {kind:?} with {bits} bits a pixel (BINARY with 1, FRACTIONAL with 8, LABELMAP with 8 or 16 are read)"
            )));
        }
    };
    if rows == 0 || cols == 0 || frames == 0 {
        return Err(bad(format!("{cols}×{rows} pixels, {frames} frames")));
    }
    let per = rows
        .checked_mul(cols)
        .ok_or_else(|| bad("a frame too large".into()))?;
    // Native pixel data (the data set deflated or not), or compressed frames decoded to it.
    let native = matches!(
        meta.ts_uid.as_str(),
        "1.2.840.10008.1.2" | "1.2.840.10008.1.2.1" | "1.2.840.10008.1.2.1.99"
    );
    let pixels = if native {
        obj.get(tags::PIXEL_DATA)
            .ok_or_else(|| bad("no pixel data (7FE0,0010)".into()))?
            .to_bytes()
            .map_err(|e| bad(format!("pixel data: {e}")))?
    } else {
        if (per as u64).saturating_mul(frames as u64) > super::MAX_VOXELS {
            return Err(bad(format!(
                "{frames} frames of {cols}×{rows}: over {} pixels",
                super::MAX_VOXELS
            )));
        }
        let mut encoded = obj.clone();
        if matches!(kind, Pixels::Binary) {
            // A BINARY frame is compressed as one 1-bit sample a pixel: decoded into bytes.
            encoded.put(dicom_core::DataElement::new(
                tags::BITS_ALLOCATED,
                dicom_core::VR::US,
                dicom_core::PrimitiveValue::from(8u16),
            ));
        }
        let decoded = super::dicom::decode_encapsulated(
            file,
            &meta.ts_uid,
            encoded,
            (cols as u32, rows as u32, frames),
        )?;
        let wide = matches!(kind, Pixels::LabelMap(2));
        let mut bytes = Vec::with_capacity(per * frames * if wide { 2 } else { 1 });
        for v in decoded.iter().flatten() {
            if wide {
                bytes.extend_from_slice(&(*v as u16).to_le_bytes());
            } else {
                bytes.push(*v as u8);
            }
        }
        // A compressed BINARY frame decodes to a sample a pixel, 0 or 1, not to packed bits.
        if matches!(kind, Pixels::Binary) {
            kind = Pixels::Fractional(1);
        }
        std::borrow::Cow::Owned(bytes)
    };
    let want = per
        .checked_mul(frames)
        .and_then(|n| match kind {
            Pixels::Binary => Some(n.div_ceil(8)),
            Pixels::Fractional(_) => Some(n),
            Pixels::LabelMap(bytes) => n.checked_mul(bytes),
        })
        .ok_or_else(|| bad("too many pixels".into()))?;
    if pixels.len() < want {
        return Err(bad(format!(
            "{frames} frames of {cols}×{rows} need {want} bytes of pixel data; it holds {}",
            pixels.len()
        )));
    }
    let (per_frame, shared) = functional_groups(obj, frames).map_err(bad)?;
    let segments: Vec<SegmentLabel> = obj
        .get(tags::SEGMENT_SEQUENCE)
        .and_then(|e| e.items())
        .map(|items| {
            items
                .iter()
                .filter_map(|s| {
                    let number = int(s, tags::SEGMENT_NUMBER)? as u16;
                    let colour = s
                        .get(tags::RECOMMENDED_DISPLAY_CIE_LAB_VALUE)
                        .and_then(|e| e.to_multi_int::<u16>().ok())
                        .and_then(|v| <[u16; 3]>::try_from(v).ok())
                        .map(crate::srgb_from_cielab);
                    let code = crate::measurement_report::code_of;
                    let kind_item = s
                        .get(tags::SEGMENTED_PROPERTY_TYPE_CODE_SEQUENCE)
                        .and_then(|e| e.items())
                        .and_then(|i| i.first());
                    // Modifiers sit in the item of the code they modify.
                    let region_item = s
                        .get(tags::ANATOMIC_REGION_SEQUENCE)
                        .and_then(|e| e.items())
                        .and_then(|i| i.first());
                    Some(SegmentLabel {
                        number,
                        label: text(s, tags::SEGMENT_LABEL),
                        colour,
                        terms: crate::SegmentTerms {
                            category: code(s, tags::SEGMENTED_PROPERTY_CATEGORY_CODE_SEQUENCE),
                            kind: code(s, tags::SEGMENTED_PROPERTY_TYPE_CODE_SEQUENCE),
                            modifier: kind_item.and_then(|k| {
                                code(k, tags::SEGMENTED_PROPERTY_TYPE_MODIFIER_CODE_SEQUENCE)
                            }),
                            region: code(s, tags::ANATOMIC_REGION_SEQUENCE),
                            region_modifier: region_item
                                .and_then(|r| code(r, tags::ANATOMIC_REGION_MODIFIER_SEQUENCE)),
                        },
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    // Each frame's plane and segment.
    let mut planes = Vec::with_capacity(frames);
    for (f, item) in per_frame.iter().enumerate() {
        let groups: Vec<&InMemDicomObject> = [Some(item), shared].into_iter().flatten().collect();
        let g = FrameGeometry::of(&groups, Some(obj));
        // A label map's pixels name their segments; a binary or fractional frame is one's.
        let segment = match kind {
            Pixels::LabelMap(_) => 0,
            _ => groups
                .iter()
                .find_map(|g| {
                    let id = g
                        .get(tags::SEGMENT_IDENTIFICATION_SEQUENCE)?
                        .items()?
                        .first()?;
                    int(id, tags::REFERENCED_SEGMENT_NUMBER)
                })
                .ok_or_else(|| bad(format!("frame {} names no segment", f + 1)))?,
        };
        if !matches!(kind, Pixels::LabelMap(_)) && !(1..=65535).contains(&segment) {
            return Err(bad(format!("frame {} names segment {segment}", f + 1)));
        }
        let missing = |what: &str| bad(format!("frame {} has no {what}", f + 1));
        planes.push((
            g.position
                .ok_or_else(|| missing("Image Position (Patient)"))?,
            g.orientation
                .ok_or_else(|| missing("Image Orientation (Patient)"))?,
            g.pixel_spacing.ok_or_else(|| missing("Pixel Spacing"))?,
            segment as u16,
            g.between_slices.or(g.thickness),
        ));
    }
    let (p0, o, pixel, _, between) = planes[0];
    for (f, &(_, of, ps, _, _)) in planes.iter().enumerate() {
        if (0..6).any(|i| (of[i] - o[i]).abs() > 1e-4)
            || (0..2).any(|i| (ps[i] - pixel[i]).abs() > 1e-4)
        {
            return Err(bad(format!(
                "frame {} is turned or sized otherwise than frame 1: its frames are not one stack",
                f + 1
            )));
        }
    }
    let (row, col) = ([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
    let normal = cross(row, col);
    let len = dot(normal, normal).sqrt();
    if !(0.99..=1.01).contains(&len) || dot(row, col).abs() > 1e-3 {
        return Err(bad(format!(
            "Image Orientation (Patient) {o:?} is not two orthogonal unit vectors"
        )));
    }
    let normal = normal.map(|v| v / len);
    // The frames' distances along the normal, and the slices' spacing.
    let along: Vec<f64> = planes.iter().map(|p| dot(sub(p.0, p0), normal)).collect();
    let mut distinct: Vec<f64> = along.clone();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup_by(|a, b| (*a - *b).abs() < 1e-3);
    let gap = distinct
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let spacing = between
        .filter(|&s| s > 1e-3)
        .or(gap.is_finite().then_some(gap))
        .unwrap_or(1.0);
    let first = distinct[0];
    let span = distinct[distinct.len() - 1] - first;
    let nz = (span / spacing).round() as usize + 1;
    let dims = [cols, rows, nz];
    voxel_count(file, dims)?;
    // The line the frames are stacked on, from the nearest to the farthest along the normal:
    // the normal, or the table's path of a gantry-tilted series (a sheared grid, as its CT's).
    let by = |key: fn(f64, f64) -> bool| {
        (0..frames)
            .reduce(|a, b| if key(along[b], along[a]) { b } else { a })
            .expect("a frame or more")
    };
    let (near, far) = (by(|x, y| x < y), by(|x, y| x > y));
    let origin = planes[near].0;
    let axis = if span > 1e-3 {
        let line = sub(planes[far].0, origin);
        let line = line.map(|v| v / dot(line, line).sqrt());
        let tilt = dot(line, normal).clamp(-1.0, 1.0).acos().to_degrees();
        if tilt > 45.0 {
            return Err(bad(format!(
                "its frames are stacked {tilt:.1}° off their normal: not one stack"
            )));
        }
        if tilt > 0.05 { line } else { normal }
    } else {
        normal
    };
    let step = spacing / dot(axis, normal);
    // Every frame on a slice of that grid, in its plane's place.
    let mut slice_of = Vec::with_capacity(frames);
    for (f, (&d, p)) in along.iter().zip(&planes).enumerate() {
        let k = (d - first) / spacing;
        let off = sub(sub(p.0, origin), axis.map(|v| v * k.round() * step));
        let tol = 0.1 * pixel[0].min(pixel[1]);
        if (k - k.round()).abs() > 0.1 || dot(off, off).sqrt() > tol {
            return Err(bad(format!(
                "frame {} lies off the grid of its frames ({spacing:.3} mm apart along their normal)",
                f + 1
            )));
        }
        slice_of.push(k.round() as usize);
    }
    // The segment that holds pixel `p` of frame `f`, if any.
    let held = |f: usize, p: usize| -> Option<u16> {
        let b = f * per + p;
        let (held, label) = match kind {
            Pixels::Binary => (pixels[b / 8] >> (b % 8) & 1 == 1, planes[f].3),
            Pixels::Fractional(h) => (pixels[b] >= h, planes[f].3),
            Pixels::LabelMap(1) => (pixels[b] > 0, pixels[b] as u16),
            Pixels::LabelMap(_) => {
                let l = u16::from_le_bytes([pixels[2 * b], pixels[2 * b + 1]]);
                (l > 0, l)
            }
        };
        held.then_some(label)
    };
    let mut data = vec![0f32; cols * rows * nz];
    let mut overlap = 0usize;
    for (f, &k) in slice_of.iter().enumerate() {
        let out = &mut data[k * per..(k + 1) * per];
        for (p, v) in out.iter_mut().enumerate() {
            let Some(label) = held(f, p) else { continue };
            let label = label as f32;
            if *v != 0.0 && *v != label {
                overlap += 1;
            }
            *v = label;
        }
    }
    let whole_segments = if whole {
        gather_whole(|add| {
            for (f, &k) in slice_of.iter().enumerate() {
                for p in 0..per {
                    if let Some(label) = held(f, p) {
                        add(label, [p % cols, p / cols, k]);
                    }
                }
            }
        })
    } else {
        Vec::new()
    };
    let spacing3 = [pixel[1], pixel[0], step];
    let direction = std::array::from_fn(|r| [row[r], col[r], axis[r]]);
    check_geometry(file, dims, spacing3, origin, &direction)?;
    let mut warnings = Vec::new();
    if overlap > 0 {
        warnings.push(format!(
            "{overlap} voxels are held by more than one segment; the label volume holds the last frame's there (iso --segment, render --outline and info take each segment whole)"
        ));
    }
    let volume = Volume {
        dims,
        spacing: spacing3,
        origin,
        direction,
        data,
        unit: ValueUnit::Unknown,
        format: VolumeFormat::Dicom,
        series: Some(DicomSeriesInfo {
            uid: text(obj, tags::SERIES_INSTANCE_UID),
            description: text(obj, tags::SERIES_DESCRIPTION),
            modality: text(obj, tags::MODALITY),
            count: frames,
            transfer_syntax: meta.ts_uid.clone(),
            transfer_syntax_name: transfer_syntax_name(&meta.ts_uid),
            all: Vec::new(),
            study: DicomStudy::of(obj),
            sources: Vec::new(),
        }),
        segments,
        phase: Phase::default(),
        warnings,
    };
    Ok((volume, whole_segments))
}
