//! What the tests that drive the NeRF Render through the host start from: one bundle shared
//! by a binary's tests, the demo's input files, file parameters as values.

use std::path::Path;
use std::sync::{Mutex, OnceLock, PoisonError};

use nerfx_graph::{node, Context, ParamValues, Value};
use nerfx_ofx_host::{Bundle, HostOptions, Instance};

/// The built bundle, loaded once per test binary by the strict default host and shared by
/// its tests (their violations and messages go to the same record, so tests that count
/// their own load one with [`super::load`]).
pub fn shared() -> &'static Bundle {
    static BUNDLE: OnceLock<Bundle> = OnceLock::new();
    BUNDLE.get_or_init(|| super::load(HostOptions::default()))
}

/// The demo's inputs (scenes, shot, graph: `nerfx_graph::demo::write_graph`) at `w × h`, written
/// once per test binary and size into a directory of its own (writing them is the slow part).
pub fn demo_dir(w: u32, h: u32) -> &'static Path {
    static DIRS: Mutex<Vec<(u32, u32, &'static Path)>> = Mutex::new(Vec::new());
    let mut dirs = DIRS.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(&(_, _, dir)) = dirs.iter().find(|d| (d.0, d.1) == (w, h)) {
        return dir;
    }
    let dir: &'static Path = Box::leak(
        Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("nerfx-ofx-demo-{}-{w}x{h}", std::process::id()))
            .into_boxed_path(),
    );
    std::fs::create_dir_all(dir).unwrap();
    nerfx_graph::demo::write_graph(dir, w, h).unwrap();
    dirs.push((w, h, dir));
    dir
}

/// A path as a text (file) parameter value.
pub fn text(s: impl AsRef<Path>) -> Value {
    Value::Text(s.as_ref().to_string_lossy().into_owned())
}

/// An instance of node `id` in `context` of `bundle` and the core's values of that node, both
/// with `params` set: the two sides that a test renders and compares.
pub fn instance_with(
    bundle: &Bundle,
    id: &str,
    context: Context,
    params: &[(&str, Value)],
) -> (Instance, ParamValues) {
    let mut values = node(id).unwrap().defaults();
    let mut instance = bundle.instance(id, context).unwrap();
    for (name, value) in params {
        values.set(name, value.clone()).unwrap();
        instance.set_param(name, value).unwrap();
    }
    (instance, values)
}
