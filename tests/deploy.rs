//! deploy/: no container engine runs here, so the compose file and the Kubernetes example are
//! checked by parsing them: three replicas on one PostgreSQL behind a balancer that lists
//! them, probes on the service's real health routes, and every FLATMESH_* variable a real
//! flag of `flatmesh serve`.

use serde_yaml::Value;
use std::collections::BTreeSet;

fn yaml(path: &str) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap();
    serde_yaml::Deserializer::from_str(&text)
        .map(|d| serde::Deserialize::deserialize(d).unwrap())
        .collect()
}

/// The environment variables `flatmesh serve` reads (its clap `env = "…"` names).
fn serve_env() -> BTreeSet<String> {
    let src = std::fs::read_to_string("src/service/config.rs").unwrap();
    src.split("env = \"")
        .skip(1)
        .map(|s| s.split('"').next().unwrap().to_string())
        .collect()
}

fn env_names(v: &Value, out: &mut BTreeSet<String>) {
    match v {
        Value::Mapping(m) => {
            for (k, v) in m {
                if let Some(k) = k.as_str().filter(|k| k.starts_with("FLATMESH_")) {
                    out.insert(k.to_string());
                }
                if k.as_str() == Some("name") {
                    if let Some(n) = v.as_str().filter(|n| n.starts_with("FLATMESH_")) {
                        out.insert(n.to_string());
                    }
                }
                env_names(v, out);
            }
        }
        Value::Sequence(s) => s.iter().for_each(|v| env_names(v, out)),
        _ => {}
    }
}

#[test]
fn compose_runs_three_replicas_on_one_postgres_behind_a_balancer() {
    let doc = &yaml("deploy/compose.yaml")[0];
    let services = doc["services"].as_mapping().unwrap();
    let replicas: Vec<&str> = services
        .iter()
        .filter(|(_, s)| s["command"][0].as_str() == Some("serve"))
        .map(|(k, _)| k.as_str().unwrap())
        .collect();
    assert_eq!(replicas, ["flatmesh-1", "flatmesh-2", "flatmesh-3"]);
    for r in &replicas {
        let s = &services[*r];
        let url = s["environment"]["FLATMESH_DATABASE_URL"].as_str().unwrap();
        assert!(
            url.starts_with("postgres://") && url.contains("@postgres:5432/"),
            "{url}"
        );
        assert_eq!(
            s["depends_on"]["postgres"]["condition"].as_str(),
            Some("service_healthy")
        );
        assert_eq!(
            s["environment"]["FLATMESH_BIND"].as_str(),
            Some("0.0.0.0:8080")
        );
    }
    assert!(services["postgres"]["image"]
        .as_str()
        .unwrap()
        .starts_with("postgres:"));
    assert!(services["postgres"]["healthcheck"]["test"][1]
        .as_str()
        .unwrap()
        .contains("pg_isready"));
    // The balancer's configuration names exactly the replicas, on their port.
    let conf = std::fs::read_to_string("deploy/nginx.conf").unwrap();
    for r in &replicas {
        assert!(
            conf.contains(&format!("server {r}:8080")),
            "{r} not balanced"
        );
    }
    let mounted = services["balancer"]["volumes"][0].as_str().unwrap();
    assert!(mounted.starts_with("./nginx.conf:"), "{mounted}");
    let mut names = BTreeSet::new();
    env_names(doc, &mut names);
    let known = serve_env();
    assert!(
        names.is_subset(&known),
        "unknown: {:?}",
        names.difference(&known)
    );
}

#[test]
fn kubernetes_example_probes_the_real_routes_and_reads_the_database_secret() {
    let docs = yaml("deploy/kubernetes/flatmesh.yaml");
    let dep = docs
        .iter()
        .find(|d| d["kind"].as_str() == Some("Deployment"))
        .unwrap();
    assert_eq!(dep["spec"]["replicas"].as_u64(), Some(3));
    let c = &dep["spec"]["template"]["spec"]["containers"][0];
    assert_eq!(
        c["readinessProbe"]["httpGet"]["path"].as_str(),
        Some("/readyz")
    );
    assert_eq!(
        c["livenessProbe"]["httpGet"]["path"].as_str(),
        Some("/healthz")
    );
    let env = c["env"].as_sequence().unwrap();
    let db = env
        .iter()
        .find(|e| e["name"].as_str() == Some("FLATMESH_DATABASE_URL"))
        .unwrap();
    assert_eq!(
        db["valueFrom"]["secretKeyRef"]["name"].as_str(),
        Some("flatmesh")
    );
    let svc = docs
        .iter()
        .find(|d| d["kind"].as_str() == Some("Service"))
        .unwrap();
    assert_eq!(
        svc["spec"]["selector"]["app"],
        dep["spec"]["template"]["metadata"]["labels"]["app"]
    );
    let mut names = BTreeSet::new();
    for d in &docs {
        env_names(d, &mut names);
    }
    let known = serve_env();
    assert!(
        names.is_subset(&known),
        "unknown: {:?}",
        names.difference(&known)
    );
}
