//! The path through the motion graph: one unit per beat slot of the song, found by beam search.
//!
//! ChoreoMaster solves the path by dynamic programming with the unit as the state. A repetition
//! cost ("no unit again within a few bars") and a cap on how long the path follows one training
//! dance in order both depend on the path's history, which a unit-only state forgets; a beam of
//! paths keeps it. Each step expands every kept path along its graph edges (and the natural
//! successor), adds the costs of [`super::Config`], and keeps the cheapest distinct ends.
use ndarray::{Array2, ArrayView1};

use super::library::Library;
use super::rhythm::Match;
use super::Config;
use crate::motion::repr::POSE_DIM;
use crate::motion::NUM_JOINTS;

/// One interval of the song a unit is warped onto: from one beat to the next (or a half or two
/// beats of it, [`crate::models::beat_graph::served`]), seconds on the dance's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slot {
    pub t0: f64,
    pub t1: f64,
    /// Beats since the bar's downbeat, when slots are beats and the bar is known.
    pub phase: Option<usize>,
}

/// A key pose the path should pass: in slot `slot`, at `fraction` of it, root-relative joints
/// in the facing frame (`POSE_DIM` values).
#[derive(Clone, Debug)]
pub struct SlotKey {
    pub slot: usize,
    pub fraction: f64,
    pub local: Vec<f32>,
}

/// Everything the search weighs besides the library.
pub struct Problem<'a> {
    pub slots: &'a [Slot],
    /// Beats a bar in the song.
    pub meter: usize,
    /// The motion descriptors the music predicts, one row per slot.
    pub predicted: &'a Array2<f32>,
    pub matcher: &'a Match,
    /// Per slot, per unit: `None` when the unit may not be used there (another style), else its
    /// style cost. A slot's row is its section's: a song whose tempo changes may change style.
    pub allowed: &'a [&'a [Option<f64>]],
    pub keys: &'a [SlotKey],
    /// The pose the dance starts from (a seed motion's last frame), and where in the first slot.
    pub start: Option<(&'a [f32], f64)>,
    pub seed: u64,
    pub fps: f64,
}

/// The path and what it is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct Path {
    /// The unit danced in each slot.
    pub units: Vec<usize>,
    /// Most slots in a row taken in order from one training dance.
    pub longest_run_slots: usize,
    /// The path's total cost.
    pub cost: f64,
}

#[derive(Clone, Copy)]
struct Node {
    unit: usize,
    /// Slots in a row this path has followed its current dance in order (0 after an edge).
    run: usize,
    cost: f64,
    parent: usize,
}

/// Finds the path of least cost (the job's seed perturbing every cost), or `None` when no unit
/// may be used at all.
pub fn search(lib: &Library, config: &Config, p: &Problem<'_>) -> Option<Path> {
    let n_units = lib.units.len();
    if p.slots.is_empty() || n_units == 0 {
        return None;
    }
    let mut layers: Vec<Vec<Node>> = Vec::with_capacity(p.slots.len());
    let first_layer = |strict: bool| -> Vec<Node> {
        (0..n_units)
            .filter_map(|v| {
                let c = unit_cost(lib, config, p, 0, v, strict)?;
                let start = match p.start {
                    Some((pose, fraction)) => {
                        let u = &lib.units[v];
                        let row = lib.sample(u.dance, u.start + fraction * u.frames());
                        config.transition_weight * pose_rms(pose, row.view())
                    }
                    None => 0.0,
                };
                Some(Node {
                    unit: v,
                    run: 0,
                    cost: c + start - gumbel(config, p.seed, 0, v),
                    parent: 0,
                })
            })
            .collect()
    };
    let mut first = first_layer(true);
    if first.is_empty() {
        // No unit's beat is within the stretch range of this slot: take the least stretched.
        first = first_layer(false);
    }
    layers.push(keep_best(first, config.beam_width));
    if layers[0].is_empty() {
        return None;
    }
    for i in 1..p.slots.len() {
        let prev = &layers[i - 1];
        let mut next = expand(lib, config, p, &layers, i, true);
        if next.is_empty() {
            next = expand(lib, config, p, &layers, i, false);
        }
        if next.is_empty() {
            // Every edge was refused (no unit may be used after these): restart from any unit,
            // at a transition's price, rather than stop the dance.
            let best = prev.iter().map(|n| n.cost).fold(f64::INFINITY, f64::min);
            let parent = prev.iter().position(|n| n.cost == best).unwrap_or(0);
            next = (0..n_units)
                .filter(|&v| p.allowed[i][v].is_some())
                .map(|v| Node {
                    unit: v,
                    run: 0,
                    cost: best + config.transition_weight * 0.5 - gumbel(config, p.seed, i, v),
                    parent,
                })
                .collect();
        }
        layers.push(keep_best(next, config.beam_width));
    }
    let last = layers.last()?;

    let (mut b, best) = last
        .iter()
        .enumerate()
        .min_by(|a, c| a.1.cost.total_cmp(&c.1.cost))?;
    let cost = best.cost;
    let mut units = vec![0; p.slots.len()];
    let mut longest = 0;
    for i in (0..p.slots.len()).rev() {
        let node = layers[i][b];
        units[i] = node.unit;
        longest = longest.max(node.run + 1);
        b = node.parent;
    }
    Some(Path {
        units,
        longest_run_slots: longest,
        cost,
    })
}

/// Every way of extending the paths of `layers[i - 1]` by one unit, `strict` refusing stretches
/// outside [`Config::stretch_range`].
fn expand(
    lib: &Library,
    config: &Config,
    p: &Problem<'_>,
    layers: &[Vec<Node>],
    i: usize,
    strict: bool,
) -> Vec<Node> {
    let prev = &layers[i - 1];
    let mut next: Vec<Node> = Vec::with_capacity(prev.len() * (config.graph_degree + 1));
    for (b, node) in prev.iter().enumerate() {
        let history = history(layers, i - 1, b, config.repetition_beats);
        let unit = &lib.units[node.unit];
        let natural = unit
            .next
            .filter(|_| node.run + 1 < config.max_run_beats)
            .map(|v| (v, 0.0f32, true));
        let edges = lib.graph[node.unit].iter().map(|&(v, c)| (v, c, false));
        for (v, transition, in_order) in natural.into_iter().chain(edges) {
            let Some(c) = unit_cost(lib, config, p, i, v, strict) else {
                continue;
            };
            let run = if in_order { node.run + 1 } else { 0 };
            // Back in the run that leads here is a repeat; the run itself is not.
            let older = if in_order { node.run + 1 } else { 0 };
            let repeated = history.iter().skip(older).any(|&h| {
                let w = &lib.units[h];
                h == v || (w.dance == lib.units[v].dance && w_near(h, v))
            });
            let cost = node.cost
                + c
                + config.transition_weight * f64::from(transition)
                + if repeated {
                    config.repetition_weight
                } else {
                    0.0
                }
                - gumbel(config, p.seed, i, v);
            next.push(Node {
                unit: v,
                run,
                cost,
                parent: b,
            });
        }
    }
    next
}

/// Two units of one dance within two beats of each other.
fn w_near(a: usize, b: usize) -> bool {
    a.abs_diff(b) <= 2
}

/// The last `depth` units of the path ending at `layers[i][b]`, most recent first.
fn history(layers: &[Vec<Node>], mut i: usize, mut b: usize, depth: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(depth);
    loop {
        let node = layers[i][b];
        out.push(node.unit);
        if out.len() >= depth || i == 0 {
            return out;
        }
        b = node.parent;
        i -= 1;
    }
}

/// The cheapest `width` nodes, one per unit.
fn keep_best(mut nodes: Vec<Node>, width: usize) -> Vec<Node> {
    nodes.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    let mut seen = std::collections::HashSet::with_capacity(width);
    nodes.retain(|n| seen.insert(n.unit));
    nodes.truncate(width.max(1));
    nodes
}

/// What unit `v` costs in slot `i` on its own (music, bar position, stretch, style, keys), or
/// `None` when it may not be used there (another style; a stretch out of range when `strict`).
fn unit_cost(
    lib: &Library,
    config: &Config,
    p: &Problem<'_>,
    i: usize,
    v: usize,
    strict: bool,
) -> Option<f64> {
    let style = p.allowed[i][v]?;
    let unit = &lib.units[v];
    let slot = p.slots[i];
    let stretch = (slot.t1 - slot.t0) * p.fps / unit.frames();
    if strict && !(config.stretch_range.0..=config.stretch_range.1).contains(&stretch) {
        return None;
    }
    let mut cost = style + config.stretch_weight * stretch.ln().powi(2);
    cost += config.rhythm_weight * p.matcher.cost(p.predicted.row(i), lib.motion.row(v));
    if let Some(phase) = slot.phase {
        if unit.meter == p.meter && unit.phase != phase {
            cost += config.phase_weight;
        }
    }
    for key in p.keys.iter().filter(|k| k.slot == i) {
        let row = lib.sample(unit.dance, unit.start + key.fraction * unit.frames());
        cost += config.key_weight * pose_rms(&key.local, row.view());
    }
    Some(cost)
}

/// RMS over joints of the distance between a pose and a feature row's pose (m).
fn pose_rms(pose: &[f32], row: ArrayView1<'_, f32>) -> f64 {
    let sq: f32 = pose
        .iter()
        .take(POSE_DIM)
        .zip(row.iter())
        .map(|(a, b)| (a - b) * (a - b))
        .sum();
    (f64::from(sq) / NUM_JOINTS as f64).sqrt()
}

/// A Gumbel draw for (seed, slot, unit), scaled: subtracted from a cost, the search's choice
/// becomes a sample that favours cheap paths (the Gumbel-max trick).
fn gumbel(config: &Config, seed: u64, slot: usize, unit: usize) -> f64 {
    if config.gumbel_scale <= 0.0 {
        return 0.0;
    }
    -config.gumbel_scale * (-uniform(seed, slot, unit).ln()).ln()
}

/// A uniform draw in (0, 1) for (seed, a, b): the same triple, the same draw.
pub fn uniform(seed: u64, a: usize, b: usize) -> f64 {
    let mut z = seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add((a as u64) << 32 ^ b as u64);
    // splitmix64's finaliser: a well-mixed 64-bit value from any input.
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
}
