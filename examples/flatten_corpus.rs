//! flatten over the regression corpus, one line per piece, with the figures a pattern maker
//! checks recomputed here from the pattern (never taken from the flatten module's measures,
//! except its exact overlap test S(Ω), which is printed beside a brute-force recount):
//!
//!     cargo run --release --example flatten_corpus -- [FILTER] [--fl-mesh] [--out DIR]
//!         [--set KEY=VALUE ...] [--no-shared | --shared-only]
//!
//! With `--fl-mesh` every mesh first goes through fl-mesh (default parameters; the result is
//! cached as DIR/NAME.fl.obj with DIR/NAME.fl.txt saying whether it converged) and the
//! flattened mesh is fl-mesh's output. Each pattern is written to DIR/NAME.svg (DIR defaults
//! to target/flatten_corpus).
//!
//! Columns: faces, boundary loops as given, real cuts, holes kept, flipped triangles (signed
//! area ≤ 0), boundary crossings and touchings (every pair of boundary segments), S(Ω), largest relative
//! edge-length error over all triangle edges (2D against 3D: the stretch an isometry would
//! not have), largest relative boundary-edge error, area-weighted mean |ln(A2D/A3D)|, ϖ_max
//! of the piece's interior.

use flatmesh::algorithms::{flatten, parse_params, Silent};
use flatmesh::corpus;
use flatmesh::corpus::pattern_checks::{
    area_distortion, boundary_crossings, boundary_length_error, edge_length_error, flipped,
};
use std::path::{Path, PathBuf};

fn main() {
    let mut filter = String::new();
    let mut params = serde_json::Map::new();
    let (mut shared, mut fl, mut out) = (true, false, PathBuf::from("target/flatten_corpus"));
    let mut shared_only = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--set" => {
                let kv = args.next().expect("--set KEY=VALUE");
                let (k, v) = kv.split_once('=').expect("KEY=VALUE");
                let v = serde_json::from_str(v).unwrap_or(serde_json::Value::String(v.into()));
                params.insert(k.into(), v);
            }
            "--no-shared" => shared = false,
            "--shared-only" => shared_only = true,
            "--fl-mesh" => fl = true,
            "--out" => out = PathBuf::from(args.next().expect("--out DIR")),
            _ => filter = a,
        }
    }
    let params: flatten::Params = parse_params(&params).expect("parameters");
    std::fs::create_dir_all(&out).expect("output directory");
    println!(
        "{:<28} {:<22} {:>6} {:>3} {:>3} {:>3} {:>5} {:>5} {:>2} {:>9} {:>9} {:>8} {:>9} {:>6}",
        "mesh",
        "piece",
        "faces",
        "lp",
        "cut",
        "hol",
        "flip",
        "cross",
        "S",
        "edge err",
        "bnd err",
        "area",
        "ϖ_max",
        "s"
    );
    let generated: Vec<String> = corpus::procedural().iter().map(|p| p.name()).collect();
    for case in corpus::cases(Path::new(corpus::SHARED_MESHES), shared) {
        let made_here = case.name.starts_with("fixture-") || generated.contains(&case.name);
        if !case.name.contains(&filter) || (shared_only && made_here) {
            continue;
        }
        let Ok(mut mesh) = case.mesh() else {
            continue;
        };
        let mut tag = "";
        if fl {
            let Some((m, conv)) = corpus::fl_meshed_cached(&case.name, &mesh, &out) else {
                continue;
            };
            mesh = m;
            tag = if conv { "" } else { " [fl-mesh stalled]" };
        }
        let t = std::time::Instant::now();
        let res = flatten::run(&mesh, &params, &Silent::default());
        let secs = t.elapsed().as_secs_f64();
        let res = match res {
            Ok(r) => r,
            Err(e) => {
                println!("{:<28} error: {e}", case.name);
                continue;
            }
        };
        let pat = res.patterns.expect("patterns");
        let _ = std::fs::write(
            out.join(format!("{}.svg", case.name)),
            flatmesh::io::pattern::to_svg(&pat),
        );
        for (k, p) in pat.pieces.iter().enumerate() {
            let s = &res.summary.pieces[k].solver;
            println!(
                "{:<28} {:<22} {:>6} {:>3} {:>3} {:>3} {:>5} {:>5} {:>2} {:>9.2e} {:>9.2e} {:>8.4} {:>9.2e} {:>6.2}{tag}",
                case.name,
                p.patch.chars().take(22).collect::<String>(),
                p.triangles.len(),
                s.loops,
                s.real_cuts,
                s.holes,
                flipped(p),
                boundary_crossings(p),
                p.measures["overlap"],
                edge_length_error(&mesh, p),
                boundary_length_error(&mesh, p),
                area_distortion(&mesh, std::slice::from_ref(p)).0,
                p.measures["varpi_max"].as_f64().unwrap_or(f64::NAN),
                secs
            );
        }
        for w in &res.summary.job_warnings {
            println!("{:<28}   warning: {w}", case.name);
        }
    }
}
