//! The music encoder (paper §3.1): a linear embedding, sinusoidal positions, and transformer
//! layers whose self-attention is local.
use tch::nn;
use tch::{Kind, Tensor};

use super::Config;
use crate::models::layers::sinusoid;

/// Multi-head self-attention restricted to a window of `k` neighbours (paper §3.1).
#[derive(Debug)]
struct LocalSelfAttention {
    qkv: nn::Linear,
    out: nn::Linear,
    n_heads: i64,
    half: i64,
}

impl LocalSelfAttention {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            qkv: nn::linear(&p / "qkv", c.d_z, 3 * c.d_z, Default::default()),
            out: nn::linear(&p / "out", c.d_z, c.d_z, Default::default()),
            n_heads: c.n_heads,
            half: c.k / 2,
        }
    }

    /// `x`: `[b, n, d]` → `[b, n, d]`.
    ///
    /// Sliding chunks: the sequence is cut into blocks of `w = k/2` frames; block `j`'s queries
    /// score against blocks `j-1, j, j+1` (3w keys), and a band mask keeps `|i - i'| ≤ w`. Every
    /// tensor is O(n·k), and the products are dense batched matmuls rather than gathers.
    fn forward(&self, x: &Tensor) -> Tensor {
        let (b, n, d) = x.size3().expect("encoder input is [b, n, d]");
        let (h, w) = (self.n_heads, self.half.max(1));
        let dh = d / h;
        let nb = (n + w - 1) / w; // blocks
        let np = nb * w; // padded length
        let dev = x.device();
        // [b, n, 3, h, dh] → three of [b, h, nb, w, dh], time padded to a whole number of blocks.
        let qkv = x
            .apply(&self.qkv)
            .view([b, n, 3, h, dh])
            .permute([2, 0, 3, 1, 4]);
        let qkv = qkv
            .constant_pad_nd([0, 0, 0, np - n])
            .view([3, b, h, nb, w, dh]);
        let (q, k, v) = (qkv.get(0), qkv.get(1), qkv.get(2));
        let window = |t: Tensor| {
            let p = t.constant_pad_nd([0, 0, 0, 0, 1, 1]); // one empty block each side: [b, h, nb+2, w, dh]
            Tensor::cat(
                &[p.narrow(2, 0, nb), p.narrow(2, 1, nb), p.narrow(2, 2, nb)],
                3,
            ) // [b, h, nb, 3w, dh]
        };
        let (k, v) = (window(k), window(v));
        let scores = q.matmul(&k.transpose(-1, -2)) / (dh as f64).sqrt(); // [b, h, nb, w, 3w]
                                                                          // Query at blk*w + r, key slot s ↔ position (blk-1)*w + s: keep |offset| ≤ w, inside [0, n).
        let r = Tensor::arange(w, (Kind::Int64, dev)).view([1, w, 1]);
        let s = Tensor::arange(3 * w, (Kind::Int64, dev)).view([1, 1, 3 * w]);
        let blk = Tensor::arange(nb, (Kind::Int64, dev)).view([nb, 1, 1]);
        let kpos = (&blk - 1) * w + &s;
        let off = &s - &r; // = kpos - qpos + w
        let outside = off
            .lt(0)
            .logical_or(&off.gt(2 * w))
            .logical_or(&kpos.lt(0))
            .logical_or(&kpos.ge(n));
        let attn = scores
            .masked_fill(&outside.view([1, 1, nb, w, 3 * w]), f64::NEG_INFINITY)
            .softmax(-1, Kind::Float);
        let y = attn.matmul(&v).view([b, h, np, dh]).narrow(2, 0, n); // [b, h, n, dh]
        y.permute([0, 2, 1, 3])
            .contiguous()
            .view([b, n, d])
            .apply(&self.out)
    }
}

/// One encoder layer: local attention and a position-wise FFN, each with residual + layer norm.
#[derive(Debug)]
struct EncoderLayer {
    attn: LocalSelfAttention,
    norm1: nn::LayerNorm,
    ff1: nn::Linear,
    ff2: nn::Linear,
    norm2: nn::LayerNorm,
    dropout: f64,
}

impl EncoderLayer {
    fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            attn: LocalSelfAttention::new(&p / "attn", c),
            norm1: nn::layer_norm(&p / "norm1", vec![c.d_z], Default::default()),
            ff1: nn::linear(&p / "ff1", c.d_z, c.d_ff, Default::default()),
            ff2: nn::linear(&p / "ff2", c.d_ff, c.d_z, Default::default()),
            norm2: nn::layer_norm(&p / "norm2", vec![c.d_z], Default::default()),
            dropout: c.dropout,
        }
    }

    fn forward(&self, x: &Tensor, train: bool) -> Tensor {
        let a = self.attn.forward(x).dropout(self.dropout, train);
        let x = (x + a).apply(&self.norm1);
        let f = x
            .apply(&self.ff1)
            .relu()
            .apply(&self.ff2)
            .dropout(self.dropout, train);
        (x + f).apply(&self.norm2)
    }
}

/// The music encoder (§3.1): features `[b, n, music_dim]` → `z` `[b, n, d_z]`.
#[derive(Debug)]
pub struct MusicEncoder {
    embed: nn::Linear,
    layers: Vec<EncoderLayer>,
    d_z: i64,
    k: i64,
}

impl MusicEncoder {
    pub(super) fn new(p: nn::Path, c: &Config) -> Self {
        Self {
            embed: nn::linear(&p / "embed", c.music_dim, c.d_z, Default::default()),
            layers: (0..c.n_layers)
                .map(|i| EncoderLayer::new(&p / "layers" / i, c))
                .collect(),
            d_z: c.d_z,
            k: c.k,
        }
    }

    /// Encodes a window whose first frame is song frame `start` (for the position encoding).
    pub fn forward(&self, music: &Tensor, start: i64, train: bool) -> Tensor {
        let n = music.size()[1];
        let mut x =
            music.apply(&self.embed) + sinusoid(start, n, self.d_z, music.device()).unsqueeze(0);
        for layer in &self.layers {
            x = layer.forward(&x, train);
        }
        x
    }

    /// Encodes a whole song `[1, n, music_dim]` in overlapping chunks so memory stays bounded.
    /// Each chunk carries `k` frames of context on each side, which covers every window that an
    /// `N`-layer stack of local attention can see (`N·k/2` per side for `N` ≤ 2).
    pub fn forward_chunked(
        &self,
        music: &Tensor,
        chunk: i64,
        on_chunk: impl FnMut(f32) -> bool,
    ) -> Option<Tensor> {
        let n = music.size()[1];
        let ctx = self.k * (self.layers.len() as i64).max(1) / 2 + 1;
        crate::models::layers::chunked(
            n,
            chunk,
            ctx,
            |cs, len| self.forward(&music.narrow(1, cs, len), cs, false),
            on_chunk,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::model;
    use tch::{Device, Kind, Tensor};

    #[test]
    fn local_attention_sees_only_its_window() {
        let (_vs, m) = model(0);
        let x = Tensor::randn([1, 40, 16], (Kind::Float, Device::Cpu));
        let attn = &m.encoder.layers[0].attn;
        let y0 = attn.forward(&x);
        // Changing frame 39 must not change frame 0 when the window (k = 8) cannot reach it.
        let x2 = x.copy();
        let _ = x2.narrow(1, 39, 1).fill_(5.0);
        let y1 = attn.forward(&x2);
        let d0 = (y0.narrow(1, 0, 1) - y1.narrow(1, 0, 1))
            .abs()
            .max()
            .double_value(&[]);
        let d39 = (y0.narrow(1, 39, 1) - y1.narrow(1, 39, 1))
            .abs()
            .max()
            .double_value(&[]);
        assert!(d0 < 1e-6, "frame 0 moved by {d0}");
        assert!(d39 > 1e-3, "frame 39 did not move");
    }

    #[test]
    fn chunked_encoding_equals_whole() {
        let (_vs, m) = model(1);
        let x = Tensor::randn([1, 50, 6], (Kind::Float, Device::Cpu));
        let whole = m.encoder.forward(&x, 0, false);
        let chunked = m.encoder.forward_chunked(&x, 7, |_| true).unwrap();
        let d = (whole - chunked).abs().max().double_value(&[]);
        assert!(d < 1e-5, "chunked encoder differs by {d}");
    }
}
