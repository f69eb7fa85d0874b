//! `bitt fit-hands`: fit both hands to a photo's 2D keypoints (OpenPose, MediaPipe or plain
//! JSON); writes `hands.json`, `fit.json` and `overlay.png`. With `--scene`, the same fit on
//! synthetic scenes from their noisy true keypoints, scored against the true hands.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::config_files::{refine_config, training_config};
use bitt::fit::{
    FitConfig, SyntheticFitSettings, check_fit_out, fit_eval_line, fit_eval_summary, fit_photo,
    fit_synthetic_scenes, write_fit_eval, write_fit_outputs,
};
use bitt_nets::Preset;

use crate::args::{HandsArgs, KeypointArgs};
use crate::device::DeviceName;
use bitt::progress::{FitBar, RefineBar};

/// Arguments of `bitt fit-hands`.
#[derive(Debug, clap::Args)]
pub struct FitHandsArgs {
    /// A photo of two interacting hands (with --keypoints).
    #[arg(long, requires = "keypoints", conflicts_with = "scene")]
    pub image: Option<PathBuf>,
    /// The photo's 2D hand keypoints: OpenPose JSON, MediaPipe HandLandmarker JSON or plain
    /// JSON (see docs/keypoints.md).
    #[arg(long, requires = "image")]
    pub keypoints: Option<PathBuf>,
    /// Keypoint format, mirroring, intrinsics and fit configuration.
    #[command(flatten)]
    pub keypoint: KeypointArgs,
    /// The photo's hand mask (white = hand, the photo's size): after the keypoint fit, the
    /// hands are refined against it (the silhouette refinement of `bitt refine-hands`).
    #[arg(long, requires = "image")]
    pub mask: Option<PathBuf>,
    /// A refinement configuration (JSON) for --mask.
    #[arg(long, requires = "mask")]
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
    /// The hand models (and, with --mask, the texture prior of the refinement).
    #[command(flatten)]
    pub hands: HandsArgs,
    /// Preset whose texture prior the --mask refinement uses.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Output folder.
    #[arg(long, default_value = "runs/fit-hands")]
    pub out: PathBuf,
    /// Cache folder for the fitted texture PCA (--mask).
    #[arg(long, default_value = "runs/cache")]
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
    let (Some(image), Some(keypoints)) = (&args.image, &args.keypoints) else {
        bail!("give --image IMG --keypoints FILE, or --scene DIR...");
    };
    check_fit_out(&args.out)?;
    let device = args.device.device()?.autodiff();
    let (hands, prior) = args.hands.sources();
    let refine = match &args.mask {
        Some(_) => Some((
            training_config(None, args.preset)?,
            refine_config(args.refine_config.as_deref(), None, None)?,
        )),
        None => None,
    };
    let mut refine_bar = RefineBar::default();
    let done = fit_photo(
        image,
        &args.keypoint.source(keypoints),
        args.keypoint.intrinsics()?,
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
    .with_context(|| {
        format!(
            "fitting --image {} --keypoints {}",
            image.display(),
            keypoints.display()
        )
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
