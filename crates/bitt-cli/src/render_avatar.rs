//! `bitt render-avatar`: render a trained run's avatar at another view, pose or light.
//!
//! Works on synthetic runs (the scene is in the run folder) and on real runs (`input.json`:
//! the hand models are read again from where the run recorded them). Poses: the training
//! pose (default), a novel pose of the run's scene (`--novel-pose K`), the hands of another
//! BiTT annotation pickle (`--pose PKL`, its own camera cropped around the hands like a
//! training view), or a named pose of the synthetic generator (`--procedural-pose NAME`, with
//! the avatar's hand shapes, seen from the front and above).
//!
//! Light (without `--light`): the estimated light stays where it is in the world for the
//! training pose and the scene's novel poses (they share the training camera's world); for
//! `--pose` and `--procedural-pose`, whose world is another one, it keeps its place relative
//! to the camera (as estimated in the training view), and `--view` then orbits the camera
//! with the light fixed in the world.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::evaluate::move_light;
use bitt::real::{
    RealAvatar, RealInput, annotation_pose, orbit_hands, parse_pose_family, procedural_pose,
    render_textures,
};
use bitt::run::SavedAvatar;
use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene, procedural_pair};
use bitt_render::scene::LightValues;

use crate::device::DeviceName;
use crate::render::parse_light;

/// Arguments of `bitt render-avatar`.
#[derive(Debug, clap::Args)]
pub struct RenderAvatarArgs {
    /// A run folder written by `bitt train-scene`.
    #[arg(long)]
    pub run: PathBuf,
    /// Orbit the camera about the hands: azimuth and elevation in degrees.
    #[arg(long, default_value = "0,0", value_parser = parse_view, allow_hyphen_values = true)]
    pub view: (f64, f64),
    /// Pose the hands as novel pose K of the run's scene (default: the training pose).
    #[arg(long, conflicts_with_all = ["pose", "procedural_pose"])]
    pub novel_pose: Option<usize>,
    /// Pose the hands as in another BiTT annotation pickle (the demo `NN.pkl` layout), seen
    /// by its camera cropped around the hands like a training view.
    #[arg(long, conflicts_with = "procedural_pose")]
    pub pose: Option<PathBuf>,
    /// Pose the hands in a named pose of the synthetic generator: clasp, interlaced,
    /// palm_on_back, palm_over_palm, side_by_side, finger_gun, pinch, fist_in_palm, prayer.
    #[arg(long)]
    pub procedural_pose: Option<String>,
    /// Seed of the procedural pose's jitter.
    #[arg(long, default_value_t = 0, requires = "procedural_pose")]
    pub pose_seed: u64,
    /// Light as JSON or a JSON file (`{"ambient": [r,g,b], "diffuse": .., "specular": ..,
    /// "location": [x,y,z]}`, camera frame of the rendered view). Default: the run's
    /// estimated light, fixed in the world; with --pose / --procedural-pose, placed relative
    /// to the camera as it was in the training view.
    #[arg(long)]
    pub light: Option<String>,
    /// Side of the square output in pixels (default: the run's image size); the camera's
    /// intrinsics are scaled, the view stays the same.
    #[arg(long)]
    pub size: Option<u32>,
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

/// A saved avatar of either kind of run.
enum Saved {
    Synthetic(Box<SavedAvatar>),
    Real(Box<RealAvatar>, Box<bitt::assets::HandAssets>),
}

impl Saved {
    fn load(dir: &std::path::Path) -> Result<Self> {
        let context = || format!("--run {}: not a complete train-scene run", dir.display());
        Ok(if RealInput::is_real_run(dir) {
            let avatar = RealAvatar::load(dir).with_context(context)?;
            let assets = avatar.assets().with_context(|| {
                format!(
                    "--run {}: the hand models the run was trained with",
                    dir.display()
                )
            })?;
            Saved::Real(Box::new(avatar), Box::new(assets))
        } else {
            Saved::Synthetic(Box::new(SavedAvatar::load(dir).with_context(context)?))
        })
    }

    fn models(&self) -> HandPair {
        match self {
            Saved::Synthetic(_) => procedural_pair(),
            Saved::Real(_, assets) => assets.models.clone(),
        }
    }

    fn image_size(&self) -> usize {
        match self {
            Saved::Synthetic(a) => a.config.nets.image_size,
            Saved::Real(a, _) => a.config.nets.image_size,
        }
    }

    /// The training pose with the training camera.
    fn training(&self) -> TwoHandScene {
        match self {
            Saved::Synthetic(a) => TwoHandScene {
                camera: a.camera,
                ..a.scene.given.clone()
            },
            Saved::Real(a, _) => a.input.train.hands.clone(),
        }
    }

    fn camera(&self) -> PinholeCamera {
        match self {
            Saved::Synthetic(a) => a.camera,
            Saved::Real(a, _) => a.camera(),
        }
    }

    fn light(&self) -> LightValues {
        match self {
            Saved::Synthetic(a) => a.light,
            Saved::Real(a, _) => a.light,
        }
    }

    /// Novel pose `k` of the run's scene; synthetic novel poses are seen from the training
    /// camera, real ones (InterHand2.6M) from their own camera.
    fn novel_pose(&self, k: usize) -> Result<TwoHandScene> {
        match self {
            Saved::Synthetic(a) => Ok(a.view(Some(k), 0.0, 0.0)?),
            Saved::Real(a, _) => {
                let poses = &a.input.novel_poses;
                if poses.is_empty() {
                    bail!(
                        "--novel-pose {k}: this run was trained from a single annotation and \
                         has no novel poses; use --pose PKL or --procedural-pose NAME"
                    );
                }
                let p = poses.get(k).with_context(|| {
                    format!("--novel-pose {k}: the run has {} novel poses", poses.len())
                })?;
                Ok(p.hands.clone())
            }
        }
    }

    fn render(
        &self,
        hands: &TwoHandScene,
        light: &LightValues,
        device: &burn::tensor::Device,
    ) -> Result<Vec<f32>> {
        Ok(match self {
            Saved::Synthetic(a) => a.render(hands, Some(light), device)?,
            Saved::Real(a, assets) => render_textures(assets, &a.fine, hands, light, device)?,
        })
    }
}

/// `camera` with its intrinsics scaled to a `size x size` image.
fn resized(camera: &PinholeCamera, size: u32) -> Result<PinholeCamera> {
    if !(8..=4096).contains(&size) {
        bail!("--size must be between 8 and 4096 (got {size})");
    }
    if camera.width != camera.height {
        bail!(
            "--size needs a square camera (got {}x{})",
            camera.width,
            camera.height
        );
    }
    let s = f64::from(size) / f64::from(camera.width);
    let mut k = camera.intrinsics * s;
    k.z_axis.z = 1.0;
    Ok(PinholeCamera::new(
        k,
        camera.rotation,
        camera.translation,
        size,
        size,
    )?)
}

/// `bitt render-avatar`.
pub fn run(args: &RenderAvatarArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--out {}: must be a .png file", args.out.display());
    }
    let user_light = args.light.as_deref().map(parse_light).transpose()?;
    let family = args
        .procedural_pose
        .as_deref()
        .map(parse_pose_family)
        .transpose()
        .context("--procedural-pose")?;
    let saved = Saved::load(&args.run)?;
    let device = args.device.device()?;
    let models = saved.models();
    let size = saved.image_size();
    // The pose and whether the estimated light stays fixed in the training camera's world.
    let (base, same_world) = if let Some(k) = args.novel_pose {
        (saved.novel_pose(k)?, true)
    } else if let Some(path) = &args.pose {
        let hands = annotation_pose(path, &models, size)
            .with_context(|| format!("--pose {}", path.display()))?;
        (hands, false)
    } else if let Some(family) = family {
        let training = saved.training();
        let betas = |side: Side| {
            training
                .hand(side)
                .map(|h| h.betas.clone())
                .unwrap_or_else(|| vec![0.0; bitt_mesh::model::NUM_BETAS])
        };
        let (l, r) = (betas(Side::Left), betas(Side::Right));
        let hands = procedural_pose(&models, family, [&l, &r], args.pose_seed, size)?;
        (hands, false)
    } else {
        (saved.training(), true)
    };
    let mut base = base;
    if let Some(n) = args.size {
        base.camera = resized(&base.camera, n)?;
    }
    let hands = orbit_hands(
        &base,
        &models,
        args.view.0.to_radians(),
        args.view.1.to_radians(),
    )?;
    let light = match user_light {
        Some(l) => l,
        None if same_world => move_light(&saved.light(), &saved.camera(), &hands.camera),
        // The estimated light, placed relative to the base camera as it was relative to the
        // training camera, then kept in the world while --view orbits.
        None => move_light(&saved.light(), &base.camera, &hands.camera),
    };
    let image = saved.render(&hands, &light, &device)?;
    let (h, w) = (hands.camera.height as usize, hands.camera.width as usize);
    bitt::outputs::write_png(&args.out, &image, h, w)?;
    println!("wrote {} ({w}x{h})", args.out.display());
    Ok(())
}
