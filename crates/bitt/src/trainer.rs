//! The per-scene trainer (paper Sec. 4.1): fresh networks, Adam, the step schedule,
//! atomic checkpoints, exact resumption, and recovery from non-finite losses.

use std::path::Path;
use std::time::Instant;

use bitt_nets::BittNets;
use bitt_render::scene::RenderSettings;
use bitt_texture::{LayoutGather, TexturePca, TexturePcaTensors};
use burn::tensor::{Device, Tensor, TensorData};

use crate::BittError;
use crate::assets::HandAssets;
use crate::checkpoint::Checkpoint;
use crate::config::TrainConfig;
use crate::losses::{LossTerms, loss};
use crate::optim::{Adam, load_parameters, parameters_host};
use crate::pipeline::{Outputs, TrainingView, forward};

/// Non-finite losses tolerated in one run before giving up.
pub const MAX_NON_FINITE: usize = 8;

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
    /// Compact <-> image index tensors.
    pub gather: LayoutGather,
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
    /// Last good state, restored after a non-finite loss.
    snapshot: Option<Checkpoint>,
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
    ) -> Result<Self, BittError> {
        config.validate()?;
        if pca.layout.num_texels() != assets.num_texels() {
            return Err(BittError::Invalid(format!(
                "the texture PCA covers {} texels, the hands' layout {}",
                pca.layout.num_texels(),
                assets.num_texels()
            )));
        }
        if pca.num_components != config.nets.html.coefficients_per_hand {
            return Err(BittError::Invalid(format!(
                "the texture PCA has {} components, the HTML network predicts {}",
                pca.num_components, config.nets.html.coefficients_per_hand
            )));
        }
        let [h, w] = geometry.size();
        let s = config.nets.image_size;
        if [h, w] != [s, s] {
            return Err(BittError::Invalid(format!(
                "the training view is {w} x {h}; the {} preset needs {s} x {s} (crop and resize first)",
                config.preset
            )));
        }
        // Initialise on the host backend (seeded), then copy: the same weights on every
        // backend, so runs on flex, ndarray, wgpu and cuda start identically.
        let host = Device::flex();
        host.seed(config.seed);
        let initial = parameters_host(&config.nets.init(&host)?);
        let nets = load_parameters(config.nets.init(device)?, &initial, device)
            .map_err(BittError::Invalid)?;
        let view = TrainingView::new(&assets, geometry, image, mask, device)?;
        let gather = assets.gather(device);
        Ok(Trainer {
            adam: Adam::new(config.optim.clone()),
            pca: pca.to_device(device),
            config,
            nets,
            assets,
            gather,
            view,
            settings: RenderSettings::default(),
            iteration: 0,
            lr_scale: 1.0,
            history: Vec::new(),
            events: Vec::new(),
            seconds_before: 0.0,
            snapshot: None,
            device: device.clone(),
        })
    }

    /// The learning rate of the next iteration.
    pub fn learning_rate(&self) -> f64 {
        self.config.optim.learning_rate_at(self.iteration) * self.lr_scale
    }

    /// One forward pass with the current networks.
    pub fn forward(&self) -> Result<Outputs, BittError> {
        forward(
            &self.nets,
            &self.pca,
            &self.assets,
            &self.gather,
            &self.view,
            &self.settings,
            self.config.loss.consistency(),
        )
    }

    /// One iteration: forward, loss, backward, Adam. Returns the loss terms and the
    /// training-view PSNR, or `Err(NonFinite)` (networks unchanged) when the loss is not finite.
    pub fn step(&mut self) -> Result<(LossTerms, f64), BittError> {
        let outputs = self.forward()?;
        let l = loss(&outputs, &self.view, &self.config.loss);
        let mut values: Vec<f64> = Vec::with_capacity(7);
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
        let host = read(Tensor::cat(vec![stacked, psnr_mse], 0))?;
        values.extend(host[..7].iter().map(|&v| f64::from(v)));
        let terms = LossTerms::from_values(&values[..6], values[6]);
        let psnr = psnr_from_mse(f64::from(host[7]));
        if !terms.is_finite() {
            return Err(BittError::NonFinite(format!(
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
    pub fn checkpoint(&self, seconds: f64) -> Result<Checkpoint, BittError> {
        let host = |t: &Option<Tensor<1>>| -> Result<Option<Vec<f32>>, BittError> {
            t.as_ref().map(|t| read(t.clone())).transpose()
        };
        let s = &self.adam.state;
        Ok(Checkpoint {
            iteration: self.iteration,
            lr_scale: self.lr_scale,
            history: self.history.clone(),
            events: self.events.clone(),
            parameters: parameters_host(&self.nets),
            adam_steps: s.steps.clone(),
            adam_m: s.m.iter().map(host).collect::<Result<_, _>>()?,
            adam_v: s.v.iter().map(host).collect::<Result<_, _>>()?,
            seconds,
        })
    }

    /// Restores a checkpoint (from [`Trainer::checkpoint`] or a file) into this trainer.
    pub fn restore(&mut self, c: &Checkpoint) -> Result<(), BittError> {
        let fresh = self.config.nets.init(&self.device)?;
        self.nets = load_parameters(fresh, &c.parameters, &self.device).map_err(|e| {
            BittError::Invalid(format!("checkpoint does not fit the networks: {e}"))
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
    /// (then returns [`BittError::Interrupted`]). A non-finite loss restores the last good
    /// state, halves the learning rate and continues (at most [`MAX_NON_FINITE`] times).
    pub fn train(
        &mut self,
        checkpoint_path: Option<&Path>,
        observer: &mut dyn Observer,
    ) -> Result<(), BittError> {
        let start = Instant::now();
        let seconds = |t: &Trainer| t.seconds_before + start.elapsed().as_secs_f64();
        if self.snapshot.is_none() {
            self.snapshot = Some(self.checkpoint(seconds(self))?);
        }
        while self.iteration < self.config.iterations {
            let lr = self.learning_rate();
            match self.step() {
                Ok((terms, psnr)) => {
                    observer.iteration(&Progress {
                        iteration: self.iteration,
                        iterations: self.config.iterations,
                        terms,
                        psnr,
                        learning_rate: lr,
                        seconds: seconds(self),
                    });
                }
                Err(BittError::NonFinite(message)) => {
                    if self.events.len() >= MAX_NON_FINITE {
                        return Err(BittError::NonFinite(format!(
                            "{message}; gave up after {MAX_NON_FINITE} recoveries"
                        )));
                    }
                    let snapshot = self.snapshot.clone().expect("snapshot taken above");
                    let mut events = self.events.clone();
                    self.restore(&snapshot)?;
                    self.lr_scale *= 0.5;
                    let note = format!(
                        "{message}; restored iteration {} and halved the learning rate",
                        snapshot.iteration
                    );
                    events.push((self.iteration, note.clone()));
                    self.events = events;
                    observer.recovered(self.iteration, &note);
                    continue;
                }
                Err(e) => return Err(e),
            }
            let done = self.iteration == self.config.iterations;
            let stop = observer.should_stop();
            if done || stop || self.iteration.is_multiple_of(self.config.checkpoint_every) {
                let c = self.checkpoint(seconds(self))?;
                if let Some(path) = checkpoint_path {
                    c.save(path)?;
                }
                self.snapshot = Some(c);
            }
            if stop && !done {
                return Err(BittError::Interrupted(self.iteration));
            }
        }
        Ok(())
    }

    /// Seconds trained so far by the last `train` call's snapshot.
    pub fn seconds(&self) -> f64 {
        self.snapshot
            .as_ref()
            .map_or(self.seconds_before, |s| s.seconds)
    }
}

/// PSNR (dB) of images in `[0, 1]` from their mean squared error.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// Reads a tensor back as host `f32`.
pub fn read<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>, BittError> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| BittError::Invalid(format!("reading a tensor back: {e:?}")))
}
