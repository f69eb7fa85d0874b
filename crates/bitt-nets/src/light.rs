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
pub(crate) const LIGHT_COLOR_SCALE: f64 = 0.4;
/// See [`LIGHT_COLOR_SCALE`].
pub(crate) const LIGHT_COLOR_OFFSET: f64 = 0.6;

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

    /// The same light with one colour: the colour of the three parts together,
    /// `c = (ambient + diffuse + specular) / mean(ambient + diffuse + specular)`, and each
    /// part keeps only its mean as an intensity of it (`ambient' = c * mean(ambient)`, the
    /// same for diffuse and specular).
    ///
    /// Not from the paper, which gives each part its own colour. A photograph's colour cast
    /// is one colour (the camera's white balance and one light rig), and with three colours
    /// the networks explain it by a diffuse colour unlike the ambient one: the albedo then
    /// takes the opposite tint wherever the diffuse part was strong in the photo, and shows
    /// it as a blotch wherever a new pose turns that skin away from the light (issue 34).
    /// The colour comes from all three parts because a part pushed to the end of its range
    /// (the ambient one, on the demo photos) has no gradient left to change its colour.
    /// The real-photo trainer uses this (`loss.photo_light`); synthetic scenes keep the paper's.
    ///
    /// # Shapes
    /// - every part `[B, 3]`, unchanged
    pub fn one_colour(self) -> LightParams {
        let mean = |t: &Tensor<2>| t.clone().mean_dim(1);
        let sum = self.ambient.clone() + self.diffuse.clone() + self.specular.clone();
        let colour = sum.clone() / mean(&sum);
        LightParams {
            ambient: colour.clone() * mean(&self.ambient),
            diffuse: colour.clone() * mean(&self.diffuse),
            specular: colour * mean(&self.specular),
            location: self.location,
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

    #[test]
    fn one_colour_keeps_the_mean_intensities_in_one_colour() {
        let device = Device::flex();
        let raw = Tensor::<2>::from_floats(
            [[
                0.9f32, 0.2, -0.4, -1.0, 2.0, -1.0, 0.0, 0.5, 1.0, 0.3, -0.2, 0.1,
            ]],
            &device,
        );
        let p = LightParams::from_raw(raw);
        let (a, d, s) = (
            to_vec(p.ambient.clone()),
            to_vec(p.diffuse.clone()),
            to_vec(p.specular.clone()),
        );
        let location = to_vec(p.location.clone());
        let one = p.one_colour();
        let mean = |v: &[f32]| v.iter().sum::<f32>() / 3.0;
        let sum: Vec<f32> = (0..3).map(|c| a[c] + d[c] + s[c]).collect();
        let scaled =
            |v: &[f32]| -> Vec<f32> { sum.iter().map(|c| c / mean(&sum) * mean(v)).collect() };
        assert_close(&to_vec(one.ambient.clone()), &scaled(&a), 1e-6, "ambient");
        assert_close(&to_vec(one.diffuse.clone()), &scaled(&d), 1e-6, "diffuse");
        assert_close(&to_vec(one.specular), &scaled(&s), 1e-6, "specular");
        assert_close(&to_vec(one.location), &location, 0.0, "location");
        // Ambient and diffuse now share one chromaticity, and keep their mean intensity.
        let (aa, dd) = (to_vec(one.ambient), to_vec(one.diffuse));
        for c in 0..3 {
            assert!((dd[c] / dd[0] - aa[c] / aa[0]).abs() < 1e-5);
        }
        assert!((mean(&dd) - mean(&d)).abs() < 1e-6);
    }
}
