//! The OpenAPI document, generated from the handlers; `openapi/openapi.json` is its checked-in copy.
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};

/// The checked-in copy of the spec, relative to the repository root.
pub const SPEC_PATH: &str = "openapi/openapi.json";

/// choreo's HTTP API.
#[derive(OpenApi)]
#[openapi(
    info(title = "choreo", description = "Upload a song, get a dance: BVH, JSON and glb motion plus a quality report."),
    paths(
        super::songs::upload,
        super::songs::get,
        super::jobs::create,
        super::jobs::list,
        super::jobs::get,
        super::jobs::cancel,
        super::jobs::result,
        super::jobs::preview,
        super::system::models,
        super::system::healthz,
        super::system::readyz,
        super::system::metrics,
    ),
    modifiers(&BearerAuth),
    tags(
        (name = "songs", description = "Upload songs; read their analysis"),
        (name = "jobs", description = "Dances: submit, follow, cancel, download"),
        (name = "models", description = "The models this server has"),
        (name = "system", description = "Health, readiness, metrics"),
    )
)]
pub struct ApiDoc;

/// Declares the optional bearer token that guards `/v1`.
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme("bearer", SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()));
    }
}

/// The spec as pretty JSON with a trailing newline, exactly as checked in.
pub fn spec_json() -> Result<String, serde_json::Error> {
    let mut json = ApiDoc::openapi().to_pretty_json()?;
    json.push('\n');
    Ok(json)
}
