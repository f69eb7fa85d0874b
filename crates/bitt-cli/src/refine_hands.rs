//! `bitt refine-hands`: fit both hands' pose, shape, root and translation to the photo
//! through the differentiable renderer; writes `hands.json`, `refine.json` and `overlay.png`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::config_files::refine_config;
use bitt::refine::{check_refine_out, refine_photo, refine_scene};
use bitt_synth::SynthScene;

use crate::args::{HandsArgs, TrainingArgs};
use crate::device::DeviceName;
use crate::progress::RefineBar;

/// Arguments of `bitt refine-hands`.
#[derive(Debug, clap::Args)]
pub struct RefineHandsArgs {
    /// A synthetic scene folder (`bitt synth`, e.g. with --mesh-noise): refine its given
    /// meshes and score them against the true ones (projected vertex error, silhouette IoU).
    #[arg(long, conflicts_with_all = ["image", "annotation"])]
    pub scene: Option<PathBuf>,
    /// A photo of two interacting hands (with --annotation).
    #[arg(long, requires = "annotation")]
    pub image: Option<PathBuf>,
    /// The photo's BiTT annotation pickle (the demo `NN.pkl`) or a `hands.json`.
    #[arg(long, requires = "image")]
    pub annotation: Option<PathBuf>,
    /// The photo's hand mask (an image of the photo's size, white = hand). Default: pixels
    /// whose mean RGB is above 0.15 (the reference's rule for the demo frames).
    #[arg(long, requires = "image")]
    pub mask: Option<PathBuf>,
    /// The hand models and the texture prior (of the photometric term).
    #[command(flatten)]
    pub hands: HandsArgs,
    /// The training configuration whose image size (`quick`: 128) and texture prior the
    /// refinement uses.
    #[command(flatten)]
    pub training: TrainingArgs,
    /// A refinement configuration (JSON, the `report.config` of a `refine.json`, edited).
    #[arg(long)]
    pub refine_config: Option<PathBuf>,
    /// Working image size (default: a photo at 256, the BiTT crop the demo annotations are
    /// for and the paper's image size; a scene at its own image size).
    #[arg(long)]
    pub size: Option<usize>,
    /// Iterations of the rigid stage (default 40).
    #[arg(long)]
    pub rigid_iterations: Option<usize>,
    /// Iterations of the full stage (default 300).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Output folder.
    #[arg(long, default_value = "runs/refine-hands")]
    pub out: PathBuf,
    /// Cache folder for the fitted texture PCA (default: `$XDG_CACHE_HOME/bitt`, else
    /// `~/.cache/bitt`; never the current folder).
    #[arg(long, default_value_os_t = crate::args::default_cache_dir())]
    pub cache: PathBuf,
}

/// `bitt refine-hands`.
pub fn run(args: &RefineHandsArgs) -> Result<()> {
    let device = args.device.device()?.autodiff();
    let train = args.training.read()?;
    let config = refine_config(
        args.refine_config.as_deref(),
        args.rigid_iterations,
        args.iterations,
    )?;
    let cache = Some(args.cache.as_path());
    check_refine_out(&args.out)?;
    let mut bar = RefineBar::default();
    let lines = if let Some(dir) = &args.scene {
        if args.hands.model_dir.is_some() || args.mask.is_some() {
            bail!("--scene refines a synthetic scene's procedural hands: drop --model-dir/--mask");
        }
        let scene = SynthScene::read(dir).with_context(|| format!("--scene {}", dir.display()))?;
        if let Some(size) = args.size.filter(|s| !(32..=1024).contains(s)) {
            bail!("--size must be within 32-1024, got {size}");
        }
        let done = refine_scene(&scene, &train, args.size, &config, cache, &device, &mut bar)
            .with_context(|| format!("refining --scene {}", dir.display()))?;
        done.write(&args.out)?;
        done.report_lines()
    } else if let (Some(image), Some(annotation)) = (&args.image, &args.annotation) {
        let (hands, prior) = args.hands.sources();
        let size = args.size.unwrap_or(bitt::real::BITT_CROP_SIZE as usize);
        if !(32..=1024).contains(&size) {
            bail!("--size must be within 32-1024, got {size}");
        }
        let done = refine_photo(
            image,
            annotation,
            args.mask.as_deref(),
            &hands,
            &prior,
            &train,
            size,
            &config,
            cache,
            &device,
            &mut bar,
        )
        .with_context(|| {
            format!(
                "refining --image {} --annotation {}",
                image.display(),
                annotation.display()
            )
        })?;
        done.write(&args.out)?;
        done.report_lines(size)
    } else {
        bail!("give --scene DIR, or --image IMG --annotation FILE");
    };
    for line in lines {
        println!("{line}");
    }
    println!(
        "wrote {0}/hands.json (use it as --annotation), {0}/refine.json and {0}/overlay.png",
        args.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_tests::real_fixture::{AnnotationOptions, scratch, write_annotation, write_image};
    use std::path::Path;

    type Cli = crate::test_args::Parsed<RefineHandsArgs>;

    fn args(extra: &[&str]) -> RefineHandsArgs {
        let mut all = vec![
            "bitt",
            "--preset",
            "tiny",
            "--rigid-iterations",
            "3",
            "--iterations",
            "5",
        ];
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    fn s(p: &Path) -> &str {
        p.to_str().unwrap()
    }

    /// A photo with its annotation refines and writes the three files; `hands.json` is
    /// accepted as `--annotation` again. A mask of the wrong size, an empty mask and an
    /// annotation with NaN are clear errors that leave no output folder behind.
    #[test]
    fn photo_refines_and_bad_inputs_leave_nothing() {
        let dir = scratch("cli-refine");
        let (img, pkl, nan) = (dir.join("01.png"), dir.join("01.pkl"), dir.join("nan.pkl"));
        write_image(&img, 256, 256, None);
        write_annotation(&pkl, AnnotationOptions::default());
        write_annotation(&nan, AnnotationOptions::NAN);
        let cache = dir.join("cache");
        let out = dir.join("out");
        let common = |annotation: &Path, out: &Path| {
            vec![
                "--image".to_string(),
                s(&img).into(),
                "--annotation".into(),
                s(annotation).into(),
                "--size".into(),
                "64".into(),
                "--cache".into(),
                s(&cache).into(),
                "--out".into(),
                s(out).into(),
            ]
        };
        let with = |extra: Vec<String>| args(&extra.iter().map(String::as_str).collect::<Vec<_>>());
        run(&with(common(&pkl, &out))).unwrap();
        for f in ["hands.json", "refine.json", "overlay.png"] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
        let record: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("refine.json")).unwrap())
                .unwrap();
        assert_eq!(record["report"]["stages"].as_array().unwrap().len(), 2);
        assert!(record["silhouette_iou_vs_mask"]["after"].as_f64().unwrap() > 0.0);
        // The written hands are an annotation for every command.
        let again = dir.join("again");
        run(&with(common(&out.join("hands.json"), &again))).unwrap();
        assert!(again.join("hands.json").is_file());

        let bad_out = dir.join("bad");
        let small = dir.join("small.png");
        write_image(&small, 100, 80, None);
        let mut a = common(&pkl, &bad_out);
        a.extend(["--mask".into(), s(&small).into()]);
        let e = format!("{:#}", run(&with(a)).unwrap_err());
        assert!(e.contains("small.png") && e.contains("100x80"), "{e}");
        let empty = dir.join("empty.png");
        write_image(&empty, 256, 256, Some(&|_, _| [0, 0, 0]));
        let mut a = common(&pkl, &bad_out);
        a.extend(["--mask".into(), s(&empty).into()]);
        let e = format!("{:#}", run(&with(a)).unwrap_err());
        assert!(e.contains("empty"), "{e}");
        // Issue 38, class 3: an all-white mask used to blow the hands up to fill the photo.
        let white = dir.join("white.png");
        write_image(&white, 256, 256, Some(&|_, _| [255, 255, 255]));
        let mut a = common(&pkl, &bad_out);
        a.extend(["--mask".into(), s(&white).into()]);
        let e = format!("{:#}", run(&with(a)).unwrap_err());
        assert!(
            e.contains("white.png") && e.contains("100.0% of the photo"),
            "{e}"
        );
        let e = format!("{:#}", run(&with(common(&nan, &bad_out))).unwrap_err());
        assert!(e.contains("nan.pkl") && e.contains("NaN"), "{e}");
        assert!(
            !bad_out.exists(),
            "a failed refinement wrote {}",
            bad_out.display()
        );
        // A folder that is not ours is refused.
        let foreign = dir.join("foreign");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
        let e = format!("{:#}", run(&with(common(&pkl, &foreign))).unwrap_err());
        assert!(e.contains("not a refine-hands output"), "{e}");
        assert_eq!(
            std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
            "mine"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `--scene` refines at the scene's own image size unless `--size` says otherwise, and
    /// scores the refined meshes against the true ones.
    #[test]
    fn a_scene_is_refined_at_its_own_size() {
        let dir = scratch("cli-refine-scene");
        let synth = bitt_synth::SynthConfig {
            size: 64,
            texture_size: 64,
            novel_views: 0,
            novel_poses: 0,
            mesh_noise: Some(bitt_synth::MeshNoise::default()),
            ..bitt_synth::SynthConfig::default()
        };
        let scene = bitt_synth::generate_scene(&synth, 3, &burn::tensor::Device::flex()).unwrap();
        let folder = dir.join("scene");
        scene.write(&folder).unwrap();
        let cache = dir.join("cache");
        for (size, expect) in [(None, 64), (Some("48"), 48)] {
            let out = dir.join(format!("out-{expect}"));
            let mut extra = vec![
                "--scene",
                folder.to_str().unwrap(),
                "--cache",
                cache.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ];
            if let Some(s) = size {
                extra.extend(["--size", s]);
            }
            run(&args(&extra)).unwrap();
            let record: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join("refine.json")).unwrap())
                    .unwrap();
            assert_eq!(record["report"]["image_size"][0], expect, "{record}");
            assert!(record["vertex_error_px"]["after"]["mean"].as_f64().unwrap() >= 0.0);
        }
        let bad = dir.join("out-bad");
        let e = format!(
            "{:#}",
            run(&args(&[
                "--scene",
                folder.to_str().unwrap(),
                "--size",
                "8",
                "--out",
                bad.to_str().unwrap()
            ]))
            .unwrap_err()
        );
        assert!(e.contains("--size must be within 32-1024"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
