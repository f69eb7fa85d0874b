//! `bitt backend-check`: the fixed computation of [`bitt_bench::backend_check`] on one backend,
//! printed as one JSON line so `cargo xtask e2e` can compare backends.

use std::time::Instant;

use anyhow::Result;
use bitt_bench::backend_check::{BackendNumbers, compute};

use crate::device::DeviceName;

/// Result of the check, printed as one JSON line.
#[derive(Debug, serde::Serialize)]
struct CheckOutput {
    device: DeviceName,
    #[serde(flatten)]
    numbers: BackendNumbers,
    seconds: f64,
}

/// Runs the check on `name` and prints one JSON line.
pub fn run(name: DeviceName) -> Result<()> {
    let device = name.device()?;
    let start = Instant::now();
    let numbers = compute(&device)?;
    let out = CheckOutput {
        device: name,
        numbers,
        seconds: start.elapsed().as_secs_f64(),
    };
    println!("{}", serde_json::to_string(&out)?);
    Ok(())
}
