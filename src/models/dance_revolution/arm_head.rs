//! The arm head (not in the paper): a second read-out of the elbows and wrists, never fed
//! back to the LSTM, and the figure it may be told to dance ([`super::figures`]).
use tch::nn;
use tch::{Kind, Tensor};

use super::figures::{self, FIGURE_DIM};
use super::Config;
use crate::motion::skeleton::{FOREARMS, HAND_DIRS, PARENTS, WRISTS};

/// The pose vector's columns of the elbows and wrists (`metrics::musicality::ARM_JOINTS`, x y z
/// each): what the [`ArmHead`] and `choreo train … --arm-readout-only` move.
pub fn arm_columns() -> Vec<i64> {
    crate::metrics::musicality::ARM_JOINTS
        .iter()
        .flat_map(|&j| (3 * j as i64)..(3 * j as i64 + 3))
        .collect()
}

/// Not in the paper: a second read-out of the elbows and wrists from `[h_i; z_i]`, added
/// to the paper's read-out in what the decoder emits but never fed back, so the LSTM steps exactly
/// as it does without it: the legs and their timing (what the tempo test checks) stay the trained
/// network's own. Its last layer starts at zero, so a head added to trained weights changes
/// nothing until it trains. Training only the paper's read-out rows of the arms could not lift the
/// ballroom hold (0.32–0.35 m/s on the test waltzes, where the slowest real dance moves 0.43), and
/// its outputs, fed back, moved the other dances' timing.
///
/// With `Config::arm_figures` the head also reads the figure the arms are to hold at each frame
/// (`[h_i; z_i; f_i]`, [`super::figures`]): the decoder alone holds one arm shape for a whole song
/// (its card), and a figure that changes over the song moves it. The
/// figure's input weights are added as new columns of the hidden layer, so a head trained without
/// them loads (`train::load_widened`) and reads the figure as nothing until it trains.
#[derive(Debug)]
pub struct ArmHead {
    hidden: nn::Linear,
    out: nn::Linear,
    /// `[arm columns, pose_dim]`: places the head's columns in the pose vector (one-hot; with
    /// figures the forearm and hand markers follow, [`Self::new`]).
    place: Tensor,
    figures: bool,
}

impl ArmHead {
    pub(super) fn new(p: nn::Path, c: &Config) -> Self {
        let columns = arm_columns();
        assert!(
            columns.iter().all(|&k| k < c.pose_dim),
            "the arm head needs the full pose vector"
        );
        let n = columns.len() as i64;
        let place = Tensor::zeros([n, c.pose_dim], (Kind::Float, p.device()));
        for (i, &k) in columns.iter().enumerate() {
            let _ = place.get(i as i64).get(k).fill_(1.0);
        }
        if c.arm_figures {
            // A figure moves the arm by tens of centimetres, and the markers the head does not
            // place would stay behind and bend the arm (the skeleton is fitted to every marker).
            // A marker on the forearm moves by the mean of the elbow's and the wrist's offsets:
            // the forearm marker, 0.4–0.67 of the way from elbow to wrist in the data, and the
            // left hand's direction point, 12 cm from the left elbow on the forearm. The right
            // hand's, 4.7 cm beyond the right wrist, moves with the wrist (`motion::skeleton`).
            for (side, (elbow, wrist)) in figures::forearms().into_iter().enumerate() {
                let wrist_joint = WRISTS[side];
                let (elbow, wrist) = (3 * elbow as i64, 3 * wrist as i64);
                for marker in [FOREARMS[side], HAND_DIRS[side]] {
                    let beyond_wrist = PARENTS[marker] == Some(wrist_joint);
                    let (from_elbow, from_wrist) =
                        if beyond_wrist { (0.0, 1.0) } else { (0.5, 0.5) };
                    let column = 3 * marker as i64;
                    for axis in 0..3 {
                        if from_elbow > 0.0 {
                            let _ = place.get(elbow + axis).get(column + axis).fill_(from_elbow);
                        }
                        let _ = place.get(wrist + axis).get(column + axis).fill_(from_wrist);
                    }
                }
            }
        }
        let zero = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bs_init: Some(nn::Init::Const(0.0)),
            bias: true,
        };
        let figure_in = if c.arm_figures { FIGURE_DIM } else { 0 };
        Self {
            hidden: nn::linear(
                &p / "hidden",
                c.hidden + c.d_z + figure_in,
                c.arm_head,
                Default::default(),
            ),
            out: nn::linear(&p / "out", c.arm_head, n, zero),
            place,
            figures: c.arm_figures,
        }
    }

    /// `[…, pose_dim]`: the head's offsets in the arm columns, zero elsewhere, for `hz` `[…,
    /// hidden + d_z]`. `figure` `[…, FIGURE_DIM]` is read by a head with figures; a head with figures given none reads
    /// the spine's own place (zeros), which no dance holds: serving always gives one.
    pub(super) fn forward(&self, hz: &Tensor, figure: Option<&Tensor>) -> Tensor {
        let input = if self.figures {
            let f = match figure {
                Some(f) => f.to_kind(hz.kind()),
                None => {
                    let mut size = hz.size();
                    if let Some(last) = size.last_mut() {
                        *last = FIGURE_DIM;
                    }
                    Tensor::zeros(size.as_slice(), (hz.kind(), hz.device()))
                }
            };
            Tensor::cat(&[hz.shallow_clone(), f], -1)
        } else {
            hz.shallow_clone()
        };
        input
            .apply(&self.hidden)
            .tanh()
            .apply(&self.out)
            .matmul(&self.place)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{figures, Config, DanceRevolution};
    use super::*;
    use tch::{nn, Device};

    /// The pose columns in which two dances `[1, n, pose]` differ in any frame.
    fn moved_columns(a: &Tensor, b: &Tensor) -> Vec<i64> {
        Vec::<bool>::try_from((a - b).abs().gt(0.0).any_dim(1, false).squeeze_dim(0))
            .unwrap()
            .iter()
            .enumerate()
            .filter(|(_, &m)| m)
            .map(|(i, _)| i as i64)
            .collect()
    }

    /// The arm head is never fed back: a trained head changes the emitted elbows and wrists and no
    /// other column of any frame (a head fed back would move the legs of every later frame). And
    /// weights saved without a head (`--init`) load into a network with one that dances exactly as
    /// before, the head's last layer being zero.
    #[test]
    fn arm_head_moves_the_arms_alone_and_starts_at_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plain.safetensors");
        tch::manual_seed(3);
        let plain_vs = nn::VarStore::new(Device::Cpu);
        let plain = DanceRevolution::new(&plain_vs.root(), Config::tiny(6, 73));
        plain_vs.save(&path).unwrap();
        let headed_vs = nn::VarStore::new(Device::Cpu);
        let headed = DanceRevolution::new(
            &headed_vs.root(),
            Config {
                arm_head: 8,
                ..Config::tiny(6, 73)
            },
        );
        crate::models::train::load_widened(&headed_vs, &path).unwrap();
        let x = Tensor::randn([1, 40, 6], (Kind::Float, Device::Cpu));
        let dance = |m: &DanceRevolution| {
            let z = m.encoder.forward(&x, 0, false);
            m.decode(&z, 5, None, None, 4, 0, |_| true).unwrap()
        };
        let before = dance(&plain);
        let d = (dance(&headed) - &before).abs().max().double_value(&[]);
        assert_eq!(d, 0.0, "an untrained head moved the dance by {d}");
        tch::no_grad(|| {
            for (name, mut v) in headed_vs.variables() {
                if name.starts_with("decoder.arm_head.") {
                    v.copy_(&(v.randn_like() * 0.5));
                }
            }
        });
        let after = dance(&headed);
        assert_eq!(moved_columns(&after, &before), arm_columns());
    }

    /// A head without figures loads into one with them and dances as before (to rounding), told
    /// any figure;
    /// once trained, the figure it is told moves the arms' columns and nothing else.
    #[test]
    fn a_head_with_figures_reads_them_only_once_trained_and_moves_the_arms_alone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("head.safetensors");
        tch::manual_seed(3);
        let c = Config {
            arm_head: 8,
            ..Config::tiny(6, 73)
        };
        let head_vs = nn::VarStore::new(Device::Cpu);
        let head = DanceRevolution::new(&head_vs.root(), c.clone());
        tch::no_grad(|| {
            for (name, mut v) in head_vs.variables() {
                if name.starts_with("decoder.arm_head.out") {
                    v.copy_(&(v.randn_like() * 0.5));
                }
            }
        });
        head_vs.save(&path).unwrap();
        let told_vs = nn::VarStore::new(Device::Cpu);
        let told = DanceRevolution::new(
            &told_vs.root(),
            Config {
                arm_figures: true,
                ..c
            },
        );
        crate::models::train::load_widened(&told_vs, &path).unwrap();
        let x = Tensor::randn([1, 40, 6], (Kind::Float, Device::Cpu));
        let plan =
            |v: f32| ndarray::Array2::<f32>::from_elem((40, figures::FIGURE_DIM as usize), v);
        let dance = |m: &DanceRevolution, figure: Option<f32>| {
            let z = m.encoder.forward(&x, 0, false);
            let d = m.begin(&z, 5, None, None, 4);
            let mut d = match figure {
                Some(v) => d.with_figures(&plan(v)),
                None => d,
            };
            d.run_to(&z, 40, 0, |_| true, None).unwrap();
            d.output()
        };
        // To rounding: the widened layer sums its zero columns too.
        let before = dance(&told, Some(-0.7));
        let d = (dance(&told, Some(0.7)) - &before)
            .abs()
            .max()
            .double_value(&[]);
        assert!(d < 1e-5, "an untrained figure input moved the dance by {d}");
        // ...and the head places the earlier head's offsets where it did (the forearm and hand
        // markers now follow them).
        let followers: Vec<i64> = [5i64, 14, 21, 22]
            .iter()
            .flat_map(|&j| 3 * j..3 * j + 3)
            .collect();
        let same = (dance(&head, None) - &before).abs().squeeze_dim(0);
        for &k in &followers {
            let _ = same.narrow(1, k, 1).fill_(0.0);
        }
        let d = same.max().double_value(&[]);
        assert!(d < 1e-5, "the loaded head moved the other columns by {d}");
        tch::no_grad(|| {
            for (name, mut v) in told_vs.variables() {
                if name.starts_with("decoder.arm_head.hidden.weight") {
                    v.copy_(&(v.randn_like() * 0.5));
                }
            }
        });
        let (a, b) = (dance(&told, Some(0.7)), dance(&told, Some(-0.7)));
        let moved = moved_columns(&a, &b);
        // The left hand's point lies on the forearm and moves as the forearm marker does; the
        // right hand's lies beyond the wrist and moves with it.
        let change = |joint: i64| (&a - &b).narrow(2, 3 * joint, 3);
        let apart = |j: i64, k: i64| (change(j) - change(k)).abs().max().double_value(&[]);
        assert!(
            apart(21, 14) < 1e-5 && apart(21, 15) > 1e-3,
            "left hand point"
        );
        assert!(
            apart(22, 6) < 1e-5 && apart(22, 5) > 1e-3,
            "right hand point"
        );
        // The elbows and wrists, and the forearm and hand markers that follow them.
        let mut arms: Vec<i64> = [4i64, 5, 6, 13, 14, 15, 21, 22]
            .iter()
            .flat_map(|&j| 3 * j..3 * j + 3)
            .collect();
        arms.sort();
        assert_eq!(moved, arms);
    }
}
