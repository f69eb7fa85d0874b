//! Image metrics on `[C, H, W]` images in `[0, 1]`: L1, PSNR, SSIM and MS-SSIM as
//! `pytorch_msssim` defines them (Gaussian window 11, sigma 1.5, K1 0.01, K2 0.03, data range
//! 1, valid convolution, mean over channels and positions).

/// The image metrics of one pair.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImageMetrics {
    /// Mean absolute difference.
    pub l1: f64,
    /// Peak signal-to-noise ratio (dB), data range 1.
    pub psnr: f64,
    /// Structural similarity.
    pub ssim: f64,
    /// Multi-scale SSIM (5 scales); `None` for images smaller than 161 pixels per side, where
    /// the standard definition does not apply.
    pub ms_ssim: Option<f64>,
}

/// Gaussian window size and sigma of SSIM.
const WIN: usize = 11;
const SIGMA: f64 = 1.5;
/// MS-SSIM scale weights (Wang et al. 2003, as `pytorch_msssim`).
const MS_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// All metrics of `a` against `b`, both `[c, h, w]` channel-major.
///
/// # Panics
/// When the lengths differ from `c * h * w`.
pub fn image_metrics(a: &[f32], b: &[f32], [c, h, w]: [usize; 3]) -> ImageMetrics {
    assert_eq!(a.len(), c * h * w);
    assert_eq!(b.len(), c * h * w);
    let n = a.len().max(1) as f64;
    let l1 = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from((x - y).abs()))
        .sum::<f64>()
        / n;
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from(x - y).powi(2))
        .sum::<f64>()
        / n;
    let psnr = if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    };
    let a64: Vec<f64> = a.iter().map(|&v| f64::from(v)).collect();
    let b64: Vec<f64> = b.iter().map(|&v| f64::from(v)).collect();
    let (ssim, _) = ssim_cs(&a64, &b64, c, h, w);
    let ms_ssim = (h.min(w) > (WIN - 1) * 16).then(|| ms_ssim(&a64, &b64, c, h, w));
    ImageMetrics {
        l1,
        psnr,
        ssim,
        ms_ssim,
    }
}

fn gaussian() -> [f64; WIN] {
    let mut g = [0.0; WIN];
    let half = (WIN / 2) as f64;
    for (i, v) in g.iter_mut().enumerate() {
        let x = i as f64 - half;
        *v = (-(x * x) / (2.0 * SIGMA * SIGMA)).exp();
    }
    let s: f64 = g.iter().sum();
    g.map(|v| v / s)
}

/// Separable valid Gaussian filter of one `h x w` plane -> `(h-10) x (w-10)`.
fn filter(plane: &[f64], h: usize, w: usize, g: &[f64; WIN]) -> Vec<f64> {
    let (oh, ow) = (h + 1 - WIN, w + 1 - WIN);
    let mut rows = vec![0.0; h * ow];
    for r in 0..h {
        for c in 0..ow {
            rows[r * ow + c] = (0..WIN).map(|k| g[k] * plane[r * w + c + k]).sum();
        }
    }
    let mut out = vec![0.0; oh * ow];
    for r in 0..oh {
        for c in 0..ow {
            out[r * ow + c] = (0..WIN).map(|k| g[k] * rows[(r + k) * ow + c]).sum();
        }
    }
    out
}

/// Mean SSIM and mean contrast-structure term over channels.
fn ssim_cs(a: &[f64], b: &[f64], c: usize, h: usize, w: usize) -> (f64, f64) {
    if h < WIN || w < WIN {
        return (f64::NAN, f64::NAN);
    }
    let g = gaussian();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let hw = h * w;
    let (mut ssim, mut cs) = (0.0, 0.0);
    for ch in 0..c {
        let x = &a[ch * hw..(ch + 1) * hw];
        let y = &b[ch * hw..(ch + 1) * hw];
        let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
        let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
        let xy: Vec<f64> = x.iter().zip(y).map(|(p, q)| p * q).collect();
        let (mx, my) = (filter(x, h, w, &g), filter(y, h, w, &g));
        let (sxx, syy, sxy) = (
            filter(&xx, h, w, &g),
            filter(&yy, h, w, &g),
            filter(&xy, h, w, &g),
        );
        let m = mx.len() as f64;
        let (mut s_sum, mut cs_sum) = (0.0, 0.0);
        for i in 0..mx.len() {
            let (ux, uy) = (mx[i], my[i]);
            let vx = sxx[i] - ux * ux;
            let vy = syy[i] - uy * uy;
            let cov = sxy[i] - ux * uy;
            let cs_i = (2.0 * cov + c2) / (vx + vy + c2);
            cs_sum += cs_i;
            s_sum += (2.0 * ux * uy + c1) / (ux * ux + uy * uy + c1) * cs_i;
        }
        ssim += s_sum / m;
        cs += cs_sum / m;
    }
    (ssim / c as f64, cs / c as f64)
}

/// 2x2 average pooling (floor), per channel.
fn pool(a: &[f64], c: usize, h: usize, w: usize) -> (Vec<f64>, usize, usize) {
    let (oh, ow) = (h / 2, w / 2);
    let mut out = Vec::with_capacity(c * oh * ow);
    for ch in 0..c {
        let p = &a[ch * h * w..];
        for r in 0..oh {
            for col in 0..ow {
                let i = 2 * r * w + 2 * col;
                out.push((p[i] + p[i + 1] + p[i + w] + p[i + w + 1]) / 4.0);
            }
        }
    }
    (out, oh, ow)
}

fn ms_ssim(a: &[f64], b: &[f64], c: usize, h: usize, w: usize) -> f64 {
    let (mut a, mut b, mut h, mut w) = (a.to_vec(), b.to_vec(), h, w);
    let mut result = 1.0;
    for (level, weight) in MS_WEIGHTS.iter().enumerate() {
        let (s, cs) = ssim_cs(&a, &b, c, h, w);
        if level + 1 == MS_WEIGHTS.len() {
            result *= s.max(0.0).powf(*weight);
        } else {
            result *= cs.max(0.0).powf(*weight);
            let (pa, nh, nw) = pool(&a, c, h, w);
            let (pb, _, _) = pool(&b, c, h, w);
            (a, b, h, w) = (pa, pb, nh, nw);
        }
    }
    result
}

/// Mean absolute difference of two compact textures `[3, T]` over the texels where `select`
/// is true (`None` when none is).
pub fn texel_l1(a: &[f32], b: &[f32], select: &[bool]) -> Option<f64> {
    let t = select.len();
    let (mut sum, mut n) = (0.0, 0usize);
    for ch in 0..3 {
        for (k, &s) in select.iter().enumerate() {
            if s {
                sum += f64::from((a[ch * t + k] - b[ch * t + k]).abs());
                n += 1;
            }
        }
    }
    (n > 0).then(|| sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(c: usize, h: usize, w: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
        let mut v = Vec::with_capacity(c * h * w);
        for ch in 0..c {
            for r in 0..h {
                for col in 0..w {
                    v.push(f(ch, r, col));
                }
            }
        }
        v
    }

    #[test]
    fn identical_images_are_perfect() {
        let a = ramp(3, 32, 32, |c, r, k| {
            ((c + r * 3 + k * 7) % 17) as f32 / 17.0
        });
        let m = image_metrics(&a, &a, [3, 32, 32]);
        assert_eq!(m.l1, 0.0);
        assert!(m.psnr.is_infinite());
        assert!((m.ssim - 1.0).abs() < 1e-12);
        assert!(m.ms_ssim.is_none());
    }

    #[test]
    fn psnr_and_l1_of_a_constant_offset() {
        let a = ramp(3, 16, 16, |_, _, _| 0.5);
        let b = ramp(3, 16, 16, |_, _, _| 0.6);
        let m = image_metrics(&a, &b, [3, 16, 16]);
        assert!((m.l1 - 0.1).abs() < 1e-6);
        assert!((m.psnr - 20.0).abs() < 1e-4, "{}", m.psnr);
        // Constant images: SSIM = (2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1).
        let want = (2.0 * 0.5 * 0.6 + 1e-4) / (0.25 + 0.36 + 1e-4);
        assert!((m.ssim - want).abs() < 1e-5, "{} vs {want}", m.ssim);
    }

    #[test]
    fn ms_ssim_is_defined_from_161_pixels_and_falls_with_noise() {
        let a = ramp(1, 176, 176, |_, r, k| ((r / 8 + k / 8) % 2) as f32);
        let b = ramp(1, 176, 176, |_, r, k| {
            let v = ((r / 8 + k / 8) % 2) as f32;
            v * 0.8 + 0.1 * (((r * 31 + k * 17) % 7) as f32 / 7.0)
        });
        let same = image_metrics(&a, &a, [1, 176, 176]);
        assert!((same.ms_ssim.unwrap() - 1.0).abs() < 1e-9);
        let m = image_metrics(&a, &b, [1, 176, 176]);
        let ms = m.ms_ssim.unwrap();
        assert!(ms > 0.0 && ms < 1.0, "{ms}");
    }

    #[test]
    fn texel_l1_uses_only_selected_texels() {
        let a = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0];
        let b = [0.5, 1.0, 0.5, 1.0, 0.5, 1.0];
        assert_eq!(texel_l1(&a, &b, &[true, false]), Some(0.5));
        assert_eq!(texel_l1(&a, &b, &[false, true]), Some(0.0));
        assert_eq!(texel_l1(&a, &b, &[false, false]), None);
    }
}
