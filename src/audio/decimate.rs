//! Whole-factor decimation (44 100 → 22 050 Hz, the analysis rate) by FFT convolution.
//!
//! The polyphase FIR of [`super::resample`] spends one dot product of its whole filter (361
//! taps at 2:1) on every output sample; that was most of the time `analyze` took. When the
//! ratio is 1/M, the filter has a single branch, so the same outputs are every M-th sample of
//! one linear convolution, which overlap-save computes with real FFTs for a few operations per
//! input sample. The filter is the polyphase one's, so the response is unchanged; the outputs
//! differ from the direct sums by float rounding only (about 1e-7 of the signal's peak).
use std::sync::Arc;

use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;

/// The FFT is at least this many times the filter's length: the share of each block spent
/// on the filter's overlap stays under 1/8, and the transforms stay in cache.
const FFT_PER_TAPS: usize = 8;

/// Streaming `y[n] = Σ_k h[k] · x[n·M + centre − k]`, with `x` zero outside the input.
pub(super) struct FftDecimator {
    m: u64,
    /// Filter delay in input samples (the filter's centre tap).
    centre: usize,
    taps: usize,
    n_fft: usize,
    fwd: Arc<dyn RealToComplex<f32>>,
    inv: Arc<dyn ComplexToReal<f32>>,
    /// The filter's spectrum, scaled by 1/n_fft (realfft's inverse does not normalise).
    filter: Vec<Complex32>,
    frame: Vec<f32>,
    spectrum: Vec<Complex32>,
    back: Vec<f32>,
    scratch_fwd: Vec<Complex32>,
    scratch_inv: Vec<Complex32>,
    /// Input not yet consumed; `buf[0]` is absolute input index `buf_start`.
    buf: Vec<f32>,
    buf_start: i64,
    next_out: u64,
    total_in: u64,
}

impl FftDecimator {
    /// `filter` in convolution order, `2·centre + 1` taps; keeps every `m`-th sample.
    pub(super) fn new(filter: &[f32], centre: usize, m: u64) -> Self {
        let taps = filter.len();
        let n_fft = (FFT_PER_TAPS * taps).next_power_of_two();
        let mut planner = RealFftPlanner::<f32>::new();
        let fwd = planner.plan_fft_forward(n_fft);
        let inv = planner.plan_fft_inverse(n_fft);
        let mut frame = fwd.make_input_vec();
        let mut spectrum = fwd.make_output_vec();
        let mut scratch_fwd = fwd.make_scratch_vec();
        frame[..taps].copy_from_slice(filter);
        // realfft only errors on wrong buffer lengths, which come from the plan itself.
        let _ = fwd.process_with_scratch(&mut frame, &mut spectrum, &mut scratch_fwd);
        let scale = 1.0 / n_fft as f32;
        let filter = spectrum.iter().map(|c| c * scale).collect();
        let back = inv.make_output_vec();
        let scratch_inv = inv.make_scratch_vec();
        Self {
            m,
            centre,
            taps,
            n_fft,
            fwd,
            inv,
            filter,
            frame,
            spectrum,
            back,
            scratch_fwd,
            scratch_inv,
            // The first output needs `centre` samples before the input starts: zeros.
            buf: vec![0.0; centre],
            buf_start: -(centre as i64),
            next_out: 0,
            total_in: 0,
        }
    }

    /// Convolves every whole block in `buf`, emitting outputs below `limit`.
    fn produce(&mut self, out: &mut Vec<f32>, limit: u64) {
        let block = self.n_fft - self.taps + 1;
        let mut at = 0usize;
        while self.buf.len() - at >= self.n_fft && self.next_out < limit {
            self.frame.copy_from_slice(&self.buf[at..at + self.n_fft]);
            let _ = self.fwd.process_with_scratch(
                &mut self.frame,
                &mut self.spectrum,
                &mut self.scratch_fwd,
            );
            for (s, h) in self.spectrum.iter_mut().zip(&self.filter) {
                *s *= h;
            }
            // The inverse real FFT needs purely real DC and Nyquist bins (they are, up to rounding).
            self.spectrum[0].im = 0.0;
            let last = self.spectrum.len() - 1;
            self.spectrum[last].im = 0.0;
            let _ = self.inv.process_with_scratch(
                &mut self.spectrum,
                &mut self.back,
                &mut self.scratch_inv,
            );
            // back[i] is the convolution at absolute index s + i, valid for i ≥ taps − 1.
            let s = self.buf_start + at as i64;
            let end = s + self.n_fft as i64;
            while self.next_out < limit {
                let j = (self.next_out * self.m) as i64 + self.centre as i64;
                if j >= end {
                    break;
                }
                out.push(self.back[(j - s) as usize]);
                self.next_out += 1;
            }
            at += block;
        }
        self.buf.drain(..at);
        self.buf_start += at as i64;
    }

    pub(super) fn push(&mut self, x: &[f32], out: &mut Vec<f32>) {
        self.buf.extend_from_slice(x);
        self.total_in += x.len() as u64;
        self.produce(out, u64::MAX);
    }

    pub(super) fn finish(mut self, out: &mut Vec<f32>) {
        // soxr/librosa length: ceil(n_in / M); the tail sees zeros past the end.
        let expected = self.total_in.div_ceil(self.m);
        while self.next_out < expected {
            self.buf.resize(self.buf.len() + self.n_fft, 0.0);
            self.produce(out, expected);
        }
    }
}
