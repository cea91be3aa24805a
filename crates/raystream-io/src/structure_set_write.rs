//! A label volume written as a DICOM RT Structure Set (SOP class 1.2.840.10008.5.1.4.1.1.481.3),
//! the form a radiotherapy planning system imports structures in: each segment a structure
//! (ROI), each of its slices' regions a closed planar contour in the patient's millimetres,
//! on the CT series it was made from (its patient, study, Frame of Reference, and each contour
//! referencing its slice's image). Written through dicom-rs (`dicom-object`), the modules
//! assembled here (PS3.3 A.19, C.8.8), as for the Segmentation.
//!
//! The contours run along the voxels' edges, half a voxel from the centres of the voxels on
//! either side (a region's boundary traced edge by edge, a hole's too, pieces that touch only at
//! a corner kept apart), so that a voxel's centre lies inside them exactly when the voxel is the
//! segment's: laid back on the CT by the centre rule (the reader's), they give back the labels
//! voxel for voxel, and each slice's polygons enclose its voxels' area.

use std::collections::HashMap;
use std::path::Path;

use dicom_core::{DataElement, PrimitiveValue, VR};
use dicom_dictionary_std::tags;

use crate::secondary_capture::{Derived, decimals, derived_object, put, truncate, write_dicom};
use crate::segmentation::{
    Segment, SegmentationInfo, item, labels_fit, reference, segmentation_source, seq, text,
};
use crate::volume::{RT_STRUCTURE_SET, SourceImage, Volume, VolumeError};

/// What was written: each structure's contours and voxels.
#[derive(Clone, Debug, PartialEq)]
pub struct StructureSetWritten {
    pub contours: Vec<usize>,
    pub voxels: Vec<usize>,
    pub sop_instance_uid: String,
}

/// The closed loops along the edges of the pixels of a `nx`×`ny` slice for which `inside` is
/// true, as corner points (corner (x, y) is the pixel corner at index (x − ½, y − ½)), each
/// loop's corners where it turns. Each pixel's boundary runs A(x,y) → B(x+1,y) → C(x+1,y+1) →
/// D(x,y+1); at a corner where two loops meet (pixels touching only there), a loop turns the
/// way that keeps to its own pixel.
pub fn pixel_loops(
    nx: usize,
    ny: usize,
    inside: impl Fn(usize, usize) -> bool,
) -> Vec<Vec<[i64; 2]>> {
    let held = |x: i64, y: i64| {
        x >= 0 && y >= 0 && (x as usize) < nx && (y as usize) < ny && inside(x as usize, y as usize)
    };
    // Each corner's outgoing edges (directions), two at most.
    let mut out: HashMap<[i64; 2], Vec<[i64; 2]>> = HashMap::new();
    for y in 0..ny as i64 {
        for x in 0..nx as i64 {
            if !held(x, y) {
                continue;
            }
            for (neighbour, from, dir) in [
                ((x, y - 1), [x, y], [1, 0]),
                ((x + 1, y), [x + 1, y], [0, 1]),
                ((x, y + 1), [x + 1, y + 1], [-1, 0]),
                ((x - 1, y), [x, y + 1], [0, -1]),
            ] {
                if !held(neighbour.0, neighbour.1) {
                    out.entry(from).or_default().push(dir);
                }
            }
        }
    }
    let mut starts: Vec<[i64; 2]> = out.keys().copied().collect();
    starts.sort_unstable_by_key(|c| (c[1], c[0]));
    let mut loops = Vec::new();
    for start in starts {
        while let Some(first) = out.get_mut(&start).and_then(|d| d.pop()) {
            let mut corners = vec![start];
            let (mut at, mut dir) = ([start[0] + first[0], start[1] + first[1]], first);
            loop {
                // Keep to the pixel: turn with the boundary's own sense, (dx, dy) → (−dy, dx);
                // back at the start, the loop closes unless that turn is still to take.
                let turn = [-dir[1], dir[0]];
                let dirs = out.get_mut(&at).filter(|d| !d.is_empty());
                if at == start && !dirs.as_ref().is_some_and(|d| d.contains(&turn)) {
                    break;
                }
                let dirs = dirs.expect("a boundary corner has an edge out for each edge in");
                let pick = dirs.iter().position(|&d| d == turn).unwrap_or(0);
                let next = dirs.swap_remove(pick);
                if next != dir {
                    corners.push(at);
                }
                dir = next;
                at = [at[0] + dir[0], at[1] + dir[1]];
            }
            // The start is a corner of the loop unless the loop runs straight through it.
            if dir == first {
                corners.remove(0);
            }
            loops.push(corners);
        }
    }
    loops
}

/// Why an RT Structure Set of `like` cannot be written, if it cannot: as for a Segmentation
/// ([`segmentation_source`]), it references the series' images, so `like` must be a DICOM
/// series whose slices are its acquired images, with its UIDs.
pub fn structure_set_source(like: &Volume) -> Result<(), String> {
    segmentation_source(like).map_err(|e| {
        e.replace("a DICOM Segmentation", "an RT Structure Set")
            .replace(
                "write a NIfTI label map, .nii.gz, instead",
                "a NIfTI label map, .nii.gz, can hold the labels instead",
            )
    })
}

/// Writes `labels` (one a voxel of `like`, i fastest, as [`Volume::data`]) to `path` as an RT
/// Structure Set of `like`'s series, a structure each of `segments` (its value, label and
/// colour), if the series can be referenced ([`structure_set_source`]).
pub fn write_structure_set(
    path: &Path,
    like: &Volume,
    labels: &[u8],
    segments: &[Segment],
    info: &SegmentationInfo,
) -> Result<StructureSetWritten, VolumeError> {
    let fail = |e: &dyn std::fmt::Display| {
        VolumeError::invalid(path, format!("cannot write a DICOM RT Structure Set: {e}"))
    };
    let [nx, ny, nz] = like.dims;
    labels_fit(like, labels).map_err(|e| fail(&e))?;
    if segments.is_empty() {
        return Err(fail(&"no structure to write"));
    }
    structure_set_source(like).map_err(|e| fail(&e))?;
    let series = like
        .series
        .as_ref()
        .expect("checked by structure_set_source");
    let study = &series.study;
    let frame = &study.frame_of_reference_uid;
    let image_ref = |s: &SourceImage| item(reference(s, true));
    // Each structure's contours, slice by slice.
    let per = nx * ny;
    let mut contours = vec![0usize; segments.len()];
    let mut voxels = vec![0usize; segments.len()];
    let mut roi_contours = Vec::new();
    for (s, seg) in segments.iter().enumerate() {
        let mut items = Vec::new();
        for k in 0..nz {
            let slice = &labels[k * per..(k + 1) * per];
            let n = slice.iter().filter(|&&l| l == seg.value).count();
            if n == 0 {
                continue;
            }
            voxels[s] += n;
            for corners in pixel_loops(nx, ny, |i, j| slice[i + nx * j] == seg.value) {
                let points: Vec<f64> = corners
                    .iter()
                    .flat_map(|c| {
                        let p = raystream_math::DVec3::new(
                            c[0] as f64 - 0.5,
                            c[1] as f64 - 0.5,
                            k as f64,
                        );
                        like.index_to_world(p).to_array()
                    })
                    .collect();
                items.push(item(vec![
                    seq(
                        tags::CONTOUR_IMAGE_SEQUENCE,
                        vec![image_ref(&series.sources[k])],
                    ),
                    text(tags::CONTOUR_GEOMETRIC_TYPE, VR::CS, "CLOSED_PLANAR"),
                    text(
                        tags::NUMBER_OF_CONTOUR_POINTS,
                        VR::IS,
                        &corners.len().to_string(),
                    ),
                    text(tags::CONTOUR_DATA, VR::DS, &decimals(&points)),
                ]));
                contours[s] += 1;
            }
        }
        let colour = seg.colour.map(|c| c.to_string()).join("\\");
        roi_contours.push(item(vec![
            text(tags::ROI_DISPLAY_COLOR, VR::IS, &colour),
            seq(tags::CONTOUR_SEQUENCE, items),
            text(tags::REFERENCED_ROI_NUMBER, VR::IS, &(s + 1).to_string()),
        ]));
    }
    if voxels.iter().all(|&n| n == 0) {
        return Err(fail(&"no voxel holds any of the structures' labels"));
    }
    // Patient and General Study (the series'), RT Series, General Equipment.
    let Derived {
        mut obj,
        sop_uid,
        date,
        time,
        ..
    } = derived_object(
        study,
        RT_STRUCTURE_SET,
        ("RTSTRUCT", "9003"),
        info.description,
        info.version,
    );
    let o = &mut obj;
    put(o, tags::OPERATORS_NAME, VR::PN, "");
    put(o, tags::FRAME_OF_REFERENCE_UID, VR::UI, frame);
    put(o, tags::POSITION_REFERENCE_INDICATOR, VR::LO, "");
    // Structure Set: what it was drawn on, every image of the series.
    put(o, tags::INSTANCE_NUMBER, VR::IS, "1");
    // A short label (16 characters): the algorithm's name, or its first word.
    let label = if info.algorithm.chars().count() <= 16 {
        info.algorithm
    } else {
        info.algorithm.split_whitespace().next().unwrap_or("")
    };
    put(o, tags::STRUCTURE_SET_LABEL, VR::SH, &truncate(label, 16));
    put(
        o,
        tags::STRUCTURE_SET_NAME,
        VR::LO,
        &truncate(info.description, 64),
    );
    put(o, tags::STRUCTURE_SET_DATE, VR::DA, &date);
    put(o, tags::STRUCTURE_SET_TIME, VR::TM, &time);
    let mut images: Vec<&SourceImage> = Vec::new();
    for s in &series.sources {
        if !images
            .iter()
            .any(|i| i.sop_instance_uid == s.sop_instance_uid && i.frame == s.frame)
        {
            images.push(s);
        }
    }
    o.put(seq(
        tags::REFERENCED_FRAME_OF_REFERENCE_SEQUENCE,
        vec![item(vec![
            text(tags::FRAME_OF_REFERENCE_UID, VR::UI, frame),
            seq(
                tags::RT_REFERENCED_STUDY_SEQUENCE,
                vec![item(vec![
                    // Study Component Management, as planning systems reference a study.
                    text(
                        tags::REFERENCED_SOP_CLASS_UID,
                        VR::UI,
                        "1.2.840.10008.3.1.2.3.2",
                    ),
                    text(tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, &study.study_uid),
                    seq(
                        tags::RT_REFERENCED_SERIES_SEQUENCE,
                        vec![item(vec![
                            text(tags::SERIES_INSTANCE_UID, VR::UI, &series.uid),
                            seq(
                                tags::CONTOUR_IMAGE_SEQUENCE,
                                images.iter().map(|s| image_ref(s)).collect(),
                            ),
                        ])],
                    ),
                ])],
            ),
        ])],
    ));
    o.put(seq(
        tags::STRUCTURE_SET_ROI_SEQUENCE,
        segments
            .iter()
            .enumerate()
            .map(|(s, seg)| {
                item(vec![
                    text(tags::ROI_NUMBER, VR::IS, &(s + 1).to_string()),
                    text(tags::REFERENCED_FRAME_OF_REFERENCE_UID, VR::UI, frame),
                    text(tags::ROI_NAME, VR::LO, &truncate(seg.label, 64)),
                    text(
                        tags::ROI_DESCRIPTION,
                        VR::ST,
                        &truncate(seg.description, 1024),
                    ),
                    text(tags::ROI_GENERATION_ALGORITHM, VR::CS, "AUTOMATIC"),
                ])
            })
            .collect(),
    ));
    // ROI Contour, RT ROI Observations.
    o.put(seq(tags::ROI_CONTOUR_SEQUENCE, roi_contours));
    o.put(seq(
        tags::RTROI_OBSERVATIONS_SEQUENCE,
        (segments.iter().enumerate())
            .map(|(s, seg)| {
                let number = (s + 1).to_string();
                item(vec![
                    text(tags::OBSERVATION_NUMBER, VR::IS, &number),
                    text(tags::REFERENCED_ROI_NUMBER, VR::IS, &number),
                    text(tags::RTROI_INTERPRETED_TYPE, VR::CS, seg.rt_type),
                    DataElement::new(tags::ROI_INTERPRETER, VR::PN, PrimitiveValue::Empty),
                ])
            })
            .collect(),
    ));
    write_dicom(obj, path, RT_STRUCTURE_SET, &sop_uid).map_err(|e| fail(&e))?;
    Ok(StructureSetWritten {
        contours,
        voxels,
        sop_instance_uid: sop_uid,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: whether (x, y) lies inside the loops by the even-odd rule.
    fn inside(loops: &[Vec<[i64; 2]>], x: f64, y: f64) -> bool {
        let mut odd = false;
        for l in loops {
            for (n, a) in l.iter().enumerate() {
                let b = l[(n + 1) % l.len()];
                let (ax, ay, bx, by) = (
                    a[0] as f64 - 0.5,
                    a[1] as f64 - 0.5,
                    b[0] as f64 - 0.5,
                    b[1] as f64 - 0.5,
                );
                if (ay <= y) != (by <= y) && ax + (y - ay) * (bx - ax) / (by - ay) <= x {
                    odd = !odd;
                }
            }
        }
        odd
    }

    /// Twice the loop's signed area (positive for a pixel's own turning, A → B → C → D).
    fn twice_area(l: &[[i64; 2]]) -> i64 {
        (0..l.len())
            .map(|n| {
                let (a, b) = (l[n], l[(n + 1) % l.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum()
    }

    #[test]
    fn loops_hold_exactly_their_pixels() {
        // A ring with a hole, two pixels touching at a corner, a lone pixel at the edge, and
        // random fields.
        let mut fields: Vec<(usize, usize, Vec<bool>)> = Vec::new();
        let ring: Vec<bool> = (0..49)
            .map(|n| {
                let (x, y) = (n % 7, n / 7);
                (1..=5).contains(&x) && (1..=5).contains(&y) && !(x == 3 && y == 3)
            })
            .collect();
        fields.push((7, 7, ring));
        fields.push((
            3,
            3,
            vec![true, false, false, false, true, false, false, false, true],
        ));
        fields.push((
            4,
            2,
            vec![true, false, false, false, false, false, false, true],
        ));
        let mut seed = 12345u64;
        for _ in 0..200 {
            let (w, h) = (1 + (seed % 9) as usize, 1 + ((seed >> 8) % 9) as usize);
            let cells = (0..w * h)
                .map(|_| {
                    seed = seed
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (seed >> 33).is_multiple_of(3)
                })
                .collect();
            fields.push((w, h, cells));
        }
        for (w, h, cells) in fields {
            let loops = pixel_loops(w, h, |x, y| cells[x + w * y]);
            let area: i64 = loops.iter().map(|l| twice_area(l).abs()).sum();
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(
                        inside(&loops, x as f64, y as f64),
                        cells[x + w * y],
                        "{w}×{h} {cells:?}: pixel ({x}, {y}), loops {loops:?}"
                    );
                }
            }
            // Each loop turns at every corner it keeps, and together (holes subtracted by
            // their opposite turning) they enclose the pixels' area.
            for l in &loops {
                assert!(l.len() >= 4, "{l:?}");
            }
            let signed: i64 = loops.iter().map(|l| twice_area(l)).sum();
            let count = cells.iter().filter(|&&c| c).count() as i64;
            assert_eq!(signed, 2 * count, "{w}×{h} {cells:?}: {loops:?}");
            assert!(area >= 2 * count);
        }
    }
}
