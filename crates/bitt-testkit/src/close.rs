//! Reading tensors back and comparing values within a tolerance.

use burn::tensor::Tensor;

/// A tensor's values as `f32`, whatever its float dtype.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("tensor readback")
}

/// Element-wise `|a - b| <= tol * max(1, |b|)`: relative above one, absolute below.
///
/// `what` names the check and the backend (`"{name} dx"`), so a failure says where.
#[track_caller]
pub fn assert_close(a: &[f32], b: &[f32], tol: f32, what: &str) {
    assert_eq!(
        a.len(),
        b.len(),
        "{what}: lengths differ ({} vs {})",
        a.len(),
        b.len()
    );
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * y.abs().max(1.0),
            "{what}: value {i}: {x} vs {y} (tol {tol})"
        );
    }
}
