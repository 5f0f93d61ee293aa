//! Tables other than the active one, loaded on demand (a render naming one with `?table=`, or
//! a DNG whose camera chose one) and kept in a cache bounded by bytes: the kernels' size, which
//! is nearly all of a table's memory. The least recently used tables leave first. The active
//! table is held apart and never counts against the bound; a table larger than the whole bound
//! renders without being kept.
//!
//! Hand-written rather than the `lru` crate: that one bounds the number of entries, and tables
//! differ in size by orders of magnitude (patch size, levels, chroma classes); a cache holds a
//! handful of them, so a scan for the oldest is cheaper than any bookkeeping.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::metrics::CacheCounters;
use crate::l3::L3Table;

/// A table's weight in the cache: its kernels' bytes.
pub fn table_bytes(t: &L3Table) -> usize {
    std::mem::size_of_val(t.kernels.as_slice())
}

struct Entry<T> {
    table: Arc<T>,
    bytes: usize,
    used: u64,
}

struct Lru<T> {
    entries: HashMap<String, Entry<T>>,
    held: usize,
    clock: u64,
}

/// The cache of tables (`T`: a table with what the service keeps beside it) by id, with its
/// counters.
pub struct TableCache<T> {
    bound: usize,
    lru: Mutex<Lru<T>>,
    /// Hits, misses and evictions (exposed by the service's metrics).
    pub counters: CacheCounters,
}

impl<T> TableCache<T> {
    /// A cache holding at most `bound` bytes of kernels.
    pub fn new(bound: usize) -> Self {
        TableCache {
            bound,
            lru: Mutex::new(Lru {
                entries: HashMap::new(),
                held: 0,
                clock: 0,
            }),
            counters: CacheCounters::default(),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Lru<T>> {
        self.lru.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The bound in bytes.
    pub fn bound(&self) -> usize {
        self.bound
    }

    /// The bytes the cached tables hold.
    pub fn held_bytes(&self) -> usize {
        self.lock().held
    }

    /// The cached table `id` (a hit, made the most recently used), or `None` (a miss).
    pub fn get(&self, id: &str) -> Option<Arc<T>> {
        let mut lru = self.lock();
        lru.clock += 1;
        let now = lru.clock;
        match lru.entries.get_mut(id) {
            Some(e) => {
                e.used = now;
                self.counters.hits.inc();
                Some(e.table.clone())
            }
            None => {
                self.counters.misses.inc();
                None
            }
        }
    }

    /// Keeps `table` as `id`, weighing `bytes` ([`table_bytes`]), evicting the least recently
    /// used tables until it fits; returns the ids evicted. A table larger than the bound is not
    /// kept (nothing is evicted for it).
    pub fn insert(&self, id: &str, bytes: usize, table: Arc<T>) -> Vec<String> {
        let mut evicted = Vec::new();
        if bytes > self.bound {
            return evicted;
        }
        let mut lru = self.lock();
        if let Some(old) = lru.entries.remove(id) {
            lru.held -= old.bytes;
        }
        while lru.held + bytes > self.bound {
            let Some(oldest) = lru
                .entries
                .iter()
                .min_by_key(|(_, e)| e.used)
                .map(|(id, _)| id.clone())
            else {
                break;
            };
            if let Some(e) = lru.entries.remove(&oldest) {
                lru.held -= e.bytes;
            }
            self.counters.evictions.inc();
            evicted.push(oldest);
        }
        lru.clock += 1;
        let used = lru.clock;
        lru.held += bytes;
        lru.entries
            .insert(id.to_string(), Entry { table, bytes, used });
        evicted
    }

    /// Drops `id` (a table found unusable); whether it was cached.
    pub fn remove(&self, id: &str) -> bool {
        let mut lru = self.lock();
        match lru.entries.remove(id) {
            Some(e) => {
                lru.held -= e.bytes;
                true
            }
            None => false,
        }
    }

    /// Whether `id` is cached.
    pub fn contains(&self, id: &str) -> bool {
        self.lock().entries.contains_key(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Inserts a table of `floats` kernel values as `id`.
    fn put(c: &TableCache<L3Table>, id: &str, floats: usize) -> Vec<String> {
        let mut t = crate::test_support::tiny_table().clone();
        t.kernels = vec![0.0; floats];
        c.insert(id, table_bytes(&t), Arc::new(t))
    }

    #[test]
    fn the_least_recently_used_tables_leave_to_keep_the_bound() {
        let c = TableCache::new(1000);
        assert!(put(&c, "a", 100).is_empty());
        assert!(put(&c, "b", 100).is_empty());
        assert_eq!(c.held_bytes(), 800);
        assert!(c.get("a").is_some());
        // c needs 400 bytes: b, the least recently used, leaves
        assert_eq!(put(&c, "c", 100), ["b"]);
        assert_eq!(c.held_bytes(), 800);
        assert!(c.contains("a") && c.contains("c") && !c.contains("b"));
        assert!(c.get("b").is_none());
        // larger than the bound: not kept, nothing evicted
        assert!(put(&c, "huge", 1000).is_empty());
        assert!(!c.contains("huge"));
        assert_eq!(put(&c, "d", 250), ["a", "c"]);
        assert_eq!(c.held_bytes(), 1000);
        let n = &c.counters;
        assert_eq!((n.hits.get(), n.misses.get(), n.evictions.get()), (1, 1, 3));
    }
}
