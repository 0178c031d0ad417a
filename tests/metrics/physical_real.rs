use super::*;
use choreo::metrics::physical::{names, seed_distance_m, PhysicalReference, Verdict};
use choreo::metrics::score::score_dance;
use choreo::motion::dataset::{Dance, Dataset};
use std::path::PathBuf;

fn dataset() -> Option<Dataset> {
    let root =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(choreo::motion::dataset::DEFAULT_ROOT);
    if root.is_dir() {
        return Some(Dataset::open(&root).expect("dataset opens"));
    }
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!("../shared/data/dance-with-melody is missing; the physical-plausibility tests need it under CI=true");
    }
    eprintln!("skipping: {} not found", root.display());
    None
}

/// Four key poses of a dance (root-relative, its own poses) at 10 %, 30 %, 55 % and 80 %.
fn own_keys(d: &Dance) -> Vec<KeyPose> {
    let rel = d.root_relative();
    let t = d.motion.num_frames();
    [0.1, 0.3, 0.55, 0.8]
        .iter()
        .map(|q| {
            let f = (q * t as f64) as usize;
            KeyPose {
                time_s: f as f64 / d.motion.fps,
                joints: (0..NUM_JOINTS)
                    .map(|j| [0, 1, 2].map(|c| f64::from(rel[[f, j, c]])))
                    .collect(),
            }
        })
        .collect()
}

/// The verdict of `m` with `keys`, and the seed criterion against `other` when given.
fn judge(m: &Motion, keys: &[KeyPose], other: Option<&Motion>) -> Verdict {
    let reference = ReferenceStats::builtin().expect("reference");
    let v = score_dance(m, &[], keys, &reference)
        .expect("scores")
        .scores
        .verdict;
    match other {
        Some(o) => v.with_seed_distance(Some(seed_distance_m(m, o))),
        None => v,
    }
}

fn fails(v: &Verdict, name: &str) -> bool {
    v.get(name).and_then(|c| c.pass) == Some(false)
}

#[test]
fn real_dances_measure_as_the_issue_reports() {
    let Some(ds) = dataset() else { return };
    let all: Vec<Motion> = ds
        .load_all(&ds.all_ids())
        .expect("dances")
        .into_iter()
        .map(|d| d.motion)
        .collect();
    assert_eq!(all.len(), 43);
    let r = PhysicalReference::compute(&all);
    let p = &r.pooled;
    // The floor is y = 0: the lowest foot point touches it, and rarely goes through.
    assert!((p.lowest_foot_m.p5 - 0.01).abs() < 0.01, "{p:?}");
    assert!((p.lowest_foot_m.median - 0.16).abs() < 0.02, "{p:?}");
    // Below −5 cm in 1.4 % of frames, all of two dances (DANCE_C_8, DANCE_T_5) whose floor
    // sits a few centimetres low.
    assert!(p.below_floor_share < 0.02 && p.deepest_m > -0.15, "{p:?}");
    assert!((p.acceleration_m_s2.median - 3.3).abs() < 0.3, "{p:?}");
    assert!((p.acceleration_m_s2.p99_9 - 56.0).abs() < 6.0, "{p:?}");
    assert!(
        (r.mean_speed_range_m_s[0] - 0.63).abs() < 0.02
            && (r.mean_speed_range_m_s[1] - 1.80).abs() < 0.02,
        "{r:?}"
    );
    assert!((p.speed_ratio - 1.0).abs() < 1e-12);
    // The committed train figures are of the same data.
    let builtin = ReferenceStats::builtin().expect("reference").physical;
    assert!(
        (builtin.pooled.lowest_foot_m.median - p.lowest_foot_m.median).abs() < 0.02,
        "{builtin:?}"
    );
}

#[test]
fn every_real_test_dance_passes_and_each_made_up_fault_is_caught() {
    let Some(ds) = dataset() else { return };
    let dances = ds.load_all(ds.test_ids()).expect("test dances");
    for (i, d) in dances.iter().enumerate() {
        // Another real dance stands in for a second seed: different dances differ.
        let other = &dances[(i + 1) % dances.len()].motion;
        let v = judge(&d.motion, &own_keys(d), Some(other));
        assert!(v.pass, "{}: {:?}", d.id, v.failures());
        assert!(
            v.criteria.iter().all(|c| c.pass.is_some()),
            "{}: every criterion applies: {v:?}",
            d.id
        );
    }

    let d = &dances[0];
    let keys = own_keys(d);
    let with_y = |dy: f32| {
        let mut m = d.motion.clone();
        m.positions
            .slice_mut(ndarray::s![.., .., 1])
            .mapv_inplace(|y| y + dy);
        m
    };
    // Floating a metre up and sunk 0.4 m: the floor criteria, and nothing else.
    for (what, m) in [("floating", with_y(1.0)), ("sinking", with_y(-0.4))] {
        let v = judge(&m, &keys, None);
        assert_eq!(
            v.failures(),
            vec![names::FOOT_MEDIAN, names::FOOT_P5],
            "{what}: {v:?}"
        );
    }

    // Popping: at each key frame the whole pose snaps, for one frame, to the pose 2 s later
    // (kept on this frame's body centre), as a model that jumps to its key poses does.
    let rel = d.root_relative();
    let mut snapped = d.motion.clone();
    let frames: Vec<usize> = keys
        .iter()
        .map(|k| (k.time_s * d.motion.fps).round() as usize)
        .collect();
    for &f in &frames {
        for j in 0..NUM_JOINTS {
            for c in 0..3 {
                snapped.positions[[f, j, c]] = d.center[[f, c]] + rel[[f + 50, j, c]];
            }
        }
    }
    let v = judge(&snapped, &keys, None);
    assert!(fails(&v, names::KEY_POPS), "whole-pose snap: {v:?}");
    // One joint jumping 2 m for one frame, 0.2 s after a key (the measure averages 23
    // joints, so a single joint registers above 84 m/s² only beyond ~1.5 m).
    let mut jump = d.motion.clone();
    jump.positions[[frames[1] + 5, sk::WRISTS[0], 0]] += 2.0;
    let v = judge(&jump, &keys, None);
    assert_eq!(v.failures(), vec![names::KEY_POPS], "one-joint jump: {v:?}");

    // Frozen: the first pose held for the whole dance.
    let mut held = d.motion.clone();
    let first = d.motion.positions.slice(ndarray::s![0, .., ..]).to_owned();
    for mut frame in held.positions.outer_iter_mut() {
        frame.assign(&first);
    }
    let v = judge(&held, &[], None);
    assert_eq!(v.failures(), vec![names::SPEED], "held pose: {v:?}");

    // Identical seeds: the same dance twice, even carried 3 m elsewhere on the floor.
    let mut moved = d.motion.clone();
    moved
        .positions
        .slice_mut(ndarray::s![.., .., 0])
        .mapv_inplace(|x| x + 3.0);
    let v = judge(&d.motion, &keys, Some(&moved));
    assert_eq!(v.failures(), vec![names::SEEDS], "identical seeds: {v:?}");
    assert!(v
        .get(names::SEEDS)
        .and_then(|c| c.value)
        .is_some_and(|x| x < 1e-4));

    // Key poses of another dance are missed.
    let v = judge(&d.motion, &own_keys(&dances[1]), None);
    assert!(fails(&v, names::KEY_POSES), "foreign key poses: {v:?}");
}
