//! The table of a render request ([`crate::pipeline::choice`] decides): the active table, the
//! one `?table=` names, or the newest good table trained for the catalogue sensor of the
//! camera a DNG names, used without being activated. Tables other than the active one come
//! from the byte-bounded cache ([`super::table_cache`]), loaded (checksum verified) on a miss.

use std::sync::Arc;

use super::ServiceError;
use super::state::{ActiveTable, AppState};
use super::table_cache::table_bytes;
use super::tables;
use crate::pipeline::{Input, StoredTables, TableChoice, choose_table};

/// The table a render uses, and why.
pub(super) struct Chosen {
    pub table: Arc<ActiveTable>,
    pub choice: TableChoice,
    /// Whether its prepared renderers may be cached: it is the active table or is held in the
    /// table cache (a table too large for the cache renders with renderers made afresh).
    pub keep_renderers: bool,
}

/// The table for a request naming `named` (if any) with `input`.
pub(super) async fn table_for(
    state: &AppState,
    named: Option<&str>,
    input: &Input,
) -> Result<Chosen, ServiceError> {
    let camera = if named.is_none() {
        input.camera()
    } else {
        None
    };
    let stored = match &camera {
        Some(_) => tables::stored_tables(&state.store).await?,
        None => StoredTables::default(),
    };
    let choice = choose_table(named, camera.as_ref(), &stored)?;
    let active = state.active.load_full();
    let (table, keep_renderers) = match (choice.table_id(), active) {
        (None, Some(a)) => (a, true),
        (None, None) => {
            return Err(ServiceError::NotReady(
                "no table is active yet (the default table may still be training; see /readyz)"
                    .into(),
            ));
        }
        (Some(id), Some(a)) if a.id == id => (a, true),
        (Some(id), _) => cached(state, id).await?,
    };
    Ok(Chosen {
        table,
        choice,
        keep_renderers,
    })
}

/// Table `id` from the cache, else loaded and kept (evicting the least recently used, whose
/// prepared renderers go too); with whether the cache holds it.
async fn cached(state: &AppState, id: &str) -> Result<(Arc<ActiveTable>, bool), ServiceError> {
    if let Some(t) = state.tables.get(id) {
        return Ok((t, true));
    }
    let t = Arc::new(tables::load_usable(state, id).await?);
    let bytes = table_bytes(&t.table);
    let evicted = state.tables.insert(id, bytes, t.clone());
    state.forget_tables(&evicted);
    Ok((t, state.tables.contains(id)))
}
