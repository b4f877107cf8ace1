//! The demo as a compositor puts it together: the object and its environment rendered apart,
//! a shadow caught on the environment and the object merged in by depth, as a node graph
//! (`nerfx demo` renders it).

use std::path::{Path, PathBuf};

use nerfx_core::demo::{scene_desc, shadow_desc, shot, FIRST_FRAME};
use nerfx_core::error::{Error, Result};
use nerfx_core::image::Planes;
use nerfx_core::render::Quality;
use nerfx_core::scene::SceneDesc;

use crate::{evaluate, Graph};

/// Writes the demo's node graph and everything it reads into `dir` and returns the graph's
/// path: the environment and the object as separate scene files, each rendered as RGBA and
/// as depth, a shadow pass, a shadow-catcher merge of the shadow onto the environment and a
/// depth merge of the object into the result (the object inside the environment), with the
/// object and the shadow pass as extra EXR layers. `nerfx render` evaluates it through the
/// OpenFX bundle, the path a compositor takes.
pub fn write_graph(dir: &Path, width: u32, height: u32) -> Result<PathBuf> {
    let [environment, object] = [0, 1].map(|i| SceneDesc {
        instances: vec![scene_desc().instances[i].clone()],
        colorspace: None,
    });
    environment.write(&dir.join("demo_environment.json"))?;
    object.write(&dir.join("demo_object.json"))?;
    shadow_desc().write(&dir.join("demo_shadow.json"))?;
    shot(width, height).write(dir.join("demo_shot.json"))?;
    let render = |name: &str, file: &str, output: &str| {
        serde_json::json!({"name": name, "node": "org.nerfx.NeRFRender",
            "params": {"file": file, "shot": "demo_shot.json", "output": output}})
    };
    let graph = serde_json::json!({
        "nodes": [
            render("env", "demo_environment.json", "rgba"),
            render("envZ", "demo_environment.json", "depthZ"),
            render("obj", "demo_object.json", "rgba"),
            render("objZ", "demo_object.json", "depthZ"),
            render("shadow", "demo_shadow.json", "accumulation"),
            {"name": "caught", "node": "org.nerfx.ShadowCatcherMerge",
             "inputs": {"Shadow": "shadow", "B": "env"},
             "params": {"opacity": 0.8, "tint": [0.05, 0.06, 0.1]}},
            {"name": "comp", "node": "org.nerfx.DepthMerge",
             "inputs": {"A": "obj", "ADepth": "objZ", "B": "caught", "BDepth": "envZ"},
             "params": {"softness": 0.05}}
        ],
        "output": "comp",
        "layers": {"object": "obj", "shadow": "shadow"}
    });
    let path = dir.join("demo_comp.json");
    let text = serde_json::to_string_pretty(&graph)
        .map_err(|e| Error::invalid("demo graph", e.to_string()))?;
    nerfx_core::write_file(&path, text.as_bytes())?;
    Ok(path)
}

/// The demo's composite, its extra layers and the graph it came from.
#[derive(Clone, Debug)]
pub struct Comp {
    /// The graph's output: the object in its environment, premultiplied RGBA.
    pub image: Planes,
    /// The graph's extra layers by EXR layer name.
    pub layers: Vec<(String, Planes)>,
    /// The graph file.
    pub graph: PathBuf,
    /// `(node name, text)` for each node whose render the user should hear about (rays at
    /// their sample budget), in the order they rendered.
    pub warnings: Vec<(String, String)>,
}

/// Renders the demo's composite at its first frame: writes the demo's files into `dir` (the
/// joint scene [`scene_desc`], and [`write_graph`]'s graph with everything it reads), then
/// evaluates the graph in process with the node registry, each NeRF Render at `quality`:
/// the nodes a compositor runs, without the OpenFX bundle.
pub fn render_comp(dir: &Path, width: u32, height: u32, quality: Quality) -> Result<Comp> {
    scene_desc().write(&dir.join("demo_scene.json"))?;
    let path = write_graph(dir, width, height)?;
    let mut graph = Graph::read(&path)?;
    for node in &mut graph.nodes {
        if node.node.desc.id == "org.nerfx.NeRFRender" {
            node.values.set_choice("quality", quality.name())?;
        }
    }
    let mut warnings = Vec::new();
    let mut images = evaluate(
        &graph,
        FIRST_FRAME as f64,
        1.0,
        false,
        &mut |node, request| {
            let rendered = node.node.render_with_stats(&node.values, request)?;
            if let Some(warning) = rendered.stats.warning() {
                warnings.push((node.name.clone(), warning));
            }
            Ok(rendered.planes)
        },
        &|_| {},
    )?;
    let mut take = |node: &str| {
        images
            .remove(node)
            .ok_or_else(|| Error::invalid("demo graph", format!("node {node} was not rendered")))
    };
    let image = take(&graph.output)?;
    let layers = graph
        .layers
        .iter()
        .map(|(layer, node)| Ok((layer.clone(), take(node)?)))
        .collect::<Result<_>>()?;
    Ok(Comp {
        image,
        layers,
        graph: path,
        warnings,
    })
}
