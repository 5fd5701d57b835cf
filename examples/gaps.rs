//! The longest stretch between two cancellation checks, per job kind, on a noisy saddle: what
//! bounds how far past its time limit a job can run (issue 20). Usage:
//! `cargo run --release --example gaps -- FACES KIND[:PARAMS_JSON] ...`, e.g.
//! `cargo run --release --example gaps -- 51000 'subdivide:{"levels":1}' fl-mesh`.
//! Prints per kind the run's seconds, the worst stretch, when it began and between which
//! progress stages, and how long rendering the artifacts took (not interruptible).
use flatmesh::algorithms::{Control, Progress};
use flatmesh::corpus::{Family, Procedural};
use flatmesh::jobs::{artifacts, Input, JobSpec};
use std::sync::Mutex;
use std::time::Instant;

struct Gaps {
    start: Instant,
    last: Mutex<(f64, String)>,
    worst: Mutex<(f64, f64, String)>,
    stage: Mutex<String>,
}
impl Control for Gaps {
    fn progress(&self, p: &Progress) {
        *self.stage.lock().unwrap() = format!("{} {}", p.stage, p.iteration);
    }
    fn cancelled(&self) -> bool {
        let now = self.start.elapsed().as_secs_f64();
        let stage = self.stage.lock().unwrap().clone();
        let mut last = self.last.lock().unwrap();
        let gap = now - last.0;
        let mut w = self.worst.lock().unwrap();
        if gap > w.0 {
            *w = (gap, last.0, format!("{} -> {}", last.1, stage));
        }
        *last = (now, stage);
        false
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let faces: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(51_000);
    let kinds: Vec<(String, serde_json::Value)> = args[2..]
        .iter()
        .map(|a| {
            let (k, p) = a.split_once(':').unwrap_or((a, "{}"));
            (k.to_string(), serde_json::from_str(p).unwrap())
        })
        .collect();
    let mesh = Procedural {
        family: Family::Saddle,
        faces,
        noise: 0.1,
    }
    .mesh();
    eprintln!("{} faces", mesh.triangles().len());
    let input = Input {
        mesh: mesh.clone(),
        reference: None,
    };
    for (k, p) in kinds {
        let spec = JobSpec::parse(&k, p.as_object().unwrap()).unwrap();
        let c = Gaps {
            start: Instant::now(),
            last: Mutex::new((0.0, "start".into())),
            worst: Mutex::new((0.0, 0.0, String::new())),
            stage: Mutex::new("start".into()),
        };
        let out = spec.run(&input, &c).unwrap();
        let ran = c.start.elapsed().as_secs_f64();
        c.cancelled();
        let t = Instant::now();
        let r = artifacts::render(spec.kind(), &input.mesh, &out, &[], ran);
        let render = t.elapsed().as_secs_f64();
        let w = c.worst.lock().unwrap();
        println!(
            "{k} {p}: run {ran:.2}s, worst gap {:.2}s at {:.2}s ({}), render {render:.2}s ({} artifacts)",
            w.0, w.1, w.2, r.artifacts.len()
        );
    }
}
