//! Argument groups several commands share (flattened with `#[command(flatten)]`): the
//! training configuration, the hand models and texture prior of real data, and the keypoint
//! options.

use std::path::{Path, PathBuf};

use anyhow::Result;
use bitt::TrainConfig;
use bitt::fit::{FitConfig, KeypointSource, parse_intrinsics};
use bitt::real::{HandSource, PriorSource};
use bitt_mesh::keypoints::KeypointFormat;
use bitt_nets::Preset;

/// The training configuration (`train-scene`, `eval`, `refine-hands`: its image size and
/// texture prior).
#[derive(Debug, Clone, clap::Args)]
pub struct TrainingArgs {
    /// Named configuration: paper, quick or tiny.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
    /// A full training configuration (a run's `config.json`, edited) instead of --preset.
    #[arg(long, conflicts_with = "preset")]
    pub config: Option<PathBuf>,
}

impl TrainingArgs {
    /// The configuration these options name.
    pub fn read(&self) -> Result<TrainConfig> {
        Ok(bitt::config_files::training_config(
            self.config.as_deref(),
            self.preset,
        )?)
    }

    /// The configuration these options name, for training on a real photo (`quick` at the
    /// photo's crop size: `TrainConfig::preset_for_photo`).
    pub fn read_for_photo(&self) -> Result<TrainConfig> {
        Ok(bitt::config_files::photo_training_config(
            self.config.as_deref(),
            self.preset,
        )?)
    }
}

/// The hand models and texture prior of real data (`train-scene`, `refine-hands`,
/// `fit-hands`).
#[derive(Debug, Clone, clap::Args)]
pub struct HandsArgs {
    /// Real data: folder with MANO_LEFT / MANO_RIGHT (`.pkl` or `.safetensors`); needs
    /// --html-dir. Default: the procedural hands.
    #[arg(long, conflicts_with = "procedural")]
    pub model_dir: Option<PathBuf>,
    /// Real data: use the procedural hands (the default without --model-dir).
    #[arg(long)]
    pub procedural: bool,
    /// Real data: HTML's TextureBasis folder (html.safetensors or model_wosr/model.pkl, and
    /// uvs*.pkl) as the texture prior, resampled to the preset's texture size; needs
    /// --model-dir. Default: the procedural texture PCA.
    #[arg(long, requires = "model_dir")]
    pub html_dir: Option<PathBuf>,
}

impl HandsArgs {
    /// The sources these options name.
    pub fn sources(&self) -> (HandSource, PriorSource) {
        bitt::real::sources(self.model_dir.as_deref(), self.html_dir.as_deref())
    }
}

/// Keypoint file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// OpenPose `--write_json` (`people[0].hand_left/right_keypoints_2d`).
    Openpose,
    /// MediaPipe HandLandmarker results saved as JSON (Python or JS field names).
    Mediapipe,
    /// `{"left": [[x, y, c], ...], "right": [...]}` in OpenPose order, pixels.
    Plain,
}

impl From<FormatArg> for KeypointFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Openpose => KeypointFormat::OpenPose,
            FormatArg::Mediapipe => KeypointFormat::MediaPipe,
            FormatArg::Plain => KeypointFormat::Plain,
        }
    }
}

/// The keypoint options of `fit-hands` and `train-scene`.
#[derive(Debug, Clone, clap::Args)]
pub struct KeypointArgs {
    /// The keypoint file's format (default: guessed from its content).
    #[arg(long, value_enum, requires = "keypoints")]
    pub format: Option<FormatArg>,
    /// The photo is a mirrored selfie (as a front camera shows it): photo, keypoints and mask
    /// are flipped left-right before the fit, so each hand gets its own side's model.
    /// Default: an ordinary photo. (MediaPipe's labels are read in each API's convention
    /// either way; see --labels-as-is.)
    #[arg(long, requires = "keypoints")]
    pub mirrored: bool,
    /// MediaPipe files: keep the hands' labels as the file gives them. By default the legacy
    /// Solutions API's labels (`multi_handedness`) are swapped, since that API labels hands
    /// as if every photo were a mirrored selfie, and the Tasks API's are kept (it labels each
    /// hand as it appears). Use this when the labels in the file are already correct.
    #[arg(long, requires = "keypoints")]
    pub labels_as_is: bool,
    /// Camera intrinsics `fx,fy,cx,cy` in pixels of the photo, for the keypoint fit (of
    /// --keypoints, or of the hands detected in a photo given alone). Default: focal length =
    /// the image diagonal, principal point at the centre.
    #[arg(long)]
    pub intrinsics: Option<String>,
    /// A keypoint-fit configuration (JSON, the `report.config` of a `fit.json`, edited).
    #[arg(long)]
    pub fit_config: Option<PathBuf>,
}

impl KeypointArgs {
    /// The source of keypoint file `path`.
    pub fn source(&self, path: &Path) -> KeypointSource {
        KeypointSource {
            path: path.to_path_buf(),
            format: self.format.map(Into::into),
            mirrored: self.mirrored,
            labels_as_is: self.labels_as_is,
        }
    }

    /// The intrinsics of `--intrinsics`.
    pub fn intrinsics(&self) -> Result<Option<[f64; 4]>> {
        Ok(match &self.intrinsics {
            Some(t) => Some(parse_intrinsics(t)?),
            None => None,
        })
    }

    /// The fit configuration.
    pub fn config(&self) -> Result<FitConfig> {
        Ok(bitt::config_files::fit_config(self.fit_config.as_deref())?)
    }
}

/// The default `--cache`: `$XDG_CACHE_HOME/bitt`, else `$HOME/.cache/bitt` (the XDG base
/// directory rule), else `runs/cache` when neither is set. Never the current directory when
/// the user has a home: a run with `--out` elsewhere leaves nothing behind there.
pub fn default_cache_dir() -> PathBuf {
    let non_empty = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    non_empty("XDG_CACHE_HOME")
        .filter(|p| p.is_absolute())
        .or_else(|| non_empty("HOME").map(|h| h.join(".cache")))
        .map_or_else(|| PathBuf::from("runs/cache"), |c| c.join("bitt"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cache is the user's cache folder, not the current one (issue 37).
    #[test]
    fn the_default_cache_is_the_users_cache_folder() {
        let dir = default_cache_dir();
        if std::env::var_os("HOME").is_some_and(|h| !h.is_empty()) {
            assert!(
                dir.is_absolute() && dir.ends_with("bitt"),
                "{}",
                dir.display()
            );
        } else {
            assert_eq!(dir, PathBuf::from("runs/cache"));
        }
    }
}
