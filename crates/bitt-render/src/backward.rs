//! Analytic backward pass of [`crate::cpu::rasterize`] (interior gradients only).
//!
//! # Derivation
//! Let the face's clip vertices be `C_j = (x_j, y_j, z_j, w_j)` and the pixel centre be at
//! NDC `(p, q)`. The perspective-correct barycentrics `b` describe the clip-space point
//! `P = sum_j b_j C_j` whose projection is the pixel centre, i.e.
//! `P.x - p P.w = 0`, `P.y - q P.w = 0`, `sum_j b_j = 1`. This is the linear system
//! `M b = e3` with rows `M_0j = x_j - p w_j`, `M_1j = y_j - q w_j`, `M_2j = 1`.
//! Differentiating `M b = e3` gives `db = -M^-1 dM b`, so for an upstream gradient `g = dL/db`
//! and `u = M^-T g`, `dL/dM_rj = -u_r b_j`; then by the chain rule through the entries of `M`:
//! `dL/dx_j = -u_0 b_j`, `dL/dy_j = -u_1 b_j`, `dL/dw_j = (p u_0 + q u_1) b_j`.
//!
//! Depth `d = N / D` with `N = sum_j b_j z_j`, `D = sum_j b_j w_j` adds
//! `dL/dz_j = g_d b_j / D`, `dL/dw_j += -g_d d b_j / D`, and (through `b`)
//! `dL/db_j += g_d (z_j - d w_j) / D`, folded into `g` before solving for `u`.
//!
//! The system involves only the original face, so faces clipped by the near plane are handled
//! exactly like unclipped ones (the barycentrics at a pixel do not depend on clipping).
//! Gradients from pixels entering or leaving coverage (silhouette terms) are not produced.

use crate::error::{RenderError, check_faces, check_len, check_positions};
use crate::raster::Fragments;

/// Gradient of a scalar loss w.r.t. the clip positions, given `dL/d(bary)` per pixel and
/// optionally `dL/d(depth)` per pixel.
///
/// For every covered pixel the perspective-correct barycentrics (and depth) at the pixel centre
/// are differentiated analytically w.r.t. x, y, w (and z when depth gradients are given) of the
/// face's three clip vertices. Faces clipped by the near plane are handled the same way.
/// Pixels whose face projects to a degenerate system are skipped.
///
/// # Errors
/// Invalid positions or indices, fragment buffers of the wrong shape or naming missing faces,
/// or gradient buffers whose length is not `width * height`.
pub fn rasterize_backward(
    clip: &[[f32; 4]],
    faces: &[[u32; 3]],
    frags: &Fragments,
    grad_bary: &[[f32; 3]],
    grad_depth: Option<&[f32]>,
) -> Result<Vec<[f32; 4]>, RenderError> {
    check_positions(clip)?;
    check_faces(faces, clip.len())?;
    let n = crate::raster::check_fragments(frags, faces.len())?;
    check_len("grad_bary", grad_bary.len(), n)?;
    if let Some(gd) = grad_depth {
        check_len("grad_depth", gd.len(), n)?;
    }
    let mut grad = vec![[0.0f64; 4]; clip.len()];
    for (pixel, &f) in frags.face.iter().enumerate() {
        let Ok(f) = usize::try_from(f) else { continue };
        let g = grad_bary[pixel].map(f64::from);
        let gd = grad_depth.map_or(0.0, |d| f64::from(d[pixel]));
        if g == [0.0; 3] && gd == 0.0 {
            continue;
        }
        let col = (pixel % frags.width) as f64;
        let row = (pixel / frags.width) as f64;
        let p = 2.0 * (col + 0.5) / frags.width as f64 - 1.0;
        let q = 2.0 * (row + 0.5) / frags.height as f64 - 1.0;
        let face = faces[f];
        let c = face.map(|i| clip[i as usize].map(f64::from));
        if let Some(dc) = pixel_grad(&c, p, q, g, gd) {
            for (k, &vi) in face.iter().enumerate() {
                for a in 0..4 {
                    grad[vi as usize][a] += dc[k][a];
                }
            }
        }
    }
    Ok(grad.into_iter().map(|g| g.map(|x| x as f32)).collect())
}

/// Gradient w.r.t. the three clip vertices `c` for one pixel centre at NDC `(p, q)`.
fn pixel_grad(c: &[[f64; 4]; 3], p: f64, q: f64, g: [f64; 3], gd: f64) -> Option<[[f64; 4]; 3]> {
    let m = [
        c.map(|v| v[0] - p * v[3]),
        c.map(|v| v[1] - q * v[3]),
        [1.0; 3],
    ];
    let inv = inverse3(&m)?;
    // b = M^-1 e3: the last column of the inverse.
    let b = [inv[0][2], inv[1][2], inv[2][2]];
    let mut g = g;
    let mut out = [[0.0; 4]; 3];
    if gd != 0.0 {
        let den: f64 = (0..3).map(|j| b[j] * c[j][3]).sum();
        let num: f64 = (0..3).map(|j| b[j] * c[j][2]).sum();
        let d = num / den;
        for j in 0..3 {
            g[j] += gd * (c[j][2] - d * c[j][3]) / den;
            out[j][2] += gd * b[j] / den;
            out[j][3] -= gd * d * b[j] / den;
        }
    }
    // u = M^-T g.
    let u: [f64; 3] = std::array::from_fn(|r| (0..3).map(|k| inv[k][r] * g[k]).sum());
    for j in 0..3 {
        out[j][0] -= u[0] * b[j];
        out[j][1] -= u[1] * b[j];
        out[j][3] += (p * u[0] + q * u[1]) * b[j];
    }
    let finite = out.iter().flatten().all(|x| x.is_finite());
    finite.then_some(out)
}

/// Inverse of a 3x3 matrix by the adjugate; `None` when singular.
fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    (det != 0.0 && det.is_finite()).then(|| adj.map(|row| row.map(|x| x / det)))
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::inverse3;

    #[test]
    fn inverse3_times_matrix_is_identity() {
        let m = [[2.0, -1.0, 0.5], [0.3, 4.0, -2.0], [1.0, 1.0, 1.0]];
        let inv = inverse3(&m).expect("invertible");
        for r in 0..3 {
            for c in 0..3 {
                let v: f64 = (0..3).map(|k| m[r][k] * inv[k][c]).sum();
                let want = if r == c { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 1e-12, "({r},{c}) = {v}");
            }
        }
        assert!(inverse3(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [1.0, 1.0, 1.0]]).is_none());
    }
}
