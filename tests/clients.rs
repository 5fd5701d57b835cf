//! Clients generated from openapi.yaml work: a Python client (openapi-python-client) is
//! generated afresh and runs an integrator's whole round trip against a real server
//! (tests/clients/python_roundtrip.py). The generator lives in a virtual environment that
//! `.ci/run` makes (`target/ci-venv`, or `FLATMESH_CLIENT_VENV`); without it the test says
//! so and skips, except under `CI=true`, where that is a failure.

mod common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The virtual environment with the generators, when there is one.
fn venv() -> Option<PathBuf> {
    let dir = std::env::var_os("FLATMESH_CLIENT_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ci-venv"));
    if dir.join("bin/openapi-python-client").is_file() {
        return Some(dir);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "CI=true but no client generator in {} (.ci/run installs it)",
        dir.display()
    );
    eprintln!(
        "SKIPPED: generated-client round trip (no openapi-python-client in {}; \
         run .ci/run or set FLATMESH_CLIENT_VENV)",
        dir.display()
    );
    None
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn generated_python_client_round_trip() {
    let Some(venv) = venv() else {
        return;
    };
    let out = tmp("pyclient");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    let path = format!(
        "{}:{}",
        venv.join("bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let gen = Command::new(venv.join("bin/openapi-python-client"))
        .args([
            "generate",
            "--path",
            "openapi.yaml",
            "--meta",
            "none",
            "--output-path",
        ])
        .arg(out.join("flatmesh_client"))
        .env("PATH", &path)
        .output()
        .unwrap();
    let log =
        String::from_utf8_lossy(&gen.stdout).to_string() + &String::from_utf8_lossy(&gen.stderr);
    assert!(gen.status.success(), "generator failed:\n{log}");
    // Warnings name what the client will lack; the only one allowed is the YAML of
    // GET /openapi.yaml, which the generator cannot type.
    let warnings: Vec<&str> = log
        .lines()
        .filter(|l| l.starts_with("WARNING"))
        .filter(|l| !l.contains("GET /openapi.yaml"))
        .collect();
    assert!(warnings.is_empty(), "generator warnings:\n{log}");
    let s = Server::start(&tmp("pyclient-server"), &["--workers", "2"]);
    let run = tokio::task::spawn_blocking({
        let (out, base, python) = (out.clone(), s.base.clone(), venv.join("bin/python"));
        move || {
            Command::new(python)
                .arg("tests/clients/python_roundtrip.py")
                .arg(&out)
                .arg(&base)
                .arg("fixtures")
                .output()
                .unwrap()
        }
    })
    .await
    .unwrap();
    let said =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "python round trip failed:\n{said}");
    assert!(said.contains("round trip: ok"), "{said}");
    let _ = std::fs::remove_dir_all(&out);
}
