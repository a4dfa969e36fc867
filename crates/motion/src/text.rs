//! Byte-level line and token reading shared by the BVH, ASF and AMC parsers.
//!
//! Mocap files are ASCII in their syntax but not always in their comments
//! (HDM05 AMC headers carry Latin-1 path names), and they mix CRLF and bare LF
//! line ends. So the parsers read bytes, split lines at `\r\n`, `\n` or a lone
//! `\r`, split tokens at ASCII whitespace, and convert a token to text only
//! when it is used as a name or a number.

use std::path::{Path, PathBuf};

use crate::error::ParseError;

/// One line of a file: its 1-based number and its bytes without the line end.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Line<'a> {
    pub number: usize,
    pub bytes: &'a [u8],
}

impl<'a> Line<'a> {
    pub fn tokens(&self) -> impl Iterator<Item = &'a [u8]> + use<'a> {
        self.bytes
            .split(|b| b.is_ascii_whitespace())
            .filter(|t| !t.is_empty())
    }

    pub fn is_blank(&self) -> bool {
        self.bytes.iter().all(|b| b.is_ascii_whitespace())
    }
}

/// Lines of `bytes`, split at `\r\n`, `\n` or a lone `\r`; a leading UTF-8
/// byte order mark (some Windows exporters write one) is skipped.
pub(crate) fn lines(bytes: &[u8]) -> Vec<Line<'_>> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut out = Vec::new();
    let mut start = 0;
    let mut i = 0;
    let mut number = 1;
    while i < bytes.len() {
        match bytes[i] {
            b'\n' => {
                out.push(Line {
                    number,
                    bytes: &bytes[start..i],
                });
                number += 1;
                i += 1;
                start = i;
            }
            b'\r' => {
                out.push(Line {
                    number,
                    bytes: &bytes[start..i],
                });
                number += 1;
                i += 1;
                if bytes.get(i) == Some(&b'\n') {
                    i += 1;
                }
                start = i;
            }
            _ => i += 1,
        }
    }
    if start < bytes.len() {
        out.push(Line {
            number,
            bytes: &bytes[start..],
        });
    }
    out
}

/// Builds parse errors for one file.
#[derive(Debug, Clone)]
pub(crate) struct Errors {
    file: PathBuf,
}

impl Errors {
    pub fn new(file: &Path) -> Self {
        Errors {
            file: file.to_path_buf(),
        }
    }

    pub fn at(&self, line: usize, message: impl Into<String>) -> ParseError {
        ParseError {
            file: self.file.clone(),
            line: Some(line),
            message: message.into(),
        }
    }

    pub fn whole(&self, message: impl Into<String>) -> ParseError {
        ParseError {
            file: self.file.clone(),
            line: None,
            message: message.into(),
        }
    }
}

/// A token shown in an error message (lossy for non-UTF-8 bytes, shortened).
pub(crate) fn show(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(token);
    if s.chars().count() > 40 {
        let head: String = s.chars().take(40).collect();
        format!("{head}...")
    } else {
        s.into_owned()
    }
}

/// A finite decimal number (`1`, `-2.5`, `.0083`, `1e-3`); `what` names it in errors.
pub(crate) fn number(token: &[u8], what: &str) -> Result<f64, String> {
    let v = std::str::from_utf8(token)
        .ok()
        .and_then(|s| s.parse::<f64>().ok());
    match v {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(format!("{what}: `{}` is not a finite number", show(token))),
    }
}

/// A non-negative integer; `what` names it in errors.
pub(crate) fn count(token: &[u8], what: &str) -> Result<usize, String> {
    std::str::from_utf8(token)
        .ok()
        .and_then(|s| s.parse::<usize>().ok())
        .ok_or_else(|| format!("{what}: `{}` is not a whole number", show(token)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_mixed_line_ends() {
        let l = lines(b"a\r\nb\nc\rd\n\ne");
        let texts: Vec<(&[u8], usize)> = l.iter().map(|l| (l.bytes, l.number)).collect();
        assert_eq!(
            texts,
            vec![
                (&b"a"[..], 1),
                (&b"b"[..], 2),
                (&b"c"[..], 3),
                (&b"d"[..], 4),
                (&b""[..], 5),
                (&b"e"[..], 6)
            ]
        );
    }

    #[test]
    fn skips_a_byte_order_mark() {
        let l = lines(b"\xEF\xBB\xBFHIERARCHY\n");
        assert_eq!(l[0].bytes, b"HIERARCHY");
    }

    #[test]
    fn numbers() {
        assert_eq!(number(b".0083333", "t"), Ok(0.0083333));
        assert_eq!(number(b"-1e-3", "t"), Ok(-0.001));
        assert!(number(b"nan", "t").is_err());
        assert!(number(b"inf", "t").is_err());
        assert!(number(b"1,5", "t").is_err());
        assert!(number(&[0xff, b'1'], "t").is_err());
        assert_eq!(count(b"12", "n"), Ok(12));
        assert!(count(b"-1", "n").is_err());
    }
}
