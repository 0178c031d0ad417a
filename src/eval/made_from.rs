//! What a committed evaluation was made from: each model folder's files by SHA-256 and the
//! serving revision, so that a test tells an `eval.json` of other weights or other serving
//! stages from one of what is served.
use std::collections::BTreeMap;
use std::path::Path;

use sha2::{Digest, Sha256};

/// The revision of what serving does to a network's output (the fixes inside each model's
/// `generate` and the shared stages after it). Raise it with any change that alters a served
/// `motion.json` (`tools/served_identical.sh` tells), and make the committed evaluations again.
pub const SERVING_REVISION: u32 = 5;

/// A model folder's files that describe it rather than serve it: its card, its evaluation, its
/// training logs.
fn describes(name: &str) -> bool {
    name == "README.md" || name == "eval.json" || name.ends_with(".jsonl")
}

/// One evaluated model's provenance.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct MadeFrom {
    pub model: String,
    /// SHA-256 (hex) of each file the model is served from, by file name.
    pub files: BTreeMap<String, String>,
    /// [`SERVING_REVISION`] when the evaluation ran.
    pub serving_revision: u32,
}

impl MadeFrom {
    /// The provenance of `model` served from folder `dir`, as of now.
    pub fn of(model: &str, dir: &Path) -> std::io::Result<Self> {
        let mut files = BTreeMap::new();
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if describes(&name) || !entry.file_type()?.is_file() {
                continue;
            }
            let bytes = std::fs::read(entry.path())?;
            files.insert(name, hex::encode(Sha256::digest(&bytes)));
        }
        Ok(Self {
            model: model.to_string(),
            files,
            serving_revision: SERVING_REVISION,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A weight file that changes changes the provenance; the card and logs do not.
    #[test]
    fn the_provenance_follows_the_served_files_only() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("model.json"), b"{}").unwrap();
        std::fs::write(dir.path().join("weights.safetensors"), b"w1").unwrap();
        std::fs::write(dir.path().join("README.md"), b"card").unwrap();
        let before = MadeFrom::of("m", dir.path()).unwrap();
        assert_eq!(before.files.len(), 2);
        std::fs::write(dir.path().join("README.md"), b"another card").unwrap();
        std::fs::write(dir.path().join("train_log.jsonl"), b"{}").unwrap();
        assert_eq!(MadeFrom::of("m", dir.path()).unwrap(), before);
        std::fs::write(dir.path().join("weights.safetensors"), b"w2").unwrap();
        assert_ne!(MadeFrom::of("m", dir.path()).unwrap(), before);
    }
}
