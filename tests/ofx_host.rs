//! The OpenFX host (`nerfx::host`) against the built bundle and against itself.

#[path = "common_ofx/mod.rs"]
mod common_ofx;

use nerfx::graph::{nodes, Context};
use nerfx::host::Bundle;

#[test]
fn smoke() {
    let b = Bundle::load(&common_ofx::bundle()).unwrap();
    println!("{:?}", b.plugin_ids());
    for n in nodes() {
        for &c in n.desc.contexts {
            let d = b.describe(n.desc.id, c);
            println!(
                "{} {c:?}: {:?}",
                n.desc.id,
                d.as_ref().map(|d| (d.clips.len(), d.params.len()))
            );
        }
    }
    println!("{:#?}", b.violations());
    println!("{:#?}", b.messages());
}
