//! BTR's `SiLU(GroupNorm(conv(x)))` as one custom burn operation on the flex backend, with a
//! hand-written backward pass.
//!
//! Composed from burn tensor operations (`btr::conv_norm_silu`), this block allocates and
//! walks about a dozen `[N, C, T]` buffers forward and as many backward, mostly on one
//! thread; at BTR's sizes (`T = 206,330`) that, not the matrix products, dominated a
//! training step on the CPU. [`conv_norm_silu`] computes the same function with the kernels
//! of [`kernels`]: three GEMMs accumulating into one buffer for the convolution (no padding
//! copies), one pass for the group moments and one for the normalisation and SiLU, all rows
//! in parallel; the backward pass is two passes plus three GEMMs for each of `dx` and `dW`.
//! It keeps only its input `x` and the convolution's output `z` for the backward pass.
//!
//! The operation is used when the tensors live on flex (`Device::flex()`, with or without
//! autodiff) in `f32`; on every other backend [`conv_norm_silu`] returns `None` and the caller
//! composes burn operations, which compute the same function. Tests compare both, values and
//! gradients, and the kernels against naive loops and finite differences.
//!
//! [`res_block`] runs a whole ResNet block (two of these blocks, the residual or its 1x1
//! projection and the sum) as one operation, so that burn's autodiff need not sum the
//! input's two gradients on one thread; it is what BTR uses on flex.
//!
//! [`conv_bias`] is the same mechanism for BTR's convolutions without a normalisation (the
//! head, its last one through a sigmoid), and [`concat`](mod@concat) for the channel concatenations of
//! BTR's decoder and the albedo U-Net.
//!
//! [`resample`] holds the albedo U-Net's upsampling and the interleaving of its outermost
//! level's output phases, as single passes.
//!
//! [`conv2d`] is the same mechanism for the image networks (albedo U-Net, light and HTML
//! encoders): `act(InstanceNorm(conv2d(x) + bias))` as one operation, tiled im2col + GEMM
//! and row passes in [`kernels2d`].

pub(crate) mod concat;
pub(crate) mod conv2d;
pub(crate) mod conv_bias;
mod gemm;
pub(crate) mod kernels;
pub(crate) mod kernels2d;
pub(crate) mod pool;
pub(crate) mod res_block;
pub(crate) mod resample;
mod scratch;
mod vectorized;

use std::sync::Arc;

use burn::backend::Flex;
use burn::backend::autodiff::Autodiff;
use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::NoCheckpointing;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, NodeGuard, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor, TensorData};

use kernels::{ConvDims, NormDims, NormStats};

/// Flex with gradients, as `Device::flex().autodiff()` creates it (no checkpointing).
type FlexAutodiff = Autodiff<Flex, NoCheckpointing>;

/// The parameters of one block, as tensors on the block's device.
#[derive(Debug, Clone)]
pub(crate) struct BlockParams {
    /// `[C_out, C_in, K]`.
    pub weight: Tensor<3>,
    /// Convolution bias, `[C_out]`.
    pub bias: Tensor<1>,
    /// Group norm scale, `[C_out]`.
    pub gamma: Tensor<1>,
    /// Group norm shift, `[C_out]`.
    pub beta: Tensor<1>,
    pub groups: usize,
    pub epsilon: f64,
}

/// `SiLU(GroupNorm(conv(x) + bias))` on flex; `None` (nothing computed) on other backends or
/// dtypes.
///
/// # Shapes
/// - `x`: `[N, C_in, T]`
/// - output: `[N, C_out, T]`
pub(crate) fn conv_norm_silu(x: &Tensor<3>, p: &BlockParams) -> Option<Tensor<3>> {
    let [c_out, c_in, kernel] = p.weight.dims();
    let [batch, x_channels, len] = x.dims();
    if x_channels != c_in
        || kernel % 2 == 0
        || len == 0
        || p.groups == 0
        || !c_out.is_multiple_of(p.groups)
    {
        return None;
    }
    let conv = ConvDims {
        batch,
        c_in,
        c_out,
        len,
        kernel,
    };
    let norm = NormDims {
        batch,
        channels: c_out,
        len,
        groups: p.groups,
        epsilon: p.epsilon,
    };
    run_on_flex(
        x,
        &p.weight,
        [&p.bias, &p.gamma, &p.beta],
        ConvNormSiluBackward,
        |x, params| forward(x, params, conv, norm),
    )
}

/// Runs a fused operation of five `f32` inputs `(x, weight, bias, gamma, beta)` on flex:
/// with autodiff (its backward `op` registered when an input is tracked) or without.
/// `None`, with nothing computed, when a tensor is not on flex or not `f32`.
///
/// `forward` gets the inputs' flex tensors and returns the output and the state the
/// backward pass keeps.
fn run_on_flex<const DX: usize, const DW: usize, const DY: usize, Op: Backward<Flex, 5>>(
    x: &Tensor<DX>,
    weight: &Tensor<DW>,
    [bias, gamma, beta]: [&Tensor<1>; 3],
    op: Op,
    forward: impl FnOnce(&FlexTensor, [&FlexTensor; 4]) -> (FlexTensor, Op::State),
) -> Option<Tensor<DY>> {
    let f32s = |ts: &[&FlexTensor]| ts.iter().all(|t| t.dtype() == DType::F32);
    if let Ok(xa) = x.clone().try_into_primitive::<FlexAutodiff>() {
        let [weight, bias, gamma, beta] = [
            weight.clone().try_into_primitive::<FlexAutodiff>().ok()?,
            bias.clone().try_into_primitive::<FlexAutodiff>().ok()?,
            gamma.clone().try_into_primitive::<FlexAutodiff>().ok()?,
            beta.clone().try_into_primitive::<FlexAutodiff>().ok()?,
        ];
        let inputs = [&xa, &weight, &bias, &gamma, &beta];
        if !f32s(&inputs.map(|t| t.primitive())) {
            return None;
        }
        let nodes = inputs.map(|t| t.node());
        let (y, saved) = forward(
            xa.primitive(),
            [&weight, &bias, &gamma, &beta].map(|t| t.primitive()),
        );
        return Some(autodiff_output(op, nodes, saved, y));
    }
    let xf = x.clone().try_into_primitive::<Flex>().ok()?;
    let [weight, bias, gamma, beta] = [
        weight.clone().try_into_primitive::<Flex>().ok()?,
        bias.clone().try_into_primitive::<Flex>().ok()?,
        gamma.clone().try_into_primitive::<Flex>().ok()?,
        beta.clone().try_into_primitive::<Flex>().ok()?,
    ];
    if !f32s(&[&xf, &weight, &bias, &gamma, &beta]) {
        return None;
    }
    let (y, _) = forward(&xf, [&weight, &bias, &gamma, &beta]);
    Some(Tensor::from_primitive::<Flex>(y))
}

/// The output `y` of a fused operation on flex with autodiff, with `op` registered as its
/// backward pass (keeping `state`) when one of the inputs behind `nodes` is tracked.
fn autodiff_output<const N: usize, const D: usize, Op: Backward<Flex, N>>(
    op: Op,
    nodes: [NodeGuard; N],
    state: Op::State,
    y: FlexTensor,
) -> Tensor<D> {
    let out = match op
        .prepare::<NoCheckpointing>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => prep.finish(state, y),
        OpsKind::UnTracked(prep) => prep.finish(y),
    };
    Tensor::from_primitive::<FlexAutodiff>(out)
}

/// The output gradient of a fused operation as a writable buffer for `dz`: the gradient's
/// own storage when nothing else holds it (saves a buffer of the output's size), else a
/// copy. `len` is the output's element count.
fn output_gradient_buffer(gy: &mut FlexTensor, len: usize) -> GradientBuffer<'_> {
    if gy.try_storage_mut::<f32>().is_some_and(|b| b.len() == len) {
        GradientBuffer::Unique(gy.try_storage_mut::<f32>().expect("unique gradient"))
    } else {
        GradientBuffer::Copy(gy.as_slice::<f32>().expect("contiguous f32").to_vec())
    }
}

/// Registers the gradients of a fused operation's per-channel parameters (bias, gamma,
/// beta; each `[C_out]`) for those that are tracked.
fn register_channel_grads(grads: &mut Gradients, ids: [Option<NodeId>; 3], values: [Vec<f32>; 3]) {
    for (id, values) in ids.into_iter().zip(values) {
        if let Some(id) = id {
            let len = values.len();
            grads.register::<Flex>(id, flex_tensor(values, [len]));
        }
    }
}

/// See [`output_gradient_buffer`].
enum GradientBuffer<'a> {
    Unique(&'a mut [f32]),
    Copy(Vec<f32>),
}

impl GradientBuffer<'_> {
    fn as_mut_slice(&mut self) -> &mut [f32] {
        match self {
            GradientBuffer::Unique(s) => s,
            GradientBuffer::Copy(v) => v,
        }
    }
}

/// The forward pass on flex tensors (all `f32`): the output `[N, C_out, T]` and what the
/// backward pass needs.
fn forward(
    x: &FlexTensor,
    [weight, bias, gamma, beta]: [&FlexTensor; 4],
    conv: ConvDims,
    norm: NormDims,
) -> (FlexTensor, Saved) {
    let x = contiguous(x);
    let [weight, bias, gamma, beta] = [weight, bias, gamma, beta].map(|t| Arc::new(values(t)));
    let z = kernels::conv_forward(x.as_slice::<f32>().expect("contiguous f32"), &weight, conv);
    let (y, stats) = kernels::norm_silu_forward(&z, &bias, &gamma, &beta, norm, None);
    let y = flex_tensor(y, [conv.batch, conv.c_out, conv.len]);
    let saved = Saved {
        x,
        weight,
        bias,
        gamma,
        beta,
        conv,
        norm,
        z: Arc::new(z),
        stats: Arc::new(stats),
    };
    (y, saved)
}

/// What the backward pass keeps: the input, the convolution output, the parameters' values.
#[derive(Debug, Clone)]
struct Saved {
    /// Contiguous `f32` input `[N, C_in, T]`.
    x: FlexTensor,
    weight: Arc<Vec<f32>>,
    bias: Arc<Vec<f32>>,
    gamma: Arc<Vec<f32>>,
    beta: Arc<Vec<f32>>,
    conv: ConvDims,
    norm: NormDims,
    /// Convolution output without bias, `[N, C_out, T]`.
    z: Arc<Vec<f32>>,
    stats: Arc<NormStats>,
}

#[derive(Debug)]
struct ConvNormSiluBackward;

impl Backward<Flex, 5> for ConvNormSiluBackward {
    type State = Saved;

    fn backward(self, ops: Ops<Saved, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_weight, node_bias, node_gamma, node_beta] = ops.parents;
        let s = ops.state;
        let mut gy = contiguous(&grads.consume::<Flex>(&ops.node));
        let mut buffer = output_gradient_buffer(&mut gy, s.z.len());
        let dz = buffer.as_mut_slice();
        let [dbias, dgamma, dbeta] = kernels::norm_silu_backward_in_place(
            dz, &s.z, &s.bias, &s.gamma, &s.beta, &s.stats, s.norm, None,
        );
        let dz: &[f32] = dz;
        register_channel_grads(
            grads,
            [node_bias, node_gamma, node_beta].map(|n| n.map(|n| n.id)),
            [dbias, dgamma, dbeta],
        );
        let c_out = s.conv.c_out;
        let x = s.x.as_slice::<f32>().expect("contiguous f32");
        let ConvDims {
            batch,
            c_in,
            kernel,
            len,
            ..
        } = s.conv;
        if let Some(node) = node_weight {
            let dw = kernels::conv_backward_weight(dz, x, s.conv);
            grads.register::<Flex>(node.id, flex_tensor(dw, [c_out, c_in, kernel]));
        }
        if let Some(node) = node_x {
            let dx = kernels::conv_backward_input(dz, &s.weight, s.conv);
            grads.register::<Flex>(node.id, flex_tensor(dx, [batch, c_in, len]));
        }
    }
}

/// The tensor with a contiguous, zero-offset layout (a cheap clone when it already is).
fn contiguous(t: &FlexTensor) -> FlexTensor {
    if t.is_contiguous() && t.layout().start_offset() == 0 {
        t.clone()
    } else {
        t.to_contiguous()
    }
}

fn values(t: &FlexTensor) -> Vec<f32> {
    contiguous(t)
        .as_slice::<f32>()
        .expect("contiguous f32")
        .to_vec()
}

/// The parts of rows in the block of `n` values starting at flat index `start` of a
/// `[rows, len]` buffer (a block may span the end of one row and the start of the next):
/// `f(row, from, at, count)` for `count` values of `row` from column `from`, at offset `at`
/// in the block.
pub(crate) fn row_segments(
    start: usize,
    n: usize,
    len: usize,
    mut f: impl FnMut(usize, usize, usize, usize),
) {
    let mut p = start;
    while p < start + n {
        let (row, from) = (p / len, p % len);
        let count = (len - from).min(start + n - p);
        f(row, from, p - start, count);
        p += count;
    }
}

/// Floats per block of [`rows_by_blocks`].
const ROW_BLOCK: usize = 256;

/// A new `[rows, len]` buffer computed block by block on rayon's threads, never cleared
/// (clearing a buffer that a pass then overwrites cost as much as the pass): `f(row, from,
/// out)` writes the row's values at `[from, from + out.len())`. The blocks are collected in
/// place (rayon's indexed `collect`), so every value is written once.
pub(crate) fn rows_by_blocks(
    rows: usize,
    len: usize,
    f: impl Fn(usize, usize, &mut [f32]) + Sync,
) -> Vec<f32> {
    use rayon::prelude::*;
    let total = rows * len;
    if total == 0 {
        return Vec::new();
    }
    let blocks: Vec<[f32; ROW_BLOCK]> = (0..total.div_ceil(ROW_BLOCK))
        .into_par_iter()
        .with_min_len(16)
        .map(|i| {
            let mut out = [0.0f32; ROW_BLOCK];
            let start = i * ROW_BLOCK;
            let end = (start + ROW_BLOCK).min(total);
            row_segments(start, end - start, len, |row, from, at, n| {
                f(row, from, &mut out[at..at + n]);
            });
            out
        })
        .collect();
    let mut out = blocks.into_flattened();
    out.truncate(total);
    out
}

/// A zeroed output buffer of `len` floats, cleared by rayon's threads in parallel. The
/// allocator keeps freed memory, so a large buffer comes back dirty and must be cleared; one
/// thread clearing it (what `vec![0.0; len]` does) kept the other core idle.
pub(crate) fn zeros(len: usize) -> Vec<f32> {
    use rayon::iter::ParallelExtend;
    if len < 1 << 16 {
        return vec![0.0; len];
    }
    let mut v = Vec::with_capacity(len);
    v.par_extend(rayon::iter::repeat_n(0.0f32, len));
    v
}

fn flex_tensor<const D: usize>(values: Vec<f32>, shape: [usize; D]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows shorter and longer than a block, blocks across rows and a ragged end: every
    /// value written once, at its place.
    #[test]
    fn rows_by_blocks_writes_every_value_at_its_place() {
        for (rows, len) in [
            (1, 1),
            (3, 5),
            (2, 255),
            (2, 256),
            (3, 257),
            (5, 700),
            (0, 9),
            (4, 0),
        ] {
            let got = rows_by_blocks(rows, len, |row, from, out| {
                for (k, v) in out.iter_mut().enumerate() {
                    *v = (row * 10_000 + from + k) as f32;
                }
            });
            let want: Vec<f32> = (0..rows)
                .flat_map(|r| (0..len).map(move |t| (r * 10_000 + t) as f32))
                .collect();
            assert_eq!(got, want, "rows {rows} len {len}");
        }
    }
}
