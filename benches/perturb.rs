//! `perturb` at the size of the paper's pants example (FL Table 1: 3,539 V on a 5,659 V body,
//! 21.5 s, stopping at ϖ_max 4.75e-3): a procedural sleeve of 3,500 vertices with inward dents
//! around a closed arm of 5,702 vertices (`corpus::sleeve`, `corpus::arm`; 17 sleeve vertices
//! start inside), with `method=local` (Algorithm 2, the paper's defaults) and `method=global`
//! (to ϖ_max ≤ 1e-6). Targets: local < 1 s, global < 1 s to 1e-6.
//!
//! Before timing, one checked run per method prints iterations, ϖ_max in and out (measured by
//! `geometry`), penetrating sleeve vertices before and after (brute force, winding number) and
//! the run's peak heap.

use criterion::{criterion_group, criterion_main, Criterion};
use flatmesh::algorithms::perturb::{self, Method, Params};
use flatmesh::algorithms::Silent;
use flatmesh::corpus;
use flatmesh::mesh::Mesh;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[path = "common/peak_alloc.rs"]
mod peak_alloc;
use peak_alloc::{LIVE, PEAK};

fn penetrating(m: &Mesh, body: &Mesh) -> usize {
    m.positions()
        .iter()
        .filter(|&&p| corpus::brute_signed_distance(body, p) < 0.0)
        .count()
}

fn bench(c: &mut Criterion) {
    let body = corpus::arm(0.3, 2.0, 94, 60);
    let garment = corpus::sleeve(0.32, 2.0, 70, 49, 0.04);
    println!(
        "sleeve {} V / {} F, arm {} V / {} F",
        garment.num_vertices(),
        garment.num_faces(),
        body.num_vertices(),
        body.num_faces()
    );
    let pen_in = penetrating(&garment, &body);
    let mut group = c.benchmark_group("perturb");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    for method in [Method::Local, Method::Global] {
        let params = Params {
            method,
            ..Params::default()
        };
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let t = std::time::Instant::now();
        let o = perturb::run(&garment, Some(&body), &params, &Silent::default()).unwrap();
        let seconds = t.elapsed().as_secs_f64();
        let peak = PEAK.load(Ordering::Relaxed) - base;
        let out = o.mesh.unwrap();
        println!(
            "{method:?}: {} iterations, ϖ_max {:.3e} -> {:.3e} ({}), penetrating {pen_in} -> {}, \
             {seconds:.2} s, peak heap {:.1} MB",
            o.summary.iterations,
            corpus::max_flattenability(&garment),
            corpus::max_flattenability(&out),
            o.summary.stop_reason.as_str(),
            penetrating(&out, &body),
            peak as f64 / 1e6
        );
        let name = format!("{method:?}").to_lowercase();
        group.bench_function(format!("sleeve3.5k_arm5.7k/{name}"), |b| {
            b.iter(|| perturb::run(&garment, Some(&body), &params, &Silent::default()).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
