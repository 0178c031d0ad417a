//! The seed matters, and so does the song: a bank of short real clips from the train split
//! (`pose_bank.safetensors`, with each clip's source and beats in `pose_bank.json`), from which each
//! job draws the seed motion and a scaffold of poses.
//!
//! A deterministic regression network started from the mean pose gives the same small, averaged
//! motion for every seed (measured: 0.15–0.20 m/s and seeds 1
//! and 2 identical). The paper's model composes a dance *between key poses*; so when the user gives
//! few of them, the scaffold supplies the rest: real poses handed to the network as key poses it is
//! *not* held to (no exact pass, unlike the user's). The network still makes every frame: the
//! transitions, the travel, the facing and the height. Scaffold poses keep away from user keys.
//!
//! **Following the music** ([`PoseBank::scaffold_to`]): the song's beats, tempo, meter
//! and energy ([`SongCues`]) choose the clips: those whose own beat period is near the song's (or
//! twice or half of it), in the song's meter (waltz clips for three beats a bar) and whose music
//! had the energy of the song around the frame they enter; the job's seed draws among the best few,
//! so two seeds still dance differently and one seed dances differently to two songs. Each clip is
//! retimed so that its own beats fall on the song's ([`super::beats::TimeMap`]): the seed rows are
//! the clip resampled at the song's pace, and a scaffold pose sits on every beat (every other beat
//! when beats come faster than [`MIN_SPACING`] frames, on half beats too when slower than
//! [`MAX_SPACING`]), read from the clip at the matching point of its own beat. When a clip runs out
//! of beats the next continues from the beat-grid position nearest the current pose among a seeded
//! share of the good candidates, so the scaffold has no jump a dancer could not make.
//!
//! A bank without `pose_bank.json` keeps the earlier scaffold ([`PoseBank::scaffold`]): the seed
//! alone draws a clip, posed every `spacing` frames in the clip's own timing.
//!
//! The dance starts on a lively stretch: the seed redraws (up to [`START_TRIES`] times) a clip and
//! start whose first 5 s move at least as fast as the slowest real dance. 14 of the 32 clips
//! hold slower stretches (a pause, a travel-heavy figure), and on a short song that one stretch was
//! the whole dance: seeds 0–31 danced a 5-s loop at 0.32–0.81 m/s, 10 of them below 0.5. The bank
//! keeps its slow stretches for later in the dance: filtering them out of the bank made every
//! dance move at one pace (Div_k on the test split 6.7 → 2.9).
use std::path::Path;

use ndarray::{s, Array2, Array3, ArrayView1};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};

use super::beats::{row_at, SongCues, TimeMap};
use super::keys::LocalKey;
use crate::models::clip_choice;
pub use crate::models::clip_choice::{BankMeta, ClipInfo};
use crate::models::ModelError;
use crate::motion::repr::{self, FEATURE_DIM, POSE_DIM};

/// A dance's first stretch moves at least this fast (m/s, mean joint speed): the slowest real
/// train dance (`metrics/reference_train.json`, `physical.mean_speed_range_m_s`).
pub const LIVELY_M_S: f64 = 0.63;
/// A clip whose arms move slower than this against the spine (m/s, over the whole clip) is
/// ranked [`HELD_ARMS_PENALTY`] lower: the slowest real dance's arms, as a whole dance
/// (`metrics::musicality`). Three of the bank's 18 waltz clips hold their arms slower
/// (0.37, 0.42, 0.43 m/s), and a waltz drawn from them danced DANCE_W_8 (seed 6) with its arms at
/// 0.42.
pub const HELD_ARMS_M_S: f64 = 0.43;
/// How much lower such a clip ranks: as much as the wrong meter, more than
/// [`clip_choice::SCORE_MARGIN`], so it is drawn only where the song has too few other candidates.
pub const HELD_ARMS_PENALTY: f64 = clip_choice::METER_PENALTY;
/// Frames of a dance's first stretch: 5 s (the metrics' window), or the whole dance if shorter.
pub const START_STRETCH: usize = 125;
/// Draws of clip and start the seed tries for a lively first stretch before taking one as it is.
pub const START_TRIES: usize = 16;

/// The bank file in a model folder (`models::folder::write_clips`: `[clips, frames, features]`,
/// denormalised, in the model's root-height representation).
pub const POSE_BANK_FILE: &str = "pose_bank.safetensors";
/// Where each bank clip came from and its beats, beside [`POSE_BANK_FILE`].
pub const POSE_BANK_META_FILE: &str = "pose_bank.json";

/// Scaffold poses come no closer than this (frames): beats faster than that get a pose every
/// other beat. 8 frames gave more pops than 12 when the spacing was fixed.
pub const MIN_SPACING: f64 = 8.0;
/// Scaffold poses come no further apart than this (frames): slower beats get half-beat poses
/// too. A fixed 25-frame spacing made dances of 0.34–0.41 m/s; with 20 here a waltz's beats
/// (17 frames at 87 BPM) got a pose each and a test dance moved 0.48 m/s as served, under the
/// verdict's 0.5.
pub const MAX_SPACING: f64 = 14.0;
/// A clip entered by a continuation has at least this many song beats left in it.
const MIN_RUN_BEATS: f64 = 4.0;

/// Real clips the seed draws from.
#[derive(Clone, Debug)]
pub struct PoseBank {
    clips: Array3<f32>,
    /// `[clips, frames − 1]` mean joint speed of each frame step (m/s at 25 fps, the root height
    /// aside); empty for a bank without root columns.
    speeds: Array2<f64>,
    /// Each clip's arm speed against the spine over the whole clip (m/s,
    /// `metrics::musicality::arm_speed_m_s`); empty for a bank without root columns.
    arms: Vec<f64>,
    /// Each clip's source and beats; none for a bank written before they were kept.
    meta: Option<BankMeta>,
}

/// A stretch of the scaffold danced from one clip: `u` of the clip's beats per song beat, from
/// beat position `q` (fractional beat index of the clip) on the song beat the run starts at.
#[derive(Clone, Copy, Debug)]
struct Run {
    clip: usize,
    q: f64,
    u: f64,
}

/// What one seed drew: the seed motion and the scaffold poses.
#[derive(Clone, Debug)]
pub struct Scaffold {
    /// `[T′, features]` seed rows.
    pub seed: Array2<f32>,
    /// `(frame, 69 local coordinates)`, frames ascending.
    pub poses: Vec<(usize, Vec<f32>)>,
    /// The bank clip and frame the dance starts from.
    pub start: (usize, usize),
    /// The clips' turning as the scaffold reads them: yaw velocity (radians per frame) per song
    /// frame; empty where the scaffold follows no beats ([`PoseBank::scaffold`]).
    pub facing: Vec<f32>,
}

fn distance(a: ArrayView1<'_, f32>, b: ArrayView1<'_, f32>) -> f32 {
    a.iter()
        .zip(b.iter())
        .take(POSE_DIM)
        .map(|(x, y)| (x - y) * (x - y))
        .sum()
}

impl PoseBank {
    /// A bank of `[clips, frames, features]`; at least one clip, frames ≥ 2, features ≥ 69.
    pub fn new(clips: Array3<f32>) -> Result<Self, ModelError> {
        let (k, l, d) = clips.dim();
        if k == 0 || l < 2 || d < POSE_DIM {
            return Err(ModelError::BadModelFile(format!(
                "pose bank of shape [{k}, {l}, {d}]"
            )));
        }
        if clips.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::BadModelFile(
                "pose bank has non-finite values".into(),
            ));
        }
        let (speeds, arms) = if d == FEATURE_DIM {
            Self::step_speeds(&clips)?
        } else {
            (Array2::zeros((0, 0)), Vec::new())
        };
        Ok(Self {
            clips,
            speeds,
            arms,
            meta: None,
        })
    }

    /// The bank with each clip's source and beats (one [`ClipInfo`] per clip, beats within it).
    pub fn with_meta(mut self, meta: BankMeta) -> Result<Self, ModelError> {
        let (k, l, _) = self.clips.dim();
        self.meta = Some(meta.checked(k, l, POSE_BANK_META_FILE)?);
        Ok(self)
    }

    /// Each clip's source and beats, when the bank has them.
    pub fn meta(&self) -> Option<&BankMeta> {
        self.meta.as_ref()
    }

    /// Mean joint speed of every frame step of every clip, decoded with the root at height 0, and
    /// each clip's arm speed against the spine.
    fn step_speeds(clips: &Array3<f32>) -> Result<(Array2<f64>, Vec<f64>), ModelError> {
        let (k, l, _) = clips.dim();
        let mut out = Array2::zeros((k, l - 1));
        let mut arms = Vec::with_capacity(k);
        for (c, clip) in clips.outer_iter().enumerate() {
            let mut f = clip.to_owned();
            f.column_mut(repr::ROOT_Y).fill(0.0);
            let fps = crate::motion::MOTION_FPS;
            let (motion, _) = repr::from_features(f.view(), repr::RootStart::default(), fps)
                .map_err(|e| ModelError::BadModelFile(e.to_string()))?;
            let v = crate::metrics::kinematics::mean_speed(motion.positions.view(), fps);
            out.row_mut(c).assign(&ndarray::Array1::from(v));
            arms.push(crate::metrics::musicality::arm_speed_m_s(
                motion.positions.view(),
                fps,
            ));
        }
        Ok((out, arms))
    }

    /// Mean joint speed (m/s) of clip `c` over frames `[start, start + len)`; 0 without speeds.
    fn pace(&self, c: usize, start: usize, len: usize) -> f64 {
        if self.speeds.is_empty() || len < 2 {
            return 0.0;
        }
        let steps = self.speeds.slice(s![c, start..start + len - 1]);
        steps.sum() / steps.len() as f64
    }

    /// Reads a bank written by [`PoseBank::save`], with [`POSE_BANK_META_FILE`] when it lies beside.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let bank = Self::new(crate::models::folder::read_clips(path)?)?;
        match BankMeta::read_beside(path, POSE_BANK_META_FILE)? {
            Some(meta) => bank.with_meta(meta),
            None => Ok(bank),
        }
    }

    /// Writes the bank as safetensors, and its [`BankMeta`] beside it when it has one.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        crate::models::folder::write_clips(&self.clips, path)?;
        match &self.meta {
            Some(meta) => meta.write_beside(path, POSE_BANK_META_FILE),
            None => Ok(()),
        }
    }

    /// `[clips, frames, features]`.
    pub fn dim(&self) -> (usize, usize, usize) {
        self.clips.dim()
    }

    /// What `seed` draws for a dance of `frames` frames with seed length `ts`, scaffold poses every
    /// `spacing` frames (none for 0) kept `spacing` frames away from the user's `keys`.
    pub fn scaffold(
        &self,
        seed: u64,
        frames: usize,
        ts: usize,
        spacing: usize,
        keys: &[LocalKey],
    ) -> Scaffold {
        let (k, l, _) = self.clips.dim();
        let ts = ts.min(l);
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5CAF_F01D);
        let need = frames.clamp(ts, START_STRETCH).min(l);
        // Every draw is made, so what follows does not depend on which was taken.
        let draws: Vec<(usize, usize)> = (0..START_TRIES)
            .map(|_| (rng.gen_range(0..k), rng.gen_range(0..=l - need)))
            .collect();
        let origin = draws
            .iter()
            .copied()
            .find(|&(c, at)| self.pace(c, at, need) >= LIVELY_M_S)
            .unwrap_or(draws[0]);
        let (mut clip, start) = origin;
        let seed_rows = self.clips.slice(s![clip, start..start + ts, ..]).to_owned();
        let mut poses = Vec::new();
        if spacing == 0 {
            return Scaffold {
                seed: seed_rows,
                poses,
                start: origin,
                facing: Vec::new(),
            };
        }
        let mut cursor = start + ts - 1;
        let mut frame = ts - 1 + spacing;
        while frame < frames {
            cursor += spacing;
            if cursor >= l {
                (clip, cursor) = self.continue_from(clip, cursor - spacing, spacing, &mut rng);
            }
            let near_key = keys.iter().any(|key| key.frame.abs_diff(frame) < spacing);
            if !near_key {
                poses.push((
                    frame,
                    self.clips.slice(s![clip, cursor, ..POSE_DIM]).to_vec(),
                ));
            }
            frame += spacing;
        }
        Scaffold {
            seed: seed_rows,
            poses,
            start: origin,
            facing: Vec::new(),
        }
    }

    /// Clips ranked by how well they suit the song around song frame `at`, best first
    /// ([`clip_choice::ranked`] with the song's period, meter and energy there).
    /// The clips ranked for the song at frame `at` ([`clip_choice::ranked`]), those that hold
    /// their arms ([`HELD_ARMS_M_S`]) [`HELD_ARMS_PENALTY`] lower.
    fn ranked(&self, meta: &BankMeta, cues: &SongCues, at: f64) -> Vec<(usize, f64, f64)> {
        let mut out = clip_choice::ranked(&meta.clips, cues.period, cues.bar, cues.energy_at(at));
        for r in out.iter_mut() {
            if self.arms.get(r.0).is_some_and(|&a| a < HELD_ARMS_M_S) {
                r.2 += HELD_ARMS_PENALTY;
            }
        }
        out.sort_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)));
        out
    }

    /// What `seed` draws for a dance of `frames` frames to the song of `cues` with seed length
    /// `ts`, kept away from the user's `keys` (module doc); none for a bank without
    /// [`BankMeta`] or without a clip of two beats.
    pub fn scaffold_to(
        &self,
        seed: u64,
        cues: &SongCues,
        frames: usize,
        ts: usize,
        keys: &[LocalKey],
    ) -> Option<Scaffold> {
        let meta = self.meta.as_ref()?;
        let (_, l, _) = self.clips.dim();
        let ts = ts.min(l);
        // Beat index → clip frame of every clip.
        let beat_maps: Vec<Option<TimeMap>> = meta
            .clips
            .iter()
            .map(|c| TimeMap::new(c.beats.iter().enumerate().map(|(j, b)| (j as f64, *b))))
            .collect();
        let last_beat = |c: usize| meta.clips[c].beats.len().saturating_sub(1) as f64;
        let mut rng = StdRng::seed_from_u64(seed ^ 0x5CAF_F01D);
        let need = frames.clamp(ts, START_STRETCH);
        let good: Vec<(usize, f64)> =
            clip_choice::good(&self.ranked(meta, cues, need as f64 / 2.0))
                .into_iter()
                .filter(|g| beat_maps[g.0].is_some())
                .collect();
        if good.is_empty() {
            return None;
        }
        let (s0, period) = (cues.beats[0], cues.period);
        // Every draw is made, so what follows does not depend on which was taken.
        let draws: Vec<Run> = (0..START_TRIES)
            .map(|_| {
                let (clip, u) = good[rng.gen_range(0..good.len())];
                let room = (last_beat(clip) - u * MIN_RUN_BEATS).floor().max(0.0) as usize;
                Run {
                    clip,
                    q: rng.gen_range(0..=room) as f64,
                    u,
                }
            })
            .collect();
        // The clip frames a run covers over the first stretch, and its pace there as retimed.
        let stretch = |r: &Run| -> f64 {
            let Some(map) = beat_maps[r.clip].as_ref() else {
                return 0.0;
            };
            let a = map.at(r.q + r.u * (0.0 - s0) / period).max(0.0);
            let b = map
                .at(r.q + r.u * (need as f64 - s0) / period)
                .min((l - 1) as f64);
            if b <= a + 1.0 {
                return 0.0;
            }
            self.pace(r.clip, a as usize, (b - a) as usize) * (b - a) / need as f64
        };
        let mut run = draws
            .iter()
            .copied()
            .find(|r| stretch(r) >= LIVELY_M_S)
            .unwrap_or(draws[0]);
        // Walk the song's beats: (song frame, run index, clip beat position, clip frame).
        let mut runs = vec![run];
        let mut points: Vec<(f64, usize, f64, f64)> = Vec::with_capacity(cues.beats.len());
        let mut run_start = 0usize;
        for (i, &s) in cues.beats.iter().enumerate() {
            let mut q = run.q + run.u * (i - run_start) as f64;
            if q > last_beat(run.clip) + 1e-9 {
                let &(_, r, _, f) = points.last()?;
                let here = row_at(self.clips.slice(s![runs[r].clip, .., ..]), f);
                let (clip, q2, u) =
                    self.continue_to(meta, &beat_maps, cues, s, run.clip, &here, &mut rng)?;
                run = Run { clip, q: q2 + u, u };
                runs.push(run);
                run_start = i;
                q = run.q;
            }
            let f = beat_maps[run.clip].as_ref()?.at(q);
            points.push((s, runs.len() - 1, q, f));
        }
        let facing = self.facing(&points, &runs, &beat_maps, frames);
        // The seed rows: the first clip at the song's pace.
        let first: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.1 == 0)
            .map(|p| (p.0, p.3))
            .collect();
        let start_clip = runs[0].clip;
        let rows = self.clips.slice(s![start_clip, .., ..]);
        let to_clip = TimeMap::new(first)?;
        let seed_rows = super::beats::resample_rows(rows, &to_clip, ts);
        let start = (
            start_clip,
            to_clip.at(0.0).clamp(0.0, (l - 1) as f64).round() as usize,
        );
        tracing::debug!(period, bar = cues.bar, runs = ?runs.iter().map(|r| (r.clip, r.q, r.u)).collect::<Vec<_>>(), "scaffold runs");
        // Poses on beats (every other one when fast, half beats too when slow).
        let every = if period < MIN_SPACING { 2 } else { 1 };
        // Poses per beat: 1, or 2 (half beats) when beats are slow.
        let per_beat = if period > MAX_SPACING { 2 } else { 1 };
        let spacing = period * every as f64 / per_beat as f64;
        let mut at: Vec<(f64, usize, f64)> = Vec::new();
        for (i, p) in points.iter().enumerate() {
            if i % every == 0 {
                at.push((p.0, runs[p.1].clip, p.3));
            }
            let Some(next) = points.get(i + 1) else {
                continue;
            };
            for k in 1..per_beat {
                // A share of the beat on in this run, or, where the next beat starts a run, that
                // much before it in that one (whose first position is nearest this beat's pose).
                let w = k as f64 / per_beat as f64;
                let (r, q) = if next.1 == p.1 {
                    (runs[p.1], p.2 + runs[p.1].u * w)
                } else {
                    (runs[next.1], next.2 - runs[next.1].u * (1.0 - w))
                };
                at.push((
                    p.0 + (next.0 - p.0) * w,
                    r.clip,
                    beat_maps[r.clip].as_ref()?.at(q),
                ));
            }
        }
        let first_pose = ts as f64 - 1.0 + spacing / 2.0;
        let keep_off = spacing.ceil() as usize;
        let poses = at
            .into_iter()
            .filter(|(s, _, _)| *s >= first_pose && s.round() < frames as f64)
            .map(|(s, c, f)| (s.round() as usize, c, f))
            .filter(|(frame, _, _)| !keys.iter().any(|k| k.frame.abs_diff(*frame) < keep_off))
            .map(|(frame, c, f)| {
                let mut pose = row_at(self.clips.slice(s![c, .., ..]), f);
                pose.truncate(POSE_DIM);
                (frame, pose)
            })
            .collect();
        Some(Scaffold {
            seed: seed_rows,
            poses,
            start,
            facing,
        })
    }

    /// The scaffold's turning: per song frame `0..frames`, the yaw velocity (radians per frame)
    /// of the clip frame the scaffold reads there, scaled by the pace it is read at. `points` are
    /// (song frame, run, clip beat position, clip frame) per song beat, ascending. Between two
    /// beats of one run the clip is read linearly; where the next beat starts a run, the stretch
    /// before it is read from that run's clip, one of its beats back (as the half-beat poses are).
    fn facing(
        &self,
        points: &[(f64, usize, f64, f64)],
        runs: &[Run],
        beat_maps: &[Option<TimeMap>],
        frames: usize,
    ) -> Vec<f32> {
        if points.len() < 2 {
            return Vec::new();
        }
        let l = self.clips.dim().1;
        (0..frames)
            .map(|t| {
                let t = t as f64;
                let i = points
                    .partition_point(|p| p.0 <= t)
                    .clamp(1, points.len() - 1)
                    - 1;
                let (p, next) = (points[i], points[i + 1]);
                let span = next.0 - p.0;
                if span <= 0.0 {
                    return 0.0;
                }
                let (clip, from) = if next.1 == p.1 {
                    (runs[p.1].clip, p.3)
                } else {
                    let r = runs[next.1];
                    let from = beat_maps[r.clip]
                        .as_ref()
                        .map_or(next.3, |m| m.at(next.2 - r.u));
                    (r.clip, from)
                };
                let pace = (next.3 - from) / span;
                let f = (from + (t - p.0).clamp(0.0, span) * pace).clamp(0.0, (l - 1) as f64);
                let row = row_at(self.clips.slice(s![clip, .., ..]), f);
                row.get(repr::YAW_VEL).copied().unwrap_or(0.0) * pace as f32
            })
            .collect()
    }

    /// Where the scaffold goes on at song frame `at` when clip `from` has run out of beats: among
    /// a seeded two thirds of the good candidates there (`from` aside), the clip and beat
    /// (a whole one, so its beats stay on the song's) whose pose is nearest to `here`, with at least [`MIN_RUN_BEATS`] song beats left
    /// after it: `(clip, q, u)`.
    #[allow(clippy::too_many_arguments)]
    fn continue_to(
        &self,
        meta: &BankMeta,
        beat_maps: &[Option<TimeMap>],
        cues: &SongCues,
        at: f64,
        from: usize,
        here: &[f32],
        rng: &mut StdRng,
    ) -> Option<(usize, f64, f64)> {
        let k = meta.clips.len();
        let ranked: Vec<(usize, f64, f64)> = self
            .ranked(meta, cues, at)
            .into_iter()
            .filter(|r| (r.0 != from || k == 1) && beat_maps[r.0].is_some())
            .collect();
        let mut good = clip_choice::good(&ranked);
        good.shuffle(rng);
        good.truncate((2 * good.len()).div_ceil(3).max(1));
        let here = ndarray::ArrayView1::from(here);
        let mut best: Option<(usize, f64, f64, f32)> = None;
        for &(c, u) in &good {
            let (Some(map), n) = (beat_maps[c].as_ref(), meta.clips[c].beats.len()) else {
                continue;
            };
            let mut q = 0.0;
            while q + u * MIN_RUN_BEATS <= (n - 1) as f64 {
                let pose = row_at(self.clips.slice(s![c, .., ..]), map.at(q));
                let d = distance(here, ndarray::ArrayView1::from(&pose));
                if best.is_none_or(|b| d < b.3) {
                    best = Some((c, q, u, d));
                }
                q += 1.0;
            }
        }
        // No candidate has that much room: the best-ranked clip from its first beat.
        best.map(|b| (b.0, b.1, b.2))
            .or_else(|| ranked.first().map(|r| (r.0, 0.0, r.1)))
    }

    /// The bank frame, `spacing` frames after the one nearest to clip `from`'s frame `at`, among a
    /// seeded half of the other clips (all clips when the bank has one).
    fn continue_from(
        &self,
        from: usize,
        at: usize,
        spacing: usize,
        rng: &mut StdRng,
    ) -> (usize, usize) {
        let (k, l, _) = self.clips.dim();
        let here = self.clips.slice(s![from, at, ..]);
        let mut others: Vec<usize> = (0..k).filter(|&c| c != from || k == 1).collect();
        others.shuffle(rng);
        others.truncate(others.len().div_ceil(2).max(1));
        let last = l.saturating_sub(spacing + 1);
        let mut best = (others[0], 0, f32::INFINITY);
        for &c in &others {
            for f in 0..=last {
                let d = distance(here, self.clips.slice(s![c, f, ..]));
                if d < best.2 {
                    best = (c, f, d);
                }
            }
        }
        (best.0, (best.1 + spacing).min(l - 1))
    }
}

#[cfg(test)]
mod tests;
