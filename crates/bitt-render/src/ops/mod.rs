//! The differentiable primitives as burn tensor functions: [`rasterize`], [`interpolate`],
//! [`texture`] and [`antialias`].
//!
//! # How the gradients are made
//! Each primitive splits into a *discrete* part and a *differentiable* part, the way
//! nvdiffrast's kernels do:
//!
//! * the discrete part decides which face covers which pixel, which texels surround a
//!   sample, which pixel pairs straddle a silhouette edge. It has no gradient; it runs on the
//!   CPU core of this crate ([`crate::cpu`]) on a copy of the (small) clip positions and
//!   produces integer index tensors;
//! * the differentiable part evaluates the closed-form quantities (perspective-correct
//!   barycentrics from the 2-D homogeneous edge functions, depth, bilinear weights, the
//!   silhouette crossing and its blend) with burn tensor operations on the device the inputs
//!   live on. Their backward passes are burn's autodiff of those expressions, which are the
//!   analytic gradients nvdiffrast derives by hand (interior barycentric gradients, bilinear
//!   weight and UV gradients, silhouette gradients to the edge's vertices).
//!
//! The hand-written backward passes of the CPU core ([`crate::cpu::rasterize_backward`],
//! [`crate::cpu::interpolate_backward`], [`crate::cpu::texture_backward`]) are the
//! independent reference the tests compare these gradients against, next to finite
//! differences.
//!
//! With [`rasterize`] only the discrete part leaves the device: the clip positions are read
//! back (`V x 4` floats) and the covered-pixel indices are uploaded (`3 N + N` integers for
//! `N` covered pixels); everything differentiable stays on the GPU. The dense path keeps the
//! discrete part on the device too: [`rasterize_dense`] (a CubeCL kernel on wgpu/CUDA), then
//! [`dense_barycentrics`], [`interpolate_dense`], [`TexturePlan`] and
//! [`AntialiasPlan::from_dense`] over all `H W` pixels, with no host readback.
//!
//! # Per-pixel values
//! A [`Raster`] lists its `N` covered pixels; per-pixel quantities are `[N, C]` tensors in that
//! order (row `k` belongs to pixel [`Raster::covered`]`[k]`). [`Raster::to_image`] scatters
//! them into a `[C, H, W]` image with a background. A [`DenseBarycentrics`] and what is
//! made from it have one row per pixel instead (`row * W + col`), zero on empty pixels.

mod antialias;
mod antialias_dense;
pub(crate) mod dense;
pub(crate) mod dense_diff;
mod interpolate;
mod raster;
mod texture;

pub use antialias::{AntialiasPlan, SilhouettePairs, antialias, silhouette_pairs};
pub use dense::{DenseRaster, RasterKernel, rasterize_dense};
pub use dense_diff::{
    DenseBarycentrics, dense_barycentrics, interpolate_dense, interpolate_dense_with_faces,
};
pub use interpolate::{interpolate, interpolate_with_faces};
pub use raster::{Raster, rasterize};
pub use texture::{TexturePlan, texture};

use crate::error::{RenderError, check_faces};

/// A triangle mesh's connectivity, prepared once: faces and, per face edge, the face across
/// it (for silhouette detection in [`antialias`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Topology {
    num_vertices: usize,
    faces: Vec<[u32; 3]>,
    /// Per face, per edge `k` (vertices `k`, `k + 1 mod 3`): the other face sharing that edge,
    /// [`Topology::BOUNDARY`] if none, [`Topology::NON_MANIFOLD`] if more than one.
    neighbors: Vec<[i32; 3]>,
}

impl Topology {
    /// Marks an edge with no face on the other side.
    pub(crate) const BOUNDARY: i32 = -1;
    /// Marks an edge shared by more than two faces.
    pub(crate) const NON_MANIFOLD: i32 = -2;

    /// Builds the topology of `faces` over `num_vertices` vertices.
    ///
    /// # Errors
    /// A face index `>= num_vertices`, or more faces than `i32` can address.
    pub fn new(faces: Vec<[u32; 3]>, num_vertices: usize) -> Result<Self, RenderError> {
        check_faces(&faces, num_vertices)?;
        let mut edges: std::collections::HashMap<(u32, u32), Vec<(usize, usize)>> =
            std::collections::HashMap::with_capacity(faces.len() * 3 / 2 + 1);
        for (f, tri) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                edges.entry((a.min(b), a.max(b))).or_default().push((f, k));
            }
        }
        let mut neighbors = vec![[Self::BOUNDARY; 3]; faces.len()];
        for users in edges.values() {
            match users.as_slice() {
                [_] => {}
                [(f0, k0), (f1, k1)] => {
                    neighbors[*f0][*k0] = *f1 as i32;
                    neighbors[*f1][*k1] = *f0 as i32;
                }
                many => {
                    for &(f, k) in many {
                        neighbors[f][k] = Self::NON_MANIFOLD;
                    }
                }
            }
        }
        Ok(Self {
            num_vertices,
            faces,
            neighbors,
        })
    }

    /// Concatenates meshes into one topology (vertex indices of later meshes offset), e.g.
    /// both hands of a scene so that one depth test resolves their occlusion. Face `f` of
    /// part `i` becomes face `f + sum of earlier face counts`.
    ///
    /// # Errors
    /// As [`Topology::new`].
    pub fn concat(parts: &[&Topology]) -> Result<Self, RenderError> {
        let mut faces = Vec::new();
        let mut offset = 0u32;
        for part in parts {
            faces.extend(
                part.faces
                    .iter()
                    .map(|t| [t[0] + offset, t[1] + offset, t[2] + offset]),
            );
            offset += part.num_vertices as u32;
        }
        Self::new(faces, offset as usize)
    }

    /// Number of vertices the faces index into.
    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// Number of faces.
    pub(crate) fn num_faces(&self) -> usize {
        self.faces.len()
    }

    /// The faces (vertex index triples).
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// Per face, per edge `k` (vertices `k` and `k + 1 mod 3`), the face across it or
    /// [`Topology::BOUNDARY`] / [`Topology::NON_MANIFOLD`].
    pub(crate) fn neighbors(&self) -> &[[i32; 3]] {
        &self.neighbors
    }
}

/// Checks a tensor's shape against `expected` (`None` = any size).
pub(crate) fn check_shape<const D: usize>(
    what: &'static str,
    actual: [usize; D],
    expected: [Option<usize>; D],
    words: impl FnOnce() -> String,
) -> Result<(), RenderError> {
    if actual
        .iter()
        .zip(expected.iter())
        .all(|(a, e)| e.is_none_or(|e| e == *a))
    {
        Ok(())
    } else {
        Err(RenderError::TensorShape {
            what,
            expected: words(),
            actual: actual.to_vec(),
        })
    }
}

/// Host readbacks made by this crate since the process started (see [`host_readbacks`]).
static HOST_READBACKS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// How many times this crate has read a tensor back to the host (`into_data`) since the
/// process started, over all threads. On a GPU each one waits for the device to finish its
/// queued work; take the difference around a step to count that step's round trips.
pub fn host_readbacks() -> u64 {
    HOST_READBACKS.load(std::sync::atomic::Ordering::Relaxed)
}

thread_local! {
    /// [`HOST_READBACKS`] of the current thread alone (tests run in parallel threads).
    static THREAD_READBACKS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// Host readbacks made by this crate on the current thread (for tests that count a step's
/// round trips while other tests run).
#[cfg(test)]
pub(crate) fn thread_host_readbacks() -> u64 {
    THREAD_READBACKS.with(std::cell::Cell::get)
}

/// Counts one host readback.
pub(crate) fn count_readback() {
    HOST_READBACKS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    THREAD_READBACKS.with(|c| c.set(c.get() + 1));
}

/// Reads a float tensor back to the host (counted in [`host_readbacks`]).
pub(crate) fn read_f32<const D: usize>(
    what: &'static str,
    tensor: burn::tensor::Tensor<D>,
) -> Result<Vec<f32>, RenderError> {
    count_readback();
    tensor
        .into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| RenderError::TensorRead {
            what,
            reason: format!("{e:?}"),
        })
}

/// An `[n]` integer index tensor.
pub(crate) fn index_tensor(
    values: Vec<i64>,
    device: &burn::tensor::Device,
) -> burn::tensor::Tensor<1, burn::tensor::Int> {
    let n = values.len();
    burn::tensor::Tensor::from_data(burn::tensor::TensorData::new(values, [n]), device)
}

/// A float tensor from host values.
pub(crate) fn float_tensor<const D: usize>(
    values: Vec<f32>,
    shape: [usize; D],
    device: &burn::tensor::Device,
) -> burn::tensor::Tensor<D> {
    burn::tensor::Tensor::from_data(burn::tensor::TensorData::new(values, shape), device)
}
