//! Bilinear texture sampling and its backward pass.
//!
//! Matches the BiTT reference, which samples with PyTorch
//! `grid_sample(mode='bilinear', padding_mode='border', align_corners=True)` at the normalized
//! grid position `(x, y) = (2u - 1, 1 - 2v)`:
//!
//! * the texture image is `[C, Ht, Wt]` channel-major with **row 0 the top image row**;
//! * `v = 0` is the **bottom** row: the continuous texel position is
//!   `col = u (Wt - 1)`, `row = (1 - v) (Ht - 1)`, so `(u, v) = (0, 0)` is the centre of the
//!   bottom-left texel and `(1, 1)` that of the top-right one;
//! * border padding clamps `col` to `[0, Wt - 1]` and `row` to `[0, Ht - 1]`; as in PyTorch the
//!   gradient w.r.t. a coordinate is zero when it is clamped, **including exactly on the
//!   border** (`col <= 0` or `col >= Wt - 1`);
//! * at an interior integer position the lower texel is the base one (`floor`), so the uv
//!   gradient there is the one-sided derivative towards the next texel, as in PyTorch.
//!
//! Outputs are pixel-major (`out[p * C + c]`) so they compose with [`crate::cpu::interpolate`]'s
//! `[H * W * A]` output (interpolate 2-channel UVs, then sample). Arithmetic is `f64`
//! internally.

use crate::error::{RenderError, check_image, check_len};
use crate::raster::Fragments;

/// Per-pixel mask of the pixels a [`Fragments`] buffer covers (`face >= 0`), for the `mask`
/// argument of [`texture`] / [`texture_backward`].
pub fn coverage_mask(frags: &Fragments) -> Vec<bool> {
    frags.face.iter().map(|&f| f >= 0).collect()
}

/// Bilinear footprint of one sample along one axis.
#[derive(Debug, Clone, Copy)]
struct Axis {
    /// Lower texel index.
    i0: usize,
    /// Upper texel index (`i0 + 1`, or `i0` on a one-texel axis).
    i1: usize,
    /// Weight of the upper texel, in `[0, 1]`.
    f: f64,
    /// d(clamped position)/d(unclamped position): 1 strictly inside, 0 when clamped.
    clip_grad: f64,
}

impl Axis {
    /// Footprint of the unclamped continuous position `pos` on an axis of `n >= 1` texels.
    fn new(pos: f64, n: usize) -> Self {
        let max = (n - 1) as f64;
        let (pos, clip_grad) = if pos <= 0.0 {
            (0.0, 0.0)
        } else if pos >= max {
            (max, 0.0)
        } else {
            (pos, 1.0)
        };
        if n == 1 {
            return Self {
                i0: 0,
                i1: 0,
                f: 0.0,
                clip_grad,
            };
        }
        // `pos` is in [0, n - 1]; keep i0 <= n - 2 so that i1 is in range (f = 1 at the end).
        let i0 = (pos.floor() as usize).min(n - 2);
        Self {
            i0,
            i1: i0 + 1,
            f: pos - i0 as f64,
            clip_grad,
        }
    }
}

/// Validated texture geometry.
struct Tex {
    channels: usize,
    height: usize,
    width: usize,
    /// Texels per channel.
    plane: usize,
}

impl Tex {
    fn new(
        image: &[f32],
        channels: usize,
        height: usize,
        width: usize,
    ) -> Result<Self, RenderError> {
        let plane = check_image(width, height)?;
        if channels == 0 {
            return Err(RenderError::ZeroChannels);
        }
        let expected = plane
            .checked_mul(channels)
            .ok_or(RenderError::ImageTooLarge { width, height })?;
        check_len("image", image.len(), expected)?;
        Ok(Self {
            channels,
            height,
            width,
            plane,
        })
    }

    /// Footprint (columns, rows) of texture coordinate `uv`.
    fn footprint(&self, uv: [f32; 2]) -> (Axis, Axis) {
        let col = f64::from(uv[0]) * (self.width - 1) as f64;
        let row = (1.0 - f64::from(uv[1])) * (self.height - 1) as f64;
        (Axis::new(col, self.width), Axis::new(row, self.height))
    }

    /// The four texel values `(v00, v01, v10, v11)` (row, col) of channel `c`.
    fn corners(&self, image: &[f32], c: usize, x: &Axis, y: &Axis) -> [f64; 4] {
        let base = c * self.plane;
        let at = |r: usize, col: usize| f64::from(image[base + r * self.width + col]);
        [
            at(y.i0, x.i0),
            at(y.i0, x.i1),
            at(y.i1, x.i0),
            at(y.i1, x.i1),
        ]
    }
}

/// Validates `uv`, `mask` and returns the pixel count; non-finite uvs are rejected only at
/// pixels that are sampled.
fn check_uv(uv: &[[f32; 2]], mask: Option<&[bool]>) -> Result<usize, RenderError> {
    let n = uv.len();
    if let Some(m) = mask {
        check_len("mask", m.len(), n)?;
    }
    for (pixel, value) in uv.iter().enumerate() {
        if is_sampled(mask, pixel) && !value.iter().all(|x| x.is_finite()) {
            return Err(RenderError::NonFiniteUv {
                pixel,
                value: *value,
            });
        }
    }
    Ok(n)
}

fn is_sampled(mask: Option<&[bool]>, pixel: usize) -> bool {
    mask.is_none_or(|m| m[pixel])
}

/// Bilinear texture lookup with border padding, like PyTorch `grid_sample(mode='bilinear',
/// padding_mode='border', align_corners=True)` at `(x, y) = (2u - 1, 1 - 2v)`: the texel
/// position is `col = u (Wt - 1)`, `row = (1 - v) (Ht - 1)` (**`v = 0` is the bottom row**,
/// `(0, 0)` the bottom-left texel centre, `(1, 1)` the top-right one), clamped to the image.
///
/// # Shapes
/// `image` `[C * Ht * Wt]` (channel-major, row 0 at the top), `uv` `[P][2]`, optional `mask`
/// `[P]` (e.g. [`coverage_mask`]) → `[P * C]` pixel-major (`out[p * C + c]`), zero where the
/// mask is `false`.
///
/// # Errors
/// Zero-size or too large texture, zero channels, `image` / `mask` of the wrong length, or a
/// non-finite uv at a sampled pixel.
pub fn texture(
    image: &[f32],
    channels: usize,
    tex_height: usize,
    tex_width: usize,
    uv: &[[f32; 2]],
    mask: Option<&[bool]>,
) -> Result<Vec<f32>, RenderError> {
    let tex = Tex::new(image, channels, tex_height, tex_width)?;
    let n = check_uv(uv, mask)?;
    let ch = tex.channels;
    let mut out = vec![0.0f32; n * ch];
    for (pixel, &t) in uv.iter().enumerate() {
        if !is_sampled(mask, pixel) {
            continue;
        }
        let (x, y) = tex.footprint(t);
        for (c, o) in out[pixel * ch..(pixel + 1) * ch].iter_mut().enumerate() {
            let [v00, v01, v10, v11] = tex.corners(image, c, &x, &y);
            let top = v00 + x.f * (v01 - v00);
            let bottom = v10 + x.f * (v11 - v10);
            *o = (top + y.f * (bottom - top)) as f32;
        }
    }
    Ok(out)
}

/// Backward of [`texture`]: from `dL/dout` (`[P * C]`, pixel-major) returns
/// `(dL/dimage [C * Ht * Wt], dL/duv [P][2])`. Masked-out pixels contribute nothing and get a
/// zero uv gradient. As in PyTorch, the uv gradient is zero along a clamped direction,
/// including exactly on the border (`col <= 0`, `col >= Wt - 1`, likewise rows), and at an
/// interior texel boundary it is the one-sided derivative towards the next texel (`floor`).
///
/// # Errors
/// As [`texture`], plus `grad_out` not of length `P * C`.
pub fn texture_backward(
    image: &[f32],
    channels: usize,
    tex_height: usize,
    tex_width: usize,
    uv: &[[f32; 2]],
    mask: Option<&[bool]>,
    grad_out: &[f32],
) -> Result<(Vec<f32>, Vec<[f32; 2]>), RenderError> {
    let tex = Tex::new(image, channels, tex_height, tex_width)?;
    let n = check_uv(uv, mask)?;
    let ch = tex.channels;
    check_len("grad_out", grad_out.len(), n * ch)?;
    let mut grad_image = vec![0.0f32; image.len()];
    let mut grad_uv = vec![[0.0f32; 2]; n];
    let du_dcol = (tex.width - 1) as f64;
    let dv_drow = -((tex.height - 1) as f64);
    for (pixel, &t) in uv.iter().enumerate() {
        if !is_sampled(mask, pixel) {
            continue;
        }
        let (x, y) = tex.footprint(t);
        let weights = [
            (1.0 - y.f) * (1.0 - x.f),
            (1.0 - y.f) * x.f,
            y.f * (1.0 - x.f),
            y.f * x.f,
        ];
        let (mut g_col, mut g_row) = (0.0f64, 0.0f64);
        for (c, &g) in grad_out[pixel * ch..(pixel + 1) * ch].iter().enumerate() {
            let g = f64::from(g);
            let [v00, v01, v10, v11] = tex.corners(image, c, &x, &y);
            g_col += g * ((1.0 - y.f) * (v01 - v00) + y.f * (v11 - v10));
            g_row += g * ((1.0 - x.f) * (v10 - v00) + x.f * (v11 - v01));
            let base = c * tex.plane;
            let idx = [
                base + y.i0 * tex.width + x.i0,
                base + y.i0 * tex.width + x.i1,
                base + y.i1 * tex.width + x.i0,
                base + y.i1 * tex.width + x.i1,
            ];
            // Sequential accumulation: on one-texel axes the indices coincide.
            for (&i, &w) in idx.iter().zip(&weights) {
                grad_image[i] += (w * g) as f32;
            }
        }
        grad_uv[pixel] = [
            (g_col * x.clip_grad * du_dcol) as f32,
            (g_row * y.clip_grad * dv_drow) as f32,
        ];
    }
    Ok((grad_image, grad_uv))
}
