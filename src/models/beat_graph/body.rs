//! One body for a composed dance: bone lengths, and a dance moved onto other ones.
use ndarray::{s, Array3, ArrayView2, ArrayView3};

use crate::motion::skeleton::{FOOT_POINTS, PARENTS};
use crate::motion::NUM_JOINTS;

/// Order of the joints from the body centre outwards (a joint after its parent).
fn outward() -> Vec<usize> {
    let mut order: Vec<usize> = Vec::with_capacity(NUM_JOINTS);
    while order.len() < NUM_JOINTS {
        for (j, parent) in PARENTS.iter().enumerate() {
            let ready = parent.is_none_or(|p| order.contains(&p));
            if ready && !order.contains(&j) {
                order.push(j);
            }
        }
    }
    order
}

/// Each bone's median length (m) over a dance, `[NUM_JOINTS]` (bone = parent → joint, the
/// body centre for the spine).
pub fn bone_lengths(positions: ArrayView3<'_, f32>, centre: ArrayView2<'_, f32>) -> Vec<f32> {
    (0..NUM_JOINTS)
        .map(|j| {
            let mut l: Vec<f32> = (0..positions.dim().0)
                .map(|t| {
                    let p = |k: usize| match PARENTS[j] {
                        Some(q) => positions[[t, q, k]],
                        None => centre[[t, k]],
                    };
                    (0..3)
                        .map(|k| (positions[[t, j, k]] - p(k)).powi(2))
                        .sum::<f32>()
                        .sqrt()
                })
                .collect();
            l.sort_by(f32::total_cmp);
            l.get(l.len() / 2).copied().unwrap_or(0.0)
        })
        .collect()
}

/// The dance on bones of `lengths`: every bone keeps its direction, frame by frame, so every
/// joint angle is the dancer's. The units of different dancers then share one skeleton, and a
/// composed dance takes the body of the key poses or seed motion it is given: the export fits
/// one rigid skeleton to a whole dance (on the key poses' or the seed's frames when there are
/// some), and a dance of other proportions than that skeleton's comes out of the fit with bent
/// joints (with 4 key poses of another dancer, authenticity 0.88 before the fit, 0.43 after).
/// With `keep_floor`, the dance is moved up or down so that its feet keep their floor.
pub fn rebone(
    positions: &mut Array3<f32>,
    centre: ArrayView2<'_, f32>,
    lengths: &[f32],
    keep_floor: bool,
) {
    let floor = crate::motion::feet::floor_height(positions.view(), &FOOT_POINTS);
    let order = outward();
    for t in 0..positions.dim().0 {
        let old = positions.slice(s![t, .., ..]).to_owned();
        for &j in &order {
            let (from_old, from_new): ([f32; 3], [f32; 3]) = match PARENTS[j] {
                Some(q) => (
                    std::array::from_fn(|k| old[[q, k]]),
                    std::array::from_fn(|k| positions[[t, q, k]]),
                ),
                None => {
                    let c = std::array::from_fn(|k| centre[[t, k]]);
                    (c, c)
                }
            };
            let d: [f32; 3] = std::array::from_fn(|k| old[[j, k]] - from_old[k]);
            let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if norm > 1e-6 {
                for k in 0..3 {
                    positions[[t, j, k]] = from_new[k] + d[k] / norm * lengths[j];
                }
            }
        }
    }
    if !keep_floor {
        return;
    }
    let lift = floor - crate::motion::feet::floor_height(positions.view(), &FOOT_POINTS);
    positions
        .slice_mut(s![.., .., 1])
        .mapv_inplace(|y| y + lift as f32);
}
