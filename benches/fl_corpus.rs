//! The issue-12 regression corpus as a benchmark.
//!
//! First one run per case prints the corpus table (`flatmesh::corpus::Row`: iterations,
//! ϖ_max in/out, folds in/out, smallest corner in/out, relative Hausdorff and largest move,
//! seconds, stop reason — all but iterations and the stop reason measured from the geometry).
//! `FL_CORPUS_FILTER=saddle` keeps the cases whose name contains it; `FL_CORPUS_TABLE=0`
//! skips the table. Then criterion times the noisy-saddle class at 7.7k and 45k faces
//! (targets: < 0.5 s and < 10 s). A case that does not converge is not timed (its row says
//! how far it got), so a stall is never read as a timing.

use criterion::{criterion_group, criterion_main, Criterion};
use flatmesh::algorithms::fl_mesh::{self, Params};
use flatmesh::algorithms::Silent;
use flatmesh::corpus::{self, Family, Procedural};
use std::path::Path;
use std::time::Duration;

fn table() {
    if std::env::var("FL_CORPUS_TABLE").is_ok_and(|v| v == "0") {
        return;
    }
    let filter = std::env::var("FL_CORPUS_FILTER").unwrap_or_default();
    corpus::print_table(
        Path::new(corpus::SHARED_MESHES),
        true,
        &filter,
        &Params::default(),
    );
}

fn bench(c: &mut Criterion) {
    table();
    let mut g = c.benchmark_group("fl_corpus");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(10));
    for faces in [7_700, 45_000] {
        let case = Procedural {
            family: Family::Saddle,
            faces,
            noise: 0.01,
        };
        let mesh = case.mesh();
        let row = corpus::run_fl_mesh(&case.name(), &mesh, &Params::default()).unwrap();
        println!("{row}");
        if !row.converged {
            // A stall is not a timing: say so and time nothing.
            println!("{}: not timed, it did not converge", case.name());
            continue;
        }
        g.bench_function(case.name(), |b| {
            b.iter(|| fl_mesh::run(&mesh, &Params::default(), &Silent::default()).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
