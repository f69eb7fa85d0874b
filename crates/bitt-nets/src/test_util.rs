//! Helpers shared by this crate's unit tests.

use burn::tensor::{Device, Tensor, TensorData};

/// The CPU devices every numeric test runs on.
#[allow(deprecated)] // burn-ndarray is deprecated but still a supported backend here
pub(crate) fn devices() -> Vec<(&'static str, Device)> {
    vec![("flex", Device::flex()), ("ndarray", Device::ndarray())]
}

/// A tensor's values as `f32`.
pub(crate) fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("tensor readback")
}

/// Deterministic values in `[-1, 1)` (SplitMix64), the same bits on every backend.
pub(crate) fn random<const D: usize>(shape: [usize; D], seed: u64, device: &Device) -> Tensor<D> {
    let n = shape.iter().product();
    let mut state = seed.wrapping_mul(0x2545_F491_4F6C_DD1D);
    let values: Vec<f32> = (0..n)
        .map(|_| {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            2.0 * ((z >> 40) as f32 / (1u64 << 24) as f32) - 1.0
        })
        .collect();
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// Element-wise `|a - b| <= tol * max(1, |b|)`.
pub(crate) fn assert_close(a: &[f32], b: &[f32], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths differ");
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * y.abs().max(1.0),
            "{what}: value {i}: {x} vs {y} (tol {tol})"
        );
    }
}

/// Every float parameter's gradient, in visiting order (empty where there is none).
pub(crate) fn param_grads<M: burn::module::Module>(
    module: &M,
    grads: &burn::tensor::Gradients,
) -> Vec<Vec<f32>> {
    struct Collect<'a> {
        grads: &'a burn::tensor::Gradients,
        out: Vec<Vec<f32>>,
    }
    impl burn::module::ModuleVisitor for Collect<'_> {
        fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
            let g = param.val().grad(self.grads).map(to_vec).unwrap_or_default();
            self.out.push(g);
        }
    }
    let mut c = Collect {
        grads,
        out: Vec::new(),
    };
    module.visit(&mut c);
    c.out
}

/// [`assert_close`] over lists of gradients.
pub(crate) fn assert_all_close(a: &[Vec<f32>], b: &[Vec<f32>], tol: f32, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: counts differ");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(!y.is_empty(), "{what}: parameter {i} has no gradient");
        assert_close(x, y, tol, &format!("{what}: parameter {i}"));
    }
}
