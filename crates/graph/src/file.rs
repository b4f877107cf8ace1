//! The graph file (`comp.json`): named instances of registry nodes, their parameter values,
//! their connections, the node whose image is written, and extra EXR layers.
//!
//! ```json
//! {"nodes": [
//!    {"name": "env",  "node": "org.nerfx.NeRFRender",
//!     "params": {"file": "env_scene.json", "shot": "shot.json", "quality": "final"}},
//!    {"name": "obj",  "node": "org.nerfx.NeRFRender",
//!     "params": {"file": "obj_scene.json", "shot": "shot.json"}},
//!    {"name": "comp", "node": "org.nerfx.ShadowCatcherMerge",
//!     "inputs": {"A": "obj", "B": "env"}, "params": {"tint": [0.1, 0.1, 0.2]}}],
//!  "output": "comp",
//!  "layers": {"env": "env"},
//!  "cryptomatte": ["obj", "env"],
//!  "deep": {"obj": "deep/obj.####.exr"},
//!  "colorspace": "acescg"}
//! ```
//!
//! `deep` (optional) maps NeRF Render nodes to the patterns of their deep scanline EXRs
//! (`####`: the frame; relative to the graph file): each node's render, its samples at their
//! depths, written per frame beside the graph's image (see [`Graph::deep`]).
//!
//! `cryptomatte` (optional) names NeRF Render nodes the output needs whose scene instances
//! get Cryptomatte layers (`CryptoObject00`, …) in the written EXR: each instance's coverage
//! in its node's own render, all the nodes' instances ranked together per pixel, one ID per
//! instance name (two nodes' instances of one name are one object). See
//! [`Graph::coverage`].
//!
//! `colorspace` (optional) is the colour space of the graph's images: every NeRF Render node
//! outputs it (one that names another is refused), and the EXR says so. Without it the NeRF
//! Render nodes the output needs must agree.
//!
//! Values are typed by the node's description: numbers, booleans, strings, arrays for
//! colours and 3-vectors, 16 numbers (row-major) or 4 rows for a matrix, and a choice by its
//! option identifier (`"final"`) or index. File parameters are relative to the graph file.
//! Everything is checked at load — unknown nodes, parameters, clips or upstream names,
//! out-of-range values, unconnected mandatory clips, cycles — with errors naming the file and
//! the node, so a farm job fails before its first frame rather than on it. A graph holds at
//! most [`Graph::MAX_NODES`] nodes; nothing walks it recursively, so its depth is free.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde_json::Value as Json;

use super::desc::ParamKind;
use super::node::Node;
use super::values::{ParamValues, Value};
use nerfx_core::camera::{Camera, Shot};
use nerfx_core::error::{Error, Result};
use nerfx_core::image::OutputColorSpace;

/// One node instance of a graph.
#[derive(Clone, Debug)]
pub struct GraphNode {
    /// Its name in the graph, unique.
    pub name: String,
    /// The registry node it instantiates.
    pub node: &'static Node,
    /// Its parameter values (file paths made absolute).
    pub values: ParamValues,
    /// Connected input clips: clip name → upstream node name.
    pub inputs: BTreeMap<String, String>,
}

/// A checked node graph.
#[derive(Clone, Debug)]
pub struct Graph {
    /// The nodes, upstream before downstream (every node after all its inputs).
    pub nodes: Vec<GraphNode>,
    /// The node whose image is the main (`R G B A`) layer of the output.
    pub output: String,
    /// Extra output layers: EXR layer name → node name (written as `layer.R` … `layer.A`).
    pub layers: Vec<(String, String)>,
    /// The colour space of the graph's images, written into the EXR's header.
    pub colorspace: OutputColorSpace,
    /// The NeRF Render nodes whose instances get Cryptomatte layers, in the file's order.
    pub cryptomatte: Vec<String>,
    /// NeRF Render nodes and the patterns of their deep EXRs (absolute), in the file's order.
    pub deep: Vec<(String, PathBuf)>,
}

impl Graph {
    /// The most nodes a graph may hold: far beyond a hand-built comp, and few enough that one
    /// plugin instance per node (the farm's path) stays within a render node's memory.
    pub const MAX_NODES: usize = 10_000;

    /// Reads and checks the graph file at `path`.
    pub fn read(path: &Path) -> Result<Graph> {
        let text = nerfx_core::read_text(path)?;
        Graph::from_json_str(&text, path)
    }

    /// Parses and checks a graph; `path` names the file in errors and anchors relative file
    /// parameters.
    pub fn from_json_str(text: &str, path: &Path) -> Result<Graph> {
        let bad = |location: &str, message: String| Error::format(path, location, message);
        let json: Json = nerfx_core::parse_json(text, path, "a node graph")?;
        if let Some(map) = json.as_object() {
            if let Some(key) = map.keys().find(|k| {
                ![
                    "nodes",
                    "output",
                    "layers",
                    "colorspace",
                    "cryptomatte",
                    "deep",
                ]
                .contains(&k.as_str())
            }) {
                return Err(bad(
                    key,
                    "unknown key (keys: nodes, output, layers, colorspace, cryptomatte, deep)"
                        .into(),
                ));
            }
        }
        let base = path.parent().unwrap_or(Path::new(""));
        let list = json
            .get("nodes")
            .and_then(Json::as_array)
            .ok_or_else(|| bad("nodes", "expected a list of nodes".into()))?;
        if list.len() > Graph::MAX_NODES {
            return Err(bad(
                "nodes",
                format!(
                    "{} nodes; a graph holds at most {}",
                    list.len(),
                    Graph::MAX_NODES
                ),
            ));
        }
        let mut nodes = Vec::with_capacity(list.len());
        let mut names = HashSet::with_capacity(list.len());
        for (i, entry) in list.iter().enumerate() {
            let node = read_node(entry, base).map_err(|e| match e {
                Error::Invalid { what, message } => bad(&format!("nodes[{i}]: {what}"), message),
                other => other,
            })?;
            if !names.insert(node.name.clone()) {
                return Err(bad(
                    &format!("nodes[{i}].name"),
                    format!("{:?} is used twice", node.name),
                ));
            }
            nodes.push(node);
        }
        let named = |key: &str, v: &Json| -> Result<String> {
            let name = v
                .as_str()
                .ok_or_else(|| bad(key, "expected a node name".into()))?;
            if !names.contains(name) {
                return Err(bad(key, format!("no node is named {name:?}")));
            }
            Ok(name.to_string())
        };
        let output = named("output", json.get("output").unwrap_or(&Json::Null))?;
        let mut layers = Vec::new();
        if let Some(map) = json.get("layers") {
            let map = map
                .as_object()
                .ok_or_else(|| bad("layers", "expected {\"layer\": \"node\", …}".into()))?;
            for (layer, node) in map {
                if layer.is_empty() || !layer.chars().all(|c| c.is_alphanumeric() || c == '_') {
                    return Err(bad(
                        &format!("layers.{layer}"),
                        "a layer name is letters, digits and _".into(),
                    ));
                }
                layers.push((layer.clone(), named(&format!("layers.{layer}"), node)?));
            }
        }
        let declared = match json.get("colorspace") {
            None => None,
            Some(v) => {
                let name = v
                    .as_str()
                    .ok_or_else(|| bad("colorspace", "expected a colour space name".into()))?;
                Some(
                    OutputColorSpace::parse(name, "colorspace").map_err(|e| match e {
                        Error::Invalid { message, .. } => bad("colorspace", message),
                        other => other,
                    })?,
                )
            }
        };
        let mut cryptomatte = Vec::new();
        if let Some(list) = json.get("cryptomatte") {
            let list = list
                .as_array()
                .ok_or_else(|| bad("cryptomatte", "expected a list of node names".into()))?;
            for (i, v) in list.iter().enumerate() {
                let key = format!("cryptomatte[{i}]");
                let name = named(&key, v)?;
                if cryptomatte.contains(&name) {
                    return Err(bad(&key, format!("{name:?} is named twice")));
                }
                cryptomatte.push(name);
            }
        }
        let mut deep = Vec::new();
        if let Some(map) = json.get("deep") {
            let map = map.as_object().ok_or_else(|| {
                bad(
                    "deep",
                    "expected an object: NeRF Render node → file pattern".into(),
                )
            })?;
            for (node, pattern) in map {
                let key = format!("deep.{node}");
                let pattern = pattern
                    .as_str()
                    .filter(|p| !p.is_empty())
                    .ok_or_else(|| bad(&key, "expected a file pattern (text)".into()))?;
                let render = nodes.iter().find(|n| n.name == *node);
                match render {
                    None => return Err(bad(&key, format!("no node is named {node:?}"))),
                    Some(n) if n.node.desc.id != super::nerf_render::NODE_ID => {
                        return Err(bad(
                            &key,
                            format!(
                                "node {node:?} is a {}; deep images come from NeRF Render nodes",
                                n.node.desc.id
                            ),
                        ))
                    }
                    Some(_) => deep.push((node.clone(), base.join(pattern))),
                }
            }
        }
        let nodes = upstream_first(nodes).map_err(|m| bad("nodes", m))?;
        let mut graph = Graph {
            nodes,
            output,
            layers,
            colorspace: OutputColorSpace::default(),
            cryptomatte,
            deep,
        };
        let need = graph.needed();
        for (i, name) in graph.cryptomatte.iter().enumerate() {
            let at = graph.nodes.iter().position(|n| n.name == *name);
            let Some(at) = at else { continue };
            let key = format!("cryptomatte[{i}]");
            if graph.nodes[at].node.desc.id != super::nerf_render::NODE_ID {
                return Err(bad(
                    &key,
                    format!(
                        "node {name:?} is a {}; Cryptomatte comes from NeRF Render nodes",
                        graph.nodes[at].node.desc.id
                    ),
                ));
            }
            if !need[at] {
                return Err(bad(
                    &key,
                    format!("node {name:?} is not upstream of the output or a layer"),
                ));
            }
        }
        graph.colorspace = graph
            .settle_color_space(declared)
            .map_err(|m| bad("colorspace", m))?;
        Ok(graph)
    }

    /// The one colour space of the graph's images: `declared` (the file's `colorspace`),
    /// which every NeRF Render node set to take its scene file's takes and none may
    /// contradict; without it, the one every needed NeRF Render node outputs (linear Rec.709
    /// when there is none; a scene file not readable yet counts for none). Compositing nodes
    /// keep the space of their inputs.
    fn settle_color_space(
        &mut self,
        declared: Option<OutputColorSpace>,
    ) -> std::result::Result<OutputColorSpace, String> {
        let need = self.needed();
        let mut found: Option<(String, OutputColorSpace)> = None;
        for (node, needed) in self.nodes.iter_mut().zip(need) {
            if node.node.desc.id != super::nerf_render::NODE_ID {
                continue;
            }
            let chosen = node
                .values
                .choice("outputColourSpace")
                .map_err(|e| e.to_string())?;
            if let Some(space) = declared {
                if chosen == "scene" {
                    node.values
                        .set_choice("outputColourSpace", space.name())
                        .map_err(|e| e.to_string())?;
                } else if chosen != space.name() {
                    return Err(format!(
                        "the graph is {}, but node {:?} outputs {chosen}",
                        space.name(),
                        node.name
                    ));
                }
                continue;
            }
            if !needed {
                continue;
            }
            // A scene file that cannot be read now is the render's to report.
            let Ok(space) = super::nerf_render::declared_color_space(&node.values) else {
                continue;
            };
            match &found {
                Some((other, s)) if *s != space => {
                    return Err(format!(
                        "node {:?} outputs {} and node {other:?} {}: say which space the \
                         graph is in with its \"colorspace\"",
                        node.name,
                        space.name(),
                        s.name()
                    ))
                }
                Some(_) => {}
                None => found = Some((node.name.clone(), space)),
            }
        }
        Ok(declared.or(found.map(|(_, s)| s)).unwrap_or_default())
    }

    /// Which nodes (in [`Graph::nodes`] order) the outputs depend on: the output, the layers,
    /// and everything upstream of them. Nothing else is rendered.
    pub fn needed(&self) -> Vec<bool> {
        let mut need: Vec<bool> = self
            .nodes
            .iter()
            .map(|n| n.name == self.output || self.layers.iter().any(|(_, l)| *l == n.name))
            .collect();
        let index = name_index(&self.nodes);
        // Downstream nodes come last, so one backward pass reaches every ancestor.
        for i in (0..self.nodes.len()).rev() {
            if need[i] {
                for up in self.nodes[i].inputs.values() {
                    if let Some(&j) = index.get(up.as_str()) {
                        need[j] = true;
                    }
                }
            }
        }
        need
    }

    /// The NeRF Render node the output image comes from: the first met walking up from the
    /// output node, inputs in clip order (`None` for a graph without one).
    pub fn output_render(&self) -> Option<&GraphNode> {
        let mut queue = std::collections::VecDeque::from([self.output.as_str()]);
        let mut seen = HashSet::new();
        while let Some(name) = queue.pop_front() {
            let node = self.node(name)?;
            if node.node.desc.id == super::nerf_render::NODE_ID {
                return Some(node);
            }
            for up in node.inputs.values() {
                if seen.insert(up.as_str()) {
                    queue.push_back(up);
                }
            }
        }
        None
    }

    /// The camera the output image was seen through at host time `time`, and its shot: the
    /// camera of [`Self::output_render`].
    pub fn output_camera(&self, time: f64) -> Result<Option<(Camera, Arc<Shot>)>> {
        self.output_render()
            .map(|node| super::nerf_render::node_camera(&node.values, time))
            .transpose()
    }

    /// The node named `name`.
    pub fn node(&self, name: &str) -> Option<&GraphNode> {
        self.nodes.iter().find(|n| n.name == name)
    }

    /// The NeRF Render nodes whose instances get Cryptomatte layers: those the file's
    /// `cryptomatte` names, or, when it names none and `all` is set, every one the output
    /// needs; in that order, leaving out a node that renders what an earlier one does (the
    /// same scene, shot and settings, another output or look of it), so that its instances'
    /// coverage is counted once.
    pub fn cryptomatte_nodes(&self, all: bool) -> Vec<String> {
        let listed: Vec<&GraphNode> = if !self.cryptomatte.is_empty() {
            self.cryptomatte
                .iter()
                .filter_map(|name| self.node(name))
                .collect()
        } else if all {
            self.nodes
                .iter()
                .zip(self.needed())
                .filter(|(n, needed)| *needed && n.node.desc.id == super::nerf_render::NODE_ID)
                .map(|(n, _)| n)
                .collect()
        } else {
            Vec::new()
        };
        let mut renders = Vec::new();
        let mut names = Vec::new();
        for node in listed {
            let render = super::nerf_render::render_values(&node.values);
            if !renders.contains(&render) {
                renders.push(render);
                names.push(node.name.clone());
            }
        }
        names
    }

    /// Each scene instance of the NeRF Render node `name` and its coverage of the window
    /// `window_of(width, height)` of the node's image at `time` and `render_scale` (as
    /// [`super::evaluate_window`] renders it): the instance's share of every pixel's
    /// opacity in the node's own render (its background and Source clip left out), so that
    /// a pixel's coverages add up to that render's alpha. Rendered by the node's own camera,
    /// transform, crop, quality and shutter, apart from its graph render (the same pixels
    /// as a separate march, with the instances in indicator colours).
    pub fn coverage(
        &self,
        name: &str,
        time: f64,
        render_scale: f64,
        window_of: &dyn Fn(u32, u32) -> Result<nerfx_core::image::Window>,
    ) -> Result<Vec<(String, nerfx_core::image::Plane)>> {
        let node = self.nerf_render(name)?;
        let scaled = nerfx_core::image::scaled_size;
        let covered = || {
            let (w, h) = node
                .node
                .region_of_definition(&node.values, time)?
                .unwrap_or((1, 1));
            let window = window_of(scaled(w, render_scale), scaled(h, render_scale))?;
            let request = super::node::RenderRequest::new(time, window, render_scale);
            super::nerf_render::node_coverage(&node.values, &request)
        };
        covered().map_err(|e| match e {
            Error::Invalid { what, message } => {
                Error::invalid(format!("graph node {name}: cryptomatte: {what}"), message)
            }
            other => other,
        })
    }

    /// The NeRF Render node `name`'s render of the window `window_of` gives for its image at
    /// `time` and `render_scale` (its RGBA, exposed and in its Output Colour Space, without
    /// its background and Source clip) and the deep image of it: its samples and fragments
    /// at their depths, merged within its quality preset's error target and at most
    /// `deep_samples` a pixel (the preset's cap without it), flattening to that RGBA.
    /// Rendered in process from the node's parameters, as its Cryptomatte coverage is.
    pub fn deep(
        &self,
        name: &str,
        time: f64,
        render_scale: f64,
        window_of: &dyn Fn(u32, u32) -> Result<nerfx_core::image::Window>,
        deep_samples: Option<u32>,
    ) -> Result<(nerfx_core::image::Planes, nerfx_core::image::DeepImage)> {
        let node = self.nerf_render(name)?;
        let rendered = || {
            let (w, h) = node
                .node
                .region_of_definition(&node.values, time)?
                .unwrap_or((1, 1));
            let scaled = nerfx_core::image::scaled_size;
            let window = window_of(scaled(w, render_scale), scaled(h, render_scale))?;
            let request = super::node::RenderRequest::new(time, window, render_scale);
            super::nerf_render::node_deep(&node.values, &request, deep_samples)
        };
        rendered().map_err(|e| match e {
            Error::Invalid { what, message } => {
                Error::invalid(format!("graph node {name}: deep: {what}"), message)
            }
            other => other,
        })
    }

    /// The camera of the NeRF Render node `name` at `time` (render scale 1), and its shot.
    pub fn node_camera(&self, name: &str, time: f64) -> Result<(Camera, Arc<Shot>)> {
        super::nerf_render::node_camera(&self.nerf_render(name)?.values, time)
    }

    /// The node `name`, which must be a NeRF Render node.
    fn nerf_render(&self, name: &str) -> Result<&GraphNode> {
        self.node(name)
            .filter(|n| n.node.desc.id == super::nerf_render::NODE_ID)
            .ok_or_else(|| {
                Error::invalid(format!("graph node {name}"), "is not a NeRF Render node")
            })
    }
}

/// One entry of `nodes`; errors are [`Error::Invalid`] naming the field within the entry.
fn read_node(entry: &Json, base: &Path) -> Result<GraphNode> {
    let keys = ["name", "node", "params", "inputs"];
    match entry.as_object() {
        None => return Err(Error::invalid("", "expected an object")),
        Some(map) => {
            if let Some(key) = map.keys().find(|k| !keys.contains(&k.as_str())) {
                return Err(Error::invalid(
                    key.as_str(),
                    format!("unknown key (keys: {})", keys.join(", ")),
                ));
            }
        }
    }
    let text = |key: &str| {
        entry
            .get(key)
            .and_then(Json::as_str)
            .ok_or_else(|| Error::invalid(key, "expected a string"))
    };
    let name = text("name")?.to_string();
    let node = super::node(text("node")?)?;
    let mut values = node.defaults();
    for (key, json) in object(entry, "params")? {
        let param = node.desc.param(key).ok_or_else(|| {
            let names: Vec<&str> = node.desc.params.iter().map(|p| p.name).collect();
            Error::invalid(
                format!("params.{key}"),
                format!("no such parameter (parameters: {})", names.join(", ")),
            )
        })?;
        let value = to_value(&param.kind, json, base).ok_or_else(|| {
            Error::invalid(
                format!("params.{key}"),
                match non_finite_entry(json) {
                    Some(i) => format!(
                        "entry {i} is NaN or infinite (written as null: JSON cannot hold it); \
                         {}",
                        describe(&param.kind)
                    ),
                    None => describe(&param.kind),
                },
            )
        })?;
        values.set(key, value).map_err(|e| match e {
            Error::Invalid { message, .. } => Error::invalid(format!("params.{key}"), message),
            other => other,
        })?;
    }
    // A graph renders unattended: a file left empty would render nothing without a word.
    if let Some(p) =
        node.desc.params.iter().find(|p| {
            matches!(p.kind, ParamKind::File) && values.text(p.name).is_ok_and(str::is_empty)
        })
    {
        return Err(Error::invalid(
            format!("params.{}", p.name),
            format!(
                "{}: no file given ({} must name one)",
                node.desc.label, p.label
            ),
        ));
    }
    let mut inputs = BTreeMap::new();
    for (clip, upstream) in object(entry, "inputs")? {
        if node.desc.clip(clip).is_none() {
            let clips: Vec<&str> = node.desc.clips.iter().map(|c| c.name).collect();
            return Err(Error::invalid(
                format!("inputs.{clip}"),
                format!(
                    "{} has no such clip (clips: {})",
                    node.desc.id,
                    clips.join(", ")
                ),
            ));
        }
        let upstream = upstream
            .as_str()
            .ok_or_else(|| Error::invalid(format!("inputs.{clip}"), "expected a node name"))?;
        inputs.insert(clip.clone(), upstream.to_string());
    }
    if let Some(c) = node
        .desc
        .clips
        .iter()
        .find(|c| !c.optional && !inputs.contains_key(c.name))
    {
        return Err(Error::invalid(
            format!("inputs.{}", c.name),
            format!("{} needs it connected", node.desc.id),
        ));
    }
    Ok(GraphNode {
        name,
        node,
        values,
        inputs,
    })
}

/// The object under `key` (absent = empty).
fn object<'a>(entry: &'a Json, key: &str) -> Result<Vec<(&'a String, &'a Json)>> {
    match entry.get(key) {
        None => Ok(Vec::new()),
        Some(Json::Object(map)) => Ok(map.iter().collect()),
        Some(_) => Err(Error::invalid(key, "expected an object")),
    }
}

/// The JSON value as a parameter value of `kind`, or `None` if it has the wrong shape (the
/// range is checked by [`ParamValues::set`]).
fn to_value(kind: &ParamKind, json: &Json, base: &Path) -> Option<Value> {
    let numbers =
        |j: &Json| -> Option<Vec<f64>> { j.as_array()?.iter().map(Json::as_f64).collect() };
    Some(match kind {
        ParamKind::Double { .. } => Value::Double(json.as_f64()?),
        ParamKind::Int { .. } => Value::Int(json.as_i64()?),
        ParamKind::Bool { .. } => Value::Bool(json.as_bool()?),
        ParamKind::Choice { options, .. } => Value::Choice(match json {
            Json::String(s) => options.iter().position(|(id, _)| id == s)?,
            other => usize::try_from(other.as_u64()?).ok()?,
        }),
        ParamKind::File => {
            let file = Path::new(json.as_str()?);
            let path: PathBuf = if file.as_os_str().is_empty() || file.is_absolute() {
                file.into()
            } else {
                base.join(file)
            };
            Value::Text(path.to_string_lossy().into_owned())
        }
        ParamKind::Text { .. } => Value::Text(json.as_str()?.to_string()),
        ParamKind::Rgb { .. } | ParamKind::Rgba { .. } | ParamKind::Double3 { .. } => {
            Value::Doubles(numbers(json)?)
        }
        ParamKind::Matrix { .. } => {
            let rows = json.as_array()?;
            if rows.iter().all(Json::is_array) {
                let mut flat = Vec::with_capacity(16);
                for row in rows {
                    let row = numbers(row)?;
                    if row.len() != 4 {
                        return None;
                    }
                    flat.extend(row);
                }
                Value::Doubles(flat)
            } else {
                Value::Doubles(numbers(json)?)
            }
        }
    })
}

/// The index, counted over a list or a list of rows, of its first null entry: a NaN or
/// infinity the file held (JSON has no such numbers; they read as null).
fn non_finite_entry(json: &Json) -> Option<usize> {
    let rows = json.as_array()?;
    let flat: Vec<&Json> = if rows.iter().all(Json::is_array) {
        rows.iter().filter_map(Json::as_array).flatten().collect()
    } else {
        rows.iter().collect()
    };
    flat.iter().position(|v| v.is_null())
}

/// What a parameter of `kind` is written as.
fn describe(kind: &ParamKind) -> String {
    match kind {
        ParamKind::Double { .. } => "expected a number".into(),
        ParamKind::Int { .. } => "expected a whole number".into(),
        ParamKind::Bool { .. } => "expected true or false".into(),
        ParamKind::Choice { options, .. } => {
            let ids: Vec<&str> = options.iter().map(|o| o.0).collect();
            format!("expected one of {}", ids.join(", "))
        }
        ParamKind::File | ParamKind::Text { .. } => "expected a string".into(),
        ParamKind::Rgb { .. } | ParamKind::Double3 { .. } => "expected 3 numbers".into(),
        ParamKind::Rgba { .. } => "expected 4 numbers".into(),
        ParamKind::Matrix { .. } => "expected 16 numbers (row-major) or 4 rows of 4".into(),
    }
}

/// Each node's position in `nodes` by name.
fn name_index(nodes: &[GraphNode]) -> HashMap<&str, usize> {
    nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.name.as_str(), i))
        .collect()
}

/// The nodes reordered so that every node comes after its inputs (Kahn's algorithm, stable:
/// of the nodes ready, the first in the file's order goes first); unknown upstream names and
/// cycles are refused.
fn upstream_first(nodes: Vec<GraphNode>) -> std::result::Result<Vec<GraphNode>, String> {
    let index = name_index(&nodes);
    // Per node: how many of its connections are not yet ordered, and who reads it.
    let mut waiting = vec![0usize; nodes.len()];
    let mut readers: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        for (clip, up) in &n.inputs {
            let &j = index
                .get(up.as_str())
                .ok_or_else(|| format!("{}.inputs.{clip}: no node is named {up:?}", n.name))?;
            waiting[i] += 1;
            readers[j].push(i);
        }
    }
    let mut ready: BinaryHeap<Reverse<usize>> = (0..nodes.len())
        .filter(|&i| waiting[i] == 0)
        .map(Reverse)
        .collect();
    let mut order = Vec::with_capacity(nodes.len());
    while let Some(Reverse(i)) = ready.pop() {
        order.push(i);
        for &r in &readers[i] {
            waiting[r] -= 1;
            if waiting[r] == 0 {
                ready.push(Reverse(r));
            }
        }
    }
    if order.len() < nodes.len() {
        let stuck: Vec<&str> = (0..nodes.len())
            .filter(|&i| waiting[i] > 0)
            .map(|i| nodes[i].name.as_str())
            .collect();
        let shown = stuck.len().min(10);
        let more = match stuck.len() - shown {
            0 => String::new(),
            n => format!(" and {n} more"),
        };
        return Err(format!(
            "the inputs of {}{more} form a cycle",
            stuck[..shown].join(", ")
        ));
    }
    let mut slots: Vec<Option<GraphNode>> = nodes.into_iter().map(Some).collect();
    Ok(order.into_iter().filter_map(|i| slots[i].take()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Graph> {
        Graph::from_json_str(text, Path::new("/shots/a/comp.json"))
    }

    const GOOD: &str = r#"{"nodes": [
        {"name": "comp", "node": "org.nerfx.DepthMerge",
         "inputs": {"A": "obj", "ADepth": "objZ", "B": "env", "BDepth": "envZ"},
         "params": {"softness": 0.25}},
        {"name": "env", "node": "org.nerfx.NeRFRender",
         "params": {"file": "env.json", "shot": "/abs/shot.json", "quality": "draft",
                    "objectTransform": [[2,0,0,1],[0,2,0,0],[0,0,2,0],[0,0,0,1]]}},
        {"name": "envZ", "node": "org.nerfx.NeRFRender",
         "params": {"file": "env.json", "shot": "s.json", "output": 2}},
        {"name": "obj", "node": "org.nerfx.NeRFRender",
         "params": {"file": "obj.json", "shot": "s.json", "background": [0,0,0,0]}},
        {"name": "objZ", "node": "org.nerfx.NeRFRender",
         "params": {"file": "obj.json", "shot": "s.json"}}],
      "output": "comp", "layers": {"env": "env"}}"#;

    /// `cryptomatte` names NeRF Render nodes the output needs; a node rendering what an
    /// earlier one does is matted once; `--cryptomatte` without the key takes every needed
    /// NeRF Render.
    #[test]
    fn cryptomatte_names_needed_renders_and_counts_each_render_once() {
        let with = |list: &str| {
            let key = format!(r#""layers": {{"env": "env"}}, "cryptomatte": {list}"#);
            parse(&GOOD.replace(r#""layers": {"env": "env"}"#, &key))
        };
        let g = with(r#"["obj", "env", "objZ"]"#).unwrap();
        assert_eq!(g.cryptomatte, ["obj", "env", "objZ"]);
        // objZ renders what obj does (they differ only in the background).
        assert_eq!(g.cryptomatte_nodes(false), ["obj", "env"]);
        assert_eq!(g.cryptomatte_nodes(true), ["obj", "env"]);
        let plain = parse(GOOD).unwrap();
        assert!(plain.cryptomatte_nodes(false).is_empty());
        let mut all = plain.cryptomatte_nodes(true);
        all.sort();
        assert_eq!(all, ["env", "envZ", "obj"]);
        for (list, said) in [
            (
                r#"["comp"]"#,
                "cryptomatte[0]: node \"comp\" is a org.nerfx.DepthMerge",
            ),
            (r#"["env", "nobody"]"#, "cryptomatte[1]: no node is named"),
            (
                r#"["env", "env"]"#,
                "cryptomatte[1]: \"env\" is named twice",
            ),
            (r#""env""#, "cryptomatte: expected a list"),
        ] {
            let e = with(list).unwrap_err().to_string();
            assert!(e.contains(said), "{list}: {e}");
        }
    }

    #[test]
    fn the_graph_colour_space_reaches_every_render_and_is_not_contradicted() {
        let with_b = |colorspace: &str, node_space: &str, b_space: &str| {
            format!(
                r#"{{"nodes": [
                {{"name": "a", "node": "org.nerfx.NeRFRender",
                  "params": {{"file": "a.json", "shot": "s.json"{node_space}}}}},
                {{"name": "b", "node": "org.nerfx.NeRFRender",
                  "params": {{"file": "b.json", "shot": "s.json"{b_space}}}}}],
              "output": "a", "layers": {{"b": "b"}}{colorspace}}}"#
            )
        };
        let with = |colorspace: &str, node_space: &str| with_b(colorspace, node_space, "");
        let g = parse(&with(r#", "colorspace": "acescg""#, "")).unwrap();
        assert_eq!(g.colorspace, OutputColorSpace::AcesCg);
        for n in &g.nodes {
            assert_eq!(n.values.choice("outputColourSpace").unwrap(), "acescg");
        }
        let same = r#", "outputColourSpace": "acescg""#;
        assert!(parse(&with(r#", "colorspace": "acescg""#, same)).is_ok());
        let e = parse(&with(
            r#", "colorspace": "acescg""#,
            r#", "outputColourSpace": "srgb""#,
        ))
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("colorspace") && e.contains("\"a\" outputs srgb"),
            "{e}"
        );
        let e = parse(&with(r#", "colorspace": "rec709""#, ""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown colour space 'rec709'"), "{e}");
        // Without the key: the nodes' own, which must agree (b's scene file cannot be read
        // here, so it counts only when it names its space itself).
        let p3 = r#", "outputColourSpace": "lin_p3d65""#;
        assert_eq!(
            parse(&with("", p3)).unwrap().colorspace,
            OutputColorSpace::LinP3D65
        );
        let e = parse(&with_b("", p3, r#", "outputColourSpace": "lin_rec709""#))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("lin_p3d65") && e.contains("say which space"),
            "{e}"
        );
        let g = parse(&with("", "")).unwrap();
        assert_eq!(g.colorspace, OutputColorSpace::LinRec709);
    }

    #[test]
    fn a_graph_is_read_typed_and_ordered_upstream_first() {
        let g = parse(GOOD).unwrap();
        let order: Vec<&str> = g.nodes.iter().map(|n| n.name.as_str()).collect();
        assert_eq!(order, ["env", "envZ", "obj", "objZ", "comp"]);
        let env = &g.node("env").unwrap().values;
        assert_eq!(env.text("file").unwrap(), "/shots/a/env.json");
        assert_eq!(env.text("shot").unwrap(), "/abs/shot.json");
        assert_eq!(env.choice("quality").unwrap(), "draft");
        let m = env.doubles("objectTransform").unwrap();
        assert_eq!((m[0], m[3], m[5], m[15]), (2.0, 1.0, 2.0, 1.0));
        assert_eq!(
            g.node("comp").unwrap().values.double("softness").unwrap(),
            0.25
        );
        assert_eq!(g.layers, [("env".to_string(), "env".to_string())]);
    }

    #[test]
    fn a_nan_in_a_matrix_is_named() {
        for (from, to) in [
            ("[0,2,0,0]", "[0,NaN,0,0]"),
            ("[0,2,0,0]", "[0,2,Infinity,0]"),
        ] {
            let e = parse(&GOOD.replace(from, to)).unwrap_err().to_string();
            let at = if to.contains("NaN") { 5 } else { 6 };
            assert!(
                e.contains("objectTransform")
                    && e.contains(&format!("entry {at} is NaN or infinite")),
                "{e}"
            );
        }
        // A flat list too; a short one is still described by its shape.
        let flat = GOOD.replace(
            "[[2,0,0,1],[0,2,0,0],[0,0,2,0],[0,0,0,1]]",
            "[2,0,0,1, 0,2,0,0, 0,0,NaN,0, 0,0,0,1]",
        );
        let e = parse(&flat).unwrap_err().to_string();
        assert!(e.contains("entry 10 is NaN"), "{e}");
        let short = GOOD.replace("[[2,0,0,1],[0,2,0,0],[0,0,2,0],[0,0,0,1]]", "[1, 2]");
        let e = parse(&short).unwrap_err().to_string();
        assert!(e.contains("16") && !e.contains("NaN"), "{e}");
    }

    #[test]
    fn mistakes_are_refused_naming_file_and_node() {
        let cases = [
            (
                GOOD.replace("\"softness\": 0.25", "\"softness\": -1"),
                "softness",
            ),
            (
                GOOD.replace("\"quality\": \"draft\"", "\"quality\": \"best\""),
                "draft, preview, final",
            ),
            (
                GOOD.replace("\"BDepth\": \"envZ\"", "\"BDepth\": \"nowhere\""),
                "nowhere",
            ),
            (GOOD.replace("\"B\": \"env\", ", ""), "inputs.B"),
            (GOOD.replace("\"ADepth\"", "\"Depth\""), "no such clip"),
            (
                GOOD.replace("org.nerfx.DepthMerge", "org.nerfx.Blur"),
                "no such node",
            ),
            (
                GOOD.replace("\"name\": \"objZ\"", "\"name\": \"obj\""),
                "used twice",
            ),
            (
                GOOD.replace("\"output\": \"comp\"", "\"output\": \"final\""),
                "final",
            ),
            (
                GOOD.replace("\"output\": 2}", "\"output\": 2, \"size\": 1}"),
                "params.size",
            ),
            (GOOD.replace("[0,0,0,0]", "[0,0,0]"), "expected 4 values"),
            (
                GOOD.replace("\"layers\": {\"env\"", "\"layers\": {\"a.b\""),
                "layer name",
            ),
            (
                GOOD.replace("\"comp\", \"node\"", "\"comp\" \"node\""),
                "line 2",
            ),
            (
                GOOD.replace("\"file\": \"env.json\", ", ""),
                "no file given",
            ),
        ];
        for (text, needle) in cases {
            let e = parse(&text).unwrap_err().to_string();
            assert!(e.contains("/shots/a/comp.json"), "{e}");
            assert!(e.contains(needle), "{needle:?} not in {e}");
        }
    }

    #[test]
    fn cycles_are_refused() {
        let text = r#"{"nodes": [
            {"name": "a", "node": "org.nerfx.AccumulationMatte", "inputs": {"Source": "b"}},
            {"name": "b", "node": "org.nerfx.AccumulationMatte", "inputs": {"Source": "a"}}],
          "output": "a"}"#;
        let e = parse(text).unwrap_err().to_string();
        assert!(e.contains("a, b form a cycle"), "{e}");
    }
}
