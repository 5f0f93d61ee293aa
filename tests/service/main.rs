//! The HTTP service, one test binary: the API end to end (`api`), training jobs (`jobs`), renders
//! with the table of a DNG's camera or a named table and the sensor catalogue (`cameras`), the
//! evaluation figure (`figure`), ColorChecker frames (`colorchecker`), the browser console
//! (`console`: headless Chromium through chromedriver), render admission (`admission`),
//! /metrics read by a Prometheus parser (`metrics`), crash safety of the real
//! `l3 serve` process (`crash`), the typed store over rows the previous store wrote
//! (`store_compat`), and openapi.yaml against the served routes (`spec`: not named
//! `openapi`, so that the filter `api::` selects the API tests alone).
//!
//! Every test starts its own server (in process on 127.0.0.1:0, or `l3 serve` on a free port)
//! with its own temporary data directory; the tests share only the tiny table
//! ([`service_support::tiny_table`], trained once) and, with `L3_TEST_BACKEND=postgres`, one
//! PostgreSQL server with a database per data directory. `L3_TEST_BACKEND=postgres cargo test
//! --test service -- api:: jobs:: figure:: store_compat::` runs the API, job, figure and
//! migration-compatibility tests on PostgreSQL.

#[path = "../service_support/mod.rs"]
mod service_support;

mod admission;
mod api;
mod cameras;
mod colorchecker;
mod console;
mod crash;
mod figure;
mod jobs;
mod metrics;
mod spec;
mod store_compat;
