//! An evaluation's scenes one after another: the synthetic benchmark's seeds and mesh
//! settings ([`evaluate_synthetic`]) or one InterHand2.6M scene per capture
//! ([`evaluate_interhand`]), this shard's only, each skipped when its result is already in
//! the folder and written there when done; [`run_evaluation`] is `bitt eval` from the
//! folder's plan to its merged tables.

use std::path::Path;

use bitt_mesh::HandPair;
use bitt_mesh::interhand::{InterHandDataset, InterHandSelection};
use bitt_synth::{MeshNoise, SynthConfig};
use bitt_texture::FitProgress;
use burn::tensor::Device;

use super::folder::{
    EvalPlan, interhand_scene_id, merge, pending, photo_scene_id, prepare_folder, result_path,
    shard_seeds, trainings_per_scene, write_scene,
};
use super::methods::{ContactSheets, evaluate_real_scene, evaluate_scene};
use super::photos::{
    Photo, PhotoNames, SceneTextures, photo_scenes, require_photo_files, write_scene_textures,
};
use super::{MeshSetting, Method, SceneResult};
use bitt::BittError;
use bitt::baselines::BaselineConfig;
use bitt::config::TrainConfig;
use bitt::lpips::LpipsVgg;
use bitt::real::{
    HandSource, PriorSource, RealScene, check_sources, interhand_views, load_models, real_trainer,
    sources,
};
use bitt::texture_model::texture_prior_with_progress;
use bitt::trainer::Observer;
use bitt_stdx::WithContext;

/// What an evaluation tells on the way; its trainings report each iteration through
/// [`Observer`].
pub trait EvalObserver: Observer {
    /// A line for the user.
    fn say(&mut self, line: &str);
    /// The work ahead: `iterations` BiTT iterations in all.
    fn plan(&mut self, iterations: usize);
    /// A scene starts; `label` names it.
    fn scene(&mut self, label: String);
    /// A progress display for fitting the procedural texture PCA.
    fn pca(&mut self) -> Box<dyn FitProgress>;
}

/// What every scene of an evaluation shares.
#[derive(Debug, Clone, Copy)]
pub struct EvalRun<'a> {
    /// The evaluation folder (`prepare_folder` done).
    pub out: &'a Path,
    /// Cache of generated scenes and fitted texture PCAs.
    pub cache: &'a Path,
    /// Every BiTT training's configuration.
    pub config: &'a TrainConfig,
    /// The baselines' configuration.
    pub baseline: &'a BaselineConfig,
    /// The methods.
    pub methods: &'a [Method],
    /// The mesh settings.
    pub settings: &'a [MeshSetting],
    /// LPIPS-VGG, when its weights are there.
    pub lpips: Option<&'a LpipsVgg>,
    /// This shard `(i, N)`: scene `k` belongs to shard `k % N`.
    pub shard: (usize, usize),
}

/// Evaluates the first `scenes` synthetic benchmark scenes (this shard's, in each mesh
/// setting) whose results are not in the folder yet, and writes each result.
///
/// # Errors
/// Generating a scene, training or scoring a method, or writing a result (naming the scene).
pub fn evaluate_synthetic(
    run: &EvalRun<'_>,
    scenes: usize,
    device: &Device,
    observer: &mut dyn EvalObserver,
) -> Result<(), BittError> {
    let (config, host) = (run.config, device.clone().inner());
    let seeds = shard_seeds(scenes, run.shard);
    let todo = pending(run.out, &seeds, run.settings);
    let skipped = seeds.len() * run.settings.len() - todo.len();
    if skipped > 0 {
        observer.say(&format!(
            "{skipped} scene result(s) already in {}: skipped",
            run.out.display()
        ));
    }
    let trainings = trainings_per_scene(run.methods, config);
    observer.plan(todo.len() * trainings * config.iterations);
    observer.say(&format!(
        "evaluating {} scene/setting pair(s), {} method(s), preset {} ({} iterations per BiTT training)",
        todo.len(),
        run.methods.len(),
        config.preset,
        config.iterations
    ));
    let progress = observer.pca();
    let pca = texture_prior_with_progress(config, Some(run.cache), &host, progress.as_ref())?;
    for (k, &(seed, setting)) in todo.iter().enumerate() {
        let synth = SynthConfig {
            mesh_noise: (setting == MeshSetting::NoisyMesh).then(MeshNoise::default),
            ..config.scene_config()
        };
        let scene = bitt_synth::cached_scene(&synth, seed, &run.cache.join("scenes"), &host)
            .context_with(|| format!("generating scene {seed:#x}"))?;
        observer.scene(format!(
            "[{}/{}] {seed:016x} {}",
            k + 1,
            todo.len(),
            setting.key()
        ));
        let (result, sheets) = evaluate_scene(
            &scene,
            setting,
            config,
            run.baseline,
            &pca,
            run.methods,
            run.lpips,
            device,
            &mut *observer,
        )
        .context_with(|| format!("scene {seed:#x} ({})", setting.key()))?;
        write_scene(
            run.out,
            &result,
            &scene.train.image,
            &sheets,
            config.nets.image_size,
        )?;
    }
    observer.say("");
    Ok(())
}

/// Real scenes have no true meshes to perturb: refuses a run whose settings leave out the
/// given meshes, saying `why`.
fn require_given_meshes(run: &EvalRun<'_>, why: &str) -> Result<(), BittError> {
    match run.settings.contains(&MeshSetting::GtMesh) {
        true => Ok(()),
        false => Err(BittError::Invalid(why.to_string())),
    }
}

/// [`evaluate_real_scene`] of a real scene with fresh trainers on its training view (the
/// InterHand2.6M and photo evaluations).
fn real_scene(
    run: &EvalRun<'_>,
    scene: &RealScene,
    id: u64,
    models: &HandPair,
    prior: &PriorSource,
    device: &Device,
    observer: &mut dyn EvalObserver,
) -> Result<(SceneResult, ContactSheets, Option<SceneTextures>), BittError> {
    let make = |cfg: &TrainConfig| {
        real_trainer(
            &scene.train.image,
            &scene.train.hands,
            models.clone(),
            prior,
            cfg.clone(),
            Some(run.cache),
            device,
        )
    };
    evaluate_real_scene(
        scene,
        id,
        &make,
        run.config,
        run.baseline,
        run.methods,
        run.lpips,
        device,
        observer,
    )
}

/// The InterHand2.6M scenes of an evaluation: the dataset, its split, the hands and texture
/// prior, and how many captures (`None`: all).
#[derive(Debug)]
pub struct InterHandScenes<'a> {
    /// The dataset's root.
    pub root: &'a Path,
    /// Its split.
    pub split: &'a str,
    /// The hand models.
    pub hands: HandSource,
    /// The texture prior.
    pub prior: PriorSource,
    /// How many captures with a usable scene (`None`: every one).
    pub scenes: Option<usize>,
}

/// Why InterHand2.6M is evaluated with its annotated meshes only.
const INTERHAND_MESHES_ONLY: &str = "--dataset interhand evaluates with the annotated meshes \
     only (Table 1a); the setting without them needs a mesh estimator such as IntagHand";

/// Evaluates one InterHand2.6M scene per capture (selected as `train-scene --interhand`
/// does; annotated meshes only, Table 1a), this shard's, skipping those with a result.
///
/// # Errors
/// A mesh setting other than the annotated meshes, an unreadable dataset, no capture with a
/// usable scene, or training, scoring or writing a scene (naming the capture).
pub fn evaluate_interhand(
    run: &EvalRun<'_>,
    data: &InterHandScenes<'_>,
    device: &Device,
    observer: &mut dyn EvalObserver,
) -> Result<(), BittError> {
    require_given_meshes(run, INTERHAND_MESHES_ONLY)?;
    let (root, split) = (data.root, data.split);
    let models = load_models(&data.hands, &data.prior)?;
    observer.say(&format!(
        "reading InterHand2.6M {split} annotations below {}",
        root.display()
    ));
    let dataset = InterHandDataset::open(root, split)?;
    observer.say(&format!("InterHand2.6M {split}: {}", dataset.counts));
    let captures = dataset.captures();
    let wanted = data.scenes.unwrap_or(captures.len());
    let (shard, shards) = run.shard;
    let size = run.config.nets.image_size;
    let trainings = trainings_per_scene(run.methods, run.config);
    observer.plan(wanted.min(captures.len()).div_ceil(shards) * trainings * run.config.iterations);
    let mut taken = 0;
    for capture in captures {
        if taken == wanted {
            break;
        }
        let selection = InterHandSelection {
            capture: Some(capture),
            ..InterHandSelection::default()
        };
        let scene = match dataset.select(&selection) {
            Ok(s) => s,
            Err(err) => {
                observer.say(&format!(
                    "capture {capture}: no usable scene ({err}); skipped"
                ));
                continue;
            }
        };
        let k = taken;
        taken += 1;
        if k % shards != shard {
            continue;
        }
        let (frame, camera) = (scene.train.entry.frame_idx, &scene.train.entry.camera);
        let id = interhand_scene_id(split, capture, frame, camera);
        let path = result_path(run.out, MeshSetting::GtMesh, id);
        if path.is_file() {
            observer.say(&format!(
                "capture {capture}: result exists ({}); skipped",
                path.display()
            ));
            continue;
        }
        let views = interhand_views(&scene, &models, size)
            .context_with(|| format!("capture {capture}: preparing its views"))?;
        observer.scene(format!(
            "[{}] capture {capture} frame {frame} cam {camera}",
            k + 1
        ));
        let (result, sheets, _) = real_scene(
            run,
            &views,
            id,
            &models,
            &data.prior,
            device,
            &mut *observer,
        )
        .context_with(|| format!("InterHand2.6M capture {capture}"))?;
        write_scene(run.out, &result, &views.train.image, &sheets, size)?;
    }
    observer.say("");
    if taken == 0 {
        return Err(BittError::Invalid(format!(
            "no capture under {} has a usable scene",
            root.display()
        )));
    }
    Ok(())
}

/// The photo benchmark's request.
#[derive(Debug)]
pub struct PhotoScenes<'a> {
    /// The photos (two or more, of the same hands).
    pub photos: &'a [Photo],
    /// The hand models.
    pub hands: HandSource,
    /// The texture prior.
    pub prior: PriorSource,
}

/// Evaluates every photo of `data` as the input view (this shard's, skipping those with a
/// result), scoring the others as its novel poses.
///
/// # Errors
/// A mesh setting other than the given meshes, fewer than two photos, an unreadable photo or
/// annotation, or training, scoring or writing a scene (naming the photo).
pub fn evaluate_photos(
    run: &EvalRun<'_>,
    data: &PhotoScenes<'_>,
    device: &Device,
    observer: &mut dyn EvalObserver,
) -> Result<(), BittError> {
    require_given_meshes(
        run,
        "--photos evaluates with the given meshes only (--mesh gt-mesh)",
    )?;
    let models = load_models(&data.hands, &data.prior)?;
    let size = run.config.nets.image_size;
    let scenes = photo_scenes(data.photos, &models, size)?;
    let (shard, shards) = run.shard;
    let trainings = trainings_per_scene(run.methods, run.config);
    let mine: Vec<usize> = (0..scenes.len()).filter(|k| k % shards == shard).collect();
    observer.plan(mine.len() * trainings * run.config.iterations);
    let names: Vec<String> = data.photos.iter().map(Photo::name).collect();
    for k in mine {
        let (photo, scene) = (&data.photos[k], &scenes[k]);
        let id = photo_scene_id(&photo.image);
        let path = result_path(run.out, MeshSetting::GtMesh, id);
        if path.is_file() {
            observer.say(&format!(
                "photo {}: result exists ({}); skipped",
                photo.image.display(),
                path.display()
            ));
            continue;
        }
        let others: Vec<&str> = (0..names.len())
            .filter(|&j| j != k)
            .map(|j| names[j].as_str())
            .collect();
        observer.scene(format!(
            "[{}/{}] trained on {}, scored on {}",
            k + 1,
            scenes.len(),
            names[k],
            others.join(", ")
        ));
        let (mut result, sheets, textures) =
            real_scene(run, scene, id, &models, &data.prior, device, &mut *observer)
                .context_with(|| format!("photo {}", photo.image.display()))?;
        result.photos = Some(PhotoNames {
            train: names[k].clone(),
            novel_poses: others.iter().map(|s| s.to_string()).collect(),
        });
        if let Some(textures) = &textures {
            write_scene_textures(run.out, id, textures)?;
        }
        write_scene(run.out, &result, &scene.train.image, &sheets, size)?;
    }
    observer.say("");
    Ok(())
}

/// Where `bitt eval`'s scenes come from.
#[derive(Debug, Clone, Copy)]
pub enum EvalSource<'a> {
    /// The synthetic benchmark.
    Synthetic,
    /// InterHand2.6M, one scene per capture.
    InterHand {
        /// The dataset's root (`None`: not given, refused once the folder is prepared).
        root: Option<&'a Path>,
        /// Its split.
        split: &'a str,
        /// MANO's folder (`None`: the procedural hands).
        model_dir: Option<&'a Path>,
        /// HTML's folder (`None`: the procedural texture PCA).
        html_dir: Option<&'a Path>,
        /// Every capture with a usable scene, rather than the first `scenes`.
        all: bool,
    },
    /// Photos of the same hands (`--photos`): each the input view once, the others its
    /// novel poses.
    Photos {
        /// The photos and their hands.
        photos: &'a [Photo],
        /// MANO's folder (`None`: the procedural hands).
        model_dir: Option<&'a Path>,
        /// HTML's folder (`None`: the procedural texture PCA).
        html_dir: Option<&'a Path>,
    },
}

/// `bitt eval`'s request: what every scene shares, how many scenes of which source, and
/// the LPIPS weights (`None`: the default weights when they exist).
#[derive(Debug, Clone, Copy)]
pub struct Evaluation<'a> {
    /// What every scene shares; its `lpips` is the one [`run_evaluation`] loads from
    /// `lpips` below.
    pub run: EvalRun<'a>,
    /// How many scenes.
    pub scenes: usize,
    /// LPIPS-VGG weights (`--lpips`).
    pub lpips: Option<&'a Path>,
    /// Where the scenes come from.
    pub source: EvalSource<'a>,
}

/// Runs `evaluation`: writes its plan into the folder, loads LPIPS (saying when there are no
/// weights), evaluates this shard's scenes that have no result yet on `device` (an autodiff
/// device), then merges the folder's results; returns the tables (`results.md`).
///
/// # Errors
/// The folder, the LPIPS weights, InterHand2.6M without a root, or any scene's evaluation.
pub fn run_evaluation(
    evaluation: &Evaluation<'_>,
    device: &Device,
    observer: &mut dyn EvalObserver,
) -> Result<String, BittError> {
    let e = evaluation;
    let dataset = match e.source {
        EvalSource::Synthetic => "synthetic".to_string(),
        EvalSource::InterHand { root, split, .. } => format!(
            "interhand {split} {}",
            root.map_or(String::new(), |r| r.display().to_string())
        ),
        EvalSource::Photos { photos, .. } => format!(
            "photos {}",
            photos
                .iter()
                .map(|p| format!("{}:{}", p.image.display(), p.annotation.display()))
                .collect::<Vec<_>>()
                .join(" ")
        ),
    };
    // The user's MANO and HTML folders are part of the plan: a folder evaluated with the
    // procedural models must not be resumed as theirs, nor the other way round.
    let models = match e.source {
        EvalSource::InterHand {
            model_dir,
            html_dir,
            ..
        }
        | EvalSource::Photos {
            model_dir,
            html_dir,
            ..
        } if model_dir.is_some() || html_dir.is_some() => {
            let (hands, prior) = sources(model_dir, html_dir);
            check_sources(&hands, &prior)?;
            Some(serde_json::json!({"hands": hands.absolute(), "prior": prior.absolute()}))
        }
        _ => None,
    };
    let plan = EvalPlan {
        train: e.run.config,
        baseline: e.run.baseline,
        methods: e.run.methods,
        settings: e.run.settings,
        scenes: e.scenes,
        dataset: &dataset,
        models: models.as_ref(),
    };
    // What can be refused from the options alone is, before the folder is touched.
    match e.source {
        EvalSource::Photos { photos, .. } => require_photo_files(photos)?,
        EvalSource::InterHand { .. } => require_given_meshes(&e.run, INTERHAND_MESHES_ONLY)?,
        EvalSource::Synthetic => {}
    }
    prepare_folder(e.run.out, &plan)?;
    let lpips = LpipsVgg::load_or_find(e.lpips, &device.clone().inner())?;
    if lpips.is_none() {
        observer.say("no LPIPS weights (see `bitt convert-lpips`): LPIPS is reported as n/a");
    }
    let run = EvalRun {
        lpips: lpips.as_ref(),
        ..e.run
    };
    match e.source {
        EvalSource::Synthetic => evaluate_synthetic(&run, e.scenes, device, observer)?,
        EvalSource::InterHand {
            root,
            split,
            model_dir,
            html_dir,
            all,
        } => {
            let root = root.ok_or_else(|| {
                BittError::Invalid(
                    "--dataset interhand needs --root (the InterHand2.6M folder)".into(),
                )
            })?;
            let (hands, prior) = sources(model_dir, html_dir);
            let data = InterHandScenes {
                root,
                split,
                hands,
                prior,
                scenes: (!all).then_some(e.scenes),
            };
            evaluate_interhand(&run, &data, device, observer)?;
        }
        EvalSource::Photos {
            photos,
            model_dir,
            html_dir,
        } => {
            let (hands, prior) = sources(model_dir, html_dir);
            let data = PhotoScenes {
                photos,
                hands,
                prior,
            };
            evaluate_photos(&run, &data, device, observer)?;
        }
    }
    merge(&[e.run.out.to_path_buf()])
}
