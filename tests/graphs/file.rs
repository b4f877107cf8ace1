//! The demo's node graph evaluated in process: the wiring (which image reaches which clip),
//! the pruning of unneeded nodes and the render scale, against the same composite written out
//! by hand from the core's pieces.

use std::path::PathBuf;

use nerfx_core::composite::{depth_merge, shadow_catcher_merge};
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_graph::demo::write_graph;
use nerfx_graph::{evaluate, node, render_direct, Graph, ParamValues, RenderRequest, Value};

fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-graph-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// A NeRF Render of `scene` (a file in `dir`) with `output`, rendered by the registry.
fn nerf(dir: &std::path::Path, scene: &str, output: usize, request: &RenderRequest) -> Planes {
    let n = node("org.nerfx.NeRFRender").unwrap();
    let mut v: ParamValues = n.defaults();
    v.set(
        "file",
        Value::Text(dir.join(scene).to_string_lossy().into()),
    )
    .unwrap();
    v.set(
        "shot",
        Value::Text(dir.join("demo_shot.json").to_string_lossy().into()),
    )
    .unwrap();
    v.set("output", Value::Choice(output)).unwrap();
    n.render(&v, request).unwrap()
}

fn red(p: &Planes) -> Plane {
    p.rgb.as_ref().unwrap()[0].clone()
}

#[test]
fn the_demo_graph_composites_what_its_file_says() {
    let dir = scratch_dir("demo");
    let (w, h) = (40, 24);
    let graph = Graph::read(&write_graph(&dir, w, h).unwrap()).unwrap();
    for scale in [1.0, 0.5] {
        let order = std::cell::RefCell::new(Vec::new());
        let images = evaluate(
            &graph,
            1003.0,
            scale,
            false,
            &mut |n, r| render_direct(n, r),
            &|name| order.borrow_mut().push(name.to_string()),
        )
        .unwrap();
        assert_eq!(
            *order.borrow(),
            ["env", "envZ", "obj", "objZ", "shadow", "caught", "comp"]
        );
        let side = |n: u32| (f64::from(n) * scale).ceil() as u32;
        let request = RenderRequest::new(1003.0, Window::new(0, 0, side(w), side(h)), scale);
        // Choice indices of the NeRF Render's output: rgba, accumulation, depthZ.
        let env = nerf(&dir, "demo_environment.json", 0, &request);
        let env_z = nerf(&dir, "demo_environment.json", 2, &request);
        let obj = nerf(&dir, "demo_object.json", 0, &request);
        let obj_z = nerf(&dir, "demo_object.json", 2, &request);
        let shadow = nerf(&dir, "demo_shadow.json", 1, &request);
        let clear = Planes {
            rgb: Some([0, 1, 2].map(|_| Plane::filled(env.width, env.height, 0.0))),
            alpha: Some(Plane::filled(env.width, env.height, 0.0)),
            ..env.clone()
        };
        let caught = shadow_catcher_merge(
            &clear,
            shadow.alpha.as_ref().unwrap(),
            &env,
            0.8,
            [0.05, 0.06, 0.1],
        )
        .unwrap();
        let comp = depth_merge(&obj, &red(&obj_z), &caught, &red(&env_z), 0.05).unwrap();
        assert_eq!(images["comp"], comp, "scale {scale}");
        assert_eq!(images["obj"], obj);
        assert_eq!((comp.width, comp.height), (side(w), side(h)));
        // The object and the shadow are really there: some pixels differ from the plain
        // environment both ways.
        let (c, e) = (
            &comp.rgb.as_ref().unwrap()[0],
            &env.rgb.as_ref().unwrap()[0],
        );
        let darker = c.data.iter().zip(&e.data).filter(|(c, e)| *c < *e).count();
        let brighter = c.data.iter().zip(&e.data).filter(|(c, e)| *c > *e).count();
        assert!(
            darker > 0 && brighter > 0,
            "{darker} darker, {brighter} brighter"
        );
    }
}
