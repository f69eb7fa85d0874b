//! Where a run goes and what it starts from: the names a run writes at the top of its
//! folder, whether a folder is free for a new run ([`out_folder`], [`fresh_out`]), a fresh
//! run's first files ([`write_fresh_run`]: configuration, input, keypoint fit and detection,
//! refinement), and a resumed run's checkpoints ([`load_checkpoints`]).

use bitt_stdx::FileErrorExt;
use std::path::{Path, PathBuf};

use bitt_mesh::TwoHandScene;
use bitt_synth::SynthScene;

use crate::BittError;
use crate::checkpoint::Checkpoint;
use crate::files;
use crate::fit::FitOutput;
use crate::outputs::{write_json, write_png};
use crate::real::{RealInput, RealScene};
use crate::refine::Refinement;
use crate::run::write_training_refinement;
use crate::trainer::{Trainer, previous_checkpoint_path};

/// What is wrong when run folder `dir` holds neither input record: `input.json` (a real
/// run) nor `scene/scene.json` (a synthetic run); `None` when it holds one.
pub(crate) fn missing_input(dir: &Path) -> Option<String> {
    let scene = dir.join(files::SCENE).join("scene.json");
    (!RealInput::is_real_run(dir) && !scene.is_file()).then(|| {
        format!(
            "the run's input is missing: neither {} (real data) nor {} (a synthetic scene) is \
             there",
            dir.join(crate::real::files::INPUT).display(),
            scene.display()
        )
    })
}

/// The keypoint fit's record in a run folder (`train-scene --keypoints`).
pub(crate) const FIT_RECORD: &str = "fit.json";

/// The keypoint fit's overlay in a run folder.
pub(crate) const FIT_OVERLAY: &str = "fit_overlay.png";

/// Names a run writes at the top of its folder.
pub(crate) const RUN_NAMES: [&str; 25] = [
    files::CONFIG,
    files::CHECKPOINT,
    files::CHECKPOINT_PREVIOUS,
    files::TIMING,
    files::METRICS,
    files::LIGHT,
    files::REPORT,
    files::AVATAR,
    crate::avatar_export::files::STATIC,
    files::XR,
    files::LOSS_PLOT,
    files::SCENE,
    files::REFINE,
    files::REFINE_OVERLAY,
    FIT_RECORD,
    FIT_OVERLAY,
    crate::detect::DETECTION_JSON,
    crate::detect::KEYPOINTS_JSON,
    crate::detect::DETECTION_OVERLAY,
    files::REAL_SCORES,
    crate::real::files::INPUT,
    crate::real::files::INPUT_DIR,
    "textures",
    "renders",
    "turntable",
];

/// What an output folder holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OutFolder {
    /// Missing or empty: a new run may go there.
    Free,
    /// A run of ours (a checkpoint).
    Run,
    /// An earlier run of ours that stopped before its first checkpoint (its configuration
    /// and input, nothing else): a new run may replace it.
    Unfinished,
    /// Anything else: not ours.
    Foreign,
}

/// What `dir` holds.
///
/// # Errors
/// A dangling symbolic link, a file, or an unreadable folder.
pub(crate) fn out_folder(dir: &Path) -> Result<OutFolder, BittError> {
    if dir.is_symlink() && !dir.exists() {
        return Err(BittError::Invalid(format!(
            "{}: is a symbolic link to nothing; choose another --out",
            dir.display()
        )));
    }
    if !dir.exists() {
        return Ok(OutFolder::Free);
    }
    if !dir.is_dir() {
        return Err(BittError::Invalid(format!(
            "{}: exists and is not a folder",
            dir.display()
        )));
    }
    if has_checkpoint(dir) || is_finished_run(dir) {
        return Ok(OutFolder::Run);
    }
    let names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| BittError::io(dir, e))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    if names.is_empty() {
        return Ok(OutFolder::Free);
    }
    let ours = names
        .iter()
        .all(|n| RUN_NAMES.contains(&n.as_str()) || n.starts_with(".checkpoint"));
    let started = dir.join(files::CONFIG).is_file()
        && (dir.join(files::SCENE).join("scene.json").is_file()
            || dir.join(crate::real::files::INPUT).is_file());
    Ok(if ours && started {
        OutFolder::Unfinished
    } else {
        OutFolder::Foreign
    })
}

/// The folder of a new run, and a line to tell the user when it is not `out`. `out` given
/// explicitly (not `default`) must not hold a run (resume it instead), nor be a non-empty
/// folder that is not a run of ours (unless `force`, and even then no file of a name the run
/// writes may be in it); the default folder moves on to `DEFAULT-2`, `-3`, ... past earlier
/// runs and foreign folders, so rerunning the demo never touches anything.
///
/// # Errors
/// `out` cannot take a new run (the message says what to do instead).
pub fn fresh_out(
    out: &Path,
    default: &Path,
    force: bool,
) -> Result<(PathBuf, Option<String>), BittError> {
    let state = out_folder(out)?;
    match state {
        OutFolder::Free | OutFolder::Unfinished => return Ok((out.to_path_buf(), None)),
        OutFolder::Foreign if force && out != default => {
            let clash: Vec<&str> = RUN_NAMES
                .iter()
                .copied()
                .filter(|n| out.join(n).exists())
                .collect();
            if !clash.is_empty() {
                return Err(BittError::Invalid(format!(
                    "{}: --force never overwrites files it did not write, and the folder holds {} \
                     (names a run writes); choose another --out",
                    out.display(),
                    clash.join(", ")
                )));
            }
            return Ok((out.to_path_buf(), None));
        }
        _ if out == default => {}
        OutFolder::Run if !has_checkpoint(out) => {
            return Err(BittError::Invalid(format!(
                "{} already holds a finished run; choose another --out",
                out.display()
            )));
        }
        OutFolder::Run => {
            return Err(BittError::Invalid(format!(
                "{} already holds a run; use --resume {} to continue it or choose another --out",
                out.display(),
                out.display()
            )));
        }
        OutFolder::Foreign => {
            return Err(BittError::Invalid(format!(
                "{}: the folder exists, is not empty and holds no run of bitt (no {}); choose \
                 another --out, or add --force to write the run into it (it never overwrites a \
                 file of the user's)",
                out.display(),
                files::CHECKPOINT
            )));
        }
    }
    let mut n = 2;
    let next = loop {
        let dir = PathBuf::from(format!("{}-{n}", default.display()));
        if matches!(out_folder(&dir)?, OutFolder::Free | OutFolder::Unfinished) {
            break dir;
        }
        n += 1;
    };
    let note = format!(
        "{} holds {}; this run goes to {}",
        default.display(),
        if state == OutFolder::Run {
            "an earlier run"
        } else {
            "files that are not a run"
        },
        next.display()
    );
    Ok((next, Some(note)))
}

/// What a run trains on.
#[derive(Debug)]
pub enum RunInput {
    /// A synthetic scene (ground truth known).
    Synthetic(Box<SynthScene>),
    /// Real data: the record kept in the run folder and the prepared views.
    Real(Box<RealInput>, Box<RealScene>),
}

impl RunInput {
    /// The synthetic scene, if that is what the run trains on.
    pub fn synthetic(&self) -> Option<&SynthScene> {
        match self {
            RunInput::Synthetic(scene) => Some(scene),
            RunInput::Real(..) => None,
        }
    }

    /// The poses the rigged avatar's clip plays: the scene's novel poses.
    pub(crate) fn novel_pose_clip(&self) -> Vec<TwoHandScene> {
        match self {
            RunInput::Synthetic(scene) => crate::run::novel_pose_clip(scene),
            RunInput::Real(_, scene) => scene.novel_poses.iter().map(|p| p.hands.clone()).collect(),
        }
    }
}

/// Refuses path arguments that are not valid UTF-8 (`paths`: each option and its path, if
/// given) before anything is read or written: a run records its inputs' paths in
/// `input.json` and `config.json` (JSON text).
///
/// # Errors
/// The first path that is not valid UTF-8, naming its option.
pub fn check_utf8_paths(paths: &[(&str, Option<&Path>)]) -> Result<(), BittError> {
    for (flag, path) in paths {
        if let Some(path) = path
            && path.to_str().is_none()
        {
            return Err(BittError::Invalid(format!(
                "{flag} {}: the path is not valid UTF-8; a run records its input paths as JSON \
                 text. Rename it, or link it under a UTF-8 name",
                path.display()
            )));
        }
    }
    Ok(())
}

/// Creates a fresh run's folder `out` and writes what it starts from: `config.json`, the
/// input (the synthetic scene, or the real input record and images), the keypoint fit and
/// the mesh refinement when there are any.
///
/// # Errors
/// A file that cannot be written.
pub(crate) fn write_fresh_run(
    out: &Path,
    trainer: &Trainer,
    input: &RunInput,
    fit: Option<&FitOutput>,
    refinement: Option<&Refinement>,
) -> Result<(), BittError> {
    std::fs::create_dir_all(out).map_err(|e| BittError::io(out, e))?;
    let config = serde_json::to_string_pretty(&trainer.config)
        .map_err(|e| BittError::Invalid(format!("encoding the configuration: {e}")))?;
    bitt_stdx::write_atomically(&out.join(files::CONFIG), config.as_bytes())?;
    match input {
        RunInput::Synthetic(scene) => scene.write(&out.join(files::SCENE))?,
        RunInput::Real(record, scene) => record.write(out, scene)?,
    }
    if let Some(f) = fit {
        write_json(&out.join(FIT_RECORD), &f.record)?;
        let [h, w] = f.overlay.1;
        write_png(&out.join(FIT_OVERLAY), &f.overlay.0, h, w)?;
        if let Some(d) = &f.detection {
            d.write_into(out)?;
        }
    }
    if let Some(r) = refinement {
        let truth = input.synthetic().map(|scene| &scene.train.hands);
        write_training_refinement(out, trainer, r, truth)?;
    }
    Ok(())
}

/// Whether `dir` holds a checkpoint (the latest or the previous one).
pub(crate) fn has_checkpoint(dir: &Path) -> bool {
    dir.join(files::CHECKPOINT).exists() || dir.join(files::CHECKPOINT_PREVIOUS).exists()
}

/// Whether `dir` holds a run that finished writing its results: its configuration, metrics
/// and textures (with or without its checkpoints).
pub(crate) fn is_finished_run(dir: &Path) -> bool {
    dir.join(files::CONFIG).is_file()
        && dir.join(files::METRICS).is_file()
        && dir.join(files::TEXTURES).is_file()
}

/// What [`remove_checkpoints`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CheckpointCleanup {
    /// Files removed and their bytes.
    pub removed: Vec<(PathBuf, u64)>,
    /// The checkpoint kept, if any, and its bytes.
    pub kept: Option<(PathBuf, u64)>,
}

impl CheckpointCleanup {
    /// The line that tells the user what happened.
    pub fn line(&self) -> String {
        let mb = |b: u64| b as f64 / 1e6;
        let freed: u64 = self.removed.iter().map(|(_, b)| b).sum();
        match &self.kept {
            Some((path, bytes)) => format!(
                "kept {} ({:.1} MB) for `--resume --iterations N`{}",
                path.display(),
                mb(*bytes),
                if self.removed.is_empty() {
                    String::new()
                } else {
                    format!("; removed the one before it ({:.1} MB)", mb(freed))
                }
            ),
            None if self.removed.is_empty() => "no checkpoint to remove".to_string(),
            None => format!(
                "removed the run's {} checkpoint{} ({:.1} MB): the run is finished \
                 (--keep-checkpoints keeps the latest, to train it further with --resume)",
                self.removed.len(),
                if self.removed.len() == 1 { "" } else { "s" },
                mb(freed)
            ),
        }
    }
}

/// Removes the checkpoints of the finished run in `dir`, or all but the latest when
/// `keep_latest`. The previous checkpoint only guards a checkpoint write that a kill cuts
/// short, so a finished run never needs it.
///
/// # Errors
/// `dir` holds no finished run (nothing is removed then), or a file cannot be removed.
pub fn remove_checkpoints(dir: &Path, keep_latest: bool) -> Result<CheckpointCleanup, BittError> {
    if !is_finished_run(dir) {
        return Err(BittError::Invalid(format!(
            "{}: holds no finished run (config.json, metrics.json and {}); its checkpoints \
             are kept",
            dir.display(),
            files::TEXTURES
        )));
    }
    let mut cleanup = CheckpointCleanup::default();
    for (name, keep) in [
        (files::CHECKPOINT_PREVIOUS, false),
        (files::CHECKPOINT, keep_latest),
    ] {
        let path = dir.join(name);
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        if keep {
            cleanup.kept = Some((path, meta.len()));
        } else {
            std::fs::remove_file(&path).map_err(|e| BittError::io(&path, e))?;
            cleanup.removed.push((path, meta.len()));
        }
    }
    Ok(cleanup)
}

/// A run's latest checkpoint and the one before it, with warnings for the user. A latest
/// file that is missing or fails its checks is reported, and the previous one (kept by the
/// trainer) is resumed instead.
///
/// # Errors
/// Neither checkpoint is usable (the latest one's error).
pub fn load_checkpoints(
    dir: &Path,
) -> Result<(Checkpoint, Option<Checkpoint>, Vec<String>), BittError> {
    let latest_path = dir.join(files::CHECKPOINT);
    let previous_path = previous_checkpoint_path(&latest_path);
    let mut warnings = Vec::new();
    let previous = if previous_path.is_file() {
        match Checkpoint::load(&previous_path) {
            Ok(c) => Some(c),
            Err(e) => {
                warnings.push(format!("ignoring the previous checkpoint: {e}"));
                None
            }
        }
    } else {
        None
    };
    match Checkpoint::load(&latest_path) {
        Ok(latest) => Ok((latest, previous, warnings)),
        Err(e) => match previous {
            Some(p) => {
                warnings.push(format!(
                    "{e}\nresuming from the previous checkpoint {} (iteration {}) instead",
                    previous_path.display(),
                    p.iteration
                ));
                Ok((p, None, warnings))
            }
            None => Err(e.into()),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("bitt-run-folder-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A finished run loses its checkpoints (or all but the latest) and stays a run of ours:
    /// the default folder moves past it and an explicit --out naming it is refused. A folder
    /// whose results are not all written keeps its checkpoints.
    #[test]
    fn finished_runs_drop_their_checkpoints_and_stay_runs() {
        let dir = scratch("checkpoints");
        let run = dir.join("runs/train-scene");
        std::fs::create_dir_all(run.join("textures")).unwrap();
        std::fs::write(run.join(files::CHECKPOINT), [1u8; 30]).unwrap();
        std::fs::write(run.join(files::CHECKPOINT_PREVIOUS), [2u8; 20]).unwrap();
        std::fs::write(run.join(files::CONFIG), "{}").unwrap();
        let e = remove_checkpoints(&run, false).unwrap_err().to_string();
        assert!(e.contains("no finished run"), "{e}");
        assert!(has_checkpoint(&run) && run.join(files::CHECKPOINT_PREVIOUS).exists());
        std::fs::write(run.join(files::METRICS), "{}").unwrap();
        std::fs::write(run.join(files::TEXTURES), "x").unwrap();
        let kept = remove_checkpoints(&run, true).unwrap();
        assert_eq!(kept.kept, Some((run.join(files::CHECKPOINT), 30)));
        assert_eq!(
            kept.removed,
            vec![(run.join(files::CHECKPOINT_PREVIOUS), 20)]
        );
        assert!(kept.line().starts_with("kept "), "{}", kept.line());
        let removed = remove_checkpoints(&run, false).unwrap();
        assert_eq!(removed.removed, vec![(run.join(files::CHECKPOINT), 30)]);
        assert!(
            removed.line().contains("--keep-checkpoints"),
            "{}",
            removed.line()
        );
        assert!(!has_checkpoint(&run));
        assert_eq!(out_folder(&run).unwrap(), OutFolder::Run);
        assert_eq!(
            fresh_out(&run, &run, false).unwrap().0,
            dir.join("runs/train-scene-2")
        );
        let e = fresh_out(&run, &dir.join("default"), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("already holds a finished run"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Rerunning with the default folder moves on to a numbered one; an explicit folder that
    /// holds a run is refused.
    #[test]
    fn new_runs_never_overwrite_earlier_ones() {
        let dir = scratch("fresh-out");
        let default = dir.join("runs/train-scene");
        let finished = |d: &Path| {
            std::fs::create_dir_all(d).unwrap();
            std::fs::write(d.join(files::CHECKPOINT), b"x").unwrap();
        };
        assert_eq!(fresh_out(&default, &default, false).unwrap().0, default);
        finished(&default);
        let second = fresh_out(&default, &default, false).unwrap().0;
        assert_eq!(second, dir.join("runs/train-scene-2"));
        finished(&second);
        assert_eq!(
            fresh_out(&default, &default, false).unwrap().0,
            dir.join("runs/train-scene-3")
        );
        let err = fresh_out(&second, &default, false).unwrap_err().to_string();
        assert!(err.contains("already holds a run"), "{err}");
        assert_eq!(
            fresh_out(&dir.join("other"), &default, false).unwrap().0,
            dir.join("other")
        );
        // A folder of the user's is refused; --force writes into it only when nothing in it
        // has a name the run writes, and the default folder moves on past it.
        let mine = dir.join("mine");
        std::fs::create_dir_all(&mine).unwrap();
        std::fs::write(mine.join("notes.txt"), "mine").unwrap();
        let err = fresh_out(&mine, &default, false).unwrap_err().to_string();
        assert!(
            err.contains("holds no run") && err.contains("--force"),
            "{err}"
        );
        assert_eq!(fresh_out(&mine, &default, true).unwrap().0, mine);
        std::fs::write(mine.join(files::CONFIG), "{\"mine\": 1}").unwrap();
        let err = fresh_out(&mine, &default, true).unwrap_err().to_string();
        assert!(
            err.contains("never overwrites") && err.contains("config.json"),
            "{err}"
        );
        assert!(
            err.contains("holds config.json (names a run writes)"),
            "one message, no run of spaces: {err}"
        );
        let own_default = dir.join("fresh-default");
        std::fs::create_dir_all(&own_default).unwrap();
        std::fs::write(own_default.join(files::CONFIG), "{}").unwrap();
        assert_eq!(
            fresh_out(&own_default, &own_default, false).unwrap().0,
            dir.join("fresh-default-2")
        );
        // An unfinished run of ours (configuration and input, no checkpoint) is replaced.
        let unfinished = dir.join("unfinished");
        std::fs::create_dir_all(unfinished.join(files::SCENE)).unwrap();
        std::fs::write(unfinished.join(files::CONFIG), "{}").unwrap();
        std::fs::write(unfinished.join(files::SCENE).join("scene.json"), "{}").unwrap();
        assert_eq!(
            fresh_out(&unfinished, &default, false).unwrap().0,
            unfinished
        );
        // A dangling symbolic link is named as such.
        #[cfg(unix)]
        {
            let link = dir.join("dangling");
            std::os::unix::fs::symlink(dir.join("nowhere"), &link).unwrap();
            let err = fresh_out(&link, &default, false).unwrap_err().to_string();
            assert!(err.contains("symbolic link to nothing"), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
