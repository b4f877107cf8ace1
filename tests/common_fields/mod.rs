//! The harness the field cross-checks share: seeded sample points and directions, the run of
//! a NumPy reference script (`tests/numpy/`) on them, and the relative error the loaders are
//! held to against it. The references are independent evaluations written in Python; this
//! module only moves the samples there and the answers back.
// Each test crate uses part of it.
#![allow(dead_code)]

#[path = "../common/rng.rs"]
mod rng;

use std::path::Path;
use std::process::Command;

use glam::Vec3;
pub use rng::SplitMix64;

/// `n` seeded points from `point(rng, i)`, then `n` directions uniform on the unit sphere,
/// all from one generator seeded with `seed` (points first, so a point set does not depend on
/// how directions are drawn).
pub fn samples(
    n: usize,
    seed: u64,
    mut point: impl FnMut(&mut SplitMix64, usize) -> Vec3,
) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = SplitMix64::new(seed);
    let pts = (0..n).map(|i| point(&mut rng, i)).collect();
    let dirs = (0..n).map(|_| rng.dir()).collect();
    (pts, dirs)
}

/// Seeded points uniform in the box `[min, max)` and unit directions.
pub fn samples_in_box(min: Vec3, max: Vec3, n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    samples(n, seed, |rng, _| min + rng.vec(0.0, 1.0) * (max - min))
}

/// Runs `tests/numpy/<script> <target> points.bin numpy_out.bin` (points and directions as
/// little-endian f32 `px py pz dx dy dz`; answers as `σ r g b`) next to `target`. `modules`
/// are the Python modules the script needs, named in the failure messages so a missing one is
/// a clear failure, never a silent pass. A cross-check: the tests that call it are ignored
/// unless the `cross-checks` feature is on (`scripts/test.sh`).
pub fn numpy_reference(
    script: &str,
    modules: &[&str],
    target: &Path,
    pts: &[Vec3],
    dirs: &[Vec3],
) -> Vec<[f32; 4]> {
    let bytes: Vec<u8> = pts
        .iter()
        .zip(dirs)
        .flat_map(|(p, d)| [p.x, p.y, p.z, d.x, d.y, d.z])
        .flat_map(f32::to_le_bytes)
        .collect();
    let out = run_script(script, modules, target, ("points.bin", &bytes), &[]);
    out.chunks_exact(16)
        .map(|c| [0, 1, 2, 3].map(|k| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap())))
        .collect()
}

/// Runs `tests/numpy/<script> <target> rays.bin numpy_out.bin <args…>` next to `target` on
/// rays given as eight little-endian f64 each (origin, direction, near, far); returns the
/// script's answer as f64 values. `modules` as for [`numpy_reference`].
pub fn numpy_rays(
    script: &str,
    modules: &[&str],
    target: &Path,
    rays: &[[f64; 8]],
    args: &[String],
) -> Vec<f64> {
    let bytes: Vec<u8> = rays
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let out = run_script(script, modules, target, ("rays.bin", &bytes), args);
    out.chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Writes `input` (name, bytes) next to `target`, runs the script on them and returns what it
/// wrote to `numpy_out.bin`.
fn run_script(
    script: &str,
    modules: &[&str],
    target: &Path,
    (input_name, bytes): (&str, &[u8]),
    args: &[String],
) -> Vec<u8> {
    let (names, pip) = (modules.join(" and "), modules.join(" "));
    let dir = target.parent().unwrap();
    let (input, output) = (dir.join(input_name), dir.join("numpy_out.bin"));
    std::fs::write(&input, bytes).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/numpy")
        .join(script);
    let run = Command::new("python3")
        .arg(&script)
        .arg(target)
        .arg(&input)
        .arg(&output)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("the NumPy cross-check needs python3 ({e}) with {names} (pip install {pip})")
        });
    assert!(
        run.status.success(),
        "the NumPy reference failed (it needs {names}: pip install {pip}):\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    std::fs::read(&output).unwrap()
}

/// `|a − b| / |b|`, with equal values (zero included) giving exactly 0.
pub fn rel_err(a: f32, b: f32) -> f32 {
    if a == b {
        0.0
    } else {
        (a - b).abs() / b.abs().max(1e-30)
    }
}

/// Asserts the density `sigma` of sample `i` (at `p`) within relative `1e-4` of the NumPy
/// answer `want = [σ, r, g, b]`; returns the error.
pub fn check_sigma(name: &str, i: usize, p: Vec3, sigma: f32, want: &[f32; 4]) -> f32 {
    let e = rel_err(sigma, want[0]);
    assert!(
        e <= 1e-4,
        "{name}: sample {i} at {p}: σ {sigma} vs NumPy {}",
        want[0]
    );
    e
}

/// Asserts each colour channel of sample `i` within relative `1e-4` of the NumPy answer
/// `want = [σ, r, g, b]`; returns the largest channel error.
pub fn check_rgb(name: &str, i: usize, rgb: Vec3, want: &[f32; 4]) -> f32 {
    let mut max = 0.0f32;
    for k in 0..3 {
        let e = rel_err(rgb[k], want[k + 1]);
        assert!(
            e <= 1e-4,
            "{name}: sample {i}: rgb[{k}] {} vs NumPy {}",
            rgb[k],
            want[k + 1]
        );
        max = max.max(e);
    }
    max
}
