//! `bitt export`: write a trained run's avatar again, without retraining: rigged glTF (the
//! default), static glTF (`--static`) or OBJ (`--format obj`), in the training pose with the
//! clip of the scene's novel poses, or in another annotation's or a generated pose.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt::avatar_export::ExportKind;
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
    /// Output file (`.glb`, or `.obj` with `--format obj`; the OBJ's `.mtl` and PNGs go next
    /// to it).
    #[arg(long)]
    pub out: PathBuf,
}

/// `bitt export`.
pub fn run(args: &ExportArgs) -> Result<()> {
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
