//! `perturb` on almost flattenable garments, as a pattern maker would send them: every case of
//! the corpus (the open shared meshes, the fixtures, the procedural families up to 7.7k faces)
//! is first made flattenable by fl-mesh (defaults; cached in DIR as NAME.fl.obj), then given a
//! few smooth bumps (`corpus::with_bumps`: 4 bumps of 0.15 mean edge lengths, radius 4), and run
//! through `perturb` with `method=global` and `method=local`. MakeHuman garments run against
//! the MakeHuman body they were made for (female/male generic, same frame).
//!
//!     cargo run --release --example perturb_corpus -- [FILTER] [--out DIR] [--no-bumps]
//!         [--body-under]
//!
//! `--body-under` gives every case a body that follows fl-mesh's output 0.3 h̄ under it
//! (`corpus::body_under`, open, oriented towards the garment) and pushes the four bumps 0.6 h̄
//! *into* it, for real garments that have no body of their own that fits.
//!
//! Every figure is measured here from the geometry: ϖ_max (corpus::max_flattenability), folds,
//! smallest corner, relative Hausdorff distance to the perturbed input, largest displacement in
//! mean edge lengths beside that of the known flattenable mesh (fl-mesh's, before the bumps:
//! a perturbation that moves much farther found a worse answer than one that exists), and
//! penetrating vertices before/after by brute-force signed distance
//! (closest point over every body triangle, sign by winding number) — not the job's figures.
//! Rows marked `fl-mesh stalled` start from a stalled fl-mesh output (not flattenable).

use flatmesh::algorithms::{perturb, Silent};
use flatmesh::corpus;
use flatmesh::mesh::{Mesh, VertexKind};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The MakeHuman body a garment was made for, if any.
fn body_for(name: &str, root: &Path) -> Option<Mesh> {
    let file = if name.starts_with("mh_female") {
        "body/mh_female_generic.obj"
    } else if name.starts_with("mh_male") {
        "body/mh_male_generic.obj"
    } else {
        return None;
    };
    flatmesh::io::load_path(&root.join(file)).ok().map(|m| m.0)
}

/// Height and radius of the bumps, in mean edge lengths.
const BUMP_HEIGHT: f64 = 0.15;
const BUMP_RADIUS: f64 = 4.0;

/// Largest distance between vertex i of `a` and vertex i of `b`.
fn max_distance(a: &Mesh, b: &Mesh) -> f64 {
    a.positions()
        .iter()
        .zip(b.positions())
        .map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

/// A body for the case: with `under`, one that follows fl-mesh's output 0.3 h̄ under it (open;
/// signed distances by the closest face's side), else the MakeHuman body a garment was made
/// for (closed; winding number).
struct CaseBody {
    mesh: Mesh,
    open: bool,
}

/// Interior vertices deeper inside `body` than 1e-6 mean edge lengths (what `converged`
/// allows), by brute force.
fn penetrating(mesh: &Mesh, body: &CaseBody) -> usize {
    let h = flatmesh::geometry::mean_edge_length(mesh);
    (0..mesh.num_vertices() as u32)
        .into_par_iter()
        .filter(|&v| mesh.conn().is_interior(v))
        .filter(|&v| {
            let p = mesh.position(v);
            let s = if body.open {
                corpus::brute_signed_distance_open(&body.mesh, p)
            } else {
                corpus::brute_signed_distance(&body.mesh, p)
            };
            s < -1e-6 * h
        })
        .count()
}

fn main() {
    let mut filter = String::new();
    let mut out = PathBuf::from("target/perturb_corpus");
    let mut bumps = true;
    let mut under = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = PathBuf::from(args.next().expect("--out DIR")),
            "--no-bumps" => bumps = false,
            "--body-under" => under = true,
            f => filter = f.to_string(),
        }
    }
    std::fs::create_dir_all(&out).expect("output directory");
    let root = PathBuf::from(corpus::SHARED_MESHES);
    println!(
        "{:<28} {:>6} {:>6} {:>4} {:>9} {:>9} {:>5} {:>6} {:>6} {:>6} {:>7} {:>7} {:>9} {:>7}  stop",
        "mesh",
        "faces",
        "method",
        "its",
        "ϖ in",
        "ϖ out",
        "conv",
        "folds",
        "∠min°",
        "hd%",
        "move/h",
        "known/h",
        "pen.in→out",
        "s"
    );
    for case in corpus::cases(&root, true) {
        if !case.name.contains(&filter) || case.name.contains("45000") {
            continue;
        }
        let Ok(mesh) = case.mesh() else {
            continue;
        };
        // Garments are open: a closed body cannot be flattenable (Gauss–Bonnet).
        let open = (0..mesh.num_vertices() as u32).any(|v| {
            !matches!(
                mesh.conn().kinds()[v as usize],
                VertexKind::Interior | VertexKind::Unreferenced
            )
        });
        if !open {
            continue;
        }
        let Some((fl, conv)) = corpus::fl_meshed_cached(&case.name, &mesh, &out) else {
            continue;
        };
        if fl.conn().interior_vertices().next().is_none() {
            continue;
        }
        let h = flatmesh::geometry::mean_edge_length(&fl);
        let body = if under {
            Some(CaseBody {
                mesh: corpus::body_under(&fl, 0.3 * h),
                open: true,
            })
        } else {
            body_for(&case.name, &root).map(|mesh| CaseBody { mesh, open: false })
        };
        // With a body under the garment the dents go into it.
        let height = if under { -0.6 } else { BUMP_HEIGHT };
        let input = if bumps {
            corpus::with_bumps(&fl, 4, height, BUMP_RADIUS, 17)
        } else {
            fl.clone()
        };
        // A flattenable mesh this far from the input is known (fl-mesh's, before the bumps).
        let known = max_distance(&input, &fl);
        let pen_in = body.as_ref().map(|b| penetrating(&input, b));
        for method in [perturb::Method::Global, perturb::Method::Local] {
            let params = perturb::Params {
                method,
                ..perturb::Params::default()
            };
            let t = std::time::Instant::now();
            let res = perturb::run(
                &input,
                body.as_ref().map(|b| &b.mesh),
                &params,
                &Silent::default(),
            );
            let seconds = t.elapsed().as_secs_f64();
            let o = match res {
                Ok(o) => o,
                Err(e) => {
                    println!("{:<28} {method:?}: error: {e}", case.name);
                    continue;
                }
            };
            let Some(result) = o.mesh else { continue };
            let m = corpus::measure(&input, &result);
            let moved = max_distance(&input, &result);
            let pen = match (&body, pen_in) {
                (Some(b), Some(before)) => format!("{before}→{}", penetrating(&result, b)),
                _ => "-".into(),
            };
            println!(
                "{:<28} {:>6} {:>6} {:>4} {:>9.2e} {:>9.2e} {:>5} {:>6} {:>6.2} {:>6.3} {:>7.2} {:>7.2} {:>9} {:>7.2}  {}{}",
                case.name,
                input.num_faces(),
                format!("{method:?}").to_lowercase(),
                o.summary.iterations,
                m.varpi_in,
                m.varpi_out,
                if m.varpi_out <= params.tolerance() { "yes" } else { "no" },
                format!("{}→{}", m.folds_in, m.folds_out),
                m.min_angle_out.to_degrees(),
                100.0 * m.hausdorff_relative,
                moved / h,
                known / h,
                pen,
                seconds,
                o.summary.stop_reason.as_str(),
                if conv { "" } else { " [fl-mesh stalled]" }
            );
        }
    }
    if let Ok(status) = std::fs::read_to_string("/proc/self/status") {
        if let Some(line) = status.lines().find(|l| l.starts_with("VmHWM")) {
            println!(
                "peak resident memory of the whole run: {}",
                line[6..].trim()
            );
        }
    }
}
