//! Builds the deep EXR writer (`src/image/deep_exr.cpp`, over OpenEXR's own C++ library)
//! where pkg-config finds OpenEXR (Debian: `libopenexr-dev`), and sets `cfg(nerfx_openexr)`;
//! without it (or with `NERFX_NO_OPENEXR` set) nerfx builds all the same and `--deep` says
//! that this build has no OpenEXR.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-check-cfg=cfg(nerfx_openexr)");
    deep_writer();
}

/// Compiles the deep writer against OpenEXR when pkg-config finds it.
fn deep_writer() {
    println!("cargo:rerun-if-changed=src/image/deep_exr.cpp");
    println!("cargo:rerun-if-env-changed=NERFX_NO_OPENEXR");
    println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
    if std::env::var_os("NERFX_NO_OPENEXR").is_some() {
        return;
    }
    let query = |what: &str| {
        std::process::Command::new("pkg-config")
            .args([what, "OpenEXR"])
            .output()
            .ok()
            .filter(|out| out.status.success())
            .map(|out| String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let (Some(cflags), Some(libs)) = (query("--cflags"), query("--libs")) else {
        println!(
            "cargo:warning=OpenEXR not found by pkg-config (Debian: libopenexr-dev): \
             building without the deep EXR writer"
        );
        return;
    };
    let mut build = cc::Build::new();
    build.cpp(true).std("c++14").file("src/image/deep_exr.cpp");
    for flag in cflags.split_whitespace() {
        match flag.strip_prefix("-I") {
            Some(dir) => {
                build.include(dir);
            }
            None => {
                build.flag_if_supported(flag);
            }
        }
    }
    build.compile("nerfx_deep_exr");
    for flag in libs.split_whitespace() {
        if let Some(lib) = flag.strip_prefix("-l") {
            println!("cargo:rustc-link-lib={lib}");
        } else if let Some(dir) = flag.strip_prefix("-L") {
            println!("cargo:rustc-link-search=native={dir}");
        }
    }
    println!("cargo:rustc-cfg=nerfx_openexr");
}
