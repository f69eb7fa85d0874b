//! Cameras: pinhole (intrinsics K + world-to-camera extrinsics R, t) and orthographic.
//!
//! Conventions (OpenCV / InterHand2.6M): the camera looks down +z, x to the right, y down in
//! the image; pixel `(u, v) = (fx * x / z + cx, fy * y / z + cy)`, continuous coordinates
//! with pixel `i` spanning `[i - 0.5, i + 0.5]`, as in OpenCV.

use glam::{DMat3, DVec2, DVec3};

use crate::MeshError;

/// The depths (metres along the camera's axis) every vertex of a photographed hand lies
/// between: nearer than 5 cm, or farther than 20 m, is a wrong translation (or keypoints in
/// the wrong units), not a photo.
pub const HAND_DEPTH_RANGE_M: [f64; 2] = [0.05, 20.0];

// ---------------------------------------------------------------------------------------------
// Camera values as users type them (`--intrinsics`, `--view`): parsed and checked here, below
// burn, so the fuzz targets reach them.

/// `fx,fy,cx,cy` (pixels) as four positive-focal numbers.
///
/// # Errors
/// Not four finite numbers, or a focal length that is not positive.
pub fn parse_intrinsics(text: &str) -> Result<[f64; 4], String> {
    let values: Vec<&str> = text.split(',').map(str::trim).collect();
    let bad = |why: String| {
        format!(
            "--intrinsics {text:?}: {why} (expected fx,fy,cx,cy in pixels, e.g. 600,600,320,240)"
        )
    };
    if values.len() != 4 {
        return Err(bad(format!("{} values", values.len())));
    }
    let mut out = [0.0; 4];
    for (o, v) in out.iter_mut().zip(&values) {
        *o = v
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(format!("{v:?} is not a finite number")))?;
    }
    if out[0] <= 0.0 || out[1] <= 0.0 {
        return Err(bad("the focal lengths must be positive".into()));
    }
    Ok(out)
}

/// The focal lengths `--intrinsics` may give, as multiples of the photo's long side: a
/// fisheye-wide 0.05 to a telephoto 100. Outside, the fit's residuals are meaningless
/// (infinite at 1e-30) rather than large (issue 38).
pub(crate) const FOCAL_RANGE_OF_LONG_SIDE: [f64; 2] = [0.05, 100.0];

/// Checks `--intrinsics` against the photo (`[w, h]` pixels): focal lengths within
/// [`FOCAL_RANGE_OF_LONG_SIDE`], the principal point within the image widened by its own size
/// on every side (a crop's principal point may lie off its centre, not a photo away).
///
/// # Errors
/// What is wrong, naming `--intrinsics`, the value and the allowed range.
pub fn check_intrinsics_for_image(
    [fx, fy, cx, cy]: [f64; 4],
    [w, h]: [usize; 2],
) -> Result<(), String> {
    let (w, h) = (w as f64, h as f64);
    let long = w.max(h);
    let [lo, hi] = FOCAL_RANGE_OF_LONG_SIDE;
    let bad = |why: String| {
        Err(format!(
            "--intrinsics {fx},{fy},{cx},{cy}: {why} for the {w}x{h} photo"
        ))
    };
    for (name, f) in [("fx", fx), ("fy", fy)] {
        if !(lo * long..=hi * long).contains(&f) {
            return bad(format!(
                "{name} = {f} px is not between {} and {} px ({lo} to {hi} times the long side)",
                lo * long,
                hi * long
            ));
        }
    }
    if !(-w..=2.0 * w).contains(&cx) || !(-h..=2.0 * h).contains(&cy) {
        return bad(format!(
            "the principal point ({cx}, {cy}) is not within ({}, {}) to ({}, {})",
            -w,
            -h,
            2.0 * w,
            2.0 * h
        ));
    }
    Ok(())
}

/// `AZ,EL` (degrees) of an orbit view, as `render-avatar --view` takes it: two finite numbers.
///
/// # Errors
/// What is wrong, naming the value.
pub fn parse_orbit_view(s: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [a, e] = parts.as_slice() else {
        return Err(format!("expected AZ,EL in degrees, got {s:?}"));
    };
    let a: f64 = a.trim().parse().map_err(|_| format!("bad azimuth {a:?}"))?;
    let e: f64 = e
        .trim()
        .parse()
        .map_err(|_| format!("bad elevation {e:?}"))?;
    if !(a.is_finite() && e.is_finite()) {
        return Err(format!("view {s:?} is not finite"));
    }
    Ok((a, e))
}

/// A pinhole camera: `x_cam = R x_world + t`, `pixel = K x_cam / z_cam`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinholeCamera {
    /// Intrinsics `K` (`fx, fy` on the diagonal, `cx, cy` in the last column, `K[2] = [0,0,1]`).
    pub intrinsics: DMat3,
    /// World-to-camera rotation.
    pub rotation: DMat3,
    /// World-to-camera translation (metres).
    pub translation: DVec3,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl PinholeCamera {
    /// A camera from `K`, `R`, `t` and the image size, rejecting non-finite or degenerate input.
    pub fn new(
        intrinsics: DMat3,
        rotation: DMat3,
        translation: DVec3,
        width: u32,
        height: u32,
    ) -> Result<Self, MeshError> {
        let cam = PinholeCamera {
            intrinsics,
            rotation,
            translation,
            width,
            height,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// A camera at the world origin looking down +z with focal length `focal` (pixels) and the
    /// principal point at the image centre.
    pub fn looking_down_z(focal: f64, width: u32, height: u32) -> Self {
        PinholeCamera {
            intrinsics: DMat3::from_cols(
                DVec3::new(focal, 0.0, 0.0),
                DVec3::new(0.0, focal, 0.0),
                DVec3::new(width as f64 / 2.0, height as f64 / 2.0, 1.0),
            ),
            rotation: DMat3::IDENTITY,
            translation: DVec3::ZERO,
            width,
            height,
        }
    }

    /// Checks that every value is finite, the focal lengths are positive, `R` is a rotation
    /// and the image is not empty.
    pub fn validate(&self) -> Result<(), MeshError> {
        let bad = |d: String| Err(MeshError::InvalidParams(format!("camera: {d}")));
        if !(self.intrinsics.is_finite()
            && self.rotation.is_finite()
            && self.translation.is_finite())
        {
            return bad("a value is NaN or infinite".into());
        }
        let (fx, fy) = (self.intrinsics.x_axis.x, self.intrinsics.y_axis.y);
        if fx <= 0.0 || fy <= 0.0 {
            return bad(format!(
                "focal lengths must be positive (fx = {fx}, fy = {fy})"
            ));
        }
        let r = self.rotation;
        if (r.transpose() * r - DMat3::IDENTITY)
            .to_cols_array()
            .iter()
            .any(|x| x.abs() > 1e-3)
            || (r.determinant() - 1.0).abs() > 1e-3
        {
            return bad(format!(
                "R is not a rotation (det = {:.4})",
                r.determinant()
            ));
        }
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// The camera assumed for a photo of unknown intrinsics, `width` x `height` pixels:
    /// identity extrinsics, the principal point at the image centre (`(w - 1) / 2`,
    /// `(h - 1) / 2` in this module's pixel convention) and both focal lengths
    /// equal to the image diagonal in pixels (a 53 degree diagonal field of view, between a
    /// phone's main camera and a portrait lens).
    ///
    /// # Errors
    /// A zero size.
    pub fn default_for_image(width: u32, height: u32) -> Result<Self, MeshError> {
        let (w, h) = (f64::from(width), f64::from(height));
        Self::from_intrinsics(
            [(w * w + h * h).sqrt(); 2],
            [(w - 1.0) / 2.0, (h - 1.0) / 2.0],
            width,
            height,
        )
    }

    /// A camera with identity extrinsics and intrinsics `fx, fy, cx, cy` (pixels).
    ///
    /// # Errors
    /// A zero size, or focal lengths that are not positive and finite.
    pub fn from_intrinsics(
        [fx, fy]: [f64; 2],
        [cx, cy]: [f64; 2],
        width: u32,
        height: u32,
    ) -> Result<Self, MeshError> {
        Self::new(
            DMat3::from_cols(
                DVec3::new(fx, 0.0, 0.0),
                DVec3::new(0.0, fy, 0.0),
                DVec3::new(cx, cy, 1.0),
            ),
            DMat3::IDENTITY,
            DVec3::ZERO,
            width,
            height,
        )
    }

    /// Focal lengths `(fx, fy)` in pixels.
    pub fn focal(&self) -> DVec2 {
        DVec2::new(self.intrinsics.x_axis.x, self.intrinsics.y_axis.y)
    }

    /// Principal point `(cx, cy)` in pixels.
    pub fn principal_point(&self) -> DVec2 {
        DVec2::new(self.intrinsics.z_axis.x, self.intrinsics.z_axis.y)
    }

    /// World point to camera frame.
    pub fn world_to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// Camera-frame point to world frame.
    pub fn camera_to_world(&self, p: DVec3) -> DVec3 {
        self.rotation.transpose() * (p - self.translation)
    }

    /// Camera-frame point to pixel coordinates (`K p / p.z`); `None` behind or on the camera plane.
    pub fn camera_to_pixel(&self, p: DVec3) -> Option<DVec2> {
        if p.z <= 0.0 {
            return None;
        }
        let q = self.intrinsics * p;
        Some(DVec2::new(q.x / q.z, q.y / q.z))
    }

    /// World point to pixel coordinates.
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        self.camera_to_pixel(self.world_to_camera(p))
    }

    /// Pixel and camera-frame depth to camera-frame point (inverse of [`Self::camera_to_pixel`]).
    pub fn unproject(&self, pixel: DVec2, depth: f64) -> DVec3 {
        let c = self.principal_point();
        let f = self.focal();
        let skew = self.intrinsics.y_axis.x;
        let y = (pixel.y - c.y) / f.y;
        let x = (pixel.x - c.x - skew * y) / f.x;
        DVec3::new(x * depth, y * depth, depth)
    }

    /// The camera centre in world coordinates.
    pub fn center(&self) -> DVec3 {
        -(self.rotation.transpose() * self.translation)
    }
}

/// An orthographic camera: `pixel = scale * (R x + t).xy + offset`, depth = `(R x + t).z`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OrthographicCamera {
    /// World-to-camera rotation.
    pub rotation: DMat3,
    /// World-to-camera translation.
    pub translation: DVec3,
    /// Pixels per metre.
    pub scale: f64,
    /// Pixel position of the camera-frame origin.
    pub offset: DVec2,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl OrthographicCamera {
    /// World point to camera frame.
    pub fn world_to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    /// World point to pixel coordinates (always defined).
    pub fn project(&self, p: DVec3) -> DVec2 {
        let c = self.world_to_camera(p);
        DVec2::new(c.x, c.y) * self.scale + self.offset
    }

    /// An orthographic camera that frames `points` (seen along `rotation`) in a
    /// `width x height` image with `margin` (a fraction of the image) left around them.
    pub fn framing(
        points: &[DVec3],
        rotation: DMat3,
        width: u32,
        height: u32,
        margin: f64,
    ) -> Result<Self, MeshError> {
        if points.is_empty() || points.iter().any(|p| !p.is_finite()) {
            return Err(MeshError::InvalidParams(
                "orthographic framing needs finite points".into(),
            ));
        }
        let cam: Vec<DVec3> = points.iter().map(|p| rotation * *p).collect();
        let lo = cam
            .iter()
            .fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
        let hi = cam
            .iter()
            .fold(DVec3::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
        let extent = (hi - lo).truncate().max(DVec2::splat(1e-9));
        let usable = DVec2::new(width as f64, height as f64) * (1.0 - 2.0 * margin).max(0.05);
        let scale = (usable / extent).min_element();
        let centre = (hi + lo) * 0.5;
        // Put the camera 1 m in front of the nearest point so depths are positive.
        let translation = DVec3::new(-centre.x, -centre.y, 1.0 - lo.z);
        Ok(OrthographicCamera {
            rotation,
            translation,
            scale,
            offset: DVec2::new(width as f64 / 2.0, height as f64 / 2.0),
            width,
            height,
        })
    }
}

/// An axis-aligned 2D box in pixels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PixelBox {
    /// Smallest x and y.
    pub min: DVec2,
    /// Largest x and y.
    pub max: DVec2,
}

impl PixelBox {
    /// The bounding box of `points`, or `None` when there are none.
    pub fn around(points: impl IntoIterator<Item = DVec2>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = it.next()?;
        Some(it.fold(
            PixelBox {
                min: first,
                max: first,
            },
            |b, p| PixelBox {
                min: b.min.min(p),
                max: b.max.max(p),
            },
        ))
    }

    /// Width and height.
    pub fn size(&self) -> DVec2 {
        self.max - self.min
    }
}

/// `camera` orbited about `center` (a point in `camera`'s frame): turned by `yaw` radians
/// about the camera's vertical axis and `pitch` about its horizontal axis, so it sees the
/// same hands from another side (a turntable view).
pub fn orbit_camera(camera: &PinholeCamera, center: DVec3, yaw: f64, pitch: f64) -> PinholeCamera {
    let turn = DMat3::from_rotation_x(pitch) * DMat3::from_rotation_y(yaw);
    PinholeCamera {
        rotation: turn * camera.rotation,
        translation: turn * (camera.translation - center) + center,
        ..*camera
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> PinholeCamera {
        let r = DMat3::from_rotation_y(0.3) * DMat3::from_rotation_x(-0.2);
        let k = DMat3::from_cols(
            DVec3::new(500.0, 0.0, 0.0),
            DVec3::new(0.0, 480.0, 0.0),
            DVec3::new(128.0, 120.0, 1.0),
        );
        PinholeCamera::new(k, r, DVec3::new(0.01, -0.02, 0.5), 256, 256).unwrap()
    }

    #[test]
    fn project_unproject_round_trip() {
        let cam = camera();
        let p = DVec3::new(0.03, -0.01, 0.1);
        let c = cam.world_to_camera(p);
        let px = cam.camera_to_pixel(c).unwrap();
        let back = cam.camera_to_world(cam.unproject(px, c.z));
        assert!((back - p).length() < 1e-12, "{back} vs {p}");
        assert!((cam.world_to_camera(cam.center())).length() < 1e-12);
    }

    #[test]
    fn projection_matches_k_formula() {
        let cam = PinholeCamera::looking_down_z(100.0, 64, 48);
        let px = cam.project(DVec3::new(0.1, -0.2, 2.0)).unwrap();
        assert!((px - DVec2::new(32.0 + 5.0, 24.0 - 10.0)).length() < 1e-12);
        assert!(cam.project(DVec3::new(0.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn degenerate_cameras_are_rejected() {
        let r = DMat3::IDENTITY;
        assert!(PinholeCamera::new(DMat3::ZERO, r, DVec3::ZERO, 10, 10).is_err());
        let k = PinholeCamera::looking_down_z(10.0, 8, 8).intrinsics;
        assert!(PinholeCamera::new(k, r, DVec3::new(f64::NAN, 0.0, 0.0), 8, 8).is_err());
        assert!(PinholeCamera::new(k, r * 2.0, DVec3::ZERO, 8, 8).is_err());
    }

    #[test]
    fn orthographic_framing_fits_points() {
        let pts = [DVec3::new(-0.1, -0.05, 0.0), DVec3::new(0.1, 0.05, 0.2)];
        let cam = OrthographicCamera::framing(&pts, DMat3::IDENTITY, 200, 100, 0.1).unwrap();
        let b = PixelBox::around(pts.iter().map(|p| cam.project(*p))).unwrap();
        assert!(
            b.min.x >= 19.9 && b.max.x <= 180.1 && b.min.y >= 9.9 && b.max.y <= 90.1,
            "{b:?}"
        );
        assert!((b.size().x - 160.0).abs() < 1e-9 || (b.size().y - 80.0).abs() < 1e-9);
    }
}
