//! The layering of DESIGN.md, checked on the source: data flows one way. Module references
//! (`super::x`, `crate::service::x`, `crate::x`) are read from the files; the graph between the
//! service's modules must have no cycle, and nothing below the service may name it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file under `root` (`handlers/jobs.rs` → [handlers, jobs]).
fn module_path(root: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(root).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|l| l == "mod") {
        parts.pop();
    }
    parts
}

/// First path segments named after `prefix` in `src`: `super::{a, b::c}` gives a and b.
fn segments_after(src: &str, prefix: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = src;
    while let Some(i) = rest.find(prefix) {
        let before = rest[..i].chars().last();
        rest = &rest[i + prefix.len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
            continue;
        }
        if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            for item in group[..end].split(',') {
                let first = item.trim().split("::").next().unwrap_or("").trim();
                if !first.is_empty() {
                    out.push(first.to_string());
                }
            }
        } else {
            let end = rest
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            out.push(rest[..end].to_string());
        }
    }
    out
}

/// Code before the first `#[cfg(test)]` (tests may reach anywhere), without comments (a doc
/// link is not an import).
fn non_test(src: &str) -> String {
    let code = src.split("#[cfg(test)]").next().unwrap_or(src);
    code.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn service_modules_import_in_one_direction() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/service");
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    let top = |p: &[String]| p.first().cloned().unwrap_or_else(|| "(service)".into());
    let modules: BTreeSet<String> = files.iter().map(|f| top(&module_path(&root, f))).collect();
    assert!(
        modules.len() > 5,
        "found the service's modules: {modules:?}"
    );
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in &files {
        let path = module_path(&root, f);
        let from = top(&path);
        let text = std::fs::read_to_string(f).unwrap();
        let code = &non_test(&text);
        let mut targets = segments_after(code, "crate::service::");
        if path.is_empty() {
            // The service module names its children by bare paths (`store::SqliteStore`).
            for m in &modules {
                if !segments_after(code, &format!("{m}::")).is_empty() {
                    targets.push(m.clone());
                }
            }
        } else if path.len() == 1 {
            // `super::x` from a top-level module names a sibling, or an item of the service
            // module itself (a re-export, which would import through the top).
            targets.extend(segments_after(code, "super::"));
        }
        for t in targets {
            let to = if modules.contains(&t) {
                t
            } else {
                "(service)".into()
            };
            if to != from {
                edges.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    // Depth-first search for a cycle; report it whole.
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        stack: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = stack.iter().position(|s| s == m) {
            let mut cycle = stack[i..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        stack.push(m.to_string());
        for n in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(n, edges, stack, done) {
                return Some(c);
            }
        }
        stack.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    for m in &modules {
        if let Some(c) = visit(m, &edges, &mut vec![], &mut done) {
            panic!("import cycle in src/service: {}", c.join(" -> "));
        }
    }
    // The check sees real edges (it would pass vacuously on a parser that found none).
    assert!(edges["worker"].contains("store"), "{edges:?}");
    assert!(edges["handlers"].contains("worker") || edges["handlers"].contains("state"));
}

#[test]
fn nothing_below_the_service_names_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    for d in ["algorithms", "jobs", "io", "mesh", "geometry"] {
        rust_files(&src.join(d), &mut files);
    }
    assert!(files.len() > 10);
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        assert!(
            !text.contains("crate::service"),
            "{} names the service",
            f.display()
        );
    }
    // io is below jobs and algorithms: it writes formats, it does not run anything.
    let mut io = Vec::new();
    rust_files(&src.join("io"), &mut io);
    for f in io {
        let code = std::fs::read_to_string(&f).unwrap();
        for above in ["crate::jobs", "crate::algorithms"] {
            assert!(
                !non_test(&code).contains(above),
                "{} imports {above}",
                f.display()
            );
        }
    }
}

#[test]
fn segments_are_read_from_groups_and_paths() {
    let src = "use super::{a, b::C};\nuse crate::service::store::X; my_super::no";
    assert_eq!(segments_after(src, "super::"), ["a", "b"]);
    assert_eq!(segments_after(src, "crate::service::"), ["store"]);
}
