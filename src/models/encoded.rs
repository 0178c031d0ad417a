//! A song's encoder pass kept for its next seeds.
//!
//! The music encoders (DanceRevolution's encoder, DanceNet's, TSMT's audio stream) read the
//! song's features and no seed, so a choreographer trying seeds on one song, or a page comparing them, would have
//! every job encode the same features again: 0.35–0.65 s of a 3-minute dance-revolution job whose
//! song is read from its cache (`choreo bench generate`). A served model keeps its last encodings
//! here, each under a hash of everything the encoder read (every input tensor's shape and every
//! value's bits), so a later job whose input is the same reads the encoding, and one whose input
//! differs in any bit (another song, another beat-time stretch, a seed motion's offset) encodes
//! its own. An encoding read from here is the one the encoder would make again (the same weights
//! on the same input, one thread), so the dance is the same byte for byte.
//!
//! A hit reports no `encode` stage: like the song's cache, the stage metric counts the encodings
//! run. The memory is per process; a worker on another host encodes once there.
//!
//! Written here rather than taken from an LRU crate: a handful of entries under a byte budget,
//! looked up by one hash, is the whole of it.
use std::collections::VecDeque;
use std::hash::Hasher;
use std::sync::Mutex;

use tch::Tensor;

/// Bytes of encodings one served model keeps, the oldest dropped first: a 3-minute song's
/// DanceRevolution encoding is 4,500 frames × 128 floats (2.3 MB), TSMT's audio stream 4,500 × 64
/// (1.2 MB), so a dozen songs or more.
pub const BUDGET_BYTES: usize = 32 << 20;

/// A served model's recent encodings, most recently used last.
#[derive(Default)]
pub struct EncoderMemo {
    kept: Mutex<VecDeque<(u64, Tensor)>>,
}

impl EncoderMemo {
    /// The encoding of `inputs`: kept from an earlier call with the same inputs, or made by
    /// `encode` and kept. `encode` returning `None` (a cancelled job) keeps nothing.
    pub fn get_or_encode(
        &self,
        inputs: &[&Tensor],
        encode: impl FnOnce() -> Option<Tensor>,
    ) -> Option<Tensor> {
        let key = key_of(inputs);
        if let Some(z) = self.take(key) {
            return Some(z);
        }
        let z = encode()?;
        self.keep(key, &z);
        Some(z)
    }

    /// How many encodings are kept.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.lock().len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<(u64, Tensor)>> {
        // A panic while holding the lock left at worst one entry too many.
        self.kept.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The kept encoding under `key`, moved to the most recent end.
    fn take(&self, key: u64) -> Option<Tensor> {
        let mut kept = self.lock();
        let at = kept.iter().position(|(k, _)| *k == key)?;
        let entry = kept.remove(at)?;
        let z = entry.1.shallow_clone();
        kept.push_back(entry);
        Some(z)
    }

    fn keep(&self, key: u64, z: &Tensor) {
        let mut kept = self.lock();
        kept.retain(|(k, _)| *k != key);
        kept.push_back((key, z.shallow_clone()));
        while kept.len() > 1 && kept.iter().map(|(_, t)| bytes(t)).sum::<usize>() > BUDGET_BYTES {
            kept.pop_front();
        }
    }
}

fn bytes(t: &Tensor) -> usize {
    t.numel() * t.kind().elt_size_in_bytes()
}

/// A hash of the tensors' shapes and float values, bit for bit.
fn key_of(inputs: &[&Tensor]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for t in inputs {
        let size = t.size();
        h.write_usize(size.len());
        for d in size {
            h.write_i64(d);
        }
        let values =
            Vec::<f32>::try_from(t.to_kind(tch::Kind::Float).reshape([-1])).unwrap_or_default();
        for v in values {
            h.write_u32(v.to_bits());
        }
    }
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_input_is_encoded_once_and_another_again() {
        let memo = EncoderMemo::default();
        let a = Tensor::from_slice(&[1.0f32, 2.0, 3.0]).view([1, 3]);
        let b = Tensor::from_slice(&[1.0f32, 2.0, 3.5]).view([1, 3]);
        let mut runs = 0;
        let mut encode = |x: &Tensor| {
            runs += 1;
            Some(x * 2.0)
        };
        let first = memo.get_or_encode(&[&a], || encode(&a)).unwrap();
        let again = memo.get_or_encode(&[&a], || encode(&a)).unwrap();
        let flat = |t: &Tensor| Vec::<f32>::try_from(t.reshape([-1])).unwrap();
        assert_eq!(flat(&first), flat(&again));
        let other = memo.get_or_encode(&[&b], || encode(&b)).unwrap();
        assert_eq!(flat(&other), vec![2.0, 4.0, 7.0]);
        // Same values, another shape: another input.
        let reshaped = a.view([3, 1]);
        let _ = memo.get_or_encode(&[&reshaped], || encode(&reshaped));
        assert_eq!(runs, 3);
        assert_eq!(memo.len(), 3);
        // A cancelled encoding keeps nothing.
        let c = Tensor::from_slice(&[9.0f32]);
        assert!(memo.get_or_encode(&[&c], || None).is_none());
        assert_eq!(memo.len(), 3);
    }

    #[test]
    fn the_oldest_encodings_go_past_the_budget() {
        let memo = EncoderMemo::default();
        // Each 12 MB: two fit in the budget, the third pushes the first out.
        let big = |v: f64| Tensor::full([3 << 20], v, (tch::Kind::Float, tch::Device::Cpu));
        let inputs: Vec<Tensor> = (0..3).map(|i| Tensor::from_slice(&[i as f32])).collect();
        for (i, x) in inputs.iter().enumerate() {
            let _ = memo.get_or_encode(&[x], || Some(big(i as f64)));
        }
        assert_eq!(memo.len(), 2);
        let mut ran = false;
        let _ = memo.get_or_encode(&[&inputs[0]], || {
            ran = true;
            Some(big(0.0))
        });
        assert!(ran, "the first input's encoding was dropped");
    }
}
