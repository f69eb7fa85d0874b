//! Synthetic two-hand scenes: the project's built-in, license-free benchmark.
//!
//! Real two-hand data (InterHand2.6M, RGB2Hands) and the MANO/HTML models are licensed, so
//! the project makes its own scenes with complete ground truth, including the texture of the
//! sides the camera never sees. A scene is deterministic in its [`SynthConfig`] and seed:
//!
//! - **identity**: shape coefficients (betas) of the procedural hand shared by both hands,
//!   and a skin from the procedural texture generator ([`bitt_texture::generate_texture`] of
//!   a [`bitt_texture::SkinIdentity`]; *not* sampled from the texture PCA, so the PCA prior
//!   is imperfect as HTML is for real hands), a personal appearance the PCA cannot know
//!   (patches of uneven tone and redness, the same on both hands) and one-sided details
//!   ([`texture`]);
//! - **poses**: interacting two-hand poses of the kinds InterHand2.6M has ([`pose`]);
//! - **views**: pinhole cameras around the hands, the hands' bounding box filling 72-88% of
//!   the training image (62-80% of novel views); the training camera is the best of
//!   [`TRAIN_CAMERA_CANDIDATES`] random ones at showing both hands; one studio point light
//!   with ambient light per scene ([`views`]);
//! - per scene: the training view, `novel_views` other cameras of the same frame,
//!   `novel_poses` other poses of the same identity (paper section 4.1), each with image,
//!   hand masks, hand parameters, camera and light; the ground-truth textures of both hands;
//!   the meshes given to the method (optionally perturbed, [`MeshNoise`]).
//!
//! Every image is exactly [`HandRenderer::render`] of the GT textures (see [`render`] for
//! the recipe); with [`SynthConfig::degrade`] only the **training** image is then blurred,
//! noised and JPEG-compressed ([`degrade`]); novel views and poses stay clean ground truth.
//! Backgrounds are black, as the reference renders.
//!
//! Scenes are written to and read from one folder each ([`SynthScene::write`],
//! [`SynthScene::read`]) and cached by [`cached_scene`].
//!
//! Architecture invariant: the same configuration and seed give the same scene, byte for
//! byte on disk; each random part draws from its own stream derived from the seed. Bump
//! [`GENERATOR_VERSION`] whenever a change alters the output.

pub mod degrade;
mod error;
mod io;
pub mod pose;
pub mod render;
mod set;
mod sheet;
pub mod stats;
pub mod texture;
pub mod views;

use std::path::Path;

use bitt_mesh::annotation::FrameInfo;
use bitt_mesh::glam::DVec3;
use bitt_mesh::keypoints::{KeypointFormat, TwoHandKeypoints, project_points};
use bitt_mesh::lbs::{HandParams, HandPose, rodrigues};
use bitt_mesh::model::NUM_BETAS;
use bitt_mesh::{HandPair, Side, TwoHandScene, procedural_pair};
use bitt_render::scene::LightValues;
use bitt_texture::SkinIdentity;
use bitt_texture::procedural::noise::{SplitMix64, derive};
use burn::tensor::Device;

pub use degrade::Degradation;
pub use error::SynthError;
pub use io::{GENERATOR_VERSION, cached_scene, scene_cache_dir};
pub use pose::PoseFamily;
pub use render::{
    HandRenderer, RenderedView, camera_frame_camera, textured_mesh, textured_mesh_with,
};
pub use set::{SceneSet, WrittenScene, write_scene_set};
pub use sheet::{PANEL, contact_sheet};
pub use stats::{TexelStats, scene_stats};
pub use texture::{AppearancePatch, PatchKind, SkinDetail, TEXTURE_GUTTER, texture_layouts};
pub use views::StudioLight;

/// Perturbation of the meshes given to the method (the paper's "without GT mesh" setting,
/// Table 1b); the images stay rendered from the true meshes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeshNoise {
    /// Standard deviation (radians) added to every finger axis-angle component; half of it
    /// turns each root rotation about a random axis.
    pub pose_std: f64,
    /// Standard deviation added to every shape coefficient (beta).
    pub shape_std: f64,
    /// Standard deviation (pixels of the training image) of each hand's shift parallel to
    /// the image plane.
    pub translation_px: f64,
}

impl Default for MeshNoise {
    /// An image-aligned single-image estimate (as IntagHand's, which the paper uses): 0.025
    /// rad per finger joint component, 0.15 per beta, 1 px of translation. On the first four
    /// benchmark scenes at 128 px this moves the projected vertices by 1.7-2.0 px on average
    /// (3.5-4 px at the paper's 256 px; largest 4-9 px at 128): see the example
    /// `mesh_noise_calibration` (`cargo xtask mesh-noise-calibration`). The earlier default (0.08, 0.5, 3 px: 5-6 px mean at 128) cost
    /// every method about 10 dB, far more than the 1-1.5 dB of the paper's Table 1b.
    fn default() -> Self {
        MeshNoise {
            pose_std: 0.025,
            shape_std: 0.15,
            translation_px: 1.0,
        }
    }
}

/// What to generate. `Default` is the default benchmark's configuration.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SynthConfig {
    /// Image side in pixels (square images). The presets are 128 and 256 (default 256);
    /// 32 to 1024 are accepted.
    pub size: u32,
    /// Side of the UV texture of the procedural layout (default 256; 64 to 2048).
    pub texture_size: usize,
    /// Novel views of the training frame per scene (default 8, paper section 4.1).
    pub novel_views: usize,
    /// Novel poses of the same identity per scene (default 8).
    pub novel_poses: usize,
    /// Perturb the meshes given to the method (`None`: the true meshes).
    pub mesh_noise: Option<MeshNoise>,
    /// Mild camera degradation (blur, noise, JPEG) of the training image (default on).
    pub degrade: bool,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            size: 256,
            texture_size: 256,
            novel_views: 8,
            novel_poses: 8,
            mesh_noise: None,
            degrade: true,
        }
    }
}

impl SynthConfig {
    /// Checks every value's range.
    ///
    /// # Errors
    /// [`SynthError::Config`] naming the value.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |s: String| Err(SynthError::Config(s));
        if !(32..=1024).contains(&self.size) {
            return bad(format!("size must be 32 to 1024 (got {})", self.size));
        }
        if !(64..=2048).contains(&self.texture_size) {
            return bad(format!(
                "texture_size must be 64 to 2048 (got {})",
                self.texture_size
            ));
        }
        if self.novel_views > 64 || self.novel_poses > 64 {
            return bad(format!(
                "at most 64 novel views and poses (got {} and {})",
                self.novel_views, self.novel_poses
            ));
        }
        if let Some(n) = &self.mesh_noise {
            let ok = |x: f64, max: f64| x.is_finite() && (0.0..=max).contains(&x);
            if !(ok(n.pose_std, 1.0) && ok(n.shape_std, 3.0) && ok(n.translation_px, 50.0)) {
                return bad(format!(
                    "mesh noise must be finite and within pose_std 0-1, shape_std 0-3, \
                     translation_px 0-50 (got {n:?})"
                ));
            }
        }
        Ok(())
    }
}

/// One rendered view of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthView {
    /// `"train"`, `"view_00"`.., `"pose_00"`...
    pub name: String,
    /// The family of the two-hand pose.
    pub family: PoseFamily,
    /// The true hand parameters (both present, person frame) and this view's camera.
    pub hands: TwoHandScene,
    /// The light, location in this view's **camera frame** (as [`HandRenderer::render`]
    /// takes it).
    pub light: LightValues,
    /// `[3, H, W]` channel-major in `[0, 1]`, black background.
    pub image: Vec<f32>,
    /// Left and right `[H, W]` masks in `{0, 1}` after mutual occlusion.
    pub masks: [Vec<f32>; 2],
}

impl SynthView {
    /// Each hand's 21 true 2D joints in this view's image (pixels, OpenPose order,
    /// confidence 1; a joint behind the camera has confidence 0), as `scene.json` holds them
    /// under `keypoints_2d` (the plain keypoint format).
    ///
    /// # Errors
    /// When a hand cannot be posed.
    pub fn keypoints_2d(&self) -> Result<TwoHandKeypoints, SynthError> {
        let posed = self.hands.pose_in_camera(&procedural_pair())?;
        let hand = |side: Side| {
            posed
                .get(side)
                .map(|p| project_points(&p.joints, &self.hands.camera, 1.0))
        };
        Ok(TwoHandKeypoints {
            left: hand(Side::Left),
            right: hand(Side::Right),
            format: KeypointFormat::Plain,
            notes: Vec::new(),
        })
    }
}

/// The identity of a scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Identity {
    /// Shape coefficients of the procedural hand, shared by both hands.
    pub betas: Vec<f64>,
    /// The skin.
    pub skin: SkinIdentity,
    /// Personal appearance (uneven tone, redness) painted on both hands alike.
    #[serde(default)]
    pub appearance: Vec<AppearancePatch>,
    /// One-sided details painted on one hand's texture only.
    pub details: Vec<SkinDetail>,
}

/// A synthetic scene with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthScene {
    /// The configuration it was generated with.
    pub config: SynthConfig,
    /// Its seed.
    pub seed: u64,
    /// The identity (betas, skin, one-sided details).
    pub identity: Identity,
    /// The scene's studio light in the person frame (every view's light is this one in the
    /// view's camera frame).
    pub studio_light: StudioLight,
    /// The training view (degraded when `config.degrade`).
    pub train: SynthView,
    /// The degradation applied to the training image, if any.
    pub train_degradation: Option<Degradation>,
    /// The training frame from other cameras.
    pub novel_views: Vec<SynthView>,
    /// Other two-hand poses of the same identity.
    pub novel_poses: Vec<SynthView>,
    /// The meshes given to the method for the training view (the train camera; equal to
    /// `train.hands` unless `config.mesh_noise`).
    pub given: TwoHandScene,
    /// Ground-truth albedo textures, left and right, compact `[3, T]` in the layouts of
    /// [`texture_layouts`] at `config.texture_size`.
    pub textures: [Vec<f32>; 2],
    /// Texture-space visibility of the training view (Table 3).
    pub stats: TexelStats,
}

impl SynthScene {
    /// How far the meshes given to the method are from the true training meshes: the mean
    /// and the largest distance (pixels of the training image) between the projections of
    /// corresponding vertices of both hands. `(0, 0)` without mesh noise.
    ///
    /// # Errors
    /// When a hand cannot be posed.
    pub fn given_mesh_error_px(&self) -> Result<(f64, f64), SynthError> {
        Ok(self
            .train
            .hands
            .projected_distance_px(&self.given, &procedural_pair())?)
    }

    /// Every view: train, novel views, novel poses.
    pub fn views(&self) -> impl Iterator<Item = &SynthView> {
        std::iter::once(&self.train)
            .chain(&self.novel_views)
            .chain(&self.novel_poses)
    }

    /// Writes the scene into folder `dir` (created if missing): `scene.json` (configuration,
    /// seed, identity, light, statistics, hand parameters, camera and light of every view, the
    /// given meshes), `data.safetensors` (every image, mask and texture, exactly: 8-bit images and masks as bytes), and
    /// for looking at: `<view>.png`, `<view>.mask.png` (red left, green right) and
    /// `texture_left.png` / `texture_right.png` (UV images). Every file is written atomically.
    ///
    /// # Errors
    /// Unwritable folder or files.
    pub fn write(&self, dir: &Path) -> Result<(), SynthError> {
        io::write(self, dir)
    }

    /// Reads a scene written by [`SynthScene::write`]: exactly the scene that was written
    /// (images, masks and textures come from `data.safetensors`; the PNGs are not read).
    ///
    /// # Errors
    /// Missing or corrupt files, another format or generator version, inconsistent shapes;
    /// each names the file.
    pub fn read(dir: &Path) -> Result<SynthScene, SynthError> {
        io::read(dir)
    }
}

/// The fixed seed of the built-in demo scene.
pub fn demo_scene_seed() -> u64 {
    0xB177_0DE3_0000_0001
}

/// The seeds of the default benchmark's first `n` scenes (the default benchmark has 24).
pub fn benchmark_seeds(n: usize) -> Vec<u64> {
    (0..n as u64).map(|i| derive(0xB177_BE7C_4A11, i)).collect()
}

/// Training-camera candidates per scene (the one showing both hands best is kept).
pub const TRAIN_CAMERA_CANDIDATES: usize = 6;

/// Number of scenes of the default benchmark.
pub const BENCHMARK_SCENES: usize = 24;

/// Random streams of a scene, one per purpose, so changing one part does not reshuffle the
/// others.
mod stream {
    pub const SHAPE: u64 = 1;
    pub const SKIN: u64 = 2;
    pub const DETAILS: u64 = 3;
    pub const TRAIN_POSE: u64 = 4;
    pub const CAMERAS: u64 = 5;
    pub const LIGHT: u64 = 6;
    pub const NOVEL_POSES: u64 = 7;
    pub const DEGRADE: u64 = 8;
    pub const MESH_NOISE: u64 = 9;
    pub const APPEARANCE: u64 = 10;
}

/// Generates the scene of `seed` with `config`, rendering on `device`.
///
/// # Errors
/// An invalid configuration, or a failure of posing or rendering.
pub fn generate_scene(
    config: &SynthConfig,
    seed: u64,
    device: &Device,
) -> Result<SynthScene, SynthError> {
    config.validate()?;
    let models = procedural_pair();
    let rig = pose::Rig::new(&models.right)?;
    let rng = |label: u64| SplitMix64::new(derive(seed, label));

    // Identity.
    let mut shape = rng(stream::SHAPE);
    let betas: Vec<f64> = (0..NUM_BETAS)
        .map(|_| (0.8 * shape.normal()).clamp(-2.0, 2.0))
        .collect();
    let skin = SkinIdentity::sample(derive(seed, stream::SKIN));
    let layouts = texture_layouts(&models, config.texture_size)?;
    let points = texture::texel_points(&models, &layouts[1])?;
    let appearance = texture::draw_appearance(&points, &mut rng(stream::APPEARANCE));
    let details = texture::draw_details(&models, &points, &mut rng(stream::DETAILS))?;
    let textures =
        texture::identity_textures(&models, &layouts, &points, &skin, &appearance, &details)?;
    let renderer = HandRenderer::new(&models, &layouts, &textures, device)?;

    // The training frame.
    let mut pose_rng = rng(stream::TRAIN_POSE);
    let family = pick_family(&mut pose_rng);
    let train_pose = pose::two_hand_pose(&models, &rig, &betas, family, &mut pose_rng)?;
    let points_train = pose_points(&models, &train_pose)?;
    let hands = |p: &pose::TwoHandPose, camera: bitt_mesh::PinholeCamera| TwoHandScene {
        left: Some(p.left.clone()),
        right: Some(p.right.clone()),
        camera,
        frame: FrameInfo::default(),
    };
    let mut cam_rng = rng(stream::CAMERAS);
    let size = config.size;
    let mut light_rng = rng(stream::LIGHT);
    let light_seed = light_rng.next_u64();
    // The training camera: the candidate that shows both hands best (largest visible share
    // of the less visible hand), as datasets keep frames where both hands are seen.
    let mut best: Option<(f64, bitt_mesh::PinholeCamera)> = None;
    for _ in 0..TRAIN_CAMERA_CANDIDATES {
        let camera = views::framed_camera(
            &views::train_placement(&mut cam_rng),
            DVec3::ZERO,
            &points_train,
            size,
        )?;
        let l = StudioLight::sample(&mut SplitMix64::new(light_seed), &camera, DVec3::ZERO);
        let r = renderer.render(&hands(&train_pose, camera), &l.in_camera(&camera))?;
        let s = stats::view_stats(&models, &layouts, &r)?.table3;
        let score = s.left_visible.min(s.right_visible);
        if best.as_ref().is_none_or(|(b, _)| score > *b) {
            best = Some((score, camera));
        }
    }
    let (_, train_camera) =
        best.ok_or_else(|| SynthError::Generate("no training camera candidate".into()))?;
    let light = StudioLight::sample(&mut SplitMix64::new(light_seed), &train_camera, DVec3::ZERO);
    let view = |name: String,
                family: PoseFamily,
                scene: TwoHandScene|
     -> Result<(SynthView, RenderedView), SynthError> {
        let l = light.in_camera(&scene.camera);
        let r = renderer.render(&scene, &l)?;
        Ok((
            SynthView {
                name,
                family,
                hands: scene,
                light: l,
                image: degrade::to_8bit(&r.image),
                masks: r.masks.clone(),
            },
            r,
        ))
    };
    let (mut train, train_render) = view("train".into(), family, hands(&train_pose, train_camera))?;
    let stats = stats::view_stats(&models, &layouts, &train_render)?;
    let train_degradation = if config.degrade {
        let d = Degradation::sample(&mut rng(stream::DEGRADE));
        train.image = d.apply(&train_render.image, size as usize)?;
        Some(d)
    } else {
        None
    };

    let mut novel_views = Vec::with_capacity(config.novel_views);
    for (k, placement) in views::novel_placements(config.novel_views, &mut cam_rng)
        .iter()
        .enumerate()
    {
        let camera = views::framed_camera(placement, DVec3::ZERO, &points_train, size)?;
        novel_views.push(view(format!("view_{k:02}"), family, hands(&train_pose, camera))?.0);
    }
    let mut novel_rng = rng(stream::NOVEL_POSES);
    let mut novel_poses = Vec::with_capacity(config.novel_poses);
    for k in 0..config.novel_poses {
        let family = pick_family(&mut novel_rng);
        let p = pose::two_hand_pose(&models, &rig, &betas, family, &mut novel_rng)?;
        let pts = pose_points(&models, &p)?;
        let camera = views::framed_camera(
            &views::train_placement(&mut novel_rng),
            DVec3::ZERO,
            &pts,
            size,
        )?;
        novel_poses.push(view(format!("pose_{k:02}"), family, hands(&p, camera))?.0);
    }
    let given = match &config.mesh_noise {
        None => train.hands.clone(),
        Some(noise) => noisy_hands(&train.hands, noise, &mut rng(stream::MESH_NOISE)),
    };
    Ok(SynthScene {
        config: config.clone(),
        seed,
        identity: Identity {
            betas,
            skin,
            appearance,
            details,
        },
        studio_light: light,
        train,
        train_degradation,
        novel_views,
        novel_poses,
        given,
        textures,
        stats,
    })
}

/// A pose family drawn with [`PoseFamily::weight`].
fn pick_family(rng: &mut SplitMix64) -> PoseFamily {
    let total: f64 = PoseFamily::ALL.iter().map(|f| f.weight()).sum();
    let mut x = rng.next_f64() * total;
    for f in PoseFamily::ALL {
        x -= f.weight();
        if x < 0.0 {
            return f;
        }
    }
    PoseFamily::Prayer
}

/// The posed vertices of both hands (person frame).
fn pose_points(models: &HandPair, p: &pose::TwoHandPose) -> Result<Vec<DVec3>, SynthError> {
    let mut pts = models.left.forward(&p.left)?.vertices;
    pts.extend(models.right.forward(&p.right)?.vertices);
    Ok(pts)
}

/// `hands` with [`MeshNoise`] applied to each hand (same camera).
fn noisy_hands(hands: &TwoHandScene, noise: &MeshNoise, rng: &mut SplitMix64) -> TwoHandScene {
    let cam = hands.camera;
    let perturb = |p: &HandParams, rng: &mut SplitMix64| {
        let mut q = p.clone();
        let jitter = |values: &[f64], rng: &mut SplitMix64| -> Vec<f64> {
            values
                .iter()
                .map(|x| x + noise.pose_std * rng.normal())
                .collect()
        };
        q.pose = match &p.pose {
            HandPose::Pca(v) => HandPose::Pca(jitter(v, rng)),
            HandPose::AxisAngle(v) => HandPose::AxisAngle(jitter(v, rng)),
            HandPose::MeanRelativeAxisAngle(v) => HandPose::MeanRelativeAxisAngle(jitter(v, rng)),
        };
        let turn = DVec3::new(rng.normal(), rng.normal(), rng.normal()) * (0.5 * noise.pose_std);
        q.root_rotation = rodrigues(turn) * p.root_rotation;
        for b in &mut q.betas {
            *b += noise.shape_std * rng.normal();
        }
        // A shift of `translation_px` pixels parallel to the image plane at the hand's depth.
        let wrist_cam = cam.world_to_camera(p.trans);
        let depth = wrist_cam.z.max(0.05);
        let f = cam.focal();
        let shift_cam = DVec3::new(
            noise.translation_px * rng.normal() * depth / f.x,
            noise.translation_px * rng.normal() * depth / f.y,
            0.0,
        );
        q.trans = p.trans + cam.rotation.transpose() * shift_cam;
        q
    };
    TwoHandScene {
        left: hands.left.as_ref().map(|p| perturb(p, rng)),
        right: hands.right.as_ref().map(|p| perturb(p, rng)),
        camera: cam,
        frame: hands.frame.clone(),
    }
}

#[cfg(test)]
mod tests;
