//! Blender's reading of the retargeted files: both importers onto armatures named for the rig,
//! the angles between bones in its evaluated pose, and `tools/blender_import.py`, the recipe
//! docs/integrating.md gives, run on a served dance.
use super::{compare, root, Pose};
use nalgebra::Vector3;
use serde_json::Value;
use std::path::Path;

/// Blender imports both files onto one armature each with the rig's bone names (`names`, at
/// least), the glb's called `armature`; the angles between bones in its evaluated pose follow
/// motion.json's.
#[allow(clippy::too_many_arguments)]
pub(super) fn blender_reads_the_files(
    rig: &str,
    armature: &str,
    bvh: &Path,
    glb: &Path,
    dir: &Path,
    motion: &Value,
    frames: &[usize],
    names: &[String],
    landmark: &dyn Fn(&str) -> String,
) {
    let out = dir.join(format!("blender.{rig}.json"));
    let list = frames
        .iter()
        .map(|f| f.to_string())
        .collect::<Vec<_>>()
        .join(",");
    let script = root().join("tests/blender/check_retarget.py");
    let run = std::process::Command::new("blender")
        .args(["-b", "--factory-startup", "--python-exit-code", "1", "-P"])
        .arg(&script)
        .arg("--")
        .args([bvh, glb])
        .arg(&list)
        .arg(&out)
        .output()
        .expect("run blender");
    let log =
        String::from_utf8_lossy(&run.stdout).to_string() + &String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "blender failed:\n{log}");
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(&out).expect("blender result"))
            .expect("json");
    for kind in ["bvh", "glb"] {
        let r = &result[kind];
        assert!(r.get("error").is_none(), "{kind}: {}", r["error"]);
        assert_eq!(r["armatures"], 1, "{kind}: {r}");
        if kind == "glb" {
            assert_eq!(r["armature_names"][0], armature, "{kind}: armature name");
        }
        let bones: Vec<&str> = r["bones"]
            .as_array()
            .expect("bones")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        for name in names {
            assert!(
                bones.contains(&name.as_str()),
                "{kind}: Blender's armature lacks {name}: {bones:?}"
            );
        }
        assert_eq!(
            r["frames"].as_u64(),
            motion["num_frames"].as_u64(),
            "{kind}: frame count"
        );
        let pose = |t: usize| -> Pose {
            r["poses"][t.to_string()]
                .as_object()
                .unwrap_or_else(|| panic!("{kind}: no pose at frame {t}"))
                .iter()
                .map(|(k, v)| {
                    (
                        k.clone(),
                        Vector3::new(
                            v[0].as_f64().unwrap(),
                            v[1].as_f64().unwrap(),
                            v[2].as_f64().unwrap(),
                        ),
                    )
                })
                .collect()
        };
        compare(
            &format!("Blender, motion.{kind}?rig={rig}"),
            motion,
            frames,
            &pose,
            landmark,
        );
    }
}

/// Runs Blender on `args`, panicking with its log when it fails; returns its stdout.
fn blender(args: &[&std::ffi::OsStr]) -> String {
    let run = std::process::Command::new("blender")
        .args(args)
        .output()
        .expect("run blender");
    let out = String::from_utf8_lossy(&run.stdout).to_string();
    assert!(
        run.status.success(),
        "blender {args:?} failed:\n{out}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    out
}

/// The recipe of docs/integrating.md: `tools/blender_import.py` imports the dance (glb and BVH)
/// and saves a .blend; opened again, the .blend's scene runs at the dance's frame rate, its
/// action has one key on each whole frame, lasts the dance's seconds, and the armature (of the
/// glb and of the BVH alike) is named for the rig.
pub(super) fn the_import_recipe_plays_the_dance(
    bvh: &Path,
    glb: &Path,
    armature: &str,
    dir: &Path,
    motion: &Value,
) {
    let fps = motion["fps"].as_f64().expect("fps");
    let frames = motion["num_frames"].as_u64().expect("num_frames");
    let seconds = (frames - 1) as f64 / fps;
    let tool = root().join("tools/blender_import.py");
    let check = root().join("tests/blender/check_blend.py");
    for (kind, file) in [("glb", glb), ("bvh", bvh)] {
        let blend = dir.join(format!("recipe.{kind}.blend"));
        let out = blender(&[
            "--background".as_ref(),
            "--factory-startup".as_ref(),
            "--python-exit-code".as_ref(),
            "1".as_ref(),
            "--python".as_ref(),
            tool.as_os_str(),
            "--".as_ref(),
            file.as_os_str(),
            blend.as_os_str(),
        ]);
        let line = out
            .lines()
            .find_map(|l| l.strip_prefix("choreo-import: {").map(|r| format!("{{{r}")))
            .unwrap_or_else(|| panic!("{kind}: no summary line in\n{out}"));
        let summary: Value = serde_json::from_str(&line).expect("summary");
        eprintln!("tools/blender_import.py, {kind}: {summary}");
        let result = dir.join(format!("recipe.{kind}.json"));
        blender(&[
            "-b".as_ref(),
            "--factory-startup".as_ref(),
            blend.as_os_str(),
            "--python-exit-code".as_ref(),
            "1".as_ref(),
            "-P".as_ref(),
            check.as_os_str(),
            "--".as_ref(),
            result.as_os_str(),
        ]);
        let r: Value =
            serde_json::from_str(&std::fs::read_to_string(&result).expect("check_blend result"))
                .expect("json");
        eprintln!("the saved .blend, {kind}: {r}");
        assert_eq!(
            r["armatures"].as_array().map(Vec::len),
            Some(1),
            "{kind}: {r}"
        );
        let name = r["armatures"][0].as_str().expect("armature name");
        // A BVH names no armature (Blender would call it after the file): the tool names it as
        // the same dance's glb does.
        let expected = armature.to_string();
        assert_eq!(name, expected, "{kind}: armature");
        assert_eq!(summary["armature"], expected, "{kind}: the tool's summary");
        let scene_fps = r["fps"].as_f64().expect("fps");
        assert!(
            (scene_fps - fps).abs() < 1e-6,
            "{kind}: scene at {scene_fps} fps"
        );
        assert_eq!(r["keyframes"].as_u64(), Some(frames), "{kind}: keyframes");
        let off = r["off_whole_frames"].as_f64().expect("off");
        assert!(off < 1e-3, "{kind}: keys {off} frames off whole frames");
        let lasts = r["seconds"].as_f64().expect("seconds");
        assert!(
            (lasts - seconds).abs() < 1e-3,
            "{kind}: the action lasts {lasts} s, the dance {seconds} s"
        );
        let range = (r["frame_end"].as_f64().unwrap() - r["frame_start"].as_f64().unwrap()) as u64;
        assert_eq!(range + 1, frames, "{kind}: scene frame range");
    }
}
