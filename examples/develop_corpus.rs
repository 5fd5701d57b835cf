//! `develop` over the regression corpus (the open shared meshes, the fixtures and the
//! procedural families: saddles, domes and the developable sheets at 2k–45k faces, noise 0.01
//! and 0.1 mean edge lengths), one line per case. Every figure but the iteration count and
//! the stop reason is measured here from the geometry (corpus::measure; δS from recomputed
//! edge lengths; G = Σϖ² from the output's angle sums), not taken from the job's report:
//!
//!     cargo run --release --example develop_corpus -- [FILTER] [--set KEY=VALUE ...]
//!         [--no-shared]
//!
//! FILTER keeps the cases whose name contains it. Closed shared meshes are skipped (develop
//! keeps a closed surface's Gauss–Bonnet obstruction, which fl-mesh's corpus already covers).

use flatmesh::algorithms::{develop, parse_params, Silent};
use flatmesh::corpus;
use flatmesh::mesh::Mesh;
use std::path::Path;
use std::time::Instant;

/// δS = Σ|l − l⁰| / Σl⁰ over the edges, recomputed from both meshes' positions.
fn delta_s(input: &Mesh, output: &Mesh) -> f64 {
    let length = |p: &[[f64; 3]], e: &[u32; 2]| {
        let (a, b) = (p[e[0] as usize], p[e[1] as usize]);
        (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
    };
    let (mut change, mut total) = (0.0, 0.0);
    for e in input.conn().edges() {
        let l0 = length(input.positions(), e);
        change += (length(output.positions(), e) - l0).abs();
        total += l0;
    }
    if total > 0.0 {
        change / total
    } else {
        0.0
    }
}

/// G = Σ ϖ² over the interior vertices (Eq. 4), recomputed from the output's angle sums.
fn big_g(mesh: &Mesh) -> f64 {
    let theta = flatmesh::geometry::angle_sums(mesh);
    flatmesh::geometry::flattenability(mesh, &theta)
        .iter()
        .map(|w| w * w)
        .sum()
}

fn main() {
    let args = corpus::ExampleArgs::parse(std::env::args().skip(1)).expect("arguments");
    let (filter, shared) = (args.filter, args.shared);
    let params: develop::Params = parse_params(&args.params).expect("parameters");
    let root = Path::new(corpus::SHARED_MESHES);
    let closed: Vec<String> = corpus::shared_closed_meshes(root)
        .unwrap_or_default()
        .iter()
        .map(|p| p.file_stem().unwrap_or_default().to_string_lossy().into())
        .collect();
    println!(
        "{:<28} {:>6} {:>5} {:>9} {:>9} {:>9} {:>7} {:>7} {:>9} {:>13} {:>5} {:>7}  stop",
        "case",
        "faces",
        "conv",
        "ϖ_in",
        "ϖ_out",
        "G_out",
        "δS%",
        "hd%",
        "folds",
        "min angle°",
        "its",
        "s"
    );
    for case in corpus::cases(root, shared) {
        if !case.name.contains(&filter) || closed.contains(&case.name) {
            continue;
        }
        let input = match case.mesh() {
            Ok(m) => m,
            Err(e) => {
                println!("{:<28} refused: {e}", case.name);
                continue;
            }
        };
        let t = Instant::now();
        let out = develop::run(&input, &params, &Silent::default());
        let seconds = t.elapsed().as_secs_f64();
        let out = match out {
            Ok(o) => o,
            Err(e) => {
                println!("{:<28} error: {e}", case.name);
                continue;
            }
        };
        let output = out.mesh.clone().unwrap_or_else(|| input.clone());
        let m = corpus::measure(&input, &output);
        println!(
            "{:<28} {:>6} {:>5} {:>9.2e} {:>9.2e} {:>9.3e} {:>7.2} {:>7.2} {:>4}→{:<4} {:>6.2}→{:<6.2} {:>5} {:>7.2}  {}",
            case.name,
            input.num_faces(),
            m.varpi_out <= params.tolerance(),
            m.varpi_in,
            m.varpi_out,
            big_g(&output),
            100.0 * delta_s(&input, &output),
            100.0 * m.hausdorff_relative,
            m.folds_in,
            m.folds_out,
            m.min_angle_in.to_degrees(),
            m.min_angle_out.to_degrees(),
            out.summary.iterations,
            seconds,
            out.summary.stop_detail.chars().take(70).collect::<String>()
        );
    }
}
