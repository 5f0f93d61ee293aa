//! Faults a request can ask for, compiled only with the `fault-injection` feature. The
//! crate's own tests enable it (through its dev-dependency on itself); a release build of
//! the binary has no such feature, so no request can reach this code there.
//!
//! - `X-L3-Fault: render-panic` on `POST /v1/render`: the render panics on its render-pool
//!   thread after it has started, to show that a panic becomes a 500 `internal` answer and
//!   the service keeps serving.
//! - `L3_DEBUG_PAUSE_ACTIVATION_MS` in the environment of the process (unset or 0: off), for
//!   the crash tests that run the real binary (`tests/service_crash.rs`, built by `cargo
//!   test` with this feature): storing a table pauses this long after its temporary file is
//!   written (before the rename), and switching the active table pauses after the new file
//!   is verified (before the switch is recorded), each announced by a log line, so a test
//!   can kill the process inside those windows.

use std::sync::OnceLock;

use axum::http::HeaderMap;

/// The request header that names a fault.
pub const FAULT_HEADER: &str = "x-l3-fault";

/// The fault that makes a render panic.
pub const RENDER_PANIC: &str = "render-panic";

/// Whether the request asks its render to panic.
pub fn render_panic_requested(headers: &HeaderMap) -> bool {
    headers
        .get(FAULT_HEADER)
        .is_some_and(|v| v.as_bytes() == RENDER_PANIC.as_bytes())
}

/// The environment variable of the activation pause.
pub const PAUSE_ACTIVATION_ENV: &str = "L3_DEBUG_PAUSE_ACTIVATION_MS";

/// The activation pause in milliseconds (0: off), read once.
fn activation_pause_ms() -> u64 {
    static PAUSE: OnceLock<u64> = OnceLock::new();
    *PAUSE.get_or_init(|| {
        let v = std::env::var(PAUSE_ACTIVATION_ENV).ok();
        let ms = v
            .as_deref()
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0);
        if ms > 0 {
            tracing::warn!(
                "debug hook {PAUSE_ACTIVATION_ENV}={ms}: table stores and switches pause"
            );
        }
        ms
    })
}

/// Blocks between the fsync of table `id`'s temporary file and its rename, when asked to.
pub(super) fn pause_before_table_rename(id: &str) {
    let ms = activation_pause_ms();
    if ms > 0 {
        tracing::warn!(
            table = id,
            "fault injection: temporary table file written, pausing {ms} ms before the rename"
        );
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

/// Waits between the check of table `id` and the record of its activation, when asked to.
pub(super) async fn pause_before_recording_activation(id: &str) {
    let ms = activation_pause_ms();
    if ms > 0 {
        tracing::warn!(
            table = id,
            "fault injection: table verified, pausing {ms} ms before recording it as active"
        );
        tokio::time::sleep(std::time::Duration::from_millis(ms)).await;
    }
}
