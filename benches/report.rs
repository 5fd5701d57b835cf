//! Parse + validate + connectivity + full report, on wavy grid meshes of 125k, 250k and 500k
//! faces written as OBJ text (issue target: 500k faces in under a second, growing linearly).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use flatmesh::io::{self, Format};
use flatmesh::report::Report;
use std::fmt::Write;

/// An n×n-vertex height-field grid, 2(n−1)² triangles, as OBJ text.
fn wavy_grid_obj(n: usize) -> String {
    let mut s = String::with_capacity(n * n * 60);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            let z = 0.1 * (7.0 * x).sin() * (5.0 * y).cos();
            let _ = writeln!(s, "v {x} {y} {z}");
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i + 1;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            let _ = writeln!(s, "f {a} {b} {d}\nf {a} {d} {c}");
        }
    }
    s
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("parse_connectivity_report");
    g.sample_size(10);
    for n in [251usize, 355, 501] {
        let text = wavy_grid_obj(n);
        let faces = 2 * (n - 1) * (n - 1);
        g.throughput(Throughput::Elements(faces as u64));
        g.bench_with_input(BenchmarkId::from_parameter(faces), &text, |b, text| {
            b.iter(|| {
                let (mesh, warnings) = io::load(text.as_bytes(), Format::Obj).unwrap();
                let report = Report::compute(&mesh, &warnings);
                assert_eq!(report.faces, faces);
                report
            })
        });
    }
    g.finish();

    // The same, plus the JSON document `flatmesh report --json` prints.
    let mut g = c.benchmark_group("parse_connectivity_report_json");
    g.sample_size(10);
    let text = wavy_grid_obj(501);
    g.bench_function("500000", |b| {
        b.iter(|| {
            let (mesh, warnings) = io::load(text.as_bytes(), Format::Obj).unwrap();
            let report = Report::compute(&mesh, &warnings);
            serde_json::to_vec(&report).unwrap().len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
