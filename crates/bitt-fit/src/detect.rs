//! The photo-only path's first step: both hands found in a photo by the built-in detector
//! (`bitt_detect`: MediaPipe Hands' networks and a two-hand search), what a detection
//! leaves behind (`detection.json`, `keypoints.json` in the plain format, an overlay of each
//! hand's keypoints and bones labelled with its side and presence), `bitt detect-hands`' job
//! and folder, and the detection weights' conversion (`bitt convert-mediapipe`).
//!
//! `fit::jobs` fits the detected keypoints (`fit-hands` and `train-scene` given a photo
//! alone) and keeps [`DetectionFiles`] in its folder; `run` shows them in the report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bitt_detect::{DetectError, HandDetector, SearchConfig, TwoHandDetection, detect_hands};
use bitt_mesh::Side;
use bitt_outputs::export::png_bytes;
use bitt_stdx::write_atomically;
use burn::tensor::Device;

use crate::FitError;
use bitt_outputs::outputs::{check_own_folder, overlay_scale, rgb_image, write_own_folder};

/// The detection's record: the search's result (`bitt_detect::TwoHandDetection`) with the
/// photo and the seconds it took.
pub const DETECTION_JSON: &str = "detection.json";

/// The detected hands' keypoints in the plain format (`--keypoints` reads them).
pub const KEYPOINTS_JSON: &str = "keypoints.json";

/// The overlay in a `detect-hands` folder.
pub(crate) const OVERLAY: &str = "overlay.png";

/// The overlay in a `fit-hands` folder or a run folder (next to their own `overlay.png`).
pub const DETECTION_OVERLAY: &str = "detection_overlay.png";

/// The left hand's colour in the overlay (orange).
pub(crate) const LEFT_COLOR: [u8; 3] = [255, 140, 0];

/// The right hand's colour in the overlay (blue).
pub(crate) const RIGHT_COLOR: [u8; 3] = [30, 144, 255];

/// A photo and the hands the detector found in it.
#[derive(Debug, Clone)]
pub struct PhotoDetection {
    /// The photo.
    pub image: PathBuf,
    /// The search's result: up to one hand per side, the stages it ran.
    pub detection: TwoHandDetection,
    /// Seconds the search took (the weights already loaded).
    pub seconds: f64,
    /// Seconds loading the built-in weights onto the device took.
    pub load_seconds: f64,
    /// The photo as read, `[3, H, W]` in `[0, 1]`.
    pub pixels: Vec<f32>,
    /// The photo's `[H, W]`.
    pub size: [usize; 2],
}

/// A detection's files as they are written into a folder: [`DETECTION_JSON`],
/// [`KEYPOINTS_JSON`] and the overlay.
#[derive(Debug, Clone)]
pub struct DetectionFiles {
    /// What [`DETECTION_JSON`] holds ([`PhotoDetection::record`]).
    pub record: serde_json::Value,
    /// What [`KEYPOINTS_JSON`] holds (plain keypoint JSON).
    pub keypoints: String,
    /// The overlay ([`PhotoDetection::overlay`]).
    pub overlay: image::RgbImage,
}

/// Names the photo in an error the detector raised about "the photo".
fn name_photo(e: DetectError, image: &Path) -> DetectError {
    match e {
        DetectError::Image { detail, .. } => DetectError::Image {
            image: image.to_path_buf(),
            detail,
        },
        other => other,
    }
}

/// Reads the photo `image` (any size; PNG or JPEG) and searches it for both hands with the
/// built-in weights on `device` (an autodiff device is used without its autodiff part).
///
/// Finding fewer than two hands is not an error here: [`TwoHandDetection::require_both`]
/// makes it one where both are needed.
///
/// # Errors
/// A missing or unreadable photo, or one that is not an image (naming it), a photo too small
/// to hold a hand, unusable built-in weights.
pub fn detect_photo(image: &Path, device: &Device) -> Result<PhotoDetection, FitError> {
    crate::photo::require_image(image)?;
    let photo = bitt_texture::image_io::load_image(image)?;
    let rgb = rgb_image(&photo.data, photo.height, photo.width)?;
    let load = Instant::now();
    let detector = HandDetector::builtin(&device.clone().inner())?;
    let load_seconds = load.elapsed().as_secs_f64();
    let started = Instant::now();
    let detection = detect_hands(&detector, &rgb, &SearchConfig::default())
        .map_err(|e| name_photo(e, image))?;
    Ok(PhotoDetection {
        image: image.to_path_buf(),
        detection,
        seconds: started.elapsed().as_secs_f64(),
        load_seconds,
        pixels: photo.data,
        size: [photo.height, photo.width],
    })
}

/// One line for a found hand: side, presence, stage (and how sure the side is).
fn hand_line(hand: &bitt_detect::DetectedHand) -> String {
    if hand.stage == "hypothesis" {
        return format!(
            "{} hand: not detected; placed by hypothesis, interlocked with the {} hand (check the overlay)",
            hand.side.as_str(),
            hand.side.mirrored().as_str()
        );
    }
    let palm = hand
        .palm_score
        .map_or(String::new(), |p| format!(", palm score {p:.2}"));
    format!(
        "{} hand: presence {:.2}, found by the {} stage ({} with probability {:.2}{palm})",
        hand.side.as_str(),
        hand.presence,
        hand.stage,
        hand.side.as_str(),
        hand.side_probability
    )
}

impl PhotoDetection {
    /// One line per found hand (side, presence, stage), for the user.
    pub fn lines(&self) -> Vec<String> {
        Side::BOTH
            .iter()
            .filter_map(|&side| {
                let hand = self.detection.hand(side)?;
                let border = if self.detection.at_border(side) {
                    "; it reaches the photo's border and may be cut off"
                } else {
                    ""
                };
                Some(format!("{}{border}", hand_line(hand)))
            })
            .collect()
    }

    /// What [`DETECTION_JSON`] holds: the search's result with the photo (`image`) and the
    /// seconds the search took (`seconds`) and loading the weights took (`load_seconds`).
    ///
    /// # Errors
    /// Only if the result cannot be encoded.
    pub fn record(&self) -> Result<serde_json::Value, FitError> {
        let mut record = serde_json::to_value(&self.detection)
            .map_err(|e| FitError::Invalid(format!("encoding the detection: {e}")))?;
        let image = std::path::absolute(&self.image).unwrap_or_else(|_| self.image.clone());
        record["image"] = serde_json::json!(image.display().to_string());
        record["seconds"] = serde_json::json!(self.seconds);
        record["load_seconds"] = serde_json::json!(self.load_seconds);
        Ok(record)
    }

    /// The photo (enlarged to at least 512 pixels wide) with each found hand's 21 keypoints
    /// and its bones (OpenPose's hand skeleton) in the hand's colour ([`LEFT_COLOR`],
    /// [`RIGHT_COLOR`]), labelled with its side and presence.
    ///
    /// # Errors
    /// Only if the embedded font cannot be read.
    pub fn overlay(&self) -> Result<image::RgbImage, FitError> {
        let [h, w] = self.size;
        let s = overlay_scale(w);
        let photo = rgb_image(&self.pixels, h, w)?;
        let mut img = image::imageops::resize(
            &photo,
            (w * s) as u32,
            (h * s) as u32,
            image::imageops::FilterType::Nearest,
        );
        let (bw, bh) = (img.width() as f64, img.height() as f64);
        let long = bw.max(bh);
        // Lines and text that stay visible from a 512-pixel overlay to a 4000-pixel photo.
        let thickness = (long / 320.0).max(2.0);
        let text_size = (bw / 28.0).clamp(14.0, 120.0) as f32;
        let sf = s as f64;
        // The label boxes drawn so far, so that the second one does not cover the first.
        let mut labels: Vec<[f32; 4]> = Vec::new();
        for side in Side::BOTH {
            let Some(hand) = self.detection.hand(side) else {
                continue;
            };
            let color = match side {
                Side::Left => LEFT_COLOR,
                Side::Right => RIGHT_COLOR,
            };
            // The project's pixel convention has the top-left pixel's centre at (0, 0).
            let at: Vec<[f64; 2]> = hand
                .points
                .iter()
                .map(|p| [(p[0] + 0.5) * sf, (p[1] + 0.5) * sf])
                .collect();
            for (child, parent) in crate::hand_priors::bones() {
                if let (Some(a), Some(b)) = (at.get(parent), at.get(child)) {
                    draw_segment(&mut img, *a, *b, thickness, color);
                }
            }
            for p in &at {
                draw_disc(&mut img, *p, thickness * 1.4, [0, 0, 0]);
                draw_disc(&mut img, *p, thickness, color);
            }
            let label = format!("{} (presence {:.2})", side.as_str(), hand.presence);
            labels.push(draw_label(
                &mut img, &at, &label, text_size, color, &labels,
            )?);
        }
        Ok(img)
    }

    /// The detection's files ([`DetectionFiles`]).
    ///
    /// # Errors
    /// As [`Self::record`] and [`Self::overlay`].
    pub fn files(&self) -> Result<DetectionFiles, FitError> {
        Ok(DetectionFiles {
            record: self.record()?,
            keypoints: self.detection.keypoints().to_plain_json(),
            overlay: self.overlay()?,
        })
    }
}

impl DetectionFiles {
    /// Writes [`DETECTION_JSON`], [`KEYPOINTS_JSON`] and the overlay as
    /// [`DETECTION_OVERLAY`] into `dir` (a `fit-hands` folder or a run folder), each
    /// atomically.
    ///
    /// # Errors
    /// A file that cannot be written.
    pub fn write_into(&self, dir: &Path) -> Result<(), FitError> {
        for (name, bytes) in self.named_files()? {
            write_atomically(&dir.join(name), &bytes)?;
        }
        Ok(())
    }

    /// The files [`write_into`](Self::write_into) writes: (name, bytes).
    pub fn named_files(&self) -> Result<Vec<(String, Vec<u8>)>, FitError> {
        Ok(vec![
            (KEYPOINTS_JSON.into(), self.keypoints.clone().into_bytes()),
            (DETECTION_OVERLAY.into(), png_bytes(&self.overlay)?),
            (DETECTION_JSON.into(), record_bytes(&self.record)?),
        ])
    }
}

fn record_bytes(record: &serde_json::Value) -> Result<Vec<u8>, FitError> {
    let mut text = serde_json::to_string_pretty(record)
        .map_err(|e| FitError::Invalid(format!("encoding the detection: {e}")))?;
    text.push('\n');
    Ok(text.into_bytes())
}

/// Fills the disc of `radius` about `c` with `color`.
fn draw_disc(img: &mut image::RgbImage, c: [f64; 2], radius: f64, color: [u8; 3]) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let r = radius.max(0.5);
    let (x0, x1) = ((c[0] - r).floor() as i64, (c[0] + r).ceil() as i64);
    let (y0, y1) = ((c[1] - r).floor() as i64, (c[1] + r).ceil() as i64);
    for y in y0.max(0)..=y1.min(h - 1) {
        for x in x0.max(0)..=x1.min(w - 1) {
            let (dx, dy) = (x as f64 + 0.5 - c[0], y as f64 + 0.5 - c[1]);
            if dx * dx + dy * dy <= r * r {
                img.put_pixel(x as u32, y as u32, image::Rgb(color));
            }
        }
    }
}

/// A line from `a` to `b`, `thickness` pixels wide, in `color`.
fn draw_segment(
    img: &mut image::RgbImage,
    a: [f64; 2],
    b: [f64; 2],
    thickness: f64,
    color: [u8; 3],
) {
    let length = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    if !length.is_finite() {
        return;
    }
    let steps = (length * 2.0).ceil().max(1.0) as usize;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let p = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
        draw_disc(img, p, thickness / 2.0, color);
    }
}

/// `text` on a darkened box above the points `at` (below them when there is no room above),
/// kept inside the image and moved down past the boxes `taken` it would cover; returns its
/// box `[x0, y0, x1, y1]`.
fn draw_label(
    img: &mut image::RgbImage,
    at: &[[f64; 2]],
    text: &str,
    size: f32,
    color: [u8; 3],
    taken: &[[f32; 4]],
) -> Result<[f32; 4], FitError> {
    let (w, h) = (img.width() as f32, img.height() as f32);
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in at {
        lo = [lo[0].min(p[0] as f32), lo[1].min(p[1] as f32)];
        hi = [hi[0].max(p[0] as f32), hi[1].max(p[1] as f32)];
    }
    let width = bitt_outputs::plot::text_width(text, size)?;
    let pad = (size * 0.25).round();
    // The capitals are about 0.73 of the pixel scale high in the embedded font.
    let cap = (size * 0.73).round();
    let box_h = cap + 2.0 * pad;
    let box_w = width + 2.0 * pad;
    let gap = size * 0.4;
    let mut y = lo[1] - gap - box_h;
    if y < 0.0 {
        y = hi[1] + gap;
    }
    let x = lo[0].clamp(0.0, (w - box_w).max(0.0));
    let mut y = y.clamp(0.0, (h - box_h).max(0.0));
    for _ in 0..=taken.len() {
        let covered = taken
            .iter()
            .find(|t| x < t[2] && x + box_w > t[0] && y < t[3] && y + box_h > t[1]);
        match covered {
            // Below the box it would cover, else above it when that runs off the image.
            Some(t) if t[3] + 1.0 + box_h <= h => y = t[3] + 1.0,
            Some(t) => y = (t[1] - box_h - 1.0).max(0.0),
            None => break,
        }
    }
    let (bx0, by0) = (x.floor() as u32, y.floor() as u32);
    let (bx1, by1) = (
        ((x + box_w).ceil() as u32).min(img.width()),
        ((y + box_h).ceil() as u32).min(img.height()),
    );
    for py in by0..by1 {
        for px in bx0..bx1 {
            let p = img.get_pixel_mut(px, py);
            for c in &mut p.0 {
                *c = (f32::from(*c) * 0.3).round() as u8;
            }
        }
    }
    bitt_outputs::plot::draw_text(img, text, size, (x + pad, y + pad), color)?;
    Ok([x, y, x + box_w, y + box_h])
}

/// Refuses an output folder that exists, is not empty and holds no [`DETECTION_JSON`] (not
/// an earlier `detect-hands` output): nothing of the user's is overwritten.
///
/// # Errors
/// [`FitError::Invalid`] naming the folder.
pub(crate) fn check_detect_out(out: &Path) -> Result<(), FitError> {
    Ok(check_own_folder(
        out,
        DETECTION_JSON,
        "detect-hands",
        &DETECT_NAMES,
    )?)
}

/// The names a `detect-hands` folder holds.
const DETECT_NAMES: [&str; 3] = [KEYPOINTS_JSON, OVERLAY, DETECTION_JSON];

/// Writes a `detect-hands` folder: [`KEYPOINTS_JSON`], [`OVERLAY`] and [`DETECTION_JSON`],
/// the folder as a whole (a kill or failure leaves the earlier folder or none).
///
/// # Errors
/// A folder that is not an earlier `detect-hands` output, or a write failure.
pub(crate) fn write_detection_folder(out: &Path, files: &DetectionFiles) -> Result<(), FitError> {
    Ok(write_own_folder(
        out,
        DETECTION_JSON,
        "detect-hands",
        &DETECT_NAMES,
        &[
            (KEYPOINTS_JSON.into(), files.keypoints.clone().into_bytes()),
            (OVERLAY.into(), png_bytes(&files.overlay)?),
            (DETECTION_JSON.into(), record_bytes(&files.record)?),
        ],
    )?)
}

/// What `bitt detect-hands` did: the detection, and the message of a hand it did not find.
#[derive(Debug)]
pub struct DetectHandsDone {
    /// The detection.
    pub detection: PhotoDetection,
    /// Set when only one hand was found ([`DetectError::OneHand`]: which, and a hint).
    pub warning: Option<DetectError>,
}

impl DetectHandsDone {
    /// What to tell the user: a line per found hand and where the files are (`out`).
    pub fn lines(&self, out: &Path) -> Vec<String> {
        let mut lines = self.detection.lines();
        lines.push(format!(
            "detected in {:.2} s; wrote {out}/{KEYPOINTS_JSON} (use it as --keypoints), \
             {out}/{DETECTION_JSON} and {out}/{OVERLAY}",
            self.detection.seconds,
            out = out.display()
        ));
        lines
    }
}

/// `bitt detect-hands`: detects both hands in `image` on `device` and writes `out`'s files
/// ([`write_detection_folder`]). One hand found is written (so its overlay can be looked at)
/// and returned as a warning.
///
/// # Errors
/// A folder that is not an earlier output (checked before anything else), an unreadable
/// photo, no hand at all ([`DetectError::NoHand`], naming the photo); nothing is written then.
pub fn detect_hands_into(
    image: &Path,
    out: &Path,
    device: &Device,
) -> Result<DetectHandsDone, FitError> {
    check_detect_out(out)?;
    let detection = detect_photo(image, device)?;
    let warning = match detection.detection.require_both(image) {
        Ok(()) => None,
        Err(e @ DetectError::NoHand { .. }) => return Err(e.into()),
        Err(e) => Some(e),
    };
    write_detection_folder(out, &detection.files()?)?;
    Ok(DetectHandsDone { detection, warning })
}

/// The [`DETECTION_JSON`] record in `dir`, if there is one.
///
/// # Errors
/// A file that is there but is not JSON.
pub fn read_detection(dir: &Path) -> Result<Option<serde_json::Value>, FitError> {
    Ok(bitt_outputs::outputs::read_json_if_present(
        &dir.join(DETECTION_JSON),
    )?)
}

/// The hands of a [`DETECTION_JSON`] record: per side found, its presence, probability of
/// its side, palm score and stage.
pub fn recorded_hands(
    record: &serde_json::Value,
) -> Vec<(&'static str, f64, f64, Option<f64>, String)> {
    let mut out = Vec::new();
    for side in ["left", "right"] {
        let hand = &record[side];
        if hand.is_object() {
            out.push((
                side,
                hand["presence"].as_f64().unwrap_or(f64::NAN),
                hand["side_probability"].as_f64().unwrap_or(f64::NAN),
                hand["palm_score"].as_f64(),
                hand["stage"].as_str().unwrap_or("").to_string(),
            ));
        }
    }
    out
}

/// A one-line summary of a [`DETECTION_JSON`] record ("left presence 0.97 (palms stage),
/// right presence 0.88 (ring stage)").
pub fn detection_summary(record: &serde_json::Value) -> String {
    let hands: Vec<String> = recorded_hands(record)
        .into_iter()
        .map(|(side, presence, _, _, stage)| {
            if stage == "hypothesis" {
                format!("{side} placed by hypothesis (not detected)")
            } else {
                format!("{side} presence {presence:.2} ({stage} stage)")
            }
        })
        .collect();
    if hands.is_empty() {
        "no hand".into()
    } else {
        hands.join(", ")
    }
}

/// Converts MediaPipe Hands' TFLite models in the unpacked `mediapipe==0.10.21` wheel
/// `wheel_dir` into the detector's weights file `out` (fp16 safetensors, written atomically;
/// `bitt_detect::tflite::convert_mediapipe`); returns its size in bytes.
///
/// # Errors
/// A model file that is missing or malformed, or a write failure.
pub fn convert_mediapipe(wheel_dir: &Path, out: &Path) -> Result<usize, FitError> {
    let bytes = bitt_detect::tflite::convert_mediapipe(wheel_dir, out)?;
    write_atomically(out, &bytes)?;
    Ok(bytes.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_detect::{DetectedHand, Rect};

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("bitt-detect-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A detection of one hand of `side` spread over a 100 x 80 grey photo.
    fn one_hand(side: Side) -> PhotoDetection {
        let points: Vec<[f64; 3]> = (0..21)
            .map(|i| [20.0 + 3.0 * i as f64, 30.0 + (i % 4) as f64 * 8.0, 0.0])
            .collect();
        let hand = DetectedHand {
            side,
            points,
            presence: 0.93,
            side_probability: 0.88,
            palm_score: Some(0.61),
            stage: "palms".into(),
            rect: Rect {
                center: [50.0, 40.0],
                size: [60.0, 60.0],
                rotation: 0.0,
            },
        };
        let (left, right) = match side {
            Side::Left => (Some(hand), None),
            Side::Right => (None, Some(hand)),
        };
        PhotoDetection {
            image: PathBuf::from("photo.png"),
            detection: TwoHandDetection {
                image_size: [100, 80],
                left,
                right,
                stages: Vec::new(),
                best_presence: 0.93,
                config: SearchConfig::default(),
            },
            seconds: 0.25,
            load_seconds: 0.01,
            pixels: vec![0.5; 3 * 80 * 100],
            size: [80, 100],
        }
    }

    /// The overlay is the photo enlarged to at least 512 wide with the hand drawn in its
    /// colour and a label; the record, summary and lines carry the scores.
    #[test]
    fn overlay_record_and_lines() {
        let d = one_hand(Side::Right);
        let img = d.overlay().unwrap();
        assert_eq!((img.width(), img.height()), (600, 480));
        let count = |c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
        assert!(count(RIGHT_COLOR) > 500, "{}", count(RIGHT_COLOR));
        assert_eq!(count(LEFT_COLOR), 0);
        // The label's darkened box: pixels darker than the grey photo and not black.
        assert!(img.pixels().any(|p| p.0[0] > 0 && p.0[0] < 60));
        let record = d.record().unwrap();
        assert_eq!(record["seconds"], 0.25);
        assert!(record["image"].as_str().unwrap().ends_with("photo.png"));
        assert_eq!(record["right"]["stage"], "palms");
        assert!(record["left"].is_null());
        assert_eq!(
            detection_summary(&record),
            "right presence 0.93 (palms stage)"
        );
        let lines = d.lines();
        assert_eq!(lines.len(), 1);
        assert!(lines[0].starts_with("right hand: presence 0.93, found by the palms stage"));
        let e = d
            .detection
            .require_both(Path::new("photo.png"))
            .unwrap_err();
        assert!(e.to_string().contains("only the right hand"), "{e}");
    }

    /// Two labels for hands at the same place do not cover each other.
    #[test]
    fn labels_do_not_cover_each_other() {
        let mut img = image::RgbImage::new(300, 200);
        let at = [[100.0, 100.0], [160.0, 150.0]];
        let a = draw_label(&mut img, &at, "left (presence 0.90)", 18.0, LEFT_COLOR, &[]).unwrap();
        let b = draw_label(
            &mut img,
            &at,
            "right (presence 0.85)",
            18.0,
            RIGHT_COLOR,
            &[a],
        )
        .unwrap();
        let apart = b[1] >= a[3] || b[3] <= a[1] || b[0] >= a[2] || b[2] <= a[0];
        assert!(apart, "{a:?} and {b:?} overlap");
        for r in [a, b] {
            assert!(
                r[0] >= 0.0 && r[1] >= 0.0 && r[2] <= 300.0 && r[3] <= 200.0,
                "{r:?}"
            );
        }
    }

    /// A detect-hands folder appears with its three files; rewriting it is fine; a folder of
    /// the user's is refused untouched.
    #[test]
    fn folder_is_written_together_and_foreign_folders_refused() {
        let dir = scratch("folder");
        let out = dir.join("runs").join("detect");
        let files = one_hand(Side::Left).files().unwrap();
        write_detection_folder(&out, &files).unwrap();
        let names = |d: &Path| {
            let mut n: Vec<String> = std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        assert_eq!(names(&out), [DETECTION_JSON, KEYPOINTS_JSON, OVERLAY]);
        assert_eq!(names(&dir.join("runs")), ["detect"], "a temporary was left");
        let kp = bitt_mesh::keypoints::read_keypoints(
            &out.join(KEYPOINTS_JSON),
            &bitt_mesh::keypoints::KeypointOptions {
                format: None,
                image_size: [100, 80],
                labels_as_is: false,
            },
        )
        .unwrap();
        assert!(kp.left.is_some() && kp.right.is_none());
        write_detection_folder(&out, &files).unwrap();
        assert_eq!(names(&out), [DETECTION_JSON, KEYPOINTS_JSON, OVERLAY]);
        let back = read_detection(&out).unwrap().unwrap();
        assert_eq!(back["left"]["presence"], 0.93);
        let mine = dir.join("mine");
        std::fs::create_dir_all(&mine).unwrap();
        std::fs::write(mine.join("notes.txt"), "mine").unwrap();
        let e = write_detection_folder(&mine, &files)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a detect-hands output"), "{e}");
        assert_eq!(names(&mine), ["notes.txt"]);
        // The files a fit or run folder gets.
        let run = dir.join("run");
        std::fs::create_dir_all(&run).unwrap();
        files.write_into(&run).unwrap();
        assert_eq!(
            names(&run),
            [DETECTION_JSON, DETECTION_OVERLAY, KEYPOINTS_JSON]
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
