//! NeRF Render nodes that differ only in their output share one march: every pass comes
//! from the same render as the command line's, a change to anything that alters the march
//! (quality, time, window, an edited file) marches again, a failed march is not kept, and
//! threads asking for the same render at once wait for one march.
//!
//! One test in its own binary: the counts it reads are the process's.

use std::path::Path;
use std::time::{Duration, SystemTime};

use nerfx_core::camera::read_shot;
use nerfx_core::demo;
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_core::render::{Outputs, Quality, RenderSettings};
use nerfx_core::scene::SceneDesc;
use nerfx_core::shot_render::{render_frame, FrameRequest};
use nerfx_graph::{
    node, purge_caches, shared_render_stats, ParamValues, RenderRequest, SharedRenderStats, Value,
};

const W: u32 = 40;
const H: u32 = 24;

fn values(scene: &Path, shot: &Path, output: &str) -> ParamValues {
    let mut v = node("org.nerfx.NeRFRender").unwrap().defaults();
    v.set("file", Value::Text(scene.display().to_string()))
        .unwrap();
    v.set("shot", Value::Text(shot.display().to_string()))
        .unwrap();
    v.set_choice("output", output).unwrap();
    v
}

/// Renders marched and requests served by another's march, so far.
fn now() -> (u64, u64) {
    let SharedRenderStats {
        marched, shared, ..
    } = shared_render_stats();
    (marched, shared)
}

fn channel(p: &Planes, c: usize) -> &Plane {
    &p.rgb.as_ref().unwrap()[c]
}

#[test]
fn passes_of_one_field_share_one_march() {
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("nerfx-shared-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (scene, shot) = (dir.join("scene.json"), dir.join("shot.json"));
    demo::scene_desc().write(&scene).unwrap();
    demo::shot(W, H).write(&shot).unwrap();
    let n = node("org.nerfx.NeRFRender").unwrap();
    let frame = demo::FIRST_FRAME + 2;
    let request = RenderRequest::new(frame as f64, Window::new(0, 0, W, H), 1.0);
    purge_caches();
    assert_eq!(shared_render_stats(), SharedRenderStats::default());

    // Four outputs and a graded RGBA: one march.
    let rgba = n.render(&values(&scene, &shot, "rgba"), &request).unwrap();
    let accumulation = n
        .render(&values(&scene, &shot, "accumulation"), &request)
        .unwrap();
    let depth_z = n
        .render(&values(&scene, &shot, "depthZ"), &request)
        .unwrap();
    let depth_ray = n
        .render(&values(&scene, &shot, "depthRay"), &request)
        .unwrap();
    let mut graded = values(&scene, &shot, "rgba");
    graded.set("exposure", Value::Double(1.0)).unwrap();
    let brighter = n.render(&graded, &request).unwrap();
    assert_eq!(now(), (1, 4));
    assert!(shared_render_stats().bytes >= 7 * 4 * (W * H) as usize);

    // Each is the pass of the command line's render of every pass.
    let loaded = SceneDesc::read(&scene).unwrap().load().unwrap();
    let settings = RenderSettings::new(Quality::Preview.params(), Outputs::all());
    let cli = render_frame(
        &loaded,
        &read_shot(&shot, "NeRF").unwrap(),
        frame,
        &FrameRequest::new(settings),
        &|_| {},
    )
    .unwrap()
    .0;
    let alpha = cli.alpha.as_ref().unwrap();
    for c in 0..3 {
        assert_eq!(channel(&rgba, c).data, channel(&cli, c).data);
        assert_eq!(channel(&accumulation, c).data, alpha.data);
        let twice: Vec<f32> = channel(&cli, c).data.iter().map(|v| 2.0 * v).collect();
        assert_eq!(channel(&brighter, c).data, twice);
    }
    let far = |p: &Option<Plane>| -> Vec<f32> {
        p.as_ref()
            .unwrap()
            .data
            .iter()
            .map(|z| z.min(nerfx_core::image::BACKGROUND_DEPTH))
            .collect()
    };
    assert_eq!(depth_z.depth_z.as_ref().unwrap().data, far(&cli.depth_z));
    assert_eq!(
        depth_ray.depth_ray.as_ref().unwrap().data,
        far(&cli.depth_ray)
    );
    assert!(alpha.data.iter().any(|&a| a > 0.5), "the object is in view");

    // What changes the march marches again.
    let mut final_quality = values(&scene, &shot, "depthZ");
    final_quality.set_choice("quality", "final").unwrap();
    n.render(&final_quality, &request).unwrap();
    let next = RenderRequest::new(frame as f64 + 1.0, request.window, 1.0);
    n.render(&values(&scene, &shot, "rgba"), &next).unwrap();
    let tile = RenderRequest::new(frame as f64, Window::new(8, 4, 24, 20), 1.0);
    let part = n.render(&values(&scene, &shot, "rgba"), &tile).unwrap();
    assert_eq!(now(), (4, 4));
    assert_eq!(
        channel(&part, 0).data,
        rgba.crop(tile.window).unwrap().rgb.unwrap()[0].data,
        "a tile is the same pixels as the frame's"
    );

    // A failed march is not kept, and an edited file is read anew.
    let outside = RenderRequest::new(frame as f64, Window::new(0, 0, W + 1, H), 1.0);
    for _ in 0..2 {
        assert!(n.render(&values(&scene, &shot, "rgba"), &outside).is_err());
    }
    assert_eq!(now(), (4, 4));
    let later = SystemTime::now() + Duration::from_secs(5);
    let file = std::fs::File::options().write(true).open(&scene).unwrap();
    file.set_modified(later).unwrap();
    drop(file);
    n.render(&values(&scene, &shot, "rgba"), &request).unwrap();
    assert_eq!(now(), (5, 4));

    // Threads asking for one new render at once: one marches, the others wait and share it.
    let half = RenderRequest::new(frame as f64 + 0.5, request.window, 1.0);
    std::thread::scope(|s| {
        for output in ["rgba", "accumulation", "depthZ", "depthRay"] {
            let (n, half, v) = (&n, &half, values(&scene, &shot, output));
            s.spawn(move || n.render(&v, half).unwrap());
        }
    });
    assert_eq!(now(), (6, 7));

    purge_caches();
    assert_eq!(shared_render_stats(), SharedRenderStats::default());
    std::fs::remove_dir_all(dir).unwrap();
}
