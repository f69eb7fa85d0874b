//! Scores of a trained real avatar at novel views and poses against the photographs.

use bitt_render::scene::LightValuesExt;

use bitt_mesh::TwoHandScene;
use bitt_render::scene::{LightValues, RenderSettings};
use burn::tensor::Tensor;

use super::{RealScene, RealView};
use crate::BittError;
use crate::assets::ViewGeometry;
use crate::trainer::Trainer;
use bitt_stdx::to_host;

/// Scores of a real multi-view scene against its photographs (hands masked by the given
/// meshes' silhouettes, as the reference's `masked_img`).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RealScores {
    /// Mean over the novel views.
    pub novel_views: Option<crate::evaluate::MeanScore>,
    /// Mean over the novel poses.
    pub novel_poses: Option<crate::evaluate::MeanScore>,
    /// Per view: name, fine and coarse metrics.
    pub views: Vec<(String, crate::evaluate::ViewScore)>,
}

/// Silhouette masks `[H, W]` of both hands (after the shared depth test) of `hands`.
pub fn hand_masks(trainer: &Trainer, hands: &TwoHandScene) -> Result<[Vec<f32>; 2], BittError> {
    let device = trainer.view.image.device().inner();
    silhouettes(&trainer.assets, hands, &device)
}

/// Silhouette masks `[H, W]` of both hands of `hands` (after the shared depth test: each
/// pixel belongs to the hand in front), without antialiasing.
pub fn silhouettes(
    assets: &crate::assets::HandAssets,
    hands: &TwoHandScene,
    device: &burn::tensor::Device,
) -> Result<[Vec<f32>; 2], BittError> {
    let geometry = ViewGeometry::new(assets, hands, device)?;
    let t = assets.num_texels();
    let zeros = Tensor::<2>::zeros([3, t], device);
    let settings = RenderSettings {
        antialias: false,
        ..RenderSettings::default()
    };
    let r = geometry.render(
        assets,
        [zeros.clone(), zeros],
        &LightValues::default().to_light(device),
        &settings,
    )?;
    let mut masks = r.masks.into_iter().map(to_host);
    let (Some(l), Some(r)) = (masks.next(), masks.next()) else {
        return Err(BittError::Invalid("the render has no mask per hand".into()));
    };
    Ok([l?, r?])
}

/// Renders the trained avatar at every novel view and pose of `scene` (the estimated light
/// kept fixed in the capture's world) and scores fine and coarse renders against the
/// photographs.
pub fn score_real(trainer: &Trainer, scene: &RealScene) -> Result<RealScores, BittError> {
    let avatar = crate::evaluate::Avatar::from_trainer(trainer)?;
    let mut views = Vec::new();
    let mut score = |v: &RealView| -> Result<crate::evaluate::ViewScore, BittError> {
        let masks = hand_masks(trainer, &v.hands)?;
        let (s, _, _) = crate::evaluate::score_view(trainer, &avatar, &v.hands, &v.image, &masks)?;
        views.push((v.name.clone(), s));
        Ok(s)
    };
    let nv: Vec<_> = scene
        .novel_views
        .iter()
        .map(&mut score)
        .collect::<Result<_, _>>()?;
    let np: Vec<_> = scene
        .novel_poses
        .iter()
        .map(&mut score)
        .collect::<Result<_, _>>()?;
    let mean = |s: &[crate::evaluate::ViewScore]| {
        let fine: Vec<_> = s.iter().map(|x| x.fine).collect();
        let coarse: Vec<_> = s.iter().map(|x| x.coarse).collect();
        Some(crate::evaluate::MeanScore {
            fine: crate::evaluate::mean_metrics(&fine)?,
            coarse: crate::evaluate::mean_metrics(&coarse)?,
            count: s.len(),
        })
    };
    Ok(RealScores {
        novel_views: mean(&nv),
        novel_poses: mean(&np),
        views,
    })
}
