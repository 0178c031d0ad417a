//! A loss that sees rhythm: the L1 between the magnitude spectra of predicted and real
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

/// `[b, n, 3·joints]`: each joint of `joints` relative to joint `reference`, in the features' own
/// units (`x`: `[b, n, ·]` normalised features whose first columns are root-relative joints, x y z
/// each; `scale`: their std).
pub fn relative_joints(x: &Tensor, scale: &Tensor, joints: &[usize], reference: usize) -> Tensor {
    let columns =
        |j: usize| x.narrow(2, 3 * j as i64, 3) * scale.narrow(0, 3 * j as i64, 3).view([1, 1, 3]);
    let base = columns(reference);
    Tensor::cat(
        &joints
            .iter()
            .map(|&j| columns(j) - &base)
            .collect::<Vec<_>>(),
        2,
    )
}

/// The spectral loss of the arms alone, each joint of `joints` relative to joint `reference`
/// ([`relative_joints`] of `pred` and `truth`). The whole-body term averages the arms' 12 columns
/// among 69, where a held ballroom frame costs little; this one sees only how the arms move
/// against the trunk, which is what `metrics::musicality::arm_speed_m_s` measures.
pub fn relative_spectral_loss(
    pred: &Tensor,
    truth: &Tensor,
    scale: &Tensor,
    joints: &[usize],
    reference: usize,
    fps: f64,
) -> Tensor {
    let relative = |x: &Tensor| relative_joints(x, scale, joints, reference);
    let ones = Tensor::ones([3 * joints.len() as i64], (Kind::Float, pred.device()));
    spectral_loss(&relative(pred), &relative(truth), &ones, fps)
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

    #[test]
    fn arms_swaying_with_the_trunk_cost_their_energy_against_arms_swaying_on_their_own() {
        // Two joints: 0 is the trunk, 1 an arm. Real: the arm sways, the trunk holds. Prediction:
        // both sway together, so the arm is held against the trunk.
        let n = 250;
        let sway1 = sway(1.0, 0.1, 0.0, n);
        let zeros = sway1.zeros_like();
        let joint = |x: &Tensor| {
            Tensor::cat(
                &[
                    x.shallow_clone(),
                    zeros.shallow_clone(),
                    zeros.shallow_clone(),
                ],
                2,
            )
        };
        let real = Tensor::cat(&[joint(&zeros), joint(&sway1)], 2);
        let together = Tensor::cat(&[joint(&sway1), joint(&sway1)], 2);
        let scale = Tensor::ones([6], (Kind::Float, tch::Device::Cpu));
        let arms =
            |p: &Tensor| relative_spectral_loss(p, &real, &scale, &[1], 0, 25.0).double_value(&[]);
        assert!(arms(&real) < 1e-6);
        // Relative to the trunk, the arm carried along by the trunk is as still as an arm held
        // with the whole body still.
        let still = arms(&real.zeros_like());
        assert!(still > 0.0);
        assert!(
            (arms(&together) - still).abs() < 1e-3 * still,
            "together {} still {still}",
            arms(&together)
        );
        let phase_shifted = Tensor::cat(&[joint(&zeros), joint(&sway(1.0, 0.1, 2.0, n))], 2);
        assert!(
            arms(&phase_shifted) < 0.1 * arms(&together),
            "shifted {} together {}",
            arms(&phase_shifted),
            arms(&together)
        );
    }
}
