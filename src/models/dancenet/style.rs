//! TEMPORARY (replaced by the musical style classifier from the dancenet-style branch).
use std::path::Path;

use crate::models::ModelError;

/// The classifier's weights file.
pub const STYLE_WEIGHTS_FILE: &str = "style.safetensors";
/// The classifier's description file.
pub const STYLE_FILE: &str = "style.json";

/// Placeholder.
pub struct ServedStyle;

impl ServedStyle {
    /// Placeholder.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        Err(ModelError::MissingWeights("dancenet style classifier".into(), dir.display().to_string()))
    }

    /// Placeholder.
    pub fn predict(&self, _features: &ndarray::Array2<f32>) -> Result<[f32; 4], ModelError> {
        Err(ModelError::Invalid("no style classifier".into()))
    }
}
