//! Uploaded rigs: the stored row of a skeleton to retarget dances onto, and the `RigStore` trait.
//!
//! A rig lives like a song: uploaded (`add_rig`), read by the downloads that name it (each one a
//! use, [`RigStore::touch_rig`]), listed, deleted by its tenant ([`RigStore::delete_rig`]) or
//! expired `retention_days` after its last use (with the songs and jobs, in
//! [`super::SongStore::expire`]). Rows go first and files after, by the caller, as for songs:
//! what a failed removal leaves has no row, and the data dir's sweep takes it.
use super::{KeyLimits, Removed, RigId, Scope, StoreFuture, TenantId};
use crate::motion::retarget::uploaded::{RigFormat, Units};
use crate::motion::retarget::TargetSkeleton;
use chrono::{DateTime, Utc};

/// An uploaded rig (a skeleton to retarget dances onto), as stored.
#[derive(Clone, Debug)]
pub struct UploadedRig {
    pub id: RigId,
    pub tenant: TenantId,
    /// The upload's own name, for display only.
    pub filename: String,
    /// Found from the bytes.
    pub format: RigFormat,
    /// The unit the file's rest pose was read in (the skeleton is in metres).
    pub units: Units,
    pub sha256: String,
    pub size_bytes: u64,
    /// The skeleton read from the file, with its humanoid mapping.
    pub skeleton: TargetSkeleton,
    pub created_at: DateTime<Utc>,
}

/// The page of `GET /v1/rigs`.
#[derive(Clone, Copy, Debug, Default)]
pub struct RigFilter {
    /// Return rigs older than this one (the cursor).
    pub before: Option<RigId>,
    pub limit: u32,
}

/// The uploaded rigs.
pub trait RigStore: Send + Sync {
    /// Stores a new rig (its file is already published).
    fn add_rig(&self, rig: UploadedRig) -> StoreFuture<'_, UploadedRig> {
        self.add_rig_within(rig, KeyLimits::default())
    }
    /// [`RigStore::add_rig`] within the tenant's `limits`: `QuotaExceeded` when its bytes would
    /// pass `storage_quota_bytes`, checked in the transaction that inserts it.
    fn add_rig_within(&self, rig: UploadedRig, limits: KeyLimits) -> StoreFuture<'_, UploadedRig>;
    /// One rig.
    fn rig(&self, scope: Scope, id: RigId) -> StoreFuture<'_, UploadedRig>;
    /// Rigs, newest first.
    fn rigs(&self, scope: Scope, filter: RigFilter) -> StoreFuture<'_, Vec<UploadedRig>>;
    /// Removes a rig's row; returns it (in [`Removed::rigs`]), whose file is the caller's to
    /// remove. No rig with the id in scope is [`super::QueueError::RigNotFound`].
    fn delete_rig(&self, scope: Scope, id: RigId) -> StoreFuture<'_, Removed>;
    /// Records a use of the rig (a download that names it), which restarts its retention.
    fn touch_rig(&self, id: RigId) -> StoreFuture<'_, ()>;
}
