//! Physical plausibility after TSMT: authenticity (joint angles within limits) and coherence
//! (joint angular velocities within limits), the limits being the 0.5th and 99.5th percentiles of
//! the real train dances ([`super::reference::ReferenceStats::angle_limits`]).
//!
//! A joint angle is the bend between bone `parent → joint` and bone `joint → child` (0° straight,
//! degrees) for each triple of [`super::skeleton_map::angle_triples`]; its angular velocity is the
//! frame difference times fps (deg/s). A frame is authentic when *every* angle is inside its
//! limits, and coherent when every angular velocity is; with 1 % of real values outside each
//! limit pair, real dances score below 1 (the Real row of `choreo eval` shows how far).
use ndarray::ArrayView3;

/// Lower and upper percentile of the limits.
pub const LIMIT_PERCENTILES: (f64, f64) = (0.5, 99.5);

/// Per-angle limits `[lo, hi]`, in the order of the triples.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AngleLimits {
    /// `(parent, joint, child)` joint indices of each angle.
    pub triples: Vec<(usize, usize, usize)>,
    /// Joint angle limits in degrees.
    pub angle_deg: Vec<[f64; 2]>,
    /// Angular velocity limits in degrees per second.
    pub velocity_deg_s: Vec<[f64; 2]>,
}

/// The bend angle (degrees) of every triple on every frame, `[T][K]`.
pub fn joint_angles(
    positions: ArrayView3<'_, f32>,
    triples: &[(usize, usize, usize)],
) -> Vec<Vec<f64>> {
    let t = positions.dim().0;
    (0..t)
        .map(|f| {
            triples
                .iter()
                .map(|&(p, j, c)| {
                    let v = |a: usize, b: usize| -> [f64; 3] {
                        std::array::from_fn(|k| {
                            positions[[f, b, k]] as f64 - positions[[f, a, k]] as f64
                        })
                    };
                    let (u, w) = (v(p, j), v(j, c));
                    let dot = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
                    let nu = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                    let nw = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
                    if nu == 0.0 || nw == 0.0 {
                        0.0
                    } else {
                        (dot / (nu * nw)).clamp(-1.0, 1.0).acos().to_degrees()
                    }
                })
                .collect()
        })
        .collect()
}

/// Angular velocities (deg/s) from [`joint_angles`], `[T−1][K]`.
pub fn angular_velocities(angles: &[Vec<f64>], fps: f64) -> Vec<Vec<f64>> {
    angles
        .windows(2)
        .map(|w| w[1].iter().zip(&w[0]).map(|(b, a)| (b - a) * fps).collect())
        .collect()
}

/// Share of rows whose every value lies within its `[lo, hi]`; 0 for no rows.
fn share_within(rows: &[Vec<f64>], limits: &[[f64; 2]]) -> f64 {
    if rows.is_empty() {
        return 0.0;
    }
    let ok = rows
        .iter()
        .filter(|r| r.iter().zip(limits).all(|(x, l)| *x >= l[0] && *x <= l[1]))
        .count();
    ok as f64 / rows.len() as f64
}

/// Authenticity and coherence of one dance.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Plausibility {
    /// Share of frames with every joint angle within the real 0.5–99.5 % limits.
    pub authenticity: f64,
    /// Share of frame steps with every joint angular velocity within the real limits.
    pub coherence: f64,
}

/// Authenticity and coherence of `positions` against `limits`.
pub fn plausibility(
    positions: ArrayView3<'_, f32>,
    fps: f64,
    limits: &AngleLimits,
) -> Plausibility {
    let angles = joint_angles(positions, &limits.triples);
    let vel = angular_velocities(&angles, fps);
    Plausibility {
        authenticity: share_within(&angles, &limits.angle_deg),
        coherence: share_within(&vel, &limits.velocity_deg_s),
    }
}
