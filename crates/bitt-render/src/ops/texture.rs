//! [`texture`]: bilinear sampling with the reference's conventions.

use burn::tensor::{Int, Tensor};

use super::check_shape;
use crate::error::RenderError;

/// Samples a texture bilinearly at per-sample UVs, like the BiTT reference's
/// `grid_sample(mode='bilinear', padding_mode='border', align_corners=True)` with `v = 0` at
/// the texture's bottom row (the conventions of [`crate::cpu::texture`]): the continuous texel
/// position is `col = u (Wt - 1)`, `row = (1 - v) (Ht - 1)`, clamped to the texture (border
/// padding).
///
/// Differentiable in the texture and in the UVs (zero UV gradient where a coordinate is
/// clamped). A NaN UV yields NaN samples (its texel lookup is redirected to texel 0 so no
/// index ever leaves the texture).
///
/// # Shapes
/// texture `[C, Ht, Wt]`, uv `[N, 2]` -> `[N, C]`
///
/// # Errors
/// When `uv` is not `[N, 2]` or the texture has no channels.
pub fn texture(image: Tensor<3>, uv: Tensor<2>) -> Result<Tensor<2>, RenderError> {
    let [c, ht, wt] = image.dims();
    if c == 0 {
        return Err(RenderError::ZeroChannels);
    }
    crate::error::check_image(wt, ht)?;
    check_shape("uv", uv.dims(), [None, Some(2)], || "[N, 2]".into())?;
    let n = uv.dims()[0];
    if n == 0 {
        return Ok(Tensor::zeros([0, c], &image.device()));
    }
    let u = uv.clone().slice([0..n, 0..1]).reshape([n]);
    let v = uv.slice([0..n, 1..2]).reshape([n]);
    let x = (u * (wt - 1) as f64).clamp(0.0, (wt - 1) as f64);
    let y = (v.neg() + 1.0) * (ht - 1) as f64;
    let y = y.clamp(0.0, (ht - 1) as f64);
    let (x0, x1, fx) = footprint(x, wt);
    let (y0, y1, fy) = footprint(y, ht);
    let flat = image.reshape([c, ht * wt]);
    let at = |row: &Tensor<1, Int>, col: &Tensor<1, Int>| {
        flat.clone()
            .select(1, row.clone() * wt as i64 + col.clone())
    };
    let (fx, fy) = (fx.reshape([1, n]), fy.reshape([1, n]));
    let top = at(&y0, &x0) * (fx.clone().neg() + 1.0) + at(&y0, &x1) * fx.clone();
    let bottom = at(&y1, &x0) * (fx.clone().neg() + 1.0) + at(&y1, &x1) * fx;
    let out = top * (fy.clone().neg() + 1.0) + bottom * fy;
    Ok(out.swap_dims(0, 1))
}

/// Lower/upper texel indices and the upper weight of clamped positions on an axis of `len`
/// texels. The indices are computed without gradient; the weight keeps the position's.
fn footprint(pos: Tensor<1>, len: usize) -> (Tensor<1, Int>, Tensor<1, Int>, Tensor<1>) {
    if len == 1 {
        let zero = Tensor::<1, Int>::zeros(pos.dims(), &pos.device());
        return (zero.clone(), zero, pos * 0.0);
    }
    let detached = pos.clone().detach();
    let detached = detached.clone().mask_fill(detached.is_nan(), 0.0);
    let base = detached.floor().clamp(0.0, (len - 2) as f64);
    let weight = pos - base.clone();
    let i0 = base.int();
    let i1 = i0.clone() + 1;
    (i0, i1, weight)
}
