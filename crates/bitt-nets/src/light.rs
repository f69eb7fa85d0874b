//! The light network `L` (paper Sec. 3.1 "Scene Estimation"; supplement D "Light Network")
//! and the mapping of its 12 outputs to the renderer's light values.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::encoder::{ConvEncoder, ConvEncoderConfig};

/// Number of light values the network predicts: ambient color, diffuse, specular, location.
pub const LIGHT_OUTPUTS: usize = 12;

/// Configuration of [`LightNet`].
#[derive(Config, Debug)]
pub struct LightNetConfig {
    /// Side of the square input image (the paper's images are 256 x 256, supplement A).
    #[config(default = 256)]
    pub image_size: usize,
    /// Width of the first convolution; widths 32, 64, 128, 256 (supplement D).
    #[config(default = 32)]
    pub base_channels: usize,
}

/// The light network: an image encoder to 12 numbers in `(-1, 1)` (tanh).
#[derive(Module, Debug)]
pub struct LightNet {
    encoder: ConvEncoder,
}

impl LightNetConfig {
    /// The encoder this network is made of.
    pub fn encoder(&self) -> ConvEncoderConfig {
        ConvEncoderConfig::new(LIGHT_OUTPUTS, self.image_size, self.base_channels)
    }

    /// Creates the network.
    ///
    /// # Panics
    /// When the image size is not a power of two >= 4.
    pub fn init(&self, device: &Device) -> LightNet {
        LightNet {
            encoder: self.encoder().init(device),
        }
    }
}

impl LightNet {
    /// Predicts the raw light vector; [`LightParams::from_raw`] maps it to light values.
    ///
    /// # Shapes
    /// - `image`: `[B, 3, S, S]`
    /// - output: `[B, 12]`, in `(-1, 1)`
    pub fn forward(&self, image: Tensor<4>) -> Tensor<2> {
        self.encoder.forward(image)
    }

    /// [`LightNet::forward`] followed by [`LightParams::from_raw`].
    ///
    /// # Shapes
    /// - `image`: `[B, 3, S, S]`
    /// - output: four `[B, 3]` tensors
    pub fn predict(&self, image: Tensor<4>) -> LightParams {
        LightParams::from_raw(self.forward(image))
    }
}

/// Light values of a Phong light per scene (paper Sec. 3.1: ambient color, diffuse,
/// specular, location), as the renderer consumes them.
#[derive(Debug, Clone)]
pub struct LightParams {
    /// Ambient color `[B, 3]`, in `[0.2, 1]`.
    pub ambient: Tensor<2>,
    /// Diffuse color `[B, 3]`, in `[0.2, 1]`.
    pub diffuse: Tensor<2>,
    /// Specular color `[B, 3]`, in `[0.2, 1]`.
    pub specular: Tensor<2>,
    /// Point light location `[B, 3]` (camera frame), in `[-1, 1]`.
    pub location: Tensor<2>,
}

/// Colors are `0.6 + 0.4 x` for `x` in `[-1, 1]`: the range `[0.2, 1]` of supplement D.
pub const LIGHT_COLOR_SCALE: f64 = 0.4;
/// See [`LIGHT_COLOR_SCALE`].
pub const LIGHT_COLOR_OFFSET: f64 = 0.6;

impl LightParams {
    /// The one mapping from the light network's 12 outputs to light values.
    ///
    /// With `x = tanh(raw)`:
    ///
    /// | outputs | value | mapping | range |
    /// |---|---|---|---|
    /// | `0..3` | ambient color | `0.6 + 0.4 x` | `[0.2, 1]` |
    /// | `3..6` | diffuse color | `0.6 + 0.4 x` | `[0.2, 1]` |
    /// | `6..9` | specular color | `0.6 + 0.4 x` | `[0.2, 1]` |
    /// | `9..12` | location | `x` | `[-1, 1]` |
    ///
    /// The `tanh` here is applied to the network's output, which already ends in a `tanh`:
    /// the reference implementation does exactly that (two `tanh` in a row), so the values
    /// actually reached are `0.6 ± 0.4 tanh(1)`, i.e. about `[0.295, 0.905]` for colors and
    /// `±0.762` for the location.
    ///
    /// # Shapes
    /// - `raw`: `[B, 12]`
    /// - output: four `[B, 3]` tensors
    ///
    /// # Panics
    /// When `raw` does not have 12 columns.
    pub fn from_raw(raw: Tensor<2>) -> LightParams {
        assert_eq!(
            raw.dims()[1],
            LIGHT_OUTPUTS,
            "light vector must have 12 values"
        );
        let x = raw.tanh();
        let color = |i: usize| {
            x.clone()
                .narrow(1, i, 3)
                .mul_scalar(LIGHT_COLOR_SCALE)
                .add_scalar(LIGHT_COLOR_OFFSET)
        };
        LightParams {
            ambient: color(0),
            diffuse: color(3),
            specular: color(6),
            location: x.clone().narrow(1, 9, 3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::{assert_close, to_vec};

    #[test]
    fn mapping_puts_each_value_in_its_range() {
        let device = Device::flex();
        let raw: Vec<f32> = (0..12).map(|i| i as f32 - 6.0).collect();
        let raw = Tensor::<2>::from_floats([<[f32; 12]>::try_from(raw).unwrap()], &device);
        let p = LightParams::from_raw(raw);
        let t = |v: f32| 0.6 + 0.4 * v.tanh();
        assert_close(
            &to_vec(p.ambient),
            &[t(-6.0), t(-5.0), t(-4.0)],
            1e-6,
            "ambient",
        );
        assert_close(
            &to_vec(p.diffuse),
            &[t(-3.0), t(-2.0), t(-1.0)],
            1e-6,
            "diffuse",
        );
        assert_close(
            &to_vec(p.specular),
            &[t(0.0), t(1.0), t(2.0)],
            1e-6,
            "specular",
        );
        assert_close(
            &to_vec(p.location),
            &[3.0f32.tanh(), 4.0f32.tanh(), 5.0f32.tanh()],
            1e-6,
            "location",
        );
    }
}
