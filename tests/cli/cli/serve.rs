//! `l3 serve`: its bind and data-dir flags, bad configuration values and failed starts.

use std::path::Path;
use std::process::Command;

/// `l3 serve --bind ADDR --data-dir DIR` listens where the flags say and keeps its database
/// in that directory, over the configuration's defaults, a `--config` file and the `L3_*`
/// variables that name others.
#[test]
fn serve_takes_bind_and_data_dir_flags() {
    use std::io::{Read, Write};
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("served");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let bind = format!("127.0.0.1:{port}");
    let config = tmp.path().join("l3.toml");
    std::fs::write(
        &config,
        "[server]\nbind = \"127.0.0.1:1\"\n[data]\ndir = \"from-file\"\n",
    )
    .unwrap();
    let mut child = Command::new(env!("L3_BIN"))
        .args(["serve", "--config"])
        .arg(&config)
        .args(["--bind", &bind, "--data-dir"])
        .arg(&data)
        .env("L3_BIND", "127.0.0.1:2")
        .env("L3_DATA_DIR", tmp.path().join("from-env"))
        .env("L3_AUTO_TRAIN", "false")
        .env("L3_ISET_DIR", tmp.path().join("no-iset"))
        .current_dir(tmp.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawn l3 serve");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let answer = loop {
        let got = std::net::TcpStream::connect(&bind).and_then(|mut s| {
            s.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")?;
            let mut text = String::new();
            s.read_to_string(&mut text)?;
            Ok(text)
        });
        match got {
            Ok(text) => break text,
            Err(_) if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50))
            }
            Err(e) => {
                let _ = child.kill();
                panic!("l3 serve did not answer on {bind}: {e}");
            }
        }
    };
    let db = data.join("l3.sqlite").exists();
    let _ = child.kill();
    let _ = child.wait();
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    assert!(db, "no database in --data-dir");
    for other in ["data", "from-file", "from-env"] {
        assert!(!tmp.path().join(other).exists(), "{other} was used");
    }
}

/// A bad configuration value stops `l3 serve` with exit code 2 and a message naming it: the
/// variable, or the key and the file.
#[test]
fn serve_names_a_bad_configuration_value() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let (code, err) = serve_until_exit(d, &[], &[("L3_MAX_PIXELS", "lots")]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("L3_MAX_PIXELS=\"lots\" is not a valid number"),
        "{err}"
    );
    let config = d.join("bad.toml");
    std::fs::write(&config, "[server]\nmax_pixels = \"many\"\n").unwrap();
    let (code, err) = serve_until_exit(d, &["--config", config.to_str().unwrap()], &[]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("server.max_pixels") && err.contains("bad.toml"),
        "{err}"
    );
}

/// Runs `l3 serve` with `env` until it exits (it must, within 60 s); returns its exit code
/// and its standard error.
fn serve_until_exit(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("L3_BIN"));
    cmd.arg("serve")
        .args(args)
        .env("L3_AUTO_TRAIN", "false")
        .env("L3_ISET_DIR", dir.join("no-iset"))
        .env("L3_LOG_FORMAT", "text")
        .env("NO_COLOR", "1")
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("spawn l3 serve");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let status = loop {
        match child.try_wait().expect("wait for l3 serve") {
            Some(s) => break s,
            None if std::time::Instant::now() < deadline => {
                std::thread::sleep(std::time::Duration::from_millis(50))
            }
            None => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("l3 serve {args:?} did not exit");
            }
        }
    };
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut err);
    }
    (status.code(), err)
}

/// A start that fails is no usage error: a busy address and a database that cannot be opened
/// exit with code 1 (not 2) and say why, and a busy address leaves the data directory alone. A
/// database URL of no backend is a bad configuration value instead (code 2), shown without
/// its password.
#[test]
fn serve_start_failures_exit_1_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let bind = taken.local_addr().unwrap().to_string();
    let data = d.join("busy");
    let (code, err) = serve_until_exit(
        d,
        &["--bind", &bind, "--data-dir", data.to_str().unwrap()],
        &[],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains(&format!("cannot listen on {bind}")) && err.contains("--bind"),
        "{err}"
    );
    assert!(
        !data.exists(),
        "a start that cannot listen created {data:?}"
    );
    drop(taken);

    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    let data = d.join("db");
    let data_arg = ["--bind", &free, "--data-dir", data.to_str().unwrap()];
    // an unknown scheme
    let url = [("L3_DATABASE_URL", "mysql://l3:s3cret@db/l3")];
    let (code, err) = serve_until_exit(d, &data_arg, &url);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("database_url 'mysql://l3:***@db/l3'") && err.contains("postgres://"),
        "{err}"
    );
    assert!(!err.contains("s3cret"), "{err}");
    // a SQLite file that cannot be created (its directory does not exist)
    let (code, err) = serve_until_exit(
        d,
        &data_arg,
        &[("L3_DATABASE_URL", "sqlite:///nonexistent-dir/l3/l3.sqlite")],
    );
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("database"), "{err}");
}
