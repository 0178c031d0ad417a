//! Per-dimension normalisation statistics, computed on the train split and stored with a model.
use ndarray::{Array1, Array2, Axis};
use serde::{Deserialize, Serialize};

/// `x ↦ (x − mean) / std`, per column. Columns with (near) zero spread keep std = 1.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Normalizer {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl Normalizer {
    /// Statistics over the rows of every matrix in `parts` (all with the same column count).
    pub fn fit<'a>(parts: impl IntoIterator<Item = &'a Array2<f32>>) -> Self {
        let mut sum: Option<Array1<f64>> = None;
        let mut sq: Option<Array1<f64>> = None;
        let mut n = 0usize;
        for m in parts {
            let m64 = m.mapv(f64::from);
            let s = m64.sum_axis(Axis(0));
            let q = (&m64 * &m64).sum_axis(Axis(0));
            sum = Some(match sum { Some(a) => a + s, None => s });
            sq = Some(match sq { Some(a) => a + q, None => q });
            n += m.nrows();
        }
        let (Some(sum), Some(sq)) = (sum, sq) else { return Self { mean: vec![], std: vec![] } };
        let n = n.max(1) as f64;
        let mean = &sum / n;
        let var = (&sq / n - &mean * &mean).mapv(|v| v.max(0.0));
        Self {
            mean: mean.iter().map(|&v| v as f32).collect(),
            std: var.iter().map(|&v| if v.sqrt() < 1e-6 { 1.0 } else { v.sqrt() as f32 }).collect(),
        }
    }

    /// Column count.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Normalises rows of `x`.
    pub fn apply(&self, x: &Array2<f32>) -> Array2<f32> {
        let mean = Array1::from(self.mean.clone());
        let std = Array1::from(self.std.clone());
        (x - &mean) / &std
    }

    /// Inverse of [`Normalizer::apply`].
    pub fn invert(&self, x: &Array2<f32>) -> Array2<f32> {
        let mean = Array1::from(self.mean.clone());
        let std = Array1::from(self.std.clone());
        x * &std + &mean
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_standardises() {
        let a = ndarray::array![[1.0f32, 5.0, 2.0], [3.0, 5.0, 4.0]];
        let b = ndarray::array![[5.0f32, 5.0, 6.0]];
        let n = Normalizer::fit([&a, &b]);
        assert!((n.mean[0] - 3.0).abs() < 1e-6);
        assert_eq!(n.std[1], 1.0, "a constant column keeps std 1");
        let z = n.apply(&a);
        let back = n.invert(&z);
        assert!((back - &a).iter().all(|d| d.abs() < 1e-5));
    }
}
