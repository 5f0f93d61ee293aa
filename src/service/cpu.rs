//! CPU work off the async runtime: two rayon pools, one for renders and one
//! for background work (training jobs, evaluations), so a training job
//! cannot fill the queue renders wait in; and one way to run a closure on a
//! pool that turns a panic into a 500 `internal` answer instead of an
//! aborted process (rayon aborts on a panic in a spawned job that nothing
//! catches).
//!
//! The pools share the cores. On Linux the background pool's threads run at
//! a lower scheduling priority (`training.background_priority`): under
//! `idle`, the default, a training job takes only the CPU time renders leave.
//! Measured with 8 clients rendering 2 MP frames to PNG beside a training
//! job (wrk, 20 s each, same run): 32.7 req/s without the job; beside it
//! 27.3 at `normal`, 30.3 at `low` (niceness 10) and 32.5 at `idle`.

use std::panic::{AssertUnwindSafe, catch_unwind};

use super::error::ServiceError;

/// How the background pool's threads are scheduled against renders (Linux;
/// elsewhere every thread runs at the process's priority).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackgroundPriority {
    /// `SCHED_IDLE`: only the CPU time nothing else wants.
    #[default]
    Idle,
    /// Niceness 10.
    Low,
    /// The same as renders.
    Normal,
}

impl std::str::FromStr for BackgroundPriority {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "idle" => Ok(Self::Idle),
            "low" => Ok(Self::Low),
            "normal" => Ok(Self::Normal),
            _ => Err(format!(
                "background priority {s:?}: expected idle, low or normal"
            )),
        }
    }
}

/// The service's CPU pools.
pub struct CpuPools {
    /// Renders (and their decoding and encoding), and the short fits of illuminant
    /// registrations, which would wait behind a training job on the background pool.
    pub render: rayon::ThreadPool,
    /// Training jobs and evaluations.
    pub background: rayon::ThreadPool,
}

impl CpuPools {
    /// `render_threads` and `background_threads` of 0 pick a size from the
    /// machine: every core for renders, half of them (at least one) for
    /// background work. The pools share the cores; what they separate is
    /// the queue, so a render never waits behind a training job's tasks.
    /// `background` sets the background threads' scheduling priority.
    pub fn new(
        render_threads: usize,
        background_threads: usize,
        background: BackgroundPriority,
    ) -> Result<Self, ServiceError> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let pick = |n: usize, auto: usize| if n == 0 { auto.max(1) } else { n };
        let build = |name: &'static str, n: usize, priority: BackgroundPriority| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(move |i| format!("l3-{name}-{i}"))
                .start_handler(move |_| lower_priority(name, priority))
                // a last line of defence: `run` catches panics itself
                .panic_handler(move |_| tracing::error!(pool = name, "a CPU task panicked"))
                .build()
                .map_err(|e| ServiceError::Internal(format!("the {name} thread pool: {e}")))
        };
        Ok(Self {
            render: build(
                "render",
                pick(render_threads, cores),
                BackgroundPriority::Normal,
            )?,
            background: build(
                "background",
                pick(background_threads, cores / 2),
                background,
            )?,
        })
    }
}

/// Lower the calling thread's scheduling priority (Linux: each thread has
/// its own policy and niceness). A refusal is logged, not fatal: the pool
/// then runs at the process's priority.
fn lower_priority(pool: &'static str, priority: BackgroundPriority) {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: the calls take plain integers and a pointer to a local
        // `sched_param` that outlives them; pid 0 is the calling thread.
        let rc = unsafe {
            match priority {
                BackgroundPriority::Normal => return,
                BackgroundPriority::Low => {
                    libc::setpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t, 10)
                }
                BackgroundPriority::Idle => {
                    let param = libc::sched_param { sched_priority: 0 };
                    libc::sched_setscheduler(0, libc::SCHED_IDLE, &param)
                }
            }
        };
        if rc != 0 {
            tracing::warn!(pool, ?priority, error = %std::io::Error::last_os_error(), "cannot lower the thread priority");
        }
    }
    #[cfg(not(target_os = "linux"))]
    if priority != BackgroundPriority::Normal {
        tracing::debug!(pool, ?priority, "thread priorities are set on Linux only");
    }
}

/// The calling thread's scheduling policy and niceness (Linux), for tests.
#[cfg(all(test, target_os = "linux"))]
fn current_priority() -> (i32, i32) {
    // SAFETY: plain integer arguments; pid 0 is the calling thread.
    unsafe {
        (
            libc::sched_getscheduler(0),
            libc::getpriority(libc::PRIO_PROCESS, libc::gettid() as libc::id_t),
        )
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
        let pools = CpuPools::new(2, 1, BackgroundPriority::Idle).unwrap();
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
        let pools = CpuPools::new(1, 1, BackgroundPriority::Idle).unwrap();
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
        let p = CpuPools::new(3, 2, BackgroundPriority::Normal).unwrap();
        assert_eq!(p.render.current_num_threads(), 3);
        assert_eq!(p.background.current_num_threads(), 2);
        let auto = CpuPools::new(0, 0, BackgroundPriority::Normal).unwrap();
        assert!(auto.render.current_num_threads() >= 1);
        assert!(auto.background.current_num_threads() >= 1);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn background_threads_run_at_a_lower_priority() {
        let (policy, nice) = current_priority();
        let idle = CpuPools::new(1, 1, BackgroundPriority::Idle).unwrap();
        assert_eq!(idle.render.install(current_priority), (policy, nice));
        assert_eq!(
            idle.background.install(current_priority).0,
            libc::SCHED_IDLE
        );
        let low = CpuPools::new(1, 1, BackgroundPriority::Low).unwrap();
        // niceness only rises for an unprivileged thread, and stops at 19
        assert_eq!(
            low.background.install(current_priority),
            (policy, (nice + 10).min(19))
        );
        assert_eq!("low".parse(), Ok(BackgroundPriority::Low));
        assert!("high".parse::<BackgroundPriority>().is_err());
    }
}
