//! Motion style classifier for evaluation: does a dance asked for in a style look like that
//! style? It judges motion only (no music), so that a dance cannot pass on its song.
//!
//! The network is DanceNet's musical style classifier (`StyleClassifier`: temporal
//! convolutions of kernel 2 with max-pooling, a Bi-LSTM, a fully connected layer; see
//! `models::dancenet::style`) over motion. What differs: the input (the 52 motion features below
//! rather than 15 music features), the window (10 s, [`WINDOW_S`], every 5 s: a figure of these
//! dances lasts a few seconds, and 10 s gives the short test dances 8–20 windows each rather than
//! 2–6), and the widths ([`config`]). Weights and card: `models/motion-style/`;
//! `choreo train motion-style` trains it on the train split's real motion.
//!
//! # Features: how the body moves, not how it stands or who it is
//! Per frame, 52 numbers, every one a change from the previous frame (0 on the first):
//! - `[0, 48)`: how the direction of each of 16 limb segments ([`BONES`]: upper arm, forearm,
//!   wrist, hand point, thigh, shin, heel and toe of each side) changed, as the difference of its
//!   unit vector (parent to child, in the body's facing frame, from `repr::to_features`'
//!   root-relative joints);
//! - `48`, `49`: root velocity x, z in the facing frame (m/frame: travel);
//! - `50`: the root's vertical velocity (m/frame: rise and fall);
//! - `51`: yaw velocity (rad/frame: turns).
//!
//! Why movement only. The performers' bodies are in the data: the 26 train waltzes are one
//! performer (shoulder marker width 0.265 m and shin 0.312 m on every one), the cha-chas and
//! rumbas two others (shoulders 0.32 m), the tango a fourth. Joint positions would let a
//! classifier tell the waltz by its shoulder width, and a classifier of segment directions (no
//! lengths) was still a posture classifier: one real pose of a test dance held still for 20 s
//! read as the style it came from at 0.61–1.00. A generated dance must not pass by holding the
//! right pose or drawing the right body, so only changes are kept: unit vectors drop the
//! lengths, differences drop the posture. Also left out: the six segments from the spine marker
//! to the head, shoulder and hip markers (the torso's rigid marker layout), and the root's
//! absolute height (leg length plus the capture's floor offset, floors from −0.10 to +0.07 m
//! across the dances). The root is the body centre computed from the joints
//! (`skeleton::body_centre_track`), for real dances as for generated ones.
//!
//! A body that stands still, or trembles in place, is no style: the trainer adds such windows
//! with a uniform target (`models::train::motion_style::no_style_windows`), and they read about
//! 0.25 each. Any other movement gets a style, so read the style beside the motion's own
//! measures (speed, freezing). One performer danced every waltz, so on this data "moves like a
//! waltz" and "moves like this performer's waltzing" cannot be told apart; the card says what
//! was checked.
use std::path::Path;

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use crate::models::dancenet::style::{
    Evaluation, HeldOut, Schedule, StyleConfig, WindowedClassifier, STYLES,
};
use crate::models::folder::{self, TrainingRecord};
use crate::models::ModelError;
use crate::motion::dataset::NormStats;
use crate::motion::{repr, skeleton, Motion, MotionError, MOTION_FPS};

/// The folder under the models dir (not a dance model: `models::MODELS` does not list it).
pub const ID: &str = "motion-style";
/// Classification window, seconds.
pub const WINDOW_S: f64 = 10.0;
/// Step between windows, seconds.
pub const HOP_S: f64 = 5.0;
/// Frame rate of the features: the dataset's.
pub const FPS: f64 = MOTION_FPS;
/// The limb segments `(parent, child)` whose change of direction is a feature (module doc).
pub const BONES: [(usize, usize); 16] = [
    (3, 4),   // right shoulder → elbow
    (4, 5),   // right elbow → forearm
    (5, 6),   // right forearm → wrist
    (6, 22),  // right wrist → hand point
    (7, 8),   // right hip → knee
    (8, 9),   // right knee → ankle
    (9, 10),  // right ankle → heel
    (9, 11),  // right ankle → toe
    (12, 13), // left shoulder → elbow
    (13, 14), // left elbow → forearm
    (14, 15), // left forearm → wrist
    (15, 21), // left wrist → hand point (the skeleton hangs it from the elbow; the wrist mirrors the right)
    (16, 17), // left hip → knee
    (17, 18), // left knee → ankle
    (18, 19), // left ankle → heel
    (18, 20), // left ankle → toe
];
/// Width of a feature row (module doc).
pub const FEATURE_DIM: usize = 3 * BONES.len() + 4;

/// The network's configuration: DanceNet's classifier with the motion's input width and wider
/// layers (52 features carry more than 15).
pub fn config() -> StyleConfig {
    StyleConfig {
        input_dim: FEATURE_DIM as i64,
        channels: vec![32, 48, 64],
        hidden: 48,
        ..StyleConfig::cpu()
    }
}

/// Errors of the motion style classifier.
#[derive(Debug, thiserror::Error)]
pub enum StyleError {
    #[error("{0}")]
    Model(#[from] ModelError),
    #[error("motion: {0}")]
    Motion(#[from] MotionError),
    #[error("motion at {got} fps; the classifier takes {want} fps")]
    Fps { got: f64, want: f64 },
}

impl StyleError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            StyleError::Model(ModelError::MissingWeights(..)) => "style-classifier-missing",
            StyleError::Model(_) => "style-classifier",
            StyleError::Motion(e) => e.code(),
            StyleError::Fps { .. } => "style-classifier-fps",
        }
    }
}

/// Feature rows `[T, 52]` of a motion (module doc).
pub fn features(motion: &Motion) -> Result<Array2<f32>, MotionError> {
    let root = skeleton::body_centre_track(motion.positions.view());
    let (f, _) = repr::to_features(motion.positions.view(), root.view())?;
    let base = 3 * BONES.len();
    let mut dirs = Array2::<f32>::zeros((f.nrows(), base));
    for t in 0..f.nrows() {
        for (b, &(p, c)) in BONES.iter().enumerate() {
            let v: [f32; 3] = std::array::from_fn(|k| f[[t, 3 * c + k]] - f[[t, 3 * p + k]]);
            let len = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            // Two markers on one spot have no direction; zero is the features' "unknown".
            if len > 1e-6 {
                for k in 0..3 {
                    dirs[[t, 3 * b + k]] = v[k] / len;
                }
            }
        }
    }
    let mut out = Array2::<f32>::zeros((f.nrows(), FEATURE_DIM));
    for t in 1..f.nrows() {
        for k in 0..base {
            out[[t, k]] = dirs[[t, k]] - dirs[[t - 1, k]];
        }
        out[[t, base]] = f[[t, repr::ROOT_VX]];
        out[[t, base + 1]] = f[[t, repr::ROOT_VZ]];
        out[[t, base + 2]] = f[[t, repr::ROOT_Y]] - f[[t - 1, repr::ROOT_Y]];
        out[[t, base + 3]] = f[[t, repr::YAW_VEL]];
    }
    Ok(out)
}

/// `models/motion-style/model.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct MotionStyleFile {
    pub config: StyleConfig,
    /// Normalisation of the 52 features, fitted on the train split's dances.
    pub pose_norm: NormStats,
    pub fps: f64,
    /// Window and hop, frames.
    pub window: usize,
    pub hop: usize,
    pub training: TrainingRecord<Schedule>,
    /// Every window and dance of the test split.
    pub test: Evaluation,
    /// Train dances left out of this run and scored (never the committed weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
}

/// The trained motion style classifier. Usable from several threads.
pub struct MotionStyle {
    file: MotionStyleFile,
    classifier: WindowedClassifier,
}

impl MotionStyle {
    /// Reads `dir/model.json` and loads `dir/weights.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, StyleError> {
        let file: MotionStyleFile = folder::read(dir, ID)?;
        if file.config.input_dim != FEATURE_DIM as i64 {
            return Err(ModelError::BadModelFile(format!(
                "{ID}: {} input features, these features are {FEATURE_DIM}",
                file.config.input_dim
            ))
            .into());
        }
        let classifier = WindowedClassifier::load(
            dir.join(folder::WEIGHTS_FILE),
            file.config.clone(),
            file.pose_norm.clone(),
            file.window,
            file.hop,
        )?;
        Ok(Self { file, classifier })
    }

    /// What `model.json` says (configuration, training, test accuracy).
    pub fn file(&self) -> &MotionStyleFile {
        &self.file
    }

    /// Style probabilities, [`crate::models::DanceStyle::ALL`] order: the mean of the softmax
    /// over 10-s windows every 5 s (one shorter window for a shorter motion).
    pub fn classify(&self, motion: &Motion) -> Result<[f32; STYLES], StyleError> {
        if (motion.fps - self.file.fps).abs() > 1e-6 {
            return Err(StyleError::Fps {
                got: motion.fps,
                want: self.file.fps,
            });
        }
        Ok(self.classifier.probabilities(&features(motion)?)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// A figure whose limbs swing (each joint on its own slow circle), drifting along its x
    /// axis; the whole body turned by `yaw` about y, scaled by `scale` and moved by `shift`.
    fn body(frames: usize, yaw: f32, scale: f32, shift: [f32; 3], still: bool) -> Motion {
        let mut p = Array3::<f32>::zeros((frames, crate::motion::NUM_JOINTS, 3));
        for t in 0..frames {
            let time = if still { 0.0 } else { t as f32 };
            for j in 0..crate::motion::NUM_JOINTS {
                let phase = 0.2 * time + j as f32;
                let x = ((j * 37) % 11) as f32 * 0.03 - 0.15 + 0.002 * time + 0.02 * phase.sin();
                let y = 1.0 - ((j * 13) % 9) as f32 * 0.1 + 0.02 * phase.cos();
                let z = ((j * 7) % 5) as f32 * 0.02;
                let (s, c) = yaw.sin_cos();
                let (rx, rz) = (c * x + s * z, -s * x + c * z);
                p[[t, j, 0]] = rx * scale + shift[0];
                p[[t, j, 1]] = y * scale + shift[1];
                p[[t, j, 2]] = rz * scale + shift[2];
            }
        }
        Motion {
            fps: MOTION_FPS,
            positions: p,
        }
    }

    fn max_diff(a: &Array2<f32>, b: &Array2<f32>) -> f32 {
        (a - b).mapv(f32::abs).fold(0f32, |m, &v| m.max(v))
    }

    #[test]
    fn features_see_movement_whatever_the_body_place_heading_or_pose() {
        let a = features(&body(12, 0.0, 1.0, [0.0; 3], false)).unwrap();
        assert_eq!(a.dim(), (12, FEATURE_DIM));
        assert!(
            a.row(5).iter().take(48).any(|v| v.abs() > 1e-3),
            "swinging limbs show no change"
        );
        let b = features(&body(12, 1.1, 1.0, [3.0, 0.5, -2.0], false)).unwrap();
        let d = max_diff(&a, &b);
        assert!(
            d < 1e-4,
            "turning and moving the dancer changed the features by {d}"
        );
        // A bigger body: the same changes of direction (the root's speeds scale with it).
        let c = features(&body(12, 0.0, 1.2, [0.0; 3], false)).unwrap();
        let limbs = |m: &Array2<f32>| m.slice(ndarray::s![.., ..48]).to_owned();
        let d = max_diff(&limbs(&a), &limbs(&c));
        assert!(d < 1e-4, "a bigger body changed the features by {d}");
        // A body held still reads all zeros, whatever its pose.
        let still = features(&body(12, 0.7, 1.3, [1.0, 0.0, 1.0], true)).unwrap();
        assert!(still.iter().all(|v| v.abs() < 1e-5));
        assert!(
            a.row(0).iter().all(|&v| v == 0.0),
            "the first frame has no previous one"
        );
    }

    #[test]
    fn feature_bones_are_limb_bones_in_mirrored_pairs() {
        let all = skeleton::bones();
        for b in BONES {
            // Every segment is a bone of the skeleton but the left hand point's, taken from the
            // wrist as on the right.
            assert!(all.contains(&b) || b == (15, 21), "{b:?} is not a bone");
            assert!(
                !skeleton::HEAD.contains(&b.1) && b.1 != skeleton::SPINE && b.0 != skeleton::SPINE,
                "{b:?} is a torso bone"
            );
            assert!(
                BONES.contains(&(skeleton::MIRROR[b.0], skeleton::MIRROR[b.1])),
                "{b:?} has no mirror"
            );
        }
    }

    #[test]
    fn missing_classifier_says_so() {
        let dir = tempfile::tempdir().unwrap();
        let err = MotionStyle::load(dir.path()).err().expect("no weights");
        assert_eq!(err.code(), "style-classifier-missing");
    }
}
