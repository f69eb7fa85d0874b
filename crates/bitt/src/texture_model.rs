//! The procedural texture prior of a run (fitted once per configuration, then cached), and
//! `bitt texture`'s job: a texture PCA model, its parameters and the UV texture PNG they make.
//!
//! The model is HTML's `model.pkl`, a safetensors file, or the project's procedural skin model
//! fitted on the fly; the parameter vector a JSON file or seeded normal draws.

use bitt_stdx::FileErrorExt;
use std::path::Path;
use std::time::Instant;

use bitt_texture::procedural::noise::SplitMix64;
use bitt_texture::procedural::{ProceduralTextureConfig, procedural_texture_pca};
use bitt_texture::{
    FitProgress, NoProgress, TexturePca, load_html_model, procedural_texture_model, save_png8,
    save_png16,
};
use burn::tensor::Device;

use crate::BittError;
use crate::config::TrainConfig;
use bitt_stdx::WithContext;

/// The texture PCA of `config.texture`, read from `cache_dir` when fitted before, else fitted
/// (seconds at `quick`, minutes at `paper`) and cached there.
pub fn texture_prior(
    config: &TrainConfig,
    cache_dir: Option<&Path>,
    device: &Device,
) -> Result<TexturePca, BittError> {
    texture_prior_with_progress(config, cache_dir, device, &NoProgress)
}

/// [`texture_prior`], reporting the fit's stages to `progress` (nothing is reported when the
/// cache has the model).
pub fn texture_prior_with_progress(
    config: &TrainConfig,
    cache_dir: Option<&Path>,
    device: &Device,
    progress: &dyn FitProgress,
) -> Result<TexturePca, BittError> {
    let key = {
        // The PCA is fitted on skins generated over the procedural hand's surface: a change
        // of that surface (the synthetic generator's version) changes the fit.
        let text = format!(
            "{}|{}",
            serde_json::to_string(&config.texture).unwrap_or_default(),
            bitt_synth::GENERATOR_VERSION
        );
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in text.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
        format!("procedural-pca-{h:016x}.safetensors")
    };
    if let Some(dir) = cache_dir {
        let path = dir.join(&key);
        if path.is_file() {
            // A corrupt entry, or one fitted on another layout of the procedural hands (a
            // cache from before a change of their surface), is refitted and overwritten below.
            if let Ok(p) = TexturePca::load_safetensors(&path) {
                let assets = crate::assets::HandAssets::new(
                    bitt_mesh::procedural_pair(),
                    config.texture.resolution,
                )?;
                if assets.check_prior(&p).is_ok() {
                    return Ok(p);
                }
            }
        }
    }
    // The model alone: the held-out identities only serve `bitt texture`'s evaluation.
    let (pca, _) = procedural_texture_model(&config.texture, device, progress)?;
    if let Some(dir) = cache_dir {
        std::fs::create_dir_all(dir).map_err(|e| BittError::io(dir, e))?;
        pca.save_safetensors(&dir.join(key))?;
    }
    Ok(pca)
}

/// Standard normal numbers from a seed (SplitMix64 + Box-Muller), reproducible everywhere.
pub fn normal_params(seed: u64, n: usize) -> Vec<f32> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let (u1, u2) = (rng.next_f64().max(1e-300), rng.next_f64());
            ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
        })
        .collect()
}

/// The parameter vector in the JSON file `path` (an array of numbers).
///
/// # Errors
/// An unreadable file, or one that does not hold an array of numbers.
pub fn read_params(path: &Path) -> Result<Vec<f32>, BittError> {
    let text =
        std::fs::read_to_string(path).context_with(|| format!("reading {}", path.display()))?;
    let values: Vec<f64> = serde_json::from_str(&text)
        .context_with(|| format!("{} must hold a JSON array of numbers", path.display()))?;
    Ok(values.into_iter().map(|v| v as f32).collect())
}

/// The configuration of the project's procedural skin model at `resolution` (128 to 1024,
/// `--resolution`).
///
/// # Errors
/// A resolution out of range.
pub fn procedural_config(resolution: usize) -> Result<ProceduralTextureConfig, BittError> {
    if !(128..=1024).contains(&resolution) {
        return Err(BittError::Invalid(format!(
            "--resolution must be between 128 and 1024 (got {resolution})"
        )));
    }
    Ok(ProceduralTextureConfig {
        resolution,
        ..Default::default()
    })
}

/// The project's procedural skin model of `config`, fitted on `device`; `say` is told how
/// well it fits.
///
/// # Errors
/// A failed fit.
pub fn procedural_model(
    config: &ProceduralTextureConfig,
    device: &Device,
    say: impl FnOnce(&str),
) -> Result<TexturePca, BittError> {
    let start = Instant::now();
    let (pca, fit, eval) = procedural_texture_pca(config, device)?;
    let explained: f32 = fit.explained_variance_ratio.iter().sum();
    say(&format!(
        "procedural texture model: {} identities, {} components ({:.1}% of variance), \
         held-out RMSE {:.4} vs train {:.4}, fitted in {:.1} s",
        config.identities,
        pca.num_components,
        100.0 * explained,
        eval.held_out_rmse,
        eval.train_rmse,
        start.elapsed().as_secs_f64()
    ));
    Ok(pca)
}

/// The texture model in `path`: a `.safetensors` (`bitt convert-html`, `--save-model`), else
/// HTML's `model.pkl`.
///
/// # Errors
/// A file that cannot be read or is not a texture model.
pub fn model_file(path: &Path) -> Result<TexturePca, BittError> {
    Ok(match path.extension().and_then(|e| e.to_str()) {
        Some("safetensors") => TexturePca::load_safetensors(path)?,
        _ => load_html_model(path)?,
    })
}

/// Writes the whole UV texture of `pca` for `params` (unused texels black) at `out`, 16-bit
/// with `png16`; `source` names the parameters in errors. Returns its width and height.
///
/// # Errors
/// A parameter count that is not the model's, or a file that cannot be written.
pub fn write_texture(
    pca: &TexturePca,
    params: &[f32],
    source: &str,
    out: &Path,
    png16: bool,
) -> Result<(usize, usize), BittError> {
    if params.len() != pca.num_components {
        return Err(BittError::Invalid(format!(
            "{source}: holds {} parameters, but the model has {} components",
            params.len(),
            pca.num_components
        )));
    }
    let compact = pca.texture(params)?;
    let image = pca.layout.compact_to_image(&compact, [0.0; 3])?;
    let (w, h) = (pca.layout.width, pca.layout.height);
    if png16 {
        save_png16(out, &image, w, h)?;
    } else {
        save_png8(out, &image, w, h)?;
    }
    Ok((w, h))
}
