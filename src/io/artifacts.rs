//! Turn a job's outcome into the files a user downloads: `report.json`, `mesh.glb`,
//! `mesh.obj`, for flattening `patterns.json`, `patterns.svg`, `patterns.dxf`, and for
//! `subdivide` every level's `level_<k>.glb` and `level_<k>.obj`. The CLI writes them into a directory; the service stores them. Both go through
//! here so the two never disagree.

use crate::algorithms::Outcome;
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

/// `report.json`: the report of the output mesh (the input when the job does not change it),
/// with the outcome's own figures and `seconds` merged in at the top level.
pub fn job_report(report: &Report, outcome: &Outcome, seconds: f64) -> serde_json::Value {
    let mut value = serde_json::to_value(report).unwrap_or_default();
    if let Some(obj) = value.as_object_mut() {
        for (k, v) in &outcome.summary {
            obj.insert(k.clone(), v.clone());
        }
        obj.insert("seconds".into(), serde_json::json!(seconds));
    }
    value
}

/// All artifacts of a finished job.
pub fn render(
    input: &Mesh,
    outcome: &Outcome,
    warnings: &[Warning],
    seconds: f64,
) -> Vec<Artifact> {
    let mesh = outcome.mesh.as_ref().unwrap_or(input);
    let report = Report::compute(mesh, warnings);
    let varpi: Vec<f64> = report.per_vertex.iter().map(|v| v.flattenability).collect();
    let value = job_report(&report, outcome, seconds);
    let mut out = vec![
        Artifact {
            name: "report.json".into(),
            media_type: "application/json",
            bytes: serde_json::to_vec_pretty(&value).unwrap_or_default(),
        },
        Artifact {
            name: "mesh.glb".into(),
            media_type: "model/gltf-binary",
            bytes: super::gltf::write_glb(mesh, Some(&varpi)),
        },
        Artifact {
            name: "mesh.obj".into(),
            media_type: "model/obj",
            bytes: super::obj::write(&mesh.to_raw()).into_bytes(),
        },
    ];
    if let Some(p) = &outcome.patterns {
        out.push(Artifact {
            name: "patterns.json".into(),
            media_type: "application/json",
            bytes: super::pattern::to_json(p).into_bytes(),
        });
        out.push(Artifact {
            name: "patterns.svg".into(),
            media_type: "image/svg+xml",
            bytes: super::pattern::to_svg(p).into_bytes(),
        });
        out.push(Artifact {
            name: "patterns.dxf".into(),
            media_type: "image/vnd.dxf",
            bytes: super::pattern::to_dxf(p).into_bytes(),
        });
    }
    // `subdivide`: every level's mesh as `level_<k>.glb` / `level_<k>.obj` (k from 1).
    for (k, level) in outcome.levels.iter().enumerate() {
        let theta = crate::geometry::angle_sums(level);
        let varpi = crate::geometry::flattenability(level, &theta);
        out.push(Artifact {
            name: format!("level_{}.glb", k + 1),
            media_type: "model/gltf-binary",
            bytes: super::gltf::write_glb(level, Some(&varpi)),
        });
        out.push(Artifact {
            name: format!("level_{}.obj", k + 1),
            media_type: "model/obj",
            bytes: super::obj::write(&level.to_raw()).into_bytes(),
        });
    }
    out
}
