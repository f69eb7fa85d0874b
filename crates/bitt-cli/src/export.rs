//! `bitt export`: write a trained run's avatar again, without retraining: rigged glTF (the
//! default), static glTF (`--static`) or OBJ (`--format obj`), in the training pose with the
//! clip of the scene's novel poses, or in another annotation's or a generated pose; or, with
//! `--xr`, one file per hand for a hand-tracking runtime (WebXR or OpenXR joints).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::avatar_export::ExportKind;
use bitt::export::XrConvention;
use bitt::saved::SavedRun;

use crate::avatar_pose::OtherPoseArgs;

/// Output format of `bitt export`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// glTF 2.0 binary (`.glb`).
    Glb,
    /// Wavefront OBJ with a material library and one texture PNG per hand.
    Obj,
}

/// A hand-tracking joint convention (`--xr`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Xr {
    /// WebXR Hand Input: 25 joints named as the specification (three.js `XRHandMeshModel`).
    Webxr,
    /// OpenXR `XR_EXT_hand_tracking`: 26 joints with the palm, named after the enum.
    Openxr,
}

/// Arguments of `bitt export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A run folder written by `bitt train-scene`.
    #[arg(long)]
    pub run: PathBuf,
    /// Another pose, without a clip (default: the training pose, with the clip of the scene's
    /// novel poses).
    #[command(flatten)]
    pub other_pose: OtherPoseArgs,
    /// The posed meshes without a rig (for tools without skinning).
    #[arg(long = "static")]
    pub static_mesh: bool,
    /// Output format (`obj` is always the posed meshes).
    #[arg(long, value_enum, default_value = "glb")]
    pub format: Format,
    /// One skinned file per hand for a hand-tracking runtime, bones named and oriented as its
    /// joints (docs/avatar.md): `--out` is then a new folder that gets `left.glb`,
    /// `right.glb`, `joints.json` (which bone is which joint), `playback.json` (the run's
    /// poses as tracked joint poses) and, for WebXR, `xr.html`.
    #[arg(long, value_enum, conflicts_with_all = ["static_mesh", "format"])]
    pub xr: Option<Xr>,
    /// Output file (`.glb`, or `.obj` with `--format obj`; the OBJ's `.mtl` and PNGs go next
    /// to it); a folder with `--xr`.
    #[arg(long)]
    pub out: PathBuf,
}

/// `bitt export --xr`.
fn run_xr(args: &ExportArgs, xr: Xr) -> Result<()> {
    if args.other_pose.pose.is_some() || args.other_pose.procedural_pose.is_some() {
        bail!(
            "--xr exports the avatar in its own rest pose; --pose and --procedural-pose do not apply"
        );
    }
    if args.out.is_file() {
        bail!(
            "--out {}: an existing file; --xr writes a folder",
            args.out.display()
        );
    }
    let convention = match xr {
        Xr::Webxr => XrConvention::WebXr,
        Xr::Openxr => XrConvention::OpenXr,
    };
    let saved = SavedRun::load(&args.run)?;
    let error = saved
        .export_xr(convention, &args.out)
        .with_context(|| format!("--out {}", args.out.display()))?;
    println!(
        "wrote {} ({} hand-tracking avatar: left.glb, right.glb, joints.json, playback.json{})",
        args.out.display(),
        convention.as_str(),
        if convention == XrConvention::WebXr {
            ", xr.html"
        } else {
            ""
        }
    );
    println!(
        "driven by tracked joint poses over {} poses: mean vertex error {:.3} mm (max {:.3}) \
         against the model's skinning, {:.3} mm (max {:.3}) with its pose correctives, which \
         no tracker drives",
        error.frames,
        error.mean_without_correctives * 1e3,
        error.max_without_correctives * 1e3,
        error.mean_with_correctives * 1e3,
        error.max_with_correctives * 1e3
    );
    Ok(())
}

/// `bitt export`.
pub fn run(args: &ExportArgs) -> Result<()> {
    if let Some(xr) = args.xr {
        return run_xr(args, xr);
    }
    let want = match args.format {
        Format::Glb => "glb",
        Format::Obj => "obj",
    };
    if args.out.extension().and_then(|e| e.to_str()) != Some(want) {
        bail!(
            "--out {}: must be a .{want} file for --format {want}",
            args.out.display()
        );
    }
    let kind = match (args.format, args.static_mesh) {
        (Format::Obj, _) => ExportKind::Obj,
        (Format::Glb, true) => ExportKind::Static,
        (Format::Glb, false) => ExportKind::Rigged,
    };
    args.other_pose.check()?;
    let saved = SavedRun::load(&args.run)?;
    let hands = args.other_pose.hands(&saved)?;
    saved
        .export(hands.as_ref(), kind, &args.out)
        .with_context(|| format!("--out {}", args.out.display()))?;
    let clip = if hands.is_none() {
        saved.num_novel_poses()
    } else {
        0
    };
    let what = kind.written(clip);
    println!("wrote {} ({what})", args.out.display());
    Ok(())
}
