//! fl-mesh to ϖ_max ≤ 1e-6 (default parameters) on real meshes:
//! - ipc_skirt4K (7.5k faces, the size of the paper's largest FL example: 21.5 s and 47
//!   iterations on a 3 GHz Pentium; target here < 0.5 s);
//! - diffavatar_tshirt (5.5k faces, ϖ_max 0.52 rad under the arms: far from flattenable, like
//!   the paper's Fig. 6 start at ϖ_max 1.92; ipc_skirt4K starts at 8.8e-4);
//! - ipc_dress_knife_stage (29k faces, 14 flat dress panels) with normal noise of 1% of the
//!   mean edge length on the interior vertices;
//! - the same dress with whole panels (they are separate components, so no T-junctions)
//!   midpoint-subdivided 1→4 to about 45k faces, then the same noise: the issue's
//!   "garment of about 45k faces" (target < 10 s). No shared garment has 45k faces.
//!
//! Before timing, one checked run per mesh prints iterations, ϖ_max measured with
//! geometry::flattenability (a failed run is never timed as a success: it panics), and the
//! peak heap of that run (a counting global allocator). Skips meshes when ../shared is absent.

use criterion::{criterion_group, criterion_main, Criterion};
use flatmesh::algorithms::fl_mesh::{self, Params};
use flatmesh::algorithms::Silent;
use flatmesh::geometry;
use flatmesh::mesh::{Mesh, RawMesh};
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[path = "common/peak_alloc.rs"]
mod peak_alloc;
use peak_alloc::{LIVE, PEAK};

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("fl_mesh");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(20));
    let cases: [(&str, &str); 4] = [
        ("ipc_skirt4K", "developable/ipc_skirt4K.obj"),
        ("diffavatar_tshirt", "garment/diffavatar_tshirt.obj"),
        ("dress29k_noisy", "garment/ipc_dress_knife_stage.obj"),
        ("dress45k_noisy", "garment/ipc_dress_knife_stage.obj"),
    ];
    for (name, rel) in cases {
        let p = Path::new("../shared/meshes").join(rel);
        if !p.exists() {
            println!("skipping {rel}: ../shared not present");
            continue;
        }
        let mut mesh = flatmesh::io::load_path(&p).expect("loads").0;
        if name == "dress45k_noisy" {
            mesh = subdivide_panels(&mesh, 45_000);
        }
        if name.starts_with("dress") {
            // The dress's panels are already flat; shake interior vertices along the normal
            // (σ ≈ 1% of the mean edge length, fixed seed) so there is work to do.
            mesh = noisy(&mesh, 0.01);
        }
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let t = std::time::Instant::now();
        let out = fl_mesh::run(&mesh, &Params::default(), &Silent::default()).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let peak = PEAK.load(Ordering::Relaxed) - base;
        let m = out.mesh.unwrap();
        let theta = geometry::angle_sums(&m);
        let w = geometry::flattenability(&m, &theta)
            .into_iter()
            .fold(0.0, f64::max);
        println!(
            "{name}: {} faces, {} vertices, {} iterations, converged {}, ϖ_max {w:e} (geometry), \
             one run {secs:.2} s, peak heap requested {:.1} MB (faer reserves LDLᵀ scratch it \
             may not touch), process peak RSS so far {}",
            mesh.num_faces(),
            mesh.num_vertices(),
            out.summary.report.iterations,
            out.summary.report.converged,
            peak as f64 / 1e6,
            vm_hwm()
        );
        assert!(w <= 1e-6, "{name} did not converge");
        g.bench_function(name, |b| {
            b.iter(|| fl_mesh::run(&mesh, &Params::default(), &Silent::default()).unwrap())
        });
    }
    g.finish();
}

/// VmHWM from /proc/self/status (Linux), else "n/a".
fn vm_hwm() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .map(|l| l["VmHWM:".len()..].trim().to_string())
        })
        .unwrap_or_else(|| "n/a".into())
}

/// Midpoint 1→4 subdivision of whole patches so that the mesh has about `target` faces. Patches must not share vertices (else a T-junction would appear).
fn subdivide_panels(mesh: &Mesh, target: usize) -> Mesh {
    let mut raw = mesh.to_raw();
    raw.uv = None;
    let mut faces = raw.triangles.len();
    let mut chosen = vec![false; raw.patch_names.len()];
    let mut count = vec![0usize; raw.patch_names.len()];
    for &p in &raw.face_patch {
        count[p as usize] += 1;
    }
    // Largest panels first, each only if it does not overshoot the target by more than 5%.
    let mut order: Vec<usize> = (0..chosen.len()).collect();
    order.sort_by_key(|&p| std::cmp::Reverse(count[p]));
    for p in order {
        if faces + 3 * count[p] <= target + target / 20 {
            chosen[p] = true;
            faces += 3 * count[p];
        }
    }
    let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
    let mut out = RawMesh {
        positions: raw.positions.clone(),
        triangles: Vec::new(),
        face_patch: Vec::new(),
        patch_names: raw.patch_names.clone(),
        uv: None,
    };
    for (t, &p) in raw.triangles.iter().zip(&raw.face_patch) {
        if !chosen[p as usize] {
            out.triangles.push(*t);
            out.face_patch.push(p);
            continue;
        }
        let mut m = [0u32; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            m[k] = *mid.entry(key).or_insert_with(|| {
                let (pa, pb) = (raw.positions[a as usize], raw.positions[b as usize]);
                out.positions.push([0, 1, 2].map(|c| 0.5 * (pa[c] + pb[c])));
                (out.positions.len() - 1) as u32
            });
        }
        for tri in [
            [t[0], m[0], m[2]],
            [m[0], t[1], m[1]],
            [m[2], m[1], t[2]],
            [m[0], m[1], m[2]],
        ] {
            out.triangles.push(tri);
            out.face_patch.push(p);
        }
    }
    Mesh::new(out).expect("subdivided mesh is valid").0
}

fn noisy(mesh: &Mesh, sigma_edges: f64) -> Mesh {
    let p = mesh.positions();
    let h = geometry::mean_edge_length(mesh);
    let n = geometry::vertex_normals(mesh);
    let mut s = 0x9e3779b97f4a7c15u64;
    let mut pos = p.to_vec();
    for v in mesh.conn().interior_vertices() {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
        for c in 0..3 {
            pos[v as usize][c] += sigma_edges * h * u * n[v as usize][c];
        }
    }
    mesh.with_positions(pos).unwrap()
}

criterion_group!(benches, bench);
criterion_main!(benches);
