//! A trained run read back from its folder, whichever kind it is: a synthetic run (its scene
//! is in the folder) or a real one (`input.json`; the hand models are read again from where
//! the run recorded them). What `bitt render-avatar` and `bitt export` start from: no networks
//! are needed, only the fine textures, the light, the hands and their models.

use std::path::Path;

use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene, procedural_pair};
use bitt_outputs::export::XrConvention;
use bitt_render::scene::{LightValues, Material};
use bitt_stdx::write_atomically;
use burn::tensor::Device;

use crate::BittError;
use crate::assets::HandAssets;
use crate::avatar_export::{AvatarFiles, ExportKind, XrAvatar, XrFrame, XrVertexError};
use crate::evaluate::move_light;
use crate::real::{RealAvatar, RealInput, render_textures};
use crate::run::SavedAvatar;

/// A saved avatar of either kind of run.
#[derive(Debug, Clone)]
pub enum SavedRun {
    /// A synthetic run (`scene/` in the folder).
    Synthetic(Box<SavedAvatar>),
    /// A real run, with the assets (models, layouts) it was trained with.
    Real(Box<RealAvatar>, Box<HandAssets>),
}

/// How `bitt render-avatar` sees the avatar.
#[derive(Debug, Clone)]
pub struct AvatarView {
    /// The pose and its camera (the training pose, a novel pose, another one).
    pub pose: TwoHandScene,
    /// Whether `pose` is in the training camera's world (the training pose and the scene's
    /// novel poses), where the estimated light stays where it is; otherwise it keeps its
    /// place relative to the camera, as estimated in the training view.
    pub same_world: bool,
    /// The camera orbited about the hands: azimuth and elevation in degrees.
    pub orbit_deg: [f64; 2],
    /// Side of the square image (default: the camera's); the intrinsics are scaled.
    pub size: Option<u32>,
    /// The light (camera frame of the rendered view) instead of the estimated one.
    pub light: Option<LightValues>,
}

/// `camera` with its intrinsics scaled to a `size x size` image (`--size`).
///
/// # Errors
/// A size outside 8..=4096, or a camera that is not square.
pub fn resized(camera: &PinholeCamera, size: u32) -> Result<PinholeCamera, BittError> {
    if !(8..=4096).contains(&size) {
        return Err(BittError::Invalid(format!(
            "--size must be between 8 and 4096 (got {size})"
        )));
    }
    if camera.width != camera.height {
        return Err(BittError::Invalid(format!(
            "--size needs a square camera (got {}x{})",
            camera.width, camera.height
        )));
    }
    let s = f64::from(size) / f64::from(camera.width);
    let mut k = camera.intrinsics * s;
    k.z_axis.z = 1.0;
    Ok(PinholeCamera::new(
        k,
        camera.rotation,
        camera.translation,
        size,
        size,
    )?)
}

impl SavedRun {
    /// Reads the run folder `dir`.
    ///
    /// # Errors
    /// A file of the run that is missing or corrupt (named), or hand models that cannot be
    /// read again.
    pub fn load(dir: &Path) -> Result<Self, BittError> {
        let context = |e: BittError| {
            BittError::Invalid(format!(
                "{}: not a complete and intact train-scene run: {e}",
                dir.display()
            ))
        };
        if let Some(missing) = crate::run_folder::missing_input(dir) {
            return Err(BittError::Invalid(format!(
                "{}: not a complete and intact train-scene run: {missing}",
                dir.display()
            )));
        }
        Ok(if RealInput::is_real_run(dir) {
            let avatar = RealAvatar::load(dir).map_err(context)?;
            let assets = avatar.assets().map_err(|e| {
                BittError::Invalid(format!(
                    "{}: the hand models the run was trained with: {e}",
                    dir.display()
                ))
            })?;
            SavedRun::Real(Box::new(avatar), Box::new(assets))
        } else {
            SavedRun::Synthetic(Box::new(SavedAvatar::load(dir).map_err(context)?))
        })
    }

    /// The hand models.
    pub fn models(&self) -> HandPair {
        match self {
            SavedRun::Synthetic(_) => procedural_pair(),
            SavedRun::Real(_, assets) => assets.models.clone(),
        }
    }

    /// The assets (models and texture layouts) the run was trained with.
    ///
    /// # Errors
    /// As [`HandAssets::new`].
    pub fn assets(&self) -> Result<HandAssets, BittError> {
        match self {
            SavedRun::Synthetic(a) => Ok(HandAssets::new(
                procedural_pair(),
                a.config.texture.resolution,
            )?),
            SavedRun::Real(_, assets) => Ok((**assets).clone()),
        }
    }

    /// The side of the run's square images.
    pub fn image_size(&self) -> usize {
        match self {
            SavedRun::Synthetic(a) => a.config.nets.image_size,
            SavedRun::Real(a, _) => a.config.nets.image_size,
        }
    }

    /// The training pose with the training camera.
    pub fn training(&self) -> TwoHandScene {
        match self {
            SavedRun::Synthetic(a) => TwoHandScene {
                camera: a.camera,
                ..a.scene.given.clone()
            },
            SavedRun::Real(a, _) => a.input.train.hands.clone(),
        }
    }

    /// The training camera.
    pub fn camera(&self) -> PinholeCamera {
        match self {
            SavedRun::Synthetic(a) => a.camera,
            SavedRun::Real(a, _) => a.camera(),
        }
    }

    /// The estimated light, in the training camera's frame.
    pub fn light(&self) -> LightValues {
        match self {
            SavedRun::Synthetic(a) => a.light,
            SavedRun::Real(a, _) => a.light,
        }
    }

    /// Fine textures `[3, T]`, left then right.
    pub fn fine(&self) -> &[Vec<f32>; 2] {
        match self {
            SavedRun::Synthetic(a) => &a.fine,
            SavedRun::Real(a, _) => &a.fine,
        }
    }

    /// How many novel poses the run's scene has.
    pub fn num_novel_poses(&self) -> usize {
        match self {
            SavedRun::Synthetic(a) => a.scene.novel_poses.len(),
            SavedRun::Real(a, _) => a.input.novel_poses.len(),
        }
    }

    /// Novel pose `k` of the run's scene; synthetic novel poses are seen from the training
    /// camera, real ones (InterHand2.6M) from their own camera.
    ///
    /// # Errors
    /// [`BittError::Invalid`] when the run has no novel pose `k`.
    pub fn novel_pose(&self, k: usize) -> Result<TwoHandScene, BittError> {
        match self {
            SavedRun::Synthetic(a) => a.view(Some(k), 0.0, 0.0),
            SavedRun::Real(a, _) => {
                let poses = &a.input.novel_poses;
                if poses.is_empty() {
                    return Err(BittError::Invalid(format!(
                        "novel pose {k}: this run was trained from a single annotation and has \
                         no novel poses"
                    )));
                }
                let p = poses.get(k).ok_or_else(|| {
                    BittError::Invalid(format!(
                        "novel pose {k}: the run has {} novel poses",
                        poses.len()
                    ))
                })?;
                Ok(p.hands.clone())
            }
        }
    }

    /// Every novel pose of the run's scene (the avatar's clip).
    ///
    /// # Errors
    /// As [`Self::novel_pose`].
    pub fn novel_poses(&self) -> Result<Vec<TwoHandScene>, BittError> {
        (0..self.num_novel_poses())
            .map(|k| self.novel_pose(k))
            .collect()
    }

    /// A named pose of the synthetic generator with the avatar's hand shapes, seen from the
    /// front and above by a camera of the run's image size.
    ///
    /// # Errors
    /// As [`crate::real::procedural_pose`].
    pub fn procedural_pose(
        &self,
        family: bitt_synth::PoseFamily,
        seed: u64,
    ) -> Result<TwoHandScene, BittError> {
        let training = self.training();
        let betas = |side: Side| {
            training
                .hand(side)
                .map(|h| h.betas.clone())
                .unwrap_or_else(|| vec![0.0; bitt_mesh::model::NUM_BETAS])
        };
        let (l, r) = (betas(Side::Left), betas(Side::Right));
        crate::real::procedural_pose(&self.models(), family, [&l, &r], seed, self.image_size())
    }

    /// Renders the avatar in `view` (`bitt render-avatar`): its pose and camera, resized and
    /// orbited, under the given light or the estimated one ([`AvatarView`]); `[3, H, W]` on
    /// the host, and the camera it was seen through.
    ///
    /// # Errors
    /// A size out of range or a camera that is not square, hands that cannot be posed or
    /// rendered.
    pub fn render_view(
        &self,
        view: &AvatarView,
        device: &Device,
    ) -> Result<(Vec<f32>, PinholeCamera), BittError> {
        let (base, hands) = self.view_hands(view)?;
        let light = match view.light {
            Some(l) => l,
            None if view.same_world => move_light(&self.light(), &self.camera(), &hands.camera),
            // The estimated light, placed relative to the base camera as it was relative to
            // the training camera, then kept in the world while the view orbits.
            None => move_light(&self.light(), &base.camera, &hands.camera),
        };
        Ok((self.render(&hands, &light, device)?, hands.camera))
    }

    /// The base pose of `view` (resized) and its hands seen from the orbited camera.
    fn view_hands(&self, view: &AvatarView) -> Result<(TwoHandScene, TwoHandScene), BittError> {
        let mut base = view.pose.clone();
        if let Some(n) = view.size {
            base.camera = resized(&base.camera, n)?;
        }
        let [yaw, pitch] = view.orbit_deg.map(f64::to_radians);
        let hands = crate::real::orbit_hands(&base, &self.models(), yaw, pitch)?;
        Ok((base, hands))
    }

    /// Each hand's silhouette in `view` (`render-avatar --masks`), as an image `[3, H, W]`:
    /// the left hand red `(1, 0, 0)`, the right hand green `(0, 1, 0)` where it is in front,
    /// black elsewhere; and the camera.
    ///
    /// # Errors
    /// As [`Self::render_view`].
    pub fn render_view_masks(
        &self,
        view: &AvatarView,
        device: &Device,
    ) -> Result<(Vec<f32>, PinholeCamera), BittError> {
        let (_, hands) = self.view_hands(view)?;
        let [left, right] = crate::real::silhouettes(&self.assets()?, &hands, device)?;
        let mut image = vec![0.0f32; 3 * left.len()];
        image[..left.len()].copy_from_slice(&left);
        image[left.len()..2 * left.len()].copy_from_slice(&right);
        Ok((image, hands.camera))
    }

    /// Renders the avatar's hands posed as `hands` (its camera included) under `light`;
    /// `[3, H, W]` on the host.
    ///
    /// # Errors
    /// Hands that cannot be posed or rendered.
    pub fn render(
        &self,
        hands: &TwoHandScene,
        light: &LightValues,
        device: &Device,
    ) -> Result<Vec<f32>, BittError> {
        match self {
            SavedRun::Synthetic(a) => a.render(hands, Some(light), device),
            SavedRun::Real(a, assets) => render_textures(
                assets,
                &a.fine,
                hands,
                light,
                a.config.loss.photo_occlusion,
                device,
            ),
        }
    }

    /// Writes the avatar of a trained run to `out` again, without retraining: standing in the
    /// training pose with the clip of the scene's novel poses (`hands` `None`), or in `hands`
    /// (another annotation's or a generated pose; no clip, since its world is another one).
    ///
    /// # Errors
    /// A run whose textures do not fit its layout, hands that cannot be posed, or an unwritable
    /// `out` (nothing is left half-written).
    pub fn export(
        &self,
        hands: Option<&TwoHandScene>,
        kind: ExportKind,
        out: &Path,
    ) -> Result<(), BittError> {
        let (assets, images) = self.texture_images()?;
        let training = self.training();
        let clip = match hands {
            None => self.novel_poses()?,
            Some(_) => Vec::new(),
        };
        let files = AvatarFiles {
            models: &assets.models,
            hands: hands.unwrap_or(&training),
            textures: [&images[0], &images[1]],
            material: Material::default(),
            clip,
        };
        match kind {
            ExportKind::Rigged | ExportKind::Static => {
                // A file the user named that is not a glTF binary is not replaced.
                bitt_stdx::check_replaceable(out, b"glTF", "glTF binary (.glb)")?;
                let bytes = if kind == ExportKind::Rigged {
                    files.rigged_glb()?
                } else {
                    files.static_glb()?
                };
                write_atomically(out, &bytes)?
            }
            ExportKind::Obj => files.write_obj(out)?,
        }
        Ok(())
    }

    /// The run's assets and its fine textures as images (left, right).
    fn texture_images(&self) -> Result<(HandAssets, Vec<image::RgbImage>), BittError> {
        let assets = self.assets()?;
        let layout = &assets.layouts[0];
        let s = assets.texture_size;
        let mut images = Vec::new();
        for fine in self.fine() {
            let values = crate::outputs::texture_image(layout, fine)?;
            images.push(crate::outputs::rgb_image(&values, s, s)?);
        }
        Ok((assets, images))
    }

    /// Writes the avatar as two hands for a hand-tracking runtime into the folder `out`
    /// (`bitt export --xr`; [`XrAvatar`]): played in the training pose and the scene's novel
    /// poses, each from the camera `render-avatar` shows it from. Returns the vertex error of
    /// the files driven by tracked joint poses against the forward pass.
    ///
    /// # Errors
    /// A run whose textures do not fit its layout, hands that cannot be posed, `out` a file or
    /// a folder that is not an earlier XR export (untouched), a write failure (nothing is
    /// left half-written).
    pub fn export_xr(
        &self,
        convention: XrConvention,
        out: &Path,
    ) -> Result<XrVertexError, BittError> {
        let (assets, images) = self.texture_images()?;
        let training = self.training();
        let mut frames = vec![XrFrame {
            name: "training pose".into(),
            novel_pose: None,
            hands: training.clone(),
        }];
        for k in 0..self.num_novel_poses() {
            frames.push(XrFrame {
                name: format!("novel pose {k}"),
                novel_pose: Some(k),
                hands: self.novel_pose(k)?,
            });
        }
        Ok(XrAvatar {
            convention,
            models: &assets.models,
            hands: &training,
            textures: [&images[0], &images[1]],
            material: Material::default(),
            frames,
        }
        .write(out)?)
    }
}
