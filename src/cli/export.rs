//! `choreo export DANCE_ID --format bvh|json|glb --out FILE`.
use std::path::PathBuf;

use anyhow::Context;
use choreo::motion::export::{export_dance, Format};

/// `choreo export DANCE_ID --format bvh|json|glb --out FILE`: a dataset dance through the same
/// exporter generated dances use.
#[derive(Clone, Debug, clap::Args)]
pub struct ExportArgs {
    /// Dataset dance id, e.g. DANCE_W_3.
    pub dance_id: String,
    /// Output format: bvh, json or glb.
    #[arg(long, value_parser = ["bvh", "json", "glb"])]
    pub format: String,
    /// Output file.
    #[arg(long)]
    pub out: PathBuf,
    /// The dance-with-melody folder.
    #[arg(long, default_value = choreo::motion::dataset::DEFAULT_ROOT)]
    pub dataset: PathBuf,
}

/// Runs the export.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let format: Format = args.format.parse().context("choreo export")?;
    export_dance(&args.dataset, &args.dance_id, format, &args.out).context("choreo export")
}
