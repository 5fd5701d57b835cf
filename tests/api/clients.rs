//! Clients generated from openapi.yaml work: a Python client (openapi-python-client) and a
//! TypeScript one (openapi-typescript types, type-checked by tsc, openapi-fetch at run time)
//! are generated afresh and each runs an integrator's whole round trip against a real server
//! (tests/clients/python_roundtrip.py, tests/clients/ts/roundtrip.ts). The generators are
//! installed by `.ci/run` (a virtual environment `target/ci-venv`, or `FLATMESH_CLIENT_VENV`;
//! `npm ci` in tests/clients/ts); without them a test says so and skips, except under
//! `CI=true`, where that is a failure.

use crate::common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Skip (saying why) or, under CI, fail.
fn missing(what: &str) {
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "CI=true but {what} (.ci/run installs it)"
    );
    eprintln!("SKIPPED: {what}; run .ci/run to install it");
}

/// The virtual environment with the generators, when there is one.
fn venv() -> Option<PathBuf> {
    let dir = std::env::var_os("FLATMESH_CLIENT_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ci-venv"));
    if dir.join("bin/openapi-python-client").is_file() {
        return Some(dir);
    }
    missing(&format!(
        "no openapi-python-client in {} (or set FLATMESH_CLIENT_VENV)",
        dir.display()
    ));
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

fn run_in(dir: &Path, program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("{program}: {e}"));
    let said =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{program} {args:?} failed:\n{said}");
    said
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn generated_typescript_client_round_trip() {
    let ts = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/ts");
    if !ts.join("node_modules/.bin/tsc").exists() {
        missing("the TypeScript client tools (npm ci in tests/clients/ts)");
        return;
    }
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("openapi.yaml");
    run_in(
        &ts,
        "node",
        &["generate.mjs", spec.to_str().unwrap(), "schema.d.ts"],
    );
    // The round trip must type-check against the generated types before it runs.
    run_in(&ts, "node_modules/.bin/tsc", &["-p", "."]);
    let s = Server::start(&tmp("tsclient-server"), &["--workers", "2"]);
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let said = tokio::task::spawn_blocking({
        let (ts, base) = (ts.clone(), s.base.clone());
        move || {
            run_in(
                &ts,
                "node",
                &["out/roundtrip.js", &base, fixtures.to_str().unwrap()],
            )
        }
    })
    .await
    .unwrap();
    assert!(said.contains("round trip: ok"), "{said}");
}

/// schemathesis with every check, bounded (10 examples per operation, deterministic): no
/// server error, every response as documented, every documented request accepted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn schemathesis_finds_nothing() {
    let Some(venv) = venv() else {
        return;
    };
    if !venv.join("bin/st").is_file() {
        missing(&format!("no schemathesis in {}", venv.display()));
        return;
    }
    let s = Server::start(&tmp("schemathesis"), &["--max-queued", "100000"]);
    let said = tokio::task::spawn_blocking({
        let (st, base) = (venv.join("bin/st"), s.base.clone());
        move || {
            run_in(
                Path::new(env!("CARGO_MANIFEST_DIR")),
                st.to_str().unwrap(),
                &[
                    "--config-file",
                    "tests/clients/schemathesis.toml",
                    "run",
                    "openapi.yaml",
                    "--url",
                    &base,
                    "--checks",
                    "all",
                    "--max-examples",
                    "10",
                    "--workers",
                    "1",
                    "--generation-deterministic",
                ],
            )
        }
    })
    .await
    .unwrap();
    assert!(said.contains("passed"), "{said}");
}
