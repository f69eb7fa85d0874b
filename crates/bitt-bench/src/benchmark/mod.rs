//! The paper's evaluation protocol (Sec. 4.1, Tables 1, 3 and 4) on synthetic scenes:
//! per scene, fresh training of every method on the input view, then scores on the input
//! view (appearance reconstruction), the novel views and the novel poses, and texture-space
//! errors against the ground-truth textures, split into texels visible in the input, usable
//! through symmetry, and invisible on both hands (which only synthetic data can measure).
//!
//! Methods ([`Method`]): BiTT and its Table-4 ablations are configurations of the one
//! trainer; the HTML baseline is BiTT's own coarse stage (`T(h)` from the H network trained
//! with BiTT's loss on the same image: the HTML texture model fitted to the image, as the
//! paper's HTML baseline); HARP-like and S2Hand-like are [`bitt::baselines`].
//!
//! Files: `methods.rs` runs the methods on one scene and scores them, `aggregate.rs`
//! averages scene results and pairs methods scene by scene, `markdown.rs` writes
//! `results.md` with the claims, `folder.rs` keeps an evaluation's folder (result files per
//! scene and setting, shards, resume, merging), `scenes.rs` runs an evaluation's scenes one
//! after another (synthetic or InterHand2.6M, this shard's, skipping finished ones),
//! `photos.rs` the real-photo benchmark (`--photos`: each photo the input once, the others
//! its novel poses, scored in the photos' own hand masks).

use std::collections::BTreeMap;

use bitt_synth::TexelStats;

use bitt::BittError;
use bitt::config::TrainConfig;
use bitt::metrics::ImageMetrics;
pub use bitt::metrics::TexelErrors;

mod aggregate;
mod folder;
mod markdown;
mod methods;
mod photos;
mod scenes;

pub use aggregate::{MeanMetrics, MethodSummary, Paired, Summary, TexelStatsMean, summarize};
pub use folder::{
    EvalPlan, interhand_scene_id, merge, parse_scenes, parse_shard, pending, photo_scene_id,
    prepare_folder, result_path, shard_seeds, trainings_per_scene, write_scene, write_sheet,
};
pub use markdown::{claims, models_text, photos_markdown, results_markdown};
pub use methods::{ContactSheets, SceneSheets, SheetImages, evaluate_real_scene, evaluate_scene};
pub use photos::{
    Photo, PhotoConsistency, PhotoMetrics, PhotoNames, PhotoScores, SceneTextures, SeenSplit,
    mean_photo_metrics, photo_consistency, photo_metrics, photo_scenes, read_scene_textures,
    require_photo_files, scene_textures_path, write_scene_textures,
};
pub use scenes::{
    EvalObserver, EvalRun, EvalSource, Evaluation, InterHandScenes, PhotoScenes,
    evaluate_interhand, evaluate_photos, evaluate_synthetic, run_evaluation,
};

/// A method of the comparison (Tables 1 and 4).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// S2Hand-like per-vertex colours.
    #[serde(rename = "s2hand-like")]
    S2HandLike,
    /// The HTML baseline: BiTT's coarse stage.
    Html,
    /// HARP-like texels optimised from the visible pixels.
    HarpLike,
    /// Table 4, row 1: coarse stage and BTR with a uni-directional decoder, without `L_sym`
    /// and without the albedo consistency loss.
    BittNoSym,
    /// Table 4, row 2: + symmetric texture (bi-directional BTR and `L_sym`), without the
    /// albedo consistency loss.
    BittNoAlb,
    /// BiTT as in the paper (Table 4, row 3: + albedo consistency).
    Bitt,
    /// BiTT trained on the given meshes after refining them against the input image
    /// ([`bitt::refine`]; `eval --refine-mesh`).
    BittRefined,
}

impl Method {
    /// Every method, in the tables' row order.
    pub const ALL: [Method; 7] = [
        Method::S2HandLike,
        Method::Html,
        Method::HarpLike,
        Method::BittNoSym,
        Method::BittNoAlb,
        Method::Bitt,
        Method::BittRefined,
    ];

    /// The name used on the command line and in `results.json`.
    pub fn key(self) -> &'static str {
        match self {
            Method::S2HandLike => "s2hand-like",
            Method::Html => "html",
            Method::HarpLike => "harp-like",
            Method::BittNoSym => "bitt-no-sym",
            Method::BittNoAlb => "bitt-no-alb",
            Method::Bitt => "bitt",
            Method::BittRefined => "bitt-refined",
        }
    }

    /// Parses [`Method::key`].
    pub(crate) fn from_key(key: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.key() == key)
    }

    /// The methods of `bitt eval --methods` (keys; empty: all but [`Method::BittRefined`]),
    /// with [`Method::BittRefined`] added when `refine_mesh`.
    ///
    /// # Errors
    /// An unknown key, named with the known ones.
    pub fn parse_list(keys: &[String], refine_mesh: bool) -> Result<Vec<Method>, BittError> {
        let mut methods: Vec<Method> = if keys.is_empty() {
            Method::ALL
                .into_iter()
                .filter(|m| *m != Method::BittRefined)
                .collect()
        } else {
            keys.iter()
                .map(|k| {
                    Method::from_key(k.trim()).ok_or_else(|| {
                        BittError::Invalid(format!(
                            "--methods: unknown method `{k}` (known: {})",
                            Method::ALL.map(|m| m.key()).join(", ")
                        ))
                    })
                })
                .collect::<Result<_, _>>()?
        };
        if refine_mesh && !methods.contains(&Method::BittRefined) {
            methods.push(Method::BittRefined);
        }
        Ok(methods)
    }

    /// The row label of the tables.
    pub fn label(self) -> &'static str {
        match self {
            Method::S2HandLike => "S2Hand-like (per-vertex colour)",
            Method::Html => "HTML (coarse stage)",
            Method::HarpLike => "HARP-like (direct texels)",
            Method::BittNoSym => "coarse + BTR, no sym. tex., no L_alb",
            Method::BittNoAlb => "+ sym. tex. (bi-directional BTR, L_sym)",
            Method::Bitt => "BiTT (+ L_alb)",
            Method::BittRefined => "BiTT + refined mesh",
        }
    }

    /// The trainer configuration of a BiTT variant (`None` for the baselines).
    pub(crate) fn bitt_config(self, base: &TrainConfig) -> Option<TrainConfig> {
        let mut c = base.clone();
        match self {
            Method::Bitt | Method::BittRefined => {}
            Method::BittNoAlb => c.loss.alb = 0.0,
            Method::BittNoSym => {
                c.loss.alb = 0.0;
                c.loss.sym = 0.0;
                c.nets.btr.bidirectional = false;
            }
            Method::S2HandLike | Method::Html | Method::HarpLike => return None,
        }
        Some(c)
    }
}

/// Whether the method was given the true meshes or perturbed ones (Table 1a / 1b).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum MeshSetting {
    /// Ground-truth meshes.
    GtMesh,
    /// Meshes perturbed by the generator's mesh-noise switch ("without GT mesh").
    NoisyMesh,
}

impl MeshSetting {
    /// Both, in table order.
    pub const ALL: [MeshSetting; 2] = [MeshSetting::GtMesh, MeshSetting::NoisyMesh];

    /// The name on the command line and in file names.
    pub fn key(self) -> &'static str {
        match self {
            MeshSetting::GtMesh => "gt-mesh",
            MeshSetting::NoisyMesh => "noisy-mesh",
        }
    }

    /// The settings of `bitt eval --mesh`: `both`, `gt-mesh` or `noisy-mesh`.
    ///
    /// # Errors
    /// Any other word.
    pub fn parse_choice(choice: &str) -> Result<Vec<MeshSetting>, BittError> {
        match choice {
            "both" => Ok(MeshSetting::ALL.to_vec()),
            "gt-mesh" => Ok(vec![MeshSetting::GtMesh]),
            "noisy-mesh" => Ok(vec![MeshSetting::NoisyMesh]),
            other => Err(BittError::Invalid(format!(
                "--mesh {other}: expected both, gt-mesh or noisy-mesh"
            ))),
        }
    }
}

/// One method's scores on one scene.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MethodScores {
    /// The input view (appearance reconstruction).
    pub input_view: ImageMetrics,
    /// Mean over the novel views.
    pub novel_views: Option<ImageMetrics>,
    /// Mean over the novel poses.
    pub novel_poses: Option<ImageMetrics>,
    /// Texture-space errors, raw.
    pub texture: TexelErrors,
    /// Texture-space errors after one gain per colour channel fitted on the visible texels
    /// (the headline; [`TextureErrors`](bitt::metrics::TextureErrors)).
    #[serde(default)]
    pub texture_gain_fitted: TexelErrors,
    /// Seconds spent training it (shared trainings are counted once, on the first method).
    pub seconds: f64,
    /// Photo scenes (`--photos`): the scores in each photo's own hand mask.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo: Option<PhotoScores>,
}

/// Every method's scores on one scene and mesh setting.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SceneResult {
    /// Format tag.
    pub format: String,
    /// The scene's seed.
    pub seed: u64,
    /// The mesh setting.
    pub setting: MeshSetting,
    /// The preset trained with.
    pub preset: String,
    /// Iterations of every BiTT training.
    pub iterations: usize,
    /// The scene's texel statistics (Table 3).
    pub stats: TexelStats,
    /// Scores per method.
    pub methods: BTreeMap<Method, MethodScores>,
    /// Photo scenes (`--photos`): the photo trained on and those scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photos: Option<PhotoNames>,
}

/// The `format` of a [`SceneResult`] file.
pub(crate) const SCENE_RESULT_FORMAT: &str = "bitt-eval-scene-1";

#[cfg(test)]
mod tests {
    use super::*;
    use bitt::metrics::{TextureErrors, texture_errors};

    #[test]
    fn texel_classes_split_by_own_and_other_hand_visibility() {
        // Four texels per hand; errors 0.1 (visible), 0.2 (seen only on the other hand),
        // 0.4 (seen on neither).
        let visible = [
            vec![true, true, false, false],
            vec![true, false, true, false],
        ];
        let gt = [vec![0.5f32; 12], vec![0.5f32; 12]];
        let err = |own: bool, other: bool| -> f32 {
            match (own, other) {
                (true, _) => 0.1,
                (false, true) => 0.2,
                (false, false) => 0.4,
            }
        };
        let textures: [Vec<f32>; 2] = std::array::from_fn(|h| {
            (0..12)
                .map(|k| 0.5 + err(visible[h][k % 4], visible[1 - h][k % 4]))
                .collect()
        });
        let e = texture_errors(&textures, &gt, &visible).raw;
        assert!((e.visible.unwrap() - 0.1).abs() < 1e-6);
        assert!((e.symmetric.unwrap() - 0.2).abs() < 1e-6);
        assert!((e.invisible.unwrap() - 0.4).abs() < 1e-6);
        // Not visible on the own hand: left texels 2 (0.2) and 3 (0.4), right 1 (0.2) and 3.
        assert!((e.not_visible.unwrap() - 0.3).abs() < 1e-6);
        // Mismatched lengths give no numbers rather than a panic.
        let short = [vec![0.5f32; 3], vec![0.5f32; 3]];
        assert_eq!(
            texture_errors(&short, &gt, &visible),
            TextureErrors::default()
        );
    }

    #[test]
    fn ablation_configs_switch_the_right_parts() {
        let base = TrainConfig::preset(bitt_nets::Preset::Tiny);
        let full = Method::Bitt.bitt_config(&base).unwrap();
        let json = |c: &TrainConfig| serde_json::to_string(c).unwrap();
        assert_eq!(json(&full), json(&base));
        let no_alb = Method::BittNoAlb.bitt_config(&base).unwrap();
        assert_eq!(no_alb.loss.alb, 0.0);
        assert!(no_alb.nets.btr.bidirectional);
        let no_sym = Method::BittNoSym.bitt_config(&base).unwrap();
        assert_eq!((no_sym.loss.alb, no_sym.loss.sym), (0.0, 0.0));
        assert!(!no_sym.nets.btr.bidirectional);
        assert!(Method::HarpLike.bitt_config(&base).is_none());
        for m in Method::ALL {
            assert_eq!(Method::from_key(m.key()), Some(m));
        }
    }
}
