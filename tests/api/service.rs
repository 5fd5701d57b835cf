//! Black-box tests of `flatmesh serve`: the real binary on a random loopback port, spoken to
//! with reqwest. Every JSON body seen is validated against the schemas of openapi.yaml.

use crate::common;

use base64::Engine;
use common::*;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn routes_and_openapi_agree() {
    let doc = openapi();
    let mut spec = std::collections::BTreeSet::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for m in ["get", "post", "put", "patch", "delete"] {
            if item.get(m).is_some() {
                spec.insert((m.to_string(), path.clone()));
            }
        }
    }
    let routes: std::collections::BTreeSet<_> = flatmesh::service::routes()
        .iter()
        .map(|(m, p)| (m.to_string(), p.to_string()))
        .collect();
    assert_eq!(spec, routes, "openapi.yaml paths vs the router's routes");
    let kinds: Vec<&str> = doc["components"]["schemas"]["Kind"]["enum"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(
        kinds,
        flatmesh::jobs::Kind::names(),
        "job kinds in openapi.yaml"
    );
    // The served document is the file.
}

/// Every kind of the registry has its parameter schema in openapi.yaml (through `KindParams`),
/// and the defaults it documents are the code's: the kind's parameters parsed from `{}`,
/// serialised, have exactly the schema's properties, each with the documented default.
/// The schema check that every other test relies on accepts a valid body and rejects what
/// openapi.yaml forbids, so a body that drifts from the spec cannot pass unseen.
#[test]
fn the_openapi_check_rejects_bodies_the_schema_forbids() {
    let problem =
        json!({"type": "http://x/problems/bad", "title": "Bad", "status": 400, "detail": "d"});
    common::check("Problem", &problem);
    let mut without_status = problem.clone();
    without_status.as_object_mut().unwrap().remove("status");
    let bad = [
        without_status,
        json!({"type": "t", "title": "Bad", "status": "400", "detail": "d"}),
        json!({"type": "t", "title": "Bad", "status": 200, "detail": "d"}),
        json!(["not", "an", "object"]),
    ];
    for b in bad {
        let caught = std::panic::catch_unwind(|| common::check("Problem", &b));
        assert!(caught.is_err(), "accepted {b}");
    }
}

#[test]
fn openapi_parameter_defaults_are_the_code_defaults() {
    use flatmesh::jobs::{JobSpec, Kind};
    let doc = openapi();
    let schemas = &doc["components"]["schemas"];
    // JobRequest and MultipartJobRequest: one schema per kind, chosen by `kind`.
    for union in ["JobRequest", "MultipartJobRequest"] {
        let mapping = schemas[union]["discriminator"]["mapping"]
            .as_object()
            .unwrap();
        assert_eq!(
            mapping.len(),
            Kind::ALL.len(),
            "{union}: one schema per kind"
        );
        assert_eq!(
            schemas[union]["oneOf"].as_array().unwrap().len(),
            Kind::ALL.len()
        );
        for (kind, target) in mapping {
            let name = target
                .as_str()
                .unwrap()
                .trim_start_matches("#/components/schemas/");
            assert_eq!(
                schemas[name]["properties"]["kind"]["enum"],
                json!([kind]),
                "{name}"
            );
            // Every example is valid against its own schema.
            check(name, &schemas[name]["example"]);
        }
    }
    let mapping = schemas["JobRequest"]["discriminator"]["mapping"].clone();
    for kind in Kind::ALL {
        let request = mapping[kind.name()]
            .as_str()
            .unwrap_or_else(|| panic!("JobRequest has no schema for `{}`", kind.name()))
            .trim_start_matches("#/components/schemas/");
        let name = schemas[request]["properties"]["params"]["$ref"]
            .as_str()
            .unwrap()
            .trim_start_matches("#/components/schemas/");
        let code = JobSpec::parse(kind.name(), &serde_json::Map::new())
            .unwrap()
            .params();
        let props = schemas[name]["properties"]
            .as_object()
            .cloned()
            .unwrap_or_default();
        let code = code.as_object().unwrap();
        let mut a: Vec<&String> = props.keys().collect();
        let mut b: Vec<&String> = code.keys().collect();
        a.sort();
        b.sort();
        assert_eq!(a, b, "{name}: properties vs the Params struct");
        for (k, v) in code {
            let Some(d) = props[k].get("default") else {
                // Nested objects and lists document their own defaults.
                assert!(v.is_object() || v.is_array(), "{name}.{k} has no default");
                continue;
            };
            match (d.as_f64(), v.as_f64()) {
                (Some(x), Some(y)) => assert_eq!(x, y, "{name}.{k}"),
                _ => assert_eq!(d, v, "{name}.{k}"),
            }
        }
        check(name, &Value::Object(code.clone()));
    }
}

/// The CLI's `run --help` shows every kind of the registry with its help, and each kind's
/// help names exactly the parameters its `Params` struct has.
#[test]
fn cli_help_documents_every_kind_and_parameter() {
    use flatmesh::jobs::{JobSpec, Kind};
    let help = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["run", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    for kind in Kind::ALL {
        let k = kind.name();
        assert!(help.contains(&format!("{k}: {}", kind.about())), "{k}");
        assert!(help.contains(kind.params_help()), "{k}: parameters");
        // Top-level items of "a=x|y (d), b (d, note), …": the name before `=`, ` ` or `(`.
        let mut documented = Vec::new();
        let (mut depth, mut item) = (0, String::new());
        for ch in kind.params_help().chars().chain([',']) {
            match ch {
                '(' | '{' => depth += 1,
                ')' | '}' => depth -= 1,
                ',' if depth == 0 => {
                    let name: String = item
                        .trim()
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if !name.is_empty() && name != "none" {
                        documented.push(name);
                    }
                    item.clear();
                    continue;
                }
                _ => {}
            }
            item.push(ch);
        }
        let params = JobSpec::parse(k, &serde_json::Map::new()).unwrap().params();
        let mut actual: Vec<String> = params.as_object().unwrap().keys().cloned().collect();
        documented.sort();
        actual.sort();
        assert_eq!(
            documented, actual,
            "{k}: parameters in its help vs its Params"
        );
    }
}

/// Standard Webhooks' published example (svix): the signature must match bit for bit.
#[test]
fn webhook_signature_matches_standard_example() {
    let key = flatmesh::service::webhook::decode_secret("whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw")
        .unwrap();
    let sig = flatmesh::service::webhook::sign(
        &key,
        "msg_p5jXN8AQM9LWM0D4loKWxJek",
        1614265330,
        br#"{"test": 2432232314}"#,
    );
    assert_eq!(sig, "v1,g0hM9SsE+OTPJTGt/tmIKtSyZlE3uFJELVlNIOLJ1OE=");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_is_served() {
    let s = Server::start(&tmp("routes"), &[]);
    let c = client();
    for (m, p) in flatmesh::service::routes() {
        let path = p.replace("{id}", "x");
        let r = c
            .request(m.to_uppercase().parse().unwrap(), s.url(&path))
            .send()
            .await
            .unwrap();
        let status = r.status().as_u16();
        assert_ne!(status, 405, "{m} {p}");
        if status == 404 {
            let v = problem(r, 404).await;
            assert!(
                !v["detail"].as_str().unwrap().starts_with("no route"),
                "{m} {p} is not routed"
            );
        }
    }
    // And an unknown route or method is a problem too.
    let v = problem(c.get(s.url("/v2/nothing")).send().await.unwrap(), 404).await;
    assert!(v["detail"].as_str().unwrap().starts_with("no route"));
    let r = c.put(s.url("/v1/jobs")).send().await.unwrap();
    assert_eq!(r.status(), 405);
    assert_eq!(
        r.headers()["content-type"].to_str().unwrap(),
        "application/problem+json"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn operational_endpoints() {
    let s = Server::start(&tmp("ops"), &[]);
    let c = client();
    let r = c.get(s.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.headers().contains_key("x-request-id"));
    json_of(r, "Health").await;
    let r = c.get(s.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    json_of(r, "Ready").await;
    let v = json_of(c.get(s.url("/version")).send().await.unwrap(), "Version").await;
    assert_eq!(v["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(v["kinds"], json!(flatmesh::jobs::Kind::names()));
    let text = c
        .get(s.url("/openapi.yaml"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(text, std::fs::read_to_string("openapi.yaml").unwrap());
    upload(&c, &s, fixture("cylinder")).await;
    let m = metrics_text(&c, &s).await;
    assert!(m.contains("flatmesh_meshes_uploaded_total 1\n"), "{m}");
    assert!(m.contains("# TYPE flatmesh_jobs_queued gauge"));
    // The log goes to a file here: plain text, no terminal colour codes.
    let log = std::fs::read_to_string(s.dir.join("server.log")).unwrap();
    assert!(log.contains("INFO"), "{log}");
    assert!(
        !log.contains('\u{1b}'),
        "ANSI codes in the log file:\n{log}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn meshes_upload_report_delete() {
    let s = Server::start(&tmp("meshes"), &["--max-upload", "64KiB"]);
    let c = client();
    let bytes = fixture("hemisphere_cap");
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body(bytes.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    let m = json_of(r, "Mesh").await;
    // Independent truth: the library on the same bytes.
    let (mesh, w) = flatmesh::io::load(&bytes, flatmesh::io::Format::Obj).unwrap();
    let rep = flatmesh::report::Report::compute(&mesh, &w);
    assert_eq!(m["vertices"], rep.vertices);
    assert_eq!(m["faces"], rep.faces);
    assert_eq!(
        m["max_flattenability"].as_f64().unwrap(),
        rep.max_flattenability
    );
    assert!(rep.max_flattenability > 1e-3, "a cap is not developable");
    assert_eq!(m["developable"], false);
    let id = m["id"].as_str().unwrap();
    // Absolute, from the Host the client used.
    assert_eq!(loc, s.url(&format!("/v1/meshes/{id}")));
    assert_eq!(m["links"]["self"], loc.as_str());
    let r = c.get(&loc).send().await.unwrap();
    assert_eq!(r.headers()["etag"].to_str().unwrap(), etag);
    assert_eq!(json_of(r, "Mesh").await, m);
    let report = json_of(
        c.get(format!("{loc}/report")).send().await.unwrap(),
        "Report",
    )
    .await;
    let pv = report["per_vertex"].as_array().unwrap();
    assert_eq!(pv.len(), rep.per_vertex.len());
    for (a, b) in pv.iter().zip(&rep.per_vertex) {
        assert_eq!(a["flattenability"].as_f64().unwrap(), b.flattenability);
    }
    // Gauss–Bonnet-free sanity: ϖ = |2π − θ| at interior vertices.
    for v in pv {
        if v["interior"].as_bool().unwrap() {
            let t = v["angle_sum"].as_f64().unwrap();
            let w = v["flattenability"].as_f64().unwrap();
            assert!((w - (2.0 * std::f64::consts::PI - t).abs()).abs() < 1e-12);
        }
    }

    // glTF binary and JSON, and multipart, are accepted; the counts agree with the OBJ.
    let glb = flatmesh::io::gltf::write_glb(&mesh, None);
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/gltf-binary")
        .body(glb)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let g = json_of(r, "Mesh").await;
    assert_eq!(
        (g["format"].as_str(), &g["faces"]),
        (Some("glb"), &m["faces"])
    );
    let gltf = flatmesh::io::gltf::write_gltf(&mesh, None);
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/gltf+json")
        .body(gltf)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(json_of(r, "Mesh").await["vertices"], m["vertices"]);
    let form = reqwest::multipart::Form::new().part("mesh", obj_part("cone", "cone.obj"));
    let r = c
        .post(s.url("/v1/meshes"))
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(json_of(r, "Mesh").await["developable"], true);

    // Errors.
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "text/html")
        .body("<html>")
        .send()
        .await
        .unwrap();
    problem(r, 415).await;
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
        .send()
        .await
        .unwrap();
    let p = problem(r, 422).await;
    assert_eq!(p["field"], "body");
    assert!(p["detail"].as_str().unwrap().contains("line 3"), "{p}");
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body(vec![b'#'; 100 * 1024])
        .send()
        .await
        .unwrap();
    problem(r, 413).await;
    problem(c.get(s.url("/v1/meshes/m_nope")).send().await.unwrap(), 404).await;
    // The same bytes again: the same mesh, 200 instead of 201, nothing stored twice.
    let files = files_under(&s.dir);
    let again = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body(bytes.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), 200);
    assert_eq!(again.headers()["location"], loc.as_str());
    assert_eq!(json_of(again, "Mesh").await["id"], id);
    assert_eq!(files_under(&s.dir), files, "a re-upload stored something");
    // Listing: newest first, in pages.
    let other = upload(&c, &s, fixture("cylinder")).await;
    let page = json_of(
        c.get(s.url("/v1/meshes?page_size=1")).send().await.unwrap(),
        "MeshList",
    )
    .await;
    assert_eq!(page["meshes"][0]["id"], other["id"], "{page}");
    let token = page["next_page_token"].as_str().unwrap();
    let page = json_of(
        c.get(s.url(&format!("/v1/meshes?page_size=100&page_token={token}")))
            .send()
            .await
            .unwrap(),
        "MeshList",
    )
    .await;
    let listed: Vec<&str> = page["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["id"].as_str().unwrap())
        .collect();
    assert!(listed.contains(&id), "{page}");
    let p = problem(
        c.get(s.url("/v1/meshes?page_token=xyz"))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "page_token");
    let r = c.delete(&loc).send().await.unwrap();
    assert_eq!(r.status(), 204);
    problem(c.get(&loc).send().await.unwrap(), 404).await;
    problem(c.delete(&loc).send().await.unwrap(), 404).await;
}

/// Every kind of the registry has its own end-to-end test below, named `{kind}_job_end_to_end`.
#[test]
fn every_kind_has_an_end_to_end_test() {
    let src = std::fs::read_to_string("tests/api/service.rs").unwrap();
    for k in flatmesh::jobs::Kind::ALL {
        let name = format!("async fn {}_job_end_to_end()", k.name().replace('-', "_"));
        assert!(src.contains(&name), "no `{name}` in tests/api/service.rs");
    }
}

/// A report job: its result is the library's report, its mesh the input in every format.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn report_job_end_to_end() {
    let s = Server::start(&tmp("k-report"), &[]);
    let c = client();
    let bytes = fixture("tube_two_panels");
    let (mesh, w) = flatmesh::io::load(&bytes, flatmesh::io::Format::Obj).unwrap();
    let m = upload(&c, &s, bytes.clone()).await;
    let mid = m["id"].as_str().unwrap();

    // report
    let r = c
        .post(s.url("/v1/jobs"))
        .json(&json!({"kind": "report", "mesh_id": mid}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    // a report on an idle server: look again in a second
    assert_eq!(r.headers()["retry-after"], "1");
    let j = json_of(r, "Job").await;
    assert_eq!(
        loc,
        s.url(&format!("/v1/jobs/{}", j["id"].as_str().unwrap()))
    );
    assert_eq!(j["links"]["self"], loc.as_str());
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert!(done["expires_at"].is_string() && done["finished_at"].is_string());
    let result = job_result(&c, &s, id).await;
    let rep = flatmesh::report::Report::compute(&mesh, &w);
    assert_eq!(
        result["max_flattenability"].as_f64().unwrap(),
        rep.max_flattenability
    );
    assert_eq!(
        result["per_vertex"].as_array().unwrap().len(),
        mesh.num_vertices()
    );
    // mesh in three formats: same geometry as the input (report does not change it)
    for (f, fmt, media) in [
        ("glb", flatmesh::io::Format::Glb, "model/gltf-binary"),
        ("gltf", flatmesh::io::Format::Gltf, "model/gltf+json"),
        ("obj", flatmesh::io::Format::Obj, "model/obj"),
    ] {
        let r = c
            .get(s.url(&format!("/v1/jobs/{id}/mesh?format={f}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.headers()["content-type"].to_str().unwrap(), media);
        let b = r.bytes().await.unwrap();
        let (back, _) = flatmesh::io::load(&b, fmt).unwrap();
        assert_eq!(back.triangles().len(), mesh.triangles().len(), "{f}");
        let mut worst = 0.0f64;
        // GLB/glTF store f32 positions.
        for (p, q) in back.positions().iter().zip(mesh.positions()) {
            for k in 0..3 {
                worst = worst.max((p[k] - q[k]).abs());
            }
        }
        assert!(worst < 1e-6, "{f}: positions moved by {worst}");
    }
    problem(
        c.get(s.url(&format!("/v1/jobs/{id}/mesh?format=stl")))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    // a report job has no patterns
    problem(
        c.get(s.url(&format!("/v1/jobs/{id}/patterns")))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
}

/// Flatten jobs on a developable fixture and a two-panel tube, checked against 3D lengths.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn flatten_job_end_to_end() {
    let s = Server::start(&tmp("k-flatten"), &[]);
    let c = client();
    let bytes = fixture("tube_two_panels");
    let m = upload(&c, &s, bytes.clone()).await;
    let mid = m["id"].as_str().unwrap();

    // flatten on a developable fixture: every pattern edge as long as its 3D edge
    let cyl = fixture("cylinder");
    let (cmesh, _) = flatmesh::io::load(&cyl, flatmesh::io::Format::Obj).unwrap();
    let cm = upload(&c, &s, cyl).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": cm["id"], "params": {"unit": "mm"}}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert!(done["links"]["patterns"].is_string());
    let r = c
        .get(s.url(&format!("/v1/jobs/{id}/patterns?format=json")))
        .send()
        .await
        .unwrap();
    let pat = json_of(r, "Patterns").await;
    let edges = pattern_edges(&pat, cmesh.positions());
    for &(l2, l3) in &edges {
        assert!((l2 - l3).abs() < 1e-6 * l3.max(1.0), "edge {l2} vs {l3}");
    }
    assert_eq!(edges.len(), 3 * cmesh.triangles().len());
    for (f, media, head) in [
        ("svg", "image/svg+xml", "<?xml"),
        ("dxf", "image/vnd.dxf", "0"),
    ] {
        let r = c
            .get(s.url(&format!("/v1/jobs/{id}/patterns?format={f}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.headers()["content-type"].to_str().unwrap(), media);
        assert!(r.text().await.unwrap().trim_start().starts_with(head));
    }
    // flatten with two panels: one piece per panel
    let j = submit(&c, &s, json!({"kind": "flatten", "mesh_id": mid})).await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let pat: Value = c
        .get(s.url(&format!("/v1/jobs/{}/patterns", j["id"].as_str().unwrap())))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    check("Patterns", &pat);
    assert_eq!(pat["pieces"].as_array().unwrap().len(), 2);
    assert_eq!(pat["seams"].as_array().unwrap().len(), 2);
}

/// An fl-mesh job on the noisy cone, its download checked with the library's own measure.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fl_mesh_job_end_to_end() {
    let s = Server::start(&tmp("k-flmesh"), &[]);
    let c = client();

    // fl-mesh on the noisy cone: the downloaded mesh is flattenable by the library's own
    // measure, boundary vertices are where they were, and its patterns are isometric.
    let cone = fixture("cone_noisy");
    let (kmesh, _) = flatmesh::io::load(&cone, flatmesh::io::Format::Obj).unwrap();
    let km = upload(&c, &s, cone).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "fl-mesh", "mesh_id": km["id"], "params": {"tolerance": 1e-7}}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert!(done["links"]["patterns"].is_string(), "{done}");
    let result = job_result(&c, &s, id).await;
    assert_eq!(result["job"]["converged"], true, "{result}");
    assert_eq!(result["job"]["kind"], "fl-mesh", "{result}");
    assert!(result["job"]["iterations"].as_u64().unwrap() >= 1);
    let b = download(&c, &s, &format!("/v1/jobs/{id}/mesh?format=obj")).await;
    let (out, _) = flatmesh::io::load(&b, flatmesh::io::Format::Obj).unwrap();
    let theta = flatmesh::geometry::angle_sums(&out);
    let varpi = flatmesh::geometry::flattenability(&out, &theta);
    let worst = varpi.iter().cloned().fold(0.0, f64::max);
    assert!(worst <= 1e-7, "downloaded fl-mesh output has ϖ_max {worst}");
    // The outcome is at the top level of the job, ϖ_max as measured on the download.
    assert_eq!(done["converged"], true, "{done}");
    assert!(done["stop_reason"].is_string(), "{done}");
    assert_eq!(done["warnings"], json!([]), "{done}");
    // The final progress is the job's end, not its last sub-step.
    assert_eq!(done["progress"]["stage"], "succeeded", "{done}");
    assert!(done["progress"]["ended_in"].is_string(), "{done}");
    assert_eq!(
        done["progress"]["max_flattenability"], done["max_flattenability"],
        "{done}"
    );
    let top = done["max_flattenability"].as_f64().unwrap();
    assert!(
        (top - worst).abs() <= 1e-15,
        "job says {top}, download has {worst}"
    );
    let conn = kmesh.conn();
    let mut moved = 0;
    for v in 0..kmesh.num_vertices() {
        if conn.is_interior(v as u32) {
            moved += usize::from(out.positions()[v] != kmesh.positions()[v]);
        } else {
            assert_eq!(
                out.positions()[v],
                kmesh.positions()[v],
                "boundary vertex {v} moved"
            );
        }
    }
    assert!(
        moved > 0,
        "the noisy cone is not flattenable, so interior vertices must move"
    );
    let pat = json_of(
        c.get(s.url(&format!("/v1/jobs/{id}/patterns")))
            .send()
            .await
            .unwrap(),
        "Patterns",
    )
    .await;
    let worst_rel = pattern_edges(&pat, out.positions())
        .iter()
        .map(|(d2, d3)| (d2 - d3).abs() / d3)
        .fold(0.0f64, f64::max);
    assert!(
        worst_rel < 1e-4,
        "pattern of the fl-mesh output: edge error {worst_rel}"
    );

    // Stopped before converging: the job still succeeds with its best iterate, and says so at
    // its top level.
    let j = submit(
        &c,
        &s,
        json!({"kind": "fl-mesh", "mesh_id": km["id"], "params": {"tolerance": 1e-12, "max_iterations": 1, "refine": false}}),
    )
    .await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["converged"], false, "{done}");
    assert_eq!(done["stop_reason"], "max_iterations", "{done}");
    let warnings = done["warnings"].as_array().unwrap();
    assert_eq!(warnings[0]["code"], "not_converged", "{done}");
    assert!(
        warnings[0]["message"]
            .as_str()
            .unwrap()
            .contains("max_iterations"),
        "{done}"
    );
    assert!(
        done["max_flattenability"].as_f64().unwrap() > 1e-12,
        "{done}"
    );
}

/// A perturb job against a reference body sent in the same multipart request: the result
/// validates, the downloaded mesh is no less flattenable than the input by the library's own
/// measure, no vertex that started outside the body ends inside (recomputed here).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn perturb_job_end_to_end() {
    let s = Server::start(&tmp("k-perturb"), &[]);
    let c = client();
    let garment = fixture("cylinder_noisy");
    let (gmesh, _) = flatmesh::io::load(&garment, flatmesh::io::Format::Obj).unwrap();
    let body_bytes = shrunk_cylinder_obj();
    let form = reqwest::multipart::Form::new()
        .part(
            "job",
            reqwest::multipart::Part::text(
                json!({"kind": "perturb", "params": {"clearance": 0.0}}).to_string(),
            )
            .mime_str("application/json")
            .unwrap(),
        )
        .part("mesh", obj_part("cylinder_noisy", "garment.obj"))
        .part(
            "reference",
            reqwest::multipart::Part::bytes(body_bytes.clone())
                .file_name("body.obj")
                .mime_str("model/obj")
                .unwrap(),
        );
    let r = post_jobs_form(&c, &s, form).await;
    assert_eq!(r.status(), 202);
    let j = json_of(r, "Job").await;
    assert!(j["reference_mesh_id"].is_string(), "{j}");
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = job_result(&c, &s, id).await;
    let fig = &result["job"];
    assert_eq!(fig["kind"], "perturb");
    assert!(fig["body"]["clearance_after"].is_array(), "{fig}");
    let r = c
        .get(s.url(&format!("/v1/jobs/{id}/mesh?format=obj")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let (out, _) =
        flatmesh::io::load(&r.bytes().await.unwrap(), flatmesh::io::Format::Obj).unwrap();
    let w = |m: &flatmesh::mesh::Mesh| {
        flatmesh::geometry::flattenability(m, &flatmesh::geometry::angle_sums(m))
            .into_iter()
            .fold(0.0, f64::max)
    };
    assert!(w(&out) <= w(&gmesh) + 1e-9, "{} > {}", w(&out), w(&gmesh));
    assert!(
        (w(&out) - fig["max_flattenability_after"].as_f64().unwrap()).abs() < 1e-9,
        "{fig}"
    );
    let (body, _) = flatmesh::io::load(&body_bytes, flatmesh::io::Format::Obj).unwrap();
    let (b, _) = flatmesh::algorithms::perturb::Body::new(&body);
    for v in 0..gmesh.num_vertices() as u32 {
        let before = b.clearance(gmesh.position(v)).signed;
        let after = b.clearance(out.position(v)).signed;
        if before >= 0.0 {
            assert!(after >= -1e-9, "vertex {v}: {before} -> {after}");
        }
    }
    // The GLB carries each vertex's displacement beside ϖ: read its accessor from the raw
    // chunks and compare with the distance recomputed from the OBJ download.
    let glb = download(&c, &s, &format!("/v1/jobs/{id}/mesh?format=glb")).await;
    let u32_at = |i: usize| u32::from_le_bytes(glb[i..i + 4].try_into().unwrap()) as usize;
    let json_len = u32_at(12);
    let root: Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin = &glb[20 + json_len + 8..];
    let acc = &root["accessors"][root["meshes"][0]["primitives"][0]["attributes"]["_DISPLACEMENT"]
        .as_u64()
        .unwrap() as usize];
    let view = &root["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap() as usize;
    assert_eq!(
        acc["count"].as_u64().unwrap() as usize,
        gmesh.num_vertices()
    );
    let mut moved = 0;
    for v in 0..gmesh.num_vertices() {
        let k = start + 4 * v;
        let stored = f32::from_le_bytes(bin[k..k + 4].try_into().unwrap()) as f64;
        let (a, b) = (gmesh.positions()[v], out.positions()[v]);
        let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        assert!(
            (stored - d).abs() <= 1e-6 * (1.0 + d),
            "vertex {v}: {stored} vs {d}"
        );
        moved += usize::from(d > 0.0);
    }
    assert!(moved > 0);
    assert!(root["asset"]["extras"]["flatmesh"]["attributes"]["_DISPLACEMENT"].is_string());
}

/// A develop job (Su et al.'s loop method): the table, every level downloadable, the output
/// developable by angle sums recomputed here.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn develop_job_end_to_end() {
    let s = Server::start(&tmp("k-develop"), &[]);
    let c = client();
    let cone = fixture("cone_noisy");
    let (kmesh, _) = flatmesh::io::load(&cone, flatmesh::io::Format::Obj).unwrap();
    let km = upload(&c, &s, cone).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "develop", "mesh_id": km["id"], "params": {"method": "loop"}}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["converged"], true, "{done}");
    let result = job_result(&c, &s, id).await;
    let fig = &result["job"];
    assert_eq!(fig["kind"], "develop");
    // The patches made flattenable: the file's, by default.
    assert_eq!(fig["patches"]["source"], "file", "{fig}");
    let rows = fig["table"]["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4, "{fig}");
    let level = download(&c, &s, &format!("/v1/jobs/{id}/mesh?level=1&format=obj")).await;
    let (lv, _) = flatmesh::io::load(&level, flatmesh::io::Format::Obj).unwrap();
    assert_eq!(
        lv.num_vertices(),
        kmesh.num_vertices() + kmesh.conn().edges().len()
    );
    assert_eq!(lv.num_faces(), 4 * kmesh.num_faces());
    let out = download(&c, &s, &format!("/v1/jobs/{id}/mesh?format=obj")).await;
    let (out, _) = flatmesh::io::load(&out, flatmesh::io::Format::Obj).unwrap();
    let w = flatmesh::geometry::flattenability(&out, &flatmesh::geometry::angle_sums(&out));
    let wmax = w.iter().copied().fold(0.0, f64::max);
    // The OBJ's decimal positions round the exact output a little.
    assert!(wmax <= 1e-5, "ϖ_max {wmax}");
    let r = c
        .post(s.url("/v1/jobs"))
        .json(&json!({"kind": "develop", "mesh_id": km["id"], "params": {"relaxation": 2.5}}))
        .send()
        .await
        .unwrap();
    let p = problem(r, 422).await;
    assert_eq!(p["field"], "params.relaxation", "{p}");
}

/// A segment job on the saddle fixture: charts far fewer than VSA's, the mesh downloadable
/// with one patch per chart, patterns with seams, and a bad parameter named.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn segment_job_end_to_end() {
    let s = Server::start(&tmp("k-segment"), &[]);
    let c = client();
    let saddle = fixture("saddle");
    let (input, _) = flatmesh::io::load(&saddle, flatmesh::io::Format::Obj).unwrap();
    let km = upload(&c, &s, saddle).await;
    let j = submit(&c, &s, json!({"kind": "segment", "mesh_id": km["id"]})).await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = job_result(&c, &s, id).await;
    let fig = &result["job"];
    assert_eq!(fig["kind"], "segment");
    let (vsa, merged) = (
        fig["charts"]["vsa"].as_u64().unwrap(),
        fig["charts"]["merged"].as_u64().unwrap(),
    );
    assert!(merged >= 1 && merged < vsa, "{}", fig["charts"]);
    let out = download(&c, &s, &format!("/v1/jobs/{id}/mesh?format=obj")).await;
    let (out, _) = flatmesh::io::load(&out, flatmesh::io::Format::Obj).unwrap();
    assert_eq!(out.num_faces(), input.num_faces());
    assert_eq!(out.num_patches() as u64, merged);
    let patterns = download(&c, &s, &format!("/v1/jobs/{id}/patterns?format=json")).await;
    let patterns: serde_json::Value = serde_json::from_slice(&patterns).unwrap();
    assert_eq!(patterns["pieces"].as_array().unwrap().len() as u64, merged);
    if merged > 1 {
        assert!(
            !patterns["seams"].as_array().unwrap().is_empty(),
            "{patterns}"
        );
    }
    let r = c
        .post(s.url("/v1/jobs"))
        .json(&json!({"kind": "segment", "mesh_id": km["id"], "params": {"max_l2_stretch": 0.5}}))
        .send()
        .await
        .unwrap();
    let p = problem(r, 422).await;
    assert_eq!(p["field"], "params.max_l2_stretch", "{p}");
}

/// A subdivide job with a curve on a rim edge, and one with a curve it must refuse.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subdivide_job_end_to_end() {
    let s = Server::start(&tmp("k-subdivide"), &[]);
    let c = client();
    let cone = fixture("cone_noisy");
    let (kmesh, _) = flatmesh::io::load(&cone, flatmesh::io::Format::Obj).unwrap();
    let km = upload(&c, &s, cone).await;

    // subdivide, one level, with a curve on a rim edge of the cone: level 1 downloadable in
    // every format and flattenable; no level 2; a bad level is named.
    let rim = kmesh.conn().boundary_loops()[0].clone();
    let (a, b) = (rim[0], rim[1]);
    let (pa, pb) = (kmesh.position(a), kmesh.position(b));
    let j = submit(
        &c,
        &s,
        json!({"kind": "subdivide", "mesh_id": km["id"], "params": {
            "levels": 1,
            "curves": [{"edge": [a, b], "points": [pa, pb]}],
            "fl_mesh": {"max_iterations": 100}
        }}),
    )
    .await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = job_result(&c, &s, id).await;
    // Whether every level reached its tolerance, at the job's top level.
    assert!(done["converged"].is_boolean(), "{done}");
    assert_eq!(done["converged"], result["job"]["converged"], "{done}");
    assert_eq!(
        result["job"]["levels"].as_array().unwrap().len(),
        1,
        "{result}"
    );
    for (f, fmt) in [
        ("obj", flatmesh::io::Format::Obj),
        ("glb", flatmesh::io::Format::Glb),
        ("gltf", flatmesh::io::Format::Gltf),
    ] {
        let r = c
            .get(s.url(&format!("/v1/jobs/{id}/mesh?level=1&format={f}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "level 1 as {f}");
        let (lv, _) = flatmesh::io::load(&r.bytes().await.unwrap(), fmt).unwrap();
        assert!(lv.num_vertices() > kmesh.num_vertices());
        if f == "obj" {
            let theta = flatmesh::geometry::angle_sums(&lv);
            let w = flatmesh::geometry::flattenability(&lv, &theta)
                .into_iter()
                .fold(0.0, f64::max);
            assert!(w <= 1e-6, "level 1 ϖ_max {w}");
            assert_eq!(
                result["job"]["levels"][0]["vertices"].as_u64().unwrap() as usize,
                lv.num_vertices()
            );
        }
    }
    // A level the job does not have, however large, is not found (not a malformed request).
    for level in ["2", "248608681082215"] {
        problem(
            c.get(s.url(&format!("/v1/jobs/{id}/mesh?level={level}")))
                .send()
                .await
                .unwrap(),
            404,
        )
        .await;
    }
    let p = problem(
        c.get(s.url(&format!("/v1/jobs/{id}/mesh?level=zero")))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "level");
    // A curve on an interior edge can only be judged against the mesh: the job fails with a
    // 422 problem naming the curve.
    let v = kmesh.conn().interior_vertices().next().unwrap();
    let w = kmesh.conn().ring_of(v)[0];
    let j = submit(
        &c,
        &s,
        json!({"kind": "subdivide", "mesh_id": km["id"], "params": {
            "curves": [{"edge": [v, w], "points": [kmesh.position(v), kmesh.position(w)]}]
        }}),
    )
    .await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "failed", "{done}");
    assert_eq!(done["error"]["status"], 422, "{done}");
    assert_eq!(done["error"]["field"], "params.curves[0].edge", "{done}");
    assert!(
        done["error"]["detail"]
            .as_str()
            .unwrap()
            .contains("curves[0].edge"),
        "{done}"
    );
}

/// The job resource: multipart submit, list/filter/paginate, ETag, delete, cancel of an ended job.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jobs_multipart_list_etag_delete() {
    let s = Server::start(&tmp("k-jobs"), &[]);
    let c = client();
    let bytes = fixture("tube_two_panels");
    let m = upload(&c, &s, bytes.clone()).await;
    let mid = m["id"].as_str().unwrap();
    let id = submit(&c, &s, json!({"kind": "report", "mesh_id": mid})).await["id"]
        .as_str()
        .unwrap()
        .to_string();
    for _ in 0..2 {
        let j = submit(&c, &s, json!({"kind": "flatten", "mesh_id": mid})).await;
        wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded"]).await;
    }
    wait_for(&c, &s, &id, &["succeeded"]).await;

    // multipart submit: job + mesh in one request
    let form = reqwest::multipart::Form::new()
        .part(
            "job",
            reqwest::multipart::Part::text(json!({"kind": "report"}).to_string())
                .mime_str("application/json")
                .unwrap(),
        )
        .part("mesh", obj_part("saddle", "saddle.obj"));
    let r = post_jobs_form(&c, &s, form).await;
    assert_eq!(r.status(), 202);
    let j = json_of(r, "Job").await;
    let done = wait_for(&c, &s, j["id"].as_str().unwrap(), &["succeeded", "failed"]).await;
    assert_eq!(done["status"], "succeeded");
    let sm = json_of(
        c.get(s.url(&format!("/v1/meshes/{}", done["mesh_id"].as_str().unwrap())))
            .send()
            .await
            .unwrap(),
        "Mesh",
    )
    .await;
    assert_eq!(sm["developable"], false);

    // list, filter, paginate
    let all = json_of(
        c.get(s.url("/v1/jobs?page_size=100")).send().await.unwrap(),
        "JobList",
    )
    .await;
    assert_eq!(all["jobs"].as_array().unwrap().len(), 4);
    let fl = json_of(
        c.get(s.url("/v1/jobs?kind=flatten&status=succeeded"))
            .send()
            .await
            .unwrap(),
        "JobList",
    )
    .await;
    assert_eq!(fl["jobs"].as_array().unwrap().len(), 2);
    let mut seen = vec![];
    let mut token: Option<String> = None;
    loop {
        let mut u = s.url("/v1/jobs?page_size=1");
        if let Some(t) = &token {
            u += &format!("&page_token={t}");
        }
        let page = json_of(c.get(u).send().await.unwrap(), "JobList").await;
        for j in page["jobs"].as_array().unwrap() {
            seen.push(j["id"].as_str().unwrap().to_string());
        }
        match page["next_page_token"].as_str() {
            Some(t) => token = Some(t.to_string()),
            None => break,
        }
    }
    let want: Vec<String> = all["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(seen, want, "pages of one, newest first, no gaps or repeats");
    // Tokens are opaque and belong to their listing: not a number, refused with other filters
    // and when made up.
    let page = json_of(
        c.get(s.url("/v1/jobs?page_size=1")).send().await.unwrap(),
        "JobList",
    )
    .await;
    let t = page["next_page_token"].as_str().unwrap().to_string();
    assert!(t.parse::<i64>().is_err(), "{t}");
    for bad in [
        format!("status=succeeded&page_token={t}"),
        "page_token=3".into(),
    ] {
        let p = problem(
            c.get(s.url(&format!("/v1/jobs?{bad}")))
                .send()
                .await
                .unwrap(),
            422,
        )
        .await;
        assert_eq!(p["field"], "page_token", "{p}");
    }
    problem(
        c.get(s.url("/v1/jobs?status=done")).send().await.unwrap(),
        422,
    )
    .await;
    problem(
        c.get(s.url("/v1/jobs?page_size=0")).send().await.unwrap(),
        422,
    )
    .await;

    // Files typed as bytes for a client that asks for bytes; their own type otherwise.
    for (accept, want) in [
        ("application/octet-stream", "application/octet-stream"),
        ("model/obj, application/octet-stream", "model/obj"),
        ("*/*", "model/obj"),
    ] {
        let r = c
            .get(s.url(&format!("/v1/jobs/{id}/mesh?format=obj")))
            .header("accept", accept)
            .send()
            .await
            .unwrap();
        assert_eq!(r.headers()["content-type"], want, "{accept}");
    }
    // A raw upload may name its format; an unknown one is refused.
    let r = c
        .post(s.url("/v1/meshes?format=obj"))
        .header("content-type", "application/octet-stream")
        .body(fixture("saddle"))
        .send()
        .await
        .unwrap();
    assert!([200, 201].contains(&r.status().as_u16()));
    assert_eq!(json_of(r, "Mesh").await["format"], "obj");
    let p = problem(
        c.post(s.url("/v1/meshes?format=stl"))
            .body(fixture("saddle"))
            .send()
            .await
            .unwrap(),
        422,
    )
    .await;
    assert_eq!(p["field"], "format");
    // ETag / If-None-Match → 304 on every GET that has an ETag
    for path in [
        format!("/v1/jobs/{id}"),
        format!("/v1/meshes/{mid}"),
        format!("/v1/jobs/{id}/result"),
        format!("/v1/jobs/{id}/mesh?format=obj"),
    ] {
        let r = c.get(s.url(&path)).send().await.unwrap();
        assert_eq!(r.status(), 200, "{path}");
        let etag = r.headers()["etag"].to_str().unwrap().to_string();
        let r = c
            .get(s.url(&path))
            .header("if-none-match", &etag)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 304, "{path}");
        assert_eq!(r.headers()["etag"], etag.as_str(), "{path}");
        let r = c
            .get(s.url(&path))
            .header("if-none-match", "\"other\"")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{path}");
    }

    // delete, then gone
    let r = c
        .delete(s.url(&format!("/v1/jobs/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    problem(
        c.get(s.url(&format!("/v1/jobs/{id}")))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    problem(
        c.get(s.url(&format!("/v1/jobs/{id}/result")))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    problem(
        c.delete(s.url(&format!("/v1/jobs/{id}")))
            .send()
            .await
            .unwrap(),
        404,
    )
    .await;
    // cancel of an ended job
    let ended = done["id"].as_str().unwrap();
    problem(
        c.post(s.url(&format!("/v1/jobs/{ended}/cancel")))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn submit_errors() {
    let s = Server::start(&tmp("submit"), &[]);
    let c = client();
    let m = upload(&c, &s, fixture("cylinder")).await;
    let mid = m["id"].as_str().unwrap();
    let post = |body: &'static str| {
        c.post(s.url("/v1/jobs"))
            .header("content-type", "application/json")
            .body(body)
            .send()
    };
    problem(post("{not json").await.unwrap(), 400).await;
    let r = c
        .post(s.url("/v1/jobs"))
        .header("content-type", "text/plain")
        .body("{}")
        .send()
        .await
        .unwrap();
    problem(r, 415).await;
    let cases = [
        (json!({"mesh_id": mid}), "kind"),
        (json!({"kind": "origami", "mesh_id": mid}), "kind"),
        (json!({"kind": "flatten"}), "mesh_id"),
        (json!({"kind": "flatten", "mesh_id": "m_nope"}), "mesh_id"),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"tolerance": 2}}),
            "params.tolerance",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"max_iterations": 0}}),
            "params.max_iterations",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"max_iterations": "9"}}),
            "params.max_iterations",
        ),
        (
            json!({"kind": "subdivide", "mesh_id": mid, "params": {"levels": -1}}),
            "params.levels",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"bogus": 1}}),
            "params.bogus",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"method": "origami"}}),
            "params.method",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": {"unit": 3}}),
            "params.unit",
        ),
        (
            json!({"kind": "flatten", "mesh_id": mid, "params": []}),
            "params",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "params": {"x": 1}}),
            "params.x",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "extra": 1}),
            "extra",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "callback_url": "ftp://example.com/x"}),
            "callback_url",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "callback_url": "http://127.0.0.1:9/hook"}),
            "callback_url",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "callback_url": "http://10.1.2.3/hook"}),
            "callback_url",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "callback_url": "http://[::1]/hook"}),
            "callback_url",
        ),
        (
            json!({"kind": "report", "mesh_id": mid, "callback_url": "http://localhost/hook"}),
            "callback_url",
        ),
    ];
    for (body, field) in cases {
        let r = c.post(s.url("/v1/jobs")).json(&body).send().await.unwrap();
        let p = problem(r, 422).await;
        assert_eq!(p["field"], field, "{body}: {p}");
        // Said in JSON's terms, not Rust's.
        let detail = p["detail"].as_str().unwrap();
        for rust in ["usize", "u32", "u64", "f64", "i64", "struct ", "sequence"] {
            assert!(!detail.contains(rust), "{body}: {detail}");
        }
    }
    // nothing was queued by the refused requests
    let l = json_of(c.get(s.url("/v1/jobs")).send().await.unwrap(), "JobList").await;
    assert!(l["jobs"].as_array().unwrap().is_empty());

    // Idempotency-Key: same request → same job; different request → 422
    let body = json!({"kind": "report", "mesh_id": mid});
    let r1 = c
        .post(s.url("/v1/jobs"))
        .header("idempotency-key", "abc-1")
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(r1.status(), 202);
    let j1 = json_of(r1, "Job").await;
    wait_for(&c, &s, j1["id"].as_str().unwrap(), &["succeeded"]).await;
    let r2 = c
        .post(s.url("/v1/jobs"))
        .header("idempotency-key", "abc-1")
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(r2.status(), 202);
    assert_eq!(r2.headers()["idempotent-replayed"], "true");
    let j2 = json_of(r2, "Job").await;
    assert_eq!(j1["id"], j2["id"]);
    let r3 = c
        .post(s.url("/v1/jobs"))
        .header("idempotency-key", "abc-1")
        .json(&json!({"kind": "flatten", "mesh_id": mid}))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r3, 422).await["field"], "Idempotency-Key");
    let l = json_of(c.get(s.url("/v1/jobs")).send().await.unwrap(), "JobList").await;
    assert_eq!(
        l["jobs"].as_array().unwrap().len(),
        1,
        "one job for three submits"
    );

    // 500: a result file lost behind the server's back is reported, not hidden
    let id = j1["id"].as_str().unwrap();
    std::fs::remove_file(s.dir.join(format!("blobs/jobs/{id}/report.json"))).unwrap();
    problem(
        c.get(s.url(&format!("/v1/jobs/{id}/result")))
            .send()
            .await
            .unwrap(),
        500,
    )
    .await;
}

/// Every problem type the code can produce is documented, and each problem's `type` is an
/// absolute URL that resolves to that documentation; behind a proxy the forwarded host is
/// used, and `--public-url` wins over both.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn problem_types_are_absolute_and_documented() {
    // Slugs in the source: `Problem::new(status, "slug", …)`, the middleware's table and the
    // job error codes.
    let mut used = std::collections::BTreeSet::new();
    let mut files = vec![];
    let mut dirs = vec![std::path::PathBuf::from("src/service")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                files.push(p);
            }
        }
    }
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for chunk in text.split("Problem::new(").skip(1) {
            let args: String = chunk.chars().take(200).collect();
            if let Some(q) = args.split('"').nth(1) {
                if !q.is_empty() && q.chars().all(|c| c.is_ascii_lowercase() || c == '-') {
                    used.insert(q.to_string());
                }
            }
        }
        for line in text.lines() {
            let l = line.trim();
            if let Some(rest) = l.split("=> \"").nth(1) {
                let slug = rest.split('"').next().unwrap_or("");
                let table = (f.ends_with("problem.rs")
                    && l.starts_with(|c: char| c.is_ascii_digit()))
                    || (f.ends_with("domain.rs") && l.starts_with("ErrorCode::"));
                if table
                    && !slug.is_empty()
                    && slug.chars().all(|c| c.is_ascii_lowercase() || c == '-')
                {
                    used.insert(slug.to_string());
                }
            }
        }
    }
    assert!(used.len() >= 15, "{used:?}");
    let s = Server::start(&tmp("problems"), &[]);
    let c = client();
    for slug in &used {
        let r = c
            .get(s.url(&format!("/problems/{slug}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "problem type `{slug}` is not documented");
        assert!(r.text().await.unwrap().contains(slug.as_str()));
    }
    let list = c
        .get(s.url("/problems"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    for slug in &used {
        assert!(list.contains(&format!("problems/{slug}")), "{slug}");
    }
    // A problem's type is where its documentation is.
    let p = problem(c.get(s.url("/v1/jobs/j_nope")).send().await.unwrap(), 404).await;
    assert_eq!(p["type"], s.url("/problems/not-found"));
    let doc = c.get(p["type"].as_str().unwrap()).send().await.unwrap();
    assert_eq!(doc.status(), 200);
    // Behind a proxy: the forwarded scheme and host.
    let r = c
        .get(s.url("/v1/jobs/j_nope"))
        .header("x-forwarded-proto", "https")
        .header("x-forwarded-host", "api.example.com")
        .send()
        .await
        .unwrap();
    assert_eq!(
        problem(r, 404).await["type"],
        "https://api.example.com/problems/not-found"
    );
    drop(s);
    let s = Server::start(
        &tmp("problems-pub"),
        &["--public-url", "https://fm.example.com/api/"],
    );
    let r = c
        .get(s.url("/v1/jobs/j_nope"))
        .header("x-forwarded-host", "other.example.com")
        .send()
        .await
        .unwrap();
    assert_eq!(
        problem(r, 404).await["type"],
        "https://fm.example.com/api/problems/not-found"
    );
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .header("host", "internal:8080")
        .body(fixture("cylinder"))
        .send()
        .await
        .unwrap();
    let location = r.headers()["location"].to_str().unwrap().to_string();
    let m = json_of(r, "Mesh").await;
    let expected = format!(
        "https://fm.example.com/api/v1/meshes/{}",
        m["id"].as_str().unwrap()
    );
    assert_eq!(m["links"]["self"], expected.as_str());
    assert_eq!(location, expected);
}

/// Every file under `dir` (path, size), except the SQLite files, whose pages change on reads.
fn files_under(dir: &Path) -> Vec<(PathBuf, u64)> {
    files_in(dir)
        .into_iter()
        .filter(|p| !p.to_string_lossy().contains("flatmesh.sqlite3") && !p.ends_with("server.log"))
        .map(|p| {
            let len = std::fs::metadata(&p).unwrap().len();
            (p, len)
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_keys() {
    let s = Server::start(
        &tmp("keys"),
        &["--api-key", "k1,k2", "--cors-origin", "http://app.example"],
    );
    let c = client();
    let p = problem(c.get(s.url("/v1/jobs")).send().await.unwrap(), 401).await;
    assert_eq!(p["type"], s.url("/problems/unauthorized"));
    let r = c
        .get(s.url("/v1/jobs"))
        .bearer_auth("wrong")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["www-authenticate"], "Bearer");
    problem(r, 401).await;
    let r = c
        .get(s.url("/v1/jobs"))
        .bearer_auth("k2")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    json_of(r, "JobList").await;
    let r = c
        .post(s.url("/v1/meshes"))
        .header("content-type", "model/obj")
        .body(fixture("cone"))
        .send()
        .await
        .unwrap();
    problem(r, 401).await;
    // The scheme is case-insensitive (RFC 9110); a key's prefix is not the key.
    for (value, status) in [("bearer k1", 200), ("BEARER k2", 200), ("Bearer k", 401)] {
        let r = c
            .get(s.url("/v1/jobs"))
            .header("authorization", value)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), status, "{value}");
    }
    // A browser's preflight for an authenticated, idempotent submit is allowed by name (a
    // wildcard does not cover Authorization).
    let r = c
        .request(reqwest::Method::OPTIONS, s.url("/v1/jobs"))
        .header("origin", "http://app.example")
        .header("access-control-request-method", "POST")
        .header(
            "access-control-request-headers",
            "authorization,content-type,idempotency-key,if-none-match,x-request-id",
        )
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let h = r.headers();
    assert_eq!(h["access-control-allow-origin"], "http://app.example");
    let allowed = h["access-control-allow-headers"]
        .to_str()
        .unwrap()
        .to_lowercase();
    for name in [
        "authorization",
        "content-type",
        "idempotency-key",
        "if-none-match",
        "x-request-id",
    ] {
        assert!(allowed.split(',').any(|a| a.trim() == name), "{allowed}");
    }
    assert!(h["access-control-allow-methods"]
        .to_str()
        .unwrap()
        .contains("POST"));
    // probes stay open
    assert_eq!(c.get(s.url("/healthz")).send().await.unwrap().status(), 200);
}

/// Cancel a running job; a full queue answers 429 while readyz stays 200 (queue_full); the
/// time limit fails a job;
/// a mesh in use cannot be deleted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cancel_full_queue_time_limit() {
    let s = Server::start(&tmp("queue"), &["--workers", "1", "--max-queued", "1"]);
    let c = client();
    let slow = upload(&c, &s, slow_obj()).await;
    let sid = slow["id"].as_str().unwrap();
    let params: Value = serde_json::from_str(SLOW).unwrap();
    let a = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": sid, "params": params}),
    )
    .await;
    let a_id = a["id"].as_str().unwrap();
    let running = wait_for(&c, &s, a_id, &["running", "succeeded", "failed"]).await;
    assert_eq!(running["status"], "running");
    let b = submit(&c, &s, json!({"kind": "report", "mesh_id": sid})).await;
    assert_eq!(b["status"], "queued");
    let r = c
        .post(s.url("/v1/jobs"))
        .json(&json!({"kind": "report", "mesh_id": sid}))
        .send()
        .await
        .unwrap();
    let ra: u64 = r.headers()["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(ra >= 1);
    problem(r, 429).await;
    // Full, yet ready: it still serves polls and downloads.
    let r = c.get(s.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let ready = json_of(r, "Ready").await;
    assert_eq!(ready["queue_full"], true, "{ready}");
    assert_eq!(ready["queued"], ready["max_queued"], "{ready}");
    // ... and in metrics: the queue at its limit, the refusal counted.
    let m = metrics_text(&c, &s).await;
    for line in [
        "flatmesh_jobs_queued 1",
        "flatmesh_jobs_queue_limit 1",
        "flatmesh_jobs_rejected_total{reason=\"queue_full\"} 1",
    ] {
        assert!(m.lines().any(|l| l == line), "{line} not in {m}");
    }
    // a mesh in use cannot go; results of an unfinished job are a conflict
    problem(
        c.delete(s.url(&format!("/v1/meshes/{sid}")))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
    problem(
        c.get(s.url(&format!("/v1/jobs/{a_id}/result")))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
    // progress is reported while running
    let t = Instant::now();
    let now = loop {
        let now = job(&c, &s, a_id).await;
        if now["progress"].is_object() || t.elapsed() > Duration::from_secs(20) {
            break now;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert!(
        now["progress"]["stage"]
            .as_str()
            .unwrap()
            .starts_with("lpfb"),
        "{now}"
    );
    assert!(
        now["progress"]["step_norm"].as_f64().unwrap() > 0.0,
        "{now}"
    );
    // Retry-After follows what such jobs take: no flatten has finished here yet, so the
    // prior (5 s) less the time it has run; a report is expected to take well under 1 s.
    let r = c
        .get(s.url(&format!("/v1/jobs/{a_id}")))
        .send()
        .await
        .unwrap();
    let after: u64 = r.headers()["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!((1..=5).contains(&after), "{after}");
    // cancel the queued one: ends at once
    let r = c
        .post(s.url(&format!("/v1/jobs/{}/cancel", b["id"].as_str().unwrap())))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let cancelled = json_of(r, "Job").await;
    assert_eq!(cancelled["status"], "cancelled");
    // No results, and the job says why; a retried cancel is 200 with the same job.
    assert_eq!(
        cancelled["error"]["type"],
        s.url("/problems/cancelled"),
        "{cancelled}"
    );
    assert_eq!(cancelled["progress"]["stage"], "cancelled", "{cancelled}");
    let r = c
        .post(s.url(&format!("/v1/jobs/{}/cancel", b["id"].as_str().unwrap())))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(json_of(r, "Job").await["error"], cancelled["error"]);
    // cancel the running one: ends at its next iteration
    let t = Instant::now();
    let r = c
        .post(s.url(&format!("/v1/jobs/{a_id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let end = wait_for(&c, &s, a_id, &["cancelled", "succeeded", "failed"]).await;
    assert_eq!(end["status"], "cancelled", "{end}");
    assert!(
        t.elapsed() < Duration::from_secs(3),
        "cancel took {:?}",
        t.elapsed()
    );
    problem(
        c.get(s.url(&format!("/v1/jobs/{a_id}/result")))
            .send()
            .await
            .unwrap(),
        409,
    )
    .await;
    let r = c.get(s.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    drop(s);

    // time limit
    let s = Server::start(&tmp("limit"), &["--workers", "1", "--job-time-limit", "1s"]);
    let slow = upload(&c, &s, slow_obj()).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": slow["id"], "params": params}),
    )
    .await;
    let end = wait_for(
        &c,
        &s,
        j["id"].as_str().unwrap(),
        &["cancelled", "succeeded", "failed"],
    )
    .await;
    assert_eq!(end["status"], "failed", "{end}");
    assert_eq!(end["error"]["type"], s.url("/problems/time-limit"));
    let took = end["attempts"].as_u64().unwrap();
    assert_eq!(took, 1);
}

/// Kill -9 the server with a finished, a running and a queued job; restart on the same data
/// directory: the finished result is intact, the running job is queued again once its lease
/// (1 s here) runs out and runs as attempt 2, the queued job runs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn restart_loses_nothing() {
    let dir = tmp("restart");
    let s = Server::start(&dir, &["--workers", "1", "--lease", "1s"]);
    let c = client();
    let cyl = upload(&c, &s, fixture("cylinder")).await;
    let done = submit(&c, &s, json!({"kind": "flatten", "mesh_id": cyl["id"]})).await;
    let done_id = done["id"].as_str().unwrap().to_string();
    wait_for(&c, &s, &done_id, &["succeeded"]).await;
    let before = download(&c, &s, &format!("/v1/jobs/{done_id}/patterns?format=dxf")).await;
    let slow = upload(&c, &s, slow_obj()).await;
    let params: Value = serde_json::from_str(SLOW).unwrap();
    let run = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": slow["id"], "params": params}),
    )
    .await;
    let run_id = run["id"].as_str().unwrap().to_string();
    wait_for(&c, &s, &run_id, &["running"]).await;
    let queued = submit(&c, &s, json!({"kind": "report", "mesh_id": cyl["id"]})).await;
    let q_id = queued["id"].as_str().unwrap().to_string();
    assert_eq!(job(&c, &s, &q_id).await["status"], "queued");
    let dir = s.kill();

    let s = Server::start(&dir, &["--workers", "1", "--lease", "1s"]);
    let j = job(&c, &s, &done_id).await;
    assert_eq!(j["status"], "succeeded");
    let after = download(&c, &s, &format!("/v1/jobs/{done_id}/patterns?format=dxf")).await;
    assert_eq!(before, after);
    json_of(
        c.get(s.url(&format!("/v1/meshes/{}", cyl["id"].as_str().unwrap())))
            .send()
            .await
            .unwrap(),
        "Mesh",
    )
    .await;
    let start = Instant::now();
    let r = loop {
        let r = job(&c, &s, &run_id).await;
        if r["status"] == "running" && r["attempts"] == 2 {
            break r;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "not re-run after the crash: {r}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert_eq!(r["attempts"], 2, "re-queued after the crash: {r}");
    c.post(s.url(&format!("/v1/jobs/{run_id}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(
        wait_for(&c, &s, &run_id, &["cancelled"]).await["status"],
        "cancelled"
    );
    let q = wait_for(&c, &s, &q_id, &["succeeded", "failed"]).await;
    assert_eq!(q["status"], "succeeded");
    assert_eq!(q["attempts"], 1);
    drop(s);

    // The webhook secret generated on the first start is kept and reused, not replaced.
    let secret = std::fs::read_to_string(dir.join("webhook_secret")).unwrap();
    assert!(secret.trim().starts_with("whsec_"), "{secret}");
    let s = Server::start(&dir, &["--workers", "1", "--lease", "1s"]);
    assert_eq!(
        std::fs::read_to_string(dir.join("webhook_secret")).unwrap(),
        secret
    );
    drop(s);
    // A job interrupted as often as allowed fails instead of looping.
    let s = Server::start(&dir, &["--workers", "1", "--lease", "1s"]);
    let again = submit(
        &c,
        &s,
        json!({"kind": "flatten", "mesh_id": slow["id"], "params": params}),
    )
    .await;
    let a_id = again["id"].as_str().unwrap().to_string();
    wait_for(&c, &s, &a_id, &["running"]).await;
    let dir = s.kill();
    let s = Server::start(
        &dir,
        &["--workers", "1", "--max-attempts", "1", "--lease", "1s"],
    );
    let f = wait_for(&c, &s, &a_id, &["failed", "succeeded", "cancelled"]).await;
    assert_eq!(f["status"], "failed", "{f}");
    assert_eq!(f["error"]["type"], s.url("/problems/interrupted"));
}

/// A webhook reaches a receiver, which checks the Standard Webhooks signature itself.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn webhook_is_signed_and_delivered() {
    use hmac::{Hmac, Mac};
    use sha2::Sha256;
    let key: Vec<u8> = (0u8..32).collect();
    let secret = format!(
        "whsec_{}",
        base64::engine::general_purpose::STANDARD.encode(&key)
    );
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<(axum::http::HeaderMap, Vec<u8>)>();
    let hits = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let h2 = hits.clone();
    let first_id = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
    let f2 = first_id.clone();
    let app = axum::Router::new().route(
        "/hook",
        axum::routing::post(
            move |headers: axum::http::HeaderMap, body: axum::body::Bytes| {
                let tx = tx.clone();
                let (h2, f2) = (h2.clone(), f2.clone());
                async move {
                    // fail the first delivery: the server must retry
                    if h2.fetch_add(1, std::sync::atomic::Ordering::SeqCst) == 0 {
                        *f2.lock().unwrap() = headers
                            .get("webhook-id")
                            .and_then(|v| v.to_str().ok())
                            .map(String::from);
                        return axum::http::StatusCode::SERVICE_UNAVAILABLE;
                    }
                    let _ = tx.send((headers, body.to_vec()));
                    axum::http::StatusCode::NO_CONTENT
                }
            },
        ),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let hook = format!("http://{}/hook", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, app).await });

    let s = Server::start(
        &tmp("hook"),
        &[
            "--webhook-secret",
            &secret,
            "--allow-private-callbacks",
            "--webhook-backoff",
            "200ms,1s",
        ],
    );
    let c = client();
    let m = upload(&c, &s, fixture("cone")).await;
    let j = submit(
        &c,
        &s,
        json!({"kind": "report", "mesh_id": m["id"], "callback_url": hook}),
    )
    .await;
    let (headers, body) = tokio::time::timeout(Duration::from_secs(30), rx.recv())
        .await
        .expect("webhook within 30 s")
        .unwrap();
    assert_eq!(
        hits.load(std::sync::atomic::Ordering::SeqCst),
        2,
        "one retry"
    );
    let id = headers["webhook-id"].to_str().unwrap();
    // The retry is the same message: a receiver can drop a duplicate by its id.
    assert_eq!(
        first_id.lock().unwrap().as_deref(),
        Some(id),
        "webhook-id across attempts"
    );
    let ts = headers["webhook-timestamp"].to_str().unwrap();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs() as i64;
    assert!((ts.parse::<i64>().unwrap() - now).abs() < 60);
    let mut mac = Hmac::<Sha256>::new_from_slice(&key).unwrap();
    mac.update(format!("{id}.{ts}.").as_bytes());
    mac.update(&body);
    let expected = base64::engine::general_purpose::STANDARD.encode(mac.finalize().into_bytes());
    let sigs = headers["webhook-signature"].to_str().unwrap();
    assert!(
        sigs.split(' ').any(|s| s == format!("v1,{expected}")),
        "signature {sigs} vs v1,{expected}"
    );
    let v: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(v["type"], "job.succeeded");
    check("WebhookEvent", &v);
    assert_eq!(v["data"]["id"], j["id"]);
    // Links as absolute as the submitter saw them (no public URL configured).
    assert_eq!(
        v["data"]["links"]["self"],
        s.url(&format!("/v1/jobs/{}", j["id"].as_str().unwrap())),
        "{v}"
    );
}

fn flatmesh_client(base: &str, args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["client", "--server", base])
        .args(args)
        .env_remove("FLATMESH_API_KEY")
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// `flatmesh client` against the real server: upload, submit (by id and multipart), wait,
/// download, health.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn client_commands() {
    let s = Server::start(&tmp("client"), &[]);
    let c = client();
    let base = s.base.clone();
    let (ok, out, err) = flatmesh_client(&base, &["upload", "fixtures/cylinder.obj"]);
    assert!(ok, "{err}");
    let m: Value = serde_json::from_str(&out).unwrap();
    check("Mesh", &m);
    let mid = m["id"].as_str().unwrap();
    let (ok, out, err) = flatmesh_client(
        &base,
        &[
            "submit",
            "flatten",
            "--mesh-id",
            mid,
            "--set",
            "unit=cm",
            "--idempotency-key",
            "k",
        ],
    );
    assert!(ok, "{err}");
    let j: Value = serde_json::from_str(&out).unwrap();
    check("Job", &j);
    assert_eq!(j["params"]["unit"], "cm");
    let id = j["id"].as_str().unwrap();
    let (ok, out, err) = flatmesh_client(&base, &["wait", id, "--timeout", "60"]);
    assert!(ok, "{err}");
    let done: Value = serde_json::from_str(&out).unwrap();
    check("Job", &done);
    assert_eq!(done["status"], "succeeded");
    assert!(err.contains(id), "progress lines on stderr: {err}");
    let dir = tmp("client-out");
    std::fs::create_dir_all(&dir).unwrap();
    for (what, format) in [("patterns", "dxf"), ("mesh", "obj"), ("result", "")] {
        let out_file = dir.join(format!("{what}.{format}"));
        let mut args = vec![
            "download",
            id,
            "--what",
            what,
            "--out",
            out_file.to_str().unwrap(),
        ];
        if !format.is_empty() {
            args.extend(["--format", format]);
        }
        let (ok, _, err) = flatmesh_client(&base, &args);
        assert!(ok, "{err}");
        let path = match what {
            "result" => format!("/v1/jobs/{id}/result"),
            _ => format!("/v1/jobs/{id}/{what}?format={format}"),
        };
        let want = c
            .get(s.url(&path))
            .send()
            .await
            .unwrap()
            .bytes()
            .await
            .unwrap();
        assert_eq!(std::fs::read(&out_file).unwrap(), want.to_vec(), "{what}");
    }
    // multipart submit with a file, and a refused parameter reported with its field
    let (ok, out, err) =
        flatmesh_client(&base, &["submit", "report", "--mesh", "fixtures/cone.obj"]);
    assert!(ok, "{err}");
    let j: Value = serde_json::from_str(&out).unwrap();
    check("Job", &j);
    let (ok, _, err) = flatmesh_client(&base, &["wait", j["id"].as_str().unwrap()]);
    assert!(ok, "{err}");
    let (ok, _, err) = flatmesh_client(
        &base,
        &[
            "submit",
            "flatten",
            "--mesh-id",
            mid,
            "--set",
            "tolerance=7",
        ],
    );
    assert!(!ok);
    assert!(
        err.contains("422") && err.contains("params.tolerance"),
        "{err}"
    );
    let (ok, _, _) = flatmesh_client(&base, &["health"]);
    assert!(ok);
    drop(s);
    let (ok, _, _) = flatmesh_client(&base, &["health"]);
    assert!(!ok, "health fails when the server is gone");
}

/// Results expire after the retention; CORS and gzip are applied.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retention_cors_compression() {
    let s = Server::start(
        &tmp("retention"),
        &["--retention", "1s", "--cors-origin", "https://cad.example"],
    );
    let c = client();
    let m = upload(&c, &s, fixture("cone")).await;
    let j = submit(&c, &s, json!({"kind": "report", "mesh_id": m["id"]})).await;
    let id = j["id"].as_str().unwrap();
    let done = wait_for(&c, &s, id, &["succeeded"]).await;
    assert!(done["expires_at"].is_string());
    let t = Instant::now();
    loop {
        let r = c
            .get(s.url(&format!("/v1/jobs/{id}")))
            .send()
            .await
            .unwrap();
        if r.status() == 404 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(10), "job not expired");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(
        !s.dir.join(format!("blobs/jobs/{id}")).exists(),
        "artifacts deleted"
    );
    // The upload goes too once no job uses it and it is older than the retention period.
    let mesh_url = s.url(&format!("/v1/meshes/{}", m["id"].as_str().unwrap()));
    let t = Instant::now();
    while c.get(&mesh_url).send().await.unwrap().status() != 404 {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "unused upload not expired"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let r = c
        .get(s.url("/v1/jobs"))
        .header("origin", "https://cad.example")
        .send()
        .await
        .unwrap();
    assert_eq!(
        r.headers()["access-control-allow-origin"],
        "https://cad.example"
    );
    let r = c
        .get(s.url("/v1/jobs"))
        .header("origin", "https://evil.example")
        .send()
        .await
        .unwrap();
    assert!(!r.headers().contains_key("access-control-allow-origin"));
    let r = c
        .get(s.url("/openapi.yaml"))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-encoding"], "gzip");
    let gz = r.bytes().await.unwrap();
    assert!(gz.len() < openapi_len(), "compressed {} bytes", gz.len());
}

fn openapi_len() -> usize {
    std::fs::metadata("openapi.yaml").unwrap().len() as usize
}

/// A reference body given to a kind that does not use one is refused (422 naming the field),
/// in a JSON submit, in a multipart submit and on the command line; nothing is stored.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reference_refused_by_kinds_without_one() {
    let s = Server::start(&tmp("reference"), &[]);
    let c = client();
    let m = upload(&c, &s, fixture("cylinder")).await;
    let mid = m["id"].as_str().unwrap();
    for kind in flatmesh::jobs::Kind::ALL {
        if kind.reference() != flatmesh::jobs::Reference::None {
            continue;
        }
        let r = c
            .post(s.url("/v1/jobs"))
            .json(&json!({"kind": kind.name(), "mesh_id": mid, "reference_mesh_id": mid}))
            .send()
            .await
            .unwrap();
        let p = problem(r, 422).await;
        assert_eq!(p["field"], "reference_mesh_id", "{p}");
        assert!(p["detail"].as_str().unwrap().contains(kind.name()), "{p}");
    }
    let form = reqwest::multipart::Form::new()
        .text("job", r#"{"kind": "report"}"#)
        .part("mesh", obj_part("cylinder", "a.obj"))
        .part("reference", obj_part("cylinder", "b.obj"));
    let r = post_jobs_form(&c, &s, form).await;
    let p = problem(r, 422).await;
    assert_eq!(p["field"], "reference", "{p}");
    let meshes = std::fs::read_dir(s.dir.join("blobs/meshes"))
        .map(|d| d.count())
        .unwrap_or(0);
    assert_eq!(meshes, 1, "only the first upload is stored");
    let o = Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(["run", "report", "fixtures/cylinder.obj", "--reference"])
        .arg("fixtures/cylinder.obj")
        .arg("--out")
        .arg(tmp("reference-cli"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("does not use a reference body"));
}

/// report.json without what depends on the clock: `seconds`, `timings` and `seconds_*`.
fn without_timings(v: &mut Value) {
    match v {
        Value::Object(o) => {
            o.retain(|k, _| k != "seconds" && k != "timings" && !k.starts_with("seconds_"));
            o.values_mut().for_each(without_timings);
        }
        Value::Array(a) => a.iter_mut().for_each(without_timings),
        _ => {}
    }
}

/// `flatmesh run KIND` and the same job through the service give the same files: the same
/// names, every file byte for byte, report.json equal once the clock's figures are removed.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cli_and_service_write_the_same_files() {
    let s = Server::start(&tmp("same-files"), &[]);
    let c = client();
    let cases = [
        ("report", "cylinder_noisy", json!({})),
        ("flatten", "tube_two_panels", json!({"unit": "cm"})),
        ("fl-mesh", "cylinder_noisy", json!({})),
        ("subdivide", "cone_noisy", json!({"levels": 1})),
    ];
    for (kind, name, params) in cases {
        let m = upload(&c, &s, fixture(name)).await;
        let j = submit(
            &c,
            &s,
            json!({"kind": kind, "mesh_id": m["id"], "params": params}),
        )
        .await;
        let id = j["id"].as_str().unwrap();
        let done = wait_for(&c, &s, id, &["succeeded", "failed"]).await;
        assert_eq!(done["status"], "succeeded", "{done}");
        let out = tmp(&format!("same-files-cli-{kind}"));
        let _ = std::fs::remove_dir_all(&out);
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_flatmesh"));
        cmd.args(["run", kind, &format!("fixtures/{name}.obj"), "--out"])
            .arg(&out);
        for (k, v) in params.as_object().unwrap() {
            cmd.args(["--set", &format!("{k}={v}")]);
        }
        let o = cmd.output().unwrap();
        assert!(
            o.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let listing = |dir: &Path| -> Vec<String> {
            let mut v: Vec<String> = std::fs::read_dir(dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        let blobs = s.dir.join(format!("blobs/jobs/{id}"));
        let names = listing(&out);
        assert_eq!(names, listing(&blobs), "{kind}: file names");
        assert!(
            names.contains(&"mesh.gltf".to_string()),
            "{kind}: {names:?}"
        );
        println!("{kind}: {} files compared: {names:?}", names.len());
        for f in &names {
            let (a, b) = (
                std::fs::read(out.join(f)).unwrap(),
                std::fs::read(blobs.join(f)).unwrap(),
            );
            if f == "report.json" {
                let mut a: Value = serde_json::from_slice(&a).unwrap();
                let mut b: Value = serde_json::from_slice(&b).unwrap();
                assert_eq!(a["job"]["kind"], kind);
                without_timings(&mut a);
                without_timings(&mut b);
                assert_eq!(a, b, "{kind}: report.json");
            } else {
                assert!(
                    a == b,
                    "{kind}: {f} differs ({} vs {} bytes)",
                    a.len(),
                    b.len()
                );
            }
        }
    }
}

/// A multipart submit retried with one Idempotency-Key (three times) makes one job and stores
/// one mesh; a different mesh under the same key is refused and stores nothing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn retried_multipart_submit_stores_one_mesh() {
    let s = Server::start(&tmp("multipart-retry"), &[]);
    let c = client();
    let form = |name: &str| {
        reqwest::multipart::Form::new()
            .text("job", r#"{"kind": "report"}"#)
            .part("mesh", obj_part(name, "a.obj"))
    };
    let mut ids = Vec::new();
    for attempt in 0..3 {
        let r = c
            .post(s.url("/v1/jobs"))
            .header("idempotency-key", "retry-1")
            .multipart(form("cylinder"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        assert_eq!(
            r.headers().get("idempotent-replayed").is_some(),
            attempt > 0,
            "attempt {attempt}"
        );
        ids.push(json_of(r, "Job").await["id"].as_str().unwrap().to_string());
    }
    assert!(ids.iter().all(|i| i == &ids[0]), "{ids:?}");
    let r = c
        .post(s.url("/v1/jobs"))
        .header("idempotency-key", "retry-1")
        .multipart(form("cone"))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r, 422).await["field"], "Idempotency-Key");
    let meshes = std::fs::read_dir(s.dir.join("blobs/meshes"))
        .unwrap()
        .count();
    assert_eq!(meshes, 1, "one mesh stored for four requests");
}

/// The worker holding a running job, read from the store (`host-pid-…/k`).
fn holder(dir: &Path, id: &str) -> Option<String> {
    let c = rusqlite::Connection::open(dir.join("flatmesh.sqlite3")).unwrap();
    c.busy_timeout(Duration::from_secs(5)).unwrap();
    c.query_row("SELECT worker FROM jobs WHERE id = ?1", [id], |r| r.get(0))
        .unwrap()
}

/// Wait until job `id` runs, and return the pid of the process holding it.
async fn running_on(c: &reqwest::Client, s: &Server, id: &str) -> u32 {
    wait_for(c, s, id, &["running"]).await;
    let w = holder(&s.dir, id).expect("a running job has a holder");
    w.split('-').nth_back(1).unwrap().parse().unwrap()
}

/// Two `flatmesh serve` processes on one data directory share one queue: a cancel sent to
/// either stops a job running on the other, progress shows through both, and of 30 jobs
/// submitted through both, with one process killed (SIGKILL) mid-run and restarted, every
/// job ends exactly once (one "job ended" line in the two processes' logs, a terminal status
/// seen alike through both).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_processes_share_one_store() {
    let dir = tmp("two-processes");
    let args = ["--workers", "1", "--lease", "1s", "--job-time-limit", "4s"];
    let a = Server::start(&dir, &args);
    let c = client();
    let cyl = upload(&c, &a, fixture("cylinder")).await;
    let saddle = upload(&c, &a, slow_obj()).await;
    let slow: Value = serde_json::from_str(SLOW).unwrap();
    let slow_job = json!({"kind": "flatten", "mesh_id": saddle["id"], "params": slow});
    // a job that runs on A (B does not exist yet) is cancelled through B
    let first = submit(&c, &a, slow_job.clone()).await;
    let first = first["id"].as_str().unwrap().to_string();
    assert_eq!(running_on(&c, &a, &first).await, a.pid());
    let b = Server::start(&dir, &args);
    let start = Instant::now();
    loop {
        let (pa, pb) = (job(&c, &a, &first).await, job(&c, &b, &first).await);
        if !pa["progress"].is_null() && !pb["progress"].is_null() {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(3),
            "no progress via B: {pb}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let r = c
        .post(b.url(&format!("/v1/jobs/{first}/cancel")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let end = wait_for(&c, &a, &first, &["cancelled", "failed", "succeeded"]).await;
    assert_eq!(end["status"], "cancelled", "{end}");
    // and the other way round: whichever process runs the next one, cancel through the other
    let second = submit(&c, &b, slow_job.clone()).await;
    let second = second["id"].as_str().unwrap().to_string();
    let other = if running_on(&c, &b, &second).await == a.pid() {
        &b
    } else {
        &a
    };
    c.post(other.url(&format!("/v1/jobs/{second}/cancel")))
        .send()
        .await
        .unwrap();
    let end = wait_for(&c, other, &second, &["cancelled", "failed", "succeeded"]).await;
    assert_eq!(end["status"], "cancelled", "{end}");

    // 30 jobs through both; four run until the time limit, so that A dies holding one
    let mut ids = Vec::new();
    for k in 0..30 {
        let via = if k % 2 == 0 { &a } else { &b };
        let body = if k % 8 == 3 {
            slow_job.clone()
        } else if k % 2 == 0 {
            json!({"kind": "report", "mesh_id": cyl["id"]})
        } else {
            json!({"kind": "flatten", "mesh_id": cyl["id"]})
        };
        ids.push(
            submit(&c, via, body).await["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
    }
    let start = Instant::now();
    let killed = loop {
        let on_a = ids
            .iter()
            .find(|id| holder(&dir, id).is_some_and(|w| w.contains(&format!("-{}-", a.pid()))));
        if let Some(id) = on_a {
            break id.clone();
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "A never ran a job"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    let a_dir = a.kill();
    let a = Server::start(&a_dir, &args);
    for id in &ids {
        let via_a = wait_for(&c, &a, id, &["succeeded", "failed", "cancelled"]).await;
        let via_b = job(&c, &b, id).await;
        assert_eq!(via_a["status"], via_b["status"], "{id}");
        assert_eq!(via_a["attempts"], via_b["attempts"], "{id}");
        let want = if via_a["params"]["tolerance"].is_null() {
            "succeeded"
        } else {
            "failed"
        };
        assert_eq!(via_a["status"], want, "{via_a}");
    }
    let killed_job = job(&c, &b, &killed).await;
    assert!(
        killed_job["attempts"].as_u64().unwrap() >= 2,
        "{killed_job}"
    );
    let log = std::fs::read_to_string(dir.join("server.log")).unwrap();
    for id in &ids {
        let ended = log
            .lines()
            .filter(|l| l.contains("job ended") && l.contains(id.as_str()))
            .count();
        assert_eq!(ended, 1, "{id} ended {ended} times");
    }
    drop((a, b));
}
