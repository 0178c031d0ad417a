//! The export's rigid fit keeps the joint angles a dance was given: authenticity and coherence
//! ([`choreo::metrics::plausibility`]) of the served motion within 0.02 of the dance's own, on
//! real dances and on the same dances with their upper arms drawn at a length that changes from
//! frame to frame, as networks draw them (dance-revolution's upper arm measures 8–47 cm over one
//! song; fixed at its median, the elbow moved 7 cm and the 13-cm elbow → forearm bone that swung
//! to reach its target from there took the authenticity from 0.74 to 0.32).

use choreo::metrics::plausibility::{plausibility, Plausibility};
use choreo::metrics::reference::ReferenceStats;
use choreo::motion::Motion;

#[path = "common/dataset.rs"]
mod common_dataset;
use common_dataset::dataset;

/// Upper arms (shoulder → elbow) and everything below them, per side.
const ARMS: [(usize, usize, &[usize]); 2] = [(3, 4, &[4, 5, 6, 22]), (12, 13, &[13, 14, 15, 21])];

/// `motion` with each upper arm stretched and shrunk by up to 40 % over a 1.6-s cycle, the joints
/// below it carried along unturned: every joint angle is the dance's own, only the bone lengths
/// change.
fn with_breathing_arms(motion: &Motion) -> Motion {
    let mut out = motion.clone();
    for t in 0..motion.num_frames() {
        let phase = 2.0 * std::f32::consts::PI * t as f32 / (1.6 * motion.fps as f32);
        for (side, &(shoulder, elbow, below)) in ARMS.iter().enumerate() {
            let stretch = 0.4 * (phase + side as f32).sin();
            let shift: Vec<f32> = (0..3)
                .map(|c| {
                    stretch * (motion.positions[[t, elbow, c]] - motion.positions[[t, shoulder, c]])
                })
                .collect();
            for &j in below {
                for (c, d) in shift.iter().enumerate() {
                    out.positions[[t, j, c]] += d;
                }
            }
        }
    }
    out
}

fn served_plausibility(dance: &Motion, reference: &ReferenceStats) -> (Plausibility, Plausibility) {
    let limits = &reference.angle_limits;
    let served = choreo::motion::serve(dance, &[], false, 0).expect("rigid fit");
    (
        plausibility(dance.positions.view(), dance.fps, limits),
        plausibility(served.motion.positions.view(), served.motion.fps, limits),
    )
}

#[test]
fn rigid_fit_keeps_authenticity_and_coherence() {
    let Some(ds) = dataset() else { return };
    let reference = ReferenceStats::builtin().expect("reference");
    let mut worst: f64 = 0.0;
    for id in ds.test_ids().iter().take(4) {
        let dance = ds.load(id).expect("load").motion;
        for (what, m) in [
            ("real", dance.clone()),
            ("arms", with_breathing_arms(&dance)),
        ] {
            let (given, served) = served_plausibility(&m, &reference);
            eprintln!(
                "{id} {what}: authenticity {:.3} → {:.3}, coherence {:.3} → {:.3}",
                given.authenticity, served.authenticity, given.coherence, served.coherence
            );
            worst = worst
                .max(given.authenticity - served.authenticity)
                .max(given.coherence - served.coherence);
        }
    }
    assert!(
        worst <= 0.02,
        "the rigid fit makes a dance {worst:.3} less real"
    );
}
