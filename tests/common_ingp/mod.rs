//! Small instant-ngp snapshots with seeded random weights for the loader's tests and the
//! NumPy cross-check, from the generator the benchmark uses (`nerfx_testkit::bench::snapshot`),
//! with the tests' conveniences: a scratch folder, writing that fails the test on error.
// Each test crate uses part of it.
#![allow(unused_imports)]

use std::path::{Path, PathBuf};

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
