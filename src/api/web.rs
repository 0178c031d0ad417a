//! The choreography page at `/`: one HTML page, one script, one stylesheet.
//!
//! They are built from `web/src` by `npm run build` in `web/` (esbuild bundles three.js from the
//! npm registry) and committed under `web/dist/`; `include_str!` compiles them into the binary,
//! so serving the page needs neither npm nor files on disk, and nothing loads from elsewhere at
//! run time (the Content-Security-Policy below says so to the browser). The page is a client of
//! the public `/v1` API only, on this origin or another one (`?api=`, with CORS configured there).
use super::AppState;
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use sha2::{Digest, Sha256};
use std::sync::LazyLock;

/// One embedded file: its bytes, content type and entity tag.
struct Asset {
    body: &'static str,
    content_type: &'static str,
    etag: HeaderValue,
}

impl Asset {
    fn new(body: &'static str, content_type: &'static str) -> Self {
        let digest = hex::encode(&Sha256::digest(body.as_bytes())[..12]);
        // A hex digest in quotes is always a valid header value.
        let etag = HeaderValue::from_str(&format!("\"{digest}\""))
            .unwrap_or(HeaderValue::from_static("\"0\""));
        Self {
            body,
            content_type,
            etag,
        }
    }
}

static INDEX: LazyLock<Asset> = LazyLock::new(|| {
    Asset::new(
        include_str!("../../web/dist/index.html"),
        "text/html; charset=utf-8",
    )
});
static SCRIPT: LazyLock<Asset> = LazyLock::new(|| {
    Asset::new(
        include_str!("../../web/dist/app.js"),
        "text/javascript; charset=utf-8",
    )
});
/// The `<choreo-player>` element for other pages (web/src/element.js): any page may load it.
static PLAYER: LazyLock<Asset> = LazyLock::new(|| {
    Asset::new(
        include_str!("../../web/dist/choreo-player.js"),
        "text/javascript; charset=utf-8",
    )
});
static STYLE: LazyLock<Asset> = LazyLock::new(|| {
    Asset::new(
        include_str!("../../web/dist/app.css"),
        "text/css; charset=utf-8",
    )
});

/// Scripts and styles come from this origin only; the API may be on another (`connect-src`), and
/// the song plays from a `blob:` URL made of the audio the page fetched with its token.
const CONTENT_SECURITY_POLICY: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; \
     media-src 'self' blob:; connect-src 'self' http: https:; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// `GET /`, `/assets/app.js`, `/assets/app.css`, `/assets/choreo-player.js`: public, like
/// `/docs`; the page asks for an API key when the API needs one.
pub fn routes() -> Router<AppState> {
    Router::new()
        .route(
            "/",
            get(|headers: HeaderMap| async move { serve(&INDEX, &headers, true) }),
        )
        .route(
            "/assets/app.js",
            get(|headers: HeaderMap| async move { serve(&SCRIPT, &headers, false) }),
        )
        .route(
            "/assets/app.css",
            get(|headers: HeaderMap| async move { serve(&STYLE, &headers, false) }),
        )
        .route(
            "/assets/choreo-player.js",
            get(|headers: HeaderMap| async move { serve(&PLAYER, &headers, false) }),
        )
}

/// The asset, or 304 when the client's copy is current. `no-cache` makes browsers ask each time,
/// so a new binary's page is picked up at once.
fn serve(asset: &Asset, request: &HeaderMap, page: bool) -> Response {
    let current = request
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|tags| {
            tags.split(',')
                .any(|t| t.trim() == asset.etag.to_str().unwrap_or(""))
        });
    let mut response = if current {
        StatusCode::NOT_MODIFIED.into_response()
    } else {
        asset.body.into_response()
    };
    let headers = response.headers_mut();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(asset.content_type),
    );
    headers.insert(header::ETAG, asset.etag.clone());
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    if page {
        headers.insert(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static(CONTENT_SECURITY_POLICY),
        );
    }
    response
}
