//! Builds the C half of the OpenFX host (feature `host`): the C-variadic parameter-suite
//! functions, which stable Rust cannot define, forwarding to typed Rust callbacks.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "host")]
    {
        println!("cargo:rerun-if-changed=src/host/param_shim.c");
        println!("cargo:rerun-if-changed=ofx_headers");
        cc::Build::new()
            .file("src/host/param_shim.c")
            .include("ofx_headers")
            .warnings(true)
            .extra_warnings(true)
            .compile("nerfx_param_shim");
    }
}
