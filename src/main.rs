//! The `flatmesh` command line: the engine without a server.

use clap::{Parser, Subcommand};
use flatmesh::algorithms::{self, Control, Progress};
use flatmesh::io;
use flatmesh::jobs::{artifacts, Input, JobSpec, Kind};
use flatmesh::report::Report;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Measure and optimise the flattenability of triangle meshes.
#[derive(Parser)]
#[command(name = "flatmesh", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Report the flattenability ϖ = |2π − θ| of a mesh (OBJ, OFF, glTF or GLB).
    ///
    /// Exit status: 0 on success, 2 when the input is invalid (one line on stderr names the
    /// problem), 1 on other failures.
    Report {
        /// The mesh file; the format is taken from the extension, else from the content.
        mesh: PathBuf,
        /// Print one JSON document (summary, patches, histogram, per-vertex ϖ) on stdout.
        #[arg(long)]
        json: bool,
        /// Also write the mesh as GLB with ϖ as the `_FLATTENABILITY` attribute and a heat map.
        #[arg(long, value_name = "OUT.glb")]
        glb: Option<PathBuf>,
        /// The heat map's range: `data` (1st–99th percentile of this mesh's ϖ) or `fixed`
        /// (1e-6–1 rad, the same for every mesh, to compare meshes).
        #[arg(long, default_value = "data", value_parser = ["data", "fixed"])]
        heatmap: String,
    },
    /// Run a job locally, without a server, and write its results into DIR.
    ///
    /// DIR receives the files a service job stores: report.json (the flattenability report of
    /// the output mesh, the job's own figures under "job"), mesh.glb, mesh.gltf and mesh.obj;
    /// `flatten`, and the kinds that change the mesh (their output flattened with flatten's
    /// defaults), also write patterns.json, patterns.svg, patterns.dxf (AAMA) and
    /// patterns-plain.dxf, and their mesh carries the pattern as texture coordinates. Progress
    /// goes to stderr. Exit status: 0 on success, 2 for invalid input or parameters, 3 when an
    /// optimiser ran and wrote its best result but did not converge (one line on stderr gives
    /// the ϖ_max reached, why it stopped and the stuck vertices), 1 on other failures.
    ///
    /// The kinds and their parameters follow.
    Run {
        /// Job kind.
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(Kind::names()))]
        kind: String,
        /// The input mesh.
        mesh: PathBuf,
        /// Output directory (created if missing).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// A parameter, KEY=VALUE; VALUE is read as JSON when it parses, else as a string.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// A reference body mesh, for kinds that use one.
        #[arg(long, value_name = "MESH")]
        reference: Option<PathBuf>,
        /// subdivide: number of levels (same as --set levels=N).
        #[arg(long, value_name = "N")]
        levels: Option<usize>,
        /// subdivide: interpolation curves of boundary edges, a JSON file
        /// `{"curves": [{"edge": [a, b], "points": [[x, y, z], ...]}, ...]}` (a, b input vertex
        /// indices; the polyline runs from a to b).
        #[arg(long, value_name = "CURVES.json")]
        curves: Option<PathBuf>,
    },
    /// Write the procedural test meshes (known answers) as OBJ files into DIR.
    Fixtures {
        /// Output directory (created if missing).
        dir: PathBuf,
    },
    /// Run the REST job service (see openapi.yaml, `GET /openapi.yaml`).
    Serve(flatmesh::service::Config),
    /// Talk to a running service: upload, submit, wait, download, health.
    Client(flatmesh::service::client::ClientArgs),
}

/// The kinds of the registry with their parameters, for `run --help`.
fn kinds_help() -> String {
    let mut out = String::from("Kinds:\n");
    for k in Kind::ALL {
        let reference = match k.reference() {
            flatmesh::jobs::Reference::None => "",
            flatmesh::jobs::Reference::Optional => " Takes --reference (optional).",
            flatmesh::jobs::Reference::Required => " Needs --reference.",
        };
        out += &format!(
            "\n  {}: {}.{reference}\n    parameters: {}.\n",
            k.name(),
            k.about(),
            k.params_help()
        );
    }
    out
}

fn main() -> ExitCode {
    use clap::{CommandFactory, FromArgMatches};
    flatmesh::io::install_quiet_panic_hook();
    let cmd = Cli::command().mut_subcommand("run", |c| c.after_long_help(kinds_help()));
    let cli = match Cli::from_arg_matches(&cmd.get_matches()) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    match cli.command {
        Command::Report {
            mesh,
            json,
            glb,
            heatmap,
        } => {
            let scale = if heatmap == "fixed" {
                io::gltf::HeatmapScale::Fixed
            } else {
                io::gltf::HeatmapScale::Data
            };
            report(&mesh, json, glb.as_deref(), scale)
        }
        Command::Run {
            kind,
            mesh,
            out,
            set,
            reference,
            levels,
            curves,
        } => run(
            &kind,
            &mesh,
            &out,
            &set,
            reference.as_deref(),
            levels,
            curves.as_deref(),
        ),
        Command::Serve(cfg) => match flatmesh::service::serve(cfg) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("flatmesh serve: {e}");
                ExitCode::FAILURE
            }
        },
        Command::Client(args) => match flatmesh::service::client::run(args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("flatmesh client: {e}");
                ExitCode::FAILURE
            }
        },
        Command::Fixtures { dir } => match flatmesh::fixtures::write_all(&dir) {
            Ok(paths) => {
                for p in paths {
                    println!("{}", p.display());
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("flatmesh: cannot write fixtures to {}: {e}", dir.display());
                ExitCode::FAILURE
            }
        },
    }
}

/// Load a mesh or explain (exit 2 for invalid content, 1 when unreadable).
fn load(path: &Path) -> Result<(flatmesh::mesh::Mesh, Vec<flatmesh::mesh::Warning>), ExitCode> {
    io::load_path(path).map_err(|e| match e {
        io::ReadError::Io(e) => {
            eprintln!("flatmesh: cannot read {e}");
            ExitCode::FAILURE
        }
        e => {
            eprintln!("flatmesh: invalid mesh {}: {e}", path.display());
            ExitCode::from(2)
        }
    })
}

fn report(path: &Path, json: bool, glb: Option<&Path>, scale: io::gltf::HeatmapScale) -> ExitCode {
    let (mesh, warnings) = match load(path) {
        Ok(m) => m,
        Err(code) => return code,
    };
    let report = Report::compute(&mesh, &warnings);
    if let Some(out) = glb {
        let varpi: Vec<f64> = report.per_vertex.iter().map(|v| v.flattenability).collect();
        let bytes = io::gltf::write_glb_scaled(&mesh, Some(&varpi), &[], scale);
        if let Err(e) = std::fs::write(out, bytes) {
            eprintln!("flatmesh: cannot write {}: {e}", out.display());
            return ExitCode::FAILURE;
        }
    }
    if json {
        let stdout = std::io::stdout();
        let mut lock = std::io::BufWriter::new(stdout.lock());
        if let Err(e) = serde_json::to_writer(&mut lock, &report) {
            eprintln!("flatmesh: cannot write JSON: {e}");
            return ExitCode::FAILURE;
        }
        use std::io::Write;
        let _ = writeln!(lock);
    } else {
        print!("{}", report.summary());
    }
    ExitCode::SUCCESS
}

/// `--set KEY=VALUE` pairs as a JSON object.
fn parse_sets(sets: &[String]) -> Result<serde_json::Map<String, serde_json::Value>, String> {
    let mut params = serde_json::Map::new();
    for s in sets {
        let (k, v) = s
            .split_once('=')
            .ok_or_else(|| format!("--set {s:?}: expected KEY=VALUE"))?;
        let k = k.trim();
        if k.is_empty() {
            return Err(format!("--set {s:?}: empty key"));
        }
        let value = serde_json::from_str(v).unwrap_or_else(|_| serde_json::Value::String(v.into()));
        params.insert(k.to_string(), value);
    }
    Ok(params)
}

/// Progress on stderr, at most a few lines a second.
struct StderrProgress {
    last: std::sync::Mutex<Option<Instant>>,
}

impl Control for StderrProgress {
    fn progress(&self, p: &Progress) {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if last.is_some_and(|t| t.elapsed() < Duration::from_millis(200)) {
            return;
        }
        *last = Some(Instant::now());
        let mut line = format!("{} {}", p.stage, p.iteration);
        if let Some(w) = p.max_flattenability {
            line += &format!("  ϖ_max {w:.3e}");
        }
        if let Some(s) = p.step_norm {
            line += &format!("  |δ| {s:.3e}");
        }
        eprintln!("{line}");
    }
    fn cancelled(&self) -> bool {
        false
    }
}

fn run(
    kind: &str,
    mesh: &Path,
    out: &Path,
    sets: &[String],
    reference: Option<&Path>,
    levels: Option<usize>,
    curves: Option<&Path>,
) -> ExitCode {
    let params = match parse_sets(sets).and_then(|p| subdivide_options(kind, p, levels, curves)) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("flatmesh: {e}");
            return ExitCode::from(2);
        }
    };
    let spec = match JobSpec::parse(kind, &params)
        .and_then(|s| s.check_reference(reference.is_some()).map(|_| s))
    {
        Ok(s) => s,
        Err(e) => {
            eprintln!("flatmesh: {e}");
            return ExitCode::from(2);
        }
    };
    let (mesh, warnings) = match load(mesh) {
        Ok(m) => m,
        Err(code) => return code,
    };
    let reference = match reference.map(load).transpose() {
        Ok(r) => r.map(|r| r.0),
        Err(code) => return code,
    };
    let input = Input { mesh, reference };
    let control = StderrProgress {
        last: std::sync::Mutex::new(None),
    };
    let start = Instant::now();
    let outcome = match spec.run(&input, &control) {
        Ok(o) => o,
        Err(e @ (algorithms::AlgoError::InvalidParam { .. } | algorithms::AlgoError::Input(_))) => {
            eprintln!("flatmesh: {e}");
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("flatmesh: {kind} failed: {e}");
            return ExitCode::FAILURE;
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    for w in outcome.figures.warnings() {
        eprintln!("flatmesh: warning: {w}");
    }
    for w in outcome.shape.iter().flat_map(|s| &s.warnings) {
        eprintln!("flatmesh: warning: {w}");
    }
    // Seams the file did not name change what "flattenable" means for this output: say so.
    if let flatmesh::jobs::Figures::FlMesh(s) = &outcome.figures {
        if s.patches.source == "uv" || s.patches.uv_seam_edges > 0 {
            eprintln!("flatmesh: patches: {}", s.patches.reason);
        }
    }
    for w in &outcome.pattern_warnings {
        eprintln!("flatmesh: warning: patterns of the output: {w}");
    }
    if let Some(why) = &outcome.patterns_unavailable {
        eprintln!("flatmesh: warning: the output could not be flattened: {why}");
    }
    if let Err(e) = std::fs::create_dir_all(out) {
        eprintln!("flatmesh: cannot create {}: {e}", out.display());
        return ExitCode::FAILURE;
    }
    let rendered = artifacts::render(spec.kind(), &input.mesh, &outcome, &warnings, seconds);
    for a in rendered.artifacts {
        let path = out.join(&a.name);
        if let Err(e) = std::fs::write(&path, &a.bytes) {
            eprintln!("flatmesh: cannot write {}: {e}", path.display());
            return ExitCode::FAILURE;
        }
        println!("{}", path.display());
    }
    if outcome.figures.converged() == Some(false) {
        eprintln!(
            "flatmesh: {}",
            not_converged_line(kind, &outcome.figures, rendered.max_flattenability)
        );
        return ExitCode::from(NOT_CONVERGED);
    }
    ExitCode::SUCCESS
}

/// Exit status of `run` when the job ran and wrote its results but did not converge.
const NOT_CONVERGED: u8 = 3;

/// One line for stderr: the ϖ_max reached (measured on the output), why the run ended and the
/// stuck vertices.
fn not_converged_line(kind: &str, figures: &flatmesh::jobs::Figures, varpi_max: f64) -> String {
    let stuck = figures.stuck_vertices();
    let shown = stuck
        .iter()
        .take(10)
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "{kind} did not converge: ϖ_max {varpi_max:.3e} rad reached ({}); {} stuck vertices{}{}",
        figures.stop_reason().unwrap_or("unknown"),
        stuck.len(),
        if stuck.is_empty() { "" } else { ": " },
        if stuck.len() > 10 {
            format!("{shown}, …")
        } else {
            shown
        }
    )
}

/// `--levels` and `--curves` (subdivide only) folded into the parameters.
fn subdivide_options(
    kind: &str,
    mut params: serde_json::Map<String, serde_json::Value>,
    levels: Option<usize>,
    curves: Option<&Path>,
) -> Result<serde_json::Map<String, serde_json::Value>, String> {
    if kind != "subdivide" {
        if levels.is_some() {
            return Err(format!("--levels is for `subdivide`, not `{kind}`"));
        }
        if curves.is_some() {
            return Err(format!("--curves is for `subdivide`, not `{kind}`"));
        }
        return Ok(params);
    }
    if let Some(n) = levels {
        if params.contains_key("levels") {
            return Err("levels given twice (--levels and --set levels=…)".into());
        }
        params.insert("levels".into(), n.into());
    }
    if let Some(path) = curves {
        if params.contains_key("curves") {
            return Err("curves given twice (--curves and --set curves=…)".into());
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not JSON: {e}", path.display()))?;
        let list = match v {
            serde_json::Value::Object(mut o) => match o.remove("curves") {
                Some(l) if o.is_empty() => l,
                Some(_) => {
                    return Err(format!(
                        "{}: unknown member(s) beside `curves`: {}",
                        path.display(),
                        o.keys().cloned().collect::<Vec<_>>().join(", ")
                    ))
                }
                None => return Err(format!("{}: no `curves` member", path.display())),
            },
            serde_json::Value::Array(a) => serde_json::Value::Array(a),
            _ => {
                return Err(format!(
                    "{}: expected {{\"curves\": [...]}}",
                    path.display()
                ))
            }
        };
        params.insert("curves".into(), list);
    }
    Ok(params)
}
