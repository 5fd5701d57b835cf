//! The issue-12 regression corpus as a benchmark.
//!
//! First one run per case prints the corpus table (`flatmesh::corpus::Row`: iterations,
//! ϖ_max in/out, folds in/out, smallest corner in/out, relative Hausdorff and largest move,
//! seconds, stop reason — all but iterations and the stop reason measured from the geometry).
//! `FL_CORPUS_FILTER=saddle` keeps the cases whose name contains it; `FL_CORPUS_TABLE=0`
//! skips the table. Then criterion times the noisy-saddle class at 7.7k and 45k faces
//! (targets: < 0.5 s and < 10 s) with the defaults (`cone_start = auto`: those saddles start
//! from their developable cone), and at 7.7k faces with `cone_start = fallback` (the default
//! before `auto`, which reaches the cone only after the run from the input stalled) as the
//! ratio to compare with.
//! A case that does not converge is not timed (its row says how far it got), so a stall is
//! never read as a timing.

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
    let fallback = Params {
        cone_start: fl_mesh::ConeStart::Fallback,
        ..Params::default()
    };
    let runs = [
        (7_700, Params::default(), ""),
        (7_700, fallback, " cone_start=fallback"),
        (45_000, Params::default(), ""),
    ];
    for (faces, params, label) in runs {
        let case = Procedural {
            family: Family::Saddle,
            faces,
            noise: 0.01,
        };
        let mesh = case.mesh();
        let name = format!("{}{label}", case.name());
        let row = corpus::run_fl_mesh(&name, &mesh, &params).unwrap();
        println!("{row}");
        if !row.converged {
            // A stall is not a timing: say so and time nothing.
            println!("{name}: not timed, it did not converge");
            continue;
        }
        g.bench_function(&name, |b| {
            b.iter(|| fl_mesh::run(&mesh, &params, &Silent::default()).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
