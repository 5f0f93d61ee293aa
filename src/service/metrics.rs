//! Prometheus metrics on the `prometheus` crate: request counts and latency histograms by
//! route and status, rendered megapixels, render admission, the table cache, training jobs by
//! state. One [`prometheus::Registry`] per service (never the process-wide default one, so
//! services started side by side in one process, as the tests do, keep their own counts),
//! encoded by its `TextEncoder` (text exposition format 0.0.4).
//!
//! `prometheus` rather than `metrics` + `metrics-exporter-prometheus`: the latter records
//! through a process-wide recorder (a local one needs `with_local_recorder` around every call
//! site) and its histogram buckets are set by name matching at install time; here each
//! service owns its registry and every metric is a typed handle with its buckets declared
//! beside it. The crate is built without its protobuf feature (only the text format is served).
//!
//! The names, labels, types and buckets are those of the earlier hand-written exposition, so
//! dashboards keep working. Gauges whose truth lives elsewhere (jobs in the database, the
//! admission queue, the table cache) are set from a [`Scrape`] just before each encoding.

use prometheus::{
    Counter, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge, IntGaugeVec, Opts,
    Registry, TextEncoder,
};

use super::store::JobStatus;

/// Upper bounds (seconds) of the latency histogram buckets.
pub const LATENCY_BUCKETS_S: [f64; 14] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];

/// A counter with a constant name. Names are literals of this module and valid, so this never
/// fails (the unit tests build every one).
fn counter(name: &str, help: &str) -> IntCounter {
    IntCounter::new(name, help).expect("a valid constant metric name")
}

/// What render admission refused or abandoned.
pub struct AdmissionCounters {
    /// Bodies that did not arrive within the body deadline (408).
    pub body_timeouts: IntCounter,
    /// Bodies refused before reading: the body budget was spent (503).
    pub budget_refusals: IntCounter,
    /// Requests refused by the queue: full, or waited too long (503).
    pub queue_refusals: IntCounter,
    /// Renders abandoned by their request (timed out or client gone) and stopped early.
    pub renders_canceled: IntCounter,
}

impl Default for AdmissionCounters {
    fn default() -> Self {
        AdmissionCounters {
            body_timeouts: counter(
                "l3_render_body_timeouts_total",
                "Render bodies that missed their deadline (408).",
            ),
            budget_refusals: counter(
                "l3_render_budget_refusals_total",
                "Render bodies refused unread because the body budget was spent (503).",
            ),
            queue_refusals: counter(
                "l3_render_queue_refusals_total",
                "Renders refused by a full queue or a wait past the limit (503).",
            ),
            renders_canceled: counter(
                "l3_renders_canceled_total",
                "Renders abandoned by their request (timed out, or the client gone) after \
                 admission, while waiting for a CPU turn or running (stopped early).",
            ),
        }
    }
}

/// The table cache's counters (the cache counts; the service's registry exposes them).
pub struct CacheCounters {
    pub hits: IntCounter,
    pub misses: IntCounter,
    pub evictions: IntCounter,
}

impl Default for CacheCounters {
    fn default() -> Self {
        CacheCounters {
            hits: counter(
                "l3_table_cache_hits_total",
                "Renders whose non-active table was in the table cache.",
            ),
            misses: counter(
                "l3_table_cache_misses_total",
                "Renders whose non-active table was loaded from the store.",
            ),
            evictions: counter(
                "l3_table_cache_evictions_total",
                "Tables evicted from the table cache to keep its bound.",
            ),
        }
    }
}

/// The values a scrape reads from elsewhere: the database's job counts and the service's
/// state at that moment.
pub struct Scrape<'a> {
    /// (state, count) pairs read from the database; `None` when it did not answer (the job
    /// gauges keep their last values and `l3_database_up` is 0).
    pub jobs: Option<&'a [(JobStatus, i64)]>,
    /// Whether a table is active.
    pub ready: bool,
    /// Body budget held by render bodies in flight (bytes).
    pub body_bytes_reserved: usize,
    /// Renders waiting for a render slot.
    pub queue_length: usize,
    /// Bytes of kernels the table cache holds, and its bound.
    pub cache_bytes: usize,
    pub cache_bound_bytes: usize,
}

/// The gauges a [`Scrape`] sets.
struct Gauges {
    training_jobs: IntGaugeVec,
    database_up: IntGauge,
    ready: IntGauge,
    body_bytes_reserved: IntGauge,
    queue_length: IntGauge,
    cache_bytes: IntGauge,
    cache_bound_bytes: IntGauge,
}

/// The service's metrics and the registry that exposes them.
pub struct Metrics {
    registry: Registry,
    requests: IntCounterVec,
    durations: HistogramVec,
    rendered_megapixels: Counter,
    renders: IntCounter,
    gauges: Gauges,
    /// Render admission refusals and cancellations, by kind.
    pub admission: AdmissionCounters,
}

/// The label names of the request metrics.
const REQUEST_LABELS: [&str; 3] = ["method", "route", "status"];

impl Metrics {
    /// The metrics of one service, exposing the table cache's `cache` counters too.
    pub fn new(cache: &CacheCounters) -> Result<Self, prometheus::Error> {
        let registry = Registry::new();
        let requests = IntCounterVec::new(
            Opts::new(
                "l3_http_requests_total",
                "HTTP requests by method, route and status.",
            ),
            &REQUEST_LABELS,
        )?;
        let durations = HistogramVec::new(
            HistogramOpts::new(
                "l3_http_request_duration_seconds",
                "HTTP request latency by method, route and status.",
            )
            .buckets(LATENCY_BUCKETS_S.to_vec()),
            &REQUEST_LABELS,
        )?;
        let rendered_megapixels =
            Counter::new("l3_rendered_megapixels_total", "Megapixels rendered.")?;
        let renders = IntCounter::new("l3_renders_total", "Renders completed.")?;
        let gauges = Gauges {
            training_jobs: IntGaugeVec::new(
                Opts::new("l3_training_jobs", "Training jobs by state."),
                &["state"],
            )?,
            database_up: IntGauge::new(
                "l3_database_up",
                "Whether the database answered this scrape's job counts (1) or not (0, the \
                 l3_training_jobs gauges then keep their last values).",
            )?,
            ready: IntGauge::new("l3_ready", "Whether a table is active (1) or not (0).")?,
            body_bytes_reserved: IntGauge::new(
                "l3_render_body_bytes_reserved",
                "Body budget held by render bodies in flight (bytes).",
            )?,
            queue_length: IntGauge::new(
                "l3_render_queue_length",
                "Renders waiting for a render slot.",
            )?,
            cache_bytes: IntGauge::new(
                "l3_table_cache_bytes",
                "Bytes of kernels the table cache holds.",
            )?,
            cache_bound_bytes: IntGauge::new(
                "l3_table_cache_bound_bytes",
                "The table cache's bound (config [tables] cache_bytes).",
            )?,
        };
        let admission = AdmissionCounters::default();
        let collectors: Vec<Box<dyn prometheus::core::Collector>> = vec![
            Box::new(requests.clone()),
            Box::new(durations.clone()),
            Box::new(rendered_megapixels.clone()),
            Box::new(renders.clone()),
            Box::new(admission.body_timeouts.clone()),
            Box::new(admission.budget_refusals.clone()),
            Box::new(admission.queue_refusals.clone()),
            Box::new(admission.renders_canceled.clone()),
            Box::new(cache.hits.clone()),
            Box::new(cache.misses.clone()),
            Box::new(cache.evictions.clone()),
            Box::new(gauges.training_jobs.clone()),
            Box::new(gauges.ready.clone()),
            Box::new(gauges.database_up.clone()),
            Box::new(gauges.body_bytes_reserved.clone()),
            Box::new(gauges.queue_length.clone()),
            Box::new(gauges.cache_bytes.clone()),
            Box::new(gauges.cache_bound_bytes.clone()),
        ];
        for c in collectors {
            registry.register(c)?;
        }
        Ok(Metrics {
            registry,
            requests,
            durations,
            rendered_megapixels,
            renders,
            gauges,
            admission,
        })
    }

    /// Records one finished request.
    pub fn observe(&self, method: &str, route: &str, status: u16, seconds: f64) {
        let status = status.to_string();
        let labels = [method, route, status.as_str()];
        self.requests.with_label_values(&labels).inc();
        self.durations.with_label_values(&labels).observe(seconds);
    }

    /// Records a finished render of `pixels` pixels.
    pub fn rendered(&self, pixels: u64) {
        self.rendered_megapixels.inc_by(pixels as f64 / 1e6);
        self.renders.inc();
    }

    /// The exposition text, with the gauges set from `s`.
    pub fn render(&self, s: &Scrape<'_>) -> Result<String, prometheus::Error> {
        let g = &self.gauges;
        g.database_up.set(i64::from(s.jobs.is_some()));
        if let Some(jobs) = s.jobs {
            for state in JobStatus::ALL {
                let n = jobs
                    .iter()
                    .find(|(st, _)| *st == state)
                    .map_or(0, |(_, n)| *n);
                g.training_jobs.with_label_values(&[state.as_str()]).set(n);
            }
        }
        let int = |v: usize| i64::try_from(v).unwrap_or(i64::MAX);
        g.ready.set(i64::from(s.ready));
        g.body_bytes_reserved.set(int(s.body_bytes_reserved));
        g.queue_length.set(int(s.queue_length));
        g.cache_bytes.set(int(s.cache_bytes));
        g.cache_bound_bytes.set(int(s.cache_bound_bytes));
        let families = self.registry.gather();
        let mut out = String::new();
        TextEncoder::new().encode_utf8(&families, &mut out)?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scrape(jobs: &[(JobStatus, i64)]) -> Scrape<'_> {
        Scrape {
            jobs: Some(jobs),
            ready: true,
            body_bytes_reserved: 4096,
            queue_length: 3,
            cache_bytes: 1000,
            cache_bound_bytes: 2000,
        }
    }

    #[test]
    fn exposition_has_histograms_and_counters() {
        let cache = CacheCounters::default();
        let m = Metrics::new(&cache).unwrap();
        m.observe("POST", "/v1/render", 200, 0.02);
        m.observe("POST", "/v1/render", 200, 0.2);
        m.rendered(2_000_000);
        cache.evictions.inc_by(3);
        m.admission.queue_refusals.inc();
        let text = m.render(&scrape(&[(JobStatus::Queued, 2)])).unwrap();
        for line in [
            "l3_http_requests_total{method=\"POST\",route=\"/v1/render\",status=\"200\"} 2",
            "l3_http_request_duration_seconds_bucket{method=\"POST\",route=\"/v1/render\",status=\"200\",le=\"0.025\"} 1",
            "l3_http_request_duration_seconds_bucket{method=\"POST\",route=\"/v1/render\",status=\"200\",le=\"1\"} 2",
            "l3_http_request_duration_seconds_bucket{method=\"POST\",route=\"/v1/render\",status=\"200\",le=\"+Inf\"} 2",
            "l3_http_request_duration_seconds_count{method=\"POST\",route=\"/v1/render\",status=\"200\"} 2",
            "# TYPE l3_http_request_duration_seconds histogram",
            "# TYPE l3_rendered_megapixels_total counter",
            "l3_rendered_megapixels_total 2",
            "l3_renders_total 1",
            "l3_render_queue_refusals_total 1",
            "l3_render_body_timeouts_total 0",
            "l3_table_cache_evictions_total 3",
            "l3_table_cache_bytes 1000",
            "l3_table_cache_bound_bytes 2000",
            "l3_render_body_bytes_reserved 4096",
            "l3_render_queue_length 3",
            "l3_training_jobs{state=\"queued\"} 2",
            "l3_training_jobs{state=\"running\"} 0",
            "# TYPE l3_training_jobs gauge",
            "l3_ready 1",
            "l3_database_up 1",
        ] {
            assert!(text.lines().any(|l| l == line), "no {line:?} in\n{text}");
        }
        // every bucket of the histogram is there
        let buckets = text
            .lines()
            .filter(|l| l.starts_with("l3_http_request_duration_seconds_bucket{"))
            .count();
        assert_eq!(buckets, LATENCY_BUCKETS_S.len() + 1);
        // a database that does not answer: the job gauges keep their values, the scrape goes on
        let mut down = scrape(&[]);
        down.jobs = None;
        let text = m.render(&down).unwrap();
        assert!(text.lines().any(|l| l == "l3_database_up 0"), "{text}");
        assert!(
            text.lines()
                .any(|l| l == "l3_training_jobs{state=\"queued\"} 2"),
            "{text}"
        );
    }

    #[test]
    fn each_service_counts_apart() {
        let (a, b) = (CacheCounters::default(), CacheCounters::default());
        let (ma, mb) = (Metrics::new(&a).unwrap(), Metrics::new(&b).unwrap());
        ma.rendered(1_000_000);
        let text = mb.render(&scrape(&[])).unwrap();
        assert!(text.lines().any(|l| l == "l3_renders_total 0"), "{text}");
        let text = ma.render(&scrape(&[])).unwrap();
        assert!(text.lines().any(|l| l == "l3_renders_total 1"), "{text}");
    }
}
