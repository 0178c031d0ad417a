//! The Markdown tables of `choreo eval`: per section, scores, physical plausibility and TSMT's
//! measures; the style-control section is [`super::style_control::markdown`].
use super::{EvalResult, EvalRow};
use crate::metrics::physical::{Criterion, PhysicalScores, Verdict};
use crate::metrics::reference::ReferenceStats;

fn f(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.3}")
    }
}

fn f2(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.2}")
    }
}

fn opt(x: Option<f64>) -> String {
    x.map(f).unwrap_or_else(|| "–".into())
}

/// The failing criteria with their values, or "pass".
fn verdict_cell(v: &Verdict) -> String {
    let fails: Vec<String> = v
        .criteria
        .iter()
        .filter(|c: &&Criterion| c.pass == Some(false))
        .map(|c| format!("✗ {} {}", c.name, c.value.map(f2).unwrap_or_default()))
        .collect();
    if fails.is_empty() {
        "pass".into()
    } else {
        fails.join("; ")
    }
}

/// The scores table of a set of rows.
fn scores_table(rows: &[EvalRow]) -> String {
    let mut out = String::from(
        "| Motion | n | BAS FACT ↑ | (chance) | BAS Bailando ↑ | Coverage | Hit rate ↑ | Rhythm hit ↑ | Beat F ↑ | FID_k window ↓ | FID_g window ↓ | FID_k dance ↓ | FID_g dance ↓ | Div_k | Div_g | S_cv ↓ | Skate ↓ | Authentic ↑ | Coherent ↑ | Multimodality |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let m = &r.scores.mean;
        let cells = [
            r.name.clone(),
            r.scores.dances.to_string(),
            f(m.rhythm.bas_fact),
            f(m.rhythm.bas_fact_chance),
            f(m.rhythm.bas_bailando),
            f(m.rhythm.beat_coverage),
            f(m.rhythm.beat_hit_rate),
            f(m.rhythm.rhythm_hit),
            f(m.rhythm.f_measure),
            f(r.scores.fid_k_window),
            f(r.scores.fid_g_window),
            f(r.scores.fid_k_dance),
            f(r.scores.fid_g_dance),
            f(r.scores.div_k),
            f(r.scores.div_g),
            f(m.smoothness_cv),
            f(m.foot_skating.skate_ratio),
            f(m.plausibility.authenticity),
            f(m.plausibility.coherence),
            opt(r.multimodality),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

const PHYSICAL_HEADER: &str = "| Motion | n | Lowest foot p5 / median / p95 m | Below −5 cm | Deepest m | Accel median / p99 / p99.9 / max m/s² | Key pop max m/s² ↓ | Speed m/s | × real | Freeze L/F | Seed Δ m (min) | Key err cm (worst) ↓ | Verdict | Dances passing | Rotation flips > 60° / > 90° (worst joint) ↓ |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

/// TSMT's own measures (Li et al. 2020): its three diversities, authenticity and coherence, and
/// beat precision/recall/F of FACT motion beats against music beats (±0.1 s).
fn paper_table(rows: &[EvalRow]) -> String {
    let mut out = String::from("| Motion | n | A-seq-D | I-seq-D | S-music-D | Authentic ↑ | Coherent ↑ | Beat P | Beat R | Beat F (TSMT) |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let m = &r.scores.mean;
        let d = &r.diversity;
        let b = &m.rhythm.beat_prf;
        let cells = [
            r.name.clone(),
            r.scores.dances.to_string(),
            opt(d.a_seq_d),
            opt(d.i_seq_d),
            opt(d.s_music_d),
            f(m.plausibility.authenticity),
            f(m.plausibility.coherence),
            f(b.precision),
            f(b.recall),
            f(b.f),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

/// One line of the physical table: `tail` is the seed distance, key error, verdict and passing cells.
fn physical_cells(
    name: &str,
    n: usize,
    p: &PhysicalScores,
    freeze: f64,
    tail: [String; 5],
) -> String {
    let [seeds, key_err, verdict, passing, flips] = tail;
    let cells = [
        name.to_string(),
        n.to_string(),
        format!(
            "{} / {} / {}",
            f2(p.lowest_foot_m.p5),
            f2(p.lowest_foot_m.median),
            f2(p.lowest_foot_m.p95)
        ),
        format!("{:.1} %", 100.0 * p.below_floor_share),
        f2(p.deepest_m),
        format!(
            "{} / {} / {} / {}",
            f2(p.acceleration_m_s2.median),
            f2(p.acceleration_m_s2.p99),
            f2(p.acceleration_m_s2.p99_9),
            f2(p.acceleration_m_s2.max)
        ),
        p.key_pose_pops_m_s2
            .iter()
            .copied()
            .reduce(f64::max)
            .map(f2)
            .unwrap_or_else(|| "–".into()),
        f2(p.mean_speed_m_s),
        f2(p.speed_ratio),
        f(freeze),
        seeds,
        key_err,
        verdict,
        passing,
        flips,
    ];
    format!("| {} |\n", cells.join(" | "))
}

/// The physical-plausibility table of a set of rows, under the real train figures.
fn physical_table(rows: &[EvalRow], reference: Option<&ReferenceStats>) -> String {
    let mut out = String::from(PHYSICAL_HEADER);
    if let Some(r) = reference {
        let p = &r.physical;
        let name = format!(
            "Real train (reference; speed per dance {:.2}–{:.2})",
            p.mean_speed_range_m_s[0], p.mean_speed_range_m_s[1]
        );
        out.push_str(&physical_cells(
            &name,
            r.dances.len(),
            &p.pooled,
            f64::NAN,
            ["–".into(), "–".into(), "–".into(), "–".into(), "–".into()],
        ));
    }
    for r in rows {
        let m = &r.scores.mean;
        let seeds = match (r.seed_distance_m, r.seed_distance_min_m) {
            (Some(a), Some(b)) => format!("{} ({})", f2(a), f2(b)),
            _ => "–".into(),
        };
        let passing = format!("{}/{}", r.scores.dances_passing, r.scores.dances);
        let key_err = worst_key_error(r).map(f2).unwrap_or_else(|| "–".into());
        out.push_str(&physical_cells(
            &r.name,
            r.scores.dances,
            &m.physical,
            m.freezing_ratio,
            [
                seeds,
                key_err,
                verdict_cell(&m.verdict),
                passing,
                flips_cell(m.rotation_flips.as_ref()),
            ],
        ));
    }
    out
}

/// Rotation flips of a row's exported rigs: shares of frame steps past 60° and 90°, worst joint.
fn flips_cell(f: Option<&crate::metrics::rotation_flips::RotationFlips>) -> String {
    f.map_or_else(
        || "–".into(),
        |f| {
            format!(
                "{:.2} % / {:.2} % ({})",
                100.0 * f.share_over_60,
                100.0 * f.share_over_90,
                f.worst_joint.as_deref().unwrap_or("none")
            )
        },
    )
}

/// The row's worst key-pose error (cm), from its verdict.
fn worst_key_error(r: &EvalRow) -> Option<f64> {
    r.scores
        .mean
        .verdict
        .get(crate::metrics::physical::names::KEY_POSES)
        .and_then(|c| c.value)
}

/// The musicality bars on each row: tempo-locked dances (step rate within 3 % of 1/6…1 of the beat
/// rate; real dances 32 of 43), the stillest arms (≥ 0.43 m/s), the worst knees (≤ 6 %), and
/// the same seed on two songs (≥ 0.15 m apart); and the longest hold in one pose (real dances
/// at most 9.5 s, 41 of 43 under 5 s: [`crate::motion::hold`]), and the posture that changed
/// least over its song ([`crate::metrics::posture::posture_variety_m`]; real dances 0.059 m
/// at the least, a dance holding one figure near 0).
/// Beside the row's own tempo lock, the network's before the beat-align stage (model rows).
fn musicality_table(rows: &[EvalRow]) -> String {
    let mut out = String::from("| Motion | n | tempo-locked ↑ | network's own (before beat-align) | arms min (m/s) ↑ | knees backwards max ↓ | longest hold (s) ↓ | posture variety min (m) ↑ | same seed, two songs min (m) ↑ |\n|---|---|---|---|---|---|---|---|---|\n");
    let locked = |m: &crate::metrics::musicality::MusicalitySummary| {
        if m.measured == 0 {
            "–".to_string()
        } else {
            format!(
                "{}/{} ({:.0} %)",
                m.tempo_locked,
                m.measured,
                100.0 * m.tempo_locked_share
            )
        }
    };
    for r in rows {
        let m = &r.scores.musicality;
        let own = r
            .musicality_raw
            .as_ref()
            .map_or_else(|| "–".to_string(), locked);
        let cells = [
            r.name.clone(),
            r.scores.dances.to_string(),
            locked(m),
            own,
            f2(m.arm_speed_min_m_s),
            format!("{:.1} %", 100.0 * m.knee_backward_max),
            format!("{:.1}", m.longest_hold_max_s),
            m.posture_variety_min_m
                .map_or_else(|| "–".to_string(), |v| format!("{v:.3}")),
            opt(r.song_distance_min_m),
        ];
        out.push_str(&format!("| {} |\n", cells.join(" | ")));
    }
    out
}

/// One section's tables; `notes` follow the titles of TSMT's table and the musicality table.
fn section(rows: &[EvalRow], reference: Option<&ReferenceStats>, notes: [&str; 2]) -> String {
    let mut out = String::from("### Scores\n\n");
    out += &scores_table(rows);
    out += "\n### Physical plausibility\n\n";
    out += &physical_table(rows, reference);
    out += &format!("\n### TSMT's measures{}\n\n", notes[0]);
    out += &paper_table(rows);
    out += &format!("\n### Musicality{}\n\n", notes[1]);
    out += &musicality_table(rows);
    out
}

/// The Markdown `choreo eval` prints: per section, a scores table and a physical-plausibility
/// table (the verdict: each criterion as the row's worst dance has it; the values beside it are
/// every frame of the row pooled).
pub fn markdown(result: &EvalResult) -> String {
    let reference = ReferenceStats::builtin().ok();
    let mut out = format!(
        "## {} split ({} songs, each cut to its dance)\n\n",
        result.split,
        result.rows.first().map_or(0, |r| r.scores.dances)
    );
    out += &section(
        &result.rows,
        reference.as_ref(),
        [
            " (diversity on z-normalised kinetic 5-s windows, beat P/R/F ±0.1 s)",
            " (musicality: tempo lock, arms, knees, song sensitivity)",
        ],
    );
    if !result.extra_rows.is_empty() {
        out += &format!(
            "\n## Extra songs, whole ({})\n\n",
            result.extra_songs.join(", ")
        );
        out += &section(&result.extra_rows, reference.as_ref(), ["", ""]);
    }
    if !result.tempo.is_empty() {
        out += "\n## Tempo: the extra songs slower and faster (sox, pitch kept)\n\n";
        out += &super::tempo::markdown(&result.tempo);
    }
    if !result.tempo_change.songs.is_empty() {
        out +=
            "\n## Tempo change: the extra songs slowed, then sped up 1.5625× (sox, pitch kept)\n\n";
        out += &super::tempo_change::markdown(&result.tempo_change);
    }
    if !result.style_control.is_empty() {
        out += "\n## Style control (every song above, test and extra, in each style)\n\n";
        out += &super::style_control::markdown(&result.style_control, result.real_styles.as_ref());
    }
    out
}

/// The table each model card shows, made from its committed `eval.json` (tests/docs.rs checks
/// that every card holds it as written here): each test-split row's authenticity and coherence
/// (TSMT's joint-angle measures), skate ratio, div_k, and FID_k over 5-s windows and whole
/// dances. `choreo eval --card-table models/<id>/eval.json` prints it.
pub fn card_table(result: &EvalResult) -> String {
    let mut t = String::from(
        "| row | dances | authenticity | coherence | skate | div_k | FID_k window / dance |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for r in &result.rows {
        let s = &r.scores;
        t += &format!(
            "| {} | {} | {} | {} | {} | {} | {:.1} / {:.1} |\n",
            r.name,
            s.dances,
            f(s.mean.plausibility.authenticity),
            f(s.mean.plausibility.coherence),
            f(s.mean.foot_skating.skate_ratio),
            f2(s.div_k),
            s.fid_k_window,
            s.fid_k_dance
        );
    }
    t
}
