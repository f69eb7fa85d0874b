//! [`rasterize`]: coverage on the CPU core, barycentrics and depth as tensor expressions.

use burn::tensor::{Int, Tensor};

use super::{Topology, check_shape, float_tensor, index_tensor, read_f32};
use crate::error::RenderError;
use crate::raster::Fragments;

/// The output of [`rasterize`]: which face covers each pixel, and differentiable
/// barycentrics and depth for the covered pixels.
#[derive(Debug, Clone)]
pub struct Raster {
    /// The discrete result (face id per pixel, and non-differentiable copies of the
    /// barycentrics and depth), on the host.
    pub fragments: Fragments,
    /// The clip positions the raster was made from, on the host (used by [`super::antialias`]).
    pub(crate) clip_host: Vec<[f32; 4]>,
    /// Linear indices (`row * W + col`) of the covered pixels, ascending.
    covered: Vec<u32>,
    covered_tensor: Tensor<1, Int>,
    /// `[3 N]`: the vertex index of each covered pixel's face corners.
    pub(crate) corners: Tensor<1, Int>,
    /// `[H W]`: for each pixel its row in the covered list, `N` for empty pixels.
    pixel_row: Tensor<1, Int>,
    /// `[N, 3]`: perspective-correct barycentrics, differentiable in the clip positions.
    pub bary: Tensor<2>,
    /// `[N]`: NDC depth z/w, differentiable in the clip positions.
    pub depth: Tensor<1>,
}

impl Raster {
    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.fragments.height
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.fragments.width
    }

    /// Number of covered pixels `N`.
    pub fn num_covered(&self) -> usize {
        self.covered.len()
    }

    /// Linear indices (`row * W + col`) of the covered pixels, in the order of the rows of
    /// every per-pixel tensor.
    pub fn covered(&self) -> &[u32] {
        &self.covered
    }

    /// The covered pixel indices as an `[N]` tensor.
    pub fn covered_tensor(&self) -> Tensor<1, Int> {
        self.covered_tensor.clone()
    }

    /// Face id of each covered pixel.
    pub(crate) fn covered_faces(&self) -> Vec<u32> {
        self.covered
            .iter()
            .map(|&p| self.fragments.face[p as usize] as u32)
            .collect()
    }

    /// Scatters per-pixel values into an image; empty pixels get `background`.
    ///
    /// # Shapes
    /// values `[N, C]`, background `C` values -> image `[C, H, W]`
    ///
    /// # Panics
    /// When `values` has not `N` rows or `background` has not `C` values.
    pub fn to_image(&self, values: Tensor<2>, background: &[f32]) -> Tensor<3> {
        let [n, c] = values.dims();
        assert_eq!(
            n,
            self.num_covered(),
            "values must have one row per covered pixel"
        );
        assert_eq!(
            background.len(),
            c,
            "background must have one value per channel"
        );
        let device = values.device();
        let bg = float_tensor(background.to_vec(), [1, c], &device);
        Tensor::cat(vec![values, bg], 0)
            .select(0, self.pixel_row.clone())
            .swap_dims(0, 1)
            .reshape([c, self.height(), self.width()])
    }

    /// Gathers per-pixel values of an image at the covered pixels (the inverse of
    /// [`Raster::to_image`] on covered pixels).
    ///
    /// # Shapes
    /// image `[C, H, W]` -> values `[N, C]`
    pub fn gather(&self, image: Tensor<3>) -> Tensor<2> {
        let [c, h, w] = image.dims();
        assert_eq!(
            [h, w],
            [self.height(), self.width()],
            "image size must match the raster"
        );
        image
            .reshape([c, h * w])
            .select(1, self.covered_tensor.clone())
            .swap_dims(0, 1)
    }

    /// Coverage mask `[H, W]`: 1 where a face is drawn, 0 elsewhere (no gradient).
    pub fn mask(&self, device: &burn::tensor::Device) -> Tensor<2> {
        let m = self
            .fragments
            .face
            .iter()
            .map(|&f| if f >= 0 { 1.0 } else { 0.0 })
            .collect();
        float_tensor(m, [self.height(), self.width()], device)
    }

    /// Mask `[H, W]` of the pixels whose face lies in `faces` (e.g. one hand's faces of a
    /// concatenated two-hand mesh: its visible pixels after the shared depth test).
    pub(crate) fn face_range_mask(
        &self,
        faces: std::ops::Range<u32>,
        device: &burn::tensor::Device,
    ) -> Tensor<2> {
        let m = self
            .fragments
            .face
            .iter()
            .map(|&f| {
                if f >= 0 && faces.contains(&(f as u32)) {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        float_tensor(m, [self.height(), self.width()], device)
    }
}

/// Rasterizes a mesh: per pixel the nearest face, and for covered pixels perspective-correct
/// barycentrics and depth that are differentiable in the clip positions.
///
/// Coverage, clipping, the fill rule and the depth test are those of [`crate::cpu::rasterize`]
/// (see the crate docs for the conventions). The barycentrics of a covered pixel are then
/// recomputed from its face's clip vertices with the 2-D homogeneous edge functions: with
/// `X_j = x_j - p w_j`, `Y_j = y_j - q w_j` for the pixel centre at NDC `(p, q)`,
/// `b_j = (X_{j+1} Y_{j+2} - X_{j+2} Y_{j+1}) / D` with `D` the sum of the three numerators,
/// and depth is `sum b_j z_j / sum b_j w_j`. Their autodiff is the interior gradient of
/// [`crate::cpu::rasterize_backward`]; pixels entering or leaving coverage get gradients from
/// [`super::antialias`].
///
/// # Shapes
/// clip `[V, 4]` (x, y, z, w), topology over `V` vertices -> [`Raster`] with `bary [N, 3]`,
/// `depth [N]` for the `N` covered pixels of a `height x width` image.
///
/// # Errors
/// Wrong clip shape, non-finite positions, zero or oversized image.
pub fn rasterize(
    clip: Tensor<2>,
    topology: &Topology,
    height: usize,
    width: usize,
) -> Result<Raster, RenderError> {
    let v = topology.num_vertices();
    check_shape("clip", clip.dims(), [Some(v), Some(4)], || {
        format!("[V, 4] with V = {v} (the topology's vertices)")
    })?;
    let device = clip.device();
    let flat = read_f32("clip", clip.clone())?;
    let clip_host: Vec<[f32; 4]> = flat
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let fragments = crate::raster::rasterize(&clip_host, topology.faces(), width, height)?;

    let faces = topology.faces();
    let mut covered = Vec::new();
    let mut corners = Vec::new();
    let mut ndc = Vec::new();
    let mut pixel_row = Vec::with_capacity(width * height);
    for (pixel, &f) in fragments.face.iter().enumerate() {
        if f < 0 {
            pixel_row.push(-1);
            continue;
        }
        pixel_row.push(covered.len() as i64);
        covered.push(pixel as u32);
        corners.extend(faces[f as usize].iter().map(|&i| i64::from(i)));
        let (row, col) = (pixel / width, pixel % width);
        ndc.push((2.0 * (col as f64 + 0.5) / width as f64 - 1.0) as f32);
        ndc.push((2.0 * (row as f64 + 0.5) / height as f64 - 1.0) as f32);
    }
    let n = covered.len();
    let pixel_row = pixel_row
        .into_iter()
        .map(|r| if r < 0 { n as i64 } else { r })
        .collect();
    let covered_tensor = index_tensor(covered.iter().map(|&p| i64::from(p)).collect(), &device);
    let corners = index_tensor(corners, &device);
    let pixel_row = index_tensor(pixel_row, &device);

    let (bary, depth) = if n == 0 {
        (Tensor::zeros([0, 3], &device), Tensor::zeros([0], &device))
    } else {
        barycentrics(clip, corners.clone(), float_tensor(ndc, [n, 2], &device))
    };
    Ok(Raster {
        fragments,
        clip_host,
        covered,
        covered_tensor,
        corners,
        pixel_row,
        bary,
        depth,
    })
}

/// Perspective-correct barycentrics `[N, 3]` and depth `[N]` at pixel centres `ndc [N, 2]` of
/// the faces whose corners are `corners [3 N]`.
fn barycentrics(
    clip: Tensor<2>,
    corners: Tensor<1, Int>,
    ndc: Tensor<2>,
) -> (Tensor<2>, Tensor<1>) {
    let n = ndc.dims()[0];
    barycentrics_of(clip.select(0, corners).reshape([n, 3, 4]), ndc)
}

/// Perspective-correct barycentrics `[N, 3]` and depth `[N]` at pixel centres `ndc [N, 2]` of
/// the triangles whose clip corners are `c [N, 3, 4]` (the expressions of [`rasterize`]).
pub(super) fn barycentrics_of(c: Tensor<3>, ndc: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
    let n = ndc.dims()[0];
    let coord = |k: usize| c.clone().slice([0..n, 0..3, k..k + 1]).reshape([n, 3]);
    let (x, y, z, w) = (coord(0), coord(1), coord(2), coord(3));
    let p = ndc.clone().slice([0..n, 0..1]);
    let q = ndc.slice([0..n, 1..2]);
    let big_x = x - w.clone() * p;
    let big_y = y - w.clone() * q;
    let col = |t: &Tensor<2>, j: usize| t.clone().slice([0..n, j..j + 1]);
    let numerator = |j: usize| {
        let (a, b) = ((j + 1) % 3, (j + 2) % 3);
        col(&big_x, a) * col(&big_y, b) - col(&big_x, b) * col(&big_y, a)
    };
    let num = Tensor::cat(vec![numerator(0), numerator(1), numerator(2)], 1);
    let denom = num.clone().sum_dim(1);
    let bary = num / denom;
    let depth = (bary.clone() * z).sum_dim(1) / (bary.clone() * w).sum_dim(1);
    (bary, depth.reshape([n]))
}
