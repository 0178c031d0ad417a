//! Reference statistics of the real train dances: the z-normalisation and Gaussians FID compares
//! against, the body scale of the geometric thresholds, and the plausibility limits.
//!
//! FID comes in two protocols, kept apart by name: windows (5-s windows every 1 s, pooled; our
//! `fid_*_window`) and whole dances (one feature vector per dance, Bailando's `fid_*_dance`).
//!
//! Committed as `src/metrics/reference_train.json` and compiled in ([`ReferenceStats::builtin`]);
//! regenerate with `choreo eval --write-reference` (train split only, never the test split).
use ndarray::ArrayView3;

use super::features::{geometric_features, kinetic_features, BodyScale};
use super::fid::{Gaussian, ZNorm};
use super::kinematics::{percentile, window_starts};
use super::physical::PhysicalReference;
use super::plausibility::{angular_velocities, joint_angles, AngleLimits, LIMIT_PERCENTILES};
use super::skeleton_map::{angle_triples, augment, kinetic_view, GEOMETRIC_JOINTS};
use super::MetricsError;
use crate::motion::{skeleton as sk, Motion};

/// FID windows: 5 s long (AIST++/FACT evaluate 5-s clips at 60 fps; we keep the duration).
pub const FID_WINDOW_S: f64 = 5.0;
/// FID windows start every 1 s, so a 60-s dance gives 56 overlapping windows.
pub const FID_STRIDE_S: f64 = 1.0;
/// The windowed FID_k curve of the report: consecutive 4-s windows (DanceRevolution Fig. 4).
pub const CURVE_WINDOW_S: f64 = 4.0;
/// A feature whose train standard deviation is below this carries no information and is left out
/// of FID (z-normalising it would divide by ~1e-10 and let one stray value dominate).
pub const MIN_FEATURE_STD: f64 = 1e-8;
/// The `window_s` (and `stride_s`) recorded for whole-dance features: one vector per dance.
pub const WHOLE_DANCE: f64 = 0.0;

/// Statistics of one feature kind over the real train windows.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureStats {
    /// Window length and stride in seconds.
    pub window_s: f64,
    pub stride_s: f64,
    /// Indices of the features kept (train std ≥ [`MIN_FEATURE_STD`]).
    pub kept: Vec<usize>,
    /// Z-normalisation of the kept features (train mean, population std).
    pub znorm: ZNorm,
    /// Gaussian of the z-normalised train windows.
    pub gaussian: Gaussian,
}

impl FeatureStats {
    /// Fits the statistics to raw train window features.
    pub fn fit(window_s: f64, stride_s: f64, rows: &[Vec<f64>]) -> Result<Self, MetricsError> {
        let full = ZNorm::fit(rows)
            .ok_or_else(|| MetricsError::NotEnoughData("no train windows".into()))?;
        let kept: Vec<usize> = (0..full.std.len())
            .filter(|&k| full.std[k] >= MIN_FEATURE_STD)
            .collect();
        let sel: Vec<Vec<f64>> = rows
            .iter()
            .map(|r| kept.iter().map(|&k| r[k]).collect())
            .collect();
        let znorm = ZNorm::fit(&sel)
            .ok_or_else(|| MetricsError::NotEnoughData("no train windows".into()))?;
        let normed: Vec<Vec<f64>> = sel.iter().map(|r| znorm.apply(r)).collect();
        let gaussian = Gaussian::fit(&normed)
            .ok_or_else(|| MetricsError::NotEnoughData("no train windows".into()))?;
        Ok(Self {
            window_s,
            stride_s,
            kept,
            znorm,
            gaussian,
        })
    }

    /// Keeps the informative features of a raw row and z-normalises them.
    pub fn normalise(&self, raw: &[f64]) -> Vec<f64> {
        let sel: Vec<f64> = self
            .kept
            .iter()
            .map(|&k| raw.get(k).copied().unwrap_or(0.0))
            .collect();
        self.znorm.apply(&sel)
    }
}

/// Everything the metrics compare a dance against.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReferenceStats {
    /// What the statistics were computed from.
    pub source: String,
    /// The dances used.
    pub dances: Vec<String>,
    pub fps: f64,
    /// Median humerus length, shoulder width and hip width of the train dances.
    pub body_scale: BodyScale,
    /// Kinetic features, 5-s windows.
    pub kinetic: FeatureStats,
    /// Geometric features, 5-s windows.
    pub geometric: FeatureStats,
    /// Kinetic features, 4-s windows (the report's FID_k curve).
    pub kinetic_curve: FeatureStats,
    /// Joint-angle and angular-velocity limits (0.5–99.5 percentiles).
    pub angle_limits: AngleLimits,
    /// Kinetic features of each whole train dance, one vector per dance (Bailando's FID_k).
    pub kinetic_dance: FeatureStats,
    /// Geometric features of each whole train dance (Bailando's FID_g).
    pub geometric_dance: FeatureStats,
    /// Floor contact, pops and speed of the train dances ([`super::physical`]).
    pub physical: PhysicalReference,
    /// Tempo lock, arms and knees of the train dances against their songs
    /// ([`super::musicality`]; filled by `choreo eval --write-reference`, which has the songs).
    #[serde(default)]
    pub musicality: super::musicality::MusicalityReference,
}

/// The committed statistics, compiled into the binary.
const BUILTIN: &str = include_str!("reference_train.json");

/// Raw kinetic features of windows of `window_s` every `stride_s` (augmented positions).
pub fn kinetic_windows(motion: &Motion, window_s: f64, stride_s: f64) -> Vec<Vec<f64>> {
    let aug = augment(motion.positions.view());
    let kin = kinetic_view(&aug);
    let len = (window_s * motion.fps).round() as usize;
    let stride = (stride_s * motion.fps).round() as usize;
    window_starts(kin.dim().0, len, stride)
        .into_iter()
        .map(|s0| {
            let end = (s0 + len).min(kin.dim().0);
            kinetic_features(kin.slice(ndarray::s![s0..end, .., ..]), motion.fps)
        })
        .collect()
}

/// Raw geometric features of windows of `window_s` every `stride_s`.
pub fn geometric_windows(
    motion: &Motion,
    scale: &BodyScale,
    window_s: f64,
    stride_s: f64,
) -> Vec<Vec<f64>> {
    let aug = augment(motion.positions.view());
    let len = (window_s * motion.fps).round() as usize;
    let stride = (stride_s * motion.fps).round() as usize;
    window_starts(aug.dim().0, len, stride)
        .into_iter()
        .map(|s0| {
            let end = (s0 + len).min(aug.dim().0);
            geometric_features(
                aug.slice(ndarray::s![s0..end, .., ..]),
                motion.fps,
                &GEOMETRIC_JOINTS,
                scale,
            )
        })
        .collect()
}

/// Raw kinetic and geometric features of a whole dance, one vector each: the AIST++ features
/// computed over every frame, as Bailando's evaluation computes one per dance.
pub fn dance_features(motion: &Motion, scale: &BodyScale) -> (Vec<f64>, Vec<f64>) {
    let aug = augment(motion.positions.view());
    let kin = kinetic_view(&aug);
    (
        kinetic_features(kin.view(), motion.fps),
        geometric_features(aug.view(), motion.fps, &GEOMETRIC_JOINTS, scale),
    )
}

fn dist(p: ArrayView3<'_, f32>, f: usize, a: usize, b: usize) -> f64 {
    (0..3)
        .map(|c| (p[[f, a, c]] as f64 - p[[f, b, c]] as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Median humerus length (both arms), shoulder width and hip width over every frame of `motions`.
pub fn body_scale(motions: &[Motion]) -> BodyScale {
    let (mut hl, mut sw, mut hw) = (Vec::new(), Vec::new(), Vec::new());
    for m in motions {
        let p = m.positions.view();
        for f in 0..p.dim().0 {
            hl.push(dist(p, f, sk::SHOULDERS[0], 4));
            hl.push(dist(p, f, sk::SHOULDERS[1], 13));
            sw.push(dist(p, f, sk::SHOULDERS[0], sk::SHOULDERS[1]));
            hw.push(dist(p, f, sk::HIPS[0], sk::HIPS[1]));
        }
    }
    BodyScale {
        humerus: percentile(&hl, 50.0),
        shoulder_width: percentile(&sw, 50.0),
        hip_width: percentile(&hw, 50.0),
    }
}

/// Joint-angle and angular-velocity limits: 0.5 and 99.5 percentiles over every frame of `motions`.
pub fn angle_limits(motions: &[Motion]) -> AngleLimits {
    let triples = angle_triples();
    let k = triples.len();
    let (mut ang, mut vel): (Vec<Vec<f64>>, Vec<Vec<f64>>) =
        (vec![Vec::new(); k], vec![Vec::new(); k]);
    for m in motions {
        let a = joint_angles(m.positions.view(), &triples);
        for row in angular_velocities(&a, m.fps) {
            for (i, x) in row.into_iter().enumerate() {
                vel[i].push(x);
            }
        }
        for row in a {
            for (i, x) in row.into_iter().enumerate() {
                ang[i].push(x);
            }
        }
    }
    let (lo, hi) = LIMIT_PERCENTILES;
    AngleLimits {
        triples,
        angle_deg: ang
            .iter()
            .map(|v| [percentile(v, lo), percentile(v, hi)])
            .collect(),
        velocity_deg_s: vel
            .iter()
            .map(|v| [percentile(v, lo), percentile(v, hi)])
            .collect(),
    }
}

impl ReferenceStats {
    /// The statistics committed in `src/metrics/reference_train.json`.
    pub fn builtin() -> Result<Self, MetricsError> {
        Ok(serde_json::from_str(BUILTIN)?)
    }

    /// Computes the statistics from real dances (the train split; `names` label them).
    pub fn compute(
        source: &str,
        names: Vec<String>,
        motions: &[Motion],
    ) -> Result<Self, MetricsError> {
        let fps = motions
            .first()
            .map(|m| m.fps)
            .ok_or_else(|| MetricsError::NotEnoughData("no dances".into()))?;
        if motions.iter().any(|m| (m.fps - fps).abs() > 1e-9) {
            return Err(MetricsError::MixedFrameRates);
        }
        let body_scale = body_scale(motions);
        let mut kin = Vec::new();
        let mut geo = Vec::new();
        let mut curve = Vec::new();
        let (mut kin_dance, mut geo_dance) = (Vec::new(), Vec::new());
        for m in motions {
            let (k, g) = dance_features(m, &body_scale);
            kin_dance.push(k);
            geo_dance.push(g);
            kin.extend(kinetic_windows(m, FID_WINDOW_S, FID_STRIDE_S));
            geo.extend(geometric_windows(
                m,
                &body_scale,
                FID_WINDOW_S,
                FID_STRIDE_S,
            ));
            curve.extend(kinetic_windows(m, CURVE_WINDOW_S, FID_STRIDE_S));
        }
        Ok(Self {
            source: source.to_string(),
            dances: names,
            fps,
            body_scale,
            kinetic: FeatureStats::fit(FID_WINDOW_S, FID_STRIDE_S, &kin)?,
            geometric: FeatureStats::fit(FID_WINDOW_S, FID_STRIDE_S, &geo)?,
            kinetic_curve: FeatureStats::fit(CURVE_WINDOW_S, FID_STRIDE_S, &curve)?,
            angle_limits: angle_limits(motions),
            kinetic_dance: FeatureStats::fit(WHOLE_DANCE, WHOLE_DANCE, &kin_dance)?,
            geometric_dance: FeatureStats::fit(WHOLE_DANCE, WHOLE_DANCE, &geo_dance)?,
            physical: PhysicalReference::compute(motions),
            // Needs the songs' beats, which the caller has (`choreo eval --write-reference`).
            musicality: Default::default(),
        })
    }

    /// Writes the statistics as pretty JSON.
    pub fn write(&self, path: &std::path::Path) -> Result<(), MetricsError> {
        let text = serde_json::to_string(self)?;
        std::fs::write(path, text).map_err(|source| MetricsError::Io {
            path: path.display().to_string(),
            source,
        })
    }
}
