//! The built-in two-hand demo scene on any hand model (`bitt demo`, `bitt render`'s default).

use std::path::Path;

use bitt_mesh::annotation::{FrameInfo, PosedTwoHands};
use bitt_mesh::lbs::{HandParams, HandPose};
use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene};
use glam::{DMat3, DVec3};

use crate::BittError;

/// Two hands facing each other, palms in, fingers up, a few centimetres apart, 0.5 m in
/// front of a 256x256 camera: the built-in two-hand scene.
///
/// Hands are in MANO's frame (fingers along -x, palm towards -y, thumb towards +z for the
/// right hand); each wrist is placed explicitly, so the scene works with any hand model.
pub fn demo_scene(models: &HandPair) -> TwoHandScene {
    // Right hand: fingers (-x) point up in the image (-y), the palm (-y) faces the left hand
    // (-x), the thumb (+z) towards the camera; then turned a little to show the palm.
    let facing = DMat3::from_cols(DVec3::Y, DVec3::X, DVec3::NEG_Z);
    let right_root = DMat3::from_rotation_y(0.35) * facing;
    // The left model is the x-mirror of the right, so its mirrored pose is M R M.
    let mirror = DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0));
    let left_root = mirror * right_root * mirror;
    let hand = |side: Side, root: DMat3, wrist: DVec3, curl: f64| {
        let model = models.get(side);
        let rest_wrist = model.regress_joints(&model.shaped_vertices(&[0.0; NUM_BETAS]))[0];
        HandParams {
            root_rotation: root,
            pose: HandPose::Pca(
                (0..NUM_POSE)
                    .map(|i| if i % 3 == 2 { curl } else { 0.0 })
                    .collect(),
            ),
            betas: vec![0.0; NUM_BETAS],
            // The root rotates about the rest wrist, so the posed wrist is rest_wrist + trans.
            trans: wrist - rest_wrist,
        }
    };
    TwoHandScene {
        left: Some(hand(
            Side::Left,
            left_root,
            DVec3::new(-0.03, 0.085, 0.5),
            0.15,
        )),
        right: Some(hand(
            Side::Right,
            right_root,
            DVec3::new(0.03, 0.085, 0.52),
            0.0,
        )),
        camera: PinholeCamera::looking_down_z(560.0, 256, 256),
        frame: FrameInfo::default(),
    }
}

/// `bitt demo`: the demo scene on the procedural hands, posed and written into the existing
/// folder `out` as `hands.obj`, `hands.glb` and `scene.json`. Returns the scene and its posed
/// hands.
///
/// # Errors
/// A file that cannot be written.
pub fn write_demo(out: &Path) -> Result<(TwoHandScene, PosedTwoHands), BittError> {
    let models = bitt_mesh::procedural_pair();
    let scene = demo_scene(&models);
    let posed = scene.pose_in_camera(&models)?;
    crate::export::write_posed(
        &posed,
        &models,
        &out.join("hands.obj"),
        Some(&out.join("hands.glb")),
    )?;
    let json = serde_json::to_string_pretty(&scene)
        .map_err(|e| BittError::Invalid(format!("encoding the demo scene: {e}")))?;
    bitt_stdx::write_atomically(&out.join("scene.json"), json.as_bytes())?;
    Ok((scene, posed))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_wrists_sit_where_placed_in_front_of_the_camera() {
        let models = bitt_mesh::procedural_pair();
        let scene = demo_scene(&models);
        let posed = scene.pose_in_camera(&models).unwrap();
        for (side, wrist) in [
            (Side::Left, DVec3::new(-0.03, 0.085, 0.5)),
            (Side::Right, DVec3::new(0.03, 0.085, 0.52)),
        ] {
            let hand = posed.get(side).unwrap();
            assert!((hand.joints[0] - wrist).length() < 1e-9, "{side}");
            assert!(hand.vertices.iter().all(|v| (0.3..0.7).contains(&v.z)));
        }
    }
}
