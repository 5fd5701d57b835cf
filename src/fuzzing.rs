//! What each fuzz target (`fuzz/fuzz_targets/`) checks on one input, here so that the same
//! checks replay the committed corpora in `cargo test` (tests/engine/fuzz_corpus.rs) without a
//! libFuzzer build. Each returns normally or panics; a panic is the finding.

use crate::io::{self, Format, Limits};

/// A reader on arbitrary bytes within a small triangle limit: a mesh or an error, and a mesh
/// it returns is measured and written back.
fn read_measure_write(data: &[u8], format: Format) {
    let limits = Limits {
        max_triangles: 100_000,
    };
    if let Ok((mesh, _)) = io::load_limited(data, format, &limits) {
        let _ = crate::report::Report::compute(&mesh, &[]);
        let _ = io::gltf::write_glb(&mesh, None);
    }
}

/// The OBJ reader (target `obj`).
pub fn obj(data: &[u8]) {
    read_measure_write(data, Format::Obj);
}

/// The OFF reader (target `off`).
pub fn off(data: &[u8]) {
    read_measure_write(data, Format::Off);
}

/// The glTF reader (target `gltf`). gltf-json panics on some malformed documents; the reader
/// catches that (`io::quietly`): a fuzzer installs [`io::install_quiet_panic_hook`] first.
pub fn gltf(data: &[u8]) {
    read_measure_write(data, Format::Gltf);
}

/// The GLB reader (target `glb`), as [`gltf`].
pub fn glb(data: &[u8]) {
    read_measure_write(data, Format::Glb);
}

/// A job request's kind and parameters (the JSON a client submits) through the typed jobs
/// domain: parsed or refused with an error naming the member; a parsed spec serialises and
/// bounds its output (target `job_request`).
pub fn job_request(data: &[u8]) {
    let Ok(serde_json::Value::Object(o)) = serde_json::from_slice::<serde_json::Value>(data) else {
        return;
    };
    let kind = o.get("kind").and_then(|k| k.as_str()).unwrap_or("report");
    let params = match o.get("params") {
        Some(serde_json::Value::Object(p)) => p.clone(),
        _ => serde_json::Map::new(),
    };
    if let Ok(spec) = crate::jobs::JobSpec::parse(kind, &params) {
        let _ = spec.params();
        let _ = spec.output_faces(1_000_000);
        let _ = spec.check_reference(true);
    }
}

/// The pattern exporters on what a user can make them draw: an arbitrary small OBJ mesh,
/// flattened with few iterations, written as JSON, SVG and DXF, and the DXF read back
/// (target `patterns`).
pub fn patterns(data: &[u8]) {
    use crate::algorithms::{flatten, Silent};
    let limits = Limits {
        max_triangles: 2_000,
    };
    let Ok((mesh, _)) = io::load_limited(data, Format::Obj, &limits) else {
        return;
    };
    let params = flatten::Params {
        max_iterations: 20,
        ..flatten::Params::default()
    };
    let Ok(out) = flatten::run(&mesh, &params, &Silent::default()) else {
        return;
    };
    if let Some(p) = &out.patterns {
        let _ = io::pattern::to_json(p);
        let _ = io::pattern::to_svg(p);
        let dxf = io::pattern::to_dxf(p);
        io::pattern::read_dxf_polylines(&dxf).expect("our own DXF reads back");
        let plain = io::pattern::to_dxf_plain(p);
        io::pattern::read_dxf_polylines(&plain).expect("our own plain DXF reads back");
    }
}
