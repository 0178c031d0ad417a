//! Least-squares inverse kinematics, for motions with key poses: bone lengths fitted to the key
//! frames, every frame refined over all 23 joints with the root free (Levenberg–Marquardt).
use nalgebra::{DMatrix, DVector, UnitQuaternion, Vector3};
use ndarray::{ArrayView2, ArrayView3, Axis};

use super::chain::{solve, solve_aimed, Aim};
use super::continuity::{limit_turn, max_turn};
use super::keyed::solve_keyed;
use super::{fk_frame, rig_index, targets, Rig, RigMotion};
use crate::motion::{skeleton, MotionError, NUM_JOINTS};

/// Fits a rig to a motion and solves its rotations in one go.
///
/// Without `anchors` the skeleton is fitted to every frame (median bone lengths) and each frame
/// solved by the chain IK of [`solve`]. With `anchors` (frame indices, the user's key poses) the
/// skeleton is fitted to those frames, so the body the user posed is the body that dances and
/// those frames come back as posed as far as one rigid skeleton can take them: its bone lengths
/// are the least-squares best for the anchor frames ([`Rig::fit_lengths`], starting from the
/// anchors' medians), and every frame is solved in least squares ([`solve_least_squares`]).
pub fn fit_and_solve(
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
    anchors: &[usize],
) -> Result<RigMotion, MotionError> {
    fit_and_solve_seeded(positions, root, fps, anchors, 0, Aim::FittedEnds)
}

/// [`fit_and_solve`] for a dance whose first `skeleton_frames` frames are a request's seed
/// motion: without anchors the skeleton is fitted on those frames alone (below), and each bone
/// aimed as `aim` says. With anchors the least squares place the joints: on every frame for
/// [`Aim::FittedEnds`], near the anchors only for [`Aim::DanceBones`] ([`solve_keyed`]).
pub fn fit_and_solve_seeded(
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
    anchors: &[usize],
    skeleton_frames: usize,
    aim: Aim,
) -> Result<RigMotion, MotionError> {
    let mut keep: Vec<usize> = anchors
        .iter()
        .copied()
        .filter(|&f| f < positions.dim().0)
        .collect();
    keep.sort_unstable();
    keep.dedup();
    if keep.is_empty() {
        // A seed motion's frames are the body the dance goes on with: fitted on them alone, the
        // skeleton is theirs, and they come back as they were (a dance's own first second fed
        // back came back up to 8.6 cm off when the skeleton was fitted on the whole new dance,
        // whose network-drawn bones have other median lengths and rest directions).
        let t = positions.dim().0;
        let rig = if (2..t).contains(&skeleton_frames) {
            Rig::fit(
                positions.slice(ndarray::s![..skeleton_frames, .., ..]),
                root.slice(ndarray::s![..skeleton_frames, ..]),
            )?
        } else {
            Rig::fit(positions, root)?
        };
        return solve_aimed(&rig, positions, root, fps, aim);
    }
    let (key_positions, key_root) = (
        positions.select(Axis(0), &keep),
        root.select(Axis(0), &keep),
    );
    let mut rig = Rig::fit(key_positions.view(), key_root.view())?;
    rig.fit_lengths(
        key_positions.view(),
        key_root.view(),
        aim == Aim::DanceBones,
    )?;
    match aim {
        Aim::FittedEnds => solve_least_squares(&rig, positions, root, fps),
        Aim::DanceBones => solve_keyed(&rig, positions, root, fps, &keep, aim),
    }
}

/// Rounds of [`Rig::fit_lengths`]' alternation between the frames' poses and the bone lengths.
/// Over the 258 sets of 4–5 captured poses of `tests/motion.rs` `captured_key_sets_of_every_dance`,
/// the worst key of a set comes back (median over sets) 2.08 cm off with no round, 1.87 after 1,
/// 1.77 after 4, 1.72 after 8, 1.67 after 16 and 1.68 after 32 (measured 2026-11-25).
const LENGTH_ROUNDS: usize = 16;

/// Rounds of [`Rig::fit_lengths`] after [`LENGTH_ROUNDS`] that fit the lengths for the key frames'
/// mean joint distance instead of the squared one (as `keyed::fit_key_frame` poses them).
const LENGTH_REWEIGHT_ROUNDS: usize = 8;

impl Rig {
    /// Refits the bone lengths (rest directions kept) to the frames `positions` `[K, 23, 3]`
    /// around `root` `[K, 3]` in least squares: each frame is posed by [`fit_frame`] (root
    /// free), then the lengths that bring the 23 joints of all frames closest to their targets
    /// are solved at once (positions are linear in the lengths once the rotations are fixed, and
    /// each frame's root translation is free), `LENGTH_ROUNDS` times. The spine's offset from
    /// the body centre is kept: with every frame's root free, it and the pelvis's could slide
    /// together without changing any joint.
    ///
    /// With `for_distance` (served dances, whose key frames `keyed::fit_key_frame` poses), then
    /// `LENGTH_REWEIGHT_ROUNDS` more for the mean joint distance. Not for captured dances'
    /// keys, posed in least squares with every other frame: lengths for the mean distance under
    /// poses for the squared one left 8 of `tests/motion.rs`' 258 key sets over 3 cm (5 before)
    /// and added acceleration near a key.
    pub fn fit_lengths(
        &mut self,
        positions: ArrayView3<'_, f32>,
        root: ArrayView2<'_, f32>,
        for_distance: bool,
    ) -> Result<(), MotionError> {
        let tg = targets(positions, root)?;
        // Unrelated poses, not a motion: no limit on how far a joint turns from one to the next.
        let chain = solve(self, positions, root, f64::NAN)?;
        let mut poses: Vec<(Vector3<f64>, Vec<UnitQuaternion<f64>>)> = chain
            .root_translation
            .into_iter()
            .zip(chain.rotations)
            .collect();
        let even = vec![vec![1.0; NUM_JOINTS]; tg.len()];
        for _ in 0..LENGTH_ROUNDS {
            poses = poses
                .iter()
                .zip(&tg)
                .map(|((r, l), t)| fit_frame(self, r, l, t))
                .collect();
            self.solve_lengths(&poses, &tg, &even);
        }
        let reached = || {
            poses
                .iter()
                .zip(&tg)
                .all(|((r, l), t)| centred_mean_distance(self, r, l, t) < REWEIGHT_FROM_M)
        };
        if !for_distance || reached() {
            return Ok(());
        }
        // Then for the mean joint distance, as `keyed::fit_key_frame` poses the key frames: each
        // frame's joints reweighted by the inverse of their distance.
        for _ in 0..LENGTH_REWEIGHT_ROUNDS {
            let weights: Vec<Vec<f64>> = poses
                .iter()
                .zip(&tg)
                .map(|((r, l), t)| inverse_distance_weights(self, r, l, t))
                .collect();
            poses = poses
                .iter()
                .zip(&tg)
                .zip(&weights)
                .map(|(((r, l), t), w)| fit_frame_weighted(self, r, l, t, ROTATION_PRIOR_M, w))
                .collect();
            self.solve_lengths(&poses, &tg, &weights);
        }
        Ok(())
    }

    /// One least-squares solve of the bone lengths for posed frames; see [`Rig::fit_lengths`].
    fn solve_lengths(
        &mut self,
        poses: &[(Vector3<f64>, Vec<UnitQuaternion<f64>>)],
        tg: &[Vec<Vector3<f64>>],
        weights: &[Vec<f64>],
    ) {
        let spine = rig_index(skeleton::SPINE);
        let bones: Vec<usize> = (0..self.parents.len())
            .filter(|&j| self.parents[j].is_some() && j != spine && self.offsets[j].norm() > 1e-6)
            .collect();
        let dirs: Vec<Vector3<f64>> = bones.iter().map(|&b| self.offsets[b].normalize()).collect();
        // Normal equations in the lengths. Each frame's root translation is free, and its best
        // value centres the frame's residuals, so every frame's rows are taken about their mean
        // over the joints.
        let mut ata = DMatrix::<f64>::zeros(bones.len(), bones.len());
        let mut atb = DVector::<f64>::zeros(bones.len());
        for (((_, local), frame), w) in poses.iter().zip(tg).zip(weights) {
            let (_, world) = fk_frame(self, &Vector3::zeros(), local);
            // rows[c][i]: joint i's coordinate c as lengths · coefficients, rhs[c][i] the rest.
            let mut rows = vec![DMatrix::<f64>::zeros(NUM_JOINTS, bones.len()); 3];
            let mut rhs = vec![DVector::<f64>::zeros(NUM_JOINTS); 3];
            for (i, j) in (0..NUM_JOINTS).map(rig_index).enumerate() {
                // p_j = root + Σ over the bones above j of world[parent] · offset: the unknown
                // lengths times their world directions, plus the bones kept as they are.
                let mut known = Vector3::<f64>::zeros();
                let mut k = j;
                while let Some(p) = self.parents[k] {
                    match bones.iter().position(|&b| b == k) {
                        Some(u) => {
                            let v = world[p] * dirs[u];
                            for c in 0..3 {
                                rows[c][(i, u)] = v[c];
                            }
                        }
                        None => known += world[p] * self.offsets[k],
                    }
                    k = p;
                }
                for c in 0..3 {
                    rhs[c][i] = frame[j][c] - known[c];
                }
            }
            // Weighted, the free root centres the residuals on their weighted mean.
            let total: f64 = w.iter().sum();
            for c in 0..3 {
                let mut mean_row = DMatrix::<f64>::zeros(1, bones.len());
                let mut mean_b = 0.0;
                for (i, wi) in w.iter().enumerate() {
                    mean_row += rows[c].row(i) * (wi / total);
                    mean_b += rhs[c][i] * wi / total;
                }
                let mut a = rows[c].clone();
                let mut b = rhs[c].add_scalar(-mean_b);
                for (i, wi) in w.iter().enumerate() {
                    let mut r = a.row_mut(i);
                    r -= &mean_row;
                    r *= wi.sqrt();
                    b[i] *= wi.sqrt();
                }
                ata += a.transpose() * &a;
                atb += a.transpose() * b;
            }
        }
        // A light pull towards the current lengths keeps a bone that no frame pins down.
        for (i, &b) in bones.iter().enumerate() {
            ata[(i, i)] += 1e-4;
            atb[i] += 1e-4 * self.offsets[b].norm();
        }
        let Some(x) = ata.cholesky().map(|ch| ch.solve(&atb)) else {
            return;
        };
        for (i, &b) in bones.iter().enumerate() {
            // A bone is never shorter than 1 cm (none of the data's is).
            if x[i].is_finite() && x[i] > 0.01 {
                self.offsets[b] = dirs[i] * x[i];
            }
        }
    }
}

/// Inverse kinematics in least squares: each frame of `positions` around the body-centre track
/// `root` is [`solve`]'s chain solution refined by [`fit_frame`], so where the data's bone lengths
/// differ from the rig's the mismatch is spread over the body rather than piled on the ends of its
/// chains, and the root sits where the body fits best.
///
/// The root's own rotation is [`solve`]'s (the facing yaw tilted onto the spine), kept through
/// the fit; so is every twist the positions leave free (the fit's pull towards its start holds
/// them), which [`solve`] carries from frame to frame.
///
/// No joint turns faster than [`super::continuity::MAX_TURN_DEG_PER_S`] at `fps`, as in
/// [`solve`] (`fps` no number: unrelated poses, each solved on its own).
///
/// Each frame starts from its own chain solution, not from the previous frame's fit: started from
/// the previous frame, the fits of a captured dance drift into a wrong pose within 20 s (mean joint
/// error 2 → 45 cm on DANCE_W_3) and stay there, while the chain solutions move as smoothly as the
/// data (acceleration p99.9 25.3 m/s² against the data's 26.3).
pub fn solve_least_squares(
    rig: &Rig,
    positions: ArrayView3<'_, f32>,
    root: ArrayView2<'_, f32>,
    fps: f64,
) -> Result<RigMotion, MotionError> {
    let tg = targets(positions, root)?;
    let chain = solve(rig, positions, root, fps)?;
    // The fit follows the data where its bones jump (the chain's start did not); the turns are
    // limited again, as the chain limits them.
    let max = max_turn(fps);
    let mut root_translation = Vec::with_capacity(tg.len());
    let mut rotations: Vec<Vec<UnitQuaternion<f64>>> = Vec::with_capacity(tg.len());
    for (t, frame) in tg.iter().enumerate() {
        let (chain_root, chain_local) = (&chain.root_translation[t], &chain.rotations[t]);
        let (root, fit) =
            fit_within_turn(rig, rotations.last(), chain_root, chain_local, frame, max);
        root_translation.push(root);
        rotations.push(fit);
    }
    Ok(RigMotion {
        rig: rig.clone(),
        fps,
        root_translation,
        rotations,
    })
}

/// [`fit_frame`] from the chain's pose of a frame, no joint turning further than `max` from
/// `prev` (the frame before, as kept).
///
/// The fit can turn a joint about a direction its targets leave nearly free (the pelvis about the
/// hips' line, its thighs turning back) for a few millimetres closer: keypose-transformer,
/// DANCE_R_9 seed 1, the pelvis 127° from the frame before, caught half-way by the turn limit, the
/// legs 15–20 cm off (96 m/s²). So a frame the limit catches is fitted again held closer to the
/// chain's rotations (which turned it 1°), and the closer of the two, turn-limited, is kept.
fn fit_within_turn(
    rig: &Rig,
    prev: Option<&Vec<UnitQuaternion<f64>>>,
    chain_root: &Vector3<f64>,
    chain_local: &[UnitQuaternion<f64>],
    frame: &[Vector3<f64>],
    max: f64,
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    let (root, fit) = fit_frame(rig, chain_root, chain_local, frame);
    let Some(prev) = prev.filter(|p| p.iter().zip(&fit).any(|(p, c)| p.angle_to(c) > max)) else {
        return (root, fit);
    };
    let limited = |fit: Vec<UnitQuaternion<f64>>| -> Vec<_> {
        prev.iter()
            .zip(fit)
            .map(|(p, c)| limit_turn(*p, c, max))
            .collect()
    };
    let first = limited(fit);
    let (held_root, held) = fit_frame_held(rig, chain_root, chain_local, frame, HELD_PRIOR_M);
    let held = limited(held);
    if position_error(rig, &held_root, &held, frame) < position_error(rig, &root, &first, frame) {
        (held_root, held)
    } else {
        (root, first)
    }
}

/// Sum of squared distances (m²) of the 23 dataset joints of `rig` posed by `root`, `local` from
/// their targets `target` (rig-indexed).
pub(super) fn position_error(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
) -> f64 {
    squared_distance(&fk_frame(rig, root, local).0, target)
}

/// Sum of squared distances (m²) of the 23 dataset joints of rig-indexed positions `pos` from
/// their targets `target`.
fn squared_distance(pos: &[Vector3<f64>], target: &[Vector3<f64>]) -> f64 {
    (0..NUM_JOINTS)
        .map(rig_index)
        .map(|j| (pos[j] - target[j]).norm_squared())
        .sum()
}

/// The pull towards the chain's rotations of a frame fitted again where the turn limit caught its
/// first fit (10 cm per radian).
const HELD_PRIOR_M: f64 = 0.1;

/// Most Levenberg–Marquardt steps of [`fit_frame`]; 200 change no key error on the test dances.
const FIT_ITERATIONS: usize = 50;

/// [`fit_frame`] stops when a step lowers its cost by less than this fraction. 1e-12 takes 2.3×
/// as long and moves no key error and no acceleration percentile of DANCE_W_3 by 0.01.
const FIT_TOLERANCE: f64 = 1e-6;

/// [`fit_frame`]'s pull towards the rotations it starts from: a joint turned θ radians away
/// costs as much as a joint `ROTATION_PRIOR_M · θ` metres off its target. It settles what the
/// targets leave free and is too weak to hold anything else (1 cm per radian).
pub(super) const ROTATION_PRIOR_M: f64 = 0.01;

/// Refits one frame of `rig` in least squares, starting from `root` and `local`: the root
/// translation and the rotation of every joint with children but the root (whose rotation is
/// kept) that bring the 23 dataset joints closest to `target` (rig-indexed, as `targets` builds
/// it) in the sum of squared distances, plus `ROTATION_PRIOR_M`'s pull towards `local`, by
/// Levenberg–Marquardt.
///
/// [`solve`] points each bone at its child's target from the parent's already-fitted end: where
/// the data's bone lengths differ from the rig's the whole mismatch lands on the chain's far end
/// (a thigh 5 cm longer than the rig's puts the knee, ankle, heel and toe 5 cm off), and the root
/// is the body centre (for generated motion the joints' weighted centroid, no rigid point of the
/// body), from which the spine is put at a fixed distance that the data's varies by 10–20 cm
/// when the body bends. This fit spreads the mismatch over every joint and moves the root where
/// the body fits best.
pub fn fit_frame(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    fit_frame_held(rig, root, local, target, ROTATION_PRIOR_M)
}

/// [`fit_frame`] with the pull towards `local` of `prior_m` metres per radian.
fn fit_frame_held(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
    prior_m: f64,
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    fit_frame_weighted(rig, root, local, target, prior_m, &[1.0; NUM_JOINTS])
}

/// A key frame whose least-squares pose is this close (mean joint distance, m) keeps it, and so
/// do the bone lengths when every key frame is: the mean-distance pose moves more joints further
/// from the chain's pose, and that correction, faded over [`KEY_REACH_S`], accelerates the frames
/// around the key (DANCE_C_8 with four of its own poses as keys: 24.3 → 25.4 m/s² within half a
/// second of a key, the data's 22.1, keys 1.1–2.2 cm in either case). Keys are promised within
/// 3 cm ([`crate::motion::limits::KEY_POSE_CM`]).
pub(super) const REWEIGHT_FROM_M: f64 = 0.025;

/// The mean distance (m) of the 23 dataset joints of `rig` posed by `root`, `local` from their
/// targets, each set taken about its centroid (as `metrics::kinematics::key_pose_errors_cm`
/// measures a key).
pub(super) fn centred_mean_distance(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
) -> f64 {
    let pos = fk_frame(rig, root, local).0;
    let off: Vec<Vector3<f64>> = (0..NUM_JOINTS)
        .map(rig_index)
        .map(|j| pos[j] - target[j])
        .collect();
    let mean = off.iter().sum::<Vector3<f64>>() / NUM_JOINTS as f64;
    off.iter().map(|o| (o - mean).norm()).sum::<f64>() / NUM_JOINTS as f64
}

/// Weiszfeld's weights for a pose of `rig`: each dataset joint's inverse distance from its
/// target, scaled to a mean of 1. A joint on its target would take all the weight, so none is
/// counted closer than 1 mm.
pub(super) fn inverse_distance_weights(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
) -> Vec<f64> {
    let pos = fk_frame(rig, root, local).0;
    let inverse: Vec<f64> = (0..NUM_JOINTS)
        .map(rig_index)
        .map(|j| 1.0 / (pos[j] - target[j]).norm().max(1e-3))
        .collect();
    let mean = inverse.iter().sum::<f64>() / NUM_JOINTS as f64;
    inverse.iter().map(|w| w / mean).collect()
}

/// [`fit_frame_held`] with each dataset joint's squared distance weighted by `weights` (in the
/// dataset's joint order).
pub(super) fn fit_frame_weighted(
    rig: &Rig,
    root: &Vector3<f64>,
    local: &[UnitQuaternion<f64>],
    target: &[Vector3<f64>],
    prior_m: f64,
    weights: &[f64],
) -> (Vector3<f64>, Vec<UnitQuaternion<f64>>) {
    let measured: Vec<usize> = (0..NUM_JOINTS).map(rig_index).collect();
    let root_w: Vec<f64> = weights.iter().map(|w| w.sqrt()).collect();
    let movers: Vec<usize> = (0..rig.names.len())
        .filter(|&j| rig.parents[j].is_some() && !rig.children(j).is_empty())
        .collect();
    let is_below = |j: usize, k: usize| {
        let mut a = rig.parents[j];
        while let Some(p) = a {
            if p == k {
                return true;
            }
            a = rig.parents[p];
        }
        false
    };
    // below[m][i]: measured joint i moves with mover m's rotation.
    let below: Vec<Vec<bool>> = movers
        .iter()
        .map(|&k| measured.iter().map(|&j| is_below(j, k)).collect())
        .collect();
    let start = local.to_vec();
    // A mover's turn away from its start, as a rotation vector in world axes.
    let turn =
        |k: usize, local: &[UnitQuaternion<f64>], world: &[UnitQuaternion<f64>]| -> Vector3<f64> {
            let d = start[k].inverse() * local[k];
            let d = if d.w < 0.0 {
                UnitQuaternion::new_unchecked(-d.into_inner())
            } else {
                d
            };
            world[k] * d.scaled_axis()
        };
    let cost_of = |root: &Vector3<f64>, local: &[UnitQuaternion<f64>]| {
        let (pos, world) = fk_frame(rig, root, local);
        let c = measured
            .iter()
            .zip(weights)
            .map(|(&j, w)| w * (pos[j] - target[j]).norm_squared())
            .sum::<f64>()
            + movers
                .iter()
                .map(|&k| (turn(k, local, &world) * prior_m).norm_squared())
                .sum::<f64>();
        (c, pos, world)
    };
    let mut root = *root;
    let mut local = local.to_vec();
    let (mut cost, mut pos, mut world) = cost_of(&root, &local);
    let params = 3 + 3 * movers.len();
    let rows = 3 * measured.len() + 3 * movers.len();
    let mut lambda = 1e-3;
    for _ in 0..FIT_ITERATIONS {
        // Residuals and Jacobian: the root translation moves every joint; a world-frame turn ω
        // of mover k moves a joint j below it by ω × (p_j − p_k) and adds ω to k's own turn.
        let mut jac = DMatrix::<f64>::zeros(rows, params);
        let mut res = DVector::<f64>::zeros(rows);
        for (i, &j) in measured.iter().enumerate() {
            let (r, w) = (pos[j] - target[j], root_w[i]);
            for c in 0..3 {
                res[3 * i + c] = w * r[c];
                jac[(3 * i + c, c)] = w;
            }
            for (m, &k) in movers.iter().enumerate() {
                if below[m][i] {
                    // ω × d = −[d]× ω
                    jac.view_mut((3 * i, 3 + 3 * m), (3, 3))
                        .copy_from(&(-(pos[j] - pos[k]).cross_matrix() * w));
                }
            }
        }
        for (m, &k) in movers.iter().enumerate() {
            let row = 3 * measured.len() + 3 * m;
            let r = turn(k, &local, &world) * prior_m;
            for c in 0..3 {
                res[row + c] = r[c];
                jac[(row + c, 3 + 3 * m + c)] = prior_m;
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * &res;
        let mut improved = false;
        for _ in 0..10 {
            let mut a = jtj.clone();
            for d in 0..params {
                a[(d, d)] += lambda * (jtj[(d, d)] + 1e-9);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-&jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let new_root = root + Vector3::new(step[0], step[1], step[2]);
            let mut new_local = local.clone();
            for (m, &k) in movers.iter().enumerate() {
                let w = Vector3::new(step[3 + 3 * m], step[4 + 3 * m], step[5 + 3 * m]);
                let parent_world = rig.parents[k].map_or(UnitQuaternion::identity(), |p| world[p]);
                new_local[k] =
                    parent_world.inverse() * UnitQuaternion::from_scaled_axis(w) * world[k];
            }
            let (c, p, w) = cost_of(&new_root, &new_local);
            if c < cost {
                improved = cost - c > FIT_TOLERANCE * cost;
                (root, local, cost, pos, world) = (new_root, new_local, c, p, w);
                lambda = (lambda / 3.0).max(1e-9);
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (root, local)
}
