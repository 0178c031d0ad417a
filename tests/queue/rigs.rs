//! The rig store's contract (`queue/sql/rigs.rs`), run on both stores by `contract!` in
//! `tests/queue.rs`: a rig keeps its skeleton; a tenant lists its own rigs newest first, a page
//! at a time; a deletion is its tenant's alone and frees the rig's bytes; expiry takes the rigs
//! unused since the cutoff, a use being [`RigStore::touch_rig`].
use super::TestDb;
use choreo::motion::retarget::uploaded::{RigFormat, Units};
use choreo::motion::retarget::{HumanBone, TargetSkeleton};
use choreo::motion::rig::Rig;
use choreo::queue::{QueueError, RigFilter, RigId, Scope, Store, TenantId, UploadedRig};
use chrono::Utc;
use std::time::Duration;

/// A three-joint skeleton with two mapped joints.
fn skeleton() -> TargetSkeleton {
    TargetSkeleton {
        rig: Rig {
            names: vec!["Hips".into(), "Spine".into(), "Bone.001".into()],
            parents: vec![None, Some(0), Some(1)],
            offsets: vec![
                nalgebra::Vector3::new(0.0, 0.95, 0.0),
                nalgebra::Vector3::new(0.0, 0.1, 0.0),
                nalgebra::Vector3::new(0.0, 0.125, 0.0),
            ],
        },
        humanoid: vec![Some(HumanBone::Hips), Some(HumanBone::Spine), None],
        armature: "Avatar".into(),
    }
}

/// A rig of `tenant`'s, `size_bytes` long, not yet stored.
fn rig(tenant: TenantId, size_bytes: u64) -> UploadedRig {
    UploadedRig {
        id: RigId::new(),
        tenant,
        filename: "mine.bvh".into(),
        format: RigFormat::Bvh,
        units: Units::Cm,
        sha256: "abc".into(),
        size_bytes,
        skeleton: skeleton(),
        created_at: Utc::now(),
    }
}

async fn ids(store: &dyn Store, scope: Scope, before: Option<RigId>, limit: u32) -> Vec<RigId> {
    store
        .rigs(scope, RigFilter { before, limit })
        .await
        .expect("list rigs")
        .iter()
        .map(|r| r.id)
        .collect()
}

pub async fn rigs_keep_their_skeleton_and_mapping(db: TestDb) {
    let store = db.store.as_ref();
    let rig = rig(TenantId::OPEN, 123);
    let stored = store.add_rig(rig.clone()).await.expect("add rig");
    let read = store.rig(Scope::All, rig.id).await.expect("read rig");
    for got in [&stored, &read] {
        assert_eq!(
            (
                got.id,
                got.filename.as_str(),
                got.format,
                got.units,
                got.size_bytes
            ),
            (rig.id, "mine.bvh", RigFormat::Bvh, Units::Cm, 123)
        );
        assert_eq!(got.skeleton, skeleton());
    }
    assert!(matches!(
        store.rig(Scope::All, RigId::new()).await,
        Err(QueueError::RigNotFound(_))
    ));
}

/// Listing, deletion and expiry of rigs, and what each leaves of another tenant's.
pub async fn rigs_list_by_tenant_delete_once_and_expire_unused(db: TestDb) {
    let store = db.store.as_ref();
    let (a, b) = (TenantId::new(), TenantId::new());
    let mut mine = Vec::new();
    for size in [100, 200, 300] {
        mine.push(store.add_rig(rig(a, size)).await.expect("a's rig").id);
    }
    let theirs = store.add_rig(rig(b, 1000)).await.expect("b's rig").id;

    // Newest first, a page at a time, each tenant its own; every tenant's in the whole scope.
    let (oldest, middle, newest) = (mine[0], mine[1], mine[2]);
    assert_eq!(
        ids(store, Scope::Tenant(a), None, 2).await,
        vec![newest, middle]
    );
    assert_eq!(
        ids(store, Scope::Tenant(a), Some(middle), 2).await,
        vec![oldest]
    );
    assert_eq!(ids(store, Scope::Tenant(b), None, 10).await, vec![theirs]);
    assert_eq!(
        ids(store, Scope::All, None, 10).await,
        vec![theirs, newest, middle, oldest]
    );

    // Deletion: another tenant's id is not found and stays; the owner's goes once, with its bytes.
    assert_eq!(store.usage(a).await.expect("usage").stored_bytes, 600);
    assert!(matches!(
        store.delete_rig(Scope::Tenant(b), middle).await,
        Err(QueueError::RigNotFound(_))
    ));
    store
        .rig(Scope::Tenant(a), middle)
        .await
        .expect("still a's");
    let removed = store
        .delete_rig(Scope::Tenant(a), middle)
        .await
        .expect("delete");
    assert_eq!(
        removed.rigs.iter().map(|r| r.id).collect::<Vec<_>>(),
        vec![middle]
    );
    assert!(removed.songs.is_empty() && removed.jobs.is_empty());
    assert!(matches!(
        store.rig(Scope::All, middle).await,
        Err(QueueError::RigNotFound(_))
    ));
    assert!(matches!(
        store.delete_rig(Scope::Tenant(a), middle).await,
        Err(QueueError::RigNotFound(_))
    ));
    assert_eq!(store.usage(a).await.expect("usage").stored_bytes, 400);
    assert_eq!(
        ids(store, Scope::Tenant(a), None, 10).await,
        vec![newest, oldest]
    );

    // Expiry: nothing was used before an hour ago; a use after the cutoff keeps a rig, the
    // others go, at most `limit` a pass; once unused, the kept one goes too.
    let later = Utc::now() + chrono::Duration::hours(1);
    assert!(store
        .expire(Utc::now() - chrono::Duration::hours(1), 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    tokio::time::sleep(Duration::from_millis(5)).await;
    let cutoff = Utc::now();
    tokio::time::sleep(Duration::from_millis(20)).await;
    store.touch_rig(newest).await.expect("touch");
    let first = store.expire(cutoff, 1, "expired").await.expect("expire");
    let second = store.expire(cutoff, 100, "expired").await.expect("expire");
    assert_eq!(
        (first.rigs.len(), second.rigs.len()),
        (1, 1),
        "a pass takes at most `limit`"
    );
    let mut expired: Vec<RigId> = first
        .rigs
        .iter()
        .chain(&second.rigs)
        .map(|r| r.id)
        .collect();
    expired.sort();
    let mut unused = vec![oldest, theirs];
    unused.sort();
    assert_eq!(expired, unused);
    assert!(store
        .expire(cutoff, 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    store
        .rig(Scope::Tenant(a), newest)
        .await
        .expect("the used rig stays");
    let last = store.expire(later, 100, "expired").await.expect("expire");
    assert_eq!(
        last.rigs.iter().map(|r| r.id).collect::<Vec<_>>(),
        vec![newest]
    );
    assert!(ids(store, Scope::All, None, 10).await.is_empty());
    assert_eq!(store.usage(a).await.expect("usage").stored_bytes, 0);
}
