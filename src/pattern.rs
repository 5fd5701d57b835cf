//! Flat sewing patterns: plain data that crosses layers. Algorithms (`flatten`) produce it, io
//! writes it (JSON, SVG, DXF) without importing any algorithm (../shared/DESIGN.md).

use serde::{Deserialize, Serialize};

/// The 2D pieces of a mesh and the seams that join them.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Patterns {
    /// One piece per patch.
    pub pieces: Vec<Piece>,
    /// Boundaries shared by two patches.
    pub seams: Vec<Seam>,
    /// Unit of the mesh coordinates, which the pieces keep (`m`, `mm`, `cm`, `in`).
    #[serde(default)]
    pub input_unit: String,
    /// Unit of the drawings (SVG, DXF).
    #[serde(default)]
    pub unit: String,
    /// Whether the SVG draws the triangles as well as the outlines.
    #[serde(default)]
    pub svg_triangles: bool,
}

/// One flat piece, in the mesh's own units.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Piece {
    /// The patch's name.
    pub patch: String,
    /// The 3D vertex of each 2D vertex.
    pub vertex_ids: Vec<u32>,
    /// 2D position of each 2D vertex.
    pub uv: Vec<[f64; 2]>,
    /// Triangles, indices into `uv`.
    pub triangles: Vec<[u32; 3]>,
    /// Boundary loops, indices into `uv`, outer loop first, counter-clockwise.
    pub boundary_loops: Vec<Vec<u32>>,
    /// Area of the piece in 2D.
    pub area: f64,
    /// Total length of its boundary loops in 2D.
    pub perimeter: f64,
    /// Distortion measures (names and values).
    pub measures: serde_json::Map<String, serde_json::Value>,
    /// The 3D face of each triangle.
    #[serde(default)]
    pub faces: Vec<u32>,
}

/// A boundary shared by two patches.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Seam {
    /// The two patches' names.
    pub patches: [String; 2],
    /// Length in 3D.
    pub length_3d: f64,
    /// Length on each piece, in the order of `patches`.
    pub lengths: [f64; 2],
    /// Indices into `Patterns::pieces` of the two pieces.
    #[serde(default)]
    pub pieces: [usize; 2],
    /// The seam's edges on each piece, as pairs of indices into that piece's `uv`.
    #[serde(default)]
    pub edges: [Vec<[u32; 2]>; 2],
}
