//! The pose options `render-avatar` and `export` share: another annotation's hands or a named
//! pose of the synthetic generator, with the avatar's own hand shapes.

use std::path::PathBuf;

use anyhow::{Context, Result};
use bitt::real::{annotation_pose, parse_pose_family};
use bitt::saved::SavedRun;
use bitt_mesh::TwoHandScene;

/// Pose options (flattened into a command's arguments).
#[derive(Debug, clap::Args)]
pub struct OtherPoseArgs {
    /// Pose the hands as in another BiTT annotation pickle (the demo `NN.pkl` layout) or
    /// hands.json, seen by its camera cropped around the hands like a training view.
    #[arg(long, conflicts_with = "procedural_pose")]
    pub pose: Option<PathBuf>,
    /// Pose the hands in a named pose of the synthetic generator (clasp, interlaced,
    /// palm_on_back, palm_over_palm, side_by_side, finger_gun, pinch, fist_in_palm, prayer)
    /// with the avatar's hand shapes, seen from the front and above.
    #[arg(long)]
    pub procedural_pose: Option<String>,
    /// Seed of the procedural pose's jitter.
    #[arg(long, default_value_t = 0, requires = "procedural_pose")]
    pub pose_seed: u64,
}

impl OtherPoseArgs {
    /// The hands these options ask for, `None` when neither option is given.
    pub fn hands(&self, saved: &SavedRun) -> Result<Option<TwoHandScene>> {
        if let Some(path) = &self.pose {
            let hands = annotation_pose(path, &saved.models(), saved.image_size())
                .with_context(|| format!("--pose {}", path.display()))?;
            return Ok(Some(hands));
        }
        let Some(name) = &self.procedural_pose else {
            return Ok(None);
        };
        let family = parse_pose_family(name).context("--procedural-pose")?;
        Ok(Some(saved.procedural_pose(family, self.pose_seed)?))
    }

    /// Checks the names given before any file is read.
    pub fn check(&self) -> Result<()> {
        if let Some(name) = &self.procedural_pose {
            parse_pose_family(name).context("--procedural-pose")?;
        }
        Ok(())
    }
}
