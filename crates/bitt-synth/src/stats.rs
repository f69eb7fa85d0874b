//! Texture-space visibility of the training view: the paper's Table 3.
//!
//! A texel of a hand is *visible* when [`bitt_render::scene::unwrap`] finds it in the image
//! (front-facing, in the frame, not occluded by either hand; the unwrap's default 5 mm depth
//! tolerance), on the layouts of [`crate::texture_layouts`] (the textures' layouts, gutter
//! included). [`TexelVisibilityStats`] counts, over the `T` texels shared by both hands: visible
//! on the left, on the right, on exactly one hand ("usable through symmetry" in the set
//! sense), on neither. The paper's prose ("using symmetric information, we can acquire up to
//! 60% texture of each hand; otherwise only about 35%") is the per-hand view: a hand's texels
//! invisible on it but visible on the other hand ([`TexelStats::symmetry_gain`]), and the
//! share of each hand seen on either hand ([`TexelStats::reachable`]).

use bitt_mesh::{HandPair, Side};
use bitt_render::scene::{TexelSurface, TexelVisibilityStats, UnwrapSettings, unwrap};
use bitt_texture::TextureLayout;
use burn::tensor::Device;

use crate::render::{HandRenderer, RenderedView};
use crate::{SynthError, SynthScene, texture_layouts};

/// Table-3 statistics of one view (or their mean over scenes).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelStats {
    /// Left visible, right visible, visible on exactly one hand, visible on neither.
    pub table3: TexelVisibilityStats,
    /// Mean over both hands of the share of a hand's texels invisible on it but visible on
    /// the other hand (what symmetry adds to each hand).
    pub symmetry_gain: f64,
    /// Mean over both hands of the share of its texels visible on it or on the other hand.
    pub reachable: f64,
}

impl TexelStats {
    /// Statistics of the two visible masks.
    ///
    /// # Errors
    /// Masks of different lengths.
    pub fn from_masks(left: &[bool], right: &[bool]) -> Result<Self, SynthError> {
        let table3 = TexelVisibilityStats::from_masks(left, right)?;
        let t = left.len().max(1) as f64;
        let gain_left = left.iter().zip(right).filter(|(l, r)| !**l && **r).count() as f64 / t;
        let gain_right = left.iter().zip(right).filter(|(l, r)| **l && !**r).count() as f64 / t;
        let symmetry_gain = 0.5 * (gain_left + gain_right);
        Ok(TexelStats {
            table3,
            symmetry_gain,
            reachable: 0.5 * (table3.left_visible + table3.right_visible) + symmetry_gain,
        })
    }

    /// The mean of several scenes' statistics (scenes weigh equally); `None` when empty.
    pub fn mean(all: &[Self]) -> Option<Self> {
        let tables: Vec<TexelVisibilityStats> = all.iter().map(|s| s.table3).collect();
        let n = all.len() as f64;
        Some(TexelStats {
            table3: TexelVisibilityStats::mean(&tables)?,
            symmetry_gain: all.iter().map(|s| s.symmetry_gain).sum::<f64>() / n,
            reachable: all.iter().map(|s| s.reachable).sum::<f64>() / n,
        })
    }
}

/// The visible masks of both hands' texels in a rendered view.
///
/// # Errors
/// Layouts that do not belong to the models, rendering errors.
pub(crate) fn view_visibility(
    models: &HandPair,
    layouts: &[TextureLayout; 2],
    view: &RenderedView,
) -> Result<[Vec<bool>; 2], SynthError> {
    let mut out: [Vec<bool>; 2] = Default::default();
    for (k, side) in Side::BOTH.into_iter().enumerate() {
        let model = models.get(side);
        let surface = TexelSurface::new(&layouts[k], &model.faces, model.num_vertices())?;
        let u = unwrap(
            view.render.image.clone(),
            &view.camera,
            &surface,
            &view.vertices[k],
            &view.render.raster,
            &UnwrapSettings::default(),
        )?;
        out[k] = u.visible_host;
    }
    Ok(out)
}

/// Table-3 statistics of a rendered view.
pub(crate) fn view_stats(
    models: &HandPair,
    layouts: &[TextureLayout; 2],
    view: &RenderedView,
) -> Result<TexelStats, SynthError> {
    let [l, r] = view_visibility(models, layouts, view)?;
    TexelStats::from_masks(&l, &r)
}

/// Recomputes the Table-3 statistics of a scene's training view (re-rendering it on
/// `device`); equals `scene.stats` for a scene from [`crate::generate_scene`].
///
/// # Errors
/// Textures that do not fit the configuration's layout, rendering errors.
pub fn scene_stats(scene: &SynthScene, device: &Device) -> Result<TexelStats, SynthError> {
    let models = bitt_mesh::procedural_pair();
    let layouts = texture_layouts(&models, scene.config.texture_size)?;
    let renderer = HandRenderer::new(&models, &layouts, &scene.textures, device)?;
    let view = renderer.render(&scene.train.hands, &scene.train.light)?;
    view_stats(&models, &layouts, &view)
}
