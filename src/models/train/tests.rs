use super::*;

/// A network given two more input columns, initialised from the narrower one's weights,
/// computes exactly what it did while those columns are anything at all times zero weights:
/// on inputs whose new columns are zero the outputs are equal.
#[test]
fn widened_weights_compute_what_the_narrow_ones_did() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("narrow.safetensors");
    let narrow_vs = nn::VarStore::new(Device::Cpu);
    let narrow = nn::linear(narrow_vs.root() / "embed", 3, 4, Default::default());
    narrow_vs.save(&path).unwrap();
    let wide_vs = nn::VarStore::new(Device::Cpu);
    let wide = nn::linear(wide_vs.root() / "embed", 5, 4, Default::default());
    assert_eq!(
        load_widened(&wide_vs, &path).unwrap(),
        vec!["embed.weight".to_string()]
    );
    let x = Tensor::from_slice(&[0.5f32, -1.0, 2.0]).view([1, 3]);
    let x_wide = Tensor::from_slice(&[0.5f32, -1.0, 2.0, 0.0, 0.0]).view([1, 5]);
    use tch::nn::Module;
    let (a, b) = (narrow.forward(&x), wide.forward(&x_wide));
    assert!((a - b).abs().max().double_value(&[]) < 1e-6);
    // A shape that is not a widening is refused by name.
    let other_vs = nn::VarStore::new(Device::Cpu);
    let _ = nn::linear(other_vs.root() / "embed", 2, 4, Default::default());
    let err = load_widened(&other_vs, &path).unwrap_err().to_string();
    assert!(err.contains("embed.weight"), "{err}");
}
