//! The node registry: every node described once and rendered once.
//!
//! A [`Node`] is a [`NodeDesc`] (contexts, clips, typed parameters with defaults and ranges)
//! and one render function taking validated [`ParamValues`] and a [`RenderRequest`] (time,
//! window, render scale, input planes). The OpenFX plugin and the graph-file renderer are
//! generic adapters over [`nodes`]: adding a node never touches them.
//!
//! Nodes: `org.nerfx.NeRFRender`, `org.nerfx.AccumulationMatte`,
//! `org.nerfx.ShadowCatcherMerge`, `org.nerfx.DepthMerge`. Files they read are cached
//! ([`cached_scene`], [`cached_shot`]), NeRF Render nodes that differ only in their output
//! share one render of every pass ([`shared_render_stats`]), and [`purge_caches`] releases
//! both.
//!
//! ```
//! use nerfx_graph::{node, RenderRequest, Value};
//! use nerfx_core::image::Window;
//! let merge = node("org.nerfx.DepthMerge").unwrap();
//! let mut values = merge.defaults();
//! values.set("softness", Value::Double(0.5)).unwrap();
//! assert!(values.set("softness", Value::Bool(true)).is_err());
//! // Without its inputs connected, the render is refused, naming the node and the clip.
//! let e = merge.render(&values, &RenderRequest::new(1.0, Window::new(0, 0, 4, 4), 1.0));
//! assert!(e.unwrap_err().to_string().contains("org.nerfx.DepthMerge: clip A"));
//! ```

mod cache;
mod compositing;
pub mod demo;
mod desc;
mod evaluate;
mod file;
mod matrix_text;
mod nerf_render;
mod node;
mod reference;
mod shared_renders;
mod values;

use std::sync::OnceLock;

pub use cache::{cached_scene, cached_shot, purge_caches, FileCache, CAMERA_PATH_OBJECT};
pub use desc::{ClipDesc, ClipKind, Context, NodeDesc, ParamDesc, ParamKind, Range};
pub use evaluate::{evaluate, evaluate_window, render_direct, RenderNode};
pub use file::{Graph, GraphNode};
pub use matrix_text::{matrix_text, parse_matrix};
pub use node::{
    check_render_scale, single_channel, Format, IdentityFn, Node, OutputSpace, OutputSpaceFn,
    PixelAspectFn, RenderFn, RenderRequest, Rendered, RodFn, TimeDomainFn,
};
pub use reference::nodes_markdown;
pub use shared_renders::{shared_render_stats, SharedRenderStats};
pub use values::{ParamValues, Value};

use nerfx_core::error::{Error, Result};

/// Every node, in menu order.
pub fn nodes() -> &'static [Node] {
    static NODES: OnceLock<Vec<Node>> = OnceLock::new();
    NODES.get_or_init(|| {
        vec![
            nerf_render::nerf_render_node(),
            compositing::accumulation_matte_node(),
            compositing::shadow_catcher_merge_node(),
            compositing::depth_merge_node(),
        ]
    })
}

/// The node with identifier `id`; unknown identifiers are refused, listing the known ones.
pub fn node(id: &str) -> Result<&'static Node> {
    nodes().iter().find(|n| n.desc.id == id).ok_or_else(|| {
        let ids: Vec<&str> = nodes().iter().map(|n| n.desc.id).collect();
        Error::invalid(
            format!("node {id}"),
            format!("no such node (nodes: {})", ids.join(", ")),
        )
    })
}
