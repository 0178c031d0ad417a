//! API keys and what each tenant holds: the `api_keys` table, its secrets, and the usage the
//! quotas are checked against.
//!
//! A key's secret is `choreo_<key id, 32 hex>_<256 random bits, 64 hex>`, shown once by
//! `choreo keys create`. Only the SHA-256 of the whole secret is stored. The secret carries 256
//! random bits, so nobody can guess it or invert its hash, and a slow password hash (argon2,
//! bcrypt) would buy nothing but CPU on every request: those exist for low-entropy passwords.
//! The id in the secret finds the row without searching by anything secret; the stored hash is
//! then compared in constant time ([`secret_matches`]).
//!
//! A key is its tenant: `tenant_id` is set to the key's id when it is made, but is a column of
//! its own so that a rotated key could later be given the tenant of the key it replaces.
use super::{JobId, KeyId, StoreFuture, TenantId};
use chrono::{DateTime, Utc};
use rand::RngCore;
use sha2::{Digest, Sha256};

/// What every key's secret starts with, so a leaked one is recognisable (secret scanners).
pub const SECRET_PREFIX: &str = "choreo_";

/// A key's own limits; none means the config's default.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct KeyLimits {
    /// Requests per second (a burst of one second's worth is allowed).
    pub rate_limit_rps: Option<f64>,
    /// Jobs queued or running at once.
    pub max_queued_jobs: Option<u64>,
    /// Bytes of songs, rigs and results stored.
    pub storage_quota_bytes: Option<u64>,
}

impl KeyLimits {
    /// The limits of a tenant whose key sets none of its own: the config's. Read here, not in
    /// the config, so the config stays below the store that reads it.
    pub fn defaults(config: &crate::config::Config) -> Self {
        Self {
            rate_limit_rps: config.rate_limit_rps,
            max_queued_jobs: config.max_queued_jobs,
            storage_quota_bytes: config.storage_quota_bytes,
        }
    }

    /// Each limit of `self`, or `default`'s where `self` has none.
    pub fn or(self, default: KeyLimits) -> KeyLimits {
        KeyLimits {
            rate_limit_rps: self.rate_limit_rps.or(default.rate_limit_rps),
            max_queued_jobs: self.max_queued_jobs.or(default.max_queued_jobs),
            storage_quota_bytes: self.storage_quota_bytes.or(default.storage_quota_bytes),
        }
    }
}

/// A key as stored (never its secret).
#[derive(Clone, Debug, PartialEq)]
pub struct ApiKey {
    pub id: KeyId,
    /// Whose songs, jobs and rigs the key's requests touch.
    pub tenant: TenantId,
    /// The operator's label, for `choreo keys list`.
    pub name: String,
    /// Operators' keys read every tenant's rows.
    pub admin: bool,
    pub limits: KeyLimits,
    /// Hex SHA-256 of the secret.
    pub secret_sha256: String,
    pub created_at: DateTime<Utc>,
    /// Recorded at most once a minute per process (a write per request would serialise them).
    pub last_used_at: Option<DateTime<Utc>>,
    pub revoked_at: Option<DateTime<Utc>>,
}

/// A key to store; [`NewKey::mint`] makes its id and secret.
#[derive(Clone, Debug)]
pub struct NewKey {
    pub id: KeyId,
    pub tenant: TenantId,
    pub name: String,
    pub admin: bool,
    pub limits: KeyLimits,
    pub secret_sha256: String,
}

impl NewKey {
    /// A fresh key (its own tenant) and its secret, which is shown once and never stored.
    pub fn mint(name: &str, admin: bool, limits: KeyLimits) -> (NewKey, String) {
        let id = KeyId::new();
        let mut random = [0u8; 32];
        rand::rngs::OsRng.fill_bytes(&mut random);
        let secret = format!("{SECRET_PREFIX}{}_{}", id.0.simple(), hex::encode(random));
        let key = NewKey {
            id,
            tenant: TenantId(id.0),
            name: name.to_string(),
            admin,
            limits,
            secret_sha256: secret_sha256(&secret),
        };
        (key, secret)
    }
}

/// Hex SHA-256 of a secret, as stored.
pub fn secret_sha256(secret: &str) -> String {
    hex::encode(Sha256::digest(secret.as_bytes()))
}

/// The key id a secret names, if it has a key's shape (it may still be wrong).
pub fn key_id_of(secret: &str) -> Option<KeyId> {
    let rest = secret.strip_prefix(SECRET_PREFIX)?;
    let (id, random) = rest.split_once('_')?;
    if random.len() != 64 || !random.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    uuid::Uuid::try_parse(id).ok().map(KeyId)
}

/// Whether `secret` is the one `key` was made with: the hashes compared without an early exit,
/// so the time taken does not tell how much of a guess matched.
pub fn secret_matches(key: &ApiKey, secret: &str) -> bool {
    constant_time_eq(
        secret_sha256(secret).as_bytes(),
        key.secret_sha256.as_bytes(),
    )
}

/// Compares two byte strings in time that depends only on their lengths.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = u8::from(a.len() != b.len());
    for (i, x) in a.iter().enumerate() {
        diff |= x ^ b.get(i % b.len().max(1)).copied().unwrap_or(0);
    }
    diff == 0
}

/// What a tenant holds now, for its quotas.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Usage {
    /// Jobs queued or running.
    pub queued_jobs: u64,
    /// Bytes of its songs, rigs and succeeded jobs' results.
    pub stored_bytes: u64,
}

/// API keys and per-tenant usage.
pub trait TenantStore: Send + Sync {
    /// Stores a new key.
    fn add_key(&self, key: NewKey) -> StoreFuture<'_, ApiKey>;
    /// Every key, revoked ones included, oldest first.
    fn keys(&self) -> StoreFuture<'_, Vec<ApiKey>>;
    /// One key, revoked or not.
    fn key(&self, id: KeyId) -> StoreFuture<'_, ApiKey>;
    /// Whether any key was ever made: from then on every `/v1` request needs a key (or the
    /// `auth_token`). Revoked keys count, so revoking the last key does not open the service.
    fn any_key(&self) -> StoreFuture<'_, bool>;
    /// Revokes a key (its requests get 401 from then on); revoking twice keeps the first time.
    fn revoke_key(&self, id: KeyId) -> StoreFuture<'_, ApiKey>;
    /// Records that a key was used at `at`.
    fn touch_key(&self, id: KeyId, at: DateTime<Utc>) -> StoreFuture<'_, ()>;
    /// What `tenant` holds now.
    fn usage(&self, tenant: TenantId) -> StoreFuture<'_, Usage>;
    /// Records the bytes of a job's result files (counted by [`TenantStore::usage`]) before they
    /// are published. A job admitted under a storage quota is refused (`QuotaFull`, nothing
    /// recorded) when its tenant already stores that much: so a tenant goes past its quota by one
    /// job's results at most, the job that crossed it.
    fn record_result_bytes(&self, job: JobId, bytes: u64) -> StoreFuture<'_, ()>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_minted_secret_names_its_key_and_matches_only_itself() {
        let (key, secret) = NewKey::mint("a", false, KeyLimits::default());
        assert_eq!(key_id_of(&secret), Some(key.id));
        assert_eq!(key.tenant.0, key.id.0);
        let stored = ApiKey {
            id: key.id,
            tenant: key.tenant,
            name: key.name,
            admin: false,
            limits: key.limits,
            secret_sha256: key.secret_sha256,
            created_at: Utc::now(),
            last_used_at: None,
            revoked_at: None,
        };
        assert!(secret_matches(&stored, &secret));
        let mut wrong = secret.clone();
        wrong.pop();
        wrong.push('x');
        assert!(!secret_matches(&stored, &wrong));
        assert_eq!(key_id_of("choreo_nothex_abc"), None);
        assert_eq!(key_id_of("hunter2"), None);
    }

    #[test]
    fn comparison_is_exact() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"ab", b"abc"));
        assert!(!constant_time_eq(b"abcd", b"abc"));
        assert!(!constant_time_eq(b"", b"abc"));
    }
}
