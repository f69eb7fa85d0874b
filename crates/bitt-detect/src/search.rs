//! The two-hand search: MediaPipe's palm → landmark pipeline finds one of two interlocked
//! hands; this search keeps looking until it has one hand of each side or has run out of
//! places to look, and says what each stage found (`docs/detection.md`).
//!
//! Stages, each run only while a hand is missing:
//! 1. **palms**: the palm detector on the letterboxed photo and on overlapping crops of it
//!    (a hand that is small in the photo is larger in a crop), every palm scoring at least
//!    [`SearchConfig::min_palm_score`];
//! 2. **landmarks**: the landmark model on each palm's hand rectangle, then again on the
//!    rectangle its own landmarks give (MediaPipe's tracking step) until it settles;
//! 3. **masked**: with the hands found so far painted black, the palm detector again: a hand
//!    hidden behind a more confident one becomes the best palm;
//! 3. (b) **whole**: with no hand found yet, the landmark model on centred squares of the
//!    whole photo, at four quarter turns, then the tracking steps;
//! 4. **ring**: hand rectangles around each found hand (the other hand of a pair touches it),
//!    at several rotations and sizes, scored by the landmark model's presence;
//! 5. **look**: with one hand found, the landmark model where the hypothesis places the
//!    other one, starting from each reading of the found hand (crops of one hand can read
//!    left and right); a reading apart from the found hand is taken as the other hand. The two
//!    hands' sides are then the more likely of the two opposite assignments: a confident
//!    reading can relabel the found hand. Otherwise the hypothesis itself is placed
//!    (presence 0).
//!
//! Candidates that lie on the same hand are merged; the two hands are then the pair of
//! distinct hands that maximises presence times the probability of each one's side, with
//! the two sides different, their wrists half a palm apart and their sizes alike.

use std::time::Instant;

use bitt_mesh::Side;
use bitt_mesh::keypoints::{Keypoint, KeypointFormat, TwoHandKeypoints};
use image::RgbImage;

use crate::crop::{Rect, normalize_angle, rotation_to_up};
use crate::detector::{HandDetector, HandLandmarks};
use crate::palm::{Palm, letterbox, weighted_nms};
use crate::{DetectError, NUM_LANDMARKS};

/// Settings of the search (defaults measured on the demo frames, `docs/detection.md`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SearchConfig {
    /// Palms scoring below this are dropped (MediaPipe's default is 0.5; interlocked hands
    /// score far lower).
    pub min_palm_score: f64,
    /// A hand needs at least this landmark presence (MediaPipe's default).
    pub min_presence: f64,
    /// Tracking steps of the landmark model per candidate (rectangle from landmarks, again).
    pub tracking_steps: usize,
    /// Run the masked second palm pass.
    pub masked_pass: bool,
    /// When no stage before it found a hand, run the landmark model on the whole photo:
    /// centred squares of its long side and of 0.75 of it, upright and turned by 90, 180 and
    /// 270 degrees, each followed by the tracking steps (stage `whole`). BiTT's photos are
    /// of two hands that fill the frame; in noisy or heavily compressed copies of the demo
    /// frames the palm detector scores their palms under 0.1 (0.055 in `01` saved as a
    /// JPEG of quality 25) while the landmark model still reads them.
    #[serde(default = "yes")]
    pub whole_photo: bool,
    /// Run the ring of hand rectangles around a found hand (off by default: on the demo
    /// frames it costs 2.4 s and finds no hand the other stages miss; `docs/detection.md`).
    pub ring: bool,
    /// Rotations of the ring's rectangles (degrees, relative to the found hand's).
    pub ring_rotations: Vec<f64>,
    /// The smallest hand (diagonal of its landmarks' box) as a fraction of the photo's long
    /// side; smaller candidates are specks of light, not hands. Never below 16 px.
    pub min_hand_size: f64,
    /// The most palms (best first) whose hands the landmark model looks at, per stage.
    pub max_palms: usize,
    /// When exactly one hand is found, place the other one by hypothesis (stage
    /// `hypothesis`, presence 0): interlocked, the mirror image of the found hand about its
    /// own wrist-to-middle-finger axis, shifted along that axis by
    /// [`SearchConfig::hypothesis_shift`] palm lengths. Its keypoints are a starting point for
    /// the fit and the refinement against the photo, not a detection.
    pub hypothesis: bool,
    /// See [`SearchConfig::hypothesis`].
    pub hypothesis_shift: f64,
    /// With one hand found, run the landmark model on the rectangle of the hypothesis (at
    /// 0.8, 1 and 1.25 of its size) before placing it: a reading whose wrist lies at least
    /// a third of a palm from the found hand's, and that could pair with it (wrists half a
    /// palm apart or points half a palm apart on average), becomes the other hand (stage
    /// `look`). It starts from every reading of the found hand. The
    /// two hands take opposite sides, whichever assignment has the higher product of the
    /// two side probabilities (`look_sides`); the reading's side needs at least
    /// [`SearchConfig::look_min_side`].
    #[serde(default = "yes")]
    pub look: bool,
    /// See [`SearchConfig::look`].
    #[serde(default = "look_min_side_default")]
    pub look_min_side: f64,
    /// The hypothesis' size relative to the found hand (about its wrist): the found hand's
    /// wrist landmark tends to sit on the forearm when the other hand hides the palm.
    pub hypothesis_scale: f64,
    /// In the choice of the pair, a hand smaller than this fraction of the largest hand's
    /// size (the diagonal of its landmarks' box) counts in proportion to its size: a crop
    /// collapsed onto a few fingertips is weak evidence of a hand and its side. Not a hard
    /// limit, because a hand cut by the border down to its fingertips is such a crop too,
    /// and the only evidence of that hand. Measured on the demo frames' copies: true pairs
    /// 0.47-0.88 (an occluded hand shows little more than its fingers), collapsed crops
    /// 0.32-0.34.
    #[serde(default = "full_weight_size_default")]
    pub full_weight_size: f64,
}

fn full_weight_size_default() -> f64 {
    0.5
}

fn yes() -> bool {
    true
}

fn look_min_side_default() -> f64 {
    0.7
}

impl Default for SearchConfig {
    fn default() -> Self {
        SearchConfig {
            min_palm_score: 0.1,
            min_presence: 0.5,
            tracking_steps: 2,
            masked_pass: true,
            whole_photo: true,
            ring: false,
            ring_rotations: vec![0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0],
            min_hand_size: 0.08,
            max_palms: 8,
            hypothesis: true,
            hypothesis_shift: 0.8,
            look: true,
            look_min_side: look_min_side_default(),
            hypothesis_scale: 0.75,
            full_weight_size: full_weight_size_default(),
        }
    }
}

/// One hand the search settled on.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetectedHand {
    /// The hand as it appears in the photo (the model that fits it).
    pub side: Side,
    /// 21 points `[x, y, z]` in the project's pixel convention (centre of the top-left pixel
    /// at `(0, 0)`), OpenPose order.
    pub points: Vec<[f64; 3]>,
    /// The landmark model's presence score.
    pub presence: f64,
    /// The probability the landmark model gives to this hand's side.
    pub side_probability: f64,
    /// The palm detector's score of the palm it started from (`None` for the ring stage).
    pub palm_score: Option<f64>,
    /// The stage that found it: `palms`, `masked`, `whole`, `ring`, `look` or `hypothesis`.
    pub stage: String,
    /// The crop the final landmarks came from.
    pub rect: Rect,
}

/// What one stage of the search did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageReport {
    /// `palms`, `masked`, `whole`, `ring`, `look` or `hypothesis`.
    pub stage: String,
    /// Palm detector inputs run.
    pub palm_runs: usize,
    /// Landmark model inputs run.
    pub landmark_runs: usize,
    /// Distinct hands with enough presence after the stage.
    pub hands: usize,
    /// Seconds.
    pub seconds: f64,
}

/// The search's result: up to one hand per side, and what it took.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TwoHandDetection {
    /// `[width, height]` of the photo.
    pub image_size: [u32; 2],
    /// The left hand as it appears in the photo.
    pub left: Option<DetectedHand>,
    /// The right hand.
    pub right: Option<DetectedHand>,
    /// The stages run, in order.
    pub stages: Vec<StageReport>,
    /// The highest presence of any candidate (for the "no hand" message).
    pub best_presence: f64,
    /// The settings used.
    pub config: SearchConfig,
}

/// A landmark candidate with where it came from.
#[derive(Debug, Clone)]
struct Candidate {
    hand: HandLandmarks,
    /// The side of the crop the candidate was first found in.
    first_crop: f64,
    palm_score: Option<f64>,
    stage: &'static str,
}

impl Candidate {
    /// Hand size: the diagonal of the landmarks' box.
    fn size(&self) -> f64 {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &self.hand.points {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2)).sqrt()
    }

    /// Palm length: wrist to the middle finger's base.
    fn palm_length(&self) -> f64 {
        let p = &self.hand.points;
        ((p[0][0] - p[9][0]).powi(2) + (p[0][1] - p[9][1]).powi(2)).sqrt()
    }

    /// Whether the landmarks look like a hand rather than a collapsed blob: they span at
    /// least a fifth of the crop they were found in (a hand fills about half of its crop)
    /// and [`SearchConfig::min_hand_size`] of the photo's long side.
    fn plausible(&self, min_size: f64) -> bool {
        let size = self.size();
        size >= 0.2 * self.first_crop && size >= min_size
    }

    /// Distance between two candidates' wrists (pixels).
    fn wrist_distance(&self, other: &Candidate) -> f64 {
        let (a, b) = (&self.hand.points[0], &other.hand.points[0]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
    }

    /// Whether two candidates cannot be the two hands of a pair: their wrists are within
    /// half a palm length and their points within half of one on average (the landmark
    /// model sometimes calls the same hand left in one crop and right in another: on `01`
    /// rotated by 20 degrees such readings have wrists 0.38 palm apart, the demo frames'
    /// true pairs 0.66 or more).
    fn overlaps(&self, other: &Candidate) -> bool {
        let palm = self.palm_length().max(other.palm_length()).max(1.0);
        let (a, b) = (&self.hand.points, &other.hand.points);
        let wrist = self.wrist_distance(other);
        let mean: f64 = a
            .iter()
            .zip(b)
            .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt())
            .sum::<f64>()
            / NUM_LANDMARKS as f64;
        wrist < palm / 2.0 && mean < palm * 0.5
    }

    /// Presence times the probability of `side`.
    fn side_score(&self, side: Side) -> f64 {
        self.hand.presence
            * match side {
                Side::Right => self.hand.right,
                Side::Left => 1.0 - self.hand.right,
            }
    }

    /// The weight of this candidate's evidence next to a hand of size `largest`: 1 from
    /// `full` of that size up, in proportion to its size below (see
    /// [`SearchConfig::full_weight_size`]).
    fn size_weight(&self, largest: f64, full: f64) -> f64 {
        if largest <= 0.0 {
            return 1.0;
        }
        (self.size() / (full * largest)).min(1.0)
    }

    /// Whether two candidates lie on the same hand: their points' mean distance is under
    /// half a palm length, and the landmark model does not say confidently that they are
    /// hands of different sides (two interlocked hands overlap that much); or the points
    /// nearly coincide.
    fn same_hand(&self, other: &Candidate) -> bool {
        let palm = self.palm_length().max(other.palm_length()).max(1.0);
        let mean: f64 = self
            .hand
            .points
            .iter()
            .zip(&other.hand.points)
            .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
            .sum::<f64>()
            / NUM_LANDMARKS as f64;
        let confident = |r: f64| !(0.3..=0.7).contains(&r);
        let opposite = confident(self.hand.right)
            && confident(other.hand.right)
            && (self.hand.right > 0.5) != (other.hand.right > 0.5);
        mean < palm * 0.15 || (!opposite && mean < palm * 0.5)
    }
}

/// The hand rectangle from landmarks (MediaPipe's `hand_landmark_landmarks_to_roi`: rotation
/// from the wrist towards the middle of the index/ring and middle finger bases, the box in
/// that rotation, scale 2.0, shift_y -0.1).
pub(crate) fn rect_from_landmarks(points: &[[f64; 3]]) -> Rect {
    let p = |i: usize| [points[i][0], points[i][1]];
    let mid = |a: [f64; 2], b: [f64; 2]| [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
    let base = mid(mid(p(5), p(13)), p(9));
    let rotation = rotation_to_up(p(0), base);
    let pts: Vec<[f64; 2]> = points.iter().map(|q| [q[0], q[1]]).collect();
    Rect::bounding(&pts, rotation).transformed(2.0, [0.0, -0.1])
}

/// Overlapping views of the photo for the palm detector: the letterboxed photo, and for a
/// photo at least 512 px on its long side (where a hand may be small at the detector's 192
/// px), a 3 x 3 grid of square crops of half the long side.
fn palm_views(width: u32, height: u32) -> Vec<Rect> {
    let mut views = vec![letterbox(width, height)];
    let long = width.max(height) as f64;
    if long >= 512.0 {
        let side = long / 2.0;
        for j in 0..3 {
            for i in 0..3 {
                let cx = side / 2.0 + (width as f64 - side).max(0.0) * i as f64 / 2.0;
                let cy = side / 2.0 + (height as f64 - side).max(0.0) * j as f64 / 2.0;
                views.push(Rect {
                    center: [cx, cy],
                    size: [side, side],
                    rotation: 0.0,
                });
            }
        }
    }
    views
}

/// Searches `image` for two hands with `detector`.
///
/// Returns whatever it found (zero, one or two hands); [`TwoHandDetection::require_both`]
/// turns a missing hand into the error a user should see.
///
/// # Errors
/// An image too small to hold a hand (under 16 px), or a failed readback.
pub fn detect_hands(
    detector: &HandDetector,
    image: &RgbImage,
    config: &SearchConfig,
) -> Result<TwoHandDetection, DetectError> {
    let (w, h) = image.dimensions();
    if w < 16 || h < 16 {
        return Err(DetectError::Image {
            image: "the photo".into(),
            detail: format!("{w}x{h} pixels is too small to hold a hand (at least 16x16)"),
        });
    }
    let long = w.max(h) as f64;
    let mut candidates: Vec<Candidate> = Vec::new();
    let mut stages = Vec::new();

    // 1. palms, 2. landmarks
    let t = Instant::now();
    let views = palm_views(w, h);
    let palms = merge_palms(
        detector.palms(image, &views, config.min_palm_score)?,
        config,
        long,
    );
    let mut runs = 0;
    candidates.extend(track(detector, image, &palms, "palms", config, &mut runs)?);
    stages.push(report(
        long,
        "palms",
        views.len(),
        runs,
        &candidates,
        config,
        t,
    ));

    // 3. masked
    if config.masked_pass && pick(&candidates, config, long).missing() {
        let t = Instant::now();
        let mut masked = image.clone();
        for c in candidates
            .iter()
            .filter(|c| c.hand.presence >= config.min_presence)
        {
            paint_hand(&mut masked, &c.hand.points);
        }
        let palms = merge_palms(
            detector.palms(&masked, &views, config.min_palm_score)?,
            config,
            long,
        );
        let mut runs = 0;
        // Landmarks on the original photo: the mask only steers where to look.
        candidates.extend(track(detector, image, &palms, "masked", config, &mut runs)?);
        stages.push(report(
            long,
            "masked",
            views.len(),
            runs,
            &candidates,
            config,
            t,
        ));
    }

    // 3b. whole
    if config.whole_photo && distinct(&candidates, config, long).is_empty() {
        let t = Instant::now();
        let mut rects = Vec::new();
        for scale in [1.0, 0.75] {
            for quarter in 0..4 {
                rects.push(Rect {
                    center: [w as f64 / 2.0, h as f64 / 2.0],
                    size: [long * scale, long * scale],
                    rotation: normalize_angle(quarter as f64 * std::f64::consts::FRAC_PI_2),
                });
            }
        }
        let mut runs = 0;
        let min = config.min_presence;
        candidates.extend(read_tracked(
            detector, image, &rects, min, "whole", config, &mut runs,
        )?);
        stages.push(report(long, "whole", 0, runs, &candidates, config, t));
    }

    // 4. ring
    if config.ring && pick(&candidates, config, long).missing() {
        let t = Instant::now();
        let found: Vec<Candidate> = distinct(&candidates, config, long);
        let mut rects = Vec::new();
        for c in &found {
            let r = rect_from_landmarks(&c.hand.points);
            let step = r.size[0] * 0.25;
            for k in 0..5 {
                let a = r.rotation + k as f64 * std::f64::consts::FRAC_PI_2;
                let d = if k == 4 { 0.0 } else { step };
                for rot in &config.ring_rotations {
                    rects.push(Rect {
                        center: [r.center[0] + d * a.cos(), r.center[1] + d * a.sin()],
                        size: r.size,
                        rotation: normalize_angle(r.rotation + rot.to_radians()),
                    });
                }
            }
        }
        let mut runs = 0;
        let min = config.min_presence * 0.5;
        candidates.extend(read_tracked(
            detector, image, &rects, min, "ring", config, &mut runs,
        )?);
        stages.push(report(long, "ring", 0, runs, &candidates, config, t));
    }

    let best_presence = candidates
        .iter()
        .map(|c| c.hand.presence)
        .fold(0.0, f64::max);
    let mut chosen = pick(&candidates, config, long);
    // 5. look
    if config.look {
        let t = Instant::now();
        let mut runs = 0;
        let hands = distinct(&candidates, config, long);
        let looked = look_stage(&chosen, &hands, config, |source, missing| {
            look(detector, image, source, missing, config, long, &mut runs)
        })?;
        if let Some(looked) = looked {
            chosen = looked;
            stages.push(StageReport {
                stage: "look".into(),
                palm_runs: 0,
                landmark_runs: runs,
                hands: 1 + usize::from(!chosen.missing()),
                seconds: t.elapsed().as_secs_f64(),
            });
        }
    }
    if config.hypothesis {
        let t = Instant::now();
        let placed = match (&chosen.left, &chosen.right) {
            (Some(found), None) => Some((false, found)),
            (None, Some(found)) => Some((true, found)),
            _ => None,
        };
        if let Some((left_missing, found)) = placed {
            let other = hypothesis(found, config.hypothesis_shift, config.hypothesis_scale);
            if left_missing {
                chosen.left = Some(other);
            } else {
                chosen.right = Some(other);
            }
            stages.push(StageReport {
                stage: "hypothesis".into(),
                palm_runs: 0,
                landmark_runs: 0,
                hands: 2,
                seconds: t.elapsed().as_secs_f64(),
            });
        }
    }
    let to_hand = |c: &Candidate, side: Side| {
        let p_right = c.hand.right;
        DetectedHand {
            side,
            points: c
                .hand
                .points
                .iter()
                .map(|p| [p[0] - 0.5, p[1] - 0.5, p[2]])
                .collect(),
            presence: c.hand.presence,
            side_probability: if side == Side::Right {
                p_right
            } else {
                1.0 - p_right
            },
            palm_score: c.palm_score,
            stage: c.stage.to_string(),
            rect: c.hand.rect,
        }
    };
    Ok(TwoHandDetection {
        image_size: [w, h],
        left: chosen.left.map(|c| to_hand(&c, Side::Left)),
        right: chosen.right.map(|c| to_hand(&c, Side::Right)),
        stages,
        best_presence,
        config: config.clone(),
    })
}

/// Stage `look` around [`look`] (passed in as `look`, so the choice is testable without the
/// networks): with one hand chosen, look for the other; with two, look again for a hand in
/// place of one that is only a small crop (it weighs less than 1,
/// [`SearchConfig::full_weight_size`]), and keep whichever pair scores higher
/// ([`Chosen::score`]). The look starts from every reading of the found hand: the chosen
/// one, and any other of the distinct `hands` on the same place that the landmark model
/// reads as the other side (one hand read left in one crop and right in another;
/// [`Candidate::overlaps`]), each with its own side; the likeliest reading wins.
///
/// Returns the new choice, or `None` when the stage did not run.
fn look_stage(
    chosen: &Chosen,
    hands: &[Candidate],
    config: &SearchConfig,
    mut look: impl FnMut(&Candidate, Side) -> Result<Option<(f64, Candidate, Side)>, DetectError>,
) -> Result<Option<Chosen>, DetectError> {
    let largest = hands.iter().map(Candidate::size).fold(0.0, f64::max);
    let weak = |c: &Candidate| c.size_weight(largest, config.full_weight_size) < 1.0;
    let (missing, found) = match (&chosen.left, &chosen.right) {
        (Some(found), None) => (Side::Right, found),
        (None, Some(found)) => (Side::Left, found),
        (Some(l), Some(r)) if weak(r) && !weak(l) => (Side::Right, l),
        (Some(l), Some(r)) if weak(l) && !weak(r) => (Side::Left, r),
        _ => return Ok(None),
    };
    let mut sources = vec![(found.clone(), missing)];
    for c in hands {
        let side = if c.hand.right >= 0.5 {
            Side::Right
        } else {
            Side::Left
        };
        if side == missing && c.overlaps(found) {
            sources.push((c.clone(), side.mirrored()));
        }
    }
    let mut best: Option<(f64, Candidate, Candidate, Side)> = None;
    for (source, missing) in sources {
        if let Some((score, other, side)) = look(&source, missing)?
            && best.as_ref().is_none_or(|b| score > b.0)
        {
            best = Some((score, source, other, side));
        }
    }
    let Some((_, source, other, side)) = best else {
        return Ok(Some(chosen.clone()));
    };
    // `side` is the reading's; the hand it started from takes the other one.
    let looked = match side {
        Side::Left => Chosen {
            left: Some(other),
            right: Some(source),
        },
        Side::Right => Chosen {
            left: Some(source),
            right: Some(other),
        },
    };
    let full = config.full_weight_size;
    Ok(Some(
        if chosen.missing() || looked.score(largest, full) > chosen.score(largest, full) {
            looked
        } else {
            chosen.clone()
        },
    ))
}

/// The other hand of an interlocked pair, placed from the found one (see
/// [`SearchConfig::hypothesis`]): every point mirrored about the line from the wrist to the
/// middle finger's base, scaled by `k` about the wrist, then shifted along that line by
/// `shift` palm lengths. Its handedness is the
/// opposite of the found hand's, its presence 0.
fn hypothesis(found: &Candidate, shift: f64, k: f64) -> Candidate {
    let p = &found.hand.points;
    let (o, m) = ([p[0][0], p[0][1]], [p[9][0], p[9][1]]);
    let len = ((m[0] - o[0]).powi(2) + (m[1] - o[1]).powi(2))
        .sqrt()
        .max(1e-9);
    let d = [(m[0] - o[0]) / len, (m[1] - o[1]) / len];
    let points = p
        .iter()
        .map(|q| {
            let v = [q[0] - o[0], q[1] - o[1]];
            let along = v[0] * d[0] + v[1] * d[1];
            let across = [v[0] - along * d[0], v[1] - along * d[1]];
            [
                o[0] + (k * along + shift * len) * d[0] - k * across[0],
                o[1] + (k * along + shift * len) * d[1] - k * across[1],
                q[2],
            ]
        })
        .collect();
    Candidate {
        first_crop: found.first_crop,
        hand: HandLandmarks {
            rect: found.hand.rect,
            points,
            presence: 0.0,
            right: 1.0 - found.hand.right,
        },
        palm_score: None,
        stage: "hypothesis",
    }
}

/// Stage `look` ([`SearchConfig::look`]): the landmark model on the rectangle where the
/// hypothesis places the `missing` hand, at three sizes. No tracking step: it drifts onto
/// the found hand, which dominates such crops. Among the readings that look like a hand, are
/// hand-sized next to the found hand, have their wrist at least a third of a palm from the
/// found hand's and could pair with it (not [`Candidate::overlaps`]), each gets its side
/// from [`look_sides`]; the best (presence times the likelihood of its assignment) is the
/// other hand, returned with that score and its side.
fn look(
    detector: &HandDetector,
    image: &RgbImage,
    found: &Candidate,
    missing: Side,
    config: &SearchConfig,
    long: f64,
    runs: &mut usize,
) -> Result<Option<(f64, Candidate, Side)>, DetectError> {
    let placed = hypothesis(found, config.hypothesis_shift, config.hypothesis_scale);
    let r = rect_from_landmarks(&placed.hand.points);
    let rects: Vec<Rect> = [0.8, 1.0, 1.25]
        .iter()
        .map(|k| Rect {
            center: r.center,
            size: [r.size[0] * k, r.size[1] * k],
            rotation: r.rotation,
        })
        .collect();
    *runs += rects.len();
    let min_size = (config.min_hand_size * long).max(16.0);
    let palm = found.palm_length().max(1.0);
    let best = detector
        .landmarks(image, &rects)?
        .into_iter()
        .map(|hand| Candidate {
            first_crop: hand.rect.size[0],
            hand,
            palm_score: None,
            stage: "look",
        })
        .filter(|c| {
            c.hand.presence >= config.min_presence
                && c.plausible(min_size)
                && c.wrist_distance(found) >= palm / 3.0
                && !c.overlaps(found)
        })
        .filter_map(|c| {
            let (side, likelihood) = look_sides(
                found.hand.right,
                c.hand.right,
                missing,
                config.look_min_side,
            )?;
            Some((c.hand.presence * likelihood, c, side))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0));
    Ok(best)
}

/// The sides of a found hand (which the search calls the side opposite `missing`) and a
/// reading of the other hand, from each one's probability of being a right hand: the two
/// take opposite sides, and of the two assignments the one with the higher product of the
/// side probabilities wins (the landmark model reads each crop independently). Returns the
/// reading's side and that product, or `None` when the reading's side probability is
/// under `min_side`.
///
/// A reading can thereby relabel the found hand: on a copy of a demo frame enlarged 2.5
/// times, a crop of the right hand reads left (0.85) and the hidden left hand left too
/// (0.885); the right-left assignment (0.15 x 0.885) beats the left-right one
/// (0.85 x 0.115).
pub(crate) fn look_sides(
    found_right: f64,
    reading_right: f64,
    missing: Side,
    min_side: f64,
) -> Option<(Side, f64)> {
    let p = |right: f64, side: Side| match side {
        Side::Right => right,
        Side::Left => 1.0 - right,
    };
    let kept = missing.mirrored();
    let keep = p(found_right, kept) * p(reading_right, missing);
    let swap = p(found_right, missing) * p(reading_right, kept);
    let (side, likelihood) = if swap > keep {
        (kept, swap)
    } else {
        (missing, keep)
    };
    (p(reading_right, side) >= min_side).then_some((side, likelihood))
}

/// Palms of all views merged (the same palm seen in two views counts once), without boxes
/// too small to hold a hand of [`SearchConfig::min_hand_size`], best first, at most
/// [`SearchConfig::max_palms`].
fn merge_palms(per_view: Vec<Vec<Palm>>, config: &SearchConfig, long: f64) -> Vec<Palm> {
    let min_box = (config.min_hand_size * long).max(16.0) / 2.0;
    let mut palms = weighted_nms(per_view.into_iter().flatten().collect(), 0.3);
    palms.retain(|p| p.size[0].max(p.size[1]) >= min_box);
    palms.truncate(config.max_palms);
    palms
}

/// The landmark model on each palm's hand rectangle, then the tracking steps.
fn track(
    detector: &HandDetector,
    image: &RgbImage,
    palms: &[Palm],
    stage: &'static str,
    config: &SearchConfig,
    runs: &mut usize,
) -> Result<Vec<Candidate>, DetectError> {
    let rects: Vec<Rect> = palms.iter().map(Palm::hand_rect).collect();
    *runs += rects.len();
    let first = detector.landmarks(image, &rects)?;
    let seeds = first
        .into_iter()
        .zip(palms)
        .map(|(hand, p)| Candidate {
            first_crop: hand.rect.size[0],
            hand,
            palm_score: Some(p.score),
            stage,
        })
        .collect();
    refine(detector, image, seeds, config, runs)
}

/// The landmark model on `rects` (no palm behind them), the readings with at least
/// `min_presence` kept as candidates of `stage`, then the tracking steps ([`refine`]).
fn read_tracked(
    detector: &HandDetector,
    image: &RgbImage,
    rects: &[Rect],
    min_presence: f64,
    stage: &'static str,
    config: &SearchConfig,
    runs: &mut usize,
) -> Result<Vec<Candidate>, DetectError> {
    *runs += rects.len();
    let seeds = detector
        .landmarks(image, rects)?
        .into_iter()
        .filter(|l| l.presence >= min_presence)
        .map(|hand| Candidate {
            first_crop: hand.rect.size[0],
            hand,
            palm_score: None,
            stage,
        })
        .collect();
    refine(detector, image, seeds, config, runs)
}

/// MediaPipe's tracking step, [`SearchConfig::tracking_steps`] times: the rectangle from a
/// candidate's landmarks, the landmark model again; each candidate keeps whichever of its
/// versions has the highest presence.
fn refine(
    detector: &HandDetector,
    image: &RgbImage,
    mut cands: Vec<Candidate>,
    config: &SearchConfig,
    runs: &mut usize,
) -> Result<Vec<Candidate>, DetectError> {
    for _ in 0..config.tracking_steps {
        let rects: Vec<Rect> = cands
            .iter()
            .map(|c| rect_from_landmarks(&c.hand.points))
            .collect();
        *runs += rects.len();
        let next = detector.landmarks(image, &rects)?;
        for (c, n) in cands.iter_mut().zip(next) {
            if n.presence >= c.hand.presence * 0.9 {
                c.hand = n;
            }
        }
    }
    Ok(cands)
}

fn report(
    long: f64,
    stage: &str,
    palm_runs: usize,
    landmark_runs: usize,
    candidates: &[Candidate],
    config: &SearchConfig,
    t: Instant,
) -> StageReport {
    StageReport {
        stage: stage.to_string(),
        palm_runs,
        landmark_runs,
        hands: distinct(candidates, config, long).len(),
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// The best candidate of each distinct hand with enough presence, best first.
fn distinct(candidates: &[Candidate], config: &SearchConfig, long_side: f64) -> Vec<Candidate> {
    let min_size = (config.min_hand_size * long_side).max(16.0);
    let mut sorted: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.hand.presence >= config.min_presence && c.plausible(min_size))
        .collect();
    sorted.sort_by(|a, b| b.hand.presence.total_cmp(&a.hand.presence));
    // Each distinct hand keeps its best candidate's points; its side is the presence-weighted
    // vote of every candidate merged into it (the landmark model's handedness wavers between
    // crops of one hand, and one crop's vote is a coin toss where another's is clear).
    let mut out: Vec<(Candidate, f64, f64)> = Vec::new();
    for c in sorted {
        match out.iter_mut().find(|(o, _, _)| o.same_hand(c)) {
            Some((_, votes, weight)) => {
                *votes += c.hand.presence * c.hand.right;
                *weight += c.hand.presence;
            }
            None => out.push((c.clone(), c.hand.presence * c.hand.right, c.hand.presence)),
        }
    }
    out.into_iter()
        .map(|(mut c, votes, weight)| {
            c.hand.right = votes / weight;
            c
        })
        .collect()
}

#[derive(Clone)]
struct Chosen {
    left: Option<Candidate>,
    right: Option<Candidate>,
}

impl Chosen {
    fn missing(&self) -> bool {
        self.left.is_none() || self.right.is_none()
    }

    /// The pair score of [`pick`]: `presence · P(side) · size weight` summed over the hands
    /// (the size weight relative to a hand of size `largest`, or larger if one is).
    fn score(&self, largest: f64, full: f64) -> f64 {
        let largest = [&self.left, &self.right]
            .into_iter()
            .flatten()
            .map(Candidate::size)
            .fold(largest, f64::max);
        let p = |c: &Option<Candidate>, side: Side| {
            c.as_ref()
                .map_or(0.0, |c| c.side_score(side) * c.size_weight(largest, full))
        };
        p(&self.left, Side::Left) + p(&self.right, Side::Right)
    }
}

/// The pair of distinct hands (one left, one right) that do not overlap with the highest
/// `presence · P(side) · size weight` summed ([`SearchConfig::full_weight_size`]); else
/// the hand with the highest `presence · size weight` alone.
fn pick(candidates: &[Candidate], config: &SearchConfig, long: f64) -> Chosen {
    let hands = distinct(candidates, config, long);
    let largest = hands.iter().map(Candidate::size).fold(0.0, f64::max);
    let weight = |c: &Candidate| c.size_weight(largest, config.full_weight_size);
    let score = |c: &Candidate, side: Side| c.side_score(side) * weight(c);
    let mut best: Option<(f64, usize, usize)> = None;
    for (i, a) in hands.iter().enumerate() {
        for (j, b) in hands.iter().enumerate() {
            if i == j || a.overlaps(b) {
                continue;
            }
            // a right, b left
            let s = score(a, Side::Right) + score(b, Side::Left);
            if best.is_none_or(|(bs, _, _)| s > bs) {
                best = Some((s, i, j));
            }
        }
    }
    match best {
        Some((_, i, j)) => Chosen {
            right: Some(hands[i].clone()),
            left: Some(hands[j].clone()),
        },
        None => match hands
            .iter()
            .max_by(|a, b| (a.hand.presence * weight(a)).total_cmp(&(b.hand.presence * weight(b))))
        {
            Some(c) if c.hand.right >= 0.5 => Chosen {
                left: None,
                right: Some(c.clone()),
            },
            Some(c) => Chosen {
                left: Some(c.clone()),
                right: None,
            },
            None => Chosen {
                left: None,
                right: None,
            },
        },
    }
}

/// Paints the convex hull of a hand's landmarks, grown by a quarter of the hand's size,
/// black.
fn paint_hand(image: &mut RgbImage, points: &[[f64; 3]]) {
    let pts: Vec<[f64; 2]> = points.iter().map(|p| [p[0], p[1]]).collect();
    let hull = convex_hull(&pts);
    if hull.len() < 3 {
        return;
    }
    let c = Candidate {
        first_crop: 0.0,
        hand: HandLandmarks {
            rect: Rect {
                center: [0.0; 2],
                size: [0.0; 2],
                rotation: 0.0,
            },
            points: points.to_vec(),
            presence: 0.0,
            right: 0.0,
        },
        palm_score: None,
        stage: "",
    };
    let grow = c.size() * 0.12;
    let (w, h) = image.dimensions();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &hull {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    let x0 = (lo[0] - grow).floor().max(0.0) as u32;
    let y0 = (lo[1] - grow).floor().max(0.0) as u32;
    let x1 = ((hi[0] + grow).ceil().max(0.0) as u32).min(w);
    let y1 = ((hi[1] + grow).ceil().max(0.0) as u32).min(h);
    for y in y0..y1 {
        for x in x0..x1 {
            let p = [x as f64 + 0.5, y as f64 + 0.5];
            if distance_outside_hull(&hull, p) <= grow {
                image.put_pixel(x, y, image::Rgb([0, 0, 0]));
            }
        }
    }
}

/// Andrew's monotone chain, counter-clockwise in a y-down frame's math orientation.
fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// 0 inside the convex polygon `hull` (counter-clockwise), else the distance to it.
fn distance_outside_hull(hull: &[[f64; 2]], p: [f64; 2]) -> f64 {
    let n = hull.len();
    let mut inside = true;
    let mut best = f64::INFINITY;
    for i in 0..n {
        let a = hull[i];
        let b = hull[(i + 1) % n];
        let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if cross < 0.0 {
            inside = false;
        }
        let ab = [b[0] - a[0], b[1] - a[1]];
        let len2 = (ab[0] * ab[0] + ab[1] * ab[1]).max(1e-12);
        let t = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0);
        let q = [a[0] + t * ab[0], a[1] + t * ab[1]];
        best = best.min(((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt());
    }
    if inside { 0.0 } else { best }
}

impl TwoHandDetection {
    /// The hand of `side`, if found.
    pub fn hand(&self, side: Side) -> Option<&DetectedHand> {
        match side {
            Side::Left => self.left.as_ref(),
            Side::Right => self.right.as_ref(),
        }
    }

    /// The found hands as keypoints (plain format; every point confidence = the hand's
    /// presence), with a note per hand saying what found it.
    pub fn keypoints(&self) -> TwoHandKeypoints {
        let hand = |h: &Option<DetectedHand>| {
            h.as_ref().map(|h| {
                h.points
                    .iter()
                    .map(|p| Keypoint {
                        x: p[0],
                        y: p[1],
                        confidence: h.presence.clamp(1e-3, 1.0),
                    })
                    .collect::<Vec<_>>()
            })
        };
        let mut notes = Vec::new();
        for side in [Side::Left, Side::Right] {
            match self.hand(side) {
                Some(h) if h.stage == "hypothesis" => notes.push(format!(
                    "the {} hand was not detected: it is placed by hypothesis, interlocked with the {} hand (check the overlay; give --keypoints if it is wrong)",
                    side.as_str(),
                    side.mirrored().as_str()
                )),
                Some(h) => notes.push(format!(
                    "{} hand detected by the {} stage (presence {:.2}, {} with probability {:.2})",
                    side.as_str(),
                    h.stage,
                    h.presence,
                    side.as_str(),
                    h.side_probability
                )),
                None => notes.push(format!("no {} hand detected", side.as_str())),
            }
            if self.at_border(side) {
                notes.push(format!(
                    "the {} hand reaches the photo's border: it may be cut off, and its hidden keypoints are guesses (check the overlay)",
                    side.as_str()
                ));
            }
        }
        TwoHandKeypoints {
            left: hand(&self.left),
            right: hand(&self.right),
            format: KeypointFormat::Plain,
            notes,
        }
    }

    /// Whether the detected hand of `side` reaches the photo's border: one of its landmarks
    /// lies outside the photo or within 1 % of its long side from an edge. Such a hand may be
    /// cut off, and its hidden landmarks are the landmark model's guesses. (A hand placed by
    /// hypothesis is a guess anyway: never.)
    pub fn at_border(&self, side: Side) -> bool {
        let [w, h] = self.image_size.map(f64::from);
        let margin = 0.01 * w.max(h);
        let detected = self.hand(side).filter(|hand| hand.stage != "hypothesis");
        detected.is_some_and(|hand| {
            hand.points.iter().any(|p| {
                p[0] < margin - 0.5
                    || p[1] < margin - 0.5
                    || p[0] > w - 0.5 - margin
                    || p[1] > h - 0.5 - margin
            })
        })
    }

    /// The side whose hand was placed by hypothesis rather than detected, if any.
    pub fn hypothesized(&self) -> Option<Side> {
        Side::BOTH
            .into_iter()
            .find(|&s| self.hand(s).is_some_and(|h| h.stage == "hypothesis"))
    }

    /// `Ok` when both hands were found; otherwise the error a user should see, naming
    /// `image` (no hand, or which one of the two is missing).
    ///
    /// # Errors
    /// [`DetectError::NoHand`] or [`DetectError::OneHand`].
    pub fn require_both(&self, image: &std::path::Path) -> Result<(), DetectError> {
        match (&self.left, &self.right) {
            (Some(_), Some(_)) => Ok(()),
            (None, None) => Err(DetectError::NoHand {
                image: image.to_path_buf(),
                best_presence: self.best_presence,
            }),
            (Some(h), None) | (None, Some(h)) => Err(DetectError::OneHand {
                image: image.to_path_buf(),
                found: h.side.as_str(),
                missing: h.side.mirrored().as_str(),
                presence: h.presence,
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_distance() {
        let hull = convex_hull(&[[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0], [2.0, 2.0]]);
        assert_eq!(hull.len(), 4);
        assert_eq!(distance_outside_hull(&hull, [2.0, 2.0]), 0.0);
        assert!((distance_outside_hull(&hull, [6.0, 2.0]) - 2.0).abs() < 1e-12);
    }

    /// A hand-shaped candidate: 21 points spread over `size` pixels from `origin`.
    fn candidate(origin: [f64; 2], size: f64, presence: f64, right: f64) -> Candidate {
        let points = (0..NUM_LANDMARKS)
            .map(|i| {
                let (finger, joint) = ((i / 4) as f64, (i % 4) as f64);
                [
                    origin[0] + size * 0.2 * finger,
                    origin[1] - size * 0.25 * joint,
                    0.0,
                ]
            })
            .collect();
        Candidate {
            hand: HandLandmarks {
                rect: Rect::bounding(&[origin], 0.0),
                points,
                presence,
                right,
            },
            first_crop: size * 2.0,
            palm_score: Some(0.5),
            stage: "palms",
        }
    }

    /// The two hands take the more likely of the two opposite assignments; the reading's
    /// side must be confident. Numbers read on copies of the demo frames.
    #[test]
    fn look_sides_choose_the_likelier_opposite_assignment() {
        // 01 enlarged 2.5 times: the found hand (truly right) reads left (0.85), the hidden
        // left hand left (0.885): the found hand is relabelled right.
        let (side, l) = look_sides(0.150, 0.115, Side::Right, 0.7).unwrap();
        assert_eq!(side, Side::Left);
        assert!((l - 0.15 * 0.885).abs() < 1e-12);
        // A closer reading of the same pair (left 0.709) favours keeping the found hand's
        // side, and then its own side (right 0.291) is not confident enough.
        assert_eq!(look_sides(0.150, 0.291, Side::Right, 0.7), None);
        // 01 enlarged 0.75 times: found right (0.608), the reading left (0.858): kept.
        assert_eq!(
            look_sides(0.608, 0.142, Side::Left, 0.7).map(|(s, _)| s),
            Some(Side::Left)
        );
        // 02 off-centre: a reading of the found (right) hand's side at 0.866 does not
        // relabel a hand that reads right at 0.928, and its left is too weak to be taken.
        assert_eq!(look_sides(0.928, 0.866, Side::Left, 0.7), None);
        // Symmetric in the sides.
        let a = look_sides(0.150, 0.115, Side::Right, 0.7).unwrap();
        let b = look_sides(0.850, 0.885, Side::Left, 0.7).unwrap();
        assert_eq!((a.0, b.0), (Side::Left, Side::Right));
        assert!((a.1 - b.1).abs() < 1e-12);
    }

    #[test]
    fn a_merged_hand_takes_its_side_from_every_crop() {
        let config = SearchConfig::default();
        // Two crops of one hand (3 px apart): the better one unsure (0.45), the other sure
        // (0.76): one right hand, its side the presence-weighted vote.
        let a = candidate([100.0, 200.0], 100.0, 0.99, 0.45);
        let b = candidate([103.0, 200.0], 100.0, 0.98, 0.76);
        let far = candidate([400.0, 200.0], 100.0, 0.9, 0.1);
        let hands = distinct(&[a.clone(), b, far], &config, 512.0);
        assert_eq!(hands.len(), 2);
        assert_eq!(
            hands[0].hand.points, a.hand.points,
            "the best crop's landmarks"
        );
        let vote = (0.99 * 0.45 + 0.98 * 0.76) / (0.99 + 0.98);
        assert!((hands[0].hand.right - vote).abs() < 1e-12);
        assert!((hands[1].hand.right - 0.1).abs() < 1e-12);
        let chosen = pick(&hands, &config, 512.0);
        assert_eq!(chosen.right.unwrap().hand.points, a.hand.points);
        assert!(chosen.left.is_some());
    }

    /// Two readings cannot be the two hands when their wrists lie within half a palm of
    /// each other (one hand read left in one crop and right in another, as on `01` rotated
    /// by 20 degrees, wrists 0.38 palm apart; true pairs of the demo frames' copies lie
    /// 0.66-1.37 palm apart).
    #[test]
    fn pairs_need_wrists_half_a_palm_apart() {
        let config = SearchConfig::default();
        let palm = candidate([100.0, 200.0], 100.0, 0.9, 0.9).palm_length();
        let right = candidate([100.0, 200.0], 100.0, 0.98, 0.9);
        for (shift, pairs) in [(0.4, false), (0.6, true)] {
            let left = candidate([100.0 + shift * palm, 200.0], 100.0, 0.97, 0.1);
            let chosen = pick(&[right.clone(), left], &config, 256.0);
            assert_eq!(!chosen.missing(), pairs, "wrists {shift} palm apart");
        }
    }

    /// A crop collapsed onto fingertips counts in proportion to its size. Numbers read on
    /// the Pillow copy of `01` mirrored and on a synthetic photo cut through the left hand.
    #[test]
    fn small_crops_weigh_less_in_the_pairing() {
        let long = 256.0;
        let config = SearchConfig::default();
        let unweighted = SearchConfig {
            full_weight_size: 0.0,
            ..config.clone()
        };
        // 01 mirrored: the found hand reads left (0.63), a crop of 0.32 of its size at the
        // other hand's fingertips left too (0.65). Unweighted, the crop wins the left side
        // (0.920 against 0.918); weighted, the found hand is left.
        let found = candidate([100.0, 200.0], 100.0, 0.983, 0.367);
        let crop = candidate([250.0, 200.0], 32.0, 0.859, 0.346);
        let hands = [found.clone(), crop];
        let left = |c: &SearchConfig| pick(&hands, c, long).left.unwrap().hand.points;
        assert_ne!(left(&unweighted), found.hand.points);
        assert_eq!(left(&config), found.hand.points);
        // A photo cut through the left hand: a right hand (0.81), the left hand's
        // fingertips read left (0.97, 0.34 of its size) and another crop on them unsure
        // (0.40, 0.26): the fingertips stay the left hand, the only evidence of it.
        let right = candidate([100.0, 200.0], 100.0, 0.945, 0.806);
        let tips = candidate([250.0, 200.0], 34.0, 0.884, 0.03);
        let other = candidate([280.0, 200.0], 26.0, 0.837, 0.398);
        let chosen = pick(&[right.clone(), tips.clone(), other], &config, long);
        assert_eq!(chosen.right.unwrap().hand.points, right.hand.points);
        assert_eq!(chosen.left.unwrap().hand.points, tips.hand.points);
    }

    /// The look stage's choice, with the landmark model replaced by canned readings.
    #[test]
    fn the_look_starts_from_every_reading_and_replaces_only_a_weaker_partner() {
        let config = SearchConfig::default();
        let palm = candidate([100.0, 200.0], 100.0, 0.9, 0.9).palm_length();
        let no_look = |_: &Candidate, _: Side| -> Result<_, DetectError> { Ok(None) };
        // Two full hands: the stage does not run.
        let right = candidate([100.0, 200.0], 100.0, 0.98, 0.9);
        let left = candidate([300.0, 200.0], 100.0, 0.97, 0.1);
        let both = Chosen {
            left: Some(left.clone()),
            right: Some(right.clone()),
        };
        assert!(
            look_stage(&both, &[right, left], &config, no_look)
                .unwrap()
                .is_none()
        );

        // 01 rotated 20: one hand read left (0.96) and, 0.38 palm away, right (0.72). The
        // left reading was chosen; the look from it finds nothing, from the right one it
        // finds the hidden left hand.
        let read_left = candidate([100.0, 200.0], 100.0, 0.99, 0.04);
        let read_right = candidate([100.0 + 0.38 * palm, 200.0], 100.0, 0.96, 0.72);
        let hidden = candidate([250.0, 200.0], 100.0, 0.94, 0.12);
        let chosen = Chosen {
            left: Some(read_left.clone()),
            right: None,
        };
        let mut starts = Vec::new();
        let looked = look_stage(
            &chosen,
            &[read_left.clone(), read_right.clone()],
            &config,
            |source, missing| {
                starts.push((source.hand.right, missing));
                Ok((missing == Side::Left).then(|| (0.6, hidden.clone(), Side::Left)))
            },
        )
        .unwrap()
        .unwrap();
        assert_eq!(starts, [(0.04, Side::Right), (0.72, Side::Left)]);
        assert_eq!(looked.right.unwrap().hand.points, read_right.hand.points);
        assert_eq!(looked.left.unwrap().hand.points, hidden.hand.points);

        // A partner that is a small crop (0.32 of the found hand's size) is replaced by a
        // full-sized reading (01 mirrored) ...
        let found = candidate([100.0, 200.0], 100.0, 0.983, 0.367);
        let crop = candidate([250.0, 200.0], 32.0, 0.859, 0.346);
        let reading = candidate([260.0, 200.0], 90.0, 0.71, 0.92);
        let chosen = Chosen {
            left: Some(found.clone()),
            right: Some(crop.clone()),
        };
        let hands = [found.clone(), crop.clone()];
        let looked = look_stage(&chosen, &hands, &config, |_, _| {
            Ok(Some((0.4, reading.clone(), Side::Right)))
        })
        .unwrap()
        .unwrap();
        assert_eq!(looked.right.unwrap().hand.points, reading.hand.points);
        assert_eq!(looked.left.unwrap().hand.points, found.hand.points);
        // ... but not by a reading whose pair scores lower (the cut photo: a second reading
        // of the right hand, read right, would relabel it left).
        let right = candidate([100.0, 200.0], 100.0, 0.945, 0.806);
        let tips = candidate([250.0, 200.0], 34.0, 0.884, 0.03);
        let again = candidate([100.0 + 0.52 * palm, 200.0], 100.0, 0.9, 0.9);
        let chosen = Chosen {
            left: Some(tips.clone()),
            right: Some(right.clone()),
        };
        let looked = look_stage(&chosen, &[right.clone(), tips.clone()], &config, |_, _| {
            Ok(Some((0.16, again.clone(), Side::Right)))
        })
        .unwrap()
        .unwrap();
        assert_eq!(looked.right.unwrap().hand.points, right.hand.points);
        assert_eq!(looked.left.unwrap().hand.points, tips.hand.points);
    }

    #[test]
    fn views_cover_the_photo() {
        assert_eq!(palm_views(100, 80).len(), 1);
        assert_eq!(palm_views(256, 256).len(), 1);
        let v = palm_views(1920, 1080);
        assert_eq!(v.len(), 10);
        assert!(v.iter().all(|r| r.center[0] - r.size[0] / 2.0 >= -1e-9));
        let last = v.last().unwrap();
        assert!((last.center[0] + last.size[0] / 2.0 - 1920.0).abs() < 1e-9);
    }
}
