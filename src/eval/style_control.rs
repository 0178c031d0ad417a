//! Style control, for models that dance a style asked for (DanceNet): every song danced once in
//! each of the four styles with one seed, then
//! - how far apart the styles' dances are (root-relative pose distance, the seed-sensitivity
//!   measure of [`crate::metrics::physical::seed_distance_m`]): a style input that changes nothing reads 0;
//! - whether each dance still passes the plausibility verdict, and how fast it moves;
//! - what a classifier trained on real motion alone ([`crate::models::motion_style::MotionStyle`]) says each
//!   dance is, beside what it says of the real test dances: its accuracy on real dances is the
//!   ceiling a model's "agrees" share can be read against.
use serde::{Deserialize, Serialize};

use super::EvalError;
use crate::audio::DecodedAudio;
use crate::metrics::physical::seed_distance_m;
use crate::metrics::reference::ReferenceStats;
use crate::metrics::score::score_dance;
use crate::models::dancenet::style::most_probable;
use crate::models::motion_style::MotionStyle;
use crate::models::{DanceModel, DanceStyle, GenerateRequest, Progress};
use crate::motion::Motion;

/// A song to dance, with its beats (seconds from its start).
pub struct StyleSong<'a> {
    pub name: &'a str,
    pub audio: &'a DecodedAudio,
    pub beats: &'a [f64],
}

/// The dances of one style asked for.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct StyleAsked {
    pub style: DanceStyle,
    pub dances: usize,
    /// Dances that pass the plausibility verdict (as served: feet planted, rigid export).
    pub passing: usize,
    /// Mean joint speed over the dances (m/s).
    pub mean_speed_m_s: f64,
    /// How many dances the motion classifier put in each style ([`DanceStyle::ALL`] order).
    pub classified: Vec<usize>,
    /// Share of dances the motion classifier puts in the style asked for.
    pub agrees: Option<f64>,
}

/// One model's style control.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct StyleControl {
    pub model: String,
    pub seed: u64,
    pub songs: Vec<String>,
    /// One entry per style, [`DanceStyle::ALL`] order.
    pub asked: Vec<StyleAsked>,
    /// `[4][4]`: mean root-relative pose distance (m) between the dances of two styles, same song
    /// and seed; the diagonal is 0.
    pub distance_m: Vec<Vec<f64>>,
    /// The smallest off-diagonal entry of `distance_m`.
    pub min_distance_m: f64,
}

/// The motion classifier on the real dances of the test split.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct RealStyles {
    /// `(dance id, its style, the classifier's)`.
    pub dances: Vec<(String, DanceStyle, DanceStyle)>,
    pub accuracy: f64,
}

/// Classifies real dances `(id, motion)`, their style from the id.
pub fn real_styles(
    classifier: &MotionStyle,
    dances: &[(&str, &Motion)],
) -> Result<RealStyles, EvalError> {
    let mut out = Vec::new();
    for (id, m) in dances {
        let Some(truth) = DanceStyle::of_dance_id(id) else {
            continue;
        };
        let p = classifier
            .classify(m)
            .map_err(|source| EvalError::Classifier {
                dance: Some(id.to_string()),
                source,
            })?;
        out.push((id.to_string(), truth, most_probable(&p)));
    }
    let accuracy = out.iter().filter(|(_, a, b)| a == b).count() as f64 / out.len().max(1) as f64;
    Ok(RealStyles {
        dances: out,
        accuracy,
    })
}

/// Dances every song in every style with `seed` and measures the differences.
pub fn style_control(
    model: &dyn DanceModel,
    id: &str,
    songs: &[StyleSong<'_>],
    seed: u64,
    classifier: Option<&MotionStyle>,
    reference: &ReferenceStats,
    progress: &mut dyn Progress,
) -> Result<StyleControl, EvalError> {
    let mut asked = Vec::new();
    // served[style][song]
    let mut served: Vec<Vec<Motion>> = Vec::new();
    for style in DanceStyle::ALL {
        let (mut passing, mut speed, mut classified) = (0, 0.0, vec![0usize; 4]);
        let mut motions = Vec::new();
        for s in songs {
            let req = GenerateRequest {
                style: Some(style),
                ..GenerateRequest::plain(s.audio, seed)
            };
            let asked_id = format!("{id} ({})", style.name());
            let (raw, composed) = super::generate(model, &asked_id, s.name, &req, progress)?;
            let (m, _) = super::as_served(raw, composed, &[], s.beats).map_err(|source| {
                EvalError::Export {
                    model: id.into(),
                    song: s.name.to_string(),
                    source,
                }
            })?;
            let sc = score_dance(&m, s.beats, &[], reference)?;
            passing += usize::from(sc.scores.verdict.pass);
            speed += sc.scores.physical.mean_speed_m_s;
            if let Some(c) = classifier {
                let p = c.classify(&m).map_err(|source| EvalError::Classifier {
                    dance: None,
                    source,
                })?;
                classified[most_probable(&p).index()] += 1;
            }
            motions.push(m);
        }
        let n = songs.len();
        asked.push(StyleAsked {
            style,
            dances: n,
            passing,
            mean_speed_m_s: speed / n.max(1) as f64,
            agrees: classifier.map(|_| classified[style.index()] as f64 / n.max(1) as f64),
            classified,
        });
        served.push(motions);
    }
    let mut distance_m = vec![vec![0.0; 4]; 4];
    let mut min_distance_m = f64::INFINITY;
    for a in 0..4 {
        for b in a + 1..4 {
            let d: Vec<f64> = (0..songs.len())
                .map(|k| seed_distance_m(&served[a][k], &served[b][k]))
                .filter(|x| !x.is_nan())
                .collect();
            let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
            distance_m[a][b] = mean;
            distance_m[b][a] = mean;
            min_distance_m = min_distance_m.min(mean);
        }
    }
    Ok(StyleControl {
        model: id.into(),
        seed,
        songs: songs.iter().map(|s| s.name.to_string()).collect(),
        asked,
        distance_m,
        min_distance_m,
    })
}

/// The Markdown of the style-control section.
pub fn markdown(controls: &[StyleControl], real: Option<&RealStyles>) -> String {
    let mut out = String::new();
    if let Some(r) = real {
        let wrong: Vec<String> = r
            .dances
            .iter()
            .filter(|(_, a, b)| a != b)
            .map(|(id, _, b)| format!("{id} as {}", b.name()))
            .collect();
        out += &format!(
            "Motion style classifier on the real test dances: {}/{} right ({:.0} %){}.\n\n",
            r.dances.len() - wrong.len(),
            r.dances.len(),
            100.0 * r.accuracy,
            if wrong.is_empty() {
                String::new()
            } else {
                format!("; wrong: {}", wrong.join(", "))
            }
        );
    }
    for c in controls {
        out += &format!(
            "**{}**, seed {}, {} songs; each row one style asked for:\n\n",
            c.model,
            c.seed,
            c.songs.len()
        );
        out += "| Style asked | Dances | Pass | Speed m/s | Classified cha-cha / rumba / tango / waltz | Agrees | Distance to cha-cha / rumba / tango / waltz m |\n|---|---|---|---|---|---|---|\n";
        for (i, a) in c.asked.iter().enumerate() {
            let d: Vec<String> = c.distance_m[i].iter().map(|x| format!("{x:.2}")).collect();
            out += &format!(
                "| {} | {} | {}/{} | {:.2} | {} | {} | {} |\n",
                a.style.name(),
                a.dances,
                a.passing,
                a.dances,
                a.mean_speed_m_s,
                a.classified
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(" / "),
                a.agrees
                    .map_or("–".into(), |x| format!("{:.0} %", 100.0 * x)),
                d.join(" / ")
            );
        }
        out += &format!(
            "\nSmallest distance between two styles' dances: {:.2} m.\n\n",
            c.min_distance_m
        );
    }
    out
}
