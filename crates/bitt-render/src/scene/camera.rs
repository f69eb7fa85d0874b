//! Cameras of the geometry crate to clip space.
//!
//! Pixel coordinates follow the reference's PyTorch3D setup (`cameras_from_opencv`-style
//! conversion of `K`): a projected point at pixel coordinate `u` lands at NDC
//! `x = 2 u / W - 1`, so the centre of pixel column `c` is `u = c + 1/2` (likewise rows).

use bitt_mesh::glam::{DMat4, DVec3, DVec4};
use bitt_mesh::{OrthographicCamera, PinholeCamera};
use burn::tensor::Tensor;

use crate::error::RenderError;
use crate::ops::{check_shape, float_tensor};

/// Depth range mapped to NDC z in `[-1, 1]` (scene units, metres for MANO).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DepthRange {
    /// Near plane distance (> 0).
    pub near: f64,
    /// Far plane distance (> near).
    pub far: f64,
}

impl Default for DepthRange {
    /// 1 cm to 100 m: hands are tens of centimetres to a few metres from the camera.
    fn default() -> Self {
        Self {
            near: 0.01,
            far: 100.0,
        }
    }
}

/// A camera the renderer can project with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Camera {
    /// Pinhole `K [R | t]` (OpenCV convention: x right, y down, z forward).
    Pinhole(PinholeCamera),
    /// Orthographic: `pixel = scale (R x + t).xy + offset`, depth `(R x + t).z`.
    Orthographic(OrthographicCamera),
}

impl Camera {
    /// Image width in pixels.
    pub fn width(&self) -> usize {
        match self {
            Camera::Pinhole(c) => c.width as usize,
            Camera::Orthographic(c) => c.width as usize,
        }
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        match self {
            Camera::Pinhole(c) => c.height as usize,
            Camera::Orthographic(c) => c.height as usize,
        }
    }

    /// The 4x4 matrix taking homogeneous world points (row vectors, `[x y z 1] M`) to clip
    /// space; its transpose maps column vectors.
    pub(crate) fn clip_matrix(&self, depth: DepthRange) -> DMat4 {
        let (w, h) = (self.width() as f64, self.height() as f64);
        let (n, f) = (depth.near, depth.far);
        match self {
            Camera::Pinhole(c) => {
                let k = c.intrinsics;
                let (fx, fy, skew) = (k.x_axis.x, k.y_axis.y, k.y_axis.x);
                let (cx, cy) = (k.z_axis.x, k.z_axis.y);
                // Camera frame -> clip (columns are the camera axes' images).
                let a = (f + n) / (f - n);
                let b = -2.0 * f * n / (f - n);
                let proj = DMat4::from_cols(
                    DVec4::new(2.0 * fx / w, 0.0, 0.0, 0.0),
                    DVec4::new(2.0 * skew / w, 2.0 * fy / h, 0.0, 0.0),
                    DVec4::new(2.0 * cx / w - 1.0, 2.0 * cy / h - 1.0, a, 1.0),
                    DVec4::new(0.0, 0.0, b, 0.0),
                );
                proj * extrinsics(c.rotation, c.translation)
            }
            Camera::Orthographic(c) => {
                let s = c.scale;
                let proj = DMat4::from_cols(
                    DVec4::new(2.0 * s / w, 0.0, 0.0, 0.0),
                    DVec4::new(0.0, 2.0 * s / h, 0.0, 0.0),
                    DVec4::new(0.0, 0.0, 2.0 / (f - n), 0.0),
                    DVec4::new(
                        2.0 * c.offset.x / w - 1.0,
                        2.0 * c.offset.y / h - 1.0,
                        -(f + n) / (f - n),
                        1.0,
                    ),
                );
                proj * extrinsics(c.rotation, c.translation)
            }
        }
    }

    /// Per point, the (unnormalised) direction towards the camera: to its centre for a
    /// pinhole camera, the constant viewing direction for an orthographic one.
    ///
    /// # Shapes
    /// points `[N, 3]` -> `[N, 3]`
    pub(crate) fn directions_to_camera(&self, points: Tensor<2>) -> Tensor<2> {
        let device = points.device();
        let n = points.dims()[0];
        match self {
            Camera::Pinhole(_) => {
                let c = self.center();
                float_tensor(vec![c.x as f32, c.y as f32, c.z as f32], [1, 3], &device) - points
            }
            Camera::Orthographic(_) => {
                let d = self.towards_camera(DVec3::ZERO);
                float_tensor(vec![d.x as f32, d.y as f32, d.z as f32], [1, 3], &device)
                    .repeat(&[n, 1])
            }
        }
    }

    /// Clip positions of world points, differentiable in the points.
    ///
    /// # Shapes
    /// points `[V, 3]` -> clip `[V, 4]`
    ///
    /// # Errors
    /// When `points` is not `[V, 3]`.
    pub fn clip_positions(
        &self,
        points: Tensor<2>,
        depth: DepthRange,
    ) -> Result<Tensor<2>, RenderError> {
        check_shape("points", points.dims(), [None, Some(3)], || "[V, 3]".into())?;
        let m = self.clip_matrix(depth);
        let device = points.device();
        // Row-vector form: clip = p M3^T + m4, with M3 the first three columns of M.
        let cols = m.to_cols_array_2d();
        let rows3: Vec<f32> = (0..3)
            .flat_map(|i| (0..4).map(move |j| cols[i][j] as f32))
            .collect();
        let offset: Vec<f32> = (0..4).map(|j| cols[3][j] as f32).collect();
        Ok(points.matmul(float_tensor(rows3, [3, 4], &device))
            + float_tensor(offset, [1, 4], &device))
    }

    /// Clip position of one world point (host, `f64`).
    pub fn clip_point(&self, p: DVec3, depth: DepthRange) -> DVec4 {
        self.clip_matrix(depth) * p.extend(1.0)
    }

    /// Unit vector from world point `p` towards the camera (towards its centre for a
    /// pinhole camera, against the viewing direction for an orthographic one).
    pub fn towards_camera(&self, p: DVec3) -> DVec3 {
        match self {
            Camera::Pinhole(c) => (c.center() - p).normalize_or_zero(),
            Camera::Orthographic(c) => -(c.rotation.transpose() * DVec3::Z),
        }
    }

    /// The camera centre in world coordinates; for an orthographic camera a point far back
    /// along the viewing direction (used for specular highlights).
    pub fn center(&self) -> DVec3 {
        match self {
            Camera::Pinhole(c) => c.center(),
            Camera::Orthographic(c) => {
                let origin = c.rotation.transpose() * (-c.translation);
                origin - c.rotation.transpose() * DVec3::Z * 1e3
            }
        }
    }

    /// Camera-frame depth (distance along the viewing axis) of an NDC depth `z/w`.
    pub(crate) fn view_depth(&self, ndc_z: f64, depth: DepthRange) -> f64 {
        let (n, f) = (depth.near, depth.far);
        match self {
            Camera::Pinhole(_) => {
                let a = (f + n) / (f - n);
                let b = -2.0 * f * n / (f - n);
                b / (ndc_z - a)
            }
            Camera::Orthographic(_) => (ndc_z + 1.0) * (f - n) / 2.0 + n,
        }
    }

    /// Checks that the camera is usable (finite, positive focal lengths / scale, non-empty
    /// image).
    ///
    /// # Errors
    /// A [`RenderError::BadCamera`] naming the problem.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |why: String| Err(RenderError::BadCamera(why));
        if self.width() == 0 || self.height() == 0 {
            return bad(format!("image size {}x{}", self.width(), self.height()));
        }
        match self {
            Camera::Pinhole(c) => {
                if let Err(e) = c.validate() {
                    return bad(e.to_string());
                }
            }
            Camera::Orthographic(c) => {
                let finite = c.rotation.is_finite() && c.translation.is_finite();
                if !(finite && c.scale.is_finite() && c.scale > 0.0 && c.offset.is_finite()) {
                    return bad("orthographic camera with non-finite values or scale <= 0".into());
                }
            }
        }
        Ok(())
    }
}

fn extrinsics(rotation: bitt_mesh::glam::DMat3, translation: DVec3) -> DMat4 {
    DMat4::from_cols(
        rotation.x_axis.extend(0.0),
        rotation.y_axis.extend(0.0),
        rotation.z_axis.extend(0.0),
        translation.extend(1.0),
    )
}
