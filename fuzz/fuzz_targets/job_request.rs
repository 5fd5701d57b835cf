//! A job request's kind and parameters (the JSON a client submits) through the typed jobs
//! domain: parsed or refused with an error naming the member, never a panic; a parsed spec
//! serialises and bounds its output.
//! The checks are flatmesh::fuzzing::job_request, which `cargo test` also replays on the corpus.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| flatmesh::fuzzing::job_request(data));
