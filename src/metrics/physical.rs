//! Physical plausibility: does the dancer stand on the floor, move like a body, keep moving, and
//! dance differently for a different seed? Numbers a viewer sees at a glance, which the
//! distribution metrics (FID, BAS, S_cv, TSMT's authenticity and coherence in
//! [`super::plausibility`]) do not: a dancer floating a metre up, sinking into the floor,
//! snapping between poses or standing still can score well on those.
//!
//! Measures (world positions in metres, y up, the floor at `y = 0`: over all 43 real dances the
//! lowest foot point's p5 is 0.01 m, and it goes below −0.05 m in 1.4 % of frames, all of two
//! dances, DANCE_C_8 and DANCE_T_5, whose floor sits a few centimetres low):
//! - **floor contact**: per frame, the lowest foot point (ankles, heels, toes) — its p5,
//!   median and p95 over the dance;
//! - **ground penetration**: the share of frames whose lowest foot is below −5 cm, and the
//!   deepest frame;
//! - **pops**: per frame, the mean over joints of `|p[t+1] − 2p[t] + p[t−1]|·fps²` (m/s²), its
//!   median, p99, p99.9 and max, and around each key pose (±0.5 s) its largest value. A mean
//!   over 23 joints: a single joint jumping `d` metres for one frame adds `2d·fps²/23`
//!   (54 m/s² per metre at 25 fps), so the measure sees whole-body snaps, not one stray marker;
//! - **liveliness**: mean joint speed (m/s) over the dance and its ratio to the real train mean;
//! - **hang** ([`hang`]): the longest span with the lowest heel or toe over 0.10 m above
//!   its lowest within ±1 s, and that lift's largest value;
//! - **freeze**: [`super::kinematics::freezing`], already in every score;
//! - **seed sensitivity** ([`seed_distance_m`]): mean distance between the root-relative poses
//!   of two dances, so two seeds that give the same dance are seen.
//!
//! [`verdict`] applies the plausibility thresholds ([`thresholds`]) and says pass or fail per
//! criterion with the measured value. The real train figures (`choreo eval --write-reference`,
//! in `reference_train.json` under `physical`): lowest foot p5 0.01 m, median 0.16 m; mean joint
//! acceleration median 3.3 m/s², p99.9 ≈ 56 (max 112, capture glitches); mean joint speed per
//! dance 0.63–1.80 m/s.
use crate::motion::feet::lowest_foot;

use super::kinematics::{mean_speed, percentile};
use crate::motion::hang;
use crate::motion::{skeleton as sk, KeyPose, Motion};

/// The foot points whose lowest is the body's contact with the floor: ankles, heels, toes.
pub const FOOT_JOINTS: [usize; 6] = [
    sk::ANKLES[0],
    sk::HEELS[0],
    sk::TOES[0],
    sk::ANKLES[1],
    sk::HEELS[1],
    sk::TOES[1],
];
/// A lowest foot below this height (metres) is in the floor.
pub const PENETRATION_M: f64 = -0.05;
/// The span around a key pose searched for its largest pop (seconds either side).
pub const KEY_POP_SPAN_S: f64 = 0.5;

/// The plausibility thresholds, each with why (kept with the motion, where the served stages
/// read them too).
pub use crate::motion::limits as thresholds;

/// p5, median and p95 of a per-frame series.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Spread {
    pub p5: f64,
    pub median: f64,
    pub p95: f64,
}

impl Spread {
    /// The spread of `v` (NaN when empty).
    pub fn of(v: &[f64]) -> Self {
        Self {
            p5: percentile(v, 5.0),
            median: percentile(v, 50.0),
            p95: percentile(v, 95.0),
        }
    }
}

/// Percentiles of the per-frame mean joint acceleration (m/s²).
#[derive(
    Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Pops {
    pub median: f64,
    pub p99: f64,
    pub p99_9: f64,
    pub max: f64,
}

impl Pops {
    /// The percentiles of `v` (NaN when empty).
    pub fn of(v: &[f64]) -> Self {
        Self {
            median: percentile(v, 50.0),
            p99: percentile(v, 99.0),
            p99_9: percentile(v, 99.9),
            max: v.iter().copied().fold(f64::NAN, f64::max),
        }
    }
}

/// The physical-plausibility numbers of a dance (or, in `choreo eval`, of every frame of a row's
/// dances pooled).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct PhysicalScores {
    /// Per-frame lowest foot height (m, floor at 0).
    pub lowest_foot_m: Spread,
    /// Share of frames whose lowest foot is below −0.05 m.
    pub below_floor_share: f64,
    /// The lowest the lowest foot goes (m; negative is in the floor).
    pub deepest_m: f64,
    /// Per-frame mean joint acceleration (m/s²).
    pub acceleration_m_s2: Pops,
    /// For each key pose, the largest per-frame mean joint acceleration within ±0.5 s (m/s²).
    pub key_pose_pops_m_s2: Vec<f64>,
    /// Mean joint speed over the dance (m/s).
    pub mean_speed_m_s: f64,
    /// `mean_speed_m_s` over the real train mean.
    pub speed_ratio: f64,
    /// The lowest heel or toe's largest height above its lowest within ±1 s (m; [`hang`]).
    #[serde(default)]
    pub lift_max_m: f64,
    /// The longest span (s) with that lift over [`hang::HANG_LIFT_M`] (both feet up).
    #[serde(default)]
    pub hang_s: f64,
}

/// The per-frame series the scores summarise, kept so a set of dances can be pooled.
#[derive(Clone, Debug, Default)]
pub struct PhysicalSeries {
    /// Lowest foot height per frame (m).
    pub lowest_foot: Vec<f64>,
    /// Mean joint acceleration per interior frame `1..T−1` (m/s²).
    pub acceleration: Vec<f64>,
    /// Mean joint speed per frame step (m/s).
    pub speed: Vec<f64>,
    /// Largest acceleration near each key pose.
    pub key_pose_pops: Vec<f64>,
    /// The lowest heel or toe's height above its lowest within ±1 s, per frame (m; [`hang`]).
    pub lift: Vec<f64>,
    /// The longest hang (s): of a pooled set, its longest dance's.
    pub hang_s: f64,
}

// Measured beside the motion, where the served stages read it without the metrics.
pub use crate::motion::skeleton::joint_acceleration;

/// For each key pose, the largest of `acceleration` (from [`joint_acceleration`]) within
/// ±[`KEY_POP_SPAN_S`] of its frame; key poses outside the dance are left out.
pub fn key_pose_pops(
    acceleration: &[f64],
    fps: f64,
    frames: usize,
    key_poses: &[KeyPose],
) -> Vec<f64> {
    let span = (KEY_POP_SPAN_S * fps + 1e-9).floor() as i64;
    key_poses
        .iter()
        .filter_map(|kp| {
            let f = (kp.time_s * fps).round() as i64;
            if f < 0 || f >= frames as i64 || acceleration.is_empty() {
                return None;
            }
            // acceleration[i] is frame i + 1.
            let lo = (f - span - 1).max(0) as usize;
            let hi = ((f + span - 1).max(0) as usize).min(acceleration.len() - 1);
            (lo <= hi).then(|| {
                acceleration[lo..=hi]
                    .iter()
                    .copied()
                    .fold(f64::NAN, f64::max)
            })
        })
        .collect()
}

/// The per-frame series of a dance.
pub fn physical_series(motion: &Motion, key_poses: &[KeyPose]) -> PhysicalSeries {
    let p = motion.positions.view();
    let acceleration = joint_acceleration(p, motion.fps);
    let key_pose_pops = key_pose_pops(&acceleration, motion.fps, p.dim().0, key_poses);
    let lift = hang::contact_lift(p, motion.fps);
    PhysicalSeries {
        hang_s: hang::longest_hang_s(&lift, motion.fps),
        lift,
        lowest_foot: lowest_foot(p, &FOOT_JOINTS),
        acceleration,
        speed: mean_speed(p, motion.fps),
        key_pose_pops,
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

impl PhysicalSeries {
    /// The series of several dances end to end (for a set's pooled scores).
    pub fn pooled<'a>(all: impl IntoIterator<Item = &'a PhysicalSeries>) -> Self {
        let mut out = Self::default();
        for s in all {
            out.lowest_foot.extend_from_slice(&s.lowest_foot);
            out.acceleration.extend_from_slice(&s.acceleration);
            out.speed.extend_from_slice(&s.speed);
            out.key_pose_pops.extend_from_slice(&s.key_pose_pops);
            out.lift.extend_from_slice(&s.lift);
            out.hang_s = out.hang_s.max(s.hang_s);
        }
        out
    }

    /// Summarises the series; `real_mean_speed_m_s` is the train split's mean joint speed.
    pub fn scores(&self, real_mean_speed_m_s: f64) -> PhysicalScores {
        let below = self
            .lowest_foot
            .iter()
            .filter(|&&h| h < PENETRATION_M)
            .count();
        let speed = mean(&self.speed);
        PhysicalScores {
            lowest_foot_m: Spread::of(&self.lowest_foot),
            below_floor_share: if self.lowest_foot.is_empty() {
                f64::NAN
            } else {
                below as f64 / self.lowest_foot.len() as f64
            },
            deepest_m: self.lowest_foot.iter().copied().fold(f64::NAN, f64::min),
            acceleration_m_s2: Pops::of(&self.acceleration),
            key_pose_pops_m_s2: self.key_pose_pops.clone(),
            mean_speed_m_s: speed,
            speed_ratio: speed / real_mean_speed_m_s,
            lift_max_m: self.lift.iter().copied().fold(f64::NAN, f64::max),
            hang_s: self.hang_s,
        }
    }
}

/// Seed sensitivity: the mean over frames and joints of the distance (m) between the
/// root-relative poses of two dances (each joint minus its own frame's body centre,
/// [`sk::body_centre_track`]), so where the dancer travels does not count, only what the body
/// does. Over the frames both dances have; NaN when either has none or the joint counts differ.
pub fn seed_distance_m(a: &Motion, b: &Motion) -> f64 {
    let (pa, pb) = (a.positions.view(), b.positions.view());
    let t = pa.dim().0.min(pb.dim().0);
    let j = pa.dim().1;
    if t == 0 || j == 0 || pb.dim().1 != j {
        return f64::NAN;
    }
    let (ca, cb) = (sk::body_centre_track(pa), sk::body_centre_track(pb));
    let mut sum = 0.0;
    for f in 0..t {
        for k in 0..j {
            sum += (0..3)
                .map(|c| {
                    let d = (f64::from(pa[[f, k, c]]) - f64::from(ca[[f, c]]))
                        - (f64::from(pb[[f, k, c]]) - f64::from(cb[[f, c]]));
                    d * d
                })
                .sum::<f64>()
                .sqrt();
        }
    }
    sum / (t * j) as f64
}

/// What the train split's dances measure (`choreo eval --write-reference`).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct PhysicalReference {
    /// Every train frame pooled.
    pub pooled: PhysicalScores,
    /// Slowest and fastest dance's mean joint speed (m/s).
    pub mean_speed_range_m_s: [f64; 2],
    /// Lowest and highest per-dance p99.9 of the mean joint acceleration (m/s²).
    pub acceleration_p99_9_range_m_s2: [f64; 2],
    /// Lowest and highest per-dance median of the lowest foot (m).
    pub lowest_foot_median_range_m: [f64; 2],
}

impl PhysicalReference {
    /// Measures real dances.
    pub fn compute(motions: &[Motion]) -> Self {
        let series: Vec<PhysicalSeries> = motions.iter().map(|m| physical_series(m, &[])).collect();
        let pooled_series = PhysicalSeries::pooled(&series);
        let real_speed = mean(&pooled_series.speed);
        let per: Vec<PhysicalScores> = series.iter().map(|s| s.scores(real_speed)).collect();
        let range = |f: &dyn Fn(&PhysicalScores) -> f64| {
            let v: Vec<f64> = per.iter().map(f).collect();
            [
                v.iter().copied().fold(f64::INFINITY, f64::min),
                v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ]
        };
        Self {
            pooled: pooled_series.scores(real_speed),
            mean_speed_range_m_s: range(&|s| s.mean_speed_m_s),
            acceleration_p99_9_range_m_s2: range(&|s| s.acceleration_m_s2.p99_9),
            lowest_foot_median_range_m: range(&|s| s.lowest_foot_m.median),
        }
    }
}

/// One criterion of the verdict.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Criterion {
    /// Stable name, e.g. `lowest-foot-median`.
    pub name: String,
    /// The measured value (`None`: does not apply, e.g. no key poses or a single seed).
    pub value: Option<f64>,
    /// Inclusive bounds the value must lie within (`None`: unbounded on that side).
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// `None` when the criterion does not apply.
    pub pass: Option<bool>,
}

impl Criterion {
    fn new(name: &str, value: Option<f64>, min: Option<f64>, max: Option<f64>) -> Self {
        let value = value.filter(|v| !v.is_nan());
        let pass = value.map(|v| min.is_none_or(|lo| v >= lo) && max.is_none_or(|hi| v <= hi));
        Self {
            name: name.into(),
            value,
            min,
            max,
            pass,
        }
    }

    /// How far inside its bounds the value is (negative: outside); `None` when it does not apply.
    pub fn margin(&self) -> Option<f64> {
        let v = self.value?;
        let lo = self.min.map_or(f64::INFINITY, |lo| v - lo);
        let hi = self.max.map_or(f64::INFINITY, |hi| hi - v);
        Some(lo.min(hi))
    }
}

/// Pass or fail per plausibility criterion, with the measured values.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Verdict {
    /// True when every criterion that applies passes.
    pub pass: bool,
    pub criteria: Vec<Criterion>,
}

impl Verdict {
    fn from_criteria(criteria: Vec<Criterion>) -> Self {
        Self {
            pass: criteria.iter().all(|c| c.pass != Some(false)),
            criteria,
        }
    }

    /// The names of the failing criteria.
    pub fn failures(&self) -> Vec<&str> {
        self.criteria
            .iter()
            .filter(|c| c.pass == Some(false))
            .map(|c| c.name.as_str())
            .collect()
    }

    /// The criterion called `name`.
    pub fn get(&self, name: &str) -> Option<&Criterion> {
        self.criteria.iter().find(|c| c.name == name)
    }

    /// The verdict of a set: each criterion as its worst member (least margin) has it, so a set
    /// passes a criterion only when every member does.
    pub fn worst<'a>(all: impl IntoIterator<Item = &'a Verdict>) -> Verdict {
        let mut out: Vec<Criterion> = Vec::new();
        for v in all {
            for c in &v.criteria {
                match out.iter_mut().find(|o| o.name == c.name) {
                    None => out.push(c.clone()),
                    Some(o) => {
                        let worse = match (o.margin(), c.margin()) {
                            (None, Some(_)) => true,
                            (Some(a), Some(b)) => b < a,
                            _ => false,
                        };
                        if worse {
                            *o = c.clone();
                        }
                    }
                }
            }
        }
        Verdict::from_criteria(out)
    }

    /// Adds (or replaces) the criterion that two seeds differ, `distance_m` from [`seed_distance_m`].
    pub fn with_seed_distance(mut self, distance_m: Option<f64>) -> Verdict {
        let c = Criterion::new(
            names::SEEDS,
            distance_m,
            Some(thresholds::MIN_SEED_DISTANCE_M),
            None,
        );
        self.criteria.retain(|o| o.name != names::SEEDS);
        self.criteria.push(c);
        Verdict::from_criteria(self.criteria)
    }
}

/// The criteria's names.
pub mod names {
    pub const FOOT_MEDIAN: &str = "lowest-foot-median";
    pub const FOOT_P5: &str = "lowest-foot-p5";
    pub const POP_P999: &str = "acceleration-p99.9";
    pub const KEY_POPS: &str = "key-pose-pops";
    pub const SPEED: &str = "mean-speed";
    pub const HANG: &str = "hang";
    pub const SEEDS: &str = "seed-distance";
    pub const KEY_POSES: &str = "key-pose-error";
}

/// The verdict of one dance. `key_pose_errors_cm` are the per-key errors
/// ([`super::kinematics::key_pose_errors_cm`]; empty: no key poses); `seed_distance_m` the
/// distance to the same song danced with another seed, when there is one.
pub fn verdict(
    s: &PhysicalScores,
    key_pose_errors_cm: &[f64],
    seed_distance_m: Option<f64>,
) -> Verdict {
    use thresholds as t;
    let worst_key_pop = s.key_pose_pops_m_s2.iter().copied().reduce(f64::max);
    let worst_key = key_pose_errors_cm.iter().copied().reduce(f64::max);
    let criteria = vec![
        Criterion::new(
            names::FOOT_MEDIAN,
            Some(s.lowest_foot_m.median),
            Some(t::FOOT_MEDIAN_M.0),
            Some(t::FOOT_MEDIAN_M.1),
        ),
        Criterion::new(
            names::FOOT_P5,
            Some(s.lowest_foot_m.p5),
            Some(t::FOOT_P5_M.0),
            Some(t::FOOT_P5_M.1),
        ),
        Criterion::new(
            names::POP_P999,
            Some(s.acceleration_m_s2.p99_9),
            None,
            Some(t::POP_P999_M_S2),
        ),
        Criterion::new(names::KEY_POPS, worst_key_pop, None, Some(t::KEY_POP_M_S2)),
        Criterion::new(
            names::SPEED,
            Some(s.mean_speed_m_s),
            Some(t::MIN_SPEED_M_S),
            None,
        ),
        Criterion::new(names::HANG, Some(s.hang_s), None, Some(t::HANG_S)),
        Criterion::new(
            names::SEEDS,
            seed_distance_m,
            Some(t::MIN_SEED_DISTANCE_M),
            None,
        ),
        Criterion::new(names::KEY_POSES, worst_key, None, Some(t::KEY_POSE_CM)),
    ];
    Verdict::from_criteria(criteria)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::NUM_JOINTS;
    use ndarray::Array3;

    fn still(frames: usize, y: f32) -> Motion {
        Motion {
            fps: 25.0,
            positions: Array3::from_shape_fn((frames, NUM_JOINTS, 3), |(_, j, c)| {
                if c == 1 {
                    y + j as f32 * 0.05
                } else {
                    j as f32 * 0.01
                }
            }),
        }
    }

    #[test]
    fn a_one_frame_spike_has_the_hand_computed_acceleration() {
        let mut m = still(60, 0.0);
        m.positions[[10, 4, 0]] += 0.23;
        let a = joint_acceleration(m.positions.view(), 25.0);
        assert_eq!(a.len(), 58);
        // Frame 10 is index 9: |−2·0.23|·625 / 23 joints = 12.5; its neighbours half that.
        assert!((a[9] - 12.5).abs() < 1e-3, "{}", a[9]);
        assert!((a[8] - 6.25).abs() < 1e-3 && (a[10] - 6.25).abs() < 1e-3);
        assert!(a[..8].iter().chain(&a[11..]).all(|&x| x.abs() < 1e-6));
        let kp = |t: f64| KeyPose {
            time_s: t,
            joints: vec![],
        };
        // ±0.5 s is ±12 frames: a key at frame 22 still sees frame 10's spike, one at 23 only
        // frame 11's half, one at 40 nothing; a key after the end is left out.
        let pops = key_pose_pops(&a, 25.0, 60, &[kp(0.88), kp(0.92), kp(1.6), kp(5.0)]);
        assert_eq!(pops.len(), 3);
        assert!(
            (pops[0] - 12.5).abs() < 1e-3 && (pops[1] - 6.25).abs() < 1e-3 && pops[2].abs() < 1e-6,
            "{pops:?}"
        );
    }

    #[test]
    fn lowest_foot_and_seed_distance_ignore_what_they_should() {
        let m = still(10, 0.3);
        let s = physical_series(&m, &[]).scores(1.0);
        // The lowest foot joint is the right ankle (index 9): 0.3 + 9·0.05.
        assert!((s.lowest_foot_m.median - 0.75).abs() < 1e-6, "{s:?}");
        assert_eq!(s.mean_speed_m_s, 0.0);
        // Translating a dance changes nothing root-relative; a pose change does.
        let mut moved = m.clone();
        moved.positions.mapv_inplace(|v| v + 1.0);
        assert!(seed_distance_m(&m, &moved) < 1e-6);
        let mut bent = m.clone();
        bent.positions[[3, 6, 2]] += 0.46;
        assert!(seed_distance_m(&m, &bent) > 0.0);
    }

    #[test]
    fn the_worst_member_decides_a_sets_verdict() {
        let good = PhysicalScores {
            lowest_foot_m: Spread {
                p5: 0.01,
                median: 0.16,
                p95: 0.4,
            },
            acceleration_m_s2: Pops {
                median: 3.0,
                p99: 20.0,
                p99_9: 50.0,
                max: 90.0,
            },
            mean_speed_m_s: 1.0,
            ..Default::default()
        };
        let floating = PhysicalScores {
            lowest_foot_m: Spread {
                p5: 1.1,
                median: 1.22,
                p95: 1.5,
            },
            ..good.clone()
        };
        let a = verdict(&good, &[], Some(0.2));
        assert!(a.pass, "{a:?}");
        assert_eq!(
            a.get(names::KEY_POSES).and_then(|c| c.pass),
            None,
            "no key poses: does not apply"
        );
        let b = verdict(&floating, &[], Some(0.2));
        assert_eq!(b.failures(), vec![names::FOOT_MEDIAN, names::FOOT_P5]);
        let set = Verdict::worst([&a, &b]);
        assert!(!set.pass);
        assert_eq!(
            set.get(names::FOOT_MEDIAN).and_then(|c| c.value),
            Some(1.22)
        );
        assert_eq!(set.with_seed_distance(Some(0.0)).failures().len(), 3);
    }
}
