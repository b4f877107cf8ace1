//! A small YAML writer for the job files: block mappings (keys in the order given) and
//! sequences, every string double-quoted with JSON's escapes (which are YAML's), so that no
//! value is ever read back as another type.

use std::fmt::Write;

/// A YAML value.
#[derive(Clone, Debug, PartialEq)]
pub enum Node {
    /// A string, always quoted.
    Str(String),
    /// A whole number.
    Int(i64),
    /// A sequence.
    List(Vec<Node>),
    /// A mapping, in this order.
    Map(Vec<(String, Node)>),
}

/// A string node.
pub fn s(text: impl Into<String>) -> Node {
    Node::Str(text.into())
}

/// A mapping node from `(key, value)` pairs.
pub fn map<'a>(entries: impl IntoIterator<Item = (&'a str, Node)>) -> Node {
    Node::Map(
        entries
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
    )
}

/// A sequence of string nodes.
pub fn strings<T: AsRef<str>>(items: &[T]) -> Node {
    Node::List(items.iter().map(|i| s(i.as_ref())).collect())
}

/// `node` as a YAML document.
pub fn to_yaml(node: &Node) -> String {
    let mut out = String::new();
    block(&mut out, node, 0);
    out
}

/// A scalar, or `None` for a mapping or sequence with entries.
fn scalar(node: &Node) -> Option<String> {
    match node {
        Node::Str(text) => Some(serde_json::Value::String(text.clone()).to_string()),
        Node::Int(n) => Some(n.to_string()),
        Node::List(items) if items.is_empty() => Some("[]".into()),
        Node::Map(entries) if entries.is_empty() => Some("{}".into()),
        _ => None,
    }
}

/// Writes the entries of a mapping or sequence at `indent`.
fn block(out: &mut String, node: &Node, indent: usize) {
    let pad = " ".repeat(indent);
    match node {
        Node::Map(entries) => {
            for (key, value) in entries {
                match scalar(value) {
                    Some(text) => {
                        let _ = writeln!(out, "{pad}{key}: {text}");
                    }
                    None => {
                        let _ = writeln!(out, "{pad}{key}:");
                        // Sequences sit at their key's indent, mappings one level in.
                        let inner = match value {
                            Node::List(_) => indent,
                            _ => indent + 2,
                        };
                        block(out, value, inner);
                    }
                }
            }
        }
        Node::List(items) => {
            for item in items {
                match scalar(item) {
                    Some(text) => {
                        let _ = writeln!(out, "{pad}- {text}");
                    }
                    None => {
                        // The item's first line follows the dash; the rest align under it.
                        let mut inner = String::new();
                        block(&mut inner, item, indent + 2);
                        let rest = inner.get(indent + 2..).unwrap_or_default();
                        let _ = write!(out, "{pad}- {rest}");
                    }
                }
            }
        }
        other => {
            if let Some(text) = scalar(other) {
                let _ = writeln!(out, "{pad}{text}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_documents() {
        let doc = map([
            ("name", s("a \"b\"")),
            ("n", Node::Int(3)),
            ("list", Node::List(vec![s("x"), Node::Int(1)])),
            (
                "steps",
                Node::List(vec![map([
                    ("name", s("Render")),
                    ("args", strings(&["--frames", "1-4"])),
                    ("deep", map([("k", Node::Int(-1))])),
                ])]),
            ),
            ("empty", Node::List(vec![])),
        ]);
        assert_eq!(
            to_yaml(&doc),
            "name: \"a \\\"b\\\"\"\nn: 3\nlist:\n- \"x\"\n- 1\nsteps:\n- name: \"Render\"\n  \
             args:\n  - \"--frames\"\n  - \"1-4\"\n  deep:\n    k: -1\nempty: []\n"
        );
    }
}
