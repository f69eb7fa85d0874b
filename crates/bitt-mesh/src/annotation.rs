//! Two-hand annotations: the BiTT/InterHand demo pickles and InterHand2.6M's JSON files,
//! both read into a [`TwoHandScene`] (per-hand MANO parameters + a pinhole camera).

use std::path::Path;

use bitt_pickle::Value;
use glam::{DMat3, DVec3};

use crate::MeshError;
use crate::camera::{PinholeCamera, PixelBox};
use crate::lbs::{HandParams, HandPose, PosedHand, rodrigues};
use crate::mano::HandPair;
use crate::model::{NUM_BETAS, NUM_POSE, Side};
use bitt_stdx::FileErrorExt;

/// Side length of the square crops the BiTT reference cuts from InterHand2.6M frames
/// (`IMG_SIZE` of its data preparation); the demo annotations' `K` is for this crop.
pub const BITT_CROP_SIZE: u32 = 256;

/// Where a frame came from, when the annotation says so (all optional).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameInfo {
    /// The InterHand2.6M image path.
    pub file_name: Option<String>,
    /// Capture id.
    pub capture: Option<i64>,
    /// Camera name (e.g. `"400262"`).
    pub camera: Option<String>,
    /// Frame index.
    pub frame_idx: Option<i64>,
}

/// Two hands and the camera that saw them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwoHandScene {
    /// Left-hand parameters, if the left hand is annotated.
    pub left: Option<HandParams>,
    /// Right-hand parameters, if the right hand is annotated.
    pub right: Option<HandParams>,
    /// The camera (world-to-camera extrinsics and intrinsics for the image).
    pub camera: PinholeCamera,
    /// Provenance.
    pub frame: FrameInfo,
}

/// Both hands of a scene posed and moved into the camera frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PosedTwoHands {
    /// The left hand in the camera frame.
    pub left: Option<PosedHand>,
    /// The right hand in the camera frame.
    pub right: Option<PosedHand>,
}

impl PosedTwoHands {
    /// The posed hand of one side.
    pub fn get(&self, side: Side) -> Option<&PosedHand> {
        match side {
            Side::Left => self.left.as_ref(),
            Side::Right => self.right.as_ref(),
        }
    }
}

impl TwoHandScene {
    /// Parameters of one side.
    pub fn hand(&self, side: Side) -> Option<&HandParams> {
        match side {
            Side::Left => self.left.as_ref(),
            Side::Right => self.right.as_ref(),
        }
    }

    /// Poses both hands with `models` and moves vertices and joints into the camera frame
    /// (`v_cam = R v + t`, as the reference does).
    pub fn pose_in_camera(&self, models: &HandPair) -> Result<PosedTwoHands, MeshError> {
        self.camera.validate()?;
        let pose = |side: Side| -> Result<Option<PosedHand>, MeshError> {
            let Some(params) = self.hand(side) else {
                return Ok(None);
            };
            let mut posed = models.get(side).forward(params).map_err(|e| match e {
                MeshError::InvalidParams(d) => {
                    MeshError::InvalidParams(format!("{side} hand: {d}"))
                }
                e => e,
            })?;
            for p in posed.vertices.iter_mut().chain(posed.joints.iter_mut()) {
                *p = self.camera.world_to_camera(*p);
            }
            let to_cam =
                glam::DMat4::from_mat3_translation(self.camera.rotation, self.camera.translation);
            for t in &mut posed.joint_transforms {
                *t = to_cam * *t;
            }
            Ok(Some(posed))
        };
        Ok(PosedTwoHands {
            left: pose(Side::Left)?,
            right: pose(Side::Right)?,
        })
    }

    /// Every camera-frame vertex of the hands present ([`Self::pose_in_camera`]), left then
    /// right.
    pub fn camera_vertices(&self, models: &HandPair) -> Result<Vec<glam::DVec3>, MeshError> {
        let posed = self.pose_in_camera(models)?;
        Ok([posed.left, posed.right]
            .into_iter()
            .flatten()
            .flat_map(|h| h.vertices)
            .collect())
    }

    /// Mean and largest distance (pixels of this scene's camera) between the projections of
    /// corresponding vertices of this scene's hands and `other`'s (the same hands posed
    /// otherwise, seen by this camera); vertices behind the camera are skipped, `(0, 0)`
    /// when none is compared.
    ///
    /// # Errors
    /// When a hand cannot be posed.
    pub fn projected_distance_px(
        &self,
        other: &TwoHandScene,
        models: &HandPair,
    ) -> Result<(f64, f64), MeshError> {
        let a = self.pose_in_camera(models)?;
        let b = TwoHandScene {
            camera: self.camera,
            ..other.clone()
        }
        .pose_in_camera(models)?;
        let (mut sum, mut max, mut n) = (0.0f64, 0.0f64, 0usize);
        for side in Side::BOTH {
            if let (Some(x), Some(y)) = (a.get(side), b.get(side)) {
                for (p, q) in x.vertices.iter().zip(&y.vertices) {
                    let (u, v) = (
                        self.camera.camera_to_pixel(*p),
                        self.camera.camera_to_pixel(*q),
                    );
                    if let (Some(u), Some(v)) = (u, v) {
                        let d = u.distance(v);
                        sum += d;
                        max = max.max(d);
                        n += 1;
                    }
                }
            }
        }
        Ok((if n > 0 { sum / n as f64 } else { 0.0 }, max))
    }

    /// The pixel bounding box of a posed hand's vertices (camera-frame input), or `None` when
    /// no vertex is in front of the camera.
    pub fn pixel_box(&self, camera_frame_vertices: &[DVec3]) -> Option<PixelBox> {
        PixelBox::around(
            camera_frame_vertices
                .iter()
                .filter_map(|p| self.camera.camera_to_pixel(*p)),
        )
    }
}

// ---------------------------------------------------------------------------------------------
// BiTT / InterHand demo pickle.

fn field<'a>(v: &'a Value, name: &str, ctx: &str, path: &Path) -> Result<&'a Value, MeshError> {
    v.get(name)
        .ok_or_else(|| MeshError::format(path, format!("missing `{ctx}{name}`")))
}

fn floats(v: &Value, n: usize, what: &str, path: &Path) -> Result<Vec<f64>, MeshError> {
    let values = match v {
        Value::Array(a) => a.to_f64(),
        Value::List(items) | Value::Tuple(items) => items
            .iter()
            .map(|x| {
                x.as_f64().ok_or_else(|| {
                    MeshError::format(path, format!("`{what}` holds a {}", x.type_name()))
                })
            })
            .collect::<Result<_, _>>()?,
        other => {
            return Err(MeshError::format(
                path,
                format!("`{what}` is a {}, expected numbers", other.type_name()),
            ));
        }
    };
    if values.len() != n {
        return Err(MeshError::format(
            path,
            format!("`{what}` holds {} numbers, expected {n}", values.len()),
        ));
    }
    if values.iter().any(|x| !x.is_finite()) {
        return Err(MeshError::format(
            path,
            format!("`{what}` holds NaN or infinite values"),
        ));
    }
    Ok(values)
}

/// Row-major 3x3 to matrix.
fn mat3_rows(m: &[f64]) -> DMat3 {
    DMat3::from_cols_array(&[m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8]]).transpose()
}

fn hand_from_bitt(v: &Value, side: Side, path: &Path) -> Result<Option<HandParams>, MeshError> {
    if matches!(v, Value::None) {
        return Ok(None);
    }
    let ctx = format!("mano_params.{side}.");
    let get = |name: &str| field(v, name, &ctx, path);
    let what = |name: &str| format!("{ctx}{name}");
    let params = HandParams {
        root_rotation: mat3_rows(&floats(get("R")?, 9, &what("R"), path)?),
        pose: HandPose::Pca(floats(get("pose")?, NUM_POSE, &what("pose"), path)?),
        betas: floats(get("shape")?, NUM_BETAS, &what("shape"), path)?,
        trans: DVec3::from_slice(&floats(get("trans")?, 3, &what("trans"), path)?),
    };
    params
        .validate()
        .map_err(|e| MeshError::format(path, format!("{ctx}: {e}")))?;
    Ok(Some(params))
}

/// Reads a BiTT/InterHand annotation pickle (the demo `NN.pkl` layout) already parsed into
/// `root`. `image_size` is the size of the image `K` refers to ([`BITT_CROP_SIZE`] for the
/// reference's crops).
pub(crate) fn scene_from_bitt_annotation(
    root: &Value,
    path: &Path,
    image_size: (u32, u32),
) -> Result<TwoHandScene, MeshError> {
    let mano = field(root, "mano_params", "", path)?;
    let left = hand_from_bitt(field(mano, "left", "mano_params.", path)?, Side::Left, path)?;
    let right = hand_from_bitt(
        field(mano, "right", "mano_params.", path)?,
        Side::Right,
        path,
    )?;
    if left.is_none() && right.is_none() {
        return Err(MeshError::format(
            path,
            "neither hand is annotated (both `mano_params` entries are None)",
        ));
    }
    let cam = field(root, "camera", "", path)?;
    let rotation = mat3_rows(&floats(
        field(cam, "R", "camera.", path)?,
        9,
        "camera.R",
        path,
    )?);
    let translation = DVec3::from_slice(&floats(
        field(cam, "t", "camera.", path)?,
        3,
        "camera.t",
        path,
    )?);
    let intrinsics = mat3_rows(&floats(
        field(cam, "camera", "camera.", path)?,
        9,
        "camera.camera",
        path,
    )?);
    let camera = file_camera(path, intrinsics, rotation, translation, image_size)?;
    let frame = match root.get("image") {
        Some(img) => FrameInfo {
            file_name: img
                .get("file_name")
                .and_then(Value::as_str)
                .map(str::to_owned),
            capture: img.get("capture").and_then(Value::as_i64),
            camera: img.get("camera").and_then(|c| {
                c.as_str()
                    .map(str::to_owned)
                    .or_else(|| c.as_i64().map(|i| i.to_string()))
            }),
            frame_idx: img.get("frame_idx").and_then(Value::as_i64),
        },
        None => FrameInfo::default(),
    };
    Ok(TwoHandScene {
        left,
        right,
        camera,
        frame,
    })
}

/// The pinhole camera a file describes, checked; an invalid one is a format error of `path`.
fn file_camera(
    path: &Path,
    intrinsics: DMat3,
    rotation: DMat3,
    translation: DVec3,
    image_size: (u32, u32),
) -> Result<PinholeCamera, MeshError> {
    PinholeCamera::new(
        intrinsics,
        rotation,
        translation,
        image_size.0,
        image_size.1,
    )
    .map_err(|e| MeshError::format(path, e.to_string()))
}

/// The image size an annotation pickle's intrinsics refer to when none is given: the size of
/// the image beside it (same name, `.jpg` / `.jpeg` / `.png`: `01.pkl` -> `01.jpg`), else
/// [`BITT_CROP_SIZE`] square (the reference's crop).
pub fn annotation_image_size(path: &Path) -> (u32, u32) {
    ["jpg", "jpeg", "png"]
        .iter()
        .map(|ext| path.with_extension(ext))
        .find(|p| p.is_file())
        .and_then(|p| image::image_dimensions(p).ok())
        .unwrap_or((BITT_CROP_SIZE, BITT_CROP_SIZE))
}

/// Reads a two-hand annotation: a BiTT/InterHand annotation pickle, or a `hands.json` as
/// written by [`hands_json`] (`bitt refine-hands`), told apart by content. `image_size` is
/// the image size of a pickle's `K`; a `hands.json` carries its own.
pub fn load_bitt_annotation(
    path: &Path,
    image_size: (u32, u32),
) -> Result<TwoHandScene, MeshError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| {
        bitt_pickle::PickleError::new(name.clone(), 0, bitt_pickle::PickleErrorKind::Io(e))
    })?;
    bitt_annotation_from_bytes(&bytes, path, image_size)
}

/// [`load_bitt_annotation`] on the bytes of the file; `path` only names it in errors.
pub fn bitt_annotation_from_bytes(
    bytes: &[u8],
    path: &Path,
    image_size: (u32, u32),
) -> Result<TwoHandScene, MeshError> {
    let first = bytes.iter().find(|b| !b.is_ascii_whitespace()).copied();
    let Some(first) = first else {
        return Err(MeshError::format(
            path,
            "the file is empty: neither an annotation pickle nor a hands.json",
        ));
    };
    if first == b'{' {
        return scene_from_hands_json(bytes, path);
    }
    // JSON that is not an object (no pickle starts with these bytes), or any `.json` file:
    // said as such, not reported as a broken pickle.
    let json_name = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if json_name || first == b'[' || first == b'"' || first == b'-' || first.is_ascii_digit() {
        let what = match serde_json::from_slice::<serde_json::Value>(bytes) {
            Ok(serde_json::Value::Array(_)) => "JSON holding an array".to_string(),
            Ok(serde_json::Value::String(_)) => "JSON holding a string".into(),
            Ok(serde_json::Value::Number(_)) => "JSON holding a number".into(),
            Ok(serde_json::Value::Bool(_)) => "JSON holding a boolean".into(),
            Ok(serde_json::Value::Null) => "JSON holding null".into(),
            Ok(serde_json::Value::Object(_)) => "a JSON object".into(),
            Err(e) => format!("not valid JSON ({e})"),
        };
        return Err(MeshError::format(
            path,
            format!(
                "{what}; a hands.json is an object with \"format\": \"{HANDS_JSON_FORMAT}\" \
                 (as refine-hands and fit-hands write it)"
            ),
        ));
    }
    let root = bitt_pickle::from_bytes(bytes, &path.display().to_string())?;
    scene_from_bitt_annotation(&root, path, image_size)
}

// ---------------------------------------------------------------------------------------------
// hands.json: refined hands (axis-angle poses) and their camera.

/// The `format` value of a `hands.json`.
pub(crate) const HANDS_JSON_FORMAT: &str = "bitt-hands/1";

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HandsJsonCamera {
    /// Intrinsics, row-major rows.
    #[serde(rename = "K")]
    k: [[f64; 3]; 3],
    /// World-to-camera rotation, rows.
    #[serde(rename = "R")]
    r: [[f64; 3]; 3],
    /// World-to-camera translation.
    t: [f64; 3],
    width: u32,
    height: u32,
}

#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HandsJsonHand {
    /// Root rotation, rows.
    #[serde(rename = "R")]
    r: [[f64; 3]; 3],
    /// Finger axis-angles, 15 joints x 3, in MANO's joint order.
    pose: Vec<f64>,
    /// Betas.
    shape: Vec<f64>,
    /// Translation.
    trans: [f64; 3],
}

#[derive(serde::Serialize, serde::Deserialize)]
struct HandsJson {
    format: String,
    camera: HandsJsonCamera,
    left: Option<HandsJsonHand>,
    right: Option<HandsJsonHand>,
    #[serde(default)]
    frame: FrameInfo,
}

fn rows(m: DMat3) -> [[f64; 3]; 3] {
    let t = m.transpose();
    [
        t.x_axis.to_array(),
        t.y_axis.to_array(),
        t.z_axis.to_array(),
    ]
}

fn from_rows(r: &[[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols(
        DVec3::from_array(r[0]),
        DVec3::from_array(r[1]),
        DVec3::from_array(r[2]),
    )
    .transpose()
}

/// A scene as `hands.json` text: the camera, and per hand its root rotation `R`, the finger
/// pose as absolute axis-angles (PCA and mean-relative poses expanded with `models`), the
/// shape and the translation.
///
/// # Errors
/// [`MeshError::InvalidParams`] for invalid hand parameters.
pub fn hands_json(scene: &TwoHandScene, models: &HandPair) -> Result<String, MeshError> {
    let hand = |side: Side| -> Result<Option<HandsJsonHand>, MeshError> {
        let Some(p) = scene.hand(side) else {
            return Ok(None);
        };
        p.validate()?;
        Ok(Some(HandsJsonHand {
            r: rows(p.root_rotation),
            pose: models.get(side).pose_axis_angles(&p.pose),
            shape: p.betas.clone(),
            trans: p.trans.to_array(),
        }))
    };
    let c = &scene.camera;
    let file = HandsJson {
        format: HANDS_JSON_FORMAT.into(),
        camera: HandsJsonCamera {
            k: rows(c.intrinsics),
            r: rows(c.rotation),
            t: c.translation.to_array(),
            width: c.width,
            height: c.height,
        },
        left: hand(Side::Left)?,
        right: hand(Side::Right)?,
        frame: scene.frame.clone(),
    };
    Ok(serde_json::to_string_pretty(&file).expect("plain data serialises") + "\n")
}

/// Reads `hands.json` bytes (see [`hands_json`]); `path` names the file in errors.
///
/// # Errors
/// [`bitt_stdx::FileError::Format`] for malformed JSON, a wrong `format`, wrong lengths, NaN, no hand,
/// or an invalid rotation or camera.
pub(crate) fn scene_from_hands_json(bytes: &[u8], path: &Path) -> Result<TwoHandScene, MeshError> {
    let file: HandsJson = serde_json::from_slice(bytes)
        .map_err(|e| MeshError::format(path, format!("not a hands.json: {e}")))?;
    if file.format != HANDS_JSON_FORMAT {
        return Err(MeshError::format(
            path,
            format!(
                "format is `{}`, expected `{HANDS_JSON_FORMAT}`",
                file.format
            ),
        ));
    }
    let hand = |h: Option<HandsJsonHand>, side: Side| -> Result<Option<HandParams>, MeshError> {
        let Some(h) = h else { return Ok(None) };
        let p = HandParams {
            root_rotation: from_rows(&h.r),
            pose: HandPose::AxisAngle(h.pose),
            betas: h.shape,
            trans: DVec3::from_array(h.trans),
        };
        p.validate()
            .map_err(|e| MeshError::format(path, format!("{side} hand: {e}")))?;
        Ok(Some(p))
    };
    let left = hand(file.left, Side::Left)?;
    let right = hand(file.right, Side::Right)?;
    if left.is_none() && right.is_none() {
        return Err(MeshError::format(path, "neither hand is given"));
    }
    let c = &file.camera;
    let finite =
        c.k.iter()
            .chain(&c.r)
            .flatten()
            .chain(&c.t)
            .all(|x| x.is_finite());
    if !finite {
        return Err(MeshError::format(
            path,
            "the camera holds NaN or infinite values",
        ));
    }
    let camera = PinholeCamera::new(
        from_rows(&c.k),
        from_rows(&c.r),
        DVec3::from_array(c.t),
        c.width,
        c.height,
    )
    .map_err(|e| MeshError::format(path, e.to_string()))?;
    Ok(TwoHandScene {
        left,
        right,
        camera,
        frame: file.frame,
    })
}

// ---------------------------------------------------------------------------------------------
// InterHand2.6M JSON.

/// Which frame of an InterHand2.6M capture to read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InterHandFrame {
    /// Capture id (a key of both JSON files).
    pub capture: String,
    /// Frame index (a key under the capture in the MANO JSON).
    pub frame_idx: String,
    /// Camera name (a key of `campos`, `camrot`, `focal`, `princpt`).
    pub camera: String,
}

fn json_floats(
    v: &serde_json::Value,
    n: usize,
    what: &str,
    path: &Path,
) -> Result<Vec<f64>, MeshError> {
    let mut out = Vec::with_capacity(n);
    // Flattens nested lists (camrot is a 3x3 list of lists) in order; JSON nesting is
    // bounded by serde_json's own recursion limit.
    fn walk(x: &serde_json::Value, out: &mut Vec<f64>) -> bool {
        match x {
            serde_json::Value::Number(n) => n.as_f64().map(|f| out.push(f)).is_some(),
            serde_json::Value::Array(items) => items.iter().all(|i| walk(i, out)),
            _ => false,
        }
    }
    if !walk(v, &mut out) || out.len() != n || out.iter().any(|x| !x.is_finite()) {
        return Err(MeshError::format(
            path,
            format!("`{what}` must hold {n} finite numbers"),
        ));
    }
    Ok(out)
}

fn json_at<'a>(
    v: &'a serde_json::Value,
    keys: &[&str],
    path: &Path,
) -> Result<&'a serde_json::Value, MeshError> {
    let mut cur = v;
    for (i, k) in keys.iter().enumerate() {
        cur = cur.get(k).ok_or_else(|| {
            MeshError::format(path, format!("no entry `{}`", keys[..=i].join(".")))
        })?;
    }
    Ok(cur)
}

/// Reads one frame of InterHand2.6M from its files: `mano_path` the
/// `*_MANO_NeuralAnnot.json`, `camera_path` the `*_camera.json` ([`scene_from_interhand_json`]).
///
/// # Errors
/// A file that cannot be read or is not JSON, or that does not hold the frame.
pub fn scene_from_interhand_files(
    mano_path: &Path,
    camera_path: &Path,
    frame: &InterHandFrame,
    image_size: (u32, u32),
) -> Result<TwoHandScene, MeshError> {
    let read = |p: &Path| -> Result<serde_json::Value, MeshError> {
        let text = std::fs::read_to_string(p).map_err(|e| MeshError::Context {
            context: format!("reading {}", p.display()),
            source: Box::new(e),
        })?;
        serde_json::from_str(&text).map_err(|e| MeshError::Context {
            context: format!("{} is not valid JSON", p.display()),
            source: Box::new(e),
        })
    };
    scene_from_interhand_json(
        &read(mano_path)?,
        &read(camera_path)?,
        frame,
        image_size,
        mano_path,
        camera_path,
    )
}

/// Each hand's projected 2D bounding box, as the lines to print: one line per hand in text,
/// or one JSON object (`{"left": [x0, y0, x1, y1] | null, ...}`, hands that are not
/// annotated left out).
pub fn pixel_box_lines(scene: &TwoHandScene, posed: &PosedTwoHands, json: bool) -> Vec<String> {
    let mut lines = Vec::new();
    let mut boxes = serde_json::Map::new();
    for side in Side::BOTH {
        let Some(p) = posed.get(side) else {
            if !json {
                lines.push(format!("{side} hand: not annotated"));
            }
            continue;
        };
        match scene.pixel_box(&p.vertices) {
            Some(b) if json => {
                boxes.insert(
                    side.to_string(),
                    serde_json::json!([b.min.x, b.min.y, b.max.x, b.max.y]),
                );
            }
            Some(b) => lines.push(format!(
                "{side} hand: 2D box x {:.1}..{:.1}, y {:.1}..{:.1} ({:.1} x {:.1} px in a {}x{} image)",
                b.min.x,
                b.max.x,
                b.min.y,
                b.max.y,
                b.size().x,
                b.size().y,
                scene.camera.width,
                scene.camera.height
            )),
            None if json => {
                boxes.insert(side.to_string(), serde_json::Value::Null);
            }
            None => lines.push(format!("{side} hand: behind the camera")),
        }
    }
    if json {
        lines.push(serde_json::Value::Object(boxes).to_string());
    }
    lines
}

/// Reads one frame of InterHand2.6M: `mano` is the parsed `*_MANO_NeuralAnnot.json`
/// (`{capture: {frame: {"left"|"right": {pose[48], shape[10], trans[3]} | null}}}`), `cameras`
/// the parsed `*_camera.json` (`{capture: {campos, camrot, focal, princpt: {camera: ...}}}`).
///
/// Converted as the reference does: root rotation from the first 3 pose values, the other 45
/// are axis-angles relative to the mean pose, the camera translation is `-R campos / 1000`
/// (millimetres to metres), and `K` comes from `focal` and `princpt` for the full image of
/// `image_size`.
pub(crate) fn scene_from_interhand_json(
    mano: &serde_json::Value,
    cameras: &serde_json::Value,
    frame: &InterHandFrame,
    image_size: (u32, u32),
    mano_path: &Path,
    camera_path: &Path,
) -> Result<TwoHandScene, MeshError> {
    let per_frame = json_at(mano, &[&frame.capture, &frame.frame_idx], mano_path)?;
    let hand = |side: Side| -> Result<Option<HandParams>, MeshError> {
        let v = match per_frame.get(side.as_str()) {
            None | Some(serde_json::Value::Null) => return Ok(None),
            Some(v) => v,
        };
        let what = |k: &str| format!("{}.{}.{side}.{k}", frame.capture, frame.frame_idx);
        let pose = json_floats(
            json_at(v, &["pose"], mano_path)?,
            48,
            &what("pose"),
            mano_path,
        )?;
        let params = HandParams {
            root_rotation: rodrigues(DVec3::new(pose[0], pose[1], pose[2])),
            pose: HandPose::MeanRelativeAxisAngle(pose[3..].to_vec()),
            betas: json_floats(
                json_at(v, &["shape"], mano_path)?,
                NUM_BETAS,
                &what("shape"),
                mano_path,
            )?,
            trans: DVec3::from_slice(&json_floats(
                json_at(v, &["trans"], mano_path)?,
                3,
                &what("trans"),
                mano_path,
            )?),
        };
        Ok(Some(params))
    };
    let (left, right) = (hand(Side::Left)?, hand(Side::Right)?);
    if left.is_none() && right.is_none() {
        return Err(MeshError::format(
            mano_path,
            format!(
                "frame {}.{} annotates neither hand",
                frame.capture, frame.frame_idx
            ),
        ));
    }
    let cam = json_at(cameras, &[&frame.capture], camera_path)?;
    let at = |k: &str, n: usize| {
        let v = json_at(cam, &[k, &frame.camera], camera_path)?;
        json_floats(
            v,
            n,
            &format!("{}.{k}.{}", frame.capture, frame.camera),
            camera_path,
        )
    };
    let campos = DVec3::from_slice(&at("campos", 3)?);
    let rotation = mat3_rows(&at("camrot", 9)?);
    let focal = at("focal", 2)?;
    let princpt = at("princpt", 2)?;
    let translation = -(rotation * campos) / 1000.0;
    let intrinsics = mat3_rows(&[
        focal[0], 0.0, princpt[0], 0.0, focal[1], princpt[1], 0.0, 0.0, 1.0,
    ]);
    let camera = file_camera(camera_path, intrinsics, rotation, translation, image_size)?;
    Ok(TwoHandScene {
        left,
        right,
        camera,
        frame: FrameInfo {
            file_name: None,
            capture: frame.capture.parse().ok(),
            camera: Some(frame.camera.clone()),
            frame_idx: frame.frame_idx.parse().ok(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 38, class 10: an empty file or JSON that is not a hands.json is said to be so,
    /// not reported as a broken pickle.
    #[test]
    fn empty_and_non_object_json_annotations_are_named_as_such() {
        for (name, bytes, expect) in [
            ("a.json", &b""[..], "the file is empty"),
            ("a.pkl", &b"  \n"[..], "the file is empty"),
            ("a.json", &b"[1, 2]"[..], "JSON holding an array"),
            ("a.dat", &b"[1, 2]"[..], "JSON holding an array"),
            ("a.json", &b"42"[..], "JSON holding a number"),
            ("a.json", &b"\"hands\""[..], "JSON holding a string"),
            ("a.json", &b"null"[..], "JSON holding null"),
            ("a.json", &b"nul"[..], "not valid JSON"),
        ] {
            let e = bitt_annotation_from_bytes(bytes, Path::new(name), (256, 256))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(name) && e.contains(expect),
                "{name} {bytes:?}: {e}"
            );
            assert!(!e.contains("pickle data") && !e.contains("opcode"), "{e}");
        }
    }

    fn mano_json() -> serde_json::Value {
        let mut pose = vec![0.0; 48];
        pose[0] = 0.5; // root about x
        pose[5] = 0.1;
        serde_json::json!({"7": {"1234": {
            "right": {"pose": pose, "shape": vec![0.1; 10], "trans": [0.01, 0.02, 0.9]},
            "left": null
        }}})
    }

    fn camera_json() -> serde_json::Value {
        serde_json::json!({"7": {
            "campos": {"400262": [100.0, -50.0, 1000.0]},
            "camrot": {"400262": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]},
            "focal": {"400262": [1200.0, 1210.0]},
            "princpt": {"400262": [167.0, 256.0]}
        }})
    }

    /// Reads frame `capture.frame_idx` seen by `camera` from the test JSON.
    fn read(capture: &str, frame_idx: &str, camera: &str) -> Result<TwoHandScene, MeshError> {
        let frame = InterHandFrame {
            capture: capture.into(),
            frame_idx: frame_idx.into(),
            camera: camera.into(),
        };
        let (m, c) = (Path::new("m.json"), Path::new("c.json"));
        scene_from_interhand_json(&mano_json(), &camera_json(), &frame, (334, 512), m, c)
    }

    #[test]
    fn interhand_json_is_converted_like_the_reference() {
        let s = read("7", "1234", "400262").unwrap();
        assert!(s.left.is_none());
        let r = s.right.unwrap();
        assert!(
            (r.root_rotation - DMat3::from_rotation_x(0.5))
                .to_cols_array()
                .iter()
                .all(|x| x.abs() < 1e-12)
        );
        match &r.pose {
            HandPose::MeanRelativeAxisAngle(p) => assert_eq!(p[2], 0.1),
            p => panic!("unexpected pose {p:?}"),
        }
        assert!((s.camera.translation - DVec3::new(-0.1, 0.05, -1.0)).length() < 1e-12);
        assert_eq!(s.camera.focal().y, 1210.0);
        assert_eq!(s.frame.capture, Some(7));
    }

    #[test]
    fn interhand_json_errors_name_the_missing_entry() {
        let e = read("7", "99", "400262").unwrap_err().to_string();
        assert!(e.contains("m.json") && e.contains("7.99"), "{e}");
        let e = read("7", "1234", "nope").unwrap_err().to_string();
        assert!(e.contains("c.json") && e.contains("nope"), "{e}");
    }

    #[test]
    fn hands_json_round_trips_and_refuses_bad_files() {
        let models = crate::procedural_pair();
        let cam = PinholeCamera::new(
            DMat3::from_cols_array(&[500.0, 0.0, 0.0, 0.0, 510.0, 0.0, 64.0, 60.0, 1.0]),
            DMat3::from_rotation_y(0.3),
            DVec3::new(0.01, -0.02, 0.6),
            128,
            120,
        )
        .unwrap();
        let hand = |x: f64| HandParams {
            root_rotation: DMat3::from_rotation_z(x),
            pose: HandPose::Pca((0..NUM_POSE).map(|i| i as f64 * 0.01 - x).collect()),
            betas: vec![x; NUM_BETAS],
            trans: DVec3::new(x, 0.1, 0.2),
        };
        let scene = TwoHandScene {
            left: Some(hand(0.2)),
            right: Some(hand(-0.4)),
            camera: cam,
            frame: FrameInfo::default(),
        };
        let text = hands_json(&scene, &models).unwrap();
        let dir = std::env::temp_dir().join(format!("bitt-hands-json-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("hands.json");
        std::fs::write(&path, &text).unwrap();
        let back = load_bitt_annotation(&path, (1, 1)).unwrap();
        assert_eq!(back.camera.width, 128);
        let a = scene.pose_in_camera(&models).unwrap();
        let b = back.pose_in_camera(&models).unwrap();
        for (p, q) in a
            .left
            .unwrap()
            .vertices
            .iter()
            .zip(&b.left.unwrap().vertices)
        {
            assert!(p.distance(*q) < 1e-12);
        }
        assert!(matches!(back.right.unwrap().pose, HandPose::AxisAngle(_)));

        let bad = text.replacen("\"trans\": [\n      0.2", "\"trans\": [\n      NaN", 1);
        for (name, body) in [
            ("nan.json", bad.as_str()),
            ("format.json", &text.replace(HANDS_JSON_FORMAT, "other/1")),
            ("short.json", &text[..text.len() / 2]),
        ] {
            let p = dir.join(name);
            std::fs::write(&p, body).unwrap();
            let e = load_bitt_annotation(&p, (1, 1)).unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
