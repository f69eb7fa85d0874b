//! 2D hand keypoints from common detectors: OpenPose, MediaPipe and a plain JSON format.
//!
//! A photo plus a keypoint file is enough to fit two hand models: this module reads the file
//! into a [`TwoHandKeypoints`], 21 points per hand in pixels of the image. The joint order is
//! OpenPose's hand order, which is also MediaPipe's and the order of the forward pass's
//! output joints ([`crate::model::OUTPUT_JOINT_ORDER`]): 0 wrist; 1-4 thumb (CMC, MCP, IP,
//! tip); 5-8 index (MCP, PIP, DIP, tip); 9-12 middle; 13-16 ring; 17-20 pinky.
//!
//! The sides of a [`TwoHandKeypoints`] are the hands *as they appear in the image*, i.e. which
//! hand model fits them. For OpenPose and the plain format that is what the file says; for
//! MediaPipe it depends on [`KeypointOptions::mirrored`] (see there). `docs/keypoints.md`
//! describes the formats with examples.
//!
//! Invariants of every [`TwoHandKeypoints`] this module reads: a hand that is `Some` has
//! exactly [`NUM_KEYPOINTS`] points and at least one of them present (confidence > 0); at
//! least one hand is `Some`; every value is finite and no confidence is negative.

#![warn(missing_docs)]

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use serde_json::{Map, Value};

use crate::{MeshError, PinholeCamera, Side};
use bitt_stdx::FileErrorExt;

/// Number of keypoints per hand (wrist + 5 digits x 4).
pub const NUM_KEYPOINTS: usize = 21;

/// Numbers in an OpenPose hand array: x, y and confidence for each point.
const OPENPOSE_HAND_LEN: usize = 3 * NUM_KEYPOINTS;

/// Where MediaPipe writes the per-hand landmark lists: the Python Tasks API's
/// `dataclasses.asdict`, the JavaScript Tasks API, the legacy Solutions API.
const MEDIAPIPE_LANDMARK_KEYS: [&str; 3] = ["hand_landmarks", "landmarks", "multi_hand_landmarks"];

/// Where MediaPipe writes the per-hand handedness, in the same order of APIs (plus the older
/// JavaScript name `handednesses`).
const MEDIAPIPE_HANDEDNESS_KEYS: [&str; 3] = ["handedness", "handednesses", "multi_handedness"];

/// The keys of a MediaPipe category that may hold the label, in order of preference.
const CATEGORY_NAME_KEYS: [&str; 5] = [
    "category_name",
    "categoryName",
    "label",
    "display_name",
    "displayName",
];

/// Keypoints of camera-frame points (e.g. a posed hand's 21 joints) seen by `camera`, each
/// with `confidence`; a point behind the camera is missing (confidence 0).
pub fn project_points(
    points: &[glam::DVec3],
    camera: &PinholeCamera,
    confidence: f64,
) -> Vec<Keypoint> {
    points
        .iter()
        .map(|p| match camera.camera_to_pixel(*p) {
            Some(q) => Keypoint {
                x: q.x,
                y: q.y,
                confidence,
            },
            None => Keypoint {
                x: 0.0,
                y: 0.0,
                confidence: 0.0,
            },
        })
        .collect()
}

/// The error when no format is given and the content matches none.
const CANNOT_TELL: &str = "cannot tell the format (expected OpenPose \
    people[].hand_*_keypoints_2d, MediaPipe handedness + hand_landmarks/landmarks, or plain \
    left/right); give --format";

/// One 2D keypoint.
///
/// `x`, `y` are in pixels of the image, `y` down, in the convention of
/// [`crate::PinholeCamera`] and OpenCV / OpenPose: the centre of the top-left pixel is
/// `(0, 0)` (pixel `i` spans `[i - 0.5, i + 0.5]`); `confidence` in `[0, 1]`; confidence 0 means the point is missing (its `x`, `y`
/// then mean nothing).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Keypoint {
    /// Horizontal pixel coordinate, growing to the right.
    pub x: f64,
    /// Vertical pixel coordinate, growing downwards.
    pub y: f64,
    /// Detector confidence in `[0, 1]`; 0 = missing point.
    pub confidence: f64,
}

/// The least diagonal (pixels) of the bounding box of a hand's present points: below it the
/// points are one spot, not a hand (normalised coordinates read as pixels span about 1 px).
pub(crate) const MIN_HAND_SPAN_PX: f64 = 8.0;

/// The least thickness of a hand's points (the standard deviation across their main
/// direction over the one along it): real hands measure 0.75 to 0.82 on the demo frames'
/// detections, points on a line 0.
pub(crate) const MIN_HAND_THICKNESS: f64 = 0.05;

/// The highest confidence a hand's points must reach: below it the detector found nothing
/// there.
pub(crate) const MIN_HAND_CONFIDENCE: f64 = 1e-3;

/// The least mean distance between the two hands' corresponding points, as a fraction of the
/// larger hand's span: interlocked hands in the demo frames are 0.12 and 0.36 apart, a hand's
/// points copied into the other hand 0.
pub(crate) const MIN_HANDS_APART: f64 = 0.03;

/// The keypoint file formats this module reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum KeypointFormat {
    /// OpenPose's `--write_json` output (`people[].hand_left_keypoints_2d`, ...).
    OpenPose,
    /// MediaPipe HandLandmarker results saved as JSON (Python, JavaScript or legacy layout).
    MediaPipe,
    /// This project's plain format: `{"left": [[x, y, c], ...], "right": [...]}`.
    Plain,
}

impl KeypointFormat {
    /// All formats, in the order [`guess_format`] tries them.
    pub const ALL: [KeypointFormat; 3] = [
        KeypointFormat::OpenPose,
        KeypointFormat::MediaPipe,
        KeypointFormat::Plain,
    ];

    /// `"openpose"`, `"mediapipe"` or `"plain"` (what [`FromStr`] reads).
    pub fn as_str(self) -> &'static str {
        match self {
            KeypointFormat::OpenPose => "openpose",
            KeypointFormat::MediaPipe => "mediapipe",
            KeypointFormat::Plain => "plain",
        }
    }
}

impl fmt::Display for KeypointFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for KeypointFormat {
    type Err = String;

    /// `"openpose"`, `"mediapipe"` or `"plain"`, in any case.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        KeypointFormat::ALL
            .into_iter()
            .find(|f| f.as_str().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                format!("unknown keypoint format {s:?} (expected openpose, mediapipe or plain)")
            })
    }
}

/// The keypoints of both hands in one image.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwoHandKeypoints {
    /// The left hand as it appears in the image (the hand the left-hand model fits), exactly
    /// [`NUM_KEYPOINTS`] points in OpenPose order when `Some`; `None` when missing.
    pub left: Option<Vec<Keypoint>>,
    /// The right hand as it appears in the image, as for [`TwoHandKeypoints::left`].
    pub right: Option<Vec<Keypoint>>,
    /// The format the keypoints were read from.
    pub format: KeypointFormat,
    /// One line per thing the user should know (extra people, swapped labels, missing
    /// hands or points...).
    pub notes: Vec<String>,
}

impl TwoHandKeypoints {
    /// The points of one hand, if present.
    pub fn hand(&self, side: Side) -> Option<&[Keypoint]> {
        match side {
            Side::Left => self.left.as_deref(),
            Side::Right => self.right.as_deref(),
        }
    }

    /// The number of points of one hand with confidence > 0 (0 for a missing hand).
    pub fn num_present(&self, side: Side) -> usize {
        self.hand(side)
            .map_or(0, |h| h.iter().filter(|p| p.confidence > 0.0).count())
    }

    /// The diagonal (pixels) of the bounding box of one hand's present points (`None` for a
    /// missing hand).
    pub fn span_px(&self, side: Side) -> Option<f64> {
        let present = present_points(self.hand(side)?);
        if present.is_empty() {
            return None;
        }
        let (lo, hi) = present.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p.x), lo[1].min(p.y)],
                    [hi[0].max(p.x), hi[1].max(p.y)],
                )
            },
        );
        Some((hi[0] - lo[0]).hypot(hi[1] - lo[1]))
    }

    /// Checks that each hand's points can be a photographed hand, before anything is fitted
    /// to them: they span at least [`MIN_HAND_SPAN_PX`], do not lie on a line (thickness at
    /// least [`MIN_HAND_THICKNESS`]), at least one is confident ([`MIN_HAND_CONFIDENCE`]), and
    /// the two hands are not the same points ([`MIN_HANDS_APART`]).
    ///
    /// # Errors
    /// What is wrong, naming the hand, the measured value and the likely cause.
    pub fn check_plausible(&self) -> Result<(), String> {
        for side in Side::BOTH {
            let Some(points) = self.hand(side) else {
                continue;
            };
            let present = present_points(points);
            if present.is_empty() {
                continue;
            }
            let highest = present.iter().map(|p| p.confidence).fold(0.0, f64::max);
            if highest < MIN_HAND_CONFIDENCE {
                return Err(format!(
                    "the {side} hand's points are all but missing: its highest confidence is \
                     {highest:e} (below {MIN_HAND_CONFIDENCE}); the detector did not find this \
                     hand, so leave it out of the file"
                ));
            }
            let span = self.span_px(side).unwrap_or(0.0);
            if span < MIN_HAND_SPAN_PX {
                return Err(format!(
                    "the {side} hand's {} points span {span:.2} px (a hand spans at least \
                     {MIN_HAND_SPAN_PX} px): not a hand; coordinates normalised to 0..1 given \
                     in a pixel format?",
                    present.len()
                ));
            }
            let thickness = thickness(&present);
            if thickness < MIN_HAND_THICKNESS {
                return Err(format!(
                    "the {side} hand's points lie on a line (thickness {thickness:.3} of their \
                     length, a hand's is above {MIN_HAND_THICKNESS}): not a hand"
                ));
            }
        }
        if let (Some(l), Some(r)) = (&self.left, &self.right) {
            let pairs: Vec<f64> = l
                .iter()
                .zip(r)
                .filter(|(a, b)| a.confidence > 0.0 && b.confidence > 0.0)
                .map(|(a, b)| (a.x - b.x).hypot(a.y - b.y))
                .collect();
            let span = Side::BOTH
                .iter()
                .filter_map(|&s| self.span_px(s))
                .fold(0.0, f64::max);
            if pairs.len() >= NUM_KEYPOINTS / 2 {
                let apart = pairs.iter().sum::<f64>() / pairs.len() as f64;
                if apart < MIN_HANDS_APART * span {
                    return Err(format!(
                        "the left and right hands are given the same points (their points are \
                         {apart:.2} px apart on average, the hands span {span:.0} px): one \
                         hand's points were copied into the other's"
                    ));
                }
            }
        }
        Ok(())
    }

    /// The plain format's JSON text: exactly what [`parse_keypoints`] reads back as
    /// [`KeypointFormat::Plain`] with identical point values.
    ///
    /// Every point is written as `[x, y, confidence]`, one per line, with the shortest decimal
    /// that round-trips; a missing hand as `null`. `format` and `notes` are not written. A
    /// hand whose points are all missing reads back as `None` (as in every format), and
    /// non-finite values are written as `null`, which does not read back.
    pub fn to_plain_json(&self) -> String {
        let mut out = String::from("{\n");
        for (n, side) in Side::BOTH.into_iter().enumerate() {
            out.push_str(&format!("  \"{side}\": "));
            match self.hand(side) {
                None => out.push_str("null"),
                Some(points) => {
                    out.push_str("[\n");
                    for (i, p) in points.iter().enumerate() {
                        let sep = if i + 1 < points.len() { "," } else { "" };
                        out.push_str(&format!(
                            "    [{}, {}, {}]{sep}\n",
                            json_number(p.x),
                            json_number(p.y),
                            json_number(p.confidence)
                        ));
                    }
                    out.push_str("  ]");
                }
            }
            out.push_str(if n == 0 { ",\n" } else { "\n" });
        }
        out.push_str("}\n");
        out
    }

    /// The points of the image resized `sx` times horizontally and `sy` times vertically:
    /// `x -> (x + 0.5) * sx - 0.5` (the image's edges stay its edges), same for `y`;
    /// confidences, format and notes unchanged.
    pub fn scaled(&self, sx: f64, sy: f64) -> TwoHandKeypoints {
        self.map_points(|p| Keypoint {
            x: (p.x + 0.5) * sx - 0.5,
            y: (p.y + 0.5) * sy - 0.5,
            confidence: p.confidence,
        })
    }

    /// The keypoints of the horizontally mirrored image, `width` pixels wide: every point's
    /// `x` becomes `width - 1 - x` (pixel `i` goes to `width - 1 - i`), and left and right swap (a mirrored right hand is a left
    /// hand). Used for mirrored selfies. Format and notes unchanged.
    pub fn mirrored(&self, width: f64) -> TwoHandKeypoints {
        let flipped = self.map_points(|p| Keypoint {
            x: width - 1.0 - p.x,
            y: p.y,
            confidence: p.confidence,
        });
        TwoHandKeypoints {
            left: flipped.right,
            right: flipped.left,
            ..flipped
        }
    }

    fn map_points(&self, f: impl Fn(&Keypoint) -> Keypoint) -> TwoHandKeypoints {
        let map = |hand: &Option<Vec<Keypoint>>| hand.as_ref().map(|h| h.iter().map(&f).collect());
        TwoHandKeypoints {
            left: map(&self.left),
            right: map(&self.right),
            format: self.format,
            notes: self.notes.clone(),
        }
    }
}

/// How to read a keypoint file.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KeypointOptions {
    /// The format; `None` guesses it from the content (see [`guess_format`]).
    pub format: Option<KeypointFormat>,
    /// The image's `[width, height]` in pixels. MediaPipe's normalised `x`, `y` are multiplied
    /// by these (so MediaPipe needs them). In every format a present point may lie outside
    /// the image (hands can be cut off), but not more than one image size outside it
    /// (`x < -width`, `x > 2 * width`, same for `y`): such a file is not in pixels of this
    /// image. `[0, 0]` (the default) means unknown: no bounds check, MediaPipe refused.
    pub image_size: [u32; 2],
    /// MediaPipe only: take the handedness labels as they are, whatever the layout. By
    /// default (`false`, an ordinary photo that MediaPipe ran on) each layout is read in its
    /// API's convention, measured with genuine MediaPipe 0.10.21 (`tests-data/mediapipe/`):
    /// the legacy Solutions API (`multi_handedness`) labels hands as if the image were a
    /// mirrored selfie, so a hand it calls "Left" appears as a *right* hand and its labels are
    /// swapped; the Tasks API (`handedness` with `hand_landmarks` or `landmarks`) labels each
    /// hand as it appears in the image, so its labels are kept. A note says which. With
    /// `true` the labels are kept in every layout: right when the application already swapped
    /// the legacy labels itself, or flipped the image for MediaPipe and flipped the landmarks
    /// back. Nothing is flipped here; see [`TwoHandKeypoints::mirrored`] for that.
    pub labels_as_is: bool,
}

/// Guesses the format of a parsed file from its keys: a `people` key is OpenPose;
/// `hand_landmarks`, `landmarks`, `multi_hand_landmarks` (or one of MediaPipe's handedness
/// keys) MediaPipe; `left` or `right` plain. `None` for anything else, including JSON that is
/// not an object. The keys' contents are checked when the file is read, not here.
pub(crate) fn guess_format(value: &Value) -> Option<KeypointFormat> {
    let obj = value.as_object()?;
    if obj.contains_key("people") {
        Some(KeypointFormat::OpenPose)
    } else if MEDIAPIPE_LANDMARK_KEYS
        .iter()
        .chain(&MEDIAPIPE_HANDEDNESS_KEYS)
        .any(|k| obj.contains_key(*k))
    {
        Some(KeypointFormat::MediaPipe)
    } else if obj.contains_key("left") || obj.contains_key("right") {
        Some(KeypointFormat::Plain)
    } else {
        None
    }
}

/// Reads keypoints from the bytes of a file; `path` only names the file in errors.
///
/// Errors are [`bitt_stdx::FileError::Format`] naming `path` and the offending field, e.g.
/// `people[0].hand_left_keypoints_2d: 60 numbers, expected 63 (...)` or
/// `right[3][1]: not a finite number (found null)`. Never panics.
pub fn parse_keypoints(
    bytes: &[u8],
    path: &Path,
    options: &KeypointOptions,
) -> Result<TwoHandKeypoints, MeshError> {
    parse(bytes, options).map_err(|detail| MeshError::format(path, detail))
}

/// Reads a keypoint file (see [`parse_keypoints`]); [`bitt_stdx::FileError::Io`] naming the file when it
/// cannot be read.
pub fn read_keypoints(
    path: &Path,
    options: &KeypointOptions,
) -> Result<TwoHandKeypoints, MeshError> {
    let bytes = std::fs::read(path).map_err(|e| MeshError::io(path, e))?;
    parse_keypoints(&bytes, path, options)
}

/// [`parse_keypoints`] with the error detail as a string.
fn parse(bytes: &[u8], options: &KeypointOptions) -> Result<TwoHandKeypoints, String> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err("not JSON: the file is empty".into());
    }
    let value = parse_json(bytes)?;
    let guessed = guess_format(&value);
    let format = options.format.or(guessed).ok_or(CANNOT_TELL)?;
    let bounds = Bounds::new(options.image_size);
    let read = match format {
        KeypointFormat::OpenPose => read_openpose(&value, &bounds),
        KeypointFormat::MediaPipe => read_mediapipe(&value, &bounds, options.labels_as_is),
        KeypointFormat::Plain => read_plain(&value, &bounds),
    };
    let (left, right, mut notes) = read.map_err(|detail| match guessed {
        Some(g) if g != format => format!("{detail} (the file looks like {g})"),
        _ => detail,
    })?;
    if left.is_none() && right.is_none() {
        return Err(match format {
            KeypointFormat::OpenPose => {
                "no hand in the file (people[0] has no hand keypoints; was OpenPose run with \
                 --hand?)"
                    .into()
            }
            _ => "no hand in the file".into(),
        });
    }
    for (side, hand) in [(Side::Left, &left), (Side::Right, &right)] {
        match hand {
            None => notes.push(format!("no {side} hand in the file")),
            Some(points) => {
                let missing: Vec<String> = points
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.confidence <= 0.0)
                    .map(|(i, _)| i.to_string())
                    .collect();
                if !missing.is_empty() {
                    notes.push(format!(
                        "{side} hand: {} of {NUM_KEYPOINTS} points missing (confidence 0): {}",
                        missing.len(),
                        missing.join(", ")
                    ));
                }
            }
        }
    }
    Ok(TwoHandKeypoints {
        left,
        right,
        format,
        notes,
    })
}

/// Marks a number that [`parse_json`] turned into a string (`\u0000#` + the number's text).
const NUMBER_MARK: &str = "\0#";

/// Parses JSON with every number read correctly rounded, so that what
/// [`TwoHandKeypoints::to_plain_json`] writes reads back bit for bit. (serde_json's own float
/// parsing, without its `float_roundtrip` feature, can be one unit in the last place off.)
///
/// The text is validated by serde_json first (its message, with line and column, is the
/// error); then every number token outside a string is wrapped into a marked string, the
/// result parsed by serde_json, and the marked strings parsed as `f64` by the standard
/// library. A number too large for `f64` stays a string, which readers reject as not a number.
fn parse_json(bytes: &[u8]) -> Result<Value, String> {
    serde_json::from_slice::<serde::de::IgnoredAny>(bytes).map_err(|e| format!("not JSON: {e}"))?;
    let mut out = Vec::with_capacity(bytes.len() + bytes.len() / 2);
    let (mut in_string, mut escaped) = (false, false);
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if in_string {
            if escaped {
                escaped = false;
            } else if b == b'\\' {
                escaped = true;
            } else if b == b'"' {
                in_string = false;
            }
            out.push(b);
            i += 1;
        } else if b == b'-' || b.is_ascii_digit() {
            let start = i;
            while i < bytes.len()
                && matches!(bytes[i], b'0'..=b'9' | b'-' | b'+' | b'.' | b'e' | b'E')
            {
                i += 1;
            }
            out.extend_from_slice(b"\"\\u0000#");
            out.extend_from_slice(&bytes[start..i]);
            out.push(b'"');
        } else {
            in_string = b == b'"';
            out.push(b);
            i += 1;
        }
    }
    let value: Value = serde_json::from_slice(&out).map_err(|e| format!("not JSON: {e}"))?;
    Ok(restore_numbers(value))
}

/// Turns [`parse_json`]'s marked strings back into numbers.
fn restore_numbers(value: Value) -> Value {
    match value {
        Value::String(s) => match s.strip_prefix(NUMBER_MARK) {
            Some(text) => text
                .parse::<f64>()
                .ok()
                .and_then(serde_json::Number::from_f64)
                // Too large for f64: stays marked, so messages call it a number.
                .map_or_else(|| Value::String(s.clone()), Value::Number),
            None => Value::String(s),
        },
        Value::Array(a) => Value::Array(a.into_iter().map(restore_numbers).collect()),
        Value::Object(o) => Value::Object(
            o.into_iter()
                .map(|(k, v)| (k, restore_numbers(v)))
                .collect(),
        ),
        other => other,
    }
}

/// Left hand, right hand, notes.
type Hands = (Option<Vec<Keypoint>>, Option<Vec<Keypoint>>, Vec<String>);

/// The image the points must lie in (loosely: one image size around it).
struct Bounds {
    /// `[width, height]`, `None` when unknown.
    size: Option<[f64; 2]>,
}

impl Bounds {
    fn new(size: [u32; 2]) -> Self {
        Bounds {
            size: (size[0] > 0 && size[1] > 0).then(|| [f64::from(size[0]), f64::from(size[1])]),
        }
    }

    /// Checks a pixel coordinate on `axis` (0: x, 1: y); `field` names it.
    fn check(&self, value: f64, axis: usize, field: impl FnOnce() -> String) -> Result<(), String> {
        let Some(size) = self.size else {
            return Ok(());
        };
        let extent = size[axis];
        if value < -extent || value > 2.0 * extent {
            return Err(format!(
                "{}: {} = {value} px is not in pixels of a {}x{} image (more than one image \
                 size outside it)",
                field(),
                ["x", "y"][axis],
                size[0],
                size[1]
            ));
        }
        Ok(())
    }
}

/// Validates a point read in pixels: confidence not negative, present points near the image.
/// `field(k)` names its x (k = 0), y (1) or confidence (2).
fn check_point(
    p: &Keypoint,
    bounds: &Bounds,
    field: impl Fn(usize) -> String,
) -> Result<(), String> {
    if p.confidence < 0.0 {
        return Err(format!(
            "{}: confidence {} is negative (expected 0 to 1)",
            field(2),
            p.confidence
        ));
    }
    if p.confidence > 0.0 {
        bounds.check(p.x, 0, || field(0))?;
        bounds.check(p.y, 1, || field(1))?;
    }
    Ok(())
}

/// The present points (confidence > 0) of one hand.
fn present_points(points: &[Keypoint]) -> Vec<Keypoint> {
    points
        .iter()
        .filter(|p| p.confidence > 0.0)
        .copied()
        .collect()
}

/// The square root of the ratio of the smaller to the larger eigenvalue of the points'
/// covariance: 0 on a line, 1 for a round cloud.
fn thickness(points: &[Keypoint]) -> f64 {
    let n = points.len() as f64;
    let (mx, my) = (
        points.iter().map(|p| p.x).sum::<f64>() / n,
        points.iter().map(|p| p.y).sum::<f64>() / n,
    );
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p.x - mx, p.y - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    let (mean, diff) = ((sxx + syy) / 2.0, (sxx - syy) / 2.0);
    let radius = diff.hypot(sxy);
    let (large, small) = (mean + radius, (mean - radius).max(0.0));
    if large <= 0.0 {
        return 0.0;
    }
    (small / large).sqrt()
}

/// `Some(points)` unless every point is missing.
fn unless_all_missing(points: Vec<Keypoint>) -> Option<Vec<Keypoint>> {
    points.iter().any(|p| p.confidence > 0.0).then_some(points)
}

/// What a JSON value is, for messages.
fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// A finite number.
fn number(v: &Value, field: impl FnOnce() -> String) -> Result<f64, String> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => Err(format!(
            "{}: not a finite number (found {})",
            field(),
            describe(v)
        )),
    }
}

/// A short description of a value for messages: its kind, and a number's or string's text.
fn describe(v: &Value) -> String {
    match v {
        Value::Number(n) => format!("{n}"),
        Value::String(s) if s.starts_with(NUMBER_MARK) => format!(
            "the number {}, too large for a 64-bit float",
            &s[NUMBER_MARK.len()..]
        ),
        Value::String(s) if s.chars().count() <= 40 => format!("the string {s:?}"),
        other => kind(other).to_owned(),
    }
}

fn array<'a>(v: &'a Value, field: &str) -> Result<&'a Vec<Value>, String> {
    v.as_array()
        .ok_or_else(|| format!("{field}: expected an array, found {}", kind(v)))
}

fn object<'a>(v: &'a Value, field: &str) -> Result<&'a Map<String, Value>, String> {
    v.as_object()
        .ok_or_else(|| format!("{field}: expected an object, found {}", kind(v)))
}

/// The top-level object of a file that should be in `format`, whose signature is `expected`.
fn root<'a>(v: &'a Value, expected: &str) -> Result<&'a Map<String, Value>, String> {
    v.as_object()
        .ok_or_else(|| format!("expected a JSON object with {expected}, found {}", kind(v)))
}

// ---------------------------------------------------------------------------------------
// OpenPose

fn read_openpose(value: &Value, bounds: &Bounds) -> Result<Hands, String> {
    const EXPECTED: &str =
        "people[].hand_left_keypoints_2d / hand_right_keypoints_2d (OpenPose --write_json)";
    let obj = root(value, EXPECTED)?;
    let people = obj
        .get("people")
        .ok_or_else(|| format!("people: missing (expected {EXPECTED})"))?;
    let people = array(people, "people")?;
    if people.is_empty() {
        return Err("people: empty, no person in the file".into());
    }
    let mut notes = Vec::new();
    if people.len() > 1 {
        notes.push(format!(
            "{} people in the file, using people[0]",
            people.len()
        ));
    }
    let person = object(&people[0], "people[0]")?;
    let hand = |key: &str| -> Result<Option<Vec<Keypoint>>, String> {
        let field = format!("people[0].{key}");
        match person.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => openpose_hand(v, &field, bounds),
        }
    };
    let left = hand("hand_left_keypoints_2d")?;
    let right = hand("hand_right_keypoints_2d")?;
    Ok((left, right, notes))
}

/// One OpenPose hand array: empty or all zero = missing hand.
fn openpose_hand(v: &Value, field: &str, bounds: &Bounds) -> Result<Option<Vec<Keypoint>>, String> {
    let values = array(v, field)?;
    if values.is_empty() {
        return Ok(None);
    }
    if values.len() != OPENPOSE_HAND_LEN {
        return Err(format!(
            "{field}: {} numbers, expected {OPENPOSE_HAND_LEN} (x, y, confidence for \
             {NUM_KEYPOINTS} points)",
            values.len()
        ));
    }
    let numbers = values
        .iter()
        .enumerate()
        .map(|(k, v)| number(v, || format!("{field}[{k}]")))
        .collect::<Result<Vec<f64>, String>>()?;
    let points: Vec<Keypoint> = numbers
        .chunks_exact(3)
        .map(|c| Keypoint {
            x: c[0],
            y: c[1],
            confidence: c[2],
        })
        .collect();
    for (i, p) in points.iter().enumerate() {
        check_point(p, bounds, |k| format!("{field}[{}]", 3 * i + k))?;
    }
    Ok(unless_all_missing(points))
}

// ---------------------------------------------------------------------------------------
// MediaPipe

fn read_mediapipe(value: &Value, bounds: &Bounds, labels_as_is: bool) -> Result<Hands, String> {
    const EXPECTED: &str = "MediaPipe handedness + hand_landmarks (Python), landmarks \
        (JavaScript) or multi_hand_landmarks (legacy Solutions)";
    let obj = root(value, EXPECTED)?;
    let find = |keys: [&'static str; 3]| keys.into_iter().find(|k| obj.contains_key(*k));
    let lm_key = find(MEDIAPIPE_LANDMARK_KEYS)
        .ok_or_else(|| format!("hand_landmarks: missing (expected {EXPECTED})"))?;
    let hd_key = find(MEDIAPIPE_HANDEDNESS_KEYS).ok_or_else(|| {
        format!("handedness: missing (expected {EXPECTED}); it tells the hands apart")
    })?;
    // The legacy Solutions API labels as for a mirrored selfie; the Tasks APIs as the hand
    // appears in the image (measured with genuine MediaPipe 0.10.21: the two APIs gave
    // opposite labels to 9 of the 10 hands both found; docs/keypoints.md).
    let legacy = lm_key == "multi_hand_landmarks" || hd_key == "multi_handedness";
    let swap = legacy && !labels_as_is;
    let empty = Vec::new();
    // The legacy API's results hold `None` (null) when no hand was found.
    let list = |key: &str| match &obj[key] {
        Value::Null => Ok(&empty),
        v => array(v, key),
    };
    let hands = list(lm_key)?;
    let labels = list(hd_key)?;
    if hands.len() != labels.len() {
        return Err(format!(
            "{hd_key}: {} entries for {} hands in {lm_key}, expected one per hand",
            labels.len(),
            hands.len()
        ));
    }
    if hands.len() > 2 {
        return Err(format!(
            "{lm_key}: {} hands, expected at most 2 (keep the two to fit)",
            hands.len()
        ));
    }
    if hands.is_empty() {
        return Ok((None, None, Vec::new()));
    }
    let Some([width, height]) = bounds.size else {
        return Err(format!(
            "{lm_key}: MediaPipe landmarks are normalised to the image; the image size is \
             needed to turn them into pixels"
        ));
    };
    let mut read = Vec::new();
    for (i, (hand, label)) in hands.iter().zip(labels).enumerate() {
        let label = mediapipe_label(label, &format!("{hd_key}[{i}]"))?;
        let points = mediapipe_hand(hand, &format!("{lm_key}[{i}]"), [width, height])?;
        read.push((label, points));
    }
    if let [(a, _), (b, _)] = read.as_slice()
        && a == b
    {
        let label = if *a == Side::Left { "Left" } else { "Right" };
        return Err(format!(
            "{hd_key}: both hands are labelled {label}; MediaPipe sometimes does this when \
             hands overlap: fix one label or use the plain format"
        ));
    }
    let api = if legacy { "legacy Solutions" } else { "Tasks" };
    let note = match (swap, labels_as_is) {
        (true, _) => format!(
            "MediaPipe {api} labels swapped: that API labels hands as if the photo were a \
             mirrored selfie, so the hand labelled Left is fitted as the right hand and vice \
             versa (--labels-as-is keeps them)"
        ),
        (false, true) => {
            format!("MediaPipe {api} labels taken as they are (--labels-as-is)")
        }
        (false, false) => format!(
            "MediaPipe {api} labels taken as they are: that API labels each hand as it appears \
             in the photo"
        ),
    };
    let notes = vec![note];
    let (mut left, mut right) = (None, None);
    for (label, points) in read {
        let side = if swap { label.mirrored() } else { label };
        *match side {
            Side::Left => &mut left,
            Side::Right => &mut right,
        } = Some(points);
    }
    Ok((left, right, notes))
}

/// One handedness entry: a list of categories (Tasks APIs) or `{"classification": [...]}`
/// (legacy); the first category's label.
fn mediapipe_label(v: &Value, field: &str) -> Result<Side, String> {
    let (categories, field) = match v {
        Value::Object(o) if o.contains_key("classification") => {
            let field = format!("{field}.classification");
            (array(&o["classification"], &field)?, field)
        }
        Value::Array(a) => (a, field.to_owned()),
        other => {
            return Err(format!(
                "{field}: expected an array of categories, found {}",
                kind(other)
            ));
        }
    };
    let first = categories
        .first()
        .ok_or_else(|| format!("{field}: no category"))?;
    let field = format!("{field}[0]");
    let category = object(first, &field)?;
    let (key, name) = CATEGORY_NAME_KEYS
        .iter()
        .find_map(|k| match category.get(*k) {
            Some(Value::String(s)) if !s.trim().is_empty() => Some((*k, s.trim())),
            _ => None,
        })
        .ok_or_else(|| format!("{field}: no category_name, categoryName or label"))?;
    if name.eq_ignore_ascii_case("left") {
        Ok(Side::Left)
    } else if name.eq_ignore_ascii_case("right") {
        Ok(Side::Right)
    } else {
        Err(format!("{field}.{key}: {name:?}, expected Left or Right"))
    }
}

/// One landmark list: an array of `{x, y, z, ...}` (Tasks APIs) or `{"landmark": [...]}`
/// (legacy), normalised coordinates turned into pixels.
fn mediapipe_hand(v: &Value, field: &str, size: [f64; 2]) -> Result<Vec<Keypoint>, String> {
    let (landmarks, field) = match v {
        Value::Object(o) if o.contains_key("landmark") => {
            let field = format!("{field}.landmark");
            (array(&o["landmark"], &field)?, field)
        }
        Value::Array(a) => (a, field.to_owned()),
        other => {
            return Err(format!(
                "{field}: expected an array of landmarks, found {}",
                kind(other)
            ));
        }
    };
    if landmarks.len() != NUM_KEYPOINTS {
        return Err(format!(
            "{field}: {} landmarks, expected {NUM_KEYPOINTS}",
            landmarks.len()
        ));
    }
    let mut points = Vec::with_capacity(NUM_KEYPOINTS);
    for (j, landmark) in landmarks.iter().enumerate() {
        let field = format!("{field}[{j}]");
        let landmark = object(landmark, &field)?;
        let mut xy = [0.0; 2];
        for (axis, name) in ["x", "y"].into_iter().enumerate() {
            let v = landmark
                .get(name)
                .ok_or_else(|| format!("{field}.{name}: missing"))?;
            let normalised = number(v, || format!("{field}.{name}"))?;
            if !(-1.0..=2.0).contains(&normalised) {
                return Err(format!(
                    "{field}.{name}: {normalised} is not a normalised image coordinate (more \
                     than one image size outside the image)"
                ));
            }
            // Normalised from the image's edge; pixel centres are at whole numbers here.
            xy[axis] = normalised * size[axis] - 0.5;
        }
        points.push(Keypoint {
            x: xy[0],
            y: xy[1],
            confidence: 1.0,
        });
    }
    Ok(points)
}

// ---------------------------------------------------------------------------------------
// Plain

fn read_plain(value: &Value, bounds: &Bounds) -> Result<Hands, String> {
    const EXPECTED: &str = "left and/or right (the plain format: {\"left\": [[x, y, c], ...], \
        \"right\": [[x, y, c], ...]})";
    let obj = root(value, EXPECTED)?;
    if !obj.contains_key("left") && !obj.contains_key("right") {
        return Err(format!("left, right: missing (expected {EXPECTED})"));
    }
    let hand = |side: Side| match obj.get(side.as_str()) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => plain_hand(v, side.as_str(), bounds),
    };
    Ok((hand(Side::Left)?, hand(Side::Right)?, Vec::new()))
}

fn plain_hand(v: &Value, field: &str, bounds: &Bounds) -> Result<Option<Vec<Keypoint>>, String> {
    let rows = array(v, field)?;
    if rows.len() != NUM_KEYPOINTS {
        return Err(format!(
            "{field}: {} points, expected {NUM_KEYPOINTS}",
            rows.len()
        ));
    }
    let mut points = Vec::with_capacity(NUM_KEYPOINTS);
    for (i, row) in rows.iter().enumerate() {
        let row_field = format!("{field}[{i}]");
        let row = array(row, &row_field)?;
        if row.len() != 2 && row.len() != 3 {
            return Err(format!(
                "{row_field}: {} numbers, expected [x, y] or [x, y, confidence]",
                row.len()
            ));
        }
        let at = |k: usize| number(&row[k], || format!("{row_field}[{k}]"));
        let p = Keypoint {
            x: at(0)?,
            y: at(1)?,
            confidence: if row.len() == 3 { at(2)? } else { 1.0 },
        };
        check_point(&p, bounds, |k| format!("{row_field}[{k}]"))?;
        points.push(p);
    }
    Ok(unless_all_missing(points))
}

/// A finite `f64` as the shortest JSON number that round-trips (`null` if not finite).
fn json_number(x: f64) -> String {
    serde_json::to_string(&x).unwrap_or_else(|_| "null".to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    const W: u32 = 640;
    const H: u32 = 480;
    /// Points missing in the OpenPose fixture: (hand, joint).
    const OPENPOSE_MISSING: [(Side, usize); 3] =
        [(Side::Left, 7), (Side::Right, 19), (Side::Right, 4)];

    fn path() -> PathBuf {
        PathBuf::from("/data/photo_0001_keypoints.json")
    }

    fn options(format: Option<KeypointFormat>) -> KeypointOptions {
        KeypointOptions {
            format,
            image_size: [W, H],
            labels_as_is: false,
        }
    }

    #[test]
    fn plausibility_measures_span_thickness_confidence_and_separation() {
        let hands = |left: Vec<Keypoint>, right: Vec<Keypoint>| TwoHandKeypoints {
            left: Some(left),
            right: Some(right),
            format: KeypointFormat::Plain,
            notes: Vec::new(),
        };
        let ok = hands(truth(Side::Left), truth(Side::Right));
        ok.check_plausible().unwrap();
        // A 3:4 box's corners: span 5, thickness 3/4 (standard deviations 1.5 and 2).
        let corners: Vec<Keypoint> = [(0.0, 0.0), (3.0, 0.0), (0.0, 4.0), (3.0, 4.0)]
            .iter()
            .map(|&(x, y)| Keypoint {
                x,
                y,
                confidence: 1.0,
            })
            .collect();
        assert!((thickness(&corners) - 0.75).abs() < 1e-12);
        let mut with_missing = truth(Side::Left);
        with_missing[3] = Keypoint {
            x: 1e6,
            y: -1e6,
            confidence: 0.0,
        };
        let full = hands(truth(Side::Left), truth(Side::Right)).span_px(Side::Left);
        assert_eq!(
            hands(with_missing, truth(Side::Right)).span_px(Side::Left),
            full
        );
        let cases: [(TwoHandKeypoints, &str); 4] = [
            (
                hands(
                    truth(Side::Left)
                        .iter()
                        .map(|p| Keypoint {
                            x: p.x / 640.0,
                            y: p.y / 480.0,
                            ..*p
                        })
                        .collect(),
                    truth(Side::Right),
                ),
                "the left hand's 21 points span 0.",
            ),
            (
                hands(
                    truth(Side::Left),
                    truth(Side::Right)
                        .iter()
                        .enumerate()
                        .map(|(i, p)| Keypoint {
                            x: i as f64 * 10.0,
                            y: 5.0,
                            ..*p
                        })
                        .collect(),
                ),
                "the right hand's points lie on a line (thickness 0.000",
            ),
            (
                hands(
                    truth(Side::Left)
                        .iter()
                        .map(|p| Keypoint {
                            confidence: 1e-4,
                            ..*p
                        })
                        .collect(),
                    truth(Side::Right),
                ),
                "highest confidence is 1e-4",
            ),
            (
                hands(truth(Side::Right), truth(Side::Right)),
                "given the same points",
            ),
        ];
        for (kp, expected) in cases {
            let e = kp.check_plausible().unwrap_err();
            assert!(e.contains(expected), "{e}");
        }
    }

    /// The geometric left and right hands: a non-trivial spread, some points near or past
    /// the image border, confidences varying.
    fn truth(side: Side) -> Vec<Keypoint> {
        (0..NUM_KEYPOINTS)
            .map(|i| {
                let t = i as f64;
                let (x0, dir) = match side {
                    Side::Left => (412.123_456_789, 1.0),
                    Side::Right => (187.654_321_987, -1.0),
                };
                let digit = if i == 0 { 0.0 } else { ((i - 1) / 4) as f64 };
                let along = if i == 0 {
                    0.0
                } else {
                    ((i - 1) % 4 + 1) as f64
                };
                Keypoint {
                    x: x0 + dir * (23.7 * along + 3.071_828_17 * digit) + (t * 0.77).sin() * 9.0,
                    y: 401.5 - 31.25 * along - 17.3 * digit + (t * 1.3).cos() * 4.4 - 0.1 * t,
                    confidence: 0.31 + 0.0317 * t,
                }
            })
            .collect()
    }

    fn numbers(v: &[f64]) -> String {
        v.iter()
            .map(|x| format!("{x}"))
            .collect::<Vec<_>>()
            .join(",")
    }

    /// OpenPose `--write_json` text for one person (as OpenPose writes it: one line, this key
    /// order), with the points of `OPENPOSE_MISSING` written as 0,0,0.
    fn openpose_person(left: &[Keypoint], right: &[Keypoint]) -> String {
        let hand = |side: Side, points: &[Keypoint]| {
            let mut v = Vec::new();
            for (i, p) in points.iter().enumerate() {
                if OPENPOSE_MISSING.contains(&(side, i)) {
                    v.extend([0.0, 0.0, 0.0]);
                } else {
                    v.extend([p.x, p.y, p.confidence]);
                }
            }
            numbers(&v)
        };
        let pose: Vec<f64> = (0..75)
            .map(|k| [300.5, 200.25, 0.8][k % 3] + (k / 3) as f64)
            .collect();
        let face: Vec<f64> = (0..210)
            .map(|k| [310.0, 120.5, 0.9][k % 3] + (k / 3) as f64 * 0.5)
            .collect();
        format!(
            "{{\"person_id\":[-1],\"pose_keypoints_2d\":[{}],\"face_keypoints_2d\":[{}],\
             \"hand_left_keypoints_2d\":[{}],\"hand_right_keypoints_2d\":[{}],\
             \"pose_keypoints_3d\":[],\"face_keypoints_3d\":[],\"hand_left_keypoints_3d\":[],\
             \"hand_right_keypoints_3d\":[]}}",
            numbers(&pose),
            numbers(&face),
            hand(Side::Left, left),
            hand(Side::Right, right)
        )
    }

    fn openpose_fixture() -> String {
        format!(
            "{{\"version\":1.3,\"people\":[{}]}}",
            openpose_person(&truth(Side::Left), &truth(Side::Right))
        )
    }

    /// The label MediaPipe gives the geometric `side`: the Tasks APIs name the hand as it
    /// appears; the legacy Solutions API assumes a mirrored image and names the other side.
    fn mediapipe_label_of(side: Side, legacy: bool) -> &'static str {
        match (side, legacy) {
            (Side::Left, false) | (Side::Right, true) => "Left",
            (Side::Right, false) | (Side::Left, true) => "Right",
        }
    }

    /// `dataclasses.asdict(result)` dumped by Python's `json.dumps` (its separators, float
    /// repr). The right hand comes first, the second hand's visibility/presence are null.
    fn mediapipe_python_fixture() -> String {
        let mut handedness = Vec::new();
        let mut landmarks = Vec::new();
        let mut world = Vec::new();
        for (i, side) in [Side::Right, Side::Left].into_iter().enumerate() {
            let label = mediapipe_label_of(side, false);
            handedness.push(format!(
                "[{{\"index\": {i}, \"score\": 0.9{i}78, \"display_name\": \"\", \
                 \"category_name\": \"{label}\"}}]"
            ));
            let extra = if i == 0 {
                "\"visibility\": 0.0, \"presence\": 0.0"
            } else {
                "\"visibility\": null, \"presence\": null"
            };
            let lms: Vec<String> = truth(side)
                .iter()
                .enumerate()
                .map(|(j, p)| {
                    format!(
                        "{{\"x\": {:?}, \"y\": {:?}, \"z\": {:?}, {extra}}}",
                        (p.x + 0.5) / f64::from(W),
                        (p.y + 0.5) / f64::from(H),
                        -0.01 * j as f64
                    )
                })
                .collect();
            landmarks.push(format!("[{}]", lms.join(", ")));
            let wl: Vec<String> = (0..NUM_KEYPOINTS)
                .map(|j| {
                    format!(
                        "{{\"x\": {:?}, \"y\": {:?}, \"z\": {:?}, {extra}}}",
                        0.001 * j as f64,
                        -0.002 * j as f64,
                        0.0005 * j as f64
                    )
                })
                .collect();
            world.push(format!("[{}]", wl.join(", ")));
        }
        format!(
            "{{\"handedness\": [{}], \"hand_landmarks\": [{}], \"hand_world_landmarks\": [{}]}}",
            handedness.join(", "),
            landmarks.join(", "),
            world.join(", ")
        )
    }

    /// The JavaScript `HandLandmarkerResult` through `JSON.stringify` (left hand first);
    /// `handednesses_too` adds the older duplicate `handednesses`, `old` has only that.
    fn mediapipe_js_fixture(handednesses_too: bool, old: bool) -> String {
        let mut handedness = Vec::new();
        let mut landmarks = Vec::new();
        let mut world = Vec::new();
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            let label = mediapipe_label_of(side, false);
            handedness.push(format!(
                "[{{\"score\":0.97{i},\"index\":{i},\"categoryName\":\"{label}\",\
                 \"displayName\":\"{label}\"}}]"
            ));
            let lms: Vec<String> = truth(side)
                .iter()
                .enumerate()
                .map(|(j, p)| {
                    format!(
                        "{{\"x\":{},\"y\":{},\"z\":{},\"visibility\":0}}",
                        (p.x + 0.5) / f64::from(W),
                        (p.y + 0.5) / f64::from(H),
                        -0.01 * j as f64
                    )
                })
                .collect();
            landmarks.push(format!("[{}]", lms.join(",")));
            let wl: Vec<String> = (0..NUM_KEYPOINTS)
                .map(|j| {
                    format!(
                        "{{\"x\":{},\"y\":{},\"z\":{},\"visibility\":0}}",
                        0.001 * j as f64,
                        0.0,
                        0.0
                    )
                })
                .collect();
            world.push(format!("[{}]", wl.join(",")));
        }
        let handedness = handedness.join(",");
        let labels = if old {
            format!("\"handednesses\":[{handedness}]")
        } else if handednesses_too {
            format!("\"handedness\":[{handedness}],\"handednesses\":[{handedness}]")
        } else {
            format!("\"handedness\":[{handedness}]")
        };
        format!(
            "{{\"landmarks\":[{}],\"worldLandmarks\":[{}],{labels}}}",
            landmarks.join(","),
            world.join(",")
        )
    }

    /// The legacy Solutions API through `MessageToDict`.
    fn mediapipe_legacy_fixture() -> String {
        let mut handedness = Vec::new();
        let mut landmarks = Vec::new();
        for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
            handedness.push(format!(
                "{{\"classification\": [{{\"index\": {i}, \"score\": 0.95, \"label\": \"{}\"}}]}}",
                mediapipe_label_of(side, true)
            ));
            let lms: Vec<String> = truth(side)
                .iter()
                .map(|p| {
                    format!(
                        "{{\"x\": {}, \"y\": {}, \"z\": -0.02}}",
                        (p.x + 0.5) / f64::from(W),
                        (p.y + 0.5) / f64::from(H)
                    )
                })
                .collect();
            landmarks.push(format!("{{\"landmark\": [{}]}}", lms.join(", ")));
        }
        format!(
            "{{\"multi_handedness\": [{}], \"multi_hand_landmarks\": [{}]}}",
            handedness.join(", "),
            landmarks.join(", ")
        )
    }

    /// The plain format, with `[x, y]` (no confidence) for the right hand and an extra key.
    fn plain_fixture() -> String {
        let left: Vec<String> = truth(Side::Left)
            .iter()
            .map(|p| format!("[{}, {}, {}]", p.x, p.y, p.confidence))
            .collect();
        let right: Vec<String> = truth(Side::Right)
            .iter()
            .map(|p| format!("[{}, {}]", p.x, p.y))
            .collect();
        format!(
            "{{\"scene\": \"scene_003\", \"left\": [{}], \"right\": [{}]}}",
            left.join(", "),
            right.join(", ")
        )
    }

    /// `text` parsed, edited and written back (for broken variants of a fixture).
    fn edited(text: &str, edit: impl FnOnce(&mut Value)) -> String {
        let mut v: Value = serde_json::from_str(text).unwrap();
        edit(&mut v);
        v.to_string()
    }

    fn read(text: &str, opts: &KeypointOptions) -> Result<TwoHandKeypoints, MeshError> {
        parse_keypoints(text.as_bytes(), &path(), opts)
    }

    fn read_ok(text: &str, opts: &KeypointOptions) -> TwoHandKeypoints {
        read(text, opts).unwrap_or_else(|e| panic!("{e}"))
    }

    /// The error message, checked to name the file and hold every one of `parts`.
    fn error(text: &[u8], opts: &KeypointOptions, parts: &[&str]) -> String {
        let e = match parse_keypoints(text, &path(), opts) {
            Ok(k) => panic!("expected an error, got {k:?}"),
            Err(e) => e,
        };
        assert!(
            matches!(e, MeshError::File(bitt_stdx::FileError::Format { .. })),
            "{e:?}"
        );
        let message = e.to_string();
        assert!(
            message.starts_with(&format!("{}: ", path().display())),
            "no path in {message:?}"
        );
        for part in parts {
            assert!(message.contains(part), "{part:?} not in {message:?}");
        }
        message
    }

    /// Same points (x, y within 1e-9 relative), ignoring points missing in either.
    fn assert_same_points(got: &TwoHandKeypoints, want_missing: &[(Side, usize)]) {
        for side in Side::BOTH {
            let hand = got.hand(side).unwrap_or_else(|| panic!("no {side} hand"));
            assert_eq!(hand.len(), NUM_KEYPOINTS);
            for (i, (a, b)) in hand.iter().zip(truth(side)).enumerate() {
                if want_missing.contains(&(side, i)) {
                    assert_eq!(a.confidence, 0.0, "{side} {i}");
                    continue;
                }
                assert!(a.confidence > 0.0, "{side} {i}");
                for (u, v) in [(a.x, b.x), (a.y, b.y)] {
                    assert!(
                        (u - v).abs() <= 1e-9 * v.abs().max(1.0),
                        "{side} {i}: {u} vs {v}"
                    );
                }
            }
        }
    }

    #[test]
    fn all_formats_read_the_same_points() {
        let opts = options(None);
        let openpose = read_ok(&openpose_fixture(), &opts);
        assert_eq!(openpose.format, KeypointFormat::OpenPose);
        assert_same_points(&openpose, &OPENPOSE_MISSING);
        for (side, i) in OPENPOSE_MISSING {
            assert_eq!(
                openpose.hand(side).unwrap()[i],
                Keypoint {
                    x: 0.0,
                    y: 0.0,
                    confidence: 0.0
                }
            );
        }
        // OpenPose confidences are kept exactly.
        assert_eq!(openpose.hand(Side::Left).unwrap()[3], truth(Side::Left)[3]);
        assert_eq!(openpose.num_present(Side::Left), 20);
        assert_eq!(openpose.num_present(Side::Right), 19);
        assert!(
            openpose
                .notes
                .iter()
                .any(|n| n.contains("right hand: 2 of 21 points missing"))
        );

        for (text, name) in [
            (mediapipe_python_fixture(), "python"),
            (mediapipe_js_fixture(false, false), "js"),
            (mediapipe_js_fixture(true, false), "js with handednesses"),
            (mediapipe_js_fixture(false, true), "old js"),
            (mediapipe_legacy_fixture(), "legacy"),
        ] {
            let k = read(&text, &opts).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(k.format, KeypointFormat::MediaPipe, "{name}");
            assert_same_points(&k, &[]);
            assert!(
                k.hand(Side::Left)
                    .unwrap()
                    .iter()
                    .all(|p| p.confidence == 1.0)
            );
            let expected = if name == "legacy" {
                "MediaPipe legacy Solutions labels swapped"
            } else {
                "MediaPipe Tasks labels taken as they are"
            };
            assert!(k.notes.iter().any(|n| n.contains(expected)), "{name}");
            assert_eq!(k.num_present(Side::Right), 21);
        }

        let plain = read_ok(&plain_fixture(), &opts);
        assert_eq!(plain.format, KeypointFormat::Plain);
        assert_same_points(&plain, &[]);
        assert_eq!(
            plain.hand(Side::Left).unwrap(),
            truth(Side::Left).as_slice()
        );
        assert!(
            plain
                .hand(Side::Right)
                .unwrap()
                .iter()
                .all(|p| p.confidence == 1.0)
        );

        // Given formats read the same as guessed ones.
        for (text, format) in [
            (openpose_fixture(), KeypointFormat::OpenPose),
            (mediapipe_python_fixture(), KeypointFormat::MediaPipe),
            (plain_fixture(), KeypointFormat::Plain),
        ] {
            assert_eq!(
                read_ok(&text, &options(Some(format))),
                read_ok(&text, &opts)
            );
        }
    }

    /// `labels_as_is` keeps the legacy API's labels (not swapped) and changes nothing for the
    /// Tasks APIs, whose labels are already the hands as they appear.
    #[test]
    fn mediapipe_labels_as_is_skips_the_legacy_swap() {
        let opts = KeypointOptions {
            labels_as_is: true,
            ..options(None)
        };
        let swapped = read_ok(&mediapipe_legacy_fixture(), &options(None));
        let as_is = read_ok(&mediapipe_legacy_fixture(), &opts);
        assert_eq!(as_is.left, swapped.right);
        assert_eq!(as_is.right, swapped.left);
        assert!(
            swapped
                .notes
                .iter()
                .any(|n| n.contains("legacy Solutions labels swapped"))
        );
        assert!(as_is.notes.iter().any(|n| n.contains("(--labels-as-is)")));
        let tasks = read_ok(&mediapipe_python_fixture(), &options(None));
        assert_eq!(read_ok(&mediapipe_python_fixture(), &opts).left, tasks.left);
        assert!(
            tasks
                .notes
                .iter()
                .any(|n| n.contains("Tasks labels taken as they are"))
        );
    }

    /// Genuine MediaPipe 0.10.21 output (`tests-data/mediapipe/dump_mediapipe.py`) on two
    /// synthetic photos of `bitt synth`, in both APIs' layouts: read by default, every hand
    /// lands on its true side (the scenes' true wrists, from their `scene.json`, within 30 px).
    /// The two APIs give opposite labels to the same hand.
    #[test]
    fn genuine_mediapipe_layouts_give_the_true_sides() {
        let opts = KeypointOptions {
            image_size: [256, 256],
            ..options(None)
        };
        let cases: [(&str, [Option<[f64; 2]>; 2]); 4] = [
            (
                include_str!("../tests-data/mediapipe/synth000_tasks.json"),
                [None, Some([127.6, 59.7])],
            ),
            (
                include_str!("../tests-data/mediapipe/synth000_legacy.json"),
                [None, Some([127.6, 59.7])],
            ),
            (
                include_str!("../tests-data/mediapipe/synth005_tasks.json"),
                [Some([204.5, 101.4]), Some([155.3, 56.5])],
            ),
            (
                include_str!("../tests-data/mediapipe/synth005_legacy.json"),
                [None, Some([155.3, 56.5])],
            ),
        ];
        for (i, (text, wrists)) in cases.iter().enumerate() {
            let k = read_ok(text, &opts);
            for (side, wrist) in Side::BOTH.into_iter().zip(wrists) {
                match (k.hand(side), wrist) {
                    (None, None) => {}
                    (Some(p), Some([x, y])) => {
                        let d = (p[0].x - x).hypot(p[0].y - y);
                        assert!(d < 30.0, "case {i} {side}: wrist {d:.1} px off");
                    }
                    (got, want) => panic!("case {i} {side}: {got:?} vs {want:?}"),
                }
            }
        }
    }

    #[test]
    fn mediapipe_one_hand_and_none() {
        let one = r#"{"handedness": [[{"index": 0, "score": 0.9, "display_name": "", "category_name": "Left"}]],
            "hand_landmarks": [[LMS]], "hand_world_landmarks": [[]]}"#;
        let lms = vec![r#"{"x": 0.5, "y": 0.25, "z": 0.0}"#; 21].join(", ");
        let k = read_ok(&one.replace("LMS", &lms), &options(None));
        assert!(k.right.is_none());
        assert_eq!(
            k.hand(Side::Left).unwrap()[0],
            Keypoint {
                x: 319.5,
                y: 119.5,
                confidence: 1.0
            }
        );
        assert!(k.notes.iter().any(|n| n == "no right hand in the file"));
        // A label only in display_name is used.
        let display = one.replace("LMS", &lms).replace(
            r#""display_name": "", "category_name": "Left""#,
            r#""display_name": "Right", "category_name": """#,
        );
        assert!(read_ok(&display, &options(None)).left.is_none());
        // No hand at all.
        let none = r#"{"handedness": [], "hand_landmarks": [], "hand_world_landmarks": []}"#;
        error(none.as_bytes(), &options(None), &["no hand in the file"]);
        let legacy_none = r#"{"multi_handedness": null, "multi_hand_landmarks": null}"#;
        error(
            legacy_none.as_bytes(),
            &options(None),
            &["no hand in the file"],
        );
        // MediaPipe needs the image size.
        let no_size = KeypointOptions::default();
        error(
            one.replace("LMS", &lms).as_bytes(),
            &no_size,
            &["hand_landmarks", "image size"],
        );
    }

    #[test]
    fn openpose_people_and_missing_hands() {
        let person = openpose_person(&truth(Side::Left), &truth(Side::Right));
        let two = format!("{{\"version\":1.3,\"people\":[{person},{person}]}}");
        let k = read_ok(&two, &options(None));
        assert!(
            k.notes
                .iter()
                .any(|n| n == "2 people in the file, using people[0]")
        );
        // An empty and an all-zero hand are missing hands.
        let zeros = numbers(&[0.0; 63]);
        let one_hand = openpose_fixture().replacen(
            &format!(
                "\"hand_right_keypoints_2d\":[{}]",
                openpose_person(&truth(Side::Left), &truth(Side::Right))
                    .split("\"hand_right_keypoints_2d\":[")
                    .nth(1)
                    .unwrap()
                    .split(']')
                    .next()
                    .unwrap()
            ),
            &format!("\"hand_right_keypoints_2d\":[{zeros}]"),
            1,
        );
        let k = read_ok(&one_hand, &options(None));
        assert!(k.right.is_none() && k.left.is_some());
        assert_eq!(k.num_present(Side::Right), 0);
        let no_hands = r#"{"version":1.3,"people":[{"person_id":[-1],"pose_keypoints_2d":[],
            "hand_left_keypoints_2d":[],"hand_right_keypoints_2d":[]}]}"#;
        error(
            no_hands.as_bytes(),
            &options(None),
            &["no hand in the file"],
        );
    }

    #[test]
    fn guessing() {
        let guess = |text: &str| guess_format(&serde_json::from_str(text).unwrap());
        assert_eq!(guess(&openpose_fixture()), Some(KeypointFormat::OpenPose));
        assert_eq!(
            guess(&mediapipe_python_fixture()),
            Some(KeypointFormat::MediaPipe)
        );
        assert_eq!(
            guess(&mediapipe_js_fixture(false, true)),
            Some(KeypointFormat::MediaPipe)
        );
        assert_eq!(
            guess(&mediapipe_legacy_fixture()),
            Some(KeypointFormat::MediaPipe)
        );
        assert_eq!(guess(&plain_fixture()), Some(KeypointFormat::Plain));
        assert_eq!(guess(r#"{"right": null}"#), Some(KeypointFormat::Plain));
        assert_eq!(guess(r#"{"scene": 1}"#), None);
        assert_eq!(guess("[1, 2]"), None);
        assert_eq!(guess("null"), None);
        error(
            br#"{"scene": 1}"#,
            &options(None),
            &["cannot tell the format", "give --format"],
        );
        error(b"[]", &options(None), &["cannot tell the format"]);
        // A given format that does not match names the field it expected.
        error(
            openpose_fixture().as_bytes(),
            &options(Some(KeypointFormat::Plain)),
            &["left, right: missing", "looks like openpose"],
        );
        error(
            plain_fixture().as_bytes(),
            &options(Some(KeypointFormat::OpenPose)),
            &["people: missing"],
        );
        error(
            plain_fixture().as_bytes(),
            &options(Some(KeypointFormat::MediaPipe)),
            &["hand_landmarks: missing"],
        );
        error(
            b"[1]",
            &options(Some(KeypointFormat::OpenPose)),
            &["expected a JSON object", "people"],
        );
    }

    #[test]
    fn format_names() {
        for f in KeypointFormat::ALL {
            assert_eq!(f.to_string().parse::<KeypointFormat>(), Ok(f));
            assert_eq!(serde_json::to_string(&f).unwrap(), format!("\"{f}\""));
        }
        assert_eq!("OpenPose".parse(), Ok(KeypointFormat::OpenPose));
        assert_eq!("MEDIAPIPE".parse(), Ok(KeypointFormat::MediaPipe));
        assert!(
            "json"
                .parse::<KeypointFormat>()
                .unwrap_err()
                .contains("openpose")
        );
    }

    #[test]
    fn count_errors() {
        let short = edited(&openpose_fixture(), |v| {
            v["people"][0]["hand_left_keypoints_2d"]
                .as_array_mut()
                .unwrap()
                .pop();
        });
        error(
            short.as_bytes(),
            &options(None),
            &[
                "people[0].hand_left_keypoints_2d: 62 numbers, expected 63 (x, y, confidence for 21 points)",
            ],
        );
        let twenty = edited(&mediapipe_python_fixture(), |v| {
            v["hand_landmarks"][1].as_array_mut().unwrap().pop();
        });
        error(
            twenty.as_bytes(),
            &options(None),
            &["hand_landmarks[1]: 20 landmarks, expected 21"],
        );
        let twenty = edited(&plain_fixture(), |v| {
            v["left"].as_array_mut().unwrap().pop();
        });
        error(
            twenty.as_bytes(),
            &options(None),
            &["left: 20 points, expected 21"],
        );

        error(
            br#"{"left": [[1, 2, 0.5, 7]]}"#,
            &options(None),
            &["left: 1 points, expected 21"],
        );
        let point4 = vec!["[1, 2, 0.5, 7]"; 21].join(", ");
        error(
            format!("{{\"left\": [{point4}]}}").as_bytes(),
            &options(None),
            &["left[0]: 4 numbers, expected [x, y] or [x, y, confidence]"],
        );

        // Handedness and landmark counts disagree; too many hands.
        let one_label = edited(&mediapipe_js_fixture(false, false), |v| {
            v["handedness"].as_array_mut().unwrap().pop();
        });
        error(
            one_label.as_bytes(),
            &options(None),
            &["handedness: 1 entries for 2 hands in landmarks"],
        );
        let lms = vec![r#"{"x": 0.5, "y": 0.25, "z": 0.0}"#; 21].join(", ");
        let cat = r#"[{"index": 0, "score": 0.9, "display_name": "", "category_name": "Left"}]"#;
        let three = format!(
            "{{\"handedness\": [{cat}, {cat}, {cat}], \"hand_landmarks\": [[{lms}], [{lms}], [{lms}]]}}"
        );
        error(
            three.as_bytes(),
            &options(None),
            &["hand_landmarks: 3 hands, expected at most 2"],
        );
    }

    #[test]
    fn value_errors() {
        let nulled = edited(&plain_fixture(), |v| v["right"][3][1] = Value::Null);
        error(
            nulled.as_bytes(),
            &options(None),
            &["right[3][1]: not a finite number (found null)"],
        );
        let stringed = edited(&plain_fixture(), |v| v["right"][3][1] = "12.5".into());
        error(
            stringed.as_bytes(),
            &options(None),
            &["right[3][1]: not a finite number (found the string \"12.5\")"],
        );
        let nulled = edited(&openpose_fixture(), |v| {
            v["people"][0]["hand_right_keypoints_2d"][0] = Value::Null
        });
        error(
            nulled.as_bytes(),
            &options(None),
            &["people[0].hand_right_keypoints_2d[0]: not a finite number (found null)"],
        );
        let py = mediapipe_python_fixture();
        let nulled = edited(&py, |v| v["hand_landmarks"][0][0]["x"] = Value::Null);
        error(
            nulled.as_bytes(),
            &options(None),
            &["hand_landmarks[0][0].x: not a finite number (found null)"],
        );
        let no_y = py.replacen(", \"y\": ", ", \"why\": ", 1);
        error(
            no_y.as_bytes(),
            &options(None),
            &["hand_landmarks[0][0].y: missing"],
        );

        // Both labelled the same, an unknown label.
        let same = py.replace(
            "\"category_name\": \"Right\"",
            "\"category_name\": \"Left\"",
        );
        error(
            same.as_bytes(),
            &options(None),
            &[
                "handedness: both hands are labelled Left",
                "fix one label or use the plain format",
            ],
        );
        let odd = py.replace("\"category_name\": \"Right\"", "\"category_name\": \"Up\"");
        error(
            odd.as_bytes(),
            &options(None),
            &["handedness[0][0].category_name: \"Up\", expected Left or Right"],
        );

        // Negative confidence, points far outside the image.
        let negative = vec!["[1, 2, -0.5]"; 21].join(", ");
        error(
            format!("{{\"left\": [{negative}]}}").as_bytes(),
            &options(None),
            &["left[0][2]: confidence -0.5 is negative"],
        );
        let far = vec!["[1, 2]"; 20].join(", ") + ", [5000, 2]";
        let far = format!("{{\"right\": [{far}]}}");
        error(
            far.as_bytes(),
            &options(None),
            &["right[20][0]: x = 5000 px is not in pixels of a 640x480 image"],
        );
        // Unknown size: no bounds check. A cut-off point just outside the image is fine.
        assert!(read(&far, &KeypointOptions::default()).is_ok());
        let near = vec!["[-30.5, 490]"; 21].join(", ");
        assert!(read(&format!("{{\"right\": [{near}]}}"), &options(None)).is_ok());
        let big = py.replacen("\"y\": ", "\"y\": 2.5, \"old_y\": ", 1);
        error(
            big.as_bytes(),
            &options(None),
            &["hand_landmarks[0][0].y: 2.5 is not a normalised"],
        );

        // Empty people, wrong types.
        error(
            br#"{"version":1.3,"people":[]}"#,
            &options(None),
            &["people: empty, no person"],
        );
        error(
            br#"{"people":"abc"}"#,
            &options(None),
            &["people: expected an array, found a string"],
        );
        error(
            br#"{"people":[3]}"#,
            &options(None),
            &["people[0]: expected an object, found a number"],
        );
        error(
            br#"{"people":[{"hand_left_keypoints_2d":"abc"}]}"#,
            &options(None),
            &["people[0].hand_left_keypoints_2d: expected an array, found a string"],
        );
        error(
            br#"{"left":"abc"}"#,
            &options(None),
            &["left: expected an array, found a string"],
        );
        error(
            format!("{{\"left\": [{}]}}", vec!["7"; 21].join(",")).as_bytes(),
            &options(None),
            &["left[0]: expected an array, found a number"],
        );
        error(
            br#"{"hand_landmarks": {"a": 1}, "handedness": []}"#,
            &options(None),
            &["hand_landmarks: expected an array, found an object"],
        );
        error(
            br#"{"hand_landmarks": [[1]], "handedness": [[{}]]}"#,
            &options(None),
            &["handedness[0][0]: no category_name"],
        );
        error(
            br#"{"hand_landmarks": [7], "handedness": [[{"category_name": "Left"}]]}"#,
            &options(None),
            &["hand_landmarks[0]: expected an array of landmarks, found a number"],
        );
        error(
            br#"{"hand_landmarks": [[]], "handedness": ["Left"]}"#,
            &options(None),
            &["handedness[0]: expected an array of categories, found a string"],
        );
        error(
            br#"{"hand_landmarks": []}"#,
            &options(None),
            &["handedness: missing"],
        );
        error(
            br#"{"left": null, "right": null}"#,
            &options(None),
            &["no hand in the file"],
        );
    }

    #[test]
    fn broken_files() {
        let op = openpose_fixture();
        error(
            &op.as_bytes()[..op.len() / 2],
            &options(None),
            &["not JSON: ", "line 1 column"],
        );
        error(b"", &options(None), &["not JSON: the file is empty"]);
        error(b"  \n", &options(None), &["not JSON: the file is empty"]);
        error(
            b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR",
            &options(None),
            &["not JSON: "],
        );
        let deep = "[".repeat(100_000);
        error(deep.as_bytes(), &options(None), &["not JSON: "]);
        // A byte-order mark is fine.
        let bom = [b"\xEF\xBB\xBF".as_slice(), plain_fixture().as_bytes()].concat();
        assert!(parse_keypoints(&bom, &path(), &options(None)).is_ok());

        let missing = Path::new("/nonexistent/dir/keypoints.json");
        let e = read_keypoints(missing, &options(None)).unwrap_err();
        assert!(matches!(
            e,
            MeshError::File(bitt_stdx::FileError::Io { .. })
        ));
        assert!(
            e.to_string().contains("/nonexistent/dir/keypoints.json"),
            "{e}"
        );
    }

    #[test]
    fn fuzz_never_panics() {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let fixtures = [
            openpose_fixture(),
            mediapipe_python_fixture(),
            mediapipe_js_fixture(true, false),
            mediapipe_legacy_fixture(),
            plain_fixture(),
        ];
        let opts = [
            options(None),
            KeypointOptions::default(),
            KeypointOptions {
                labels_as_is: true,
                ..options(Some(KeypointFormat::MediaPipe))
            },
        ];
        let check = |bytes: &[u8], next: &mut dyn FnMut() -> u64| {
            let o = &opts[(next() % 3) as usize];
            if let Err(e) = parse_keypoints(bytes, &path(), o) {
                assert!(
                    e.to_string()
                        .starts_with("/data/photo_0001_keypoints.json: "),
                    "{e}"
                );
            }
        };
        for text in &fixtures {
            let bytes = text.as_bytes();
            // Truncations.
            for len in (0..bytes.len()).step_by(13) {
                check(&bytes[..len], &mut next);
            }
            // Byte mutations, favouring JSON punctuation and numbers.
            const SPICE: &[u8] = b"[]{}\",:-0123456789.eEnul \xff";
            for _ in 0..400 {
                let mut m = bytes.to_vec();
                for _ in 0..1 + next() % 4 {
                    let at = (next() % m.len() as u64) as usize;
                    m[at] = if next() % 2 == 0 {
                        SPICE[(next() % SPICE.len() as u64) as usize]
                    } else {
                        next() as u8
                    };
                }
                check(&m, &mut next);
            }
        }
        // Random bytes.
        for _ in 0..300 {
            let len = (next() % 200) as usize;
            let m: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            check(&m, &mut next);
        }
        // Valid JSON of wrong types everywhere.
        let wrong = [
            "null",
            "true",
            "1",
            "\"x\"",
            "[]",
            "{}",
            "[[1]]",
            "{\"a\": {}}",
            "-1e308",
        ];
        for key in [
            "people",
            "hand_landmarks",
            "handedness",
            "left",
            "right",
            "multi_hand_landmarks",
        ] {
            for w in wrong {
                check(format!("{{\"{key}\": {w}}}").as_bytes(), &mut next);
                check(format!("{{\"{key}\": [{w}, {w}]}}").as_bytes(), &mut next);
                check(format!("{{\"{key}\": [[{w}]]}}").as_bytes(), &mut next);
                check(
                    format!(
                        "{{\"people\": [{{\"hand_left_keypoints_2d\": [{w}]}}], \"{key}\": {w}}}"
                    )
                    .as_bytes(),
                    &mut next,
                );
            }
        }
    }

    #[test]
    fn numbers_are_read_exactly() {
        // serde_json's default parser reads this one unit in the last place off.
        let text = "489.87450429153523";
        let v = parse_json(format!("[{text}, -1, 2e-3, 1E+2, 0]").as_bytes()).unwrap();
        let want = [text.parse::<f64>().unwrap(), -1.0, 2e-3, 100.0, 0.0];
        let got: Vec<f64> = v
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(got, want);
        // Strings holding digits, minus signs and escaped quotes are left alone.
        let v = parse_json(br#"{"a\"-1": "x\"-2 3e5\\", "b": [-0.5]}"#).unwrap();
        assert_eq!(v["a\"-1"], Value::String("x\"-2 3e5\\".into()));
        assert_eq!(v["b"][0].as_f64(), Some(-0.5));
        // A number too large for f64 is not a number.
        let huge = vec!["[1e400, 2]"; 21].join(", ");
        let e = parse_keypoints(
            format!("{{\"left\": [{huge}]}}").as_bytes(),
            &path(),
            &options(None),
        );
        let message = e.unwrap_err().to_string();
        assert!(
            message.contains("left[0][0]") || message.contains("not JSON"),
            "{message}"
        );
        // ... and is named as a number, not as a string (issue 38, class 10).
        assert!(
            message.contains("left[0][0]")
                && message.contains("the number 1e400, too large")
                && !message.contains("string"),
            "{message}"
        );
    }

    #[test]
    fn plain_json_round_trips() {
        for text in [
            openpose_fixture(),
            mediapipe_python_fixture(),
            plain_fixture(),
        ] {
            let k = read_ok(&text, &options(None));
            let json = k.to_plain_json();
            let back = read_ok(&json, &options(Some(KeypointFormat::Plain)));
            assert_eq!(back.format, KeypointFormat::Plain);
            assert_eq!(back.left, k.left);
            assert_eq!(back.right, k.right);
            assert_eq!(
                guess_format(&serde_json::from_str(&json).unwrap()),
                Some(KeypointFormat::Plain)
            );
        }
        // A missing hand is written as null.
        let one = TwoHandKeypoints {
            left: None,
            right: Some(vec![
                Keypoint {
                    x: 0.1,
                    y: 1e-300,
                    confidence: 1.0 / 3.0
                };
                NUM_KEYPOINTS
            ]),
            format: KeypointFormat::MediaPipe,
            notes: vec!["a note".into()],
        };
        let json = one.to_plain_json();
        assert!(json.contains("\"left\": null"));
        let back = read_ok(&json, &KeypointOptions::default());
        assert_eq!(back.right, one.right);
        assert!(back.left.is_none());
    }

    #[test]
    fn mirrored_and_scaled() {
        let k = read_ok(&openpose_fixture(), &options(None));
        let m = k.mirrored(f64::from(W));
        assert_eq!(m.left.as_ref().unwrap().len(), NUM_KEYPOINTS);
        let (l, r) = (k.hand(Side::Left).unwrap(), m.hand(Side::Right).unwrap());
        assert_eq!(r[3].x, f64::from(W) - 1.0 - l[3].x);
        assert_eq!(r[3].y, l[3].y);
        assert_eq!(r[3].confidence, l[3].confidence);
        assert_eq!(m.num_present(Side::Right), k.num_present(Side::Left));
        let twice = m.mirrored(f64::from(W));
        assert_eq!(twice.format, k.format);
        assert_eq!(twice.notes, k.notes);
        for side in Side::BOTH {
            for (a, b) in twice.hand(side).unwrap().iter().zip(k.hand(side).unwrap()) {
                assert!((a.x - b.x).abs() < 1e-9 && a.y == b.y && a.confidence == b.confidence);
            }
        }
        // Exact for coordinates representable on the grid of the width.
        let exact = TwoHandKeypoints {
            left: Some(vec![
                Keypoint {
                    x: 12.25,
                    y: 3.0,
                    confidence: 0.5
                };
                NUM_KEYPOINTS
            ]),
            right: None,
            format: KeypointFormat::Plain,
            notes: Vec::new(),
        };
        assert_eq!(exact.mirrored(640.0).mirrored(640.0), exact);
        assert_eq!(exact.mirrored(640.0).right.unwrap()[0].x, 626.75);

        let s = k.scaled(0.5, 2.0);
        for side in Side::BOTH {
            for (a, b) in s.hand(side).unwrap().iter().zip(k.hand(side).unwrap()) {
                assert_eq!(
                    (a.x, a.y, a.confidence),
                    (
                        (b.x + 0.5) * 0.5 - 0.5,
                        (b.y + 0.5) * 2.0 - 0.5,
                        b.confidence
                    )
                );
            }
        }
        assert_eq!(k.scaled(1.0, 1.0), k);
    }
}
