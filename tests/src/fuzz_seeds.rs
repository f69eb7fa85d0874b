//! The seeds of the fuzz targets' corpora (`fuzz/corpus/<target>/seed_*`): small valid
//! inputs of each reader, built in code (never copied from licensed data). The corpus replay
//! test checks they read; `cargo xtask fuzz-seeds` (the example `fuzz_seeds`) writes them.

use std::path::{Path, PathBuf};

use bitt_mesh::annotation::{FrameInfo, TwoHandScene, hands_json};
use bitt_mesh::glam::{DMat3, DVec2, DVec3};
use bitt_mesh::interhand::InterHandPaths;
use bitt_mesh::mano::to_safetensors;
use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
use bitt_mesh::{HandModel, HandParams, HandPose, PinholeCamera, Side, UvLayout};

use crate::pickle_writer::{PyValue, write_protocol2, write_protocol4};
use crate::real_fixture::{self, AnnotationOptions};

/// The corpus folder of fuzz target `target`.
pub fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target)
}

/// The fuzz targets' one-vertex model, with a one-vertex UV layout when `uv`.
fn tiny_model(side: Side, uv: bool) -> HandModel {
    HandModel {
        uv: uv.then(|| UvLayout {
            uvs: vec![DVec2::new(0.25, 0.75)],
            faces: vec![[0, 0, 0]],
        }),
        ..crate::fuzz_checks::tiny_model(side)
    }
}

fn points(x0: f64) -> Vec<String> {
    (0..21)
        .map(|i| {
            format!(
                "[{}, {}, 0.9]",
                x0 + 3.0 * f64::from(i),
                100.0 + f64::from(i)
            )
        })
        .collect()
}

/// A small value with every kind the pickle writer emits (scalars, strings, containers,
/// numpy arrays in both orders, a numpy scalar, a scipy CSC matrix, chumpy objects): the
/// generic reader's seeds, one per protocol.
fn every_kind() -> PyValue {
    let ch = PyValue::ChumpyCh(Box::new(PyValue::f64_array(
        &[2, 2],
        vec![1.0, 2.0, 3.0, 4.0],
    )));
    PyValue::dict(vec![
        ("none", PyValue::None),
        (
            "flags",
            PyValue::List(vec![PyValue::Bool(true), PyValue::Bool(false)]),
        ),
        (
            "numbers",
            PyValue::Tuple(vec![PyValue::Int(-7), PyValue::Float(0.25)]),
        ),
        ("set", PyValue::Set(vec![PyValue::Int(1), PyValue::Int(2)])),
        ("text", PyValue::Unicode("hand".into())),
        ("bytes", PyValue::Bytes(vec![0, 1, 255])),
        (
            "f64",
            PyValue::f64_array(&[2, 3], vec![0.5, -1.0, 2.0, 3.0, 4.0, 5.0]),
        ),
        (
            "fortran",
            PyValue::NdArrayI64 {
                shape: vec![2, 2],
                data: vec![1, 3, 2, 4],
                fortran: true,
            },
        ),
        (
            "u32",
            PyValue::NdArrayU32 {
                shape: vec![1, 3],
                data: vec![0, 1, 2],
            },
        ),
        (
            "f32",
            PyValue::NdArrayF32 {
                shape: vec![2],
                data: vec![1.5, -2.5],
            },
        ),
        (
            "u8",
            PyValue::NdArrayU8 {
                shape: vec![3],
                data: vec![7, 8, 9],
            },
        ),
        (
            "mask",
            PyValue::NdArrayBool {
                shape: vec![2],
                data: vec![true, false],
            },
        ),
        ("scalar", PyValue::NpScalarF64(6.5)),
        (
            "sparse",
            PyValue::Csc {
                shape: (3, 2),
                data: vec![1.0, 2.0],
                indices: vec![0, 2],
                indptr: vec![0, 1, 2],
            },
        ),
        ("ch", ch.clone()),
        (
            "select",
            PyValue::ChumpySelect {
                a: Box::new(ch),
                idxs: vec![3, 0],
                preferred_shape: vec![2],
            },
        ),
    ])
}

/// The seeds of every target: small valid inputs built here (never copied from licensed
/// data).
pub fn seeds() -> Vec<(&'static str, String, Vec<u8>)> {
    let mut out = Vec::new();
    // The generic pickle reader: every kind of value in protocols 2 and 4, and an annotation.
    let value = every_kind();
    out.push((
        "from_bytes",
        "seed_kinds_p2.pkl".into(),
        write_protocol2(&value),
    ));
    out.push((
        "from_bytes",
        "seed_kinds_p4.pkl".into(),
        write_protocol4(&value),
    ));
    out.push((
        "from_bytes",
        "seed_annotation_p4.pkl".into(),
        write_protocol4(&real_fixture::annotation(AnnotationOptions::default())),
    ));
    // Torch: the project's own checkpoints (`crates/bitt-pickle/tests-data`).
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../crates/bitt-pickle/tests-data");
    for name in ["torch_zip.pth", "torch_legacy.pth"] {
        let bytes = std::fs::read(data.join(name)).unwrap();
        out.push(("torch", format!("seed_{name}"), bytes));
    }
    // MANO safetensors: one-vertex models, with and without a UV layout.
    for (side, uv) in [(Side::Right, false), (Side::Left, true)] {
        let bytes = to_safetensors(&tiny_model(side, uv)).unwrap();
        out.push((
            "mano_safetensors",
            format!("seed_{side}_uv{uv}.safetensors"),
            bytes,
        ));
    }
    // Annotations: the demo pickle layout (protocols 4 and 2, one hand missing) and a
    // hands.json.
    let ann = real_fixture::annotation(AnnotationOptions::default());
    out.push((
        "annotation",
        "seed_demo_p4.pkl".into(),
        write_protocol4(&ann),
    ));
    let one = real_fixture::annotation(AnnotationOptions::RIGHT_ONLY);
    out.push((
        "annotation",
        "seed_right_only_p2.pkl".into(),
        write_protocol2(&one),
    ));
    let scene = TwoHandScene {
        left: Some(HandParams {
            root_rotation: DMat3::from_rotation_z(0.2),
            pose: HandPose::AxisAngle(vec![0.01; NUM_POSE]),
            betas: vec![0.1; NUM_BETAS],
            trans: DVec3::new(0.1, 0.0, 0.0),
        }),
        right: None,
        camera: PinholeCamera::new(
            DMat3::from_cols_array(&[300.0, 0.0, 0.0, 0.0, 300.0, 0.0, 64.0, 60.0, 1.0]),
            DMat3::IDENTITY,
            DVec3::new(0.0, 0.0, 0.6),
            128,
            120,
        )
        .unwrap(),
        frame: FrameInfo::default(),
    };
    let text = hands_json(&scene, &crate::fuzz_checks::tiny_pair()).unwrap();
    out.push(("annotation", "seed_hands.json".into(), text.into_bytes()));
    // InterHand: the miniature dataset of the InterHand tests, and a one-image one.
    let root = real_fixture::scratch("fuzz-seeds");
    real_fixture::write_mini_interhand(&root);
    let paths = InterHandPaths::new(&root, "test");
    let mut joined = Vec::new();
    for (i, p) in [&paths.data, &paths.camera, &paths.mano]
        .into_iter()
        .enumerate()
    {
        if i > 0 {
            joined.push(0);
        }
        joined.extend(std::fs::read(p).unwrap());
    }
    std::fs::remove_dir_all(&root).ok();
    out.push(("interhand", "seed_mini.json".into(), joined));
    let pose: Vec<String> = (0..48)
        .map(|i| format!("{}", 0.01 * f64::from(i)))
        .collect();
    let hand = format!(
        "{{\"pose\":[{}],\"shape\":[0,0,0,0,0,0,0,0,0,0],\"trans\":[0,0,0]}}",
        pose.join(",")
    );
    let one = format!(
        "{{\"images\":[{{\"id\":1,\"file_name\":\"a.jpg\",\"width\":334,\"height\":512,\
         \"capture\":7,\"camera\":400262,\"frame_idx\":3}}],\"annotations\":[{{\"image_id\":1,\
         \"bbox\":[1,2,30,40],\"hand_type\":\"interacting\",\"hand_type_valid\":true}}]}}\0\
         {{\"7\":{{\"campos\":{{\"400262\":[100,-50,1000]}},\"camrot\":{{\"400262\":\
         [[1,0,0],[0,1,0],[0,0,1]]}},\"focal\":{{\"400262\":[1200,1210]}},\"princpt\":\
         {{\"400262\":[167,256]}}}}}}\0{{\"7\":{{\"3\":{{\"left\":{hand},\"right\":{hand}}}}}}}"
    );
    out.push(("interhand", "seed_one.json".into(), one.into_bytes()));
    // Keypoints (first byte: the options, 0 = guess the format, no image size).
    let (l, r) = (points(100.0), points(300.0));
    let openpose = format!(
        "{{\"version\":1.3,\"people\":[{{\"hand_left_keypoints_2d\":[{}],\
         \"hand_right_keypoints_2d\":[{}]}}]}}",
        l.join(",").replace(['[', ']'], ""),
        r.join(",").replace(['[', ']'], "")
    );
    let plain = format!("{{\"left\": [{}], \"right\": null}}", l.join(", "));
    let lms: Vec<String> = (0..21)
        .map(|i| {
            format!(
                "{{\"x\": {}, \"y\": 0.5, \"z\": -0.01}}",
                0.02 * f64::from(i)
            )
        })
        .collect();
    let mediapipe = format!(
        "{{\"handedness\": [[{{\"index\": 0, \"score\": 0.97, \"display_name\": \"\", \
         \"category_name\": \"Left\"}}]], \"hand_landmarks\": [[{}]]}}",
        lms.join(", ")
    );
    for (name, sel, text) in [
        ("openpose", 0u8, openpose),
        ("plain", 0, plain),
        ("mediapipe", 4, mediapipe), // 640 x 480, guessed format
    ] {
        let bytes = [vec![sel], text.into_bytes()].concat();
        out.push(("keypoints", format!("seed_{name}.json"), bytes));
    }
    // Camera values (first byte: bit 0 picks --view over --intrinsics, bits 1-2 the photo).
    for (name, sel, text) in [
        ("intrinsics", 0u8, "600,600,320,240"),
        ("intrinsics_4000", 4, "3600, 3600, 2000.5, 1500"),
        ("view", 1, "30,-15"),
    ] {
        let bytes = [vec![sel], text.as_bytes().to_vec()].concat();
        out.push(("camera_values", format!("seed_{name}.txt"), bytes));
    }
    // The --light text.
    let light = r#"{"ambient": [0.5, 0.5, 0.5], "diffuse": [0.3, 0.3, 0.3], "specular": [0.2, 0.2, 0.2], "location": [0, -1, 0]}"#;
    out.push(("light", "seed_light.json".into(), light.as_bytes().to_vec()));
    out
}

/// Writes every seed into its corpus folder; returns how many files were written.
///
/// # Errors
/// A folder or file that cannot be written.
pub fn write_seeds() -> std::io::Result<usize> {
    let all = seeds();
    for (target, name, bytes) in &all {
        let dir = corpus_dir(target);
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join(name), bytes)?;
    }
    Ok(all.len())
}
