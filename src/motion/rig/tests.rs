use super::*;
use ndarray::{Array2, Axis};

/// A rig with random offsets, the branch joints on the spine as [`Rig::fit`] puts them.
fn random_rig(rng: &mut impl rand::Rng) -> Rig {
    let (names, parents) = hierarchy();
    let mut offsets: Vec<Vector3<f64>> = (0..RIG_JOINTS)
        .map(|j| {
            if j == 0 {
                Vector3::zeros()
            } else {
                Vector3::new(
                    rng.gen_range(-0.2..0.2),
                    rng.gen_range(-0.3..0.3),
                    rng.gen_range(-0.2..0.2),
                )
            }
        })
        .collect();
    offsets[NUM_JOINTS + 1] = offsets[rig_index(super::super::skeleton::SPINE)];
    offsets[NUM_JOINTS + 2] = Vector3::zeros();
    Rig {
        names,
        parents,
        offsets,
    }
}

/// The 23 dataset joints of posed frames, `[T, 23, 3]`, and the root track `[T, 3]`.
fn arrays(
    rig: &Rig,
    roots: &[Vector3<f64>],
    locals: &[Vec<UnitQuaternion<f64>>],
) -> (Array3<f32>, Array2<f32>) {
    let t_len = roots.len();
    let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
    let mut root = Array2::zeros((t_len, 3));
    for t in 0..t_len {
        let p = fk_frame(rig, &roots[t], &locals[t]).0;
        for c in 0..3 {
            root[[t, c]] = roots[t][c] as f32;
            for j in 0..NUM_JOINTS {
                pos[[t, j, c]] = p[rig_index(j)][c] as f32;
            }
        }
    }
    (pos, root)
}

fn random_rotation(rng: &mut impl rand::Rng, size: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(
        rng.gen_range(-size..size),
        rng.gen_range(-size..size),
        rng.gen_range(-size..size),
    )
}

/// Mean distance (cm) over the 23 joints between two frames, each centred on its joints'
/// centroid: the key-pose error of `metrics::kinematics::key_pose_errors_cm`.
fn centred_error_cm(a: ArrayView2<'_, f32>, b: ArrayView2<'_, f32>) -> f64 {
    let mean = |x: ArrayView2<'_, f32>| x.mean_axis(Axis(0)).expect("joints");
    let (ca, cb) = (mean(a), mean(b));
    let sum: f64 = (0..NUM_JOINTS)
        .map(|j| {
            (0..3)
                .map(|c| f64::from(a[[j, c]] - ca[c] - b[[j, c]] + cb[c]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum();
    100.0 * sum / NUM_JOINTS as f64
}

/// A rigid skeleton posed with random rotations: IK must recover its positions exactly, of
/// unrelated poses (no frame rate: no limit on the turns between them) and of a motion (each
/// joint turning steadily, up to 8° a frame, from a random pose).
#[test]
fn ik_of_a_rigid_motion_is_exact() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let rig = random_rig(&mut rng);
    let t_len = 20;
    let roots: Vec<Vector3<f64>> = (0..t_len)
        .map(|t| Vector3::new(0.1 * t as f64, 1.0, 0.0))
        .collect();
    let poses: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
        .map(|_| {
            (0..RIG_JOINTS)
                .map(|_| random_rotation(&mut rng, 1.0))
                .collect()
        })
        .collect();
    let spin: Vec<Vector3<f64>> = (0..RIG_JOINTS)
        .map(|_| Vector3::from_fn(|_, _| rng.gen_range(-0.08..0.08)))
        .collect();
    let motion: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
        .map(|t| {
            (0..RIG_JOINTS)
                .map(|j| UnitQuaternion::from_scaled_axis(spin[j] * t as f64) * poses[0][j])
                .collect()
        })
        .collect();
    for (locals, fps) in [(&poses, f64::NAN), (&motion, 25.0)] {
        let (pos, root) = arrays(&rig, &roots, locals);
        for m in [
            solve(&rig, pos.view(), root.view(), fps).expect("solve"),
            solve_least_squares(&rig, pos.view(), root.view(), fps).expect("solve"),
        ] {
            let back = m.joint_positions();
            let err = joint_errors(back.view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
            assert!(err < 1e-4, "{fps} fps: max error {err} m");
        }
    }
}

/// A nearly straight right arm swinging forward and back while its elbow bend (±1.5°) changes
/// side: the positions leave the arm's twist free, and a frame solved on its own picks it from
/// whichever side the bend is on, half a turn apart. Carried from frame to frame, no
/// joint turns past 60° between frames, and the positions stay exact.
#[test]
fn a_straight_arm_keeps_its_twist() {
    use crate::metrics::rotation_flips::RotationFlips;
    use crate::motion::skeleton::JOINT_NAMES;
    use rand::SeedableRng;
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let mut rig = random_rig(&mut rng);
    let arm = |name: &str| rig_index(JOINT_NAMES.iter().position(|n| *n == name).expect("joint"));
    let (shoulder, elbow) = (arm("right_shoulder"), arm("right_elbow"));
    let d = Vector3::new(-1.0, -0.3, 0.1).normalize();
    for (name, len) in [
        ("right_elbow", 0.30),
        ("right_forearm", 0.13),
        ("right_wrist", 0.12),
        ("right_hand_dir", 0.05),
    ] {
        rig.offsets[arm(name)] = d * len;
    }
    let swing_axis = Unit::new_normalize(d.cross(&Vector3::y()));
    let bend_axis = Unit::new_normalize(d.cross(&swing_axis));
    let t_len = 100;
    let pose: Vec<UnitQuaternion<f64>> = (0..RIG_JOINTS)
        .map(|_| random_rotation(&mut rng, 0.3))
        .collect();
    let locals: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
        .map(|t| {
            let s = std::f64::consts::TAU * t as f64 / t_len as f64;
            let mut l = pose.clone();
            for j in [arm("right_forearm"), arm("right_wrist")] {
                l[j] = UnitQuaternion::identity();
            }
            l[shoulder] = UnitQuaternion::from_axis_angle(&swing_axis, 1.2 * s.sin());
            l[elbow] =
                UnitQuaternion::from_axis_angle(&bend_axis, 1.5f64.to_radians() * (2.0 * s).sin());
            l
        })
        .collect();
    let roots = vec![Vector3::new(0.0, 1.0, 0.0); t_len];
    let (pos, root) = arrays(&rig, &roots, &locals);
    let one_by_one: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
        .map(|t| {
            let s = ndarray::s![t..t + 1, .., ..];
            solve(
                &rig,
                pos.slice(s),
                root.slice(ndarray::s![t..t + 1, ..]),
                25.0,
            )
            .expect("solve")
            .rotations
            .remove(0)
        })
        .collect();
    let before = RotationFlips::of(&RigMotion {
        rig: rig.clone(),
        fps: 25.0,
        root_translation: roots.clone(),
        rotations: one_by_one,
    });
    eprintln!("frame by frame: {before:?}");
    assert!(
        before.steps_over_90 > 0,
        "the test's arm does not flip frame by frame: {before:?}"
    );
    for m in [
        solve(&rig, pos.view(), root.view(), 25.0).expect("solve"),
        solve_least_squares(&rig, pos.view(), root.view(), 25.0).expect("solve"),
    ] {
        let flips = RotationFlips::of(&m);
        assert_eq!(flips.steps_over_60, 0, "{flips:?}");
        // Not a slow spin either: the shoulder turns about as much as the swing (1.2 rad · 2π / 100 frames ≈ 4.3°).
        let turn = (1..t_len)
            .map(|t| {
                m.rotations[t - 1][shoulder]
                    .angle_to(&m.rotations[t][shoulder])
                    .to_degrees()
            })
            .fold(0.0, f64::max);
        assert!(turn < 10.0, "the shoulder turns {turn:.1}° in a frame");
        let err =
            joint_errors(m.joint_positions().view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
        assert!(err < 1e-4, "max error {err} m");
    }
}

/// Two key frames whose data disagree on the right thigh by 8 cm (as captured poses do:
/// DANCE_W_3's thigh measures 43–54 cm): the chain IK on the anchors' median skeleton puts the
/// whole difference on the knee and everything below it, the least-squares fit spreads it.
#[test]
fn a_thigh_the_key_frames_disagree_on_is_spread_over_the_body() {
    use rand::SeedableRng;
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let rig = random_rig(&mut rng);
    let roots = vec![Vector3::new(0.0, 1.0, 0.0); 2];
    let locals: Vec<Vec<UnitQuaternion<f64>>> = (0..2)
        .map(|_| {
            (0..RIG_JOINTS)
                .map(|_| random_rotation(&mut rng, 0.6))
                .collect()
        })
        .collect();
    let (mut pos, root) = arrays(&rig, &roots, &locals);
    // Frame 1's thigh 8 cm longer: the knee and everything below it moves along the thigh.
    use crate::motion::skeleton::{HIPS, PARENTS};
    let knee = (0..NUM_JOINTS)
        .find(|&j| PARENTS[j] == Some(HIPS[0]))
        .expect("right knee");
    let thigh: Vec<f32> = (0..3)
        .map(|c| pos[[1, knee, c]] - pos[[1, HIPS[0], c]])
        .collect();
    let len = thigh.iter().map(|v| v * v).sum::<f32>().sqrt();
    let below = |mut j: usize| loop {
        if j == knee {
            return true;
        }
        match PARENTS[j] {
            Some(p) => j = p,
            None => return false,
        }
    };
    for j in (0..NUM_JOINTS).filter(|&j| below(j)) {
        for c in 0..3 {
            pos[[1, j, c]] += 0.08 * thigh[c] / len;
        }
    }
    let worst = |m: &RigMotion| {
        let back = m.joint_positions();
        (0..2)
            .map(|t| centred_error_cm(back.index_axis(Axis(0), t), pos.index_axis(Axis(0), t)))
            .fold(0.0, f64::max)
    };
    let chain = worst(
        &solve(
            &Rig::fit(pos.view(), root.view()).expect("fit"),
            pos.view(),
            root.view(),
            f64::NAN,
        )
        .expect("solve"),
    );
    // Two key poses, not a motion (no frame rate): each solved on its own.
    let fitted = worst(&fit_and_solve(pos.view(), root.view(), f64::NAN, &[0, 1]).expect("solve"));
    eprintln!("worst key frame error: chain on median lengths {chain:.2} cm, least squares {fitted:.2} cm");
    assert!(
        chain > 1.0,
        "the test's mismatch does not show in the chain IK: {chain:.2} cm"
    );
    assert!(
        fitted < 0.5 * chain,
        "least squares {fitted:.2} cm against the chain's {chain:.2} cm"
    );
}

/// A smoothly turning rigid motion: the least-squares IK keeps its positions and its root
/// track, and the root's, spine's and pelvis's rotations move as smoothly as the motion. ([`solve`]'s root rotation is free about the spine's offset, which the
/// pelvis's repeats, and jumps by up to 180°, spine and pelvis turning back.)
#[test]
fn least_squares_keeps_the_root_track_and_turns_smoothly() {
    use rand::SeedableRng;
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let rig = random_rig(&mut rng);
    let t_len = 50;
    let (a, b): (Vec<UnitQuaternion<f64>>, Vec<UnitQuaternion<f64>>) = (0..RIG_JOINTS)
        .map(|_| {
            (
                random_rotation(&mut rng, 0.5),
                random_rotation(&mut rng, 0.5),
            )
        })
        .unzip();
    let roots: Vec<Vector3<f64>> = (0..t_len)
        .map(|t| Vector3::new(0.02 * t as f64, 1.0, 0.0))
        .collect();
    let locals: Vec<Vec<UnitQuaternion<f64>>> = (0..t_len)
        .map(|t| {
            let u = t as f64 / (t_len - 1) as f64;
            (0..RIG_JOINTS)
                .map(|j| {
                    let q = a[j].slerp(&b[j], u);
                    // The root also turns a quarter of a turn about +y over the motion.
                    if j == 0 {
                        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 1.5 * u) * q
                    } else {
                        q
                    }
                })
                .collect()
        })
        .collect();
    let (pos, root) = arrays(&rig, &roots, &locals);
    let m = solve_least_squares(&rig, pos.view(), root.view(), 25.0).expect("solve");
    let err = joint_errors(m.joint_positions().view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
    assert!(err < 1e-3, "max error {err} m");
    assert_eq!(m.root_translation.len(), t_len);
    for (t, (got, want)) in m.root_translation.iter().zip(&roots).enumerate() {
        let off = (got - want).norm();
        assert!(off < 1e-3, "frame {t}: the root is {off} m off its track");
    }
    // The root and its children (spine, pelvis); further down, the twist of a limb its
    // joints leave free is the chain's (the left knee of this rig turns 16° in one frame in
    // both).
    let turn = |m: &RigMotion| {
        (1..t_len)
            .flat_map(|t| {
                [0, rig_index(super::super::skeleton::SPINE), NUM_JOINTS + 1].map(|j| (t, j))
            })
            .map(|(t, j)| {
                m.rotations[t - 1][j]
                    .angle_to(&m.rotations[t][j])
                    .to_degrees()
            })
            .fold(0.0, f64::max)
    };
    let chain = solve(&rig, pos.view(), root.view(), 25.0).expect("solve");
    eprintln!("largest turn of the root, spine or pelvis between frames: chain {:.1}°, least squares {:.1}°", turn(&chain), turn(&m));
    assert!(
        turn(&m) < 5.0,
        "the root, spine or pelvis turns {:.1}° between two frames",
        turn(&m)
    );
}

/// Without anchors (a dance with no key pose) the export is the chain IK on the median
/// skeleton, as it always was.
#[test]
fn without_anchors_the_chain_solution_is_kept() {
    use rand::SeedableRng;
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let rig = random_rig(&mut rng);
    let roots: Vec<Vector3<f64>> = (0..10)
        .map(|t| Vector3::new(0.0, 1.0, 0.05 * t as f64))
        .collect();
    let locals: Vec<Vec<UnitQuaternion<f64>>> = (0..10)
        .map(|_| {
            (0..RIG_JOINTS)
                .map(|_| random_rotation(&mut rng, 0.8))
                .collect()
        })
        .collect();
    let (pos, root) = arrays(&rig, &roots, &locals);
    let a = fit_and_solve(pos.view(), root.view(), 25.0, &[]).expect("solve");
    let b = solve(
        &Rig::fit(pos.view(), root.view()).expect("fit"),
        pos.view(),
        root.view(),
        25.0,
    )
    .expect("solve");
    assert_eq!(a.rig, b.rig);
    assert_eq!(a.root_translation, b.root_translation);
    assert_eq!(a.rotations, b.rotations);
}

/// A pose turning slowly about y: the root's rotation turns with it, never by the free
/// quarter turns a best fit of the coinciding spine and pelvis offsets allows.
#[test]
fn the_root_turns_with_the_body() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let (names, parents) = hierarchy();
    let mut offsets: Vec<Vector3<f64>> = (0..RIG_JOINTS)
        .map(|_| {
            Vector3::new(
                rng.gen_range(-0.2..0.2),
                rng.gen_range(-0.3..0.3),
                rng.gen_range(-0.2..0.2),
            )
        })
        .collect();
    offsets[0] = Vector3::zeros();
    offsets[NUM_JOINTS + 1] = offsets[rig_index(super::super::skeleton::SPINE)];
    offsets[NUM_JOINTS + 2] = Vector3::zeros();
    let rig = Rig {
        names,
        parents,
        offsets,
    };
    let pose: Vec<UnitQuaternion<f64>> = (0..RIG_JOINTS)
        .map(|_| {
            UnitQuaternion::from_euler_angles(
                rng.gen_range(-0.5..0.5),
                rng.gen_range(-0.5..0.5),
                rng.gen_range(-0.5..0.5),
            )
        })
        .collect();
    let t_len = 30;
    let step = 0.02; // rad per frame
    let mut pos = Array3::zeros((t_len, NUM_JOINTS, 3));
    let mut root = Array2::zeros((t_len, 3));
    for t in 0..t_len {
        let mut local = pose.clone();
        local[0] = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), step * t as f64) * pose[0];
        let r = Vector3::new(0.0, 1.0, 0.0);
        let (p, _) = fk_frame(&rig, &r, &local);
        for j in 0..NUM_JOINTS {
            for c in 0..3 {
                pos[[t, j, c]] = p[rig_index(j)][c] as f32;
            }
        }
        for c in 0..3 {
            root[[t, c]] = r[c] as f32;
        }
    }
    let m = solve(&rig, pos.view(), root.view(), 25.0).expect("solve");
    let worst = (1..t_len)
        .map(|t| m.rotations[t][0].angle_to(&m.rotations[t - 1][0]))
        .fold(0.0, f64::max);
    assert!(
        worst < 3.0 * step,
        "the root turned {worst:.3} rad in one frame (the body {step})"
    );
    let err = joint_errors(m.joint_positions().view(), pos.view()).fold(0.0f32, |a, &b| a.max(b));
    assert!(err < 1e-4, "positions moved by {err} m");
}

#[test]
fn six_d_round_trips() {
    let q = UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0);
    let m = q.to_rotation_matrix();
    let m = m.matrix();
    let v = [
        m[(0, 0)] as f32,
        m[(1, 0)] as f32,
        m[(2, 0)] as f32,
        m[(0, 1)] as f32,
        m[(1, 1)] as f32,
        m[(2, 1)] as f32,
    ];
    let back = rotation_from_6d(&v).expect("valid");
    assert!(back.angle_to(&q) < 1e-5);
}

/// keypose-transformer's planted dance up to just after its first key pose on DANCE_R_9 (seed 1),
/// fitted with its four key frames as anchors: the first fit of frame 182 turned the pelvis 127°
/// about the hips' line from the frame before (its thighs turning back), which the turn limit
/// caught half-way, the legs 15–20 cm off for one frame: 95 m/s², where its targets reach 20.
#[test]
fn a_fit_caught_by_the_turn_limit_is_not_left_off_its_targets() {
    #[derive(serde::Deserialize)]
    struct Fixture {
        anchors: Vec<usize>,
        positions: Vec<[[f32; 3]; NUM_JOINTS]>,
    }
    let doc: Fixture = serde_json::from_str(include_str!(
        "../../../tests/fixtures/motion/keypose_r9_pelvis_flip.json"
    ))
    .expect("fixture");
    let values: Vec<f32> = doc.positions.iter().flatten().flatten().copied().collect();
    let pos = Array3::from_shape_vec((doc.positions.len(), NUM_JOINTS, 3), values).expect("shape");
    let anchors = doc.anchors;
    let root = crate::motion::skeleton::body_centre_track(pos.view());
    let m = fit_and_solve(pos.view(), root.view(), 25.0, &anchors).expect("solve");
    let world = m.joint_positions();
    // The clip's own frames (the last three are the other key poses, not a motion).
    let clip = anchors[1];
    let peak = |p: ndarray::ArrayView3<'_, f32>| {
        crate::metrics::physical::joint_acceleration(p.slice(ndarray::s![..clip, .., ..]), 25.0)
            .into_iter()
            .fold(0f64, f64::max)
    };
    let (fitted, targets) = (peak(world.view()), peak(pos.view()));
    eprintln!("largest acceleration: fitted {fitted:.1} m/s², its targets {targets:.1}");
    // Before: 96 m/s² two frames after the key, where the targets' largest is 20.
    assert!(
        fitted < 2.0 * targets,
        "the fit pops: {fitted:.1} m/s² where its targets reach {targets:.1}"
    );
}
