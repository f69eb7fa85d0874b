//! Named configurations of all four networks: `paper`, `quick`, `tiny`.

use std::fmt;
use std::str::FromStr;

use burn::config::Config;
use burn::module::Module;
use burn::tensor::Device;

use crate::NetsError;
use crate::albedo::{AlbedoNet, AlbedoNetConfig};
use crate::btr::{Btr, BtrConfig};
use crate::html_encoder::{HtmlEncoder, HtmlEncoderConfig};
use crate::light::{LightNet, LightNetConfig};

/// HTML's compact texel count: valid texels of its 1024 x 1024 UV map (paper Sec. 3.2).
pub const PAPER_TEXELS: usize = 206_330;

/// Texels of the procedural hand's 256 x 256 UV layout (2-texel gutter), the `quick`
/// preset's texture.
pub const QUICK_TEXELS: usize = 28_544;

/// A named configuration of the networks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The paper's networks: 256 x 256 images, `T = 206,330` texels, supplement D widths.
    Paper,
    /// For the CPU demo: 128 x 128 images, a procedural layout of tens of thousands of
    /// texels, narrower networks.
    Quick,
    /// For tests and backend checks: runs in seconds.
    Tiny,
}

impl Preset {
    /// Every preset, largest first.
    pub const ALL: [Preset; 3] = [Preset::Paper, Preset::Quick, Preset::Tiny];

    /// The lowercase name (`paper`, `quick`, `tiny`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
            Preset::Quick => "quick",
            Preset::Tiny => "tiny",
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = NetsError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| NetsError::UnknownPreset(s.to_string()))
    }
}

/// The configuration of all four networks, as the trainer saves it (`config.json`).
#[derive(Config, Debug)]
pub struct BittNetsConfig {
    /// Side of the square input images of `A`, `L` and `H`.
    pub image_size: usize,
    /// Texels per hand the BTR works on. The networks accept any count (BTR is fully
    /// convolutional); this is the count of the preset's UV layout, used for shapes and
    /// benchmarks (for `quick` a nominal size of the procedural layout).
    pub num_texels: usize,
    /// Albedo network `A`.
    pub albedo: AlbedoNetConfig,
    /// Light network `L`.
    pub light: LightNetConfig,
    /// HTML network `H`.
    pub html: HtmlEncoderConfig,
    /// Bi-directional texture reconstructor.
    pub btr: BtrConfig,
}

impl BittNetsConfig {
    /// The named configuration.
    pub fn preset(preset: Preset) -> Self {
        match preset {
            // Supplement A (256 x 256 images), D (widths), Sec. 3.2 (206,330 texels).
            Preset::Paper => BittNetsConfig::new(
                256,
                PAPER_TEXELS,
                AlbedoNetConfig::new(),
                LightNetConfig::new(),
                HtmlEncoderConfig::new(),
                BtrConfig::new(),
            ),
            // Sized so that `cargo xtask train-scene` trains in about 2 minutes on a 2-core
            // CPU: the procedural hand's 256 x 256 UV layout (28,544 texels), a quarter of the
            // paper's albedo widths and an eighth of BTR's below the stem (8 groups per norm
            // need multiples of 8). BTR was `8, 16, 32, 64` until 2026-12-06; this width
            // trains the demo in about 0.64x the time with equal or better scores on it
            // (`docs/training.md`, issue 37).
            Preset::Quick => BittNetsConfig::new(
                128,
                QUICK_TEXELS,
                AlbedoNetConfig::new().with_base_channels(16),
                LightNetConfig::new()
                    .with_image_size(128)
                    .with_base_channels(16),
                HtmlEncoderConfig::new()
                    .with_image_size(128)
                    .with_base_channels(16),
                BtrConfig::new().with_channels(vec![8, 8, 16, 32]),
            ),
            Preset::Tiny => BittNetsConfig::new(
                32,
                999,
                AlbedoNetConfig::new()
                    .with_base_channels(8)
                    .with_num_downs(5),
                LightNetConfig::new()
                    .with_image_size(32)
                    .with_base_channels(4),
                HtmlEncoderConfig::new()
                    .with_image_size(32)
                    .with_base_channels(4),
                BtrConfig::new().with_channels(vec![8, 16, 16, 24]),
            ),
        }
    }

    /// Checks that the parts fit together (image sizes, widths, texel count).
    pub fn validate(&self) -> Result<(), NetsError> {
        self.albedo.validate()?;
        self.light.encoder().validate()?;
        self.html.encoder().validate()?;
        self.btr.validate()?;
        for (name, size) in [
            ("light", self.light.image_size),
            ("html", self.html.image_size),
        ] {
            if size != self.image_size {
                return Err(NetsError::Invalid(format!(
                    "{name} network image size {size} differs from image_size {}",
                    self.image_size
                )));
            }
        }
        if !self.image_size.is_multiple_of(self.albedo.size_multiple()) {
            return Err(NetsError::Invalid(format!(
                "image size {} is not a multiple of the albedo U-Net's {}",
                self.image_size,
                self.albedo.size_multiple()
            )));
        }
        if self.num_texels < self.btr.min_texels() {
            return Err(NetsError::Invalid(format!(
                "{} texels is too short for BTR (at least {})",
                self.num_texels,
                self.btr.min_texels()
            )));
        }
        Ok(())
    }

    /// Creates all four networks.
    ///
    /// # Errors
    /// When [`BittNetsConfig::validate`] fails.
    pub fn init(&self, device: &Device) -> Result<BittNets, NetsError> {
        self.validate()?;
        Ok(BittNets {
            albedo: self.albedo.init(device),
            light: self.light.init(device),
            html: self.html.init(device),
            btr: self.btr.init(device),
        })
    }
}

/// The four networks of BiTT (paper Fig. 2).
#[derive(Module, Debug)]
pub struct BittNets {
    /// Albedo network `A` (Sec. 3.1).
    pub albedo: AlbedoNet,
    /// Light network `L` (Sec. 3.1).
    pub light: LightNet,
    /// HTML network `H` (Sec. 3.2).
    pub html: HtmlEncoder,
    /// Bi-directional texture reconstructor (Sec. 3.3).
    pub btr: Btr,
}

impl BittNets {
    /// Parameter count of each network: `[albedo, light, html, btr]`.
    pub fn param_counts(&self) -> [(&'static str, usize); 4] {
        [
            ("albedo", self.albedo.num_params()),
            ("light", self.light.num_params()),
            ("html", self.html.num_params()),
            ("btr", self.btr.num_params()),
        ]
    }
}
