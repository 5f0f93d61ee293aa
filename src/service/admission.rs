//! Admission of renders, in three steps:
//!
//! 1. The body's memory is reserved from a global budget (`body_budget_bytes`) before any of
//!    it is read: a body that would pass the budget gets 503 with Retry-After unread.
//! 2. The body is read, bounded by `max_body_bytes` (413) and by a deadline
//!    (`body_timeout_s`, `min_body_rate_bytes_s`; 408). A slow body holds no render slot.
//! 3. The request waits in a bounded FIFO queue for one of `render_concurrency` render
//!    slots; a full queue (`render_queue_depth`) or a wait past `render_queue_wait_s` gets
//!    503 with Retry-After.
//!
//! A request abandoned in any step (timed out, or its client gone) leaves the queue and
//! returns its reservation when its future is dropped.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes, HttpBody};
use axum::http::{HeaderMap, header};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use super::config::ServerConfig;
use super::error::ServiceError;
use super::metrics::AdmissionCounters;

/// The budget counts memory in units of this many bytes (semaphore permits are counted in
/// `u32` per acquisition).
const BUDGET_UNIT: usize = 1024;

/// How long a body is read before its average rate is judged.
const RATE_GRACE: Duration = Duration::from_secs(2);

/// How often a body that sends nothing is checked against its deadline and rate.
const BODY_TICK: Duration = Duration::from_millis(250);

/// Seconds a refused client is asked to wait.
const RETRY_AFTER_S: u64 = 1;

/// The admission state shared by all render requests.
pub struct Admission {
    body_budget: Arc<Semaphore>,
    budget_units: usize,
    /// The running renders' slots; waiters are served in arrival order.
    pub render_slots: Arc<Semaphore>,
    queued: AtomicUsize,
    queue_depth: usize,
    queue_wait: Duration,
    body_timeout: Duration,
    min_body_rate: u64,
    max_body_bytes: usize,
    render_concurrency: usize,
}

/// Memory reserved for one body; returned to the budget when dropped.
#[derive(Debug)]
pub struct BodyReservation(Option<OwnedSemaphorePermit>);

/// Leaves the queue count when dropped (also when the waiting request is abandoned).
struct InQueue<'a>(&'a AtomicUsize);

impl Drop for InQueue<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

fn units(bytes: usize) -> usize {
    bytes.div_ceil(BUDGET_UNIT)
}

/// The declared `Content-Length`, if any and valid.
pub fn content_length(headers: &HeaderMap) -> Option<usize> {
    headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse().ok())
}

impl Admission {
    pub fn new(cfg: &ServerConfig) -> Self {
        Self {
            body_budget: Arc::new(Semaphore::new(units(cfg.body_budget_bytes))),
            budget_units: units(cfg.body_budget_bytes),
            render_slots: Arc::new(Semaphore::new(cfg.render_concurrency)),
            queued: AtomicUsize::new(0),
            queue_depth: cfg.render_queue_depth,
            queue_wait: Duration::from_secs_f64(cfg.render_queue_wait_s),
            body_timeout: Duration::from_secs_f64(cfg.body_timeout_s),
            min_body_rate: cfg.min_body_rate_bytes_s,
            max_body_bytes: cfg.max_body_bytes,
            render_concurrency: cfg.render_concurrency,
        }
    }

    /// Bytes of the body budget reserved by bodies in flight now.
    pub fn reserved_bytes(&self) -> usize {
        self.budget_units
            .saturating_sub(self.body_budget.available_permits())
            * BUDGET_UNIT
    }

    /// Requests waiting for a render slot now.
    pub fn queued(&self) -> usize {
        self.queued.load(Ordering::Acquire)
    }

    fn too_large(&self, limit: usize) -> ServiceError {
        ServiceError::PayloadTooLarge(format!(
            "the request body is larger than the limit of {limit} bytes"
        ))
    }

    /// The most a body may hold: `max_body_bytes`, or less (`limit`).
    fn limit(&self, limit: usize) -> usize {
        limit.min(self.max_body_bytes)
    }

    fn budget_spent(&self, bytes: usize, counters: &AdmissionCounters) -> ServiceError {
        counters.budget_refusals.inc();
        ServiceError::Overloaded {
            msg: format!(
                "the bodies in flight hold the whole body budget; this one ({bytes} bytes) must wait; retry shortly"
            ),
            retry_after_s: RETRY_AFTER_S,
        }
    }

    /// Step 1: reserves `declared` bytes of the budget, or refuses at once (413 past `limit`,
    /// itself at most `max_body_bytes`).
    pub fn reserve(
        &self,
        declared: usize,
        limit: usize,
        counters: &AdmissionCounters,
    ) -> Result<BodyReservation, ServiceError> {
        let limit = self.limit(limit);
        if declared > limit {
            return Err(self.too_large(limit));
        }
        if declared == 0 {
            return Ok(BodyReservation(None));
        }
        let n = u32::try_from(units(declared)).map_err(|_| self.too_large(limit))?;
        self.body_budget
            .clone()
            .try_acquire_many_owned(n)
            .map(|p| BodyReservation(Some(p)))
            .map_err(|_| self.budget_spent(declared, counters))
    }

    /// Grows `r` to cover `bytes` (a body without Content-Length, or longer than declared).
    fn grow(
        &self,
        r: &mut BodyReservation,
        bytes: usize,
        counters: &AdmissionCounters,
    ) -> Result<(), ServiceError> {
        let have = r.0.as_ref().map_or(0, |p| p.num_permits());
        let need = units(bytes);
        if need <= have {
            return Ok(());
        }
        let more = u32::try_from(need - have).map_err(|_| self.too_large(self.max_body_bytes))?;
        let p = self
            .body_budget
            .clone()
            .try_acquire_many_owned(more)
            .map_err(|_| self.budget_spent(bytes, counters))?;
        match &mut r.0 {
            Some(have) => have.merge(p),
            None => r.0 = Some(p),
        }
        Ok(())
    }

    fn too_slow(
        &self,
        got: usize,
        elapsed: Duration,
        counters: &AdmissionCounters,
    ) -> ServiceError {
        counters.body_timeouts.inc();
        ServiceError::BodyTimeout(format!(
            "the request body was too slow: {got} bytes in {:.1} s (limits: {} s for the whole body, at least {} bytes/s)",
            elapsed.as_secs_f64(),
            self.body_timeout.as_secs_f64(),
            self.min_body_rate
        ))
    }

    /// Step 2: reads the body within the size limit (`limit`, at most `max_body_bytes`) and
    /// the deadline, growing the reservation if the body is longer than declared.
    pub async fn read_body(
        &self,
        mut body: Body,
        declared: Option<usize>,
        limit: usize,
        reservation: &mut BodyReservation,
        counters: &AdmissionCounters,
    ) -> Result<Bytes, ServiceError> {
        let limit = self.limit(limit);
        let started = Instant::now();
        let deadline = started + self.body_timeout;
        let mut buf = bytes::BytesMut::with_capacity(declared.unwrap_or(0).min(limit));
        loop {
            let now = Instant::now();
            let elapsed = now - started;
            if now >= deadline
                || (self.min_body_rate > 0
                    && elapsed >= RATE_GRACE
                    && (buf.len() as f64) < self.min_body_rate as f64 * elapsed.as_secs_f64())
            {
                return Err(self.too_slow(buf.len(), elapsed, counters));
            }
            let wake = (now + BODY_TICK).min(deadline);
            let frame = tokio::time::timeout_at(
                wake.into(),
                std::future::poll_fn(|cx| std::pin::Pin::new(&mut body).poll_frame(cx)),
            )
            .await;
            match frame {
                Err(_) => continue,
                Ok(None) => return Ok(buf.freeze()),
                Ok(Some(Err(e))) => {
                    return Err(ServiceError::BadRequest(format!(
                        "cannot read the request body: {e}"
                    )));
                }
                Ok(Some(Ok(frame))) => {
                    if let Ok(data) = frame.into_data() {
                        let len = buf.len() + data.len();
                        if len > limit {
                            return Err(self.too_large(limit));
                        }
                        self.grow(reservation, len, counters)?;
                        buf.extend_from_slice(&data);
                    }
                }
            }
        }
    }

    /// Steps 1 and 2 for a request with `headers`: its reservation, and its body read within
    /// `limit` (at most `max_body_bytes`). The reservation is held until dropped.
    pub async fn take_body(
        &self,
        body: Body,
        headers: &HeaderMap,
        limit: usize,
        counters: &AdmissionCounters,
    ) -> Result<(Bytes, BodyReservation), ServiceError> {
        let declared = content_length(headers);
        let mut reservation = self.reserve(declared.unwrap_or(0), limit, counters)?;
        let body = self
            .read_body(body, declared, limit, &mut reservation, counters)
            .await?;
        Ok((body, reservation))
    }

    /// Step 3: waits in the FIFO queue for a render slot.
    pub async fn render_slot(
        &self,
        counters: &AdmissionCounters,
    ) -> Result<OwnedSemaphorePermit, ServiceError> {
        // a free slot is only free when nobody waits (the semaphore serves waiters first)
        if let Ok(p) = self.render_slots.clone().try_acquire_owned() {
            return Ok(p);
        }
        let ahead = self.queued.fetch_add(1, Ordering::AcqRel);
        let _in_queue = InQueue(&self.queued);
        let refuse = |why: String| {
            counters.queue_refusals.inc();
            ServiceError::Overloaded {
                msg: why,
                retry_after_s: RETRY_AFTER_S,
            }
        };
        if ahead >= self.queue_depth {
            return Err(refuse(format!(
                "{} renders are running and {ahead} are waiting (the queue holds {}); retry shortly",
                self.render_concurrency, self.queue_depth
            )));
        }
        match tokio::time::timeout(self.queue_wait, self.render_slots.clone().acquire_owned()).await
        {
            Ok(Ok(p)) => Ok(p),
            Ok(Err(_)) => Err(ServiceError::Internal("the render slots are closed".into())),
            Err(_) => Err(refuse(format!(
                "no render slot came free within {} s; retry shortly",
                self.queue_wait.as_secs_f64()
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> ServerConfig {
        let mut c = super::super::ServiceConfig::load_with_env(None, &[])
            .unwrap()
            .server;
        c.max_body_bytes = 4096;
        c.body_budget_bytes = 8192;
        c.render_concurrency = 1;
        c.render_queue_depth = 1;
        c.render_queue_wait_s = 0.05;
        c
    }

    #[test]
    fn the_budget_refuses_past_its_size_and_refills() {
        let a = Admission::new(&cfg());
        let n = AdmissionCounters::default();
        let max = usize::MAX;
        let r1 = a.reserve(4096, max, &n).unwrap();
        let r2 = a.reserve(3000, max, &n).unwrap();
        assert_eq!(a.reserve(2000, max, &n).unwrap_err().status(), 503);
        assert_eq!(a.reserve(5000, max, &n).unwrap_err().status(), 413);
        // a lower limit of the request's own
        let e = a.reserve(1001, 1000, &n).unwrap_err();
        assert_eq!(e.status(), 413);
        assert!(e.to_string().contains("limit of 1000 bytes"), "{e}");
        drop(r1);
        let mut r3 = a.reserve(1, max, &n).unwrap();
        a.grow(&mut r3, 4096, &n).unwrap();
        drop((r2, r3));
        assert_eq!(n.budget_refusals.get(), 1);
    }

    #[tokio::test]
    async fn the_queue_is_bounded_in_depth_and_wait() {
        let a = Arc::new(Admission::new(&cfg()));
        let n = Arc::new(AdmissionCounters::default());
        let held = a.render_slot(&n).await.unwrap();
        // one may wait; it gives up after the maximum wait
        let (a2, n2) = (a.clone(), n.clone());
        let waiter = tokio::spawn(async move { a2.render_slot(&n2).await.map(|_| ()) });
        while a.queued() == 0 {
            tokio::task::yield_now().await;
        }
        // the queue is full
        assert_eq!(a.render_slot(&n).await.unwrap_err().status(), 503);
        assert_eq!(waiter.await.unwrap().unwrap_err().status(), 503);
        assert_eq!(a.queued(), 0);
        drop(held);
        assert!(a.render_slot(&n).await.is_ok());
        assert_eq!(n.queue_refusals.get(), 2);
    }
}
