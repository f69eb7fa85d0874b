//! The record a real run keeps to be resumed: `input.json` and `input/images.safetensors`.

use bitt_stdx::FileErrorExt;
use std::path::{Path, PathBuf};

use bitt_mesh::{PinholeCamera, TwoHandScene};
use bitt_stdx::st;
use burn::tensor::Device;

use super::{HandSource, PriorSource, RealScene, RealView, load_models, real_trainer};
use crate::BittError;
use crate::config::TrainConfig;
use crate::trainer::Trainer;

/// Names of a real run's input files.
pub mod files {
    /// The [`super::RealInput`] record.
    pub(crate) const INPUT: &str = "input.json";
    /// Folder of the prepared input images.
    pub(crate) const INPUT_DIR: &str = "input";
    /// The exact prepared images, `f32` `[3, S, S]`, one tensor per view name (`train`,
    /// `view_00`, ..., `pose_00`, ...).
    pub(crate) const IMAGES: &str = "input/images.safetensors";
}

/// Format tag of `input.json`.
pub const INPUT_FORMAT: &str = "bitt-real-input/1";

/// Where a real run's images came from.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum RealSource {
    /// An image and a BiTT annotation pickle.
    Annotation {
        /// The image.
        image: PathBuf,
        /// The annotation pickle.
        annotation: PathBuf,
    },
    /// An image and its 2D hand keypoints, the hands fitted to them (`bitt fit-hands`).
    Keypoints {
        /// The image.
        image: PathBuf,
        /// The keypoint file.
        keypoints: PathBuf,
        /// Whether the image was un-mirrored before the fit.
        #[serde(default)]
        mirrored: bool,
    },
    /// A photo alone: its hands were found by the built-in detector and fitted to its
    /// keypoints (the run folder keeps the detection: `detection.json`, `keypoints.json`,
    /// `detection_overlay.png`).
    Detected {
        /// The photo.
        image: PathBuf,
    },
    /// A scene of InterHand2.6M.
    InterHand {
        /// Dataset root.
        root: PathBuf,
        /// Split.
        split: String,
        /// Capture id.
        capture: i64,
        /// Training frame index.
        frame: i64,
        /// Training camera name.
        camera: String,
    },
}

/// A view as `input.json` records it (no pixels).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ViewRecord {
    /// The view's name.
    pub name: String,
    /// The original image file.
    pub source: PathBuf,
    /// Both hands with the camera fitted to the preset's size.
    pub hands: TwoHandScene,
}

impl From<&RealView> for ViewRecord {
    fn from(v: &RealView) -> Self {
        ViewRecord {
            name: v.name.clone(),
            source: v.source.clone(),
            hands: v.hands.clone(),
        }
    }
}

/// Everything a real run needs besides its configuration and the training image (saved as
/// `input.json`; see the [module docs](super)).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RealInput {
    /// [`INPUT_FORMAT`].
    pub format: String,
    /// Where the images came from.
    pub source: RealSource,
    /// The hand models.
    pub hands: HandSource,
    /// The texture prior.
    pub prior: PriorSource,
    /// The training view.
    pub train: ViewRecord,
    /// Novel views (InterHand2.6M scenes).
    #[serde(default)]
    pub novel_views: Vec<ViewRecord>,
    /// Novel poses (InterHand2.6M scenes).
    #[serde(default)]
    pub novel_poses: Vec<ViewRecord>,
}

impl RealInput {
    /// Whether `dir` holds a real run (an `input.json`).
    pub(crate) fn is_real_run(dir: &Path) -> bool {
        dir.join(files::INPUT).is_file()
    }

    /// Writes `input.json`, the exact training image and PNGs of every view into `dir`.
    pub fn write(&self, dir: &Path, scene: &RealScene) -> Result<(), BittError> {
        let input_dir = dir.join(files::INPUT_DIR);
        std::fs::create_dir_all(&input_dir).map_err(|e| BittError::io(&input_dir, e))?;
        let s = scene.train.hands.camera.width as usize;
        let views: Vec<&RealView> = std::iter::once(&scene.train)
            .chain(&scene.novel_views)
            .chain(&scene.novel_poses)
            .collect();
        write_image_safetensors(&dir.join(files::IMAGES), &views, s)?;
        for v in &views {
            crate::outputs::write_png(&input_dir.join(format!("{}.png", v.name)), &v.image, s, s)?;
        }
        Ok(crate::outputs::write_json(&dir.join(files::INPUT), self)?)
    }

    /// The prepared views of a real run in `dir` (exact images from `input/images.safetensors`).
    pub(crate) fn read_scene(&self, dir: &Path, size: usize) -> Result<RealScene, BittError> {
        let path = dir.join(files::IMAGES);
        let bytes = std::fs::read(&path).map_err(|e| BittError::io(&path, e))?;
        let view = |r: &ViewRecord| -> Result<RealView, BittError> {
            Ok(RealView {
                name: r.name.clone(),
                source: r.source.clone(),
                image: read_image_tensor(&bytes, &path, &r.name, size)?,
                hands: r.hands.clone(),
            })
        };
        Ok(RealScene {
            train: view(&self.train)?,
            novel_views: self
                .novel_views
                .iter()
                .map(view)
                .collect::<Result<_, _>>()?,
            novel_poses: self
                .novel_poses
                .iter()
                .map(view)
                .collect::<Result<_, _>>()?,
        })
    }

    /// Reads `input.json` of a real run, with the exact hand and camera values stored in
    /// `input/images.safetensors`.
    pub fn read(dir: &Path) -> Result<Self, BittError> {
        let path = dir.join(files::INPUT);
        let text = std::fs::read_to_string(&path).map_err(|e| BittError::io(&path, e))?;
        let input: RealInput = serde_json::from_str(&text)
            .map_err(|e| BittError::format(&path, format!("not a real-run input record: {e}")))?;
        if input.format != INPUT_FORMAT {
            return Err(BittError::format(
                &path,
                format!("format `{}`, expected `{INPUT_FORMAT}`", input.format),
            ));
        }
        let mut input = input;
        let path = dir.join(files::IMAGES);
        let bytes = st::read_file(&path)?;
        let r = st::Reader::open(&bytes, &path)?;
        for view in std::iter::once(&mut input.train)
            .chain(&mut input.novel_views)
            .chain(&mut input.novel_poses)
        {
            restore_exact_floats(&r, &view.name, &mut view.hands)?;
        }
        Ok(input)
    }

    /// Rebuilds the trainer of a real run in `dir` (its `config.json`, `input.json` and exact
    /// training image; the MANO / HTML folders must still be where `input.json` says). The
    /// caller restores the checkpoint.
    pub fn resume_trainer(
        dir: &Path,
        config: TrainConfig,
        cache: Option<&Path>,
        device: &Device,
    ) -> Result<(RealInput, RealScene, Trainer), BittError> {
        let input = Self::read(dir)?;
        let scene = input.read_scene(dir, config.nets.image_size)?;
        let models = load_models(&input.hands, &input.prior)?;
        let trainer = real_trainer(
            &scene.train.image,
            &scene.train.hands,
            models,
            &input.prior,
            config,
            cache,
            device,
        )?;
        Ok((input, scene, trainer))
    }
}

/// Every float of a scene (hand parameters, camera), in a fixed order: `input.json` is for
/// reading, these are stored exactly beside the images (JSON parsing may round the last bit,
/// and an exact resume needs the same geometry).
fn float_slots(scene: &mut TwoHandScene) -> Vec<&mut f64> {
    let TwoHandScene {
        left,
        right,
        camera,
        ..
    } = scene;
    let mut out: Vec<&mut f64> = Vec::new();
    fn mat(m: &mut bitt_mesh::glam::DMat3) -> [&mut f64; 9] {
        let bitt_mesh::glam::DMat3 {
            x_axis,
            y_axis,
            z_axis,
        } = m;
        [
            &mut x_axis.x,
            &mut x_axis.y,
            &mut x_axis.z,
            &mut y_axis.x,
            &mut y_axis.y,
            &mut y_axis.z,
            &mut z_axis.x,
            &mut z_axis.y,
            &mut z_axis.z,
        ]
    }
    for hand in [left.as_mut(), right.as_mut()].into_iter().flatten() {
        let bitt_mesh::HandParams {
            root_rotation,
            pose,
            betas,
            trans,
        } = hand;
        out.extend(mat(root_rotation));
        match pose {
            bitt_mesh::HandPose::Pca(v)
            | bitt_mesh::HandPose::AxisAngle(v)
            | bitt_mesh::HandPose::MeanRelativeAxisAngle(v) => out.extend(v.iter_mut()),
        }
        out.extend(betas.iter_mut());
        out.extend([&mut trans.x, &mut trans.y, &mut trans.z]);
    }
    let PinholeCamera {
        intrinsics,
        rotation,
        translation,
        ..
    } = camera;
    out.extend(mat(intrinsics));
    out.extend(mat(rotation));
    out.extend([&mut translation.x, &mut translation.y, &mut translation.z]);
    out
}

fn write_image_safetensors(path: &Path, views: &[&RealView], size: usize) -> Result<(), BittError> {
    let mut entries: Vec<st::Entry> = Vec::new();
    for v in views {
        entries.push(st::unit_entry(
            v.name.clone(),
            vec![3, size, size],
            &v.image,
        ));
        let mut hands = v.hands.clone();
        let floats = st::f64_bytes(float_slots(&mut hands).into_iter().map(|x| *x));
        entries.push((
            format!("hands.{}", v.name),
            safetensors::Dtype::F64,
            vec![floats.len() / 8],
            floats,
        ));
    }
    let meta = std::collections::HashMap::from([(
        "format".to_string(),
        "bitt-real-input-images: per view, `NAME` [3, S, S] in [0, 1] (f32, or u8 holding \
         255 * value where that is exact) and `hands.NAME` \
         the exact f64 values of input.json's hands and camera"
            .to_string(),
    )]);
    Ok(st::write(path, &entries, meta)?)
}

/// Puts the exact floats stored for view `name` into `hands`.
fn restore_exact_floats(
    r: &st::Reader<'_>,
    name: &str,
    hands: &mut TwoHandScene,
) -> Result<(), BittError> {
    let key = format!("hands.{name}");
    let slots = float_slots(hands);
    let (_, values) = r.values::<f64>(&key, &[Some(slots.len())])?;
    if values.iter().any(|x| !x.is_finite()) {
        return Err(r.err(format!("`{key}` holds non-finite values")).into());
    }
    for (slot, v) in slots.into_iter().zip(values) {
        *slot = v;
    }
    Ok(())
}

fn read_image_tensor(
    bytes: &[u8],
    path: &Path,
    name: &str,
    size: usize,
) -> Result<Vec<f32>, BittError> {
    let r = st::Reader::open(bytes, path)?;
    let (_, v) = r.unit_f32s(name, Some(&[Some(3), Some(size), Some(size)]))?;
    Ok(v)
}
