//! CPU core of an nvdiffrast-style differentiable rasterizer (pure Rust, `f32` I/O, `f64`
//! internally).
//!
//! * [`rasterize`] turns clip-space triangles into per-pixel [`Fragments`] (face id,
//!   perspective-correct barycentrics, depth);
//! * [`rasterize_backward`] gives the analytic interior gradient of the barycentrics (and
//!   optionally depth) w.r.t. the clip positions, like nvdiffrast's rasterize backward without
//!   antialiasing/silhouette terms;
//! * [`interpolate`] / [`interpolate_backward`] interpolate per-vertex attributes and back;
//! * [`texture`] / [`texture_backward`] sample a `[C, Ht, Wt]` texture bilinearly at per-pixel
//!   UVs and back, like the BiTT reference's `grid_sample(align_corners=True,
//!   padding_mode='border')` with `v = 0` at the texture's bottom row (see the module docs);
//!   [`coverage_mask`] turns [`Fragments`] into its pixel mask.
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
//! * **Backward**: [`rasterize_backward`] treats near-clipped faces like any other face (the
//!   barycentrics at a pixel centre do not depend on clipping); see its module docs for the
//!   derivation.

mod backward;
mod clip;
mod error;
mod interpolate;
mod raster;
mod texture;

pub use backward::rasterize_backward;
pub use error::{MAX_IMAGE_SIDE, RenderError};
pub use interpolate::{interpolate, interpolate_backward};
pub use raster::{Fragments, rasterize};
pub use texture::{coverage_mask, texture, texture_backward};

// Index loops mirror the maths in the tests.
#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests;
