//! The node reference page of the user's guide, written from the registry, so the page
//! cannot drift from the nodes (`nerfx reference nodes` prints it; a test compares it with
//! `docs/src/reference/nodes.md`).

use std::fmt::Write;

use super::desc::{ClipKind, Context, NodeDesc, ParamDesc, ParamKind, Range};

/// The reference of every node in `nodes`, as Markdown.
pub fn nodes_markdown(nodes: &[&NodeDesc]) -> String {
    let mut md = String::from(
        "# Node reference\n\n\
         Generated from the node registry by `nerfx reference nodes`; do not edit by hand.\n\
         Every node is in the menu group shown, outputs premultiplied float RGBA, supports \
         tiles and render scales, and is identified by the id shown (graph files name nodes \
         by it and parameters by their script names).\n",
    );
    for desc in nodes {
        node(&mut md, desc);
    }
    md
}

fn node(md: &mut String, desc: &NodeDesc) {
    let contexts: Vec<&str> = desc.contexts.iter().map(|c| context(*c)).collect();
    let _ = write!(
        md,
        "\n## {}\n\n{}\n\n- id: `{}`\n- menu group: {}\n- contexts: {}\n- output changes from \
         frame to frame: {}\n",
        desc.label,
        desc.hint,
        desc.id,
        desc.group,
        contexts.join(", "),
        if desc.frame_varying { "yes" } else { "no" }
    );
    if !desc.clips.is_empty() {
        md.push_str("\n### Inputs\n\n| clip | label | read as | optional | contexts | what it is |\n|---|---|---|---|---|---|\n");
        for clip in &desc.clips {
            let contexts: Vec<&str> = clip.contexts.iter().map(|c| context(*c)).collect();
            let _ = writeln!(
                md,
                "| `{}` | {} | {} | {} | {} | {} |",
                clip.name,
                clip.label,
                clip_kind(clip.kind),
                if clip.optional { "yes" } else { "no" },
                contexts.join(", "),
                cell(clip.hint)
            );
        }
    }
    if !desc.params.is_empty() {
        md.push_str("\n### Parameters\n\n| script name | label | type | default | range | animates | what it does |\n|---|---|---|---|---|---|---|\n");
        for param in &desc.params {
            param_row(md, param);
        }
    }
}

fn param_row(md: &mut String, p: &ParamDesc) {
    let (kind, default, range) = match &p.kind {
        ParamKind::Double { default, range } => ("real", number(*default), range_text(range)),
        ParamKind::Int { default, range } => ("integer", default.to_string(), range_text(range)),
        ParamKind::Bool { default } => ("check box", default.to_string(), String::new()),
        ParamKind::Choice { options, default } => {
            let names: Vec<String> = options
                .iter()
                .map(|(id, label)| format!("`{id}` ({label})"))
                .collect();
            let default = options
                .get(*default)
                .map_or_else(String::new, |(id, _)| format!("`{id}`"));
            ("choice", default, names.join(", "))
        }
        ParamKind::File => ("file", "none".to_string(), String::new()),
        ParamKind::Text { default } => ("text", format!("`{default}`"), String::new()),
        ParamKind::Rgb { default, range } => ("RGB", numbers(default), range_text(range)),
        ParamKind::Rgba { default, range } => ("RGBA", numbers(default), range_text(range)),
        ParamKind::Double3 { default, range } => ("3 reals", numbers(default), range_text(range)),
        ParamKind::Matrix { default } => {
            let identity = default
                .iter()
                .enumerate()
                .all(|(i, v)| *v == if i % 5 == 0 { 1.0 } else { 0.0 });
            let default = if identity {
                "identity".to_string()
            } else {
                numbers(default)
            };
            ("4×4 matrix (16 numbers, row-major)", default, String::new())
        }
    };
    let spatial = if p.spatial {
        " In pixels: the render scale applies."
    } else {
        ""
    };
    let _ = writeln!(
        md,
        "| `{}` | {} | {} | {} | {} | {} | {}{} |",
        p.name,
        p.label,
        kind,
        default,
        range,
        if p.animates { "yes" } else { "no" },
        cell(p.hint),
        spatial
    );
}

fn context(c: Context) -> &'static str {
    match c {
        Context::Generator => "Generator",
        Context::Filter => "Filter",
        Context::General => "General",
    }
}

fn clip_kind(k: ClipKind) -> &'static str {
    match k {
        ClipKind::Rgba => "premultiplied RGBA",
        ClipKind::Matte => "a grey matte",
        ClipKind::Alpha => "its alpha",
        ClipKind::Depth => "camera Z (Blender units)",
    }
}

fn range_text(r: &Range) -> String {
    let mut text = format!("{} to {}", number(r.min), number(r.max));
    if (r.display_min, r.display_max) != (r.min, r.max) {
        let _ = write!(
            text,
            " (slider {} to {})",
            number(r.display_min),
            number(r.display_max)
        );
    }
    text
}

/// A number as an artist reads it: no trailing zeros, huge bounds in words.
fn number(v: f64) -> String {
    if v.abs() >= f64::MAX / 2.0 {
        "no limit".into()
    } else if v.abs() >= 1e6 && v.fract() == 0.0 {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

fn numbers(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| number(*x)).collect();
    parts.join(" ")
}

/// Text fit for a table cell: one line, pipes escaped.
fn cell(text: &str) -> String {
    text.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace('|', "\\|")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_node_and_parameter_is_on_the_page() {
        let descs: Vec<&NodeDesc> = crate::nodes().iter().map(|n| &n.desc).collect();
        let md = nodes_markdown(&descs);
        for d in &descs {
            assert!(md.contains(&format!("`{}`", d.id)), "{}", d.id);
            for p in &d.params {
                assert!(md.contains(&format!("| `{}` |", p.name)), "{}", p.name);
            }
            for c in &d.clips {
                assert!(md.contains(&format!("| `{}` |", c.name)), "{}", c.name);
            }
        }
        assert_eq!(number(f64::MAX), "no limit");
        assert_eq!(number(0.5), "0.5");
        assert_eq!(number(2.0), "2");
    }
}
