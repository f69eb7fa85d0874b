//! `bitt synth`: write synthetic two-hand scenes (the default benchmark unless told
//! otherwise), their Table-3 statistics and a contact sheet.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt_synth::{BENCHMARK_SCENES, MeshNoise, SynthConfig, benchmark_seeds, write_scene_set};

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
    let started = Instant::now();
    let set = write_scene_set(&config, &seeds, &args.out, sheet_n, &device, |w| {
        eprintln!("{}", w.line());
    })?;
    let (sheet, w, h) = &set.sheet;
    if let Some(extra) = &args.sheet {
        bitt_texture::save_png8(extra, sheet, *w, *h)
            .with_context(|| format!("--sheet {}", extra.display()))?;
    }
    for line in set.table3_lines(args.scenes) {
        println!("{line}");
    }
    println!(
        "wrote {} scenes, {} and {} in {:.1} s",
        args.scenes,
        set.stats_path.display(),
        set.sheet_path.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
