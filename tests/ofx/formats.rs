//! What a compositor learns about the NeRF Render's images through the strict host and the
//! built bundle, against the core and against values written out here: the frame range
//! (getTimeDomain) of a shot, non-square pixels (a shot with pixel aspect 2: clip preferences,
//! the region of definition in canonical coordinates, tiles at scales 1 and ½ equal to the
//! core's render).

use std::path::{Path, PathBuf};

use crate::common_ofx::fixtures::{instance_with, shared as bundle, text};
use crate::common_ofx::images::{differing, render_tiled};
use nerfx_core::image::{scaled_size, Window};
use nerfx_graph::{node, Context, RenderRequest, Value};
use nerfx_ofx_host::Instance;

/// The demo's inputs at 45×27 (frames 1001 to 1024), written once per test binary.
fn demo_dir() -> &'static Path {
    crate::common_ofx::fixtures::demo_dir(45, 27)
}

/// A NeRF Render instance in `context` over the demo environment and `shot`, draft quality.
fn nerf_instance(context: Context, shot: &Path) -> (Instance, nerfx_graph::ParamValues) {
    let set = [
        ("file", text(demo_dir().join("demo_environment.json"))),
        ("shot", text(shot)),
        ("quality", Value::Choice(0)),
    ];
    instance_with(bundle(), "org.nerfx.NeRFRender", context, &set)
}

#[test]
fn a_generator_tells_the_host_its_shots_frame_range() {
    let shot = demo_dir().join("demo_shot.json");
    let n = node("org.nerfx.NeRFRender").unwrap();
    // The demo shot holds frames 1001 to 1024.
    for context in [Context::Generator, Context::General] {
        let (mut instance, mut values) = nerf_instance(context, &shot);
        assert_eq!(
            instance.time_domain().unwrap(),
            Some((1001.0, 1024.0)),
            "{context:?}"
        );
        assert_eq!(n.time_domain(&values).unwrap(), Some((1001.0, 1024.0)));
        // Host frame t renders shot frame t + offset: the range moves back by the offset.
        instance.set_param("frameOffset", &Value::Int(10)).unwrap();
        values.set("frameOffset", Value::Int(10)).unwrap();
        assert_eq!(instance.time_domain().unwrap(), Some((991.0, 1014.0)));
        assert_eq!(n.time_domain(&values).unwrap(), Some((991.0, 1014.0)));
    }
    // In the Filter context the host decides the range: it does not ask.
    let (filter, _) = nerf_instance(Context::Filter, &shot);
    assert_eq!(filter.time_domain().unwrap(), None);
    // A node without its shot yet replies default, without an error.
    let empty = bundle()
        .instance("org.nerfx.NeRFRender", Context::Generator)
        .unwrap();
    assert_eq!(empty.time_domain().unwrap(), None);
    // Nodes sized by their inputs have no range of their own.
    let merge = bundle()
        .instance("org.nerfx.DepthMerge", Context::General)
        .unwrap();
    assert_eq!(merge.time_domain().unwrap(), None);
    assert_eq!(
        node("org.nerfx.DepthMerge")
            .unwrap()
            .time_domain(&node("org.nerfx.DepthMerge").unwrap().defaults())
            .unwrap(),
        None
    );
    assert_eq!(bundle().violations(), Vec::<String>::new());
    // An unreadable shot is an error naming it.
    let corrupt = demo_dir().join("corrupt_range_shot.json");
    std::fs::write(&corrupt, "{\"frames\": [").unwrap();
    let (broken, _) = nerf_instance(Context::Generator, &corrupt);
    let e = broken.time_domain().unwrap_err().to_string();
    assert!(e.contains("corrupt_range_shot.json"), "{e}");
}

/// The demo shot with `pixel_aspect_x`, `pixel_aspect_y` changed, written under `name`.
fn anamorphic_shot(name: &str, pa_x: f64, pa_y: f64) -> PathBuf {
    let dir = demo_dir();
    let shot = std::fs::read_to_string(dir.join("demo_shot.json")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&shot).unwrap();
    json["pixel_aspect_x"] = pa_x.into();
    json["pixel_aspect_y"] = pa_y.into();
    let path = dir.join(name);
    std::fs::write(&path, json.to_string()).unwrap();
    path
}

#[test]
fn an_anamorphic_shot_has_non_square_pixels_through_the_host() {
    let n = node("org.nerfx.NeRFRender").unwrap();
    let wide = anamorphic_shot("anamorphic_shot.json", 2.0, 1.0);
    let (instance, values) = nerf_instance(Context::Generator, &wide);
    // Pixels twice as wide as tall: the output clip says 2, the region of definition is the
    // shot's 45×27 pixels (90×27 canonical).
    assert_eq!(n.pixel_aspect(&values, 1005.0).unwrap(), Some(2.0));
    assert_eq!(instance.pixel_aspect(), 2.0);
    assert_eq!(instance.region_of_definition(1005.0).unwrap(), (45, 27));
    assert_eq!(
        n.region_of_definition(&values, 1005.0).unwrap(),
        Some((45, 27))
    );
    for scale in [1.0, 0.5] {
        let (w, h) = (scaled_size(45, scale), scaled_size(27, scale));
        let want = n
            .render(
                &values,
                &RenderRequest::new(1005.0, Window::new(0, 0, w, h), scale),
            )
            .unwrap();
        let got = render_tiled(&instance, 1005.0, w, h, scale);
        assert_eq!(differing(&got, &want), 0, "scale {scale}");
    }
    // The pixel aspect reaches the camera: the square-pixel render differs.
    let (square, _) = nerf_instance(Context::Generator, &demo_dir().join("demo_shot.json"));
    assert_eq!(square.pixel_aspect(), 1.0);
    let full = Window::new(0, 0, 45, 27);
    assert!(
        differing(
            &square.render(1005.0, full, 1.0, false).unwrap(),
            &instance.render(1005.0, full, 1.0, false).unwrap()
        ) > 0
    );
    // Tall pixels: x over y.
    let tall = anamorphic_shot("tall_pixel_shot.json", 1.0, 2.0);
    let (instance, values) = nerf_instance(Context::Generator, &tall);
    assert_eq!(n.pixel_aspect(&values, 1001.0).unwrap(), Some(0.5));
    assert_eq!(instance.pixel_aspect(), 0.5);
    assert_eq!(instance.region_of_definition(1001.0).unwrap(), (45, 27));
    // A panorama from the shot's position has square pixels.
    let (mut pano, mut values) = nerf_instance(Context::Generator, &wide);
    pano.set_param("cameraModel", &Value::Choice(1)).unwrap();
    values.set("cameraModel", Value::Choice(1)).unwrap();
    assert_eq!(n.pixel_aspect(&values, 1001.0).unwrap(), Some(1.0));
    assert_eq!(pano.pixel_aspect(), 1.0);
    // Nodes sized by their inputs have no pixel aspect of their own.
    let merge = node("org.nerfx.DepthMerge").unwrap();
    assert_eq!(merge.pixel_aspect(&merge.defaults(), 1.0).unwrap(), None);
    assert_eq!(bundle().violations(), Vec::<String>::new());
}

#[test]
fn a_sub_frame_renders_the_shot_between_its_frames() {
    let n = node("org.nerfx.NeRFRender").unwrap();
    let (instance, values) = nerf_instance(Context::Generator, &demo_dir().join("demo_shot.json"));
    let full = Window::new(0, 0, 45, 27);
    let core = |t: f64| {
        n.render(&values, &RenderRequest::new(t, full, 1.0))
            .unwrap()
    };
    let half = instance.render(1005.5, full, 1.0, false).unwrap();
    assert_eq!(differing(&half, &core(1005.5)), 0);
    // Neither neighbouring frame: the camera moved.
    assert!(differing(&half, &instance.render(1005.0, full, 1.0, false).unwrap()) > 0);
    assert!(differing(&half, &instance.render(1006.0, full, 1.0, false).unwrap()) > 0);
    // Past the last frame is an error, as a missing whole frame is.
    assert!(instance.render(1024.5, full, 1.0, false).is_err());
}
