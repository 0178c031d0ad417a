//! Decoding with symphonia: mono downmix (channel mean, as librosa's `to_mono`), the AAC
//! encoder-delay trim from the MP4 edit list, and streaming rubato resampling so that a long
//! song never exists at its native rate in memory when a lower rate is asked for.
use std::io::{Cursor, Read, Seek, SeekFrom};
use std::path::Path;

use rubato::{FftFixedIn, Resampler};
use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{self, DecoderOptions, CODEC_TYPE_NULL};
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::{MediaSource, MediaSourceStream};
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;

use super::{AudioError, AudioFormat, DecodedAudio, MAX_DURATION_S, MAX_SAMPLE_RATE, MIN_SAMPLE_RATE};

/// Input chunk (frames) fed to rubato; small so the resampler's buffers stay tiny.
const RESAMPLE_CHUNK: usize = 4096;

/// Decodes a file; with `target_sr` the mono signal is resampled while it streams.
pub fn decode_path_at(path: &Path, target_sr: Option<u32>) -> Result<DecodedAudio, AudioError> {
    let mut file = std::fs::File::open(path)?;
    let edit = mp4_edit(&mut file).unwrap_or(None);
    file.seek(SeekFrom::Start(0))?;
    let mut hint = Hint::new();
    if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
        hint.with_extension(ext);
    }
    decode_source(Box::new(file), hint, edit, target_sr)
}

/// Decodes an in-memory file (an upload); with `target_sr` the signal is resampled.
pub fn decode_bytes(bytes: Vec<u8>, target_sr: Option<u32>) -> Result<DecodedAudio, AudioError> {
    let edit = mp4_edit(&mut Cursor::new(&bytes[..])).unwrap_or(None);
    decode_source(Box::new(Cursor::new(bytes)), Hint::new(), edit, target_sr)
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

fn decode_source(
    source: Box<dyn MediaSource>,
    hint: Hint,
    edit: Option<Mp4Edit>,
    target_sr: Option<u32>,
) -> Result<DecodedAudio, AudioError> {
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

    loop {
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
            if !(MIN_SAMPLE_RATE..=MAX_SAMPLE_RATE).contains(&native_sr) {
                return Err(AudioError::UnsupportedSampleRate(native_sr));
            }
            sink = Some(MonoSink::new(native_sr, target_sr.unwrap_or(native_sr))?);
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
        if native_len as f64 / native_sr as f64 > MAX_DURATION_S {
            return Err(AudioError::TooLong { seconds: native_len as f64 / native_sr as f64, limit: MAX_DURATION_S });
        }
        if let Some(s) = sink.as_mut() { s.push(slice)?; }
    }
    let sink = sink.ok_or(AudioError::Empty)?;
    if native_len == 0 {
        return Err(AudioError::Empty);
    }
    let (samples, sample_rate) = sink.finish()?;
    if samples.iter().any(|x| !x.is_finite()) {
        return Err(AudioError::NonFinite);
    }
    Ok(DecodedAudio {
        format,
        sample_rate,
        channels,
        duration_s: native_len as f64 / native_sr as f64,
        samples,
    })
}

/// Collects mono audio, resampling on the fly when the rates differ.
struct MonoSink {
    out: Vec<f32>,
    stream: Option<StreamResampler>,
    sr_out: u32,
}

impl MonoSink {
    fn new(sr_in: u32, sr_out: u32) -> Result<Self, AudioError> {
        let stream = if sr_in == sr_out { None } else { Some(StreamResampler::new(sr_in, sr_out)?) };
        Ok(Self { out: Vec::new(), stream, sr_out })
    }

    fn push(&mut self, x: &[f32]) -> Result<(), AudioError> {
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
    let mut sink = MonoSink::new(sr_in, sr_out)?;
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
        let skip = if self.media_timescale > 0 {
            (self.media_time as u128 * sr as u128 / self.media_timescale as u128) as u64
        } else { 0 };
        let keep = if self.segment_duration > 0 && self.movie_timescale > 0 {
            Some((self.segment_duration as u128 * sr as u128 / self.movie_timescale as u128) as u64)
        } else { None };
        (skip, keep)
    }
}

fn read_box_header<R: Read>(r: &mut R) -> std::io::Result<(u64, [u8; 4], u64)> {
    let mut h = [0u8; 8];
    r.read_exact(&mut h)?;
    let size32 = u32::from_be_bytes([h[0], h[1], h[2], h[3]]) as u64;
    let kind = [h[4], h[5], h[6], h[7]];
    if size32 == 1 {
        let mut l = [0u8; 8];
        r.read_exact(&mut l)?;
        Ok((u64::from_be_bytes(l), kind, 16))
    } else {
        Ok((size32, kind, 8))
    }
}

/// Reads the edit list of the first sound track of an MP4/M4A file; `None` for other files.
pub fn mp4_edit<R: Read + Seek>(r: &mut R) -> std::io::Result<Option<Mp4Edit>> {
    let end = r.seek(SeekFrom::End(0))?;
    let mut pos = 0u64;
    while pos + 8 <= end {
        r.seek(SeekFrom::Start(pos))?;
        let (size, kind, hdr) = read_box_header(r)?;
        let size = if size == 0 { end - pos } else { size };
        if size < hdr { return Ok(None); }
        if &kind == b"moov" {
            let len = (size - hdr).min(64 << 20) as usize;
            let mut body = vec![0u8; len];
            r.read_exact(&mut body)?;
            return Ok(parse_moov(&body));
        }
        if pos == 0 && &kind != b"ftyp" { return Ok(None); }
        pos += size;
    }
    Ok(None)
}

fn children(body: &[u8]) -> Vec<([u8; 4], &[u8])> {
    let mut out = Vec::new();
    let mut i = 0usize;
    while i + 8 <= body.len() {
        let size = u32::from_be_bytes([body[i], body[i + 1], body[i + 2], body[i + 3]]) as usize;
        let kind = [body[i + 4], body[i + 5], body[i + 6], body[i + 7]];
        let (size, hdr) = if size == 1 && i + 16 <= body.len() {
            let mut l = [0u8; 8];
            l.copy_from_slice(&body[i + 8..i + 16]);
            (u64::from_be_bytes(l) as usize, 16)
        } else if size == 0 { (body.len() - i, 8) } else { (size, 8) };
        if size < hdr || i + size > body.len() { break; }
        out.push((kind, &body[i + hdr..i + size]));
        i += size;
    }
    out
}

fn be_u32(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at + 4).map(|s| u32::from_be_bytes([s[0], s[1], s[2], s[3]]))
}

fn be_u64(b: &[u8], at: usize) -> Option<u64> {
    b.get(at..at + 8).map(|s| {
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
        let count = be_u32(elst, 4)? as usize;
        let entry = if version == 1 { 20 } else { 12 };
        for e in 0..count {
            let at = 8 + e * entry;
            let (dur, mt) = if version == 1 {
                (be_u64(elst, at)?, be_u64(elst, at + 8)? as i64)
            } else {
                (be_u32(elst, at)? as u64, be_u32(elst, at + 4)? as i32 as i64)
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
