//! `bitt train-scene`: train BiTT on one scene (synthetic, or real data: a photo with its
//! annotation pickle or keypoints or alone, or an InterHand2.6M scene) and write the run
//! folder (the main job).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use crate::progress::{SetupLines, TrainBar};
use anyhow::{Result, bail};
use bitt::config_files::refine_config;
use bitt::files;
use bitt::run_folder::{check_utf8_paths, fresh_out, remove_checkpoints};
use bitt::train_scene::{
    FreshRequest, KeypointInput, SceneInput, finish_run, resumed_run, start_fresh, summary_lines,
    training_line, unfinished_error,
};
use bitt_mesh::interhand::{InterHandSelection, PAPER_NOVEL_POSES, PAPER_NOVEL_VIEWS};

use crate::args::{HandsArgs, KeypointArgs, TrainingArgs};
use crate::device::DeviceName;

/// Where a run goes without `--out`.
const DEFAULT_OUT: &str = "runs/train-scene";

/// Arguments of `bitt train-scene`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("image_hands").args(["annotation", "keypoints"])))]
pub struct TrainSceneArgs {
    /// A synthetic scene folder (`bitt synth`). Default: the built-in demo scene, generated
    /// (and cached) by the synthetic generator.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Real data: a photograph of two interacting hands, with --annotation (whose camera is
    /// for the reference's 256x256 crop, the BiTT demo `NN.jpg`), with --keypoints (any
    /// size; the hands are fitted to them first, as `bitt fit-hands` does), or alone (any
    /// size): both hands are found by the built-in detector, fitted to its keypoints with
    /// the default camera and refined against the photo (--mask, else pixels whose mean RGB
    /// is above 0.15 are hand) before training. The run folder keeps the detection
    /// (detection.json, keypoints.json, detection_overlay.png; report.html shows it) and
    /// the fit (fit.json, fit_overlay.png). An error names the photo when not both hands are
    /// found.
    #[arg(long, conflicts_with_all = ["scene", "interhand"])]
    pub image: Option<PathBuf>,
    /// Real data: the image's BiTT annotation pickle (the demo `NN.pkl` layout) or a
    /// `hands.json` (`bitt refine-hands`, `bitt fit-hands`).
    #[arg(long, requires = "image")]
    pub annotation: Option<PathBuf>,
    /// 2D hand keypoints (OpenPose, MediaPipe or plain JSON; docs/keypoints.md) of --image,
    /// or of a synthetic --scene's training view: both hands are fitted to them, and the run
    /// trains on the fitted hands. The run folder gets `fit.json` and `fit_overlay.png`.
    #[arg(long, conflicts_with_all = ["annotation", "interhand"])]
    pub keypoints: Option<PathBuf>,
    /// Keypoint format, mirroring, intrinsics and fit configuration (with --keypoints).
    #[command(flatten)]
    pub keypoint: KeypointArgs,
    /// With --image --keypoints, or --image alone: the photo's hand mask (white = hand); the
    /// fitted hands are then refined against it before training.
    #[arg(long, requires = "image", conflicts_with = "annotation")]
    pub mask: Option<PathBuf>,
    /// Real data: the InterHand2.6M root; selects a scene (training view, novel views of the
    /// same frame, novel poses of the same capture; see docs/training.md for the rule).
    #[arg(long, conflicts_with = "scene")]
    pub interhand: Option<PathBuf>,
    /// InterHand2.6M split (with --interhand).
    #[arg(long, requires = "interhand")]
    pub split: Option<String>,
    /// InterHand2.6M capture id (default: the smallest with a usable frame).
    #[arg(long, requires = "interhand")]
    pub capture: Option<i64>,
    /// InterHand2.6M training frame index (default: the frame seen by the most cameras).
    #[arg(long, requires = "interhand")]
    pub frame: Option<i64>,
    /// InterHand2.6M training camera name (default: the largest hand box).
    #[arg(long, requires = "interhand")]
    pub camera: Option<String>,
    /// InterHand2.6M: number of novel views scored after training (default: the paper's 8).
    #[arg(long, requires = "interhand")]
    pub novel_views: Option<usize>,
    /// InterHand2.6M: number of novel poses scored after training (default: the paper's 8).
    #[arg(long, requires = "interhand")]
    pub novel_poses: Option<usize>,
    /// Real data: the hand models and texture prior.
    #[command(flatten)]
    pub hands: HandsArgs,
    /// The training configuration.
    #[command(flatten)]
    pub training: TrainingArgs,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Iterations (default: the preset's).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Output folder of the run.
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Continue the run in this folder exactly where its last checkpoint left it (its
    /// `config.json` and scene, or for real data its `input.json` and `input/` images, are
    /// used; other options except --iterations and --keep-checkpoints are ignored).
    #[arg(long, conflicts_with_all = ["scene", "out", "image", "interhand"])]
    pub resume: Option<PathBuf>,
    /// Keep the latest checkpoint when the run finishes, so that `--resume DIR --iterations
    /// N` can train it further. Without it a finished run keeps none (the quick preset's are
    /// 2 x 27 MB): its avatar, textures, renders and report are all there. An interrupted run
    /// always keeps its checkpoints.
    #[arg(long)]
    pub keep_checkpoints: bool,
    /// Write a new run into an existing folder that is not a run (it must hold no file of a
    /// name the run writes: nothing of the user's is overwritten).
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// Cache folder for the demo scene and the fitted texture PCA (default: `$XDG_CACHE_HOME/bitt`, else
    /// `~/.cache/bitt`; never the current folder).
    #[arg(long, default_value_os_t = crate::args::default_cache_dir())]
    pub cache: PathBuf,
    /// Frames of the turntable of novel views.
    #[arg(long, default_value_t = 8)]
    pub turntable: usize,
    /// Seed of the network initialisation.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Refine the given meshes against the training image before training (pose, shape,
    /// root and translation through the renderer; see `bitt refine-hands`). The run folder
    /// gets `refine.json` and `overlay.png`, and trains on the refined meshes.
    #[arg(long)]
    pub refine_mesh: bool,
    /// A refinement configuration (JSON) for --refine-mesh, and for the refinement of a
    /// photo given alone.
    #[arg(long)]
    pub refine_config: Option<PathBuf>,
}

/// The Ctrl-C flag, its handler installed once per process (tests run several trainings).
fn stop_flag() -> Result<Arc<AtomicBool>> {
    static FLAG: OnceLock<Result<Arc<AtomicBool>, String>> = OnceLock::new();
    let flag = FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let stop = flag.clone();
        // A second Ctrl-C while saving is ignored: the checkpoint write is atomic anyway.
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .map(|()| flag)
            .map_err(|e| e.to_string())
    });
    match flag {
        Ok(f) => {
            f.store(false, Ordering::SeqCst);
            Ok(f.clone())
        }
        Err(e) => bail!("installing the Ctrl-C handler: {e}"),
    }
}

/// What a fresh run trains on, as the options name it (`bitt::train_scene`).
fn request(args: &TrainSceneArgs) -> Result<FreshRequest<'_>> {
    let refine = if args.refine_mesh {
        Some(refine_config(args.refine_config.as_deref(), None, None)?)
    } else {
        None
    };
    let keypoints = |path: &Path| KeypointInput {
        source: args.keypoint.source(path),
        intrinsics: args.keypoint.intrinsics.clone(),
        config: args.keypoint.fit_config.clone(),
    };
    let photo_only = args.image.is_some() && args.annotation.is_none() && args.keypoints.is_none();
    if args.keypoint.fit_config.is_some() && args.keypoints.is_none() && !photo_only {
        bail!(
            "--fit-config configures the keypoint fit: of --keypoints, or of a photo given alone \
             (--image without --annotation); it does not apply here"
        );
    }
    // clap waives `requires = "keypoints"` when --annotation (which conflicts with it) is
    // given, so the options that only apply to a keypoint file or a fit are checked here.
    let keypoint_file_only = [
        ("--format", args.keypoint.format.is_some()),
        ("--mirrored", args.keypoint.mirrored),
        ("--labels-as-is", args.keypoint.labels_as_is),
    ];
    let fit_only = [("--intrinsics", args.keypoint.intrinsics.is_some())];
    let ignored: Vec<&str> = keypoint_file_only
        .iter()
        .filter(|(_, given)| *given && args.keypoints.is_none())
        .chain(
            fit_only
                .iter()
                .filter(|(_, given)| *given && args.keypoints.is_none() && !photo_only),
        )
        .map(|(name, _)| *name)
        .collect();
    if !ignored.is_empty() {
        bail!(
            "{} {} not apply here: --format, --mirrored and --labels-as-is describe a --keypoints file, \
             --intrinsics the camera of a keypoint fit (--keypoints, or --image alone); an \
             annotation or a scene brings its own camera",
            ignored.join(", "),
            if ignored.len() == 1 { "does" } else { "do" }
        );
    }
    if args.refine_config.is_some() && !args.refine_mesh && !photo_only {
        bail!(
            "--refine-config configures --refine-mesh, or the refinement of a photo given alone \
             (--image without --annotation or --keypoints)"
        );
    }
    let input = match (&args.image, &args.annotation, &args.interhand) {
        (Some(image), None, _) => match &args.keypoints {
            Some(path) => SceneInput::PhotoKeypoints {
                image,
                keypoints: keypoints(path),
                mask: args.mask.as_deref(),
            },
            None => SceneInput::Photo {
                image,
                mask: args.mask.as_deref(),
                fit: args.keypoint.fit_config.clone(),
                intrinsics: args.keypoint.intrinsics.clone(),
                refine: refine_config(args.refine_config.as_deref(), None, None)?,
            },
        },
        (Some(image), Some(annotation), _) => SceneInput::PhotoAnnotation { image, annotation },
        (None, _, Some(root)) => SceneInput::InterHand {
            root,
            split: args.split.as_deref().unwrap_or("test"),
            selection: InterHandSelection {
                capture: args.capture,
                frame: args.frame,
                camera: args.camera.clone(),
                novel_views: args.novel_views.unwrap_or(PAPER_NOVEL_VIEWS),
                novel_poses: args.novel_poses.unwrap_or(PAPER_NOVEL_POSES),
            },
        },
        (None, _, None) => SceneInput::Synthetic {
            scene: args.scene.as_deref(),
            keypoints: args.keypoints.as_deref().map(keypoints),
        },
    };
    let (hands, prior) = args.hands.sources();
    Ok(FreshRequest {
        input,
        hands,
        prior,
        refine,
        cache: &args.cache,
    })
}

/// `bitt train-scene`.
pub fn run(args: &TrainSceneArgs) -> Result<()> {
    let started = Instant::now();
    check_utf8_paths(&[
        ("--scene", args.scene.as_deref()),
        ("--image", args.image.as_deref()),
        ("--annotation", args.annotation.as_deref()),
        ("--keypoints", args.keypoints.as_deref()),
        ("--mask", args.mask.as_deref()),
        ("--interhand", args.interhand.as_deref()),
        ("--config", args.training.config.as_deref()),
        ("--resume", args.resume.as_deref()),
        ("--refine-config", args.refine_config.as_deref()),
        ("--model-dir", args.hands.model_dir.as_deref()),
        ("--html-dir", args.hands.html_dir.as_deref()),
        ("--out", Some(&args.out)),
        ("--cache", Some(&args.cache)),
    ])?;
    let device = args.device.device()?.autodiff();
    let (out, mut trainer, input) = match &args.resume {
        Some(dir) => {
            let (trainer, input) =
                resumed_run(dir, args.iterations, &args.cache, &device, &mut SetupLines)?;
            (dir.clone(), trainer, input)
        }
        None => {
            let (out, note) = fresh_out(&args.out, Path::new(DEFAULT_OUT), args.force)?;
            if let Some(note) = note {
                println!("{note}");
            }
            let photo = args.image.is_some() || args.interhand.is_some();
            let config = if photo {
                args.training.read_for_photo()?
            } else {
                args.training.read()?
            };
            let config = config.with_overrides(args.iterations, args.seed)?;
            let (trainer, input) =
                start_fresh(&out, &request(args)?, config, &device, &mut SetupLines)?;
            (out, trainer, input)
        }
    };
    eprintln!("{}", training_line(&trainer));
    let mut bar = TrainBar::new(stop_flag()?);
    let mut gave_up = None;
    match trainer.train(Some(&out.join(files::CHECKPOINT)), &mut bar) {
        Err(bitt::TrainError::Interrupted(i)) => {
            eprintln!(
                "\ninterrupted after iteration {i}; saved {}. Continue with: cargo xtask train-scene --resume {}",
                out.join(files::CHECKPOINT).display(),
                out.display()
            );
            std::process::exit(130);
        }
        Err(e @ bitt::TrainError::RecoveryExhausted { .. }) => {
            eprintln!(
                "\nerror: {e}\nwriting the results of that state (iteration {}) anyway",
                trainer.iteration
            );
            gave_up = Some(e);
        }
        r => r?,
    }
    eprintln!("writing results");
    let (summary, real_scores) = finish_run(&out, &trainer, &input, args.turntable)?;
    let wall = started.elapsed().as_secs_f64();
    for line in summary_lines(&out, &summary, real_scores.as_ref(), wall) {
        println!("{line}");
    }
    match gave_up {
        Some(e) => Err(unfinished_error(&e, &out, trainer.iteration).into()),
        None => {
            println!(
                "{}",
                remove_checkpoints(&out, args.keep_checkpoints)?.line()
            );
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt::TrainConfig;
    use bitt::real::RealInput;
    use bitt::run_folder::load_checkpoints;
    use bitt_nets::Preset;
    use bitt_tests::real_fixture::{
        AnnotationOptions, TWO_HAND_PHOTO_SEED, scratch, write_annotation, write_image,
    };

    type Cli = crate::test_args::Parsed<TrainSceneArgs>;

    type AvatarCli = crate::test_args::Parsed<crate::render_avatar::RenderAvatarArgs>;

    type ExportCli = crate::test_args::Parsed<crate::export::ExportArgs>;

    fn args(extra: &[&str]) -> TrainSceneArgs {
        let mut all = vec!["bitt", "--preset", "tiny", "--turntable", "2"];
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    fn s(p: &Path) -> &str {
        p.to_str().unwrap()
    }

    /// `bitt train-scene --resume OUT --iterations N --cache CACHE --turntable 0`.
    fn resume_args(out: &Path, cache: &Path, iterations: usize) -> TrainSceneArgs {
        let n = iterations.to_string();
        Cli::try_parse_from([
            "bitt",
            "--resume",
            s(out),
            "--iterations",
            &n,
            "--cache",
            s(cache),
            "--turntable",
            "0",
            "--keep-checkpoints",
        ])
        .unwrap()
        .args
    }

    /// `--config FILE` replaces the preset (the run's `config.json` is that file's content);
    /// it conflicts with `--preset`, and a broken file is named and leaves nothing behind.
    #[test]
    fn config_file_replaces_the_preset() {
        let dir = scratch("cli-config");
        let mut c = TrainConfig::preset(Preset::Tiny);
        c.loss.alb = 0.0;
        c.iterations = 2;
        c.seed = 7;
        let path = dir.join("my-config.json");
        std::fs::write(&path, serde_json::to_string(&c).unwrap()).unwrap();
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        let parse = |extra: &[&str]| {
            let mut all = vec!["bitt", "--turntable", "2", "--cache", s(&cache)];
            all.extend_from_slice(extra);
            Cli::try_parse_from(all).map(|c| c.args)
        };
        run(&parse(&["--config", s(&path), "--out", s(&out)]).unwrap()).unwrap();
        let text = std::fs::read_to_string(out.join(files::CONFIG)).unwrap();
        let back = TrainConfig::from_json(&text, &out).unwrap();
        assert_eq!(back.loss.alb, 0.0);
        assert_eq!((back.iterations, back.seed), (2, 7));
        assert_eq!(back.preset, Preset::Tiny);
        // A finished run keeps no checkpoint; it is still a run (not overwritten, not
        // resumable, and saying why).
        for f in [files::CHECKPOINT, files::CHECKPOINT_PREVIOUS] {
            assert!(!out.join(f).exists(), "{f} kept");
        }
        let e = format!(
            "{:#}",
            run(&parse(&["--config", s(&path), "--out", s(&out)]).unwrap()).unwrap_err()
        );
        assert!(e.contains("already holds a finished run"), "{e}");
        let resume = parse(&["--resume", s(&out)]).unwrap();
        let e = format!("{:#}", run(&resume).unwrap_err());
        assert!(
            e.contains("checkpoints were removed") && e.contains("--keep-checkpoints"),
            "{e}"
        );
        assert!(parse(&["--config", s(&path), "--preset", "quick"]).is_err());
        std::fs::write(&path, "{\"preset\": ").unwrap();
        let other = dir.join("run2");
        let e = format!(
            "{:#}",
            run(&parse(&["--config", s(&path), "--out", s(&other)]).unwrap()).unwrap_err()
        );
        assert!(e.contains("my-config.json"), "{e}");
        assert!(!other.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `train-scene --image --annotation --procedural`, then `--resume` and `render-avatar`
    /// in the training pose, another annotation's pose, a procedural pose and another view.
    #[test]
    fn real_pair_trains_resumes_and_renders() {
        let dir = scratch("cli-real");
        let (img, pkl, other) = (dir.join("01.jpg"), dir.join("01.pkl"), dir.join("02.pkl"));
        write_image(&img, 256, 256, None);
        write_annotation(&pkl, AnnotationOptions::default());
        write_annotation(
            &other,
            AnnotationOptions {
                turn: -0.3,
                ..AnnotationOptions::default()
            },
        );
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        let common = [
            "--image",
            s(&img),
            "--annotation",
            s(&pkl),
            "--procedural",
            "--cache",
            s(&cache),
            "--out",
            s(&out),
        ];
        let mut first = common.to_vec();
        first.extend(["--iterations", "2", "--keep-checkpoints"]);
        run(&args(&first)).unwrap();
        for f in [
            "config.json",
            "input.json",
            "input/images.safetensors",
            "checkpoint.safetensors",
            "report.html",
            "avatar.glb",
            "renders/turntable.png",
        ] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
        // --keep-checkpoints keeps the latest only; it is set aside to play the previous one
        // of a later checkpoint below.
        assert!(!out.join(files::CHECKPOINT_PREVIOUS).exists());
        let iteration_2 = std::fs::read(out.join(files::CHECKPOINT)).unwrap();
        assert!(!out.join("scene").exists());
        // An existing run is refused; --resume continues it.
        let e = format!("{:#}", run(&args(&first)).unwrap_err());
        assert!(e.contains("--resume"), "{e}");
        let resume = resume_args(&out, &cache, 3);
        // A temporary left by a killed checkpoint write is removed on resume.
        let stale = out.join(".checkpoint.safetensors.tmp4000000");
        std::fs::write(&stale, b"half a checkpoint").unwrap();
        // Fewer iterations than the run has done is refused, naming both.
        let short = Cli::try_parse_from([
            "bitt",
            "--resume",
            s(&out),
            "--iterations",
            "1",
            "--cache",
            s(&cache),
        ])
        .unwrap()
        .args;
        let e = format!("{:#}", run(&short).unwrap_err());
        assert!(
            e.contains("already at iteration 2") && e.contains("--iterations 1"),
            "{e}"
        );
        run(&resume).unwrap();
        assert!(!stale.exists(), "the stale temporary survived the resume");
        let metrics: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        assert_eq!(metrics["history"].as_array().unwrap().len(), 3);
        // An uninterrupted run of the same 3 iterations writes the same metrics.json, byte
        // for byte (the history read back from the checkpoint is bit-exact; timings are in
        // timing.json), and the same textures and light.
        let straight = dir.join("straight");
        let mut uninterrupted: Vec<&str> = common
            .iter()
            .map(|a| if *a == s(&out) { s(&straight) } else { *a })
            .collect();
        uninterrupted.extend(["--iterations", "3", "--keep-checkpoints"]);
        run(&args(&uninterrupted)).unwrap();
        for f in [
            "metrics.json",
            "light.json",
            "textures/left_fine.png",
            "textures/right_fine.png",
        ] {
            let (a, b) = (out.join(f), straight.join(f));
            assert!(
                std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
                "{f} differs between the resumed and the uninterrupted run"
            );
        }
        assert!(out.join("timing.json").is_file());
        // A checkpoint with a flipped byte is refused, naming it, and the previous one is
        // resumed instead; with neither usable, the resume fails naming the file.
        let ckpt = out.join(files::CHECKPOINT);
        std::fs::write(out.join(files::CHECKPOINT_PREVIOUS), &iteration_2).unwrap();
        let mut bytes = std::fs::read(&ckpt).unwrap();
        let last = bytes.len() - 3;
        bytes[last] ^= 0x40;
        std::fs::write(&ckpt, &bytes).unwrap();
        let (c, p, _) = load_checkpoints(&out).unwrap();
        assert!(
            p.is_none() && c.iteration < 3,
            "resumed from {}",
            c.iteration
        );
        std::fs::remove_file(out.join(files::CHECKPOINT_PREVIOUS)).unwrap();
        let e = format!("{:#}", load_checkpoints(&out).unwrap_err());
        assert!(
            e.contains("checkpoint.safetensors") && e.contains("corrupt"),
            "{e}"
        );
        std::fs::write(
            &ckpt,
            std::fs::read(straight.join(files::CHECKPOINT)).unwrap(),
        )
        .unwrap();
        // A run whose input record was deleted names what is missing.
        let moved = out.join("input.json.bak");
        std::fs::rename(out.join("input.json"), &moved).unwrap();
        let e = format!("{:#}", run(&resume).unwrap_err());
        assert!(
            e.contains("input.json")
                && e.contains("input is missing")
                && !e.contains("scene/scene.json is not"),
            "{e}"
        );
        std::fs::rename(&moved, out.join("input.json")).unwrap();
        // render-avatar in several poses.
        let render = |extra: &[&str], name: &str| {
            let png = dir.join(name);
            let mut all = vec!["bitt", "--run", s(&out), "--out", s(&png)];
            all.extend_from_slice(extra);
            crate::render_avatar::run(&AvatarCli::try_parse_from(all).unwrap().args)?;
            anyhow::Ok(png)
        };
        let (w, h) = image::image_dimensions(render(&[], "train.png").unwrap()).unwrap();
        assert_eq!((w, h), (32, 32));
        render(&["--pose", s(&other)], "pose.png").unwrap();
        render(
            &["--procedural-pose", "palm-on-back", "--view", "30,-10"],
            "proc.png",
        )
        .unwrap();
        let big = render(&["--procedural-pose", "clasp", "--size", "96"], "big.png").unwrap();
        assert_eq!(image::image_dimensions(big).unwrap(), (96, 96));
        let e = format!(
            "{:#}",
            render(&["--novel-pose", "0"], "np.png").unwrap_err()
        );
        assert!(e.contains("single annotation"), "{e}");
        let e = format!(
            "{:#}",
            render(&["--procedural-pose", "wave"], "bad.png").unwrap_err()
        );
        assert!(e.contains("wave") && e.contains("clasp"), "{e}");
        // export: rigged (the run's avatar.glb again), static, OBJ, another pose.
        let export = |extra: &[&str]| {
            let mut all = vec!["bitt", "--run", s(&out)];
            all.extend_from_slice(extra);
            crate::export::run(&ExportCli::try_parse_from(all).unwrap().args)
        };
        let rigged = dir.join("again.glb");
        export(&["--out", s(&rigged)]).unwrap();
        assert_eq!(
            std::fs::read(&rigged).unwrap(),
            std::fs::read(out.join("avatar.glb")).unwrap(),
            "re-exporting gives the run's own avatar"
        );
        let fixed = dir.join("static.glb");
        export(&["--static", "--out", s(&fixed)]).unwrap();
        assert_eq!(
            std::fs::read(&fixed).unwrap(),
            std::fs::read(out.join("avatar_static.glb")).unwrap()
        );
        let obj = dir.join("hands.obj");
        export(&["--format", "obj", "--out", s(&obj)]).unwrap();
        for f in [
            "hands.obj",
            "hands.mtl",
            "hands_left_hand.png",
            "hands_right_hand.png",
        ] {
            assert!(dir.join(f).is_file(), "{f}");
        }
        let posed = dir.join("posed.glb");
        export(&["--procedural-pose", "clasp", "--out", s(&posed)]).unwrap();
        assert_ne!(
            std::fs::read(&posed).unwrap(),
            std::fs::read(&rigged).unwrap()
        );
        let e = format!(
            "{:#}",
            export(&["--out", s(&dir.join("x.obj"))]).unwrap_err()
        );
        assert!(e.contains("x.obj") && e.contains(".glb"), "{e}");
        assert!(!dir.join("x.obj").exists());
        let not_a_run = ExportCli::try_parse_from(["bitt", "--run", s(&dir), "--out", "y.glb"]);
        let e = format!(
            "{:#}",
            crate::export::run(&not_a_run.unwrap().args).unwrap_err()
        );
        assert!(
            e.contains("not a complete and intact train-scene run"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `train-scene --interhand` on a miniature dataset: the selected scene trains, its novel
    /// views and poses are scored, the run resumes, and `render-avatar --novel-pose` works.
    #[test]
    fn interhand_scene_trains_scores_and_renders() {
        let dir = scratch("cli-interhand");
        let root = bitt_tests::real_fixture::write_mini_interhand(&dir.join("ih"));
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        run(&args(&[
            "--interhand",
            s(&root),
            "--capture",
            "0",
            "--iterations",
            "1",
            "--cache",
            s(&cache),
            "--out",
            s(&out),
            "--keep-checkpoints",
        ]))
        .unwrap();
        let scores: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join(files::REAL_SCORES)).unwrap())
                .unwrap();
        assert_eq!(scores["novel_poses"]["count"], 2);
        assert!(out.join("input/pose_01.png").is_file());
        let input = RealInput::read(&out).unwrap();
        assert!(matches!(
            input.source,
            bitt::real::RealSource::InterHand { frame: 100, .. }
        ));
        let resume = Cli::try_parse_from([
            "bitt",
            "--resume",
            s(&out),
            "--iterations",
            "2",
            "--cache",
            s(&cache),
        ])
        .unwrap()
        .args;
        run(&resume).unwrap();
        let png = dir.join("pose1.png");
        let avatar = AvatarCli::try_parse_from([
            "bitt",
            "--run",
            s(&out),
            "--novel-pose",
            "1",
            "--out",
            s(&png),
        ])
        .unwrap()
        .args;
        crate::render_avatar::run(&avatar).unwrap();
        assert!(png.is_file());
        let e = format!(
            "{:#}",
            run(&args(&[
                "--interhand",
                s(&root),
                "--capture",
                "3",
                "--cache",
                s(&cache),
                "--out",
                s(&dir.join("run2")),
            ]))
            .unwrap_err()
        );
        assert!(e.contains("capture 3") && e.contains("_data.json"), "{e}");
        assert!(!dir.join("run2").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `--refine-mesh` refines the real pair's meshes before training: the run folder holds
    /// `refine.json` and `overlay.png`, `metrics.json` and the report carry the refinement,
    /// and the recorded hands (what `--resume` trains on) are the refined ones.
    #[test]
    fn refine_mesh_refines_before_training() {
        let dir = scratch("cli-refine-mesh");
        let (img, pkl) = (dir.join("01.jpg"), dir.join("01.pkl"));
        write_image(&img, 256, 256, None);
        write_annotation(&pkl, AnnotationOptions::default());
        let cfg = dir.join("refine.json");
        std::fs::write(&cfg, r#"{"rigid_iterations": 2, "full_iterations": 3}"#).unwrap();
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        let all = [
            "--image",
            s(&img),
            "--annotation",
            s(&pkl),
            "--cache",
            s(&cache),
            "--out",
            s(&out),
            "--iterations",
            "2",
            "--refine-mesh",
            "--refine-config",
            s(&cfg),
        ];
        run(&args(&all)).unwrap();
        assert!(out.join("overlay.png").is_file());
        let read = |f: &str| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(out.join(f)).unwrap()).unwrap()
        };
        let refine = read("refine.json");
        assert_eq!(refine["report"]["config"]["full_iterations"], 3);
        assert_eq!(read("metrics.json")["refine"], refine);
        let report = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert!(report.contains("Mesh refinement"));
        let input = read("input.json");
        let pose = &input["train"]["hands"]["left"]["pose"];
        assert_eq!(
            pose["kind"], "axis_angle",
            "the run trains on the refined hands"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `train-scene --image IMG` alone: detect, fit, refine, train; the run folder keeps the
    /// detection, the report shows it, `input.json` records it, and `--resume` continues
    /// without detecting again.
    #[test]
    fn photo_only_detects_fits_refines_trains_and_resumes() {
        let dir = scratch("cli-photo-only");
        let img = dir.join("hands.png");
        bitt_tests::real_fixture::write_synthetic_photo(&img, TWO_HAND_PHOTO_SEED);
        let cfg = dir.join("refine.json");
        std::fs::write(&cfg, r#"{"rigid_iterations": 2, "full_iterations": 3}"#).unwrap();
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        run(&args(&[
            "--image",
            s(&img),
            "--refine-config",
            s(&cfg),
            "--cache",
            s(&cache),
            "--out",
            s(&out),
            "--iterations",
            "2",
            "--keep-checkpoints",
        ]))
        .unwrap();
        for f in [
            "detection.json",
            "detection_overlay.png",
            "keypoints.json",
            "fit.json",
            "fit_overlay.png",
            "input.json",
            "report.html",
            "avatar.glb",
        ] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
        let read = |f: &str| -> serde_json::Value {
            serde_json::from_str(&std::fs::read_to_string(out.join(f)).unwrap()).unwrap()
        };
        let detection = read("detection.json");
        for side in ["left", "right"] {
            assert!(
                detection[side]["presence"].as_f64().unwrap() >= 0.5,
                "{detection}"
            );
        }
        let fit = read("fit.json");
        assert_eq!(fit["keypoints"], "detected in the photo");
        assert_eq!(fit["refinement"]["mask"], "mean RGB above 0.15", "{fit}");
        let input = read("input.json");
        assert_eq!(input["source"]["kind"], "detected");
        let report = || std::fs::read_to_string(out.join("report.html")).unwrap();
        let overlay = std::fs::read(out.join("detection_overlay.png")).unwrap();
        let embedded = bitt::outputs::base64(&overlay);
        let first = report();
        assert!(
            first.contains("Hand detection") && first.contains("hand detection: left presence")
        );
        assert!(
            first.contains(&embedded),
            "the report does not show the overlay"
        );
        // --resume continues from the record: the detection is not made again.
        let detection_bytes = std::fs::read(out.join("detection.json")).unwrap();
        let resume = resume_args(&out, &cache, 3);
        run(&resume).unwrap();
        assert_eq!(read("metrics.json")["history"].as_array().unwrap().len(), 3);
        assert_eq!(
            std::fs::read(out.join("detection.json")).unwrap(),
            detection_bytes
        );
        let again = report();
        assert!(again.contains("Hand detection") && again.contains(&embedded));
        // The detected keypoints without the right hand: the message says the file has no
        // right hand (issue 38), and no run folder is made.
        let mut left_only = read("keypoints.json");
        left_only["right"] = serde_json::Value::Null;
        let kp = dir.join("left_only.json");
        std::fs::write(&kp, left_only.to_string()).unwrap();
        let other = dir.join("run-left-only");
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image",
                s(&img),
                "--keypoints",
                s(&kp),
                "--cache",
                s(&cache),
                "--out",
                s(&other),
            ]))
            .unwrap_err()
        );
        assert!(
            e.contains("left_only.json") && e.contains("the file has no right hand"),
            "{e}"
        );
        assert!(!other.exists(), "a refused run made {}", other.display());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Bad real inputs fail before the run folder is created.
    #[test]
    fn bad_real_inputs_write_nothing() {
        let dir = scratch("cli-bad");
        let (img, pkl) = (dir.join("01.jpg"), dir.join("01.pkl"));
        write_image(&img, 128, 128, None);
        write_annotation(&pkl, AnnotationOptions::default());
        let nan = dir.join("nan.pkl");
        write_annotation(&nan, AnnotationOptions::NAN);
        let (out, cache) = (dir.join("run"), dir.join("cache"));
        let attempt = |image: &Path, annotation: &Path, extra: &[&str]| {
            let mut all = vec![
                "--image",
                s(image),
                "--annotation",
                s(annotation),
                "--cache",
                s(&cache),
                "--out",
                s(&out),
            ];
            all.extend_from_slice(extra);
            format!("{:#}", run(&args(&all)).unwrap_err())
        };
        let e = attempt(&img, &pkl, &[]);
        assert!(e.contains("01.jpg") && e.contains("128x128"), "{e}");
        let e = attempt(&img, &nan, &[]);
        assert!(e.contains("nan.pkl") && e.contains("NaN"), "{e}");
        let e = attempt(&dir.join("missing.jpg"), &pkl, &[]);
        assert!(e.contains("missing.jpg"), "{e}");
        let e = attempt(&img, &dir.join("missing.pkl"), &[]);
        assert!(e.contains("missing.pkl"), "{e}");
        let e = attempt(&img, &pkl, &["--model-dir", s(&dir.join("mano"))]);
        assert!(e.contains("HTML"), "{e}");
        assert!(!out.exists(), "a failed run created {}", out.display());
        // Real-data options need real data. A photo alone is the photo-only path, which
        // takes a mask and a refinement configuration; --mask needs a photo and no annotation.
        let e = format!(
            "{:#}",
            run(&args(&["--model-dir", "x", "--out", s(&out)])).unwrap_err()
        );
        assert!(e.contains("real data"), "{e}");
        let photo = Cli::try_parse_from([
            "bitt",
            "--image",
            s(&img),
            "--mask",
            "m.png",
            "--refine-config",
            "r.json",
            "--fit-config",
            "f.json",
        ])
        .unwrap()
        .args;
        assert!(photo.annotation.is_none() && photo.keypoints.is_none());
        assert!(Cli::try_parse_from(["bitt", "--mask", "m.png"]).is_err());
        assert!(
            Cli::try_parse_from([
                "bitt",
                "--image",
                s(&img),
                "--annotation",
                s(&pkl),
                "--mask",
                "m.png"
            ])
            .is_err()
        );
        // --refine-config configures --refine-mesh or the photo-only refinement.
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image",
                s(&img),
                "--annotation",
                s(&pkl),
                "--refine-config",
                "r.json",
                "--out",
                s(&out)
            ]))
            .unwrap_err()
        );
        assert!(e.contains("--refine-config"), "{e}");
        // --fit-config with an annotation: no keypoint fit runs, so it is refused (issue 38).
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image",
                s(&img),
                "--annotation",
                s(&pkl),
                "--fit-config",
                "f.json",
                "--out",
                s(&out)
            ]))
            .unwrap_err()
        );
        assert!(
            e.contains("--fit-config") && e.contains("does not apply"),
            "{e}"
        );
        // Issue 38, class 4: keypoint-file and fit options next to an annotation (clap waives
        // their `requires` there) are refused, naming them, instead of being ignored.
        for (extra, named) in [
            (
                &["--intrinsics", "0,0,0,0"][..],
                "--intrinsics does not apply",
            ),
            (&["--format", "openpose"][..], "--format does not apply"),
            (&["--mirrored"][..], "--mirrored does not apply"),
            (
                &["--mirrored", "--intrinsics", "9,9,1,1"][..],
                "--mirrored, --intrinsics do not apply",
            ),
        ] {
            let mut all = vec![
                "--image",
                s(&img),
                "--annotation",
                s(&pkl),
                "--out",
                s(&out),
            ];
            all.extend(extra);
            let e = format!("{:#}", run(&args(&all)).unwrap_err());
            assert!(e.contains(named), "{extra:?}: {e}");
        }
        // With a photo alone, --intrinsics is the fit's camera: parsed (and refused when bad)
        // before the photo is even read.
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image",
                s(&img),
                "--intrinsics",
                "0,0,0,0",
                "--out",
                s(&out)
            ]))
            .unwrap_err()
        );
        assert!(e.contains("--intrinsics \"0,0,0,0\""), "{e}");
        assert!(!out.exists());
        // Malformed keypoints are named and leave no run folder.
        let bad_kp = dir.join("bad_keypoints.json");
        std::fs::write(&bad_kp, r#"{"right": [[1, 2, 1]]}"#).unwrap();
        let e = format!(
            "{:#}",
            run(&args(&[
                "--image",
                s(&img),
                "--keypoints",
                s(&bad_kp),
                "--out",
                s(&out)
            ]))
            .unwrap_err()
        );
        assert!(
            e.contains("bad_keypoints.json") && e.contains("right"),
            "{e}"
        );
        assert!(
            !out.exists(),
            "a failed keypoint run created {}",
            out.display()
        );
        assert!(
            Cli::try_parse_from([
                "bitt",
                "--image",
                s(&img),
                "--annotation",
                s(&pkl),
                "--scene",
                "x"
            ])
            .is_err()
        );
        assert!(Cli::try_parse_from(["bitt", "--capture", "0"]).is_err());
        // A path that is not UTF-8 is refused before anything is written.
        #[cfg(unix)]
        {
            use std::os::unix::ffi::OsStringExt;
            let odd = std::ffi::OsString::from_vec(
                [dir.as_os_str().as_encoded_bytes(), b"/caf\xe9.jpg"].concat(),
            );
            std::fs::copy(&img, &odd).unwrap();
            let all: Vec<std::ffi::OsString> = [
                "bitt",
                "--preset",
                "tiny",
                "--annotation",
                s(&pkl),
                "--out",
                s(&out),
                "--image",
            ]
            .into_iter()
            .map(Into::into)
            .chain([odd])
            .collect();
            let e = format!(
                "{:#}",
                run(&Cli::try_parse_from(all).unwrap().args).unwrap_err()
            );
            assert!(
                e.contains("--image") && e.contains("not valid UTF-8"),
                "{e}"
            );
            assert!(!out.exists(), "a refused run created {}", out.display());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
