//! Every metric of one dance, and of a set of dances (a row of `choreo eval`).
use super::beats::{
    beats_within, kinematic_beats_bailando, kinematic_beats_fact, rhythm_scores, RhythmScores,
};
use super::fid::{frechet_distance, mean_pairwise_distance, Gaussian};
use super::kinematics::{
    foot_skating, freezing, key_pose_errors_cm, smoothness_cv, FootSkating, Freezing,
};
use super::musicality::{Musicality, MusicalitySummary};
use super::physical::{physical_series, verdict, PhysicalScores, PhysicalSeries, Verdict};
use super::plausibility::{plausibility, Plausibility};
use super::reference::{
    dance_features, geometric_windows, kinetic_windows, FeatureStats, ReferenceStats,
    CURVE_WINDOW_S,
};
use super::rotation_flips::RotationFlips;
use super::MetricsError;
use crate::motion::{skeleton as sk, KeyPose, Motion, NUM_JOINTS};

/// The raw window features of one dance (5-s windows every 1 s).
#[derive(Clone, Debug, Default)]
pub struct WindowFeatures {
    pub kinetic: Vec<Vec<f64>>,
    pub geometric: Vec<Vec<f64>>,
    /// The whole dance's kinetic features (one vector, Bailando's protocol).
    pub kinetic_dance: Vec<f64>,
    /// The whole dance's geometric features.
    pub geometric_dance: Vec<f64>,
}

/// Kinematic beat times (seconds from the first frame).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct KinematicBeats {
    /// FACT variant: minima of summed joint speed, order 10 at 60 fps scaled.
    pub fact: Vec<f64>,
    /// Bailando variant: minima of Gaussian-smoothed (σ = 5 frames at 60 fps) mean joint speed.
    pub bailando: Vec<f64>,
}

/// Every per-dance number.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct DanceScores {
    pub rhythm: RhythmScores,
    /// FID_k of this dance's 5-s windows against the real train windows.
    pub fid_k: f64,
    /// FID_g, likewise with geometric features.
    pub fid_g: f64,
    /// Div_k: mean pairwise distance of this dance's z-normalised kinetic windows.
    pub div_k: f64,
    /// Div_g: likewise with geometric features.
    pub div_g: f64,
    /// Smoothness S_cv (lower is smoother).
    pub smoothness_cv: f64,
    pub foot_skating: FootSkating,
    /// Motion energy in the last 30 s over the first 30 s.
    pub freezing_ratio: f64,
    pub plausibility: Plausibility,
    /// Key-pose consistency error (cm), when key poses were given.
    pub key_pose_error_cm: Option<f64>,
    /// Floor contact, ground penetration, pops and speed ([`super::physical`]).
    pub physical: PhysicalScores,
    /// The plausibility thresholds applied (the seed criterion only where two seeds are compared).
    pub verdict: Verdict,
    /// Does it go with this song: tempo lock, arm liveliness, knee direction
    /// ([`super::musicality`]).
    #[serde(default)]
    pub musicality: Musicality,
    /// Frame steps on which an exported joint's rotation turns past 60° / 90°
    /// ([`super::rotation_flips`]): filled in where the dance went through the rig (the report,
    /// `choreo eval`'s served and real rows), absent for positions alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_flips: Option<RotationFlips>,
}

/// One dance scored, with the series a report plots and the features a set-level FID pools.
#[derive(Clone, Debug)]
pub struct ScoredDance {
    pub scores: DanceScores,
    /// Music beats within the dance's span (seconds from the first frame).
    pub music_beats: Vec<f64>,
    pub kinematic_beats: KinematicBeats,
    pub freezing: Freezing,
    pub features: WindowFeatures,
    /// The per-frame series behind `scores.physical`, for pooling a set.
    pub physical: PhysicalSeries,
}

fn check(motion: &Motion) -> Result<(), MetricsError> {
    let dim = motion.positions.dim();
    if dim.1 != NUM_JOINTS || dim.2 != 3 {
        return Err(MetricsError::JointCount {
            got: dim.1,
            want: NUM_JOINTS,
        });
    }
    if dim.0 < 2 || !(motion.fps.is_finite() && motion.fps > 0.0) {
        return Err(MetricsError::NotEnoughData(format!(
            "{} frames at {} fps",
            dim.0, motion.fps
        )));
    }
    if motion.positions.iter().any(|v| !v.is_finite()) {
        return Err(MetricsError::NotEnoughData("non-finite positions".into()));
    }
    Ok(())
}

/// FID of raw window features against the real statistics (`NaN` without windows).
pub fn fid_against(stats: &FeatureStats, raw: &[Vec<f64>]) -> f64 {
    let normed: Vec<Vec<f64>> = raw.iter().map(|r| stats.normalise(r)).collect();
    match Gaussian::fit(&normed) {
        Some(g) => frechet_distance(&g, &stats.gaussian),
        None => f64::NAN,
    }
}

/// Mean pairwise distance of z-normalised window features.
pub fn diversity(stats: &FeatureStats, raw: &[Vec<f64>]) -> f64 {
    let normed: Vec<Vec<f64>> = raw.iter().map(|r| stats.normalise(r)).collect();
    mean_pairwise_distance(&normed)
}

/// Scores one dance. `music_beats` are on the dance's clock (motion frame 0 at 0 s); beats outside
/// the dance are ignored.
pub fn score_dance(
    motion: &Motion,
    music_beats: &[f64],
    key_poses: &[KeyPose],
    reference: &ReferenceStats,
) -> Result<ScoredDance, MetricsError> {
    check(motion)?;
    let p = motion.positions.view();
    let fps = motion.fps;
    let span = (p.dim().0 - 1) as f64 / fps;
    let music = beats_within(music_beats, span);
    let kb = KinematicBeats {
        fact: kinematic_beats_fact(p, fps),
        bailando: kinematic_beats_bailando(p, fps),
    };
    let (kinetic_dance, geometric_dance) = dance_features(motion, &reference.body_scale);
    let features = WindowFeatures {
        kinetic: kinetic_windows(
            motion,
            reference.kinetic.window_s,
            reference.kinetic.stride_s,
        ),
        geometric: geometric_windows(
            motion,
            &reference.body_scale,
            reference.geometric.window_s,
            reference.geometric.stride_s,
        ),
        kinetic_dance,
        geometric_dance,
    };
    let fr = freezing(p, fps);
    let series = physical_series(motion, key_poses);
    let physical = series.scores(reference.physical.pooled.mean_speed_m_s);
    let key_errors = key_pose_errors_cm(p, fps, key_poses);
    let scores = DanceScores {
        rhythm: rhythm_scores(&music, &kb.fact, &kb.bailando, span),
        fid_k: fid_against(&reference.kinetic, &features.kinetic),
        fid_g: fid_against(&reference.geometric, &features.geometric),
        div_k: diversity(&reference.kinetic, &features.kinetic),
        div_g: diversity(&reference.geometric, &features.geometric),
        smoothness_cv: smoothness_cv(p, fps),
        foot_skating: foot_skating(p, fps, &sk::FOOT_POINTS),
        freezing_ratio: fr.last_first_ratio,
        plausibility: plausibility(p, fps, &reference.angle_limits),
        key_pose_error_cm: if key_errors.is_empty() {
            None
        } else {
            Some(key_errors.iter().sum::<f64>() / key_errors.len() as f64)
        },
        verdict: verdict(&physical, &key_errors, None),
        physical,
        musicality: Musicality::of(motion, &music),
        rotation_flips: None,
    };
    Ok(ScoredDance {
        scores,
        music_beats: music,
        kinematic_beats: kb,
        freezing: fr,
        features,
        physical: series,
    })
}

/// One point of the windowed FID_k curve.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct CurvePoint {
    pub start_s: f64,
    pub end_s: f64,
    pub fid_k: f64,
}

/// FID_k over consecutive 4-s windows (DanceRevolution Fig. 4). Each window is one feature
/// vector, a Gaussian with zero covariance, so a point is `|x − μ_real|² + tr Σ_real`: the
/// constant `tr Σ_real` (≈ the feature count, as features are z-normalised) is the floor, and
/// the distance above it shows where a long dance drifts from real motion.
pub fn fid_k_curve(motion: &Motion, reference: &ReferenceStats) -> Vec<CurvePoint> {
    let stats = &reference.kinetic_curve;
    let len = (CURVE_WINDOW_S * motion.fps).round() as usize;
    let t = motion.positions.dim().0;
    let mut out = Vec::new();
    let mut s0 = 0;
    while s0 + len <= t {
        let clip = Motion {
            fps: motion.fps,
            positions: motion
                .positions
                .slice(ndarray::s![s0..s0 + len, .., ..])
                .to_owned(),
        };
        let raw = kinetic_windows(&clip, CURVE_WINDOW_S, CURVE_WINDOW_S);
        out.push(CurvePoint {
            start_s: s0 as f64 / motion.fps,
            end_s: (s0 + len) as f64 / motion.fps,
            fid_k: fid_against(stats, &raw),
        });
        s0 += len;
    }
    out
}

/// Means of the per-dance scores over a set, with FID and diversity recomputed on the pooled
/// windows of the whole set (the way papers report a model), FID also on one vector per dance
/// (Bailando's protocol), and the physical numbers on every frame of the set pooled.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct SetScores {
    /// Dances in the set.
    pub dances: usize,
    /// Per-dance scores averaged (their `fid_*`/`div_*` are per-dance means), except `physical`
    /// (every frame of the set pooled) and `verdict` (each criterion as the worst dance has it).
    pub mean: DanceScores,
    /// FID_k of all 5-s windows of the set pooled.
    pub fid_k_window: f64,
    /// FID_g of all windows pooled.
    pub fid_g_window: f64,
    /// FID_k of one whole-dance kinetic vector per dance against the train dances' (Bailando's
    /// protocol; few dances give a singular covariance, so compare sets of similar size).
    pub fid_k_dance: f64,
    /// FID_g likewise with whole-dance geometric vectors.
    pub fid_g_dance: f64,
    /// Dances whose own verdict passes.
    pub dances_passing: usize,
    /// Div_k over all windows pooled.
    pub div_k: f64,
    /// Div_g over all windows pooled.
    pub div_g: f64,
    /// The musicality bars on the set: tempo-locked share, stillest arms, worst knees.
    #[serde(default)]
    pub musicality: MusicalitySummary,
}

fn mean_of(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Aggregates scored dances into set scores.
pub fn score_set(dances: &[ScoredDance], reference: &ReferenceStats) -> SetScores {
    let d = || dances.iter().map(|s| &s.scores);
    let r = || d().map(|s| &s.rhythm);
    let kin: Vec<Vec<f64>> = dances
        .iter()
        .flat_map(|s| s.features.kinetic.iter().cloned())
        .collect();
    let geo: Vec<Vec<f64>> = dances
        .iter()
        .flat_map(|s| s.features.geometric.iter().cloned())
        .collect();
    let kp: Vec<f64> = d().filter_map(|s| s.key_pose_error_cm).collect();
    let mean = DanceScores {
        rhythm: RhythmScores {
            bas_fact: mean_of(r().map(|x| x.bas_fact)),
            bas_bailando: mean_of(r().map(|x| x.bas_bailando)),
            bas_fact_chance: mean_of(r().map(|x| x.bas_fact_chance)),
            beat_coverage: mean_of(r().map(|x| x.beat_coverage)),
            beat_hit_rate: mean_of(r().map(|x| x.beat_hit_rate)),
            rhythm_hit: mean_of(r().map(|x| x.rhythm_hit)),
            f_measure: mean_of(r().map(|x| x.f_measure)),
            cemgil: mean_of(r().map(|x| x.cemgil)),
            p_score: mean_of(r().map(|x| x.p_score)),
            beat_prf: super::beats::BeatPrf {
                precision: mean_of(r().map(|x| x.beat_prf.precision)),
                recall: mean_of(r().map(|x| x.beat_prf.recall)),
                f: mean_of(r().map(|x| x.beat_prf.f)),
            },
        },
        fid_k: mean_of(d().map(|s| s.fid_k)),
        fid_g: mean_of(d().map(|s| s.fid_g)),
        div_k: mean_of(d().map(|s| s.div_k)),
        div_g: mean_of(d().map(|s| s.div_g)),
        smoothness_cv: mean_of(d().map(|s| s.smoothness_cv)),
        foot_skating: FootSkating {
            contact_share: mean_of(d().map(|s| s.foot_skating.contact_share)),
            skate_ratio: mean_of(d().map(|s| s.foot_skating.skate_ratio)),
            mean_contact_speed_m_s: mean_of(d().map(|s| s.foot_skating.mean_contact_speed_m_s)),
        },
        freezing_ratio: mean_of(d().map(|s| s.freezing_ratio)),
        plausibility: Plausibility {
            authenticity: mean_of(d().map(|s| s.plausibility.authenticity)),
            coherence: mean_of(d().map(|s| s.plausibility.coherence)),
        },
        key_pose_error_cm: if kp.is_empty() {
            None
        } else {
            Some(mean_of(kp.into_iter()))
        },
        physical: PhysicalSeries::pooled(dances.iter().map(|s| &s.physical))
            .scores(reference.physical.pooled.mean_speed_m_s),
        verdict: Verdict::worst(d().map(|s| &s.verdict)),
        musicality: MusicalitySummary::mean(d().map(|s| &s.musicality)),
        rotation_flips: {
            let measured: Vec<&RotationFlips> =
                d().filter_map(|s| s.rotation_flips.as_ref()).collect();
            (!measured.is_empty()).then(|| RotationFlips::pooled(measured.into_iter()))
        },
    };
    let kin_dance: Vec<Vec<f64>> = dances
        .iter()
        .map(|s| s.features.kinetic_dance.clone())
        .collect();
    let geo_dance: Vec<Vec<f64>> = dances
        .iter()
        .map(|s| s.features.geometric_dance.clone())
        .collect();
    SetScores {
        dances: dances.len(),
        mean,
        fid_k_window: fid_against(&reference.kinetic, &kin),
        fid_g_window: fid_against(&reference.geometric, &geo),
        fid_k_dance: fid_against(&reference.kinetic_dance, &kin_dance),
        fid_g_dance: fid_against(&reference.geometric_dance, &geo_dance),
        dances_passing: d().filter(|s| s.verdict.pass).count(),
        div_k: diversity(&reference.kinetic, &kin),
        div_g: diversity(&reference.geometric, &geo),
        musicality: MusicalitySummary::of(d().map(|s| &s.musicality)),
    }
}

/// Multimodality: for each song, the mean pairwise distance between the mean z-normalised kinetic
/// features of dances generated with different seeds; averaged over songs with ≥ 2 dances.
pub fn multimodality(per_song: &[Vec<&ScoredDance>], reference: &ReferenceStats) -> Option<f64> {
    let vals: Vec<f64> = per_song
        .iter()
        .filter(|v| v.len() >= 2)
        .map(|v| {
            let means: Vec<Vec<f64>> = v
                .iter()
                .filter_map(|s| {
                    let normed: Vec<Vec<f64>> = s
                        .features
                        .kinetic
                        .iter()
                        .map(|r| reference.kinetic.normalise(r))
                        .collect();
                    Gaussian::fit(&normed).map(|g| g.mean)
                })
                .collect();
            mean_pairwise_distance(&means)
        })
        .collect();
    if vals.is_empty() {
        None
    } else {
        Some(mean_of(vals.into_iter()))
    }
}
