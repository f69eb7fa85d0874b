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
use bitt::saved::{AvatarView, SavedRun};

use crate::avatar_pose::OtherPoseArgs;
use crate::device::DeviceName;

/// Arguments of `bitt render-avatar`.
#[derive(Debug, clap::Args)]
pub struct RenderAvatarArgs {
    /// A run folder written by `bitt train-scene`.
    #[arg(long)]
    pub run: PathBuf,
    /// Orbit the camera about the hands: azimuth and elevation in degrees.
    #[arg(long, default_value = "0,0", value_parser = bitt_mesh::camera::parse_orbit_view, allow_hyphen_values = true)]
    pub view: (f64, f64),
    /// Pose the hands as novel pose K of the run's scene (default: the training pose).
    #[arg(long, conflicts_with_all = ["pose", "procedural_pose"])]
    pub novel_pose: Option<usize>,
    /// Another pose (default: the training pose).
    #[command(flatten)]
    pub other_pose: OtherPoseArgs,
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
    /// Write each hand's silhouette instead of the shaded render: the left hand red, the right
    /// hand green where it is in front, black elsewhere (for compositing and for checking
    /// other renderers, e.g. `cargo xtask check-clients`' XR check).
    #[arg(long, conflicts_with = "light")]
    pub masks: bool,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
}

/// `bitt render-avatar`.
pub fn run(args: &RenderAvatarArgs) -> Result<()> {
    if args.out.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--out {}: must be a .png file", args.out.display());
    }
    let user_light = args
        .light
        .as_deref()
        .map(bitt::figure_inputs::read_light)
        .transpose()?;
    args.other_pose.check()?;
    let saved = SavedRun::load(&args.run)?;
    let device = args.device.device()?;
    // The pose and whether the estimated light stays fixed in the training camera's world.
    let (pose, same_world) = if let Some(k) = args.novel_pose {
        let hands = saved.novel_pose(k).with_context(|| {
            format!(
                "--novel-pose {k}; --pose PKL and --procedural-pose NAME pose the avatar otherwise"
            )
        })?;
        (hands, true)
    } else if let Some(hands) = args.other_pose.hands(&saved)? {
        (hands, false)
    } else {
        (saved.training(), true)
    };
    let view = AvatarView {
        pose,
        same_world,
        orbit_deg: [args.view.0, args.view.1],
        size: args.size,
        light: user_light,
    };
    let (image, camera) = if args.masks {
        saved.render_view_masks(&view, &device)?
    } else {
        saved.render_view(&view, &device)?
    };
    let (h, w) = (camera.height as usize, camera.width as usize);
    bitt::outputs::write_png(&args.out, &image, h, w)?;
    println!("wrote {} ({w}x{h})", args.out.display());
    Ok(())
}
