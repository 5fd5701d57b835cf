//! The functions Wang–Tang minimise, with their analytic gradients: the spring energy
//! E = Σ_e (|v_a − v_b| − l⁰_e)² (Eq. 7), the developability detect function
//! G = Σ_i g_i² with g_i = 2π − θ_i at interior vertices and 0 elsewhere (Eq. 4–5), and the
//! penalty objective J = E + (ρ/2) G² (Eq. 9–10).
//!
//! The mesh is welded, so an edge on a seam is one spring (the paper's per-patch E counts it
//! once per patch) and a seam vertex is one position: the "linked vertex sets" of Sec. 4.2 are
//! implicit and G0 continuity is exact. ∂G/∂v is exact (Props. 1–2 of the FL paper through
//! [`corner_angle_gradient`]), not the central differences of Eq. 12, which is the same
//! quantity (G_P is the part of G that depends on v) computed approximately. Gradients are
//! checked against central differences in tests/engine/develop.rs.

use crate::geometry::corner_angle_gradient;
use crate::mesh::{dot, sub, Mesh};
use std::f64::consts::TAU;

/// E, G and J on one mesh's connectivity against rest lengths `rest` (one per edge of
/// `mesh.conn().edges()`).
#[derive(Debug, Clone)]
pub struct Model<'a> {
    mesh: &'a Mesh,
    rest: Vec<f64>,
    interior: Vec<bool>,
}

impl<'a> Model<'a> {
    /// The model whose rest lengths are the mesh's own edge lengths (E = 0 at the input).
    pub fn new(mesh: &'a Mesh) -> Self {
        let rest = crate::geometry::edge_lengths(mesh, mesh.positions());
        Self::with_rest(mesh, rest)
    }

    /// The model with given rest lengths (one per edge). Interior vertices of a closed
    /// component whose Euler characteristic is not 0 get g = 0: by Gauss–Bonnet their defects
    /// sum to 2πχ, so no deformation can zero them (the run reports them instead).
    pub fn with_rest(mesh: &'a Mesh, rest: Vec<f64>) -> Self {
        debug_assert_eq!(rest.len(), mesh.conn().edges().len());
        let impossible = crate::algorithms::fl_mesh::impossible_vertices(mesh);
        let interior = (0..mesh.num_vertices() as u32)
            .map(|v| mesh.conn().is_interior(v) && !impossible[v as usize])
            .collect();
        Model {
            mesh,
            rest,
            interior,
        }
    }

    /// The mesh whose connectivity the model uses.
    pub fn mesh(&self) -> &'a Mesh {
        self.mesh
    }

    /// The rest lengths l⁰.
    pub fn rest(&self) -> &[f64] {
        &self.rest
    }

    /// Whether g is defined at `v` (an interior vertex).
    pub fn is_interior(&self, v: usize) -> bool {
        self.interior[v]
    }

    /// E (Eq. 7).
    pub fn e(&self, pos: &[[f64; 3]]) -> f64 {
        self.mesh
            .conn()
            .edges()
            .iter()
            .zip(&self.rest)
            .map(|(e, &l0)| {
                let d = sub(pos[e[0] as usize], pos[e[1] as usize]);
                (dot(d, d).sqrt() - l0).powi(2)
            })
            .sum()
    }

    /// ∂E/∂v (Eq. 11) into `out` (overwritten). A zero-length edge contributes nothing (its
    /// direction is undefined; the gradient's norm 2|l⁰| is bounded there).
    pub fn e_gradient(&self, pos: &[[f64; 3]], out: &mut [[f64; 3]]) {
        out.fill([0.0; 3]);
        for (e, &l0) in self.mesh.conn().edges().iter().zip(&self.rest) {
            let (a, b) = (e[0] as usize, e[1] as usize);
            let d = sub(pos[a], pos[b]);
            let l = dot(d, d).sqrt();
            if l == 0.0 {
                continue;
            }
            let s = 2.0 * (l - l0) / l;
            for k in 0..3 {
                out[a][k] += s * d[k];
                out[b][k] -= s * d[k];
            }
        }
    }

    /// g per vertex (Eq. 5) into `g` (overwritten): 2π − θ at interior vertices, 0 elsewhere.
    pub fn g(&self, pos: &[[f64; 3]], g: &mut [f64]) {
        crate::geometry::angle_sums_into(self.mesh, pos, g);
        for (v, gv) in g.iter_mut().enumerate() {
            *gv = if self.interior[v] { TAU - *gv } else { 0.0 };
        }
    }

    /// ∂G/∂v = −2 Σ_i g_i ∂θ_i/∂v (Eq. 4, Props. 1–2) into `out` (overwritten), `g` from
    /// [`Model::g`] at the same positions. A degenerate corner contributes nothing.
    pub fn g_gradient(&self, pos: &[[f64; 3]], g: &[f64], out: &mut [[f64; 3]]) {
        out.fill([0.0; 3]);
        for t in self.mesh.triangles() {
            for k in 0..3 {
                let a = t[k] as usize;
                if g[a] == 0.0 {
                    continue;
                }
                let (b, c) = (t[(k + 1) % 3] as usize, t[(k + 2) % 3] as usize);
                let (gb, gc) = corner_angle_gradient(pos[a], pos[b], pos[c]);
                if !(gb.iter().chain(&gc).all(|x| x.is_finite())) {
                    continue;
                }
                let s = -2.0 * g[a];
                for i in 0..3 {
                    out[b][i] += s * gb[i];
                    out[c][i] += s * gc[i];
                    out[a][i] -= s * (gb[i] + gc[i]);
                }
            }
        }
    }

    /// J = E + (ρ/2) G² (Eq. 9), with `g` as scratch.
    pub fn j(&self, pos: &[[f64; 3]], rho: f64, g: &mut [f64]) -> f64 {
        self.g(pos, g);
        let big_g = big_g(g);
        self.e(pos) + 0.5 * rho * big_g * big_g
    }

    /// ∂J/∂v = ∂E/∂v + ρ G ∂G/∂v (Eq. 10) into `out`, with `g` and `tmp` as scratch; returns J.
    pub fn j_gradient(
        &self,
        pos: &[[f64; 3]],
        rho: f64,
        g: &mut [f64],
        tmp: &mut [[f64; 3]],
        out: &mut [[f64; 3]],
    ) -> f64 {
        self.g(pos, g);
        let big_g = big_g(g);
        self.g_gradient(pos, g, tmp);
        self.e_gradient(pos, out);
        for (o, t) in out.iter_mut().zip(tmp.iter()) {
            for k in 0..3 {
                o[k] += rho * big_g * t[k];
            }
        }
        self.e(pos) + 0.5 * rho * big_g * big_g
    }
}

/// G = Σ g² (Eq. 4).
pub fn big_g(g: &[f64]) -> f64 {
    g.iter().map(|x| x * x).sum()
}

/// max |g|.
pub fn g_max(g: &[f64]) -> f64 {
    g.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}
