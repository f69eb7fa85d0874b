//! Rotated rectangles of a photo and the resampling that turns one into a network input.
//!
//! Coordinates here are MediaPipe's continuous pixel frame: pixel `i` spans `[i, i + 1]`,
//! so its centre is at `i + 0.5` (the project's keypoints put it at `i`; see
//! [`crate::HandKeypoints`]).

use image::RgbImage;

/// A rotated rectangle in continuous pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rect {
    /// Centre `[x, y]`.
    pub center: [f64; 2],
    /// `[width, height]` in pixels.
    pub size: [f64; 2],
    /// Rotation in radians: the rectangle's up direction turned clockwise on the image by
    /// this angle.
    pub rotation: f64,
}

/// How samples outside the photo are filled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Border {
    /// Black (the palm detector's letterbox).
    Zero,
    /// The nearest edge pixel (the landmark model's crops).
    Replicate,
}

impl Rect {
    /// The photo point of a point of the rectangle given in its unit frame (`[0, 1]²`, `u`
    /// right, `v` down).
    pub fn to_image(&self, u: f64, v: f64) -> [f64; 2] {
        let dx = (u - 0.5) * self.size[0];
        let dy = (v - 0.5) * self.size[1];
        let (s, c) = self.rotation.sin_cos();
        [
            self.center[0] + dx * c - dy * s,
            self.center[1] + dx * s + dy * c,
        ]
    }

    /// The inverse of [`Rect::to_image`].
    pub fn from_image(&self, x: f64, y: f64) -> [f64; 2] {
        let (s, c) = self.rotation.sin_cos();
        let dx = x - self.center[0];
        let dy = y - self.center[1];
        [
            (dx * c + dy * s) / self.size[0] + 0.5,
            (-dx * s + dy * c) / self.size[1] + 0.5,
        ]
    }

    /// MediaPipe's `RectTransformationCalculator`: shift by a fraction of the size along
    /// the rectangle's own axes, make it square on its long side, scale.
    pub(crate) fn transformed(&self, scale: f64, shift: [f64; 2]) -> Rect {
        let (s, c) = self.rotation.sin_cos();
        let [w, h] = self.size;
        let dx = w * shift[0] * c - h * shift[1] * s;
        let dy = w * shift[0] * s + h * shift[1] * c;
        let long = w.max(h);
        Rect {
            center: [self.center[0] + dx, self.center[1] + dy],
            size: [long * scale, long * scale],
            rotation: self.rotation,
        }
    }

    /// The rectangle holding `points` (continuous pixels) with edges along `rotation`.
    pub fn bounding(points: &[[f64; 2]], rotation: f64) -> Rect {
        let (s, c) = rotation.sin_cos();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            // into the rotated frame
            let u = p[0] * c + p[1] * s;
            let v = -p[0] * s + p[1] * c;
            lo = [lo[0].min(u), lo[1].min(v)];
            hi = [hi[0].max(u), hi[1].max(v)];
        }
        let (cu, cv) = ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
        Rect {
            center: [cu * c - cv * s, cu * s + cv * c],
            size: [hi[0] - lo[0], hi[1] - lo[1]],
            rotation,
        }
    }
}

/// The angle (radians, in `(-π, π]`) that turns the direction `from -> to` on the image into
/// "up": MediaPipe's `target_angle - atan2(-(y1 - y0), x1 - x0)` with a 90° target.
pub(crate) fn rotation_to_up(from: [f64; 2], to: [f64; 2]) -> f64 {
    let r = std::f64::consts::FRAC_PI_2 - (-(to[1] - from[1])).atan2(to[0] - from[0]);
    normalize_angle(r)
}

/// `a` wrapped into `(-π, π]`.
pub(crate) fn normalize_angle(a: f64) -> f64 {
    use std::f64::consts::PI;
    a - 2.0 * PI * ((a + PI) / (2.0 * PI)).floor()
}

/// Bilinear sample of `image` at continuous point `(x, y)`, `[0, 1]` per channel.
fn sample(image: &RgbImage, x: f64, y: f64, border: Border) -> [f32; 3] {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let (px, py) = (x - 0.5, y - 0.5);
    let (x0, y0) = (px.floor(), py.floor());
    let (fx, fy) = ((px - x0) as f32, (py - y0) as f32);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let mut out = [0f32; 3];
    for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
        for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
            let (mut xi, mut yi) = (x0 + dx, y0 + dy);
            let outside = xi < 0 || yi < 0 || xi >= w || yi >= h;
            if outside {
                match border {
                    Border::Zero => continue,
                    Border::Replicate => {
                        xi = xi.clamp(0, w - 1);
                        yi = yi.clamp(0, h - 1);
                    }
                }
            }
            let p = image.get_pixel(xi as u32, yi as u32).0;
            for k in 0..3 {
                out[k] += wx * wy * p[k] as f32 / 255.0;
            }
        }
    }
    out
}

/// `rect` of `image` resampled to `size x size`, values in `[0, 1]`, as planar
/// `[3, size, size]` (NCHW without the batch). Each output pixel averages `k x k` bilinear
/// samples where the rectangle is more than 1.5 times larger than the output (`k` up to 4),
/// so a large photo is not aliased.
pub fn resample(image: &RgbImage, rect: &Rect, size: usize, border: Border) -> Vec<f32> {
    let ratio = rect.size[0].max(rect.size[1]) / size as f64;
    let k = if ratio > 1.5 {
        (ratio.ceil() as usize).min(4)
    } else {
        1
    };
    let plane = size * size;
    let mut out = vec![0f32; 3 * plane];
    let norm = 1.0 / (k * k) as f32;
    for v in 0..size {
        for u in 0..size {
            let mut acc = [0f32; 3];
            for sy in 0..k {
                for sx in 0..k {
                    let uu = (u as f64 + (sx as f64 + 0.5) / k as f64) / size as f64;
                    let vv = (v as f64 + (sy as f64 + 0.5) / k as f64) / size as f64;
                    let [x, y] = rect.to_image(uu, vv);
                    let s = sample(image, x, y, border);
                    for c in 0..3 {
                        acc[c] += s[c];
                    }
                }
            }
            for c in 0..3 {
                out[c * plane + v * size + u] = acc[c] * norm;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rect_maps_round_trip_and_rotate_clockwise() {
        let r = Rect {
            center: [50.0, 40.0],
            size: [20.0, 10.0],
            rotation: 0.3,
        };
        let p = r.to_image(0.2, 0.9);
        let q = r.from_image(p[0], p[1]);
        assert!((q[0] - 0.2).abs() < 1e-12 && (q[1] - 0.9).abs() < 1e-12);
        // A quarter turn: the rectangle's top (v = 0) points to the image's right.
        let r = Rect {
            rotation: std::f64::consts::FRAC_PI_2,
            ..r
        };
        let top = r.to_image(0.5, 0.0);
        assert!((top[0] - 55.0).abs() < 1e-9 && (top[1] - 40.0).abs() < 1e-9);
    }

    #[test]
    fn upward_direction_needs_no_rotation() {
        assert!(rotation_to_up([10.0, 20.0], [10.0, 5.0]).abs() < 1e-12);
        // Fingers pointing right: rotate by +90 degrees.
        let r = rotation_to_up([10.0, 20.0], [30.0, 20.0]);
        assert!((r - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((normalize_angle(4.0) - (4.0 - 2.0 * std::f64::consts::PI)).abs() < 1e-12);
    }

    #[test]
    fn bounding_rect_holds_the_points() {
        let pts = [[0.0, 0.0], [10.0, 0.0], [10.0, 4.0], [0.0, 4.0]];
        let r = Rect::bounding(&pts, 0.0);
        assert_eq!(r.center, [5.0, 2.0]);
        assert_eq!(r.size, [10.0, 4.0]);
        let t = r.transformed(2.0, [0.0, -0.5]);
        assert_eq!(t.center, [5.0, 0.0]);
        assert_eq!(t.size, [20.0, 20.0]);
    }

    #[test]
    fn identity_resample_returns_the_pixels() {
        let img = RgbImage::from_fn(4, 4, |x, y| image::Rgb([(x * 60) as u8, (y * 60) as u8, 7]));
        let r = Rect {
            center: [2.0, 2.0],
            size: [4.0, 4.0],
            rotation: 0.0,
        };
        let v = resample(&img, &r, 4, Border::Zero);
        assert!((v[1] - 60.0 / 255.0).abs() < 1e-6); // red of pixel (1, 0)
        assert!((v[16 + 4] - 60.0 / 255.0).abs() < 1e-6); // green of pixel (0, 1)
        // Outside the photo: zero or the edge.
        let off = Rect {
            center: [-10.0, 2.0],
            ..r
        };
        assert!(
            resample(&img, &off, 4, Border::Zero)
                .iter()
                .all(|&x| x == 0.0)
        );
        let edge = resample(&img, &off, 4, Border::Replicate);
        assert!((edge[32] - 7.0 / 255.0).abs() < 1e-6);
    }
}
