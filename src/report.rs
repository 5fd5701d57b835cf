//! The flattenability report: plain data, computed from a [`Mesh`] by [`Report::compute`],
//! serialised as the JSON of `flatmesh report --json` and of every job's result.

use crate::geometry::{self, DEVELOPABLE_TOLERANCE};
use crate::mesh::{Mesh, VertexKind, Warning};
use serde::Serialize;

/// Upper edges of the ϖ histogram's bins (radians); a last bin takes everything above 1 rad.
/// Decades, because ϖ spans from round-off (1e-15) to whole radians.
pub const HISTOGRAM_EDGES: [f64; 12] = [
    1e-12, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0,
];

/// Per-patch summary.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PatchReport {
    /// Patch name (OBJ group/object, glTF mesh/primitive).
    pub name: String,
    /// Faces in the patch.
    pub faces: usize,
    /// Vertices used by the patch.
    pub vertices: usize,
    /// Vertices interior to the patch.
    pub interior_vertices: usize,
    /// Boundary loops of the patch (free boundary and seams).
    pub boundary_loops: usize,
    /// Euler characteristic V − E + F (1 for a disk, 0 for an annulus or open cylinder).
    pub euler_characteristic: i64,
    /// Area of the patch.
    pub area: f64,
    /// Largest ϖ over the patch's interior vertices (0 when it has none).
    pub max_flattenability: f64,
}

/// One histogram bin: interior vertices with `lo < ϖ ≤ hi` (`hi` = null: unbounded).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Bin {
    /// Lower edge (exclusive, except 0).
    pub lo: f64,
    /// Upper edge (inclusive); `None` for the last bin.
    pub hi: Option<f64>,
    /// Number of interior vertices in the bin.
    pub count: usize,
}

/// Per-vertex figures.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct VertexReport {
    /// Vertex index (for OBJ input: the file's `v` line order, from 0).
    pub index: u32,
    /// `interior`, `seam`, `boundary` or `unreferenced`.
    pub kind: &'static str,
    /// Whether ϖ is defined here (closed fan within one patch).
    pub interior: bool,
    /// Angle sum θ(v) over all faces at the vertex (radians).
    pub angle_sum: f64,
    /// ϖ(v) = |2π − θ(v)| at interior vertices, 0 elsewhere (Eq. 5).
    pub flattenability: f64,
    /// Discrete Gaussian curvature (Eq. 1) where the fan is closed; null on the free boundary.
    pub gaussian_curvature: Option<f64>,
}

/// The flattenability report of a mesh.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Report {
    /// Number of vertices (including unreferenced ones).
    pub vertices: usize,
    /// Number of triangles.
    pub faces: usize,
    /// Connected components.
    pub components: usize,
    /// Free-boundary loops of the whole mesh.
    pub boundary_loops: usize,
    /// Vertices shared by more than one patch.
    pub shared_vertices: usize,
    /// Total surface area.
    pub area: f64,
    /// Per-patch summaries.
    pub patches: Vec<PatchReport>,
    /// Number of interior vertices.
    pub interior_vertices: usize,
    /// ϖ_max over interior vertices (radians).
    pub max_flattenability: f64,
    /// The vertex where ϖ_max occurs (null when there is no interior vertex).
    pub max_flattenability_vertex: Option<u32>,
    /// Mean ϖ over interior vertices.
    pub mean_flattenability: f64,
    /// Root mean square ϖ over interior vertices.
    pub rms_flattenability: f64,
    /// ϖ at or below this counts as developable in `D` and `developable_vertices`.
    pub developable_tolerance: f64,
    /// Interior vertices with ϖ ≤ tolerance.
    pub developable_vertices: usize,
    /// D[M], Eq. 2 of the wang-tang paper.
    #[serde(rename = "wang_tang_d")]
    pub d: f64,
    /// G[M], Eq. 4.
    #[serde(rename = "wang_tang_g")]
    pub g: f64,
    /// ϖ histogram over interior vertices.
    pub histogram: Vec<Bin>,
    /// Per-vertex figures, by index.
    pub per_vertex: Vec<VertexReport>,
    /// What was repaired or ignored on input.
    pub warnings: Vec<Warning>,
}

impl Report {
    /// Compute the report of `mesh`; `warnings` are those from loading it.
    pub fn compute(mesh: &Mesh, warnings: &[Warning]) -> Report {
        let conn = mesh.conn();
        let theta = geometry::angle_sums(mesh);
        let varpi = geometry::flattenability(mesh, &theta);
        let farea = geometry::face_areas(mesh);
        let varea = geometry::vertex_areas(mesh, &farea);
        let kappa = geometry::gaussian_curvature(mesh, &theta, &varea);

        let mut n_int = 0usize;
        let (mut sum, mut sum2, mut max) = (0.0f64, 0.0f64, 0.0f64);
        let mut argmax = None;
        let mut counts = vec![0usize; HISTOGRAM_EDGES.len() + 1];
        let mut developable = 0usize;
        for v in conn.interior_vertices() {
            let w = varpi[v as usize];
            n_int += 1;
            sum += w;
            sum2 += w * w;
            if argmax.is_none() || w > max {
                max = w;
                argmax = Some(v);
            }
            if w <= DEVELOPABLE_TOLERANCE {
                developable += 1;
            }
            let bin = HISTOGRAM_EDGES.partition_point(|&e| e < w);
            counts[bin] += 1;
        }
        let histogram = counts
            .iter()
            .enumerate()
            .map(|(i, &count)| Bin {
                lo: if i == 0 { 0.0 } else { HISTOGRAM_EDGES[i - 1] },
                hi: HISTOGRAM_EDGES.get(i).copied(),
                count,
            })
            .collect();

        let patches = conn
            .patches()
            .iter()
            .zip(mesh.patch_names())
            .map(|(p, name)| {
                let mut pmax = 0.0f64;
                let mut area = 0.0;
                for &f in &p.faces {
                    area += farea[f as usize];
                    for &v in &mesh.triangles()[f as usize] {
                        if conn.is_interior(v) {
                            pmax = pmax.max(varpi[v as usize]);
                        }
                    }
                }
                PatchReport {
                    name: name.clone(),
                    faces: p.faces.len(),
                    vertices: p.vertices,
                    interior_vertices: p.interior_vertices,
                    boundary_loops: p.boundary_loops.len(),
                    euler_characteristic: p.euler_characteristic(),
                    area,
                    max_flattenability: pmax,
                }
            })
            .collect();

        let per_vertex = (0..mesh.num_vertices())
            .map(|v| {
                let kind = conn.kind(v as u32);
                VertexReport {
                    index: v as u32,
                    kind: kind_name(kind),
                    interior: kind == VertexKind::Interior,
                    angle_sum: theta[v],
                    flattenability: varpi[v],
                    gaussian_curvature: kappa[v],
                }
            })
            .collect();

        let denom = n_int.max(1) as f64;
        Report {
            vertices: mesh.num_vertices(),
            faces: mesh.num_faces(),
            components: conn.components(mesh.num_faces()),
            boundary_loops: conn.boundary_loops().len(),
            shared_vertices: conn.shared_vertices().len(),
            area: farea.iter().sum(),
            patches,
            interior_vertices: n_int,
            max_flattenability: max,
            max_flattenability_vertex: argmax,
            mean_flattenability: sum / denom,
            rms_flattenability: (sum2 / denom).sqrt(),
            developable_tolerance: DEVELOPABLE_TOLERANCE,
            developable_vertices: developable,
            d: geometry::developability_d(&varpi, &varea, DEVELOPABLE_TOLERANCE),
            g: geometry::developability_g(&varpi),
            histogram,
            per_vertex,
            warnings: warnings.to_vec(),
        }
    }

    /// A few lines for a person at a terminal.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} vertices, {} faces, {} patches, {} components, {} boundary loops",
            self.vertices,
            self.faces,
            self.patches.len(),
            self.components,
            self.boundary_loops
        );
        let _ = writeln!(
            s,
            "interior vertices: {} ({} developable at ϖ ≤ {:e} rad)",
            self.interior_vertices, self.developable_vertices, self.developable_tolerance
        );
        match self.max_flattenability_vertex {
            Some(v) => {
                let _ = writeln!(
                    s,
                    "flattenability ϖ: max {:.3e} rad (vertex {v}), mean {:.3e}, rms {:.3e}",
                    self.max_flattenability, self.mean_flattenability, self.rms_flattenability
                );
            }
            None => {
                let _ = writeln!(s, "flattenability ϖ: no interior vertex");
            }
        }
        let _ = writeln!(s, "D[M] = {:.6}, G[M] = {:.6e}", self.d, self.g);
        for p in &self.patches {
            let _ = writeln!(
                s,
                "  patch {:?}: {} faces, {} vertices ({} interior), {} boundary loops, χ = {}, ϖ_max {:.3e}",
                p.name,
                p.faces,
                p.vertices,
                p.interior_vertices,
                p.boundary_loops,
                p.euler_characteristic,
                p.max_flattenability
            );
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning [{}]: {}", w.code, w.message);
        }
        s
    }
}

/// The JSON name of a vertex kind.
pub fn kind_name(k: VertexKind) -> &'static str {
    match k {
        VertexKind::Interior => "interior",
        VertexKind::Seam => "seam",
        VertexKind::Boundary => "boundary",
        VertexKind::Unreferenced => "unreferenced",
    }
}
