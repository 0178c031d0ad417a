//! Motion core: the 23-joint skeleton, the real dataset, representations, and exporters.
//!
//! CONTRACT STUB (lead): the names below are what the rest of the crate calls; the motion
//! owner fills in the rest and may add fields, not rename.
use ndarray::Array3;

/// Frame rate of the dance-with-melody data.
pub const MOTION_FPS: f64 = 25.0;
/// Joints in the skeleton (21 anatomical + 2 hand-direction points).
pub const NUM_JOINTS: usize = 23;

/// A dance: world joint positions in metres, y up, `[T, J, 3]`.
#[derive(Clone, Debug)]
pub struct Motion {
    pub fps: f64,
    pub positions: Array3<f32>,
}

/// A key pose a user fixes: root-relative joint positions in metres at a time in the song.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct KeyPose {
    pub time_s: f64,
    /// `J × [x, y, z]`, metres, root-relative, in `joint_names` order.
    pub joints: Vec<[f64; 3]>,
}
