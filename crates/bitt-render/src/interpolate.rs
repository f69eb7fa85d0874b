//! Per-pixel attribute interpolation and its backward pass.

use crate::error::{RenderError, check_faces, check_len};
use crate::raster::Fragments;

/// Validates the attribute layout; returns the number of vertices.
fn check_attrs(attrs: &[f32], num_attrs: usize) -> Result<usize, RenderError> {
    if num_attrs == 0 || !attrs.len().is_multiple_of(num_attrs) {
        return Err(RenderError::BadAttributeLayout {
            len: attrs.len(),
            num_attrs,
        });
    }
    Ok(attrs.len() / num_attrs)
}

/// Per-pixel attribute interpolation:
/// `out[p * A + c] = sum_k bary[p][k] * attrs[face[p][k] * A + c]` with `A = num_attrs`
/// channels, zeros where no face. `attrs` is `[V * A]` row-major, the output `[H * W * A]`.
///
/// # Errors
/// `num_attrs` zero or not dividing `attrs.len()`, out-of-range indices, or malformed fragments.
pub fn interpolate(
    attrs: &[f32],
    num_attrs: usize,
    faces: &[[u32; 3]],
    frags: &Fragments,
) -> Result<Vec<f32>, RenderError> {
    let num_vertices = check_attrs(attrs, num_attrs)?;
    check_faces(faces, num_vertices)?;
    let n = crate::raster::check_fragments(frags, faces.len())?;
    let a = num_attrs;
    let mut out = vec![0.0f32; n * a];
    for (pixel, &f) in frags.face.iter().enumerate() {
        let Ok(f) = usize::try_from(f) else { continue };
        let bary = frags.bary[pixel];
        let dst = &mut out[pixel * a..(pixel + 1) * a];
        for (k, &vi) in faces[f].iter().enumerate() {
            let src = &attrs[vi as usize * a..(vi as usize + 1) * a];
            for (d, s) in dst.iter_mut().zip(src) {
                *d += bary[k] * s;
            }
        }
    }
    Ok(out)
}

/// Backward of [`interpolate`]: from `dL/dout` (`[H * W * A]`) returns
/// `(dL/dattrs [V * A], dL/dbary [H * W])`; both are zero where no face is drawn.
///
/// # Errors
/// As [`interpolate`], plus `grad_out` not of length `width * height * num_attrs`.
pub fn interpolate_backward(
    attrs: &[f32],
    num_attrs: usize,
    faces: &[[u32; 3]],
    frags: &Fragments,
    grad_out: &[f32],
) -> Result<(Vec<f32>, Vec<[f32; 3]>), RenderError> {
    let num_vertices = check_attrs(attrs, num_attrs)?;
    check_faces(faces, num_vertices)?;
    let n = crate::raster::check_fragments(frags, faces.len())?;
    let a = num_attrs;
    check_len("grad_out", grad_out.len(), n * a)?;
    let mut grad_attrs = vec![0.0f32; attrs.len()];
    let mut grad_bary = vec![[0.0f32; 3]; n];
    for (pixel, &f) in frags.face.iter().enumerate() {
        let Ok(f) = usize::try_from(f) else { continue };
        let bary = frags.bary[pixel];
        let g = &grad_out[pixel * a..(pixel + 1) * a];
        for (k, &vi) in faces[f].iter().enumerate() {
            let range = vi as usize * a..(vi as usize + 1) * a;
            grad_bary[pixel][k] = attrs[range.clone()].iter().zip(g).map(|(x, y)| x * y).sum();
            for (d, gc) in grad_attrs[range].iter_mut().zip(g) {
                *d += bary[k] * gc;
            }
        }
    }
    Ok((grad_attrs, grad_bary))
}
