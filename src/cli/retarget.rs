//! `choreo retarget MOTION.json --rig mixamo|vrm|smpl|FILE --out F`, and the retargeted files
//! `choreo generate --rig R` writes beside the others.
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use choreo::motion::export::{write_atomic, MotionJson};
use choreo::motion::retarget::{self, Format, TargetSkeleton};

/// `choreo retarget` arguments.
#[derive(Clone, Debug, clap::Args)]
pub struct RetargetArgs {
    /// A motion.json: a job's, `choreo generate`'s or `choreo export --format json`'s.
    pub motion: PathBuf,
    /// The target: mixamo, vrm or smpl (built in), or a BVH or glb file whose skeleton stands in a rest pose
    /// (joints mapped by name, as `POST /v1/rigs` maps them).
    #[arg(long)]
    pub rig: String,
    /// Output file, by extension: .bvh or .glb (any rig), .vrma (vrm), .npz (smpl).
    #[arg(long)]
    pub out: PathBuf,
}

/// The target a `--rig` names.
pub fn target(rig: &str) -> anyhow::Result<TargetSkeleton> {
    if let Some(t) = retarget::builtin(rig) {
        return Ok(t);
    }
    if Path::new(rig).is_file() {
        // The same reader `POST /v1/rigs` uses: BVH or glb in a rest pose, joints mapped by name.
        let bytes = std::fs::read(rig).with_context(|| format!("reading {rig}"))?;
        let read = retarget::uploaded::read(&bytes, &Default::default())
            .with_context(|| format!("reading the skeleton of {rig}"))?;
        return Ok(read.skeleton);
    }
    bail!(
        "unknown rig {rig:?}: use {} or a BVH or glb file",
        retarget::BUILTINS.join(", ")
    )
}

/// The format an output path asks for, checked against the rig.
fn format(out: &Path, rig: &str) -> anyhow::Result<Format> {
    let name = out.file_name().and_then(|n| n.to_str()).unwrap_or_default();
    let format = match name.rsplit('.').next() {
        Some("bvh") => Format::Bvh,
        Some("glb") => Format::Glb,
        Some("vrma") => Format::Vrma,
        Some("npz") => Format::SmplNpz,
        _ => bail!(
            "{}: name the output .bvh, .glb, .vrma (vrm) or .npz (smpl)",
            out.display()
        ),
    };
    match (format, rig) {
        (Format::Vrma, r) if r != "vrm" => bail!(".vrma is VRM Animation: use --rig vrm"),
        (Format::SmplNpz, r) if r != "smpl" => bail!(".npz holds SMPL parameters: use --rig smpl"),
        _ => Ok(format),
    }
}

/// Reads a motion.json as the rig motion it describes.
fn read_motion(path: &Path) -> anyhow::Result<choreo::motion::rig::RigMotion> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let json: MotionJson = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a motion.json", path.display()))?;
    Ok(retarget::from_motion_json(&json)?)
}

/// `choreo retarget`: one file.
pub fn run(args: &RetargetArgs) -> anyhow::Result<()> {
    let format = format(&args.out, &args.rig)?;
    let target = target(&args.rig)?;
    let src = read_motion(&args.motion)?;
    let bytes = retarget::render(&src, &target, format).context("choreo retarget")?;
    write_atomic(&args.out, &bytes)?;
    println!("{}", args.out.display());
    Ok(())
}

/// The files `choreo generate --rig R` adds in `dir` from its motion.json: `motion.R.bvh` and
/// `motion.R.glb`, and `motion.vrma` (vrm) or `motion.smpl.npz` (smpl). `choreo` adds nothing.
pub fn beside(dir: &Path, rig: &str) -> anyhow::Result<Vec<PathBuf>> {
    if rig == "choreo" {
        return Ok(Vec::new());
    }
    let target = target(rig)?;
    let src = read_motion(&dir.join(choreo::motion::export::JSON_FILE))?;
    let mut files = vec![
        (format!("motion.{rig}.bvh"), Format::Bvh),
        (format!("motion.{rig}.glb"), Format::Glb),
    ];
    match rig {
        "vrm" => files.push(("motion.vrma".into(), Format::Vrma)),
        "smpl" => files.push(("motion.smpl.npz".into(), Format::SmplNpz)),
        _ => {}
    }
    let mut written = Vec::new();
    for (name, format) in files {
        let path = dir.join(name);
        write_atomic(
            &path,
            &retarget::render(&src, &target, format)
                .with_context(|| format!("writing {}", path.display()))?,
        )?;
        written.push(path);
    }
    Ok(written)
}
