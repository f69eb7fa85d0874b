//! Tensors read back to the host: the one way every crate turns a burn tensor into numbers.

use burn::tensor::Tensor;

/// A tensor whose data could not be read back from its device (a failed device, a dtype
/// that does not convert), said in burn's words.
#[derive(Debug, thiserror::Error)]
#[error("reading a tensor back: {0}")]
pub struct ReadBackError(pub String);

/// The values of `t` as `f32`, in row-major order (whatever its dtype on the device).
///
/// # Errors
/// [`ReadBackError`] when the device cannot give the data back.
pub fn to_host<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>, ReadBackError> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| ReadBackError(format!("{e:?}")))
}
