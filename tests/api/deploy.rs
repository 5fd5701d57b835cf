//! deploy/: no container engine runs here, so the compose file and the Kubernetes example are
//! checked by parsing them: three replicas on one PostgreSQL behind a balancer that lists
//! them, probes on the service's real health routes, and every FLATMESH_* variable a real
//! flag of `flatmesh serve`.

use crate::common;

use serde_yaml::Value;
use std::collections::{BTreeMap, BTreeSet};

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

/// The Dockerfile's instructions, continuation lines joined: (instruction, arguments).
fn dockerfile() -> Vec<(String, String)> {
    let text = std::fs::read_to_string("Dockerfile").unwrap();
    let joined = text.replace("\\\n", " ");
    joined
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            let (i, a) = l.split_once(' ').unwrap_or((l, ""));
            (i.to_string(), a.trim().to_string())
        })
        .collect()
}

/// A JSON-array (exec form) argument list.
fn exec_form(args: &str) -> Vec<String> {
    serde_json::from_str(args).unwrap_or_else(|e| panic!("{args}: {e}"))
}

/// The image runs `flatmesh serve` as a non-root user on the `/data` volume, bound to the
/// port it exposes, and its healthcheck passes against that server and fails without it:
/// checked by running the image's command with the image's environment (on a free port and a
/// temporary data directory; no container engine runs here). The build stage's stub benches
/// are exactly Cargo.toml's, so the dependency layer builds.
#[test]
fn dockerfile_runs_the_service_as_documented() {
    use std::io::BufRead;
    let all = dockerfile();
    let last_from = all.iter().rposition(|(i, _)| i == "FROM").unwrap();
    let (build, image) = all.split_at(last_from);
    let get = |name: &str| -> Vec<String> {
        image
            .iter()
            .filter(|(i, _)| i == name)
            .map(|(_, a)| a.clone())
            .collect()
    };
    let user = get("USER");
    assert_eq!(user.len(), 1);
    assert!(!["root", "0"].contains(&user[0].as_str()), "{user:?}");
    let runs = get("RUN").join(" ");
    assert!(
        runs.contains("useradd") && runs.contains(&user[0]),
        "{runs}"
    );
    let env: BTreeMap<String, String> = get("ENV")
        .iter()
        .flat_map(|a| a.split_whitespace().map(str::to_string).collect::<Vec<_>>())
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            (k.to_string(), v.to_string())
        })
        .collect();
    let known = serve_env();
    for k in env.keys() {
        assert!(known.contains(k), "ENV {k} is no flag of flatmesh serve");
    }
    // What the README tells users to run: `-p 8080:8080 -v flatmesh-data:/data`.
    assert_eq!(env["FLATMESH_DATA_DIR"], "/data");
    assert_eq!(env["FLATMESH_BIND"], "0.0.0.0:8080");
    let data = &env["FLATMESH_DATA_DIR"];
    assert_eq!(get("VOLUME"), std::slice::from_ref(data));
    assert!(
        runs.contains(&format!("chown {} {data}", user[0])),
        "{runs}"
    );
    let port = env["FLATMESH_BIND"].rsplit(':').next().unwrap().to_string();
    assert_eq!(get("EXPOSE"), std::slice::from_ref(&port));
    let health = get("HEALTHCHECK");
    let health = exec_form(health[0].split_once("CMD ").unwrap().1);
    let si = health.iter().position(|a| a == "--server").unwrap() + 1;
    assert_eq!(health[si].rsplit(':').next().unwrap(), port, "{health:?}");
    let argv: Vec<String> = [exec_form(&get("ENTRYPOINT")[0]), exec_form(&get("CMD")[0])].concat();
    assert_eq!(argv[0], "flatmesh");
    assert_eq!(health[0], "flatmesh");

    // The image's command with its environment, on a free port of the same interface.
    let dir = common::tmp("docker-image");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
        .args(&argv[1..])
        .envs(&env)
        .env("FLATMESH_BIND", env["FLATMESH_BIND"].replace(&port, "0"))
        .env("FLATMESH_DATA_DIR", &dir)
        .env_remove("FLATMESH_API_KEYS")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let actual = line.trim().rsplit(':').next().unwrap().to_string();
    assert!(actual.parse::<u16>().is_ok(), "{line}");
    let healthcheck = |url: &str| {
        let mut args = health[1..].to_vec();
        args[si - 1] = url.to_string();
        std::process::Command::new(env!("CARGO_BIN_EXE_flatmesh"))
            .args(&args)
            .status()
            .unwrap()
            .success()
    };
    let url = health[si].replace(&format!(":{port}"), &format!(":{actual}"));
    assert!(healthcheck(&url), "healthcheck against {url}");
    assert!(dir.join("flatmesh.sqlite3").exists(), "no store in {dir:?}");
    // The README's "SQLite index (WAL)": the write-ahead log sits beside it while it runs.
    assert!(
        dir.join("flatmesh.sqlite3-wal").exists(),
        "no WAL in {dir:?}"
    );
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!healthcheck(&url), "healthcheck passes with no server");

    // The build stage's awk lists Cargo.toml's [[bench]] names, one stub each.
    let build_runs: String = build
        .iter()
        .filter(|(i, _)| i == "RUN")
        .map(|(_, a)| a.as_str())
        .collect();
    let program = build_runs.split("awk '").nth(1).unwrap();
    let program = program.split("' Cargo.toml").next().unwrap();
    let out = std::process::Command::new("awk")
        .args([program, "Cargo.toml"])
        .output()
        .unwrap();
    let listed: BTreeSet<String> = String::from_utf8(out.stdout)
        .unwrap()
        .split_whitespace()
        .map(str::to_string)
        .collect();
    let cargo = std::fs::read_to_string("Cargo.toml").unwrap();
    let benches: BTreeSet<String> = cargo
        .split("[[bench]]")
        .skip(1)
        .map(|b| {
            let line = b
                .lines()
                .find(|l| l.trim_start().starts_with("name"))
                .unwrap();
            line.split('"').nth(1).unwrap().to_string()
        })
        .collect();
    assert!(!benches.is_empty());
    assert_eq!(listed, benches);
}
