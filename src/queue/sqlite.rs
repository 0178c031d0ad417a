//! The SQLite store: WAL mode, `synchronous=NORMAL`, one file beside one process.
//!
//! The queue's statements are in `sql.rs`; this file holds what is SQLite's own. SQLite has a
//! single writer, so a claim that selects and updates in one statement cannot hand the same job
//! to two workers, and no row needs locking. Every write transaction starts with its write, so a
//! waiting writer is handled by the busy timeout and never surfaces as `SQLITE_BUSY`.
use super::sql::{Dialect, SqlStore};
use super::{QueueError, StoreFuture};
use sqlx::sqlite::{
    Sqlite, SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteQueryResult,
    SqliteSynchronous,
};
use sqlx::Pool;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use uuid::Uuid;

/// How long a writer waits for the lock before SQLite gives up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(30);
/// Connections in the pool; SQLite serialises writers anyway, readers run in parallel in WAL.
const MAX_CONNECTIONS: u32 = 8;

/// The jobs and songs of one SQLite file.
pub type SqliteStore = SqlStore<Sqlite>;

impl Dialect for Sqlite {
    /// Ids are hyphenated UUID text (`migrations/`).
    type Id = String;

    const SKIP_LOCKED: &'static str = "";

    fn backoff_factor(cap: &str) -> String {
        format!("(1 << MIN(attempts - 1, {cap}))")
    }

    fn id(id: Uuid) -> String {
        id.hyphenated().to_string()
    }

    fn uuid(id: String) -> Result<Uuid, uuid::Error> {
        Uuid::parse_str(&id)
    }

    fn rows_affected(done: &SqliteQueryResult) -> u64 {
        done.rows_affected()
    }

    fn watch(
        _pool: &Pool<Sqlite>,
        _wake: Arc<Notify>,
        _shutdown: CancellationToken,
    ) -> StoreFuture<'_, ()> {
        // SQLite cannot notify another process: this process's registrations wake its workers
        // directly (`worker::Context::wake`), other processes' jobs are found by polling.
        Box::pin(async { Ok(()) })
    }
}

impl SqlStore<Sqlite> {
    /// Opens (creating if needed) the database file and runs the migrations.
    pub async fn open(path: &Path) -> Result<Self, QueueError> {
        let options = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(BUSY_TIMEOUT)
            .foreign_keys(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(MAX_CONNECTIONS)
            .acquire_timeout(BUSY_TIMEOUT)
            .connect_with(options)
            .await?;
        sqlx::migrate!("./migrations").run(&pool).await?;
        Ok(Self::from_pool(pool))
    }
}
