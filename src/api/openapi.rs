//! The OpenAPI document, generated from the handlers; `openapi/openapi.json` is its checked-in copy.
//!
//! The modifiers state what the middleware does for every `/v1` route, so the document says
//! exactly what the server does: the bearer token is optional (only a server with `auth_token`
//! set asks for it, and then answers 401), and the ids that `POST /v1/songs` and `POST /v1/jobs`
//! return are linked to the operations that take them.
use utoipa::openapi::link::LinkBuilder;
use utoipa::openapi::path::{Operation, PathItem};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme};
use utoipa::openapi::{ContentBuilder, Ref, RefOr, ResponseBuilder};
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
        super::system::models,
        super::system::healthz,
        super::system::readyz,
        super::system::metrics,
    ),
    modifiers(&BearerAuth, &Links),
    tags(
        (name = "songs", description = "Upload songs; read their analysis"),
        (name = "jobs", description = "Dances: submit, follow, cancel, download"),
        (name = "models", description = "The models this server has"),
        (name = "system", description = "Health, readiness, metrics"),
    )
)]
pub struct ApiDoc;

fn operations(item: &mut PathItem) -> impl Iterator<Item = &mut Operation> {
    [&mut item.get, &mut item.post, &mut item.put, &mut item.delete, &mut item.patch].into_iter().flatten()
}

/// Declares the bearer token that guards `/v1` when the server has one: every `/v1` operation
/// may be called without it (the default) or with it, and may answer 401.
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme("bearer", SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()));
        let unauthorized = ResponseBuilder::new()
            .description("The server has an auth_token and the request did not send it as `Authorization: Bearer <token>`")
            .content(super::problem::PROBLEM_JSON, ContentBuilder::new().schema(Some(Ref::from_schema_name("Problem"))).build())
            .build();
        for (path, item) in openapi.paths.paths.iter_mut() {
            if !path.starts_with("/v1/") {
                continue;
            }
            for op in operations(item) {
                op.security = Some(vec![SecurityRequirement::default(), SecurityRequirement::new("bearer", Vec::<String>::new())]);
                op.responses.responses.entry("401".into()).or_insert_with(|| RefOr::T(unauthorized.clone()));
            }
        }
    }
}

/// OpenAPI links from the responses that create a song or a job to the operations taking its id.
struct Links;

impl Modify for Links {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let link = |op: &str, params: &[(&str, &str)]| {
            let mut b = LinkBuilder::new().operation_id(op);
            for (name, value) in params {
                b = b.parameter(*name, *value);
            }
            RefOr::T(b.build())
        };
        let song_links = || {
            [
                ("GetSong", link("getSong", &[("id", "$response.body#/id")])),
                (
                    "CreateJob",
                    RefOr::T(
                        LinkBuilder::new()
                            .operation_id("createJob")
                            .request_body(Some(serde_json::json!({ "song_id": "$response.body#/id", "model": "dance-revolution" })))
                            .build(),
                    ),
                ),
            ]
        };
        let job_links = || {
            [
                ("GetJob", link("getJob", &[("id", "$response.body#/id")])),
                ("CancelJob", link("cancelJob", &[("id", "$response.body#/id")])),
                ("GetJobFile", link("getJobFile", &[("id", "$response.body#/id"), ("file", "report.json")])),
                ("GetSong", link("getSong", &[("id", "$response.body#/song_id")])),
            ]
        };
        let add = |openapi: &mut utoipa::openapi::OpenApi, path: &str, status: &str, links: &[(&str, RefOr<utoipa::openapi::link::Link>)]| {
            let Some(op) = openapi.paths.paths.get_mut(path).and_then(|item| item.post.as_mut()) else { return };
            if let Some(RefOr::T(response)) = op.responses.responses.get_mut(status) {
                for (name, l) in links {
                    response.links.insert((*name).to_string(), l.clone());
                }
            }
        };
        add(openapi, "/v1/songs", "201", &song_links());
        add(openapi, "/v1/songs", "200", &song_links());
        add(openapi, "/v1/jobs", "202", &job_links());
    }
}

/// The spec as pretty JSON with a trailing newline, exactly as checked in.
pub fn spec_json() -> Result<String, serde_json::Error> {
    let mut json = ApiDoc::openapi().to_pretty_json()?;
    json.push('\n');
    Ok(json)
}
