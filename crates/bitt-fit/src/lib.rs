//! Geometry from a photo: both hands found, fitted and refined, as differentiable burn
//! functions.
//!
//! - [`hand_layer`]: the hand model as a differentiable burn function (both hands batched).
//! - [`hand_priors`]: joint-angle, off-axis and penetration priors shared by the fit and the
//!   refinement.
//! - [`photo`]: a photo cropped and resized around its hands, the camera adjusted
//!   ([`photo::ImageInput`]).
//! - [`detect`]: both hands found in a photo by the built-in detector (`bitt-detect`), the
//!   detection's files and overlay.
//! - [`fit`]: both hands fitted to 2D keypoints (detected, OpenPose, MediaPipe, plain JSON).
//! - [`refine`]: both hands refined against the photo through the renderer.
//!
//! Architecture invariant: this crate turns a photo (and keypoints or starting hands) into
//! hands. It never trains textures, and never makes a run folder: the jobs that write
//! `fit-hands` / `refine-hands` folders and the real-photo runs are the orchestration
//! crate's (`bitt::fit`, `bitt::refine`, `bitt::real`).
//!
//! Why the hand layer lives here and not in `bitt-mesh` or `bitt-render`: `bitt-mesh` stays
//! free of burn (its `f64` forward pass is the reference the layer is tested against), and
//! `bitt-render` must never know hand models. This is where geometry first meets tensors
//! and the renderer.
//!
//! Architecture invariant: the hand layer reads only `HandModel` arrays (nothing branches on
//! MANO or procedural); whether a PCA finger pose means anything for a model is a property
//! of its pose basis ([`hand_layer::has_learned_pose_pca`]), not of its origin.

mod error;

pub mod detect;
pub mod fit;
pub mod hand_layer;
pub mod hand_priors;
pub mod photo;
pub mod refine;

pub use error::FitError;
