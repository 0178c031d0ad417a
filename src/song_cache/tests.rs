use super::*;
use crate::audio::AudioFormat;
use std::sync::atomic::AtomicUsize;

/// A 12 s click track at 120 BPM over a quiet tone, at 22 050 Hz.
fn clicks() -> DecodedAudio {
    let sr = 22_050u32;
    let n = 12 * sr as usize;
    let samples = (0..n)
        .map(|i| {
            let t = i as f64 / f64::from(sr);
            let click = if (t % 0.5) < 0.01 { 0.8 } else { 0.0 };
            (click + 0.05 * (t * 440.0 * std::f64::consts::TAU).sin()) as f32
        })
        .collect();
    DecodedAudio {
        format: AudioFormat::Wav,
        sample_rate: sr,
        channels: 1,
        duration_s: 12.0,
        samples,
    }
}

#[test]
fn the_second_job_reads_what_the_first_computed_bit_for_bit() {
    let song = clicks();
    let decodes = AtomicUsize::new(0);
    let decode = |_: &Budget| {
        decodes.fetch_add(1, Ordering::SeqCst);
        Ok(song.clone())
    };
    let files = MemoryFiles::default();
    let budget = Budget::unlimited();

    let first = SongCache::new(&files, &decode, "test", None);
    assert!(!first.is_analysed());
    let analysis = first.analyze_within(&budget).expect("analyses");
    let keypose = first
        .features(FeatureSet::Keypose, 30.0, 0.0, 360)
        .expect("features");
    assert_eq!(decodes.load(Ordering::SeqCst), 1, "decoded once for both");
    assert!(first.stored_bytes() > 0);
    assert_eq!(
        files.names(),
        vec![
            analysis_file(),
            features_file(FeatureSet::Keypose, 30.0, 0.0, 360)
        ]
    );

    let second = SongCache::new(&files, &decode, "test", None);
    assert!(second.is_analysed());
    assert_eq!(second.analyze_within(&budget).expect("read"), analysis);
    assert_eq!(second.duration_s(), song.duration_s);
    let again = second
        .features(FeatureSet::Keypose, 30.0, 0.0, 360)
        .expect("read");
    assert_eq!(
        decodes.load(Ordering::SeqCst),
        1,
        "the second job decodes nothing"
    );
    assert_eq!(second.stored_bytes(), 0);
    let bits = |a: &Array2<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&again), bits(&keypose));

    // What the cache serves is what the decoded song computes.
    assert_eq!(crate::audio::analyze(&song).expect("analyses"), analysis);
    assert_eq!(
        bits(
            &FeatureSet::Keypose
                .compute(&song, 30.0, 0.0, 360)
                .expect("features")
        ),
        bits(&keypose)
    );

    // Another layout, rate or length is another file: computed, after one more decode.
    second
        .features(FeatureSet::Tsmt, 30.0, 0.0, 360)
        .expect("features");
    assert_eq!(decodes.load(Ordering::SeqCst), 2);
}

#[test]
fn names_carry_the_version_layout_rate_start_and_rows() {
    let names = [
        features_file(FeatureSet::Keypose, 30.0, 0.0, 360),
        features_file(FeatureSet::Keypose, 25.0, 0.0, 360),
        features_file(FeatureSet::Keypose, 30.0, 0.5, 360),
        features_file(FeatureSet::Keypose, 30.0, 0.0, 361),
        features_file(FeatureSet::DanceNet, 30.0, 0.0, 360),
        analysis_file(),
    ];
    for (i, a) in names.iter().enumerate() {
        assert!(a.contains(&format!("-v{VERSION}")), "{a}");
        for b in &names[i + 1..] {
            assert_ne!(a, b);
        }
    }
}

#[test]
fn a_file_cut_short_or_of_another_kind_is_refused_and_computed_again() {
    let song = clicks();
    let features = FeatureSet::Tsmt
        .compute(&song, 30.0, 0.0, 100)
        .expect("features");
    let bytes = codec::encode_features(&features);
    assert_eq!(
        codec::decode_features("f", &bytes).expect("round trip"),
        features
    );
    for bad in [
        &bytes[..bytes.len() - 1],
        &bytes[..10],
        b"CHOBEAT1".as_slice(),
    ] {
        let err = codec::decode_features("f", bad).expect_err("refused");
        assert_eq!(err.code(), "song-cache-corrupt");
    }
    let analysis = crate::audio::analyze(&song).expect("analyses");
    let heard = codec::encode_heard(12.0, &analysis);
    assert_eq!(
        codec::decode_heard("a", &heard).expect("round trip"),
        (12.0, analysis)
    );
    assert!(codec::decode_heard("a", &heard[..heard.len() - 8]).is_err());
    assert!(codec::decode_heard("a", &bytes).is_err());

    // A corrupt stored analysis is computed again (and stored over).
    let files = MemoryFiles::default();
    files.put(&analysis_file(), b"CHOBEAT1junk").expect("put");
    let decode = |_: &Budget| Ok(song.clone());
    let cache = SongCache::new(&files, &decode, "test", None);
    assert!(!cache.is_analysed());
    cache
        .analyze_within(&Budget::unlimited())
        .expect("analyses");
    assert!(SongCache::new(&files, &decode, "test", None).is_analysed());
}
