//! What a compositor learns about the NeRF Render's images through the strict host and the
//! built bundle, against the core and against values written out here: the frame range
//! (getTimeDomain) of a shot, non-square pixels (a shot with pixel aspect 2: clip preferences,
//! the region of definition in canonical coordinates, tiles at scales 1 and ½ equal to the
//! core's render).

mod common_ofx;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nerfx::demo;
use nerfx::graph::{node, Context, Value};
use nerfx::host::{Bundle, Instance};

fn bundle() -> &'static Bundle {
    static BUNDLE: OnceLock<Bundle> = OnceLock::new();
    BUNDLE.get_or_init(|| Bundle::load(&common_ofx::bundle()).expect("the built bundle loads"))
}

/// The demo's inputs at 45×27 (frames 1001 to 1024), written once per test binary.
fn demo_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("nerfx-ofx-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        demo::write_graph(&dir, 45, 27).unwrap();
        dir
    })
}

fn text(s: impl AsRef<Path>) -> Value {
    Value::Text(s.as_ref().to_string_lossy().into_owned())
}

/// A NeRF Render instance in `context` over the demo environment and `shot`, draft quality.
fn nerf_instance(context: Context, shot: &Path) -> (Instance, nerfx::graph::ParamValues) {
    let n = node("org.nerfx.NeRFRender").unwrap();
    let mut values = n.defaults();
    let mut instance = bundle().instance(n.desc.id, context).unwrap();
    let set = [
        ("file", text(demo_dir().join("demo_environment.json"))),
        ("shot", text(shot)),
        ("quality", Value::Choice(0)),
    ];
    for (name, value) in set {
        values.set(name, value.clone()).unwrap();
        instance.set_param(name, &value).unwrap();
    }
    (instance, values)
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
