//! What the fuzz targets assert, one function per target, shared by the targets
//! (`fuzz_targets/*.rs`) and by the replay of the committed corpora in the test suite
//! (`tests/tests/fuzz_corpus.rs`, which includes this file), so both check the same thing.
//! Each function takes the raw input, must never panic on any of it, and returns whether
//! the input was read (the corpora's `seed_*` files must be).

#![allow(dead_code)] // every target uses one function

use std::path::Path;

use bitt_mesh::annotation::bitt_annotation_from_bytes;
use bitt_mesh::camera::{check_intrinsics_for_image, parse_intrinsics, parse_orbit_view};
use bitt_mesh::glam::DVec3;
use bitt_mesh::interhand::{InterHandDataset, InterHandPaths, InterHandSelection};
use bitt_mesh::keypoints::{KeypointFormat, KeypointOptions, parse_keypoints};
use bitt_mesh::light::{LightValues, parse_light};
use bitt_mesh::mano::{from_safetensors, to_safetensors};
use bitt_mesh::model::{MANO_PARENTS, NUM_BETAS, NUM_JOINTS, NUM_POSE, NUM_POSE_FEATURES};
use bitt_mesh::{HandModel, HandPair, HandParams, PinholeCamera, Side};
use bitt_pickle::{PickleError, Value};

/// A pickle reader's result: a self-consistent value, or an error that names `name` and
/// points inside the input (or just past its end).
fn pickle_result(result: Result<Value, PickleError>, data: &[u8], name: &str) -> bool {
    match result {
        Ok(v) => {
            exercise(&v);
            true
        }
        Err(e) => {
            assert!(
                e.offset <= data.len() && e.to_string().contains(name),
                "{e}"
            );
            false
        }
    }
}

/// Every accessor of a value, recursively; arrays' shapes match their data.
fn exercise(v: &Value) {
    let _ = (
        v.type_name(),
        v.as_f64(),
        v.as_i64(),
        v.as_str(),
        v.as_list(),
    );
    for key in ["v_template", "x", "", "\u{e9}"] {
        let _ = v.get(key);
    }
    match v {
        Value::Array(a) => {
            let n = a
                .shape
                .iter()
                .try_fold(1usize, |acc, &d| acc.checked_mul(d));
            assert_eq!(n, Some(a.len()), "shape {:?} vs {}", a.shape, a.len());
            assert_eq!(a.to_f64().len(), a.len());
            assert_eq!(a.to_i64().len(), a.len());
            let _ = a.dtype();
        }
        // The reader validated the structure, so a small matrix must densify.
        Value::Sparse(m) if m.shape.0.saturating_mul(m.shape.1) <= 1 << 16 => {
            let dense = m.to_dense_row_major();
            assert!(dense.is_ok(), "{dense:?}");
        }
        Value::List(items) | Value::Tuple(items) | Value::Set(items) => {
            items.iter().for_each(exercise);
        }
        Value::Dict(items) => {
            for (k, x) in items {
                exercise(k);
                exercise(x);
            }
        }
        _ => {}
    }
}

/// The pickle reader (`bitt_pickle::from_bytes`).
pub fn from_bytes(data: &[u8]) -> bool {
    pickle_result(bitt_pickle::from_bytes(data, "fuzz.pkl"), data, "fuzz.pkl")
}

/// Torch checkpoints, zip and legacy (`bitt_pickle::torch_from_bytes`, what `convert-lpips`
/// reads).
pub fn torch(data: &[u8]) -> bool {
    pickle_result(
        bitt_pickle::torch_from_bytes(data, "fuzz.pth"),
        data,
        "fuzz.pth",
    )
}

/// The project's MANO safetensors: a model that loads is valid, poses, and writes back to
/// the same model.
pub fn mano_safetensors(data: &[u8]) -> bool {
    let path = Path::new("fuzz.safetensors");
    match from_safetensors(data, path) {
        Ok(model) => {
            model.validate().expect("a loaded model is valid");
            let posed = model.forward(&HandParams::mean_pose());
            assert!(posed.is_ok(), "{posed:?}");
            let bytes = to_safetensors(&model).expect("a loaded model writes");
            let back = from_safetensors(&bytes, path).expect("a written model reads");
            assert_eq!(back, model);
            true
        }
        Err(e) => {
            assert!(e.to_string().contains("fuzz.safetensors"), "{e}");
            false
        }
    }
}

/// BiTT annotation pickles and `hands.json`: a scene that loads holds a hand and poses (on
/// [`tiny_pair`], so posing stays cheap) or fails with an error.
pub fn annotation(data: &[u8]) -> bool {
    let path = Path::new("fuzz.annotation");
    match bitt_annotation_from_bytes(data, path, (256, 256)) {
        Ok(scene) => {
            assert!(scene.left.is_some() || scene.right.is_some());
            let _ = scene.pose_in_camera(&tiny_pair());
            for side in Side::BOTH {
                if let Some(h) = scene.hand(side) {
                    let _ = scene.camera.project(h.trans);
                }
            }
            true
        }
        Err(e) => {
            assert!(e.to_string().contains("fuzz.annotation"), "{e}");
            false
        }
    }
}

/// InterHand2.6M: the data, camera and MANO JSON files joined by NUL bytes (JSON never holds
/// a raw NUL). Every candidate's scene converts or fails with an error; selection (whose
/// images do not exist here) fails with an error. Read means at least one scene converted.
pub fn interhand(data: &[u8]) -> bool {
    let mut parts = data.splitn(3, |&b| b == 0);
    let mut next = || parts.next().unwrap_or(&[]);
    let (d, c, m) = (next(), next(), next());
    let paths = InterHandPaths::new(Path::new("/nonexistent/bitt-fuzz"), "test");
    let set = match InterHandDataset::from_json_bytes(paths, d, c, m) {
        Ok(set) => set,
        Err(e) => {
            assert!(e.to_string().contains("InterHand2.6M_test_"), "{e}");
            return false;
        }
    };
    let _ = set.counts.to_string();
    let mut scenes = 0;
    for capture in set.captures() {
        for frame in set.frames(capture) {
            for entry in set.cameras(capture, frame) {
                scenes += usize::from(set.scene(entry).is_ok());
            }
        }
    }
    let _ = set.select(&InterHandSelection::default());
    scenes > 0
}

/// 2D keypoint files: the first byte picks the options (format or guess, image size,
/// mirrored), the rest is the file. What the reader read, written as plain JSON, reads back.
pub fn keypoints(data: &[u8]) -> bool {
    let Some((&sel, file)) = data.split_first() else {
        return false;
    };
    let options = KeypointOptions {
        format: match sel & 3 {
            0 => None,
            1 => Some(KeypointFormat::OpenPose),
            2 => Some(KeypointFormat::MediaPipe),
            _ => Some(KeypointFormat::Plain),
        },
        image_size: match (sel >> 2) & 3 {
            0 => [0, 0],
            1 => [640, 480],
            2 => [1, 1],
            _ => [u32::MAX, 3],
        },
        labels_as_is: sel & 16 != 0,
    };
    let path = Path::new("fuzz_keypoints.json");
    match parse_keypoints(file, path, &options) {
        Ok(k) => {
            let text = k.to_plain_json();
            let _ = k.scaled(0.5, 2.0).mirrored(640.0);
            // The plausibility checks (issue 38) take any parsed file without panicking.
            let _ = k.check_plausible();
            let _ = Side::BOTH.map(|s| k.span_px(s));
            let back = parse_keypoints(text.as_bytes(), path, &KeypointOptions::default());
            assert!(back.is_ok(), "{text}: {back:?}");
            true
        }
        Err(e) => {
            assert!(e.to_string().starts_with("fuzz_keypoints.json: "), "{e}");
            false
        }
    }
}

/// The camera values users type (`--intrinsics`, `render-avatar --view`; bitt-mesh
/// `camera::parse_intrinsics`, `check_intrinsics_for_image`, `parse_orbit_view`). The first
/// byte picks the parser (bit 0) and the photo size (bits 1-2), the rest is the text.
/// Accepted intrinsics always make a camera of that photo.
pub fn camera_values(data: &[u8]) -> bool {
    let Some((&sel, rest)) = data.split_first() else {
        return false;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return false;
    };
    if sel & 1 == 1 {
        return match parse_orbit_view(text) {
            Ok((az, el)) => {
                assert!(az.is_finite() && el.is_finite(), "{text:?}");
                true
            }
            Err(e) => {
                assert!(!e.is_empty());
                false
            }
        };
    }
    match parse_intrinsics(text) {
        Ok(k) => {
            assert!(
                k.iter().all(|x| x.is_finite()) && k[0] > 0.0 && k[1] > 0.0,
                "{k:?}"
            );
            let [w, h] = [[640u32, 480], [1, 1], [4000, 3000], [0, 0]][usize::from((sel >> 1) & 3)];
            if check_intrinsics_for_image(k, [w as usize, h as usize]).is_ok() {
                let camera = PinholeCamera::from_intrinsics([k[0], k[1]], [k[2], k[3]], w, h);
                assert!(camera.is_ok(), "{k:?} {w}x{h}: {camera:?}");
            }
            true
        }
        Err(e) => {
            assert!(e.starts_with("--intrinsics "), "{e}");
            false
        }
    }
}

/// The `--light` text (bitt-mesh `light::parse_light`): any input gives a light whose values
/// are finite and whose colours are not negative and not all 0, or an error naming the source.
pub fn light(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    match parse_light(text, "--light") {
        Ok(l) => {
            assert!(l.check_finite().is_ok(), "{l:?}");
            let colours = [l.ambient, l.diffuse, l.specular];
            assert!(colours.iter().flatten().all(|&x| x >= 0.0), "{l:?}");
            assert!(colours.iter().flatten().any(|&x| x > 0.0), "{l:?}");
            assert_eq!(LightValues::from_array(l.to_array()), l);
            true
        }
        Err(e) => {
            assert!(e.starts_with("--light: "), "{e}");
            false
        }
    }
}

/// A valid one-vertex model (MANO's joint tree): small enough to fuzz, cheap to pose.
pub fn tiny_model(side: Side) -> HandModel {
    HandModel {
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
    }
}

/// [`tiny_model`] for both sides.
pub fn tiny_pair() -> HandPair {
    HandPair {
        left: tiny_model(Side::Left),
        right: tiny_model(Side::Right),
    }
}
