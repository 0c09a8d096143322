//! JSON parsing with errors that name the field path, line and column.

use crate::scene::SceneError;

/// Parses JSON text into any `T`, with the errors of [`SceneDescription::from_json_str`]: a
/// [`SceneError::Json`] naming the field path, line and column.
pub fn parse_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, SceneError> {
    serde_json::from_str(text).map_err(|error| json_error(text, &error))
}

/// `parent.key`, or `parent["key"]` when the key is not a plain identifier.
pub(crate) fn key_path(parent: &str, key: &str) -> String {
    let plain = !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    match (parent.is_empty(), plain) {
        (true, true) => key.to_owned(),
        (false, true) => format!("{parent}.{key}"),
        (_, false) => format!("{parent}[{key:?}]"),
    }
}

/// Turns a serde_json error into a [`SceneError::Json`] naming the field path at the error's
/// position.
fn json_error(text: &str, error: &serde_json::Error) -> SceneError {
    let (line, column) = (error.line(), error.column());
    let mut message = error.to_string();
    let suffix = format!(" at line {line} column {column}");
    if let Some(stripped) = message.strip_suffix(&suffix) {
        message = stripped.to_owned();
    }
    let mut offset = byte_offset(text, line, column);
    // Syntax errors point at the offending character (which may close an object); data errors
    // point just past what was read.
    if error.is_syntax() {
        offset = offset.saturating_sub(1);
    }
    let mut field = json_path_at(text, offset);
    // serde reports a missing field at the end of the object that lacks it.
    if let Some(name) = backticked_after(&message, "missing field ") {
        field = key_path(&field, &name);
        message = "required field is missing".to_owned();
    }
    if field.is_empty() {
        field = "(root)".to_owned();
    }
    SceneError::Json { field, message, line, column }
}

/// The text between backticks right after `prefix` at the start of `message`.
fn backticked_after(message: &str, prefix: &str) -> Option<String> {
    let rest = message.strip_prefix(prefix)?.strip_prefix('`')?;
    rest.split_once('`').map(|(name, _)| name.to_owned())
}

/// Byte offset just past the 1-based (line, column) character serde_json reports.
fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let line_start: usize = text.split_inclusive('\n').take(line.saturating_sub(1)).map(str::len).sum();
    (line_start + column).min(text.len())
}

/// One step of a JSON path.
enum Frame {
    Object { key: Option<String>, expecting_key: bool },
    Array { index: usize },
}

/// The path (`meshes[0].transform.scale`) of the value being read when a parser has consumed
/// the first `offset` bytes of `text`. A small tokenizer that tracks the open objects and
/// arrays; it does not validate.
pub(super) fn json_path_at(text: &str, offset: usize) -> String {
    let bytes = &text.as_bytes()[..offset.min(text.len())];
    let mut stack: Vec<Frame> = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'{' => stack.push(Frame::Object { key: None, expecting_key: true }),
            b'[' => stack.push(Frame::Array { index: 0 }),
            b'}' | b']' => {
                stack.pop();
            }
            b',' => match stack.last_mut() {
                Some(Frame::Object { key, expecting_key }) => {
                    *key = None;
                    *expecting_key = true;
                }
                Some(Frame::Array { index }) => *index += 1,
                None => {}
            },
            b'"' => {
                let start = i + 1;
                let mut end = start;
                while end < bytes.len() && bytes[end] != b'"' {
                    end += if bytes[end] == b'\\' { 2 } else { 1 };
                }
                if let Some(Frame::Object { key, expecting_key: expecting_key @ true }) = stack.last_mut() {
                    let raw = &bytes[start..end.min(bytes.len())];
                    *key = Some(String::from_utf8_lossy(raw).into_owned());
                    *expecting_key = false;
                }
                i = end;
            }
            _ => {}
        }
        i += 1;
    }
    let mut path = String::new();
    for frame in &stack {
        match frame {
            Frame::Object { key: Some(key), .. } => path = key_path(&path, key),
            Frame::Object { key: None, .. } => {}
            Frame::Array { index } => path.push_str(&format!("[{index}]")),
        }
    }
    path
}
