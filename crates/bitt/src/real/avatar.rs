//! A saved real avatar read back from its folder, and textures rendered on any hands.

use bitt_render::scene::LightValuesExt;
use bitt_stdx::FileErrorExt;

use std::path::Path;

use bitt_mesh::{PinholeCamera, TwoHandScene};
use bitt_render::scene::{LightValues, RenderSettings};
use burn::tensor::{Device, Tensor, TensorData};

use super::{RealInput, load_models};
use crate::BittError;
use crate::assets::{HandAssets, ViewGeometry};
use crate::config::TrainConfig;
use bitt_stdx::to_host;

/// A real run's avatar read back from its folder (no networks needed).
#[derive(Debug, Clone)]
pub struct RealAvatar {
    /// The run's (adapted) configuration.
    pub config: TrainConfig,
    /// The run's input record.
    pub input: RealInput,
    /// Fine textures `[3, T]`, left then right.
    pub fine: [Vec<f32>; 2],
    /// The estimated light, in the training camera's frame.
    pub light: LightValues,
}

impl RealAvatar {
    /// Reads `config.json`, `input.json`, `textures/textures.safetensors` and `light.json`.
    pub fn load(dir: &Path) -> Result<Self, BittError> {
        let path = dir.join(crate::files::CONFIG);
        let text = std::fs::read_to_string(&path).map_err(|e| BittError::io(&path, e))?;
        let config = TrainConfig::from_json(&text, &path)?;
        let input = RealInput::read(dir)?;
        Ok(RealAvatar {
            config,
            input,
            fine: crate::files::read_fine_textures(dir)?,
            light: crate::files::read_light(dir)?,
        })
    }

    /// The hand models and assets the avatar was trained with (MANO and HTML's UV layouts
    /// are read from the folders `input.json` names).
    pub fn assets(&self) -> Result<HandAssets, BittError> {
        let models = load_models(&self.input.hands, &self.input.prior)?;
        let assets = HandAssets::new(models, self.config.texture.resolution)?;
        if self.fine[0].len() != 3 * assets.num_texels() {
            return Err(BittError::Invalid(format!(
                "the saved textures have {} values; the hands' {}x{} layout needs {}",
                self.fine[0].len(),
                self.config.texture.resolution,
                self.config.texture.resolution,
                3 * assets.num_texels()
            )));
        }
        Ok(assets)
    }

    /// The training camera (fitted to the preset's size).
    pub fn camera(&self) -> PinholeCamera {
        self.input.train.hands.camera
    }
}

/// Renders compact textures `[3, T]` (left, right) on `hands` (camera included) under
/// `light` (in that camera's frame), shaded with ambient occlusion of `occlusion` strength
/// (the run's `loss.photo_occlusion`; [`ViewGeometry::with_occlusion`]): `[3, H, W]` on the
/// host.
pub fn render_textures(
    assets: &HandAssets,
    textures: &[Vec<f32>; 2],
    hands: &TwoHandScene,
    light: &LightValues,
    occlusion: f64,
    device: &Device,
) -> Result<Vec<f32>, BittError> {
    let t = assets.num_texels();
    for tex in textures {
        if tex.len() != 3 * t {
            return Err(BittError::Invalid(format!(
                "a texture has {} values; the layout needs {}",
                tex.len(),
                3 * t
            )));
        }
    }
    let geometry = ViewGeometry::new(assets, hands, device)?.with_occlusion(assets, occlusion)?;
    let tex = |v: &Vec<f32>| Tensor::<2>::from_data(TensorData::new(v.clone(), [3, t]), device);
    let r = geometry.render(
        assets,
        [tex(&textures[0]), tex(&textures[1])],
        &light.to_light(device),
        &RenderSettings::default(),
    )?;
    Ok(to_host(r.image)?)
}
