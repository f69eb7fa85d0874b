//! The convolutional image encoder shared by the light network (Sec. 3.1) and the HTML
//! network (Sec. 3.2); supplement D, "Light Network" and "HTML Network".
//!
//! `log2(S) - 1` convolutions (kernel 4, stride 2, no bias, ReLU) halve an `S x S` image
//! down to `4 x 4`, the last one (no padding) to `1 x 1`; widths double from
//! `base_channels` up to `8 base_channels`. A 1x1 convolution (no bias) and tanh give the
//! output vector.
//!
//! Each convolution with its ReLU is one operation (`conv_block`: a custom
//! operation on flex, burn's layers elsewhere).

use burn::config::Config;
use burn::module::Module;
use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::{Device, Tensor};

use crate::NetsError;
use crate::conv_block::{Activation, compose, conv_norm_act};

/// Configuration of a [`ConvEncoder`].
#[derive(Config, Debug)]
pub struct ConvEncoderConfig {
    /// Channels of the input image (RGB).
    #[config(default = 3)]
    pub channels_in: usize,
    /// Length of the output vector.
    pub channels_out: usize,
    /// Side of the square input image; a power of two, at least 4.
    pub image_size: usize,
    /// Width of the first convolution; later ones double it up to 8 times this.
    pub base_channels: usize,
}

/// The encoder, see the module docs.
#[derive(Module, Debug)]
pub struct ConvEncoder {
    layers: Vec<Conv2d>,
    out: Conv2d,
}

impl ConvEncoderConfig {
    /// Checks that the image side is a power of two (at least 4) and the widths non-zero.
    pub fn validate(&self) -> Result<(), NetsError> {
        if !self.image_size.is_power_of_two() || self.image_size < 4 {
            return Err(NetsError::Invalid(format!(
                "encoder image size {} must be a power of two >= 4",
                self.image_size
            )));
        }
        if self.channels_in == 0 || self.channels_out == 0 || self.base_channels == 0 {
            return Err(NetsError::Invalid(format!(
                "encoder widths must be non-zero: {self:?}"
            )));
        }
        Ok(())
    }

    /// The widths after each strided convolution.
    pub fn widths(&self) -> Vec<usize> {
        let layers = self.image_size.trailing_zeros() as usize - 1;
        (0..layers)
            .map(|i| (self.base_channels << i).min(8 * self.base_channels))
            .collect()
    }

    /// Creates the encoder.
    ///
    /// # Panics
    /// When [`ConvEncoderConfig::validate`] fails.
    pub fn init(&self, device: &Device) -> ConvEncoder {
        if let Err(e) = self.validate() {
            panic!("{e}");
        }
        let widths = self.widths();
        let mut layers = Vec::with_capacity(widths.len());
        let mut c_in = self.channels_in;
        for (i, &c_out) in widths.iter().enumerate() {
            let pad = if i + 1 == widths.len() { 0 } else { 1 };
            layers.push(
                Conv2dConfig::new([c_in, c_out], [4, 4])
                    .with_stride([2, 2])
                    .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
                    .with_bias(false)
                    .init(device),
            );
            c_in = c_out;
        }
        ConvEncoder {
            layers,
            out: Conv2dConfig::new([c_in, self.channels_out], [1, 1])
                .with_bias(false)
                .init(device),
        }
    }
}

impl ConvEncoder {
    /// Encodes images into vectors in `(-1, 1)`.
    ///
    /// # Shapes
    /// - `image`: `[B, C_in, S, S]` with `S` the configured `image_size`
    /// - output: `[B, C_out]`
    pub fn forward(&self, image: Tensor<4>) -> Tensor<2> {
        self.forward_with(image, |conv, act, x| conv_norm_act(conv, None, act, x))
    }

    /// [`ConvEncoder::forward`] composed from burn's layers (`relu(conv(x))`, then the 1x1
    /// convolution and tanh), without the fused operation: the same function, for tests
    /// and the `bench_encoders` example.
    ///
    /// # Shapes
    /// - `image`: `[B, C_in, S, S]`
    /// - output: `[B, C_out]`
    pub fn forward_burn_layers(&self, image: Tensor<4>) -> Tensor<2> {
        self.forward_with(image, |conv, act, x| compose(conv, None, act, x))
    }

    /// The layers with `block(conv, activation, x)` evaluating each convolution.
    fn forward_with(
        &self,
        image: Tensor<4>,
        block: impl Fn(&Conv2d, Activation, Tensor<4>) -> Tensor<4>,
    ) -> Tensor<2> {
        let b = image.dims()[0];
        let mut x = image;
        for layer in &self.layers {
            x = block(layer, Activation::Relu, x);
        }
        let x = block(&self.out, Activation::Identity, x);
        let c = x.dims()[1];
        x.reshape([b, c]).tanh()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths_follow_the_image_size() {
        let c = ConvEncoderConfig::new(12, 256, 32);
        assert_eq!(c.widths(), [32, 64, 128, 256, 256, 256, 256]);
        assert_eq!(ConvEncoderConfig::new(1, 8, 2).widths(), [2, 4]);
        assert!(ConvEncoderConfig::new(1, 100, 2).validate().is_err());
        assert!(ConvEncoderConfig::new(1, 2, 2).validate().is_err());
    }

    /// With the custom operation on flex: the values, the input's and every parameter's
    /// gradient of burn's layers; on ndarray and wgpu the same values through burn's layers.
    #[test]
    fn encoder_matches_burn_layers_with_gradients() {
        use crate::test_util::{assert_all_close, assert_same_as_flex, param_grads};
        use bitt_testkit::{assert_close, random, to_vec};
        let device = Device::flex().autodiff();
        let e = ConvEncoderConfig::new(7, 32, 4).init(&device);
        let image = random([3, 3, 32, 32], 31, &device).require_grad();
        let y = e.forward(image.clone());
        let r = e.forward_burn_layers(image.clone());
        assert_close(
            &to_vec(y.clone()),
            &to_vec(r.clone()),
            1e-5,
            "encoder values",
        );
        let g = random([3, 7], 32, &device);
        let grads = (y * g.clone()).sum().backward();
        let grads_ref = (r * g).sum().backward();
        assert_all_close(
            &param_grads(&e, &grads),
            &param_grads(&e, &grads_ref),
            1e-4,
            "encoder parameter gradients",
        );
        assert_close(
            &to_vec(image.grad(&grads).unwrap()),
            &to_vec(image.grad(&grads_ref).unwrap()),
            1e-4,
            "encoder input gradient",
        );
        let flex = Device::flex();
        let e = ConvEncoderConfig::new(7, 32, 4).init(&flex);
        let image = random([2, 3, 32, 32], 33, &flex);
        assert_same_as_flex(&e, &image, |e, x| e.forward(x), 1e-5, "encoder");
    }
}
