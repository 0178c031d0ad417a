//! Deletion and retention in the store's contract, run on both stores by `contract!` in
//! `tests/queue.rs`.
use super::*;

/// A generate job of `song` (dance-revolution, seed 0).
fn dance(song: SongId) -> NewJob {
    NewJob {
        kind: JobKind::Generate(choreo::queue::GenerateOptions {
            song_id: song,
            model: choreo::models::ModelId("dance-revolution".into()),
            seed: 0,
            key_poses: Vec::new(),
            seed_motion: None,
            plant_feet: true,
            style: None,
            temperature: None,
            top_k: None,
            webhook_url: None,
        }),
        ..analyze(song, 1)
    }
}

/// Deletion and retention (`queue/sql/delete.rs`): a song goes with every job made from it, a
/// running one included (its worker's heartbeat and outcome then match no row); a finished job
/// goes on its own, an unfinished one never; expiry takes finished dances unused since the
/// cutoff, then songs none of whose jobs is unfinished or used since; each removed job leaves a
/// `deleted` line in `job_events`, and another tenant removes nothing.
pub async fn deletion_and_expiry_leave_only_an_audit_line(db: TestDb) {
    let store = db.store.as_ref();
    let p = policy(60_000, 0);
    let stranger = Scope::Tenant(TenantId::new());
    let owner = Scope::Tenant(TenantId::OPEN);
    let deleted = |from: &str| Some((Some(from.to_string()), "deleted".to_string()));

    // A song whose analyze job is running.
    let first = with_song(store).await;
    let running = store.claim("w", p).await.expect("claim").expect("a job");
    assert_eq!(running.kind.song_id(), first);
    assert!(matches!(
        store.delete_song(stranger, first, "no").await,
        Err(QueueError::SongNotFound(_))
    ));
    let removed = store
        .delete_song(owner, first, "deleted with its song")
        .await
        .expect("delete song");
    assert_eq!(
        removed.songs.iter().map(|s| s.id).collect::<Vec<_>>(),
        vec![first]
    );
    assert_eq!(
        removed.jobs.iter().map(|j| j.id).collect::<Vec<_>>(),
        vec![running.id]
    );
    assert_eq!(
        store
            .heartbeat(running.id, "w", "analyze", 0.5, p)
            .await
            .expect("beat"),
        Beat::Lost
    );
    assert!(!store
        .complete(running.id, "w", Outcome::Files(JobFiles::default()))
        .await
        .expect("complete"));
    assert!(matches!(
        store.song(Scope::All, first).await,
        Err(QueueError::SongNotFound(_))
    ));
    assert!(matches!(
        store.job(Scope::All, running.id).await,
        Err(QueueError::JobNotFound(_))
    ));
    assert_eq!(
        db.events(running.id).await.last().cloned(),
        deleted("running")
    );

    // A job alone: not while queued, and only by its tenant once finished.
    let second = with_song(store).await;
    let queued = store.analyze_job(second).await.expect("read").expect("job");
    assert!(matches!(
        store.delete_job(owner, queued.id, "no").await,
        Err(QueueError::JobNotFound(_))
    ));
    store
        .job(Scope::All, queued.id)
        .await
        .expect("a queued job stays");
    store.cancel(owner, queued.id).await.expect("cancel");
    assert!(matches!(
        store.delete_job(stranger, queued.id, "no").await,
        Err(QueueError::JobNotFound(_))
    ));
    let gone = store
        .delete_job(owner, queued.id, "deleted by its owner")
        .await
        .expect("delete job");
    assert_eq!(gone.status, Status::Cancelled);
    assert_eq!(
        db.events(queued.id).await.last().cloned(),
        deleted("cancelled")
    );
    store
        .song(Scope::All, second)
        .await
        .expect("its song stays");

    // Expiry: nothing is older than an hour ago; a dance waiting keeps its song.
    let job = store
        .register(dance(second))
        .await
        .expect("register")
        .job()
        .id;
    let later = Utc::now() + chrono::Duration::hours(1);
    assert!(store
        .expire(Utc::now() - chrono::Duration::hours(1), 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    assert!(store
        .expire(later, 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    let claimed = store
        .claim("w", p)
        .await
        .expect("claim")
        .expect("the dance");
    assert_eq!(claimed.id, job);
    assert!(store
        .complete(job, "w", Outcome::Files(JobFiles::default()))
        .await
        .expect("complete"));
    // A use after the cutoff keeps the dance, and the dance keeps its song.
    let cutoff = Utc::now();
    tokio::time::sleep(Duration::from_millis(20)).await;
    store.touch_job(job).await.expect("touch");
    assert!(store
        .expire(cutoff, 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    let expired = store.expire(later, 100, "expired").await.expect("expire");
    assert_eq!(
        expired.songs.iter().map(|s| s.id).collect::<Vec<_>>(),
        vec![second]
    );
    assert_eq!(
        expired.jobs.iter().map(|j| j.id).collect::<Vec<_>>(),
        vec![job]
    );
    assert_eq!(db.events(job).await.last().cloned(), deleted("succeeded"));
    assert!(matches!(
        store.song(Scope::All, second).await,
        Err(QueueError::SongNotFound(_))
    ));
    // A song's own use (an upload of the same bytes, its audio) keeps it past an earlier cutoff.
    let third = with_song(store).await;
    let analysis = store.analyze_job(third).await.expect("read").expect("job");
    store.cancel(owner, analysis.id).await.expect("cancel");
    let cutoff = Utc::now() + chrono::Duration::milliseconds(5);
    tokio::time::sleep(Duration::from_millis(20)).await;
    store.touch_song(third).await.expect("touch");
    assert!(store
        .expire(cutoff, 100, "expired")
        .await
        .expect("expire")
        .is_empty());
    let expired = store.expire(later, 100, "expired").await.expect("expire");
    assert_eq!(expired.songs.len(), 1);
    assert_eq!(
        expired.jobs.iter().map(|j| j.id).collect::<Vec<_>>(),
        vec![analysis.id]
    );
}
