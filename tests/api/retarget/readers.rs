//! The other readers of a retargeted dance: `@pixiv/three-vrm-animation` (the .vrma, in
//! chromium) and numpy (the SMPL .npz).
use super::{angles, choreo_pose, have, median, root, runs, Pose, LEG_LIMIT_DEG, MEDIAN_LIMIT_DEG};
use choreo::motion::retarget::smpl;
use nalgebra::{UnitQuaternion, Vector3};
use serde_json::Value;
use std::collections::HashMap;
use std::path::Path;

/// `@pixiv/three-vrm-animation` plays the .vrma on a humanoid unlike the target; its bones point
/// where motion.json's do.
pub(super) fn three_vrm_plays_the_vrma(vrma: &Path, motion: &Path, dir: &Path) {
    let out = dir.join("vrma.json");
    let run = std::process::Command::new("node")
        .arg(root().join("tests/web/vrma.mjs"))
        .args([vrma, motion, &out])
        .output()
        .expect("run node");
    let log =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "tests/web/vrma.mjs failed:\n{log}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("vrma result")).expect("json");
    eprintln!(
        "three-vrm, motion.vrma: median bone direction error (deg): {}",
        summary["median_deg"]
    );
    let medians = summary["median_deg"].as_object().expect("median_deg");
    assert!(medians.len() >= 8, "{summary}");
    for (bone, v) in medians {
        let v = v.as_f64().expect("number");
        assert!(
            v <= MEDIAN_LIMIT_DEG,
            "three-vrm: {bone} points {v:.1}° off motion.json's (median)"
        );
    }
}

/// The npz has AMASS's arrays (numpy reads them); its poses, put through SMPL's kinematic tree,
/// bend knees, hips and elbows as motion.json does, and all three spine joints turn.
pub(super) fn smpl_npz_follows_the_dance(npz: &Path, motion: &Value, frames: &[usize]) {
    use ndarray_npy::ReadNpyExt;
    let file = std::fs::File::open(npz).expect("npz");
    let mut zip = zip::ZipArchive::new(file).expect("npz is a zip");
    let mut read = |name: &str| -> ndarray::ArrayD<f64> {
        let entry = zip
            .by_name(name)
            .unwrap_or_else(|_| panic!("npz lacks {name}"));
        ndarray::ArrayD::<f64>::read_npy(entry).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let poses = read("poses.npy");
    let trans = read("trans.npy");
    let t_len = motion["num_frames"].as_u64().expect("frames") as usize;
    assert_eq!(poses.shape(), [t_len, 72]);
    assert_eq!(trans.shape(), [t_len, 3]);
    assert_eq!(
        read("mocap_framerate.npy").iter().next().copied(),
        motion["fps"].as_f64()
    );
    let target = smpl::smpl();
    let pose = |t: usize| -> Pose {
        let locals: Vec<UnitQuaternion<f64>> = (0..24)
            .map(|j| {
                UnitQuaternion::from_scaled_axis(Vector3::new(
                    poses[[t, 3 * j]],
                    poses[[t, 3 * j + 1]],
                    poses[[t, 3 * j + 2]],
                ))
            })
            .collect();
        let root = Vector3::new(trans[[t, 0]], trans[[t, 1]], trans[[t, 2]])
            + Vector3::from(smpl::REST[0]);
        let (pos, _) = choreo::motion::rig::fk_frame(&target.rig, &root, &locals);
        target.rig.names.iter().cloned().zip(pos).collect()
    };
    // The torso's turn is spread over spine1, spine2 and spine3: none stays at rest.
    for name in ["spine1", "spine2", "spine3"] {
        let j = smpl::JOINT_NAMES
            .iter()
            .position(|n| *n == name)
            .expect(name);
        let turned = (0..t_len)
            .filter(|&t| (0..3).map(|c| poses[[t, 3 * j + c]].powi(2)).sum::<f64>() > 1e-6)
            .count();
        eprintln!("SMPL npz: {name} turned on {turned} of {t_len} frames");
        assert!(turned * 2 > t_len, "SMPL npz: {name} rests on most frames");
    }
    // SMPL's collar-to-shoulder differs from choreo's markers (the shoulder angle is not
    // compared on SMPL); knees, hips and elbows are.
    let mut knee_elbow: HashMap<&str, Vec<f64>> = HashMap::new();
    for &t in frames {
        let want = angles(&choreo_pose(motion, t), &|k| k.to_string());
        // SMPL names these landmarks as choreo does (left_shoulder … left_ankle).
        let got = angles(&pose(t), &|k| k.to_string());
        for ((name, a), (_, b)) in want.iter().zip(&got) {
            if !name.ends_with("shoulder") {
                knee_elbow.entry(name).or_default().push((a - b).abs());
            }
        }
    }
    for (k, v) in knee_elbow {
        let m = median(v);
        let limit = if k.ends_with("elbow") {
            MEDIAN_LIMIT_DEG
        } else {
            LEG_LIMIT_DEG
        };
        eprintln!("SMPL npz: {k} off by {m:.1}° median");
        assert!(
            m <= limit,
            "SMPL npz: {k} off by {m:.1}° median (limit {limit}°)"
        );
    }
    if have(
        "numpy for /usr/bin/python3 (python3-numpy)",
        runs("/usr/bin/python3", &["-c", "import numpy"]),
    ) {
        let check = "import sys, numpy as np\nd = np.load(sys.argv[1])\nassert sorted(d.files) == ['betas', 'gender', 'mocap_framerate', 'poses', 'trans'], d.files\nassert d['poses'].dtype == np.float64 and d['poses'].shape[1] == 72\nassert d['trans'].shape == (d['poses'].shape[0], 3)\nassert str(d['gender']) == 'neutral', d['gender']\nassert float(d['mocap_framerate']) == 25.0\nassert not d['betas'].any()\nprint('numpy reads', d['poses'].shape)";
        let run = std::process::Command::new("/usr/bin/python3")
            .args(["-c", check])
            .arg(npz)
            .output()
            .expect("python3");
        assert!(
            run.status.success(),
            "numpy cannot read the npz: {}",
            String::from_utf8_lossy(&run.stderr)
        );
    }
}
