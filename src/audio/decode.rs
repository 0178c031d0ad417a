//! Decoding with symphonia: mono downmix (channel mean, as librosa's `to_mono`), the AAC
//! encoder-delay trim from the MP4 edit list, and streaming resampling so that a long song
//! never exists at its native rate in memory when a lower rate is asked for.
//!
//! Every decode is bounded while it runs, because the file is a stranger's: the sample rate and
//! (where the header declares one) the duration are checked before the first packet; the decoded
//! length is counted as it streams and decoding stops at the limit; a [`Budget`] is checked on
//! every packet; and what is kept ([`Keep`]) never grows with the native rate beyond the caller's
//! choice. The edit list is read by [`super::mp4`], the resampling done by [`super::resample`].
use std::io::{Cursor, Seek, SeekFrom};
use std::path::Path;

use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{self, CodecParameters, DecoderOptions, CODEC_TYPE_NULL};
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::{MediaSource, MediaSourceStream};
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;

use super::mp4::{mp4_edit, Mp4Edit};
use super::resample::StreamResampler;
use super::{
    AudioError, AudioFormat, Budget, DecodedAudio, MAX_DURATION_S, MAX_SAMPLE_RATE, MIN_SAMPLE_RATE,
};
use crate::stage::Stage;

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
    Ok(decode_file(
        path,
        &DecodeOptions {
            keep,
            max_duration_s: MAX_DURATION_S,
            budget: &budget,
        },
    )?
    .audio)
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
        Err(AudioError::Undecodable(format!(
            "the decoder failed on a malformed header: {message}"
        )))
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
            .is_some_and(|d| {
                d.short_name.starts_with("pcm") || d.short_name.starts_with("adpcm")
            }) =>
        {
            AudioFormat::Wav
        }
        other => {
            return Err(AudioError::Undecodable(format!(
                "unsupported codec {other}"
            )))
        }
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
    let fmt_opts = FormatOptions {
        enable_gapless: true,
        ..Default::default()
    };
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
            return Err(AudioError::TooLong {
                seconds,
                limit: max_s,
            });
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
        budget.check(Stage::DecodeAudio)?;
        let packet = match reader.next_packet() {
            Ok(p) => p,
            Err(SymError::IoError(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(SymError::ResetRequired) => break,
            Err(e) => {
                // A stream cut short after good audio is still a song; fail only if nothing came out.
                if native_len > 0 {
                    break;
                }
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
        if native_sr == 0 {
            native_sr = spec.rate;
        }
        if channels == 0 {
            channels = spec.channels.count() as u16;
        }
        if sink.is_none() {
            check_rate(native_sr)?;
            max_len = (max_s * f64::from(native_sr)).floor() as u64;
            sink = Some(MonoSink::new(native_sr, options.keep)?);
        }
        let n_ch = spec.channels.count().max(1);
        let buf =
            sample_buf.get_or_insert_with(|| SampleBuffer::new(decoded.capacity() as u64, spec));
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
            return Err(AudioError::TooLong {
                seconds: native_len as f64 / f64::from(native_sr),
                limit: max_s,
            });
        }
        // Checked here, where the native samples pass, so a decode that keeps none checks too.
        if slice.iter().any(|x| !x.is_finite()) {
            return Err(AudioError::NonFinite);
        }
        if let Some(s) = sink.as_mut() {
            s.push(slice)?;
        }
    }
    let sink = sink.ok_or(AudioError::Empty)?;
    if native_len == 0 {
        return Err(AudioError::Empty);
    }
    let (samples, sample_rate) = sink.finish()?;
    let audio = DecodedAudio {
        format,
        sample_rate,
        channels,
        duration_s: native_len as f64 / f64::from(native_sr),
        samples,
    };
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
        let stream = if sr_in == sr_out || !store {
            None
        } else {
            Some(StreamResampler::new(sr_in, sr_out)?)
        };
        Ok(Self {
            out: Vec::new(),
            stream,
            sr_out,
            store,
        })
    }

    fn push(&mut self, x: &[f32]) -> Result<(), AudioError> {
        if !self.store {
            return Ok(());
        }
        match self.stream.as_mut() {
            None => {
                self.out.extend_from_slice(x);
                Ok(())
            }
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
