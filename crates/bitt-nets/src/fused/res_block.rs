//! BTR's whole ResNet block, `SiLU(GN(conv2(SiLU(GN(conv1(x)))))) + residual(x)` with the
//! residual `x` or a 1x1 projection `conv(x) + bias`, as one custom burn operation on flex.
//!
//! Composed from two [`super::conv_norm_silu`] operations, a projection and burn's add, the
//! block's input `x` has two consumers, so burn's autodiff adds its two gradients in
//! `Gradients::register`: a new `[N, C_in, T]` sum on one thread (burn's flex backend splits
//! element-wise work across threads only from 4 Mi elements on), once per block and step,
//! while the other core waited. The forward sum `h + residual` was another single-threaded
//! pass. Here the residual is added in the second normalisation's output pass, and the
//! backward pass sums `x`'s two gradients itself, in parallel. It computes the same values
//! and gradients as the composition, bit for bit: the same kernels in the same order, and
//! each sum's two terms are added in one `f32` addition either way.

use std::sync::Arc;

use burn::backend::Flex;
use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, NodeGuard, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use super::conv_bias::bias_gradient;
use super::kernels::{self, ConvDims, NormDims, NormStats, Residual};
use super::{
    BlockParams, FlexAutodiff, autodiff_output, contiguous, flex_tensor, output_gradient_buffer,
    register_channel_grads, rows_by_blocks, values,
};

/// The 1x1 projection on a block's residual path, when the width changes.
#[derive(Debug, Clone)]
pub(crate) struct SkipParams {
    /// `[C_out, C_in, 1]`.
    pub weight: Tensor<3>,
    /// `[C_out]`.
    pub bias: Tensor<1>,
}

/// The ResNet block on flex: `SiLU(GN(conv(SiLU(GN(conv(x)))))) + x` with `skip` `None`
/// (then `C_in = C_out`), or `+ skip.weight x + skip.bias`. `None` (nothing computed) on
/// other backends or dtypes, or when the shapes do not fit such a block.
///
/// # Shapes
/// - `x`: `[N, C_in, T]`; `first.weight`: `[C_out, C_in, K1]`; `second.weight`:
///   `[C_out, C_out, K2]` (odd kernels)
/// - output: `[N, C_out, T]`
pub(crate) fn res_block(
    x: &Tensor<3>,
    first: &BlockParams,
    second: &BlockParams,
    skip: Option<&SkipParams>,
) -> Option<Tensor<3>> {
    let dims = block_dims(x.dims(), first, second, skip)?;
    let rank3: Vec<&Tensor<3>> = [x, &first.weight, &second.weight]
        .into_iter()
        .chain(skip.map(|s| &s.weight))
        .collect();
    let rank1: Vec<&Tensor<1>> = [
        &first.bias,
        &first.gamma,
        &first.beta,
        &second.bias,
        &second.gamma,
        &second.beta,
    ]
    .into_iter()
    .chain(skip.map(|s| &s.bias))
    .collect();
    let f32s = |ts: &[&FlexTensor]| ts.iter().all(|t| t.dtype() == DType::F32);
    if x.clone().try_into_primitive::<FlexAutodiff>().is_ok() {
        let r3 = rank3
            .iter()
            .map(|t| (*t).clone().try_into_primitive::<FlexAutodiff>().ok())
            .collect::<Option<Vec<_>>>()?;
        let r1 = rank1
            .iter()
            .map(|t| (*t).clone().try_into_primitive::<FlexAutodiff>().ok())
            .collect::<Option<Vec<_>>>()?;
        let all: Vec<&FlexTensor> = r3.iter().chain(&r1).map(|t| t.primitive()).collect();
        if !f32s(&all) {
            return None;
        }
        let inputs = Inputs::new(&all);
        // Parents in the order of `Parent`.
        let nodes: Vec<NodeGuard> = [&r3[0], &r3[1], &r1[0], &r1[1], &r1[2]]
            .into_iter()
            .chain([&r3[2], &r1[3], &r1[4], &r1[5]])
            .chain(
                skip.is_some()
                    .then(|| [&r3[3], &r1[6]])
                    .into_iter()
                    .flatten(),
            )
            .map(|t| t.node())
            .collect();
        let (y, saved) = forward(&inputs, dims);
        return Some(match nodes.try_into() {
            Ok(nodes) => autodiff_output(ResBlockBackward::<11>, nodes, saved, y),
            Err(nodes) => {
                let nodes: [NodeGuard; 9] = nodes.try_into().expect("9 or 11 parents");
                autodiff_output(ResBlockBackward::<9>, nodes, saved, y)
            }
        });
    }
    let r3 = rank3
        .iter()
        .map(|t| (*t).clone().try_into_primitive::<Flex>().ok())
        .collect::<Option<Vec<_>>>()?;
    let r1 = rank1
        .iter()
        .map(|t| (*t).clone().try_into_primitive::<Flex>().ok())
        .collect::<Option<Vec<_>>>()?;
    let all: Vec<&FlexTensor> = r3.iter().chain(&r1).collect();
    if !f32s(&all) {
        return None;
    }
    Some(Tensor::from_primitive::<Flex>(
        forward(&Inputs::new(&all), dims).0,
    ))
}

/// The sizes of a block's two convolutions, its normalisations and its projection.
#[derive(Debug, Clone, Copy)]
struct BlockDims {
    first: ConvDims,
    second: ConvDims,
    norm1: NormDims,
    norm2: NormDims,
    /// The projection's 1x1 convolution, when there is one.
    skip: Option<ConvDims>,
}

/// [`BlockDims`] of a block on `x` of shape `[batch, c_in, len]`; `None` when the shapes do
/// not fit.
fn block_dims(
    [batch, c_in, len]: [usize; 3],
    first: &BlockParams,
    second: &BlockParams,
    skip: Option<&SkipParams>,
) -> Option<BlockDims> {
    let [c_out, w1_in, k1] = first.weight.dims();
    let [w2_out, w2_in, k2] = second.weight.dims();
    let channel_params = |p: &BlockParams| [&p.bias, &p.gamma, &p.beta].map(|t| t.dims());
    let fits = w1_in == c_in
        && [w2_out, w2_in] == [c_out, c_out]
        && k1 % 2 == 1
        && k2 % 2 == 1
        && len > 0
        && [first, second]
            .iter()
            .all(|p| p.groups > 0 && c_out.is_multiple_of(p.groups))
        && channel_params(first) == [[c_out]; 3]
        && channel_params(second) == [[c_out]; 3]
        && match skip {
            None => c_in == c_out,
            Some(s) => s.weight.dims() == [c_out, c_in, 1] && s.bias.dims() == [c_out],
        };
    if !fits {
        return None;
    }
    let conv = |c_in, kernel| ConvDims {
        batch,
        c_in,
        c_out,
        len,
        kernel,
    };
    let norm = |p: &BlockParams| NormDims {
        batch,
        channels: c_out,
        len,
        groups: p.groups,
        epsilon: p.epsilon,
    };
    Some(BlockDims {
        first: conv(c_in, k1),
        second: conv(c_out, k2),
        norm1: norm(first),
        norm2: norm(second),
        skip: skip.map(|_| conv(c_in, 1)),
    })
}

/// The parents of the operation, in order; the projection's two only when there is one.
#[derive(Debug, Clone, Copy)]
enum Parent {
    X,
    Weight1,
    Bias1,
    Gamma1,
    Beta1,
    Weight2,
    Bias2,
    Gamma2,
    Beta2,
    SkipWeight,
    SkipBias,
}

/// The flex tensors of a block, borrowed: `[x, w1, w2, (ws)]` then `[b1, g1, be1, b2, g2,
/// be2, (bs)]`, as [`res_block`] lists them.
struct Inputs<'a> {
    x: &'a FlexTensor,
    first: [&'a FlexTensor; 4],
    second: [&'a FlexTensor; 4],
    skip: Option<[&'a FlexTensor; 2]>,
}

impl<'a> Inputs<'a> {
    fn new(all: &[&'a FlexTensor]) -> Self {
        let skip = all.len() == 11;
        let r1 = if skip { 4 } else { 3 };
        Inputs {
            x: all[0],
            first: [all[1], all[r1], all[r1 + 1], all[r1 + 2]],
            second: [all[2], all[r1 + 3], all[r1 + 4], all[r1 + 5]],
            skip: skip.then(|| [all[3], all[10]]),
        }
    }
}

/// One convolution + group norm + SiLU of the block, as the backward pass needs it.
#[derive(Debug, Clone)]
struct Half {
    /// `[weight, bias, gamma, beta]`.
    params: [Arc<Vec<f32>>; 4],
    conv: ConvDims,
    norm: NormDims,
    /// The convolution's output without bias.
    z: Arc<Vec<f32>>,
    stats: Arc<NormStats>,
    /// The SiLU's sigmoids, kept for blocks up to [`KEEP_SIGMOIDS_UP_TO`] values.
    sigmoid: Option<Arc<Vec<f32>>>,
}

/// Values per half up to which the forward pass keeps the SiLU's sigmoids for the backward
/// pass (4 MiB values, 16 MiB): every block of the `quick` preset (at most 2 x 8 x 28,544),
/// none of `paper`'s larger levels, whose memory stays as it was. Reading them back instead
/// of computing `1 / (1 + e^-a)` again made `bench-nets step --preset quick` about 8 %
/// faster (`docs/training.md`); the values are the same, so are the gradients.
const KEEP_SIGMOIDS_UP_TO: usize = 1 << 22;

/// [`kernels::norm_silu_forward`], keeping the sigmoids when the block is small enough.
fn norm_silu(
    z: &[f32],
    [bias, gamma, beta]: [&[f32]; 3],
    d: NormDims,
    residual: Option<Residual<'_>>,
) -> (Vec<f32>, NormStats, Option<Arc<Vec<f32>>>) {
    if z.len() <= KEEP_SIGMOIDS_UP_TO {
        let (y, stats, sigmoid) =
            kernels::norm_silu_forward_keeping_sigmoid(z, bias, gamma, beta, d, residual);
        (y, stats, Some(Arc::new(sigmoid)))
    } else {
        let (y, stats) = kernels::norm_silu_forward(z, bias, gamma, beta, d, residual);
        (y, stats, None)
    }
}

/// What the backward pass keeps.
#[derive(Debug, Clone)]
struct Saved {
    /// Contiguous `f32` input `[N, C_in, T]`.
    x: FlexTensor,
    first: Half,
    /// The first half's output, the second convolution's input `[N, C_out, T]`.
    h: Arc<Vec<f32>>,
    second: Half,
    /// The projection's weight `[C_out, C_in]` and its sizes.
    skip: Option<(Arc<Vec<f32>>, ConvDims)>,
}

/// The block's output `[N, C_out, T]` and the backward pass's state.
fn forward(inputs: &Inputs<'_>, dims: BlockDims) -> (FlexTensor, Saved) {
    let x = contiguous(inputs.x);
    let xs = x.as_slice::<f32>().expect("contiguous f32");
    let [w1, b1, g1, be1] = inputs.first.map(|t| Arc::new(values(t)));
    let z1 = kernels::conv_forward(xs, &w1, dims.first);
    let (h, stats1, sigmoid1) = norm_silu(&z1, [&b1, &g1, &be1], dims.norm1, None);
    let [w2, b2, g2, be2] = inputs.second.map(|t| Arc::new(values(t)));
    let z2 = kernels::conv_forward(&h, &w2, dims.second);
    let skip = inputs
        .skip
        .zip(dims.skip)
        .map(|([weight, bias], d)| (Arc::new(values(weight)), values(bias), d));
    let projected = skip
        .as_ref()
        .map(|(weight, _, d)| kernels::conv_forward(xs, weight, *d));
    let residual = match (&skip, &projected) {
        (Some((_, bias, _)), Some(projected)) => Residual {
            values: projected,
            bias: Some(bias),
        },
        _ => Residual {
            values: xs,
            bias: None,
        },
    };
    let (y, stats2, sigmoid2) = norm_silu(&z2, [&b2, &g2, &be2], dims.norm2, Some(residual));
    let y = flex_tensor(y, [dims.second.batch, dims.second.c_out, dims.second.len]);
    let saved = Saved {
        first: Half {
            params: [w1, b1, g1, be1],
            conv: dims.first,
            norm: dims.norm1,
            z: Arc::new(z1),
            stats: Arc::new(stats1),
            sigmoid: sigmoid1,
        },
        h: Arc::new(h),
        second: Half {
            params: [w2, b2, g2, be2],
            conv: dims.second,
            norm: dims.norm2,
            z: Arc::new(z2),
            stats: Arc::new(stats2),
            sigmoid: sigmoid2,
        },
        skip: skip.map(|(weight, _, d)| (weight, d)),
        x,
    };
    (y, saved)
}

/// The backward pass of a block with `N` parents: 9 without a projection, 11 with one.
#[derive(Debug)]
struct ResBlockBackward<const N: usize>;

impl<const N: usize> Backward<Flex, N> for ResBlockBackward<N> {
    type State = Saved;

    fn backward(self, ops: Ops<Saved, N>, grads: &mut Gradients, _: &mut Checkpointer) {
        let ids: Vec<Option<NodeId>> = ops
            .parents
            .iter()
            .map(|p| p.as_ref().map(|n| n.id))
            .collect();
        let id = |p: Parent| ids.get(p as usize).copied().flatten();
        let s = ops.state;
        let x = s.x.as_slice::<f32>().expect("contiguous f32");
        let mut gy = contiguous(&grads.consume::<Flex>(&ops.node));
        let x_tracked = id(Parent::X).is_some();
        // The residual path first, while the output gradient is intact: the projection's
        // gradients, and `x`'s share of it (the output gradient itself without a projection).
        let mut dx_residual = None;
        if let Some((weight, d)) = &s.skip {
            let gout = gy.as_slice::<f32>().expect("contiguous f32");
            if let Some(node) = id(Parent::SkipBias) {
                grads.register::<Flex>(node, flex_tensor(bias_gradient(gout, *d), [d.c_out]));
            }
            if let Some(node) = id(Parent::SkipWeight) {
                let dw = kernels::conv_backward_weight(gout, x, *d);
                grads.register::<Flex>(node, flex_tensor(dw, [d.c_out, d.c_in, 1]));
            }
            if x_tracked {
                dx_residual = Some(kernels::conv_backward_input(gout, weight, *d));
            }
        }
        // The second half's gradient `dz2` overwrites the output gradient, unless the output
        // gradient is still needed as `x`'s residual share: then a copy (in parallel).
        let keep_output_gradient = x_tracked && s.skip.is_none();
        let (rows, len) = (s.second.conv.batch * s.second.conv.c_out, s.second.conv.len);
        let mut copy;
        let mut buffer;
        let dz2: &mut [f32] = if keep_output_gradient {
            let gout = gy.as_slice::<f32>().expect("contiguous f32");
            copy = rows_by_blocks(rows, len, |row, from, out| {
                out.copy_from_slice(&gout[row * len + from..][..out.len()]);
            });
            &mut copy
        } else {
            buffer = output_gradient_buffer(&mut gy, rows * len);
            buffer.as_mut_slice()
        };
        let second_ids = [
            Parent::Weight2,
            Parent::Bias2,
            Parent::Gamma2,
            Parent::Beta2,
        ]
        .map(id);
        half_backward(grads, dz2, &s.h, &s.second, second_ids);
        let first_ids = [
            Parent::Weight1,
            Parent::Bias1,
            Parent::Gamma1,
            Parent::Beta1,
        ]
        .map(id);
        if !x_tracked && first_ids.iter().all(Option::is_none) {
            return;
        }
        let [w2, ..] = &s.second.params;
        let mut dz1 = kernels::conv_backward_input(dz2, w2, s.second.conv);
        half_backward(grads, &mut dz1, x, &s.first, first_ids);
        let Some(node) = id(Parent::X) else {
            return;
        };
        let [w1, ..] = &s.first.params;
        let d = s.first.conv;
        let mut dx = kernels::conv_backward_input(&dz1, w1, d);
        let residual: &[f32] = match &dx_residual {
            Some(projected) => projected,
            None => gy.as_slice::<f32>().expect("contiguous f32"),
        };
        add_in_parallel(&mut dx, residual);
        grads.register::<Flex>(node, flex_tensor(dx, [d.batch, d.c_in, d.len]));
    }
}

/// One half's backward pass: `grad` holds the half's output gradient on entry and its
/// convolution output's gradient `dz` on return; registers the gradients of its tracked
/// parameters (`ids`: weight, bias, gamma, beta). `input` is the half's convolution input.
fn half_backward(
    grads: &mut Gradients,
    grad: &mut [f32],
    input: &[f32],
    half: &Half,
    ids: [Option<NodeId>; 4],
) {
    let [weight, bias, gamma, beta] = &half.params;
    let [dbias, dgamma, dbeta] = kernels::norm_silu_backward_in_place(
        grad,
        &half.z,
        bias,
        gamma,
        beta,
        &half.stats,
        half.norm,
        half.sigmoid.as_ref().map(|s| s.as_slice()),
    );
    let [weight_id, channel_ids @ ..] = ids;
    register_channel_grads(grads, channel_ids, [dbias, dgamma, dbeta]);
    if let Some(node) = weight_id {
        let d = half.conv;
        let dw = kernels::conv_backward_weight(grad, input, d);
        debug_assert_eq!(dw.len(), weight.len());
        grads.register::<Flex>(node, flex_tensor(dw, [d.c_out, d.c_in, d.kernel]));
    }
}

/// `a += b`, in blocks on rayon's threads.
fn add_in_parallel(a: &mut [f32], b: &[f32]) {
    const CHUNK: usize = 1 << 14;
    assert_eq!(a.len(), b.len(), "add_in_parallel");
    a.par_chunks_mut(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(a, &b)| *a += b));
}
