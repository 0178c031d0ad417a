//! A decode that can stop after any frame and go on later (the opening check keeps the draw it
//! chose and goes on from there).
use tch::Tensor;

use super::served::StallWatch;
use super::DanceDecoder;
use crate::models::layers::LstmState;

/// One decode of [`DanceRevolution::decode`] that can stop after any frame and go on later,
/// decoding exactly what one run would: the opening check decodes a draw's opening, and the
/// draw it keeps goes on from there instead of being decoded again from its warm-up.
pub struct Decoding<'a> {
    pub(super) decoder: &'a DanceDecoder,
    pub(super) state: LstmState,
    pub(super) watch: Option<StallWatch<'a>>,
    pub(super) prev: Tensor,
    /// The emitted frames, in runs of one or more.
    pub(super) out: Vec<Tensor>,
    pub(super) done: i64,
    /// `[1, n, FIGURE_DIM]`: the figure of every frame, for a head with figures
    /// ([`Self::with_figures`]).
    pub(super) figures: Option<Tensor>,
}

impl Decoding<'_> {
    /// The figures `[n, FIGURE_DIM]` (metres, [`figures::Figures::plan`]) the arm head reads at
    /// each frame decoded from here on.
    pub fn with_figures(mut self, plan: &ndarray::Array2<f32>) -> Self {
        self.figures = Some(crate::models::to_tensor(plan).unsqueeze(0));
        self
    }

    /// Frames decoded so far (seed poses included).
    pub fn done(&self) -> i64 {
        self.done
    }

    /// Decodes on up to frame `end` of `z` (the song's encoding, or as much of its start as is
    /// decoded: frame i reads `z`'s frame i). `on_step` is called with the fraction of `z` done
    /// after every `report_every`-th frame (0: never) and may stop it: `None`. `sink` collects
    /// what [`DanceRevolution::rollout`] returns.
    pub fn run_to(
        &mut self,
        z: &Tensor,
        end: i64,
        report_every: i64,
        mut on_step: impl FnMut(f32) -> bool,
        mut sink: Option<&mut Vec<(Tensor, Tensor)>>,
    ) -> Option<()> {
        let n = z.size()[1];
        for i in self.done..end.min(n) {
            let figure = self
                .figures
                .as_ref()
                .map(|f| f.narrow(1, i.min(f.size()[1] - 1), 1));
            let (y, emitted, hz) = self.decoder.run_with_input(
                &self.prev,
                &z.narrow(1, i, 1),
                figure.as_ref(),
                &mut self.state,
            );
            if let Some(sink) = sink.as_mut() {
                sink.push((y.shallow_clone(), hz));
            }
            if let Some(w) = self.watch.as_mut() {
                w.observe(&y, &mut self.state);
            }
            self.prev = y;
            self.out.push(emitted);
            self.done = i + 1;
            if report_every > 0
                && (i + 1) % report_every == 0
                && !on_step((i + 1) as f32 / n as f32)
            {
                return None;
            }
        }
        Some(())
    }

    /// The frames decoded so far `[1, done, pose]`.
    pub fn output(&self) -> Tensor {
        if let Some(w) = self.watch.as_ref() {
            tracing::debug!(
                frames = self.done,
                kicked = w.kicked,
                "dance-revolution stall guard"
            );
        }
        Tensor::cat(&self.out, 1)
    }
}
