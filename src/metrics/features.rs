//! AIST++ motion features for FID: kinetic (Onuma et al. 2008, as coded in
//! `aistplusplus_api/aist_plusplus/features/kinetic.py`) and geometric (Müller et al. 2005's
//! relational features, as coded in `features/manual.py`), written from the formulas.
//!
//! Differences from the reference code, on purpose:
//! - **Acceleration.** Bailando's and several copies' `calc_average_acceleration` reads
//!   `v1 = p[i+j] - p[i+j-1] / frame_time`, which by operator precedence divides only the second
//!   position. We compute `v1 = (p[i+j] − p[i+j−1]) / Δt` as the formula says.
//! - **Frame time.** `manual.py` hard-codes `time_per_frame = 1/120` for 60-fps data (doubling every
//!   velocity); we use the motion's true `1 / fps`.
//! - Everything else follows `manual.py` exactly, including `f_move(j1, j2, j3, j4)` moving `j3`
//!   (relative to `j1`, along `j1 → j2`) and ignoring `j4`, so published numbers stay comparable.
use ndarray::ArrayView3;

/// The sliding half-window of the kinetic features (AIST++: 2 frames).
pub const KINETIC_SLIDING_WINDOW: isize = 2;
/// Kinetic features per joint: horizontal kinetic energy, vertical kinetic energy, energy expenditure.
pub const KINETIC_PER_JOINT: usize = 3;
/// Number of geometric (boolean relational) features.
pub const GEOMETRIC_DIM: usize = 32;

type V3 = [f64; 3];

fn at(p: &ArrayView3<'_, f32>, t: usize, j: usize) -> V3 {
    [
        p[[t, j, 0]] as f64,
        p[[t, j, 1]] as f64,
        p[[t, j, 2]] as f64,
    ]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Kinetic features of a window, `J × 3` values in joint order: for each joint, the mean over
/// frames `i = 1..T−1` of (a) the squared horizontal (x, z) speed, (b) the squared vertical (y)
/// speed, each averaged over the `±2`-frame sliding window, and (c) the norm of the windowed mean
/// acceleration. Units: m²/s², m²/s², m/s².
pub fn kinetic_features(positions: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let (t, j, _) = positions.dim();
    let dt = 1.0 / fps;
    let mut out = Vec::with_capacity(j * KINETIC_PER_JOINT);
    let denom = (t as f64 - 1.0).max(1.0);
    for k in 0..j {
        let (mut h, mut v, mut a) = (0.0, 0.0, 0.0);
        for i in 1..t as isize {
            // Windowed mean velocity: displacements p[f] − p[f−1] for f in i−2..=i+2 inside the clip.
            let mut vel = [0.0; 3];
            let mut n = 0usize;
            // Windowed mean acceleration: needs p[f−1], p[f], p[f+1].
            let mut acc = [0.0; 3];
            let mut m = 0usize;
            for off in -KINETIC_SLIDING_WINDOW..=KINETIC_SLIDING_WINDOW {
                let f = i + off;
                if f >= 1 && f < t as isize {
                    let d = sub(
                        at(&positions, f as usize, k),
                        at(&positions, f as usize - 1, k),
                    );
                    for c in 0..3 {
                        vel[c] += d[c];
                    }
                    n += 1;
                }
                if f >= 1 && f + 1 < t as isize {
                    let v2 = sub(
                        at(&positions, f as usize + 1, k),
                        at(&positions, f as usize, k),
                    );
                    let v1 = sub(
                        at(&positions, f as usize, k),
                        at(&positions, f as usize - 1, k),
                    );
                    for c in 0..3 {
                        // ((p[f+1] − p[f]) / Δt − (p[f] − p[f−1]) / Δt) / Δt
                        acc[c] += (v2[c] / dt - v1[c] / dt) / dt;
                    }
                    m += 1;
                }
            }
            if n > 0 {
                let s = 1.0 / (n as f64 * dt);
                h += (vel[0] * s).powi(2) + (vel[2] * s).powi(2);
                v += (vel[1] * s).powi(2);
            }
            if m > 0 {
                a += norm([acc[0] / m as f64, acc[1] / m as f64, acc[2] / m as f64]);
            }
        }
        out.extend([h / denom, v / denom, a / denom]);
    }
    out
}

/// The joints the geometric features name (SMPL names in `manual.py`), as indices into our
/// skeleton. See [`super::skeleton_map`] for how each is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct GeometricJoints {
    pub root: usize,
    pub belly: usize,
    pub chest: usize,
    pub neck: usize,
    pub lhip: usize,
    pub rhip: usize,
    pub lknee: usize,
    pub rknee: usize,
    pub lankle: usize,
    pub rankle: usize,
    pub ltoes: usize,
    pub rtoes: usize,
    pub lshoulder: usize,
    pub rshoulder: usize,
    pub lelbow: usize,
    pub relbow: usize,
    pub lwrist: usize,
    pub rwrist: usize,
}

/// Body-size scales the geometric thresholds use (metres).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct BodyScale {
    /// Humerus length `hl` (shoulder to elbow).
    pub humerus: f64,
    /// Shoulder width `sw`.
    pub shoulder_width: f64,
    /// Hip width `hw`.
    pub hip_width: f64,
}

/// One frame and its predecessor, with the named points of `manual.py`.
struct Frame<'a, 'b> {
    p: &'a ArrayView3<'b, f32>,
    t: usize,
    dt: f64,
    y_min: f64,
}

impl Frame<'_, '_> {
    fn cur(&self, j: usize) -> V3 {
        at(self.p, self.t, j)
    }
    fn prev(&self, j: usize) -> V3 {
        at(self.p, self.t - 1, j)
    }
    /// `manual.py`'s f_move(j1, j2, j3, _): velocity of `j3` relative to `j1`, along `j1 → j2`, above `thr`.
    fn f_move(&self, j1: usize, j2: usize, j3: usize, thr: f64) -> bool {
        let vel = sub(
            sub(self.cur(j3), self.cur(j1)),
            sub(self.prev(j3), self.prev(j1)),
        );
        let dir = sub(self.cur(j2), self.cur(j1));
        dot(vel, dir) / norm(dir) / self.dt > thr
    }
    /// F_nmove(j1, j2, j3; j4): velocity of `j4` relative to `j1` along the normal `(j3−j1)×(j2−j1)`.
    fn f_nmove(&self, j1: usize, j2: usize, j3: usize, j4: usize, thr: f64) -> bool {
        let vel = sub(
            sub(self.cur(j4), self.cur(j1)),
            sub(self.prev(j4), self.prev(j1)),
        );
        let n = cross(
            sub(self.cur(j3), self.cur(j1)),
            sub(self.cur(j2), self.cur(j1)),
        );
        dot(vel, n) / norm(n) / self.dt > thr
    }
    /// F_plane(a, b, c; p): signed distance of `p` from the plane through a, b, c (normal
    /// `(c−a)×(b−a)`) above `thr`.
    fn f_plane(&self, a: V3, b: V3, c: V3, p: V3, thr: f64) -> bool {
        let n = cross(sub(c, a), sub(b, a));
        dot(n, sub(p, a)) / norm(n) > thr
    }
    /// F_nplane(n1, n2, a; p): distance of `p` from the plane through `a` with normal `n2 − n1`.
    fn f_nplane(&self, n1: V3, n2: V3, a: V3, p: V3, thr: f64) -> bool {
        let n = sub(n2, n1);
        dot(n, sub(p, a)) / norm(n) > thr
    }
    /// F_angle(j1, j2, k1, k2): angle between `j2 − j1` and `k2 − k1` strictly inside (lo, hi) degrees.
    fn f_angle(&self, j1: V3, j2: V3, k1: V3, k2: V3, lo: f64, hi: f64) -> bool {
        let a = sub(j2, j1);
        let b = sub(k2, k1);
        let deg = (dot(a, b) / (norm(a) * norm(b)))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        deg > lo && deg < hi
    }
    /// F_fast(j): speed of `j` above `thr`.
    fn f_fast(&self, j: usize, thr: f64) -> bool {
        norm(sub(self.cur(j), self.prev(j))) / self.dt > thr
    }
}

/// Geometric features of a window: the share of frames `1..T−1` where each of the 32 boolean
/// relational features of `manual.py` holds (same order, same thresholds in units of `hl`, `sw`,
/// `hw`). Empty windows (T < 2) give zeros.
pub fn geometric_features(
    positions: ArrayView3<'_, f32>,
    fps: f64,
    g: &GeometricJoints,
    s: &BodyScale,
) -> Vec<f64> {
    let (t, nj, _) = positions.dim();
    let mut sums = vec![0.0f64; GEOMETRIC_DIM];
    if t < 2 {
        return sums;
    }
    let (hl, sw, hw) = (s.humerus, s.shoulder_width, s.hip_width);
    let zero = [0.0; 3];
    let y_unit = [0.0, 1.0, 0.0];
    let minus_y = [0.0, -1.0, 0.0];
    for f in 1..t {
        let y_min = (0..nj)
            .map(|j| positions[[f, j, 1]] as f64)
            .fold(f64::INFINITY, f64::min);
        let fr = Frame {
            p: &positions,
            t: f,
            dt: 1.0 / fps,
            y_min,
        };
        let c = |j: usize| fr.cur(j);
        let ymin = [0.0, fr.y_min, 0.0];
        let feats: [bool; GEOMETRIC_DIM] = [
            fr.f_nmove(g.neck, g.rhip, g.lhip, g.rwrist, 1.8 * hl),
            fr.f_nmove(g.neck, g.lhip, g.rhip, g.lwrist, 1.8 * hl),
            fr.f_nplane(c(g.chest), c(g.neck), c(g.neck), c(g.rwrist), 0.2 * hl),
            fr.f_nplane(c(g.chest), c(g.neck), c(g.neck), c(g.lwrist), 0.2 * hl),
            fr.f_move(g.belly, g.chest, g.chest, 1.8 * hl),
            fr.f_move(g.belly, g.chest, g.chest, 1.8 * hl),
            fr.f_angle(
                c(g.relbow),
                c(g.rshoulder),
                c(g.relbow),
                c(g.rwrist),
                0.0,
                110.0,
            ),
            fr.f_angle(
                c(g.lelbow),
                c(g.lshoulder),
                c(g.lelbow),
                c(g.lwrist),
                0.0,
                110.0,
            ),
            fr.f_nplane(
                c(g.lshoulder),
                c(g.rshoulder),
                c(g.lwrist),
                c(g.rwrist),
                2.5 * sw,
            ),
            fr.f_move(g.lwrist, g.rwrist, g.rwrist, 1.4 * hl),
            fr.f_move(g.rwrist, g.root, g.lwrist, 1.4 * hl),
            fr.f_move(g.lwrist, g.root, g.rwrist, 1.4 * hl),
            fr.f_fast(g.rwrist, 2.5 * hl),
            fr.f_fast(g.lwrist, 2.5 * hl),
            fr.f_plane(c(g.root), c(g.lhip), c(g.ltoes), c(g.rankle), 0.38 * hl),
            fr.f_plane(c(g.root), c(g.rhip), c(g.rtoes), c(g.lankle), 0.38 * hl),
            fr.f_nplane(zero, y_unit, ymin, c(g.rankle), 1.2 * hl),
            fr.f_nplane(zero, y_unit, ymin, c(g.lankle), 1.2 * hl),
            fr.f_nplane(c(g.lhip), c(g.rhip), c(g.lankle), c(g.rankle), 2.1 * hw),
            fr.f_angle(c(g.rknee), c(g.rhip), c(g.rknee), c(g.rankle), 0.0, 110.0),
            fr.f_angle(c(g.lknee), c(g.lhip), c(g.lknee), c(g.lankle), 0.0, 110.0),
            fr.f_fast(g.rankle, 2.5 * hl),
            fr.f_fast(g.lankle, 2.5 * hl),
            fr.f_angle(
                c(g.neck),
                c(g.root),
                c(g.rshoulder),
                c(g.relbow),
                25.0,
                180.0,
            ),
            fr.f_angle(
                c(g.neck),
                c(g.root),
                c(g.lshoulder),
                c(g.lelbow),
                25.0,
                180.0,
            ),
            fr.f_angle(c(g.neck), c(g.root), c(g.rhip), c(g.rknee), 50.0, 180.0),
            fr.f_angle(c(g.neck), c(g.root), c(g.lhip), c(g.lknee), 50.0, 180.0),
            fr.f_plane(c(g.rankle), c(g.neck), c(g.lankle), c(g.root), 0.5 * hl),
            fr.f_angle(c(g.neck), c(g.root), zero, y_unit, 70.0, 110.0),
            fr.f_nplane(zero, minus_y, ymin, c(g.rwrist), -1.2 * hl),
            fr.f_nplane(zero, minus_y, ymin, c(g.lwrist), -1.2 * hl),
            fr.f_fast(g.root, 2.3 * hl),
        ];
        for (s, b) in sums.iter_mut().zip(feats) {
            if b {
                *s += 1.0;
            }
        }
    }
    let n = (t - 1) as f64;
    sums.iter_mut().for_each(|s| *s /= n);
    sums
}
