//! `bitt eval` and `bitt eval-merge`: the paper's evaluation protocol on the synthetic
//! benchmark (crate `bitt`, module `benchmark`), resumable and shardable.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt::baselines::BaselineConfig;
use bitt::benchmark::{
    EvalObserver, EvalPlan, EvalRun, InterHandScenes, MeshSetting, Method, evaluate_interhand,
    evaluate_synthetic, parse_shard, prepare_folder,
};
use bitt::lpips::LpipsVgg;
use bitt::real::sources;
use bitt::{Observer, Progress};
use bitt_synth::BENCHMARK_SCENES;

use crate::args::TrainingArgs;
use crate::device::DeviceName;
use crate::progress::ProgressLine;

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
    /// InterHand2.6M split.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// InterHand2.6M: folder with MANO_LEFT / MANO_RIGHT (`.pkl` or `.safetensors`); needs
    /// --html-dir. Default: the procedural hands.
    #[arg(long)]
    pub model_dir: Option<PathBuf>,
    /// InterHand2.6M: HTML's TextureBasis folder as the texture prior; needs --model-dir.
    /// Default: the procedural texture PCA.
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
    /// Cache of generated scenes and fitted texture PCAs.
    #[arg(long, default_value = "runs/cache")]
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

/// Progress over the whole evaluation (`crate::progress`): BiTT iterations are the unit of
/// work.
struct EvalBar {
    line: ProgressLine,
    done: usize,
    total: usize,
    label: String,
}

impl Observer for EvalBar {
    fn iteration(&mut self, p: &Progress) {
        self.done += 1;
        let per = self.line.elapsed() / self.done.max(1) as f64;
        let eta = per * self.total.saturating_sub(self.done) as f64;
        let label = format!(
            "{} it {}/{} loss {:.4} | eval ",
            self.label, p.iteration, p.iterations, p.terms.total
        );
        let text = format!("ETA {:.0} min", eta / 60.0);
        self.line.show(&label, self.done, self.total, &text);
    }
    fn recovered(&mut self, iteration: usize, message: &str) {
        eprintln!("\nrecovered at iteration {iteration}: {message}");
    }
}

impl EvalObserver for EvalBar {
    fn say(&mut self, line: &str) {
        eprintln!("{line}");
    }

    fn plan(&mut self, iterations: usize) {
        self.total = iterations;
    }

    fn scene(&mut self, label: String) {
        self.label = label;
    }

    fn pca(&mut self) -> Box<dyn bitt_texture::FitProgress> {
        Box::new(crate::progress::PcaFitBar::new())
    }
}

/// `bitt eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    let started = Instant::now();
    let scenes = match args.scenes.as_str() {
        "all" => BENCHMARK_SCENES,
        n => n
            .parse::<usize>()
            .ok()
            .filter(|&n| n >= 1)
            .with_context(|| format!("--scenes {n}: expected a positive number or `all`"))?,
    };
    let methods = Method::parse_list(&args.methods, args.refine_mesh)?;
    let settings = MeshSetting::parse_choice(&args.mesh)?;
    let (shard, shards) = match &args.shard {
        Some(s) => parse_shard(s)?,
        None => (0, 1),
    };
    if args.dataset == Dataset::Synthetic
        && (args.root.is_some() || args.model_dir.is_some() || args.html_dir.is_some())
    {
        bail!("--root, --model-dir and --html-dir are for --dataset interhand");
    }
    let mut config = args.training.read()?;
    if let Some(n) = args.iterations {
        config.iterations = n;
    }
    config.validate()?;
    let baseline = BaselineConfig {
        iterations: args.baseline_iterations,
        ..BaselineConfig::default()
    };
    let device = args.device.device()?.autodiff();
    let host = device.clone().inner();
    let dataset = match args.dataset {
        Dataset::Synthetic => "synthetic".to_string(),
        Dataset::Interhand => format!(
            "interhand {} {}",
            args.split,
            args.root
                .as_ref()
                .map_or(String::new(), |r| r.display().to_string())
        ),
    };
    let plan = EvalPlan {
        train: &config,
        baseline: &baseline,
        methods: &methods,
        settings: &settings,
        scenes,
        dataset: &dataset,
    };
    prepare_folder(&args.out, &plan)?;
    let lpips = match &args.lpips {
        Some(p) => Some(
            LpipsVgg::load(p, &host).with_context(|| format!("LPIPS weights {}", p.display()))?,
        ),
        None => LpipsVgg::find(&host).context("LPIPS weights")?,
    };
    if lpips.is_none() {
        eprintln!("no LPIPS weights (see `bitt convert-lpips`): LPIPS is reported as n/a");
    }
    let run = EvalRun {
        out: &args.out,
        cache: &args.cache,
        config: &config,
        baseline: &baseline,
        methods: &methods,
        settings: &settings,
        lpips: lpips.as_ref(),
        shard: (shard, shards),
    };
    let mut bar = EvalBar {
        line: ProgressLine::open_ended(),
        done: 0,
        total: 0,
        label: String::new(),
    };
    match args.dataset {
        Dataset::Synthetic => evaluate_synthetic(&run, scenes, &device, &mut bar)?,
        Dataset::Interhand => {
            let root = args
                .root
                .as_ref()
                .context("--dataset interhand needs --root (the InterHand2.6M folder)")?;
            let (hands, prior) = sources(args.model_dir.as_deref(), args.html_dir.as_deref());
            let data = InterHandScenes {
                root,
                split: &args.split,
                hands,
                prior,
                scenes: (args.scenes != "all").then_some(scenes),
            };
            evaluate_interhand(&run, &data, &device, &mut bar)?;
        }
    }
    finish(&args.out, started)
}

/// Merges the scene results in `out` into its tables and says where they are.
fn finish(out: &Path, started: Instant) -> Result<()> {
    merge(&[out.to_path_buf()])?;
    println!(
        "evaluation done in {:.1} min; results in {}/results.md",
        started.elapsed().as_secs_f64() / 60.0,
        out.display()
    );
    Ok(())
}

/// Merges the scene results of `dirs` into the tables of `dirs[0]` and prints them.
fn merge(dirs: &[PathBuf]) -> Result<()> {
    println!("{}", bitt::benchmark::merge(dirs)?);
    Ok(())
}

/// `bitt eval-merge`.
pub fn merge_cmd(args: &MergeArgs) -> Result<()> {
    merge(&args.dirs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt::benchmark::SceneResult;
    use bitt_tests::real_fixture::{scratch, write_mini_interhand};

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
}
