//! Image metrics on `[C, H, W]` images in `[0, 1]`: L1, PSNR, SSIM and MS-SSIM.
//!
//! SSIM and MS-SSIM follow `pytorch_msssim` (the package BiTT's reference code evaluates
//! with): Gaussian window 11, sigma 1.5, K1 0.01, K2 0.03, data range 1, "valid" filtering
//! (no padding), mean over positions, then over channels; MS-SSIM uses 5 scales with the
//! weights of Wang et al. 2003, 2x2 average pooling that zero-pads odd sizes (as
//! `avg_pool2d(kernel_size=2, padding=size % 2)`), the product over scales per channel and
//! then the mean over channels. scikit-image's `structural_similarity(gaussian_weights=True,
//! sigma=1.5, use_sample_covariance=False, data_range=1, channel_axis=0)` computes the same
//! SSIM except for one detail: `pytorch_msssim` builds its Gaussian window in float32, whose
//! weights sum to `1 - 3.1e-8`, which shifts SSIM by a few `1e-6`. [`SsimWindow`] selects
//! either; everything here computes in `f64`. See docs/evaluation.md for the reference values
//! the tests compare against (crates/bitt-eval/tests-data/metrics_reference.py).

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
    /// LPIPS-VGG; `None` when no LPIPS weights were given (never estimated). Filled in by the
    /// callers that hold an [`crate::lpips::LpipsVgg`].
    #[serde(default)]
    pub lpips: Option<f64>,
}

/// Gaussian window size and sigma of SSIM.
const WIN: usize = 11;
const SIGMA: f64 = 1.5;
/// MS-SSIM scale weights (Wang et al. 2003, as `pytorch_msssim`).
const MS_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];
/// The smallest image side MS-SSIM accepts: `pytorch_msssim` asserts `min(h, w) > 160`
/// (`(WIN - 1) * 2^4`), so that the coarsest scale still holds a whole window.
pub(crate) const MS_SSIM_MIN_SIDE: usize = (WIN - 1) * 16 + 1;
/// `pytorch_msssim`'s window (`_fspecial_gauss_1d(11, 1.5)`, float32), as bits.
const PYTORCH_WINDOW_BITS: [u32; WIN] = [
    0x3a86_cab8,
    0x3bf8_ff01,
    0x3d13_758c,
    0x3ddf_f87f,
    0x3e5a_1e1f,
    0x3e88_32b0,
    0x3e5a_1e1f,
    0x3ddf_f87f,
    0x3d13_758c,
    0x3bf8_ff01,
    0x3a86_cab8,
];

/// Which 1-D Gaussian window SSIM and MS-SSIM filter with (11 taps, sigma 1.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SsimWindow {
    /// The window `pytorch_msssim` builds: computed and normalised in float32, so its weights
    /// sum to `1 - 3.1e-8`. Matches `pytorch_msssim.ssim` / `ms_ssim` (BiTT's reference
    /// evaluation, and so the paper's tables); SSIM differs from [`SsimWindow::Exact`] by a few
    /// `1e-6`.
    #[default]
    PytorchMsssim,
    /// The exact normalised Gaussian in `f64`, as scikit-image's `structural_similarity`
    /// (`gaussian_weights=True`, `sigma=1.5`, `use_sample_covariance=False`) and
    /// `scipy.ndimage.gaussian_filter(truncate=3.5)` use.
    Exact,
}

impl SsimWindow {
    fn weights(self) -> [f64; WIN] {
        match self {
            SsimWindow::PytorchMsssim => PYTORCH_WINDOW_BITS.map(|b| f64::from(f32::from_bits(b))),
            SsimWindow::Exact => {
                let mut g = [0.0; WIN];
                let half = (WIN / 2) as f64;
                for (i, v) in g.iter_mut().enumerate() {
                    let x = i as f64 - half;
                    *v = (-(x * x) / (2.0 * SIGMA * SIGMA)).exp();
                }
                let s: f64 = g.iter().sum();
                g.map(|v| v / s)
            }
        }
    }
}

/// All metrics of `a` against `b`, both `[c, h, w]` channel-major, SSIM and MS-SSIM with
/// `pytorch_msssim`'s window ([`SsimWindow::PytorchMsssim`]).
///
/// `ssim` is NaN for images smaller than 11 pixels on a side, `ms_ssim` is `None` below
/// [`MS_SSIM_MIN_SIDE`] pixels.
///
/// # Panics
/// When the lengths differ from `c * h * w`.
pub fn image_metrics(a: &[f32], b: &[f32], dims: [usize; 3]) -> ImageMetrics {
    image_metrics_with(a, b, dims, SsimWindow::PytorchMsssim)
}

/// [`image_metrics`] with a chosen SSIM window.
///
/// # Panics
/// When the lengths differ from `c * h * w`.
pub(crate) fn image_metrics_with(
    a: &[f32],
    b: &[f32],
    [c, h, w]: [usize; 3],
    window: SsimWindow,
) -> ImageMetrics {
    assert_eq!(a.len(), c * h * w);
    assert_eq!(b.len(), c * h * w);
    let (l1, mse) = l1_mse(a.iter().zip(b).map(|(&x, &y)| (x, y)));
    ImageMetrics {
        l1,
        psnr: psnr_of_mse(mse),
        ssim: ssim(a, b, [c, h, w], window).unwrap_or(f64::NAN),
        ms_ssim: ms_ssim(a, b, [c, h, w], window),
        lpips: None,
    }
}

/// The metrics of `a` against `b` restricted to a mask `[h, w]` (a pixel counts when its mask
/// value is at least 0.5; the mask applies to every channel).
///
/// - L1 and PSNR: the mean absolute / squared difference over the masked pixels only
///   (all channels), so the background does not dilute them.
/// - SSIM and MS-SSIM: of both images multiplied by the (binarised) mask, i.e. with the
///   background set to black in both. Windowed statistics need whole images; this is how
///   BiTT's reference evaluates rendered hands (hand renders on a black background against
///   the input image times the hand mask).
///
/// `None` when no pixel is masked.
///
/// # Panics
/// When the lengths differ from `c * h * w` (images) or `h * w` (mask).
pub fn masked_image_metrics(
    a: &[f32],
    b: &[f32],
    mask: &[f32],
    [c, h, w]: [usize; 3],
    window: SsimWindow,
) -> Option<ImageMetrics> {
    assert_eq!(a.len(), c * h * w);
    assert_eq!(b.len(), c * h * w);
    assert_eq!(mask.len(), h * w);
    let keep: Vec<bool> = mask.iter().map(|&m| m >= 0.5).collect();
    if !keep.iter().any(|&k| k) {
        return None;
    }
    let hw = h * w;
    let pairs = (0..c * hw).filter(|i| keep[i % hw]).map(|i| (a[i], b[i]));
    let (l1, mse) = l1_mse(pairs);
    let am = apply_mask(a, mask, [c, h, w]);
    let bm = apply_mask(b, mask, [c, h, w]);
    Some(ImageMetrics {
        l1,
        psnr: psnr_of_mse(mse),
        ssim: ssim(&am, &bm, [c, h, w], window).unwrap_or(f64::NAN),
        ms_ssim: ms_ssim(&am, &bm, [c, h, w], window),
        lpips: None,
    })
}

/// `image` `[c, h, w]` with the pixels whose mask value is below 0.5 set to 0.
///
/// # Panics
/// When the lengths differ from `c * h * w` (image) or `h * w` (mask).
pub(crate) fn apply_mask(image: &[f32], mask: &[f32], [c, h, w]: [usize; 3]) -> Vec<f32> {
    assert_eq!(image.len(), c * h * w);
    assert_eq!(mask.len(), h * w);
    image
        .iter()
        .enumerate()
        .map(|(i, &v)| if mask[i % (h * w)] >= 0.5 { v } else { 0.0 })
        .collect()
}

/// Mean absolute and mean squared difference (`(0, 0)` for no pairs).
fn l1_mse(pairs: impl Iterator<Item = (f32, f32)>) -> (f64, f64) {
    let (mut abs, mut sq, mut n) = (0.0, 0.0, 0usize);
    for (x, y) in pairs {
        let d = f64::from(x) - f64::from(y);
        abs += d.abs();
        sq += d * d;
        n += 1;
    }
    let n = n.max(1) as f64;
    (abs / n, sq / n)
}

/// PSNR (dB) at data range 1: `-10 log10(mse)`, infinite for identical images.
fn psnr_of_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// SSIM of `a` against `b` (`[c, h, w]`), the mean over channels of the mean over valid
/// window positions; `None` when a side is smaller than 11 pixels.
///
/// # Panics
/// When the lengths differ from `c * h * w`.
pub fn ssim(a: &[f32], b: &[f32], [c, h, w]: [usize; 3], window: SsimWindow) -> Option<f64> {
    assert_eq!(a.len(), c * h * w);
    assert_eq!(b.len(), c * h * w);
    if h < WIN || w < WIN || c == 0 {
        return None;
    }
    let g = window.weights();
    let hw = h * w;
    let mut sum = 0.0;
    for ch in 0..c {
        let x = to_f64(&a[ch * hw..(ch + 1) * hw]);
        let y = to_f64(&b[ch * hw..(ch + 1) * hw]);
        sum += ssim_cs(&x, &y, h, w, &g).0;
    }
    Some(sum / c as f64)
}

/// MS-SSIM of `a` against `b` (`[c, h, w]`) as `pytorch_msssim.ms_ssim`: per channel, the
/// product over 5 scales of `relu(cs)^w` (the first four) and `relu(ssim)^w` (the last), then
/// the mean over channels. `None` when a side is smaller than [`MS_SSIM_MIN_SIDE`].
///
/// # Panics
/// When the lengths differ from `c * h * w`.
pub fn ms_ssim(a: &[f32], b: &[f32], [c, h, w]: [usize; 3], window: SsimWindow) -> Option<f64> {
    assert_eq!(a.len(), c * h * w);
    assert_eq!(b.len(), c * h * w);
    if h.min(w) < MS_SSIM_MIN_SIDE || c == 0 {
        return None;
    }
    let g = window.weights();
    let hw = h * w;
    let mut sum = 0.0;
    for ch in 0..c {
        let (mut x, mut y) = (
            to_f64(&a[ch * hw..(ch + 1) * hw]),
            to_f64(&b[ch * hw..(ch + 1) * hw]),
        );
        let (mut ph, mut pw) = (h, w);
        let mut prod = 1.0;
        for (level, weight) in MS_WEIGHTS.iter().enumerate() {
            let (s, cs) = ssim_cs(&x, &y, ph, pw, &g);
            if level + 1 == MS_WEIGHTS.len() {
                prod *= s.max(0.0).powf(*weight);
            } else {
                prod *= cs.max(0.0).powf(*weight);
                let (nx, nh, nw) = pool(&x, ph, pw);
                y = pool(&y, ph, pw).0;
                (x, ph, pw) = (nx, nh, nw);
            }
        }
        sum += prod;
    }
    Some(sum / c as f64)
}

fn to_f64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

/// Separable valid filter of one `h x w` plane -> `(h-10) x (w-10)`.
fn filter(plane: &[f64], h: usize, w: usize, g: &[f64; WIN]) -> Vec<f64> {
    let (oh, ow) = (h + 1 - WIN, w + 1 - WIN);
    let mut rows = vec![0.0; h * ow];
    for r in 0..h {
        let src = &plane[r * w..(r + 1) * w];
        for (c, out) in rows[r * ow..(r + 1) * ow].iter_mut().enumerate() {
            *out = g.iter().zip(&src[c..c + WIN]).map(|(k, v)| k * v).sum();
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

/// Mean SSIM and mean contrast-structure term of one channel (`h, w >= 11`).
fn ssim_cs(x: &[f64], y: &[f64], h: usize, w: usize, g: &[f64; WIN]) -> (f64, f64) {
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
    let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = x.iter().zip(y).map(|(p, q)| p * q).collect();
    let (mx, my) = (filter(x, h, w, g), filter(y, h, w, g));
    let (sxx, syy, sxy) = (
        filter(&xx, h, w, g),
        filter(&yy, h, w, g),
        filter(&xy, h, w, g),
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
    (s_sum / m, cs_sum / m)
}

/// 2x2 average pooling of one plane as `avg_pool2d(kernel_size=2, padding=(h % 2, w % 2))`:
/// an odd side is zero-padded by one pixel at both ends and the padding counts in the
/// average, giving `h / 2 + h % 2` rows.
fn pool(p: &[f64], h: usize, w: usize) -> (Vec<f64>, usize, usize) {
    let (pad_h, pad_w) = (h % 2, w % 2);
    let (oh, ow) = (h / 2 + pad_h, w / 2 + pad_w);
    let at = |r: isize, c: isize| -> f64 {
        if r < 0 || c < 0 || r >= h as isize || c >= w as isize {
            0.0
        } else {
            p[r as usize * w + c as usize]
        }
    };
    let mut out = Vec::with_capacity(oh * ow);
    for r in 0..oh {
        for col in 0..ow {
            let r0 = (2 * r) as isize - pad_h as isize;
            let c0 = (2 * col) as isize - pad_w as isize;
            out.push((at(r0, c0) + at(r0, c0 + 1) + at(r0 + 1, c0) + at(r0 + 1, c0 + 1)) / 4.0);
        }
    }
    (out, oh, ow)
}

/// Mean absolute difference of two compact textures `[3, T]` over the texels where `select`
/// is true (`None` when none is).
pub(crate) fn texel_l1(a: &[f32], b: &[f32], select: &[bool]) -> Option<f64> {
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

/// Texture-space L1 against the ground truth, per texel class (both hands pooled).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TexelErrors {
    /// Texels visible in the input on their own hand.
    pub visible: Option<f64>,
    /// Invisible on their own hand, visible on the other (usable through symmetry).
    pub symmetric: Option<f64>,
    /// Invisible on both hands.
    pub invisible: Option<f64>,
    /// Every texel invisible on its own hand (`symmetric` and `invisible` together).
    pub not_visible: Option<f64>,
}

/// A texture's errors against the ground truth: raw, and after one gain per colour channel
/// (docs/evaluation.md, "Scale-invariant texture error").
///
/// The split of an image into albedo and light is ambiguous up to a scale per channel: a
/// texture twice as bright under a light half as strong renders the same image. The raw
/// texel L1 punishes that scale as if it were an error of the texture. The gain-fitted error
/// first fits, per channel `c`, the least-squares gain `g_c = sum x y / sum x^2` of the
/// texture `x` to the ground truth `y` over the texels visible in the input (both hands, the
/// only texels the photo can pin down), applies it to every texel, then takes the L1 per
/// class. It is the headline texture number; the raw one is kept beside it.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TextureErrors {
    /// Errors after the per-channel gain (the headline).
    pub gain_fitted: TexelErrors,
    /// Raw errors.
    pub raw: TexelErrors,
    /// The fitted gains (R, G, B); `None` when no texel is visible or the texture is black
    /// there.
    pub gains: Option<[f64; 3]>,
}

/// The least-squares gain per channel of `texture` to `gt` over the selected texels (both
/// `[3, T]`): `g_c = sum x y / sum x^2`. `None` when no texel is selected or the texture is
/// zero on all of them in some channel.
pub(crate) fn channel_gains(texture: &[f32], gt: &[f32], select: &[bool]) -> Option<[f64; 3]> {
    let t = select.len();
    if texture.len() != 3 * t || gt.len() != 3 * t {
        return None;
    }
    let mut gains = [0.0; 3];
    for (ch, gain) in gains.iter_mut().enumerate() {
        let (mut xy, mut xx) = (0.0f64, 0.0f64);
        for (k, _) in select.iter().enumerate().filter(|(_, s)| **s) {
            let (x, y) = (f64::from(texture[ch * t + k]), f64::from(gt[ch * t + k]));
            xy += x * y;
            xx += x * x;
        }
        if xx <= 0.0 || !(xy / xx).is_finite() {
            return None;
        }
        *gain = xy / xx;
    }
    Some(gains)
}

/// Raw and gain-fitted texture errors of textures `[3, T]` (left, right) against the ground
/// truth, with each hand's texels visible in the input (see [`TextureErrors`]). Classes: a
/// texel of one hand is `visible` if that hand shows it, `symmetric` if only the other hand
/// shows the same texel (usable through the layout's left/right symmetry, paper Sec. 3.3),
/// `invisible` if neither does. Mismatched lengths give all `None`.
pub fn texture_errors(
    textures: &[Vec<f32>; 2],
    gt: &[Vec<f32>; 2],
    visible: &[Vec<bool>; 2],
) -> TextureErrors {
    let t = visible[0].len();
    if textures.iter().chain(gt).any(|x| x.len() != 3 * t) || visible[1].len() != t {
        return TextureErrors::default();
    }
    // Both hands as one [3, 2T] texture.
    let cat = |a: &[Vec<f32>; 2]| -> Vec<f32> {
        (0..3)
            .flat_map(|ch| {
                a[0][ch * t..(ch + 1) * t]
                    .iter()
                    .chain(&a[1][ch * t..(ch + 1) * t])
                    .copied()
            })
            .collect()
    };
    let (x, g) = (cat(textures), cat(gt));
    let class = |f: &dyn Fn(bool, bool) -> bool| -> Vec<bool> {
        (0..2)
            .flat_map(|h| (0..t).map(move |i| (h, i)))
            .map(|(h, i)| f(visible[h][i], visible[1 - h][i]))
            .collect()
    };
    let classes = [
        class(&|own, _| own),
        class(&|own, other| !own && other),
        class(&|own, other| !own && !other),
        class(&|own, _| !own),
    ];
    let errors = |x: &[f32]| TexelErrors {
        visible: texel_l1(x, &g, &classes[0]),
        symmetric: texel_l1(x, &g, &classes[1]),
        invisible: texel_l1(x, &g, &classes[2]),
        not_visible: texel_l1(x, &g, &classes[3]),
    };
    let gains = channel_gains(&x, &g, &classes[0]);
    let gain_fitted = gains.map_or_else(TexelErrors::default, |gains| {
        let n = 2 * t;
        let scaled: Vec<f32> = x
            .iter()
            .enumerate()
            .map(|(i, &v)| (f64::from(v) * gains[i / n]) as f32)
            .collect();
        errors(&scaled)
    });
    TextureErrors {
        gain_fitted,
        raw: errors(&x),
        gains,
    }
}

/// Intersection over union of two masks (values > 0.5 are inside); 1 when both are empty.
pub fn mask_iou(a: &[f32], b: &[f32]) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (*x > 0.5, *y > 0.5);
        inter += usize::from(x && y);
        union += usize::from(x || y);
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// Side of the square window a high-pass subtracts the mean of: image pixels in
/// [`detail_correlation`], UV texels in the `evaluate` module's `unseen_detail`.
pub const DETAIL_WINDOW: usize = 5;

/// How much of `photo`'s fine detail `render` reproduces where it should (issue 34: "the
/// hair and veins are gone"): the correlation of the two images' high-passes, each pixel's
/// value minus the mean of its [`DETAIL_WINDOW`]-square window, over the
/// masked pixels whose whole window is masked (so no silhouette edge enters), all channels
/// together. 1: every vein, hair and crease in place; 0: none (a smooth texture, or detail
/// that lands beside the photo's). `None` with fewer than 100 such pixels, or an image
/// with no detail there.
///
/// # Panics
/// When the lengths differ from `c * h * w` (images) or `h * w` (mask).
pub fn detail_correlation(
    render: &[f32],
    photo: &[f32],
    mask: &[f32],
    [c, h, w]: [usize; 3],
) -> Option<f64> {
    assert_eq!(render.len(), c * h * w);
    assert_eq!(photo.len(), c * h * w);
    assert_eq!(mask.len(), h * w);
    let r = DETAIL_WINDOW / 2;
    let inside = |y: usize, x: usize| mask[y * w + x] >= 0.5;
    let kept: Vec<usize> = (r..h.saturating_sub(r))
        .flat_map(|y| (r..w - r).map(move |x| (y, x)))
        .filter(|&(y, x)| (y - r..=y + r).all(|yy| (x - r..=x + r).all(|xx| inside(yy, xx))))
        .map(|(y, x)| y * w + x)
        .collect();
    if kept.len() < 100 {
        return None;
    }
    let n = ((2 * r + 1) * (2 * r + 1)) as f64;
    let high_pass = |image: &[f32], ch: usize, p: usize| {
        let (y, x) = (p / w, p % w);
        let plane = &image[ch * h * w..(ch + 1) * h * w];
        let sum: f64 = (y - r..=y + r)
            .flat_map(|yy| (x - r..=x + r).map(move |xx| f64::from(plane[yy * w + xx])))
            .sum();
        f64::from(plane[p]) - sum / n
    };
    let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ch in 0..c {
        for &p in &kept {
            let (a, b) = (high_pass(render, ch, p), high_pass(photo, ch, p));
            sa += a;
            sb += b;
            saa += a * a;
            sbb += b * b;
            sab += a * b;
        }
    }
    let m = (c * kept.len()) as f64;
    let cov = sab / m - (sa / m) * (sb / m);
    let (va, vb) = (saa / m - (sa / m).powi(2), sbb / m - (sb / m).powi(2));
    (va > 1e-12 && vb > 1e-12).then(|| cov / (va * vb).sqrt())
}

#[cfg(test)]
mod tests {

    #[test]
    fn mask_iou_counts_pixels() {
        assert_eq!(
            mask_iou(&[1.0, 1.0, 0.0, 0.0], &[1.0, 0.0, 1.0, 0.0]),
            1.0 / 3.0
        );
        assert_eq!(mask_iou(&[0.0; 3], &[0.0; 3]), 1.0);
    }

    #[test]
    fn detail_correlation_reads_detail_in_place() {
        let (c, h, w) = (3, 32, 32);
        // A smooth gradient (skin) with fine stripes (veins) inside a square mask.
        let veins = |y: usize, x: usize| if (x + 2 * y) % 7 < 2 { 0.2 } else { 0.0 };
        let photo = ramp(c, h, w, |ch, y, x| {
            0.3 + 0.01 * y as f32 + veins(y, x) + 0.05 * ch as f32
        });
        let mask = ramp(1, h, w, |_, y, x| {
            f32::from((4..28).contains(&y) && (4..28).contains(&x))
        });
        let dims = [c, h, w];
        let same = detail_correlation(&photo, &photo, &mask, dims).unwrap();
        assert!((same - 1.0).abs() < 1e-9, "{same}");
        // The same detail at half the contrast on another colour: still fully in place.
        let fainter = ramp(c, h, w, |_, y, x| 0.6 + 0.5 * veins(y, x));
        let f = detail_correlation(&fainter, &photo, &mask, dims).unwrap();
        assert!((f - 1.0).abs() < 1e-6, "{f}");
        // The stripes three pixels off: they no longer line up.
        let shifted = ramp(c, h, w, |_, y, x| 0.6 + veins(y, x + 3));
        let s = detail_correlation(&shifted, &photo, &mask, dims).unwrap();
        assert!(s < 0.2, "{s}");
        // A smooth render has no detail to correlate; so has a mask too small for a window.
        let smooth = ramp(c, h, w, |_, y, _| 0.3 + 0.01 * y as f32);
        assert_eq!(detail_correlation(&smooth, &photo, &mask, dims), None);
        let speck = ramp(1, h, w, |_, y, x| f32::from(y < 6 && x < 6));
        assert_eq!(detail_correlation(&photo, &photo, &speck, dims), None);
        // Pixels outside the mask do not count, even a wild silhouette next to it.
        let wild = ramp(c, h, w, |ch, y, x| {
            if (4..28).contains(&y) && (4..28).contains(&x) {
                photo[ch * h * w + y * w + x]
            } else {
                ((x * 7 + y * 13) % 5) as f32
            }
        });
        let edge = detail_correlation(&wild, &photo, &mask, dims).unwrap();
        assert!((edge - 1.0).abs() < 1e-9, "{edge}");
    }
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
    fn a_rescaled_texture_has_no_gain_fitted_error() {
        // 4 texels per hand; left sees 0, 1; right sees 0. Ground truth per channel.
        let gt_hand = |s: f32| -> Vec<f32> {
            (0..3)
                .flat_map(|ch| (0..4).map(move |k| s * (0.1 + 0.05 * k as f32 + 0.2 * ch as f32)))
                .collect()
        };
        let gt = [gt_hand(1.0), gt_hand(0.9)];
        // The texture is the truth under other per-channel gains.
        let g = [0.5f32, 2.0, 1.25];
        let scale =
            |v: &[f32]| -> Vec<f32> { v.iter().enumerate().map(|(i, &x)| x / g[i / 4]).collect() };
        let tex = [scale(&gt[0]), scale(&gt[1])];
        let visible = [
            vec![true, true, false, false],
            vec![true, false, false, false],
        ];
        let e = texture_errors(&tex, &gt, &visible);
        let gains = e.gains.expect("gains");
        for ch in 0..3 {
            assert!((gains[ch] - f64::from(g[ch])).abs() < 1e-5, "{gains:?}");
        }
        for v in [
            e.gain_fitted.visible,
            e.gain_fitted.symmetric,
            e.gain_fitted.invisible,
            e.gain_fitted.not_visible,
        ] {
            assert!(v.expect("value") < 1e-6);
        }
        assert!(e.raw.not_visible.expect("raw") > 0.05);
        // Classes: left texel 2, 3 and right 2, 3 are hidden on both; right 1 is symmetric.
        let raw_sym = e.raw.symmetric.expect("symmetric");
        let want: f64 = (0..3)
            .map(|ch| f64::from((gt[1][ch * 4 + 1] - tex[1][ch * 4 + 1]).abs()))
            .sum::<f64>()
            / 3.0;
        assert!((raw_sym - want).abs() < 1e-6);
        // No visible texel: no gain, no gain-fitted error, raw errors still there.
        let none = [vec![false; 4], vec![false; 4]];
        let e = texture_errors(&tex, &gt, &none);
        assert_eq!(e.gains, None);
        assert_eq!(e.gain_fitted, TexelErrors::default());
        assert!(e.raw.invisible.is_some());
        // A black texture has no gain.
        assert_eq!(channel_gains(&[0.0; 3], &[0.5; 3], &[true]), None);
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

/// The test images of `crates/bitt-eval/tests-data/metrics_reference.py`, rebuilt bit for bit
/// (integer arithmetic only).
#[cfg(test)]
pub(crate) mod reference_images {

    /// The script's LCG (Numerical Recipes), one byte per step.
    pub(crate) struct Lcg(pub(crate) u32);

    impl Lcg {
        pub(crate) fn byte(&mut self) -> i64 {
            self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            i64::from(self.0 >> 24)
        }
    }

    fn clamp(v: i64) -> i64 {
        v.clamp(0, 255)
    }

    /// 8-bit levels `[c, h, w]`.
    #[derive(Debug, Clone)]
    pub(crate) struct Img {
        pub(crate) c: usize,
        pub(crate) h: usize,
        pub(crate) w: usize,
        pub(crate) v: Vec<i64>,
    }

    pub(crate) fn base_image(c: usize, h: usize, w: usize, seed: u32) -> Img {
        let mut rng = Lcg(seed);
        let mut v = Vec::with_capacity(c * h * w);
        for ch in 0..c as i64 {
            for r in 0..h as i64 {
                for col in 0..w as i64 {
                    let mut x = 30 + (r * 150) / h as i64 + (col * 60) / w as i64 + ch * 20;
                    x += ((r / 8 + col / 8) % 2) * 30;
                    x += rng.byte() % 16;
                    v.push(clamp(x));
                }
            }
        }
        Img { c, h, w, v }
    }

    pub(crate) fn noisy(img: &Img, seed: u32, amp_div: i64) -> Img {
        let mut rng = Lcg(seed);
        let v = img
            .v
            .iter()
            .map(|&x| clamp(x + (rng.byte() - 128).div_euclid(amp_div)))
            .collect();
        Img { v, ..*img }
    }

    pub(crate) fn shifted(img: &Img) -> Img {
        let (c, h, w) = (img.c, img.h, img.w);
        let mut v = Vec::with_capacity(c * h * w);
        for ch in 0..c {
            for r in 0..h {
                for col in 0..w {
                    let src = img.v[(ch * h + r) * w + (col + w - 1) % w];
                    v.push(clamp(src * 9 / 10 + if ch == 0 { 5 } else { 0 }));
                }
            }
        }
        Img { v, ..*img }
    }

    pub(crate) fn disk_mask(h: usize, w: usize) -> Vec<f32> {
        let (hi, wi) = (h as i64, w as i64);
        let mut m = Vec::with_capacity(h * w);
        for r in 0..hi {
            for col in 0..wi {
                let dy = 2 * r + 1 - hi;
                let dx = 2 * col + 1 - wi;
                let inside = 9 * dy * dy * wi * wi + 9 * dx * dx * hi * hi <= 4 * hi * hi * wi * wi;
                m.push(if inside { 1.0 } else { 0.0 });
            }
        }
        m
    }

    impl Img {
        pub(crate) fn float(&self) -> Vec<f32> {
            self.v.iter().map(|&x| x as f32 / 255.0).collect()
        }

        pub(crate) fn dims(&self) -> [usize; 3] {
            [self.c, self.h, self.w]
        }
    }
}

/// Comparison against scikit-image and pytorch_msssim: the images and values come from
/// `crates/bitt-eval/tests-data/metrics_reference.py` (output pasted below).
#[cfg(test)]
mod reference {
    use super::reference_images::*;
    use super::*;

    /// What the script printed for one pair.
    struct Want {
        l1: f64,
        psnr: f64,
        ssim_skimage: f64,
        ssim_torch64: f64,
        ssim_torch32: f64,
        ms_torch64: Option<f64>,
        ms_torch32: Option<f64>,
    }

    /// Tolerances: the same formula in f64 as the f64 references (scikit-image, and
    /// pytorch_msssim run on float64 tensors) agrees to rounding; pytorch_msssim in float32
    /// (how BiTT's reference runs it) differs by its own float32 rounding, ~1e-6.
    const TOL_F64: f64 = 1e-9;
    const TOL_F32: f64 = 3e-6;

    fn check(name: &str, got: ImageMetrics, exact: ImageMetrics, want: &Want) {
        let close = |what: &str, g: f64, w: f64, tol: f64| {
            eprintln!("{name} {what}: |diff| {:.1e}", (g - w).abs());
            assert!(
                (g - w).abs() <= tol,
                "{name} {what}: got {g:.12}, reference {w:.12} (|diff| {:.2e} > {tol:.0e})",
                (g - w).abs()
            );
        };
        close("l1", got.l1, want.l1, 1e-12);
        close("psnr", got.psnr, want.psnr, 1e-9);
        close("ssim vs skimage", exact.ssim, want.ssim_skimage, TOL_F64);
        close(
            "ssim vs pytorch_msssim f64",
            got.ssim,
            want.ssim_torch64,
            TOL_F64,
        );
        close(
            "ssim vs pytorch_msssim f32",
            got.ssim,
            want.ssim_torch32,
            TOL_F32,
        );
        match (got.ms_ssim, want.ms_torch64, want.ms_torch32) {
            (Some(g), Some(w64), Some(w32)) => {
                close("ms_ssim vs pytorch_msssim f64", g, w64, TOL_F64);
                close("ms_ssim vs pytorch_msssim f32", g, w32, TOL_F32);
            }
            (None, None, None) => {}
            (g, w, _) => panic!("{name} ms_ssim: got {g:?}, reference {w:?}"),
        }
    }

    fn run(name: &str, a: &Img, b: &Img, want: &Want) {
        let (fa, fb) = (a.float(), b.float());
        let got = image_metrics(&fa, &fb, a.dims());
        let exact = image_metrics_with(&fa, &fb, a.dims(), SsimWindow::Exact);
        check(name, got, exact, want);
    }

    // python3 crates/bitt-eval/tests-data/metrics_reference.py
    // (numpy 2.4.6, torch 2.15.0, scikit-image 0.26.0, pytorch-msssim 1.0.0):
    //
    // == small_noise [3, 64, 64]
    // l1 = 0.059728284961541554
    // psnr = 23.0514976149814
    // ssim_skimage = 0.5348483127355893
    // ssim_pytorch_msssim_float64 = 0.5348516562527467
    // ssim_pytorch_msssim_float32 = 0.5348516702651978
    // == large_noise [3, 180, 200]
    // l1 = 0.07878057261954786
    // psnr = 20.628179143322576
    // ssim_skimage = 0.3843522625453522
    // ssim_pytorch_msssim_float64 = 0.3843559591170125
    // ms_ssim_pytorch_msssim_float64 = 0.8623100986966556
    // ssim_pytorch_msssim_float32 = 0.38435545563697815
    // ms_ssim_pytorch_msssim_float32 = 0.8623103499412537
    // == odd_shift [3, 181, 203]
    // l1 = 0.07151571475011632
    // psnr = 21.628551659632123
    // ssim_skimage = 0.6503903250779263
    // ssim_pytorch_msssim_float64 = 0.6503947449080564
    // ms_ssim_pytorch_msssim_float64 = 0.9223183190654898
    // ssim_pytorch_msssim_float32 = 0.6503963470458984
    // ms_ssim_pytorch_msssim_float32 = 0.9223178029060364
    // == gray_noise [1, 170, 170]
    // l1 = 0.12154881593176715
    // psnr = 16.992856675952694
    // ssim_skimage = 0.2246440187853701
    // ssim_pytorch_msssim_float64 = 0.2246457445335176
    // ms_ssim_pytorch_msssim_float64 = 0.7372981422189966
    // ssim_pytorch_msssim_float32 = 0.22464582324028015
    // ms_ssim_pytorch_msssim_float32 = 0.7372982501983643
    // == masked [3, 180, 200]
    // mask_pixels = 12564
    // l1 = 0.08201636217758304
    // psnr = 20.420058098936877
    // ssim_skimage = 0.7850986544511613
    // ssim_pytorch_msssim_float64 = 0.7850995886224315
    // ms_ssim_pytorch_msssim_float64 = 0.9577015168937039
    // ssim_pytorch_msssim_float32 = 0.7850996851921082
    // ms_ssim_pytorch_msssim_float32 = 0.9577014446258545

    #[test]
    fn small_noise_matches_skimage_and_pytorch_msssim() {
        let a = base_image(3, 64, 64, 1);
        let b = noisy(&a, 2, 4);
        run(
            "small_noise",
            &a,
            &b,
            &Want {
                l1: 0.059728284961541554,
                psnr: 23.0514976149814,
                ssim_skimage: 0.5348483127355893,
                ssim_torch64: 0.5348516562527467,
                ssim_torch32: 0.5348516702651978,
                ms_torch64: None,
                ms_torch32: None,
            },
        );
    }

    #[test]
    fn large_noise_matches_skimage_and_pytorch_msssim() {
        let a = base_image(3, 180, 200, 3);
        let b = noisy(&a, 4, 3);
        run(
            "large_noise",
            &a,
            &b,
            &Want {
                l1: 0.07878057261954786,
                psnr: 20.628179143322576,
                ssim_skimage: 0.3843522625453522,
                ssim_torch64: 0.3843559591170125,
                ssim_torch32: 0.38435545563697815,
                ms_torch64: Some(0.8623100986966556),
                ms_torch32: Some(0.8623103499412537),
            },
        );
    }

    #[test]
    fn odd_sizes_and_a_shift_match_pytorch_msssim_padding() {
        let a = base_image(3, 181, 203, 5);
        let b = shifted(&a);
        run(
            "odd_shift",
            &a,
            &b,
            &Want {
                l1: 0.07151571475011632,
                psnr: 21.628551659632123,
                ssim_skimage: 0.6503903250779263,
                ssim_torch64: 0.6503947449080564,
                ssim_torch32: 0.6503963470458984,
                ms_torch64: Some(0.9223183190654898),
                ms_torch32: Some(0.9223178029060364),
            },
        );
    }

    #[test]
    fn one_channel_matches_skimage_and_pytorch_msssim() {
        let a = base_image(1, 170, 170, 7);
        let b = noisy(&a, 8, 2);
        run(
            "gray_noise",
            &a,
            &b,
            &Want {
                l1: 0.12154881593176715,
                psnr: 16.992856675952694,
                ssim_skimage: 0.2246440187853701,
                ssim_torch64: 0.2246457445335176,
                ssim_torch32: 0.22464582324028015,
                ms_torch64: Some(0.7372981422189966),
                ms_torch32: Some(0.7372982501983643),
            },
        );
    }

    #[test]
    fn masked_metrics_match_the_script() {
        let a = base_image(3, 180, 200, 9);
        let b = noisy(&a, 10, 3);
        let mask = disk_mask(180, 200);
        assert_eq!(mask.iter().filter(|&&m| m > 0.5).count(), 12564);
        let (fa, fb) = (a.float(), b.float());
        let got = masked_image_metrics(&fa, &fb, &mask, a.dims(), SsimWindow::PytorchMsssim)
            .expect("mask is not empty");
        let exact = masked_image_metrics(&fa, &fb, &mask, a.dims(), SsimWindow::Exact)
            .expect("mask is not empty");
        check(
            "masked",
            got,
            exact,
            &Want {
                l1: 0.08201636217758304,
                psnr: 20.420058098936877,
                ssim_skimage: 0.7850986544511613,
                ssim_torch64: 0.7850995886224315,
                ssim_torch32: 0.7850996851921082,
                ms_torch64: Some(0.9577015168937039),
                ms_torch32: Some(0.9577014446258545),
            },
        );
        let empty = vec![0.0; 180 * 200];
        assert!(masked_image_metrics(&fa, &fb, &empty, a.dims(), SsimWindow::Exact).is_none());
    }
}
