//! Who is calling: the `/v1` authentication middleware and the [`Caller`] it hands to handlers.
//!
//! Every `/v1` request runs [`authenticate`] first; it either answers 401 or puts a [`Caller`] in
//! the request's extensions. Handlers take `caller: Caller` and scope every store call by
//! [`Caller::scope`], so a tenant never reads, lists or changes another's rows: another tenant's
//! id is a 404, exactly like an id that never existed.
use super::problem::ApiError;
use super::AppState;
use crate::queue::{Scope, TenantId};
use axum::extract::{FromRequestParts, Request, State};
use axum::http::{header, request::Parts};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

/// The tenant a request acts for, and whether it may act for all (operators' keys).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Caller {
    pub tenant: TenantId,
    pub admin: bool,
}

impl Caller {
    /// An open service, or the single `auth_token`: one tenant, [`TenantId::OPEN`].
    pub const OPEN: Caller = Caller {
        tenant: TenantId::OPEN,
        admin: false,
    };

    /// What this caller's store reads and changes may touch: its own tenant's rows.
    pub fn scope(&self) -> Scope {
        Scope::Tenant(self.tenant)
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

/// Demands `Authorization: Bearer <token>` when a token is configured, and tells the handlers who
/// is calling ([`Caller`], in the request's extensions).
pub async fn authenticate(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let Some(token) = &state.config.auth_token else {
        req.extensions_mut().insert(Caller::OPEN);
        return next.run(req).await;
    };
    let given = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(bearer_token)
        .unwrap_or("");
    if constant_time_eq(given.as_bytes(), token.expose().as_bytes()) {
        req.extensions_mut().insert(Caller::OPEN);
        next.run(req).await
    } else {
        let mut response = ApiError::Unauthorized.into_response();
        // An unauthenticated body is not read. hyper drops a connection with unread bytes after
        // the answer, so say so, or a keep-alive client sends its next request into it.
        if has_body(&req) {
            response.headers_mut().insert(
                header::CONNECTION,
                axum::http::HeaderValue::from_static("close"),
            );
        }
        response
    }
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

/// Compares without an early exit, so timing does not reveal how much of a token matched.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = u8::from(a.len() != b.len());
    for (i, x) in a.iter().enumerate() {
        diff |= x ^ b.get(i % b.len().max(1)).copied().unwrap_or(0);
    }
    diff == 0
}

#[cfg(test)]
mod tests {
    use super::{bearer_token, constant_time_eq};

    #[test]
    fn the_bearer_scheme_is_case_insensitive() {
        assert_eq!(bearer_token("Bearer abc"), Some("abc"));
        assert_eq!(bearer_token("bearer abc"), Some("abc"));
        assert_eq!(bearer_token("BEARER  abc"), Some("abc"));
        assert_eq!(bearer_token("Basic abc"), None);
        assert_eq!(bearer_token("Bearerabc"), None);
    }

    #[test]
    fn token_comparison_is_exact() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"ab", b"abc"));
        assert!(!constant_time_eq(b"abcd", b"abc"));
        assert!(!constant_time_eq(b"", b"abc"));
    }
}
