//! A built beat-graph folder (`model.json`, `weights.safetensors` = the unit library and its
//! graph) and the served path: the song's beats into slots, the style, the search, the
//! composition, and the user's key poses passed exactly.
use std::path::Path;

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::body::{bone_lengths, rebone};
use super::library::{style_counts, Library, DEFAULT_PACE, MIN_STYLE_UNITS};
use super::rhythm::{music_descriptors, Match};
use super::search::{search, Problem, Slot, SlotKey};
use super::{compose, Config};
use crate::audio::Analysis;
use crate::models::folder::{self, WEIGHTS_FILE};
use crate::models::keypose_transformer::keys::{local_keys, pass_through_keys, pass_through_yaws};
use crate::models::keypose_transformer::served::{BLEND_RADIUS, YAW_BLEND_RADIUS};
use crate::models::{
    Capabilities, DanceModel, DanceStyle, GenerateRequest, Generated, ModelError, ModelId,
    ModelInfo, Progress, StyleChoice,
};
use crate::motion::repr::{self, RootStart, POSE_DIM};
use crate::motion::NUM_JOINTS;
use crate::stage::Stage;

/// The API id.
pub const ID: &str = "beat-graph";
/// How sharply the style guess prefers the style whose tempo and bar fit the song (the softmax
/// temperature over [`style_distance`]).
const STYLE_SHARPNESS: f64 = 0.15;
/// The shortest stretch of a song danced in a style of its own (s): eight bars of a cha-cha.
const MIN_SECTION_S: f64 = 16.0;

/// A style as the train split dances it: its bar, its median beat, how many units it has.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StyleProfile {
    pub style: DanceStyle,
    pub meter: usize,
    pub beat_s: f64,
    pub units: usize,
    pub dances: usize,
}

/// How well the music match ranks the true unit of a held-out beat (the test split's pairs):
/// the share of other units it costs less than.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MatchCheck {
    pub pairs: usize,
    /// Against units drawn from the whole library.
    pub auc_library: f64,
    /// Against other beats of the same dance (tempo and style the same: the rhythm alone).
    pub auc_same_dance: f64,
    /// The same two figures on the train pairs the map was fitted on.
    pub train_auc_library: f64,
    pub train_auc_same_dance: f64,
}

/// What the library holds and how it was made.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LibraryRecord {
    pub dances: Vec<String>,
    pub units: usize,
    pub frames: usize,
    pub made_by: String,
    pub seconds: f64,
}

/// `model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelFile {
    pub config: Config,
    pub fps: f64,
    pub matcher: Match,
    pub styles: Vec<StyleProfile>,
    pub library: LibraryRecord,
    pub held_out: MatchCheck,
}

/// The beat-graph model, ready to serve.
pub struct Served {
    file: ModelFile,
    lib: Library,
    /// Per style, the median steps a beat of its units.
    style_pace: [f64; 4],
}

/// What a composition was made of, for the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Composition {
    /// Slots (beats, or half or double beats) the song was cut into.
    pub slots: usize,
    /// Beats of the song a slot spans (0.5, 1 or 2).
    pub beats_per_slot: f64,
    /// Distinct training dances the units came from.
    pub dances_used: usize,
    /// The longest stretch taken in order from one training dance, seconds of the dance.
    pub longest_copy_s: f64,
    /// Where one unit gives way to another that does not follow it in its dance (seconds):
    /// what a test of the joins looks at; too long for the report.
    #[serde(skip)]
    #[schema(ignore)]
    pub joins_s: Vec<f64>,
    /// Where the style changes with the song's tempo (a song that speeds up from a rumba's
    /// tempo to a cha-cha's): each section's start and style. Empty when the whole dance is one
    /// style.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sections: Vec<StyleSection>,
}

/// A stretch of the song danced in one style, from `from_s` to the next section's start.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct StyleSection {
    pub from_s: f64,
    pub style: DanceStyle,
}

/// The style danced at `t`.
fn style_at(sections: &[StyleSection], t: f64) -> DanceStyle {
    sections
        .iter()
        .rev()
        .find(|s| s.from_s <= t)
        .or(sections.first())
        .map_or(DanceStyle::Rumba, |s| s.style)
}

/// The style danced longest over `[0, duration]`.
fn main_style(sections: &[StyleSection], duration: f64) -> DanceStyle {
    let mut time = [0.0f64; 4];
    for (k, s) in sections.iter().enumerate() {
        let end = sections.get(k + 1).map_or(duration, |n| n.from_s);
        time[s.style.index()] += (end.min(duration) - s.from_s.max(0.0)).max(0.0);
    }
    let best = (0..4).max_by(|&a, &b| time[a].total_cmp(&time[b]));
    match (sections.len(), best) {
        (1, _) | (_, None) => style_at(sections, 0.0),
        (_, Some(b)) => DanceStyle::ALL[b],
    }
}

impl Served {
    /// Loads `dir/model.json` and the library in `dir/weights.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let file: ModelFile = folder::read(dir, ID)?;
        if !file.matcher.is_well_formed() || file.fps.is_nan() || file.fps <= 0.0 {
            return Err(ModelError::BadModelFile(format!(
                "{ID}/model.json: the music match or the frame rate is malformed"
            )));
        }
        let lib = Library::load(&dir.join(WEIGHTS_FILE))?;
        let per_dance = lib.dance_paces(file.fps);
        let style_pace = DanceStyle::ALL.map(|st| {
            let mut v: Vec<f64> = lib
                .units
                .iter()
                .filter(|u| u.style == st)
                .map(|u| per_dance[u.dance])
                .collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(DEFAULT_PACE)
        });
        Ok(Self {
            file,
            lib,
            style_pace,
        })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The unit library.
    pub fn library(&self) -> &Library {
        &self.lib
    }

    /// The style whose bar and beat fit a song of median beat `beat_s` and bar `meter`.
    pub fn predict_style(&self, beat_s: f64, meter: usize) -> StyleChoice {
        let weights: Vec<f64> = DanceStyle::ALL
            .iter()
            .map(|&st| {
                self.file
                    .styles
                    .iter()
                    .find(|p| p.style == st && p.units > 0)
                    .map_or(0.0, |p| {
                        (-style_distance(p, beat_s, meter) / STYLE_SHARPNESS).exp()
                    })
            })
            .collect();
        let total: f64 = weights.iter().sum::<f64>().max(1e-12);
        let probabilities: Vec<f32> = weights.iter().map(|w| (w / total) as f32).collect();
        let best = (0..4)
            .max_by(|&a, &b| weights[a].total_cmp(&weights[b]))
            .unwrap_or(0);
        StyleChoice {
            style: DanceStyle::ALL[best],
            predicted: true,
            probabilities,
        }
    }

    /// The styles the song is danced in: the chosen one throughout, unless the style was guessed
    /// and the song's tempo moves so far that another style's tempo fits a part of it better
    /// (dancers change dance when a DJ mix goes from a rumba's tempo to a cha-cha's, and only a
    /// style whose own beat is near the song's can follow it within the units' stretch range).
    /// Sections shorter than [`MIN_SECTION_S`] go to their neighbour.
    pub fn sections(
        &self,
        analysis: &Analysis,
        choice: &StyleChoice,
        duration: f64,
    ) -> Vec<StyleSection> {
        let whole = vec![StyleSection {
            from_s: 0.0,
            style: choice.style,
        }];
        let curve = &analysis.tempo_curve;
        let moves = curve
            .windows(2)
            .any(|w| (w[1].bpm / w[0].bpm).ln().abs() > 0.01);
        if !choice.predicted || !moves {
            return whole;
        }
        let meter = meter_of(analysis);
        let mut out: Vec<StyleSection> = Vec::new();
        let mut pace: Option<f64> = None;
        for p in curve.iter().filter(|p| p.bpm > 0.0 && p.time_s < duration) {
            // After the first, a section keeps the dance's steps a beat where a style of that
            // pace fits the tempo (a rumba's two steps a bar go on as a cha-cha's, not as a
            // tango's), so its steps speed up with the beats.
            let style = match pace {
                None => self.predict_style(60.0 / p.bpm, meter).style,
                Some(pace) => self.predict_style_at_pace(60.0 / p.bpm, meter, pace),
            };
            pace.get_or_insert(self.style_pace[style.index()]);
            if out.last().is_none_or(|s| s.style != style) {
                out.push(StyleSection {
                    from_s: p.time_s,
                    style,
                });
            }
        }
        // Short sections (a tempo curve passing another style's tempo on its way) join the
        // section before them; the first section starts the song.
        let mut merged: Vec<StyleSection> = Vec::new();
        for (k, s) in out.iter().enumerate() {
            let end = out.get(k + 1).map_or(duration, |n| n.from_s);
            if end - s.from_s < MIN_SECTION_S && !merged.is_empty() {
                continue;
            }
            if merged.last().is_some_and(|m| m.style == s.style) {
                continue;
            }
            merged.push(*s);
        }
        match merged.first_mut() {
            Some(first) => {
                first.from_s = 0.0;
                merged
            }
            None => whole,
        }
    }

    /// The style whose tempo fits a beat of `beat_s` best, each style's distance
    /// ([`style_distance`]) raised by how far its steps a beat are from `pace` (as a log ratio).
    fn predict_style_at_pace(&self, beat_s: f64, meter: usize, pace: f64) -> DanceStyle {
        self.file
            .styles
            .iter()
            .filter(|p| p.units > 0)
            .map(|p| {
                let off = (self.style_pace[p.style.index()] / pace).ln().abs();
                (p.style, style_distance(p, beat_s, meter) + off)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(DanceStyle::Rumba, |(st, _)| st)
    }

    /// Per unit: whether it may dance `style`, and at what cost: the style's, plus the seed's
    /// leaning towards the unit's dance ([`Config::dance_preference`]).
    fn allowed(&self, style: DanceStyle, seed: u64) -> Vec<Option<f64>> {
        let lean: Vec<f64> = (0..self.lib.dance_first.len().saturating_sub(1))
            .map(|d| {
                self.file.config.dance_preference * super::search::uniform(seed ^ 0xDA7CE, d, 0)
            })
            .collect();
        let counts = style_counts(&self.lib.units);
        let own = counts[style.index()];
        let meter = self
            .file
            .styles
            .iter()
            .find(|p| p.style == style)
            .map_or(4, |p| p.meter);
        self.lib
            .units
            .iter()
            .map(|u| {
                let cost = if u.style == style {
                    Some(0.0)
                } else if own < MIN_STYLE_UNITS && u.meter == meter {
                    Some(self.file.config.style_weight)
                } else {
                    None
                };
                cost.map(|c| c + lean[u.dance])
            })
            .collect()
    }

    /// Composes one dance: the path through the graph and its motion, with what it was made of.
    pub fn compose(
        &self,
        req: &GenerateRequest<'_>,
        analysis: &Analysis,
        music: ndarray::ArrayView2<'_, f32>,
        sections: &[StyleSection],
        progress: &mut dyn Progress,
    ) -> Result<(crate::motion::Motion, Composition), ModelError> {
        let fps = self.file.fps;
        let n = music.nrows();
        let duration = n as f64 / fps;
        let keys = local_keys(req.key_poses, n, fps)?;
        let style = main_style(sections, duration);
        let (beat_s, unit_meter) = self
            .file
            .styles
            .iter()
            .find(|p| p.style == style)
            .map_or((0.6, 4), |p| (p.beat_s, p.meter));
        let (slots, per_slot) = slots_of(analysis, duration, beat_s, unit_meter);
        let spans: Vec<(f64, f64)> = slots.iter().map(|s| (s.t0, s.t1)).collect();
        let predicted = self
            .file
            .matcher
            .predict(&music_descriptors(music, fps, &spans));
        let (seed_rows, start) = match req.seed_motion {
            Some(m) if m.num_frames() > 0 => {
                let m = m
                    .positions
                    .slice(ndarray::s![..m.num_frames().min(n), .., ..]);
                let root = crate::motion::skeleton::body_centre_track(m);
                repr::to_features(m, root.view())?
            }
            _ => (Array2::zeros((0, repr::FEATURE_DIM)), RootStart::default()),
        };
        let from = seed_rows.nrows();
        let slot_of = |t: f64| slots.iter().rposition(|s| s.t0 <= t).unwrap_or(0);
        let fraction =
            |i: usize, t: f64| ((t - slots[i].t0) / (slots[i].t1 - slots[i].t0)).clamp(0.0, 1.0);
        let first = slot_of(from as f64 / fps);
        let start_pose: Option<Vec<f32>> = (from > 0).then(|| {
            seed_rows
                .row(from - 1)
                .iter()
                .take(POSE_DIM)
                .copied()
                .collect()
        });
        let slot_keys: Vec<SlotKey> = keys
            .iter()
            .map(|k| {
                let t = k.frame as f64 / fps;
                let i = slot_of(t);
                SlotKey {
                    slot: i - first.min(i),
                    fraction: fraction(i, t),
                    local: k.local.clone(),
                }
            })
            .collect();
        // One row of allowed units per style danced, and each slot pointing at its section's.
        let rows: Vec<(DanceStyle, Vec<Option<f64>>)> = DanceStyle::ALL
            .iter()
            .filter(|st| sections.iter().any(|s| s.style == **st))
            .map(|&st| (st, self.allowed(st, req.seed)))
            .collect();
        let allowed: Vec<&[Option<f64>]> = slots[first..]
            .iter()
            .map(|slot| {
                let st = style_at(sections, 0.5 * (slot.t0 + slot.t1));
                rows.iter()
                    .find(|(s, _)| *s == st)
                    .map_or(&rows[0].1[..], |(_, r)| &r[..])
            })
            .collect();
        let mut config = self.file.config.clone();
        config.gumbel_scale *= req.temperature.unwrap_or(1.0).max(0.0);
        let problem = Problem {
            slots: &slots[first..],
            meter: unit_meter,
            predicted: &predicted.slice(ndarray::s![first.., ..]).to_owned(),
            matcher: &self.file.matcher,
            allowed: &allowed,
            keys: &slot_keys,
            start: start_pose
                .as_deref()
                .map(|p| (p, fraction(first, from as f64 / fps))),
            seed: req.seed,
            fps,
        };
        progress.report(Stage::Generate, 0.0)?;
        let path = search(&self.lib, &config, &problem).ok_or_else(|| {
            ModelError::Input(format!("no {} unit fits this song's beats", style.name()))
        })?;
        progress.report(Stage::Generate, 0.5)?;
        let mut x = compose::compose(
            &self.lib,
            &path.units,
            &slots[first..],
            n,
            fps,
            config.blend_halflife_s,
            seed_rows.view(),
        );
        let mut start = start;
        if let Some(lengths) = body_of(req) {
            // The key pass comes after, so the key poses are met on their own bones.
            let (mut motion, root) = repr::from_features(x.view(), start, fps)?;
            // A seed motion sets the floor; the dance goes on from it where it stands.
            rebone(&mut motion.positions, root.view(), &lengths, from == 0);
            (x, start) = repr::to_features(motion.positions.view(), root.view())?;
        }
        let targets: Vec<(usize, Vec<f32>)> =
            keys.iter().map(|k| (k.frame, k.local.clone())).collect();
        pass_through_keys(&mut x, 0..POSE_DIM, &targets, BLEND_RADIUS);
        let yaws: Vec<(usize, f32)> = keys.iter().map(|k| (k.frame, k.yaw)).collect();
        if !yaws.is_empty() {
            start.yaw = pass_through_yaws(&mut x, start.yaw, &yaws, YAW_BLEND_RADIUS);
        }
        let (mut motion, _) = repr::from_features(x.view(), start, fps)?;
        if let Some(seed) = req.seed_motion {
            // The seed's own frames open the dance exactly as they came.
            let n = from.min(motion.num_frames());
            motion
                .positions
                .slice_mut(ndarray::s![..n, .., ..])
                .assign(&seed.positions.slice(ndarray::s![..n, .., ..]));
        }
        progress.report(Stage::Generate, 1.0)?;
        let mut dances: Vec<usize> = path
            .units
            .iter()
            .map(|&u| self.lib.units[u].dance)
            .collect();
        dances.sort_unstable();
        dances.dedup();
        let longest_copy_s = longest_copy_frames(&self.lib, &path.units) / fps;
        let joins_s = (1..path.units.len())
            .filter(|&i| self.lib.units[path.units[i - 1]].next != Some(path.units[i]))
            .map(|i| slots[first + i].t0)
            .collect();
        Ok((
            motion,
            Composition {
                slots: path.units.len(),
                beats_per_slot: per_slot,
                dances_used: dances.len(),
                longest_copy_s,
                joins_s,
                sections: if sections.len() > 1 {
                    sections.to_vec()
                } else {
                    Vec::new()
                },
            },
        ))
    }
}

/// The bone lengths the dance should have: its key poses' (the medians over them), else its
/// seed motion's, else none (the library's own).
fn body_of(req: &GenerateRequest<'_>) -> Option<Vec<f32>> {
    if !req.key_poses.is_empty() {
        let keys =
            ndarray::Array3::from_shape_fn((req.key_poses.len(), NUM_JOINTS, 3), |(k, j, c)| {
                req.key_poses[k].joints.get(j).map_or(0.0, |p| p[c] as f32)
            });
        let centre = ndarray::Array2::zeros((req.key_poses.len(), 3));
        return Some(bone_lengths(keys.view(), centre.view()));
    }
    let seed = req.seed_motion.filter(|m| m.num_frames() > 0)?;
    let centre = crate::motion::skeleton::body_centre_track(seed.positions.view());
    Some(bone_lengths(seed.positions.view(), centre.view()))
}

/// Frames of the longest run of natural successors in `units` (in the source dances' time).
fn longest_copy_frames(lib: &Library, units: &[usize]) -> f64 {
    let (mut best, mut run) = (0.0f64, 0.0f64);
    for (i, &u) in units.iter().enumerate() {
        let follows = i > 0 && lib.units[units[i - 1]].next == Some(u);
        run = if follows { run } else { 0.0 } + lib.units[u].frames();
        best = best.max(run);
    }
    best
}

/// How far a style's bar and beat lie from a song's: the beat's log ratio (at the nearest of
/// half, same and double time) plus 1 where the bars differ.
fn style_distance(p: &StyleProfile, beat_s: f64, meter: usize) -> f64 {
    let tempo = [0.5, 1.0, 2.0]
        .iter()
        .map(|m| (beat_s * m / p.beat_s).ln().abs())
        .fold(f64::INFINITY, f64::min);
    tempo + if p.meter == meter { 0.0 } else { 1.0 }
}

/// The song's bar: the median count of beats between its downbeats (4 when unknown).
pub fn meter_of(analysis: &Analysis) -> usize {
    let beats = &analysis.beat_times;
    let mut counts: Vec<usize> = analysis
        .downbeat_times
        .windows(2)
        .map(|w| {
            beats
                .iter()
                .filter(|&&b| b >= w[0] - 0.02 && b < w[1] - 0.02)
                .count()
        })
        .filter(|&c| (2..=7).contains(&c))
        .collect();
    counts.sort_unstable();
    counts.get(counts.len() / 2).copied().unwrap_or(4)
}

/// The position in a bar of `meter` of each of `times` (consecutive beats or slots, seconds):
/// counted from the slot index, with the one offset that puts the most downbeats on position 0.
/// Counting keeps the positions consistent where the downbeat tracker wavers; a unit and the
/// slot it fills agree on their position only if both are counted this way.
pub fn bar_positions(times: &[f64], downbeats: &[f64], meter: usize) -> Vec<usize> {
    let meter = meter.max(1);
    let mut votes = vec![0usize; meter];
    for (i, &t) in times.iter().enumerate() {
        if downbeats.iter().any(|&d| (d - t).abs() < 0.07) {
            votes[(meter - i % meter) % meter] += 1;
        }
    }
    let offset = (0..meter)
        .max_by_key(|&o| (votes[o], meter - o))
        .unwrap_or(0);
    (0..times.len()).map(|i| (i + offset) % meter).collect()
}

/// The median beat (s) of a list of beat times.
fn median_beat(beats: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = beats
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied()
}

/// The slots the song is cut into, covering `[0, duration]`: its beats, or every other beat
/// when its beat is under 0.7 of the units' (`unit_beat_s`), or half beats when over 1.45 of
/// it; before the first beat and after the last, the nearest beat's length repeated. Returns the
/// slots and the beats a slot spans.
pub fn slots_of(
    analysis: &Analysis,
    duration: f64,
    unit_beat_s: f64,
    unit_meter: usize,
) -> (Vec<Slot>, f64) {
    let beats: Vec<f64> = analysis
        .beat_times
        .iter()
        .copied()
        .filter(|b| b.is_finite() && *b >= 0.0 && *b < duration)
        .collect();
    let Some(beat) = median_beat(&beats).filter(|_| beats.len() >= 4) else {
        // No beat to follow: the units at their own pace.
        let p = unit_beat_s.max(0.2);
        let count = (duration / p).ceil().max(1.0) as usize;
        let slots = (0..count)
            .map(|i| Slot {
                t0: i as f64 * p,
                t1: (i + 1) as f64 * p,
                phase: Some(i % unit_meter.max(1)),
            })
            .collect();
        return (slots, 1.0);
    };
    let ratio = beat / unit_beat_s.max(0.1);
    let (times, per_slot): (Vec<f64>, f64) = if ratio < 0.7 {
        (beats.iter().copied().step_by(2).collect(), 2.0)
    } else if ratio > 1.45 {
        let mut t = Vec::with_capacity(beats.len() * 2);
        for w in beats.windows(2) {
            t.extend([w[0], 0.5 * (w[0] + w[1])]);
        }
        t.extend(beats.last());
        (t, 0.5)
    } else {
        (beats.clone(), 1.0)
    };
    let mut bounds = times.clone();
    let first_len = times[1] - times[0];
    while bounds[0] > 0.0 {
        bounds.insert(0, bounds[0] - first_len);
    }
    let last_len = times[times.len() - 1] - times[times.len() - 2];
    while *bounds.last().unwrap_or(&duration) < duration {
        let t = bounds[bounds.len() - 1] + last_len;
        bounds.push(t);
    }
    let phases = bar_positions(&bounds, &analysis.downbeat_times, unit_meter);
    let slots = bounds
        .windows(2)
        .zip(phases)
        .map(|(w, phase)| Slot {
            t0: w[0],
            t1: w[1],
            phase: Some(phase),
        })
        .collect();
    (slots, per_slot)
}

impl DanceModel for Served {
    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "ChoreoMaster: choreography-oriented music-driven dance synthesis (a motion graph of real dance units on the song's beats)".into(),
            capabilities: Capabilities {
                key_poses: true,
                seed_motion: true,
                style: true,
                temperature: true,
                top_k: false,
            },
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
        progress.report(Stage::Features, 0.0)?;
        let music = req
            .audio
            .features(crate::audio::features::FeatureSet::Keypose, fps, 0.0, n)?;
        let analysis = req.analysis_or_analyze()?;
        progress.report(Stage::Features, 1.0)?;
        let choice = match req.style {
            Some(style) => StyleChoice {
                style,
                predicted: false,
                probabilities: Vec::new(),
            },
            None => {
                let beat = median_beat(&analysis.beat_times).unwrap_or(0.6);
                self.predict_style(beat, meter_of(&analysis))
            }
        };
        let duration = n as f64 / fps;
        let sections = self.sections(&analysis, &choice, duration);
        // The style reported is the one danced longest, not the guess from the median beat that
        // no section may have kept.
        let choice = StyleChoice {
            style: main_style(&sections, duration),
            ..choice
        };
        let (motion, composition) =
            self.compose(req, &analysis, music.view(), &sections, progress)?;
        tracing::debug!(
            ?composition,
            style = choice.style.name(),
            "beat-graph composed"
        );
        let mut generated = Generated::from(motion);
        generated.style = Some(choice);
        generated.composition = Some(composition);
        Ok(generated)
    }
}
