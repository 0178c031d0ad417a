//! Spectral building blocks with librosa 0.11 defaults: centred STFT (zero padding, periodic
//! Hann), Slaney mel filterbank, `power_to_db`, orthonormal DCT-II (MFCC) and `delta`.
//!
//! Matrices are time-major: `[frames, bins]`, one row per STFT frame.
use std::sync::Arc;

use ndarray::{Array2, ArrayView2, Axis};
use realfft::{RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;

/// `|c|`, without the overflow guard of `hypot` (what `Complex32::norm` calls), which costs
/// several times more; spectra of audio in [-1, 1] are nowhere near overflow.
pub fn magnitude(c: Complex32) -> f32 {
    (c.re * c.re + c.im * c.im).sqrt()
}

/// Dot product over equal-length slices, with 32 independent accumulators: a sum in one
/// register waits on each add before the next (its latency, 3–4 cycles), so four vector
/// registers' worth of partial sums keep the adder busy and the loop vectorises.
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 32;
    let mut acc = [0.0f32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..LANES {
            acc[k] += x[k] * y[k];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Periodic Hann window (scipy `get_window('hann', n, fftbins=True)`).
pub fn hann_periodic(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()) as f32)
        .collect()
}

/// Number of frames of a centred STFT (librosa `center=True`).
pub fn n_frames(len: usize, hop: usize) -> usize {
    1 + len / hop
}

/// A centred STFT that hands out one frame at a time, so no spectrogram is ever stored whole.
pub struct Stft {
    pub n_fft: usize,
    pub hop: usize,
    window: Vec<f32>,
    fft: Arc<dyn RealToComplex<f32>>,
    frame: Vec<f32>,
    spectrum: Vec<Complex32>,
    scratch: Vec<Complex32>,
}

impl Stft {
    /// A Hann-windowed STFT.
    pub fn new(n_fft: usize, hop: usize) -> Self {
        Self::with_window(n_fft, hop, hann_periodic(n_fft))
    }

    /// An STFT with a given window of length `n_fft`.
    pub fn with_window(n_fft: usize, hop: usize, window: Vec<f32>) -> Self {
        let fft = RealFftPlanner::<f32>::new().plan_fft_forward(n_fft);
        let spectrum = fft.make_output_vec();
        let scratch = fft.make_scratch_vec();
        Self {
            n_fft,
            hop,
            window,
            fft,
            frame: vec![0.0; n_fft],
            spectrum,
            scratch,
        }
    }

    /// Number of bins, `1 + n_fft / 2`.
    pub fn n_bins(&self) -> usize {
        self.n_fft / 2 + 1
    }

    /// Complex spectrum of frame `t` of `y` (zero padded by `n_fft / 2` on both sides).
    pub fn frame(&mut self, y: &[f32], t: usize) -> &[Complex32] {
        let half = self.n_fft / 2;
        let start = (t * self.hop) as isize - half as isize;
        if start >= 0 && start as usize + self.n_fft <= y.len() {
            // A frame inside the signal (all but the first and last few) needs no bounds test.
            let x = &y[start as usize..start as usize + self.n_fft];
            for ((f, w), v) in self.frame.iter_mut().zip(&self.window).zip(x) {
                *f = v * w;
            }
        } else {
            self.pad_frame(y, start);
        }
        // realfft only errors on wrong buffer lengths, which are fixed at construction.
        let _ =
            self.fft
                .process_with_scratch(&mut self.frame, &mut self.spectrum, &mut self.scratch);
        &self.spectrum
    }

    /// Windows a frame that overhangs either end of `y` (zero outside it).
    fn pad_frame(&mut self, y: &[f32], start: isize) {
        for (i, (f, w)) in self.frame.iter_mut().zip(&self.window).enumerate() {
            let idx = start + i as isize;
            *f = if idx >= 0 && (idx as usize) < y.len() {
                y[idx as usize] * w
            } else {
                0.0
            };
        }
    }

    /// Power spectrum |X|² of frame `t` into `out` (length `n_bins`).
    pub fn power(&mut self, y: &[f32], t: usize, out: &mut [f32]) {
        let spec = self.frame(y, t);
        for (o, c) in out.iter_mut().zip(spec) {
            *o = c.re * c.re + c.im * c.im;
        }
    }
}

/// Hz → mel, Slaney scale (librosa `hz_to_mel(htk=False)`).
pub fn hz_to_mel(f: f64) -> f64 {
    let f_sp = 200.0 / 3.0;
    let min_log_hz = 1000.0;
    let min_log_mel = min_log_hz / f_sp;
    let logstep = (6.4f64).ln() / 27.0;
    if f >= min_log_hz {
        min_log_mel + (f / min_log_hz).ln() / logstep
    } else {
        f / f_sp
    }
}

/// Mel → Hz, Slaney scale.
pub fn mel_to_hz(m: f64) -> f64 {
    let f_sp = 200.0 / 3.0;
    let min_log_hz = 1000.0;
    let min_log_mel = min_log_hz / f_sp;
    let logstep = (6.4f64).ln() / 27.0;
    if m >= min_log_mel {
        min_log_hz * (logstep * (m - min_log_mel)).exp()
    } else {
        f_sp * m
    }
}

/// A sparse filterbank: for each output band, the first bin and its weights.
#[derive(Clone, Debug)]
pub struct SparseBank {
    pub rows: Vec<(usize, Vec<f32>)>,
    pub n_bins: usize,
}

impl SparseBank {
    /// Builds from a dense `[bands][bins]` matrix, keeping the non-zero span of each row.
    pub fn from_dense(dense: &[Vec<f64>]) -> Self {
        let n_bins = dense.first().map_or(0, |r| r.len());
        let rows = dense
            .iter()
            .map(|r| {
                let first = r.iter().position(|&w| w != 0.0).unwrap_or(0);
                let last = r.iter().rposition(|&w| w != 0.0).map_or(first, |l| l + 1);
                (
                    first,
                    r[first..last.max(first)]
                        .iter()
                        .map(|&w| w as f32)
                        .collect(),
                )
            })
            .collect();
        Self { rows, n_bins }
    }

    /// Number of output bands.
    pub fn n_bands(&self) -> usize {
        self.rows.len()
    }

    /// `out[b] = Σ_k W[b,k] x[k]`.
    pub fn apply(&self, x: &[f32], out: &mut [f32]) {
        for ((first, w), o) in self.rows.iter().zip(out.iter_mut()) {
            *o = w
                .iter()
                .zip(&x[*first..*first + w.len()])
                .map(|(a, b)| a * b)
                .sum();
        }
    }
}

/// Slaney-normalised mel filterbank (librosa `filters.mel`, `htk=False`, `norm='slaney'`).
pub fn mel_filterbank(sr: u32, n_fft: usize, n_mels: usize, fmin: f64, fmax: f64) -> SparseBank {
    let n_bins = n_fft / 2 + 1;
    let fftfreqs: Vec<f64> = (0..n_bins)
        .map(|k| k as f64 * sr as f64 / n_fft as f64)
        .collect();
    let (mmin, mmax) = (hz_to_mel(fmin), hz_to_mel(fmax));
    let mel_f: Vec<f64> = (0..n_mels + 2)
        .map(|i| mel_to_hz(mmin + (mmax - mmin) * i as f64 / (n_mels + 1) as f64))
        .collect();
    let dense: Vec<Vec<f64>> = (0..n_mels)
        .map(|i| {
            let (lo, c, hi) = (mel_f[i], mel_f[i + 1], mel_f[i + 2]);
            let enorm = 2.0 / (hi - lo);
            fftfreqs
                .iter()
                .map(|&f| {
                    let lower = (f - lo) / (c - lo);
                    let upper = (hi - f) / (hi - c);
                    lower.min(upper).max(0.0) * enorm
                })
                .collect()
        })
        .collect();
    SparseBank::from_dense(&dense)
}

/// Mel power spectrogram `[frames, n_mels]` (librosa `melspectrogram`, power 2).
pub fn melspectrogram(y: &[f32], sr: u32, n_fft: usize, hop: usize, n_mels: usize) -> Array2<f32> {
    let bank = mel_filterbank(sr, n_fft, n_mels, 0.0, sr as f64 / 2.0);
    let mut stft = Stft::new(n_fft, hop);
    let t_n = n_frames(y.len(), hop);
    let mut out = Array2::<f32>::zeros((t_n, n_mels));
    let mut power = vec![0.0f32; stft.n_bins()];
    for (t, mut row) in out.axis_iter_mut(Axis(0)).enumerate() {
        stft.power(y, t, &mut power);
        if let Some(r) = row.as_slice_mut() {
            bank.apply(&power, r);
        }
    }
    out
}

/// `power_to_db(S, ref=1, amin=1e-10, top_db=80)`, in place; the floor is global, as librosa's.
pub fn power_to_db_inplace(s: &mut Array2<f32>) {
    let amin = 1e-10f32;
    s.mapv_inplace(|v| 10.0 * v.max(amin).log10());
    let max = s.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    if max.is_finite() {
        let floor = max - 80.0;
        s.mapv_inplace(|v| v.max(floor));
    }
}

/// `power_to_db(S, ref=np.max)`: like `power_to_db_inplace` but 0 dB at the loudest bin.
pub fn power_to_db_ref_max_inplace(s: &mut Array2<f32>) {
    let max = s.iter().cloned().fold(0.0f32, f32::max);
    let ref_db = 10.0 * max.max(1e-10).log10();
    power_to_db_inplace(s);
    s.mapv_inplace(|v| v - ref_db);
}

/// Orthonormal DCT-II matrix `[n_out, n_in]` (scipy `dct(type=2, norm='ortho')`).
pub fn dct_matrix(n_out: usize, n_in: usize) -> Array2<f32> {
    let mut m = Array2::<f32>::zeros((n_out, n_in));
    for k in 0..n_out {
        let scale = if k == 0 {
            (1.0 / n_in as f64).sqrt()
        } else {
            (2.0 / n_in as f64).sqrt()
        };
        for n in 0..n_in {
            let v = scale
                * (std::f64::consts::PI * k as f64 * (2 * n + 1) as f64 / (2 * n_in) as f64).cos();
            m[[k, n]] = v as f32;
        }
    }
    m
}

/// MFCC `[frames, n_mfcc]` from a mel power spectrogram `[frames, n_mels]` (librosa `mfcc`).
pub fn mfcc_from_mel(mel_power: &Array2<f32>, n_mfcc: usize) -> Array2<f32> {
    let mut db = mel_power.clone();
    power_to_db_inplace(&mut db);
    mfcc_from_db(db.view(), n_mfcc)
}

/// MFCC from a mel spectrogram already in dB.
pub fn mfcc_from_db(mel_db: ArrayView2<f32>, n_mfcc: usize) -> Array2<f32> {
    let d = dct_matrix(n_mfcc, mel_db.ncols());
    mel_db.dot(&d.t())
}

/// librosa `feature.delta(width, order=1, mode='interp')` along time (rows), `width` odd ≥ 3.
///
/// Savitzky–Golay of order 1 is the slope of a least-squares line over `width` frames; at the
/// edges `interp` fits one line to the first (last) `width` frames, so the edge rows copy the
/// first (last) full-window row. Fewer frames than `width` (librosa raises) fall back to one
/// line fit over all frames.
pub fn delta(x: &Array2<f32>, width: usize) -> Array2<f32> {
    let t_n = x.nrows();
    let mut out = Array2::<f32>::zeros(x.raw_dim());
    if t_n < 2 {
        return out;
    }
    let half = (width.max(3) | 1) / 2;
    if t_n < 2 * half + 1 {
        let mean_t = (t_n - 1) as f64 / 2.0;
        let denom: f64 = (0..t_n).map(|t| (t as f64 - mean_t).powi(2)).sum();
        for c in 0..x.ncols() {
            let num: f64 = (0..t_n)
                .map(|t| (t as f64 - mean_t) * x[[t, c]] as f64)
                .sum();
            let s = (num / denom) as f32;
            for t in 0..t_n {
                out[[t, c]] = s;
            }
        }
        return out;
    }
    let denom: f64 = (1..=half).map(|k| 2.0 * (k * k) as f64).sum();
    for t in half..t_n - half {
        for c in 0..x.ncols() {
            let mut acc = 0.0f64;
            for k in 1..=half {
                acc += k as f64 * (x[[t + k, c]] as f64 - x[[t - k, c]] as f64);
            }
            out[[t, c]] = (acc / denom) as f32;
        }
    }
    let (a, b) = (out.row(half).to_owned(), out.row(t_n - 1 - half).to_owned());
    for t in 0..half {
        out.row_mut(t).assign(&a);
        out.row_mut(t_n - 1 - t).assign(&b);
    }
    out
}

/// librosa `util.normalize(norm=inf)` per row: divide by the max |x| unless it is below `tiny`.
pub fn normalize_rows_inf(x: &mut Array2<f32>) {
    for mut row in x.axis_iter_mut(Axis(0)) {
        let m = row.iter().fold(0.0f32, |a, &v| a.max(v.abs()));
        if m >= f32::MIN_POSITIVE {
            row.mapv_inplace(|v| v / m);
        }
    }
}

/// Median of a slice (mean of the middle two for even lengths), as numpy; 0 for empty.
pub fn median(v: &mut [f32]) -> f32 {
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    v.sort_unstable_by(|a, b| a.total_cmp(b));
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}
