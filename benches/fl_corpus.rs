//! The issue-12 regression corpus as a benchmark.
//!
//! First one run per case prints the corpus table (`flatmesh::corpus::Row`: iterations,
//! ϖ_max in/out, folds in/out, smallest corner in/out, relative Hausdorff and largest move,
//! seconds, stop reason — all but iterations and the stop reason measured from the geometry).
//! `FL_CORPUS_FILTER=saddle` keeps the cases whose name contains it; `FL_CORPUS_TABLE=0`
//! skips the table. Then criterion times the noisy-saddle class at 7.7k and 45k faces
//! (targets: < 0.5 s and < 10 s), with the defaults and with `cone_start = first` (the
//! default at 45k faces is run once, not timed: it spends minutes stalling before the cone).
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
    let first = Params {
        cone_start: fl_mesh::ConeStart::First,
        ..Params::default()
    };
    // (faces, parameters, label, timed): the defaults reach the saddles' cone only after the
    // run from the input stalled (minutes at 45k faces, so that one is run once, not timed).
    let runs = [
        (7_700, Params::default(), "", true),
        (7_700, first.clone(), " cone_start=first", true),
        (45_000, Params::default(), "", false),
        (45_000, first, " cone_start=first", true),
    ];
    for (faces, params, label, timed) in runs {
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
        if !timed {
            println!("{name}: one run only (above)");
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
