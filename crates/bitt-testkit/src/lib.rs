//! The workspace's test kit: backends to test on, closeness checks, readback, seeded inputs,
//! error chains.
//!
//! A dev-dependency of the crates' tests only; it depends on burn and nothing of ours.
//! [`devices`] is flex, ndarray and, when a Vulkan adapter can be created (a GPU's driver
//! or Mesa's software lavapipe), wgpu; `BITT_TEST_WGPU=0` leaves wgpu out.

mod close;
mod devices;
mod errors;
mod rng;

pub use close::{assert_close, to_vec};
pub use devices::{WGPU_ENV, autodiff_devices, cpu_devices, devices, wgpu};
pub use errors::error_chain;
pub use rng::{Rng, random, values};
