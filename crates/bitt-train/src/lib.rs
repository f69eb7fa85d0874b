//! The BiTT training core (paper Sec. 3-4): what one scene trains from and how.
//!
//! - [`config`]: the trainer's configuration, the `paper` / `quick` / `tiny` presets and the
//!   range check every configuration of the project uses.
//! - [`assets`]: hand models, render meshes, texture layouts; one view's geometry.
//! - [`pipeline`]: the forward pass (scene estimation, coarse stage, fine stage).
//! - [`losses`]: the paper's loss (eq. 6-10).
//! - [`optim`], [`checkpoint`], [`trainer`]: Adam, checkpoints, the per-scene trainer.
//! - [`light_search`]: a real photo's light location, chosen from the view's image before
//!   training.
//!
//! This crate knows one training view and its networks. It never knows photos, detectors,
//! keypoint fits, mesh refinement, run folders, reports or evaluation protocols: those are
//! `bitt`'s, above it. It writes only the checkpoint files it is handed, atomically.
//!
//! Architecture invariant: a [`assets::ViewGeometry`]'s vertices never change, so what a
//! render needs from them is computed once per render setting and every later render only
//! shades; moving geometry (the refinement in `bitt-fit`) renders through the renderer's
//! primitives and `bitt_render::scene::render` instead.
//!
//! Architecture invariant: initial weights are drawn on the seeded host backend and copied to
//! the training device, so every backend starts a run from the same networks; seeding and
//! drawing are one step under [`trainer::NETS_INIT`].

pub mod assets;
pub mod checkpoint;
pub mod config;
mod error;
pub mod light_search;
pub mod losses;
pub mod optim;
pub mod pipeline;
pub mod trainer;

pub use config::{LossWeights, OptimConfig, QUICK_PHOTO_BTR_CHANNELS, TrainConfig};
pub use error::TrainError;
pub use losses::LossTerms;
pub use trainer::{Observer, Progress, Trainer};
