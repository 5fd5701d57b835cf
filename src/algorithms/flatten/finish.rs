//! Cut-ready pieces: grain line, notches and seam allowance on flattened pieces.
//!
//! - **Grain** ([`Grain`]): each piece is rotated in its plane so that the grain runs along the
//!   drawing's +y axis. For a 3D direction g (default the mesh's up axis, +Y), the direction in
//!   the piece is the area-weighted image of g's tangential part under each triangle's linear
//!   map 3D → 2D; where g is nearly normal to the piece that image means nothing and the
//!   piece's principal axis is used instead (said in a warning). The grain line is drawn
//!   through the piece's area centroid, half the piece's height long.
//! - **Notches**: both sides of a seam are walked in the same direction from the same end,
//!   matched by their 3D positions; notches sit at both ends and every `notch_spacing` of 3D
//!   arc length, each as (boundary edge, t) on each side. The same (edge, t) on both sides is
//!   the same 3D point, whatever the flattening did to the lengths (LSCM does not keep them).
//! - **Seam allowance**: the cut line bounds the union of the piece, a rectangle of the edge's
//!   allowance outside each sew-line edge, and a join at each convex corner: a mitre where the
//!   two offset lines meet, squared off at `mitre_limit` × allowance from the corner
//!   (`corners = square` is a limit of 1). The allowance is per edge (a seam's override by its
//!   patch pair, or the hem allowance on free boundary), which a uniform offset cannot do. The
//!   union is Clipper2's (the `clipper2-rust` port) in 64-bit integers scaled so the piece
//!   spans 2⁴² units: a straight edge's cut line lies at its allowance to ~1e-12 of the piece's
//!   size (i_overlay works on a 32-bit grid, ~1e-9). The result is a set of simple polygons.

use super::cut::dist;
use crate::pattern::{Notch, Patterns, Piece};
use clipper2_rust::{FillRule, Path64, Paths64, Point64};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Notches × cut-line vertices of a piece above which a notch's point on the cut line is
/// taken straight out by its allowance instead of found by a ray (bounds the time).
pub const MAX_RAY_WORK: usize = 20_000_000;

/// Most notches on one seam: a spacing that would put more is widened.
pub const MAX_NOTCHES_PER_SEAM: f64 = 10_000.0;

/// How the grain is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Grain {
    /// The mesh's up axis (+Y, glTF's convention).
    #[default]
    Up,
    /// The piece's own longest axis (principal axis of its area).
    Principal,
    /// Leave pieces as flattened, with no grain line.
    None,
    /// A 3D direction in mesh coordinates.
    Direction([f64; 3]),
}

impl Serialize for Grain {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Grain::Up => s.serialize_str("up"),
            Grain::Principal => s.serialize_str("principal"),
            Grain::None => s.serialize_str("none"),
            Grain::Direction(d) => d.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Grain {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let v = serde_json::Value::deserialize(d)?;
        match &v {
            serde_json::Value::String(s) => match s.as_str() {
                "up" => Ok(Grain::Up),
                "principal" => Ok(Grain::Principal),
                "none" => Ok(Grain::None),
                _ => Err(D::Error::custom(format!(
                    "unknown grain `{s}`: expected `up`, `principal`, `none` or a 3D direction [x, y, z]"
                ))),
            },
            _ => {
                let a: [f64; 3] = serde_json::from_value(v).map_err(|_| {
                    D::Error::custom(
                        "expected `up`, `principal`, `none` or a 3D direction [x, y, z]",
                    )
                })?;
                Ok(Grain::Direction(a))
            }
        }
    }
}

/// Corner style of the cut line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Corners {
    /// Offset lines meet at a point, squared off past `mitre_limit` × allowance.
    #[default]
    Mitre,
    /// Every convex corner squared off at the allowance.
    Square,
}

/// A seam allowance for the seams between two patches (the same name twice: the real cuts of
/// that piece).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SeamAllowance {
    /// The two pieces' names, in either order.
    pub patches: [String; 2],
    /// Allowance in the drawing unit.
    pub allowance: f64,
}

/// What [`apply`] does, lengths in mesh units.
#[derive(Debug, Clone, PartialEq)]
pub struct Finish {
    /// Allowance of a seam without an override.
    pub seam_allowance: f64,
    /// Allowance of free boundary edges (hems, necklines).
    pub hem_allowance: f64,
    /// Per patch pair.
    pub overrides: Vec<([String; 2], f64)>,
    /// A mitre reaching further than this many allowances from its sew-line corner, measured
    /// along the corner's bisector, is squared off there.
    pub mitre_limit: f64,
    /// Arc length between notches along a seam; 0 puts them at the ends only.
    pub notch_spacing: f64,
    /// Grain.
    pub grain: Grain,
}

/// Grain, notches and cut lines of every piece (what was there before is replaced, so this
/// can run again after the seams change). `positions` are the 3D positions of the mesh the
/// pieces' `vertex_ids` refer to. Returns warnings for what could not be done.
pub fn apply(p: &mut Patterns, positions: &[[f64; 3]], f: &Finish) -> Vec<String> {
    let mut warnings = Vec::new();
    for pc in &mut p.pieces {
        if let Some(w) = orient(pc, positions, f.grain) {
            warnings.push(w);
        }
        pc.notches.clear();
        pc.cut_lines.clear();
    }
    warnings.extend(notches(p, positions, f.notch_spacing));
    let allowances = edge_allowances(p, f);
    for (i, pc) in p.pieces.iter_mut().enumerate() {
        let limit = f.mitre_limit.max(1.0);
        pc.cut_lines = cut_lines(
            pc,
            &|a, b| {
                allowances
                    .get(&(i, a.min(b), a.max(b)))
                    .copied()
                    .unwrap_or(f.hem_allowance)
            },
            limit,
        );
        // The cut line is at most `limit` allowances out (and may round ~1e-12 inside).
        let reach = limit
            * f.seam_allowance
                .max(f.hem_allowance)
                .max(f.overrides.iter().map(|o| o.1).fold(0.0, f64::max));
        let allowance_of = |e: [u32; 2]| {
            allowances
                .get(&(i, e[0].min(e[1]), e[0].max(e[1])))
                .copied()
                .unwrap_or(f.hem_allowance)
        };
        place_on_cut_line(pc, &allowance_of, reach, MAX_RAY_WORK);
    }
    warnings
}

/// Each notch's point on the cut line: its ray out against the whole cut line, unless that is
/// more than `max_work` segment tests (a piece with a hostile number of seams): then straight
/// out by its edge's allowance, which is the same point along a straight run.
fn place_on_cut_line(
    pc: &mut Piece,
    allowance_of: &dyn Fn([u32; 2]) -> f64,
    reach: f64,
    max_work: usize,
) {
    let cut = &pc.cut_lines;
    let work = pc.notches.len() * cut.iter().map(Vec::len).sum::<usize>();
    for n in &mut pc.notches {
        let out = [-n.inward[0], -n.inward[1]];
        n.cut_at = if cut.is_empty() {
            n.at
        } else if work <= max_work {
            out_to(cut, n.at, out, reach).unwrap_or(n.at)
        } else {
            let w = allowance_of(n.edge);
            [n.at[0] + w * out[0], n.at[1] + w * out[1]]
        };
    }
}

/// The first point where the ray from `p` along `d` crosses one of the polygons, no further
/// than `reach` (a hit up to 1e-9 × reach behind `p` counts: rounding).
fn out_to(polys: &[Vec<[f64; 2]>], p: [f64; 2], d: [f64; 2], reach: f64) -> Option<[f64; 2]> {
    let slack = 1e-9 * reach;
    let mut best: Option<f64> = None;
    for poly in polys {
        let n = poly.len();
        for k in 0..n {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            let e = sub2(b, a);
            let den = cross2(d, e);
            if den.abs() < 1e-300 {
                continue;
            }
            let r = sub2(a, p);
            let s = cross2(r, e) / den;
            let u = cross2(r, d) / den;
            if s >= -slack
                && s <= reach + slack
                && (0.0..=1.0).contains(&u)
                && best.is_none_or(|b| s < b)
            {
                best = Some(s.max(0.0));
            }
        }
    }
    best.map(|s| [p[0] + s * d[0], p[1] + s * d[1]])
}

fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}
fn dot2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}
fn len2(a: [f64; 2]) -> f64 {
    dot2(a, a).sqrt()
}

/// Area-weighted centroid of the piece's triangles and their total area.
fn centroid(pc: &Piece) -> ([f64; 2], f64) {
    let (mut c, mut total) = ([0.0; 2], 0.0);
    for t in &pc.triangles {
        let [a, b, d] = t.map(|i| pc.uv[i as usize]);
        let area = 0.5 * cross2(sub2(b, a), sub2(d, a)).abs();
        for k in 0..2 {
            c[k] += area * (a[k] + b[k] + d[k]) / 3.0;
        }
        total += area;
    }
    if total > 0.0 {
        ([c[0] / total, c[1] / total], total)
    } else {
        (pc.uv.first().copied().unwrap_or([0.0; 2]), 0.0)
    }
}

/// The piece's principal axis (the major axis of its area's second moment, exact for the
/// triangles whatever the triangulation), pointing into y ≥ 0.
fn principal_axis(pc: &Piece) -> [f64; 2] {
    let (m, _) = centroid(pc);
    let (mut xx, mut xy, mut yy) = (0.0, 0.0, 0.0);
    for t in &pc.triangles {
        let [a, b, d] = t.map(|i| sub2(pc.uv[i as usize], m));
        let area = 0.5 * cross2(sub2(b, a), sub2(d, a)).abs();
        // ∫_T x xᵀ dA = A/12 (Σ vᵢvᵢᵀ + (Σ vᵢ)(Σ vᵢ)ᵀ)
        let s = [a[0] + b[0] + d[0], a[1] + b[1] + d[1]];
        let k = area / 12.0;
        xx += k * (a[0] * a[0] + b[0] * b[0] + d[0] * d[0] + s[0] * s[0]);
        xy += k * (a[0] * a[1] + b[0] * b[1] + d[0] * d[1] + s[0] * s[1]);
        yy += k * (a[1] * a[1] + b[1] * b[1] + d[1] * d[1] + s[1] * s[1]);
    }
    let phi = 0.5 * (2.0 * xy).atan2(xx - yy);
    let d = [phi.cos(), phi.sin()];
    if d[1] < 0.0 {
        [-d[0], -d[1]]
    } else {
        d
    }
}

/// The 2D image of the 3D direction g on the piece (area-weighted), and the share of g that is
/// tangential to it on average (0 when g is normal to the piece everywhere).
fn image_of(pc: &Piece, positions: &[[f64; 3]], g: [f64; 3]) -> ([f64; 2], f64) {
    let gl = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
    let g = g.map(|x| x / gl);
    let (mut d, mut tangential, mut total) = ([0.0; 2], 0.0, 0.0);
    for t in &pc.triangles {
        let [p0, p1, p2] = t.map(|i| positions[pc.vertex_ids[i as usize] as usize]);
        let [q0, q1, q2] = t.map(|i| pc.uv[i as usize]);
        let e1 = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
        let e2 = [p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]];
        let d3 = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (g11, g12, g22) = (d3(e1, e1), d3(e1, e2), d3(e2, e2));
        let det = g11 * g22 - g12 * g12;
        if det <= 0.0 {
            continue;
        }
        let area = 0.5 * det.sqrt();
        let (b1, b2) = (d3(e1, g), d3(e2, g));
        let c1 = (g22 * b1 - g12 * b2) / det;
        let c2 = (g11 * b2 - g12 * b1) / det;
        let tan = [0, 1, 2].map(|k| c1 * e1[k] + c2 * e2[k]);
        let (f1, f2) = (sub2(q1, q0), sub2(q2, q0));
        for k in 0..2 {
            d[k] += area * (c1 * f1[k] + c2 * f2[k]);
        }
        tangential += area * d3(tan, tan).sqrt();
        total += area;
    }
    let share = if total > 0.0 { tangential / total } else { 0.0 };
    (d, share)
}

/// Rotate the piece so that its grain runs along +y and set its grain line; a warning when
/// the grain asked for could not be used on it.
fn orient(pc: &mut Piece, positions: &[[f64; 3]], grain: Grain) -> Option<String> {
    let g = match grain {
        Grain::None => {
            pc.grain = None;
            return None;
        }
        Grain::Up => Some([0.0, 1.0, 0.0]),
        Grain::Direction(g) => Some(g),
        Grain::Principal => None,
    };
    let mut warning = None;
    let dir = match g {
        None => principal_axis(pc),
        Some(g) => {
            let (d, share) = image_of(pc, positions, g);
            let l = len2(d);
            // Below a fifth of the piece's area seeing g along it, the direction is noise.
            if share < 0.2 || l.is_nan() || l <= 0.0 {
                warning = Some(format!(
                    "piece `{}`: the grain direction lies across the piece (only {:.0} % of it \
                     along the surface); its principal axis is used instead",
                    pc.patch,
                    100.0 * share
                ));
                principal_axis(pc)
            } else {
                [d[0] / l, d[1] / l]
            }
        }
    };
    let angle = std::f64::consts::FRAC_PI_2 - dir[1].atan2(dir[0]);
    let (s, c) = angle.sin_cos();
    let (m, _) = centroid(pc);
    for q in &mut pc.uv {
        let r = sub2(*q, m);
        *q = [m[0] + c * r[0] - s * r[1], m[1] + s * r[0] + c * r[1]];
    }
    let (m, _) = centroid(pc);
    let (lo, hi) = pc.uv.iter().fold((f64::MAX, f64::MIN), |(lo, hi), q| {
        (lo.min(q[1]), hi.max(q[1]))
    });
    let half = if hi > lo { (hi - lo) / 4.0 } else { 0.0 };
    pc.grain = Some([[m[0], m[1] - half], [m[0], m[1] + half]]);
    warning
}

/// A seam side's edges in walking order, each directed along the walk, and whether they close
/// a loop. The walk follows the mesh vertices (`vid`), not the piece's: where another cut
/// ends on the seam, one side has two copies of a vertex, and its edges are still one path
/// on the surface. None when they do not form one simple path or loop.
fn walk(edges: &[[u32; 2]], vid: &dyn Fn(u32) -> u32) -> Option<(Vec<[u32; 2]>, bool)> {
    if edges.is_empty() {
        return None;
    }
    let mut at: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, e) in edges.iter().enumerate() {
        let (a, b) = (vid(e[0]), vid(e[1]));
        if a == b {
            return None;
        }
        at.entry(a).or_default().push(k);
        at.entry(b).or_default().push(k);
    }
    if at.values().any(|v| v.len() > 2) {
        return None;
    }
    let mut ends: Vec<u32> = at
        .iter()
        .filter(|(_, e)| e.len() == 1)
        .map(|(&v, _)| v)
        .collect();
    ends.sort_unstable();
    let closed = ends.is_empty();
    if !closed && ends.len() != 2 {
        return None;
    }
    let start = if closed { *at.keys().min()? } else { ends[0] };
    let mut used = vec![false; edges.len()];
    let mut order = Vec::with_capacity(edges.len());
    let mut v = start;
    while let Some(&k) = at[&v].iter().find(|&&k| !used[k]) {
        used[k] = true;
        let e = edges[k];
        let forward = vid(e[0]) == v;
        order.push(if forward { e } else { [e[1], e[0]] });
        v = if forward { vid(e[1]) } else { vid(e[0]) };
    }
    if used.iter().any(|u| !u) {
        return None;
    }
    Some((order, closed))
}

/// Notches of every seam, pushed onto the pieces; warnings for seams that have none.
fn notches(p: &mut Patterns, positions: &[[f64; 3]], spacing: f64) -> Vec<String> {
    let mut warnings = Vec::new();
    let mut out: Vec<Vec<Notch>> = vec![Vec::new(); p.pieces.len()];
    let thirds: Vec<HashMap<(u32, u32), u32>> = p.pieces.iter().map(opposite).collect();
    for (s, seam) in p.seams.iter().enumerate() {
        let pieces = seam.pieces;
        if pieces.iter().any(|&i| i >= p.pieces.len()) {
            continue;
        }
        let vid0 = |v: u32| p.pieces[pieces[0]].vertex_ids[v as usize];
        let vid1 = |v: u32| p.pieces[pieces[1]].vertex_ids[v as usize];
        let pos =
            |side: usize, v: u32| positions[p.pieces[pieces[side]].vertex_ids[v as usize] as usize];
        let (Some((w0, closed0)), Some((mut w1, closed1))) =
            (walk(&seam.edges[0], &vid0), walk(&seam.edges[1], &vid1))
        else {
            warnings.push(format!(
                "seam S{s} ({} – {}): not one simple path on both pieces; no notches",
                seam.patches[0], seam.patches[1]
            ));
            continue;
        };
        if closed0 != closed1 || w0.len() != w1.len() {
            warnings.push(format!(
                "seam S{s} ({} – {}): its two sides differ in shape; no notches",
                seam.patches[0], seam.patches[1]
            ));
            continue;
        }
        // Side 1 walked from side 0's start, in side 0's direction (matched in 3D).
        let n = w0.len();
        let p0 = pos(0, w0[0][0]);
        let reverse = |w: &mut Vec<[u32; 2]>| {
            w.reverse();
            for e in w.iter_mut() {
                e.swap(0, 1);
            }
        };
        if closed0 {
            let k = (0..n)
                .min_by(|&a, &b| dist(pos(1, w1[a][0]), p0).total_cmp(&dist(pos(1, w1[b][0]), p0)))
                .unwrap_or(0);
            w1.rotate_left(k);
            if dist(pos(1, w1[0][1]), pos(0, w0[0][1]))
                > dist(pos(1, w1[n - 1][0]), pos(0, w0[0][1]))
            {
                // Walk the loop the other way (reversed, it still starts at w1[0][0]).
                reverse(&mut w1);
            }
        } else if dist(pos(1, w1[n - 1][1]), p0) < dist(pos(1, w1[0][0]), p0) {
            reverse(&mut w1);
        }
        let mut cum = vec![0.0];
        for (i, e) in w0.iter().enumerate() {
            cum.push(cum[i] + dist(pos(0, e[0]), pos(0, e[1])));
        }
        let total = *cum.last().unwrap_or(&0.0);
        let tol = 1e-6 * total.max(f64::MIN_POSITIVE);
        let apart = |i: usize, k: usize| dist(pos(0, w0[i][k]), pos(1, w1[i][k])) > tol;
        if (0..n).any(|i| apart(i, 0) || apart(i, 1)) {
            warnings.push(format!(
                "seam S{s} ({} – {}): its two sides do not meet in 3D; no notches",
                seam.patches[0], seam.patches[1]
            ));
            continue;
        }
        let mut at = vec![0.0];
        // Bounds the output whatever the mesh's size.
        let spacing = spacing.max(total / MAX_NOTCHES_PER_SEAM);
        if spacing > 0.0 {
            let mut k = 1.0;
            while k * spacing < total - 0.25 * spacing {
                at.push(k * spacing);
                k += 1.0;
            }
        }
        if !closed0 {
            at.push(total);
        }
        for (number, &s_at) in at.iter().enumerate() {
            let i = cum[1..].partition_point(|&c| c < s_at).min(n - 1);
            let l = cum[i + 1] - cum[i];
            let t = if l > 0.0 {
                ((s_at - cum[i]) / l).clamp(0.0, 1.0)
            } else {
                0.0
            };
            for (side, w) in [&w0, &w1].into_iter().enumerate() {
                let pc = &p.pieces[pieces[side]];
                let edge = w[i];
                let (a, b) = (pc.uv[edge[0] as usize], pc.uv[edge[1] as usize]);
                let at = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                out[pieces[side]].push(Notch {
                    seam: s,
                    side,
                    number,
                    edge,
                    t,
                    at,
                    inward: inward(pc, &thirds[pieces[side]], edge),
                    cut_at: at,
                });
            }
        }
    }
    for (pc, ns) in p.pieces.iter_mut().zip(out) {
        pc.notches = ns;
    }
    warnings
}

/// The third vertex of the triangle on each boundary edge of a piece, by (lower, higher)
/// uv vertex.
fn opposite(pc: &Piece) -> HashMap<(u32, u32), u32> {
    let mut count: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for t in &pc.triangles {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let e = count.entry((a.min(b), a.max(b))).or_insert((0, c));
            e.0 += 1;
        }
    }
    count
        .into_iter()
        .filter(|(_, (n, _))| *n == 1)
        .map(|(e, (_, c))| (e, c))
        .collect()
}

/// Unit normal of a boundary edge pointing into its triangle (`third`: [`opposite`]).
fn inward(pc: &Piece, third: &HashMap<(u32, u32), u32>, e: [u32; 2]) -> [f64; 2] {
    let (a, b) = (pc.uv[e[0] as usize], pc.uv[e[1] as usize]);
    let d = sub2(b, a);
    let l = len2(d);
    if l <= 0.0 {
        return [0.0, 0.0];
    }
    let left = [-d[1] / l, d[0] / l];
    match third.get(&(e[0].min(e[1]), e[0].max(e[1]))) {
        Some(&c) if dot2(sub2(pc.uv[c as usize], a), left) < 0.0 => [-left[0], -left[1]],
        _ => left,
    }
}

/// Allowance (mesh units) of each seam edge, by (piece, lower uv vertex, higher uv vertex).
fn edge_allowances(p: &Patterns, f: &Finish) -> HashMap<(usize, u32, u32), f64> {
    let key = |a: &str, b: &str| {
        if a <= b {
            (a.to_string(), b.to_string())
        } else {
            (b.to_string(), a.to_string())
        }
    };
    let mut by_pair: HashMap<(String, String), f64> = HashMap::new();
    for (pair, a) in &f.overrides {
        by_pair.entry(key(&pair[0], &pair[1])).or_insert(*a);
    }
    let mut out = HashMap::new();
    for seam in &p.seams {
        let a = by_pair
            .get(&key(&seam.patches[0], &seam.patches[1]))
            .copied()
            .unwrap_or(f.seam_allowance);
        for side in 0..2 {
            for e in &seam.edges[side] {
                out.insert((seam.pieces[side], e[0].min(e[1]), e[0].max(e[1])), a);
            }
        }
    }
    out
}

/// The cut line of a piece: its sew line offset outwards by each edge's allowance.
fn cut_lines(pc: &Piece, allowance: &dyn Fn(u32, u32) -> f64, limit: f64) -> Vec<Vec<[f64; 2]>> {
    // (polygon, whether it keeps its orientation): sew-line loops do (outer counter-clockwise,
    // holes clockwise), rectangles and joins are made to count positively.
    let mut shapes: Vec<(Vec<[f64; 2]>, bool)> = Vec::new();
    let mut reach: f64 = 0.0;
    let third = opposite(pc);
    for lp in &pc.boundary_loops {
        let n = lp.len();
        if n < 3 {
            continue;
        }
        // Walk each loop with the piece on its left, so "outwards" is the right-hand normal.
        let left = (0..n)
            .filter(|&k| {
                let e = [lp[k], lp[(k + 1) % n]];
                let d = sub2(pc.uv[e[1] as usize], pc.uv[e[0] as usize]);
                dot2(inward(pc, &third, e), [-d[1], d[0]]) > 0.0
            })
            .count();
        let mut lp: Vec<u32> = lp.clone();
        if 2 * left < n {
            lp.reverse();
        }
        // The offset is built on the sew line without zero-length edges, simplified within
        // SIMPLIFY × allowance where the allowance does not change; the piece itself enters
        // the union as that simplified loop too, so that its edges are the rectangles' own
        // (the exact sew line is within SIMPLIFY × w of it, inside the allowance).
        let (pts, dist) = simplified(
            lp.iter().map(|&v| pc.uv[v as usize]).collect(),
            (0..n)
                .map(|k| allowance(lp[k], lp[(k + 1) % n]).max(0.0))
                .collect(),
        );
        let m = pts.len();
        if m < 3 {
            continue;
        }
        shapes.push((pts.clone(), true));
        let mut normal = Vec::with_capacity(m);
        for k in 0..m {
            let (a, b) = (pts[k], pts[(k + 1) % m]);
            let d = sub2(b, a);
            let l = len2(d);
            // (A loop touching itself can leave two equal points after simplification.)
            let nr = if l > 0.0 {
                [d[1] / l, -d[0] / l]
            } else {
                [0.0, 0.0]
            };
            let w = dist[k];
            reach = reach.max(w);
            normal.push(nr);
            if w > 0.0 && l > 0.0 {
                let rect = vec![
                    a,
                    b,
                    [b[0] + w * nr[0], b[1] + w * nr[1]],
                    [a[0] + w * nr[0], a[1] + w * nr[1]],
                ];
                shapes.push((rect, false));
            }
        }
        for k in 0..m {
            let j = (k + m - 1) % m;
            if let Some(join) = corner(pts[k], normal[j], dist[j], normal[k], dist[k], limit) {
                shapes.push((join, false));
            }
        }
    }
    if reach <= 0.0 {
        return Vec::new();
    }
    union(shapes)
}

/// A sew line's tolerance for simplification before offsetting, relative to the allowance:
/// the cut line is within 0.1 % of the allowance of the exact offset, and a tight concave
/// curve keeps a few dozen vertices (its rectangles all cross each other, so the union's
/// work grows with their square).
pub const SIMPLIFY: f64 = 1e-3;

/// A closed sew line (points, and each edge's allowance) without zero-length edges, and
/// simplified (Douglas–Peucker within [`SIMPLIFY`] × the allowance) along each run of edges
/// with one allowance; where the allowance changes, and on runs without allowance, every
/// vertex is kept.
fn simplified(pts: Vec<[f64; 2]>, dist: Vec<f64>) -> (Vec<[f64; 2]>, Vec<f64>) {
    // Zero-length edges: drop the repeated point (and its edge).
    let n = pts.len();
    let (mut p, mut d) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        if pts[k] != pts[(k + 1) % n] {
            p.push(pts[k]);
            d.push(dist[k]);
        }
    }
    let n = p.len();
    if n < 3 {
        return (p, d);
    }
    // Anchors: where the allowance changes; a loop with one allowance gets two.
    let mut keep = vec![false; n];
    let mut anchors: Vec<usize> = (0..n).filter(|&k| d[k] != d[(k + n - 1) % n]).collect();
    if anchors.is_empty() {
        let far = (0..n)
            .max_by(|&a, &b| len2(sub2(p[a], p[0])).total_cmp(&len2(sub2(p[b], p[0]))))
            .unwrap_or(0);
        anchors = vec![0, far];
        anchors.sort_unstable();
        anchors.dedup();
    }
    for &a in &anchors {
        keep[a] = true;
    }
    for (i, &a) in anchors.iter().enumerate() {
        let b = anchors[(i + 1) % anchors.len()];
        let eps = SIMPLIFY * d[a];
        let len = (b + n - a) % n;
        let len = if len == 0 { n } else { len };
        if eps <= 0.0 {
            for k in 0..len {
                keep[(a + k) % n] = true;
            }
            continue;
        }
        // Douglas–Peucker on the run a → b, iteratively.
        let mut stack = vec![(0usize, len)];
        while let Some((s, e)) = stack.pop() {
            let (ps, pe) = (p[(a + s) % n], p[(a + e) % n]);
            let chord = sub2(pe, ps);
            let cl = len2(chord);
            let mut worst = (0.0f64, s);
            for k in s + 1..e {
                let q = sub2(p[(a + k) % n], ps);
                let dk = if cl > 0.0 {
                    cross2(chord, q).abs() / cl
                } else {
                    len2(q)
                };
                if dk > worst.0 {
                    worst = (dk, k);
                }
            }
            if worst.0 > eps {
                keep[(a + worst.1) % n] = true;
                stack.push((s, worst.1));
                stack.push((worst.1, e));
            }
        }
    }
    let (mut sp, mut sd) = (Vec::new(), Vec::new());
    for k in 0..n {
        if keep[k] {
            sp.push(p[k]);
            sd.push(d[k]);
        }
    }
    (sp, sd)
}

/// The join at a convex corner v between an edge arriving with outward normal n1 at allowance
/// d1 and one leaving with n2, d2: the mitre [v, p1, M, p2] where the offset lines meet at M,
/// cut off at `limit` × max(d1, d2) from v along the bisector. None at a straight or reflex
/// corner (the edges' rectangles already cover it).
fn corner(
    v: [f64; 2],
    n1: [f64; 2],
    d1: f64,
    n2: [f64; 2],
    d2: f64,
    limit: f64,
) -> Option<Vec<[f64; 2]>> {
    // Directions of the two edges (outward normal is the right-hand one).
    let t1 = [-n1[1], n1[0]];
    let t2 = [-n2[1], n2[0]];
    let (turn, along) = (cross2(t1, t2), dot2(t1, t2));
    let dmax = d1.max(d2);
    let hairpin = turn.abs() <= 1e-12 && along < 0.0;
    if dmax <= 0.0 || len2(t1) == 0.0 || len2(t2) == 0.0 || (turn <= 1e-12 && !hairpin) {
        return None;
    }
    let p1 = [v[0] + d1 * n1[0], v[1] + d1 * n1[1]];
    let p2 = [v[0] + d2 * n2[0], v[1] + d2 * n2[1]];
    let sum = [n1[0] + n2[0], n1[1] + n2[1]];
    let bisector = if len2(sum) > 1e-9 {
        [sum[0] / len2(sum), sum[1] / len2(sum)]
    } else {
        t1
    };
    let cap = limit * dmax;
    let wedge = if hairpin {
        // The offset lines never meet: a square end at the cap.
        vec![
            v,
            p1,
            [p1[0] + cap * t1[0], p1[1] + cap * t1[1]],
            [p2[0] - cap * t2[0], p2[1] - cap * t2[1]],
            p2,
        ]
    } else {
        // Mitre point: p1 + α t1 = p2 − β t2.
        let alpha = cross2(sub2(p2, p1), t2) / turn;
        vec![v, p1, [p1[0] + alpha * t1[0], p1[1] + alpha * t1[1]], p2]
    };
    // Within the corner's sector (past the end of the first edge, before the start of the
    // second): where the allowance changes at a shallow turn the offset lines meet far
    // along one edge, and the join is then a square step.
    let clipped = clip_half_plane(&wedge, v, bisector, cap);
    let clipped = clip_half_plane(&clipped, v, [-t1[0], -t1[1]], 0.0);
    let clipped = clip_half_plane(&clipped, v, t2, 0.0);
    (clipped.len() >= 3).then_some(clipped)
}

/// The part of a polygon where (x − v)·b ≤ c (Sutherland–Hodgman against one line).
fn clip_half_plane(poly: &[[f64; 2]], v: [f64; 2], b: [f64; 2], c: f64) -> Vec<[f64; 2]> {
    let f = |p: [f64; 2]| dot2(sub2(p, v), b) - c;
    let mut out = Vec::with_capacity(poly.len() + 1);
    for k in 0..poly.len() {
        let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
        let (fp, fq) = (f(p), f(q));
        if fp <= 0.0 {
            out.push(p);
        }
        if (fp < 0.0 && fq > 0.0) || (fp > 0.0 && fq < 0.0) {
            let t = fp / (fp - fq);
            out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
    }
    out
}

/// Signed area of a closed polygon (positive counter-clockwise).
pub(crate) fn signed_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|k| cross2(poly[k], poly[(k + 1) % n]))
        .sum::<f64>()
        / 2.0
}

/// Union (positive winding) of polygons, each either kept as oriented or made positive.
/// Outer boundaries first (counter-clockwise, largest first), then holes (clockwise).
fn union(shapes: Vec<(Vec<[f64; 2]>, bool)>) -> Vec<Vec<[f64; 2]>> {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for q in shapes.iter().flat_map(|s| &s.0) {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if !(extent > 0.0 && extent.is_finite()) {
        return Vec::new();
    }
    // A power of two, so that scaling is exact.
    let scale = 2f64.powi(42 - extent.log2().ceil() as i32);
    let to = |q: [f64; 2]| {
        Point64::new(
            ((q[0] - lo[0]) * scale).round() as i64,
            ((q[1] - lo[1]) * scale).round() as i64,
        )
    };
    let from = |p: &Point64| [p.x as f64 / scale + lo[0], p.y as f64 / scale + lo[1]];
    let paths: Paths64 = shapes
        .iter()
        .map(|(s, keep)| {
            let mut path: Path64 = s.iter().map(|&q| to(q)).collect();
            if !keep && signed_area(s) < 0.0 {
                path.reverse();
            }
            path
        })
        .collect();
    let result = clipper2_rust::union_subjects_64(&paths, FillRule::Positive);

    let mut out: Vec<(f64, Vec<[f64; 2]>)> = result
        .iter()
        .map(|p| {
            let poly: Vec<[f64; 2]> = p.iter().map(from).collect();
            (signed_area(&poly), poly)
        })
        // Slivers of no area are rounding where the sew line's own vertices meet the
        // rectangles built on its simplified copy.
        .filter(|(a, _)| a.abs() > 1e-9 * extent * extent)
        .collect();
    out.sort_by(|a, b| {
        (b.0 > 0.0)
            .cmp(&(a.0 > 0.0))
            .then(b.0.abs().total_cmp(&a.0.abs()))
    });
    out.into_iter().map(|(_, p)| p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bounded fallback puts a notch where the ray does along a straight run.
    #[test]
    fn notches_straight_out_agree_with_the_ray_on_straight_edges() {
        // A 4 × 2 rectangle piece (two triangles), allowance 0.5, notches mid-edge.
        let mut pc = Piece {
            uv: vec![[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            boundary_loops: vec![vec![0, 1, 2, 3]],
            ..Piece::default()
        };
        pc.cut_lines = cut_lines(&pc, &|_, _| 0.5, 3.0);
        let third = opposite(&pc);
        for k in 0..4u32 {
            let e = [k, (k + 1) % 4];
            let (a, b) = (pc.uv[e[0] as usize], pc.uv[e[1] as usize]);
            let at = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
            pc.notches.push(Notch {
                edge: e,
                t: 0.5,
                at,
                inward: inward(&pc, &third, e),
                cut_at: at,
                ..Notch::default()
            });
        }
        let mut by_ray = pc.clone();
        place_on_cut_line(&mut by_ray, &|_| 0.5, 1.5, usize::MAX);
        place_on_cut_line(&mut pc, &|_| 0.5, 1.5, 0);
        for (a, b) in by_ray.notches.iter().zip(&pc.notches) {
            assert!(
                (a.cut_at[0] - b.cut_at[0]).abs() < 1e-9
                    && (a.cut_at[1] - b.cut_at[1]).abs() < 1e-9
            );
            let d = ((a.cut_at[0] - a.at[0]).powi(2) + (a.cut_at[1] - a.at[1]).powi(2)).sqrt();
            assert!((d - 0.5).abs() < 1e-9, "notch {:?} → {:?}", a.at, a.cut_at);
        }
    }
}
