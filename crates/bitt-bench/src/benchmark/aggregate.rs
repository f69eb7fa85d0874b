//! Averaging scene results into `results.json`, and the paired per-scene differences.

use std::collections::BTreeMap;

use super::{MeshSetting, Method, MethodScores, SceneResult, TexelErrors};
use bitt::metrics::ImageMetrics;

/// The mean of a list of optional values (`None` when any is missing or the list is empty).
fn mean_opt(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Option<Vec<f64>> = values.collect();
    let v = v?;
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Per class, the mean over scenes (a class only when every scene has it).
fn mean_texel_errors<'a>(all: impl Iterator<Item = &'a TexelErrors> + Clone) -> TexelErrors {
    TexelErrors {
        visible: mean_opt(all.clone().map(|t| t.visible)),
        symmetric: mean_opt(all.clone().map(|t| t.symmetric)),
        invisible: mean_opt(all.clone().map(|t| t.invisible)),
        not_visible: mean_opt(all.map(|t| t.not_visible)),
    }
}

/// Mean image metrics over scenes ([`bitt::evaluate::mean_metrics`]: `ms_ssim` and `lpips`
/// only when every scene has them): the same fields as one pair's.
pub type MeanMetrics = ImageMetrics;

fn mean_metrics(all: &[ImageMetrics]) -> Option<MeanMetrics> {
    bitt::evaluate::mean_metrics(all)
}

/// One method's scores averaged over the scenes of one mesh setting.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MethodSummary {
    /// Scenes averaged.
    pub scenes: usize,
    /// Input view.
    pub input_view: Option<MeanMetrics>,
    /// Novel views.
    pub novel_views: Option<MeanMetrics>,
    /// Novel poses.
    pub novel_poses: Option<MeanMetrics>,
    /// Texture errors, raw.
    pub texture: TexelErrors,
    /// Texture errors after the per-channel gain (the headline).
    #[serde(default)]
    pub texture_gain_fitted: TexelErrors,
    /// Mean seconds per scene.
    pub seconds: f64,
}

/// Everything `results.json` holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// Per mesh setting, per method.
    pub settings: BTreeMap<MeshSetting, BTreeMap<Method, MethodSummary>>,
    /// Mean Table-3 statistics of the scenes (per setting they are the same scenes).
    pub stats: Option<TexelStatsMean>,
    /// The scene seeds included.
    pub seeds: Vec<u64>,
    /// Presets seen (normally one).
    pub presets: Vec<String>,
    /// Per-scene paired differences behind the claims (see [`Paired`]).
    #[serde(default)]
    pub paired: Vec<Paired>,
}

/// The PSNR difference `a - b` of two methods scene by scene, over the scenes of one mesh
/// setting that have both: one seed's training noise is about as large as the effects the
/// claims are about, so the claims say how consistent a difference is, not only its mean.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Paired {
    /// The mesh setting.
    pub setting: MeshSetting,
    /// The method compared.
    pub a: Method,
    /// The method it is compared with.
    pub b: Method,
    /// `true`: novel views only (Table 1); `false`: the mean of novel poses and novel views
    /// (Table 4).
    pub views_only: bool,
    /// Scenes with both.
    pub scenes: usize,
    /// Mean of `a - b` (dB).
    pub mean_db: f64,
    /// Standard error of that mean (dB); `None` for a single scene.
    pub stderr_db: Option<f64>,
    /// Scenes where `a` has the higher PSNR.
    pub wins: usize,
}

/// The comparisons the claims make: BiTT against each baseline on novel views, and each
/// ablation step against the row above it on the mean of novel poses and views.
const PAIRS: [(Method, Method, bool); 5] = [
    (Method::Bitt, Method::Html, true),
    (Method::Bitt, Method::HarpLike, true),
    (Method::Bitt, Method::S2HandLike, true),
    (Method::BittNoAlb, Method::BittNoSym, false),
    (Method::Bitt, Method::BittNoAlb, false),
];

fn paired(results: &[SceneResult]) -> Vec<Paired> {
    let psnr = |m: &MethodScores, views_only: bool| -> Option<f64> {
        let v = m.novel_views?.psnr;
        if views_only {
            Some(v)
        } else {
            Some(0.5 * (v + m.novel_poses?.psnr))
        }
    };
    let mut out = Vec::new();
    for setting in MeshSetting::ALL {
        for (a, b, views_only) in PAIRS {
            let d: Vec<f64> = results
                .iter()
                .filter(|r| r.setting == setting)
                .filter_map(|r| {
                    Some(
                        psnr(r.methods.get(&a)?, views_only)?
                            - psnr(r.methods.get(&b)?, views_only)?,
                    )
                })
                .collect();
            if d.is_empty() {
                continue;
            }
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let stderr = (d.len() > 1).then(|| {
                let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
                (var / n).sqrt()
            });
            out.push(Paired {
                setting,
                a,
                b,
                views_only,
                scenes: d.len(),
                mean_db: mean,
                stderr_db: stderr,
                wins: d.iter().filter(|&&x| x > 0.0).count(),
            });
        }
    }
    out
}

/// Mean texel statistics (Table 3, percent of texels).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelStatsMean {
    /// Left visible.
    pub left_visible: f64,
    /// Right visible.
    pub right_visible: f64,
    /// Visible on exactly one hand.
    pub symmetric_usable: f64,
    /// Visible on neither.
    pub invisible: f64,
}

/// Averages scene results into the tables.
pub fn summarize(results: &[SceneResult]) -> Summary {
    let mut settings: BTreeMap<MeshSetting, BTreeMap<Method, MethodSummary>> = BTreeMap::new();
    for setting in MeshSetting::ALL {
        let scenes: Vec<&SceneResult> = results.iter().filter(|r| r.setting == setting).collect();
        let mut per = BTreeMap::new();
        for method in Method::ALL {
            let s: Vec<&MethodScores> = scenes
                .iter()
                .filter_map(|r| r.methods.get(&method))
                .collect();
            if s.is_empty() {
                continue;
            }
            let collect = |f: &dyn Fn(&MethodScores) -> Option<ImageMetrics>| {
                let v: Option<Vec<ImageMetrics>> = s.iter().map(|m| f(m)).collect();
                v.and_then(|v| mean_metrics(&v))
            };
            per.insert(
                method,
                MethodSummary {
                    scenes: s.len(),
                    input_view: collect(&|m| Some(m.input_view)),
                    novel_views: collect(&|m| m.novel_views),
                    novel_poses: collect(&|m| m.novel_poses),
                    texture: mean_texel_errors(s.iter().map(|m| &m.texture)),
                    texture_gain_fitted: mean_texel_errors(
                        s.iter().map(|m| &m.texture_gain_fitted),
                    ),
                    seconds: s.iter().map(|m| m.seconds).sum::<f64>() / s.len() as f64,
                },
            );
        }
        if !per.is_empty() {
            settings.insert(setting, per);
        }
    }
    let mut seeds: Vec<u64> = results.iter().map(|r| r.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let unique: Vec<&SceneResult> = seeds
        .iter()
        .filter_map(|s| results.iter().find(|r| r.seed == *s))
        .collect();
    let stats = (!unique.is_empty()).then(|| {
        let n = unique.len() as f64;
        let f = |g: &dyn Fn(&SceneResult) -> f64| unique.iter().map(|r| g(r)).sum::<f64>() / n;
        TexelStatsMean {
            left_visible: 100.0 * f(&|r| r.stats.table3.left_visible),
            right_visible: 100.0 * f(&|r| r.stats.table3.right_visible),
            symmetric_usable: 100.0 * f(&|r| r.stats.table3.symmetric_usable),
            invisible: 100.0 * f(&|r| r.stats.table3.invisible),
        }
    });
    let mut presets: Vec<String> = results.iter().map(|r| r.preset.clone()).collect();
    presets.sort();
    presets.dedup();
    Summary {
        settings,
        stats,
        seeds,
        presets,
        paired: paired(results),
    }
}
