//! Reading the files a user names: regular files only (a directory, a device such as
//! `/dev/zero` or a pipe is refused, naming the file), read whole but never past the size the
//! file had when it was opened, so memory stays bounded by what the file really holds.

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// The bytes of the regular file at `path`.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let what = if meta.is_dir() {
            "a folder"
        } else {
            "not a regular file"
        };
        return Err(Error::format(
            path,
            "",
            format!("is {what}; expected a file"),
        ));
    }
    let len = meta.len();
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(len)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The UTF-8 text of the regular file at `path`.
pub(crate) fn read_text(path: &Path) -> Result<String> {
    String::from_utf8(read_bytes(path)?).map_err(|e| {
        Error::format(
            path,
            format!("byte {}", e.utf8_error().valid_up_to()),
            "is not UTF-8 text",
        )
    })
}

/// Replaces the bare tokens `NaN`, `Infinity` and `-Infinity` outside strings (what Python's
/// `json` writes for non-finite floats) by `null`, so that the schema walk can name the field.
pub(crate) fn non_finite_tokens_to_null(text: &str) -> std::borrow::Cow<'_, str> {
    if !(text.contains("NaN") || text.contains("Infinity")) {
        return text.into();
    }
    let mut out = String::with_capacity(text.len());
    let (mut in_string, mut escaped) = (false, false);
    let mut rest = text;
    while let Some(ch) = rest.chars().next() {
        if in_string {
            if escaped {
                escaped = false;
            } else if ch == '\\' {
                escaped = true;
            } else if ch == '"' {
                in_string = false;
            }
        } else if ch == '"' {
            in_string = true;
        } else if let Some(token) = ["NaN", "-Infinity", "Infinity"]
            .iter()
            .find(|t| rest.starts_with(**t))
        {
            out.push_str("null");
            rest = &rest[token.len()..];
            continue;
        }
        out.push(ch);
        rest = &rest[ch.len_utf8()..];
    }
    out.into()
}

/// Parses the JSON text of the file at `path` as a `T`, for files a user writes (by hand or
/// with Python's `json`, which writes `NaN` and `Infinity`). Errors are in the user's terms:
/// where (the element's path, `instances[0].field.analytic.primitives[1].density`, else the
/// line and column), and what was expected in JSON's words (a number, a list, an object),
/// never a Rust type; a non-finite number is named as such; a file that is not an object at
/// all is described as `what` (e.g. `a scene: an object with "instances"`).
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &Path,
    what: &str,
) -> Result<T> {
    let readable = non_finite_tokens_to_null(text);
    let had_non_finite = matches!(readable, std::borrow::Cow::Owned(_));
    let mut de = serde_json::Deserializer::from_str(&readable);
    let value = serde_path_to_error::deserialize(&mut de)
        .map_err(|e| (e.path().to_string(), e.into_inner()))
        .and_then(|v| de.end().map(|()| v).map_err(|e| (String::new(), e)));
    value.map_err(|(at, inner)| {
        let by_line = inner.is_syntax() || inner.is_eof() || at.is_empty() || at == ".";
        let location = if by_line {
            format!("line {} column {}", inner.line(), inner.column())
        } else {
            at.clone()
        };
        let mut message = in_json_words(&inner.to_string());
        if inner.is_syntax() || inner.is_eof() {
            message = format!("not valid JSON: {message}");
        } else if at.is_empty() || at == "." {
            message = format!("expected {what} ({message})");
        }
        if had_non_finite && message.contains("null") {
            message.push_str(" (NaN or Infinity, which JSON cannot hold, reads as null)");
        }
        Error::format(path, location, message)
    })
}

/// serde's message in JSON's words: its position dropped (the location says it) and Rust's
/// names of types replaced by what they are in JSON.
fn in_json_words(message: &str) -> String {
    let message = message.split(" at line ").next().unwrap_or(message);
    let mut out: Vec<String> = Vec::new();
    let mut words = message.split(' ').peekable();
    while let Some(word) = words.next() {
        let (core, tail) = word.split_at(word.trim_end_matches([',', ';', ':']).len());
        let replaced = match core {
            "f32" | "f64" => Some("a number".to_string()),
            "u8" | "u16" | "u32" | "u64" | "usize" | "i32" | "i64" => {
                Some("a whole number".to_string())
            }
            "sequence" => Some("a list".to_string()),
            "map" => Some("an object".to_string()),
            "struct" | "enum" => {
                // `struct Name` (`with N elements`): an object; `enum Name`: one of its forms.
                let name = words.next().unwrap_or_default();
                let tail = &name[name.trim_end_matches([',', ';', ':']).len()..];
                if words.peek() == Some(&"with") {
                    for _ in 0..3 {
                        words.next();
                    }
                }
                let is_struct = core == "struct";
                Some(format!(
                    "{}{tail}",
                    if is_struct {
                        "an object"
                    } else {
                        "one of its forms"
                    }
                ))
            }
            _ => None,
        };
        match replaced {
            Some(r) if core == "struct" || core == "enum" => out.push(r),
            Some(r) => out.push(format!("{r}{tail}")),
            None => out.push(word.to_string()),
        }
    }
    out.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_and_devices_are_refused_naming_them() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_bytes(dir.path()).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let e = read_text(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
        let file = dir.path().join("t.json");
        std::fs::write(&file, [b'{', 0xff, b'}']).unwrap();
        let e = read_text(&file).unwrap_err().to_string();
        assert!(e.contains("byte 1") && e.contains("UTF-8"), "{e}");
        std::fs::write(&file, "{}").unwrap();
        assert_eq!(read_text(&file).unwrap(), "{}");
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Scene {
        items: Vec<Item>,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Item {
        size: f32,
        count: u32,
    }

    #[test]
    fn json_errors_name_the_element_in_json_words() {
        let path = Path::new("s.json");
        let e = |text: &str| {
            parse_json::<Scene>(text, path, "a scene: an object {\"items\": [...]}")
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            e(r#"{"items": [{"size": 1, "count": 2}, {"size": NaN, "count": 2}]}"#),
            "s.json: items[1].size: invalid type: null, expected a number (NaN or Infinity, \
             which JSON cannot hold, reads as null)"
        );
        assert_eq!(
            e(r#"{"items": [{"size": 1, "count": -2}]}"#),
            "s.json: items[0].count: invalid value: integer `-2`, expected a whole number"
        );
        assert_eq!(
            e("[]"),
            "s.json: line 1 column 2: expected a scene: an object {\"items\": [...]} (invalid \
             length 0, expected an object)"
        );
        let m = e("{\"items\": [\n  {\"size\": 1,}]}");
        assert!(
            m.starts_with("s.json: line 2 column 14: not valid JSON: trailing comma"),
            "{m}"
        );
        let m = e(r#"{"items": [], "extra": 1}"#);
        assert!(m.contains("extra") && !m.contains("struct"), "{m}");
        let m = e(r#"{"items": []} {}"#);
        assert!(
            m.contains("line 1 column 15") && m.contains("trailing"),
            "{m}"
        );
        // A NaN inside a string is text, not a number.
        assert!(parse_json::<serde_json::Value>(r#"{"a": "NaN"}"#, path, "x").is_ok());
    }
}
