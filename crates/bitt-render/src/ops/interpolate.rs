//! [`interpolate`]: per-vertex attributes at the covered pixels.

use burn::tensor::Tensor;

use super::{Raster, check_shape};
use crate::error::RenderError;

/// Interpolates per-vertex attributes (UVs, normals, world positions, colours) at the covered
/// pixels of a [`Raster`] with its perspective-correct barycentrics.
///
/// Differentiable in the attributes and, through the barycentrics, in the clip positions.
///
/// # Shapes
/// attributes `[V, A]`, raster with `N` covered pixels -> `[N, A]`
///
/// # Errors
/// When `attributes` has not one row per vertex of the rasterized mesh.
pub fn interpolate(attributes: Tensor<2>, raster: &Raster) -> Result<Tensor<2>, RenderError> {
    let [v, a] = attributes.dims();
    let num_vertices = raster.clip_host.len();
    check_shape("attributes", [v, a], [Some(num_vertices), None], || {
        format!("[V, A] with V = {num_vertices} (the rasterized mesh's vertices)")
    })?;
    let n = raster.num_covered();
    if n == 0 {
        return Ok(Tensor::zeros([0, a], &attributes.device()));
    }
    Ok(blend(attributes, raster.corners.clone(), raster))
}

/// Gathers the corner rows `corners [3 N]` and blends them with the raster's barycentrics.
fn blend(
    attributes: Tensor<2>,
    corners: Tensor<1, burn::tensor::Int>,
    raster: &Raster,
) -> Tensor<2> {
    let (n, a) = (raster.num_covered(), attributes.dims()[1]);
    let corner_values = attributes.select(0, corners).reshape([n, 3, a]);
    let weights = raster.bary.clone().reshape([n, 3, 1]);
    (corner_values * weights).sum_dim(1).reshape([n, a])
}

/// Interpolates attributes indexed by their own faces (nvdiffrast's `tri` argument), e.g.
/// UVs whose vertices differ from the mesh's: `faces[f]` are the attribute rows of face
/// `f`'s corners, in the mesh face's corner order.
///
/// # Shapes
/// attributes `[U, A]`, `faces` one triple per mesh face -> `[N, A]`
///
/// # Errors
/// When `faces` has not one triple per face of the rasterized mesh or indexes past `U`.
pub fn interpolate_with_faces(
    attributes: Tensor<2>,
    faces: &[[u32; 3]],
    raster: &Raster,
) -> Result<Tensor<2>, RenderError> {
    let [u, a] = attributes.dims();
    crate::error::check_faces(faces, u)?;
    let n = raster.num_covered();
    let device = attributes.device();
    let mut corners = Vec::with_capacity(3 * n);
    for &pixel in raster.covered() {
        let f = raster.fragments.face[pixel as usize] as usize;
        let tri = faces.get(f).ok_or(RenderError::BufferLength {
            what: "attribute faces",
            expected: f + 1,
            actual: faces.len(),
        })?;
        corners.extend(tri.iter().map(|&i| i64::from(i)));
    }
    if n == 0 {
        return Ok(Tensor::zeros([0, a], &device));
    }
    Ok(blend(
        attributes,
        super::index_tensor(corners, &device),
        raster,
    ))
}
