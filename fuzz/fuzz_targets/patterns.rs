//! The pattern exporters on what a user can make them draw: an arbitrary small OBJ mesh,
//! flattened with few iterations, written as JSON, SVG and DXF, and the DXF read back.
//! The checks are flatmesh::fuzzing::patterns, which `cargo test` also replays on the corpus.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| flatmesh::fuzzing::patterns(data));
