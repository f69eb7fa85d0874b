//! BiTT/InterHand annotation pickles with the demo layout (protocol 4, numpy float32 arrays),
//! built in the test: read into a `TwoHandScene`, posed, exported, and refused with a clear
//! error when a value is NaN, an array has the wrong shape, or a key is missing.

use std::path::PathBuf;

use bitt::export::{ExportHand, glb_bytes};
use bitt_mesh::annotation::BITT_CROP_SIZE;
use bitt_mesh::lbs::HandPose;
use bitt_mesh::{Side, load_bitt_annotation, procedural_pair};
use bitt_tests::pickle_writer::{PyValue, write_protocol4};
use bitt_tests::real_fixture::{camera_entry, f32s, image_entry, s};
use glam::{DMat3, DVec3};

/// Root rotation of each hand, row-major.
fn root(side: Side) -> [f32; 9] {
    let m = match side {
        Side::Left => DMat3::from_rotation_y(0.4) * DMat3::from_rotation_z(1.2),
        Side::Right => DMat3::from_rotation_x(-0.3) * DMat3::from_rotation_z(-1.4),
    };
    let r = m.transpose().to_cols_array(); // rows of m
    r.map(|x| x as f32)
}

fn hand(side: Side, pose: Vec<f32>) -> PyValue {
    let x = if side == Side::Left { -0.05 } else { 0.05 };
    PyValue::Dict(vec![
        (s("R"), f32s(&[1, 3, 3], root(side).to_vec())),
        (s("pose"), f32s(&[1, 45], pose)),
        (
            s("shape"),
            f32s(&[1, 10], (0..10).map(|i| 0.1 * i as f32 - 0.4).collect()),
        ),
        (s("trans"), f32s(&[1, 3], vec![x, 0.0, 0.0])),
    ])
}

/// An annotation with the demo files' layout (see the shared demo README).
fn annotation(right_pose: Vec<f32>) -> PyValue {
    let camera = camera_entry(600.0, 0.6);
    let image = image_entry(6659, "400028", 48873);
    let ann = PyValue::Dict(vec![
        (
            s("bbox"),
            PyValue::List(vec![
                PyValue::Float(42.9),
                PyValue::Float(80.0),
                PyValue::Float(120.0),
                PyValue::Float(140.0),
            ]),
        ),
        (s("hand_type"), s("interacting")),
    ]);
    PyValue::Dict(vec![
        (s("inter_idx"), PyValue::Int(12)),
        (s("image"), image),
        (s("annotation"), ann),
        (
            s("mano_params"),
            PyValue::Dict(vec![
                (s("left"), hand(Side::Left, vec![0.1; 45])),
                (s("right"), hand(Side::Right, right_pose)),
            ]),
        ),
        (s("camera"), camera),
    ])
}

fn write(name: &str, value: &PyValue) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bitt-annotation-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, write_protocol4(value)).unwrap();
    path
}

#[test]
fn annotation_reads_poses_and_exports() {
    let pose: Vec<f32> = (0..45).map(|i| 0.02 * (i % 7) as f32).collect();
    let path = write("ok.pkl", &annotation(pose.clone()));
    let scene = load_bitt_annotation(&path, (BITT_CROP_SIZE, BITT_CROP_SIZE)).unwrap();
    let right = scene.right.as_ref().unwrap();
    assert_eq!(
        right.pose,
        HandPose::Pca(pose.iter().map(|&x| f64::from(x)).collect())
    );
    let r = root(Side::Right);
    assert_eq!(
        right.root_rotation.row(0),
        DVec3::new(r[0].into(), r[1].into(), r[2].into())
    );
    assert_eq!(
        scene.camera.translation,
        DVec3::new(0.0, 0.0, f64::from(0.6f32))
    );
    assert_eq!(scene.frame.frame_idx, Some(48873));
    assert_eq!(scene.frame.camera.as_deref(), Some("400028"));

    let models = procedural_pair();
    let posed = scene.pose_in_camera(&models).unwrap();
    for side in Side::BOTH {
        let hand = posed.get(side).unwrap();
        assert!(
            hand.vertices.iter().all(|v| v.is_finite() && v.z > 0.3),
            "{side} hand in front of the camera"
        );
        let b = scene.pixel_box(&hand.vertices).unwrap();
        assert!(b.size().x > 20.0 && b.size().y > 20.0, "{side} box {b:?}");
    }
    // Left hand on the image's left, right hand on the right (trans x = -/+ 5 cm).
    let centre = |side| {
        let b = scene.pixel_box(&posed.get(side).unwrap().vertices).unwrap();
        (b.min.x + b.max.x) / 2.0
    };
    assert!(centre(Side::Left) < centre(Side::Right));

    let hands: Vec<ExportHand> = Side::BOTH
        .iter()
        .map(|&side| ExportHand {
            name: side.as_str(),
            vertices: &posed.get(side).unwrap().vertices,
            faces: &models.get(side).faces,
            uv: models.get(side).uv.as_ref(),
            texture: None,
        })
        .collect();
    let glb = glb_bytes(&hands).unwrap();
    let gltf = gltf::Gltf::from_slice(&glb).unwrap();
    assert_eq!(gltf.meshes().count(), 2);
}

#[test]
fn bad_annotations_are_named_errors() {
    let mut nan_pose = vec![0.0f32; 45];
    nan_pose[17] = f32::NAN;
    let path = write("nan.pkl", &annotation(nan_pose));
    let e = load_bitt_annotation(&path, (256, 256))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nan.pkl") && e.contains("mano_params.right.pose") && e.contains("NaN"),
        "{e}"
    );

    let path = write("short.pkl", &annotation(vec![0.0; 12]));
    let e = load_bitt_annotation(&path, (256, 256))
        .unwrap_err()
        .to_string();
    assert!(e.contains("short.pkl") && e.contains("45"), "{e}");

    let path = write(
        "nocam.pkl",
        &PyValue::Dict(vec![(s("mano_params"), PyValue::Dict(vec![]))]),
    );
    let e = load_bitt_annotation(&path, (256, 256))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nocam.pkl") && e.contains("mano_params.left"),
        "{e}"
    );

    let path = std::env::temp_dir().join("bitt-definitely-missing.pkl");
    let e = load_bitt_annotation(&path, (256, 256))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bitt-definitely-missing.pkl"), "{e}");
}
