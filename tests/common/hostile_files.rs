//! The two hostile files, written byte by byte (shared by the audio and API tests).

/// A 16-byte `ftyp`, then an `mdat` whose 64-bit size is 2^64 − 16: summed into the position,
/// it wraps to 0, and a box walker that does not check it loops for ever.
pub fn the_40_byte_m4a() -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&16u32.to_be_bytes());
    b.extend_from_slice(b"ftypM4A \0\0\0\0");
    b.extend_from_slice(&1u32.to_be_bytes());
    b.extend_from_slice(b"mdat");
    b.extend_from_slice(&(u64::MAX - 15).to_be_bytes());
    b.extend_from_slice(&[0u8; 8]);
    assert_eq!(b.len(), 40);
    b
}

fn crc8(data: &[u8]) -> u8 {
    data.iter().fold(0u8, |mut c, &b| {
        c ^= b;
        for _ in 0..8 {
            c = if c & 0x80 != 0 {
                (c << 1) ^ 0x07
            } else {
                c << 1
            };
        }
        c
    })
}

fn crc16(data: &[u8]) -> u16 {
    data.iter().fold(0u16, |mut c, &b| {
        c ^= u16::from(b) << 8;
        for _ in 0..8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x8005
            } else {
                c << 1
            };
        }
        c
    })
}

/// FLAC's UTF-8-like frame number.
fn utf8_number(n: u32) -> Vec<u8> {
    match n {
        0..=0x7f => vec![n as u8],
        0x80..=0x7ff => vec![0xC0 | (n >> 6) as u8, 0x80 | (n & 0x3f) as u8],
        0x800..=0xffff => vec![
            0xE0 | (n >> 12) as u8,
            0x80 | ((n >> 6) & 0x3f) as u8,
            0x80 | (n & 0x3f) as u8,
        ],
        _ => vec![
            0xF0 | (n >> 18) as u8,
            0x80 | ((n >> 12) & 0x3f) as u8,
            0x80 | ((n >> 6) & 0x3f) as u8,
            0x80 | (n & 0x3f) as u8,
        ],
    }
}

/// Mono 16-bit FLAC of digital silence at `sr`, `seconds` long, in 4096-sample frames of one
/// constant subframe each (what flac makes of silence: 14 bytes a frame). With `declare` false
/// STREAMINFO's total is 0 ("unknown"), so only counting the decoded samples finds the length.
pub fn silent_flac(sr: u32, seconds: u64, declare: bool) -> Vec<u8> {
    const BLOCK: u64 = 4096;
    let total = u64::from(sr) * seconds;
    let mut out = b"fLaC".to_vec();
    out.extend_from_slice(&[0x80, 0, 0, 34]); // last metadata block, STREAMINFO, 34 bytes
    out.extend_from_slice(&(BLOCK as u16).to_be_bytes());
    out.extend_from_slice(&(BLOCK as u16).to_be_bytes());
    out.extend_from_slice(&[0; 6]); // frame sizes unknown
    let packed = (u64::from(sr) << 44) | (15 << 36) | if declare { total } else { 0 };
    out.extend_from_slice(&packed.to_be_bytes()); // rate, 1 channel, 16 bits, total samples
    out.extend_from_slice(&[0; 16]); // MD5 unknown
    for n in 0..(total / BLOCK) as u32 {
        // Sync, fixed blocking; 4096 samples, rate and depth from STREAMINFO; mono.
        let mut frame = vec![0xFF, 0xF8, 0xC0, 0x00];
        frame.extend_from_slice(&utf8_number(n));
        frame.push(crc8(&frame));
        frame.extend_from_slice(&[0x00, 0x00, 0x00]); // CONSTANT subframe, value 0
        let crc = crc16(&frame);
        frame.extend_from_slice(&crc.to_be_bytes());
        out.extend_from_slice(&frame);
    }
    out
}
