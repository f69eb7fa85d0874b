//! Unwrapping: from an image to a mesh's compact texel vector, with the visible mask.
//!
//! Every texel of a UV layout has a 3D surface point (its face and barycentrics, found once
//! per layout by rasterizing the mesh in UV space: [`bitt_texture::TextureLayout`]). A texel
//! is *visible* in an image when its point
//! * projects inside the image,
//! * faces the camera (interpolated normal towards the camera), and
//! * passes the depth test against the scene's depth buffer (all meshes, so the other hand
//!   occludes too) at all four pixels its bilinear sample reads: each is covered and shows a
//!   surface within a tolerance of the texel's view depth. A nearer surface there occludes
//!   the texel; an empty pixel or a farther surface would bleed background or the other
//!   hand into the sample along silhouettes, so those texels count as not visible either.
//!
//! Its value is the bilinear sample of the image at the projected point. The sampling is a
//! [`crate::texture`] call, so the result is differentiable in the image (an albedo network's
//! output); visibility has no gradient.

use bitt_mesh::glam::DVec3;
use bitt_texture::TextureLayout;
use burn::tensor::Tensor;

use super::{Camera, DepthRange};
use crate::error::RenderError;
use crate::ops::{Raster, float_tensor, texture};

/// The surface point of every texel of a layout on a mesh: face and barycentrics.
#[derive(Debug, Clone, PartialEq)]
pub struct TexelSurface {
    texel_faces: Vec<(u32, [f32; 3])>,
    mesh_faces: Vec<[u32; 3]>,
    num_vertices: usize,
}

impl TexelSurface {
    /// The texel surface of `layout` on a mesh with `mesh_faces` over `num_vertices`
    /// vertices (the layout's UV faces must be the mesh's faces, in order).
    ///
    /// # Errors
    /// A layout without texel faces, or one naming faces the mesh does not have.
    pub fn new(
        layout: &TextureLayout,
        mesh_faces: &[[u32; 3]],
        num_vertices: usize,
    ) -> Result<Self, RenderError> {
        let texel_faces = layout.texel_faces().ok_or_else(|| {
            RenderError::BadLayout(
                "the layout has no per-texel faces (built from an index map?)".into(),
            )
        })?;
        crate::error::check_faces(mesh_faces, num_vertices)?;
        if let Some((t, &(f, _))) = texel_faces
            .iter()
            .enumerate()
            .find(|(_, (f, _))| *f as usize >= mesh_faces.len())
        {
            return Err(RenderError::BadLayout(format!(
                "texel {t} lies on face {f}, but the mesh has {} faces",
                mesh_faces.len()
            )));
        }
        Ok(Self {
            texel_faces: texel_faces.to_vec(),
            mesh_faces: mesh_faces.to_vec(),
            num_vertices,
        })
    }

    /// Number of texels `T`.
    pub fn num_texels(&self) -> usize {
        self.texel_faces.len()
    }

    fn check(&self, vertices: &[DVec3]) -> Result<(), RenderError> {
        crate::error::check_len("vertices", vertices.len(), self.num_vertices)?;
        if let Some(i) = vertices.iter().position(|v| !v.is_finite()) {
            let v = vertices[i];
            return Err(RenderError::NonFinitePosition {
                vertex: i,
                value: [v.x as f32, v.y as f32, v.z as f32, 1.0],
            });
        }
        Ok(())
    }

    /// Texel surface points on the posed mesh `vertices`.
    ///
    /// # Errors
    /// Wrong vertex count or non-finite vertices.
    pub fn points(&self, vertices: &[DVec3]) -> Result<Vec<DVec3>, RenderError> {
        self.check(vertices)?;
        Ok(self.at_texels(vertices).collect())
    }

    /// Per-vertex values interpolated at every texel with its face's barycentrics.
    fn at_texels<'a>(&'a self, values: &'a [DVec3]) -> impl Iterator<Item = DVec3> + 'a {
        self.texel_faces.iter().map(move |&(f, b)| {
            let t = self.mesh_faces[f as usize];
            (0..3)
                .map(|k| values[t[k] as usize] * f64::from(b[k]))
                .sum()
        })
    }

    /// Per-vertex values (e.g. ambient occlusion) interpolated at every texel.
    ///
    /// # Errors
    /// A value count other than the mesh's vertex count.
    pub fn values(&self, per_vertex: &[f32]) -> Result<Vec<f32>, RenderError> {
        crate::error::check_len("per-vertex values", per_vertex.len(), self.num_vertices)?;
        Ok(self
            .texel_faces
            .iter()
            .map(|&(f, b)| {
                let t = self.mesh_faces[f as usize];
                (0..3).map(|k| per_vertex[t[k] as usize] * b[k]).sum()
            })
            .collect())
    }

    /// Unit surface normals at the texels (interpolated area-weighted vertex normals).
    ///
    /// # Errors
    /// Wrong vertex count or non-finite vertices.
    pub fn normals(&self, vertices: &[DVec3]) -> Result<Vec<DVec3>, RenderError> {
        self.check(vertices)?;
        let vn = bitt_mesh::model::vertex_normals(vertices, &self.mesh_faces);
        Ok(self.at_texels(&vn).map(DVec3::normalize_or_zero).collect())
    }
}

/// Unwrapping tolerances.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UnwrapSettings {
    /// How far (scene units; metres for MANO) behind the depth buffer a texel may lie and
    /// still count as visible: absorbs the depth difference between a texel's point and the
    /// surface at the pixel centre it projects near. 5 mm by default, under a third of a
    /// finger's thickness, so a finger in front still occludes.
    pub depth_tolerance: f64,
    /// The projection's depth range (must match the render that made the depth buffer).
    pub depth: DepthRange,
}

impl Default for UnwrapSettings {
    fn default() -> Self {
        Self {
            depth_tolerance: 0.005,
            depth: DepthRange::default(),
        }
    }
}

/// The visible texels of one mesh in an image.
#[derive(Debug, Clone)]
pub struct Unwrapped {
    /// `u`: `[C, T]` the sampled colour of visible texels, 0 elsewhere (differentiable in the
    /// image).
    pub texels: Tensor<2>,
    /// `v`: `[1, T]` visible mask (1 visible, 0 not).
    pub visible: Tensor<2>,
    /// The visible mask on the host.
    pub visible_host: Vec<bool>,
}

/// Where each texel of one mesh lands in an image and whether it is visible there: the
/// discrete, geometry-only part of [`unwrap`]. A per-scene trainer plans once (meshes and
/// camera are fixed) and applies the plan to a new image every iteration.
#[derive(Debug, Clone)]
pub struct UnwrapPlan {
    /// Per texel, the `texture` sample position in the image (`[T, 2]` row-major,
    /// `align_corners`, `v = 0` at the bottom row).
    uv: Vec<f32>,
    /// Per texel, visible in the image.
    visible: Vec<bool>,
    /// Image size `[H, W]` the plan was made for.
    size: [usize; 2],
}

impl UnwrapPlan {
    /// Plans the unwrap of one mesh into images of `camera` (see the module docs and
    /// [`unwrap`]).
    ///
    /// # Errors
    /// A raster of another size than the camera's, wrong vertex counts, non-finite vertices,
    /// an unusable camera.
    pub fn new(
        camera: &Camera,
        surface: &TexelSurface,
        vertices: &[DVec3],
        raster: &Raster,
        settings: &UnwrapSettings,
    ) -> Result<Self, RenderError> {
        camera.validate()?;
        let (h, w) = (camera.height(), camera.width());
        if [raster.height(), raster.width()] != [h, w] {
            return Err(RenderError::TensorShape {
                what: "raster",
                expected: format!("{h}x{w} (the camera's size)"),
                actual: vec![raster.height(), raster.width()],
            });
        }
        let points = surface.points(vertices)?;
        let normals = surface.normals(vertices)?;
        let t = points.len();
        let mut visible = vec![false; t];
        let mut uv = vec![0.0f32; 2 * t];
        let frags = &raster.fragments;
        for k in 0..t {
            let clip = camera.clip_point(points[k], settings.depth);
            if clip.w <= 0.0 {
                continue;
            }
            let (x, y, z) = (clip.x / clip.w, clip.y / clip.w, clip.z / clip.w);
            // Continuous pixel coordinates, pixel centres at c + 1/2.
            let (px, py) = ((x + 1.0) * w as f64 / 2.0, (y + 1.0) * h as f64 / 2.0);
            // Sample position for `texture` (align_corners, v = 0 at the bottom row).
            uv[2 * k] = if w > 1 {
                ((px - 0.5) / (w - 1) as f64) as f32
            } else {
                0.0
            };
            uv[2 * k + 1] = if h > 1 {
                (1.0 - (py - 0.5) / (h - 1) as f64) as f32
            } else {
                0.0
            };
            if !(0.0..w as f64).contains(&px) || !(0.0..h as f64).contains(&py) {
                continue;
            }
            if normals[k].dot(camera.towards_camera(points[k])) <= 0.0 {
                continue;
            }
            // The bilinear taps around the point must all show this surface: covered, and at
            // the texel's depth within the tolerance (a nearer surface occludes it; a
            // background or a farther surface at a tap would bleed into the sample at a
            // silhouette).
            let texel_depth = camera.view_depth(z, settings.depth);
            visible[k] = bilinear_taps(px, py, [h, w]).iter().all(|&(col, row)| {
                let buffer = frags.depth[row * w + col];
                buffer.is_finite()
                    && (camera.view_depth(f64::from(buffer), settings.depth) - texel_depth).abs()
                        <= settings.depth_tolerance
            });
        }
        Ok(Self {
            uv,
            visible,
            size: [h, w],
        })
    }

    /// Per texel, visible in the image.
    pub fn visible(&self) -> &[bool] {
        &self.visible
    }

    /// Keeps only the visible texels whose four bilinear taps all lie on pixels `keep`
    /// `[H * W]` trusts (a photo's hand pixels): the others become not visible, so nothing is
    /// unwrapped from the background or a dark shadow at them. Returns how many were dropped.
    ///
    /// # Errors
    /// A mask of another size than the plan's image.
    pub fn restrict(&mut self, keep: &[bool]) -> Result<usize, RenderError> {
        let [h, w] = self.size;
        if keep.len() != h * w {
            return Err(RenderError::TensorShape {
                what: "pixel mask",
                expected: format!("{} (the plan's {h}x{w} pixels)", h * w),
                actual: vec![keep.len()],
            });
        }
        let mut dropped = 0;
        for k in 0..self.visible.len() {
            if !self.visible[k] {
                continue;
            }
            // Back from the sample position to continuous pixels (see `new`).
            let px = f64::from(self.uv[2 * k]) * (w.max(2) - 1) as f64 + 0.5;
            let py = (1.0 - f64::from(self.uv[2 * k + 1])) * (h.max(2) - 1) as f64 + 0.5;
            let trusted = bilinear_taps(px, py, [h, w])
                .iter()
                .all(|&(col, row)| keep[row * w + col]);
            if !trusted {
                self.visible[k] = false;
                dropped += 1;
            }
        }
        Ok(dropped)
    }

    /// Number of texels `T`.
    pub fn num_texels(&self) -> usize {
        self.visible.len()
    }

    /// Samples `image` at the planned positions: `u` and `v` (differentiable in the image).
    ///
    /// # Shapes
    /// image `[C, H, W]` -> texels `[C, T]`, visible `[1, T]`
    ///
    /// # Errors
    /// An image of another size than the plan's.
    pub fn apply(&self, image: Tensor<3>) -> Result<Unwrapped, RenderError> {
        let [c, h, w] = image.dims();
        crate::ops::check_shape(
            "image",
            [c, h, w],
            [None, Some(self.size[0]), Some(self.size[1])],
            || {
                format!(
                    "[C, {}, {}] (the camera's size)",
                    self.size[0], self.size[1]
                )
            },
        )?;
        let t = self.num_texels();
        let device = image.device();
        let samples = texture(image, float_tensor(self.uv.clone(), [t, 2], &device))?;
        let mask: Vec<f32> = self
            .visible
            .iter()
            .map(|&v| if v { 1.0 } else { 0.0 })
            .collect();
        let mask = float_tensor(mask, [1, t], &device);
        Ok(Unwrapped {
            texels: samples.swap_dims(0, 1) * mask.clone(),
            visible: mask,
            visible_host: self.visible.clone(),
        })
    }
}

/// The four pixels `(col, row)` a bilinear sample at continuous pixel `(px, py)` (pixel
/// centres at `c + 1/2`) reads, clamped to the image `[h, w]`.
fn bilinear_taps(px: f64, py: f64, [h, w]: [usize; 2]) -> [(usize, usize); 4] {
    let (c0, r0) = ((px - 0.5).floor(), (py - 0.5).floor());
    let at = |c: f64, r: f64| {
        (
            c.clamp(0.0, (w - 1) as f64) as usize,
            r.clamp(0.0, (h - 1) as f64) as usize,
        )
    };
    [
        at(c0, r0),
        at(c0 + 1.0, r0),
        at(c0, r0 + 1.0),
        at(c0 + 1.0, r0 + 1.0),
    ]
}

/// Unwraps `image` onto the texels of one mesh (see the module docs):
/// [`UnwrapPlan::new`] then [`UnwrapPlan::apply`].
///
/// `raster` is the depth buffer of the whole scene in this camera (e.g.
/// [`super::SceneRender::raster`] of both hands); `vertices` are this mesh's world vertices.
///
/// # Shapes
/// image `[C, H, W]` -> texels `[C, T]`, visible `[1, T]`
///
/// # Errors
/// Image or raster sizes different from the camera's, wrong vertex counts, non-finite
/// vertices, an unusable camera.
pub fn unwrap(
    image: Tensor<3>,
    camera: &Camera,
    surface: &TexelSurface,
    vertices: &[DVec3],
    raster: &Raster,
    settings: &UnwrapSettings,
) -> Result<Unwrapped, RenderError> {
    camera.validate()?;
    let [c, h, w] = image.dims();
    crate::ops::check_shape(
        "image",
        [c, h, w],
        [None, Some(camera.height()), Some(camera.width())],
        || {
            format!(
                "[C, {}, {}] (the camera's size)",
                camera.height(),
                camera.width()
            )
        },
    )?;
    UnwrapPlan::new(camera, surface, vertices, raster, settings)?.apply(image)
}

/// Texture-space visibility of a scene (the paper's Table 3) for two meshes sharing one
/// layout (texel `i` of one is texel `i` of the other): fractions of the `T` texels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelVisibilityStats {
    /// Number of texels per hand.
    pub num_texels: usize,
    /// Visible on the left hand.
    pub left_visible: f64,
    /// Visible on the right hand.
    pub right_visible: f64,
    /// Usable through symmetry: visible on exactly one hand.
    pub symmetric_usable: f64,
    /// Visible on neither hand.
    pub invisible: f64,
}

impl TexelVisibilityStats {
    /// Statistics of two visible masks of equal length.
    ///
    /// # Errors
    /// Masks of different lengths.
    pub fn from_masks(left: &[bool], right: &[bool]) -> Result<Self, RenderError> {
        crate::error::check_len("right visible mask", right.len(), left.len())?;
        let t = left.len().max(1) as f64;
        let count = |f: &dyn Fn(bool, bool) -> bool| {
            left.iter().zip(right).filter(|(l, r)| f(**l, **r)).count() as f64 / t
        };
        Ok(Self {
            num_texels: left.len(),
            left_visible: count(&|l, _| l),
            right_visible: count(&|_, r| r),
            symmetric_usable: count(&|l, r| l != r),
            invisible: count(&|l, r| !l && !r),
        })
    }

    /// Averages statistics (e.g. over the scenes of a benchmark), weighting scenes equally.
    pub fn mean(all: &[Self]) -> Option<Self> {
        let n = all.len() as f64;
        (!all.is_empty()).then(|| Self {
            num_texels: all[0].num_texels,
            left_visible: all.iter().map(|s| s.left_visible).sum::<f64>() / n,
            right_visible: all.iter().map(|s| s.right_visible).sum::<f64>() / n,
            symmetric_usable: all.iter().map(|s| s.symmetric_usable).sum::<f64>() / n,
            invisible: all.iter().map(|s| s.invisible).sum::<f64>() / n,
        })
    }
}
