//! The InterHand2.6M dataset: reading a split's annotation files and selecting scenes the
//! way the paper's protocol does (Sec. 4.1: one training image of two interacting hands, other
//! camera views of the same frame as novel views, other frames of the same capture as novel
//! poses).
//!
//! # Layout read
//!
//! ```text
//! ROOT/images/{split}/{file_name}            (file_name = Capture{N}/{seq}/cam{C}/image{F}.jpg)
//! ROOT/annotations/{split}/InterHand2.6M_{split}_data.json
//! ROOT/annotations/{split}/InterHand2.6M_{split}_camera.json
//! ROOT/annotations/{split}/InterHand2.6M_{split}_MANO_NeuralAnnot.json
//! ```
//!
//! `_data.json` is COCO-style: `images` (`id`, `file_name`, `width`, `height`, `capture`,
//! `seq_name`, `camera`, `frame_idx`) and `annotations` (`image_id`, `bbox` `[x, y, w, h]`,
//! `hand_type`, `hand_type_valid`), joined on the image id. Only the fields named here are
//! read; the MANO file is parsed keeping only the frames that can be selected, so a full
//! split's files are read without holding their whole JSON trees.
//!
//! # Which images can be selected (candidates)
//!
//! As the reference's data preparation keeps them: `hand_type == "interacting"` with
//! `hand_type_valid` set, both hands fitted in the MANO file for the frame, the camera known
//! to the camera file, and the camera neither one of the `41xxxx` cameras nor one of
//! [`DROP_VIEWS`]. An image whose mean brightness is below [`DARK_IMAGE_MEAN`] is skipped when
//! selected (the reference skips `mean < 10` on the 0..255 scale).
//!
//! # Selection rule (deterministic)
//!
//! A capture is one recording session of one subject, so a capture is an identity.
//! 1. Capture: the one asked for, else the smallest capture id with a candidate.
//! 2. Training frame: the one asked for, else the frame seen by the most candidate cameras
//!    (ties: the smallest frame index).
//! 3. Training camera: the one asked for, else the candidate camera of that frame whose
//!    annotated hand box is largest (ties: the smallest camera name), skipping dark images.
//! 4. Novel views: the frame's other candidate cameras in camera-name order; when there are
//!    more than asked, evenly spaced ones (`floor((2k + 1) M / 2n)` of `M`), then the rest in
//!    order as replacements for dark images.
//! 5. Novel poses: the capture's other candidate frames in frame order, picked the same way;
//!    each seen by the training camera when it is a candidate there, else by the camera with
//!    the largest hand box (dark images skipped: next camera by box size).
//!
//! Every selected image must exist: a missing file is an error naming it.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};

use serde::de::{DeserializeSeed, IgnoredAny, MapAccess, Visitor};

use crate::MeshError;
use crate::annotation::{InterHandFrame, TwoHandScene, scene_from_interhand_json};
use bitt_stdx::FileErrorExt;

/// Cameras the reference's data preparation drops (besides every `41xxxx` camera).
pub(crate) const DROP_VIEWS: [&str; 9] = [
    "400006", "400008", "400015", "400016", "400029", "400030", "400031", "400035", "400049",
];

/// Images darker than this mean value (of `[0, 1]` RGB) are not selected (the reference's
/// `img.mean() < 10` on 0..255).
pub(crate) const DARK_IMAGE_MEAN: f64 = 10.0 / 255.0;

/// Novel views and novel poses per scene in the paper (Sec. 4.1: 8 and 8).
pub const PAPER_NOVEL_VIEWS: usize = 8;
/// See [`PAPER_NOVEL_VIEWS`].
pub const PAPER_NOVEL_POSES: usize = 8;

/// The files of one split of the dataset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InterHandPaths {
    /// Dataset root.
    pub root: PathBuf,
    /// `train`, `val` or `test`.
    pub split: String,
    /// `ROOT/images/{split}`: `file_name`s are relative to it.
    pub images: PathBuf,
    /// `InterHand2.6M_{split}_data.json`.
    pub data: PathBuf,
    /// `InterHand2.6M_{split}_camera.json`.
    pub camera: PathBuf,
    /// `InterHand2.6M_{split}_MANO_NeuralAnnot.json`.
    pub mano: PathBuf,
}

impl InterHandPaths {
    /// The standard layout below `root` for `split`.
    pub fn new(root: &Path, split: &str) -> Self {
        let annotations = root.join("annotations").join(split);
        let name = |what: &str| annotations.join(format!("InterHand2.6M_{split}_{what}.json"));
        InterHandPaths {
            root: root.to_path_buf(),
            split: split.to_string(),
            images: root.join("images").join(split),
            data: name("data"),
            camera: name("camera"),
            mano: name("MANO_NeuralAnnot"),
        }
    }
}

/// One image of the dataset with its annotation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InterHandEntry {
    /// Image id (`images[].id`).
    pub image_id: i64,
    /// Path below `images/{split}`.
    pub file_name: String,
    /// Full frame width in pixels.
    pub width: u32,
    /// Full frame height in pixels.
    pub height: u32,
    /// Capture id (one subject).
    pub capture: i64,
    /// Sequence name.
    pub seq_name: String,
    /// Camera name (e.g. `"400262"`).
    pub camera: String,
    /// Frame index (a key of the MANO file under the capture).
    pub frame_idx: i64,
    /// Both hands' box `[x, y, w, h]` in full-frame pixels.
    pub bbox: [f64; 4],
}

impl InterHandEntry {
    fn box_area(&self) -> f64 {
        (self.bbox[2].max(0.0) * self.bbox[3].max(0.0)).max(0.0)
    }
}

/// How many images each filter kept (printed to explain an empty selection).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CandidateCounts {
    /// Images listed in the data file (with an annotation).
    pub images: usize,
    /// Of those, valid `interacting` ones.
    pub interacting: usize,
    /// Of those, on a camera that is not dropped.
    pub camera_kept: usize,
    /// Of those, with both hands fitted in the MANO file and the camera in the camera file:
    /// the candidates.
    pub candidates: usize,
}

impl fmt::Display for CandidateCounts {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} annotated images, {} valid interacting, {} on kept cameras, {} with both hands \
             fitted and a known camera",
            self.images, self.interacting, self.camera_kept, self.candidates
        )
    }
}

/// What to select (see the [module docs](self) for the rule).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InterHandSelection {
    /// Capture id (default: the smallest with a candidate).
    pub capture: Option<i64>,
    /// Training frame index (default: the frame with the most candidate cameras).
    pub frame: Option<i64>,
    /// Training camera name (default: the largest hand box).
    pub camera: Option<String>,
    /// Number of novel views (other cameras of the training frame).
    pub novel_views: usize,
    /// Number of novel poses (other frames of the capture).
    pub novel_poses: usize,
}

impl Default for InterHandSelection {
    fn default() -> Self {
        InterHandSelection {
            capture: None,
            frame: None,
            camera: None,
            novel_views: PAPER_NOVEL_VIEWS,
            novel_poses: PAPER_NOVEL_POSES,
        }
    }
}

/// One selected image: its entry, its file and its hands and full-frame camera.
#[derive(Debug, Clone, PartialEq)]
pub struct InterHandView {
    /// The data-file entry.
    pub entry: InterHandEntry,
    /// The image file.
    pub image_path: PathBuf,
    /// Both hands and the camera of the full frame (`entry.width x entry.height`).
    pub scene: TwoHandScene,
}

/// A selected scene: a training view, novel views (same frame, other cameras) and novel poses
/// (same capture, other frames).
#[derive(Debug, Clone, PartialEq)]
pub struct InterHandScene {
    /// The capture (identity).
    pub capture: i64,
    /// The training view.
    pub train: InterHandView,
    /// Other cameras of the training frame.
    pub novel_views: Vec<InterHandView>,
    /// Other frames of the capture.
    pub novel_poses: Vec<InterHandView>,
}

/// One split of InterHand2.6M, indexed for selection.
#[derive(Debug, Clone)]
pub struct InterHandDataset {
    /// Its files.
    pub paths: InterHandPaths,
    /// What the filters kept.
    pub counts: CandidateCounts,
    /// Candidates: capture -> frame -> entries in camera-name order.
    candidates: BTreeMap<i64, BTreeMap<i64, Vec<InterHandEntry>>>,
    /// Every capture of the data file (to tell "unknown" from "no candidate").
    captures_seen: HashSet<i64>,
    /// The MANO file, reduced to the candidate frames.
    mano: serde_json::Value,
    /// The camera file.
    cameras: serde_json::Value,
}

// -------------------------------------------------------------------------------------------
// The data file.

#[derive(serde::Deserialize)]
struct DataFile {
    images: Vec<RawImage>,
    annotations: Vec<RawAnnotation>,
}

#[derive(serde::Deserialize)]
struct RawImage {
    id: i64,
    file_name: String,
    width: u32,
    height: u32,
    capture: i64,
    #[serde(default)]
    seq_name: String,
    camera: NameOrNumber,
    frame_idx: i64,
}

#[derive(serde::Deserialize)]
struct RawAnnotation {
    image_id: i64,
    bbox: [f64; 4],
    hand_type: String,
    hand_type_valid: Truthy,
}

/// A camera name written as a string or a number.
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum NameOrNumber {
    Name(String),
    Number(i64),
}

impl NameOrNumber {
    fn into_string(self) -> String {
        match self {
            NameOrNumber::Name(s) => s,
            NameOrNumber::Number(n) => n.to_string(),
        }
    }
}

/// `hand_type_valid`: a boolean or a number (0 / 1).
#[derive(serde::Deserialize)]
#[serde(untagged)]
enum Truthy {
    Bool(bool),
    Number(f64),
}

impl Truthy {
    fn is_true(&self) -> bool {
        match self {
            Truthy::Bool(b) => *b,
            Truthy::Number(x) => *x != 0.0,
        }
    }
}

/// Whether the reference's data preparation drops a camera.
pub(crate) fn camera_dropped(camera: &str) -> bool {
    camera.starts_with("41") || DROP_VIEWS.contains(&camera)
}

/// Camera names in numeric order when both are numbers, else text order.
fn camera_order(a: &str, b: &str) -> std::cmp::Ordering {
    match (a.parse::<u64>(), b.parse::<u64>()) {
        (Ok(x), Ok(y)) => x.cmp(&y),
        _ => a.cmp(b),
    }
}

fn open_json(path: &Path) -> Result<std::io::BufReader<std::fs::File>, MeshError> {
    let file = std::fs::File::open(path).map_err(|e| MeshError::io(path, e))?;
    Ok(std::io::BufReader::new(file))
}

// -------------------------------------------------------------------------------------------
// The MANO file, parsed keeping only the wanted frames.

/// `{capture: {frame: value}}` keeping only `wanted[capture]` frames.
struct ManoFilter<'a> {
    wanted: &'a HashMap<String, HashSet<String>>,
}

struct FrameFilter<'a> {
    wanted: &'a HashSet<String>,
}

impl<'de> DeserializeSeed<'de> for ManoFilter<'_> {
    type Value = serde_json::Map<String, serde_json::Value>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for ManoFilter<'_> {
    type Value = serde_json::Map<String, serde_json::Value>;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an object {capture: {frame: {left, right}}}")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut out = serde_json::Map::new();
        while let Some(capture) = map.next_key::<String>()? {
            match self.wanted.get(&capture) {
                Some(frames) => {
                    let kept = map.next_value_seed(FrameFilter { wanted: frames })?;
                    out.insert(capture, serde_json::Value::Object(kept));
                }
                None => {
                    map.next_value::<IgnoredAny>()?;
                }
            }
        }
        Ok(out)
    }
}

impl<'de> DeserializeSeed<'de> for FrameFilter<'_> {
    type Value = serde_json::Map<String, serde_json::Value>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for FrameFilter<'_> {
    type Value = serde_json::Map<String, serde_json::Value>;
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an object {frame: {left, right}}")
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut out = serde_json::Map::new();
        while let Some(frame) = map.next_key::<String>()? {
            if self.wanted.contains(&frame) {
                out.insert(frame, map.next_value::<serde_json::Value>()?);
            } else {
                map.next_value::<IgnoredAny>()?;
            }
        }
        Ok(out)
    }
}

fn hand_fitted(frame: Option<&serde_json::Value>, side: &str) -> bool {
    frame
        .and_then(|f| f.get(side))
        .is_some_and(serde_json::Value::is_object)
}

// -------------------------------------------------------------------------------------------
// Opening a split.

impl InterHandDataset {
    /// Reads the split `split` of the dataset at `root` (see the [module docs](self)).
    ///
    /// Fails with the file's name when an annotation file is missing or is not what it
    /// should be (a missing field names the field, line and column).
    pub fn open(root: &Path, split: &str) -> Result<Self, MeshError> {
        let paths = InterHandPaths::new(root, split);
        for p in [&paths.data, &paths.camera, &paths.mano] {
            if !p.is_file() {
                return Err(MeshError::io(
                    p,
                    std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        format!(
                            "InterHand2.6M annotation file missing (expected the dataset layout \
                             ROOT/annotations/{split}/InterHand2.6M_{split}_*.json below {})",
                            root.display()
                        ),
                    ),
                ));
            }
        }
        let data = open_json(&paths.data)?;
        let mano = open_json(&paths.mano)?;
        let camera = open_json(&paths.camera)?;
        Self::from_readers(paths, data, mano, camera)
    }

    /// [`open`](Self::open) on the three annotation files' contents already in memory;
    /// `paths` names them in errors and locates the images.
    pub fn from_json_bytes(
        paths: InterHandPaths,
        data: &[u8],
        camera: &[u8],
        mano: &[u8],
    ) -> Result<Self, MeshError> {
        Self::from_readers(paths, data, mano, camera)
    }

    /// Parses and indexes the data, MANO and camera files read from `data`, `mano`, `camera`.
    fn from_readers(
        paths: InterHandPaths,
        data: impl std::io::Read,
        mano: impl std::io::Read,
        camera: impl std::io::Read,
    ) -> Result<Self, MeshError> {
        let data: DataFile = serde_json::from_reader(data).map_err(|e| {
            MeshError::format(&paths.data, format!("not an InterHand2.6M data file: {e}"))
        })?;
        let mut counts = CandidateCounts::default();
        let mut by_id: HashMap<i64, RawImage> = HashMap::with_capacity(data.images.len());
        let mut captures_seen = HashSet::new();
        for img in data.images {
            captures_seen.insert(img.capture);
            by_id.insert(img.id, img);
        }
        let mut kept: Vec<InterHandEntry> = Vec::new();
        for ann in data.annotations {
            let Some(img) = by_id.remove(&ann.image_id) else {
                continue;
            };
            counts.images += 1;
            if ann.hand_type != "interacting" || !ann.hand_type_valid.is_true() {
                continue;
            }
            counts.interacting += 1;
            let camera = img.camera.into_string();
            if camera_dropped(&camera) {
                continue;
            }
            counts.camera_kept += 1;
            kept.push(InterHandEntry {
                image_id: img.id,
                file_name: img.file_name,
                width: img.width,
                height: img.height,
                capture: img.capture,
                seq_name: img.seq_name,
                camera,
                frame_idx: img.frame_idx,
                bbox: ann.bbox,
            });
        }
        drop(by_id);

        let mut wanted: HashMap<String, HashSet<String>> = HashMap::new();
        for e in &kept {
            wanted
                .entry(e.capture.to_string())
                .or_default()
                .insert(e.frame_idx.to_string());
        }
        let mut de = serde_json::Deserializer::from_reader(mano);
        let mano = ManoFilter { wanted: &wanted }
            .deserialize(&mut de)
            .and_then(|m| de.end().map(|()| m))
            .map_err(|e| {
                MeshError::format(
                    &paths.mano,
                    format!("not an InterHand2.6M MANO file ({{capture: {{frame: {{left, right}}}}}}): {e}"),
                )
            })?;
        let mano = serde_json::Value::Object(mano);
        let cameras: serde_json::Value = serde_json::from_reader(camera)
            .map_err(|e| MeshError::format(&paths.camera, format!("not valid JSON: {e}")))?;

        let mut candidates: BTreeMap<i64, BTreeMap<i64, Vec<InterHandEntry>>> = BTreeMap::new();
        for e in kept {
            let (c, f) = (e.capture.to_string(), e.frame_idx.to_string());
            let frame = mano.get(&c).and_then(|m| m.get(&f));
            if !(hand_fitted(frame, "left") && hand_fitted(frame, "right")) {
                continue;
            }
            let known = cameras
                .get(&c)
                .and_then(|cap| cap.get("campos"))
                .and_then(|p| p.get(&e.camera))
                .is_some();
            if !known {
                continue;
            }
            counts.candidates += 1;
            candidates
                .entry(e.capture)
                .or_default()
                .entry(e.frame_idx)
                .or_default()
                .push(e);
        }
        for frames in candidates.values_mut() {
            for entries in frames.values_mut() {
                entries.sort_by(|a, b| camera_order(&a.camera, &b.camera));
                entries.dedup_by(|a, b| a.camera == b.camera);
            }
        }
        Ok(InterHandDataset {
            paths,
            counts,
            candidates,
            captures_seen,
            mano,
            cameras,
        })
    }

    /// Captures with at least one candidate image, in increasing order.
    pub fn captures(&self) -> Vec<i64> {
        self.candidates.keys().copied().collect()
    }

    /// Candidate frames of a capture, in increasing order (empty for an unknown capture).
    pub fn frames(&self, capture: i64) -> Vec<i64> {
        self.candidates
            .get(&capture)
            .map(|f| f.keys().copied().collect())
            .unwrap_or_default()
    }

    /// Candidate entries of one frame, in camera-name order.
    pub fn cameras(&self, capture: i64, frame: i64) -> &[InterHandEntry] {
        self.candidates
            .get(&capture)
            .and_then(|f| f.get(&frame))
            .map_or(&[], Vec::as_slice)
    }

    /// The image file of an entry.
    pub fn image_path(&self, entry: &InterHandEntry) -> PathBuf {
        self.paths.images.join(&entry.file_name)
    }

    /// Both hands and the full-frame camera of an entry (MANO parameters converted as the
    /// reference does; see [`scene_from_interhand_json`]).
    pub fn scene(&self, entry: &InterHandEntry) -> Result<TwoHandScene, MeshError> {
        let frame = InterHandFrame {
            capture: entry.capture.to_string(),
            frame_idx: entry.frame_idx.to_string(),
            camera: entry.camera.clone(),
        };
        let mut scene = scene_from_interhand_json(
            &self.mano,
            &self.cameras,
            &frame,
            (entry.width, entry.height),
            &self.paths.mano,
            &self.paths.camera,
        )?;
        scene.frame.file_name = Some(entry.file_name.clone());
        Ok(scene)
    }

    fn view(&self, entry: &InterHandEntry) -> Result<InterHandView, MeshError> {
        Ok(InterHandView {
            entry: entry.clone(),
            image_path: self.image_path(entry),
            scene: self.scene(entry)?,
        })
    }

    /// Whether an entry's image is usable: it must exist (else an error naming it) and not be
    /// dark.
    fn bright(&self, entry: &InterHandEntry) -> Result<bool, MeshError> {
        Ok(image_mean(&self.image_path(entry))? >= DARK_IMAGE_MEAN)
    }

    /// Selects one scene (see the [module docs](self) for the rule).
    pub fn select(&self, sel: &InterHandSelection) -> Result<InterHandScene, MeshError> {
        let data = &self.paths.data;
        let capture = match sel.capture {
            Some(c) => c,
            None => *self.candidates.keys().next().ok_or_else(|| {
                MeshError::format(data, format!("no image can be selected ({})", self.counts))
            })?,
        };
        let frames = self.candidates.get(&capture).ok_or_else(|| {
            let why = if self.captures_seen.contains(&capture) {
                "has no valid interacting-hand image with both hands fitted on a kept camera"
            } else {
                "is not in the file"
            };
            MeshError::format(
                data,
                format!(
                    "capture {capture} {why} (captures with candidates: {:?})",
                    self.captures()
                ),
            )
        })?;
        let frame = match sel.frame {
            Some(f) => {
                if !frames.contains_key(&f) {
                    return Err(MeshError::format(
                        data,
                        format!(
                            "frame {f} of capture {capture} is not a candidate (no valid \
                             interacting-hand image of it with both hands fitted in {} on a \
                             kept camera)",
                            self.paths.mano.display()
                        ),
                    ));
                }
                f
            }
            None => frames
                .iter()
                .max_by(|a, b| a.1.len().cmp(&b.1.len()).then(b.0.cmp(a.0)))
                .map(|(f, _)| *f)
                .expect("a capture in the index has frames"),
        };
        let entries = &frames[&frame];
        let train = match &sel.camera {
            Some(name) => {
                let e = entries.iter().find(|e| &e.camera == name).ok_or_else(|| {
                    MeshError::format(
                        data,
                        format!(
                            "camera {name} is not a candidate for frame {frame} of capture \
                             {capture} (candidates: {})",
                            entries
                                .iter()
                                .map(|e| e.camera.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                })?;
                // It must exist and decode (the error names the file); a dark image asked
                // for by name is used anyway.
                image_mean(&self.image_path(e))?;
                e
            }
            None => {
                let mut order: Vec<&InterHandEntry> = entries.iter().collect();
                order.sort_by(|a, b| {
                    b.box_area()
                        .total_cmp(&a.box_area())
                        .then(camera_order(&a.camera, &b.camera))
                });
                let mut found = None;
                for e in order {
                    if self.bright(e)? {
                        found = Some(e);
                        break;
                    }
                }
                found.ok_or_else(|| {
                    MeshError::format(
                        data,
                        format!("every image of frame {frame} of capture {capture} is dark"),
                    )
                })?
            }
        };
        let others: Vec<&InterHandEntry> = entries
            .iter()
            .filter(|e| e.camera != train.camera)
            .collect();
        let mut novel_views = Vec::new();
        for e in spread_order(others.len(), sel.novel_views) {
            if novel_views.len() == sel.novel_views {
                break;
            }
            if self.bright(others[e])? {
                novel_views.push(self.view(others[e])?);
            }
        }
        let other_frames: Vec<i64> = frames.keys().copied().filter(|&f| f != frame).collect();
        let mut novel_poses = Vec::new();
        for i in spread_order(other_frames.len(), sel.novel_poses) {
            if novel_poses.len() == sel.novel_poses {
                break;
            }
            let cams = &frames[&other_frames[i]];
            let mut order: Vec<&InterHandEntry> = cams.iter().collect();
            order.sort_by(|a, b| {
                (b.camera == train.camera)
                    .cmp(&(a.camera == train.camera))
                    .then(b.box_area().total_cmp(&a.box_area()))
                    .then(camera_order(&a.camera, &b.camera))
            });
            for e in order {
                if self.bright(e)? {
                    novel_poses.push(self.view(e)?);
                    break;
                }
            }
        }
        Ok(InterHandScene {
            capture,
            train: self.view(train)?,
            novel_views,
            novel_poses,
        })
    }
}

/// Indices `0..m` in selection order: `n` evenly spaced ones (`floor((2k + 1) m / 2n)`)
/// first, then the others in increasing order (replacements).
pub(crate) fn spread_order(m: usize, n: usize) -> Vec<usize> {
    if n == 0 {
        return Vec::new();
    }
    if n >= m {
        return (0..m).collect();
    }
    let first: Vec<usize> = (0..n).map(|k| (2 * k + 1) * m / (2 * n)).collect();
    let chosen: HashSet<usize> = first.iter().copied().collect();
    first
        .into_iter()
        .chain((0..m).filter(|i| !chosen.contains(i)))
        .collect()
}

/// Mean of an image's RGB values in `[0, 1]`; fails naming the file when it is missing or
/// cannot be decoded.
pub(crate) fn image_mean(path: &Path) -> Result<f64, MeshError> {
    if !path.is_file() {
        return Err(MeshError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "image listed in the InterHand2.6M data file is missing",
            ),
        ));
    }
    let img = image::open(path)
        .map_err(|e| MeshError::format(path, format!("cannot decode the image: {e}")))?
        .to_rgb8();
    let n = img.as_raw().len().max(1) as f64;
    Ok(img.as_raw().iter().map(|&v| f64::from(v)).sum::<f64>() / n / 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_order_is_even_then_the_rest() {
        assert_eq!(spread_order(10, 3), vec![1, 5, 8, 0, 2, 3, 4, 6, 7, 9]);
        assert_eq!(spread_order(3, 8), vec![0, 1, 2]);
        assert_eq!(spread_order(5, 0), Vec::<usize>::new());
        let o = spread_order(81, 8);
        assert_eq!(o.len(), 81);
        let mut s = o.clone();
        s.sort_unstable();
        s.dedup();
        assert_eq!(s.len(), 81);
    }

    #[test]
    fn dropped_cameras_follow_the_reference() {
        assert!(camera_dropped("410001"));
        assert!(camera_dropped("400015"));
        assert!(!camera_dropped("400262"));
        assert_eq!(
            camera_order("400100", "400028"),
            std::cmp::Ordering::Greater
        );
    }
}
