//! A label map's names and colours from a colour table: 3D Slicer's (`.ctbl` or `.txt`, a
//! line `index name R G B [A]`) or ITK-SNAP's label description (a line `index R G B A
//! visibility mesh "label"`), `#` starting a comment. Both are a few whitespace-separated
//! fields a line, which no maintained crate reads, so they are parsed here.

use std::path::Path;

use crate::volume::{SegmentLabel, VolumeError};

/// The largest colour table read (a table of every 16-bit label is under 2 MB).
const MAX_BYTES: u64 = 16 << 20;

/// The labels a colour table names, in its order: number, name and sRGB colour (label 0, the
/// background, left out). Errors name the file and the line.
pub fn read_colour_table(path: &Path) -> Result<Vec<SegmentLabel>, VolumeError> {
    let size = std::fs::metadata(path)
        .map_err(|e| VolumeError::io(path, e))?
        .len();
    if size > MAX_BYTES {
        return Err(VolumeError::invalid(
            path,
            format!("a colour table of {size} bytes (at most {MAX_BYTES} are read)"),
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| VolumeError::io(path, e))?;
    let text = String::from_utf8_lossy(&bytes);
    let mut out: Vec<SegmentLabel> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let bad =
            |problem: String| VolumeError::invalid(path, format!("line {}: {problem}", n + 1));
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (fields, quoted) = match line.find('"') {
            // ITK-SNAP: the label in quotes after the numbers.
            Some(q) => {
                let rest = &line[q + 1..];
                let end = rest
                    .find('"')
                    .ok_or_else(|| bad("a label whose quotes do not close".into()))?;
                (&line[..q], Some(rest[..end].to_string()))
            }
            None => (line, None),
        };
        let words: Vec<&str> = fields.split_whitespace().collect();
        let number = |w: &str, what: &str, max: u32| {
            w.parse::<u32>().ok().filter(|&v| v <= max).ok_or_else(|| {
                bad(format!(
                    "{what} {w:?} is not a whole number from 0 to {max}"
                ))
            })
        };
        let (index, name, rgb) = match quoted {
            Some(label) => {
                // index R G B A visibility mesh "label"
                if words.len() < 4 {
                    return Err(bad(format!(
                        "{} numbers before the label; ITK-SNAP's has index, R, G, B, A, visibility, mesh",
                        words.len()
                    )));
                }
                (words[0], label, &words[1..4])
            }
            None => {
                // index name R G B [A]
                if words.len() < 5 {
                    return Err(bad(format!(
                        "{} fields; 3D Slicer's has index, name, R, G, B and A",
                        words.len()
                    )));
                }
                let has_alpha = words.len() >= 6
                    && words[words.len() - 4..]
                        .iter()
                        .all(|w| w.parse::<u32>().is_ok());
                let colour_at = words.len() - if has_alpha { 4 } else { 3 };
                (
                    words[0],
                    words[1..colour_at].join(" "),
                    &words[colour_at..colour_at + 3],
                )
            }
        };
        let index = number(index, "the index", 65535)?;
        let mut colour = [0u8; 3];
        for (c, w) in colour.iter_mut().zip(rgb) {
            *c = number(w, "a colour component", 255)? as u8;
        }
        if index == 0 {
            continue;
        }
        if out.iter().any(|l| l.number as u32 == index) {
            return Err(bad(format!("label {index} named twice")));
        }
        out.push(SegmentLabel {
            number: index as u16,
            label: name,
            colour: Some(colour),
            ..Default::default()
        });
    }
    if out.is_empty() {
        return Err(VolumeError::invalid(path, "a colour table naming no label"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(name: &str, text: &str) -> Result<Vec<SegmentLabel>, String> {
        let scratch = crate::tests::scratch_dir("ctbl");
        let dir = scratch.path();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        read_colour_table(&path).map_err(|e| e.to_string())
    }

    fn label(number: u16, name: &str, colour: [u8; 3]) -> SegmentLabel {
        SegmentLabel {
            number,
            label: name.into(),
            colour: Some(colour),
            ..Default::default()
        }
    }

    /// 3D Slicer's table (background left out, alpha optional, a name of several words kept)
    /// and ITK-SNAP's label description give the same labels; bad lines are errors naming the
    /// file and the line.
    #[test]
    fn slicer_and_itk_snap_tables() {
        let slicer = table(
            "t.ctbl",
            "# Color table file\n0 Background 0 0 0 0\n1 aorta 224 32 32 255\n2 left kidney 185 102 83\n",
        )
        .unwrap();
        let want = [
            label(1, "aorta", [224, 32, 32]),
            label(2, "left kidney", [185, 102, 83]),
        ];
        assert_eq!(slicer, want);
        let snap = table(
            "t.txt",
            "################################################\n\
             # ITK-SnAP Label Description File\n\
             0     0    0    0        0  0  0    \"Clear Label\"\n\
             1   224   32   32        1  1  1    \"aorta\"\n\
             2   185  102   83        1  1  1    \"left kidney\"\n",
        )
        .unwrap();
        assert_eq!(snap, want);
        for (text, want) in [
            (
                "1 aorta 300 0 0 255\n",
                "t.ctbl: line 1: a colour component \"300\"",
            ),
            ("1 aorta 0 0\n", "t.ctbl: line 1: 4 fields"),
            ("x aorta 1 2 3 255\n", "t.ctbl: line 1: the index \"x\""),
            (
                "1 a 1 2 3 255\n1 b 1 2 3 255\n",
                "t.ctbl: line 2: label 1 named twice",
            ),
            (
                "1 2 3 4 1 1 1 \"open\n",
                "t.ctbl: line 1: a label whose quotes do not close",
            ),
            (
                "# nothing\n0 Background 0 0 0 0\n",
                "t.ctbl: a colour table naming no label",
            ),
        ] {
            let e = table("t.ctbl", text).unwrap_err();
            assert!(e.contains(want), "{e}");
        }
    }
}
