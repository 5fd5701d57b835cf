//! `flatten` end to end (pieces, LPFB, interior Cholesky, measures, seams) on noisy
//! half-cylinder patches of 50k and 200k faces and on ../shared/meshes/classic/bff_face.obj.
//! Peers on this kind of machine (issue 4): Boundary First Flattening 0.27 s at 50k faces and
//! 2.1 s at 200k; libigl LSCM ≈ 1.0 s and CGAL LSCM ≈ 0.5 s at 50k.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use flatmesh::algorithms::flatten::{self, Method, Params};
use flatmesh::algorithms::Silent;
use flatmesh::mesh::{Mesh, RawMesh};

/// Half cylinder (radius 0.5 m, height 1 m) on an n×n grid, 2(n−1)² faces, every vertex moved
/// radially by uniform noise of ±0.2 % of the radius (a deterministic LCG), so the patch is
/// nearly but not exactly developable, with a noisy boundary.
fn noisy_half_cylinder(n: usize) -> Mesh {
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut positions = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let t = std::f64::consts::PI * i as f64 / (n - 1) as f64;
            let r = 0.5 * (1.0 + 0.004 * rnd());
            positions.push([r * t.cos(), r * t.sin(), j as f64 / (n - 1) as f64]);
        }
    }
    let mut triangles = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    let nf = triangles.len();
    Mesh::new(RawMesh {
        positions,
        triangles,
        face_patch: vec![0; nf],
        patch_names: vec!["half cylinder".into()],
        uv: None,
    })
    .expect("valid")
    .0
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("flatten");
    g.sample_size(10);
    let mut cases: Vec<(String, Mesh)> = [159usize, 317]
        .iter()
        .map(|&n| {
            let m = noisy_half_cylinder(n);
            (format!("half_cylinder_{}", m.num_faces()), m)
        })
        .collect();
    match flatmesh::io::load_path(std::path::Path::new(
        "../shared/meshes/classic/bff_face.obj",
    )) {
        Ok((m, _)) => cases.push(("bff_face_34144".into(), m)),
        Err(_) => println!("skipping bff_face: ../shared not present"),
    }
    for (name, mesh) in &cases {
        g.throughput(Throughput::Elements(mesh.num_faces() as u64));
        for method in [Method::Lpfb, Method::Lscm] {
            let params = Params {
                method,
                ..Params::default()
            };
            let id = BenchmarkId::new(format!("{method:?}").to_lowercase(), name);
            g.bench_with_input(id, mesh, |b, mesh| {
                b.iter(|| {
                    let o = flatten::run(mesh, &params, &Silent::default()).unwrap();
                    assert!(o.patterns.is_some());
                    o
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
