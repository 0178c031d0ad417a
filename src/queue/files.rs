//! The data dir's file layout: songs and job results, named by id, written atomically.
//!
//! ```text
//! <data_dir>/choreo.sqlite        jobs, songs, job_events
//! <data_dir>/songs/<song id>.<format>
//! <data_dir>/rigs/<rig id>.bvh|glb
//! <data_dir>/jobs/<job id>/motion.bvh, motion.json, motion.glb, report.json, preview.png
//! <data_dir>/tmp/                 uploads in flight; renamed into place when complete
//! ```
//! Names come from ids and the decoded format only, never from user input, so no upload can
//! name a path outside the data dir.
use super::{JobId, RigId, SongId};
use crate::audio::AudioFormat;
use crate::motion::retarget::uploaded::RigFormat;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The result files a generate job may write, in the order the API lists them.
pub const RESULT_FILES: &[&str] = &[
    "motion.bvh",
    "motion.json",
    "motion.glb",
    "report.json",
    "preview.png",
];

/// The data dir and the paths inside it.
#[derive(Clone, Debug)]
pub struct DataDir {
    root: PathBuf,
}

/// The file extension a decoded format is stored under.
pub fn extension(format: AudioFormat) -> &'static str {
    match format {
        AudioFormat::Mp3 => "mp3",
        AudioFormat::Wav => "wav",
        AudioFormat::Flac => "flac",
        AudioFormat::Ogg => "ogg",
        AudioFormat::M4a => "m4a",
    }
}

impl DataDir {
    /// Creates the layout under `root` if missing.
    pub fn create(root: &Path) -> std::io::Result<Self> {
        for sub in ["songs", "rigs", "jobs", "tmp"] {
            std::fs::create_dir_all(root.join(sub))?;
        }
        Ok(Self {
            root: root.to_path_buf(),
        })
    }

    /// The root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Where an uploaded song lives.
    pub fn song_path(&self, id: SongId, format: AudioFormat) -> PathBuf {
        self.root
            .join("songs")
            .join(format!("{id}.{}", extension(format)))
    }

    /// Where an uploaded rig's file lives.
    pub fn rig_path(&self, id: RigId, format: RigFormat) -> PathBuf {
        self.root
            .join("rigs")
            .join(format!("{id}.{}", format.extension()))
    }

    /// Where a job's results live.
    pub fn job_dir(&self, id: JobId) -> PathBuf {
        self.root.join("jobs").join(id.to_string())
    }

    /// A fresh temporary file inside the data dir (same filesystem, so rename is atomic).
    pub fn temp_file(&self) -> std::io::Result<tempfile::NamedTempFile> {
        tempfile::Builder::new()
            .prefix("upload-")
            .tempfile_in(self.root.join("tmp"))
    }

    /// Removes temp files left by a previous process (uploads cut off by a crash).
    pub fn clean_tmp(&self) -> std::io::Result<usize> {
        let mut removed = 0;
        for entry in std::fs::read_dir(self.root.join("tmp"))? {
            let entry = entry?;
            if entry.file_type()?.is_file() {
                std::fs::remove_file(entry.path())?;
                removed += 1;
            }
        }
        Ok(removed)
    }
}

/// Writes `bytes` to `path` atomically: a temp file in the same dir, fsync, then rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path
        .parent()
        .ok_or_else(|| std::io::Error::other(format!("{} has no parent dir", path.display())))?;
    std::fs::create_dir_all(dir)?;
    let mut tmp = tempfile::Builder::new()
        .prefix(".partial-")
        .tempfile_in(dir)?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_are_named_by_id_and_writes_are_atomic() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = DataDir::create(dir.path()).expect("layout");
        let song = SongId::new();
        let path = data.song_path(song, AudioFormat::Flac);
        assert_eq!(path, dir.path().join("songs").join(format!("{song}.flac")));
        write_atomic(&path, b"abc").expect("write");
        write_atomic(&path, b"de").expect("overwrite");
        assert_eq!(std::fs::read(&path).expect("read"), b"de");
        let leftovers: Vec<_> = std::fs::read_dir(path.parent().expect("dir"))
            .expect("ls")
            .collect();
        assert_eq!(leftovers.len(), 1, "no partial files remain");
    }
}
