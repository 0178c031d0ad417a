//! Rotation flips: how often a joint's local rotation turns further in one frame than a body can.
//!
//! A rig's local rotations are what a skinned mesh follows. The positions of an export can be
//! exact while a joint's twist about its own bone jumps between two frames (a straight arm leaves
//! the twist free): a stick figure does not show it, a mesh bound to the bones wraps like a
//! sweet paper and a tool that interpolates between frames spins the limb. This measure counts
//! the frame steps on which some joint's local rotation turns more than 60° (and 90°): the angle
//! of `q_t⁻¹ · q_{t+1}`. In the real data a bone's direction changes more than 60° in one frame
//! (1/25 s) on 0.003 % of frames, so a step past 60° is a flip of the fit, not motion.
//!
//! It takes a [`RigMotion`] (what motion.bvh, motion.json and motion.glb carry), not positions:
//! the report and `choreo eval` fill it in where the rig exists (`scores.rotation_flips`).
use std::collections::BTreeMap;

use crate::motion::rig::RigMotion;

/// A one-frame turn past this (degrees) counts as a flip.
pub const FLIP_DEG: f64 = 60.0;
/// The larger threshold reported beside it (degrees).
pub const BIG_FLIP_DEG: f64 = 90.0;

/// Frame steps on which some joint's local rotation turns past [`FLIP_DEG`] and [`BIG_FLIP_DEG`].
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct RotationFlips {
    /// Frame steps measured (frames − 1, summed over a set's dances).
    pub steps: usize,
    /// Steps on which some joint turns more than 60°.
    pub steps_over_60: usize,
    /// Steps on which some joint turns more than 90°.
    pub steps_over_90: usize,
    /// `steps_over_60 / steps` (0 without steps).
    pub share_over_60: f64,
    /// `steps_over_90 / steps`.
    pub share_over_90: f64,
    /// The joint that turns more than 60° on the most steps (none when no step does).
    pub worst_joint: Option<String>,
    /// Steps over 60° per joint, joints that have none left out.
    pub joints_over_60: BTreeMap<String, usize>,
    /// The largest one-step turn of any joint (degrees).
    pub max_step_deg: f64,
}

impl RotationFlips {
    /// Measures every joint of `m` on every frame step.
    pub fn of(m: &RigMotion) -> RotationFlips {
        let n = m.rig.names.len();
        let mut per_joint = vec![0usize; n];
        let (mut over_60, mut over_90, mut max_deg) = (0, 0, 0.0f64);
        for pair in m.rotations.windows(2) {
            let mut step_max = 0.0f64;
            for (j, (a, b)) in pair[0].iter().zip(&pair[1]).enumerate() {
                let deg = a.angle_to(b).to_degrees();
                step_max = step_max.max(deg);
                if deg > FLIP_DEG {
                    per_joint[j] += 1;
                }
            }
            over_60 += usize::from(step_max > FLIP_DEG);
            over_90 += usize::from(step_max > BIG_FLIP_DEG);
            max_deg = max_deg.max(step_max);
        }
        let joints = m
            .rig
            .names
            .iter()
            .cloned()
            .zip(per_joint)
            .filter(|(_, c)| *c > 0)
            .collect();
        RotationFlips::from_counts(
            m.rotations.len().saturating_sub(1),
            over_60,
            over_90,
            joints,
            max_deg,
        )
    }

    /// The dances of a set pooled: every step of every dance counted once.
    pub fn pooled<'a>(dances: impl Iterator<Item = &'a RotationFlips>) -> RotationFlips {
        let (mut steps, mut over_60, mut over_90, mut max_deg) = (0, 0, 0, 0.0f64);
        let mut joints: BTreeMap<String, usize> = BTreeMap::new();
        for d in dances {
            steps += d.steps;
            over_60 += d.steps_over_60;
            over_90 += d.steps_over_90;
            max_deg = max_deg.max(d.max_step_deg);
            for (name, c) in &d.joints_over_60 {
                *joints.entry(name.clone()).or_default() += c;
            }
        }
        RotationFlips::from_counts(steps, over_60, over_90, joints, max_deg)
    }

    fn from_counts(
        steps: usize,
        over_60: usize,
        over_90: usize,
        joints: BTreeMap<String, usize>,
        max_step_deg: f64,
    ) -> RotationFlips {
        let share = |c: usize| {
            if steps == 0 {
                0.0
            } else {
                c as f64 / steps as f64
            }
        };
        // The most flips; ties to the first name, so the answer does not depend on map order.
        let worst_joint =
            joints
                .iter()
                .fold(None::<(&String, usize)>, |best, (name, &c)| match best {
                    Some((_, b)) if b >= c => best,
                    _ => Some((name, c)),
                });
        RotationFlips {
            steps,
            steps_over_60: over_60,
            steps_over_90: over_90,
            share_over_60: share(over_60),
            share_over_90: share(over_90),
            worst_joint: worst_joint.map(|(name, _)| name.clone()),
            joints_over_60: joints,
            max_step_deg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::rig::Rig;
    use nalgebra::{UnitQuaternion, Vector3};

    fn motion(turns_deg: &[f64]) -> RigMotion {
        let rig = Rig {
            names: vec!["root".into(), "arm".into()],
            parents: vec![None, Some(0)],
            offsets: vec![Vector3::zeros(), Vector3::x()],
        };
        let mut angle = 0.0f64;
        let mut rotations = vec![vec![UnitQuaternion::identity(); 2]];
        for d in turns_deg {
            angle += d.to_radians();
            rotations.push(vec![
                UnitQuaternion::identity(),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angle),
            ]);
        }
        RigMotion {
            rig,
            fps: 25.0,
            root_translation: vec![Vector3::zeros(); rotations.len()],
            rotations,
        }
    }

    #[test]
    fn counts_the_steps_past_each_threshold_and_names_the_joint() {
        let f = RotationFlips::of(&motion(&[10.0, 70.0, 10.0, 120.0, -170.0]));
        assert_eq!((f.steps, f.steps_over_60, f.steps_over_90), (5, 3, 2));
        assert!((f.share_over_60 - 0.6).abs() < 1e-12);
        assert_eq!(f.worst_joint.as_deref(), Some("arm"));
        assert_eq!(f.joints_over_60.get("arm"), Some(&3));
        assert!((f.max_step_deg - 170.0).abs() < 1e-6, "{}", f.max_step_deg);
        // q and −q are one rotation: a sign change is no turn.
        let mut m = motion(&[10.0]);
        m.rotations[1][1] = UnitQuaternion::new_unchecked(-m.rotations[1][1].into_inner());
        assert_eq!(RotationFlips::of(&m).steps_over_60, 0);
    }

    #[test]
    fn a_set_pools_its_steps() {
        let a = RotationFlips::of(&motion(&[70.0, 0.0]));
        let b = RotationFlips::of(&motion(&[0.0, 0.0, 0.0, 0.0]));
        let p = RotationFlips::pooled([&a, &b].into_iter());
        assert_eq!((p.steps, p.steps_over_60), (6, 1));
        assert_eq!(p.worst_joint.as_deref(), Some("arm"));
        assert_eq!(
            RotationFlips::pooled(std::iter::empty()),
            RotationFlips::default()
        );
    }
}
