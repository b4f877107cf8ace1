//! How set-up grows with content: an analytic field of ever more spheres (loaded, its
//! occupancy grid built, a small frame rendered) and node graphs of ever more nodes (read
//! and evaluated on a small image). For each, the CPU time per item: flat when set-up grows
//! no faster than the content.

use std::path::Path;
use std::time::Instant;

use glam::{DMat4, DVec3, Vec3};

use super::field::process_cpu_seconds;
use super::memory::peak_during;
use super::scaling::{Growth, Point, PRESET};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::demo::look_at;
use nerfx_core::error::Result;
use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};
use nerfx_core::render::{render_with_progress, Outputs, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use nerfx_graph::{evaluate, render_direct, Graph};

/// The CPU time (wall where the system does not say) of `work`, in seconds, and the most
/// heap it held at once, where the program counts it.
fn cpu_seconds(work: impl FnOnce() -> Result<()>) -> Result<(f64, Option<usize>)> {
    let (t, cpu) = (Instant::now(), process_cpu_seconds());
    let (done, heap) = peak_during(work);
    done?;
    let wall = t.elapsed().as_secs_f64();
    let cpu_s = cpu.zip(process_cpu_seconds()).map_or(wall, |(a, b)| b - a);
    Ok((cpu_s, heap.map(|h| h.peak)))
}

/// `n` small spheres on a cubic lattice filling `[−1, 1]³`, one analytic field.
fn lattice(n: usize) -> Analytic {
    let side = (n as f64).cbrt().ceil() as usize;
    let step = 2.0 / side as f32;
    let primitives = (0..n)
        .map(|i| {
            let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
            let at = |k: usize| -1.0 + (k as f32 + 0.5) * step;
            Primitive {
                shape: Shape::Sphere {
                    center: Vec3::new(at(x), at(y), at(z)),
                    radius: 0.25 * step,
                },
                density: 4.0 / step,
                color: ShColor::constant(Vec3::new(0.8, 0.5, 0.3)),
            }
        })
        .collect();
    Analytic { primitives }
}

/// Set-up of `counts` spheres each: the scene made, its occupancy built and a 16×16 frame
/// rendered at [`PRESET`], one point per count (the work: the spheres).
pub fn primitives(counts: &[usize]) -> Result<Growth> {
    let p = Perspective::from_vertical_fov(16, 16, 40.0)?;
    let camera = Camera::new(
        look_at(DVec3::new(0.0, -4.0, 0.5), DVec3::ZERO),
        Projection::Perspective(p),
    )?;
    let settings = RenderSettings::new(PRESET.params(), Outputs::rgba());
    let mut points = Vec::new();
    for &n in counts {
        let field = lattice(n);
        let (cpu_s, heap) = cpu_seconds(|| {
            let handle = FieldHandle::analytic(field);
            let scene = Scene::new(vec![Instance::new(
                "spheres",
                handle,
                DMat4::IDENTITY,
                None,
            )?]);
            render_with_progress(&scene, &camera, camera.full_window(), &settings, &|_| {})?;
            Ok(())
        })?;
        points.push(Point::per_item(
            format!("{n} spheres"),
            n as u64,
            cpu_s,
            heap,
        ));
    }
    Ok(Growth::per_item(
        "analytic primitives (spheres set up and a 16×16 frame rendered)",
        "sphere",
        points,
    ))
}

/// Graphs of a NeRF Render (the demo's environment, `width × height`, draft) and a chain of
/// `counts` Accumulation Mattes each, read and evaluated once the scene is cached (the work:
/// the nodes). `dir` takes the demo's files.
pub fn graph_nodes(counts: &[usize], dir: &Path) -> Result<Growth> {
    nerfx_graph::demo::write_graph(dir, 16, 16)?;
    let chain = |length: usize| -> Result<Graph> {
        let mut nodes = vec![
            serde_json::json!({"name": "m0", "node": "org.nerfx.NeRFRender",
            "params": {"file": "demo_environment.json", "shot": "demo_shot.json",
                       "quality": "draft"}}),
        ];
        for i in 1..=length {
            nodes.push(serde_json::json!({"name": format!("m{i}"),
                "node": "org.nerfx.AccumulationMatte",
                "inputs": {"Source": format!("m{}", i - 1)}}));
        }
        let text = serde_json::json!({"nodes": nodes, "output": format!("m{length}")});
        Graph::from_json_str(&text.to_string(), &dir.join("chain.json"))
    };
    let run = |graph: &Graph| {
        evaluate(graph, 1001.0, 1.0, false, &mut render_direct, &|_| {}).map(|_| ())
    };
    // The scene and shot are loaded and cached by the first evaluation.
    run(&chain(1)?)?;
    let mut points = Vec::new();
    for &n in counts {
        let (cpu_s, heap) = cpu_seconds(|| run(&chain(n)?))?;
        points.push(Point::per_item(format!("{n} nodes"), n as u64, cpu_s, heap));
    }
    Ok(Growth::per_item(
        "graph nodes (a chain of Accumulation Mattes read and evaluated, 16×16)",
        "node",
        points,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both series run and report per-item costs in their own table.
    #[test]
    fn the_set_up_series_report_per_item_costs() {
        let dir = tempfile::tempdir().unwrap();
        let growths = vec![
            primitives(&[10, 100]).unwrap(),
            graph_nodes(&[2, 4], dir.path()).unwrap(),
        ];
        for g in &growths {
            assert_eq!(g.points.len(), 2);
            assert!(g.points.iter().all(|p| p.cpu_s >= 0.0 && p.samples > 0));
        }
        let md = super::super::scaling::markdown(&growths);
        assert!(
            md.contains("| CPU µs per sphere |") && md.contains("| 100 spheres | 100 |"),
            "{md}"
        );
        assert!(
            md.contains("| CPU µs per node |") && md.contains("| 4 nodes | 4 |"),
            "{md}"
        );
    }
}
