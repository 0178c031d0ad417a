//! Hostile motion files made from the rig fixture, for the readers' tests and the server's.
use std::path::Path;

/// The mannequin rig (Unreal names, centimetres), a hierarchy without frames.
pub fn rig_fixture() -> String {
    std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rig_unreal_cm.bvh"),
    )
    .expect("rig fixture")
}

/// `text`'s hierarchy with every `CHANNELS n name…` clause taken out, line by line.
pub fn without_channels(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines().take_while(|l| !l.starts_with("MOTION")) {
        let mut tokens = line.split_whitespace();
        let mut kept = Vec::new();
        while let Some(token) = tokens.next() {
            if token == "CHANNELS" {
                let n: usize = tokens.next().and_then(|n| n.parse().ok()).unwrap_or(0);
                tokens.by_ref().take(n).for_each(drop);
            } else {
                kept.push(token);
            }
        }
        out.push_str(&kept.join(" "));
        out.push('\n');
    }
    out
}

/// The 1 KB BVH that once aborted the server: the rig fixture with every `CHANNELS` clause
/// removed, claiming `frames` frames.
pub fn claiming_frames(frames: &str) -> String {
    format!(
        "{}MOTION\nFrames: {frames}\nFrame Time: 0.04\n",
        without_channels(&rig_fixture())
    )
}
