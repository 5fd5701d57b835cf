//! Step 1: error-controlled variational shape approximation (Cohen-Steiner, Alliez & Desbrun
//! 2004, with the L^{2,1} metric; wang-lpfb Sec. 2 step 1).
//!
//! A proxy is a unit normal N_i; a face's error against it is e(T, P_i) = |T|·‖n_T − N_i‖²
//! and a chart's error E(R_i) = Σ e. Partition: one priority queue of (e, face, proxy) flooded
//! from each proxy's seed face, a face joining the first proxy that reaches it (so charts stay
//! connected). Fit: N_i = normalise(Σ |T| n_T), the exact L^{2,1} minimiser; the new seed is
//! the lowest-error face of the chart. Lloyd alternates the two until the labels repeat or
//! `lloyd_iterations`.
//!
//! Error control (the paper: "incrementally add more seeds … until the maximal approximation
//! error max L^{2,1} on all charts is less than a given tolerance", no value given): the
//! tolerance is relative, max_i E(R_i)/A_total ≤ `vsa_tolerance` (paper-notes D.4: 5e-4 gives
//! the paper's tens of charts). Each round adds a seed at the worst face of **every** chart
//! over the tolerance, worst chart first, not only of the worst one: one seed per round needs
//! as many Lloyd runs as charts (minutes at 50k faces), and the merge step that follows
//! removes any surplus the wider insertion makes. Every connected component starts with its
//! own seed.

use super::dual::{components, Dual};
use crate::algorithms::{AlgoError, Control, Progress};
use crate::mesh::NONE;
use std::collections::BinaryHeap;

/// What VSA produced.
#[derive(Debug, Clone)]
pub struct Vsa {
    /// Chart of every face.
    pub labels: Vec<u32>,
    /// Proxy normal of every chart.
    pub proxies: Vec<[f64; 3]>,
    /// E(R_i) / A_total of every chart.
    pub errors: Vec<f64>,
    /// Lloyd iterations over all rounds.
    pub lloyd_iterations: usize,
    /// Seed-insertion rounds.
    pub rounds: usize,
}

/// Face error e(T, P) = |T|·‖n_T − N‖².
#[inline]
pub fn face_error(dual: &Dual, f: usize, n: [f64; 3]) -> f64 {
    let m = dual.normal[f];
    let d = [m[0] - n[0], m[1] - n[1], m[2] - n[2]];
    dual.area[f] * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
}

/// Error-controlled VSA of the faces of `dual`.
pub fn run(
    dual: &Dual,
    tolerance: f64,
    max_charts: usize,
    lloyd_iterations: usize,
    control: &dyn Control,
) -> Result<Vsa, AlgoError> {
    let nf = dual.len();
    let total: f64 = dual.area.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let (comp, ncomp) = components(dual, |_, _| true);
    let mut seeds: Vec<usize> = vec![usize::MAX; ncomp];
    for (f, &c) in comp.iter().enumerate() {
        let c = c as usize;
        if seeds[c] == usize::MAX {
            seeds[c] = f;
        }
    }
    let mut proxies: Vec<[f64; 3]> = seeds.iter().map(|&s| dual.normal[s]).collect();
    let mut labels = vec![NONE; nf];
    let mut out = Vsa {
        labels: Vec::new(),
        proxies: Vec::new(),
        errors: Vec::new(),
        lloyd_iterations: 0,
        rounds: 0,
    };
    let mut heap = BinaryHeap::new();
    loop {
        // Lloyd at the current chart count.
        let mut previous: Vec<u32> = Vec::new();
        for _ in 0..lloyd_iterations.max(1) {
            if control.cancelled() {
                return Err(AlgoError::Cancelled);
            }
            flood(dual, &seeds, &proxies, &|_| true, &mut labels, &mut heap);
            out.lloyd_iterations += 1;
            fit(dual, &labels, &mut proxies, &mut seeds);
            if labels == previous {
                break;
            }
            previous.clone_from(&labels);
        }
        let errors = chart_errors(dual, &labels, &proxies, total);
        control.progress(&Progress {
            stage: "vsa".into(),
            iteration: out.rounds,
            ..Progress::default()
        });
        let mut over: Vec<usize> = (0..proxies.len())
            .filter(|&i| errors[i] > tolerance)
            .collect();
        if over.is_empty() || proxies.len() >= max_charts {
            out.errors = errors;
            break;
        }
        over.sort_by(|&a, &b| errors[b].total_cmp(&errors[a]).then(a.cmp(&b)));
        over.truncate(max_charts - proxies.len());
        let worst = worst_faces(dual, &labels, &proxies, &seeds);
        let before = seeds.len();
        for i in over {
            if let Some(f) = worst[i] {
                seeds.push(f);
                proxies.push(dual.normal[f]);
            }
        }
        out.rounds += 1;
        if seeds.len() == before {
            // Every chart over the tolerance is a single face: nothing left to split.
            out.errors = errors;
            break;
        }
    }
    out.labels = labels;
    out.proxies = proxies;
    Ok(out)
}

/// Heap entry: error, face and proxy packed in one integer so that the lowest error pops
/// first, ties by face then proxy (an error is ≥ 0, so its bits order as it does). One
/// integer comparison instead of three: flooding was 18 % of segmenting a 34k-face scan.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
struct Entry(std::cmp::Reverse<u128>);

impl Entry {
    fn new(error: f64, face: usize, proxy: u32) -> Entry {
        let bits = if error > 0.0 { error.to_bits() } else { 0 };
        Entry(std::cmp::Reverse(
            (u128::from(bits) << 64) | (u128::from(face as u32) << 32) | u128::from(proxy),
        ))
    }
    fn face(&self) -> usize {
        (self.0 .0 >> 32) as u32 as usize
    }
    fn proxy(&self) -> u32 {
        self.0 .0 as u32
    }
}

/// The flooding partition from `seeds` with proxies `proxies`, over the faces `inside`
/// accepts (the others stay `NONE`).
fn flood(
    dual: &Dual,
    seeds: &[usize],
    proxies: &[[f64; 3]],
    inside: &dyn Fn(usize) -> bool,
    labels: &mut [u32],
    heap: &mut BinaryHeap<Entry>,
) {
    labels.fill(NONE);
    heap.clear();
    for (i, &s) in seeds.iter().enumerate() {
        labels[s] = i as u32;
    }
    for (i, &s) in seeds.iter().enumerate() {
        for (g, _) in dual.arcs(s) {
            if labels[g] == NONE && inside(g) {
                heap.push(Entry::new(face_error(dual, g, proxies[i]), g, i as u32));
            }
        }
    }
    while let Some(e) = heap.pop() {
        let (f, i) = (e.face(), e.proxy());
        if labels[f] != NONE {
            continue;
        }
        labels[f] = i;
        for (g, _) in dual.arcs(f) {
            if labels[g] == NONE && inside(g) {
                heap.push(Entry::new(face_error(dual, g, proxies[i as usize]), g, i));
            }
        }
    }
}

/// Refit every proxy to its chart and move its seed to the chart's lowest-error face (faces
/// labelled `NONE` belong to no chart).
fn fit(dual: &Dual, labels: &[u32], proxies: &mut [[f64; 3]], seeds: &mut [usize]) {
    let k = proxies.len();
    let mut sum = vec![[0.0f64; 3]; k];
    for (f, &l) in labels.iter().enumerate().filter(|(_, &l)| l != NONE) {
        let (n, a) = (dual.normal[f], dual.area[f]);
        for c in 0..3 {
            sum[l as usize][c] += a * n[c];
        }
    }
    for (p, s) in proxies.iter_mut().zip(&sum) {
        let n = crate::geometry::normalize(*s);
        // A chart whose normals cancel (a closed fold) keeps its previous proxy.
        if n != [0.0; 3] {
            *p = n;
        }
    }
    let mut best = vec![(f64::INFINITY, usize::MAX); k];
    for (f, &l) in labels.iter().enumerate().filter(|(_, &l)| l != NONE) {
        let e = face_error(dual, f, proxies[l as usize]);
        let b = &mut best[l as usize];
        if e < b.0 {
            *b = (e, f);
        }
    }
    for (s, b) in seeds.iter_mut().zip(best) {
        if b.1 != usize::MAX {
            *s = b.1;
        }
    }
}

/// E(R_i) / A_total of every chart.
pub fn chart_errors(dual: &Dual, labels: &[u32], proxies: &[[f64; 3]], total: f64) -> Vec<f64> {
    let mut e = vec![0.0; proxies.len()];
    for (f, &l) in labels.iter().enumerate() {
        e[l as usize] += face_error(dual, f, proxies[l as usize]);
    }
    e.iter().map(|x| x / total).collect()
}

/// The highest-error face of every chart other than its seed (`None` for a one-face chart).
fn worst_faces(
    dual: &Dual,
    labels: &[u32],
    proxies: &[[f64; 3]],
    seeds: &[usize],
) -> Vec<Option<usize>> {
    let mut worst = vec![(f64::NEG_INFINITY, None); proxies.len()];
    for (f, &l) in labels.iter().enumerate() {
        if seeds[l as usize] == f {
            continue;
        }
        let e = face_error(dual, f, proxies[l as usize]);
        let w = &mut worst[l as usize];
        if e > w.0 {
            *w = (e, Some(f));
        }
    }
    worst.into_iter().map(|w| w.1).collect()
}

/// Two-proxy VSA inside one chart (`faces`, connected): seeds at the chart's lowest- and
/// highest-error faces against its own proxy, [`flood`] and [`fit`] within the chart, at most
/// ten Lloyd iterations. Returns, per face of `faces`, whether it went to the second part;
/// both parts are connected and non-empty.
pub fn split(dual: &Dual, faces: &[u32]) -> Vec<bool> {
    let mut inside = vec![false; dual.len()];
    let mut sum = [0.0f64; 3];
    for &f in faces {
        inside[f as usize] = true;
        let (n, a) = (dual.normal[f as usize], dual.area[f as usize]);
        for c in 0..3 {
            sum[c] += a * n[c];
        }
    }
    let proxy = crate::geometry::normalize(sum);
    let err = |f: u32| face_error(dual, f as usize, proxy);
    let lo = faces
        .iter()
        .copied()
        .min_by(|&a, &b| err(a).total_cmp(&err(b)).then(a.cmp(&b)));
    let hi = faces
        .iter()
        .copied()
        .max_by(|&a, &b| err(a).total_cmp(&err(b)).then(b.cmp(&a)));
    let (Some(lo), Some(mut hi)) = (lo, hi) else {
        return vec![false; faces.len()];
    };
    if hi == lo {
        hi = *faces.iter().find(|&&f| f != lo).unwrap_or(&lo);
    }
    let mut seeds = [lo as usize, hi as usize];
    let mut proxies = [dual.normal[seeds[0]], dual.normal[seeds[1]]];
    let mut labels = vec![NONE; dual.len()];
    let mut heap = BinaryHeap::new();
    for _ in 0..10 {
        flood(
            dual,
            &seeds,
            &proxies,
            &|f| inside[f],
            &mut labels,
            &mut heap,
        );
        let before = seeds;
        fit(dual, &labels, &mut proxies, &mut seeds);
        if seeds == before {
            break;
        }
    }
    faces.iter().map(|&f| labels[f as usize] == 1).collect()
}
