//! The README's two commands share one build: every crate that both the service
//! (`cargo build --release`) and the tests (`cargo test --release`) compile is compiled with
//! the same features, so the second command reuses the first one's artefacts instead of
//! rebuilding them (and everything that depends on them). Cargo.toml turns on in
//! `[dependencies]` what the dev-dependencies would otherwise add.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

/// `package version` → features, as `cargo tree` resolves them for the given edge kinds.
fn features(edges: &str) -> BTreeMap<String, BTreeSet<String>> {
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--locked",
            "--offline",
            "-e",
            edges,
            "--prefix",
            "none",
            "-f",
            "{p}|{f}",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run cargo tree");
    assert!(
        out.status.success(),
        "cargo tree failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut map: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        // A subtree already shown ends in " (*)".
        let line = line.trim_end().trim_end_matches("(*)").trim_end();
        let Some((pkg, feats)) = line.split_once('|') else {
            continue;
        };
        // "name v1.2.3 (path or registry) (*)" → "name v1.2.3"
        let key: Vec<&str> = pkg.split_whitespace().take(2).collect();
        map.entry(key.join(" "))
            .or_default()
            .extend(feats.split(',').filter(|f| !f.is_empty()).map(String::from));
    }
    map
}

#[test]
fn tests_build_the_services_crates_with_the_same_features() {
    let service = features("normal,build");
    let tests = features("normal,build,dev");
    assert!(
        service.len() > 100,
        "cargo tree listed {} crates",
        service.len()
    );
    let differ: Vec<String> = service
        .iter()
        .filter_map(|(pkg, f)| {
            let t = tests.get(pkg)?;
            (t != f).then(|| format!("{pkg}: tests add {:?}", t.difference(f).collect::<Vec<_>>()))
        })
        .collect();
    assert!(
        differ.is_empty(),
        "crates the tests would compile again (add these features in [dependencies]):\n{}",
        differ.join("\n")
    );
}
