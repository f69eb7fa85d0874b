//! Hand geometry for BiTT.
//!
//! - [`model`]: the [`HandModel`] struct shared by MANO and the procedural hand.
//! - [`lbs`]: the forward pass (shape and pose blend shapes, linear blend skinning).
//! - [`mano`]: loading the user's MANO `.pkl` files and their safetensors conversions.
//! - [`procedural`]: the license-free hand model this project generates itself.
//! - [`camera`]: pinhole and orthographic cameras.
//! - [`annotation`]: BiTT/InterHand annotation pickles and InterHand2.6M JSON.
//! - [`interhand`]: the InterHand2.6M dataset reader and the paper's scene selection.
//! - [`keypoints`]: 2D hand keypoints from OpenPose, MediaPipe and a plain JSON format.
//! - [`light`]: the scene light's 12 values and the `--light` text.
//! - [`occlusion`]: ambient occlusion of posed meshes by shadow rays.
//!
//! Everything is `f64` on the CPU: posing is cheap and exactness helps the tests (this forward
//! pass is the reference `bitt-fit`'s differentiable hand layer is tested against). Tensors
//! begin above; writing posed hands as OBJ / glTF is `bitt-outputs`' (`export::write_posed`).
//!
//! This crate knows nothing of tensors, networks or textures beyond a UV layout, and never
//! decides where files live: it reads and writes only the paths it is handed.
//!
//! Architecture invariant: MANO and the procedural hand are one [`HandModel`] through one
//! forward pass; nothing downstream may branch on which one it has.

pub mod annotation;
pub mod camera;
pub mod error;
pub mod interhand;
pub mod keypoints;
pub mod lbs;
pub mod light;
pub mod mano;
pub mod model;
pub mod occlusion;
pub mod procedural;

/// The `glam` crate this crate's types ([`UvLayout`], [`HandModel`], ...) are built on, so
/// that crates above can name `glam::DVec2` / `glam::DVec3` without depending on it directly.
pub use glam;

pub use annotation::{TwoHandScene, load_bitt_annotation};
pub use camera::{OrthographicCamera, PinholeCamera};
pub use error::MeshError;
pub use lbs::{HandParams, HandPose, PosedHand};
pub use mano::{HandPair, load_model_dir};
pub use model::{HandModel, Side, UvLayout};
pub use procedural::{ProceduralHandConfig, default_hand, procedural_hand};

/// The procedural left and right hands with default settings.
pub fn procedural_pair() -> HandPair {
    HandPair {
        left: default_hand(Side::Left),
        right: default_hand(Side::Right),
    }
}
