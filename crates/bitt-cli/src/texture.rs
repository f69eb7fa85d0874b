//! `bitt texture` and `bitt convert-html`: UV textures from a texture PCA model
//! (`bitt::texture_model`).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use bitt::texture_model::{
    model_file, normal_params, procedural_config, procedural_model, read_params, write_texture,
};
use bitt_texture::{TexturePca, convert_html};

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

fn load_model(args: &TextureArgs) -> Result<TexturePca> {
    if args.procedural {
        let config = procedural_config(args.resolution)?;
        let device = args.device.device()?;
        return Ok(procedural_model(&config, &device, |line| {
            eprintln!("{line}")
        })?);
    }
    let Some(path) = &args.model else {
        bail!("give --model FILE or --procedural")
    };
    Ok(model_file(path)?)
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
    let source = args
        .params
        .as_ref()
        .map_or("--random".into(), |p| p.display().to_string());
    let (w, h) = write_texture(&pca, &params, &source, &args.out, args.png16)?;
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
