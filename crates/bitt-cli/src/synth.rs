//! `bitt synth`: write synthetic two-hand scenes (the default benchmark unless told
//! otherwise), their Table-3 statistics and a contact sheet.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt_synth::{
    BENCHMARK_SCENES, MeshNoise, SynthConfig, TexelStats, benchmark_seeds, contact_sheet,
    generate_scene,
};

use crate::device::DeviceName;

/// Arguments of `bitt synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Number of scenes.
    #[arg(long, default_value_t = BENCHMARK_SCENES)]
    pub scenes: usize,
    /// First seed: scene i gets seed S + i. Default: the default benchmark's fixed seeds.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Image side (128 or 256).
    #[arg(long, default_value_t = 256, value_parser = parse_image_size)]
    pub size: u32,
    /// Side of the UV textures (64 to 2048).
    #[arg(long, default_value_t = 256)]
    pub texture_size: usize,
    /// Novel views per scene.
    #[arg(long, default_value_t = 8)]
    pub novel_views: usize,
    /// Novel poses per scene.
    #[arg(long, default_value_t = 8)]
    pub novel_poses: usize,
    /// Perturb the meshes given to the method (pose, shape, a few pixels of translation).
    #[arg(long)]
    pub mesh_noise: bool,
    /// Keep the training images clean (no blur, noise or JPEG).
    #[arg(long)]
    pub no_degrade: bool,
    /// Output folder: one folder per scene, `stats.json`, `contact.png`.
    #[arg(long, default_value = "runs/synth")]
    pub out: PathBuf,
    /// Also write the contact sheet here (e.g. docs/images/synth_contact.png).
    #[arg(long)]
    pub sheet: Option<PathBuf>,
    /// Scenes on the contact sheet (the first ones; default 12, at most 24; 12 keep the PNG
    /// under 1 MB).
    #[arg(long)]
    pub sheet_scenes: Option<usize>,
    /// Device to render on.
    #[arg(long, default_value = "flex")]
    pub device: DeviceName,
}

fn parse_image_size(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(n @ (128 | 256)) => Ok(n),
        _ => Err(format!("`{s}`: the image size is 128 or 256")),
    }
}

fn percent(x: f64) -> String {
    format!("{:6.2}%", 100.0 * x)
}

/// `bitt synth`.
pub fn run(args: &SynthArgs) -> Result<()> {
    if !(1..=10_000).contains(&args.scenes) {
        bail!("--scenes must be between 1 and 10000 (got {})", args.scenes);
    }
    let config = SynthConfig {
        size: args.size,
        texture_size: args.texture_size,
        novel_views: args.novel_views,
        novel_poses: args.novel_poses,
        mesh_noise: args.mesh_noise.then(MeshNoise::default),
        degrade: !args.no_degrade,
    };
    config.validate()?;
    let seeds: Vec<u64> = match args.seed {
        Some(s) => (0..args.scenes as u64).map(|i| s.wrapping_add(i)).collect(),
        None => benchmark_seeds(args.scenes),
    };
    let device = args.device.device()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out {}: cannot create the folder", args.out.display()))?;
    let sheet_n = args.sheet_scenes.unwrap_or(12).clamp(1, 24);
    let mut sheet_scenes = Vec::new();
    let mut stats = Vec::new();
    let mut per_scene = Vec::new();
    let started = Instant::now();
    for (i, &seed) in seeds.iter().enumerate() {
        let t0 = Instant::now();
        let scene = generate_scene(&config, seed, &device)
            .with_context(|| format!("generating scene {i} (seed {seed})"))?;
        let gen_s = t0.elapsed().as_secs_f64();
        let dir = args.out.join(format!("scene_{i:03}"));
        scene.write(&dir)?;
        let s = scene.stats;
        eprintln!(
            "scene {i:3} seed {seed:#018x} {:13} left {} right {} sym {} invisible {}  ({gen_s:.1} s + write {:.1} s)",
            format!("{:?}", scene.train.family),
            percent(s.table3.left_visible),
            percent(s.table3.right_visible),
            percent(s.table3.symmetric_usable),
            percent(s.table3.invisible),
            t0.elapsed().as_secs_f64() - gen_s,
        );
        per_scene.push(serde_json::json!({
            "folder": dir.file_name().map(|n| n.to_string_lossy().into_owned()),
            "seed": seed,
            "family": scene.train.family,
            "stats": s,
            "seconds": gen_s,
        }));
        stats.push(s);
        if i < sheet_n {
            sheet_scenes.push(scene);
        }
    }
    let mean = TexelStats::mean(&stats).context("no scenes")?;
    let summary = serde_json::json!({
        "config": config,
        "scenes": args.scenes,
        "mean": mean,
        "paper_interhand": {
            "left_visible": 0.3540, "right_visible": 0.3644,
            "symmetric_usable": 0.2429, "invisible": 0.1989,
        },
        "per_scene": per_scene,
        "seconds": started.elapsed().as_secs_f64(),
    });
    let stats_path = args.out.join("stats.json");
    bitt_mesh::export::write_atomically(
        &stats_path,
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    let (sheet, w, h) = contact_sheet(&sheet_scenes)?;
    let sheet_path = args.out.join("contact.png");
    bitt_texture::save_png8(&sheet_path, &sheet, w, h)?;
    if let Some(extra) = &args.sheet {
        bitt_texture::save_png8(extra, &sheet, w, h)
            .with_context(|| format!("--sheet {}", extra.display()))?;
    }
    let t = mean.table3;
    println!(
        "Table 3 ({} scenes, training views)      this     paper (InterHand2.6M)",
        args.scenes
    );
    println!(
        "left-hand visible texture          {}   35.40%",
        percent(t.left_visible)
    );
    println!(
        "right-hand visible texture         {}   36.44%",
        percent(t.right_visible)
    );
    println!(
        "usable symmetric (exactly one)     {}   24.29%",
        percent(t.symmetric_usable)
    );
    println!(
        "invisible (on neither hand)        {}   19.89%",
        percent(t.invisible)
    );
    println!(
        "symmetry gain per hand             {}",
        percent(mean.symmetry_gain)
    );
    println!(
        "reachable per hand (own + other)   {}   ~60%",
        percent(mean.reachable)
    );
    println!(
        "wrote {} scenes, {} and {} in {:.1} s",
        args.scenes,
        stats_path.display(),
        sheet_path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
