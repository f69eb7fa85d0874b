//! `train-scene`'s job as library calls: what a fresh run trains on ([`fresh_run`]: a
//! synthetic scene, a photo with its annotation or keypoints or alone, an InterHand2.6M
//! scene), a
//! resumed run's trainer ([`resumed_run`]) and the results written when training ends
//! ([`finish_run`]).

use std::path::{Path, PathBuf};

use bitt_mesh::PinholeCamera;
use bitt_mesh::interhand::{InterHandDataset, InterHandSelection};
use bitt_mesh::keypoints::{KeypointOptions, read_keypoints};
use bitt_synth::SynthScene;
use bitt_texture::{FitProgress, TexturePca};
use burn::tensor::Device;

use crate::BittError;
use crate::assets::HandAssets;
use crate::config::TrainConfig;
use crate::config_files::fit_config;
use crate::files;
use crate::fit::FitOutput;
use crate::fit::{
    FitObserver, KeypointSource, PhotoKeypoints, fit_keypoints, fit_photo, parse_intrinsics,
    record_synthetic_fit,
};
use crate::real::{
    HandSource, PriorSource, RealInput, RealRunSettings, RealScores, annotation_setup,
    interhand_setup, keypoint_setup, score_real,
};
use crate::refine::{
    MeshRefine, RefineConfig, RefineObserver, Refinement, pca_pose_notes, refine_synthetic,
};
use crate::run::{RunSummary, synthetic_trainer, write_run};
use crate::run_folder::{
    RunInput, has_checkpoint, is_finished_run, load_checkpoints, missing_input, write_fresh_run,
};
use crate::texture_model::texture_prior_with_progress;
use crate::trainer::Trainer;
use bitt_stdx::WithContext;

/// What the setup of a run tells on the way: lines for the user, and progress displays for
/// its long steps (each call gives a new one).
pub trait SetupObserver {
    /// A line for the user (a step begins, a note on the input); `""` ends a progress line.
    fn say(&mut self, line: &str);
    /// A progress display for a mesh refinement.
    fn refine(&mut self) -> Box<dyn RefineObserver>;
    /// A progress display for a keypoint fit.
    fn fit(&mut self) -> Box<dyn FitObserver>;
    /// A progress display for fitting the procedural texture PCA.
    fn pca(&mut self) -> Box<dyn FitProgress>;
}

/// The keypoints both hands are fitted to before training (`--keypoints`).
#[derive(Debug, Clone)]
pub struct KeypointInput {
    /// The keypoint file, its format and whether the photo is mirrored.
    pub source: KeypointSource,
    /// Camera intrinsics `fx,fy,cx,cy` in pixels, as text (`None`: the default, or a synthetic
    /// scene's true camera).
    pub intrinsics: Option<String>,
    /// The fit's configuration file (`None`: the default configuration).
    pub config: Option<PathBuf>,
}

impl KeypointInput {
    /// The intrinsics, parsed.
    fn intrinsics(&self) -> Result<Option<[f64; 4]>, BittError> {
        self.intrinsics.as_deref().map(parse_intrinsics).transpose()
    }
}

/// What a fresh run trains on.
#[derive(Debug, Clone)]
pub enum SceneInput<'a> {
    /// A synthetic scene folder (`None`: the built-in demo scene, generated and cached),
    /// with keypoints of its training view that its hands are fitted to.
    Synthetic {
        /// The scene folder.
        scene: Option<&'a Path>,
        /// Keypoints of the training view.
        keypoints: Option<KeypointInput>,
    },
    /// A photo of two hands with their 2D keypoints (and a hand mask to refine against).
    PhotoKeypoints {
        /// The photo.
        image: &'a Path,
        /// Its keypoints.
        keypoints: KeypointInput,
        /// Its hand mask (white = hand).
        mask: Option<&'a Path>,
    },
    /// A photo of two hands alone: both are found by the built-in detector, fitted to its
    /// keypoints and refined against the photo (its hand mask, else the threshold rule).
    Photo {
        /// The photo.
        image: &'a Path,
        /// Its hand mask (white = hand).
        mask: Option<&'a Path>,
        /// The keypoint fit's configuration file (`None`: the default configuration).
        fit: Option<PathBuf>,
        /// Camera intrinsics `fx,fy,cx,cy` in pixels, as text (`None`: the default camera).
        intrinsics: Option<String>,
        /// The refinement's configuration.
        refine: RefineConfig,
    },
    /// A photo of two hands with its annotation (a BiTT pickle or `hands.json`).
    PhotoAnnotation {
        /// The photo.
        image: &'a Path,
        /// Its annotation.
        annotation: &'a Path,
    },
    /// A scene of InterHand2.6M.
    InterHand {
        /// The dataset's root.
        root: &'a Path,
        /// Its split.
        split: &'a str,
        /// Which capture, frame, camera, novel views and novel poses.
        selection: InterHandSelection,
    },
}

/// A fresh run's request: its input, the hands and texture prior of real data, an optional
/// mesh refinement before training, and the cache folder.
#[derive(Debug, Clone)]
pub struct FreshRequest<'a> {
    /// What the run trains on.
    pub input: SceneInput<'a>,
    /// The hand models of real data.
    pub hands: HandSource,
    /// The texture prior of real data.
    pub prior: PriorSource,
    /// Refine the given meshes against the training image before training.
    pub refine: Option<RefineConfig>,
    /// Cache of the demo scene and the fitted texture PCA.
    pub cache: &'a Path,
}

/// What a fresh run starts from: its trainer, its input, and the refinement and keypoint
/// fit made before training.
#[derive(Debug)]
pub(crate) struct FreshRun {
    /// The trainer at iteration 0.
    pub trainer: Trainer,
    /// The run's input.
    pub input: RunInput,
    /// The mesh refinement, when asked for.
    pub refinement: Option<Refinement>,
    /// The keypoint fit, with keypoints.
    pub fit: Option<FitOutput>,
}

/// The line a photo-only run ([`SceneInput::Photo`]) starts with.
pub(crate) const PHOTO_ONLY_LINE: &str = "photo only: detecting both hands, fitting them to the keypoints, refining against the photo, then training";

/// The procedural texture PCA of `config.texture`, from the cache or fitted (with a progress
/// display) and cached.
///
/// # Errors
/// Reading or writing the cache.
pub(crate) fn procedural_prior(
    config: &TrainConfig,
    cache: Option<&Path>,
    device: &Device,
    observer: &mut dyn SetupObserver,
) -> Result<TexturePca, BittError> {
    observer.say(&format!(
        "fitting / loading the texture PCA ({} components)",
        config.texture.components
    ));
    let progress = observer.pca();
    texture_prior_with_progress(config, cache, &device.clone().inner(), progress.as_ref())
}

/// Reads and checks every input of a fresh run and builds its trainer (fitting keypoints and
/// refining meshes first when asked); writes nothing.
///
/// # Errors
/// Any input that cannot be read or is not what it should be, naming it.
pub(crate) fn fresh_run(
    request: &FreshRequest<'_>,
    config: TrainConfig,
    device: &Device,
    observer: &mut dyn SetupObserver,
) -> Result<FreshRun, BittError> {
    let cache = Some(request.cache);
    let (hands, prior) = (&request.hands, &request.prior);
    if matches!(request.input, SceneInput::Synthetic { .. })
        && (*hands != HandSource::Procedural || *prior != PriorSource::Procedural)
    {
        return Err(BittError::Invalid(
            "--model-dir and --html-dir apply to real data: give --image IMG --annotation PKL \
             or --interhand ROOT"
                .into(),
        ));
    }
    let mut bar = observer.refine();
    let mut refine = request.refine.as_ref().map(|config| MeshRefine {
        config,
        observer: bar.as_mut(),
    });
    // What every real-data setup takes besides its input.
    let real_settings = |config, refine| RealRunSettings {
        hands,
        prior,
        config,
        cache,
        refine,
        device,
    };
    let real = |setup: crate::real::RealSetup, fit| FreshRun {
        trainer: setup.trainer,
        input: RunInput::Real(Box::new(setup.input), Box::new(setup.scene)),
        refinement: setup.refinement,
        fit,
    };
    match &request.input {
        SceneInput::PhotoKeypoints {
            image,
            keypoints,
            mask,
        } => {
            let path = &keypoints.source.path;
            observer.say(&format!(
                "real data: {} with the keypoints {} (fitting both hands to them first)",
                image.display(),
                path.display()
            ));
            let fit_settings = fit_config(keypoints.config.as_deref())?;
            let mask_refine = RefineConfig::default();
            let mut mask_bar = observer.refine();
            let mask_observer: &mut dyn RefineObserver = mask_bar.as_mut();
            let mut fit_bar = observer.fit();
            let fit = fit_photo(
                image,
                PhotoKeypoints::File(&keypoints.source),
                keypoints.intrinsics()?,
                *mask,
                hands,
                prior,
                &fit_settings,
                mask.map(|_| (&config, &mask_refine, mask_observer)),
                cache,
                device,
                fit_bar.as_mut(),
            )
            .context_with(|| {
                format!(
                    "fitting --image {} --keypoints {}",
                    image.display(),
                    path.display()
                )
            })?;
            observer.say("");
            for n in &fit.fit.report.notes {
                observer.say(&format!("note: {n}"));
            }
            let settings = real_settings(config, refine.take());
            let setup = keypoint_setup(&fit, image, Some(path), settings)?;
            let output = FitOutput {
                record: fit.record(),
                overlay: fit.overlay.clone(),
                detection: None,
            };
            Ok(real(setup, Some(output)))
        }
        SceneInput::Photo {
            image,
            mask,
            fit,
            intrinsics,
            refine: photo_refine,
        } => {
            let intrinsics = intrinsics
                .as_deref()
                .map(crate::fit::parse_intrinsics)
                .transpose()?;
            observer.say(PHOTO_ONLY_LINE);
            let found = crate::detect::detect_photo(image, device)?;
            for line in found.lines() {
                observer.say(&line);
            }
            observer.say(&format!("detected in {:.2} s", found.seconds));
            found.detection.require_both(image)?;
            let fit_settings = fit_config(fit.as_deref())?;
            let mut mask_bar = observer.refine();
            let mut fit_bar = observer.fit();
            let done = fit_photo(
                image,
                PhotoKeypoints::Detected(Box::new(found)),
                intrinsics,
                *mask,
                hands,
                prior,
                &fit_settings,
                Some((&config, photo_refine, mask_bar.as_mut())),
                cache,
                device,
                fit_bar.as_mut(),
            )
            .context_with(|| {
                format!(
                    "fitting the hands detected in --image {} and refining them",
                    image.display()
                )
            })?;
            observer.say("");
            for n in &done.fit.report.notes {
                observer.say(&format!("note: {n}"));
            }
            for h in &done.fit.report.hands {
                observer.say(&format!(
                    "fitted the {} hand: residual {:.2} px mean ({:.2} max)",
                    h.side, h.mean_residual_px, h.max_residual_px
                ));
            }
            if let Some(r) = &done.refinement {
                observer.say(&format!(
                    "refined against the photo ({}): silhouette IoU {:.4} -> {:.4}",
                    r.mask_source, r.iou_before, r.iou_after
                ));
            }
            let settings = real_settings(config, refine.take());
            let setup = keypoint_setup(&done, image, None, settings)?;
            let output = FitOutput {
                record: done.record(),
                overlay: done.overlay.clone(),
                detection: done.detection.clone(),
            };
            Ok(real(setup, Some(output)))
        }
        SceneInput::PhotoAnnotation { image, annotation } => {
            observer.say(&format!(
                "real data: {} with {} ({} hands, {} texture prior)",
                image.display(),
                annotation.display(),
                match hands {
                    HandSource::Mano { .. } => "MANO",
                    HandSource::Procedural => "procedural",
                },
                match prior {
                    PriorSource::Html { .. } => "HTML",
                    PriorSource::Procedural => "procedural PCA",
                },
            ));
            let settings = real_settings(config, refine.take());
            let setup = annotation_setup(image, annotation, settings).context_with(|| {
                format!(
                    "real data --image {} --annotation {}",
                    image.display(),
                    annotation.display()
                )
            })?;
            if setup.refinement.is_none() {
                for n in pca_pose_notes(
                    &setup.trainer.assets.models,
                    &setup.input.train.hands,
                    "its fingers are posed by meaningless numbers (add --refine-mesh to fit them to the photo)",
                ) {
                    observer.say(&format!("note: {n}"));
                }
            }
            Ok(real(setup, None))
        }
        SceneInput::InterHand {
            root,
            split,
            selection,
        } => {
            observer.say(&format!(
                "reading InterHand2.6M {split} annotations below {}",
                root.display()
            ));
            let dataset = InterHandDataset::open(root, split)?;
            observer.say(&format!("InterHand2.6M {split}: {}", dataset.counts));
            let scene = dataset.select(selection)?;
            observer.say(&format!(
                "selected capture {}, frame {}, camera {} ({} novel views, {} novel poses)",
                scene.capture,
                scene.train.entry.frame_idx,
                scene.train.entry.camera,
                scene.novel_views.len(),
                scene.novel_poses.len()
            ));
            let settings = real_settings(config, refine.take());
            let setup = interhand_setup(&scene, &dataset.paths, settings)?;
            Ok(real(setup, None))
        }
        SceneInput::Synthetic { scene, keypoints } => {
            let mut scene = match scene {
                Some(dir) => {
                    SynthScene::read(dir).context_with(|| format!("--scene {}", dir.display()))?
                }
                None => {
                    observer.say(&format!(
                        "building the demo scene (synthetic generator, cached in {})",
                        request.cache.display()
                    ));
                    bitt_synth::cached_scene(
                        &config.scene_config(),
                        bitt_synth::demo_scene_seed(),
                        &request.cache.join("scenes"),
                        &device.clone().inner(),
                    )?
                }
            };
            let fit = match keypoints {
                Some(k) => Some(fit_synthetic(&mut scene, k, device, observer)?),
                None => None,
            };
            let pca = procedural_prior(&config, cache, device, observer)?;
            let refinement = match refine {
                Some(r) => {
                    observer.say("refining the given meshes against the training image");
                    let assets =
                        HandAssets::new(bitt_mesh::procedural_pair(), config.texture.resolution)?;
                    let done = refine_synthetic(
                        &scene,
                        &assets,
                        &pca,
                        config.nets.image_size,
                        r.config,
                        device,
                        r.observer,
                    )?;
                    scene.given = done.hands.clone();
                    Some(done)
                }
                None => None,
            };
            let trainer = synthetic_trainer(&scene, &config, &pca, device)?;
            Ok(FreshRun {
                trainer,
                input: RunInput::Synthetic(Box::new(scene)),
                refinement,
                fit,
            })
        }
    }
}

/// Fits a synthetic scene's hands to `keypoints` of its training image (the scene's true
/// camera, or the given intrinsics) and makes them the scene's given meshes.
fn fit_synthetic(
    scene: &mut SynthScene,
    keypoints: &KeypointInput,
    device: &Device,
    observer: &mut dyn SetupObserver,
) -> Result<FitOutput, BittError> {
    let path = &keypoints.source.path;
    if keypoints.source.mirrored {
        return Err(BittError::Invalid(
            "--mirrored applies to photos, not to a synthetic scene".into(),
        ));
    }
    let truth = scene.train.hands.camera;
    let options = KeypointOptions {
        format: keypoints.source.format,
        image_size: [truth.width, truth.height],
        labels_as_is: keypoints.source.labels_as_is,
    };
    let points = read_keypoints(path, &options)?;
    let camera = match keypoints.intrinsics()? {
        Some([fx, fy, cx, cy]) => PinholeCamera {
            intrinsics: PinholeCamera::from_intrinsics(
                [fx, fy],
                [cx, cy],
                truth.width,
                truth.height,
            )?
            .intrinsics,
            ..truth
        },
        None => truth,
    };
    observer.say(&format!(
        "fitting both hands to the keypoints {} of the scene's training image",
        path.display()
    ));
    let models = bitt_mesh::procedural_pair();
    let mut bar = observer.fit();
    let fit = fit_keypoints(
        &models,
        &points,
        &camera,
        &fit_config(keypoints.config.as_deref())?,
        device,
        bar.as_mut(),
    )
    .context_with(|| format!("fitting --keypoints {}", path.display()))?;
    observer.say("");
    for n in &fit.report.notes {
        observer.say(&format!("note: {n}"));
    }
    if fit.hands.left.is_none() || fit.hands.right.is_none() {
        return Err(BittError::Invalid(format!(
            "{}: a hand has too few keypoints to be fitted; BiTT needs both",
            path.display()
        )));
    }
    let (scores, output) = record_synthetic_fit(&fit, scene, &points, &camera, path)?;
    observer.say(&format!(
        "fitted in {:.1} s: 2D joints {:.2} px, root-relative 3D joints {:.1} mm from the truth",
        fit.report.seconds, scores.joint_2d_px, scores.joint_3d_mm
    ));
    Ok(output)
}

/// A resumed run's trainer (its last usable checkpoint restored) and input; `iterations`
/// replaces the run's total.
///
/// # Errors
/// The run's configuration, input or checkpoints are missing or corrupt, or `iterations`
/// ends before the checkpoint.
pub fn resumed_run(
    dir: &Path,
    iterations: Option<usize>,
    cache: &Path,
    device: &Device,
    observer: &mut dyn SetupObserver,
) -> Result<(Trainer, RunInput), BittError> {
    let path = dir.join(files::CONFIG);
    let text = std::fs::read_to_string(&path)
        .context_with(|| format!("--resume {}: cannot read {}", dir.display(), path.display()))?;
    let mut config = TrainConfig::from_json(&text, &path)?;
    if let Some(n) = iterations {
        config.iterations = n;
        config.validate()?;
    }
    // The run's input: `input.json` for real data, `scene/` for a synthetic scene.
    let real = RealInput::is_real_run(dir);
    if let Some(missing) = missing_input(dir) {
        return Err(BittError::Invalid(format!(
            "--resume {}: {missing}",
            dir.display()
        )));
    }
    if !has_checkpoint(dir) && is_finished_run(dir) {
        return Err(BittError::Invalid(format!(
            "--resume {}: the run is finished and its checkpoints were removed at its end \
             (`train-scene --keep-checkpoints` keeps the latest); its results are all there, and \
             training longer needs a new run with more --iterations",
            dir.display()
        )));
    }
    let (checkpoint, previous, warnings) = load_checkpoints(dir)
        .context_with(|| format!("--resume {}: no usable checkpoint", dir.display()))?;
    for w in warnings {
        observer.say(&format!("warning: {w}"));
    }
    // Temporaries of writes a killed process never finished (it is a run folder of ours).
    for path in bitt_stdx::remove_stale_temporaries(dir)? {
        observer.say(&format!(
            "removed {}, left by an interrupted write",
            path.display()
        ));
    }
    if let Some(n) = iterations
        && n < checkpoint.iteration
    {
        return Err(BittError::Invalid(format!(
            "--resume {}: the run is already at iteration {}; --iterations {n} would end before \
             it (give at least {})",
            dir.display(),
            checkpoint.iteration,
            checkpoint.iteration
        )));
    }
    let cache = Some(cache);
    let (mut trainer, input) = if real {
        let (input, scene, trainer) = RealInput::resume_trainer(dir, config, cache, device)
            .context_with(|| format!("--resume {}: the run's real input", dir.display()))?;
        (trainer, RunInput::Real(Box::new(input), Box::new(scene)))
    } else {
        let scene = SynthScene::read(&dir.join(files::SCENE))
            .context_with(|| format!("--resume {}: the run's scene", dir.display()))?;
        let pca = procedural_prior(&config, cache, device, observer)?;
        let trainer = synthetic_trainer(&scene, &config, &pca, device)?;
        (trainer, RunInput::Synthetic(Box::new(scene)))
    };
    trainer.resume_from(&checkpoint, previous)?;
    observer.say(&format!(
        "resuming at iteration {} of {}",
        checkpoint.iteration, trainer.config.iterations
    ));
    Ok((trainer, input))
}

/// A fresh run in `out`: its inputs read and checked and its trainer built ([`fresh_run`]),
/// then its folder created with its first files ([`write_fresh_run`]); the refinement's
/// notes and result are told to `observer`.
///
/// # Errors
/// Any input that cannot be read or is not what it should be (nothing is written then), or
/// a file that cannot be written.
pub fn start_fresh(
    out: &Path,
    request: &FreshRequest<'_>,
    config: TrainConfig,
    device: &Device,
    observer: &mut dyn SetupObserver,
) -> Result<(Trainer, RunInput), BittError> {
    // Every input is read and checked (and the trainer built) before the run folder is
    // created, so a bad input leaves nothing behind.
    let FreshRun {
        trainer,
        input,
        refinement,
        fit,
    } = fresh_run(request, config, device, observer)?;
    write_fresh_run(out, &trainer, &input, fit.as_ref(), refinement.as_ref())?;
    if let Some(r) = &refinement {
        for n in &r.report.notes {
            observer.say(&format!("note: {n}"));
        }
        observer.say(&format!(
            "refined the meshes in {:.1} s: silhouette IoU against the hand mask {:.4} -> {:.4}",
            r.report.seconds, r.report.iou_before, r.report.iou_after
        ));
    }
    Ok((trainer, input))
}

/// The line that says what a training is about to do.
pub fn training_line(trainer: &Trainer) -> String {
    let config = &trainer.config;
    let [lv, rv] = trainer.view.visible_fraction();
    format!(
        "training {} iterations ({} preset, {} texels per hand, {} texture components, visible {:.0}% / {:.0}%)",
        config.iterations,
        config.preset,
        trainer.assets.num_texels(),
        config.nets.html.coefficients_per_hand,
        100.0 * lv,
        100.0 * rv
    )
}

/// The error of a run whose training gave up (`error`) but whose results, those of
/// `iteration`, were written into `out`.
pub fn unfinished_error(error: &dyn std::fmt::Display, out: &Path, iteration: usize) -> BittError {
    BittError::Invalid(format!(
        "training did not finish: {error}. The results in {} are those of iteration {iteration}; \
         `--resume {}` continues from there at the lowered learning rate",
        out.display(),
        out.display()
    ))
}

/// The summary of a finished run for the user: where its results are, its timings and
/// input-view PSNR, the novel views' and poses' scores (against the ground truth or the
/// photographs), and a synthetic run's texture errors; `wall` is the whole command's seconds.
pub fn summary_lines(
    out: &Path,
    s: &RunSummary,
    real: Option<&RealScores>,
    wall: f64,
) -> Vec<String> {
    let mut lines = vec![
        format!(
            "results in {}/ (open {}/report.html)",
            out.display(),
            out.display()
        ),
        format!(
            "{} iterations, {:.1} s training, {:.1} s wall clock; input-view PSNR {:.2} dB",
            s.iterations, s.seconds, wall, s.input_psnr
        ),
    ];
    let means = match (&s.synthetic, real) {
        (Some(g), _) => Some((&g.novel_views, &g.novel_poses)),
        (None, Some(r)) => Some((&r.novel_views, &r.novel_poses)),
        _ => None,
    };
    if let Some((views, poses)) = means {
        let against = if real.is_some() { " (photographs)" } else { "" };
        for (name, m) in [("novel views", views), ("novel poses", poses)] {
            if let Some(m) = m {
                lines.push(format!(
                    "{name} ({}){against}: PSNR fine {:.2} dB vs coarse {:.2} dB; SSIM fine {:.4} vs coarse {:.4}",
                    m.count, m.fine.psnr, m.coarse.psnr, m.fine.ssim, m.coarse.ssim
                ));
            }
        }
    }
    if let Some(t) = s.synthetic.as_ref().and_then(|g| g.texture.as_ref()) {
        let f = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4}"));
        let (fine, coarse) = (&t.fine.gain_fitted, &t.coarse.gain_fitted);
        lines.push(format!(
            "texture L1 after a gain per channel, texels invisible in the input: fine {} vs coarse {} \
             (visible on the other hand: fine {} vs coarse {}; invisible on both: fine {} vs coarse {}); \
             raw: fine {} vs coarse {}",
            f(fine.not_visible),
            f(coarse.not_visible),
            f(fine.symmetric),
            f(coarse.symmetric),
            f(fine.invisible),
            f(coarse.invisible),
            f(t.fine.raw.not_visible),
            f(t.coarse.raw.not_visible),
        ));
    }
    lines
}

/// Writes a trained run's results into `out` ([`write_run`]) and, for real data with novel
/// views or poses, scores them against the photographs (`real_scores.json`).
///
/// # Errors
/// Rendering, scoring or writing the results.
pub fn finish_run(
    out: &Path,
    trainer: &Trainer,
    input: &RunInput,
    turntable: usize,
) -> Result<(RunSummary, Option<RealScores>), BittError> {
    let clip = input.novel_pose_clip();
    let summary = write_run(out, trainer, input.synthetic(), turntable, &clip)?;
    let real_scores = match input {
        RunInput::Real(_, scene)
            if !(scene.novel_views.is_empty() && scene.novel_poses.is_empty()) =>
        {
            let scores = score_real(trainer, scene)?;
            crate::run::write_real_scores(out, &scores)?;
            Some(scores)
        }
        _ => None,
    };
    Ok((summary, real_scores))
}
