//! fl-mesh never returns a mesh worse than its input: on every real open mesh of
//! ../shared/meshes, on the procedural corpus and on random and adversarial inputs. ϖ, folds
//! and angles are measured from the geometry of input and output (flatmesh::corpus::measure),
//! never taken from the solver's report; the report is checked against those measures.

use flatmesh::algorithms::fl_mesh::{self, Params};
use flatmesh::algorithms::Silent;
use flatmesh::corpus::{self, Family, Procedural};
use flatmesh::mesh::{Mesh, VertexKind};
use proptest::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// ../shared/meshes, or None with a visible notice; under CI=true its absence is a failure.
fn shared_root() -> Option<PathBuf> {
    corpus::shared_root_for_tests("fl-mesh on the real-mesh corpus")
}

/// Run and check what must hold for every input; returns (ϖ in, ϖ out, converged).
fn check_never_worse(name: &str, mesh: &Mesh, params: &Params) -> (f64, f64, bool) {
    let (out, report) = checked_run(name, mesh, params);
    let m = corpus::measure(mesh, &out);
    (m.varpi_in, m.varpi_out, report.converged)
}

/// [`check_never_worse`]'s run and checks, returning the output and the report.
fn checked_run(name: &str, mesh: &Mesh, params: &Params) -> (Mesh, fl_mesh::Report) {
    let (out, report) = fl_mesh::solve(mesh, params, &Silent::default()).expect("runs");
    let m = corpus::measure(mesh, &out);
    assert!(m.varpi_out.is_finite(), "{name}: non-finite ϖ");
    assert!(
        m.varpi_out <= m.varpi_in,
        "{name}: ϖ_max {:e} in, {:e} out",
        m.varpi_in,
        m.varpi_out
    );
    // Boundary and seam vertices bit-identical; input vertex i is output vertex i.
    for (v, kind) in mesh.conn().kinds().iter().enumerate() {
        if *kind != VertexKind::Interior {
            let (a, b) = (mesh.positions()[v], out.positions()[v]);
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{name}: boundary vertex {v} moved"
            );
        }
    }
    // The report agrees with the measures.
    assert_eq!(report.max_flattenability, m.varpi_out, "{name}");
    assert_eq!(
        report.converged,
        m.varpi_out <= params.tolerance,
        "{name}: converged flag vs measured ϖ_max {:e}",
        m.varpi_out
    );
    let theta = flatmesh::geometry::angle_sums(&out);
    let w = flatmesh::geometry::flattenability(&out, &theta);
    let mut above: Vec<u32> = (0..w.len() as u32)
        .filter(|&v| w[v as usize] > params.tolerance)
        .collect();
    let mut stuck = report.stuck_vertices.clone();
    above.sort_unstable();
    stuck.sort_unstable();
    assert_eq!(
        stuck, above,
        "{name}: stuck vertices are those above the tolerance"
    );
    // Unfolding never adds a fold, and says what the output has (when remeshing did not
    // change it afterwards).
    let remeshed = report.remesh.as_ref().is_some_and(|r| r.rounds > 0);
    if let Some(r) = &report.remesh {
        // A round is kept on a lower ϖ_max when the result before it was unconverged, else on
        // fewer new folds plus slivers (flattenable, so ϖ_max may move within the
        // tolerance); what it says it reached is what the output has.
        assert!(
            r.max_flattenability[1] <= r.max_flattenability[0].max(params.tolerance),
            "{name}: {r:?}"
        );
        assert_eq!(r.max_flattenability[1], m.varpi_out, "{name}: {r:?}");
        if r.max_flattenability[0] <= params.tolerance {
            assert!(
                r.new_folds[1] + r.new_slivers[1] <= r.new_folds[0] + r.new_slivers[0],
                "{name}: {r:?}"
            );
        }
        // What it says it left is what the output has, counted here from the geometry.
        let (folds_in, slivers_in) = folds_and_slivers(mesh, params.min_angle);
        let (folds, slivers) = folds_and_slivers(&out, params.min_angle);
        assert_eq!(
            [
                folds.difference(&folds_in).count(),
                slivers.difference(&slivers_in).count()
            ],
            [r.new_folds[1], r.new_slivers[1]],
            "{name}: {r:?}"
        );
    }
    if let Some(u) = report.unfold.as_ref().filter(|_| !remeshed) {
        assert!(u.folds_after <= u.folds_before, "{name}: {u:?}");
        assert_eq!(u.folds_after, m.folds_out, "{name}: {u:?}");
        assert!(u.opened <= u.tried, "{name}: {u:?}");
        let slivers = flatmesh::geometry::min_corner_angles(&out)
            .into_iter()
            .filter(|&a| a < params.min_angle.to_radians())
            .count();
        assert_eq!(u.slivers_after, slivers, "{name}: {u:?}");
    }
    if params.shape_guard {
        assert!(
            m.folds_out <= m.folds_in,
            "{name}: folds {} -> {}",
            m.folds_in,
            m.folds_out
        );
        let floor = params.min_angle.to_radians().min(0.5 * m.min_angle_in);
        assert!(
            m.min_angle_out >= floor * (1.0 - 1e-9),
            "{name}: smallest angle {}° -> {}°",
            m.min_angle_in.to_degrees(),
            m.min_angle_out.to_degrees()
        );
    }
    eprintln!(
        "{name}: ϖ_max {:.2e} -> {:.2e}, folds {} -> {}, min angle {:.2}° -> {:.2}°, \
         hausdorff {:.3}%, converged {}",
        m.varpi_in,
        m.varpi_out,
        m.folds_in,
        m.folds_out,
        m.min_angle_in.to_degrees(),
        m.min_angle_out.to_degrees(),
        100.0 * m.hausdorff_relative,
        report.converged
    );
    (out, report)
}

/// A budget that keeps the suite short (20 iterations; on the 2-core VM the real meshes took
/// 263 s with 60, 131 s with 30); the property holds for any budget. Without the detour, which
/// would run on every mesh this budget leaves unconverged and triple the test's time; it has
/// its own test below, with the same checks.
fn budget() -> Params {
    Params {
        max_iterations: 20,
        detour: false,
        ..Params::default()
    }
}

/// mh_male_worksuit01 with the defaults stalls (its shirt, χ = −9, at ϖ_max 0.145 in 2026-11
/// without the detour); the detour through develop's SQP and fl-mesh again takes it lower,
/// with everything `check_never_worse` asks (ϖ from the geometry, boundary and seams
/// bit-identical, the report agreeing with the measures).
///
/// Named to run first: the suite's longest test (two whole-suit runs), it would otherwise
/// start last and run alone.
#[test]
fn a_stalled_whole_suit_goes_lower_through_the_sqp_detour() {
    let Some(root) = shared_root() else { return };
    let path = root.join("garment/mh_male_worksuit01.obj");
    let (mesh, _) = flatmesh::io::load_path(&path).expect("loads");
    // Remeshing, which follows the detour, is off in both runs: this measures the detour.
    let on = Params {
        remesh: false,
        ..Params::default()
    };
    let off = Params {
        detour: false,
        ..on.clone()
    };
    let (_, w_off, conv_off) = check_never_worse("worksuit without the detour", &mesh, &off);
    assert!(!conv_off, "converged without the detour: pick another mesh");
    let (_, w_on, _) = check_never_worse("worksuit", &mesh, &on);
    assert!(
        w_on < 0.5 * w_off,
        "ϖ_max {w_off:e} without the detour, {w_on:e} with it"
    );
}

#[test]
fn never_worse_on_every_real_open_mesh() {
    let Some(root) = shared_root() else { return };
    let paths = corpus::shared_open_meshes(&root).expect("MANIFEST.tsv lists the meshes");
    assert!(paths.len() >= 20, "only {} open meshes listed", paths.len());
    let mut ran = 0;
    for p in &paths {
        let Ok((mesh, _)) = flatmesh::io::load_path(p) else {
            // Refused inputs (non-manifold, degenerate) are the reader's tests' business.
            continue;
        };
        check_never_worse(&p.display().to_string(), &mesh, &budget());
        ran += 1;
    }
    assert!(ran >= 20, "only {ran} meshes loaded");
}

#[test]
fn closed_meshes_are_named_obstructions_and_left_as_they_are() {
    let Some(root) = shared_root() else { return };
    for p in corpus::shared_closed_meshes(&root).expect("manifest") {
        let (mesh, _) = flatmesh::io::load_path(&p).expect("closed meshes load");
        let (out, report) = fl_mesh::solve(&mesh, &budget(), &Silent::default()).expect("runs");
        assert!(!report.converged);
        assert!(
            report.stop_reason.contains("Gauss–Bonnet"),
            "{}",
            report.stop_reason
        );
        assert_eq!(out.positions(), mesh.positions());
    }
}

#[test]
fn never_worse_on_the_small_procedural_corpus() {
    for p in corpus::procedural()
        .into_iter()
        .filter(|p| p.faces <= 2_000)
    {
        check_never_worse(&p.name(), &p.mesh(), &budget());
    }
}

#[test]
fn shape_guard_keeps_folds_and_angles() {
    let params = Params {
        shape_guard: true,
        ..budget()
    };
    for p in corpus::procedural()
        .into_iter()
        .filter(|p| p.faces <= 2_000)
    {
        check_never_worse(&format!("{} guarded", p.name()), &p.mesh(), &params);
    }
    for f in ["cube_cuts", "saddle", "hemisphere_cap", "cone_noisy"] {
        let m = Mesh::new(flatmesh::fixtures::by_name(f).unwrap().mesh)
            .unwrap()
            .0;
        check_never_worse(&format!("{f} guarded"), &m, &params);
    }
}

fn family() -> impl Strategy<Value = Family> {
    prop::sample::select(Family::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Random surfaces with noise from mild to violent (half an edge along the normal), and a
    /// few vertices kicked far out (adversarial spikes).
    #[test]
    fn never_worse_on_random_and_adversarial_inputs(
        fam in family(),
        faces in 60usize..400,
        noise in 0.0f64..0.5,
        seed in any::<u64>(),
        kicks in prop::collection::vec((any::<prop::sample::Index>(), -3.0f64..3.0), 0..4),
        guard in any::<bool>(),
    ) {
        let base = Procedural { family: fam, faces, noise: 0.0 }.mesh();
        let mesh = corpus::with_normal_noise(&base, noise, seed);
        let h = flatmesh::geometry::mean_edge_length(&mesh);
        let interior: Vec<u32> = mesh.conn().interior_vertices().collect();
        prop_assume!(!interior.is_empty());
        let normals = flatmesh::geometry::vertex_normals(&mesh);
        let mut pos = mesh.positions().to_vec();
        for (i, amount) in &kicks {
            let v = interior[i.index(interior.len())] as usize;
            for c in 0..3 {
                pos[v][c] += amount * h * normals[v][c];
            }
        }
        let Ok(mesh) = mesh.with_positions(pos) else {
            return Err(TestCaseError::reject("kicks degenerated a triangle"));
        };
        let params = Params { max_iterations: 40, shape_guard: guard, ..Params::default() };
        check_never_worse("random", &mesh, &params);
    }
}

/// The shape penalty (default κ = 1) against the paper's model (κ = 0) on two real garments
/// that the paper's model converges on by creasing: both runs converge, and the penalised one
/// leaves at most half as many new folds (measured: t-shirt 81 → 25, shirt front 25 → 0).
#[test]
fn shape_penalty_halves_new_folds_on_garments() {
    let Some(root) = shared_root() else { return };
    for rel in [
        "garment/diffavatar_tshirt.obj",
        "garment/gf_shirtfront00041.obj",
    ] {
        let (mesh, _) = flatmesh::io::load_path(&root.join(rel)).expect("loads");
        let folds_in = flatmesh::geometry::fold_edges(&mesh).len();
        let mut new_folds = Vec::new();
        for kappa in [0.0, 1.0] {
            let params = Params {
                shape_penalty: kappa,
                // The penalty alone is compared here; unfolding has its own test.
                unfold: false,
                ..Params::default()
            };
            let (out, _) = fl_mesh::solve(&mesh, &params, &Silent::default()).expect("runs");
            let m = corpus::measure(&mesh, &out);
            assert!(
                m.varpi_out <= 1e-6,
                "{rel} κ = {kappa}: ϖ_max {:e}",
                m.varpi_out
            );
            new_folds.push(m.folds_out.saturating_sub(folds_in));
        }
        assert!(
            2 * new_folds[1] <= new_folds[0],
            "{rel}: new folds {} with the penalty, {} without",
            new_folds[1],
            new_folds[0]
        );
    }
}

/// Unfolding on the real garments whose converged results fold edges the input did not
/// (measured at 200 region iterations: t-shirt 18 → 3, gc_tee_sim 10 → 0): the result stays
/// flattenable, free vertices only move, and at least half of the run's folds open.
#[test]
fn unfolding_opens_most_new_folds_on_garments() {
    let Some(root) = shared_root() else { return };
    // Unfolding alone: remeshing, which mends what it leaves, has its own test.
    let params = Params {
        remesh: false,
        ..Params::default()
    };
    for rel in ["garment/diffavatar_tshirt.obj", "garment/gc_tee_sim.obj"] {
        let (mesh, _) = flatmesh::io::load_path(&root.join(rel)).expect("loads");
        let (out, report) = fl_mesh::solve(&mesh, &params, &Silent::default()).expect("runs");
        let m = corpus::measure(&mesh, &out);
        assert!(m.varpi_out <= 1e-6, "{rel}: ϖ_max {:e}", m.varpi_out);
        let u = report.unfold.as_ref().expect("new folds to open");
        assert_eq!(u.folds_after, m.folds_out, "{rel}: {u:?}");
        assert!(2 * u.folds_after <= u.folds_before, "{rel}: {u:?}");
        for (v, kind) in mesh.conn().kinds().iter().enumerate() {
            if *kind != VertexKind::Interior {
                assert_eq!(out.positions()[v], mesh.positions()[v], "{rel}: vertex {v}");
            }
        }
    }
}

/// Folded edges (normals turning past 120°) by vertex pair and faces with a corner below
/// `degrees` by sorted vertex triple, computed here from positions and faces alone.
fn folds_and_slivers(mesh: &Mesh, degrees: f64) -> (HashSet<[u32; 2]>, HashSet<[u32; 3]>) {
    let p = mesh.positions();
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let mut by_edge: HashMap<[u32; 2], Vec<[f64; 3]>> = HashMap::new();
    let mut slivers = HashSet::new();
    for t in mesh.triangles() {
        let [a, b, c] = t.map(|v| p[v as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let len = dot(n, n).sqrt();
        let n = n.map(|x| x / len);
        for k in 0..3 {
            let (u, v) = (t[k], t[(k + 1) % 3]);
            by_edge.entry([u.min(v), u.max(v)]).or_default().push(n);
            let (o, x, y) = (
                p[t[k] as usize],
                p[t[(k + 1) % 3] as usize],
                p[t[(k + 2) % 3] as usize],
            );
            let (e1, e2) = (sub(x, o), sub(y, o));
            let corner = dot(cross(e1, e2), cross(e1, e2)).sqrt().atan2(dot(e1, e2));
            if corner < degrees.to_radians() {
                let mut key = *t;
                key.sort_unstable();
                slivers.insert(key);
            }
        }
    }
    let folds = by_edge
        .into_iter()
        .filter(|(_, n)| n.len() == 2 && dot(n[0], n[1]) < -0.5)
        .map(|(e, _)| e)
        .collect();
    (folds, slivers)
}

/// What unfolding leaves on two shared garments (measured: t-shirt one new fold and one face
/// below 2°, pf_robert_shirt_14 one and four) is mended by flips and collapses and a re-solve:
/// each output is flattenable with no fold and no corner below 2° that its input did not
/// have, boundary vertices bit-identical, every removed vertex unreferenced and placed on the
/// vertex it was merged into. Measured here from positions and faces.
#[test]
fn remeshing_mends_the_folds_and_slivers_unfolding_left() {
    let Some(root) = shared_root() else { return };
    let tshirt = with_defaults(&root, "garment/diffavatar_tshirt.obj");
    for (rel, (mesh, out, report)) in [
        ("garment/diffavatar_tshirt.obj", &tshirt),
        (
            "garment/pf_robert_shirt_14.obj",
            robert_with_defaults(&root),
        ),
    ] {
        let m = corpus::measure(mesh, out);
        assert!(m.varpi_out <= 1e-6, "{rel}: ϖ_max {:e}", m.varpi_out);
        let r = report.remesh.as_ref().expect("something to mend");
        assert!(r.rounds >= 1, "{rel}: {r:?}");
        let (folds_in, slivers_in) = folds_and_slivers(mesh, 2.0);
        let (folds, slivers) = folds_and_slivers(out, 2.0);
        let new_folds: Vec<_> = folds.difference(&folds_in).collect();
        let new_slivers: Vec<_> = slivers.difference(&slivers_in).collect();
        assert!(new_folds.is_empty(), "{rel}: new folds {new_folds:?}");
        assert!(new_slivers.is_empty(), "{rel}: new slivers {new_slivers:?}");
        assert_eq!(r.new_folds[1] + r.new_slivers[1], 0, "{rel}: {r:?}");
        for (v, kind) in mesh.conn().kinds().iter().enumerate() {
            if *kind != VertexKind::Interior {
                assert_eq!(out.positions()[v], mesh.positions()[v], "{rel}: vertex {v}");
            }
        }
        for &[removed, kept] in &r.operations.merged {
            assert!(
                out.triangles().iter().all(|t| !t.contains(&removed)),
                "{rel}: removed vertex {removed} still in a face"
            );
            assert!(
                mesh.conn().is_interior(removed),
                "{rel}: {removed} was not interior"
            );
            let at = out.positions()[removed as usize];
            assert!(
                out.triangles()
                    .iter()
                    .flatten()
                    .any(|&v| out.positions()[v as usize] == at),
                "{rel}: vertex {removed} (merged into {kept}) is not on a used vertex"
            );
        }
    }
}

/// mh_female_elegantsuit01's top (a sphere with three openings) stalls with slivers and
/// folds the input did not have (measured 2026-11-27: ϖ_max 4.4e-3, 28 folded edges, smallest
/// corner 0.01°). Remeshing that stalled result and solving again keeps a round only when it
/// lowers ϖ_max (`remesh_defects`, the merit), so the result is never worse than the
/// run without remeshing, and a refused round leaves that run's result exactly. Measured: until
/// 2026-11-28 three rounds took it 4.4e-3 → 2.2e-3; since develop's SQP shortens refused
/// trials in place (2026-11-29; fl-mesh's detour runs it), round 1 re-solves to 4.5e-3 with 17
/// new folds and 4 slivers and is refused, so 4.4e-3 stays. Which of the two happens is a
/// matter of a stalled, chaotic run, so it is not asserted; checked against an independent
/// run without remeshing, from the geometry: ϖ_max no higher (lower when a round was kept, the
/// same mesh when none was), and the report's new folds and slivers recounted.
#[test]
fn remeshing_a_stalled_whole_garment_never_raises_its_flattenability() {
    let Some(root) = shared_root() else { return };
    let (mesh, _) =
        flatmesh::io::load_path(&root.join("garment/mh_female_elegantsuit01.obj")).expect("loads");
    let off = Params {
        remesh: false,
        ..Params::default()
    };
    let (before, _) = fl_mesh::solve(&mesh, &off, &Silent::default()).expect("runs");
    let b = corpus::measure(&mesh, &before);
    assert!(
        b.varpi_out > 1e-6,
        "converged without remeshing: pick another mesh"
    );
    let (out, report) = checked_run("elegantsuit", &mesh, &Params::default());
    let m = corpus::measure(&mesh, &out);
    let r = report
        .remesh
        .expect("the stalled result had slivers to mend");
    if r.rounds == 0 {
        assert_eq!(out.positions(), before.positions(), "{r:?}");
        assert_eq!(out.triangles(), before.triangles(), "{r:?}");
        assert!(r.stop_reason.contains("not kept"), "{r:?}");
    } else {
        assert!(
            m.varpi_out < b.varpi_out,
            "ϖ_max {:e} without remeshing, {:e} with it",
            b.varpi_out,
            m.varpi_out
        );
    }
    let (folds_in, slivers_in) = folds_and_slivers(&mesh, 2.0);
    let count = |m: &Mesh| {
        let (f, s) = folds_and_slivers(m, 2.0);
        f.difference(&folds_in).count() + s.difference(&slivers_in).count()
    };
    assert_eq!(
        r.new_folds[0] + r.new_slivers[0],
        count(&before),
        "the report's new folds plus slivers before remeshing, against the run without it"
    );
    assert_eq!(
        r.new_folds[1] + r.new_slivers[1],
        count(&out),
        "the report's new folds plus slivers after remeshing, against the geometry"
    );
}

/// `rel` and fl-mesh's result from it with the defaults.
fn with_defaults(root: &Path, rel: &str) -> (Mesh, Mesh, fl_mesh::Report) {
    let (mesh, _) = flatmesh::io::load_path(&root.join(rel)).expect("loads");
    let (out, report) =
        fl_mesh::solve(&mesh, &Params::default(), &Silent::default()).expect("runs");
    (mesh, out, report)
}

/// pf_robert_shirt_14 with the defaults, run once for the two tests that check it (22 s of
/// CI's CPU each time); the second to ask waits for the first.
fn robert_with_defaults(root: &Path) -> &'static (Mesh, Mesh, fl_mesh::Report) {
    static RUN: OnceLock<(Mesh, Mesh, fl_mesh::Report)> = OnceLock::new();
    RUN.get_or_init(|| with_defaults(root, "garment/pf_robert_shirt_14.obj"))
}

/// pf_robert_shirt_14's penalised run stalls and the paper's model from the input converges
/// crumpled (129 folded edges measured, 23 after unfolding); the paper's model started from
/// the penalised result instead converges with far fewer (20, then 1), and that is what is
/// returned. Measured here against an independent run of the paper's model from the input.
#[test]
fn the_papers_model_from_the_penalised_result_is_kept_when_it_folds_less() {
    let Some(root) = shared_root() else { return };
    let (mesh, out, report) = robert_with_defaults(&root);
    let plain = Params {
        shape_penalty: 0.0,
        ..Params::default()
    };
    let (paper, _) = fl_mesh::solve(mesh, &plain, &Silent::default()).expect("runs");
    let m = corpus::measure(mesh, out);
    let p = corpus::measure(mesh, &paper);
    assert!(m.varpi_out <= 1e-6, "ϖ_max {:e}", m.varpi_out);
    assert!(
        p.varpi_out <= 1e-6,
        "paper's model: ϖ_max {:e}",
        p.varpi_out
    );
    assert!(
        report
            .stop_reason
            .contains("from the penalised result instead"),
        "{}",
        report.stop_reason
    );
    assert!(
        2 * m.folds_out < p.folds_out,
        "folds {} against the paper's model's {}",
        m.folds_out,
        p.folds_out
    );
    assert_eq!(report.history.len(), report.iterations);
    for (v, kind) in mesh.conn().kinds().iter().enumerate() {
        if *kind != VertexKind::Interior {
            assert_eq!(out.positions()[v], mesh.positions()[v], "vertex {v}");
        }
    }
}

/// A penalised run that does not converge is followed by the paper's model from the input,
/// whose result is kept because it converges: the noisy 7.7k-face saddle (the penalised run
/// stalls near 1e-4 there with full-length normal steps, `step_radius = 0`; should it one day
/// converge, pick another case that falls back).
#[test]
fn a_stalled_penalised_run_falls_back_to_the_papers_model() {
    let mesh = Procedural {
        family: Family::Saddle,
        faces: 7_700,
        noise: 0.1,
    }
    .mesh();
    let stages = Stages::default();
    let params = Params {
        step_radius: 0.0,
        cone_start: fl_mesh::ConeStart::Never,
        ..Params::default()
    };
    let (out, r) = fl_mesh::solve(&mesh, &params, &stages).expect("runs");
    let m = corpus::measure(&mesh, &out);
    assert!(m.varpi_out <= 1e-6, "ϖ_max {:e}", m.varpi_out);
    assert!(r.converged);
    // Progress names the second run's stage, whose iterations count from 1 again.
    let seen = stages.0.lock().unwrap();
    let k = seen
        .iter()
        .position(|(s, _)| s == "newton, no shape penalty")
        .expect("the second run reports its own stage");
    assert_eq!(seen[k].1, 1);
    assert!(seen[..k]
        .iter()
        .all(|(s, _)| !s.contains("no shape penalty")));
    assert!(
        r.stop_reason.contains("without it, from the input"),
        "{}",
        r.stop_reason
    );
    // One history, the second run restarting from the input's ϖ_max; the returned iterate
    // is one of the second run's.
    assert_eq!(r.history.len(), r.iterations);
    let w0 = r.history[0].max_flattenability;
    let restart = (1..r.history.len())
        .find(|&k| r.history[k].max_flattenability == w0)
        .expect("the second run starts from the input");
    assert!(
        r.best_iteration > restart,
        "best {} restart {restart}",
        r.best_iteration
    );
}

/// A noisy saddle, which from the input stalls or crumples, converges from the developable
/// cone over its boundary: flattenable, no fold, no corner below 2°, boundary bit-identical,
/// with the cone's stage reported (ϖ measured from the output's angles, not the report).
#[test]
fn a_noisy_saddle_converges_from_its_developable_cone() {
    let mesh = Procedural {
        family: Family::Saddle,
        faces: 2_000,
        noise: 0.01,
    }
    .mesh();
    let stages = Stages::default();
    let params = Params {
        cone_start: fl_mesh::ConeStart::First,
        ..Params::default()
    };
    let (_, w_out, converged) = check_never_worse("saddle-2000-0.01", &mesh, &params);
    assert!(converged && w_out <= 1e-6, "ϖ_max {w_out:e}");
    let (out, r) = fl_mesh::solve(&mesh, &params, &stages).expect("runs");
    let m = corpus::measure(&mesh, &out);
    assert_eq!(m.folds_out, 0);
    assert!(
        m.min_angle_out >= 2f64.to_radians(),
        "{}°",
        m.min_angle_out.to_degrees()
    );
    assert!(r.iterations < 60, "{} iterations", r.iterations);
    // Accepted from the cone, not rejected and then solved from the input.
    assert!(
        r.stop_reason.starts_with("developable cone: ")
            && !r.stop_reason.contains("from the input"),
        "{}",
        r.stop_reason
    );
    assert!(stages
        .0
        .lock()
        .unwrap()
        .iter()
        .any(|(s, _)| s.ends_with("from the cone")));
}

/// With the defaults (`auto`), a 7.7k-face noisy saddle, whose fitted curvature is clearly
/// below −1 rad, starts from its developable cone: flattenable (measured here), no new fold,
/// smooth, in few iterations, and the stop reason says why the cone went first.
#[test]
fn by_default_a_curved_saddle_starts_from_its_developable_cone() {
    let mesh = Procedural {
        family: Family::Saddle,
        faces: 7_700,
        noise: 0.01,
    }
    .mesh();
    let (out, r) = fl_mesh::solve(&mesh, &Params::default(), &Silent::default()).expect("runs");
    let m = corpus::measure(&mesh, &out);
    assert!(m.varpi_out <= 1e-6, "ϖ_max {:e}", m.varpi_out);
    assert!(m.folds_out <= m.folds_in);
    let edges = mesh.conn().edges().len();
    assert!(
        creases(&out) <= creases(&mesh) + edges / 100,
        "{} creases",
        creases(&out)
    );
    assert!(r.iterations < 40, "{} iterations", r.iterations);
    assert!(
        r.stop_reason
            .starts_with("developable cone first (fitted total curvature -")
            && !r.stop_reason.contains("from the input"),
        "{}",
        r.stop_reason
    );
}

/// Edges whose two faces' normals turn by more than 60°, counted here from scratch (cross
/// products of the corner positions), not with the solver's own helper.
fn creases(mesh: &Mesh) -> usize {
    let normal = |t: [u32; 3]| {
        let p = t.map(|v| mesh.position(v));
        let (a, b) = (
            [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]],
            [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]],
        );
        let n = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|x| x / l)
    };
    let mut by_edge = std::collections::HashMap::<(u32, u32), Vec<[f64; 3]>>::new();
    for &t in mesh.triangles() {
        let n = normal(t);
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(n);
        }
    }
    by_edge
        .values()
        .filter(|ns| ns.len() == 2)
        .filter(|ns| ns[0][0] * ns[1][0] + ns[0][1] * ns[1][1] + ns[0][2] * ns[1][2] < 0.5)
        .count()
}

/// A pouch (a sphere with a hole, past its equator, like a shoe's upper) is no height field
/// and holds 11 times the area any flat disk with its opening can have: by default it ends
/// flattenable on the developable cone over its opening (from the harmonic layout), measured
/// from the output's angles; no fold, boundary bit-identical; and the output obeys the
/// isoperimetric inequality that makes it flattenable (area ≤ P²/4π, recomputed here from
/// the positions), which the stop reason names.
#[test]
fn a_pouch_ends_flattenable_on_the_cone_over_its_opening() {
    let mesh = corpus::pouch(24);
    let params = Params::default();
    let (_, w_out, converged) = check_never_worse("pouch-24", &mesh, &params);
    assert!(converged && w_out <= 1e-6, "ϖ_max {w_out:e}");
    let (out, r) = fl_mesh::solve(&mesh, &params, &Silent::default()).expect("runs");
    let m = corpus::measure(&mesh, &out);
    assert_eq!(m.folds_out, 0);
    let area = |x: &Mesh| -> f64 {
        x.triangles()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| x.position(v));
                let (u, w) = (
                    [0, 1, 2].map(|k| b[k] - a[k]),
                    [0, 1, 2].map(|k| c[k] - a[k]),
                );
                let n = [
                    u[1] * w[2] - u[2] * w[1],
                    u[2] * w[0] - u[0] * w[2],
                    u[0] * w[1] - u[1] * w[0],
                ];
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .sum()
    };
    let ring = &mesh.conn().boundary_loops()[0];
    let p: f64 = (0..ring.len())
        .map(|i| {
            let (a, b) = (
                mesh.position(ring[i]),
                mesh.position(ring[(i + 1) % ring.len()]),
            );
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        })
        .sum();
    let bound = p * p / (4.0 * std::f64::consts::PI);
    assert!(area(&mesh) > 5.0 * bound, "{} vs {bound}", area(&mesh));
    assert!(area(&out) <= bound, "{} vs {bound}", area(&out));
    assert!(
        r.stop_reason.contains("developable cone") && r.stop_reason.contains("isoperimetric"),
        "{}",
        r.stop_reason
    );
}

/// "Never worse" across runs: with the cone first and a budget too small for any run to
/// converge, the cone's unconverged result, far lower in ϖ_max than what the input's one
/// remaining iteration reaches, is what comes back, and the report describes that mesh
/// (ϖ_max and stuck vertices checked against the output's angles by `check_never_worse`).
#[test]
fn an_unconverged_cone_run_is_kept_when_it_reached_the_lowest_varpi() {
    let mesh = corpus::pouch(16);
    let params = Params {
        cone_start: fl_mesh::ConeStart::First,
        max_iterations: 3,
        refine: false,
        retry: false,
        ..Params::default()
    };
    let (w_in, w_out, converged) = check_never_worse("pouch-16-short", &mesh, &params);
    assert!(!converged);
    let (_, r) = fl_mesh::solve(&mesh, &params, &Silent::default()).expect("runs");
    assert!(
        r.stop_reason
            .contains("kept the developable cone's result, the lowest ϖ_max reached"),
        "{}",
        r.stop_reason
    );
    // The input's own run had one iteration: the cone's result is far lower.
    assert!(w_out < 0.1 * w_in, "{w_in:e} -> {w_out:e}");
    assert!(r.best_iteration <= r.iterations && r.history.len() == r.iterations);
}

/// With `fallback`, a noisy saddle that the run from the input makes flattenable only by
/// crumpling it (hundreds of edges turning past 60°) is handed to the developable cone, whose
/// result is smooth: flattenable, no new fold, and creases on under 1 % of the edges.
#[test]
fn a_crumpled_result_is_replaced_by_the_developable_cone() {
    let fallback = Params {
        cone_start: fl_mesh::ConeStart::Fallback,
        ..Params::default()
    };
    let mesh = Procedural {
        family: Family::Saddle,
        faces: 2_000,
        noise: 0.1,
    }
    .mesh();
    let crumpled = Params {
        cone_start: fl_mesh::ConeStart::Never,
        ..Params::default()
    };
    let (plain, _) = fl_mesh::solve(&mesh, &crumpled, &Silent::default()).expect("runs");
    let edges = mesh.conn().edges().len();
    assert!(
        creases(&plain) > creases(&mesh) + edges / 100,
        "the run from the input no longer crumples ({} creases): pick another case",
        creases(&plain)
    );
    let (_, w_out, converged) = check_never_worse("saddle-2000-0.1", &mesh, &fallback);
    assert!(converged && w_out <= 1e-6);
    let (out, r) = fl_mesh::solve(&mesh, &fallback, &Silent::default()).expect("runs");
    assert!(r.stop_reason.contains("but crumpled"), "{}", r.stop_reason);
    let m = corpus::measure(&mesh, &out);
    assert!(m.folds_out <= m.folds_in);
    assert!(
        creases(&out) <= creases(&mesh) + edges / 100,
        "{} creases",
        creases(&out)
    );
}

/// Records every progress report's stage and iteration.
#[derive(Default)]
struct Stages(std::sync::Mutex<Vec<(String, usize)>>);

impl flatmesh::algorithms::Control for Stages {
    fn progress(&self, p: &flatmesh::algorithms::Progress) {
        self.0.lock().unwrap().push((p.stage.clone(), p.iteration));
    }
    fn cancelled(&self) -> bool {
        false
    }
}
