//! The stages of `bitt gpu-check`, each one computation on the device under test (and the
//! host reference where it compares) returning a [`StageOutcome`].

use std::time::Instant;

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{PinholeCamera, Side, procedural_pair};
use bitt_nets::{BittNetsConfig, Preset};
use bitt_render::scene::{Camera, DepthRange, Scene};
use bitt_render::{RasterKernel, rasterize_dense};
use bitt_synth::{SynthConfig, demo_scene_seed, generate_scene, textured_mesh};
use burn::tensor::{Device, Tensor, TensorData};
use serde_json::json;

use super::{PAPER_ITERATIONS, StageOutcome, TrainingPlan};
use crate::backend_check::{compare, compute};
use crate::nets_bench::{BenchedNet, bench_net};
use bitt::BittError;
use bitt::config::TrainConfig;
use bitt::figure::{FigureHand, FigureOptions, default_light, render_figure};
use bitt::figure_inputs::procedural_textures;
use bitt::run::synthetic_trainer;
use bitt::texture_model::texture_prior;
use bitt_stdx::to_host;

/// Largest mean absolute difference of the demo render allowed between the device and the
/// host (values in `[0, 1]`; `cargo xtask e2e` uses the same bound).
pub(crate) const RENDER_MEAN_TOLERANCE: f64 = 1e-3;
/// UV side of the demo render's procedural skin (`cargo xtask e2e` renders at 256 too).
pub(crate) const RENDER_UV_SIZE: usize = 256;
/// The demo render's procedural skin (`bitt render`'s default person).
pub(crate) const RENDER_SKIN_SEED: u64 = 7;
/// Timed runs of each network bench (the first includes compiling the device's kernels).
pub(crate) const BENCH_RUNS: usize = 3;

fn ok(summary: String, data: serde_json::Value) -> StageOutcome {
    StageOutcome {
        summary,
        data,
        problem: None,
    }
}

/// The backend check ([`crate::backend_check`]) on `device` and on `host`, compared value by
/// value; fails when a field disagrees beyond [`crate::backend_check::close`].
pub fn backend_check(device: &Device, host: &Device) -> Result<StageOutcome, BittError> {
    let reference = compute(host)?;
    let numbers = compute(device)?;
    let c = compare(&reference, &numbers);
    let summary = format!(
        "{} values, max |difference| {:.1e}, loss {:.6} vs {:.6}",
        c.values, c.max_abs_diff, numbers.loss, reference.loss
    );
    let problem = (!c.disagreements.is_empty())
        .then(|| format!("differs from the reference: {}", c.disagreements.join("; ")));
    Ok(StageOutcome {
        summary,
        data: json!({
            "values": c.values,
            "max_abs_diff": c.max_abs_diff,
            "disagreements": c.disagreements,
            "loss": numbers.loss,
            "reference_loss": reference.loss,
        }),
        problem,
    })
}

/// The demo scene's two procedural hands, posed in the camera frame, and its camera.
fn demo_hands() -> Result<([FigureHand; 2], PinholeCamera), BittError> {
    let models = procedural_pair();
    let scene = bitt::demo::demo_scene(&models);
    let posed = scene.pose_in_camera(&models)?;
    let hand = |side: Side| -> Result<FigureHand, BittError> {
        let model = models.get(side).clone();
        let uv = model.uv.clone().ok_or_else(|| {
            BittError::Invalid(format!("the procedural {side} hand has no UV layout"))
        })?;
        let vertices = posed
            .get(side)
            .ok_or_else(|| BittError::Invalid(format!("the demo scene has no {side} hand")))?
            .vertices
            .clone();
        Ok(FigureHand {
            side,
            model,
            uv,
            vertices,
        })
    };
    Ok(([hand(Side::Left)?, hand(Side::Right)?], scene.camera))
}

/// The demo render of `bitt render --procedural --demo --uv-size 256` (both hands under the
/// default light, antialiased) on `device` and on `host`; fails when the mean absolute
/// difference reaches [`RENDER_MEAN_TOLERANCE`] or the image is (almost) black.
pub(crate) fn render_comparison(device: &Device, host: &Device) -> Result<StageOutcome, BittError> {
    let (hands, camera) = demo_hands()?;
    let models = procedural_pair();
    let uvs = [hands[0].uv.clone(), hands[1].uv.clone()];
    let options = FigureOptions {
        uv_size: RENDER_UV_SIZE,
        views: None,
        unwrap: None,
        antialias: true,
    };
    let render_on = |d: &Device| -> Result<(Vec<f32>, [usize; 2], f64), BittError> {
        let start = Instant::now();
        let textures = procedural_textures(&models, &uvs, RENDER_SKIN_SEED, RENDER_UV_SIZE, d)?;
        let (images, _) = render_figure(&hands, &textures, &camera, &default_light(), &options)?;
        let main = images
            .into_iter()
            .find(|i| i.suffix.is_none())
            .ok_or_else(|| BittError::Invalid("the figure has no image of both hands".into()))?;
        Ok((
            main.data,
            [main.height, main.width],
            start.elapsed().as_secs_f64(),
        ))
    };
    let (reference, size, host_seconds) = render_on(host)?;
    let (image, _, device_seconds) = render_on(device)?;
    if image.len() != reference.len() {
        return Err(BittError::Invalid(format!(
            "the device rendered {} values, the reference {}",
            image.len(),
            reference.len()
        )));
    }
    let n = reference.len().max(1) as f64;
    let (sum, max) = reference
        .iter()
        .zip(&image)
        .map(|(a, b)| f64::from((a - b).abs()))
        .fold((0.0, 0.0f64), |(s, m), d| (s + d, m.max(d)));
    let mean = sum / n;
    let brightness = image.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let problem = if mean.is_nan() || mean >= RENDER_MEAN_TOLERANCE {
        Some(format!(
            "mean |difference| {mean:.2e} is not below {RENDER_MEAN_TOLERANCE:e}"
        ))
    } else if brightness < 0.01 {
        Some(format!(
            "the device's image is (almost) black: mean {brightness:.4}"
        ))
    } else {
        None
    };
    Ok(StageOutcome {
        summary: format!(
            "{}x{} demo render: mean |difference| {mean:.2e}, max {max:.2e}",
            size[1], size[0]
        ),
        data: json!({
            "image": [size[0], size[1]],
            "mean_abs_diff": mean,
            "max_abs_diff": max,
            "mean_value": brightness,
            "seconds_device": device_seconds,
            "seconds_reference": host_seconds,
        }),
        problem,
    })
}

/// `bitt_render::rasterize_dense` of the demo scene (both hands, 256 x 256) on `device`
/// against the CPU core (`bitt_render::cpu::rasterize`) on the same clip positions: face ids
/// that differ (and how many of them are exact depth ties, which the check allows), the
/// kernel that ran and the renderer's host readbacks during the call. A second call is timed.
pub(crate) fn raster_comparison(device: &Device) -> Result<StageOutcome, BittError> {
    let (hands, camera) = demo_hands()?;
    let meshes = [
        textured_mesh(&hands[0].model)?,
        textured_mesh(&hands[1].model)?,
    ];
    let topology = Scene::new(&[&meshes[0], &meshes[1]])?.topology().clone();
    let vertices: Vec<f32> = hands
        .iter()
        .flat_map(|h| h.vertices.iter())
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let v = vertices.len() / 3;
    let camera = Camera::Pinhole(PinholeCamera {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..camera
    });
    let (h, w) = (camera.height(), camera.width());
    let clip = camera.clip_positions(
        Tensor::from_data(TensorData::new(vertices, [v, 3]), device),
        DepthRange::default(),
    )?;
    let clip_host: Vec<[f32; 4]> = to_host(clip.clone())?
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let before = bitt_render::host_readbacks();
    let dense = rasterize_dense(clip.clone(), &topology, h, w)?;
    let readbacks = bitt_render::host_readbacks() - before;
    let faces: Vec<i32> = dense
        .face
        .into_data()
        .convert::<i32>()
        .try_into_vec::<i32>()
        .map_err(|e| BittError::Invalid(format!("reading face ids back: {e:?}")))?;
    let depth = to_host(dense.depth)?;
    let start = Instant::now();
    let again = rasterize_dense(clip, &topology, h, w)?;
    to_host(again.depth.clamp_max(1.0).sum())?;
    let seconds = start.elapsed().as_secs_f64();
    let core = bitt_render::cpu::rasterize(&clip_host, topology.faces(), w, h)?;
    let (mut differ, mut ties) = (0usize, 0usize);
    for p in 0..core.face.len() {
        if core.face[p] != faces[p] {
            differ += 1;
            ties += usize::from(core.depth[p] == depth[p]);
        }
    }
    let covered = core.face.iter().filter(|&&f| f >= 0).count();
    let kernel = match dense.kernel {
        RasterKernel::Cube => "Cube",
        RasterKernel::Host => "Host",
    };
    let kernel_text = match dense.host_reason {
        None => kernel.to_string(),
        Some(why) => format!("{kernel} ({why})"),
    };
    let problem = (differ != ties).then(|| {
        format!(
            "{} face ids differ from the CPU core off exact depth ties",
            differ - ties
        )
    });
    Ok(StageOutcome {
        summary: format!(
            "kernel {kernel_text}: {differ} of {covered} covered pixels' face ids differ \
             ({ties} exact ties), {readbacks} host readbacks, {:.3} s per call",
            seconds
        ),
        data: json!({
            "image": [h, w],
            "kernel": kernel,
            "host_reason": dense.host_reason,
            "covered_pixels": covered,
            "face_ids_differing": differ,
            "exact_ties": ties,
            "host_readbacks": readbacks,
            "seconds_per_call": seconds,
        }),
        problem,
    })
}

/// The training iterations' timing: `first` (which compiles the device's kernels) and the
/// mean of the rest, projected to [`PAPER_ITERATIONS`] as the first plus 699 of the rest's
/// mean (the first alone when only one ran).
pub(crate) fn projected_seconds(seconds: &[f64]) -> Option<(f64, f64, f64)> {
    let (&first, rest) = seconds.split_first()?;
    let steady = if rest.is_empty() {
        first
    } else {
        rest.iter().sum::<f64>() / rest.len() as f64
    };
    Some((
        first,
        steady,
        first + steady * (PAPER_ITERATIONS - 1) as f64,
    ))
}

/// Training on the demo scene (`train-scene` without arguments: the synthetic generator's
/// demo seed, generated here on `host`, and the procedural texture PCA fitted here) at
/// `plan`'s preset for its iterations on `device`: setup and per-iteration seconds, the
/// projection to the paper's 700 iterations, and the loss.
pub fn training(
    device: &Device,
    host: &Device,
    plan: &TrainingPlan,
) -> Result<StageOutcome, BittError> {
    let mut config = TrainConfig::preset(plan.preset);
    config.iterations = plan.iterations;
    config.validate()?;
    let start = Instant::now();
    let synth = SynthConfig {
        novel_views: 0,
        novel_poses: 0,
        ..config.scene_config()
    };
    let scene = generate_scene(&synth, demo_scene_seed(), host)?;
    let scene_seconds = start.elapsed().as_secs_f64();
    let pca = texture_prior(&config, None, host)?;
    let pca_seconds = start.elapsed().as_secs_f64() - scene_seconds;
    let mut trainer = synthetic_trainer(&scene, &config, &pca, &device.clone().autodiff())?;
    let setup_seconds = start.elapsed().as_secs_f64();
    let mut seconds = Vec::with_capacity(plan.iterations);
    let mut losses = Vec::with_capacity(plan.iterations);
    for _ in 0..plan.iterations {
        let t = Instant::now();
        let (terms, _psnr) = trainer.step()?;
        seconds.push(t.elapsed().as_secs_f64());
        losses.push(terms.total);
    }
    let (first, steady, projected) = projected_seconds(&seconds)
        .ok_or_else(|| BittError::Invalid("no training iteration ran".into()))?;
    let (loss_first, loss_last) = (losses[0], losses[losses.len() - 1]);
    Ok(ok(
        format!(
            "{} x {}: {steady:.2} s per iteration (first {first:.2} s), \
             {PAPER_ITERATIONS} iterations ~ {:.1} min; setup {setup_seconds:.1} s; \
             loss {loss_first:.4} -> {loss_last:.4}",
            plan.preset,
            plan.iterations,
            projected / 60.0
        ),
        json!({
            "preset": plan.preset,
            "iterations": plan.iterations,
            "image_size": config.nets.image_size,
            "num_texels": trainer.assets.num_texels(),
            "scene_seconds": scene_seconds,
            "texture_pca_seconds": pca_seconds,
            "setup_seconds": setup_seconds,
            "iteration_seconds": seconds,
            "first_iteration_seconds": first,
            "seconds_per_iteration": steady,
            "projected_700_seconds": projected,
            "losses": losses,
        }),
    ))
}

/// [`bench_net`] of BTR or the albedo U-Net at `preset` on `device`, [`BENCH_RUNS`] runs:
/// the first (kernel compilation included) and the fastest.
pub(crate) fn net_bench(
    device: &Device,
    net: BenchedNet,
    preset: Preset,
) -> Result<StageOutcome, BittError> {
    let config = BittNetsConfig::preset(preset);
    let b = bench_net(net, &config, BENCH_RUNS, device)?;
    let best = b.seconds.iter().copied().fold(f64::INFINITY, f64::min);
    let first = b.seconds.first().copied().unwrap_or(f64::NAN);
    Ok(ok(
        format!(
            "{preset} {:?}: forward + backward {best:.3} s (first {first:.3} s), {} parameters",
            b.input_shape, b.params
        ),
        json!({
            "preset": preset,
            "net": net.name(),
            "params": b.params,
            "input_shape": b.input_shape,
            "seconds": b.seconds,
            "best_seconds": best,
        }),
    ))
}
