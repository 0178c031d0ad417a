//! Chroma: tuning estimation (librosa `piptrack` + `pitch_tuning`), `chroma_stft`, the
//! constant-Q transform (librosa 0.11 `cqt`: recursive octave downsampling, Hann wavelets,
//! L1-normalised, sparsified FFT basis) and `chroma_cqt`.
//!
//! librosa halves the sample rate between octaves with soxr; we use a zero-phase Kaiser
//! windowed-sinc FIR instead. Each octave only needs the band below ~0.2 of the input rate,
//! where both resamplers are flat, so the chroma agrees (tested: correlation > 0.99).
use ndarray::{Array2, Axis};
use realfft::RealFftPlanner;
use rustfft::num_complex::Complex32;
use rustfft::FftPlanner;

use super::dsp::{self, normalize_rows_inf, Stft};
use super::AudioError;

/// librosa `note_to_hz('C1')`.
pub const C1_HZ: f64 = 32.703_195_662_574_83;
/// Equivalent noise bandwidth of the Hann window, in FFT bins (librosa `WINDOW_BANDWIDTHS`).
const HANN_BANDWIDTH: f64 = 1.500_183_105_468_75;

/// One peak found by `piptrack`: (interpolated frequency in Hz, interpolated magnitude).
type Peak = (f32, f32);

/// Peaks of one spectrum frame `s` (librosa `piptrack`, fmin 150, fmax 4000, threshold 0.1).
fn piptrack_frame(s: &[f32], sr: u32, n_fft: usize, out: &mut Vec<Peak>) {
    let n = s.len();
    if n < 3 {
        return;
    }
    let fmax = 4000f64.min(sr as f64 / 2.0);
    let fmin = 150.0;
    let ref_value = 0.1 * s.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let th = |i: usize| if s[i] > ref_value { s[i] } else { 0.0 };
    for i in 1..n {
        let f = i as f64 * sr as f64 / n_fft as f64;
        if f < fmin || f >= fmax {
            continue;
        }
        let x = th(i);
        let is_max = if i == n - 1 {
            x > th(i - 1)
        } else {
            x > th(i - 1) && x >= th(i + 1)
        };
        if !is_max {
            continue;
        }
        let (shift, avg) = if i == n - 1 {
            (0.0, s[i] - s[i - 1])
        } else {
            let a = s[i + 1] + s[i - 1] - 2.0 * s[i];
            let b = (s[i + 1] - s[i - 1]) / 2.0;
            (if b.abs() >= a.abs() { 0.0 } else { -b / a }, b)
        };
        let pitch = (i as f32 + shift) * sr as f32 / n_fft as f32;
        let mag = s[i] + 0.5 * avg * shift;
        out.push((pitch, mag));
    }
}

/// librosa `pitch_tuning`: histogram (resolution 0.01) of the deviation from the nearest bin.
fn pitch_tuning(freqs: impl Iterator<Item = f32>, bins_per_octave: usize) -> f64 {
    let n_hist = 100usize;
    let mut counts = vec![0usize; n_hist];
    let mut any = false;
    for f in freqs.filter(|&f| f > 0.0) {
        any = true;
        let octs = (f as f64 / (440.0 / 16.0)).log2();
        let mut r = (bins_per_octave as f64 * octs).rem_euclid(1.0);
        if r >= 0.5 {
            r -= 1.0;
        }
        let edge = |i: usize| -0.5 + i as f64 * 0.01;
        let mut idx = ((r + 0.5) * 100.0).floor().clamp(0.0, (n_hist - 1) as f64) as usize;
        if r < edge(idx) && idx > 0 {
            idx -= 1;
        } else if idx + 1 < n_hist && r >= edge(idx + 1) {
            idx += 1;
        }
        counts[idx] += 1;
    }
    if !any {
        return 0.0;
    }
    let best = counts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
        .map_or(0, |(i, _)| i);
    -0.5 + best as f64 * 0.01
}

/// librosa `estimate_tuning` over spectrogram frames `[frames, bins]` (magnitude or power).
pub fn estimate_tuning_from_spec(
    spec: &Array2<f32>,
    sr: u32,
    n_fft: usize,
    bins_per_octave: usize,
) -> f64 {
    let mut peaks: Vec<Peak> = Vec::new();
    for row in spec.axis_iter(Axis(0)) {
        let r = row.to_vec();
        piptrack_frame(&r, sr, n_fft, &mut peaks);
    }
    tuning_from_peaks(peaks, bins_per_octave)
}

fn tuning_from_peaks(peaks: Vec<Peak>, bins_per_octave: usize) -> f64 {
    let mut mags: Vec<f32> = peaks.iter().filter(|p| p.0 > 0.0).map(|p| p.1).collect();
    let threshold = if mags.is_empty() {
        0.0
    } else {
        dsp::median(&mut mags)
    };
    pitch_tuning(
        peaks
            .iter()
            .filter(|p| p.0 > 0.0 && p.1 >= threshold)
            .map(|p| p.0),
        bins_per_octave,
    )
}

/// librosa `estimate_tuning(y=y)`: piptrack on the magnitude STFT (n_fft 2048, hop 512).
pub fn estimate_tuning(y: &[f32], sr: u32, bins_per_octave: usize) -> f64 {
    let n_fft = 2048;
    let mut stft = Stft::new(n_fft, n_fft / 4);
    let mut peaks = Vec::new();
    let mut mag = vec![0.0f32; stft.n_bins()];
    for t in 0..dsp::n_frames(y.len(), n_fft / 4) {
        for (m, c) in mag.iter_mut().zip(stft.frame(y, t)) {
            *m = dsp::magnitude(*c);
        }
        piptrack_frame(&mag, sr, n_fft, &mut peaks);
    }
    tuning_from_peaks(peaks, bins_per_octave)
}

fn hz_to_octs(f: f64, tuning: f64, bins_per_octave: usize) -> f64 {
    let a440 = 440.0 * 2f64.powf(tuning / bins_per_octave as f64);
    (f / (a440 / 16.0)).log2()
}

/// librosa `filters.chroma` (12 bins, ctroct 5, octwidth 2, L2 columns, base C): `[12, bins]`.
pub fn chroma_filterbank(sr: u32, n_fft: usize, tuning: f64) -> Array2<f32> {
    let n_chroma = 12usize;
    let nc = n_chroma as f64;
    let mut frqbins: Vec<f64> = (1..n_fft)
        .map(|k| nc * hz_to_octs(k as f64 * sr as f64 / n_fft as f64, tuning, n_chroma))
        .collect();
    frqbins.insert(0, frqbins[0] - 1.5 * nc);
    let mut binwidth: Vec<f64> = frqbins.windows(2).map(|w| (w[1] - w[0]).max(1.0)).collect();
    binwidth.push(1.0);
    let n2 = (nc / 2.0).round();
    let mut wts = Array2::<f64>::zeros((n_chroma, n_fft));
    for (k, (&fb, &bw)) in frqbins.iter().zip(&binwidth).enumerate() {
        for c in 0..n_chroma {
            let d = (fb - c as f64 + n2 + 10.0 * nc).rem_euclid(nc) - n2;
            wts[[c, k]] = (-0.5 * (2.0 * d / bw).powi(2)).exp();
        }
    }
    for k in 0..n_fft {
        let norm = (0..n_chroma)
            .map(|c| wts[[c, k]].powi(2))
            .sum::<f64>()
            .sqrt();
        let oct = (-0.5 * ((frqbins[k] / nc - 5.0) / 2.0).powi(2)).exp();
        for c in 0..n_chroma {
            let v = if norm > f64::MIN_POSITIVE {
                wts[[c, k]] / norm
            } else {
                wts[[c, k]]
            };
            wts[[c, k]] = v * oct;
        }
    }
    // Roll so that row 0 is C (librosa rolls by -3).
    let n_bins = n_fft / 2 + 1;
    let mut out = Array2::<f32>::zeros((n_chroma, n_bins));
    for c in 0..n_chroma {
        for k in 0..n_bins {
            out[[c, k]] = wts[[(c + 3) % n_chroma, k]] as f32;
        }
    }
    out
}

/// librosa `chroma_stft` (power spectrogram, n_fft 2048, tuning estimated): `[frames, 12]`.
pub fn chroma_stft(y: &[f32], sr: u32, n_fft: usize, hop: usize) -> Array2<f32> {
    let mut stft = Stft::new(n_fft, hop);
    let t_n = dsp::n_frames(y.len(), hop);
    let mut power = Array2::<f32>::zeros((t_n, stft.n_bins()));
    for (t, mut row) in power.axis_iter_mut(Axis(0)).enumerate() {
        if let Some(r) = row.as_slice_mut() {
            stft.power(y, t, r);
        }
    }
    let tuning = estimate_tuning_from_spec(&power, sr, n_fft, 12);
    let fb = chroma_filterbank(sr, n_fft, tuning);
    let mut chroma = power.dot(&fb.t());
    normalize_rows_inf(&mut chroma);
    chroma
}

/// Zero-phase half-band FIR decimator: lowpass at the new Nyquist, keep every 2nd sample,
/// scaled by √2 as librosa's `resample(scale=True)` does.
pub struct Halver {
    taps: Vec<f32>,
}

impl Default for Halver {
    fn default() -> Self {
        Self::new()
    }
}

impl Halver {
    /// A 95-tap Kaiser (β = 9) windowed sinc with cutoff 0.245 of the input rate.
    pub fn new() -> Self {
        let m = 47i64;
        let fc = 0.245f64;
        let beta = 9.0f64;
        let i0 = |x: f64| {
            let (mut sum, mut term, mut k) = (1.0f64, 1.0f64, 1.0f64);
            while term > 1e-12 * sum {
                term *= (x / (2.0 * k)).powi(2);
                sum += term;
                k += 1.0;
            }
            sum
        };
        let mut taps: Vec<f64> = (-m..=m)
            .map(|n| {
                let x = n as f64;
                let sinc = if n == 0 {
                    2.0 * fc
                } else {
                    (2.0 * std::f64::consts::PI * fc * x).sin() / (std::f64::consts::PI * x)
                };
                let r = x / m as f64;
                sinc * i0(beta * (1.0 - r * r).max(0.0).sqrt()) / i0(beta)
            })
            .collect();
        let s: f64 = taps.iter().sum();
        taps.iter_mut().for_each(|t| *t /= s);
        Self {
            taps: taps
                .into_iter()
                .map(|t| (t * std::f64::consts::SQRT_2) as f32)
                .collect(),
        }
    }

    /// Halves the rate; output length `ceil(n / 2)`.
    pub fn halve(&self, x: &[f32]) -> Vec<f32> {
        let n = x.len();
        let m = self.taps.len() / 2;
        let out_len = n.div_ceil(2);
        let mut out = vec![0.0f32; out_len];
        for (o, y) in out.iter_mut().enumerate() {
            let c = 2 * o;
            let lo = c.saturating_sub(m);
            let hi = (c + m + 1).min(n);
            let t0 = lo + m - c;
            *y = dsp::dot(&self.taps[t0..t0 + (hi - lo)], &x[lo..hi]);
        }
        out
    }
}

/// One octave's sparse FFT-domain filters: per filter, first bin and complex weights.
struct OctaveBasis {
    n_fft: usize,
    rows: Vec<(usize, Vec<Complex32>)>,
}

fn octave_basis(freqs: &[f64], alpha: &[f64], sr: f64, scale: f64) -> OctaveBasis {
    let lengths: Vec<f64> = freqs
        .iter()
        .zip(alpha)
        .map(|(f, a)| (1.0 / a) * sr / f)
        .collect();
    let max_len = lengths.iter().cloned().fold(0.0, f64::max);
    let n_fft = 2f64.powf(max_len.log2().ceil()) as usize;
    let mut planner = FftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(n_fft);
    let mut rows = Vec::with_capacity(freqs.len());
    for (&f, &ilen) in freqs.iter().zip(&lengths) {
        // np.arange(-ilen // 2, ilen // 2): floor division of a float.
        let start = (-ilen / 2.0).floor();
        let stop = (ilen / 2.0).floor();
        let count = (stop - start).ceil().max(0.0) as usize;
        let win = dsp::hann_periodic(count);
        let mut sig: Vec<rustfft::num_complex::Complex<f64>> = (0..count)
            .map(|i| {
                let t = start + i as f64;
                let ph = t * 2.0 * std::f64::consts::PI * f / sr;
                rustfft::num_complex::Complex::new(ph.cos(), ph.sin()) * win[i] as f64
            })
            .collect();
        let l1: f64 = sig.iter().map(|c| c.norm()).sum();
        if l1 > 0.0 {
            sig.iter_mut().for_each(|c| *c /= l1);
        }
        let mut buf = vec![rustfft::num_complex::Complex::new(0.0, 0.0); n_fft];
        let lpad = (n_fft - count.min(n_fft)) / 2;
        for (i, c) in sig.iter().take(n_fft).enumerate() {
            buf[lpad + i] = *c * (ilen / n_fft as f64);
        }
        fft.process(&mut buf);
        let half: Vec<rustfft::num_complex::Complex<f64>> = buf[..n_fft / 2 + 1].to_vec();
        // util.sparsify_rows(quantile=0.01): drop the smallest bins holding 1% of the L1 mass.
        let mags: Vec<f64> = half.iter().map(|c| c.norm()).collect();
        let total: f64 = mags.iter().sum();
        let mut sorted = mags.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let mut cum = 0.0;
        let mut thr = sorted.last().copied().unwrap_or(0.0);
        for &m in &sorted {
            cum += m / total;
            if cum >= 0.01 {
                thr = m;
                break;
            }
        }
        let first = mags.iter().position(|&m| m >= thr).unwrap_or(0);
        let last = mags
            .iter()
            .rposition(|&m| m >= thr)
            .map_or(first, |l| l + 1);
        let w: Vec<Complex32> = (first..last)
            .map(|k| {
                let c = if mags[k] >= thr {
                    half[k] * scale
                } else {
                    rustfft::num_complex::Complex::new(0.0, 0.0)
                };
                Complex32::new(c.re as f32, c.im as f32)
            })
            .collect();
        rows.push((first, w));
    }
    OctaveBasis { n_fft, rows }
}

/// Constant-Q magnitude `[frames, n_bins]` (librosa `cqt`, hann, filter_scale 1, scale=True).
pub fn cqt_magnitude(
    y: &[f32],
    sr: u32,
    hop: usize,
    fmin: f64,
    n_bins: usize,
    bins_per_octave: usize,
    tuning: f64,
) -> Result<Array2<f32>, AudioError> {
    let n_octaves = n_bins.div_ceil(bins_per_octave);
    let fmin = fmin * 2f64.powf(tuning / bins_per_octave as f64);
    let freqs: Vec<f64> = (0..n_bins)
        .map(|k| fmin * 2f64.powf(k as f64 / bins_per_octave as f64))
        .collect();
    let logf: Vec<f64> = freqs.iter().map(|f| f.log2()).collect();
    let alpha: Vec<f64> = (0..n_bins)
        .map(|k| {
            let bpo = if n_bins < 2 {
                bins_per_octave as f64
            } else if k == 0 {
                1.0 / (logf[1] - logf[0])
            } else if k == n_bins - 1 {
                1.0 / (logf[k] - logf[k - 1])
            } else {
                2.0 / (logf[k + 1] - logf[k - 1])
            };
            let r = 2f64.powf(2.0 / bpo);
            (r - 1.0) / (r + 1.0)
        })
        .collect();
    let cutoff = freqs
        .iter()
        .zip(&alpha)
        .map(|(f, a)| f * (1.0 + 0.5 * HANN_BANDWIDTH * a))
        .fold(0.0, f64::max);
    let nyquist = sr as f64 / 2.0;
    if cutoff > nyquist {
        return Err(AudioError::InvalidParameter(format!(
            "CQT top frequency {cutoff:.0} Hz exceeds the Nyquist frequency {nyquist:.0} Hz"
        )));
    }
    let halver = Halver::new();
    // Early downsampling, as librosa's __early_downsample_count.
    let count1 = ((nyquist / cutoff).log2().ceil() as i64 - 1 - 1).max(0);
    let twos = hop.trailing_zeros() as i64;
    let count2 = (twos - n_octaves as i64 + 1).max(0);
    let early = count1.min(count2) as u32;
    let mut my_y = y.to_vec();
    let mut base_sr = sr as f64;
    let mut my_hop = hop;
    for _ in 0..early {
        my_y = halver.halve(&my_y);
        base_sr /= 2.0;
        my_hop /= 2;
    }
    let mut my_sr = base_sr;
    let mut responses: Vec<Array2<f32>> = Vec::with_capacity(n_octaves);
    let mut rplanner = RealFftPlanner::<f32>::new();
    for i in 0..n_octaves {
        let hi = n_bins - bins_per_octave * i;
        let lo = hi.saturating_sub(bins_per_octave);
        let basis = octave_basis(
            &freqs[lo..hi],
            &alpha[lo..hi],
            my_sr,
            (base_sr / my_sr).sqrt(),
        );
        let fft = rplanner.plan_fft_forward(basis.n_fft);
        let mut frame = fft.make_input_vec();
        let mut spec = fft.make_output_vec();
        let mut scratch = fft.make_scratch_vec();
        let t_n = dsp::n_frames(my_y.len(), my_hop);
        let mut resp = Array2::<f32>::zeros((t_n, hi - lo));
        let half = basis.n_fft / 2;
        for t in 0..t_n {
            let start = (t * my_hop) as isize - half as isize;
            for (j, v) in frame.iter_mut().enumerate() {
                let idx = start + j as isize;
                *v = if idx >= 0 && (idx as usize) < my_y.len() {
                    my_y[idx as usize]
                } else {
                    0.0
                };
            }
            let _ = fft.process_with_scratch(&mut frame, &mut spec, &mut scratch);
            for (b, (first, w)) in basis.rows.iter().enumerate() {
                let mut acc = Complex32::new(0.0, 0.0);
                for (wk, sk) in w.iter().zip(&spec[*first..*first + w.len()]) {
                    acc += wk * sk;
                }
                resp[[t, b]] = dsp::magnitude(acc);
            }
        }
        responses.push(resp);
        if my_hop.is_multiple_of(2) && i + 1 < n_octaves {
            my_hop /= 2;
            my_sr /= 2.0;
            my_y = halver.halve(&my_y);
        }
    }
    let t_min = responses.iter().map(|r| r.nrows()).min().unwrap_or(0);
    let mut out = Array2::<f32>::zeros((t_min, n_bins));
    for (i, r) in responses.iter().enumerate() {
        let hi = n_bins - bins_per_octave * i;
        let lo = hi.saturating_sub(bins_per_octave);
        let width = hi - lo;
        out.slice_mut(ndarray::s![.., lo..hi])
            .assign(&r.slice(ndarray::s![..t_min, r.ncols() - width..]));
    }
    // scale=True: divide by √(filter length) at the (early-downsampled) base rate.
    for k in 0..n_bins {
        let len = (1.0 / alpha[k]) * base_sr / freqs[k];
        let s = 1.0 / len.sqrt() as f32;
        out.column_mut(k).mapv_inplace(|v| v * s);
    }
    Ok(out)
}

/// librosa `chroma_cqt` defaults (C1, 7 octaves, 36 bins per octave, tuning estimated,
/// max-normalised): `[frames, 12]`.
pub fn chroma_cqt(y: &[f32], sr: u32, hop: usize) -> Result<Array2<f32>, AudioError> {
    let bpo = 36usize;
    let n_bins = 7 * bpo;
    let tuning = estimate_tuning(y, sr, bpo);
    let c = cqt_magnitude(y, sr, hop, C1_HZ, n_bins, bpo, tuning)?;
    // cq_to_chroma: bin k feeds pitch class ((k + 1) mod 36) / 3 (C1 is pitch class 0).
    let mut chroma = Array2::<f32>::zeros((c.nrows(), 12));
    for (t, row) in c.axis_iter(Axis(0)).enumerate() {
        for (k, &v) in row.iter().enumerate() {
            chroma[[t, ((k + 1) % bpo) / (bpo / 12)]] += v;
        }
    }
    normalize_rows_inf(&mut chroma);
    Ok(chroma)
}
