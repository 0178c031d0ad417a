//! `choreo bench jobs` runs its dances through the real service: every job it queues succeeds,
//! with one worker and with two, and its rows say so. (Its timings are the bench's to print,
//! not this test's to judge.)
use crate::common_models::models_dir;
use crate::helpers::{short_song, test_config};
use choreo::api::bench::jobs::{run, JobsBench};

#[tokio::test]
async fn the_jobs_bench_dances_every_job_it_queues_with_one_and_two_workers() {
    let data = tempfile::tempdir().expect("tempdir");
    let mut config = test_config(data.path());
    config.models_dir = models_dir();
    let rows = run(JobsBench {
        song: short_song(),
        model: "beat-graph".into(),
        jobs: 3,
        workers: vec![1, 2],
        config,
    })
    .await
    .expect("the bench runs");
    assert_eq!(rows.len(), 2, "{rows:?}");
    for (row, workers) in rows.iter().zip([1, 2]) {
        assert_eq!(row.workers, workers, "{row:?}");
        assert_eq!(row.succeeded, 3, "{row:?}");
        assert!(row.seconds > 0.0 && row.jobs_per_min.is_finite(), "{row:?}");
    }
    assert_eq!(rows[0].speedup, 1.0);
    assert_eq!(rows[1].ideal_speedup, 2.0);
}
