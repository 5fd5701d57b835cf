//! Turn a finished job into the files a user downloads: `report.json`, `mesh.glb`, `mesh.gltf`,
//! `mesh.obj`; patterns (`patterns.json`, `.svg`, `.dxf` in the AAMA layout, `patterns-plain.dxf`) for a job that flattens or changes
//! the mesh; and for `subdivide` every level's `level_<k>.glb`, `.gltf` and `.obj`. The CLI
//! writes them into a directory and the service stores them; both call [`render`], so the two
//! give the same files.

use super::{JobOutcome, Kind};
use crate::algorithms::{flatten, AlgoError, Control};
use crate::io;
use crate::mesh::{Mesh, Warning};
use crate::report::Report;

/// One downloadable file.
#[derive(Debug, Clone)]
pub struct Artifact {
    /// File name (`report.json`, `mesh.glb`, …).
    pub name: String,
    /// Media type.
    pub media_type: &'static str,
    /// Contents.
    pub bytes: Vec<u8>,
}

/// A job that changes the mesh but does not flatten it still gets the patterns of its output
/// mesh, from `flatten` with its defaults (so `GET /v1/jobs/{id}/patterns` and `patterns.svg`
/// exist for every mesh-changing job). When the output cannot be flattened the job still
/// succeeds and `report.json` says why under `job.patterns_unavailable`. Only cancellation
/// propagates.
pub fn derive_patterns(outcome: &mut JobOutcome, control: &dyn Control) -> Result<(), AlgoError> {
    let Some(mesh) = outcome.mesh.as_ref() else {
        return Ok(());
    };
    if outcome.patterns.is_some() {
        return Ok(());
    }
    match flatten::run(mesh, &flatten::Params::default(), control) {
        Ok(flat) => {
            // The same mesh, with the pattern's texture coordinates.
            if let Some(m) = flat.mesh {
                outcome.mesh = Some(m);
            }
            outcome.patterns = flat.patterns;
            outcome.pattern_warnings = flat.summary.job_warnings;
            Ok(())
        }
        Err(AlgoError::Cancelled) => Err(AlgoError::Cancelled),
        Err(e) => {
            outcome.patterns_unavailable = Some(e.to_string());
            Ok(())
        }
    }
}

/// How a mesh-changing job's output compares with its input in what no measure of
/// flattenability sees: folds (edges whose faces turn by more than 120°,
/// [`crate::geometry::FOLD_ANGLE`]), creases (more than 60°) and the smallest corner angle
/// (degrees).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ShapeCheck {
    /// Folds of the input.
    pub folds_before: usize,
    /// Folds of the output.
    pub folds_after: usize,
    /// Total length of the input's folded edges (mesh units).
    pub fold_length_before: f64,
    /// Total length of the output's folded edges: unlike the count, it does not grow when
    /// refinement or subdivision splits a fold that was already there.
    pub fold_length_after: f64,
    /// Smallest corner angle of the input, degrees.
    pub min_angle_before: f64,
    /// Smallest corner angle of the output, degrees.
    pub min_angle_after: f64,
    /// Edges of the input whose faces turn by more than 60° ([`crate::geometry::CREASE_ANGLE`]).
    pub creases_before: usize,
    /// Such edges of the output.
    pub creases_after: usize,
    /// What a user should know: new folds, new creases on more than 1 % of the edges
    /// ([`crate::geometry::CRUMPLED_SHARE`]), or new slivers below 1° (empty otherwise).
    pub warnings: Vec<String>,
}

/// Corners below this (degrees) that the input did not have are warned about.
pub use crate::geometry::SLIVER_DEGREES;

/// The [`ShapeCheck`] of a job whose output mesh is not its input's geometry (None for the
/// others). A flattenable output can still be crumpled: measured on unseen whole garments
/// (several openings, one patch), fl-mesh converged with 41–308 new folds where sleeves and
/// body meet, and said nothing. The advice it gives was measured on 14 such garments
/// (issue 12 note of 2026-11-27): `segment` with then=fl-mesh made every one flattenable per
/// panel at 1.1–3.5 % of the diagonal, against 6–10 % for whole-garment fl-mesh.
pub fn check_shape(input: &Mesh, outcome: &JobOutcome) -> Option<ShapeCheck> {
    let out = outcome.mesh.as_ref()?;
    if out.positions() == input.positions() {
        return None;
    }
    let smallest = |m: &Mesh| crate::geometry::smallest_corner(m).to_degrees();
    let folds = |m: &Mesh| {
        let edges = crate::geometry::fold_edges(m);
        let lengths = crate::geometry::edge_lengths(m, m.positions());
        // fold, not sum: an empty f64 sum is −0.0, which the report would print.
        let length = edges.iter().fold(0.0, |s, &e| s + lengths[e as usize]);
        (edges.len(), length)
    };
    let (folds_before, fold_length_before) = folds(input);
    let (folds_after, fold_length_after) = folds(out);
    let (min_angle_before, min_angle_after) = (smallest(input), smallest(out));
    let creases_before = crate::geometry::crease_count(input);
    let creases_after = crate::geometry::crease_count(out);
    let edges = out.conn().edges().len();
    let mut warnings = Vec::new();
    // New folds, by count and by length (a fold kept where it was, split by refinement,
    // counts more edges but no more length; 10 % allows for its vertices moving a little).
    let folded = folds_after > folds_before && fold_length_after > 1.1 * fold_length_before;
    // Without new folds an output can still be creased all over: fl-mesh's converged
    // diffavatar_tshirt turns 868 of its 8368 edges past 60° (the input 12) and looks like
    // crushed foil (rendered, issue 12 note of 2026-11-27, session 26).
    let creased = creases_after.saturating_sub(creases_before) as f64
        > crate::geometry::CRUMPLED_SHARE * edges as f64;
    if creased && !folded {
        warnings.push(format!(
            "the output is creased all over: {creases_after} of its {edges} edges turn by \
             more than 60° (the input's {creases_before}); look at mesh.glb before using it. \
             A patch that cannot become flattenable smoothly with its boundary kept (e.g. a \
             whole garment whose sleeves or legs join its body) creases instead: cut it into \
             panels first (the segment job with then=fl-mesh makes each panel flattenable; \
             or give the panels as patches in the file, or as islands of its texture layout, \
             which fl-mesh takes by default and develop with patches=auto)"
        ));
    }
    if folded {
        warnings.push(format!(
            "the output is crumpled: {folds_after} edges fold (their faces turn by more than \
             120°), the input's {folds_before}; look at mesh.glb before using it. A patch that \
             cannot become flattenable smoothly with its boundary kept (e.g. a whole garment \
             whose sleeves or legs join its body) folds there: cut it into panels first \
             (the segment job with then=fl-mesh makes each panel flattenable; or give the \
             panels as patches in the file, or as islands of its texture layout, which \
             fl-mesh takes by default and develop with patches=auto)"
        ));
    }
    if min_angle_after < SLIVER_DEGREES.min(min_angle_before) {
        warnings.push(format!(
            "the output has sliver triangles: its smallest corner is {min_angle_after:.2}° \
             (the input's {min_angle_before:.2}°)"
        ));
    }
    Some(ShapeCheck {
        folds_before,
        folds_after,
        fold_length_before,
        fold_length_after,
        min_angle_before,
        min_angle_after,
        creases_before,
        creases_after,
        warnings,
    })
}

/// `report.json`: the report of the output mesh (the input when the job does not change it),
/// and under `"job"` the job's own figures with its `kind` and `seconds`, so that no figure of
/// the job shadows one of the mesh report.
pub fn job_report(
    report: &Report,
    kind: Kind,
    outcome: &JobOutcome,
    seconds: f64,
) -> serde_json::Value {
    let mut job = match serde_json::to_value(&outcome.figures) {
        Ok(serde_json::Value::Object(o)) => o,
        _ => serde_json::Map::new(),
    };
    job.insert("kind".into(), kind.name().into());
    job.insert("seconds".into(), seconds.into());
    if !outcome.pattern_warnings.is_empty() {
        job.insert(
            "pattern_warnings".into(),
            outcome.pattern_warnings.clone().into(),
        );
    }
    if let Some(why) = &outcome.patterns_unavailable {
        job.insert("patterns_unavailable".into(), why.clone().into());
    }
    if let Some(shape) = &outcome.shape {
        job.insert(
            "shape".into(),
            serde_json::to_value(shape).unwrap_or_default(),
        );
    }
    let mut value = serde_json::to_value(report).unwrap_or_default();
    if let Some(obj) = value.as_object_mut() {
        obj.insert("job".into(), serde_json::Value::Object(job));
    }
    value
}

/// The files of a finished job, and ϖ_max measured on its output mesh.
pub struct Rendered {
    /// The files, in a fixed order.
    pub artifacts: Vec<Artifact>,
    /// ϖ_max of the output mesh (the input when the job does not change it).
    pub max_flattenability: f64,
}

/// All files of a finished job.
pub fn render(
    kind: Kind,
    input: &Mesh,
    outcome: &JobOutcome,
    warnings: &[Warning],
    seconds: f64,
) -> Rendered {
    let mesh = outcome.mesh.as_ref().unwrap_or(input);
    let report = Report::compute(mesh, warnings);
    let varpi: Vec<f64> = report.per_vertex.iter().map(|v| v.flattenability).collect();
    let max_flattenability = varpi
        .iter()
        .copied()
        .filter(|w| w.is_finite())
        .fold(0.0f64, f64::max);
    let value = job_report(&report, kind, outcome, seconds);
    let mut out = vec![Artifact {
        name: "report.json".into(),
        media_type: "application/json",
        bytes: serde_json::to_vec_pretty(&value).unwrap_or_default(),
    }];
    // `perturb`, `develop`: how far each vertex moved, beside ϖ.
    let moved = match &outcome.figures {
        super::Figures::Perturb(s) => Some(&s.displacement),
        super::Figures::Develop(s) => Some(&s.displacement),
        _ => None,
    };
    let displacement = moved.map(|values| io::gltf::VertexScalar {
        attribute: "_DISPLACEMENT",
        quantity: "distance each vertex moved from the input (develop loop: from the \
                   subdivided mesh), mesh units",
        values,
    });
    push_mesh(&mut out, "mesh", mesh, &varpi, displacement.as_slice());
    if let Some(p) = &outcome.patterns {
        out.push(Artifact {
            name: "patterns.json".into(),
            media_type: "application/json",
            bytes: io::pattern::to_json(p).into_bytes(),
        });
        out.push(Artifact {
            name: "patterns.svg".into(),
            media_type: "image/svg+xml",
            bytes: io::pattern::to_svg(p).into_bytes(),
        });
        out.push(Artifact {
            name: "patterns.dxf".into(),
            media_type: "image/vnd.dxf",
            bytes: io::pattern::to_dxf(p).into_bytes(),
        });
        out.push(Artifact {
            name: "patterns-plain.dxf".into(),
            media_type: "image/vnd.dxf",
            bytes: io::pattern::to_dxf_plain(p).into_bytes(),
        });
    }
    // `subdivide`: every level's mesh as `level_<k>.*` (k from 1).
    for (k, level) in outcome.levels.iter().enumerate() {
        let theta = crate::geometry::angle_sums(level);
        let varpi = crate::geometry::flattenability(level, &theta);
        push_mesh(&mut out, &format!("level_{}", k + 1), level, &varpi, &[]);
    }
    Rendered {
        artifacts: out,
        max_flattenability,
    }
}

/// `stem.glb`, `stem.gltf` (both with ϖ per vertex) and `stem.obj`.
fn push_mesh(
    out: &mut Vec<Artifact>,
    stem: &str,
    mesh: &Mesh,
    varpi: &[f64],
    scalars: &[io::gltf::VertexScalar<'_>],
) {
    out.push(Artifact {
        name: format!("{stem}.glb"),
        media_type: "model/gltf-binary",
        bytes: io::gltf::write_glb_with(mesh, Some(varpi), scalars),
    });
    out.push(Artifact {
        name: format!("{stem}.gltf"),
        media_type: "model/gltf+json",
        bytes: io::gltf::write_gltf_with(mesh, Some(varpi), scalars),
    });
    out.push(Artifact {
        name: format!("{stem}.obj"),
        media_type: "model/obj",
        bytes: io::obj::write(&mesh.to_raw()).into_bytes(),
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::RawMesh;

    /// A 3×3-vertex square sheet (8 triangles) with its centre at `centre`.
    fn sheet(centre: [f64; 3]) -> Mesh {
        let mut positions = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                positions.push([i as f64, j as f64, 0.0]);
            }
        }
        positions[4] = centre;
        let id = |i: u32, j: u32| j * 3 + i;
        let mut triangles = Vec::new();
        for j in 0..2 {
            for i in 0..2 {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        Mesh::new(RawMesh {
            positions,
            triangles,
            ..RawMesh::default()
        })
        .unwrap()
        .0
    }

    fn outcome(mesh: Mesh) -> JobOutcome {
        JobOutcome {
            mesh: Some(mesh),
            patterns: None,
            levels: Vec::new(),
            figures: super::super::Figures::Report(Default::default()),
            pattern_warnings: Vec::new(),
            patterns_unavailable: None,
            shape: None,
        }
    }

    /// Pulling the centre of a flat sheet past the sheet's corner (and a little below) makes the
    /// faces around it turn over against the others: folds, counted and warned about; the
    /// same geometry is not checked, a smooth bump warns of nothing, and a centre moved next to
    /// the boundary leaves a sliver.
    #[test]
    fn new_folds_and_slivers_are_warned_about() {
        let flat = sheet([1.0, 1.0, 0.0]);
        assert_eq!(check_shape(&flat, &outcome(flat.clone())), None);
        let bump = check_shape(&flat, &outcome(sheet([1.0, 1.0, 0.3]))).unwrap();
        assert_eq!((bump.folds_before, bump.folds_after), (0, 0));
        assert!(bump.warnings.is_empty(), "{:?}", bump.warnings);
        let crumpled = sheet([2.6, 2.4, -0.05]);
        let check = check_shape(&flat, &outcome(crumpled.clone())).unwrap();
        let folds = crate::geometry::fold_edges(&crumpled).len();
        assert!(folds > 0);
        assert_eq!((check.folds_before, check.folds_after), (0, folds));
        assert!(check.warnings[0].contains(&format!("{folds} edges fold")));
        // The centre next to a boundary vertex: a corner of a few tenths of a degree.
        let sliver = sheet([1.0, 0.004, 0.0]);
        let check = check_shape(&flat, &outcome(sliver)).unwrap();
        assert_eq!(check.folds_after, 0);
        assert!(check.min_angle_after < SLIVER_DEGREES && check.min_angle_before == 45.0);
        assert_eq!(check.warnings.len(), 1, "{:?}", check.warnings);
        assert!(check.warnings[0].contains("sliver"));
    }

    /// A spike two units high turns 4 of the sheet's 16 edges by 70–79° and none past 120°:
    /// creased all over without a fold, which is warned about; the 0.3 bump (turns below 25°)
    /// is not.
    #[test]
    fn new_creases_on_many_edges_are_warned_about() {
        let flat = sheet([1.0, 1.0, 0.0]);
        let spike = sheet([1.0, 1.0, 2.0]);
        assert_eq!(crate::geometry::fold_edges(&spike).len(), 0);
        let check = check_shape(&flat, &outcome(spike)).unwrap();
        assert_eq!((check.creases_before, check.creases_after), (0, 4));
        assert_eq!(check.warnings.len(), 1, "{:?}", check.warnings);
        assert!(
            check.warnings[0].contains("creased all over: 4 of its 16 edges"),
            "{:?}",
            check.warnings
        );
        let bump = check_shape(&flat, &outcome(sheet([1.0, 1.0, 0.3]))).unwrap();
        assert_eq!(bump.creases_after, 0);
        assert!(bump.warnings.is_empty(), "{:?}", bump.warnings);
    }
}
