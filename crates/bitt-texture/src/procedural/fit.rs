//! A texture PCA model fitted to procedural skins, and how well it represents unseen people.

use bitt_mesh::{HandModel, Side, default_hand};
use burn::tensor::Device;
use rayon::prelude::*;

use super::generate::generate_texture;
use super::identity::SkinIdentity;
use super::noise::derive;
use crate::TextureError;
use crate::layout::TextureLayout;
use crate::pca::{
    FitProgress, FitStage, NoProgress, PcaFitReport, PcaProjector, StageCounter, TexturePca,
};

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
    pub(crate) fn held_out_identity(&self, j: usize) -> SkinIdentity {
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
/// [`procedural_texture_pca_with_progress`] without progress reports.
///
/// # Errors
/// [`TextureError::Invalid`] for a configuration outside its ranges, and any error of
/// [`TextureLayout::from_uv`] or [`TexturePca::fit`].
pub fn procedural_texture_pca(
    config: &ProceduralTextureConfig,
    device: &Device,
) -> Result<(TexturePca, PcaFitReport, EvalReport), TextureError> {
    procedural_texture_pca_with_progress(config, device, &NoProgress)
}

/// [`procedural_texture_pca`], on all cores, reporting its stages to `progress`:
/// [`FitStage::Generate`] (one step per identity, training and held-out together), the
/// stages of [`TexturePca::fit_with_progress`], then [`FitStage::Evaluate`] (the normal
/// equations, then one step per projected sample).
///
/// The identities are generated in parallel (rayon) and every sum runs in the same order
/// as in the sequential code, so the model and the report are the same bit for bit for any
/// number of threads.
///
/// # Errors
/// As [`procedural_texture_pca`].
pub fn procedural_texture_pca_with_progress(
    config: &ProceduralTextureConfig,
    device: &Device,
    progress: &dyn FitProgress,
) -> Result<(TexturePca, PcaFitReport, EvalReport), TextureError> {
    let (pca, report, train, held) = fit_model(config, device, progress, true)?;
    let eval = StageCounter::new(progress, FitStage::Evaluate, 1 + train.len() + held.len());
    let projector = pca.projector(None, EVAL_RIDGE)?;
    eval.step();
    let eval = EvalReport {
        train_rmse: reconstruction_rmse(&pca, &projector, &train, &eval)?,
        held_out_rmse: reconstruction_rmse(&pca, &projector, &held, &eval)?,
        held_out_mean_rmse: rmse_against(&pca.mean, &held),
        train_mean_rmse: rmse_against(&pca.mean, &train),
        explained_variance_at_k: report.explained_variance_ratio.iter().sum(),
    };
    Ok((pca, report, eval))
}

/// The model of [`procedural_texture_pca_with_progress`] without its evaluation: the
/// held-out people are neither generated nor projected (what a trainer needs; the same
/// model and fit report, bit for bit). Reports [`FitStage::Generate`] (training identities)
/// and the stages of [`TexturePca::fit_with_progress`].
///
/// # Errors
/// As [`procedural_texture_pca`].
pub fn procedural_texture_model(
    config: &ProceduralTextureConfig,
    device: &Device,
    progress: &dyn FitProgress,
) -> Result<(TexturePca, PcaFitReport), TextureError> {
    let (pca, report, _, _) = fit_model(config, device, progress, false)?;
    Ok((pca, report))
}

/// The fitted model, its report, the training samples and (when `held_out`) the held-out
/// samples.
#[allow(clippy::type_complexity)]
fn fit_model(
    config: &ProceduralTextureConfig,
    device: &Device,
    progress: &dyn FitProgress,
    held_out: bool,
) -> Result<(TexturePca, PcaFitReport, Vec<Vec<f32>>, Vec<Vec<f32>>), TextureError> {
    config.validate()?;
    let right = default_hand(Side::Right);
    let left = default_hand(Side::Left);
    let uv = right
        .uv
        .as_ref()
        .ok_or_else(|| TextureError::Invalid("the procedural hand has no UV layout".into()))?;
    let layout = TextureLayout::from_uv(uv, config.resolution, config.resolution, config.gutter)?;
    let held_count = if held_out { config.held_out } else { 0 };
    let ids: Vec<SkinIdentity> = (0..config.identities)
        .map(|i| config.training_identity(i))
        .chain((0..held_count).map(|j| config.held_out_identity(j)))
        .collect();
    let stage = StageCounter::new(progress, FitStage::Generate, ids.len());
    let mut train = both_hands(&layout, &left, &right, &ids, &stage)?;
    stage.finish();
    let held = train.split_off(2 * config.identities);
    let (pca, report) =
        TexturePca::fit_with_progress(layout, &train, config.components, device, progress)?;
    Ok((pca, report, train, held))
}

/// Left then right texture of every identity, the identities in parallel (rayon), one
/// progress step per identity.
fn both_hands(
    layout: &TextureLayout,
    left: &HandModel,
    right: &HandModel,
    ids: &[SkinIdentity],
    stage: &StageCounter<'_>,
) -> Result<Vec<Vec<f32>>, TextureError> {
    let per_id: Vec<Result<[Vec<f32>; 2], TextureError>> = ids
        .par_iter()
        .map(|id| {
            let l = generate_texture(layout, left, id, Side::Left)?;
            let r = generate_texture(layout, right, id, Side::Right)?;
            stage.step();
            Ok([l, r])
        })
        .collect();
    let mut out = Vec::with_capacity(2 * ids.len());
    for r in per_id {
        out.extend(r?);
    }
    Ok(out)
}

/// RMSE of the model's least-squares reconstructions of `samples` (projected in parallel;
/// the per-sample sums are added in order, as a sequential loop would), one progress step
/// per sample.
fn reconstruction_rmse(
    pca: &TexturePca,
    projector: &PcaProjector<'_>,
    samples: &[Vec<f32>],
    stage: &StageCounter<'_>,
) -> Result<f32, TextureError> {
    let errors: Vec<Result<f64, TextureError>> = samples
        .par_iter()
        .map(|s| {
            let params = projector.project(s)?;
            let recon = pca.texture(&params)?;
            stage.step();
            Ok(squared_error(&recon, s))
        })
        .collect();
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (e, s) in errors.into_iter().zip(samples) {
        sum += e?;
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
    use crate::test_util::{Recorder, on_threads};

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

    fn tiny() -> ProceduralTextureConfig {
        ProceduralTextureConfig {
            resolution: 128,
            identities: 3,
            held_out: 1,
            components: 3,
            seed: 9,
            gutter: 1,
        }
    }

    /// The model and evaluation as computed before the fit ran on rayon: textures one at a
    /// time, the sequential fit, one projection (with its own normal equations) per sample.
    fn previous(config: &ProceduralTextureConfig) -> (TexturePca, PcaFitReport, EvalReport) {
        let right = default_hand(Side::Right);
        let left = default_hand(Side::Left);
        let uv = right.uv.as_ref().unwrap();
        let layout =
            TextureLayout::from_uv(uv, config.resolution, config.resolution, config.gutter)
                .unwrap();
        let textures = |ids: Vec<SkinIdentity>| -> Vec<Vec<f32>> {
            ids.iter()
                .flat_map(|id| {
                    [
                        generate_texture(&layout, &left, id, Side::Left).unwrap(),
                        generate_texture(&layout, &right, id, Side::Right).unwrap(),
                    ]
                })
                .collect()
        };
        let train = textures(
            (0..config.identities)
                .map(|i| config.training_identity(i))
                .collect(),
        );
        let held = textures(
            (0..config.held_out)
                .map(|j| config.held_out_identity(j))
                .collect(),
        );
        let (pca, report) = on_threads(1, || {
            TexturePca::fit(layout.clone(), &train, config.components, &Device::flex()).unwrap()
        });
        let rmse = |samples: &[Vec<f32>]| {
            let mut sum = 0.0f64;
            let mut count = 0usize;
            for s in samples {
                let params = pca.project(s, None, EVAL_RIDGE).unwrap();
                sum += squared_error(&pca.texture(&params).unwrap(), s);
                count += s.len();
            }
            (sum / count as f64).sqrt() as f32
        };
        let eval = EvalReport {
            train_rmse: rmse(&train),
            held_out_rmse: rmse(&held),
            held_out_mean_rmse: rmse_against(&pca.mean, &held),
            train_mean_rmse: rmse_against(&pca.mean, &train),
            explained_variance_at_k: report.explained_variance_ratio.iter().sum(),
        };
        (pca, report, eval)
    }

    #[test]
    fn parallel_procedural_pca_equals_the_sequential_one_bit_for_bit() {
        let config = tiny();
        let want = previous(&config);
        for threads in [1, 3] {
            let got = on_threads(threads, || {
                procedural_texture_pca(&config, &Device::flex()).unwrap()
            });
            assert_eq!(got, want, "{threads} threads");
        }
        // Without the evaluation: the same model.
        let (pca, report) = on_threads(2, || {
            procedural_texture_model(&config, &Device::flex(), &NoProgress).unwrap()
        });
        assert_eq!((pca, report), (want.0, want.1));
    }

    #[test]
    fn procedural_pca_reports_every_stage_monotonically() {
        let config = tiny();
        let rec = Recorder::default();
        on_threads(2, || {
            procedural_texture_pca_with_progress(&config, &Device::flex(), &rec).unwrap()
        });
        // Every stage in order; the model without the evaluation stops before the last.
        let stages = [
            FitStage::Generate,
            FitStage::Centre,
            FitStage::Gram,
            FitStage::Eigen,
            FitStage::Basis,
            FitStage::Evaluate,
        ];
        let totals = rec.check(&stages);
        // Training and held-out identities; the normal equations and the 2 x 4 samples.
        assert_eq!(totals[0], 4);
        assert_eq!(totals[5], 1 + 8);
        let calls = rec.0.lock().unwrap().clone();
        let generated: Vec<usize> = calls
            .iter()
            .filter(|c| c.0 == FitStage::Generate)
            .map(|c| c.1)
            .collect();
        assert_eq!(generated, [0, 1, 2, 3, 4], "one step per identity");
        // Without the evaluation: training identities only, no evaluation stage.
        let rec = Recorder::default();
        procedural_texture_model(&config, &Device::flex(), &rec).unwrap();
        let totals = rec.check(&stages[..5]);
        assert_eq!(totals[0], 3);
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
