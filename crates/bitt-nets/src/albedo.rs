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

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{InstanceNorm, InstanceNormConfig, PaddingConfig2d};
use burn::tensor::activation::{leaky_relu, relu, sigmoid};
use burn::tensor::ops::PadMode;
use burn::tensor::{Device, Tensor};

use crate::NetsError;

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
pub struct UnetLevel {
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
    pub fn size_multiple(&self) -> usize {
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

/// Nearest-neighbour x2 upsampling: `[N, C, H, W] -> [N, C, 2H, 2W]`.
fn upsample2(x: Tensor<4>) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    x.reshape([n, c, h, 1, w, 1])
        .expand([n, c, h, 2, w, 2])
        .reshape([n, c, 2 * h, 2 * w])
}

impl UnetLevel {
    fn up(&self, x: Tensor<4>) -> Tensor<4> {
        let x = upsample2(relu(x));
        let x = if self.outermost {
            x.pad((1, 1, 1, 1), PadMode::Edge)
        } else {
            x
        };
        let y = self.up.forward(x);
        match &self.up_norm {
            Some(norm) => norm.forward(y),
            None => y,
        }
    }

    fn down(&self, x: Tensor<4>) -> Tensor<4> {
        let y = self.down.forward(x);
        match &self.down_norm {
            Some(norm) => norm.forward(y),
            None => y,
        }
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
        // Down: remember each inner level's (activated) input for its skip connection.
        let mut skips = Vec::with_capacity(self.levels.len());
        let mut h = image;
        for (i, level) in self.levels.iter().enumerate() {
            if i > 0 {
                h = leaky_relu(h, self.leaky_slope);
                skips.push(h.clone());
            }
            h = level.down(h);
        }
        // Up, innermost first: each inner level returns [its input, its up path].
        for (i, level) in self.levels.iter().enumerate().rev() {
            h = level.up(h);
            if i > 0 {
                let skip = skips.pop().expect("one skip per inner level");
                h = Tensor::cat(vec![skip, h], 1);
            }
        }
        sigmoid(h)
    }
}
