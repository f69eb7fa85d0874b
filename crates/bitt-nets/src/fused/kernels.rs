//! CPU kernels of BTR's `SiLU(GroupNorm(conv(x)))` block on plain `f32` slices: the
//! convolution and its two backward products as GEMMs over shifted views (no padding copies,
//! the taps accumulate into one buffer), and group norm + SiLU as two passes per row forward
//! and two backward. Rows are `[batch, channels, len]` row-major; rows run in parallel on
//! rayon, and the per-element loops are compiled for the best instruction set present
//! (`pulp`).

use pulp::{Arch, Simd};
use rayon::prelude::*;

use super::gemm::{Columns, MatMut, MatRef, matmul, products_into_new};
use super::scratch::Scratch;
use super::vectorized::vectorized;

/// Sizes of a stride-1, zero-padded ("same") 1-D convolution over a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ConvDims {
    pub batch: usize,
    pub c_in: usize,
    pub c_out: usize,
    pub len: usize,
    /// Odd; padded by `kernel / 2` on each side.
    pub kernel: usize,
}

impl ConvDims {
    /// Taps `(j, offset)`, the centre first: output `t` reads input `t + offset`.
    fn taps(&self) -> impl Iterator<Item = (usize, isize)> {
        let pad = self.kernel / 2;
        std::iter::once(pad)
            .chain((0..self.kernel).filter(move |&j| j != pad))
            .map(move |j| (j, j as isize - pad as isize))
    }

    /// Tap `j` of `weight [c_out, c_in, kernel]` as a `[c_out, c_in]` matrix.
    fn tap<'a>(&self, weight: &'a [f32], j: usize) -> MatRef<'a> {
        MatRef {
            data: &weight[j..],
            rows: self.c_out,
            cols: self.c_in,
            row_stride: self.c_in * self.kernel,
            col_stride: self.kernel,
        }
    }

    /// Tap `j` transposed, `[c_in, c_out]`.
    fn tap_t<'a>(&self, weight: &'a [f32], j: usize) -> MatRef<'a> {
        MatRef {
            data: &weight[j..],
            rows: self.c_in,
            cols: self.c_out,
            row_stride: self.kernel,
            col_stride: self.c_in * self.kernel,
        }
    }
}

/// Output columns `[lo, hi)` of a length-`len` signal whose input `t + offset` lies inside
/// it.
fn valid_columns(len: usize, offset: isize) -> (usize, usize) {
    let l = len as isize;
    let lo = (-offset).clamp(0, l) as usize;
    (lo, ((l - offset).clamp(0, l) as usize).max(lo))
}

/// Columns `[from, from + cols)` of a row-major `[rows, len]` block.
fn columns(data: &[f32], rows: usize, len: usize, from: usize, cols: usize) -> MatRef<'_> {
    MatRef {
        data: &data[from..],
        rows,
        cols,
        row_stride: len,
        col_stride: 1,
    }
}

/// [`shifted_products`] for every sample of a batch: `src` is `[batch, rows_in, len]`, the
/// result `[batch, rows_out, len]` (a new buffer the products overwrite, never cleared). The
/// samples run on rayon's threads with single-threaded GEMMs when there are at least as many
/// as threads (BTR's two hands on two cores), else one at a time with multi-threaded GEMMs.
fn batched_products(
    src: &[f32],
    batch: usize,
    rows_out: usize,
    len: usize,
    taps: &[(MatRef<'_>, isize)],
) -> Vec<f32> {
    if batch * rows_out * len == 0 {
        return Vec::new();
    }
    let rows_in = src.len() / (batch * len);
    let in_parallel = batch >= rayon::current_num_threads();
    products_into_new(
        batch,
        rows_out,
        len,
        in_parallel,
        || (),
        |(), b, dst| {
            let s = &src[b * rows_in * len..(b + 1) * rows_in * len];
            shifted_products(dst, s, len, taps, !in_parallel);
        },
    )
}

/// Input channels up to which [`shifted_products`] stacks the shifted inputs into one GEMM
/// (im2col along the texel axis, in blocks) instead of one GEMM per tap: with few channels
/// a per-tap GEMM is bound by re-reading its destination.
const IM2COL_MAX_CHANNELS: usize = 64;
/// Texels per im2col block (the stacked block stays in cache).
const IM2COL_BLOCK: usize = 2048;

/// For one sample, `dst[:, t] = sum_i A_i src[:, t + offset_i]` with `src` zero outside
/// `[0, len)`; every column of `dst` is written.
///
/// # Shapes
/// - `dst`: `[rows_out, len]`; `src`: `[rows_in, len]`; each `A_i`: `[rows_out, rows_in]`
fn shifted_products(
    dst: &mut Columns<'_>,
    src: &[f32],
    len: usize,
    taps: &[(MatRef<'_>, isize)],
    parallel: bool,
) {
    let Some(&(first, _)) = taps.first() else {
        return;
    };
    if taps.len() == 1 || first.cols > IM2COL_MAX_CHANNELS {
        per_tap_products(dst, src, len, taps, parallel);
    } else {
        stacked_products(dst, src, len, taps, [first.rows, first.cols], parallel);
    }
}

/// [`shifted_products`] as one GEMM per tap: the first (the centre, offset 0, every column)
/// overwrites `dst`, the others accumulate onto it.
fn per_tap_products(
    dst: &mut Columns<'_>,
    src: &[f32],
    len: usize,
    taps: &[(MatRef<'_>, isize)],
    parallel: bool,
) {
    for (n, &(a, offset)) in taps.iter().enumerate() {
        let (lo, hi) = valid_columns(len, offset);
        if hi > lo {
            let from = (lo as isize + offset) as usize;
            dst.product(
                lo,
                a,
                columns(src, a.cols, len, from, hi - lo),
                n > 0,
                parallel,
            );
        }
    }
}

/// [`shifted_products`] as one GEMM per block of texels over the stacked shifted inputs.
fn stacked_products(
    dst: &mut Columns<'_>,
    src: &[f32],
    len: usize,
    taps: &[(MatRef<'_>, isize)],
    [rows_out, rows_in]: [usize; 2],
    parallel: bool,
) {
    // The taps side by side, `[rows_out, taps * rows_in]`, and blocks of stacked shifted rows.
    let k = taps.len() * rows_in;
    let mut combined = vec![0.0f32; rows_out * k];
    for (i, (a, _)) in taps.iter().enumerate() {
        for o in 0..rows_out {
            for c in 0..rows_in {
                combined[o * k + i * rows_in + c] = a.data[o * a.row_stride + c * a.col_stride];
            }
        }
    }
    let combined = MatRef {
        data: &combined,
        rows: rows_out,
        cols: k,
        row_stride: k,
        col_stride: 1,
    };
    // Every element of a block is written below (zeros outside the signal, copies inside).
    let mut stacked = Scratch::new(k * IM2COL_BLOCK.min(len));
    for t0 in (0..len).step_by(IM2COL_BLOCK) {
        let cols = IM2COL_BLOCK.min(len - t0);
        for (i, &(_, offset)) in taps.iter().enumerate() {
            // Block columns u with 0 <= t0 + u + offset < len.
            let start = t0 as isize + offset;
            let lo = (-start).clamp(0, cols as isize) as usize;
            let hi = ((len as isize - start).clamp(0, cols as isize) as usize).max(lo);
            for c in 0..rows_in {
                let row = &mut stacked[(i * rows_in + c) * cols..(i * rows_in + c + 1) * cols];
                row[..lo].fill(0.0);
                row[hi..].fill(0.0);
                if hi > lo {
                    let s0 = c * len + (start + lo as isize) as usize;
                    row[lo..hi].copy_from_slice(&src[s0..s0 + hi - lo]);
                }
            }
        }
        dst.product(
            t0,
            combined,
            MatRef {
                data: &stacked[..k * cols],
                rows: k,
                cols,
                row_stride: cols,
                col_stride: 1,
            },
            false,
            parallel,
        );
    }
}

/// `z[b, o, t] = sum_{j, c} w[o, c, j] x[b, c, t + j - kernel / 2]` (zero outside), no bias.
///
/// # Shapes
/// - `x`: `[batch, c_in, len]`; `weight`: `[c_out, c_in, kernel]`
/// - output: `[batch, c_out, len]`
pub(crate) fn conv_forward(x: &[f32], weight: &[f32], d: ConvDims) -> Vec<f32> {
    assert_eq!(weight.len(), d.c_out * d.c_in * d.kernel, "conv_forward: w");
    tap_products(x, weight, d, false)
}

/// Gradient of [`conv_forward`] with respect to `x`.
///
/// # Shapes
/// - `dz`: `[batch, c_out, len]`; `weight`: `[c_out, c_in, kernel]`
/// - output: `[batch, c_in, len]`
pub(crate) fn conv_backward_input(dz: &[f32], weight: &[f32], d: ConvDims) -> Vec<f32> {
    // dx[:, s] += W_j^T dz[:, s - offset_j].
    tap_products(dz, weight, d, true)
}

/// The convolution's taps applied to `src`: `W_j src[:, t + offset_j]` summed over the taps
/// (`transposed = false`, the forward pass), or `W_j^T src[:, t - offset_j]` (`true`, the
/// gradient with respect to the input).
///
/// # Shapes
/// - `src`: `[batch, c_in, len]` (`[batch, c_out, len]` when `transposed`)
/// - output: `[batch, c_out, len]` (`[batch, c_in, len]` when `transposed`)
fn tap_products(src: &[f32], weight: &[f32], d: ConvDims, transposed: bool) -> Vec<f32> {
    let (rows_in, rows_out) = if transposed {
        (d.c_out, d.c_in)
    } else {
        (d.c_in, d.c_out)
    };
    assert_eq!(
        src.len(),
        d.batch * rows_in * d.len,
        "conv taps: input size"
    );
    let taps: Vec<(MatRef<'_>, isize)> = d
        .taps()
        .map(|(j, offset)| {
            if transposed {
                (d.tap_t(weight, j), -offset)
            } else {
                (d.tap(weight, j), offset)
            }
        })
        .collect();
    batched_products(src, d.batch, rows_out, d.len, &taps)
}

/// Gradient of [`conv_forward`] with respect to the weight. The texel axis (the long
/// reduction) is split across rayon's threads and the partial sums added in order.
///
/// # Shapes
/// - `dz`: `[batch, c_out, len]`; `x`: `[batch, c_in, len]`
/// - output: `[c_out, c_in, kernel]`
pub(crate) fn conv_backward_weight(dz: &[f32], x: &[f32], d: ConvDims) -> Vec<f32> {
    assert_eq!(
        dz.len(),
        d.batch * d.c_out * d.len,
        "conv_backward_weight: dz"
    );
    assert_eq!(x.len(), d.batch * d.c_in * d.len, "conv_backward_weight: x");
    let size = d.c_out * d.c_in * d.kernel;
    let parts = rayon::current_num_threads().clamp(1, d.len.max(1));
    let chunk = d.len.div_ceil(parts).max(1);
    // Each part accumulates contiguous per-tap blocks `[kernel][c_out][c_in]` (GEMM runs much
    // faster into a contiguous destination than into the interleaved weight layout).
    let partial = |part: usize| {
        let mut taps = vec![0.0f32; size];
        let (start, end) = (part * chunk, ((part + 1) * chunk).min(d.len));
        for (gb, xb) in dz
            .chunks_exact(d.c_out * d.len)
            .zip(x.chunks_exact(d.c_in * d.len))
        {
            for (j, offset) in d.taps() {
                let (lo, hi) = valid_columns(d.len, offset);
                let (lo, hi) = (lo.max(start), hi.min(end));
                if hi <= lo {
                    continue;
                }
                let from = (lo as isize + offset) as usize;
                matmul(
                    MatMut {
                        data: &mut taps[j * d.c_out * d.c_in..(j + 1) * d.c_out * d.c_in],
                        rows: d.c_out,
                        cols: d.c_in,
                        row_stride: d.c_in,
                        col_stride: 1,
                    },
                    columns(gb, d.c_out, d.len, lo, hi - lo),
                    // x[:, from..from + cols] transposed: [cols, c_in].
                    MatRef {
                        data: &xb[from..],
                        rows: hi - lo,
                        cols: d.c_in,
                        row_stride: 1,
                        col_stride: d.len,
                    },
                    true,
                    false,
                );
            }
        }
        taps
    };
    // Partial sums in a fixed order, so the result does not depend on rayon's scheduling.
    let partials: Vec<Vec<f32>> = (0..parts).into_par_iter().map(partial).collect();
    let mut dw = vec![0.0f32; size];
    for taps in &partials {
        for (j, block) in taps.chunks_exact(d.c_out * d.c_in).enumerate() {
            for (oc, v) in block.iter().enumerate() {
                dw[oc * d.kernel + j] += v;
            }
        }
    }
    dw
}

/// Sizes of a group norm over `[batch, channels, len]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NormDims {
    pub batch: usize,
    pub channels: usize,
    pub len: usize,
    pub groups: usize,
    pub epsilon: f64,
}

/// Per `(batch, group)` statistics of `y = z + bias`, and per row the moments of `z`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NormStats {
    /// `[batch * groups]`.
    pub mean: Vec<f64>,
    /// `1 / sqrt(var + eps)`, `[batch * groups]`.
    pub rstd: Vec<f64>,
    /// `sum_t z` per row `[batch * channels]`.
    pub row_sum: Vec<f64>,
}

/// The per-row affine maps of the forward pass: `a = z scale + shift` is the group norm's
/// output, `xhat = z xs + xh` the normalised value.
struct RowMaps {
    scale: Vec<f32>,
    shift: Vec<f32>,
    xs: Vec<f32>,
    xh: Vec<f32>,
}

fn row_maps(bias: &[f32], gamma: &[f32], beta: &[f32], stats: &NormStats, d: NormDims) -> RowMaps {
    let cg = d.channels / d.groups;
    let rows = d.batch * d.channels;
    let mut m = RowMaps {
        scale: Vec::with_capacity(rows),
        shift: Vec::with_capacity(rows),
        xs: Vec::with_capacity(rows),
        xh: Vec::with_capacity(rows),
    };
    for row in 0..rows {
        let (b, c) = (row / d.channels, row % d.channels);
        let g = b * d.groups + c / cg;
        let (mean, rstd) = (stats.mean[g], stats.rstd[g]);
        let xh = (f64::from(bias[c]) - mean) * rstd;
        m.xs.push(rstd as f32);
        m.xh.push(xh as f32);
        m.scale.push((rstd * f64::from(gamma[c])) as f32);
        m.shift
            .push((xh * f64::from(gamma[c]) + f64::from(beta[c])) as f32);
    }
    m
}

/// Elements per block: the per-block sums are `f32` (16 lanes), the totals `f64`.
const BLOCK: usize = 1024;
const LANES: usize = 16;

/// `(sum a, sum a b)` of one block, vectorisable (independent lanes).
#[inline(always)]
fn sums(a: &[f32], b: &[f32]) -> (f32, f32) {
    let (mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (ac, bc) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        for i in 0..LANES {
            s1[i] += x[i];
            s2[i] += x[i] * y[i];
        }
    }
    lane_totals(&s1, &s2, ar, br)
}

/// The end of [`sums`] and [`sums_v`]: each lane array summed in lane order, then the
/// remainder `(a, b)` added one by one.
#[inline(always)]
fn lane_totals(s1: &[f32; LANES], s2: &[f32; LANES], ar: &[f32], br: &[f32]) -> (f32, f32) {
    let mut t1: f32 = s1.iter().sum();
    let mut t2: f32 = s2.iter().sum();
    for (x, y) in ar.iter().zip(br) {
        t1 += x;
        t2 += x * y;
    }
    (t1, t2)
}

/// [`sums`] with pulp's vectors where they hold [`LANES`] floats (AVX-512): the same lanes,
/// additions and order, so the same bits. LLVM compiled the array version into scalar and
/// 4-lane code that shuffled the two sums together: in a profile of the `quick` training
/// step it took about 6 % of the samples. Elsewhere it is [`sums`].
#[inline(always)]
fn sums_v<S: Simd>(simd: S, a: &[f32], b: &[f32]) -> (f32, f32) {
    if S::F32_LANES != LANES || a.len() != b.len() {
        return sums(a, b);
    }
    let (av, ar) = S::as_simd_f32s(a);
    let (bv, br) = S::as_simd_f32s(b);
    let (mut s1, mut s2) = (simd.splat_f32s(0.0), simd.splat_f32s(0.0));
    for (&x, &y) in av.iter().zip(bv) {
        s1 = simd.add_f32s(s1, x);
        s2 = simd.add_f32s(s2, simd.mul_f32s(x, y));
    }
    let (mut l1, mut l2) = ([0.0f32; LANES], [0.0f32; LANES]);
    S::as_mut_simd_f32s(&mut l1).0[0] = s1;
    S::as_mut_simd_f32s(&mut l2).0[0] = s2;
    lane_totals(&l1, &l2, ar, br)
}

/// `exp(x)` for `x` in `[-87, 88]` (clamped outside), relative error below 3e-7: `2^n p(r)`
/// with Cephes' polynomial; branch-free so that it vectorises.
#[inline(always)]
fn exp(x: f32) -> f32 {
    const ROUND: f32 = 12_582_912.0; // 1.5 * 2^23: adding it rounds to an integer
    let x = x.clamp(-87.0, 88.0);
    let t = x * std::f32::consts::LOG2_E + ROUND;
    let n = t - ROUND;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
    let mut p = 1.987_569_1e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let p = p * r * r + r + 1.0;
    let n = (t.to_bits() as i32).wrapping_sub(0x4B40_0000);
    p * f32::from_bits(((n + 127) << 23) as u32)
}

#[inline(always)]
pub(crate) fn sigmoid(a: f32) -> f32 {
    1.0 / (1.0 + exp(-a))
}

/// A residual that [`norm_silu_forward`] adds to its output: `values + bias` (per channel),
/// or `values` alone.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Residual<'a> {
    /// `[batch, channels, len]`.
    pub values: &'a [f32],
    /// `[channels]`, added to `values` before they are added to the output.
    pub bias: Option<&'a [f32]>,
}

/// `SiLU(GroupNorm(z + bias))` with the norm's `gamma`, `beta`, plus `residual` when given
/// (a ResNet block's sum, in the same pass): the output and the statistics the backward pass
/// needs.
///
/// # Shapes
/// - `z`: `[batch, channels, len]`; `bias`, `gamma`, `beta`: `[channels]`
/// - output: `[batch, channels, len]`
pub(crate) fn norm_silu_forward(
    z: &[f32],
    bias: &[f32],
    gamma: &[f32],
    beta: &[f32],
    d: NormDims,
    residual: Option<Residual<'_>>,
) -> (Vec<f32>, NormStats) {
    let (y, stats, _) = norm_silu_forward_with(z, bias, gamma, beta, d, residual, false);
    (y, stats)
}

/// [`norm_silu_forward`] that also returns the SiLU's sigmoid `sigmoid(z scale + shift)`
/// of every element, written in the same pass, for [`norm_silu_backward_in_place`] to read
/// instead of computing it again (its exponential and division were most of that pass).
pub(crate) fn norm_silu_forward_keeping_sigmoid(
    z: &[f32],
    bias: &[f32],
    gamma: &[f32],
    beta: &[f32],
    d: NormDims,
    residual: Option<Residual<'_>>,
) -> (Vec<f32>, NormStats, Vec<f32>) {
    let (y, stats, sigmoid) = norm_silu_forward_with(z, bias, gamma, beta, d, residual, true);
    (y, stats, sigmoid.expect("kept"))
}

/// [`norm_silu_forward`], with the sigmoids when `keep_sigmoid`.
#[allow(clippy::too_many_arguments)]
fn norm_silu_forward_with(
    z: &[f32],
    bias: &[f32],
    gamma: &[f32],
    beta: &[f32],
    d: NormDims,
    residual: Option<Residual<'_>>,
    keep_sigmoid: bool,
) -> (Vec<f32>, NormStats, Option<Vec<f32>>) {
    let rows = d.batch * d.channels;
    assert_eq!(z.len(), rows * d.len, "norm_silu_forward: z");
    if let Some(r) = residual {
        assert_eq!(r.values.len(), z.len(), "norm_silu_forward: residual");
        assert!(r.bias.is_none_or(|b| b.len() == d.channels));
    }
    assert!(d.groups > 0 && d.channels.is_multiple_of(d.groups) && d.len > 0);
    let arch = Arch::new();
    // Pass 1: moments of z per row.
    let moments: Vec<(f64, f64)> = z
        .par_chunks_exact(d.len)
        .map(|row| {
            vectorized!(arch, <'a> |simd| (row: &'a [f32] = row) -> (f64, f64) {
                row.chunks(BLOCK).fold((0.0, 0.0), |(a, b), block| {
                    let (s1, s2) = sums_v(simd, block, block);
                    (a + f64::from(s1), b + f64::from(s2))
                })
            })
        })
        .collect();
    // Group statistics of y = z + bias.
    let cg = d.channels / d.groups;
    let count = (cg * d.len) as f64;
    let (mut mean, mut rstd) = (Vec::new(), Vec::new());
    for b in 0..d.batch {
        for g in 0..d.groups {
            let (mut sy, mut syy) = (0.0f64, 0.0f64);
            for c in g * cg..(g + 1) * cg {
                let (s1, s2) = moments[b * d.channels + c];
                let bc = f64::from(bias[c]);
                sy += s1 + d.len as f64 * bc;
                syy += s2 + 2.0 * bc * s1 + d.len as f64 * bc * bc;
            }
            let m = sy / count;
            let var = (syy / count - m * m).max(0.0);
            mean.push(m);
            rstd.push(1.0 / (var + d.epsilon).sqrt());
        }
    }
    let stats = NormStats {
        mean,
        rstd,
        row_sum: moments.iter().map(|m| m.0).collect(),
    };
    let maps = row_maps(bias, gamma, beta, &stats, d);
    if keep_sigmoid {
        // Pass 2 with the sigmoids: the same operations, both values written.
        let (y, sigmoid) = super::gemm::pair_by_blocks(rows, d.len, |row, from, yr, gr| {
            let (s, h) = (maps.scale[row], maps.shift[row]);
            let at = row * d.len + from;
            let zr = &z[at..][..yr.len()];
            let residual = residual.map(|r| (&r.values[at..], r.bias.map(|b| b[row % d.channels])));
            vectorized!(arch, <'a> (
                yr: &'a mut [f32] = yr, gr: &'a mut [f32] = gr, zr: &'a [f32] = zr,
                s: f32 = s, h: f32 = h, residual: Option<(&'a [f32], Option<f32>)> = residual,
            ) -> () {
                silu_and_sigmoid(yr, gr, zr, residual, s, h)
            });
        });
        return (y, stats, Some(sigmoid));
    }
    // Pass 2: y = silu(z scale + shift) (+ residual).
    let y = super::rows_by_blocks(rows, d.len, |row, from, yr| {
        let (s, h) = (maps.scale[row], maps.shift[row]);
        let at = row * d.len + from;
        let zr = &z[at..][..yr.len()];
        match residual {
            None => vectorized!(arch, <'a> (
                yr: &'a mut [f32] = yr, zr: &'a [f32] = zr, s: f32 = s, h: f32 = h,
            ) -> () {
                for (y, &z) in yr.iter_mut().zip(zr) {
                    let a = z * s + h;
                    *y = a * sigmoid(a);
                }
            }),
            Some(Residual { values, bias: None }) => vectorized!(arch, <'a> (
                yr: &'a mut [f32] = yr, zr: &'a [f32] = zr, rr: &'a [f32] = &values[at..],
                s: f32 = s, h: f32 = h,
            ) -> () {
                for ((y, &z), &r) in yr.iter_mut().zip(zr).zip(rr) {
                    let a = z * s + h;
                    *y = a * sigmoid(a) + r;
                }
            }),
            Some(Residual {
                values,
                bias: Some(bias),
            }) => vectorized!(arch, <'a> (
                yr: &'a mut [f32] = yr, zr: &'a [f32] = zr, rr: &'a [f32] = &values[at..],
                s: f32 = s, h: f32 = h, rb: f32 = bias[row % d.channels],
            ) -> () {
                for ((y, &z), &r) in yr.iter_mut().zip(zr).zip(rr) {
                    let a = z * s + h;
                    *y = a * sigmoid(a) + (r + rb);
                }
            }),
        }
    });
    (y, stats, None)
}

/// `y = a sigmoid(a) + extra` and `g = sigmoid(a)` for `a = z s + h`, where `extra` is
/// nothing, `r` or `r + rb` ([`norm_silu_forward`]'s three forms, in the same operations).
#[inline(always)]
fn silu_and_sigmoid(
    yr: &mut [f32],
    gr: &mut [f32],
    zr: &[f32],
    residual: Option<(&[f32], Option<f32>)>,
    s: f32,
    h: f32,
) {
    let out = yr.iter_mut().zip(gr.iter_mut()).zip(zr);
    match residual {
        None => {
            for ((y, g), &z) in out {
                let a = z * s + h;
                let sg = sigmoid(a);
                *g = sg;
                *y = a * sg;
            }
        }
        Some((rr, None)) => {
            for (((y, g), &z), &r) in out.zip(rr) {
                let a = z * s + h;
                let sg = sigmoid(a);
                *g = sg;
                *y = a * sg + r;
            }
        }
        Some((rr, Some(rb))) => {
            for (((y, g), &z), &r) in out.zip(rr) {
                let a = z * s + h;
                let sg = sigmoid(a);
                *g = sg;
                *y = a * sg + (r + rb);
            }
        }
    }
}

/// Gradients of [`norm_silu_forward`] (the tests' allocating form).
#[cfg(test)]
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NormSiluGrads {
    /// With respect to `z` (and so to the convolution's output), `[batch, channels, len]`.
    pub dz: Vec<f32>,
    pub dbias: Vec<f32>,
    pub dgamma: Vec<f32>,
    pub dbeta: Vec<f32>,
}

/// [`norm_silu_backward_in_place`] into a new buffer (tests).
#[cfg(test)]
pub(crate) fn norm_silu_backward(
    gy: &[f32],
    z: &[f32],
    bias: &[f32],
    gamma: &[f32],
    beta: &[f32],
    stats: &NormStats,
    d: NormDims,
) -> NormSiluGrads {
    let mut dz = gy.to_vec();
    let [dbias, dgamma, dbeta] =
        norm_silu_backward_in_place(&mut dz, z, bias, gamma, beta, stats, d, None);
    NormSiluGrads {
        dz,
        dbias,
        dgamma,
        dbeta,
    }
}

/// The backward pass of [`norm_silu_forward`], in place: `grad` holds the output gradient
/// `gy` on entry and `dz` on return (no new `[batch, channels, len]` buffer); returns
/// `[dbias, dgamma, dbeta]`.
///
/// With `a = xhat gamma + beta`, `ga = gy silu'(a)`, per group `m1 = mean(gamma ga)`,
/// `m2 = mean(gamma ga xhat)`: `dz = rstd (gamma ga - m1 - xhat m2)`, `dgamma = sum ga xhat`,
/// `dbeta = sum ga`, `dbias = sum dz`. Per row this is two passes: `ga` with the sums
/// `sum ga`, `sum ga z`, then `dz` as an affine map of `(ga, z)`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn norm_silu_backward_in_place(
    grad: &mut [f32],
    z: &[f32],
    bias: &[f32],
    gamma: &[f32],
    beta: &[f32],
    stats: &NormStats,
    d: NormDims,
    sigmoid_kept: Option<&[f32]>,
) -> [Vec<f32>; 3] {
    let rows = d.batch * d.channels;
    assert_eq!(grad.len(), rows * d.len, "norm_silu_backward: gy");
    assert_eq!(z.len(), rows * d.len, "norm_silu_backward: z");
    let arch = Arch::new();
    let maps = row_maps(bias, gamma, beta, stats, d);
    let dz = grad;
    // Pass 1: ga over gy; per row (sum ga, sum ga z).
    if let Some(kept) = sigmoid_kept {
        assert_eq!(kept.len(), z.len(), "norm_silu_backward: kept sigmoids");
    }
    let sums_ga: Vec<(f64, f64)> = dz
        .par_chunks_exact_mut(d.len)
        .zip(z.par_chunks_exact(d.len))
        .enumerate()
        .map(|(row, (out, zr))| {
            let (s, h) = (maps.scale[row], maps.shift[row]);
            if let Some(kept) = sigmoid_kept {
                // The forward pass's sigmoids: the same values, read instead of computed.
                let gr = &kept[row * d.len..(row + 1) * d.len];
                return vectorized!(arch, <'a> |simd| (
                    out: &'a mut [f32] = out, zr: &'a [f32] = zr, gr: &'a [f32] = gr,
                    s: f32 = s, h: f32 = h,
                ) -> (f64, f64) {
                    let mut total = (0.0f64, 0.0f64);
                    for ((o, zb), gb) in out.chunks_mut(BLOCK).zip(zr.chunks(BLOCK)).zip(gr.chunks(BLOCK)) {
                        for ((o, &z), &sg) in o.iter_mut().zip(zb).zip(gb) {
                            let a = z * s + h;
                            *o *= sg * (1.0 + a * (1.0 - sg));
                        }
                        let (s1, s2) = sums_v(simd, o, zb);
                        total.0 += f64::from(s1);
                        total.1 += f64::from(s2);
                    }
                    total
                });
            }
            vectorized!(arch, <'a> |simd| (
                out: &'a mut [f32] = out, zr: &'a [f32] = zr, s: f32 = s, h: f32 = h,
            ) -> (f64, f64) {
                let mut total = (0.0f64, 0.0f64);
                for (o, zb) in out.chunks_mut(BLOCK).zip(zr.chunks(BLOCK)) {
                    for (o, &z) in o.iter_mut().zip(zb) {
                        let a = z * s + h;
                        let sg = sigmoid(a);
                        *o *= sg * (1.0 + a * (1.0 - sg));
                    }
                    let (s1, s2) = sums_v(simd, o, zb);
                    total.0 += f64::from(s1);
                    total.1 += f64::from(s2);
                }
                total
            })
        })
        .collect();
    // Per row: A = sum ga, B = sum ga xhat = xs sum(ga z) + xh sum(ga).
    let a_sum: Vec<f64> = sums_ga.iter().map(|s| s.0).collect();
    let b_sum: Vec<f64> = sums_ga
        .iter()
        .enumerate()
        .map(|(row, s)| f64::from(maps.xs[row]) * s.1 + f64::from(maps.xh[row]) * s.0)
        .collect();
    let cg = d.channels / d.groups;
    let count = (cg * d.len) as f64;
    // Per row the map dz = p ga + q z + r.
    let mut coef = Vec::with_capacity(rows);
    for row in 0..rows {
        let (b, c) = (row / d.channels, row % d.channels);
        let group = c / cg;
        let g = b * d.groups + group;
        let (m1, m2) = (group * cg..(group + 1) * cg).fold((0.0f64, 0.0f64), |(m1, m2), k| {
            let r = b * d.channels + k;
            let gk = f64::from(gamma[k]);
            (m1 + gk * a_sum[r], m2 + gk * b_sum[r])
        });
        let (m1, m2) = (m1 / count, m2 / count);
        let rstd = stats.rstd[g];
        let (xs, xh) = (f64::from(maps.xs[row]), f64::from(maps.xh[row]));
        let p = rstd * f64::from(gamma[c]);
        let q = -rstd * xs * m2;
        let r = -rstd * (m1 + xh * m2);
        coef.push((p, q, r));
    }
    // Pass 2: dz in place.
    dz.par_chunks_exact_mut(d.len)
        .zip(z.par_chunks_exact(d.len))
        .enumerate()
        .for_each(|(row, (o, zr))| {
            let (p, q, r) = coef[row];
            let (p, q, r) = (p as f32, q as f32, r as f32);
            vectorized!(arch, <'a> (
                o: &'a mut [f32] = o, zr: &'a [f32] = zr, p: f32 = p, q: f32 = q, r: f32 = r,
            ) -> () {
                for (o, &z) in o.iter_mut().zip(zr) {
                    *o = p * *o + q * z + r;
                }
            });
        });
    let (mut dbias, mut dgamma, mut dbeta) = (
        vec![0.0f32; d.channels],
        vec![0.0f32; d.channels],
        vec![0.0f32; d.channels],
    );
    for row in 0..rows {
        let c = row % d.channels;
        let (p, q, r) = coef[row];
        dbias[c] += (p * a_sum[row] + q * stats.row_sum[row] + r * d.len as f64) as f32;
        dgamma[c] += b_sum[row] as f32;
        dbeta[c] += a_sum[row] as f32;
    }
    [dbias, dgamma, dbeta]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::assert_conv_adjoints;
    use bitt_testkit::{assert_close, values};

    /// The convolution as the textbook triple loop.
    fn conv_naive(x: &[f32], w: &[f32], d: ConvDims) -> Vec<f32> {
        let pad = (d.kernel / 2) as isize;
        let mut z = vec![0.0; d.batch * d.c_out * d.len];
        for b in 0..d.batch {
            for o in 0..d.c_out {
                for t in 0..d.len {
                    let mut s = 0.0f64;
                    for c in 0..d.c_in {
                        for j in 0..d.kernel {
                            let u = t as isize + j as isize - pad;
                            if (0..d.len as isize).contains(&u) {
                                s += f64::from(w[(o * d.c_in + c) * d.kernel + j])
                                    * f64::from(x[(b * d.c_in + c) * d.len + u as usize]);
                            }
                        }
                    }
                    z[(b * d.c_out + o) * d.len + t] = s as f32;
                }
            }
        }
        z
    }

    /// Forward against the naive loop; both backward products against the adjoint identity
    /// `<conv(x), g> = <x, dx(g)> = <w, dw(g, x)>` (the convolution is bilinear).
    #[test]
    fn convolution_and_its_adjoints() {
        for &(batch, c_in, c_out, len, kernel) in &[
            (2, 3, 5, 11, 3),
            (1, 4, 2, 1, 3),
            (2, 2, 3, 7, 1),
            (1, 3, 4, 9, 5),
            (3, 1, 1, 2, 3),
        ] {
            let d = ConvDims {
                batch,
                c_in,
                c_out,
                len,
                kernel,
            };
            let x = values(batch * c_in * len, 1);
            let w = values(c_out * c_in * kernel, 2);
            let g = values(batch * c_out * len, 3);
            let z = conv_forward(&x, &w, d);
            assert_close(&z, &conv_naive(&x, &w, d), 1e-5, "forward");
            let dx = conv_backward_input(&g, &w, d);
            let dw = conv_backward_weight(&g, &x, d);
            assert_conv_adjoints(
                [&x, &w, &g],
                [&dx, &dw],
                |x, w| conv_naive(x, w, d),
                [1e-4, 1e-5, 1e-4],
                &format!("{d:?}"),
            );
        }
    }

    /// Both ways of evaluating the shifted products agree, including blocks that end inside
    /// the padding and offsets longer than the signal.
    #[test]
    fn stacked_and_per_tap_products_agree() {
        for &(rows_out, rows_in, len) in &[(5, 3, 11), (4, 2, 2 * IM2COL_BLOCK + 3), (2, 3, 1)] {
            let mats: Vec<Vec<f32>> = (0..3).map(|i| values(rows_out * rows_in, 10 + i)).collect();
            let src = values(rows_in * len, 20);
            for offsets in [[0isize, -1, 1], [0, 2, -3]] {
                let taps: Vec<(MatRef<'_>, isize)> = mats
                    .iter()
                    .zip(offsets)
                    .map(|(m, o)| {
                        let a = MatRef {
                            data: m,
                            rows: rows_out,
                            cols: rows_in,
                            row_stride: rows_in,
                            col_stride: 1,
                        };
                        (a, o)
                    })
                    .collect();
                let a = products_into_new(
                    1,
                    rows_out,
                    len,
                    false,
                    || (),
                    |(), _, dst| {
                        per_tap_products(dst, &src, len, &taps, false);
                    },
                );
                let b = products_into_new(
                    1,
                    rows_out,
                    len,
                    false,
                    || (),
                    |(), _, dst| {
                        stacked_products(dst, &src, len, &taps, [rows_out, rows_in], true);
                    },
                );
                assert_close(&b, &a, 1e-5, "stacked vs per tap");
            }
        }
    }

    #[test]
    fn fast_exp_is_accurate() {
        let mut worst = 0.0f64;
        for i in -8700..=8800 {
            let x = i as f32 * 0.01;
            let e = f64::from(x).exp();
            worst = worst.max((f64::from(exp(x)) - e).abs() / e);
        }
        assert!(worst < 3e-7, "worst relative error {worst}");
        assert_eq!(exp(-1000.0), exp(-87.0));
        assert!(exp(1000.0).is_finite());
    }

    /// Group norm + SiLU against a direct f64 evaluation, and the backward pass against
    /// central finite differences of `sum(y * gy)` in f64.
    /// The forward pass that keeps its sigmoids gives the same outputs, and the backward pass
    /// that reads them the same gradients, bit for bit, with each form of residual.
    #[test]
    fn kept_sigmoids_give_the_same_bits() {
        let d = NormDims {
            batch: 2,
            channels: 4,
            len: 300,
            groups: 2,
            epsilon: 1e-5,
        };
        let n = d.batch * d.channels * d.len;
        let z: Vec<f32> = values(n, 14).iter().map(|v| v * 3.0 - 0.2).collect();
        let (bias, gamma, beta) = (values(4, 15), values(4, 16), values(4, 17));
        let (r, rb, gy) = (values(n, 18), values(4, 19), values(n, 20));
        for residual in [
            None,
            Some(Residual {
                values: &r,
                bias: None,
            }),
            Some(Residual {
                values: &r,
                bias: Some(&rb),
            }),
        ] {
            let (y, stats) = norm_silu_forward(&z, &bias, &gamma, &beta, d, residual);
            let (y_kept, stats_kept, sigmoid) =
                norm_silu_forward_keeping_sigmoid(&z, &bias, &gamma, &beta, d, residual);
            assert_eq!(y, y_kept);
            assert_eq!(stats.rstd, stats_kept.rstd);
            let (mut g, mut g_kept) = (gy.clone(), gy.clone());
            let grads =
                norm_silu_backward_in_place(&mut g, &z, &bias, &gamma, &beta, &stats, d, None);
            let grads_kept = norm_silu_backward_in_place(
                &mut g_kept,
                &z,
                &bias,
                &gamma,
                &beta,
                &stats,
                d,
                Some(&sigmoid),
            );
            assert_eq!(g, g_kept);
            assert_eq!(grads, grads_kept);
        }
    }

    #[test]
    fn norm_silu_matches_definition_and_finite_differences() {
        let d = NormDims {
            batch: 2,
            channels: 4,
            len: 13,
            groups: 2,
            epsilon: 1e-5,
        };
        let n = d.batch * d.channels * d.len;
        let z: Vec<f32> = values(n, 4).iter().map(|v| v * 2.0 + 0.3).collect();
        let bias = values(4, 5);
        let gamma: Vec<f32> = values(4, 6).iter().map(|v| v + 1.2).collect();
        let beta = values(4, 7);
        let gy = values(n, 8);
        // Reference in f64.
        let reference = |z: &[f64], bias: &[f64], gamma: &[f64], beta: &[f64]| -> Vec<f64> {
            let cg = d.channels / d.groups;
            let mut y = vec![0.0; n];
            for b in 0..d.batch {
                for g in 0..d.groups {
                    let idx = |c: usize, t: usize| (b * d.channels + c) * d.len + t;
                    let vals: Vec<f64> = (g * cg..(g + 1) * cg)
                        .flat_map(|c| (0..d.len).map(move |t| (c, t)))
                        .map(|(c, t)| z[idx(c, t)] + bias[c])
                        .collect();
                    let m = vals.iter().sum::<f64>() / vals.len() as f64;
                    let v = vals.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / vals.len() as f64;
                    for c in g * cg..(g + 1) * cg {
                        for t in 0..d.len {
                            let a = (z[idx(c, t)] + bias[c] - m) / (v + d.epsilon).sqrt()
                                * gamma[c]
                                + beta[c];
                            y[idx(c, t)] = a / (1.0 + (-a).exp());
                        }
                    }
                }
            }
            y
        };
        let f64s = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
        let (zd, bd, gd, betad) = (f64s(&z), f64s(&bias), f64s(&gamma), f64s(&beta));
        let (y, stats) = norm_silu_forward(&z, &bias, &gamma, &beta, d, None);
        let yr = reference(&zd, &bd, &gd, &betad);
        // A residual is added in the same pass, exactly as a separate sum would add it.
        let r = values(n, 9);
        let rb = values(4, 10);
        for rbias in [None, Some(rb.as_slice())] {
            let residual = Residual {
                values: &r,
                bias: rbias,
            };
            let (with, with_stats) = norm_silu_forward(&z, &bias, &gamma, &beta, d, Some(residual));
            assert_eq!(with_stats, stats);
            let want: Vec<f32> = (0..n)
                .map(|i| y[i] + (r[i] + rbias.map_or(0.0, |b| b[(i / d.len) % d.channels])))
                .collect();
            assert_eq!(with, want, "residual bias {}", rbias.is_some());
        }
        assert_close(
            &y,
            &yr.iter().map(|&v| v as f32).collect::<Vec<_>>(),
            2e-6,
            "y",
        );
        let grads = norm_silu_backward(&gy, &z, &bias, &gamma, &beta, &stats, d);
        let loss = |y: Vec<f64>| -> f64 { y.iter().zip(&gy).map(|(y, g)| y * f64::from(*g)).sum() };
        let h = 1e-6;
        let fd = |which: usize, i: usize| -> f64 {
            let mut args = [zd.clone(), bd.clone(), gd.clone(), betad.clone()];
            args[which][i] += h;
            let up = loss(reference(&args[0], &args[1], &args[2], &args[3]));
            args[which][i] -= 2.0 * h;
            let down = loss(reference(&args[0], &args[1], &args[2], &args[3]));
            (up - down) / (2.0 * h)
        };
        for i in [0, 5, 27, n - 1] {
            let e = fd(0, i);
            assert!(
                (f64::from(grads.dz[i]) - e).abs() < 2e-4,
                "dz[{i}] {} vs {e}",
                grads.dz[i]
            );
        }
        for c in 0..4 {
            for (which, got) in [(1, &grads.dbias), (2, &grads.dgamma), (3, &grads.dbeta)] {
                let e = fd(which, c);
                assert!(
                    (f64::from(got[c]) - e).abs() < 2e-4,
                    "arg {which} [{c}]: {} vs {e}",
                    got[c]
                );
            }
        }
    }
}
