//! The cache files' bytes: little-endian numbers as their bits, so what is read back is exactly
//! what was computed (JSON's decimal floats would not promise that), behind a magic that names
//! the kind of file.
use super::SongCacheError;
use crate::audio::{Analysis, TempoPoint};
use ndarray::Array2;

/// First bytes of a feature set's file.
const FEATURES_MAGIC: &[u8; 8] = b"CHOFEAT1";
/// First bytes of the analysis file.
const HEARD_MAGIC: &[u8; 8] = b"CHOBEAT1";

/// `[rows, cols]` as the magic, rows and cols (u64), then the values row by row (f32).
pub fn encode_features(features: &Array2<f32>) -> Vec<u8> {
    let (rows, cols) = features.dim();
    let mut out = Vec::with_capacity(24 + 4 * rows * cols);
    out.extend_from_slice(FEATURES_MAGIC);
    out.extend_from_slice(&(rows as u64).to_le_bytes());
    out.extend_from_slice(&(cols as u64).to_le_bytes());
    for v in features.iter() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The inverse of [`encode_features`].
pub fn decode_features(file: &str, bytes: &[u8]) -> Result<Array2<f32>, SongCacheError> {
    let mut r = Reader::new(file, bytes, FEATURES_MAGIC)?;
    let rows = r.len()?;
    let cols = r.len()?;
    let n = rows
        .checked_mul(cols)
        .ok_or_else(|| r.corrupt("rows × cols overflows"))?;
    if r.rest.len() != 4 * n {
        return Err(r.corrupt(&format!(
            "{} bytes of values for {rows} × {cols}",
            r.rest.len()
        )));
    }
    let values: Vec<f32> = r
        .rest
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Array2::from_shape_vec((rows, cols), values).map_err(|e| r.corrupt(&e.to_string()))
}

/// The song's length and analysis: the magic, then f64s: length, tempo, and the beats, the
/// downbeats and the tempo curve (time, bpm), each after its count (u64).
pub fn encode_heard(duration_s: f64, analysis: &Analysis) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(HEARD_MAGIC);
    let f64s = |out: &mut Vec<u8>, vs: &[f64]| {
        out.extend_from_slice(&(vs.len() as u64).to_le_bytes());
        for v in vs {
            out.extend_from_slice(&v.to_le_bytes());
        }
    };
    f64s(&mut out, &[duration_s, analysis.tempo_bpm]);
    f64s(&mut out, &analysis.beat_times);
    f64s(&mut out, &analysis.downbeat_times);
    let curve: Vec<f64> = analysis
        .tempo_curve
        .iter()
        .flat_map(|p| [p.time_s, p.bpm])
        .collect();
    f64s(&mut out, &curve);
    out
}

/// The inverse of [`encode_heard`].
pub fn decode_heard(file: &str, bytes: &[u8]) -> Result<(f64, Analysis), SongCacheError> {
    let mut r = Reader::new(file, bytes, HEARD_MAGIC)?;
    let head = r.f64s()?;
    let [duration_s, tempo_bpm] = head[..] else {
        return Err(r.corrupt("the head is not length and tempo"));
    };
    let beat_times = r.f64s()?;
    let downbeat_times = r.f64s()?;
    let curve = r.f64s()?;
    if curve.len() % 2 != 0 || !r.rest.is_empty() {
        return Err(r.corrupt("the tempo curve or the end does not fit"));
    }
    let tempo_curve = curve
        .chunks_exact(2)
        .map(|p| TempoPoint {
            time_s: p[0],
            bpm: p[1],
        })
        .collect();
    Ok((
        duration_s,
        Analysis {
            tempo_bpm,
            beat_times,
            downbeat_times,
            tempo_curve,
        },
    ))
}

/// Reads a file's numbers in order, refusing one cut short.
struct Reader<'b> {
    file: &'b str,
    rest: &'b [u8],
}

impl<'b> Reader<'b> {
    fn new(file: &'b str, bytes: &'b [u8], magic: &[u8; 8]) -> Result<Self, SongCacheError> {
        let r = Self { file, rest: bytes };
        match bytes.strip_prefix(&magic[..]) {
            Some(rest) => Ok(Self { rest, ..r }),
            None => Err(r.corrupt("wrong magic")),
        }
    }

    fn corrupt(&self, reason: &str) -> SongCacheError {
        SongCacheError::Corrupt {
            file: self.file.to_string(),
            reason: reason.to_string(),
        }
    }

    fn take8(&mut self) -> Result<[u8; 8], SongCacheError> {
        let Some((head, rest)) = self.rest.split_first_chunk::<8>() else {
            return Err(self.corrupt("cut short"));
        };
        self.rest = rest;
        Ok(*head)
    }

    fn len(&mut self) -> Result<usize, SongCacheError> {
        let n = u64::from_le_bytes(self.take8()?);
        usize::try_from(n).map_err(|_| self.corrupt("a count past usize"))
    }

    fn f64s(&mut self) -> Result<Vec<f64>, SongCacheError> {
        let n = self.len()?;
        if self.rest.len() / 8 < n {
            return Err(self.corrupt("cut short"));
        }
        (0..n)
            .map(|_| self.take8().map(f64::from_le_bytes))
            .collect()
    }
}
