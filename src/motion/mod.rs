//! Motion core: the 23-joint skeleton, the real dataset, representations, and exporters.
//!
//! - [`skeleton`]: joint names, hierarchy, mirror pairs, identified from the data.
//! - [`dataset`]: the dance-with-melody dances, their split, music alignment, normalisation.
//! - [`repr`]: what the models predict (root-relative poses + root velocity in the facing
//!   frame) with its exact inverse, and foot-contact labels.
//! - [`rotations`]: DanceNet's rotation features (root changes, 6-D local rotations, end
//!   effectors) with their inverse through the rig.
//! - [`beat_align`]: the served stage that moves a network's steps onto the song's beats.
//! - [`retarget`]: the dance on another skeleton (Mixamo, VRM, SMPL, an uploaded rig).
//! - [`input`] and [`validate`]: key poses and seed motion as users send them (either joint set,
//!   or BVH), made canonical and checked by the rules the API and the models share.
//!
//! Units everywhere: metres, seconds, y up, right-handed.
use std::path::PathBuf;

use ndarray::Array3;

use trace::{traced, ServingStage, StageCounts, StageObserver, Unobserved};

pub mod beat_align;
pub mod bursts;
pub mod bvh;
pub mod dataset;
pub mod export;
pub mod feet;
pub mod hang;
pub mod hold;
pub mod input;
pub mod input_error;
pub mod knees;
pub mod limits;
pub mod mannequin;
pub mod repr;
pub mod retarget;
pub mod rig;
pub mod rotations;
pub mod skeleton;
pub mod trace;
pub mod validate;

/// Frame rate of the dance-with-melody data.
pub const MOTION_FPS: f64 = 25.0;
/// Joints in the skeleton (21 anatomical + 2 hand-direction points).
pub const NUM_JOINTS: usize = 23;

/// A dance: world joint positions in metres, y up, `[T, J, 3]`.
#[derive(Clone, Debug)]
pub struct Motion {
    pub fps: f64,
    pub positions: Array3<f32>,
}

/// `3t² − 2t³` of `t` = `x` from `lo` to `hi`, clamped to `[0, 1]`: a ramp with no corner, the
/// one every stage (and the key-pose bridges) fades with.
pub fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The motion stage after any model, before export: the dance kept on the floor
/// ([`feet::keep_on_floor`]: grounded, and brought down where both feet stay up longer than a
/// hop), the feet planted ([`feet::plant_feet`]) and backward knees turned forward
/// ([`knees::bend_forward`]), unless the caller asked for the model's motion as it came. Jobs,
/// `choreo generate` and `choreo eval` all go through it.
pub fn finish(motion: Motion, plant_feet: bool) -> Motion {
    finish_observed(motion, plant_feet, &mut Unobserved)
}

/// [`finish`], telling `observer` what each of its steps did ([`feet::keep_on_floor`] told as its
/// two steps, [`feet::ground`] then [`feet::land_hangs`]).
pub fn finish_observed(
    mut motion: Motion,
    plant_feet: bool,
    observer: &mut dyn StageObserver,
) -> Motion {
    if plant_feet {
        traced(&mut motion, ServingStage::KneesForward, observer, |m| {
            StageCounts {
                knee_frames_turned: Some(knees::bend_forward(m.positions.view_mut())),
                ..StageCounts::default()
            }
        });
        traced(&mut motion, ServingStage::Ground, observer, |m| {
            feet::ground(m.positions.view_mut(), m.fps);
            StageCounts::default()
        });
        traced(&mut motion, ServingStage::LandHangs, observer, |m| {
            feet::land_hangs(m.positions.view_mut(), m.fps);
            StageCounts::default()
        });
        traced(&mut motion, ServingStage::PlantFeet, observer, |m| {
            StageCounts {
                frame_steps_planted: Some(feet::plant_feet(m.positions.view_mut(), m.fps)),
                ..StageCounts::default()
            }
        });
    }
    motion
}

/// Which motion stages run after a model: jobs run both; `choreo generate --no-beat-align` and
/// `--no-plant-feet` leave one out (to see what a stage does).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotionStages {
    /// [`beat_align::align_served`]: the network's steps onto the song's beats.
    pub beat_align: bool,
    /// [`finish`]: the dance kept on the floor and its feet planted.
    pub plant_feet: bool,
    /// [`beat_align::tempo_follow`] where the song's tempo changes. Off for a dance composed on
    /// the song's own beats (beat-graph): its pace follows the tempo already, and a second warp
    /// would speed it up twice.
    pub tempo_follow: bool,
}

impl Default for MotionStages {
    fn default() -> Self {
        Self {
            beat_align: true,
            plant_feet: true,
            tempo_follow: true,
        }
    }
}

/// The motion stages after any model: [`beat_align::tempo_follow`] where the song's tempo
/// changes, then [`beat_align::align_served`] (the timing, planned on the
/// network's rhythm and on the planted one, the key poses' frames mapped to themselves), with
/// [`finish`] applied to the warped motion, so the feet are planted on the motion that is
/// served. `beat_times_s` are the song's beats on the dance's clock. Jobs, `choreo generate`
/// and `choreo eval` all go through it. `seed_frames`: the frames of the seed motion the request
/// brought (0 without), which open the dance as they are: every frame of that span is fixed, so
/// the warp is the identity there, and they are put back after the stages ([`put_back_seed`]).
/// The summary is `None` when alignment was not asked for.
pub fn after_model(
    motion: Motion,
    beat_times_s: &[f64],
    key_poses: &[KeyPose],
    seed_frames: usize,
    stages: MotionStages,
) -> (Motion, Option<beat_align::BeatAlignSummary>) {
    after_model_observed(
        motion,
        beat_times_s,
        key_poses,
        seed_frames,
        stages,
        &mut Unobserved,
    )
}

/// [`after_model`], telling `observer` what each stage that ran did to the dance served
/// ([`trace`]). The warp and the [`finish`] after it are told apart: of the candidates beat
/// alignment judges, the one served is finished once more, observed (the same work on the same
/// motion, so the same dance; its cost is one [`finish`], 1–6 ms on a 133-s song).
pub fn after_model_observed(
    motion: Motion,
    beat_times_s: &[f64],
    key_poses: &[KeyPose],
    seed_frames: usize,
    stages: MotionStages,
    observer: &mut dyn StageObserver,
) -> (Motion, Option<beat_align::BeatAlignSummary>) {
    let seed = motion
        .positions
        .slice(ndarray::s![..seed_frames.min(motion.num_frames()), .., ..])
        .to_owned();
    if !stages.beat_align {
        let mut done = finish_observed(motion, stages.plant_feet, observer);
        keep_seed(&mut done, seed.view(), observer);
        return (done, None);
    }
    // A song whose tempo changes: the dance's pace first follows it (a network hears one pace).
    let came = motion.clone();
    let pace_fixed = !stages.tempo_follow || !key_poses.is_empty() || seed_frames > 0;
    let motion = beat_align::tempo_follow::follow_tempo(motion, beat_times_s, pace_fixed);
    if !pace_fixed {
        observer.stage(
            ServingStage::TempoFollow,
            &came,
            &motion,
            StageCounts::default(),
        );
    }
    let warped = motion.positions != came.positions;
    drop(came);
    let composed_on_changing_beats = !stages.tempo_follow
        && beat_align::tempo_follow::tempo_changes(beat_times_s, motion.num_frames(), motion.fps);
    if warped || composed_on_changing_beats {
        // One grid fraction and a mean slope of 1 over the dance cannot hold a pace that changes:
        // aligned after the warp, dancenet's and tsmt's steps sped up 0.6–2.4× for the music's
        // 1.56× (without it, 1.5–1.75×), and a beat-graph dance's 1.6× became 2.0–2.7×.
        let mut done = finish_observed(motion, stages.plant_feet, observer);
        keep_seed(&mut done, seed.view(), observer);
        let why = if warped {
            "the song's tempo changes: the dance's pace follows it instead (tempo_follow)"
        } else {
            "the song's tempo changes: the dance was composed on its beats"
        };
        let skipped = beat_align::BeatAlignSummary {
            applied: false,
            skipped: Some(why.into()),
            ..Default::default()
        };
        return (done, Some(skipped));
    }
    let mut fixed: Vec<f64> = key_poses.iter().map(|k| k.time_s).collect();
    fixed.extend((0..=seed_frames.min(motion.num_frames())).map(|f| f as f64 / motion.fps));
    // `finish` without planting changes nothing, so then the stage reads the network's rhythm only.
    let plant = stages.plant_feet.then_some(|m| finish(m, true));
    // What a candidate becomes when served: its seed put back and the rigid skeleton fitted, as
    // the caller's [`serve`] does after this.
    let judge = |m: &Motion| {
        let mut m = m.clone();
        keep_seed(&mut m, seed.view(), &mut Unobserved);
        serve(&m, key_poses, stages.plant_feet, seed_frames)
            .ok()
            .map(|s| s.motion)
    };
    let came = observer.observes().then(|| motion.clone());
    let aligned = beat_align::align_served_parts(motion, beat_times_s, &fixed, plant, Some(judge));
    if let Some(came) = came {
        let counts = StageCounts {
            frames_retimed: Some(aligned.frames_retimed),
            ..StageCounts::default()
        };
        observer.stage(ServingStage::BeatAlign, &came, &aligned.warped, counts);
        let refinished = finish_observed(aligned.warped, stages.plant_feet, observer);
        debug_assert!(
            refinished.positions == aligned.served.positions,
            "finish is a function of its motion"
        );
    }
    let mut aligned_motion = aligned.served;
    keep_seed(&mut aligned_motion, seed.view(), observer);
    (aligned_motion, Some(aligned.summary))
}

/// [`put_back_seed`] as a stage: told to `observer` only where there is a seed to put back.
fn keep_seed(
    motion: &mut Motion,
    seed: ndarray::ArrayView3<'_, f32>,
    observer: &mut dyn StageObserver,
) {
    if seed.dim().0.min(motion.num_frames()) == 0 {
        return;
    }
    traced(motion, ServingStage::KeepSeed, observer, |m| {
        put_back_seed(m, seed);
        StageCounts::default()
    });
}

/// Puts the request's seed motion (`seed`, the dance's first frames as the model returned them)
/// back as it came after the stages, which would otherwise ground, plant and re-bend it: it is a
/// dance the user already has (often choreo's own, already planted), and it opens this one as
/// it is. What the stages did to the seed's last frame is handed over to the frames after it,
/// fading out over the planting's own spread (3 × [`feet::PLANT_BLEND_S`], 0.12 s), so nothing
/// jumps where the seed ends: that spread reached into the last seed frames and moved them up to
/// 6.5 cm.
fn put_back_seed(motion: &mut Motion, seed: ndarray::ArrayView3<'_, f32>) {
    let n = seed.dim().0.min(motion.num_frames());
    if n == 0 {
        return;
    }
    let last = n - 1;
    let handover =
        &seed.slice(ndarray::s![last, .., ..]) - &motion.positions.slice(ndarray::s![last, .., ..]);
    motion
        .positions
        .slice_mut(ndarray::s![..n, .., ..])
        .assign(&seed.slice(ndarray::s![..n, .., ..]));
    let fade = ((3.0 * feet::PLANT_BLEND_S * motion.fps).ceil() as usize).max(1);
    for k in 0..fade.min(motion.num_frames() - n) {
        let w = 1.0 - (k + 1) as f32 / (fade + 1) as f32;
        let mut row = motion.positions.slice_mut(ndarray::s![n + k, .., ..]);
        row.scaled_add(w, &handover);
    }
}

/// A finished dance as a user downloads it: the export's rigid skeleton ([`rig::RigMotion`], what
/// the BVH, JSON and glb carry) and the motion that skeleton draws (what motion.json holds, and
/// what the report, the preview and `choreo eval` judge).
pub struct Served {
    pub rig: rig::RigMotion,
    pub motion: Motion,
}

/// The export step after [`finish`]: fits the rigid skeleton to `finished` with the key poses'
/// frames as anchors ([`export::prepare_anchored`]). Jobs, `choreo generate` and `choreo eval`
/// all go through it, so what is scored is what is served. `ground`: where [`finish`] ran (not
/// where the caller asked for the model's motion as it came), the fitted skeleton's pops are
/// calmed ([`bursts::calm`], the key poses' and the seed's frames kept as they are) and it is
/// put back on the floor ([`ground_rig`]). `seed_frames`: the request's seed motion opens the
/// dance on this many frames, and the skeleton is theirs ([`export::prepare_seeded`]).
pub fn serve(
    finished: &Motion,
    key_poses: &[KeyPose],
    ground: bool,
    seed_frames: usize,
) -> Result<Served, MotionError> {
    serve_observed(finished, key_poses, ground, seed_frames, &mut Unobserved)
}

/// [`serve`], telling `observer` what the fit and each step on the fitted skeleton did to the
/// motion it draws (what motion.json holds).
pub fn serve_observed(
    finished: &Motion,
    key_poses: &[KeyPose],
    ground: bool,
    seed_frames: usize,
    observer: &mut dyn StageObserver,
) -> Result<Served, MotionError> {
    let anchors: Vec<usize> = key_poses
        .iter()
        .map(|k| (k.time_s * finished.fps).round() as usize)
        .collect();
    let mut rig = export::prepare_seeded(finished, &anchors, seed_frames)?;
    // The motion the skeleton draws after each step, drawn only where someone listens.
    let mut drawn = observer.observes().then(|| export::served_motion(&rig));
    if let Some(fitted) = &drawn {
        observer.stage(
            ServingStage::RigidFit,
            finished,
            fitted,
            StageCounts::default(),
        );
    }
    if ground {
        let fixed: Vec<usize> = anchors.iter().copied().chain(0..seed_frames).collect();
        let calmed = bursts::calm(&mut rig, &fixed);
        let counts = StageCounts {
            frames_calmed: Some(calmed),
            ..StageCounts::default()
        };
        rig_stage(&rig, ServingStage::CalmBursts, counts, &mut drawn, observer);
        ground_rig(&mut rig);
        let counts = StageCounts::default();
        rig_stage(&rig, ServingStage::GroundRig, counts, &mut drawn, observer);
    }
    let motion = export::served_motion(&rig);
    Ok(Served { rig, motion })
}

/// Tells `observer` what a step on the fitted skeleton did: `drawn` is what the skeleton drew
/// before it, and becomes what it draws now.
fn rig_stage(
    rig: &rig::RigMotion,
    stage: ServingStage,
    counts: StageCounts,
    drawn: &mut Option<Motion>,
    observer: &mut dyn StageObserver,
) {
    if let Some(before) = drawn.take() {
        let after = export::served_motion(rig);
        observer.stage(stage, &before, &after, counts);
        *drawn = Some(after);
    }
}

/// Keeps the fitted skeleton on the floor as [`feet::keep_on_floor`] keeps joint positions,
/// moving the root only.
/// The rigid fit keeps every bone at its median length, so where a network draws its legs longer
/// than that for a while the fitted feet leave the floor: tsmt on lets_go_fishin (seed 2), lowest
/// foot 0.002 m before the fit and 0.17 m after it at 130 s, 0.09–0.17 m over the last 30 s.
fn ground_rig(rig: &mut rig::RigMotion) {
    let before = rig.joint_positions();
    let mut after = before.clone();
    feet::keep_on_floor(after.view_mut(), rig.fps);
    for (t, root) in rig.root_translation.iter_mut().enumerate() {
        root.y += f64::from(after[[t, 0, 1]] - before[[t, 0, 1]]);
    }
}

impl Motion {
    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.positions.shape()[0]
    }

    /// Duration in seconds (frames / fps).
    pub fn duration_s(&self) -> f64 {
        self.num_frames() as f64 / self.fps
    }
}

/// A key pose in the canonical form the models take: 23 joint positions relative to the body
/// centre, metres, in the dataset's order ([`skeleton::JOINT_NAMES`]), at a time in the song.
/// What users send ([`input::KeyPoseInput`]) becomes one through [`input::key_poses`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KeyPose {
    /// Seconds from the song's start; lands on frame `round(time_s · fps)`.
    pub time_s: f64,
    /// `23 × [x, y, z]`, metres, relative to the body centre, in [`skeleton::JOINT_NAMES`] order.
    pub joints: Vec<[f64; 3]>,
}

/// Everything that can go wrong reading, converting, validating or exporting motion.
#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    #[error("dataset not found at {path}: expected ../shared/data/dance-with-melody (the shared data folder next to the repository)")]
    DatasetMissing { path: PathBuf },
    #[error("unknown dance {id:?} (not a folder of the dataset)")]
    UnknownDance { id: String },
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("malformed {path}: {reason}")]
    Malformed { path: PathBuf, reason: String },
    #[error("motion has the wrong shape: {0}")]
    Shape(String),
    #[error("invalid input: {0}")]
    Invalid(String),
    #[error("BVH parse error at line {line}: {reason}")]
    Bvh { line: usize, reason: String },
    #[error("BVH line {line}: {what} is not a finite number")]
    NotFinite { line: usize, what: String },
    #[error("export failed: {0}")]
    Export(String),
    #[error(transparent)]
    Input(#[from] validate::InputError),
}

impl MotionError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            MotionError::DatasetMissing { .. } => "dataset-missing",
            MotionError::UnknownDance { .. } => "unknown-dance",
            MotionError::Io { .. } => "motion-io",
            MotionError::Malformed { .. } => "malformed-data",
            MotionError::Shape(_) => "motion-shape",
            MotionError::Invalid(_) => "invalid-motion",
            MotionError::Bvh { .. } => "invalid-bvh",
            MotionError::NotFinite { .. } => "motion-not-finite",
            MotionError::Export(_) => "export-failed",
            MotionError::Input(e) => e.code(),
        }
    }

    /// Whether the error is the caller's input (an API maps these to 422).
    pub fn is_client_error(&self) -> bool {
        match self {
            MotionError::Invalid(_)
            | MotionError::Bvh { .. }
            | MotionError::NotFinite { .. }
            | MotionError::Shape(_)
            | MotionError::Input(_) => true,
            MotionError::UnknownDance { .. } => true,
            MotionError::DatasetMissing { .. }
            | MotionError::Io { .. }
            | MotionError::Malformed { .. }
            | MotionError::Export(_) => false,
        }
    }

    /// Whether trying again later may succeed.
    pub fn is_retryable(&self) -> bool {
        match self {
            MotionError::Io { .. } | MotionError::Export(_) => true,
            MotionError::DatasetMissing { .. }
            | MotionError::UnknownDance { .. }
            | MotionError::Malformed { .. }
            | MotionError::Shape(_)
            | MotionError::Invalid(_)
            | MotionError::Input(_)
            | MotionError::Bvh { .. }
            | MotionError::NotFinite { .. } => false,
        }
    }

    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        MotionError::Io {
            path: path.into(),
            source,
        }
    }
}
