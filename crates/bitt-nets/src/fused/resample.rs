//! The albedo U-Net's two resampling steps and BTR's texel upsampling as custom burn
//! operations on flex, each one pass forward and one backward:
//!
//! - [`upsample2`]: nearest-neighbour x2 upsampling. Composed from burn operations it is a
//!   `reshape`, an `expand` and a `reshape`, whose last step copies the stride-0 view
//!   element by element, and whose backward pass is two `sum_dim`s over strided axes.
//! - [`upsample2_texels_on_flex`]: the same along BTR's texel axis (`[N, C, L] -> [N, C, 2L]`), one
//!   `expand` and one `sum_dim`, composed.
//! - [`interleave_phases`]: the outermost level's four output phases
//!   (`albedo::outermost_up`) woven into the full-resolution image. Composed, it is four
//!   slices, four copies and three concatenations; its backward pass zeroes a buffer the
//!   size of the phases' input for each of the four slices and adds the four.
//!
//! - [`pad_edge1`]: the outermost U-Net level's edge padding by one pixel on each side
//!   (`albedo::outermost_up`). burn composes it from zero-filled buffers, slices, repeats and
//!   slice assignments, each way on one thread.
//!
//! All compute exactly what the compositions compute, values and gradients bit for bit
//! (the upsampling gradient adds the four pixels in the order burn's two `sum_dim`s do).
//! On every backend but flex (`f32`) they return `None` and the caller composes burn
//! operations; tests compare both.

use burn::backend::Flex;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use super::{FlexAutodiff, autodiff_output, contiguous, flex_tensor};

/// Runs a one-input data-movement operation on flex, with its backward `op` registered when
/// the input is tracked; `None` off flex or off `f32`.
fn run<const D: usize, Op: Backward<Flex, 1>>(
    x: &Tensor<D>,
    op: Op,
    state: Op::State,
    forward: impl FnOnce(&[f32]) -> FlexTensor,
) -> Option<Tensor<D>> {
    #[cfg(test)]
    if super::conv2d::fusion_disabled() {
        return None;
    }
    if let Ok(xa) = x.clone().try_into_primitive::<FlexAutodiff>() {
        if xa.primitive().dtype() != DType::F32 {
            return None;
        }
        let xc = contiguous(xa.primitive());
        let y = forward(xc.as_slice::<f32>().expect("contiguous f32"));
        return Some(autodiff_output(op, [xa.node()], state, y));
    }
    let xf = x.clone().try_into_primitive::<Flex>().ok()?;
    if xf.dtype() != DType::F32 {
        return None;
    }
    let xc = contiguous(&xf);
    let y = forward(xc.as_slice::<f32>().expect("contiguous f32"));
    Some(Tensor::from_primitive::<Flex>(y))
}

/// Nearest-neighbour x2 upsampling on any backend: one pass on flex, else the burn
/// composition.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, 2H, 2W]`
pub(crate) fn upsample2(x: Tensor<4>) -> Tensor<4> {
    upsample2_on_flex(&x).unwrap_or_else(|| upsample2_composed(x))
}

/// [`upsample2`] as burn operations.
fn upsample2_composed(x: Tensor<4>) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    x.reshape([n, c, h, 1, w, 1])
        .expand([n, c, h, 2, w, 2])
        .reshape([n, c, 2 * h, 2 * w])
}

/// [`upsample2`] on flex; `None` (nothing computed) elsewhere.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, 2H, 2W]`
fn upsample2_on_flex(x: &Tensor<4>) -> Option<Tensor<4>> {
    let shape = x.dims();
    let [n, c, h, w] = shape;
    run(x, Upsample2Backward, shape, |x| {
        flex_tensor(upsample_rows(x, n * c * h, w), [n, c, 2 * h, 2 * w])
    })
}

/// `[rows, w]` -> `[2 rows, 2 w]`: each input row becomes two output rows, each value two
/// neighbours.
fn upsample_rows(x: &[f32], rows: usize, w: usize) -> Vec<f32> {
    super::rows_by_blocks(2 * rows, 2 * w, |r, from, out| {
        let row = &x[(r / 2) * w..(r / 2 + 1) * w];
        for (k, v) in out.iter_mut().enumerate() {
            *v = row[(from + k) / 2];
        }
    })
}

/// The gradient of [`upsample_rows`]: `[2 rows, 2 w]` -> `[rows, w]`, each input the sum of
/// its four outputs, added as burn's `expand` backward adds them (over the row pair first,
/// then over the column pair).
fn downsample_rows(g: &[f32], rows: usize, w: usize) -> Vec<f32> {
    super::rows_by_blocks(rows, w, |r, from, out| {
        let (top, bottom) = g[r * 4 * w..(r + 1) * 4 * w].split_at(2 * w);
        for (k, d) in out.iter_mut().enumerate() {
            let j = from + k;
            let left = top[2 * j] + bottom[2 * j];
            let right = top[2 * j + 1] + bottom[2 * j + 1];
            *d = left + right;
        }
    })
}

/// Nearest-neighbour x2 upsampling along the last axis as burn operations (any backend).
///
/// # Shapes
/// - `x`: `[N, C, L]`
/// - output: `[N, C, 2L]`
pub(crate) fn upsample2_texels_composed(x: Tensor<3>) -> Tensor<3> {
    let [n, c, l] = x.dims();
    x.unsqueeze_dim::<4>(3)
        .expand([n, c, l, 2])
        .reshape([n, c, 2 * l])
}

/// [`upsample2_texels_composed`] in one pass on flex (backward one pass too); `None`
/// (nothing computed) elsewhere.
pub(crate) fn upsample2_texels_on_flex(x: &Tensor<3>) -> Option<Tensor<3>> {
    let shape = x.dims();
    let [n, c, l] = shape;
    run(x, UpsampleTexelsBackward, shape, |x| {
        let y = super::rows_by_blocks(n * c, 2 * l, |r, from, out| {
            let row = &x[r * l..(r + 1) * l];
            for (k, v) in out.iter_mut().enumerate() {
                *v = row[(from + k) / 2];
            }
        });
        flex_tensor(y, [n, c, 2 * l])
    })
}

#[derive(Debug)]
struct UpsampleTexelsBackward;

impl Backward<Flex, 1> for UpsampleTexelsBackward {
    type State = [usize; 3];

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let shape = ops.state;
        let [n, c, l] = shape;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        if let Some(node) = node_x {
            let g = gy.as_slice::<f32>().expect("contiguous f32");
            // Each texel's gradient: its two copies' gradients added.
            let dx = super::rows_by_blocks(n * c, l, |r, from, out| {
                let pairs = &g[2 * (r * l + from)..];
                for (k, d) in out.iter_mut().enumerate() {
                    *d = pairs[2 * k] + pairs[2 * k + 1];
                }
            });
            grads.register::<Flex>(node.id, flex_tensor(dx, shape));
        }
    }
}

/// Edge padding by one pixel on each side of the last two axes (burn's `PadMode::Edge`):
/// one pass each way on flex, else burn's composition.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, H + 2, W + 2]`
pub(crate) fn pad_edge1(x: Tensor<4>) -> Tensor<4> {
    pad_edge1_on_flex(&x).unwrap_or_else(|| pad_edge1_composed(x))
}

/// [`pad_edge1`] as burn operations.
fn pad_edge1_composed(x: Tensor<4>) -> Tensor<4> {
    x.pad((1, 1, 1, 1), burn::tensor::ops::PadMode::Edge)
}

/// [`pad_edge1`] on flex; `None` (nothing computed) elsewhere, and for planes narrower or
/// lower than 2 pixels (whose three copies of one pixel burn adds in another order).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`
/// - output: `[N, C, H + 2, W + 2]`
fn pad_edge1_on_flex(x: &Tensor<4>) -> Option<Tensor<4>> {
    let shape = x.dims();
    let [n, c, h, w] = shape;
    if h < 2 || w < 2 {
        return None;
    }
    run(x, PadEdgeBackward, shape, |x| {
        let y = super::rows_by_blocks(n * c * (h + 2), w + 2, |r, from, out| {
            // Output row `r` of plane `r / (h + 2)` repeats input row `clamp(r - 1)`.
            let (plane, i) = (r / (h + 2), r % (h + 2));
            let row = &x[(plane * h + i.saturating_sub(1).min(h - 1)) * w..][..w];
            for (k, v) in out.iter_mut().enumerate() {
                *v = row[(from + k).saturating_sub(1).min(w - 1)];
            }
        });
        flex_tensor(y, [n, c, h + 2, w + 2])
    })
}

/// The gradient of [`pad_edge1`] (`H, W >= 2`): `[N, C, H + 2, W + 2]` -> `[N, C, H, W]`.
/// A border pixel's copies are added as burn's composition adds them: the columns first (the
/// composition pads the rows first, so its backward undoes the columns first), then the rows.
fn pad_edge1_gradient(g: &[f32], [n, c, h, w]: [usize; 4]) -> Vec<f32> {
    let w2 = w + 2;
    // Row `r` of the padded gradient with its columns folded back: `[w]` values.
    let folded = |r: usize, j: usize| -> f32 {
        let row = &g[r * w2..][..w2];
        if j == 0 {
            row[1] + row[0]
        } else if j == w - 1 {
            row[w] + row[w + 1]
        } else {
            row[j + 1]
        }
    };
    super::rows_by_blocks(n * c * h, w, |r, from, out| {
        let (plane, i) = (r / h, r % h);
        let base = plane * (h + 2);
        for (k, d) in out.iter_mut().enumerate() {
            let j = from + k;
            let centre = folded(base + i + 1, j);
            *d = if i == 0 {
                centre + folded(base, j)
            } else if i == h - 1 {
                centre + folded(base + h + 1, j)
            } else {
                centre
            };
        }
    })
}

#[derive(Debug)]
struct PadEdgeBackward;

impl Backward<Flex, 1> for PadEdgeBackward {
    type State = [usize; 4];

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let shape = ops.state;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        if let Some(node) = node_x {
            let g = gy.as_slice::<f32>().expect("contiguous f32");
            grads.register::<Flex>(node.id, flex_tensor(pad_edge1_gradient(g, shape), shape));
        }
    }
}

#[derive(Debug)]
struct Upsample2Backward;

impl Backward<Flex, 1> for Upsample2Backward {
    type State = [usize; 4];

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let shape = ops.state;
        let [n, c, h, w] = shape;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        if let Some(node) = node_x {
            let g = gy.as_slice::<f32>().expect("contiguous f32");
            grads.register::<Flex>(
                node.id,
                flex_tensor(downsample_rows(g, n * c * h, w), shape),
            );
        }
    }
}

/// Sizes of [`interleave_phases`]: the phases' input `[N, 4 C, H + 1, W + 1]`, the output
/// `[N, C, 2H, 2W]`.
#[derive(Debug, Clone, Copy)]
struct PhaseDims {
    n: usize,
    c: usize,
    h: usize,
    w: usize,
}

impl PhaseDims {
    fn input(&self) -> [usize; 4] {
        [self.n, 4 * self.c, self.h + 1, self.w + 1]
    }

    /// Output rows, `N C 2H`.
    fn rows(&self) -> usize {
        self.n * self.c * self.h * 2
    }
}

/// `out[b, o, 2a + py, 2j + px] = x[b, (2 py + px) C + o, a + py, j + px]` on any backend:
/// one pass on flex, else the burn composition. The outermost level's phase `(py, px)`
/// lives at rows `py..`, columns `px..` of its `C` channels (`albedo::outermost_up`).
///
/// # Shapes
/// - `x`: `[N, 4 C, H + 1, W + 1]`
/// - output: `[N, C, 2H, 2W]`
///
/// # Panics
/// When `x` has not `4 C` channels or a side below 2.
pub(crate) fn interleave_phases(x: Tensor<4>, c: usize) -> Tensor<4> {
    interleave_on_flex(&x, c).unwrap_or_else(|| interleave_composed(x, c))
}

/// [`interleave_phases`] as burn operations: four slices, woven by concatenation.
fn interleave_composed(x: Tensor<4>, c: usize) -> Tensor<4> {
    let [b, c4, h1, w1] = x.dims();
    assert!(
        c4 == 4 * c && h1 > 1 && w1 > 1,
        "interleave_phases: x is {:?}",
        x.dims()
    );
    let (h, w) = (h1 - 1, w1 - 1);
    let phase = |k: usize, py: usize, px: usize| {
        x.clone()
            .slice([0..b, k * c..(k + 1) * c, py..py + h, px..px + w])
            .reshape([b, c, h, 1, w, 1])
    };
    let even = Tensor::cat(vec![phase(0, 0, 0), phase(1, 0, 1)], 5);
    let odd = Tensor::cat(vec![phase(2, 1, 0), phase(3, 1, 1)], 5);
    Tensor::cat(vec![even, odd], 3).reshape([b, c, 2 * h, 2 * w])
}

/// [`interleave_phases`] on flex; `None` (nothing computed) elsewhere or for other sizes.
fn interleave_on_flex(x: &Tensor<4>, c: usize) -> Option<Tensor<4>> {
    let [n, c4, h1, w1] = x.dims();
    if c4 != 4 * c || h1 < 2 || w1 < 2 {
        return None;
    }
    let d = PhaseDims {
        n,
        c,
        h: h1 - 1,
        w: w1 - 1,
    };
    run(x, InterleaveBackward, d, |x| {
        flex_tensor(interleave(x, d), [d.n, d.c, 2 * d.h, 2 * d.w])
    })
}

/// The input row of output row `r` (of `[N, C, 2H]` rows) and, for each column parity
/// `px`, the input offset of its first value.
fn source_row(d: PhaseDims, r: usize) -> [usize; 2] {
    let (w1, h1) = (d.w + 1, d.h + 1);
    let (bo, y) = (r / (2 * d.h), r % (2 * d.h));
    let (b, o) = (bo / d.c, bo % d.c);
    let (a, py) = (y / 2, y % 2);
    [0, 1].map(|px| {
        let channel = (2 * py + px) * d.c + o;
        ((b * 4 * d.c + channel) * h1 + a + py) * w1 + px
    })
}

fn interleave(x: &[f32], d: PhaseDims) -> Vec<f32> {
    super::rows_by_blocks(d.rows(), 2 * d.w, |r, from, out| {
        let starts = source_row(d, r);
        for (k, v) in out.iter_mut().enumerate() {
            let j = from + k;
            *v = x[starts[j % 2] + j / 2];
        }
    })
}

/// The gradient of [`interleave`]: each output's gradient back at its input, zero at the
/// inputs no phase reads (each input is read at most once).
fn deinterleave(g: &[f32], d: PhaseDims) -> Vec<f32> {
    let [n, c4, h1, w1] = d.input();
    let mut dx = super::zeros(n * c4 * h1 * w1);
    let w2 = 2 * d.w;
    if w2 == 0 {
        return dx;
    }
    // Each input plane `[H + 1, W + 1]` is written by the output rows of one (b, channel):
    // split by planes so that threads write disjoint parts.
    dx.par_chunks_exact_mut(h1 * w1)
        .enumerate()
        .for_each(|(plane, dst)| {
            let (b, channel) = (plane / c4, plane % c4);
            let (k, o) = (channel / d.c, channel % d.c);
            let (py, px) = (k / 2, k % 2);
            for a in 0..d.h {
                let r = (b * d.c + o) * 2 * d.h + 2 * a + py;
                let src = &g[r * w2..(r + 1) * w2];
                let row = &mut dst[(a + py) * w1 + px..];
                for (j, v) in src.iter().skip(px).step_by(2).enumerate() {
                    row[j] = *v;
                }
            }
        });
    dx
}

#[derive(Debug)]
struct InterleaveBackward;

impl Backward<Flex, 1> for InterleaveBackward {
    type State = PhaseDims;

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let d = ops.state;
        let gy = contiguous(&grads.consume::<Flex>(&ops.node));
        if let Some(node) = node_x {
            let g = gy.as_slice::<f32>().expect("contiguous f32");
            grads.register::<Flex>(node.id, flex_tensor(deinterleave(g, d), d.input()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    fn values(t: Tensor<4>) -> Vec<f32> {
        bitt_testkit::to_vec(t)
    }

    fn input(shape: [usize; 4], device: &Device) -> Tensor<4> {
        let n = shape.iter().product::<usize>();
        let v: Vec<f32> = (0..n)
            .map(|i| ((i * 37 + 11) % 23) as f32 / 7.0 - 1.5 + i as f32 * 1e-3)
            .collect();
        Tensor::from_data(TensorData::new(v, shape), device)
    }

    /// Values and gradients bit for bit those of the burn compositions, with and without
    /// autodiff, and `None` off flex.
    #[test]
    fn resampling_matches_the_burn_compositions_bit_for_bit() {
        let device = Device::flex().autodiff();
        for shape in [[2, 3, 4, 5], [1, 1, 1, 1], [4, 2, 7, 3]] {
            let x = input(shape, &device).require_grad();
            let ours = upsample2_on_flex(&x).expect("runs on flex");
            let theirs = upsample2_composed(x.clone());
            assert_eq!(values(ours.clone()), values(theirs.clone()), "{shape:?}");
            let w = input(ours.dims(), &device).detach() * 3.0 + 0.5;
            let a = x.grad(&(ours * w.clone()).sum().backward()).unwrap();
            let b = x.grad(&(theirs * w).sum().backward()).unwrap();
            assert_eq!(values(a), values(b), "upsample2 gradient {shape:?}");
        }
        for (co, h, w) in [(3, 4, 5), (1, 1, 1), (2, 6, 3)] {
            let x = input([2, 4 * co, h + 1, w + 1], &device).require_grad();
            let ours = interleave_on_flex(&x, co).expect("runs on flex");
            let theirs = interleave_composed(x.clone(), co);
            assert_eq!(values(ours.clone()), values(theirs.clone()), "{co} {h} {w}");
            let wt = input(ours.dims(), &device).detach() * 3.0 + 0.5;
            let a = x.grad(&(ours * wt.clone()).sum().backward()).unwrap();
            let b = x.grad(&(theirs * wt).sum().backward()).unwrap();
            assert_eq!(values(a), values(b), "interleave gradient {co} {h} {w}");
        }
        for shape in [[2, 3, 5], [1, 1, 1], [2, 8, 300]] {
            let x = input([shape[0], shape[1], 1, shape[2]], &device)
                .reshape(shape)
                .require_grad();
            let ours = upsample2_texels_on_flex(&x).expect("runs on flex");
            let theirs = upsample2_texels_composed(x.clone());
            assert_eq!(
                values(ours.clone().unsqueeze()),
                values(theirs.clone().unsqueeze())
            );
            let w = ours.clone().detach() * 3.0 + 0.5;
            let a = x.grad(&(ours * w.clone()).sum().backward()).unwrap();
            let b = x.grad(&(theirs * w).sum().backward()).unwrap();
            assert_eq!(
                values(a.unsqueeze()),
                values(b.unsqueeze()),
                "texels {shape:?}"
            );
        }
        for shape in [[2, 3, 4, 5], [1, 2, 2, 2], [3, 1, 2, 7], [1, 1, 6, 2]] {
            let x = input(shape, &device).require_grad();
            let ours = pad_edge1_on_flex(&x).expect("runs on flex");
            let theirs = pad_edge1_composed(x.clone());
            assert_eq!(
                values(ours.clone()),
                values(theirs.clone()),
                "pad {shape:?}"
            );
            let w = input(ours.dims(), &device).detach() * 3.0 + 0.5;
            let a = x.grad(&(ours * w.clone()).sum().backward()).unwrap();
            let b = x.grad(&(theirs * w).sum().backward()).unwrap();
            assert_eq!(values(a), values(b), "pad gradient {shape:?}");
        }
        for shape in [[1, 1, 1, 1], [1, 2, 1, 3], [2, 1, 3, 1]] {
            assert!(
                pad_edge1_on_flex(&input(shape, &device)).is_none(),
                "{shape:?}"
            );
        }
        let plain = input([2, 8, 4, 3], &Device::flex());
        assert_eq!(
            values(upsample2_on_flex(&plain).unwrap()),
            values(upsample2_composed(plain.clone()))
        );
        assert_eq!(
            values(interleave_on_flex(&plain, 2).unwrap()),
            values(interleave_composed(plain.clone(), 2))
        );
        assert!(interleave_on_flex(&plain, 3).is_none(), "8 is not 4 x 3");
        assert_eq!(
            values(pad_edge1_on_flex(&plain).unwrap()),
            values(pad_edge1_composed(plain.clone()))
        );
        for (name, other) in bitt_testkit::devices()
            .into_iter()
            .filter(|(n, _)| *n != "flex")
        {
            for device in [other.clone(), other.autodiff()] {
                let x = input([1, 4, 2, 2], &device);
                assert!(upsample2_on_flex(&x).is_none(), "{name}");
                assert!(pad_edge1_on_flex(&x).is_none(), "{name}");
                let t = x.clone().reshape([1, 4, 4]);
                assert!(upsample2_texels_on_flex(&t).is_none(), "{name}");
                assert!(interleave_on_flex(&x, 1).is_none(), "{name}");
            }
        }
    }
}
