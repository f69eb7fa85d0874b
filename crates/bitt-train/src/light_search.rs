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
//! ([`TrainingView::light_location`]).
//!
//! The same fit gives the light's ambient and diffuse colours at that place (`a` and `b` per
//! channel, made one colour when the view's light has one, [`one_colour`]). With
//! `loss.photo_light_colours` the forward pass holds them too ([`TrainingView::light_colours`])
//! and the light network is not used. The network's twelve outputs end in two `tanh` in a
//! row; on the demo photos training pushed most of them to an end of their range, where they
//! have no gradient left, and which end each reached depended on the seed: the light came out
//! different in every run, and one of two places the run on `01` ends in scored 1.3 dB worse
//! at the other photo's pose (docs/results/photos.md, The light's colours).

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
    /// The fitted ambient colour at the chosen location (`a` per channel; one colour when the
    /// view's light has one).
    pub ambient: [f32; 3],
    /// The fitted diffuse colour at the chosen location (`b` per channel, likewise).
    pub diffuse: [f32; 3],
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
        let mut fits = Vec::new();
        for c in candidates() {
            let diffuse = render(light(0.0, 1.0, c))?;
            fits.push((c, fit_shading(&photo, &ambient, &diffuse, &pixels)));
        }
        let (location, fit) = fits
            .iter()
            .min_by(|a, b| a.1.residual.total_cmp(&b.1.residual))
            .copied()
            .ok_or_else(|| TrainError::Invalid("no light candidate".into()))?;
        let [ambient, diffuse] = if view.one_colour_light {
            one_colour(fit.ambient, fit.diffuse)
        } else {
            [fit.ambient, fit.diffuse]
        };
        Ok(LightSearch {
            location,
            candidates: fits.iter().map(|(c, f)| (*c, f.residual)).collect(),
            pixels: pixels.len(),
            ambient,
            diffuse,
        })
    }
}

/// The ambient and diffuse colours as one colour, as [`bitt_nets::LightParams::one_colour`]
/// makes the network's: the colour of both together, `c = (a + b) / mean(a + b)`, and each
/// part its mean as an intensity of it (`a' = c mean(a)`, `b' = c mean(b)`). A light with
/// nothing in it stays dark.
pub fn one_colour(ambient: [f32; 3], diffuse: [f32; 3]) -> [[f32; 3]; 2] {
    let mean = |v: [f32; 3]| v.iter().sum::<f32>() / 3.0;
    let sum = [0, 1, 2].map(|c| ambient[c] + diffuse[c]);
    let total = mean(sum);
    if total <= 0.0 {
        return [[0.0; 3]; 2];
    }
    let colour = sum.map(|v| v / total);
    [
        colour.map(|c| c * mean(ambient)),
        colour.map(|c| c * mean(diffuse)),
    ]
}

/// The best non-negative fit `photo ≈ a · ambient + b · diffuse` per channel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingFit {
    /// `a` per channel.
    pub ambient: [f32; 3],
    /// `b` per channel.
    pub diffuse: [f32; 3],
    /// The residual sum of squares over the photo's sum of squares.
    pub residual: f64,
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

/// The best non-negative fit `photo ≈ a · ambient + b · diffuse` per channel (images
/// `[3, S, S]` channel-major, `pixels` indices into one channel).
pub fn fit_shading(
    photo: &[f32],
    ambient: &[f32],
    diffuse: &[f32],
    pixels: &[usize],
) -> ShadingFit {
    let n = photo.len() / 3;
    let (mut residual, mut total) = (0.0, 0.0);
    let (mut fit_a, mut fit_b) = ([0.0f32; 3], [0.0f32; 3]);
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
        // The candidates: both factors free, then each alone (the non-negative optimum is
        // one of them, or nothing at all).
        let mut options = vec![(0.0, 0.0)];
        let det = aa * bb - ab * ab;
        if det > 1e-12 * aa * bb {
            let x = (bb * ap - ab * bp) / det;
            let y = (aa * bp - ab * ap) / det;
            if x >= 0.0 && y >= 0.0 {
                options.push((x, y));
            }
        }
        if aa > 0.0 {
            options.push(((ap / aa).max(0.0), 0.0));
        }
        if bb > 0.0 {
            options.push((0.0, (bp / bb).max(0.0)));
        }
        let (x, y, best) = options
            .into_iter()
            .map(|(x, y)| (x, y, rss(x, y)))
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .expect("nothing is always an option");
        fit_a[c] = x as f32;
        fit_b[c] = y as f32;
        residual += best.max(0.0);
        total += pp;
    }
    ShadingFit {
        ambient: fit_a,
        diffuse: fit_b,
        residual: if total > 0.0 { residual / total } else { 0.0 },
    }
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
        let fit = fit_shading(&photo, &ambient, &diffuse, &all);
        assert!(fit.residual < 1e-9);
        for c in 0..3 {
            assert!((fit.ambient[c] - 0.3).abs() < 1e-5, "{fit:?}");
            assert!((fit.diffuse[c] - 0.5).abs() < 1e-5, "{fit:?}");
        }
        // Another candidate's diffuse image explains it worse.
        let other = [0.4, 0.2, 0.0, 0.1].repeat(3);
        assert!(fit_shading(&photo, &ambient, &other, &all).residual > 1e-3);
    }

    #[test]
    fn negative_factors_are_not_allowed() {
        // The photo is brighter where the diffuse image is darker: the unconstrained fit
        // would take b < 0; the non-negative fit keeps the ambient term alone.
        let ambient = [1.0f32; 4].repeat(3);
        let diffuse = [0.0, 0.2, 0.4, 0.6].repeat(3);
        let photo = [0.6, 0.5, 0.4, 0.3].repeat(3);
        let r = fit_shading(&photo, &ambient, &diffuse, &[0, 1, 2, 3]).residual;
        let mean = 0.45f64;
        let rss: f64 = [0.6f64, 0.5, 0.4, 0.3]
            .iter()
            .map(|p| (p - mean).powi(2))
            .sum();
        let pp: f64 = [0.6f64, 0.5, 0.4, 0.3].iter().map(|p| p * p).sum();
        assert!((r - rss / pp).abs() < 1e-6, "{r} vs {}", rss / pp);
        let fit = fit_shading(&photo, &ambient, &diffuse, &[0, 1, 2, 3]);
        assert_eq!(fit.diffuse, [0.0; 3]);
        assert!(
            fit.ambient.iter().all(|a| (a - 0.45).abs() < 1e-6),
            "{fit:?}"
        );
        // A photo darker than nothing explains is fitted by nothing.
        let dark = [-0.1f32; 4].repeat(3);
        let fit = fit_shading(&dark, &ambient, &diffuse, &[0, 1, 2, 3]);
        assert_eq!((fit.ambient, fit.diffuse), ([0.0; 3], [0.0; 3]));
        assert!((fit.residual - 1.0).abs() < 1e-9);
    }

    #[test]
    fn one_colour_keeps_each_parts_intensity_in_the_colour_of_both() {
        let [a, d] = one_colour([0.2, 0.2, 0.1], [0.6, 0.4, 0.2]);
        // Colour (0.8, 0.6, 0.3) / 0.5666...; intensities 0.1666... and 0.4.
        let colour = [0.8f32, 0.6, 0.3].map(|v| v / (1.7 / 3.0));
        for c in 0..3 {
            assert!((a[c] - colour[c] * 0.5 / 3.0).abs() < 1e-6, "{a:?}");
            assert!((d[c] - colour[c] * 0.4).abs() < 1e-6, "{d:?}");
        }
        // The means are kept, and the two parts have one colour.
        assert!(((a[0] + a[1] + a[2]) / 3.0 - 0.5 / 3.0).abs() < 1e-6);
        assert!((a[0] / a[2] - d[0] / d[2]).abs() < 1e-5);
        assert_eq!(one_colour([0.0; 3], [0.0; 3]), [[0.0; 3]; 2]);
    }
}
