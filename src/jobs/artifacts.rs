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
