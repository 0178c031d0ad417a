//! What each serving stage did to a dance. The stages after a model ([`super::after_model_observed`])
//! and at export ([`super::serve_observed`]) show a [`StageObserver`] the dance before and after
//! each of them, with what they counted of their own work. They measure nothing else: how real a
//! dance looks is the metrics' business, and the report's observer asks them
//! (`report::serving`), so motion never reaches down the flow into the grader.
use super::Motion;

/// A stage every served dance may go through after its model, in the order they run. Serialised
/// as a stable snake_case name: report.json readers and the page key on it.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum ServingStage {
    /// The dance's pace follows a song whose tempo changes
    /// ([`super::beat_align::tempo_follow`]).
    TempoFollow,
    /// The steps moved onto the song's beats ([`super::beat_align::align_served`]): the warp
    /// alone, the feet as the network left them.
    BeatAlign,
    /// Backward knees turned forward ([`super::knees::bend_forward`]).
    KneesForward,
    /// The lowest foot brought to the floor ([`super::feet::ground`]).
    Ground,
    /// A float with both feet up brought down ([`super::feet::land_hangs`]).
    LandHangs,
    /// The supporting foot held still ([`super::feet::plant_feet`]).
    PlantFeet,
    /// The request's seed motion put back as it came (only with a seed motion).
    KeepSeed,
    /// The export's rigid skeleton fitted to the dance ([`super::export::prepare_seeded`]).
    RigidFit,
    /// The fitted skeleton's pops calmed ([`super::bursts::calm`]).
    CalmBursts,
    /// The fitted skeleton put back on the floor, its root moved only.
    GroundRig,
}

/// What a stage counts of its own work, where it counts something; each is absent for the other
/// stages.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    utoipa::ToSchema,
)]
pub struct StageCounts {
    /// `beat_align`: frames the warp shows from another moment of the network's dance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_retimed: Option<usize>,
    /// `knees_forward`: knee-frames turned forward (two knees a frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub knee_frames_turned: Option<usize>,
    /// `plant_feet`: frame steps on which a foot bore the body and was held still.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_steps_planted: Option<usize>,
    /// `calm_bursts`: frames whose pops were calmed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_calmed: Option<usize>,
}

/// Hears each serving stage that ran, in order.
pub trait StageObserver {
    /// Whether it listens at all: where not, the stages keep no copy of the dance before them.
    fn observes(&self) -> bool {
        true
    }

    /// `stage` ran: `before` is the dance it was given, `after` the dance it left.
    fn stage(&mut self, stage: ServingStage, before: &Motion, after: &Motion, counts: StageCounts);
}

/// Listens to nothing: `choreo eval`, and the candidates beat alignment judges before one is
/// served.
pub struct Unobserved;

impl StageObserver for Unobserved {
    fn observes(&self) -> bool {
        false
    }

    fn stage(&mut self, _: ServingStage, _: &Motion, _: &Motion, _: StageCounts) {}
}

/// Runs `work` on `motion` in place as `stage`, and tells `observer`.
pub(crate) fn traced(
    motion: &mut Motion,
    stage: ServingStage,
    observer: &mut dyn StageObserver,
    work: impl FnOnce(&mut Motion) -> StageCounts,
) {
    let before = observer.observes().then(|| motion.clone());
    let counts = work(motion);
    if let Some(before) = before {
        observer.stage(stage, &before, motion, counts);
    }
}
