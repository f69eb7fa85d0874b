//! nvdiffrast-style differentiable rendering for BiTT, in three layers:
//!
//! * [`cpu`] — the CPU core on host slices (`f32` in and out, `f64` inside): a z-buffer
//!   rasterizer with exact edge functions and near-plane clipping, interpolation, bilinear
//!   texture sampling, and their hand-written backward passes;
//! * [`ops`] — the primitives as burn tensor functions on any device ([`rasterize`],
//!   [`interpolate`], [`texture`], [`antialias`]): the discrete decisions (coverage,
//!   texel footprints, silhouette pairs) come from the core, the differentiable quantities
//!   are tensor expressions whose autodiff is the analytic gradient (see [`ops`]), and
//!   [`rasterize_dense`], the rasterizer as a backend operation with nvdiffrast's dense
//!   per-pixel outputs left on the device (a CubeCL kernel on wgpu/CUDA, the core on all
//!   cores elsewhere; the same face ids as [`cpu::rasterize`]), with its differentiable
//!   dense counterparts [`dense_barycentrics`], [`interpolate_dense`] and
//!   [`AntialiasPlan::from_dense`] that keep every decision on the device;
//! * [`scene`] — cameras to clip space, Phong shading with a point light as the reference's
//!   PyTorch3D setup computes it, several textured meshes in one depth test (the two
//!   hands; on a GPU without host readback), image-to-UV unwrapping with visible masks, and
//!   the paper's texel visibility statistics (Table 3).
//!
//! Architecture invariant: [`cpu`] and [`ops`] know triangles, attributes and images only;
//! [`scene`] knows meshes with UV layouts, cameras and lights, never hand models, texture
//! PCA or networks. Every gradient is burn autodiff of a tensor expression or a hand-written
//! backward pass checked against finite differences; the CPU core's backward passes are the
//! reference the [`ops`] gradients are tested against.
//!
//! # Conventions
//! * **Input** positions are clip space `[V][4]` = (x, y, z, w) as produced by a projection;
//!   NDC = xyz / w.
//! * **Image** is `height x width`, row-major, **row 0 at the top**. Pixel `(col, row)` has its
//!   centre at NDC `x = 2 (col + 0.5) / width - 1`, `y = 2 (row + 0.5) / height - 1`, so NDC y
//!   grows **down** the image, matching OpenCV pixel coordinates (x right, y down).
//! * **Depth** is NDC z = z/w, smaller is nearer. Triangles are clipped in homogeneous space
//!   (Sutherland–Hodgman) against `w >= 1e-6` and the near plane `z >= -w` (z/w = -1); fragments
//!   with z/w > 1 (beyond the far plane) are discarded. Empty pixels have depth `+inf`.
//! * **Faces** are `[F][3]` `u32` vertex indices. Both windings are rasterized (no culling).
//! * **Coverage**: vertices are snapped to 1/65536 pixel and edge functions are evaluated
//!   exactly (integers) at pixel centres with a top-left fill rule (a centre on an edge is
//!   drawn iff the edge is a top edge — interior below it, y down — or a left edge), so pixels
//!   on edges shared by two triangles are drawn exactly once. Screen coordinates are clamped to
//!   +-2^30 pixels (guard band). Zero-area triangles (after snapping) draw nothing.
//! * **Barycentrics** are computed from the unsnapped positions in `f64`: screen-space
//!   barycentrics at the pixel centre, divided by w per vertex and renormalised. A near-clipped
//!   face is split into up to 3 triangles whose vertices carry weights of the original
//!   vertices, so the output always refers to the original face. Because coverage uses snapped
//!   positions, barycentrics of pixels within ~1e-5 px of an edge may be very slightly negative.
//! * **Depth test**: nearest wins; ties go to the lower face index.
//! * **Backward**: [`cpu::rasterize_backward`] treats near-clipped faces like any other face (the
//!   barycentrics at a pixel centre do not depend on clipping); see its module docs for the
//!   derivation.

mod backward;
mod clip;
mod cube;
mod error;
mod interpolate;
pub mod ops;
mod raster;
pub mod scene;
mod texture;

pub use error::{MAX_IMAGE_SIDE, RenderError};
pub use ops::{
    AntialiasPlan, DenseBarycentrics, DenseRaster, Raster, RasterKernel, SilhouettePairs,
    TexturePlan, Topology, antialias, dense_barycentrics, host_readbacks, interpolate,
    interpolate_dense, interpolate_dense_with_faces, rasterize, rasterize_dense, silhouette_pairs,
    texture,
};
pub use raster::Fragments;

/// The CPU core: the primitives on host slices (`f32` in and out, `f64` inside), with
/// hand-written backward passes. [`ops`] builds the burn primitives on it; the tests use the
/// backward passes as the independent reference for the autodiff gradients.
pub mod cpu {
    pub use crate::backward::rasterize_backward;
    pub use crate::interpolate::{interpolate, interpolate_backward};
    pub use crate::raster::{Fragments, rasterize, rasterize_parallel};
    pub use crate::texture::{coverage_mask, texture, texture_backward};
}

// Index loops mirror the maths in the tests.
#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests;
