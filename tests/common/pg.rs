//! A throwaway PostgreSQL cluster for tests: `initdb` in a temporary directory, the server on
//! a free loopback port with its socket in that directory, trust authentication, no fsync;
//! stopped and removed on drop. As root (CI containers) the server runs as the `postgres`
//! user, since PostgreSQL refuses to run as root. Without PostgreSQL's binaries the tests
//! say so and skip, except under `CI=true`, where `.ci/run` installs them.

use std::path::{Path, PathBuf};
use std::process::Command;

pub struct PgCluster {
    dir: PathBuf,
    bin: PathBuf,
    as_postgres: bool,
    /// The server's port on 127.0.0.1.
    pub port: u16,
}

/// The directory holding `initdb`, `pg_ctl` and `createdb`: `initdb`'s on PATH, else Debian's
/// newest /usr/lib/postgresql/*/bin.
fn pg_bin() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("PATH") {
        for d in std::env::split_paths(&path) {
            // Follow a link (/usr/local/bin/initdb → …/postgresql/15/bin) to the directory
            // with the other tools (createdb).
            if let Ok(real) = std::fs::canonicalize(d.join("initdb")) {
                let dir = real.parent()?.to_path_buf();
                if dir.join("pg_ctl").is_file() && dir.join("createdb").is_file() {
                    return Some(dir);
                }
            }
        }
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
        .filter(|d| d.join("initdb").is_file())
        .collect();
    found.sort_by_key(|d| {
        d.parent()
            .and_then(|v| v.file_name())
            .and_then(|v| v.to_str())
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or(0)
    });
    found.pop()
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

impl PgCluster {
    /// Start a cluster, or None (said on stderr) when PostgreSQL is not installed.
    pub fn start(what: &str) -> Option<PgCluster> {
        let Some(bin) = pg_bin() else {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "PostgreSQL (initdb, pg_ctl) is missing although CI=true: .ci/run installs it"
            );
            eprintln!(
                "SKIPPED ({what}): PostgreSQL's initdb and pg_ctl are not installed, so the \
                 PostgreSQL checks did not run"
            );
            return None;
        };
        let as_postgres = unsafe { libc::geteuid() } == 0;
        let dir = std::env::temp_dir().join(format!(
            "flatmesh-pg-{}-{}",
            std::process::id(),
            uuid_like()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        if as_postgres {
            let st = Command::new("chown")
                .args(["postgres:", dir.to_str().unwrap()])
                .status()
                .unwrap();
            assert!(
                st.success(),
                "chown of {} to postgres failed",
                dir.display()
            );
        }
        let mut c = PgCluster {
            dir,
            bin,
            as_postgres,
            port: 0,
        };
        let data = c.dir.join("data");
        c.run(
            "initdb",
            &[
                "-D",
                data.to_str().unwrap(),
                "-U",
                "flatmesh",
                "--auth=trust",
                "-E",
                "UTF8",
                "--no-sync",
            ],
        );
        // A port may be taken between choosing and binding: try a few.
        for _ in 0..5 {
            c.port = free_port();
            // FLATMESH_PG_OPTS: extra server options (say `-c log_min_duration_statement=5`
            // to see slow statements; the log is copied to FLATMESH_PG_LOG when set).
            if c.try_start() {
                return Some(c);
            }
        }
        panic!(
            "PostgreSQL did not start; its log: {}",
            std::fs::read_to_string(c.dir.join("server.log")).unwrap_or_default()
        );
    }

    /// The server's options (port, socket directory, the speed settings of a throwaway).
    fn server_opts(&self) -> String {
        format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=off \
                 -c synchronous_commit=off -c full_page_writes=off -c max_connections=200 {}",
            self.port,
            self.dir.display(),
            std::env::var("FLATMESH_PG_OPTS").unwrap_or_default()
        )
    }

    /// Stop the server (its data stays): for tests of what happens while the database is away.
    pub fn stop(&self) {
        let data = self.dir.join("data");
        self.run(
            "pg_ctl",
            &["-D", data.to_str().unwrap(), "-m", "fast", "-w", "stop"],
        );
    }

    /// `pg_ctl start` on this cluster's port and directory; whether it started.
    fn try_start(&self) -> bool {
        let (data, log, opts) = (
            self.dir.join("data"),
            self.dir.join("server.log"),
            self.server_opts(),
        );
        self.try_run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-o",
                &opts,
                "-l",
                log.to_str().unwrap(),
                "-w",
                "start",
            ],
        )
    }

    /// Start the server again after [`PgCluster::stop`], on the same port.
    pub fn start_again(&self) {
        assert!(self.try_start(), "PostgreSQL did not start again");
    }

    fn command(&self, tool: &str, args: &[&str]) -> Command {
        let exe = self.bin.join(tool);
        if self.as_postgres {
            let mut cmd = Command::new("runuser");
            cmd.args(["-u", "postgres", "--"]).arg(exe).args(args);
            cmd
        } else {
            let mut cmd = Command::new(exe);
            cmd.args(args);
            cmd
        }
    }

    fn try_run(&self, tool: &str, args: &[&str]) -> bool {
        let out = self.command(tool, args).output().unwrap();
        out.status.success()
    }

    fn run(&self, tool: &str, args: &[&str]) {
        let out = self.command(tool, args).output().unwrap();
        assert!(
            out.status.success(),
            "{tool} failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// A new empty database; its URL.
    pub fn database(&self, name: &str) -> String {
        self.run(
            "createdb",
            &[
                "-h",
                "127.0.0.1",
                "-p",
                &self.port.to_string(),
                "-U",
                "flatmesh",
                name,
            ],
        );
        self.url(name)
    }

    /// The URL of database `name`.
    pub fn url(&self, name: &str) -> String {
        format!("postgres://flatmesh@127.0.0.1:{}/{name}", self.port)
    }

    /// The data directory (for tests that look at the server's files).
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for PgCluster {
    fn drop(&mut self) {
        if let Ok(to) = std::env::var("FLATMESH_PG_LOG") {
            let _ = std::fs::copy(self.dir.join("server.log"), to);
        }
        let data = self.dir.join("data");
        let _ = self
            .command(
                "pg_ctl",
                &["-D", data.to_str().unwrap(), "-m", "immediate", "stop"],
            )
            .output();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A short random-enough suffix (time and a counter), without another dependency.
fn uuid_like() -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("{t:x}-{}", N.fetch_add(1, Ordering::Relaxed))
}
