//! The console at `/`: served as small, self-contained files without a token, and used end to
//! end in headless Chromium driven through chromedriver (WebDriver): the status, a simulated
//! RGBW DNG rendered with its light and timings (and taken off the page by a failed render), a
//! tiny training job to 100 % (its card kept, focus and all, through a refresh), an evaluation's
//! figure, the job's table activated from its card, a light added and removed. The browser test prints `skipped:` without Chromium or
//! chromedriver (fails under `CI`); it writes screenshots to a temporary folder, kept (and its
//! path printed) when the test fails or `L3_KEEP_SCREENSHOTS` is set, else removed.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value, json};

use crate::service_support::*;

const TOKEN: &str = "console-secret";

/// The screenshots' folder: removed after a passing run; kept, and its path printed, after a
/// failing one or with `L3_KEEP_SCREENSHOTS` set.
struct Shots(Option<tempfile::TempDir>);

impl Shots {
    fn path(&self) -> &Path {
        self.0.as_ref().map(|d| d.path()).unwrap()
    }
}

impl Drop for Shots {
    fn drop(&mut self) {
        let keep = std::thread::panicking() || std::env::var_os("L3_KEEP_SCREENSHOTS").is_some();
        if keep && let Some(dir) = self.0.take() {
            println!("console screenshots in {}", dir.keep().display());
        }
    }
}

/// A config whose mutating routes need [`TOKEN`].
fn config_with_token(d: &Path) -> l3::service::ServiceConfig {
    let mut cfg = test_config(d);
    cfg.server.bearer_token = TOKEN.into();
    cfg
}

/// The hosts of every `http://` or `https://` URL in `text`.
fn absolute_url_hosts(text: &str) -> Vec<String> {
    let mut hosts = Vec::new();
    for scheme in ["http://", "https://"] {
        for (at, _) in text.match_indices(scheme) {
            let rest = &text[at + scheme.len()..];
            let end = rest
                .find(|c: char| c == '/' || c == '"' || c == '\'' || c == ')' || c.is_whitespace())
                .unwrap_or(rest.len());
            hosts.push(rest[..end].to_string());
        }
    }
    hosts
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_is_small_self_contained_and_needs_no_token() {
    let tmp = tempfile::tempdir().unwrap();
    let (server, _) = server_with_table(tmp.path(), Some(config_with_token(tmp.path()))).await;
    let c = client();
    let mut total = 0;
    let mut page = String::new();
    for (path, ctype) in [
        ("/", "text/html; charset=utf-8"),
        ("/console/console.css", "text/css; charset=utf-8"),
        ("/console/console.js", "text/javascript; charset=utf-8"),
    ] {
        // no Authorization header: the console's files are GETs
        let r = c.get(url(&server, path)).send().await.unwrap();
        assert_eq!(r.status(), 200, "{path}");
        assert_eq!(r.headers()["content-type"], ctype, "{path}");
        assert_eq!(r.headers()["cache-control"], "no-cache", "{path}");
        let etag = r.headers()["etag"].to_str().unwrap().to_string();
        if path == "/" {
            let csp = r.headers()["content-security-policy"].to_str().unwrap();
            assert!(csp.starts_with("default-src 'self'"), "{csp}");
        }
        let text = r.text().await.unwrap();
        total += text.len();
        let foreign = absolute_url_hosts(&text);
        assert!(foreign.is_empty(), "{path} names other hosts: {foreign:?}");
        if path == "/" {
            page = text;
        }
        let again = c
            .get(url(&server, path))
            .header("if-none-match", &etag)
            .send()
            .await
            .unwrap();
        assert_eq!(again.status(), 304, "{path} revalidated with its ETag");
    }
    assert!(
        page.contains("/console/console.css") && page.contains("/console/console.js"),
        "the page loads its assets"
    );
    println!("console: {total} bytes in 3 files");
    assert!(total < 150 * 1024, "the console is {total} bytes");
    // the API the page calls still wants the token for what changes something
    let r = c
        .put(url(&server, "/v1/illuminants/Warm"))
        .json(&json!({ "cct": 3000 }))
        .send()
        .await
        .unwrap();
    problem(r, 401, "unauthorized").await;
    server.shutdown().await.unwrap();
}

// ---------------------------------------------------------------- the browser

/// `name` on the PATH (or at an absolute path).
fn which(name: &str) -> Option<PathBuf> {
    let p = Path::new(name);
    if p.is_absolute() {
        return p.is_file().then(|| p.to_path_buf());
    }
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// Chromium and chromedriver (`L3_CHROMIUM`, `L3_CHROMEDRIVER`, else on the PATH), or why not.
fn browser() -> Result<(PathBuf, PathBuf), String> {
    let find = |var: &str, names: &[&str]| {
        std::env::var(var)
            .ok()
            .and_then(|v| which(&v))
            .or_else(|| names.iter().find_map(|n| which(n)))
            .ok_or_else(|| {
                format!(
                    "no {} (install Debian's chromium and chromium-driver, or set {var})",
                    names[0]
                )
            })
    };
    Ok((
        find(
            "L3_CHROMIUM",
            &["chromium", "chromium-browser", "google-chrome"],
        )?,
        find("L3_CHROMEDRIVER", &["chromedriver"])?,
    ))
}

/// chromedriver on a free loopback port, killed when dropped.
struct Driver {
    child: Child,
    url: String,
}

impl Driver {
    async fn start(bin: &Path, log: &Path) -> Driver {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = Command::new(bin)
            .arg(format!("--port={port}"))
            .arg(format!("--log-path={}", log.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromedriver");
        let driver = Driver {
            child,
            url: format!("http://127.0.0.1:{port}"),
        };
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let up = reqwest::get(format!("{}/status", driver.url)).await;
            if up.is_ok_and(|r| r.status().is_success()) {
                return driver;
            }
            assert!(Instant::now() < deadline, "chromedriver did not start");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A WebDriver session of headless Chromium, with the flags it needs on a closed network.
async fn session(driver: &Driver, chromium: &Path, profile: &Path) -> Client {
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
        "--window-size=1360,900",
    ];
    let mut args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
    args.push(format!("--user-data-dir={}", profile.display()));
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({ "binary": chromium.to_string_lossy(), "args": args }),
    );
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(caps)
        .connect(&driver.url)
        .await
        .expect("a Chromium session")
}

/// Polls `script` (a function body returning a value) until it returns `true`.
async fn wait_js(b: &Client, what: &str, script: &str, secs: u64) {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if b.execute(script, vec![]).await.unwrap() == Value::Bool(true) {
            return;
        }
        if Instant::now() > deadline {
            let msgs = b
                .execute(
                    "return [...document.querySelectorAll('.msg')].map(m => m.id + ': ' + m.textContent).join(' | ')",
                    vec![],
                )
                .await
                .unwrap();
            panic!("waited {secs} s for {what}; the page's messages: {msgs}");
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

async fn text(b: &Client, css: &str) -> String {
    b.find(Locator::Css(css))
        .await
        .unwrap()
        .text()
        .await
        .unwrap()
}

async fn set_field(b: &Client, css: &str, value: &str) {
    let e = b.find(Locator::Css(css)).await.unwrap();
    e.clear().await.unwrap();
    e.send_keys(value).await.unwrap();
}

async fn click(b: &Client, css: &str) {
    b.find(Locator::Css(css))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
}

async fn screenshot(b: &Client, dir: &Path, name: &str) {
    let png = b.screenshot().await.unwrap();
    std::fs::write(dir.join(name), png).unwrap();
}

/// A simulated RGBW DNG: `l3 simulate`'s Macbeth chart under tungsten, with its AsShotNeutral.
fn simulated_dng(d: &Path) -> PathBuf {
    let out = Command::new(env!("L3_BIN"))
        .args(["simulate", "--scene", "macbeth", "--illuminant", "Tungsten"])
        .args(["--seed", "3", "--out", "sim"])
        .current_dir(d)
        .output()
        .expect("run l3 simulate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    d.join("sim/mosaic.dng")
}

async fn render_a_dng(b: &Client, dng: &Path, shots: &Path) {
    let file = b.find(Locator::Css("#render-file")).await.unwrap();
    file.send_keys(&dng.to_string_lossy()).await.unwrap();
    click(b, "#render-go").await;
    wait_js(
        b,
        "the rendered image",
        "const i = document.querySelector('#render-img'); \
         return !document.querySelector('#render-figure').hidden && i.complete && i.naturalWidth > 0",
        120,
    )
    .await;
    let info = |key: &str| format!("#render-info dd[data-key=\"{key}\"]");
    let light = text(b, &info("x-l3-illuminant")).await;
    assert!(
        light.starts_with("cct:"),
        "the light from AsShotNeutral: {light}"
    );
    assert_eq!(
        text(b, &info("x-l3-illuminant-source")).await,
        "from the file's metadata"
    );
    for key in ["x-l3-decode-ms", "x-l3-render-ms", "x-l3-encode-ms"] {
        let t = text(b, &info(key)).await;
        assert!(t.ends_with(" ms"), "{key}: {t}");
    }
    let saturated = text(b, &info("x-l3-saturated-pixels")).await;
    assert!(saturated.parse::<u64>().is_ok(), "{saturated}");
    let link = b.find(Locator::Css("#render-download")).await.unwrap();
    assert!(
        link.attr("href")
            .await
            .unwrap()
            .unwrap()
            .starts_with("blob:")
    );
    assert_eq!(link.attr("download").await.unwrap().unwrap(), "mosaic.png");
    screenshot(b, shots, "console-render.png").await;
    // a failed render takes the previous one off the page: its image, values and download
    let bad = dng.with_file_name("broken.dng");
    std::fs::write(&bad, b"not a DNG").unwrap();
    let file = b.find(Locator::Css("#render-file")).await.unwrap();
    file.send_keys(&bad.to_string_lossy()).await.unwrap();
    click(b, "#render-go").await;
    wait_js(
        b,
        "the failed render's message, and the old render gone",
        "return document.querySelector('#render-msg').classList.contains('error') \
         && document.querySelector('#render-figure').hidden \
         && document.querySelector('#render-download').hidden \
         && document.querySelector('#render-info').children.length == 0",
        60,
    )
    .await;
}

async fn train_a_tiny_table(b: &Client, shots: &Path) -> String {
    click(b, "button[data-tab=\"jobs\"]").await;
    wait_js(
        b,
        "the illuminants",
        "return document.querySelectorAll('#job-lights input:checked').length == 2",
        30,
    )
    .await;
    for (css, v) in [
        ("#job-scenes", "4"),
        ("#job-scene-size", "48"),
        ("#job-levels", "10"),
        ("#job-chroma", "2"),
        ("#job-shards", "2"),
    ] {
        set_field(b, css, v).await;
    }
    // without the token the service refuses, and the page says so in words
    click(b, "#job-go").await;
    wait_js(
        b,
        "the refusal",
        "return document.querySelector('#job-msg').classList.contains('error')",
        30,
    )
    .await;
    let refusal = text(b, "#job-msg").await;
    assert!(
        refusal.starts_with("Unauthorized")
            && refusal.contains("Bearer")
            && refusal.contains("Token field"),
        "{refusal}"
    );
    set_field(b, "#token", TOKEN).await;
    click(b, "#job-go").await;
    wait_js(
        b,
        "the job at 100 %",
        "return !!document.querySelector('.job[data-status=\"succeeded\"] .bar[aria-valuenow=\"100\"]')",
        600,
    )
    .await;
    assert_eq!(
        text(b, ".job[data-status=\"succeeded\"] .pct").await,
        "100 %"
    );
    // a survey and an accumulation bar per shard, each full
    let shard_bars = b.find_all(Locator::Css(".job .shards .bar")).await.unwrap();
    assert_eq!(shard_bars.len(), 4);
    for bar in shard_bars {
        assert_eq!(bar.attr("aria-valuenow").await.unwrap().unwrap(), "100");
    }
    let id = b
        .find(Locator::Css(".job[data-status=\"succeeded\"]"))
        .await
        .unwrap()
        .attr("data-id")
        .await
        .unwrap()
        .unwrap();
    screenshot(b, shots, "console-jobs.png").await;
    // a refresh updates the cards in place: the same card, its button still focused
    let card = format!(".job[data-id=\"{id}\"]");
    b.execute(
        &format!(
            "const c = document.querySelector('{card}'); c.l3Mark = 1; \
             c.querySelector('.table button').focus(); \
             document.querySelector('[data-refresh=\"jobs\"]').click()"
        ),
        vec![],
    )
    .await
    .unwrap();
    tokio::time::sleep(Duration::from_millis(1500)).await;
    wait_js(
        b,
        "the same card, its button focused, after a refresh",
        &format!(
            "const c = document.querySelector('{card}'); \
             return c.l3Mark === 1 && document.activeElement === c.querySelector('.table button')"
        ),
        5,
    )
    .await;
    id
}

/// Activates the job's table from its card: the outcome on the card, which (like the header)
/// then marks that table active.
async fn activate_from_the_job_card(b: &Client, job: &str, shots: &Path) -> String {
    click(b, "button[data-tab=\"jobs\"]").await;
    let card = format!(".job[data-id=\"{job}\"]");
    let table = b
        .find(Locator::Css(&format!("{card} .table [data-id]")))
        .await
        .unwrap()
        .attr("data-id")
        .await
        .unwrap()
        .unwrap();
    click(b, &format!("{card} .table button:last-child")).await;
    wait_js(
        b,
        "the activation said on the job's card",
        &format!(
            "const c = document.querySelector('{card}'); \
             return c.querySelector('.table ~ .msg.ok') != null \
             && !c.querySelector('.table .tag.ok').hidden \
             && document.querySelector('#st-table').textContent == '{table}'"
        ),
        30,
    )
    .await;
    assert_eq!(
        text(b, &format!("{card} .table ~ .msg")).await,
        format!("{table} is now the active table.")
    );
    screenshot(b, shots, "console-activated.png").await;
    table
}

async fn evaluate(b: &Client, shots: &Path) {
    click(b, "button[data-tab=\"evals\"]").await;
    set_field(b, "#eval-exposure", "0.5").await;
    click(b, "#eval-go").await;
    wait_js(
        b,
        "the evaluation's figure",
        "const i = document.querySelector('#eval-figure'); \
         return !document.querySelector('#eval-view').hidden && i.complete && i.naturalWidth > 0",
        600,
    )
    .await;
    let info = text(b, "#eval-info").await;
    assert!(
        info.contains("Mean ΔE2000") && info.contains("× 0.5"),
        "{info}"
    );
    let json_link = b.find(Locator::Css("#eval-json")).await.unwrap();
    let href = json_link.attr("href").await.unwrap().unwrap();
    assert!(href.starts_with("/v1/evaluations/"), "{href}");
    screenshot(b, shots, "console-evaluation.png").await;
}

/// Adds a light from a colour temperature, finds it among the render's lights, removes it.
async fn add_and_remove_a_light(b: &Client, shots: &Path) {
    click(b, "button[data-tab=\"lights\"]").await;
    set_field(b, "#light-name", "Studio4700").await;
    set_field(b, "#light-cct", "4700").await;
    click(b, "#light-go").await;
    let row = "#lights-body tr:has(button.danger)";
    wait_js(
        b,
        "the new light",
        &format!("return !!document.querySelector('{row}')"),
        30,
    )
    .await;
    assert!(text(b, row).await.starts_with("Studio4700"));
    assert!(
        text(b, "#light-msg")
            .await
            .starts_with("Added Studio4700 (4700 K)")
    );
    let option = b
        .find(Locator::Css("#render-light option[value=\"Studio4700\"]"))
        .await
        .unwrap();
    assert_eq!(
        option.prop("textContent").await.unwrap().unwrap(),
        "Studio4700 (4700 K)"
    );
    screenshot(b, shots, "console-lights.png").await;
    click(b, &format!("{row} button")).await;
    b.accept_alert().await.unwrap();
    wait_js(
        b,
        "the light removed",
        &format!("return !document.querySelector('{row}')"),
        30,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_renders_trains_and_evaluates_in_chromium() {
    let (chromium, chromedriver) = match browser() {
        Ok(found) => found,
        Err(why) if std::env::var_os("CI").is_some() => {
            panic!("the console test cannot run under CI: {why}")
        }
        Err(why) => {
            println!("skipped: {why}");
            return;
        }
    };
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    let (server, _) = server_with_table(&data, Some(config_with_token(&data))).await;
    let dng = simulated_dng(tmp.path());
    let shots_dir = Shots(Some(
        tempfile::Builder::new()
            .prefix("l3-console-")
            .tempdir()
            .unwrap(),
    ));
    let shots = shots_dir.path().to_path_buf();
    let driver = Driver::start(&chromedriver, &shots.join("chromedriver.log")).await;
    let b = session(&driver, &chromium, &tmp.path().join("profile")).await;
    b.goto(&url(&server, "/")).await.unwrap();
    wait_js(
        &b,
        "the status ready",
        "return document.querySelector('#st-ready').dataset.state == 'ready' \
         && document.querySelector('#st-sensor').textContent != '—'",
        60,
    )
    .await;
    assert_eq!(text(&b, "#st-ready").await, "ready");
    render_a_dng(&b, &dng, &shots).await;
    let job = train_a_tiny_table(&b, &shots).await;
    evaluate(&b, &shots).await;
    let activated = activate_from_the_job_card(&b, &job, &shots).await;
    // the tables: the active one and the job's, each with the sensor it was trained for
    click(&b, "button[data-tab=\"tables\"]").await;
    wait_js(
        &b,
        "two tables",
        "return document.querySelectorAll('#tables-body tr').length == 2",
        30,
    )
    .await;
    let tables = text(&b, "#tables-body").await;
    assert!(
        tables.contains("rgbw-paper") && tables.contains("active"),
        "{tables}"
    );
    screenshot(&b, &shots, "console-tables.png").await;
    add_and_remove_a_light(&b, &shots).await;
    // the job the page submitted is the service's
    let j = json(
        client()
            .get(url(&server, &format!("/v1/training-jobs/{job}")))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(j["status"], "succeeded");
    assert_eq!(j["request"]["scenes"], 4);
    assert_eq!(j["shards"]["done"], 4);
    assert_eq!(j["table_id"], activated.as_str());
    let t = json(
        client()
            .get(url(&server, "/v1/tables"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(t["active_table_id"], activated.as_str());
    b.close().await.unwrap();
    drop(driver);
    server.shutdown().await.unwrap();
}
