//! `bitt eval` and `bitt eval-merge`: the paper's evaluation protocol on the synthetic
//! benchmark (crate `bitt-bench`, module `benchmark`), resumable and shardable.

use std::path::PathBuf;
use std::time::Instant;

use crate::progress::EvalBar;
use anyhow::{Result, bail};
use bitt::baselines::BaselineConfig;
use bitt_bench::benchmark::{
    EvalRun, EvalSource, Evaluation, MeshSetting, Method, parse_scenes, parse_shard, run_evaluation,
};

use crate::args::TrainingArgs;
use crate::device::DeviceName;

/// Where the evaluated scenes come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Dataset {
    /// The built-in synthetic benchmark (ground-truth textures; both mesh settings).
    Synthetic,
    /// InterHand2.6M under `--root`: one scene per capture (identity), selected as
    /// `train-scene --interhand` does; annotated meshes only (Table 1a).
    Interhand,
}

/// Arguments of `bitt eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Scenes to evaluate: a number (the first N) or `all` (the synthetic benchmark's 24, or
    /// every InterHand2.6M capture with a usable frame). The default (1 synthetic scene, both
    /// mesh settings, all methods, `quick`) takes about 25 minutes on a 2-core CPU.
    #[arg(long, default_value = "1")]
    pub scenes: String,
    /// The scenes: the synthetic benchmark or InterHand2.6M (with --root).
    #[arg(long, value_enum, default_value = "synthetic")]
    pub dataset: Dataset,
    /// InterHand2.6M root (`images/`, `annotations/`), with `--dataset interhand`.
    #[arg(long)]
    pub root: Option<PathBuf>,
    /// Photos of the same hands, each `IMAGE:ANNOTATION` (a BiTT pickle or the `hands.json`
    /// of `refine-hands` / `fit-hands`): each is the input view once and a novel pose of the
    /// others, scored in its own hand mask (docs/results/photos.md). Trains at the photo's
    /// 256 px crop with `quick` unless --preset or --config is given.
    #[arg(long, num_args = 2.., conflicts_with = "root")]
    pub photos: Vec<String>,
    /// InterHand2.6M split.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// InterHand2.6M and --photos: folder with MANO_LEFT / MANO_RIGHT (`.pkl` or
    /// `.safetensors`); needs --html-dir. Default: the procedural hands.
    #[arg(long)]
    pub model_dir: Option<PathBuf>,
    /// InterHand2.6M and --photos: HTML's TextureBasis folder as the texture prior; needs
    /// --model-dir. Default: the procedural texture PCA.
    #[arg(long, requires = "model_dir")]
    pub html_dir: Option<PathBuf>,
    /// Methods, comma-separated: bitt, bitt-no-alb, bitt-no-sym, html, harp-like,
    /// s2hand-like, bitt-refined (default: all but bitt-refined; see --refine-mesh).
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Add the method "BiTT + refined mesh": BiTT trained after refining the given meshes
    /// against the input image (`bitt refine-hands`; synthetic scenes).
    #[arg(long)]
    pub refine_mesh: bool,
    /// Mesh settings: both, gt-mesh or noisy-mesh.
    #[arg(long, default_value = "both")]
    pub mesh: String,
    /// The configuration of every BiTT training (the ablations switch their parts off from
    /// it).
    #[command(flatten)]
    pub training: TrainingArgs,
    /// BiTT iterations (default: the preset's).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Adam iterations of the HARP-like and S2Hand-like baselines.
    #[arg(long, default_value_t = BaselineConfig::default().iterations)]
    pub baseline_iterations: usize,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Output folder: `scenes/` (one result per scene and setting; finished ones are
    /// skipped on rerun), `sheets/`, `results.json`, `results.md`.
    #[arg(long, default_value = "runs/eval")]
    pub out: PathBuf,
    /// Cache of generated scenes and fitted texture PCAs (default: `$XDG_CACHE_HOME/bitt`,
    /// else `~/.cache/bitt`; never the current folder).
    #[arg(long, default_value_os_t = crate::args::default_cache_dir())]
    pub cache: PathBuf,
    /// LPIPS-VGG weights (safetensors from `bitt convert-lpips`). Default:
    /// $BITT_LPIPS_WEIGHTS, else ~/.cache/bitt/lpips_vgg.safetensors when it exists; without
    /// weights LPIPS is reported as unavailable (never estimated).
    #[arg(long)]
    pub lpips: Option<PathBuf>,
    /// Run only slice `i` of `N` (`i/N`, 0-based): scene `k` belongs to slice `k % N`.
    #[arg(long)]
    pub shard: Option<String>,
}

/// Arguments of `bitt eval-merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The evaluation folder the shards wrote into (`--out` of `bitt eval`); several folders
    /// may be given, their `scenes/` are combined into the first.
    #[arg(long = "out", num_args = 1.., default_value = "runs/eval")]
    pub dirs: Vec<PathBuf>,
}

/// `bitt eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    let started = Instant::now();
    let scenes = parse_scenes(&args.scenes)?;
    let methods = Method::parse_list(&args.methods, args.refine_mesh)?;
    let settings = MeshSetting::parse_choice(&args.mesh)?;
    let shard = match &args.shard {
        Some(s) => parse_shard(s)?,
        None => (0, 1),
    };
    if args.dataset == Dataset::Synthetic
        && args.photos.is_empty()
        && (args.root.is_some() || args.model_dir.is_some() || args.html_dir.is_some())
    {
        bail!("--root, --model-dir and --html-dir are for --dataset interhand or --photos");
    }
    let photos = args
        .photos
        .iter()
        .map(|p| bitt_bench::benchmark::Photo::parse(p))
        .collect::<Result<Vec<_>, _>>()?;
    if !photos.is_empty() && args.dataset != Dataset::Synthetic {
        bail!("--photos brings its own scenes; leave out --dataset");
    }
    let config = match photos.is_empty() {
        true => args.training.read()?,
        false => args.training.read_for_photo()?,
    }
    .with_overrides(args.iterations, None)?;
    let baseline = BaselineConfig {
        iterations: args.baseline_iterations,
        ..BaselineConfig::default()
    };
    let device = args.device.device()?.autodiff();
    let source = match args.dataset {
        Dataset::Synthetic if !photos.is_empty() => EvalSource::Photos {
            photos: &photos,
            model_dir: args.model_dir.as_deref(),
            html_dir: args.html_dir.as_deref(),
        },
        Dataset::Synthetic => EvalSource::Synthetic,
        Dataset::Interhand => EvalSource::InterHand {
            root: args.root.as_deref(),
            split: &args.split,
            model_dir: args.model_dir.as_deref(),
            html_dir: args.html_dir.as_deref(),
            all: args.scenes == "all",
        },
    };
    let run = EvalRun {
        out: &args.out,
        cache: &args.cache,
        config: &config,
        baseline: &baseline,
        methods: &methods,
        settings: &settings,
        lpips: None,
        shard,
    };
    let evaluation = Evaluation {
        run,
        scenes,
        lpips: args.lpips.as_deref(),
        source,
    };
    let tables = run_evaluation(&evaluation, &device, &mut EvalBar::default())?;
    println!("{tables}");
    println!(
        "evaluation done in {:.1} min; results in {}/results.md",
        started.elapsed().as_secs_f64() / 60.0,
        args.out.display()
    );
    Ok(())
}

/// `bitt eval-merge`: merges the scene results of the folders into the tables of the first
/// and prints them.
pub fn merge_cmd(args: &MergeArgs) -> Result<()> {
    println!("{}", bitt_bench::benchmark::merge(&args.dirs)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_bench::benchmark::SceneResult;
    use bitt_tests::real_fixture::{
        AnnotationOptions, scratch, write_annotation, write_image, write_mano_html_folders,
        write_mini_interhand,
    };
    use std::path::Path;

    type Cli = crate::test_args::Parsed<EvalArgs>;

    fn s(p: &Path) -> &str {
        p.to_str().unwrap()
    }

    /// `eval --dataset interhand` on a miniature dataset: one scene per usable capture, every
    /// method scored on the photographs (no texture errors: there is no true texture),
    /// Table 1a only, a rerun skips finished scenes, and the setting without annotated
    /// meshes is refused.
    #[test]
    fn interhand_evaluation_scores_every_method_and_resumes() {
        let dir = scratch("cli-eval-interhand");
        let root = write_mini_interhand(&dir.join("ih"));
        let (out, cache) = (dir.join("eval"), dir.join("cache"));
        let parse = |extra: &[&str]| {
            let mut all = vec![
                "bitt",
                "--dataset",
                "interhand",
                "--root",
                s(&root),
                "--preset",
                "tiny",
                "--iterations",
                "1",
                "--baseline-iterations",
                "2",
                "--methods",
                "bitt,html,harp-like,s2hand-like",
                "--cache",
                s(&cache),
                "--out",
                s(&out),
            ];
            all.extend_from_slice(extra);
            Cli::try_parse_from(all).unwrap().args
        };
        run(&parse(&["--scenes", "all"])).unwrap();
        let files = || -> Vec<PathBuf> {
            let mut v: Vec<PathBuf> = std::fs::read_dir(out.join("scenes"))
                .unwrap()
                .map(|e| e.unwrap().path())
                .collect();
            v.sort();
            v
        };
        let first = files();
        assert!(!first.is_empty());
        let r: SceneResult =
            serde_json::from_str(&std::fs::read_to_string(&first[0]).unwrap()).unwrap();
        assert_eq!(r.setting, MeshSetting::GtMesh);
        assert_eq!(r.methods.len(), 4);
        for (m, score) in &r.methods {
            let nv = score.novel_views.expect("novel views scored");
            assert!(nv.psnr.is_finite() && nv.psnr > 5.0, "{m:?}: {nv:?}");
            assert!(score.novel_poses.is_some(), "{m:?}");
            assert_eq!(score.texture.visible, None, "{m:?}");
        }
        let vis = r.stats.table3.left_visible;
        assert!(vis > 0.0 && vis < 1.0, "{vis}");
        let md = std::fs::read_to_string(out.join("results.md")).unwrap();
        assert!(md.contains("Table 1a") && !md.contains("Table 1b"), "{md}");
        assert!(out.join("sheets").is_dir());
        // A rerun finds every scene done.
        run(&parse(&["--scenes", "all"])).unwrap();
        assert_eq!(files(), first);
        // Without annotated meshes InterHand needs a mesh estimator.
        let e = format!("{:#}", run(&parse(&["--mesh", "noisy-mesh"])).unwrap_err());
        assert!(e.contains("IntagHand"), "{e}");
        let missing = Cli::try_parse_from([
            "bitt",
            "--dataset",
            "interhand",
            "--root",
            s(&dir.join("nope")),
            "--preset",
            "tiny",
            "--out",
            s(&dir.join("eval2")),
        ])
        .unwrap()
        .args;
        let e = format!("{:#}", run(&missing).unwrap_err());
        assert!(e.contains("nope"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Two photos `a.jpg` and `b.jpg` of the "same hands" in `dir` (b's turned), as `--photos`
    /// arguments `IMAGE:ANNOTATION`.
    fn photo_pair(dir: &Path) -> [String; 2] {
        ["a", "b"].map(|name| {
            let (image, annotation) = (
                dir.join(format!("{name}.jpg")),
                dir.join(format!("{name}.pkl")),
            );
            write_image(&image, 256, 256, None);
            let turn = if name == "b" { -0.3 } else { 0.0 };
            write_annotation(
                &annotation,
                AnnotationOptions {
                    turn,
                    ..AnnotationOptions::default()
                },
            );
            format!("{}:{}", image.display(), annotation.display())
        })
    }

    /// `eval --preset tiny --iterations 1 --cache CACHE --out OUT`, then `extra`.
    fn tiny_eval(cache: &Path, out: &Path, extra: &[&str]) -> EvalArgs {
        let mut all = vec!["bitt", "--preset", "tiny", "--iterations", "1", "--cache"];
        all.extend_from_slice(&[s(cache), "--out", s(out)]);
        all.extend_from_slice(extra);
        Cli::try_parse_from(all).unwrap().args
    }

    /// `eval --photos`: two photos of the "same hands", each trained on once and scored on
    /// the other, in the photo's own hand mask; the table, a contact sheet per photo, resume,
    /// and refusals (one photo, a missing file) that write nothing.
    #[test]
    fn photo_pairs_are_scored_both_ways_in_the_photos_masks() {
        let dir = scratch("cli-eval-photos");
        let [ja, jb] = photo_pair(&dir);
        let (out, cache) = (dir.join("eval"), dir.join("cache"));
        let parse = |photos: &[&str], out: &Path| {
            let mut all = vec![
                "--baseline-iterations",
                "2",
                "--methods",
                "bitt,html,harp-like",
                "--photos",
            ];
            all.extend_from_slice(photos);
            tiny_eval(&cache, out, &all)
        };
        run(&parse(&[&ja, &jb], &out)).unwrap();
        let md = std::fs::read_to_string(out.join("results.md")).unwrap();
        assert!(md.contains("## Real photos"), "{md}");
        assert!(
            md.contains("the procedural hands with the procedural texture PCA"),
            "{md}"
        );
        for row in [
            "| a -> b | bitt |",
            "| b -> a | harp-like |",
            "| a -> a (input view) | html |",
        ] {
            assert!(md.contains(row), "{row}: {md}");
        }
        assert!(md.contains("| a & b |"), "consistency: {md}");
        let results: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                .unwrap();
        let scenes = results["scenes"].as_array().unwrap();
        assert_eq!(scenes.len(), 2);
        for scene in scenes {
            let photo = &scene["methods"]["bitt"]["photo"];
            let cov = photo["novel_poses"]["coverage"].as_f64().unwrap();
            let holes = photo["input_view"]["holes"].as_f64().unwrap();
            assert!(cov > 0.0 && cov <= 1.0, "{cov}");
            assert!((0.0..=1.0).contains(&holes), "{holes}");
            assert!(photo["novel_poses"]["hand_mask"]["psnr"].as_f64().unwrap() > 3.0);
        }
        let c = &results["photo_consistency"][0];
        assert!(c["shared_texels"].as_u64().unwrap() > 0, "{c}");
        assert!(c["l1_gain_fitted"].as_f64().unwrap() >= 0.0, "{c}");
        let sheets = std::fs::read_dir(out.join("sheets")).unwrap().count();
        assert_eq!(sheets, 3, "two sheets and columns.txt");
        // Each sheet: the input view, then the other photo; input, photo and three methods.
        for e in std::fs::read_dir(out.join("sheets")).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "png") {
                let (w, h) = image::image_dimensions(&p).unwrap();
                assert_eq!(w * 2, h * 5, "{}: {w}x{h}", p.display());
            }
        }
        // A rerun finds both done and trains nothing.
        let before = std::fs::read_to_string(out.join("results.json")).unwrap();
        run(&parse(&[&ja, &jb], &out)).unwrap();
        assert_eq!(
            std::fs::read_to_string(out.join("results.json")).unwrap(),
            before
        );
        // A missing file is named and nothing is written.
        let fresh = dir.join("eval2");
        let missing = format!(
            "{}:{}",
            dir.join("nope.jpg").display(),
            jb.split_once(':').unwrap().1
        );
        let e = format!("{:#}", run(&parse(&[&ja, &missing], &fresh)).unwrap_err());
        assert!(e.contains("nope.jpg"), "{e}");
        assert!(!fresh.exists());
        // One photo is refused by the parser.
        assert!(
            Cli::try_parse_from(["bitt", "--photos", ja.as_str()]).is_err(),
            "one photo"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// `eval --photos --model-dir --html-dir`, the command that checks the real-photo
    /// benchmark with the user's MANO and HTML (here folders of their structure): both
    /// directions scored, the models named in `results.md` and in the plan, so that a folder
    /// evaluated with one kind of hands is never resumed with the other; MANO without HTML is
    /// refused before anything is written.
    #[test]
    fn photo_pairs_score_with_mano_and_html_folders() {
        let dir = scratch("cli-eval-photos-mano");
        let (mano, html) = write_mano_html_folders(&dir);
        let [ja, jb] = photo_pair(&dir);
        let (out, cache) = (dir.join("eval"), dir.join("cache"));
        let parse = |models: &[&str], out: &Path| {
            let mut all = vec![
                "--methods",
                "bitt,html",
                "--photos",
                ja.as_str(),
                jb.as_str(),
            ];
            all.extend_from_slice(models);
            tiny_eval(&cache, out, &all)
        };
        let models = ["--model-dir", s(&mano), "--html-dir", s(&html)];
        run(&parse(&models, &out)).unwrap();
        let md = std::fs::read_to_string(out.join("results.md")).unwrap();
        assert!(
            md.contains(&format!(
                "MANO hands (`{}`) with the HTML prior (`{}`)",
                mano.display(),
                html.display()
            )),
            "{md}"
        );
        for row in ["| a -> b | bitt |", "| b -> a | html |"] {
            assert!(md.contains(row), "{row}: {md}");
        }
        let results: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                .unwrap();
        for scene in results["scenes"].as_array().unwrap() {
            let psnr = scene["methods"]["bitt"]["photo"]["novel_poses"]["hand_mask"]["psnr"]
                .as_f64()
                .unwrap();
            assert!(psnr > 3.0, "{psnr}");
        }
        // The folder holds MANO's results: resuming it with the procedural hands is refused,
        // naming what differs, and leaves it as it was.
        let before = std::fs::read_to_string(out.join("results.json")).unwrap();
        let e = format!("{:#}", run(&parse(&[], &out)).unwrap_err());
        assert!(e.contains("models differ"), "{e}");
        assert_eq!(
            std::fs::read_to_string(out.join("results.json")).unwrap(),
            before
        );
        // MANO without HTML: refused before the folder exists.
        let fresh = dir.join("eval2");
        let e = format!(
            "{:#}",
            run(&parse(&["--model-dir", s(&mano)], &fresh)).unwrap_err()
        );
        assert!(e.contains("HTML"), "{e}");
        assert!(!fresh.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
