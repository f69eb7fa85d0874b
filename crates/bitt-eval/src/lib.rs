//! Evaluation (paper Sec. 4): the image and texture metrics (PSNR, SSIM, MS-SSIM, masked
//! and texel-wise errors), LPIPS-VGG with user-provided weights, the HARP-like and
//! S2Hand-like baselines, and a trained avatar rendered at other views, poses and lights and
//! scored against ground truth.
//!
//! - [`metrics`]: image and texture metrics on host buffers.
//! - [`lpips`]: LPIPS-VGG (unavailable without its weights); [`lpips_convert`] writes its
//!   weights file from the torch checkpoints.
//! - [`pair_metrics`]: two image files compared (`bitt metrics`): metrics, LPIPS, report.
//! - [`baselines`]: the baselines the benchmark compares BiTT with.
//! - [`evaluate`]: a trained avatar's renders at other views and poses, its scores, and the
//!   checks of its textures (saturated texels, albedo in shade).
//!
//! Architecture invariant: this crate measures what it is handed. It never trains a run,
//! fits hands, reads a run folder or decides where files go; the benchmark protocol that
//! runs the methods per scene is `bitt-bench`'s (`bitt_bench::benchmark`). It sits below
//! `bitt-fit` because the mesh refinement scores with [`metrics::mask_iou`].

mod error;

pub mod baselines;
pub mod evaluate;
pub mod lpips;
pub mod lpips_convert;
pub mod metrics;
pub mod pair_metrics;

pub use error::EvalError;
