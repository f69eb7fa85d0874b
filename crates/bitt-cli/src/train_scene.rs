//! `bitt train-scene`: train BiTT on one scene and write the run folder (the main job).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt::checkpoint::Checkpoint;
use bitt::run::{files, synthetic_trainer, texture_prior, write_run};
use bitt::{Observer, Progress, TrainConfig};
use bitt_nets::Preset;
use bitt_synth::{SynthConfig, SynthScene};

use crate::device::DeviceName;

/// Arguments of `bitt train-scene`.
#[derive(Debug, clap::Args)]
pub struct TrainSceneArgs {
    /// A synthetic scene folder (`bitt synth`). Default: the built-in demo scene, generated
    /// (and cached) by the synthetic generator.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Named configuration.
    #[arg(long, default_value = "quick")]
    pub preset: Preset,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Iterations (default: the preset's).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Output folder of the run.
    #[arg(long, default_value = "runs/train-scene")]
    pub out: PathBuf,
    /// Continue the run in this folder exactly where its last checkpoint left it (its
    /// `config.json` and scene are used; other options except --iterations are ignored).
    #[arg(long, conflicts_with_all = ["scene", "out"])]
    pub resume: Option<PathBuf>,
    /// Cache folder for the demo scene and the fitted texture PCA.
    #[arg(long, default_value = "runs/cache")]
    pub cache: PathBuf,
    /// Frames of the turntable of novel views.
    #[arg(long, default_value_t = 8)]
    pub turntable: usize,
    /// Seed of the network initialisation.
    #[arg(long)]
    pub seed: Option<u64>,
}

/// A one-line progress bar on stderr; Ctrl-C sets `stop`.
struct Bar {
    started: Instant,
    done_before: usize,
    stop: Arc<AtomicBool>,
}

impl Observer for Bar {
    fn iteration(&mut self, p: &Progress) {
        let width = 30;
        let filled = width * p.iteration / p.iterations.max(1);
        let per =
            self.started.elapsed().as_secs_f64() / (p.iteration - self.done_before).max(1) as f64;
        let eta = per * (p.iterations - p.iteration) as f64;
        eprint!(
            "\r[{}{}] {}/{} loss {:.4} PSNR {:.2} dB lr {:.1e} {:.2} s/it ETA {:.0} s   ",
            "#".repeat(filled),
            "-".repeat(width - filled),
            p.iteration,
            p.iterations,
            p.terms.total,
            p.psnr,
            p.learning_rate,
            per,
            eta
        );
        let _ = std::io::stderr().flush();
        if p.iteration == p.iterations {
            eprintln!();
        }
    }

    fn recovered(&mut self, iteration: usize, message: &str) {
        eprintln!("\nwarning: at iteration {iteration}: {message}");
    }

    fn should_stop(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

fn scene_config(config: &TrainConfig) -> SynthConfig {
    SynthConfig {
        size: config.nets.image_size as u32,
        texture_size: config.texture.resolution,
        ..SynthConfig::default()
    }
}

/// `bitt train-scene`.
pub fn run(args: &TrainSceneArgs) -> Result<()> {
    let started = Instant::now();
    let device = args.device.device()?.autodiff();
    let (out, config, scene, resume) = match &args.resume {
        Some(dir) => {
            let path = dir.join(files::CONFIG);
            let text = std::fs::read_to_string(&path).with_context(|| {
                format!("--resume {}: cannot read {}", dir.display(), path.display())
            })?;
            let mut config = TrainConfig::from_json(&text, &path)?;
            if let Some(n) = args.iterations {
                config.iterations = n;
                config.validate()?;
            }
            let scene = SynthScene::read(&dir.join(files::SCENE))
                .with_context(|| format!("--resume {}: the run's scene", dir.display()))?;
            let ckpt = dir.join(files::CHECKPOINT);
            let checkpoint = Checkpoint::load(&ckpt)
                .with_context(|| format!("--resume {}: no usable checkpoint", dir.display()))?;
            (dir.clone(), config, scene, Some(checkpoint))
        }
        None => {
            if args.out.join(files::CHECKPOINT).exists() {
                bail!(
                    "{} already holds a run; use --resume {} to continue it or choose another --out",
                    args.out.display(),
                    args.out.display()
                );
            }
            let mut config = TrainConfig::preset(args.preset);
            if let Some(n) = args.iterations {
                config.iterations = n;
            }
            if let Some(s) = args.seed {
                config.seed = s;
            }
            config.validate()?;
            let scene = match &args.scene {
                Some(dir) => {
                    SynthScene::read(dir).with_context(|| format!("--scene {}", dir.display()))?
                }
                None => {
                    eprintln!(
                        "building the demo scene (synthetic generator, cached in {})",
                        args.cache.display()
                    );
                    bitt_synth::cached_scene(
                        &scene_config(&config),
                        bitt_synth::demo_scene_seed(),
                        &args.cache.join("scenes"),
                        &device.clone().inner(),
                    )?
                }
            };
            (args.out.clone(), config, scene, None)
        }
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    if resume.is_none() {
        bitt_mesh::export::write_atomically(
            &out.join(files::CONFIG),
            serde_json::to_string_pretty(&config)?.as_bytes(),
        )?;
        scene.write(&out.join(files::SCENE))?;
    }
    eprintln!(
        "fitting / loading the texture PCA ({} components)",
        config.texture.components
    );
    let pca = texture_prior(&config, Some(&args.cache), &device.clone().inner())?;
    let mut trainer = synthetic_trainer(&scene, &config, &pca, &device)?;
    if let Some(c) = &resume {
        trainer.restore(c)?;
        eprintln!(
            "resuming at iteration {} of {}",
            c.iteration, config.iterations
        );
    }
    let [lv, rv] = trainer.view.visible_fraction();
    eprintln!(
        "training {} iterations ({} preset, {} texels per hand, visible {:.0}% / {:.0}%)",
        config.iterations,
        config.preset,
        trainer.assets.num_texels(),
        100.0 * lv,
        100.0 * rv
    );
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while saving is ignored: the checkpoint write is atomic anyway.
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    let mut bar = Bar {
        started: Instant::now(),
        done_before: trainer.iteration,
        stop,
    };
    match trainer.train(Some(&out.join(files::CHECKPOINT)), &mut bar) {
        Err(bitt::BittError::Interrupted(i)) => {
            eprintln!(
                "\ninterrupted after iteration {i}; saved {}. Continue with: cargo xtask train-scene --resume {}",
                out.join(files::CHECKPOINT).display(),
                out.display()
            );
            std::process::exit(130);
        }
        r => r?,
    }
    eprintln!("writing results");
    let summary = write_run(&out, &trainer, Some(&scene), args.turntable)?;
    print_summary(&out, &summary, started.elapsed().as_secs_f64());
    Ok(())
}

fn print_summary(out: &Path, s: &bitt::run::RunSummary, wall: f64) {
    println!(
        "results in {}/ (open {}/report.html)",
        out.display(),
        out.display()
    );
    println!(
        "{} iterations, {:.1} s training, {:.1} s wall clock; input-view PSNR {:.2} dB",
        s.iterations, s.seconds, wall, s.input_psnr
    );
    if let Some(g) = &s.synthetic {
        for (name, m) in [
            ("novel views", &g.novel_views),
            ("novel poses", &g.novel_poses),
        ] {
            if let Some(m) = m {
                println!(
                    "{name} ({}): PSNR fine {:.2} dB vs coarse {:.2} dB; SSIM fine {:.4} vs coarse {:.4}",
                    m.count, m.fine.psnr, m.coarse.psnr, m.fine.ssim, m.coarse.ssim
                );
            }
        }
        if let Some(t) = &g.texture {
            let f = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4}"));
            println!(
                "texture L1 on texels invisible in the input: fine {} vs coarse {}",
                f(t.fine_invisible),
                f(t.coarse_invisible)
            );
        }
    }
}
