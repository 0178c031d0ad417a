//! Streaming resampling for the decode: a soxr_hq-like polyphase FIR for small-fraction ratios
//! (run by FFT convolution when the ratio is 1/M, [`super::decimate`]), rubato's FFT resampler
//! otherwise.
use rubato::{FftFixedIn, Resampler};

use super::decimate::FftDecimator;
use super::AudioError;

/// Input chunk (frames) fed to rubato; small so the resampler's buffers stay tiny.
const RESAMPLE_CHUNK: usize = 4096;

/// Streaming resampler: the soxr_hq-like polyphase FIR when the ratio is a small fraction,
/// rubato's FFT resampler otherwise.
pub(super) enum StreamResampler {
    Poly(PolyResampler),
    /// The polyphase filter of a 1/M ratio, by FFT convolution; boxed for its FFT buffers.
    Decimate(Box<FftDecimator>),
    /// Boxed: rubato's FFT state is several times the polyphase one's size.
    Rubato(Box<RubatoResampler>),
}

impl StreamResampler {
    pub(super) fn new(sr_in: u32, sr_out: u32) -> Result<Self, AudioError> {
        match PolyResampler::new(sr_in, sr_out) {
            Some(p) if p.l == 1 => Ok(Self::Decimate(Box::new(p.into_decimator()))),
            Some(p) => Ok(Self::Poly(p)),
            None => Ok(Self::Rubato(Box::new(RubatoResampler::new(sr_in, sr_out)?))),
        }
    }

    pub(super) fn push(&mut self, x: &[f32], out: &mut Vec<f32>) -> Result<(), AudioError> {
        match self {
            Self::Poly(p) => {
                p.push(x, out);
                Ok(())
            }
            Self::Decimate(d) => {
                d.push(x, out);
                Ok(())
            }
            Self::Rubato(r) => r.push(x, out),
        }
    }

    pub(super) fn finish(self, out: &mut Vec<f32>) -> Result<(), AudioError> {
        match self {
            Self::Poly(p) => {
                p.finish(out);
                Ok(())
            }
            Self::Decimate(d) => {
                d.finish(out);
                Ok(())
            }
            Self::Rubato(r) => r.finish(out),
        }
    }
}

/// Largest interpolation factor L (sr_out / sr_in = L / M reduced) served by the polyphase FIR.
const MAX_POLY_PHASES: u64 = 1024;

/// Linear-phase polyphase FIR resampler with soxr's "HQ" response: passband flat to 0.913
/// of the lower Nyquist, stopband from 1.0 of it, 120 dB (Kaiser). librosa loads with
/// soxr_hq; rubato's FFT resampler cuts off at ~0.99 of Nyquist, which measurably moves
/// librosa's beats (F 0.975 on hungarian_dance_5), while this response gives F = 1.0.
pub(super) struct PolyResampler {
    l: u64,
    m: u64,
    /// Half length R in input samples; branch p has 2R + 1 taps, stored reversed.
    r: usize,
    branches: Vec<f32>,
    /// Input not yet consumed; `buf[0]` is absolute input index `buf_start`.
    buf: Vec<f32>,
    buf_start: i64,
    next_out: u64,
    total_in: u64,
}

/// Zeroth-order modified Bessel function of the first kind (Kaiser window).
fn bessel_i0(x: f64) -> f64 {
    let (mut sum, mut term, mut k) = (1.0f64, 1.0f64, 1.0f64);
    while term > 1e-14 * sum {
        term *= (x / (2.0 * k)).powi(2);
        sum += term;
        k += 1.0;
    }
    sum
}

impl PolyResampler {
    fn new(sr_in: u32, sr_out: u32) -> Option<Self> {
        let g = gcd(sr_in as u64, sr_out as u64);
        let (l, m) = (sr_out as u64 / g, sr_in as u64 / g);
        if l > MAX_POLY_PHASES {
            return None;
        }
        let (pass_end, atten) = (0.913f64, 120.0f64);
        let up_rate = sr_in as f64 * l as f64;
        let nyq = sr_in.min(sr_out) as f64 / 2.0;
        let fc = (1.0 + pass_end) / 2.0 * nyq / up_rate; // cycles per up-rate sample
        let dw = (1.0 - pass_end) * nyq / up_rate;
        let beta = 0.1102 * (atten - 8.7);
        let n_up = ((atten - 7.95) / (2.285 * 2.0 * std::f64::consts::PI * dw)).ceil();
        let r = (n_up / (2.0 * l as f64)).ceil() as usize;
        let center = (r as u64 * l) as f64;
        let half_len = center;
        let i0b = bessel_i0(beta);
        let taps = 2 * r + 1;
        let mut branches = vec![0.0f32; l as usize * taps];
        for p in 0..l as usize {
            for i in 0..taps {
                let k = p as f64 + (i as u64 * l) as f64;
                let x = k - center;
                if x.abs() > half_len {
                    continue;
                }
                let sinc = if x == 0.0 {
                    2.0 * fc
                } else {
                    (2.0 * std::f64::consts::PI * fc * x).sin() / (std::f64::consts::PI * x)
                };
                let w = bessel_i0(beta * (1.0 - (x / half_len).powi(2)).max(0.0).sqrt()) / i0b;
                // Stored reversed so the dot product runs forward over the input.
                branches[p * taps + (taps - 1 - i)] = (sinc * w * l as f64) as f32;
            }
        }
        Some(Self {
            l,
            m,
            r,
            branches,
            buf: Vec::new(),
            buf_start: 0,
            next_out: 0,
            total_in: 0,
        })
    }

    fn taps(&self) -> usize {
        2 * self.r + 1
    }

    /// The same filter as an FFT decimator (a 1/M ratio has one branch, stored reversed).
    fn into_decimator(self) -> FftDecimator {
        let filter: Vec<f32> = self.branches[..self.taps()].iter().rev().copied().collect();
        FftDecimator::new(&filter, self.r, self.m)
    }

    /// Output sample n needs input `base - R ..= base + R` with base = ⌊n M / L⌋.
    fn produce(&mut self, out: &mut Vec<f32>, available_end: i64, limit: u64) {
        let taps = self.taps();
        let r = self.r as i64;
        while self.next_out < limit {
            let t = self.next_out * self.m;
            let (base, p) = ((t / self.l) as i64, (t % self.l) as usize);
            if base + r >= available_end {
                break;
            }
            let g = &self.branches[p * taps..(p + 1) * taps];
            let lo = base - r;
            let mut acc = 0.0f32;
            if lo >= self.buf_start {
                let s = (lo - self.buf_start) as usize;
                acc = dot(g, &self.buf[s..s + taps]);
            } else {
                for (i, w) in g.iter().enumerate() {
                    let j = lo + i as i64;
                    if j >= self.buf_start {
                        acc += w * self.buf[(j - self.buf_start) as usize];
                    }
                }
            }
            out.push(acc);
            self.next_out += 1;
        }
        // Drop input that no future output needs.
        let t = self.next_out * self.m;
        let keep_from = (t / self.l) as i64 - r;
        if keep_from > self.buf_start {
            let d = ((keep_from - self.buf_start) as usize).min(self.buf.len());
            self.buf.drain(..d);
            self.buf_start += d as i64;
        }
    }

    fn push(&mut self, x: &[f32], out: &mut Vec<f32>) {
        self.buf.extend_from_slice(x);
        self.total_in += x.len() as u64;
        let end = self.buf_start + self.buf.len() as i64;
        self.produce(out, end, u64::MAX);
    }

    fn finish(mut self, out: &mut Vec<f32>) {
        // soxr/librosa length: ceil(n_in · L / M); the tail sees zeros past the end.
        let expected = (self.total_in * self.l).div_ceil(self.m);
        self.buf.extend(std::iter::repeat_n(0.0, self.taps() + 1));
        let end = self.buf_start + self.buf.len() as i64;
        while self.next_out < expected {
            let before = self.next_out;
            self.produce(out, end, expected);
            if self.next_out == before {
                self.buf.extend(std::iter::repeat_n(0.0, self.taps() + 1));
                let end2 = self.buf_start + self.buf.len() as i64;
                self.produce(out, end2, expected);
                if self.next_out == before {
                    break;
                }
            }
        }
    }
}

/// Dot product with eight accumulators so it vectorises. Kept at eight (not
/// [`super::dsp::dot`]'s 32): the feature sets' beat trackers run on these samples, and a
/// different summation order moved one TSMT/DanceNet beat of vibe_ace by a frame.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a.max(1)
}

/// rubato's synchronous FFT resampler, fed in fixed chunks, with its delay removed so output
/// sample n is the input at time n / sr_out exactly. Used for rates whose ratio has a large
/// numerator (e.g. 44 101 Hz), where a polyphase table would be too big.
pub(super) struct RubatoResampler {
    inner: FftFixedIn<f32>,
    pending: Vec<f32>,
    delay_left: usize,
    total_in: u64,
    total_out: u64,
    sr_in: u32,
    sr_out: u32,
}

impl RubatoResampler {
    fn new(sr_in: u32, sr_out: u32) -> Result<Self, AudioError> {
        let inner = FftFixedIn::<f32>::new(sr_in as usize, sr_out as usize, RESAMPLE_CHUNK, 2, 1)
            .map_err(|e| AudioError::Resample(e.to_string()))?;
        let delay_left = inner.output_delay();
        Ok(Self {
            inner,
            pending: Vec::new(),
            delay_left,
            total_in: 0,
            total_out: 0,
            sr_in,
            sr_out,
        })
    }

    fn emit(&mut self, chunk: &[f32], out: &mut Vec<f32>) {
        let skip = self.delay_left.min(chunk.len());
        self.delay_left -= skip;
        out.extend_from_slice(&chunk[skip..]);
        self.total_out += (chunk.len() - skip) as u64;
    }

    fn push(&mut self, x: &[f32], out: &mut Vec<f32>) -> Result<(), AudioError> {
        self.total_in += x.len() as u64;
        self.pending.extend_from_slice(x);
        let mut start = 0;
        loop {
            let need = self.inner.input_frames_next();
            if self.pending.len() - start < need {
                break;
            }
            let res = self
                .inner
                .process(&[&self.pending[start..start + need]], None)
                .map_err(|e| AudioError::Resample(e.to_string()))?;
            start += need;
            let chunk = res.into_iter().next().unwrap_or_default();
            self.emit(&chunk, out);
        }
        self.pending.drain(..start);
        Ok(())
    }

    fn finish(mut self, out: &mut Vec<f32>) -> Result<(), AudioError> {
        let expected =
            (self.total_in as u128 * self.sr_out as u128).div_ceil(self.sr_in as u128) as u64;
        let mut first = true;
        // Flush with zeros until the delayed tail is out; bounded by delay + one chunk.
        let mut guard = 0;
        while self.total_out < expected && guard < 64 {
            let pending = std::mem::take(&mut self.pending);
            let input: Option<&[&[f32]]> = if first && !pending.is_empty() {
                Some(&[&pending[..]])
            } else {
                None
            };
            let res = self
                .inner
                .process_partial(input, None)
                .map_err(|e| AudioError::Resample(e.to_string()))?;
            first = false;
            let chunk = res.into_iter().next().unwrap_or_default();
            self.emit(&chunk, out);
            guard += 1;
        }
        let excess = self.total_out.saturating_sub(expected) as usize;
        out.truncate(out.len() - excess.min(out.len()));
        Ok(())
    }
}
