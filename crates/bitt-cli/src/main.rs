//! `bitt`: two-hand texture reconstruction from one image (BiTT, CVPR 2024).
//!
//! The binary is the only place that picks a burn device and touches the command line;
//! everything else lives in the library crates (see ARCHITECTURE.md).

mod allocator;
mod args;
mod avatar_pose;
mod backend_check;
mod demo;
mod detect_hands;
mod device;
mod eval;
mod export;
mod fit_hands;
mod gpu_check;
mod metrics;
mod nets;
mod pose_hands;
mod progress;
mod refine_hands;
mod render;
mod render_avatar;
mod synth;
#[cfg(test)]
mod test_args;
mod texture;
mod train_scene;

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// BiTT: bi-directional texture reconstruction of interacting two hands from a single image.
#[derive(Debug, Parser)]
#[command(name = "bitt", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Pose both hands of an annotation and write them (left then right, camera frame) as OBJ
    /// (and optionally glTF binary); print each hand's projected 2D bounding box.
    PoseHands(pose_hands::PoseHandsArgs),
    /// Convert MANO_LEFT.pkl / MANO_RIGHT.pkl to safetensors, so later runs skip the pickle.
    ConvertMano {
        /// Folder holding MANO_LEFT.pkl and MANO_RIGHT.pkl exactly as distributed.
        #[arg(long)]
        model_dir: PathBuf,
        /// Folder to write MANO_LEFT.safetensors and MANO_RIGHT.safetensors into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Write the UV texture of a texture PCA model (HTML or procedural) for a parameter vector.
    Texture(texture::TextureArgs),
    /// Convert the HTML texture model (model_wosr/model.pkl, uvs*.pkl) to safetensors.
    ConvertHtml {
        /// Folder holding HTML's TextureBasis files as distributed.
        #[arg(long)]
        model_dir: PathBuf,
        /// Folder to write html.safetensors into.
        #[arg(long)]
        out: PathBuf,
    },
    /// Run the built-in demo scene (procedural hands; no licensed files needed).
    Demo(demo::DemoArgs),
    /// Print the four networks' parameter counts and output shapes at a preset (JSON).
    Nets(nets::NetsArgs),
    /// L1, PSNR, SSIM, MS-SSIM and LPIPS of one image pair (JSON; LPIPS null without weights).
    Metrics(metrics::MetricsArgs),
    /// Convert the `lpips` package's VGG weights (vgg.pth + torchvision's VGG16) to the
    /// safetensors file LPIPS reads (no Python needed).
    ConvertLpips(metrics::ConvertLpipsArgs),
    /// Time forward + backward of BTR or the albedo U-Net (JSON; `cargo xtask bench`).
    BenchNets(nets::BenchNetsArgs),
    /// Render both hands of a scene with a UV texture under a point light; optionally unwrap
    /// an image onto their texels (visible texels, masks, Table-3 statistics).
    Render(render::RenderArgs),
    /// Write synthetic two-hand scenes (default: the 24-scene benchmark) with ground truth,
    /// their Table-3 statistics (`stats.json`) and a contact sheet.
    Synth(synth::SynthArgs),
    /// Train BiTT on one scene (default: the built-in demo scene) and write the run folder:
    /// textures, light, renders, avatar.glb, metrics and report.html.
    TrainScene(Box<train_scene::TrainSceneArgs>),
    /// The paper's evaluation on the synthetic benchmark: every method trained per scene,
    /// scored on the input view, novel views and poses and in texture space, both mesh
    /// settings; writes results.json, results.md (the paper's tables) and contact sheets.
    Eval(eval::EvalArgs),
    /// Combine the scene results of `bitt eval` shards into results.json and results.md.
    EvalMerge(eval::MergeArgs),
    /// Refine both hands' pose, shape, root and translation against the photo through the
    /// differentiable renderer (a synthetic scene's perturbed meshes, or a photo with its
    /// annotation); writes hands.json, refine.json and overlay.png.
    RefineHands(refine_hands::RefineHandsArgs),
    /// Fit both hands to a photo's 2D keypoints (OpenPose, MediaPipe or plain JSON), with
    /// the photo's intrinsics or a default camera, optionally refined against a hand mask;
    /// without --keypoints, to the hands the built-in detector finds, refined against the
    /// photo. Writes hands.json (an annotation for train-scene), fit.json and overlay.png.
    /// With --scene, the fit on synthetic scenes scored against their true hands.
    FitHands(fit_hands::FitHandsArgs),
    /// Find both hands in a photo with the built-in detector (MediaPipe Hands' networks on
    /// burn and a two-hand search); writes keypoints.json, detection.json and overlay.png,
    /// and prints each hand found. No hand: an error, nothing written; one hand: written,
    /// with a warning naming the missing one.
    DetectHands(detect_hands::DetectHandsArgs),
    /// Convert MediaPipe Hands' TFLite models from the mediapipe 0.10.21 wheel into the
    /// detector's weights file (fp16 safetensors, built into bitt): `pip download --no-deps
    /// mediapipe==0.10.21`, unzip the wheel into DIR, then `bitt convert-mediapipe
    /// --wheel-dir DIR --out crates/bitt-detect/assets/mediapipe_hands.safetensors` (or
    /// `cargo xtask convert-mediapipe --wheel-dir DIR`) and rebuild.
    ConvertMediapipe(detect_hands::ConvertMediapipeArgs),
    /// Render a trained run's avatar at another view (`--view AZ,EL`), pose or light.
    RenderAvatar(render_avatar::RenderAvatarArgs),
    /// Write a trained run's avatar again without retraining: rigged glTF (default, with the
    /// clip of the scene's novel poses), `--static` glTF or `--format obj`, in the training
    /// pose or another (`--pose`, `--procedural-pose`).
    Export(export::ExportArgs),
    /// Mean and largest absolute difference of two images (JSON; `cargo xtask e2e`).
    #[command(hide = true)]
    ImageDiff {
        /// First image.
        a: PathBuf,
        /// Second image.
        b: PathBuf,
    },
    /// Run a small fixed computation (conv, matmul, autodiff) on one backend and print the
    /// numbers, for comparing backends (`cargo xtask e2e`).
    BackendCheck {
        /// flex, ndarray, wgpu or cuda.
        #[arg(long, default_value = "flex")]
        device: device::DeviceName,
    },
    /// Every GPU check in one run on wgpu (whatever adapter exists) against flex: backend
    /// check, demo render, dense rasterizer, training time, network benches; one table at the
    /// end, JSON in --out (`cargo xtask gpu-bundle`, docs/gpu-check.md).
    GpuCheck(gpu_check::GpuCheckArgs),
}

/// Mesa's device-selection Vulkan layer (an implicit layer on Linux) connects to a Wayland
/// display whenever an instance enables Wayland surfaces, as wgpu's does, and prints `error:
/// XDG_RUNTIME_DIR is invalid` each time where there is none (services, CI, Slurm jobs).
/// wgpu picks its adapter itself, so the layer is switched off there (`NODEVICE_SELECT=1`,
/// the layer's own switch); a user's explicit setting is kept.
#[allow(unsafe_code)]
fn quiet_vulkan_layers() {
    let runtime_dir =
        std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| std::path::Path::new(&d).is_dir());
    if !runtime_dir && std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: the first thing `main` does, before any other thread exists, so nothing
        // reads the environment concurrently.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

fn main() -> Result<()> {
    quiet_vulkan_layers();
    allocator::keep_freed_memory();
    let cli = Cli::parse();
    rayon::ThreadPoolBuilder::new()
        .stack_size(WORKER_STACK_BYTES)
        .build_global()?;
    // The command runs on one of rayon's workers, not on the main thread: a parallel
    // operation then starts on the calling worker while the other steals its second half,
    // instead of waking both workers while the main thread sleeps. On 2 cores the main thread
    // was a third thread that ran the serial work (burn's element-wise operations, the
    // autodiff graph) while the workers slept, and handed every parallel section over to
    // them: `bitt train-scene --iterations 60` trained about 15 % faster this way
    // (`docs/training.md`, Speed on the CPU).
    rayon::scope(|_| dispatch(cli.command))
}

/// Stack of each rayon worker, the one that runs the command included: more than the main
/// thread's 8 MiB, which the commands ran on before (reserved, not committed, memory).
const WORKER_STACK_BYTES: usize = 16 << 20;

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::PoseHands(args) => pose_hands::run(&args),
        Command::ConvertMano { model_dir, out } => pose_hands::convert_mano(&model_dir, &out),
        Command::Demo(args) => demo::run(&args),
        Command::Texture(args) => texture::run(&args),
        Command::ConvertHtml { model_dir, out } => texture::convert(&model_dir, &out),
        Command::BackendCheck { device } => backend_check::run(device),
        Command::GpuCheck(args) => gpu_check::run(&args),
        Command::Render(args) => render::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::TrainScene(args) => train_scene::run(&args),
        Command::RenderAvatar(args) => render_avatar::run(&args),
        Command::Export(args) => export::run(&args),
        Command::RefineHands(args) => refine_hands::run(&args),
        Command::FitHands(args) => fit_hands::run(&args),
        Command::DetectHands(args) => detect_hands::run(&args),
        Command::ConvertMediapipe(args) => detect_hands::convert(&args),
        Command::Eval(args) => eval::run(&args),
        Command::EvalMerge(args) => eval::merge_cmd(&args),
        Command::ImageDiff { a, b } => render::image_diff(&a, &b),
        Command::Nets(args) => nets::run(&args),
        Command::Metrics(args) => metrics::run(&args),
        Command::ConvertLpips(args) => metrics::convert(&args),
        Command::BenchNets(args) => nets::bench(&args),
    }
}
