//! Builds the C half of the OpenFX host: the C-variadic parameter-suite functions, which
//! stable Rust cannot define, forwarding to typed Rust callbacks.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src/param_shim.c");
    println!("cargo:rerun-if-changed=../../ofx_headers");
    cc::Build::new()
        .file("src/param_shim.c")
        .include("../../ofx_headers")
        .warnings(true)
        .extra_warnings(true)
        .compile("nerfx_param_shim");
}
