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

/// Millimetres per unit, for `mm`, `cm`, `dm`, `m`, `in` (None for anything else).
pub fn mm_per(unit: &str) -> Option<f64> {
    match unit {
        "mm" => Some(1.0),
        "dm" => Some(100.0),
        "cm" => Some(10.0),
        "m" => Some(1000.0),
        "in" => Some(25.4),
        _ => None,
    }
}

impl Patterns {
    /// Drawing units per mesh unit (1 when a unit is missing or unknown).
    pub fn scale(&self) -> f64 {
        match (mm_per(&self.input_unit), mm_per(&self.unit)) {
            (Some(a), Some(b)) => a / b,
            _ => 1.0,
        }
    }

    /// Placement of each piece in the drawing: drawing = uv · scale + offset. Also returns the
    /// drawing's width and height. Shelf packing by bounding boxes (cut lines included),
    /// tallest first, shelves no wider than max(widest piece, 1.5 √(Σ box areas)); a gap of
    /// 3 % of the mean box size.
    pub fn layout(&self) -> (Vec<[f64; 2]>, f64, f64) {
        let s = self.scale();
        let boxes: Vec<([f64; 2], [f64; 2])> = self
            .pieces
            .iter()
            .map(|pc| {
                let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
                for q in pc.uv.iter().chain(pc.cut_lines.iter().flatten()) {
                    for k in 0..2 {
                        lo[k] = lo[k].min(q[k] * s);
                        hi[k] = hi[k].max(q[k] * s);
                    }
                }
                if pc.uv.is_empty() {
                    ([0.0; 2], [0.0; 2])
                } else {
                    (lo, hi)
                }
            })
            .collect();
        let n = boxes.len().max(1) as f64;
        let mean = boxes
            .iter()
            .map(|(lo, hi)| ((hi[0] - lo[0]) + (hi[1] - lo[1])) / 2.0)
            .sum::<f64>()
            / n;
        let gap = 0.03 * mean.max(f64::MIN_POSITIVE);
        let area: f64 = boxes
            .iter()
            .map(|(lo, hi)| (hi[0] - lo[0] + gap) * (hi[1] - lo[1] + gap))
            .sum();
        let widest = boxes
            .iter()
            .map(|(lo, hi)| hi[0] - lo[0])
            .fold(0.0, f64::max);
        let shelf_w = widest.max(1.5 * area.sqrt());
        let mut order: Vec<usize> = (0..boxes.len()).collect();
        order.sort_by(|&a, &b| {
            let ha = boxes[a].1[1] - boxes[a].0[1];
            let hb = boxes[b].1[1] - boxes[b].0[1];
            hb.partial_cmp(&ha).unwrap_or(std::cmp::Ordering::Equal)
        });
        let mut off = vec![[0.0; 2]; boxes.len()];
        let (mut x, mut y, mut shelf_h, mut width) = (gap, gap, 0.0f64, 0.0f64);
        for i in order {
            let (lo, hi) = boxes[i];
            let (w, h) = (hi[0] - lo[0], hi[1] - lo[1]);
            if x > gap && x + w > shelf_w + gap {
                x = gap;
                y += shelf_h + gap;
                shelf_h = 0.0;
            }
            off[i] = [x - lo[0], y - lo[1]];
            x += w + gap;
            width = width.max(x);
            shelf_h = shelf_h.max(h);
        }
        (off, width, y + shelf_h + gap)
    }

    /// Texture coordinates for the mesh the pieces were cut from: each triangle corner at its
    /// point in the drawing ([`Patterns::layout`], drawing units, y up), one coordinate per
    /// piece vertex. None unless every face of the mesh is in exactly one piece.
    pub fn uv_layer(&self, num_faces: usize) -> Option<crate::mesh::UvLayer> {
        let s = self.scale();
        let (off, _, _) = self.layout();
        let mut coords = Vec::new();
        let mut triangles = vec![[u32::MAX; 3]; num_faces];
        for (i, pc) in self.pieces.iter().enumerate() {
            let base = coords.len() as u32;
            coords.extend(
                pc.uv
                    .iter()
                    .map(|q| [q[0] * s + off[i][0], q[1] * s + off[i][1]]),
            );
            for (t, &f) in pc.triangles.iter().zip(&pc.faces) {
                let slot = triangles.get_mut(f as usize)?;
                if slot[0] != u32::MAX {
                    return None;
                }
                *slot = t.map(|c| base + c);
            }
        }
        if triangles.iter().any(|t| t[0] == u32::MAX) {
            return None;
        }
        Some(crate::mesh::UvLayer { coords, triangles })
    }
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
    /// Cut lines: the sew line (`boundary_loops`) offset outwards by the seam allowance,
    /// outer first (counter-clockwise), then what is left of each hole (clockwise). Empty when
    /// no allowance was asked for.
    #[serde(default)]
    pub cut_lines: Vec<Vec<[f64; 2]>>,
    /// Notches on the sew line, where the piece meets another piece (or itself) along a seam.
    #[serde(default)]
    pub notches: Vec<Notch>,
    /// The grain line, from one end to the other; the piece is rotated so that it runs along
    /// +y.
    #[serde(default)]
    pub grain: Option<[[f64; 2]; 2]>,
}

/// A notch: a short cut into the seam allowance that the sewer matches with the notch of the
/// same number on the seam's other side.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Notch {
    /// Index into `Patterns::seams`.
    pub seam: usize,
    /// Which side of the seam this piece is (0 or 1; a real cut has both on one piece).
    pub side: usize,
    /// Number along the seam from its first end (0), the same on both sides.
    pub number: usize,
    /// The boundary edge it lies on, as indices into the piece's `uv`.
    pub edge: [u32; 2],
    /// Where on that edge: `uv[edge[0]] · (1 − t) + uv[edge[1]] · t` (and the same on the 3D
    /// edge).
    pub t: f64,
    /// Position on the sew line.
    pub at: [f64; 2],
    /// Unit direction into the piece, across the sew line.
    pub inward: [f64; 2],
    /// Where the notch meets the cut line (straight out from `at`); `at` when there is no cut
    /// line.
    #[serde(default)]
    pub cut_at: [f64; 2],
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
