//! Poses to render an avatar in: another annotation, a procedural family, an orbited camera.

use std::path::Path;

use bitt_mesh::glam::DVec3;
use bitt_mesh::{HandPair, Side, TwoHandScene};
use bitt_synth::PoseFamily;

use crate::BittError;
use crate::input::{fit_camera, hands_box, reference_crop_box};

/// The hands of another BiTT annotation pickle, with its camera cropped around the hands
/// like a training view and resized to `size` (the annotation's intrinsics are for the image
/// beside it, `NN.jpg` / `NN.png`, else for the reference's 256 x 256 crop).
pub fn annotation_pose(
    path: &Path,
    models: &HandPair,
    size: usize,
) -> Result<TwoHandScene, BittError> {
    let image_size = bitt_mesh::annotation::annotation_image_size(path);
    let hands = bitt_mesh::load_bitt_annotation(path, image_size)?;
    for side in Side::BOTH {
        if hands.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand is not annotated; the avatar needs both hands",
                path.display()
            )));
        }
    }
    let b = hands_box(&hands, models)
        .map_err(|e| BittError::Invalid(format!("{}: {e}", path.display())))?;
    let camera = fit_camera(&hands.camera, Some(reference_crop_box(b)), size)?;
    let scene = TwoHandScene { camera, ..hands };
    // As for a training view: a hand kilometres wide or away (a huge shape or translation)
    // is a broken file, not a pose (issue 38).
    crate::real::check_hand_placement(&scene, models, path)?;
    Ok(scene)
}

/// Names of the procedural pose families (`clasp`, `interlaced`, `palm_on_back`, ...).
pub fn pose_family_names() -> Vec<String> {
    PoseFamily::ALL
        .iter()
        .filter_map(|f| serde_json::to_value(f).ok())
        .filter_map(|v| v.as_str().map(str::to_owned))
        .collect()
}

/// Parses a pose family name (`palm_on_back` or `palm-on-back`).
pub fn parse_pose_family(name: &str) -> Result<PoseFamily, BittError> {
    serde_json::from_value(serde_json::Value::String(
        name.trim().to_lowercase().replace('-', "_"),
    ))
    .map_err(|_| {
        BittError::Invalid(format!(
            "unknown procedural pose `{name}`; the families are {}",
            pose_family_names().join(", ")
        ))
    })
}

/// A two-hand pose of `family` from the synthetic generator (`seed` picks the jitter), for
/// hands of shape `betas` (left, right), seen from a camera in front of the person and
/// somewhat above, framed so the hands fill 80% of a `size x size` image.
pub fn procedural_pose(
    models: &HandPair,
    family: PoseFamily,
    betas: [&[f64]; 2],
    seed: u64,
    size: usize,
) -> Result<TwoHandScene, BittError> {
    let rig = bitt_synth::pose::Rig::new(&models.right)?;
    let mut rng = bitt_texture::procedural::noise::SplitMix64::new(seed);
    let pose = bitt_synth::pose::two_hand_pose(models, &rig, betas[1], family, &mut rng)?;
    let (mut left, mut right) = (pose.left, pose.right);
    left.betas = betas[0].to_vec();
    right.betas = betas[1].to_vec();
    let mut points = models.left.forward(&left)?.vertices;
    points.extend(models.right.forward(&right)?.vertices);
    let placement = bitt_synth::views::CameraPlacement {
        azimuth: 0.0,
        elevation: 0.5,
        distance: 0.6,
        roll: 0.0,
        fill: 0.8,
    };
    let camera = bitt_synth::views::framed_camera(&placement, DVec3::ZERO, &points, size as u32)?;
    Ok(TwoHandScene {
        left: Some(left),
        right: Some(right),
        camera,
        frame: Default::default(),
    })
}

/// `hands` seen from its camera orbited by `yaw` and `pitch` radians about the hands' centre
/// (see [`crate::run::orbit_camera`]).
pub fn orbit_hands(
    hands: &TwoHandScene,
    models: &HandPair,
    yaw: f64,
    pitch: f64,
) -> Result<TwoHandScene, BittError> {
    if yaw == 0.0 && pitch == 0.0 {
        return Ok(hands.clone());
    }
    let all = hands.camera_vertices(models)?;
    let center = all.iter().copied().sum::<DVec3>() / all.len().max(1) as f64;
    Ok(TwoHandScene {
        camera: bitt_mesh::camera::orbit_camera(&hands.camera, center, yaw, pitch),
        ..hands.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::procedural_pair;

    #[test]
    fn pose_families_parse() {
        assert_eq!(
            parse_pose_family("palm-on-back").unwrap(),
            PoseFamily::PalmOnBack
        );
        assert_eq!(parse_pose_family("Clasp").unwrap(), PoseFamily::Clasp);
        let e = parse_pose_family("wave").unwrap_err().to_string();
        assert!(e.contains("interlaced") && e.contains("wave"), "{e}");
        let models = procedural_pair();
        let betas = vec![0.0; 10];
        let s = procedural_pose(&models, PoseFamily::Prayer, [&betas, &betas], 3, 32).unwrap();
        let b = hands_box(&s, &models).unwrap();
        assert!(
            b[0] > 0.0 && b[2] < 32.0 && b[1] > 0.0 && b[3] < 32.0,
            "{b:?}"
        );
        let turned = orbit_hands(&s, &models, 0.5, 0.0).unwrap();
        assert_ne!(turned.camera, s.camera);
    }

    /// Issue 38, class 6: a pose file whose hand is huge or far away is refused, naming the
    /// file and the hand; the same file with sane values is a pose.
    #[test]
    fn absurd_pose_files_are_refused() {
        let models = procedural_pair();
        let betas = vec![0.0; 10];
        let s = procedural_pose(&models, PoseFamily::Clasp, [&betas, &betas], 1, 64).unwrap();
        let dir = std::env::temp_dir().join(format!("bitt-absurd-pose-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, scene: &TwoHandScene| {
            let path = dir.join(name);
            let text = bitt_mesh::annotation::hands_json(scene, &models).unwrap();
            std::fs::write(&path, text).unwrap();
            path
        };
        let sane = write("sane.json", &s);
        annotation_pose(&sane, &models, 64).unwrap();
        let mut far = s.clone();
        far.left.as_mut().unwrap().trans = DVec3::new(0.0, 0.0, 1e20);
        let mut huge = s.clone();
        huge.right.as_mut().unwrap().betas = vec![5e4; 10];
        for (name, scene, hand) in [("far.json", far, "left"), ("huge.json", huge, "right")] {
            let path = write(name, &scene);
            let e = annotation_pose(&path, &models, 64).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(hand), "{name}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
