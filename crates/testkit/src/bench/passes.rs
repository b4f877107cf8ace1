//! What extra passes of one field cost: NeRF Render nodes of the demo's scene and shot asking
//! for RGBA alone, RGBA and depth Z, and every output, each set from a cold cache, as a
//! compositor's graph asks them (the nodes share one march: see [`nerfx_graph`]).

use std::path::Path;
use std::time::Instant;

use nerfx_core::demo;
use nerfx_core::error::Result;
use nerfx_core::image::Window;
use nerfx_core::render::Quality;
use nerfx_graph::{node, purge_caches, shared_render_stats, RenderRequest, Value};

/// One set of outputs asked of the same field.
#[derive(Clone, Debug, PartialEq)]
pub struct PassTiming {
    /// The node outputs asked, in order.
    pub outputs: &'static [&'static str],
    /// Best wall time of the set, milliseconds.
    pub ms: f64,
    /// Marches the set took.
    pub marched: u64,
}

const SETS: [&[&str]; 3] = [
    &["rgba"],
    &["rgba", "depthZ"],
    &["rgba", "accumulation", "depthZ", "depthRay"],
];

/// Times each set of outputs of the demo frame at `width × height` and `quality`, best of
/// `repeats`; the scene and shot files are written into `dir`.
pub fn time_passes(
    dir: &Path,
    width: u32,
    height: u32,
    quality: Quality,
    repeats: u32,
) -> Result<Vec<PassTiming>> {
    let (scene, shot) = (dir.join("passes_scene.json"), dir.join("passes_shot.json"));
    demo::scene_desc().write(&scene)?;
    demo::shot(width, height).write(&shot)?;
    let nerf = node("org.nerfx.NeRFRender")?;
    let values = |output: &str| -> Result<_> {
        let mut v = nerf.defaults();
        v.set("file", Value::Text(scene.display().to_string()))?;
        v.set("shot", Value::Text(shot.display().to_string()))?;
        v.set_choice("quality", quality.name())?;
        v.set_choice("output", output)?;
        Ok(v)
    };
    let request = RenderRequest::new(
        demo::FIRST_FRAME as f64,
        Window::new(0, 0, width, height),
        1.0,
    );
    let mut timings = Vec::new();
    for outputs in SETS {
        let (mut best, mut marched) = (f64::INFINITY, 0);
        for _ in 0..repeats.max(1) {
            purge_caches();
            let started = Instant::now();
            for output in outputs {
                nerf.render(&values(output)?, &request)?;
            }
            best = best.min(started.elapsed().as_secs_f64() * 1e3);
            marched = shared_render_stats().marched;
        }
        timings.push(PassTiming {
            outputs,
            ms: best,
            marched,
        });
    }
    purge_caches();
    Ok(timings)
}
