//! API tests: the real service on port 0, real HTTP (reqwest), a real SQLite file on disk.
//! One module per endpoint or concern; `helpers::spawn_app()` starts the service.
mod artifacts;
mod bad_input;
mod bench;
mod cli;
#[path = "../common/models.rs"]
mod common_models;
mod concurrency;
mod crash;
mod dancenet;
mod delete;
mod events;
mod fairness;
mod generate;
mod health;
mod helpers;
mod hostile;
#[path = "../common/hostile_files.rs"]
mod hostile_files;
mod hostile_motion;
mod jobs;
mod keypose;
mod limits;
mod logs;
mod models;
#[path = "../common/motion_files.rs"]
mod motion_files;
mod openapi;
#[path = "../common/postgres.rs"]
mod postgres;
mod preview;
mod quotas;
mod ranges;
mod resilience;
mod retarget;
mod rig_lifecycle;
mod rigs;
mod roundtrip;
mod scale;
mod schemathesis;
mod serving;
mod song_cache;
mod songs;
mod tenants;
mod tsmt;
mod webhooks;
