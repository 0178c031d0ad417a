//! Serving DanceRevolution: the served guard against stalls, the warm-up, and the model behind
//! `POST /v1/jobs {"model": "dance-revolution"}` (none of it in the paper).
use std::path::Path;

use serde::{Deserialize, Serialize};
use tch::Tensor;

use super::{DanceRevolution, Decoding, ModelFile, ID};
use crate::models::beat_time;
use crate::models::encoded::EncoderMemo;
use crate::models::folder;
use crate::models::layers::LstmState;
use crate::models::opening_check::{OpeningCheck, OpeningChosen};
use crate::models::stretch::MusicLayout;
use crate::models::{
    to_array, to_tensor, Cancelled, Capabilities, DanceModel, GenerateRequest, Generated,
    InstancePool, ModelError, ModelId, ModelInfo, Progress,
};
use crate::motion::dataset::NormStats;
use crate::motion::repr::RootStart;
use crate::stage::Stage;

/// A served guard against stalls (not in the paper): the decoder is deterministic once `h_0` is
/// drawn, and some draws settle into a held pose for tens of seconds (seed 0 on sugar_plum_fairy
/// stood at 0.18 m/s for its first 25 s). While no pose of the last `window_frames` frames is
/// more than `min_reach_m` (mean over joints, root-relative) from the newest, every layer's `h`
/// takes Gaussian noise of standard deviation `kick` per frame, a random walk small enough per
/// frame not to jump, until the dancer moves again.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct StallGuard {
    pub min_reach_m: f32,
    pub window_frames: usize,
    pub kick: f64,
}

impl StallGuard {
    /// What is served: 2-s windows, 0.10 m (below the 5th percentile of most served dances'
    /// reach), kick 0.3 per frame (h_0 itself is N(0, 1)).
    pub const SERVED: StallGuard = StallGuard {
        min_reach_m: 0.10,
        window_frames: 50,
        kick: 0.3,
    };
}

/// What is served: `h_0`'s draw checked ([`OpeningCheck`]) over the song's first 20 s, 6 draws,
/// inside the real dances' ranges with a margin (the opening measures a little slower than the
/// whole dance it leads into). The decoder is deterministic once `h_0` is drawn, and the draw sets
/// the dance's character for the whole song: on the test split seed 3 stepped a 2-m/s metronome
/// with the arms at 1.4–2.6 m/s against the spine on every song (real dances: 0.43–1.44) and seed
/// 4 shuffled at 0.44–0.63 m/s (real: 0.63–1.80).
pub const OPENING_CHECK: OpeningCheck = OpeningCheck {
    frames: 500,
    draws: 6,
    speed_m_s: [0.6, 1.6],
    arms_m_s: [0.5, 1.3],
};

/// Warm-up frames served: 10 s (the song's first 10 s, or the whole song when shorter). With 3 s
/// the opening was still `h_0`'s more than the song's: seed 0 danced the 5-s trumpet loop and the
/// first 5 s of sugar_plum_fairy 0.11 m apart (root-relative; two real dances are 0.34 m apart),
/// and its calm draw played back under the verdict's 0.5 m/s on the loop and on DANCE_W_8. After
/// 10 s of the song the state is the song's: 0.30 m apart, 0.63 m/s and more (model card). Longer
/// is not better: the calm draws of two seeds can then forget `h_0` altogether (model card).
pub const WARM_UP_FRAMES: i64 = 250;

impl Serving {
    /// What `choreo train` writes: the served guard and warm-up.
    pub fn served() -> Self {
        Self {
            stall_guard: Some(StallGuard::SERVED),
            warm_up_frames: WARM_UP_FRAMES,
            beat_time: None,
            opening_check: Some(OPENING_CHECK),
            figures: None,
        }
    }
}

/// `model.json` fields of DanceRevolution's own.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Serving {
    /// The stall guard, if any ([`StallGuard`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stall_guard: Option<StallGuard>,
    /// Frames decoded over the song's opening and dropped before the dance starts (not in the
    /// paper), so frame 0 is already mid-dance rather than the mean pose's slow start.
    #[serde(default)]
    pub warm_up_frames: i64,
    /// The network runs on a clock of beats at this tempo ([`beat_time`]); absent: in seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_time: Option<beat_time::BeatTimeConfig>,
    /// The check of `h_0`'s draw, if any ([`OpeningCheck`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub opening_check: Option<OpeningCheck>,
    /// The figures an arm head with figures is told ([`super::figures`]); read only where
    /// `config.arm_figures` is set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub figures: Option<super::figures::Figures>,
}

/// The guard's running state: the last frames' root-relative joints in metres.
pub(super) struct StallWatch<'a> {
    guard: StallGuard,
    norm: &'a NormStats,
    history: std::collections::VecDeque<Vec<f32>>,
    rng: rand::rngs::StdRng,
    pub(super) kicked: usize,
}

impl<'a> StallWatch<'a> {
    pub(super) fn new(guard: StallGuard, norm: &'a NormStats, seed: u64) -> Self {
        use rand::SeedableRng;
        let rng = rand::rngs::StdRng::seed_from_u64(seed ^ 0x5354_414c_4c00_0000);
        Self {
            guard,
            norm,
            history: std::collections::VecDeque::with_capacity(guard.window_frames + 1),
            rng,
            kicked: 0,
        }
    }

    /// Records output `y` `[1, 1, pose]` (normalised) and kicks `state` if the dance has stalled.
    pub(super) fn observe(&mut self, y: &Tensor, state: &mut LstmState) {
        // The root-relative joints lead the pose vector ([`crate::motion::repr`]).
        let width =
            (y.size().last().copied().unwrap_or(0) as usize).min(crate::motion::repr::POSE_DIM) / 3
                * 3;
        let v: Vec<f32> =
            Vec::<f32>::try_from(y.flatten(0, -1).narrow(0, 0, width as i64)).unwrap_or_default();
        let metres: Vec<f32> = v
            .iter()
            .enumerate()
            .map(|(k, x)| x * self.norm.std[k] + self.norm.mean[k])
            .collect();
        self.history.push_back(metres);
        if self.history.len() > self.guard.window_frames {
            self.history.pop_front();
        }
        if self.history.len() < self.guard.window_frames
            || reach_m(&self.history) >= self.guard.min_reach_m
        {
            return;
        }
        use rand_distr::{Distribution, StandardNormal};
        self.kicked += 1;
        for (h, _) in state.iter_mut() {
            let noise: Vec<f32> = (0..h.numel())
                .map(|_| StandardNormal.sample(&mut self.rng))
                .collect();
            let noise = Tensor::from_slice(&noise)
                .view(h.size().as_slice())
                .to_device(h.device());
            *h = &*h + noise * self.guard.kick;
        }
    }
}

/// The largest distance (mean over joints, metres) of any pose in `history` from the newest.
pub(super) fn reach_m(history: &std::collections::VecDeque<Vec<f32>>) -> f32 {
    let Some(last) = history.back() else {
        return 0.0;
    };
    let joints = last.len() / 3;
    history
        .iter()
        .map(|f| {
            let sum: f32 = (0..joints)
                .map(|j| {
                    (0..3)
                        .map(|c| (last[3 * j + c] - f[3 * j + c]).powi(2))
                        .sum::<f32>()
                        .sqrt()
                })
                .sum();
            sum / joints.max(1) as f32
        })
        .fold(0.0, f32::max)
}

/// A trained DanceRevolution, ready to serve.
pub struct Served {
    file: ModelFile,
    pool: InstancePool<DanceRevolution>,
    /// The song's encoding, kept for the next seeds ([`crate::models::encoded`]).
    encoded: EncoderMemo,
}

impl Served {
    /// Loads `dir/model.json` and `dir/weights.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let (file, pool) = folder::load(dir, ID, |p, f: &ModelFile| {
            DanceRevolution::new(p, f.config.clone())
        })?;
        let told = file
            .extra
            .figures
            .as_ref()
            .is_some_and(|f| !f.bank.is_empty());
        if file.config.arm_figures && !told {
            // The head would read the spine's own place as the figure: no dance holds that.
            return Err(ModelError::BadModelFile(format!(
                "{}: config.arm_figures without figures to tell the arm head",
                dir.join("model.json").display()
            )));
        }
        Ok(Self {
            file,
            pool,
            encoded: EncoderMemo::default(),
        })
    }

    /// The draw a job without a seed motion dances from ([`OpeningCheck`]) and what the check
    /// saw: `seed` itself, and nothing, where there is no check. With the check, the kept draw's
    /// decode too, stopped at the end of its opening, where going on from there decodes what
    /// one run from the start would (the warm-up it ran is the whole song's).
    fn checked_seed<'a>(
        &self,
        model: &'a DanceRevolution,
        z: &Tensor,
        seed: u64,
        guard: Option<(&StallGuard, &'a NormStats)>,
        clock: &beat_time::BeatTime,
    ) -> Result<(u64, Option<OpeningChosen>, Option<Decoding<'a>>), ModelError> {
        let Some(check) = self.file.extra.opening_check else {
            return Ok((seed, None, None));
        };
        let warm = self.file.extra.warm_up_frames;
        let window = check.window(clock);
        let n = z.size()[1];
        let m = (window.net_frames as i64).min(n);
        let head = z.narrow(1, 0, m);
        // A warm-up that ran over all of `head` but not all of the song would differ.
        let resumable = warm.min(m) == warm.min(n);
        let mut opened: Vec<(u64, Decoding<'a>)> = Vec::new();
        let chosen = check.choose(ID, seed, &window, |s| -> Result<_, ModelError> {
            let mut d = self.with_figures(model.begin(&head, s, None, guard, warm), n, s);
            if d.run_to(&head, m, 0, |_| true, None).is_none() {
                return Ok(None);
            }
            let motion = self.motion_of(&d.output())?;
            if resumable {
                opened.push((s, d));
            }
            Ok(Some(motion))
        })?;
        let (seed, seen) = chosen.ok_or(Cancelled)?;
        let kept = opened
            .into_iter()
            .find_map(|(s, d)| (s == seed).then_some(d));
        if let Some(d) = kept.as_ref() {
            tracing::debug!(from = d.done(), "dance-revolution: the kept draw goes on");
        }
        Ok((seed, Some(seen), kept))
    }

    /// `d` told the figures of draw `seed` over `n` network frames, where the arm head reads them.
    fn with_figures<'a>(&self, d: Decoding<'a>, n: i64, seed: u64) -> Decoding<'a> {
        match &self.file.extra.figures {
            Some(f) if self.file.config.arm_figures => d.with_figures(&f.plan(n as usize, seed)),
            _ => d,
        }
    }

    /// The decoder's output `[1, n, pose]` (normalised) as a dance on the network's clock.
    fn motion_of(&self, y: &Tensor) -> Result<crate::motion::Motion, ModelError> {
        let poses = self
            .file
            .pose_norm
            .denormalize(&to_array(&y.squeeze_dim(0))?)?;
        let (motion, _root) =
            crate::motion::repr::from_features(poses.view(), RootStart::default(), self.file.fps)?;
        Ok(motion)
    }

    /// Music features of a whole song on the network's clock, normalised, as `[1, n, F]`.
    fn music(
        &self,
        audio: &dyn crate::audio::SongAudio,
        clock: &beat_time::BeatTime,
    ) -> Result<Tensor, ModelError> {
        use crate::audio::features::FeatureSet;
        let set = if self.file.config.beat_clock {
            FeatureSet::DanceRevolutionClock
        } else {
            FeatureSet::DanceRevolution
        };
        let feats = audio.features(set, self.file.fps, 0.0, clock.song_frames)?;
        let layout = MusicLayout::dance_revolution(self.file.config.beat_clock);
        let feats = clock.music(feats.view(), &layout);
        Ok(to_tensor(&self.file.music_norm.normalize(&feats)?).unsqueeze(0))
    }
}

impl DanceModel for Served {
    fn frame_flops(&self) -> Option<f64> {
        Some(self.file.config.frame_flops())
    }

    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "Huang et al., Dance Revolution: Long-Term Dance Generation with Music via Curriculum Learning, ICLR 2021".into(),
            capabilities: Capabilities { key_poses: false, seed_motion: true, ..Default::default() },
            beat_time: self.file.extra.beat_time,
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
        progress.report(Stage::Features, 0.0)?;
        let clock = beat_time::BeatTime::for_request(self.file.extra.beat_time, req, n)?;
        let music = self.music(req.audio, &clock)?;
        progress.report(Stage::Features, 1.0)?;
        let seed_motion = req.seed_motion.map(|m| clock.seed_motion(m));
        let seed_poses = match seed_motion.as_ref() {
            Some(m) => {
                let root = crate::motion::skeleton::body_centre_track(m.positions.view());
                let (f, _) = crate::motion::repr::to_features(m.positions.view(), root.view())?;
                Some(to_tensor(&self.file.pose_norm.normalize(&f)?).unsqueeze(0))
            }
            None => None,
        };
        let mut opening = None;
        let out = self.pool.with(|model| {
            tch::no_grad(|| -> Result<Tensor, ModelError> {
                let mut cancelled = false;
                let z = self.encoded.get_or_encode(&[&music], || {
                    model.encoder.forward_chunked(&music, 1000, |f| {
                        cancelled = progress.report(Stage::Encode, f).is_err();
                        !cancelled
                    })
                });
                let z = z.ok_or(Cancelled)?;
                let guard = self
                    .file
                    .extra
                    .stall_guard
                    .as_ref()
                    .map(|g| (g, &self.file.pose_norm));
                let (seed, kept) = match seed_poses {
                    Some(_) => (req.seed, None),
                    None => {
                        let (seed, seen, kept) =
                            self.checked_seed(model, &z, req.seed, guard, &clock)?;
                        opening = seen;
                        (seed, kept)
                    }
                };
                // The kept draw goes on from the end of its opening; else one decode from the
                // start.
                let mut d = kept.unwrap_or_else(|| {
                    let warm = self.file.extra.warm_up_frames;
                    let d = model.begin(&z, seed, seed_poses.as_ref(), guard, warm);
                    self.with_figures(d, z.size()[1], seed)
                });
                let ran = d.run_to(
                    &z,
                    z.size()[1],
                    250,
                    |f| {
                        cancelled = progress.report(Stage::Generate, f).is_err();
                        !cancelled
                    },
                    None,
                );
                ran.map(|()| d.output())
                    .ok_or(ModelError::Cancelled(Cancelled))
            })
        })?;
        let motion = self.motion_of(&out?)?;
        Ok(Generated::from(clock.back(motion))
            .with_beat_time(clock.used(self.file.extra.beat_time))
            .with_opening(opening))
    }
}
