//! `bitt fit-hands`: fit both hands to a photo's 2D keypoints (OpenPose, MediaPipe or plain
//! JSON, or without `--keypoints` those the built-in detector finds); writes `hands.json`,
//! `fit.json` and `overlay.png`. With `--scene`, the same fit on synthetic scenes from their
//! noisy true keypoints, scored against the true hands.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::config_files::{refine_config, training_config};
use bitt::fit::{
    FitConfig, PhotoKeypoints, SyntheticFitSettings, check_fit_out, fit_eval_line,
    fit_eval_summary, fit_photo, fit_synthetic_scenes, write_fit_eval, write_fit_outputs,
};
use bitt_nets::Preset;

use crate::args::{HandsArgs, KeypointArgs};
use crate::device::DeviceName;
use crate::progress::{FitBar, RefineBar};

/// Arguments of `bitt fit-hands`.
#[derive(Debug, clap::Args)]
pub struct FitHandsArgs {
    /// A photo of two interacting hands. Without --keypoints, both hands are found by the
    /// built-in detector first (as `bitt detect-hands`; an error naming the photo when it does
    /// not find both), fitted to its keypoints with the default camera, and refined against
    /// the photo: against --mask, else against the reference's rule (pixels whose mean RGB is
    /// above 0.15 are hand). The folder also gets detection.json, keypoints.json and
    /// detection_overlay.png.
    #[arg(long, conflicts_with = "scene")]
    pub image: Option<PathBuf>,
    /// The photo's 2D hand keypoints: OpenPose JSON, MediaPipe HandLandmarker JSON or plain
    /// JSON (see docs/keypoints.md). Without it the photo's hands are detected.
    #[arg(long, requires = "image")]
    pub keypoints: Option<PathBuf>,
    /// Keypoint format, mirroring, intrinsics and fit configuration.
    #[command(flatten)]
    pub keypoint: KeypointArgs,
    /// The photo's hand mask (white = hand, the photo's size): after the keypoint fit, the
    /// hands are refined against it (the silhouette refinement of `bitt refine-hands`).
    #[arg(long, requires = "image")]
    pub mask: Option<PathBuf>,
    /// A refinement configuration (JSON) for the refinement (--mask, or a photo without
    /// --keypoints).
    #[arg(long, requires = "image")]
    pub refine_config: Option<PathBuf>,
    /// Synthetic scene folders (`bitt synth`), repeatable: fit each training view's true 2D
    /// joints (from `scene.json`) with noise and dropped points, and score the fit against
    /// the true hands (2D joint error, root-relative 3D joint error, fingers bent backwards).
    #[arg(long, num_args = 1..)]
    pub scene: Vec<PathBuf>,
    /// Synthetic: Gaussian noise (pixels) added to each keypoint coordinate.
    #[arg(long, default_value_t = 2.0)]
    pub noise_px: f64,
    /// Synthetic: fraction of the 42 keypoints dropped.
    #[arg(long, default_value_t = 0.1)]
    pub drop: f64,
    /// Synthetic: seed of the noise and of the dropped points.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic: fit with the default intrinsics (focal = image diagonal, centred) instead
    /// of the scene's true ones.
    #[arg(long)]
    pub default_intrinsics: bool,
    /// The hand models (and the texture prior of the refinement).
    #[command(flatten)]
    pub hands: HandsArgs,
    /// Preset whose texture prior the refinement uses.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Output folder.
    #[arg(long, default_value = "runs/fit-hands")]
    pub out: PathBuf,
    /// Cache folder for the fitted texture PCA (the refinement) (default: `$XDG_CACHE_HOME/bitt`, else
    /// `~/.cache/bitt`; never the current folder).
    #[arg(long, default_value_os_t = crate::args::default_cache_dir())]
    pub cache: PathBuf,
}

fn run_scenes(args: &FitHandsArgs, config: &FitConfig) -> Result<()> {
    if args.hands.model_dir.is_some() {
        bail!("--scene fits a synthetic scene's procedural hands: drop --model-dir");
    }
    if args.keypoint.intrinsics.is_some() {
        bail!(
            "--scene uses the scene's true intrinsics or, with --default-intrinsics, the default"
        );
    }
    let device = args.device.device()?.autodiff();
    let settings = SyntheticFitSettings {
        noise_px: args.noise_px,
        drop: args.drop,
        seed: args.seed,
        default_intrinsics: args.default_intrinsics,
    };
    let results = fit_synthetic_scenes(&args.scene, &settings, config, &device, |dir, r| {
        println!("{}", r.line(dir));
    })?;
    let summary = fit_eval_summary(&results, &settings, config);
    println!("{}", fit_eval_line(results.len(), &summary));
    let path = write_fit_eval(&args.out, &summary)?;
    println!("wrote {}", path.display());
    Ok(())
}

/// `bitt fit-hands`.
pub fn run(args: &FitHandsArgs) -> Result<()> {
    let config = args.keypoint.config()?;
    if !args.scene.is_empty() {
        return run_scenes(args, &config);
    }
    let Some(image) = &args.image else {
        bail!("give --image IMG [--keypoints FILE], or --scene DIR...");
    };
    if args.keypoints.is_some() && args.mask.is_none() && args.refine_config.is_some() {
        bail!(
            "--refine-config configures the refinement, which runs with --mask or, without \
             --keypoints, against the photo; add --mask or drop --refine-config"
        );
    }
    let intrinsics = args.keypoint.intrinsics()?;
    check_fit_out(&args.out)?;
    let device = args.device.device()?.autodiff();
    let (hands, prior) = args.hands.sources();
    // With a keypoint file the refinement needs --mask; detected hands are always refined.
    let refine = match args.mask.is_some() || args.keypoints.is_none() {
        true => Some((
            training_config(None, args.preset)?,
            refine_config(args.refine_config.as_deref(), None, None)?,
        )),
        false => None,
    };
    let source = args.keypoints.as_deref().map(|k| args.keypoint.source(k));
    let keypoints = match &source {
        Some(s) => PhotoKeypoints::File(s),
        None => {
            let found = bitt::detect::detect_photo(image, &device)?;
            for line in found.lines() {
                println!("{line}");
            }
            found.detection.require_both(image)?;
            PhotoKeypoints::Detected(Box::new(found))
        }
    };
    let mut refine_bar = RefineBar::default();
    let done = fit_photo(
        image,
        keypoints,
        intrinsics,
        args.mask.as_deref(),
        &hands,
        &prior,
        &config,
        refine.as_ref().map(|(t, r)| {
            (
                t,
                r,
                &mut refine_bar as &mut dyn bitt::refine::RefineObserver,
            )
        }),
        Some(args.cache.as_path()),
        &device,
        &mut FitBar::default(),
    )
    .with_context(|| match &args.keypoints {
        Some(k) => format!(
            "fitting --image {} --keypoints {}",
            image.display(),
            k.display()
        ),
        None => format!("fitting the hands detected in --image {}", image.display()),
    })?;
    eprintln!();
    write_fit_outputs(&args.out, &done)?;
    for line in done.report_lines(&args.out) {
        println!("{line}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::glam::DVec3;
    use bitt_mesh::keypoints::KeypointFormat;
    use bitt_mesh::keypoints::TwoHandKeypoints;
    use bitt_mesh::{HandParams, HandPose, PinholeCamera, Side};
    use bitt_tests::real_fixture::{scratch, write_image};
    use std::path::Path;

    type Cli = crate::test_args::Parsed<FitHandsArgs>;

    fn args(extra: &[String]) -> FitHandsArgs {
        let mut all = vec!["bitt".to_string()];
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    fn s(p: &Path) -> String {
        p.to_str().unwrap().to_string()
    }

    /// Both procedural hands in front of the default camera of a 256-pixel photo, projected.
    fn plain_keypoints() -> String {
        let models = bitt_mesh::procedural_pair();
        let camera = PinholeCamera::default_for_image(256, 256).unwrap();
        let hand = |side: Side, rot: DVec3, x: f64| {
            let p = HandParams {
                root_rotation: bitt_mesh::lbs::rodrigues(rot),
                pose: HandPose::Pca(vec![0.0; 45]),
                betas: vec![0.0; 10],
                trans: DVec3::new(x, 0.0, 0.6),
            };
            let joints = models.get(side).forward(&p).unwrap().joints;
            bitt_mesh::keypoints::project_points(&joints, &camera, 0.9)
        };
        TwoHandKeypoints {
            left: Some(hand(Side::Left, DVec3::new(0.2, 1.0, 0.1), -0.05)),
            right: Some(hand(Side::Right, DVec3::new(-0.2, -1.0, 0.3), 0.06)),
            format: KeypointFormat::Plain,
            notes: Vec::new(),
        }
        .to_plain_json()
    }

    /// `fit-hands --image` alone: the hands are detected, fitted and refined against the
    /// photo's threshold mask, and the folder also holds the detection. `--refine-config`
    /// with keypoints but no mask (nothing to configure) is refused.
    #[test]
    fn photo_alone_is_detected_fitted_and_refined() {
        let dir = scratch("cli-fit-photo");
        let img = dir.join("hands.png");
        bitt_tests::real_fixture::write_synthetic_photo(
            &img,
            bitt_tests::real_fixture::TWO_HAND_PHOTO_SEED,
        );
        let cfg = dir.join("refine.json");
        std::fs::write(&cfg, r#"{"rigid_iterations": 2, "full_iterations": 3}"#).unwrap();
        let out = dir.join("out");
        let a = args(&[
            "--image".into(),
            s(&img),
            "--refine-config".into(),
            s(&cfg),
            "--preset".into(),
            "tiny".into(),
            "--out".into(),
            s(&out),
            "--cache".into(),
            s(&dir.join("cache")),
        ]);
        assert!(a.keypoints.is_none());
        run(&a).unwrap();
        for f in [
            "hands.json",
            "fit.json",
            "overlay.png",
            "detection.json",
            "keypoints.json",
            "detection_overlay.png",
        ] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
        let record: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
        assert_eq!(record["keypoints"], "detected in the photo");
        assert_eq!(
            record["refinement"]["mask"], "mean RGB above 0.15",
            "{record}"
        );
        assert_eq!(record["report"]["hands"].as_array().unwrap().len(), 2);
        // The keypoint residual after the refinement is reported beside the fit's.
        let after = record["refined_residual_px"].as_array().unwrap();
        assert!(after.iter().all(|r| r.as_f64().unwrap() >= 0.0), "{record}");
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image".into(),
                s(&img),
                "--keypoints".into(),
                s(&out.join("keypoints.json")),
                "--refine-config".into(),
                s(&cfg),
                "--out".into(),
                s(&dir.join("other")),
            ]))
            .unwrap_err()
        );
        assert!(e.contains("--refine-config"), "{e}");
        assert!(!dir.join("other").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A photo with its keypoints fits and writes the three files; `hands.json` is an
    /// annotation again. Malformed keypoints, a mask of the wrong size and a foreign output
    /// folder are clear errors that write nothing.
    #[test]
    fn photo_fits_and_bad_inputs_leave_nothing() {
        let dir = scratch("cli-fit");
        let (img, kp) = (dir.join("photo.png"), dir.join("kp.json"));
        write_image(&img, 256, 256, None);
        std::fs::write(&kp, plain_keypoints()).unwrap();
        let out = dir.join("out");
        let common = |keypoints: &Path, out: &Path| {
            vec![
                "--image".to_string(),
                s(&img),
                "--keypoints".into(),
                s(keypoints),
                "--out".into(),
                s(out),
                "--cache".into(),
                s(&dir.join("cache")),
            ]
        };
        run(&args(&common(&kp, &out))).unwrap();
        for f in ["hands.json", "fit.json", "overlay.png"] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
        let record: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
        let hands = record["report"]["hands"].as_array().unwrap();
        assert_eq!(hands.len(), 2);
        for h in hands {
            assert!(h["mean_residual_px"].as_f64().unwrap() < 1.5, "{h}");
            assert_eq!(h["residual_px"].as_array().unwrap().len(), 21);
        }
        let scene = bitt_mesh::load_bitt_annotation(&out.join("hands.json"), (256, 256)).unwrap();
        assert!(scene.left.is_some() && scene.right.is_some());
        // Rerunning into its own folder is fine.
        run(&args(&common(&kp, &out))).unwrap();

        let bad_out = dir.join("bad");
        let short = dir.join("short.json");
        std::fs::write(&short, r#"{"left": [[1, 2, 1], [3, 4, 1]]}"#).unwrap();
        let e = format!("{:#}", run(&args(&common(&short, &bad_out))).unwrap_err());
        assert!(e.contains("short.json") && e.contains("left"), "{e}");
        let small = dir.join("small.png");
        write_image(&small, 100, 80, None);
        let mut a = common(&kp, &bad_out);
        a.extend(["--mask".into(), s(&small)]);
        let e = format!("{:#}", run(&args(&a)).unwrap_err());
        assert!(e.contains("small.png") && e.contains("100x80"), "{e}");
        // Issue 38, class 3: an all-white mask used to blow the hands up to fill the photo.
        let white = dir.join("white.png");
        write_image(&white, 256, 256, Some(&|_, _| [255, 255, 255]));
        let mut a = common(&kp, &bad_out);
        a.extend(["--mask".into(), s(&white)]);
        let e = format!("{:#}", run(&args(&a)).unwrap_err());
        assert!(
            e.contains("white.png") && e.contains("100.0% of the photo"),
            "{e}"
        );
        let mut a = common(&kp, &bad_out);
        a.extend(["--intrinsics".into(), "600,600".into()]);
        let e = format!("{:#}", run(&args(&a)).unwrap_err());
        assert!(e.contains("--intrinsics"), "{e}");
        assert!(
            !bad_out.exists(),
            "a failed fit wrote {}",
            bad_out.display()
        );
        let foreign = dir.join("foreign");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
        let e = format!("{:#}", run(&args(&common(&kp, &foreign))).unwrap_err());
        assert!(e.contains("not a fit-hands output"), "{e}");
        assert_eq!(
            std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
            "mine"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
