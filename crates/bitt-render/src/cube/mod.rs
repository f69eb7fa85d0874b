//! The rasterizer on cubecl devices (wgpu, and CUDA where it is built): [`kernel`] launched on
//! the clip positions' own buffer, through burn's `extension` mechanism
//! (`Tensor::try_into_primitive::<Cube>`), the outputs dense and left on the device.

mod kernel;

use burn::backend::Cube;
use burn::tensor::{DType, Int, Tensor, TensorCreationOptions, TensorData};
use cubecl::ir::{ElemType, FloatKind, IntKind};
use cubecl::prelude::*;

use kernel::{Pass, rasterize_kernel};

/// Faces per cube (workgroup).
const FACES_PER_CUBE: u32 = 64;

/// The dense rasterizer outputs on the device: face id `[H, W]` (`i32`, -1 where empty),
/// barycentrics `[H, W, 3]`, NDC depth `[H, W]` (`+inf` where empty).
pub(crate) type DenseOutputs = (Tensor<2, Int>, Tensor<3>, Tensor<2>);

/// Rasterizes on the clip tensor's cubecl device; `Err(why)` (nothing launched) when the
/// tensor is not on a cubecl device, is not `f32`, or the device lacks `f64` or `i64` in
/// shaders (the kernel's arithmetic; Vulkan's `shaderFloat64` / `shaderInt64`, which
/// NVIDIA's, AMD's and Mesa's lavapipe drivers have).
///
/// # Shapes
/// clip `[V, 4]`, faces `F` index triples into `V` (already validated) -> see
/// [`DenseOutputs`].
pub(crate) fn rasterize(
    clip: &Tensor<2>,
    faces: &[[u32; 3]],
    height: usize,
    width: usize,
) -> Result<DenseOutputs, &'static str> {
    // The kernel works on the plain backend; outputs go back to an autodiff device as
    // constants (they have no gradient).
    let autodiff = clip.is_autodiff();
    let device = clip.device().without_autodiff();
    let plain = clip.clone().without_autodiff();
    let [v, _] = plain.dims();
    let clip_prim = plain
        .reshape([v * 4])
        .try_into_primitive::<Cube>()
        .map_err(|_| "not a cubecl device")?;
    let client = clip_prim.client.clone();
    let props = client.properties();
    let supported = props.supports_type(ElemType::Float(FloatKind::F64))
        && props.supports_type(ElemType::Int(IntKind::I64));
    if !supported {
        return Err("the adapter has no f64 or no i64 in shaders");
    }
    if clip_prim.dtype != DType::F32 || !clip_prim.is_contiguous() {
        return Err("the clip positions are not contiguous f32");
    }
    let i32_opts = || TensorCreationOptions::new(device.clone()).with_dtype(DType::I32);
    let f32_opts = || TensorCreationOptions::new(device.clone()).with_dtype(DType::F32);
    let n = height * width;
    let flat: Vec<i32> = faces.iter().flatten().map(|&i| i as i32).collect();
    const ALLOC: &str = "an output buffer is not a cubecl tensor";
    let prim = |t: Tensor<1, Int>| t.try_into_primitive::<Cube>().map_err(|_| ALLOC);
    let faces_prim = prim(Tensor::from_data(
        TensorData::new(flat, [faces.len() * 3]),
        i32_opts(),
    ))?;
    let keys = prim(Tensor::full([n], i32::MAX, i32_opts()))?;
    let winners = prim(Tensor::full([n], i32::MAX, i32_opts()))?;
    let bary = Tensor::<1>::zeros([n * 3], f32_opts())
        .try_into_primitive::<Cube>()
        .map_err(|_| ALLOC)?;
    let depth = Tensor::<1>::full([n], f32::INFINITY, f32_opts())
        .try_into_primitive::<Cube>()
        .map_err(|_| ALLOC)?;
    if [&faces_prim, &keys, &winners]
        .iter()
        .any(|t| t.dtype != DType::I32 || !t.is_contiguous())
        || [&bary, &depth]
            .iter()
            .any(|t| t.dtype != DType::F32 || !t.is_contiguous())
    {
        return Err("an output buffer is not a contiguous i32/f32 tensor");
    }
    if !faces.is_empty() {
        let cube_dim = CubeDim::new_1d(FACES_PER_CUBE);
        for pass in [Pass::Depth, Pass::Face, Pass::Write] {
            let cube_count = cubecl::calculate_cube_count_elemwise(&client, faces.len(), cube_dim);
            rasterize_kernel::launch(
                &client,
                cube_count,
                cube_dim,
                clip_prim.clone().into_buffer_arg(),
                faces_prim.clone().into_buffer_arg(),
                keys.clone().into_buffer_arg(),
                winners.clone().into_buffer_arg(),
                bary.clone().into_buffer_arg(),
                depth.clone().into_buffer_arg(),
                width as u32,
                height as u32,
                pass,
            );
        }
    }
    let winners = Tensor::<1, Int>::from_primitive::<Cube>(winners).reshape([height, width]);
    let empty = winners.clone().equal_elem(i32::MAX);
    let face = winners.mask_fill(empty, -1);
    let bary = Tensor::<1>::from_primitive::<Cube>(bary).reshape([height, width, 3]);
    let depth = Tensor::<1>::from_primitive::<Cube>(depth).reshape([height, width]);
    if autodiff {
        Ok((face.autodiff(), bary.autodiff(), depth.autodiff()))
    } else {
        Ok((face, bary, depth))
    }
}
