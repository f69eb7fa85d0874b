//! The keypoint fit on synthetic scenes, where the true joints and camera are known: noisy
//! keypoints from the true 2D joints (`keypoints_2d` of `scene.json`) and the fit's scores.

use std::path::{Path, PathBuf};

use bitt_mesh::glam::DVec2;
use bitt_mesh::keypoints::{NUM_KEYPOINTS, TwoHandKeypoints};
use bitt_mesh::{PinholeCamera, Side, TwoHandScene, procedural_pair};
use bitt_synth::SynthScene;
use bitt_texture::procedural::noise::SplitMix64;

use super::{FitOutput, KeypointFit, keypoint_overlay};
use crate::BittError;
use crate::assets::HandAssets;
use crate::hand_priors::{FLEXION_RANGE, flexion_angles, flexion_axes};
use bitt_stdx::WithContext;

/// A keypoint fit of `scene`'s training view (seen by `camera`, with the keypoints `points`
/// read from `keypoints`) as a run folder records it (`train-scene --scene DIR --keypoints
/// FILE`): its scores against the true hands, and `fit.json`'s record with the overlay. The
/// fitted hands become the scene's given meshes (in the scene's own camera).
///
/// # Errors
/// Hands that cannot be posed or rendered.
pub fn record_synthetic_fit(
    fit: &KeypointFit,
    scene: &mut SynthScene,
    points: &TwoHandKeypoints,
    camera: &PinholeCamera,
    keypoints: &Path,
) -> Result<(FitScores, FitOutput), BittError> {
    let scores = score_fit(fit, scene, camera)?;
    let models = procedural_pair();
    let assets = HandAssets::new(models.clone(), 64)?;
    let overlay = keypoint_overlay(
        &scene.train.image,
        &models,
        &assets,
        points,
        &TwoHandScene {
            camera: *camera,
            ..fit.hands.clone()
        },
    )?;
    scene.given = TwoHandScene {
        camera: scene.given.camera,
        ..fit.hands.clone()
    };
    let record = serde_json::json!({
        "kind": "keypoint fit (synthetic scene)",
        "keypoints": keypoints.display().to_string(),
        "report": fit.report,
        "scores_vs_truth": scores,
    });
    Ok((
        scores,
        FitOutput {
            record,
            overlay,
            detection: None,
        },
    ))
}

/// The training view's true 2D joints with noise and dropped points.
#[derive(Debug, Clone)]
pub struct SyntheticKeypoints {
    /// What the fit gets.
    pub keypoints: TwoHandKeypoints,
    /// Points dropped (confidence 0).
    pub dropped: usize,
}

/// The true 2D joints of `scene`'s training view (both hands, pixels) with Gaussian noise of
/// `noise_px` pixels per coordinate and `round(drop * 42)` points dropped, seeded.
///
/// # Errors
/// A `drop` outside 0-1, a negative noise, or hands that cannot be posed.
pub fn synthetic_keypoints(
    scene: &SynthScene,
    noise_px: f64,
    drop: f64,
    seed: u64,
) -> Result<SyntheticKeypoints, BittError> {
    if !((0.0..=1.0).contains(&drop) && noise_px.is_finite() && noise_px >= 0.0) {
        return Err(BittError::Invalid(format!(
            "keypoint noise must be >= 0 px and the dropped fraction within 0-1 (got {noise_px} \
             px, {drop})"
        )));
    }
    let mut kp = scene.train.keypoints_2d()?;
    let mut rng = SplitMix64::new(seed ^ 0x4B45_5950_4F49_4E54);
    for side in Side::BOTH {
        let hand = match side {
            Side::Left => kp.left.as_mut(),
            Side::Right => kp.right.as_mut(),
        };
        for p in hand.into_iter().flatten() {
            p.x += noise_px * rng.normal();
            p.y += noise_px * rng.normal();
        }
    }
    // Exactly round(drop * n) points, chosen by a seeded shuffle.
    let n = 2 * NUM_KEYPOINTS;
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    let dropped = (drop * n as f64).round() as usize;
    for &i in &order[..dropped] {
        let hand = if i < NUM_KEYPOINTS {
            kp.left.as_mut()
        } else {
            kp.right.as_mut()
        };
        if let Some(h) = hand {
            let p = &mut h[i % NUM_KEYPOINTS];
            *p = bitt_mesh::keypoints::Keypoint {
                x: 0.0,
                y: 0.0,
                confidence: 0.0,
            };
        }
    }
    Ok(SyntheticKeypoints {
        keypoints: kp,
        dropped,
    })
}

/// A fit's scores against a synthetic scene's true training hands.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitScores {
    /// Mean distance (pixels) between the fitted joints' projections (with the fit's
    /// camera) and the true 2D joints, over all 42 joints (dropped ones included).
    pub joint_2d_px: f64,
    /// Mean root-relative 3D joint error (millimetres, camera frame; each hand's wrist at the
    /// origin), over the 40 non-wrist joints.
    pub joint_3d_mm: f64,
    /// The largest root-relative 3D joint error (millimetres).
    pub max_joint_3d_mm: f64,
    /// Smallest fitted finger flexion (degrees; negative is bent backwards).
    pub min_flexion_deg: f64,
    /// Fitted finger joints bent backwards beyond the limit.
    pub bent_backwards: usize,
    /// Smallest true finger flexion (degrees), for comparison.
    pub true_min_flexion_deg: f64,
}

/// Scores `fit` (made with `camera`, of the scene's training image) against the scene's true
/// training hands.
///
/// # Errors
/// A hand missing from the fit, or hands that cannot be posed.
pub fn score_fit(
    fit: &KeypointFit,
    scene: &SynthScene,
    camera: &PinholeCamera,
) -> Result<FitScores, BittError> {
    let models = procedural_pair();
    let truth = scene.train.hands.pose_in_camera(&models)?;
    let fitted = fit.hands.pose_in_camera(&models)?;
    let true_2d = scene.train.keypoints_2d()?;
    let axes = flexion_axes(&models);
    let (mut e2, mut n2) = (0.0, 0usize);
    let (mut e3, mut n3, mut max3) = (0.0, 0usize, 0.0f64);
    let (mut min_flex, mut true_min, mut backwards) = (f64::INFINITY, f64::INFINITY, 0usize);
    for (h, side) in Side::BOTH.into_iter().enumerate() {
        let (Some(t), Some(f)) = (truth.get(side), fitted.get(side)) else {
            return Err(BittError::Invalid(format!(
                "the fit has no {side} hand to score"
            )));
        };
        let t2 = true_2d
            .hand(side)
            .ok_or_else(|| BittError::Invalid(format!("no true {side} keypoints")))?;
        for (k, j) in f.joints.iter().enumerate() {
            let p = camera
                .camera_to_pixel(*j)
                .map_or(f64::INFINITY, |p| p.distance(DVec2::new(t2[k].x, t2[k].y)));
            e2 += p;
            n2 += 1;
        }
        for k in 1..NUM_KEYPOINTS {
            let d = ((f.joints[k] - f.joints[0]) - (t.joints[k] - t.joints[0])).length() * 1e3;
            e3 += d;
            max3 = max3.max(d);
            n3 += 1;
        }
        let flex = |p: &bitt_mesh::HandParams| {
            let aa = models.get(side).pose_axis_angles(&p.pose);
            flexion_angles(&aa, &axes[45 * h..45 * h + 45])
                .into_iter()
                .flatten()
                .collect::<Vec<f64>>()
        };
        if let Some(p) = fit.hands.hand(side) {
            for a in flex(p) {
                min_flex = min_flex.min(a.to_degrees());
                if a < FLEXION_RANGE.0 - 1e-3 {
                    backwards += 1;
                }
            }
        }
        if let Some(p) = scene.train.hands.hand(side) {
            for a in flex(p) {
                true_min = true_min.min(a.to_degrees());
            }
        }
    }
    Ok(FitScores {
        joint_2d_px: e2 / n2.max(1) as f64,
        joint_3d_mm: e3 / n3.max(1) as f64,
        max_joint_3d_mm: max3,
        min_flexion_deg: min_flex,
        bent_backwards: backwards,
        true_min_flexion_deg: true_min,
    })
}

/// One synthetic scene's keypoint fit scored against its true hands: a row of
/// `fit-eval.json` (`bitt fit-hands --scene DIR...`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct SceneFitResult {
    /// The scene (its folder, as given).
    pub scene: String,
    /// The fit's scores against the true hands.
    pub scores: FitScores,
    /// Mean keypoint residual of the hands (pixels).
    pub residual_px: f64,
    /// Seconds the fit took.
    pub seconds: f64,
    /// Keypoints dropped from the true ones.
    pub dropped: usize,
    /// The fit's notes.
    pub notes: Vec<String>,
    /// Per hand, what the fit did.
    pub hands: Vec<super::HandFitReport>,
}

impl SceneFitResult {
    /// The scene's line for the user; `dir` names the scene.
    pub fn line(&self, dir: &Path) -> String {
        let scores = &self.scores;
        format!(
            "{}: 2D joints {:.2} px, root-relative 3D {:.1} mm (max {:.1}), min flexion {:.0} deg ({} bent backwards), {:.1} s",
            dir.display(),
            scores.joint_2d_px,
            scores.joint_3d_mm,
            scores.max_joint_3d_mm,
            scores.min_flexion_deg,
            scores.bent_backwards,
            self.seconds
        )
    }
}

/// The line for the user of [`fit_eval_summary`] over `scenes` scenes.
pub fn fit_eval_line(scenes: usize, summary: &serde_json::Value) -> String {
    format!(
        "mean over {scenes} scenes: 2D joints {:.2} px, root-relative 3D {:.1} mm, {} joints bent backwards, {:.1} s per fit ({} intrinsics)",
        summary["mean_joint_2d_px"].as_f64().unwrap_or(f64::NAN),
        summary["mean_joint_3d_mm"].as_f64().unwrap_or(f64::NAN),
        summary["bent_backwards"],
        summary["mean_seconds"].as_f64().unwrap_or(f64::NAN),
        summary["intrinsics"].as_str().unwrap_or("true"),
    )
}

/// Reads each synthetic scene folder ([`SynthScene::read`]) and fits it
/// ([`fit_synthetic_scene`], named by its path, silently); `on_scene` sees each result when
/// it is done.
///
/// # Errors
/// The first folder that cannot be read (in a context `--scene DIR`) or fitted (`fitting
/// --scene DIR`).
pub fn fit_synthetic_scenes(
    dirs: &[PathBuf],
    settings: &SyntheticFitSettings,
    config: &super::FitConfig,
    device: &burn::tensor::Device,
    mut on_scene: impl FnMut(&Path, &SceneFitResult),
) -> Result<Vec<SceneFitResult>, BittError> {
    let mut results = Vec::new();
    for dir in dirs {
        let scene = SynthScene::read(dir).context_with(|| format!("--scene {}", dir.display()))?;
        let name = dir.display().to_string();
        let r = fit_synthetic_scene(&scene, name, settings, config, device, &mut super::Quiet)
            .context_with(|| format!("fitting --scene {}", dir.display()))?;
        on_scene(dir, &r);
        results.push(r);
    }
    Ok(results)
}

/// Writes [`fit_eval_summary`] as `<out>/fit-eval.json` (creating `out`) and returns the
/// file's path.
///
/// # Errors
/// An unwritable folder or file.
pub fn write_fit_eval(out: &Path, summary: &serde_json::Value) -> Result<PathBuf, BittError> {
    std::fs::create_dir_all(out).context_with(|| format!("creating {}", out.display()))?;
    let path = out.join("fit-eval.json");
    crate::outputs::write_json(&path, summary)?;
    Ok(path)
}

/// How the synthetic keypoints of [`fit_synthetic_scene`] are made and seen.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SyntheticFitSettings {
    /// Gaussian noise (pixels) added to each keypoint coordinate.
    pub noise_px: f64,
    /// Fraction of the 42 keypoints dropped.
    pub drop: f64,
    /// Seed of the noise and of the dropped points.
    pub seed: u64,
    /// Fit with the default intrinsics (focal = image diagonal, centred) instead of the
    /// scene's true ones.
    pub default_intrinsics: bool,
}

/// Fits `scene`'s training view from its noisy true keypoints ([`synthetic_keypoints`]) and
/// scores the fit against the true hands; `name` names the scene in the result.
///
/// # Errors
/// Invalid settings, a camera that cannot be made, a fit or score that fails.
pub fn fit_synthetic_scene(
    scene: &SynthScene,
    name: String,
    settings: &SyntheticFitSettings,
    config: &super::FitConfig,
    device: &burn::tensor::Device,
    observer: &mut dyn super::FitObserver,
) -> Result<SceneFitResult, BittError> {
    let kp = synthetic_keypoints(scene, settings.noise_px, settings.drop, settings.seed)?;
    let truth = scene.train.hands.camera;
    let camera = if settings.default_intrinsics {
        PinholeCamera {
            intrinsics: PinholeCamera::default_for_image(truth.width, truth.height)?.intrinsics,
            ..truth
        }
    } else {
        truth
    };
    let models = procedural_pair();
    let fit = super::fit_keypoints(&models, &kp.keypoints, &camera, config, device, observer)?;
    let scores = score_fit(&fit, scene, &camera)?;
    let residual = fit
        .report
        .hands
        .iter()
        .map(|h| h.mean_residual_px)
        .sum::<f64>()
        / fit.report.hands.len().max(1) as f64;
    Ok(SceneFitResult {
        scene: name,
        scores,
        residual_px: residual,
        seconds: fit.report.seconds,
        dropped: kp.dropped,
        notes: fit.report.notes,
        hands: fit.report.hands,
    })
}

/// `fit-eval.json`: the settings, the means and extremes over the scenes, the configuration
/// and every scene's result.
pub fn fit_eval_summary(
    results: &[SceneFitResult],
    settings: &SyntheticFitSettings,
    config: &super::FitConfig,
) -> serde_json::Value {
    let n = results.len() as f64;
    let mean = |f: &dyn Fn(&SceneFitResult) -> f64| results.iter().map(f).sum::<f64>() / n;
    serde_json::json!({
        "scenes": results.len(),
        "noise_px": settings.noise_px,
        "drop": settings.drop,
        "seed": settings.seed,
        "intrinsics": if settings.default_intrinsics { "default" } else { "true" },
        "mean_joint_2d_px": mean(&|r| r.scores.joint_2d_px),
        "mean_joint_3d_mm": mean(&|r| r.scores.joint_3d_mm),
        "max_joint_3d_mm": results.iter().map(|r| r.scores.max_joint_3d_mm).fold(0.0, f64::max),
        "bent_backwards": results.iter().map(|r| r.scores.bent_backwards).sum::<usize>(),
        "min_flexion_deg": results.iter().map(|r| r.scores.min_flexion_deg).fold(f64::INFINITY, f64::min),
        "mean_seconds": mean(&|r| r.seconds),
        "max_seconds": results.iter().map(|r| r.seconds).fold(0.0, f64::max),
        "config": config,
        "per_scene": results,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> SyntheticFitSettings {
        SyntheticFitSettings {
            noise_px: 2.0,
            drop: 0.1,
            seed: 0,
            default_intrinsics: false,
        }
    }

    /// A folder that holds no scene stops the loop with an error naming it as `--scene DIR`
    /// (its cause below), before anything is fitted.
    #[test]
    fn unreadable_scene_is_named() {
        let dir = std::env::temp_dir().join(format!("bitt-fit-noscene-{}", std::process::id()));
        let config = super::super::FitConfig::default();
        let mut seen = 0;
        let err = fit_synthetic_scenes(
            std::slice::from_ref(&dir),
            &settings(),
            &config,
            &burn::tensor::Device::flex(),
            |_, _| seen += 1,
        )
        .unwrap_err();
        assert_eq!(err.to_string(), format!("--scene {}", dir.display()));
        assert!(std::error::Error::source(&err).is_some());
        assert_eq!(seen, 0);
    }

    /// The summary goes to `<out>/fit-eval.json`, the folder created; a folder that cannot
    /// be created is an error `creating DIR`.
    #[test]
    fn fit_eval_file() {
        let root = std::env::temp_dir().join(format!("bitt-fit-eval-{}", std::process::id()));
        let out = root.join("a/b");
        let summary = fit_eval_summary(&[], &settings(), &super::super::FitConfig::default());
        let path = write_fit_eval(&out, &summary).unwrap();
        assert_eq!(path, out.join("fit-eval.json"));
        let back: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(back["scenes"], 0);
        let blocked = path.join("x");
        let err = write_fit_eval(&blocked, &summary).unwrap_err();
        assert_eq!(err.to_string(), format!("creating {}", blocked.display()));
        std::fs::remove_dir_all(&root).unwrap();
    }
}
