//! Extractors whose rejections are problem+json bodies naming the field at fault.
use super::problem::ApiError;
use super::AppState;
use axum::body::Bytes;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::{header, request::Parts, StatusCode};
use serde::de::DeserializeOwned;

/// A JSON body; malformed JSON is a 400, a wrong field a 422 that names it.
pub struct ApiJson<T>(pub T);

/// Turns a serde error at `path` into the API error that names the field.
pub fn json_error(path: String, error: serde_json::Error) -> ApiError {
    use serde_json::error::Category;
    match error.classify() {
        Category::Syntax | Category::Eof | Category::Io => {
            ApiError::MalformedJson(error.to_string())
        }
        Category::Data => {
            let message = error.to_string();
            // serde names the offending key in backticks: "unknown field `x`, expected ...".
            let quoted = message.split('`').nth(1).map(str::to_string);
            let prefix = if path == "." {
                String::new()
            } else {
                format!("{path}.")
            };
            if message.starts_with("unknown field") {
                // The path already ends at the unknown key, unless it is at the top level.
                let name = quoted.unwrap_or_default();
                let field = if path == "." {
                    name
                } else if path.ends_with(&name) {
                    path
                } else {
                    format!("{prefix}{name}")
                };
                ApiError::UnknownField(field)
            } else if message.starts_with("missing field") {
                ApiError::MissingField(format!("{prefix}{}", quoted.unwrap_or_default()))
            } else {
                // Drop serde_json's " at line 1 column 9" position suffix; the field is named.
                let message = message
                    .split(" at line ")
                    .next()
                    .unwrap_or(&message)
                    .to_string();
                ApiError::InvalidField {
                    field: path,
                    message,
                }
            }
        }
    }
}

/// Parses JSON bytes into `T`, naming the field at fault on error.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        json_error(path, e.into_inner())
    })?;
    de.end()
        .map_err(|e| ApiError::MalformedJson(e.to_string()))?;
    Ok(value)
}

impl<T> FromRequest<AppState> for ApiJson<T>
where
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Self::Rejection> {
        let is_json = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split(';').next())
            .is_some_and(|mime| {
                let mime = mime.trim().to_ascii_lowercase();
                mime == "application/json"
                    || (mime.starts_with("application/") && mime.ends_with("+json"))
            });
        if !is_json {
            return Err(ApiError::NotJson);
        }
        // The route's `DefaultBodyLimit` is `max_job_body_bytes`; past it nothing more is read.
        let bytes = Bytes::from_request(req, state).await.map_err(|e| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::BodyTooLarge {
                    limit: state.config.max_job_body_bytes,
                }
            } else if super::multipart::caused_by::<tower_http::timeout::TimeoutError>(&e) {
                ApiError::BodyTimeout {
                    seconds: state.config.body_timeout_s,
                }
            } else {
                ApiError::MalformedJson(e.body_text())
            }
        })?;
        parse_json(&bytes).map(ApiJson)
    }
}

/// Deserialises an optional integer written as `36` or `36.0`: JSON Schema's `integer` admits
/// both, so clients and generators may send either. A fraction or an out-of-range value is an
/// error that names the field.
pub fn optional_integer<'de, D, T>(deserializer: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: TryFrom<i128>,
{
    use serde::de::Error;
    use serde::Deserialize;
    let Some(n) = Option::<serde_json::Number>::deserialize(deserializer)? else {
        return Ok(None);
    };
    let value = match (n.as_i64(), n.as_u64(), n.as_f64()) {
        (Some(i), _, _) => i128::from(i),
        (_, Some(u), _) => i128::from(u),
        // 2^64 bounds every integer field; past it (or with a fraction) it is no integer we take.
        (_, _, Some(f)) if f.fract() == 0.0 && f.abs() <= 18_446_744_073_709_551_615.0 => f as i128,
        _ => {
            return Err(D::Error::custom(format!(
                "invalid value {n}, expected an integer"
            )))
        }
    };
    T::try_from(value)
        .map(Some)
        .map_err(|_| D::Error::custom(format!("{n} is out of range")))
}

/// A query string; an unknown or malformed parameter is a 400 that says which.
pub struct ApiQuery<T>(pub T);

impl<S, T> FromRequestParts<S> for ApiQuery<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Self::Rejection> {
        axum::extract::Query::<T>::from_request_parts(parts, state)
            .await
            .map(|q| ApiQuery(q.0))
            .map_err(|e| ApiError::InvalidQuery(e.body_text()))
    }
}
