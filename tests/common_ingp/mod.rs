//! Small instant-ngp snapshots with seeded random weights for the loader's tests and the
//! NumPy cross-check, from the generator the benchmark uses (`nerfx_testkit::bench::snapshot`),
//! with the tests' conveniences: a scratch folder, writing that fails the test on error.
// Each test crate uses part of it.
#![allow(unused_imports)]

use std::path::{Path, PathBuf};

use glam::DVec3;
use nerfx_core::camera::{Camera, Perspective, Projection};

pub use nerfx_testkit::bench::snapshot::{param_counts, Ball, SnapshotSpec as Spec};
// The tests' one generator, through the shared harness (which every crate using this
// writer declares as `mod common_fields`).
pub use super::common_fields::SplitMix64;

/// The snapshot's msgpack bytes (before any gzip framing).
pub fn snapshot_bytes(s: &Spec) -> Vec<u8> {
    nerfx_testkit::bench::snapshot::snapshot_bytes(s).unwrap()
}

/// The file's bytes: msgpack, gzip-framed when `s.gzip`.
pub fn file_bytes(s: &Spec) -> Vec<u8> {
    nerfx_testkit::bench::snapshot::file_bytes(s).unwrap()
}

/// A fresh scratch folder for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("nerfx-ingp-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the snapshot of `s` into `dir`; returns its path.
pub fn write_snapshot(dir: &Path, name: &str, s: &Spec) -> PathBuf {
    nerfx_testkit::bench::snapshot::write_snapshot(dir, name, s).unwrap()
}

/// Writes the snapshot of `s` made surface-like: only `balls` occupied (1 inside, 0 outside,
/// in every cascade) and the σ row of the density MLP's last layer replaced by `|w|·gain`
/// (see `SnapshotSpec::sigma_gain`). Returns the path and the occupied fraction of cascade 0.
pub fn write_blob_snapshot(
    dir: &Path,
    name: &str,
    s: &Spec,
    balls: &[Ball],
    gain: f32,
) -> (PathBuf, f64) {
    let spec = Spec {
        occupancy: balls.to_vec(),
        sigma_gain: Some(gain),
        ..s.clone()
    };
    let path = write_snapshot(dir, name, &spec);
    (
        path,
        nerfx_testkit::bench::snapshot::occupied_fraction(&spec),
    )
}

/// The snapshot at `snapshot` (in `dir`) as the one instance of a scene, at the identity,
/// with `"sampler": sampler` when given.
pub fn placed(
    dir: &Path,
    snapshot: &Path,
    sampler: Option<&str>,
) -> nerfx_core::Result<nerfx_core::scene::Scene> {
    let scene_file = dir.join("scene.json");
    let sampler = sampler.map_or(String::new(), |s| format!(r#", "sampler": "{s}""#));
    std::fs::write(
        &scene_file,
        format!(
            r#"{{"instances": [{{"name": "blob", "field": {{"ingp": {{"path": "{}"{sampler}}}}}}}]}}"#,
            snapshot.file_name().unwrap().to_string_lossy()
        ),
    )
    .unwrap();
    nerfx_core::scene::SceneDesc::read(&scene_file)?
        .load()?
        .place(glam::DMat4::IDENTITY, &|_| Ok(glam::DMat4::IDENTITY))
}

/// One ball in each of three cascades (aabb_scale 4).
pub const BALLS_IN_THREE_CASCADES: [Ball; 3] = [
    Ball {
        centre: [0.5, 0.5, 0.5],
        radius: 0.3,
    },
    Ball {
        centre: [1.4, 0.6, 0.5],
        radius: 0.35,
    },
    Ball {
        centre: [0.5, -0.9, 0.4],
        radius: 0.45,
    },
];

/// A perspective camera at `eye` looking at `target`, `fov` degrees vertically.
pub fn camera(w: u32, h: u32, fov: f64, eye: DVec3, target: DVec3) -> Camera {
    let p = Perspective::from_vertical_fov(w, h, fov).unwrap();
    Camera::new(
        nerfx_core::demo::look_at(eye, target),
        Projection::Perspective(p),
    )
    .unwrap()
}
