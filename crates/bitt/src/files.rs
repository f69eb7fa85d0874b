//! The run folder's file names, and readers of what a finished run keeps of its avatar
//! (fine textures and estimated light), shared by synthetic and real runs.

use bitt_stdx::FileErrorExt;
use std::path::Path;

use bitt_render::scene::{LightValues, LightValuesExt};
use bitt_stdx::st;

use crate::BittError;

/// The resolved configuration.
pub const CONFIG: &str = "config.json";
/// The latest checkpoint.
pub const CHECKPOINT: &str = "checkpoint.safetensors";
/// The checkpoint before it (see [`crate::trainer::previous_checkpoint_path`]).
pub const CHECKPOINT_PREVIOUS: &str = "checkpoint.previous.safetensors";
/// Metrics and loss history: the same bytes for a resumed run as for an uninterrupted
/// one (no timings; those are in [`TIMING`]).
pub(crate) const METRICS: &str = "metrics.json";
/// How long training took (seconds, iterations).
pub(crate) const TIMING: &str = "timing.json";
/// The estimated light.
pub const LIGHT: &str = "light.json";
/// The report.
pub const REPORT: &str = "report.html";
/// The avatar.
pub(crate) const AVATAR: &str = "avatar.glb";
/// The per-hand avatars for WebXR hand tracking (`left.glb`, `right.glb`, `xr.html`).
pub const XR: &str = "xr";
/// Loss curves.
pub(crate) const LOSS_PLOT: &str = "loss.png";
/// The scene a run was trained on (synthetic runs), to resume without the generator.
pub(crate) const SCENE: &str = "scene";
/// The mesh refinement's report (`train-scene --refine-mesh`, `bitt refine-hands`).
pub(crate) const REFINE: &str = "refine.json";
/// The photo with the mesh outlines before (red) and after (green) refinement.
pub(crate) const REFINE_OVERLAY: &str = "overlay.png";
/// Scores of a real multi-view run against the photographs of its novel views and poses.
pub const REAL_SCORES: &str = "real_scores.json";
/// The trained textures and light parameters (what `render-avatar` and `export` read).
pub(crate) const TEXTURES: &str = "textures/textures.safetensors";

/// Reads the fine textures `[3, T]` (left, right) of a run's
/// `textures/textures.safetensors`.
pub(crate) fn read_fine_textures(dir: &Path) -> Result<[Vec<f32>; 2], BittError> {
    let path = dir.join(TEXTURES);
    let bytes = st::read_file(&path)?;
    let r = st::Reader::open(&bytes, &path)?;
    let texture = |name: &str| -> Result<Vec<f32>, BittError> {
        Ok(r.finite_f32s(name, Some(&[Some(3), None]))?.1)
    };
    Ok([texture("left.fine")?, texture("right.fine")?])
}

/// Reads a run's `light.json` (the estimated light, training camera frame).
pub fn read_light(dir: &Path) -> Result<LightValues, BittError> {
    let path = dir.join(LIGHT);
    let text = std::fs::read_to_string(&path).map_err(|e| BittError::io(&path, e))?;
    let light: LightValues = serde_json::from_str(&text)
        .map_err(|e| BittError::format(&path, format!("not a light: {e}")))?;
    light
        .validate()
        .map_err(|e| BittError::format(&path, e.to_string()))?;
    Ok(light)
}
