//! A job request's kind and parameters (the JSON a client submits) through the typed jobs
//! domain: parsed or refused with an error naming the member, never a panic; a parsed spec
//! serialises and bounds its output.
#![no_main]

use flatmesh::jobs::JobSpec;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(serde_json::Value::Object(o)) = serde_json::from_slice::<serde_json::Value>(data) else {
        return;
    };
    let kind = o.get("kind").and_then(|k| k.as_str()).unwrap_or("report");
    let params = match o.get("params") {
        Some(serde_json::Value::Object(p)) => p.clone(),
        _ => serde_json::Map::new(),
    };
    if let Ok(spec) = JobSpec::parse(kind, &params) {
        let _ = spec.params();
        let _ = spec.output_faces(1_000_000);
        let _ = spec.check_reference(true);
    }
});
