//! The store's behaviour and coordination contract, one suite run unchanged on both
//! backends: the embedded SQLite store (several handles on one data directory standing in
//! for several processes) and PostgreSQL (a throwaway cluster; several pools on one
//! database).

mod common;

use common::pg::PgCluster;
use flatmesh::service::store::{PgStore, SqliteStore, Store};
use std::sync::Arc;

#[test]
fn sqlite_store_keeps_the_contract() {
    let dir = std::env::temp_dir().join(format!("flatmesh-contract-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let store = SqliteStore::open(&dir).unwrap();
    let open = || -> Arc<dyn Store> { Arc::new(SqliteStore::open(&dir).unwrap()) };
    flatmesh::service::store::contract::check(&store, &open);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn postgres_store_keeps_the_contract() {
    let Some(pg) = PgCluster::start("PostgreSQL store contract") else {
        return;
    };
    let url = pg.database("contract");
    let store = PgStore::open(&url, 4).unwrap();
    assert_eq!(store.migrations().unwrap(), [1, 2, 3]);
    let open = || -> Arc<dyn Store> { Arc::new(PgStore::open(&url, 4).unwrap()) };
    flatmesh::service::store::contract::check(&store, &open);
    // The webhook secret: the first to ask sets it, every handle gets the same.
    assert_eq!(
        store
            .shared_webhook_secret("whsec_first")
            .unwrap()
            .as_deref(),
        Some("whsec_first")
    );
    assert_eq!(
        open()
            .shared_webhook_secret("whsec_second")
            .unwrap()
            .as_deref(),
        Some("whsec_first")
    );
    // Opening again applies nothing twice.
    assert_eq!(
        PgStore::open(&url, 1).unwrap().migrations().unwrap(),
        [1, 2, 3]
    );
}

/// Replicas starting together on an empty database: each migration is applied once and
/// every one of them opens.
#[test]
fn postgres_migrations_apply_once_under_concurrent_starts() {
    let Some(pg) = PgCluster::start("PostgreSQL concurrent migrations") else {
        return;
    };
    let url = pg.database("migrate");
    let stores: Vec<PgStore> = std::thread::scope(|sc| {
        let ts: Vec<_> = (0..4)
            .map(|_| sc.spawn(|| PgStore::open(&url, 1).unwrap()))
            .collect();
        ts.into_iter().map(|t| t.join().unwrap()).collect()
    });
    for s in &stores {
        assert_eq!(s.migrations().unwrap(), [1, 2, 3]);
        s.ping().unwrap();
    }
}

/// A queued job wakes a watcher on another handle at once (LISTEN/NOTIFY), well before any
/// polling interval.
#[test]
fn postgres_queue_notifications_reach_other_handles() {
    let Some(pg) = PgCluster::start("PostgreSQL queue notifications") else {
        return;
    };
    let url = pg.database("notify");
    let a = PgStore::open(&url, 2).unwrap();
    let b = PgStore::open(&url, 2).unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    let tx = std::sync::Mutex::new(tx);
    b.watch_queue(Arc::new(move || {
        let _ = tx.lock().unwrap().send(());
    }))
    .unwrap();
    // The listener connects in the background: insert until it hears one.
    let t0 = std::time::Instant::now();
    let mut k = 0;
    loop {
        let j = flatmesh::service::domain::JobRecord::queued(&format!("j_n{k}"), "report", "m", 0);
        a.insert_job(&j).unwrap();
        k += 1;
        if rx
            .recv_timeout(std::time::Duration::from_millis(100))
            .is_ok()
        {
            break;
        }
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(10),
            "no notification in 10 s"
        );
    }
}
