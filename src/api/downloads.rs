//! A job's dance on another skeleton: `motion.bvh?rig=R`, `motion.glb?rig=R`, `motion.vrma` and
//! `motion.smpl.npz`, computed on request from the job's stored motion.json
//! ([`crate::motion::retarget`]). `rig=choreo`, the default, serves the stored files unchanged.
//!
//! Which skeleton a `rig` names is decided in one place, [`resolve_rig`].
use super::auth::Caller;
use super::extract::ApiQuery;
use super::problem::{ApiError, Problem};
use super::AppState;
use crate::artifacts::Artifact;
use crate::motion::export::{MotionJson, JSON_FILE};
use crate::motion::retarget::{self, Format, RetargetError, TargetSkeleton};
use crate::queue::{Job, JobKind, Scope, Status};
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue};
use axum::response::Response;
use futures::TryStreamExt as _;
use serde::Deserialize;

/// The skeleton a motion download is on.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct RigQuery {
    /// `choreo` (default: choreo's own 26-joint rig, the file as the job wrote it), `mixamo`
    /// (Mixamo's `mixamorig:*` bones, T-pose), `vrm` (VRM 1.0 humanoid bones), `smpl` (SMPL's 24
    /// joints), or the id of a rig uploaded to `POST /v1/rigs`.
    #[param(example = "mixamo")]
    pub rig: Option<String>,
}

/// The target a `rig` names: `None` for choreo's own rig (nothing to retarget), a built-in by
/// name, else an uploaded rig by id (`POST /v1/rigs`); anything else is 404 `rig-not-found`.
pub async fn resolve_rig(
    state: &AppState,
    job: &Job,
    rig: &str,
) -> Result<Option<TargetSkeleton>, ApiError> {
    if rig == "choreo" {
        return Ok(None);
    }
    if let Some(target) = retarget::builtin(rig) {
        return Ok(Some(target));
    }
    super::rigs::target_skeleton(state, Scope::Tenant(job.tenant), rig)
        .await
        .map(Some)
        .map_err(|e| match e {
            ApiError::RigNotFound(_) => ApiError::RigNotFound(format!(
                "{rig:?} (rigs are choreo, {}, or the id of an uploaded rig)",
                retarget::BUILTINS.join(", ")
            )),
            other => other,
        })
}

/// A succeeded generate job, or the answer the result routes give when there is none.
async fn finished_job(state: &AppState, caller: Caller, id: &str) -> Result<Job, ApiError> {
    let job = state
        .store
        .job(caller.scope(), super::jobs::parse_job_id(id)?)
        .await?;
    if let JobKind::Analyze { song_id } = job.kind {
        return Err(ApiError::ResultNotFound(format!(
            "analyze jobs write no files; the analysis is on /v1/songs/{song_id}"
        )));
    }
    Ok(job)
}

/// Reads the job's motion.json and renders it on `target` as `format`, off the async threads.
async fn render(
    state: &AppState,
    job: &Job,
    target: TargetSkeleton,
    format: Format,
) -> Result<Vec<u8>, ApiError> {
    if job.status != Status::Succeeded {
        return Err(ApiError::JobNotFinished {
            id: job.id,
            status: job.status,
        });
    }
    if !job.files.files.iter().any(|f| f == JSON_FILE) {
        return Err(ApiError::ResultNotFound(format!(
            "job {} did not write {JSON_FILE}",
            job.id
        )));
    }
    let doing = format!("reading {JSON_FILE} of job {}", job.id);
    let file = state
        .artifacts
        .stream(Artifact::Result(job.id, JSON_FILE))
        .await
        .map_err(|e| ApiError::artifact(&doing, &e))?;
    super::jobs::record_use(state, job.id).await;
    let bytes: Vec<u8> = file
        .body
        .try_fold(
            Vec::with_capacity(file.len as usize),
            |mut acc, chunk| async move {
                acc.extend_from_slice(&chunk);
                Ok(acc)
            },
        )
        .await
        .map_err(|e| ApiError::storage(&doing, &e))?;
    let id = job.id;
    tokio::task::spawn_blocking(move || {
        let json: MotionJson = serde_json::from_slice(&bytes).map_err(|e| {
            ApiError::Internal(format!("job {id}'s {JSON_FILE} does not parse: {e}"))
        })?;
        let src = retarget::from_motion_json(&json).map_err(|e| retarget_error(id, e))?;
        retarget::render(&src, &target, format).map_err(|e| retarget_error(id, e))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("retargeting job {id}: {e}")))?
}

/// A retarget failure as the API answers it: the rig's fault is 422 on `rig`, the rest ours.
fn retarget_error(id: crate::queue::JobId, e: RetargetError) -> ApiError {
    match e {
        RetargetError::InvalidTarget(_)
        | RetargetError::MissingBone(_)
        | RetargetError::DuplicateBone(_) => ApiError::InvalidField {
            field: "rig".into(),
            message: e.to_string(),
        },
        RetargetError::NotChoreoMotion(_)
        | RetargetError::EmptyMotion
        | RetargetError::Write { .. } => {
            ApiError::Internal(format!("retargeting job {id}: {e} ({})", e.code()))
        }
    }
}

/// The response for rendered bytes: its type, a file name naming the rig, and the part of it
/// the request's `Range` asks for.
fn respond(
    request: &HeaderMap,
    bytes: Vec<u8>,
    content_type: &'static str,
    filename: &str,
) -> Result<Response, ApiError> {
    let disposition = HeaderValue::from_str(&format!("attachment; filename=\"{filename}\""))
        .unwrap_or_else(|_| HeaderValue::from_static("attachment"));
    super::ranges::bytes(
        request,
        bytes,
        [
            (header::CONTENT_TYPE, HeaderValue::from_static(content_type)),
            (header::CONTENT_DISPOSITION, disposition),
        ],
    )
}

/// `motion.bvh` or `motion.glb` on the rig asked for.
async fn on_rig(
    state: State<AppState>,
    caller: Caller,
    id: String,
    rig: Option<String>,
    format: Format,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    let (file, content_type, ext) = match format {
        Format::Glb => ("motion.glb", "model/gltf-binary", "glb"),
        _ => ("motion.bvh", "text/plain; charset=utf-8", "bvh"),
    };
    let rig = rig.unwrap_or_else(|| "choreo".into());
    let job = finished_job(&state, caller, &id).await?;
    let Some(target) = resolve_rig(&state, &job, &rig).await? else {
        return super::jobs::result(state, caller, Path((id, file.to_string())), request).await;
    };
    let bytes = render(&state, &job, target, format).await?;
    // The rig is a built-in name or an id here: safe in a header.
    respond(
        &request,
        bytes,
        content_type,
        &format!("motion.{rig}.{ext}"),
    )
}

/// A succeeded generate job's dance as BVH, on choreo's rig or another.
///
/// `rig=choreo` (default) is the file the job wrote. Any other rig is computed from the job's
/// motion.json: each bone of the target points where choreo's matching bone points, twist taken
/// from choreo's rotations, the hips scaled by leg length and the feet kept on the floor (foot IK).
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/motion.bvh",
    operation_id = "getJobMotionBvh",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id"), RigQuery, ("Range" = Option<String>, Header, description = "One byte range; without it, the whole file")),
    responses(
        (status = 200, description = "BVH text, metres, y up", content_type = "text/plain"),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which"),
        (status = 400, description = "An unknown query parameter", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job, or no such rig (`rig-not-found`)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "The rig lacks a bone a dance needs", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn motion_bvh(
    state: State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<RigQuery>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    on_rig(state, caller, id, q.rig, Format::Bvh, request).await
}

/// A succeeded generate job's dance as glTF binary, on choreo's rig or another.
///
/// One node per joint of the rig, a skin over them and one animation. `rig` as for motion.bvh.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/motion.glb",
    operation_id = "getJobMotionGlb",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id"), RigQuery, ("Range" = Option<String>, Header, description = "One byte range; without it, the whole file")),
    responses(
        (status = 200, description = "glTF 2.0 binary", content_type = "model/gltf-binary"),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which"),
        (status = 400, description = "An unknown query parameter", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such job, or no such rig (`rig-not-found`)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "The rig lacks a bone a dance needs", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn motion_glb(
    state: State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    ApiQuery(q): ApiQuery<RigQuery>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    on_rig(state, caller, id, q.rig, Format::Glb, request).await
}

/// A succeeded generate job's dance as a VRM Animation (`.vrma`) for any VRM 1.0 avatar.
///
/// glTF 2.0 binary with the `VRMC_vrm_animation` extension (specVersion 1.0): the VRM humanoid
/// bones in the T-pose, the hips' translation and every bone's rotation. `@pixiv/three-vrm-animation`
/// loads it (`VRMAnimationLoaderPlugin`) and `createVRMAnimationClip` applies it to any VRM.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/motion.vrma",
    operation_id = "getJobMotionVrma",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id"), ("Range" = Option<String>, Header, description = "One byte range; without it, the whole file")),
    responses(
        (status = 200, description = "VRM Animation (glTF 2.0 binary)", content_type = "model/gltf-binary"),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn motion_vrma(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    let job = finished_job(&state, caller, &id).await?;
    let bytes = render(&state, &job, retarget::vrm(), Format::Vrma).await?;
    respond(&request, bytes, "model/gltf-binary", "motion.vrma")
}

/// A succeeded generate job's dance as SMPL parameters, AMASS-style (`numpy.load`).
///
/// `poses` `[T, 72]` (axis-angle per joint, SMPL's joint order, radians), `trans` `[T, 3]`
/// (metres, y up), `mocap_framerate`, `betas` (16 zeros), `gender` (`neutral`). SMPL's rest joints
/// are approximated (its model file is not shipped): see `motion::retarget::smpl`.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/motion.smpl.npz",
    operation_id = "getJobMotionSmpl",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id"), ("Range" = Option<String>, Header, description = "One byte range; without it, the whole file")),
    responses(
        (status = 200, description = "numpy .npz (zip of .npy arrays)", content_type = "application/octet-stream"),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn motion_smpl(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    let job = finished_job(&state, caller, &id).await?;
    let bytes = render(&state, &job, retarget::smpl(), Format::SmplNpz).await?;
    respond(
        &request,
        bytes,
        "application/octet-stream",
        "motion.smpl.npz",
    )
}
