//! A graph rendered through the OpenFX bundle: one plugin instance per node, created and set
//! once, fed its upstream images through the host. This is the farm's path, and it runs the
//! very code an artist's compositor runs; what the plugins flag their nodes with (a render
//! whose pixels may be off) is gathered per frame ([`OfxGraph::warnings`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use super::{Bundle, ClipSource, Instance};
use nerfx_core::error::{Error, Result};
use nerfx_core::image::{Planes, Window};
use nerfx_graph::{
    evaluate_window, matrix_text, Context, Graph, GraphNode, ParamKind, RenderRequest, Value,
};

/// The context a graph node is instantiated in: Generator without inputs, Filter when its
/// only input is `Source`, otherwise General — each where the node supports it.
fn context_of(node: &GraphNode) -> Context {
    let supports = |c| node.node.desc.contexts.contains(&c);
    let only_source = node.inputs.keys().all(|clip| clip == "Source");
    if node.inputs.is_empty() && supports(Context::Generator) {
        Context::Generator
    } else if only_source && supports(Context::Filter) {
        Context::Filter
    } else if supports(Context::General) {
        Context::General
    } else {
        node.node.desc.contexts[0]
    }
}

/// A graph whose nodes are instances of a loaded bundle.
pub struct OfxGraph {
    graph: Graph,
    instances: BTreeMap<String, Instance>,
    warnings: Vec<(String, String)>,
}

impl OfxGraph {
    /// Instantiates every node of `graph` in `bundle` and sets its parameter values.
    pub fn new(graph: Graph, bundle: &Bundle) -> Result<OfxGraph> {
        let mut instances = BTreeMap::new();
        for node in &graph.nodes {
            let named = |e: Error| match e {
                Error::Invalid { what, message } => {
                    Error::invalid(format!("graph node {}: {what}", node.name), message)
                }
                other => other,
            };
            let mut instance = bundle
                .instance(node.node.desc.id, context_of(node))
                .map_err(named)?;
            for (name, value) in node.values.iter() {
                let value = as_published(node, name, value);
                instance.set_param(name, &value).map_err(named)?;
            }
            instances.insert(node.name.clone(), instance);
        }
        Ok(OfxGraph {
            graph,
            instances,
            warnings: Vec::new(),
        })
    }

    /// The graph.
    pub fn graph(&self) -> &Graph {
        &self.graph
    }

    /// The pixel aspect of node `name`'s image: its own when it makes its images (a NeRF
    /// Render of an anamorphic shot), else that of its first input.
    pub fn pixel_aspect(&self, name: &str) -> f64 {
        let mut name = name;
        // Each step goes upstream, so the walk ends within the graph's size.
        for _ in 0..=self.graph.nodes.len() {
            let Some(node) = self.graph.node(name) else {
                break;
            };
            if node.node.has_own_format() {
                return self.instances.get(name).map_or(1.0, Instance::pixel_aspect);
            }
            match node.inputs.values().next() {
                Some(up) => name = up,
                None => break,
            }
        }
        1.0
    }

    /// The frames every needed node with a frame range of its own can make (the
    /// intersection of their time domains), or `None` when no node has one.
    pub fn time_domain(&self) -> Result<Option<(f64, f64)>> {
        let mut range: Option<(f64, f64)> = None;
        for (node, needed) in self.graph.nodes.iter().zip(self.graph.needed()) {
            let Some(instance) = self.instances.get(&node.name).filter(|_| needed) else {
                continue;
            };
            if let Some((a, b)) = instance.time_domain()? {
                range = Some(match range {
                    Some((first, last)) => (first.max(a), last.min(b)),
                    None => (a, b),
                });
            }
        }
        match range {
            Some((first, last)) if first > last => Err(Error::invalid(
                "graph frame range",
                format!("the nodes' frame ranges do not overlap ({first}..{last})"),
            )),
            other => Ok(other),
        }
    }

    /// Tells every instance a sequence of frames `first..=last` is about to render (plugins
    /// may load what the whole range needs once).
    pub fn begin_sequence(&self, first: f64, last: f64, render_scale: f64) -> Result<()> {
        self.instances
            .values()
            .try_for_each(|i| i.begin_sequence(first, last, render_scale))
    }

    /// Tells every instance the sequence begun by [`OfxGraph::begin_sequence`] is over.
    pub fn end_sequence(&self, first: f64, last: f64, render_scale: f64) -> Result<()> {
        self.instances
            .values()
            .try_for_each(|i| i.end_sequence(first, last, render_scale))
    }

    /// The warnings the nodes rendered by the last [`OfxGraph::render`] were flagged with,
    /// as `(node name, text)` in the order they rendered: the render succeeded, but these
    /// nodes' pixels may be off (the text says why and what to do).
    pub fn warnings(&self) -> &[(String, String)] {
        &self.warnings
    }

    /// Renders the nodes the outputs need at `time` through the bundle (whole images at
    /// `render_scale`), as [`nerfx_graph::evaluate`] does; `on_node` hears each finished
    /// node's name.
    pub fn render(
        &mut self,
        time: f64,
        render_scale: f64,
        draft: bool,
        on_node: &dyn Fn(&str),
    ) -> Result<BTreeMap<String, Planes>> {
        let whole = |w, h| Ok(Window::new(0, 0, w, h));
        self.render_window(time, render_scale, draft, &whole, on_node)
    }

    /// [`OfxGraph::render`] of the window `window_of(width, height)` of every image, as
    /// [`evaluate_window`] does.
    pub fn render_window(
        &mut self,
        time: f64,
        render_scale: f64,
        draft: bool,
        window_of: &dyn Fn(u32, u32) -> Result<Window>,
        on_node: &dyn Fn(&str),
    ) -> Result<BTreeMap<String, Planes>> {
        let instances = &mut self.instances;
        let warnings = &mut self.warnings;
        warnings.clear();
        let mut render = |node: &GraphNode, request: &RenderRequest| -> Result<Planes> {
            let instance = instances.get_mut(&node.name).ok_or_else(|| {
                Error::invalid(format!("graph node {}", node.name), "was not instantiated")
            })?;
            // The instance's clips see the images only while this render holds them.
            let mut held = Vec::with_capacity(request.inputs.len());
            for (clip, image) in &request.inputs {
                let image = Arc::new(image.clone());
                let source = upstream(
                    &image,
                    request.render_scale,
                    request.window,
                    request.image_size,
                );
                instance.connect(clip, source)?;
                held.push(image);
            }
            let planes = instance.render(
                request.time,
                request.window,
                request.render_scale,
                request.draft,
            )?;
            // After a render the instance's persistent message is the plugin's word on it (a
            // clean render clears it).
            if let Some(m) = instance.persistent_message().filter(|m| m.is_warning()) {
                warnings.push((node.name.clone(), m.text));
            }
            Ok(planes)
        };
        evaluate_window(
            &self.graph,
            time,
            render_scale,
            draft,
            window_of,
            &mut render,
            on_node,
        )
    }
}

/// `value` as the plugin publishes the parameter: a matrix as its text (see
/// [`matrix_text`]), everything else as it is.
fn as_published(node: &GraphNode, name: &str, value: &Value) -> Value {
    let is_matrix = matches!(
        node.node.desc.param(name).map(|p| &p.kind),
        Some(ParamKind::Matrix { .. })
    );
    match value {
        Value::Doubles(m) if is_matrix => match <&[f64; 16]>::try_from(m.as_slice()) {
            Ok(m) => Value::Text(matrix_text(m)),
            Err(_) => value.clone(),
        },
        _ => value.clone(),
    }
}

/// An upstream node's image of `window` (of its whole image, `image_size` at `scale`) as a
/// clip source; its region of definition in full-resolution pixels is the whole image's size
/// undone by the scale. The source holds the image weakly: once the render that connected it
/// is over, the instance keeps no pixels.
fn upstream(image: &Arc<Planes>, scale: f64, window: Window, image_size: (u32, u32)) -> ClipSource {
    let full = |n: u32| (f64::from(n) / scale).floor().max(1.0) as u32;
    let rod = (full(image_size.0), full(image_size.1));
    let image = Arc::downgrade(image);
    ClipSource::new(rod, move |_, asked: Window, s| {
        if s != scale {
            return Err(Error::invalid(
                "clip source",
                format!("rendered at render scale {scale}, asked for {s}"),
            ));
        }
        let image = image.upgrade().ok_or_else(|| {
            Error::invalid(
                "clip source",
                "its upstream image was released after the render it was connected for",
            )
        })?;
        // The pixels held are those of `window`: the request is cut from them.
        if asked.intersect(&window) != asked {
            return Err(Error::invalid(
                "clip source",
                format!("asked for {asked:?}, holds only {window:?}"),
            ));
        }
        image.crop(Window::new(
            asked.x0 - window.x0,
            asked.y0 - window.y0,
            asked.x1 - window.x0,
            asked.y1 - window.y0,
        ))
    })
}
