//! `choreo train beat-graph`: the unit library, its motion graph and the music match, built from
//! the train split in a few minutes (no gradient descent), and the match's ranking checked on the
//! test split's (beat, unit) pairs.
use std::time::Instant;

use ndarray::Array2;

use super::{CommonOptions, TrainError};
use crate::audio::Analysis;
use crate::models::beat_graph::body::{bone_lengths, rebone};
use crate::models::beat_graph::library::{style_counts, Library, Unit};
use crate::models::beat_graph::rhythm::{motion_descriptors, music_descriptors, Match, MUSIC_DIM};
use crate::models::beat_graph::served::{
    bar_positions, LibraryRecord, MatchCheck, ModelFile, StyleProfile, ID,
};
use crate::models::beat_graph::Config;
use crate::models::folder::{MODEL_FILE, WEIGHTS_FILE};
use crate::models::DanceStyle;
use crate::motion::dataset::{Dataset, Fold};
use crate::motion::{MOTION_FPS, NUM_JOINTS};

/// The build's options.
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    /// Ridge penalty of the music match (per pair).
    pub ridge: f64,
    /// Edges per unit in the graph ([`Config::graph_degree`]).
    pub graph_degree: usize,
    /// Leave fold `K/N` of the train dances out of the library ([`Fold`]), so that settings can
    /// be chosen on dances the library lacks (`choreo eval --split train --hold-out K/N`)
    /// rather than on the test split.
    pub hold_out: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            ridge: 0.05,
            graph_degree: Config::default().graph_degree,
            hold_out: None,
        }
    }
}

/// A shortest and longest beat a unit may have (s): outside, the tracker missed or split a beat.
const BEAT_RANGE_S: (f64, f64) = (0.25, 1.5);

/// A beat shorter than this (s; over 143 BPM) is taken for half of the dancer's beat.
const DOUBLE_TIME_BEAT_S: f64 = 0.42;

fn median_beat_s(beats: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = beats.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied()
}

/// One dance cut at its song's beats: its feature rows, its units (dance index and successor
/// links relative to this dance), and each unit's music.
struct Cut {
    rows: Array2<f32>,
    units: Vec<Unit>,
    music: Array2<f32>,
}

fn cut(
    ds: &Dataset,
    id: &str,
    dance: usize,
    lengths: Option<&[f32]>,
) -> Result<(Cut, Analysis), TrainError> {
    let mut d = ds.load(id)?;
    if let Some(lengths) = lengths {
        rebone(&mut d.motion.positions, d.center.view(), lengths, true);
    }
    let audio = crate::audio::decode_path(&d.audio_path)?;
    let analysis = crate::audio::analyze(&audio)?;
    let fps = MOTION_FPS;
    let song_frames = crate::motion::validate::song_frames(audio.duration_s, fps);
    let feats = crate::audio::features::keypose(&audio, fps, 0.0, song_frames)?;
    let (rows, _) = crate::motion::repr::to_features(d.motion.positions.view(), d.center.view())?;
    let t = rows.nrows() as f64;
    let style = DanceStyle::of_dance_id(id)
        .ok_or_else(|| TrainError::InvalidOption(format!("{id}: no style letter")))?;
    // The style's bar, not the tracker's guess (it hears some waltzes in four): a waltz is in
    // three, the others in four.
    let meter = if style == DanceStyle::Waltz { 3 } else { 4 };
    let start = f64::from(d.start_position);
    // A tracker that hears a waltz or a rumba at twice its tempo (172 BPM for 86) makes a
    // "beat" of half a step: every other beat is the dancer's.
    let beats: Vec<f64> = match median_beat_s(&analysis.beat_times) {
        Some(b) if b < DOUBLE_TIME_BEAT_S => {
            analysis.beat_times.iter().copied().step_by(2).collect()
        }
        _ => analysis.beat_times.clone(),
    };
    let beats = &beats;
    let positions = bar_positions(beats, &analysis.downbeat_times, meter);
    let mut units = Vec::new();
    let mut spans = Vec::new();
    for (k, w) in beats.windows(2).enumerate() {
        let (a, b) = (w[0] * fps - start, w[1] * fps - start);
        let len_s = w[1] - w[0];
        if a < 1.0 || b > t - 2.0 || !(BEAT_RANGE_S.0..=BEAT_RANGE_S.1).contains(&len_s) {
            continue;
        }
        let follows = units
            .last()
            .is_some_and(|u: &Unit| (u.end - a).abs() < 1e-9);
        if follows {
            let i = units.len();
            if let Some(prev) = units.last_mut() {
                prev.next = Some(i);
            }
        }
        units.push(Unit {
            dance,
            start: a,
            end: b,
            phase: positions[k],
            meter,
            style,
            next: None,
        });
        spans.push((w[0], w[1]));
    }
    let music = music_descriptors(feats.view(), fps, &spans);
    tracing::info!(dance = %id, units = units.len(), meter, tempo = analysis.tempo_bpm, "cut");
    Ok((Cut { rows, units, music }, analysis))
}

/// The ankles' mean speed about the body over a unit (m/frame): where in its beats a dancer steps.
fn ankle_activity(lib: &Library, u: &Unit) -> f64 {
    const ANKLES: [usize; 2] = [9, 18];
    let x = lib.dance(u.dance);
    let (a, b) = (
        u.start.floor() as usize,
        (u.end.ceil() as usize).min(x.nrows() - 1),
    );
    let mut sum = 0.0;
    for f in a + 1..=b {
        for j in ANKLES {
            sum += (0..3)
                .map(|k| f64::from(x[[f, 3 * j + k]] - x[[f - 1, 3 * j + k]]).powi(2))
                .sum::<f64>()
                .sqrt();
        }
    }
    sum / (b - a).max(1) as f64
}

/// Puts every dance's bar positions in step with the other dances of its style, by the motion:
/// the positions come from each training song's tracked downbeats, and where the tracker put one
/// song's downbeat a beat early the dancer's steps fall on the other beats of the bar. Joining
/// such dancers by bar position flips the step pattern at each join (a composed cha-cha then
/// stepped at 0.53–0.58 of the beat rate, not 1/2). Each dance's profile of ankle activity over
/// the bar is rolled to agree best with its style's mean profile (three rounds, starting from the
/// style's longest dance).
fn align_steps(lib: &mut Library) {
    let dances = lib.dance_first.len() - 1;
    let mut profiles: Vec<Vec<f64>> = vec![Vec::new(); dances];
    for (d, profile) in profiles.iter_mut().enumerate() {
        let of: Vec<&Unit> = lib.units.iter().filter(|u| u.dance == d).collect();
        let Some(meter) = of.first().map(|u| u.meter) else {
            continue;
        };
        let mut p = vec![0.0; meter];
        let mut n = vec![0usize; meter];
        for u in &of {
            p[u.phase % meter] += ankle_activity(lib, u);
            n[u.phase % meter] += 1;
        }
        let mean = p.iter().sum::<f64>() / of.len().max(1) as f64;
        *profile = (0..meter)
            .map(|k| p[k] / n[k].max(1) as f64 / mean.max(1e-9) - 1.0)
            .collect();
    }
    let mut shift = vec![0usize; dances];
    for style in DanceStyle::ALL {
        let members: Vec<usize> = (0..dances)
            .filter(|&d| lib.units.iter().any(|u| u.dance == d && u.style == style))
            .filter(|&d| !profiles[d].is_empty())
            .collect();
        let Some(&longest) = members
            .iter()
            .max_by_key(|&&d| lib.dance_first[d + 1] - lib.dance_first[d])
        else {
            continue;
        };
        let meter = profiles[longest].len();
        let rolled = |d: usize, s: usize| -> Vec<f64> {
            (0..meter).map(|k| profiles[d][(k + s) % meter]).collect()
        };
        let mut reference = profiles[longest].clone();
        for _ in 0..3 {
            for &d in &members {
                if profiles[d].len() != meter {
                    continue;
                }
                shift[d] = (0..meter)
                    .max_by(|&a, &b| {
                        let dot = |s: usize| -> f64 {
                            rolled(d, s)
                                .iter()
                                .zip(&reference)
                                .map(|(x, y)| x * y)
                                .sum()
                        };
                        dot(a).total_cmp(&dot(b))
                    })
                    .unwrap_or(0);
            }
            reference = (0..meter)
                .map(|k| {
                    members.iter().map(|&d| rolled(d, shift[d])[k]).sum::<f64>()
                        / members.len() as f64
                })
                .collect();
        }
        tracing::info!(
            style = style.name(),
            ?reference,
            "bar profile of ankle activity"
        );
    }
    for u in &mut lib.units {
        // Rolling a profile by s reads position k from k + s: the unit at k + s becomes k.
        u.phase = (u.phase + u.meter - shift[u.dance] % u.meter) % u.meter;
    }
}

/// Share of `others` whose cost exceeds the true unit's (ties count half).
fn auc(
    matcher: &Match,
    pred: ndarray::ArrayView1<'_, f32>,
    truth: ndarray::ArrayView1<'_, f32>,
    others: &[ndarray::ArrayView1<'_, f32>],
) -> f64 {
    let c = matcher.cost(pred, truth);
    let wins: f64 = others
        .iter()
        .map(|o| {
            let d = matcher.cost(pred, *o);
            if d > c {
                1.0
            } else if d == c {
                0.5
            } else {
                0.0
            }
        })
        .sum();
    wins / others.len().max(1) as f64
}

/// The two rankings of [`MatchCheck`] over the pairs of `cuts` (their motion descriptors
/// `motion`, rows in cut order), against the library's descriptors `library`.
fn rankings(
    matcher: &Match,
    music: &Array2<f32>,
    motion: &Array2<f32>,
    dance_of: &[usize],
    library: &Array2<f32>,
) -> (f64, f64, usize) {
    let pred = matcher.predict(music);
    let n = motion.nrows();
    // Every 7th library unit: a fixed sample of a few hundred.
    let lib_rows: Vec<_> = (0..library.nrows())
        .step_by(7)
        .map(|i| library.row(i))
        .collect();
    let (mut a_lib, mut a_same) = (0.0, 0.0);
    for i in 0..n {
        a_lib += auc(matcher, pred.row(i), motion.row(i), &lib_rows);
        let same: Vec<_> = (0..n)
            .filter(|&j| j != i && dance_of[j] == dance_of[i])
            .map(|j| motion.row(j))
            .collect();
        a_same += auc(matcher, pred.row(i), motion.row(i), &same);
    }
    let n_f = n.max(1) as f64;
    (a_lib / n_f, a_same / n_f, n)
}

fn stack(rows: &[Array2<f32>], width: usize) -> Array2<f32> {
    let total: usize = rows.iter().map(Array2::nrows).sum();
    let mut out = Array2::zeros((total, width));
    let mut at = 0;
    for r in rows {
        out.slice_mut(ndarray::s![at..at + r.nrows(), ..]).assign(r);
        at += r.nrows();
    }
    out
}

/// Builds the library from the train split, checks the match on the test split, and writes
/// `model.json` and `weights.safetensors` into the model folder.
pub fn train(o: &Options) -> Result<ModelFile, TrainError> {
    let started = Instant::now();
    let fps = MOTION_FPS;
    let ds = Dataset::open(&o.common.data)?;
    let fold = o.hold_out.as_deref().map(Fold::parse).transpose()?;
    let train_ids: Vec<String> = match fold {
        Some(f) => ds
            .train_ids()
            .iter()
            .zip(f.holds_ids(ds.train_ids()))
            .filter(|(_, held)| !held)
            .map(|(id, _)| id.clone())
            .collect(),
        None => ds.train_ids().to_vec(),
    };
    // One skeleton for every unit: each bone at the median of the train dances' own medians.
    let mut per_dance = Vec::new();
    for id in &train_ids {
        let d = ds.load(id)?;
        per_dance.push(bone_lengths(d.motion.positions.view(), d.center.view()));
    }
    let lengths: Vec<f32> = (0..NUM_JOINTS)
        .map(|j| {
            let mut l: Vec<f32> = per_dance.iter().map(|b| b[j]).collect();
            l.sort_by(f32::total_cmp);
            l[l.len() / 2]
        })
        .collect();
    let mut cuts = Vec::new();
    for (d, id) in train_ids.iter().enumerate() {
        cuts.push(cut(&ds, id, d, Some(&lengths))?.0);
    }
    let mut units = Vec::new();
    let mut dance_first = vec![0];
    for c in &cuts {
        let offset = units.len();
        units.extend(c.units.iter().cloned().map(|mut u| {
            u.next = u.next.map(|n| n + offset);
            u
        }));
        dance_first.push(dance_first.last().copied().unwrap_or(0) + c.rows.nrows());
    }
    let frames = stack(
        &cuts.iter().map(|c| c.rows.clone()).collect::<Vec<_>>(),
        crate::motion::repr::FEATURE_DIM,
    );
    let music = stack(
        &cuts.iter().map(|c| c.music.clone()).collect::<Vec<_>>(),
        MUSIC_DIM,
    );
    let mut lib = Library {
        frames,
        dance_first,
        units,
        motion: Array2::zeros((0, 0)),
        graph: Vec::new(),
    };
    align_steps(&mut lib);
    lib.motion = motion_descriptors(
        lib.units
            .iter()
            .map(|u| (lib.dance(u.dance), u.start, u.end)),
        fps,
    );
    let matcher = Match::fit(&music, &lib.motion, o.ridge);
    lib.build_graph(o.graph_degree, fps)?;
    let train_dance: Vec<usize> = lib.units.iter().map(|u| u.dance).collect();
    let (train_lib, train_same, _) =
        rankings(&matcher, &music, &lib.motion, &train_dance, &lib.motion);
    // The held-out pairs: the test split cut the same way, never used above.
    let mut test_music = Vec::new();
    let mut test_motion = Vec::new();
    let mut test_dance = Vec::new();
    for (d, id) in ds.test_ids().iter().enumerate() {
        let (c, _) = cut(&ds, id, d, None)?;
        test_motion.push(motion_descriptors(
            c.units.iter().map(|u| (c.rows.view(), u.start, u.end)),
            fps,
        ));
        test_dance.extend(std::iter::repeat_n(d, c.units.len()));
        test_music.push(c.music);
    }
    let test_music = stack(&test_music, MUSIC_DIM);
    let test_motion = stack(&test_motion, crate::models::beat_graph::rhythm::MOTION_DIM);
    let (auc_library, auc_same_dance, pairs) = rankings(
        &matcher,
        &test_music,
        &test_motion,
        &test_dance,
        &lib.motion,
    );
    let counts = style_counts(&lib.units);
    let styles = DanceStyle::ALL
        .iter()
        .map(|&style| {
            let of: Vec<&Unit> = lib.units.iter().filter(|u| u.style == style).collect();
            let median = |mut v: Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v.get(v.len() / 2).copied().unwrap_or(0.0)
            };
            let mut dances: Vec<usize> = of.iter().map(|u| u.dance).collect();
            dances.sort_unstable();
            dances.dedup();
            StyleProfile {
                style,
                meter: median(of.iter().map(|u| u.meter as f64).collect())
                    .round()
                    .max(1.0) as usize,
                beat_s: median(of.iter().map(|u| u.frames() / fps).collect()),
                units: counts[style.index()],
                dances: dances.len(),
            }
        })
        .collect();
    let config = Config {
        graph_degree: o.graph_degree,
        ..Config::default()
    };
    let file = ModelFile {
        config,
        fps,
        matcher,
        styles,
        library: LibraryRecord {
            dances: train_ids.clone(),
            units: lib.units.len(),
            frames: lib.frames.nrows(),
            made_by: format!(
                "choreo train beat-graph --ridge {} --graph-degree {}{}: every train dance cut at its song's beats (audio::analyze), units of {:.2}–{:.2} s",
                o.ridge,
                o.graph_degree,
                fold.map(|f| format!(" --hold-out {f}")).unwrap_or_default(),
                BEAT_RANGE_S.0, BEAT_RANGE_S.1
            ),
            seconds: started.elapsed().as_secs_f64(),
        },
        held_out: MatchCheck {
            pairs,
            auc_library,
            auc_same_dance,
            train_auc_library: train_lib,
            train_auc_same_dance: train_same,
        },
    };
    let out = o.common.out_dir(ID);
    std::fs::create_dir_all(&out).map_err(|source| TrainError::Io {
        path: out.clone(),
        source,
    })?;
    lib.save(&out.join(WEIGHTS_FILE))?;
    let path = out.join(MODEL_FILE);
    let json = serde_json::to_string_pretty(&file)?;
    std::fs::write(&path, json + "\n").map_err(|source| TrainError::Io { path, source })?;
    tracing::info!(
        units = lib.units.len(),
        auc_library,
        auc_same_dance,
        seconds = started.elapsed().as_secs_f64(),
        "beat-graph built"
    );
    Ok(file)
}
