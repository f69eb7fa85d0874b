//! `bitt render-avatar`: render a trained run's avatar at another view, pose or light.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::run::SavedAvatar;

use crate::device::DeviceName;
use crate::render::parse_light;

/// Arguments of `bitt render-avatar`.
#[derive(Debug, clap::Args)]
pub struct RenderAvatarArgs {
    /// A run folder written by `bitt train-scene`.
    #[arg(long)]
    pub run: PathBuf,
    /// Orbit the training camera about the hands: azimuth and elevation in degrees.
    #[arg(long, default_value = "0,0", value_parser = parse_view, allow_hyphen_values = true)]
    pub view: (f64, f64),
    /// Pose the hands as novel pose K of the run's scene (default: the training pose).
    #[arg(long)]
    pub novel_pose: Option<usize>,
    /// Light as JSON or a JSON file (`{"ambient": [r,g,b], "diffuse": .., "specular": ..,
    /// "location": [x,y,z]}`, camera frame of the rendered view). Default: the run's
    /// estimated light, fixed in the world.
    #[arg(long)]
    pub light: Option<String>,
    /// Backend.
    #[arg(long, value_enum, default_value = "flex")]
    pub device: DeviceName,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_view(s: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [a, e] = parts.as_slice() else {
        return Err(format!("expected AZ,EL in degrees, got {s:?}"));
    };
    let a: f64 = a.trim().parse().map_err(|_| format!("bad azimuth {a:?}"))?;
    let e: f64 = e
        .trim()
        .parse()
        .map_err(|_| format!("bad elevation {e:?}"))?;
    if !(a.is_finite() && e.is_finite()) {
        return Err(format!("view {s:?} is not finite"));
    }
    Ok((a, e))
}

/// `bitt render-avatar`.
pub fn run(args: &RenderAvatarArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--out {}: must be a .png file", args.out.display());
    }
    let light = args.light.as_deref().map(parse_light).transpose()?;
    let avatar = SavedAvatar::load(&args.run).with_context(|| {
        format!(
            "--run {}: not a complete train-scene run",
            args.run.display()
        )
    })?;
    let device = args.device.device()?;
    let hands = avatar.view(
        args.novel_pose,
        args.view.0.to_radians(),
        args.view.1.to_radians(),
    )?;
    let image = avatar.render(&hands, light.as_ref(), &device)?;
    let (h, w) = (hands.camera.height as usize, hands.camera.width as usize);
    bitt::outputs::write_png(&args.out, &image, h, w)?;
    println!("wrote {} ({w}x{h})", args.out.display());
    Ok(())
}
