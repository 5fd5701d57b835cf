//! fl-mesh over the whole regression corpus, one line per mesh, every figure measured from the
//! geometry (flatmesh::corpus::measure), never taken from the solver's report:
//!
//!     cargo run --release --example fl_corpus -- [FILTER] [--set KEY=VALUE ...] [--no-shared]
//!
//! FILTER keeps the cases whose name contains it. Closed meshes are run too (they must come
//! back no worse and named as Gauss–Bonnet obstructions).

use flatmesh::algorithms::{fl_mesh, parse_params};
use flatmesh::corpus;
use std::path::Path;

fn main() {
    let mut filter = String::new();
    let mut params = serde_json::Map::new();
    let mut shared = true;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--set" {
            let kv = args.next().expect("--set KEY=VALUE");
            let (k, v) = kv.split_once('=').expect("KEY=VALUE");
            let v = serde_json::from_str(v).unwrap_or(serde_json::Value::String(v.into()));
            params.insert(k.into(), v);
        } else if a == "--no-shared" {
            shared = false;
        } else {
            filter = a;
        }
    }
    let params: fl_mesh::Params = parse_params(&params).expect("parameters");
    corpus::print_table(Path::new(corpus::SHARED_MESHES), shared, &filter, &params);
}
