//! The store's coordination contract (claim, heartbeat, finish, request_cancel,
//! requeue_expired) on the embedded SQLite backend, with several handles on one data
//! directory standing in for several processes.

use flatmesh::service::store::{SqliteStore, Store};
use std::sync::Arc;

#[test]
fn sqlite_store_keeps_the_coordination_contract() {
    let dir = std::env::temp_dir().join(format!("flatmesh-contract-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let store = SqliteStore::open(&dir).unwrap();
    let open = || -> Arc<dyn Store> { Arc::new(SqliteStore::open(&dir).unwrap()) };
    flatmesh::service::store::contract::check(&store, &open);
    let _ = std::fs::remove_dir_all(&dir);
}
