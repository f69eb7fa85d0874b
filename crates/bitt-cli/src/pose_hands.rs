//! `bitt pose-hands` and `bitt convert-mano`.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use bitt_mesh::annotation::{
    InterHandFrame, PosedTwoHands, annotation_image_size, pixel_box_lines,
    scene_from_interhand_files,
};
use bitt_mesh::mano::convert_mano_dir;
use bitt_mesh::{HandPair, TwoHandScene, load_bitt_annotation, load_model_dir, procedural_pair};

/// The hand models of `bitt pose-hands` and `bitt render`: MANO or the procedural hands.
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Folder holding MANO_LEFT / MANO_RIGHT as `.pkl` (as distributed) or `.safetensors`
    /// (`bitt render` also needs --uvs for them).
    #[arg(
        long,
        conflicts_with = "procedural",
        required_unless_present = "procedural"
    )]
    pub model_dir: Option<PathBuf>,
    /// Use the project's procedural hand model instead of MANO (it has its own UV layout).
    #[arg(long)]
    pub procedural: bool,
}

impl ModelArgs {
    /// Loads the hand models these options name.
    pub fn models(&self) -> Result<HandPair> {
        match (&self.model_dir, self.procedural) {
            (Some(dir), false) => Ok(load_model_dir(dir)?),
            (None, true) => Ok(procedural_pair()),
            _ => bail!("give exactly one of --model-dir DIR and --procedural"),
        }
    }
}

/// Arguments of `bitt pose-hands`.
#[derive(Debug, clap::Args)]
pub struct PoseHandsArgs {
    /// The hand models.
    #[command(flatten)]
    pub hands: ModelArgs,
    /// A BiTT/InterHand annotation pickle (the demo `NN.pkl` layout).
    #[arg(
        long,
        required_unless_present = "interhand_mano",
        conflicts_with = "interhand_mano"
    )]
    pub annotation: Option<PathBuf>,
    /// InterHand2.6M `*_MANO_NeuralAnnot.json` (with --interhand-cameras, --capture, --frame, --camera-name).
    #[arg(long, requires_all = ["interhand_cameras", "capture", "frame", "camera_name"])]
    pub interhand_mano: Option<PathBuf>,
    /// InterHand2.6M `*_camera.json`.
    #[arg(long)]
    pub interhand_cameras: Option<PathBuf>,
    /// InterHand2.6M capture id.
    #[arg(long)]
    pub capture: Option<String>,
    /// InterHand2.6M frame index.
    #[arg(long)]
    pub frame: Option<String>,
    /// InterHand2.6M camera name.
    #[arg(long)]
    pub camera_name: Option<String>,
    /// Image size `WxH` that the intrinsics refer to. Default: the size of the image beside
    /// the annotation (same name, .jpg/.png), else 256x256 (the BiTT crop).
    #[arg(long, value_parser = parse_size)]
    pub image_size: Option<(u32, u32)>,
    /// OBJ file to write (both hands, left then right, camera frame).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write a glTF binary file.
    #[arg(long)]
    pub glb: Option<PathBuf>,
    /// Print the bounding boxes as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Parses an image size `WxH` (sides 1 to 4096), as `--image-size` takes it.
pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WxH"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| (1..=4096).contains(&n))
            .ok_or_else(|| format!("`{s}` is not WxH with sides 1 to 4096"))
    };
    Ok((parse(w)?, parse(h)?))
}

fn scene(args: &PoseHandsArgs) -> Result<TwoHandScene> {
    if let Some(path) = &args.annotation {
        let size = args
            .image_size
            .unwrap_or_else(|| annotation_image_size(path));
        return Ok(load_bitt_annotation(path, size)?);
    }
    let (Some(mano_path), Some(cam_path), Some(capture), Some(frame), Some(camera)) = (
        &args.interhand_mano,
        &args.interhand_cameras,
        &args.capture,
        &args.frame,
        &args.camera_name,
    ) else {
        bail!(
            "give --annotation FILE, or all of --interhand-mano, --interhand-cameras, --capture, --frame, --camera-name"
        );
    };
    let Some(size) = args.image_size else {
        bail!(
            "--image-size WxH is required with InterHand2.6M JSON (the full frame's size, e.g. 334x512)"
        );
    };
    let which = InterHandFrame {
        capture: capture.clone(),
        frame_idx: frame.clone(),
        camera: camera.clone(),
    };
    Ok(scene_from_interhand_files(
        mano_path, cam_path, &which, size,
    )?)
}

/// Prints each hand's projected bounding box (text or one JSON object).
pub fn report_boxes(scene: &TwoHandScene, posed: &PosedTwoHands, json: bool) {
    for line in pixel_box_lines(scene, posed, json) {
        println!("{line}");
    }
}

/// `bitt pose-hands`.
pub fn run(args: &PoseHandsArgs) -> Result<()> {
    let models = args.hands.models()?;
    let scene = scene(args)?;
    let posed = scene.pose_in_camera(&models)?;
    bitt::export::write_posed(&posed, &models, &args.out, args.glb.as_deref())?;
    report_boxes(&scene, &posed, args.json);
    if !args.json {
        println!("wrote {}", args.out.display());
        if let Some(g) = &args.glb {
            println!("wrote {}", g.display());
        }
    }
    Ok(())
}

/// `bitt convert-mano`: reads both pickles (checking them fully) and writes safetensors.
pub fn convert_mano(model_dir: &Path, out: &Path) -> Result<()> {
    let written = convert_mano_dir(model_dir, out, |line| println!("{line}"))?;
    for w in written {
        println!("wrote {}", w.display());
    }
    Ok(())
}
