//! `choreo bench audio`: decode + DanceRevolution features per song, and decode + beat analysis
//! (`audio::analyze`: beats, downbeats, tempo curve), against librosa doing the same work
//! (tools/librosa_reference.py, one thread, as a subprocess: its features, and `load` at 22 050 Hz
//! + `beat.beat_track`) in the same run.
//!
//! Peak memory is the growth of this process's resident set while one song is processed:
//! the kernel's high-water mark (`VmHWM`) is reset before each song through
//! `/proc/self/clear_refs`, so libtorch and other start-up mappings are not counted.
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use serde::Serialize;

use super::features::{dance_revolution, FrameGrid};
use super::{decode_path, decode_path_at, AudioError};

/// What to benchmark.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Folder of songs (every mp3/wav/flac/ogg/m4a in it).
    pub songs_dir: PathBuf,
    /// Motion frame rate of the feature set.
    pub fps: f64,
    /// Also build a 3-minute and a long song (minutes) by concatenating the songs.
    pub long_minutes: f64,
    /// The Python interpreter for the librosa side; `None` skips librosa.
    pub python: Option<PathBuf>,
    /// Repository root (where tools/librosa_reference.py lives).
    pub repo_root: PathBuf,
}

/// The Python that runs tools/librosa_reference.py by default (it creates .venv-librosa on first
/// use).
pub const PYTHON: &str = "python3";

impl Default for BenchOptions {
    /// The committed benchmark, run from the repository root (the working directory).
    fn default() -> Self {
        Self {
            songs_dir: PathBuf::from("../shared/audio"),
            fps: 25.0,
            long_minutes: 15.0,
            python: Some(PathBuf::from(PYTHON)),
            repo_root: PathBuf::from("."),
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    pub song: String,
    pub duration_s: f64,
    pub rust_decode_s: f64,
    pub rust_features_s: f64,
    pub rust_total_s: f64,
    pub rust_peak_mb: Option<f64>,
    pub librosa_total_s: Option<f64>,
    pub speedup: Option<f64>,
    /// Decode + beat analysis, choreo and librosa, and librosa's time over choreo's.
    pub rust_beats_s: f64,
    pub librosa_beats_s: Option<f64>,
    pub beats_speedup: Option<f64>,
}

fn read_status_kb(field: &str) -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(field))?;
    line.split_whitespace().nth(1)?.parse::<f64>().ok()
}

/// Resets the resident high-water mark; returns the current resident set in kB.
fn reset_peak() -> Option<f64> {
    std::fs::write("/proc/self/clear_refs", "5").ok()?;
    read_status_kb("VmRSS:")
}

fn is_song(p: &Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("mp3" | "wav" | "flac" | "ogg" | "m4a")
    )
}

/// Writes mono 16-bit PCM WAV.
fn write_wav_mono(path: &Path, sr: u32, y: &[f32]) -> Result<(), AudioError> {
    use std::io::Write;
    let data_len = (y.len() * 2) as u32;
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    w.write_all(b"RIFF")?;
    w.write_all(&(36 + data_len).to_le_bytes())?;
    w.write_all(b"WAVEfmt ")?;
    w.write_all(&16u32.to_le_bytes())?;
    w.write_all(&1u16.to_le_bytes())?;
    w.write_all(&1u16.to_le_bytes())?;
    w.write_all(&sr.to_le_bytes())?;
    w.write_all(&(sr * 2).to_le_bytes())?;
    w.write_all(&2u16.to_le_bytes())?;
    w.write_all(&16u16.to_le_bytes())?;
    w.write_all(b"data")?;
    w.write_all(&data_len.to_le_bytes())?;
    for &v in y {
        w.write_all(&((v.clamp(-1.0, 1.0) * 32767.0).round() as i16).to_le_bytes())?;
    }
    w.flush()?;
    Ok(())
}

/// Concatenates songs (looping) into a `seconds`-long mono WAV at 44.1 kHz (this bench's long
/// songs, and the 3-minute song of `choreo bench jobs`).
pub fn make_long_song(songs: &[PathBuf], seconds: f64, out: &Path) -> Result<(), AudioError> {
    let sr = 44_100u32;
    let want = (seconds * sr as f64) as usize;
    let mut parts = Vec::new();
    for s in songs {
        let a = decode_path(s)?;
        parts.push(if a.sample_rate == sr {
            a.samples
        } else {
            super::resample(&a.samples, a.sample_rate, sr)?
        });
    }
    if parts.iter().all(|p| p.is_empty()) {
        return Err(AudioError::Empty);
    }
    let mut y = Vec::with_capacity(want);
    'outer: loop {
        for p in &parts {
            let take = (want - y.len()).min(p.len());
            y.extend_from_slice(&p[..take]);
            if y.len() >= want {
                break 'outer;
            }
        }
    }
    write_wav_mono(out, sr, &y)
}

/// Runs the benchmark and returns its rows (also printed as a table on stdout).
pub fn run(opts: &BenchOptions) -> Result<Vec<BenchRow>, AudioError> {
    let grid = FrameGrid::for_fps(opts.fps)?;
    let mut songs: Vec<PathBuf> = std::fs::read_dir(&opts.songs_dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| is_song(p))
        .collect();
    songs.sort();
    if songs.is_empty() {
        return Err(AudioError::InvalidParameter(format!(
            "no songs in {}",
            opts.songs_dir.display()
        )));
    }
    let tmp = tempfile::tempdir()?;
    let mut all = songs.clone();
    let three = tmp.path().join("concat_3min.wav");
    make_long_song(&songs, 180.0, &three)?;
    all.push(three);
    if opts.long_minutes > 0.0 {
        let long = tmp
            .path()
            .join(format!("concat_{}min.wav", opts.long_minutes));
        make_long_song(&songs, opts.long_minutes * 60.0, &long)?;
        all.push(long);
    }

    let mut rows = Vec::new();
    for song in &all {
        let base = reset_peak();
        let t0 = Instant::now();
        let audio = decode_path_at(song, Some(grid.sr))?;
        let t1 = Instant::now();
        let n = ((audio.duration_s * opts.fps).floor() as usize + 1).max(1);
        let x = dance_revolution(&audio, opts.fps, n)?;
        let t2 = Instant::now();
        let peak = match (base, read_status_kb("VmHWM:")) {
            (Some(b), Some(h)) => Some((h - b).max(0.0) / 1024.0),
            _ => None,
        };
        drop(x);
        let t3 = Instant::now();
        super::analyze(&decode_path(song)?)?;
        let beats_s = t3.elapsed().as_secs_f64();
        let name = song
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        rows.push(BenchRow {
            song: name,
            duration_s: audio.duration_s,
            rust_decode_s: (t1 - t0).as_secs_f64(),
            rust_features_s: (t2 - t1).as_secs_f64(),
            rust_total_s: (t2 - t0).as_secs_f64(),
            rust_peak_mb: peak,
            librosa_total_s: None,
            speedup: None,
            rust_beats_s: beats_s,
            librosa_beats_s: None,
            beats_speedup: None,
        });
    }

    if let Some(py) = &opts.python {
        let script = opts.repo_root.join("tools/librosa_reference.py");
        let mut cmd = Command::new(py);
        cmd.arg(&script)
            .arg("bench")
            .arg("--fps")
            .arg(opts.fps.to_string())
            .args(&all);
        for var in [
            "OMP_NUM_THREADS",
            "OPENBLAS_NUM_THREADS",
            "MKL_NUM_THREADS",
            "NUMBA_NUM_THREADS",
        ] {
            cmd.env(var, "1");
        }
        let out = cmd.output()?;
        if !out.status.success() {
            return Err(AudioError::Reference(
                String::from_utf8_lossy(&out.stderr)
                    .chars()
                    .take(2000)
                    .collect(),
            ));
        }
        let text = String::from_utf8_lossy(&out.stdout);
        for (row, line) in rows
            .iter_mut()
            .zip(text.lines().filter(|l| l.starts_with('{')))
        {
            let v: serde_json::Value =
                serde_json::from_str(line).map_err(|e| AudioError::Reference(e.to_string()))?;
            if let Some(t) = v["total_s"].as_f64() {
                row.librosa_total_s = Some(t);
                row.speedup = Some(t / row.rust_total_s.max(1e-9));
            }
            if let Some(t) = v["beats_s"].as_f64() {
                row.librosa_beats_s = Some(t);
                row.beats_speedup = Some(t / row.rust_beats_s.max(1e-9));
            }
        }
    }
    Ok(rows)
}
