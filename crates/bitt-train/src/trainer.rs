//! The per-scene trainer (paper Sec. 4.1): fresh networks, Adam, the step schedule,
//! atomic checkpoints, exact resumption, and recovery from non-finite losses.

use std::path::Path;
use std::time::Instant;

use bitt_nets::BittNets;
use bitt_render::scene::RenderSettings;
use bitt_texture::{TexturePca, TexturePcaTensors};
use burn::tensor::{Device, Tensor, TensorData};

use crate::TrainError;
use crate::assets::{HandAssets, ViewGeometry};
use crate::checkpoint::Checkpoint;
use crate::config::TrainConfig;
use crate::losses::{LossTerms, loss};
use crate::optim::{Adam, load_parameters, parameters_host};
use crate::pipeline::{Outputs, TrainingView, forward};
use bitt_stdx::FileErrorExt;
use bitt_stdx::to_host;

/// Non-finite losses tolerated in one run before giving up.
pub const MAX_NON_FINITE: usize = 8;

/// Held while networks are initialised, which draws from the host backend's one random
/// generator (see [`Trainer::new`]). Anything else in the process that draws from flex's
/// generator (a module's random init in a test) holds it too: flex's generator is one
/// `take`-and-put-back state, so a draw on another thread mid-initialisation shifts the
/// networks' weights.
pub static NETS_INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The factor on the learning rate at every recovery from a non-finite loss.
pub(crate) const RECOVERY_LR_FACTOR: f64 = 0.5;

/// A state the trainer can go back to. A checkpoint is written right after a step, from
/// weights no forward pass has tried yet; it is `verified` once a step from it gave a finite
/// loss. An unverified state whose own forward pass is not finite is dropped, and the trainer
/// goes back to the one before it (always verified).
#[derive(Debug, Clone)]
struct Snapshot {
    checkpoint: Checkpoint,
    verified: bool,
}

/// The file next to `checkpoint` that keeps the checkpoint before it
/// (`checkpoint.safetensors` -> `checkpoint.previous.safetensors`).
pub fn previous_checkpoint_path(checkpoint: &Path) -> std::path::PathBuf {
    let stem = checkpoint
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "checkpoint".into());
    let ext = checkpoint
        .extension()
        .map(|s| format!(".{}", s.to_string_lossy()))
        .unwrap_or_default();
    checkpoint.with_file_name(format!("{stem}.previous{ext}"))
}

/// Keeps the current checkpoint file as the previous one before a new one replaces it: a
/// hard link moved into place atomically (a copy where links are not supported).
fn keep_as_previous(path: &Path) -> Result<(), TrainError> {
    if !path.is_file() {
        return Ok(());
    }
    let previous = previous_checkpoint_path(path);
    // The temporaries' pattern of `write_atomically`, which a resume removes when stale.
    let name = previous
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = previous.with_file_name(format!(".{name}.tmp{}", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    if std::fs::hard_link(path, &tmp).is_err() {
        std::fs::copy(path, &tmp).map_err(|e| TrainError::io(&tmp, e))?;
    }
    std::fs::rename(&tmp, &previous).map_err(|e| TrainError::io(&previous, e))
}

/// What the trainer reports after each iteration.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    /// Iterations completed (1-based).
    pub iteration: usize,
    /// Total iterations of the run.
    pub iterations: usize,
    /// The iteration's loss terms.
    pub terms: LossTerms,
    /// PSNR (dB) of `I_fine` against `I_hand` on the training view.
    pub psnr: f64,
    /// Learning rate used.
    pub learning_rate: f64,
    /// Seconds of training so far (including earlier sessions of a resumed run).
    pub seconds: f64,
}

/// Receives progress and may ask the trainer to stop (Ctrl-C).
pub trait Observer {
    /// After every iteration.
    fn iteration(&mut self, progress: &Progress);
    /// After a non-finite loss was recovered from.
    fn recovered(&mut self, iteration: usize, message: &str);
    /// Polled after every iteration; `true` makes the trainer save and stop.
    fn should_stop(&self) -> bool {
        false
    }
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Silent;

impl Observer for Silent {
    fn iteration(&mut self, _: &Progress) {}
    fn recovered(&mut self, _: usize, _: &str) {}
}

/// One scene's training state.
#[derive(Debug)]
pub struct Trainer {
    /// The configuration.
    pub config: TrainConfig,
    /// The networks (on the autodiff device).
    pub nets: BittNets,
    /// The optimiser.
    pub adam: Adam,
    /// The texture PCA on the device.
    pub pca: TexturePcaTensors,
    /// Hand models, meshes, layouts.
    pub assets: HandAssets,
    /// The training view.
    pub view: TrainingView,
    /// Render settings of every render.
    pub settings: RenderSettings,
    /// Iterations completed.
    pub iteration: usize,
    /// Factor on the scheduled learning rate.
    pub lr_scale: f64,
    /// Loss terms per completed iteration.
    pub history: Vec<LossTerms>,
    /// Recovered non-finite events.
    pub events: Vec<(usize, String)>,
    /// Seconds trained before this session (resumed runs).
    pub seconds_before: f64,
    /// The last two states to go back to after a non-finite loss, oldest first (see
    /// [`Snapshot`]).
    snapshots: Vec<Snapshot>,
    device: Device,
}

impl Trainer {
    /// Fresh networks (seeded) for one scene. `device` must be an autodiff device; `image`
    /// is the training view's `[3, S, S]` image and `mask` its optional `[S, S]` hand mask.
    pub fn new(
        config: TrainConfig,
        assets: HandAssets,
        pca: &TexturePca,
        geometry: crate::assets::ViewGeometry,
        image: &[f32],
        mask: Option<&[f32]>,
        device: &Device,
    ) -> Result<Self, TrainError> {
        config.validate()?;
        assets.check_prior(pca)?;
        if pca.num_components != config.nets.html.coefficients_per_hand {
            return Err(TrainError::Invalid(format!(
                "the texture PCA has {} components, the HTML network predicts {}",
                pca.num_components, config.nets.html.coefficients_per_hand
            )));
        }
        let [h, w] = geometry.size();
        let s = config.nets.image_size;
        if [h, w] != [s, s] {
            return Err(TrainError::Invalid(format!(
                "the training view is {w} x {h}; the {} preset needs {s} x {s} (crop and resize first)",
                config.preset
            )));
        }
        // Initialise on the host backend (seeded), then copy: the same weights on every
        // backend, so runs on flex, ndarray, wgpu and cuda start identically.
        let nets = {
            // The host backend's random generator is one per process: seeding it and drawing
            // every initial weight is one step, or a training set up on another thread (tests,
            // a library user) would take draws in between and change these weights.
            let _only_us = NETS_INIT.lock().unwrap_or_else(|e| e.into_inner());
            let host = Device::flex();
            host.seed(config.seed);
            let initial = parameters_host(&config.nets.init(&host)?);
            load_parameters(config.nets.init(device)?, &initial, device)
                .map_err(TrainError::Invalid)?
        };
        let view = TrainingView::new(&assets, geometry, image, mask, device)?;
        for (side, visible) in ["left", "right"].into_iter().zip(view.visible_fraction()) {
            if visible <= 0.0 {
                return Err(TrainError::Invalid(format!(
                    "the {side} hand shows no texel in the training view (it is hidden, behind \
                     the camera or off the image); BiTT needs both hands in view"
                )));
            }
        }
        Ok(Trainer {
            adam: Adam::new(config.optim.clone()),
            pca: pca.to_device(device),
            config,
            nets,
            assets,
            view,
            settings: RenderSettings::default(),
            iteration: 0,
            lr_scale: 1.0,
            history: Vec::new(),
            events: Vec::new(),
            seconds_before: 0.0,
            snapshots: Vec::new(),
            device: device.clone(),
        })
    }

    /// The learning rate of the next iteration.
    pub fn learning_rate(&self) -> f64 {
        self.config.optim.learning_rate_at(self.iteration) * self.lr_scale
    }

    /// One forward pass with the current networks.
    pub fn forward(&self) -> Result<Outputs, TrainError> {
        forward(
            &self.nets,
            &self.pca,
            &self.assets,
            &self.view,
            &self.settings,
            self.config.loss.consistency(),
        )
    }

    /// One iteration: forward, loss, backward, Adam. Returns the loss terms and the
    /// training-view PSNR, or `Err(NonFinite)` (networks unchanged) when the loss is not finite.
    pub fn step(&mut self) -> Result<(LossTerms, f64), TrainError> {
        let outputs = self.forward()?;
        let l = loss(&outputs, &self.view, &self.config.loss);
        if l.terms.len() != LossTerms::COUNT {
            return Err(TrainError::Invalid(format!(
                "the loss has {} terms, LossTerms::COUNT says {}",
                l.terms.len(),
                LossTerms::COUNT
            )));
        }
        let stacked = Tensor::cat(
            l.terms
                .iter()
                .cloned()
                .chain([l.total.clone()])
                .map(|t| t.inner().reshape([1]))
                .collect(),
            0,
        );
        let psnr_mse = (outputs.fine_image.clone().inner() - self.view.hand_image.clone().inner())
            .square()
            .mean()
            .reshape([1]);
        let host = to_host(Tensor::cat(vec![stacked, psnr_mse], 0))?;
        // The terms and the total, then the PSNR's squared error.
        let mut row = [0.0; LossTerms::COUNT + 1];
        for (r, &v) in row.iter_mut().zip(&host) {
            *r = f64::from(v);
        }
        let terms = LossTerms::from_row(&row);
        let psnr = psnr_from_mse(f64::from(host[LossTerms::COUNT + 1]));
        if !terms.is_finite() {
            return Err(TrainError::NonFinite(format!(
                "loss at iteration {}: {terms:?}",
                self.iteration + 1
            )));
        }
        let grads = l.total.backward();
        let lr = self.learning_rate();
        self.nets = self.adam.step(self.nets.clone(), &grads, lr);
        self.iteration += 1;
        self.history.push(terms);
        Ok((terms, psnr))
    }

    /// The current state as a checkpoint.
    pub fn checkpoint(&self, seconds: f64) -> Result<Checkpoint, TrainError> {
        let host = |t: &Option<Tensor<1>>| -> Result<Option<Vec<f32>>, TrainError> {
            Ok(t.as_ref().map(|t| to_host(t.clone())).transpose()?)
        };
        let s = &self.adam.state;
        let c = Checkpoint {
            iteration: self.iteration,
            lr_scale: self.lr_scale,
            history: self.history.clone(),
            events: self.events.clone(),
            parameters: parameters_host(&self.nets),
            adam_steps: s.steps.clone(),
            adam_m: s.m.iter().map(host).collect::<Result<_, _>>()?,
            adam_v: s.v.iter().map(host).collect::<Result<_, _>>()?,
            seconds,
        };
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        if !(c.parameters.iter().all(|(_, v)| finite(v))
            && c.adam_m
                .iter()
                .chain(&c.adam_v)
                .flatten()
                .all(|v| finite(v)))
        {
            return Err(TrainError::NonFinite(format!(
                "the weights or Adam moments after iteration {}",
                self.iteration
            )));
        }
        Ok(c)
    }

    /// Restores `latest` (a run's checkpoint file) and keeps `previous` (the one before it,
    /// when there is one) to go back to should `latest`'s weights give a non-finite loss.
    pub fn resume_from(
        &mut self,
        latest: &Checkpoint,
        previous: Option<Checkpoint>,
    ) -> Result<(), TrainError> {
        self.restore(latest)?;
        self.snapshots = previous
            .filter(|p| p.iteration < latest.iteration)
            .map(|checkpoint| Snapshot {
                checkpoint,
                verified: true,
            })
            .into_iter()
            .chain([Snapshot {
                checkpoint: latest.clone(),
                verified: false,
            }])
            .collect();
        Ok(())
    }

    /// Restores a checkpoint (from [`Trainer::checkpoint`] or a file) into this trainer.
    pub fn restore(&mut self, c: &Checkpoint) -> Result<(), TrainError> {
        let fresh = {
            let _only_us = NETS_INIT.lock().unwrap_or_else(|e| e.into_inner());
            self.config.nets.init(&self.device)?
        };
        self.nets = load_parameters(fresh, &c.parameters, &self.device).map_err(|e| {
            TrainError::Invalid(format!("checkpoint does not fit the networks: {e}"))
        })?;
        let inner = self.device.clone().inner();
        let tensor = |v: &Option<Vec<f32>>| {
            v.as_ref()
                .map(|v| Tensor::<1>::from_data(TensorData::new(v.clone(), [v.len()]), &inner))
        };
        self.adam.state.steps = c.adam_steps.clone();
        self.adam.state.m = c.adam_m.iter().map(tensor).collect();
        self.adam.state.v = c.adam_v.iter().map(tensor).collect();
        self.iteration = c.iteration;
        self.lr_scale = c.lr_scale;
        self.history = c.history.clone();
        self.events = c.events.clone();
        self.seconds_before = c.seconds;
        Ok(())
    }

    /// Trains until `config.iterations`, writing `checkpoint_path` every
    /// `config.checkpoint_every` iterations, at the end, and when the observer asks to stop
    /// (then returns [`TrainError::Interrupted`]); the checkpoint it replaces is kept as
    /// [`previous_checkpoint_path`].
    ///
    /// A non-finite loss (or non-finite weights) goes back to the last good state, lowers
    /// the learning rate by [`RECOVERY_LR_FACTOR`] (cumulatively) and continues; the state
    /// gone back to is saved at once, so `--resume` never repeats the failure. After
    /// [`MAX_NON_FINITE`] recoveries it returns [`TrainError::RecoveryExhausted`], holding
    /// (and having saved) the last good state, whose results can still be written.
    pub fn train(
        &mut self,
        checkpoint_path: Option<&Path>,
        observer: &mut dyn Observer,
    ) -> Result<(), TrainError> {
        let start = Instant::now();
        let seconds = |t: &Trainer| t.seconds_before + start.elapsed().as_secs_f64();
        // The steps are hundreds of short parallel passes: keep rayon's idle worker awake.
        let _awake = bitt_nets::awake::KeepAwake::on(&self.device);
        if self.snapshots.is_empty() {
            let checkpoint = self.checkpoint(seconds(self))?;
            self.snapshots.push(Snapshot {
                checkpoint,
                verified: false,
            });
        }
        while self.iteration < self.config.iterations {
            let lr = self.learning_rate();
            let failure = match self.step() {
                Ok((terms, psnr)) => {
                    // A step from the latest state gave a finite loss: that state is good.
                    if let Some(latest) = self.snapshots.last_mut() {
                        latest.verified = true;
                    }
                    observer.iteration(&Progress {
                        iteration: self.iteration,
                        iterations: self.config.iterations,
                        terms,
                        psnr,
                        learning_rate: lr,
                        seconds: seconds(self),
                    });
                    let done = self.iteration == self.config.iterations;
                    let stop = observer.should_stop();
                    if done || stop || self.iteration.is_multiple_of(self.config.checkpoint_every) {
                        match self.checkpoint(seconds(self)) {
                            Ok(c) => {
                                if let Some(path) = checkpoint_path {
                                    keep_as_previous(path)?;
                                    c.save(path)?;
                                }
                                self.snapshots.push(Snapshot {
                                    checkpoint: c,
                                    verified: false,
                                });
                                if self.snapshots.len() > 2 {
                                    self.snapshots.remove(0);
                                }
                                if stop && !done {
                                    return Err(TrainError::Interrupted(self.iteration));
                                }
                                None
                            }
                            Err(TrainError::NonFinite(m)) => Some(m),
                            Err(e) => return Err(e),
                        }
                    } else {
                        None
                    }
                }
                Err(TrainError::NonFinite(message)) => Some(message),
                Err(e) => return Err(e),
            };
            if let Some(message) = failure {
                self.recover(&message, checkpoint_path, seconds(self), observer)?;
            }
        }
        Ok(())
    }

    /// Goes back to the last good state after a non-finite loss (see [`Trainer::train`]).
    fn recover(
        &mut self,
        message: &str,
        checkpoint_path: Option<&Path>,
        seconds: f64,
        observer: &mut dyn Observer,
    ) -> Result<(), TrainError> {
        let failed_at = self.iteration;
        // The latest state's own forward pass failed: it is not a state to go back to.
        if self.snapshots.last().is_some_and(|s| !s.verified) && self.snapshots.len() > 1 {
            self.snapshots.pop();
        }
        let Some(good) = self.snapshots.last().cloned() else {
            return Err(TrainError::NonFinite(format!(
                "{message}; no earlier state to go back to"
            )));
        };
        if !good.verified {
            return Err(TrainError::NonFinite(format!(
                "{message}; the networks' first forward pass from iteration {} is not finite, \
                 and there is no earlier state to go back to",
                good.checkpoint.iteration
            )));
        }
        let scale = self.lr_scale * RECOVERY_LR_FACTOR;
        let mut events = self.events.clone();
        let exhausted = events.len() >= MAX_NON_FINITE;
        let seconds_before = self.seconds_before;
        self.restore(&good.checkpoint)?;
        self.seconds_before = seconds_before;
        let note = if exhausted {
            format!(
                "{message}; gave up after {MAX_NON_FINITE} recoveries and went back to \
                 iteration {}",
                good.checkpoint.iteration
            )
        } else {
            self.lr_scale = scale;
            format!(
                "{message}; went back to iteration {} and lowered the learning rate to {:.3e} \
                 (x{scale})",
                good.checkpoint.iteration,
                self.learning_rate()
            )
        };
        events.push((failed_at, note.clone()));
        self.events = events;
        // The state gone back to, with its new rate and events, replaces the failed one on
        // disk too, so a resume starts from it.
        let c = Checkpoint {
            lr_scale: self.lr_scale,
            events: self.events.clone(),
            seconds,
            ..good.checkpoint
        };
        if let Some(path) = checkpoint_path {
            c.save(path)?;
        }
        *self.snapshots.last_mut().expect("a good state") = Snapshot {
            checkpoint: c,
            verified: true,
        };
        observer.recovered(failed_at, &note);
        if exhausted {
            return Err(TrainError::RecoveryExhausted {
                message: message.to_string(),
                count: MAX_NON_FINITE,
                restored: self.iteration,
            });
        }
        Ok(())
    }

    /// The geometry of `hands` (a novel view or pose) on `device`, shaded as the training
    /// view is: with its ambient occlusion strength ([`ViewGeometry::with_occlusion`]).
    ///
    /// # Errors
    /// Hands that cannot be posed, or vertices the occlusion rays cannot be cast over.
    pub fn view_geometry(
        &self,
        hands: &bitt_mesh::TwoHandScene,
        device: &Device,
    ) -> Result<ViewGeometry, TrainError> {
        ViewGeometry::new(&self.assets, hands, device)?
            .with_occlusion(&self.assets, self.view.geometry.occlusion_strength())
    }

    /// Seconds trained so far by the last `train` call's latest state.
    pub fn seconds(&self) -> f64 {
        self.snapshots
            .last()
            .map_or(self.seconds_before, |s| s.checkpoint.seconds)
    }
}

/// PSNR (dB) of images in `[0, 1]` from their mean squared error.
pub(crate) fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}
