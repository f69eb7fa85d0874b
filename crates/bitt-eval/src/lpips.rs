//! LPIPS with the VGG16 backbone (Zhang et al. 2018, version 0.1 of the `lpips` package), the
//! perceptual metric of the paper's tables.
//!
//! `d(x, y) = sum_l mean_hw( w_l . (n(f_l(s(x))) - n(f_l(s(y))))^2 )`, where
//!
//! - `s` is the `lpips` scaling layer, `(x - shift) / scale` per channel with
//!   `shift = [-0.030, -0.088, -0.188]` and `scale = [0.458, 0.448, 0.450]`, on inputs in
//!   `[-1, 1]`;
//! - `f_l` are the ReLU outputs of VGG16's `conv1_2`, `conv2_2`, `conv3_3`, `conv4_3` and
//!   `conv5_3` (3x3 convolutions with padding 1, 2x2 max pooling with stride 2 between the
//!   blocks, floor sizes);
//! - `n` divides each feature vector by its channel norm plus `1e-10`;
//! - `w_l` are the learned non-negative 1x1 "lin" weights (no bias); `mean_hw` is the spatial
//!   mean.
//!
//! Weights come from one safetensors file ([`WEIGHT_NAMES`] lists its tensors, all `F32`):
//! `features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.weight` `[out, in, 3, 3]` and `.bias`
//! `[out]` (torchvision's `vgg16().features` indices), and `lin0.weight` .. `lin4.weight`
//! `[1, C, 1, 1]` (the `lpips` package's `lin{l}.model.1.weight`). `bitt convert-lpips` writes
//! it from the `lpips` package's `vgg.pth` and torchvision's `vgg16-397923af.pth`. Without
//! that file there is no LPIPS: callers hold an `Option<LpipsVgg>` and report LPIPS as
//! unavailable, never an estimate.
//!
//! Inputs: [`LpipsVgg::forward`] takes `[N, 3, H, W]` in `[-1, 1]` (`lpips.LPIPS(...)(x, y)`);
//! [`LpipsVgg::distance`] takes host images in `[0, 1]` and maps them to `[-1, 1]` first
//! (`lpips.LPIPS(...)(x, y, normalize=True)`), the standard use. BiTT's reference code
//! passes `[0, 1]` tensors without `normalize=True`; [`LpipsVgg::distance_unscaled`]
//! reproduces that (docs/evaluation.md).

use bitt_stdx::FileErrorExt;
use std::path::{Path, PathBuf};

use burn::module::{Module, Param, ParamId};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::nn::pool::{MaxPool2d, MaxPool2dConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};

use bitt_stdx::st;

use crate::EvalError;
use bitt_stdx::WithContext;

/// The VGG16 `features` indices of the 13 convolutions with their `(in, out)` channels.
pub(crate) const VGG16_CONVS: [(usize, usize, usize); 13] = [
    (0, 3, 64),
    (2, 64, 64),
    (5, 64, 128),
    (7, 128, 128),
    (10, 128, 256),
    (12, 256, 256),
    (14, 256, 256),
    (17, 256, 512),
    (19, 512, 512),
    (21, 512, 512),
    (24, 512, 512),
    (26, 512, 512),
    (28, 512, 512),
];

/// Convolutions per block (a 2x2 max pooling precedes blocks 2-5); the ReLU after a block's
/// last convolution is the LPIPS tap.
const BLOCKS: [usize; 5] = [2, 2, 3, 3, 3];

/// Channels of the five taps (and of `lin0` .. `lin4`).
pub(crate) const LIN_CHANNELS: [usize; 5] = [64, 128, 256, 512, 512];

/// The scaling layer's shift and scale (`lpips.pretrained_networks.ScalingLayer`).
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// Smallest input side: after four 2x2 poolings `conv5_3` still has a pixel.
pub(crate) const MIN_SIDE: usize = 16;

/// Where `bitt convert-lpips` writes the weights by default and where [`LpipsVgg::find`]
/// looks: `$BITT_LPIPS_WEIGHTS`, else `~/.cache/bitt/lpips_vgg.safetensors`.
pub fn default_weights_path() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("BITT_LPIPS_WEIGHTS") {
        return Some(PathBuf::from(p));
    }
    std::env::var_os("HOME").map(|h| {
        PathBuf::from(h)
            .join(".cache")
            .join("bitt")
            .join("lpips_vgg.safetensors")
    })
}

/// Every tensor name of the weights file with its shape, in a fixed order.
pub(crate) fn weight_names() -> Vec<(String, Vec<usize>)> {
    let mut out = Vec::with_capacity(31);
    for (idx, cin, cout) in VGG16_CONVS {
        out.push((format!("features.{idx}.weight"), vec![cout, cin, 3, 3]));
        out.push((format!("features.{idx}.bias"), vec![cout]));
    }
    for (l, c) in LIN_CHANNELS.iter().enumerate() {
        out.push((format!("lin{l}.weight"), vec![1, *c, 1, 1]));
    }
    out
}

/// The tensor names of the weights file (see the module docs), for documentation and tools.
pub(crate) const WEIGHT_NAMES: &str = "features.{0,2,5,7,10,12,14,17,19,21,24,26,28}.weight \
                                [out, in, 3, 3], features.{..}.bias [out], \
                                lin{0..4}.weight [1, C, 1, 1]; all F32";

/// The `format` metadata of the weights file.
pub(crate) const WEIGHTS_FORMAT: &str = "bitt-lpips-vgg-v0.1";

/// Writes the weights file: `tensors` must hold exactly the tensors of [`weight_names`] with
/// their shapes (`(name, shape, values)`). Atomic (a temporary file renamed into place);
/// creates the parent folder.
pub(crate) fn save_weights(
    path: &Path,
    tensors: &[(String, Vec<usize>, Vec<f32>)],
) -> Result<(), EvalError> {
    let want = weight_names();
    if tensors.len() != want.len() {
        return Err(EvalError::Invalid(format!(
            "{}: LPIPS weights need {} tensors, got {}",
            path.display(),
            want.len(),
            tensors.len()
        )));
    }
    for (name, shape) in &want {
        let Some((_, s, v)) = tensors.iter().find(|(n, _, _)| n == name) else {
            return Err(EvalError::Invalid(format!(
                "{}: LPIPS weights lack {name}",
                path.display()
            )));
        };
        if s != shape || v.len() != shape.iter().product::<usize>() {
            return Err(EvalError::Invalid(format!(
                "{}: LPIPS tensor {name} has shape {s:?} ({} values), expected {shape:?}",
                path.display(),
                v.len()
            )));
        }
    }
    let entries: Vec<st::Entry> = tensors
        .iter()
        .map(|(n, s, v)| {
            (
                n.clone(),
                safetensors::Dtype::F32,
                s.clone(),
                st::f32_bytes(v),
            )
        })
        .collect();
    let meta =
        std::collections::HashMap::from([("format".to_string(), WEIGHTS_FORMAT.to_string())]);
    Ok(st::write(path, &entries, meta)?)
}

/// LPIPS-VGG, see the module docs.
#[derive(Module, Debug)]
pub struct LpipsVgg {
    /// The 13 VGG16 convolutions (3x3, padding 1, bias).
    convs: Vec<Conv2d>,
    /// The five 1x1 lin layers (no bias).
    lins: Vec<Conv2d>,
    pool: MaxPool2d,
}

fn param<const D: usize>(t: Tensor<D>) -> Param<Tensor<D>> {
    Param::initialized(ParamId::new(), t)
}

fn conv(weight: Tensor<4>, bias: Option<Tensor<1>>, pad: usize) -> Conv2d {
    let [_, _, kh, kw] = weight.dims();
    Conv2d {
        weight: param(weight),
        bias: bias.map(param),
        stride: [1, 1],
        kernel_size: [kh, kw],
        dilation: [1, 1],
        groups: 1,
        padding: PaddingConfig2d::Explicit(pad, pad, pad, pad),
    }
}

impl LpipsVgg {
    /// Builds the module from host tensors: `get(name, shape)` returns the `f32` values of
    /// the tensor `name` (see [`weight_names`]) or an error message.
    pub fn from_fn(
        mut get: impl FnMut(&str, &[usize]) -> Result<Vec<f32>, String>,
        device: &Device,
    ) -> Result<Self, String> {
        let tensor = |v: Vec<f32>, shape: &[usize]| TensorData::new(v, shape.to_vec());
        let mut convs = Vec::with_capacity(VGG16_CONVS.len());
        for (idx, cin, cout) in VGG16_CONVS {
            let ws = [cout, cin, 3, 3];
            let w = get(&format!("features.{idx}.weight"), &ws)?;
            let b = get(&format!("features.{idx}.bias"), &[cout])?;
            convs.push(conv(
                Tensor::from_data(tensor(w, &ws), device),
                Some(Tensor::from_data(tensor(b, &[cout]), device)),
                1,
            ));
        }
        let mut lins = Vec::with_capacity(LIN_CHANNELS.len());
        for (l, &c) in LIN_CHANNELS.iter().enumerate() {
            let s = [1, c, 1, 1];
            let w = get(&format!("lin{l}.weight"), &s)?;
            lins.push(conv(Tensor::from_data(tensor(w, &s), device), None, 0));
        }
        Ok(LpipsVgg {
            convs,
            lins,
            pool: MaxPool2dConfig::new([2, 2]).with_strides([2, 2]).init(),
        })
    }

    /// Reads the weights file (see the module docs). Errors name the file and the tensor.
    pub fn load(path: &Path, device: &Device) -> Result<Self, EvalError> {
        let bytes = std::fs::read(path).map_err(|e| EvalError::io(path, e))?;
        Self::from_safetensors_bytes(&bytes, path, device)
    }

    /// [`LpipsVgg::load`] from bytes already read; `path` names them in errors.
    pub(crate) fn from_safetensors_bytes(
        bytes: &[u8],
        path: &Path,
        device: &Device,
    ) -> Result<Self, EvalError> {
        let r = st::Reader::open(bytes, path).map_err(|e| {
            EvalError::format(
                path,
                format!("{}; write it with `bitt convert-lpips`", e.detail()),
            )
        })?;
        Self::from_fn(
            |name, shape| {
                let want: Vec<Option<usize>> = shape.iter().copied().map(Some).collect();
                let (_, v) = r.finite_f32s(name, Some(&want)).map_err(|e| {
                    format!(
                        "LPIPS weights: {} (expected {WEIGHT_NAMES}; write the file with \
                         `bitt convert-lpips`)",
                        e.detail()
                    )
                })?;
                Ok(v)
            },
            device,
        )
        .map_err(|m| EvalError::format(path, m))
    }

    /// The weights at [`default_weights_path`] when that file exists; `Ok(None)` (LPIPS
    /// unavailable) when it does not; an error naming the file when it exists but cannot be
    /// read.
    pub fn find(device: &Device) -> Result<Option<Self>, EvalError> {
        match default_weights_path() {
            Some(p) if p.is_file() => Self::load(&p, device).map(Some),
            _ => Ok(None),
        }
    }

    /// The weights at `path` (`--lpips`), else [`LpipsVgg::find`]'s; an error is said to be
    /// about `LPIPS weights FILE` (or `LPIPS weights`).
    pub fn load_or_find(path: Option<&Path>, device: &Device) -> Result<Option<Self>, EvalError> {
        match path {
            Some(p) => Ok(Self::load(p, device)
                .map(Some)
                .context_with(|| format!("LPIPS weights {}", p.display()))?),
            None => Ok(Self::find(device).context_with(|| "LPIPS weights".to_string())?),
        }
    }

    /// LPIPS distances `[N]` of two batches `[N, 3, H, W]` with values in `[-1, 1]` (as
    /// `lpips.LPIPS(net='vgg')(x, y)`). Sides must be at least [`MIN_SIDE`].
    ///
    /// # Panics
    /// When the shapes differ or are not `[N, 3, H, W]` (the host entry points check).
    pub fn forward(&self, x: Tensor<4>, y: Tensor<4>) -> Tensor<1> {
        let [n, c, _, _] = x.dims();
        assert_eq!(x.dims(), y.dims(), "LPIPS inputs differ in shape");
        assert_eq!(c, 3, "LPIPS takes 3-channel images");
        let device = x.device();
        let col = |v: [f32; 3]| -> Tensor<4> {
            Tensor::from_data(TensorData::new(v.to_vec(), [1, 3, 1, 1]), &device)
        };
        let (shift, scale) = (col(SHIFT), col(SCALE));
        // Both images in one batch: one pass through VGG.
        let xy = Tensor::cat(vec![x, y], 0).sub(shift).div(scale);
        let mut h = xy;
        let mut total: Option<Tensor<1>> = None;
        let mut k = 0;
        for (block, &count) in BLOCKS.iter().enumerate() {
            if block > 0 {
                h = self.pool.forward(h);
            }
            for _ in 0..count {
                h = relu(self.convs[k].forward(h));
                k += 1;
            }
            let feats = normalize_channels(h.clone());
            let f0 = feats.clone().narrow(0, 0, n);
            let f1 = feats.narrow(0, n, n);
            let diff = f0.sub(f1).powi_scalar(2);
            let per = self.lins[block]
                .forward(diff)
                .mean_dim(3)
                .mean_dim(2)
                .reshape([n]);
            total = Some(match total {
                Some(t) => t.add(per),
                None => per,
            });
        }
        total.expect("five blocks")
    }

    /// LPIPS of two host images `[c, h, w]` with values in `[0, 1]` (mapped to `[-1, 1]`,
    /// as `normalize=True`). `c` is 3, or 1 (repeated to 3 channels).
    pub fn distance(
        &self,
        a: &[f32],
        b: &[f32],
        dims: [usize; 3],
        device: &Device,
    ) -> Result<f64, EvalError> {
        self.host(a, b, dims, device, true)
    }

    /// LPIPS of two host images `[c, h, w]` passed as they are, without mapping `[0, 1]` to
    /// `[-1, 1]`: what BiTT's reference evaluation computes (`lpips(x, y)` on `[0, 1]`
    /// tensors). Not the standard use; see docs/evaluation.md.
    pub fn distance_unscaled(
        &self,
        a: &[f32],
        b: &[f32],
        dims: [usize; 3],
        device: &Device,
    ) -> Result<f64, EvalError> {
        self.host(a, b, dims, device, false)
    }

    fn host(
        &self,
        a: &[f32],
        b: &[f32],
        [c, h, w]: [usize; 3],
        device: &Device,
        to_signed: bool,
    ) -> Result<f64, EvalError> {
        if c != 3 && c != 1 {
            return Err(EvalError::Invalid(format!(
                "LPIPS takes RGB (or gray) images, got {c} channels"
            )));
        }
        if a.len() != c * h * w || b.len() != c * h * w {
            return Err(EvalError::Invalid(format!(
                "LPIPS: image sizes {} and {} do not match [{c}, {h}, {w}]",
                a.len(),
                b.len()
            )));
        }
        if h < MIN_SIDE || w < MIN_SIDE {
            return Err(EvalError::Invalid(format!(
                "LPIPS needs images of at least {MIN_SIDE}x{MIN_SIDE} pixels, got {w}x{h}"
            )));
        }
        let prep = |img: &[f32]| -> Tensor<4> {
            let v: Vec<f32> = if to_signed {
                img.iter().map(|x| 2.0 * x - 1.0).collect()
            } else {
                img.to_vec()
            };
            let t = Tensor::<4>::from_data(TensorData::new(v, [1, c, h, w]), device);
            if c == 1 { t.repeat_dim(1, 3) } else { t }
        };
        let d = self.forward(prep(a), prep(b));
        let v = bitt_stdx::to_host(d)?;
        let v = f64::from(v[0]);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(EvalError::NonFinite("LPIPS distance".into()))
        }
    }
}

/// `x / (||x||_channels + 1e-10)` (`lpips.normalize_tensor`).
fn normalize_channels(x: Tensor<4>) -> Tensor<4> {
    let norm = x.clone().powi_scalar(2).sum_dim(1).sqrt().add_scalar(1e-10);
    x.div(norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The weights of `tests-data/lpips_reference.py`: an integer hash of (index, salt).
    fn hashed(n: usize, salt: u64) -> Vec<u64> {
        const M: u64 = 0xFFFF_FFFF;
        (0..n as u64)
            .map(|i| {
                let mut x = (i.wrapping_mul(2_654_435_761).wrapping_add(salt * 97_531)) & M;
                x ^= x >> 15;
                x = (x * 2_246_822_519) & M;
                x ^= x >> 13;
                x
            })
            .collect()
    }

    fn signed_unit(n: usize, salt: u64) -> Vec<f64> {
        hashed(n, salt)
            .into_iter()
            .map(|x| (x % 2001) as f64 / 1000.0 - 1.0)
            .collect()
    }

    fn formula_weight(name: &str, shape: &[usize]) -> Result<Vec<f32>, String> {
        let n: usize = shape.iter().product();
        if let Some(l) = name
            .strip_prefix("lin")
            .and_then(|s| s.strip_suffix(".weight"))
        {
            let l: u64 = l.parse().map_err(|_| name.to_string())?;
            return Ok(hashed(n, 100 + l)
                .into_iter()
                .map(|x| ((x % 1001) as f64 / 1000.0) as f32)
                .collect());
        }
        let mut parts = name.split('.');
        let idx: usize = parts.nth(1).and_then(|s| s.parse().ok()).ok_or(name)?;
        let k = VGG16_CONVS.iter().position(|c| c.0 == idx).ok_or(name)? as u64;
        let (_, cin, _) = VGG16_CONVS[k as usize];
        if name.ends_with(".weight") {
            let scale = (6.0 / (cin * 9) as f64).sqrt();
            Ok(signed_unit(n, 2 * k + 1)
                .into_iter()
                .map(|v| (v * scale) as f32)
                .collect())
        } else {
            Ok(signed_unit(n, 2 * k + 2)
                .into_iter()
                .map(|v| (v * 0.05) as f32)
                .collect())
        }
    }

    fn image(c: usize, h: usize, w: usize, seed: u32) -> Vec<f32> {
        let mut x = seed;
        (0..c * h * w)
            .map(|i| {
                x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let smooth = ((i % w) as f32 / w as f32 + (i / w % h) as f32 / h as f32) / 2.0;
                (0.7 * smooth + 0.3 * (x >> 24) as f32 / 255.0).clamp(0.0, 1.0)
            })
            .collect()
    }

    #[test]
    fn formula_weights_match_the_script_checksum() {
        // weights_abs_sum = 296034.3332708416 (lpips_reference.py)
        let mut sum = 0.0;
        for (name, shape) in weight_names() {
            let v = formula_weight(&name, &shape).unwrap();
            assert_eq!(v.len(), shape.iter().product::<usize>());
            sum += v.iter().map(|x| f64::from(x.abs())).sum::<f64>();
        }
        assert!((sum - 296_034.333_270_841_6).abs() < 1e-6, "{sum}");
    }

    /// Structure on arbitrary weights: identical images give 0, distances are positive,
    /// symmetric, and batch entries are independent.
    #[test]
    fn identical_images_give_zero_and_batches_are_independent() {
        let device = Device::flex();
        let net = LpipsVgg::from_fn(
            |name, shape| {
                // Arbitrary (not the reference formula) but deterministic weights.
                formula_weight(name, shape).map(|v| v.into_iter().map(|x| x * 0.9).collect())
            },
            &device,
        )
        .unwrap();
        let dims = [3, 24, 20];
        let a = image(3, 24, 20, 1);
        let b = image(3, 24, 20, 2);
        let same = net.distance(&a, &a, dims, &device).unwrap();
        assert!(same.abs() < 1e-6, "{same}");
        let ab = net.distance(&a, &b, dims, &device).unwrap();
        let ba = net.distance(&b, &a, dims, &device).unwrap();
        assert!(ab > 1e-4, "{ab}");
        assert!((ab - ba).abs() < 1e-5 * ab.max(1.0), "{ab} vs {ba}");
        // A batch of [a, a] vs [a, b] gives [0, d(a, b)].
        let t = |v: &[f32]| {
            Tensor::<4>::from_data(TensorData::new(v.to_vec(), [1, 3, 24, 20]), &device)
                .mul_scalar(2.0)
                .sub_scalar(1.0)
        };
        let x = Tensor::cat(vec![t(&a), t(&a)], 0);
        let y = Tensor::cat(vec![t(&a), t(&b)], 0);
        let d = bitt_stdx::to_host(net.forward(x, y)).unwrap();
        assert_eq!(d.len(), 2);
        assert!(d[0].abs() < 1e-6);
        assert!((f64::from(d[1]) - ab).abs() < 1e-5, "{} vs {ab}", d[1]);
        // Gray images are repeated to RGB.
        let g = image(1, 24, 20, 3);
        let rgb: Vec<f32> = g.iter().chain(&g).chain(&g).copied().collect();
        let d1 = net.distance(&g, &a[..480], [1, 24, 20], &device).unwrap();
        let a_gray: Vec<f32> = a[..480]
            .iter()
            .chain(&a[..480])
            .chain(&a[..480])
            .copied()
            .collect();
        let d3 = net.distance(&rgb, &a_gray, dims, &device).unwrap();
        assert!((d1 - d3).abs() < 1e-6);
        // Too small, wrong channel count.
        assert!(
            net.distance(&a[..300], &a[..300], [3, 10, 10], &device)
                .is_err()
        );
        assert!(
            net.distance(&a[..960], &a[..960], [2, 24, 20], &device)
                .is_err()
        );
    }

    #[test]
    fn loading_errors_name_the_file_and_the_tensor() {
        let device = Device::flex();
        let dir = std::env::temp_dir().join(format!("bitt-lpips-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let missing = dir.join("missing.safetensors");
        let e = LpipsVgg::load(&missing, &device).unwrap_err().to_string();
        assert!(e.contains("missing.safetensors"), "{e}");
        let junk = dir.join("junk.safetensors");
        std::fs::write(&junk, b"not safetensors").unwrap();
        let e = LpipsVgg::load(&junk, &device).unwrap_err().to_string();
        assert!(
            e.contains("junk.safetensors") && e.contains("convert-lpips"),
            "{e}"
        );
        // A file with only lin0.
        let v = vec![0u8; 64 * 4];
        let view =
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![1, 64, 1, 1], &v)
                .unwrap();
        let bytes = safetensors::serialize(vec![("lin0.weight".to_string(), view)], None).unwrap();
        let partial = dir.join("partial.safetensors");
        std::fs::write(&partial, bytes).unwrap();
        let e = LpipsVgg::load(&partial, &device).unwrap_err().to_string();
        assert!(
            e.contains("partial.safetensors") && e.contains("features.0.weight"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    // python3 crates/bitt-eval/tests-data/lpips_reference.py (lpips 0.1.4, torch 2.15.0):
    //
    // weights_abs_sum = 296034.3332708416
    // small_noise = 0.1519603282213211
    // small_shift = 0.13741089403629303
    // rect_noise = 0.38800719380378723
    // small_noise_raw01 = 0.017631739377975464
    // identical = 0.0

    /// Tolerance against the python float32 values: both sides compute in float32 with
    /// different summation orders in the convolutions.
    const TOL: f64 = 1e-6;

    #[test]
    fn matches_python_lpips_on_formula_weights() {
        use crate::metrics::reference_images as ri;
        let device = Device::flex();
        let net = LpipsVgg::from_fn(formula_weight, &device).unwrap();
        let a = ri::base_image(3, 64, 64, 1);
        let cases = [
            (
                "small_noise",
                a.clone(),
                ri::noisy(&a, 2, 4),
                0.1519603282213211,
            ),
            (
                "small_shift",
                a.clone(),
                ri::shifted(&a),
                0.13741089403629303,
            ),
            (
                "rect_noise",
                ri::base_image(3, 48, 80, 11),
                ri::noisy(&ri::base_image(3, 48, 80, 11), 12, 2),
                0.38800719380378723,
            ),
        ];
        for (name, x, y, want) in &cases {
            let got = net
                .distance(&x.float(), &y.float(), x.dims(), &device)
                .unwrap();
            eprintln!(
                "{name}: rust {got}, python {want}, |diff| {:.1e}",
                (got - want).abs()
            );
            assert!(
                (got - want).abs() < TOL,
                "{name}: got {got}, python lpips {want}"
            );
        }
        let (x, y) = (&cases[0].1, &cases[0].2);
        let raw = net
            .distance_unscaled(&x.float(), &y.float(), x.dims(), &device)
            .unwrap();
        eprintln!("raw01: rust {raw}, python 0.017631739377975464");
        assert!((raw - 0.017631739377975464).abs() < TOL, "raw01: {raw}");
    }

    /// The real weights (`bitt convert-lpips`), when present: identical images give 0 and
    /// a noisy copy a distance in LPIPS's usual range. Python values for the real weights
    /// could not be computed where this was written (the torchvision VGG16 download was
    /// unreachable), so the exact comparison runs on formula weights above.
    #[test]
    fn real_weights_when_present() {
        let Some(path) = default_weights_path().filter(|p| p.is_file()) else {
            eprintln!(
                "skipped: no LPIPS weights at {:?} (set BITT_LPIPS_WEIGHTS or run `bitt \
                 convert-lpips`)",
                default_weights_path()
            );
            return;
        };
        use crate::metrics::reference_images as ri;
        let device = Device::flex();
        let net = LpipsVgg::load(&path, &device).unwrap();
        let a = ri::base_image(3, 64, 64, 1);
        let b = ri::noisy(&a, 2, 4);
        let same = net
            .distance(&a.float(), &a.float(), a.dims(), &device)
            .unwrap();
        assert!(same.abs() < 1e-6);
        let d = net
            .distance(&a.float(), &b.float(), a.dims(), &device)
            .unwrap();
        assert!(d > 0.0 && d < 1.5, "{d}");
        eprintln!("real LPIPS weights {path:?}: small_noise = {d}");
    }
}
