//! Key poses in pose space: a user's key pose (root-relative joints in world axes) becomes the
//! 69 local coordinates the network takes plus a facing yaw ([`local_keys`], [`to_local`]), and
//! the generated features are pulled exactly through every key by a smooth local correction
//! ([`pass_through_keys`], [`pass_through_yaws`]) that spreads over at least half a second.
use ndarray::{Array2, ArrayView2};

use crate::models::ModelError;
use crate::motion::dataset::NormStats;
use crate::motion::repr::{self, POSE_DIM, YAW_VEL};
use crate::motion::{KeyPose, NUM_JOINTS};

/// Quintic fall-off `1 − (10u³ − 15u⁴ + 6u⁵)` on `[0, 1)`, 0 beyond: 1 at 0, 0 at 1, with first
/// and second derivatives 0 at both ends, so a correction adds no jump in velocity *or*
/// acceleration (a cubic's acceleration steps where it starts, which reads as a pop).
fn falloff(u: f64) -> f64 {
    if u >= 1.0 {
        0.0
    } else {
        1.0 - u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
    }
}

/// Adds to each column of `x` `[n, c]` a smooth correction that makes row `t_i` equal `target_i`
/// exactly. Each key's residual fades out over `radius` frames, never reaching a neighbouring key
/// (the radius shrinks to the gap), so every key frame gets exactly its own residual.
pub fn pass_through_keys(
    x: &mut Array2<f32>,
    cols: std::ops::Range<usize>,
    keys: &[(usize, Vec<f32>)],
    radius: f64,
) {
    let mut sorted: Vec<&(usize, Vec<f32>)> = keys.iter().collect();
    sorted.sort_by_key(|k| k.0);
    let n = x.nrows();
    let residuals: Vec<Vec<f32>> = sorted
        .iter()
        .map(|(f, target)| {
            cols.clone()
                .zip(target)
                .map(|(c, v)| v - x[[*f, c]])
                .collect()
        })
        .collect();
    for (i, (f, _)) in sorted.iter().enumerate() {
        let left = if i > 0 {
            (f - sorted[i - 1].0) as f64
        } else {
            radius
        }
        .min(radius)
        .max(1.0);
        let right = if i + 1 < sorted.len() {
            (sorted[i + 1].0 - f) as f64
        } else {
            radius
        }
        .min(radius)
        .max(1.0);
        let lo = f.saturating_sub(left.ceil() as usize);
        let hi = (f + right.ceil() as usize).min(n - 1);
        for t in lo..=hi {
            let u = if t <= *f {
                (f - t) as f64 / left
            } else {
                (t - f) as f64 / right
            };
            let w = falloff(u) as f32;
            if w == 0.0 {
                continue;
            }
            for (k, c) in cols.clone().enumerate() {
                x[[t, c]] += w * residuals[i][k];
            }
        }
    }
}

/// Frames on each side of a key that [`bridge_keys`] replaces.
pub const BRIDGE_HALF: usize = 3;

/// Replaces rows `k − half ..= k + half` around each key frame `k` of `x` `[n, c]` by the cubic
/// Hermite curve between the rows just outside them, with the network's own per-frame velocity
/// there as tangents (the nearer row held at either end of the motion). The network tends to put
/// a key pose on its own frame without leading into it: a spike up to three frames wide that the
/// exact pass would keep. Bridging first makes the pass start from the network's trajectory, so
/// the correction is the smooth [`pass_through_keys`] blend alone. A straight line (the earlier
/// bridge) left a velocity kink where it met the trajectory: an 87 m/s² wrist pop one frame past
/// a bridge on a test dance.
pub fn bridge_keys(x: &mut Array2<f32>, frames: &[usize], half: usize) {
    let n = x.nrows();
    for &k in frames {
        if k >= n {
            continue;
        }
        let before = k.checked_sub(half + 1);
        let after = (k + half + 1 < n).then_some(k + half + 1);
        let (lo, hi) = (k.saturating_sub(half), (k + half).min(n - 1));
        // Per-frame velocity just outside the bridge (zero where the motion ends there).
        let slope = |a: usize, b: usize| -> Vec<f32> {
            x.row(b)
                .iter()
                .zip(x.row(a).iter())
                .map(|(q, p)| q - p)
                .collect()
        };
        let (va, vb) = match (before, after) {
            (Some(a), Some(b)) => (
                if a > 0 {
                    slope(a - 1, a)
                } else {
                    vec![0.0; x.ncols()]
                },
                if b + 1 < n {
                    slope(b, b + 1)
                } else {
                    vec![0.0; x.ncols()]
                },
            ),
            _ => (Vec::new(), Vec::new()),
        };
        for t in lo..=hi {
            let row: Vec<f32> = match (before, after) {
                (Some(a), Some(b)) => {
                    let len = (b - a) as f32;
                    let u = (t - a) as f32 / len;
                    let (u2, u3) = (u * u, u * u * u);
                    let (h00, h10, h01, h11) = (
                        2.0 * u3 - 3.0 * u2 + 1.0,
                        u3 - 2.0 * u2 + u,
                        -2.0 * u3 + 3.0 * u2,
                        u3 - u2,
                    );
                    (0..x.ncols())
                        .map(|c| {
                            h00 * x[[a, c]]
                                + h10 * len * va[c]
                                + h01 * x[[b, c]]
                                + h11 * len * vb[c]
                        })
                        .collect()
                }
                (Some(a), None) => x.row(a).to_vec(),
                (None, Some(b)) => x.row(b).to_vec(),
                (None, None) => continue,
            };
            x.row_mut(t).assign(&ndarray::ArrayView1::from(&row));
        }
    }
}

/// Frames each side of a jump ([`jump_frames`]) that the served path bridges: 15 frames in all, 0.6 s.
pub const JUMP_HALF: usize = 7;

/// The frames of features `[n, 73]` (absolute root height) whose mean joint acceleration
/// (root-relative joints, the root height added to theirs) exceeds `threshold_m_s2`: jumps to
/// spread over [`JUMP_HALF`] frames each side with [`bridge_keys`].
///
/// Between a scaffold pose and a user key pose the network can snap from one posture to the
/// other on a single frame (a 27-cm drop of the body on test dance DANCE_R_9, 178 m/s², 0.56 s
/// before a key); a dancer takes half a second.
pub fn jump_frames(x: ArrayView2<'_, f32>, threshold_m_s2: f64, fps: f64) -> Vec<usize> {
    let joints = ndarray::Array3::from_shape_fn((x.nrows(), NUM_JOINTS, 3), |(t, j, c)| {
        x[[t, 3 * j + c]] + if c == 1 { x[[t, repr::ROOT_Y]] } else { 0.0 }
    });
    // `joint_acceleration`'s value i is frame i + 1's.
    let acceleration = crate::motion::skeleton::joint_acceleration(joints.view(), fps);
    acceleration
        .iter()
        .enumerate()
        .filter(|(_, &a)| a > threshold_m_s2)
        .map(|(i, _)| i + 1)
        .collect()
}

/// Turns the integrated yaw so that frame `t_i` faces `yaw_i` (radians), blending the
/// correction like [`pass_through_keys`]; returns the start yaw to integrate from.
pub fn pass_through_yaws(
    features: &mut Array2<f32>,
    start_yaw: f32,
    keys: &[(usize, f32)],
    radius: f64,
) -> f32 {
    let n = features.nrows();
    // Integrated (unwrapped) yaw per frame.
    let mut yaw = Array2::<f32>::zeros((n, 1));
    let mut acc = start_yaw;
    for t in 0..n {
        if t > 0 {
            acc += features[[t, YAW_VEL]];
        }
        yaw[[t, 0]] = acc;
    }
    let targets: Vec<(usize, Vec<f32>)> = keys
        .iter()
        .map(|&(f, k)| {
            let d = (k - yaw[[f, 0]]).rem_euclid(std::f32::consts::TAU);
            let d = if d > std::f32::consts::PI {
                d - std::f32::consts::TAU
            } else {
                d
            };
            (f, vec![yaw[[f, 0]] + d])
        })
        .collect();
    pass_through_keys(&mut yaw, 0..1, &targets, radius);
    for t in 1..n {
        features[[t, YAW_VEL]] = yaw[[t, 0]] - yaw[[t - 1, 0]];
    }
    if n > 0 {
        yaw[[0, 0]]
    } else {
        start_yaw
    }
}

/// A key pose mapped into pose space: its frame, its 69 local coordinates (facing frame,
/// metres) and its facing yaw.
#[derive(Clone, Debug)]
pub struct LocalKey {
    pub frame: usize,
    pub local: Vec<f32>,
    pub yaw: f32,
}

/// Checks key poses against a song of `n` frames at `fps` and maps them into pose space.
/// The checks are the API's own ([`crate::motion::validate::key_frames`]): what it accepted passes here.
pub fn local_keys(keys: &[KeyPose], n: usize, fps: f64) -> Result<Vec<LocalKey>, ModelError> {
    let frames = crate::motion::validate::key_frames(keys, n, fps)
        .map_err(crate::motion::MotionError::from)?;
    let mut out: Vec<LocalKey> = Vec::with_capacity(keys.len());
    for (k, frame) in keys.iter().zip(frames) {
        let mut joints = Array2::<f32>::zeros((NUM_JOINTS, 3));
        for (j, p) in k.joints.iter().enumerate() {
            for a in 0..3 {
                joints[[j, a]] = p[a] as f32;
            }
        }
        let (local, yaw) = to_local(joints.view());
        out.push(LocalKey { frame, local, yaw });
    }
    Ok(out)
}

/// Root-relative joints `[J, 3]` → facing-frame coordinates (69) and the facing yaw, exactly as
/// [`repr::to_features`] computes columns `0..69`.
pub fn to_local(joints: ArrayView2<'_, f32>) -> (Vec<f32>, f32) {
    let yaw = repr::facing_yaw(joints);
    let (s, c) = (-f64::from(yaw)).sin_cos();
    let mut local = Vec::with_capacity(POSE_DIM);
    for j in 0..NUM_JOINTS {
        let (x, y, z) = (
            f64::from(joints[[j, 0]]),
            f64::from(joints[[j, 1]]),
            f64::from(joints[[j, 2]]),
        );
        local.push((c * x + s * z) as f32);
        local.push(y as f32);
        local.push((-s * x + c * z) as f32);
    }
    (local, yaw)
}

/// Normalises a key's 69 local coordinates with the pose statistics' first 69 columns.
pub fn normalize_key(norm: &NormStats, local: &[f32]) -> Vec<f32> {
    local
        .iter()
        .enumerate()
        .map(|(i, v)| (v - norm.mean[i]) / norm.std[i])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::keypose_transformer::served::BLEND_RADIUS;
    use crate::motion::repr::RootStart;

    #[test]
    fn bridging_removes_a_spike_at_a_key_and_nothing_else() {
        let mut x = Array2::from_shape_fn((20, 2), |(t, c)| (t + c) as f32);
        x[[10, 0]] = 50.0;
        x[[11, 1]] = -50.0;
        let mut y = x.clone();
        bridge_keys(&mut y, &[10], BRIDGE_HALF);
        // A straight trajectory is bridged by itself.
        for t in 7..=13 {
            assert!(
                (y[[t, 0]] - t as f32).abs() < 1e-4 && (y[[t, 1]] - (t + 1) as f32).abs() < 1e-4,
                "{t}"
            );
        }
        assert_eq!(y.row(3), x.row(3));
        assert_eq!(y.row(15), x.row(15));
        // At the motion's start the nearer outside row is held.
        let mut z = x.clone();
        bridge_keys(&mut z, &[0], BRIDGE_HALF);
        assert_eq!(z.row(0), x.row(4));
        // A curved trajectory is met with its own velocity: no kink where the bridge ends.
        let curve = Array2::from_shape_fn((30, 1), |(t, _)| (t as f32 * 0.3).sin());
        let mut w = curve.clone();
        w[[15, 0]] = 5.0;
        bridge_keys(&mut w, &[15], BRIDGE_HALF);
        let acc =
            |m: &Array2<f32>, t: usize| (m[[t + 1, 0]] - 2.0 * m[[t, 0]] + m[[t - 1, 0]]).abs();
        for t in 10..=20 {
            assert!(
                acc(&w, t) < 0.2,
                "frame {t}: {} against the curve's {}",
                acc(&w, t),
                acc(&curve, t)
            );
        }
    }

    #[test]
    fn a_one_frame_drop_is_found_and_spread_over_half_a_second() {
        // Standing, swaying 1 cm a frame; on frame 30 the body drops 27 cm and stays down.
        let mut x = Array2::<f32>::zeros((60, repr::FEATURE_DIM));
        for t in 0..60 {
            x[[t, repr::ROOT_Y]] = if t < 30 { 1.0 } else { 0.73 };
            for j in 0..NUM_JOINTS {
                x[[t, 3 * j]] = 0.01 * (t as f32 * 0.3).sin();
            }
        }
        let acc = |x: &Array2<f32>| -> f64 {
            (1..59)
                .map(|t| {
                    625.0
                        * f64::from(
                            (x[[t + 1, repr::ROOT_Y]] - 2.0 * x[[t, repr::ROOT_Y]]
                                + x[[t - 1, repr::ROOT_Y]])
                            .abs(),
                        )
                })
                .fold(0.0, f64::max)
        };
        let jumps = jump_frames(x.view(), 57.0, 25.0);
        assert_eq!(jumps, vec![29, 30]);
        assert!(acc(&x) > 150.0);
        bridge_keys(&mut x, &jumps, JUMP_HALF);
        assert!(acc(&x) < 20.0, "{}", acc(&x));
        assert!(jump_frames(x.view(), 57.0, 25.0).is_empty());
        // The sway alone (0.9 m/s² at most) is no jump.
        let mut still = x.clone();
        still.column_mut(repr::ROOT_Y).fill(1.0);
        assert!(jump_frames(still.view(), 57.0, 25.0).is_empty());
        // The served threshold is the real p99.9 the metrics measure.
        let real = crate::metrics::reference::ReferenceStats::builtin()
            .unwrap()
            .physical
            .pooled
            .acceleration_m_s2
            .p99_9;
        assert!(
            (real - crate::models::keypose_transformer::served::JUMP_M_S2).abs() < 0.5,
            "{real}"
        );
    }

    #[test]
    fn pass_through_hits_every_key_and_leaves_far_frames() {
        let mut x = Array2::<f32>::zeros((60, 3));
        let keys = vec![
            (10usize, vec![1.0, 2.0, 3.0]),
            (12, vec![-1.0, 0.0, 0.5]),
            (40, vec![0.3, 0.3, 0.3]),
        ];
        pass_through_keys(&mut x, 0..3, &keys, 8.0);
        for (f, t) in &keys {
            for c in 0..3 {
                assert!((x[[*f, c]] - t[c]).abs() < 1e-6);
            }
        }
        assert_eq!(x.row(25).to_vec(), vec![0.0; 3]);
        assert_eq!(x.row(59).to_vec(), vec![0.0; 3]);
    }

    #[test]
    fn key_pose_honoured_through_features() {
        // A real-shaped pose through to_local → pass_through → from_features comes back within 1 mm.
        let n = 40;
        let features = Array2::<f32>::zeros((n, repr::FEATURE_DIM));
        let mut joints = Vec::new();
        for j in 0..NUM_JOINTS {
            joints.push([
                0.1 * (j as f64 % 5.0) - 0.2,
                0.05 * j as f64 - 0.5,
                0.03 * (j as f64 % 3.0),
            ]);
        }
        let key = KeyPose {
            time_s: 20.0 / 25.0,
            joints,
        };
        let lk = local_keys(std::slice::from_ref(&key), n, 25.0).unwrap();
        let mut out = features.clone();
        pass_through_keys(
            &mut out,
            0..POSE_DIM,
            &[(lk[0].frame, lk[0].local.clone())],
            BLEND_RADIUS,
        );
        let yaw0 = pass_through_yaws(&mut out, 0.0, &[(lk[0].frame, lk[0].yaw)], BLEND_RADIUS);
        let (motion, root) = repr::from_features(
            out.view(),
            RootStart {
                yaw: yaw0,
                ..Default::default()
            },
            25.0,
        )
        .unwrap();
        let err = crate::metrics::kinematics::key_pose_error_root_cm(&motion, root.view(), &[key])
            .unwrap();
        assert!(err < 0.1, "key pose error {err} cm");
    }

    #[test]
    fn bad_key_poses_are_rejected() {
        let ok = KeyPose {
            time_s: 1.0,
            joints: vec![[0.0; 3]; NUM_JOINTS],
        };
        assert!(local_keys(std::slice::from_ref(&ok), 50, 25.0).is_ok());
        let outside = KeyPose {
            time_s: 3.0,
            ..ok.clone()
        };
        assert!(local_keys(&[outside], 50, 25.0).is_err());
        let nan = KeyPose {
            joints: vec![[f64::NAN, 0.0, 0.0]; NUM_JOINTS],
            ..ok.clone()
        };
        assert!(local_keys(&[nan], 50, 25.0).is_err());
        let short = KeyPose {
            joints: vec![[0.0; 3]; 5],
            ..ok.clone()
        };
        assert!(local_keys(&[short], 50, 25.0).is_err());
        let near = KeyPose {
            time_s: 1.01,
            ..ok.clone()
        };
        assert!(local_keys(&[ok.clone(), near], 50, 25.0).is_err());
        assert!(local_keys(&[ok.clone(), ok.clone()], 1, 25.0).is_err());
    }
}
