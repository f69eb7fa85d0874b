//! A texture PCA model fitted to procedural skins, and how well it represents unseen people.

use bitt_mesh::{HandModel, Side, default_hand};
use burn::tensor::Device;

use super::generate::generate_texture;
use super::identity::SkinIdentity;
use super::noise::derive;
use crate::TextureError;
use crate::layout::TextureLayout;
use crate::pca::{PcaFitReport, TexturePca};

/// Ridge of the least-squares projections in the evaluation (a colour noise variance; the
/// fitted parameters have unit variance).
const EVAL_RIDGE: f32 = 1e-4;

/// Settings of [`procedural_texture_pca`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ProceduralTextureConfig {
    /// Side length of the square texture, 128 to 1024 texels.
    pub resolution: usize,
    /// Number of training identities (each gives two samples: the left and the right hand).
    pub identities: usize,
    /// Number of held-out identities, drawn from seeds disjoint from the training ones.
    pub held_out: usize,
    /// Number of principal components kept (at most `2 * identities - 1`).
    pub components: usize,
    /// Seed of the whole population.
    pub seed: u64,
    /// Texels of gutter around the UV charts (see [`TextureLayout::from_uv`]).
    pub gutter: usize,
}

impl Default for ProceduralTextureConfig {
    fn default() -> Self {
        ProceduralTextureConfig {
            resolution: 256,
            identities: 40,
            held_out: 8,
            components: 24,
            seed: 0,
            gutter: 2,
        }
    }
}

impl ProceduralTextureConfig {
    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<(), TextureError> {
        let bad = |m: String| Err(TextureError::Invalid(m));
        if !(128..=1024).contains(&self.resolution) {
            return bad(format!(
                "resolution {} is outside 128..=1024",
                self.resolution
            ));
        }
        if self.identities < 2 {
            return bad(format!(
                "need at least 2 training identities, got {}",
                self.identities
            ));
        }
        if self.held_out == 0 {
            return bad("need at least 1 held-out identity".into());
        }
        if self.components == 0 || self.components > 2 * self.identities - 1 {
            return bad(format!(
                "{} components asked; {} training identities support 1 to {}",
                self.components,
                self.identities,
                2 * self.identities - 1
            ));
        }
        Ok(())
    }

    /// The `i`-th training identity.
    pub fn training_identity(&self, i: usize) -> SkinIdentity {
        SkinIdentity::sample(derive(self.seed, i as u64))
    }

    /// The `j`-th held-out identity. Its seed is derived from a label no training identity
    /// uses (and the derivation is a bijection), so held-out people are never training ones.
    pub fn held_out_identity(&self, j: usize) -> SkinIdentity {
        SkinIdentity::sample(derive(self.seed, (self.identities + j) as u64))
    }
}

/// How well a fitted model represents textures, as root-mean-square errors over all colour
/// values (`[0, 1]` scale) of the left and right textures of the identities.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvalReport {
    /// Training identities, reconstructed from their least-squares parameters.
    pub train_rmse: f32,
    /// Held-out identities, reconstructed from their least-squares parameters.
    pub held_out_rmse: f32,
    /// Held-out identities "reconstructed" by the mean texture alone.
    pub held_out_mean_rmse: f32,
    /// Training identities represented by the mean texture alone.
    pub train_mean_rmse: f32,
    /// Fraction of the training variance the kept components explain.
    pub explained_variance_at_k: f32,
}

/// Builds the procedural right hand's layout at `config.resolution`, generates both hands of
/// `config.identities` people, fits a `config.components`-component [`TexturePca`] (the
/// left and right textures of a person are both samples: the hands share their UV layout),
/// and evaluates it on the training people and on `config.held_out` unseen ones.
///
/// # Errors
/// [`TextureError::Invalid`] for a configuration outside its ranges, and any error of
/// [`TextureLayout::from_uv`] or [`TexturePca::fit`].
pub fn procedural_texture_pca(
    config: &ProceduralTextureConfig,
    device: &Device,
) -> Result<(TexturePca, PcaFitReport, EvalReport), TextureError> {
    config.validate()?;
    let right = default_hand(Side::Right);
    let left = default_hand(Side::Left);
    let uv = right
        .uv
        .as_ref()
        .ok_or_else(|| TextureError::Invalid("the procedural hand has no UV layout".into()))?;
    let layout = TextureLayout::from_uv(uv, config.resolution, config.resolution, config.gutter)?;
    let train_ids: Vec<SkinIdentity> = (0..config.identities)
        .map(|i| config.training_identity(i))
        .collect();
    let held_ids: Vec<SkinIdentity> = (0..config.held_out)
        .map(|j| config.held_out_identity(j))
        .collect();
    let train = both_hands(&layout, &left, &right, &train_ids)?;
    let held = both_hands(&layout, &left, &right, &held_ids)?;
    let (pca, report) = TexturePca::fit(layout, &train, config.components, device)?;
    let eval = EvalReport {
        train_rmse: reconstruction_rmse(&pca, &train)?,
        held_out_rmse: reconstruction_rmse(&pca, &held)?,
        held_out_mean_rmse: rmse_against(&pca.mean, &held),
        train_mean_rmse: rmse_against(&pca.mean, &train),
        explained_variance_at_k: report.explained_variance_ratio.iter().sum(),
    };
    Ok((pca, report, eval))
}

/// Left then right texture of every identity, generated on all available cores.
fn both_hands(
    layout: &TextureLayout,
    left: &HandModel,
    right: &HandModel,
    ids: &[SkinIdentity],
) -> Result<Vec<Vec<f32>>, TextureError> {
    let jobs: Vec<(&SkinIdentity, Side)> = ids
        .iter()
        .flat_map(|id| Side::BOTH.map(|s| (id, s)))
        .collect();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(jobs.len())
        .max(1);
    let chunk = jobs.len().div_ceil(threads);
    let results: Vec<Result<Vec<Vec<f32>>, TextureError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = jobs
            .chunks(chunk.max(1))
            .map(|part| {
                scope.spawn(move || {
                    part.iter()
                        .map(|(id, side)| {
                            let hand = if *side == Side::Left { left } else { right };
                            generate_texture(layout, hand, id, *side)
                        })
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    let mut out = Vec::with_capacity(jobs.len());
    for r in results {
        out.extend(r?);
    }
    Ok(out)
}

/// RMSE of the model's least-squares reconstructions of `samples`.
fn reconstruction_rmse(pca: &TexturePca, samples: &[Vec<f32>]) -> Result<f32, TextureError> {
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for s in samples {
        let params = pca.project(s, None, EVAL_RIDGE)?;
        let recon = pca.texture(&params)?;
        sum += squared_error(&recon, s);
        count += s.len();
    }
    Ok((sum / count.max(1) as f64).sqrt() as f32)
}

/// RMSE of one fixed texture against every sample.
fn rmse_against(texture: &[f32], samples: &[Vec<f32>]) -> f32 {
    let sum: f64 = samples.iter().map(|s| squared_error(texture, s)).sum();
    let count: usize = samples.iter().map(Vec::len).sum();
    (sum / count.max(1) as f64).sqrt() as f32
}

fn squared_error(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> ProceduralTextureConfig {
        ProceduralTextureConfig {
            resolution: 128,
            identities: 16,
            held_out: 6,
            components: 12,
            seed: 5,
            gutter: 1,
        }
    }

    #[test]
    fn config_ranges_are_checked() {
        assert!(ProceduralTextureConfig::default().validate().is_ok());
        let bad = [
            ProceduralTextureConfig {
                resolution: 64,
                ..small()
            },
            ProceduralTextureConfig {
                resolution: 2048,
                ..small()
            },
            ProceduralTextureConfig {
                identities: 1,
                ..small()
            },
            ProceduralTextureConfig {
                held_out: 0,
                ..small()
            },
            ProceduralTextureConfig {
                components: 0,
                ..small()
            },
            ProceduralTextureConfig {
                components: 32,
                ..small()
            },
        ];
        for c in bad {
            assert!(c.validate().is_err(), "{c:?}");
            assert!(procedural_texture_pca(&c, &Device::flex()).is_err());
        }
        let json = serde_json::to_string(&small()).unwrap();
        let back: ProceduralTextureConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, small());
        let partial: ProceduralTextureConfig = serde_json::from_str(r#"{"seed": 3}"#).unwrap();
        assert_eq!(
            partial,
            ProceduralTextureConfig {
                seed: 3,
                ..Default::default()
            }
        );
    }

    #[test]
    fn held_out_identities_are_not_training_identities() {
        let c = ProceduralTextureConfig::default();
        let train: Vec<u64> = (0..c.identities)
            .map(|i| c.training_identity(i).seed)
            .collect();
        for j in 0..c.held_out {
            assert!(!train.contains(&c.held_out_identity(j).seed));
        }
    }

    #[test]
    fn pca_generalises_to_held_out_people() {
        let config = small();
        let (pca, report, eval) = procedural_texture_pca(&config, &Device::flex()).unwrap();
        assert_eq!(pca.num_components, config.components);
        assert_eq!(report.explained_variance_ratio.len(), config.components);
        let ratios = &report.explained_variance_ratio;
        assert!(ratios.windows(2).all(|w| w[0] >= w[1] - 1e-6), "{ratios:?}");
        // Skin tone dominates the variation between people.
        assert!(
            ratios[0] > 0.5,
            "first component explains only {}",
            ratios[0]
        );
        assert!(eval.explained_variance_at_k > 0.9, "{eval:?}");
        // Unseen people are represented worse than the training ones, but still far better
        // than by the mean texture.
        assert!(eval.held_out_rmse > 1.2 * eval.train_rmse, "{eval:?}");
        assert!(
            eval.held_out_rmse < 0.5 * eval.held_out_mean_rmse,
            "{eval:?}"
        );
        assert!(eval.train_rmse < eval.train_mean_rmse, "{eval:?}");
        // The model's own textures are valid colours.
        let tex = pca.texture(&vec![1.0; config.components]).unwrap();
        assert!(tex.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    /// Prints the numbers quoted in `docs/procedural-textures.md` (default configuration):
    /// `cargo test --release --workspace default_pca_numbers -- --ignored --nocapture`.
    #[test]
    #[ignore = "slow: fits the default-configuration model"]
    fn default_pca_numbers() {
        let config = ProceduralTextureConfig::default();
        let start = std::time::Instant::now();
        let (pca, report, eval) = procedural_texture_pca(&config, &Device::flex()).unwrap();
        println!("config: {}", serde_json::to_string(&config).unwrap());
        println!("texels: {}", pca.layout.num_texels());
        let cumulative: Vec<String> = report
            .explained_variance_ratio
            .iter()
            .scan(0.0, |acc, r| {
                *acc += r;
                Some(format!("{:.3}", *acc))
            })
            .collect();
        println!("cumulative explained variance: {}", cumulative.join(" "));
        println!("total variance: {:.3}", report.total_variance);
        println!("{}", serde_json::to_string_pretty(&eval).unwrap());
        println!("elapsed: {:.1?}", start.elapsed());
        assert!(eval.held_out_rmse > eval.train_rmse);
        assert!(eval.held_out_rmse < 0.8 * eval.held_out_mean_rmse);
    }
}
