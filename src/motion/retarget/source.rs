//! The dance to retarget, read back from what a job serves: motion.json ([`MotionJson`]) holds
//! choreo's rig (names, parents, offsets) and its local rotations, so the exact [`RigMotion`]
//! the job exported comes back from it.
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::RetargetError;
use crate::motion::export::MotionJson;
use crate::motion::rig::{Rig, RigMotion};

/// The rig motion a motion.json describes.
pub fn from_motion_json(m: &MotionJson) -> Result<RigMotion, RetargetError> {
    let n = m.joint_names.len();
    let bad = |what: String| RetargetError::NotChoreoMotion(what);
    if m.parents.len() != n || m.offsets.len() != n {
        return Err(bad(format!(
            "{n} joint names, {} parents, {} offsets",
            m.parents.len(),
            m.offsets.len()
        )));
    }
    if m.rotations.is_empty() {
        return Err(RetargetError::EmptyMotion);
    }
    if m.root_translation.len() != m.rotations.len() || m.rotations.iter().any(|f| f.len() != n) {
        return Err(bad(
            "rotations and root_translation do not have one row per frame and joint".into(),
        ));
    }
    if !(m.fps.is_finite() && m.fps > 0.0) {
        return Err(bad(format!("fps {}", m.fps)));
    }
    let parents = m
        .parents
        .iter()
        .map(|&p| match p {
            -1 => Ok(None),
            p if p >= 0 && (p as usize) < n => Ok(Some(p as usize)),
            p => Err(bad(format!("parent index {p}"))),
        })
        .collect::<Result<Vec<_>, _>>()?;
    let v3 = |v: &[f32; 3]| Vector3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
    let rig = Rig {
        names: m.joint_names.clone(),
        parents,
        offsets: m.offsets.iter().map(v3).collect(),
    };
    let rotations = m
        .rotations
        .iter()
        .map(|frame| {
            frame
                .iter()
                .map(|q| {
                    let q = Quaternion::new(
                        f64::from(q[3]),
                        f64::from(q[0]),
                        f64::from(q[1]),
                        f64::from(q[2]),
                    );
                    if q.norm() > 1e-6 && q.coords.iter().all(|c| c.is_finite()) {
                        Ok(UnitQuaternion::from_quaternion(q))
                    } else {
                        Err(bad("a rotation is not a unit quaternion".into()))
                    }
                })
                .collect::<Result<Vec<_>, _>>()
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(RigMotion {
        rig,
        fps: m.fps,
        root_translation: m.root_translation.iter().map(v3).collect(),
        rotations,
    })
}
