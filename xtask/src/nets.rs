//! `cargo xtask nets [--preset paper|quick|tiny] [--no-run]`: the four networks' parameter
//! counts and output shapes as JSON, from the release `bitt nets`.

use anyhow::Result;

/// Forwards to `bitt nets` (release build), defaulting to the paper preset.
pub fn nets(args: &[String]) -> Result<()> {
    let mut full = vec!["nets".to_string()];
    full.extend_from_slice(args);
    crate::bitt(&full)
}
