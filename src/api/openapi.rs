//! The OpenAPI document, generated from the handlers; `openapi/openapi.json` is its checked-in copy.
//!
//! The modifiers state what the middleware does for every `/v1` route, so the document says
//! exactly what the server does: the bearer secret is optional (only a server with API keys or
//! an `auth_token` asks for it, and then answers 401), every `/v1` operation may answer 429
//! (the caller's rate limit), and the ids that `POST /v1/songs` and `POST /v1/jobs`
//! return (and `POST /v1/rigs`) are linked to the operations that take them.
use serde_json::{json, Value};
use utoipa::openapi::header::HeaderBuilder;
use utoipa::openapi::path::{Operation, PathItem};
use utoipa::openapi::schema::{ObjectBuilder, Type};
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
        super::songs::list,
        super::songs::get,
        super::song_audio::audio,
        super::songs::delete,
        super::rigs::upload,
        super::rigs::list,
        super::rigs::get,
        super::rigs::delete,
        super::jobs::create,
        super::jobs::list,
        super::jobs::get,
        super::jobs::cancel_or_delete,
        super::jobs::result,
        super::jobs::preview,
        super::events::events,
        super::downloads::motion_bvh,
        super::downloads::motion_glb,
        super::downloads::motion_vrma,
        super::downloads::motion_smpl,
        super::system::models,
        super::system::healthz,
        super::system::readyz,
        super::system::metrics,
    ),
    // report.json's `serving` list (its own file, not a route's body, so named here).
    components(schemas(
        crate::report::serving::StageTrace,
        crate::motion::trace::ServingStage,
    )),
    modifiers(&BearerAuth),
    tags(
        (name = "songs", description = "Upload songs; list them; read their analysis and audio; delete them"),
        (name = "rigs", description = "Your own skeletons (BVH or glb) to take dances onto: upload, list, delete"),
        (name = "jobs", description = "Dances: submit, follow, cancel, download, delete"),
        (name = "models", description = "The models this server has"),
        (name = "system", description = "Health, readiness, metrics"),
    )
)]
pub struct ApiDoc;

fn operations(item: &mut PathItem) -> impl Iterator<Item = &mut Operation> {
    [
        &mut item.get,
        &mut item.post,
        &mut item.put,
        &mut item.delete,
        &mut item.patch,
    ]
    .into_iter()
    .flatten()
}

/// Declares the bearer secret that guards `/v1` when the server has keys or a token: every `/v1`
/// operation may be called without it (the default) or with it, and may answer 401; and the
/// rate limit every `/v1` operation may answer 429 for.
struct BearerAuth;

/// What the `bearer` security scheme says.
const BEARER_DESCRIPTION: &str = "An API key's secret (`choreo keys create --name N` prints it once: \
`choreo_…`), or the server's `auth_token`. Each key is a tenant: its songs, rigs, jobs and results are its \
own, and another tenant's ids answer 404. Once any key exists every /v1 request needs one (or the token); \
a revoked or unknown key answers 401. A server with neither keys nor a token is open.";

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(BEARER_DESCRIPTION))
                    .build(),
            ),
        );
        let problem = || {
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Problem")))
                .build()
        };
        let unauthorized = ResponseBuilder::new()
            .description("The server has API keys or an auth_token, and the request sent no valid one as `Authorization: Bearer <secret>` (an unknown or revoked key, or a wrong token)")
            .content(super::problem::PROBLEM_JSON, problem())
            .build();
        let retry_after = HeaderBuilder::new()
            .schema(
                ObjectBuilder::new()
                    .schema_type(Type::Integer)
                    .minimum(Some(1)),
            )
            .description(Some("Seconds to wait before trying again"))
            .build();
        let rate_limited = |what: &str| {
            ResponseBuilder::new()
                .description(what)
                .content(super::problem::PROBLEM_JSON, problem())
                .header("Retry-After", retry_after.clone())
                .build()
        };
        for (path, item) in openapi.paths.paths.iter_mut() {
            if !path.starts_with("/v1/") {
                continue;
            }
            for op in operations(item) {
                op.security = Some(vec![
                    SecurityRequirement::default(),
                    SecurityRequirement::new("bearer", Vec::<String>::new()),
                ]);
                op.responses
                    .responses
                    .entry("401".into())
                    .or_insert_with(|| RefOr::T(unauthorized.clone()));
                let too_many = match op.operation_id.as_deref() {
                    Some("createJob") | Some("uploadSong") => {
                        "The key made more requests per second than its rate_limit_rps (code rate-limited), or has \
                         max_queued_jobs jobs queued or running already, an upload's analysis included (code \
                         too-many-queued-jobs); nothing was queued or stored"
                    }
                    Some("getJobEvents") => {
                        "The key made more requests per second than its rate_limit_rps (code rate-limited), or has \
                         max_event_streams_per_key event streams open already (code too-many-event-streams; the \
                         connection is closed)"
                    }
                    _ => "The key made more requests per second than its rate_limit_rps (code rate-limited)",
                };
                op.responses
                    .responses
                    .entry("429".into())
                    .or_insert_with(|| RefOr::T(rate_limited(too_many)));
            }
        }
    }
}

/// OpenAPI links from the responses that create a song or a job to the operations taking its
/// id. Written into the JSON, because utoipa 5 serialises `Link` with snake_case keys
/// (`operation_id`), which no OpenAPI tool reads.
fn add_links(spec: &mut Value) {
    let song = json!({
        "GetSong": { "operationId": "getSong", "parameters": { "id": "$response.body#/id" } },
        "CreateJob": {
            "operationId": "createJob",
            "requestBody": { "song_id": "$response.body#/id", "model": "dance-revolution" },
        },
        "GetSongAudio": { "operationId": "getSongAudio", "parameters": { "id": "$response.body#/id" } },
        "DeleteSong": { "operationId": "deleteSong", "parameters": { "id": "$response.body#/id" } },
    });
    let job = json!({
        "GetJob": { "operationId": "getJob", "parameters": { "id": "$response.body#/id" } },
        "CancelJob": { "operationId": "cancelJob", "parameters": { "id": "$response.body#/id" } },
        "GetJobFile": { "operationId": "getJobFile", "parameters": { "id": "$response.body#/id", "file": "report.json" } },
        "GetJobPreview": { "operationId": "getJobPreview", "parameters": { "id": "$response.body#/id" } },
        "GetSong": { "operationId": "getSong", "parameters": { "id": "$response.body#/song_id" } },
    });
    let rig = json!({
        "GetRig": { "operationId": "getRig", "parameters": { "id": "$response.body#/id" } },
        "DeleteRig": { "operationId": "deleteRig", "parameters": { "id": "$response.body#/id" } },
    });
    for (path, status, links) in [
        ("/v1/songs", "201", &song),
        ("/v1/songs", "200", &song),
        ("/v1/jobs", "202", &job),
        ("/v1/rigs", "201", &rig),
    ] {
        if let Some(response) = spec.pointer_mut(&format!(
            "/paths/{}/post/responses/{status}",
            path.replace('/', "~1")
        )) {
            response["links"] = links.clone();
        }
    }
}

/// The result file names, from the one list the handler serves.
fn result_file_names(spec: &mut Value) {
    let Some(params) = spec
        .pointer_mut("/paths/~1v1~1jobs~1{id}~1{file}/get/parameters")
        .and_then(Value::as_array_mut)
    else {
        return;
    };
    for param in params.iter_mut().filter(|p| p["name"] == "file") {
        param["schema"] = json!({ "type": "string", "enum": crate::queue::files::RESULT_FILES });
    }
}

/// Array lengths serde enforces but utoipa 5 does not write: `[f64; 3]` points, and the
/// joints of a seed-motion frame.
fn fixed_lengths(spec: &mut Value) {
    // A point is exactly [x, y, z] (serde refuses any other length before anything else runs);
    // the joint count (23 or 26) is checked after the song is found, and said in the description.
    for pointer in [
        "/components/schemas/SeedMotionInput/properties/positions/items/items",
        "/components/schemas/KeyPoseInput/properties/joints/items",
    ] {
        if let Some(Value::Object(schema)) = spec.pointer_mut(pointer) {
            schema.insert("minItems".into(), 3.into());
            schema.insert("maxItems".into(), 3.into());
        }
    }
}

/// The spec the server serves: the generated document with its links, result file names and
/// array lengths.
pub fn spec() -> Result<Value, serde_json::Error> {
    let mut spec = serde_json::to_value(ApiDoc::openapi())?;
    add_links(&mut spec);
    result_file_names(&mut spec);
    fixed_lengths(&mut spec);
    Ok(spec)
}

/// The spec as pretty JSON with a trailing newline, exactly as checked in.
pub fn spec_json() -> Result<String, serde_json::Error> {
    let mut json = serde_json::to_string_pretty(&spec()?)?;
    json.push('\n');
    Ok(json)
}
