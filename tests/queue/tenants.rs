//! Tenancy in the store's contract, run on both stores by `contract!` in `tests/queue.rs`: what
//! one tenant can see of another's rows (nothing), and how the claim shares the workers between
//! tenants.
use super::*;

/// Two tenants share nothing they can see: the same bytes are two songs, an idempotency key is
/// each one's own, and every scoped read, listing and cancel of the other's id is "not found".
pub async fn tenants_see_only_their_own_rows(db: TestDb) {
    let store = db.store.as_ref();
    let (a, b) = (TenantId::new(), TenantId::new());
    let song_of = |tenant| Song {
        tenant,
        ..song("shared-bytes")
    };
    let job_of = |tenant, song| NewJob {
        tenant,
        ..analyze(song, 1)
    };
    let first = song_of(a);
    let (song_a, created_a) = store
        .add_song(first.clone(), job_of(a, first.id))
        .await
        .expect("a's song");
    let second = song_of(b);
    let (song_b, created_b) = store
        .add_song(second.clone(), job_of(b, second.id))
        .await
        .expect("b's song");
    assert!(
        created_a && created_b,
        "the same bytes from two tenants are two songs"
    );
    assert_ne!(song_a.id, song_b.id);
    assert_eq!((song_a.tenant, song_b.tenant), (a, b));
    assert_eq!(
        store
            .song_by_sha256(a, "shared-bytes")
            .await
            .expect("by sha")
            .map(|s| s.id),
        Some(song_a.id)
    );
    assert_eq!(
        store
            .song_by_sha256(TenantId::OPEN, "shared-bytes")
            .await
            .expect("by sha")
            .map(|s| s.id),
        None
    );
    assert!(matches!(
        store.song(Scope::Tenant(b), song_a.id).await,
        Err(QueueError::SongNotFound(_))
    ));
    assert_eq!(
        store
            .song(Scope::Tenant(a), song_a.id)
            .await
            .expect("own song")
            .id,
        song_a.id
    );

    // A job on another tenant's song is refused as if the song did not exist.
    assert!(matches!(
        store.register(job_of(b, song_a.id)).await,
        Err(QueueError::SongNotFound(_))
    ));
    let keyed = |tenant, song| NewJob {
        idempotency: Some(Idempotency {
            key: "same-key".into(),
            request_hash: "h".into(),
        }),
        ..job_of(tenant, song)
    };
    let job_a = store.register(keyed(a, song_a.id)).await.expect("a's job");
    let job_b = store.register(keyed(b, song_b.id)).await.expect("b's job");
    assert!(
        matches!(job_b, Registered::Created(_)),
        "an idempotency key is one tenant's"
    );
    let (job_a, job_b) = (job_a.job().clone(), job_b.job().clone());
    assert_eq!((job_a.tenant, job_b.tenant), (a, b));

    assert!(matches!(
        store.job(Scope::Tenant(b), job_a.id).await,
        Err(QueueError::JobNotFound(_))
    ));
    assert!(matches!(
        store.cancel(Scope::Tenant(b), job_a.id).await,
        Err(QueueError::JobNotFound(_))
    ));
    assert_eq!(
        store
            .job(Scope::Tenant(a), job_a.id)
            .await
            .expect("own job")
            .status,
        Status::Queued
    );
    let listed = |scope| async move {
        let jobs = store
            .jobs(
                scope,
                JobFilter {
                    limit: 100,
                    ..JobFilter::default()
                },
            )
            .await
            .expect("list");
        jobs.iter().map(|j| j.id).collect::<HashSet<_>>()
    };
    let (of_a, of_b, all) = (
        listed(Scope::Tenant(a)).await,
        listed(Scope::Tenant(b)).await,
        listed(Scope::All).await,
    );
    assert!(of_a.contains(&job_a.id) && !of_a.contains(&job_b.id));
    assert!(of_b.contains(&job_b.id) && !of_b.contains(&job_a.id));
    assert!(all.contains(&job_a.id) && all.contains(&job_b.id));
    assert!(of_a.iter().chain(&of_b).all(|id| all.contains(id)) && of_a.is_disjoint(&of_b));
}

/// One tenant's many jobs, even at a higher priority, do not keep another tenant's job waiting:
/// the tenant with the fewest jobs running goes first, then the one served least recently;
/// priority orders each tenant's own jobs.
pub async fn claims_are_fair_between_tenants(db: TestDb) {
    let store = db.store.as_ref();
    let p = policy(30_000, 0);
    let (a, b) = (TenantId::new(), TenantId::new());
    let song_of = |tenant, sha: &str| Song {
        tenant,
        ..song(sha)
    };
    let job_of = |tenant, song, priority| NewJob {
        tenant,
        priority,
        ..analyze(song, 1)
    };
    let sa = song_of(a, "a-bytes");
    store
        .add_song(sa.clone(), job_of(a, sa.id, 0))
        .await
        .expect("a's song");
    for _ in 0..20 {
        store
            .register(job_of(a, sa.id, 100))
            .await
            .expect("a's urgent job");
    }
    let sb = song_of(b, "b-bytes");
    store
        .add_song(sb.clone(), job_of(b, sb.id, 0))
        .await
        .expect("b's song");

    // Neither has run anything: priority decides, among equals.
    let first = store.claim("w", p).await.expect("claim").expect("a job");
    assert_eq!((first.tenant, first.priority), (a, 100));
    assert!(store
        .complete(first.id, "w", Outcome::Files(JobFiles::default()))
        .await
        .expect("complete"));
    // Nobody runs anything: b was never served, a just was, so b's job goes before a's
    // nineteen urgent ones.
    let second = store.claim("w", p).await.expect("claim").expect("a job");
    assert_eq!(
        second.tenant, b,
        "b's only job is not starved by a's twenty"
    );
    // b has one running and a none: a goes next, its highest priority first.
    store
        .register(job_of(b, sb.id, 0))
        .await
        .expect("b's second job");
    // Times are kept in milliseconds: let a's next start be later than b's.
    tokio::time::sleep(Duration::from_millis(5)).await;
    let third = store.claim("w", p).await.expect("claim").expect("a job");
    assert_eq!((third.tenant, third.priority), (a, 100));
    // One running each; a was served last, so b's second job comes before a's others.
    let fourth = store.claim("w", p).await.expect("claim").expect("a job");
    assert_eq!(fourth.tenant, b);
}
