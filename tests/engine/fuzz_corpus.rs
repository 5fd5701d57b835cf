//! Every fuzz target's checks (flatmesh::fuzzing) on every input of its committed corpus in
//! fuzz/corpus/TARGET, so that a regression in a reader, the jobs domain or an exporter on a
//! known input fails `cargo test` without a libFuzzer build. Live fuzzing is run by hand
//! (README, "Fuzzing").

use std::path::Path;

/// One target's checks on one input.
type Check = fn(&[u8]);

#[test]
fn every_fuzz_target_passes_its_committed_corpus() {
    flatmesh::io::install_quiet_panic_hook();
    let targets: [(&str, Check); 6] = [
        ("obj", flatmesh::fuzzing::obj),
        ("off", flatmesh::fuzzing::off),
        ("gltf", flatmesh::fuzzing::gltf),
        ("glb", flatmesh::fuzzing::glb),
        ("job_request", flatmesh::fuzzing::job_request),
        ("patterns", flatmesh::fuzzing::patterns),
    ];
    for (name, check) in targets {
        let dir = Path::new("fuzz/corpus").join(name);
        let mut inputs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.unwrap().path())
            .collect();
        inputs.sort();
        assert!(!inputs.is_empty(), "{}: empty corpus", dir.display());
        for input in &inputs {
            let data = std::fs::read(input).unwrap();
            let run = std::panic::catch_unwind(|| check(&data));
            assert!(run.is_ok(), "{name}: {} panicked", input.display());
        }
        eprintln!("{name}: {} corpus inputs", inputs.len());
    }
}
