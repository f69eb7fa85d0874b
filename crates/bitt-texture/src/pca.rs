//! Texture PCA models: `T(a) = clamp((mean + basis a) * scale, 0, 1)` over the compact texels
//! of a [`TextureLayout`].
//!
//! HTML is such a model (`mean` and `basis` on a 0..255 scale, `scale = 1/255`, 101
//! components); the project's procedural skin model is another, fitted with
//! [`TexturePca::fit`] (scale 1).
//!
//! Vectors are compact textures in channel-major order (`[3, T]` flattened: all red, then all
//! green, then all blue; see [`crate::layout`]); the basis is `[3T, K]` row-major.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;

use bitt_mesh::UvLayout;
use bitt_mesh::glam::DVec2;
use burn::tensor::{Device, Tensor, TensorData};
use rayon::prelude::*;
use safetensors::Dtype;

use crate::TextureError;
use crate::layout::TextureLayout;
use crate::st;

/// The `format` metadata of a texture PCA safetensors file.
pub(crate) const PCA_FORMAT: &str = "bitt-texture-pca";

/// Sweeps per singular value allowed to `burn::linalg::svd` in [`TexturePca::fit`].
const SVD_SWEEPS: usize = 100;

/// Values of the texel vector per block of the mean in [`TexturePca::fit_with_progress`]
/// (one progress step each).
/// (Tiny in unit tests, so that their small samples span several blocks.)
const MEAN_BLOCK: usize = if cfg!(test) { 5 } else { 1 << 16 };

/// Basis rows per sign-scan block in [`TexturePca::fit_with_progress`] (one progress step
/// each).
const BASIS_BLOCK: usize = if cfg!(test) { 4 } else { 1 << 16 };

/// A stage of a texture PCA fit, as reported to a [`FitProgress`].
///
/// [`TexturePca::fit_with_progress`] reports `Centre`, `Gram`, `Eigen`, `Basis` in that order;
/// [`crate::procedural::procedural_texture_pca_with_progress`] reports `Generate` before them
/// and `Evaluate` after them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FitStage {
    /// Generating the people's skin textures; counts identities (training and held-out
    /// together; each is both hands).
    Generate,
    /// The mean texture and the centred samples; counts blocks of the mean, then samples.
    Centre,
    /// The samples' Gram matrix (one matrix product on the fit's device; 0, then 1).
    Gram,
    /// Its eigendecomposition through `burn::linalg::svd` (0, then 1).
    Eigen,
    /// The basis: the product with the eigenvectors (1 step), then blocks of rows whose
    /// signs are fixed.
    Basis,
    /// Evaluating the fitted model: the normal equations (1 step), then one step per
    /// projected sample (training, then held-out).
    Evaluate,
}

impl FitStage {
    /// A short lower-case label for a progress bar, e.g. `"generating identities"`.
    pub fn label(self) -> &'static str {
        match self {
            FitStage::Generate => "generating identities",
            FitStage::Centre => "centring samples",
            FitStage::Gram => "Gram matrix",
            FitStage::Eigen => "eigendecomposition",
            FitStage::Basis => "basis",
            FitStage::Evaluate => "evaluating",
        }
    }
}

/// Receives the progress of a texture PCA fit: `report(stage, done, total)`.
///
/// Every stage starts with `done = 0` and ends with `done = total` (`total >= 1`); within a
/// stage the counts never decrease, and calls never overlap (they are made one at a time,
/// under a lock, possibly from worker threads: keep them cheap). Any
/// `Fn(FitStage, usize, usize) + Sync` closure is a `FitProgress`; [`NoProgress`] ignores
/// everything.
pub trait FitProgress: Sync {
    /// `done` of `total` steps of `stage` are finished.
    fn report(&self, stage: FitStage, done: usize, total: usize);
}

impl<F: Fn(FitStage, usize, usize) + Sync> FitProgress for F {
    fn report(&self, stage: FitStage, done: usize, total: usize) {
        self(stage, done, total);
    }
}

/// A [`FitProgress`] that ignores every report.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl FitProgress for NoProgress {
    fn report(&self, _stage: FitStage, _done: usize, _total: usize) {}
}

/// Counts the steps of one stage from any thread, reporting each under a lock so the counts
/// a [`FitProgress`] sees are monotone. Reports `0` on creation.
pub(crate) struct StageCounter<'a> {
    progress: &'a dyn FitProgress,
    stage: FitStage,
    total: usize,
    done: Mutex<usize>,
}

impl<'a> StageCounter<'a> {
    pub(crate) fn new(progress: &'a dyn FitProgress, stage: FitStage, total: usize) -> Self {
        let total = total.max(1);
        progress.report(stage, 0, total);
        StageCounter {
            progress,
            stage,
            total,
            done: Mutex::new(0),
        }
    }

    /// One more step done.
    pub(crate) fn step(&self) {
        let mut done = self.done.lock().unwrap_or_else(|e| e.into_inner());
        *done = (*done + 1).min(self.total);
        self.progress.report(self.stage, *done, self.total);
    }

    /// Reports the stage complete (when it has not been already).
    pub(crate) fn finish(&self) {
        let mut done = self.done.lock().unwrap_or_else(|e| e.into_inner());
        if *done < self.total {
            *done = self.total;
            self.progress.report(self.stage, *done, self.total);
        }
    }
}

/// A texture PCA model.
#[derive(Debug, Clone, PartialEq)]
pub struct TexturePca {
    /// The texels the model covers.
    pub layout: TextureLayout,
    /// Mean texture, `[3T]`, on the model's scale.
    pub mean: Vec<f32>,
    /// Principal components, `[3T, K]` row-major, on the model's scale.
    pub basis: Vec<f32>,
    /// `K`, the number of components (parameters).
    pub num_components: usize,
    /// Multiply `mean + basis a` by this to get `[0, 1]` colours (1/255 for HTML).
    pub scale: f32,
}

/// A [`TexturePca`]'s arrays uploaded once to a device (see [`TexturePca::to_device`]).
#[derive(Debug, Clone)]
pub struct TexturePcaTensors {
    /// Mean texture, `[3T]`, on the model's scale.
    pub mean: Tensor<1>,
    /// Principal components, `[3T, K]`, on the model's scale.
    pub basis: Tensor<2>,
    /// Multiply by this to get `[0, 1]` colours.
    pub scale: f32,
}

/// What [`TexturePca::fit`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct PcaFitReport {
    /// Fraction of the total variance each kept component explains, largest first (`[K]`).
    pub explained_variance_ratio: Vec<f32>,
    /// Total variance of the samples: the trace of their covariance (`1/(N-1)`
    /// normalisation), summed over all `3T` values.
    pub total_variance: f32,
}

impl TexturePca {
    /// A model from its arrays. Checks `mean` is `[3T]` and `basis` `[3T, K]` for the
    /// layout's `T`, `K >= 1`, all values finite and `scale` finite and positive.
    pub fn new(
        layout: TextureLayout,
        mean: Vec<f32>,
        basis: Vec<f32>,
        num_components: usize,
        scale: f32,
    ) -> Result<Self, TextureError> {
        let n = 3 * layout.num_texels();
        if num_components == 0 {
            return Err(TextureError::Invalid(
                "a texture PCA model needs at least one component".into(),
            ));
        }
        if mean.len() != n {
            return Err(TextureError::Invalid(format!(
                "PCA mean has {} values, expected 3 x {} texels = {n}",
                mean.len(),
                layout.num_texels()
            )));
        }
        if n.checked_mul(num_components) != Some(basis.len()) {
            return Err(TextureError::Invalid(format!(
                "PCA basis has {} values, expected {n} x {num_components}",
                basis.len()
            )));
        }
        if !(scale.is_finite() && scale > 0.0) {
            return Err(TextureError::Invalid(format!(
                "PCA scale must be finite and positive, got {scale}"
            )));
        }
        if let Some(i) = mean.iter().position(|x| !x.is_finite()) {
            return Err(TextureError::Invalid(format!(
                "PCA mean value {i} is not finite ({})",
                mean[i]
            )));
        }
        if let Some(i) = basis.iter().position(|x| !x.is_finite()) {
            return Err(TextureError::Invalid(format!(
                "PCA basis value {i} (row {}, component {}) is not finite",
                i / num_components,
                i % num_components
            )));
        }
        Ok(TexturePca {
            layout,
            mean,
            basis,
            num_components,
            scale,
        })
    }

    /// `clamp((mean + basis a) * scale, 0, 1)`: a compact texture `[3T]` (channel-major
    /// `[3, T]`) in `[0, 1]`. Fails when `params` does not have `K` finite values.
    pub fn texture(&self, params: &[f32]) -> Result<Vec<f32>, TextureError> {
        self.check_params(params)?;
        let s = f64::from(self.scale);
        Ok(self
            .mean
            .iter()
            .zip(self.basis.chunks_exact(self.num_components))
            .map(|(&m, row)| {
                let v = row.iter().zip(params).fold(f64::from(m), |acc, (&b, &a)| {
                    acc + f64::from(b) * f64::from(a)
                });
                ((v * s) as f32).clamp(0.0, 1.0)
            })
            .collect())
    }

    fn check_params(&self, params: &[f32]) -> Result<(), TextureError> {
        if params.len() != self.num_components {
            return Err(TextureError::Invalid(format!(
                "texture PCA takes {} parameters, got {}",
                self.num_components,
                params.len()
            )));
        }
        if let Some(i) = params.iter().position(|a| !a.is_finite()) {
            return Err(TextureError::Invalid(format!(
                "texture PCA parameter {i} is not finite ({})",
                params[i]
            )));
        }
        Ok(())
    }

    /// Uploads the mean and the basis to `device` (the autodiff device when gradients with
    /// respect to the parameters are needed).
    pub fn to_device(&self, device: &Device) -> TexturePcaTensors {
        let n = self.mean.len();
        TexturePcaTensors {
            mean: Tensor::from_data(TensorData::new(self.mean.clone(), [n]), device),
            basis: Tensor::from_data(
                TensorData::new(self.basis.clone(), [n, self.num_components]),
                device,
            ),
            scale: self.scale,
        }
    }

    /// Least-squares parameters for a compact texture `texture` (`[3T]`, in `[0, 1]`), using
    /// only the texels `t` where `mask[t]` (`mask` has `T` entries; `None` = all texels).
    ///
    /// Solves, in colour units (`[0, 1]`),
    /// `(s^2 B_m^T B_m + ridge I) a = s B_m^T (texture_m - s mean_m)` with `s` the scale and
    /// `B_m` the masked rows of the basis (all three channels of each masked texel), by a
    /// Cholesky factorisation. The clamp of [`Self::texture`] is ignored. With parameters
    /// `~ N(0, 1)` (as [`Self::fit`] makes them), `ridge` = the colour noise variance gives the
    /// MAP estimate. Fails on wrong lengths, non-finite values, a negative ridge, an empty
    /// mask, or singular normal equations (use `ridge > 0` then).
    ///
    /// To project many textures with the same mask and ridge, build the normal equations
    /// once with [`Self::projector`] (the same numbers, bit for bit).
    pub fn project(
        &self,
        texture: &[f32],
        mask: Option<&[bool]>,
        ridge: f32,
    ) -> Result<Vec<f32>, TextureError> {
        self.check_texture(texture)?;
        self.projector(mask, ridge)?.project(texture)
    }

    fn check_texture(&self, texture: &[f32]) -> Result<(), TextureError> {
        let t = self.layout.num_texels();
        if texture.len() != 3 * t {
            return Err(TextureError::Invalid(format!(
                "texture to project has {} values, expected 3 x {t}",
                texture.len()
            )));
        }
        if let Some(i) = texture.iter().position(|x| !x.is_finite()) {
            return Err(TextureError::Invalid(format!(
                "texture value {i} to project is not finite"
            )));
        }
        Ok(())
    }

    /// The factorised normal equations of [`Self::project`] for one mask and ridge, to
    /// project any number of textures (each then costs `3T x K` instead of `3T x K^2 / 2`).
    /// Built on all cores (rayon), with every sum in the same order as a sequential loop,
    /// so the parameters equal [`Self::project`]'s bit for bit.
    ///
    /// Fails on a mask of the wrong length, a negative or non-finite ridge, an empty mask,
    /// or singular normal equations (use `ridge > 0` then).
    pub(crate) fn projector<'a>(
        &'a self,
        mask: Option<&'a [bool]>,
        ridge: f32,
    ) -> Result<PcaProjector<'a>, TextureError> {
        let t = self.layout.num_texels();
        let k = self.num_components;
        if let Some(m) = mask
            && m.len() != t
        {
            return Err(TextureError::Invalid(format!(
                "projection mask has {} entries, expected {t} texels",
                m.len()
            )));
        }
        if !(ridge.is_finite() && ridge >= 0.0) {
            return Err(TextureError::Invalid(format!(
                "ridge must be finite and >= 0, got {ridge}"
            )));
        }
        let used = 3 * mask.map_or(t, |m| m.iter().filter(|&&b| b).count());
        if used == 0 {
            return Err(TextureError::Invalid(
                "projection mask selects no texel".into(),
            ));
        }
        let mut ata = self.normal_matrix(mask);
        for a in 0..k {
            ata[a * k + a] += f64::from(ridge);
            for b in 0..a {
                ata[b * k + a] = ata[a * k + b];
            }
        }
        if !cholesky_factor(&mut ata, k) {
            return Err(TextureError::Invalid(format!(
                "the normal equations of the projection are singular ({} masked values do \
                 not determine {k} parameters); use ridge > 0",
                used
            )));
        }
        Ok(PcaProjector {
            pca: self,
            mask,
            factor: ata,
        })
    }

    /// The lower triangle of `s^2 B_m^T B_m` (row-major `k x k`, the upper triangle zero).
    ///
    /// Each entry is a sum over the masked values in increasing order, exactly as a single
    /// loop would add them; the work is split between threads by rows of the triangle (each
    /// entry belongs to one thread), over blocks of basis rows that stay in cache.
    fn normal_matrix(&self, mask: Option<&[bool]>) -> Vec<f64> {
        const ROWS_PER_BLOCK: usize = if cfg!(test) { 5 } else { 4096 };
        let t = self.layout.num_texels();
        let k = self.num_components;
        let s = f64::from(self.scale);
        // Rows of the triangle in groups of about equal work (row `a` has `a + 1` entries).
        let groups = (4 * rayon::current_num_threads()).clamp(1, k);
        let work = k * (k + 1) / 2;
        let mut bounds = vec![0usize];
        let mut acc = 0usize;
        for a in 0..k {
            acc += a + 1;
            if acc * groups >= work * bounds.len() && a + 1 < k {
                bounds.push(a + 1);
            }
        }
        bounds.push(k);
        bounds.dedup();
        let ranges: Vec<std::ops::Range<usize>> = bounds.windows(2).map(|w| w[0]..w[1]).collect();
        let mut parts: Vec<Vec<f64>> = ranges
            .iter()
            .map(|r| vec![0f64; r.clone().map(|a| a + 1).sum()])
            .collect();
        // The masked value indices, in order.
        let used: Vec<usize> = (0..3)
            .flat_map(|c| (0..t).map(move |ti| (c, ti)))
            .filter(|&(_, ti)| mask.is_none_or(|m| m[ti]))
            .map(|(c, ti)| c * t + ti)
            .collect();
        for block in used.chunks(ROWS_PER_BLOCK) {
            parts.par_iter_mut().zip(&ranges).for_each(|(part, range)| {
                let end = range.end;
                let mut row = vec![0f64; end];
                for &i in block {
                    for (r, &b) in row.iter_mut().zip(&self.basis[i * k..i * k + end]) {
                        *r = s * f64::from(b);
                    }
                    let mut off = 0;
                    for a in range.clone() {
                        let ra = row[a];
                        let line = &mut part[off..off + a + 1];
                        for (x, &rb) in line.iter_mut().zip(&row[..=a]) {
                            *x += ra * rb;
                        }
                        off += a + 1;
                    }
                }
            });
        }
        let mut ata = vec![0f64; k * k];
        for (part, range) in parts.iter().zip(&ranges) {
            let mut off = 0;
            for a in range.clone() {
                ata[a * k..a * k + a + 1].copy_from_slice(&part[off..off + a + 1]);
                off += a + 1;
            }
        }
        ata
    }

    /// Fits a PCA model over sample textures (each a compact `[3T]` texture on scale 1).
    ///
    /// Centres the samples, computes their `N x N` Gram matrix `G = X X^T` on `device`,
    /// decomposes it with `burn::linalg::svd` (`G` is symmetric positive semi-definite, so
    /// its singular vectors are its eigenvectors `u_k`, its singular values the eigenvalues
    /// `s_k`), and keeps `K` components. Basis column `k` is the unit covariance eigenvector
    /// times `sqrt(lambda_k)` with `lambda_k = s_k / (N - 1)`, i.e. `X^T u_k / sqrt(N - 1)`,
    /// so the samples' parameters have unit variance. Each column's sign makes its largest
    /// entry (in magnitude) positive. The model's scale is 1.
    ///
    /// Fails with fewer than 2 samples, `K` outside `1..=N-1`, or samples of the wrong
    /// length or with non-finite values.
    ///
    /// [`Self::fit_with_progress`] without progress reports.
    ///
    /// # Panics
    /// When the SVD does not converge (burn panics; a Gram matrix never needs more than a
    /// few sweeps).
    pub fn fit(
        layout: TextureLayout,
        samples: &[Vec<f32>],
        num_components: usize,
        device: &Device,
    ) -> Result<(Self, PcaFitReport), TextureError> {
        Self::fit_with_progress(layout, samples, num_components, device, &NoProgress)
    }

    /// [`Self::fit`], reporting its stages to `progress`: [`FitStage::Centre`] (blocks of the
    /// mean, then one step per sample), [`FitStage::Gram`], [`FitStage::Eigen`] and
    /// [`FitStage::Basis`] (the product, then blocks of rows).
    ///
    /// The host work (checks, mean, centring, the basis signs) runs on all cores (rayon);
    /// the products run on `device` (flex: gemm on rayon). Every value is summed in the
    /// same order as in a sequential loop, so the model is the same bit for bit for any
    /// number of threads.
    ///
    /// # Errors and panics
    /// As [`Self::fit`].
    pub(crate) fn fit_with_progress(
        layout: TextureLayout,
        samples: &[Vec<f32>],
        num_components: usize,
        device: &Device,
        progress: &dyn FitProgress,
    ) -> Result<(Self, PcaFitReport), TextureError> {
        let n = samples.len();
        let d = 3 * layout.num_texels();
        let k = num_components;
        if n < 2 {
            return Err(TextureError::Invalid(format!(
                "a PCA fit needs at least 2 samples, got {n}"
            )));
        }
        if k == 0 || k > n - 1 {
            return Err(TextureError::Invalid(format!(
                "{n} samples support 1 to {} components, {k} asked",
                n - 1
            )));
        }
        let bad = samples
            .par_iter()
            .position_first(|s| s.len() != d || s.iter().any(|x| !x.is_finite()));
        if let Some(i) = bad {
            let s = &samples[i];
            if s.len() != d {
                return Err(TextureError::Invalid(format!(
                    "sample {i} has {} values, expected 3 x {} texels",
                    s.len(),
                    layout.num_texels()
                )));
            }
            return Err(TextureError::Invalid(format!(
                "sample {i} has non-finite values"
            )));
        }
        let centre = StageCounter::new(progress, FitStage::Centre, d.div_ceil(MEAN_BLOCK) + n);
        // The mean: per value, the samples summed in order in f64.
        let mut mean = vec![0f32; d];
        mean.par_chunks_mut(MEAN_BLOCK)
            .enumerate()
            .for_each(|(b, out)| {
                let start = b * MEAN_BLOCK;
                let mut acc = vec![0f64; out.len()];
                for s in samples {
                    for (m, &x) in acc.iter_mut().zip(&s[start..start + out.len()]) {
                        *m += f64::from(x);
                    }
                }
                for (o, m) in out.iter_mut().zip(acc) {
                    *o = (m / n as f64) as f32;
                }
                centre.step();
            });
        let mut centred = vec![0f32; n * d];
        centred
            .par_chunks_mut(d.max(1))
            .zip(samples.par_iter())
            .for_each(|(out, s)| {
                for ((o, &x), &m) in out.iter_mut().zip(s).zip(&mean) {
                    *o = x - m;
                }
                centre.step();
            });
        centre.finish();
        let gram_stage = StageCounter::new(progress, FitStage::Gram, 1);
        let x = Tensor::<2>::from_data(TensorData::new(centred, [n, d]), device);
        let gram = x.clone().matmul(x.clone().transpose());
        gram_stage.finish();
        let eigen = StageCounter::new(progress, FitStage::Eigen, 1);
        let (u, s, _vt) = burn::linalg::svd::<2, 1>(gram, SVD_SWEEPS);
        let s: Vec<f32> = bitt_stdx::to_host(s)?;
        eigen.finish();
        let basis_stage = StageCounter::new(progress, FitStage::Basis, 1 + d.div_ceil(BASIS_BLOCK));
        let u_k = u.narrow(1, 0, k);
        let basis_t = x
            .transpose()
            .matmul(u_k)
            .mul_scalar(1.0 / ((n - 1) as f64).sqrt());
        let mut basis: Vec<f32> = bitt_stdx::to_host(basis_t.reshape([d * k]))?;
        basis_stage.step();
        flip_to_positive_peaks(&mut basis, k, &basis_stage);
        basis_stage.finish();
        let total: f64 = s.iter().map(|&x| f64::from(x.max(0.0))).sum();
        let report = PcaFitReport {
            explained_variance_ratio: s
                .iter()
                .take(k)
                .map(|&x| {
                    if total > 0.0 {
                        (f64::from(x.max(0.0)) / total) as f32
                    } else {
                        0.0
                    }
                })
                .collect(),
            total_variance: (total / (n - 1) as f64) as f32,
        };
        Ok((Self::new(layout, mean, basis, k, 1.0)?, report))
    }

    /// Serializes the model (arrays as `f32`, the layout's texels, UV layout and texel
    /// faces when present, the size and scale as metadata) to safetensors bytes.
    pub fn to_safetensors(&self, path_for_errors: &Path) -> Result<Vec<u8>, TextureError> {
        let (entries, meta) = self.entries();
        Ok(st::serialize(path_for_errors, &entries, meta)?)
    }

    fn entries(&self) -> (Vec<st::Entry>, HashMap<String, String>) {
        let l = &self.layout;
        let t = l.num_texels();
        let mut e: Vec<st::Entry> = vec![
            (
                "mean".into(),
                Dtype::F32,
                vec![3 * t],
                st::f32_bytes(&self.mean),
            ),
            (
                "basis".into(),
                Dtype::F32,
                vec![3 * t, self.num_components],
                st::f32_bytes(&self.basis),
            ),
        ];
        e.extend(layout_entries(l));
        let meta = HashMap::from([
            ("format".to_string(), PCA_FORMAT.to_string()),
            ("width".to_string(), l.width.to_string()),
            ("height".to_string(), l.height.to_string()),
            ("scale".to_string(), self.scale.to_string()),
        ]);
        (e, meta)
    }

    /// Writes the model to `path` as safetensors, atomically (see [`Self::to_safetensors`]).
    /// Memory: the encoded bytes and one serialized copy are held next to the model (for
    /// HTML's 250 MB `f32` basis about 500 MB on top of the model).
    pub fn save_safetensors(&self, path: &Path) -> Result<(), TextureError> {
        let (entries, meta) = self.entries();
        Ok(st::write(path, &entries, meta)?)
    }

    /// Loads a model written by [`Self::save_safetensors`].
    pub fn load_safetensors(path: &Path) -> Result<Self, TextureError> {
        let bytes = st::read_file(path)?;
        Self::from_safetensors(&bytes, path)
    }

    /// Parses safetensors bytes written by [`Self::to_safetensors`]; `path` names them in
    /// errors.
    pub fn from_safetensors(bytes: &[u8], path: &Path) -> Result<Self, TextureError> {
        let r = st::Reader::new(bytes, path, PCA_FORMAT)?;
        let scale: f32 = r.meta("scale")?;
        let layout = read_layout(&r)?;
        let t = layout.num_texels();
        let (_, mean) = r.values::<f32>("mean", &[Some(3 * t)])?;
        let (bs, basis) = r.values::<f32>("basis", &[Some(3 * t), None])?;
        Self::new(layout, mean, basis, bs[1], scale).map_err(|e| r.err(e.to_string()).into())
    }
}

/// Safetensors entries describing a layout: `texels` (U32 `[T, 2]`, row then column),
/// optional `uv_coords` (F64 `[n, 2]`) and `uv_faces` (U32 `[F, 3]`), optional
/// `texel_faces` (U32 `[T]`) and `texel_barycentrics` (F32 `[T, 3]`). Width and height go
/// in the metadata (`width`, `height`).
pub(crate) fn layout_entries(l: &TextureLayout) -> Vec<st::Entry> {
    let t = l.num_texels();
    let mut e: Vec<st::Entry> = vec![(
        "texels".into(),
        Dtype::U32,
        vec![t, 2],
        st::u32_bytes(l.texels.iter().flat_map(|&(r, c)| [r, c])),
    )];
    if let Some(uv) = &l.uv {
        e.push((
            "uv_coords".into(),
            Dtype::F64,
            vec![uv.uvs.len(), 2],
            st::f64_bytes(uv.uvs.iter().flat_map(|p| [p.x, p.y])),
        ));
        e.push((
            "uv_faces".into(),
            Dtype::U32,
            vec![uv.faces.len(), 3],
            st::u32_bytes(uv.faces.iter().flatten().copied()),
        ));
    }
    if let Some(tf) = l.texel_faces() {
        e.push((
            "texel_faces".into(),
            Dtype::U32,
            vec![t],
            st::u32_bytes(tf.iter().map(|&(f, _)| f)),
        ));
        let barys: Vec<f32> = tf.iter().flat_map(|&(_, b)| b).collect();
        e.push((
            "texel_barycentrics".into(),
            Dtype::F32,
            vec![t, 3],
            st::f32_bytes(&barys),
        ));
    }
    e
}

/// Reads what [`layout_entries`] wrote.
pub(crate) fn read_layout(r: &st::Reader<'_>) -> Result<TextureLayout, TextureError> {
    let width: usize = r.meta("width")?;
    let height: usize = r.meta("height")?;
    let (_, tx) = r.values::<u32>("texels", &[None, Some(2)])?;
    let texels: Vec<(u32, u32)> = tx.chunks_exact(2).map(|c| (c[0], c[1])).collect();
    let t = texels.len();
    let uv = if r.has("uv_coords") || r.has("uv_faces") {
        let (_, uvs) = r.values::<f64>("uv_coords", &[None, Some(2)])?;
        let (_, faces) = r.values::<u32>("uv_faces", &[None, Some(3)])?;
        let uvs: Vec<DVec2> = uvs
            .chunks_exact(2)
            .map(|c| DVec2::new(c[0], c[1]))
            .collect();
        if let Some(i) = faces.iter().find(|&&i| i as usize >= uvs.len()) {
            return Err(r
                .err(format!(
                    "uv_faces uses UV vertex {i}, but there are {}",
                    uvs.len()
                ))
                .into());
        }
        Some(UvLayout {
            uvs,
            faces: faces.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        })
    } else {
        None
    };
    let layout = if r.has("texel_faces") || r.has("texel_barycentrics") {
        let (_, f) = r.values::<u32>("texel_faces", &[Some(t)])?;
        let (_, b) = r.values::<f32>("texel_barycentrics", &[Some(t), Some(3)])?;
        let tf = f
            .into_iter()
            .zip(b.chunks_exact(3))
            .map(|(f, b)| (f, [b[0], b[1], b[2]]))
            .collect();
        TextureLayout::from_texel_faces(width, height, texels, uv, tf)
    } else {
        TextureLayout::from_texels(width, height, texels, uv)
    };
    layout.map_err(|e| r.err(e.to_string()).into())
}

impl TexturePcaTensors {
    /// `clamp((mean + basis a) * scale, 0, 1)` as burn ops, differentiable in `params`
    /// (the clamp passes no gradient where it clips).
    ///
    /// # Shapes
    /// params `[K]` -> texture `[3, T]` in `[0, 1]`
    ///
    /// # Panics
    /// When `params` does not have `K` entries.
    pub fn texture(&self, params: Tensor<1>) -> Tensor<2> {
        let [n, k] = self.basis.dims();
        self.basis
            .clone()
            .matmul(params.reshape([k, 1]))
            .reshape([n])
            .add(self.mean.clone())
            .mul_scalar(self.scale)
            .clamp(0.0, 1.0)
            .reshape([3, n / 3])
    }

    /// [`Self::texture`] for a batch of parameter vectors (e.g. both hands).
    ///
    /// # Shapes
    /// params `[B, K]` -> textures `[B, 3, T]` in `[0, 1]`
    ///
    /// # Panics
    /// When `params` does not have `K` columns.
    pub fn textures(&self, params: Tensor<2>) -> Tensor<3> {
        let [n, _] = self.basis.dims();
        let [b, _] = params.dims();
        params
            .matmul(self.basis.clone().transpose())
            .add(self.mean.clone().unsqueeze::<2>())
            .mul_scalar(self.scale)
            .clamp(0.0, 1.0)
            .reshape([b, 3, n / 3])
    }
}

/// Negates the basis columns (`[d, k]` row-major) whose largest entry in magnitude (the
/// first such row) is negative. Row blocks are scanned in parallel and combined in row order
/// with the same strict comparison, so the chosen entry is the sequential scan's.
fn flip_to_positive_peaks(basis: &mut [f32], k: usize, stage: &StageCounter<'_>) {
    let peaks: Vec<Vec<(f32, f32)>> = basis
        .par_chunks(BASIS_BLOCK * k)
        .map(|block| {
            let mut peaks = vec![(0f32, 1f32); k];
            for row in block.chunks_exact(k) {
                for (p, &v) in peaks.iter_mut().zip(row) {
                    if v.abs() > p.0 {
                        *p = (v.abs(), v.signum());
                    }
                }
            }
            stage.step();
            peaks
        })
        .collect();
    let mut best = vec![(0f32, 1f32); k];
    for block in &peaks {
        for (b, &p) in best.iter_mut().zip(block) {
            if p.0 > b.0 {
                *b = p;
            }
        }
    }
    let flip: Vec<bool> = best.iter().map(|&(_, sign)| sign < 0.0).collect();
    if flip.iter().any(|&f| f) {
        basis.par_chunks_mut(BASIS_BLOCK * k).for_each(|block| {
            for row in block.chunks_exact_mut(k) {
                for (v, &f) in row.iter_mut().zip(&flip) {
                    if f {
                        *v = -*v;
                    }
                }
            }
        });
    }
}

/// The factorised normal equations of [`TexturePca::project`] for one mask and ridge (see
/// [`TexturePca::projector`]).
#[derive(Debug, Clone)]
pub struct PcaProjector<'a> {
    pca: &'a TexturePca,
    mask: Option<&'a [bool]>,
    /// Cholesky factor in the lower triangle, row-major `k x k`.
    factor: Vec<f64>,
}

impl PcaProjector<'_> {
    /// The least-squares parameters of `texture` (`[3T]`, in `[0, 1]`), as
    /// [`TexturePca::project`]. Fails on a wrong length or non-finite values.
    pub fn project(&self, texture: &[f32]) -> Result<Vec<f32>, TextureError> {
        let pca = self.pca;
        pca.check_texture(texture)?;
        let t = pca.layout.num_texels();
        let k = pca.num_components;
        let s = f64::from(pca.scale);
        let mut atb = vec![0f64; k];
        let mut row = vec![0f64; k];
        for c in 0..3 {
            for ti in 0..t {
                if self.mask.is_some_and(|m| !m[ti]) {
                    continue;
                }
                let i = c * t + ti;
                for (r, &b) in row.iter_mut().zip(&pca.basis[i * k..(i + 1) * k]) {
                    *r = s * f64::from(b);
                }
                let resid = f64::from(texture[i]) - s * f64::from(pca.mean[i]);
                for (x, &ra) in atb.iter_mut().zip(&row) {
                    *x += ra * resid;
                }
            }
        }
        let sol = cholesky_solve_factored(&self.factor, &atb, k);
        Ok(sol.into_iter().map(|x| x as f32).collect())
    }
}

/// Factorises a symmetric positive definite `k x k` matrix (row-major) in place: its lower
/// triangle becomes the Cholesky factor. `false` when `A` is not numerically positive
/// definite.
fn cholesky_factor(a: &mut [f64], k: usize) -> bool {
    let max_diag = (0..k).map(|i| a[i * k + i].abs()).fold(0.0, f64::max);
    let tol = max_diag * 1e-13;
    for j in 0..k {
        let d = a[j * k + j] - (0..j).map(|p| a[j * k + p] * a[j * k + p]).sum::<f64>();
        if d.is_nan() || d <= tol || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        a[j * k + j] = d;
        for i in j + 1..k {
            let v = a[i * k + j] - (0..j).map(|p| a[i * k + p] * a[j * k + p]).sum::<f64>();
            a[i * k + j] = v / d;
        }
    }
    true
}

/// Solves `L L^T x = b` with `L` the lower triangle of `l` (from [`cholesky_factor`]).
fn cholesky_solve_factored(l: &[f64], b: &[f64], k: usize) -> Vec<f64> {
    // L y = b, then L^T x = y.
    let mut y = vec![0f64; k];
    for i in 0..k {
        y[i] = (b[i] - (0..i).map(|p| l[i * k + p] * y[p]).sum::<f64>()) / l[i * k + i];
    }
    let mut x = vec![0f64; k];
    for i in (0..k).rev() {
        x[i] = (y[i] - (i + 1..k).map(|p| l[p * k + i] * x[p]).sum::<f64>()) / l[i * k + i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_testkit::{Rng, assert_close, devices, to_vec};

    use crate::test_util::{Recorder, on_threads, temp_dir};

    /// A 6x5 layout with 12 texels in a scattered order, and a random model with colours
    /// comfortably inside (0, 1) for parameters in [-1, 1].
    fn model(k: usize, scale: f32, seed: u64) -> TexturePca {
        let texels = vec![
            (0, 0),
            (4, 5),
            (1, 2),
            (3, 3),
            (2, 0),
            (0, 5),
            (4, 1),
            (1, 4),
            (2, 2),
            (3, 0),
            (0, 3),
            (4, 4),
        ];
        let layout = TextureLayout::from_texels(6, 5, texels, None).unwrap();
        let n = 3 * layout.num_texels();
        let mut r = Rng::new(seed);
        let mean = (0..n).map(|_| r.uniform_f32(0.4, 0.6) / scale).collect();
        let basis = (0..n * k)
            .map(|_| r.uniform_f32(-0.05, 0.05) / scale)
            .collect();
        TexturePca::new(layout, mean, basis, k, scale).unwrap()
    }

    /// `(mean + basis a) * scale` in f64, unclamped.
    fn direct(m: &TexturePca, a: &[f64]) -> Vec<f64> {
        let k = m.num_components;
        (0..m.mean.len())
            .map(|i| {
                let v: f64 = f64::from(m.mean[i])
                    + (0..k)
                        .map(|j| f64::from(m.basis[i * k + j]) * a[j])
                        .sum::<f64>();
                v * f64::from(m.scale)
            })
            .collect()
    }

    #[test]
    fn texture_matches_the_formula_and_clamps() {
        let m = model(4, 1.0 / 255.0, 1);
        let a = [0.5f32, -1.0, 0.25, 0.8];
        let a64: Vec<f64> = a.iter().map(|&x| f64::from(x)).collect();
        let want: Vec<f32> = direct(&m, &a64).iter().map(|&x| x as f32).collect();
        assert_close(&m.texture(&a).unwrap(), &want, 1e-6, "texture");
        // Huge parameters clip to [0, 1].
        let tex = m.texture(&[1e4, -1e4, 1e4, 0.0]).unwrap();
        assert!(tex.iter().all(|&x| (0.0..=1.0).contains(&x)));
        assert!(tex.contains(&0.0) && tex.contains(&1.0));
    }

    #[test]
    fn bad_arguments_are_refused() {
        let m = model(3, 1.0, 2);
        let e = |r: Result<Vec<f32>, TextureError>| r.unwrap_err().to_string();
        assert!(e(m.texture(&[0.0; 2])).contains("takes 3 parameters, got 2"));
        assert!(e(m.texture(&[0.0, f32::NAN, 0.0])).contains("parameter 1 is not finite"));
        let l = m.layout.clone();
        let ne = |r: Result<TexturePca, TextureError>| r.unwrap_err().to_string();
        assert!(
            ne(TexturePca::new(
                l.clone(),
                vec![0.0; 35],
                vec![0.0; 108],
                3,
                1.0
            ))
            .contains("mean")
        );
        assert!(
            ne(TexturePca::new(
                l.clone(),
                vec![0.0; 36],
                vec![0.0; 107],
                3,
                1.0
            ))
            .contains("basis")
        );
        assert!(
            ne(TexturePca::new(l.clone(), vec![0.0; 36], vec![], 0, 1.0)).contains("at least one")
        );
        assert!(
            ne(TexturePca::new(
                l.clone(),
                vec![0.0; 36],
                vec![0.0; 36],
                1,
                0.0
            ))
            .contains("scale")
        );
        let mut b = vec![0.0; 108];
        b[50] = f32::INFINITY;
        assert!(
            ne(TexturePca::new(l.clone(), vec![0.0; 36], b, 3, 1.0))
                .contains("row 16, component 2")
        );
        assert!(e(m.project(&[0.5; 35], None, 0.0)).contains("expected 3 x 12"));
        assert!(e(m.project(&[0.5; 36], Some(&[true; 11]), 0.0)).contains("mask has 11"));
        assert!(e(m.project(&[0.5; 36], None, -1.0)).contains("ridge"));
        assert!(e(m.project(&[0.5; 36], Some(&[false; 12]), 0.0)).contains("no texel"));
        let mut t = vec![0.5; 36];
        t[3] = f32::NAN;
        assert!(e(m.project(&t, None, 0.0)).contains("not finite"));
        // One texel gives 3 equations: fine for K = 3 only with an independent basis, never
        // for K = 4 without a ridge.
        let m4 = model(4, 1.0, 3);
        let mut one = [false; 12];
        one[5] = true;
        assert!(e(m4.project(&[0.5; 36], Some(&one), 0.0)).contains("singular"));
        assert!(m4.project(&[0.5; 36], Some(&one), 1e-3).is_ok());
    }

    #[test]
    fn tensor_texture_matches_plain_and_batches() {
        let m = model(4, 1.0 / 255.0, 4);
        let a = [0.3f32, -0.7, 0.9, -0.1];
        let b = [-0.4f32, 0.2, 0.0, 0.6];
        let plain_a = m.texture(&a).unwrap();
        let plain_b = m.texture(&b).unwrap();
        for (name, device) in devices() {
            let pt = m.to_device(&device);
            let ta = pt.texture(Tensor::from_data(TensorData::new(a.to_vec(), [4]), &device));
            assert_eq!(ta.dims(), [3, 12], "{name}");
            assert_close(&to_vec(ta), &plain_a, 1e-5, name);
            let ab: Vec<f32> = a.iter().chain(&b).copied().collect();
            let tb = pt.textures(Tensor::from_data(TensorData::new(ab, [2, 4]), &device));
            assert_eq!(tb.dims(), [2, 3, 12], "{name}");
            let both: Vec<f32> = plain_a.iter().chain(&plain_b).copied().collect();
            assert_close(&to_vec(tb), &both, 1e-5, name);
        }
    }

    /// loss(a) = sum(w * image(texture(a))^2) over the UV image, background included.
    #[test]
    fn gradient_reaches_pca_params_through_the_uv_image() {
        let m = model(4, 1.0 / 255.0, 5);
        let a = [0.3f64, -0.7, 0.9, -0.1];
        let (w_img, h_img) = (m.layout.width, m.layout.height);
        let mut r = Rng::new(9);
        let weights: Vec<f32> = (0..3 * w_img * h_img)
            .map(|_| r.uniform_f32(-1.0, 1.0))
            .collect();
        let bg = [0.2f32, 0.4, 0.6];
        // The same loss in f64 on the plain path (no clamping happens at these values).
        let loss64 = |a: &[f64]| -> f64 {
            let tex: Vec<f32> = direct(&m, a).iter().map(|&x| x as f32).collect();
            let img = m.layout.compact_to_image(&tex, bg).unwrap();
            img.iter()
                .zip(&weights)
                .map(|(&x, &w)| f64::from(w) * f64::from(x) * f64::from(x))
                .sum()
        };
        let tex = direct(&m, &a);
        assert!(tex.iter().all(|&x| x > 0.05 && x < 0.95));
        // Analytic: dL/da_k = sum_i 2 w(i) T_i s B_ik over compact values i.
        let (t, k) = (m.layout.num_texels(), 4);
        let mut analytic = vec![0f64; k];
        for c in 0..3 {
            for (ti, &(row, col)) in m.layout.texels.iter().enumerate() {
                let i = c * t + ti;
                let w = f64::from(weights[c * w_img * h_img + row as usize * w_img + col as usize]);
                for (j, g) in analytic.iter_mut().enumerate() {
                    *g += 2.0 * w * tex[i] * f64::from(m.scale) * f64::from(m.basis[i * k + j]);
                }
            }
        }
        // Central finite differences in f64 agree with the analytic gradient.
        let h = 1e-2;
        for j in 0..k {
            let (mut ap, mut am) = (a.to_vec(), a.to_vec());
            ap[j] += h;
            am[j] -= h;
            let fd = (loss64(&ap) - loss64(&am)) / (2.0 * h);
            assert!(
                (fd - analytic[j]).abs() <= 1e-2 * analytic[j].abs().max(1e-3),
                "fd {fd} vs analytic {}",
                analytic[j]
            );
        }
        let want: Vec<f32> = analytic.iter().map(|&x| x as f32).collect();
        for (name, device) in devices() {
            let ad = device.autodiff();
            let pt = m.to_device(&ad);
            let params = Tensor::<1>::from_data(
                TensorData::new(a.iter().map(|&x| x as f32).collect::<Vec<_>>(), [4]),
                &ad,
            )
            .require_grad();
            let compact = pt.texture(params.clone());
            let img = m.layout.compact_to_image_tensor(compact, bg);
            let w =
                Tensor::<3>::from_data(TensorData::new(weights.clone(), [3, h_img, w_img]), &ad);
            let loss = (img.clone() * img * w).sum();
            let got_loss = to_vec(loss.clone())[0];
            assert!((f64::from(got_loss) - loss64(&a)).abs() < 1e-4, "{name}");
            let grads = loss.backward();
            let g = params.grad(&grads).expect("parameter gradient");
            assert_close(&to_vec(g), &want, 1e-3, name);
        }
    }

    #[test]
    fn project_recovers_known_params_from_half_the_texels() {
        for scale in [1.0, 1.0 / 255.0] {
            let m = model(5, scale, 6);
            let a = [0.8f32, -0.6, 0.3, -0.9, 0.5];
            let tex = m.texture(&a).unwrap();
            let mask: Vec<bool> = (0..12).map(|t| t % 2 == 0).collect();
            let got = m.project(&tex, Some(&mask), 0.0).unwrap();
            assert_close(&got, &a, 1e-3, "masked projection");
            let all = m.project(&tex, None, 0.0).unwrap();
            assert_close(&all, &a, 1e-3, "projection");
            // Texels outside the mask do not matter.
            let mut spoiled = tex.clone();
            for c in 0..3 {
                spoiled[c * 12 + 1] = 0.0;
            }
            assert_close(
                &m.project(&spoiled, Some(&mask), 0.0).unwrap(),
                &a,
                1e-3,
                "masked-out texels ignored",
            );
            // A ridge shrinks the estimate towards the mean.
            let shrunk = m.project(&tex, Some(&mask), 1.0).unwrap();
            let norm = |v: &[f32]| v.iter().map(|x| x * x).sum::<f32>();
            assert!(norm(&shrunk) < 0.5 * norm(&a));
        }
    }

    /// Samples of a known rank-3 model plus its mean.
    fn low_rank_samples(n: usize, seed: u64) -> (TextureLayout, Vec<Vec<f32>>, Vec<Vec<f32>>) {
        let m = model(3, 1.0, seed);
        let d = m.mean.len();
        let dirs: Vec<Vec<f32>> = (0..3)
            .map(|j| (0..d).map(|i| m.basis[i * 3 + j]).collect())
            .collect();
        let mut r = Rng::new(seed + 100);
        let samples = (0..n)
            .map(|_| {
                let z: Vec<f32> = (0..3).map(|_| r.uniform_f32(-2.0, 2.0)).collect();
                (0..d)
                    .map(|i| m.mean[i] + (0..3).map(|j| z[j] * dirs[j][i]).sum::<f32>())
                    .collect()
            })
            .collect();
        (m.layout, samples, dirs)
    }

    #[test]
    fn fit_recovers_a_low_rank_subspace() {
        let (layout, samples, dirs) = low_rank_samples(12, 7);
        let n = samples.len();
        let d = samples[0].len();
        // Direct total variance (1/(N-1) normalisation).
        let mean: Vec<f64> = (0..d)
            .map(|i| samples.iter().map(|s| f64::from(s[i])).sum::<f64>() / n as f64)
            .collect();
        let total: f64 = samples
            .iter()
            .flat_map(|s| {
                s.iter()
                    .zip(&mean)
                    .map(|(&x, &m)| (f64::from(x) - m).powi(2))
            })
            .sum::<f64>()
            / (n - 1) as f64;
        for (name, device) in devices() {
            let (m, report) = TexturePca::fit(layout.clone(), &samples, 5, &device).unwrap();
            assert_eq!(m.num_components, 5);
            assert_eq!(m.scale, 1.0);
            let r = &report.explained_variance_ratio;
            assert_eq!(r.len(), 5);
            let top3: f32 = r[..3].iter().sum();
            assert!(top3 > 0.9999, "{name}: {r:?}");
            assert!(r[3] < 1e-4 && r[4] < 1e-4, "{name}: {r:?}");
            assert!(r[0] >= r[1] && r[1] >= r[2], "{name}: {r:?}");
            assert!(
                (f64::from(report.total_variance) - total).abs() < 1e-4 * total,
                "{name}: {} vs {total}",
                report.total_variance
            );
            // The true directions lie in the span of the first three components.
            let cols: Vec<Vec<f64>> = (0..3)
                .map(|j| (0..d).map(|i| f64::from(m.basis[i * 5 + j])).collect())
                .collect();
            // Gram-Schmidt the fitted columns (they are orthogonal already, up to scale).
            let unit: Vec<Vec<f64>> = cols
                .iter()
                .map(|c| {
                    let nrm = c.iter().map(|x| x * x).sum::<f64>().sqrt();
                    c.iter().map(|x| x / nrm).collect()
                })
                .collect();
            for (a, ua) in unit.iter().enumerate() {
                for ub in &unit[a + 1..] {
                    let dot: f64 = ua.iter().zip(ub).map(|(x, y)| x * y).sum();
                    assert!(dot.abs() < 1e-3, "{name}: columns not orthogonal ({dot})");
                }
            }
            for v in &dirs {
                let v: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
                let vv: f64 = v.iter().map(|x| x * x).sum();
                let proj: f64 = unit
                    .iter()
                    .map(|u| u.iter().zip(&v).map(|(a, b)| a * b).sum::<f64>().powi(2))
                    .sum();
                assert!(proj / vv > 0.9999, "{name}: {}", proj / vv);
            }
            // With K = 3 (components 4 and 5 above are numerically zero, so projecting on
            // them is singular): the samples' parameters have unit variance per component,
            // and every sample is reproduced by its projection.
            let (m, _) = TexturePca::fit(layout.clone(), &samples, 3, &device).unwrap();
            let params: Vec<Vec<f32>> = samples
                .iter()
                .map(|s| m.project(s, None, 0.0).unwrap())
                .collect();
            for j in 0..3 {
                let var: f32 = params.iter().map(|p| p[j] * p[j]).sum::<f32>() / (n - 1) as f32;
                assert!(
                    (var - 1.0).abs() < 1e-2,
                    "{name}: component {j} variance {var}"
                );
            }
            for (s, p) in samples.iter().zip(&params) {
                assert_close(&m.texture(p).unwrap(), s, 1e-4, name);
            }
            // Each column's largest entry is positive.
            for j in 0..3 {
                let big = (0..d)
                    .map(|i| m.basis[i * 3 + j])
                    .fold(0f32, |b, x| if x.abs() > b.abs() { x } else { b });
                assert!(big >= 0.0, "{name}");
            }
        }
    }

    /// [`TexturePca::fit`] as it was before it ran on rayon (sequential mean, centring and
    /// sign scan), the reference the parallel fit must equal bit for bit.
    fn previous_fit(
        layout: TextureLayout,
        samples: &[Vec<f32>],
        k: usize,
        device: &Device,
    ) -> (TexturePca, PcaFitReport) {
        let n = samples.len();
        let d = 3 * layout.num_texels();
        let mut mean64 = vec![0f64; d];
        for s in samples {
            for (m, &x) in mean64.iter_mut().zip(s) {
                *m += f64::from(x);
            }
        }
        let mean: Vec<f32> = mean64.iter().map(|&m| (m / n as f64) as f32).collect();
        let mut centred = Vec::with_capacity(n * d);
        for s in samples {
            centred.extend(s.iter().zip(&mean).map(|(&x, &m)| x - m));
        }
        let x = Tensor::<2>::from_data(TensorData::new(centred, [n, d]), device);
        let gram = x.clone().matmul(x.clone().transpose());
        let (u, s, _vt) = burn::linalg::svd::<2, 1>(gram, SVD_SWEEPS);
        let s: Vec<f32> = bitt_stdx::to_host(s).unwrap();
        let basis_t = x
            .transpose()
            .matmul(u.narrow(1, 0, k))
            .mul_scalar(1.0 / ((n - 1) as f64).sqrt());
        let mut basis: Vec<f32> = bitt_stdx::to_host(basis_t.reshape([d * k])).unwrap();
        for c in 0..k {
            let (mut big, mut sign) = (0f32, 1f32);
            for r in 0..d {
                let v = basis[r * k + c];
                if v.abs() > big {
                    big = v.abs();
                    sign = v.signum();
                }
            }
            if sign < 0.0 {
                for r in 0..d {
                    basis[r * k + c] = -basis[r * k + c];
                }
            }
        }
        let total: f64 = s.iter().map(|&x| f64::from(x.max(0.0))).sum();
        let report = PcaFitReport {
            explained_variance_ratio: s
                .iter()
                .take(k)
                .map(|&x| (f64::from(x.max(0.0)) / total) as f32)
                .collect(),
            total_variance: (total / (n - 1) as f64) as f32,
        };
        (
            TexturePca::new(layout, mean, basis, k, 1.0).unwrap(),
            report,
        )
    }

    /// [`TexturePca::project`] as it was before the projector (one sequential loop).
    fn previous_project(
        m: &TexturePca,
        texture: &[f32],
        mask: Option<&[bool]>,
        ridge: f32,
    ) -> Vec<f32> {
        let t = m.layout.num_texels();
        let k = m.num_components;
        let s = f64::from(m.scale);
        let mut ata = vec![0f64; k * k];
        let mut atb = vec![0f64; k];
        let mut row = vec![0f64; k];
        for c in 0..3 {
            for ti in 0..t {
                if mask.is_some_and(|m| !m[ti]) {
                    continue;
                }
                let i = c * t + ti;
                for (r, &b) in row.iter_mut().zip(&m.basis[i * k..(i + 1) * k]) {
                    *r = s * f64::from(b);
                }
                let resid = f64::from(texture[i]) - s * f64::from(m.mean[i]);
                for a in 0..k {
                    let ra = row[a];
                    atb[a] += ra * resid;
                    let line = &mut ata[a * k..a * k + a + 1];
                    for (x, &rb) in line.iter_mut().zip(&row[..=a]) {
                        *x += ra * rb;
                    }
                }
            }
        }
        for a in 0..k {
            ata[a * k + a] += f64::from(ridge);
            for b in 0..a {
                ata[b * k + a] = ata[a * k + b];
            }
        }
        assert!(cholesky_factor(&mut ata, k));
        let sol = cholesky_solve_factored(&ata, &atb, k);
        sol.into_iter().map(|x| x as f32).collect()
    }

    /// Low-rank samples plus noise (so every component is fitted to something).
    fn noisy_samples(n: usize, seed: u64) -> (TextureLayout, Vec<Vec<f32>>) {
        let (layout, mut samples, _) = low_rank_samples(n, seed);
        let mut r = Rng::new(seed + 7);
        for s in &mut samples {
            for x in s.iter_mut() {
                *x += r.uniform_f32(-0.02, 0.02);
            }
        }
        (layout, samples)
    }

    #[test]
    fn parallel_fit_equals_the_sequential_fit_bit_for_bit() {
        let (layout, samples) = noisy_samples(11, 21);
        for (name, device) in devices() {
            let want = previous_fit(layout.clone(), &samples, 6, &device);
            for threads in [1, 2, 3, 8] {
                let got = on_threads(threads, || {
                    TexturePca::fit(layout.clone(), &samples, 6, &device).unwrap()
                });
                assert_eq!(got, want, "{name}, {threads} threads");
            }
        }
    }

    #[test]
    fn fit_reports_monotone_progress_to_each_total() {
        let (layout, samples) = noisy_samples(9, 22);
        let d = samples[0].len();
        for threads in [1, 3] {
            let rec = Recorder::default();
            let (m, _) = on_threads(threads, || {
                TexturePca::fit_with_progress(layout.clone(), &samples, 4, &Device::flex(), &rec)
                    .unwrap()
            });
            let totals = rec.check(&[
                FitStage::Centre,
                FitStage::Gram,
                FitStage::Eigen,
                FitStage::Basis,
            ]);
            assert_eq!(
                totals,
                [
                    d.div_ceil(MEAN_BLOCK) + 9,
                    1,
                    1,
                    1 + d.div_ceil(BASIS_BLOCK)
                ]
            );
            // Every block and sample is one step: no count is skipped.
            let calls = rec.0.lock().unwrap();
            let centre = calls.iter().filter(|c| c.0 == FitStage::Centre).count();
            assert_eq!(centre, totals[0] + 1);
            assert_eq!(
                m,
                TexturePca::fit(layout.clone(), &samples, 4, &Device::flex())
                    .unwrap()
                    .0
            );
        }
        // A closure is a `FitProgress` too.
        let last = Mutex::new(None);
        let f = |stage: FitStage, done: usize, total: usize| {
            *last.lock().unwrap() = Some((stage, done, total));
        };
        TexturePca::fit_with_progress(layout, &samples, 2, &Device::flex(), &f).unwrap();
        let (stage, done, total) = last.lock().unwrap().unwrap();
        assert_eq!((stage, done), (FitStage::Basis, total));
        assert_eq!(stage.label(), "basis");
    }

    #[test]
    fn projector_equals_the_sequential_projection_bit_for_bit() {
        let (layout, samples) = noisy_samples(14, 23);
        let (m, _) = TexturePca::fit(layout, &samples, 9, &Device::flex()).unwrap();
        let half: Vec<bool> = (0..12).map(|t| t % 3 != 1).collect();
        for (mask, ridge) in [(None, 1e-4), (Some(&half[..]), 1e-3), (None, 0.0)] {
            let want: Vec<Vec<f32>> = samples
                .iter()
                .map(|s| previous_project(&m, s, mask, ridge))
                .collect();
            for threads in [1, 2, 5] {
                let got: Vec<Vec<f32>> = on_threads(threads, || {
                    let p = m.projector(mask, ridge).unwrap();
                    samples.iter().map(|s| p.project(s).unwrap()).collect()
                });
                assert_eq!(got, want, "{threads} threads, ridge {ridge}");
                let one: Vec<Vec<f32>> = on_threads(threads, || {
                    samples
                        .iter()
                        .map(|s| m.project(s, mask, ridge).unwrap())
                        .collect()
                });
                assert_eq!(one, want);
            }
        }
        let p = m.projector(None, 0.1).unwrap();
        assert!(p.project(&[0.5; 35]).is_err());
        assert!(p.project(&[f32::NAN; 36]).is_err());
    }

    #[test]
    fn fit_refuses_bad_input() {
        let (layout, samples, _) = low_rank_samples(4, 8);
        let dev = Device::flex();
        let e = |r: Result<(TexturePca, PcaFitReport), TextureError>| r.unwrap_err().to_string();
        assert!(e(TexturePca::fit(layout.clone(), &samples[..1], 1, &dev)).contains("at least 2"));
        assert!(e(TexturePca::fit(layout.clone(), &samples, 4, &dev)).contains("1 to 3"));
        assert!(e(TexturePca::fit(layout.clone(), &samples, 0, &dev)).contains("1 to 3"));
        let mut bad = samples.clone();
        bad[2].pop();
        assert!(e(TexturePca::fit(layout.clone(), &bad, 2, &dev)).contains("sample 2"));
        let mut bad = samples.clone();
        bad[1][4] = f32::NAN;
        assert!(e(TexturePca::fit(layout, &bad, 2, &dev)).contains("non-finite"));
    }

    #[test]
    fn safetensors_round_trip_and_bad_files() {
        let dir = temp_dir("pca-st");
        // A plain layout and one from UV triangles (with texel faces and the UV layout).
        let plain = model(3, 1.0 / 255.0, 10);
        let uv = UvLayout {
            uvs: vec![
                DVec2::new(0.0, 0.0),
                DVec2::new(1.0, 0.0),
                DVec2::new(0.0, 1.0),
            ],
            faces: vec![[0, 1, 2]],
        };
        let layout = TextureLayout::from_uv(&uv, 4, 4, 1).unwrap();
        let n = 3 * layout.num_texels();
        let mut r = Rng::new(11);
        let with_uv = TexturePca::new(
            layout,
            (0..n).map(|_| r.uniform_f32(0.0, 1.0)).collect(),
            (0..2 * n).map(|_| r.uniform_f32(-1.0, 1.0)).collect(),
            2,
            1.0,
        )
        .unwrap();
        for (i, m) in [plain, with_uv].into_iter().enumerate() {
            let p = dir.join(format!("m{i}.safetensors"));
            m.save_safetensors(&p).unwrap();
            let back = TexturePca::load_safetensors(&p).unwrap();
            assert_eq!(back, m);
        }
        let p = dir.join("m0.safetensors");
        let bytes = std::fs::read(&p).unwrap();
        let trunc = dir.join("truncated.safetensors");
        std::fs::write(&trunc, &bytes[..bytes.len() - 7]).unwrap();
        let msg = TexturePca::load_safetensors(&trunc)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("truncated.safetensors") && msg.contains("not a safetensors"),
            "{msg}"
        );
        let garbage = dir.join("garbage.safetensors");
        std::fs::write(&garbage, b"\xff\xff\xff\xff\xff\xff\xff\x7fnot json").unwrap();
        assert!(TexturePca::load_safetensors(&garbage).is_err());
        let missing = dir.join("missing.safetensors");
        let msg = TexturePca::load_safetensors(&missing).unwrap_err();
        assert!(
            matches!(msg, TextureError::File(bitt_stdx::FileError::Io { .. })),
            "{msg}"
        );
        // A file of the right format without `basis`.
        let m = model(2, 1.0, 12);
        let (entries, meta) = m.entries();
        let no_basis: Vec<st::Entry> = entries.into_iter().filter(|e| e.0 != "basis").collect();
        let nb = dir.join("no_basis.safetensors");
        st::write(&nb, &no_basis, meta.clone()).unwrap();
        let msg = TexturePca::load_safetensors(&nb).unwrap_err().to_string();
        assert!(
            msg.contains("no_basis.safetensors") && msg.contains("missing tensor `basis`"),
            "{msg}"
        );
        // Wrong format name.
        let (entries, mut meta) = m.entries();
        meta.insert("format".into(), "something-else".into());
        let wf = dir.join("wrong_format.safetensors");
        st::write(&wf, &entries, meta).unwrap();
        let msg = TexturePca::load_safetensors(&wf).unwrap_err().to_string();
        assert!(msg.contains("expected \"bitt-texture-pca\""), "{msg}");
        // Basis with the wrong number of rows.
        let (mut entries, meta) = m.entries();
        entries[1].2 = vec![3, 24];
        let wr = dir.join("wrong_rows.safetensors");
        st::write(&wr, &entries, meta).unwrap();
        let msg = TexturePca::load_safetensors(&wr).unwrap_err().to_string();
        assert!(msg.contains("`basis` has shape [3, 24]"), "{msg}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
