//! The built OpenFX bundle, for the tests that drive it through the host, and what those
//! tests share: the demo files and parameter values ([`fixtures`]), RGBA images built,
//! tiled and compared ([`images`]).

// Each test binary uses a part of these; the rest is not dead, only unused there.
#[allow(dead_code)]
pub mod fixtures;
#[allow(dead_code)]
pub mod images;

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use nerfx_ofx_host::{Bundle, HostOptions};

/// Builds `nerfx.ofx.bundle` once per test binary with `bundle/build.sh --profile test` (the
/// README's build command, at the test profile) and returns its path.
pub fn bundle() -> PathBuf {
    static BUNDLE: OnceLock<PathBuf> = OnceLock::new();
    BUNDLE.get_or_init(|| build("test")).clone()
}

/// The built bundle loaded by a host of its own behaving as `options` say: its violations
/// and messages are those of the test that loaded it only.
pub fn load(options: HostOptions) -> Bundle {
    Bundle::load_with(&bundle(), options).expect("the built bundle loads")
}

/// The bundle as shipped (release profile), for the bench targets (`benches/graph.rs`); the
/// test binaries do not use it.
#[allow(dead_code)]
pub fn release_bundle() -> PathBuf {
    build("release")
}

/// Runs `bundle/build.sh --profile <profile>` and returns the bundle's path.
fn build(profile: &str) -> PathBuf {
    let root = env!("CARGO_MANIFEST_DIR");
    let out = Command::new("bash")
        .args([&format!("{root}/bundle/build.sh"), "--profile", profile])
        .env("CARGO", env!("CARGO"))
        .current_dir(root)
        .output()
        .unwrap_or_else(|e| panic!("bundle/build.sh did not start: {e}"));
    assert!(
        out.status.success(),
        "bundle/build.sh failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
}
