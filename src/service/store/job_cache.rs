//! A replica's cache of job rows for status polls on the shared store.
//!
//! Why: on PostgreSQL every poll was a round trip through two processes that, on a small
//! host whose cores the workers keep busy, wait to be scheduled (poll p99 19–22 ms against
//! 0.4 ms on SQLite, `benches/service_load.rs`). A polled job's row changes rarely (claim,
//! a heartbeat every quarter lease, finish), so a poll can almost always be answered from
//! memory if the replica learns of every change.
//!
//! How it stays correct: every change to a job row sends `NOTIFY flatmesh_job_changes, id`
//! (a trigger, so no write path can forget it; queued jobs, whose claim is the busiest
//! write, are neither announced nor cached) and the replica's listener drops the entry;
//! writes made through this replica drop it as soon as they commit, so a replica always
//! reads its own writes. A reader fills the cache only through a token taken *before* its
//! query: a change that commits after the query's snapshot is announced after the token was
//! taken and revokes it, so a stale row is never stored. The cache serves only while the
//! listener is connected; losing it empties the cache (notifications may have been missed).
//! What remains is the announcement delay: a change made through another replica is seen
//! here once its notification arrives (well under a millisecond on an idle host). Should
//! the listener's connection die silently, its keepalive (every 2 s) notices, and no entry
//! is served older than 10 s in any case.

use crate::service::domain::{JobRecord, Status};
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Entries kept at most; beyond it an arbitrary entry makes room (polls of it just miss).
const CAPACITY: usize = 8192;
/// An entry older than this is read again, whatever was announced: the bound on staleness
/// should notifications ever stop without the listener noticing.
const MAX_AGE: Duration = Duration::from_secs(10);

enum Slot {
    /// A read is in flight, begun at this instant; only the holder of this token may fill
    /// the slot.
    Pending(u64, Instant),
    Filled(Box<JobRecord>, Instant),
}

#[derive(Default)]
struct Inner {
    /// Notifications are being received: the cache may serve.
    live: bool,
    slots: HashMap<String, Slot>,
    next_token: u64,
    /// Polls answered from memory.
    hits: u64,
}

/// The cache; cheap to share behind an `Arc`.
#[derive(Default)]
pub struct JobCache {
    inner: Mutex<Inner>,
}

/// Permission to fill one slot with the row a read is about to fetch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Token(u64);

impl JobCache {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cached row, when the cache is live and holds one.
    pub fn get(&self, id: &str) -> Option<JobRecord> {
        let mut g = self.lock();
        let hit = match g.slots.get(id) {
            Some(Slot::Filled(j, at)) if g.live && at.elapsed() < MAX_AGE => Some((**j).clone()),
            _ => None,
        };
        g.hits += hit.is_some() as u64;
        hit
    }

    /// Before reading `id` from the database: a token to store the answer with, or None
    /// when the cache is not live or another read of `id` is already in flight.
    pub fn begin(&self, id: &str) -> Option<Token> {
        let mut g = self.lock();
        if !g.live {
            return None;
        }
        match g.slots.get(id) {
            Some(Slot::Filled(_, at)) if at.elapsed() >= MAX_AGE => {}
            Some(_) => return None,
            None => {}
        }
        if g.slots.len() >= CAPACITY {
            let victim = g.slots.keys().next().cloned();
            if let Some(k) = victim {
                g.slots.remove(&k);
            }
        }
        g.next_token += 1;
        let t = g.next_token;
        g.slots
            .insert(id.to_string(), Slot::Pending(t, Instant::now()));
        Some(Token(t))
    }

    /// Store what the read of `id` found (None: no such job, nothing stored) if its token
    /// still stands, i.e. no change to `id` was announced since [`JobCache::begin`].
    pub fn fill(&self, id: &str, token: Token, job: Option<&JobRecord>) {
        let mut g = self.lock();
        // The row is as old as the read's start (a wait for a connection counts).
        let begun = match g.slots.get(id) {
            Some(Slot::Pending(t, at)) if *t == token.0 => *at,
            _ => return,
        };
        match job {
            // Queued rows change silently (see the trigger), so they are never kept.
            Some(j) if g.live && j.status != Status::Queued => {
                g.slots
                    .insert(id.to_string(), Slot::Filled(Box::new(j.clone()), begun));
            }
            _ => {
                g.slots.remove(id);
            }
        }
    }

    /// A change to `id` was announced or made here: forget it (and revoke a pending read).
    pub fn invalidate(&self, id: &str) {
        self.lock().slots.remove(id);
    }

    /// The listener connected (true) or lost its connection (false); either way everything
    /// cached so far is dropped, since notifications may have been missed in between.
    pub fn set_live(&self, live: bool) {
        let mut g = self.lock();
        g.live = live;
        g.slots.clear();
    }

    /// Whether the cache serves (its listener is connected), and how many polls it answered.
    pub fn stats(&self) -> (bool, u64) {
        let g = self.lock();
        (g.live, g.hits)
    }

    /// Entries held (filled or pending), for tests.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.lock().slots.len()
    }

    /// Nothing held.
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(id: &str, status: Status) -> JobRecord {
        let mut j = JobRecord::queued(id, "report", "m1", 0);
        j.status = status;
        j
    }

    #[test]
    fn serves_only_what_a_standing_token_filled_while_live() {
        let c = JobCache::default();
        // Not live: nothing is cached.
        assert_eq!(c.begin("a"), None);
        c.set_live(true);
        let t = c.begin("a").unwrap();
        // A second concurrent read does not take the slot.
        assert_eq!(c.begin("a"), None);
        assert!(c.get("a").is_none(), "a pending slot serves nothing");
        c.fill("a", t, Some(&job("a", Status::Running)));
        assert_eq!(c.get("a").unwrap().status, Status::Running);
        // A hit is not re-read, so there is no token to take.
        assert_eq!(c.begin("a"), None);
    }

    #[test]
    fn a_change_announced_during_the_read_revokes_its_token() {
        let c = JobCache::default();
        c.set_live(true);
        let t = c.begin("a").unwrap();
        // The row changed after the read's snapshot: the notification (or the local write)
        // arrives before the read returns its older row.
        c.invalidate("a");
        c.fill("a", t, Some(&job("a", Status::Running)));
        assert!(c.get("a").is_none(), "the stale row must not be cached");
        // A later read, begun after the change, may fill it.
        let t2 = c.begin("a").unwrap();
        c.fill("a", t2, Some(&job("a", Status::Succeeded)));
        assert_eq!(c.get("a").unwrap().status, Status::Succeeded);
        // ... and an old token cannot overwrite it.
        c.fill("a", t, Some(&job("a", Status::Running)));
        assert_eq!(c.get("a").unwrap().status, Status::Succeeded);
        c.invalidate("a");
        assert!(c.get("a").is_none());
    }

    #[test]
    fn losing_the_listener_empties_and_disables_the_cache() {
        let c = JobCache::default();
        c.set_live(true);
        let t = c.begin("a").unwrap();
        c.fill("a", t, Some(&job("a", Status::Running)));
        let pending = c.begin("b").unwrap();
        c.set_live(false);
        assert!(c.get("a").is_none());
        assert!(c.is_empty());
        // A read in flight across the outage stores nothing.
        c.fill("b", pending, Some(&job("b", Status::Running)));
        assert!(c.is_empty());
        c.set_live(true);
        assert!(
            c.get("a").is_none(),
            "reconnecting does not bring old rows back"
        );
    }

    #[test]
    fn missing_and_queued_jobs_are_not_cached_and_capacity_holds() {
        let c = JobCache::default();
        c.set_live(true);
        let t = c.begin("gone").unwrap();
        c.fill("gone", t, None);
        assert!(c.is_empty());
        // A queued job's claim is not announced: caching it would serve "queued" for ever.
        let t = c.begin("q").unwrap();
        c.fill("q", t, Some(&job("q", Status::Queued)));
        assert!(c.is_empty());
        for k in 0..CAPACITY + 10 {
            let id = format!("j{k}");
            let t = c.begin(&id).unwrap();
            c.fill(&id, t, Some(&job(&id, Status::Succeeded)));
        }
        assert_eq!(c.len(), CAPACITY);
    }
}
