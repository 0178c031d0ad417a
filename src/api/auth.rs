//! Who is calling: the `/v1` authentication middleware and the [`Caller`] it hands to handlers.
//!
//! Every `/v1` request runs [`authenticate`] first; it either answers 401 or puts a [`Caller`] in
//! the request's extensions. Handlers take `caller: Caller` and scope every store call by
//! [`Caller::scope`], so a tenant never reads, lists or changes another's rows: another tenant's
//! id is a 404, exactly like an id that never existed.
//!
//! Who may call, in order: a `Bearer` secret shaped like an API key's (`choreo_…`) must be a
//! key that exists, matches and is not revoked: its tenant is the caller. Otherwise, with an
//! `auth_token` configured, the token must match: the caller is the single open tenant
//! ([`Caller::OPEN`]). Otherwise, once any key was made (revoked ones count), a key is needed.
//! With neither keys nor token the service is open, everything [`TenantId::OPEN`]'s. Every
//! tenant's requests then pass its rate limit ([`super::tenancy`]).
use super::problem::ApiError;
use super::AppState;
use crate::queue::keys::{constant_time_eq, key_id_of, secret_matches};
use crate::queue::{KeyId, KeyLimits, Scope, TenantId};
use axum::extract::{FromRequestParts, Request, State};
use axum::http::{header, request::Parts};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

/// The tenant a request acts for, and whether it may act for all (operators' keys).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Caller {
    pub tenant: TenantId,
    /// The API key the request came with; none for an open service or the `auth_token`.
    pub key: Option<KeyId>,
    pub admin: bool,
    /// The tenant's limits: its key's own, else the config's defaults.
    pub limits: KeyLimits,
}

impl Caller {
    /// An open service, or the single `auth_token`: one tenant, [`TenantId::OPEN`] (no limits
    /// here; `authenticate` gives it the config's).
    pub const OPEN: Caller = Caller {
        tenant: TenantId::OPEN,
        key: None,
        admin: false,
        limits: KeyLimits {
            rate_limit_rps: None,
            max_queued_jobs: None,
            storage_quota_bytes: None,
        },
    };

    /// What this caller's store reads and changes may touch: its own tenant's rows, or every
    /// tenant's for an operator's (`--admin`) key. New rows are always the caller's tenant's.
    pub fn scope(&self) -> Scope {
        if self.admin {
            Scope::All
        } else {
            Scope::Tenant(self.tenant)
        }
    }
}

impl FromRequestParts<AppState> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut Parts,
        _state: &AppState,
    ) -> Result<Self, Self::Rejection> {
        // Only `authenticate` inserts a Caller; a route outside it fails closed.
        parts
            .extensions
            .get::<Caller>()
            .copied()
            .ok_or(ApiError::Unauthorized)
    }
}

/// The token of an `Authorization` header's `Bearer` credentials (the scheme is
/// case-insensitive, RFC 9110 §11.1).
fn bearer_token(value: &str) -> Option<&str> {
    let (scheme, token) = value.trim().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| token.trim_start_matches(' '))
}

/// Who sent `given` (the `Bearer` credentials, if any); `None` when nobody may.
async fn identify(state: &AppState, given: Option<&str>) -> Result<Option<Caller>, ApiError> {
    let defaults = KeyLimits::defaults(&state.config);
    let open = Caller {
        limits: defaults,
        ..Caller::OPEN
    };
    if let Some(id) = given.and_then(key_id_of) {
        let Some(key) = state.tenancy.key(state.store.as_ref(), id).await? else {
            return Ok(None);
        };
        let secret = given.unwrap_or_default();
        if key.revoked_at.is_some() || !secret_matches(&key, secret) {
            return Ok(None);
        }
        state.tenancy.record_use(&state.store, key.id);
        return Ok(Some(Caller {
            tenant: key.tenant,
            key: Some(key.id),
            admin: key.admin,
            limits: key.limits.or(defaults),
        }));
    }
    if let Some(token) = &state.config.auth_token {
        let given = given.unwrap_or("");
        return Ok(constant_time_eq(given.as_bytes(), token.expose().as_bytes()).then_some(open));
    }
    if state.tenancy.keys_required(state.store.as_ref()).await? {
        return Ok(None);
    }
    Ok(Some(open))
}

/// Demands `Authorization: Bearer <secret>` (an API key's, or the `auth_token`) once keys or a
/// token are configured, applies the caller's rate limit, and tells the handlers who is calling
/// ([`Caller`], in the request's extensions).
pub async fn authenticate(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer_token);
    let refused = match identify(&state, given).await {
        Ok(Some(caller)) => {
            let limited = caller
                .limits
                .rate_limit_rps
                .map(|rps| state.tenancy.limiter.admit(caller.tenant, rps));
            match limited {
                Some(Err(e)) => e,
                None | Some(Ok(())) => {
                    req.extensions_mut().insert(caller);
                    return next.run(req).await;
                }
            }
        }
        Ok(None) => ApiError::Unauthorized,
        Err(e) => e,
    };
    let mut response = refused.into_response();
    // A refused request's body is not read. hyper drops a connection with unread bytes after
    // the answer, so say so, or a keep-alive client sends its next request into it.
    if has_body(&req) {
        response.headers_mut().insert(
            header::CONNECTION,
            axum::http::HeaderValue::from_static("close"),
        );
    }
    response
}

/// Whether a request announces a body (a non-zero `Content-Length`, or chunked).
fn has_body(req: &Request) -> bool {
    let headers = req.headers();
    headers.contains_key(header::TRANSFER_ENCODING)
        || headers
            .get(header::CONTENT_LENGTH)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.parse::<u64>().ok())
            .is_some_and(|n| n > 0)
}

#[cfg(test)]
mod tests {
    use super::bearer_token;

    #[test]
    fn the_bearer_scheme_is_case_insensitive() {
        assert_eq!(bearer_token("Bearer abc"), Some("abc"));
        assert_eq!(bearer_token("bearer abc"), Some("abc"));
        assert_eq!(bearer_token("BEARER  abc"), Some("abc"));
        assert_eq!(bearer_token("Basic abc"), None);
        assert_eq!(bearer_token("Bearerabc"), None);
    }
}
