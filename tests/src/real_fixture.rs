//! Real-data fixtures built in the test, never shipped: a BiTT annotation pickle with the
//! demo files' layout plus a matching 256 x 256 image, a photo of two hands rendered by the
//! synthetic generator, and a miniature InterHand2.6M folder (data, camera and MANO JSON
//! files and small PNG / JPEG frames).

use std::path::{Path, PathBuf};

use glam::DMat3;

use crate::pickle_writer::{PyValue, write_protocol4};

/// A Python `str`.
pub fn s(k: &str) -> PyValue {
    PyValue::Unicode(k.into())
}

/// A float32 numpy array.
pub fn f32s(shape: &[usize], data: Vec<f32>) -> PyValue {
    PyValue::NdArrayF32 {
        shape: shape.to_vec(),
        data,
    }
}

/// An annotation's `camera` entry: identity rotation, translation `(0, 0, depth)` and a `K`
/// with focal length `focal` about the 256 x 256 crop's centre.
pub fn camera_entry(focal: f64, depth: f32) -> PyValue {
    PyValue::Dict(vec![
        (s("R"), f32s(&[3, 3], rows(DMat3::IDENTITY))),
        (s("t"), f32s(&[3], vec![0.0, 0.0, depth])),
        (
            s("camera"),
            PyValue::NdArrayF64 {
                shape: vec![3, 3],
                data: vec![focal, 0.0, 128.0, 0.0, focal, 128.0, 0.0, 0.0, 1.0],
                fortran: false,
            },
        ),
    ])
}

/// An annotation's `image` entry: InterHand2.6M frame `frame` of capture 0 seen by
/// `camera` (a 334 x 512 frame), with image id `id`.
pub fn image_entry(id: i64, camera: &str, frame: i64) -> PyValue {
    PyValue::Dict(vec![
        (s("id"), PyValue::Int(id)),
        (
            s("file_name"),
            s(&format!("Capture0/seq/cam{camera}/image{frame:04}.jpg")),
        ),
        (s("width"), PyValue::Int(334)),
        (s("height"), PyValue::Int(512)),
        (s("capture"), PyValue::Int(0)),
        (s("camera"), s(camera)),
        (s("frame_idx"), PyValue::Int(frame)),
    ])
}

/// Row-major entries of a rotation matrix as `f32`.
fn rows(m: DMat3) -> Vec<f32> {
    m.transpose().to_cols_array().map(|x| x as f32).to_vec()
}

/// Options of [`annotation`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnnotationOptions {
    /// Turns both hands' root rotations by this angle about the camera's axis (radians), for
    /// a second, different pose.
    pub turn: f64,
    /// Puts a NaN into the right hand's translation.
    pub nan: bool,
    /// Drops the left hand (`None`, as the reference writes single-hand frames).
    pub no_left: bool,
    /// Added to the left hand's translation (metres, camera frame): hands off the image,
    /// far away or behind the camera.
    pub left_offset: [f32; 3],
}

impl AnnotationOptions {
    /// A NaN in the right hand's translation, nothing else changed.
    pub const NAN: Self = Self {
        turn: 0.0,
        nan: true,
        no_left: false,
        left_offset: [0.0; 3],
    };
    /// The right hand only (no left hand), nothing else changed.
    pub const RIGHT_ONLY: Self = Self {
        turn: 0.0,
        nan: false,
        no_left: true,
        left_offset: [0.0; 3],
    };
}

/// A BiTT annotation (the demo `NN.pkl` layout; see `shared/data/interhand_demo/README.md`)
/// of two hands about 0.6 m in front of a camera whose `K` is for a 256 x 256 crop.
pub fn annotation(opts: AnnotationOptions) -> PyValue {
    let turn = DMat3::from_rotation_z(opts.turn);
    let hand = |left: bool| -> PyValue {
        let root = if left {
            DMat3::from_rotation_y(0.3) * DMat3::from_rotation_x(-1.2)
        } else {
            DMat3::from_rotation_y(-0.3) * DMat3::from_rotation_x(-1.4)
        };
        let x = if left { 0.1 } else { -0.1 };
        let mut trans = vec![x as f32, 0.0, 0.0];
        if opts.nan && !left {
            trans[1] = f32::NAN;
        }
        if left {
            for (t, o) in trans.iter_mut().zip(opts.left_offset) {
                *t += o;
            }
        }
        PyValue::Dict(vec![
            (s("R"), f32s(&[1, 3, 3], rows(turn * root))),
            (
                s("pose"),
                f32s(
                    &[1, 45],
                    (0..45).map(|i| 0.05 * ((i % 5) as f32 - 2.0)).collect(),
                ),
            ),
            (
                s("shape"),
                f32s(&[1, 10], (0..10).map(|i| 0.05 * i as f32 - 0.2).collect()),
            ),
            (s("trans"), f32s(&[1, 3], trans)),
        ])
    };
    let camera = camera_entry(300.0, 0.65);
    let image = image_entry(101, "400262", 101);
    let ann = PyValue::Dict(vec![
        (s("bbox"), PyValue::List(vec![PyValue::Float(40.0); 4])),
        (s("hand_type"), s("interacting")),
        (s("hand_type_valid"), PyValue::Bool(true)),
    ]);
    PyValue::Dict(vec![
        (s("inter_idx"), PyValue::Int(0)),
        (s("image"), image),
        (s("annotation"), ann),
        (
            s("mano_params"),
            PyValue::Dict(vec![
                (
                    s("left"),
                    if opts.no_left {
                        PyValue::None
                    } else {
                        hand(true)
                    },
                ),
                (s("right"), hand(false)),
            ]),
        ),
        (s("camera"), camera),
    ])
}

/// Writes [`annotation`] as a protocol-4 pickle.
pub fn write_annotation(path: &Path, opts: AnnotationOptions) {
    std::fs::write(path, write_protocol4(&annotation(opts))).expect("write annotation");
}

/// Writes an RGB image of `w x h`: a dark background with a warm, smoothly shaded blob in
/// the middle (values from `pixel(x, y)` when given). The format follows the extension.
pub fn write_image(path: &Path, w: u32, h: u32, pixel: Option<&dyn Fn(u32, u32) -> [u8; 3]>) {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        if let Some(f) = pixel {
            return image::Rgb(f(x, y));
        }
        let (dx, dy) = (
            (x as f64 - w as f64 / 2.0) / w as f64,
            (y as f64 - h as f64 / 2.0) / h as f64,
        );
        let r2 = dx * dx + dy * dy;
        if r2 < 0.12 {
            let shade = 1.0 - r2 * 3.0;
            image::Rgb([
                (220.0 * shade) as u8,
                (170.0 * shade) as u8,
                (140.0 * shade) as u8,
            ])
        } else {
            image::Rgb([30, 30, 35])
        }
    });
    img.save(path).expect("write image");
}

/// A synthetic scene ([`write_synthetic_photo`]) in whose training image the built-in
/// detector finds both hands, each with its own side: the default benchmark's scene 19
/// (`bitt_synth::benchmark_seeds(24)[19]`; a finger gun cupped from below; both hands
/// found by the first stage, presence 0.95 / 0.92, keypoints 4.5 / 5.2 px from the true
/// joints on average). Of the benchmark's 24 training images the detector finds two hands
/// in 23; in 16 of them each lies on its own side's true joints (mean error under 31 px).
pub const TWO_HAND_PHOTO_SEED: u64 = 8_376_631_787_109_948_082;

/// The training image of the synthetic generator's scene `seed` at 256 x 256 pixels (two
/// procedural hands in one of its two-hand poses, textured, lit, on black), written as a
/// PNG: a photo of two hands made in the test, for the photo-only path.
pub fn write_synthetic_photo(path: &Path, seed: u64) {
    let config = bitt_synth::SynthConfig {
        size: 256,
        novel_views: 0,
        novel_poses: 0,
        ..bitt_synth::SynthConfig::default()
    };
    let scene = bitt_synth::generate_scene(&config, seed, &burn::tensor::Device::flex())
        .expect("synthetic scene");
    bitt::outputs::write_png(path, &scene.train.image, 256, 256).expect("write photo");
}

/// A fresh scratch folder below the system temp dir.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("bitt-real-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

// -------------------------------------------------------------------------------------------
// Miniature InterHand2.6M.

/// Side of the miniature frames.
pub const MINI_W: u32 = 64;
/// See [`MINI_W`].
pub const MINI_H: u32 = 48;

/// One image of the miniature dataset.
#[derive(Debug, Clone)]
pub struct MiniImage {
    /// Image id.
    pub id: i64,
    /// Capture.
    pub capture: i64,
    /// Frame index.
    pub frame: i64,
    /// Camera name.
    pub camera: &'static str,
    /// `hand_type`.
    pub hand_type: &'static str,
    /// `hand_type_valid` (written as 0 / 1).
    pub valid: bool,
    /// Box side (pixels) written as `bbox` `[x, y, side, side]`.
    pub box_side: f64,
    /// A black frame.
    pub dark: bool,
}

/// Camera names and their azimuths (radians) about the hands.
pub const MINI_CAMERAS: [(&str, f64); 5] = [
    ("400262", 0.0),
    ("400263", 0.5),
    ("400264", -0.5),
    ("410001", 1.0),
    ("400015", -1.0),
];

/// The images of the miniature dataset (see the InterHand tests for what each exercises).
pub fn mini_images() -> Vec<MiniImage> {
    let im = |id, capture, frame, camera, hand_type, valid, box_side, dark| MiniImage {
        id,
        capture,
        frame,
        camera,
        hand_type,
        valid,
        box_side,
        dark,
    };
    vec![
        // Frame 100: three candidate cameras (400263 has the largest box; 400264 is dark),
        // plus a 41xxxx camera and a dropped one.
        im(1, 0, 100, "400262", "interacting", true, 30.0, false),
        im(2, 0, 100, "400263", "interacting", true, 40.0, false),
        im(3, 0, 100, "400264", "interacting", true, 20.0, true),
        im(4, 0, 100, "410001", "interacting", true, 45.0, false),
        im(5, 0, 100, "400015", "interacting", true, 45.0, false),
        // Frame 101: two cameras, not the training one.
        im(6, 0, 101, "400262", "interacting", true, 25.0, false),
        im(7, 0, 101, "400264", "interacting", true, 35.0, false),
        // Frame 102: the training camera only.
        im(8, 0, 102, "400263", "interacting", true, 10.0, false),
        // Frame 103: a single right hand; frame 104: the left hand is not fitted.
        im(9, 0, 103, "400262", "right", true, 30.0, false),
        im(10, 0, 104, "400262", "interacting", true, 30.0, false),
        // Capture 1: not valid.
        im(11, 1, 5, "400262", "interacting", false, 30.0, false),
    ]
}

fn mano_hand(left: bool, frame: i64) -> serde_json::Value {
    // Root axis-angle (the hand turned a little per frame), 45 mean-relative finger values.
    let a = 0.05 * (frame - 100) as f64;
    let mut pose = vec![0.0; 48];
    pose[0] = -1.3 + a;
    pose[1] = if left { 0.3 } else { -0.3 };
    for (i, p) in pose.iter_mut().enumerate().skip(3) {
        *p = 0.02 * ((i % 4) as f64 - 1.5);
    }
    serde_json::json!({
        "pose": pose,
        "shape": vec![0.0; 10],
        "trans": [if left { 0.1 } else { -0.1 }, 0.0, 0.0],
    })
}

/// Writes the miniature dataset (split `test`) below `root` and returns `root`. The frames
/// are `MINI_W x MINI_H`: a horizontal grey ramp (`value = 255 (x + 0.5) / W`) so that a
/// crop's pixels tell where they came from, black for dark frames.
pub fn write_mini_interhand(root: &Path) -> PathBuf {
    let split = "test";
    let ann_dir = root.join("annotations").join(split);
    std::fs::create_dir_all(&ann_dir).unwrap();
    let images = mini_images();
    let mut img_json = Vec::new();
    let mut ann_json = Vec::new();
    for m in &images {
        let file_name = format!(
            "Capture{}/0000_seq/cam{}/image{}.png",
            m.capture, m.camera, m.frame
        );
        img_json.push(serde_json::json!({
            "id": m.id, "file_name": file_name, "width": MINI_W, "height": MINI_H,
            "capture": m.capture, "subject": m.capture, "seq_name": "0000_seq",
            "camera": m.camera, "frame_idx": m.frame,
        }));
        ann_json.push(serde_json::json!({
            "id": m.id, "image_id": m.id,
            "bbox": [10.0, 5.0, m.box_side, m.box_side],
            "joint_valid": vec![[1]; 42],
            "hand_type": m.hand_type, "hand_type_valid": if m.valid { 1 } else { 0 },
        }));
        let path = root.join("images").join(split).join(&file_name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let dark = m.dark;
        let ramp = move |x: u32, _y: u32| -> [u8; 3] {
            if dark {
                [0, 0, 0]
            } else {
                let v = (255.0 * (f64::from(x) + 0.5) / f64::from(MINI_W)).round() as u8;
                [v, v, v]
            }
        };
        write_image(&path, MINI_W, MINI_H, Some(&ramp));
    }
    let data = serde_json::json!({"images": img_json, "annotations": ann_json, "categories": []});
    std::fs::write(
        ann_dir.join(format!("InterHand2.6M_{split}_data.json")),
        data.to_string(),
    )
    .unwrap();
    // MANO: capture 0 frames 100-104 (104 without the left hand), capture 1 frame 5, and an
    // unrelated capture the reader must skip.
    let mut mano = serde_json::Map::new();
    let mut cap0 = serde_json::Map::new();
    for f in 100..=104 {
        let left = if f == 104 {
            serde_json::Value::Null
        } else {
            mano_hand(true, f)
        };
        cap0.insert(
            f.to_string(),
            serde_json::json!({"left": left, "right": mano_hand(false, f)}),
        );
    }
    mano.insert("0".into(), serde_json::Value::Object(cap0));
    mano.insert(
        "1".into(),
        serde_json::json!({"5": {"left": mano_hand(true, 5), "right": mano_hand(false, 5)}}),
    );
    mano.insert(
        "7".into(),
        serde_json::json!({"1": {"left": mano_hand(true, 1), "right": null}}),
    );
    std::fs::write(
        ann_dir.join(format!("InterHand2.6M_{split}_MANO_NeuralAnnot.json")),
        serde_json::Value::Object(mano).to_string(),
    )
    .unwrap();
    // Cameras looking at the origin from 0.6 m (InterHand: campos in mm, t = -R campos).
    let mut campos = serde_json::Map::new();
    let mut camrot = serde_json::Map::new();
    let mut focal = serde_json::Map::new();
    let mut princpt = serde_json::Map::new();
    for (name, az) in MINI_CAMERAS {
        let d = glam::DVec3::new(az.sin(), 0.0, az.cos());
        let x = glam::DVec3::new(az.cos(), 0.0, -az.sin());
        let y = glam::DVec3::Y;
        let c = -d * 600.0;
        campos.insert(name.into(), serde_json::json!([c.x, c.y, c.z]));
        camrot.insert(
            name.into(),
            serde_json::json!([[x.x, x.y, x.z], [y.x, y.y, y.z], [d.x, d.y, d.z]]),
        );
        focal.insert(name.into(), serde_json::json!([90.0, 90.0]));
        princpt.insert(
            name.into(),
            serde_json::json!([f64::from(MINI_W) / 2.0, f64::from(MINI_H) / 2.0]),
        );
    }
    let cams =
        serde_json::json!({"campos": campos, "camrot": camrot, "focal": focal, "princpt": princpt});
    let cameras = serde_json::json!({"0": cams.clone(), "1": cams});
    std::fs::write(
        ann_dir.join(format!("InterHand2.6M_{split}_camera.json")),
        cameras.to_string(),
    )
    .unwrap();
    root.to_path_buf()
}

/// A MANO folder and an HTML folder under `dir` (`mano/`, `html/`), returned in that order:
/// the procedural hands saved as the project's MANO safetensors without UV layouts, and
/// HTML's `uvs.pkl` (the procedural right hand's UVs) with an `html.safetensors` texture PCA
/// at 256² with 12 components (mean 150 / 190 / 230 of 255 per channel).
pub fn write_mano_html_folders(dir: &Path) -> (PathBuf, PathBuf) {
    use bitt_texture::{TextureLayout, TexturePca};
    let (mano, html) = (dir.join("mano"), dir.join("html"));
    std::fs::create_dir_all(&mano).unwrap();
    std::fs::create_dir_all(&html).unwrap();
    let pair = bitt_mesh::procedural_pair();
    let uv = pair.right.uv.clone().unwrap();
    for (model, name) in [(&pair.left, "MANO_LEFT"), (&pair.right, "MANO_RIGHT")] {
        let mut m = model.clone();
        m.uv = None;
        bitt_mesh::mano::save_safetensors(&m, &mano.join(format!("{name}.safetensors"))).unwrap();
    }
    let uvs = PyValue::dict(vec![
        (
            "verts_uvs",
            PyValue::f64_array(
                &[uv.uvs.len(), 2],
                uv.uvs.iter().flat_map(|p| [p.x, p.y]).collect(),
            ),
        ),
        (
            "faces_uvs",
            PyValue::NdArrayI64 {
                shape: vec![uv.faces.len(), 3],
                data: uv.faces.iter().flatten().map(|&i| i64::from(i)).collect(),
                fortran: false,
            },
        ),
    ]);
    std::fs::write(html.join("uvs.pkl"), write_protocol4(&uvs)).unwrap();
    let layout = TextureLayout::from_uv(&uv, 256, 256, 0).unwrap();
    let (t, k) = (layout.num_texels(), 12);
    let mean: Vec<f32> = (0..3 * t).map(|i| 150.0 + 40.0 * (i / t) as f32).collect();
    let basis: Vec<f32> = (0..3 * t * k)
        .map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.5)
        .collect();
    TexturePca::new(layout, mean, basis, k, 1.0 / 255.0)
        .unwrap()
        .save_safetensors(&html.join("html.safetensors"))
        .unwrap();
    (mano, html)
}
