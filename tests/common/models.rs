//! The committed models, for every test binary that serves or runs them.
#![allow(dead_code)]
use std::path::PathBuf;

/// The five served models, by id.
pub const SERVED: [&str; 5] = [
    "dance-revolution",
    "keypose-transformer",
    "tsmt",
    "dancenet",
    "beat-graph",
];

/// `models/` of this checkout; panics, naming what is missing, unless every served model's
/// committed weights are there (they are part of the repository, so a missing file is a defect).
pub fn models_dir() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models");
    for id in SERVED {
        let weights = dir.join(id).join("weights.safetensors");
        assert!(
            weights.is_file(),
            "the committed weights are missing: {}",
            weights.display()
        );
    }
    dir
}
