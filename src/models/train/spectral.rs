//! A loss that sees rhythm (issue 25): the L1 between the magnitude spectra of predicted and real
//! velocities over a window.
//!
//! A pose loss is met best by the mean of what may come next; where the timing of a movement is
//! uncertain that mean is a held pose (dance-revolution's frozen arms) or a slow drift (DanceNet
//! stepping every 5–10 beats). A magnitude spectrum does not see phase, so a movement whose timing
//! the network cannot be sure of still earns its energy at the frequency the real dance has it,
//! which is a fixed fraction of the song's beat; energy the real dance lacks (shaking, a step rate
//! of its own) costs as much as energy it has and the prediction does not.
use tch::{Kind, Tensor};

/// Mean L1 between the magnitude spectra (m/s per frequency bin; Hann window over the whole
/// window) of the frame-to-frame velocities of `pred` and `truth` `[b, n, ·]`, over their first
/// `scale.len()` columns multiplied by `scale` (the normalisation's std, so the spectra are in
/// the features' own units per second).
pub fn spectral_loss(pred: &Tensor, truth: &Tensor, scale: &Tensor, fps: f64) -> Tensor {
    let dims = scale.size()[0];
    let n = pred.size()[1];
    let hann = Tensor::hann_window_periodic(n - 1, false, (Kind::Float, pred.device()));
    // A sinusoid's amplitude at its bin is |X| · 2 / Σ window.
    let to_amplitude = 2.0 / hann.sum(Kind::Float).double_value(&[]) * fps;
    let spectrum = |x: &Tensor| {
        let units = x.narrow(2, 0, dims) * scale.view([1, 1, dims]);
        let velocity = units.narrow(1, 1, n - 1) - units.narrow(1, 0, n - 1);
        (velocity * hann.view([1, n - 1, 1]))
            .fft_rfft(None::<i64>, 1, "backward")
            .abs()
            * to_amplitude
    };
    (spectrum(pred) - spectrum(truth)).abs().mean(Kind::Float)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sway(hz: f64, amplitude: f64, phase: f64, n: i64) -> Tensor {
        let t = Tensor::arange(n, (Kind::Float, tch::Device::Cpu)) / 25.0;
        ((t * (2.0 * std::f64::consts::PI * hz) + phase).sin() * amplitude).view([1, n, 1])
    }

    #[test]
    fn a_movement_at_the_real_rate_costs_little_whatever_its_phase_and_a_held_pose_costs_its_energy(
    ) {
        let scale = Tensor::from_slice(&[1.0f32]);
        let real = sway(1.0, 0.1, 0.0, 250);
        let shifted =
            spectral_loss(&sway(1.0, 0.1, 1.3, 250), &real, &scale, 25.0).double_value(&[]);
        let held =
            spectral_loss(&(real.zeros_like() + 0.05), &real, &scale, 25.0).double_value(&[]);
        let other_rate =
            spectral_loss(&sway(1.7, 0.1, 0.0, 250), &real, &scale, 25.0).double_value(&[]);
        // The pose L1 of the shifted copy is larger than the held pose's; the spectrum orders them
        // the other way.
        let l1 = |a: &Tensor| (a - &real).abs().mean(Kind::Float).double_value(&[]);
        assert!(l1(&sway(1.0, 0.1, 1.3, 250)) > l1(&(real.zeros_like() + 0.05)));
        assert!(shifted < 0.1 * held, "shifted {shifted}, held {held}");
        assert!(
            other_rate > 0.5 * held,
            "other rate {other_rate}, held {held}"
        );
    }
}
