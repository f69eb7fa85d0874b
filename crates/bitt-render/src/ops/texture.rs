//! [`texture`]: bilinear sampling with the reference's conventions, and [`TexturePlan`], its
//! UV-dependent part prepared once for UVs that do not change (fixed geometry).

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
    let [_, ht, wt] = image.dims();
    TexturePlan::new(uv, ht, wt)?.sample(image)
}

/// The part of [`texture`] that depends only on the UVs and the texture's size: the four
/// texel indices around every sample and the bilinear weights (which keep the UVs'
/// gradient). Made once, it samples any number of textures of that size at the same UVs,
/// as a training step does for every render of a fixed geometry.
#[derive(Debug, Clone)]
pub struct TexturePlan {
    height: usize,
    width: usize,
    samples: usize,
    /// Flat texel indices `row * Wt + col` of the corners (y0 x0, y0 x1, y1 x0, y1 x1).
    corners: [Tensor<1, Int>; 4],
    /// Upper weights along x and y, `[1, N]` each.
    fx: Tensor<2>,
    fy: Tensor<2>,
}

impl TexturePlan {
    /// Prepares sampling a `height x width` texture at `uv` (see [`texture`]).
    ///
    /// # Shapes
    /// uv `[N, 2]`
    ///
    /// # Errors
    /// When `uv` is not `[N, 2]` or the size is zero or too large.
    pub fn new(uv: Tensor<2>, height: usize, width: usize) -> Result<Self, RenderError> {
        crate::error::check_image(width, height)?;
        check_shape("uv", uv.dims(), [None, Some(2)], || "[N, 2]".into())?;
        let n = uv.dims()[0];
        let device = uv.device();
        if n == 0 {
            let none = Tensor::<1, Int>::zeros([0], &device);
            return Ok(Self {
                height,
                width,
                samples: 0,
                corners: [none.clone(), none.clone(), none.clone(), none],
                fx: Tensor::zeros([1, 0], &device),
                fy: Tensor::zeros([1, 0], &device),
            });
        }
        let u = uv.clone().slice([0..n, 0..1]).reshape([n]);
        let v = uv.slice([0..n, 1..2]).reshape([n]);
        let x = (u * (width - 1) as f64).clamp(0.0, (width - 1) as f64);
        let y = (v.neg() + 1.0) * (height - 1) as f64;
        let y = y.clamp(0.0, (height - 1) as f64);
        let (x0, x1, fx) = footprint(x, width);
        let (y0, y1, fy) = footprint(y, height);
        let at =
            |row: &Tensor<1, Int>, col: &Tensor<1, Int>| row.clone() * width as i64 + col.clone();
        Ok(Self {
            height,
            width,
            samples: n,
            corners: [at(&y0, &x0), at(&y0, &x1), at(&y1, &x0), at(&y1, &x1)],
            fx: fx.reshape([1, n]),
            fy: fy.reshape([1, n]),
        })
    }

    /// Number of samples `N`.
    pub fn num_samples(&self) -> usize {
        self.samples
    }

    /// The same samples (corners and weights) of a texture stored as a table of texels:
    /// `columns` `[Ht Wt]` gives, for every texel of the plan's texture (row-major), the
    /// column of a `[C, K]` table that holds its value. The plan returned samples such tables
    /// given as `[C, 1, K]` images, with the values [`TexturePlan::sample`] gives on the
    /// texture the table stands for: a texture that is mostly unused (a UV layout's compact
    /// texels) is then never expanded to its full size, and the gradient of a sample is
    /// scattered into `K` texels rather than `Ht Wt`.
    ///
    /// # Shapes
    /// columns `[Ht * Wt]`, values in `0..K`
    ///
    /// # Errors
    /// `columns` of another length than the plan's texture, or `K = 0`.
    pub fn through_columns(
        &self,
        columns: &Tensor<1, Int>,
        table_len: usize,
    ) -> Result<Self, RenderError> {
        let want = self.height * self.width;
        check_shape("texel columns", columns.dims(), [Some(want)], || {
            format!("[{want}] (one per texel of the plan's texture)")
        })?;
        crate::error::check_image(table_len, 1)?;
        let at = |k: usize| columns.clone().select(0, self.corners[k].clone());
        Ok(Self {
            height: 1,
            width: table_len,
            samples: self.samples,
            corners: [at(0), at(1), at(2), at(3)],
            fx: self.fx.clone(),
            fy: self.fy.clone(),
        })
    }

    /// Samples `image` at the plan's UVs; differentiable in the image (and in the UVs the
    /// plan was made from, through its weights).
    ///
    /// # Shapes
    /// image `[C, Ht, Wt]` -> `[N, C]`
    ///
    /// # Errors
    /// An image of another size than the plan's, or with no channels.
    pub fn sample(&self, image: Tensor<3>) -> Result<Tensor<2>, RenderError> {
        let [c, ht, wt] = image.dims();
        if c == 0 {
            return Err(RenderError::ZeroChannels);
        }
        check_shape(
            "texture",
            [c, ht, wt],
            [None, Some(self.height), Some(self.width)],
            || {
                format!(
                    "[C, {}, {}] (the plan's texture size)",
                    self.height, self.width
                )
            },
        )?;
        let n = self.samples;
        if n == 0 {
            return Ok(Tensor::zeros([0, c], &image.device()));
        }
        let flat = image.reshape([c, ht * wt]);
        let at = |k: usize| flat.clone().select(1, self.corners[k].clone());
        let (fx, fy) = (self.fx.clone(), self.fy.clone());
        let top = at(0) * (fx.clone().neg() + 1.0) + at(1) * fx.clone();
        let bottom = at(2) * (fx.clone().neg() + 1.0) + at(3) * fx;
        let out = top * (fy.clone().neg() + 1.0) + bottom * fy;
        Ok(out.swap_dims(0, 1))
    }
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
