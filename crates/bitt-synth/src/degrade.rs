//! Mild camera degradation of the training image: lens blur, sensor noise, JPEG.

use bitt_stdx::st;
use bitt_texture::procedural::noise::SplitMix64;
use image::codecs::jpeg::JpegEncoder;
use image::{ImageBuffer, Rgb};

use crate::SynthError;

/// The degradation applied to one image (recorded in `scene.json`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Degradation {
    /// Gaussian blur standard deviation (pixels).
    pub blur_sigma: f64,
    /// Gaussian noise standard deviation (image values in `[0, 1]`).
    pub noise_sigma: f64,
    /// JPEG quality (1-100).
    pub jpeg_quality: u8,
    /// Seed of the noise.
    pub noise_seed: u64,
}

impl Degradation {
    /// Draws a mild degradation: blur 0.3-0.7 px, noise 0.004-0.012, JPEG quality 85-95.
    pub fn sample(rng: &mut SplitMix64) -> Self {
        Degradation {
            blur_sigma: rng.range(0.3, 0.7),
            noise_sigma: rng.range(0.004, 0.012),
            jpeg_quality: rng.range(85.0, 96.0).floor() as u8,
            noise_seed: rng.next_u64(),
        }
    }

    /// Applies it to a `[3, size, size]` image in `[0, 1]`; deterministic.
    ///
    /// # Errors
    /// A wrong image length, or a JPEG round trip that fails.
    pub fn apply(&self, image: &[f32], size: usize) -> Result<Vec<f32>, SynthError> {
        let hw = size * size;
        if image.len() != 3 * hw || size == 0 {
            return Err(SynthError::Generate(format!(
                "cannot degrade an image of {} values as 3 x {size} x {size}",
                image.len()
            )));
        }
        let mut out = blur(image, size, self.blur_sigma);
        let mut rng = SplitMix64::new(self.noise_seed);
        for x in &mut out {
            *x = (*x + (self.noise_sigma * rng.normal()) as f32).clamp(0.0, 1.0);
        }
        jpeg(&out, size, self.jpeg_quality)
    }
}

/// Separable Gaussian blur of each channel, clamped borders.
fn blur(image: &[f32], size: usize, sigma: f64) -> Vec<f32> {
    if sigma <= 0.0 {
        return image.to_vec();
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let weights: Vec<f32> = (-radius..=radius)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32)
        .collect();
    let total: f32 = weights.iter().sum();
    let weights: Vec<f32> = weights.iter().map(|w| w / total).collect();
    let n = size as isize;
    let mut tmp = vec![0.0f32; image.len()];
    let mut out = vec![0.0f32; image.len()];
    for c in 0..3 {
        let plane = c * size * size;
        for y in 0..n {
            for x in 0..n {
                let mut s = 0.0;
                for (k, w) in weights.iter().enumerate() {
                    let xx = (x + k as isize - radius).clamp(0, n - 1);
                    s += w * image[plane + (y * n + xx) as usize];
                }
                tmp[plane + (y * n + x) as usize] = s;
            }
        }
        for y in 0..n {
            for x in 0..n {
                let mut s = 0.0;
                for (k, w) in weights.iter().enumerate() {
                    let yy = (y + k as isize - radius).clamp(0, n - 1);
                    s += w * tmp[plane + (yy * n + x) as usize];
                }
                out[plane + (y * n + x) as usize] = s;
            }
        }
    }
    out
}

/// The image as an 8-bit file holds it: every value clamped to [0, 1] and rounded to the
/// nearest `k / 255`. The generator's ground-truth images are 8-bit, as the rendered
/// datasets of the paper (saved as PNG) and every photograph are; that also lets a run keep
/// them as bytes (`bitt_stdx::st::unit_entry`).
pub(crate) fn to_8bit(image: &[f32]) -> Vec<f32> {
    image
        .iter()
        .map(|&v| st::from_unit_byte(st::unit_byte(v)))
        .collect()
}

/// Encodes as 8-bit JPEG at `quality` and decodes again.
fn jpeg(image: &[f32], size: usize, quality: u8) -> Result<Vec<f32>, SynthError> {
    let hw = size * size;
    let mut px = Vec::with_capacity(3 * hw);
    for p in 0..hw {
        for c in 0..3 {
            px.push(st::unit_byte(image[c * hw + p]));
        }
    }
    let side = u32::try_from(size).map_err(|_| SynthError::Generate("image too large".into()))?;
    let buf = ImageBuffer::<Rgb<u8>, Vec<u8>>::from_raw(side, side, px)
        .ok_or_else(|| SynthError::Generate("bad image buffer".into()))?;
    let mut bytes = Vec::new();
    JpegEncoder::new_with_quality(&mut bytes, quality.clamp(1, 100))
        .encode_image(&buf)
        .map_err(|e| SynthError::Generate(format!("JPEG encoding failed: {e}")))?;
    let decoded = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)
        .map_err(|e| SynthError::Generate(format!("JPEG decoding failed: {e}")))?
        .to_rgb8();
    let raw = decoded.into_raw();
    let mut out = vec![0.0f32; 3 * hw];
    for (p, rgb) in raw.chunks_exact(3).enumerate().take(hw) {
        for c in 0..3 {
            out[c * hw + p] = st::from_unit_byte(rgb[c]);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degradation_is_mild_and_deterministic() {
        let size = 32;
        let image: Vec<f32> = (0..3 * size * size)
            .map(|i| ((i % 97) as f32 / 97.0) * 0.5 + 0.25)
            .collect();
        let d = Degradation::sample(&mut SplitMix64::new(3));
        let a = d.apply(&image, size).unwrap();
        let b = d.apply(&image, size).unwrap();
        assert_eq!(a, b);
        let mean_diff: f32 = a
            .iter()
            .zip(&image)
            .map(|(x, y)| (x - y).abs())
            .sum::<f32>()
            / image.len() as f32;
        assert!(mean_diff < 0.2, "{mean_diff}");
        assert!(a.iter().all(|x| (0.0..=1.0).contains(x)));
        assert!(d.apply(&image[1..], size).is_err());
    }
}
