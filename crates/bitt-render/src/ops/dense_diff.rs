//! [`dense_barycentrics`] and [`interpolate_dense`]: the differentiable part of
//! [`super::rasterize`] and [`super::interpolate`] over every pixel of a [`DenseRaster`], so
//! that the discrete decisions stay on the device (no host readback).

use burn::tensor::{Bool, Int, Tensor, TensorData};

use super::{DenseRaster, Topology, check_shape, float_tensor};
use crate::error::RenderError;

/// Differentiable perspective-correct barycentrics and depth at every pixel of an image, as
/// nvdiffrast's `rasterize` output: rows are pixels in row-major order (`row * W + col`).
///
/// Covered pixels hold the values (and the clip gradient) of [`super::rasterize`]; empty
/// pixels hold zeros and get no gradient.
#[derive(Debug, Clone)]
pub struct DenseBarycentrics {
    height: usize,
    width: usize,
    num_vertices: usize,
    num_faces: usize,
    /// `[H W]`: face id per pixel, 0 on empty pixels (a safe index to gather with).
    face: Tensor<1, Int>,
    /// `[H W]`: true where a face covers the pixel centre.
    covered: Tensor<1, Bool>,
    /// `[3 H W]`: vertex ids of each pixel's face corners (face 0's on empty pixels).
    corners: Tensor<1, Int>,
    /// `[H W, 3]`: perspective-correct barycentrics, differentiable in the clip positions,
    /// zero on empty pixels.
    pub bary: Tensor<2>,
    /// `[H W]`: NDC depth z/w, differentiable in the clip positions, zero on empty pixels.
    pub depth: Tensor<1>,
}

impl DenseBarycentrics {
    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Coverage per pixel (no gradient).
    ///
    /// # Shapes
    /// `[H W]`
    pub fn covered(&self) -> Tensor<1, Bool> {
        self.covered.clone()
    }

    /// Face id per pixel with empty pixels set to 0 (use with [`DenseBarycentrics::covered`]).
    ///
    /// # Shapes
    /// `[H W]`
    pub fn face_or_zero(&self) -> Tensor<1, Int> {
        self.face.clone()
    }
}

/// The clip corners of a triangle covering the whole viewport at `w = 1`: substituted for
/// the corners of empty pixels so that every expression stays finite (a NaN there would turn
/// into a NaN gradient even behind a mask).
const SAFE_TRIANGLE: [f32; 12] = [
    -1.0, -1.0, 0.0, 1.0, 3.0, -1.0, 0.0, 1.0, -1.0, 3.0, 0.0, 1.0,
];

/// NDC coordinates `[H W, 2]` of every pixel centre (the values [`super::rasterize`] uses).
pub(crate) fn pixel_centres_ndc(
    height: usize,
    width: usize,
    device: &burn::tensor::Device,
) -> Tensor<2> {
    let mut ndc = Vec::with_capacity(2 * height * width);
    for row in 0..height {
        for col in 0..width {
            ndc.push((2.0 * (col as f64 + 0.5) / width as f64 - 1.0) as f32);
            ndc.push((2.0 * (row as f64 + 0.5) / height as f64 - 1.0) as f32);
        }
    }
    float_tensor(ndc, [height * width, 2], device)
}

/// The faces of `topology` as an `[F, 3]` integer tensor on `device`.
pub(crate) fn face_table(topology: &Topology, device: &burn::tensor::Device) -> Tensor<2, Int> {
    let flat: Vec<i64> = topology
        .faces()
        .iter()
        .flatten()
        .map(|&i| i64::from(i))
        .collect();
    Tensor::from_data(TensorData::new(flat, [topology.num_faces(), 3]), device)
}

/// Differentiable barycentrics and depth at every pixel of `dense`, from the clip positions
/// it was rasterized from: each pixel's face corners are gathered on the device and the
/// barycentrics and depth are the tensor expressions of [`super::rasterize`], so autodiff
/// gives the same interior gradient. Nothing is read back to the host (the faces and the
/// pixel centres are uploaded). `dense` must come from [`super::rasterize_dense`] with the
/// same `topology` (its face ids are not checked, which would need a readback).
///
/// # Shapes
/// dense `face [H, W]`, clip `[V, 4]`, topology over `V` vertices -> `bary [H W, 3]`,
/// `depth [H W]` (row-major pixels)
///
/// # Errors
/// A clip shape other than `[V, 4]`, or a topology without faces.
pub fn dense_barycentrics(
    dense: &DenseRaster,
    clip: Tensor<2>,
    topology: &Topology,
) -> Result<DenseBarycentrics, RenderError> {
    let v = topology.num_vertices();
    check_shape("clip", clip.dims(), [Some(v), Some(4)], || {
        format!("[V, 4] with V = {v} (the topology's vertices)")
    })?;
    let [height, width] = dense.face.dims();
    let n = height * width;
    let device = clip.device();
    if topology.num_faces() == 0 {
        return Err(RenderError::BadLayout(
            "dense barycentrics need at least one face".into(),
        ));
    }
    let table = face_table(topology, &device);
    let face = dense.face.clone().reshape([n]).cast(table.dtype());
    let covered = face.clone().greater_equal_elem(0);
    let face = face.clamp_min(0);
    let corners = table.select(0, face.clone()).reshape([3 * n]);
    let empty = covered.clone().bool_not();
    let safe = float_tensor(SAFE_TRIANGLE.to_vec(), [1, 3, 4], &device).repeat_dim(0, n);
    let c = clip
        .select(0, corners.clone())
        .reshape([n, 3, 4])
        .mask_where(empty.clone().reshape([n, 1, 1]).expand([n, 3, 4]), safe);
    let (bary, depth) =
        super::raster::barycentrics_of(c, pixel_centres_ndc(height, width, &device));
    let bary = bary.mask_fill(empty.clone().reshape([n, 1]).expand([n, 3]), 0.0);
    let depth = depth.mask_fill(empty, 0.0);
    Ok(DenseBarycentrics {
        height,
        width,
        num_vertices: v,
        num_faces: topology.num_faces(),
        face,
        covered,
        corners,
        bary,
        depth,
    })
}

/// Interpolates per-vertex attributes at every pixel with [`DenseBarycentrics`], zero on
/// empty pixels. Differentiable in the attributes and, through the barycentrics, in the
/// clip positions; equal to [`super::interpolate`] on covered pixels.
///
/// # Shapes
/// attributes `[V, A]` -> `[H W, A]`
///
/// # Errors
/// When `attributes` has not one row per vertex of the rasterized mesh.
pub fn interpolate_dense(
    attributes: Tensor<2>,
    raster: &DenseBarycentrics,
) -> Result<Tensor<2>, RenderError> {
    let [v, a] = attributes.dims();
    let want = raster.num_vertices;
    check_shape("attributes", [v, a], [Some(want), None], || {
        format!("[V, A] with V = {want} (the rasterized mesh's vertices)")
    })?;
    Ok(blend(attributes, raster.corners.clone(), raster))
}

/// Interpolates attributes indexed by their own faces (nvdiffrast's `tri` argument, e.g.
/// UVs) at every pixel, zero on empty pixels; equal to [`super::interpolate_with_faces`] on
/// covered pixels.
///
/// # Shapes
/// attributes `[U, A]`, `faces` one triple per mesh face -> `[H W, A]`
///
/// # Errors
/// When `faces` has not one triple per face of the rasterized mesh or indexes past `U`.
pub fn interpolate_dense_with_faces(
    attributes: Tensor<2>,
    faces: &[[u32; 3]],
    raster: &DenseBarycentrics,
) -> Result<Tensor<2>, RenderError> {
    let [u, _] = attributes.dims();
    crate::error::check_faces(faces, u)?;
    crate::error::check_len("attribute faces", faces.len(), raster.num_faces)?;
    let n = raster.height * raster.width;
    let flat: Vec<i64> = faces.iter().flatten().map(|&i| i64::from(i)).collect();
    let table: Tensor<2, Int> = Tensor::from_data(
        TensorData::new(flat, [faces.len(), 3]),
        &attributes.device(),
    );
    let corners = table.select(0, raster.face.clone()).reshape([3 * n]);
    Ok(blend(attributes, corners, raster))
}

/// Gathers the corner rows `corners [3 H W]` and blends them with the barycentrics.
fn blend(attributes: Tensor<2>, corners: Tensor<1, Int>, raster: &DenseBarycentrics) -> Tensor<2> {
    let (n, a) = (raster.height * raster.width, attributes.dims()[1]);
    let corner_values = attributes.select(0, corners).reshape([n, 3, a]);
    let weights = raster.bary.clone().reshape([n, 3, 1]);
    (corner_values * weights).sum_dim(1).reshape([n, a])
}
