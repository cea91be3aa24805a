//! What the legacy VTK readers share (`# vtk DataFile Version …` files: image data read as a
//! volume, polygonal data as a mesh): the four header lines, a cursor over the keyword lines
//! and the values between them (big-endian binary or text), and the type names. Written by
//! hand: the VTK crates on crates.io read VTK's XML formats, not the legacy ones' binary
//! sections.

use crate::volume::raw::Scalar;

/// A cursor over a legacy VTK file's bytes: keyword lines, and the values after them. Errors
/// are the problem alone; the readers name the file.
pub(crate) struct Cursor<'a> {
    pub bytes: &'a [u8],
    pub pos: usize,
}

impl<'a> Cursor<'a> {
    /// The next line, without its line end; `None` at the end of the file.
    pub fn line(&mut self) -> Option<&'a str> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        Some(
            std::str::from_utf8(&rest[..end])
                .unwrap_or("")
                .trim_end_matches('\r'),
        )
    }

    /// The next line with any text, split into words, or `None` at the end of the file.
    pub fn next_words(&mut self) -> Option<Vec<&'a str>> {
        loop {
            let words: Vec<&str> = self.line()?.split_whitespace().collect();
            if !words.is_empty() {
                return Some(words);
            }
        }
    }

    /// The next line with any text, split into words; an error at the end of the file.
    pub fn words(&mut self, wanted: &str) -> Result<Vec<&'a str>, String> {
        self.next_words()
            .ok_or_else(|| format!("the VTK file ends before its {wanted}"))
    }

    /// Whether the next line starts with `keyword` (case aside), without moving past it.
    pub fn next_line_starts_with(&self, keyword: &str) -> bool {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let n = keyword.len();
        rest.len() >= n && rest[..n].eq_ignore_ascii_case(keyword.as_bytes())
    }

    /// The next `n` values of `size` bytes, binary: checked against what the file holds
    /// before anything is sized by `n`.
    pub fn binary(&mut self, n: usize, size: usize, what: &str) -> Result<&'a [u8], String> {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let nbytes = n
            .checked_mul(size)
            .filter(|&b| b <= rest.len())
            .ok_or_else(|| {
                format!(
                    "{what} is truncated: the header implies {n} values of {size} bytes, the file \
                 holds {} bytes",
                    rest.len()
                )
            })?;
        self.pos += nbytes;
        Ok(&rest[..nbytes])
    }

    /// The next `n` numbers written as text, separated by white space.
    pub fn text(&mut self, n: usize, what: &str) -> Result<Vec<f64>, String> {
        let mut out =
            Vec::with_capacity(n.min((self.bytes.len() - self.pos.min(self.bytes.len())) / 2 + 1));
        while out.len() < n {
            let rest = &self.bytes[self.pos.min(self.bytes.len())..];
            let start = rest.iter().position(|b| !b.is_ascii_whitespace());
            let Some(start) = start else {
                return Err(format!(
                    "{what} is truncated: the header implies {n} values, the file holds {}",
                    out.len()
                ));
            };
            let len = rest[start..]
                .iter()
                .position(|b| b.is_ascii_whitespace())
                .unwrap_or(rest.len() - start);
            let word = std::str::from_utf8(&rest[start..start + len]).unwrap_or("?");
            let v: f64 = word.parse().map_err(|_| {
                format!("{what}: value {} is not a number: {word:?}", out.len() + 1)
            })?;
            out.push(v);
            self.pos += start + len;
        }
        Ok(out)
    }
}

/// A legacy VTK file's header: whether its values are binary, its dataset kind
/// (`STRUCTURED_POINTS`, `POLYDATA`, …, upper case), and the cursor after it.
pub(crate) struct Header<'a> {
    pub binary: bool,
    pub dataset: String,
    pub cursor: Cursor<'a>,
}

/// Reads the four header lines: the version line, the title, ASCII or BINARY, `DATASET kind`.
pub(crate) fn header(bytes: &[u8]) -> Result<Header<'_>, String> {
    let mut c = Cursor { bytes, pos: 0 };
    let first = c.line().unwrap_or("");
    if !first.to_ascii_lowercase().starts_with("# vtk datafile") {
        return Err(format!(
            "not a legacy VTK file: it starts {:?}, not \"# vtk DataFile Version\"",
            first.chars().take(40).collect::<String>()
        ));
    }
    let _title = c.line();
    let encoding = c.words("encoding (ASCII or BINARY)")?;
    let binary = match encoding[0].to_ascii_uppercase().as_str() {
        "BINARY" => true,
        "ASCII" => false,
        other => return Err(format!("VTK encoding {other:?}: ASCII or BINARY expected")),
    };
    let dataset = c.words("DATASET line")?;
    if !dataset[0].eq_ignore_ascii_case("DATASET") || dataset.len() < 2 {
        return Err(format!(
            "VTK {:?}: a DATASET line expected",
            dataset.join(" ")
        ));
    }
    Ok(Header {
        binary,
        dataset: dataset[1].to_ascii_uppercase(),
        cursor: c,
    })
}

/// The dataset kind a legacy VTK file at `path` holds (its first kilobyte read), if it is one.
pub(crate) fn dataset_of(path: &std::path::Path) -> Option<String> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path)
        .ok()?
        .take(1024)
        .read_to_end(&mut head)
        .ok()?;
    header(&head).ok().map(|h| h.dataset)
}

/// The scalar type a VTK type name stands for. `long` is 8 bytes, as VTK writes it on the
/// 64-bit Linux and macOS machines that write nearly all such files.
pub(crate) fn scalar_of(name: &str) -> Result<Scalar, String> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "unsigned_char" => Scalar::U8,
        "char" | "signed_char" => Scalar::I8,
        "unsigned_short" => Scalar::U16,
        "short" => Scalar::I16,
        "unsigned_int" | "vtktypeuint32" => Scalar::U32,
        "int" | "vtktypeint32" => Scalar::I32,
        "unsigned_long" | "vtktypeuint64" => Scalar::U64,
        "long" | "vtktypeint64" => Scalar::I64,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        _ => return Err(format!("VTK values of type {name:?} are not read")),
    })
}
