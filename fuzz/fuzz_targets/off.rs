//! The OFF reader on arbitrary bytes, within a small triangle limit: it must return a mesh
//! or an error, never panic, and a mesh it returns must validate and write back.
//! The checks are flatmesh::fuzzing::off, which `cargo test` also replays on the corpus.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| flatmesh::fuzzing::off(data));
