//! Procedural meshes with known answers, for tests, benchmarks and first runs.
//!
//! `flatmesh fixtures DIR` writes them as OBJ; the committed copies in `fixtures/` are checked
//! byte for byte against this generator (tests/engine/fixtures.rs), so a change here shows up as a
//! diff to review rather than silently changing what other tests measure.
//!
//! The developable ones are built so that developability holds exactly, not approximately:
//! cylinder and cone patches are grids whose rows lie on rulings, so every quad cell is planar
//! and every interior vertex sits on a straight ruling with planar strips on both sides
//! (angle sum π + π). Noise comes from a fixed-seed splitmix64, so output never changes.

use crate::mesh::RawMesh;
use std::collections::HashMap;
use std::f64::consts::{PI, TAU};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One procedural mesh and what is known about it.
#[derive(Debug, Clone)]
pub struct Fixture {
    /// File stem, e.g. `hemisphere_cap`.
    pub name: &'static str,
    /// One line on how it is built and what to expect.
    pub description: &'static str,
    /// The mesh itself.
    pub mesh: RawMesh,
    /// Whether every interior vertex has angle sum exactly 2π (up to rounding).
    pub developable: bool,
    /// Euler characteristic V − E + F of the whole mesh.
    pub euler: i64,
    /// Number of boundary loops of the whole mesh (seams between patches not counted).
    pub boundary_loops: usize,
}

impl Fixture {
    /// The OBJ text committed as `fixtures/<name>.obj`.
    pub fn obj(&self) -> String {
        format!(
            "# flatmesh fixture {}: {}\n{}",
            self.name,
            self.description,
            crate::io::obj::write(&self.mesh)
        )
    }
}

/// Every fixture, in a fixed order.
pub fn all() -> Vec<Fixture> {
    vec![
        flat_disk(),
        cylinder(),
        cone(),
        cylinder_noisy(),
        cone_noisy(),
        hemisphere_cap(),
        saddle(),
        cube_cuts(),
        two_holes(),
        tube_two_panels(),
    ]
}

/// The fixture called `name`, if there is one.
pub fn by_name(name: &str) -> Option<Fixture> {
    all().into_iter().find(|f| f.name == name)
}

/// The README written beside the fixtures: what each one is and its known answers.
pub fn readme() -> String {
    let mut s = String::from(
        "# Fixtures\n\n\
         Procedural meshes with known answers, written by `flatmesh fixtures fixtures` from\n\
         `src/fixtures.rs`. Do not edit by hand: tests/engine/fixtures.rs checks that these files are\n\
         exactly what the generator writes. Lengths are in the mesh's own units.\n\n\
         | name | vertices | faces | patches | χ | boundary loops | developable | what it is |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for f in all() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            f.name,
            f.mesh.positions.len(),
            f.mesh.triangles.len(),
            f.mesh.patch_names.join(", "),
            f.euler,
            f.boundary_loops,
            if f.developable { "yes" } else { "no" },
            f.description
        );
    }
    s
}

/// Write every fixture as `<name>.obj` into `dir` (created if missing), plus `README.md`.
pub fn write_all(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for f in all() {
        let path = dir.join(format!("{}.obj", f.name));
        std::fs::write(&path, f.obj())?;
        written.push(path);
    }
    let path = dir.join("README.md");
    std::fs::write(&path, readme())?;
    written.push(path);
    Ok(written)
}

/// One patch named `name` of the given triangles.
pub(crate) fn single_patch(
    name: &str,
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
) -> RawMesh {
    let n = triangles.len();
    RawMesh {
        positions,
        triangles,
        face_patch: vec![0; n],
        patch_names: vec![name.to_string()],
        uv: None,
    }
}

/// Positions, triangles, and the grid cell (i, j) of each triangle.
pub(crate) type Grid = (Vec<[f64; 3]>, Vec<[u32; 3]>, Vec<(usize, usize)>);

/// A grid of (nu + 1) × (nv + 1) vertices through `f(i, j)` with two triangles per cell,
/// counter-clockwise when ∂f/∂i × ∂f/∂j points to the front. Diagonals alternate like a
/// checkerboard so that valences vary. With `wrap_u` column nu is column 0 (a closed band).
/// Cells with `keep(i, j) == false` are left out and vertices no cell uses are dropped.
pub(crate) fn grid(
    nu: usize,
    nv: usize,
    wrap_u: bool,
    f: impl Fn(usize, usize) -> [f64; 3],
    keep: impl Fn(usize, usize) -> bool,
) -> Grid {
    let cols = if wrap_u { nu } else { nu + 1 };
    let id = |i: usize, j: usize| j * cols + if wrap_u { i % nu } else { i };
    let mut tris = Vec::new();
    let mut cells = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            if !keep(i, j) {
                continue;
            }
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            } else {
                tris.push([a, b, d]);
                tris.push([b, c, d]);
            }
            cells.push((i, j));
            cells.push((i, j));
        }
    }
    // Number the used vertices in grid order so indices do not depend on the cell order.
    let mut new_id = vec![u32::MAX; cols * (nv + 1)];
    for t in &tris {
        for &v in t {
            new_id[v] = 0;
        }
    }
    let mut positions = Vec::new();
    for j in 0..=nv {
        for i in 0..cols {
            let v = id(i, j);
            if new_id[v] == 0 {
                new_id[v] = positions.len() as u32;
                positions.push(f(i, j));
            }
        }
    }
    let triangles = tris
        .iter()
        .map(|t| [new_id[t[0]], new_id[t[1]], new_id[t[2]]])
        .collect();
    (positions, triangles, cells)
}

/// A disk of `rings` concentric rings around a centre vertex, ring k holding 6k vertices, all
/// through `f(k, t)` with t ∈ [0, 1) the turn along the ring. Counter-clockwise when t turns
/// counter-clockwise seen from the front.
fn ring_disk(rings: usize, f: impl Fn(usize, f64) -> [f64; 3]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut positions = vec![f(0, 0.0)];
    let mut start = vec![0usize];
    for k in 1..=rings {
        start.push(positions.len());
        for j in 0..6 * k {
            positions.push(f(k, j as f64 / (6 * k) as f64));
        }
    }
    let mut triangles = Vec::new();
    for k in 1..=rings {
        let (m, n) = (if k == 1 { 1 } else { 6 * (k - 1) }, 6 * k);
        let a = |i: usize| (start[k - 1] + i % m) as u32;
        let b = |j: usize| (start[k] + j % n) as u32;
        let (mut i, mut j) = (0, 0);
        if k == 1 {
            // fan around the centre
            for j in 0..n {
                triangles.push([a(0), b(j), b(j + 1)]);
            }
            continue;
        }
        // Zip the two rings by angle; (j + 1) / n ≤ (i + 1) / m compared exactly.
        while i < m || j < n {
            if j < n && (i == m || (j + 1) * m <= (i + 1) * n) {
                triangles.push([a(i), b(j), b(j + 1)]);
                j += 1;
            } else {
                triangles.push([a(i), b(j), a(i + 1)]);
                i += 1;
            }
        }
    }
    (positions, triangles)
}

/// splitmix64: tiny, fixed, reproducible on every platform.
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in (0, 1].
    pub(crate) fn unit(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub(crate) fn normal(&mut self) -> f64 {
        let (u, v) = (self.unit(), self.unit());
        (-2.0 * u.ln()).sqrt() * (TAU * v).cos()
    }
}

/// Move every vertex not on the boundary by a normal random vector of standard deviation
/// `sigma` per coordinate; boundary vertices stay exactly where they are.
fn add_noise(mesh: &mut RawMesh, sigma: f64, seed: u64) {
    let mut count: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let mut on_boundary = vec![false; mesh.positions.len()];
    for (&(a, b), &c) in &count {
        if c == 1 {
            on_boundary[a as usize] = true;
            on_boundary[b as usize] = true;
        }
    }
    let mut rng = SplitMix(seed);
    for (p, &fixed) in mesh.positions.iter_mut().zip(&on_boundary) {
        let d = [rng.normal(), rng.normal(), rng.normal()];
        if !fixed {
            for k in 0..3 {
                p[k] += sigma * d[k];
            }
        }
    }
}

const DISK_RINGS: usize = 6;

fn flat_disk() -> Fixture {
    let (p, t) = ring_disk(DISK_RINGS, |k, s| {
        let r = k as f64 / DISK_RINGS as f64;
        [r * (TAU * s).cos(), r * (TAU * s).sin(), 0.0]
    });
    Fixture {
        name: "flat_disk",
        description: "unit disk in the plane z = 0, 6 rings; every interior vertex has θ = 2π",
        mesh: single_patch("disk", p, t),
        developable: true,
        euler: 1,
        boundary_loops: 1,
    }
}

/// Cylinder patch: radius 1, angle [0, 3π/2], height 2; rulings along z.
fn cylinder_mesh() -> RawMesh {
    let (nu, nv) = (24, 8);
    let (p, t, _) = grid(
        nu,
        nv,
        false,
        |i, j| {
            let phi = 1.5 * PI * i as f64 / nu as f64;
            [phi.cos(), phi.sin(), 2.0 * j as f64 / nv as f64]
        },
        |_, _| true,
    );
    single_patch("cylinder", p, t)
}

/// Cone patch: apex at the origin, half-angle 30°, rulings from distance 1 to 2.5, angle
/// [0, 4π/3]. The apex itself is not part of it (it is a cone point with θ = 2π sin 30°).
fn cone_mesh() -> RawMesh {
    let (nu, nv) = (24, 8);
    let alpha = PI / 6.0;
    let (p, t, _) = grid(
        nu,
        nv,
        false,
        |i, j| {
            let phi = 4.0 / 3.0 * PI * i as f64 / nu as f64;
            let s = 1.0 + 1.5 * j as f64 / nv as f64;
            [
                s * alpha.sin() * phi.cos(),
                s * alpha.sin() * phi.sin(),
                s * alpha.cos(),
            ]
        },
        |_, _| true,
    );
    single_patch("cone", p, t)
}

fn cylinder() -> Fixture {
    Fixture {
        name: "cylinder",
        description: "cylinder patch, radius 1, angle 3π/2, height 2, grid on the rulings: \
                      exactly developable, unrolls to a 3π/2 × 2 rectangle",
        mesh: cylinder_mesh(),
        developable: true,
        euler: 1,
        boundary_loops: 1,
    }
}

fn cone() -> Fixture {
    Fixture {
        name: "cone",
        description: "truncated cone patch, half-angle 30°, rulings 1 to 2.5 from the apex, \
                      angle 4π/3: exactly developable, unrolls to an annulus sector of angle 2π/3",
        mesh: cone_mesh(),
        developable: true,
        euler: 1,
        boundary_loops: 1,
    }
}

fn cylinder_noisy() -> Fixture {
    let mut mesh = cylinder_mesh();
    // edges are about 0.2 long; σ = 1% of that
    add_noise(&mut mesh, 0.002, 0x5eed_0001);
    Fixture {
        name: "cylinder_noisy",
        description: "the cylinder patch with normal noise (σ = 0.002, 1% of an edge) on its \
                      interior vertices; boundary unchanged",
        mesh,
        developable: false,
        euler: 1,
        boundary_loops: 1,
    }
}

fn cone_noisy() -> Fixture {
    let mut mesh = cone_mesh();
    add_noise(&mut mesh, 0.002, 0x5eed_0002);
    Fixture {
        name: "cone_noisy",
        description: "the cone patch with normal noise (σ = 0.002, about 1% of an edge) on its \
                      interior vertices; boundary unchanged",
        mesh,
        developable: false,
        euler: 1,
        boundary_loops: 1,
    }
}

fn hemisphere_cap() -> Fixture {
    let rings = 8;
    let (p, t) = ring_disk(rings, |k, s| {
        let psi = 0.5 * PI * k as f64 / rings as f64;
        [
            psi.sin() * (TAU * s).cos(),
            psi.sin() * (TAU * s).sin(),
            psi.cos(),
        ]
    });
    Fixture {
        name: "hemisphere_cap",
        description: "upper unit hemisphere, 8 rings, vertices on the sphere: positive \
                      curvature, θ < 2π inside, total curvature 2π",
        mesh: single_patch("cap", p, t),
        developable: false,
        euler: 1,
        boundary_loops: 1,
    }
}

fn saddle() -> Fixture {
    let (p, t) = ring_disk(DISK_RINGS, |k, s| {
        let r = k as f64 / DISK_RINGS as f64;
        let (x, y) = (r * (TAU * s).cos(), r * (TAU * s).sin());
        [x, y, 0.5 * (x * x - y * y)]
    });
    Fixture {
        name: "saddle",
        description: "z = (x² − y²)/2 over the unit disk, 6 rings: negative curvature, θ > 2π",
        mesh: single_patch("saddle", p, t),
        developable: false,
        euler: 1,
        boundary_loops: 1,
    }
}

fn cube_cuts() -> Fixture {
    const N: i32 = 4;
    // Each face as a map from its grid (i, j) to lattice points, with i × j the outward normal.
    let faces: [fn(i32, i32) -> [i32; 3]; 6] = [
        |i, j| [j, i, 0], // bottom, −z
        |i, j| [i, j, N], // top, +z
        |i, j| [i, 0, j], // front, −y
        |i, j| [j, N, i], // back, +y
        |i, j| [0, j, i], // left, −x
        |i, j| [N, i, j], // right, +x
    ];
    // The top face is cut free along three of its edges (y = 0, x = N, y = N; its corners at
    // x = 0 stay joined, being the ends of the cut path); its vertices there are its own.
    let on_cut = |p: [i32; 3]| p[2] == N && p[0] > 0 && (p[1] == 0 || p[0] == N || p[1] == N);
    let mut index: HashMap<([i32; 3], bool), u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for (fi, map) in faces.iter().enumerate() {
        let mut vid = |i: i32, j: i32| -> u32 {
            let p = map(i, j);
            let key = (p, fi == 1 && on_cut(p));
            *index.entry(key).or_insert_with(|| {
                positions.push([
                    p[0] as f64 / N as f64,
                    p[1] as f64 / N as f64,
                    p[2] as f64 / N as f64,
                ]);
                (positions.len() - 1) as u32
            })
        };
        for j in 0..N {
            for i in 0..N {
                let (a, b, c, d) = (vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1));
                if (i + j) % 2 == 0 {
                    triangles.push([a, b, c]);
                    triangles.push([a, c, d]);
                } else {
                    triangles.push([a, b, d]);
                    triangles.push([b, c, d]);
                }
            }
        }
    }
    Fixture {
        name: "cube_cuts",
        description: "unit cube surface, 4 × 4 squares per face, cut along three edges of the top \
                      face (a flap hinged on the fourth): a disk whose four bottom corners are \
                      interior with θ = 3π/2; all other interior vertices have θ = 2π",
        mesh: single_patch("cube", positions, triangles),
        developable: false,
        euler: 1,
        boundary_loops: 1,
    }
}

fn two_holes() -> Fixture {
    let (nu, nv) = (24, 12);
    let hole = |i: usize, j: usize| {
        ((4..8).contains(&i) && (4..8).contains(&j))
            || ((13..19).contains(&i) && (3..9).contains(&j))
    };
    let (p, t, _) = grid(
        nu,
        nv,
        false,
        |i, j| {
            let phi = PI * i as f64 / nu as f64;
            [1.5 * phi.cos(), 1.5 * phi.sin(), 1.8 * j as f64 / nv as f64]
        },
        |i, j| !hole(i, j),
    );
    Fixture {
        name: "two_holes",
        description: "half cylinder of radius 1.5 and height 1.8 with two rectangular holes \
                      (4 × 4 and 6 × 6 cells): exactly developable, three boundary loops",
        mesh: single_patch("panel", p, t),
        developable: true,
        euler: -1,
        boundary_loops: 3,
    }
}

fn tube_two_panels() -> Fixture {
    let (nu, nv) = (32, 12);
    let height = 2.0;
    let (p, t, cells) = grid(
        nu,
        nv,
        true,
        |i, j| {
            let phi = TAU * i as f64 / nu as f64;
            let z = height * j as f64 / nv as f64;
            let r = 1.0 + 0.08 * (PI * z / height).sin();
            [r * phi.cos(), r * phi.sin(), z]
        },
        |_, _| true,
    );
    let face_patch = cells.iter().map(|&(i, _)| u32::from(i >= nu / 2)).collect();
    Fixture {
        name: "tube_two_panels",
        description: "garment-like tube, radius 1 bulging to 1.08 at mid-height, height 2, made \
                      of two panels (front: angle 0 to π, back: π to 2π) sharing two vertical \
                      seams; open at both ends, not developable",
        mesh: RawMesh {
            positions: p,
            triangles: t,
            face_patch,
            patch_names: vec!["front".into(), "back".into()],
            uv: None,
        },
        developable: false,
        euler: 0,
        boundary_loops: 2,
    }
}
