//! Rendering a trained avatar at other views, poses and lights, and measuring it against
//! ground truth (synthetic scenes).

use bitt_render::scene::LightValuesExt;

use bitt_mesh::glam::DVec3;
use bitt_mesh::{PinholeCamera, TwoHandScene};
use bitt_render::scene::{LightValues, PointLight};
use burn::tensor::{Tensor, TensorData};

use crate::EvalError;
use crate::metrics::{ImageMetrics, TextureErrors, image_metrics, texture_errors};
use bitt_stdx::to_host;
use bitt_train::assets::ViewGeometry;
use bitt_train::pipeline::Outputs;
use bitt_train::trainer::Trainer;

/// Host copies of a trained avatar: compact textures `[3, T]` and the estimated light.
#[derive(Debug, Clone)]
pub struct Avatar {
    /// Fine textures (BTR output), left then right.
    pub fine: [Vec<f32>; 2],
    /// Coarse textures `T(h_i)`.
    pub coarse: [Vec<f32>; 2],
    /// Unwrapped visible albedo texels `u_i`.
    pub albedo_uv: [Vec<f32>; 2],
    /// Visible masks `v_i` (one value per texel).
    pub visible: [Vec<f32>; 2],
    /// The estimated light in the training camera's frame.
    pub light: LightValues,
    /// The training camera (to move the light to other views).
    pub camera: PinholeCamera,
}

/// The highest HSV saturation a fine texel may have: skin never comes near it (the demo
/// frames' coarse textures reach 0.44, their visible albedo texels 0.62), while a few
/// hidden texels BTR invented on `02` reached 0.99 (saturated green; docs/training.md,
/// Real data). Issue 34's acceptance threshold.
pub const MAX_SKIN_SATURATION: f32 = 0.85;

/// HSV saturation of an RGB value, `(max - min) / max` (0 for black).
pub(crate) fn hsv_saturation(rgb: [f32; 3]) -> f32 {
    let max = rgb[0].max(rgb[1]).max(rgb[2]);
    let min = rgb[0].min(rgb[1]).min(rgb[2]);
    if max <= 0.0 {
        0.0
    } else {
        (max - min.max(0.0)) / max
    }
}

/// The highest HSV saturation of any texel of a texture `[3, T]` (0 for none).
pub fn max_hsv_saturation(texture: &[f32]) -> f32 {
    let t = texture.len() / 3;
    (0..t)
        .map(|i| hsv_saturation([texture[i], texture[t + i], texture[2 * t + i]]))
        .fold(0.0, f32::max)
}

/// Texels whose ambient occlusion is below this are "in shade" for [`albedo_in_shade`].
pub(crate) const SHADE_OCCLUSION: f32 = 0.6;
/// Texels whose ambient occlusion is above this are "open" for [`albedo_in_shade`].
pub(crate) const OPEN_OCCLUSION: f32 = 0.9;

/// How much darker an albedo is in shade than in the open: over the texels `visible` per
/// hand, the mean luminance (Rec. 709) of `textures` (`[3, T]` per hand) on the texels
/// whose ambient occlusion `ao` is below [`SHADE_OCCLUSION`] divided by that on the texels
/// whose ambient occlusion is above [`OPEN_OCCLUSION`]. An albedo with a photo's crease
/// shadows painted into it reads well below 1; skin of one colour reads 1. `None` when
/// either class has fewer than 20 texels.
pub fn albedo_in_shade(
    textures: &[Vec<f32>; 2],
    visible: &[Vec<bool>; 2],
    ao: &[Vec<f32>; 2],
) -> Option<f64> {
    let (mut shade, mut open) = ((0.0f64, 0usize), (0.0f64, 0usize));
    for h in 0..2 {
        let t = textures[h].len() / 3;
        for i in (0..t).filter(|&i| visible[h].get(i) == Some(&true)) {
            let (tex, a) = (&textures[h], ao[h].get(i).copied().unwrap_or(1.0));
            let lum = 0.2126 * tex[i] + 0.7152 * tex[t + i] + 0.0722 * tex[2 * t + i];
            let class = if a < SHADE_OCCLUSION {
                &mut shade
            } else if a > OPEN_OCCLUSION {
                &mut open
            } else {
                continue;
            };
            class.0 += f64::from(lum);
            class.1 += 1;
        }
    }
    (shade.1 >= 20 && open.1 >= 20 && open.0 > 0.0)
        .then(|| (shade.0 / shade.1 as f64) / (open.0 / open.1 as f64))
}

/// Detail a texture has where no photo shows the hand, beyond its prior's (issue 34, palm):
/// see [`unseen_detail`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UnseenDetail {
    /// Texels (both hands together) of the region that neither hand's photo shows.
    pub texels: usize,
    /// Mean absolute high-pass of `texture - prior` on them (all channels, `[0, 1]` values):
    /// detail the texture has there and the prior does not.
    pub invented: f64,
    /// Mean absolute high-pass of the prior on them: the prior's own detail, for scale.
    pub prior: f64,
    /// Mean `|texture - prior|` on them: how far the colour moved from the prior's.
    pub shift: f64,
}

/// Side of the square UV window [`unseen_detail`]'s high-pass subtracts the mean of.
pub use crate::metrics::DETAIL_WINDOW;

/// How much detail `texture` (`[3, T]` per hand) invented where neither photo shows the
/// hand: over the texels of `region` that are visible in neither hand (BTR's other source is
/// the same texel of the other hand), the mean absolute high-pass of `texture - prior`, where
/// the high-pass of a texel is its value minus the mean of the used texels in the
/// [`DETAIL_WINDOW`]-square window around it on `layout`'s UV grid. A texture that keeps
/// the prior's detail and only shifts its colour smoothly reads near 0; one that paints
/// creases, spots or streaks there reads like [`UnseenDetail::prior`] or above. `None`
/// with fewer than 20 such texels, or textures that do not fit `layout`.
pub fn unseen_detail(
    texture: &[Vec<f32>; 2],
    prior: &[Vec<f32>; 2],
    visible: &[Vec<bool>; 2],
    region: &[Vec<bool>; 2],
    layout: &bitt_texture::TextureLayout,
) -> Option<UnseenDetail> {
    let t = layout.num_texels();
    let fits = |v: &[Vec<f32>; 2]| v.iter().all(|x| x.len() == 3 * t);
    let fits_mask = |v: &[Vec<bool>; 2]| v.iter().all(|x| x.len() == t);
    if !(fits(texture) && fits(prior) && fits_mask(visible) && fits_mask(region)) {
        return None;
    }
    let r = (DETAIL_WINDOW / 2) as i64;
    // The high-pass of channel `c` of `values` at texel `i`.
    let high_pass = |values: &dyn Fn(usize) -> f64, c: usize, i: usize| {
        let (row, col) = layout.texels[i];
        let (mut sum, mut n) = (0.0, 0usize);
        for dy in -r..=r {
            for dx in -r..=r {
                let (y, x) = (i64::from(row) + dy, i64::from(col) + dx);
                if y < 0 || x < 0 {
                    continue;
                }
                if let Some(j) = layout.compact_index(y as usize, x as usize) {
                    sum += values(c * t + j);
                    n += 1;
                }
            }
        }
        values(c * t + i) - sum / n as f64
    };
    let (mut invented, mut own, mut shift, mut texels) = (0.0, 0.0, 0.0, 0usize);
    for h in 0..2 {
        let (tex, pri) = (&texture[h], &prior[h]);
        let diff = |k: usize| f64::from(tex[k]) - f64::from(pri[k]);
        let pri_at = |k: usize| f64::from(pri[k]);
        for i in (0..t).filter(|&i| region[h][i] && !visible[0][i] && !visible[1][i]) {
            texels += 1;
            for c in 0..3 {
                invented += high_pass(&diff, c, i).abs();
                own += high_pass(&pri_at, c, i).abs();
                shift += diff(c * t + i).abs();
            }
        }
    }
    let n = (3 * texels) as f64;
    (texels >= 20).then(|| UnseenDetail {
        texels,
        invented: invented / n,
        prior: own / n,
        shift: shift / n,
    })
}

/// Replaces each texel of `fine` (`[3, T]`) whose HSV saturation, as it is or rounded to 8
/// bits, is above [`MAX_SKIN_SATURATION`] with the same texel of `coarse` (the texture
/// prior's); returns how many were replaced. The avatar's fine textures pass through it, so
/// no file, render or score carries a texel no skin has.
pub(crate) fn replace_implausible_texels(fine: &mut [f32], coarse: &[f32]) -> usize {
    let t = fine.len() / 3;
    let mut replaced = 0;
    for i in 0..t {
        let rgb = [fine[i], fine[t + i], fine[2 * t + i]];
        // As written to an 8-bit PNG too: rounding moves a dark texel's saturation by up to
        // a few hundredths.
        let png = rgb.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0);
        if hsv_saturation(rgb).max(hsv_saturation(png)) > MAX_SKIN_SATURATION {
            for c in 0..3 {
                fine[c * t + i] = coarse[c * t + i];
            }
            replaced += 1;
        }
    }
    replaced
}

impl Avatar {
    /// Reads the avatar of the trainer's current networks (one forward pass).
    pub fn from_trainer(trainer: &Trainer) -> Result<Self, EvalError> {
        Self::from_outputs(trainer, &trainer.forward()?)
    }

    /// Reads the avatar from a forward pass `o` of the trainer's networks.
    pub fn from_outputs(trainer: &Trainer, o: &Outputs) -> Result<Self, EvalError> {
        let host = |t: &Tensor<3>| to_host(t.clone().inner());
        let pair = |a: &[Tensor<3>; 2]| -> Result<[Vec<f32>; 2], EvalError> {
            Ok([host(&a[0])?, host(&a[1])?])
        };
        let l = &o.light;
        let mut values = Vec::with_capacity(12);
        for part in [&l.ambient, &l.diffuse, &l.specular, &l.location] {
            values.extend(to_host(part.clone().inner())?);
        }
        let light =
            LightValues::from_array(values.try_into().map_err(|_| {
                EvalError::Invalid("the light network did not give 12 values".into())
            })?);
        let mut fine = pair(&o.fine)?;
        let coarse = pair(&o.coarse)?;
        for (f, c) in fine.iter_mut().zip(&coarse) {
            replace_implausible_texels(f, c);
        }
        let avatar = Avatar {
            fine,
            coarse,
            albedo_uv: pair(&o.unwrapped)?,
            visible: pair(&trainer.view.visible)?,
            light,
            camera: trainer.view.geometry.scene_camera,
        };
        avatar.check_finite()?;
        Ok(avatar)
    }

    /// Fails when any value is not finite (nothing non-finite is ever written).
    pub fn check_finite(&self) -> Result<(), EvalError> {
        for (name, v) in [
            ("left fine texture", &self.fine[0]),
            ("right fine texture", &self.fine[1]),
            ("left coarse texture", &self.coarse[0]),
            ("right coarse texture", &self.coarse[1]),
        ] {
            if v.iter().any(|x| !x.is_finite()) {
                return Err(EvalError::NonFinite(name.into()));
            }
        }
        if self.light.to_array().iter().any(|x| !x.is_finite()) {
            return Err(EvalError::NonFinite("estimated light".into()));
        }
        Ok(())
    }

    /// The estimated light moved from the training camera's frame to `camera`'s frame (the
    /// light stays where it is in the world).
    pub fn light_for(&self, camera: &PinholeCamera) -> LightValues {
        move_light(&self.light, &self.camera, camera)
    }
}

/// `light` (in `from`'s camera frame) in `to`'s camera frame: the same place in the world.
pub fn move_light(light: &LightValues, from: &PinholeCamera, to: &PinholeCamera) -> LightValues {
    let l = light.location;
    let p = DVec3::new(f64::from(l[0]), f64::from(l[1]), f64::from(l[2]));
    let q = to.world_to_camera(from.camera_to_world(p));
    LightValues {
        location: [q.x as f32, q.y as f32, q.z as f32],
        ..*light
    }
}

/// Renders compact textures on the hands of `scene` (a view or pose) under `light`:
/// the image `[3, H, W]` on the host.
pub fn render_view(
    trainer: &Trainer,
    scene: &TwoHandScene,
    textures: &[Vec<f32>; 2],
    light: &LightValues,
) -> Result<Vec<f32>, EvalError> {
    let device = trainer.view.image.device().inner();
    let geometry = trainer.view_geometry(scene, &device)?;
    render_geometry(trainer, &geometry, textures, &light.to_light(&device))
}

/// [`render_view`] for prepared geometry and a light on the geometry's device.
pub fn render_geometry(
    trainer: &Trainer,
    geometry: &ViewGeometry,
    textures: &[Vec<f32>; 2],
    light: &PointLight,
) -> Result<Vec<f32>, EvalError> {
    let device = geometry.vertices[0].device();
    let t = trainer.assets.num_texels();
    let tex = |v: &Vec<f32>| Tensor::<2>::from_data(TensorData::new(v.clone(), [3, t]), &device);
    let r = geometry.render(
        &trainer.assets,
        [tex(&textures[0]), tex(&textures[1])],
        light,
        &trainer.settings,
    )?;
    Ok(to_host(r.image)?)
}

/// Which pixels of a render at `geometry` show a texel the training view saw (issue 34's
/// split of a novel pose): `visible` (per hand, per texel) rendered as a texture, 1 where
/// seen and 0 elsewhere, under a white ambient light, read above 0.5. `[S * S]`, row-major;
/// uncovered pixels are not seen. Bilinear sampling blends the border between seen and
/// unseen texels, so the split falls half way.
///
/// # Errors
/// Masks of the wrong length, or a render that fails.
pub fn seen_pixels(
    trainer: &Trainer,
    geometry: &ViewGeometry,
    visible: &[Vec<bool>; 2],
) -> Result<Vec<bool>, EvalError> {
    let t = trainer.assets.num_texels();
    if visible.iter().any(|v| v.len() != t) {
        return Err(EvalError::Invalid(format!(
            "the visible-texel masks have {} and {} texels; the layout has {t}",
            visible[0].len(),
            visible[1].len()
        )));
    }
    let texture = |v: &Vec<bool>| -> Vec<f32> {
        let one: Vec<f32> = v.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
        [one.as_slice(), &one, &one].concat()
    };
    let device = geometry.vertices[0].device();
    let white = LightValues {
        ambient: [1.0; 3],
        diffuse: [0.0; 3],
        specular: [0.0; 3],
        location: [0.0; 3],
    };
    let image = render_geometry(
        trainer,
        geometry,
        &[texture(&visible[0]), texture(&visible[1])],
        &white.to_light(&device),
    )?;
    let hw = image.len() / 3;
    Ok(image[..hw].iter().map(|&v| v > 0.5).collect())
}

/// Means of fine and coarse metrics over several views.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct MeanScore {
    /// BiTT (fine).
    pub fine: ImageMetrics,
    /// Coarse stage.
    pub coarse: ImageMetrics,
    /// Views averaged.
    pub count: usize,
}

pub fn mean_score(scores: &[ViewScore]) -> Option<MeanScore> {
    let fine: Vec<ImageMetrics> = scores.iter().map(|s| s.fine).collect();
    let coarse: Vec<ImageMetrics> = scores.iter().map(|s| s.coarse).collect();
    Some(MeanScore {
        fine: mean_metrics(&fine)?,
        coarse: mean_metrics(&coarse)?,
        count: scores.len(),
    })
}

/// Metrics of the fine and coarse renders of one ground-truth view.
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct ViewScore {
    /// BiTT (fine stage).
    pub fine: ImageMetrics,
    /// Coarse stage only (the HTML baseline).
    pub coarse: ImageMetrics,
}

/// Texture-space errors of the fine (BiTT) and coarse (HTML) textures against the
/// ground-truth textures, per texel class, raw and after one gain per colour channel (see
/// [`TextureErrors`]; the gain-fitted numbers are the headline).
#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
pub struct TextureScore {
    /// The fine textures (BiTT).
    pub fine: TextureErrors,
    /// The coarse textures (the HTML stage).
    pub coarse: TextureErrors,
}

/// Means of several image metrics.
pub fn mean_metrics(all: &[ImageMetrics]) -> Option<ImageMetrics> {
    if all.is_empty() {
        return None;
    }
    let n = all.len() as f64;
    let ms: Vec<f64> = all.iter().filter_map(|m| m.ms_ssim).collect();
    let lp: Vec<f64> = all.iter().filter_map(|m| m.lpips).collect();
    Some(ImageMetrics {
        l1: all.iter().map(|m| m.l1).sum::<f64>() / n,
        psnr: all.iter().map(|m| m.psnr).sum::<f64>() / n,
        ssim: all.iter().map(|m| m.ssim).sum::<f64>() / n,
        ms_ssim: (ms.len() == all.len()).then(|| ms.iter().sum::<f64>() / n),
        lpips: (lp.len() == all.len()).then(|| lp.iter().sum::<f64>() / n),
    })
}

/// Scores a rendered view against its ground truth image times its hand masks.
pub fn score_view(
    trainer: &Trainer,
    avatar: &Avatar,
    scene: &TwoHandScene,
    gt_image: &[f32],
    gt_masks: &[Vec<f32>; 2],
) -> Result<(ViewScore, Vec<f32>, Vec<f32>), EvalError> {
    let device = trainer.view.image.device().inner();
    let geometry = trainer.view_geometry(scene, &device)?;
    let light = avatar.light_for(&scene.camera).to_light(&device);
    let fine = render_geometry(trainer, &geometry, &avatar.fine, &light)?;
    let coarse = render_geometry(trainer, &geometry, &avatar.coarse, &light)?;
    let (h, w) = (scene.camera.height as usize, scene.camera.width as usize);
    let gt = hand_image(gt_image, gt_masks, h * w)?;
    let size = [3, h, w];
    Ok((
        ViewScore {
            fine: image_metrics(&fine, &gt, size),
            coarse: image_metrics(&coarse, &gt, size),
        },
        fine,
        coarse,
    ))
}

/// `image * (mask_l + mask_r)` clamped: the ground-truth hand image.
pub fn hand_image(image: &[f32], masks: &[Vec<f32>; 2], hw: usize) -> Result<Vec<f32>, EvalError> {
    if image.len() != 3 * hw || masks.iter().any(|m| m.len() != hw) {
        return Err(EvalError::Invalid(format!(
            "ground-truth image/masks do not match the camera's {hw} pixels"
        )));
    }
    let mut out = image.to_vec();
    for ch in 0..3 {
        for p in 0..hw {
            let m = (masks[0][p] + masks[1][p]).min(1.0);
            out[ch * hw + p] *= m;
        }
    }
    Ok(out)
}

/// Texture errors of an avatar against ground-truth textures `[3, T]` (left, right).
pub fn score_textures(avatar: &Avatar, gt: &[Vec<f32>; 2]) -> TextureScore {
    let visible = avatar
        .visible
        .clone()
        .map(|v| v.iter().map(|&x| x > 0.5).collect::<Vec<bool>>());
    TextureScore {
        fine: texture_errors(&avatar.fine, gt, &visible),
        coarse: texture_errors(&avatar.coarse, gt, &visible),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::glam::DMat3;

    /// A texture darkened where the occlusion is low reads below 1, by the darkening; one
    /// colour reads 1; hidden texels do not count, and too few texels in a class give none.
    #[test]
    fn albedo_in_shade_reads_the_darkening_of_shaded_texels() {
        let t = 100;
        let ao: Vec<f32> = (0..t).map(|i| if i < 40 { 0.3 } else { 0.95 }).collect();
        let texture = |shade: f32| -> Vec<f32> {
            (0..3 * t)
                .map(|k| if k % t < 40 { 0.6 * shade } else { 0.6 })
                .collect()
        };
        let visible = [vec![true; t], vec![false; t]];
        let ao = [ao.clone(), ao];
        let flat = [texture(1.0), texture(0.1)];
        let r = albedo_in_shade(&flat, &visible, &ao).unwrap();
        assert!(
            (r - 1.0).abs() < 1e-6,
            "{r}: the hidden right hand must not count"
        );
        let baked = [texture(0.5), texture(0.5)];
        let r = albedo_in_shade(&baked, &visible, &ao).unwrap();
        assert!((r - 0.5).abs() < 1e-6, "{r}");
        let few = [(0..t).map(|i| i < 10).collect(), vec![false; t]];
        assert_eq!(albedo_in_shade(&baked, &few, &ao), None);
    }

    /// A texture that only shifts the prior's colour invents nothing; streaks painted on
    /// unseen texels read as invented detail; texels either hand shows, or outside the region,
    /// do not count.
    #[test]
    fn unseen_detail_reads_what_the_texture_adds_to_the_prior() {
        let (w, h) = (16usize, 16usize);
        let texels: Vec<(u32, u32)> = (0..h as u32)
            .flat_map(|r| (0..w as u32).map(move |c| (r, c)))
            .filter(|&(r, c)| (r + c) % 7 != 0)
            .collect();
        let layout = bitt_texture::TextureLayout::from_texels(w, h, texels, None).unwrap();
        let t = layout.num_texels();
        // A prior with detail (a checker), and a texture 0.1 brighter everywhere.
        let prior: Vec<f32> = (0..3 * t)
            .map(|k| {
                let (r, c) = layout.texels[k % t];
                if (r + c) % 2 == 0 { 0.5 } else { 0.4 }
            })
            .collect();
        let shifted: Vec<f32> = prior.iter().map(|v| v + 0.1).collect();
        let visible = [vec![false; t], vec![false; t]];
        let everywhere = [vec![true; t], vec![true; t]];
        let prior2 = [prior.clone(), prior.clone()];
        let d = unseen_detail(
            &[shifted.clone(), shifted.clone()],
            &prior2,
            &visible,
            &everywhere,
            &layout,
        )
        .unwrap();
        assert_eq!(d.texels, 2 * t);
        assert!(d.invented < 1e-6, "{d:?}");
        assert!((d.shift - 0.1).abs() < 1e-6, "{d:?}");
        assert!(
            d.prior > 0.03,
            "the checker is the prior's own detail: {d:?}"
        );
        // Streaks: every fourth column 0.3 darker.
        let streaked: Vec<f32> = shifted
            .iter()
            .enumerate()
            .map(|(k, v)| {
                if layout.texels[k % t].1.is_multiple_of(4) {
                    v - 0.3
                } else {
                    *v
                }
            })
            .collect();
        let s = unseen_detail(
            &[streaked.clone(), streaked.clone()],
            &prior2,
            &visible,
            &everywhere,
            &layout,
        )
        .unwrap();
        assert!(s.invented > 0.1, "{s:?}");
        // Seen texels (by either hand) and texels outside the region do not count.
        let seen_right: Vec<bool> = (0..t)
            .map(|i| layout.texels[i].1.is_multiple_of(4))
            .collect();
        let v = unseen_detail(
            &[streaked.clone(), streaked.clone()],
            &prior2,
            &[vec![false; t], seen_right.clone()],
            &everywhere,
            &layout,
        )
        .unwrap();
        assert_eq!(
            v.texels,
            2 * (t - seen_right.iter().filter(|&&s| s).count())
        );
        assert!(v.invented < s.invented, "{v:?} vs {s:?}");
        let none = [vec![false; t], vec![false; t]];
        assert_eq!(
            unseen_detail(
                &[streaked.clone(), streaked],
                &prior2,
                &visible,
                &none,
                &layout
            ),
            None
        );
        assert_eq!(
            unseen_detail(
                &[vec![0.0; 3], vec![0.0; 3]],
                &prior2,
                &visible,
                &everywhere,
                &layout
            ),
            None
        );
    }

    /// Texel classes: visible, invisible, of which usable by symmetry or hidden on both.
    #[test]
    fn texture_scores_split_invisible_texels_by_the_other_hand() {
        // 3 texels per hand; left sees texel 0, right sees texels 0 and 1.
        let texture = |v: [f32; 3]| [v, v, v].concat();
        let avatar = Avatar {
            fine: [texture([0.1, 0.2, 0.3]), texture([0.0, 0.0, 0.5])],
            coarse: [texture([0.0; 3]), texture([0.0; 3])],
            albedo_uv: [texture([0.0; 3]), texture([0.0; 3])],
            visible: [vec![1.0, 0.0, 0.0], vec![1.0, 1.0, 0.0]],
            light: LightValues::default(),
            camera: PinholeCamera::new(DMat3::IDENTITY, DMat3::IDENTITY, DVec3::Z, 4, 4)
                .expect("camera"),
        };
        let gt = [texture([0.0; 3]), texture([0.0; 3])];
        let s = score_textures(&avatar, &gt);
        let near = |a: Option<f64>, b: f64| assert!((a.expect("value") - b).abs() < 1e-6);
        let (fine, coarse) = (s.fine.raw, s.coarse.raw);
        // Visible: left 0 (0.1), right 0 and 1 (0.0, 0.0).
        near(fine.visible, 0.1 / 3.0);
        // Invisible: left 1, 2 (0.2, 0.3), right 2 (0.5).
        near(fine.not_visible, 1.0 / 3.0);
        // Symmetric: left 1 (right sees it).
        near(fine.symmetric, 0.2);
        // Hidden on both: left 2 and right 2.
        near(fine.invisible, 0.4);
        near(coarse.invisible, 0.0);
    }

    #[test]
    fn implausible_texels_take_the_prior() {
        // Three texels: skin, saturated green (BTR's outlier), black.
        let mut fine = vec![0.6, 0.1, 0.0, 0.4, 1.0, 0.0, 0.3, 0.02, 0.0];
        let coarse = vec![0.5, 0.3, 0.1, 0.3, 0.16, 0.05, 0.2, 0.09, 0.02];
        assert!((hsv_saturation([0.1, 1.0, 0.02]) - 0.98).abs() < 1e-6);
        assert_eq!(hsv_saturation([0.0; 3]), 0.0);
        assert_eq!(replace_implausible_texels(&mut fine, &coarse), 1);
        assert_eq!(fine, vec![0.6, 0.3, 0.0, 0.4, 0.16, 0.0, 0.3, 0.09, 0.0]);
    }
}
