//! Reading the camera files' JSON (shot files, nerfstudio camera paths, dataparser
//! transforms) with messages that name the file and the field.
//!
//! The text is parsed into a [`Value`] tree by [`parse`], then walked with an [`Obj`]: a JSON
//! object that knows where it is (`frames[3].camera`), so that every refusal reads
//! `shot.json: frames[3].camera.lens: expected a number > 0, got 0`. Each file keeps its own
//! schema (and its typed getters, as a private extension trait on [`Obj`]); only the walking
//! and the shared wording live here.
//!
//! Python's `json` writes `NaN` and `Infinity`, which JSON cannot hold: they are read as
//! `null` and a required `null` is refused naming the element. Files whose schema serde
//! walks (scenes, graphs) go through [`parse_json`], with messages in the same terms.
//!
//! The two walkers this replaced differ in how a value that is not the object or list
//! wanted is described, by its kind (`a string`) or by its text cut short (`"abc"`): a
//! [`Style`] chosen by the caller.

use std::path::Path;

use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use crate::error::{Error, Result};

/// Parses `text`; a syntax error becomes a format error at `line L column C` of `path`, with
/// the message `not valid JSON`.
pub(crate) fn parse(text: &str, path: &Path) -> Result<Value> {
    parse_with(text, path, |_| "not valid JSON".to_string())
}

/// As [`parse`], with serde_json's reason after the message: `not valid JSON: expected value`.
pub(crate) fn parse_with_reason(text: &str, path: &Path) -> Result<Value> {
    parse_with(text, path, |e| {
        // serde_json's message ends with the position, already in the location.
        format!(
            "not valid JSON: {}",
            e.to_string().split(" at line ").next().unwrap_or_default()
        )
    })
}

fn parse_with(
    text: &str,
    path: &Path,
    message: impl Fn(&serde_json::Error) -> String,
) -> Result<Value> {
    serde_json::from_str(&non_finite_tokens_to_null(text)).map_err(|e| {
        Error::format(
            path,
            format!("line {} column {}", e.line(), e.column()),
            message(&e),
        )
    })
}

/// The kind of a JSON value, for messages: `null`, `a boolean`, `a number`, `a string`,
/// `a list`, `an object`.
pub(crate) fn kind_of(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "an object",
    }
}

/// A value for a message: its JSON text, cut to 40 characters and `…`.
pub(crate) fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s
    }
}

/// The numbers of a JSON list, or `None` unless it is a list of finite numbers only.
pub(crate) fn numbers(v: &Value) -> Option<Vec<f64>> {
    match v {
        Value::Array(items) => items
            .iter()
            .map(|x| x.as_f64().filter(|f| f.is_finite()))
            .collect(),
        _ => None,
    }
}

/// How a value is described where an object or a list was wanted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Describe {
    /// By [`kind_of`]: `expected a list, got a string`.
    Kind,
    /// By [`short`]: `expected a list, got "abc"`.
    Value,
}

/// A file's wording of the messages that [`Obj`] writes itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Style {
    /// How a value that is not the object or list wanted is described.
    pub(crate) wrong_shape: Describe,
}

impl Style {
    fn describe(self, v: &Value) -> String {
        match self.wrong_shape {
            Describe::Kind => kind_of(v).to_string(),
            Describe::Value => short(v),
        }
    }
}

/// A JSON object being read, with its location for messages.
pub(crate) struct Obj<'a> {
    map: &'a Map<String, Value>,
    path: &'a Path,
    /// JSON path of this object, e.g. `frames[3].camera`; empty at the top.
    loc: String,
    style: Style,
}

impl<'a> Obj<'a> {
    /// The top-level object of the file `path`.
    pub(crate) fn root(value: &'a Value, path: &'a Path, style: Style) -> Result<Self> {
        Obj::new(value, path, String::new(), style)
    }

    /// The object `value` found at `loc`; refused (at `loc`) when it is not an object.
    pub fn new(value: &'a Value, path: &'a Path, loc: String, style: Style) -> Result<Self> {
        match value {
            Value::Object(map) => Ok(Obj {
                map,
                path,
                loc,
                style,
            }),
            other => Err(Error::format(
                path,
                loc,
                format!("expected a JSON object, got {}", style.describe(other)),
            )),
        }
    }

    /// The location of the field `key` of this object: `frames[3].camera.lens`.
    pub(crate) fn field_loc(&self, key: &str) -> String {
        if self.loc.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.loc)
        }
    }

    /// A format error at the field `key`.
    pub fn error(&self, key: &str, message: impl Into<String>) -> Error {
        Error::format(self.path, self.field_loc(key), message)
    }

    /// A format error at `loc` (an element inside a field) in this object's file.
    pub(crate) fn error_at(&self, loc: String, message: impl Into<String>) -> Error {
        Error::format(self.path, loc, message)
    }

    /// Whether the field `key` is present, even as `null`.
    pub fn has(&self, key: &str) -> bool {
        self.map.contains_key(key)
    }

    /// The field names, in order.
    pub(crate) fn keys(&self) -> impl Iterator<Item = &'a String> {
        self.map.keys()
    }

    /// The value at `key`; JSON `null` counts as absent.
    pub(crate) fn opt(&self, key: &str) -> Option<&'a Value> {
        self.map.get(key).filter(|v| !v.is_null())
    }

    /// The value at `key`, refused when missing or `null`; `expected` describes the wanted
    /// value in the message.
    pub(crate) fn required(&self, key: &str, expected: &str) -> Result<&'a Value> {
        match self.map.get(key) {
            None => Err(self.error(key, format!("missing; expected {expected}"))),
            Some(Value::Null) => Err(self.error(
                key,
                format!("expected {expected}, got null (or NaN/Infinity, which JSON cannot hold)"),
            )),
            Some(v) => Ok(v),
        }
    }

    /// A required value of type `T`, described as `expected` in messages.
    pub fn get<T: DeserializeOwned>(&self, key: &str, expected: &str) -> Result<T> {
        let v = self.required(key, expected)?;
        T::deserialize(v)
            .map_err(|_| self.error(key, format!("expected {expected}, got {}", short(v))))
    }

    /// A required finite number; `expected` describes it when it is missing.
    pub(crate) fn finite(&self, key: &str, expected: &str) -> Result<f64> {
        let v = self.required(key, expected)?;
        match v.as_f64() {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(self.error(key, format!("expected a finite number, got {}", short(v)))),
        }
    }

    /// A required list.
    pub fn array(&self, key: &str) -> Result<&'a Vec<Value>> {
        match self.required(key, "a list")? {
            Value::Array(a) => Ok(a),
            other => Err(self.error(
                key,
                format!("expected a list, got {}", self.style.describe(other)),
            )),
        }
    }

    /// A required object, read in the same style.
    pub fn object(&self, key: &str) -> Result<Obj<'a>> {
        let v = self.required(key, "an object")?;
        Obj::new(v, self.path, self.field_loc(key), self.style)
    }
}

/// Replaces the bare tokens `NaN`, `Infinity` and `-Infinity` outside strings (what Python's
/// `json` writes for non-finite floats) by `null`, so that the schema walk can name the field.
fn non_finite_tokens_to_null(text: &str) -> std::borrow::Cow<'_, str> {
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
pub fn parse_json<T: serde::de::DeserializeOwned>(
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
                // `struct Name` (`with N elements`): an object; `enum Name`: one of its forms;
                // `struct variant Type::Name`: an object too.
                let mut name = words.next().unwrap_or_default();
                if name == "variant" {
                    name = words.next().unwrap_or_default();
                }
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
        // serde writes `a sequence`, `a map`: the replacement brings its own article.
        if replaced.is_some() && matches!(out.last().map(String::as_str), Some("a" | "an")) {
            out.pop();
        }
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
    use serde_json::json;

    const SHOT_LIKE: Style = Style {
        wrong_shape: Describe::Kind,
    };
    const PATH_LIKE: Style = Style {
        wrong_shape: Describe::Value,
    };

    fn message<T>(r: Result<T>) -> String {
        match r {
            Ok(_) => panic!("expected an error"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn syntax_errors_give_line_and_column() {
        let text = "{\"a\": 1,\n  oops}";
        let e = message(parse(text, Path::new("f.json")));
        assert!(e.contains("f.json") && e.contains("line 2 column 3"), "{e}");
        assert!(e.ends_with("not valid JSON"), "{e}");
        let e = message(parse_with_reason(text, Path::new("f.json")));
        assert!(e.contains("not valid JSON: key must be a string"), "{e}");
        assert!(!e.contains(" at line "), "{e}");
    }

    #[test]
    fn short_cuts_at_forty_characters() {
        assert_eq!(short(&json!("ab")), "\"ab\"");
        let long = json!("x".repeat(50));
        assert_eq!(short(&long), format!("\"{}…", "x".repeat(39)));
    }

    #[test]
    fn numbers_accepts_only_lists_of_numbers() {
        assert_eq!(numbers(&json!([1, 2.5, -3])), Some(vec![1.0, 2.5, -3.0]));
        assert_eq!(numbers(&json!([1, "2"])), None);
        assert_eq!(numbers(&json!([1, null])), None);
        assert_eq!(numbers(&json!(1)), None);
        assert_eq!(numbers(&json!([])), Some(vec![]));
    }

    #[test]
    fn locations_nest_and_styles_keep_their_wording() {
        let v = json!({"cam": {"lens": null, "tags": "x", "n": "7"}});
        let path = Path::new("s.json");
        for (style, null_msg, list_msg) in [
            (
                SHOT_LIKE,
                "s.json: cam.lens: expected a number, got null (or NaN/Infinity, which JSON \
                 cannot hold)",
                "s.json: cam.tags: expected a list, got a string",
            ),
            (
                PATH_LIKE,
                "s.json: cam.lens: expected a number, got null (or NaN/Infinity, which JSON \
                 cannot hold)",
                "s.json: cam.tags: expected a list, got \"x\"",
            ),
        ] {
            let cam = Obj::root(&v, path, style).unwrap().object("cam").unwrap();
            assert_eq!(message(cam.required("lens", "a number")), null_msg);
            assert_eq!(message(cam.array("tags")), list_msg);
            assert_eq!(
                message(cam.finite("n", "a number")),
                "s.json: cam.n: expected a finite number, got \"7\""
            );
            assert_eq!(
                message(cam.get::<u32>("zz", "an integer")),
                "s.json: cam.zz: missing; expected an integer"
            );
            assert!(cam.has("lens") && cam.opt("lens").is_none());
        }
        let top = json!([1]);
        assert_eq!(
            message(Obj::root(&top, path, SHOT_LIKE)),
            "s.json: expected a JSON object, got a list"
        );
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
    fn serde_words_become_json_words_with_one_article() {
        assert_eq!(
            in_json_words("invalid type: map, expected a sequence"),
            "invalid type: an object, expected a list"
        );
        assert_eq!(
            in_json_words("invalid type: sequence, expected a map"),
            "invalid type: a list, expected an object"
        );
        assert_eq!(
            in_json_words("invalid type: string \"x\", expected struct variant Shape::Gaussian"),
            "invalid type: string \"x\", expected an object"
        );
        assert_eq!(in_json_words("expected f32"), "expected a number");
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
