//! The `choreo` command line: every `clap` argument, the tables printed and the progress bar.
//!
//! The library takes plain option structs (`EvalOptions`, `train::dancenet::Options`, …) whose
//! `Default` is the committed schedule; each argument struct here reads its defaults from that
//! `Default` (so `--help` and the library cannot disagree) and converts into it.
use std::path::PathBuf;

use anyhow::Context;
use choreo::config::Overrides;
use clap::{Args, Parser, Subcommand};

/// Declares a clap argument struct and its conversion into the library's options struct, field
/// for field (each through `Into`, so a flattened group converts into the library's group).
macro_rules! args_into {
    ($(#[$m:meta])* pub struct $name:ident => $lib:path { $($(#[$fm:meta])* $field:ident : $ty:ty),* $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, Debug, clap::Args)]
        pub struct $name {
            $($(#[$fm])* pub $field: $ty,)*
        }

        impl From<$name> for $lib {
            fn from(a: $name) -> Self {
                Self { $($field: a.$field.into(),)* }
            }
        }
    };
}

pub mod bench;
pub mod eval;
pub mod export;
pub mod generate;
pub mod keys;
pub mod retarget;
pub mod train;

#[derive(Parser)]
#[command(
    name = "choreo",
    version,
    about = "A service that turns a song into a dance"
)]
pub struct Cli {
    /// Config file; defaults to ./config.toml when present.
    #[arg(long, global = true, env = "CHOREO_CONFIG")]
    pub config: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run the HTTP service and its workers (`--no-workers`: the API only).
    Serve(ServeArgs),
    /// Run workers only, no HTTP: they take jobs from the configured database.
    Worker(WorkerArgs),
    /// Print a song's tempo, beats and downbeats as JSON.
    Analyze {
        /// An mp3, wav, flac, ogg or m4a file.
        path: PathBuf,
    },
    /// Print the libtorch version, thread settings, data dir and the models found.
    Doctor(ServiceArgs),
    /// Score Real, Mismatched-real and models on the test split (Markdown table + JSON).
    Eval(eval::EvalArgs),
    /// Generate a dance for a song: motion.bvh, motion.json, motion.glb, report.json and preview.png
    /// (`--rig`: also the dance on a Mixamo, VRM or SMPL skeleton).
    Generate(generate::GenerateCmd),
    /// Train a model on the train split of dance-with-melody and write its folder under models/.
    Train {
        #[command(subcommand)]
        model: train::TrainArgs,
    },
    /// Write a dataset dance as BVH, JSON or glb through the exporter generated dances use.
    Export(export::ExportArgs),
    /// Put a motion.json's dance on another skeleton (Mixamo, VRM, SMPL): BVH, glb, .vrma or .npz.
    Retarget(retarget::RetargetArgs),
    /// API keys: create (prints the secret once), list, revoke; on the configured database,
    /// also while the server runs.
    Keys(keys::KeysArgs),
    /// Benchmarks.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
}

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Seconds per minute of music for each model, split by stage (decode → report).
    Generate(generate::BenchArgs),
    /// Throughput and p99 of GET /v1/jobs/{id} on loopback while the workers are busy.
    Http(bench::HttpBenchArgs),
    /// Decode + DanceRevolution features per song vs librosa (one thread each), peak memory.
    Audio(bench::AudioBenchArgs),
    /// Dances a minute through the service with 1 and 2 workers: many seeds of one song.
    Jobs(bench::JobsBenchArgs),
}

/// Flags that override the config file and `CHOREO_*` environment.
#[derive(Args, Default)]
pub struct ServiceArgs {
    /// Listen address, e.g. 127.0.0.1:8080 (port 0 picks one) [env: CHOREO_BIND].
    #[arg(long)]
    bind: Option<String>,
    /// Where the database, songs and results live [env: CHOREO_DATA_DIR].
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Where trained models live [env: CHOREO_MODELS_DIR].
    #[arg(long)]
    models_dir: Option<PathBuf>,
    /// Worker count; 0 = one per core [env: CHOREO_WORKERS].
    #[arg(long)]
    workers: Option<usize>,
}

impl ServiceArgs {
    pub fn overrides(&self) -> Overrides {
        Overrides {
            bind: self.bind.clone(),
            data_dir: self.data_dir.clone(),
            models_dir: self.models_dir.clone(),
            workers: self.workers,
        }
    }
}

#[derive(Args)]
pub struct ServeArgs {
    #[command(flatten)]
    pub service: ServiceArgs,
    /// Serve the API only; `choreo worker` processes sharing the database run the jobs.
    #[arg(long)]
    pub no_workers: bool,
}

#[derive(Args)]
pub struct WorkerArgs {
    /// Where songs and results live [env: CHOREO_DATA_DIR].
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Where trained models live [env: CHOREO_MODELS_DIR].
    #[arg(long)]
    models_dir: Option<PathBuf>,
    /// Worker count; 0 = one per core [env: CHOREO_WORKERS].
    #[arg(long)]
    workers: Option<usize>,
}

impl WorkerArgs {
    pub fn overrides(&self) -> Overrides {
        Overrides {
            data_dir: self.data_dir.clone(),
            models_dir: self.models_dir.clone(),
            workers: self.workers,
            ..Overrides::default()
        }
    }
}

/// The async runtime of the commands that need one.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Command {
        Cli::try_parse_from(std::iter::once("choreo").chain(args.iter().copied()))
            .expect("parses")
            .command
    }

    /// Every command given no flags hands the library exactly its `Default`.
    #[test]
    fn flags_left_out_give_the_library_defaults() {
        use choreo::models::train::{self as lib, Training};
        let same = |a: &dyn std::fmt::Debug, b: &dyn std::fmt::Debug| {
            assert_eq!(format!("{a:?}"), format!("{b:?}"))
        };
        for (name, want) in [
            (
                "dance-revolution",
                Training::DanceRevolution(lib::dance_revolution::Options::default()),
            ),
            (
                "dancenet",
                Training::Dancenet(lib::dancenet::Options::default()),
            ),
            (
                "keypose-transformer",
                Training::KeyposeTransformer(lib::keypose_transformer::Options::default()),
            ),
            ("tsmt", Training::Tsmt(lib::tsmt::Options::default())),
            (
                "dancenet-style",
                Training::DancenetStyle(lib::dancenet_style::Options::default()),
            ),
            (
                "motion-style",
                Training::MotionStyle(lib::motion_style::Options::default()),
            ),
        ] {
            let Command::Train { model } = parse(&["train", name]) else {
                panic!("train {name}")
            };
            same(&Training::from(model), &want);
        }
        let Command::Eval(e) = parse(&["eval"]) else {
            panic!("eval")
        };
        same(&e.options(), &choreo::eval::EvalOptions::default());
        assert_eq!(e.reference_out, PathBuf::from(choreo::eval::REFERENCE_PATH));
        let Command::Generate(g) = parse(&["generate", "song.ogg", "--out", "o"]) else {
            panic!("generate")
        };
        let want = choreo::worker::standalone::GenerateSong {
            song: "song.ogg".into(),
            out: "o".into(),
            ..Default::default()
        };
        assert_eq!(g.rig, "choreo");
        same(
            &choreo::worker::standalone::GenerateSong::from(g.song),
            &want,
        );
        let Command::Bench {
            what: BenchCommand::Generate(b),
        } = parse(&["bench", "generate"])
        else {
            panic!("bench generate")
        };
        same(
            &choreo::worker::standalone::BenchOptions::from(b),
            &choreo::worker::standalone::BenchOptions::default(),
        );
        let Command::Bench {
            what: BenchCommand::Audio(a),
        } = parse(&["bench", "audio"])
        else {
            panic!("bench audio")
        };
        same(
            &a.options(".".into()),
            &choreo::audio::bench::BenchOptions::default(),
        );
        let Command::Train {
            model: train::TrainArgs::DancenetStyle(s),
        } = parse(&["train", "dancenet-style", "--readout", "last"])
        else {
            panic!("readout")
        };
        assert_eq!(
            lib::classify::ClassifyOptions::from(s.schedule).readout,
            Some(choreo::models::dancenet::style::Readout::Last)
        );
    }
}
