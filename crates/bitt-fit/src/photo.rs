//! A photo brought to the preset's square size: crop a square around both hands (the
//! reference's crop around their projected box), resize, and adjust the camera intrinsics to
//! match ([`ImageInput`]).

use bitt_stdx::FileErrorExt;
use std::path::Path;

use bitt_mesh::glam::{DMat3, DVec3};
use bitt_mesh::{HandPair, PinholeCamera, TwoHandScene};

use crate::FitError;

/// Margin around the hands' pixel box, as a fraction of its larger side.
pub const CROP_MARGIN: f64 = 0.15;

/// The reference's `HAND_BBOX_RATIO`: the hands' box fills this fraction of the crop's side.
pub const REFERENCE_HAND_BOX_RATIO: f64 = 0.8;

/// An image `[3, H, W]` (channel-major, values in `[0, 1]`) with its camera and optional mask
/// `[H, W]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageInput {
    /// Pixels.
    pub image: Vec<f32>,
    /// Optional hand mask.
    pub mask: Option<Vec<f32>>,
    /// The camera of the image.
    pub camera: PinholeCamera,
}

impl ImageInput {
    /// `[H, W]`.
    pub fn size(&self) -> [usize; 2] {
        [self.camera.height as usize, self.camera.width as usize]
    }

    /// Crops a square around `hands_box` (`[x0, y0, x1, y1]` pixels; the square is the box's
    /// larger side plus [`CROP_MARGIN`], centred on the box; pixels outside the image are
    /// black) and resizes it to `size x size` by area averaging (bilinear when enlarging).
    /// The camera's principal point and focal lengths follow. Returns `self` unchanged when
    /// it already is `size x size` and `hands_box` is `None`.
    pub fn fit_square(&self, hands_box: Option<[f64; 4]>, size: usize) -> Result<Self, FitError> {
        let [h, w] = self.size();
        if self.image.len() != 3 * h * w {
            return Err(FitError::Invalid(format!(
                "image has {} values, the camera says 3 x {h} x {w}",
                self.image.len()
            )));
        }
        if let Some(m) = &self.mask
            && m.len() != h * w
        {
            return Err(FitError::Invalid(format!(
                "mask has {} values, the image is {h} x {w}",
                m.len()
            )));
        }
        if hands_box.is_none() && h == size && w == size {
            return Ok(self.clone());
        }
        let (x0, y0, side) = square_window([h, w], hands_box, size)?;
        let sample = |plane: &[f32]| resample(plane, h, w, x0, y0, side, size);
        let mut image = Vec::with_capacity(3 * size * size);
        for ch in 0..3 {
            image.extend(sample(&self.image[ch * h * w..(ch + 1) * h * w]));
        }
        let mask = self.mask.as_ref().map(|m| {
            sample(m)
                .into_iter()
                .map(|v| if v > 0.5 { 1.0 } else { 0.0 })
                .collect()
        });
        let camera = crop_camera(&self.camera, x0, y0, side, size)?;
        Ok(ImageInput {
            image,
            mask,
            camera,
        })
    }
}

/// The camera of [`ImageInput::fit_square`] alone, without touching pixels: the camera of
/// an `[H, W]` image after cropping the square around `hands_box` (the centred square when
/// `None`) and resizing it to `size x size`.
pub fn fit_camera(
    camera: &PinholeCamera,
    hands_box: Option<[f64; 4]>,
    size: usize,
) -> Result<PinholeCamera, FitError> {
    let [h, w] = [camera.height as usize, camera.width as usize];
    if hands_box.is_none() && h == size && w == size {
        return Ok(*camera);
    }
    let (x0, y0, side) = square_window([h, w], hands_box, size)?;
    crop_camera(camera, x0, y0, side, size)
}

/// The pixel box `[x0, y0, x1, y1]` of both hands' projected vertices (either hand alone when
/// only one is annotated).
pub fn hands_box(hands: &TwoHandScene, models: &HandPair) -> Result<[f64; 4], FitError> {
    let points = hands.camera_vertices(models)?;
    let b = hands
        .pixel_box(&points)
        .ok_or_else(|| FitError::Invalid("no hand vertex is in front of the camera".into()))?;
    Ok([b.min.x, b.min.y, b.max.x, b.max.y])
}

/// The box to give [`ImageInput::fit_square`] so that its square is the reference's crop
/// (side `max(w, h) / REFERENCE_HAND_BOX_RATIO`, same centre).
pub fn reference_crop_box(b: [f64; 4]) -> [f64; 4] {
    let grow = 1.0 / REFERENCE_HAND_BOX_RATIO / (1.0 + CROP_MARGIN);
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let half = (b[2] - b[0]).max(b[3] - b[1]) / 2.0 * grow;
    [cx - half, cy - half, cx + half, cy + half]
}

/// The pixel box of both hands ([`hands_box`]), refused when it lies outside the image (the
/// image at `source` and its annotation do not belong together).
pub fn hands_in_image(
    hands: &TwoHandScene,
    models: &HandPair,
    source: &Path,
) -> Result<[f64; 4], FitError> {
    let b = hands_box(hands, models)
        .map_err(|e| FitError::Invalid(format!("{}: {e}", source.display())))?;
    let (w, h) = (
        f64::from(hands.camera.width),
        f64::from(hands.camera.height),
    );
    if b[2] < 0.0 || b[3] < 0.0 || b[0] > w || b[1] > h {
        return Err(FitError::Invalid(format!(
            "{}: the hands project to [{:.0}, {:.0}] - [{:.0}, {:.0}], outside the {w}x{h} \
             image: the image and its annotation do not belong together",
            source.display(),
            b[0],
            b[1],
            b[2],
            b[3]
        )));
    }
    Ok(b)
}

/// The square `(x0, y0, side)` in pixels cropped from an `[h, w]` image (see
/// [`ImageInput::fit_square`]).
fn square_window(
    [h, w]: [usize; 2],
    hands_box: Option<[f64; 4]>,
    size: usize,
) -> Result<(f64, f64, f64), FitError> {
    if size == 0 {
        return Err(FitError::Invalid("target size must be positive".into()));
    }
    match hands_box {
        None => {
            let side = h.min(w) as f64;
            Ok(((w as f64 - side) / 2.0, (h as f64 - side) / 2.0, side))
        }
        Some([bx0, by0, bx1, by1]) => {
            if !(bx1 > bx0 && by1 > by0 && [bx0, by0, bx1, by1].iter().all(|v| v.is_finite())) {
                return Err(FitError::Invalid(format!(
                    "hands box {:?} is empty or not finite",
                    [bx0, by0, bx1, by1]
                )));
            }
            let side = (bx1 - bx0).max(by1 - by0) * (1.0 + CROP_MARGIN);
            let (cx, cy) = ((bx0 + bx1) / 2.0, (by0 + by1) / 2.0);
            Ok((cx - side / 2.0, cy - side / 2.0, side))
        }
    }
}

/// `camera` after cropping the square `(x0, y0, side)` and resizing it to `size x size`.
fn crop_camera(
    camera: &PinholeCamera,
    x0: f64,
    y0: f64,
    side: f64,
    size: usize,
) -> Result<PinholeCamera, FitError> {
    let scale = size as f64 / side;
    let k = camera.intrinsics;
    let intrinsics = DMat3::from_cols(
        DVec3::new(k.x_axis.x * scale, 0.0, 0.0),
        DVec3::new(k.y_axis.x * scale, k.y_axis.y * scale, 0.0),
        DVec3::new((k.z_axis.x - x0) * scale, (k.z_axis.y - y0) * scale, 1.0),
    );
    Ok(PinholeCamera::new(
        intrinsics,
        camera.rotation,
        camera.translation,
        size as u32,
        size as u32,
    )?)
}

/// Resamples the square `[x0, x0 + side) x [y0, y0 + side)` of an `h x w` plane to
/// `size x size`: each output pixel averages the source over its footprint (a grid of
/// bilinear samples, at least 2 x 2 per pixel).
fn resample(
    plane: &[f32],
    h: usize,
    w: usize,
    x0: f64,
    y0: f64,
    side: f64,
    size: usize,
) -> Vec<f32> {
    let step = side / size as f64;
    let taps = (step.ceil() as usize).max(2);
    let at = |x: f64, y: f64| -> f64 {
        // Pixel centres at integer + 1/2.
        let (fx, fy) = (x - 0.5, y - 0.5);
        let (c0, r0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - c0, fy - r0);
        let get = |r: f64, c: f64| -> f64 {
            if r < 0.0 || c < 0.0 || r >= h as f64 || c >= w as f64 {
                0.0
            } else {
                f64::from(plane[r as usize * w + c as usize])
            }
        };
        let top = get(r0, c0) * (1.0 - tx) + get(r0, c0 + 1.0) * tx;
        let bottom = get(r0 + 1.0, c0) * (1.0 - tx) + get(r0 + 1.0, c0 + 1.0) * tx;
        top * (1.0 - ty) + bottom * ty
    };
    let mut out = Vec::with_capacity(size * size);
    for r in 0..size {
        for c in 0..size {
            let mut sum = 0.0;
            for i in 0..taps {
                for j in 0..taps {
                    let x = x0 + (c as f64 + (j as f64 + 0.5) / taps as f64) * step;
                    let y = y0 + (r as f64 + (i as f64 + 0.5) / taps as f64) * step;
                    sum += at(x, y);
                }
            }
            out.push((sum / (taps * taps) as f64) as f32);
        }
    }
    out
}

/// A [`FitError::File`] I/O error naming `image` when it is not a file (before anything is read).
///
/// # Errors
/// The missing input image.
pub fn require_image(image: &Path) -> Result<(), FitError> {
    if image.is_file() {
        return Ok(());
    }
    Err(FitError::io(
        image,
        std::io::Error::new(std::io::ErrorKind::NotFound, "input image not found"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_and_resize_keeps_projections_consistent() {
        let camera = PinholeCamera::looking_down_z(300.0, 200, 100);
        // A bright pixel where a point projects.
        let p = DVec3::new(0.02, -0.01, 0.5);
        let px = camera.project(p).unwrap();
        let (h, w) = (100usize, 200usize);
        let mut image = vec![0.0f32; 3 * h * w];
        let (c, r) = (px.x.floor() as usize, px.y.floor() as usize);
        for ch in 0..3 {
            for dr in 0..4 {
                for dc in 0..4 {
                    image[ch * h * w + (r + dr - 2) * w + (c + dc - 2)] = 1.0;
                }
            }
        }
        let input = ImageInput {
            image,
            mask: None,
            camera,
        };
        let out = input
            .fit_square(
                Some([px.x - 20.0, px.y - 20.0, px.x + 20.0, px.y + 20.0]),
                32,
            )
            .unwrap();
        let q = out.camera.project(p).unwrap();
        let box_ = [px.x - 20.0, px.y - 20.0, px.x + 20.0, px.y + 20.0];
        assert_eq!(fit_camera(&camera, Some(box_), 32).unwrap(), out.camera);
        assert!(
            (q.x - 16.0).abs() < 1e-9 && (q.y - 16.0).abs() < 1e-9,
            "{q:?}"
        );
        // The bright square lands around the projection.
        let v = out.image[(q.y as usize) * 32 + q.x as usize];
        assert!(v > 0.3, "{v}");
        assert!(out.image[0] == 0.0);
    }

    #[test]
    fn bad_sizes_are_reported() {
        let input = ImageInput {
            image: vec![0.0; 10],
            mask: None,
            camera: PinholeCamera::looking_down_z(100.0, 8, 8),
        };
        assert!(
            input
                .fit_square(None, 4)
                .unwrap_err()
                .to_string()
                .contains("values")
        );
    }

    #[test]
    fn reference_crop_has_the_reference_side() {
        let b = [10.0, 20.0, 90.0, 60.0];
        let g = reference_crop_box(b);
        // fit_square's side from g equals max(w, h) / 0.8 from b.
        let side = (g[2] - g[0]).max(g[3] - g[1]) * (1.0 + crate::photo::CROP_MARGIN);
        assert!(
            (side - 80.0 / REFERENCE_HAND_BOX_RATIO).abs() < 1e-9,
            "{side}"
        );
        assert!(((g[0] + g[2]) / 2.0 - 50.0).abs() < 1e-12);
    }
}
