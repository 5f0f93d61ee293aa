//! Keeps a replica in step with changes made through the others: the active table and the
//! illuminant registry follow the database on a NOTIFY (PostgreSQL), and on a periodic re-read
//! as the safety net (a lost notification, a reconnect). A NOTIFY of a queued job wakes the
//! job workers.

use std::sync::atomic::Ordering;
use std::time::Duration;

use sqlx::postgres::PgListener;

use super::illuminants::follow_stored;
use super::state::AppState;
use super::store::Change;
use super::tables::follow_recorded_active;

/// How often the database is re-read without a notification.
pub const RESYNC_EVERY: Duration = Duration::from_secs(5);

/// What woke the follower.
enum Wake {
    Change(Change),
    /// A periodic re-read, or a (re)connected listener: everything is re-read.
    All,
}

async fn next_notification(listener: &mut Option<PgListener>) -> Wake {
    let Some(l) = listener else {
        return std::future::pending().await;
    };
    match l.recv().await {
        Ok(n) => Change::parse(n.payload()).map_or(Wake::All, Wake::Change),
        Err(e) => {
            // the listener reconnects on the next recv; what was missed is re-read
            tracing::warn!("database notifications: {e}; re-reading");
            tokio::time::sleep(Duration::from_millis(200)).await;
            Wake::All
        }
    }
}

async fn follow(state: &AppState, wake: Wake) {
    let (active, illuminants) = match wake {
        Wake::Change(Change::Jobs) => {
            state.job_notify.notify_waiters();
            state.job_notify.notify_one();
            return;
        }
        Wake::Change(Change::ActiveTable) => (true, false),
        Wake::Change(Change::Illuminants) => (false, true),
        Wake::All => (true, true),
    };
    if illuminants && let Err(e) = follow_stored(state).await {
        tracing::error!("following the illuminant registry: {e}");
    }
    if active && let Err(e) = follow_recorded_active(state).await {
        tracing::error!("following the active table: {e}");
    }
}

/// Runs until shutdown.
pub async fn follower(state: AppState) {
    let mut listener = match state.store.listener().await {
        Ok(l) => l,
        Err(e) => {
            tracing::error!(
                "cannot listen for database notifications: {e}; re-reading every {} s",
                RESYNC_EVERY.as_secs()
            );
            None
        }
    };
    let mut tick = tokio::time::interval(RESYNC_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.tick().await;
    loop {
        let shutdown = state.shutdown_notify.notified();
        tokio::pin!(shutdown);
        shutdown.as_mut().enable();
        if state.shutting_down.load(Ordering::SeqCst) {
            return;
        }
        let wake = tokio::select! {
            w = next_notification(&mut listener) => w,
            _ = tick.tick() => Wake::All,
            _ = &mut shutdown => return,
        };
        follow(&state, wake).await;
    }
}
