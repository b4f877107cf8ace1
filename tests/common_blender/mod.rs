//! The Blenders the Blender tests run in: Debian's `blender` binary (3.4, on `PATH`) and
//! PyPI's `bpy` module (Blender as a Python module) 4.5 LTS and 5.0, each in a virtual
//! environment that `scripts/test.sh` installs under `$NERFX_BPY_DIR` (default
//! `~/.cache/nerfx-bpy`, as `bpy-4.5` and `bpy-5.0`). A test script runs the same way in
//! each: `blender -b --factory-startup --python SCRIPT -- ARGS` or `python SCRIPT -- ARGS`.
//!
//! A Blender that is missing fails the test, unless `NERFX_SKIP_BPY=1` (Debian's only), which
//! skips the `bpy` runs knowingly with a message. Each run gets a temporary folder of its own
//! (`TMPDIR`), removed after it: the scripts end with `os._exit` (bpy 4.5 hangs at exit after a
//! Cycles render), so Blender never removes its own temporary folder.

#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `bpy` versions tested, as their virtual environments are named.
pub const BPY_VERSIONS: [&str; 2] = ["4.5", "5.0"];

/// One Blender to run scripts in.
pub struct Blender {
    /// How the test names it: `blender 3.4 (Debian)`, `bpy 4.5`, `bpy 5.0`.
    pub name: String,
    program: PathBuf,
    module: bool,
}

impl Blender {
    /// Runs `script -- args` in this Blender.
    pub fn run(&self, script: &Path, args: &[&OsStr]) -> Output {
        let mut command = Command::new(&self.program);
        if !self.module {
            command.args(["-b", "--factory-startup", "--python"]);
        }
        command.arg(script).arg("--").args(args);
        let tmp = tempfile::tempdir().expect("a temporary folder for Blender");
        command.env("TMPDIR", tmp.path());
        command.output().unwrap_or_else(|e| {
            panic!(
                "{}: {} could not be started: {e}",
                self.name,
                self.program.display()
            )
        })
    }

    /// Runs `script -- args` and returns its log, failing the test unless it exits 0 and its
    /// log holds `done` (the line the script prints at its end).
    pub fn run_ok(&self, script: &Path, args: &[&Path], done: &str) -> String {
        let args: Vec<&OsStr> = args.iter().map(|a| a.as_os_str()).collect();
        self.run_ok_with(script, &args, done)
    }

    /// [`Blender::run_ok`] with arguments that need not be paths.
    pub fn run_ok_with(&self, script: &Path, args: &[&OsStr], done: &str) -> String {
        let run = self.run(script, args);
        let log = String::from_utf8_lossy(&run.stdout).to_string()
            + &String::from_utf8_lossy(&run.stderr);
        assert!(
            run.status.success() && log.contains(done),
            "{}: {} failed:\n{log}",
            self.name,
            script.display()
        );
        log
    }
}

/// Every Blender the tests run in (see the module documentation); `test` names the test in
/// skip messages.
pub fn blenders(test: &str) -> Vec<Blender> {
    let found = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|dir| dir.join("blender"))
            .find(|p| p.is_file())
    });
    let Some(program) = found else {
        panic!("`blender` is not on PATH (apt-get install -y blender)")
    };
    let mut all = vec![Blender {
        name: "blender (Debian)".to_string(),
        program,
        module: false,
    }];
    if std::env::var("NERFX_SKIP_BPY").as_deref() == Ok("1") {
        eprintln!("SKIPPED {test} in bpy {BPY_VERSIONS:?}: NERFX_SKIP_BPY=1");
        return all;
    }
    let dir = std::env::var_os("NERFX_BPY_DIR").map_or_else(
        || {
            let home = std::env::var_os("HOME").expect("HOME is set");
            PathBuf::from(home).join(".cache/nerfx-bpy")
        },
        PathBuf::from,
    );
    for version in BPY_VERSIONS {
        let python = dir.join(format!("bpy-{version}/bin/python"));
        assert!(
            python.is_file(),
            "{} is missing: scripts/test.sh installs bpy {version} there (NERFX_BPY_DIR moves it; \
             NERFX_SKIP_BPY=1 skips the bpy runs)",
            python.display()
        );
        all.push(Blender {
            name: format!("bpy {version}"),
            program: python,
            module: true,
        });
    }
    all
}
