//! Debug hooks read from the process environment, never from the configuration, for the
//! crash tests that run the real binary (`tests/service_crash.rs`):
//!
//! - `L3_DEBUG_PAUSE_ACTIVATION_MS` (unset or 0: off): storing a table pauses this long after
//!   its temporary file is written (before the rename), and switching the active table pauses
//!   after the new file is verified (before the switch is recorded), each announced by a log
//!   line, so a test can kill the process inside those windows.
//!
//! The hook is read once; a production deployment never sets it.

use std::sync::OnceLock;

/// The environment variable of the activation pause.
pub const PAUSE_ACTIVATION_ENV: &str = "L3_DEBUG_PAUSE_ACTIVATION_MS";

/// The fault-injection pause in milliseconds (0: off).
pub fn activation_pause_ms() -> u64 {
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
