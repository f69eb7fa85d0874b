//! Running the methods on one scene: each trained on the input view, then scored.

use bitt_render::scene::LightValuesExt;

use std::collections::BTreeMap;
use std::time::Instant;

use bitt_mesh::TwoHandScene;
use bitt_render::scene::LightValues;
use bitt_synth::{SynthScene, SynthView, TexelStats};
use bitt_texture::TexturePca;
use burn::tensor::Device;

use super::photos::{PhotoScores, SceneTextures, mean_photo_metrics, photo_metrics};
use super::{MeshSetting, Method, MethodScores, SCENE_RESULT_FORMAT, SceneResult};
use bitt::BittError;
use bitt::assets::ViewGeometry;
use bitt::baselines::{Baseline, BaselineConfig, run_baseline};
use bitt::config::TrainConfig;
use bitt::evaluate::{Avatar, hand_image, move_light, render_geometry};
use bitt::input::fit_synthetic_view;
use bitt::lpips::LpipsVgg;
use bitt::metrics::{TextureErrors, image_metrics, texture_errors};
use bitt::real::{RealScene, RealView, hand_masks};
use bitt::run::synthetic_trainer;
use bitt::trainer::{Observer, Trainer};
use bitt_stdx::to_host;

/// An avatar to score: compact textures and a light in the training camera's frame.
struct Candidate {
    textures: [Vec<f32>; 2],
    light: LightValues,
    /// The texture prior the method started from, for [`bitt::evaluate::unseen_detail`]
    /// (BiTT: its coarse textures).
    prior: Option<[Vec<f32>; 2]>,
}

/// One scored view's ground truth: the hand image, the posed geometry, the hands and, for
/// photo scenes, the photo itself with the meshes' silhouette (for [`PhotoMetrics`]).
struct TruthView {
    gt: Vec<f32>,
    geometry: ViewGeometry,
    hands: TwoHandScene,
    photo: Option<(Vec<f32>, Vec<f32>)>,
}

/// Ground truth prepared once per scene: hand images and posed geometry of every view.
struct Truth {
    input: TruthView,
    views: Vec<TruthView>,
    poses: Vec<TruthView>,
    /// Photo scenes: the input view's ambient occlusion at every texel (for
    /// [`bitt::evaluate::albedo_in_shade`]), made once for all methods.
    input_occlusion: Option<[Vec<f32>; 2]>,
    /// Photo scenes: the palm-side texels of each hand ([`bitt_texture::palm_side_texels`]),
    /// for [`bitt::evaluate::unseen_detail`].
    palm: Option<[Vec<bool>; 2]>,
}

/// What [`Truth::from_views`] needs of a view: its ground-truth hand image, its hands and
/// (photo scenes) the photo with the meshes' silhouette.
type ViewTruth = (Vec<f32>, TwoHandScene, Option<(Vec<f32>, Vec<f32>)>);

impl Truth {
    /// From the input view, the novel views and poses, and `truth`, which gives a view's
    /// ground truth.
    fn from_views<V>(
        trainer: &Trainer,
        (input, views, poses): (&V, &[V], &[V]),
        truth: impl Fn(&V) -> Result<ViewTruth, BittError>,
        device: &Device,
    ) -> Result<Self, BittError> {
        let prep = |v: &V| {
            let (gt, hands, photo) = truth(v)?;
            let geometry = trainer.view_geometry(&hands, device)?;
            Ok::<_, BittError>(TruthView {
                gt,
                geometry,
                hands,
                photo,
            })
        };
        let input = prep(input)?;
        let (input_occlusion, palm) = match input.photo {
            Some(_) => {
                let assets = &trainer.assets;
                let palm = |k: usize, side: bitt_mesh::Side| {
                    bitt_texture::palm_side_texels(&assets.layouts[k], assets.models.get(side))
                };
                (
                    Some(input.geometry.texel_occlusion(assets)?),
                    Some([
                        palm(0, bitt_mesh::Side::Left)?,
                        palm(1, bitt_mesh::Side::Right)?,
                    ]),
                )
            }
            None => (None, None),
        };
        Ok(Truth {
            input,
            views: views.iter().map(prep).collect::<Result<_, _>>()?,
            poses: poses.iter().map(prep).collect::<Result<_, _>>()?,
            input_occlusion,
            palm,
        })
    }

    /// A real scene: each photograph times the silhouettes of its annotated meshes (the
    /// reference's `masked_img`), and the photograph itself, scored in its own hand mask.
    fn real(trainer: &Trainer, scene: &RealScene, device: &Device) -> Result<Self, BittError> {
        let size = trainer.config.nets.image_size;
        let views = (&scene.train, &scene.novel_views[..], &scene.novel_poses[..]);
        Self::from_views(
            trainer,
            views,
            |v: &RealView| {
                let masks = hand_masks(trainer, &v.hands)?;
                let gt = hand_image(&v.image, &masks, size * size)?;
                let drawn = masks[0]
                    .iter()
                    .zip(&masks[1])
                    .map(|(a, b)| a.max(*b))
                    .collect();
                Ok((gt, v.hands.clone(), Some((v.image.clone(), drawn))))
            },
            device,
        )
    }

    /// The first novel view's and pose's ground truth (for the contact sheets; the photo
    /// itself where there is one). A photo scene has no novel view: its input view takes
    /// that row.
    fn firsts(&self) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
        let shown = |v: &TruthView| {
            v.photo
                .as_ref()
                .map_or_else(|| v.gt.clone(), |p| p.0.clone())
        };
        let view = match (self.views.first(), &self.input.photo) {
            (Some(v), _) => Some(shown(v)),
            (None, Some(photo)) => Some(photo.0.clone()),
            (None, None) => None,
        };
        (view, self.poses.first().map(shown))
    }

    /// A synthetic scene: each view's image times its true hand masks.
    fn new(trainer: &Trainer, scene: &SynthScene, device: &Device) -> Result<Self, BittError> {
        let size = trainer.config.nets.image_size;
        let views = (&scene.train, &scene.novel_views[..], &scene.novel_poses[..]);
        Self::from_views(
            trainer,
            views,
            |v: &SynthView| {
                let (image, masks, hands) = fit_synthetic_view(v, size)?;
                Ok((hand_image(&image, &masks, size * size)?, hands, None))
            },
            device,
        )
    }
}

/// Renders of a candidate at the first novel view and pose (for the contact sheets).
pub type SheetImages = (Vec<f32>, Vec<f32>);

fn score(
    trainer: &Trainer,
    truth: &Truth,
    c: &Candidate,
    visible: &[Vec<bool>; 2],
    gt_textures: Option<&[Vec<f32>; 2]>,
    lpips: Option<&LpipsVgg>,
) -> Result<(MethodScores, SheetImages), BittError> {
    let size = trainer.config.nets.image_size;
    let dims = [3, size, size];
    let train_camera = truth.input.hands.camera;
    let mut first = (Vec::new(), Vec::new());
    let one = |entry: &TruthView| {
        let device = entry.geometry.vertices[0].device();
        let light = move_light(&c.light, &train_camera, &entry.hands.camera).to_light(&device);
        let img = render_geometry(trainer, &entry.geometry, &c.textures, &light)?;
        let mut m = image_metrics(&img, &entry.gt, dims);
        if let Some(net) = lpips {
            m.lpips = Some(net.distance(&img, &entry.gt, dims, &device)?);
        }
        let photo = match &entry.photo {
            Some((photo, drawn)) => {
                let seen = bitt::evaluate::seen_pixels(trainer, &entry.geometry, visible)?;
                photo_metrics(&img, photo, drawn, Some(&seen), size)
            }
            None => None,
        };
        Ok::<_, BittError>((m, photo, img))
    };
    let (input_view, input_photo, input_img) = one(&truth.input)?;
    if truth.views.is_empty() && truth.input.photo.is_some() {
        // Photo scenes have no novel view: their sheet's first row is the input view.
        first.0 = input_img;
    }
    let mut views = Vec::new();
    for (k, v) in truth.views.iter().enumerate() {
        let (m, _, img) = one(v)?;
        if k == 0 {
            first.0 = img;
        }
        views.push(m);
    }
    let mut poses = Vec::new();
    let mut pose_photos = Vec::new();
    for (k, v) in truth.poses.iter().enumerate() {
        let (m, photo, img) = one(v)?;
        if k == 0 {
            first.1 = img;
        }
        poses.push(m);
        pose_photos.extend(photo);
    }
    let shade = truth
        .input_occlusion
        .as_ref()
        .and_then(|ao| bitt::evaluate::albedo_in_shade(&c.textures, visible, ao));
    let unseen_palm = match (&truth.palm, &c.prior) {
        (Some(palm), Some(prior)) => bitt::evaluate::unseen_detail(
            &c.textures,
            prior,
            visible,
            palm,
            &trainer.assets.layouts[0],
        ),
        _ => None,
    };
    let photo = input_photo.map(|input_view| PhotoScores {
        input_view,
        novel_poses: mean_photo_metrics(&pose_photos),
        albedo_in_shade: shade,
        unseen_palm,
    });
    let texture: TextureErrors = gt_textures
        .map(|gt| texture_errors(&c.textures, gt, visible))
        .unwrap_or_default();
    Ok((
        MethodScores {
            input_view,
            novel_views: bitt::evaluate::mean_metrics(&views),
            novel_poses: bitt::evaluate::mean_metrics(&poses),
            texture: texture.raw,
            texture_gain_fitted: texture.gain_fitted,
            seconds: 0.0,
            photo,
        },
        first,
    ))
}

/// What [`evaluate_scene`] returns besides the scores: renders for the contact sheets,
/// per method: (first novel view, first novel pose).
pub type SceneSheets = Vec<(Method, SheetImages)>;

/// Where the scenes of an evaluation come from: how to build a trainer for a configuration,
/// the ground truth of every scored view, and (synthetic only) the true textures.
/// Builds a trainer for a configuration.
type TrainerFactory<'a> = &'a dyn Fn(&TrainConfig) -> Result<Trainer, BittError>;

struct SceneSource<'a> {
    trainer: TrainerFactory<'a>,
    /// A trainer on the given meshes refined against the input image (`None`: not offered).
    refined_trainer: Option<TrainerFactory<'a>>,
    truth: &'a dyn Fn(&Trainer) -> Result<Truth, BittError>,
    gt_textures: Option<&'a [Vec<f32>; 2]>,
}

/// What [`evaluate_with`] returns: scores per method, contact-sheet renders, the training
/// view's visible texels and the ground truth of the first novel view and pose.
type Evaluated = (
    BTreeMap<Method, MethodScores>,
    SceneSheets,
    [Vec<bool>; 2],
    (Option<Vec<f32>>, Option<Vec<f32>>),
    Option<SceneTextures>,
);

/// Trains and scores `methods` on one synthetic scene. `device` must be an autodiff device;
/// `observer` sees every BiTT training iteration.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_scene(
    scene: &SynthScene,
    setting: MeshSetting,
    config: &TrainConfig,
    baseline: &BaselineConfig,
    pca: &TexturePca,
    methods: &[Method],
    lpips: Option<&LpipsVgg>,
    device: &Device,
    observer: &mut dyn Observer,
) -> Result<(SceneResult, ContactSheets), BittError> {
    let host = device.clone().inner();
    let refined = |cfg: &TrainConfig| -> Result<Trainer, BittError> {
        let assets =
            bitt::assets::HandAssets::new(bitt_mesh::procedural_pair(), cfg.texture.resolution)?;
        let done = bitt::refine::refine_synthetic(
            scene,
            &assets,
            pca,
            cfg.nets.image_size,
            &bitt::refine::RefineConfig::default(),
            device,
            &mut bitt::refine::Quiet,
        )?;
        let mut refined_scene = scene.clone();
        refined_scene.given = done.hands;
        synthetic_trainer(&refined_scene, cfg, pca, device)
    };
    let source = SceneSource {
        trainer: &|cfg| synthetic_trainer(scene, cfg, pca, device),
        refined_trainer: Some(&refined),
        truth: &|trainer| Truth::new(trainer, scene, &host),
        gt_textures: Some(&scene.textures),
    };
    let (results, sheets, _, (view, pose), _) =
        evaluate_with(&source, config, baseline, methods, lpips, device, observer)?;
    Ok((
        SceneResult {
            format: SCENE_RESULT_FORMAT.to_string(),
            seed: scene.seed,
            setting,
            preset: config.preset.to_string(),
            iterations: config.iterations,
            stats: scene.stats,
            methods: results,
            photos: None,
        },
        ContactSheets {
            view,
            pose,
            methods: sheets,
        },
    ))
}

/// Contact-sheet material of a scene: the ground-truth hand image of the first novel view
/// and novel pose (for real scenes the photograph times the annotated meshes' silhouettes),
/// and each method's renders of them.
#[derive(Debug, Clone)]
pub struct ContactSheets {
    /// Ground truth of the first novel view.
    pub view: Option<Vec<f32>>,
    /// Ground truth of the first novel pose.
    pub pose: Option<Vec<f32>>,
    /// Per method: (first novel view, first novel pose).
    pub methods: SceneSheets,
}

/// Trains and scores `methods` on one real multi-view scene (InterHand2.6M, annotated
/// meshes: Table 1a's setting). As [`evaluate_scene`], but every view's ground truth is its
/// photograph times the silhouettes of its annotated meshes, the light stays where it was
/// in the capture's world, texture-space errors are absent (no true texture exists) and the
/// Table-3 statistics come from the training view's visible texels. `trainer` builds a
/// fresh trainer on the training view for a configuration; `id` names the scene in the
/// results. Also returns BiTT's textures when it was among the methods (or trained for
/// HTML).
#[allow(clippy::too_many_arguments)]
pub fn evaluate_real_scene(
    scene: &RealScene,
    id: u64,
    trainer: &dyn Fn(&TrainConfig) -> Result<Trainer, BittError>,
    config: &TrainConfig,
    baseline: &BaselineConfig,
    methods: &[Method],
    lpips: Option<&LpipsVgg>,
    device: &Device,
    observer: &mut dyn Observer,
) -> Result<(SceneResult, ContactSheets, Option<SceneTextures>), BittError> {
    let host = device.clone().inner();
    if methods.contains(&Method::BittRefined) {
        return Err(BittError::Invalid(
            "the refined-mesh method is measured on synthetic scenes (their perturbed meshes); \
             real scenes are trained on their annotated meshes"
                .into(),
        ));
    }
    let source = SceneSource {
        trainer,
        refined_trainer: None,
        truth: &|t| Truth::real(t, scene, &host),
        gt_textures: None,
    };
    let (results, sheets, visible, (view, pose), textures) =
        evaluate_with(&source, config, baseline, methods, lpips, device, observer)?;
    let stats = TexelStats::from_masks(&visible[0], &visible[1])
        .map_err(|e| BittError::Invalid(format!("texel statistics: {e}")))?;
    Ok((
        SceneResult {
            format: SCENE_RESULT_FORMAT.to_string(),
            seed: id,
            setting: MeshSetting::GtMesh,
            preset: config.preset.to_string(),
            iterations: config.iterations,
            stats,
            methods: results,
            photos: None,
        },
        ContactSheets {
            view,
            pose,
            methods: sheets,
        },
        textures,
    ))
}

/// The shared part of [`evaluate_scene`] and [`evaluate_real_scene`].
fn evaluate_with(
    source: &SceneSource<'_>,
    config: &TrainConfig,
    baseline: &BaselineConfig,
    methods: &[Method],
    lpips: Option<&LpipsVgg>,
    device: &Device,
    observer: &mut dyn Observer,
) -> Result<Evaluated, BittError> {
    let mut results = BTreeMap::new();
    let mut sheets = Vec::new();
    // BiTT trainings; the full one also yields the HTML baseline.
    let mut trainings: Vec<Method> = methods
        .iter()
        .copied()
        .filter(|m| m.bitt_config(config).is_some())
        .collect();
    if methods.contains(&Method::Html) && !trainings.contains(&Method::Bitt) {
        trainings.push(Method::Bitt);
    }
    trainings.sort();
    let mut context: Option<(Trainer, Truth, [Vec<bool>; 2])> = None;
    let mut bitt_textures = None;
    for m in trainings {
        let cfg = m.bitt_config(config).expect("BiTT variant");
        let started = Instant::now();
        let mut trainer = match (m, source.refined_trainer) {
            (Method::BittRefined, Some(refined)) => refined(&cfg)?,
            (Method::BittRefined, None) => {
                return Err(BittError::Invalid(
                    "this scene source offers no refined meshes".into(),
                ));
            }
            _ => (source.trainer)(&cfg)?,
        };
        trainer.train(None, observer)?;
        let outputs = trainer.forward()?;
        let avatar = Avatar::from_outputs(&trainer, &outputs)?;
        let seconds = started.elapsed().as_secs_f64();
        let visible = [
            avatar.visible[0].iter().map(|&v| v > 0.5).collect(),
            avatar.visible[1].iter().map(|&v| v > 0.5).collect(),
        ];
        let truth = (source.truth)(&trainer)?;
        if m == Method::Bitt {
            bitt_textures = Some((avatar.fine.clone(), visible.clone()));
        }
        let mut candidates = Vec::new();
        if methods.contains(&m) {
            candidates.push((m, avatar.fine.clone(), seconds, Some(avatar.coarse.clone())));
        }
        if m == Method::Bitt && methods.contains(&Method::Html) {
            candidates.push((Method::Html, avatar.coarse.clone(), 0.0, None));
        }
        for (method, textures, secs, prior) in candidates {
            let c = Candidate {
                textures,
                light: avatar.light,
                prior,
            };
            let (mut s, sheet) = score(&trainer, &truth, &c, &visible, source.gt_textures, lpips)?;
            s.seconds = secs;
            results.insert(method, s);
            sheets.push((method, sheet));
        }
        // The baselines train on the given meshes, never on the refined ones.
        if m != Method::BittRefined {
            context = Some((trainer, truth, visible));
        }
    }
    let baselines: Vec<(Method, Baseline)> = [
        (Method::HarpLike, Baseline::HarpLike),
        (Method::S2HandLike, Baseline::S2HandLike),
    ]
    .into_iter()
    .filter(|(m, _)| methods.contains(m))
    .collect();
    let (trainer, truth, visible) = match context {
        Some(c) => c,
        None => {
            let trainer = (source.trainer)(config)?;
            let truth = (source.truth)(&trainer)?;
            let visible = trainer
                .view
                .visible
                .clone()
                .map(|v| to_host(v.inner()).map(|x| x.iter().map(|&b| b > 0.5).collect()));
            let [l, r] = visible;
            (trainer, truth, [l?, r?])
        }
    };
    for (method, b) in baselines {
        let started = Instant::now();
        let out = run_baseline(&trainer, b, baseline, device)?;
        let seconds = started.elapsed().as_secs_f64();
        let c = Candidate {
            textures: out.textures,
            light: out.light,
            prior: None,
        };
        let (mut s, sheet) = score(&trainer, &truth, &c, &visible, source.gt_textures, lpips)?;
        s.seconds = seconds;
        results.insert(method, s);
        sheets.push((method, sheet));
    }
    Ok((results, sheets, visible, truth.firsts(), bitt_textures))
}
