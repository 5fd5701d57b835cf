//! The regression corpus for the optimisers: procedural hard cases generated at several sizes
//! and noise levels, the real open meshes of `../shared/meshes` (listed by its MANIFEST.tsv),
//! and measures of a result taken from geometry alone (never from a solver's own figures).
//!
//! Tests and benchmarks share it so that both judge the same meshes the same way.

use crate::fixtures::{grid, SplitMix};
use crate::geometry;
use crate::mesh::{dot, sub, Mesh, RawMesh};
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// A procedural family: a smooth surface over a grid, with normal noise on interior vertices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// z = (x² − y²)/2 over [−1, 1]²: negative curvature everywhere (θ > 2π).
    Saddle,
    /// z = (2 − x² − y²)/2 over [−1, 1]²: positive curvature everywhere (θ < 2π).
    Dome,
    /// z = 0.15 sin(3πx) over [−1, 1]²: a developable corrugated sheet (pleats).
    Pleats,
    /// A cone sector, half-angle 30°, rulings 1 to 2.5 from the apex, angle 4π/3.
    Cone,
    /// A closed band (two boundary loops), radius 1 bulging to 1.1 at mid-height, height 2.
    Tube,
}

impl Family {
    /// Every family.
    pub const ALL: [Family; 5] = [
        Family::Saddle,
        Family::Dome,
        Family::Pleats,
        Family::Cone,
        Family::Tube,
    ];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Family::Saddle => "saddle",
            Family::Dome => "dome",
            Family::Pleats => "pleats",
            Family::Cone => "cone",
            Family::Tube => "tube",
        }
    }
}

/// One procedural case.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Procedural {
    /// Surface family.
    pub family: Family,
    /// About this many faces.
    pub faces: usize,
    /// Standard deviation of the normal noise, as a fraction of the mean edge length.
    pub noise: f64,
}

impl Procedural {
    /// `family-faces-noise`, e.g. `saddle-7700-0.05`.
    pub fn name(&self) -> String {
        format!("{}-{}-{}", self.family.name(), self.faces, self.noise)
    }

    /// The mesh (deterministic: the seed is derived from the parameters).
    pub fn mesh(&self) -> Mesh {
        let cells = (self.faces as f64 / 2.0).sqrt().round().max(2.0) as usize;
        let (nu, nv, wrap) = match self.family {
            Family::Tube => {
                // Cells about square on a tube of circumference 2π and height 2.
                let nv = ((cells * cells) as f64 / PI).sqrt().round().max(2.0) as usize;
                ((cells * cells / nv).max(3), nv, true)
            }
            Family::Cone => (cells * 3 / 2, cells * 2 / 3, false),
            _ => (cells, cells, false),
        };
        let f = |i: usize, j: usize| -> [f64; 3] {
            let (s, t) = (i as f64 / nu as f64, j as f64 / nv as f64);
            let (x, y) = (2.0 * s - 1.0, 2.0 * t - 1.0);
            match self.family {
                Family::Saddle => [x, y, 0.5 * (x * x - y * y)],
                Family::Dome => [x, y, 0.5 * (2.0 - x * x - y * y)],
                Family::Pleats => [x, y, 0.15 * (3.0 * PI * x).sin()],
                Family::Cone => {
                    let (alpha, phi, r) = (PI / 6.0, 4.0 / 3.0 * PI * s, 1.0 + 1.5 * t);
                    [
                        r * alpha.sin() * phi.cos(),
                        r * alpha.sin() * phi.sin(),
                        r * alpha.cos(),
                    ]
                }
                Family::Tube => {
                    let (phi, z) = (TAU * s, 2.0 * t);
                    let r = 1.0 + 0.1 * (PI * t).sin();
                    [r * phi.cos(), r * phi.sin(), z]
                }
            }
        };
        let mesh = grid_mesh(grid(nu, nv, wrap, f, |_, _| true), self.family.name());
        let seed = (self.faces as u64) << 20 ^ (self.noise * 1e6) as u64 ^ self.family as u64;
        with_normal_noise(&mesh, self.noise, seed)
    }
}

/// A pouch: the unit sphere with a hole, the inverse stereographic image of a `cells` ×
/// `cells` grid over [−3, 3]² (the square's image is a wavy loop 143°–153° from the south
/// pole), so the patch wraps past its equator and is no height field over any plane. Its
/// area is about 11 times the isoperimetric bound P²/4π of its opening, as the upper of a
/// shoe is (mh_shoes01: 10.9). Conformal, so its triangles keep their shapes while their
/// sizes vary tenfold. Not in [`procedural`]: a case for the cone start's harmonic layout.
pub fn pouch(cells: usize) -> Mesh {
    let cells = cells.max(2);
    let f = |i: usize, j: usize| -> [f64; 3] {
        let (x, y) = (
            6.0 * i as f64 / cells as f64 - 3.0,
            6.0 * j as f64 / cells as f64 - 3.0,
        );
        let r2 = x * x + y * y;
        [
            2.0 * x / (1.0 + r2),
            2.0 * y / (1.0 + r2),
            (r2 - 1.0) / (1.0 + r2),
        ]
    };
    grid_mesh(grid(cells, cells, false, f, |_, _| true), "pouch")
}

/// A generated grid as a mesh of one patch called `name`.
pub(crate) fn grid_mesh((positions, triangles, _): crate::fixtures::Grid, name: &str) -> Mesh {
    let n = triangles.len();
    let raw = RawMesh {
        positions,
        triangles,
        face_patch: vec![0; n],
        patch_names: vec![name.into()],
        uv: None,
    };
    Mesh::new(raw).expect("procedural mesh is valid").0
}

/// The procedural corpus: every family at three sizes (saddles and domes from 2k to 45k faces)
/// and two noise levels.
pub fn procedural() -> Vec<Procedural> {
    let mut out = Vec::new();
    for family in Family::ALL {
        let sizes: &[usize] = match family {
            Family::Saddle | Family::Dome => &[2_000, 7_700, 45_000],
            _ => &[2_000, 7_700],
        };
        for &faces in sizes {
            for noise in [0.01, 0.1] {
                out.push(Procedural {
                    family,
                    faces,
                    noise,
                });
            }
        }
    }
    out
}

/// Move every interior vertex along its normal by a normal random amount of standard deviation
/// `sigma` mean edge lengths (fixed seed); other vertices stay bit-identical.
pub fn with_normal_noise(mesh: &Mesh, sigma: f64, seed: u64) -> Mesh {
    let h = geometry::mean_edge_length(mesh);
    let normals = geometry::vertex_normals(mesh);
    let mut rng = SplitMix(seed);
    let mut pos = mesh.positions().to_vec();
    for v in mesh.conn().interior_vertices() {
        let d = sigma * h * rng.normal();
        for c in 0..3 {
            pos[v as usize][c] += d * normals[v as usize][c];
        }
    }
    mesh.with_positions(pos)
        .expect("noise keeps the mesh valid")
}

/// An almost flattenable version of `mesh`: `count` smooth bumps, each a Gaussian of height
/// `amplitude` and radius `radius` (both in mean edge lengths) centred on an interior vertex
/// picked with `seed`, moving every interior vertex near it along the centre's normal (one
/// direction per bump, so that the bump stays smooth across creases and slivers, where
/// per-vertex normals are not); other vertices stay bit-identical. The input the `perturb`
/// job is made for (a garment that is flattenable but for a few spots).
pub fn with_bumps(mesh: &Mesh, count: usize, amplitude: f64, radius: f64, seed: u64) -> Mesh {
    let h = geometry::mean_edge_length(mesh);
    let normals = geometry::vertex_normals(mesh);
    let interior: Vec<u32> = mesh.conn().interior_vertices().collect();
    if interior.is_empty() {
        return mesh.clone();
    }
    let mut rng = SplitMix(seed);
    let centres: Vec<([f64; 3], [f64; 3])> = (0..count)
        .map(|_| {
            let k = ((rng.unit() * interior.len() as f64) as usize).min(interior.len() - 1);
            let v = interior[k];
            (mesh.position(v), normals[v as usize])
        })
        .collect();
    let mut pos = mesh.positions().to_vec();
    let r2 = (radius * h).powi(2);
    for &v in &interior {
        let p = mesh.position(v);
        for (c, n) in &centres {
            let lift = amplitude * h * (-dot(sub(p, *c), sub(p, *c)) / r2).exp();
            for k in 0..3 {
                pos[v as usize][k] += lift * n[k];
            }
        }
    }
    mesh.with_positions(pos).unwrap_or_else(|_| mesh.clone())
}

/// fl-mesh's output for the case `name` with default parameters and whether it converged,
/// cached in `dir` as NAME.fl.obj and NAME.fl.txt (`converged` or `stalled`) so that corpus
/// runs that start from it need not repeat it; None when fl-mesh refuses the mesh.
pub fn fl_meshed_cached(name: &str, mesh: &Mesh, dir: &Path) -> Option<(Mesh, bool)> {
    use crate::algorithms::{fl_mesh, Silent};
    let (obj, txt) = (
        dir.join(format!("{name}.fl.obj")),
        dir.join(format!("{name}.fl.txt")),
    );
    if let (Ok((m, _)), Ok(t)) = (crate::io::load_path(&obj), std::fs::read_to_string(&txt)) {
        return Some((m, t.trim() == "converged"));
    }
    let params = fl_mesh::Params::default();
    let (m, _) = fl_mesh::solve(mesh, &params, &Silent::default()).ok()?;
    let conv = max_flattenability(&m) <= params.tolerance;
    let _ = std::fs::create_dir_all(dir);
    let _ = std::fs::write(&obj, crate::io::obj::write(&m.to_raw()));
    let _ = std::fs::write(&txt, if conv { "converged" } else { "stalled" });
    Some((m, conv))
}

/// The regular octahedron (closed, χ = 2, every vertex's defect 2π − 4π/3): the smallest
/// mesh Gauss–Bonnet forbids to be flattenable (tests).
pub fn octahedron() -> Mesh {
    let positions = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let triangles = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    procedural_mesh(positions, triangles)
}

/// `perturb`'s procedural pair, a garment and the body it is worn on (tests and benchmarks).
/// A closed capsule-like body: a cylinder of radius `r` along z over [0, len], capped by fans.
pub fn arm(r: f64, len: f64, around: usize, along: usize) -> Mesh {
    let mut p = Vec::new();
    for j in 0..=along {
        for i in 0..around {
            let a = i as f64 / around as f64 * std::f64::consts::TAU;
            p.push([r * a.cos(), r * a.sin(), len * j as f64 / along as f64]);
        }
    }
    let bottom = p.len() as u32;
    p.push([0.0, 0.0, -r]);
    let top = p.len() as u32;
    p.push([0.0, 0.0, len + r]);
    let mut t = band_triangles(around, along);
    let id = |i: usize, j: usize| (j * around + i % around) as u32;
    for i in 0..around {
        t.push([bottom, id(i + 1, 0), id(i, 0)]);
        t.push([top, id(i, along), id(i + 1, along)]);
    }
    procedural_mesh(p, t)
}

/// An open sleeve of radius `r` along z over [0.1, len−0.1], with dents pushed inwards.
pub fn sleeve(r: f64, len: f64, around: usize, along: usize, dent: f64) -> Mesh {
    let mut p = Vec::new();
    for j in 0..=along {
        for i in 0..around {
            let a = i as f64 / around as f64 * std::f64::consts::TAU;
            let z = 0.1 + (len - 0.2) * j as f64 / along as f64;
            let dz = ((z - len / 2.0) * 6.0).powi(2);
            let da = (a - 1.0).powi(2) * 4.0;
            let rr = r - dent * (-(dz + da)).exp();
            p.push([rr * a.cos(), rr * a.sin(), z]);
        }
    }
    procedural_mesh(p, band_triangles(around, along))
}

/// The triangles of a band of `along` rows of `around` quads each, closed around (vertex
/// i + j·around is the i-th of ring j).
fn band_triangles(around: usize, along: usize) -> Vec<[u32; 3]> {
    let mut t = Vec::new();
    let id = |i: usize, j: usize| (j * around + i % around) as u32;
    for j in 0..along {
        for i in 0..around {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    t
}

fn procedural_mesh(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
    let raw = crate::fixtures::single_patch("default", positions, triangles);
    Mesh::new(raw).expect("a procedural mesh is valid").0
}

/// A body that follows a garment: `mesh` moved by `distance` against its vertex normals,
/// same triangles (so its outside, the side its normals point to, is the garment's side).
/// For `perturb` on a real garment where no body of its own fits it (an open body: the
/// solver queries every moved vertex).
pub fn body_under(mesh: &Mesh, distance: f64) -> Mesh {
    let normals = geometry::vertex_normals(mesh);
    let pos = mesh
        .positions()
        .iter()
        .zip(&normals)
        .map(|(p, n)| [0, 1, 2].map(|k| p[k] - distance * n[k]))
        .collect();
    mesh.with_positions(pos).unwrap_or_else(|_| mesh.clone())
}

/// Signed distance from `p` to the open surface `body` by brute force: the closest point over
/// every triangle, signed by the side of that triangle's plane (positive on its normal's
/// side). Independent of the pseudo-normals `perturb` uses; exact where the closest point is
/// inside a face, which is where a garment lies over a body that follows it.
pub fn brute_signed_distance_open(body: &Mesh, p: [f64; 3]) -> f64 {
    let mut best = (f64::INFINITY, 1.0);
    for t in body.triangles() {
        let [a, b, c] = t.map(|v| body.position(v));
        let q = crate::spatial::closest_point_on_triangle(p, a, b, c);
        let d = dot(sub(p, q), sub(p, q)).sqrt();
        if d < best.0 {
            let n = crate::mesh::cross(sub(b, a), sub(c, a));
            best = (d, if dot(sub(p, q), n) < 0.0 { -1.0 } else { 1.0 });
        }
    }
    best.0 * best.1
}

/// Signed distance from `p` to the closed surface `body` by brute force: the closest point over
/// every triangle, the sign from the winding number (Van Oosterom–Strackee solid angles),
/// negative inside. Independent of the pseudo-normals `perturb` uses; O(triangles) per query.
pub fn brute_signed_distance(body: &Mesh, p: [f64; 3]) -> f64 {
    let mut best = f64::INFINITY;
    let mut solid = 0.0;
    let norm = |v: [f64; 3]| dot(v, v).sqrt();
    for t in body.triangles() {
        let [a, b, c] = t.map(|v| body.position(v));
        let q = crate::spatial::closest_point_on_triangle(p, a, b, c);
        best = best.min(norm(sub(q, p)));
        let (ra, rb, rc) = (sub(a, p), sub(b, p), sub(c, p));
        let num = dot(ra, crate::mesh::cross(rb, rc));
        let (la, lb, lc) = (norm(ra), norm(rb), norm(rc));
        let den = la * lb * lc + dot(ra, rb) * lc + dot(ra, rc) * lb + dot(rb, rc) * la;
        solid += 2.0 * num.atan2(den);
    }
    if solid / (4.0 * PI) > 0.5 {
        -best
    } else {
        best
    }
}

/// Where the shared meshes live, relative to the crate root.
pub const SHARED_MESHES: &str = "../shared/meshes";

/// `../shared/meshes` beside the crate, for tests: None when it is absent (a user's fresh
/// clone), after a SKIPPED line naming `what` written straight to the process's stderr (the
/// test harness captures `println!`/`eprintln!` of passing tests, so a skip said that way was
/// never seen); a panic when it is absent although `CI=true`, since CI always has it.
pub fn shared_root_for_tests(what: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(SHARED_MESHES);
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{} is missing although CI=true: CI always has it",
        dir.display()
    );
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED ({what}): {} is absent, so these real-mesh checks did not run",
        dir.display()
    );
    None
}

/// One shared mesh's path, `rel` under `../shared/meshes` (see [`shared_root_for_tests`]).
pub fn shared_mesh_for_tests(rel: &str) -> Option<PathBuf> {
    shared_root_for_tests(rel).map(|root| root.join(rel))
}

/// The open-surface meshes listed in `root/MANIFEST.tsv` (column `surface` starting with
/// "open"), as paths; `None` when the manifest is missing.
pub fn shared_open_meshes(root: &Path) -> Option<Vec<PathBuf>> {
    shared_meshes_where(root, |surface| surface.starts_with("open"))
}

/// The closed meshes listed in `root/MANIFEST.tsv`.
pub fn shared_closed_meshes(root: &Path) -> Option<Vec<PathBuf>> {
    shared_meshes_where(root, |surface| surface.starts_with("closed"))
}

fn shared_meshes_where(root: &Path, keep: impl Fn(&str) -> bool) -> Option<Vec<PathBuf>> {
    let text = std::fs::read_to_string(root.join("MANIFEST.tsv")).ok()?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next()?.split('\t').collect();
    let file = header.iter().position(|h| *h == "file")?;
    let surface = header.iter().position(|h| *h == "surface")?;
    Some(
        lines
            .map(|l| l.split('\t').collect::<Vec<_>>())
            .filter(|c| c.len() > file.max(surface) && keep(c[surface]))
            .map(|c| root.join(c[file]))
            .collect(),
    )
}

/// Shape and flattenability figures of a result, measured from the geometry of the input and
/// the output only.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Measures {
    /// ϖ_max of the input.
    pub varpi_in: f64,
    /// ϖ_max of the output.
    pub varpi_out: f64,
    /// Folds (adjacent normals turning by more than 120°) in the input.
    pub folds_in: usize,
    /// Folds in the output.
    pub folds_out: usize,
    /// Creases (adjacent normals turning by more than 60°) in the input.
    pub creases_in: usize,
    /// Creases in the output: folds count only the near-fold-overs; this shows how crumpled
    /// the surface got short of that.
    pub creases_out: usize,
    /// Smallest corner angle of the input, radians.
    pub min_angle_in: f64,
    /// Smallest corner angle of the output, radians.
    pub min_angle_out: f64,
    /// Two-sided vertex-to-surface distance between output and input over the input's
    /// bounding-box diagonal.
    pub hausdorff_relative: f64,
    /// Largest move of an input vertex over the diagonal.
    pub max_move_relative: f64,
}

/// ϖ_max measured by `geometry`.
pub use geometry::max_flattenability;

/// Measure `output` against `input` (output keeps input vertex i as vertex i).
pub fn measure(input: &Mesh, output: &Mesh) -> Measures {
    let (lo, hi) = input.bbox();
    let d = sub(hi, lo);
    let diag = dot(d, d).sqrt().max(f64::MIN_POSITIVE);
    let hd = crate::spatial::vertex_surface_hausdorff(
        output.positions(),
        output.triangles(),
        input.positions(),
        input.triangles(),
    );
    let moved = input
        .positions()
        .iter()
        .zip(output.positions())
        .map(|(a, b)| dot(sub(*a, *b), sub(*a, *b)).sqrt())
        .fold(0.0, f64::max);
    Measures {
        varpi_in: max_flattenability(input),
        varpi_out: max_flattenability(output),
        folds_in: geometry::fold_edges(input).len(),
        folds_out: geometry::fold_edges(output).len(),
        creases_in: geometry::crease_count(input),
        creases_out: geometry::crease_count(output),
        min_angle_in: geometry::smallest_corner(input),
        min_angle_out: geometry::smallest_corner(output),
        hausdorff_relative: hd / diag,
        max_move_relative: moved / diag,
    }
}

/// A case of the corpus: its name and how to make its mesh.
pub struct Case {
    /// File stem of a shared mesh, `fixture-NAME`, or a procedural name.
    pub name: String,
    load: Box<dyn Fn() -> Result<Mesh, String>>,
}

impl Case {
    /// The mesh, or why the reader refused it.
    pub fn mesh(&self) -> Result<Mesh, String> {
        (self.load)()
    }
}

/// Every case: with `shared`, the open then the closed meshes of `root` (when its manifest is
/// there), then the fixtures, then [`procedural`].
pub fn cases(root: &Path, shared: bool) -> Vec<Case> {
    let mut out = Vec::new();
    if shared {
        let open = shared_open_meshes(root).unwrap_or_default();
        let closed = shared_closed_meshes(root).unwrap_or_default();
        for p in open.into_iter().chain(closed) {
            out.push(Case {
                name: p.file_stem().unwrap_or_default().to_string_lossy().into(),
                load: Box::new(move || {
                    crate::io::load_path(&p)
                        .map(|(m, _)| m)
                        .map_err(|e| format!("{}: {e}", p.display()))
                }),
            });
        }
    }
    for f in crate::fixtures::all() {
        out.push(Case {
            name: format!("fixture-{}", f.name),
            load: Box::new(move || {
                Mesh::new(f.mesh.clone())
                    .map(|m| m.0)
                    .map_err(|e| e.to_string())
            }),
        });
    }
    for p in procedural() {
        out.push(Case {
            name: p.name(),
            load: Box::new(move || Ok(p.mesh())),
        });
    }
    out
}

/// One fl-mesh run on one case: the solver's iteration count and stop reason, and everything
/// else measured from the geometry.
#[derive(Debug, Clone)]
pub struct Row {
    /// Case name.
    pub name: String,
    /// Faces of the input.
    pub faces: usize,
    /// Iterations taken.
    pub iterations: usize,
    /// Measured ϖ_max(out) ≤ tolerance.
    pub converged: bool,
    /// The solver's stop reason.
    pub stop_reason: String,
    /// Geometry-only figures.
    pub measures: Measures,
    /// Wall-clock seconds of the run.
    pub seconds: f64,
}

/// Run fl-mesh on `mesh` as the job does ([`fl_mesh::run`]: on the patches `params.patches`
/// chooses, and back to the file's when those stall) and measure the result against the mesh
/// with the patches it solved, so that ϖ in and out are over the same patches.
///
/// [`fl_mesh::run`]: crate::algorithms::fl_mesh::run
pub fn run_fl_mesh(
    name: &str,
    mesh: &Mesh,
    params: &crate::algorithms::fl_mesh::Params,
) -> Result<Row, crate::algorithms::AlgoError> {
    use crate::algorithms::fl_mesh;
    let t = std::time::Instant::now();
    let done = fl_mesh::run(mesh, params, &crate::algorithms::Silent::default())?;
    let seconds = t.elapsed().as_secs_f64();
    let summary = done.summary;
    let out = done.mesh.unwrap_or_else(|| mesh.clone());
    let (solved, stop_reason) = match summary.patches.source.as_str() {
        "uv" => (
            fl_mesh::choose_patches(mesh, fl_mesh::Patches::Uv)?.0,
            format!(
                "{} texture islands; {}",
                summary.patches.count, summary.report.stop_reason
            ),
        ),
        _ => (mesh.clone(), summary.report.stop_reason),
    };
    let measures = measure(&solved, &out);
    Ok(Row {
        name: name.into(),
        faces: mesh.num_faces(),
        iterations: summary.report.iterations,
        converged: measures.varpi_out <= params.tolerance,
        stop_reason,
        measures,
        seconds,
    })
}

impl Row {
    /// Column titles for [`Row`]'s `Display`.
    pub fn header() -> String {
        format!(
            "{:<28} {:>6} {:>4} {:>9} {:>9} {:>5} {:>5} {:>5} {:>5} {:>6} {:>6} {:>7} {:>7} {:>6}  stop",
            "mesh",
            "faces",
            "its",
            "ϖ in",
            "ϖ out",
            "f.in",
            "f.out",
            "c.in",
            "c.out",
            "∠in°",
            "∠out°",
            "hd%",
            "move%",
            "s"
        )
    }
}

impl std::fmt::Display for Row {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = &self.measures;
        write!(
            f,
            "{:<28} {:>6} {:>4} {:>9.2e} {:>9.2e} {:>5} {:>5} {:>5} {:>5} {:>6.2} {:>6.2} {:>7.3} {:>7.3} {:>6.2}  {}{}",
            self.name,
            self.faces,
            self.iterations,
            x.varpi_in,
            x.varpi_out,
            x.folds_in,
            x.folds_out,
            x.creases_in,
            x.creases_out,
            x.min_angle_in.to_degrees(),
            x.min_angle_out.to_degrees(),
            100.0 * x.hausdorff_relative,
            100.0 * x.max_move_relative,
            self.seconds,
            self.stop_reason,
            if self.converged { "" } else { " [NOT CONVERGED]" }
        )
    }
}

/// Run fl-mesh on every case (of [`cases`]) whose name contains `filter` and print the table:
/// [`Row::header`], one row per case (or why the reader refused it), then the count that
/// converged.
pub fn print_table(
    root: &Path,
    shared: bool,
    filter: &str,
    params: &crate::algorithms::fl_mesh::Params,
) {
    println!("{}", Row::header());
    let (mut total, mut conv) = (0, 0);
    for case in cases(root, shared) {
        if !case.name.contains(filter) {
            continue;
        }
        let mesh = match case.mesh() {
            Ok(m) => m,
            Err(e) => {
                println!("{:<28} refused by the reader: {e}", case.name);
                continue;
            }
        };
        match run_fl_mesh(&case.name, &mesh, params) {
            Ok(row) => {
                total += 1;
                conv += usize::from(row.converged);
                println!("{row}");
            }
            Err(e) => println!("{:<28} error: {e}", case.name),
        }
    }
    println!("{conv} of {total} reached ϖ_max ≤ {:e}", params.tolerance);
}

/// What the corpus examples take: `[FILTER] [--set KEY=VALUE ...] [--no-shared]`.
pub struct ExampleArgs {
    /// Keep the cases whose name contains it.
    pub filter: String,
    /// The job's parameters as JSON values (a VALUE that is not JSON is a string).
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Whether the meshes of `../shared/meshes` are in.
    pub shared: bool,
}

impl ExampleArgs {
    /// From the program's arguments (without the program's name).
    pub fn parse(mut args: impl Iterator<Item = String>) -> Result<Self, String> {
        let mut out = Self {
            filter: String::new(),
            params: serde_json::Map::new(),
            shared: true,
        };
        while let Some(a) = args.next() {
            if a == "--set" {
                let kv = args.next().ok_or("--set needs KEY=VALUE")?;
                let (k, v) = kv
                    .split_once('=')
                    .ok_or_else(|| format!("--set {kv}: not KEY=VALUE"))?;
                let v = serde_json::from_str(v).unwrap_or(serde_json::Value::String(v.into()));
                out.params.insert(k.into(), v);
            } else if a == "--no-shared" {
                out.shared = false;
            } else {
                out.filter = a;
            }
        }
        Ok(out)
    }
}

/// Figures of a flat pattern recomputed from its 2D and 3D positions alone, for tests,
/// examples and benchmarks to judge patterns without the flatten module's own measures.
pub mod pattern_checks {
    use crate::mesh::Mesh;
    use crate::pattern::Piece;

    fn d2(a: [f64; 2], b: [f64; 2]) -> f64 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
    }

    fn d3(a: [f64; 3], b: [f64; 3]) -> f64 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }

    /// Signed 2D area of triangle `t` of a piece.
    pub fn signed_area(p: &Piece, t: [u32; 3]) -> f64 {
        let [a, b, c] = t.map(|v| p.uv[v as usize]);
        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    }

    /// 3D area of triangle `t` of a piece.
    pub fn area_3d(mesh: &Mesh, p: &Piece, t: [u32; 3]) -> f64 {
        let [a, b, c] = t.map(|v| mesh.position(p.vertex_ids[v as usize]));
        crate::geometry::triangle_area(a, b, c)
    }

    /// Triangles with signed 2D area ≤ 0.
    pub fn flipped(p: &Piece) -> usize {
        p.triangles
            .iter()
            .filter(|&&t| signed_area(p, t) <= 0.0)
            .count()
    }

    fn worst_edge(mesh: &Mesh, p: &Piece, edges: impl Iterator<Item = (u32, u32)>) -> f64 {
        let mut worst: f64 = 0.0;
        for (a, b) in edges {
            let l3 = d3(
                mesh.position(p.vertex_ids[a as usize]),
                mesh.position(p.vertex_ids[b as usize]),
            );
            if l3 > 0.0 {
                worst = worst.max((d2(p.uv[a as usize], p.uv[b as usize]) - l3).abs() / l3);
            }
        }
        worst
    }

    /// Largest relative difference between a triangle edge in 2D and in 3D: 0 for an
    /// isometry, and a bound on the stretch of every triangle's edges.
    pub fn edge_length_error(mesh: &Mesh, p: &Piece) -> f64 {
        let edges = p
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]);
        worst_edge(mesh, p, edges)
    }

    /// Largest relative difference of a boundary edge, 2D against 3D.
    pub fn boundary_length_error(mesh: &Mesh, p: &Piece) -> f64 {
        let edges = p
            .boundary_loops
            .iter()
            .flat_map(|lp| (0..lp.len()).map(move |k| (lp[k], lp[(k + 1) % lp.len()])));
        worst_edge(mesh, p, edges)
    }

    /// Pairs of boundary segments sharing no vertex that cross or touch, by brute force.
    /// Orientations within 1e-12 of the squared segment length count as collinear, so two
    /// pieces of one straight side (a rectangle's) do not count, but a slit whose two sides
    /// lie on each other does.
    pub fn boundary_crossings(p: &Piece) -> usize {
        let segs: Vec<(u32, u32)> = p
            .boundary_loops
            .iter()
            .flat_map(|lp| (0..lp.len()).map(move |k| (lp[k], lp[(k + 1) % lp.len()])))
            .collect();
        let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
            let o = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            let scale = (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2);
            if o.abs() <= 1e-12 * scale {
                0.0
            } else {
                o.signum()
            }
        };
        // c on segment ab, given collinear
        let on = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
            (c[0] - a[0]) * (c[0] - b[0]) + (c[1] - a[1]) * (c[1] - b[1]) <= 0.0
        };
        let mut n = 0;
        for i in 0..segs.len() {
            for j in i + 1..segs.len() {
                let (s, t) = (segs[i], segs[j]);
                if s.0 == t.0 || s.0 == t.1 || s.1 == t.0 || s.1 == t.1 {
                    continue;
                }
                let [a, b, c, d] = [s.0, s.1, t.0, t.1].map(|v| p.uv[v as usize]);
                let (o1, o2) = (orient(a, b, c), orient(a, b, d));
                let (o3, o4) = (orient(c, d, a), orient(c, d, b));
                let hit = (o1 * o2 < 0.0 && o3 * o4 < 0.0)
                    || (o1 == 0.0 && on(a, b, c))
                    || (o2 == 0.0 && on(a, b, d))
                    || (o3 == 0.0 && on(c, d, a))
                    || (o4 == 0.0 && on(c, d, b));
                n += hit as usize;
            }
        }
        n
    }

    /// Area-weighted mean |ln(A2D/A3D)| over the triangles of `pieces`, and the range of
    /// A2D/A3D.
    pub fn area_distortion(mesh: &Mesh, pieces: &[Piece]) -> (f64, f64, f64) {
        let (mut sum, mut wsum, mut lo, mut hi) = (0.0, 0.0, f64::MAX, f64::MIN);
        for p in pieces {
            for &t in &p.triangles {
                let a3 = area_3d(mesh, p, t);
                if a3 <= 0.0 {
                    continue;
                }
                let r = signed_area(p, t) / a3;
                sum += a3 * r.abs().ln().abs();
                wsum += a3;
                lo = lo.min(r);
                hi = hi.max(r);
            }
        }
        (sum / wsum.max(f64::MIN_POSITIVE), lo, hi)
    }
}
