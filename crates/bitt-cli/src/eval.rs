//! `bitt eval` and `bitt eval-merge`: the paper's evaluation protocol on the synthetic
//! benchmark (crate `bitt`, module `benchmark`), resumable and shardable.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt::baselines::BaselineConfig;
use bitt::benchmark::{
    MeshSetting, Method, SCENE_RESULT_FORMAT, SceneResult, evaluate_scene, results_markdown,
    summarize,
};
use bitt::outputs::{contact_sheet, write_png};
use bitt::run::texture_prior;
use bitt::{Observer, Progress, TrainConfig};
use bitt_mesh::export::write_atomically;
use bitt_nets::Preset;
use bitt_synth::{BENCHMARK_SCENES, MeshNoise, SynthConfig};

use crate::device::DeviceName;

/// Arguments of `bitt eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Scenes of the default benchmark to evaluate: a number (the first N) or `all` (24).
    /// The default (1 scene, both mesh settings, all methods, `quick`) takes about 25
    /// minutes on a 2-core CPU.
    #[arg(long, default_value = "1")]
    pub scenes: String,
    /// Methods, comma-separated: bitt, bitt-no-alb, bitt-no-sym, html, harp-like,
    /// s2hand-like (default: all).
    #[arg(long, value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Mesh settings: both, gt-mesh or noisy-mesh.
    #[arg(long, default_value = "both")]
    pub mesh: String,
    /// Named configuration of every BiTT training.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
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

fn parse_shard(s: &str) -> Result<(usize, usize)> {
    let (i, n) = s
        .split_once('/')
        .with_context(|| format!("--shard {s}: expected i/N"))?;
    let (i, n): (usize, usize) = (
        i.trim().parse().with_context(|| format!("--shard {s}"))?,
        n.trim().parse().with_context(|| format!("--shard {s}"))?,
    );
    if n == 0 || i >= n {
        bail!("--shard {s}: need 0 <= i < N");
    }
    Ok((i, n))
}

fn result_path(out: &Path, setting: MeshSetting, seed: u64) -> PathBuf {
    out.join("scenes")
        .join(format!("{}-{seed:016x}.json", setting.key()))
}

/// Progress over the whole evaluation: BiTT iterations are the unit of work.
struct EvalBar {
    started: Instant,
    done: usize,
    total: usize,
    label: String,
}

impl Observer for EvalBar {
    fn iteration(&mut self, p: &Progress) {
        self.done += 1;
        let per = self.started.elapsed().as_secs_f64() / self.done.max(1) as f64;
        let eta = per * self.total.saturating_sub(self.done) as f64;
        eprint!(
            "\r{} it {}/{} loss {:.4} | eval {}/{} ETA {:.0} min   ",
            self.label,
            p.iteration,
            p.iterations,
            p.terms.total,
            self.done,
            self.total,
            eta / 60.0
        );
        let _ = std::io::stderr().flush();
    }
    fn recovered(&mut self, iteration: usize, message: &str) {
        eprintln!("\nrecovered at iteration {iteration}: {message}");
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
    let methods: Vec<Method> = if args.methods.is_empty() {
        Method::ALL.to_vec()
    } else {
        args.methods
            .iter()
            .map(|k| {
                Method::from_key(k.trim()).with_context(|| {
                    format!(
                        "--methods: unknown method `{k}` (known: {})",
                        Method::ALL.map(|m| m.key()).join(", ")
                    )
                })
            })
            .collect::<Result<_>>()?
    };
    let settings: Vec<MeshSetting> = match args.mesh.as_str() {
        "both" => MeshSetting::ALL.to_vec(),
        "gt-mesh" => vec![MeshSetting::GtMesh],
        "noisy-mesh" => vec![MeshSetting::NoisyMesh],
        other => bail!("--mesh {other}: expected both, gt-mesh or noisy-mesh"),
    };
    let (shard, shards) = match &args.shard {
        Some(s) => parse_shard(s)?,
        None => (0, 1),
    };
    let mut config = TrainConfig::preset(args.preset);
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
    std::fs::create_dir_all(args.out.join("scenes"))
        .with_context(|| format!("creating {}", args.out.join("scenes").display()))?;
    write_atomically(
        &args.out.join("config.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "train": config,
            "baseline": baseline,
            "methods": methods.iter().map(|m| m.key()).collect::<Vec<_>>(),
            "settings": settings.iter().map(|s| s.key()).collect::<Vec<_>>(),
            "scenes": scenes,
        }))?
        .as_bytes(),
    )?;
    let seeds: Vec<(usize, u64)> = bitt_synth::benchmark_seeds(scenes)
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % shards == shard)
        .collect();
    let todo: Vec<(u64, MeshSetting)> = seeds
        .iter()
        .flat_map(|&(_, seed)| settings.iter().map(move |&s| (seed, s)))
        .filter(|&(seed, s)| !result_path(&args.out, s, seed).is_file())
        .collect();
    let skipped = seeds.len() * settings.len() - todo.len();
    if skipped > 0 {
        eprintln!(
            "{skipped} scene result(s) already in {}: skipped",
            args.out.display()
        );
    }
    let trainings = methods
        .iter()
        .filter(|m| m.bitt_config(&config).is_some())
        .count()
        .max(usize::from(methods.contains(&Method::Html)));
    let mut bar = EvalBar {
        started: Instant::now(),
        done: 0,
        total: todo.len() * trainings * config.iterations,
        label: String::new(),
    };
    eprintln!(
        "evaluating {} scene/setting pair(s), {} method(s), preset {} ({} iterations per BiTT training)",
        todo.len(),
        methods.len(),
        config.preset,
        config.iterations
    );
    let pca = texture_prior(&config, Some(&args.cache), &host)?;
    for (k, &(seed, setting)) in todo.iter().enumerate() {
        let synth = SynthConfig {
            size: config.nets.image_size as u32,
            texture_size: config.texture.resolution,
            mesh_noise: (setting == MeshSetting::NoisyMesh).then(MeshNoise::default),
            ..SynthConfig::default()
        };
        let scene = bitt_synth::cached_scene(&synth, seed, &args.cache.join("scenes"), &host)
            .with_context(|| format!("generating scene {seed:#x}"))?;
        bar.label = format!("[{}/{}] {seed:016x} {}", k + 1, todo.len(), setting.key());
        let (result, sheets) = evaluate_scene(
            &scene, setting, &config, &baseline, &pca, &methods, &device, &mut bar,
        )
        .with_context(|| format!("scene {seed:#x} ({})", setting.key()))?;
        // Contact sheet: ground truth then each method, novel view (top) and pose (bottom).
        let size = config.nets.image_size;
        let gt = |v: &bitt_synth::SynthView| -> Vec<f32> {
            let hw = v.masks[0].len();
            (0..3 * hw)
                .map(|i| v.image[i] * (v.masks[0][i % hw] + v.masks[1][i % hw]).min(1.0))
                .collect()
        };
        if let (Some(v), Some(p)) = (scene.novel_views.first(), scene.novel_poses.first())
            && v.masks[0].len() == size * size
        {
            let mut panels = vec![scene.train.image.clone(), gt(v)];
            panels.extend(sheets.iter().map(|(_, s)| s.0.clone()));
            panels.push(scene.train.image.clone());
            panels.push(gt(p));
            panels.extend(sheets.iter().map(|(_, s)| s.1.clone()));
            let (img, h, w) = contact_sheet(&panels, size, size, 2 + sheets.len());
            let dir = args.out.join("sheets");
            std::fs::create_dir_all(&dir)?;
            write_png(
                &dir.join(format!("{}-{seed:016x}.png", setting.key())),
                &img,
                h,
                w,
            )?;
            let legend: Vec<&str> = ["input", "ground truth"]
                .into_iter()
                .chain(sheets.iter().map(|(m, _)| m.key()))
                .collect();
            write_atomically(
                &dir.join("columns.txt"),
                format!("{}\n", legend.join(" | ")).as_bytes(),
            )?;
        }
        write_atomically(
            &result_path(&args.out, setting, seed),
            serde_json::to_string_pretty(&result)?.as_bytes(),
        )?;
    }
    eprintln!();
    merge(std::slice::from_ref(&args.out))?;
    println!(
        "evaluation done in {:.1} min; results in {}/results.md",
        started.elapsed().as_secs_f64() / 60.0,
        args.out.display()
    );
    Ok(())
}

/// Reads every scene result under `dirs[k]/scenes/` and writes `results.json` and
/// `results.md` into `dirs[0]`.
fn merge(dirs: &[PathBuf]) -> Result<()> {
    let mut results: Vec<SceneResult> = Vec::new();
    for dir in dirs {
        let scenes = dir.join("scenes");
        let entries =
            std::fs::read_dir(&scenes).with_context(|| format!("reading {}", scenes.display()))?;
        let mut paths: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "json"))
            .collect();
        paths.sort();
        for p in paths {
            let text =
                std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
            let r: SceneResult = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a scene result", p.display()))?;
            if r.format != SCENE_RESULT_FORMAT {
                bail!(
                    "{}: format {} (expected {SCENE_RESULT_FORMAT})",
                    p.display(),
                    r.format
                );
            }
            if !results
                .iter()
                .any(|x| x.seed == r.seed && x.setting == r.setting)
            {
                results.push(r);
            }
        }
    }
    if results.is_empty() {
        bail!(
            "no scene results under {}",
            dirs[0].join("scenes").display()
        );
    }
    let summary = summarize(&results);
    let out = &dirs[0];
    write_atomically(
        &out.join("results.json"),
        serde_json::to_string_pretty(&serde_json::json!({
            "summary": summary,
            "scenes": results,
        }))?
        .as_bytes(),
    )?;
    let md = results_markdown(&summary, "unavailable (no LPIPS weights; never estimated)");
    write_atomically(&out.join("results.md"), md.as_bytes())?;
    println!("{md}");
    Ok(())
}

/// `bitt eval-merge`.
pub fn merge_cmd(args: &MergeArgs) -> Result<()> {
    merge(&args.dirs)
}
