//! [`rasterize_dense`]: the rasterizer as a backend operation with dense outputs on the
//! device, as nvdiffrast's `rasterize` returns them.

use burn::tensor::{Int, Tensor, TensorData};

use super::{Topology, check_shape, read_f32};
use crate::error::RenderError;

/// Which implementation produced a [`DenseRaster`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterKernel {
    /// The CubeCL kernel on the clip tensor's cubecl device (wgpu, CUDA): nothing was read
    /// back to the host.
    Cube,
    /// The CPU core on all cores ([`crate::cpu::rasterize_parallel`]): the clip positions were
    /// read back (on flex and ndarray a copy in memory) and the outputs uploaded.
    Host,
}

/// Per-pixel rasterizer outputs over the whole image, on the clip positions' device.
///
/// The discrete result of [`crate::cpu::rasterize`] as tensors: the same face ids, and
/// barycentrics and depth as the core computes them (not differentiable; [`super::rasterize`]
/// gives differentiable ones).
#[derive(Debug, Clone)]
pub struct DenseRaster {
    /// `[H, W]`: the nearest face per pixel, -1 where no face covers the pixel centre.
    pub face: Tensor<2, Int>,
    /// `[H, W, 3]`: perspective-correct barycentrics of the face's original vertices,
    /// 0 where empty.
    pub bary: Tensor<3>,
    /// `[H, W]`: NDC depth z/w, `+inf` where empty.
    pub depth: Tensor<2>,
    /// The implementation that ran.
    pub kernel: RasterKernel,
    /// Why the CubeCL kernel did not run (`None` when it did): e.g. not a cubecl device,
    /// or an adapter without `f64`/`i64` in shaders.
    pub host_reason: Option<&'static str>,
}

/// Rasterizes a mesh into dense per-pixel outputs that stay on the clip positions' device.
///
/// On a cubecl device whose shaders have `f64` and `i64` (wgpu on Vulkan, including Mesa's
/// lavapipe; CUDA) this is one CubeCL kernel run in three passes (nearest depth, lowest face
/// id among the nearest, then the winner's barycentrics), with no host round trip. Elsewhere
/// (flex, ndarray, adapters without 64-bit shader types) it is the CPU core on all cores.
/// Both make the decisions of [`crate::cpu::rasterize`]: clipping, snapping, the top-left fill
/// rule, the far-plane discard and the depth test with ties to the lower face index.
///
/// # Shapes
/// clip `[V, 4]` (x, y, z, w), topology over `V` vertices -> face `[H, W]`, bary
/// `[H, W, 3]`, depth `[H, W]` for `H = height`, `W = width`.
///
/// # Errors
/// Wrong clip shape, zero or oversized image; on the host path also non-finite positions.
pub fn rasterize_dense(
    clip: Tensor<2>,
    topology: &Topology,
    height: usize,
    width: usize,
) -> Result<DenseRaster, RenderError> {
    let v = topology.num_vertices();
    check_shape("clip", clip.dims(), [Some(v), Some(4)], || {
        format!("[V, 4] with V = {v} (the topology's vertices)")
    })?;
    let host_reason = match rasterize_on_device(&clip, topology, height, width)? {
        Ok(dense) => return Ok(dense),
        Err(why) => why,
    };
    let device = clip.device();
    let flat = read_f32("clip", clip)?;
    let clip_host: Vec<[f32; 4]> = flat
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let frags = crate::raster::rasterize_parallel(&clip_host, topology.faces(), width, height)?;
    let bary: Vec<f32> = frags.bary.iter().flatten().copied().collect();
    Ok(DenseRaster {
        face: Tensor::from_data(TensorData::new(frags.face, [height, width]), &device),
        bary: Tensor::from_data(TensorData::new(bary, [height, width, 3]), &device),
        depth: Tensor::from_data(TensorData::new(frags.depth, [height, width]), &device),
        kernel: RasterKernel::Host,
        host_reason: Some(host_reason),
    })
}

/// [`rasterize_dense`] when the CubeCL kernel can run on the clip tensor's device, or why
/// not (then nothing was done). The clip shape must have been checked.
///
/// # Errors
/// A zero or oversized image.
pub(crate) fn rasterize_on_device(
    clip: &Tensor<2>,
    topology: &Topology,
    height: usize,
    width: usize,
) -> Result<Result<DenseRaster, &'static str>, RenderError> {
    crate::error::check_image(width, height)?;
    Ok(
        crate::cube::rasterize(clip, topology.faces(), height, width).map(|(face, bary, depth)| {
            DenseRaster {
                face,
                bary,
                depth,
                kernel: RasterKernel::Cube,
                host_reason: None,
            }
        }),
    )
}
