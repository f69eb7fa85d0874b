//! The job of `bitt fit-hands` (and of `train-scene --image IMG --keypoints FILE`): a photo
//! and a keypoint file, or the hands the built-in detector found in the photo, to both
//! hands, optionally refined against a hand mask (or the threshold rule), and the output
//! folder (`hands.json`, `fit.json`, `overlay.png`; a detection's files too).

use std::path::{Path, PathBuf};

use bitt_mesh::keypoints::{KeypointFormat, KeypointOptions, TwoHandKeypoints, read_keypoints};
use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene};
use burn::tensor::Device;

use super::{FitConfig, FitObserver, KeypointFit, fit_keypoints};
use crate::BittError;
use crate::assets::HandAssets;
use crate::config::TrainConfig;
use crate::detect::{DetectionFiles, PhotoDetection};
use crate::input::{HandSource, PriorSource, check_sources, load_models};
use crate::outputs::overlay_scale;
use crate::refine::{
    HANDS_JSON, PhotoRefinement, RefineConfig, RefineObserver, outlines, read_mask,
    refine_photo_hands,
};

/// The fit's record in a `fit-hands` folder.
pub const FIT_JSON: &str = "fit.json";

/// The un-mirrored photo a `fit-hands --mirrored` folder's `hands.json` is for.
pub const UNMIRRORED_IMAGE: &str = "image.png";

/// A keypoint fit to record in the run folder: [`crate::run_folder::FIT_RECORD`] and its overlay, and the
/// detection its keypoints came from (a photo alone).
#[derive(Debug, Clone)]
pub struct FitOutput {
    /// The record (`fit.json`).
    pub record: serde_json::Value,
    /// The overlay image `[3, H, W]` and its `[H, W]`.
    pub overlay: (Vec<f32>, [usize; 2]),
    /// The detection (`detection.json`, `keypoints.json`, `detection_overlay.png`).
    pub detection: Option<crate::detect::DetectionFiles>,
}

/// Where the keypoints come from and how to read them.
#[derive(Debug, Clone)]
pub struct KeypointSource {
    /// The keypoint file.
    pub path: PathBuf,
    /// Its format (`None`: guessed from the content).
    pub format: Option<KeypointFormat>,
    /// The photo is a mirrored selfie: it is un-mirrored (flipped left-right) before the
    /// fit, with its keypoints and mask, so that each hand gets its own side's model.
    pub mirrored: bool,
    /// MediaPipe: keep the file's labels whatever its layout
    /// ([`KeypointOptions::labels_as_is`]).
    pub labels_as_is: bool,
}

/// Checks `--intrinsics` against the photo (`[w, h]` pixels), as
/// [`bitt_mesh::camera::check_intrinsics_for_image`].
///
/// # Errors
/// [`BittError::Invalid`] naming `--intrinsics`, the value and the allowed range.
pub fn check_intrinsics_for_image(k: [f64; 4], size: [usize; 2]) -> Result<(), BittError> {
    bitt_mesh::camera::check_intrinsics_for_image(k, size).map_err(BittError::Invalid)
}

/// Where a photo's keypoints come from.
#[derive(Debug)]
pub enum PhotoKeypoints<'a> {
    /// A keypoint file.
    File(&'a KeypointSource),
    /// The hands the built-in detector found in the photo (`crate::detect::detect_photo`
    /// of the same photo; it holds the photo's pixels). Both hands are needed.
    Detected(Box<PhotoDetection>),
}

/// `fx,fy,cx,cy` (pixels), as [`bitt_mesh::camera::parse_intrinsics`].
///
/// # Errors
/// [`BittError::Invalid`]: not four finite numbers, or a focal length that is not positive.
pub fn parse_intrinsics(text: &str) -> Result<[f64; 4], BittError> {
    bitt_mesh::camera::parse_intrinsics(text).map_err(BittError::Invalid)
}

/// A photo's keypoint fit.
#[derive(Debug, Clone)]
pub struct PhotoFit {
    /// The keypoint fit (hands at the photo's camera).
    pub fit: KeypointFit,
    /// The keypoints as fitted (un-mirrored with the photo when `mirrored`).
    pub keypoints: TwoHandKeypoints,
    /// The silhouette refinement that followed, when one was asked for.
    pub refinement: Option<PhotoRefinement>,
    /// Each hand's mean keypoint residual (pixels; left, right) after the refinement, when
    /// there was one: the fit's report holds the residual before it.
    pub refined_residual_px: Option<[Option<f64>; 2]>,
    /// The detection the keypoints came from (no keypoint file given).
    pub detection: Option<DetectionFiles>,
    /// The final hands (refined when asked), at the photo's camera.
    pub hands: TwoHandScene,
    /// The hand models.
    pub models: HandPair,
    /// The photo `[3, H, W]` as fitted (un-mirrored when `mirrored`).
    pub image: Vec<f32>,
    /// Whether the photo was un-mirrored.
    pub mirrored: bool,
    /// Where the intrinsics came from.
    pub camera_source: String,
    /// The photo with the keypoints (yellow), the fitted joints and bones (cyan) and the
    /// fitted hands' outlines (green), and its `[H, W]`.
    pub overlay: (Vec<f32>, [usize; 2]),
}

impl PhotoFit {
    /// What the fit did, as lines for the user (its notes, the camera, each hand's residual,
    /// the mask refinement's IoU, where the files are: `out`).
    pub fn report_lines(&self, out: &Path) -> Vec<String> {
        let report = &self.fit.report;
        let mut lines: Vec<String> = report.notes.iter().map(|n| format!("note: {n}")).collect();
        lines.push(format!("camera: {}", self.camera_source));
        for h in &report.hands {
            let refined = self
                .refined_residual_px
                .and_then(|r| r[h.side as usize])
                .map_or(String::new(), |r| {
                    format!("; {r:.2} px mean after the mask refinement")
                });
            lines.push(format!(
                "{} hand: {} keypoints, residual {:.2} px mean ({:.2} max), wrist at {:.3} m{refined}",
                h.side, h.keypoints, h.mean_residual_px, h.max_residual_px, h.wrist_depth_m
            ));
        }
        if let Some(r) = &self.refinement {
            lines.push(format!(
                "mask refinement ({}): silhouette IoU {:.4} -> {:.4}",
                r.mask_source, r.iou_before, r.iou_after
            ));
        }
        lines.push(format!(
            "fitted in {:.1} s; wrote {out}/hands.json (use it as --annotation), {out}/fit.json and {out}/overlay.png",
            report.seconds,
            out = out.display()
        ));
        if self.detection.is_some() {
            lines.push(format!(
                "the detection: {out}/{}, {out}/{} and {out}/{}",
                crate::detect::DETECTION_JSON,
                crate::detect::KEYPOINTS_JSON,
                crate::detect::DETECTION_OVERLAY,
                out = out.display()
            ));
        }
        lines
    }

    /// The record `fit.json` holds.
    pub fn record(&self) -> serde_json::Value {
        serde_json::json!({
            "kind": "keypoint fit",
            "keypoint_format": self.keypoints.format,
            "keypoints": if self.detection.is_some() { "detected in the photo" } else { "file" },
            "mirrored": self.mirrored,
            "camera": self.camera_source,
            "report": self.fit.report,
            "refinement": self.refinement.as_ref().map(PhotoRefinement::record),
            "refined_residual_px": self.refined_residual_px,
        })
    }
}

/// Flips a planar image `[C, H, W]` left-right.
fn flip_planar(image: &[f32], channels: usize, [h, w]: [usize; 2]) -> Vec<f32> {
    let mut out = vec![0.0; image.len()];
    for c in 0..channels {
        for y in 0..h {
            for x in 0..w {
                out[(c * h + y) * w + x] = image[(c * h + y) * w + (w - 1 - x)];
            }
        }
    }
    out
}

/// Fits both hands to the keypoints of a photo (any size): a keypoint file's, or the
/// detector's (which must have found both hands); with `refine`, then refines them against
/// `mask`, or without one against the reference's threshold rule (mean RGB above
/// [`crate::refine::MASK_THRESHOLD`]), as `bitt refine-hands` does, at the BiTT crop size of
/// 256 with `train`'s texture prior.
///
/// # Errors
/// Missing or unreadable files, malformed keypoints (naming the file and field), a
/// detection without both hands (naming the photo and the missing hand), a mask of the wrong
/// size, bad intrinsics, no hand with enough keypoints; as [`fit_keypoints`] and
/// [`refine_photo_hands`].
#[allow(clippy::too_many_arguments)]
pub fn fit_photo(
    image: &Path,
    keypoints: PhotoKeypoints<'_>,
    intrinsics: Option<[f64; 4]>,
    mask: Option<&Path>,
    hands: &HandSource,
    prior: &PriorSource,
    config: &FitConfig,
    refine: Option<(&TrainConfig, &RefineConfig, &mut dyn RefineObserver)>,
    cache: Option<&Path>,
    device: &Device,
    observer: &mut dyn FitObserver,
) -> Result<PhotoFit, BittError> {
    check_sources(hands, prior)?;
    let (mut pixels, [h, w], mut points, mirrored, detection, placed) = match keypoints {
        PhotoKeypoints::File(source) => {
            crate::input::require_image(image)?;
            let photo = bitt_texture::image_io::load_image(image)?;
            let (w, h) = (photo.width, photo.height);
            let options = KeypointOptions {
                format: source.format,
                image_size: [w as u32, h as u32],
                labels_as_is: source.labels_as_is,
            };
            let points = read_keypoints(&source.path, &options)?;
            (photo.data, [h, w], points, source.mirrored, None, None)
        }
        PhotoKeypoints::Detected(found) => {
            found.detection.require_both(image)?;
            let files = found.files()?;
            let points = found.detection.keypoints();
            let placed = found.detection.hypothesized();
            (found.pixels, found.size, points, false, Some(files), placed)
        }
    };
    let mut mask_pixels = match mask {
        Some(m) => Some((read_mask(m, [h, w])?, m.to_path_buf())),
        None => None,
    };
    if mirrored {
        pixels = flip_planar(&pixels, 3, [h, w]);
        points = points.mirrored(w as f64);
        points.notes.push(
            "the photo is a mirrored selfie (--mirrored): photo, keypoints and mask were \
             flipped left-right before the fit, so each hand is fitted by its own side's model"
                .into(),
        );
        if let Some((m, _)) = &mut mask_pixels {
            *m = flip_planar(m, 1, [h, w]);
        }
    }
    let (camera, camera_source) = match intrinsics {
        Some([fx, fy, cx, cy]) => (
            {
                check_intrinsics_for_image([fx, fy, cx, cy], [w, h])?;
                PinholeCamera::from_intrinsics([fx, fy], [cx, cy], w as u32, h as u32)?
            },
            format!("--intrinsics {fx},{fy},{cx},{cy}"),
        ),
        None => {
            let c = PinholeCamera::default_for_image(w as u32, h as u32)?;
            (
                c,
                format!(
                    "default: focal {:.1} px (the image diagonal), principal point at the centre",
                    c.focal().x
                ),
            )
        }
    };
    let models = load_models(hands, prior)?;
    let fit = fit_keypoints(&models, &points, &camera, config, device, observer)?;
    let both = fit.hands.left.is_some() && fit.hands.right.is_some();
    let mut notes = Vec::new();
    let refinement = match (refine, mask_pixels) {
        (Some((train, refine_config, refine_observer)), m) if both => Some(refine_photo_hands(
            image,
            pixels.clone(),
            &fit.hands,
            m,
            models.clone(),
            prior,
            train,
            bitt_mesh::annotation::BITT_CROP_SIZE as usize,
            refine_config,
            cache,
            device,
            refine_observer,
        )?),
        (Some(_), _) => {
            notes.push(
                "the mask refinement needs both hands and was skipped: only one was fitted".into(),
            );
            None
        }
        _ => None,
    };
    let final_hands = refinement
        .as_ref()
        .map_or_else(|| fit.hands.clone(), |r| r.refinement.hands.clone());
    let refined_residual_px = match &refinement {
        Some(_) => {
            let after = keypoint_residuals(&models, &final_hands, &points)?;
            for side in Side::BOTH {
                let (Some(r), Some(span)) = (after[side as usize], points.span_px(side)) else {
                    continue;
                };
                if r > crate::fit::MAX_RESIDUAL_OF_SPAN * span && placed == Some(side) {
                    // The hypothesis is a guess the refinement is there to correct.
                    notes.push(format!(
                        "the mask refinement moved the {side} hand, which the detection placed \
                         by hypothesis, {r:.1} px on average from the placed keypoints ({:.0}% of \
                         their span): the photo, not the guess, decided where it lies (see the \
                         overlay)",
                        100.0 * r / span
                    ));
                } else if r > crate::fit::MAX_RESIDUAL_OF_SPAN * span {
                    notes.push(format!(
                        "the mask refinement moved the {side} hand off its keypoints (it misses \
                         them by {r:.1} px on average, {:.0}% of their span): check the mask",
                        100.0 * r / span
                    ));
                }
            }
            Some(after)
        }
        None => None,
    };
    let mut fit = fit;
    fit.report.notes.extend(notes);
    let assets = HandAssets::new(models.clone(), 64)?;
    let overlay = keypoint_overlay(&pixels, &models, &assets, &points, &final_hands)?;
    Ok(PhotoFit {
        fit,
        keypoints: points,
        refinement,
        refined_residual_px,
        detection,
        hands: final_hands,
        models,
        image: pixels,
        mirrored,
        camera_source,
        overlay,
    })
}

/// Each hand's mean distance (pixels; left, right) between its present `keypoints` and the
/// projected joints of `hands` (`None` for a hand missing from either).
///
/// # Errors
/// Hands that cannot be posed.
pub(crate) fn keypoint_residuals(
    models: &HandPair,
    hands: &TwoHandScene,
    keypoints: &TwoHandKeypoints,
) -> Result<[Option<f64>; 2], BittError> {
    let posed = hands.pose_in_camera(models)?;
    Ok(Side::BOTH.map(|side| {
        let (joints, points) = (&posed.get(side)?.joints, keypoints.hand(side)?);
        let d: Vec<f64> = points
            .iter()
            .zip(joints)
            .filter(|(k, _)| k.confidence > 0.0)
            .filter_map(|(k, j)| {
                let p = hands.camera.camera_to_pixel(*j)?;
                Some((p.x - k.x).hypot(p.y - k.y))
            })
            .collect();
        (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
    }))
}

/// The overlay of [`PhotoFit::overlay`]: `image` `[3, H, W]` at `hands`' camera with
/// `keypoints` (yellow crosses), the fitted joints and bones (cyan) and the hands' outlines
/// (green), enlarged to at least 512 pixels wide; returns it and its `[H, W]`.
///
/// # Errors
/// When a hand cannot be posed or the image does not match the camera.
pub fn keypoint_overlay(
    image: &[f32],
    models: &HandPair,
    assets: &HandAssets,
    keypoints: &TwoHandKeypoints,
    hands: &TwoHandScene,
) -> Result<(Vec<f32>, [usize; 2]), BittError> {
    let w = hands.camera.width as usize;
    let s = overlay_scale(w);
    let (mut out, [bh, bw]) =
        outlines(image, models, &assets.scene, &[(hands, [0.1, 1.0, 0.2])], s)?;
    let posed = hands.pose_in_camera(models)?;
    let sf = s as f64;
    let mut put = |x: f64, y: f64, colour: [f32; 3]| {
        let (px, py) = ((x + 0.5) * sf, (y + 0.5) * sf);
        if px >= 0.0 && py >= 0.0 && (px as usize) < bw && (py as usize) < bh {
            let p = py as usize * bw + px as usize;
            for (c, v) in colour.iter().enumerate() {
                out[c * bw * bh + p] = *v;
            }
        }
    };
    const CYAN: [f32; 3] = [0.1, 0.9, 1.0];
    const YELLOW: [f32; 3] = [1.0, 0.9, 0.1];
    for side in Side::BOTH {
        let Some(p) = posed.get(side) else { continue };
        let px: Vec<Option<bitt_mesh::glam::DVec2>> = p
            .joints
            .iter()
            .map(|j| hands.camera.camera_to_pixel(*j))
            .collect();
        for (child, parent) in crate::hand_priors::bones() {
            if let (Some(a), Some(b)) = (px[child], px[parent]) {
                let n = ((a - b).length() * sf).ceil().max(1.0) as usize;
                for i in 0..=n {
                    let q = b + (a - b) * (i as f64 / n as f64);
                    put(q.x, q.y, CYAN);
                }
            }
        }
        for q in px.iter().flatten() {
            for dy in -2..=2 {
                for dx in -2..=2 {
                    put(q.x + dx as f64 / sf, q.y + dy as f64 / sf, CYAN);
                }
            }
        }
    }
    for side in Side::BOTH {
        for k in keypoints.hand(side).into_iter().flatten() {
            if k.confidence <= 0.0 {
                continue;
            }
            // A cross of 4 enlarged pixels' arms.
            for d in -4i32..=4 {
                let d = f64::from(d) / sf;
                put(k.x + d, k.y, YELLOW);
                put(k.x, k.y + d, YELLOW);
            }
        }
    }
    Ok((out, [bh, bw]))
}

/// Refuses an output folder that exists, is not empty and holds no `fit.json` (not an
/// earlier `fit-hands` output): nothing of the user's is overwritten.
///
/// # Errors
/// [`BittError::Invalid`] naming the folder.
pub fn check_fit_out(out: &Path) -> Result<(), BittError> {
    Ok(crate::outputs::check_own_folder(
        out,
        FIT_JSON,
        "fit-hands",
        &FIT_NAMES,
    )?)
}

/// The names a `fit-hands` folder may hold.
const FIT_NAMES: [&str; 7] = [
    HANDS_JSON,
    UNMIRRORED_IMAGE,
    crate::files::REFINE_OVERLAY,
    FIT_JSON,
    crate::detect::KEYPOINTS_JSON,
    crate::detect::DETECTION_OVERLAY,
    crate::detect::DETECTION_JSON,
];

/// Writes `hands.json`, `fit.json` and `overlay.png` as the folder `out`, for a mirrored
/// photo the un-mirrored `image.png` the hands are for, and for detected keypoints the
/// detection's files (`detection.json`, `keypoints.json`, `detection_overlay.png`). The
/// folder is written as a whole (a kill leaves the earlier folder or the new one); a folder
/// that exists, is not empty and is not an earlier `fit-hands` output is refused.
///
/// # Errors
/// A foreign folder, or a write failure.
pub fn write_fit_outputs(out: &Path, fit: &PhotoFit) -> Result<(), BittError> {
    use crate::outputs::{json_bytes, png_file_bytes};
    let text = bitt_mesh::annotation::hands_json(&fit.hands, &fit.models)?;
    let mut files = vec![(HANDS_JSON.to_string(), text.into_bytes())];
    if fit.mirrored {
        let (w, h) = (
            fit.hands.camera.width as usize,
            fit.hands.camera.height as usize,
        );
        files.push((UNMIRRORED_IMAGE.into(), png_file_bytes(&fit.image, h, w)?));
    }
    let [oh, ow] = fit.overlay.1;
    files.push((
        crate::files::REFINE_OVERLAY.into(),
        png_file_bytes(&fit.overlay.0, oh, ow)?,
    ));
    if let Some(d) = &fit.detection {
        files.extend(d.named_files()?);
    }
    files.push((
        FIT_JSON.into(),
        json_bytes(&out.join(FIT_JSON), &fit.record())?,
    ));
    Ok(crate::outputs::write_own_folder(
        out,
        FIT_JSON,
        "fit-hands",
        &FIT_NAMES,
        &files,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intrinsics_parse_and_bad_ones_are_named() {
        assert_eq!(
            parse_intrinsics("600, 610,320,240").unwrap(),
            [600.0, 610.0, 320.0, 240.0]
        );
        for bad in ["600,600,320", "a,1,2,3", "0,600,1,1", "nan,1,1,1"] {
            let e = parse_intrinsics(bad).unwrap_err().to_string();
            assert!(e.contains("--intrinsics"), "{e}");
        }
        // Against the photo (issue 38, class 2): absurd focals and principal points.
        check_intrinsics_for_image([600.0, 600.0, 320.0, 240.0], [640, 480]).unwrap();
        check_intrinsics_for_image([600.0, 600.0, -100.0, 900.0], [640, 480]).unwrap();
        for (bad, what) in [
            ([1e-30, 600.0, 320.0, 240.0], "fx = "),
            ([600.0, 1e9, 320.0, 240.0], "fy = "),
            ([600.0, 600.0, 1e9, 240.0], "principal point"),
            ([600.0, 600.0, 320.0, -1e6], "principal point"),
        ] {
            let e = check_intrinsics_for_image(bad, [640, 480])
                .unwrap_err()
                .to_string();
            assert!(e.contains("--intrinsics") && e.contains(what), "{e}");
        }
    }
}
