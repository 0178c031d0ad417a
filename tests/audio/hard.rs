//! Hard audio: synthesised WAV files (silence, offsets and clipping, channel layouts, sample
//! rates, tiny, broken and very long inputs), no ../shared needed.
use super::*;

/// Sample encodings for synthetic WAV files.
#[derive(Clone, Copy)]
enum WavKind {
    Pcm16,
    Float32,
}

/// Writes interleaved samples as WAV (WAVE_FORMAT_EXTENSIBLE above two channels).
fn write_wav(path: &std::path::Path, sr: u32, channels: u16, interleaved: &[f32], kind: WavKind) {
    let (bits, tag) = match kind {
        WavKind::Pcm16 => (16u16, 1u16),
        WavKind::Float32 => (32u16, 3u16),
    };
    let block = channels as u32 * bits as u32 / 8;
    let data_len = interleaved.len() as u32 * bits as u32 / 8;
    let ext = channels > 2;
    let fmt_len: u32 = if ext { 40 } else { 16 };
    let mut b: Vec<u8> = Vec::with_capacity(data_len as usize + 80);
    b.extend_from_slice(b"RIFF");
    b.extend_from_slice(&(4 + 8 + fmt_len + 8 + data_len).to_le_bytes());
    b.extend_from_slice(b"WAVEfmt ");
    b.extend_from_slice(&fmt_len.to_le_bytes());
    b.extend_from_slice(&(if ext { 0xFFFEu16 } else { tag }).to_le_bytes());
    b.extend_from_slice(&channels.to_le_bytes());
    b.extend_from_slice(&sr.to_le_bytes());
    b.extend_from_slice(&(sr * block).to_le_bytes());
    b.extend_from_slice(&(block as u16).to_le_bytes());
    b.extend_from_slice(&bits.to_le_bytes());
    if ext {
        b.extend_from_slice(&22u16.to_le_bytes());
        b.extend_from_slice(&bits.to_le_bytes());
        let mask: u32 = (1u32 << channels) - 1;
        b.extend_from_slice(&mask.to_le_bytes());
        // KSDATAFORMAT_SUBTYPE_PCM / _IEEE_FLOAT GUID: tag, then the fixed suffix.
        b.extend_from_slice(&(tag as u32).to_le_bytes());
        b.extend_from_slice(&[
            0x00, 0x00, 0x10, 0x00, 0x80, 0x00, 0x00, 0xAA, 0x00, 0x38, 0x9B, 0x71,
        ]);
    }
    b.extend_from_slice(b"data");
    b.extend_from_slice(&data_len.to_le_bytes());
    for &v in interleaved {
        match kind {
            WavKind::Pcm16 => {
                b.extend_from_slice(&((v.clamp(-1.0, 1.0) * 32767.0).round() as i16).to_le_bytes())
            }
            WavKind::Float32 => b.extend_from_slice(&v.to_le_bytes()),
        }
    }
    std::fs::write(path, b).expect("write wav");
}

/// Deterministic white noise in [-1, 1].
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

/// A click track: a decaying noise burst plus a 60 Hz kick at `bpm` from `t0`; accents every
/// `meter` beats carry a louder kick and a new chord (for downbeat tests). Returns the signal
/// and the true beat and downbeat times.
pub fn click_track(
    sr: u32,
    seconds: f64,
    bpm: f64,
    meter: usize,
    t0: f64,
) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
    let n = (seconds * sr as f64) as usize;
    let mut y = vec![0.0f32; n];
    let mut rng = Lcg(7);
    for v in y.iter_mut() {
        *v = 0.01 * rng.next();
    }
    let period = 60.0 / bpm;
    let (mut beats, mut downs) = (Vec::new(), Vec::new());
    let chords = [
        [261.6, 329.6, 392.0],
        [349.2, 440.0, 523.3],
        [392.0, 493.9, 587.3],
        [220.0, 261.6, 329.6],
    ];
    let mut k = 0usize;
    loop {
        let t = t0 + k as f64 * period;
        if t >= seconds - 0.05 {
            break;
        }
        beats.push(t);
        let accent = k.is_multiple_of(meter);
        if accent {
            downs.push(t);
        }
        let start = (t * sr as f64) as usize;
        let chord = chords[(k / meter) % chords.len()];
        let kick = if accent { 0.8 } else { 0.3 };
        for i in 0..((period * sr as f64) as usize).min(n - start) {
            let s = i as f64 / sr as f64;
            let burst = if s < 0.03 {
                0.5 * rng.next() * (-s / 0.005).exp() as f32
            } else {
                0.0
            };
            let bass =
                (kick * (2.0 * std::f64::consts::PI * 60.0 * s).sin() * (-s / 0.08).exp()) as f32;
            let pad: f32 = chord
                .iter()
                .map(|f| (0.05 * (2.0 * std::f64::consts::PI * f * s).sin()) as f32)
                .sum();
            y[start + i] += burst + bass + pad;
        }
        k += 1;
    }
    (y, beats, downs)
}

fn interleave(mono: &[f32], channels: u16) -> Vec<f32> {
    mono.iter()
        .flat_map(|&v| std::iter::repeat_n(v, channels as usize))
        .collect()
}

fn assert_finite_features(a: &DecodedAudio, what: &str) {
    let n = (a.duration_s * 25.0).ceil() as usize + 1;
    let dr = features::dance_revolution(a, 25.0, n).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(dr.dim(), (n, 438), "{what}");
    assert!(
        dr.iter().all(|v| v.is_finite()),
        "{what}: NaN/inf in DanceRevolution features"
    );
    for (name, x) in [
        ("dancenet", features::dancenet(a, 25.0, 0.0, n)),
        ("keypose", features::keypose(a, 25.0, 0.0, n)),
        ("tsmt", features::tsmt(a, 25.0, 0.0, n)),
    ] {
        let x = x.unwrap_or_else(|e| panic!("{what} {name}: {e}"));
        assert_eq!(x.nrows(), n, "{what} {name}");
        assert!(x.iter().all(|v| v.is_finite()), "{what} {name}: NaN/inf");
    }
}

#[test]
fn silence_gives_no_beats_and_finite_features() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("silence.wav");
    write_wav(&p, 44_100, 2, &vec![0.0; 44_100 * 2 * 5], WavKind::Pcm16);
    let a = audio::decode_path(&p).expect("decodes");
    let an = audio::analyze(&a).expect("analyze");
    assert_eq!(an.tempo_bpm, 0.0);
    assert!(an.beat_times.is_empty() && an.downbeat_times.is_empty());
    assert_finite_features(&a, "silence");
}

#[test]
fn dc_offset_and_clipping_keep_the_beat() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (y, truth, _) = click_track(44_100, 12.0, 120.0, 4, 0.25);
    for (name, signal) in [
        ("dc", y.iter().map(|v| v * 0.5 + 0.4).collect::<Vec<f32>>()),
        (
            "clipped",
            y.iter()
                .map(|v| (v * 20.0).clamp(-1.0, 1.0))
                .collect::<Vec<f32>>(),
        ),
        ("dc-only", vec![0.5f32; 44_100 * 3]),
    ] {
        let p = dir.path().join(format!("{name}.wav"));
        write_wav(&p, 44_100, 1, &signal, WavKind::Pcm16);
        let a = audio::decode_path(&p).expect("decodes");
        let an = audio::analyze(&a).expect("analyze");
        assert!(
            an.tempo_bpm.is_finite() && an.beat_times.iter().all(|t| t.is_finite()),
            "{name}"
        );
        if name != "dc-only" {
            let f = f_measure(&truth, &an.beat_times, 0.07);
            eprintln!("{name}: tempo {:.1}, beat F vs truth {f:.3}", an.tempo_bpm);
            assert!(f > 0.9, "{name}: beat F {f}");
        }
        assert_finite_features(&a, name);
    }
}

#[test]
fn mono_stereo_and_5_1_downmix_to_the_same_signal() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (y, _, _) = click_track(48_000, 4.0, 120.0, 4, 0.25);
    let mut reference: Option<Vec<f32>> = None;
    for channels in [1u16, 2, 6] {
        let p = dir.path().join(format!("c{channels}.wav"));
        write_wav(
            &p,
            48_000,
            channels,
            &interleave(&y, channels),
            WavKind::Float32,
        );
        let a = audio::decode_path(&p).expect("decodes");
        assert_eq!(a.channels, channels);
        assert_eq!(a.samples.len(), y.len());
        match &reference {
            None => reference = Some(a.samples.clone()),
            Some(r) => {
                let d = r
                    .iter()
                    .zip(&a.samples)
                    .map(|(x, z)| (x - z).abs())
                    .fold(0.0f32, f32::max);
                assert!(d < 1e-6, "{channels} channels differ by {d}");
            }
        }
        assert!(!audio::analyze(&a).expect("analyze").beat_times.is_empty());
    }
    // A 5.1 file whose channels differ downmixes to their mean (librosa `to_mono`).
    let p = dir.path().join("mixed.wav");
    let inter: Vec<f32> = (0..1000)
        .flat_map(|i| (0..6).map(move |c| (c as f32 - 2.5) * 0.1 + (i as f32 * 0.01).sin() * 0.1))
        .collect();
    write_wav(&p, 48_000, 6, &inter, WavKind::Float32);
    let a = audio::decode_path(&p).expect("decodes");
    for (i, v) in a.samples.iter().enumerate() {
        let mean: f32 = inter[i * 6..i * 6 + 6].iter().sum::<f32>() / 6.0;
        assert!((v - mean).abs() < 1e-6);
    }
}

#[test]
fn sample_rates_from_8_to_96_khz() {
    let dir = tempfile::tempdir().expect("tempdir");
    for sr in [
        8_000u32, 11_025, 16_000, 22_050, 32_000, 44_100, 48_000, 88_200, 96_000,
    ] {
        let (y, truth, _) = click_track(sr, 10.0, 120.0, 4, 0.25);
        let p = dir.path().join(format!("sr{sr}.wav"));
        write_wav(&p, sr, 2, &interleave(&y, 2), WavKind::Pcm16);
        let a = audio::decode_path(&p).expect("decodes");
        assert_eq!(a.sample_rate, sr);
        assert!((a.duration_s - 10.0).abs() < 1e-3);
        let an = audio::analyze(&a).expect("analyze");
        let f = f_measure(&truth, &an.beat_times, 0.07);
        eprintln!("{sr} Hz: tempo {:.1}, beat F vs truth {f:.3}", an.tempo_bpm);
        assert!(f > 0.9, "{sr} Hz: beat F {f}");
        // Resampled while decoding: same length as resampling afterwards.
        let b = audio::decode_path_at(&p, Some(12_800)).expect("decodes at 12.8 kHz");
        assert_eq!(b.sample_rate, 12_800);
        assert_eq!(
            b.samples.len(),
            (y.len() as u64 * 12_800).div_ceil(sr as u64) as usize
        );
        assert_finite_features(&b, &format!("{sr} Hz"));
    }
}

#[test]
fn one_second_song_and_tiny_inputs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (y, _, _) = click_track(44_100, 1.0, 120.0, 4, 0.1);
    let p = dir.path().join("one.wav");
    write_wav(&p, 44_100, 2, &interleave(&y, 2), WavKind::Pcm16);
    let a = audio::decode_path(&p).expect("decodes");
    let an = audio::analyze(&a).expect("analyze");
    assert!(an.tempo_bpm.is_finite());
    assert_finite_features(&a, "1 s");
    // Ten samples: still a result, not a panic.
    let p = dir.path().join("ten.wav");
    write_wav(&p, 44_100, 1, &y[..10], WavKind::Pcm16);
    let a = audio::decode_path(&p).expect("decodes");
    assert!(audio::analyze(&a).is_ok());
    assert_finite_features(&a, "10 samples");
    // More rows than the song has: padded with the features of silence.
    let x = features::dance_revolution(&a, 25.0, 50).expect("padded");
    assert_eq!(x.nrows(), 50);
}

#[test]
fn bad_input_gives_clear_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("garbage.mp3");
    std::fs::write(&p, b"this is not audio at all, just some text pretending").expect("write");
    assert!(matches!(
        audio::decode_path(&p),
        Err(audio::AudioError::Undecodable(_))
    ));
    let p = dir.path().join("empty.wav");
    write_wav(&p, 44_100, 2, &[], WavKind::Pcm16);
    let e = audio::decode_path(&p);
    assert!(
        matches!(
            e,
            Err(audio::AudioError::Empty) | Err(audio::AudioError::Undecodable(_))
        ),
        "{e:?}"
    );
    let p = dir.path().join("nan.wav");
    write_wav(&p, 44_100, 1, &[0.0, f32::NAN, 0.1, 0.2], WavKind::Float32);
    assert!(matches!(
        audio::decode_path(&p),
        Err(audio::AudioError::NonFinite)
    ));
    assert!(matches!(
        audio::decode_path(&dir.path().join("missing.wav")),
        Err(audio::AudioError::Io(_))
    ));
    let p = dir.path().join("long.wav");
    write_wav(&p, 4_000, 1, &vec![0.0; 4_000 * 60 * 31], WavKind::Pcm16);
    assert!(matches!(
        audio::decode_path(&p),
        Err(audio::AudioError::TooLong { .. })
    ));
    let a = DecodedAudio {
        format: audio::AudioFormat::Wav,
        sample_rate: 44_100,
        channels: 1,
        duration_s: 1.0,
        samples: vec![0.0; 44_100],
    };
    assert!(matches!(
        features::dance_revolution(&a, 25.3, 10),
        Err(audio::AudioError::InvalidParameter(_))
    ));
    assert!(matches!(
        features::dancenet(&a, 25.0, -1.0, 10),
        Err(audio::AudioError::InvalidParameter(_))
    ));
    assert!(matches!(
        features::tsmt(&a, 25.0, 0.0, 0),
        Err(audio::AudioError::InvalidParameter(_))
    ));
}

#[test]
fn fifteen_minute_song_streams_and_stays_finite() {
    let dir = tempfile::tempdir().expect("tempdir");
    let sr = 22_050;
    let (y, truth, _) = click_track(sr, 15.0 * 60.0, 126.0, 4, 0.3);
    let p = dir.path().join("long.wav");
    write_wav(&p, sr, 2, &interleave(&y, 2), WavKind::Pcm16);
    drop(y);
    let a = audio::decode_path_at(&p, Some(12_800)).expect("decodes");
    assert!((a.duration_s - 900.0).abs() < 1e-3);
    let n = 900 * 25;
    let x = features::dance_revolution(&a, 25.0, n).expect("features");
    assert_eq!(x.dim(), (n, 438));
    assert!(x.iter().all(|v| v.is_finite()));
    let beats: Vec<f64> = (0..n)
        .filter(|&i| x[[i, 437]] > 0.5)
        .map(|i| i as f64 / 25.0)
        .collect();
    let f = f_measure(&truth, &beats, 0.07);
    eprintln!("15 min: {} beats, F vs truth {f:.3}", beats.len());
    assert!(f > 0.9, "beat F {f}");
}
