//! Prometheus metrics, written in the text exposition format by hand: request counts and
//! latency histograms by route and status, rendered megapixels, training jobs by state.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::store::JobStatus;

/// Upper bounds (seconds) of the latency histogram buckets.
pub const LATENCY_BUCKETS_S: [f64; 14] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];

#[derive(Default, Clone)]
struct Histogram {
    counts: [u64; LATENCY_BUCKETS_S.len()],
    count: u64,
    sum: f64,
}

/// The service's counters.
#[derive(Default)]
pub struct Metrics {
    /// (method, route, status) → latency histogram.
    requests: Mutex<BTreeMap<(String, String, u16), Histogram>>,
    rendered_pixels: AtomicU64,
    renders: AtomicU64,
    /// Render admission refusals and cancellations, by kind.
    pub admission: AdmissionCounters,
}

/// What render admission refused or abandoned.
#[derive(Default)]
pub struct AdmissionCounters {
    /// Bodies that did not arrive within the body deadline (408).
    pub body_timeouts: AtomicU64,
    /// Bodies refused before reading: the body budget was spent (503).
    pub budget_refusals: AtomicU64,
    /// Requests refused by the queue: full, or waited too long (503).
    pub queue_refusals: AtomicU64,
    /// Renders abandoned by their request (timed out or client gone) and stopped early.
    pub renders_canceled: AtomicU64,
}

impl Metrics {
    /// Records one finished request.
    pub fn observe(&self, method: &str, route: &str, status: u16, seconds: f64) {
        let mut m = self.requests.lock().unwrap_or_else(|p| p.into_inner());
        let h = m
            .entry((method.to_string(), route.to_string(), status))
            .or_default();
        for (i, b) in LATENCY_BUCKETS_S.iter().enumerate() {
            if seconds <= *b {
                h.counts[i] += 1;
            }
        }
        h.count += 1;
        h.sum += seconds;
    }

    /// Records a finished render of `pixels` pixels.
    pub fn rendered(&self, pixels: u64) {
        self.rendered_pixels.fetch_add(pixels, Ordering::Relaxed);
        self.renders.fetch_add(1, Ordering::Relaxed);
    }

    /// The exposition text; `jobs` are (state, count) pairs read from the database.
    pub fn render(&self, jobs: &[(JobStatus, i64)], ready: bool) -> String {
        let mut out = String::new();
        let requests = self
            .requests
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        write_requests(&mut out, &requests);
        let px = self.rendered_pixels.load(Ordering::Relaxed);
        let _ = writeln!(
            out,
            "# HELP l3_rendered_megapixels_total Megapixels rendered.\n# TYPE l3_rendered_megapixels_total counter\nl3_rendered_megapixels_total {}",
            px as f64 / 1e6
        );
        let _ = writeln!(
            out,
            "# HELP l3_renders_total Renders completed.\n# TYPE l3_renders_total counter\nl3_renders_total {}",
            self.renders.load(Ordering::Relaxed)
        );
        let a = &self.admission;
        for (name, help, v) in [
            (
                "l3_render_body_timeouts_total",
                "Render bodies that missed their deadline (408).",
                &a.body_timeouts,
            ),
            (
                "l3_render_budget_refusals_total",
                "Render bodies refused unread because the body budget was spent (503).",
                &a.budget_refusals,
            ),
            (
                "l3_render_queue_refusals_total",
                "Renders refused by a full queue or a wait past the limit (503).",
                &a.queue_refusals,
            ),
            (
                "l3_renders_canceled_total",
                "Renders abandoned by their request and stopped early.",
                &a.renders_canceled,
            ),
        ] {
            let _ = writeln!(
                out,
                "# HELP {name} {help}\n# TYPE {name} counter\n{name} {}",
                v.load(Ordering::Relaxed)
            );
        }
        let _ = writeln!(
            out,
            "# HELP l3_training_jobs Training jobs by state.\n# TYPE l3_training_jobs gauge"
        );
        for state in JobStatus::ALL {
            let n = jobs
                .iter()
                .find(|(s, _)| *s == state)
                .map_or(0, |(_, n)| *n);
            let _ = writeln!(out, "l3_training_jobs{{state=\"{state}\"}} {n}");
        }
        let _ = writeln!(
            out,
            "# HELP l3_ready Whether a table is active (1) or not (0).\n# TYPE l3_ready gauge\nl3_ready {}",
            u8::from(ready)
        );
        out
    }
}

/// The request counters and latency histograms, by (method, route, status).
fn write_requests(out: &mut String, requests: &BTreeMap<(String, String, u16), Histogram>) {
    let _ = writeln!(
        out,
        "# HELP l3_http_requests_total HTTP requests by method, route and status.\n# TYPE l3_http_requests_total counter"
    );
    for ((method, route, status), h) in requests {
        let _ = writeln!(
            out,
            "l3_http_requests_total{{method=\"{method}\",route=\"{route}\",status=\"{status}\"}} {}",
            h.count
        );
    }
    let _ = writeln!(
        out,
        "# HELP l3_http_request_duration_seconds HTTP request latency by method, route and status.\n# TYPE l3_http_request_duration_seconds histogram"
    );
    for ((method, route, status), h) in requests {
        let labels = format!("method=\"{method}\",route=\"{route}\",status=\"{status}\"");
        for (i, b) in LATENCY_BUCKETS_S.iter().enumerate() {
            let _ = writeln!(
                out,
                "l3_http_request_duration_seconds_bucket{{{labels},le=\"{b}\"}} {}",
                h.counts[i]
            );
        }
        let _ = writeln!(
            out,
            "l3_http_request_duration_seconds_bucket{{{labels},le=\"+Inf\"}} {}",
            h.count
        );
        let _ = writeln!(
            out,
            "l3_http_request_duration_seconds_sum{{{labels}}} {}",
            h.sum
        );
        let _ = writeln!(
            out,
            "l3_http_request_duration_seconds_count{{{labels}}} {}",
            h.count
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_has_histograms_and_counters() {
        let m = Metrics::default();
        m.observe("POST", "/v1/render", 200, 0.02);
        m.observe("POST", "/v1/render", 200, 0.2);
        m.rendered(2_000_000);
        let text = m.render(&[(JobStatus::Queued, 2)], true);
        assert!(text.contains(
            "l3_http_requests_total{method=\"POST\",route=\"/v1/render\",status=\"200\"} 2"
        ));
        assert!(text.contains(
            "l3_http_request_duration_seconds_bucket{method=\"POST\",route=\"/v1/render\",status=\"200\",le=\"0.025\"} 1"
        ));
        assert!(text.contains("l3_rendered_megapixels_total 2"));
        assert!(text.contains("l3_training_jobs{state=\"queued\"} 2"));
        assert!(text.contains("l3_training_jobs{state=\"running\"} 0"));
    }
}
