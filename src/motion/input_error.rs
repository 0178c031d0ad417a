//! What user-supplied motion is refused for ([`InputError`], HTTP 422), and the joint sets
//! ([`JointSet`]) a pose may list, which the refusal names. Both [`super::input`] (what the API
//! and the CLI accept) and [`super::validate`] (the checks on the canonical forms) use them, so
//! they live below both.
use serde::{Deserialize, Serialize};

use super::rig::{self, RIG_JOINTS};
use super::NUM_JOINTS;

/// Which joints a pose lists.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JointSet {
    /// motion.json's `joint_names` (26): `body_centre`, the 23 dataset joints, `pelvis`, `neck`.
    Choreo,
    /// The 23 dataset joints in the dataset's order.
    Dataset,
}

impl JointSet {
    /// Joints a pose of this set lists.
    pub const fn joint_count(self) -> usize {
        match self {
            JointSet::Choreo => RIG_JOINTS,
            JointSet::Dataset => NUM_JOINTS,
        }
    }

    /// The name the API uses.
    pub const fn name(self) -> &'static str {
        match self {
            JointSet::Choreo => "choreo",
            JointSet::Dataset => "dataset",
        }
    }

    /// The set `asked` for, or the one with `count` joints; an error naming both otherwise.
    pub fn resolve(
        what: &str,
        asked: Option<JointSet>,
        count: usize,
    ) -> Result<JointSet, InputError> {
        let by_count = [JointSet::Choreo, JointSet::Dataset]
            .into_iter()
            .find(|s| s.joint_count() == count);
        match (asked, by_count) {
            (Some(set), Some(found)) if set == found => Ok(set),
            (None, Some(found)) => Ok(found),
            _ => Err(InputError::WrongJointCount {
                what: what.to_string(),
                got: count,
                asked,
            }),
        }
    }

    /// Index in a pose of this set of dataset joint `j`.
    pub(super) const fn index_of(self, j: usize) -> usize {
        match self {
            JointSet::Choreo => rig::rig_index(j),
            JointSet::Dataset => j,
        }
    }
}

/// Why user-supplied motion was refused (HTTP 422).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("{what} is not a finite number")]
    NonFinite { what: String },
    #[error("{what} has {got} joints; {}", joint_sets_wanted(*.asked))]
    WrongJointCount {
        what: String,
        got: usize,
        /// The joint set the input named, if it named one.
        asked: Option<JointSet>,
    },
    #[error("{what}: bone {joint} is {length_m:.3} m long, at most {max_m:.3} m is plausible (are the units metres?)")]
    AbsurdBone {
        what: String,
        joint: &'static str,
        length_m: f32,
        max_m: f32,
    },
    #[error("{what}: bone lengths sum to {total_m:.2} m, plausible is {min_m:.2}–{max_m:.2} m (are the units metres?)")]
    AbsurdSize {
        what: String,
        total_m: f32,
        min_m: f32,
        max_m: f32,
    },
    #[error("key pose {index} at {time_s} s lands on frame {frame}, but the dance has {frames} frames at {fps} fps: times from 0 to under {limit_s:.3} s")]
    TimeOutsideSong {
        index: usize,
        time_s: f64,
        /// `round(time_s · fps)`.
        frame: i64,
        frames: usize,
        fps: f64,
        /// `(frames − ½) / fps`, the first time past the last frame.
        limit_s: f64,
    },
    #[error("key poses {first} and {second} ({first_s} s and {second_s} s) fall on the same frame {frame}")]
    DuplicateTime {
        first: usize,
        second: usize,
        first_s: f64,
        second_s: f64,
        frame: usize,
    },
    #[error("{0}")]
    Malformed(String),
}

/// The accepted joint sets, for a wrong count: which one was asked for, if any, and both.
fn joint_sets_wanted(asked: Option<JointSet>) -> String {
    let both = format!(
        "send {} joints in motion.json's `joint_names` order (joint_set \"choreo\") or {} in the dataset's order (joint_set \"dataset\")",
        JointSet::Choreo.joint_count(),
        JointSet::Dataset.joint_count()
    );
    match asked {
        Some(set) => format!(
            "joint_set \"{}\" has {}: {both}",
            set.name(),
            set.joint_count()
        ),
        None => both,
    }
}

impl InputError {
    /// Stable kebab-case code for problem responses.
    pub fn code(&self) -> &'static str {
        match self {
            InputError::NonFinite { .. } => "motion-not-finite",
            InputError::WrongJointCount { .. } => "wrong-joint-count",
            InputError::AbsurdBone { .. } => "absurd-bone-length",
            InputError::AbsurdSize { .. } => "absurd-skeleton-size",
            InputError::TimeOutsideSong { .. } => "time-outside-song",
            InputError::DuplicateTime { .. } => "duplicate-time",
            InputError::Malformed(_) => "malformed-motion",
        }
    }
}
