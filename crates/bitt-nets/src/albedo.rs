//! The albedo network `A` (paper Sec. 3.1 "Scene Estimation"; supplement D "Albedo
//! Network"): a U-Net from the input image to an albedo image.
//!
//! `num_downs` levels, outermost first. Level `i` halves the image with a convolution
//! (kernel 4, stride 2, padding 1) to `w_i = base_channels 2^min(i, 3)` channels
//! (64-128-256-512-512-512 in the paper) and later doubles it back with nearest x2
//! upsampling and a convolution, concatenating its input as the skip connection:
//!
//! - level 0 (outermost): conv, ... , ReLU, upsample, 3x3 conv (replicate padding, bias),
//!   sigmoid; no norm, the down conv has no bias;
//! - levels 1-3: LeakyReLU(0.2), conv, instance norm, ... , ReLU, upsample, 1x1 conv,
//!   instance norm; no biases (the norm removes them);
//! - levels 4 .. num_downs-2 and the innermost one: LeakyReLU(0.2), conv with bias, ... ,
//!   ReLU, upsample, 1x1 conv with bias; no norm (the innermost one has no concatenation
//!   below it).
//!
//! Instance norms have no affine parameters (PyTorch's default). The skip that a level
//! concatenates is its input *after* the LeakyReLU: the reference applies that LeakyReLU
//! in place, so the tensor it concatenates has already been activated; this module
//! reproduces that.
//!
//! Each convolution runs with the norm and activation that follow it as one operation
//! (`conv_block`: a custom operation on flex, burn's layers elsewhere). A 1x1
//! convolution and an instance norm commute with nearest upsampling (each output pixel is
//! the same dot product, each channel's moments are the same), so the inner levels'
//! up-convolutions run at the low resolution and upsample their normalised output: the same
//! function at a quarter of the cost. The outermost 3x3 up-convolution runs as four 2x2
//! convolutions at the low resolution, one per output phase (`outermost_up`).

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{InstanceNorm, InstanceNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use crate::NetsError;
use crate::conv_block::{Activation, conv_act, conv_norm_act};
use crate::fused::concat::{Middle, cat_channels};
use crate::fused::resample::{interleave_phases, upsample2};

/// Configuration of [`AlbedoNet`].
#[derive(Config, Debug)]
pub struct AlbedoNetConfig {
    /// Channels of the input image (RGB).
    #[config(default = 3)]
    pub channels_in: usize,
    /// Channels of the albedo image (RGB).
    #[config(default = 3)]
    pub channels_out: usize,
    /// Width of the outermost level; 64 in supplement D (64-128-256-512).
    #[config(default = 64)]
    pub base_channels: usize,
    /// Number of downsamplings, at least 5; the reference uses 6 (a 256 image reaches 4x4).
    #[config(default = 6)]
    pub num_downs: usize,
    /// Negative slope of the encoder's LeakyReLU (supplement D; the reference uses 0.2).
    #[config(default = 0.2)]
    pub leaky_slope: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LevelKind {
    Outermost,
    Normed,
    Plain,
}

/// One U-Net level (see the module docs).
#[derive(Module, Debug)]
pub(crate) struct UnetLevel {
    down: Conv2d,
    down_norm: Option<InstanceNorm>,
    up: Conv2d,
    up_norm: Option<InstanceNorm>,
    /// The outermost level: no LeakyReLU before `down`, replicate-padded 3x3 `up`.
    #[module(skip)]
    outermost: bool,
}

/// The albedo U-Net, see the module docs.
#[derive(Module, Debug)]
pub struct AlbedoNet {
    /// Outermost first.
    levels: Vec<UnetLevel>,
    #[module(skip)]
    leaky_slope: f64,
}

impl AlbedoNetConfig {
    /// Checks the level count and widths.
    pub fn validate(&self) -> Result<(), NetsError> {
        if self.num_downs < 5 || self.base_channels == 0 || self.channels_in == 0 {
            return Err(NetsError::Invalid(format!(
                "albedo U-Net needs num_downs >= 5 and non-zero widths: {self:?}"
            )));
        }
        Ok(())
    }

    /// The width after each level's down convolution, outermost first.
    pub fn widths(&self) -> Vec<usize> {
        (0..self.num_downs)
            .map(|i| self.base_channels << i.min(3))
            .collect()
    }

    /// The image side must be a multiple of this (one halving per level).
    pub(crate) fn size_multiple(&self) -> usize {
        1 << self.num_downs
    }

    /// Creates the network.
    ///
    /// # Panics
    /// When [`AlbedoNetConfig::validate`] fails.
    pub fn init(&self, device: &Device) -> AlbedoNet {
        if let Err(e) = self.validate() {
            panic!("{e}");
        }
        let widths = self.widths();
        let n = self.num_downs;
        let norm = |c| InstanceNormConfig::new(c).with_affine(false).init(device);
        let levels = (0..n)
            .map(|i| {
                let kind = match i {
                    0 => LevelKind::Outermost,
                    1..=3 => LevelKind::Normed,
                    _ => LevelKind::Plain,
                };
                let (c_in, c_out) = if i == 0 {
                    (self.channels_in, self.channels_out)
                } else {
                    (widths[i - 1], widths[i - 1])
                };
                let inner = widths[i];
                let up_in = if i + 1 == n { inner } else { 2 * inner };
                let plain = kind == LevelKind::Plain;
                let down = Conv2dConfig::new([c_in, inner], [4, 4])
                    .with_stride([2, 2])
                    .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                    .with_bias(plain)
                    .init(device);
                let up = if kind == LevelKind::Outermost {
                    // Padding is applied by hand (replicate), see `UnetLevel::up`.
                    Conv2dConfig::new([up_in, c_out], [3, 3]).init(device)
                } else {
                    Conv2dConfig::new([up_in, c_out], [1, 1])
                        .with_bias(plain)
                        .init(device)
                };
                let normed = kind == LevelKind::Normed;
                UnetLevel {
                    down,
                    down_norm: normed.then(|| norm(inner)),
                    up,
                    up_norm: normed.then(|| norm(c_out)),
                    outermost: kind == LevelKind::Outermost,
                }
            })
            .collect();
        AlbedoNet {
            levels,
            leaky_slope: self.leaky_slope,
        }
    }
}

/// `sigmoid(conv3x3(pad_edge(upsample2(x))) + bias)`, the outermost level's up path,
/// computed at the low resolution: along each axis an even output `2a` reads the padded
/// upsampled input at `2a - 1, 2a, 2a + 1`, i.e. `x[a - 1], x[a], x[a]` (indices clamped),
/// and an odd output `2a + 1` reads `x[a], x[a], x[a + 1]`. So each of the four output
/// phases is a 2x2 convolution of the edge-padded low-resolution input with taps summed
/// from the 3x3 kernel (`[k0, k1 + k2]` at offset 0 for even, `[k0 + k1, k2]` at offset 1
/// for odd), all four as one convolution with `4 C_out` channels; the phases are then
/// interleaved. The same function in 45% of the multiply-adds and without the 4x larger
/// upsampled and padded tensors.
///
/// # Shapes
/// - `x`: `[B, C, H, W]` (rectified); output: `[B, C_out, 2H, 2W]`
fn outermost_up(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let weight = conv.weight.val();
    let co = weight.dims()[0];
    // The two 2-tap kernels of one axis (`dim` 2: rows, 3: columns).
    let fold = |k: Tensor<4>, dim: usize| -> [Tensor<4>; 2] {
        let tap = |i| k.clone().narrow(dim, i, 1);
        [
            Tensor::cat(vec![tap(0), tap(1) + tap(2)], dim),
            Tensor::cat(vec![tap(0) + tap(1), tap(2)], dim),
        ]
    };
    // Phases in the order (even, even), (even, odd), (odd, even), (odd, odd).
    let phases: Vec<Tensor<4>> = fold(weight, 2)
        .into_iter()
        .flat_map(|rows| fold(rows, 3))
        .collect();
    let bias = conv
        .bias
        .as_ref()
        .map(|bias| Tensor::cat(vec![bias.val(); 4], 0));
    let out = conv_act(
        crate::fused::resample::pad_edge1(x),
        Tensor::cat(phases, 0),
        bias,
        Activation::Sigmoid,
    );
    // Phase (py, px) lives at rows py.., columns px.. of its channels.
    interleave_phases(out, co)
}

impl UnetLevel {
    /// The level's up path, `norm(conv(upsample2(relu(x))))` (the outermost level's with
    /// sigmoid); `x` is already rectified when `rectified` (the innermost level's down path
    /// ends with the ReLU).
    ///
    /// # Shapes
    /// - `x`: `[B, C, h, w]`; output: `[B, C_out, 2h, 2w]`
    fn up(&self, x: Tensor<4>, rectified: bool) -> Tensor<4> {
        let x = if rectified { x } else { relu(x) };
        if self.outermost {
            outermost_up(&self.up, x)
        } else {
            // conv1x1 and instance norm commute with nearest upsampling (module docs).
            upsample2(conv_norm_act(
                &self.up,
                self.up_norm.as_ref(),
                Activation::Identity,
                x,
            ))
        }
    }

    /// `act(norm(conv(x)))` of the level's down path.
    ///
    /// # Shapes
    /// - `x`: `[B, C_in, h, w]`; output: `[B, C_inner, h / 2, w / 2]`
    fn down(&self, x: Tensor<4>, act: Activation) -> Tensor<4> {
        conv_norm_act(&self.down, self.down_norm.as_ref(), act, x)
    }
}

impl AlbedoNet {
    /// Predicts the albedo image.
    ///
    /// # Shapes
    /// - `image`: `[B, C_in, H, W]`, `H` and `W` multiples of `2^num_downs` (64 in the
    ///   paper; its images are 256 x 256)
    /// - output: `[B, C_out, H, W]`, in `(0, 1)` (sigmoid)
    pub fn forward(&self, image: Tensor<4>) -> Tensor<4> {
        let n = self.levels.len();
        // Down: each level's output goes through the next level's LeakyReLU (the innermost
        // one's through its own up path's ReLU); the activated tensor is the next level's
        // skip connection.
        let mut skips = Vec::with_capacity(n);
        let mut h = image;
        for (i, level) in self.levels.iter().enumerate() {
            let act = if i + 1 < n {
                Activation::LeakyRelu(self.leaky_slope)
            } else {
                Activation::Relu
            };
            h = level.down(h, act);
            if i + 1 < n {
                skips.push(h.clone());
            }
        }
        // Up, innermost first: each inner level returns [its input, its up path], which the
        // next level's up path rectifies first (on flex in the concatenation's pass).
        let mut rectified = true;
        for (i, level) in self.levels.iter().enumerate().rev() {
            h = level.up(h, rectified);
            if i > 0 {
                let skip = skips.pop().expect("one skip per inner level");
                (h, rectified) = match cat_channels(&skip, Middle::Nothing, &h, true) {
                    Some(joined) => (joined, true),
                    None => (Tensor::cat(vec![skip, h], 1), false),
                };
            }
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::activation::{leaky_relu, sigmoid};
    use burn::tensor::ops::PadMode;

    use super::*;
    use crate::fused::conv2d::without_fusion;
    use crate::test_util::{assert_all_close, assert_same_as_flex, param_grads};
    use bitt_testkit::{assert_close, random, to_vec};

    /// The network as the reference writes it, in burn layers: activations, norms and
    /// upsampling as separate operations, the up-convolutions at the high resolution.
    fn reference_forward(net: &AlbedoNet, image: Tensor<4>) -> Tensor<4> {
        let mut skips = Vec::new();
        let mut h = image;
        for (i, level) in net.levels.iter().enumerate() {
            if i > 0 {
                h = leaky_relu(h, net.leaky_slope);
                skips.push(h.clone());
            }
            h = level.down.forward(h);
            if let Some(norm) = &level.down_norm {
                h = norm.forward(h);
            }
        }
        for (i, level) in net.levels.iter().enumerate().rev() {
            let x = upsample2(relu(h));
            let x = if level.outermost {
                x.pad((1, 1, 1, 1), PadMode::Edge)
            } else {
                x
            };
            h = level.up.forward(x);
            if let Some(norm) = &level.up_norm {
                h = norm.forward(h);
            }
            if i > 0 {
                h = Tensor::cat(vec![skips.pop().unwrap(), h], 1);
            }
        }
        sigmoid(h)
    }

    fn small() -> AlbedoNetConfig {
        AlbedoNetConfig::new()
            .with_base_channels(4)
            .with_num_downs(5)
    }

    /// On flex (the custom operations) and with them switched off (burn's layers), the
    /// network computes the reference's function: values, the input's and every parameter's
    /// gradient; batch of two, 32 x 64 images.
    #[test]
    fn albedo_matches_the_reference_composition_with_gradients() {
        let device = Device::flex().autodiff();
        let net = small().init(&device);
        let image = random([2, 3, 32, 64], 21, &device)
            .add_scalar(1.0)
            .div_scalar(2.0)
            .require_grad();
        let reference = reference_forward(&net, image.clone());
        let g = random(reference.dims(), 22, &device);
        let grads_ref = (reference.clone() * g.clone()).sum().backward();
        let ref_params = param_grads(&net, &grads_ref);
        let ref_dx = to_vec(image.grad(&grads_ref).unwrap());
        let fused = net.forward(image.clone());
        let unfused = without_fusion(|| net.forward(image.clone()));
        for (name, y) in [("fused", fused), ("burn layers", unfused)] {
            assert_close(
                &to_vec(y.clone()),
                &to_vec(reference.clone()),
                1e-5,
                &format!("albedo values, {name}"),
            );
            let grads = (y * g.clone()).sum().backward();
            assert_all_close(
                &param_grads(&net, &grads),
                &ref_params,
                2e-3,
                &format!("albedo parameter gradients, {name}"),
            );
            assert_close(
                &to_vec(image.grad(&grads).unwrap()),
                &ref_dx,
                2e-3,
                &format!("albedo input gradient, {name}"),
            );
        }
    }

    /// On another backend (ndarray, wgpu) the network composes burn's layers and computes the
    /// same values as on flex.
    #[test]
    fn albedo_off_flex_equals_flex() {
        let net = small().init(&Device::flex());
        let image = random([1, 3, 32, 32], 23, &Device::flex());
        assert_same_as_flex(&net, &image, |n, x| n.forward(x), 1e-5, "albedo");
    }
}
