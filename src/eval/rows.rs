//! The rows of `choreo eval`: scored dances grouped into a row (diversity, multimodality, seed
//! distance), and each model's dances, generated once and finished both ways (served: beat-aligned,
//! planted, exported; raw: the network's motion as it came).
use std::path::Path;

use super::songs::{key_poses_of, Song};
use super::{as_served_measured, EvalDance, EvalError, EvalOptions, EvalRow};
use crate::metrics::diversity::diversity;
use crate::metrics::physical::seed_distance_m;
use crate::metrics::reference::ReferenceStats;
use crate::metrics::score::{multimodality, score_dance, score_set, ScoredDance};
use crate::models::{Cancelled, GenerateRequest, Progress};
use crate::motion::dataset::Dance;
use crate::motion::{KeyPose, Motion};

/// A progress sink for the CLI: never cancels.
pub(super) struct Quiet;
impl Progress for Quiet {
    fn report(&mut self, _stage: crate::stage::Stage, _fraction: f32) -> Result<(), Cancelled> {
        Ok(())
    }
}

pub(super) fn crop(m: &Motion, frames: usize) -> Motion {
    let n = frames.min(m.positions.dim().0);
    Motion {
        fps: m.fps,
        positions: m.positions.slice(ndarray::s![..n, .., ..]).to_owned(),
    }
}

/// Mean and smallest of the distances that are numbers (none without any), and the two dances
/// (indices into the row's dances) that are the smallest apart.
fn mean_and_min(
    mut distances: Vec<(f64, usize, usize)>,
) -> (Option<f64>, Option<f64>, Option<(usize, usize)>) {
    distances.retain(|x| !x.0.is_nan());
    let Some(&(min, a, b)) = distances.iter().min_by(|x, y| x.0.total_cmp(&y.0)) else {
        return (None, None, None);
    };
    (
        Some(distances.iter().map(|x| x.0).sum::<f64>() / distances.len() as f64),
        Some(min),
        Some((a, b)),
    )
}

/// A row of scored dances; `per_song` groups the indices of dances of one song (different
/// seeds), with their motions, for multimodality and the seed distance.
pub(super) fn row(
    name: &str,
    scored: Vec<(EvalDance, ScoredDance)>,
    per_song: Option<Vec<Vec<(usize, Motion)>>>,
    reference: &ReferenceStats,
) -> EvalRow {
    let dances: Vec<ScoredDance> = scored.iter().map(|(_, s)| s.clone()).collect();
    let mut scores = score_set(&dances, reference);
    // The paper's diversity measures: dances grouped by song (each dance alone without groups).
    let normed: Vec<Vec<Vec<f64>>> = dances
        .iter()
        .map(|s| {
            s.features
                .kinetic
                .iter()
                .map(|r| reference.kinetic.normalise(r))
                .collect()
        })
        .collect();
    let song_groups: Vec<Vec<usize>> = match &per_song {
        Some(groups) => groups
            .iter()
            .map(|g| g.iter().map(|(i, _)| *i).collect())
            .collect(),
        None => (0..dances.len()).map(|i| vec![i]).collect(),
    };
    let by_song: Vec<Vec<&[Vec<f64>]>> = song_groups
        .iter()
        .map(|g| g.iter().map(|&i| normed[i].as_slice()).collect())
        .collect();
    let diversity_v = diversity(&by_song);
    let (mut multimodality_v, mut seed_mean, mut seed_min) = (None, None, None);
    let (mut song_mean, mut song_min) = (None, None);
    let (mut seed_pair, mut song_pair) = (None, None);
    if let Some(groups) = per_song {
        // The same seed (the same place in each song's group) on every pair of songs.
        let mut per_song_pair = Vec::new();
        for a in 0..groups.len() {
            for b in a + 1..groups.len() {
                for (x, y) in groups[a].iter().zip(&groups[b]) {
                    per_song_pair.push((seed_distance_m(&x.1, &y.1), x.0, y.0));
                }
            }
        }
        (song_mean, song_min, song_pair) = mean_and_min(per_song_pair);
        let g: Vec<Vec<&ScoredDance>> = groups
            .iter()
            .map(|ix| ix.iter().map(|(i, _)| &dances[*i]).collect())
            .collect();
        multimodality_v = multimodality(&g, reference);
        let per_pair: Vec<(f64, usize, usize)> = groups
            .iter()
            .flat_map(|grp| {
                let mut d = Vec::new();
                for a in 0..grp.len() {
                    for b in a + 1..grp.len() {
                        d.push((seed_distance_m(&grp[a].1, &grp[b].1), grp[a].0, grp[b].0));
                    }
                }
                d
            })
            .collect();
        (seed_mean, seed_min, seed_pair) = mean_and_min(per_pair);
        scores.mean.verdict = scores.mean.verdict.clone().with_seed_distance(seed_min);
    }
    let raw: Option<Vec<&crate::metrics::musicality::Musicality>> = scored
        .iter()
        .map(|(e, _)| e.musicality_raw.as_ref())
        .collect();
    let named = |pair: Option<(usize, usize)>| {
        pair.map(|(a, b)| [a, b].map(|i| format!("{} {}", scored[i].0.song, scored[i].0.motion)))
    };
    EvalRow {
        name: name.into(),
        seed_distance_min_between: named(seed_pair),
        song_distance_min_between: named(song_pair),
        musicality_raw: raw
            .filter(|r| !r.is_empty())
            .map(crate::metrics::musicality::MusicalitySummary::of),
        scores,
        multimodality: multimodality_v,
        seed_distance_m: seed_mean,
        seed_distance_min_m: seed_min,
        song_distance_m: song_mean,
        song_distance_min_m: song_min,
        diversity: diversity_v,
        dances: scored.into_iter().map(|(e, _)| e).collect(),
    }
}

/// The rows of one model: as served (beat-aligned, feet planted) and as the network made them, on the test
/// songs and on the extra songs. Each dance is generated once and finished both ways.
pub(super) struct ModelRows {
    pub(super) test: [EvalRow; 2],
    pub(super) extra: Option<[EvalRow; 2]>,
}

/// A model's dances of a list of songs, finished both ways, grouped by song.
#[derive(Default)]
struct Danced {
    scored: [Vec<(EvalDance, ScoredDance)>; 2],
    per_song: [Vec<Vec<(usize, Motion)>>; 2],
}

fn dance_songs(
    model: &dyn crate::models::DanceModel,
    id: &str,
    songs: &[Song],
    keys_of: impl Fn(usize) -> Vec<KeyPose>,
    args: &EvalOptions,
    reference: &ReferenceStats,
) -> Result<Danced, EvalError> {
    let mut out = Danced::default();
    for (i, s) in songs.iter().enumerate() {
        let keys = keys_of(i);
        let mut groups: [Vec<(usize, Motion)>; 2] = Default::default();
        for seed in args.seed..args.seed + args.seeds.max(1) {
            let req = GenerateRequest {
                key_poses: &keys,
                ..GenerateRequest::plain(&s.audio, seed)
            };
            let (raw, composed) = super::generate(model, id, &s.name, &req, &mut Quiet)?;
            // The motion stage every job runs (feet planted), and the network's motion as it came.
            // Served: planted and exported through the rigid skeleton, as motion.json holds it.
            // Served: beat-aligned, planted and exported through the rigid skeleton.
            let (served, aligned, flips) =
                as_served_measured(raw.clone(), composed, &keys, &s.beats).map_err(|source| {
                    EvalError::Export {
                        model: id.into(),
                        song: s.name.clone(),
                        source,
                    }
                })?;
            let finished = [served, crate::motion::finish(raw, false)];
            let mut scored = [
                score_dance(&finished[0], &s.beats, &keys, reference)?,
                score_dance(&finished[1], &s.beats, &keys, reference)?,
            ];
            if let Some(dir) = &args.previews {
                let m = &scored[0].scores.musicality;
                write_preview(dir, id, s, seed, &finished[0], &keys, m)?;
            }
            scored[0].scores.rotation_flips = Some(flips);
            // Both rows keep the network's own musicality beside their own.
            let raw_musicality = scored[1].scores.musicality;
            for (v, (m, sc)) in finished.into_iter().zip(scored).enumerate() {
                let e = EvalDance {
                    song: s.name.clone(),
                    motion: format!("{id}@{seed}"),
                    seconds: m.duration_s(),
                    scores: sc.scores.clone(),
                    musicality_raw: Some(raw_musicality),
                    beat_align: (v == 0).then(|| aligned.clone()),
                };
                groups[v].push((out.scored[v].len(), m));
                out.scored[v].push((e, sc));
            }
        }
        for (v, g) in groups.into_iter().enumerate() {
            out.per_song[v].push(g);
        }
    }
    Ok(out)
}

/// Names of the two rows of a model.
fn row_names(base: &str) -> [String; 2] {
    [
        base.to_string(),
        format!("{base} (raw network output, feet not planted)"),
    ]
}

fn rows_of(d: Danced, names: &[String; 2], reference: &ReferenceStats) -> [EvalRow; 2] {
    let Danced {
        scored: [s0, s1],
        per_song: [g0, g1],
    } = d;
    [
        row(&names[0], s0, Some(g0), reference),
        row(&names[1], s1, Some(g1), reference),
    ]
}

pub(super) fn model_rows(
    model: &dyn crate::models::DanceModel,
    id: &str,
    test: (&[Song], &[Dance]),
    extra: &[Song],
    args: &EvalOptions,
    reference: &ReferenceStats,
) -> Result<ModelRows, EvalError> {
    let keyed = args.key_poses > 0 && model.info().capabilities.key_poses;
    let (songs, dances) = test;
    let keys_of = |i: usize| {
        if keyed {
            key_poses_of(&dances[i], args.key_poses, args.seed + i as u64)
        } else {
            Vec::new()
        }
    };
    let base = if keyed {
        format!("{id} + {} key poses", args.key_poses)
    } else {
        id.to_string()
    };
    let test_rows = rows_of(
        dance_songs(model, id, songs, keys_of, args, reference)?,
        &row_names(&base),
        reference,
    );
    let extra_rows = if extra.is_empty() {
        None
    } else {
        Some(rows_of(
            dance_songs(model, id, extra, |_| Vec::new(), args, reference)?,
            &row_names(id),
            reference,
        ))
    };
    Ok(ModelRows {
        test: test_rows,
        extra: extra_rows,
    })
}

/// Writes the contact sheet of `model`'s dance to `song` with `seed` into `dir`.
pub(super) fn write_preview(
    dir: &Path,
    model: &str,
    song: &Song,
    seed: u64,
    motion: &Motion,
    keys: &[KeyPose],
    musicality: &crate::metrics::musicality::Musicality,
) -> Result<(), EvalError> {
    use crate::report::preview::{write_png, Caption, Sheet};
    let stem = song
        .name
        .rsplit_once('.')
        .map_or(song.name.as_str(), |(stem, _)| stem);
    let name: String = format!("{model}_{stem}_seed{seed}.png")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    std::fs::create_dir_all(dir).map_err(|source| EvalError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let caption = Caption {
        model: model.to_string(),
        seed,
        song: Some(song.name.clone()),
        style: None,
    };
    let key_pose_times: Vec<f64> = keys.iter().map(|k| k.time_s).collect();
    let sheet = Sheet {
        motion,
        beat_times: &song.beats,
        key_pose_times: &key_pose_times,
        song_duration_s: song.audio.duration_s,
        caption: &caption,
        musicality,
    };
    let path = dir.join(name);
    write_png(&path, &sheet).map_err(|source| EvalError::Preview { path, source })
}
