//! BTR's encoder downsampling, max pooling by 2 along the texel axis, as one custom burn
//! operation on flex with a hand-written backward pass.
//!
//! burn's `max_pool1d` runs as a 3-D pooling with `i64` argmax indices, and its backward pass
//! scatters through them: at the `quick` preset that was about 6 % of a training step. Here
//! the forward pass keeps one byte per output (which of the two texels won) and the backward
//! pass writes every input gradient once, row by row in parallel. Ties go to the first texel
//! of the pair, as in burn's pooling; an odd last texel is dropped (gradient zero).
//!
//! On every backend but flex (`f32`) [`max_pool_half`] returns `None` and the caller uses
//! burn's `max_pool1d`; tests compare both, values and gradients.

use burn::backend::Flex;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use super::{FlexAutodiff, autodiff_output, contiguous, flex_tensor};

/// Max pooling with window and stride 2 along the last axis, on flex; `None` (nothing
/// computed) on other backends or dtypes.
///
/// # Shapes
/// - `x`: `[N, C, L]`, `L >= 2`
/// - output: `[N, C, floor(L / 2)]`
pub(crate) fn max_pool_half(x: &Tensor<3>) -> Option<Tensor<3>> {
    let [batch, channels, len] = x.dims();
    if len < 2 {
        return None;
    }
    let dims = PoolDims {
        rows: batch * channels,
        len,
        shape: [batch, channels, len],
    };
    if let Ok(xa) = x.clone().try_into_primitive::<FlexAutodiff>() {
        if xa.primitive().dtype() != DType::F32 {
            return None;
        }
        let (y, picks) = forward(xa.primitive(), dims);
        return Some(autodiff_output(
            MaxPoolHalfBackward,
            [xa.node()],
            (picks, dims),
            y,
        ));
    }
    let xf = x.clone().try_into_primitive::<Flex>().ok()?;
    if xf.dtype() != DType::F32 {
        return None;
    }
    Some(Tensor::from_primitive::<Flex>(forward(&xf, dims).0))
}

/// The input's size: `rows` rows of `len` texels, `shape` `[N, C, L]`.
#[derive(Debug, Clone, Copy)]
struct PoolDims {
    rows: usize,
    len: usize,
    shape: [usize; 3],
}

/// The output `[N, C, L / 2]` and, per output, whether the second texel of its pair won.
fn forward(x: &FlexTensor, d: PoolDims) -> (FlexTensor, Vec<bool>) {
    let x = contiguous(x);
    let (y, picks) = pool_rows(x.as_slice::<f32>().expect("contiguous f32"), d.rows, d.len);
    let [n, c, l] = d.shape;
    (flex_tensor(y, [n, c, l / 2]), picks)
}

/// The pooling on a row-major `[rows, len]` slice: outputs `[rows, len / 2]` and the picks.
fn pool_rows(x: &[f32], rows: usize, len: usize) -> (Vec<f32>, Vec<bool>) {
    let half = len / 2;
    let mut y = super::zeros(rows * half);
    let mut picks = vec![false; rows * half];
    if half == 0 {
        return (y, picks);
    }
    y.par_chunks_exact_mut(half)
        .zip(picks.par_chunks_exact_mut(half))
        .zip(x.par_chunks_exact(len))
        .for_each(|((yr, pr), xr)| {
            for ((y, p), pair) in yr.iter_mut().zip(pr).zip(xr.chunks_exact(2)) {
                // `>`: a tie keeps the first texel, as burn's pooling does.
                *p = pair[1] > pair[0];
                *y = if *p { pair[1] } else { pair[0] };
            }
        });
    (y, picks)
}

/// The input gradient `[rows, len]` from the output gradient `[rows, len / 2]`: each output's
/// gradient goes to the texel that won, zero elsewhere.
fn unpool_rows(g: &[f32], picks: &[bool], rows: usize, len: usize) -> Vec<f32> {
    let half = len / 2;
    let mut dx = super::zeros(rows * len);
    if half == 0 {
        return dx;
    }
    dx.par_chunks_exact_mut(len)
        .zip(g.par_chunks_exact(half))
        .zip(picks.par_chunks_exact(half))
        .for_each(|((dr, gr), pr)| {
            for ((pair, &g), &p) in dr.chunks_exact_mut(2).zip(gr).zip(pr) {
                pair[usize::from(p)] = g;
            }
        });
    dx
}

#[derive(Debug)]
struct MaxPoolHalfBackward;

impl Backward<Flex, 1> for MaxPoolHalfBackward {
    type State = (Vec<bool>, PoolDims);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let (picks, d) = ops.state;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        if let Some(node) = node_x {
            let g = gy.as_slice::<f32>().expect("contiguous f32");
            let dx = unpool_rows(g, &picks, d.rows, d.len);
            grads.register::<Flex>(node.id, flex_tensor(dx, d.shape));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::module::max_pool1d;
    use burn::tensor::ops::MaxPoolOptions;
    use burn::tensor::{Device, TensorData};

    fn burn_pool(x: Tensor<3>) -> Tensor<3> {
        max_pool1d(x, MaxPoolOptions::new([2]).with_stride([2]))
    }

    fn values(t: Tensor<3>) -> Vec<f32> {
        bitt_testkit::to_vec(t)
    }

    /// Inputs with ties (repeated values) and both parities of `L`.
    fn input(shape: [usize; 3], device: &Device) -> Tensor<3> {
        let n = shape.iter().product::<usize>();
        let v: Vec<f32> = (0..n)
            .map(|i| ((i * 37 + 11) % 23) as f32 / 7.0 - 1.5)
            .collect();
        Tensor::from_data(TensorData::new(v, shape), device)
    }

    #[test]
    fn pooling_matches_burn_values_and_gradients() {
        let device = Device::flex().autodiff();
        for shape in [[2, 3, 8], [1, 2, 9], [3, 1, 2], [2, 4, 101]] {
            let x = input(shape, &device).require_grad();
            let ours = max_pool_half(&x).expect("runs on flex");
            let theirs = burn_pool(x.clone());
            assert_eq!(values(ours.clone()), values(theirs.clone()), "{shape:?}");
            // A weighted sum so that every output's gradient differs.
            let [n, c, h] = ours.dims();
            let w = input([n, c, h], &device).detach() + 2.0;
            let g_ours = (ours * w.clone()).sum().backward();
            let g_theirs = (theirs * w).sum().backward();
            let a = x.grad(&g_ours).expect("gradient");
            let b = x.grad(&g_theirs).expect("gradient");
            assert_eq!(values(a), values(b), "{shape:?}");
        }
    }

    #[test]
    fn pooling_runs_without_autodiff_and_declines_off_flex() {
        let x = input([2, 3, 7], &Device::flex());
        let ours = max_pool_half(&x).expect("runs on flex");
        assert_eq!(values(ours), values(burn_pool(x)));
        for (name, plain) in bitt_testkit::devices()
            .into_iter()
            .filter(|(n, _)| *n != "flex")
        {
            for device in [plain.clone(), plain.autodiff()] {
                assert!(
                    max_pool_half(&input([2, 3, 7], &device)).is_none(),
                    "{name}"
                );
            }
        }
        assert!(max_pool_half(&input([1, 1, 1], &Device::flex())).is_none());
    }

    #[test]
    fn ties_keep_the_first_texel_and_odd_texels_get_no_gradient() {
        let (y, picks) = pool_rows(&[1.0, 1.0, 2.0, 3.0, 5.0, 4.0, 9.0], 1, 7);
        assert_eq!(y, [1.0, 3.0, 5.0]);
        assert_eq!(picks, [false, true, false]);
        let dx = unpool_rows(&[10.0, 20.0, 30.0], &picks, 1, 7);
        assert_eq!(dx, [10.0, 0.0, 0.0, 20.0, 30.0, 0.0, 0.0]);
    }
}
