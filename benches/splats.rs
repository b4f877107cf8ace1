//! Splats, checked and printed: `cargo bench --bench splats -- [NAME…]`.
//!
//! - `real_captures`: whole real captures, too large to keep in the repository, against
//!   PlayCanvas splat-transform's decoding of each (the check `tests/splats/formats.rs` makes
//!   on 512-splat subsets): every file `NAME` in the folder `NERFX_REAL_SPLATS` names that has
//!   a `NAME.decoded.ply` beside it. Prints each file's differences and render PSNR, and fails
//!   where one is off by more than the test allows.

#[path = "../tests/common_splats/mod.rs"]
mod common_splats;

use std::path::PathBuf;

use common_splats::{assert_matches, check_against_decoding};
use nerfx_core::field::Axes;
use nerfx_testkit::bench::targets::Measurement;

fn main() {
    nerfx_testkit::bench::targets::main(
        "splats",
        &[Measurement::new(
            "real_captures",
            "whole real captures against splat-transform's decoding",
            real_captures,
        )
        .needing("NERFX_REAL_SPLATS")],
    );
}

/// Whole real captures, which are too large to keep here: every file `NAME` in the folder
/// `NERFX_REAL_SPLATS` names that has a `NAME.decoded.ply` beside it (splat-transform's
/// decoding). `NERFX_REAL_SPLATS=dir cargo bench --bench splats -- real_captures`.
fn real_captures() {
    let Some(dir) = std::env::var_os("NERFX_REAL_SPLATS").map(PathBuf::from) else {
        panic!("NERFX_REAL_SPLATS names no folder");
    };
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".decoded.ply") || !dir.join(format!("{name}.decoded.ply")).is_file() {
            continue;
        }
        let axes = if name.ends_with(".spz") {
            Axes::Rub
        } else {
            Axes::Stored
        };
        assert_matches(&name, check_against_decoding(&dir, &name, axes));
        checked += 1;
    }
    assert!(
        checked > 0,
        "no NAME with a NAME.decoded.ply in {}",
        dir.display()
    );
}
