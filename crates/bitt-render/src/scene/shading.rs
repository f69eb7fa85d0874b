//! Phong shading with a point light, as the reference's PyTorch3D `SoftPhongShader` computes
//! it, and vertex normals.

use burn::tensor::{IndexingUpdateOp, Tensor, activation::relu};

use crate::error::RenderError;
use crate::ops::{Topology, check_shape, float_tensor, index_tensor};

/// A point light with ambient, diffuse and specular colours, as PyTorch3D's `PointLights`.
/// All four parts are `[3]` tensors, so a light predicted by a network stays differentiable.
#[derive(Debug, Clone)]
pub struct PointLight {
    /// Ambient colour `[3]`.
    pub ambient: Tensor<1>,
    /// Diffuse colour `[3]`.
    pub diffuse: Tensor<1>,
    /// Specular colour `[3]`.
    pub specular: Tensor<1>,
    /// Location `[3]` in world coordinates.
    pub location: Tensor<1>,
}

pub use bitt_mesh::light::LightValues;

/// The renderer's side of [`LightValues`]: its check as a [`RenderError`] and its tensors.
pub trait LightValuesExt {
    /// Checks that every value is finite.
    ///
    /// # Errors
    /// [`RenderError::BadLight`] naming the first non-finite part.
    fn validate(&self) -> Result<(), RenderError>;

    /// The light as tensors on `device`.
    fn to_light(&self, device: &burn::tensor::Device) -> PointLight;
}

impl LightValuesExt for LightValues {
    fn validate(&self) -> Result<(), RenderError> {
        self.check_finite().map_err(RenderError::BadLight)
    }

    fn to_light(&self, device: &burn::tensor::Device) -> PointLight {
        let t = |v: [f32; 3]| float_tensor(v.to_vec(), [3], device);
        PointLight {
            ambient: t(self.ambient),
            diffuse: t(self.diffuse),
            specular: t(self.specular),
            location: t(self.location),
        }
    }
}

impl PointLight {
    /// The same light cut from the autodiff graph: no gradient flows back through it.
    pub fn detach(&self) -> Self {
        PointLight {
            ambient: self.ambient.clone().detach(),
            diffuse: self.diffuse.clone().detach(),
            specular: self.specular.clone().detach(),
            location: self.location.clone().detach(),
        }
    }

    /// A light from a `[12]` tensor (ambient, diffuse, specular, location), keeping its
    /// gradient.
    ///
    /// # Errors
    /// When `values` has not 12 elements.
    pub fn from_tensor(values: Tensor<1>) -> Result<Self, RenderError> {
        check_shape("light", values.dims(), [Some(12)], || "[12]".into())?;
        let part = |i: usize| values.clone().narrow(0, 3 * i, 3);
        Ok(Self {
            ambient: part(0),
            diffuse: part(1),
            specular: part(2),
            location: part(3),
        })
    }
}

/// Material reflectances; the reference uses ambient = diffuse = 1 and specular = 0.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Material {
    /// Ambient reflectance.
    pub ambient: [f32; 3],
    /// Diffuse reflectance.
    pub diffuse: [f32; 3],
    /// Specular reflectance.
    pub specular: [f32; 3],
    /// Phong exponent (PyTorch3D's default 64).
    pub shininess: f32,
}

impl Default for Material {
    /// The reference renderer's material (`build_renderer`): ambient 1, diffuse 1,
    /// specular 0, PyTorch3D's default shininess 64.
    fn default() -> Self {
        Self {
            ambient: [1.0; 3],
            diffuse: [1.0; 3],
            specular: [0.0; 3],
            shininess: 64.0,
        }
    }
}

/// Phong shading of per-pixel texels:
/// `color = (ka La + kd Ld max(0, n.l)) texel + ks Ls max(0, v.r)^shininess [n.l > 0]`,
/// with `l` the unit direction from the point to the light, `n` the unit normal, `v` the
/// unit direction to the camera and `r = 2 (n.l) n - l`, exactly as PyTorch3D's
/// `phong_shading` with `PointLights` and `Materials`.
///
/// # Shapes
/// texels, normals, points, to_camera `[N, 3]` -> `[N, 3]`
pub fn phong(
    texels: Tensor<2>,
    normals: Tensor<2>,
    points: Tensor<2>,
    to_camera: Tensor<2>,
    light: &PointLight,
    material: &Material,
) -> Tensor<2> {
    let device = texels.device();
    let row = |t: Tensor<1>| t.reshape([1, 3]);
    let konst = |v: [f32; 3]| float_tensor(v.to_vec(), [1, 3], &device);
    let n = normalize(normals);
    let l = normalize(row(light.location.clone()) - points);
    let v = normalize(to_camera);
    let cos = (n.clone() * l.clone()).sum_dim(1);
    let diffuse = row(light.diffuse.clone()) * konst(material.diffuse) * relu(cos.clone());
    let ambient = row(light.ambient.clone()) * konst(material.ambient);
    let lit = (ambient + diffuse) * texels;
    if material.specular.iter().all(|&k| k == 0.0) {
        return lit;
    }
    let facing = cos.clone().greater_elem(0.0).float();
    let reflect = n * (cos * 2.0) - l;
    let alpha = relu((v * reflect).sum_dim(1)) * facing;
    let spec = alpha.powf_scalar(material.shininess);
    lit + row(light.specular.clone()) * konst(material.specular) * spec
}

/// Normalizes rows, like `F.normalize(eps = 1e-6)`.
fn normalize(x: Tensor<2>) -> Tensor<2> {
    let norm = (x.clone() * x.clone()).sum_dim(1).sqrt().clamp_min(1e-6);
    x / norm
}

/// Area-weighted vertex normals (sum of the unnormalised face normals around each vertex,
/// then normalized), differentiable in the vertices, as PyTorch3D's `verts_normals`.
///
/// # Shapes
/// vertices `[V, 3]` -> `[V, 3]`
///
/// # Errors
/// When `vertices` has not the topology's vertex count.
pub fn vertex_normals(vertices: Tensor<2>, topology: &Topology) -> Result<Tensor<2>, RenderError> {
    let v = topology.num_vertices();
    check_shape("vertices", vertices.dims(), [Some(v), Some(3)], || {
        format!("[V, 3] with V = {v}")
    })?;
    let device = vertices.device();
    let corner = |k: usize| {
        index_tensor(
            topology.faces().iter().map(|t| i64::from(t[k])).collect(),
            &device,
        )
    };
    let (i0, i1, i2) = (corner(0), corner(1), corner(2));
    let p0 = vertices.clone().select(0, i0.clone());
    let p1 = vertices.clone().select(0, i1.clone());
    let p2 = vertices.select(0, i2.clone());
    let face_normal = cross(p1 - p0.clone(), p2 - p0);
    let sum = Tensor::<2>::zeros([v, 3], &device)
        .select_assign(0, i0, face_normal.clone(), IndexingUpdateOp::Add)
        .select_assign(0, i1, face_normal.clone(), IndexingUpdateOp::Add)
        .select_assign(0, i2, face_normal, IndexingUpdateOp::Add);
    Ok(normalize(sum))
}

/// Row-wise cross product of `[N, 3]` tensors.
pub(crate) fn cross(a: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    let n = a.dims()[0];
    let c = |t: &Tensor<2>, k: usize| t.clone().slice([0..n, k..k + 1]);
    Tensor::cat(
        vec![
            c(&a, 1) * c(&b, 2) - c(&a, 2) * c(&b, 1),
            c(&a, 2) * c(&b, 0) - c(&a, 0) * c(&b, 2),
            c(&a, 0) * c(&b, 1) - c(&a, 1) * c(&b, 0),
        ],
        1,
    )
}
