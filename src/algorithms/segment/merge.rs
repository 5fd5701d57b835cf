//! Step 4: boundary-based LPFB merging (wang-lpfb Sec. 4.2, steps 1–11).
//!
//! A boundary curve is a maximal chain of mesh edges whose two faces lie in the same
//! unordered pair of charts, ending where three charts meet, at the mesh boundary, or where
//! the pair changes (paper-notes D.3); a pair of charts may share several. A max heap holds
//! every curve keyed by the area of its two charts (ties: the longer curve, then the lower
//! id). Popping ζ, the candidate is both charts' faces with every cut edge except ζ's kept
//! as a cut (other curves between the same charts, dangling cuts of earlier merges); it is
//! refused before flattening unless it is one connected disk, with or without holes, and
//! then flattened by exactly the pipeline `flatten` runs (so what is accepted is what the
//! user downloads) and accepted when |A(Ω)| ≤ `max_area_distortion` (Eq. 19, taken in
//! absolute value: a saddle-shaped chart shrinks), L² ≤ `max_l2_stretch` and, with
//! `reject_overlap`, no overlap. Accepting removes ζ only: the charts' other common curves
//! become dangling cuts ("converted into cuts when generating charts").
//!
//! Step 10 is ambiguous about curves refused earlier: without `retry_rejected` (default)
//! refused curves stay refused, the paper read literally; with it every curve of the merged
//! chart goes back into the heap, since its test depended on a chart that has changed. Each
//! (curve, chart versions) is tested once, so the loop ends either way. Retrying cost 2–6×
//! the time (t-shirt 8.9 → 1.6 s, spot, hemisphere) for the same chart counts on the
//! t-shirt, spot, shoe and hemisphere, so it is an option, not the default (paper-notes D.3
//! proposed it on by default for local maximality).
//!
//! `merge = patch` is Fig. 6(a): a merge removes every curve between the two charts, so no
//! slit is ever left. It is the default (see [`super::MergeMode`] for the measurements);
//! its candidates are cached per chart pair, since every curve between two charts is then
//! the same candidate.
//!
//! Candidates are tested in parallel in batches: the longest run of the heap's top entries
//! whose charts are pairwise disjoint, committed in heap order; a commit ends the batch (the
//! rest go back), and results are cached by (curve, chart versions), so the charts are
//! exactly those of the sequential loop whatever the thread count. (Taking the top entries
//! regardless of their charts wasted two thirds of the flattenings on spot: the biggest
//! chart's curves are on top, and once one merges the others are stale.)

use super::dual::Dual;
use super::vsa;
use crate::algorithms::flatten::{self, cut::Piece3};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::mesh::{Mesh, VertexKind, NONE};
use rayon::prelude::*;
use serde::Serialize;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, HashSet};

/// What the acceptance test needs.
#[derive(Debug, Clone)]
pub struct Criteria {
    /// Largest |A(Ω)| in percent.
    pub max_area_distortion: f64,
    /// Largest L² stretch.
    pub max_l2_stretch: f64,
    /// Refuse a flattening that overlaps itself.
    pub reject_overlap: bool,
    /// Put curves refused earlier back in the heap when one of their charts grows.
    pub retry_rejected: bool,
    /// Remove every curve between the two charts (patch-based) instead of one.
    pub patch_based: bool,
    /// How candidates are flattened.
    pub flatten: flatten::Params,
}

/// One tested candidate of the merge log.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Curve id.
    pub curve: u32,
    /// The two charts (ids as they were at the test).
    pub charts: [u32; 2],
    /// Faces of the merged chart.
    pub faces: usize,
    /// A(Ω) in percent (signed, Eq. 19), when flattened.
    pub area_distortion_pct: Option<f64>,
    /// L² stretch, when flattened.
    pub l2_stretch: Option<f64>,
    /// Overlap S(Ω), when flattened.
    pub overlap: Option<u8>,
    /// Accepted.
    pub accepted: bool,
    /// Why not, when refused.
    pub reason: Option<String>,
}

/// What merging produced.
#[derive(Debug, Clone, Default)]
pub struct Merged {
    /// Chart of every face (ids of surviving charts, not renumbered).
    pub labels: Vec<u32>,
    /// Every edge left as a cut inside a chart (dangling), as mesh edge ids.
    pub dangling: Vec<u32>,
    /// Every edge between two faces that is cut (chart boundaries and dangling cuts).
    pub cut: Vec<u32>,
    /// Candidates in the order tested.
    pub log: Vec<Candidate>,
    /// Flattenings run (cache misses).
    pub evaluations: usize,
}

/// Curve state.
#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Pending,
    Refused,
    Removed,
    Dangling,
}

struct Curve {
    edges: Vec<u32>,
    /// A face on each side of the first edge (their charts are the curve's pair).
    sides: [u32; 2],
    length: f64,
    state: State,
}

#[derive(PartialEq)]
struct Entry {
    key: f64,
    length: f64,
    curve: u32,
    versions: [u32; 2],
}
impl Eq for Entry {}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        self.key
            .total_cmp(&o.key)
            .then(self.length.total_cmp(&o.length))
            .then(o.curve.cmp(&self.curve))
    }
}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// Result of testing one candidate.
#[derive(Clone)]
struct Test {
    faces: usize,
    measures: Option<(f64, f64, u8)>,
    refusal: Option<String>,
}

/// Merge the charts of `labels` (ids 0..k) greedily.
pub fn run(
    mesh: &Mesh,
    dual: &Dual,
    labels: &[u32],
    k: usize,
    criteria: &Criteria,
    control: &dyn Control,
) -> Result<Merged, AlgoError> {
    let mut labels = labels.to_vec();
    let mut cut = cut_edges(mesh, dual, &labels);
    let mut curves = find_curves(mesh, dual, &labels);
    let mut area = vec![0.0; k];
    for (f, &l) in labels.iter().enumerate() {
        area[l as usize] += dual.area[f];
    }
    let mut version: Vec<u32> = (0..k as u32).collect();
    let mut next_version = k as u32;
    let pair = |labels: &[u32], c: &Curve| -> [u32; 2] {
        let (a, b) = (labels[c.sides[0] as usize], labels[c.sides[1] as usize]);
        [a.min(b), a.max(b)]
    };
    let mut heap = BinaryHeap::new();
    for (i, c) in curves.iter().enumerate() {
        let [a, b] = pair(&labels, c);
        heap.push(Entry {
            key: area[a as usize] + area[b as usize],
            length: c.length,
            curve: i as u32,
            versions: [version[a as usize], version[b as usize]],
        });
    }
    let mut out = Merged::default();
    let mut cache: HashMap<(u32, [u32; 2]), Test> = HashMap::new();
    let batch = 2 * rayon::current_num_threads().max(1);
    let mut members = members_of(&labels, k);
    loop {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        // Step 3, a batch at a time: the longest run of current entries, in heap order, whose
        // charts are pairwise disjoint (a commit cannot make a later one stale, and
        // processing them in order is the sequential loop).
        let mut top = Vec::new();
        let mut busy: Vec<u32> = Vec::new();
        while top.len() < batch {
            let Some(e) = heap.pop() else { break };
            let c = &curves[e.curve as usize];
            let [a, b] = pair(&labels, c);
            if c.state != State::Pending
                || a == b
                || e.versions != [version[a as usize], version[b as usize]]
            {
                continue;
            }
            if busy.contains(&a) || busy.contains(&b) {
                heap.push(e);
                break;
            }
            busy.extend([a, b]);
            top.push(e);
        }
        if top.is_empty() {
            break;
        }
        // With patch-based merging every curve between two charts is the same candidate.
        let key = |e: &Entry| -> (u32, [u32; 2]) {
            let c = if criteria.patch_based { NONE } else { e.curve };
            (c, e.versions)
        };
        // (curve, its charts, cache key)
        type Todo = (u32, [u32; 2], (u32, [u32; 2]));
        let todo: Vec<Todo> = top
            .iter()
            .filter(|e| !cache.contains_key(&key(e)))
            .map(|e| (e.curve, pair(&labels, &curves[e.curve as usize]), key(e)))
            .collect();
        let tested: Vec<Result<Test, AlgoError>> = todo
            .par_iter()
            .map(|&(ci, [a, b], _)| {
                let removed = removed_edges(&curves, ci, [a, b], &labels, criteria.patch_based);
                test(mesh, &members, [a, b], &cut, &removed, criteria, control)
            })
            .collect();
        for (t, (_, _, k)) in tested.into_iter().zip(todo) {
            cache.insert(k, t?);
            out.evaluations += 1;
        }
        control.progress(&Progress {
            stage: "merge".into(),
            iteration: out.log.len(),
            ..Progress::default()
        });
        let mut rest = top.into_iter();
        for e in rest.by_ref() {
            let ci = e.curve;
            let [a, b] = pair(&labels, &curves[ci as usize]);
            let t = &cache[&key(&e)];
            let accepted = t.refusal.is_none();
            out.log.push(Candidate {
                curve: ci,
                charts: [a, b],
                faces: t.faces,
                area_distortion_pct: t.measures.map(|m| m.0),
                l2_stretch: t.measures.map(|m| m.1),
                overlap: t.measures.map(|m| m.2),
                accepted,
                reason: t.refusal.clone(),
            });
            if !accepted {
                curves[ci as usize].state = State::Refused;
                continue;
            }
            // Step 9: b joins a.
            for e in removed_edges(&curves, ci, [a, b], &labels, criteria.patch_based) {
                cut[e as usize] = false;
            }
            let moved = std::mem::take(&mut members[b as usize]);
            for &f in &moved {
                labels[f as usize] = a;
            }
            members[a as usize].extend(moved);
            members[a as usize].sort_unstable();
            area[a as usize] += area[b as usize];
            area[b as usize] = 0.0;
            version[a as usize] = next_version;
            version[b as usize] = NONE;
            next_version += 1;
            // Step 10: the merged chart's curves.
            for (i, c) in curves.iter_mut().enumerate() {
                let [p, q] = pair(&labels, c);
                if c.edges.iter().all(|&e| !cut[e as usize]) {
                    c.state = State::Removed;
                    continue;
                }
                if p == q {
                    if c.state != State::Removed {
                        c.state = State::Dangling;
                    }
                    continue;
                }
                if p != a && q != a {
                    continue;
                }
                if c.state == State::Refused && criteria.retry_rejected {
                    c.state = State::Pending;
                }
                if c.state == State::Pending {
                    heap.push(Entry {
                        key: area[p as usize] + area[q as usize],
                        length: c.length,
                        curve: i as u32,
                        versions: [version[p as usize], version[q as usize]],
                    });
                }
            }
            break;
        }
        heap.extend(rest);
    }
    for c in &curves {
        if c.state == State::Dangling {
            out.dangling.extend(c.edges.iter().copied());
        }
    }
    out.dangling.sort_unstable();
    let ef = mesh.conn().edge_faces();
    out.cut = (0..cut.len() as u32)
        .filter(|&e| cut[e as usize] && ef[e as usize][1] != NONE)
        .collect();
    out.labels = labels;
    Ok(out)
}

/// Whether each mesh edge is cut: every edge except those between two faces of one chart
/// (edges between patches, with `keep_patches`, and on the free boundary are always cut).
fn cut_edges(mesh: &Mesh, dual: &Dual, labels: &[u32]) -> Vec<bool> {
    let mut cut = vec![true; mesh.conn().edges().len()];
    for f in 0..dual.len() {
        for (g, e) in dual.arcs(f) {
            if labels[f] == labels[g] {
                cut[e] = false;
            }
        }
    }
    cut
}

/// The faces of each chart 0..k, ascending.
fn members_of(labels: &[u32], k: usize) -> Vec<Vec<u32>> {
    let mut members = vec![Vec::new(); k];
    for (f, &l) in labels.iter().enumerate() {
        members[l as usize].push(f as u32);
    }
    members
}

/// Split every chart that does not pass the test on its own (VSA charts are only nearly
/// planar: a ring round a limb, or a chart VSA left over its tolerance at `max_charts`, may
/// not flatten within the bounds), in two by [`vsa::split`], until all pass. Merging tests
/// only unions, so without this a chart nothing merged with could end outside the bounds.
/// Returns the chart count and the number of splits.
pub fn split_until_within(
    mesh: &Mesh,
    dual: &Dual,
    labels: &mut [u32],
    k: usize,
    criteria: &Criteria,
    control: &dyn Control,
) -> Result<(usize, usize), AlgoError> {
    let mut cut = cut_edges(mesh, dual, labels);
    let mut members = members_of(labels, k);
    let mut todo: Vec<u32> = (0..k as u32).collect();
    let mut splits = 0;
    while !todo.is_empty() {
        if control.cancelled() {
            return Err(AlgoError::Cancelled);
        }
        let tests: Vec<Result<Test, AlgoError>> = todo
            .par_iter()
            .map(|&c| {
                evaluate(
                    mesh,
                    members[c as usize].clone(),
                    &cut,
                    &[],
                    criteria,
                    control,
                )
            })
            .collect();
        let mut next = Vec::new();
        for (&c, t) in todo.iter().zip(tests) {
            if t?.refusal.is_none() || members[c as usize].len() < 2 {
                continue;
            }
            let part = vsa::split(dual, &members[c as usize]);
            let new = members.len() as u32;
            let faces = std::mem::take(&mut members[c as usize]);
            let (mut keep, mut moved) = (Vec::new(), Vec::new());
            for (&f, &p) in faces.iter().zip(&part) {
                if p {
                    moved.push(f);
                } else {
                    keep.push(f);
                }
            }
            for &f in &moved {
                labels[f as usize] = new;
            }
            for &f in &moved {
                for (g, e) in dual.arcs(f as usize) {
                    cut[e] = labels[g] != labels[f as usize];
                }
            }
            members[c as usize] = keep;
            members.push(moved);
            next.push(c);
            next.push(new);
            splits += 1;
        }
        todo = next;
    }
    Ok((members.len(), splits))
}

/// Slit edges (`slits`, both faces in one chart) that splitting vertices cannot open: both
/// ends are inside the chart (a closed fan of its faces) with no other slit edge. Such a
/// one-edge slit is zipped, in the test and in the output alike: no mesh can hold it open.
pub fn isolated_slits(mesh: &Mesh, chart_of: impl Fn(usize) -> u32, slits: &[u32]) -> HashSet<u32> {
    let conn = mesh.conn();
    let mut degree: HashMap<u32, u32> = HashMap::new();
    for &e in slits {
        for v in conn.edges()[e as usize] {
            *degree.entry(v).or_default() += 1;
        }
    }
    let tip = |v: u32, c: u32| {
        degree[&v] == 1
            && conn.kind(v) != VertexKind::Boundary
            && conn
                .fan_of(v)
                .iter()
                .all(|&h| chart_of((h / 3) as usize) == c)
    };
    slits
        .iter()
        .copied()
        .filter(|&e| {
            let c = chart_of(conn.edge_faces()[e as usize][0] as usize);
            conn.edges()[e as usize].iter().all(|&v| tip(v, c))
        })
        .collect()
}

/// The edges a merge along curve `ci` removes: its own, or with `patch_based` every curve's
/// between the same two charts.
fn removed_edges(
    curves: &[Curve],
    ci: u32,
    charts: [u32; 2],
    labels: &[u32],
    patch_based: bool,
) -> Vec<u32> {
    if !patch_based {
        return curves[ci as usize].edges.clone();
    }
    curves
        .iter()
        .filter(|c| {
            let (a, b) = (labels[c.sides[0] as usize], labels[c.sides[1] as usize]);
            [a.min(b), a.max(b)] == charts
        })
        .flat_map(|c| c.edges.iter().copied())
        .collect()
}

/// Steps 4–8 for the union of two charts with `removed` no longer cut.
fn test(
    mesh: &Mesh,
    members: &[Vec<u32>],
    [a, b]: [u32; 2],
    cut: &[bool],
    removed: &[u32],
    criteria: &Criteria,
    control: &dyn Control,
) -> Result<Test, AlgoError> {
    let mut faces: Vec<u32> = members[a as usize]
        .iter()
        .chain(&members[b as usize])
        .copied()
        .collect();
    faces.sort_unstable();
    evaluate(mesh, faces, cut, removed, criteria, control)
}

/// Flatten the chart made of `faces`, cut along `cut` except `removed`, and judge it.
fn evaluate(
    mesh: &Mesh,
    faces: Vec<u32>,
    cut: &[bool],
    removed: &[u32],
    criteria: &Criteria,
    control: &dyn Control,
) -> Result<Test, AlgoError> {
    let refuse = |why: String| Test {
        faces: faces.len(),
        measures: None,
        refusal: Some(why),
    };
    let removed: HashSet<u32> = removed.iter().copied().collect();
    let conn = mesh.conn();
    let inside: HashSet<u32> = faces.iter().copied().collect();
    let mut slits = Vec::new();
    for &f in &faces {
        for i in 0..3 {
            let e = conn.edge_of(3 * f + i);
            let [g, h] = conn.edge_faces()[e as usize];
            if cut[e as usize]
                && !removed.contains(&e)
                && h != NONE
                && inside.contains(&g)
                && inside.contains(&h)
                && f == g
            {
                slits.push(e);
            }
        }
    }
    let zipped = isolated_slits(mesh, |f| u32::from(!inside.contains(&(f as u32))), &slits);
    let cuts: HashSet<(u32, u32)> = slits
        .iter()
        .filter(|e| !zipped.contains(e))
        .map(|&e| {
            let [p, q] = conn.edges()[e as usize];
            (p.min(q), p.max(q))
        })
        .collect();
    let piece = match Piece3::build_cut(
        format!("chart of face {}", faces[0]),
        faces.clone(),
        mesh.triangles(),
        mesh.positions(),
        &cuts,
    ) {
        Ok(p) => p,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => return Ok(refuse(format!("topology: {e}"))),
    };
    if piece.loops.is_empty() {
        return Ok(refuse("topology: closed (no boundary loop)".into()));
    }
    let (flat, _) = match flatten::flatten_piece(&piece, &criteria.flatten, control) {
        Ok(r) => r,
        Err(AlgoError::Cancelled) => return Err(AlgoError::Cancelled),
        Err(e) => return Ok(refuse(format!("flattening failed: {e}"))),
    };
    let get = |k: &str| flat.measures.get(k).and_then(|v| v.as_f64());
    let (Some(area), Some(l2), Some(overlap)) = (
        get("area_distortion_pct"),
        get("l2_stretch"),
        get("overlap"),
    ) else {
        return Ok(refuse("flattening gave no measures".into()));
    };
    let overlap = overlap as u8;
    let refusal = if area.is_nan() || area.abs() > criteria.max_area_distortion {
        Some(format!(
            "area distortion {area:.2} % exceeds {} %",
            criteria.max_area_distortion
        ))
    } else if l2.is_nan() || l2 > criteria.max_l2_stretch {
        Some(format!(
            "L2 stretch {l2:.3} exceeds {}",
            criteria.max_l2_stretch
        ))
    } else if criteria.reject_overlap && overlap != 0 {
        Some("the flattening overlaps itself".into())
    } else {
        None
    };
    Ok(Test {
        faces: faces.len(),
        measures: Some((area, l2, overlap)),
        refusal,
    })
}

/// The boundary curves between charts.
fn find_curves(mesh: &Mesh, dual: &Dual, labels: &[u32]) -> Vec<Curve> {
    let conn = mesh.conn();
    let edges = conn.edges();
    let ef = conn.edge_faces();
    // Inter-chart edges and their chart pair.
    let mut pair_of: HashMap<u32, [u32; 2]> = HashMap::new();
    for f in 0..dual.len() {
        for (g, e) in dual.arcs(f) {
            let (a, b) = (labels[f], labels[g]);
            if a != b {
                pair_of.insert(e as u32, [a.min(b), a.max(b)]);
            }
        }
    }
    let mut at: HashMap<u32, Vec<u32>> = HashMap::new();
    let mut ids: Vec<u32> = pair_of.keys().copied().collect();
    ids.sort_unstable();
    for &e in &ids {
        for v in edges[e as usize] {
            at.entry(v).or_default().push(e);
        }
    }
    // A chain passes through v only when v has exactly two such edges of one pair and is
    // not on the mesh boundary or a seam.
    let through = |v: u32, e: u32| -> Option<u32> {
        if conn.kind(v) != VertexKind::Interior {
            return None;
        }
        let list = &at[&v];
        if list.len() != 2 {
            return None;
        }
        let o = if list[0] == e { list[1] } else { list[0] };
        (pair_of[&o] == pair_of[&e]).then_some(o)
    };
    let mut seen: HashSet<u32> = HashSet::new();
    let mut curves = Vec::new();
    for &e0 in &ids {
        if seen.contains(&e0) {
            continue;
        }
        seen.insert(e0);
        // Walk away from each end of e0; the chain is the backward walk reversed, e0, then
        // the forward walk.
        let mut walks = [Vec::new(), Vec::new()];
        for (walk, start) in walks.iter_mut().zip(edges[e0 as usize]) {
            let (mut v, mut e) = (start, e0);
            while let Some(o) = through(v, e) {
                if !seen.insert(o) {
                    break;
                }
                walk.push(o);
                let [p, q] = edges[o as usize];
                v = if p == v { q } else { p };
                e = o;
            }
        }
        let [mut chain, forward] = walks;
        chain.reverse();
        chain.push(e0);
        chain.extend(forward);
        let length = chain.iter().map(|&e| dual.edge_length[e as usize]).sum();
        let [f, g] = ef[e0 as usize];
        curves.push(Curve {
            edges: chain,
            sides: [f, g],
            length,
            state: State::Pending,
        });
    }
    curves
}
