//! `bitt demo`: the built-in demo scene, on the procedural hands (no licensed files).
//!
//! Today it poses the scene and exports it; the reconstruction pipeline extends it.

use std::path::PathBuf;

use anyhow::Result;
use bitt::demo::write_demo;

use crate::pose_hands::report_boxes;

/// Arguments of `bitt demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "runs/demo")]
    pub out: PathBuf,
}

/// `bitt demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    std::fs::create_dir_all(&args.out)?;
    let (scene, posed) = write_demo(&args.out)?;
    report_boxes(&scene, &posed, false);
    println!(
        "wrote {}, {} and scene.json",
        args.out.join("hands.obj").display(),
        args.out.join("hands.glb").display()
    );
    Ok(())
}
