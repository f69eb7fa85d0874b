//! CPU kernels of a 2-D convolution (+ bias) followed by an optional instance norm and an
//! activation, on plain `f32` slices (`[batch, channels, height, width]`, row-major).
//!
//! The convolution is im2col + GEMM in tiles of output pixels: a tile's patch matrix
//! `[C_in kh kw, tile]` stays in cache (one buffer per call, reused for every tile) and one
//! GEMM writes the tile's columns of the output; a 1x1 stride-1 convolution is one GEMM over
//! the input itself. The backward pass walks the same tiles: `dW += dz_tile col^T` and
//! `dcol = W^T dz_tile`, scattered back (col2im) channel by channel in parallel. A batch with
//! at least as many samples as threads runs one sample per thread with single-threaded
//! GEMMs, a smaller one sample after sample with multi-threaded GEMMs; `dW`'s long pixel
//! reduction is split into one run of tiles per thread. The patch gathers and scatters run
//! parallel over rows.
//! Instance norm + activation is one pass per `(sample, channel)` row forward (after the
//! moments) and two backward, rows in parallel.

use pulp::Arch;
use rayon::prelude::*;

use super::gemm::{MatMut, MatRef, matmul, products_into_new};
use super::scratch::Scratch;
use super::vectorized::vectorized;

/// Sizes of a 2-D convolution with symmetric zero padding and no dilation or groups.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Conv2dDims {
    pub batch: usize,
    pub c_in: usize,
    pub c_out: usize,
    /// Input height and width.
    pub size: [usize; 2],
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    /// Zero padding on both sides of each axis.
    pub padding: [usize; 2],
}

/// Patch-matrix elements per tile (1 MiB of `f32`: the tile stays in the L2 cache).
const COL_BUDGET: usize = 1 << 18;
/// Fewest output pixels per tile (narrower GEMMs waste the packed weight).
const MIN_TILE: usize = 128;

impl Conv2dDims {
    /// The output height and width, `None` when the kernel does not fit the padded input or
    /// a size or stride is zero.
    pub(crate) fn out_size(&self) -> Option<[usize; 2]> {
        let mut out = [0; 2];
        for (a, o) in out.iter_mut().enumerate() {
            let padded = self.size[a] + 2 * self.padding[a];
            if self.stride[a] == 0 || self.kernel[a] == 0 || self.kernel[a] > padded {
                return None;
            }
            *o = (padded - self.kernel[a]) / self.stride[a] + 1;
        }
        Some(out)
    }

    fn out(&self) -> [usize; 2] {
        self.out_size().expect("valid convolution sizes")
    }

    /// Output pixels per sample.
    pub fn pixels(&self) -> usize {
        let [h, w] = self.out();
        h * w
    }

    /// Rows of the patch matrix, `C_in kh kw`.
    pub fn patch(&self) -> usize {
        self.c_in * self.kernel[0] * self.kernel[1]
    }

    fn plane(&self) -> usize {
        self.size[0] * self.size[1]
    }

    /// A 1x1, stride-1, unpadded convolution: a matrix product over the input itself.
    fn pointwise(&self) -> bool {
        self.kernel == [1, 1] && self.stride == [1, 1] && self.padding == [0, 0]
    }

    /// Output pixels per tile (all of them for a 1x1 convolution, which needs no patch
    /// matrix).
    fn tile(&self) -> usize {
        if self.pointwise() {
            return self.pixels().max(1);
        }
        (COL_BUDGET / self.patch().max(1))
            .max(MIN_TILE)
            .min(self.pixels())
            .max(1)
    }

    /// A patch-matrix buffer for one tile (empty for a 1x1 convolution, which needs none);
    /// its values are left from earlier use, and every user writes the part it reads.
    fn col_buffer(&self) -> Scratch {
        Scratch::new(if self.pointwise() {
            0
        } else {
            self.patch() * self.tile()
        })
    }

    /// The weight `[C_out, C_in kh kw]`.
    fn weight<'a>(&self, weight: &'a [f32]) -> MatRef<'a> {
        let k = self.patch();
        MatRef {
            data: weight,
            rows: self.c_out,
            cols: k,
            row_stride: k,
            col_stride: 1,
        }
    }

    /// The weight transposed, `[C_in kh kw, C_out]`.
    fn weight_t<'a>(&self, weight: &'a [f32]) -> MatRef<'a> {
        let k = self.patch();
        MatRef {
            data: weight,
            rows: k,
            cols: self.c_out,
            row_stride: 1,
            col_stride: k,
        }
    }
}

/// Indices `u` in `[0, count)` with `0 <= (start + u) stride + offset < size`.
fn valid(start: usize, count: usize, stride: usize, offset: isize, size: usize) -> (usize, usize) {
    let s = stride as isize;
    // First output index whose input index is >= 0, and the end of those below `size`.
    let first = if offset >= 0 {
        0
    } else {
        (-offset + s - 1) / s
    };
    let end = if size as isize > offset {
        (size as isize - offset + s - 1) / s
    } else {
        0
    };
    let lo = (first - start as isize).clamp(0, count as isize) as usize;
    let hi = (end - start as isize).clamp(0, count as isize) as usize;
    (lo, hi.max(lo))
}

/// Walks patch row `k` (channel `c`, tap `(i, j)`) over the tile's pixels `[p0, p0 + n)`:
/// calls `f(t, Some(input index in the plane))` for each tile column `t` that reads the
/// input and `f(t, None)` for those in the padding. Runs are handed over as ranges:
/// `f(t0..t1, Some(first), step)` or `f(t0..t1, None, 0)`.
fn walk_row(
    d: &Conv2dDims,
    tap: (usize, usize),
    p0: usize,
    n: usize,
    mut f: impl FnMut(std::ops::Range<usize>, Option<usize>, usize),
) {
    let [_, ow] = d.out();
    let [h, w] = d.size;
    let (i, j) = tap;
    let mut t = 0;
    // The output pixel `p0 + t` as (row, column), advanced by segments (no division each).
    let (mut oy, mut ox0) = (p0 / ow, p0 % ow);
    while t < n {
        let seg = (ow - ox0).min(n - t);
        let iy = (oy * d.stride[0] + i) as isize - d.padding[0] as isize;
        if iy < 0 || iy >= h as isize {
            f(t..t + seg, None, 0);
        } else {
            let off = j as isize - d.padding[1] as isize;
            let (lo, hi) = valid(ox0, seg, d.stride[1], off, w);
            if lo > 0 {
                f(t..t + lo, None, 0);
            }
            if hi > lo {
                let ix = ((ox0 + lo) * d.stride[1]) as isize + off;
                f(
                    t + lo..t + hi,
                    Some(iy as usize * w + ix as usize),
                    d.stride[1],
                );
            }
            if hi < seg {
                f(t + hi..t + seg, None, 0);
            }
        }
        t += seg;
        ox0 += seg;
        if ox0 == ow {
            (oy, ox0) = (oy + 1, 0);
        }
    }
}

/// `row[u] = src[2 u]`: a stride-2 convolution's taps. In blocks of 16 that LLVM turns into
/// wide loads and shuffles (an element at a time, these gathers were 3 % of the `quick`
/// training step).
#[inline(always)]
fn every_second(row: &mut [f32], src: &[f32]) {
    let full = (src.len() / 32).min(row.len() / 16);
    for (o, s) in row[..16 * full]
        .chunks_exact_mut(16)
        .zip(src.chunks_exact(32))
    {
        for i in 0..16 {
            o[i] = s[2 * i];
        }
    }
    for (v, &s) in row[16 * full..]
        .iter_mut()
        .zip(src[32 * full..].iter().step_by(2))
    {
        *v = s;
    }
}

/// `dst[2 u] += row[u]`, the adjoint of [`every_second`], in the same blocks.
#[inline(always)]
fn add_every_second(dst: &mut [f32], row: &[f32]) {
    let full = (dst.len() / 32).min(row.len() / 16);
    for (o, s) in dst[..32 * full]
        .chunks_exact_mut(32)
        .zip(row.chunks_exact(16))
    {
        for i in 0..16 {
            o[2 * i] += s[i];
        }
    }
    for (x, &v) in dst[32 * full..]
        .iter_mut()
        .step_by(2)
        .zip(&row[16 * full..])
    {
        *x += v;
    }
}

/// The patch matrix of one sample's tile: `col[k, t]` is input channel `c`, tap `(i, j)`
/// (`k = (c kh + i) kw + j`) of output pixel `p0 + t`, zero in the padding.
///
/// # Shapes
/// - `x`: `[C_in, H, W]`; `col`: at least `[C_in kh kw, n]`
fn im2col(x: &[f32], d: &Conv2dDims, p0: usize, n: usize, col: &mut [f32]) {
    let arch = Arch::new();
    let [kh, kw] = d.kernel;
    let plane = d.plane();
    col[..d.patch() * n]
        .par_chunks_mut(n)
        .with_min_len(4)
        .enumerate()
        .for_each(|(k, row)| {
            let (c, r) = (k / (kh * kw), k % (kh * kw));
            let src = &x[c * plane..(c + 1) * plane];
            walk_row(d, (r / kw, r % kw), p0, n, |ts, from, step| match from {
                None => row[ts].fill(0.0),
                Some(s0) if step == 1 => {
                    let len = ts.len();
                    row[ts].copy_from_slice(&src[s0..s0 + len]);
                }
                Some(s0) => {
                    // One bounds check for the segment, then a plain strided walk.
                    let row = &mut row[ts];
                    let src = &src[s0..=s0 + (row.len() - 1) * step];
                    if step == 2 {
                        vectorized!(arch, <'a> (row: &'a mut [f32] = row, src: &'a [f32] = src) -> () {
                            every_second(row, src)
                        });
                    } else {
                        for (v, &s) in row.iter_mut().zip(src.iter().step_by(step)) {
                            *v = s;
                        }
                    }
                }
            });
        });
}

/// The adjoint of [`im2col`]: adds `dcol` back into one sample's input gradient, channels
/// in parallel (each channel owns its patch rows, so no two threads write one element).
///
/// # Shapes
/// - `dx`: `[C_in, H, W]`; `dcol`: at least `[C_in kh kw, n]`
fn col2im_add(dcol: &[f32], d: &Conv2dDims, p0: usize, n: usize, dx: &mut [f32]) {
    let arch = Arch::new();
    let [kh, kw] = d.kernel;
    let taps = kh * kw;
    dx.par_chunks_mut(d.plane())
        .enumerate()
        .for_each(|(c, plane)| {
            for r in 0..taps {
                let row = &dcol[(c * taps + r) * n..(c * taps + r + 1) * n];
                walk_row(d, (r / kw, r % kw), p0, n, |ts, from, step| {
                    if let Some(s0) = from {
                        let row = &row[ts];
                        let dst = &mut plane[s0..=s0 + (row.len() - 1) * step];
                        if step == 2 {
                            vectorized!(arch, <'a> (dst: &'a mut [f32] = dst, row: &'a [f32] = row) -> () {
                                add_every_second(dst, row)
                            });
                        } else {
                            for (x, &v) in dst.iter_mut().step_by(step).zip(row) {
                                *x += v;
                            }
                        }
                    }
                });
            }
        });
}

/// `z[b, o] = sum_k W[o, k] col_b[k] + bias[o]`: the convolution with its bias (`bias`
/// empty for none).
///
/// # Shapes
/// - `x`: `[B, C_in, H, W]`; `weight`: `[C_out, C_in, kh, kw]`; `bias`: `[C_out]` or `[]`
/// - output: `[B, C_out, OH, OW]`
pub(crate) fn conv2d_forward(x: &[f32], weight: &[f32], bias: &[f32], d: Conv2dDims) -> Vec<f32> {
    assert_eq!(x.len(), d.batch * d.c_in * d.plane(), "conv2d_forward: x");
    assert_eq!(weight.len(), d.c_out * d.patch(), "conv2d_forward: w");
    assert!(
        bias.is_empty() || bias.len() == d.c_out,
        "conv2d_forward: bias"
    );
    let (pixels, k) = (d.pixels(), d.patch());
    if d.batch * d.c_out * pixels == 0 {
        return Vec::new();
    }
    let w = d.weight(weight);
    let in_parallel = samples_in_parallel(d.batch);
    let sample_len = d.c_in * d.plane();
    // One sample: `z_b = W col_b`, tile by tile (multi-threaded GEMMs when the samples run
    // in order). The products overwrite a new buffer, never cleared.
    let mut z = products_into_new(
        d.batch,
        d.c_out,
        pixels,
        in_parallel,
        || d.col_buffer(),
        |col, b, zb| {
            let xb = &x[b * sample_len..(b + 1) * sample_len];
            for p0 in (0..pixels).step_by(d.tile()) {
                let n = d.tile().min(pixels - p0);
                let cols = if d.pointwise() {
                    &xb[p0..]
                } else {
                    im2col(xb, &d, p0, n, col);
                    &col[..k * n]
                };
                zb.product(
                    p0,
                    w,
                    MatRef {
                        data: cols,
                        rows: k,
                        cols: n,
                        row_stride: if d.pointwise() { pixels } else { n },
                        col_stride: 1,
                    },
                    false,
                    !in_parallel,
                );
            }
        },
    );
    if !bias.is_empty() {
        z.par_chunks_exact_mut(pixels)
            .enumerate()
            .for_each(|(row, zr)| {
                let b = bias[row % d.c_out];
                zr.iter_mut().for_each(|v| *v += b);
            });
    }
    z
}

/// Whether a batch runs one sample per rayon task with single-threaded GEMMs: when there
/// are at least as many samples as threads (the albedo U-Net's batch of 4 on 2 cores), which
/// keeps both cores busy through the patch gathers and GEMM packing as well. Otherwise the
/// samples run in order with multi-threaded GEMMs.
fn samples_in_parallel(batch: usize) -> bool {
    let threads = rayon::current_num_threads();
    threads > 1 && batch >= threads
}

/// Gradients of [`conv2d_forward`] with respect to the input and the weight (each only
/// when asked for; the bias gradient is the row sums of `dz`, see [`post_backward_in_place`]).
///
/// # Shapes
/// - `dz`: `[B, C_out, OH, OW]`; `x`: `[B, C_in, H, W]`; `weight`: `[C_out, C_in, kh, kw]`
/// - output: (`[B, C_in, H, W]`, `[C_out, C_in, kh, kw]`)
pub(crate) fn conv2d_backward(
    dz: &[f32],
    x: &[f32],
    weight: &[f32],
    d: Conv2dDims,
    need_dx: bool,
    need_dw: bool,
) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
    assert_eq!(
        dz.len(),
        d.batch * d.c_out * d.pixels(),
        "conv2d_backward: dz"
    );
    assert_eq!(x.len(), d.batch * d.c_in * d.plane(), "conv2d_backward: x");
    assert_eq!(weight.len(), d.c_out * d.patch(), "conv2d_backward: w");
    let mut dx = need_dx.then(|| super::zeros(x.len()));
    let mut dw = need_dw.then(|| vec![0.0f32; weight.len()]);
    if d.pixels() == 0 || d.batch == 0 {
        return (dx, dw);
    }
    if let Some(dw) = dw.as_mut() {
        weight_gradient(dz, x, d, dw);
    }
    if let Some(dx) = dx.as_mut() {
        input_gradient(dz, weight, d, dx);
    }
    (dx, dw)
}

/// Columns `[p0, p0 + n)` of one sample's `dz` `[C_out, pixels]`.
fn dz_cols<'a>(gb: &'a [f32], d: &Conv2dDims, p0: usize, n: usize) -> MatRef<'a> {
    MatRef {
        data: &gb[p0..],
        rows: d.c_out,
        cols: n,
        row_stride: d.pixels(),
        col_stride: 1,
    }
}

/// `dW = sum over tiles of dz_tile col_tile^T` (for a 1x1 convolution, `dz_b x_b^T` per
/// sample). With at least as many tiles (of all samples) as threads, the tiles are cut into
/// one contiguous run per thread, each run summed with single-threaded GEMMs into its own
/// buffer, and the partial sums added in run order: the long pixel reduction is what a
/// multi-threaded GEMM cannot split, so it would run on one core. With fewer tiles they run
/// in order with multi-threaded GEMMs.
///
/// # Shapes
/// - `dz`: `[B, C_out, OH, OW]`; `x`: `[B, C_in, H, W]`; `dw`: `[C_out, C_in kh kw]`, zeros
fn weight_gradient(dz: &[f32], x: &[f32], d: Conv2dDims, dw: &mut [f32]) {
    let (pixels, k, plane, tile) = (d.pixels(), d.patch(), d.plane(), d.tile());
    let tiles: Vec<(usize, usize)> = (0..d.batch)
        .flat_map(|b| (0..pixels).step_by(tile).map(move |p0| (b, p0)))
        .collect();
    let run = |dw: &mut [f32], tiles: &[(usize, usize)], col: &mut [f32], parallel: bool| {
        for &(b, p0) in tiles {
            let n = tile.min(pixels - p0);
            let gb = &dz[b * d.c_out * pixels..(b + 1) * d.c_out * pixels];
            let xb = &x[b * d.c_in * plane..(b + 1) * d.c_in * plane];
            // col^T = [n, k]; for a 1x1 convolution col is the sample itself.
            let (cols, col_stride) = if d.pointwise() {
                (xb, pixels)
            } else {
                im2col(xb, &d, p0, n, col);
                (&col[..k * n], n)
            };
            matmul(
                MatMut {
                    data: dw,
                    rows: d.c_out,
                    cols: k,
                    row_stride: k,
                    col_stride: 1,
                },
                dz_cols(gb, &d, p0, n),
                MatRef {
                    data: cols,
                    rows: n,
                    cols: k,
                    row_stride: 1,
                    col_stride,
                },
                true,
                parallel,
            );
        }
    };
    let threads = rayon::current_num_threads();
    if threads > 1 && tiles.len() >= threads {
        let partials: Vec<Vec<f32>> = tiles
            .par_chunks(tiles.len().div_ceil(threads))
            .map(|part| {
                let mut acc = vec![0.0f32; dw.len()];
                run(&mut acc, part, &mut d.col_buffer(), false);
                acc
            })
            .collect();
        for part in &partials {
            dw.iter_mut().zip(part).for_each(|(a, v)| *a += v);
        }
    } else {
        run(dw, &tiles, &mut d.col_buffer(), true);
    }
}

/// `dx_b = col2im(W^T dz_b)`, tile by tile; samples run in parallel as in the forward pass
/// (each owns its `dx_b`).
///
/// # Shapes
/// - `dz`: `[B, C_out, OH, OW]`; `weight`: `[C_out, C_in, kh, kw]`; `dx`: `[B, C_in, H, W]`,
///   zeros
fn input_gradient(dz: &[f32], weight: &[f32], d: Conv2dDims, dx: &mut [f32]) {
    let (pixels, k, tile) = (d.pixels(), d.patch(), d.tile());
    let wt = d.weight_t(weight);
    let sample = |gb: &[f32], dxb: &mut [f32], dcol: &mut [f32], parallel: bool| {
        if d.pointwise() {
            let dxb = MatMut {
                data: dxb,
                rows: d.c_in,
                cols: pixels,
                row_stride: pixels,
                col_stride: 1,
            };
            matmul(dxb, wt, dz_cols(gb, &d, 0, pixels), false, parallel);
            return;
        }
        for p0 in (0..pixels).step_by(tile) {
            let n = tile.min(pixels - p0);
            let dcol_mat = MatMut {
                data: &mut dcol[..k * n],
                rows: k,
                cols: n,
                row_stride: n,
                col_stride: 1,
            };
            matmul(dcol_mat, wt, dz_cols(gb, &d, p0, n), false, parallel);
            col2im_add(dcol, &d, p0, n, dxb);
        }
    };
    let (dz_len, dx_len) = (d.c_out * pixels, d.c_in * d.plane());
    if samples_in_parallel(d.batch) {
        dz.par_chunks_exact(dz_len)
            .zip(dx.par_chunks_exact_mut(dx_len))
            .for_each_init(
                || d.col_buffer(),
                |dcol, (gb, dxb)| sample(gb, dxb, dcol, false),
            );
    } else {
        let mut dcol = d.col_buffer();
        for (gb, dxb) in dz.chunks_exact(dz_len).zip(dx.chunks_exact_mut(dx_len)) {
            sample(gb, dxb, &mut dcol, true);
        }
    }
}

/// The activation after the (normalised) convolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Activation {
    Identity,
    Relu,
    /// LeakyReLU with this negative slope.
    LeakyRelu(f64),
    Sigmoid,
}

/// `out[t] = act(inp[t] s + h)`, the loop compiled once per activation.
#[inline(always)]
fn map_row(out: &mut [f32], inp: &[f32], s: f32, h: f32, act: Activation) {
    #[inline(always)]
    fn run(out: &mut [f32], inp: &[f32], s: f32, h: f32, f: impl Fn(f32) -> f32) {
        for (y, &z) in out.iter_mut().zip(inp) {
            *y = f(z * s + h);
        }
    }
    match act {
        Activation::Identity => run(out, inp, s, h, |a| a),
        Activation::Relu => run(out, inp, s, h, |a| a.max(0.0)),
        Activation::LeakyRelu(slope) => {
            let slope = slope as f32;
            run(
                out,
                inp,
                s,
                h,
                move |a| if a >= 0.0 { a } else { a * slope },
            );
        }
        Activation::Sigmoid => run(out, inp, s, h, |a| 1.0 / (1.0 + (-a).exp())),
    }
}

/// `g[t] *= act'(z[t] s + h)`, the loop compiled once per activation.
#[inline(always)]
fn grad_row(g: &mut [f32], z: &[f32], s: f32, h: f32, act: Activation) {
    #[inline(always)]
    fn run(g: &mut [f32], z: &[f32], s: f32, h: f32, f: impl Fn(f32) -> f32) {
        for (g, &z) in g.iter_mut().zip(z) {
            *g *= f(z * s + h);
        }
    }
    match act {
        Activation::Identity => {}
        Activation::Relu => run(g, z, s, h, |a| if a > 0.0 { 1.0 } else { 0.0 }),
        Activation::LeakyRelu(slope) => {
            let slope = slope as f32;
            run(g, z, s, h, move |a| if a > 0.0 { 1.0 } else { slope });
        }
        Activation::Sigmoid => run(g, z, s, h, |a| {
            let e = 1.0 / (1.0 + (-a).exp());
            e * (1.0 - e)
        }),
    }
}

/// Elements per block of the row sums: `f32` lanes within a block, `f64` across blocks.
const BLOCK: usize = 1024;
const LANES: usize = 16;

/// `(sum_t g[t], sum_t g[t] (z[t] - m))`, vectorisable (independent lanes).
#[inline(always)]
fn dot_dev(g: &[f32], z: &[f32], m: f32) -> (f64, f64) {
    let (mut t1, mut t2) = (0.0f64, 0.0f64);
    for (gb, zb) in g.chunks(BLOCK).zip(z.chunks(BLOCK)) {
        let (mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES]);
        let (gc, zc) = (gb.chunks_exact(LANES), zb.chunks_exact(LANES));
        let (gr, zr) = (gc.remainder(), zc.remainder());
        for (x, y) in gc.zip(zc) {
            for i in 0..LANES {
                s1[i] += x[i];
                s2[i] += x[i] * (y[i] - m);
            }
        }
        let mut b1: f32 = s1.iter().sum();
        let mut b2: f32 = s2.iter().sum();
        for (x, y) in gr.iter().zip(zr) {
            b1 += x;
            b2 += x * (y - m);
        }
        t1 += f64::from(b1);
        t2 += f64::from(b2);
    }
    (t1, t2)
}

/// `(sum_t (z[t] - k), sum_t (z[t] - k)^2)`, vectorisable.
#[inline(always)]
fn sum_dev(z: &[f32], k: f32) -> (f64, f64) {
    let (mut t1, mut t2) = (0.0f64, 0.0f64);
    for zb in z.chunks(BLOCK) {
        let (mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES]);
        let zc = zb.chunks_exact(LANES);
        let zr = zc.remainder();
        for x in zc {
            for i in 0..LANES {
                let d = x[i] - k;
                s1[i] += d;
                s2[i] += d * d;
            }
        }
        let mut b1: f32 = s1.iter().sum();
        let mut b2: f32 = s2.iter().sum();
        for x in zr {
            let d = x - k;
            b1 += d;
            b2 += d * d;
        }
        t1 += f64::from(b1);
        t2 += f64::from(b2);
    }
    (t1, t2)
}

/// Sizes of the part after the convolution: an optional instance norm over each
/// `(sample, channel)` row of `len` pixels (with `gamma`, `beta`, ones and zeros when it is
/// not affine), then the activation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PostDims {
    pub batch: usize,
    pub channels: usize,
    pub len: usize,
    /// The norm's epsilon; `None` for no norm.
    pub norm: Option<f64>,
    pub act: Activation,
}

/// Per row, the forward map's `a = z scale + shift` (the activation's input) and the
/// norm's `mean`, `rstd` (`0`, `1` without a norm).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RowStats {
    pub mean: Vec<f32>,
    pub rstd: Vec<f32>,
}

impl RowStats {
    /// `(scale, shift)` of row `row`.
    fn map(&self, row: usize, gamma: &[f32], beta: &[f32], d: &PostDims) -> (f32, f32) {
        if d.norm.is_none() {
            return (1.0, 0.0);
        }
        let c = row % d.channels;
        let s = self.rstd[row] * gamma[c];
        (s, beta[c] - self.mean[row] * s)
    }
}

/// `act(InstanceNorm(z))` (or `act(z)` without a norm) and the per-row statistics.
///
/// # Shapes
/// - `z`: `[B, C, len]`; `gamma`, `beta`: `[C]`
/// - output: `[B, C, len]`
pub(crate) fn post_forward(
    z: &[f32],
    gamma: &[f32],
    beta: &[f32],
    d: PostDims,
) -> (Vec<f32>, RowStats) {
    let rows = d.batch * d.channels;
    assert_eq!(z.len(), rows * d.len, "post_forward: z");
    let len = d.len.max(1);
    let arch = Arch::new();
    let (mean, rstd): (Vec<f32>, Vec<f32>) = match d.norm {
        // Moments about the row's first value (a shift near the mean keeps the variance
        // `E[(z - k)^2] - E[z - k]^2` accurate).
        Some(eps) => z
            .par_chunks_exact(len)
            .map(|r| {
                let n = r.len() as f64;
                let k = r[0];
                let (s1, s2) = vectorized!(arch, <'a> (r: &'a [f32] = r, k: f32 = k) -> (f64, f64) {
                    sum_dev(r, k)
                });
                let d1 = s1 / n;
                let var = (s2 / n - d1 * d1).max(0.0);
                (
                    (f64::from(k) + d1) as f32,
                    (1.0 / (var + eps).sqrt()) as f32,
                )
            })
            .unzip(),
        None => (vec![0.0; rows], vec![1.0; rows]),
    };
    let stats = RowStats { mean, rstd };
    let filled_rows = if z.is_empty() { 0 } else { rows };
    let y = super::rows_by_blocks(filled_rows, len, |row, from, yr| {
        let (s, h) = stats.map(row, gamma, beta, &d);
        let act = d.act;
        let zr = &z[row * len + from..][..yr.len()];
        vectorized!(arch, <'a> (
            yr: &'a mut [f32] = yr, zr: &'a [f32] = zr, s: f32 = s, h: f32 = h,
            act: Activation = act,
        ) -> () {
            map_row(yr, zr, s, h, act)
        });
    });
    (y, stats)
}

/// The backward pass of [`post_forward`] in place: `grad` holds the output gradient on
/// entry and `dz` on return; returns `[dbias, dgamma, dbeta]` (`dbias` is `sum dz` per
/// channel, the gradient of a bias added to `z`: zero under a norm, which a per-channel
/// constant does not change).
///
/// With `xhat = (z - mean) rstd`, `a = xhat gamma + beta`, `ga = gy act'(a)`, per row
/// `A = sum ga`, `B = sum ga xhat`: `dz = rstd gamma (ga - A / n - xhat B / n)`,
/// `dgamma = sum B`, `dbeta = sum A`.
///
/// # Shapes
/// - `grad`, `z`: `[B, C, len]`; `gamma`, `beta`: `[C]`
/// - output: three `[C]`
pub(crate) fn post_backward_in_place(
    grad: &mut [f32],
    z: &[f32],
    gamma: &[f32],
    beta: &[f32],
    stats: &RowStats,
    d: PostDims,
) -> [Vec<f32>; 3] {
    let rows = d.batch * d.channels;
    assert_eq!(grad.len(), rows * d.len, "post_backward: gy");
    assert_eq!(z.len(), rows * d.len, "post_backward: z");
    let len = d.len.max(1);
    let n = d.len as f64;
    let arch = Arch::new();
    // Per row (sum ga, sum ga xhat, sum dz).
    let sums: Vec<(f64, f64, f64)> = grad
        .par_chunks_exact_mut(len)
        .zip(z.par_chunks_exact(len))
        .enumerate()
        .map(|(row, (g, zr))| {
            let (s, h) = stats.map(row, gamma, beta, &d);
            let (act, normed) = (d.act, d.norm.is_some());
            let (m, r) = (stats.mean[row], stats.rstd[row]);
            // gamma is empty without a norm.
            let p = if normed {
                r * gamma[row % d.channels]
            } else {
                0.0
            };
            vectorized!(arch, <'a> (
                g: &'a mut [f32] = g, zr: &'a [f32] = zr, s: f32 = s, h: f32 = h,
                act: Activation = act, normed: bool = normed, m: f32 = m, r: f32 = r, p: f32 = p,
                n: f64 = n,
            ) -> (f64, f64, f64) {
                grad_row(g, zr, s, h, act);
                if !normed {
                    let (total, _) = dot_dev(g, zr, 0.0);
                    return (0.0, 0.0, total);
                }
                let (sa, sgd) = dot_dev(g, zr, m);
                let sb = f64::from(r) * sgd;
                let (ma, mb) = ((sa / n) as f32, (sb / n) as f32);
                // dz = p (ga - ma - (z - m) r mb) = p ga + q z + c.
                let q = -p * r * mb;
                let c = -p * (ma - m * r * mb);
                for (g, &z) in g.iter_mut().zip(zr.iter()) {
                    *g = p * *g + q * z + c;
                }
                // A norm is blind to a constant added to its row: sum dz = 0 exactly.
                (sa, sb, 0.0)
            })
        })
        .collect();
    let mut out = [
        vec![0.0f32; d.channels],
        vec![0.0f32; d.channels],
        vec![0.0f32; d.channels],
    ];
    let mut acc = vec![(0.0f64, 0.0f64, 0.0f64); d.channels];
    for (row, &(a, b, s)) in sums.iter().enumerate() {
        let e = &mut acc[row % d.channels];
        e.0 += a;
        e.1 += b;
        e.2 += s;
    }
    for (c, &(a, b, s)) in acc.iter().enumerate() {
        out[0][c] = s as f32;
        out[1][c] = b as f32;
        out[2][c] = a as f32;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::assert_conv_adjoints;
    use bitt_testkit::{assert_close, values};

    /// The convolution as the textbook loop nest, in f64.
    fn conv_naive(x: &[f32], w: &[f32], bias: &[f32], d: Conv2dDims) -> Vec<f32> {
        let [oh, ow] = d.out_size().unwrap();
        let [h, wd] = d.size;
        let [kh, kw] = d.kernel;
        let mut z = vec![0.0; d.batch * d.c_out * oh * ow];
        for b in 0..d.batch {
            for o in 0..d.c_out {
                for y in 0..oh {
                    for xo in 0..ow {
                        let mut s = bias.get(o).map_or(0.0, |&v| f64::from(v));
                        for c in 0..d.c_in {
                            for i in 0..kh {
                                for j in 0..kw {
                                    let iy = (y * d.stride[0] + i) as isize - d.padding[0] as isize;
                                    let ix =
                                        (xo * d.stride[1] + j) as isize - d.padding[1] as isize;
                                    if (0..h as isize).contains(&iy)
                                        && (0..wd as isize).contains(&ix)
                                    {
                                        s += f64::from(w[((o * d.c_in + c) * kh + i) * kw + j])
                                            * f64::from(
                                                x[((b * d.c_in + c) * h + iy as usize) * wd
                                                    + ix as usize],
                                            );
                                    }
                                }
                            }
                        }
                        z[((b * d.c_out + o) * oh + y) * ow + xo] = s as f32;
                    }
                }
            }
        }
        z
    }

    fn dims(
        batch: usize,
        c_in: usize,
        c_out: usize,
        size: [usize; 2],
        kernel: usize,
        stride: usize,
        padding: usize,
    ) -> Conv2dDims {
        Conv2dDims {
            batch,
            c_in,
            c_out,
            size,
            kernel: [kernel; 2],
            stride: [stride; 2],
            padding: [padding; 2],
        }
    }

    /// Forward against the naive loops (with tiles that end mid-row: a wide patch makes
    /// the tile `MIN_TILE` pixels); both gradients against the naive convolution's
    /// gradient, probed with one-hot inputs, and the adjoint identities.
    #[test]
    fn conv2d_kernels_match_naive_loops() {
        let cases = [
            dims(2, 3, 5, [9, 7], 4, 2, 1),
            dims(1, 4, 3, [8, 8], 4, 2, 0),
            dims(2, 3, 4, [5, 6], 3, 1, 0),
            dims(1, 2, 3, [7, 5], 3, 1, 1),
            dims(3, 5, 2, [3, 4], 1, 1, 0),
            dims(1, 1, 2, [4, 4], 4, 2, 0),
            // 48 patch rows at 64 x 64: several tiles, one ending inside an output row.
            dims(1, 3, 2, [128, 90], 4, 2, 1),
            dims(2, 300, 2, [13, 11], 3, 1, 1),
        ];
        for d in cases {
            let x = values(d.batch * d.c_in * d.plane(), 1);
            let w = values(d.c_out * d.patch(), 2);
            let bias = values(d.c_out, 3);
            let z = conv2d_forward(&x, &w, &bias, d);
            assert_close(&z, &conv_naive(&x, &w, &bias, d), 1e-4, "forward");
            let g = values(z.len(), 4);
            let (dx, dw) = conv2d_backward(&g, &x, &w, d, true, true);
            let (dx, dw) = (dx.unwrap(), dw.unwrap());
            assert_conv_adjoints(
                [&x, &w, &g],
                [&dx, &dw],
                |x, w| conv_naive(x, w, &[], d),
                [1e-3, 1e-4, 1e-3],
                &format!("{d:?}"),
            );
            // Only one of the two asked for.
            let (none, only_w) = conv2d_backward(&g, &x, &w, d, false, true);
            assert!(none.is_none());
            assert_close(&only_w.unwrap(), &dw, 1e-6, "dw alone");
        }
    }

    #[test]
    fn valid_ranges() {
        // stride 2, offset -1, size 8: inputs 2u - 1 in [0, 8) for u in [1, 5).
        assert_eq!(valid(0, 6, 2, -1, 8), (1, 5));
        assert_eq!(valid(0, 4, 2, -1, 8), (1, 4));
        assert_eq!(valid(2, 4, 2, -1, 8), (0, 3));
        assert_eq!(valid(0, 3, 1, 5, 4), (0, 0));
        assert_eq!(valid(0, 3, 1, -9, 4), (3, 3));
    }

    /// Instance norm + each activation against an f64 evaluation, and the backward pass
    /// against central finite differences of `sum(y gy)`.
    #[test]
    fn norm_activation_matches_definition_and_finite_differences() {
        for act in [
            Activation::Identity,
            Activation::Relu,
            Activation::LeakyRelu(0.2),
            Activation::Sigmoid,
        ] {
            for norm in [Some(1e-5), None] {
                let d = PostDims {
                    batch: 2,
                    channels: 3,
                    len: 11,
                    norm,
                    act,
                };
                let n = d.batch * d.channels * d.len;
                let z: Vec<f32> = values(n, 5).iter().map(|v| v * 2.0 + 0.3).collect();
                let gamma: Vec<f32> = values(3, 6).iter().map(|v| v + 1.2).collect();
                let beta = values(3, 7);
                let gy = values(n, 8);
                let f = |a: f64| match act {
                    Activation::Identity => a,
                    Activation::Relu => a.max(0.0),
                    Activation::LeakyRelu(s) => {
                        if a >= 0.0 {
                            a
                        } else {
                            a * s
                        }
                    }
                    Activation::Sigmoid => 1.0 / (1.0 + (-a).exp()),
                };
                let reference = |z: &[f64], gamma: &[f64], beta: &[f64]| -> Vec<f64> {
                    let mut y = vec![0.0; n];
                    for row in 0..d.batch * d.channels {
                        let r = &z[row * d.len..(row + 1) * d.len];
                        let c = row % d.channels;
                        let m = r.iter().sum::<f64>() / d.len as f64;
                        let v = r.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / d.len as f64;
                        for t in 0..d.len {
                            let a = match norm {
                                Some(eps) => (r[t] - m) / (v + eps).sqrt() * gamma[c] + beta[c],
                                None => r[t],
                            };
                            y[row * d.len + t] = f(a);
                        }
                    }
                    y
                };
                let f64s = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<_>>();
                let (zd, gd, bd) = (f64s(&z), f64s(&gamma), f64s(&beta));
                let (y, stats) = post_forward(&z, &gamma, &beta, d);
                let yr: Vec<f32> = reference(&zd, &gd, &bd).iter().map(|&v| v as f32).collect();
                assert_close(&y, &yr, 1e-5, "y");
                let mut dz = gy.clone();
                let [dbias, dgamma, dbeta] =
                    post_backward_in_place(&mut dz, &z, &gamma, &beta, &stats, d);
                let loss = |y: Vec<f64>| -> f64 {
                    y.iter().zip(&gy).map(|(y, g)| y * f64::from(*g)).sum()
                };
                let h = 1e-6;
                let fd = |which: usize, i: usize| -> f64 {
                    let mut args = [zd.clone(), gd.clone(), bd.clone()];
                    args[which][i] += h;
                    let up = loss(reference(&args[0], &args[1], &args[2]));
                    args[which][i] -= 2.0 * h;
                    let down = loss(reference(&args[0], &args[1], &args[2]));
                    (up - down) / (2.0 * h)
                };
                for i in [0, 5, 27, n - 1] {
                    let e = fd(0, i);
                    assert!(
                        (f64::from(dz[i]) - e).abs() < 2e-4,
                        "{act:?} {norm:?} dz[{i}] {} vs {e}",
                        dz[i]
                    );
                }
                for c in 0..3 {
                    // A bias on z moves every element of its channel's rows.
                    let e: f64 = (0..d.batch)
                        .flat_map(|b| (0..d.len).map(move |t| ((b * 3 + c) * d.len) + t))
                        .map(|i| fd(0, i))
                        .sum();
                    assert!((f64::from(dbias[c]) - e).abs() < 1e-3, "{act:?} dbias[{c}]");
                    if norm.is_some() {
                        for (which, got) in [(1, &dgamma), (2, &dbeta)] {
                            let e = fd(which, c);
                            assert!(
                                (f64::from(got[c]) - e).abs() < 2e-4,
                                "{act:?} arg {which} [{c}]: {} vs {e}",
                                got[c]
                            );
                        }
                    }
                }
            }
        }
    }
}
