//! Both hands fitted to 2D keypoints (OpenPose, MediaPipe or plain JSON, read by
//! [`bitt_mesh::keypoints`]): a photo and the keypoints any hand detector gives are enough to
//! place the hand models, with no annotation and no calibrated camera.
//!
//! The hands go through [`HandLayer::joints`] (any `HandModel`), are projected with the
//! camera (given intrinsics, or [`PinholeCamera::default_for_image`]) and the loss is
//! - **keypoints**: the confidence-weighted 2-D reprojection error of the 21 joints, robust
//!   (pseudo-Huber with a scale of `robust_scale_px`), normalised per hand;
//! - **limits**: joint-angle limits about each joint's flexion axis ([`HandPriors::limits`]);
//! - **relaxed pose**: finger axis-angles near the model's mean pose (a relaxed hand);
//! - **shape**: betas near 0;
//! - **penetration**: the two hands' joint spheres kept apart ([`HandPriors::penetration`]).
//!
//! Stages, from the model's relaxed pose:
//! 1. **palm** (closed form, on the host): the rigid joints of the palm (wrist, thumb base
//!    and the four knuckles, which only the root rotation moves) are aligned under weak
//!    perspective over a grid of rotations; the scale gives the depth guess, and the best
//!    distinct orientations become the candidates;
//! 2. **root**: root rotation and translation by Adam from a candidate; while a hand's mean
//!    residual stays above `restart_residual_px`, the next candidate is tried and the best
//!    kept;
//! 3. **all**: also finger pose and shape.
//!
//! Deterministic: no randomness (the keypoints' noise in evaluations is seeded by the caller).

use std::time::Instant;

use bitt_mesh::camera::HAND_DEPTH_RANGE_M;
use bitt_mesh::glam::{DMat3, DVec2, DVec3};
use bitt_mesh::keypoints::{Keypoint, NUM_KEYPOINTS, TwoHandKeypoints};
use bitt_mesh::model::{NUM_BETAS, NUM_POSE};
use bitt_mesh::{HandPair, HandParams, HandPose, PinholeCamera, Side, TwoHandScene};
use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

use crate::FitError;
use crate::hand_layer::{HandLayer, HandLayerParams, host_params};
use crate::hand_priors::{FLEXION_RANGE, HandPriors, flexion_angles, flexion_axes};
use bitt_stdx::to_host;
use bitt_train::config::{Bounds, OptimConfig, check_field, check_fields};
use bitt_train::optim::{Adam, STEP_BOUNDS};

/// Weights of the keypoint fit's loss terms.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct FitWeights {
    /// Robust reprojection error (in units of `robust_scale_px`, squared near 0).
    pub keypoints: f64,
    /// Joint-angle limit violations (radians^2, summed).
    pub limits: f64,
    /// Squared finger-pose distance from the model's mean pose (radians^2, mean).
    pub relaxed_pose: f64,
    /// Squared finger rotation about other axes than the flexion axes (abduction, twist;
    /// radians^2, summed), which 2D keypoints hardly constrain.
    pub off_axis: f64,
    /// Squared betas (mean).
    pub shape: f64,
    /// Overlap of the two hands' joint spheres.
    pub penetration: f64,
}

impl Default for FitWeights {
    fn default() -> Self {
        FitWeights {
            keypoints: 1.0,
            limits: 30.0,
            relaxed_pose: 0.5,
            off_axis: 1.0,
            shape: 0.005,
            penetration: 0.1,
        }
    }
}

/// How to fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct FitConfig {
    /// Iterations of the root stage per candidate orientation.
    pub root_iterations: usize,
    /// Iterations of the full stage.
    pub full_iterations: usize,
    /// Adam step at the start of each stage (cosine decay to `final_lr_fraction` of it).
    pub learning_rate: f64,
    /// Final step as a fraction of `learning_rate`.
    pub final_lr_fraction: f64,
    /// Metres per unit of the translation variable.
    pub translation_unit: f64,
    /// Betas per unit of the shape variable.
    pub shape_unit: f64,
    /// Scale of the robust reprojection loss (pixels at a 256-pixel image; scaled with the
    /// image's larger side).
    pub robust_scale_px: f64,
    /// A hand whose mean residual after the root stage is above this (pixels at 256) is
    /// restarted from its next candidate orientation.
    pub restart_residual_px: f64,
    /// Candidate root orientations per hand (the palm stage's best distinct ones).
    pub orientations: usize,
    /// Also fit each keypoint set with the other side's model and report which fits better
    /// (a check of the detector's left/right labels against the geometry).
    pub check_handedness: bool,
    /// Radius of the joint spheres of the penetration prior (metres).
    pub joint_radius: f64,
    /// The fit's limit on hyperextension (radians of backward flexion): tighter than the
    /// refinement's ([`FLEXION_RANGE`]), since 2D keypoints cannot tell a finger bent towards
    /// the camera from one bent away; the soft limit then stays inside the joint-angle check.
    pub hyperextension: f64,
    /// The loss weights.
    pub weights: FitWeights,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            root_iterations: 60,
            full_iterations: 240,
            learning_rate: 0.02,
            final_lr_fraction: 0.05,
            translation_unit: 0.05,
            shape_unit: 3.0,
            robust_scale_px: 4.0,
            restart_residual_px: 4.0,
            orientations: 4,
            check_handedness: true,
            joint_radius: 0.006,
            hyperextension: 0.25,
            weights: FitWeights::default(),
        }
    }
}

impl FitConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`FitError::Invalid`] naming the value.
    pub fn validate(&self) -> Result<(), FitError> {
        check_field("fit.learning_rate", self.learning_rate, STEP_BOUNDS)?;
        check_fields(
            "fit",
            &[
                ("translation_unit", self.translation_unit),
                ("shape_unit", self.shape_unit),
                ("robust_scale_px", self.robust_scale_px),
                ("restart_residual_px", self.restart_residual_px),
                ("joint_radius", self.joint_radius),
                ("hyperextension", self.hyperextension),
            ],
            Bounds::POSITIVE,
        )?;
        check_field(
            "fit.final_lr_fraction",
            self.final_lr_fraction,
            Bounds::UNIT,
        )?;
        if self.orientations == 0 {
            return Err(FitError::Invalid(
                "fit.orientations must be at least 1".into(),
            ));
        }
        let w = &self.weights;
        check_fields(
            "fit.weights",
            &[
                ("keypoints", w.keypoints),
                ("limits", w.limits),
                ("relaxed_pose", w.relaxed_pose),
                ("off_axis", w.off_axis),
                ("shape", w.shape),
                ("penetration", w.penetration),
            ],
            Bounds::NON_NEGATIVE,
        )?;
        Ok(())
    }
}

/// The fewest keypoints a hand needs to be fitted.
pub(crate) const MIN_KEYPOINTS: usize = 6;

/// Output joints that only the root rotation moves (wrist, thumb base, the four knuckles):
/// the palm stage aligns these.
pub(crate) const PALM_JOINTS: [usize; 6] = [0, 1, 5, 9, 13, 17];

/// Progress of one iteration.
#[derive(Debug, Clone)]
pub struct FitProgress {
    /// `root`, `all`, or `handedness` (the swapped-sides check).
    pub stage: &'static str,
    /// Position within the whole fit (1-based): iterations run, plus the root-stage rounds
    /// that no hand needed (skipped forward when a search ends early).
    pub iteration: usize,
    /// The fit's whole length, fixed from the first iteration: every root-stage round the
    /// configuration allows (`orientations`, twice with the handedness check), then the full
    /// stage. (It used to grow with each restart: 540, 600, 660, 720.)
    pub iterations: usize,
    /// This iteration's loss.
    pub loss: f64,
    /// Mean reprojection residual (pixels) over the fitted hands' present keypoints.
    pub residual_px: f64,
}

/// Called after every iteration.
pub trait FitObserver {
    /// One iteration done.
    fn iteration(&mut self, progress: &FitProgress);
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Quiet;

impl FitObserver for Quiet {
    fn iteration(&mut self, _: &FitProgress) {}
}

/// One stage's summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitStageReport {
    /// `root` (per candidate round) or `all`.
    pub stage: String,
    /// Iterations run.
    pub iterations: usize,
    /// Loss at the first iteration.
    pub first_loss: f64,
    /// Loss at the last iteration.
    pub last_loss: f64,
    /// Mean residual (pixels) per fitted hand at the end (left, right; `None`: not fitted).
    pub residual_px: [Option<f64>; 2],
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// One hand's fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HandFitReport {
    /// `left` or `right` (the model that fits it).
    pub side: Side,
    /// Keypoints present (confidence above 0).
    pub keypoints: usize,
    /// Distance (pixels) between each keypoint and the fitted joint's projection, in
    /// OpenPose order (`None`: the keypoint is missing).
    pub residual_px: Vec<Option<f64>>,
    /// Mean of `residual_px`.
    pub mean_residual_px: f64,
    /// Largest of `residual_px`.
    pub max_residual_px: f64,
    /// Depth of the fitted wrist (metres, camera frame).
    pub wrist_depth_m: f64,
    /// Candidate orientations tried before one was kept, and which (0-based).
    pub orientations_tried: usize,
    /// The kept candidate.
    pub orientation_kept: usize,
    /// Flexion of each of the 15 finger joints (degrees; negative is bent backwards; `None`
    /// for a joint the model's mean pose does not bend), in the model's joint order.
    pub flexion_deg: Vec<Option<f64>>,
    /// Smallest finger flexion (degrees).
    pub min_flexion_deg: f64,
    /// Finger joints bent backwards beyond the limit ([`FLEXION_RANGE`]).
    pub bent_backwards: usize,
}

/// The swapped-sides check of one keypoint set.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HandednessCheck {
    /// The side the keypoints were given as.
    pub labelled: Side,
    /// Mean residual (pixels) with the labelled side's model.
    pub labelled_px: f64,
    /// ... with the other side's model.
    pub swapped_px: f64,
    /// Whether the labelled side fits at least as well (within 25 %).
    pub agrees: bool,
}

/// What [`fit_keypoints`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitReport {
    /// Image size `[H, W]`.
    pub image_size: [usize; 2],
    /// Intrinsics used `[fx, fy, cx, cy]`.
    pub intrinsics: [f64; 4],
    /// Per fitted hand.
    pub hands: Vec<HandFitReport>,
    /// Per stage.
    pub stages: Vec<FitStageReport>,
    /// The swapped-sides check per fitted hand (when `check_handedness`).
    pub handedness: Vec<HandednessCheck>,
    /// One line per thing the user should know.
    pub notes: Vec<String>,
    /// Seconds in all.
    pub seconds: f64,
    /// The configuration it ran with.
    pub config: FitConfig,
}

/// The fitted hands and the report.
#[derive(Debug, Clone)]
pub struct KeypointFit {
    /// The fitted hands in the camera's world frame (axis-angle poses), with the camera. A
    /// hand without enough keypoints is `None`.
    pub hands: TwoHandScene,
    /// The report.
    pub report: FitReport,
}

/// The optimised offsets from the start.
#[derive(Module, Debug)]
struct FitVars {
    root: Param<Tensor<2>>,
    trans: Param<Tensor<2>>,
    pose: Param<Tensor<2>>,
    betas: Param<Tensor<2>>,
}

impl FitVars {
    fn zeros(device: &Device) -> Self {
        let z = |shape: [usize; 2]| {
            Param::from_tensor(Tensor::<2>::zeros(shape, device).require_grad())
        };
        FitVars {
            root: z([2, 6]),
            trans: z([2, 3]),
            pose: z([2, NUM_POSE]),
            betas: z([2, NUM_BETAS]),
        }
    }
}

fn float<const D: usize>(v: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(v, shape), device)
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// One hand's starting point: parameters in the camera frame.
#[derive(Debug, Clone)]
struct Start {
    root: DMat3,
    trans: DVec3,
}

/// Everything about the keypoints of both batch slots (0 = left model, 1 = right model).
struct Targets {
    /// `[2, 21, 1]` each, pixels.
    x: Tensor<3>,
    y: Tensor<3>,
    /// Confidence `[2, 21, 1]` (0 for missing points and for an unfitted slot).
    c: Tensor<3>,
    /// Per slot, whether it is fitted.
    fitted: [bool; 2],
    /// Host copies.
    points: [Option<Vec<Keypoint>>; 2],
}

impl Targets {
    fn new(points: [Option<Vec<Keypoint>>; 2], device: &Device) -> Self {
        let mut x = Vec::with_capacity(42);
        let mut y = Vec::with_capacity(42);
        let mut c = Vec::with_capacity(42);
        for p in &points {
            for k in 0..NUM_KEYPOINTS {
                let q = p.as_ref().map(|v| v[k]);
                x.push(q.map_or(0.0, |q| q.x) as f32);
                y.push(q.map_or(0.0, |q| q.y) as f32);
                c.push(q.map_or(0.0, |q| q.confidence.max(0.0)) as f32);
            }
        }
        Targets {
            x: float(x, [2, 21, 1], device),
            y: float(y, [2, 21, 1], device),
            c: float(c, [2, 21, 1], device),
            fitted: [points[0].is_some(), points[1].is_some()],
            points,
        }
    }
}

/// The camera's pixel projection of camera-frame points `[2, 21, 3]` -> `(x, y)` `[2, 21, 1]`.
fn project(camera: &PinholeCamera, p: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
    let k = camera.intrinsics;
    let z = p.clone().narrow(2, 2, 1).clamp_min(1e-3);
    let xn = p.clone().narrow(2, 0, 1) / z.clone();
    let yn = p.narrow(2, 1, 1) / z;
    let x = xn * k.x_axis.x + yn.clone() * k.y_axis.x + k.z_axis.x;
    let y = yn * k.y_axis.y + k.z_axis.y;
    (x, y)
}

/// The camera with identity extrinsics (the fit works in the camera frame).
fn camera_frame(camera: &PinholeCamera) -> PinholeCamera {
    PinholeCamera {
        rotation: DMat3::IDENTITY,
        translation: DVec3::ZERO,
        ..*camera
    }
}

/// Rotations covering SO(3): a Fibonacci sphere of `directions` axes for the model's `+x`
/// and `rolls` angles about it.
fn rotation_grid(directions: usize, rolls: usize) -> Vec<DMat3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let mut out = Vec::with_capacity(directions * rolls);
    for i in 0..directions {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / directions as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        let d = DVec3::new(r * phi.cos(), r * phi.sin(), z);
        // A rotation taking +x to d, then rolls about d.
        let base = rotation_between(DVec3::X, d);
        for k in 0..rolls {
            let a = std::f64::consts::TAU * k as f64 / rolls as f64;
            out.push(DMat3::from_axis_angle(d, a) * base);
        }
    }
    out
}

fn rotation_between(a: DVec3, b: DVec3) -> DMat3 {
    let c = a.cross(b);
    let s = c.length();
    let d = a.dot(b);
    if s < 1e-9 {
        return if d > 0.0 {
            DMat3::IDENTITY
        } else {
            DMat3::from_axis_angle(DVec3::Z, std::f64::consts::PI)
        };
    }
    DMat3::from_axis_angle(c / s, s.atan2(d))
}

/// Angle (radians) between two rotations.
fn rotation_angle(a: DMat3, b: DMat3) -> f64 {
    let m = a.transpose() * b;
    let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    ((tr - 1.0) / 2.0).clamp(-1.0, 1.0).acos()
}

/// The palm stage for one hand: candidate (root rotation, translation) in the camera frame,
/// best first, at least 40 degrees apart.
///
/// `relaxed` are the model's 21 joints in its relaxed pose (identity root, no translation),
/// `wrist` its rest wrist.
fn palm_candidates(
    relaxed: &[DVec3],
    wrist: DVec3,
    points: &[Keypoint],
    camera: &PinholeCamera,
    max: usize,
) -> Vec<(Start, f64)> {
    // Palm joints when at least three are present, else every present joint.
    let present = |k: &usize| points[*k].confidence > 0.0;
    let mut ids: Vec<usize> = PALM_JOINTS.iter().copied().filter(present).collect();
    if ids.len() < 3 {
        ids = (0..NUM_KEYPOINTS).filter(present).collect();
    }
    let wsum: f64 = ids.iter().map(|&k| points[k].confidence).sum();
    // Normalised image coordinates (x / z, y / z) of the keypoints.
    let q: Vec<DVec2> = ids
        .iter()
        .map(|&k| {
            let p = camera.unproject(DVec2::new(points[k].x, points[k].y), 1.0);
            DVec2::new(p.x, p.y)
        })
        .collect();
    let wts: Vec<f64> = ids.iter().map(|&k| points[k].confidence / wsum).collect();
    let q_mean: DVec2 = q.iter().zip(&wts).map(|(p, w)| *p * *w).sum();
    let p3: Vec<DVec3> = ids.iter().map(|&k| relaxed[k]).collect();
    let c3: DVec3 = p3.iter().zip(&wts).map(|(p, w)| *p * *w).sum();
    let mut scored: Vec<(f64, DMat3, f64)> = Vec::new();
    for r in rotation_grid(400, 24) {
        let d: Vec<DVec2> = p3
            .iter()
            .map(|p| {
                let v = r * (*p - c3);
                DVec2::new(v.x, v.y)
            })
            .collect();
        let (mut num, mut den) = (0.0, 0.0);
        for ((dq, dp), w) in q.iter().zip(&d).zip(&wts) {
            num += w * (*dq - q_mean).dot(*dp);
            den += w * dp.length_squared();
        }
        if den <= 0.0 || num <= 0.0 {
            continue;
        }
        let s = num / den;
        let res: f64 = q
            .iter()
            .zip(&d)
            .zip(&wts)
            .map(|((dq, dp), w)| w * (*dq - q_mean - *dp * s).length_squared())
            .sum();
        scored.push((res, r, s));
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<(Start, f64)> = Vec::new();
    let mut kept: Vec<DMat3> = Vec::new();
    let focal = camera.focal().x;
    for (res, r, s) in scored {
        if out.len() >= max {
            break;
        }
        if kept
            .iter()
            .any(|k| rotation_angle(*k, r) < 40f64.to_radians())
        {
            continue;
        }
        kept.push(r);
        // Depth of the palm centroid from the scale; the centroid on its keypoints' ray.
        let z = 1.0 / s;
        let centre = DVec3::new(q_mean.x * z, q_mean.y * z, z);
        let trans = centre - wrist - r * (c3 - wrist);
        out.push((Start { root: r, trans }, res.sqrt() * focal));
    }
    out
}

/// The state of one run of the optimiser over both slots.
struct Run {
    root0: Tensor<2>,
    trans0: Tensor<2>,
    pose0: Tensor<2>,
    betas0: Tensor<2>,
    vars: FitVars,
}

/// Host parameters of both slots from their starts (relaxed pose, mean shape).
fn start_params(starts: [&Start; 2]) -> [HandParams; 2] {
    std::array::from_fn(|h| HandParams {
        root_rotation: starts[h].root,
        pose: HandPose::Pca(vec![0.0; NUM_POSE]),
        betas: vec![0.0; NUM_BETAS],
        trans: starts[h].trans,
    })
}

impl Run {
    fn new(models: &HandPair, hands: [&HandParams; 2], device: &Device) -> Self {
        let (root, pose, betas, trans) = host_params(models, hands);
        Run {
            root0: float(f32s(&root), [2, 6], device),
            trans0: float(f32s(&trans), [2, 3], device),
            pose0: float(f32s(&pose), [2, NUM_POSE], device),
            betas0: float(f32s(&betas), [2, NUM_BETAS], device),
            vars: FitVars::zeros(device),
        }
    }

    fn params(&self, config: &FitConfig, fingers: bool) -> HandLayerParams {
        let maybe = |t: Tensor<2>| if fingers { t } else { t.detach() };
        HandLayerParams {
            root_6d: self.root0.clone() + self.vars.root.val(),
            trans: self.trans0.clone() + self.vars.trans.val() * config.translation_unit,
            finger_pose: self.pose0.clone() + maybe(self.vars.pose.val()),
            betas: self.betas0.clone() + maybe(self.vars.betas.val()) * config.shape_unit,
        }
    }

    fn host(&self, config: &FitConfig) -> Result<[HandParams; 2], FitError> {
        self.params(config, true).to_host()
    }
}

/// The fit's shared constants.
struct Fitter<'a> {
    models: &'a HandPair,
    layer: HandLayer,
    priors: HandPriors,
    mean_pose: Tensor<2>,
    camera: PinholeCamera,
    config: &'a FitConfig,
    scale: f64,
    device: &'a Device,
    done: usize,
    planned: usize,
}

impl Fitter<'_> {
    /// Adam over `iterations` on `run`; returns (first loss, last loss, per-slot residual).
    fn optimise(
        &mut self,
        run: &mut Run,
        targets: &Targets,
        stage: &'static str,
        fingers: bool,
        iterations: usize,
        observer: &mut dyn FitObserver,
    ) -> Result<(f64, f64, [f64; 2]), FitError> {
        let config = self.config;
        let w = &config.weights;
        let mut adam = Adam::new(OptimConfig::default());
        let sigma = config.robust_scale_px * self.scale;
        let (mut first, mut last) = (f64::NAN, f64::NAN);
        let csum = targets.c.clone().sum_dim(1).clamp_min(1e-9); // [2, 1, 1]
        let both = targets.fitted.iter().all(|&f| f);
        for it in 0..iterations {
            let params = run.params(config, fingers);
            let joints = self.layer.joints(&params);
            let (px, py) = project(&self.camera, joints.clone());
            let dx = px - targets.x.clone();
            let dy = py - targets.y.clone();
            let r2 = (dx.square() + dy.square()) / (sigma * sigma);
            let robust = ((r2 + 1.0).sqrt() - 1.0) * 2.0;
            let keypoints = ((robust * targets.c.clone()).sum_dim(1) / csum.clone()).sum();
            let mut loss = keypoints * w.keypoints;
            if fingers {
                let slot = float(
                    targets
                        .fitted
                        .iter()
                        .map(|&f| if f { 1.0 } else { 0.0 })
                        .collect(),
                    [2],
                    self.device,
                );
                let range = (-config.hyperextension, FLEXION_RANGE.1);
                let limits = (self.priors.limits_within(params.finger_pose.clone(), range)
                    * slot.clone())
                .sum();
                let relaxed = ((params.finger_pose.clone() - self.mean_pose.clone())
                    .square()
                    .mean_dim(1)
                    .reshape([2])
                    * slot.clone())
                .sum();
                let off_axis =
                    (self.priors.off_axis(params.finger_pose.clone()) * slot.clone()).sum();
                let shape = (params.betas.clone().square().mean_dim(1).reshape([2]) * slot).sum();
                loss = loss
                    + limits * w.limits
                    + relaxed * w.relaxed_pose
                    + off_axis * w.off_axis
                    + shape * w.shape;
            }
            if both && w.penetration > 0.0 {
                loss = loss + self.priors.penetration(joints, config.joint_radius) * w.penetration;
            }
            let value = f64::from(
                to_host(loss.clone().detach())?
                    .first()
                    .copied()
                    .unwrap_or(f32::NAN),
            );
            if !value.is_finite() {
                return Err(FitError::NonFinite(format!(
                    "keypoint fit loss at {stage} iteration {} (the fit diverged: check \
                     fit.learning_rate, {} here, and the camera's intrinsics)",
                    it + 1,
                    config.learning_rate
                )));
            }
            if it == 0 {
                first = value;
            }
            last = value;
            self.done += 1;
            observer.iteration(&FitProgress {
                stage,
                iteration: self.done,
                iterations: self.planned.max(self.done),
                loss: value,
                residual_px: f64::NAN,
            });
            let grads = loss.backward();
            let progress = it as f64 / (iterations.max(2) - 1) as f64;
            let decay = config.final_lr_fraction
                + (1.0 - config.final_lr_fraction)
                    * 0.5
                    * (1.0 + (std::f64::consts::PI * progress).cos());
            let vars = std::mem::replace(&mut run.vars, FitVars::zeros(self.device));
            run.vars = adam.step(vars, &grads, config.learning_rate * decay);
        }
        let res = self.residuals(&run.host(config)?, targets)?;
        let mean = |h: usize| mean_present(&res[h]);
        Ok((first, last, [mean(0), mean(1)]))
    }

    /// Per slot, the residual (pixels) of each keypoint (`None`: missing or unfitted).
    fn residuals(
        &self,
        hands: &[HandParams; 2],
        targets: &Targets,
    ) -> Result<[Vec<Option<f64>>; 2], FitError> {
        let mut out: [Vec<Option<f64>>; 2] = [Vec::new(), Vec::new()];
        for (h, side) in Side::BOTH.into_iter().enumerate() {
            let Some(points) = &targets.points[h] else {
                out[h] = vec![None; NUM_KEYPOINTS];
                continue;
            };
            let posed = self.models.get(side).forward(&hands[h])?;
            out[h] = points
                .iter()
                .zip(&posed.joints)
                .map(|(k, j)| {
                    (k.confidence > 0.0).then(|| {
                        self.camera
                            .camera_to_pixel(*j)
                            .map_or(f64::INFINITY, |p| p.distance(DVec2::new(k.x, k.y)))
                    })
                })
                .collect();
        }
        Ok(out)
    }

    /// Root stage rounds over the candidates of each slot; the best start per slot.
    fn root_search(
        &mut self,
        candidates: &[Vec<(Start, f64)>; 2],
        targets: &Targets,
        stage: &'static str,
        rounds: usize,
        stages: &mut Vec<FitStageReport>,
        observer: &mut dyn FitObserver,
    ) -> Result<RootResult, FitError> {
        let mut best: [Option<(f64, HandParams, usize)>; 2] = [None, None];
        let threshold = self.config.restart_residual_px * self.scale;
        let mut tried = [0usize; 2];
        let mut rounds_run = 0;
        for round in 0..rounds {
            let searching: Vec<bool> = (0..2)
                .map(|h| {
                    targets.fitted[h]
                        && round < candidates[h].len()
                        && best[h].as_ref().is_none_or(|b| b.0 > threshold)
                })
                .collect();
            if !searching.iter().any(|&s| s) {
                break;
            }
            let pick = |h: usize| -> &Start {
                let c = &candidates[h];
                if c.is_empty() {
                    &FALLBACK_START
                } else if searching[h] {
                    &c[round].0
                } else {
                    &c[best[h].as_ref().map_or(0, |b| b.2)].0
                }
            };
            let starts = start_params([pick(0), pick(1)]);
            let mut run = Run::new(self.models, [&starts[0], &starts[1]], self.device);
            rounds_run += 1;
            let started = Instant::now();
            let iterations = self.config.root_iterations;
            let (first, last, res) =
                self.optimise(&mut run, targets, stage, false, iterations, observer)?;
            let hands = run.host(self.config)?;
            for h in 0..2 {
                if !searching[h] {
                    continue;
                }
                tried[h] += 1;
                if best[h].as_ref().is_none_or(|b| res[h] < b.0) {
                    best[h] = Some((res[h], hands[h].clone(), round));
                }
            }
            stages.push(FitStageReport {
                stage: format!("{stage} (orientation {})", round + 1),
                iterations,
                first_loss: first,
                last_loss: last,
                residual_px: std::array::from_fn(|h| searching[h].then_some(res[h])),
                seconds: started.elapsed().as_secs_f64(),
            });
        }
        // The rounds no hand needed: skipped forward, so the planned total stays fixed.
        self.done += (rounds - rounds_run) * self.config.root_iterations;
        Ok(RootResult { best, tried })
    }
}

struct RootResult {
    best: [Option<(f64, HandParams, usize)>; 2],
    tried: [usize; 2],
}

/// The start of a slot that is not fitted (far from the other hand, out of its way).
static FALLBACK_START: Start = Start {
    root: DMat3::IDENTITY,
    trans: DVec3::new(0.0, 0.0, 10.0),
};

fn mean_present(r: &[Option<f64>]) -> f64 {
    let v: Vec<f64> = r.iter().flatten().copied().collect();
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Fits both hands of `models` to `keypoints` seen by `camera` (its intrinsics and image
/// size; the result is in its world frame). A hand with fewer than [`MIN_KEYPOINTS`] present
/// keypoints is left out, and the report says so.
///
/// # Errors
/// No hand with enough keypoints, a bad camera or configuration, models the hand layer cannot
/// batch, or a non-finite loss.
pub fn fit_keypoints(
    models: &HandPair,
    keypoints: &TwoHandKeypoints,
    camera: &PinholeCamera,
    config: &FitConfig,
    device: &Device,
    observer: &mut dyn FitObserver,
) -> Result<KeypointFit, FitError> {
    config.validate()?;
    camera.validate()?;
    let started = Instant::now();
    let mut notes = keypoints.notes.clone();
    let mut points: [Option<Vec<Keypoint>>; 2] = [None, None];
    for (h, side) in Side::BOTH.into_iter().enumerate() {
        let Some(p) = keypoints.hand(side) else {
            continue;
        };
        if p.len() != NUM_KEYPOINTS {
            return Err(FitError::Invalid(format!(
                "the {side} hand has {} keypoints, expected {NUM_KEYPOINTS}",
                p.len()
            )));
        }
        if p.iter()
            .any(|k| !(k.x.is_finite() && k.y.is_finite() && k.confidence.is_finite()))
        {
            return Err(FitError::NonFinite(format!("the {side} hand's keypoints")));
        }
        let n = keypoints.num_present(side);
        if n < MIN_KEYPOINTS {
            notes.push(format!(
                "{side} hand: only {n} keypoints are present, {MIN_KEYPOINTS} are needed; it is \
                 left out"
            ));
            continue;
        }
        points[h] = Some(p.to_vec());
    }
    if points.iter().all(Option::is_none) {
        return Err(FitError::Invalid(format!(
            "no hand has at least {MIN_KEYPOINTS} keypoints to fit"
        )));
    }
    let kept = TwoHandKeypoints {
        left: points[0].clone(),
        right: points[1].clone(),
        format: keypoints.format,
        notes: Vec::new(),
    };
    kept.check_plausible().map_err(FitError::Invalid)?;
    let cam = camera_frame(camera);
    let scale = f64::from(camera.width.max(camera.height)) / 256.0;
    let mean_pose: Vec<f32> = Side::BOTH
        .iter()
        .flat_map(|&s| models.get(s).pose_pca_mean.clone())
        .map(|x| x as f32)
        .collect();
    let mut fitter = Fitter {
        models,
        layer: HandLayer::new(models, device)?,
        priors: HandPriors::new(models, device),
        mean_pose: float(mean_pose, [2, NUM_POSE], device),
        camera: cam,
        config,
        scale,
        device,
        done: 0,
        planned: config.root_iterations
            * config.orientations
            * if config.check_handedness { 2 } else { 1 }
            + config.full_iterations,
    };
    let relaxed: Vec<(Vec<DVec3>, DVec3)> = Side::BOTH
        .iter()
        .map(|&s| -> Result<_, FitError> {
            let m = models.get(s);
            let joints = m.forward(&HandParams::mean_pose())?.joints;
            let wrist = m.regress_joints(&m.shaped_vertices(&[0.0; NUM_BETAS]))[0];
            Ok((joints, wrist))
        })
        .collect::<Result<_, _>>()?;
    let candidates_for = |pts: &[Option<Vec<Keypoint>>; 2]| -> [Vec<(Start, f64)>; 2] {
        std::array::from_fn(|h| match &pts[h] {
            Some(p) => palm_candidates(&relaxed[h].0, relaxed[h].1, p, &cam, config.orientations),
            None => Vec::new(),
        })
    };

    let mut stages = Vec::new();
    let targets = Targets::new(points.clone(), device);
    let candidates = candidates_for(&points);
    let root = fitter.root_search(
        &candidates,
        &targets,
        "root",
        config.orientations,
        &mut stages,
        observer,
    )?;

    // The swapped-sides check: each keypoint set fitted by the other side's model.
    let mut handedness = Vec::new();
    if config.check_handedness {
        let swapped_points = [points[1].clone(), points[0].clone()];
        let swapped_targets = Targets::new(swapped_points.clone(), device);
        let swapped = fitter.root_search(
            &candidates_for(&swapped_points),
            &swapped_targets,
            "handedness",
            config.orientations,
            &mut stages,
            observer,
        )?;
        for (h, side) in Side::BOTH.into_iter().enumerate() {
            if let (Some(a), Some(b)) = (&root.best[h], &swapped.best[1 - h]) {
                let agrees = a.0 <= 1.25 * b.0 || a.0 <= config.restart_residual_px * scale;
                if !agrees {
                    notes.push(format!(
                        "the keypoints given as the {side} hand fit the {} hand's model better \
                         ({:.1} px against {:.1} px): the detector's left/right labels may be \
                         swapped (for MediaPipe, see --mirrored)",
                        side.mirrored(),
                        b.0,
                        a.0
                    ));
                }
                handedness.push(HandednessCheck {
                    labelled: side,
                    labelled_px: a.0,
                    swapped_px: b.0,
                    agrees,
                });
            }
        }
    }

    // Everything, from the best root per hand.
    let fallback = start_params([&FALLBACK_START, &FALLBACK_START]);
    let starts: [HandParams; 2] = std::array::from_fn(|h| {
        root.best[h]
            .as_ref()
            .map_or_else(|| fallback[h].clone(), |b| b.1.clone())
    });
    let mut run = Run::new(models, [&starts[0], &starts[1]], device);
    let t = Instant::now();
    let (first, last, res) = fitter.optimise(
        &mut run,
        &targets,
        "all",
        true,
        config.full_iterations,
        observer,
    )?;
    stages.push(FitStageReport {
        stage: "all".into(),
        iterations: config.full_iterations,
        first_loss: first,
        last_loss: last,
        residual_px: std::array::from_fn(|h| targets.fitted[h].then_some(res[h])),
        seconds: t.elapsed().as_secs_f64(),
    });
    let fitted = run.host(config)?;
    let residuals = fitter.residuals(&fitted, &targets)?;
    let axes = flexion_axes(models);
    let mut hands_report = Vec::new();
    let mut out: [Option<HandParams>; 2] = [None, None];
    // Camera frame -> the camera's world frame.
    let to_world = camera.rotation.transpose();
    let world_shift = -(to_world * camera.translation);
    for (h, side) in Side::BOTH.into_iter().enumerate() {
        if !targets.fitted[h] {
            continue;
        }
        let p = &fitted[h];
        let r = &residuals[h];
        let present: Vec<f64> = r.iter().flatten().copied().collect();
        let aa = models.get(side).pose_axis_angles(&p.pose);
        let per_joint = flexion_angles(&aa, &axes[45 * h..45 * h + 45]);
        let flex: Vec<f64> = per_joint.iter().flatten().copied().collect();
        let wrist = models.get(side).forward(p)?.joints[0];
        check_fitted_hand(side, wrist.z, mean_present(r), kept.span_px(side))?;
        hands_report.push(HandFitReport {
            side,
            keypoints: present.len(),
            residual_px: r.clone(),
            mean_residual_px: mean_present(r),
            max_residual_px: present.iter().copied().fold(0.0, f64::max),
            wrist_depth_m: wrist.z,
            orientations_tried: root.tried[h],
            orientation_kept: root.best[h].as_ref().map_or(0, |b| b.2),
            flexion_deg: per_joint.iter().map(|a| a.map(f64::to_degrees)).collect(),
            min_flexion_deg: flex
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min)
                .to_degrees(),
            bent_backwards: flex.iter().filter(|&&a| a < FLEXION_RANGE.0 - 1e-3).count(),
        });
        out[h] = Some(p.rigidly_moved(models.get(side), to_world, world_shift));
    }
    let [left, right] = out;
    let f = camera.focal();
    let c = camera.principal_point();
    Ok(KeypointFit {
        hands: TwoHandScene {
            left,
            right,
            camera: *camera,
            frame: Default::default(),
        },
        report: FitReport {
            image_size: [camera.height as usize, camera.width as usize],
            intrinsics: [f.x, f.y, c.x, c.y],
            hands: hands_report,
            stages,
            handedness,
            notes,
            seconds: started.elapsed().as_secs_f64(),
            config: config.clone(),
        },
    })
}

/// The largest mean keypoint residual of a fitted hand, as a fraction of the span of its
/// keypoints: the detections of the demo frames and of 12 resized, mirrored, rotated and
/// shifted copies fit to 0.004 to 0.015 of their span; 21 random points in the photo miss by
/// 0.16, a detection's points in shuffled order by 0.14.
pub const MAX_RESIDUAL_OF_SPAN: f64 = 0.08;

/// Refuses a fitted hand that cannot be the photographed one: its wrist outside
/// [`HAND_DEPTH_RANGE_M`], or its mean residual above [`MAX_RESIDUAL_OF_SPAN`] of the
/// keypoints' span.
fn check_fitted_hand(
    side: Side,
    wrist_depth_m: f64,
    residual_px: f64,
    span_px: Option<f64>,
) -> Result<(), FitError> {
    let [near, far] = HAND_DEPTH_RANGE_M;
    if !(near..=far).contains(&wrist_depth_m) {
        return Err(FitError::Invalid(format!(
            "the {side} hand's keypoints fit a hand {wrist_depth_m:.3} m from the camera (a \
             photographed hand lies {near} to {far} m away): are the keypoints in the photo's \
             pixels (see --format) and the intrinsics the photo's?"
        )));
    }
    if let Some(span) = span_px
        && residual_px > MAX_RESIDUAL_OF_SPAN * span
    {
        return Err(FitError::Invalid(format!(
            "the {side} hand's keypoints fit no hand: the fitted hand misses them by \
             {residual_px:.1} px on average, {:.0}% of the {span:.0} px they span (at most \
             {:.0}%); check that they are a hand's 21 points in OpenPose order",
            100.0 * residual_px / span,
            100.0 * MAX_RESIDUAL_OF_SPAN
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::keypoints::KeypointFormat;

    /// Two procedural hands in a clearly non-trivial pose in front of a 256-pixel camera,
    /// and their exact 2D joints.
    fn scene() -> (TwoHandScene, TwoHandKeypoints) {
        let models = bitt_mesh::procedural_pair();
        let camera =
            PinholeCamera::from_intrinsics([420.0, 420.0], [128.0, 120.0], 256, 256).unwrap();
        let hand = |side: Side, rot: DVec3, trans: DVec3, curl: f64| {
            let mean = &models.get(side).pose_pca_mean;
            HandParams {
                root_rotation: bitt_mesh::lbs::rodrigues(rot),
                pose: HandPose::AxisAngle(mean.iter().map(|a| a * curl).collect()),
                betas: vec![0.0; NUM_BETAS],
                trans,
            }
        };
        let hands = TwoHandScene {
            left: Some(hand(
                Side::Left,
                DVec3::new(0.3, 1.2, 0.2),
                DVec3::new(-0.06, 0.0, 0.45),
                2.0,
            )),
            right: Some(hand(
                Side::Right,
                DVec3::new(-0.4, -0.9, 0.5),
                DVec3::new(0.07, 0.02, 0.5),
                0.5,
            )),
            camera,
            frame: Default::default(),
        };
        let posed = hands.pose_in_camera(&models).unwrap();
        let kp = |side: Side| {
            posed
                .get(side)
                .map(|p| bitt_mesh::keypoints::project_points(&p.joints, &camera, 1.0))
        };
        let keypoints = TwoHandKeypoints {
            left: kp(Side::Left),
            right: kp(Side::Right),
            format: KeypointFormat::Plain,
            notes: Vec::new(),
        };
        (hands, keypoints)
    }

    #[test]
    fn exact_keypoints_are_fitted_to_within_a_pixel_from_the_relaxed_pose() {
        let (truth, keypoints) = scene();
        let models = bitt_mesh::procedural_pair();
        let device = Device::flex().autodiff();
        let config = FitConfig {
            check_handedness: false,
            ..FitConfig::default()
        };
        let fit = fit_keypoints(
            &models,
            &keypoints,
            &truth.camera,
            &config,
            &device,
            &mut Quiet,
        )
        .unwrap();
        assert_eq!(fit.report.hands.len(), 2);
        for h in &fit.report.hands {
            assert!(
                h.mean_residual_px < 1.0,
                "{} hand: {:.2} px",
                h.side,
                h.mean_residual_px
            );
            assert_eq!(h.bent_backwards, 0);
        }
        // The fitted wrists are at the true depth within 10 %.
        let posed = truth.pose_in_camera(&models).unwrap();
        for h in &fit.report.hands {
            let z = posed.get(h.side).unwrap().joints[0].z;
            assert!((h.wrist_depth_m - z).abs() < 0.1 * z, "{h:?} vs {z}");
        }
    }

    #[test]
    fn a_hand_with_too_few_keypoints_is_left_out_and_none_is_an_error() {
        let (truth, mut keypoints) = scene();
        let models = bitt_mesh::procedural_pair();
        let device = Device::flex().autodiff();
        let config = FitConfig {
            root_iterations: 5,
            full_iterations: 5,
            orientations: 1,
            check_handedness: false,
            ..FitConfig::default()
        };
        for p in keypoints.left.as_mut().unwrap().iter_mut().skip(4) {
            p.confidence = 0.0;
        }
        let fit = fit_keypoints(
            &models,
            &keypoints,
            &truth.camera,
            &config,
            &device,
            &mut Quiet,
        )
        .unwrap();
        assert!(fit.hands.left.is_none() && fit.hands.right.is_some());
        assert!(
            fit.report
                .notes
                .iter()
                .any(|n| n.contains("left hand: only 4"))
        );
        keypoints.right = None;
        let e = fit_keypoints(
            &models,
            &keypoints,
            &truth.camera,
            &config,
            &device,
            &mut Quiet,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("no hand"), "{e}");
    }

    /// Issue 38, class 1: points that are not a photographed hand are refused with the reason,
    /// not fitted (before, each of these "succeeded").
    #[test]
    fn keypoints_that_are_not_a_hand_are_refused() {
        let (truth, keypoints) = scene();
        let models = bitt_mesh::procedural_pair();
        let device = Device::flex().autodiff();
        let config = FitConfig {
            check_handedness: false,
            ..FitConfig::default()
        };
        let fit = |kp: &TwoHandKeypoints, camera: &PinholeCamera| {
            fit_keypoints(&models, kp, camera, &config, &device, &mut Quiet)
                .map(|_| ())
                .unwrap_err()
                .to_string()
        };
        let map = |f: &dyn Fn(usize, &Keypoint) -> Keypoint| TwoHandKeypoints {
            left: keypoints
                .left
                .as_ref()
                .map(|h| h.iter().enumerate().map(|(i, p)| f(i, p)).collect()),
            right: keypoints
                .right
                .as_ref()
                .map(|h| h.iter().enumerate().map(|(i, p)| f(i, p)).collect()),
            ..keypoints.clone()
        };
        // Normalised coordinates read as pixels.
        let e = fit(
            &map(&|_, p| Keypoint {
                x: p.x / 256.0,
                y: p.y / 256.0,
                ..*p
            }),
            &truth.camera,
        );
        assert!(e.contains("span 0.") && e.contains("normalised"), "{e}");
        // Every point on one pixel.
        let e = fit(
            &map(&|_, p| Keypoint {
                x: 100.0,
                y: 90.0,
                ..*p
            }),
            &truth.camera,
        );
        assert!(e.contains("span 0.00 px"), "{e}");
        // Points on a line.
        let e = fit(
            &map(&|i, p| Keypoint {
                x: 40.0 + 5.0 * i as f64,
                y: 50.0 + 3.0 * i as f64,
                ..*p
            }),
            &truth.camera,
        );
        assert!(e.contains("lie on a line"), "{e}");
        // Confidences of 1e-300.
        let e = fit(
            &map(&|_, p| Keypoint {
                confidence: 1e-300,
                ..*p
            }),
            &truth.camera,
        );
        assert!(e.contains("highest confidence is 1e-300"), "{e}");
        // Both hands given the same points.
        let same = TwoHandKeypoints {
            left: keypoints.right.clone(),
            ..keypoints.clone()
        };
        let e = fit(&same, &truth.camera);
        assert!(e.contains("the same points"), "{e}");
        // The points in another order (not a hand's skeleton).
        let order = [
            7, 19, 3, 12, 0, 16, 9, 4, 20, 1, 14, 6, 11, 18, 2, 8, 15, 5, 13, 10, 17,
        ];
        let shuffled = TwoHandKeypoints {
            left: keypoints
                .left
                .as_ref()
                .map(|h| order.iter().map(|&i| h[i]).collect()),
            right: None,
            ..keypoints.clone()
        };
        let e = fit(&shuffled, &truth.camera);
        assert!(e.contains("left hand's keypoints fit no hand"), "{e}");
        // A 12-pixel hand under a focal length of 100 times the image: 100s of metres away.
        let far =
            PinholeCamera::from_intrinsics([25_600.0, 25_600.0], [128.0, 120.0], 256, 256).unwrap();
        let tiny = map(&|_, p| Keypoint {
            x: 128.0 + (p.x - 128.0) * 0.1,
            y: 120.0 + (p.y - 120.0) * 0.1,
            ..*p
        });
        let e = fit(&tiny, &far);
        assert!(
            e.contains("m from the camera (a photographed hand lies 0.05 to 20 m"),
            "{e}"
        );
    }

    /// Issue 37: the fit's progress total is fixed from the first iteration, the position
    /// only grows, and it ends at the total (restarts or not).
    #[test]
    fn fit_progress_has_a_fixed_total() {
        struct Record(Vec<(usize, usize)>);
        impl FitObserver for Record {
            fn iteration(&mut self, p: &FitProgress) {
                self.0.push((p.iteration, p.iterations));
            }
        }
        let (truth, keypoints) = scene();
        let models = bitt_mesh::procedural_pair();
        let device = Device::flex().autodiff();
        let config = FitConfig {
            root_iterations: 30,
            full_iterations: 120,
            restart_residual_px: 1e-9,
            orientations: 3,
            ..FitConfig::default()
        };
        for check_handedness in [false, true] {
            let config = FitConfig {
                check_handedness,
                ..config.clone()
            };
            let mut seen = Record(Vec::new());
            fit_keypoints(
                &models,
                &keypoints,
                &truth.camera,
                &config,
                &device,
                &mut seen,
            )
            .unwrap();
            let total = 30 * 3 * if check_handedness { 2 } else { 1 } + 120;
            assert!(seen.0.iter().all(|&(_, t)| t == total), "{:?}", seen.0);
            assert!(seen.0.windows(2).all(|w| w[1].0 > w[0].0), "{:?}", seen.0);
            assert_eq!(seen.0.last().unwrap().0, total);
        }
    }

    /// Issue 38, class 10: a learning rate of 1e30 is named as such, not as a non-finite loss.
    #[test]
    fn absurd_learning_rates_are_named() {
        let fit = FitConfig {
            learning_rate: 1e30,
            ..FitConfig::default()
        };
        let e = fit.validate().unwrap_err().to_string();
        assert!(
            e.contains("fit.learning_rate = 1000000000000000000000000000000 is out of range")
                && e.contains("(0, 1]")
                && e.contains("only diverges"),
            "{e}"
        );
        let refine = crate::refine::RefineConfig {
            learning_rate: 2.0,
            ..Default::default()
        };
        let e = refine.validate().unwrap_err().to_string();
        assert!(
            e.contains("refine.learning_rate = 2 is out of range"),
            "{e}"
        );
        FitConfig::default().validate().unwrap();
    }

    #[test]
    fn fitted_hands_are_checked_for_depth_and_residual() {
        assert!(check_fitted_hand(Side::Left, 0.4, 2.0, Some(200.0)).is_ok());
        let e = check_fitted_hand(Side::Right, 100.0, 0.01, Some(0.5)).unwrap_err();
        assert!(
            e.to_string()
                .contains("right hand's keypoints fit a hand 100.000 m")
        );
        let e = check_fitted_hand(Side::Left, 0.4, 30.0, Some(200.0)).unwrap_err();
        assert!(e.to_string().contains("15% of the 200 px"), "{e}");
    }

    /// The keypoints of [`scene`] written as OpenPose, MediaPipe (Python and JS field names)
    /// and plain files, exactly in those tools' layouts.
    fn keypoint_files(kp: &TwoHandKeypoints, dir: &std::path::Path) -> Vec<std::path::PathBuf> {
        let (w, h) = (256.0, 256.0);
        let flat = |side: Side| -> Vec<f64> {
            kp.hand(side)
                .unwrap()
                .iter()
                .flat_map(|k| [k.x, k.y, k.confidence])
                .collect()
        };
        let openpose = serde_json::json!({
            "version": 1.3,
            "people": [{
                "person_id": [-1],
                "pose_keypoints_2d": vec![0.0; 75],
                "face_keypoints_2d": vec![0.0; 210],
                "hand_left_keypoints_2d": flat(Side::Left),
                "hand_right_keypoints_2d": flat(Side::Right),
                "pose_keypoints_3d": [],
                "face_keypoints_3d": [],
                "hand_left_keypoints_3d": [],
                "hand_right_keypoints_3d": []
            }]
        });
        // MediaPipe's Tasks API: normalised from the image's edges; its label names the hand
        // as the image shows it.
        let landmarks = |side: Side| -> Vec<serde_json::Value> {
            kp.hand(side)
                .unwrap()
                .iter()
                .map(|k| {
                    serde_json::json!({"x": (k.x + 0.5) / w, "y": (k.y + 0.5) / h, "z": 0.0,
                        "visibility": 0.0, "presence": 0.0})
                })
                .collect()
        };
        let python = serde_json::json!({
            "handedness": [
                [{"index": 1, "score": 0.97, "display_name": "Right", "category_name": "Right"}],
                [{"index": 0, "score": 0.95, "display_name": "Left", "category_name": "Left"}]
            ],
            "hand_landmarks": [landmarks(Side::Right), landmarks(Side::Left)],
            "hand_world_landmarks": [[], []]
        });
        let js = serde_json::json!({
            "handedness": [
                [{"score": 0.95, "index": 0, "categoryName": "Left", "displayName": "Left"}],
                [{"score": 0.97, "index": 1, "categoryName": "Right", "displayName": "Right"}]
            ],
            "landmarks": [landmarks(Side::Left), landmarks(Side::Right)],
            "worldLandmarks": [[], []]
        });
        let files = [
            ("openpose.json", openpose.to_string()),
            ("python.json", python.to_string()),
            ("js.json", js.to_string()),
            ("plain.json", kp.to_plain_json()),
        ];
        files
            .iter()
            .map(|(name, text)| {
                let path = dir.join(name);
                std::fs::write(&path, text).unwrap();
                path
            })
            .collect()
    }

    #[test]
    fn the_same_keypoints_in_every_format_give_the_same_fit() {
        let (truth, keypoints) = scene();
        let dir = std::env::temp_dir().join(format!("bitt-fit-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let models = bitt_mesh::procedural_pair();
        let device = Device::flex().autodiff();
        let config = FitConfig {
            root_iterations: 20,
            full_iterations: 30,
            orientations: 2,
            ..FitConfig::default()
        };
        let options = bitt_mesh::keypoints::KeypointOptions {
            format: None,
            image_size: [256, 256],
            labels_as_is: false,
        };
        let mut fits = Vec::new();
        for path in keypoint_files(&keypoints, &dir) {
            let read = bitt_mesh::keypoints::read_keypoints(&path, &options).unwrap();
            for side in Side::BOTH {
                for (a, b) in read
                    .hand(side)
                    .unwrap()
                    .iter()
                    .zip(keypoints.hand(side).unwrap())
                {
                    assert!(
                        (a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9,
                        "{}: {side} {a:?} vs {b:?}",
                        path.display()
                    );
                }
            }
            let fit =
                fit_keypoints(&models, &read, &truth.camera, &config, &device, &mut Quiet).unwrap();
            fits.push((path, fit));
        }
        let (_, first) = &fits[0];
        for (path, fit) in &fits[1..] {
            for side in Side::BOTH {
                let (a, b) = (
                    first.hands.hand(side).unwrap(),
                    fit.hands.hand(side).unwrap(),
                );
                let pa = models.get(side).pose_axis_angles(&a.pose);
                let pb = models.get(side).pose_axis_angles(&b.pose);
                let worst = pa
                    .iter()
                    .zip(&pb)
                    .map(|(x, y)| (x - y).abs())
                    .chain([(a.trans - b.trans).length()])
                    .chain(
                        (a.root_rotation - b.root_rotation)
                            .to_cols_array()
                            .map(f64::abs),
                    )
                    .fold(0.0, f64::max);
                assert!(
                    worst < 1e-4,
                    "{}: {side} differs by {worst:e}",
                    path.display()
                );
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
