//! A developable start for a disk whose fixed boundary rules out a nearby developable: the
//! cone over the boundary from an apex where its angle is exactly 2π.
//!
//! Why. With the boundary fixed, a patch whose interior is curved like a saddle or a dome
//! has no flattenable surface near it: the linearisation of θ = 2π is a wave operator on
//! negative curvature, and a near-flat cap has to come down to its boundary's hull (issue 12
//! notes). The Newton runs then stall at 1e-4–1e-3 or converge by crumpling the sheet into
//! mesh-sized pleats. A sheet of paper forced onto such a boundary forms a d-cone instead,
//! and that surface always exists: seen from a point p in the convex hull of a closed curve,
//! the curve's central projection onto the unit sphere lies in no open hemisphere, so its
//! length (the cone angle at p) is ≥ 2π (the lemma behind Fenchel's theorem), and it falls to
//! 0 as p leaves to infinity; in between it is exactly 2π. The cone from such a p over the
//! boundary polygon is a fan of planar triangles whose angles at p sum to 2π: intrinsically
//! flat, so its vertices away from p are flattenable.
//!
//! How. When the patch is one disk (one boundary loop, Euler characteristic 1, no seams) and
//! a height field over the plane orthogonal to its area-weighted mean normal d, every
//! interior vertex is moved along d onto the fan (its position in the plane, and so the
//! triangulation's layout, is kept); the vertex nearest the apex is put on it. Apexes are
//! sought on the lines along d through the boundary's centroid and through a sample of the
//! interior vertices (the boundary must be star-shaped from there), on both sides of the
//! surface. Among the apexes whose start leaves no corner below min(10°, the input's
//! smallest) (an apex near the boundary leaves a steep flank of slivers), the one that moves
//! the vertices least (sum of squared moves) is taken. The triangles, chords of the fan,
//! leave some ϖ near the apex and along the fan's sharp generators, which the Newton
//! iterations remove (measured: the noisy saddles in 10–24 iterations at a relative
//! Hausdorff distance of 18 %, the domes in 3–28 at 11 %, no folds; issue 12 note).
//!
//! A disk that is no height field (a pouch, a shoe's upper, a cap that folds over) has no
//! projection to keep. Its plane is that of its boundary's vector area, and its layout the
//! cotangent-harmonic map into the boundary's projection on it, or, where that map folds (a
//! non-convex projection), the one into the unit disk (boundary by arc length; convex, so it
//! folds only where a cotangent weight is negative, which is refused), carried onto the
//! boundary's projection ray by ray from each candidate apex (one-to-one as a continuous map
//! since that polygon is star-shaped from it; an apex whose mapped triangles turn over is
//! refused). Such a disk often holds more area than any flat disk with its
//! boundary can ([`isoperimetric_excess`]); then nothing near it is flattenable and the cone
//! is the honest answer. Measured: mh_shoes01's uppers (10.9 times the bound), which stalled
//! from the input at 8e-3 in every strategy tried, end flattenable from the cone with no
//! fold (issue 12 note).
//!
//! Cost: O(candidates · (F + n log m + m · bisection steps)) for F faces, n interior and m
//! boundary vertices, no factorisation; candidates are scored in parallel. 0.07 s at 7.7k
//! faces, 0.4 s at 45k.

use crate::algorithms::flatten::param::CotanSystem;
use crate::geometry;
use crate::mesh::{cross, dot, sub, Mesh, VertexKind};
use rayon::prelude::*;
use std::f64::consts::TAU;

/// Most apex lines tried (the centroid's and a stride sample of interior vertices).
const CANDIDATES: usize = 48;

/// Most steps of the apex-height root finder (the bracket is at most a few diagonals long).
const ROOT_STEPS: usize = 100;

/// The root in (0, b) of a continuous g that is positive (`g0` = g(0)) before it and not
/// after it: regula falsi with the Illinois modification (superlinear where bisection gains
/// a bit per step; each step of g costs a pass over the boundary), bracketing throughout.
/// Stops when |g| ≤ 1e-13 or the bracket is no longer than 1e-15 b. None when (0, b) is no
/// bracket (g(0) ≤ 0, or g(b) > 0 or NaN).
fn root(g: impl Fn(f64) -> f64, g0: f64, b: f64) -> Option<f64> {
    let (mut lo, mut glo, mut hi, mut ghi) = (0.0, g0, b, g(b));
    if !(g0 > 0.0 && ghi <= 0.0) {
        return None;
    }
    let (mut best, mut gbest) = if g0 < -ghi { (lo, g0) } else { (hi, ghi) };
    let mut kept = 0i8; // +1: lo was kept last step, −1: hi was.
    for _ in 0..ROOT_STEPS {
        if gbest.abs() <= 1e-13 || hi - lo <= 1e-15 * b {
            break;
        }
        let secant = (lo * ghi - hi * glo) / (ghi - glo);
        let x = if secant > lo && secant < hi {
            secant
        } else {
            0.5 * (lo + hi)
        };
        let gx = g(x);
        if gx.is_nan() {
            break;
        }
        if gx.abs() < gbest.abs() {
            (best, gbest) = (x, gx);
        }
        if gx > 0.0 {
            (lo, glo) = (x, gx);
            if kept == -1 {
                ghi *= 0.5;
            }
            kept = -1;
        } else {
            (hi, ghi) = (x, gx);
            if kept == 1 {
                glo *= 0.5;
            }
            kept = 1;
        }
    }
    Some(best)
}

/// Corners below min(this, the input's smallest), degrees, disqualify an apex when another
/// apex avoids them.
const MIN_CORNER: f64 = 10.0;

/// Least component of a face's unit normal along d for the patch to count as a height field.
const HEIGHT_FIELD: f64 = 0.05;

/// Why a mesh has no cone start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoCone {
    /// Not exactly one patch forming one disk (one boundary loop, χ = 1) without seams.
    NotADisk,
    /// A face turns too far from the mean normal (or away from it): no height field.
    NotAHeightField,
    /// From no candidate apex is the boundary star-shaped with a 2π cone point.
    NoApex,
    /// Not a height field, and no harmonic layout: the boundary encloses no area on its own
    /// plane, or the maps into its projection and into the unit disk both fold (or fail).
    NoEmbedding,
}

impl std::fmt::Display for NoCone {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NoCone::NotADisk => "the patch is not a single disk without seams",
            NoCone::NotAHeightField => {
                "the patch is not a height field over the plane of its mean normal"
            }
            NoCone::NoApex => "no apex with a 2π cone angle sees the whole boundary",
            NoCone::NoEmbedding => {
                "the patch is no height field, and neither harmonic map (into its boundary's \
                 projection, into the unit disk) lays it out without folding"
            }
        })
    }
}

/// A cone start for `mesh`: the same mesh with every interior vertex moved along the mean
/// normal onto the developable cone over its boundary (boundary vertices bit-identical).
pub fn cone_start(mesh: &Mesh) -> Result<Mesh, NoCone> {
    start_and_apex(mesh).map(|(start, _)| start)
}

/// A one-disk patch's area over the most any flattenable disk with its boundary can have,
/// A ÷ (P²/4π) for a boundary of length P: a disk whose interior angle sums are all 2π is
/// flat and simply connected, so the Euclidean isoperimetric inequality holds on it (Weil
/// 1926, for simply connected surfaces of curvature ≤ 0), and fl-mesh keeps the boundary.
/// Above 1 no flattenable surface keeps the patch's area: it must shrink by this factor at
/// least (a shoe's upper: 10.9). None when the mesh is not one disk.
pub fn isoperimetric_excess(mesh: &Mesh) -> Option<f64> {
    if !one_disk(mesh) {
        return None;
    }
    let perimeter: f64 = boundary_lengths(mesh).iter().sum();
    let area: f64 = geometry::face_areas(mesh).iter().sum();
    let excess = area / (perimeter * perimeter / (4.0 * std::f64::consts::PI));
    excess.is_finite().then_some(excess)
}

/// Whether the mesh is one patch forming one disk: one component, one boundary loop, χ = 1.
fn one_disk(mesh: &Mesh) -> bool {
    let conn = mesh.conn();
    let patches = conn.patches();
    patches.len() == 1
        && patches[0].boundary_loops.len() == 1
        && patches[0].euler_characteristic() == 1
        && conn.components(mesh.triangles().len()) == 1
}

/// The lengths of a one-disk mesh's boundary edges, in loop order (edge i from point i).
fn boundary_lengths(mesh: &Mesh) -> Vec<f64> {
    let loop_ = &mesh.conn().patches()[0].boundary_loops[0];
    let m = loop_.len();
    (0..m)
        .map(|i| {
            let e = sub(mesh.position(loop_[(i + 1) % m]), mesh.position(loop_[i]));
            dot(e, e).sqrt()
        })
        .collect()
}

/// The frame of a disk that is a height field over the plane orthogonal to its area-weighted
/// mean normal d, or why the mesh is not one.
fn disk_frame(mesh: &Mesh) -> Result<Frame, NoCone> {
    if !one_disk(mesh) || mesh.conn().kinds().contains(&VertexKind::Seam) {
        return Err(NoCone::NotADisk);
    }
    let normals = geometry::face_normals(mesh);
    let areas = geometry::face_areas(mesh);
    let mut sum = [0.0; 3];
    for (n, a) in normals.iter().zip(&areas) {
        for k in 0..3 {
            sum[k] += a * n[k];
        }
    }
    let d = geometry::normalize(sum);
    if dot(d, d) < 0.5 || normals.iter().any(|n| dot(*n, d) < HEIGHT_FIELD) {
        return Err(NoCone::NotAHeightField);
    }
    Ok(Frame::new(d))
}

/// A heuristic reading of the smooth part of the patch's total Gaussian curvature (radians),
/// or why the mesh is no height-field disk: the median over up to [`CURVATURE_SAMPLES`]
/// interior vertices of the curvature of a quartic height field fitted by least squares to
/// the vertices within a quarter of the patch's RMS radius (in the plane of the mean
/// normal), times the area — ∫K dA when K is uniform, less where it concentrates. The
/// neighbourhood averages per-vertex noise out (the angle defects themselves sum to the
/// boundary's turning, which noise near the boundary swamps; issue 12 notes), and is small
/// enough that a cone or a cylinder, whose curvature is zero, reads as about zero (a quadric
/// fitted to the whole patch reads a cone sector as a dome). 0 when no sample has enough
/// neighbours to fit (below a few thousand faces). Scale-free.
pub fn fitted_curvature(mesh: &Mesh) -> Result<Curvature, NoCone> {
    let frame = disk_frame(mesh)?;
    let pts: Vec<[f64; 3]> = mesh
        .positions()
        .iter()
        .map(|&p| {
            let q = frame.plane(p);
            [q[0], q[1], frame.height(p)]
        })
        .collect();
    let n = pts.len() as f64;
    let c = pts
        .iter()
        .fold([0.0; 2], |s, p| [s[0] + p[0] / n, s[1] + p[1] / n]);
    let rms = (pts
        .iter()
        .map(|p| (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let radius = 0.25 * rms;
    let interior: Vec<u32> = mesh.conn().interior_vertices().collect();
    let stride = interior.len().div_ceil(CURVATURE_SAMPLES).max(1);
    let samples: Vec<f64> = interior
        .par_iter()
        .step_by(stride)
        .filter_map(|&v| curvature_at(&pts, pts[v as usize], radius))
        .collect();
    // The median, not the mean: across a strongly bent cylinder (pleats) the fitted
    // curvature across the bend is the noise times the bend, large with either sign
    // (measured on pleats-2000-0.1: a mean of +5.3 rad, a median of 0.02). Its standard
    // error from the interquartile range (normal approximation: 1.25 σ/√n, σ = IQR/1.349).
    let mut ks = samples;
    if ks.len() < 4 {
        return Ok(Curvature::default());
    }
    ks.sort_by(f64::total_cmp);
    let n = ks.len();
    let (median, iqr) = (ks[n / 2], ks[3 * n / 4] - ks[n / 4]);
    let area: f64 = geometry::face_areas(mesh).iter().sum();
    let out = Curvature {
        total: median * area,
        error: 1.25 * iqr / 1.349 / (n as f64).sqrt() * area,
    };
    Ok(if out.total.is_finite() && out.error.is_finite() {
        out
    } else {
        Curvature::default()
    })
}

/// A patch's fitted total curvature ([`fitted_curvature`]) and its spread, radians.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Curvature {
    /// Median sampled curvature times the area.
    pub total: f64,
    /// Standard error of `total` as if the samples were independent (they overlap, and
    /// the spread holds K's own variation too: a rough guide, not a calibrated error).
    pub error: f64,
}

/// The Gaussian curvature at plane point `o` of the quartic height field fitted to the
/// points `pts` (plane coordinates and height) within `radius` of it, or None with fewer than
/// [`MIN_NEIGHBOURS`] of them. Unbiased for the fit's noise to first order.
fn curvature_at(pts: &[[f64; 3]], o: [f64; 3], radius: f64) -> Option<f64> {
    use faer::linalg::solvers::{Solve, SolveLstsq};
    // Local coordinates scaled by the radius: the fit stays well conditioned.
    let near: Vec<[f64; 3]> = pts
        .iter()
        .map(|p| std::array::from_fn(|k| (p[k] - o[k]) / radius))
        .filter(|p: &[f64; 3]| p[0] * p[0] + p[1] * p[1] <= 1.0)
        .collect();
    if near.len() < MIN_NEIGHBOURS {
        return None;
    }
    // Columns x^i y^j, i + j ≤ 4, in the order of MONOMIALS.
    let a = faer::Mat::from_fn(near.len(), MONOMIALS.len(), |i, j| {
        let [x, y, _] = near[i];
        x.powi(MONOMIALS[j].0) * y.powi(MONOMIALS[j].1)
    });
    let b = faer::Mat::from_fn(near.len(), 1, |i, _| near[i][2]);
    let c = a.qr().solve_lstsq(&b);
    let (fx, fy) = (c[(1, 0)], c[(2, 0)]);
    let (fxx, fxy, fyy) = (2.0 * c[(3, 0)], c[(4, 0)], 2.0 * c[(5, 0)]);
    // The fitted coefficients carry the noise, and a product of estimates is biased by their
    // covariance (E[XY] = E[X]E[Y] + Cov(X, Y)): fxy² alone reads every noisy sheet as a
    // saddle. Covariances σ²(AᵀA)⁻¹, σ² from the residuals.
    let rss: f64 = (&a * &c - &b).col(0).iter().map(|r| r * r).sum();
    let sigma2 = rss / (near.len() - MONOMIALS.len()) as f64;
    let pick = faer::Mat::from_fn(MONOMIALS.len(), 2, |i, j| f64::from(i == [4, 5][j]));
    let inv = (a.transpose() * &a).partial_piv_lu().solve(&pick);
    let (var_fxy, cov_fxx_fyy) = (sigma2 * inv[(4, 0)], 4.0 * sigma2 * inv[(3, 1)]);
    // K in radius units (a pure number), then in the mesh's.
    let gauss = (fxx * fyy - cov_fxx_fyy - fxy * fxy + var_fxy) / (1.0 + fx * fx + fy * fy).powi(2);
    let k = gauss / (radius * radius);
    k.is_finite().then_some(k)
}

/// Most samples for [`fitted_curvature`].
const CURVATURE_SAMPLES: usize = 256;

/// Fewest vertices in a sample's neighbourhood for a fit: four per coefficient. With fewer
/// (2k-face meshes: about 35) the noise left in the fit skews the curvature of noisy
/// developable sheets towards saddles (a 2k-face cylinder, noise 0.1: −0.9 ± 0.2 rad).
const MIN_NEIGHBOURS: usize = 4 * MONOMIALS.len();

/// Exponents (i, j) of the fit's monomials x^i y^j: every one of degree ≤ 4, the second-order
/// ones at indices 3–5. Quartic, not quadric: on a strongly bent cylinder (pleats) the
/// quartic part of the bend, left to a quadric, leaks into the y² coefficient of a disk fit
/// and reads as curvature across the bend (measured: pleats-2000 read −1.2 to −2.3 rad).
const MONOMIALS: [(i32, i32); 15] = [
    (0, 0),
    (1, 0),
    (0, 1),
    (2, 0),
    (1, 1),
    (0, 2),
    (3, 0),
    (2, 1),
    (1, 2),
    (0, 3),
    (4, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 4),
];

/// Where the interior vertices go in the plane, before they are lifted onto the fan.
enum Layout {
    /// The same whatever the apex: a height field's projections, or the harmonic map into
    /// the boundary's projection.
    Projected(Vec<[f64; 2]>),
    /// Their places in the unit disk under the harmonic map whose boundary is the unit
    /// circle by arc length; [`Layout::flat`] maps the disk onto the boundary's projection,
    /// star-shaped from the apex, ray by ray.
    Disk {
        uv: Vec<[f64; 2]>,
        /// Boundary points in the plane and their angles on the circle (from 0, increasing).
        ring: Vec<[f64; 2]>,
        angles: Vec<f64>,
    },
}

impl Layout {
    /// The interior vertices' plane positions for an apex over `q` (from which the
    /// boundary is star-shaped): a point at radius ρ and angle ψ of the disk goes to
    /// q + ρ (P(ψ) − q), P(ψ) the boundary polygon's point at ψ (linear between the
    /// boundary points' angles), so rays from the disk's centre map to rays from q and the
    /// continuous map is one-to-one (the triangles between the mapped vertices can still
    /// turn over near a reflex corner: [`start_and_apex`] refuses such an apex).
    fn flat(&self, q: [f64; 2]) -> std::borrow::Cow<'_, [[f64; 2]]> {
        let (uv, ring, angles) = match self {
            Layout::Projected(flat) => return std::borrow::Cow::Borrowed(flat),
            Layout::Disk { uv, ring, angles } => (uv, ring, angles),
        };
        let m = ring.len();
        let out = uv
            .iter()
            .map(|&[x, y]| {
                let rho = (x * x + y * y).sqrt().min(1.0);
                let psi = y.atan2(x).rem_euclid(TAU);
                let i = angles.partition_point(|&a| a <= psi).max(1) - 1;
                let next = if i + 1 < m { angles[i + 1] } else { TAU };
                let t = ((psi - angles[i]) / (next - angles[i])).clamp(0.0, 1.0);
                let (a, b) = (ring[i], ring[(i + 1) % m]);
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                [q[0] + rho * (p[0] - q[0]), q[1] + rho * (p[1] - q[1])]
            })
            .collect();
        std::borrow::Cow::Owned(out)
    }
}

/// The plane frame and where the interior vertices (in `interior_vertices` order) go in it:
/// their projection when the disk is a height field over the plane of its mean normal; else
/// (a pouch, a cap that folds over) the plane is that of the boundary's vector area, which
/// points to the side the faces face (the loop has the surface on its left), and the layout
/// the cotangent-harmonic map into the boundary's projection, or where that folds (a
/// non-convex projection) into the unit disk (convex, so it folds only where a cotangent
/// weight is negative), carried onto the boundary's projection per apex ([`Layout::flat`]).
/// Err when the patch is no disk, or both harmonic maps fold.
fn layout(mesh: &Mesh) -> Result<(Frame, Layout), NoCone> {
    let conn = mesh.conn();
    let interior: Vec<u32> = conn.interior_vertices().collect();
    match disk_frame(mesh) {
        Ok(frame) => {
            let flat = interior
                .iter()
                .map(|&v| frame.plane(mesh.position(v)))
                .collect();
            return Ok((frame, Layout::Projected(flat)));
        }
        Err(NoCone::NotAHeightField) => {}
        Err(other) => return Err(other),
    }
    let loop_ = &conn.patches()[0].boundary_loops[0];
    let m = loop_.len();
    let b: Vec<[f64; 3]> = loop_.iter().map(|&v| mesh.position(v)).collect();
    let twice_area = (0..m).fold([0.0; 3], |s, i| {
        let c = cross(b[i], b[(i + 1) % m]);
        [s[0] + c[0], s[1] + c[1], s[2] + c[2]]
    });
    let lengths = boundary_lengths(mesh);
    let perimeter: f64 = lengths.iter().sum();
    // A boundary that encloses (almost) no area on any plane leaves no polygon to map into.
    let enclosed = dot(twice_area, twice_area).sqrt();
    if enclosed.is_nan() || enclosed < 1e-6 * perimeter * perimeter {
        return Err(NoCone::NoEmbedding);
    }
    let frame = Frame::new(geometry::normalize(twice_area));
    let mut angles = Vec::with_capacity(m);
    let mut run = 0.0;
    for l in &lengths {
        angles.push(TAU * run / perimeter);
        run += l;
    }
    let (pos, tris) = (mesh.positions(), mesh.triangles());
    // Unreferenced vertices are held too (at the origin): left free, their empty rows
    // would make the system singular.
    let mut on_boundary: Vec<bool> = conn
        .kinds()
        .iter()
        .map(|k| *k == VertexKind::Unreferenced)
        .collect();
    for &v in loop_ {
        on_boundary[v as usize] = true;
    }
    let mut system = CotanSystem::new(pos, tris, &on_boundary).map_err(|_| NoCone::NoEmbedding)?;
    let mut harmonic = |at: &dyn Fn(usize) -> [f64; 2]| -> Option<Vec<[f64; 2]>> {
        let mut fixed: Vec<Option<[f64; 2]>> = on_boundary
            .iter()
            .map(|&b| b.then_some([0.0, 0.0]))
            .collect();
        for (i, &v) in loop_.iter().enumerate() {
            fixed[v as usize] = Some(at(i));
        }
        let uv = system.fill(pos, tris, &fixed, 0).ok()?;
        (!folds_in_plane(tris, &uv)).then(|| interior.iter().map(|&v| uv[v as usize]).collect())
    };
    // Into the boundary's projection itself when that map does not fold (it stays close to
    // the projection where the patch nearly is a height field: bff_face's cone run reached
    // 6.4e-4 from it, 5.9e-2 through the disk); else through the unit disk.
    let ring: Vec<[f64; 2]> = b.iter().map(|&p| frame.plane(p)).collect();
    if let Some(flat) = harmonic(&|i| ring[i]) {
        return Ok((frame, Layout::Projected(flat)));
    }
    let uv = harmonic(&|i| [angles[i].cos(), angles[i].sin()]).ok_or(NoCone::NoEmbedding)?;
    Ok((frame, Layout::Disk { uv, ring, angles }))
}

/// [`cone_start`] and the apex it used.
fn start_and_apex(mesh: &Mesh) -> Result<(Mesh, [f64; 3]), NoCone> {
    let (frame, layout) = layout(mesh)?;
    let conn = mesh.conn();
    let patches = conn.patches();
    let loop_ = &patches[0].boundary_loops[0];
    let boundary: Vec<[f64; 3]> = loop_.iter().map(|&v| mesh.position(v)).collect();
    let interior: Vec<u32> = conn.interior_vertices().collect();
    let fan = Fan::new(&boundary, &frame);
    let place = |apex: Apex| -> Option<Vec<[f64; 3]>> {
        let mut pos = mesh.positions().to_vec();
        let polar = fan.polar_angles(apex.q);
        let flat = layout.flat(apex.q);
        if matches!(layout, Layout::Disk { .. }) && turns_over(mesh, &frame, &interior, &flat) {
            return None;
        }
        for (&v, &q) in interior.iter().zip(flat.iter()) {
            pos[v as usize] = frame.lift(q, fan.height(apex, &polar, q)?);
        }
        snap_nearest_to_apex(mesh, &frame, &mut pos, &interior, &flat, apex);
        Some(pos)
    };
    // Among the apexes whose fan leaves no corner below the floor, the one that moves the
    // vertices least; if none, the one with the largest smallest corner. Candidates are
    // independent, so they are scored in parallel; ties go to the earlier candidate. Apex
    // lines go through a fixed layout's points, else through the interior vertices'
    // projections (most lie inside the boundary's projection).
    let floor = smallest_corner(mesh, mesh.positions()).min(MIN_CORNER.to_radians());
    let through: Vec<[f64; 2]> = match &layout {
        Layout::Projected(flat) => flat.clone(),
        Layout::Disk { .. } => interior
            .iter()
            .map(|&v| frame.plane(mesh.position(v)))
            .collect(),
    };
    let apexes: Vec<Apex> = candidate_lines(&fan, &through)
        .into_par_iter()
        .flat_map_iter(|q| fan.apexes(q))
        .collect();
    let keys: Vec<Option<(bool, f64)>> = apexes
        .par_iter()
        .map(|&apex| {
            let pos = place(apex)?;
            let corner = smallest_corner(mesh, &pos);
            let moved: f64 = interior
                .iter()
                .map(|&v| {
                    let d = sub(pos[v as usize], mesh.position(v));
                    dot(d, d)
                })
                .sum();
            let ok = corner >= floor;
            let key = if ok { moved } else { -corner };
            key.is_finite().then_some((!ok, key))
        })
        .collect();
    let best = (0..apexes.len())
        .filter_map(|i| keys[i].map(|k| (i, k)))
        .min_by(|a, b| a.1 .0.cmp(&b.1 .0).then(a.1 .1.total_cmp(&b.1 .1)))
        .ok_or(NoCone::NoApex)?
        .0;
    let apex = apexes[best];
    let pos = place(apex).ok_or(NoCone::NoApex)?;
    let start = mesh.with_positions(pos).map_err(|_| NoCone::NoApex)?;
    Ok((start, frame.lift(apex.q, apex.h)))
}

/// Whether a triangle turns over (or degenerates) in the plane when the interior vertices are
/// at `flat` (in `interior` order) and the boundary at its projection.
fn turns_over(mesh: &Mesh, frame: &Frame, interior: &[u32], flat: &[[f64; 2]]) -> bool {
    let mut at: Vec<[f64; 2]> = mesh.positions().iter().map(|&p| frame.plane(p)).collect();
    for (&v, &q) in interior.iter().zip(flat) {
        at[v as usize] = q;
    }
    folds_in_plane(mesh.triangles(), &at)
}

/// Whether a triangle turns clockwise (or degenerates) at plane positions `at`.
fn folds_in_plane(tris: &[[u32; 3]], at: &[[f64; 2]]) -> bool {
    tris.iter().any(|t| {
        let [a, b, c] = t.map(|v| at[v as usize]);
        let turn = cross2(sub2(b, a), sub2(c, a));
        turn.is_nan() || turn <= 0.0
    })
}

/// The smallest corner angle of the mesh's triangles at positions `pos`: the largest cosine,
/// one arccosine at the end (no arctangent per corner: this scores every candidate apex). A
/// corner with a zero-length side counts as 0.
fn smallest_corner(mesh: &Mesh, pos: &[[f64; 3]]) -> f64 {
    let cosine = |o: [f64; 3], a: [f64; 3], b: [f64; 3]| {
        let (u, v) = (sub(a, o), sub(b, o));
        let c = dot(u, v) / (dot(u, u).sqrt() * dot(v, v).sqrt());
        if c.is_nan() {
            1.0
        } else {
            c
        }
    };
    let largest = mesh
        .triangles()
        .iter()
        .map(|t| {
            let p = t.map(|v| pos[v as usize]);
            cosine(p[0], p[1], p[2])
                .max(cosine(p[1], p[2], p[0]))
                .max(cosine(p[2], p[0], p[1]))
        })
        .fold(-1.0, f64::max);
    largest.clamp(-1.0, 1.0).acos()
}

/// Orthonormal (e1, e2, d) with e1 × e2 = d: plane coordinates and heights along d.
struct Frame {
    e1: [f64; 3],
    e2: [f64; 3],
    d: [f64; 3],
}

impl Frame {
    fn new(d: [f64; 3]) -> Frame {
        let t = if d[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let e1 = geometry::normalize(cross(t, d));
        let e2 = cross(d, e1);
        Frame { e1, e2, d }
    }
    fn plane(&self, p: [f64; 3]) -> [f64; 2] {
        [dot(p, self.e1), dot(p, self.e2)]
    }
    fn height(&self, p: [f64; 3]) -> f64 {
        dot(p, self.d)
    }
    fn lift(&self, q: [f64; 2], h: f64) -> [f64; 3] {
        std::array::from_fn(|k| q[0] * self.e1[k] + q[1] * self.e2[k] + h * self.d[k])
    }
}

/// The boundary polygon in 3D and in plane coordinates, counter-clockwise.
struct Fan<'a> {
    points: Vec<[f64; 3]>,
    flat: Vec<[f64; 2]>,
    heights: Vec<f64>,
    frame: &'a Frame,
}

/// An apex: its plane position and height.
#[derive(Debug, Clone, Copy)]
struct Apex {
    q: [f64; 2],
    h: f64,
}

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn sub2(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

impl<'a> Fan<'a> {
    fn new(boundary: &[[f64; 3]], frame: &'a Frame) -> Fan<'a> {
        let mut points = boundary.to_vec();
        let area: f64 = (0..points.len())
            .map(|i| {
                cross2(
                    frame.plane(points[i]),
                    frame.plane(points[(i + 1) % points.len()]),
                )
            })
            .sum();
        if area < 0.0 {
            points.reverse();
        }
        let flat = points.iter().map(|&p| frame.plane(p)).collect();
        let heights = points.iter().map(|&p| frame.height(p)).collect();
        Fan {
            points,
            flat,
            heights,
            frame,
        }
    }

    fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether every boundary edge turns counter-clockwise around `q` (star-shaped from q).
    fn sees_all(&self, q: [f64; 2]) -> bool {
        let m = self.len();
        (0..m).all(|i| {
            let (a, b) = (sub2(self.flat[i], q), sub2(self.flat[(i + 1) % m], q));
            cross2(a, b) > 1e-12 * (dot2(a, a) + dot2(b, b))
        })
    }

    /// The cone angle at `p`: the length of the boundary's central projection.
    fn angle(&self, p: [f64; 3]) -> f64 {
        let m = self.len();
        (0..m)
            .map(|i| {
                let (a, b) = (sub(self.points[i], p), sub(self.points[(i + 1) % m], p));
                let c = cross(a, b);
                dot(c, c).sqrt().atan2(dot(a, b))
            })
            .sum()
    }

    /// The points on the line along d through `q` where the cone angle is 2π, above and
    /// below the height of largest angle (found on a grid over the boundary's heights).
    fn apexes(&self, q: [f64; 2]) -> Vec<Apex> {
        if !self.sees_all(q) {
            return Vec::new();
        }
        let (lo, hi) = self
            .heights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        let span = (hi - lo).max(1e-9 * (1.0 + lo.abs().max(hi.abs())));
        let at = |h: f64| self.angle(self.frame.lift(q, h));
        let grid = 32;
        let (peak, best) = (0..=grid)
            .map(|k| lo + span * k as f64 / grid as f64)
            .map(|h| (h, at(h)))
            .fold(
                (lo, f64::NEG_INFINITY),
                |b, x| if x.1 > b.1 { x } else { b },
            );
        if best.is_nan() || best <= TAU {
            return Vec::new();
        }
        let mut out = Vec::new();
        for dir in [1.0, -1.0] {
            let mut far = span;
            while at(peak + dir * far) > TAU && far < 1e6 * span {
                far *= 2.0;
            }
            let Some(x) = root(|x| at(peak + dir * x) - TAU, best - TAU, far) else {
                continue;
            };
            let h = peak + dir * x;
            if h.is_finite() {
                out.push(Apex { q, h });
            }
        }
        out
    }

    /// The polar angles around `q` of the boundary points, measured from b₀'s and
    /// increasing (the boundary is star-shaped from q): computed once per apex, so that
    /// [`Fan::height`] costs one arctangent and a binary search.
    fn polar_angles(&self, q: [f64; 2]) -> Polar {
        let polar = |x: [f64; 2]| {
            let r = sub2(x, q);
            r[1].atan2(r[0])
        };
        let base = polar(self.flat[0]);
        let angles = self
            .flat
            .iter()
            .map(|&b| (polar(b) - base).rem_euclid(TAU))
            .collect();
        Polar { q, base, angles }
    }

    /// The height of the fan from `apex` above plane point `p`, or None when p is outside
    /// the boundary polygon; `polar` from [`Fan::polar_angles`] at the apex.
    fn height(&self, apex: Apex, polar: &Polar, p: [f64; 2]) -> Option<f64> {
        let i = polar.sector(p);
        let m = self.len();
        let (a, b) = (
            sub2(self.flat[i], apex.q),
            sub2(self.flat[(i + 1) % m], apex.q),
        );
        let r = sub2(p, apex.q);
        let det = cross2(a, b);
        let (s, t) = (cross2(r, b) / det, cross2(a, r) / det);
        let slack = 1e-9;
        if s < -slack || t < -slack || s + t > 1.0 + slack {
            return None;
        }
        let h = apex.h + s * (self.heights[i] - apex.h) + t * (self.heights[(i + 1) % m] - apex.h);
        h.is_finite().then_some(h)
    }
}

/// Polar angles of the boundary points around an apex q: b₀'s, and each one's from it.
struct Polar {
    q: [f64; 2],
    base: f64,
    angles: Vec<f64>,
}

impl Polar {
    /// The fan triangle (apex, i, i + 1) whose angular sector around q holds `p`: the last
    /// i whose angle is ≤ p's, by binary search (angles[0] = 0).
    fn sector(&self, p: [f64; 2]) -> usize {
        let r = sub2(p, self.q);
        let target = (r[1].atan2(r[0]) - self.base).rem_euclid(TAU);
        self.angles.partition_point(|&a| a <= target).max(1) - 1
    }
}

fn dot2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The lines tried for the apex: through the boundary's centroid and through up to
/// `CANDIDATES − 1` interior vertices taken at an even stride.
fn candidate_lines(fan: &Fan<'_>, flat: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let m = fan.len() as f64;
    let c = fan
        .flat
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0] / m, s[1] + p[1] / m]);
    let stride = (flat.len() / (CANDIDATES - 1)).max(1);
    std::iter::once(c)
        .chain(flat.iter().step_by(stride).copied())
        .take(CANDIDATES)
        .collect()
}

/// Put the interior vertex nearest (in the plane) to the apex onto it, when that keeps every
/// triangle around it turning the same way in the plane; so that the cone point is a vertex.
fn snap_nearest_to_apex(
    mesh: &Mesh,
    frame: &Frame,
    pos: &mut [[f64; 3]],
    interior: &[u32],
    flat: &[[f64; 2]],
    apex: Apex,
) {
    let Some((&v, _)) = interior.iter().zip(flat).min_by(|a, b| {
        dot2(sub2(*a.1, apex.q), sub2(*a.1, apex.q))
            .total_cmp(&dot2(sub2(*b.1, apex.q), sub2(*b.1, apex.q)))
    }) else {
        return;
    };
    let keeps_turning = mesh.conn().fan_of(v).iter().all(|&h| {
        let t = mesh.triangles()[h as usize / 3];
        let at = |u: u32| {
            if u == v {
                apex.q
            } else {
                frame.plane(pos[u as usize])
            }
        };
        let (a, b, c) = (at(t[0]), at(t[1]), at(t[2]));
        cross2(sub2(b, a), sub2(c, a)) > 0.0
    });
    if keeps_turning {
        pos[v as usize] = frame.lift(apex.q, apex.h);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::{Family, Procedural};

    /// Independent check: the apex is a 2π cone point of the boundary polygon (brute-force
    /// sum of its angles), every interior vertex lies on one of the planar fan triangles from
    /// it (brute-force closest point), and the boundary is kept; with `d` (a height field),
    /// also every vertex's position in the plane orthogonal to d (but the one put on the apex).
    fn assert_on_a_flat_cone(mesh: &Mesh, (start, apex): (Mesh, [f64; 3]), d: Option<[f64; 3]>) {
        let b: Vec<[f64; 3]> = mesh.conn().boundary_loops()[0]
            .iter()
            .map(|&v| mesh.position(v))
            .collect();
        for &v in &mesh.conn().boundary_loops()[0] {
            assert_eq!(start.position(v), mesh.position(v));
        }
        let m = b.len();
        let angle_at = |p: [f64; 3]| -> f64 {
            (0..m)
                .map(|i| {
                    let (x, y) = (sub(b[i], p), sub(b[(i + 1) % m], p));
                    dot(cross(x, y), cross(x, y)).sqrt().atan2(dot(x, y))
                })
                .sum()
        };
        assert!(
            (angle_at(apex) - TAU).abs() < 1e-9,
            "cone angle {}",
            angle_at(apex)
        );
        let tris: Vec<[u32; 3]> = (0..m as u32)
            .map(|i| [m as u32, i, (i + 1) % m as u32])
            .collect();
        let mut pts = b.clone();
        pts.push(apex);
        let h = geometry::mean_edge_length(mesh);
        let mut sideways = 0;
        for v in mesh.conn().interior_vertices() {
            let (p, q) = (start.position(v), mesh.position(v));
            let d2 = crate::spatial::brute_closest_d2(p, &pts, &tris);
            assert!(
                d2.sqrt() < 1e-9 * h,
                "vertex {v} is {} off the fan",
                d2.sqrt()
            );
            let Some(d) = d else { continue };
            let along = dot(sub(p, q), d);
            let side = sub(sub(p, q), [along * d[0], along * d[1], along * d[2]]);
            if dot(side, side).sqrt() > 1e-9 * h {
                sideways += 1;
            }
        }
        assert!(sideways <= 1, "{sideways} vertices moved sideways");
    }

    fn mean_normal(mesh: &Mesh) -> [f64; 3] {
        let (n, a) = (geometry::face_normals(mesh), geometry::face_areas(mesh));
        geometry::normalize(n.iter().zip(&a).fold([0.0; 3], |s, (n, a)| {
            [s[0] + a * n[0], s[1] + a * n[1], s[2] + a * n[2]]
        }))
    }

    #[test]
    fn the_start_lies_on_a_flat_cone_over_the_boundary() {
        let mesh = Procedural {
            family: Family::Saddle,
            faces: 2_000,
            noise: 0.01,
        }
        .mesh();
        let start = start_and_apex(&mesh).expect("a saddle is a height-field disk");
        assert_on_a_flat_cone(&mesh, start, Some(mean_normal(&mesh)));
    }

    /// A pouch (a sphere with a hole, past its equator) is no height field: its start comes
    /// from the harmonic map into the opening's projection, and lies on a flat cone all the
    /// same; its area is well above the isoperimetric bound of its opening.
    #[test]
    fn a_pouch_lies_on_a_flat_cone_through_its_harmonic_map() {
        let mesh = crate::corpus::pouch(24);
        assert_eq!(disk_frame(&mesh).err(), Some(NoCone::NotAHeightField));
        // Its opening projects to a four-pointed, non-convex outline: the map into it folds,
        // so the layout goes through the unit disk.
        assert!(matches!(layout(&mesh), Ok((_, Layout::Disk { .. }))));
        let start = start_and_apex(&mesh).expect("the pouch's opening has a 2π apex");
        assert_on_a_flat_cone(&mesh, start, None);
        let excess = isoperimetric_excess(&mesh).expect("one disk");
        assert!(excess > 5.0, "{excess}");
    }

    /// A square dome with a leaning bump that overhangs (faces turned past vertical) is no
    /// height field, but its boundary, a square, is convex: the harmonic map into the
    /// boundary's projection is laid out directly, and the start lies on a flat cone.
    #[test]
    fn an_overhanging_dome_lies_on_a_flat_cone_through_the_map_into_its_outline() {
        let mesh = Procedural {
            family: Family::Dome,
            faces: 2_000,
            noise: 0.0,
        }
        .mesh();
        // x ↦ x + 0.45 b(x) turns back where 0.45 |b′| > 1 (up to 1.36): an overhang.
        let bumped: Vec<[f64; 3]> = mesh
            .positions()
            .iter()
            .map(|&[x, y, z]| {
                let b = (-(x * x + y * y) / 0.08).exp();
                [x + 0.45 * b, y, z + 0.6 * b]
            })
            .collect();
        let mesh = mesh.with_positions(bumped).unwrap();
        assert_eq!(disk_frame(&mesh).err(), Some(NoCone::NotAHeightField));
        assert!(matches!(layout(&mesh), Ok((_, Layout::Projected(_)))));
        let start = start_and_apex(&mesh).expect("a square has a 2π apex");
        assert_on_a_flat_cone(&mesh, start, None);
    }

    /// The isoperimetric ratio against a closed form: a flat square's A ÷ (P²/4π) is π/4
    /// whatever its grid, and a tube (two boundary loops) has none.
    #[test]
    fn a_square_has_an_isoperimetric_ratio_of_a_quarter_pi() {
        let square = Procedural {
            family: Family::Pleats,
            faces: 800,
            noise: 0.0,
        }
        .mesh();
        let flat: Vec<[f64; 3]> = square
            .positions()
            .iter()
            .map(|&[x, y, _]| [3.0 * x, 3.0 * y, 0.0])
            .collect();
        let square = square.with_positions(flat).unwrap();
        let ratio = isoperimetric_excess(&square).expect("one disk");
        assert!(
            (ratio - std::f64::consts::FRAC_PI_4).abs() < 1e-12,
            "{ratio}"
        );
        let tube = Procedural {
            family: Family::Tube,
            faces: 800,
            noise: 0.0,
        }
        .mesh();
        assert_eq!(isoperimetric_excess(&tube), None);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(32))]
        /// Saddles, domes and pleats of random size and noise, turned and scaled at random:
        /// the start, when there is one, lies on a flat cone over the boundary, and with
        /// noise up to 0.1 edge lengths there always is one.
        #[test]
        fn random_height_field_disks_land_on_a_flat_cone(
            family in 0usize..3,
            faces in 100usize..2500,
            noise in 0.0f64..0.15,
            yaw in 0.0f64..TAU,
            pitch in -1.0f64..1.0,
            scale in 0.01f64..100.0,
        ) {
            let family = [Family::Saddle, Family::Dome, Family::Pleats][family];
            let mesh = Procedural { family, faces, noise }.mesh();
            let (cy, sy, cp, sp) = (yaw.cos(), yaw.sin(), pitch.cos(), pitch.sin());
            let moved: Vec<[f64; 3]> = mesh
                .positions()
                .iter()
                .map(|&[x, y, z]| {
                    let (x, y) = (cy * x - sy * y, sy * x + cy * y);
                    let (y, z) = (cp * y - sp * z, sp * y + cp * z);
                    [scale * x + 3.0, scale * y - 1.0, scale * z + 0.5]
                })
                .collect();
            let mesh = mesh.with_positions(moved).unwrap();
            // Only rough noise may tilt a face past the height-field margin; the harmonic
            // layout then places the vertices, not the projection.
            let d = disk_frame(&mesh).ok().map(|_| mean_normal(&mesh));
            proptest::prop_assert!(d.is_some() || noise > 0.1, "{family:?} {faces} {noise}");
            match start_and_apex(&mesh) {
                Ok(start) => assert_on_a_flat_cone(&mesh, start, d),
                Err(e) => proptest::prop_assert!(
                    noise > 0.1 && matches!(e, NoCone::NoEmbedding | NoCone::NoApex),
                    "{family:?} {faces} {noise}: {e}"
                ),
            }
        }
    }

    #[test]
    fn a_tube_and_an_overhang_are_refused() {
        let tube = Procedural {
            family: Family::Tube,
            faces: 2_000,
            noise: 0.0,
        }
        .mesh();
        assert_eq!(cone_start(&tube).err(), Some(NoCone::NotADisk));
        // 240° of a cone around its axis: its boundary is not star-shaped from any apex.
        let wrapped = Procedural {
            family: Family::Cone,
            faces: 2_000,
            noise: 0.0,
        }
        .mesh();
        assert_eq!(cone_start(&wrapped).err(), Some(NoCone::NoApex));
        // A saddle whose half x > 0 is bent back by 150° about the y axis overhangs itself.
        let saddle = Procedural {
            family: Family::Saddle,
            faces: 2_000,
            noise: 0.0,
        }
        .mesh();
        let a = 150f64.to_radians();
        let bent: Vec<[f64; 3]> = saddle
            .positions()
            .iter()
            .map(|&[x, y, z]| {
                if x > 0.0 {
                    [x * a.cos() - z * a.sin(), y, x * a.sin() + z * a.cos()]
                } else {
                    [x, y, z]
                }
            })
            .collect();
        let bent = saddle.with_positions(bent).unwrap();
        assert_eq!(disk_frame(&bent).err(), Some(NoCone::NotAHeightField));
        // Its harmonic layout exists, but the boundary's projection on the plane of its
        // vector area is star-shaped from no candidate apex.
        assert_eq!(cone_start(&bent).err(), Some(NoCone::NoApex));
    }

    /// A height field z = f(x, y) over [−1, 1]² with about `faces` faces, normal noise of
    /// `noise` mean edge lengths, turned and scaled rigidly.
    fn height_field(faces: usize, noise: f64, f: impl Fn(f64, f64) -> f64, scale: f64) -> Mesh {
        let n = ((faces as f64 / 2.0).sqrt().round() as usize).max(2);
        let xy = |i: usize| 2.0 * i as f64 / n as f64 - 1.0;
        let (positions, triangles, _) = crate::fixtures::grid(
            n,
            n,
            false,
            |i, j| [xy(i), xy(j), f(xy(i), xy(j))],
            |_, _| true,
        );
        let count = triangles.len();
        let mesh = Mesh::new(crate::mesh::RawMesh {
            positions,
            triangles,
            face_patch: vec![0; count],
            patch_names: vec!["p".into()],
            uv: None,
        })
        .unwrap()
        .0;
        let mesh = crate::corpus::with_normal_noise(&mesh, noise, faces as u64);
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        let turned: Vec<[f64; 3]> = mesh
            .positions()
            .iter()
            .map(|&[x, y, z]| {
                [
                    scale * (c * x - s * z) + 2.0,
                    scale * y,
                    scale * (s * x + c * z),
                ]
            })
            .collect();
        mesh.with_positions(turned).unwrap()
    }

    #[test]
    fn the_fitted_curvature_of_a_spherical_cap_is_its_area_over_r_squared() {
        // K = 1/R² everywhere on a sphere, so ∫K dA = A/R²; A summed over a fine mesh of the
        // same cap (independent of the fit).
        let r = 2.5;
        let cap = |x: f64, y: f64| (r * r - x * x - y * y).sqrt();
        let fine = height_field(200_000, 0.0, cap, 1.0);
        let truth = geometry::face_areas(&fine).iter().sum::<f64>() / (r * r);
        for (faces, noise) in [(7_700, 0.0), (7_700, 0.1), (20_000, 0.1)] {
            let k = fitted_curvature(&height_field(faces, noise, cap, 1.0)).unwrap();
            // Noise skews the sampled curvatures, so their median reads low: up to a
            // quarter at 0.1 edge lengths on 7.7k faces (a guide for a threshold, not a
            // measurement).
            let slack = if noise > 0.0 { 0.25 } else { 0.01 };
            assert!(
                (k.total - truth).abs() < slack * truth,
                "{faces} faces, noise {noise}: {k:?} against {truth}"
            );
            for scale in [0.01, 100.0] {
                let other = fitted_curvature(&height_field(faces, noise, cap, scale)).unwrap();
                assert!(
                    (other.total - k.total).abs() < 1e-6 * truth,
                    "×{scale}: {other:?} against {k:?}"
                );
            }
        }
    }

    #[test]
    fn auto_starts_saddles_and_domes_from_the_cone_never_developable_sheets() {
        use super::super::curved;
        type Surface = dyn Fn(f64, f64) -> f64;
        let sheets: [(&str, &Surface); 3] = [
            ("cylinder", &|x, _| (4.0 - x * x).sqrt()),
            ("pleats", &|x, _| {
                0.15 * (3.0 * std::f64::consts::PI * x).sin()
            }),
            ("cone", &|x, y| -((x - 3.0).powi(2) + y * y).sqrt()),
        ];
        let sizes = [(7_700, 0.01), (7_700, 0.1), (20_000, 0.1)];
        for (name, f) in sheets {
            for (faces, noise) in sizes {
                let m = height_field(faces, noise, f, 1.0);
                let k = fitted_curvature(&m).unwrap();
                assert!(k.total.abs() < 0.5, "{name} {faces} {noise}: {k:?}");
                assert_eq!(curved(&m), None, "{name} {faces} {noise}: {k:?}");
            }
        }
        let curved_ones: [(&str, &Surface); 2] = [
            ("saddle", &|x, y| 0.5 * (x * x - y * y)),
            ("dome", &|x, y| 0.5 * (2.0 - x * x - y * y)),
        ];
        for (name, f) in curved_ones {
            for (faces, noise) in sizes {
                let m = height_field(faces, noise, f, 1.0);
                let k = fitted_curvature(&m).unwrap();
                let signed = if name == "saddle" {
                    k.total <= -super::super::CONE_FIRST_SADDLE
                } else {
                    k.total >= super::super::CONE_FIRST_DOME
                };
                assert!(
                    signed && curved(&m).is_some(),
                    "{name} {faces} {noise}: {k:?}"
                );
            }
        }
        // Too few vertices per neighbourhood to fit (2k faces: about 35): no verdict.
        for noise in [0.0, 0.1] {
            let coarse = height_field(2_000, noise, |x, y| 0.5 * (x * x - y * y), 1.0);
            assert_eq!(fitted_curvature(&coarse), Ok(Curvature::default()));
        }
    }

    #[test]
    fn the_root_finder_agrees_with_bisection_and_refuses_a_non_bracket() {
        // Decreasing functions with a root in (0, b), some far from linear.
        let cases: [(&dyn Fn(f64) -> f64, f64); 4] = [
            (&|x| 1.0 - x, 3.0),
            (&|x| (-5.0 * x).exp() - 0.01, 2.0),
            (&|x| 0.5 - x.powi(7), 1.5),
            (&|x| (1.0 - x).cbrt(), 4.0),
        ];
        for (g, b) in cases {
            let x = root(g, g(0.0), b).expect("a bracket");
            let (mut lo, mut hi) = (0.0, b);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if g(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            assert!((x - lo).abs() < 1e-9 * b, "{x} against {lo}");
        }
        assert_eq!(root(|x| 1.0 + x, 1.0, 2.0), None);
        assert_eq!(root(|_| f64::NAN, 1.0, 2.0), None);
        assert_eq!(root(|x| -x, 0.0, 2.0), None);
    }

    #[test]
    fn sectors_and_smallest_corners_match_brute_force() {
        let mesh = Procedural {
            family: Family::Dome,
            faces: 800,
            noise: 0.05,
        }
        .mesh();
        let frame = disk_frame(&mesh).unwrap();
        let boundary: Vec<[f64; 3]> = mesh.conn().boundary_loops()[0]
            .iter()
            .map(|&v| mesh.position(v))
            .collect();
        let fan = Fan::new(&boundary, &frame);
        let q = [0.1, -0.2];
        let polar = fan.polar_angles(q);
        let m = fan.len();
        for v in mesh.conn().interior_vertices() {
            let p = frame.plane(mesh.position(v));
            let i = polar.sector(p);
            // p lies in the angular sector between b_i and b_{i+1} seen from q.
            let (a, b, r) = (
                sub2(fan.flat[i], q),
                sub2(fan.flat[(i + 1) % m], q),
                sub2(p, q),
            );
            assert!(
                cross2(a, r) >= -1e-12 && cross2(r, b) >= -1e-12,
                "vertex {v}, sector {i}"
            );
        }
        let brute = geometry::min_corner_angles(&mesh)
            .into_iter()
            .fold(std::f64::consts::PI, f64::min);
        let fast = smallest_corner(&mesh, mesh.positions());
        assert!((fast - brute).abs() < 1e-7, "{fast} against {brute}");
    }
}
