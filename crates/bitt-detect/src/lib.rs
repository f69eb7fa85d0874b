//! A two-hand detector on burn: MediaPipe Hands' palm detector and hand landmark model
//! (Apache-2.0 weights built into the binary, fp16) interpreted from their TFLite graphs on
//! any burn device, and a search that finds **both** of two interacting hands, which a single
//! pass of MediaPipe's own pipeline does not (`docs/detection.md`).
//!
//! Layers, lowest first: [`flatbuffer`] and [`tflite`] read a `.tflite` file into a
//! [`graph::Graph`] (only `cargo xtask convert-mediapipe` does this); [`graph`] stores the
//! graphs and fp16 weights as one safetensors file; [`exec`] runs a graph on a burn device;
//! [`crop`] and [`palm`] are MediaPipe's pre- and post-processing; [`detector`] runs the two
//! networks in batches; [`search`] finds the two hands.
//!
//! Architecture invariant: this crate knows photos, networks and 2D keypoints only. It never
//! knows hand meshes, fitting, training or run folders (`bitt-fit` uses it for those).
//!
//! Architecture invariant: the weights file (`assets/mediapipe_hands.safetensors`, built
//! into the binary) is the only place the models live; no code path downloads anything or
//! needs Python at run time.

#![warn(missing_docs)]

mod error;
mod flatbuffer;

pub mod crop;
pub mod detector;
pub mod exec;
pub mod graph;
pub mod palm;
pub mod search;
pub mod tflite;

#[cfg(test)]
mod tests;

pub use crop::Rect;
pub use detector::{HandDetector, HandLandmarks};
pub use error::DetectError;
pub use search::{DetectedHand, SearchConfig, TwoHandDetection, detect_hands};

/// Landmarks per hand (MediaPipe's order, which is OpenPose's and the project's).
pub const NUM_LANDMARKS: usize = 21;
