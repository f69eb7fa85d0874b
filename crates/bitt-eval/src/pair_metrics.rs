//! `bitt metrics`' comparison of two image files (optionally under a mask): the image
//! metrics, the images LPIPS compares, and the JSON report; `bitt image-diff`'s mean and
//! largest absolute difference of two images.

use std::path::{Path, PathBuf};

use bitt_texture::{ImageDifference, PlanarImage, load_image};
use burn::tensor::Device;
use serde_json::json;

use crate::EvalError;
use crate::lpips::LpipsVgg;
use crate::metrics::{
    ImageMetrics, MS_SSIM_MIN_SIDE, SsimWindow, apply_mask, image_metrics_with,
    masked_image_metrics,
};
use bitt_stdx::WithContext;

/// Two images compared: their size, metrics, the mask's pixel count, and the images LPIPS
/// compares (masked when there is a mask).
#[derive(Debug, Clone)]
pub struct ImagePair {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The metrics.
    pub metrics: ImageMetrics,
    /// With a mask: how many pixels it selects.
    pub mask_pixels: Option<usize>,
    /// The two images as LPIPS gets them, planar `[3, H, W]`.
    pub lpips_inputs: (Vec<f32>, Vec<f32>),
}

impl ImagePair {
    /// `[3, H, W]`.
    pub fn dims(&self) -> [usize; 3] {
        [3, self.height, self.width]
    }
}

fn load_planar(path: &Path, what: &str) -> Result<PlanarImage, EvalError> {
    Ok(load_image(path).context_with(|| format!("cannot read {what} {}", path.display()))?)
}

/// The mean and largest absolute difference of images `a` and `b` of equal size (values in
/// `[0, 1]`) and their means, as JSON (`bitt image-diff`; `cargo xtask e2e` compares backends
/// with it).
///
/// # Errors
/// An unreadable image, or images of different sizes.
pub fn image_diff(a: &Path, b: &Path) -> Result<serde_json::Value, EvalError> {
    let ia = load_image(a).context_with(|| format!("cannot load {}", a.display()))?;
    let ib = load_image(b).context_with(|| format!("cannot load {}", b.display()))?;
    let Some(d) = ImageDifference::between(&ia, &ib) else {
        return Err(EvalError::Invalid(format!(
            "{} is {}x{} but {} is {}x{}",
            a.display(),
            ia.width,
            ia.height,
            b.display(),
            ib.width,
            ib.height
        )));
    };
    Ok(json!({
        "mean_abs_diff": d.mean_abs_diff,
        "max_abs_diff": d.max_abs_diff,
        "mean_a": d.mean_a,
        "mean_b": d.mean_b,
    }))
}

/// Compares images `a` and `b` (the same size); with `mask` (the same size, pixels whose
/// mean RGB is at least 0.5 count), L1 and PSNR use the masked pixels only and SSIM, MS-SSIM
/// and LPIPS both images times the mask.
///
/// # Errors
/// An unreadable image, images of different sizes, or a mask that selects no pixel.
pub fn compare_images(
    a_path: &Path,
    b_path: &Path,
    mask_path: Option<&Path>,
    window: SsimWindow,
) -> Result<ImagePair, EvalError> {
    let a = load_planar(a_path, "image")?;
    let b = load_planar(b_path, "image")?;
    let same_size = |p: &Path, i: &PlanarImage| -> Result<(), EvalError> {
        if (i.width, i.height) != (a.width, a.height) {
            return Err(EvalError::Invalid(format!(
                "{} is {}x{} but {} is {}x{}; the images must have the same size",
                p.display(),
                i.width,
                i.height,
                a_path.display(),
                a.width,
                a.height
            )));
        }
        Ok(())
    };
    same_size(b_path, &b)?;
    let dims = [3, a.height, a.width];
    let hw = a.width * a.height;
    let (metrics, mask_pixels, lpips_inputs) = match mask_path {
        None => (
            image_metrics_with(&a.data, &b.data, dims, window),
            None,
            (a.data.clone(), b.data.clone()),
        ),
        Some(p) => {
            let mi = load_planar(p, "mask")?;
            same_size(p, &mi)?;
            let mask: Vec<f32> = (0..hw)
                .map(|i| (mi.data[i] + mi.data[hw + i] + mi.data[2 * hw + i]) / 3.0)
                .collect();
            let m =
                masked_image_metrics(&a.data, &b.data, &mask, dims, window).ok_or_else(|| {
                    EvalError::Invalid(format!("mask {} selects no pixel", p.display()))
                })?;
            let count = mask.iter().filter(|&&v| v >= 0.5).count();
            let am = apply_mask(&a.data, &mask, dims);
            let bm = apply_mask(&b.data, &mask, dims);
            (m, Some(count), (am, bm))
        }
    };
    Ok(ImagePair {
        width: a.width,
        height: a.height,
        metrics,
        mask_pixels,
        lpips_inputs,
    })
}

/// The LPIPS weights of a comparison: `given` (`--lpips`), else `default` when that file
/// exists.
pub fn lpips_weights(given: Option<&Path>, default: Option<&Path>) -> Option<PathBuf> {
    match given {
        Some(p) => Some(p.to_path_buf()),
        None => default.filter(|p| p.is_file()).map(Path::to_path_buf),
    }
}

/// The note of a comparison without LPIPS weights (`default`: where they are looked for).
pub fn no_lpips_note(default: Option<&Path>) -> String {
    format!(
        "LPIPS unavailable: no weights (pass --lpips FILE, set BITT_LPIPS_WEIGHTS, or \
         write {} with `bitt convert-lpips`); it is not estimated",
        default.map_or("~/.cache/bitt/lpips_vgg.safetensors".into(), |p| p
            .display()
            .to_string())
    )
}

/// LPIPS-VGG of `pair` with the weights in `weights`, on `device`, and the note saying
/// where they are from.
///
/// # Errors
/// Weights that cannot be read, or a failure computing the distance.
pub fn pair_lpips(
    pair: &ImagePair,
    weights: &Path,
    device: &Device,
) -> Result<(f64, String), EvalError> {
    let net = LpipsVgg::load(weights, device)?;
    let (a, b) = &pair.lpips_inputs;
    let d = net
        .distance(a, b, pair.dims(), device)
        .context_with(|| "computing LPIPS".to_string())?;
    Ok((
        d,
        format!(
            "LPIPS-VGG v0.1 from {}, inputs mapped from [0, 1] to [-1, 1]",
            weights.display()
        ),
    ))
}

/// The JSON report of a comparison: paths, size, metrics (non-finite ones as `null` with a
/// note), LPIPS and its note, the SSIM window, and the mask.
pub fn pair_report(
    a: &Path,
    b: &Path,
    mask: Option<&Path>,
    pair: &ImagePair,
    window: SsimWindow,
    lpips: Option<f64>,
    lpips_note: &str,
) -> serde_json::Value {
    let m = &pair.metrics;
    let finite = |v: f64| v.is_finite().then_some(v);
    let mut out = json!({
        "a": a.display().to_string(),
        "b": b.display().to_string(),
        "width": pair.width,
        "height": pair.height,
        "l1": m.l1,
        "psnr": finite(m.psnr),
        "ssim": finite(m.ssim),
        "ms_ssim": m.ms_ssim,
        "lpips": lpips,
        "lpips_note": lpips_note,
        "ssim_window": window,
    });
    let obj = out.as_object_mut().expect("an object");
    if m.psnr.is_infinite() {
        obj.insert(
            "psnr_note".into(),
            json!("identical images: PSNR is infinite"),
        );
    }
    if m.ms_ssim.is_none() {
        obj.insert(
            "ms_ssim_note".into(),
            json!(format!(
                "MS-SSIM needs both sides of at least {MS_SSIM_MIN_SIDE} pixels"
            )),
        );
    }
    if m.ssim.is_nan() {
        obj.insert(
            "ssim_note".into(),
            json!("SSIM needs both sides of at least 11 pixels"),
        );
    }
    if let (Some(p), Some(count)) = (mask, pair.mask_pixels) {
        obj.insert("mask".into(), json!(p.display().to_string()));
        obj.insert("mask_pixels".into(), json!(count));
    }
    out
}
