//! What a BiTT user opens, drawn and written: images, figures, plots, the report's 3D view,
//! the XR page and the avatar files.
//!
//! - [`export`]: OBJ and glTF 2.0 binary writers of posed hands (`export/skinned.rs`: the
//!   rigged avatar and its reading back as a viewer would; `export/xr.rs`: one hand for
//!   hand-tracking runtimes).
//! - [`outputs`]: PNG and JSON writing, contact sheets, texture images, a folder of ours.
//! - [`plot`]: the loss plot (`loss.png`: axes, decade ticks, legend, learning-rate steps).
//! - [`viewer`]: the report's interactive 3D view of the avatar (three.js, embedded).
//! - [`xr_page`]: `xr.html`, the per-hand XR avatars driven by three.js's `XRHandMeshModel`.
//! - [`avatar_export`]: the avatar files: rigged `avatar.glb`, `avatar_static.glb`, OBJ, the
//!   `xr/` folder.
//!
//! This crate draws what it is given (hands, textures, images, loss histories); it never
//! trains, refines, evaluates or decides what a run folder holds. It writes only the paths
//! it is handed, atomically. It depends on `bitt-train` only for what `loss.png` plots (the
//! loss terms and the learning-rate schedule).

pub mod avatar_export;
mod error;
pub mod export;
pub mod outputs;
pub mod plot;
pub mod viewer;
pub mod xr_page;

pub use error::OutputError;
