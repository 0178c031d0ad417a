//! Hostile files: the decoder answers every file, however crafted, with Ok or an error, quickly,
//! in bounded memory, and never panics or hangs.
//!
//! A mutation loop runs thousands of mutated headers of real mp3, ogg, flac, wav and m4a files
//! (made with ffmpeg from ../shared/audio) through the decoder; the regression tests write the
//! two hostile files (`hostile_files`) byte by byte.
use crate::hostile_files::{silent_flac, the_40_byte_m4a};
use choreo::audio::{self, AudioError, Budget, DecodeOptions, Keep};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Runs `work` on its own thread; a hang fails the test (with `what`) instead of hanging it.
fn within<T: Send + 'static>(
    limit: Duration,
    what: &str,
    work: impl FnOnce() -> T + Send + 'static,
) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(work());
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("{what}: no answer within {limit:?}"))
}

fn options<'a>(keep: Keep, max_duration_s: f64, budget: &'a Budget<'a>) -> DecodeOptions<'a> {
    DecodeOptions {
        keep,
        max_duration_s,
        budget,
    }
}

// ---------------------------------------------------------------------------------------------
// The two hostile files (written by `hostile_files`).

#[test]
fn the_40_byte_m4a_is_refused_at_once() {
    let started = Instant::now();
    let result = within(Duration::from_secs(10), "the 40-byte m4a", || {
        let budget = Budget::unlimited();
        audio::decode_bytes(the_40_byte_m4a(), &options(Keep::Nothing, 900.0, &budget))
            .map(|d| d.audio.duration_s)
    });
    assert!(
        matches!(result, Err(AudioError::Undecodable(_))),
        "{result:?}"
    );
    eprintln!("40-byte m4a: {result:?} in {:?}", started.elapsed());
}

#[test]
fn a_29_minute_384_khz_flac_is_refused_from_its_header() {
    let flac = silent_flac(384_000, 1740, true);
    eprintln!("29-minute 384 kHz FLAC: {} bytes", flac.len());
    let started = Instant::now();
    let budget = Budget::unlimited();
    let result = audio::decode_bytes(flac, &options(Keep::Nothing, 900.0, &budget));
    let elapsed = started.elapsed();
    match result {
        Err(AudioError::TooLong { seconds, limit }) => assert!(
            (seconds - 1740.0).abs() < 0.01 && limit == 900.0,
            "{seconds} {limit}"
        ),
        other => panic!(
            "expected TooLong, got {:?}",
            other.map(|d| d.audio.duration_s)
        ),
    }
    eprintln!("refused from STREAMINFO in {elapsed:?}");
    assert!(
        elapsed < Duration::from_secs(1),
        "not a single packet needs decoding: {elapsed:?}"
    );
}

#[test]
fn an_undeclared_length_is_counted_and_decoding_stops_at_the_limit() {
    // STREAMINFO says "length unknown": the samples are counted and decoding stops at 60 s of
    // the 1740 s, keeping nothing.
    let flac = silent_flac(384_000, 1740, false);
    let started = Instant::now();
    let budget = Budget::unlimited();
    match audio::decode_bytes(flac.clone(), &options(Keep::Nothing, 60.0, &budget)) {
        Err(AudioError::TooLong { seconds, .. }) => {
            assert!((60.0..61.0).contains(&seconds), "{seconds}")
        }
        other => panic!(
            "expected TooLong, got {:?}",
            other.map(|d| d.audio.duration_s)
        ),
    }
    eprintln!(
        "stopped after 60 s of 384 kHz samples in {:?}",
        started.elapsed()
    );
    // A budget stops it too, whatever the duration limit.
    let budget = Budget::new(Some(Duration::from_millis(200)), None);
    let started = Instant::now();
    let result = audio::decode_bytes(flac, &options(Keep::Nothing, 1e9, &budget));
    assert!(
        matches!(result, Err(AudioError::TimedOut { .. })),
        "{:?}",
        result.map(|d| d.audio.duration_s)
    );
    assert!(
        started.elapsed() < Duration::from_secs(2),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn high_rates_are_kept_at_the_asked_rate_or_refused() {
    let budget = Budget::unlimited();
    let decoded = audio::decode_bytes(
        silent_flac(384_000, 20, true),
        &options(Keep::At(22_050), 900.0, &budget),
    )
    .expect("decodes");
    assert_eq!(
        (decoded.audio.sample_rate, decoded.audio.samples.len()),
        (22_050, 20 * 22_050)
    );
    let decoded = audio::decode_bytes(
        silent_flac(384_000, 2, true),
        &options(Keep::AtMost(48_000), 900.0, &budget),
    )
    .expect("decodes");
    assert_eq!(decoded.audio.sample_rate, 48_000);
    let decoded = audio::decode_bytes(
        silent_flac(384_000, 2, true),
        &options(Keep::Nothing, 900.0, &budget),
    )
    .expect("decodes");
    assert!(decoded.audio.samples.is_empty());
    assert_eq!(
        (decoded.audio.sample_rate, decoded.declared_s),
        (384_000, Some(2.0))
    );
    // Above the ceiling (and within FLAC's own): refused from the header, before any packet.
    let result = audio::decode_bytes(
        silent_flac(500_000, 1, true),
        &options(Keep::Nothing, 900.0, &budget),
    );
    assert!(
        matches!(result, Err(AudioError::UnsupportedSampleRate(500_000))),
        "{:?}",
        result.map(|d| d.audio.sample_rate)
    );
}

// ---------------------------------------------------------------------------------------------
// The mutation loop.

/// How many mutants of each format; `FUZZ_CASES` raises it for a longer run.
fn cases_per_format() -> usize {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000)
}

/// The head of a real file: container headers, codec set-up and a few packets (m4a excepted).
const SEED_BYTES: usize = 64 * 1024;

/// Real files of each format, made once per build from a song of ../shared/audio.
fn seeds() -> Option<Vec<(&'static str, Vec<u8>)>> {
    let song =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/audio/trumpet_loop_90bpm.ogg");
    if !song.is_file() {
        if std::env::var("CI").as_deref() == Ok("true") {
            panic!(
                "{} is missing: the decoder fuzz test mutates it (CI=true)",
                song.display()
            );
        }
        eprintln!(
            "NOTICE: skipping the decoder fuzz test: {} not found",
            song.display()
        );
        return None;
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("fuzz-seeds");
    std::fs::create_dir_all(&dir).expect("seed dir");
    let recipes: [(&str, &[&str]); 4] = [
        ("mp3", &["-c:a", "libmp3lame", "-b:a", "128k"]),
        ("flac", &["-c:a", "flac"]),
        ("wav", &["-c:a", "pcm_s16le"]),
        // The moov first, so the head holds the edit list the hand parser reads.
        (
            "m4a",
            &["-c:a", "aac", "-b:a", "128k", "-movflags", "+faststart"],
        ),
    ];
    let mut out = vec![("ogg", std::fs::read(&song).expect("read song"))];
    for (ext, codec) in recipes {
        let path = dir.join(format!("seed.{ext}"));
        if !path.is_file() {
            let partial = dir.join(format!("partial-{}.{ext}", std::process::id()));
            let status = std::process::Command::new("ffmpeg")
                .args(["-v", "error", "-y", "-i"])
                .arg(&song)
                .args(codec)
                .arg(&partial)
                .status()
                .expect(
                    "ffmpeg makes the fuzz seeds: run `scripts/setup.sh --test` (or `make test`)",
                );
            assert!(status.success(), "ffmpeg failed to make {}", path.display());
            std::fs::rename(&partial, &path).expect("rename seed");
        }
        out.push((ext, std::fs::read(&path).expect("read seed")));
    }
    // symphonia's MP4 reader walks every top-level box on opening, so a cut m4a is no m4a at
    // all: it stays whole (80 kB), and its mutations still fall mostly on the moov.
    for (format, bytes) in &mut out {
        if *format != "m4a" {
            bytes.truncate(SEED_BYTES);
        }
    }
    Some(out)
}

/// Values that break size arithmetic.
const INTERESTING: [u32; 10] = [
    0,
    1,
    7,
    8,
    0x7f,
    0xff,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
];

/// One to eight mutations, most of them in the first 512 bytes where the headers are.
fn mutate(seed: &[u8], rng: &mut StdRng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.gen_range(1..=8) {
        if b.len() < 8 {
            b.extend_from_slice(&[0u8; 8]);
        }
        let span = if rng.gen_bool(0.8) {
            b.len().min(512)
        } else {
            b.len()
        };
        let at = rng.gen_range(0..span);
        match rng.gen_range(0..7) {
            0 => b[at] ^= 1 << rng.gen_range(0..8),
            1 => b[at] = rng.gen(),
            2 => {
                // A size field: an interesting 32-bit value, big- or little-endian.
                let v = INTERESTING[rng.gen_range(0..INTERESTING.len())];
                let bytes = if rng.gen_bool(0.5) {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                };
                let at = at.min(b.len() - 4);
                b[at..at + 4].copy_from_slice(&bytes);
            }
            3 => {
                // A 64-bit size near the top of the range.
                let v = u64::MAX - rng.gen_range(0..64u64);
                let at = at.min(b.len() - 8);
                b[at..at + 8].copy_from_slice(&v.to_be_bytes());
            }
            4 => b.truncate(rng.gen_range(0..b.len())),
            5 => {
                // Repeat a chunk (duplicated boxes, pages, frames).
                let len = rng.gen_range(1..=64).min(b.len() - at);
                let chunk = b[at..at + len].to_vec();
                let to = rng.gen_range(0..=b.len());
                b.splice(to..to, chunk);
            }
            _ => {
                let junk: Vec<u8> = (0..rng.gen_range(1..=16)).map(|_| rng.gen()).collect();
                b.splice(at..at, junk);
            }
        }
    }
    b
}

#[test]
fn thousands_of_mutated_headers_get_an_answer_never_a_panic_or_a_hang() {
    let Some(seeds) = seeds() else { return };
    let n = cases_per_format();
    // Each decode gets a 5 s budget inside the decoder, and the loop a watchdog outside it: a
    // mutant that hangs where no budget is checked fails the test, naming the mutant.
    let per_case = Duration::from_secs(5);
    let (tx, rx) = mpsc::channel::<(String, Duration, Result<(), String>)>();
    let worker = std::thread::spawn(move || {
        for (format, seed) in &seeds {
            // The unmutated seed decodes: the mutants start from a working file.
            let budget = Budget::unlimited();
            if let Err(e) =
                audio::decode_bytes(seed.clone(), &options(Keep::Native, 900.0, &budget))
            {
                let _ = tx.send((format!("{format} seed"), Duration::ZERO, Err(e.to_string())));
                return;
            }
            for case in 0..n {
                let mut rng = StdRng::seed_from_u64(case as u64 * 7919 + format.len() as u64);
                let mutant = mutate(seed, &mut rng);
                let name = format!("{format} #{case}");
                let started = Instant::now();
                let outcome = std::panic::catch_unwind(|| {
                    let budget = Budget::new(Some(per_case), None);
                    let keep = if case % 2 == 0 {
                        Keep::Native
                    } else {
                        Keep::At(22_050)
                    };
                    audio::decode_bytes(mutant, &options(keep, 900.0, &budget)).map(|_| ())
                });
                let outcome = match outcome {
                    Ok(_) => Ok(()),
                    Err(panic) => Err(format!(
                        "panicked: {:?}",
                        panic
                            .downcast_ref::<String>()
                            .cloned()
                            .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    )),
                };
                if tx.send((name, started.elapsed(), outcome)).is_err() {
                    return;
                }
            }
        }
    });
    let (mut done, mut slowest) = (0usize, (String::new(), Duration::ZERO));
    let started = Instant::now();
    loop {
        match rx.recv_timeout(per_case * 3) {
            Ok((name, took, outcome)) => {
                if let Err(e) = outcome {
                    panic!("{name}: {e}");
                }
                assert!(took < per_case * 2, "{name} took {took:?}");
                if took > slowest.1 {
                    slowest = (name, took);
                }
                done += 1;
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                panic!("a mutant after #{done} hung past {:?}", per_case * 3)
            }
        }
    }
    worker.join().expect("fuzz thread");
    assert_eq!(done, 5 * n, "every mutant answered");
    eprintln!(
        "{done} mutants in {:?}; slowest {} in {:?}",
        started.elapsed(),
        slowest.0,
        slowest.1
    );
}
