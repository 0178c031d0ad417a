//! What real dances do: the limits past which a dance is not plausible, each with why.
//!
//! The grader's verdict reads them ([`crate::metrics::physical::verdict`], which re-exports this
//! module as `thresholds`), and so do the served stages that keep a dance inside them
//! ([`super::bursts`] calms pops above [`POP_P999_M_S2`]): one module below both, so a stage
//! does not reach up into the metrics and a limit is changed in one place.

/// The lowest foot's median (m): real 0.16; a body standing on the floor keeps it near.
pub const FOOT_MEDIAN_M: (f64, f64) = (-0.05, 0.35);
/// The lowest foot's p5 (m): real 0.01; the floor is touched.
pub const FOOT_P5_M: (f64, f64) = (-0.15, 0.15);
/// Mean joint acceleration p99.9 (m/s²): real 56, its glitch-free max 1.5× that.
pub const POP_P999_M_S2: f64 = 84.0;
/// Largest mean joint acceleration within ±0.5 s of any key pose (m/s²).
pub const KEY_POP_M_S2: f64 = 84.0;
/// Mean joint speed (m/s): the slowest real dance moves at 0.63.
pub const MIN_SPEED_M_S: f64 = 0.5;
/// The longest hang (s, [`super::hang`]): real dances at most 0.72, about 1.4× that.
pub const HANG_S: f64 = 1.0;
/// Two seeds' dances differ by at least this root-relative distance (m).
pub const MIN_SEED_DISTANCE_M: f64 = 0.05;
/// Every key pose is hit within this (cm, centroid-aligned mean joint error).
pub const KEY_POSE_CM: f64 = 3.0;
