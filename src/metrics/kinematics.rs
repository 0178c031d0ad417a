//! Motion-quality numbers that need no music: smoothness, foot skating, freezing, key-pose error,
//! and the windows the feature-based metrics are computed on.
use ndarray::{s, ArrayView3};

/// Per-frame mean joint speed (the motion module's, which its beat-align stage reads too).
pub use crate::motion::skeleton::mean_speed;

/// Smoothness `S_cv`: the coefficient of variation (population sd / |mean|) of the frame-difference
/// sequence, here the per-frame mean joint speed ([`mean_speed`]). 0 for a motion that never moves.
/// Jittery motion has a speed that jumps from frame to frame, so a higher `S_cv` is less smooth.
pub fn smoothness_cv(positions: ArrayView3<'_, f32>, fps: f64) -> f64 {
    let d = mean_speed(positions, fps);
    if d.is_empty() {
        return 0.0;
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    if mean.abs() < 1e-12 {
        return 0.0;
    }
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    var.sqrt() / mean.abs()
}

/// A foot is in contact when its height above the floor is below this (metres).
pub const CONTACT_HEIGHT_M: f64 = 0.05;
/// A foot in contact skates when its horizontal speed exceeds this (m/s).
pub const SKATE_SPEED_M_S: f64 = 0.2;
/// The floor is this percentile of the per-frame lowest foot height, robust to a few noisy frames
/// (the motion module's floor, which foot planting uses too).
pub const FLOOR_PERCENTILE: f64 = crate::motion::feet::FLOOR_PERCENTILE;

/// Foot skating over a dance.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct FootSkating {
    /// Share of (foot, frame step) pairs in contact at both ends of the step.
    pub contact_share: f64,
    /// Of those contact steps, the share whose horizontal speed exceeds 0.2 m/s.
    pub skate_ratio: f64,
    /// Mean horizontal speed of feet in contact (m/s).
    pub mean_contact_speed_m_s: f64,
}

/// The `q`-th percentile (0–100) with numpy's default linear interpolation; NaN if `v` is empty.
pub fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let pos = q / 100.0 * (s.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    s[lo] + (s[hi] - s[lo]) * (pos - lo as f64)
}

/// Foot skating: a foot joint (`feet`, e.g. both ankles and toes) is in contact on a frame step
/// when it is within [`CONTACT_HEIGHT_M`] of the floor at both ends; the floor is the
/// [`FLOOR_PERCENTILE`]th percentile of the lowest foot's height per frame. A contact step skates
/// when its horizontal (x, z) speed exceeds [`SKATE_SPEED_M_S`].
pub fn foot_skating(positions: ArrayView3<'_, f32>, fps: f64, feet: &[usize]) -> FootSkating {
    let t = positions.dim().0;
    if t < 2 || feet.is_empty() {
        return FootSkating::default();
    }
    let floor = crate::motion::feet::floor_height(positions, feet);
    let (mut steps, mut contact, mut skate, mut speed_sum) = (0usize, 0usize, 0usize, 0.0f64);
    for f in 1..t {
        for &j in feet {
            steps += 1;
            let h0 = positions[[f - 1, j, 1]] as f64 - floor;
            let h1 = positions[[f, j, 1]] as f64 - floor;
            if h0 < CONTACT_HEIGHT_M && h1 < CONTACT_HEIGHT_M {
                contact += 1;
                let dx = positions[[f, j, 0]] as f64 - positions[[f - 1, j, 0]] as f64;
                let dz = positions[[f, j, 2]] as f64 - positions[[f - 1, j, 2]] as f64;
                let v = (dx * dx + dz * dz).sqrt() * fps;
                speed_sum += v;
                if v > SKATE_SPEED_M_S {
                    skate += 1;
                }
            }
        }
    }
    FootSkating {
        contact_share: contact as f64 / steps as f64,
        skate_ratio: if contact > 0 {
            skate as f64 / contact as f64
        } else {
            0.0
        },
        mean_contact_speed_m_s: if contact > 0 {
            speed_sum / contact as f64
        } else {
            0.0
        },
    }
}

/// The span compared by the freezing ratio: the first and last 30 s.
pub const FREEZE_SPAN_S: f64 = 30.0;

/// Motion energy over time, to see a dance that freezes.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Freezing {
    /// Start of each 1-s bin (s).
    pub times_s: Vec<f64>,
    /// Motion energy per bin: mean over frames and joints of the squared joint speed (m²/s²).
    pub energy: Vec<f64>,
    /// Mean energy of the last 30 s over that of the first 30 s (halves when the dance is
    /// shorter than 60 s); 0 when the first span does not move.
    pub last_first_ratio: f64,
}

/// Per-frame-step motion energy `mean_j |v_j|²` in m²/s².
pub fn energy_per_step(positions: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let (t, j, _) = positions.dim();
    (1..t)
        .map(|f| {
            (0..j)
                .map(|k| {
                    (0..3)
                        .map(|c| {
                            ((positions[[f, k, c]] as f64 - positions[[f - 1, k, c]] as f64) * fps)
                                .powi(2)
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
                / j.max(1) as f64
        })
        .collect()
}

/// Motion energy in 1-s bins, and the last-30-s / first-30-s ratio.
pub fn freezing(positions: ArrayView3<'_, f32>, fps: f64) -> Freezing {
    let e = energy_per_step(positions, fps);
    if e.is_empty() {
        return Freezing::default();
    }
    let per_bin = fps.round().max(1.0) as usize;
    let (mut times_s, mut energy) = (Vec::new(), Vec::new());
    for (b, chunk) in e.chunks(per_bin).enumerate() {
        times_s.push(b as f64 * per_bin as f64 / fps);
        energy.push(chunk.iter().sum::<f64>() / chunk.len() as f64);
    }
    let span = ((FREEZE_SPAN_S * fps).round() as usize)
        .min(e.len() / 2)
        .max(1);
    let first = e[..span].iter().sum::<f64>() / span as f64;
    let last = e[e.len() - span..].iter().sum::<f64>() / span as f64;
    Freezing {
        times_s,
        energy,
        last_first_ratio: if first > 0.0 { last / first } else { 0.0 },
    }
}

/// Key-pose consistency error in cm: at each key pose's frame (`round(time · fps)`, skipped when
/// outside the dance or of the wrong joint count), the mean over joints of the distance between the
/// dance's pose and the key pose, both centred on their own joint centroid (a key pose is
/// root-relative and a generated dance carries no body centre, so centring both is the one root
/// they share); averaged over key poses. `None` when no key pose applies.
pub fn key_pose_error_cm(
    positions: ArrayView3<'_, f32>,
    fps: f64,
    key_poses: &[crate::motion::KeyPose],
) -> Option<f64> {
    let errs = key_pose_errors_cm(positions, fps, key_poses);
    if errs.is_empty() {
        None
    } else {
        Some(errs.iter().sum::<f64>() / errs.len() as f64)
    }
}

/// The error (cm) of each key pose that applies, as [`key_pose_error_cm`] measures it, in order.
pub fn key_pose_errors_cm(
    positions: ArrayView3<'_, f32>,
    fps: f64,
    key_poses: &[crate::motion::KeyPose],
) -> Vec<f64> {
    let (t, j, _) = positions.dim();
    let mut errs = Vec::new();
    for kp in key_poses {
        let f = (kp.time_s * fps).round();
        if j == 0 || !(0.0..t as f64).contains(&f) || kp.joints.len() != j {
            continue;
        }
        let pose = positions.slice(s![f as usize, .., ..]);
        let pc: [f64; 3] =
            std::array::from_fn(|c| (0..j).map(|k| pose[[k, c]] as f64).sum::<f64>() / j as f64);
        let kc: [f64; 3] =
            std::array::from_fn(|c| kp.joints.iter().map(|p| p[c]).sum::<f64>() / j as f64);
        let sum: f64 = (0..j)
            .map(|k| {
                (0..3)
                    .map(|c| (pose[[k, c]] as f64 - pc[c] - (kp.joints[k][c] - kc[c])).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .sum();
        errs.push(100.0 * sum / j as f64);
    }
    errs
}

/// Mean per-joint distance (cm) between each key pose and the motion's root-relative joints at
/// its frame, where `root` `[T, 3]` is the root track the motion was built around.
pub fn key_pose_error_root_cm(
    motion: &crate::motion::Motion,
    root: ndarray::ArrayView2<'_, f32>,
    keys: &[crate::motion::KeyPose],
) -> Option<f64> {
    let mut sum = 0.0;
    let mut count = 0usize;
    for k in keys {
        let f = (k.time_s * motion.fps).round() as usize;
        if f >= motion.num_frames() {
            return None;
        }
        for (j, p) in k.joints.iter().enumerate() {
            let d: f64 = (0..3)
                .map(|a| (f64::from(motion.positions[[f, j, a]] - root[[f, a]]) - p[a]).powi(2))
                .sum();
            sum += d.sqrt();
            count += 1;
        }
    }
    (count > 0).then(|| 100.0 * sum / count as f64)
}

/// Start frames of windows of `len` frames taken every `stride` frames; one window starting at 0
/// covering everything when the motion is shorter than `len` (but at least 2 frames).
pub fn window_starts(frames: usize, len: usize, stride: usize) -> Vec<usize> {
    if frames < 2 {
        return Vec::new();
    }
    if frames <= len {
        return vec![0];
    }
    (0..=frames - len).step_by(stride.max(1)).collect()
}
