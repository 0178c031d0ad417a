//! The dance units and the motion graph over them, as `weights.safetensors` stores them.
//!
//! A unit is one beat of a real training dance: the frames between two consecutive beats of its
//! song (our own analysis of the training song, moved onto the dance's frames), in the motion
//! features of [`crate::motion::repr`] (root-relative joints in the facing frame, root travel and
//! turn as velocities), so units from any dance, anywhere on the floor, join end to start.
use std::path::Path;

use ndarray::{s, Array1, Array2};
use tch::{Kind, Tensor};

use super::rhythm::MOTION_DIM;
use crate::models::{DanceStyle, ModelError};
use crate::motion::repr::{FEATURE_DIM, POSE_DIM, ROOT_Y};
use crate::motion::NUM_JOINTS;

/// A style with fewer units than this also takes units of the styles in its meter, at
/// [`super::Config::style_weight`] (the train split's one tango gives ~250; a path over so few
/// would come back to the same steps every few bars).
pub const MIN_STYLE_UNITS: usize = 600;
/// Steps a beat of a dance whose step rate cannot be measured: the ballroom's two steps a bar
/// of four.
pub const DEFAULT_PACE: f64 = 0.5;
/// How far (seconds) a boundary's velocity weighs in [`Library::transition`]: a joint moving
/// 1 m/s apart counts as 0.1 m of pose apart.
const VELOCITY_S: f32 = 0.1;
/// Width of a boundary vector: pose, root height, pose velocity.
const BOUNDARY_DIM: usize = 2 * POSE_DIM + 1;

/// One beat of a training dance.
#[derive(Clone, Debug, PartialEq)]
pub struct Unit {
    /// Index into [`Library::dances`].
    pub dance: usize,
    /// The beat's frame in its dance (fractional: beats fall between frames).
    pub start: f64,
    /// The next beat's frame.
    pub end: f64,
    /// Beats since the bar's downbeat (0 on the downbeat).
    pub phase: usize,
    /// Beats a bar in its song.
    pub meter: usize,
    pub style: DanceStyle,
    /// The unit that follows it in its dance (the graph's natural edge), if any.
    pub next: Option<usize>,
}

impl Unit {
    /// Frames the unit lasts at its dancer's tempo.
    pub fn frames(&self) -> f64 {
        self.end - self.start
    }
}

/// The units, their frames, their motion descriptors and the graph.
#[derive(Clone, Debug)]
pub struct Library {
    /// Every training dance's feature rows, one after another, `[N, FEATURE_DIM]`.
    pub frames: Array2<f32>,
    /// Dance `d` is rows `dance_first[d]..dance_first[d + 1]`.
    pub dance_first: Vec<usize>,
    pub units: Vec<Unit>,
    /// [`super::rhythm::motion_descriptors`] per unit, `[U, MOTION_DIM]`.
    pub motion: Array2<f32>,
    /// Per unit, the units whose start best meets its end, with that transition's cost (m),
    /// cheapest first; the natural successor is not among them.
    pub graph: Vec<Vec<(usize, f32)>>,
}

impl Library {
    /// Frames of dance `d`.
    pub fn dance(&self, d: usize) -> ndarray::ArrayView2<'_, f32> {
        self.frames
            .slice(s![self.dance_first[d]..self.dance_first[d + 1], ..])
    }

    /// The feature row of dance `d` at fractional frame `at` (linear between frames, held at the
    /// dance's ends).
    pub fn sample(&self, d: usize, at: f64) -> Array1<f32> {
        let x = self.dance(d);
        let last = x.nrows() - 1;
        let at = at.clamp(0.0, last as f64);
        let i = (at.floor() as usize).min(last);
        let j = (i + 1).min(last);
        let w = (at - i as f64) as f32;
        &x.row(i) * (1.0 - w) + &x.row(j) * w
    }

    /// Steps each training dancer takes a beat of their song: the ankles' step rate over the
    /// beat rate of the dance's units ([`crate::metrics::musicality::tempo_lock`]); ~1/2 for the
    /// train split's rumbas and cha-chas, ~1/3 for its waltzes, 0.3–0.4 for a few dancers whose
    /// song was analysed at another beat level. A path that keeps one pace steps in proportion to
    /// the song's beats, so its steps follow the music's tempo wherever it changes.
    /// [`DEFAULT_PACE`] where a dance has no measurable step rate.
    pub fn dance_paces(&self, fps: f64) -> Vec<f64> {
        (0..self.dance_first.len().saturating_sub(1))
            .map(|d| {
                let beats: Vec<f64> = self
                    .units
                    .iter()
                    .filter(|u| u.dance == d)
                    .map(|u| u.start / fps)
                    .collect();
                crate::motion::repr::from_features(self.dance(d), Default::default(), fps)
                    .ok()
                    .and_then(|(m, _)| {
                        crate::metrics::musicality::tempo_lock(m.positions.view(), fps, &beats)
                    })
                    .map_or(DEFAULT_PACE, |l| l.ratio)
            })
            .collect()
    }

    /// Pose, root height and pose velocity (per second × [`VELOCITY_S`]) at a unit's start or end.
    fn boundary(&self, u: usize, end: bool, fps: f64) -> Vec<f32> {
        let unit = &self.units[u];
        let at = if end { unit.end } else { unit.start };
        let here = self.sample(unit.dance, at);
        let before = self.sample(unit.dance, at - 0.5);
        let after = self.sample(unit.dance, at + 0.5);
        let mut v = Vec::with_capacity(BOUNDARY_DIM);
        v.extend(here.iter().take(POSE_DIM));
        v.push(here[ROOT_Y]);
        let scale = fps as f32 * VELOCITY_S;
        v.extend((0..POSE_DIM).map(|c| (after[c] - before[c]) * scale));
        v
    }

    /// The cost of going from unit `u`'s end to unit `v`'s start: the RMS over joints of the
    /// distance between the two boundary vectors (m).
    pub fn transition(&self, u: usize, v: usize, fps: f64) -> f64 {
        let a = self.boundary(u, true, fps);
        let b = self.boundary(v, false, fps);
        let sq: f32 = a.iter().zip(&b).map(|(x, y)| (x - y) * (x - y)).sum();
        (f64::from(sq) / NUM_JOINTS as f64).sqrt()
    }

    /// Links each unit to the `degree` units whose start best meets its end: among its own
    /// style's units when the style has [`MIN_STYLE_UNITS`], else among its meter's. Left out:
    /// its natural successor (always an edge) and the units within two beats of it in its own
    /// dance (a step repeated or skipped, not a transition).
    pub fn build_graph(&mut self, degree: usize, fps: f64) -> Result<(), ModelError> {
        let n = self.units.len();
        let stack = |end: bool| -> Result<Tensor, ModelError> {
            let rows: Vec<f32> = (0..n).flat_map(|u| self.boundary(u, end, fps)).collect();
            Ok(Tensor::from_slice(&rows).view([n as i64, BOUNDARY_DIM as i64]))
        };
        let ends = stack(true)?;
        let starts = stack(false)?;
        // ‖a − b‖² = ‖a‖² + ‖b‖² − 2 a·b, all pairs at once.
        let sq = ends
            .pow_tensor_scalar(2)
            .sum_dim_intlist(1, true, Kind::Float)
            + starts
                .pow_tensor_scalar(2)
                .sum_dim_intlist(1, false, Kind::Float)
                .unsqueeze(0)
            - ends.matmul(&starts.transpose(0, 1)) * 2.0;
        let d2: Vec<f32> = Vec::<f32>::try_from(sq.clamp_min(0.0).contiguous().view([-1]))?;
        let counts = style_counts(&self.units);
        let mut graph = Vec::with_capacity(n);
        for u in 0..n {
            let unit = &self.units[u];
            let own_style = counts[unit.style.index()] >= MIN_STYLE_UNITS;
            let mut cands: Vec<(usize, f32)> = (0..n)
                .filter(|&v| {
                    let w = &self.units[v];
                    let near_in_dance =
                        w.dance == unit.dance && unit.next.is_some_and(|nx| nx.abs_diff(v) <= 2);
                    let kin = if own_style {
                        w.style == unit.style
                    } else {
                        w.meter == unit.meter
                    };
                    v != u && kin && !near_in_dance && Some(v) != unit.next
                })
                .map(|v| (v, (d2[u * n + v] / NUM_JOINTS as f32).sqrt()))
                .collect();
            let k = degree.min(cands.len());
            if k > 0 {
                cands.select_nth_unstable_by(k - 1, |a, b| a.1.total_cmp(&b.1));
                cands.truncate(k);
                cands.sort_by(|a, b| a.1.total_cmp(&b.1));
            }
            graph.push(cands);
        }
        self.graph = graph;
        Ok(())
    }

    /// Writes the library as safetensors.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        let u = self.units.len() as i64;
        let f32s = |v: &[f32], shape: &[i64]| Tensor::from_slice(v).view(shape);
        let i64s = |v: Vec<i64>| Tensor::from_slice(&v);
        let f64s = |v: Vec<f64>| Tensor::from_slice(&v);
        let degree = self.graph.iter().map(Vec::len).max().unwrap_or(0);
        let mut edges = vec![-1i64; self.units.len() * degree];
        let mut costs = vec![f32::INFINITY; self.units.len() * degree];
        for (i, row) in self.graph.iter().enumerate() {
            for (k, &(v, c)) in row.iter().enumerate() {
                edges[i * degree + k] = v as i64;
                costs[i * degree + k] = c;
            }
        }
        let frames: Vec<f32> = self.frames.iter().copied().collect();
        let motion: Vec<f32> = self.motion.iter().copied().collect();
        let units = &self.units;
        let named = [
            // Half precision: half a millimetre at a metre, and half the file.
            (
                "frames",
                f32s(&frames, &[self.frames.nrows() as i64, FEATURE_DIM as i64])
                    .to_kind(Kind::Half),
            ),
            (
                "dance_first",
                i64s(self.dance_first.iter().map(|&x| x as i64).collect()),
            ),
            (
                "unit_dance",
                i64s(units.iter().map(|x| x.dance as i64).collect()),
            ),
            ("unit_start", f64s(units.iter().map(|x| x.start).collect())),
            ("unit_end", f64s(units.iter().map(|x| x.end).collect())),
            (
                "unit_phase",
                i64s(units.iter().map(|x| x.phase as i64).collect()),
            ),
            (
                "unit_meter",
                i64s(units.iter().map(|x| x.meter as i64).collect()),
            ),
            (
                "unit_style",
                i64s(units.iter().map(|x| x.style.index() as i64).collect()),
            ),
            (
                "unit_next",
                i64s(
                    units
                        .iter()
                        .map(|x| x.next.map_or(-1, |n| n as i64))
                        .collect(),
                ),
            ),
            ("unit_motion", f32s(&motion, &[u, MOTION_DIM as i64])),
            ("graph", Tensor::from_slice(&edges).view([u, degree as i64])),
            (
                "graph_cost",
                Tensor::from_slice(&costs).view([u, degree as i64]),
            ),
        ];
        Tensor::write_safetensors(&named, path)?;
        Ok(())
    }

    /// Reads a library written by [`Self::save`], checking that its parts agree.
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let bad = |what: String| ModelError::BadModelFile(format!("{}: {what}", path.display()));
        let named = Tensor::read_safetensors(path)?;
        let get = |name: &str| -> Result<&Tensor, ModelError> {
            named
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, t)| t)
                .ok_or_else(|| bad(format!("no `{name}` tensor")))
        };
        let i64s = |name: &str| -> Result<Vec<i64>, ModelError> {
            Ok(Vec::<i64>::try_from(
                get(name)?.to_kind(Kind::Int64).contiguous().view([-1]),
            )?)
        };
        let f64s = |name: &str| -> Result<Vec<f64>, ModelError> {
            Ok(Vec::<f64>::try_from(
                get(name)?.to_kind(Kind::Double).contiguous().view([-1]),
            )?)
        };
        let f32s = |name: &str, width: usize| -> Result<Array2<f32>, ModelError> {
            let v = Vec::<f32>::try_from(get(name)?.to_kind(Kind::Float).contiguous().view([-1]))?;
            let rows = v.len() / width.max(1);
            Array2::from_shape_vec((rows, width), v).map_err(|e| bad(format!("{name}: {e}")))
        };
        let frames = f32s("frames", FEATURE_DIM)?;
        let dance_first: Vec<usize> = i64s("dance_first")?
            .into_iter()
            .map(|x| x as usize)
            .collect();
        let dances = dance_first.len().saturating_sub(1);
        if dances == 0
            || dance_first.windows(2).any(|w| w[0] >= w[1])
            || dance_first.last() != Some(&frames.nrows())
        {
            return Err(bad("dance offsets do not cover the frames".into()));
        }
        let (dance, start, end) = (i64s("unit_dance")?, f64s("unit_start")?, f64s("unit_end")?);
        let (phase, meter, style, next) = (
            i64s("unit_phase")?,
            i64s("unit_meter")?,
            i64s("unit_style")?,
            i64s("unit_next")?,
        );
        let n = dance.len();
        if [
            start.len(),
            end.len(),
            phase.len(),
            meter.len(),
            style.len(),
            next.len(),
        ]
        .iter()
        .any(|&l| l != n)
            || n == 0
        {
            return Err(bad("unit tables of different lengths".into()));
        }
        let mut units = Vec::with_capacity(n);
        for i in 0..n {
            let d = usize::try_from(dance[i]).ok().filter(|&d| d < dances);
            let st = usize::try_from(style[i])
                .ok()
                .and_then(|s| DanceStyle::ALL.get(s).copied());
            let nx = match next[i] {
                -1 => Some(None),
                x => usize::try_from(x).ok().filter(|&x| x < n).map(Some),
            };
            let (Some(d), Some(st), Some(nx)) = (d, st, nx) else {
                return Err(bad(format!("unit {i} points outside the library")));
            };
            let len = (dance_first[d + 1] - dance_first[d]) as f64;
            if !(start[i] >= 0.0 && end[i] > start[i] && end[i] <= len) {
                return Err(bad(format!("unit {i} lies outside its dance")));
            }
            units.push(Unit {
                dance: d,
                start: start[i],
                end: end[i],
                phase: phase[i].clamp(0, 15) as usize,
                meter: meter[i].clamp(1, 16) as usize,
                style: st,
                next: nx,
            });
        }
        let motion = f32s("unit_motion", MOTION_DIM)?;
        if motion.nrows() != n {
            return Err(bad("unit_motion rows ≠ units".into()));
        }
        let edges = i64s("graph")?;
        let costs = f64s("graph_cost")?;
        let degree = edges.len() / n;
        if edges.len() != n * degree || costs.len() != edges.len() {
            return Err(bad("graph is not units × degree".into()));
        }
        let graph = (0..n)
            .map(|u| {
                (0..degree)
                    .filter_map(|k| {
                        let v = edges[u * degree + k];
                        usize::try_from(v)
                            .ok()
                            .filter(|&v| v < n)
                            .map(|v| (v, costs[u * degree + k] as f32))
                    })
                    .collect()
            })
            .collect();
        Ok(Self {
            frames,
            dance_first,
            units,
            motion,
            graph,
        })
    }

    /// The median beat (frames) of each style's units, and how many it has, in
    /// [`DanceStyle::ALL`] order.
    pub fn style_beats(&self) -> Vec<(f64, usize)> {
        DanceStyle::ALL
            .iter()
            .map(|&st| {
                let mut f: Vec<f64> = self
                    .units
                    .iter()
                    .filter(|u| u.style == st)
                    .map(Unit::frames)
                    .collect();
                f.sort_by(f64::total_cmp);
                (f.get(f.len() / 2).copied().unwrap_or(0.0), f.len())
            })
            .collect()
    }
}

/// Units per style, in [`DanceStyle::ALL`] order.
pub fn style_counts(units: &[Unit]) -> [usize; 4] {
    let mut c = [0; 4];
    for u in units {
        c[u.style.index()] += 1;
    }
    c
}
