//! `bitt demo`: the built-in demo scene, on the procedural hands (no licensed files).
//!
//! Today it poses the scene and exports it; the reconstruction pipeline extends it.

use std::path::PathBuf;

use anyhow::Result;
use bitt::demo::demo_scene;
use bitt_mesh::procedural_pair;

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
    let models = procedural_pair();
    let scene = demo_scene(&models);
    let posed = scene.pose_in_camera(&models)?;
    std::fs::create_dir_all(&args.out)?;
    let obj = args.out.join("hands.obj");
    let glb = args.out.join("hands.glb");
    posed.write(&models, &obj, Some(&glb))?;
    bitt_mesh::export::write_atomically(
        &args.out.join("scene.json"),
        serde_json::to_string_pretty(&scene)?.as_bytes(),
    )?;
    report_boxes(&scene, &posed, false);
    println!("wrote {}, {} and scene.json", obj.display(), glb.display());
    Ok(())
}
