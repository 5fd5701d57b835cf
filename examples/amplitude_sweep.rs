//! fl-mesh on height-field disks of growing curvature, the measurements behind `cone_start =
//! auto`'s thresholds (issue 12): one line per mesh and cone_start, every figure measured
//! from the geometry, preceded by the mesh's fitted total curvature.
//!
//!     cargo run --release --example amplitude_sweep -- FAMILY AMPLITUDES SIZES MODES
//!
//! FAMILY is saddle (z = a(x² − y²)/2), dome (z = a(2 − x² − y²)/2), cylinder
//! (z = √(4 − a²x²)/a, developable), pleats (z = 0.15a sin 3πx, developable) or bumps (six
//! Gaussian bumps of height 3a and radius 4 mean edge lengths on a flat sheet) over [−1, 1]²;
//! AMPLITUDES, SIZES (faces) and MODES (cone_start values) are comma-separated, e.g.
//! `saddle 0.2,0.5,1 2000,7700 never,first,auto`. Noise 0.01 and 0.1 mean edge lengths. A
//! fifth argument KEY=VALUE,… sets other fl-mesh parameters for every run. With
//! SWEEP_HISTORY set, each run's iteration history is printed first; SWEEP_ROUND keeps the
//! cells inside the unit circle (a ragged round disk), SWEEP_JITTER=J moves interior grid
//! points in the plane by up to J cell widths (irregular triangles).

use flatmesh::algorithms::{fl_mesh, parse_params};
use flatmesh::corpus;
use flatmesh::mesh::{Mesh, RawMesh};
use std::f64::consts::PI;

/// The height field over an n × n grid of [−1, 1]²; with `round`, only the cells inside the
/// unit circle (a ragged round disk); with `jitter`, interior grid points moved in the plane
/// by up to that many cell widths (deterministic), so that the triangles are irregular.
fn height_field(n: usize, f: &dyn Fn(f64, f64) -> f64, round: bool, jitter: f64) -> Mesh {
    let at = |i: usize| 2.0 * i as f64 / n as f64 - 1.0;
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let cell = 2.0 / n as f64;
    let wobble = |i: usize, j: usize, k: u64| {
        let mut x = (i as u64 * 0x9E37_79B9 + j as u64 * 0x85EB_CA6B + k).wrapping_mul(0xC2B2_AE35);
        x ^= x >> 29;
        (x % 10_000) as f64 / 10_000.0 - 0.5
    };
    let positions: Vec<[f64; 3]> = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| (i, j)))
        .map(|(i, j)| {
            let inner = i > 0 && j > 0 && i < n && j < n;
            let s = if inner { jitter * cell } else { 0.0 };
            let (x, y) = (at(i) + s * wobble(i, j, 1), at(j) + s * wobble(i, j, 2));
            [x, y, f(x, y)]
        })
        .collect();
    let inside = |i: usize, j: usize| {
        let (x, y) = (at(i) + 0.5 * cell, at(j) + 0.5 * cell);
        !round || x * x + y * y <= 1.0
    };
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in (0..n).filter(|&i| inside(i, j)) {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.extend([[a, b, c], [a, c, d]]);
            } else {
                triangles.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    // Keep the used vertices only.
    let mut map = vec![u32::MAX; (n + 1) * (n + 1)];
    let mut kept = Vec::new();
    for t in &mut triangles {
        for v in t.iter_mut() {
            if map[*v as usize] == u32::MAX {
                map[*v as usize] = kept.len() as u32;
                kept.push(*v);
            }
            *v = map[*v as usize];
        }
    }
    let positions: Vec<[f64; 3]> = kept.iter().map(|&v| positions[v as usize]).collect();
    let count = triangles.len();
    let raw = RawMesh {
        positions,
        triangles,
        face_patch: vec![0; count],
        patch_names: vec!["sheet".into()],
        uv: None,
    };
    Mesh::new(raw).expect("a grid is a valid mesh").0
}

fn list<T: std::str::FromStr>(arg: Option<&String>, default: &str) -> Vec<T> {
    arg.map_or(default, |s| s.as_str())
        .split(',')
        .map(|x| x.parse().ok().expect("comma-separated values"))
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let family = args.first().map_or("saddle", |s| s.as_str()).to_string();
    let amplitudes: Vec<f64> = list(args.get(1), "0.05,0.2,0.5,0.7,1");
    let sizes: Vec<usize> = list(args.get(2), "2000,7700");
    let modes: Vec<String> = list(args.get(3), "never,first,auto");
    for &faces in &sizes {
        let n = (faces as f64 / 2.0).sqrt().round() as usize;
        for &a in &amplitudes {
            let f: Box<dyn Fn(f64, f64) -> f64> = match family.as_str() {
                "saddle" => Box::new(move |x, y| 0.5 * a * (x * x - y * y)),
                "dome" => Box::new(move |x, y| 0.5 * a * (2.0 - x * x - y * y)),
                "cylinder" => Box::new(move |x, _| (4.0 - a * a * x * x).sqrt() / a),
                "pleats" => Box::new(move |x, _| 0.15 * a * (3.0 * PI * x).sin()),
                "bumps" => Box::new(|_, _| 0.0),
                other => panic!("unknown family {other}"),
            };
            let round = std::env::var("SWEEP_ROUND").is_ok();
            let jitter = std::env::var("SWEEP_JITTER").map_or(0.0, |j| j.parse().unwrap_or(0.0));
            let mut clean = height_field(n, &*f, round, jitter);
            if family == "bumps" {
                // Six Gaussian bumps of height 3a and radius 4 mean edge lengths on a flat sheet.
                clean = corpus::with_bumps(&clean, 6, 3.0 * a, 4.0, 11);
            }
            for noise in [0.01, 0.1] {
                let mesh = corpus::with_normal_noise(&clean, noise, 7 + faces as u64);
                let name = format!("{family}-{a}-{faces}-{noise}");
                println!("# {name}: {:?}", fl_mesh::fitted_curvature(&mesh));
                for mode in &modes {
                    let mut m = serde_json::Map::new();
                    m.insert("cone_start".into(), mode.clone().into());
                    for kv in args.get(4).iter().flat_map(|s| s.split(',')) {
                        let (k, v) = kv.split_once('=').expect("KEY=VALUE");
                        let v = serde_json::from_str(v).unwrap_or_else(|_| v.into());
                        m.insert(k.into(), v);
                    }
                    let params: fl_mesh::Params = parse_params(&m).expect("cone_start");
                    if std::env::var("SWEEP_HISTORY").is_ok() {
                        // Per iteration: ϖ_max, full step / h̄, step length, μ.
                        let silent = flatmesh::algorithms::Silent::default();
                        let (_, r) = fl_mesh::solve(&mesh, &params, &silent).expect("runs");
                        for h in &r.history {
                            let (w, n, a) = (h.max_flattenability, h.step_norm, h.step_length);
                            println!("  {} {w:.3e} {n:.3} {a:.3} {:.1e}", h.iteration, h.damping);
                        }
                    }
                    match corpus::run_fl_mesh(&format!("{name}-{mode}"), &mesh, &params) {
                        Ok(row) => println!("{row}"),
                        Err(e) => println!("{name}-{mode}: {e}"),
                    }
                }
            }
        }
    }
}
