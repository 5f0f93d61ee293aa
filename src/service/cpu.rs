//! CPU work off the async runtime: two rayon pools, one for renders and one
//! for background work (training jobs, evaluations), so a training job
//! cannot fill the queue renders wait in; and one way to run a closure on a
//! pool that turns a panic into a 500 `internal` answer instead of an
//! aborted process (rayon aborts on a panic in a spawned job that nothing
//! catches).

use std::panic::{AssertUnwindSafe, catch_unwind};

use super::error::ServiceError;

/// The service's CPU pools.
pub struct CpuPools {
    /// Renders (and their decoding and encoding).
    pub render: rayon::ThreadPool,
    /// Training jobs and evaluations.
    pub background: rayon::ThreadPool,
}

impl CpuPools {
    /// `render_threads` and `background_threads` of 0 pick a size from the
    /// machine: every core for renders, half of them (at least one) for
    /// background work. The pools share the cores; what they separate is
    /// the queue, so a render never waits behind a training job's tasks.
    pub fn new(render_threads: usize, background_threads: usize) -> Result<Self, ServiceError> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let pick = |n: usize, auto: usize| if n == 0 { auto.max(1) } else { n };
        let build = |name: &'static str, n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(move |i| format!("l3-{name}-{i}"))
                // a last line of defence: `run` catches panics itself
                .panic_handler(move |_| tracing::error!(pool = name, "a CPU task panicked"))
                .build()
                .map_err(|e| ServiceError::Internal(format!("the {name} thread pool: {e}")))
        };
        Ok(Self {
            render: build("render", pick(render_threads, cores))?,
            background: build("background", pick(background_threads, cores / 2))?,
        })
    }
}

/// The text of a panic's payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

/// Run `f` on `pool` and wait for it without blocking the runtime. A panic
/// in `f` is caught, logged (inside the caller's span, so with its request
/// id) and returned as [`ServiceError::Internal`].
pub async fn run<T, F>(pool: &rayon::ThreadPool, what: &str, f: F) -> Result<T, ServiceError>
where
    T: Send + 'static,
    F: FnOnce() -> T + Send + 'static,
{
    let (tx, rx) = tokio::sync::oneshot::channel();
    pool.spawn(move || {
        let _ = tx.send(catch_unwind(AssertUnwindSafe(f)).map_err(|p| panic_message(&*p)));
    });
    match rx.await {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(msg)) => {
            tracing::error!(task = what, panic = %msg, "CPU work panicked");
            Err(ServiceError::Internal(format!(
                "{what} failed unexpectedly"
            )))
        }
        Err(_) => Err(ServiceError::Internal(format!("{what} was lost"))),
    }
}

/// Run `f` on `pool` and hand its result, or the panic's message, to
/// `done` on the pool thread: for work whose caller does not wait on it
/// (training jobs report through their own channel).
pub fn spawn_catching<T, F, D>(pool: &rayon::ThreadPool, f: F, done: D)
where
    F: FnOnce() -> T + Send + 'static,
    D: FnOnce(Result<T, String>) + Send + 'static,
{
    pool.spawn(move || done(catch_unwind(AssertUnwindSafe(f)).map_err(|p| panic_message(&*p))));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_panic_becomes_an_internal_error_and_the_pool_lives_on() {
        let pools = CpuPools::new(2, 1).unwrap();
        let r: Result<u32, _> = run(&pools.render, "a render", || panic!("boom")).await;
        match r {
            Err(ServiceError::Internal(m)) => assert!(m.contains("a render"), "{m}"),
            other => panic!("{other:?}"),
        }
        // the pool still runs work after the panic
        assert_eq!(run(&pools.render, "a sum", || 2 + 2).await.unwrap(), 4);
        let msg = run(&pools.background, "work", || -> u8 {
            panic!("{}", String::from("formatted"))
        })
        .await;
        assert!(msg.is_err());
    }

    #[test]
    fn spawned_work_reports_its_panic() {
        let pools = CpuPools::new(1, 1).unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        spawn_catching(
            &pools.background,
            || -> u8 { panic!("lost") },
            move |r| {
                let _ = tx.send(r);
            },
        );
        assert_eq!(rx.recv().unwrap(), Err("lost".to_string()));
    }

    #[test]
    fn sizes_follow_the_config_or_the_machine() {
        let p = CpuPools::new(3, 2).unwrap();
        assert_eq!(p.render.current_num_threads(), 3);
        assert_eq!(p.background.current_num_threads(), 2);
        let auto = CpuPools::new(0, 0).unwrap();
        assert!(auto.render.current_num_threads() >= 1);
        assert!(auto.background.current_num_threads() >= 1);
    }
}
