//! Metrics checked against their peers (fixtures from `tools/metrics_reference.py`: scipy,
//! mir_eval, scipy.linalg.sqrtm), on hand-computable motions, and on the real data.
#[path = "common/models.rs"]
mod common_models;

use choreo::metrics::beats::{
    self, bas_bailando, bas_fact, fact_order, kinematic_beats_bailando, kinematic_beats_fact,
};
use choreo::metrics::features::{geometric_features, kinetic_features, BodyScale};
use choreo::metrics::fid::{frechet_distance, mean_pairwise_distance, Gaussian, ZNorm};
use choreo::metrics::kinematics::{foot_skating, freezing, key_pose_error_cm, smoothness_cv};
use choreo::metrics::plausibility::joint_angles;
use choreo::metrics::reference::ReferenceStats;
use choreo::metrics::skeleton_map::{augment, GEOMETRIC_JOINTS};
use choreo::motion::{skeleton as sk, KeyPose, Motion, NUM_JOINTS};
use ndarray::Array3;
use serde_json::Value;

const FPS: f64 = 25.0;

fn fixture(name: &str) -> Value {
    let path = format!(
        "{}/tests/fixtures/metrics/{name}.json",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{path}: {e} (run tools/metrics_reference.py)"));
    serde_json::from_str(&text).expect("fixture is JSON")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("rows").iter().map(floats).collect()
}

fn assert_close(got: f64, want: f64, tol: f64, what: &str) {
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got}, want {want} (tol {tol})"
    );
}

/// Walks two JSON values and compares numbers to a relative `tol` (serde_json's default float
/// parser may be off by an ulp, so a written-and-read value is equal only to rounding).
fn assert_json_close(a: &Value, b: &Value, tol: f64, path: &str) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().expect("f64"), y.as_f64().expect("f64"));
            assert!(
                (x - y).abs() <= tol * x.abs().max(y.abs()).max(1e-300),
                "{path}: {x} vs {y}"
            );
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}: lengths");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                assert_json_close(u, v, tol, &format!("{path}[{i}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(
                x.keys().collect::<Vec<_>>(),
                y.keys().collect::<Vec<_>>(),
                "{path}: keys"
            );
            for (k, u) in x {
                assert_json_close(u, &y[k], tol, &format!("{path}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

fn assert_list(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert_close(*g, *w, 1e-9, what);
    }
}

#[test]
fn kinematic_beats_and_bas_match_scipy_on_synthetic_motions() {
    let fx = fixture("beats");
    for (i, m) in fx["motions"]
        .as_array()
        .expect("motions")
        .iter()
        .enumerate()
    {
        let shape: Vec<usize> = m["shape"]
            .as_array()
            .expect("shape")
            .iter()
            .map(|x| x.as_u64().expect("dim") as usize)
            .collect();
        let data: Vec<f32> = floats(&m["positions"])
            .into_iter()
            .map(|x| x as f32)
            .collect();
        let p = Array3::from_shape_vec((shape[0], shape[1], shape[2]), data).expect("shape");
        let fps = m["fps"].as_f64().expect("fps");
        let fb = kinematic_beats_fact(p.view(), fps);
        let bb = kinematic_beats_bailando(p.view(), fps);
        assert_list(
            &fb,
            &floats(&m["fact_beats"]),
            &format!("motion {i} FACT beats"),
        );
        assert_list(
            &bb,
            &floats(&m["bailando_beats"]),
            &format!("motion {i} Bailando beats"),
        );
        let music = floats(&m["music_beats"]);
        assert_close(
            bas_fact(&music, &fb),
            m["bas_fact"].as_f64().expect("n"),
            1e-6,
            "BAS FACT",
        );
        assert_close(
            bas_bailando(&music, &bb),
            m["bas_bailando"].as_f64().expect("n"),
            1e-6,
            "BAS Bailando",
        );
        assert_close(
            beats::f_measure(&music, &fb),
            m["f_measure"].as_f64().expect("n"),
            1e-6,
            "F-measure",
        );
        assert_close(
            beats::cemgil(&music, &fb),
            m["cemgil"].as_f64().expect("n"),
            1e-6,
            "Cemgil",
        );
        assert_close(
            beats::p_score(&music, &fb),
            m["p_score"].as_f64().expect("n"),
            1e-6,
            "P-score",
        );
    }
}

#[test]
fn beat_list_metrics_match_mir_eval() {
    let fx = fixture("beats");
    let lists = fx["beat_lists"].as_array().expect("lists");
    assert!(lists.len() >= 30);
    for (i, c) in lists.iter().enumerate() {
        let (r, e) = (floats(&c["reference"]), floats(&c["estimated"]));
        let what = |m: &str| format!("case {i} {m}");
        assert_close(
            beats::f_measure(&r, &e),
            c["f_measure"].as_f64().expect("n"),
            1e-6,
            &what("f_measure"),
        );
        assert_close(
            beats::cemgil(&r, &e),
            c["cemgil"].as_f64().expect("n"),
            1e-6,
            &what("cemgil"),
        );
        assert_close(
            beats::p_score(&r, &e),
            c["p_score"].as_f64().expect("n"),
            1e-6,
            &what("p_score"),
        );
        assert_close(
            bas_fact(&r, &e),
            c["bas_fact"].as_f64().expect("n"),
            1e-6,
            &what("bas_fact"),
        );
        assert_close(
            bas_bailando(&r, &e),
            c["bas_bailando"].as_f64().expect("n"),
            1e-6,
            &what("bas_bailando"),
        );
    }
}

#[test]
fn fid_matches_scipy_sqrtm_to_1e4_relative() {
    let fx = fixture("fid");
    for (i, c) in fx["cases"].as_array().expect("cases").iter().enumerate() {
        let (a, b) = (matrix(&c["a"]), matrix(&c["b"]));
        let z = ZNorm::fit(&a).expect("fit");
        let an: Vec<Vec<f64>> = a.iter().map(|r| z.apply(r)).collect();
        let bn: Vec<Vec<f64>> = b.iter().map(|r| z.apply(r)).collect();
        let fid = frechet_distance(
            &Gaussian::fit(&an).expect("a"),
            &Gaussian::fit(&bn).expect("b"),
        );
        let want = c["fid_normalised"].as_f64().expect("n");
        assert!(
            (fid - want).abs() <= 1e-4 * want.abs(),
            "case {i}: FID {fid} vs scipy {want}"
        );
        assert_close(
            mean_pairwise_distance(&an),
            c["div_a"].as_f64().expect("n"),
            1e-6,
            "div a",
        );
        assert_close(
            mean_pairwise_distance(&bn),
            c["div_b"].as_f64().expect("n"),
            1e-6,
            "div b",
        );
    }
}

/// A `[T, 23, 3]` motion where every joint follows `f(frame, joint)`.
fn motion_from(frames: usize, f: impl Fn(usize, usize) -> [f64; 3]) -> Motion {
    let mut p = Array3::<f32>::zeros((frames, NUM_JOINTS, 3));
    for t in 0..frames {
        for j in 0..NUM_JOINTS {
            let v = f(t, j);
            for c in 0..3 {
                p[[t, j, c]] = v[c] as f32;
            }
        }
    }
    Motion {
        fps: FPS,
        positions: p,
    }
}

/// A plausible standing pose (metres): joints spread so no bone is degenerate.
fn rest_pose(j: usize) -> [f64; 3] {
    let side = if j == 2 {
        0.0
    } else if (3..=11).contains(&j) || j == 22 {
        -1.0
    } else {
        1.0
    };
    let y = match j {
        0 | 1 => 1.65,
        2 => 1.1,
        3 | 12 => 1.45,
        4 | 13 => 1.2,
        5 | 14 => 1.05,
        6 | 15 | 21 | 22 => 0.9,
        7 | 16 => 0.95,
        8 | 17 => 0.5,
        9 | 18 => 0.1,
        10 | 19 => 0.02,
        _ => 0.0,
    };
    let z = match j {
        11 | 20 => 0.15,
        10 | 19 => -0.05,
        0 | 1 => 0.05,
        _ => 0.0,
    };
    let x = side
        * match j {
            3 | 12 => 0.2,
            4..=6 | 13..=15 | 21 | 22 => 0.25,
            7..=11 | 16..=20 => 0.1,
            0 | 1 => 0.05,
            _ => 0.0,
        };
    [x, y, z]
}

#[test]
fn static_pose_has_zero_kinetics_no_beats_and_no_fast_features() {
    let m = motion_from(60, |_, j| rest_pose(j));
    let k = kinetic_features(m.positions.view(), FPS);
    assert_eq!(k.len(), NUM_JOINTS * 3);
    assert!(k.iter().all(|&x| x == 0.0), "{k:?}");
    assert!(kinematic_beats_fact(m.positions.view(), FPS).is_empty());
    assert!(kinematic_beats_bailando(m.positions.view(), FPS).is_empty());
    assert_eq!(smoothness_cv(m.positions.view(), FPS), 0.0);
    assert_eq!(freezing(m.positions.view(), FPS).last_first_ratio, 0.0);
    let aug = augment(m.positions.view());
    let scale = BodyScale {
        humerus: 0.28,
        shoulder_width: 0.27,
        hip_width: 0.22,
    };
    let g = geometric_features(aug.view(), FPS, &GEOMETRIC_JOINTS, &scale);
    // f_fast on both wrists, both ankles and the root: a static pose is never fast.
    for idx in [12, 13, 21, 22, 31] {
        assert_eq!(g[idx], 0.0, "feature {idx}");
    }
}

#[test]
fn constant_velocity_has_known_kinetic_energy_and_no_acceleration() {
    // Every joint moves at (0.6, 0.3, 0.8) m/s: horizontal speed² = 1.0, vertical² = 0.09.
    let v = [0.6, 0.3, 0.8];
    let m = motion_from(50, |t, j| {
        let r = rest_pose(j);
        std::array::from_fn(|c| r[c] + v[c] * t as f64 / FPS)
    });
    let k = kinetic_features(m.positions.view(), FPS);
    for j in 0..NUM_JOINTS {
        assert_close(k[3 * j], 1.0, 1e-4, "horizontal v²");
        assert_close(k[3 * j + 1], 0.09, 1e-4, "vertical v²");
        assert_close(k[3 * j + 2], 0.0, 1e-2, "|a|");
    }
    // Constant speed: the frame-difference sequence has no spread.
    assert!(smoothness_cv(m.positions.view(), FPS) < 1e-4);
}

#[test]
fn circle_at_known_speed_gives_speed_squared_and_centripetal_acceleration() {
    // Radius 0.5 m, ω = 2 rad/s in the horizontal plane: speed 1 m/s, |a| = rω² = 2 m/s².
    let (r, w) = (0.5, 2.0);
    let frames = 2000;
    let m = motion_from(frames, |t, j| {
        let a = w * t as f64 / FPS;
        let b = rest_pose(j);
        [b[0] + r * a.cos(), b[1], b[2] + r * a.sin()]
    });
    let k = kinetic_features(m.positions.view(), FPS);
    // The ±2-frame window averages chords: speed = 2r·sin(5θ/2)/(5Δt) with θ = ωΔt, and the mean
    // of five rotated accelerations shrinks by sin(5θ/2)/(5 sin(θ/2)); edges cost < 0.5 %.
    let th = w / FPS;
    let speed = 2.0 * r * (5.0 * th / 2.0).sin() / (5.0 / FPS);
    let acc = 4.0 * r * (th / 2.0).sin().powi(2) * FPS * FPS * (5.0 * th / 2.0).sin()
        / (5.0 * (th / 2.0).sin());
    for j in 0..NUM_JOINTS {
        assert!(
            (k[3 * j] - speed * speed).abs() < 5e-3 * speed * speed,
            "h {} vs {}",
            k[3 * j],
            speed * speed
        );
        assert!(k[3 * j + 1].abs() < 1e-9);
        assert!(
            (k[3 * j + 2] - acc).abs() < 5e-3 * acc,
            "a {} vs {acc}",
            k[3 * j + 2]
        );
    }
    assert!(
        (speed - 1.0).abs() < 0.01 && (acc - 2.0).abs() < 0.03,
        "hand formulas near v = 1, a = 2"
    );
}

#[test]
fn known_elbow_angle_sets_the_angle_features() {
    // Right upper arm straight down from the shoulder, forearm forward: a 90° bend at the elbow.
    let pose = |j: usize| -> [f64; 3] {
        match j {
            3 => [-0.2, 1.45, 0.0],
            4 => [-0.2, 1.15, 0.0],
            5 => [-0.2, 1.15, 0.12],
            6 | 22 => [-0.2, 1.15, 0.25],
            _ => rest_pose(j),
        }
    };
    let m = motion_from(10, |_, j| pose(j));
    let angles = joint_angles(m.positions.view(), &[(3, 4, 5), (4, 5, 6)]);
    assert_close(angles[0][0], 90.0, 1e-4, "elbow bend");
    assert_close(angles[0][1], 0.0, 1e-2, "straight forearm");
    let aug = augment(m.positions.view());
    let scale = BodyScale {
        humerus: 0.28,
        shoulder_width: 0.27,
        hip_width: 0.22,
    };
    let g = geometric_features(aug.view(), FPS, &GEOMETRIC_JOINTS, &scale);
    // Feature 6: angle(relbow→rshoulder, relbow→rwrist) = 90° ∈ (0, 110) on every frame.
    assert_eq!(g[6], 1.0);
    // The left arm hangs straight (180°): feature 7 is off.
    assert_eq!(g[7], 0.0);
}

#[test]
fn fid_of_a_set_with_itself_is_zero_and_a_shift_adds_its_square() {
    let rows: Vec<Vec<f64>> = (0..50)
        .map(|i| vec![(i as f64).sin(), (i as f64 * 0.7).cos(), i as f64 / 50.0])
        .collect();
    let g = Gaussian::fit(&rows).expect("fit");
    assert!(frechet_distance(&g, &g).abs() < 1e-9);
    let shifted: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| vec![r[0] + 3.0, r[1], r[2] - 4.0])
        .collect();
    let h = Gaussian::fit(&shifted).expect("fit");
    assert_close(frechet_distance(&g, &h), 25.0, 1e-9, "|Δμ|² = 25");
}

#[test]
fn bas_is_one_on_perfect_alignment_and_scales_with_fps() {
    let b = [0.5, 1.0, 1.5];
    assert_close(bas_fact(&b, &b), 1.0, 1e-12, "FACT");
    assert_close(bas_bailando(&b, &b), 1.0, 1e-12, "Bailando");
    // One σ (0.05 s) off: exp(−1/2).
    let off: Vec<f64> = b.iter().map(|x| x + 0.05).collect();
    assert_close(bas_fact(&b, &off), (-0.5f64).exp(), 1e-12, "one sigma");
    assert_eq!(fact_order(60.0), 10);
    assert_eq!(fact_order(25.0), 4);
    assert_close(
        beats::bailando_sigma(25.0),
        5.0 * 25.0 / 60.0,
        1e-12,
        "sigma",
    );
    // Chance level of random beats against a 0.5-s grid: σ√(2π)/P.
    let grid: Vec<f64> = (0..=200).map(|i| i as f64 * 0.5).collect();
    let want = 0.05 * (2.0 * std::f64::consts::PI).sqrt() / 0.5;
    assert_close(beats::bas_fact_chance(&grid, 100.0), want, 1e-3, "chance");
}

#[test]
fn key_pose_error_is_centroid_aligned_in_cm() {
    let m = motion_from(50, |_, j| rest_pose(j));
    let exact: Vec<[f64; 3]> = (0..NUM_JOINTS).map(rest_pose).collect();
    // A translated key pose matches exactly (both are centred).
    let moved: Vec<[f64; 3]> = exact
        .iter()
        .map(|p| [p[0] + 1.0, p[1] - 0.5, p[2]])
        .collect();
    let kp = |joints: Vec<[f64; 3]>| KeyPose {
        time_s: 1.0,
        joints,
    };
    assert!(key_pose_error_cm(m.positions.view(), FPS, &[kp(moved)]).expect("applies") < 1e-4);
    // One joint 23 cm off: that joint is off by d(1 − 1/J), the others by d/J each.
    let mut one = exact.clone();
    one[6][2] += 0.23;
    let j = NUM_JOINTS as f64;
    let want = 100.0 * 2.0 * 0.23 * (j - 1.0) / (j * j);
    assert_close(
        key_pose_error_cm(m.positions.view(), FPS, &[kp(one)]).expect("applies"),
        want,
        1e-3,
        "one joint",
    );
    // Outside the dance: no error to report.
    assert!(key_pose_error_cm(
        m.positions.view(),
        FPS,
        &[KeyPose {
            time_s: 99.0,
            joints: exact
        }]
    )
    .is_none());
}

#[test]
fn sliding_planted_feet_skate_and_lifted_feet_do_not() {
    // Everything slides along x at 0.5 m/s with the feet on the floor: every contact step skates.
    let slide = motion_from(50, |t, j| {
        let r = rest_pose(j);
        [r[0] + 0.5 * t as f64 / FPS, r[1], r[2]]
    });
    let s = foot_skating(slide.positions.view(), FPS, &sk::FOOT_POINTS);
    assert!(s.contact_share > 0.99, "{s:?}");
    assert_close(s.skate_ratio, 1.0, 1e-12, "skate ratio");
    assert_close(s.mean_contact_speed_m_s, 0.5, 1e-4, "slide speed");
    // Standing still: contact but no skating.
    let still = motion_from(50, |_, j| rest_pose(j));
    let s = foot_skating(still.positions.view(), FPS, &sk::FOOT_POINTS);
    assert!(s.contact_share > 0.99 && s.skate_ratio == 0.0, "{s:?}");
}

#[test]
fn a_dance_that_stops_after_30_seconds_has_freeze_ratio_zero() {
    let frames = (70.0 * FPS) as usize;
    let m = motion_from(frames, |t, j| {
        let r = rest_pose(j);
        let tt = (t as f64 / FPS).min(30.0);
        [r[0] + 0.1 * (3.0 * tt).sin(), r[1], r[2]]
    });
    let fr = freezing(m.positions.view(), FPS);
    assert!(fr.last_first_ratio < 1e-9, "{}", fr.last_first_ratio);
    assert_eq!(fr.energy.len(), fr.times_s.len());
    assert!(fr.energy[0] > 0.0 && fr.energy[fr.energy.len() - 1] == 0.0);
}

#[test]
fn report_of_a_synthetic_dance_round_trips_through_json() {
    let reference = ReferenceStats::builtin().expect("committed reference statistics parse");
    let m = motion_from(400, |t, j| {
        let r = rest_pose(j);
        let a = t as f64 / FPS;
        [
            r[0] + 0.1 * (2.0 * a + j as f64).sin(),
            r[1] + 0.05 * (4.0 * a).sin(),
            r[2] + 0.1 * (3.0 * a).cos(),
        ]
    });
    let analysis = choreo::audio::Analysis {
        tempo_bpm: 120.0,
        beat_times: (0..40).map(|i| i as f64 * 0.5).collect(),
        downbeat_times: vec![],
        tempo_curve: vec![],
    };
    let report = choreo::report::build(&m, &analysis, &[], &reference).expect("report");
    assert_eq!(report.frames, 400);
    assert_eq!(report.fid_k_curve.len(), 4, "16 s in 4-s windows");
    assert!(report.music_beat_times.iter().all(|&b| b <= 16.0));
    assert!(report.scores.fid_k.is_finite() && report.scores.fid_k > 0.0);
    assert!(report.scores.key_pose_error_cm.is_none());
    // The physical numbers and their verdict are part of every report: the feet stand at 0 m
    // (rest pose) give or take the 5-cm vertical sway, and every joint moves.
    let ph = &report.scores.physical;
    assert!(
        (ph.lowest_foot_m.median - 0.0).abs() < 0.06 && ph.mean_speed_m_s > 0.1,
        "{ph:?}"
    );
    assert!(ph.acceleration_m_s2.max.is_finite() && ph.key_pose_pops_m_s2.is_empty());
    assert_eq!(report.scores.verdict.criteria.len(), 8);
    // A body bobbing 0.10 m from top to bottom never holds its feet over 0.10 m up: no hang.
    assert!(
        report
            .scores
            .verdict
            .get("hang")
            .is_some_and(|c| c.pass == Some(true))
            && ph.hang_s == 0.0,
        "{ph:?}"
    );
    assert!(
        report
            .scores
            .verdict
            .get("seed-distance")
            .is_some_and(|c| c.pass.is_none()),
        "one dance: no seed pair"
    );
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("report.json");
    choreo::report::write(&report, &path).expect("write");
    let back: choreo::report::Report =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("read")).expect("parse");
    let want = serde_json::to_value(&report).expect("value");
    assert_json_close(
        &serde_json::to_value(&back).expect("value"),
        &want,
        1e-14,
        "report",
    );
}

#[test]
fn report_rejects_a_motion_with_the_wrong_joint_count() {
    let reference = ReferenceStats::builtin().expect("reference");
    let m = Motion {
        fps: FPS,
        positions: Array3::zeros((10, 5, 3)),
    };
    let analysis = choreo::audio::Analysis {
        tempo_bpm: 120.0,
        beat_times: vec![],
        downbeat_times: vec![],
        tempo_curve: vec![],
    };
    assert!(choreo::report::build(&m, &analysis, &[], &reference).is_err());
}

#[path = "metrics/real_data.rs"]
mod real_data;

/// The physical-plausibility measures on the real dances and on bad motions made from them.
#[path = "metrics/physical_real.rs"]
mod physical_real;

/// The committed style classifiers (DanceNet's musical one, `models/dancenet/style.*`, and the
/// motion one, `models/motion-style/`) on the test split, through their serving APIs. The floors
/// come from the cards: above what answering "waltz" everywhere scores, and below every seed
/// tried.
#[path = "metrics/style_classifiers.rs"]
mod style_classifiers;

/// The motion style card's probes: not a check (nothing is asserted), the table the card quotes.
/// `cargo test --release --test metrics style_probes -- --ignored --nocapture`
#[test]
#[ignore = "prints the motion style card's probe table"]
fn style_probes() {
    use choreo::models::motion_style::MotionStyle;
    use choreo::models::{Cancelled, GenerateRequest, Progress, Registry};
    use choreo::motion::dataset::Dataset;
    use ndarray::{Array3, Axis};
    use std::path::PathBuf;

    struct Quiet;
    impl Progress for Quiet {
        fn report(&mut self, _: choreo::stage::Stage, _: f32) -> Result<(), Cancelled> {
            Ok(())
        }
    }
    let fmt = |p: [f32; 4]| {
        p.iter()
            .map(|v| format!("{v:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    tch::set_num_threads(1);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let ds = Dataset::open(&root.join(choreo::motion::dataset::DEFAULT_ROOT)).expect("the dataset");
    let ms = MotionStyle::load(&root.join("models").join(choreo::models::motion_style::ID))
        .expect("the classifier");
    let remade = |frames: usize, f: &dyn Fn(usize, usize, usize) -> f32| Motion {
        fps: 25.0,
        positions: Array3::from_shape_fn((frames, NUM_JOINTS, 3), |(t, j, k)| f(t, j, k)),
    };
    println!("probabilities: cha-cha rumba tango waltz");
    for id in ds
        .test_ids()
        .iter()
        .chain(std::iter::once(&"DANCE_T_5".to_string()))
    {
        let m = ds.load(id).expect("dance").motion;
        let (t, p) = (m.num_frames(), &m.positions);
        let pose = p.index_axis(Axis(0), t / 2).to_owned();
        let probes: Vec<(&str, Motion)> = vec![
            ("real", m.clone()),
            ("held still 20 s", remade(500, &|_, j, k| pose[[j, k]])),
            (
                "held, wobble 1 cm",
                remade(500, &|t, j, k| {
                    pose[[j, k]] + 0.01 * ((t * 31 + j * 7 + k * 3) as f32 * 0.7).sin()
                }),
            ),
            ("half speed", remade(2 * t, &|i, j, k| p[[i / 2, j, k]])),
            ("double speed", remade(t / 2, &|i, j, k| p[[2 * i, j, k]])),
            (
                "mirrored",
                remade(t, &|i, j, k| {
                    if k == 0 {
                        -p[[i, sk::MIRROR[j], k]]
                    } else {
                        p[[i, sk::MIRROR[j], k]]
                    }
                }),
            ),
            ("reversed", remade(t, &|i, j, k| p[[t - 1 - i, j, k]])),
        ];
        for (name, motion) in probes {
            println!(
                "{id:11} {name:18} {}",
                fmt(ms.classify(&motion).expect("classifies"))
            );
        }
    }
    // Other models' dances (they take no style) on the first 60 s of three test songs.
    let registry = Registry::load(&root.join("models")).expect("models");
    for id in ["DANCE_W_8", "DANCE_C_8", "DANCE_R_9"] {
        let mut audio =
            choreo::audio::decode_path(&ds.load(id).expect("dance").audio_path).expect("song");
        audio
            .samples
            .truncate((60.0 * audio.sample_rate as f64) as usize);
        audio.duration_s = audio.duration_s.min(60.0);
        for info in registry.list() {
            let model = registry.get(&info.id).expect("listed");
            let g = model
                .generate(&GenerateRequest::plain(&audio, 1), &mut Quiet)
                .expect("generates");
            let motion = choreo::motion::finish(g.motion, true);
            println!(
                "{id:11} {:18} {}",
                info.id.0,
                fmt(ms.classify(&motion).expect("classifies"))
            );
        }
    }
}

/// The musicality measures on all 43 real dances, each against its own song's beats: the
/// figures docs/evaluation.md states (and the model cards compare against) are what these
/// functions give.
#[path = "metrics/musicality_real.rs"]
mod musicality_real;
