//! The built OpenFX bundle, for the tests that drive it through the host.

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// Builds `nerfx.ofx.bundle` once per test binary with `bundle/build.sh --profile test` (the
/// README's build command, at the test profile) and returns its path.
pub fn bundle() -> PathBuf {
    static BUNDLE: OnceLock<PathBuf> = OnceLock::new();
    BUNDLE
        .get_or_init(|| {
            let root = env!("CARGO_MANIFEST_DIR");
            let out = Command::new("bash")
                .args([&format!("{root}/bundle/build.sh"), "--profile", "test"])
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
        })
        .clone()
}
