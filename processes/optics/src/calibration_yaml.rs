//! A strict, bounded reader of the calibration YAML that OpenCV's calibration tools
//! and ROS's `camera_calibration` write. It replaces OpenCV's `FileStorage` on the
//! read path because OpenCV 4.6's YAML parser loops forever on some malformed files
//! (found by `landing-fuzz`: `%YAML:1.0\n t:d\nncv-\n`), and a calibration file is
//! user input a flight process reads at start. This reader is one pass over the text
//! (`CameraCalibration::load` reads at most [`MAX_FILE_BYTES`]), so it ends on any input.
//!
//! What it reads: top-level `key: scalar` lines and top-level keys whose value is an
//! indented mapping (OpenCV's `!!opencv-matrix` or ROS's untagged one) with `rows`,
//! `cols`, optional `dt` and `data: [ ... ]` (the list may span lines). Other
//! top-level keys (`calibration_time`, `camera_name`, ...) and their indented lines
//! are skipped unread.

use std::collections::BTreeMap;

/// A calibration is well under 1 kB; anything past this is not one.
pub(crate) const MAX_FILE_BYTES: usize = 64 * 1024;
/// The largest matrix read: a 3x4 projection or 14 distortion terms fit.
pub(crate) const MAX_ELEMENTS: usize = 64;

/// What the reader found wrong, and on which line (1-based; 0: the whole file).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SyntaxError {
    /// The line of the fault.
    pub line: usize,
    /// What is wrong and what is allowed.
    pub message: String,
}

/// A top-level value the stack may read.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Value {
    /// `key: text` (quotes removed).
    Scalar { line: usize, text: String },
    /// `key:` (or `key: !!opencv-matrix`) with an indented mapping under it.
    Matrix {
        line: usize,
        rows: i32,
        cols: i32,
        data: Vec<f64>,
    },
}

/// The top-level entries by key; only [`Document::get`] is needed by the loader.
#[derive(Debug, Default)]
pub(crate) struct Document {
    entries: BTreeMap<String, Value>,
}

impl Document {
    /// The value of a top-level key, if the file has it.
    pub(crate) fn get(&self, key: &str) -> Option<&Value> {
        self.entries.get(key)
    }
}

fn err(line: usize, message: impl Into<String>) -> SyntaxError {
    SyntaxError {
        line,
        message: message.into(),
    }
}

/// The line without its comment: `#` at the start or after whitespace, outside quotes.
fn strip_comment(line: &str) -> &str {
    let mut quote: Option<char> = None;
    let mut prev_space = true;
    for (i, c) in line.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' && prev_space => return &line[..i],
            None => {}
        }
        prev_space = c == ' ' || c == '\t';
    }
    line
}

/// `key: rest` or `key:`; the key is a plain word.
fn split_key(s: &str) -> Option<(&str, &str)> {
    let (key, rest) = s.split_once(':')?;
    let plain = !key.is_empty()
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.');
    if !plain || !(rest.is_empty() || rest.starts_with(' ')) {
        return None;
    }
    Some((key, rest.trim()))
}

fn unquote(s: &str) -> &str {
    for q in ['"', '\''] {
        if let Some(inner) = s.strip_prefix(q).and_then(|t| t.strip_suffix(q)) {
            return inner;
        }
    }
    s
}

/// `text` as a number, or an error naming `key` and the line.
pub(crate) fn number(line: usize, key: &str, text: &str) -> Result<f64, SyntaxError> {
    text.parse::<f64>()
        .map_err(|_| err(line, format!("`{key}`: `{text}` is not a number")))
}

/// Reads a calibration document; the caller bounds its size ([`MAX_FILE_BYTES`]).
pub(crate) fn parse(text: &str) -> Result<Document, SyntaxError> {
    let mut doc = Document::default();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l)).peekable();
    let mut started = false;
    while let Some((n, raw)) = lines.next() {
        let line = strip_comment(raw).trim_end();
        if line.trim().is_empty() {
            continue;
        }
        if !started && (line.starts_with("%YAML") || line == "---") {
            continue;
        }
        if line == "..." || line == "---" {
            break; // the end of the (first) document
        }
        if line.starts_with([' ', '\t']) {
            return Err(err(
                n,
                "an indented line with no top-level key above it (keys start in column 1)",
            ));
        }
        started = true;
        let Some((key, rest)) = split_key(line) else {
            return Err(err(n, format!("`{}` is not `key: value`", line.trim())));
        };
        // The indented lines under this key.
        let mut body: Vec<(usize, &str)> = Vec::new();
        while let Some(&(m, next)) = lines.peek() {
            let content = strip_comment(next).trim_end();
            if content.trim().is_empty() {
                lines.next();
                continue;
            }
            if !next.starts_with([' ', '\t']) {
                break;
            }
            if next.trim_start_matches(' ').starts_with('\t') {
                return Err(err(m, "a tab in the indentation (YAML allows spaces only)"));
            }
            body.push((m, content.trim()));
            lines.next();
        }
        let value = if rest.is_empty() || rest == "!!opencv-matrix" {
            if body.is_empty() {
                Value::Scalar {
                    line: n,
                    text: String::new(),
                }
            } else {
                matrix(n, key, &body)?
            }
        } else if body.is_empty() {
            Value::Scalar {
                line: n,
                text: unquote(rest).to_string(),
            }
        } else {
            // A value continued on indented lines (a flow list, a folded string):
            // the stack reads no such key, so it is kept as its first line.
            Value::Scalar {
                line: n,
                text: rest.to_string(),
            }
        };
        if doc.entries.insert(key.to_string(), value).is_some() {
            return Err(err(n, format!("`{key}` is given twice")));
        }
    }
    Ok(doc)
}

/// The indented mapping of a matrix: `rows`, `cols`, `dt` and `data: [ ... ]`.
fn matrix(line: usize, key: &str, body: &[(usize, &str)]) -> Result<Value, SyntaxError> {
    let mut rows = None;
    let mut cols = None;
    let mut data: Option<Vec<f64>> = None;
    let mut i = 0;
    while i < body.len() {
        let (n, l) = body[i];
        i += 1;
        let Some((field, rest)) = split_key(l) else {
            return Err(err(n, format!("`{key}`: `{l}` is not `field: value`")));
        };
        match field {
            "rows" | "cols" => {
                let v = number(n, field, rest)?;
                if !(v.fract() == 0.0 && (1.0..=MAX_ELEMENTS as f64).contains(&v)) {
                    return Err(err(
                        n,
                        format!("`{key}`: {field} {rest}: allowed 1 to {MAX_ELEMENTS}"),
                    ));
                }
                let slot = if field == "rows" {
                    &mut rows
                } else {
                    &mut cols
                };
                if slot.replace(v as i32).is_some() {
                    return Err(err(n, format!("`{key}`: {field} is given twice")));
                }
            }
            // One channel of any depth (OpenCV's letters); the values are read as
            // numbers whatever it says.
            "dt" if !matches!(unquote(rest), "d" | "f" | "i" | "u" | "s" | "c" | "w") => {
                return Err(err(
                    n,
                    format!("`{key}`: dt `{rest}`: allowed one channel (d, f, i, u, s, c, w)"),
                ));
            }
            "data" => {
                let mut text = rest.to_string();
                while !text.contains(']') && i < body.len() {
                    text.push(' ');
                    text.push_str(body[i].1);
                    i += 1;
                }
                let inner = text
                    .strip_prefix('[')
                    .and_then(|t| t.strip_suffix(']'))
                    .ok_or_else(|| {
                        err(n, format!("`{key}`: data is not one list `[ a, b, ... ]`"))
                    })?;
                let mut v = Vec::new();
                for item in inner.split(',').map(str::trim) {
                    if item.is_empty() {
                        continue;
                    }
                    if v.len() == MAX_ELEMENTS {
                        return Err(err(
                            n,
                            format!("`{key}`: more than {MAX_ELEMENTS} values in data"),
                        ));
                    }
                    v.push(number(n, key, item)?);
                }
                if data.replace(v).is_some() {
                    return Err(err(n, format!("`{key}`: data is given twice")));
                }
            }
            // ROS writes nothing else under a matrix; other fields are not read.
            _ => {}
        }
    }
    let (Some(rows), Some(cols), Some(data)) = (rows, cols, data) else {
        return Err(err(
            line,
            format!("`{key}` is not a matrix (needs rows, cols and data)"),
        ));
    };
    if data.len() != (rows * cols) as usize {
        return Err(err(
            line,
            format!(
                "`{key}`: {rows}x{cols} needs {} values, data has {}",
                rows * cols,
                data.len()
            ),
        ));
    }
    Ok(Value::Matrix {
        line,
        rows,
        cols,
        data,
    })
}
