//! API keys at request time, and each tenant's limits: the key cache, the per-tenant rate
//! limiter and the queue and storage quotas.
//!
//! Keys live in the database (`choreo keys create|list|revoke` write them there, from another
//! process, while the server runs), so every API process reads them back, through a cache that
//! keeps a key for [`KEY_CACHE`]: a revocation takes effect within that time, and a burst of
//! requests costs one read. Whether any key exists (then every `/v1` request must carry one, or
//! the `auth_token`) is cached as long while it is "no", and for good once it is "yes": keys
//! are never deleted, only revoked.
//!
//! The rate limit is a GCRA (the generic cell rate algorithm, as in the `governor` crate, which
//! is not in this build's dependencies; the algorithm is the few lines of [`RateLimiter::admit`]):
//! one "theoretical arrival time" per tenant, a burst of one second's worth of requests. It is
//! per process: with N API processes a tenant gets up to N times its rate.
use super::auth::Caller;
use super::problem::ApiError;
use super::AppState;
use crate::queue::{ApiKey, KeyId, Store, TenantId};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How long a key read from the database is trusted (a revocation takes effect within it).
pub const KEY_CACHE: Duration = Duration::from_secs(1);
/// A key's last use is written at most this often (one write per request would serialise them).
const TOUCH_EVERY: Duration = Duration::from_secs(60);
/// Past this many tenants tracked, the limiter forgets those that are idle.
const LIMITER_PRUNE_AT: usize = 4096;

struct CachedKey {
    key: Option<ApiKey>,
    read_at: Instant,
}

/// Keys as recently read, and whether any exists.
#[derive(Default)]
pub struct Tenancy {
    keys: Mutex<HashMap<KeyId, CachedKey>>,
    /// When each key's last use was last written by this process.
    touched: Mutex<HashMap<KeyId, Instant>>,
    /// `Some(true)` for good once seen; `Some(false)` is re-read after [`KEY_CACHE`].
    any_key: Mutex<Option<(bool, Instant)>>,
    pub limiter: RateLimiter,
    /// Event streams open per tenant.
    pub streams: Arc<StreamSlots>,
}

/// Event streams each tenant holds open in this process: `max_event_streams_per_key` each, so
/// one key's thousand streams cannot take the connections every other client needs.
#[derive(Default)]
pub struct StreamSlots {
    open: Mutex<HashMap<TenantId, usize>>,
}

/// One open event stream of a tenant; its slot is given back when dropped (the stream ended,
/// or its client went away).
pub struct StreamSlot {
    slots: Arc<StreamSlots>,
    tenant: TenantId,
}

impl StreamSlots {
    /// A slot for one more stream of `tenant`, or `429 too-many-event-streams` past `limit`.
    pub fn take(self: &Arc<Self>, tenant: TenantId, limit: usize) -> Result<StreamSlot, ApiError> {
        let mut open = lock(&self.open);
        let count = open.entry(tenant).or_default();
        if *count >= limit {
            return Err(ApiError::TooManyEventStreams { limit });
        }
        *count += 1;
        Ok(StreamSlot {
            slots: self.clone(),
            tenant,
        })
    }

    /// Streams `tenant` holds open now.
    pub fn open(&self, tenant: TenantId) -> usize {
        lock(&self.open).get(&tenant).copied().unwrap_or(0)
    }
}

impl Drop for StreamSlot {
    fn drop(&mut self) {
        let mut open = lock(&self.slots.open);
        if let Some(count) = open.get_mut(&self.tenant) {
            *count = count.saturating_sub(1);
            if *count == 0 {
                open.remove(&self.tenant);
            }
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic while holding one of these locks leaves plain data behind; keep using it.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Tenancy {
    /// Whether `/v1` requests need a key (or the `auth_token`): any key was ever made.
    pub async fn keys_required(&self, store: &dyn Store) -> Result<bool, ApiError> {
        if let Some((any, read_at)) = *lock(&self.any_key) {
            if any || read_at.elapsed() < KEY_CACHE {
                return Ok(any);
            }
        }
        let any = store.any_key().await?;
        *lock(&self.any_key) = Some((any, Instant::now()));
        Ok(any)
    }

    /// The key `id`, revoked or not; none when it does not exist.
    pub async fn key(&self, store: &dyn Store, id: KeyId) -> Result<Option<ApiKey>, ApiError> {
        if let Some(cached) = lock(&self.keys).get(&id) {
            if cached.read_at.elapsed() < KEY_CACHE {
                return Ok(cached.key.clone());
            }
        }
        let key = match store.key(id).await {
            Ok(key) => Some(key),
            Err(crate::queue::QueueError::KeyNotFound(_)) => None,
            Err(e) => return Err(e.into()),
        };
        let mut keys = lock(&self.keys);
        if keys.len() >= LIMITER_PRUNE_AT {
            keys.retain(|_, c| c.read_at.elapsed() < KEY_CACHE);
        }
        keys.insert(
            id,
            CachedKey {
                key: key.clone(),
                read_at: Instant::now(),
            },
        );
        Ok(key)
    }

    /// Records that `key` was used, in the background, at most once per [`TOUCH_EVERY`].
    pub fn record_use(&self, store: &Arc<dyn Store>, key: KeyId) {
        {
            let mut touched = lock(&self.touched);
            if touched
                .get(&key)
                .is_some_and(|at| at.elapsed() < TOUCH_EVERY)
            {
                return;
            }
            touched.insert(key, Instant::now());
        }
        let store = store.clone();
        tokio::spawn(async move {
            if let Err(e) = store.touch_key(key, chrono::Utc::now()).await {
                tracing::warn!(error = %e, %key, "could not record the key's last use");
            }
        });
    }
}

/// Requests per second per tenant: a GCRA over one theoretical arrival time per tenant.
#[derive(Default)]
pub struct RateLimiter {
    next: Mutex<HashMap<TenantId, Instant>>,
}

impl RateLimiter {
    /// Counts one request of `tenant` against `rps` (a burst of `ceil(rps)` is allowed); the
    /// error says how many seconds to wait.
    pub fn admit(&self, tenant: TenantId, rps: f64) -> Result<(), ApiError> {
        // Limits are checked where they are set, but a row written by hand (or by an older
        // version) could hold anything: held to the range here too, so no stored value can make
        // the arithmetic below overflow (1e-19 per second once panicked every request).
        let range = crate::config::RATE_LIMIT_RPS;
        let rps = if rps.is_nan() {
            *range.start()
        } else {
            rps.clamp(*range.start(), *range.end())
        };
        let now = Instant::now();
        let interval = Duration::from_secs_f64(1.0 / rps);
        // A burst of one second's worth: `burst` requests may arrive at once.
        let burst = rps.ceil().max(1.0);
        let tolerance = interval.mul_f64(burst - 1.0);
        let mut next = lock(&self.next);
        if next.len() >= LIMITER_PRUNE_AT {
            next.retain(|_, at| *at > now);
        }
        let tat = next.get(&tenant).copied().unwrap_or(now).max(now);
        let allowed_at = tat.checked_sub(tolerance).unwrap_or(now);
        let Some(after) = tat.checked_add(interval) else {
            return Err(ApiError::RateLimited {
                rps,
                retry_after_s: interval.as_secs_f64().ceil().max(1.0) as u64,
            });
        };
        if allowed_at > now {
            let wait = allowed_at - now;
            return Err(ApiError::RateLimited {
                rps,
                retry_after_s: wait.as_secs_f64().ceil().max(1.0) as u64,
            });
        }
        next.insert(tenant, after);
        Ok(())
    }
}

/// Refuses an upload of `size` bytes that would take the caller's tenant past its storage quota,
/// before the upload is read. Only an early answer: uploads racing each other all pass it, and
/// the store holds the quota where it inserts the row (`queue::sql::quota`).
pub async fn check_storage(state: &AppState, caller: &Caller, size: u64) -> Result<(), ApiError> {
    let Some(quota) = caller.limits.storage_quota_bytes else {
        return Ok(());
    };
    let used = state.store.usage(caller.tenant).await?.stored_bytes;
    if used.saturating_add(size) > quota {
        return Err(ApiError::StorageQuotaExceeded { used, size, quota });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limiter_allows_a_burst_then_refuses_with_a_wait() {
        let limiter = RateLimiter::default();
        let (a, b) = (TenantId::new(), TenantId::new());
        for _ in 0..5 {
            limiter.admit(a, 5.0).expect("within the burst");
        }
        let Err(ApiError::RateLimited { retry_after_s, .. }) = limiter.admit(a, 5.0) else {
            panic!("the sixth request at once is refused")
        };
        assert_eq!(retry_after_s, 1);
        limiter
            .admit(b, 5.0)
            .expect("another tenant has its own budget");
        std::thread::sleep(Duration::from_millis(250));
        limiter.admit(a, 5.0).expect("one interval later, one more");
    }

    /// A stored rate out of range (1e-19 once overflowed the arrival time and panicked every
    /// request) is held to the range: each call answers.
    #[test]
    fn rates_out_of_range_are_held_to_the_range() {
        let limiter = RateLimiter::default();
        for rps in [1e-19, f64::NAN, 0.0, -5.0, 1e300, f64::INFINITY] {
            let tenant = TenantId::new();
            assert!(limiter.admit(tenant, rps).is_ok(), "{rps}");
            for _ in 0..3 {
                match limiter.admit(tenant, rps) {
                    Ok(()) => {}
                    Err(ApiError::RateLimited { retry_after_s, .. }) => {
                        assert!(retry_after_s <= 100, "{rps}: {retry_after_s}")
                    }
                    Err(e) => panic!("{rps}: {e}"),
                }
            }
        }
    }

    #[test]
    fn a_tenants_streams_are_capped_and_given_back() {
        let slots = Arc::new(StreamSlots::default());
        let (a, b) = (TenantId::new(), TenantId::new());
        let held: Vec<_> = (0..3).map(|_| slots.take(a, 3).expect("room")).collect();
        assert!(matches!(
            slots.take(a, 3),
            Err(ApiError::TooManyEventStreams { limit: 3 })
        ));
        let _other = slots.take(b, 3).expect("another tenant has its own");
        drop(held);
        assert_eq!(slots.open(a), 0);
        slots.take(a, 3).expect("given back");
    }
}
