//! Commands that regenerate what the documentation shows, each running an example of a
//! library crate in release mode (the logic lives in the example, not here):
//!
//! - `docs-images [DIR]`: the procedural skin images (`bitt-texture`'s `docs_images`) and the
//!   synthetic benchmark's contact sheet with its Table-3 statistics (`bitt-synth`'s
//!   `docs_synth_contact`), into `DIR` (default `docs/images`).
//! - `mesh-noise-calibration`: how far the default mesh noise moves the given meshes
//!   (`bitt-synth`'s `mesh_noise_calibration`, quoted in `docs/synthetic.md`).
//! - `fuzz-seeds`: the fuzz targets' seed files into `fuzz/corpus/` (`bitt-tests`'
//!   `fuzz_seeds`).

use std::process::Command;

use anyhow::{Context, Result, bail};

/// Runs the release example `name` with `args`, inheriting stdio.
fn example(name: &str, args: &[String]) -> Result<()> {
    let bin = crate::build_example(name)?;
    let status = Command::new(&bin)
        .args(args)
        .current_dir(crate::root())
        .status()
        .with_context(|| format!("running the {name} example ({})", bin.display()))?;
    crate::check(status, name)
}

/// `cargo xtask docs-images [DIR]`.
pub fn docs_images(args: &[String]) -> Result<()> {
    let dir = match args {
        [] => "docs/images".to_string(),
        [dir] => dir.clone(),
        _ => bail!("usage: cargo xtask docs-images [DIR]"),
    };
    example("docs_images", std::slice::from_ref(&dir))?;
    example("docs_synth_contact", &[dir])
}

/// `cargo xtask mesh-noise-calibration`.
pub fn mesh_noise_calibration(args: &[String]) -> Result<()> {
    if !args.is_empty() {
        bail!("usage: cargo xtask mesh-noise-calibration");
    }
    example("mesh_noise_calibration", &[])
}

/// `cargo xtask fuzz-seeds`.
pub fn fuzz_seeds(args: &[String]) -> Result<()> {
    if !args.is_empty() {
        bail!("usage: cargo xtask fuzz-seeds");
    }
    example("fuzz_seeds", &[])
}
