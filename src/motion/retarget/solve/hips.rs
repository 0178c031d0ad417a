//! The hips' shift onto the supporting feet (step 4 of the solver's doc): each foot's ask of it
//! along its leg and across, summed.
use nalgebra::{Matrix3, Vector3};

use super::ACROSS_LEG_WEIGHT;

/// One supporting foot's ask of the hips' shift `s`, as the normal equations of
/// `|uᵀs − c|² + ACROSS_LEG_WEIGHT · |P(s − (floor − reach))|²`: `u` the direction from the
/// target's `hip` to the floor goal, `c` how much nearer the hip must come along it for the leg
/// to reach with the dance's knee angle (the reach goal's distance), `P` the projection across
/// the leg. The shift then keeps each knee's angle where the feet allow, and otherwise goes by the
/// floor goal's offset from the reach goal, as a plain mean did.
pub(super) fn leg_gap(floor: &Vector3<f64>, reach: &Vector3<f64>, hip: &Vector3<f64>) -> GapSum {
    let gap = floor - reach;
    let Some(u) = (floor - hip).try_normalize(1e-9) else {
        return GapSum {
            normal: Matrix3::identity(),
            rhs: gap,
            weight: 1.0,
        };
    };
    let c = (floor - hip).norm() - (reach - hip).norm();
    let along = u * u.transpose();
    let across = Matrix3::identity() - along;
    GapSum {
        normal: along + across * ACROSS_LEG_WEIGHT,
        rhs: u * c + across * gap * ACROSS_LEG_WEIGHT,
        weight: 1.0,
    }
}

/// Supporting feet's asks of the hips' shift, summed (weighted by how firmly each stands): the
/// normal equations of one least-squares shift.
#[derive(Clone, Copy)]
pub(super) struct GapSum {
    normal: Matrix3<f64>,
    rhs: Vector3<f64>,
    pub(super) weight: f64,
}

impl Default for GapSum {
    fn default() -> Self {
        GapSum {
            normal: Matrix3::zeros(),
            rhs: Vector3::zeros(),
            weight: 0.0,
        }
    }
}

impl GapSum {
    pub(super) fn add(self, g: &GapSum, w: f64) -> GapSum {
        GapSum {
            normal: self.normal + g.normal * w,
            rhs: self.rhs + g.rhs * w,
            weight: self.weight + g.weight * w,
        }
    }

    pub(super) fn merge(self, g: &GapSum) -> GapSum {
        self.add(g, 1.0)
    }

    /// The shift, where any foot stands.
    pub(super) fn shift(&self) -> Option<Vector3<f64>> {
        if self.weight <= 0.0 {
            return None;
        }
        self.normal.try_inverse().map(|m| m * self.rhs)
    }
}
