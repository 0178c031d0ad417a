//! report.json's `serving` list: what each serving stage did to the dance
//! ([`crate::motion::trace`]): whether it moved it, how many frames and how far, what it counted,
//! and TSMT's authenticity and coherence ([`crate::metrics::plausibility`], the measures `choreo
//! eval` reports) before and after it, so a stage that makes a dance less real shows.
use crate::metrics::plausibility::{plausibility, AngleLimits, Plausibility};
use crate::motion::trace::{ServingStage, StageCounts, StageObserver};
use crate::motion::Motion;
use ndarray::Array3;

/// One serving stage that ran, as report.json states it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct StageTrace {
    pub stage: ServingStage,
    /// Whether any joint of any frame moved at all.
    pub changed: bool,
    /// Frames on which some joint moved (every frame from where the stage changed the length).
    pub frames_changed: usize,
    /// The largest distance (m) one joint moved on one frame.
    pub largest_move_m: f64,
    /// What the stage counted of its own work, where it counts something.
    #[serde(flatten)]
    pub counts: StageCounts,
    /// Authenticity and coherence of the dance the stage was given.
    pub before: Plausibility,
    /// Authenticity and coherence of the dance the stage left.
    pub after: Plausibility,
}

/// A [`StageObserver`] that writes the list. Each stage's dance is judged once: a stage's
/// `before` is the dance the stage before it left, so that judgement is kept and reused.
pub struct Recorder {
    limits: AngleLimits,
    /// The last dance judged and its judgement.
    judged: Option<(Array3<f32>, Plausibility)>,
    stages: Vec<StageTrace>,
}

impl Recorder {
    /// A recorder judging against `limits` (the reference's, as the report's own scores).
    pub fn new(limits: AngleLimits) -> Self {
        Self {
            limits,
            judged: None,
            stages: Vec::new(),
        }
    }

    /// The stages heard so far, in order.
    pub fn into_stages(self) -> Vec<StageTrace> {
        self.stages
    }

    fn judge(&mut self, motion: &Motion) -> Plausibility {
        if let Some((positions, judged)) = &self.judged {
            if *positions == motion.positions {
                return judged.clone();
            }
        }
        let judged = plausibility(motion.positions.view(), motion.fps, &self.limits);
        self.judged = Some((motion.positions.clone(), judged.clone()));
        judged
    }
}

impl StageObserver for Recorder {
    fn stage(&mut self, stage: ServingStage, before: &Motion, after: &Motion, counts: StageCounts) {
        let (frames_changed, largest_move_m) = difference(before, after);
        let judged_before = self.judge(before);
        let judged_after = self.judge(after);
        self.stages.push(StageTrace {
            stage,
            changed: frames_changed > 0,
            frames_changed,
            largest_move_m,
            counts,
            before: judged_before,
            after: judged_after,
        });
    }
}

/// Frames on which any joint differs between `a` and `b` (every frame past the shorter's end
/// counts), and the largest distance (m) between one joint's two positions.
fn difference(a: &Motion, b: &Motion) -> (usize, f64) {
    let (ta, ja, _) = a.positions.dim();
    let (tb, jb, _) = b.positions.dim();
    let (frames, joints) = (ta.min(tb), ja.min(jb));
    let mut changed = ta.max(tb) - frames;
    let mut largest = 0.0f64;
    for f in 0..frames {
        let mut moved = ja != jb;
        for j in 0..joints {
            let d: f64 = (0..3)
                .map(|k| f64::from(a.positions[[f, j, k]] - b.positions[[f, j, k]]).powi(2))
                .sum::<f64>()
                .sqrt();
            // Bit equality, not a distance: a stage that moved a joint by less than a float's
            // rounding still changed what is served.
            moved |= (0..3).any(|k| a.positions[[f, j, k]] != b.positions[[f, j, k]]);
            largest = largest.max(d);
        }
        changed += usize::from(moved);
    }
    (changed, largest)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion(frames: usize, lift: f32) -> Motion {
        Motion {
            fps: 25.0,
            positions: Array3::from_elem((frames, crate::motion::NUM_JOINTS, 3), lift),
        }
    }

    #[test]
    fn a_stage_that_moved_nothing_says_so() {
        assert_eq!(difference(&motion(10, 0.0), &motion(10, 0.0)), (0, 0.0));
    }

    #[test]
    fn frames_moved_and_the_largest_move_are_counted() {
        let a = motion(10, 0.0);
        let mut b = a.clone();
        b.positions[[3, 5, 1]] = 0.25;
        b.positions[[7, 0, 0]] = -0.5;
        let (frames, largest) = difference(&a, &b);
        assert_eq!(frames, 2);
        assert!((largest - 0.5).abs() < 1e-9, "{largest}");
        // A dance the stage made longer: the new frames count as changed.
        assert_eq!(difference(&a, &motion(12, 0.0)).0, 2);
    }
}
