//! The library's and the command line's integration tests, one module a subject, in one test
//! binary: twenty binaries linked the whole library and its dependencies twenty times.
//! `cargo test --release --test engine develop::` runs one module's tests.
//!
//! tests/fl_mesh_corpus.rs (minutes of real-garment runs) and tests/time_limit.rs (wall-clock
//! bounds that other tests' load would blur) stay binaries of their own.

mod architecture;
mod build;
mod cli_fl_mesh;
mod develop;
mod fixtures;
mod fl_mesh;
mod flatten;
mod flatten_cuts;
mod fuzz_corpus;
mod gltf;
mod gradients;
mod obj_off;
mod patterns_cut_ready;
mod perturb;
mod report_cli;
mod robustness;
mod segment;
mod shared_meshes;
mod subdivide;
mod validation;
