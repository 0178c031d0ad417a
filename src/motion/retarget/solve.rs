//! The solver: a dance on choreo's rig ([`RigMotion`] as motion.json carries it) onto a
//! [`TargetSkeleton`].
//!
//! # Per frame
//! 1. **Bone directions.** Each humanoid bone the target has is aimed like its choreo bone
//!    ([`aim`]): a choreo joint whose rotation drives it (the *driver*: the left upper arm is
//!    driven by choreo's `left_shoulder`), and two point sets whose difference is the bone's
//!    direction in either skeleton (choreo's `left_shoulder → left_elbow`, the target's
//!    `leftUpperArm → leftLowerArm`). The target bone's world rotation is the driver's world
//!    rotation times a constant *rest alignment* `A` (the rotation taking the target's rest frame
//!    of the bone onto choreo's: bone direction first, the body's forward, or up for the feet,
//!    second), then turned by the shortest arc that puts the bone exactly on choreo's direction
//!    this frame. So every mapped bone points where choreo's points, and its twist about itself is
//!    choreo's own (continuous wherever choreo's fit is: this solver adds no twist of its own).
//! 2. **What choreo does not have** follows its parent (local rotation = rest): the clavicles,
//!    hands and toes, and every joint with no humanoid bone. The torso's twist from the hips
//!    (choreo has one spine joint) is spread evenly over the spine bones the target has (spine,
//!    chest, upper chest), its bend on the first, the last ending where the torso is; the head faces within
//!    [`HEAD_TURN_KEPT_DEG`] of the torso (the capture's head markers swap); the neck takes half
//!    the head's turn from the torso.
//! 3. **Scale.** The target's hips go where choreo's hips go, scaled by the ratio of leg lengths
//!    (thigh + shin), the floor (choreo's, the 1st percentile of its lowest foot point) on y = 0.
//! 4. **Foot IK.** A foot near the floor (choreo's lowest point of it within
//!    [`crate::motion::feet::SUPPORT_HEIGHT_M`]) aims its ankle at choreo's ankle scaled the same
//!    way, its height measured from the flat-foot height of either skeleton (per foot for choreo,
//!    whose markers sit differently on either foot), so a foot choreo has on the floor is on the
//!    floor and a lifted one is lifted as much (scaled). A lifted foot (twice that high) aims at
//!    choreo's hip-to-ankle vector scaled by its own leg's ratio, from the target's hip, which
//!    keeps the knee's angle (choreo's two legs differ by 2-3 cm, a target's need not); in
//!    between, a blend. Where a goal is out of reach the hips are lowered (smoothed over
//!    ±[`DROP_WINDOW`] frames); then a two-bone IK turns thigh and shin in the plane of the knee
//!    (the shortest arcs, so the twist stays), the foot keeping its world rotation. Hands and
//!    head are not solved for: they follow their chains.
//! 5. **Lower arms.** A lower arm turns no faster than choreo's joints do (55° a frame at 25 fps):
//!    it is one joint where choreo has two, so its twist is held back where their composed turn
//!    is faster, and catches up over the next frames ([`limit_lower_arms`]).
//!
//! Rotations carry over through the two rest poses, as animation retargeting usually does; bone
//! directions come from choreo's positions (so a rest pose that differs, an average dancing pose
//! against a T-pose, costs nothing), and the feet are solved afterwards.
use std::collections::HashMap;

use nalgebra::{UnitQuaternion, Vector3};

use super::{HumanBone, RetargetError, TargetSkeleton};
use crate::motion::rig::{fk_frame, RigMotion};

mod bones;
mod hips;
mod kinematics;
mod upper_body;

pub use bones::REQUIRED;
use bones::{aim, Aim, CHOREO_JOINTS, LEGS};
use hips::{leg_gap, GapSum};
use kinematics::{
    arc, fk_world, frame, locals, make_continuous, mean, mean_rotation, spread_max, two_bone_ik,
    MAX_REACH,
};
use upper_body::{face_with_torso, limit_lower_arms, spread_torso};

/// How far (degrees) the head's twist from the torso is kept as the markers give it; beyond, it
/// is turned back towards the torso ([`face_with_torso`]). 60°: 90 % of frames of the dances
/// whose head markers do not swap lie within 33-60°.
pub const HEAD_TURN_KEPT_DEG: f64 = 60.0;

/// Half-width (frames) of the window over which a lowering of the hips is spread.
pub const DROP_WINDOW: usize = 4;
/// Half-width (frames) of the window over which the hips' shift onto the supporting feet is
/// averaged: a quarter of a second either side, so a change of supporting foot glides.
pub const HIP_SHIFT_WINDOW: usize = 6;

/// World positions and rotations of every joint of one frame.
type WorldPose = (Vec<Vector3<f64>>, Vec<UnitQuaternion<f64>>);

/// One leg's goals in one frame: its floor goal, its reach goal, how firmly the foot stands
/// (1 on the floor, 0 lifted) and the target's hip joint, all before the hips move.
type LegGoals = (Vector3<f64>, Vector3<f64>, f64, Vector3<f64>);

/// How much a supporting foot's gap across its leg counts against its gap along it, when the hips
/// move to close the gaps. Along the leg a gap bends or stretches the knee (a nearly straight
/// knee 10-20° per centimetre); across, it only leans the leg. Counted alike, as they were, the
/// two feet's gaps across (3 cm either way sideways on a dancenet dance onto Mixamo: another hip
/// width) pulled the hips off what the legs' lengths asked for, the right knee 6.3° off
/// motion.json's (median); at this weight 3.5°, the hips up to 3 cm from where they went.
pub const ACROSS_LEG_WEIGHT: f64 = 0.03;

/// The target's joints by humanoid bone, checked: every bone once, the required ones present.
fn bone_index(target: &TargetSkeleton) -> Result<HashMap<HumanBone, usize>, RetargetError> {
    let n = target.rig.names.len();
    if n == 0
        || target.rig.parents.len() != n
        || target.rig.offsets.len() != n
        || target.humanoid.len() != n
    {
        return Err(RetargetError::InvalidTarget(format!(
            "{n} names, {} parents, {} offsets, {} humanoid entries",
            target.rig.parents.len(),
            target.rig.offsets.len(),
            target.humanoid.len()
        )));
    }
    if target.rig.parents.iter().filter(|p| p.is_none()).count() != 1
        || target
            .rig
            .parents
            .iter()
            .enumerate()
            .any(|(j, p)| p.is_some_and(|p| p >= n || p == j))
        || target.rig.order().len() != n
    {
        return Err(RetargetError::InvalidTarget(
            "the joints are not one tree with a single root".into(),
        ));
    }
    if target
        .rig
        .offsets
        .iter()
        .any(|o| !o.iter().all(|v| v.is_finite()))
    {
        return Err(RetargetError::InvalidTarget(
            "a rest offset is not finite".into(),
        ));
    }
    let mut index = HashMap::new();
    for (j, b) in target.humanoid.iter().enumerate() {
        if let Some(b) = b {
            if index.insert(*b, j).is_some() {
                return Err(RetargetError::DuplicateBone(*b));
            }
        }
    }
    if let Some(b) = REQUIRED.iter().find(|b| !index.contains_key(b)) {
        return Err(RetargetError::MissingBone(*b));
    }
    Ok(index)
}

/// Rest world positions (identity rotations, root at the origin).
fn rest_positions(rig: &crate::motion::rig::Rig) -> Vec<Vector3<f64>> {
    let ident = vec![UnitQuaternion::identity(); rig.names.len()];
    fk_frame(rig, &Vector3::zeros(), &ident).0
}

/// Everything about the target that does not change over frames.
struct Prepared {
    /// Per target joint: the aim, the driver's choreo index, the point sets as choreo indices,
    /// the target's rest direction and the rest alignment.
    aims: Vec<Option<PreparedAim>>,
    order: Vec<usize>,
    /// Target joint of each humanoid bone.
    bones: HashMap<HumanBone, usize>,
    rest: Vec<Vector3<f64>>,
    parents: Vec<Option<usize>>,
}

struct PreparedAim {
    driver: usize,
    from: Vec<usize>,
    to: Vec<usize>,
    rest_dir: Vector3<f64>,
    align: UnitQuaternion<f64>,
    /// Turned onto choreo's direction every frame (all but the feet, whose landmarks differ).
    exact: bool,
}

/// Puts a dance on choreo's rig onto `target`: see the module doc. The result is a motion on
/// `target.rig` with the same frame rate and frame count.
pub fn retarget(src: &RigMotion, target: &TargetSkeleton) -> Result<RigMotion, RetargetError> {
    let t_len = src.num_frames();
    if t_len == 0 || src.rotations.len() != t_len {
        return Err(RetargetError::EmptyMotion);
    }
    let choreo: HashMap<&str, usize> = src
        .rig
        .names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let cj = |name: &str| {
        choreo
            .get(name)
            .copied()
            .ok_or_else(|| RetargetError::NotChoreoMotion(name.to_string()))
    };
    for name in CHOREO_JOINTS {
        cj(name)?;
    }
    if src.rotations.iter().any(|f| f.len() != src.rig.names.len()) {
        return Err(RetargetError::NotChoreoMotion(
            "rotations do not match the joints".into(),
        ));
    }
    let bones = bone_index(target)?;
    let n = target.rig.names.len();
    let rest = rest_positions(&target.rig);
    let choreo_rest = rest_positions(&src.rig);
    let tpoint =
        |set: &[HumanBone]| mean(set.iter().filter_map(|b| bones.get(b)).map(|&j| rest[j]));

    // Choreo's world poses, its floor, and the frames each foot stands flat (heel and toe down).
    let choreo_frames: Vec<WorldPose> = (0..t_len)
        .map(|t| fk_frame(&src.rig, &src.root_translation[t], &src.rotations[t]))
        .collect();
    let foot_points: Vec<usize> = ["left_heel", "left_toe", "right_heel", "right_toe"]
        .iter()
        .filter_map(|s| choreo.get(s).copied())
        .collect();
    let mut lowest: Vec<f64> = choreo_frames
        .iter()
        .map(|(p, _)| {
            foot_points
                .iter()
                .map(|&k| p[k].y)
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    lowest.sort_by(f64::total_cmp);
    let choreo_floor = lowest[((lowest.len() - 1) as f64 * crate::motion::feet::FLOOR_PERCENTILE
        / 100.0)
        .round() as usize];
    let flat = |side: &str| -> Vec<usize> {
        let points: Vec<usize> = [format!("{side}_heel"), format!("{side}_toe")]
            .iter()
            .filter_map(|s| choreo.get(s.as_str()).copied())
            .collect();
        (0..t_len)
            .filter(|&t| {
                points.iter().all(|&k| {
                    choreo_frames[t].0[k].y - choreo_floor < crate::motion::feet::SUPPORT_HEIGHT_M
                })
            })
            .collect()
    };
    let flat_frames = [flat("left"), flat("right")];

    // Per-bone preparation: the target's rest direction and the rest alignment.
    let mut aims: Vec<Option<PreparedAim>> = (0..n).map(|_| None).collect();
    for (&b, &j) in &bones {
        let Some(a) = aim(b) else { continue };
        let from: Vec<usize> = a.from.iter().map(|s| cj(s)).collect::<Result<_, _>>()?;
        let to: Vec<usize> = a.to.iter().map(|s| cj(s)).collect::<Result<_, _>>()?;
        let driver = cj(a.driver)?;
        let choreo_dir =
            mean(to.iter().map(|&k| choreo_rest[k])) - mean(from.iter().map(|&k| choreo_rest[k]));
        let rest_dir = target_direction(target, &bones, &rest, j, &a, &tpoint);
        let second = if a.up { Vector3::y() } else { Vector3::z() };
        let mut align = UnitQuaternion::from_rotation_matrix(
            &(frame(&choreo_dir, &second) * frame(&rest_dir, &second).inverse()),
        );
        // Feet: choreo's toe marker and the target's toe joint are different landmarks (choreo's
        // ankle-to-toe line dips 40° on a flat foot, a rig's 10-20°), so a foot is aligned on the
        // frames where choreo's stands flat: there the target's foot is in its rest pitch, turned
        // only about the vertical to choreo's heading.
        let flat = match b {
            HumanBone::LeftFoot => Some(&flat_frames[0]),
            HumanBone::RightFoot => Some(&flat_frames[1]),
            _ => None,
        };
        if let Some(frames) = flat.filter(|f| !f.is_empty()) {
            align = mean_rotation(frames.iter().map(|&t| {
                let (pos, rot) = &choreo_frames[t];
                let d = mean(to.iter().map(|&k| pos[k])) - mean(from.iter().map(|&k| pos[k]));
                let heading = arc(
                    &Vector3::new(rest_dir.x, 0.0, rest_dir.z),
                    &Vector3::new(d.x, 0.0, d.z),
                );
                rot[driver].inverse() * heading
            }));
        }
        aims[j] = Some(PreparedAim {
            driver,
            from,
            to,
            rest_dir,
            align,
            exact: !a.up,
        });
    }
    let prepared = Prepared {
        aims,
        order: target.rig.order(),
        bones,
        rest,
        parents: target.rig.parents.clone(),
    };

    // Scale and floors.
    let leg =
        |a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>| (b - a).norm() + (c - b).norm();
    let tb = |b: HumanBone| prepared.rest[prepared.bones[&b]];
    let target_leg = 0.5
        * (leg(
            &tb(HumanBone::LeftUpperLeg),
            &tb(HumanBone::LeftLowerLeg),
            &tb(HumanBone::LeftFoot),
        ) + leg(
            &tb(HumanBone::RightUpperLeg),
            &tb(HumanBone::RightLowerLeg),
            &tb(HumanBone::RightFoot),
        ));
    let cr = |s: &str| choreo_rest[choreo[s]];
    let choreo_leg = 0.5
        * (leg(&cr("left_hip"), &cr("left_knee"), &cr("left_ankle"))
            + leg(&cr("right_hip"), &cr("right_knee"), &cr("right_ankle")));
    if !(target_leg > 1e-3 && choreo_leg > 1e-3) {
        return Err(RetargetError::InvalidTarget(format!(
            "leg lengths {target_leg:.3} m (target) and {choreo_leg:.3} m (dance)"
        )));
    }
    let scale = target_leg / choreo_leg;
    let target_floor = prepared
        .rest
        .iter()
        .map(|p| p.y)
        .fold(f64::INFINITY, f64::min);
    let target_ankle_h =
        0.5 * (tb(HumanBone::LeftFoot).y + tb(HumanBone::RightFoot).y) - target_floor;
    // Choreo's flat-foot ankle height per foot: the median over the frames that foot stands flat
    // (markers sit a little differently on either foot); both feet's median, or the rest pose's,
    // for a foot that never does.
    let flat_height = |ankle: &str, frames: &[usize]| -> Option<f64> {
        let mut h: Vec<f64> = frames
            .iter()
            .map(|&t| choreo_frames[t].0[choreo[ankle]].y - choreo_floor)
            .collect();
        h.sort_by(f64::total_cmp);
        h.get(h.len() / 2).copied()
    };
    let both: Vec<usize> = flat_frames.concat();
    let fallback = flat_height("left_ankle", &both).unwrap_or_else(|| {
        let heel = ["left_heel", "right_heel"]
            .iter()
            .filter_map(|s| choreo.get(s))
            .map(|&k| choreo_rest[k].y)
            .fold(f64::INFINITY, f64::min);
        cr("left_ankle").y - heel.min(cr("left_toe").y)
    });
    let choreo_ankle_h = [
        flat_height("left_ankle", &flat_frames[0]).unwrap_or(fallback),
        flat_height("right_ankle", &flat_frames[1]).unwrap_or(fallback),
    ];
    // Each leg's own ratio: choreo's legs differ by up to 2-3 cm (marker placement), the target's
    // need not, so a lifted foot keeps its knee angle with its own leg's ratio.
    let side_scale = [
        leg(
            &tb(HumanBone::LeftUpperLeg),
            &tb(HumanBone::LeftLowerLeg),
            &tb(HumanBone::LeftFoot),
        ) / leg(&cr("left_hip"), &cr("left_knee"), &cr("left_ankle")),
        leg(
            &tb(HumanBone::RightUpperLeg),
            &tb(HumanBone::RightLowerLeg),
            &tb(HumanBone::RightFoot),
        ) / leg(&cr("right_hip"), &cr("right_knee"), &cr("right_ankle")),
    ];
    let to_target =
        |p: &Vector3<f64>| Vector3::new(p.x * scale, (p.y - choreo_floor) * scale, p.z * scale);

    // 1–3: world rotations and the root per frame.
    let mut worlds = Vec::with_capacity(t_len);
    let mut roots = Vec::with_capacity(t_len);
    for (pos, rot) in &choreo_frames {
        let w = world_rotations(&prepared, pos, rot);
        // Root so the target's hip joints land on choreo's (scaled).
        let p0 = fk_world(&target.rig, &prepared.order, &Vector3::zeros(), &w);
        let target_hips = mean(
            [HumanBone::LeftUpperLeg, HumanBone::RightUpperLeg]
                .iter()
                .map(|b| p0[prepared.bones[b]]),
        );
        let choreo_hips = to_target(&mean(
            ["left_hip", "right_hip"].iter().map(|s| pos[choreo[s]]),
        ));
        roots.push(choreo_hips - target_hips);
        worlds.push(w);
    }

    // 4: ankle goals, the hips moved so that the feet on the floor reach it with the dance's own
    // knee angles, lowered further only where a goal is still out of reach, then two-bone IK.
    // A foot near the floor goes to its floor goal (the ankle over choreo's, at the target's own
    // flat-foot height plus choreo's lift, scaled); a lifted one to its reach goal (choreo's
    // hip-to-ankle vector at its leg's own ratio, from the target's hip), which keeps the knee's
    // angle; in between, a blend by the lowest foot point's height.
    // Per leg: the floor goal, the reach goal, how firmly the foot stands, the target's hip.
    let parts = |t: usize, root: &Vector3<f64>| -> [LegGoals; 2] {
        let (pos, _) = &choreo_frames[t];
        let p = fk_world(&target.rig, &prepared.order, root, &worlds[t]);
        let mut out = [(Vector3::zeros(), Vector3::zeros(), 0.0, Vector3::zeros()); 2];
        for (k, (thigh, _, _, ankle)) in LEGS.iter().enumerate() {
            let side = if k == 0 { "left" } else { "right" };
            let a = to_target(&pos[choreo[*ankle]]);
            let floor_goal =
                Vector3::new(a.x, target_ankle_h + a.y - scale * choreo_ankle_h[k], a.z);
            let hip = pos[choreo[format!("{side}_hip").as_str()]];
            let reach_goal = p[prepared.bones[thigh]] + side_scale[k] * (pos[choreo[*ankle]] - hip);
            let low = [format!("{side}_heel"), format!("{side}_toe")]
                .iter()
                .filter_map(|n| choreo.get(n.as_str()))
                .map(|&j| pos[j].y - choreo_floor)
                .fold(f64::INFINITY, f64::min);
            let support = crate::motion::feet::SUPPORT_HEIGHT_M;
            let on_floor = ((2.0 * support - low) / support).clamp(0.0, 1.0);
            out[k] = (floor_goal, reach_goal, on_floor, p[prepared.bones[thigh]]);
        }
        out
    };
    // The hips where choreo's are (scaled) leave a foot on the floor some centimetres from where
    // the leg reaches at the dance's knee angle (another hip width and height, other ankle
    // markers): 6-7 cm on a dancenet dance onto Mixamo, which the IK took up by bending the knees
    // (11-12° off motion.json's, median). The root moves instead, by the supporting feet's gap,
    // weighted by how firmly each stands and smoothed over ±HIP_SHIFT_WINDOW frames: the shift
    // that best closes every supporting foot's gap, its part along the leg first ([`leg_gap`]).
    let legs: Vec<_> = (0..t_len).map(|t| parts(t, &roots[t])).collect();
    let gaps: Vec<GapSum> = legs
        .iter()
        .map(|pr| {
            pr.iter()
                .fold(GapSum::default(), |sum, (floor, reach, on, hip)| {
                    sum.add(&leg_gap(floor, reach, hip), *on)
                })
        })
        .collect();
    let overall = gaps
        .iter()
        .fold(GapSum::default(), |a, g| a.merge(g))
        .shift()
        .unwrap_or_else(Vector3::zeros);
    let shifts: Vec<Vector3<f64>> = (0..t_len)
        .map(|t| {
            let lo = t.saturating_sub(HIP_SHIFT_WINDOW);
            let hi = (t + HIP_SHIFT_WINDOW + 1).min(t_len);
            let sum = gaps[lo..hi]
                .iter()
                .fold(GapSum::default(), |a, g| a.merge(g));
            match sum.shift() {
                Some(s) if sum.weight > 0.5 => s,
                _ => overall,
            }
        })
        .collect();
    for (root, shift) in roots.iter_mut().zip(&shifts) {
        *root += shift;
    }
    // The whole body moved with the root: each reach goal (from the hip) by the same shift.
    let goals: Vec<[Vector3<f64>; 2]> = legs
        .iter()
        .zip(&shifts)
        .map(|(pr, shift)| {
            pr.map(|(floor, reach, on, _)| floor * on + (reach + shift) * (1.0 - on))
        })
        .collect();
    let mut drop = vec![0.0f64; t_len];
    for t in 0..t_len {
        let p = fk_world(&target.rig, &prepared.order, &roots[t], &worlds[t]);
        for (k, (thigh, shin, foot, _)) in LEGS.iter().enumerate() {
            let (hip, knee, ankle) = (
                p[prepared.bones[thigh]],
                p[prepared.bones[shin]],
                p[prepared.bones[foot]],
            );
            let reach = MAX_REACH * ((knee - hip).norm() + (ankle - knee).norm());
            let g = goals[t][k];
            let horizontal = ((g.x - hip.x).powi(2) + (g.z - hip.z).powi(2))
                .sqrt()
                .min(reach);
            let need = (hip.y - g.y) - (reach * reach - horizontal * horizontal).sqrt();
            drop[t] = drop[t].max(need);
        }
    }
    let drop = spread_max(&drop, DROP_WINDOW);
    let mut rotations = Vec::with_capacity(t_len);
    for t in 0..t_len {
        roots[t].y -= drop[t];
        let w = &mut worlds[t];
        for (k, (thigh, shin, foot, _)) in LEGS.iter().enumerate() {
            let p = fk_world(&target.rig, &prepared.order, &roots[t], w);
            let (jt, js, jf) = (
                prepared.bones[thigh],
                prepared.bones[shin],
                prepared.bones[foot],
            );
            two_bone_ik(w, jt, js, jf, p[jt], p[js], p[jf], goals[t][k]);
        }
        rotations.push(locals(&target.rig, w));
    }
    // 5: the lower arms turn no faster than choreo's joints.
    limit_lower_arms(&prepared, &mut rotations, src.fps);
    make_continuous(&mut rotations);
    Ok(RigMotion {
        rig: target.rig.clone(),
        fps: src.fps,
        root_translation: roots,
        rotations,
    })
}

/// The target's rest direction of bone `j` for its aim: the target's point sets when it has
/// them; else (an end bone whose next bone the target lacks, e.g. a foot without toes) the mean
/// of its children, or the continuation of its parent's bone.
fn target_direction(
    target: &TargetSkeleton,
    bones: &HashMap<HumanBone, usize>,
    rest: &[Vector3<f64>],
    j: usize,
    a: &Aim,
    tpoint: &dyn Fn(&[HumanBone]) -> Vector3<f64>,
) -> Vector3<f64> {
    let has = |set: &[HumanBone]| set.iter().any(|b| bones.contains_key(b));
    if has(a.target_from) && has(a.target_to) {
        let d = tpoint(a.target_to) - tpoint(a.target_from);
        if d.norm() > 1e-6 {
            return d;
        }
    }
    let kids = target.rig.children(j);
    let from = if has(a.target_from) {
        tpoint(a.target_from)
    } else {
        rest[j]
    };
    if !kids.is_empty() {
        let d = mean(kids.iter().map(|&c| rest[c])) - from;
        if d.norm() > 1e-6 {
            return d;
        }
    }
    match target.rig.parents[j] {
        Some(p) if (rest[j] - rest[p]).norm() > 1e-6 => rest[j] - rest[p],
        _ => Vector3::y(),
    }
}

/// World rotations of every target joint for one choreo frame (steps 1 and 2 of the module doc).
fn world_rotations(
    p: &Prepared,
    pos: &[Vector3<f64>],
    rot: &[UnitQuaternion<f64>],
) -> Vec<UnitQuaternion<f64>> {
    let n = p.aims.len();
    let mut w = vec![UnitQuaternion::identity(); n];
    for &j in &p.order {
        let inherited = |w: &[UnitQuaternion<f64>]| parent_world(p, w, j);
        w[j] = match &p.aims[j] {
            Some(a) => {
                let g = rot[a.driver] * a.align;
                if a.exact {
                    let d =
                        mean(a.to.iter().map(|&k| pos[k])) - mean(a.from.iter().map(|&k| pos[k]));
                    arc(&(g * a.rest_dir), &d) * g
                } else {
                    g
                }
            }
            None => inherited(&w),
        };
    }
    use HumanBone as B;
    let spine: Vec<usize> = [B::Spine, B::Chest, B::UpperChest]
        .iter()
        .filter_map(|b| p.bones.get(b).copied())
        .collect();
    if let (Some(&hips), Some(&first)) = (p.bones.get(&B::Hips), spine.first()) {
        let torso = w[first];
        if let Some(a) = &p.aims[first] {
            spread_torso(&mut w, hips, &spine, torso, &a.rest_dir);
        }
        if let Some(&head) = p.bones.get(&B::Head) {
            if let Some(a) = &p.aims[head] {
                face_with_torso(&mut w[head], &torso, &a.rest_dir);
            }
            // The neck halfway from the torso to the head.
            if let Some(&neck) = p.bones.get(&B::Neck) {
                w[neck] = torso.slerp(&w[head], 0.5);
            }
        }
    }
    // Joints that follow their parent take its final rotation (the spine and neck moved above).
    for &j in &p.order {
        if p.aims[j].is_none() {
            w[j] = parent_world(p, &w, j);
        }
    }
    w
}

/// The world rotation a joint with rest local rotation has: its parent's (identity at the root).
fn parent_world(p: &Prepared, w: &[UnitQuaternion<f64>], j: usize) -> UnitQuaternion<f64> {
    match p.parent_of(j) {
        Some(par) => w[par],
        None => UnitQuaternion::identity(),
    }
}

impl Prepared {
    fn parent_of(&self, j: usize) -> Option<usize> {
        self.parents.get(j).copied().flatten()
    }
}
