//! BTR, the bi-directional texture reconstructor (paper Sec. 3.3 "Fine Stage", eq. 3-5;
//! supplement D "Bi-directional Texture Reconstructor").
//!
//! BTR works on texel vectors: a hand's texture as the compact vector of its UV layout's
//! valid texels, `[B, 3, T]` (`T = 206,330` for HTML's 1024x1024 layout). For each hand the
//! input is the composed vector `t_i = T(h_i)(1 - v_i) + u_i` ([`compose_texels`]): the
//! coarse HTML texture where the hand is not visible, the unwrapped albedo where it is.
//!
//! Architecture (one set of weights for both hands):
//!
//! - stem: a 1-D ResNet block `3 -> c0`;
//! - encoder: per level `l` two ResNet blocks `c_l -> c_{l+1} -> c_{l+1}` then max-pool /2
//!   (`T -> floor(T / 2)`); the pooled features `e^l` are the skips;
//! - middle: two ResNet blocks at the deepest width;
//! - bi-directional decoder (eq. 4-5): level `i` concatenates `[own previous features,
//!   the other hand's previous features, own skip]` (`3 c_{l+1}` channels), a ResNet block
//!   to `c_l`, nearest x2 upsampling (plus one copy of the last texel when the encoder's
//!   length at that level was odd, so `T` comes back exactly) and a second ResNet block;
//! - head: 1x1 convolutions `c0 -> 8 -> 3` and a sigmoid.
//!
//! A ResNet block is `SiLU(GN(conv3(SiLU(GN(conv3(x)))))) + skip(x)`, with group norm over 8
//! groups and a 1x1 convolution as `skip` when the width changes.
//!
//! Both hands run as one batch of `2B` (left then right): group norm is per sample, so this
//! is exactly the per-hand computation, and "the other hand" is the other half of the batch.
//! With `bidirectional = false` (the paper's ablation, Table 4) the other hand's features
//! are replaced by zeros; the layers and the parameter count stay the same.

use burn::config::Config;
use burn::module::Module;
use burn::nn::{GroupNorm, GroupNormConfig};
use burn::tensor::activation::silu;
use burn::tensor::module::max_pool1d;
use burn::tensor::ops::MaxPoolOptions;
use burn::tensor::{Device, Tensor};

use crate::NetsError;
use crate::conv1d::{ConvImpl, TexelConv, TexelConvConfig};
use crate::fused::concat::Middle;
use crate::fused::{self, BlockParams};

/// Configuration of [`Btr`].
#[derive(Config, Debug)]
pub struct BtrConfig {
    /// Channels of the input texel vectors (RGB).
    #[config(default = 3)]
    pub channels_in: usize,
    /// Channels of the output texel vectors (RGB).
    #[config(default = 3)]
    pub channels_out: usize,
    /// Widths `c0, c1, ...`: the stem's output and each encoder level's output; one
    /// downsampling per step. Supplement D: 16, 64, 128, 256.
    #[config(default = "vec![16, 64, 128, 256]")]
    pub channels: Vec<usize>,
    /// Groups of every group norm (the reference's ResNet blocks use 8).
    #[config(default = 8)]
    pub groups: usize,
    /// Width of the hidden 1x1 convolution of the head (the reference uses 8).
    #[config(default = 8)]
    pub head_channels: usize,
    /// `true`: the decoder sees the other hand's features (eq. 4-5). `false`: zeros instead
    /// (the "w/o bi-directional" ablation, paper Sec. 4.3), same parameters.
    #[config(default = true)]
    pub bidirectional: bool,
    /// How the 1-D convolutions are evaluated (same function, different speed). The default,
    /// [`ConvImpl::Fused`], runs each conv + group norm + SiLU as one operation on flex.
    #[config(default = "ConvImpl::Fused")]
    pub conv: ConvImpl,
}

/// One 1-D ResNet block: two (conv k=3, group norm, SiLU) and a residual connection.
#[derive(Module, Debug)]
pub(crate) struct ResBlock1d {
    conv1: TexelConv,
    norm1: GroupNorm,
    conv2: TexelConv,
    norm2: GroupNorm,
    /// 1x1 convolution on the residual path when the width changes.
    skip: Option<TexelConv>,
}

impl ResBlock1d {
    fn new(c_in: usize, c_out: usize, groups: usize, conv: ConvImpl, device: &Device) -> Self {
        let conv3 = |a, b| {
            TexelConvConfig::new(a, b, 3)
                .with_implementation(conv)
                .init(device)
        };
        let norm = || GroupNormConfig::new(groups, c_out).init(device);
        ResBlock1d {
            conv1: conv3(c_in, c_out),
            norm1: norm(),
            conv2: conv3(c_out, c_out),
            norm2: norm(),
            skip: (c_in != c_out).then(|| {
                TexelConvConfig::new(c_in, c_out, 1)
                    .with_implementation(conv)
                    .init(device)
            }),
        }
    }

    /// # Shapes
    /// - `x`: `[N, C_in, L]`
    /// - output: `[N, C_out, L]`
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        if let Some(y) = self.fused(&x) {
            return y;
        }
        self.composed(x)
    }

    /// The block as one operation ([`fused::res_block`]) with [`ConvImpl::Fused`] on flex.
    fn fused(&self, x: &Tensor<3>) -> Option<Tensor<3>> {
        let convs = [Some(&self.conv1), Some(&self.conv2), self.skip.as_ref()];
        if convs
            .iter()
            .flatten()
            .any(|c| c.implementation != ConvImpl::Fused)
        {
            return None;
        }
        let first = block_params(&self.conv1, &self.norm1)?;
        let second = block_params(&self.conv2, &self.norm2)?;
        let skip = self.skip.as_ref().map(|conv| fused::res_block::SkipParams {
            weight: conv.weight.val(),
            bias: conv.bias.val(),
        });
        fused::res_block::res_block(x, &first, &second, skip.as_ref())
    }

    /// The block from its parts: two [`conv_norm_silu`] and the residual's sum.
    fn composed(&self, x: Tensor<3>) -> Tensor<3> {
        let h = conv_norm_silu(&self.conv1, &self.norm1, x.clone());
        let h = conv_norm_silu(&self.conv2, &self.norm2, h);
        let residual = match &self.skip {
            Some(conv) => conv.forward(x),
            None => x,
        };
        h + residual
    }
}

/// `SiLU(GroupNorm(conv(x)))`, the block of a ResNet block.
///
/// Computes exactly `silu(norm.forward(conv.forward(x)))` (up to rounding) with fewer passes
/// over the `[N, C, L]` activations: the convolution's bias is folded into the
/// normalisation (its effect on the group statistics follows from the per-channel moments
/// `E[z]`, `E[z^2]` of the bias-free output `z`), and the normalisation becomes one
/// per-channel affine map `z scale + shift`. The variance is `E[y^2] - E[y]^2` (clamped at
/// zero), computed in `f32` like the rest.
///
/// With [`ConvImpl::Fused`] on flex the whole block is one custom operation (`fused`).
fn conv_norm_silu(conv: &TexelConv, norm: &GroupNorm, x: Tensor<3>) -> Tensor<3> {
    if conv.implementation == ConvImpl::Fused
        && let Some(params) = block_params(conv, norm)
        && let Some(y) = fused::conv_norm_silu(&x, &params)
    {
        return y;
    }
    let z = conv.forward_without_bias(x);
    let [n, c, _] = z.dims();
    let (g, eps) = (norm.num_groups, norm.epsilon);
    let cg = c / g;
    let b = conv.bias.val().reshape([1, c, 1]);
    // Per-channel moments of y = z + b over the texel axis.
    let z1 = z.clone().mean_dim(2);
    let z2 = z.clone().square().mean_dim(2);
    let y1 = z1.clone() + b.clone();
    let y2 = z2 + (z1 * b.clone()).mul_scalar(2.0) + b.clone().square();
    // Group moments (every channel of a group has the same number of texels).
    let mean = y1.reshape([n, g, cg]).mean_dim(2);
    let var = (y2.reshape([n, g, cg]).mean_dim(2) - mean.clone().square()).clamp_min(0.0);
    let rstd = var.add_scalar(eps).sqrt().recip();
    let per_channel = |t: Tensor<3>| t.expand([n, g, cg]).reshape([n, c, 1]);
    let mut scale = per_channel(rstd);
    let mut shift = (b - per_channel(mean)) * scale.clone();
    if let (Some(gamma), Some(beta)) = (&norm.gamma, &norm.beta) {
        let gamma = gamma.val().reshape([1, c, 1]);
        shift = shift * gamma.clone() + beta.val().reshape([1, c, 1]);
        scale = scale * gamma;
    }
    silu(z * scale + shift)
}

/// The fused operations' view of a convolution and its group norm; `None` when the norm has
/// no affine parameters.
fn block_params(conv: &TexelConv, norm: &GroupNorm) -> Option<BlockParams> {
    let (Some(gamma), Some(beta)) = (&norm.gamma, &norm.beta) else {
        return None;
    };
    Some(BlockParams {
        weight: conv.weight.val(),
        bias: conv.bias.val(),
        gamma: gamma.val(),
        beta: beta.val(),
        groups: norm.num_groups,
        epsilon: norm.epsilon,
    })
}

/// Two ResNet blocks of one encoder or decoder level.
#[derive(Module, Debug)]
pub(crate) struct BtrLevel {
    block1: ResBlock1d,
    block2: ResBlock1d,
}

/// The bi-directional texture reconstructor, see the module docs.
#[derive(Module, Debug)]
pub struct Btr {
    stem: ResBlock1d,
    encoder: Vec<BtrLevel>,
    middle: Vec<ResBlock1d>,
    decoder: Vec<BtrLevel>,
    head1: TexelConv,
    head2: TexelConv,
    #[module(skip)]
    bidirectional: bool,
    /// Pools and upsamples with the fused operations on flex ([`ConvImpl::Fused`]); burn's
    /// `max_pool1d` and an `expand` otherwise.
    #[module(skip)]
    fused_texel_ops: bool,
}

/// BTR's output: the full texel vectors of both hands, values in `(0, 1)`.
#[derive(Debug, Clone)]
pub struct BtrOutput {
    /// `[B, 3, T]`.
    pub left: Tensor<3>,
    /// `[B, 3, T]`.
    pub right: Tensor<3>,
}

impl BtrConfig {
    /// Checks the widths (each a multiple of `groups`, at least one level).
    pub fn validate(&self) -> Result<(), NetsError> {
        if self.channels.len() < 2 {
            return Err(NetsError::Invalid(format!(
                "BTR needs at least two widths (one level), got {:?}",
                self.channels
            )));
        }
        if self.groups == 0
            || self.head_channels == 0
            || self.channels_in == 0
            || self.channels_out == 0
            || self
                .channels
                .iter()
                .any(|&c| c == 0 || !c.is_multiple_of(self.groups))
        {
            return Err(NetsError::Invalid(format!(
                "BTR widths {:?} must be non-zero multiples of the {} groups",
                self.channels, self.groups
            )));
        }
        Ok(())
    }

    /// The smallest texel count the network accepts: every level keeps at least one texel.
    pub(crate) fn min_texels(&self) -> usize {
        1 << (self.channels.len() - 1)
    }

    /// Creates the network.
    ///
    /// # Panics
    /// When [`BtrConfig::validate`] fails.
    pub fn init(&self, device: &Device) -> Btr {
        if let Err(e) = self.validate() {
            panic!("{e}");
        }
        let (g, conv) = (self.groups, self.conv);
        let ch = &self.channels;
        let block = |a, b| ResBlock1d::new(a, b, g, conv, device);
        let deepest = ch[ch.len() - 1];
        let head = |a, b| {
            TexelConvConfig::new(a, b, 1)
                .with_implementation(conv)
                .init(device)
        };
        Btr {
            stem: block(self.channels_in, ch[0]),
            encoder: ch
                .windows(2)
                .map(|w| BtrLevel {
                    block1: block(w[0], w[1]),
                    block2: block(w[1], w[1]),
                })
                .collect(),
            middle: vec![block(deepest, deepest), block(deepest, deepest)],
            decoder: ch
                .windows(2)
                .rev()
                .map(|w| BtrLevel {
                    block1: block(3 * w[1], w[0]),
                    block2: block(w[0], w[0]),
                })
                .collect(),
            head1: head(ch[0], self.head_channels),
            head2: head(self.head_channels, self.channels_out),
            bidirectional: self.bidirectional,
            fused_texel_ops: self.conv == ConvImpl::Fused,
        }
    }
}

/// The other hand's features: the two halves of the batch swapped. With one sample per
/// hand (training) that is a flip of the batch axis, whose gradient is a flip too; the two
/// slices of the general case each have a zero-padded copy of the whole batch as gradient.
fn swap_hands(x: Tensor<3>) -> Tensor<3> {
    let b = x.dims()[0] / 2;
    if b == 1 {
        return x.flip([0]);
    }
    Tensor::cat(vec![x.clone().narrow(0, b, b), x.narrow(0, 0, b)], 0)
}

impl Btr {
    /// Whether the decoder mixes the hands (eq. 4-5) or sees zeros (ablation).
    pub fn bidirectional(&self) -> bool {
        self.bidirectional
    }

    /// Reconstructs both hands' full texel vectors.
    ///
    /// # Shapes
    /// - `left`, `right`: `[B, C_in, T]` composed texel vectors ([`compose_texels`]),
    ///   `T >= 2^levels` (8 for the paper's widths), any parity
    /// - output: [`BtrOutput`] with `left`, `right`: `[B, C_out, T]`, in `(0, 1)`
    ///
    /// # Panics
    /// When the two inputs differ in shape, have the wrong channel count or `T` is too short.
    pub fn forward(&self, left: Tensor<3>, right: Tensor<3>) -> BtrOutput {
        let dims = left.dims();
        assert_eq!(dims, right.dims(), "BTR: left and right shapes differ");
        let [b, _, t] = dims;
        let levels = self.encoder.len();
        assert!(
            t >= 1 << levels,
            "BTR: {t} texels is too short for {levels} levels"
        );
        let mut h = self.stem.forward(Tensor::cat(vec![left, right], 0));
        let mut lengths = Vec::with_capacity(levels);
        let mut skips = Vec::with_capacity(levels);
        for level in &self.encoder {
            h = level.block2.forward(level.block1.forward(h));
            lengths.push(h.dims()[2]);
            h = match self
                .fused_texel_ops
                .then(|| fused::pool::max_pool_half(&h))
                .flatten()
            {
                Some(pooled) => pooled,
                None => max_pool1d(h, MaxPoolOptions::new([2]).with_stride([2])),
            };
            skips.push(h.clone());
        }
        for block in &self.middle {
            h = block.forward(h);
        }
        for level in &self.decoder {
            let skip = skips.pop().expect("one skip per level");
            let input = self
                .fused_texel_ops
                .then(|| {
                    let middle = if self.bidirectional {
                        Middle::SwappedHalves
                    } else {
                        Middle::Zeros
                    };
                    fused::concat::cat_channels(&h, middle, &skip, false)
                })
                .flatten();
            let input = input.unwrap_or_else(|| {
                let other = if self.bidirectional {
                    swap_hands(h.clone())
                } else {
                    h.zeros_like()
                };
                Tensor::cat(vec![h, other, skip], 1)
            });
            h = level.block1.forward(input);
            h = match self
                .fused_texel_ops
                .then(|| fused::resample::upsample2_texels_on_flex(&h))
                .flatten()
            {
                Some(up) => up,
                None => fused::resample::upsample2_texels_composed(h),
            };
            let target = lengths.pop().expect("one length per level");
            let len = h.dims()[2];
            if len < target {
                let last = h.clone().narrow(2, len - 1, 1);
                h = Tensor::cat(vec![h, last], 2);
            }
            h = level.block2.forward(h);
        }
        let out = self.head2.forward_sigmoid(self.head1.forward(h));
        BtrOutput {
            left: out.clone().narrow(0, 0, b),
            right: out.narrow(0, b, b),
        }
    }
}

/// The BTR input of one hand (eq. 3): the coarse texture where the hand is not visible, the
/// unwrapped albedo where it is, `coarse (1 - visible) + unwrapped visible`.
///
/// This equals the paper's `T(h)(1 - v) + u` when `u` is zero outside the visible mask, as
/// an unwrapped texture is; multiplying by the mask makes it hold for any `unwrapped`.
///
/// # Shapes
/// - `coarse`, `unwrapped`: `[B, 3, T]`; `visible`: `[B, 1, T]` or `[B, 3, T]` in `[0, 1]`
/// - output: `[B, 3, T]`
pub fn compose_texels(coarse: Tensor<3>, unwrapped: Tensor<3>, visible: Tensor<3>) -> Tensor<3> {
    let hidden = visible.clone().neg().add_scalar(1.0);
    coarse * hidden + unwrapped * visible
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::{assert_close, devices, random, to_vec};

    fn tiny(bidirectional: bool) -> BtrConfig {
        BtrConfig::new()
            .with_channels(vec![8, 16, 16, 24])
            .with_bidirectional(bidirectional)
    }

    /// The flip taken with one sample per hand swaps the hands as the general slices do,
    /// values and gradients.
    #[test]
    fn swapping_hands_by_flip_matches_the_slices() {
        for (name, device) in devices() {
            let ad = device.autodiff();
            for b in [1, 2] {
                let x = random([2 * b, 3, 5], 7, &ad).require_grad();
                let w = random([2 * b, 3, 5], 8, &ad);
                let sliced = Tensor::cat(
                    vec![x.clone().narrow(0, b, b), x.clone().narrow(0, 0, b)],
                    0,
                );
                assert_eq!(
                    to_vec(swap_hands(x.clone())),
                    to_vec(sliced.clone()),
                    "{name} b={b}"
                );
                let grad = |y: Tensor<3>| {
                    let g = (y * w.clone()).sum().backward();
                    to_vec(x.grad(&g).expect("gradient"))
                };
                assert_close(&grad(swap_hands(x.clone())), &grad(sliced), 0.0, name);
            }
        }
    }

    #[test]
    fn btr_shapes_any_parity() {
        for (name, device) in devices() {
            let net = tiny(true).init(&device);
            for t in [8, 9, 37, 64, 101] {
                let out = net.forward(random([2, 3, t], 1, &device), random([2, 3, t], 2, &device));
                assert_eq!(out.left.dims(), [2, 3, t], "{name} T={t}");
                assert_eq!(out.right.dims(), [2, 3, t], "{name} T={t}");
                let v = to_vec(out.left);
                assert!(
                    v.iter().all(|x| *x > 0.0 && *x < 1.0),
                    "{name}: sigmoid range"
                );
            }
        }
    }

    #[test]
    fn decoder_mixes_hands_only_when_bidirectional() {
        for (name, device) in devices() {
            for bidirectional in [true, false] {
                let net = tiny(bidirectional).init(&device);
                let left = random([1, 3, 45], 5, &device);
                let a = net.forward(left.clone(), random([1, 3, 45], 6, &device));
                let b = net.forward(left, random([1, 3, 45], 7, &device));
                let (la, lb) = (to_vec(a.left), to_vec(b.left));
                let diff = la
                    .iter()
                    .zip(&lb)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f32::max);
                if bidirectional {
                    assert!(diff > 1e-5, "{name}: left output ignores the right hand");
                } else {
                    assert_eq!(diff, 0.0, "{name}: ablation leaks the right hand");
                }
                // The right output always depends on the right input.
                assert_ne!(to_vec(a.right), to_vec(b.right), "{name}");
            }
        }
    }

    #[test]
    fn ablation_has_the_same_parameters() {
        let device = Device::flex();
        assert_eq!(
            tiny(true).init(&device).num_params(),
            tiny(false).init(&device).num_params()
        );
    }

    /// The hands are processed as one batch; that must equal running each hand on its own
    /// (swapping the inputs swaps the outputs).
    #[test]
    fn hands_are_symmetric() {
        for (name, device) in devices() {
            let net = tiny(true).init(&device);
            let (l, r) = (
                random([1, 3, 21], 8, &device),
                random([1, 3, 21], 9, &device),
            );
            let a = net.forward(l.clone(), r.clone());
            let b = net.forward(r, l);
            assert_close(&to_vec(a.left), &to_vec(b.right), 1e-5, name);
            assert_close(&to_vec(a.right), &to_vec(b.left), 1e-5, name);
        }
    }

    /// The folded conv + group norm + SiLU and the fused operation (flex only) equal the plain
    /// composition, values and gradients (input, weight, bias, gamma, beta), also for a
    /// non-contiguous input.
    #[test]
    fn folded_and_fused_blocks_match_burn_group_norm() {
        use burn::module::Param;
        for (name, device) in devices() {
            let ad = device.clone().autodiff();
            let conv = TexelConvConfig::new(4, 16, 3)
                .with_implementation(ConvImpl::ShiftedSum)
                .init(&ad);
            let mut norm = GroupNormConfig::new(8, 16).init(&ad);
            norm.gamma = Some(Param::from_tensor(random([16], 11, &ad).add_scalar(1.0)));
            norm.beta = Some(Param::from_tensor(random([16], 12, &ad)));
            for transposed in [false, true] {
                // An offset input makes the bias and the mean matter.
                let x = if transposed {
                    random([2, 19, 4], 13, &ad).swap_dims(1, 2)
                } else {
                    random([2, 4, 19], 13, &ad)
                };
                let x = x.add_scalar(0.7).require_grad();
                let w = random([2, 16, 19], 14, &ad);
                let mut results = Vec::new();
                for variant in ["composed", "folded", "fused"] {
                    let y = match variant {
                        "composed" => silu(norm.forward(conv.forward(x.clone()))),
                        "folded" => conv_norm_silu(&conv, &norm, x.clone()),
                        _ => {
                            let params = BlockParams {
                                weight: conv.weight.val(),
                                bias: conv.bias.val(),
                                gamma: norm.gamma.as_ref().unwrap().val(),
                                beta: norm.beta.as_ref().unwrap().val(),
                                groups: 8,
                                epsilon: norm.epsilon,
                            };
                            match fused::conv_norm_silu(&x, &params) {
                                Some(y) => y,
                                None => {
                                    assert_ne!(name, "flex", "flex must take the fused path");
                                    continue;
                                }
                            }
                        }
                    };
                    let grads = (y.clone() * w.clone()).sum().backward();
                    let (gamma, beta) = (norm.gamma.as_ref().unwrap(), norm.beta.as_ref().unwrap());
                    results.push((
                        variant,
                        [
                            to_vec(y.inner()),
                            to_vec(x.grad(&grads).unwrap()),
                            to_vec(conv.weight.grad(&grads).unwrap()),
                            to_vec(conv.bias.grad(&grads).unwrap()),
                            to_vec(gamma.grad(&grads).unwrap()),
                            to_vec(beta.grad(&grads).unwrap()),
                        ],
                    ));
                }
                assert_eq!(results.len(), if name == "flex" { 3 } else { 2 });
                let (_, reference) = &results[0];
                for (variant, got) in &results[1..] {
                    for (a, b) in got.iter().zip(reference) {
                        assert_close(a, b, 2e-4, &format!("{name} {variant} T={transposed}"));
                    }
                }
            }
        }
    }

    /// The fused path without autodiff (inference on flex) and with an input that does not
    /// require a gradient gives the same values.
    #[test]
    fn fused_block_without_gradients() {
        let device = Device::flex();
        let conv = TexelConvConfig::new(3, 8, 3).init(&device);
        let norm = GroupNormConfig::new(8, 8).init(&device);
        let x = random([2, 3, 33], 21, &device);
        let fused = conv_norm_silu(&conv, &norm, x.clone());
        let composed = silu(norm.forward(conv.forward(x)));
        assert_close(&to_vec(fused), &to_vec(composed), 2e-5, "inference");
        // Autodiff device, untracked input: only the parameters get gradients.
        let ad = device.autodiff();
        let conv = TexelConvConfig::new(3, 8, 3).init(&ad);
        let norm = GroupNormConfig::new(4, 8).init(&ad);
        let x = random([1, 3, 10], 22, &ad);
        let grads = conv_norm_silu(&conv, &norm, x.clone()).sum().backward();
        assert!(x.grad(&grads).is_none());
        let dw = to_vec(conv.weight.grad(&grads).expect("weight grad"));
        let reference = {
            let conv2 = TexelConvConfig::new(3, 8, 3)
                .with_implementation(ConvImpl::ShiftedSum)
                .init(&ad);
            let conv2 = TexelConv {
                weight: burn::module::Param::from_tensor(conv.weight.val().detach()),
                bias: burn::module::Param::from_tensor(conv.bias.val().detach()),
                ..conv2
            };
            let g = silu(norm.forward(conv2.forward(x))).sum().backward();
            to_vec(conv2.weight.grad(&g).unwrap())
        };
        assert_close(&dw, &reference, 2e-4, "untracked input");
    }

    /// A whole ResNet block as one operation gives the composed block's values and every
    /// gradient bit for bit (the same kernels, each sum one `f32` addition), with the
    /// identity and with the projection on the residual path; so does inference, and an
    /// input that is not tracked.
    #[test]
    fn fused_res_block_equals_the_composed_block_bit_for_bit() {
        use burn::module::Param;
        let ad = Device::flex().autodiff();
        for (c_in, c_out) in [(8, 8), (3, 8), (24, 16)] {
            let mut block = ResBlock1d::new(c_in, c_out, 8, ConvImpl::Fused, &ad);
            for (i, norm) in [&mut block.norm1, &mut block.norm2].into_iter().enumerate() {
                let seed = 40 + 2 * i as u64;
                norm.gamma = Some(Param::from_tensor(
                    random([c_out], seed, &ad).add_scalar(1.0),
                ));
                norm.beta = Some(Param::from_tensor(random([c_out], seed + 1, &ad)));
            }
            let x = random([2, c_in, 29], 50, &ad)
                .add_scalar(0.4)
                .require_grad();
            let w = random([2, c_out, 29], 51, &ad);
            let what = format!("{c_in} -> {c_out}");
            let fused = block.fused(&x).expect("flex takes the fused path");
            let composed = block.composed(x.clone());
            let mut gradients = Vec::new();
            for y in [fused, composed] {
                let grads = (y.clone() * w.clone()).sum().backward();
                let mut all = vec![to_vec(y.inner()), to_vec(x.grad(&grads).unwrap())];
                all.extend(crate::test_util::param_grads(&block, &grads));
                gradients.push(all);
            }
            assert_eq!(gradients[0].len(), if c_in == c_out { 10 } else { 12 });
            for (i, (a, b)) in gradients[0].iter().zip(&gradients[1]).enumerate() {
                assert_eq!(a, b, "{what}: value {i} (0: output, 1: input gradient)");
            }
            // Inference on flex, and an untracked input on the autodiff device.
            let device = Device::flex();
            let plain = ResBlock1d::new(c_in, c_out, 8, ConvImpl::Fused, &device)
                .load_record(block.clone().into_record());
            let xp = random([2, c_in, 29], 50, &device).add_scalar(0.4);
            let y = plain.fused(&xp).expect("flex takes the fused path");
            assert_eq!(to_vec(y), to_vec(plain.composed(xp)), "{what}: inference");
            let untracked = random([1, c_in, 9], 52, &ad);
            let grads = block.forward(untracked.clone()).sum().backward();
            assert!(untracked.grad(&grads).is_none());
            let reference = block.composed(untracked).sum().backward();
            assert_eq!(
                to_vec(block.conv1.weight.grad(&grads).unwrap()),
                to_vec(block.conv1.weight.grad(&reference).unwrap()),
                "{what}: untracked input"
            );
        }
    }

    /// The whole network with the fused blocks equals the composed one on flex.
    #[test]
    fn fused_btr_matches_composed_btr() {
        let ad = Device::flex().autodiff();
        let fused = tiny(true).init(&ad);
        // Same weights: the fused network's record loaded into a composed one.
        let composed = tiny(true)
            .with_conv(ConvImpl::ShiftedSum)
            .init(&ad)
            .load_record(fused.clone().into_record());
        assert_eq!(composed.stem.conv1.implementation, ConvImpl::ShiftedSum);
        assert_eq!(fused.stem.conv1.implementation, ConvImpl::Fused);
        let (l, r) = (
            random([1, 3, 37], 31, &ad).require_grad(),
            random([1, 3, 37], 32, &ad),
        );
        let mut outs = Vec::new();
        for net in [&fused, &composed] {
            let out = net.forward(l.clone(), r.clone());
            let loss = (out.left.clone() * 0.3 + out.right.clone()).sum();
            let grads = loss.backward();
            outs.push((to_vec(out.left.inner()), to_vec(l.grad(&grads).unwrap())));
        }
        assert_close(&outs[0].0, &outs[1].0, 1e-4, "BTR output");
        assert_close(&outs[0].1, &outs[1].1, 1e-3, "BTR input gradient");
    }

    #[test]
    fn compose_uses_coarse_where_hidden() {
        let device = Device::flex();
        let coarse = Tensor::<3>::from_floats([[[0.5, 0.5, 0.5]]], &device);
        let unwrapped = Tensor::<3>::from_floats([[[0.9, 0.0, 0.2]]], &device);
        let visible = Tensor::<3>::from_floats([[[1.0, 0.0, 0.5]]], &device);
        let t = to_vec(compose_texels(coarse, unwrapped, visible));
        assert_close(&t, &[0.9, 0.5, 0.35], 1e-6, "compose");
    }

    #[test]
    fn rejects_widths_not_divisible_by_groups() {
        assert!(
            BtrConfig::new()
                .with_channels(vec![12, 16])
                .validate()
                .is_err()
        );
        assert!(BtrConfig::new().with_channels(vec![16]).validate().is_err());
        assert!(BtrConfig::new().validate().is_ok());
    }
}
