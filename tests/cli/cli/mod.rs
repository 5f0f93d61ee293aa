//! The `l3` binary end to end: simulate → train → render → eval, through
//! the real executable, in a temporary folder (with no ISET data directory
//! beside it: the built-in spectral data serves).
//!
//! By topic: the end-to-end run and bad arguments (`pipeline`), its evaluation steps and
//! `eval --colour-classes` (`eval`), training in shards and with chroma classes (`train`), and
//! `l3 serve`'s flags, configuration errors and failed starts (`serve`).

use std::path::Path;

use crate::support::l3;

mod eval;
mod pipeline;
mod serve;
mod train;

/// Runs `f` on the state of a service started on `data` (no listener in use beyond a free
/// local port, no default training), then stops the service.
pub(crate) fn with_service<F, Fut, T>(data: &Path, f: F) -> T
where
    F: FnOnce(l3::service::AppState) -> Fut,
    Fut: std::future::Future<Output = T>,
{
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut cfg = l3::service::ServiceConfig::load_with_env(None, &[]).unwrap();
        cfg.server.bind = "127.0.0.1:0".parse().unwrap();
        cfg.data.dir = data.to_path_buf();
        cfg.training.auto_train_default = false;
        let server = l3::service::start(cfg).await.unwrap();
        let out = f(server.state().clone()).await;
        server.shutdown().await.unwrap();
        out
    })
}

/// `l3 simulate` of the Macbeth chart under tungsten (seed 3) into `out`.
fn simulate_macbeth(d: &Path, out: &Path) {
    let (ok, stdout, err) = l3(
        &[
            "simulate",
            "--scene",
            "macbeth",
            "--illuminant",
            "Tungsten",
            "--seed",
            "3",
            "--out",
            out.to_str().unwrap(),
        ],
        d,
    );
    assert!(ok, "simulate failed: {stdout}{err}");
}
