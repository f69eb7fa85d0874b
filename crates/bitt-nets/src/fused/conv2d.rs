//! `act(InstanceNorm(conv2d(x) + bias))` as one custom burn operation on flex, with a
//! hand-written backward pass: the convolutions of the albedo U-Net and of the stride-2
//! image encoders.
//!
//! burn's composition (conv2d, then instance norm as group norm, then the activation)
//! allocates and walks several buffers of the output's size each way; [`conv2d_norm_act`]
//! runs the convolution as tiled im2col + GEMM ([`super::kernels2d`]) and the norm and
//! activation as one pass per row after the moments. It keeps its input `x` and the
//! convolution output `z` (with bias) for the backward pass, which is two row passes for
//! the norm and activation, then per tile one GEMM for `dW` and one (+ col2im) for `dx`.
//!
//! As for BTR's block (`super::conv_norm_silu`), the operation runs when every tensor lives
//! on flex (with or without autodiff) in `f32`; elsewhere it returns `None` and the caller
//! composes burn operations, which compute the same function (tests compare values and every
//! gradient).

use std::sync::Arc;

use burn::backend::Flex;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::Tensor;

use super::kernels2d::{self, Conv2dDims, PostDims, RowStats};
use super::{
    contiguous, flex_tensor, output_gradient_buffer, register_channel_grads, run_on_flex, values,
};

pub(crate) use super::kernels2d::Activation;

/// An instance norm after the convolution.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Norm2d<'a> {
    pub epsilon: f64,
    /// `(gamma, beta)`, each `[C_out]`, when the norm is affine.
    pub affine: Option<(&'a Tensor<1>, &'a Tensor<1>)>,
}

/// One block: a convolution (symmetric zero padding, no dilation or groups), its optional
/// bias, an optional instance norm and an activation.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Conv2dBlock<'a> {
    /// `[C_out, C_in, kh, kw]`.
    pub weight: &'a Tensor<4>,
    /// `[C_out]`.
    pub bias: Option<&'a Tensor<1>>,
    pub stride: [usize; 2],
    pub padding: [usize; 2],
    pub norm: Option<Norm2d<'a>>,
    pub act: Activation,
}

#[cfg(test)]
thread_local! {
    /// Tests switch the operation off to compare a network with its burn composition.
    static DISABLED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with [`conv2d_norm_act`] and the resampling operations
/// ([`super::resample`]) declining on this thread (tests).
#[cfg(test)]
pub(crate) fn without_fusion<T>(f: impl FnOnce() -> T) -> T {
    DISABLED.with(|d| d.set(true));
    let out = f();
    DISABLED.with(|d| d.set(false));
    out
}

/// Whether [`without_fusion`] is running on this thread.
#[cfg(test)]
pub(crate) fn fusion_disabled() -> bool {
    DISABLED.with(|d| d.get())
}

/// `act(InstanceNorm(conv2d(x, weight) + bias))` on flex; `None` (nothing computed) on other
/// backends or dtypes, or sizes the convolution does not support.
///
/// # Shapes
/// - `x`: `[B, C_in, H, W]`
/// - output: `[B, C_out, OH, OW]`, `OH = (H + 2 padding - kh) / stride + 1` (and `OW`)
pub(crate) fn conv2d_norm_act(x: &Tensor<4>, block: &Conv2dBlock<'_>) -> Option<Tensor<4>> {
    #[cfg(test)]
    if DISABLED.with(|d| d.get()) {
        return None;
    }
    let [c_out, c_in, kh, kw] = block.weight.dims();
    let [batch, x_channels, h, w] = x.dims();
    let conv = Conv2dDims {
        batch,
        c_in,
        c_out,
        size: [h, w],
        kernel: [kh, kw],
        stride: block.stride,
        padding: block.padding,
    };
    let [oh, ow] = conv.out_size()?;
    if x_channels != c_in || block.bias.is_some_and(|b| b.dims() != [c_out]) {
        return None;
    }
    let post = PostDims {
        batch,
        channels: c_out,
        len: oh * ow,
        norm: block.norm.map(|n| n.epsilon),
        act: block.act,
    };
    let device = x.device();
    // Absent parameters as constants (untracked, so no gradient is registered for them).
    let bias = block
        .bias
        .cloned()
        .unwrap_or_else(|| Tensor::zeros([c_out], &device));
    let (gamma, beta) = match block.norm.and_then(|n| n.affine) {
        Some((g, b)) => (g.clone(), b.clone()),
        None => (
            Tensor::ones([c_out], &device),
            Tensor::zeros([c_out], &device),
        ),
    };
    let meta = Meta {
        conv,
        post,
        has_bias: block.bias.is_some(),
    };
    run_on_flex(
        x,
        block.weight,
        [&bias, &gamma, &beta],
        Conv2dNormActBackward,
        |x, params| forward(x, params, meta),
    )
}

/// The sizes of one call.
#[derive(Debug, Clone, Copy)]
struct Meta {
    conv: Conv2dDims,
    post: PostDims,
    has_bias: bool,
}

impl Meta {
    fn out_shape(&self) -> [usize; 4] {
        let [oh, ow] = self.conv.out_size().expect("checked sizes");
        [self.conv.batch, self.conv.c_out, oh, ow]
    }
}

/// The forward pass on flex tensors (all `f32`).
fn forward(
    x: &FlexTensor,
    [weight, bias, gamma, beta]: [&FlexTensor; 4],
    meta: Meta,
) -> (FlexTensor, Saved) {
    let x = contiguous(x);
    // The weight is shared, not copied (the U-Net's inner ones are 16 MiB each).
    let weight = contiguous(weight);
    let [bias, gamma, beta] = [bias, gamma, beta].map(|t| Arc::new(values(t)));
    let bias_values: &[f32] = if meta.has_bias { &bias } else { &[] };
    let z = kernels2d::conv2d_forward(
        x.as_slice::<f32>().expect("contiguous f32"),
        weight.as_slice::<f32>().expect("contiguous f32"),
        bias_values,
        meta.conv,
    );
    let (y, stats) = kernels2d::post_forward(&z, &gamma, &beta, meta.post);
    let y = flex_tensor(y, meta.out_shape());
    let saved = Saved {
        x,
        weight,
        gamma,
        beta,
        meta,
        z: Arc::new(z),
        stats: Arc::new(stats),
    };
    (y, saved)
}

/// What the backward pass keeps.
#[derive(Debug, Clone)]
struct Saved {
    /// Contiguous `f32` input `[B, C_in, H, W]`.
    x: FlexTensor,
    /// Contiguous `f32` weight `[C_out, C_in, kh, kw]`.
    weight: FlexTensor,
    gamma: Arc<Vec<f32>>,
    beta: Arc<Vec<f32>>,
    meta: Meta,
    /// Convolution output with bias, `[B, C_out, OH, OW]`.
    z: Arc<Vec<f32>>,
    stats: Arc<RowStats>,
}

#[derive(Debug)]
struct Conv2dNormActBackward;

impl Backward<Flex, 5> for Conv2dNormActBackward {
    type State = Saved;

    fn backward(self, ops: Ops<Saved, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_weight, node_bias, node_gamma, node_beta] = ops.parents;
        let s = ops.state;
        let mut gy = contiguous(&grads.consume::<Flex>(&ops.node));
        let mut buffer = output_gradient_buffer(&mut gy, s.z.len());
        let dz = buffer.as_mut_slice();
        let [dbias, dgamma, dbeta] =
            kernels2d::post_backward_in_place(dz, &s.z, &s.gamma, &s.beta, &s.stats, s.meta.post);
        let dz: &[f32] = dz;
        register_channel_grads(
            grads,
            [node_bias, node_gamma, node_beta].map(|n| n.map(|n| n.id)),
            [dbias, dgamma, dbeta],
        );
        let c_out = s.meta.conv.c_out;
        let d = s.meta.conv;
        let (dx, dw) = kernels2d::conv2d_backward(
            dz,
            s.x.as_slice::<f32>().expect("contiguous f32"),
            s.weight.as_slice::<f32>().expect("contiguous f32"),
            d,
            node_x.is_some(),
            node_weight.is_some(),
        );
        if let (Some(node), Some(dw)) = (node_weight, dw) {
            grads.register::<Flex>(
                node.id,
                flex_tensor(dw, [c_out, d.c_in, d.kernel[0], d.kernel[1]]),
            );
        }
        if let (Some(node), Some(dx)) = (node_x, dx) {
            grads.register::<Flex>(
                node.id,
                flex_tensor(dx, [d.batch, d.c_in, d.size[0], d.size[1]]),
            );
        }
    }
}
