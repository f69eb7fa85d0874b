//! Fuzzes the two-hand annotation reader behind every `--annotation`: BiTT/InterHand
//! annotation pickles and `hands.json`, told apart by content. Any input gives a scene or an
//! error naming the file, never a panic; a scene that loads must pose (on a one-vertex model,
//! so posing stays cheap) or fail with an error.

#![no_main]

use std::path::Path;

use bitt_mesh::annotation::bitt_annotation_from_bytes;
use bitt_mesh::glam::DVec3;
use bitt_mesh::{HandModel, HandPair, Side};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.annotation");
    match bitt_annotation_from_bytes(data, path, (256, 256)) {
        Ok(scene) => {
            assert!(scene.left.is_some() || scene.right.is_some());
            let models = tiny_pair();
            let _ = scene.pose_in_camera(&models);
            for side in Side::BOTH {
                if let Some(h) = scene.hand(side) {
                    let _ = scene.camera.project(h.trans);
                }
            }
        }
        Err(e) => assert!(e.to_string().contains("fuzz.annotation"), "{e}"),
    }
});

/// A valid one-vertex model per side (MANO's joint tree), so posing costs nothing.
fn tiny_pair() -> HandPair {
    use bitt_mesh::model::{MANO_PARENTS, NUM_BETAS, NUM_JOINTS, NUM_POSE, NUM_POSE_FEATURES};
    let model = |side| HandModel {
        side,
        source: "tiny".into(),
        v_template: vec![DVec3::new(0.01, 0.02, 0.03)],
        faces: vec![[0, 0, 0]],
        joint_regressor: vec![1.0; NUM_JOINTS],
        skinning_weights: (0..NUM_JOINTS)
            .map(|j| f64::from(u8::from(j == 0)))
            .collect(),
        parents: MANO_PARENTS.to_vec(),
        shape_dirs: vec![0.01; 3 * NUM_BETAS],
        pose_dirs: vec![0.001; 3 * NUM_POSE_FEATURES],
        pose_pca_components: (0..NUM_POSE * NUM_POSE)
            .map(|i| f64::from(u8::from(i % (NUM_POSE + 1) == 0)))
            .collect(),
        pose_pca_mean: vec![0.1; NUM_POSE],
        fingertips: [0; 5],
        uv: None,
    };
    HandPair {
        left: model(Side::Left),
        right: model(Side::Right),
    }
}
