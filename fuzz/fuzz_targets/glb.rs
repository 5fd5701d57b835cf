//! The GLB reader on arbitrary bytes, within a small triangle limit: it must return a mesh
//! or an error, never panic, and a mesh it returns must validate and write back.
//! The checks are flatmesh::fuzzing::glb, which `cargo test` also replays on the corpus.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(
    // gltf-json panics on some malformed documents; the reader catches that (io::quietly)
    // and reports an error. libFuzzer's hook would abort on the caught panic: keep it for
    // every other panic only.
    init: flatmesh::io::install_quiet_panic_hook(),
    |data: &[u8]| flatmesh::fuzzing::glb(data)
);
