//! The runs (orchestration): from a scene or a photo to a trained avatar in a run folder,
//! over the stages below it. The training core is `bitt-train`'s, geometry from a photo
//! `bitt-fit`'s, the metrics `bitt-eval`'s and the files a user opens `bitt-outputs`'s; they
//! are re-exported here under the paths the commands use.
//!
//! - [`train_scene`]: a run's setup (fresh or resumed) and its results, for `train-scene`.
//! - [`input`]: what a run is given: hand and prior sources, photos read and checked against
//!   their hands, cropped and resized to the preset's size.
//! - [`real`]: real runs (an image and its annotation, InterHand2.6M scenes, keypoints, a
//!   photo alone).
//! - [`fit`], [`refine`]: the jobs of `fit-hands` and `refine-hands` (their output folders),
//!   over `bitt_fit`'s fit and refinement.
//! - [`run`]: the run folder (textures, renders, avatar, metrics, report); [`files`]: its
//!   file names and the readers of a finished run's textures and light; [`run_folder`]:
//!   where a new run may go, its first files, a resumed run's checkpoints.
//! - [`saved`]: a trained run read back from its folder (either kind), for re-rendering and
//!   re-exporting without the networks.
//! - [`config_files`]: the configuration files the commands take (training, refinement, fit).
//! - [`demo`]: the built-in two-hand demo scene (procedural or any other hands).
//! - [`texture_model`]: a run's procedural texture prior (fitted once, cached) and `bitt
//!   texture`'s texture PCA model (a file or the procedural fit).
//! - [`figure`], [`figure_inputs`]: `bitt render`'s figures and what they are made of.
//!
//! Architecture invariant: the stages below never know about run folders, resuming or the
//! command line; this crate never prints (progress goes to the observers the binary gives).
//! It writes only the paths it is given and below the folders it is given, atomically.

pub mod config_files;
pub mod demo;
mod error;
pub mod figure;
pub mod figure_inputs;
pub mod files;
pub mod fit;
pub mod input;
pub mod real;
pub mod refine;
pub mod run;
pub mod run_folder;
pub mod saved;
pub mod texture_model;
pub mod train_scene;

pub use bitt_eval::{baselines, evaluate, lpips, lpips_convert, metrics, pair_metrics};
pub use bitt_fit::{detect, hand_layer, hand_priors};
pub use bitt_outputs::{avatar_export, export, outputs, plot, viewer, xr_page};
pub use bitt_train::{
    LossTerms, LossWeights, Observer, OptimConfig, Progress, TrainConfig, TrainError, Trainer,
    assets, checkpoint, config, losses, optim, pipeline, trainer,
};
pub use error::BittError;

#[cfg(test)]
mod tests;
