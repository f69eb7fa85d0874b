//! Measurements of the whole pipeline, on top of the runs (`bitt`):
//!
//! - [`benchmark`]: `bitt eval`, the benchmark protocol: every method (BiTT, its coarse
//!   prior, the baselines) trained and scored per synthetic scene, InterHand2.6M scene or
//!   real photo pair, aggregated into a results folder (`results.json`, `results.md`).
//! - [`gpu_check`]: `bitt gpu-check`, every GPU check in one report (forward passes against
//!   flex, the rasterizer, the network benches, a short demo run, figures).
//! - [`backend_check`]: a fixed computation to compare two backends (`bitt backend-check`).
//! - [`nets_bench`]: the four networks' forward and backward timings (`bitt nets --bench`);
//!   [`net_shapes`]: their parameter counts and shapes (`bitt nets`).
//!
//! Errors are the runs' ([`bitt::BittError`]): this crate adds none of its own.
//!
//! Architecture invariant: this crate only measures. It runs the library's jobs (training,
//! refinement, the networks) as a user would and never changes what they compute; nothing
//! below depends on it.

pub mod backend_check;
pub mod benchmark;
pub mod gpu_check;
pub mod net_shapes;
pub mod nets_bench;
