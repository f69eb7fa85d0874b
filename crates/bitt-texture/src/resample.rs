//! Resampling a texture PCA onto another layout (HTML's model onto the hands' layout).

use crate::TextureError;
use crate::layout::{TextureLayout, texel_uv, uv_to_texel};
use crate::pca::TexturePca;

/// Resamples a texture PCA onto another layout: each target texel averages the source texels
/// under its footprint in UV space (bilinear taps over the texel's area; the nearest source
/// texel when none is under it). Resampling is linear, so the result is again a PCA model
/// (`mean' + basis' a` is the resampled `mean + basis a`).
pub fn resample_pca(src: &TexturePca, target: &TextureLayout) -> Result<TexturePca, TextureError> {
    let (sw, sh) = (src.layout.width, src.layout.height);
    let (tw, th) = (target.width, target.height);
    let ratio = |s: usize, t: usize| s.saturating_sub(1) as f64 / t.saturating_sub(1).max(1) as f64;
    let (rx, ry) = (ratio(sw, tw), ratio(sh, th));
    let (nx, ny) = (rx.ceil().max(1.0) as usize, ry.ceil().max(1.0) as usize);
    let (ts, tt, k) = (
        src.layout.num_texels(),
        target.num_texels(),
        src.num_components,
    );
    let snap = |x: f64| {
        if (x - x.round()).abs() < 1e-9 {
            x.round()
        } else {
            x
        }
    };
    let mut mean = vec![0f32; 3 * tt];
    let mut basis = vec![0f32; 3 * tt * k];
    let mut weights: Vec<(usize, f64)> = Vec::new();
    let mut acc = vec![0f64; k];
    for (t, &(row, col)) in target.texels.iter().enumerate() {
        let p = uv_to_texel(texel_uv(row as usize, col as usize, tw, th), sw, sh);
        weights.clear();
        for i in 0..ny {
            for j in 0..nx {
                let off = |n: usize, idx: usize, r: f64| {
                    if n == 1 {
                        0.0
                    } else {
                        ((idx as f64 + 0.5) / n as f64 - 0.5) * r
                    }
                };
                let x = snap(p.x + off(nx, j, rx));
                let y = snap(p.y + off(ny, i, ry));
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                for (dy, wy) in [(0.0, 1.0 - fy), (1.0, fy)] {
                    for (dx, wx) in [(0.0, 1.0 - fx), (1.0, fx)] {
                        let w = wx * wy;
                        let (r, c) = (y0 + dy, x0 + dx);
                        if w <= 0.0 || r < 0.0 || c < 0.0 {
                            continue;
                        }
                        if let Some(s) = src.layout.compact_index(r as usize, c as usize) {
                            weights.push((s, w));
                        }
                    }
                }
            }
        }
        if weights.is_empty() {
            // No source texel under the footprint (a gutter texel past the source's charts):
            // the nearest source texel.
            let radius = (4.0 * rx.max(ry)).ceil() as isize + 4;
            let (cx, cy) = (p.x.round() as isize, p.y.round() as isize);
            let mut best: Option<(f64, usize)> = None;
            for dy in -radius..=radius {
                for dx in -radius..=radius {
                    let (r, c) = (cy + dy, cx + dx);
                    if r < 0 || c < 0 {
                        continue;
                    }
                    if let Some(s) = src.layout.compact_index(r as usize, c as usize) {
                        let d = (c as f64 - p.x).powi(2) + (r as f64 - p.y).powi(2);
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, s));
                        }
                    }
                }
            }
            let (_, s) = best.ok_or_else(|| {
                TextureError::Invalid(format!(
                    "texel (row {row}, col {col}) of the {tw}x{th} layout has no texel of the \
                     {sw}x{sh} texture model within {radius} texels: the model does not cover \
                     the hands' UV layout"
                ))
            })?;
            weights.push((s, 1.0));
        }
        let total: f64 = weights.iter().map(|(_, w)| w).sum();
        for c in 0..3 {
            let mut m = 0.0;
            acc.iter_mut().for_each(|a| *a = 0.0);
            for &(s, w) in &weights {
                let w = w / total;
                let row = c * ts + s;
                m += w * f64::from(src.mean[row]);
                for (a, &b) in acc.iter_mut().zip(&src.basis[row * k..(row + 1) * k]) {
                    *a += w * f64::from(b);
                }
            }
            let out = c * tt + t;
            mean[out] = m as f32;
            for (dst, a) in basis[out * k..(out + 1) * k].iter_mut().zip(&acc) {
                *dst = *a as f32;
            }
        }
    }
    TexturePca::new(target.clone(), mean, basis, k, src.scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::procedural_pair;

    fn ramp_pca(layout: TextureLayout, k: usize) -> TexturePca {
        // mean = 100 u + 50 v per channel (plus the channel), basis_j = u^j.
        let t = layout.num_texels();
        let (w, h) = (layout.width, layout.height);
        let mut mean = vec![0f32; 3 * t];
        let mut basis = vec![0f32; 3 * t * k];
        for (i, &(r, c)) in layout.texels.iter().enumerate() {
            let uv = texel_uv(r as usize, c as usize, w, h);
            for ch in 0..3 {
                mean[ch * t + i] = (100.0 * uv.x + 50.0 * uv.y) as f32 + ch as f32;
                for j in 0..k {
                    basis[(ch * t + i) * k + j] = uv.x.powi(j as i32 + 1) as f32;
                }
            }
        }
        TexturePca::new(layout, mean, basis, k, 1.0 / 255.0).unwrap()
    }

    #[test]
    fn resampling_keeps_smooth_models_and_is_exact_at_the_same_size() {
        let uv = procedural_pair().right.uv.unwrap();
        let fine = TextureLayout::from_uv(&uv, 256, 256, 2).unwrap();
        let coarse = TextureLayout::from_uv(&uv, 128, 128, 2).unwrap();
        let src = ramp_pca(fine.clone(), 2);
        // Same layout: identity.
        let same = resample_pca(&src, &fine).unwrap();
        assert_eq!(same.mean, src.mean);
        assert_eq!(same.basis, src.basis);
        // Coarser: the linear ramp is kept inside the charts (up to the footprint).
        let down = resample_pca(&src, &coarse).unwrap();
        assert_eq!(down.layout.num_texels(), coarse.num_texels());
        let expect = ramp_pca(coarse.clone(), 2);
        let t = coarse.num_texels();
        let mut worst = 0f32;
        let mut within = 0usize;
        for i in 0..t {
            let d = (down.mean[i] - expect.mean[i]).abs();
            worst = worst.max(d);
            if d < 0.5 {
                within += 1;
            }
        }
        // Texels inside the charts match to a fraction of a unit (of 0..255); only texels at
        // chart borders (footprint partly outside) may differ more.
        assert!(
            within as f64 > 0.8 * t as f64,
            "{within} of {t} within 0.5 (worst {worst})"
        );
        assert!(worst < 6.0, "{worst}");
        assert!(down.basis.iter().all(|x| x.is_finite()));
    }
}
