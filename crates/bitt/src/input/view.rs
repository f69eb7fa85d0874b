//! A real run's views: photos checked against their hands, cropped and resized.

use std::path::{Path, PathBuf};

use bitt_mesh::interhand::{InterHandScene, InterHandView};
use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene};
use bitt_texture::load_image;

use crate::BittError;
use crate::input::{ImageInput, hands_in_image, reference_crop_box};
use bitt_mesh::annotation::BITT_CROP_SIZE;

/// One prepared view: the image at the preset's size and the hands with the fitted camera.
#[derive(Debug, Clone, PartialEq)]
pub struct RealView {
    /// A short name (`train`, `view_00`, `pose_03`).
    pub name: String,
    /// The original image file.
    pub source: PathBuf,
    /// `[3, S, S]` in `[0, 1]`, channel-major.
    pub image: Vec<f32>,
    /// Both hands; the camera is the crop's (`S x S`).
    pub hands: TwoHandScene,
}

/// A prepared multi-view scene (InterHand2.6M): the training view, novel views (same frame,
/// other cameras) and novel poses (same capture, other frames).
#[derive(Debug, Clone, PartialEq)]
pub struct RealScene {
    /// The training view.
    pub train: RealView,
    /// Other cameras of the training frame.
    pub novel_views: Vec<RealView>,
    /// Other frames of the same capture.
    pub novel_poses: Vec<RealView>,
}

/// The smallest fraction of each hand's projected vertices that must fall inside the
/// training image: less, and the photo shows too little of that hand to texture it (or the
/// annotation belongs to another image).
pub const MIN_HAND_INSIDE: f64 = 0.5;

pub use bitt_mesh::camera::HAND_DEPTH_RANGE_M;

/// Checks each hand of the training view on its own: its position finite, every vertex in
/// front of the camera within [`HAND_DEPTH_RANGE_M`], and at least [`MIN_HAND_INSIDE`] of its
/// projected vertices inside the image. Errors name `source` (the annotation), the hand and
/// the problem.
pub fn check_hand_placement(
    hands: &TwoHandScene,
    models: &HandPair,
    source: &Path,
) -> Result<(), BittError> {
    let bad = |m: String| Err(BittError::Invalid(format!("{}: {m}", source.display())));
    let posed = hands
        .pose_in_camera(models)
        .map_err(|e| BittError::Invalid(format!("{}: {e}", source.display())))?;
    let (w, h) = (
        f64::from(hands.camera.width),
        f64::from(hands.camera.height),
    );
    let [near, far] = HAND_DEPTH_RANGE_M;
    for side in Side::BOTH {
        let Some(hand) = posed.get(side) else {
            continue;
        };
        let vertices = &hand.vertices;
        if vertices.is_empty() {
            continue;
        }
        if vertices.iter().any(|v| !v.is_finite()) {
            return bad(format!(
                "the {side} hand's position is not finite (its translation is out of range)"
            ));
        }
        let (zmin, zmax) = vertices
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v.z), b.max(v.z))
            });
        if zmax <= 0.0 {
            return bad(format!(
                "the {side} hand is behind the camera (depth {zmin:.3} to {zmax:.3} m)"
            ));
        }
        if zmin <= 0.0 {
            return bad(format!(
                "the {side} hand is partly behind the camera (depth {zmin:.3} to {zmax:.3} m)"
            ));
        }
        if zmin < near || zmax > far {
            return bad(format!(
                "the {side} hand lies {zmin:.3} to {zmax:.3} m from the camera; a photographed \
                 hand lies between {near} and {far} m"
            ));
        }
        let inside = vertices
            .iter()
            .filter_map(|v| hands.camera.camera_to_pixel(*v))
            .filter(|p| p.x >= -0.5 && p.x <= w - 0.5 && p.y >= -0.5 && p.y <= h - 0.5)
            .count();
        let fraction = inside as f64 / vertices.len() as f64;
        if fraction < MIN_HAND_INSIDE {
            return bad(format!(
                "only {:.0}% of the {side} hand projects into the {w}x{h} image (at least {:.0}% \
                 must): the hand is off the image, or the image and its annotation do not belong \
                 together",
                100.0 * fraction,
                100.0 * MIN_HAND_INSIDE
            ));
        }
    }
    Ok(())
}

/// Refuses a photo (`[3, S, S]`, at `hands`' camera) that is black or too dark under every
/// projected vertex of the hands: none of those pixels passes the photo mask's `threshold`
/// (mean RGB), so the photo is corrupt or not the annotation's. Checked before anything is
/// fitted or cached.
pub(crate) fn check_photo_under_hands(
    image: &[f32],
    hands: &TwoHandScene,
    models: &HandPair,
    threshold: f64,
) -> Result<(), BittError> {
    let (w, h) = (hands.camera.width as usize, hands.camera.height as usize);
    let hw = w * h;
    if image.len() != 3 * hw {
        return Ok(());
    }
    let posed = hands.pose_in_camera(models)?;
    let mut inside = 0usize;
    for side in Side::BOTH {
        let Some(hand) = posed.get(side) else {
            continue;
        };
        for v in &hand.vertices {
            let Some(p) = hands.camera.camera_to_pixel(*v) else {
                continue;
            };
            let (x, y) = (p.x.round(), p.y.round());
            if !(x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h) {
                continue;
            }
            inside += 1;
            let i = y as usize * w + x as usize;
            let mean = f64::from(image[i] + image[hw + i] + image[2 * hw + i]) / 3.0;
            if mean > threshold {
                return Ok(());
            }
        }
    }
    if inside == 0 {
        return Ok(());
    }
    Err(BittError::Invalid(format!(
        "the photo is black or too dark where the hands are: none of the {inside} pixels under \
         their vertices is brighter than the photo mask's threshold (mean RGB {threshold}); is \
         the image corrupt, or does the annotation belong to another photo? (a --config with \
         loss.photo_mask 0 trains on it anyway)"
    )))
}

/// Crops an image `[3, H, W]` (with its full camera in `hands`) around the hands as the
/// reference does and resizes it to `size`.
pub fn prepare_view(
    name: &str,
    source: &Path,
    image: Vec<f32>,
    hands: &TwoHandScene,
    models: &HandPair,
    size: usize,
) -> Result<RealView, BittError> {
    let b = hands_in_image(hands, models, source)?;
    let input = ImageInput {
        image,
        mask: None,
        camera: hands.camera,
    };
    let fitted = input.fit_square(Some(reference_crop_box(b)), size)?;
    Ok(RealView {
        name: name.to_string(),
        source: source.to_path_buf(),
        image: fitted.image,
        hands: TwoHandScene {
            camera: fitted.camera,
            ..hands.clone()
        },
    })
}

/// Reads an image, checking its size against the camera's.
pub fn read_image(path: &Path, camera: &PinholeCamera, what: &str) -> Result<Vec<f32>, BittError> {
    let img = load_image(path)?;
    if (img.width as u32, img.height as u32) != (camera.width, camera.height) {
        return Err(BittError::Invalid(format!(
            "{}: the image is {}x{}, but {what} is for a {}x{} image",
            path.display(),
            img.width,
            img.height,
            camera.width,
            camera.height
        )));
    }
    Ok(img.data)
}

/// The training view of an image and its BiTT annotation pickle (the demo `NN.jpg` +
/// `NN.pkl`): the annotation's camera is for the reference's 256 x 256 crop, so the image
/// must be 256 x 256; it is cropped around the hands and resized to `size`.
pub fn annotation_view(
    image: &Path,
    annotation: &Path,
    models: &HandPair,
    size: usize,
) -> Result<RealView, BittError> {
    crate::input::require_image(image)?;
    let hands = bitt_mesh::load_bitt_annotation(annotation, (BITT_CROP_SIZE, BITT_CROP_SIZE))?;
    for side in Side::BOTH {
        if hands.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand is not annotated; BiTT needs both hands",
                annotation.display()
            )));
        }
    }
    let what = format!(
        "the camera of {} (the reference's {BITT_CROP_SIZE}x{BITT_CROP_SIZE} crop)",
        annotation.display()
    );
    let pixels = read_image(image, &hands.camera, &what)?;
    check_hand_placement(&hands, models, annotation)?;
    prepare_view("train", image, pixels, &hands, models, size)
}

/// Loads and prepares every view of a selected InterHand2.6M scene.
pub fn interhand_views(
    scene: &InterHandScene,
    models: &HandPair,
    size: usize,
) -> Result<RealScene, BittError> {
    let prep = |name: String, v: &InterHandView| -> Result<RealView, BittError> {
        let what = format!(
            "the data file's entry for image {} ({})",
            v.entry.image_id, v.entry.file_name
        );
        let pixels = read_image(&v.image_path, &v.scene.camera, &what)?;
        prepare_view(&name, &v.image_path, pixels, &v.scene, models, size)
    };
    check_hand_placement(&scene.train.scene, models, &scene.train.image_path)?;
    Ok(RealScene {
        train: prep("train".into(), &scene.train)?,
        novel_views: scene
            .novel_views
            .iter()
            .enumerate()
            .map(|(k, v)| prep(format!("view_{k:02}"), v))
            .collect::<Result<_, _>>()?,
        novel_poses: scene
            .novel_poses
            .iter()
            .enumerate()
            .map(|(k, v)| prep(format!("pose_{k:02}"), v))
            .collect::<Result<_, _>>()?,
    })
}

/// Image `[3, S, S]`, hand masks `[S, S]` and the hands with the fitted camera.
pub type FittedView = (Vec<f32>, [Vec<f32>; 2], TwoHandScene);

/// A synthetic view's ground truth brought to the preset's `size` as the input is (crop
/// around the hands and resize, intrinsics adjusted): (image `[3, S, S]`, hand masks
/// `[S, S]` each, the hands with the fitted camera).
pub fn fit_synthetic_view(
    view: &bitt_synth::SynthView,
    size: usize,
) -> Result<FittedView, BittError> {
    let input = ImageInput {
        image: view.image.clone(),
        mask: None,
        camera: view.hands.camera,
    };
    let (image, masks, camera) = if input.size() == [size, size] {
        (view.image.clone(), view.masks.clone(), view.hands.camera)
    } else {
        let f = input.fit_square(None, size)?;
        let m = |m: &Vec<f32>| {
            ImageInput {
                image: [m.as_slice(), m, m].concat(),
                mask: None,
                camera: view.hands.camera,
            }
            .fit_square(None, size)
            .map(|x| x.image[..size * size].to_vec())
        };
        (f.image, [m(&view.masks[0])?, m(&view.masks[1])?], f.camera)
    };
    let hands = TwoHandScene {
        camera,
        ..view.hands.clone()
    };
    Ok((image, masks, hands))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::{REFERENCE_HAND_BOX_RATIO, hands_box};
    use bitt_mesh::glam::{DMat3, DVec3};
    use bitt_mesh::procedural_pair;

    /// The procedural hands side by side, 0.7 m in front of a 200 x 120 camera.
    fn hands_before_a_small_camera() -> (HandPair, TwoHandScene) {
        let models = procedural_pair();
        let mut hands = TwoHandScene {
            left: Some(bitt_mesh::HandParams::mean_pose()),
            right: Some(bitt_mesh::HandParams::mean_pose()),
            camera: PinholeCamera::looking_down_z(300.0, 200, 120),
            frame: Default::default(),
        };
        for (side, x) in [(Side::Left, -0.07), (Side::Right, 0.07)] {
            let p = match side {
                Side::Left => hands.left.as_mut().unwrap(),
                Side::Right => hands.right.as_mut().unwrap(),
            };
            p.trans = DVec3::new(x - 0.09, -0.01, 0.7);
            p.root_rotation = DMat3::IDENTITY;
        }
        (models, hands)
    }

    #[test]
    fn crop_keeps_projections_consistent() {
        let (models, hands) = hands_before_a_small_camera();
        let image = vec![0.5f32; 3 * 200 * 120];
        let v = prepare_view("train", Path::new("x.png"), image, &hands, &models, 32).unwrap();
        assert_eq!(v.image.len(), 3 * 32 * 32);
        assert_eq!([v.hands.camera.width, v.hands.camera.height], [32, 32]);
        // A 3-D point projects consistently: the crop maps its full-frame pixel linearly.
        let b = hands_box(&hands, &models).unwrap();
        let side = (b[2] - b[0]).max(b[3] - b[1]) / REFERENCE_HAND_BOX_RATIO;
        let (x0, y0) = ((b[0] + b[2] - side) / 2.0, (b[1] + b[3] - side) / 2.0);
        let p = DVec3::new(0.01, 0.02, 0.68);
        let before = hands.camera.project(p).unwrap();
        let after = v.hands.camera.project(p).unwrap();
        let expect = (before - bitt_mesh::glam::DVec2::new(x0, y0)) * (32.0 / side);
        assert!((after - expect).length() < 1e-9, "{after} vs {expect}");
        // The hands' box fills 80% of the crop.
        let nb = hands_box(&v.hands, &models).unwrap();
        let fill = (nb[2] - nb[0]).max(nb[3] - nb[1]) / 32.0;
        assert!((fill - REFERENCE_HAND_BOX_RATIO).abs() < 1e-6, "{fill}");
        // Hands outside the image are refused.
        let mut away = hands.clone();
        away.camera.intrinsics.z_axis.x += 5000.0;
        let e = prepare_view(
            "t",
            Path::new("far.png"),
            vec![0.0; 3 * 200 * 120],
            &away,
            &models,
            32,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("far.png") && e.contains("outside"), "{e}");
    }

    /// Each hand is checked on its own: one hand off the image, far away, behind the camera
    /// or at a non-finite place is refused, naming the file, the hand and the problem, even
    /// when the other hand is fine.
    #[test]
    fn each_hand_must_be_in_front_of_the_camera_and_in_the_image() {
        let (models, hands) = hands_before_a_small_camera();
        let source = Path::new("frame.pkl");
        check_hand_placement(&hands, &models, source).unwrap();
        let moved = |offset: DVec3| {
            let mut h = hands.clone();
            let left = h.left.as_mut().unwrap();
            left.trans += offset;
            check_hand_placement(&h, &models, source)
                .unwrap_err()
                .to_string()
        };
        for (offset, expect) in [
            (DVec3::new(100.0, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(1e20, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(3e38, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(0.0, 0.0, -5.0), "left hand is behind the camera"),
            (DVec3::new(0.0, 0.0, -0.7), "left hand is partly behind"),
            (
                DVec3::new(0.0, 0.0, 100.0),
                "a photographed hand lies between",
            ),
            (
                DVec3::new(0.0, 0.0, 1e20),
                "a photographed hand lies between",
            ),
            (
                DVec3::new(f64::INFINITY, 0.0, 0.0),
                "left hand: a pose, shape, rotation or translation value is NaN or infinite",
            ),
            // Shifted right by most of the image: the box of both hands still overlaps it.
            (
                DVec3::new(0.55, 0.0, 0.0),
                "of the left hand projects into the 200x120",
            ),
        ] {
            let e = moved(offset);
            assert!(
                e.contains("frame.pkl") && e.contains(expect),
                "{offset}: {e}"
            );
        }
        // The check on the box of both hands alone let the last one through.
        let mut h = hands.clone();
        h.left.as_mut().unwrap().trans += DVec3::new(0.55, 0.0, 0.0);
        hands_in_image(&h, &models, source).unwrap();
    }
}
