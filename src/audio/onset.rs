//! Onset strength (librosa `onset.onset_strength`) and harmonic/percussive separation of the
//! signal (librosa `effects.hpss`), whose percussive part gives the percussive onset envelope.
use ndarray::Array2;

use super::dsp::{self, median, Stft};

/// How the per-band flux is pooled into one value per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aggregate {
    /// `np.mean`, the default of `onset_strength`.
    Mean,
    /// `np.median`, what `beat_track` uses.
    Median,
}

/// Onset strength from a mel spectrogram in dB `[frames, bands]`, lag 1, max_size 1, centred:
/// `env[t] = agg_f max(0, S[t-2, f] - S[t-3, f])` (the shift `1 + n_fft / (2 hop)` counters
/// framing), zero for the first frames, same length as `S`.
pub fn onset_strength_from_db(
    s_db: &Array2<f32>,
    n_fft: usize,
    hop: usize,
    agg: Aggregate,
) -> Vec<f32> {
    let t_n = s_db.nrows();
    let pad = 1 + n_fft / (2 * hop);
    let mut env = vec![0.0f32; t_n];
    let mut flux = vec![0.0f32; s_db.ncols()];
    for j in 0..t_n.saturating_sub(1) {
        let t = j + pad;
        if t >= t_n {
            break;
        }
        let (prev, cur) = (s_db.row(j), s_db.row(j + 1));
        for ((f, &a), &b) in flux.iter_mut().zip(cur.iter()).zip(prev.iter()) {
            *f = (a - b).max(0.0);
        }
        env[t] = match agg {
            Aggregate::Mean => {
                flux.iter().map(|&v| v as f64).sum::<f64>() as f32 / flux.len().max(1) as f32
            }
            Aggregate::Median => median(&mut flux),
        };
    }
    env
}

/// Onset strength of a signal: mel (128 bands, fmax sr/2) → dB → flux (librosa defaults).
pub fn onset_strength(y: &[f32], sr: u32, n_fft: usize, hop: usize, agg: Aggregate) -> Vec<f32> {
    let mut mel = dsp::melspectrogram(y, sr, n_fft, hop, super::N_MELS);
    dsp::power_to_db_inplace(&mut mel);
    onset_strength_from_db(&mel, n_fft, hop, agg)
}

/// A window of `2·half + 1` values kept sorted, for sliding medians.
///
/// The values are kept as `f32::total_cmp`'s integer keys: the same order, and integer
/// comparisons count four to a register where the float ordering's bit twiddling does not.
struct SortedWindow {
    v: Vec<i32>,
}

/// The integer whose order is `f32::total_cmp`'s (its own definition).
fn key(x: f32) -> i32 {
    let b = x.to_bits() as i32;
    b ^ ((((b >> 31) as u32) >> 1) as i32)
}

/// The inverse of [`key`] (the mask depends on the sign bit only, which it keeps).
fn unkey(k: i32) -> f32 {
    f32::from_bits((k ^ ((((k >> 31) as u32) >> 1) as i32)) as u32)
}

impl SortedWindow {
    fn new(init: Vec<f32>) -> Self {
        let mut v: Vec<i32> = init.into_iter().map(key).collect();
        v.sort_unstable();
        Self { v }
    }

    /// Swaps one occurrence of `old` for `new`. Both places are found by counting the values
    /// below them, without branches: a binary search over 31 values mispredicts at nearly
    /// every step, and this runs twice per bin and frame of [`hpss_signal`].
    fn replace(&mut self, old: f32, new: f32) {
        let (old, new) = (key(old), key(new));
        let v = &mut self.v;
        let below = |x: i32| v.iter().map(|&y| u32::from(y < x)).sum::<u32>() as usize;
        let i = below(old).min(v.len() - 1);
        let j = below(new);
        if j <= i {
            // v[j..i] are ≥ new: they move right over `old`.
            v.copy_within(j..i, j + 1);
            v[j] = new;
        } else {
            // v[i+1..j] are < new: they move left over `old`.
            v.copy_within(i + 1..j, i);
            v[j - 1] = new;
        }
    }

    fn median(&self) -> f32 {
        unkey(self.v[self.v.len() / 2])
    }
}

/// scipy `mode='reflect'` index (d c b a | a b c d), folded until in range.
fn reflect(mut j: isize, n: usize) -> usize {
    let n = n as isize;
    loop {
        if j < 0 {
            j = -j - 1;
        } else if j >= n {
            j = 2 * n - j - 1;
        } else {
            return j as usize;
        }
    }
}

/// Sliding median of width `2·half + 1` over a contiguous lane, reflect boundaries.
fn sliding_median(x: &[f32], half: usize, out: &mut [f32]) {
    let n = x.len();
    if n == 0 {
        return;
    }
    let ext = |j: isize| x[reflect(j, n)];
    let mut w = SortedWindow::new((-(half as isize)..=half as isize).map(ext).collect());
    out[0] = w.median();
    for i in 1..n {
        let i = i as isize;
        w.replace(ext(i - half as isize - 1), ext(i + half as isize));
        out[i as usize] = w.median();
    }
}

/// librosa `effects.hpss(y)`: STFT (2048/512, Hann) → median filters (31 frames along time
/// for the harmonic part, 31 bins along frequency for the percussive part) → soft masks
/// (power 2, margin 1) → inverse STFT. Streams over frames: memory is 31 frames plus the
/// two output signals.
pub fn hpss_signal(y: &[f32], n_fft: usize, hop: usize) -> (Vec<f32>, Vec<f32>) {
    let len = y.len();
    let t_n = dsp::n_frames(len, hop);
    let half = 15usize;
    let mut stft = Stft::new(n_fft, hop);
    let nb = stft.n_bins();
    // Cache of (spectrum, magnitude) for the frames a window needs.
    let mut cache: std::collections::BTreeMap<
        usize,
        (Vec<rustfft::num_complex::Complex32>, Vec<f32>),
    > = std::collections::BTreeMap::new();
    let mut get = |t: usize,
                   cache: &mut std::collections::BTreeMap<
        usize,
        (Vec<rustfft::num_complex::Complex32>, Vec<f32>),
    >| {
        cache.entry(t).or_insert_with(|| {
            let spec = stft.frame(y, t).to_vec();
            let mag = spec.iter().map(|c| dsp::magnitude(*c)).collect();
            (spec, mag)
        });
    };
    let ext = |j: isize| reflect(j, t_n);
    for j in -(half as isize)..=half as isize {
        get(ext(j), &mut cache);
    }
    let mut windows: Vec<SortedWindow> = (0..nb)
        .map(|k| {
            SortedWindow::new(
                (-(half as isize)..=half as isize)
                    .map(|j| cache[&ext(j)].1[k])
                    .collect(),
            )
        })
        .collect();
    let window = dsp::hann_periodic(n_fft);
    let inv = realfft::RealFftPlanner::<f32>::new().plan_fft_inverse(n_fft);
    let mut ispec = inv.make_input_vec();
    let mut frame_out = inv.make_output_vec();
    let mut iscratch = inv.make_scratch_vec();
    let mut harm_y = vec![0.0f32; len];
    let mut perc_y = vec![0.0f32; len];
    let mut perc_med = vec![0.0f32; nb];
    let mut mask_p = vec![0.0f32; nb];
    for t in 0..t_n {
        if t > 0 {
            let (old, new) = (
                ext(t as isize - half as isize - 1),
                ext((t + half) as isize),
            );
            get(new, &mut cache);
            let (old_mag, new_mag) = (&cache[&old].1, &cache[&new].1);
            for ((w, &o), &n) in windows.iter_mut().zip(old_mag).zip(new_mag) {
                w.replace(o, n);
            }
            // Frames older than the window (and not needed for end reflection) can go.
            let keep_from = t.saturating_sub(half + 1);
            while let Some((&first, _)) = cache.iter().next() {
                if first < keep_from && first + 2 * half + 2 < t_n {
                    cache.remove(&first);
                } else {
                    break;
                }
            }
        }
        let (spec, mag) = &cache[&t];
        sliding_median(mag, half, &mut perc_med);
        for k in 0..nb {
            let (h, p) = (windows[k].median(), perc_med[k]);
            let z = h.max(p);
            mask_p[k] = if z < f32::MIN_POSITIVE {
                0.5
            } else {
                let (hh, pp) = ((h / z).powi(2), (p / z).powi(2));
                pp / (hh + pp)
            };
        }
        let start = (t * hop) as isize - (n_fft / 2) as isize;
        // Only the percussive part is inverted: the masks sum to 1, so the harmonic part is the
        // signal minus it (istft(stft(y)) = y), found after the loop at half the cost.
        for (k, c) in ispec.iter_mut().enumerate() {
            *c = spec[k] * mask_p[k];
        }
        // The inverse real FFT needs purely real DC and Nyquist bins.
        ispec[0].im = 0.0;
        ispec[nb - 1].im = 0.0;
        let _ = inv.process_with_scratch(&mut ispec, &mut frame_out, &mut iscratch);
        for (i, (v, w)) in frame_out.iter().zip(&window).enumerate() {
            let idx = start + i as isize;
            if idx >= 0 && (idx as usize) < len {
                perc_y[idx as usize] += v * w / n_fft as f32;
            }
        }
    }
    // Divide by the window's sum of squares over the (at most n_fft / hop) overlapping frames.
    let half_fft = (n_fft / 2) as isize;
    for (idx, (h, p)) in harm_y.iter_mut().zip(perc_y.iter_mut()).enumerate() {
        let pos = idx as isize + half_fft;
        let t_hi = ((pos / hop as isize) as usize).min(t_n - 1);
        let t_lo = ((pos - n_fft as isize + 1).max(0) as usize).div_ceil(hop);
        let mut w = 0.0f32;
        for t in t_lo..=t_hi {
            let off = pos - (t * hop) as isize;
            if (0..n_fft as isize).contains(&off) {
                w += window[off as usize] * window[off as usize];
            }
        }
        if w > f32::MIN_POSITIVE {
            *p /= w;
        }
        *h = y[idx] - *p;
    }
    (harm_y, perc_y)
}
