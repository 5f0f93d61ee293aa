//! The HTTP service, one test binary: the API end to end (`api`), training jobs (`jobs`), the
//! evaluation figure (`figure`), render admission (`admission`), crash safety of the real
//! `l3 serve` process (`crash`) and openapi.yaml against the served routes (`openapi`).
//!
//! Every test starts its own server (on 127.0.0.1:0, or `l3 serve` on a free port) with its own
//! temporary data directory, so the tests share nothing but [`service_support::tiny_table`].
//! `L3_TEST_BACKEND=postgres cargo test --test service -- api:: jobs:: figure::` runs the API
//! tests again on PostgreSQL.

#[path = "../service_support/mod.rs"]
mod service_support;

mod admission;
mod api;
mod crash;
mod figure;
mod jobs;
mod openapi;
