//! Closest-point queries (src/spatial.rs): building the hierarchy and 1 query per 10 vertices,
//! on a noisy 100k-face saddle and on a 20k-triangle fan of long thin triangles; checked
//! against brute force on a sample first.
use criterion::{criterion_group, criterion_main, Criterion};
use flatmesh::corpus::{Family, Procedural};
use flatmesh::spatial::{brute_closest_d2, TriangleBvh};
use std::hint::black_box;

fn fan(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut pos = vec![[0.0, 0.0, 0.0]];
    for i in 0..=n {
        let a = std::f64::consts::TAU * i as f64 / (n + 1) as f64;
        pos.push([a.cos(), a.sin(), 0.01 * (7.0 * a).sin()]);
    }
    let tri = (0..=n as u32)
        .map(|i| [0, 1 + i, 1 + (i + 1) % (n as u32 + 1)])
        .collect();
    (pos, tri)
}

fn bench(c: &mut Criterion) {
    let saddle = Procedural {
        family: Family::Saddle,
        faces: 100_000,
        noise: 0.1,
    }
    .mesh();
    let cases = [
        (
            "saddle100k",
            saddle.positions().to_vec(),
            saddle.triangles().to_vec(),
        ),
        {
            let (p, t) = fan(20_000);
            ("fan20k", p, t)
        },
    ];
    for (name, pos, tri) in &cases {
        let queries: Vec<[f64; 3]> = pos
            .iter()
            .step_by(10)
            .map(|p| [p[0] + 0.003, p[1] - 0.002, p[2] + 0.01])
            .collect();
        let mut g = c.benchmark_group(*name);
        g.sample_size(10);
        g.bench_function("bvh build", |b| {
            b.iter(|| black_box(TriangleBvh::new(pos, tri)))
        });
        let bvh = TriangleBvh::new(pos, tri);
        for q in queries.iter().step_by(97) {
            let brute = brute_closest_d2(*q, pos, tri);
            let d = bvh.closest(*q).1;
            assert!((d - brute).abs() <= 1e-12 * (1.0 + brute), "{d} vs {brute}");
        }
        g.bench_function("bvh queries", |b| {
            b.iter(|| queries.iter().map(|q| bvh.closest(*q).1).sum::<f64>())
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
