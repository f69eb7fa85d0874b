//! A bounds-checked, safe front to the `gemm` crate (the GEMM burn's flex backend uses).
//!
//! This is the workspace's only `unsafe` code: `gemm::gemm` takes raw pointers and strides.
//! [`matmul`] checks that every element the strides address lies inside its slice, and the
//! borrow rules keep the destination from aliasing the operands, which is all `gemm::gemm`
//! requires.
#![allow(unsafe_code)]

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
    for (what, len, rows, cols, rs, cs) in [
        ("dst", dst.data.len(), m, n, dst.row_stride, dst.col_stride),
        ("lhs", lhs.data.len(), m, k, lhs.row_stride, lhs.col_stride),
        ("rhs", rhs.data.len(), k, n, rhs.row_stride, rhs.col_stride),
    ] {
        assert!(
            fits(len, rows, cols, rs, cs),
            "matmul: {what} view [{rows}, {cols}] with strides ({rs}, {cs}) exceeds {len} elements"
        );
        assert!(
            isize::try_from(rs).is_ok() && isize::try_from(cs).is_ok(),
            "matmul: {what} strides overflow"
        );
    }
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
    let parallelism = if parallel && m.saturating_mul(n).saturating_mul(k) >= 1 << 20 {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: the checks above keep every element addressed through the strides (which fit
    // in `isize`) inside its slice; `dst` is a unique borrow, so it aliases neither operand.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.data.as_mut_ptr(),
            dst.col_stride as isize,
            dst.row_stride as isize,
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

#[cfg(test)]
mod tests {
    use super::*;

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
