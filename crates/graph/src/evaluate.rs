//! Evaluating a graph for one frame: every needed node once, upstream first, each over its
//! whole image.
//!
//! Who renders a node is the caller's choice: the registry directly ([`render_direct`]), or
//! an OpenFX instance of the bundle through the host (the farm's path, `host` feature). Both
//! see the same requests, so their images can be compared pixel for pixel.

use std::collections::{BTreeMap, HashMap};

use super::file::{Graph, GraphNode};
use super::node::RenderRequest;
use nerfx_core::error::{Error, Result};
use nerfx_core::image::{scaled_size, Planes, Window};

/// Renders one node for `request` (whose inputs are its upstream nodes' images of the
/// request's window).
pub type RenderNode<'a> = dyn FnMut(&GraphNode, &RenderRequest) -> Result<Planes> + 'a;

/// The image size of `node` at `render_scale`: its own region of definition (a NeRF Render:
/// the shot's resolution, `ceil(n·s)` as the camera has it), else that of its inputs (their
/// whole images' sizes, by clip), which must agree.
fn image_size(
    node: &GraphNode,
    time: f64,
    render_scale: f64,
    inputs: &[(&String, (u32, u32))],
) -> Result<(u32, u32)> {
    if let Some((w, h)) = node.node.region_of_definition(&node.values, time)? {
        return Ok((scaled_size(w, render_scale), scaled_size(h, render_scale)));
    }
    let mut sizes = inputs.iter().copied();
    let Some((_, size)) = sizes.next() else {
        return Err(Error::invalid(
            format!("graph node {}", node.name),
            "has no input to take its size from",
        ));
    };
    match sizes.find(|(_, s)| *s != size) {
        Some((clip, (w, h))) => Err(Error::invalid(
            format!("graph node {}: clip {clip}", node.name),
            format!("is {w}×{h}, the other inputs {}×{}", size.0, size.1),
        )),
        None => Ok(size),
    }
}

/// Renders the nodes of `graph` that its outputs need at `time` and `render_scale` with
/// `render_node`, and returns the images of the output and the layers by node name. `on_node`
/// hears each node's name as it finishes (for a progress bar).
///
/// An intermediate image lives until its last consumer has rendered, so the images alive at
/// once are bounded by the graph's width, not its length: a chain of any length holds two.
pub fn evaluate(
    graph: &Graph,
    time: f64,
    render_scale: f64,
    draft: bool,
    render_node: &mut RenderNode<'_>,
    on_node: &dyn Fn(&str),
) -> Result<BTreeMap<String, Planes>> {
    let whole = |w, h| Ok(Window::new(0, 0, w, h));
    evaluate_window(
        graph,
        time,
        render_scale,
        draft,
        &whole,
        render_node,
        on_node,
    )
}

/// [`evaluate`] over part of each image: every node renders the window `window_of(width,
/// height)` of its whole image (its inputs are their nodes' images of that window), so the
/// images returned are that window of the whole images. Every node composites pixel by
/// pixel, so the window's pixels are the whole images' (a frame rendered in stripes on
/// several machines joins into the whole frame).
pub fn evaluate_window(
    graph: &Graph,
    time: f64,
    render_scale: f64,
    draft: bool,
    window_of: &dyn Fn(u32, u32) -> Result<Window>,
    render_node: &mut RenderNode<'_>,
    on_node: &dyn Fn(&str),
) -> Result<BTreeMap<String, Planes>> {
    let need = graph.needed();
    let index: HashMap<&str, usize> = graph
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| (n.name.as_str(), i))
        .collect();
    let kept: Vec<bool> = graph
        .nodes
        .iter()
        .map(|n| n.name == graph.output || graph.layers.iter().any(|(_, l)| *l == n.name))
        .collect();
    // How many connections of needed nodes still have to read each node's image.
    let mut readers = vec![0usize; graph.nodes.len()];
    for (node, _) in graph.nodes.iter().zip(&need).filter(|(_, &n)| n) {
        for up in node.inputs.values().filter_map(|up| index.get(up.as_str())) {
            readers[*up] += 1;
        }
    }
    // The images still to be read, by node index, and the sizes of the whole images.
    let mut images: BTreeMap<usize, Planes> = BTreeMap::new();
    let mut sizes: HashMap<usize, (u32, u32)> = HashMap::new();
    for (i, node) in graph.nodes.iter().enumerate().filter(|(i, _)| need[*i]) {
        let mut inputs = BTreeMap::new();
        let mut input_sizes = Vec::new();
        for (clip, up) in &node.inputs {
            let Some(&j) = index.get(up.as_str()) else {
                continue;
            };
            if let Some(&size) = sizes.get(&j) {
                input_sizes.push((clip, size));
            }
            readers[j] -= 1;
            // The last reader takes the image; earlier ones (and outputs) copy it.
            let image = if readers[j] == 0 && !kept[j] {
                images.remove(&j)
            } else {
                images.get(&j).cloned()
            };
            if let Some(image) = image {
                inputs.insert(clip.clone(), image);
            }
        }
        // Every failure names the node it happened in.
        let named = |e: Error| match e {
            Error::Invalid { what, message } => {
                Error::invalid(format!("graph node {}: {what}", node.name), message)
            }
            other => Error::invalid(
                format!("graph node {} ({})", node.name, node.node.desc.id),
                other.to_string(),
            ),
        };
        let (w, h) = image_size(node, time, render_scale, &input_sizes).map_err(named)?;
        let window = window_of(w, h).map_err(named)?;
        let request = RenderRequest {
            draft,
            inputs,
            image_size: (w, h),
            ..RenderRequest::new(time, window, render_scale)
        };
        let planes = render_node(node, &request).map_err(named)?;
        // The inputs go before the next node's are gathered.
        drop(request);
        on_node(&node.name);
        if readers[i] > 0 || kept[i] {
            images.insert(i, planes);
            sizes.insert(i, (w, h));
        }
    }
    Ok(images
        .into_iter()
        .map(|(i, image)| (graph.nodes[i].name.clone(), image))
        .collect())
}

/// Renders a node with the registry, in process: the reference for the OpenFX path.
pub fn render_direct(node: &GraphNode, request: &RenderRequest) -> Result<Planes> {
    node.node.render(&node.values, request)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn graph() -> Graph {
        let text = r#"{"nodes": [
            {"name": "a", "node": "org.nerfx.NeRFRender", "params": {"file": "s", "shot": "t"}},
            {"name": "unused", "node": "org.nerfx.NeRFRender",
             "params": {"file": "s", "shot": "t"}},
            {"name": "m", "node": "org.nerfx.AccumulationMatte", "inputs": {"Source": "a"}},
            {"name": "b", "node": "org.nerfx.NeRFRender", "params": {"file": "s", "shot": "t"}}],
          "output": "m", "layers": {"extra": "b"}}"#;
        Graph::from_json_str(text, Path::new("comp.json")).unwrap()
    }

    #[test]
    fn only_needed_nodes_render_upstream_first_with_their_inputs() {
        let g = graph();
        let rendered = std::cell::RefCell::new(Vec::new());
        // A stand-in renderer: NeRF Renders have no shot here, so it makes 3×2 images.
        let mut render = |node: &GraphNode, request: &RenderRequest| -> Result<Planes> {
            let clips: Vec<&String> = request.inputs.keys().collect();
            rendered
                .borrow_mut()
                .push(format!("{}{clips:?}", node.name));
            let p = nerfx_core::image::Plane::filled(3, 2, 0.5);
            Ok(Planes {
                width: 3,
                height: 2,
                rgb: Some([p.clone(), p.clone(), p.clone()]),
                alpha: Some(p),
                depth_z: None,
                depth_ray: None,
                depth_median: None,
            })
        };
        // Without a shot the NeRF Render's region of definition is an error naming the node.
        let e = evaluate(&g, 1.0, 1.0, false, &mut render, &|_| {}).unwrap_err();
        assert!(e.to_string().contains("org.nerfx.NeRFRender"), "{e}");
        assert!(rendered.borrow().is_empty());
        assert_eq!(g.needed(), [true, false, true, true]);
    }
}
