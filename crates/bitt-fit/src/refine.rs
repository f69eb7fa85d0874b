//! Mesh refinement: both hands' pose, shape, root and translation fitted to the photo through
//! the differentiable renderer (the paper's future work, "refine 3D meshes"; HARP-style
//! silhouette and photometric losses).
//!
//! The hands go through [`HandLayer`] (any `HandModel`), are projected with the view's camera
//! and rasterized; the loss ([`RefineTerms`]) is
//! - **silhouette**: the antialiased coverage ([`bitt_render::ops::antialias`], whose gradient
//!   moves silhouette edges) against the hand mask, per mask pixel;
//! - **outside** and **coverage**, a symmetric 2-D chamfer between the mesh and the mask that
//!   reaches further than one pixel: each projected vertex pays the mask's distance transform
//!   at its position (bilinear), and each mask pixel the render leaves uncovered pulls its
//!   nearest projected vertex (pseudo-Huber, within `coverage_radius`);
//! - **photometric**: `|render - I * mask|` under the current texture (the prior's PCA with
//!   fitted coefficients, or the caller's fixed texture) and a fitted point light;
//! - priors: finger pose near its start, joint-angle limits about each joint's flexion axis
//!   (the axis of the model's mean pose, so MANO and the procedural hand alike), betas near 0,
//!   and joint spheres of the two hands kept apart.
//!
//! Stages: `rigid` (root rotation and translation) then `all` (also finger pose and shape),
//! Adam with a cosine-decayed step. Variables are offsets from the start in chosen units
//! (radians, `translation_unit` metres, betas), so one step size suits all of them.
//! Deterministic: no randomness, fixed pixel subsampling.

use bitt_render::scene::LightValuesExt;

use std::time::Instant;

use bitt_mesh::glam::DVec3;
use bitt_mesh::model::NUM_POSE;
use bitt_mesh::{HandPair, HandParams, HandPose, PinholeCamera, Side, TwoHandScene};
use bitt_nets::LightParams;
use bitt_render::ops::{antialias, rasterize, texture};
use bitt_render::scene::{Camera, DepthRange, RenderSettings, render};
use bitt_texture::TexturePcaTensors;
use burn::module::{Module, Param};
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::FitError;
use crate::hand_layer::{HandLayer, HandLayerParams, has_learned_pose_pca, host_params};
use crate::hand_priors::HandPriors;
use bitt_eval::metrics::mask_iou;
use bitt_stdx::to_host;
use bitt_train::assets::HandAssets;
use bitt_train::config::{Bounds, OptimConfig, check_field, check_fields};
use bitt_train::optim::{Adam, STEP_BOUNDS};
use bitt_train::pipeline::point_light;

/// Weights of the refinement loss terms.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RefineWeights {
    /// Antialiased silhouette vs mask (squared difference, per mask pixel).
    pub silhouette: f64,
    /// Mask distance (pixels) at each projected vertex, mean over vertices.
    pub outside: f64,
    /// Uncovered mask pixels to their nearest projected vertex (pixels, pseudo-Huber).
    pub coverage: f64,
    /// Multiplies `coverage` for the uncovered mask pixels inside the hands' outline (the
    /// holes between touching fingers, [`holes`]): such a pixel pulls `1 + holes` times as
    /// hard as one outside. 5 closes the demo photos' holes (under 1 % of their hand pixels)
    /// and lowers the mesh error on unseen synthetic scenes (docs/refinement.md, Holes); 0
    /// turns it off. In short refinements (100 iterations) it makes the result erratic.
    pub holes: f64,
    /// `|render - I * mask|` per covered-or-mask pixel and channel.
    pub photometric: f64,
    /// Squared finger-pose change from the start (radians^2, mean over values). It also
    /// holds the fingers the photo cannot see (hidden behind the other hand) where they were.
    pub pose: f64,
    /// Multiplies `pose` for a hand whose finger pose starts uninformed (the model's mean
    /// pose): that start is only a relaxed hand, not an estimate.
    pub uninformed_pose: f64,
    /// Joint-angle limit violations (radians^2, summed).
    pub limits: f64,
    /// Squared betas (mean).
    pub shape: f64,
    /// Overlap of the two hands' joint spheres (squared, in sphere radii).
    pub penetration: f64,
}

impl Default for RefineWeights {
    fn default() -> Self {
        RefineWeights {
            silhouette: 1.0,
            outside: 0.05,
            coverage: 0.2,
            holes: 5.0,
            photometric: 1.0,
            pose: 5.0,
            uninformed_pose: 0.1,
            limits: 1.0,
            shape: 0.01,
            penetration: 0.1,
        }
    }
}

/// How to refine.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct RefineConfig {
    /// Iterations of the rigid stage (root rotation and translation).
    pub rigid_iterations: usize,
    /// Iterations of the full stage (also finger pose and shape).
    pub full_iterations: usize,
    /// Adam step at the start of each stage (cosine decay to `final_lr_fraction` of it).
    pub learning_rate: f64,
    /// Final step as a fraction of `learning_rate`.
    pub final_lr_fraction: f64,
    /// Metres per unit of the translation variable.
    pub translation_unit: f64,
    /// Betas per unit of the shape variable.
    pub shape_unit: f64,
    /// Radians per unit of the finger-pose variable of a hand whose finger pose starts
    /// uninformed (from the mean pose, the annotation's PCA being meaningless for the model):
    /// its fingers have far to go, so they move this many times faster (1 radian per unit
    /// otherwise).
    pub uninformed_pose_unit: f64,
    /// Mask pixels further than this from every projected vertex (pixels at 128 px; scaled
    /// with the image) do not pull (forearms, background above the threshold).
    pub coverage_radius: f64,
    /// At most this many uncovered mask pixels pull per iteration (evenly subsampled).
    pub coverage_samples: usize,
    /// Radius of the joint spheres of the penetration prior (metres).
    pub joint_radius: f64,
    /// Fit the light and the texture PCA coefficients jointly (photometric term).
    pub fit_appearance: bool,
    /// The loss weights.
    pub weights: RefineWeights,
}

impl Default for RefineConfig {
    fn default() -> Self {
        RefineConfig {
            rigid_iterations: 40,
            full_iterations: 300,
            learning_rate: 0.01,
            final_lr_fraction: 0.05,
            translation_unit: 0.05,
            shape_unit: 3.0,
            uninformed_pose_unit: 3.0,
            coverage_radius: 16.0,
            coverage_samples: 1500,
            joint_radius: 0.006,
            fit_appearance: true,
            weights: RefineWeights::default(),
        }
    }
}

impl RefineConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`FitError::Invalid`] naming the value.
    pub fn validate(&self) -> Result<(), FitError> {
        check_field("refine.learning_rate", self.learning_rate, STEP_BOUNDS)?;
        check_fields(
            "refine",
            &[
                ("translation_unit", self.translation_unit),
                ("shape_unit", self.shape_unit),
                ("uninformed_pose_unit", self.uninformed_pose_unit),
                ("coverage_radius", self.coverage_radius),
                ("joint_radius", self.joint_radius),
            ],
            Bounds::POSITIVE,
        )?;
        check_field(
            "refine.final_lr_fraction",
            self.final_lr_fraction,
            Bounds::UNIT,
        )?;
        let w = &self.weights;
        check_fields(
            "refine.weights",
            &[
                ("silhouette", w.silhouette),
                ("outside", w.outside),
                ("coverage", w.coverage),
                ("holes", w.holes),
                ("photometric", w.photometric),
                ("pose", w.pose),
                ("uninformed_pose", w.uninformed_pose),
                ("limits", w.limits),
                ("shape", w.shape),
                ("penetration", w.penetration),
            ],
            Bounds::NON_NEGATIVE,
        )?;
        Ok(())
    }
}

/// The photo the hands are fitted to.
#[derive(Debug, Clone)]
pub struct RefineTarget {
    /// The image `[3, H, W]` in `[0, 1]`.
    pub image: Vec<f32>,
    /// The two-hand mask `[H, W]` in `{0, 1}`.
    pub mask: Vec<f32>,
    /// The camera of the image (`hands` are in its world frame).
    pub camera: PinholeCamera,
}

/// The reference's rule for a hand mask when none is given: pixels whose mean RGB is above
/// this threshold (the demo frames' dark background).
pub const MASK_THRESHOLD: f32 = 0.15;

/// The threshold rule on the synthetic benchmark's renders (black background, mild sensor
/// noise and JPEG): IoU against the true silhouettes of the first 4 benchmark scenes at 128 px
/// is 0.969 / 0.996 / 0.991 / 0.977 at 0.08, against 0.824 / 0.997 / 0.995 / 0.834 at 0.15
/// (dark skin falls below it) and 0.943 / 0.993 / 0.970 / 0.960 at 0.05 (noise rises above).
pub(crate) const SYNTHETIC_MASK_THRESHOLD: f32 = 0.08;

/// Threshold-mask components below this fraction of the largest are specks (the demo frames'
/// point lights), not hands.
pub const SPECK_FRACTION: f64 = 0.05;

/// `mean_rgb > threshold` of an image `[3, H, W]`, as `[H, W]` 1/0.
pub fn threshold_mask(image: &[f32], hw: usize, threshold: f32) -> Vec<f32> {
    (0..hw)
        .map(|p| {
            let m = (image[p] + image[hw + p] + image[2 * hw + p]) / 3.0;
            if m > threshold { 1.0 } else { 0.0 }
        })
        .collect()
}

/// `mask` (`[H, W]`, > 0.5 inside) without its small specks: 4-connected components smaller
/// than `min_fraction` of the largest one are dropped (the demo frames' point lights pass the
/// threshold rule as isolated blobs, and would pull fingertips towards them).
pub fn drop_small_components(mask: &[f32], [h, w]: [usize; 2], min_fraction: f64) -> Vec<f32> {
    let mut label = vec![u32::MAX; h * w];
    let mut sizes: Vec<usize> = Vec::new();
    for start in 0..h * w {
        if mask[start] <= 0.5 || label[start] != u32::MAX {
            continue;
        }
        let id = sizes.len() as u32;
        label[start] = id;
        let size = flood4([h, w], vec![start], |q| {
            let enter = mask[q] > 0.5 && label[q] == u32::MAX;
            if enter {
                label[q] = id;
            }
            enter
        });
        sizes.push(size);
    }
    let largest = sizes.iter().copied().max().unwrap_or(0) as f64;
    label
        .iter()
        .map(|&l| {
            let keep = l != u32::MAX && sizes[l as usize] as f64 >= min_fraction * largest;
            if keep { 1.0 } else { 0.0 }
        })
        .collect()
}

/// A 4-connected flood fill over an `[h, w]` grid from `seeds` (already taken by the
/// caller): each neighbour `q` of a taken pixel is offered to `enter`, which takes it (and
/// marks it, so it is not offered as taken again) by returning true. Returns how many pixels
/// were taken, seeds included.
fn flood4([h, w]: [usize; 2], seeds: Vec<usize>, mut enter: impl FnMut(usize) -> bool) -> usize {
    let mut stack = seeds;
    let mut taken = 0;
    while let Some(p) = stack.pop() {
        taken += 1;
        let (x, y) = (p % w, p / w);
        let neighbours = [
            (x > 0).then(|| p - 1),
            (x + 1 < w).then(|| p + 1),
            (y > 0).then(|| p - w),
            (y + 1 < h).then(|| p + w),
        ];
        for q in neighbours.into_iter().flatten() {
            if enter(q) {
                stack.push(q);
            }
        }
    }
    taken
}

impl RefineTarget {
    /// A target from an image and an optional mask (`[H, W]`, values > 0.5 are hand); without
    /// a mask, [`threshold_mask`] at [`MASK_THRESHOLD`] without its specks
    /// ([`drop_small_components`] at [`SPECK_FRACTION`]).
    ///
    /// # Errors
    /// Wrong sizes, non-finite values, or an empty mask. `what` names the inputs in messages.
    pub fn new(
        image: Vec<f32>,
        mask: Option<Vec<f32>>,
        camera: PinholeCamera,
        what: &str,
    ) -> Result<Self, FitError> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        if image.len() != 3 * w * h {
            return Err(FitError::Invalid(format!(
                "{what}: the image has {} values, the camera is for a {w}x{h} image",
                image.len()
            )));
        }
        if image.iter().any(|x| !x.is_finite()) {
            return Err(FitError::NonFinite(format!("{what}: the image")));
        }
        let mask = match mask {
            Some(m) => {
                if m.len() != w * h {
                    return Err(FitError::Invalid(format!(
                        "{what}: the mask has {} pixels, the image {w}x{h} = {}",
                        m.len(),
                        w * h
                    )));
                }
                if m.iter().any(|x| !x.is_finite()) {
                    return Err(FitError::NonFinite(format!("{what}: the mask")));
                }
                m.into_iter()
                    .map(|x| if x > 0.5 { 1.0 } else { 0.0 })
                    .collect()
            }
            None => drop_small_components(
                &threshold_mask(&image, w * h, MASK_THRESHOLD),
                [h, w],
                SPECK_FRACTION,
            ),
        };
        let area = mask.iter().filter(|&&m| m > 0.5).count();
        if area == 0 {
            return Err(FitError::Invalid(format!(
                "{what}: the hand mask is empty (no pixel is hand), so there is nothing to fit to"
            )));
        }
        Ok(RefineTarget {
            image,
            mask,
            camera,
        })
    }

    fn size(&self) -> [usize; 2] {
        [self.camera.height as usize, self.camera.width as usize]
    }
}

/// The appearance the photometric term renders with.
#[derive(Debug, Clone)]
pub enum Appearance {
    /// A texture PCA on the hands' layout: its coefficients are fitted (from 0, the mean)
    /// with the light when `fit_appearance`, else the mean under the reference's light.
    Prior(TexturePcaTensors),
    /// Fixed compact textures `[3, T]` (left, right) and a fixed light (e.g. a trained run's).
    Fixed {
        /// Compact textures.
        textures: [Tensor<2>; 2],
        /// The light.
        light: bitt_render::scene::LightValues,
    },
}

/// The loss terms of one iteration (weighted values; `total` is their sum).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineTerms {
    /// Total.
    pub total: f64,
    /// Silhouette.
    pub silhouette: f64,
    /// Vertices outside the mask.
    pub outside: f64,
    /// Uncovered mask pixels.
    pub coverage: f64,
    /// Photometric.
    pub photometric: f64,
    /// Pose prior.
    pub pose: f64,
    /// Joint limits.
    pub limits: f64,
    /// Shape prior.
    pub shape: f64,
    /// Hand-hand penetration.
    pub penetration: f64,
}

/// Progress of one iteration.
#[derive(Debug, Clone)]
pub struct RefineProgress {
    /// `rigid` or `all`.
    pub stage: &'static str,
    /// Iteration within the whole refinement (1-based).
    pub iteration: usize,
    /// Iterations of the whole refinement.
    pub iterations: usize,
    /// This iteration's terms.
    pub terms: RefineTerms,
    /// Silhouette IoU against the mask (before this iteration's step).
    pub iou: f64,
}

/// One stage's summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StageReport {
    /// `rigid` or `all`.
    pub stage: String,
    /// Iterations run.
    pub iterations: usize,
    /// Terms at the stage's first iteration.
    pub first: RefineTerms,
    /// Terms at its last iteration.
    pub last: RefineTerms,
    /// IoU against the mask at the end of the stage.
    pub iou: f64,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// What [`refine_hands`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineReport {
    /// Silhouette IoU of the given hands against the mask.
    pub iou_before: f64,
    /// ... of the refined hands.
    pub iou_after: f64,
    /// Per stage.
    pub stages: Vec<StageReport>,
    /// Seconds in all.
    pub seconds: f64,
    /// Image size `[H, W]`.
    pub image_size: [usize; 2],
    /// One line per thing the user should know (e.g. a finger pose that was not usable).
    pub notes: Vec<String>,
    /// The configuration it ran with.
    pub config: RefineConfig,
}

/// The refined hands and the report.
#[derive(Debug, Clone)]
pub struct Refinement {
    /// The refined scene: same camera and frame, poses as axis-angles.
    pub hands: TwoHandScene,
    /// The hands it started from, as given.
    pub initial: TwoHandScene,
    /// The report.
    pub report: RefineReport,
}

/// Called after every iteration.
pub trait RefineObserver {
    /// One iteration done.
    fn iteration(&mut self, progress: &RefineProgress);
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Quiet;

impl RefineObserver for Quiet {
    fn iteration(&mut self, _: &RefineProgress) {}
}

/// The optimised offsets from the start.
#[derive(Module, Debug)]
struct RefineVars {
    root: Param<Tensor<2>>,
    trans: Param<Tensor<2>>,
    pose: Param<Tensor<2>>,
    betas: Param<Tensor<2>>,
    texture: Param<Tensor<2>>,
    light: Param<Tensor<2>>,
}

fn float<const D: usize>(v: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(v, shape), device)
}

/// Exact Euclidean distance (pixels) from every pixel to the nearest pixel of `mask`
/// (`[H, W]`, > 0.5 is inside; 0 inside), Felzenszwalb and Huttenlocher's two passes.
pub(crate) fn distance_to_mask(mask: &[f32], [h, w]: [usize; 2]) -> Vec<f32> {
    const INF: f64 = 1e20;
    let mut g = vec![0.0f64; h * w];
    for (i, m) in mask.iter().enumerate() {
        g[i] = if *m > 0.5 { 0.0 } else { INF };
    }
    fn pass(f: &[f64], out: &mut [f64]) {
        let n = f.len();
        let mut v = vec![0usize; n];
        let mut z = vec![0.0f64; n + 1];
        let mut k = 0usize;
        v[0] = 0;
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        for q in 1..n {
            loop {
                let p = v[k];
                let s =
                    ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
                if s <= z[k] && k > 0 {
                    k -= 1;
                    continue;
                }
                if s <= z[k] {
                    // k == 0 and the new parabola dominates everywhere.
                    v[0] = q;
                    z[0] = f64::NEG_INFINITY;
                    z[1] = f64::INFINITY;
                    break;
                }
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
        k = 0;
        for (q, o) in out.iter_mut().enumerate() {
            while z[k + 1] < q as f64 {
                k += 1;
            }
            let p = v[k];
            let d = q as f64 - p as f64;
            *o = d * d + f[p];
        }
    }
    let mut col = vec![0.0; h];
    let mut out = vec![0.0; h];
    for x in 0..w {
        for y in 0..h {
            col[y] = g[y * w + x];
        }
        pass(&col, &mut out);
        for y in 0..h {
            g[y * w + x] = out[y];
        }
    }
    let mut row = vec![0.0; w];
    let mut out = vec![0.0; w];
    for y in 0..h {
        row.copy_from_slice(&g[y * w..(y + 1) * w]);
        pass(&row, &mut out);
        g[y * w..(y + 1) * w].copy_from_slice(&out);
    }
    g.into_iter().map(|d| d.sqrt() as f32).collect()
}

/// Whether hand `side` of `params` gives PCA coefficients that its model cannot interpret
/// (a model without a learned pose PCA: the coefficients are meant for MANO's basis).
fn uninterpretable_pca(models: &HandPair, side: Side, params: &HandParams) -> bool {
    matches!(params.pose, HandPose::Pca(_)) && !has_learned_pose_pca(models.get(side))
}

/// One line per hand of `hands` whose finger pose is PCA coefficients its model cannot
/// interpret, ending in `consequence`.
pub fn pca_pose_notes(models: &HandPair, hands: &TwoHandScene, consequence: &str) -> Vec<String> {
    Side::BOTH
        .into_iter()
        .filter(|&side| {
            hands
                .hand(side)
                .is_some_and(|p| uninterpretable_pca(models, side, p))
        })
        .map(|side| {
            format!(
                "{side} hand: the annotation's finger pose is MANO PCA coefficients, which the \
                 {} model has no basis for; {consequence}",
                models.get(side).source
            )
        })
        .collect()
}

/// Refines both hands of `hands` (both must be present) against `target`.
///
/// `assets` must be built from `models` (the render meshes and layouts). The finger pose of
/// a hand whose annotation gives PCA coefficients that its model cannot interpret (a model
/// without a learned pose PCA, [`has_learned_pose_pca`]) starts from the model's mean pose,
/// and the report says so.
///
/// # Errors
/// A missing hand, hands that cover no pixel of the image, a bad configuration, or a
/// non-finite loss.
#[allow(clippy::too_many_arguments)]
pub fn refine_hands(
    assets: &HandAssets,
    hands: &TwoHandScene,
    target: &RefineTarget,
    appearance: &Appearance,
    config: &RefineConfig,
    device: &Device,
    observer: &mut dyn RefineObserver,
) -> Result<Refinement, FitError> {
    config.validate()?;
    let started = Instant::now();
    let models = &assets.models;
    let mut notes = Vec::new();
    let mut start: Vec<HandParams> = Vec::new();
    let mut pose_units = Vec::new();
    let mut prior_scale = Vec::new();
    for side in Side::BOTH {
        let p = hands.hand(side).ok_or_else(|| {
            FitError::Invalid(format!(
                "the {side} hand is not given; refinement needs both"
            ))
        })?;
        p.validate()
            .map_err(|e| FitError::Invalid(format!("the {side} hand: {e}")))?;
        let mut p = p.clone();
        let uninformed = uninterpretable_pca(models, side, &p);
        if uninformed {
            p.pose = HandPose::Pca(vec![0.0; NUM_POSE]);
        }
        pose_units.push(if uninformed {
            config.uninformed_pose_unit as f32
        } else {
            1.0
        });
        prior_scale.push(if uninformed {
            config.weights.uninformed_pose as f32
        } else {
            1.0
        });
        start.push(p);
    }
    notes.extend(pca_pose_notes(
        models,
        hands,
        "its fingers start from the model's mean pose",
    ));
    hands.camera.validate()?;
    if hands.camera.width != target.camera.width || hands.camera.height != target.camera.height {
        return Err(FitError::Invalid(format!(
            "the hands' camera is for a {}x{} image, the target is {}x{}",
            hands.camera.width, hands.camera.height, target.camera.width, target.camera.height
        )));
    }
    let [h, w] = target.size();
    let hw = h * w;

    let layer = HandLayer::new(models, device)?;
    let nv = layer.num_vertices();
    let (root0, pose0, betas0, trans0) = host_params(models, [&start[0], &start[1]]);
    let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let root0 = float(f(&root0), [2, 6], device);
    let pose0 = float(f(&pose0), [2, NUM_POSE], device);
    let betas0 = float(f(&betas0), [2, 10], device);
    let trans0 = float(f(&trans0), [2, 3], device);
    let pose_unit = float(pose_units, [2, 1], device);
    let prior_scale = float(prior_scale, [2, 1], device);

    // Camera frame: v_cam = R v + t, rendered with identity extrinsics (as `ViewGeometry`).
    let cam = target.camera;
    let r = cam.rotation;
    // `points [N, 3] @ R^T` gives rows `R p`; R^T row-major: R^T[i][j] = R[j][i].
    let rt: Vec<f32> = (0..3)
        .flat_map(|i| (0..3).map(move |j| r.col(i)[j] as f32))
        .collect();
    let r_t = float(rt, [3, 3], device);
    let t_cam = float(
        vec![
            cam.translation.x as f32,
            cam.translation.y as f32,
            cam.translation.z as f32,
        ],
        [1, 3],
        device,
    );
    let render_camera = Camera::Pinhole(PinholeCamera {
        rotation: bitt_mesh::glam::DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..cam
    });
    let depth = DepthRange::default();
    let topology = assets.scene.topology();

    // Fixed targets on the device.
    let mask_t = float(target.mask.clone(), [1, h, w], device);
    let area = target.mask.iter().filter(|&&m| m > 0.5).count() as f64;
    let photo_hand: Vec<f32> = (0..3 * hw)
        .map(|i| target.image[i] * target.mask[i % hw])
        .collect();
    let photo_hand = float(photo_hand, [3, h, w], device);
    let dt = distance_to_mask(&target.mask, [h, w]);
    let dt_t = float(dt, [1, h, w], device);
    let scale_px = (h.max(w) as f64) / 128.0;
    let coverage_radius = config.coverage_radius * scale_px;
    let mask_pixels: Vec<usize> = (0..hw).filter(|&p| target.mask[p] > 0.5).collect();

    let priors = HandPriors::new(models, device);

    let k_tex = match appearance {
        Appearance::Prior(p) => p.basis.dims()[1],
        Appearance::Fixed { .. } => 1,
    };
    let zeros =
        |shape: [usize; 2]| Param::from_tensor(Tensor::<2>::zeros(shape, device).require_grad());
    let mut vars = RefineVars {
        root: zeros([2, 6]),
        trans: zeros([2, 3]),
        pose: zeros([2, NUM_POSE]),
        betas: zeros([2, 10]),
        texture: zeros([2, k_tex]),
        light: zeros([1, 12]),
    };
    let settings = RenderSettings::default();
    let gather = assets.gather(device);
    let fit_appearance = config.fit_appearance;

    let mut stages = Vec::new();
    let mut iou_before = f64::NAN;
    let total_iterations = config.rigid_iterations + config.full_iterations;
    let mut done = 0usize;
    for (stage, iterations) in [
        ("rigid", config.rigid_iterations),
        ("all", config.full_iterations),
    ] {
        if iterations == 0 {
            continue;
        }
        let stage_started = Instant::now();
        let mut adam = Adam::new(OptimConfig::default());
        let mut first = None;
        let mut last = RefineTerms::default();
        let mut iou = f64::NAN;
        for it in 0..iterations {
            let rigid = stage == "rigid";
            let maybe = |t: Tensor<2>, frozen: bool| if frozen { t.detach() } else { t };
            let params = HandLayerParams {
                root_6d: root0.clone() + vars.root.val(),
                trans: trans0.clone() + vars.trans.val() * config.translation_unit,
                finger_pose: pose0.clone() + maybe(vars.pose.val(), rigid) * pose_unit.clone(),
                betas: betas0.clone() + maybe(vars.betas.val(), rigid) * config.shape_unit,
            };
            let out = layer.forward(&params);
            let world = out.vertices.clone().reshape([2 * nv, 3]);
            let cam_pts = world.matmul(r_t.clone()) + t_cam.clone();
            let per_hand = [
                cam_pts.clone().narrow(0, 0, nv),
                cam_pts.clone().narrow(0, nv, nv),
            ];

            // Render: photometric image (with its raster) or the raster alone.
            let shading = match appearance {
                _ if w_photo(config) <= 0.0 => None,
                Appearance::Prior(pca) => {
                    let fit = |t: Tensor<2>| if fit_appearance { t } else { t.detach() };
                    let tex = pca.textures(fit(vars.texture.val()));
                    let t = assets.num_texels();
                    let hand = |k: usize| tex.clone().narrow(0, k, 1).reshape([3, t]);
                    let light = point_light(&LightParams::from_raw(fit(vars.light.val())));
                    Some(([hand(0), hand(1)], light))
                }
                Appearance::Fixed { textures, light } => {
                    Some((textures.clone(), light.to_light(device)))
                }
            };
            let (image, raster, clip) = match shading {
                Some((textures, light)) => {
                    let [l, r] = textures;
                    let images = [
                        gather.compact_to_image(l, [0.0; 3]),
                        gather.compact_to_image(r, [0.0; 3]),
                    ];
                    let r = render(
                        &assets.scene,
                        &per_hand,
                        &images,
                        &render_camera,
                        &light,
                        &settings,
                    )?;
                    (Some(r.image), r.raster, r.clip)
                }
                None => {
                    let clip = render_camera.clip_positions(cam_pts.clone(), depth)?;
                    let raster = rasterize(clip.clone(), topology, h, w)?;
                    (None, raster, clip)
                }
            };
            if raster.num_covered() == 0 {
                return Err(FitError::Invalid(format!(
                    "the hands cover no pixel of the {w}x{h} image (they project outside it \
                     or behind the camera{})",
                    if done == 0 {
                        ""
                    } else {
                        " after refining: it diverged"
                    }
                )));
            }
            let covered = raster.mask(device);
            let covered_host = to_host(covered.clone())?;
            iou = mask_iou(&covered_host, &target.mask);
            if done == 0 {
                iou_before = iou;
            }

            let sil = antialias(covered.reshape([1, h, w]), &raster, clip.clone(), topology)?;
            let wts = &config.weights;
            let silhouette = (sil - mask_t.clone()).square().sum() / area;

            // Projected vertices (pixels) from clip space, as the rasterizer sees them.
            let n = 2 * nv;
            let cw = clip.clone().narrow(1, 3, 1);
            let px = (clip.clone().narrow(1, 0, 1) / cw.clone() + 1.0) * (w as f64 / 2.0);
            let py = (clip.clone().narrow(1, 1, 1) / cw + 1.0) * (h as f64 / 2.0);
            let u = (px.clone() - 0.5) / ((w - 1) as f64);
            let v = ((py.clone() - 0.5) / ((h - 1) as f64)).neg() + 1.0;
            let dist = texture(dt_t.clone(), Tensor::cat(vec![u, v], 1))?;
            let outside = dist.sum() / (n as f64);

            // Uncovered mask pixels pull their nearest projected vertex.
            let pxh = to_host(px.clone())?;
            let pyh = to_host(py.clone())?;
            let uncovered: Vec<usize> = mask_pixels
                .iter()
                .copied()
                .filter(|&p| covered_host[p] < 0.5)
                .collect();
            let stride = uncovered
                .len()
                .div_ceil(config.coverage_samples.max(1))
                .max(1);
            let inside = (wts.holes > 0.0).then(|| {
                let drawn: Vec<bool> = covered_host.iter().map(|&c| c >= 0.5).collect();
                let radius = (OUTLINE_CLOSING_PX_AT_256 * h.max(w) as f64 / 256.0)
                    .round()
                    .max(1.0) as usize;
                outline(&drawn, [h, w], radius)
            });
            let pulls = coverage_pulls(
                uncovered.iter().step_by(stride).copied(),
                w,
                (&pxh, &pyh),
                coverage_radius,
                inside.as_deref().map(|i| (i, wts.holes as f32)),
            );
            let coverage = if pulls.is_empty() {
                Tensor::<1>::zeros([1], device)
            } else {
                let k = pulls.len();
                let idx = Tensor::<1, Int>::from_data(
                    TensorData::new(pulls.iter().map(|p| p.0).collect::<Vec<_>>(), [k]),
                    device,
                );
                let qx = float(pulls.iter().map(|p| p.1).collect(), [k, 1], device);
                let qy = float(pulls.iter().map(|p| p.2).collect(), [k, 1], device);
                let weight = float(pulls.iter().map(|p| p.3).collect(), [k, 1], device);
                let d2 = (px.clone().select(0, idx.clone()) - qx).square()
                    + (py.clone().select(0, idx) - qy).square();
                // Normalised by the mask area so that the term fades as coverage completes.
                (((d2 + 1.0).sqrt() - 1.0) * weight).sum()
                    / (mask_pixels.len() as f64 / stride as f64)
            };

            let photometric = match &image {
                Some(img) => {
                    let union = (mask_t.clone()
                        + covered_host_tensor(&covered_host, [h, w], device))
                    .clamp(0.0, 1.0);
                    ((img.clone() - photo_hand.clone()).abs() * union).sum() / (3.0 * area)
                }
                None => Tensor::<1>::zeros([1], device),
            };

            // Priors.
            let dpose = params.finger_pose.clone() - pose0.clone();
            let pose_prior = (dpose.square() * prior_scale.clone()).mean();
            let limits = priors.limits(params.finger_pose.clone()).sum();
            let shape = params.betas.clone().square().mean();
            let penetration = priors.penetration(out.joints.clone(), config.joint_radius);

            let parts = [
                (wts.silhouette, silhouette),
                (wts.outside, outside),
                (wts.coverage, coverage),
                (w_photo(config), photometric),
                (wts.pose, pose_prior),
                (wts.limits, limits),
                (wts.shape, shape),
                (wts.penetration, penetration),
            ];
            let mut values = [0.0f64; 8];
            let mut loss: Option<Tensor<1>> = None;
            for (i, (weight, term)) in parts.into_iter().enumerate() {
                if weight <= 0.0 {
                    continue;
                }
                let t = term.reshape([1]) * weight;
                values[i] = to_host(t.clone().detach())?
                    .first()
                    .map_or(f64::NAN, |&v| f64::from(v));
                loss = Some(match loss {
                    Some(l) => l + t,
                    None => t,
                });
            }
            let terms = RefineTerms {
                total: values.iter().sum(),
                silhouette: values[0],
                outside: values[1],
                coverage: values[2],
                photometric: values[3],
                pose: values[4],
                limits: values[5],
                shape: values[6],
                penetration: values[7],
            };
            if !terms.total.is_finite() {
                return Err(FitError::NonFinite(format!(
                    "refinement loss at {stage} iteration {}: {terms:?}",
                    it + 1
                )));
            }
            first.get_or_insert(terms);
            last = terms;
            done += 1;
            observer.iteration(&RefineProgress {
                stage,
                iteration: done,
                iterations: total_iterations,
                terms,
                iou,
            });
            let Some(loss) = loss else { break };
            let grads = loss.backward();
            let progress = it as f64 / (iterations.max(2) - 1) as f64;
            let decay = config.final_lr_fraction
                + (1.0 - config.final_lr_fraction)
                    * 0.5
                    * (1.0 + (std::f64::consts::PI * progress).cos());
            vars = adam.step(vars, &grads, config.learning_rate * decay);
        }
        stages.push(StageReport {
            stage: stage.to_string(),
            iterations,
            first: first.unwrap_or_default(),
            last,
            iou,
            seconds: stage_started.elapsed().as_secs_f64(),
        });
    }
    let params = HandLayerParams {
        root_6d: root0 + vars.root.val(),
        trans: trans0 + vars.trans.val() * config.translation_unit,
        finger_pose: pose0 + vars.pose.val() * pose_unit,
        betas: betas0 + vars.betas.val() * config.shape_unit,
    };
    let [left, right] = params.to_host()?;
    let refined = TwoHandScene {
        left: Some(left),
        right: Some(right),
        camera: hands.camera,
        frame: hands.frame.clone(),
    };
    let iou_after = silhouette_iou(&assets.models, &refined, &assets.scene, &target.mask)?;
    if stages.is_empty() {
        iou_before = iou_after;
    }
    Ok(Refinement {
        hands: refined,
        initial: hands.clone(),
        report: RefineReport {
            iou_before,
            iou_after,
            stages,
            seconds: started.elapsed().as_secs_f64(),
            image_size: [h, w],
            notes,
            config: config.clone(),
        },
    })
}

/// A refinement to run before training: its configuration and where progress goes.
pub struct MeshRefine<'a> {
    /// How to refine.
    pub config: &'a RefineConfig,
    /// Progress.
    pub observer: &'a mut dyn RefineObserver,
}

impl std::fmt::Debug for MeshRefine<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshRefine")
            .field("config", self.config)
            .finish_non_exhaustive()
    }
}

/// Refines `hands` against one view's image (`[3, H, W]` at the hands' camera size) with the
/// texture prior `pca` fitted jointly (photometric term). `device` must be an autodiff device.
///
/// # Errors
/// As [`RefineTarget::new`] and [`refine_hands`].
#[allow(clippy::too_many_arguments)]
pub fn refine_view(
    assets: &HandAssets,
    pca: &bitt_texture::TexturePca,
    hands: &TwoHandScene,
    image: &[f32],
    mask: Option<Vec<f32>>,
    config: &RefineConfig,
    device: &Device,
    observer: &mut dyn RefineObserver,
    what: &str,
) -> Result<Refinement, FitError> {
    assets.check_prior(pca)?;
    let target = RefineTarget::new(image.to_vec(), mask, hands.camera, what)?;
    let appearance = Appearance::Prior(pca.to_device(device));
    refine_hands(
        assets,
        hands,
        &target,
        &appearance,
        config,
        device,
        observer,
    )
}

/// Refines a synthetic scene's given meshes against its training image at `image_size` (the
/// preset's; the image is resized as the trainer resizes it). The result's camera is the
/// scene's (`scene.given.camera`), so it can replace `scene.given`.
///
/// # Errors
/// As [`refine_view`].
#[allow(clippy::too_many_arguments)]
pub fn refine_synthetic(
    scene: &bitt_synth::SynthScene,
    assets: &HandAssets,
    pca: &bitt_texture::TexturePca,
    image_size: usize,
    config: &RefineConfig,
    device: &Device,
    observer: &mut dyn RefineObserver,
) -> Result<Refinement, FitError> {
    let input = crate::photo::ImageInput {
        image: scene.train.image.clone(),
        mask: None,
        camera: scene.given.camera,
    };
    let input = if input.size() == [image_size, image_size] {
        input
    } else {
        input.fit_square(None, image_size)?
    };
    let given = TwoHandScene {
        camera: input.camera,
        ..scene.given.clone()
    };
    let [h, w] = input.size();
    let mask = threshold_mask(&input.image, h * w, SYNTHETIC_MASK_THRESHOLD);
    let mut done = refine_view(
        assets,
        pca,
        &given,
        &input.image,
        Some(mask),
        config,
        device,
        observer,
        "the scene's training image",
    )?;
    done.hands.camera = scene.given.camera;
    done.initial.camera = scene.given.camera;
    Ok(done)
}

/// Per-hand visible masks `[H, W]` of `hands` in their camera, as a label image: 0 none,
/// 1 left, 2 right (host rasterizer, mutual occlusion resolved).
fn hand_labels(
    models: &HandPair,
    hands: &TwoHandScene,
    scene: &bitt_render::scene::Scene,
) -> Result<Vec<u8>, FitError> {
    let posed = hands.pose_in_camera(models)?;
    let mut pts = Vec::new();
    for side in Side::BOTH {
        match posed.get(side) {
            Some(p) => pts.extend_from_slice(&p.vertices),
            // A missing hand is put behind the camera, where nothing of it is drawn.
            None => pts.extend(std::iter::repeat_n(
                DVec3::new(0.0, 0.0, -1.0),
                models.get(side).num_vertices(),
            )),
        }
    }
    let camera = Camera::Pinhole(PinholeCamera {
        rotation: bitt_mesh::glam::DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..hands.camera
    });
    let clip: Vec<[f32; 4]> = pts
        .iter()
        .map(|p| {
            let c = camera.clip_point(*p, DepthRange::default());
            [c.x as f32, c.y as f32, c.z as f32, c.w as f32]
        })
        .collect();
    let fragments = bitt_render::cpu::rasterize(
        &clip,
        scene.topology().faces(),
        camera.width(),
        camera.height(),
    )?;
    let left_faces = scene.face_range(0);
    Ok(fragments
        .face
        .iter()
        .map(|&f| {
            if f < 0 {
                0
            } else if left_faces.contains(&(f as u32)) {
                1
            } else {
                2
            }
        })
        .collect())
}

/// The photo `[3, H, W]` enlarged `scale` times (nearest) with the outlines of each hand's
/// visible region before (red) and after (green) refinement drawn over it; returns the image
/// and its `[H, W]`. Both scenes must have the photo's camera.
///
/// # Errors
/// When a hand cannot be posed or the image does not match the camera.
pub fn overlay(
    image: &[f32],
    models: &HandPair,
    scene: &bitt_render::scene::Scene,
    before: &TwoHandScene,
    after: &TwoHandScene,
    scale: usize,
) -> Result<(Vec<f32>, [usize; 2]), FitError> {
    outlines(
        image,
        models,
        scene,
        &[(before, [1.0, 0.15, 0.1]), (after, [0.1, 1.0, 0.2])],
        scale,
    )
}

/// The photo `[3, H, W]` enlarged `scale` times (nearest) with the outline of each hand's
/// visible region of every scene drawn over it in its colour (later ones on top); returns
/// the image and its `[H, W]`. Every scene must have the photo's camera; a missing hand is
/// not drawn.
///
/// # Errors
/// When a hand cannot be posed or the image does not match the camera.
pub fn outlines(
    image: &[f32],
    models: &HandPair,
    scene: &bitt_render::scene::Scene,
    drawn: &[(&TwoHandScene, [f32; 3])],
    scale: usize,
) -> Result<(Vec<f32>, [usize; 2]), FitError> {
    let Some((first, _)) = drawn.first() else {
        return Err(FitError::Invalid("overlay: nothing to draw".into()));
    };
    let (w, h) = (first.camera.width as usize, first.camera.height as usize);
    if image.len() != 3 * w * h {
        return Err(FitError::Invalid(format!(
            "overlay: the image has {} values, the camera is {w}x{h}",
            image.len()
        )));
    }
    let s = scale.max(1);
    let (bw, bh) = (w * s, h * s);
    let mut out = vec![0.0f32; 3 * bw * bh];
    for c in 0..3 {
        for y in 0..bh {
            for x in 0..bw {
                out[c * bw * bh + y * bw + x] = image[c * w * h + (y / s) * w + x / s];
            }
        }
    }
    let big = |t: &TwoHandScene| {
        let mut t = t.clone();
        let k = &mut t.camera.intrinsics;
        let m = bitt_mesh::glam::DMat3::from_diagonal(DVec3::new(s as f64, s as f64, 1.0));
        *k = m * *k;
        t.camera.width = bw as u32;
        t.camera.height = bh as u32;
        t
    };
    for (hands, colour) in drawn {
        let labels = hand_labels(models, &big(hands), scene)?;
        for y in 0..bh {
            for x in 0..bw {
                let l = labels[y * bw + x];
                if l == 0 {
                    continue;
                }
                let edge = [(0i64, 1i64), (0, -1), (1, 0), (-1, 0)]
                    .iter()
                    .any(|(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        nx < 0
                            || ny < 0
                            || nx >= bw as i64
                            || ny >= bh as i64
                            || labels[ny as usize * bw + nx as usize] != l
                    });
                if edge {
                    for (c, v) in colour.iter().enumerate() {
                        out[c * bw * bh + y * bw + x] = *v;
                    }
                }
            }
        }
    }
    Ok((out, [bh, bw]))
}

fn w_photo(config: &RefineConfig) -> f64 {
    config.weights.photometric
}

fn covered_host_tensor(covered: &[f32], [h, w]: [usize; 2], device: &Device) -> Tensor<3> {
    float(covered.to_vec(), [1, h, w], device)
}

/// The two-hand silhouette `[H, W]` (1/0) of `hands` in their camera (host rasterizer).
///
/// # Errors
/// When a hand cannot be posed.
pub fn silhouette(
    models: &HandPair,
    hands: &TwoHandScene,
    scene: &bitt_render::scene::Scene,
) -> Result<Vec<f32>, FitError> {
    Ok(hand_labels(models, hands, scene)?
        .into_iter()
        .map(|l| if l > 0 { 1.0 } else { 0.0 })
        .collect())
}

/// IoU of the silhouette of `hands` against `mask`.
///
/// # Errors
/// When a hand cannot be posed.
pub(crate) fn silhouette_iou(
    models: &HandPair,
    hands: &TwoHandScene,
    scene: &bitt_render::scene::Scene,
    mask: &[f32],
) -> Result<f64, FitError> {
    Ok(mask_iou(&silhouette(models, hands, scene)?, mask))
}

/// Mean and largest distance (pixels of `a`'s camera) between the projections of
/// corresponding vertices of two scenes of the same hands
/// ([`TwoHandScene::projected_distance_px`]).
///
/// # Errors
/// When a hand cannot be posed.
pub fn vertex_error_px(
    models: &HandPair,
    a: &TwoHandScene,
    b: &TwoHandScene,
) -> Result<(f64, f64), FitError> {
    Ok(a.projected_distance_px(b, models)?)
}

/// The outline's closing radius at 256 px: gaps between touching fingers narrower than
/// twice this count as inside the hands.
pub(crate) const OUTLINE_CLOSING_PX_AT_256: f64 = 3.0;

/// The hands' outline `[h, w]` of a rendered silhouette: a morphological closing (square,
/// `radius` pixels) that bridges slits between touching parts, then every region it encloses
/// (not reachable from the image border through pixels outside it) filled.
pub fn outline(rendered: &[bool], [h, w]: [usize; 2], radius: usize) -> Vec<bool> {
    let shift = |m: &[bool], grow: bool| -> Vec<bool> {
        // Separable square dilation (grow) or erosion (shrink).
        let r = radius as isize;
        let pass = |src: &[bool], horizontal: bool| -> Vec<bool> {
            let mut out = vec![false; h * w];
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let mut acc = !grow;
                    for d in -r..=r {
                        let (xx, yy) = if horizontal { (x + d, y) } else { (x, y + d) };
                        let v = if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                            !grow
                        } else {
                            src[yy as usize * w + xx as usize]
                        };
                        if grow {
                            acc |= v;
                        } else {
                            acc &= v;
                        }
                    }
                    out[y as usize * w + x as usize] = acc;
                }
            }
            out
        };
        pass(&pass(m, true), false)
    };
    let closed = shift(&shift(rendered, true), false);
    // Flood the outside from the border.
    let mut outside = vec![false; h * w];
    let seeds: Vec<usize> = (0..h * w)
        .filter(|&p| {
            let (y, x) = (p / w, p % w);
            (y == 0 || x == 0 || y == h - 1 || x == w - 1) && !closed[p]
        })
        .collect();
    for &p in &seeds {
        outside[p] = true;
    }
    flood4([h, w], seeds, |q| {
        let enter = !outside[q] && !closed[q];
        outside[q] |= enter;
        enter
    });
    outside.iter().map(|&o| !o).collect()
}

/// The coverage term's pulls: each uncovered mask pixel `p` (row-major, rows of `w`) pulls
/// its nearest projected vertex (`xs`, `ys` in pixels) when that lies within `radius`
/// pixels, as `(vertex, x, y, weight)` with the pixel's centre. The weight is 1, or
/// `1 + holes` for a pixel inside the hands' outline (`inside`, [`outline`]).
fn coverage_pulls(
    uncovered: impl Iterator<Item = usize>,
    w: usize,
    (xs, ys): (&[f32], &[f32]),
    radius: f64,
    inside: Option<(&[bool], f32)>,
) -> Vec<(i64, f32, f32, f32)> {
    let mut pulls = Vec::new();
    for p in uncovered {
        let (qx, qy) = ((p % w) as f32 + 0.5, (p / w) as f32 + 0.5);
        let mut best = (f32::INFINITY, 0usize);
        for (i, (x, y)) in xs.iter().zip(ys).enumerate() {
            let d = (x - qx).powi(2) + (y - qy).powi(2);
            if d < best.0 {
                best = (d, i);
            }
        }
        if f64::from(best.0.sqrt()) <= radius {
            let weight = match inside {
                Some((mask, holes)) if mask[p] => 1.0 + holes,
                _ => 1.0,
            };
            pulls.push((best.1 as i64, qx, qy, weight));
        }
    }
    pulls
}

/// Holes: the fraction of the photo's hand pixels `hand` `[h, w]` inside the hands' outline
/// ([`outline`] of the silhouette `drawn`, closed by [`OUTLINE_CLOSING_PX_AT_256`] scaled to
/// the image) that the silhouette leaves uncovered: skin between and within the hands that no
/// mesh shows. 0 when no hand pixel lies inside.
pub fn holes(drawn: &[bool], hand: &[bool], [h, w]: [usize; 2]) -> f64 {
    let radius = (OUTLINE_CLOSING_PX_AT_256 * h.max(w) as f64 / 256.0)
        .round()
        .max(1.0) as usize;
    let inside = outline(drawn, [h, w], radius);
    let (mut inner, mut uncovered) = (0usize, 0usize);
    for p in 0..h * w {
        if hand[p] && inside[p] {
            inner += 1;
            uncovered += usize::from(!drawn[p]);
        }
    }
    if inner == 0 {
        0.0
    } else {
        uncovered as f64 / inner as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An uncovered pixel pulls its nearest vertex within the radius, `1 + holes` times as
    /// hard inside the outline; a pixel farther than the radius from every vertex pulls none.
    #[test]
    fn holes_pull_harder_than_uncovered_pixels_outside() {
        let w = 10;
        let (xs, ys) = ([1.5f32, 8.5], [1.5f32, 1.5]);
        let mut inside = vec![false; w * w];
        inside[2] = true; // (2, 0): nearest vertex 0
        let pulls = coverage_pulls(
            [2, 7, 99].into_iter(),
            w,
            (&xs, &ys),
            3.0,
            Some((&inside, 5.0)),
        );
        assert_eq!(pulls, vec![(0, 2.5, 0.5, 6.0), (1, 7.5, 0.5, 1.0)]);
        let plain = coverage_pulls([2].into_iter(), w, (&xs, &ys), 3.0, None);
        assert_eq!(plain, vec![(0, 2.5, 0.5, 1.0)]);
    }

    #[test]
    fn outline_bridges_slits_and_fills_enclosed_gaps() {
        // A 12 x 12 ring with a one-pixel slit in its wall: the closing bridges the slit, the
        // fill takes the inside.
        let (h, w) = (12, 12);
        let mut m = vec![false; h * w];
        for y in 2..10 {
            for x in 2..10 {
                if y == 2 || y == 9 || x == 2 || x == 9 {
                    m[y * w + x] = true;
                }
            }
        }
        m[2 * w + 5] = false; // the slit
        let o = outline(&m, [h, w], 1);
        assert!(o[5 * w + 5], "the inside is inside");
        assert!(o[2 * w + 5], "the slit is inside");
        assert!(!o[0] && !o[11 * w + 11], "corners stay outside");
        // Without the closing the slit opens the ring.
        let open = outline(&m, [h, w], 0);
        assert!(!open[5 * w + 5]);
    }

    #[test]
    fn distance_transform_is_exact_on_small_masks() {
        let (h, w) = (7, 9);
        let mut mask = vec![0.0; h * w];
        mask[2 * w + 3] = 1.0;
        mask[5 * w + 7] = 1.0;
        let dt = distance_to_mask(&mask, [h, w]);
        for y in 0..h {
            for x in 0..w {
                let d1 = (((x as f64 - 3.0).powi(2)) + (y as f64 - 2.0).powi(2)).sqrt();
                let d2 = (((x as f64 - 7.0).powi(2)) + (y as f64 - 5.0).powi(2)).sqrt();
                assert!(
                    (f64::from(dt[y * w + x]) - d1.min(d2)).abs() < 1e-5,
                    "({x}, {y})"
                );
            }
        }
    }

    #[test]
    fn small_components_are_dropped() {
        let (h, w) = (6, 10);
        let mut mask = vec![0.0f32; h * w];
        for y in 0..5 {
            for x in 0..5 {
                mask[y * w + x] = 1.0;
            }
        }
        mask[2 * w + 8] = 1.0; // a speck
        let kept = drop_small_components(&mask, [h, w], 0.05);
        assert_eq!(kept[2 * w + 8], 0.0);
        assert_eq!(kept.iter().sum::<f32>(), 25.0);
        assert_eq!(drop_small_components(&mask, [h, w], 0.0), mask);
    }

    #[test]
    fn bad_targets_are_refused() {
        let cam = PinholeCamera::looking_down_z(100.0, 8, 6);
        let img = vec![0.5f32; 3 * 48];
        assert!(RefineTarget::new(img.clone(), Some(vec![1.0; 47]), cam, "t").is_err());
        let e = RefineTarget::new(img.clone(), Some(vec![0.0; 48]), cam, "t").unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let mut nan = img.clone();
        nan[3] = f32::NAN;
        assert!(RefineTarget::new(nan, None, cam, "t").is_err());
        assert!(RefineTarget::new(vec![0.0; 3 * 48], None, cam, "t").is_err());
        assert!(RefineTarget::new(img, None, cam, "t").is_ok());
    }
}
