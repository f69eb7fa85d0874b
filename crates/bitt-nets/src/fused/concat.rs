//! The channel concatenations of BTR's decoder (`[h, other hand's h, skip]`) and of the
//! albedo U-Net (`[skip, h]`) as one custom burn operation on flex.
//!
//! With burn's `cat` each input's gradient is a strided view of the output gradient, and
//! every one of these inputs has a second consumer (a skip connection feeds a convolution
//! too; BTR's `h` is also flipped for the other hand). burn's autodiff then adds the two
//! gradients through flex's strided element-wise path on one thread: in a profile of the
//! `quick` training step that was the largest single-threaded pass. Here the forward pass and
//! the gradients are row copies on rayon's threads, the gradients contiguous (so the
//! remaining sum takes flex's contiguous path), and BTR's `h` gets both of its shares, its
//! own and the other hand's, summed in the same pass.
//!
//! On every backend but flex (`f32`) [`cat_channels`] returns `None` and the caller uses
//! burn's `cat` (and `flip`); tests compare both, values and gradients.

use burn::backend::Flex;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor};

use super::{FlexAutodiff, autodiff_output, contiguous, flex_tensor, rows_by_blocks};

/// What lies between the two inputs of [`cat_channels`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Middle {
    /// Nothing: `[a, b]`.
    Nothing,
    /// `a` with the two halves of its batch swapped (BTR's other hand, paper eq. 4-5).
    SwappedHalves,
    /// As many zero channels as `a` has (BTR's "w/o bi-directional" ablation).
    Zeros,
}

/// `cat([a, middle(a), b], 1)` on flex, rectified (`max(0, .)`, the U-Net's ReLU before its
/// up-convolution) when `rectified`; `None` (nothing computed) on other backends or dtypes,
/// or when the shapes do not fit.
///
/// # Shapes
/// - `a`: `[N, C_a, ...]`; `b`: `[N, C_b, ...]` (the same trailing dimensions); `N` even
///   with [`Middle::SwappedHalves`]
/// - output: `[N, C_a + C_mid + C_b, ...]`, `C_mid` is `C_a` or 0
pub(crate) fn cat_channels<const D: usize>(
    a: &Tensor<D>,
    middle: Middle,
    b: &Tensor<D>,
    rectified: bool,
) -> Option<Tensor<D>> {
    #[cfg(test)]
    if super::conv2d::fusion_disabled() {
        return None;
    }
    let (da, db) = (a.dims(), b.dims());
    if D < 2
        || da[0] != db[0]
        || da[2..] != db[2..]
        || (middle == Middle::SwappedHalves && da[0] % 2 == 1)
    {
        return None;
    }
    let dims = CatDims {
        batch: da[0],
        c_a: da[1],
        c_mid: if middle == Middle::Nothing { 0 } else { da[1] },
        c_b: db[1],
        len: da[2..].iter().product(),
        middle,
        rectified,
    };
    let mut shape = da;
    shape[1] = dims.channels();
    if let Ok(aa) = a.clone().try_into_primitive::<FlexAutodiff>() {
        let ba = b.clone().try_into_primitive::<FlexAutodiff>().ok()?;
        if [aa.primitive(), ba.primitive()]
            .iter()
            .any(|t| t.dtype() != DType::F32)
        {
            return None;
        }
        let y = forward(aa.primitive(), ba.primitive(), dims, shape);
        let state = CatState {
            dims,
            shapes: [da, db],
            output: rectified.then(|| y.clone()),
        };
        return Some(autodiff_output(
            CatBackward::<D>,
            [aa.node(), ba.node()],
            state,
            y,
        ));
    }
    let af = a.clone().try_into_primitive::<Flex>().ok()?;
    let bf = b.clone().try_into_primitive::<Flex>().ok()?;
    if af.dtype() != DType::F32 || bf.dtype() != DType::F32 {
        return None;
    }
    Some(Tensor::from_primitive::<Flex>(forward(
        &af, &bf, dims, shape,
    )))
}

/// The sizes of a concatenation: per sample, `c_a + c_mid + c_b` rows of `len` values.
#[derive(Debug, Clone, Copy)]
struct CatDims {
    batch: usize,
    c_a: usize,
    c_mid: usize,
    c_b: usize,
    len: usize,
    middle: Middle,
    rectified: bool,
}

impl CatDims {
    fn channels(&self) -> usize {
        self.c_a + self.c_mid + self.c_b
    }

    /// The sample whose `a` the middle channels of sample `n` show: the other half's.
    fn swapped(&self, n: usize) -> usize {
        (n + self.batch / 2) % self.batch
    }
}

fn forward<const D: usize>(
    a: &FlexTensor,
    b: &FlexTensor,
    d: CatDims,
    shape: [usize; D],
) -> FlexTensor {
    let (a, b) = (contiguous(a), contiguous(b));
    let a = a.as_slice::<f32>().expect("contiguous f32");
    let b = b.as_slice::<f32>().expect("contiguous f32");
    let channels = d.channels();
    let y = rows_by_blocks(d.batch * channels, d.len, |row, from, out| {
        let (n, c) = (row / channels, row % channels);
        let source = if c < d.c_a {
            Some(&a[(n * d.c_a + c) * d.len..])
        } else if c < d.c_a + d.c_mid {
            match d.middle {
                Middle::SwappedHalves => Some(&a[(d.swapped(n) * d.c_a + c - d.c_a) * d.len..]),
                _ => None,
            }
        } else {
            Some(&b[(n * d.c_b + c - d.c_a - d.c_mid) * d.len..])
        };
        match source {
            Some(row) if d.rectified => {
                for (o, &v) in out.iter_mut().zip(&row[from..]) {
                    *o = v.max(0.0);
                }
            }
            Some(row) => out.copy_from_slice(&row[from..from + out.len()]),
            None => out.fill(0.0),
        }
    });
    flex_tensor(y, shape)
}

/// What the backward pass keeps: the sizes, both inputs' shapes and, when rectified, the
/// output (its positive values pass the gradient).
#[derive(Debug, Clone)]
struct CatState<const D: usize> {
    dims: CatDims,
    shapes: [[usize; D]; 2],
    output: Option<FlexTensor>,
}

#[derive(Debug)]
struct CatBackward<const D: usize>;

impl<const D: usize> Backward<Flex, 2> for CatBackward<D> {
    type State = CatState<D>;

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_a, node_b] = ops.parents;
        let CatState {
            dims: d,
            shapes: [shape_a, shape_b],
            output,
        } = ops.state;
        let g = contiguous(&grads.consume::<Flex>(&ops.node));
        let g = g.as_slice::<f32>().expect("contiguous f32");
        let y = output.map(|y| contiguous(&y));
        let y = y
            .as_ref()
            .map(|y| y.as_slice::<f32>().expect("contiguous f32"));
        // `out += g[at..]`, or `=`, where the output passed the gradient.
        let take = |out: &mut [f32], at: usize, add: bool| {
            let g = &g[at..at + out.len()];
            match (y, add) {
                (None, false) => out.copy_from_slice(g),
                (None, true) => out.iter_mut().zip(g).for_each(|(o, &v)| *o += v),
                (Some(y), add) => {
                    for ((o, &v), &y) in out.iter_mut().zip(g).zip(&y[at..]) {
                        let v = if y > 0.0 { v } else { 0.0 };
                        *o = if add { *o + v } else { v };
                    }
                }
            }
        };
        let channels = d.channels();
        if let Some(node) = node_b {
            let gb = rows_by_blocks(d.batch * d.c_b, d.len, |row, from, out| {
                let (n, c) = (row / d.c_b, row % d.c_b);
                take(
                    out,
                    (n * channels + d.c_a + d.c_mid + c) * d.len + from,
                    false,
                );
            });
            grads.register::<Flex>(node.id, flex_tensor(gb, shape_b));
        }
        if let Some(node) = node_a {
            let ga = rows_by_blocks(d.batch * d.c_a, d.len, |row, from, out| {
                let (n, c) = (row / d.c_a, row % d.c_a);
                take(out, (n * channels + c) * d.len + from, false);
                if d.middle == Middle::SwappedHalves {
                    // Sample `n`'s `a` is the middle of the other half's sample.
                    take(
                        out,
                        (d.swapped(n) * channels + d.c_a + c) * d.len + from,
                        true,
                    );
                }
            });
            grads.register::<Flex>(node.id, flex_tensor(ga, shape_a));
        }
    }
}

#[cfg(test)]
mod tests {
    use bitt_testkit::{random, to_vec};
    use burn::tensor::Device;
    use burn::tensor::activation::relu;

    use super::*;

    /// burn's composition: `cat([a, middle(a), b], 1)`, rectified when asked.
    fn composed<const D: usize>(
        a: &Tensor<D>,
        middle: Middle,
        b: &Tensor<D>,
        rectified: bool,
    ) -> Tensor<D> {
        let half = a.dims()[0] / 2;
        let mut parts = vec![a.clone()];
        match middle {
            Middle::Nothing => {}
            Middle::SwappedHalves => parts.push(Tensor::cat(
                vec![
                    a.clone().narrow(0, half, half),
                    a.clone().narrow(0, 0, half),
                ],
                0,
            )),
            Middle::Zeros => parts.push(a.zeros_like()),
        }
        parts.push(b.clone());
        let y = Tensor::cat(parts, 1);
        if rectified { relu(y) } else { y }
    }

    /// Values and both inputs' gradients equal burn's `cat` (and `narrow`, `relu`), for each
    /// middle, rectified or not, on rank 3 and 4 and batches of 2 and 4.
    #[test]
    fn cat_channels_equals_burn_cat_values_and_gradients() {
        let ad = Device::flex().autodiff();
        for middle in [Middle::Nothing, Middle::SwappedHalves, Middle::Zeros] {
            for rectified in [false, true] {
                for batch in [2, 4] {
                    let what = format!("{middle:?} rectified {rectified} batch {batch}");
                    let a = random([batch, 3, 7], 1, &ad).require_grad();
                    let b = random([batch, 2, 7], 2, &ad).require_grad();
                    let channels = if middle == Middle::Nothing { 5 } else { 8 };
                    let w = random([batch, channels, 7], 3, &ad);
                    let mut results = Vec::new();
                    for fused in [true, false] {
                        let y = if fused {
                            cat_channels(&a, middle, &b, rectified).expect("flex")
                        } else {
                            composed(&a, middle, &b, rectified)
                        };
                        let grads = (y.clone() * w.clone()).sum().backward();
                        results.push([
                            to_vec(y.inner()),
                            to_vec(a.grad(&grads).unwrap()),
                            to_vec(b.grad(&grads).unwrap()),
                        ]);
                    }
                    assert_eq!(results[0], results[1], "{what}");
                }
            }
        }
        // Rank 4, without autodiff.
        let device = Device::flex();
        let (a, b) = (
            random([2, 2, 3, 5], 4, &device),
            random([2, 1, 3, 5], 5, &device),
        );
        let y = cat_channels(&a, Middle::Nothing, &b, true).expect("flex");
        assert_eq!(
            to_vec(y),
            to_vec(composed(&a, Middle::Nothing, &b, true)),
            "rank 4"
        );
        // Shapes that do not fit are declined.
        let odd = random([3, 2, 5], 6, &device);
        assert!(cat_channels(&odd, Middle::SwappedHalves, &odd, false).is_none());
        let short = random([3, 2, 4], 7, &device);
        assert!(cat_channels(&odd, Middle::Nothing, &short, false).is_none());
    }
}
