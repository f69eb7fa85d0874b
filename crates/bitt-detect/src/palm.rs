//! The palm detector's post-processing: SSD anchors, box and keypoint decoding, weighted
//! non-maximum suppression, and the hand rectangle the landmark model crops (MediaPipe's
//! `palm_detection_cpu` and `hand_landmark_tracking_cpu` graphs, options cited inline).

use crate::crop::{Rect, rotation_to_up};

/// Input side of the palm detector.
pub(crate) const PALM_INPUT: usize = 192;
/// Numbers per anchor in the regressor output: box (x, y, w, h) + 7 keypoints (x, y).
pub(crate) const PALM_VALUES: usize = 18;
/// Number of anchors: 24² · 2 (stride 8) + 12² · 6 (three stride-16 layers merged).
pub(crate) const PALM_ANCHORS: usize = 2016;

/// A palm found by the detector, in continuous pixels of the photo.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Palm {
    /// Sigmoid of the logit (clipped to ±100, `palm_detection_cpu.pbtxt`).
    pub score: f64,
    /// Box centre `[x, y]`.
    pub center: [f64; 2],
    /// Box `[width, height]`.
    pub size: [f64; 2],
    /// The 7 palm keypoints: 0 wrist, 2 middle finger base (the two that set the rotation).
    pub keypoints: [[f64; 2]; 7],
}

/// Anchor centres in the detector's unit input frame, in output order.
pub fn anchors() -> Vec<[f64; 2]> {
    // ssd_anchors_calculator: 4 layers, strides [8, 16, 16, 16], offset 0.5, fixed anchor
    // size 1, aspect ratio 1 plus the interpolated scale: 2 anchors per layer and cell;
    // layers of equal stride share their cells.
    let mut out = Vec::with_capacity(PALM_ANCHORS);
    for (grid, per_cell) in [(24usize, 2usize), (12, 6)] {
        for y in 0..grid {
            for x in 0..grid {
                let c = [
                    (x as f64 + 0.5) / grid as f64,
                    (y as f64 + 0.5) / grid as f64,
                ];
                out.extend(std::iter::repeat_n(c, per_cell));
            }
        }
    }
    out
}

/// The letterbox of a `width x height` photo: the square rectangle the detector sees.
pub fn letterbox(width: u32, height: u32) -> Rect {
    let side = width.max(height) as f64;
    Rect {
        center: [width as f64 / 2.0, height as f64 / 2.0],
        size: [side, side],
        rotation: 0.0,
    }
}

/// Decodes the detector's outputs for the input crop `view` of the photo (for the whole
/// photo, [`letterbox`]): every anchor scoring at least `min_score`, then weighted NMS.
///
/// `regressors` is `[2016 · 18]`, `logits` `[2016]`.
pub fn decode(regressors: &[f32], logits: &[f32], view: &Rect, min_score: f64) -> Vec<Palm> {
    let anchors = anchors();
    let s = PALM_INPUT as f64;
    let mut found = Vec::new();
    for (i, a) in anchors.iter().enumerate() {
        let Some(&logit) = logits.get(i) else { break };
        let score = 1.0 / (1.0 + (-(logit as f64).clamp(-100.0, 100.0)).exp());
        if score < min_score || !score.is_finite() {
            continue;
        }
        let r = &regressors[i * PALM_VALUES..(i + 1) * PALM_VALUES];
        let unit = |dx: f32, dy: f32| view.to_image(a[0] + dx as f64 / s, a[1] + dy as f64 / s);
        let center = unit(r[0], r[1]);
        let scale = view.size[0].max(view.size[1]);
        let size = [r[2] as f64 / s * scale, r[3] as f64 / s * scale];
        let mut keypoints = [[0.0; 2]; 7];
        for (k, p) in keypoints.iter_mut().enumerate() {
            *p = unit(r[4 + 2 * k], r[5 + 2 * k]);
        }
        if size[0] <= 0.0 || size[1] <= 0.0 || !center.iter().all(|v| v.is_finite()) {
            continue;
        }
        found.push(Palm {
            score,
            center,
            size,
            keypoints,
        });
    }
    weighted_nms(found, 0.3)
}

/// Intersection over union of two axis-aligned boxes.
pub fn iou(a: &Palm, b: &Palm) -> f64 {
    let lo = |p: &Palm, k: usize| p.center[k] - p.size[k] / 2.0;
    let hi = |p: &Palm, k: usize| p.center[k] + p.size[k] / 2.0;
    let w = (hi(a, 0).min(hi(b, 0)) - lo(a, 0).max(lo(b, 0))).max(0.0);
    let h = (hi(a, 1).min(hi(b, 1)) - lo(a, 1).max(lo(b, 1))).max(0.0);
    let inter = w * h;
    let union = a.size[0] * a.size[1] + b.size[0] * b.size[1] - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// MediaPipe's weighted non-maximum suppression (`non_max_suppression_calculator`,
/// `WEIGHTED`, IoU): the best remaining detection absorbs every detection overlapping it by
/// more than `threshold`, its box and keypoints becoming their score-weighted mean.
pub(crate) fn weighted_nms(mut palms: Vec<Palm>, threshold: f64) -> Vec<Palm> {
    palms.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut out = Vec::new();
    while !palms.is_empty() {
        let best = palms[0].clone();
        let (group, rest): (Vec<Palm>, Vec<Palm>) =
            palms.into_iter().partition(|p| iou(&best, p) > threshold);
        palms = rest;
        let total: f64 = group.iter().map(|p| p.score).sum();
        let mut merged = best.clone();
        if group.len() > 1 && total > 0.0 {
            let avg = |f: &dyn Fn(&Palm) -> f64| {
                group.iter().map(|p| p.score * f(p)).sum::<f64>() / total
            };
            merged.center = [avg(&|p| p.center[0]), avg(&|p| p.center[1])];
            merged.size = [avg(&|p| p.size[0]), avg(&|p| p.size[1])];
            for k in 0..7 {
                merged.keypoints[k] = [avg(&|p| p.keypoints[k][0]), avg(&|p| p.keypoints[k][1])];
            }
        }
        out.push(merged);
    }
    out
}

impl Palm {
    /// The hand rectangle the landmark model crops (`hand_landmark_tracking_cpu`:
    /// rotation from the wrist to the middle finger's base, target 90°; then
    /// `RectTransformationCalculator` with scale 2.6, shift_y -0.5, square_long).
    pub fn hand_rect(&self) -> Rect {
        let rotation = rotation_to_up(self.keypoints[0], self.keypoints[2]);
        Rect {
            center: self.center,
            size: self.size,
            rotation,
        }
        .transformed(2.6, [0.0, -0.5])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anchors_are_in_mediapipes_order() {
        let a = anchors();
        assert_eq!(a.len(), PALM_ANCHORS);
        assert_eq!(a[0], [0.5 / 24.0, 0.5 / 24.0]);
        assert_eq!(a[1], a[0]);
        assert_eq!(a[2], [1.5 / 24.0, 0.5 / 24.0]);
        // index = 1152 + (y·12 + x)·6 + k
        assert_eq!(a[1152 + (3 * 12 + 5) * 6 + 4], [5.5 / 12.0, 3.5 / 12.0]);
    }

    fn palm(score: f64, x: f64) -> Palm {
        Palm {
            score,
            center: [x, 10.0],
            size: [10.0, 10.0],
            keypoints: [[x, 10.0]; 7],
        }
    }

    #[test]
    fn weighted_nms_merges_overlaps_and_keeps_the_rest() {
        let out = weighted_nms(vec![palm(0.5, 11.0), palm(0.9, 10.0), palm(0.8, 40.0)], 0.3);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].score, 0.9);
        let x = (0.9 * 10.0 + 0.5 * 11.0) / 1.4;
        assert!((out[0].center[0] - x).abs() < 1e-12);
        assert_eq!(out[1].center[0], 40.0);
    }

    #[test]
    fn decoding_places_a_box_on_its_anchor() {
        let mut reg = vec![0f32; PALM_ANCHORS * PALM_VALUES];
        let mut logits = vec![-50f32; PALM_ANCHORS];
        // anchor 2: cell (1, 0) of the 24 grid; box 19.2 wide = 0.1 of the input
        logits[2] = 3.0;
        reg[2 * 18 + 2] = 19.2;
        reg[2 * 18 + 3] = 19.2;
        reg[2 * 18] = 9.6; // +0.05 in x
        let view = letterbox(384, 192); // side 384, centre (192, 96)
        let out = decode(&reg, &logits, &view, 0.5);
        assert_eq!(out.len(), 1);
        let p = &out[0];
        assert!((p.score - 1.0 / (1.0 + (-3f64).exp())).abs() < 1e-12);
        assert!((p.size[0] - 38.4).abs() < 1e-5);
        let ux = 1.5 / 24.0 + 0.05;
        assert!((p.center[0] - (192.0 + (ux - 0.5) * 384.0)).abs() < 1e-5);
        assert!((p.center[1] - (96.0 + (0.5 / 24.0 - 0.5) * 384.0)).abs() < 1e-5);
    }
}
