//! The configuration files the commands take (training, mesh refinement, keypoint fit): read
//! and checked when given, else the preset or the defaults.

use std::path::Path;

use bitt_nets::Preset;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::BittError;
use crate::config::{TrainConfig, read_config};
use crate::fit::FitConfig;
use crate::refine::RefineConfig;
use bitt_stdx::WithContext;

/// The text of configuration file `path`.
fn read_text(path: &Path) -> Result<String, BittError> {
    Ok(std::fs::read_to_string(path).context_with(|| format!("reading {}", path.display()))?)
}

/// The configuration in `config` (a full [`TrainConfig`] as JSON), else the named preset.
///
/// # Errors
/// The file cannot be read or is not a valid configuration.
pub fn training_config(config: Option<&Path>, preset: Preset) -> Result<TrainConfig, BittError> {
    match config {
        Some(path) => Ok(TrainConfig::from_json(&read_text(path)?, path)?),
        None => Ok(TrainConfig::preset(preset)),
    }
}

/// As [`training_config`], for training on a real photo: the named preset is
/// [`TrainConfig::preset_for_photo`] (a file is taken as it is).
///
/// # Errors
/// The file cannot be read or is not a valid configuration.
pub fn photo_training_config(
    config: Option<&Path>,
    preset: Preset,
) -> Result<TrainConfig, BittError> {
    match config {
        Some(_) => training_config(config, preset),
        None => Ok(TrainConfig::preset_for_photo(preset)),
    }
}

/// `what` read from `file` and checked by `validate` (its error then names the file), else
/// the default.
fn checked_file<T: Serialize + DeserializeOwned + Default, E: std::fmt::Display>(
    file: Option<&Path>,
    what: &str,
    validate: impl Fn(&T) -> Result<(), E>,
) -> Result<T, BittError> {
    let Some(path) = file else {
        return Ok(T::default());
    };
    let config: T = read_config(&read_text(path)?, path, what)?;
    validate(&config).map_err(|e| BittError::Invalid(format!("{}: {e}", path.display())))?;
    Ok(config)
}

/// The refinement configuration in `file` (the `report.config` of a `refine.json`), else
/// the default, with the iterations of its two stages replaced when given.
///
/// # Errors
/// The file cannot be read or is not a valid configuration, or an iteration count is out of
/// range.
pub fn refine_config(
    file: Option<&Path>,
    rigid: Option<usize>,
    full: Option<usize>,
) -> Result<RefineConfig, BittError> {
    let mut config = checked_file(file, "a refinement configuration", RefineConfig::validate)?;
    if let Some(n) = rigid {
        config.rigid_iterations = n;
    }
    if let Some(n) = full {
        config.full_iterations = n;
    }
    config.validate()?;
    Ok(config)
}

/// The keypoint-fit configuration in `file` (the `report.config` of a `fit.json`), else the
/// default.
///
/// # Errors
/// The file cannot be read or is not a valid configuration.
pub fn fit_config(file: Option<&Path>) -> Result<FitConfig, BittError> {
    let config = checked_file(file, "a keypoint-fit configuration", FitConfig::validate)?;
    if file.is_none() {
        config.validate()?;
    }
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::error_chain;

    /// Files are read and checked (errors name the file and the field), the stage
    /// iterations replace the file's, and without a file the preset or defaults hold.
    #[test]
    fn configuration_files_are_read_checked_and_overridden() {
        let dir = std::env::temp_dir().join(format!("bitt-config-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let refine = dir.join("refine.json");
        std::fs::write(&refine, r#"{"rigid_iterations": 2, "full_iterations": 3}"#).unwrap();
        let c = refine_config(Some(&refine), None, None).unwrap();
        assert_eq!((c.rigid_iterations, c.full_iterations), (2, 3));
        let c = refine_config(Some(&refine), Some(5), Some(7)).unwrap();
        assert_eq!((c.rigid_iterations, c.full_iterations), (5, 7));
        let d = refine_config(None, None, None).unwrap();
        let default = RefineConfig::default();
        assert_eq!(
            (d.rigid_iterations, d.full_iterations),
            (default.rigid_iterations, default.full_iterations)
        );
        let typo = dir.join("typo.json");
        std::fs::write(&typo, r#"{"rigid_iteration": 2}"#).unwrap();
        let e = error_chain(&refine_config(Some(&typo), None, None).unwrap_err());
        assert!(
            e.contains("typo.json") && e.contains("rigid_iteration"),
            "{e}"
        );
        let e = error_chain(&fit_config(Some(&typo)).unwrap_err());
        assert!(e.contains("typo.json") && e.contains("keypoint-fit"), "{e}");
        let missing = dir.join("missing.json");
        let e = error_chain(&training_config(Some(&missing), Preset::Tiny).unwrap_err());
        assert!(
            e.starts_with("reading ") && e.contains("missing.json"),
            "{e}"
        );
        let tiny = training_config(None, Preset::Tiny).unwrap();
        assert_eq!(
            serde_json::to_value(&tiny).unwrap(),
            serde_json::to_value(TrainConfig::preset(Preset::Tiny)).unwrap()
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
