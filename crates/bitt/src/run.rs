//! A whole per-scene run: prepare the trainer from a synthetic scene, train (resumably),
//! evaluate against ground truth, and write the run folder.

use bitt_render::scene::LightValuesExt;
use bitt_stdx::FileErrorExt;

use std::path::{Path, PathBuf};

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{PinholeCamera, TwoHandScene, procedural_pair};
use bitt_render::scene::LightValues;
use bitt_stdx::st;
use bitt_synth::SynthScene;
use bitt_texture::TexturePca;
use burn::tensor::Device;

use crate::BittError;
use crate::assets::{HandAssets, ViewGeometry};
use crate::avatar_export::AvatarFiles;
use crate::config::TrainConfig;
use crate::evaluate::{
    Avatar, MeanScore, TextureScore, ViewScore, mean_score, score_textures, score_view,
};
use crate::files;
use crate::input::ImageInput;
use crate::metrics::{ImageMetrics, image_metrics};
use crate::outputs::{
    base64, contact_sheet, mask_rgb, rgb_image, texture_image, write_avatar_glb, write_json,
    write_loss_plot, write_png,
};
use crate::trainer::Trainer;
use bitt_stdx::to_host;

/// Writes one named PNG `[3, h, w]` and lists it in the report.
type PngSink<'a> = dyn FnMut(&str, PathBuf, &[f32], usize, usize) -> Result<(), BittError> + 'a;

/// A scored view: scores, fine render, coarse render, ground-truth hand image.
type Scored = (ViewScore, Vec<f32>, Vec<f32>, Vec<f32>);

/// Writes a real run's scores ([`crate::real::score_real`]) to [`files::REAL_SCORES`].
pub(crate) fn write_real_scores(
    out: &Path,
    scores: &crate::real::RealScores,
) -> Result<(), BittError> {
    Ok(write_json(&out.join(files::REAL_SCORES), scores)?)
}

/// Writes a refinement's record into a run folder: `refine.json` (the report and whatever
/// the caller adds) and `overlay.png`. [`write_run`] puts both into `metrics.json` and the
/// report when they are there.
pub(crate) fn write_refinement(
    dir: &Path,
    record: &serde_json::Value,
    overlay: &[f32],
    [h, w]: [usize; 2],
) -> Result<(), BittError> {
    write_png(&dir.join(files::REFINE_OVERLAY), overlay, h, w)?;
    Ok(write_json(&dir.join(files::REFINE), record)?)
}

/// Writes the record of a refinement that ran before training (`train-scene --refine-mesh`):
/// the overlay on the training view (outlines of the given and the refined hands) and
/// `refine.json` with the report, plus, when the true hands are known (a synthetic scene),
/// the projected vertex errors before and after.
pub(crate) fn write_training_refinement(
    dir: &Path,
    trainer: &Trainer,
    refinement: &crate::refine::Refinement,
    truth: Option<&TwoHandScene>,
) -> Result<(), BittError> {
    let [_, _, _, w] = trainer.view.image.dims();
    let image = to_host(trainer.view.image.clone().inner())?;
    let camera = trainer.view.geometry.scene_camera;
    let at_view = |s: &TwoHandScene| TwoHandScene {
        camera,
        ..s.clone()
    };
    let models = &trainer.assets.models;
    let overlay = crate::refine::overlay(
        &image,
        models,
        &trainer.assets.scene,
        &at_view(&refinement.initial),
        &at_view(&refinement.hands),
        crate::outputs::overlay_scale(w),
    )?;
    let mut record = serde_json::json!({
        "kind": "train-scene",
        "report": refinement.report,
    });
    if let Some(truth) = truth {
        let before = crate::refine::vertex_error_px(models, truth, &refinement.initial)?;
        let after = crate::refine::vertex_error_px(models, truth, &refinement.hands)?;
        record["vertex_error_px"] = serde_json::json!({
            "before": {"mean": before.0, "max": before.1},
            "after": {"mean": after.0, "max": after.1},
        });
    }
    write_refinement(dir, &record, &overlay.0, overlay.1)
}

/// The `refine.json` of a run folder, if it has one.
fn read_refinement(dir: &Path) -> Result<Option<serde_json::Value>, BittError> {
    Ok(crate::outputs::read_json_if_present(
        &dir.join(files::REFINE),
    )?)
}

/// A trainer for a synthetic scene: the given (possibly noisy) meshes, the training image
/// (cropped and resized when its size is not the preset's), the procedural hand models.
pub fn synthetic_trainer(
    scene: &SynthScene,
    config: &TrainConfig,
    pca: &TexturePca,
    device: &Device,
) -> Result<Trainer, BittError> {
    let assets = HandAssets::new(procedural_pair(), config.texture.resolution)?;
    let size = config.nets.image_size;
    let input = ImageInput {
        image: scene.train.image.clone(),
        mask: None,
        camera: scene.given.camera,
    };
    let input = if input.size() == [size, size] {
        input
    } else {
        input.fit_square(None, size)?
    };
    let given = TwoHandScene {
        camera: input.camera,
        ..scene.given.clone()
    };
    let geometry = ViewGeometry::new(&assets, &given, device)?;
    Ok(Trainer::new(
        config.clone(),
        assets,
        pca,
        geometry,
        &input.image,
        input.mask.as_deref(),
        device,
    )?)
}

/// Ground-truth scores of a synthetic run.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SyntheticScores {
    /// The input view (appearance reconstruction).
    pub input_view: ViewScore,
    /// Mean over the novel views.
    pub novel_views: Option<MeanScore>,
    /// Mean over the novel poses.
    pub novel_poses: Option<MeanScore>,
    /// Texture-space errors (`None` when the scene's ground-truth textures use another
    /// texture size than the run).
    pub texture: Option<TextureScore>,
}

/// What [`write_run`] measured, for the caller to print.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RunSummary {
    /// Iterations trained.
    pub iterations: usize,
    /// Training seconds (in `timing.json`, not `metrics.json`: they differ between runs).
    #[serde(skip)]
    pub seconds: f64,
    /// Final loss terms.
    pub final_loss: Option<crate::LossTerms>,
    /// PSNR of `I_fine` against the input hand image.
    pub input_psnr: f64,
    /// Ground-truth scores (synthetic scenes).
    pub synthetic: Option<SyntheticScores>,
}

/// The hands of a synthetic scene's novel poses, for the avatar's clip.
pub(crate) fn novel_pose_clip(scene: &SynthScene) -> Vec<TwoHandScene> {
    scene.novel_poses.iter().map(|v| v.hands.clone()).collect()
}

/// Writes every output of a trained run into `dir` and returns the summary. `clip`: the
/// poses the rigged avatar's animation plays (the scene's novel poses; see
/// [`novel_pose_clip`]).
pub fn write_run(
    dir: &Path,
    trainer: &Trainer,
    synthetic: Option<&SynthScene>,
    turntable_frames: usize,
    clip: &[TwoHandScene],
) -> Result<RunSummary, BittError> {
    let outputs = trainer.forward()?;
    let avatar = Avatar::from_outputs(trainer, &outputs)?;
    let [_, _, h, w] = trainer.view.image.dims();
    let host4 = |t: &burn::tensor::Tensor<4>| to_host(t.clone().inner());
    let renders = dir.join("renders");
    let textures = dir.join("textures");
    for d in [&renders, &textures] {
        std::fs::create_dir_all(d).map_err(|e| BittError::io(d, e))?;
    }
    let mut gallery: Vec<(String, PathBuf)> = Vec::new();
    let mut png = |name: &str, path: PathBuf, values: &[f32], hh: usize, ww: usize| {
        write_png(&path, values, hh, ww)?;
        gallery.push((name.to_string(), path));
        Ok::<(), BittError>(())
    };

    // Images of the training view.
    let input = host4(&trainer.view.image)?;
    let mask = host4(&trainer.view.mask)?;
    let fine_image = host4(&outputs.fine_image)?;
    png("input", renders.join("input.png"), &input, h, w)?;
    png("mask", renders.join("mask.png"), &mask_rgb(&mask), h, w)?;
    png(
        "albedo image A(I)",
        renders.join("albedo.png"),
        &(host4(&outputs.albedo_image)?
            .iter()
            .zip(mask_rgb(&mask))
            .map(|(a, m)| a * m)
            .collect::<Vec<_>>()),
        h,
        w,
    )?;
    png(
        "coarse (I_coarse)",
        renders.join("coarse.png"),
        &host4(&outputs.coarse_image)?,
        h,
        w,
    )?;
    png("fine (I_fine)", renders.join("fine.png"), &fine_image, h, w)?;
    png(
        "visible albedo (I_albedo)",
        renders.join("albedo_render.png"),
        &host4(&outputs.albedo_render)?,
        h,
        w,
    )?;

    // Relit: a white light from below and the estimated colour from below (supplement E).
    let geometry = &trainer.view.geometry;
    let device = geometry.vertices[0].device();
    let lights = [
        (
            "relit: white light from below",
            "relit_white.png",
            LightValues {
                ambient: [0.5; 3],
                diffuse: [0.3; 3],
                specular: [0.2; 3],
                location: [0.0, 1.0, 0.0],
            },
        ),
        (
            "relit: estimated colour from below",
            "relit_colour.png",
            LightValues {
                diffuse: [0.3; 3],
                specular: [0.2; 3],
                location: [0.0, 1.0, 0.0],
                ..avatar.light
            },
        ),
    ];
    for (name, file, light) in lights {
        let img = crate::evaluate::render_geometry(
            trainer,
            geometry,
            &avatar.fine,
            &light.to_light(&device),
        )?;
        png(name, renders.join(file), &img, h, w)?;
    }

    // Turntable of novel views (orbiting the hands' centre).
    let center = {
        let all: Vec<DVec3> = trainer
            .view
            .geometry
            .vertices_host
            .iter()
            .flatten()
            .copied()
            .collect();
        all.iter().copied().sum::<DVec3>() / all.len().max(1) as f64
    };
    let frames_dir = renders.join("turntable");
    std::fs::create_dir_all(&frames_dir).map_err(|e| BittError::io(&frames_dir, e))?;
    let mut frames = Vec::new();
    for k in 0..turntable_frames {
        let yaw = std::f64::consts::TAU * k as f64 / turntable_frames.max(1) as f64;
        // The vertices' centre is in the training camera's frame. The training view's posed
        // vertices are orbited directly, so real runs (no hand parameters kept in the
        // trainer) get a turntable too.
        let (orbited, camera) = orbit_geometry(&trainer.view.geometry, center, yaw, 0.0);
        let img = crate::evaluate::render_geometry(
            trainer,
            &orbited,
            &avatar.fine,
            &avatar.light_for(&camera).to_light(&device),
        )?;
        write_png(&frames_dir.join(format!("frame_{k:03}.png")), &img, h, w)?;
        frames.push(img);
    }
    if !frames.is_empty() {
        let (sheet, sh, sw) = contact_sheet(&frames, h, w, frames.len().min(6));
        png(
            "turntable (novel views)",
            renders.join("turntable.png"),
            &sheet,
            sh,
            sw,
        )?;
    }

    // Textures: PNG per hand and stage, all compact textures in one safetensors file.
    let layout = &trainer.assets.layouts[0];
    let s = trainer.assets.texture_size;
    let mut st_entries: Vec<(String, Vec<f32>)> = Vec::new();
    for (i, side) in ["left", "right"].iter().enumerate() {
        for (stage, values) in [
            ("fine", &avatar.fine[i]),
            ("coarse", &avatar.coarse[i]),
            ("albedo_uv", &avatar.albedo_uv[i]),
            ("visible_mask", &mask_rgb(&avatar.visible[i])),
        ] {
            let img = texture_image(layout, values)?;
            png(
                &format!("{side} texture: {stage}"),
                textures.join(format!("{side}_{stage}.png")),
                &img,
                s,
                s,
            )?;
            st_entries.push((format!("{side}.{stage}"), values.clone()));
        }
    }
    write_texture_safetensors(
        &textures.join("textures.safetensors"),
        &st_entries,
        layout.num_texels(),
        s,
    )?;
    write_json(
        &dir.join(files::LIGHT),
        &light_json(
            &avatar.light,
            trainer.view.light_location.is_some(),
            trainer.view.light_colours.is_some(),
        ),
    )?;

    // The avatar, posed as in the input.
    let images = [
        rgb_image(&texture_image(layout, &avatar.fine[0])?, s, s)?,
        rgb_image(&texture_image(layout, &avatar.fine[1])?, s, s)?,
    ];
    // Rigged (with its clip and a static copy) when the hands' parameters are known; the
    // posed meshes alone for a view made from vertices.
    match &trainer.view.geometry.hands {
        Some(hands) => {
            AvatarFiles {
                models: &trainer.assets.models,
                hands,
                textures: [&images[0], &images[1]],
                material: bitt_render::scene::Material::default(),
                clip: clip.to_vec(),
            }
            .write(dir)?;
            // The hands for WebXR hand tracking (`xr/`), played in the same poses. Synthetic
            // novel poses are seen from the training camera, real ones from their own (as
            // `render-avatar --novel-pose` shows them).
            let mut frames = vec![crate::avatar_export::XrFrame {
                name: "training pose".into(),
                novel_pose: None,
                hands: hands.clone(),
            }];
            for (k, pose) in clip.iter().enumerate() {
                let mut pose = pose.clone();
                if synthetic.is_some() {
                    pose.camera = hands.camera;
                }
                frames.push(crate::avatar_export::XrFrame {
                    name: format!("novel pose {k}"),
                    novel_pose: Some(k),
                    hands: pose,
                });
            }
            crate::avatar_export::XrAvatar {
                convention: bitt_outputs::export::XrConvention::WebXr,
                models: &trainer.assets.models,
                hands,
                textures: [&images[0], &images[1]],
                material: bitt_render::scene::Material::default(),
                frames,
            }
            .write(&dir.join(files::XR))?;
        }
        None => {
            let v = &trainer.view.geometry.vertices_host;
            write_avatar_glb(
                &dir.join(files::AVATAR),
                &[
                    ("left_hand", &v[0], &trainer.assets.models.left, &images[0]),
                    (
                        "right_hand",
                        &v[1],
                        &trainer.assets.models.right,
                        &images[1],
                    ),
                ],
            )?;
        }
    }

    // Ground truth.
    let input_hand = host4(&trainer.view.hand_image)?;
    let input_psnr = image_metrics(&fine_image, &input_hand, [3, h, w]).psnr;
    let synthetic_scores = match synthetic {
        Some(scene) => Some(score_synthetic(
            trainer, &avatar, scene, &mut png, &renders,
        )?),
        None => None,
    };
    write_loss_plot(
        &dir.join(files::LOSS_PLOT),
        &trainer.history,
        &trainer.config.optim,
    )?;
    gallery.push(("loss".into(), dir.join(files::LOSS_PLOT)));
    let summary = RunSummary {
        iterations: trainer.iteration,
        seconds: trainer.seconds(),
        final_loss: trainer.history.last().copied(),
        input_psnr,
        synthetic: synthetic_scores,
    };
    let refinement = read_refinement(dir)?;
    if refinement.is_some() && dir.join(files::REFINE_OVERLAY).is_file() {
        gallery.insert(
            0,
            (
                "mesh refinement: before (red), after (green)".into(),
                dir.join(files::REFINE_OVERLAY),
            ),
        );
    }
    let detection = crate::detect::read_detection(dir)?;
    let detection_overlay = dir.join(crate::detect::DETECTION_OVERLAY);
    if let Some(d) = &detection
        && detection_overlay.is_file()
    {
        gallery.insert(
            0,
            (
                format!(
                    "hand detection: {} (left orange, right blue)",
                    crate::detect::detection_summary(d)
                ),
                detection_overlay,
            ),
        );
    }
    let metrics = serde_json::json!({
        "summary": summary,
        "loss_terms": crate::LossTerms::NAMES,
        "history": trainer.history,
        "events": trainer.events,
        "visible_fraction": trainer.view.visible_fraction(),
        "num_texels": trainer.assets.num_texels(),
        "refine": refinement,
    });
    write_json(&dir.join(files::METRICS), &metrics)?;
    write_json(
        &dir.join(files::TIMING),
        &serde_json::json!({
            "training_seconds": summary.seconds,
            "iterations": summary.iterations,
        }),
    )?;
    write_report(
        &dir.join(files::REPORT),
        trainer,
        &summary,
        refinement.as_ref(),
        detection.as_ref(),
        &gallery,
    )?;
    Ok(summary)
}

fn score_synthetic(
    trainer: &Trainer,
    avatar: &Avatar,
    scene: &SynthScene,
    png: &mut PngSink,
    renders: &Path,
) -> Result<SyntheticScores, BittError> {
    let size = trainer.config.nets.image_size;
    let score = |view: &bitt_synth::SynthView| -> Result<Scored, BittError> {
        // Bring ground truth to the preset's size like the input.
        let (image, masks, hands) = crate::input::fit_synthetic_view(view, size)?;
        let (s, fine, coarse) = score_view(trainer, avatar, &hands, &image, &masks)?;
        let gt = crate::evaluate::hand_image(&image, &masks, size * size)?;
        Ok((s, fine, coarse, gt))
    };
    let (input_view, ..) = score(&scene.train)?;
    let mut sheet = Vec::new();
    let mut views = Vec::new();
    for v in &scene.novel_views {
        let (s, fine, coarse, gt) = score(v)?;
        if sheet.is_empty() {
            sheet.extend([gt, coarse, fine]);
        }
        views.push(s);
    }
    let mut poses = Vec::new();
    for v in &scene.novel_poses {
        let (s, fine, coarse, gt) = score(v)?;
        if sheet.len() == 3 {
            sheet.extend([gt, coarse, fine]);
        }
        poses.push(s);
    }
    if !sheet.is_empty() {
        let (img, gh, gw) = contact_sheet(&sheet, size, size, 3);
        png(
            "ground truth | coarse | fine: novel view (top), novel pose (bottom)",
            renders.join("novel_view_pose.png"),
            &img,
            gh,
            gw,
        )?;
    }
    Ok(SyntheticScores {
        input_view,
        novel_views: mean_score(&views),
        novel_poses: mean_score(&poses),
        texture: (scene.textures[0].len() == 3 * trainer.assets.num_texels())
            .then(|| score_textures(avatar, &scene.textures)),
    })
}

/// `light.json`: the light, its frame, and where its location and colours came from
/// (`searched` / `fitted`: chosen from the photo before training, `bitt_train::light_search`;
/// else the light network's).
fn light_json(l: &LightValues, searched: bool, fitted: bool) -> serde_json::Value {
    let location_from = if searched {
        "the photo's shading, chosen before training and held (loss.photo_light_search)"
    } else {
        "the light network"
    };
    let colours_from = if fitted {
        "the photo's shading, fitted with the location before training and held \
         (loss.photo_light_colours)"
    } else {
        "the light network"
    };
    serde_json::json!({
        "ambient": l.ambient,
        "diffuse": l.diffuse,
        "specular": l.specular,
        "location": l.location,
        "frame": "training camera (metres; x right, y down, z forward)",
        "location_from": location_from,
        "colours_from": colours_from,
    })
}

fn write_texture_safetensors(
    path: &Path,
    entries: &[(String, Vec<f32>)],
    texels: usize,
    size: usize,
) -> Result<(), BittError> {
    let tensors: Vec<st::Entry> = entries
        .iter()
        .map(|(n, v)| {
            let c = v.len() / texels.max(1);
            (
                n.clone(),
                safetensors::Dtype::F32,
                vec![c, texels],
                st::f32_bytes(v),
            )
        })
        .collect();
    let meta = std::collections::HashMap::from([
        ("format".to_string(), "bitt-run-textures".to_string()),
        (
            "layout".to_string(),
            format!(
                "compact [C, T] texels of a {size}x{size} UV map, row-major scan of used texels"
            ),
        ),
    ]);
    Ok(st::write(path, &tensors, meta)?)
}

fn fmt_metrics(m: &ImageMetrics) -> String {
    format!(
        "<td>{:.4}</td><td>{:.2}</td><td>{:.4}</td><td>{}</td>",
        m.l1,
        m.psnr,
        m.ssim,
        m.ms_ssim.map_or("n/a".to_string(), |v| format!("{v:.4}"))
    )
}

fn write_report(
    path: &Path,
    trainer: &Trainer,
    summary: &RunSummary,
    refinement: Option<&serde_json::Value>,
    detection: Option<&serde_json::Value>,
    gallery: &[(String, PathBuf)],
) -> Result<(), BittError> {
    let mut html = String::from(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>BiTT run</title>\
         <style>body{font-family:sans-serif;margin:2em;background:#fafafa}\
         figure{display:inline-block;margin:.5em;vertical-align:top}\
         figcaption{font-size:.85em;color:#444;max-width:24em}\
         img{image-rendering:pixelated;border:1px solid #ccc;max-width:48em}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2em .6em}</style>\
         </head><body><h1>BiTT: two-hand texture reconstruction</h1>",
    );
    html.push_str(&format!(
        "<p>Preset <b>{}</b>, {} iterations in {:.1} s, {} texels per hand. \
         PSNR of the fine render against the input hand image: {:.2} dB.</p>",
        trainer.config.preset,
        summary.iterations,
        summary.seconds,
        trainer.assets.num_texels(),
        summary.input_psnr
    ));
    // The interactive 3D view of the avatar and light `write_run` wrote next to this report.
    let dir = path.parent().unwrap_or(Path::new("."));
    html.push_str("<h2>3D avatar</h2>");
    html.push_str(&crate::viewer::run_viewer_html(
        &dir.join(files::AVATAR),
        &dir.join(files::LIGHT),
    )?);
    if dir
        .join(files::XR)
        .join(crate::avatar_export::xr_files::PAGE)
        .is_file()
    {
        html.push_str(&format!(
            "<p>For hand tracking: <a href=\"{xr}/{page}\">{xr}/{page}</a> plays the hands \
             with three.js's <code>XRHandMeshModel</code> and follows live WebXR hands on a \
             headset; <code>{xr}/{left}</code> and <code>{xr}/{right}</code> are one hand each, \
             with WebXR's 25 joints as bones (<code>{xr}/{joints}</code> maps them to the \
             model's joints).</p>",
            xr = files::XR,
            page = crate::avatar_export::xr_files::PAGE,
            left = crate::avatar_export::xr_files::LEFT,
            right = crate::avatar_export::xr_files::RIGHT,
            joints = crate::avatar_export::xr_files::JOINTS,
        ));
    }
    if let Some(s) = &summary.synthetic {
        html.push_str("<h2>Against ground truth</h2><table><tr><th>evaluation</th><th>method</th><th>L1</th><th>PSNR</th><th>SSIM</th><th>MS-SSIM</th></tr>");
        let mut row = |name: &str, fine: &ImageMetrics, coarse: &ImageMetrics| {
            html.push_str(&format!(
                "<tr><td>{name}</td><td>coarse (HTML)</td>{}</tr>",
                fmt_metrics(coarse)
            ));
            html.push_str(&format!(
                "<tr><td>{name}</td><td><b>BiTT (fine)</b></td>{}</tr>",
                fmt_metrics(fine)
            ));
        };
        row("input view", &s.input_view.fine, &s.input_view.coarse);
        if let Some(m) = &s.novel_views {
            row(&format!("novel views ({})", m.count), &m.fine, &m.coarse);
        }
        if let Some(m) = &s.novel_poses {
            row(&format!("novel poses ({})", m.count), &m.fine, &m.coarse);
        }
        html.push_str("</table>");
        let f = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.4}"));
        if let Some(t) = &s.texture {
            let (fine, coarse) = (&t.fine.gain_fitted, &t.coarse.gain_fitted);
            let (fine_raw, coarse_raw) = (&t.fine.raw, &t.coarse.raw);
            html.push_str(&format!(
                "<p>Texture L1 against the ground-truth albedo, after one gain per colour channel \
                 fitted on the texels visible in the input (raw L1 in brackets): texels visible in \
                 the input: fine {} ({}) / coarse {} ({}); invisible: fine {} ({}) / coarse {} ({}); \
                 of those, visible on the other hand: fine {} ({}) / coarse {} ({}); invisible on \
                 both hands: fine {} ({}) / coarse {} ({}).</p>",
                f(fine.visible),
                f(fine_raw.visible),
                f(coarse.visible),
                f(coarse_raw.visible),
                f(fine.not_visible),
                f(fine_raw.not_visible),
                f(coarse.not_visible),
                f(coarse_raw.not_visible),
                f(fine.symmetric),
                f(fine_raw.symmetric),
                f(coarse.symmetric),
                f(coarse_raw.symmetric),
                f(fine.invisible),
                f(fine_raw.invisible),
                f(coarse.invisible),
                f(coarse_raw.invisible),
            ));
        }
    }
    if let Some(d) = detection {
        html.push_str(&detection_html(d));
    }
    if let Some(r) = refinement {
        let num = |k: &str| {
            r["report"][k]
                .as_f64()
                .map_or("n/a".into(), |v| format!("{v:.3}"))
        };
        html.push_str(&format!(
            "<h2>Mesh refinement</h2><p>The given meshes were refined against the photo \
             before training ({} s). Silhouette IoU against the hand mask: {} before, {} after.</p>",
            num("seconds"),
            num("iou_before"),
            num("iou_after")
        ));
        if let Some(stages) = r["report"]["stages"].as_array() {
            html.push_str("<table><tr><th>stage</th><th>iterations</th><th>loss first</th><th>loss last</th><th>IoU</th><th>s</th></tr>");
            for st in stages {
                let f =
                    |v: &serde_json::Value| v.as_f64().map_or("n/a".into(), |v| format!("{v:.4}"));
                html.push_str(&format!(
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                    escape(st["stage"].as_str().unwrap_or("")),
                    st["iterations"],
                    f(&st["first"]["total"]),
                    f(&st["last"]["total"]),
                    f(&st["iou"]),
                    f(&st["seconds"]),
                ));
            }
            html.push_str("</table>");
        }
        if let Some(notes) = r["report"]["notes"].as_array() {
            for n in notes.iter().filter_map(|n| n.as_str()) {
                html.push_str(&format!("<p>{}</p>", escape(n)));
            }
        }
    }
    if !trainer.events.is_empty() {
        html.push_str("<h2>Recovered events</h2><ul>");
        for (i, e) in &trainer.events {
            html.push_str(&format!("<li>iteration {i}: {}</li>", escape(e)));
        }
        html.push_str("</ul>");
    }
    html.push_str("<h2>Images</h2>");
    for (name, file) in gallery {
        let bytes = std::fs::read(file).map_err(|e| BittError::io(file, e))?;
        html.push_str(&format!(
            "<figure><img src=\"data:image/png;base64,{}\"><figcaption>{}</figcaption></figure>",
            base64(&bytes),
            escape(name)
        ));
    }
    html.push_str("</body></html>\n");
    bitt_stdx::write_atomically(path, html.as_bytes())?;
    Ok(())
}

/// The report's section on the hand detection of a photo-only run (`detection.json`).
fn detection_html(record: &serde_json::Value) -> String {
    let f = |v: f64| {
        if v.is_finite() {
            format!("{v:.3}")
        } else {
            "n/a".into()
        }
    };
    let mut html = format!(
        "<h2>Hand detection</h2><p>Only the photo was given: the built-in detector (MediaPipe \
         Hands' palm and landmark networks and a two-hand search) found both hands in {} s, \
         the hands were fitted to its keypoints and refined against the photo before training \
         (the overlay is below: left hand orange, right hand blue).</p>\
         <table><tr><th>hand</th><th>presence</th><th>probability of its side</th>\
         <th>palm score</th><th>found by</th></tr>",
        f(record["seconds"].as_f64().unwrap_or(f64::NAN)),
    );
    for (side, presence, side_p, palm, stage) in crate::detect::recorded_hands(record) {
        html.push_str(&format!(
            "<tr><td>{side}</td><td>{}</td><td>{}</td><td>{}</td><td>{} stage</td></tr>",
            f(presence),
            f(side_p),
            palm.map_or("n/a".into(), f),
            escape(&stage),
        ));
    }
    html.push_str("</table>");
    html
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The camera the trainer sees for a synthetic scene: the given camera, adjusted when the
/// scene's images are resized to the preset's size.
pub fn training_camera(
    scene: &SynthScene,
    config: &TrainConfig,
) -> Result<PinholeCamera, BittError> {
    Ok(crate::input::fit_camera(
        &scene.given.camera,
        None,
        config.nets.image_size,
    )?)
}

/// A trained avatar read back from a run folder: no networks needed to render it.
#[derive(Debug, Clone)]
pub struct SavedAvatar {
    /// The run's configuration.
    pub config: TrainConfig,
    /// The run's scene.
    pub scene: SynthScene,
    /// Fine textures `[3, T]`, left then right.
    pub fine: [Vec<f32>; 2],
    /// The estimated light, in the training camera's frame.
    pub light: LightValues,
    /// The training camera.
    pub camera: PinholeCamera,
}

impl SavedAvatar {
    /// Reads `config.json`, the scene, `textures/textures.safetensors` and `light.json`.
    pub fn load(dir: &Path) -> Result<Self, BittError> {
        let path = dir.join(files::CONFIG);
        let text = std::fs::read_to_string(&path).map_err(|e| BittError::io(&path, e))?;
        let config = TrainConfig::from_json(&text, &path)?;
        let scene = SynthScene::read(&dir.join(files::SCENE))?;
        let fine = crate::files::read_fine_textures(dir)?;
        let light = crate::files::read_light(dir)?;
        let camera = training_camera(&scene, &config)?;
        Ok(SavedAvatar {
            config,
            scene,
            fine,
            light,
            camera,
        })
    }

    /// Renders the avatar's hands posed as `hands` (its camera included) under `light`
    /// (`None`: the estimated light, kept fixed in the world); `[3, H, W]` on the host.
    pub fn render(
        &self,
        hands: &TwoHandScene,
        light: Option<&LightValues>,
        device: &Device,
    ) -> Result<Vec<f32>, BittError> {
        let assets = HandAssets::new(procedural_pair(), self.config.texture.resolution)?;
        let t = assets.num_texels();
        if self.fine[0].len() != 3 * t {
            return Err(BittError::Invalid(format!(
                "the saved textures have {} values; the {}x{} layout needs {}",
                self.fine[0].len(),
                self.config.texture.resolution,
                self.config.texture.resolution,
                3 * t
            )));
        }
        let geometry = ViewGeometry::new(&assets, hands, device)?;
        let light = match light {
            Some(l) => *l,
            None => crate::evaluate::move_light(&self.light, &self.camera, &hands.camera),
        };
        let tex = |v: &Vec<f32>| {
            burn::tensor::Tensor::<2>::from_data(
                burn::tensor::TensorData::new(v.clone(), [3, t]),
                device,
            )
        };
        let r = geometry.render(
            &assets,
            [tex(&self.fine[0]), tex(&self.fine[1])],
            &light.to_light(device),
            &bitt_render::scene::RenderSettings::default(),
        )?;
        Ok(to_host(r.image)?)
    }

    /// The hands of the training view (or of novel pose `pose`), seen from the training
    /// camera orbited by `yaw` and `pitch` radians about the hands' centre.
    pub fn view(
        &self,
        pose: Option<usize>,
        yaw: f64,
        pitch: f64,
    ) -> Result<TwoHandScene, BittError> {
        let mut hands = match pose {
            None => self.scene.given.clone(),
            Some(k) => {
                let p = self.scene.novel_poses.get(k).ok_or_else(|| {
                    BittError::Invalid(format!(
                        "novel pose {k} asked; the scene has {}",
                        self.scene.novel_poses.len()
                    ))
                })?;
                p.hands.clone()
            }
        };
        hands.camera = self.camera;
        let all = hands.camera_vertices(&procedural_pair())?;
        let center = all.iter().copied().sum::<DVec3>() / all.len().max(1) as f64;
        hands.camera = bitt_mesh::camera::orbit_camera(&self.camera, center, yaw, pitch);
        Ok(hands)
    }
}

// ---------------------------------------------------------------------------------------------
// Orbiting a view.

/// A view's geometry seen from its camera orbited about `center` (camera frame) by `yaw` and
/// `pitch` radians (as [`orbit_camera`]), with the orbited scene camera: the camera-frame
/// vertices are turned instead of the camera, so no hand parameters are needed.
pub(crate) fn orbit_geometry(
    geometry: &ViewGeometry,
    center: DVec3,
    yaw: f64,
    pitch: f64,
) -> (ViewGeometry, PinholeCamera) {
    let turn = DMat3::from_rotation_x(pitch) * DMat3::from_rotation_y(yaw);
    let device = geometry.vertices[0].device();
    let host = geometry.vertices_host.clone().map(|v| {
        v.into_iter()
            .map(|p| turn * (p - center) + center)
            .collect::<Vec<_>>()
    });
    let camera = bitt_mesh::camera::orbit_camera(&geometry.scene_camera, center, yaw, pitch);
    (
        ViewGeometry::from_vertices(geometry.camera, camera, host, &device),
        camera,
    )
}
