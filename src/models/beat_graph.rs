//! beat-graph: real dance units composed on the song's beats, in the manner of ChoreoMaster
//! (Chen et al., "ChoreoMaster: Choreography-Oriented Music-Driven Dance Synthesis", SIGGRAPH
//! 2021), with the unit warping of ChoreoGraph (Au et al., MM 2022).
//!
//! ChoreoMaster does not generate poses: it cuts real dances into *dance units* at the music's
//! beats, links them into a *choreography-oriented motion graph* (an edge where one unit's end
//! meets another's start), and finds the path through the graph that fits the song by dynamic
//! programming over its beats, with costs for the transition, the music match (its rhythm and
//! style signatures) and repetition. Here:
//! - [`library`]: the units of the train split, each one beat of a real dance between two of
//!   its song's beats (our own analysis of the training song), with its style, bar position,
//!   boundary poses and velocities; the graph's edges, the nearest starts to each unit's end.
//! - [`rhythm`]: the music match. A beat of music is described by its onset intensity, accent,
//!   harmonic change and tempo ([`rhythm::music_descriptors`]); a unit by how its body moves
//!   ([`rhythm::motion_descriptors`]); a ridge map fitted on the train pairs predicts the one
//!   from the other, and the cost is the predicted motion's distance to the unit's
//!   (the rhythm signature's role in the paper, derived rather than learned by a network).
//! - [`search`]: beam search over the song's beats (the paper's dynamic programme, with the
//!   history that a repetition cost needs), Gumbel noise on the costs drawn from the job's seed.
//! - [`compose`]: each unit time-warped onto its beat interval, joins inertialized.
//!
//! Nothing in this folder serves a request; [`served`] does, and is the only file that knows
//! of jobs.
use serde::{Deserialize, Serialize};

pub mod body;
pub mod compose;
pub mod library;
pub mod rhythm;
pub mod search;
pub mod served;

pub use served::{Composition, Served, ID};

/// The composition's settings: ChoreoMaster's graph and search, with the weights of its costs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Config {
    /// Edges kept per unit in the motion graph: the units whose start best meets its end.
    pub graph_degree: usize,
    /// Paths kept at each beat of the search.
    pub beam_width: usize,
    /// Most beats in a row taken in order from one training dance (the graph's natural edge):
    /// held-out real dances repeat 1.3–7.4 s of some training dance, and a path that follows
    /// one dance longer replays it.
    pub max_run_beats: usize,
    /// Beats within which no unit comes back (nor its neighbours in its dance).
    pub repetition_beats: usize,
    /// Cost of a transition, per metre of root-relative joint distance (RMS) between one unit's
    /// end and the next one's start, velocities included ([`library::Library::transition`]).
    pub transition_weight: f64,
    /// Cost of the music match per unit of [`rhythm::Match::cost`].
    pub rhythm_weight: f64,
    /// Cost of a unit starting at another position in the bar than the song's beat.
    pub phase_weight: f64,
    /// Cost per `(ln stretch)²` of warping a unit onto its beat interval.
    pub stretch_weight: f64,
    /// Stretches beyond this range (song beat ÷ unit beat) are not taken at all: a unit played
    /// that much slower or faster no longer looks like the dance it came from.
    pub stretch_range: (f64, f64),
    /// Cost of a unit of another style than the dance's (taken only where the style has too
    /// few units of its own, [`library::MIN_STYLE_UNITS`]).
    pub style_weight: f64,
    /// Cost of a unit seen within [`Self::repetition_beats`].
    pub repetition_weight: f64,
    /// Cost per metre (RMS over joints) between a key pose and the unit's pose at its frame.
    pub key_weight: f64,
    /// Scale of the Gumbel noise the job's seed adds to every cost: different seeds, different
    /// paths, each still a good one.
    pub gumbel_scale: f64,
    /// Most cost the job's seed adds to a training dance's units (a uniform draw per dance): each
    /// seed leans towards some dancers, so a dance keeps a character and seeds differ in it,
    /// where an even mixture of every dancer is the same average dance on every seed.
    #[serde(default)]
    pub dance_preference: f64,
    /// Half-life (seconds) of the inertialization that absorbs a join's pose and velocity gap.
    pub blend_halflife_s: f64,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            graph_degree: 24,
            beam_width: 32,
            max_run_beats: 8,
            repetition_beats: 24,
            transition_weight: 12.0,
            rhythm_weight: 0.4,
            phase_weight: 3.0,
            stretch_weight: 4.0,
            stretch_range: (0.7, 1.45),
            style_weight: 1.5,
            repetition_weight: 4.0,
            key_weight: 20.0,
            gumbel_scale: 0.35,
            dance_preference: 4.0,
            blend_halflife_s: 0.12,
        }
    }
}
