//! A bounds-checked, safe front to the `gemm` crate (the GEMM burn's flex backend uses).
//!
//! This is the workspace's only `unsafe` library code: `gemm::gemm` takes raw pointers and
//! strides. [`matmul`] checks that every element the strides address lies inside its slice,
//! and the borrow rules keep the destination from aliasing the operands, which is all
//! `gemm::gemm` requires.
//!
//! [`products_into_new`] builds a new buffer from GEMMs without clearing it first: clearing
//! a fresh output before a GEMM overwrote it was a sixth of BTR's step at the `quick`
//! preset (110 buffers per step, written twice). The GEMMs write into the buffer's
//! uninitialised capacity through [`Columns`], which records the columns each product
//! overwrote, lets a product accumulate only onto columns already written, and checks that
//! every column of every sample was written before the buffer's length is set.
//!
//! [`pair_by_blocks`] builds two new buffers from one row pass the same way: the pass writes
//! blocks on the stack, and this module copies every block into the buffers' capacity.
#![allow(unsafe_code)]

use std::mem::MaybeUninit;

use rayon::prelude::*;

/// A strided, read-only matrix: element `(i, j)` is `data[i * row_stride + j * col_stride]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MatRef<'a> {
    pub data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    pub row_stride: usize,
    pub col_stride: usize,
}

/// A strided, writable matrix, laid out as [`MatRef`].
#[derive(Debug)]
pub(crate) struct MatMut<'a> {
    pub data: &'a mut [f32],
    pub rows: usize,
    pub cols: usize,
    pub row_stride: usize,
    pub col_stride: usize,
}

/// Whether a `rows x cols` view with these strides stays inside `len` elements.
fn fits(len: usize, rows: usize, cols: usize, row_stride: usize, col_stride: usize) -> bool {
    rows == 0
        || cols == 0
        || (rows - 1)
            .checked_mul(row_stride)
            .zip((cols - 1).checked_mul(col_stride))
            .and_then(|(a, b)| a.checked_add(b))
            .is_some_and(|last| last < len)
}

/// Panics unless a `[rows, cols]` view with these strides stays inside `len` elements and
/// its strides fit in `isize` (what `gemm::gemm` takes).
fn check_view(what: &str, len: usize, [rows, cols]: [usize; 2], [rs, cs]: [usize; 2]) {
    assert!(
        fits(len, rows, cols, rs, cs),
        "{what} view [{rows}, {cols}] with strides ({rs}, {cs}) exceeds {len} elements"
    );
    assert!(
        isize::try_from(rs).is_ok() && isize::try_from(cs).is_ok(),
        "{what} strides overflow"
    );
}

/// [`check_view`] for both operands of a product.
fn check_operands(caller: &str, lhs: MatRef<'_>, rhs: MatRef<'_>) {
    for (what, m) in [("lhs", lhs), ("rhs", rhs)] {
        check_view(
            &format!("{caller} {what}"),
            m.data.len(),
            [m.rows, m.cols],
            [m.row_stride, m.col_stride],
        );
    }
}

/// `dst = lhs rhs` (or `dst += lhs rhs` when `accumulate`), multi-threaded on rayon's pool
/// when `parallel` and the product is large.
///
/// # Panics
/// When the shapes disagree or a view addresses elements outside its slice.
pub(crate) fn matmul(
    dst: MatMut<'_>,
    lhs: MatRef<'_>,
    rhs: MatRef<'_>,
    accumulate: bool,
    parallel: bool,
) {
    let (m, n, k) = (lhs.rows, rhs.cols, lhs.cols);
    assert!(
        dst.rows == m && dst.cols == n && rhs.rows == k,
        "matmul: [{}, {}] = [{m}, {k}] x [{}, {n}]",
        dst.rows,
        dst.cols,
        rhs.rows
    );
    check_view(
        "matmul dst",
        dst.data.len(),
        [m, n],
        [dst.row_stride, dst.col_stride],
    );
    check_operands("matmul", lhs, rhs);
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            for i in 0..m {
                for j in 0..n {
                    dst.data[i * dst.row_stride + j * dst.col_stride] = 0.0;
                }
            }
        }
        return;
    }
    // SAFETY: the checks above keep every element addressed through the strides (which fit
    // in `isize`) inside its slice; `dst` is a unique borrow of initialised values, so it
    // aliases neither operand and may be read.
    unsafe {
        gemm_into(
            dst.data.as_mut_ptr(),
            [dst.row_stride, dst.col_stride],
            lhs,
            rhs,
            accumulate,
            parallel,
        );
    }
}

/// `dst = lhs rhs` (`dst += lhs rhs` when `accumulate`) through `gemm::gemm`.
///
/// # Safety
/// `lhs` and `rhs` have been checked to fit their slices (`fits`) and `k > 0`, `m, n > 0`.
/// Every element `dst + i * strides[0] + j * strides[1]` (`i < m`, `j < n`) is valid for
/// writes, owned by the caller alone, and when `accumulate` holds an initialised value.
/// Without `accumulate` gemm writes each of them before it reads it (its `alpha` is zero).
unsafe fn gemm_into(
    dst: *mut f32,
    strides: [usize; 2],
    lhs: MatRef<'_>,
    rhs: MatRef<'_>,
    accumulate: bool,
    parallel: bool,
) {
    let (m, n, k) = (lhs.rows, rhs.cols, lhs.cols);
    let parallelism = if parallel && m.saturating_mul(n).saturating_mul(k) >= 1 << 20 {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: as the caller guarantees.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst,
            strides[1] as isize,
            strides[0] as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.col_stride as isize,
            lhs.row_stride as isize,
            rhs.data.as_ptr(),
            rhs.col_stride as isize,
            rhs.row_stride as isize,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// One sample's `[rows, len]` part of a buffer that [`products_into_new`] fills: GEMMs
/// write whole columns of it (every row) and it records which.
#[derive(Debug)]
pub(crate) struct Columns<'a> {
    data: &'a mut [MaybeUninit<f32>],
    rows: usize,
    len: usize,
    /// Column ranges `[from, to)` overwritten so far.
    written: Vec<(usize, usize)>,
}

impl Columns<'_> {
    /// Columns `[from, from + rhs.cols)` = `lhs rhs` (every row), or `+=` when `accumulate`,
    /// which needs those columns written before.
    ///
    /// # Panics
    /// When the shapes disagree, the columns leave the buffer, an operand view leaves its
    /// slice, or `accumulate` reaches columns not yet written.
    pub(crate) fn product(
        &mut self,
        from: usize,
        lhs: MatRef<'_>,
        rhs: MatRef<'_>,
        accumulate: bool,
        parallel: bool,
    ) {
        let (m, n, k) = (lhs.rows, rhs.cols, lhs.cols);
        assert!(
            m == self.rows && rhs.rows == k && from.checked_add(n).is_some_and(|e| e <= self.len),
            "Columns::product: [{}, {from}..+{n}] of [{}, {}] = [{m}, {k}] x [{}, {n}]",
            self.rows,
            self.rows,
            self.len,
            rhs.rows
        );
        check_operands("Columns::product", lhs, rhs);
        if accumulate {
            assert!(
                covered(&self.written, from, from + n),
                "Columns::product: accumulating onto columns {from}..{} not written yet",
                from + n
            );
        }
        if m == 0 || n == 0 {
            return;
        }
        if k == 0 {
            if !accumulate {
                for i in 0..m {
                    self.data[i * self.len + from..i * self.len + from + n]
                        .fill(MaybeUninit::new(0.0));
                }
                self.written.push((from, from + n));
            }
            return;
        }
        // SAFETY: the operands fit their slices (checked above) and `k, m, n > 0`. The
        // destination's elements `from + i * len + j` (`i < rows`, `j < n`, `from + n <=
        // len`) lie inside `data` (`rows * len` long), which this value borrows uniquely;
        // with `accumulate` they were all written by an earlier product (checked above).
        unsafe {
            gemm_into(
                self.data.as_mut_ptr().cast::<f32>().add(from),
                [self.len, 1],
                lhs,
                rhs,
                accumulate,
                parallel,
            );
        }
        if !accumulate {
            self.written.push((from, from + n));
        }
    }
}

/// Whether the ranges cover `[from, to)`.
fn covered(ranges: &[(usize, usize)], from: usize, to: usize) -> bool {
    let mut sorted = ranges.to_vec();
    sorted.sort_unstable();
    let mut reach = from;
    for (a, b) in sorted {
        if a <= reach {
            reach = reach.max(b);
        }
    }
    reach >= to
}

/// A new `[samples, rows, len]` buffer whose every sample `fill` writes with products
/// ([`Columns::product`]), not cleared first. The samples run on rayon's threads when
/// `in_parallel`, else in order; `init` makes each task's scratch state.
///
/// # Panics
/// When a sample's columns are not all written (nothing is returned then), or `fill` panics.
pub(crate) fn products_into_new<S>(
    samples: usize,
    rows: usize,
    len: usize,
    in_parallel: bool,
    init: impl Fn() -> S + Sync + Send,
    fill: impl Fn(&mut S, usize, &mut Columns<'_>) + Sync + Send,
) -> Vec<f32> {
    let size = rows * len;
    let total = samples * size;
    let mut out: Vec<f32> = Vec::with_capacity(total);
    if total > 0 {
        let run = |state: &mut S, (b, data): (usize, &mut [MaybeUninit<f32>])| {
            let mut columns = Columns {
                data,
                rows,
                len,
                written: Vec::new(),
            };
            fill(state, b, &mut columns);
            assert!(
                covered(&columns.written, 0, len),
                "products_into_new: sample {b} has columns left unwritten"
            );
        };
        let spare = &mut out.spare_capacity_mut()[..total];
        if in_parallel {
            spare
                .par_chunks_exact_mut(size)
                .enumerate()
                .for_each_init(&init, run);
        } else {
            let mut state = init();
            spare
                .chunks_exact_mut(size)
                .enumerate()
                .for_each(|item| run(&mut state, item));
        }
    }
    // SAFETY: `total <= capacity`, and every sample's `rows * len` elements were written:
    // each product overwrote every row of its columns, and the columns of every sample
    // cover `[0, len)` (asserted above; a failed assertion unwinds before this line).
    unsafe { out.set_len(total) };
    out
}

/// Floats per block of [`pair_by_blocks`] (as [`super::rows_by_blocks`]'s).
const PAIR_BLOCK: usize = 256;

/// Two new `[rows, len]` buffers computed block by block on rayon's threads, never cleared:
/// `f(row, from, a, b)` writes the row's values at `[from, from + a.len())` of each (`a`,
/// `b` of equal length). The blocks are written on the stack and copied into place, every
/// element of both, so a pass that produces two outputs reads its inputs once.
pub(crate) fn pair_by_blocks(
    rows: usize,
    len: usize,
    f: impl Fn(usize, usize, &mut [f32], &mut [f32]) + Sync,
) -> (Vec<f32>, Vec<f32>) {
    let total = rows * len;
    let (mut a, mut b): (Vec<f32>, Vec<f32>) =
        (Vec::with_capacity(total), Vec::with_capacity(total));
    if total > 0 {
        a.spare_capacity_mut()[..total]
            .par_chunks_mut(PAIR_BLOCK)
            .zip(b.spare_capacity_mut()[..total].par_chunks_mut(PAIR_BLOCK))
            .enumerate()
            .with_min_len(16)
            .for_each(|(i, (da, db))| {
                let (mut la, mut lb) = ([0.0f32; PAIR_BLOCK], [0.0f32; PAIR_BLOCK]);
                let (start, n) = (i * PAIR_BLOCK, da.len());
                super::row_segments(start, n, len, |row, from, at, m| {
                    f(row, from, &mut la[at..at + m], &mut lb[at..at + m]);
                });
                for (d, &v) in da.iter_mut().zip(&la[..n]) {
                    d.write(v);
                }
                for (d, &v) in db.iter_mut().zip(&lb[..n]) {
                    d.write(v);
                }
            });
    }
    // SAFETY: `total <= capacity` for both, and every chunk of both `[..total]` was written
    // element by element above (`da`, `db` have `n` elements each; the loops write all `n`).
    unsafe {
        a.set_len(total);
        b.set_len(total);
    }
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pair_by_blocks_writes_both_buffers_row_by_row() {
        for (rows, len) in [(3, 100), (2, 600), (5, 1), (0, 7)] {
            let (a, b) = pair_by_blocks(rows, len, |row, from, a, b| {
                for (u, (x, y)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
                    *x = (row * 1000 + from + u) as f32;
                    *y = -*x;
                }
            });
            let want: Vec<f32> = (0..rows)
                .flat_map(|r| (0..len).map(move |t| (r * 1000 + t) as f32))
                .collect();
            assert_eq!(a, want);
            assert_eq!(b, want.iter().map(|v| -v).collect::<Vec<_>>());
        }
    }

    #[test]
    fn strided_products_and_accumulation() {
        // lhs [2, 3] row-major, rhs = transpose of a [2, 3] row-major buffer -> [3, 2].
        let lhs = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let rhs_t = [1.0, 0.0, -1.0, 2.0, 1.0, 0.5];
        let mut out = vec![10.0; 4];
        let lhs = MatRef {
            data: &lhs,
            rows: 2,
            cols: 3,
            row_stride: 3,
            col_stride: 1,
        };
        let rhs = MatRef {
            data: &rhs_t,
            rows: 3,
            cols: 2,
            row_stride: 1,
            col_stride: 3,
        };
        fn dst(out: &mut [f32]) -> MatMut<'_> {
            MatMut {
                data: out,
                rows: 2,
                cols: 2,
                row_stride: 2,
                col_stride: 1,
            }
        }
        matmul(dst(&mut out), lhs, rhs, false, true);
        assert_eq!(out, [-2.0, 5.5, -2.0, 16.0]);
        matmul(dst(&mut out), lhs, rhs, true, false);
        assert_eq!(out, [-4.0, 11.0, -4.0, 32.0]);
    }

    /// A buffer built by products equals the same products into a cleared buffer, in
    /// parallel and in order, with overwriting blocks and accumulating taps.
    #[test]
    fn products_into_new_equal_products_into_a_cleared_buffer() {
        let (rows, k, len, samples) = (3, 4, 37, 3);
        let lhs: Vec<f32> = (0..rows * k).map(|i| i as f32 * 0.25 - 1.0).collect();
        let src: Vec<f32> = (0..samples * k * len)
            .map(|i| ((i * 7) % 11) as f32 - 5.0)
            .collect();
        let lhs = MatRef {
            data: &lhs,
            rows,
            cols: k,
            row_stride: k,
            col_stride: 1,
        };
        let cols = |b: usize, from: usize, n: usize| MatRef {
            data: &src[b * k * len + from..],
            rows: k,
            cols: n,
            row_stride: len,
            col_stride: 1,
        };
        // Columns in two blocks (0..20, 20..37), then a second product added onto 5..30.
        let mut want = vec![0.0f32; samples * rows * len];
        for b in 0..samples {
            let dst = &mut want[b * rows * len..];
            for (from, n) in [(0, 20), (20, 17)] {
                let view = MatMut {
                    data: &mut dst[from..],
                    rows,
                    cols: n,
                    row_stride: len,
                    col_stride: 1,
                };
                matmul(view, lhs, cols(b, from, n), false, false);
            }
            let view = MatMut {
                data: &mut dst[5..],
                rows,
                cols: 25,
                row_stride: len,
                col_stride: 1,
            };
            matmul(view, lhs, cols(b, 0, 25), true, false);
        }
        for in_parallel in [false, true] {
            let got = products_into_new(
                samples,
                rows,
                len,
                in_parallel,
                || (),
                |(), b, dst| {
                    dst.product(20, lhs, cols(b, 20, 17), false, !in_parallel);
                    dst.product(0, lhs, cols(b, 0, 20), false, !in_parallel);
                    dst.product(5, lhs, cols(b, 0, 25), true, !in_parallel);
                },
            );
            assert_eq!(got, want, "in_parallel {in_parallel}");
        }
    }

    /// Fills `samples` samples of `[2, 4]` with products of ones over the column ranges
    /// `(from, accumulate)`, each two columns wide.
    fn fill_ones(samples: usize, products: &[(usize, bool)]) -> Vec<f32> {
        let ones = [1.0f32; 4];
        let m = MatRef {
            data: &ones,
            rows: 2,
            cols: 2,
            row_stride: 2,
            col_stride: 1,
        };
        products_into_new(
            samples,
            2,
            4,
            samples > 1,
            || (),
            |(), _, dst| {
                for &(from, accumulate) in products {
                    dst.product(from, m, m, accumulate, false);
                }
            },
        )
    }

    #[test]
    fn products_of_ones_fill_their_columns() {
        assert_eq!(fill_ones(2, &[(0, false), (2, false), (1, true)]), {
            let sample = [2.0, 4.0, 4.0, 2.0];
            [sample, sample, sample, sample].concat()
        });
    }

    #[test]
    #[should_panic(expected = "not written yet")]
    fn accumulating_onto_unwritten_columns_is_refused() {
        fill_ones(1, &[(0, false), (1, true)]);
    }

    #[test]
    #[should_panic(expected = "left unwritten")]
    fn a_sample_with_unwritten_columns_is_refused() {
        fill_ones(2, &[(0, false)]);
    }

    #[test]
    #[should_panic(expected = "exceeds")]
    fn views_outside_the_slice_are_refused() {
        let a = [0.0; 5];
        let mut out = [0.0; 4];
        let view = MatRef {
            data: &a,
            rows: 2,
            cols: 3,
            row_stride: 3,
            col_stride: 1,
        };
        matmul(
            MatMut {
                data: &mut out,
                rows: 2,
                cols: 2,
                row_stride: 2,
                col_stride: 1,
            },
            view,
            MatRef {
                data: &a,
                rows: 3,
                cols: 2,
                row_stride: 1,
                col_stride: 1,
            },
            false,
            false,
        );
    }
}
