//! Fréchet distance between feature distributions (FID_k, FID_g) and diversity.
//!
//! FID (Heusel et al. 2017) between Gaussians `N(μ₁, Σ₁)` and `N(μ₂, Σ₂)`:
//! `|μ₁ − μ₂|² + tr Σ₁ + tr Σ₂ − 2 tr (Σ₁ Σ₂)^{1/2}`.
//!
//! The trace of the square root is computed with symmetric eigendecompositions only:
//! `Σ₁Σ₂` is similar to the symmetric PSD matrix `M = Σ₁^{1/2} Σ₂ Σ₁^{1/2}`, so
//! `tr (Σ₁Σ₂)^{1/2} = Σᵢ √λᵢ(M)`. Eigenvalues that come out negative are rounding noise of a PSD
//! matrix and are clamped to 0 (the only epsilon: [`EIGEN_FLOOR`] = 0). No diagonal offset is
//! added: `scipy.linalg.sqrtm` as pytorch-fid uses it adds `1e-6·I` only when its Schur method
//! fails, which never happens on our data, and the eigen route needs no such rescue.
//!
//! Features are z-normalised by the real (train) mean and standard deviation before any of this,
//! `(x − μ) / (σ + 1e-10)` as in Bailando's `normalize` ([`Z_EPS`]).
use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// Eigenvalues of the PSD matrices below this are treated as 0 (rounding noise).
pub const EIGEN_FLOOR: f64 = 0.0;
/// Added to the standard deviation when z-normalising, so constant features do not divide by 0.
pub const Z_EPS: f64 = 1e-10;

/// Mean and covariance of a feature distribution.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Gaussian {
    pub mean: Vec<f64>,
    /// Row-major `d × d`, unbiased (`N − 1`) like `np.cov`; all zeros for a single sample.
    pub cov: Vec<f64>,
    /// How many feature vectors it was fitted on.
    pub count: usize,
}

impl Gaussian {
    /// Fits mean and unbiased covariance to `rows` (each of length `d`). `None` when empty or ragged.
    pub fn fit(rows: &[Vec<f64>]) -> Option<Self> {
        let n = rows.len();
        let d = rows.first()?.len();
        if rows.iter().any(|r| r.len() != d) {
            return None;
        }
        let mut mean = vec![0.0; d];
        for r in rows {
            for (m, x) in mean.iter_mut().zip(r) {
                *m += x;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        let mut cov = vec![0.0; d * d];
        if n > 1 {
            for r in rows {
                for a in 0..d {
                    let da = r[a] - mean[a];
                    for b in a..d {
                        cov[a * d + b] += da * (r[b] - mean[b]);
                    }
                }
            }
            for a in 0..d {
                for b in a..d {
                    let v = cov[a * d + b] / (n as f64 - 1.0);
                    cov[a * d + b] = v;
                    cov[b * d + a] = v;
                }
            }
        }
        Some(Self {
            mean,
            cov,
            count: n,
        })
    }

    fn dim(&self) -> usize {
        self.mean.len()
    }

    fn cov_matrix(&self) -> DMatrix<f64> {
        DMatrix::from_row_slice(self.dim(), self.dim(), &self.cov)
    }
}

/// Per-feature mean and (population, `ddof = 0`, as numpy's default `std`) standard deviation.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ZNorm {
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
}

impl ZNorm {
    /// Fits the normaliser to `rows`; `None` when empty or ragged.
    pub fn fit(rows: &[Vec<f64>]) -> Option<Self> {
        let n = rows.len() as f64;
        let d = rows.first()?.len();
        if rows.iter().any(|r| r.len() != d) {
            return None;
        }
        let mean: Vec<f64> = (0..d)
            .map(|k| rows.iter().map(|r| r[k]).sum::<f64>() / n)
            .collect();
        let std = (0..d)
            .map(|k| (rows.iter().map(|r| (r[k] - mean[k]).powi(2)).sum::<f64>() / n).sqrt())
            .collect();
        Some(Self { mean, std })
    }

    /// `(x − μ) / (σ + 1e-10)` for each feature.
    pub fn apply(&self, row: &[f64]) -> Vec<f64> {
        row.iter()
            .zip(&self.mean)
            .zip(&self.std)
            .map(|((x, m), s)| (x - m) / (s + Z_EPS))
            .collect()
    }
}

/// Symmetric PSD square root `U diag(√max(λ, 0)) Uᵀ`.
fn sqrt_psd(m: DMatrix<f64>) -> DMatrix<f64> {
    let e = SymmetricEigen::new(m);
    let s = DVector::from_iterator(
        e.eigenvalues.len(),
        e.eigenvalues.iter().map(|&l| clamp_eig(l).sqrt()),
    );
    &e.eigenvectors * DMatrix::from_diagonal(&s) * e.eigenvectors.transpose()
}

fn clamp_eig(l: f64) -> f64 {
    if l < EIGEN_FLOOR {
        0.0
    } else {
        l
    }
}

/// `tr (Σ₁ Σ₂)^{1/2}` via `Σ₁^{1/2} Σ₂ Σ₁^{1/2}` (see the module doc).
pub fn trace_sqrt_product(s1: &DMatrix<f64>, s2: &DMatrix<f64>) -> f64 {
    let r1 = sqrt_psd(s1.clone());
    let m = &r1 * s2 * &r1;
    // Symmetrise: the product is symmetric in exact arithmetic only.
    let m = (&m + m.transpose()) * 0.5;
    SymmetricEigen::new(m)
        .eigenvalues
        .iter()
        .map(|&l| clamp_eig(l).sqrt())
        .sum()
}

/// The Fréchet distance between two fitted Gaussians of the same dimension.
pub fn frechet_distance(a: &Gaussian, b: &Gaussian) -> f64 {
    let s1 = a.cov_matrix();
    let s2 = b.cov_matrix();
    let dmu: f64 = a
        .mean
        .iter()
        .zip(&b.mean)
        .map(|(x, y)| (x - y).powi(2))
        .sum();
    dmu + s1.trace() + s2.trace() - 2.0 * trace_sqrt_product(&s1, &s2)
}

/// Mean Euclidean distance over all unordered pairs of rows (Bailando's `calculate_avg_distance`);
/// 0 with fewer than two rows.
pub fn mean_pairwise_distance(rows: &[Vec<f64>]) -> f64 {
    let n = rows.len();
    if n < 2 {
        return 0.0;
    }
    let mut total = 0.0;
    for i in 0..n {
        for j in i + 1..n {
            total += rows[i]
                .iter()
                .zip(&rows[j])
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
        }
    }
    total / (n * (n - 1) / 2) as f64
}
