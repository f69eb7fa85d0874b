//! The 1-D convolution of BTR (paper Sec. 3.3, supplement D), written as matrix products.
//!
//! BTR convolves texel vectors of length `T = 206,330` at 16-256 channels. burn's generic
//! `conv1d` (an im2col + GEMM over a 3-D convolution with two unit dimensions) and its
//! backward are much slower than plain GEMMs on CPU (flex: 1.7x for the whole BTR), so
//! [`TexelConv`] computes the same function with matrix products over shifted views of the
//! zero-padded input: one product per kernel tap, summed ([`ConvImpl::ShiftedSum`], the
//! default and the fastest on flex), or one product over the stacked views ("im2col" along
//! the texel axis, [`ConvImpl::Im2col`]):
//!
//! ```text
//! y[b, o, t] = bias[o] + sum_{k, c} w[o, c, k] * x_pad[b, c, t + k]
//!            = bias[o] + (W' X_k)[b, o, t],  W' = w as [C_out, K * C_in] (k major),
//!                                           X_k = [x_pad[.., k .. k + T] for k] as [B, K * C_in, T]
//! ```
//!
//! Only differentiable tensor ops are used (pad, slice, cat, matmul, add), so the autodiff
//! gradients are exact; a test checks values and gradients against burn's `conv1d`. The
//! parameters are those of a `torch.nn.Conv1d` (`weight [C_out, C_in, K]`, `bias [C_out]`),
//! with PyTorch's default initialisation (uniform in `±1/sqrt(C_in K)`).

use burn::config::Config;
use burn::module::{Module, Param};
use burn::nn::Initializer;
use burn::tensor::activation::sigmoid;
use burn::tensor::module::conv1d;
use burn::tensor::ops::{ConvOptions, PadMode};
use burn::tensor::{Device, Tensor};

use crate::fused::conv_bias::{Output, conv_bias};

/// How [`TexelConv`] evaluates the convolution. All variants compute the same function with
/// the same parameters; they differ only in speed.
#[derive(Config, Debug, PartialEq, Eq, Copy)]
pub enum ConvImpl {
    /// One matrix product over the stacked shifted views (im2col along the texel axis).
    Im2col,
    /// One matrix product per kernel tap, summed.
    ShiftedSum,
    /// burn's `conv1d` (reference; slow on CPU at BTR's sizes).
    Burn,
    /// When the tensors live on flex (the CPU default; see `fused`): each of BTR's ResNet
    /// blocks (convolutions, group norms, SiLU, residual) runs as one custom operation with a
    /// hand-written backward pass, and a plain convolution plus bias as another; elsewhere as
    /// [`ConvImpl::ShiftedSum`]. The default.
    Fused,
}

/// Configuration of a [`TexelConv`]: a stride-1, "same"-padded 1-D convolution with bias.
#[derive(Config, Debug)]
pub struct TexelConvConfig {
    /// Input channels.
    pub channels_in: usize,
    /// Output channels.
    pub channels_out: usize,
    /// Kernel size; odd, padded by `kernel_size / 2` zeros on each side (BTR uses 3 and 1).
    pub kernel_size: usize,
    /// How the convolution is evaluated.
    #[config(default = "ConvImpl::Fused")]
    pub implementation: ConvImpl,
}

/// A stride-1, zero-padded ("same" length) 1-D convolution with bias, see the module docs.
#[derive(Module, Debug)]
pub struct TexelConv {
    /// `[channels_out, channels_in, kernel_size]`, as `torch.nn.Conv1d`.
    pub weight: Param<Tensor<3>>,
    /// `[channels_out]`.
    pub bias: Param<Tensor<1>>,
    /// How the convolution is evaluated.
    #[module(skip)]
    pub implementation: ConvImpl,
}

impl TexelConvConfig {
    /// Creates the layer with PyTorch's default initialisation.
    ///
    /// # Panics
    /// When `kernel_size` is even or a size is zero.
    pub fn init(&self, device: &Device) -> TexelConv {
        assert!(
            !self.kernel_size.is_multiple_of(2) && self.channels_in > 0 && self.channels_out > 0,
            "TexelConv needs an odd kernel and non-zero channels: {self:?}"
        );
        let fan_in = self.channels_in * self.kernel_size;
        let init = Initializer::KaimingUniform {
            gain: 1.0 / 3.0f64.sqrt(),
            fan_out_only: false,
        };
        TexelConv {
            weight: init.init_with(
                [self.channels_out, self.channels_in, self.kernel_size],
                Some(fan_in),
                Some(self.channels_out * self.kernel_size),
                device,
            ),
            bias: init.init_with([self.channels_out], Some(fan_in), None, device),
            implementation: self.implementation,
        }
    }
}

impl TexelConv {
    /// Convolves `x` along its last axis.
    ///
    /// # Shapes
    /// - `x`: `[B, C_in, T]`
    /// - output: `[B, C_out, T]` (same length: zero padding `kernel_size / 2` on each side)
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let c_out = self.bias.dims()[0];
        if self.implementation == ConvImpl::Burn {
            let pad = self.weight.dims()[2] / 2;
            return conv1d(
                x,
                self.weight.val(),
                Some(self.bias.val()),
                ConvOptions::new([1], [pad], [1], 1),
            );
        }
        if self.implementation == ConvImpl::Fused
            && let Some(y) = conv_bias(&x, &self.weight.val(), &self.bias.val(), Output::Linear)
        {
            return y;
        }
        self.forward_without_bias(x) + self.bias.val().reshape([1, c_out, 1])
    }

    /// `sigmoid(self.forward(x))`, as one operation with [`ConvImpl::Fused`] on flex.
    ///
    /// # Shapes
    /// - `x`: `[B, C_in, T]`
    /// - output: `[B, C_out, T]`, in `(0, 1)`
    pub fn forward_sigmoid(&self, x: Tensor<3>) -> Tensor<3> {
        if self.implementation == ConvImpl::Fused
            && let Some(y) = conv_bias(&x, &self.weight.val(), &self.bias.val(), Output::Sigmoid)
        {
            return y;
        }
        sigmoid(self.forward(x))
    }

    /// The convolution without the bias term (callers that fold the bias into a following
    /// normalisation, see `btr`).
    ///
    /// # Shapes
    /// - `x`: `[B, C_in, T]`
    /// - output: `[B, C_out, T]`
    pub(crate) fn forward_without_bias(&self, x: Tensor<3>) -> Tensor<3> {
        let weight = self.weight.val();
        let [c_out, c_in, k] = weight.dims();
        let t = x.dims()[2];
        let pad = k / 2;
        match self.implementation {
            ConvImpl::Burn => conv1d(x, weight, None, ConvOptions::new([1], [pad], [1], 1)),
            ConvImpl::Im2col => {
                // [C_out, C_in, K] -> [C_out, K, C_in] -> [1, C_out, K * C_in]
                let w = weight.swap_dims(1, 2).reshape([1, c_out, k * c_in]);
                let cols = if k == 1 {
                    x
                } else {
                    let xp = x.pad([(pad, pad)], PadMode::Constant(0.0));
                    let views = (0..k).map(|j| xp.clone().narrow(2, j, t)).collect();
                    Tensor::cat(views, 1)
                };
                w.matmul(cols)
            }
            ConvImpl::ShiftedSum | ConvImpl::Fused => {
                let xp = if k == 1 {
                    x
                } else {
                    x.pad([(pad, pad)], PadMode::Constant(0.0))
                };
                let mut acc: Option<Tensor<3>> = None;
                for j in 0..k {
                    let wj = weight.clone().narrow(2, j, 1).reshape([1, c_out, c_in]);
                    let yj = wj.matmul(xp.clone().narrow(2, j, t));
                    acc = Some(match acc {
                        Some(a) => a + yj,
                        None => yj,
                    });
                }
                acc.expect("kernel_size >= 1")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::{assert_close, devices, random, to_vec};

    /// Values and gradients (input, weight, bias) of the matmul forms equal burn's conv1d,
    /// plain and through a sigmoid ([`TexelConv::forward_sigmoid`]).
    #[test]
    fn matmul_conv_matches_burn_conv1d_values_and_gradients() {
        for (name, device) in devices() {
            let ad = device.clone().autodiff();
            for &(c_in, c_out, k, t) in &[(3, 8, 3, 11), (5, 4, 1, 7), (4, 6, 3, 1), (2, 3, 5, 9)] {
                for through_sigmoid in [false, true] {
                    let mut reference: Option<[Vec<f32>; 4]> = None;
                    for implementation in [
                        ConvImpl::Burn,
                        ConvImpl::Im2col,
                        ConvImpl::ShiftedSum,
                        ConvImpl::Fused,
                    ] {
                        let conv = TexelConvConfig::new(c_in, c_out, k)
                            .with_implementation(implementation)
                            .init(&ad);
                        // Same parameters for every variant.
                        let conv = TexelConv {
                            weight: Param::from_tensor(random([c_out, c_in, k], 1, &ad)),
                            bias: Param::from_tensor(random([c_out], 2, &ad)),
                            ..conv
                        };
                        let x = random([2, c_in, t], 3, &ad).require_grad();
                        let y = if through_sigmoid {
                            conv.forward_sigmoid(x.clone())
                        } else {
                            conv.forward(x.clone())
                        };
                        assert_eq!(y.dims(), [2, c_out, t]);
                        let weights = random([2, c_out, t], 4, &ad);
                        let grads = (y.clone() * weights).sum().backward();
                        let got = [
                            to_vec(y.inner()),
                            to_vec(x.grad(&grads).expect("x grad")),
                            to_vec(conv.weight.grad(&grads).expect("w grad")),
                            to_vec(conv.bias.grad(&grads).expect("b grad")),
                        ];
                        match &reference {
                            None => reference = Some(got),
                            Some(r) => {
                                for (a, b) in got.iter().zip(r) {
                                    let what =
                                        format!("{name} {implementation:?} {through_sigmoid}");
                                    assert_close(a, b, 1e-4, &what);
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
