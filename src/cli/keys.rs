//! `choreo keys create|list|revoke`: API keys, written straight to the configured database, so
//! they work while the server runs (it reads keys back within `api::tenancy::KEY_CACHE`).
use anyhow::Context;
use choreo::config::{self as limits, in_range, Config};
use choreo::queue::{ApiKey, KeyId, KeyLimits, NewKey, Store};
use choreo::telemetry::KeysSeen;
use clap::{Args, Subcommand};
use serde_json::json;
use std::sync::Arc;
use std::time::Duration;

use super::ServiceArgs;

#[derive(Args)]
pub struct KeysArgs {
    #[command(subcommand)]
    pub command: KeysCommand,
    /// Where the database lives when `database_url` is unset [env: CHOREO_DATA_DIR].
    #[arg(long, global = true)]
    data_dir: Option<std::path::PathBuf>,
}

impl KeysArgs {
    pub fn service(&self) -> ServiceArgs {
        ServiceArgs {
            data_dir: self.data_dir.clone(),
            ..ServiceArgs::default()
        }
    }
}

#[derive(Subcommand)]
pub enum KeysCommand {
    /// Make a key (its own tenant) and print `{"id", "name", "secret"}`: the secret is shown
    /// this once and only its hash is kept.
    Create(CreateArgs),
    /// Print every key (never a secret) as a JSON array, revoked ones included.
    List,
    /// Revoke a key: its requests get 401 from then on (within a second); its tenant's songs,
    /// jobs and results stay.
    Revoke {
        /// The key's id, as `create` and `list` print it.
        id: KeyId,
    },
}

#[derive(Args)]
pub struct CreateArgs {
    /// A label for the key (who or what uses it).
    #[arg(long)]
    pub name: String,
    /// An operator's key: reads every tenant's songs, jobs and rigs.
    #[arg(long)]
    pub admin: bool,
    /// This key's requests per second, 0.01 to 100000 (default: the config's rate_limit_rps).
    #[arg(long, value_parser = rate_limit_rps)]
    pub rate_limit_rps: Option<f64>,
    /// This key's most jobs queued or running, 1 to 1000000 (default: the config's
    /// max_queued_jobs).
    #[arg(long, value_parser = max_queued_jobs)]
    pub max_queued_jobs: Option<u64>,
    /// This key's most bytes stored, 1024 to 2^50 (default: the config's storage_quota_bytes).
    #[arg(long, value_parser = storage_quota_bytes)]
    pub storage_quota_bytes: Option<u64>,
}

// Checked where the flags are parsed, so a value out of range is refused as any bad flag is:
// a message naming the range, and exit code 2, before the database is opened.
fn rate_limit_rps(s: &str) -> Result<f64, String> {
    let rps: f64 = s
        .parse()
        .map_err(|e| format!("{s:?} is not a number: {e}"))?;
    in_range("the rate", rps, &limits::RATE_LIMIT_RPS)
}

fn max_queued_jobs(s: &str) -> Result<u64, String> {
    let n: u64 = s
        .parse()
        .map_err(|e| format!("{s:?} is not a whole number: {e}"))?;
    in_range("the queue limit", n, &limits::MAX_QUEUED_JOBS)
}

fn storage_quota_bytes(s: &str) -> Result<u64, String> {
    let n: u64 = s
        .parse()
        .map_err(|e| format!("{s:?} is not a whole number of bytes: {e}"))?;
    in_range("the quota", n, &limits::STORAGE_QUOTA_BYTES)
}

fn shown(key: &ApiKey) -> serde_json::Value {
    json!({
        "id": key.id,
        "name": key.name,
        "tenant": key.tenant,
        "admin": key.admin,
        "rate_limit_rps": key.limits.rate_limit_rps,
        "max_queued_jobs": key.limits.max_queued_jobs,
        "storage_quota_bytes": key.limits.storage_quota_bytes,
        "created_at": key.created_at,
        "last_used_at": key.last_used_at,
        "revoked_at": key.revoked_at,
    })
}

/// What `choreo keys create` prints on stderr when its key is the first on a service that had
/// neither keys nor an `auth_token`.
pub const CLOSED_WARNING: &str = "warning: this service was open (no API key, no auth_token); \
from now on every /v1 request needs a key (Authorization: Bearer <secret>), within a second on a \
running server. The songs, jobs and rigs made without a key stay, in the open tenant: an \
operator's key (`choreo keys create --name ops --admin`) reads them, and on a server with \
auth_token set (CHOREO_AUTH_TOKEN) that token still acts as the open tenant.";

/// The API keys in the configured database, for `choreo doctor`; never creates the database.
pub fn seen(config: &Config) -> KeysSeen {
    let database = match config.database() {
        Ok(database) => database,
        Err(e) => return KeysSeen::Unreadable(e.to_string()),
    };
    if let choreo::config::Database::Sqlite(path) = &database {
        if !path.exists() {
            return KeysSeen::NoDatabase;
        }
    }
    let counted = super::runtime().and_then(|runtime| {
        runtime.block_on(async {
            let store: Arc<dyn Store> =
                choreo::queue::open(&database, Duration::from_secs_f64(config.db_timeout_s))
                    .await
                    .context("opening the database")?;
            let keys = store.keys().await.context("reading the keys")?;
            let revoked = keys.iter().filter(|k| k.revoked_at.is_some()).count();
            Ok(KeysSeen::Counted {
                active: keys.len() - revoked,
                revoked,
            })
        })
    });
    counted.unwrap_or_else(|e| KeysSeen::Unreadable(format!("{e:#}")))
}

/// Runs one `choreo keys` command against the configured database.
pub fn run(args: &KeysArgs, config: Config) -> anyhow::Result<()> {
    super::runtime()?.block_on(async {
        let database = config.database()?;
        if let choreo::config::Database::Sqlite(path) = &database {
            if let Some(dir) = path.parent() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
        }
        let store: Arc<dyn Store> =
            choreo::queue::open(&database, Duration::from_secs_f64(config.db_timeout_s))
                .await
                .context("opening the database")?;
        let out = match &args.command {
            KeysCommand::Create(create) => {
                let limits = KeyLimits {
                    rate_limit_rps: create.rate_limit_rps,
                    max_queued_jobs: create.max_queued_jobs,
                    storage_quota_bytes: create.storage_quota_bytes,
                };
                // The config's own checks, applied to the key's overrides.
                Config {
                    rate_limit_rps: limits.rate_limit_rps,
                    max_queued_jobs: limits.max_queued_jobs,
                    storage_quota_bytes: limits.storage_quota_bytes,
                    ..config.clone()
                }
                .validate()
                .context("checking the key's limits (--rate-limit-rps, --max-queued-jobs, --storage-quota-bytes)")?;
                // The first key closes a service that was open (api::auth): say so, and how
                // the rows made without a key stay reachable, rather than let anonymous
                // clients find out from a 401.
                let was_open = config.auth_token.is_none()
                    && !store.any_key().await.context("reading the keys")?;
                let (key, secret) = NewKey::mint(&create.name, create.admin, limits);
                let key = store.add_key(key).await.context("storing the key")?;
                if was_open {
                    eprintln!("{CLOSED_WARNING}");
                }
                json!({"id": key.id, "name": key.name, "secret": secret})
            }
            KeysCommand::List => {
                let keys = store.keys().await.context("reading the keys")?;
                serde_json::Value::Array(keys.iter().map(shown).collect())
            }
            KeysCommand::Revoke { id } => {
                shown(&store.revoke_key(*id).await.context("revoking the key")?)
            }
        };
        println!("{}", serde_json::to_string_pretty(&out)?);
        Ok(())
    })
}
