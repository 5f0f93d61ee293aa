//! A throwaway PostgreSQL server for the tests: Debian's `postgresql` package (`initdb` and
//! `pg_ctl`) into a temporary directory, on 127.0.0.1 at a free port, trust authentication;
//! stopped (and removed) on drop. PostgreSQL refuses to run as root: as root it runs as the
//! `postgres` user the package creates.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// A running PostgreSQL server.
pub struct PgServer {
    dir: tempfile::TempDir,
    bin: PathBuf,
    port: u16,
    as_postgres: bool,
}

/// Where `initdb`, `pg_ctl` and `createdb` are: Debian's versioned directory (the newest), else
/// the directory `initdb` on PATH links to.
fn pg_bin_dir() -> Option<PathBuf> {
    let complete = |d: &Path| {
        ["initdb", "pg_ctl", "createdb"]
            .iter()
            .all(|t| d.join(t).is_file())
    };
    let mut versions: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|d| complete(d))
        .collect();
    versions.sort();
    if let Some(d) = versions.pop() {
        return Some(d);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .filter_map(|d| std::fs::canonicalize(d.join("initdb")).ok())
        .filter_map(|exe| exe.parent().map(Path::to_path_buf))
        .find(|d| complete(d))
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() == 0 }
}

impl PgServer {
    /// Starts a server, or explains why it cannot (PostgreSQL not installed) and returns
    /// `None`; under `CI` a missing PostgreSQL fails the test instead.
    pub fn start(test: &str) -> Option<PgServer> {
        let Some(bin) = pg_bin_dir() else {
            let why = "PostgreSQL (initdb, pg_ctl) is not installed: apt-get install postgresql";
            assert!(std::env::var_os("CI").is_none(), "{test}: {why}");
            eprintln!("skipping {test}: {why}");
            return None;
        };
        let dir = tempfile::Builder::new()
            .prefix("l3-pg-")
            .tempdir()
            .expect("temporary directory");
        let as_postgres = is_root();
        if as_postgres {
            let ok = Command::new("chown")
                .args(["-R", "postgres:postgres"])
                .arg(dir.path())
                .status()
                .expect("chown")
                .success();
            assert!(ok, "chown of {} to postgres", dir.path().display());
        }
        let port = free_port();
        let server = PgServer {
            dir,
            bin,
            port,
            as_postgres,
        };
        let data = server.data_dir();
        server.run(
            "initdb",
            &[
                "-D".as_ref(),
                data.as_os_str(),
                "-A".as_ref(),
                "trust".as_ref(),
                "-U".as_ref(),
                "postgres".as_ref(),
                "-E".as_ref(),
                "UTF8".as_ref(),
                "--no-sync".as_ref(),
            ],
        );
        let opts = format!(
            "-h 127.0.0.1 -p {port} -k {} -F -c max_connections=200 -c fsync=off",
            server.dir.path().display()
        );
        let log = server.dir.path().join("postgres.log");
        server.run(
            "pg_ctl",
            &[
                "-D".as_ref(),
                data.as_os_str(),
                "-o".as_ref(),
                opts.as_ref(),
                "-l".as_ref(),
                log.as_os_str(),
                "-w".as_ref(),
                "start".as_ref(),
            ],
        );
        Some(server)
    }

    fn data_dir(&self) -> PathBuf {
        self.dir.path().join("data")
    }

    fn run(&self, tool: &str, args: &[&std::ffi::OsStr]) {
        let exe = self.bin.join(tool);
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        let out = cmd
            .args(args)
            .current_dir(self.dir.path())
            .stdin(Stdio::null())
            .output()
            .unwrap_or_else(|e| panic!("{}: {e}", exe.display()));
        assert!(
            out.status.success(),
            "{tool} failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// The URL of the server's `postgres` database.
    pub fn url(&self) -> String {
        format!("postgres://postgres@127.0.0.1:{}/postgres", self.port)
    }

    /// The server's directory (its log is `postgres.log` there).
    pub fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for PgServer {
    fn drop(&mut self) {
        let data = self.data_dir();
        let exe = self.bin.join("pg_ctl");
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        let _ = cmd
            .arg("-D")
            .arg(&data)
            .args(["-m", "immediate", "-w", "stop"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// The database the service tests run against: `None` for the default (SQLite in the test's
/// data directory); with `L3_TEST_BACKEND=postgres`, a new database on a PostgreSQL server
/// shared by the test binary. That server is started on first use and stopped (its directory
/// removed) by a watchdog once the test process has exited. One database per data directory,
/// so a restart on the same directory finds its state.
pub fn test_database_url(data: &Path) -> Option<String> {
    match std::env::var("L3_TEST_BACKEND").as_deref() {
        Ok("postgres") => {}
        Ok("sqlite") | Err(_) => return None,
        Ok(other) => panic!("L3_TEST_BACKEND={other:?}: sqlite or postgres"),
    }
    static SHARED: std::sync::OnceLock<(u16, PathBuf)> = std::sync::OnceLock::new();
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    static BY_DIR: std::sync::Mutex<Vec<(PathBuf, String)>> = std::sync::Mutex::new(Vec::new());
    let mut by_dir = BY_DIR.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((_, url)) = by_dir.iter().find(|(d, _)| d == data) {
        return Some(url.clone());
    }
    let (port, bin) = SHARED.get_or_init(|| {
        let server = PgServer::start("L3_TEST_BACKEND=postgres")
            .expect("L3_TEST_BACKEND=postgres needs PostgreSQL (initdb, pg_ctl) installed");
        let (port, bin) = (server.port, server.bin.clone());
        // hand the server to a watchdog that outlives this process
        let dir = server.dir.path().to_path_buf();
        let stop = format!(
            "(while kill -0 {pid} 2>/dev/null; do sleep 1; done; {runas} '{pg_ctl}' -D '{data}' -m immediate -w stop; rm -rf '{dir}') >/dev/null 2>&1 &",
            pid = std::process::id(),
            runas = if server.as_postgres { "runuser -u postgres --" } else { "" },
            pg_ctl = bin.join("pg_ctl").display(),
            data = server.data_dir().display(),
            dir = dir.display(),
        );
        // the shell starts the watchdog in the background and returns
        let started = Command::new("sh")
            .args(["-c", &stop])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .expect("start the PostgreSQL watchdog");
        assert!(started.success(), "the PostgreSQL watchdog did not start");
        // the watchdog owns the server and its directory now
        std::mem::forget(server);
        (port, bin)
    });
    let name = format!(
        "l3_test_{}_{}",
        std::process::id(),
        NEXT.fetch_add(1, std::sync::atomic::Ordering::SeqCst)
    );
    let out = Command::new(bin.join("createdb"))
        .args([
            "-h",
            "127.0.0.1",
            "-p",
            &port.to_string(),
            "-U",
            "postgres",
            &name,
        ])
        .output()
        .expect("createdb");
    assert!(
        out.status.success(),
        "createdb {name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let url = format!("postgres://postgres@127.0.0.1:{port}/{name}");
    by_dir.push((data.to_path_buf(), url.clone()));
    Some(url)
}
