//! `bitt texture` and `bitt convert-html`: UV textures from a texture PCA model.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use bitt_texture::procedural::noise::SplitMix64;
use bitt_texture::procedural::{ProceduralTextureConfig, procedural_texture_pca};
use bitt_texture::{TexturePca, convert_html, load_html_model, save_png8, save_png16};

use crate::device::DeviceName;

/// Arguments of `bitt texture`.
#[derive(Debug, clap::Args)]
pub struct TextureArgs {
    /// Texture model: the HTML `model.pkl`, or a `.safetensors` written by `convert-html`
    /// or `--save-model`.
    #[arg(
        long,
        conflicts_with = "procedural",
        required_unless_present = "procedural"
    )]
    pub model: Option<PathBuf>,
    /// Use the project's procedural skin model (fitted on the fly; see --resolution).
    #[arg(long)]
    pub procedural: bool,
    /// Side length of the procedural UV texture, 128 to 1024.
    #[arg(long, default_value_t = 256)]
    pub resolution: usize,
    /// JSON file holding the parameter vector (an array of numbers, one per component).
    #[arg(long, conflicts_with = "random", required_unless_present = "random")]
    pub params: Option<PathBuf>,
    /// Draw the parameters from N(0, 1) with this seed.
    #[arg(long)]
    pub random: Option<u64>,
    /// PNG to write (the whole UV texture; unused texels are black).
    #[arg(long)]
    pub out: PathBuf,
    /// Write a 16-bit PNG instead of 8-bit.
    #[arg(long)]
    pub png16: bool,
    /// Also save the model (useful with --procedural, to skip the fit next time).
    #[arg(long)]
    pub save_model: Option<PathBuf>,
    /// Device for the procedural PCA fit.
    #[arg(long, default_value = "flex")]
    pub device: DeviceName,
}

/// Standard normal numbers from a seed (SplitMix64 + Box-Muller), reproducible everywhere.
fn normal_params(seed: u64, n: usize) -> Vec<f32> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let (u1, u2) = (rng.next_f64().max(1e-300), rng.next_f64());
            ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
        })
        .collect()
}

fn read_params(path: &Path) -> Result<Vec<f32>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let values: Vec<f64> = serde_json::from_str(&text)
        .with_context(|| format!("{} must hold a JSON array of numbers", path.display()))?;
    Ok(values.into_iter().map(|v| v as f32).collect())
}

fn load_model(args: &TextureArgs) -> Result<TexturePca> {
    if args.procedural {
        if !(128..=1024).contains(&args.resolution) {
            bail!(
                "--resolution must be between 128 and 1024 (got {})",
                args.resolution
            );
        }
        let config = ProceduralTextureConfig {
            resolution: args.resolution,
            ..Default::default()
        };
        let start = Instant::now();
        let (pca, fit, eval) = procedural_texture_pca(&config, &args.device.device()?)?;
        let explained: f32 = fit.explained_variance_ratio.iter().sum();
        eprintln!(
            "procedural texture model: {} identities, {} components ({:.1}% of variance), \
             held-out RMSE {:.4} vs train {:.4}, fitted in {:.1} s",
            config.identities,
            pca.num_components,
            100.0 * explained,
            eval.held_out_rmse,
            eval.train_rmse,
            start.elapsed().as_secs_f64()
        );
        return Ok(pca);
    }
    let Some(path) = &args.model else {
        bail!("give --model FILE or --procedural")
    };
    Ok(match path.extension().and_then(|e| e.to_str()) {
        Some("safetensors") => TexturePca::load_safetensors(path)?,
        _ => load_html_model(path)?,
    })
}

/// `bitt texture`.
pub fn run(args: &TextureArgs) -> Result<()> {
    let pca = load_model(args)?;
    if let Some(path) = &args.save_model {
        pca.save_safetensors(path)?;
        println!("wrote {}", path.display());
    }
    let params = match (&args.params, args.random) {
        (Some(p), None) => read_params(p)?,
        (None, Some(seed)) => normal_params(seed, pca.num_components),
        _ => bail!("give exactly one of --params FILE and --random SEED"),
    };
    if params.len() != pca.num_components {
        let source = args
            .params
            .as_ref()
            .map_or("--random".into(), |p| p.display().to_string());
        bail!(
            "{source}: holds {} parameters, but the model has {} components",
            params.len(),
            pca.num_components
        );
    }
    let compact = pca.texture(&params)?;
    let image = pca.layout.compact_to_image(&compact, [0.0; 3])?;
    let (w, h) = (pca.layout.width, pca.layout.height);
    if args.png16 {
        save_png16(&args.out, &image, w, h)?;
    } else {
        save_png8(&args.out, &image, w, h)?;
    }
    println!(
        "wrote {} ({w}x{h}, {} texels used)",
        args.out.display(),
        pca.layout.num_texels()
    );
    Ok(())
}

/// `bitt convert-html`.
pub fn convert(model_dir: &Path, out: &Path) -> Result<()> {
    let written = convert_html(model_dir, out)?;
    println!("wrote {}", written.display());
    Ok(())
}
