//! `POST /v1/rigs`, `GET /v1/rigs`, `GET /v1/rigs/{id}` and `DELETE /v1/rigs/{id}`: a user's own
//! skeleton to take dances onto.
//!
//! An upload is a BVH or glb whose skeleton stands in a rest pose, and optionally a `mapping`
//! (joint name → humanoid bone) that overrides the name mapping. It streams to a temp file in the
//! data dir like a song ([`super::songs`]: the same size limit, checks and refusals), is read into
//! a [`TargetSkeleton`] ([`crate::motion::retarget::uploaded`]), renamed into `rigs/<id>.<ext>`,
//! published to the artifact store and recorded with its skeleton. Dance downloads name the rig by
//! its id (`?rig=<id>`); [`target_skeleton`] is the lookup they use, and each such lookup is a
//! use that restarts the rig's retention. A deletion removes the row, then the file, as a song's
//! does ([`crate::artifacts::retention::remove_files`]).
use super::auth::Caller;
use super::extract::ApiQuery;
use super::multipart::{self, Form};
use super::paging::PageRequest;
use super::problem::{ApiError, Problem};
use super::songs::{drain, receive, Received, UploadError};
use super::AppState;
use crate::artifacts::Artifact;
use crate::motion::retarget::uploaded::{self, RigFormat, Units};
use crate::motion::retarget::{HumanBone, TargetSkeleton};
use crate::queue::{RigFilter, RigId, Scope, UploadedRig};
use axum::extract::{Path, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::{Json, RequestExt};
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::str::FromStr;
use std::time::Duration;

/// Longest `mapping` field accepted, bytes (a few hundred joints' names).
const MAX_MAPPING_BYTES: usize = 64 * 1024;

/// An uploaded rig: how its joints map onto the humanoid bones a dance drives.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RigView {
    pub id: RigId,
    /// The upload's file name, for display.
    pub filename: String,
    /// Found from the bytes.
    pub format: RigFormat,
    /// The unit the rest pose was read in, found from its height (BVH has none; glTF is metres,
    /// but exporters that skip the armature's scale write centimetres): scaled to metres.
    pub units: Units,
    /// Number of joints in the skeleton.
    pub joints: usize,
    /// Joint name → the humanoid bone (VRM 1.0 name) it is driven as.
    #[schema(value_type = BTreeMap<String, String>)]
    pub mapping: BTreeMap<String, HumanBone>,
    /// Joints no humanoid bone maps to: they keep their rest rotation.
    pub unmapped: Vec<String>,
    pub created_at: DateTime<Utc>,
}

impl From<&UploadedRig> for RigView {
    fn from(rig: &UploadedRig) -> Self {
        let s = &rig.skeleton;
        let pairs = s.rig.names.iter().zip(&s.humanoid);
        RigView {
            id: rig.id,
            filename: rig.filename.clone(),
            format: rig.format,
            units: rig.units,
            joints: s.rig.names.len(),
            mapping: pairs
                .clone()
                .filter_map(|(n, b)| b.map(|b| (n.clone(), b)))
                .collect(),
            unmapped: pairs
                .filter(|(_, b)| b.is_none())
                .map(|(n, _)| n.clone())
                .collect(),
            created_at: rig.created_at,
        }
    }
}

/// A page of rigs.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RigPage {
    pub items: Vec<RigView>,
    /// Pass as `cursor` for the next page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// The page of `GET /v1/rigs`.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct RigListQuery {
    /// 1..=100, default 20.
    #[param(minimum = 1, maximum = 100, default = 20)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page (a rig id).
    #[param(format = Uuid)]
    pub cursor: Option<String>,
}

/// The multipart form of a rig upload: `file` and, optionally, `mapping` (any other field is
/// refused with 422).
#[derive(utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct RigUploadForm {
    /// The skeleton in its rest pose: BVH (text; metres, centimetres or millimetres) or glb
    /// (binary glTF with a skin; a `.gltf` JSON is read too).
    #[schema(value_type = String, format = Binary, min_length = 1)]
    file: Vec<u8>,
    /// JSON object, joint name → humanoid bone (VRM 1.0 name such as `leftUpperArm`, or null for
    /// none), applied over the mapping found from the joints' names.
    #[schema(value_type = Option<String>, example = json!(r#"{"Bone.012": "leftUpperArm"}"#))]
    mapping: Option<String>,
}

/// The form's fields.
#[derive(Default)]
struct RigForm {
    file: Option<Received>,
    mapping: Option<String>,
}

async fn read_form(state: &AppState, request: Request) -> Result<RigForm, UploadError> {
    let (parts, body) = request.with_limited_body().into_parts();
    let mut multipart = multipart::form(&parts.headers, body, state.config.max_part_header_bytes)
        .map_err(UploadError::before_body_end)?;
    match read_fields(state, &mut multipart).await {
        Ok(form) => Ok(form),
        Err(error) => {
            let drained = drain(&mut multipart).await;
            Err(UploadError {
                error,
                body_unread: !drained,
            })
        }
    }
}

async fn read_fields(state: &AppState, multipart: &mut Form) -> Result<RigForm, ApiError> {
    let mut form = RigForm::default();
    loop {
        let mut field = match multipart.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => return Ok(form),
            Err(e) => return Err(multipart::error(&e, &state.config)),
        };
        match field.name() {
            Some("file") if form.file.is_none() => form.file = Some(receive(state, field).await?),
            Some("mapping") if form.mapping.is_none() => {
                let mut text = Vec::new();
                loop {
                    match field.chunk().await {
                        Ok(Some(chunk)) => {
                            text.extend_from_slice(&chunk);
                            if text.len() > MAX_MAPPING_BYTES {
                                return Err(ApiError::InvalidField {
                                    field: "mapping".into(),
                                    message: format!("longer than {MAX_MAPPING_BYTES} bytes"),
                                });
                            }
                        }
                        Ok(None) => break,
                        Err(e) => return Err(multipart::error(&e, &state.config)),
                    }
                }
                let text = String::from_utf8(text).map_err(|_| ApiError::InvalidField {
                    field: "mapping".into(),
                    message: "not UTF-8 text".into(),
                })?;
                form.mapping = Some(text);
            }
            Some(name @ ("file" | "mapping")) => {
                return Err(ApiError::UnexpectedField(format!("{name} (a second one)")))
            }
            Some(other) => return Err(ApiError::UnknownField(other.chars().take(80).collect())),
            None => return Err(ApiError::UnexpectedField("(unnamed)".into())),
        }
    }
}

/// The `mapping` field: joint name → humanoid bone (or null).
fn parse_mapping(text: Option<&str>) -> Result<BTreeMap<String, Option<HumanBone>>, ApiError> {
    let Some(text) = text.map(str::trim).filter(|t| !t.is_empty()) else {
        return Ok(BTreeMap::new());
    };
    serde_json::from_str(text).map_err(|e| ApiError::InvalidField {
        field: "mapping".into(),
        message: format!(
            "{e}; send a JSON object of joint name → humanoid bone, one of {}, or null",
            HumanBone::ALL
                .iter()
                .map(|b| b.vrm_name())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    })
}

/// Upload a rig.
///
/// A BVH or glb whose skeleton stands in its rest pose (T- or A-pose). Its joints are mapped onto
/// humanoid bones by name (Mixamo, VRM/VRoid, Unreal mannequin, Blender Rigify and SMPL names,
/// any case, namespace prefixes such as `mixamorig:` ignored), then by `mapping`. The rig needs
/// hips, spine, head, both upper and lower legs and feet, and both upper and lower arms; without
/// one the answer is 422 naming the bones it could not map and the joints left over. Dances are
/// then downloaded on it with `?rig=<id>`.
#[utoipa::path(
    post,
    path = "/v1/rigs",
    operation_id = "uploadRig",
    tag = "rigs",
    request_body(content = RigUploadForm, content_type = "multipart/form-data"),
    responses(
        (status = 201, description = "Rig stored", body = RigView),
        (status = 400, description = "Empty file, a second or unnamed field, bad file name or bad multipart", body = Problem, content_type = "application/problem+json"),
        (status = 408, description = "The body stalled for more than body_timeout_s", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Over the size limit (code file-too-large), or past the key's storage quota (code storage-quota-exceeded: delete songs, rigs or results to make room)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Neither BVH nor glTF", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "No file; an unknown field; a skeleton that cannot be read, has a number that is not finite (code motion-not-finite), too many joints or nodes, or lacks a bone a dance needs (named); a bad `mapping`; a file not read within audio_timeout_s (code rig-timed-out)", body = Problem, content_type = "application/problem+json"),
        (status = 431, description = "A part's headers are longer than max_part_header_bytes", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The server's database is unreachable; send the upload again when it is back", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The server is out of storage; nothing was stored", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn upload(
    State(state): State<AppState>,
    caller: Caller,
    request: Request,
) -> Result<(StatusCode, HeaderMap, Json<RigView>), UploadError> {
    let form = read_form(&state, request).await?;
    let received = form
        .file
        .ok_or_else(|| ApiError::MissingField("file".into()))?;
    let overrides = parse_mapping(form.mapping.as_deref())?;
    // An early refusal that saves the read; the store's check, in the transaction that inserts
    // the rig, is the one that holds against uploads racing each other.
    super::tenancy::check_storage(&state, &caller, received.size).await?;
    // Read under the songs' decode budget: one of the permits that bound decodes in parallel
    // (so uploads cannot take every core, or memory, at once), and `audio_timeout_s`.
    let read = {
        let permit = state
            .decode_permits
            .clone()
            .acquire_owned()
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        let bytes = tokio::fs::read(received.file.path())
            .await
            .map_err(|e| ApiError::storage("reading the upload", &e))?;
        let limit = Duration::from_secs_f64(state.config.audio_timeout_s);
        // The reader's work is bounded by the file's size (joints and nodes are capped), so a
        // reader past its time is left to finish on its own and its answer dropped; it keeps its
        // permit until it does, so readers left running still count against the budget.
        let reading = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            uploaded::read(&bytes, &overrides)
        });
        match tokio::time::timeout(limit, reading).await {
            Ok(joined) => joined
                .map_err(|e| ApiError::Internal(format!("rig reader thread: {e}")))?
                .map_err(ApiError::Rig)?,
            Err(_) => {
                return Err(ApiError::RigTimedOut {
                    limit_s: limit.as_secs_f64(),
                }
                .into())
            }
        }
    };

    let id = RigId::new();
    let path = state.data.rig_path(id, read.format);
    received
        .file
        .persist(&path)
        .map_err(|e| ApiError::storage("storing the rig", &e.error))?;
    let artifact = Artifact::Rig(id, read.format);
    if let Err(e) = state.artifacts.publish(artifact).await {
        forget(&state, artifact).await;
        return Err(ApiError::artifact("storing the rig", &e).into());
    }
    let rig = UploadedRig {
        id,
        tenant: caller.tenant,
        filename: received.filename,
        format: read.format,
        units: read.units,
        sha256: received.sha256,
        size_bytes: received.size,
        skeleton: read.skeleton,
        created_at: Utc::now(),
    };
    let stored = match state.store.add_rig_within(rig, caller.limits).await {
        Ok(stored) => stored,
        Err(e) => {
            forget(&state, artifact).await;
            return Err(ApiError::from(e).into());
        }
    };
    tracing::info!(rig_id = %stored.id, format = ?stored.format, joints = stored.skeleton.rig.names.len(), "rig stored");
    let mut headers = HeaderMap::new();
    if let Ok(value) = HeaderValue::from_str(&format!("/v1/rigs/{id}")) {
        headers.insert(header::LOCATION, value);
    }
    Ok((StatusCode::CREATED, headers, Json(RigView::from(&stored))))
}

/// Removes a stored rig file whose row was never written.
async fn forget(state: &AppState, artifact: Artifact<'_>) {
    if let Err(e) = state.artifacts.remove(artifact).await {
        tracing::warn!(error = %e, "could not remove a rig file whose row was not written");
    }
}

/// An uploaded rig and its mapping.
#[utoipa::path(
    get,
    path = "/v1/rigs/{id}",
    operation_id = "getRig",
    tag = "rigs",
    params(("id" = String, Path, description = "Rig id")),
    responses(
        (status = 200, description = "The rig", body = RigView),
        (status = 404, description = "No such rig", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn get(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<RigView>, ApiError> {
    let id = RigId::from_str(&id)
        .map_err(|_| ApiError::RigNotFound(format!("{id:?} (not a rig id)")))?;
    let rig = state.store.rig(caller.scope(), id).await?;
    Ok(Json(RigView::from(&rig)))
}

/// The caller's rigs, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/v1/rigs",
    operation_id = "listRigs",
    tag = "rigs",
    params(RigListQuery),
    responses(
        (status = 200, description = "A page of rigs", body = RigPage),
        (status = 400, description = "An unknown or malformed query parameter", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A limit outside 1..=100, or a cursor that is not a next_cursor", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn list(
    State(state): State<AppState>,
    caller: Caller,
    ApiQuery(query): ApiQuery<RigListQuery>,
) -> Result<Json<RigPage>, ApiError> {
    let page = PageRequest::<RigId>::parse(query.limit, query.cursor.as_deref())?;
    let filter = RigFilter {
        before: page.before,
        limit: page.fetch(),
    };
    let rigs = state.store.rigs(caller.scope(), filter).await?;
    let (rigs, next_cursor) = page.page(rigs, |r| r.id.to_string());
    Ok(Json(RigPage {
        items: rigs.iter().map(RigView::from).collect(),
        next_cursor,
    }))
}

/// Delete a rig: its row and its file.
///
/// Afterwards its id is 404, to `GET` and to the downloads that name it (`?rig=<id>`), and its
/// bytes no longer count against the key's storage quota. Dances already downloaded on it are
/// the client's; any job can still be downloaded on another rig.
#[utoipa::path(
    delete,
    path = "/v1/rigs/{id}",
    operation_id = "deleteRig",
    tag = "rigs",
    params(("id" = String, Path, description = "Rig id")),
    responses(
        (status = 204, description = "The rig and its file are deleted"),
        (status = 404, description = "No such rig", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The database is unreachable; nothing was deleted, send it again shortly", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn delete(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let id = RigId::from_str(&id)
        .map_err(|_| ApiError::RigNotFound(format!("{id:?} (not a rig id)")))?;
    // The row first, so no download finds the rig any more; then its file.
    let removed = state.store.delete_rig(caller.scope(), id).await?;
    if let Err(e) =
        crate::artifacts::retention::remove_files(state.artifacts.as_ref(), &removed).await
    {
        // No row names it now: the data dir's sweep removes what is left.
        tracing::warn!(rig_id = %id, error = %e, "a deleted rig's file could not be removed");
    }
    tracing::info!(rig_id = %id, "rig deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// The skeleton of uploaded rig `id` (a `?rig=` value that is not a built-in's name), for the
/// downloads that retarget onto it; only `scope`'s rigs are found. Finding it is a use of the
/// rig, which restarts its retention.
pub async fn target_skeleton(
    state: &AppState,
    scope: Scope,
    id: &str,
) -> Result<TargetSkeleton, ApiError> {
    let id = RigId::from_str(id)
        .map_err(|_| ApiError::RigNotFound(format!("{id:?} (not a rig id nor a built-in rig)")))?;
    let rig = state.store.rig(scope, id).await?;
    // A failure only logs: the download does not depend on it.
    if let Err(e) = state.store.touch_rig(id).await {
        tracing::warn!(rig_id = %id, error = %e, "could not record a use of the rig");
    }
    Ok(rig.skeleton)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mappings_parse_or_say_what_to_send() {
        let m =
            parse_mapping(Some(r#"{"Bone.1": "leftUpperArm", "Bone.2": null}"#)).expect("mapping");
        assert_eq!(m["Bone.1"], Some(HumanBone::LeftUpperArm));
        assert_eq!(m["Bone.2"], None);
        assert!(parse_mapping(Some("  ")).expect("blank").is_empty());
        let err = parse_mapping(Some(r#"{"Bone.1": "leftWing"}"#)).expect_err("unknown bone");
        assert!(err.to_string().contains("leftUpperArm"), "{err}");
    }
}
