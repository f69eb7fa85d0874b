//! The two jobs of `bitt refine-hands` and their output folder: a synthetic scene's given
//! meshes (scored against its true meshes) and a real photo with its annotation (scored
//! against the hand mask).

use std::path::Path;

use bitt_mesh::{HandPair, TwoHandScene, procedural_pair};
use bitt_synth::SynthScene;
use burn::tensor::Device;

use super::{
    MASK_THRESHOLD, RefineConfig, RefineObserver, Refinement, SPECK_FRACTION,
    drop_small_components, holes, overlay, refine_synthetic, refine_view, silhouette,
    threshold_mask, vertex_error_px,
};
use crate::BittError;
use crate::assets::HandAssets;
use crate::config::TrainConfig;
use crate::input::ImageInput;
use crate::input::{
    HandSource, PriorSource, check_hand_placement, check_sources, hands_in_image, load_models,
    read_image, reference_crop_box, texture_model,
};
use crate::metrics::mask_iou;
use crate::outputs::overlay_scale;
use bitt_mesh::annotation::BITT_CROP_SIZE;

/// The refined hands file of `bitt refine-hands`.
pub const HANDS_JSON: &str = "hands.json";

/// A synthetic scene's refinement with its scores against the true meshes.
#[derive(Debug, Clone)]
pub struct SceneRefinement {
    /// The refinement (hands at the scene's camera).
    pub refinement: Refinement,
    /// Mean and largest projected vertex error (pixels of the scene's image) of the given
    /// meshes against the true ones.
    pub vertex_error_before: (f64, f64),
    /// ... of the refined meshes.
    pub vertex_error_after: (f64, f64),
    /// Silhouette IoU of the given meshes against the true meshes' silhouette.
    pub iou_truth_before: f64,
    /// ... of the refined meshes.
    pub iou_truth_after: f64,
    /// The training image with outlines before (red) and after (green), and its `[H, W]`.
    pub overlay: (Vec<f32>, [usize; 2]),
}

impl SceneRefinement {
    /// Writes the refined hands, `refine.json` and the overlay into `out`
    /// ([`write_refine_outputs`]; the scene's hands are the procedural ones).
    ///
    /// # Errors
    /// As [`write_refine_outputs`].
    pub fn write(&self, out: &Path) -> Result<(), BittError> {
        write_refine_outputs(
            out,
            &procedural_pair(),
            &self.refinement.hands,
            &self.record(),
            &self.overlay,
        )
    }

    /// What the refinement did, as lines for the user: its notes, the projected vertex error
    /// and the silhouette IoU against the true meshes.
    pub fn report_lines(&self) -> Vec<String> {
        let mut lines = notes(&self.refinement);
        let (b, a) = (self.vertex_error_before, self.vertex_error_after);
        lines.push(format!(
            "projected vertex error: {:.2} px mean ({:.2} max) before, {:.2} px mean ({:.2} max) after",
            b.0, b.1, a.0, a.1
        ));
        lines.push(format!(
            "silhouette IoU against the true meshes: {:.4} before, {:.4} after; {:.1} s",
            self.iou_truth_before, self.iou_truth_after, self.refinement.report.seconds
        ));
        lines
    }

    /// The record `refine.json` holds.
    pub fn record(&self) -> serde_json::Value {
        serde_json::json!({
            "kind": "synthetic scene",
            "report": self.refinement.report,
            "vertex_error_px": {
                "before": {"mean": self.vertex_error_before.0, "max": self.vertex_error_before.1},
                "after": {"mean": self.vertex_error_after.0, "max": self.vertex_error_after.1},
            },
            "silhouette_iou_vs_truth": {
                "before": self.iou_truth_before,
                "after": self.iou_truth_after,
            },
        })
    }
}

/// Refines the given meshes of a synthetic scene at `size` x `size` (`None`: the scene's own
/// image size; refining a 256 px scene at 128 left twice the vertex error on scenes the
/// refinement was not tuned on, `docs/refinement.md`) with `train`'s procedural texture
/// prior (cached in `cache`), and scores them against the true meshes.
///
/// # Errors
/// As [`refine_synthetic`].
pub fn refine_scene(
    scene: &SynthScene,
    train: &TrainConfig,
    size: Option<usize>,
    config: &RefineConfig,
    cache: Option<&Path>,
    device: &Device,
    observer: &mut dyn RefineObserver,
) -> Result<SceneRefinement, BittError> {
    let pca = crate::texture_model::texture_prior(train, cache, &device.clone().inner())?;
    let assets = HandAssets::new(procedural_pair(), train.texture.resolution)?;
    let refinement = refine_synthetic(
        scene,
        &assets,
        &pca,
        size.unwrap_or(scene.given.camera.width.max(scene.given.camera.height) as usize),
        config,
        device,
        observer,
    )?;
    let models = &assets.models;
    let truth = &scene.train.hands;
    let truth_mask = silhouette(models, truth, &assets.scene)?;
    let iou = |hands: &TwoHandScene| -> Result<f64, BittError> {
        Ok(mask_iou(
            &silhouette(models, hands, &assets.scene)?,
            &truth_mask,
        ))
    };
    let image = &scene.train.image;
    let w = scene.given.camera.width as usize;
    Ok(SceneRefinement {
        vertex_error_before: vertex_error_px(models, truth, &scene.given)?,
        vertex_error_after: vertex_error_px(models, truth, &refinement.hands)?,
        iou_truth_before: iou(&scene.given)?,
        iou_truth_after: iou(&refinement.hands)?,
        overlay: overlay(
            image,
            models,
            &assets.scene,
            &scene.given,
            &refinement.hands,
            overlay_scale(w),
        )?,
        refinement,
    })
}

/// The box the photo is refined in (`fit_square` makes a square of it): the reference's crop
/// around the hands, grown to hold every mask pixel (what the fit is scored against), within
/// the photo.
fn fit_box(hands: [f64; 4], mask: &[f32], [h, w]: [usize; 2]) -> [f64; 4] {
    let mut b = reference_crop_box(hands);
    for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m > 0.5) {
        let (x, y) = ((p % w) as f64, (p / w) as f64);
        b = [
            b[0].min(x),
            b[1].min(y),
            b[2].max(x + 1.0),
            b[3].max(y + 1.0),
        ];
    }
    let b = [
        b[0].max(0.0),
        b[1].max(0.0),
        b[2].min(w as f64),
        b[3].min(h as f64),
    ];
    // `fit_square` adds its margin around the box; this box already is the region wanted.
    let k = 1.0 / (1.0 + crate::input::CROP_MARGIN);
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let (hw, hh) = ((b[2] - b[0]) / 2.0 * k, (b[3] - b[1]) / 2.0 * k);
    [cx - hw, cy - hh, cx + hw, cy + hh]
}

/// A photo's refinement with its scores against the hand mask at the photo's size.
#[derive(Debug, Clone)]
pub struct PhotoRefinement {
    /// The refinement (hands at the photo's camera).
    pub refinement: Refinement,
    /// The hand models.
    pub models: HandPair,
    /// Silhouette IoU of the given hands against the mask, at the photo's size.
    pub iou_before: f64,
    /// ... of the refined hands.
    pub iou_after: f64,
    /// Holes ([`super::holes`]) of the given hands in the mask, at the photo's size: the
    /// fraction of mask pixels inside the hands' outline that no mesh covers.
    pub holes_before: f64,
    /// ... of the refined hands.
    pub holes_after: f64,
    /// Where the mask came from (`--mask FILE` or the threshold rule).
    pub mask_source: String,
    /// The photo with outlines before (red) and after (green), and its `[H, W]`.
    pub overlay: (Vec<f32>, [usize; 2]),
}

/// A refinement's notes as lines for the user.
fn notes(refinement: &Refinement) -> Vec<String> {
    refinement
        .report
        .notes
        .iter()
        .map(|n| format!("note: {n}"))
        .collect()
}

impl PhotoRefinement {
    /// Writes the refined hands, `refine.json` and the overlay into `out`
    /// ([`write_refine_outputs`]).
    ///
    /// # Errors
    /// As [`write_refine_outputs`].
    pub fn write(&self, out: &Path) -> Result<(), BittError> {
        write_refine_outputs(
            out,
            &self.models,
            &self.refinement.hands,
            &self.record(),
            &self.overlay,
        )
    }

    /// What the refinement did at `size` x `size`, as lines for the user: its notes and the
    /// silhouette IoU against the mask.
    pub fn report_lines(&self, size: usize) -> Vec<String> {
        let mut lines = notes(&self.refinement);
        lines.push(format!(
            "silhouette IoU against the mask ({}): {:.4} before, {:.4} after; {:.1} s at {size}x{size}",
            self.mask_source, self.iou_before, self.iou_after, self.refinement.report.seconds
        ));
        lines.push(format!(
            "holes (mask pixels inside the hands' outline that no mesh covers): {:.2}% before, \
             {:.2}% after",
            100.0 * self.holes_before,
            100.0 * self.holes_after
        ));
        lines
    }

    /// The record `refine.json` holds.
    pub fn record(&self) -> serde_json::Value {
        serde_json::json!({
            "kind": "photo",
            "report": self.refinement.report,
            "mask": self.mask_source,
            "silhouette_iou_vs_mask": {"before": self.iou_before, "after": self.iou_after},
            "holes_vs_mask": {"before": self.holes_before, "after": self.holes_after},
        })
    }
}

/// Reads a mask image (PNG or JPEG; a pixel is hand when its brightest channel is above 0.5:
/// white, or the red and green of `bitt synth`'s `<view>.mask.png`) and checks it against the
/// photo's size.
///
/// # Errors
/// An unreadable file, a size other than `[h, w]`, or more than [`MAX_MASK_FRACTION`] of
/// it marked as hand.
pub fn read_mask(path: &Path, [h, w]: [usize; 2]) -> Result<Vec<f32>, BittError> {
    let img = bitt_texture::image_io::load_image(path)?;
    if [img.height, img.width] != [h, w] {
        return Err(BittError::Invalid(format!(
            "{}: the mask is {}x{}, the photo {w}x{h}",
            path.display(),
            img.width,
            img.height
        )));
    }
    let hw = h * w;
    let mask: Vec<f32> = (0..hw)
        .map(|p| {
            let brightest = img.data[p].max(img.data[hw + p]).max(img.data[2 * hw + p]);
            if brightest > 0.5 { 1.0 } else { 0.0 }
        })
        .collect();
    let fraction = mask.iter().filter(|&&m| m > 0.5).count() as f64 / (h * w) as f64;
    if fraction > MAX_MASK_FRACTION {
        return Err(BittError::Invalid(format!(
            "{}: the mask marks {:.1}% of the photo as hand (at most {:.0}%): a hand mask is \
             white on the hands and black elsewhere; is it blank or inverted?",
            path.display(),
            100.0 * fraction,
            100.0 * MAX_MASK_FRACTION
        )));
    }
    Ok(mask)
}

/// The largest fraction of a photo that a given hand mask may mark as hand: both hands must
/// be in view, so they cannot fill it (the demo frames' hands and forearms cover 37%). An
/// all-white mask used to blow the hands up to fill the frame.
pub(crate) const MAX_MASK_FRACTION: f64 = 0.9;

/// Refines the hands of a BiTT annotation (pickle or `hands.json`) against its photo, at
/// `size` x `size` (the photo is cropped around the hands as the reference does and resized;
/// the result is for the photo's own camera).
///
/// # Errors
/// Missing or mismatched files, a mask of the wrong size or empty, an annotation with NaN or
/// without both hands, hands outside the image; as [`refine_view`].
#[allow(clippy::too_many_arguments)]
pub fn refine_photo(
    image: &Path,
    annotation: &Path,
    mask: Option<&Path>,
    hands: &HandSource,
    prior: &PriorSource,
    train: &TrainConfig,
    size: usize,
    config: &RefineConfig,
    cache: Option<&Path>,
    device: &Device,
    observer: &mut dyn RefineObserver,
) -> Result<PhotoRefinement, BittError> {
    check_sources(hands, prior)?;
    crate::input::require_image(image)?;
    let scene = bitt_mesh::load_bitt_annotation(annotation, (BITT_CROP_SIZE, BITT_CROP_SIZE))?;
    for side in bitt_mesh::Side::BOTH {
        if scene.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand is not annotated; refinement needs both hands",
                annotation.display()
            )));
        }
    }
    let what = format!("the camera of {}", annotation.display());
    let pixels = read_image(image, &scene.camera, &what)?;
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let mask = match mask {
        Some(m) => Some((read_mask(m, [h, w])?, m.to_path_buf())),
        None => None,
    };
    let models = load_models(hands, prior)?;
    refine_photo_hands(
        image, pixels, &scene, mask, models, prior, train, size, config, cache, device, observer,
    )
}

/// [`refine_photo`] on hands and a photo already in memory: `pixels` `[3, H, W]` at the
/// hands' camera size (`image` names the photo in messages), `mask` an `[H, W]` hand mask and
/// its file (else the threshold rule).
///
/// # Errors
/// As [`refine_photo`].
#[allow(clippy::too_many_arguments)]
pub fn refine_photo_hands(
    image: &Path,
    pixels: Vec<f32>,
    scene: &TwoHandScene,
    mask: Option<(Vec<f32>, std::path::PathBuf)>,
    models: HandPair,
    prior: &PriorSource,
    train: &TrainConfig,
    size: usize,
    config: &RefineConfig,
    cache: Option<&Path>,
    device: &Device,
    observer: &mut dyn RefineObserver,
) -> Result<PhotoRefinement, BittError> {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    if pixels.len() != 3 * w * h {
        return Err(BittError::Invalid(format!(
            "{}: the photo has {} values, the hands' camera is for a {w}x{h} image",
            image.display(),
            pixels.len()
        )));
    }
    let given_mask = mask.is_some();
    let (full_mask, mask_source) = match mask {
        Some((m, path)) => (m, path.display().to_string()),
        None => (
            threshold_mask(&pixels, h * w, MASK_THRESHOLD),
            format!("mean RGB above {MASK_THRESHOLD}"),
        ),
    };
    if !full_mask.iter().any(|&m| m > 0.5) {
        return Err(BittError::Invalid(format!(
            "{} ({mask_source}): the hand mask is empty (no pixel is hand), so there is nothing to fit to",
            image.display()
        )));
    }
    check_hand_placement(scene, &models, image)?;
    let b = hands_in_image(scene, &models, image)?;
    // The fit sees the threshold mask without its specks (point lights); it is scored
    // against the mask as the rule gives it.
    let fit_mask = match given_mask {
        true => full_mask.clone(),
        false => drop_small_components(&full_mask, [h, w], SPECK_FRACTION),
    };
    let view = ImageInput {
        image: pixels.clone(),
        mask: Some(fit_mask.clone()),
        camera: scene.camera,
    }
    .fit_square(Some(fit_box(b, &fit_mask, [h, w])), size)?;
    let mut train = train.clone();
    let assets = HandAssets::new(models, train.texture.resolution)?;
    let pca = texture_model(&mut train, prior, &assets, cache, &device.clone().inner())?;
    let view_hands = TwoHandScene {
        camera: view.camera,
        ..scene.clone()
    };
    let mut refinement = refine_view(
        &assets,
        &pca,
        &view_hands,
        &view.image,
        view.mask,
        config,
        device,
        observer,
        &image.display().to_string(),
    )?;
    refinement.hands.camera = scene.camera;
    refinement.initial.camera = scene.camera;
    let models = &assets.models;
    let hand: Vec<bool> = full_mask.iter().map(|&m| m > 0.5).collect();
    let score = |s: &TwoHandScene| -> Result<(f64, f64), BittError> {
        let drawn = silhouette(models, s, &assets.scene)?;
        let on: Vec<bool> = drawn.iter().map(|&m| m > 0.5).collect();
        Ok((mask_iou(&drawn, &full_mask), holes(&on, &hand, [h, w])))
    };
    let ((iou_before, holes_before), (iou_after, holes_after)) =
        (score(scene)?, score(&refinement.hands)?);
    Ok(PhotoRefinement {
        iou_before,
        iou_after,
        holes_before,
        holes_after,
        mask_source,
        overlay: overlay(
            &pixels,
            models,
            &assets.scene,
            scene,
            &refinement.hands,
            overlay_scale(w),
        )?,
        models: assets.models.clone(),
        refinement,
    })
}

/// Refuses an output folder that exists, is not empty and holds no `refine.json` (not an
/// earlier `refine-hands` output): nothing of the user's is overwritten.
///
/// # Errors
/// [`BittError::Invalid`] naming the folder.
pub fn check_refine_out(out: &Path) -> Result<(), BittError> {
    Ok(crate::outputs::check_own_folder(
        out,
        crate::files::REFINE,
        "refine-hands",
        &REFINE_NAMES,
    )?)
}

/// The names a `refine-hands` folder holds.
const REFINE_NAMES: [&str; 3] = [
    HANDS_JSON,
    crate::files::REFINE_OVERLAY,
    crate::files::REFINE,
];

/// Writes `hands.json`, `refine.json` and `overlay.png` as the folder `out`, as a whole (a
/// kill leaves the earlier folder or the new one). A folder that exists, is not empty and is
/// not an earlier `refine-hands` output is refused.
///
/// # Errors
/// A foreign folder, or a write failure.
pub fn write_refine_outputs(
    out: &Path,
    models: &HandPair,
    hands: &TwoHandScene,
    record: &serde_json::Value,
    overlay: &(Vec<f32>, [usize; 2]),
) -> Result<(), BittError> {
    use crate::files::{REFINE, REFINE_OVERLAY};
    use crate::outputs::{json_bytes, png_file_bytes};
    let text = bitt_mesh::annotation::hands_json(hands, models)?;
    let [h, w] = overlay.1;
    let files = [
        (HANDS_JSON.to_string(), text.into_bytes()),
        (REFINE_OVERLAY.into(), png_file_bytes(&overlay.0, h, w)?),
        (REFINE.into(), json_bytes(&out.join(REFINE), record)?),
    ];
    Ok(crate::outputs::write_own_folder(
        out,
        REFINE,
        "refine-hands",
        &REFINE_NAMES,
        &files,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 38, classes 3 and 10: a mask is hand where its brightest channel is bright (so
    /// `bitt synth`'s red/green masks are not "empty"), and a mask marking nearly the whole
    /// photo is refused.
    #[test]
    fn masks_read_by_their_brightest_channel_and_blank_ones_are_refused() {
        let dir = std::env::temp_dir().join(format!("bitt-read-mask-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (8usize, 4usize);
        // Red on the left half, green on the right half of the top row, black elsewhere.
        let mut rgb = vec![0.0f32; 3 * w * h];
        for x in 0..w {
            let channel = if x < w / 2 { 0 } else { 1 };
            rgb[channel * w * h + x] = 1.0;
        }
        let path = dir.join("train.mask.png");
        bitt_texture::save_png8(&path, &rgb, w, h).unwrap();
        let mask = read_mask(&path, [h, w]).unwrap();
        assert_eq!(mask.iter().filter(|&&m| m > 0.5).count(), w);
        assert!(mask[..w].iter().all(|&m| m == 1.0));
        let white = dir.join("white.png");
        bitt_texture::save_png8(&white, &vec![1.0; 3 * w * h], w, h).unwrap();
        let e = read_mask(&white, [h, w]).unwrap_err().to_string();
        assert!(
            e.contains("white.png") && e.contains("100.0% of the photo"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
