//! BTR's plain 1-D convolutions, `conv(x) + bias` without a normalisation (the head, its
//! last one through a sigmoid; the ResNet blocks' 1x1 projections when a block is not fused
//! whole), as one custom burn operation on flex.
//!
//! Composed from burn operations this is a broadcast `matmul` and an add. burn runs the
//! matmul's backward pass on the calling thread: two transposed copies and a GEMM whose long
//! reduction (the texel axis) it does not split, so the other core waited; in a profile of
//! the `quick` step that backward pass was a tenth of the main thread's time. Here the
//! convolution and its adjoints are [`kernels`]' (samples in parallel forward and for `dx`,
//! the texel axis split across threads for `dW`), and the bias is added and its gradient
//! summed row by row in parallel.
//!
//! On every backend but flex (`f32`) [`conv_bias`] returns `None` and the caller composes
//! burn operations; `conv1d.rs`'s tests compare both, values and gradients.

use std::sync::Arc;

use burn::backend::Flex;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use super::kernels::{self, ConvDims, sigmoid};
use super::{FlexAutodiff, autodiff_output, contiguous, flex_tensor, values};

/// What [`conv_bias`] applies to `conv(x) + bias`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Output {
    /// Nothing.
    Linear,
    /// The logistic sigmoid (BTR's head, whose texels lie in `(0, 1)`).
    Sigmoid,
}

/// `conv(x) + bias` ("same" zero padding, stride 1), or its sigmoid, on flex; `None`
/// (nothing computed) on other backends or dtypes.
///
/// # Shapes
/// - `x`: `[N, C_in, T]`; `weight`: `[C_out, C_in, K]`, `K` odd; `bias`: `[C_out]`
/// - output: `[N, C_out, T]`
pub(crate) fn conv_bias(
    x: &Tensor<3>,
    weight: &Tensor<3>,
    bias: &Tensor<1>,
    output: Output,
) -> Option<Tensor<3>> {
    let [c_out, c_in, kernel] = weight.dims();
    let [batch, x_channels, len] = x.dims();
    if x_channels != c_in || kernel % 2 == 0 || len == 0 || bias.dims() != [c_out] {
        return None;
    }
    let d = ConvDims {
        batch,
        c_in,
        c_out,
        len,
        kernel,
    };
    let f32s = |ts: &[&FlexTensor]| ts.iter().all(|t| t.dtype() == DType::F32);
    if let Ok(xa) = x.clone().try_into_primitive::<FlexAutodiff>() {
        let w = weight.clone().try_into_primitive::<FlexAutodiff>().ok()?;
        let b = bias.clone().try_into_primitive::<FlexAutodiff>().ok()?;
        if !f32s(&[xa.primitive(), w.primitive(), b.primitive()]) {
            return None;
        }
        let (y, saved) = forward(xa.primitive(), w.primitive(), b.primitive(), d, output);
        let nodes = [xa.node(), w.node(), b.node()];
        return Some(autodiff_output(ConvBiasBackward, nodes, saved, y));
    }
    let xf = x.clone().try_into_primitive::<Flex>().ok()?;
    let wf = weight.clone().try_into_primitive::<Flex>().ok()?;
    let bf = bias.clone().try_into_primitive::<Flex>().ok()?;
    if !f32s(&[&xf, &wf, &bf]) {
        return None;
    }
    Some(Tensor::from_primitive::<Flex>(
        forward(&xf, &wf, &bf, d, output).0,
    ))
}

/// What the backward pass keeps: the contiguous input, the weight's values and, after a
/// sigmoid, the output.
#[derive(Debug, Clone)]
struct Saved {
    x: FlexTensor,
    weight: Arc<Vec<f32>>,
    d: ConvDims,
    sigmoid: Option<FlexTensor>,
}

/// The output `[N, C_out, T]` and the backward pass's state.
fn forward(
    x: &FlexTensor,
    weight: &FlexTensor,
    bias: &FlexTensor,
    d: ConvDims,
    output: Output,
) -> (FlexTensor, Saved) {
    let x = contiguous(x);
    let weight = Arc::new(values(weight));
    let bias = values(bias);
    let mut y = kernels::conv_forward(x.as_slice::<f32>().expect("contiguous f32"), &weight, d);
    y.par_chunks_exact_mut(d.len)
        .enumerate()
        .for_each(|(row, values)| {
            let b = bias[row % d.c_out];
            match output {
                Output::Linear => values.iter_mut().for_each(|v| *v += b),
                Output::Sigmoid => values.iter_mut().for_each(|v| *v = sigmoid(*v + b)),
            }
        });
    let y = flex_tensor(y, [d.batch, d.c_out, d.len]);
    let sigmoid = (output == Output::Sigmoid).then(|| y.clone());
    (
        y,
        Saved {
            x,
            weight,
            d,
            sigmoid,
        },
    )
}

/// The bias gradient: `dy` `[N, C_out, T]` summed over the samples and texels (each row in
/// `f64`, the rows of a channel in sample order).
pub(super) fn bias_gradient(dy: &[f32], d: ConvDims) -> Vec<f32> {
    let rows: Vec<f64> = dy
        .par_chunks_exact(d.len)
        .map(|row| row.iter().map(|&v| f64::from(v)).sum())
        .collect();
    (0..d.c_out)
        .map(|o| (0..d.batch).map(|n| rows[n * d.c_out + o]).sum::<f64>() as f32)
        .collect()
}

#[derive(Debug)]
struct ConvBiasBackward;

impl Backward<Flex, 3> for ConvBiasBackward {
    type State = Saved;

    fn backward(self, ops: Ops<Saved, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_weight, node_bias] = ops.parents;
        let s = ops.state;
        let d = s.d;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        let gy_pre;
        let dy = match &s.sigmoid {
            // Through the sigmoid: `dy = gy y (1 - y)`, one pass on rayon's threads.
            Some(y) => {
                let (gy, y) = (gy.as_slice::<f32>(), y.as_slice::<f32>());
                let (gy, y) = (gy.expect("contiguous f32"), y.expect("contiguous f32"));
                gy_pre = super::rows_by_blocks(d.batch * d.c_out, d.len, |row, from, out| {
                    let at = row * d.len + from;
                    for ((o, &g), &y) in out.iter_mut().zip(&gy[at..]).zip(&y[at..]) {
                        *o = g * (y * (1.0 - y));
                    }
                });
                &gy_pre[..]
            }
            None => gy.as_slice::<f32>().expect("contiguous f32"),
        };
        if let Some(node) = node_bias {
            grads.register::<Flex>(node.id, flex_tensor(bias_gradient(dy, d), [d.c_out]));
        }
        if let Some(node) = node_weight {
            let x = s.x.as_slice::<f32>().expect("contiguous f32");
            let dw = kernels::conv_backward_weight(dy, x, d);
            grads.register::<Flex>(node.id, flex_tensor(dw, [d.c_out, d.c_in, d.kernel]));
        }
        if let Some(node) = node_x {
            let dx = kernels::conv_backward_input(dy, &s.weight, d);
            grads.register::<Flex>(node.id, flex_tensor(dx, [d.batch, d.c_in, d.len]));
        }
    }
}
