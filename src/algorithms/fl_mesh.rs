//! The `fl-mesh` job: the closest fair surface whose interior vertices are all flattenable
//! (wang-flattenable-laplacian-meshes, Sec. 2.3), by sequential linearly constrained
//! programming on the KKT system of Eq. 7.
//!
//! Unknowns are the positions of the interior vertices (whole closed fan in one patch);
//! boundary and seam vertices are never written, so they stay bit-identical. Beyond the
//! paper, `seams = free` makes the seam vertices unknowns too, without a constraint of their
//! own: their rows in Eq. 7 keep θ at 2π, ∂θ at 0 and a (2,2) entry of −1, so λ = 0 there
//! and they move only through the fairness and closeness terms and the constraints of the
//! interior vertices around them; the patches stay welded. A sewn cut's vertices (a slit
//! opened by `patches = uv`) share one row, their rings make its J_fair, and each trial puts
//! them where it puts that row's vertex, so the cut stays closed (see [`Seams`], [`run`]).
//!
//! Each iteration assembles Eq. 7 with H of Eq. 10 (w1 = 1, w2 = 0.1 by default), B_p of
//! Eq. 8, B_λ of Eq. 9 and Λ = ∂θ/∂v of Eq. 11 from Propositions 1 and 2, factors it (faer's
//! sparse LDLᵀ of the quasi-definite system by default, or its sparse LU; the symbolic
//! factorisation is computed once per mesh, only the numeric one every iteration) and solves
//! for δ and λ.
//!
//! Beyond the paper:
//! - Never worse. Every iterate is compared with the best so far by ϖ_max (among flattenable
//!   iterates the latest wins, so `until = stationary` still ends at its stationary point);
//!   the best is returned and `best_iteration` says which it was (0: the input). Over
//!   refinement rounds likewise: a round whose refinement did not lower ϖ_max is dropped and
//!   the mesh before it returned. So ϖ_max(out) ≤ ϖ_max(in) always (tests/fl_mesh_corpus.rs
//!   checks it on every real mesh, the procedural corpus and random and adversarial inputs).
//! - Step length. The paper always moves by τδ with τ = 0.25 (`step_rule = "fixed"` does
//!   that). The default `step_rule = "merit"` tries the full step first, shrinking the
//!   tangential part and then the normal one, and accepts the first trial that lowers
//!   ‖2π − θ‖₂ by the Armijo rule; when none does it takes the trial with the lowest ϖ_max
//!   (non-monotone, which lets it cross ridges of ‖2π − θ‖; safe since the best iterate is
//!   kept) and shifts the (2,2) block harder. `step_rule = "lm"` is monotone
//!   Levenberg–Marquardt: the (2,2) block −μ I makes the normal step minimise
//!   ‖2π − θ − Λδ‖² + μ δᵀHδ, μ follows Nielsen's rule on the ratio of actual to predicted
//!   decrease of ‖2π − θ‖², a refused step doubles the factor. On the corpus (issue 12 note)
//!   it converges less often than `merit`: its steps are accurate (ratio ≈ 1) but too short
//!   to leave the shallow valleys of ‖2π − θ‖ the non-monotone rule jumps out of.
//! - Shape guard (`shape_guard`, off by default). A trial that folds an edge (adjacent
//!   normals turning by more than 120°, `geometry::FOLD_ANGLE`) that was not folded, or leaves
//!   a corner below `min_angle` (a face that came in smaller may not get smaller), is refused
//!   like a degenerate one; with `lm`, the rows of an edge that kept folding are stiffened
//!   (H scaled by √(s_r s_j), ×4 per refusal) so the next step spreads the change. Measured
//!   on the corpus this keeps every output fold-free but stalls most garments between 1e-3 and
//!   1 rad: the normal steps of Eq. 7 reach θ = 2π by creasing the surface, and refusing the
//!   crease leaves no descent direction (measured without the shape penalty below, which
//!   puts the guard into the model instead).
//! - Shape penalty (`shape_penalty` κ = 1 by default; 0 is the paper's model).
//!   ½ κ h̄² (Σ_e (φ_e − φ⁰_e)₊² + Σ_c (α⁰_c − α_c)₊²): φ_e the turning angle between the
//!   normals across edge e, above φ⁰_e = max(60°, the input's φ_e), and α_c a corner angle,
//!   below α⁰_c = min(10°, the input's α_c). So the model itself, not a refusal, resists
//!   creasing and slivers. Its force enters the normal right-hand side and the diagonal of
//!   its Gauss–Newton Hessian is added to H (the couplings between a hinge's or a triangle's
//!   vertices are dropped to keep H's pattern; the line search makes up for them). It
//!   vanishes wherever no edge turns past its onset and no corner closes below its onset, so
//!   Eq. 3's solutions of that kind stay solutions. Measured on the 62-case corpus (issue 12
//!   note), against κ = 0 with the same budget: converged 35 → 40, new folds (> 120°)
//!   1197 → 130 (cases with any 21 → 10), but new creases (> 60°) 4238 → 7934: the penalty
//!   moves the creasing below its onset rather than removing it, and being soft it does not
//!   keep every corner above 10° (t-shirt: 0.07°). It needs the longer stall window (40) and
//!   iteration budget (600), since resisting a crease slows ϖ_max's fall. When the penalised
//!   run does not converge, [`solve`] runs the paper's model from the input with the rest of
//!   the budget and keeps its result if it converged, or if it got ϖ_max lowest without new
//!   folds or corners below the floor; if it converged with new folds, the paper's model runs
//!   again from the penalised result and is kept if it converges with fewer.
//! - Step radius (`step_radius`, merit rule, default 0.5 mean edge lengths; 0 = the full step
//!   however long, as before). Near flat caps ∂θ is small, so the least-norm normal step that
//!   the linearisation asks for grows to several edge lengths (5–7 h̄ on dome-7700-0.01 when it
//!   stalled) while it lowers ‖2π − θ‖ by a few per cent; scaling every trial down to the
//!   radius keeps the step where θ's linearisation holds. Measured on the 62-case corpus
//!   (issue 12 note): converged 40 → 43, converged without new folds 32 → 38
//!   (bff_hemisphere, fixture-cube_cuts, dome-7700-0.01 and mh_female_casualsuit02 newly;
//!   mh_female_sportsuit01 no longer, 2.0e-3); radius 1 gave 42 and 36, 0.25 was worse on
//!   the cases tried. Long non-monotone runs are chaotic (a rounding-level change of the
//!   radius's arithmetic took saddle-7700-0.1 from 109 to 397 iterations), so compare
//!   corpus totals, not single meshes. An
//!   adaptive trust region (radius doubled after a full step, cut after a shortened one) was
//!   measured worse: every case tried stalled, the steps too short to leave the shallow
//!   valleys the non-monotone rule jumps out of. `perturb` keeps 0 (not measured there).
//! - Corrections. After a step (merit rule), up to four re-solves of Eq. 7 with the same
//!   factorisation and right-hand side [0; h̄·(2π − θ)] at the new point, kept while each
//!   halves ‖2π − θ‖₂ (a second-order correction: the fairing part of a step is tangent to
//!   the constraints only to first order). A solve costs a fraction of a factorisation; on
//!   gf_skirt_3D_0 iterations fell from 21 to 9, on the t-shirt from 37 to 33. Only normal
//!   steps are added, so the fixed point is unchanged.
//! - Ordering. The factorisation keeps x, y, z and λ of a vertex together and orders the
//!   vertices by AMD on the mesh graph (`LdltSolver`'s groups): on ipc_skirt4K this ordering
//!   costs 8 ms instead of 28 ms and its numeric factorisation ~10% less than AMD on all 4n
//!   unknowns. A BFS-level-set nested dissection we tried gave 60% more fill.
//! - Fairing weight (`until = "flattenable"` only). The tangential (fairing) part of the step
//!   is halved whenever ϖ_max did not fall over an iteration. There the run stops at the first
//!   flattenable iterate, so the fairing only shapes the path; on the t-shirt it otherwise kept
//!   undoing the normal steps (ϖ_max oscillating near 5e-3). With `until = "stationary"` the
//!   full step is kept, so the paper's stationary point (B = 0) is what is reached.
//! - Shift. The (2,2) block is −μ I, μ from 1e-4 down to 1e-10: divided by 10 after a full
//!   step, kept after a step of ≥ 1/4, multiplied by 10 only when the linearisation failed.
//!   (Growing it on every shortened step held ϖ_max near 1e-2 on the t-shirt: the shifted
//!   normal step leaves a residual of about μ·λ.)
//! - Regularisation. The (2,2) block is −ε I with ε = 1e-10 (rows scaled by h̄ so that all
//!   blocks are O(1)). A planar vertex has ∂θ = 0 (θ is stationary at 2π), which would make
//!   Eq. 7 singular; the shift keeps it solvable and biases θ − 2π by at most ε·|λ|, far below
//!   the tolerance.
//! - Stop. Converged when ϖ_max ≤ `tolerance` (and, with `until = "stationary"`, also the
//!   paper's ‖δ‖ < `step_tolerance`, measured as max_v |δ_v| / h̄ so it does not depend on
//!   units or mesh size). A step below `step_tolerance` with ϖ_max above the tolerance, or
//!   ϖ_max not halving within `stall_iterations`, is a stall.
//! - Obstructions (Sec. 2.3). On a stall, interior vertices whose ϖ stayed among the highest
//!   (≥ 0.1 ϖ_max) for `stall_iterations` iterations get their fan refined √3-style (Kobbelt):
//!   each fan triangle is split at its centroid and the spokes are flipped, so the vertex is
//!   surrounded by new free vertices. New vertices are numbered after the existing ones. With
//!   `shape_guard`, a vertex whose refinement would create a corner below `min_angle` is not
//!   refined.
//!   After `max_refinements` rounds the run ends with `converged: false` and the stuck
//!   vertices named.
//! - Developable cone (`cone_start`, the `cone` module). A single disk whose fixed boundary
//!   admits no flattenable surface near the input (saddles, whose linearised constraint is a
//!   wave operator; domes, whose cap must come down to the boundary's hull) either stalls or
//!   converges by crumpling into mesh-sized pleats (saddle-7700-0.1: 994 edges turning past
//!   60°, looked at). The cone over its boundary from an
//!   apex with cone angle 2π (one always exists: Fenchel's lemma) is flattenable, and the
//!   run from it converges in 3–28 iterations on every noisy saddle and dome of the corpus
//!   with no folds, at a relative Hausdorff distance of 11 % (domes) to 18 % (saddles).
//!   `auto` (default) runs it first on a clearly curved disk — fitted total curvature
//!   (`fitted_curvature`: the median of local quartic fits' Gaussian curvature times the
//!   area, unbiased for the fit's noise) ≥ [`CONE_FIRST_DOME`] or ≤ −[`CONE_FIRST_SADDLE`]
//!   rad and 3 standard errors clear of zero — where the input's run was measured never to
//!   end better (saddles a(x² − y²)/2 from a = 0.7 and domes from a = 0.5, 2k–20k faces,
//!   noise 0.01–0.1: it stalled or crumpled, or converged farther than the cone), and is
//!   `fallback` otherwise; the cone's run then gets at most a third of the budget (where
//!   `auto` fired it converged in 12–26 iterations on the corpus, in up to 93 on the
//!   amplitude sweeps). Developable sheets (cylinder, cone, pleats; 7.7k–20k faces, noise up
//!   to 0.1) read at most 0.4 rad, and then within 1.2 standard errors of zero, so never
//!   pass; meshes too coarse to fit (≈ 60 vertices per neighbourhood of a quarter of the
//!   RMS radius, a few thousand faces) get no verdict.
//!   `fallback` runs it after the run from the input failed, and also after one
//!   that converged by crumpling (new creases past 60° on more than 1 % of the edges), whose
//!   result it then replaces if it creases less: the issue puts "never crumple it" before
//!   closeness, and a crumpled sheet is no shape to sew. `first` runs it before the input's;
//!   `never` not at all. Its result is kept only if flattenable with no new folds and no
//!   corner below min(`min_angle`, the input's smallest), or, unconverged, if it keeps those
//!   and no other run's result has a lower ϖ_max (likewise the paper's model's run below:
//!   "never worse" by ϖ_max first). Not with an obstacle, nor with
//!   `until = stationary` (from the cone those iterations drift back towards the input and
//!   lose flattenability: saddle-7700-0.01 7.5e-4, dome-7700-0.1 0.11). Measured on
//!   the 62-case corpus (issue 12 note): converged 43 → 49, converged without new folds
//!   38 → 44 (every saddle and dome), and the crumpled saddles (fixture-saddle,
//!   saddle-2000-*, saddle-7700-0.1: 44–989 new creases) come back smooth (≤ 10 creases)
//!   at 16–18 % instead of 2–5 % of the diagonal. No real mesh of ../shared is a height-field
//!   disk; the disks that are not (mh_shoes01's uppers, bff_face) get the cone through a
//!   harmonic layout (the `cone` module): the shoe's uppers converge from it (issue 12 note). Criterion medians, noisy
//!   saddles (0.01), defaults (`auto`, the cone first): 7.7k faces 0.44 s (14 iterations),
//!   45k faces 5.2 s (20); with `fallback`, which reaches the cone only after the input's
//!   run stalls, 5.1 s (181) at 7.7k. The noisy domes of 7.7k and 45k faces, which `auto`
//!   also starts from the cone: 0.3–0.4 s and 6.6–6.8 s (were 5.8 s and 52–53 s with
//!   `fallback`), at the same 11 % of the diagonal.
//!   Tried and dropped: disks that are no height field laid out by Tutte's embedding in
//!   the cone's development (bff_face: the start lands on the cone, but the run from it
//!   stalls at 1.4e-3 with every stuck vertex within 3 edge lengths of the apex).
//! - Obstacle ([`solve_clear_of`], used by `perturb`'s global method): every free vertex kept
//!   at least a clearance outside a body, one inequality row per vertex on the same fixed KKT
//!   pattern with an active set, every trial checked with the exact distance (`contact`).
//! - Unfolding (`unfold`, default on; [`open_new_folds`], the `unfold` module). The result's
//!   folds, then its faces with a corner below `min_angle`, that the input did not have are
//!   repaired one neighbourhood at a time along the constraints, keeping every interior vertex
//!   within max(tolerance / 2, where it was). On
//!   the shared garments they are isolated pinched hinges 5–12 rings inside the panels, not
//!   crease lines. Measured (issue 12 note, fl-mesh defaults; folds, then faces below 2°):
//!   t-shirt 18 → 4 and 2 → 0, pf_robert_shirt_14 129 → 23 and 3 → 5,
//!   mh_female_casualsuit02 214 → 85 and 24 → 23, mh_female_sportsuit01 18 → 3 and 12 → 9,
//!   gc_tee_sim 10 → 1, mh_classicshoes_medium 10 → 2 (its input has 12), the unconverged
//!   mh_male_worksuit01 13 → 3 and 12 → 8; ϖ_max stays ≤ 1e-6 on every converged one, for
//!   1.3–4.3 s more (t-shirt 3.2 → 4.5 s, casualsuit 5.7 → 10.0 s; single runs, 2-core EPYC).
//!   Since (issue 12 note of 2026-11-27: the retry from the penalised run, the length-free
//!   second attempt, sliver corners weighted 100): t-shirt 18 → 1 and 2 → 1, robert 20 → 1 and
//!   4 → 4, casualsuit 214 → 73 and 24 → 12, sportsuit 18 → 0 and 12 → 0, gc_tee_sim 10 → 0,
//!   classicshoes 10 → 2.
//! - Remeshing (`remesh`, default on; [`remesh_defects`], the `remesh` module). What unfolding
//!   leaves is mostly a bad choice of edges, not of positions: caps (a corner near 180°,
//!   whose long edge wants flipping), needles (two vertices nearly coincident, whose short
//!   edge wants collapsing) and overlapping hinges (whose edge wants the other diagonal). A
//!   flattenable result's remaining new folds and slivers are mended so, θ = 2π is solved
//!   again from there (the angle sums of the few vertices whose fans changed move) and
//!   unfolded, in up to [`FOLD_ROUNDS`] rounds, each kept only when the output is
//!   flattenable with fewer new folds plus slivers. A collapsed vertex stays in the output,
//!   unreferenced, at the position of the vertex it was merged into, so input vertex i is
//!   still output vertex i; texture coordinates are dropped once faces change, as with
//!   refinement. Measured (issue 12 note of 2026-11-27, defaults; new folds and faces below
//!   2° after unfolding → after remeshing): diffavatar_tshirt 1 and 1 → 0 and 0,
//!   pf_robert_shirt_14 1 and 4 → 0 and 0, mh_female_casualsuit02 73 and 12 → 8 and 5 (but
//!   its smallest corner 0.47° → 0.001°: a re-solve pressed a valence-3 vertex beside a
//!   remaining fold onto its neighbours' edge), and on
//!   unseen garments GarmentTransfer's t-shirt 0 and 3 → 0 and 0, its shirt likewise, its
//!   trousers 50 and 2 → 17 and 1; each re-solve took 0.2–0.5 s on these 3k-vertex meshes.
//!   An unconverged result is remeshed too, each round kept when it lowers ϖ_max (a refused
//!   round is tried once more with the slivers mended first): the stalled
//!   whole garments carry new caps, needles and near-folded fans, where θ's linearisation
//!   fails (on mh_female_elegantsuit01's stalled result a min-norm step scaled to 0.01 h̄
//!   moved θ by 0.5 rad at caps beside the openings). Measured (issue 12 note of
//!   2026-11-27, session 26; defaults, against the code before): mh_female_elegantsuit01
//!   4.4e-3 → 2.9e-3 (folds 28 → 9, smallest corner 0.01° → 2.39°), mh_male_elegantsuit01
//!   0.31 → 0.17 (folds 131 → 56); unseen MakeHuman suits: male casualsuit02 1.6e-2 →
//!   flattenable (47 folds → 2, smallest corner 2.19°), casualsuit01 1.4e-2 → 5.3e-3,
//!   casualsuit03 3.4e-3 → 6.6e-4, casualsuit05 1.4e-2 → 9.7e-3, mh_male_worksuit01 2.3e-2
//!   → 6.7e-3 (the last three only through the second order: slivers first alone lost
//!   casualsuit02's convergence, 2.6e-5); diffavatar_shirt_artist unchanged (both orders
//!   refused). The re-solves cost time: worksuit 36 → 75 s, casualsuit05 39 → 121 s,
//!   casualsuit01 114 → 245 s with its three kept rounds, shirt_artist 203 → 326 s for
//!   nothing. Without refinement in the re-solve the gains vanish (elegantsuit and
//!   casualsuit02 unchanged), so it keeps `refine`. Since develop's SQP (the detour below)
//!   shortens refused trials in place (2026-11-29), elegantsuit's round 1 re-solves to
//!   4.5e-3 and is refused (4.4e-3 stays; before, 2.2e-3 in three rounds); the other
//!   figures here were not measured again.
//! - Detour through develop's SQP (`detour`, default on; [`detour`]). Whole garments (a sphere
//!   with 3–11 holes, sleeves and legs joined to the body) stall with nearly every interior
//!   vertex at the same small excess θ > 2π (mh_female_elegantsuit01's top: 2219 of 2227
//!   vertices, ϖ 2–4e-3): by Gauss–Bonnet only the fixed openings can take that curvature up,
//!   and Eq. 7's normal steps no longer lower ‖2π − θ‖ there (probed on GarmentTransfer's
//!   t-shirt: the linearised violation after a full normal step was 0.999 of the violation,
//!   the damped system's answer to a nearly singular mean mode). Such a result is run
//!   through develop's SQP (boundary held) and fl-mesh once more from there; on unseen
//!   garments (issue 12 note of 2026-11-27) two of six stalled tops then converge, and ϖ_max
//!   falls on the rest (mh_male_worksuit01 0.145 → 2.3e-2). A second detour changed nothing
//!   on the two suits tried, so there is one.
//! - Closed components whose Euler characteristic χ ≠ 0 cannot become flattenable
//!   (Gauss–Bonnet: the angle defects sum to 2πχ); their vertices are held fixed and reported
//!   as stuck, and the run ends with `converged: false`.
//!
//! An already flattenable input (ϖ_max ≤ tolerance) is returned unchanged with the default
//! `until = "flattenable"`; with `until = "stationary"` it moves to the paper's optimum, i.e.
//! by exactly the fairing that w1 and w2 ask for while every constraint stays satisfied
//! (for a planar mesh: the solution of (w1 L + w2 I) v = w2 v⁰ in the plane).

// Index loops over xyz and rows read like the equations they implement.
#![allow(clippy::needless_range_loop)]

mod cone;
mod contact;
mod parts;

pub use cone::{cone_start, fitted_curvature, isoperimetric_excess, Curvature, NoCone};
pub use contact::{Keep, Obstacle};

use super::{AlgoError, Control, Outcome, Progress, Renamed};
use crate::geometry::{corner_angle, corner_angle_gradient};
use crate::linalg::{LdltSolver, LinalgError, LuSolver};
use crate::mesh::{cross, dot, sub, Mesh, RawMesh, VertexKind, NONE};
use contact::Contact;
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// Step-length rule (see the module doc).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StepRule {
    /// Armijo backtracking on the KKT-residual merit, full step first (default).
    #[default]
    Merit,
    /// The paper's fixed damping: X ← X + τδ (Algorithm 1).
    Fixed,
    /// Levenberg–Marquardt: μ of the (2,2) block from the ratio of actual to predicted
    /// decrease of ‖2π − θ‖²; monotone.
    Lm,
}

/// Where an fl-mesh job's seams come from: the patches are what must each be flattenable, and
/// their seams are held (see [`choose_patches`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Patches {
    /// `uv` when the file's texture layout cuts its patches into islands (at most
    /// [`MAX_AUTO_ISLANDS`]), else `file`.
    #[default]
    Auto,
    /// The file's patches (OBJ `o`/`g`, glTF primitives).
    File,
    /// One patch per texture-coordinate island, inside the file's patches.
    Uv,
}

/// What the seams between patches do while the patches' interiors are made flattenable.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Seams {
    /// `held`, and for the texture islands of a file of one patch that stall, or converge
    /// with more folds than the input, `free` too ([`run`]'s fallback; default).
    #[default]
    Auto,
    /// Held where they are, bit-identical (the paper's fixed boundary curves).
    Held,
    /// They move with the surface, welded (G0), with no constraint of their own: a seam
    /// vertex is on every one of its patches' boundaries, where ϖ is not defined. So do sewn
    /// cuts: boundary vertices at one position whose boundary edges all have a twin joining
    /// the same positions (a slit `patches = uv` opened, its tip and its end on a seam) move
    /// as one vertex. Only the free boundary is held.
    Free,
}

/// More islands than this look like a texture atlas rather than a sewing pattern (the real
/// garments and shoes have 3–23), so `patches=auto` keeps the file's patches.
pub const MAX_AUTO_ISLANDS: usize = 256;
/// Nor does a layout whose islands average fewer faces than this (one island per face holds
/// every vertex: nothing would be solved); the real ones average 150 and more.
pub const MIN_AUTO_ISLAND_FACES: usize = 16;

/// When to start from the developable cone over a disk's boundary (`cone` module).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ConeStart {
    /// First when the patch's smooth curvature is large enough that the input's run was
    /// measured never to end better (fitted total curvature ≥ [`CONE_FIRST_DOME`] or ≤
    /// −[`CONE_FIRST_SADDLE`] rad, and 3 standard errors clear of zero; that run gets at most
    /// a third of `max_iterations`), else as `fallback` (default).
    #[default]
    Auto,
    /// After the run from the input did not converge, or converged only by crumpling.
    Fallback,
    /// Before the run from the input, which then runs only if the cone's result is not
    /// accepted (not flattenable, more folds than the input, or a corner below the floor).
    First,
    /// Never.
    Never,
}

/// What v⁰ in J_pos (Eq. 5) is.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Anchor {
    /// The input position of each vertex (default).
    #[default]
    Input,
    /// The closest point to the current position on the input surface, recomputed each
    /// iteration.
    Closest,
}

/// When to stop iterating.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Until {
    /// As soon as ϖ_max ≤ tolerance (default).
    #[default]
    Flattenable,
    /// ϖ_max ≤ tolerance and the step below `step_tolerance` (the paper's optimum).
    Stationary,
}

/// Which factorisation solves Eq. 7.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LinearSolver {
    /// Sparse LU of Eq. 7 exactly as printed (H of Eq. 10 is not symmetric).
    Lu,
    /// Sparse LDLᵀ of Eq. 7 with H symmetrised as (w1 + w2) I − w1 D^{-1/2} A D^{-1/2}
    /// (similar to Eq. 10's H, identical on valence-regular meshes). The fixed point, and so
    /// the result's meaning, is unchanged: B_p and B_λ are the paper's; only the path differs.
    #[default]
    Ldlt,
}

/// Parameters of `fl-mesh`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Weight of the fairness term J_fair (Eq. 4).
    pub w1: f64,
    /// Weight of the position term J_pos (Eq. 5); must be much smaller than w1.
    pub w2: f64,
    /// Damping factor of Algorithm 1 (the fixed rule, and the merit rule's fallback).
    pub tau: f64,
    /// `merit` (default) or `fixed`.
    pub step_rule: StepRule,
    /// `input` (default) or `closest`.
    pub anchor: Anchor,
    /// `flattenable` (default) or `stationary`.
    pub until: Until,
    /// Target ϖ_max in radians.
    pub tolerance: f64,
    /// ‖δ‖ threshold, as max_v |δ_v| over the mean edge length.
    pub step_tolerance: f64,
    /// Most Newton iterations in total (over all refinement rounds).
    pub max_iterations: usize,
    /// Refine around stuck vertices (Sec. 2.3).
    pub refine: bool,
    /// Most refinement rounds.
    pub max_refinements: usize,
    /// Iterations without ϖ_max halving that count as a stall.
    pub stall_iterations: usize,
    /// `ldlt` (default) or `lu`.
    pub linear_solver: LinearSolver,
    /// Shape guard: refuse steps that fold an edge (adjacent normals turning by more than
    /// 120°) or leave a corner below `min_angle`. Off by default for now: the normal steps
    /// of Eq. 7 concentrate the change into creases, and refusing them stalls most garments
    /// (see the module doc).
    pub shape_guard: bool,
    /// Weight κ of the shape penalty on edges turning past max(60°, the input's turning) and
    /// corners closing below min(10°, the input's angle); 0 is the paper's model.
    pub shape_penalty: f64,
    /// With `shape_guard`: smallest corner angle, degrees, a step may leave in a triangle it
    /// moves (a triangle that came in with a smaller one is never made worse than it was).
    /// With the guard, refinement never creates a smaller corner either.
    pub min_angle: f64,
    /// Merit rule: the longest normal step tried, in mean edge lengths (a full step that asks
    /// for more is scaled down to it); 0 tries the full step however long.
    pub step_radius: f64,
    /// `auto` (default), `fallback`, `first` or `never`: when a disk is started from the
    /// developable cone over its boundary (see the module doc and the `cone` module).
    pub cone_start: ConeStart,
    /// A run that stalled (ended unconverged before `max_iterations`) is retried: its parts
    /// alone, then from the best result, each run with its own `max_iterations` (see
    /// [`solve`]).
    pub retry: bool,
    /// Repair the folds the run made (edges whose normals turn past 120° that the input did
    /// not fold), then its faces with a corner below `min_angle` that the input did not have,
    /// by moving their neighbourhoods along θ = 2π (the `unfold` module); and when the
    /// paper's model converged by folding after a stalled penalised run, run it again from
    /// the penalised result (see [`solve`]). Not with `until = stationary`, whose answer
    /// is the paper's stationary point.
    pub unfold: bool,
    /// A run that stalled (not one cut short by `max_iterations`) and is still unconverged
    /// after the retries is run through `develop`'s SQP (edge lengths kept, boundary and
    /// seams held) and fl-mesh once more from there, and replaced when that lowers ϖ_max
    /// (see [`solve`]). Not with `until = stationary`.
    pub detour: bool,
    /// The new folds and slivers a result still has after `unfold` are mended by flipping
    /// edges and collapsing needles (the `remesh` module), then θ = 2π is solved again from
    /// there; kept when that converges with fewer, or, on an unconverged result, when it
    /// lowers ϖ_max (see [`remesh_defects`]). A collapsed
    /// vertex stays in the output unreferenced, so the numbering holds. Not with
    /// `until = stationary`.
    pub remesh: bool,
    /// `auto` (default), `file` or `uv`: the seams of an fl-mesh job's input (see
    /// [`choose_patches`]). Only [`run`] reads it: [`solve`] (and so subdivide and segment)
    /// takes the mesh's patches as they are.
    pub patches: Patches,
    /// `auto` (default), `held` or `free`: whether the seams between patches move (see
    /// [`Seams`]). Only `free` frees them in [`solve`]; `auto` frees a stalled or folded run's
    /// islands in [`run`].
    pub seams: Seams,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            w1: 1.0,
            w2: 0.1,
            tau: 0.25,
            step_rule: StepRule::Merit,
            anchor: Anchor::Input,
            until: Until::Flattenable,
            tolerance: crate::geometry::DEVELOPABLE_TOLERANCE,
            step_tolerance: 1e-5,
            max_iterations: 600,
            refine: true,
            max_refinements: 3,
            stall_iterations: 40,
            linear_solver: LinearSolver::Ldlt,
            shape_guard: false,
            shape_penalty: 1.0,
            min_angle: 2.0,
            step_radius: 0.5,
            cone_start: ConeStart::Auto,
            retry: true,
            unfold: true,
            detour: true,
            remesh: true,
            patches: Patches::Auto,
            seams: Seams::Auto,
        }
    }
}

fn bad(key: &str, message: String) -> AlgoError {
    AlgoError::InvalidParam {
        key: key.into(),
        message,
    }
}

impl Params {
    /// Range checks.
    pub fn check(&self) -> Result<(), AlgoError> {
        if !(self.w1.is_finite() && self.w1 >= 0.0) {
            return Err(bad(
                "w1",
                format!("must be finite and ≥ 0, got {}", self.w1),
            ));
        }
        if !(self.w2.is_finite() && self.w2 > 0.0) {
            return Err(bad(
                "w2",
                format!(
                    "must be finite and > 0 (it keeps H regular), got {}",
                    self.w2
                ),
            ));
        }
        if !(self.tau > 0.0 && self.tau <= 1.0) {
            return Err(bad("tau", format!("must be in (0, 1], got {}", self.tau)));
        }
        if !(self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(bad(
                "tolerance",
                format!("must be in (0, 1) rad, got {}", self.tolerance),
            ));
        }
        if !(self.step_tolerance > 0.0 && self.step_tolerance < 1.0) {
            return Err(bad(
                "step_tolerance",
                format!("must be in (0, 1), got {}", self.step_tolerance),
            ));
        }
        if self.max_iterations == 0 || self.max_iterations > 100_000 {
            return Err(bad(
                "max_iterations",
                format!("must be in 1..=100000, got {}", self.max_iterations),
            ));
        }
        if !(self.shape_penalty.is_finite() && self.shape_penalty >= 0.0) {
            return Err(bad(
                "shape_penalty",
                format!("must be finite and ≥ 0, got {}", self.shape_penalty),
            ));
        }
        if !(self.min_angle >= 0.0 && self.min_angle < 60.0) {
            return Err(bad(
                "min_angle",
                format!("must be in [0, 60) degrees, got {}", self.min_angle),
            ));
        }
        if !(self.step_radius.is_finite() && self.step_radius >= 0.0) {
            return Err(bad(
                "step_radius",
                format!("must be finite and ≥ 0, got {}", self.step_radius),
            ));
        }
        if self.max_refinements > 20 {
            return Err(bad(
                "max_refinements",
                format!("must be in 0..=20, got {}", self.max_refinements),
            ));
        }
        if self.stall_iterations < 2 || self.stall_iterations > 1000 {
            return Err(bad(
                "stall_iterations",
                format!("must be in 2..=1000, got {}", self.stall_iterations),
            ));
        }
        Ok(())
    }
}

/// One row of the iteration history.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HistoryEntry {
    /// Iteration (1-based, counted over all refinement rounds).
    pub iteration: usize,
    /// ϖ_max before the step.
    pub max_flattenability: f64,
    /// max_v |δ_v| / h̄ of the full Newton direction.
    pub step_norm: f64,
    /// Step length taken (τ for the fixed rule).
    pub step_length: f64,
    /// Feasibility corrections taken after the step with the same factorisation.
    pub corrections: usize,
    /// Levenberg–Marquardt parameter μ of the (2,2) block for the next iteration.
    pub damping: f64,
}

/// What a run found, besides the mesh.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Report {
    /// Newton iterations taken (factorisations, rejected steps included).
    pub iterations: usize,
    /// The iteration whose iterate is returned (0: the input, or the developable cone's start
    /// when the stop reason says the result came from the cone): the best by ϖ_max, the
    /// latest among flattenable ones. After retries, that of the run last taken (a mesh kept
    /// part by part has one per part; this is then the whole run's).
    pub best_iteration: usize,
    /// ϖ_max ≤ tolerance on the output (and the step criterion, for `until = stationary`).
    pub converged: bool,
    /// Why the run ended.
    pub stop_reason: String,
    /// Per iteration.
    pub history: Vec<HistoryEntry>,
    /// Vertices whose fans were refined (ids in the numbering of the round they were refined
    /// in, which keeps all earlier ids).
    pub refined: Vec<u32>,
    /// Interior vertices with ϖ above the tolerance at the end.
    pub stuck_vertices: Vec<u32>,
    /// ϖ_max of the output, measured by `geometry`.
    pub max_flattenability: f64,
    /// ‖B_p − Λᵀλ‖∞ / h̄ at the last solve: how far from the paper's stationary point.
    pub stationarity: f64,
    /// Number of unknown (interior, free) vertices at the end.
    pub free_vertices: usize,
    /// When the whole run stalled, `retry` is on and the mesh has several independent parts
    /// (its patch components; see [`solve`]): each part's outcome, in patch order, then by
    /// first face. Empty otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<PartReport>,
    /// With `unfold`, when the run's result had folds or slivers the input did not: what
    /// repairing them did (the counts are the whole mesh's, the input's own included).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unfold: Option<super::unfold::Summary>,
    /// With `remesh`, when a result still had new folds or slivers after unfolding: what
    /// mending its connectivity did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub remesh: Option<RemeshReport>,
}

/// What [`remesh_defects`] did: its operations over all rounds and the new folds and
/// slivers (those the input did not have) before and after.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RemeshReport {
    /// Rounds whose result was kept (mend, re-solve, unfold).
    pub rounds: usize,
    /// Edges flipped, edges collapsed, and each collapse as [removed, kept].
    #[serde(flatten)]
    pub operations: super::remesh::Summary,
    /// New folds before the first round and after the last kept one.
    pub new_folds: [usize; 2],
    /// New faces with a corner below `min_angle`, likewise.
    pub new_slivers: [usize; 2],
    /// ϖ_max before the first round and after the last kept one.
    pub max_flattenability: [f64; 2],
    /// Why it stopped.
    pub stop_reason: String,
}

/// The outcome of one independent part of a mesh (a connected part of one patch).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PartReport {
    /// The part's patch name, `#k` appended when the patch has several parts (as `flatten`
    /// names its pieces).
    pub patch: String,
    /// Its faces in the input.
    pub faces: usize,
    /// Its interior (free) vertices in the input.
    pub interior_vertices: usize,
    /// Which result it kept: "whole" (the whole mesh's run), "alone" (its own run from the
    /// input) or "restart" (its run from the better of those two).
    pub kept: String,
    /// ϖ_max ≤ tolerance on the kept result.
    pub converged: bool,
    /// ϖ_max of the kept result.
    pub max_flattenability: f64,
    /// Iterations of its own runs (0 when it was flattenable in the whole run's result, or a
    /// closed component that cannot be).
    pub iterations: usize,
    /// Why its own runs ended ("" when there were none).
    pub stop_reason: String,
}

/// What `fl-mesh` reports: the solver's [`Report`] and the distance moved.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Summary {
    /// The solver's figures.
    #[serde(flatten)]
    pub report: Report,
    /// Hausdorff distance from the output to the input.
    pub hausdorff_to_input: super::Distance,
    /// The patches solved for and where they came from.
    pub patches: PatchesUsed,
}

/// The patches an fl-mesh or develop job solved for.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PatchesUsed {
    /// `file` or `uv`.
    pub source: String,
    /// How many.
    pub count: usize,
    /// Edges of the file's patches cut by the texture layout (0 without one).
    pub uv_seam_edges: usize,
    /// Vertices appended (copies) to open the cuts that end inside an island; the output's
    /// vertices after the input's (and before any refinement's) are these.
    pub opened_vertices: usize,
    /// Why this source.
    pub reason: String,
    /// `held` or `free`: what the seams between the patches did (see [`Seams`]).
    pub seams: String,
}

/// Run `fl-mesh`: on the patches `params.patches` chooses ([`choose_patches`]).
pub fn run(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<Outcome<Summary>, AlgoError> {
    params.check()?;
    let (work, mut patches) = choose_patches(mesh, params.patches)?;
    if params.seams == Seams::Free {
        patches.seams = "free".into();
    }
    let (mut out, mut report) = solve(&work, params, control)?;
    // Islands that stalled (a retry's rule: not a run cut short by max_iterations, whose
    // stop reason is that word, nor one asked for without retries) are solved again with
    // their seams free (`seams = auto`, [`free_seams`]); if still unconverged and chosen by
    // `patches = auto`, the file's patches are tried too, with a budget of their own, and
    // taken when they become flattenable. A failed or stopped later run keeps the result
    // before it.
    let stalled = !report.converged
        && params.retry
        && params.until == Until::Flattenable
        && !report.stop_reason.starts_with("max_iterations");
    let may_free = patches.source == "uv"
        && params.seams == Seams::Auto
        && mesh.num_patches() == 1
        && params.retry
        && params.until == Until::Flattenable;
    // Counted as the job's shape check counts them: the input as given against the output.
    let folds = |m: &Mesh| crate::geometry::fold_edges(m).len();
    let (folds_in, folds_out) = (folds(mesh), folds(&out));
    let w = report.max_flattenability;
    let lower = |_: &Mesh, r: &Report| {
        if r.converged {
            Some("it became flattenable".to_string())
        } else {
            (r.max_flattenability < w)
                .then(|| format!("it reached ϖ_max {:.2e}", r.max_flattenability))
        }
    };
    let fewer = |m: &Mesh, r: &Report| {
        let n = folds(m);
        (r.converged && n < folds_out).then(|| format!("it became flattenable with {n}"))
    };
    // What the held islands did that the free ones are asked to do better (a stall and a
    // converged run exclude each other, so at most one free run).
    let why: Option<(String, &Judge)> = if !may_free {
        None
    } else if stalled {
        Some((format!("it stalled at ϖ_max {w:.2e}"), &lower))
    } else if report.converged && folds_out > folds_in {
        let held = format!("it folded {folds_out} edges (the input {folds_in})");
        Some((held, &fewer))
    } else {
        None
    };
    if let Some((held, better)) = why {
        free_seams(
            &work,
            params,
            control,
            (&mut out, &mut report),
            &mut patches,
            (held.as_str(), better),
        );
    }
    if stalled && !report.converged && patches.source == "uv" && params.patches == Patches::Auto {
        let label = Renamed::before(control, "file patches".into());
        match solve(mesh, params, &label) {
            Ok((whole, whole_report)) if whole_report.converged => {
                patches = PatchesUsed {
                    source: "file".into(),
                    count: mesh.num_patches(),
                    reason: format!(
                        "by its {} texture islands it stalled at ϖ_max {:.2e}; by the file's \
                         {} patch(es) it became flattenable",
                        patches.count,
                        report.max_flattenability,
                        mesh.num_patches()
                    ),
                    opened_vertices: 0,
                    seams: if params.seams == Seams::Free {
                        "free"
                    } else {
                        "held"
                    }
                    .into(),
                    ..patches
                };
                out = whole;
                report = chain(report, whole_report, |a, b| {
                    format!("by the texture islands: {a}; by the file's patches: {b}")
                });
            }
            Ok((_, whole_report)) => {
                absorb(&mut report, &whole_report);
                let not = format!(
                    "the file's {} patch(es) did not become flattenable either (ϖ_max {:.2e}, \
                     {} iterations)",
                    mesh.num_patches(),
                    whole_report.max_flattenability,
                    whole_report.iterations
                );
                report.stop_reason = format!("{}; {not}", report.stop_reason);
                patches.reason = format!("{}; {not}", patches.reason);
            }
            Err(e) => {
                patches.reason = format!(
                    "{}; the file's patches were not tried ({e})",
                    patches.reason
                );
            }
        }
    }
    let hausdorff_to_input = super::Distance::hausdorff_reported(&out, mesh, control);
    Ok(Outcome {
        mesh: Some(out),
        patterns: None,
        summary: Summary {
            report,
            hausdorff_to_input,
            patches,
        },
        levels: Vec::new(),
    })
}

/// How [`free_seams`] judges the free run: what it did better, if it did.
type Judge<'a> = dyn Fn(&Mesh, &Report) -> Option<String> + 'a;

/// `seams = auto`: islands that stalled with their seams held are solved again from the input
/// with the seams free ([`Seams::Free`]: they move, welded, with no constraint of their own),
/// and that result is taken when it converged or lowered ϖ_max; islands that converged by
/// folding more edges than the input had are too, and the result is taken when it converged
/// with fewer (mh_female_casualsuit02: 2 folds held, 1 free as in the input; its smallest
/// corner 2.3° → 0.5°, the input's 1.0°). `held` says what the held run did, `better`
/// judges the free one.
///
/// Held first, because held seams keep the panels' outlines where the designer drew them and
/// the surface closer: on the 20 garments and shoes that converge by their islands either way (issue 12 note of
/// 2026-11-27), freeing the seams moved it farther on 15 (relative Hausdorff distance, e.g.
/// mh_shoes01 3.6 → 5.9 %) and less on 3, though it left fewer creases past 60° on 18 and a
/// larger smallest corner on 16. Where held islands stall, the seams are what the panels
/// needed to move: the unseen mh_shoes03 and mh_fedora converge with them free at 4.4 % and
/// 14 % of the diagonal moved, against 20 % and 26 % solved whole, and the unseen
/// mh_male_casualsuit05, which stalled every way, converges (3.6 %): its sleeves, bent tubes
/// whose seam was held, stalled. It costs a third run where everything stalls
/// (mh_male_elegantsuit01 377 s → 526 s). Only for a file of one patch, since the file's own
/// seams are always held. A failed or stopped run keeps the held result.
fn free_seams(
    work: &Mesh,
    params: &Params,
    control: &dyn Control,
    (out, report): (&mut Mesh, &mut Report),
    patches: &mut PatchesUsed,
    (held, better): (&str, &Judge<'_>),
) {
    let free = Params {
        seams: Seams::Free,
        ..params.clone()
    };
    let label = Renamed::before(control, "free seams".into());
    match solve(work, &free, &label) {
        Ok((again, second)) => match better(&again, &second) {
            Some(how) => {
                patches.seams = "free".into();
                patches.reason = format!(
                    "{}; with its seams held {held}, with them free {how}",
                    patches.reason
                );
                *out = again;
                *report = chain(std::mem::take(report), second, |a, b| {
                    format!("with the seams held: {a}; with the seams free: {b}")
                });
            }
            None => {
                absorb(report, &second);
                let not = format!(
                    "with its seams free it did no better (ϖ_max {:.2e}, {} iterations)",
                    second.max_flattenability, second.iterations
                );
                report.stop_reason = format!("{}; {not}", report.stop_reason);
                patches.reason = format!("{}; {not}", patches.reason);
            }
        },
        Err(e) => {
            patches.reason = format!("{}; its seams were not tried free ({e})", patches.reason);
        }
    }
}

/// The mesh whose patches fl-mesh makes flattenable. A garment is sewn from panels, and a
/// file from a design tool carries them as its texture layout's islands; solved whole instead,
/// a garment with sleeves or legs must push the curvature of its armpits and crotch into its
/// fixed openings (Gauss–Bonnet), and converges, if at all, by creasing all over (issue 12
/// note of 2026-11-27: diffavatar_tshirt whole 7.2 s, hd 8.6 %, 868 new creases; by its four
/// islands 0.4 s, hd 2.1 %; mh_female_elegantsuit01 stalls whole at 2.9e-3 and converges by
/// its islands in 0.6 s). `auto` takes the islands when the layout cuts the file's patches
/// and has at most [`MAX_AUTO_ISLANDS`] islands of [`MIN_AUTO_ISLAND_FACES`] faces or more on
/// average; `uv` requires a layout. ([`run`] also falls back to the file's patches when the
/// islands stall.)
pub fn choose_patches(mesh: &Mesh, wanted: Patches) -> Result<(Mesh, PatchesUsed), AlgoError> {
    use crate::mesh::islands;
    let file = |reason: String, seams: usize| {
        (
            mesh.clone(),
            PatchesUsed {
                source: "file".into(),
                count: mesh.num_patches(),
                uv_seam_edges: seams,
                opened_vertices: 0,
                reason,
                seams: "held".into(),
            },
        )
    };
    let found = match wanted {
        Patches::File => return Ok(file("asked for (patches=file)".into(), 0)),
        _ => islands::uv_islands(mesh),
    };
    let Some(found) = found else {
        if wanted == Patches::Uv {
            return Err(bad(
                "patches",
                "`uv` needs texture coordinates on every face, and the mesh has none".into(),
            ));
        }
        return Ok(file("the file has no texture coordinates".into(), 0));
    };
    let seams = found.seam_edges;
    if wanted == Patches::Auto {
        if seams == 0 {
            return Ok(file(
                "its texture layout cuts none of the file's patches".into(),
                0,
            ));
        }
        if found.count() > MAX_AUTO_ISLANDS
            || found.count() * MIN_AUTO_ISLAND_FACES > mesh.num_faces()
        {
            return Ok(file(
                format!(
                    "its texture layout has {} islands for {} faces: more than the \
                     {MAX_AUTO_ISLANDS} of a sewing pattern, or fewer than \
                     {MIN_AUTO_ISLAND_FACES} faces each on average (patches=uv takes them \
                     anyway)",
                    found.count(),
                    mesh.num_faces()
                ),
                seams,
            ));
        }
    }
    let cut = match islands::with_island_patches(mesh, &found) {
        Ok(cut) => cut,
        Err(e) if wanted == Patches::Auto => {
            return Ok(file(
                format!("its texture islands do not make a valid mesh ({e})"),
                seams,
            ))
        }
        Err(e) => {
            return Err(bad(
                "patches",
                format!("the texture islands do not make a valid mesh: {e}"),
            ))
        }
    };
    let opened = match cut.opened {
        0 => String::new(),
        n => format!(", {n} vertices split to open the cuts inside an island (a tube's seam)"),
    };
    let reason = match wanted {
        Patches::Uv => format!("asked for (patches=uv){opened}"),
        _ => format!(
            "the file's texture layout cuts it into {} islands along {seams} edges{opened}, \
             taken as its panels (patches=file solves the file's {} patch(es) instead)",
            found.count(),
            mesh.num_patches()
        ),
    };
    Ok((
        cut.mesh,
        PatchesUsed {
            source: "uv".into(),
            count: found.count(),
            uv_seam_edges: seams,
            opened_vertices: cut.opened,
            reason,
            seams: "held".into(),
        },
    ))
}

/// The solver proper: the output mesh (input vertices first, refinement vertices after) and
/// what happened.
///
/// With `cone_start = first`, a disk is first run from its developable cone; with
/// `fallback`, after the run from the input did not converge or converged only by crumpling;
/// with the default `auto`, first when it is clearly curved and as `fallback` otherwise (see
/// the module doc).
///
/// With the shape penalty on, a run that does not converge is followed by a run of the
/// paper's model (no penalty) from the input, for the rest of the iteration budget, whose
/// result is returned only if it converged: creasing is accepted only when it buys a
/// flattenable mesh. Between two unconverged results the penalised one is kept even when the
/// other's ϖ_max is lower (a deliberate departure from "ϖ_max first": on the corpus the plain
/// runs' stalled outputs carry 5× the new folds, e.g. mh_male_worksuit01 4.4e-3 rad with 124
/// new folds against 0.47 rad with none, and neither is usable). Continuing from the penalised
/// result instead of the input was measured worse (worksuit 0.18 rad). But when the run from
/// the input converged by folding edges the input did not fold, the paper's model is run once
/// more from the penalised result, anchored to the input, and kept if it converges with fewer
/// folds ([`plain_from_best`]: pf_robert_shirt_14 129 → 20). With `shape_guard`, neither
/// run folds.
///
/// Retries (`retry`, default on; not with `until = stationary`). A run that stalled — ended
/// unconverged before `max_iterations` — is tried again, each new run with its own
/// `max_iterations`. A mesh of several independent parts (the connected parts of its patches;
/// the `parts` module) runs every part still above the tolerance alone from the input, in
/// parallel, and, where that does not converge, once more from the better of the part's two
/// results (a restart: anchors, damping, fairing weight, stall window and the cone's fold and
/// corner baselines start afresh there); each part keeps the best of its results
/// (flattenable first, then the lower ϖ_max: the issue's merit; the penalised-first choice
/// above is made inside each run). Parts share no constraint, only the shape penalty's
/// hinges across a seam, which a part alone does not see: a part whose result, combined,
/// folds a seam edge that neither the whole run's result nor the input folds gives it up,
/// unless giving up such results leaves the combined mesh unflattenable where keeping them
/// would not (ϖ_max first; the folds are then `unfold`'s and `remesh`'s). A part keeps the
/// whole run's result when its own runs fail or are stopped. So no part takes more than three
/// times `max_iterations`; the reported `iterations` (every run's, chained in `history`,
/// whose ϖ_max is then each run's own mesh's) can reach (1 + 2·parts)·`max_iterations`.
/// A mesh of one part, or whose result cannot be split faithfully, gets the restart from the
/// whole run's result. The report lists each part in `parts` and measures ϖ_max, the stuck
/// and the free vertices on the combined output. Measured on the real meshes (issue 12
/// note): mh_female_sportsuit01 converges (stalled at 2.0e-3 before); ϖ_max falls on five
/// more (diffavatar_shirt_artist 1.4e-3 → 4.2e-4, mh_shoes01 1.3e-2 → 8.3e-3), and every
/// mesh that converged whole is untouched.
///
/// Detour (`detour`, default on): a result still unconverged after a stall (not after a run
/// cut short by `max_iterations`) and the retries is handed to [`detour`].
///
/// Unfolding (`unfold`, default on): the result's new folds and slivers are then repaired
/// where that keeps every interior vertex within the tolerance ([`open_new_folds`]), and
/// remeshing (`remesh`, default on) mends what is left of them by flips and collapses and a
/// re-solve ([`remesh_defects`]); a collapsed vertex stays,
/// unreferenced, so input vertex i is still output vertex i.
pub fn solve(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    let (out, report) = solve_retried(mesh, params, control)?;
    let (out, report) = open_new_folds(mesh, out, report, params, control)?;
    remesh_defects(mesh, out, report, params, control)
}

/// An unconverged result run through `develop`'s SQP (least change of its edge lengths along
/// θ = 2π, boundary and seams held, no restoration), then fl-mesh once more (one run, no
/// retries) from the SQP's result; the outcome replaces the result when it converged or
/// lowered ϖ_max. The stalls it breaks are those of whole garments, where every interior
/// vertex sits at a similar small excess θ > 2π that only the openings can absorb
/// (Gauss–Bonnet) and Eq. 7's steps no longer lower ‖2π − θ‖: the SQP's Levenberg–Marquardt
/// steps on E move the mesh off that point. Measured on unseen MakeHuman and GarmentTransfer
/// garments (issue 12 note of 2026-11-27): GarmentTransfer's shirt 1.2e-4 and t-shirt 8.0e-4
/// converge through it in 10 and 31 fl-mesh iterations. Unconverged, the outcome is taken on
/// ϖ_max alone (the issue's merit), though on the stalled MakeHuman suits it folds more
/// (mh_male_worksuit01 2 → 17 folds for 0.145 → 2.3e-2): neither result is usable as it is,
/// and the warnings point to `segment`. A stop or failure of either stage keeps the result.
fn detour(
    out: Mesh,
    mut report: Report,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    if report.converged
        || !params.detour
        || report.free_vertices == 0
        || impossible_vertices(&out).contains(&true)
    {
        return Ok((out, report));
    }
    let sqp = super::develop::Params {
        fix_boundary: true,
        restore: Some(false),
        unfold: false,
        tolerance: Some(params.tolerance),
        // fl-mesh goes on from the flattenable result; the corner barrier only lengthens
        // develop's objective phase, which fl-mesh's own objective then replaces.
        corner_barrier: 0.0,
        // Its own budget, as each retry's, within develop's default.
        max_iterations: params
            .max_iterations
            .min(super::develop::Params::default().max_iterations),
        ..super::develop::Params::default()
    };
    let polished = match super::develop::run(&out, &sqp, &Renamed::after(control, "sqp detour")) {
        Ok(o) => o.mesh.map(|m| (m, o.summary.g_max_after)),
        Err(e) => {
            report.stop_reason =
                format!("{}; detour through develop's SQP: {e}", report.stop_reason);
            return Ok((out, report));
        }
    };
    let Some((polished, g)) = polished else {
        return Ok((out, report));
    };
    // One run: solve_clear_of has neither retries nor a detour of its own.
    let (again, second) = match solve_clear_of(
        &polished,
        params,
        None,
        &Renamed::after(control, "after the sqp detour"),
    ) {
        Ok(done) => done,
        Err(e) => {
            report.stop_reason = format!(
                "{}; detour through develop's SQP (g_max {g:.2e}), then fl-mesh: {e}",
                report.stop_reason
            );
            return Ok((out, report));
        }
    };
    let what = format!(
        "then develop's SQP from the best result (boundary held, g_max {g:.2e}) and fl-mesh \
         from there"
    );
    Ok(keep_lower((out, report), (again, second), &what))
}

/// The later run (`second`, from `first`'s result, whose numbering it extends) when it
/// converged or lowered ϖ_max, its report chained to the first's; else the first, with the
/// later run's iterations absorbed. `what` names the later stage in the stop reason.
fn keep_lower(first: (Mesh, Report), second: (Mesh, Report), what: &str) -> (Mesh, Report) {
    let ((out, mut first), (again, second)) = (first, second);
    if second.converged || second.max_flattenability < first.max_flattenability {
        // Refinement appends, so the first run's refined ids stay valid.
        let refined = first.refined.clone();
        let mut report = chain(first, second, |f, s| format!("{f}; {what}: {s}"));
        report.refined = [refined, report.refined].concat();
        return (again, report);
    }
    absorb(&mut first, &second);
    first.stop_reason = format!(
        "{}; {what}, which did not lower ϖ_max ({:.2e}: {})",
        first.stop_reason, second.max_flattenability, second.stop_reason
    );
    (out, first)
}

/// A result's folds (edges) and slivers (faces with a corner below the minimum) that its
/// input did not have, by vertex pair and triple: refinement's or remeshing's new edges and
/// faces count as new.
struct Defects {
    folds: Vec<u32>,
    slivers: Vec<u32>,
}

impl Defects {
    /// (folds, slivers).
    fn counts(&self) -> (usize, usize) {
        (self.folds.len(), self.slivers.len())
    }
}

/// How [`remesh_defects`] compares rounds: new folds and slivers together, then folds.
fn merit(d: &Defects) -> (usize, usize) {
    (d.folds.len() + d.slivers.len(), d.folds.len())
}

fn new_defects(input: &Mesh, out: &Mesh, min_corner: f64) -> Defects {
    let old: std::collections::HashSet<[u32; 2]> = crate::geometry::fold_edges(input)
        .into_iter()
        .map(|e| input.conn().edges()[e as usize])
        .collect();
    let folds: Vec<u32> = crate::geometry::fold_edges(out)
        .into_iter()
        .filter(|&e| !old.contains(&out.conn().edges()[e as usize]))
        .collect();
    let sliver_faces = |m: &Mesh| {
        let small = crate::geometry::min_corner_angles(m);
        (0..m.num_faces()).filter(move |&f| small[f] < min_corner)
    };
    let key = |t: [u32; 3]| {
        let mut t = t;
        t.sort_unstable();
        t
    };
    let old_slivers: std::collections::HashSet<[u32; 3]> = sliver_faces(input)
        .map(|f| key(input.triangles()[f]))
        .collect();
    let slivers: Vec<u32> = sliver_faces(out)
        .filter(|&f| !old_slivers.contains(&key(out.triangles()[f])))
        .map(|f| f as u32)
        .collect();
    Defects { folds, slivers }
}

/// Rounds of [`remesh_defects`] on an unconverged result. Measured (issue 12 note of
/// 2026-11-27, 9 garments, when this bounded both kinds of round): one round was kept on
/// six, two on GarmentTransfer's shirt and on MakeHuman's two female casual suits, a third
/// never. On unconverged results (session 26): all three were kept on
/// mh_female_elegantsuit01 and an unseen male casual suit, where six took ϖ_max 1.4e-2 →
/// 3.2e-3 instead of 5.3e-3, for 357 s instead of 251 s, still unconverged.
const REMESH_ROUNDS: usize = 3;

/// Rounds of [`remesh_defects`] on a flattenable result: each is kept only when it leaves
/// fewer new folds plus slivers, so the rounds end by themselves at the first that does not
/// help; this only bounds their time. Measured (session 29, against 3; unseen MakeHuman
/// suits): male casualsuit02 4 → 2 new folds in 5 rounds (30 → 38 s), casualsuit01 10 → 9
/// new folds in 7 (9 folds in all, its input 11); casualsuit05 and female casualsuit02
/// ended by themselves at 3 and 2, as before.
const FOLD_ROUNDS: usize = 10;

/// A result's new folds and slivers that unfolding left, mended by connectivity
/// ([`super::remesh::mend`]: flip a fold's edge or a cap's long edge, collapse a needle's
/// short edge), then θ = 2π solved again from the mended mesh (one run: no cone, retries or
/// detour) and unfolded. On a flattenable result a round is kept only when its result is
/// flattenable with fewer new folds plus slivers than before (as many: fewer folds). On an
/// unconverged one (whose stall the slivers and folds feed: on the stalled suits the
/// linearised θ is worst at caps and near-folded fans, where 0.01 h̄ of the step moves θ by
/// 0.5 rad) a round is kept when it lowers ϖ_max, as the retries and the detour are, and a
/// refused round is tried once more with the slivers mended first, for up to
/// [`REMESH_ROUNDS`] rounds; once a round made it flattenable, up to [`FOLD_ROUNDS`] more
/// follow under the first rule.
/// Vertices a collapse removed stay unreferenced, at the final position of the vertex they
/// were merged into. A failure or stop of a round keeps the result before it.
fn remesh_defects(
    input: &Mesh,
    mut out: Mesh,
    mut report: Report,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    if !params.remesh || params.until == Until::Stationary {
        return Ok((out, report));
    }
    // An unconverged result held by a proven obstruction (a closed component) has nothing
    // a re-solve could lower.
    if !report.converged && (report.free_vertices == 0 || impossible_vertices(&out).contains(&true))
    {
        return Ok((out, report));
    }
    let min_corner = params.min_angle.to_radians();
    let mut defects = new_defects(input, &out, min_corner);
    let (folds, slivers) = defects.counts();
    if folds + slivers == 0 {
        return Ok((out, report));
    }
    let mut done = RemeshReport {
        new_folds: [folds; 2],
        new_slivers: [slivers; 2],
        max_flattenability: [report.max_flattenability; 2],
        stop_reason: "no new fold or sliver left".into(),
        ..RemeshReport::default()
    };
    let polish = Params {
        cone_start: ConeStart::Never,
        retry: false,
        detour: false,
        remesh: false,
        ..params.clone()
    };
    // Rounds since the result became flattenable (or since the start): an unconverged
    // result gets REMESH_ROUNDS towards convergence, then FOLD_ROUNDS for its folds.
    let mut in_mode = 0;
    // One past the most rounds, so the limit is said.
    for round in 1..=REMESH_ROUNDS + FOLD_ROUNDS + 1 {
        if defects.counts() == (0, 0) {
            break;
        }
        let limit = if report.converged {
            FOLD_ROUNDS
        } else {
            REMESH_ROUNDS
        };
        if in_mode == limit {
            done.stop_reason = format!("the limit of {limit} rounds was reached");
            break;
        }
        in_mode += 1;
        let edges = out.conn().edges();
        let folds: Vec<[u32; 2]> = defects.folds.iter().map(|&e| edges[e as usize]).collect();
        let slivers: Vec<[u32; 3]> = defects
            .slivers
            .iter()
            .map(|&f| out.triangles()[f as usize])
            .collect();
        let movable = free_vertices(&out);
        // An unconverged result whose round was refused tries the round once more with
        // slivers first (the order of the mend, not its rule): on the stalled suits either
        // order may be the one whose re-solve lowers ϖ_max.
        let orders: &[bool] = if report.converged {
            &[false]
        } else {
            &[false, true]
        };
        let mut taken = None;
        let mut refusal = String::new();
        let mut tried_lenient = false;
        for &slivers_first in orders {
            if slivers_first && tried_lenient {
                break;
            }
            let task = super::remesh::Task {
                folds: &folds,
                slivers: &slivers,
                movable: &movable,
                min_corner,
                slivers_first,
            };
            // Slivers whose every mending folds an edge before the re-solve are tried again
            // with slivers first: the re-solve may open the fold, and the round is judged
            // after.
            let mended = super::remesh::mend(&out, &task).or_else(|| {
                tried_lenient = true;
                let lenient = super::remesh::Task {
                    slivers_first: true,
                    ..task
                };
                super::remesh::mend(&out, &lenient)
            });
            let Some(mended) = mended else {
                refusal = "no flip or collapse improved its faces".into();
                continue;
            };
            let ctl = Renamed::after(control, "remesh");
            let solved = solve_clear_of(&mended.mesh, &polish, None, &ctl)
                .and_then(|(m, r)| open_new_folds(input, m, r, params, &ctl));
            let (again, second) = match solved {
                Ok(d) => d,
                Err(e) => {
                    refusal = format!("the re-solve failed: {e}");
                    break;
                }
            };
            absorb(&mut report, &second);
            let after = new_defects(input, &again, min_corner);
            let kept = if report.converged {
                second.converged && merit(&after) < merit(&defects)
            } else {
                // Unconverged: ϖ_max first (the issue's merit), as the retries and the detour.
                second.converged || second.max_flattenability < report.max_flattenability
            };
            if kept {
                taken = Some((mended, again, second, after));
                break;
            }
            refusal = format!(
                "re-solved to ϖ_max {:.2e} with {} new folds and {} slivers, not kept",
                second.max_flattenability,
                after.folds.len(),
                after.slivers.len()
            );
        }
        let Some((mended, again, second, after)) = taken else {
            done.stop_reason = format!("round {round}: {refusal}");
            break;
        };
        if second.converged && !report.converged {
            in_mode = 0;
            report.converged = true;
            report.stop_reason = format!(
                "{}; flattenable after remeshing (round {round})",
                report.stop_reason
            );
        }
        report.max_flattenability = second.max_flattenability;
        done.max_flattenability[1] = second.max_flattenability;
        report.stuck_vertices = second.stuck_vertices;
        report.stationarity = second.stationarity;
        report.free_vertices = second.free_vertices;
        report.refined.extend(second.refined);
        done.rounds = round;
        done.operations.flips += mended.summary.flips;
        done.operations.collapses += mended.summary.collapses;
        done.operations.merged.extend(mended.summary.merged);
        (done.new_folds[1], done.new_slivers[1]) = after.counts();
        out = again;
        defects = after;
    }
    if done.rounds > 0 {
        out = place_merged(out, &done.operations.merged);
        report.stop_reason = format!(
            "{}; remeshed in {} round(s): {} flips, {} collapses",
            report.stop_reason, done.rounds, done.operations.flips, done.operations.collapses
        );
    }
    report.remesh = Some(done);
    Ok((out, report))
}

/// Interior vertices not held by a proven obstruction: what unfolding and remeshing may move.
fn free_vertices(out: &Mesh) -> Vec<bool> {
    let impossible = impossible_vertices(out);
    (0..out.num_vertices())
        .map(|v| out.conn().is_interior(v as u32) && !impossible[v])
        .collect()
}

/// Each vertex a collapse removed put at the final position of the vertex it ended up merged
/// into (following later collapses of that one), so that it lies on the surface.
fn place_merged(out: Mesh, merged: &[[u32; 2]]) -> Mesh {
    let into: std::collections::HashMap<u32, u32> = merged
        .iter()
        .map(|&[removed, kept]| (removed, kept))
        .collect();
    let mut positions = out.positions().to_vec();
    for &[removed, _] in merged {
        let mut root = removed;
        // Chains are at most as long as the collapses.
        for _ in 0..=merged.len() {
            match into.get(&root) {
                Some(&next) => root = next,
                None => break,
            }
        }
        positions[removed as usize] = positions[root as usize];
    }
    out.with_positions(positions).unwrap_or(out)
}

/// The result's folds and slivers (a corner below `min_angle`) that the input did not have
/// (by vertex pair and triple: refinement's new edges and faces count as new), repaired by
/// [`super::unfold::unfold`], moving only the free vertices.
fn open_new_folds(
    input: &Mesh,
    out: Mesh,
    mut report: Report,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    if !params.unfold || params.until == Until::Stationary {
        return Ok((out, report));
    }
    let min_corner = params.min_angle.to_radians();
    let Defects { folds, slivers } = new_defects(input, &out, min_corner);
    if folds.is_empty() && slivers.is_empty() {
        return Ok((out, report));
    }
    let free = free_vertices(&out);
    let task = super::unfold::Task {
        folds: &folds,
        slivers: &slivers,
        min_corner,
        movable: &free,
        constrained: &free,
        tolerance: params.tolerance,
    };
    let done = super::unfold::unfold(&out, out.positions(), &task, control)?;
    let Ok(unfolded) = out.with_positions(done.positions) else {
        return Ok((out, report));
    };
    let (wmax, stuck) = verdict(&unfolded, params.tolerance);
    // Every row was kept within max(tolerance / 2, where it was): never worse, but checked
    // on the mesh itself.
    if wmax > report.max_flattenability.max(params.tolerance) {
        return Ok((out, report));
    }
    report.max_flattenability = wmax;
    report.stuck_vertices = stuck;
    report.unfold = Some(done.summary);
    // The corrections may close rows the run left open (each stays below where it was).
    if !report.converged && wmax <= params.tolerance {
        report.converged = true;
        report.stop_reason = format!("{}; flattenable after unfolding", report.stop_reason);
    }
    Ok((unfolded, report))
}

/// [`solve`] before opening new folds: the whole run, its retries and the detour.
fn solve_retried(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    let (whole_out, whole) = solve_clear_of(mesh, params, None, control)?;
    // Only a stall is retried: a run cut short by `max_iterations` was given its budget, and
    // `until = stationary` asks for the paper's stationary point of this run.
    if whole.converged
        || params.until == Until::Stationary
        || whole.iterations >= params.max_iterations
    {
        return Ok((whole_out, whole));
    }
    let (out, report) = if !params.retry {
        (whole_out, whole)
    } else {
        // Parts are solved alone with their seams held where the input has them: with free
        // seams the whole run moved those, and a merge would mix the two.
        let split = match params.seams {
            Seams::Free => None,
            _ => parts::split(mesh),
        };
        match split {
            Some(split) => match retry_parts(mesh, &split, whole_out, whole, params, control) {
                Ok(done) => done,
                Err(back) => {
                    let (whole_out, whole) = *back;
                    restart(mesh, whole_out, whole, params, control)?
                }
            },
            None => restart(mesh, whole_out, whole, params, control)?,
        }
    };
    detour(out, report, params, control)
}

/// The parts stage of [`solve`]: each unconverged part run alone ([`retry_part`]), each part
/// keeping its best result, merged. Gives the whole run back (Err) when its result cannot be
/// split into the parts faithfully.
fn retry_parts(
    mesh: &Mesh,
    split: &[parts::Part],
    whole_out: Mesh,
    mut whole: Report,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), Box<(Mesh, Report)>> {
    // Each part of the whole run's result, with its vertices' ids in that result.
    let Some(from_whole) = parts::restrict(&whole_out, mesh, split) else {
        return Err(Box::new((whole_out, whole)));
    };
    let wmax = |m: &Mesh| crate::geometry::max_flattenability(m);
    let total = split.len();
    let runs: Vec<Option<Result<PartRun, AlgoError>>> = {
        use rayon::prelude::*;
        split
            .par_iter()
            .zip(&from_whole)
            .enumerate()
            .map(|(k, (part, (w, _)))| {
                // A closed part whose χ ≠ 0 is a proven obstruction: nothing to retry.
                let retry =
                    wmax(w) > params.tolerance && !impossible_vertices(&part.mesh).contains(&true);
                retry.then(|| {
                    let label =
                        Renamed::before(control, format!("part {} of {total} alone", k + 1));
                    retry_part(&part.mesh, w, params, &label)
                })
            })
            .collect()
    };
    // A part whose own run failed or was stopped keeps the whole run's result.
    let mut failed = Vec::new();
    let runs: Vec<Option<PartRun>> = runs
        .into_iter()
        .enumerate()
        .map(|(k, run)| match run {
            Some(Ok(run)) => Some(run),
            Some(Err(e)) => {
                failed.push(format!("part {}: {e}", k + 1));
                None
            }
            None => None,
        })
        .collect();
    // Which parts take their own result: flattenable first, then the lower ϖ_max.
    // (`retry_part` names "whole" when neither of its runs beat the whole run's result.)
    let mut own: Vec<bool> = runs
        .iter()
        .map(|run| run.as_ref().is_some_and(|r| r.kept != "whole"))
        .collect();
    // Parts share no constraint, but the shape penalty's hinges across a seam see both sides:
    // a part that, combined, folds a seam edge that neither the whole run nor the input folds
    // gives its result up (and so may its neighbours, against that part's result from the
    // whole run). Unless that costs flattenability: ϖ_max comes first, and the folds are then
    // left to `unfold` and `remesh` (mh_male_elegantsuit01: all 23 islands converge alone, but
    // their seam folds gave every large island up and the job ended at 5e-2; see
    // [`parts::new_seam_folds`]).
    let merged_with = |own: &[bool]| -> Option<Mesh> {
        let chosen: Vec<&Mesh> = (0..total)
            .map(|k| match (&runs[k], own[k]) {
                (Some(run), true) => &run.mesh,
                _ => &from_whole[k].0,
            })
            .collect();
        let raw = parts::merge(mesh, split, &chosen);
        match Mesh::new(raw.clone()) {
            Ok((m, _)) if m.triangles() == &raw.triangles[..] => Some(m),
            _ => None,
        }
    };
    let own_first = own.clone();
    let Some(all_own) = merged_with(&own) else {
        return Err(Box::new((whole_out, whole)));
    };
    let mut merged = all_own.clone();
    loop {
        let folds = parts::new_seam_folds(mesh, split, &whole_out, &merged);
        let back: Vec<usize> = folds.into_iter().filter(|&k| own[k]).collect();
        if back.is_empty() {
            break;
        }
        for k in back {
            own[k] = false;
        }
        let Some(m) = merged_with(&own) else {
            return Err(Box::new((whole_out, whole)));
        };
        merged = m;
    }
    let flat = |m: &Mesh| wmax(m) <= params.tolerance;
    let seam_folds_kept = own != own_first && flat(&all_own) && !flat(&merged);
    let out = if seam_folds_kept {
        own = own_first;
        all_own
    } else {
        merged
    };
    let folding = if seam_folds_kept {
        parts::new_seam_folds(mesh, split, &whole_out, &out)
    } else {
        Vec::new()
    };
    let whole_refined = std::mem::take(&mut whole.refined);
    let mut report = whole;
    // New (refinement) vertices of the kept results are appended part by part.
    let mut first_new = mesh.num_vertices() as u32;
    for (k, part) in split.iter().enumerate() {
        let (w, w_vertices) = &from_whole[k];
        let w_whole = wmax(w);
        let mut row = PartReport {
            patch: part.name.clone(),
            faces: part.faces.len(),
            interior_vertices: part.mesh.conn().interior_vertices().count(),
            kept: "whole".into(),
            converged: w_whole <= params.tolerance,
            max_flattenability: w_whole,
            ..PartReport::default()
        };
        // The whole run's refined vertices that are this part's, in its local numbering.
        let mut local = vec![NONE; whole_out.num_vertices()];
        for (l, &v) in w_vertices.iter().enumerate() {
            local[v as usize] = l as u32;
        }
        let local_whole: Vec<u32> = whole_refined
            .iter()
            .map(|&v| local[v as usize])
            .filter(|&l| l != NONE)
            .collect();
        let mut refined = local_whole.clone();
        let mut kept = w;
        if let Some(run) = &runs[k] {
            let r = &run.report;
            absorb(&mut report, r);
            row.iterations = r.iterations;
            row.stop_reason = r.stop_reason.clone();
            if own[k] {
                kept = &run.mesh;
                refined = if run.from_whole {
                    [local_whole, r.refined.clone()].concat()
                } else {
                    r.refined.clone()
                };
                row.kept = run.kept.into();
                row.converged = r.converged;
                row.max_flattenability = r.max_flattenability;
                if folding.contains(&k) {
                    row.stop_reason = format!(
                        "{}; kept though combined with the other parts it folds a seam edge \
                         (without it the whole would not be flattenable)",
                        row.stop_reason
                    );
                }
            } else if run.kept != "whole" {
                row.stop_reason = format!(
                    "{}; not kept: combined with the other parts it folds a seam edge",
                    row.stop_reason
                );
            }
        }
        report.refined.extend(
            refined
                .into_iter()
                .map(|l| parts::global_vertex(part, first_new, l)),
        );
        first_new += (kept.num_vertices() - part.vertices.len()) as u32;
        report.parts.push(row);
    }
    // The verdict from the combined mesh's own angles, as for a whole run.
    (report.max_flattenability, report.stuck_vertices) = verdict(&out, params.tolerance);
    let impossible = impossible_vertices(&out);
    report.free_vertices = out
        .conn()
        .interior_vertices()
        .filter(|&v| !impossible[v as usize])
        .count();
    report.converged =
        report.parts.iter().all(|p| p.converged) && report.max_flattenability <= params.tolerance;
    let mut reason = format!(
        "whole: {}; {}",
        report.stop_reason,
        parts_reason(&report.parts)
    );
    if !failed.is_empty() {
        reason = format!(
            "{reason}; kept the whole run's result where a part's own run failed ({})",
            failed.join(", ")
        );
    }
    report.stop_reason = reason;
    Ok((out, report))
}

/// [`solve`] without its retries: one run of the whole mesh (for callers that handle a
/// failure themselves, as `segment` splits the chart).
pub fn solve_once(
    mesh: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    solve_clear_of(mesh, params, None, control)
}

/// A mesh of one part that the whole run left unconverged: one more run from its result (the
/// best iterate; anchors, damping, fairing weight and stall window start afresh), kept when it
/// converged or lowered ϖ_max. Not for closed components, whose obstruction is proven.
fn restart(
    mesh: &Mesh,
    out: Mesh,
    mut first: Report,
    params: &Params,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    if first.free_vertices == 0 || impossible_vertices(mesh).contains(&true) {
        return Ok((out, first));
    }
    let (again, second) =
        match solve_clear_of(&out, params, None, &Renamed::after(control, "restart")) {
            Ok(done) => done,
            // An optional stage stopped (cancel or time limit) or failed: the first run stands.
            Err(e) => {
                first.stop_reason = format!("{}; restart: {e}", first.stop_reason);
                return Ok((out, first));
            }
        };
    Ok(keep_lower(
        (out, first),
        (again, second),
        "restarted from the best iterate",
    ))
}

/// A part's own runs and the result it keeps.
struct PartRun {
    mesh: Mesh,
    /// The runs chained (iterations, history; `refined` in `mesh`'s numbering, beyond the
    /// start's own refinement when `from_whole`).
    report: Report,
    /// "alone" (its run from the input), "restart" (the run from its best result so far), or
    /// "whole" (neither beat the whole run's result).
    kept: &'static str,
    /// The kept result continued the whole run's result (whose refinement it carries).
    from_whole: bool,
}

/// A part that the whole run left unconverged: solved alone from the input, and if that does
/// not converge either, once more from the better of the two results (a restart: anchors,
/// damping, fairing weight and stall window start afresh there). Measured on the real garments
/// (issue 12 note) the second run is what converged mh_female_sportsuit01; the first, the
/// buttons of mh_male_worksuit01.
fn retry_part(
    part: &Mesh,
    whole: &Mesh,
    params: &Params,
    control: &dyn Control,
) -> Result<PartRun, AlgoError> {
    let w_whole = crate::geometry::max_flattenability(whole);
    let (a, ra) = solve_clear_of(part, params, None, control)?;
    let a_better = ra.converged || ra.max_flattenability < w_whole;
    if ra.converged {
        return Ok(PartRun {
            mesh: a,
            report: ra,
            kept: "alone",
            from_whole: false,
        });
    }
    let start = if a_better { &a } else { whole };
    let (b, rb) = match solve_clear_of(start, params, None, &Renamed::after(control, "restart")) {
        Ok(done) => done,
        // Stopped or failed: the first run's result stands.
        Err(e) => {
            let mut report = ra;
            report.stop_reason = format!("{}; restart: {e}", report.stop_reason);
            let kept = if a_better { "alone" } else { "whole" };
            return Ok(PartRun {
                mesh: a,
                report,
                kept,
                from_whole: false,
            });
        }
    };
    let b_better = rb.converged || rb.max_flattenability < ra.max_flattenability.min(w_whole);
    let (refined_a, best_a) = (ra.refined.clone(), ra.best_iteration);
    let mut report = chain(ra, rb, |a, b| {
        format!("from the input: {a}; restarted from the better result: {b}")
    });
    let (mesh, kept, from_whole) = match (b_better, a_better) {
        (true, _) => {
            if a_better {
                report.refined = [refined_a, report.refined].concat();
            }
            (b, "restart", !a_better)
        }
        (false, true) => {
            report.refined = refined_a;
            report.converged = false;
            (a, "alone", false)
        }
        (false, false) => (a, "whole", false),
    };
    if kept == "alone" {
        // The figures of the kept (first) run.
        report.max_flattenability = crate::geometry::max_flattenability(&mesh);
        report.best_iteration = best_a;
    }
    Ok(PartRun {
        mesh,
        report,
        kept,
        from_whole,
    })
}

/// What became of the parts: how many are flattenable, which run each kept, and the others'
/// ϖ_max (the worst five; every part is in `Report::parts`).
fn parts_reason(rows: &[PartReport]) -> String {
    let flat = rows.iter().filter(|p| p.converged).count();
    let alone = rows.iter().filter(|p| p.kept == "alone").count();
    let mut failed: Vec<(usize, &PartReport)> = rows
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.converged)
        .collect();
    let head = format!(
        "then the {} independent parts alone: {flat} flattenable ({alone} from their own run)",
        rows.len()
    );
    if failed.is_empty() {
        return head;
    }
    failed.sort_by(|a, b| b.1.max_flattenability.total_cmp(&a.1.max_flattenability));
    let shown: Vec<String> = failed
        .iter()
        .take(5)
        .map(|(k, p)| {
            format!(
                "part {} ({} faces of patch {:?}): ϖ_max {:.2e}",
                k + 1,
                p.faces,
                p.patch,
                p.max_flattenability
            )
        })
        .collect();
    let more = match failed.len().saturating_sub(5) {
        0 => String::new(),
        m => format!(", and {m} more"),
    };
    format!("{head}; not: {}{more}", shown.join(", "))
}

/// [`solve`], with every free vertex kept at least `keep.clearance` outside `keep.obstacle`
/// (one that starts closer never ends closer than it started): see the `contact` module.
pub fn solve_clear_of(
    mesh: &Mesh,
    params: &Params,
    keep: Option<Keep<'_>>,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    params.check()?;
    // The cone answers "some flattenable surface with this boundary": not with an obstacle,
    // and not when the paper's stationary point is asked for (measured: from the cone the
    // stationary iterations drift back towards the input and lose flattenability).
    let cone_allowed = keep.is_none()
        && params.cone_start != ConeStart::Never
        && params.until == Until::Flattenable;
    let mut spent = 0;
    let mut tried: Option<Report> = None;
    let mut spare: Option<Spare> = None;
    // `first` leaves one iteration for the input's run, and an input that is flattenable
    // already to that run (which returns it unchanged). `auto` gives the cone a third of the
    // budget: where it fired the cone's run converged in 12–26 iterations (corpus), and
    // where it stalls (a ragged boundary's d-cone is pleated along the generators to every
    // corner: a round staircase saddle, 1.6e-4) the input's run keeps two thirds.
    let cone_budget = match params.cone_start {
        ConeStart::Auto => (params.max_iterations / 3).max(1),
        _ => params.max_iterations,
    }
    .min(params.max_iterations.saturating_sub(1));
    let cone_first = if cone_allowed
        && cone_budget > 0
        && crate::geometry::max_flattenability(mesh) > params.tolerance
    {
        match params.cone_start {
            ConeStart::First => Some(String::new()),
            ConeStart::Auto => curved(mesh),
            ConeStart::Fallback | ConeStart::Never => None,
        }
    } else {
        None
    };
    // `reading`: why the cone goes first ("" for `first`, the curvature for `auto`).
    if let Some(reading) = &cone_first {
        match from_cone(mesh, params, cone_budget, control)? {
            ConeRun::Accepted(out, mut report) => {
                report.stop_reason = format!("developable cone{reading}: {}", report.stop_reason);
                return Ok((out, report));
            }
            ConeRun::Rejected(why, report) => {
                spent = report.iterations;
                tried = Some(Report {
                    stop_reason: why,
                    ..report
                });
            }
            ConeRun::Unconverged(why, report, out) => {
                spent = report.iterations;
                spare = Some((out, report.clone(), 0, "the developable cone's"));
                tried = Some(Report {
                    stop_reason: why,
                    ..report
                });
            }
        }
    }
    // A cone that went first and was rejected is not tried again after the input's run.
    let cone_after =
        tried.is_none() && matches!(params.cone_start, ConeStart::Auto | ConeStart::Fallback);
    let budget = Params {
        max_iterations: params.max_iterations - spent,
        ..params.clone()
    };
    let (out, mut first) = solve_phase(mesh, &budget, keep, None, control)?;
    if let Some(cone) = tried {
        let reading = cone_first.unwrap_or_default();
        first = chain(cone, first, |c, f| {
            format!("developable cone{reading}: {c}; from the input: {f}")
        });
    }
    if first.converged || first.free_vertices == 0 {
        if first.converged && cone_allowed && cone_after {
            return uncrumple(mesh, params, out, first, control);
        }
        return Ok(prefer_spare(out, first, spare));
    }
    if cone_allowed && cone_after {
        let remaining = params.max_iterations.saturating_sub(first.iterations);
        if remaining > 0 {
            match from_cone(mesh, params, remaining, control)? {
                ConeRun::Accepted(out2, second) => {
                    let report = chain(first, second, |f, c| {
                        format!("from the input: {f}; from the developable cone: {c}")
                    });
                    return Ok((out2, report));
                }
                ConeRun::Rejected(why, second) => {
                    first.stop_reason = format!("{}; developable cone: {why}", first.stop_reason);
                    absorb(&mut first, &second);
                }
                ConeRun::Unconverged(why, second, out2) => {
                    first.stop_reason = format!("{}; developable cone: {why}", first.stop_reason);
                    spare = Some((
                        out2,
                        second.clone(),
                        first.iterations,
                        "the developable cone's",
                    ));
                    absorb(&mut first, &second);
                }
            }
        }
    }
    let remaining = params.max_iterations.saturating_sub(first.iterations);
    if params.shape_penalty == 0.0 || remaining == 0 {
        return Ok(prefer_spare(out, first, spare));
    }
    let plain = Params {
        shape_penalty: 0.0,
        max_iterations: remaining,
        ..params.clone()
    };
    let (out2, second) = solve_phase(
        mesh,
        &plain,
        keep,
        None,
        &Renamed::after(control, "no shape penalty"),
    )?;
    if second.converged {
        let folds = crate::geometry::fold_edges(&out2).len();
        if folds > crate::geometry::fold_edges(mesh).len() {
            if let Some(found) =
                plain_from_best(mesh, &plain, keep, &out, folds, &first, &second, control)?
            {
                return Ok(found);
            }
        }
        let report = chain(first, second, |f, s| {
            format!("with the shape penalty: {f}; without it, from the input: {s}")
        });
        Ok((out2, report))
    } else {
        first.stop_reason = format!(
            "{}; the paper's model (no shape penalty) from the input did not converge either \
             (ϖ_max {:.2e}: {})",
            first.stop_reason, second.max_flattenability, second.stop_reason
        );
        let offset = first.iterations;
        absorb(&mut first, &second);
        let lowest = spare
            .as_ref()
            .map_or(f64::INFINITY, |s| s.1.max_flattenability);
        if second.max_flattenability < lowest && keeps_shape(mesh, &out2, params) {
            spare = Some((out2, second, offset, "the paper's model's"));
        }
        Ok(prefer_spare(out, first, spare))
    }
}

/// The paper's model again, started from the penalised run's result `best` (smoother, and
/// nearer θ = 2π, than the input) but anchored to the input as before (vertices that
/// refinement added to `best` to where they were made), for when the run from the input
/// converged with `folds` edges folded, more than the input has: its result if it converged
/// with fewer. Measured on the shared garments whose penalised run stalled (issue 12 note):
/// pf_robert_shirt_14 129 → 20 new folds before unfolding (1 after, against 23), while
/// mh_female_sportsuit01 got 19 (against 18) and mh_female_casualsuit02 did not converge from
/// there; so both runs, and the better kept. `first` is the penalised run's report. Not with
/// `anchor=closest`, whose anchors come from the input's surface, nor with `unfold` off: a
/// caller that repairs no folds does not pay for fewer (develop's restoration, whose δS it
/// raised: mh_female_sportsuit01 27.2 → 32.4 %).
#[allow(clippy::too_many_arguments)]
fn plain_from_best(
    mesh: &Mesh,
    plain: &Params,
    keep: Option<Keep<'_>>,
    best: &Mesh,
    folds: usize,
    first: &Report,
    from_input: &Report,
    control: &dyn Control,
) -> Result<Option<(Mesh, Report)>, AlgoError> {
    let n = mesh.num_vertices();
    if !plain.unfold || plain.anchor != Anchor::Input || best.num_vertices() < n {
        return Ok(None);
    }
    let anchors: Vec<[f64; 3]> = mesh
        .positions()
        .iter()
        .chain(&best.positions()[n..])
        .copied()
        .collect();
    // Stopped (cancel or time limit) during this optional run: keep the run from the input.
    let (out3, mut third) = match solve_phase(
        best,
        plain,
        keep,
        Some(&anchors),
        &Renamed::after(control, "no shape penalty, from the penalised result"),
    ) {
        Err(AlgoError::Cancelled) => return Ok(None),
        other => other?,
    };
    let folds3 = crate::geometry::fold_edges(&out3).len();
    if !third.converged || folds3 >= folds {
        return Ok(None);
    }
    third.refined.splice(0..0, first.refined.iter().copied());
    let mut head = first.clone();
    absorb(&mut head, from_input);
    let report = chain(head, third, |f, t| {
        format!(
            "with the shape penalty: {f}; without it, from the input: flattenable with {folds} \
             folded edges; from the penalised result instead: {t} ({folds3} folded)"
        )
    });
    Ok(Some((out3, report)))
}

/// A flattenable result from the input that crumpled the surface (new creases past 60° on
/// more than [`crate::geometry::CRUMPLED_SHARE`] of the edges, as the noisy saddles do) is
/// replaced by the run from the developable cone when that one is accepted and creases less:
/// "never crumple it" (issue 12) before closeness, since a crumpled sheet is no shape anyone
/// can sew.
fn uncrumple(
    mesh: &Mesh,
    params: &Params,
    out: Mesh,
    mut first: Report,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    use crate::geometry::crease_count;
    let (before, after) = (crease_count(mesh), crease_count(&out));
    let edges = out.conn().edges().len();
    let remaining = params.max_iterations.saturating_sub(first.iterations);
    let crumpled =
        after.saturating_sub(before) as f64 > crate::geometry::CRUMPLED_SHARE * edges as f64;
    if !crumpled || remaining == 0 {
        return Ok((out, first));
    }
    let new = after - before;
    match from_cone(mesh, params, remaining, control)? {
        ConeRun::Accepted(out2, second) if crease_count(&out2) < after => {
            let report = chain(first, second, |f, c| {
                format!(
                    "from the input: {f}, but crumpled ({new} new creases past 60° in \
                     {edges} edges); developable cone: {c}"
                )
            });
            Ok((out2, report))
        }
        ConeRun::Accepted(_, second) => {
            absorb(&mut first, &second);
            first.stop_reason = format!(
                "{} ({new} new creases past 60°; the developable cone's result creases no less)",
                first.stop_reason
            );
            Ok((out, first))
        }
        ConeRun::Rejected(why, second) | ConeRun::Unconverged(why, second, _) => {
            absorb(&mut first, &second);
            first.stop_reason = format!(
                "{} ({new} new creases past 60°; developable cone: {why})",
                first.stop_reason
            );
            Ok((out, first))
        }
    }
}

/// Fitted total curvature (rad, [`fitted_curvature`]) from which `auto` starts a dome-like
/// disk from its cone: from a reading of about 0.15 (domes z = a(2 − x² − y²)/2, a ≥ 0.2,
/// 2k–20k faces, noise 0.01 and 0.1) the cone's result was as close to the input as the
/// input's own run or closer (hd 2.4–8.2 % against 3.4–11.8 %), in fewer iterations, with
/// larger corners. Developable sheets read up to 0.4 rad but never 3 standard errors clear of zero
/// (pleats-7700-0.1: −0.39 ± 0.36), which the gate also asks.
pub const CONE_FIRST_DOME: f64 = 0.25;

/// Fitted total curvature (rad) from which `auto` starts a saddle-like disk (a reading ≤
/// −this) from its cone. Saddles z = a(x² − y²)/2 keep nearby crumpled flattenable surfaces:
/// from the input, a ≤ 0.5 (reading ≈ −0.6) can converge at 1–2 % with few creases, but from
/// a = 0.7 (≈ −1.1) every run from the input stalled or crumpled (102–395 new creases), so the
/// default ended at the cone anyway after 50–340 wasted iterations (issue 12 note).
pub const CONE_FIRST_SADDLE: f64 = 1.0;

/// Standard errors by which the fitted curvature must clear zero for `auto` to trust it:
/// coarse noisy meshes leave the fit too few vertices per sample to read the curvature.
const SIGNIFICANT: f64 = 3.0;

/// Why `auto` starts from the cone (for the stop reason), or None when the patch's fitted
/// curvature is below both thresholds or it is no height-field disk.
fn curved(mesh: &Mesh) -> Option<String> {
    let Curvature { total, error } = fitted_curvature(mesh).ok()?;
    let clear = total.abs() >= SIGNIFICANT * error;
    (clear && (total >= CONE_FIRST_DOME || total <= -CONE_FIRST_SADDLE))
        .then(|| format!(" first (fitted total curvature {total:+.2} ± {error:.2} rad)"))
}

/// `first` with the iterations and history of a later run whose result was not taken.
fn absorb(first: &mut Report, second: &Report) {
    let offset = first.iterations;
    first
        .history
        .extend(second.history.iter().map(|h| HistoryEntry {
            iteration: h.iteration + offset,
            ..*h
        }));
    first.iterations += second.iterations;
}

/// The report of a run that followed `first`: iterations and history counted on from
/// first's, the stop reason written by `reason(first's, second's)`, the rest second's.
fn chain(first: Report, second: Report, reason: impl Fn(&str, &str) -> String) -> Report {
    let offset = first.iterations;
    let mut history = first.history;
    history.extend(second.history.iter().map(|h| HistoryEntry {
        iteration: h.iteration + offset,
        ..*h
    }));
    Report {
        iterations: offset + second.iterations,
        best_iteration: match second.best_iteration {
            0 => 0,
            b => offset + b,
        },
        stop_reason: reason(&first.stop_reason, &second.stop_reason),
        history,
        ..second
    }
}

/// What became of a run from the developable cone.
enum ConeRun {
    /// It converged with no more folds than the input and no corner below
    /// min(`min_angle`, the input's smallest).
    Accepted(Mesh, Report),
    /// Why not (no cone, or the run's outcome), and the iterations it took.
    Rejected(String, Report),
    /// It did not converge but kept the shape (no more folds, no corner below the floor):
    /// its result, kept in case nothing later gets ϖ_max lower.
    Unconverged(String, Report, Mesh),
}

/// An unconverged result of a later run that kept the shape (the cone's, the paper's
/// model's): its mesh, its report, the iterations run before it (so that its
/// `best_iteration` counts from the start) and whose it is.
type Spare = (Mesh, Report, usize, &'static str);

/// `(out, report)`, or the `spare` when its ϖ_max is lower ("never worse": the merit is
/// ϖ_max first). The report keeps the whole run's iterations and history.
fn prefer_spare(out: Mesh, report: Report, spare: Option<Spare>) -> (Mesh, Report) {
    match spare {
        Some((mesh, s, offset, whose)) if s.max_flattenability < report.max_flattenability => {
            let stop_reason = format!(
                "{}; kept {whose} result, the lowest ϖ_max reached ({:.2e})",
                report.stop_reason, s.max_flattenability
            );
            let best_iteration = match s.best_iteration {
                0 => 0,
                b => offset + b,
            };
            let report = Report {
                best_iteration,
                converged: false,
                stop_reason,
                refined: s.refined,
                stuck_vertices: s.stuck_vertices,
                max_flattenability: s.max_flattenability,
                stationarity: s.stationarity,
                free_vertices: s.free_vertices,
                ..report
            };
            (mesh, report)
        }
        _ => (out, report),
    }
}

/// Whether `out` has no more folds than `input` and no corner below min(`min_angle`, the
/// input's smallest): what a later run's result must keep to be taken.
fn keeps_shape(input: &Mesh, out: &Mesh, params: &Params) -> bool {
    let floor = crate::geometry::smallest_corner(input).min(params.min_angle.to_radians());
    crate::geometry::fold_edges(out).len() <= crate::geometry::fold_edges(input).len()
        && crate::geometry::smallest_corner(out) >= floor
}

/// A run from the developable cone over the boundary (the `cone` module) with at most
/// `budget` iterations.
fn from_cone(
    mesh: &Mesh,
    params: &Params,
    budget: usize,
    control: &dyn Control,
) -> Result<ConeRun, AlgoError> {
    if control.cancelled() {
        return Ok(ConeRun::Rejected(
            "not tried, cancelled".into(),
            Report::default(),
        ));
    }
    let start = match cone_start(mesh) {
        Ok(start) => start,
        Err(why) => return Ok(ConeRun::Rejected(format!("none, {why}"), Report::default())),
    };
    let p = Params {
        max_iterations: budget,
        ..params.clone()
    };
    // Stopped (cancel or time limit) during this optional stage: keep what came before.
    let (out, mut report) = match solve_phase(
        &start,
        &p,
        None,
        None,
        &Renamed::after(control, "from the cone"),
    ) {
        Err(AlgoError::Cancelled) => {
            return Ok(ConeRun::Rejected(
                "stopped, cancelled or out of time".into(),
                Report::default(),
            ))
        }
        other => other?,
    };
    // Why the cone, so far from the input, may be the only way: a proof, not a stall.
    if let Some(excess) = isoperimetric_excess(mesh).filter(|&e| e > 1.0) {
        report.stop_reason = format!(
            "{} (the input's area is {excess:.1}× P²/4π, the most any flattenable disk with \
             its boundary can have, by the isoperimetric inequality of flat disks: none stays \
             near it; cut it, e.g. with `segment`, to keep its shape)",
            report.stop_reason
        );
    }
    let folds_in = crate::geometry::fold_edges(mesh).len();
    let folds_out = crate::geometry::fold_edges(&out).len();
    let floor = crate::geometry::smallest_corner(mesh).min(params.min_angle.to_radians());
    let why = if !report.converged {
        let why = format!(
            "not flattenable from it (ϖ_max {:.2e}: {})",
            report.max_flattenability, report.stop_reason
        );
        if keeps_shape(mesh, &out, params) {
            return Ok(ConeRun::Unconverged(why, report, out));
        }
        why
    } else if folds_out > folds_in {
        format!("flattenable from it, but with {folds_out} folds (input {folds_in})")
    } else if crate::geometry::smallest_corner(&out) < floor {
        format!(
            "flattenable from it, but with a corner of {:.2}° (floor {:.2}°)",
            crate::geometry::smallest_corner(&out).to_degrees(),
            floor.to_degrees()
        )
    } else {
        return Ok(ConeRun::Accepted(out, report));
    };
    Ok(ConeRun::Rejected(why, report))
}

/// One run of the solver with fixed parameters (see [`solve`]) from `mesh`, anchored to its
/// positions or to `anchors` (one per vertex) when given.
fn solve_phase(
    mesh: &Mesh,
    params: &Params,
    keep: Option<Keep<'_>>,
    anchors: Option<&[[f64; 3]]>,
    control: &dyn Control,
) -> Result<(Mesh, Report), AlgoError> {
    let mut report = Report::default();
    let mut current = mesh.clone();
    let impossible = impossible_vertices(mesh);
    let input_grid = match params.anchor {
        Anchor::Closest => Some(crate::spatial::TriangleBvh::new(
            mesh.positions(),
            mesh.triangles(),
        )),
        Anchor::Input => None,
    };
    let mut anchors: Vec<[f64; 3]> = anchors.unwrap_or(mesh.positions()).to_vec();
    // Per vertex, the least signed distance to the obstacle it may end at: min(c, where it
    // started).
    let mut floors: Vec<f64> = match keep {
        Some(k) => mesh.positions().iter().map(|&p| k.floor_at(p)).collect(),
        None => Vec::new(),
    };
    let mut rounds = 0usize;
    // The best result over the refinement rounds: (ϖ_max, mesh, refined count, best iteration,
    // stationarity, free vertices). A round whose refinement did not lower ϖ_max is dropped.
    let mut best: Option<(f64, Mesh, usize, usize, f64, usize)> = None;
    loop {
        let faces = current.triangles().len() as f64;
        if control.cancelled_before(crate::cost::FL_MESH_SETUP.seconds(faces)) {
            return Err(AlgoError::Cancelled);
        }
        let setup = std::time::Instant::now();
        let mut sys = System::new(
            &current,
            &impossible,
            params,
            keep.map(|k| (k, &floors[..])),
        )?;
        crate::cost::FL_MESH_SETUP.learn(faces, setup.elapsed().as_secs_f64());
        let round = Round {
            mesh: &current,
            grid: input_grid.as_ref(),
            params,
            control,
        };
        let end = sys.iterate(&round, &mut anchors, &mut report)?;
        // Accepted iterates pass the validator's own degeneracy test (trial_valid), so this
        // cannot fail; if it ever did, the best valid mesh so far is returned.
        current = match current.with_positions(sys.pos.clone()) {
            Ok(m) => m,
            Err(e) => {
                report.stop_reason = format!("an iterate failed validation ({e})");
                break;
            }
        };
        let wmax = violation(&sys.theta).0;
        if best.as_ref().is_none_or(|b| wmax < b.0) {
            best = Some((
                wmax,
                current.clone(),
                report.refined.len(),
                report.best_iteration,
                sys.stationarity,
                sys.nc,
            ));
        }
        match end {
            End::Stalled(stuck)
                if params.refine
                    && rounds < params.max_refinements
                    && report.iterations < params.max_iterations
                    && !stuck.is_empty() =>
            {
                let min_angle = if params.shape_guard {
                    params.min_angle.to_radians()
                } else {
                    0.0
                };
                let chosen = independent(&current, &stuck, min_angle);
                if chosen.is_empty() {
                    break;
                }
                rounds += 1;
                control.progress(&Progress {
                    stage: "refine".into(),
                    iteration: rounds,
                    max_flattenability: None,
                    step_norm: None,
                });
                let raw = refine_sqrt3(&current, &chosen);
                let added = raw.positions[anchors.len()..].to_vec();
                match Mesh::new(raw) {
                    Ok((refined, _)) => {
                        if let Some(k) = keep {
                            floors.extend(added.iter().map(|&p| k.floor_at(p)));
                        }
                        anchors.extend(added);
                        report.refined.extend_from_slice(&chosen);
                        current = refined;
                        continue;
                    }
                    Err(e) => {
                        report.stop_reason = format!(
                            "{}; refinement would leave an invalid mesh ({e})",
                            report.stop_reason
                        );
                    }
                }
            }
            End::Stalled(_) => {
                if report.stop_reason.is_empty() {
                    report.stop_reason = "stalled".into();
                }
            }
            End::Done(reason) => report.stop_reason = reason,
        }
        break;
    }
    if let Some((_, mesh, refined, best_iteration, stationarity, free)) = best {
        if refined < report.refined.len() {
            report.stop_reason = format!(
                "{}; refining {} more fans did not lower ϖ_max, so the best iterate before \
                 that refinement is returned",
                report.stop_reason,
                report.refined.len() - refined
            );
        }
        report.refined.truncate(refined);
        current = mesh;
        report.best_iteration = best_iteration;
        report.stationarity = stationarity;
        report.free_vertices = free;
    } else {
        // No round ended with a valid mesh: the input is returned.
        report.best_iteration = 0;
    }
    // The verdict comes from the mesh core's own measure, not from the solver's numbers.
    (report.max_flattenability, report.stuck_vertices) = verdict(&current, params.tolerance);
    let mut flat = report.max_flattenability <= params.tolerance;
    if let (Some(k), true) = (keep, flat) {
        let h = crate::geometry::mean_edge_length(&current);
        let below: Vec<u32> = current
            .conn()
            .interior_vertices()
            .filter(|&v| !impossible.get(v as usize).copied().unwrap_or(false))
            .filter(|&v| {
                k.obstacle.clearance(current.position(v)).0 < k.clearance - CONTACT_TOLERANCE * h
            })
            .collect();
        if !below.is_empty() {
            flat = false;
            report.stop_reason = format!(
                "{}; {} free vertices still closer to the obstacle than the clearance (e.g. {})",
                report.stop_reason,
                below.len(),
                below[0]
            );
        }
    }
    report.converged = flat
        && match params.until {
            Until::Flattenable => true,
            Until::Stationary => report.stop_reason == "stationary",
        };
    if impossible.iter().any(|&b| b) && report.stop_reason != "cancelled" {
        report.stop_reason = format!(
            "{}; closed component(s) with Euler characteristic ≠ 0 cannot be flattenable (Gauss–Bonnet)",
            report.stop_reason
        );
    }
    Ok((current, report))
}

/// With `seams = free`: the boundary vertices of sewn cuts, grouped by position, each group
/// one unknown. A boundary edge is sewn when another boundary edge joins the same two
/// positions, and a boundary vertex is on a sewn cut when all its boundary edges are: the two
/// sides of a slit that `patches = uv` opened (its copies sit bit for bit where their vertex
/// is), its tip and its end on a seam, or a file's seam left unwelded. A group with a vertex
/// on the free boundary stays held. Sorted, so rows do not depend on hashing.
fn sewn_cuts(mesh: &Mesh) -> Vec<Vec<u32>> {
    use std::collections::HashMap;
    let conn = mesh.conn();
    let key = |v: u32| mesh.position(v).map(f64::to_bits);
    let nv = mesh.num_vertices();
    let (mut on_cut, mut held) = (vec![false; nv], vec![false; nv]);
    for group in crate::mesh::boundary_edges_by_position(mesh) {
        let sewn = group.len() >= 2;
        for e in group {
            for v in conn.edges()[e] {
                on_cut[v as usize] = true;
                held[v as usize] |= !sewn;
            }
        }
    }
    let mut groups: HashMap<[u64; 3], Vec<u32>> = HashMap::new();
    for v in (0..nv as u32).filter(|&v| on_cut[v as usize]) {
        groups.entry(key(v)).or_default().push(v);
    }
    let mut out: Vec<Vec<u32>> = groups
        .into_values()
        .filter(|g| g.iter().all(|&v| !held[v as usize]))
        .collect();
    out.sort_unstable();
    out
}

/// ϖ_max of `mesh` measured by `geometry`, and its interior vertices above `tolerance`, worst
/// first.
fn verdict(mesh: &Mesh, tolerance: f64) -> (f64, Vec<u32>) {
    let theta = crate::geometry::angle_sums(mesh);
    let varpi = crate::geometry::flattenability(mesh, &theta);
    let mut stuck: Vec<u32> = (0..varpi.len() as u32)
        .filter(|&v| varpi[v as usize] > tolerance)
        .collect();
    stuck.sort_by(|a, b| varpi[*b as usize].total_cmp(&varpi[*a as usize]));
    (varpi.iter().copied().fold(0.0, f64::max), stuck)
}

/// Vertices of closed components (no boundary or seam vertex) whose Euler characteristic is not
/// zero: Σ(2π − θ) = 2πχ there, so not every vertex can reach θ = 2π.
pub(crate) fn impossible_vertices(mesh: &Mesh) -> Vec<bool> {
    let nv = mesh.num_vertices();
    let mut sets = crate::mesh::disjoint::DisjointSets::new(nv);
    for t in mesh.triangles() {
        sets.union(t[0], t[1]);
        sets.union(t[1], t[2]);
    }
    let mut comp_v = vec![0i64; nv];
    let mut comp_f = vec![0i64; nv];
    let mut comp_e = vec![0i64; nv];
    let mut open = vec![false; nv];
    let kinds = mesh.conn().kinds();
    for v in 0..nv as u32 {
        if kinds[v as usize] == VertexKind::Unreferenced {
            continue;
        }
        let r = sets.find(v) as usize;
        comp_v[r] += 1;
        if kinds[v as usize] != VertexKind::Interior {
            open[r] = true;
        }
    }
    for t in mesh.triangles() {
        let r = sets.find(t[0]) as usize;
        comp_f[r] += 1;
    }
    for e in mesh.conn().edges() {
        let r = sets.find(e[0]) as usize;
        comp_e[r] += 1;
    }
    (0..nv as u32)
        .map(|v| {
            if kinds[v as usize] == VertexKind::Unreferenced {
                return false;
            }
            let r = sets.find(v) as usize;
            !open[r] && comp_v[r] - comp_e[r] + comp_f[r] != 0
        })
        .collect()
}

enum End {
    Done(String),
    Stalled(Vec<u32>),
}

/// What one refinement round's iterations read: the mesh (its connectivity), the input
/// surface for `anchor = closest`, the parameters and the caller's control.
#[derive(Clone, Copy)]
struct Round<'a> {
    mesh: &'a Mesh,
    grid: Option<&'a crate::spatial::TriangleBvh>,
    params: &'a Params,
    control: &'a dyn Control,
}

/// The KKT system of one mesh (fixed connectivity): pattern, symbolic LU, work arrays.
struct System<'a> {
    /// Free vertices, row r ↔ vertex free[r]: first the `nc` constrained ones (interior, not
    /// in an impossible component), then with `seams = free` the seam vertices, which move
    /// without a constraint of their own (θ kept at 2π, ∂θ at 0, λ at 0).
    free: Vec<u32>,
    nc: usize,
    n: usize,
    /// With `seams = free`, the vertices of a sewn cut that follow another: (vertex, the
    /// vertex whose row moves it).
    ties: Vec<(u32, u32)>,
    /// Per row, the neighbours whose mean J_fair pulls towards (`b_p`).
    fair_start: Vec<usize>,
    fair_ring: Vec<u32>,
    /// Unknowns: x, y, z, λ per free vertex (4n), and with an obstacle one body multiplier
    /// each (5n; row 4n + r, see `contact`).
    dim: usize,
    /// The obstacle's rows, when there is one.
    contact: Option<Contact<'a>>,
    /// Per row r: slots slot_start[r]..slot_start[r+1] hold vertex q = free[r] first, then its
    /// ring counter-clockwise; `slot_col` is the row of that vertex (NONE when fixed).
    slot_start: Vec<usize>,
    slot_vertex: Vec<u32>,
    slot_col: Vec<u32>,
    /// Where Λ's six values of a slot start in `values` (NONE when the column is fixed).
    slot_value: Vec<u32>,
    values: Vec<f64>,
    lu: Factor,
    /// Mean edge length: the length scale.
    h: f64,
    /// Current positions (all vertices).
    pos: Vec<[f64; 3]>,
    /// θ per row, gradients per slot, at `pos`.
    theta: Vec<f64>,
    grad: Vec<[f64; 3]>,
    /// Trial copies.
    trial_pos: Vec<[f64; 3]>,
    trial_theta: Vec<f64>,
    trial_grad: Vec<[f64; 3]>,
    /// Right-hand sides, solved together: normal [0; h̄·B_λ] in 0..4n, tangential [B_p; 0]
    /// in 4n..8n.
    rhs: Vec<f64>,
    force: Vec<[f64; 3]>,
    /// Step of a feasibility correction.
    correction: Vec<[f64; 3]>,
    stationarity: f64,
    /// Where the (2,2) block's diagonal starts in `values`, and the body rows' entries (seven
    /// per row: the gradient's three entries twice, below and above the diagonal, then it).
    reg_start: usize,
    body_start: usize,
    /// Best iterate of the round by ϖ_max.
    best_pos: Vec<[f64; 3]>,
    best_wmax: f64,
    /// The obstacle's residual at the best iterate (0 without one).
    best_body: f64,
    /// Shape guard: faces that touch a free vertex, the smallest corner angle each may take,
    /// edges (their two faces) that must not fold, and unit face normals of the trial.
    active_faces: Vec<u32>,
    floor: Vec<f64>,
    guarded_edges: Vec<[u32; 2]>,
    trial_normal: Vec<[f64; 3]>,
    /// Row of each vertex (NONE when fixed).
    row: Vec<u32>,
    /// H's entries (row, column) and values as built; `stiff` scales H symmetrically per row
    /// (H_rj · √(s_r s_j)) where trial steps kept folding an edge, so that the next steps
    /// spread the change instead of creasing there.
    h_pairs: Vec<(u32, u32)>,
    h_base: Vec<f64>,
    stiff: Vec<f64>,
    /// Rows of the vertices of edges the last trials would have folded.
    folding: Vec<u32>,
    /// `params.shape_guard`.
    guard: bool,
    /// Shape penalty: hinges (i, j, k, l: edge i–j, apexes k and l) near a free vertex with
    /// their onset φ⁰, and per row the penalty's force and the diagonal it adds to H.
    hinges: Vec<([u32; 4], f64)>,
    /// Shape penalty: faces with a free vertex and the onset of each corner.
    corners: Vec<([u32; 3], [f64; 3])>,
    penalty_force: Vec<[f64; 3]>,
    penalty_diag: Vec<f64>,
}

const REGULARISATION: f64 = 1e-10;
/// Rounding allowance below a vertex's obstacle floor, in mean edge lengths.
const CONTACT_SLACK: f64 = 1e-10;
/// A free vertex counts as clear of the obstacle within this many mean edge lengths below the
/// clearance (the active rows reach it to Newton accuracy, not exactly).
const CONTACT_TOLERANCE: f64 = 1e-6;
/// Rows within this many mean edge lengths above the clearance stay active once active.
const CONTACT_BAND: f64 = 0.05;
const MAX_REFINED_PER_ROUND: usize = 64;
/// Most feasibility corrections per iteration (each one triangular solve with the same factor).
const MAX_CORRECTIONS: usize = 4;
/// First Levenberg–Marquardt parameter μ, and the largest: at μ = 1e8 a step is a gradient
/// step of ~1e-8 of the violation, so refusing it means no step can help.
const MU_START: f64 = 1e-4;
/// Factor by which H's rows are stiffened around an edge a trial step folded, and the cap.
const STIFFEN: f64 = 4.0;
const STIFF_MAX: f64 = 1e6;
const MU_MAX: f64 = 1e8;
/// Most tangential (fairness) movement per iteration, in mean edge lengths.
const TANGENT_RADIUS: f64 = 0.5;

impl<'a> System<'a> {
    fn new(
        mesh: &Mesh,
        impossible: &[bool],
        params: &Params,
        keep: Option<(Keep<'a>, &[f64])>,
    ) -> Result<Self, AlgoError> {
        let conn = mesh.conn();
        let nv = mesh.num_vertices();
        let mut row = vec![NONE; nv];
        let mut free = Vec::new();
        for v in conn.interior_vertices() {
            if impossible.get(v as usize).copied().unwrap_or(false) {
                continue;
            }
            row[v as usize] = free.len() as u32;
            free.push(v);
        }
        let nc = free.len();
        if params.seams == Seams::Free {
            for v in 0..nv as u32 {
                if conn.kind(v) == VertexKind::Seam
                    && !impossible.get(v as usize).copied().unwrap_or(false)
                {
                    row[v as usize] = free.len() as u32;
                    free.push(v);
                }
            }
        }
        let mut ties = Vec::new();
        if params.seams == Seams::Free {
            for group in sewn_cuts(mesh) {
                row[group[0] as usize] = free.len() as u32;
                free.push(group[0]);
                for &m in &group[1..] {
                    row[m as usize] = row[group[0] as usize];
                    ties.push((m, group[0]));
                }
            }
        }
        let n = free.len();
        // The neighbours J_fair averages per row: a vertex's ring, a sewn cut's rings together.
        let mut fair_start = vec![0usize];
        let mut fair_ring: Vec<u32> = Vec::new();
        {
            let mut tied: Vec<Vec<u32>> = vec![Vec::new(); n];
            for &(m, rep) in &ties {
                tied[row[rep as usize] as usize].push(m);
            }
            for (r, &v) in free.iter().enumerate() {
                for &m in std::iter::once(&v).chain(&tied[r]) {
                    fair_ring.extend_from_slice(conn.ring_of(m));
                }
                fair_start.push(fair_ring.len());
            }
        }
        let fair_len = |r: usize| (fair_start[r + 1] - fair_start[r]) as f64;
        let mut entries: Vec<(usize, usize)> = Vec::new();
        let mut values: Vec<f64> = Vec::new();
        // H ⊗ I3 (Eq. 10): constant but for the stiffening of folding regions.
        let mut h_pairs: Vec<(u32, u32)> = Vec::new();
        for r in 0..n {
            let ring = &fair_ring[fair_start[r]..fair_start[r + 1]];
            let di = fair_len(r);
            for c in 0..3 {
                entries.push((c * n + r, c * n + r));
                values.push(params.w1 + params.w2);
                h_pairs.push((r as u32, r as u32));
                for &p in ring {
                    let j = row[p as usize];
                    if j != NONE && j as usize != r {
                        h_pairs.push((r as u32, j));
                        entries.push((c * n + r, c * n + j as usize));
                        values.push(match params.linear_solver {
                            LinearSolver::Lu => -params.w1 / di,
                            LinearSolver::Ldlt => -params.w1 / (di * fair_len(j as usize)).sqrt(),
                        });
                    }
                }
            }
        }
        let mut slot_start = vec![0usize];
        let mut slot_vertex = Vec::new();
        let mut slot_col = Vec::new();
        let mut slot_value = Vec::new();
        for (r, &v) in free.iter().enumerate() {
            for &p in std::iter::once(&v).chain(conn.ring_of(v)) {
                slot_vertex.push(p);
                let j = row[p as usize];
                slot_col.push(j);
                if j == NONE {
                    slot_value.push(NONE);
                    continue;
                }
                slot_value.push(values.len() as u32);
                let j = j as usize;
                for c in 0..3 {
                    entries.push((3 * n + r, c * n + j));
                    values.push(0.0);
                }
                for c in 0..3 {
                    entries.push((c * n + j, 3 * n + r));
                    values.push(0.0);
                }
            }
            slot_start.push(slot_vertex.len());
        }
        let reg_start = values.len();
        for r in 0..n {
            entries.push((3 * n + r, 3 * n + r));
            values.push(-REGULARISATION);
        }
        // Body rows (inactive: −μ_r = 0): the gradient's three entries then the diagonal.
        let body_start = values.len();
        let dim = if keep.is_some() { 5 * n } else { 4 * n };
        if keep.is_some() {
            for r in 0..n {
                for c in 0..3 {
                    entries.push((4 * n + r, c * n + r));
                    entries.push((c * n + r, 4 * n + r));
                    values.extend([0.0, 0.0]);
                }
                entries.push((4 * n + r, 4 * n + r));
                values.push(-1.0);
            }
        }
        let h = crate::geometry::mean_edge_length(mesh);
        if !(h > 0.0 && h.is_finite()) {
            return Err(AlgoError::Input(
                "mesh has no edge of positive length".into(),
            ));
        }
        let kkt = |e: crate::linalg::LinalgError| AlgoError::Input(format!("KKT system: {e}"));
        let lu = match params.linear_solver {
            LinearSolver::Lu => Factor::Lu(Box::new(LuSolver::new(dim, &entries).map_err(kkt)?)),
            LinearSolver::Ldlt => {
                let signs = (0..dim).map(|i| if i < 3 * n { 1 } else { -1 }).collect();
                // x, y, z, λ (and μ) of a vertex share their couplings: order them as one.
                let groups: Vec<u32> = (0..dim).map(|i| (i % n) as u32).collect();
                Factor::Ldlt(Box::new(
                    LdltSolver::new(dim, &entries, signs, Some(&groups)).map_err(kkt)?,
                ))
            }
        };
        let ns = slot_vertex.len();
        let (active_faces, floor, guarded_edges) = shape_guard(mesh, &row, params);
        let h_base = values[..h_pairs.len()].to_vec();
        let (hinges, corners) = if params.shape_penalty > 0.0 {
            (hinges(mesh, &row), corners(mesh, &active_faces))
        } else {
            (Vec::new(), Vec::new())
        };
        let contact = keep
            .map(|(k, floors)| Contact::new(k, &free, floors, mesh.positions(), CONTACT_SLACK * h));
        Ok(System {
            dim,
            contact,
            body_start,
            free,
            nc,
            n,
            ties,
            fair_start,
            fair_ring,
            slot_start,
            slot_vertex,
            slot_col,
            slot_value,
            values,
            lu,
            h,
            pos: mesh.positions().to_vec(),
            theta: vec![TAU; n],
            grad: vec![[0.0; 3]; ns],
            trial_pos: mesh.positions().to_vec(),
            trial_theta: vec![TAU; n],
            trial_grad: vec![[0.0; 3]; ns],
            rhs: vec![0.0; 2 * dim],
            force: vec![[0.0; 3]; n],
            correction: vec![[0.0; 3]; n],
            stationarity: 0.0,
            reg_start,
            best_pos: mesh.positions().to_vec(),
            best_wmax: f64::INFINITY,
            best_body: f64::INFINITY,
            active_faces,
            floor,
            guarded_edges,
            trial_normal: crate::geometry::face_normals(mesh),
            row,
            h_pairs,
            h_base,
            stiff: vec![1.0; n],
            folding: Vec::new(),
            guard: params.shape_guard,
            hinges,
            corners,
            penalty_force: vec![[0.0; 3]; n],
            penalty_diag: vec![0.0; n],
        })
    }

    /// Newton iterations on the current connectivity. Leaves the best iterate of the round (by
    /// ϖ_max, the latest among flattenable ones) in `pos`, `theta` and `grad`.
    fn iterate(
        &mut self,
        round: &Round<'_>,
        anchors: &mut [[f64; 3]],
        report: &mut Report,
    ) -> Result<End, AlgoError> {
        let end = self.iterate_inner(round, anchors, report);
        let (w, _, b) = self.merit(false);
        let tol = round.params.tolerance;
        if better(self.best_wmax, self.best_body, w, b, tol)
            && (self.best_wmax, self.best_body) != (w, b)
        {
            std::mem::swap(&mut self.pos, &mut self.best_pos);
            eval(
                &self.pos,
                round.mesh.triangles(),
                round.mesh.conn(),
                &self.free[..self.nc],
                &self.slot_start,
                &mut self.theta,
                &mut self.grad,
            );
        }
        end
    }

    fn iterate_inner(
        &mut self,
        round: &Round<'_>,
        anchors: &mut [[f64; 3]],
        report: &mut Report,
    ) -> Result<End, AlgoError> {
        let Round {
            mesh,
            grid,
            params,
            control,
        } = *round;
        let tris = mesh.triangles();
        let conn = mesh.conn();
        let n = self.n;
        eval(
            &self.pos,
            tris,
            conn,
            &self.free[..self.nc],
            &self.slot_start,
            &mut self.theta,
            &mut self.grad,
        );
        let (mut wmax, mut c2, mut body) = self.merit(false);
        self.best_pos.clone_from(&self.pos);
        self.best_wmax = wmax;
        self.best_body = body;
        if n == 0 {
            return Ok(End::Done("no free interior vertex".into()));
        }
        let mut lambda = vec![0.0; n];
        let mut delta = vec![[0.0; 3]; n];
        let mut dn = vec![[0.0; 3]; n];
        let mut dt = vec![[0.0; 3]; n];
        let mut window: std::collections::VecDeque<f64> = Default::default();
        let mut high_streak = vec![0usize; n];
        let mut last_step: Option<f64> = None;
        // Levenberg–Marquardt parameter: the (2,2) block is −μ I, so the normal step minimises
        // ‖c − Λδ‖² + μ δᵀHδ (c = 2π − θ). Nielsen's update from the ratio ρ of actual to
        // predicted decrease of ‖c‖²; a rejected step multiplies μ by ν, which doubles.
        let (mut mu, mut nu) = match params.step_rule {
            StepRule::Merit | StepRule::Lm => (MU_START, 2.0),
            StepRule::Fixed => (REGULARISATION, 2.0),
        };
        // Weight of the tangential (fairing) part with `until = flattenable`: halved whenever
        // ϖ_max did not fall over an iteration, so that the fairing, which only shapes the
        // path there, cannot keep undoing the normal steps.
        let mut fair = 1.0f64;
        let mut prev_wmax = f64::INFINITY;
        loop {
            if control.cancelled_before(self.lu.predicted_factor_seconds()) {
                return Err(AlgoError::Cancelled);
            }
            // With an obstacle, done also means every free vertex at the clearance or beyond.
            let flat = wmax <= params.tolerance
                && match &mut self.contact {
                    Some(ct) => ct.satisfied(&self.pos, CONTACT_TOLERANCE * self.h),
                    None => true,
                };
            if flat && params.until == Until::Flattenable {
                return Ok(End::Done("flattenable".into()));
            }
            if let Some(s) = last_step {
                if s < params.step_tolerance {
                    if flat {
                        return Ok(End::Done("stationary".into()));
                    }
                    report.stop_reason = "stalled: step below step_tolerance".into();
                    return Ok(End::Stalled(self.stuck(&high_streak, params)));
                }
            }
            if report.iterations >= params.max_iterations {
                return Ok(if flat {
                    End::Done("max_iterations".into())
                } else {
                    report.stop_reason = "max_iterations".into();
                    End::Stalled(Vec::new())
                });
            }
            for (r, t) in self.theta.iter().enumerate() {
                let w = (TAU - t).abs();
                if w >= 0.1 * wmax && w > params.tolerance {
                    high_streak[r] += 1;
                } else {
                    high_streak[r] = 0;
                }
            }
            // Stall: ϖ_max (with an obstacle, the larger of it and the obstacle's residual)
            // has not halved over the window.
            let progress = wmax.max(body);
            window.push_back(progress);
            if window.len() > params.stall_iterations {
                let old = window.pop_front().unwrap_or(progress);
                if !flat && progress > 0.5 * old {
                    report.stop_reason = "stalled: ϖ_max did not halve".into();
                    return Ok(End::Stalled(self.stuck(&high_streak, params)));
                }
            }
            if let Some(g) = grid {
                for &v in &self.free {
                    anchors[v as usize] = g.closest(self.pos[v as usize]).0;
                }
            }
            if params.until == Until::Flattenable && progress >= prev_wmax {
                fair *= 0.5;
            }
            prev_wmax = progress;
            if let Some(ct) = &mut self.contact {
                ct.choose(&self.pos, CONTACT_BAND * self.h);
            }
            self.assemble(anchors, params, mu);
            let mut solved = self
                .lu
                .factor(&self.values)
                .and_then(|_| self.lu.solve_two_in_place(&mut self.rhs));
            // The obstacle's active set: drop rows that pull inwards, add predicted crossings.
            for _ in 0..contact::ACTIVE_SET_ROUNDS {
                if solved.is_err() || !self.revise_contact(fair) {
                    break;
                }
                self.assemble(anchors, params, mu);
                solved = self
                    .lu
                    .factor(&self.values)
                    .and_then(|_| self.lu.solve_two_in_place(&mut self.rhs));
            }
            report.iterations += 1;
            if let Err(e) = solved {
                if params.step_rule != StepRule::Fixed && mu < MU_MAX {
                    mu = (mu * 100.0).min(MU_MAX);
                    self.push_history(report, control, wmax, 0.0, 0.0, 0, mu);
                    continue;
                }
                report.stop_reason = format!("linear solve failed: {e}");
                return Ok(End::Stalled(self.stuck(&high_streak, params)));
            }
            let h = self.h;
            let mut step_norm = 0.0f64;
            let mut tan_norm = 0.0f64;
            for r in 0..n {
                dn[r] = [self.rhs[r], self.rhs[n + r], self.rhs[2 * n + r]];
                let t = &self.rhs[self.dim..];
                dt[r] = [t[r], t[n + r], t[2 * n + r]];
                let d = [0, 1, 2].map(|c| dn[r][c] + dt[r][c]);
                step_norm = step_norm.max(dot(d, d).sqrt());
                tan_norm = tan_norm.max(dot(dt[r], dt[r]).sqrt());
                lambda[r] = h * t[3 * n + r];
            }
            step_norm /= h;
            tan_norm /= h;
            self.stationarity = self.force_residual_max(anchors, &lambda, params, false);
            let (alpha, corrections) = match params.step_rule {
                StepRule::Fixed => {
                    for r in 0..n {
                        delta[r] = [0, 1, 2].map(|c| dn[r][c] + dt[r][c]);
                    }
                    if !self.try_step(tris, conn, &delta, params.tau) {
                        report.stop_reason = "the fixed step degenerates, turns over, folds a \
                                              triangle or takes a vertex into the obstacle"
                            .into();
                        return Ok(End::Stalled(self.stuck(&high_streak, params)));
                    }
                    self.accept_trial();
                    (params.tau, 0)
                }
                StepRule::Merit => {
                    // Trials: the full normal step with the tangential one shrinking to
                    // nothing, then shorter normal steps. Accept the first that passes the
                    // shape guard and lowers ‖2π − θ‖₂ by the Armijo rule, or reaches half the
                    // tolerance; if none does, take the guarded trial with the lowest ϖ_max
                    // (non-monotone: the best iterate is kept aside, so the output is never
                    // worse) and shift harder.
                    let s = fair * (TANGENT_RADIUS / tan_norm.max(TANGENT_RADIUS));
                    // The normal step is trusted over at most `step_radius` mean edge lengths.
                    // (μ's rule below then sees the scaled length: a capped full step counts as
                    // a shortened one; this is how it was measured.)
                    let cap = match params.step_radius {
                        r if r > 0.0 => {
                            let reach =
                                (0..n).map(|r| dot(dn[r], dn[r]).sqrt()).fold(0.0, f64::max);
                            (r * h / reach.max(r * h)).min(1.0)
                        }
                        _ => 1.0,
                    };
                    const TRIALS: [(f64, f64); 9] = [
                        (1.0, 1.0),
                        (1.0, 0.5),
                        (1.0, 0.25),
                        (1.0, 0.0),
                        (0.5, 0.0),
                        (0.25, 0.0),
                        (0.125, 0.0),
                        (0.0625, 0.0),
                        (0.015625, 0.0),
                    ];
                    let mut best = (f64::INFINITY, (0.0, 0.0));
                    let mut accepted = None;
                    for &(an, at) in &TRIALS {
                        let an = an * cap;
                        for r in 0..n {
                            delta[r] = [0, 1, 2].map(|c| an * dn[r][c] + at * s * dt[r][c]);
                        }
                        if !self.try_step(tris, conn, &delta, 1.0) {
                            continue;
                        }
                        let (w, c1, b1) = self.merit(true);
                        if c1 <= (1.0 - 1e-4 * an) * c2
                            || (w <= 0.5 * params.tolerance && b1 <= body)
                        {
                            accepted = Some(an);
                            break;
                        }
                        if w < best.0 {
                            best = (w, (an, at * s));
                        }
                    }
                    // The shift biases the normal step's residual by about μ·λ, so it must not
                    // ratchet up on every shortened step: it shrinks after a full step, stays
                    // after a step of ≥ 1/4, and grows when the linearisation failed.
                    mu = match accepted {
                        Some(a) if a >= 1.0 => (mu * 0.1).max(REGULARISATION),
                        Some(a) if a >= 0.25 => mu,
                        _ => (mu * 10.0).min(MU_MAX),
                    };
                    let alpha = match accepted {
                        Some(a) => a,
                        None if best.0.is_finite() => {
                            let (an, at) = best.1;
                            for r in 0..n {
                                delta[r] = [0, 1, 2].map(|c| an * dn[r][c] + at * dt[r][c]);
                            }
                            self.try_step(tris, conn, &delta, 1.0);
                            an
                        }
                        None => 0.0,
                    };
                    if alpha > 0.0 {
                        self.accept_trial();
                        (alpha, self.correct(tris, conn, params))
                    } else {
                        if mu >= MU_MAX {
                            report.stop_reason =
                                "stalled: every step degenerates or folds a triangle".into();
                            return Ok(End::Stalled(self.stuck(&high_streak, params)));
                        }
                        (0.0, 0)
                    }
                }
                StepRule::Lm => {
                    // The fairness part may ask to move far (the uniform Laplacian also
                    // redistributes vertices); its linearisation of θ is trusted over at most
                    // half a mean edge length per iteration.
                    let s = fair * (TANGENT_RADIUS / tan_norm.max(TANGENT_RADIUS));
                    let trials: [(f64, f64); 3] = [(1.0, s), (1.0, 0.0), (0.5, 0.0)];
                    let mut accepted = None;
                    self.folding.clear();
                    for (k, &(an, at)) in trials.iter().enumerate() {
                        if k == 1 && at == 0.0 && trials[0].1 == 0.0 {
                            continue;
                        }
                        for r in 0..n {
                            delta[r] = [0, 1, 2].map(|c| an * dn[r][c] + at * dt[r][c]);
                        }
                        // Levenberg–Marquardt models ‖2π − θ‖ alone (not the obstacle's rows).
                        let c2 = violation(&self.theta).1;
                        let predicted = c2 * c2 - self.linearised_violation(&delta);
                        if !self.try_step(tris, conn, &delta, 1.0) {
                            continue;
                        }
                        let (w1, c1) = violation(&self.trial_theta);
                        let rho = (c2 * c2 - c1 * c1) / predicted.max(f64::MIN_POSITIVE);
                        if rho > 1e-4 || w1 <= 0.5 * params.tolerance {
                            accepted = Some((an, rho));
                            break;
                        }
                    }
                    match accepted {
                        Some((an, rho)) => {
                            if an >= 1.0 {
                                let f = 1.0 - (2.0 * rho.min(1.0) - 1.0).powi(3);
                                mu = (mu * f.max(1.0 / 3.0)).max(REGULARISATION);
                            }
                            nu = 2.0;
                            self.accept_trial();
                            (an, self.correct(tris, conn, params))
                        }
                        None => {
                            if mu >= MU_MAX {
                                report.stop_reason =
                                    "stalled: no step lowers ‖2π − θ‖ without folding".into();
                                return Ok(End::Stalled(self.stuck(&high_streak, params)));
                            }
                            if !self.stiffen_folding() {
                                mu = (mu * nu).min(MU_MAX);
                                nu *= 2.0;
                            }
                            (0.0, 0)
                        }
                    }
                }
            };
            (wmax, c2, body) = self.merit(false);
            if alpha > 0.0 {
                last_step = Some(alpha * step_norm);
            }
            if better(wmax, body, self.best_wmax, self.best_body, params.tolerance) {
                self.best_pos.copy_from_slice(&self.pos);
                self.best_wmax = wmax;
                self.best_body = body;
                report.best_iteration = report.iterations;
            }
            self.push_history(
                report,
                control,
                prev_wmax,
                step_norm,
                alpha,
                corrections,
                mu,
            );
        }
    }

    /// Fill Λ (Eq. 11–13, scaled by h̄ so that every block is O(1)), the two right-hand sides
    /// (normal [0; h̄·B_λ] of Eq. 9 and tangential [B_p; 0] of Eq. 8: Eq. 7 is linear in B, so
    /// their solutions add up to the paper's δ) and the (2,2) block −μ I.
    fn assemble(&mut self, anchors: &[[f64; 3]], params: &Params, mu: f64) {
        let n = self.n;
        let h = self.h;
        for r in 0..n {
            for s in self.slot_start[r]..self.slot_start[r + 1] {
                let k = self.slot_value[s];
                if k == NONE {
                    continue;
                }
                let g = self.grad[s];
                let k = k as usize;
                for c in 0..3 {
                    self.values[k + c] = h * g[c];
                    self.values[k + 3 + c] = h * g[c];
                }
            }
        }
        let dim = self.dim;
        for (r, &v) in self.free.iter().enumerate() {
            let ring = &self.fair_ring[self.fair_start[r]..self.fair_start[r + 1]];
            let b = b_p(&self.pos, anchors, ring, v, params);
            for c in 0..3 {
                self.rhs[c * n + r] = 0.0;
                self.rhs[dim + c * n + r] = b[c];
            }
            self.rhs[3 * n + r] = h * (TAU - self.theta[r]);
            self.rhs[dim + 3 * n + r] = 0.0;
        }
        for v in &mut self.values[self.reg_start..self.body_start] {
            *v = -mu;
        }
        // A seam row has no constraint: λ = 0 exactly.
        for v in &mut self.values[self.reg_start + self.nc..self.reg_start + n] {
            *v = -1.0;
        }
        self.fill_contact();
        self.shape_penalty(params.shape_penalty);
        for (r, f) in self.penalty_force.iter().enumerate() {
            for c in 0..3 {
                self.rhs[c * n + r] = f[c];
            }
        }
        for (k, &(r, j)) in self.h_pairs.iter().enumerate() {
            self.values[k] =
                self.h_base[k] * (self.stiff[r as usize] * self.stiff[j as usize]).sqrt();
            if r == j {
                self.values[k] += self.penalty_diag[r as usize];
            }
        }
    }

    /// The obstacle's rows (see `contact`): an active row r is ∇s·δ_r − ε μ_r = c − s, an
    /// inactive one −μ_r = 0; the tangential right-hand side is 0 in both, so the fairing part
    /// of a step slides along an active constraint.
    fn fill_contact(&mut self) {
        let Some(ct) = &self.contact else {
            return;
        };
        let (n, dim) = (self.n, self.dim);
        for r in 0..n {
            let k = self.body_start + 7 * r;
            let (g, target, diag) = match ct.row(r) {
                Some((g, target)) => (g, target, -REGULARISATION),
                None => ([0.0; 3], 0.0, -1.0),
            };
            for c in 0..3 {
                self.values[k + 2 * c] = g[c];
                self.values[k + 2 * c + 1] = g[c];
            }
            self.values[k + 6] = diag;
            self.rhs[4 * n + r] = target;
            self.rhs[dim + 4 * n + r] = 0.0;
        }
    }

    /// One round of the obstacle's active set after a solve (the full step: normal part plus
    /// the tangential part as the merit rule first tries it). True when the set changed.
    fn revise_contact(&mut self, fair: f64) -> bool {
        let (n, dim) = (self.n, self.dim);
        let Some(ct) = &mut self.contact else {
            return false;
        };
        let t = &self.rhs[dim..];
        let tan_norm = (0..n)
            .map(|r| (t[r] * t[r] + t[n + r] * t[n + r] + t[2 * n + r] * t[2 * n + r]).sqrt())
            .fold(0.0, f64::max)
            / self.h;
        let scale = fair * (TANGENT_RADIUS / tan_norm.max(TANGENT_RADIUS));
        ct.revise(&self.pos, &self.rhs, dim, scale)
    }

    /// The shape penalty ½ κ h̄² (Σ (φ − φ⁰)₊² + Σ (α⁰ − α)₊²) at `pos`: its force −∇ into
    /// `penalty_force` and the diagonal of its Gauss–Newton Hessian (κ h̄² |∇_v φ|² per vertex and
    /// coordinate, likewise for α: the couplings between a hinge's or a triangle's vertices
    /// are left out, which keeps H's pattern) into `penalty_diag`. It enters the normal
    /// right-hand side, so the shortened steps of the merit rule shorten it too but the
    /// fairing weight does not.
    fn shape_penalty(&mut self, kappa: f64) {
        self.penalty_force.fill([0.0; 3]);
        self.penalty_diag.fill(0.0);
        let k = kappa * self.h * self.h;
        for &(v, onset) in &self.hinges {
            let p = v.map(|i| self.pos[i as usize]);
            let (phi, g) = crate::geometry::turning_angle_gradient(p[0], p[1], p[2], p[3]);
            if phi <= onset {
                continue;
            }
            for (q, gq) in v.iter().zip(g) {
                let r = self.row[*q as usize];
                if r == NONE {
                    continue;
                }
                let r = r as usize;
                for c in 0..3 {
                    self.penalty_force[r][c] -= k * (phi - onset) * gq[c];
                }
                self.penalty_diag[r] += k * dot(gq, gq);
            }
        }
        for &(t, onset) in &self.corners {
            for i in 0..3 {
                let q = [t[i], t[(i + 1) % 3], t[(i + 2) % 3]];
                let [a, b, c] = q.map(|v| self.pos[v as usize]);
                let alpha = corner_angle(a, b, c);
                if alpha >= onset[i] || cross(sub(b, a), sub(c, a)) == [0.0; 3] {
                    continue;
                }
                let (gb, gc) = corner_angle_gradient(a, b, c);
                let ga = [0, 1, 2].map(|x| -gb[x] - gc[x]);
                for (v, g) in q.iter().zip([ga, gb, gc]) {
                    let r = self.row[*v as usize];
                    if r == NONE {
                        continue;
                    }
                    let r = r as usize;
                    for x in 0..3 {
                        self.penalty_force[r][x] += k * (onset[i] - alpha) * g[x];
                    }
                    self.penalty_diag[r] += k * dot(g, g);
                }
            }
        }
    }

    /// Stiffen the rows of edges that trials folded (and forget them); true when any was.
    fn stiffen_folding(&mut self) -> bool {
        let any = !self.folding.is_empty();
        self.folding.sort_unstable();
        self.folding.dedup();
        for &r in &self.folding {
            self.stiff[r as usize] = (self.stiff[r as usize] * STIFFEN).min(STIFF_MAX);
        }
        self.folding.clear();
        any
    }

    /// The merit of the current state or the last trial: (ϖ_max, ℓ2 of 2π − θ together with
    /// the obstacle's residual ‖(c − s)₊‖/h̄, that residual alone).
    fn merit(&self, trial: bool) -> (f64, f64, f64) {
        let (w, c) = violation(if trial {
            &self.trial_theta
        } else {
            &self.theta
        });
        match &self.contact {
            Some(ct) => {
                let b = ct.residual(trial, self.h);
                (w, c.hypot(b), b)
            }
            None => (w, c, 0.0),
        }
    }

    /// ‖2π − θ − Λδ‖²: the violation the linearisation predicts after the step δ.
    fn linearised_violation(&self, delta: &[[f64; 3]]) -> f64 {
        let mut sum = 0.0;
        for r in 0..self.n {
            let mut lin = TAU - self.theta[r];
            for s in self.slot_start[r]..self.slot_start[r + 1] {
                let j = self.slot_col[s];
                if j != NONE {
                    lin -= dot(self.grad[s], delta[j as usize]);
                }
            }
            sum += lin * lin;
        }
        sum
    }

    /// Make the trial state (left by `try_step`) the current one.
    fn accept_trial(&mut self) {
        std::mem::swap(&mut self.pos, &mut self.trial_pos);
        std::mem::swap(&mut self.theta, &mut self.trial_theta);
        std::mem::swap(&mut self.grad, &mut self.trial_grad);
        if let Some(ct) = &mut self.contact {
            ct.accept_trial();
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn push_history(
        &self,
        report: &mut Report,
        control: &dyn Control,
        wmax: f64,
        step_norm: f64,
        alpha: f64,
        corrections: usize,
        mu: f64,
    ) {
        report.history.push(HistoryEntry {
            iteration: report.iterations,
            max_flattenability: wmax,
            step_norm,
            step_length: alpha,
            corrections,
            damping: mu,
        });
        control.progress(&Progress {
            stage: "newton".into(),
            iteration: report.iterations,
            max_flattenability: Some(self.best_wmax),
            step_norm: Some(step_norm),
        });
    }

    /// Feasibility corrections with the factorisation already computed (a chord / second-order
    /// correction step): solve Eq. 7 for [0; h̄·(2π − θ)] at the new point with the old Λ and
    /// move by the result, while the violation ‖2π − θ‖₂ at least halves. The tangential
    /// (fairing) part of a step leaves a violation of second order in its length; these
    /// solves remove it for the cost of a triangular solve each instead of a factorisation.
    /// Returns how many were taken. Only normal steps are added, so the stationary point is
    /// unchanged.
    fn correct(
        &mut self,
        tris: &[[u32; 3]],
        conn: &crate::mesh::Connectivity,
        params: &Params,
    ) -> usize {
        let n = self.n;
        let h = self.h;
        let mut taken = 0;
        // Corrections hold the obstacle's rows, so they are judged by ‖2π − θ‖ alone.
        let (mut wmax, mut c0) = violation(&self.theta);
        while taken < MAX_CORRECTIONS {
            if wmax <= 0.5 * params.tolerance {
                break;
            }
            for r in 0..n {
                for c in 0..3 {
                    self.rhs[c * n + r] = 0.0;
                }
                self.rhs[3 * n + r] = h * (TAU - self.theta[r]);
            }
            // Active obstacle rows hold still (to first order); inactive ones are −μ = 0.
            self.rhs[4 * n..self.dim].fill(0.0);
            if self.lu.solve_in_place(&mut self.rhs[..self.dim]).is_err() {
                break;
            }
            let mut step = std::mem::take(&mut self.correction);
            for r in 0..n {
                step[r] = [0, 1, 2].map(|c| self.rhs[c * n + r]);
            }
            let valid = self.try_step(tris, conn, &step, 1.0);
            self.correction = step;
            let (w1, c1) = violation(&self.trial_theta);
            // Halving in ℓ2; never into a degenerate or flipped state.
            if !valid || c1.is_nan() || c1 > 0.5 * c0 {
                break;
            }
            self.accept_trial();
            (wmax, c0) = (w1, c1);
            taken += 1;
        }
        taken
    }

    /// Vertices whose ϖ stayed high through the stall window, worst first; else the worst one.
    fn stuck(&self, high_streak: &[usize], params: &Params) -> Vec<u32> {
        let w: Vec<f64> = self.theta.iter().map(|t| (TAU - t).abs()).collect();
        let wmax = w.iter().copied().fold(0.0, f64::max);
        let mut out: Vec<u32> = (0..self.n)
            .filter(|&r| high_streak[r] >= params.stall_iterations && w[r] > params.tolerance)
            .filter(|&r| w[r] >= 0.5 * wmax)
            .map(|r| r as u32)
            .collect();
        if out.is_empty() {
            if let Some(r) = (0..self.n).max_by(|a, b| w[*a].total_cmp(&w[*b])) {
                if w[r] > params.tolerance {
                    out.push(r as u32);
                }
            }
        }
        out.sort_by(|a, b| w[*b as usize].total_cmp(&w[*a as usize]));
        out.truncate(MAX_REFINED_PER_ROUND);
        out.into_iter().map(|r| self.free[r as usize]).collect()
    }

    /// Set trial_pos = pos + α δ and evaluate θ and its gradients there. Returns false when a
    /// triangle degenerates or turns over.
    fn try_step(
        &mut self,
        tris: &[[u32; 3]],
        conn: &crate::mesh::Connectivity,
        delta: &[[f64; 3]],
        alpha: f64,
    ) -> bool {
        self.trial_pos.copy_from_slice(&self.pos);
        for (r, &v) in self.free.iter().enumerate() {
            let p = &mut self.trial_pos[v as usize];
            for c in 0..3 {
                p[c] += alpha * delta[r][c];
            }
        }
        for &(m, rep) in &self.ties {
            self.trial_pos[m as usize] = self.trial_pos[rep as usize];
        }
        eval(
            &self.trial_pos,
            tris,
            conn,
            &self.free[..self.nc],
            &self.slot_start,
            &mut self.trial_theta,
            &mut self.trial_grad,
        );
        if !self.trial_valid(tris) {
            return false;
        }
        match &mut self.contact {
            Some(ct) => ct.check_trial(&self.pos, &self.trial_pos),
            None => true,
        }
    }

    /// The shape guard on the trial: no triangle touching a free vertex degenerates, turns over
    /// relative to `pos` or gets a corner below its floor, and no guarded edge folds.
    fn trial_valid(&mut self, tris: &[[u32; 3]]) -> bool {
        let tiny = 1e-12 * self.h * self.h;
        for (k, &f) in self.active_faces.iter().enumerate() {
            let t = tris[f as usize];
            let p = |q: &[[f64; 3]], i: usize| q[t[i] as usize];
            let (a, b, c) = (
                p(&self.trial_pos, 0),
                p(&self.trial_pos, 1),
                p(&self.trial_pos, 2),
            );
            let n1 = cross(sub(b, a), sub(c, a));
            let n0 = cross(
                sub(p(&self.pos, 1), p(&self.pos, 0)),
                sub(p(&self.pos, 2), p(&self.pos, 0)),
            );
            let a1 = dot(n1, n1).sqrt();
            if a1.is_nan()
                || a1 <= tiny
                || dot(n1, n0) <= 0.0
                || crate::mesh::is_degenerate_triangle(a, b, c)
            {
                return false;
            }
            if !self.guard {
                continue;
            }
            let floor = self.floor[k];
            if corner_angle(a, b, c) < floor
                || corner_angle(b, c, a) < floor
                || corner_angle(c, a, b) < floor
            {
                return false;
            }
            self.trial_normal[f as usize] = [n1[0] / a1, n1[1] / a1, n1[2] / a1];
        }
        let limit = crate::geometry::FOLD_ANGLE.cos();
        for &[f, g] in self.guarded_edges.iter().filter(|_| self.guard) {
            if dot(self.trial_normal[f as usize], self.trial_normal[g as usize]) < limit {
                for v in tris[f as usize].iter().chain(&tris[g as usize]) {
                    let r = self.row[*v as usize];
                    if r != NONE {
                        self.folding.push(r);
                    }
                }
                return false;
            }
        }
        self.trial_theta.iter().all(|t| t.is_finite())
    }

    fn force_residual_max(
        &mut self,
        anchors: &[[f64; 3]],
        lambda: &[f64],
        params: &Params,
        trial: bool,
    ) -> f64 {
        self.fill_force(anchors, lambda, params, trial);
        self.force
            .iter()
            .map(|f| dot(*f, *f).sqrt())
            .fold(0.0, f64::max)
            / self.h
    }

    /// force_r = B_p(v_r) − (Λᵀλ)_r.
    fn fill_force(&mut self, anchors: &[[f64; 3]], lambda: &[f64], params: &Params, trial: bool) {
        let (pos, grad) = if trial {
            (&self.trial_pos, &self.trial_grad)
        } else {
            (&self.pos, &self.grad)
        };
        for (r, &v) in self.free.iter().enumerate() {
            let ring = &self.fair_ring[self.fair_start[r]..self.fair_start[r + 1]];
            self.force[r] = b_p(pos, anchors, ring, v, params);
        }
        for r in 0..self.n {
            let l = lambda[r];
            for s in self.slot_start[r]..self.slot_start[r + 1] {
                let j = self.slot_col[s];
                if j == NONE {
                    continue;
                }
                let f = &mut self.force[j as usize];
                for c in 0..3 {
                    f[c] -= l * grad[s][c];
                }
            }
        }
        debug_assert_eq!(self.slot_vertex.len(), grad.len());
    }
}

enum Factor {
    Lu(Box<LuSolver>),
    Ldlt(Box<LdltSolver>),
}

impl Factor {
    fn factor(&mut self, values: &[f64]) -> Result<(), LinalgError> {
        match self {
            Factor::Lu(s) => s.factor(values),
            Factor::Ldlt(s) => s.factor(values),
        }
    }
    /// Expected seconds of the next factorisation (0 when unknown: the LU's fill is only known
    /// after pivoting).
    fn predicted_factor_seconds(&self) -> f64 {
        match self {
            Factor::Lu(_) => 0.0,
            Factor::Ldlt(s) => s.predicted_factor_seconds(),
        }
    }
    fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<(), LinalgError> {
        match self {
            Factor::Lu(s) => s.solve_in_place(rhs),
            Factor::Ldlt(s) => s.solve_in_place(rhs),
        }
    }
    /// Two right-hand sides stored one after the other.
    fn solve_two_in_place(&mut self, rhs: &mut [f64]) -> Result<(), LinalgError> {
        match self {
            Factor::Lu(s) => {
                let (a, b) = rhs.split_at_mut(rhs.len() / 2);
                s.solve_in_place(a).and_then(|_| s.solve_in_place(b))
            }
            Factor::Ldlt(s) => s.solve_many_in_place(rhs, 2),
        }
    }
}

/// Whether an iterate with ϖ_max `w` and obstacle residual `b` is at least as good as one with
/// (`w0`, `b0`): among flattenable ones (ϖ_max ≤ `tol`) the one no farther inside the
/// obstacle (so without one the latest flattenable iterate wins), else the lower ϖ_max.
fn better(w: f64, b: f64, w0: f64, b0: f64, tol: f64) -> bool {
    match (w <= tol, w0 <= tol) {
        (true, true) => b <= b0,
        (true, false) => true,
        (false, true) => false,
        (false, false) => w < w0,
    }
}

/// Constraint violation 2π − θ (Eq. 9's B_λ): (max, ℓ2 norm).
fn violation(theta: &[f64]) -> (f64, f64) {
    let (m, q) = theta.iter().fold((0.0f64, 0.0f64), |(m, q), t| {
        let d = (TAU - t).abs();
        (m.max(d), q + d * d)
    });
    (m, q.sqrt())
}

/// B_p of Eq. 8 at vertex v.
#[inline]
fn b_p(pos: &[[f64; 3]], anchors: &[[f64; 3]], ring: &[u32], v: u32, params: &Params) -> [f64; 3] {
    let mut avg = [0.0; 3];
    for &q in ring {
        for c in 0..3 {
            avg[c] += pos[q as usize][c];
        }
    }
    let k = 1.0 / ring.len() as f64;
    let p = pos[v as usize];
    let a = anchors[v as usize];
    [0, 1, 2].map(|c| -params.w1 * (p[c] - avg[c] * k) - params.w2 * (p[c] - a[c]))
}

/// θ at every free vertex and ∂θ_q/∂(q and ring) at its slots (Prop. 1, 2; same sums as
/// `geometry::theta_gradient`, on a position slice).
#[allow(clippy::too_many_arguments)]
fn eval(
    pos: &[[f64; 3]],
    tris: &[[u32; 3]],
    conn: &crate::mesh::Connectivity,
    free: &[u32],
    slot_start: &[usize],
    theta: &mut [f64],
    grad: &mut [[f64; 3]],
) {
    for (r, &q) in free.iter().enumerate() {
        let base = slot_start[r];
        let ring_len = slot_start[r + 1] - base - 1;
        for g in &mut grad[base..slot_start[r + 1]] {
            *g = [0.0; 3];
        }
        let pq = pos[q as usize];
        let mut th = 0.0;
        for (j, &hc) in conn.fan_of(q).iter().enumerate() {
            let t = tris[hc as usize / 3];
            let k = hc as usize % 3;
            let pb = pos[t[(k + 1) % 3] as usize];
            let pc = pos[t[(k + 2) % 3] as usize];
            th += corner_angle(pq, pb, pc);
            let (gb, gc) = corner_angle_gradient(pq, pb, pc);
            let jb = base + 1 + j;
            let jc = base + 1 + (j + 1) % ring_len;
            for i in 0..3 {
                grad[jb][i] += gb[i];
                grad[jc][i] += gc[i];
                grad[base][i] -= gb[i] + gc[i];
            }
        }
        theta[r] = th;
    }
}

/// What the shape guard checks on `mesh` with free vertices `row != NONE`: the faces touching
/// a free vertex with each one's angle floor (the smaller of `min_angle` and its own smallest
/// angle now, so a face is never made worse than it came), and the edges between two faces, one
/// of them active, that are not folded now (they must not fold).
fn shape_guard(mesh: &Mesh, row: &[u32], params: &Params) -> (Vec<u32>, Vec<f64>, Vec<[u32; 2]>) {
    let tris = mesh.triangles();
    let active: Vec<bool> = tris
        .iter()
        .map(|t| t.iter().any(|&v| row[v as usize] != NONE))
        .collect();
    let min_angle = params.min_angle.to_radians();
    let mut faces = Vec::new();
    let mut floor = Vec::new();
    for (f, &a) in active.iter().enumerate() {
        if a {
            let [p, q, r] = mesh.face_positions(f);
            let m = corner_angle(p, q, r)
                .min(corner_angle(q, r, p))
                .min(corner_angle(r, p, q));
            faces.push(f as u32);
            floor.push(min_angle.min(m));
        }
    }
    let normals = crate::geometry::face_normals(mesh);
    let limit = crate::geometry::FOLD_ANGLE.cos();
    let edges = mesh
        .conn()
        .edge_faces()
        .iter()
        .filter(|e| e[1] != NONE && (active[e[0] as usize] || active[e[1] as usize]))
        .filter(|e| dot(normals[e[0] as usize], normals[e[1] as usize]) >= limit)
        .copied()
        .collect();
    (faces, floor, edges)
}

/// Turning below which the shape penalty is silent (unless the input turns more there).
const FOLD_ONSET: f64 = PI / 3.0;

/// Corner angle below which the shape penalty pushes back (unless the input's corner is
/// smaller: then below that).
const CORNER_ONSET: f64 = PI / 18.0;

/// The faces with a free vertex (`active`, from [`shape_guard`]) and the penalty's onset at
/// each of their corners.
fn corners(mesh: &Mesh, active: &[u32]) -> Vec<([u32; 3], [f64; 3])> {
    active
        .iter()
        .map(|&f| {
            let t = mesh.triangles()[f as usize];
            let p = t.map(|v| mesh.position(v));
            let onset = [0, 1, 2]
                .map(|i| CORNER_ONSET.min(corner_angle(p[i], p[(i + 1) % 3], p[(i + 2) % 3])));
            (t, onset)
        })
        .collect()
}

/// Every edge with two faces and a free vertex among its four, as (i, j, k, l) with faces
/// (i, j, k) and (j, i, l), and the penalty's onset there.
fn hinges(mesh: &Mesh, row: &[u32]) -> Vec<([u32; 4], f64)> {
    let tris = mesh.triangles();
    let conn = mesh.conn();
    let apex = |f: u32, a: u32, b: u32| {
        let t = tris[f as usize];
        t.into_iter().find(|&x| x != a && x != b).unwrap_or(a)
    };
    let mut out = Vec::new();
    for (e, f) in conn.edges().iter().zip(conn.edge_faces()) {
        if f[1] == NONE {
            continue;
        }
        // Orient i → j as in face f[0].
        let t = tris[f[0] as usize];
        let k0 = (0..3).find(|&k| t[k] == e[0]).unwrap_or(0);
        let (i, j) = if t[(k0 + 1) % 3] == e[1] {
            (e[0], e[1])
        } else {
            (e[1], e[0])
        };
        let v = [i, j, apex(f[0], i, j), apex(f[1], i, j)];
        if v.iter().all(|&q| row[q as usize] == NONE) {
            continue;
        }
        let p = v.map(|q| mesh.position(q));
        let phi0 = crate::geometry::turning_angle_gradient(p[0], p[1], p[2], p[3]).0;
        out.push((v, FOLD_ONSET.max(phi0)));
    }
    out
}

/// A subset of `stuck` with pairwise disjoint fans (no two adjacent), worst first, leaving
/// out vertices whose refinement would create a zero-area triangle or a corner below
/// `min_angle` (radians; 0: no angle floor).
fn independent(mesh: &Mesh, stuck: &[u32], min_angle: f64) -> Vec<u32> {
    let conn = mesh.conn();
    let mut blocked = vec![false; mesh.num_vertices()];
    let mut out = Vec::new();
    for &v in stuck {
        if blocked[v as usize] || !conn.is_interior(v) {
            continue;
        }
        // A refinement that would leave a zero-area triangle is never made (smallest = 0).
        let smallest = smallest_after_refining(mesh, v);
        if smallest == 0.0 || smallest < min_angle {
            continue;
        }
        out.push(v);
        blocked[v as usize] = true;
        for &p in conn.ring_of(v) {
            blocked[p as usize] = true;
        }
    }
    out
}

/// The smallest corner of the triangles that refining `v`'s fan would leave (0 when one
/// would be degenerate): the same triangles as [`refine_sqrt3`] makes, built from positions
/// alone (no mesh copy).
fn smallest_after_refining(mesh: &Mesh, v: u32) -> f64 {
    let fan = mesh.conn().fan_of(v);
    let k = fan.len();
    let pv = mesh.position(v);
    let centroid = |j: usize| {
        let [pa, pb, pc] = mesh.face_positions(fan[j] as usize / 3);
        [0, 1, 2].map(|c| (pa[c] + pb[c] + pc[c]) / 3.0)
    };
    let smallest = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        if crate::mesh::is_degenerate_triangle(a, b, c) {
            return 0.0;
        }
        corner_angle(a, b, c)
            .min(corner_angle(b, c, a))
            .min(corner_angle(c, a, b))
    };
    (0..k)
        .map(|j| {
            let t = mesh.triangles()[fan[j] as usize / 3];
            let i = fan[j] as usize % 3;
            let (a, b) = (mesh.position(t[(i + 1) % 3]), mesh.position(t[(i + 2) % 3]));
            let (cj, cp) = (centroid(j), centroid((j + k - 1) % k));
            smallest(a, b, cj)
                .min(smallest(pv, cp, cj))
                .min(smallest(cp, a, cj))
        })
        .fold(PI, f64::min)
}

/// √3-style refinement of the fans of `vertices` (Kobbelt, as Sec. 2.3 suggests): every fan
/// triangle (v, r_j, r_{j+1}) gets a centroid vertex c_j; the spokes v–r_j are flipped, leaving
/// (r_j, r_{j+1}, c_j), (v, c_{j−1}, c_j) and (c_{j−1}, r_j, c_j). The vertices must be interior
/// with disjoint fans. New vertices are appended; texture coordinates are dropped (their
/// corners no longer exist).
pub fn refine_sqrt3(mesh: &Mesh, vertices: &[u32]) -> RawMesh {
    let mut raw = mesh.to_raw();
    raw.uv = None;
    let conn = mesh.conn();
    for &v in vertices {
        let fan = conn.fan_of(v);
        let k = fan.len();
        let first = raw.positions.len() as u32;
        let mut ring = Vec::with_capacity(k);
        for &hc in fan {
            let f = hc as usize / 3;
            let t = mesh.triangles()[f];
            let i = hc as usize % 3;
            let (a, b) = (t[(i + 1) % 3], t[(i + 2) % 3]);
            ring.push((f, a, b));
            let [pa, pb, pc] = mesh.face_positions(f);
            raw.positions
                .push([0, 1, 2].map(|c| (pa[c] + pb[c] + pc[c]) / 3.0));
        }
        for (j, &(f, a, b)) in ring.iter().enumerate() {
            let cj = first + j as u32;
            let cp = first + ((j + k - 1) % k) as u32;
            let patch = raw.face_patch[f];
            raw.triangles[f] = [a, b, cj];
            raw.triangles.push([v, cp, cj]);
            raw.face_patch.push(patch);
            raw.triangles.push([cp, a, cj]);
            raw.face_patch.push(patch);
        }
    }
    raw
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat 16×1 strip of squares, its layout cut (when `cut`) between the 8th and 9th: two
    /// islands of 16 faces, as many as `auto` asks of an island on average.
    fn strip_with_layout(cut: bool) -> Mesh {
        let positions: Vec<[f64; 3]> = (0..17)
            .flat_map(|i| [[i as f64, 0.0, 0.0], [i as f64, 1.0, 0.0]])
            .collect();
        let mut triangles = Vec::new();
        for i in 0..16u32 {
            triangles.push([2 * i, 2 * i + 2, 2 * i + 3]);
            triangles.push([2 * i, 2 * i + 3, 2 * i + 1]);
        }
        let mut coords: Vec<[f64; 2]> = positions.iter().map(|p| [p[0], p[1]]).collect();
        coords.extend([[8.5, 0.0], [8.5, 1.0]]);
        let uv = triangles
            .iter()
            .enumerate()
            .map(|(f, t)| {
                t.map(|v| {
                    if cut && f >= 16 && (16..=17).contains(&v) {
                        v + 18
                    } else {
                        v
                    }
                })
            })
            .collect();
        Mesh::new(crate::mesh::RawMesh {
            positions,
            face_patch: vec![0; triangles.len()],
            triangles,
            patch_names: vec!["default".into()],
            uv: Some(crate::mesh::UvLayer {
                coords,
                triangles: uv,
            }),
        })
        .expect("valid")
        .0
    }

    #[test]
    fn the_patches_follow_the_layout_only_where_it_cuts() {
        let cut = strip_with_layout(true);
        let (m, used) = choose_patches(&cut, Patches::Auto).expect("chosen");
        assert_eq!(
            (used.source.as_str(), used.count, used.uv_seam_edges),
            ("uv", 2, 1)
        );
        assert_eq!(m.num_patches(), 2);
        let (m, used) = choose_patches(&cut, Patches::File).expect("chosen");
        assert_eq!((used.source.as_str(), m.num_patches()), ("file", 1));
        // An uncut layout: auto keeps the file's patches; uv makes its one island.
        let whole = strip_with_layout(false);
        let (_, used) = choose_patches(&whole, Patches::Auto).expect("chosen");
        assert_eq!(used.source, "file");
        let (m, used) = choose_patches(&whole, Patches::Uv).expect("chosen");
        assert_eq!((used.source.as_str(), m.num_patches()), ("uv", 1));
        // No layout: auto keeps the file's, uv is refused by name.
        let bare = Mesh::new(crate::mesh::RawMesh {
            uv: None,
            ..cut.to_raw()
        })
        .expect("valid")
        .0;
        assert_eq!(
            choose_patches(&bare, Patches::Auto).unwrap().1.source,
            "file"
        );
        match choose_patches(&bare, Patches::Uv) {
            Err(AlgoError::InvalidParam { key, .. }) => assert_eq!(key, "patches"),
            other => panic!("{other:?}"),
        }
    }

    /// mh_male_elegantsuit01's 23 texture islands each converge alone, but combined their
    /// results fold seam edges that neither the input nor the whole run's result fold; giving
    /// those parts up (and then their neighbours) left the job at ϖ_max 5e-2 after 526 s
    /// (issue 12 note of 2026-11-28). The whole run's result is stood in for by the input, as
    /// if it had made no progress, so every seam fold of the merge is new. With the old rule
    /// (always give up) the merge ends at ϖ_max 2.0 (checked).
    #[test]
    fn converged_parts_are_kept_though_they_fold_a_seam_when_giving_them_up_costs_flattenability() {
        let Some(path) = crate::corpus::shared_mesh_for_tests("garment/mh_male_elegantsuit01.obj")
        else {
            return;
        };
        let bytes = std::fs::read(&path).expect("readable");
        let (mesh, _) = crate::io::load(&bytes, crate::io::Format::Obj).expect("valid");
        let (work, used) = choose_patches(&mesh, Patches::Uv).expect("islands");
        assert_eq!(used.count, 23);
        let split = parts::split(&work).expect("independent parts");
        let tolerance = Params::default().tolerance;
        let before = crate::geometry::max_flattenability(&work);
        assert!(before > 1.0, "{before}");
        let whole = Report {
            max_flattenability: before,
            ..Report::default()
        };
        let (out, report) = match retry_parts(
            &work,
            &split,
            work.clone(),
            whole,
            &Params::default(),
            &super::super::Silent::default(),
        ) {
            Ok(done) => done,
            Err(_) => panic!("the parts could not be merged"),
        };
        // Measured on the merged mesh's own angles, not taken from the report.
        let after = crate::geometry::max_flattenability(&out);
        assert!(after <= tolerance, "ϖ_max {after:.2e}");
        assert!(report.converged);
        assert!(report.parts.iter().all(|p| p.kept != "whole"));
        // The rule was exercised: the merge folds seam edges the input does not.
        let folding = parts::new_seam_folds(&work, &split, &work, &out);
        assert!(!folding.is_empty());
        for k in folding {
            assert!(
                report.parts[k].stop_reason.contains("kept though"),
                "{}",
                report.parts[k].stop_reason
            );
        }
    }

    /// A flat 9 × 9 grid in two patches, its seam (the column x = 4) bent out of the plane.
    fn grid_with_bent_seam() -> Mesh {
        let positions: Vec<[f64; 3]> = (0..81)
            .map(|i| {
                let (x, y) = ((i % 9) as f64, (i / 9) as f64);
                let z = if x == 4.0 {
                    0.4 * (PI * y / 8.0).sin()
                } else {
                    0.0
                };
                [x, y, z]
            })
            .collect();
        let mut triangles = Vec::new();
        let mut face_patch = Vec::new();
        for j in 0..8u32 {
            for i in 0..8u32 {
                let v = 9 * j + i;
                triangles.extend([[v, v + 1, v + 10], [v, v + 10, v + 9]]);
                face_patch.extend([u32::from(i >= 4); 2]);
            }
        }
        Mesh::new(crate::mesh::RawMesh {
            positions,
            triangles,
            face_patch,
            patch_names: vec!["left".into(), "right".into()],
            uv: None,
        })
        .expect("valid")
        .0
    }

    #[test]
    fn free_seams_move_welded_and_the_boundary_stays() {
        let mesh = grid_with_bent_seam();
        let conn = mesh.conn();
        let seam: Vec<u32> = (0..81)
            .filter(|&v| conn.kind(v) == VertexKind::Seam)
            .collect();
        assert_eq!(seam.len(), 7);
        let boundary: Vec<u32> = (0..81)
            .filter(|&v| conn.kind(v) == VertexKind::Boundary)
            .collect();
        let varpi_max = |m: &Mesh| {
            let theta = crate::geometry::angle_sums(m);
            crate::geometry::flattenability(m, &theta)
                .into_iter()
                .fold(0.0, f64::max)
        };
        assert!(varpi_max(&mesh) > 1e-2, "{}", varpi_max(&mesh));
        for (seams, moved) in [(Seams::Held, false), (Seams::Free, true)] {
            let params = Params {
                seams,
                ..Params::default()
            };
            let (out, report) =
                solve(&mesh, &params, &crate::algorithms::Silent::default()).expect("runs");
            // Measured from the output's geometry, not the solver's numbers.
            assert!(varpi_max(&out) <= 1e-6, "{seams:?}: {}", report.stop_reason);
            for &v in &boundary {
                assert_eq!(out.position(v), mesh.position(v), "{seams:?}: boundary {v}");
            }
            let seam_moved = seam.iter().any(|&v| out.position(v) != mesh.position(v));
            assert_eq!(seam_moved, moved, "{seams:?}");
            // Welded: the two patches still share every seam vertex.
            assert_eq!(out.triangles(), mesh.triangles());
        }
    }

    /// A flat 9 × 9 grid of one patch slit along x = 4 from its edge y = 0 to its centre (the
    /// slit's vertices below the tip copied for the faces right of it, as `patches = uv`
    /// opens a sleeve's seam), the slit bent out of the plane.
    fn grid_with_bent_slit() -> Mesh {
        let z = |y: f64| 0.4 * (PI * y / 4.0).sin();
        let mut positions: Vec<[f64; 3]> = (0..81)
            .map(|i| {
                let (x, y) = ((i % 9) as f64, (i / 9) as f64);
                [x, y, if x == 4.0 && y < 4.0 { z(y) } else { 0.0 }]
            })
            .collect();
        positions.extend((0..4).map(|y| [4.0, y as f64, z(y as f64)]));
        let copy = |v: u32| {
            if v % 9 == 4 && v / 9 < 4 {
                81 + v / 9
            } else {
                v
            }
        };
        let mut triangles = Vec::new();
        for j in 0..8u32 {
            for i in 0..8u32 {
                let v = 9 * j + i;
                let mut cell = [[v, v + 1, v + 10], [v, v + 10, v + 9]];
                if i == 4 {
                    cell = cell.map(|t| t.map(copy));
                }
                triangles.extend(cell);
            }
        }
        Mesh::new(crate::mesh::RawMesh {
            positions,
            face_patch: vec![0; triangles.len()],
            triangles,
            patch_names: vec!["default".into()],
            uv: None,
        })
        .expect("valid")
        .0
    }

    #[test]
    fn free_seams_move_a_slit_as_one_and_hold_its_end_on_the_boundary() {
        let mesh = grid_with_bent_slit();
        let varpi_max = |m: &Mesh| {
            let theta = crate::geometry::angle_sums(m);
            crate::geometry::flattenability(m, &theta)
                .into_iter()
                .fold(0.0, f64::max)
        };
        let before = varpi_max(&mesh);
        assert!(before > 1e-2, "{before}");
        // The slit: (4, y) and its copy 81 + y; its end on the boundary y = 0 is held.
        let pairs: Vec<(u32, u32)> = (1..4).map(|y| (9 * y + 4, 81 + y)).collect();
        let held: Vec<u32> = (0..85u32)
            .filter(|&v| {
                let p = mesh.position(v);
                v % 9 != 4 && (p[0] == 0.0 || p[0] == 8.0 || p[1] == 0.0 || p[1] == 8.0)
            })
            .chain([4, 81])
            .collect();
        for seams in [Seams::Held, Seams::Free] {
            let params = Params {
                seams,
                ..Params::default()
            };
            let (out, report) =
                solve(&mesh, &params, &crate::algorithms::Silent::default()).expect("runs");
            let after = varpi_max(&out);
            for &v in &held {
                assert_eq!(out.position(v), mesh.position(v), "{seams:?}: held {v}");
            }
            for &(a, b) in &pairs {
                // Sewn: both sides of the slit stay one point in space.
                assert_eq!(out.position(a), out.position(b), "{seams:?}: {a} {b}");
                let moved = out.position(a) != mesh.position(a);
                assert_eq!(moved, seams == Seams::Free, "{seams:?}: slit vertex {a}");
            }
            if seams == Seams::Free {
                assert!(after <= 1e-6, "{after}: {}", report.stop_reason);
            } else {
                assert!(after <= before);
            }
        }
    }

    /// The shape penalty's force is −∇ of ½ κ h̄² (Σ (φ − φ⁰)₊² + Σ (α⁰ − α)₊²), by central
    /// differences, on a flat disk with one vertex moved so that both parts are active.
    #[test]
    fn shape_penalty_force_is_minus_the_gradient_of_its_energy() {
        let disk = crate::fixtures::all()
            .into_iter()
            .find(|f| f.name == "flat_disk")
            .unwrap();
        let mesh = Mesh::new(disk.mesh).unwrap().0;
        let params = Params {
            shape_penalty: 3.0,
            ..Params::default()
        };
        let impossible = vec![false; mesh.num_vertices()];
        let mut sys = System::new(&mesh, &impossible, &params, None).unwrap();
        // Lift one vertex and slide it most of the way to a neighbour: its hinges bend past
        // the onset and some of its corners close below it.
        let v = sys.free[sys.n / 2];
        let w = mesh.conn().ring_of(v)[0];
        let (pv, pw) = (sys.pos[v as usize], sys.pos[w as usize]);
        sys.pos[v as usize] = [0, 1, 2].map(|c| pv[c] + 0.95 * (pw[c] - pv[c]));
        sys.pos[v as usize][2] += 0.1 * sys.h;
        let bent = |sys: &System| {
            let k = params.shape_penalty * sys.h * sys.h;
            sys.hinges
                .iter()
                .map(|&(q, onset)| {
                    let p = q.map(|i| sys.pos[i as usize]);
                    let phi = crate::geometry::turning_angle_gradient(p[0], p[1], p[2], p[3]).0;
                    0.5 * k * (phi - onset).max(0.0).powi(2)
                })
                .sum::<f64>()
        };
        let closed = |sys: &System| {
            let k = params.shape_penalty * sys.h * sys.h;
            let mut e = 0.0;
            for &(t, onset) in &sys.corners {
                for i in 0..3 {
                    let [a, b, c] =
                        [t[i], t[(i + 1) % 3], t[(i + 2) % 3]].map(|q| sys.pos[q as usize]);
                    e += 0.5 * k * (onset[i] - corner_angle(a, b, c)).max(0.0).powi(2);
                }
            }
            e
        };
        assert!(bent(&sys) > 0.0, "hinges must bend past the onset");
        assert!(closed(&sys) > 0.0, "corners must close below the onset");
        let energy = |sys: &System| bent(sys) + closed(sys);
        sys.shape_penalty(params.shape_penalty);
        let mut checked = 0;
        for &q in std::iter::once(&v).chain(mesh.conn().ring_of(v)) {
            let r = sys.row[q as usize];
            if r == NONE {
                continue;
            }
            let force = sys.penalty_force[r as usize];
            for c in 0..3 {
                let step = 1e-6 * sys.h;
                let mut t = System::new(&mesh, &impossible, &params, None).unwrap();
                t.pos.clone_from(&sys.pos);
                t.pos[q as usize][c] += step;
                let up = energy(&t);
                t.pos[q as usize][c] -= 2.0 * step;
                let down = energy(&t);
                let fd = -(up - down) / (2.0 * step);
                assert!(
                    (fd - force[c]).abs() <= 1e-5 * (1.0 + force[c].abs()),
                    "vertex {q} coordinate {c}: force {} vs −∂E {fd}",
                    force[c]
                );
            }
            checked += 1;
        }
        assert!(checked >= 4);
    }

    #[test]
    fn smallest_after_refining_matches_refining_a_copy() {
        for f in crate::fixtures::all() {
            let mesh = Mesh::new(f.mesh).unwrap().0;
            for v in mesh.conn().interior_vertices() {
                let raw = refine_sqrt3(&mesh, &[v]);
                let old_fan = mesh.conn().fan_of(v).iter().map(|&hc| hc as usize / 3);
                let brute = raw.triangles[mesh.num_faces()..]
                    .iter()
                    .chain(old_fan.map(|f| &raw.triangles[f]))
                    .map(|t| {
                        let [a, b, c] = t.map(|i| raw.positions[i as usize]);
                        if crate::mesh::is_degenerate_triangle(a, b, c) {
                            return 0.0;
                        }
                        corner_angle(a, b, c)
                            .min(corner_angle(b, c, a))
                            .min(corner_angle(c, a, b))
                    })
                    .fold(PI, f64::min);
                assert_eq!(smallest_after_refining(&mesh, v), brute, "{} v{v}", f.name);
            }
        }
    }

    #[test]
    fn slice_gradient_matches_geometry() {
        // A bumpy 5×5 grid: compare eval's gradients with geometry::theta_gradient.
        let n = 5;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f64, j as f64);
                pos.push([
                    x + 0.1 * (y * 1.3).sin(),
                    y,
                    0.3 * (x * 0.7).sin() * (y * 0.9).cos(),
                ]);
            }
        }
        let mut tri = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = (j * (n + 1) + i) as u32;
                let w = v + n as u32 + 1;
                tri.push([v, v + 1, w + 1]);
                tri.push([v, w + 1, w]);
            }
        }
        let raw = RawMesh {
            positions: pos,
            triangles: tri.clone(),
            face_patch: vec![0; tri.len()],
            patch_names: vec!["a".into()],
            uv: None,
        };
        let mesh = Mesh::new(raw).unwrap().0;
        let sys = System::new(
            &mesh,
            &vec![false; mesh.num_vertices()],
            &Params::default(),
            None,
        )
        .unwrap();
        let mut theta = vec![0.0; sys.n];
        let mut grad = vec![[0.0; 3]; sys.slot_vertex.len()];
        eval(
            mesh.positions(),
            mesh.triangles(),
            mesh.conn(),
            &sys.free,
            &sys.slot_start,
            &mut theta,
            &mut grad,
        );
        let mut out = Vec::new();
        for (r, &q) in sys.free.iter().enumerate() {
            crate::geometry::theta_gradient(&mesh, q, &mut out);
            assert!((theta[r] - crate::geometry::angle_sum_at(&mesh, q)).abs() < 1e-14);
            for (k, (p, g)) in out.iter().enumerate() {
                let s = sys.slot_start[r] + k;
                assert_eq!(sys.slot_vertex[s], *p);
                for c in 0..3 {
                    assert!((grad[s][c] - g[c]).abs() < 1e-12);
                }
            }
        }
    }
}
