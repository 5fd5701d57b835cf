//! `segment`, the whole pipeline (VSA, min-cut, split, merging, cut mesh, flattening), on
//! ../shared/meshes' classic/bff_face.obj (34k faces, a scanned face: the largest shared mesh)
//! and paper/bff_hemisphere.obj after two levels of Loop subdivision (64k faces, above the
//! issue's 50k). Target: under 10 s on a 50k-face model (CGAL's VSA alone: 0.9 s for 20
//! proxies on such a mesh).
//!
//! Before timing, one checked run per mesh prints the chart counts per stage, the worst
//! chart, the flattenings run, the seconds per stage and the run's peak heap.
//!
//! Measured (2-core VM, defaults, medians of 10): bff_face 8.88 s (VSA 1.47, merging 7.35 s
//! over 343 flattenings, 162 → 15 charts, peak heap 219 MB), hemisphere 64k 3.46 s (64 → 8
//! charts, 38 MB); before the counting sort of half-edges and the packed VSA heap key:
//! 11.0 s and 4.7 s (criterion's change against that baseline: −19 % and −27 %).

use criterion::{criterion_group, criterion_main, Criterion};
use flatmesh::algorithms::develop::loop_subdivide;
use flatmesh::algorithms::segment::{self, Params};
use flatmesh::algorithms::Silent;
use flatmesh::corpus;
use flatmesh::mesh::Mesh;
use std::sync::atomic::Ordering;
use std::time::Duration;

#[path = "common/peak_alloc.rs"]
mod peak_alloc;
use peak_alloc::{LIVE, PEAK};

fn load(rel: &str) -> Option<Mesh> {
    let path = std::path::Path::new(corpus::SHARED_MESHES).join(rel);
    let Ok(bytes) = std::fs::read(&path) else {
        println!("SKIPPED: {} is absent", path.display());
        return None;
    };
    Some(
        flatmesh::io::load(&bytes, flatmesh::io::Format::Obj)
            .unwrap()
            .0,
    )
}

fn bench(c: &mut Criterion) {
    let Some(face) = load("classic/bff_face.obj") else {
        return;
    };
    let Some(mut hemi) = load("paper/bff_hemisphere.obj") else {
        return;
    };
    for _ in 0..2 {
        hemi = Mesh::new(loop_subdivide(&hemi)).unwrap().0;
    }
    let mut group = c.benchmark_group("segment");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(60));
    let params = Params::default();
    for (label, mesh) in [("bff_face34k", &face), ("hemisphere_loop2_64k", &hemi)] {
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let o = segment::run(mesh, &params, &Silent::default()).unwrap();
        let peak = PEAK.load(Ordering::Relaxed) - base;
        let s = &o.summary;
        println!(
            "{label}: {} F; charts {} → {} → {} (tested) → {}; worst |A| {:.2} %, L² {:.3}, \
             within {}; {} flattenings; s: vsa {:.2} refine {:.2} merge {:.2} flatten {:.2} \
             total {:.2}; peak heap {:.0} MB",
            mesh.num_faces(),
            s.charts.vsa,
            s.charts.refined,
            s.charts.tested,
            s.charts.merged,
            s.worst_area_distortion_pct,
            s.worst_l2_stretch,
            s.all_within_bounds,
            s.merge_evaluations,
            s.stage_seconds.vsa,
            s.stage_seconds.refine,
            s.stage_seconds.merge,
            s.stage_seconds.flatten,
            s.stage_seconds.total,
            peak as f64 / 1e6
        );
        group.bench_function(label, |b| {
            b.iter(|| segment::run(mesh, &params, &Silent::default()).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
