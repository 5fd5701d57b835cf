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
    let args = corpus::ExampleArgs::parse(std::env::args().skip(1)).expect("arguments");
    let params: fl_mesh::Params = parse_params(&args.params).expect("parameters");
    corpus::print_table(
        Path::new(corpus::SHARED_MESHES),
        args.shared,
        &args.filter,
        &params,
    );
}
