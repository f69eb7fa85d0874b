//! The BiTT pipeline (paper Sec. 3-4): from one image of two interacting hands and their
//! meshes to relightable UV textures of both hands.
//!
//! The training core is `bitt-train`'s, re-exported here under the same paths: [`config`],
//! [`assets`], [`pipeline`], [`losses`], [`optim`], [`checkpoint`], [`trainer`]. The files a
//! user opens are drawn by `bitt-outputs`, re-exported likewise: [`outputs`], [`plot`],
//! [`viewer`], [`xr_page`], [`avatar_export`].
//!
//! - [`config_files`]: the configuration files the commands take (training, refinement, fit).
//! - [`demo`]: the built-in two-hand demo scene (procedural or any other hands).
//! - [`input`]: what a run is given: hand and prior sources, photos read and checked against
//!   their hands, cropped and resized to the preset's size.
//! - [`metrics`], [`evaluate`]: image and texture metrics, renders at other views and poses.
//! - [`pair_metrics`]: two image files compared (`bitt metrics`): metrics, LPIPS inputs, report.
//! - [`lpips`]: LPIPS-VGG with user-provided weights (unavailable without them);
//!   [`lpips_convert`] writes its weights file from the torch checkpoints.
//! - [`train_scene`]: a run's setup (fresh or resumed) and its results, for `train-scene`.
//! - [`outputs`], [`run`]: the run folder (textures, renders, avatar, metrics, report);
//!   [`files`]: its file names and the readers of a finished run's textures and light;
//!   [`run_folder`]: where a new run may go, its first files, a resumed run's checkpoints.
//! - [`avatar_export`]: the avatar files: rigged `avatar.glb`, `avatar_static.glb`, OBJ.
//! - [`saved`]: a trained run read back from its folder (either kind), for re-rendering and
//!   re-exporting without the networks.
//! - [`viewer`]: the report's interactive 3D view of the avatar (three.js, embedded).
//! - [`xr_page`]: `xr.html`, the per-hand XR avatars driven by three.js's `XRHandMeshModel`
//!   (the scene's poses as tracked joint poses, or live WebXR hand tracking).
//! - [`figure`]: `bitt render`'s figures (both hands, each alone, masks, unwrapped images,
//!   a grid of orthographic views).
//! - [`figure_inputs`]: what the figures are made of, read and checked (light, UV layouts,
//!   images, procedural skin textures).
//! - [`texture_model`]: a run's procedural texture prior (fitted once, cached) and `bitt
//!   texture`'s texture PCA model (a file or the procedural fit), its parameters and the UV
//!   texture it makes.
//! - [`plot`]: the loss plot (`loss.png`: axes, decade ticks, legend, learning-rate steps).
//! - [`progress`]: progress on stderr (training, evaluation, refinement, keypoint fit, PCA fit,
//!   a run's setup): a bar redrawn on a terminal, a plain line every 10 % in a log.
//! - [`hand_layer`]: the hand model as a differentiable burn function (both hands batched).
//! - [`refine`]: mesh refinement of both hands against the photo through the renderer.
//! - [`hand_priors`]: joint-angle, off-axis and penetration priors shared by `refine` and `fit`.
//! - [`detect`]: both hands found in a photo by the built-in detector (`bitt-detect`), the
//!   detection's files and overlay (`bitt detect-hands`, the photo-only path).
//! - [`fit`]: both hands fitted to 2D keypoints (OpenPose, MediaPipe, plain JSON).
//! - [`real`]: real runs (an image + annotation pickle, InterHand2.6M scenes, keypoints).
//! - [`backend_check`], [`nets_bench`], [`gpu_check`]: a fixed computation to compare
//!   backends, the network benches, and `bitt gpu-check` (every GPU check in one report);
//!   [`net_shapes`]: the networks' parameter counts and shapes (`bitt nets`).

pub mod backend_check;
pub mod baselines;
pub mod benchmark;
pub mod config_files;
pub mod demo;
pub mod detect;
mod error;
pub mod evaluate;
pub mod figure;
pub mod figure_inputs;
pub mod files;
pub mod fit;
pub mod gpu_check;
pub mod hand_layer;
pub mod hand_priors;
pub mod input;
pub mod lpips;
pub mod lpips_convert;
pub mod metrics;
pub mod net_shapes;
pub mod nets_bench;
pub mod pair_metrics;
pub mod progress;
pub mod real;
pub mod refine;
pub mod run;
pub mod run_folder;
pub mod saved;
pub mod texture_model;
pub mod train_scene;

pub use bitt_outputs::{avatar_export, outputs, plot, viewer, xr_page};
pub use bitt_train::{
    LossTerms, LossWeights, Observer, OptimConfig, Progress, TrainConfig, TrainError, Trainer,
    assets, checkpoint, config, losses, optim, pipeline, trainer,
};
pub use error::BittError;

#[cfg(test)]
mod tests;
