//! 3D Slicer segmentations (`.seg.nrrd`): a NRRD label map whose `SegmentN_*` key/value
//! fields name each segment, its colour, and the label value that marks its voxels on its
//! layer. Segments that do not overlap share one 3-D layer; overlapping ones lie on the layers
//! of a 4-D file's first (`list`) axis. Files of Slicer before 4.11 give no label values:
//! each segment then has a layer of its own, its voxels 1.
//!
//! Written here: no crate on crates.io reads them (`cargo search slicer`: none), and the
//! fields are a few lines of text on top of the NRRD reader. The layout is the one Slicer's
//! developer guide ("Segmentation labelmap file format") gives, and `slicerio`, Slicer's own
//! Python reader and writer, follows; the tests read files both wrote.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::structure_set::gather_whole;
use super::{SegmentLabel, VolumeError, WholeSegments};

/// One segment as the header describes it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SlicerSegment {
    pub name: String,
    pub colour: Option<[u8; 3]>,
    /// The value that marks its voxels on its layer (≥ 1).
    pub label_value: u32,
    pub layer: usize,
    /// Its category, type, type modifier, anatomic region and region modifier from its
    /// `TerminologyEntry` tag.
    pub terms: crate::SegmentTerms,
}

/// The category, type and type modifier, and the anatomic region and its modifier, of a `Tags`
/// field's `TerminologyEntry` (tags are
/// `key:value` pairs between `|`; the entry's parts lie between `~`: the context's name, the
/// category, the type, the type modifier, then the anatomic context, region and modifier; a
/// code is `scheme^value^meaning`, `^^` where none is given).
fn terms(tags: &str) -> crate::SegmentTerms {
    let Some(entry) = tags
        .split('|')
        .find_map(|t| t.trim().strip_prefix("TerminologyEntry:"))
    else {
        return crate::SegmentTerms::default();
    };
    let parts: Vec<&str> = entry.split('~').collect();
    let code = |k: usize| {
        let mut c = parts.get(k)?.splitn(3, '^');
        let (scheme, value, meaning) = (c.next()?, c.next()?, c.next()?);
        (!value.is_empty()).then(|| crate::ReadCode {
            value: value.to_string(),
            scheme: scheme.to_string(),
            meaning: meaning.to_string(),
        })
    };
    crate::SegmentTerms {
        category: code(1),
        kind: code(2),
        modifier: code(3),
        region: code(5),
        // A modifier of no region modifies nothing (slicerio drops it too).
        region_modifier: code(5).and(code(6)),
    }
}

/// The segments the `SegmentN_*` fields of `fields` (a header's `key:=value` pairs) describe,
/// in the order of N; `None` where it describes none (a plain NRRD). `layers`: the layers the
/// file holds (1 for a 3-D one). A segment's layer or label value that is not a number, or a
/// layer the file lacks, is an error; a colour that is not three numbers from 0 to 1 is left
/// out with a warning.
pub(crate) fn segments(
    fields: &[(String, String)],
    layers: usize,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<Option<Vec<SlicerSegment>>, VolumeError> {
    let mut by_index: BTreeMap<usize, HashMap<&str, &str>> = BTreeMap::new();
    for (k, v) in fields {
        let Some(rest) = k.strip_prefix("Segment") else {
            continue;
        };
        let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
        let (Ok(n), Some(field)) = (
            rest[..digits].parse::<usize>(),
            rest[digits..].strip_prefix('_'),
        ) else {
            continue;
        };
        by_index.entry(n).or_default().insert(field, v.trim());
    }
    if by_index.is_empty() {
        return Ok(None);
    }
    // Before Slicer 4.11 no segment has a label value: each is alone on its layer, its voxels 1.
    let legacy = by_index.values().all(|f| !f.contains_key("LabelValue"));
    let mut out = Vec::with_capacity(by_index.len());
    for (position, (n, f)) in by_index.iter().enumerate() {
        let bad = |what: String| VolumeError::invalid(path, format!("Segment{n}_{what}"));
        let number = |key: &str, default: usize| -> Result<usize, VolumeError> {
            f.get(key).map_or(Ok(default), |v| {
                v.parse()
                    .map_err(|_| bad(format!("{key} {v:?} is not a whole number")))
            })
        };
        let default_layer = if legacy && layers > 1 { position } else { 0 };
        let layer = number("Layer", default_layer)?;
        if layer >= layers {
            return Err(bad(format!(
                "Layer {layer}: the file holds {layers} layer{}",
                if layers == 1 { "" } else { "s" }
            )));
        }
        let label_value = number("LabelValue", 1)?;
        if label_value == 0 || label_value > u32::MAX as usize {
            return Err(bad(format!(
                "LabelValue {label_value}: label values run from 1 (0 is no segment)"
            )));
        }
        let colour = f.get("Color").and_then(|c| {
            let rgb: Vec<f64> = c
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            match rgb[..] {
                [r, g, b] if [r, g, b].iter().all(|x| (0.0..=1.0).contains(x)) => {
                    Some([r, g, b].map(|x| (x * 255.0).round() as u8))
                }
                _ => {
                    warnings.push(format!(
                        "Segment{n}_Color {c:?} is not three numbers from 0 to 1; left out"
                    ));
                    None
                }
            }
        });
        let name = f
            .get("Name")
            .or_else(|| f.get("ID"))
            .map_or_else(|| format!("Segment {n}"), |s| s.to_string());
        out.push(SlicerSegment {
            name,
            colour,
            label_value: label_value as u32,
            layer,
            terms: f.get("Tags").map(|t| terms(t)).unwrap_or_default(),
        });
    }
    Ok(Some(out))
}

/// A segmentation as a label volume: each voxel's segment number (0 none), the segments'
/// numbers, names and colours, and each segment's voxels whole where asked.
pub(crate) struct LabelVolume {
    pub data: Vec<f32>,
    pub segments: Vec<SegmentLabel>,
    pub whole: Option<WholeSegments>,
}

/// The label volume of the file's values (`value(i)`, the i-th in the file) on a `dims` grid,
/// `layers` values a voxel (voxel `v`'s on layer `l` the one at
/// `((v / inner)·layers + l)·inner + v % inner`, as a NRRD lays out a list axis with `inner`
/// voxels a run), its segments' names and colours, and,
/// with `whole`, each segment's voxels whole.
///
/// Each segment's number is its label value where those are distinct, else its place in the
/// file from 1 (segments on different layers may share a label value). Where segments overlap
/// the voxel holds the later one's number. Values no segment names are left out (as Slicer
/// shows them: not at all).
pub(crate) fn label_volume(
    value: impl Fn(usize) -> f64,
    dims: [usize; 3],
    (layers, inner): (usize, usize),
    segments: &[SlicerSegment],
    whole: bool,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<LabelVolume, VolumeError> {
    let n = dims[0] * dims[1] * dims[2];
    let mut which: HashMap<(usize, u32), usize> = HashMap::new();
    for (s, seg) in segments.iter().enumerate() {
        if let Some(t) = which.insert((seg.layer, seg.label_value), s) {
            return Err(VolumeError::invalid(
                path,
                format!(
                    "segments {:?} and {:?} both have label value {} on layer {}",
                    segments[t].name, seg.name, seg.label_value, seg.layer
                ),
            ));
        }
    }
    let mut values_seen: Vec<u32> = segments.iter().map(|s| s.label_value).collect();
    values_seen.sort_unstable();
    values_seen.dedup();
    let own_values = values_seen.len() == segments.len()
        && values_seen.last().is_some_and(|&v| v <= u16::MAX as u32);
    let numbers: Vec<u16> = if own_values {
        segments.iter().map(|s| s.label_value as u16).collect()
    } else if segments.len() <= u16::MAX as usize {
        warnings.push(
            "segments on different layers share label values: numbered from 1 in the file's order"
                .into(),
        );
        (1..=segments.len() as u16).collect()
    } else {
        return Err(VolumeError::invalid(
            path,
            format!("{} segments: at most 65535 are read", segments.len()),
        ));
    };
    // The segment that holds voxel `v` on layer `l`, if any; `Err` for a value none names.
    let held = |v: usize, l: usize| -> Result<Option<usize>, ()> {
        let x = value(((v / inner) * layers + l) * inner + v % inner);
        if x == 0.0 {
            return Ok(None);
        }
        if x.fract() != 0.0 || !(1.0..=u32::MAX as f64).contains(&x) {
            return Err(());
        }
        which.get(&(l, x as u32)).copied().map(Some).ok_or(())
    };
    let mut data = vec![0f32; n];
    let (mut overlap, mut unnamed) = (0usize, 0usize);
    for (v, out) in data.iter_mut().enumerate() {
        // In the file's order of segments: the later one's number where they overlap.
        let mut last: Option<usize> = None;
        for l in 0..layers {
            match held(v, l) {
                Ok(Some(s)) => {
                    if last.is_some() {
                        overlap += 1;
                    }
                    last = Some(last.map_or(s, |t| t.max(s)));
                }
                Ok(None) => {}
                Err(()) => unnamed += 1,
            }
        }
        if let Some(s) = last {
            *out = numbers[s] as f32;
        }
    }
    if overlap > 0 {
        warnings.push(format!(
            "{overlap} voxels are held by more than one segment; the label volume holds the later segment's there (iso --segment, render --outline and info take each segment whole)"
        ));
    }
    if unnamed > 0 {
        warnings.push(format!(
            "{unnamed} voxels hold values no segment names; read as no segment"
        ));
    }
    let labels = segments
        .iter()
        .zip(&numbers)
        .map(|(s, &number)| SegmentLabel {
            number,
            label: s.name.clone(),
            colour: s.colour,
            terms: s.terms.clone(),
        })
        .collect();
    let [nx, ny, _] = dims;
    let whole = whole.then(|| {
        gather_whole(|add| {
            for v in 0..n {
                for l in 0..layers {
                    if let Ok(Some(s)) = held(v, l) {
                        add(numbers[s], [v % nx, (v / nx) % ny, v / (nx * ny)]);
                    }
                }
            }
        })
    });
    Ok(LabelVolume {
        data,
        segments: labels,
        whole,
    })
}
