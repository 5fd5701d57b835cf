//! Draw a mesh as a flat-shaded SVG, edges that fold (adjacent normals turning by more than
//! 120°, `geometry::fold_edges`) in red, to look at what fl-mesh or develop did to a garment:
//!
//!     cargo run --release --example render_mesh -- IN.obj OUT.svg [YAW_DEG] [PITCH_DEG]
//!
//! Orthographic view after turning the mesh by YAW about y and PITCH about x (defaults 20, 10);
//! faces painted back to front. Rasterise with the `render_svg` example.

use flatmesh::geometry;
use std::fmt::Write;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: render_mesh IN.(obj|glb|gltf|off) OUT.svg [YAW_DEG] [PITCH_DEG]");
        std::process::exit(2);
    }
    let angle = |k: usize, d: f64| {
        args.get(k)
            .and_then(|a| a.parse::<f64>().ok())
            .unwrap_or(d)
            .to_radians()
    };
    let (yaw, pitch) = (angle(2, 20.0), angle(3, 10.0));
    let mesh = match flatmesh::io::load_path(std::path::Path::new(&args[0])) {
        Ok((m, _)) => m,
        Err(e) => {
            eprintln!("{}: {e}", args[0]);
            std::process::exit(2);
        }
    };
    let turn = |p: [f64; 3]| {
        let (x, z) = (
            p[0] * yaw.cos() + p[2] * yaw.sin(),
            -p[0] * yaw.sin() + p[2] * yaw.cos(),
        );
        let (y, z) = (
            p[1] * pitch.cos() - z * pitch.sin(),
            p[1] * pitch.sin() + z * pitch.cos(),
        );
        [x, y, z]
    };
    let pos: Vec<[f64; 3]> = mesh.positions().iter().map(|&p| turn(p)).collect();
    let turned = mesh
        .with_positions(pos.clone())
        .expect("a rotation keeps the mesh valid");
    let normals = geometry::face_normals(&turned);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &pos {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let scale = 800.0 / (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f64::MIN_POSITIVE);
    let at = |p: [f64; 3]| ((p[0] - lo[0]) * scale + 10.0, (hi[1] - p[1]) * scale + 10.0);
    let tris = turned.triangles();
    let mut order: Vec<usize> = (0..tris.len()).collect();
    let depth = |t: &[u32; 3]| t.iter().map(|&v| pos[v as usize][2]).sum::<f64>();
    order.sort_by(|&a, &b| depth(&tris[a]).total_cmp(&depth(&tris[b])));
    let light = geometry::normalize([0.3, 0.5, 1.0]);
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{:.0}\" height=\"{:.0}\">\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        (hi[0] - lo[0]) * scale + 20.0,
        (hi[1] - lo[1]) * scale + 20.0
    );
    for f in order {
        let n = normals[f];
        let g = (60.0 + 180.0 * (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).abs()) as u8;
        let mut points = String::new();
        for &v in &tris[f] {
            let (x, y) = at(pos[v as usize]);
            let _ = write!(points, "{x:.1},{y:.1} ");
        }
        let _ = writeln!(
            svg,
            "<polygon points=\"{points}\" fill=\"rgb({g},{g},{b})\" stroke=\"rgb({g},{g},{b})\" \
             stroke-width=\"0.3\"/>",
            b = g.saturating_add(15)
        );
    }
    let folds = geometry::fold_edges(&turned);
    for &e in &folds {
        let [a, b] = turned.conn().edges()[e as usize];
        let ((x1, y1), (x2, y2)) = (at(pos[a as usize]), at(pos[b as usize]));
        let _ = writeln!(
            svg,
            "<line x1=\"{x1:.1}\" y1=\"{y1:.1}\" x2=\"{x2:.1}\" y2=\"{y2:.1}\" stroke=\"red\" \
             stroke-width=\"2\"/>"
        );
    }
    svg.push_str("</svg>\n");
    if let Err(e) = std::fs::write(&args[1], svg) {
        eprintln!("{}: {e}", args[1]);
        std::process::exit(1);
    }
    println!("{} faces, {} folds drawn in red", tris.len(), folds.len());
}
