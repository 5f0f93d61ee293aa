//! Faults a request can ask for, compiled only with the `fault-injection` feature. The
//! crate's own tests enable it (through its dev-dependency on itself); a release build of
//! the binary has no such feature, so no request can reach this code there.
//!
//! - `X-L3-Fault: render-panic` on `POST /v1/render`: the render panics on its render-pool
//!   thread after it has started, to show that a panic becomes a 500 `internal` answer and
//!   the service keeps serving.

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
