//! A trained key-pose transformer folder (`model.json`, `weights.safetensors`, `pose_bank.safetensors`)
//! and the served generation path: seed and scaffold drawn by the job's seed to the song's beats
//! ([`super::scaffold`]),
//! the network over overlapping windows, root height from the predicted foot clearance, and the
//! exact pass through the user's key poses ([`super::keys`]).
use std::path::Path;

use ndarray::{s, Array2};
use serde::{Deserialize, Serialize};
use tch::Tensor;

use super::beats::SongCues;
use super::keys::{
    bridge_keys, jump_frames, local_keys, normalize_key, pass_through_keys, pass_through_yaws,
    LocalKey, BRIDGE_HALF, JUMP_HALF,
};
use super::scaffold::{PoseBank, Scaffold, POSE_BANK_FILE};
use super::{Config, KeyposeTransformer};
use crate::models::folder;
use crate::models::{
    to_array, to_tensor, Cancelled, Capabilities, DanceModel, GenerateRequest, Generated,
    InstancePool, ModelError, ModelId, ModelInfo, Progress,
};
use crate::motion::repr::{self, RootStart, POSE_DIM};
use crate::stage::Stage;

/// The API id.
pub const ID: &str = "keypose-transformer";
/// Frames over which a key pose's residual is blended in after the network (1 s at 25 fps, and
/// never less than half a second unless two keys are closer than that): a correction faster
/// than that is a visible pop.
pub const BLEND_RADIUS: f64 = 25.0;
/// Frames over which a key pose's facing (yaw) residual is blended in (2 s at 25 fps): the
/// network's integrated facing can be far from a key's, and turning the body that far within
/// half a second would be a spin that no dancer made.
pub const YAW_BLEND_RADIUS: f64 = 50.0;

/// A frame of the network's motion accelerating more than this (m/s², mean over joints, root
/// travel aside) is a jump, spread over [`JUMP_HALF`] frames each side: the train split's p99.9
/// (`metrics/reference_train.json`, `physical.pooled`), which 0.1 % of real frames exceed.
pub const JUMP_M_S2: f64 = 57.0;

/// The key-pose sampling behind the committed weights, stored beside the common record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct KeySampling {
    pub steps: usize,
    pub max_keys: usize,
    /// Weight of the frame-difference (velocity) L1 term beside the ω(t)-weighted pose term.
    #[serde(default)]
    pub velocity_weight: f64,
}

/// What column [`repr::ROOT_Y`] of the pose features holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RootHeight {
    /// The root's height above the floor (the motion module's features as they are).
    #[default]
    Absolute,
    /// The lowest foot's clearance above the dance's floor ([`repr::height_to_clearance`]).
    FootClearance,
}

/// The served path's own fields of `model.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Serving {
    /// What the root-height column means.
    #[serde(default)]
    pub root_height: RootHeight,
    /// Frames between scaffold poses when serving ([`super::scaffold`]); 0 turns the scaffold off.
    #[serde(default)]
    pub scaffold_spacing: usize,
    /// The dance turns as the scaffold's clips turn ([`super::scaffold::Scaffold::facing`])
    /// instead of as the network turns it: the network makes the poses, the travel and the
    /// height, the clips give the facing (measured: the network turned a waltz 25°/s where real
    /// waltzers turn 56–70°/s, and a waltz's arms move against the spine mostly by turning).
    #[serde(default)]
    pub scaffold_facing: bool,
}

/// `model.json`: configuration, normalisation, training record and serving fields.
pub type ModelFile = folder::ModelFile<Config, KeySampling, Serving>;

/// One generation: the network's features and the served ones (after the exact key pass), both
/// with absolute root heights, and where the root starts.
pub struct Generation {
    pub network: Array2<f32>,
    pub served: Array2<f32>,
    pub start: RootStart,
}

/// Generation on normalised music plus the exact key-pose pass. `seed` is denormalised features
/// (in the model's root-height representation) and the root start; `keys` are the user's key
/// poses (passed exactly); `scaffold` are poses `(frame, 69 local coordinates)` the network is
/// given as key poses but not held to. `keep_seed`: the seed's frames are kept as they are (a
/// user's seed motion) rather than rendered by the network (a drawn one). `facing`, when not
/// empty, is the yaw velocity per frame the served motion turns by (the scaffold's,
/// [`Serving::scaffold_facing`]) in place of the network's (a kept seed keeps its own). Shared by
/// serving and the model card's evaluation.
#[allow(clippy::too_many_arguments)]
pub fn generate_features(
    model: &KeyposeTransformer,
    file: &ModelFile,
    music: &Tensor,
    seed: Option<(&Array2<f32>, RootStart)>,
    keep_seed: bool,
    keys: &[LocalKey],
    scaffold: &[(usize, Vec<f32>)],
    facing: &[f32],
    mut on_window: impl FnMut(usize, usize) -> bool,
) -> Result<Option<Generation>, ModelError> {
    let ts = file.config.seed_len as usize;
    let seed_norm = match seed {
        Some((f, _)) => {
            // The last T′ frames, front-padded by repeating the first when the seed is shorter.
            let m = f.nrows();
            let mut rows = Array2::<f32>::zeros((ts, f.ncols()));
            for i in 0..ts {
                let src = (m + i).saturating_sub(ts);
                rows.row_mut(i).assign(&f.row(src.min(m.saturating_sub(1))));
            }
            Some(to_tensor(&file.pose_norm.normalize(&rows)?))
        }
        None => None,
    };
    let mut nkeys: Vec<(i64, Vec<f32>)> = keys
        .iter()
        .map(|k| (k.frame as i64, normalize_key(&file.pose_norm, &k.local)))
        .collect();
    nkeys.extend(
        scaffold
            .iter()
            .map(|(f, local)| (*f as i64, normalize_key(&file.pose_norm, local))),
    );
    let y = tch::no_grad(|| {
        model.generate_long(music, seed_norm.as_ref(), keep_seed, &nkeys, &mut on_window)
    });
    let Some(y) = y else { return Ok(None) };
    let mut network = file.pose_norm.denormalize(&to_array(&y)?)?;
    let mut served = network.clone();
    let kept = if keep_seed && seed.is_some() { ts } else { 0 };
    for (t, &v) in facing.iter().enumerate().take(served.nrows()).skip(kept) {
        served[[t, repr::YAW_VEL]] = v;
    }
    if file.extra.root_height == RootHeight::FootClearance {
        repr::clearance_to_height(&mut network);
    }
    let mut jumps = jump_frames(network.view(), JUMP_M_S2, file.fps);
    if keep_seed && seed.is_some() {
        // The user's seed frames stay as given: a jump where the network takes over from them
        // (or inside them) is spread over the frames after them.
        for t in &mut jumps {
            *t = (*t).max(ts + JUMP_HALF);
        }
        jumps.dedup();
    }
    if !jumps.is_empty() {
        tracing::debug!(?jumps, "spreading the network's one-frame jumps");
    }
    // Poses and height only: the root's travel and turn are velocities, left as the network made them.
    let cols: Vec<usize> = (0..POSE_DIM).chain([repr::ROOT_Y]).collect();
    let mut posed = served.select(ndarray::Axis(1), &cols);
    bridge_keys(&mut posed, &jumps, JUMP_HALF);
    for (i, &c) in cols.iter().enumerate() {
        served.column_mut(c).assign(&posed.column(i));
    }
    bridge_keys(
        &mut served,
        &keys.iter().map(|k| k.frame).collect::<Vec<_>>(),
        BRIDGE_HALF,
    );
    let targets: Vec<(usize, Vec<f32>)> = keys.iter().map(|k| (k.frame, k.local.clone())).collect();
    pass_through_keys(&mut served, 0..POSE_DIM, &targets, BLEND_RADIUS);
    if file.extra.root_height == RootHeight::FootClearance {
        // After the key pass, so a key pose's legs set the height at its frame.
        repr::clearance_to_height(&mut served);
    }
    let mut start = seed.map(|(_, s)| s).unwrap_or_default();
    let yaws: Vec<(usize, f32)> = keys.iter().map(|k| (k.frame, k.yaw)).collect();
    if !yaws.is_empty() {
        start.yaw = pass_through_yaws(&mut served, start.yaw, &yaws, YAW_BLEND_RADIUS);
    }
    Ok(Some(Generation {
        network,
        served,
        start,
    }))
}

/// A trained key-pose transformer, ready to serve.
pub struct Served {
    file: ModelFile,
    bank: Option<PoseBank>,
    pool: InstancePool<KeyposeTransformer>,
}

impl Served {
    /// Loads `dir/model.json`, `dir/weights.safetensors` and, when present, `dir/pose_bank.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let (file, pool) = folder::load(dir, ID, |p, f: &ModelFile| {
            KeyposeTransformer::new(p, f.config.clone())
        })?;
        let bank_path = dir.join(POSE_BANK_FILE);
        let bank = if bank_path.exists() {
            Some(PoseBank::load(&bank_path)?)
        } else {
            None
        };
        Ok(Self { file, bank, pool })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The seed rows and scaffold the job's seed draws for the song of `cues`, or none without a
    /// pose bank. A bank without its clips' beats ([`super::scaffold::BankMeta`]) draws by the seed alone.
    pub fn scaffold(
        &self,
        seed: u64,
        cues: &SongCues,
        frames: usize,
        keys: &[LocalKey],
    ) -> Option<Scaffold> {
        let bank = self.bank.as_ref()?;
        let ts = self.file.config.seed_len as usize;
        let on = self.file.extra.scaffold_spacing > 0;
        on.then(|| bank.scaffold_to(seed, cues, frames, ts, keys))
            .flatten()
            .or_else(|| {
                Some(bank.scaffold(seed, frames, ts, self.file.extra.scaffold_spacing, keys))
            })
    }

    /// What the scaffold hears of the song: the analysis's beats and downbeats (the ones the
    /// report measures against) and the onset strength of the model's own features `[n, 15]`.
    pub fn cues(
        &self,
        analysis: &crate::audio::Analysis,
        feats: &Array2<f32>,
    ) -> Result<SongCues, ModelError> {
        let onset: Vec<f32> = feats
            .column(crate::audio::features::KEYPOSE_DIM - 1)
            .to_vec();
        let fallback = self.file.extra.scaffold_spacing.max(1) as f64;
        Ok(SongCues::new(
            &analysis.beat_times,
            &analysis.downbeat_times,
            &onset,
            self.file.fps,
            feats.nrows(),
            fallback,
        ))
    }
}

impl DanceModel for Served {
    fn frame_flops(&self) -> Option<f64> {
        Some(self.file.config.frame_flops())
    }

    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "Controllable music-driven dance generation with key-pose constraints (key-pose controllable cross-modal transformer)".into(),
            capabilities: Capabilities { key_poses: true, seed_motion: true, ..Default::default() },
            beat_time: None,
        }
    }

    fn generate(
        &self,
        req: &GenerateRequest<'_>,
        progress: &mut dyn Progress,
    ) -> Result<Generated, ModelError> {
        self.refuse_unsupported(req)?;
        let fps = self.file.fps;
        let n = crate::motion::validate::song_frames(req.audio.duration_s(), fps);
        let keys = local_keys(req.key_poses, n, fps)?;
        progress.report(Stage::Features, 0.0)?;
        let feats = req
            .audio
            .features(crate::audio::features::FeatureSet::Keypose, fps, 0.0, n)?;
        let music = to_tensor(&self.file.music_norm.normalize(&feats)?);
        // Only a bank with its clips' beats listens to the song; the analysis is skipped without.
        let cues = if self.bank.as_ref().is_some_and(|b| b.meta().is_some()) {
            Some(self.cues(&*req.analysis_or_analyze()?, &feats)?)
        } else {
            None
        };
        progress.report(Stage::Features, 1.0)?;
        let given = match req.seed_motion {
            Some(m) if m.num_frames() > 0 => {
                // The network continues from the seed's last T′ frames, so the root starts there.
                let ts = self.file.config.seed_len as usize;
                let tail =
                    m.positions
                        .slice(ndarray::s![m.num_frames().saturating_sub(ts).., .., ..]);
                let root = crate::motion::skeleton::body_centre_track(tail);
                let (mut f, start) = repr::to_features(tail, root.view())?;
                let mut floor = 0.0;
                if self.file.extra.root_height == RootHeight::FootClearance {
                    floor = repr::floor_of_features(f.view());
                    repr::height_to_clearance(&mut f, floor);
                }
                Some((f, start, floor))
            }
            _ => None,
        };
        // The dance continues on a given seed's floor, so its frames come back where they were.
        let floor = given.as_ref().map_or(0.0, |g| g.2);
        let given = given.map(|(f, s, _)| (f, s));
        // One dance from the scaffold that `draw` (a seed) draws.
        let mut dance = |draw: u64| -> Result<crate::motion::Motion, ModelError> {
            let plan = match &cues {
                Some(cues) => self.scaffold(draw, cues, n, &keys),
                None => self.bank.as_ref().map(|b| {
                    b.scaffold(
                        draw,
                        n,
                        self.file.config.seed_len as usize,
                        self.file.extra.scaffold_spacing,
                        &keys,
                    )
                }),
            };
            let keep_seed = given.is_some();
            // A given seed motion wins over the drawn one; the scaffold stays either way.
            let seed = given.clone().or_else(|| {
                plan.as_ref()
                    .map(|p| (p.seed.clone(), RootStart::default()))
            });
            let (scaffold, facing) = match plan {
                Some(p) if self.file.extra.scaffold_facing => (p.poses, p.facing),
                Some(p) => (p.poses, Vec::new()),
                None => (Vec::new(), Vec::new()),
            };
            let out = self.pool.with(|model| {
                generate_features(
                    model,
                    &self.file,
                    &music,
                    seed.as_ref().map(|(f, s)| (f, *s)),
                    keep_seed,
                    &keys,
                    &scaffold,
                    &facing,
                    |done, total| {
                        progress
                            .report(Stage::Generate, done as f32 / total as f32)
                            .is_ok()
                    },
                )
            })?;
            let Some(mut g) = out? else {
                return Err(Cancelled.into());
            };
            g.served
                .column_mut(repr::ROOT_Y)
                .mapv_inplace(|y| y + floor);
            Ok(repr::from_features(g.served.view(), g.start, fps)?.0)
        };
        if given.is_some() || n > SHORT_SONG_FRAMES {
            return Ok(dance(req.seed)?.into());
        }
        // A short song: its dance is one or two scaffold clips, and how fast it moves is theirs
        // and the network's (module doc of `SHORT_SONG_FRAMES`).
        let drawn = crate::models::opening_check::first_inside(
            req.seed,
            SHORT_SONG_DRAWS,
            |s| -> Result<_, ModelError> {
                let motion = dance(s)?;
                let planted = crate::motion::finish(motion.clone(), true);
                let p = planted.positions.view();
                let speed = crate::motion::skeleton::average_speed(p, fps);
                let half = p.shape()[0] / 2;
                let halves = [s![..half, .., ..], s![half.., .., ..]]
                    .map(|h| crate::motion::skeleton::average_speed(p.slice(h), fps));
                let slower_half = halves[0].min(halves[1]);
                tracing::debug!(
                    seed = s,
                    speed,
                    ?halves,
                    "keypose-transformer: a short song's draw"
                );
                Ok(Some((speed, slower_half, motion)))
            },
            |(speed, half, _)| short_song_miss(*speed, *half),
        )?;
        let Some(crate::models::opening_check::Drawn {
            tried,
            index: kept,
            kept: (speed, half, motion),
            ..
        }) = drawn
        else {
            return Err(Cancelled.into());
        };
        tracing::debug!(
            tried,
            kept,
            speed,
            half,
            "keypose-transformer: short-song draws"
        );
        let arms = crate::metrics::musicality::arm_speed_m_s(motion.positions.view(), fps);
        Ok(Generated::from(motion).with_opening(Some(
            crate::models::opening_check::OpeningChosen {
                tried,
                kept,
                speed_m_s: speed,
                arms_m_s: arms,
                inside: short_song_miss(speed, half) == 0.0,
            },
        )))
    }
}

/// How far a short song's draw with mean joint speed `speed` and slower half `half` (m/s) lies
/// under the floors ([`SHORT_SONG_MIN_SPEED_M_S`], [`SHORT_SONG_MIN_HALF_SPEED_M_S`]): summed log
/// ratios, the slower the farther; 0 at or above both, which is what report.json calls inside.
fn short_song_miss(speed: f64, half: f64) -> f64 {
    let below = |v: f64, floor: f64| (floor / v.max(1e-6)).ln().max(0.0);
    below(speed, SHORT_SONG_MIN_SPEED_M_S) + below(half, SHORT_SONG_MIN_HALF_SPEED_M_S)
}

/// A song this short (frames, 20 s: the other models' opening window) is danced by up to
/// [`SHORT_SONG_DRAWS`] scaffold draws (the job's seed first, then the seeds
/// `opening_check::draw_seed` derives from it) until one moves at least
/// [`SHORT_SONG_MIN_SPEED_M_S`] and each half [`SHORT_SONG_MIN_HALF_SPEED_M_S`], else the one
/// nearest both (the least summed log shortfall). Such a dance is one or two scaffold clips, and
/// its pace is theirs: on the 5-s trumpet loop seeds 0–31 moved 0.42–0.80 m/s, 4 under the
/// verdict's 0.5 (the card); at 1.2× (4.4 s) seeds 2 and 15 drew the same clips and moved 0.40.
/// A longer song's dance passes through many clips, and its pace is their average (whole songs
/// 0.54–1.18 m/s). Not done with a seed motion: the user's motion opens the dance.
pub const SHORT_SONG_FRAMES: usize = 500;
/// Draws a short song tries at most.
pub const SHORT_SONG_DRAWS: usize = 6;
/// The mean joint speed (m/s, feet planted as served) a short song's draw must reach: the
/// verdict's floor (0.5) and a margin. Planted here and downloaded they differ by less than 0.01
/// m/s (the loop at 1.2×: seed 2's first draw 0.398 and 0.397, seed 7's 0.573 and 0.569, seed
/// 4's 0.598 and 0.592).
pub const SHORT_SONG_MIN_SPEED_M_S: f64 = 0.55;
/// The mean joint speed (m/s, feet planted) each half of a short song's draw must reach besides,
/// a margin over the line under which a second stands in one pose
/// ([`crate::motion::hold::HOLD_SPEED_M_S`], 0.3; a half is a mean over seconds, some of which
/// may stand as a dancer's pose does). The mean alone let through a
/// draw that moves and then stands: the loop at 1.2×, seed 2, redrawn, moved 1.50 m/s and then
/// 0.25 for its last 2.2 s (0.88 m/s mean), a dance that stops halfway.
pub const SHORT_SONG_MIN_HALF_SPEED_M_S: f64 = 0.4;
