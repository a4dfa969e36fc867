//! The token stream of a BVH file's header: tokens with their line numbers,
//! skipping blank lines, with the "expected X" errors every header stage uses.

use crate::error::ParseError;
use crate::text::{self, Errors, Line, show};

/// The tokens of the non-blank lines, one at a time, with their line numbers.
pub(super) struct Cursor<'a> {
    lines: &'a [Line<'a>],
    line: usize,
    tokens: Vec<&'a [u8]>,
    token: usize,
    errors: &'a Errors,
}

impl<'a> Cursor<'a> {
    pub fn new(lines: &'a [Line<'a>], errors: &'a Errors) -> Self {
        let mut c = Cursor {
            lines,
            line: 0,
            tokens: Vec::new(),
            token: 0,
            errors,
        };
        c.load();
        c
    }

    /// Make `tokens` hold the tokens of the first non-blank line at or after `line`.
    fn load(&mut self) {
        while self.line < self.lines.len() {
            self.tokens = self.lines[self.line].tokens().collect();
            self.token = 0;
            if !self.tokens.is_empty() {
                return;
            }
            self.line += 1;
        }
        self.tokens.clear();
        self.token = 0;
    }

    /// Line number of the next token (or of the last line at the end).
    pub fn line_number(&self) -> usize {
        match self.lines.get(self.line) {
            Some(l) => l.number,
            None => self.lines.last().map_or(1, |l| l.number),
        }
    }

    pub fn next(&mut self) -> Option<(&'a [u8], usize)> {
        if self.token >= self.tokens.len() {
            return None;
        }
        let t = self.tokens[self.token];
        let n = self.line_number();
        self.token += 1;
        if self.token >= self.tokens.len() {
            self.line += 1;
            self.load();
        }
        Some((t, n))
    }

    pub fn peek(&self) -> Option<&'a [u8]> {
        self.tokens.get(self.token).copied()
    }

    /// The next token, or an error saying the file ended while `expected`.
    pub fn need(&mut self, expected: &str) -> Result<(&'a [u8], usize), ParseError> {
        let at = self.line_number();
        self.next().ok_or_else(|| {
            self.errors
                .at(at, format!("file ends where {expected} was expected"))
        })
    }

    /// The next token, which must be `word` (ASCII case-insensitive).
    pub fn expect(&mut self, word: &str) -> Result<usize, ParseError> {
        let (t, n) = self.need(&format!("`{word}`"))?;
        if t.eq_ignore_ascii_case(word.as_bytes()) {
            Ok(n)
        } else {
            Err(self
                .errors
                .at(n, format!("expected `{word}`, found `{}`", show(t))))
        }
    }

    pub fn number(&mut self, what: &str) -> Result<f64, ParseError> {
        let (t, n) = self.need(what)?;
        text::number(t, what).map_err(|m| self.errors.at(n, m))
    }

    /// All remaining tokens of the current line (for names with spaces).
    pub fn rest_of_line(&mut self) -> Vec<&'a [u8]> {
        if self.token >= self.tokens.len() {
            return Vec::new();
        }
        let rest = self.tokens[self.token..].to_vec();
        self.line += 1;
        self.load();
        rest
    }
}
