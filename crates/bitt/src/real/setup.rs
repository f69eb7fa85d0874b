//! Fresh real runs: an annotation, keypoint fit or InterHand2.6M scene turned into a trainer.

use std::path::Path;

use bitt_mesh::interhand::InterHandScene;
use bitt_mesh::{HandPair, Side, TwoHandScene};
use burn::tensor::Device;

use super::{
    HandSource, INPUT_FORMAT, PriorSource, RealInput, RealScene, RealSource, RealView, ViewRecord,
    absolute, annotation_view, check_hand_placement, interhand_views, load_models, prepare_view,
    texture_model,
};
use crate::BittError;
use crate::assets::{HandAssets, ViewGeometry};
use crate::config::TrainConfig;
use crate::refine::{MeshRefine, Refinement, refine_view, threshold_mask};
use crate::trainer::Trainer;
use bitt_stdx::WithContext;

/// What every fresh real run's setup shares ([`annotation_setup`], [`keypoint_setup`],
/// [`interhand_setup`]): where the hand models and the texture prior come from, the training
/// configuration, the cache of fitted texture PCAs, an optional mesh refinement of the
/// training view, and the device (an autodiff device).
#[derive(Debug)]
pub struct RealRunSettings<'a> {
    /// The hand models.
    pub hands: &'a HandSource,
    /// The texture prior.
    pub prior: &'a PriorSource,
    /// The training configuration (adapted to the prior; see the [module docs](super)).
    pub config: TrainConfig,
    /// Cache of fitted texture PCAs (`None`: fit every time).
    pub cache: Option<&'a Path>,
    /// A mesh refinement of the training view before training.
    pub refine: Option<MeshRefine<'a>>,
    /// The training device.
    pub device: &'a Device,
}

impl RealRunSettings<'_> {
    /// The trainer of the training view `image` of `hands` (refined first when asked; the
    /// refined hands replace `hands`), as [`refined_real_trainer`].
    fn trainer(
        self,
        image: &[f32],
        hands: &mut TwoHandScene,
        models: HandPair,
    ) -> Result<(Trainer, Option<Refinement>), BittError> {
        refined_real_trainer(
            image,
            hands,
            models,
            self.prior,
            self.config,
            self.cache,
            self.refine,
            self.device,
        )
    }
}

impl<'a> RealRunSettings<'a> {
    /// Settings without a cache or a refinement.
    pub fn new(
        hands: &'a HandSource,
        prior: &'a PriorSource,
        config: TrainConfig,
        device: &'a Device,
    ) -> Self {
        RealRunSettings {
            hands,
            prior,
            config,
            cache: None,
            refine: None,
            device,
        }
    }
}

/// A trainer for one prepared view: hand assets of `models` at the preset's texture size, the
/// prior of `prior` on their layout (the configuration adapted to it; see the
/// [module docs](super)). `device` must be an autodiff device.
pub fn real_trainer(
    view_image: &[f32],
    hands: &TwoHandScene,
    models: HandPair,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    device: &Device,
) -> Result<Trainer, BittError> {
    let mut hands = hands.clone();
    let (trainer, _) = refined_real_trainer(
        view_image, &mut hands, models, prior, config, cache, None, device,
    )?;
    Ok(trainer)
}

/// [`real_trainer`] that first refines the view's hands against its image when `refine` is
/// given (`hands` is replaced by the refined hands, same camera), returning the refinement.
#[allow(clippy::too_many_arguments)]
pub fn refined_real_trainer(
    view_image: &[f32],
    hands: &mut TwoHandScene,
    models: HandPair,
    prior: &PriorSource,
    mut config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<(Trainer, Option<Refinement>), BittError> {
    let s = config.nets.image_size;
    if [hands.camera.width, hands.camera.height] != [s as u32, s as u32] {
        return Err(BittError::Invalid(format!(
            "the training view is {}x{}; the {} preset needs {s}x{s}",
            hands.camera.width, hands.camera.height, config.preset
        )));
    }
    if config.loss.photo_mask > 0.0 {
        crate::input::check_photo_under_hands(view_image, hands, &models, config.loss.photo_mask)?;
    }
    let assets = HandAssets::new(models, config.texture.resolution)?;
    let pca = texture_model(&mut config, prior, &assets, cache, &device.clone().inner())?;
    let refinement = match refine {
        Some(r) => {
            let done = refine_view(
                &assets,
                &pca,
                hands,
                view_image,
                None,
                r.config,
                device,
                r.observer,
                "the training view",
            )?;
            *hands = done.hands.clone();
            Some(done)
        }
        None => None,
    };
    let geometry = ViewGeometry::new(&assets, hands, device)?
        .with_occlusion(&assets, config.loss.photo_occlusion)?;
    let threshold = config.loss.photo_mask;
    let one_colour_light = config.loss.photo_light;
    let light_search = config.loss.photo_light_search;
    let light_colours = config.loss.photo_light_colours;
    let prior_colour_gain = config.loss.photo_prior_colour;
    let mut trainer = Trainer::new(config, assets, &pca, geometry, view_image, None, device)?;
    if threshold > 0.0 {
        let keep: Vec<bool> = threshold_mask(view_image, s * s, threshold as f32)
            .iter()
            .map(|&m| m > 0.5)
            .collect();
        trainer.view.trust_photo(&keep)?;
    }
    trainer.view.one_colour_light = one_colour_light;
    trainer.view.prior_colour_gain = prior_colour_gain;
    if light_search {
        let found = trainer.search_light_location()?;
        trainer.view.light_location = Some(found.location);
        if light_colours {
            trainer.view.light_colours = Some([found.ambient, found.diffuse]);
        }
    }
    Ok((trainer, refinement))
}

/// Everything a fresh real run starts from: the record, the prepared views and the trainer.
#[derive(Debug)]
pub struct RealSetup {
    /// What `input.json` will hold.
    pub input: RealInput,
    /// The prepared views (novel views and poses empty for a single annotation).
    pub scene: RealScene,
    /// The trainer (its `config` possibly adapted to the prior).
    pub trainer: Trainer,
    /// The mesh refinement of the training view, when asked for (its hands are the view's).
    pub refinement: Option<Refinement>,
}

/// A fresh real run from an image and its BiTT annotation pickle.
pub fn annotation_setup(
    image: &Path,
    annotation: &Path,
    settings: RealRunSettings<'_>,
) -> Result<RealSetup, BittError> {
    let models = load_models(settings.hands, settings.prior)?;
    let view = annotation_view(image, annotation, &models, settings.config.nets.image_size)?;
    let source = RealSource::Annotation {
        image: absolute(image),
        annotation: absolute(annotation),
    };
    single_view_setup(view, source, image, models, settings)
}

/// The setup of a run on one prepared view (`image` is its photo).
fn single_view_setup(
    mut view: RealView,
    source: RealSource,
    image: &Path,
    models: HandPair,
    settings: RealRunSettings<'_>,
) -> Result<RealSetup, BittError> {
    let (hands, prior) = (settings.hands, settings.prior);
    let (trainer, refinement) = settings
        .trainer(&view.image, &mut view.hands, models)
        .context_with(|| format!("training on {}", image.display()))?;
    Ok(RealSetup {
        refinement,
        input: RealInput {
            format: INPUT_FORMAT.into(),
            source,
            hands: hands.absolute(),
            prior: prior.absolute(),
            train: ViewRecord {
                source: absolute(image),
                ..ViewRecord::from(&view)
            },
            novel_views: Vec::new(),
            novel_poses: Vec::new(),
        },
        scene: RealScene {
            train: view,
            novel_views: Vec::new(),
            novel_poses: Vec::new(),
        },
        trainer,
    })
}

/// A fresh real run from a photo whose hands were fitted to its keypoints
/// ([`crate::fit::fit_photo`]; `fit.image` is the photo as fitted): those of the file
/// `keypoints`, or with `None` those the built-in detector found in the photo.
///
/// # Errors
/// A fit without both hands, hands outside the image; as [`real_trainer`].
pub fn keypoint_setup(
    fit: &crate::fit::PhotoFit,
    image: &Path,
    keypoints: Option<&Path>,
    settings: RealRunSettings<'_>,
) -> Result<RealSetup, BittError> {
    // What the keypoints' problems are named by: their file, else the photo.
    let named = keypoints.unwrap_or(image);
    for side in Side::BOTH {
        if fit.hands.hand(side).is_none() {
            let points = match side {
                Side::Left => &fit.keypoints.left,
                Side::Right => &fit.keypoints.right,
            };
            let why = match (points, keypoints) {
                (None, Some(_)) => format!("the file has no {side} hand"),
                (None, None) => format!("no {side} hand was found in the photo"),
                (Some(_), _) => format!("the {side} hand has too few keypoints to be fitted"),
            };
            return Err(BittError::Invalid(format!(
                "{}: {why}; BiTT needs both hands",
                named.display()
            )));
        }
    }
    let models = fit.models.clone();
    check_hand_placement(&fit.hands, &models, named)?;
    let view = prepare_view(
        "train",
        image,
        fit.image.clone(),
        &fit.hands,
        &models,
        settings.config.nets.image_size,
    )?;
    let source = match keypoints {
        Some(keypoints) => RealSource::Keypoints {
            image: absolute(image),
            keypoints: absolute(keypoints),
            mirrored: fit.mirrored,
        },
        None => RealSource::Detected {
            image: absolute(image),
        },
    };
    single_view_setup(view, source, image, models, settings)
}

/// A fresh real run from a selected InterHand2.6M scene.
pub fn interhand_setup(
    scene: &InterHandScene,
    paths: &bitt_mesh::interhand::InterHandPaths,
    settings: RealRunSettings<'_>,
) -> Result<RealSetup, BittError> {
    let (hands, prior) = (settings.hands, settings.prior);
    let models = load_models(hands, prior)?;
    let mut views = interhand_views(scene, &models, settings.config.nets.image_size)?;
    let train_photo = views.train.source.clone();
    let (trainer, refinement) = settings
        .trainer(&views.train.image, &mut views.train.hands, models)
        .context_with(|| format!("training on {}", train_photo.display()))?;
    let record = |v: &RealView| ViewRecord {
        source: absolute(&v.source),
        ..ViewRecord::from(v)
    };
    Ok(RealSetup {
        refinement,
        input: RealInput {
            format: INPUT_FORMAT.into(),
            source: RealSource::InterHand {
                root: absolute(&paths.root),
                split: paths.split.clone(),
                capture: scene.capture,
                frame: scene.train.entry.frame_idx,
                camera: scene.train.entry.camera.clone(),
            },
            hands: hands.absolute(),
            prior: prior.absolute(),
            train: record(&views.train),
            novel_views: views.novel_views.iter().map(record).collect(),
            novel_poses: views.novel_poses.iter().map(record).collect(),
        },
        scene: views,
        trainer,
    })
}
