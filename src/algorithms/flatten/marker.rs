//! A cost estimate for cutting the pieces from a roll: total piece area (inside the cut lines),
//! cut-line length, and the fabric length a simple marker needs on a roll of `fabric_width`.
//!
//! The marker is a greedy strip packing of the pieces' cut-line bounding boxes, grain along the
//! roll (pieces were rotated so the grain runs along +y: only 0° and 180° turns keep it, and
//! those do not change a box): first-fit decreasing height, shelves across the width. It is a
//! quick upper bound, not a nesting: real markers interlock pieces. How close it comes to the
//! area bound (Σ area / width) is reported as the utilisation.

use super::finish::signed_area;
use crate::pattern::{Patterns, Piece};
use serde::Serialize;

/// Most pieces packed first-fit (quadratic); beyond, next-fit.
pub const FIRST_FIT_MAX: usize = 2000;

/// The estimate, in drawing units.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Cost {
    /// Drawing unit of every figure here.
    pub unit: String,
    /// Σ piece area inside the cut lines (the sew lines when there is no allowance).
    pub piece_area: f64,
    /// Σ length of the cut lines (the sew lines when there is no allowance).
    pub cut_length: f64,
    /// Width of the roll.
    pub fabric_width: f64,
    /// Length of roll the marker uses; None when a piece is wider than the roll.
    pub fabric_length: Option<f64>,
    /// Area bound on that length: Σ piece area / width.
    pub length_bound: f64,
    /// Piece area over the fabric used (width × length), percent.
    pub utilisation_pct: Option<f64>,
    /// Pieces wider than the roll (by name).
    pub too_wide: Vec<String>,
}

fn outline(pc: &Piece) -> Vec<Vec<[f64; 2]>> {
    if pc.cut_lines.is_empty() {
        pc.boundary_loops
            .iter()
            .map(|lp| lp.iter().map(|&v| pc.uv[v as usize]).collect())
            .collect()
    } else {
        pc.cut_lines.clone()
    }
}

/// The estimate for a roll `fabric_width` wide (drawing units).
pub fn estimate(p: &Patterns, fabric_width: f64) -> Cost {
    let s = p.scale();
    let mut cost = Cost {
        unit: p.unit.clone(),
        fabric_width,
        ..Cost::default()
    };
    let mut boxes: Vec<(f64, f64, usize)> = Vec::new();
    for (i, pc) in p.pieces.iter().enumerate() {
        let loops = outline(pc);
        // Outer loop counter-clockwise, holes clockwise: the sum is the area inside.
        let area: f64 = loops.iter().map(|l| signed_area(l)).sum::<f64>().abs();
        cost.piece_area += area * s * s;
        for l in &loops {
            let n = l.len();
            cost.cut_length += (0..n)
                .map(|k| {
                    let (a, b) = (l[k], l[(k + 1) % n]);
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
                })
                .sum::<f64>()
                * s;
        }
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for q in loops.iter().flatten() {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k] * s);
                hi[k] = hi[k].max(q[k] * s);
            }
        }
        if lo[0] <= hi[0] {
            boxes.push((hi[0] - lo[0], hi[1] - lo[1], i));
        }
    }
    cost.length_bound = if fabric_width > 0.0 {
        cost.piece_area / fabric_width
    } else {
        0.0
    };
    for &(w, _, i) in &boxes {
        if w > fabric_width {
            cost.too_wide.push(p.pieces[i].patch.clone());
        }
    }
    if !cost.too_wide.is_empty() {
        return cost;
    }
    // First-fit decreasing height: each box on the first shelf with room, else a new shelf.
    // Past FIRST_FIT_MAX pieces, next-fit (the last shelf only), which is linear.
    boxes.sort_by(|a, b| b.1.total_cmp(&a.1));
    let first_fit = boxes.len() <= FIRST_FIT_MAX;
    let mut shelves: Vec<(f64, f64)> = Vec::new(); // (used width, height)
    for (w, h, _) in boxes {
        let room = |sh: &&mut (f64, f64)| sh.0 + w <= fabric_width;
        let found = if first_fit {
            shelves.iter_mut().find(room)
        } else {
            shelves.last_mut().filter(|sh| sh.0 + w <= fabric_width)
        };
        match found {
            Some(sh) => sh.0 += w,
            None => shelves.push((w, h)),
        }
    }
    let length: f64 = shelves.iter().map(|sh| sh.1).sum();
    cost.fabric_length = Some(length);
    cost.utilisation_pct =
        (length > 0.0).then(|| 100.0 * cost.piece_area / (fabric_width * length));
    cost
}
