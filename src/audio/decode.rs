//! Decoding with symphonia: mono downmix (channel mean, as librosa's `to_mono`), the AAC
//! encoder-delay trim from the MP4 edit list, and streaming resampling so that a long song
//! never exists at its native rate in memory when a lower rate is asked for.
//!
//! Every decode is bounded while it runs, because the file is a stranger's: the sample rate and
//! (where the header declares one) the duration are checked before the first packet; the decoded
//! length is counted as it streams and decoding stops at the limit; a [`Budget`] is checked on
//! every packet; and what is kept ([`Keep`]) never grows with the native rate beyond the caller's
//! choice. symphonia's own MP4 reader parses the edit list but does not expose it (its `atoms`
//! module is private, and `CodecParameters` carries no delay for MP4), hence the small parser at
//! the end of this file, which reads sizes from the file with checked arithmetic only.
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::Path;

use rubato::{FftFixedIn, Resampler};
use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{self, CodecParameters, DecoderOptions, CODEC_TYPE_NULL};
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::{MediaSource, MediaSourceStream};
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;

use super::{AudioError, AudioFormat, Budget, DecodedAudio, MAX_DURATION_S, MAX_SAMPLE_RATE, MIN_SAMPLE_RATE};

/// Input chunk (frames) fed to rubato; small so the resampler's buffers stay tiny.
const RESAMPLE_CHUNK: usize = 4096;
/// Slack on a header's declared duration before it alone refuses a song: declared lengths
/// count the encoder's priming and padding, which the decoded length does not.
const DECLARED_SLACK_S: f64 = 1.0;

/// What a decode keeps of the signal (always mono).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Keep {
    /// No samples: the file is decoded to prove it is audio and to measure it (uploads).
    Nothing,
    /// Every sample at the native rate.
    Native,
    /// Resampled to this rate while decoding.
    At(u32),
    /// The native rate, or this rate (resampled while decoding) when the native one is higher.
    AtMost(u32),
}

/// How one decode is bounded.
pub struct DecodeOptions<'a> {
    /// What of the signal to keep.
    pub keep: Keep,
    /// Longer songs are refused: from the header when it declares a length, otherwise as soon
    /// as the decoded samples pass it.
    pub max_duration_s: f64,
    /// Checked on every packet.
    pub budget: &'a Budget<'a>,
}

/// A decoded file and the duration its header declares, when it declares one.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The decoded song (no samples with [`Keep::Nothing`]).
    pub audio: DecodedAudio,
    /// From the header (Xing/Info frame count, WAV data size, FLAC STREAMINFO, MP4 track
    /// duration): a decoded length well short of it means the file was cut short.
    pub declared_s: Option<f64>,
}

/// Decodes a file with the default bounds; with `target_sr` the mono signal is resampled while
/// it streams.
pub fn decode_path_at(path: &Path, target_sr: Option<u32>) -> Result<DecodedAudio, AudioError> {
    let keep = target_sr.map_or(Keep::Native, Keep::At);
    let budget = Budget::unlimited();
    Ok(decode_file(path, &DecodeOptions { keep, max_duration_s: MAX_DURATION_S, budget: &budget })?.audio)
}

/// Decodes a file within `options`.
pub fn decode_file(path: &Path, options: &DecodeOptions) -> Result<Decoded, AudioError> {
    let mut file = std::fs::File::open(path)?;
    // The edit list only trims; a file whose boxes cannot be read simply has none.
    let edit = mp4_edit(&mut file).unwrap_or(None);
    file.seek(SeekFrom::Start(0))?;
    let mut hint = Hint::new();
    if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
        hint.with_extension(ext);
    }
    guarded(|| decode_source(Box::new(file), hint, edit, options))
}

/// Decodes an in-memory file within `options`.
pub fn decode_bytes(bytes: Vec<u8>, options: &DecodeOptions) -> Result<Decoded, AudioError> {
    let edit = mp4_edit(&mut Cursor::new(&bytes[..])).unwrap_or(None);
    guarded(|| decode_source(Box::new(Cursor::new(bytes)), Hint::new(), edit, options))
}

/// Runs a decode, answering a panic inside it as an undecodable file.
///
/// symphonia 0.5 panics on some malformed headers: a WAV or AIFF whose sample rate is 0 builds a
/// `TimeBase` with a zero denominator (found by `tests/audio/hostile.rs`). The decoder's state
/// is dropped with the panic, so nothing half-updated survives it.
fn guarded(decode: impl FnOnce() -> Result<Decoded, AudioError>) -> Result<Decoded, AudioError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(decode)).unwrap_or_else(|panic| {
        let message = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        Err(AudioError::Undecodable(format!("the decoder failed on a malformed header: {message}")))
    })
}

fn undecodable(e: SymError) -> AudioError {
    AudioError::Undecodable(e.to_string())
}

fn format_of(codec: codecs::CodecType) -> Result<AudioFormat, AudioError> {
    use codecs::*;
    Ok(match codec {
        CODEC_TYPE_MP3 | CODEC_TYPE_MP2 | CODEC_TYPE_MP1 => AudioFormat::Mp3,
        CODEC_TYPE_FLAC => AudioFormat::Flac,
        CODEC_TYPE_VORBIS => AudioFormat::Ogg,
        CODEC_TYPE_AAC => AudioFormat::M4a,
        c if symphonia::default::get_codecs()
            .get_codec(c)
            .is_some_and(|d| d.short_name.starts_with("pcm") || d.short_name.starts_with("adpcm")) =>
        {
            AudioFormat::Wav
        }
        other => return Err(AudioError::Undecodable(format!("unsupported codec {other}"))),
    })
}

fn check_rate(sr: u32) -> Result<(), AudioError> {
    if (MIN_SAMPLE_RATE..=MAX_SAMPLE_RATE).contains(&sr) {
        Ok(())
    } else {
        Err(AudioError::UnsupportedSampleRate(sr))
    }
}

/// The duration a header declares, in seconds.
fn declared_seconds(params: &CodecParameters) -> Option<f64> {
    let frames = params.n_frames?;
    let seconds = match (params.time_base, params.sample_rate) {
        (Some(tb), _) if tb.denom > 0 => {
            let t = tb.calc_time(frames);
            t.seconds as f64 + t.frac
        }
        (_, Some(sr)) if sr > 0 => frames as f64 / f64::from(sr),
        _ => return None,
    };
    seconds.is_finite().then_some(seconds)
}

fn decode_source(
    source: Box<dyn MediaSource>,
    hint: Hint,
    edit: Option<Mp4Edit>,
    options: &DecodeOptions,
) -> Result<Decoded, AudioError> {
    let budget = options.budget;
    let max_s = options.max_duration_s;
    let mss = MediaSourceStream::new(source, Default::default());
    let fmt_opts = FormatOptions { enable_gapless: true, ..Default::default() };
    let probed = symphonia::default::get_probe()
        .format(&hint, mss, &fmt_opts, &MetadataOptions::default())
        .map_err(undecodable)?;
    let mut reader = probed.format;
    let track = reader
        .tracks()
        .iter()
        .find(|t| t.codec_params.codec != CODEC_TYPE_NULL)
        .ok_or_else(|| AudioError::Undecodable("no audio track".into()))?;
    let track_id = track.id;
    let params = track.codec_params.clone();
    let format = format_of(params.codec)?;
    // What the header says is refused before a single packet is decoded.
    let declared_s = declared_seconds(&params);
    if let Some(rate) = params.sample_rate {
        check_rate(rate)?;
    }
    if let Some(seconds) = declared_s {
        if seconds > max_s + DECLARED_SLACK_S {
            return Err(AudioError::TooLong { seconds, limit: max_s });
        }
    }
    let mut decoder = symphonia::default::get_codecs()
        .make(&params, &DecoderOptions::default())
        .map_err(undecodable)?;

    let mut native_sr = params.sample_rate.unwrap_or(0);
    let mut channels = params.channels.map(|c| c.count() as u16).unwrap_or(0);
    // Leading samples to drop (AAC priming) and how many to keep, from the MP4 edit list.
    let (mut skip, mut keep) = match (format, edit) {
        (AudioFormat::M4a, Some(e)) if native_sr > 0 => e.to_samples(native_sr),
        _ => (0, None),
    };
    let mut sink: Option<MonoSink> = None;
    let mut sample_buf: Option<SampleBuffer<f32>> = None;
    let mut mono: Vec<f32> = Vec::new();
    let mut native_len: u64 = 0;
    // Samples past which the song is too long, fixed once the rate is known.
    let mut max_len: u64 = u64::MAX;

    loop {
        budget.check("decoding")?;
        let packet = match reader.next_packet() {
            Ok(p) => p,
            Err(SymError::IoError(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(SymError::ResetRequired) => break,
            Err(e) => {
                // A stream cut short after good audio is still a song; fail only if nothing came out.
                if native_len > 0 { break; }
                return Err(undecodable(e));
            }
        };
        if packet.track_id() != track_id {
            continue;
        }
        let decoded = match decoder.decode(&packet) {
            Ok(d) => d,
            // One corrupt frame is skipped, as players do.
            Err(SymError::DecodeError(_)) => continue,
            Err(SymError::IoError(_)) => continue,
            Err(e) => return Err(undecodable(e)),
        };
        let spec = *decoded.spec();
        if native_sr == 0 { native_sr = spec.rate; }
        if channels == 0 { channels = spec.channels.count() as u16; }
        if sink.is_none() {
            check_rate(native_sr)?;
            max_len = (max_s * f64::from(native_sr)).floor() as u64;
            sink = Some(MonoSink::new(native_sr, options.keep)?);
        }
        let n_ch = spec.channels.count().max(1);
        let buf = sample_buf.get_or_insert_with(|| SampleBuffer::new(decoded.capacity() as u64, spec));
        if buf.capacity() < decoded.capacity() * n_ch {
            *buf = SampleBuffer::new(decoded.capacity() as u64, spec);
        }
        buf.copy_interleaved_ref(decoded);
        mono.clear();
        let inv = 1.0 / n_ch as f32;
        for frame in buf.samples().chunks_exact(n_ch) {
            mono.push(frame.iter().sum::<f32>() * inv);
        }
        let mut slice = &mono[..];
        if skip > 0 {
            let s = skip.min(slice.len() as u64) as usize;
            slice = &slice[s..];
            skip -= s as u64;
        }
        if let Some(k) = keep.as_mut() {
            let n = (*k).min(slice.len() as u64) as usize;
            slice = &slice[..n];
            *k -= n as u64;
        }
        native_len += slice.len() as u64;
        if native_len > max_len {
            return Err(AudioError::TooLong { seconds: native_len as f64 / f64::from(native_sr), limit: max_s });
        }
        // Checked here, where the native samples pass, so a decode that keeps none checks too.
        if slice.iter().any(|x| !x.is_finite()) {
            return Err(AudioError::NonFinite);
        }
        if let Some(s) = sink.as_mut() { s.push(slice)?; }
    }
    let sink = sink.ok_or(AudioError::Empty)?;
    if native_len == 0 {
        return Err(AudioError::Empty);
    }
    let (samples, sample_rate) = sink.finish()?;
    let audio = DecodedAudio { format, sample_rate, channels, duration_s: native_len as f64 / f64::from(native_sr), samples };
    Ok(Decoded { audio, declared_s })
}

/// Collects mono audio as [`Keep`] asks, resampling on the fly when the rates differ.
struct MonoSink {
    out: Vec<f32>,
    stream: Option<StreamResampler>,
    sr_out: u32,
    store: bool,
}

impl MonoSink {
    fn new(sr_in: u32, keep: Keep) -> Result<Self, AudioError> {
        let (sr_out, store) = match keep {
            Keep::Nothing => (sr_in, false),
            Keep::Native => (sr_in, true),
            Keep::At(sr) => (sr, true),
            Keep::AtMost(sr) => (sr_in.min(sr), true),
        };
        if sr_out == 0 {
            return Err(AudioError::UnsupportedSampleRate(0));
        }
        let stream = if sr_in == sr_out || !store { None } else { Some(StreamResampler::new(sr_in, sr_out)?) };
        Ok(Self { out: Vec::new(), stream, sr_out, store })
    }

    fn push(&mut self, x: &[f32]) -> Result<(), AudioError> {
        if !self.store {
            return Ok(());
        }
        match self.stream.as_mut() {
            None => { self.out.extend_from_slice(x); Ok(()) }
            Some(s) => s.push(x, &mut self.out),
        }
    }

    fn finish(mut self) -> Result<(Vec<f32>, u32), AudioError> {
        if let Some(s) = self.stream.take() {
            s.finish(&mut self.out)?;
        }
        self.out.shrink_to_fit();
        Ok((self.out, self.sr_out))
    }
}

/// Streaming resampler: the soxr_hq-like polyphase FIR when the ratio is a small fraction,
/// rubato's FFT resampler otherwise.
enum StreamResampler {
    Poly(PolyResampler),
    Rubato(RubatoResampler),
}

impl StreamResampler {
    fn new(sr_in: u32, sr_out: u32) -> Result<Self, AudioError> {
        match PolyResampler::new(sr_in, sr_out) {
            Some(p) => Ok(Self::Poly(p)),
            None => Ok(Self::Rubato(RubatoResampler::new(sr_in, sr_out)?)),
        }
    }

    fn push(&mut self, x: &[f32], out: &mut Vec<f32>) -> Result<(), AudioError> {
        match self {
            Self::Poly(p) => {
                p.push(x, out);
                Ok(())
            }
            Self::Rubato(r) => r.push(x, out),
        }
    }

    fn finish(self, out: &mut Vec<f32>) -> Result<(), AudioError> {
        match self {
            Self::Poly(p) => {
                p.finish(out);
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
struct PolyResampler {
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
                let sinc = if x == 0.0 { 2.0 * fc } else { (2.0 * std::f64::consts::PI * fc * x).sin() / (std::f64::consts::PI * x) };
                let w = bessel_i0(beta * (1.0 - (x / half_len).powi(2)).max(0.0).sqrt()) / i0b;
                // Stored reversed so the dot product runs forward over the input.
                branches[p * taps + (taps - 1 - i)] = (sinc * w * l as f64) as f32;
            }
        }
        Some(Self { l, m, r, branches, buf: Vec::new(), buf_start: 0, next_out: 0, total_in: 0 })
    }

    fn taps(&self) -> usize {
        2 * self.r + 1
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

/// Dot product with eight accumulators so it vectorises.
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
struct RubatoResampler {
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
        Ok(Self { inner, pending: Vec::new(), delay_left, total_in: 0, total_out: 0, sr_in, sr_out })
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
            if self.pending.len() - start < need { break; }
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
        let expected = (self.total_in as u128 * self.sr_out as u128).div_ceil(self.sr_in as u128) as u64;
        let mut first = true;
        // Flush with zeros until the delayed tail is out; bounded by delay + one chunk.
        let mut guard = 0;
        while self.total_out < expected && guard < 64 {
            let pending = std::mem::take(&mut self.pending);
            let input: Option<&[&[f32]]> = if first && !pending.is_empty() { Some(&[&pending[..]]) } else { None };
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

/// Resamples a whole mono signal (returns a copy when the rates match).
pub fn resample(x: &[f32], sr_in: u32, sr_out: u32) -> Result<Vec<f32>, AudioError> {
    if sr_in == 0 || sr_out == 0 {
        return Err(AudioError::UnsupportedSampleRate(sr_in.min(sr_out)));
    }
    if sr_in == sr_out {
        return Ok(x.to_vec());
    }
    let mut sink = MonoSink::new(sr_in, Keep::At(sr_out))?;
    for chunk in x.chunks(1 << 16) {
        sink.push(chunk)?;
    }
    Ok(sink.finish()?.0)
}

/// The first edit of an MP4 audio track: where the audio starts, and how long it runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mp4Edit {
    /// Start of presentation in media timescale units (the encoder delay).
    pub media_time: u64,
    /// Media timescale (usually the sample rate).
    pub media_timescale: u32,
    /// Presented duration in movie timescale units (0: to the end).
    pub segment_duration: u64,
    /// Movie timescale.
    pub movie_timescale: u32,
}

impl Mp4Edit {
    fn to_samples(self, sr: u32) -> (u64, Option<u64>) {
        // u128 cannot overflow here (u64 × u32); a result past u64 saturates.
        let scale = |v: u64, ts: u32| u64::try_from(u128::from(v) * u128::from(sr) / u128::from(ts)).unwrap_or(u64::MAX);
        let skip = if self.media_timescale > 0 { scale(self.media_time, self.media_timescale) } else { 0 };
        let keep = (self.segment_duration > 0 && self.movie_timescale > 0).then(|| scale(self.segment_duration, self.movie_timescale));
        (skip, keep)
    }
}

/// Largest `moov` box read for its edit list. Real ones hold a sample table of a few bytes per
/// packet: about 1 MB for the longest song accepted.
const MAX_MOOV_BYTES: u64 = 16 << 20;
/// Most top-level boxes looked at before the `moov`; real files have a handful (ftyp, free,
/// mdat, moov, udta), and each look is a seek and a read.
const MAX_TOP_LEVEL_BOXES: usize = 1024;

/// A box header: total size (0 resolved by the caller), type, and header length.
fn read_box_header<R: Read>(r: &mut R) -> std::io::Result<(u64, [u8; 4], u64)> {
    let mut h = [0u8; 8];
    r.read_exact(&mut h)?;
    let size32 = u64::from(u32::from_be_bytes([h[0], h[1], h[2], h[3]]));
    let kind = [h[4], h[5], h[6], h[7]];
    if size32 == 1 {
        let mut l = [0u8; 8];
        r.read_exact(&mut l)?;
        Ok((u64::from_be_bytes(l), kind, 16))
    } else {
        Ok((size32, kind, 8))
    }
}

/// Reads the edit list of the first sound track of an MP4/M4A file; `None` for other files,
/// and for files whose boxes do not add up (the decoder then judges them).
///
/// Every size comes from the file, so each is checked against the bytes actually present before
/// it moves the position or sizes an allocation: the position only grows (a box is at least its
/// header), it never passes the end, and at most [`MAX_TOP_LEVEL_BOXES`] are visited.
pub fn mp4_edit<R: Read + Seek>(r: &mut R) -> std::io::Result<Option<Mp4Edit>> {
    let end = r.seek(SeekFrom::End(0))?;
    let mut pos = 0u64;
    for _ in 0..MAX_TOP_LEVEL_BOXES {
        let left = end.saturating_sub(pos);
        if left < 8 {
            return Ok(None);
        }
        r.seek(SeekFrom::Start(pos))?;
        let (size, kind, hdr) = read_box_header(r)?;
        let size = if size == 0 { left } else { size };
        if size < hdr || size > left {
            return Ok(None);
        }
        if &kind == b"moov" {
            let len = size - hdr;
            if len > MAX_MOOV_BYTES {
                return Ok(None);
            }
            // `len` is at most what is left of the file, so this allocation is backed by bytes.
            let mut body = vec![0u8; usize::try_from(len).unwrap_or(0)];
            r.read_exact(&mut body)?;
            return Ok(parse_moov(&body));
        }
        if pos == 0 && &kind != b"ftyp" {
            return Ok(None);
        }
        pos += size; // size <= left = end - pos: no overflow.
    }
    Ok(None)
}

/// The child boxes of a box body. Stops at the first child whose size does not fit.
fn children(body: &[u8]) -> Vec<([u8; 4], &[u8])> {
    let mut out = Vec::new();
    let mut rest = body;
    while let (Some(size32), Some(kind)) = (be_u32(rest, 0), rest.get(4..8)) {
        let kind = [kind[0], kind[1], kind[2], kind[3]];
        let (size, hdr) = match size32 {
            0 => (rest.len() as u64, 8usize),
            1 => match be_u64(rest, 8) {
                Some(size) => (size, 16),
                None => break,
            },
            size => (u64::from(size), 8),
        };
        // `size <= rest.len()` makes the cast exact; `size >= hdr` makes progress.
        if size < hdr as u64 || size > rest.len() as u64 {
            break;
        }
        let size = size as usize;
        out.push((kind, &rest[hdr..size]));
        rest = &rest[size..];
    }
    out
}

fn be_u32(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at.checked_add(4)?).map(|s| u32::from_be_bytes([s[0], s[1], s[2], s[3]]))
}

fn be_u64(b: &[u8], at: usize) -> Option<u64> {
    b.get(at..at.checked_add(8)?).map(|s| {
        let mut a = [0u8; 8];
        a.copy_from_slice(s);
        u64::from_be_bytes(a)
    })
}

/// (timescale) of an mvhd/mdhd full box: version 0 at byte 12, version 1 at byte 20.
fn header_timescale(b: &[u8]) -> Option<u32> {
    match b.first()? {
        0 => be_u32(b, 12),
        _ => be_u32(b, 20),
    }
}

fn parse_moov(moov: &[u8]) -> Option<Mp4Edit> {
    let kids = children(moov);
    let movie_timescale = kids.iter().find(|(k, _)| k == b"mvhd").and_then(|(_, b)| header_timescale(b))?;
    for (_, trak) in kids.iter().filter(|(k, _)| k == b"trak") {
        let tk = children(trak);
        let mdia = tk.iter().find(|(k, _)| k == b"mdia").map(|(_, b)| children(b))?;
        let is_sound = mdia.iter().any(|(k, b)| k == b"hdlr" && b.get(8..12) == Some(b"soun"));
        if !is_sound { continue; }
        let media_timescale = mdia.iter().find(|(k, _)| k == b"mdhd").and_then(|(_, b)| header_timescale(b))?;
        let edts = tk.iter().find(|(k, _)| k == b"edts").map(|(_, b)| children(b))?;
        let elst = edts.iter().find(|(k, _)| k == b"elst").map(|(_, b)| *b)?;
        let version = *elst.first()?;
        let entry = if version == 1 { 20 } else { 12 };
        // The declared count is believed only as far as the box holds entries.
        let count = (be_u32(elst, 4)? as usize).min(elst.len().saturating_sub(8) / entry);
        for e in 0..count {
            let at = 8 + e * entry;
            let (dur, mt) = if version == 1 {
                (be_u64(elst, at)?, be_u64(elst, at + 8)? as i64)
            } else {
                (u64::from(be_u32(elst, at)?), i64::from(be_u32(elst, at + 4)? as i32))
            };
            // media_time -1 is an empty edit (a gap); the first real edit says where audio starts.
            if mt >= 0 {
                return Some(Mp4Edit { media_time: mt as u64, media_timescale, segment_duration: dur, movie_timescale });
            }
        }
        return None;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mp4_box(kind: &[u8; 4], body: &[u8]) -> Vec<u8> {
        let mut b = ((body.len() + 8) as u32).to_be_bytes().to_vec();
        b.extend_from_slice(kind);
        b.extend_from_slice(body);
        b
    }

    fn ftyp() -> Vec<u8> {
        mp4_box(b"ftyp", b"M4A \0\0\0\0M4A ")
    }

    /// A `moov` with one sound track whose edit list starts at `media_time`.
    fn moov(media_time: u32, elst_count: u32) -> Vec<u8> {
        let mut mvhd = vec![0u8; 100];
        mvhd[12..16].copy_from_slice(&1000u32.to_be_bytes());
        let mut mdhd = vec![0u8; 24];
        mdhd[12..16].copy_from_slice(&44_100u32.to_be_bytes());
        let mut hdlr = vec![0u8; 24];
        hdlr[8..12].copy_from_slice(b"soun");
        let mut elst = vec![0u8; 8];
        elst[4..8].copy_from_slice(&elst_count.to_be_bytes());
        elst.extend_from_slice(&5000u32.to_be_bytes());
        elst.extend_from_slice(&media_time.to_be_bytes());
        elst.extend_from_slice(&0x0001_0000u32.to_be_bytes());
        let mdia = [mp4_box(b"hdlr", &hdlr), mp4_box(b"mdhd", &mdhd)].concat();
        let trak = [mp4_box(b"edts", &mp4_box(b"elst", &elst)), mp4_box(b"mdia", &mdia)].concat();
        mp4_box(b"moov", &[mp4_box(b"mvhd", &mvhd), mp4_box(b"trak", &trak)].concat())
    }

    /// The hostile file of issue 11, byte for byte.
    pub(crate) fn the_40_byte_m4a() -> Vec<u8> {
        let mut b = mp4_box(b"ftyp", b"M4A \0\0\0\0");
        b.extend_from_slice(&1u32.to_be_bytes());
        b.extend_from_slice(b"mdat");
        b.extend_from_slice(&(u64::MAX - 15).to_be_bytes());
        b.extend_from_slice(&[0u8; 8]);
        b
    }

    fn edit(bytes: &[u8]) -> Option<Mp4Edit> {
        mp4_edit(&mut Cursor::new(bytes)).unwrap_or(None)
    }

    #[test]
    fn reads_the_edit_list() {
        let file = [ftyp(), moov(2112, 1)].concat();
        let e = edit(&file).expect("an edit");
        assert_eq!((e.media_time, e.media_timescale, e.segment_duration, e.movie_timescale), (2112, 44_100, 5000, 1000));
        assert_eq!(e.to_samples(44_100), (2112, Some(220_500)));
        // A count larger than the box holds reads the entries that are there.
        assert_eq!(edit(&[ftyp(), moov(2112, u32::MAX)].concat()).map(|e| e.media_time), Some(2112));
    }

    #[test]
    fn sizes_from_the_file_cannot_loop_overflow_or_over_allocate() {
        // The 40-byte file that once looped for ever: a 16-byte ftyp, then a box whose 64-bit
        // size is 2^64 - 16, which took the position back to 0.
        let wrap = the_40_byte_m4a();
        assert_eq!(wrap.len(), 40);
        assert_eq!(edit(&wrap), None);
        // Sizes that wrap the position to the start, to the box itself, or do not cover a header.
        for size in [u64::MAX - 23, u64::MAX - 15, u64::MAX, 16, 8, 1, 2, 7] {
            let mut b = ftyp();
            b.extend_from_slice(&1u32.to_be_bytes());
            b.extend_from_slice(b"free");
            b.extend_from_slice(&size.to_be_bytes());
            assert_eq!(edit(&b), None, "size {size}");
        }
        // A 4 GB moov header in a small file allocates nothing.
        let mut big = ftyp();
        big.extend_from_slice(&u32::MAX.to_be_bytes());
        big.extend_from_slice(b"moov");
        big.extend_from_slice(&[0u8; 64]);
        assert_eq!(edit(&big), None);
        // A child with a 2^64 size inside a real moov.
        let mut m = moov(2112, 1);
        let at = 8;
        m[at..at + 4].copy_from_slice(&1u32.to_be_bytes());
        m.splice(at + 8..at + 8, u64::MAX.to_be_bytes());
        let size = m.len() as u32;
        m[0..4].copy_from_slice(&size.to_be_bytes());
        assert_eq!(edit(&[ftyp(), m].concat()), None);
        // Many empty boxes: visited a bounded number of times.
        let mut many = ftyp();
        for _ in 0..100_000 {
            many.extend_from_slice(&mp4_box(b"free", &[]));
        }
        many.extend_from_slice(&moov(2112, 1));
        assert_eq!(edit(&many), None);
        // Every truncation of a good file.
        let good = [ftyp(), moov(2112, 1)].concat();
        for n in 0..good.len() {
            let _ = edit(&good[..n]);
        }
    }
}
