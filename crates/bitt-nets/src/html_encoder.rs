//! The HTML network `H` of the coarse stage (paper Sec. 3.2, eq. 1; supplement D "HTML
//! Network"): an image encoder to the HTML parameter vectors of both hands.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::encoder::{ConvEncoder, ConvEncoderConfig};

/// Configuration of [`HtmlEncoder`].
#[derive(Config, Debug)]
pub struct HtmlEncoderConfig {
    /// Side of the square input image (256 in the paper, supplement A).
    #[config(default = 256)]
    pub image_size: usize,
    /// Width of the first convolution; widths 64, 128, 256, 512 (supplement D).
    #[config(default = 64)]
    pub base_channels: usize,
    /// HTML parameters per hand: HTML's 101 principal components (Sec. 3.2).
    #[config(default = 101)]
    pub coefficients_per_hand: usize,
    /// Factor on the tanh output; the reference implementation uses 2, so each HTML
    /// coefficient lies in `(-2, 2)`.
    #[config(default = 2.0)]
    pub output_scale: f64,
}

/// The HTML network: image to `2 x 101` HTML coefficients (left hand first).
#[derive(Module, Debug)]
pub struct HtmlEncoder {
    encoder: ConvEncoder,
    #[module(skip)]
    coefficients_per_hand: usize,
    #[module(skip)]
    output_scale: f64,
}

/// The HTML parameter vectors `h_l, h_r` of both hands.
#[derive(Debug, Clone)]
pub struct HtmlCoefficients {
    /// `[B, 101]`.
    pub left: Tensor<2>,
    /// `[B, 101]`.
    pub right: Tensor<2>,
}

impl HtmlEncoderConfig {
    /// The encoder this network is made of.
    pub fn encoder(&self) -> ConvEncoderConfig {
        ConvEncoderConfig::new(
            2 * self.coefficients_per_hand,
            self.image_size,
            self.base_channels,
        )
    }

    /// Creates the network.
    ///
    /// # Panics
    /// When the image size is not a power of two >= 4.
    pub fn init(&self, device: &Device) -> HtmlEncoder {
        HtmlEncoder {
            encoder: self.encoder().init(device),
            coefficients_per_hand: self.coefficients_per_hand,
            output_scale: self.output_scale,
        }
    }
}

impl HtmlEncoder {
    /// Predicts both hands' HTML coefficients as one vector, left hand first (eq. 1).
    ///
    /// # Shapes
    /// - `image`: `[B, 3, S, S]`
    /// - output: `[B, 2K]` (`K = 101`), in `(-output_scale, output_scale)`
    pub fn forward(&self, image: Tensor<4>) -> Tensor<2> {
        self.encoder.forward(image).mul_scalar(self.output_scale)
    }

    /// [`HtmlEncoder::forward`] split into the two hands.
    ///
    /// # Shapes
    /// - `image`: `[B, 3, S, S]`
    /// - output: `left`, `right`: `[B, K]`
    pub fn predict(&self, image: Tensor<4>) -> HtmlCoefficients {
        let k = self.coefficients_per_hand;
        let h = self.forward(image);
        HtmlCoefficients {
            left: h.clone().narrow(1, 0, k),
            right: h.narrow(1, k, k),
        }
    }
}
