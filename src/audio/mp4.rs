//! The encoder delay of an MP4/M4A file, read from its edit list. symphonia's own MP4 reader
//! parses the edit list but does not expose it (its `atoms` module is private, and
//! `CodecParameters` carries no delay for MP4), hence this small parser, which reads sizes
//! from the file with checked arithmetic only.
use std::io::{Read, Seek, SeekFrom};

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
    pub(super) fn to_samples(self, sr: u32) -> (u64, Option<u64>) {
        // u128 cannot overflow here (u64 × u32); a result past u64 saturates.
        let scale = |v: u64, ts: u32| {
            u64::try_from(u128::from(v) * u128::from(sr) / u128::from(ts)).unwrap_or(u64::MAX)
        };
        let skip = if self.media_timescale > 0 {
            scale(self.media_time, self.media_timescale)
        } else {
            0
        };
        let keep = (self.segment_duration > 0 && self.movie_timescale > 0)
            .then(|| scale(self.segment_duration, self.movie_timescale));
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
    b.get(at..at.checked_add(4)?)
        .map(|s| u32::from_be_bytes([s[0], s[1], s[2], s[3]]))
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
    let movie_timescale = kids
        .iter()
        .find(|(k, _)| k == b"mvhd")
        .and_then(|(_, b)| header_timescale(b))?;
    for (_, trak) in kids.iter().filter(|(k, _)| k == b"trak") {
        let tk = children(trak);
        let mdia = tk
            .iter()
            .find(|(k, _)| k == b"mdia")
            .map(|(_, b)| children(b))?;
        let is_sound = mdia
            .iter()
            .any(|(k, b)| k == b"hdlr" && b.get(8..12) == Some(b"soun"));
        if !is_sound {
            continue;
        }
        let media_timescale = mdia
            .iter()
            .find(|(k, _)| k == b"mdhd")
            .and_then(|(_, b)| header_timescale(b))?;
        let edts = tk
            .iter()
            .find(|(k, _)| k == b"edts")
            .map(|(_, b)| children(b))?;
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
                (
                    u64::from(be_u32(elst, at)?),
                    i64::from(be_u32(elst, at + 4)? as i32),
                )
            };
            // media_time -1 is an empty edit (a gap); the first real edit says where audio starts.
            if mt >= 0 {
                return Some(Mp4Edit {
                    media_time: mt as u64,
                    media_timescale,
                    segment_duration: dur,
                    movie_timescale,
                });
            }
        }
        return None;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

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
        let trak = [
            mp4_box(b"edts", &mp4_box(b"elst", &elst)),
            mp4_box(b"mdia", &mdia),
        ]
        .concat();
        mp4_box(
            b"moov",
            &[mp4_box(b"mvhd", &mvhd), mp4_box(b"trak", &trak)].concat(),
        )
    }

    /// The 40-byte hostile M4A (an `mdat` size that wraps the position), byte for byte.
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
        assert_eq!(
            (
                e.media_time,
                e.media_timescale,
                e.segment_duration,
                e.movie_timescale
            ),
            (2112, 44_100, 5000, 1000)
        );
        assert_eq!(e.to_samples(44_100), (2112, Some(220_500)));
        // A count larger than the box holds reads the entries that are there.
        assert_eq!(
            edit(&[ftyp(), moov(2112, u32::MAX)].concat()).map(|e| e.media_time),
            Some(2112)
        );
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
