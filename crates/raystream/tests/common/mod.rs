//! Helpers for the command-line tests: run the built binary, find the shared data and the
//! Python tools (rays.py with Embree).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_raystream"))
}

pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("raystream runs")
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

pub fn shared() -> PathBuf {
    repo().join("../shared")
}

pub fn mesh(name: &str) -> String {
    shared()
        .join("data/meshes")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

pub fn tmp(name: &str) -> PathBuf {
    let dir = repo().join("target/test-tmp");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The Python that has rays.py's requirements: `$RAYSTREAM_PYTHON`, else the repo's `.venv`.
/// Without one the Embree checks skip, except under CI (`CI=true`), where they fail.
pub fn python() -> Option<PathBuf> {
    let p = std::env::var_os("RAYSTREAM_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv/bin/python"));
    if p.exists() {
        return Some(p);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "CI=true but no Python with rays.py's requirements at {} (set RAYSTREAM_PYTHON)",
            p.display()
        );
    }
    eprintln!(
        "skipping: no Python with rays.py's requirements at {}",
        p.display()
    );
    None
}

pub fn rays_py(python: &Path, args: &[&str]) -> Output {
    Command::new(python)
        .arg(shared().join("tools/rays.py"))
        .args(args)
        .output()
        .expect("rays.py runs")
}
