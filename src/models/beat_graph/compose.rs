//! The path made into motion: each unit time-warped onto its slot, the joins inertialized.
//!
//! Warp (ChoreoGraph's): output frame `f` in slot `[t0, t1)` shows the unit at source frame
//! `start + (f/fps − t0)·fps·k`, `k` = unit frames ÷ slot frames, so the unit's first frame lands
//! on the slot's beat and its last on the next; root travel and turn, stored per frame, are
//! scaled by `k`. Before the first slot and after the last, the first unit's dance runs on
//! backwards and the last one's forwards, at their rates.
//!
//! Joins (inertialization, Bollo 2016, in the critically damped form of Holden's "dead
//! blending"): where a unit follows another that is not its natural successor, the gap between
//! where the previous unit's dance would have gone and where the new unit starts (pose and
//! velocity, every feature column) becomes an offset that decays to zero with half-life
//! [`super::Config::blend_halflife_s`]: the motion is continuous with a continuous velocity,
//! and a few tenths of a second later it is the new unit's own.
use ndarray::{Array1, Array2, ArrayView2};

use super::library::Library;
use super::search::Slot;
use crate::motion::repr::{FEATURE_DIM, ROOT_VX, ROOT_VZ, YAW_VEL};

/// Feature rows `[n, FEATURE_DIM]` of the path `units` (one per slot) at `fps`. Rows
/// `..seed.nrows()` are the seed's own (a request's seed motion); the composed motion starts
/// after them, its join with the seed's last frames inertialized like any other.
pub fn compose(
    lib: &Library,
    units: &[usize],
    slots: &[Slot],
    n: usize,
    fps: f64,
    halflife_s: f64,
    seed: ArrayView2<'_, f32>,
) -> Array2<f32> {
    let mut out = Array2::<f32>::zeros((n, FEATURE_DIM));
    let from = seed.nrows().min(n);
    for f in 0..from {
        out.row_mut(f).assign(&seed.row(f));
    }
    if units.is_empty() || slots.is_empty() || from >= n {
        return out;
    }
    let dt = 1.0 / fps;
    let y = 2.0 * std::f64::consts::LN_2 / halflife_s.max(1e-3);
    let mut x_off = Array1::<f64>::zeros(FEATURE_DIM);
    let mut v_off = Array1::<f64>::zeros(FEATURE_DIM);
    let mut slot = 0usize;
    let mut previous: Option<usize> = None;
    for f in from..n {
        let t = f as f64 * dt;
        while slot + 1 < slots.len() && t >= slots[slot + 1].t0 {
            slot += 1;
        }
        let here = |s: usize, t: f64| row_at(lib, units[s], &slots[s], t, fps);
        let row = here(slot, t);
        let joined_from = match previous {
            None if from > 0 => Some(Continuation::Seed),
            Some(p) if p != slot && lib.units[units[p]].next != Some(units[slot]) => {
                Some(Continuation::Slot(p))
            }
            _ => None,
        };
        if let Some(cont) = joined_from {
            let (x0, x1) = match cont {
                Continuation::Seed => {
                    let a = out.row(from - 1).to_owned();
                    let b = if from >= 2 {
                        out.row(from - 2).to_owned()
                    } else {
                        a.clone()
                    };
                    (&a + &(&a - &b), &a + &(&a - &b) * 2.0)
                }
                Continuation::Slot(p) => (here(p, t), here(p, t + dt)),
            };
            let next = here(slot, t + dt);
            for c in 0..FEATURE_DIM {
                x_off[c] += f64::from(x0[c] - row[c]);
                v_off[c] += f64::from((x1[c] - x0[c]) - (next[c] - row[c])) / dt;
            }
        }
        previous = Some(slot);
        for c in 0..FEATURE_DIM {
            out[[f, c]] = row[c] + x_off[c] as f32;
        }
        // One step of the critically damped spring that takes the offset to zero.
        let e = (-y * dt).exp();
        for c in 0..FEATURE_DIM {
            let j1 = v_off[c] + x_off[c] * y;
            x_off[c] = e * (x_off[c] + j1 * dt);
            v_off[c] = e * (v_off[c] - j1 * y * dt);
        }
    }
    out
}

enum Continuation {
    Seed,
    Slot(usize),
}

/// The feature row unit `u` shows at time `t` when warped onto `slot`.
fn row_at(lib: &Library, u: usize, slot: &Slot, t: f64, fps: f64) -> Array1<f32> {
    let unit = &lib.units[u];
    let k = unit.frames() / ((slot.t1 - slot.t0) * fps).max(1e-6);
    let mut row = lib.sample(unit.dance, unit.start + (t - slot.t0) * fps * k);
    for c in [ROOT_VX, ROOT_VZ, YAW_VEL] {
        row[c] *= k as f32;
    }
    row
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::beat_graph::library::Unit;
    use crate::models::DanceStyle;

    /// Two dances of constant poses, 0 and 1: a path that jumps from one to the other arrives
    /// smoothly, and a natural successor is played through untouched.
    #[test]
    fn a_join_is_continuous_and_settles() {
        let mut frames = Array2::<f32>::zeros((100, FEATURE_DIM));
        frames.slice_mut(ndarray::s![50.., ..]).fill(1.0);
        let unit = |dance, start: f64, next| Unit {
            dance,
            start,
            end: start + 10.0,
            phase: 0,
            meter: 4,
            style: DanceStyle::Waltz,
            next,
        };
        let lib = Library {
            frames,
            dance_first: vec![0, 50, 100],
            units: vec![
                unit(0, 10.0, Some(1)),
                unit(0, 20.0, None),
                unit(1, 10.0, None),
            ],
            motion: Array2::zeros((3, 4)),
            graph: vec![vec![], vec![], vec![]],
        };
        let slots: Vec<Slot> = (0..3)
            .map(|i| Slot {
                t0: i as f64 * 0.4,
                t1: (i + 1) as f64 * 0.4,
                phase: None,
            })
            .collect();
        let x = compose(
            &lib,
            &[0, 1, 2],
            &slots,
            60,
            25.0,
            0.12,
            Array2::zeros((0, FEATURE_DIM)).view(),
        );
        let col: Vec<f32> = x.column(0).to_vec();
        assert!(col[..20].iter().all(|&v| v == 0.0), "{col:?}");
        let steps = col
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0f32, f32::max);
        assert!(steps < 0.25, "largest step {steps}: {col:?}");
        assert!((col[59] - 1.0).abs() < 0.02, "{col:?}");
    }
}
