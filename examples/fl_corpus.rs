//! fl-mesh over the whole regression corpus, one line per mesh, every figure measured from the
//! geometry (flatmesh::corpus::measure), never taken from the solver's report:
//!
//!     cargo run --release --example fl_corpus -- [FILTER] [--set KEY=VALUE ...] [--no-shared]
//!
//! FILTER keeps the cases whose name contains it. Closed meshes are run too (they must come
//! back no worse and named as Gauss–Bonnet obstructions).

use flatmesh::algorithms::{fl_mesh, parse_params, Silent};
use flatmesh::corpus;
use flatmesh::mesh::Mesh;
use std::path::Path;
use std::time::Instant;

/// Loads a case's mesh (None when the reader refuses it, after saying why).
type Loader = Box<dyn Fn() -> Option<Mesh>>;

fn main() {
    let mut filter = String::new();
    let mut params = serde_json::Map::new();
    let mut shared = true;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--set" {
            let kv = args.next().expect("--set KEY=VALUE");
            let (k, v) = kv.split_once('=').expect("KEY=VALUE");
            let v = serde_json::from_str(v).unwrap_or(serde_json::Value::String(v.into()));
            params.insert(k.into(), v);
        } else if a == "--no-shared" {
            shared = false;
        } else {
            filter = a;
        }
    }
    let params: fl_mesh::Params = parse_params(&params).expect("parameters");
    let mut cases: Vec<(String, Loader)> = Vec::new();
    let root = Path::new(corpus::SHARED_MESHES);
    if shared {
        let open = corpus::shared_open_meshes(root).unwrap_or_default();
        let closed = corpus::shared_closed_meshes(root).unwrap_or_default();
        for p in open.into_iter().chain(closed) {
            let name = p.file_stem().unwrap().to_string_lossy().to_string();
            cases.push((
                name,
                Box::new(move || match flatmesh::io::load_path(&p) {
                    Ok((m, _)) => Some(m),
                    Err(e) => {
                        println!("{:<28} refused by the reader: {e}", p.display());
                        None
                    }
                }),
            ));
        }
    }
    for f in flatmesh::fixtures::all() {
        cases.push((
            format!("fixture-{}", f.name),
            Box::new(move || Some(Mesh::new(f.mesh.clone()).unwrap().0)),
        ));
    }
    for p in corpus::procedural() {
        cases.push((p.name(), Box::new(move || Some(p.mesh()))));
    }
    println!(
        "{:<28} {:>6} {:>4} {:>9} {:>9} {:>5} {:>5} {:>6} {:>6} {:>7} {:>7} {:>6}  stop",
        "mesh",
        "faces",
        "its",
        "ϖ in",
        "ϖ out",
        "f.in",
        "f.out",
        "∠in°",
        "∠out°",
        "hd%",
        "move%",
        "s"
    );
    let (mut total, mut conv) = (0, 0);
    for (name, load) in cases {
        if !name.contains(&filter) {
            continue;
        }
        let Some(mesh) = load() else { continue };
        let t = Instant::now();
        let out = fl_mesh::solve(&mesh, &params, &Silent::default());
        let secs = t.elapsed().as_secs_f64();
        let (m, r) = match out {
            Ok(x) => x,
            Err(e) => {
                println!("{name:<28} error: {e}");
                continue;
            }
        };
        let x = corpus::measure(&mesh, &m);
        total += 1;
        if x.varpi_out <= params.tolerance {
            conv += 1;
        }
        println!(
            "{:<28} {:>6} {:>4} {:>9.2e} {:>9.2e} {:>5} {:>5} {:>6.2} {:>6.2} {:>7.3} {:>7.3} {:>6.2}  {}{}",
            name,
            mesh.num_faces(),
            r.iterations,
            x.varpi_in,
            x.varpi_out,
            x.folds_in,
            x.folds_out,
            x.min_angle_in.to_degrees(),
            x.min_angle_out.to_degrees(),
            100.0 * x.hausdorff_relative,
            100.0 * x.max_move_relative,
            secs,
            r.stop_reason,
            if r.converged { "" } else { " [NOT CONVERGED]" }
        );
    }
    println!("{conv} of {total} reached ϖ_max ≤ {:e}", params.tolerance);
}
