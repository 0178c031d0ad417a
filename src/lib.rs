//! choreo: a service that turns a song into a dance.
//!
//! # The life of a job
//! Data flows one way, and each step lives in its own module:
//!
//! 1. **upload** (`api`): `POST /v1/songs` stores the bytes under the data dir, named by their
//!    id, after `audio` has proved them decodable, and publishes them to the artifact store
//!    (`artifacts`: the data dir, or an S3 bucket). An `analyze` job is queued for the song.
//! 2. **queue** (`queue`): jobs are rows in SQLite, or in PostgreSQL shared by API and worker
//!    processes. A worker claims one in a single atomic `UPDATE … RETURNING` (`FOR UPDATE SKIP
//!    LOCKED` in PostgreSQL), holds a lease and heartbeats; expired leases are requeued.
//! 3. **decode → features** (`audio`): symphonia decodes, rubato resamples, and the feature
//!    sets each paper used are computed to match librosa. A generate job computes the song's
//!    beats and each feature set once per song: `song_cache` stores them with the song, and the
//!    song's later jobs read them instead of decoding it again.
//! 4. **model** (`models`): one file per paper; libtorch runs on the worker's blocking thread.
//! 5. **motion** (`motion`): the model's poses become a rigid skeleton with rotations.
//! 6. **export + report** (`motion` exporters, `metrics`, `report`): BVH, JSON, glb, the
//!    report of how well it dances, and `preview.png`, a contact sheet to see it at a glance.
//!
//! A job's status, stage and progress changes are lines of `job_events`, written by triggers on
//! its row; `GET /v1/jobs/{id}/events` streams them (`api::events`), and when a job with a
//! `webhook_url` ends, the workers POST it there, signed (`webhooks`).
//!
//! Beside the flow, `eval` (`choreo eval`) runs the models on the test split and on whole songs
//! and judges them with `metrics`: it sits above `models` and `metrics`, and `metrics` measures
//! motion without knowing any model. The command line (flags, printed tables, progress bar)
//! lives in the binary (`src/cli/`); the library takes plain option structs whose `Default` is
//! the committed schedule.
//!
//! # Who owns libtorch
//! Only worker threads (tokio blocking threads) and the CLI's `train`/`generate`/`eval` call into
//! libtorch. Each worker runs with one intra-op thread, so N workers never oversubscribe the cores.
pub mod api;
pub mod artifacts;
pub mod audio;
pub mod config;
pub mod eval;
pub mod metrics;
pub mod models;
pub mod motion;
pub mod queue;
pub mod report;
pub mod song_cache;
pub mod stage;
pub mod telemetry;
pub mod webhooks;
pub mod worker;
