//! Real photos: the point light's location decided by the photo's shading before training
//! (`loss.photo_light_search`; not from the paper, issue 34).
//!
//! The light network places its point light anywhere in the box its two `tanh` allow
//! (±[`REACH`] m around the camera). On the demo photos, lit from every side by the capture
//! rig, training always pushed the location into a corner of that box, and which corner
//! depended on small changes of the meshes: one corner scored 2.5 dB worse at the other
//! photo's pose and 1.4 dB worse at the input view (docs/results/photos.md, "The light's
//! location"). The trainer found a worse local minimum, not an equally good one.
//!
//! Here the location is chosen once, by how well each place on a grid of the reachable box
//! explains the photo's shading of the prior's mean texture: for every candidate the photo's
//! trusted hand pixels are fitted (least squares, per channel, both factors non-negative) as
//! `a · T + b · T max(0, n·l)`, the ambient and diffuse renders of the mean texture `T`, and
//! the candidate with the smallest residual wins. The forward pass then holds the light there
//! ([`TrainingView::light_location`]); the light network still estimates the colours.

use bitt_mesh::light::LightValues;
use bitt_render::scene::LightValuesExt;
use bitt_stdx::to_host;
use burn::tensor::Tensor;

use crate::TrainError;
use crate::pipeline::TrainingView;
use crate::trainer::Trainer;

/// How far the light network's location reaches along each axis: `tanh(tanh(x))` for
/// `x` in `(-1, 1)`, i.e. `tanh(1)` (the reference's two `tanh` in a row).
pub const REACH: f32 = 0.761_594_2;

/// The search's result.
#[derive(Debug, Clone, PartialEq)]
pub struct LightSearch {
    /// The chosen location (camera frame, metres).
    pub location: [f32; 3],
    /// Every candidate with its relative residual (residual sum of squares over the sum of
    /// squares of the photo's pixels), in grid order.
    pub candidates: Vec<([f32; 3], f64)>,
    /// Pixels the fit used.
    pub pixels: usize,
}

/// The candidate locations: the grid `{-REACH, 0, REACH}^3` without the camera's own
/// position.
pub fn candidates() -> Vec<[f32; 3]> {
    let steps = [-REACH, 0.0, REACH];
    let mut out = Vec::with_capacity(26);
    for x in steps {
        for y in steps {
            for z in steps {
                if [x, y, z] != [0.0; 3] {
                    out.push([x, y, z]);
                }
            }
        }
    }
    out
}

impl Trainer {
    /// Chooses the light's location from the view's photo (module docs).
    ///
    /// # Errors
    /// A render that fails, or a view whose meshes cover no trusted pixel.
    pub fn search_light_location(&self) -> Result<LightSearch, TrainError> {
        let view = &self.view;
        let k = self.pca.basis.dims()[1];
        let device = self.pca.mean.device();
        let mean = self
            .pca
            .textures(Tensor::zeros([1, k], &device))
            .reshape([3, self.assets.num_texels()]);
        let render = |light: LightValues| -> Result<Vec<f32>, TrainError> {
            let image = view.geometry.render_image(
                &self.assets,
                [mean.clone(), mean.clone()],
                &light.to_light(&device),
                &self.settings,
            )?;
            Ok(to_host(image)?)
        };
        let light = |ambient: f32, diffuse: f32, location: [f32; 3]| LightValues {
            ambient: [ambient; 3],
            diffuse: [diffuse; 3],
            specular: [0.0; 3],
            location,
        };
        let pixels = fitted_pixels(view)?;
        let photo = to_host(view.image.clone())?;
        let ambient = render(light(1.0, 0.0, [0.0; 3]))?;
        let mut scored = Vec::new();
        for c in candidates() {
            let diffuse = render(light(0.0, 1.0, c))?;
            scored.push((c, relative_residual(&photo, &ambient, &diffuse, &pixels)));
        }
        let best = scored
            .iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|c| c.0)
            .ok_or_else(|| TrainError::Invalid("no light candidate".into()))?;
        Ok(LightSearch {
            location: best,
            candidates: scored,
            pixels: pixels.len(),
        })
    }
}

/// The pixels the fit uses: covered by the meshes and trusted.
fn fitted_pixels(view: &TrainingView) -> Result<Vec<usize>, TrainError> {
    let mask = to_host(view.mask.clone())?;
    let weight = match &view.weight {
        Some(w) => to_host(w.clone())?,
        None => vec![1.0; mask.len()],
    };
    let pixels: Vec<usize> = (0..mask.len())
        .filter(|&i| mask[i] > 0.5 && weight[i] > 0.5)
        .collect();
    if pixels.is_empty() {
        return Err(TrainError::Invalid(
            "the light search has no pixel: the meshes cover no trusted pixel of the photo".into(),
        ));
    }
    Ok(pixels)
}

/// The residual of the best non-negative fit `photo ≈ a · ambient + b · diffuse` per
/// channel (images `[3, S, S]` channel-major, `pixels` indices into one channel), over the
/// photo's sum of squares.
pub fn relative_residual(photo: &[f32], ambient: &[f32], diffuse: &[f32], pixels: &[usize]) -> f64 {
    let n = photo.len() / 3;
    let (mut residual, mut total) = (0.0, 0.0);
    for c in 0..3 {
        let at = |v: &[f32], i: usize| f64::from(v[c * n + i]);
        let (mut aa, mut ab, mut bb, mut ap, mut bp, mut pp) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for &i in pixels {
            let (a, b, p) = (at(ambient, i), at(diffuse, i), at(photo, i));
            aa += a * a;
            ab += a * b;
            bb += b * b;
            ap += a * p;
            bp += b * p;
            pp += p * p;
        }
        // Sum of squares of p - x a - y b, from the moments.
        let rss = |x: f64, y: f64| {
            pp - 2.0 * (x * ap + y * bp) + x * x * aa + 2.0 * x * y * ab + y * y * bb
        };
        let mut best = pp;
        let det = aa * bb - ab * ab;
        if det > 1e-12 * aa * bb {
            let x = (bb * ap - ab * bp) / det;
            let y = (aa * bp - ab * ap) / det;
            if x >= 0.0 && y >= 0.0 {
                best = best.min(rss(x, y));
            }
        }
        if aa > 0.0 {
            best = best.min(rss((ap / aa).max(0.0), 0.0));
        }
        if bb > 0.0 {
            best = best.min(rss(0.0, (bp / bb).max(0.0)));
        }
        residual += best.max(0.0);
        total += pp;
    }
    if total > 0.0 { residual / total } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_is_the_reachable_box_without_the_camera() {
        let c = candidates();
        assert_eq!(c.len(), 26);
        assert!(c.iter().all(|p| p.iter().all(|v| v.abs() <= REACH)));
        assert!(!c.contains(&[0.0; 3]));
        assert!((REACH - 1f32.tanh()).abs() < 1e-6);
    }

    #[test]
    fn the_residual_is_zero_for_a_photo_the_model_explains() {
        // 4 pixels per channel; the photo is 0.3 ambient + 0.5 diffuse exactly.
        let ambient = [0.5, 0.6, 0.7, 0.8].repeat(3);
        let diffuse = [0.1, 0.0, 0.4, 0.2].repeat(3);
        let photo: Vec<f32> = ambient
            .iter()
            .zip(&diffuse)
            .map(|(a, d)| 0.3 * a + 0.5 * d)
            .collect();
        let all = [0, 1, 2, 3];
        assert!(relative_residual(&photo, &ambient, &diffuse, &all) < 1e-9);
        // Another candidate's diffuse image explains it worse.
        let other = [0.4, 0.2, 0.0, 0.1].repeat(3);
        assert!(relative_residual(&photo, &ambient, &other, &all) > 1e-3);
    }

    #[test]
    fn negative_factors_are_not_allowed() {
        // The photo is brighter where the diffuse image is darker: the unconstrained fit
        // would take b < 0; the non-negative fit keeps the ambient term alone.
        let ambient = [1.0f32; 4].repeat(3);
        let diffuse = [0.0, 0.2, 0.4, 0.6].repeat(3);
        let photo = [0.6, 0.5, 0.4, 0.3].repeat(3);
        let r = relative_residual(&photo, &ambient, &diffuse, &[0, 1, 2, 3]);
        let mean = 0.45f64;
        let rss: f64 = [0.6f64, 0.5, 0.4, 0.3]
            .iter()
            .map(|p| (p - mean).powi(2))
            .sum();
        let pp: f64 = [0.6f64, 0.5, 0.4, 0.3].iter().map(|p| p * p).sum();
        assert!((r - rss / pp).abs() < 1e-6, "{r} vs {}", rss / pp);
    }
}
