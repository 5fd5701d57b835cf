//! The black-box service tests: each starts real `flatmesh serve` processes (tests/common) and
//! talks to them over HTTP. One test binary for all of them, because linking and
//! monomorphising the HTTP client and server stack once instead of nine times saves minutes
//! of every CI build; `cargo test --release --test api service::` runs one file's tests.

#[path = "../common/mod.rs"]
mod common;

mod browser;
mod clients;
mod deploy;
mod hostile;
mod readme_promises;
mod replicas;
mod service;
mod store_contract;
mod upgrade;
