//! Real data: an image with its annotation (the BiTT demo `NN.jpg` + `NN.pkl`), or a scene
//! selected from InterHand2.6M, turned into a [`Trainer`]; the record a real run keeps to be
//! resumed and re-rendered; and the poses a saved avatar can be rendered in.
//!
//! # Inputs
//!
//! - Hands: the user's MANO models ([`HandSource::Mano`]) or the procedural hands
//!   ([`HandSource::Procedural`], in MANO's frame, so InterHand parameters pose them
//!   plausibly; no licensed file needed).
//! - Texture prior: HTML ([`PriorSource::Html`]: `html.safetensors` from `bitt convert-html`,
//!   or `model_wosr/model.pkl` / `model.pkl`, with `uvs_right.pkl` / `uvs.pkl` and optionally
//!   `uvs_left.pkl`) or the procedural PCA fitted from `config.texture`
//!   ([`PriorSource::Procedural`]). HTML's UV layout is defined on MANO's faces, so HTML needs
//!   MANO hands, and MANO hands (which carry no UV layout) need HTML.
//!
//! # The texture layout with HTML
//!
//! The trainer's layout is always [`HandAssets`]' one: the hands' UV triangles rasterized at
//! `config.texture.resolution` with a [`crate::assets::TEXTURE_GUTTER`]-texel gutter. HTML's
//! mean and basis (1024 x 1024, its own texel set) are resampled onto that layout by
//! [`resample_pca`]: each texel averages HTML's texels under its footprint (bilinear taps over
//! the texel's area; the nearest HTML texel when none is under it). Resampling is linear, so
//! the result is again a PCA model (`mean' + basis' a` is the resampled `mean + basis a`).
//!
//! # Components
//!
//! HTML has 101 components; a preset's HTML network predicts `config.nets.html.
//! coefficients_per_hand` (8 at `tiny`, 24 at `quick`). When the prior's count differs, the
//! network is built for the prior's count ([`adapt_config_to_prior`]): `coefficients_per_hand`
//! and `texture.components` become the prior's `K` (and `texture.identities` is raised to at
//! least `(K + 1) / 2` so the configuration still validates; the procedural fit settings are
//! not used by an HTML run). The saved `config.json` holds the adapted values.
//!
//! # Crop
//!
//! Every view is cropped around both hands as the reference's data preparation does
//! (`cut_img` with `HAND_BBOX_RATIO = 0.8`: a square of side `max(box w, box h) / 0.8` centred
//! on the projected vertices' box; pixels outside the image are black) and resized to the
//! preset's size by [`ImageInput::fit_square`], which adjusts the intrinsics.
//!
//! # What a real run keeps (`input.json`, `input/`)
//!
//! `input.json` ([`RealInput`]) records where the input came from (image and annotation
//! paths, or the InterHand2.6M root, split, capture, frame and camera), the hand and prior
//! sources (paths of the user's MANO / HTML folders; licensed files are never copied), and
//! the hands of the training view (and of the novel views and poses) with their cameras
//! already fitted to the preset's size. `input/images.safetensors` holds the exact `f32`
//! images the trainer saw (and the novel views' and poses' ones) and the exact `f64` values
//! of those hands and cameras (JSON parsing may change a last bit), so `--resume` rebuilds
//! the same trainer even when the original image and annotation have moved or changed; PNG
//! copies of every view are in `input/` to look at.

use std::path::{Path, PathBuf};

use bitt_mesh::glam::DVec3;
use bitt_mesh::interhand::{InterHandScene, InterHandView};
use bitt_mesh::{HandPair, PinholeCamera, Side, TwoHandScene, UvLayout, procedural_pair};
use bitt_render::scene::{LightValues, RenderSettings};
use bitt_synth::PoseFamily;
use bitt_texture::layout::{texel_uv, uv_to_texel};
use bitt_texture::{TextureLayout, TexturePca, load_html_model, load_html_uvs, load_image};
use burn::tensor::{Device, Tensor, TensorData};

use crate::BittError;
use crate::assets::{HandAssets, ViewGeometry};
use crate::config::TrainConfig;
use crate::input::{ImageInput, fit_camera};
use crate::refine::{MeshRefine, Refinement, refine_view};
use crate::trainer::{Trainer, read};

/// The reference's `HAND_BBOX_RATIO`: the hands' box fills this fraction of the crop's side.
pub const REFERENCE_HAND_BOX_RATIO: f64 = 0.8;

/// Side of the square crops the BiTT annotation pickles' intrinsics refer to.
pub use bitt_mesh::annotation::BITT_CROP_SIZE;

/// Names of a real run's input files.
pub mod files {
    /// The [`super::RealInput`] record.
    pub const INPUT: &str = "input.json";
    /// Folder of the prepared input images.
    pub const INPUT_DIR: &str = "input";
    /// The exact prepared images, `f32` `[3, S, S]`, one tensor per view name (`train`,
    /// `view_00`, ..., `pose_00`, ...).
    pub const IMAGES: &str = "input/images.safetensors";
}

/// Format tag of `input.json`.
pub const INPUT_FORMAT: &str = "bitt-real-input/1";

/// Where the hand models come from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HandSource {
    /// The project's procedural hands.
    Procedural,
    /// A folder with `MANO_LEFT` / `MANO_RIGHT` (`.pkl` or `.safetensors`).
    Mano {
        /// The folder (absolute when recorded).
        dir: PathBuf,
    },
}

/// Where the texture prior comes from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PriorSource {
    /// The procedural PCA of `config.texture`.
    Procedural,
    /// An HTML folder (see the [module docs](self)).
    Html {
        /// The folder (absolute when recorded).
        dir: PathBuf,
    },
}

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

/// One prepared view: the image at the preset's size and the hands with the fitted camera.
#[derive(Debug, Clone, PartialEq)]
pub struct RealView {
    /// A short name (`train`, `view_00`, `pose_03`).
    pub name: String,
    /// The original image file.
    pub source: PathBuf,
    /// `[3, S, S]` in `[0, 1]`, channel-major.
    pub image: Vec<f32>,
    /// Both hands; the camera is the crop's (`S x S`).
    pub hands: TwoHandScene,
}

/// A prepared multi-view scene (InterHand2.6M): the training view, novel views (same frame,
/// other cameras) and novel poses (same capture, other frames).
#[derive(Debug, Clone, PartialEq)]
pub struct RealScene {
    /// The training view.
    pub train: RealView,
    /// Other cameras of the training frame.
    pub novel_views: Vec<RealView>,
    /// Other frames of the same capture.
    pub novel_poses: Vec<RealView>,
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
/// `input.json`; see the [module docs](self)).
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

// -------------------------------------------------------------------------------------------
// Hands and texture prior.

fn absolute(p: &Path) -> PathBuf {
    std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf())
}

impl HandSource {
    /// The same source with an absolute path.
    pub fn absolute(&self) -> Self {
        match self {
            HandSource::Procedural => HandSource::Procedural,
            HandSource::Mano { dir } => HandSource::Mano { dir: absolute(dir) },
        }
    }
}

impl PriorSource {
    /// The same source with an absolute path.
    pub fn absolute(&self) -> Self {
        match self {
            PriorSource::Procedural => PriorSource::Procedural,
            PriorSource::Html { dir } => PriorSource::Html { dir: absolute(dir) },
        }
    }
}

/// Checks that hands and prior go together (HTML needs MANO's faces; MANO needs HTML's UVs).
pub fn check_sources(hands: &HandSource, prior: &PriorSource) -> Result<(), BittError> {
    match (hands, prior) {
        (HandSource::Procedural, PriorSource::Html { dir }) => Err(BittError::Invalid(format!(
            "the HTML texture model ({}) is defined on MANO's UV layout; use it with MANO hands \
             (a MANO folder), or drop it to use the procedural hands with the procedural prior",
            dir.display()
        ))),
        (HandSource::Mano { dir }, PriorSource::Procedural) => Err(BittError::Invalid(format!(
            "MANO hands ({}) have no UV layout of their own; give the HTML folder (uvs.pkl and \
             model_wosr/model.pkl or html.safetensors) as the texture prior",
            dir.display()
        ))),
        _ => Ok(()),
    }
}

/// HTML's native model file in `dir`: `html.safetensors`, `model_wosr/model.pkl` or
/// `model.pkl`.
fn html_model_path(dir: &Path) -> Result<PathBuf, BittError> {
    let candidates = [
        dir.join(bitt_texture::html::HTML_SAFETENSORS),
        dir.join("model_wosr").join("model.pkl"),
        dir.join("model.pkl"),
    ];
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| {
            BittError::Invalid(format!(
                "{}: no HTML texture model (looked for {})",
                dir.display(),
                candidates
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

/// Loads HTML's native model (1024 x 1024 texels, 101 components, scale 1/255).
pub fn load_html_prior(dir: &Path) -> Result<TexturePca, BittError> {
    let path = html_model_path(dir)?;
    Ok(
        if path.extension().and_then(|e| e.to_str()) == Some("safetensors") {
            TexturePca::load_safetensors(&path)?
        } else {
            load_html_model(&path)?
        },
    )
}

/// The left hand's UV faces from the right hand's: corner `k` of left face `f` gets the UV of
/// the right face's corner on the same vertex (the meshes share vertex indices; only the
/// winding differs).
pub fn left_uv_from_right(
    right_uv: &UvLayout,
    right_faces: &[[u32; 3]],
    left_faces: &[[u32; 3]],
) -> Result<UvLayout, BittError> {
    if right_faces.len() != left_faces.len() || right_uv.faces.len() != right_faces.len() {
        return Err(BittError::Invalid(format!(
            "cannot derive the left hand's UV faces: {} right faces, {} left faces, {} UV faces",
            right_faces.len(),
            left_faces.len(),
            right_uv.faces.len()
        )));
    }
    let mut faces = Vec::with_capacity(left_faces.len());
    for (f, (l, r)) in left_faces.iter().zip(right_faces).enumerate() {
        let mut uv = [0u32; 3];
        for k in 0..3 {
            let j = r.iter().position(|&v| v == l[k]).ok_or_else(|| {
                BittError::Invalid(format!(
                    "cannot derive the left hand's UV faces: face {f} uses vertices {l:?} on \
                     the left and {r:?} on the right (give uvs_left.pkl)"
                ))
            })?;
            uv[k] = right_uv.faces[f][j];
        }
        faces.push(uv);
    }
    Ok(UvLayout {
        uvs: right_uv.uvs.clone(),
        faces,
    })
}

/// Puts HTML's UV layouts on both hands: `uvs_right.pkl` or `uvs.pkl` (else the layout stored
/// in `html.safetensors`) for the right hand, `uvs_left.pkl` or [`left_uv_from_right`] for
/// the left.
pub fn attach_html_uvs(models: &mut HandPair, dir: &Path) -> Result<(), BittError> {
    let right_file = ["uvs_right.pkl", "uvs.pkl"]
        .iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file());
    let right = match right_file {
        Some(p) => load_html_uvs(&p)?,
        None => {
            let st = dir.join(bitt_texture::html::HTML_SAFETENSORS);
            let stored = if st.is_file() {
                TexturePca::load_safetensors(&st)?.layout.uv
            } else {
                None
            };
            stored.ok_or_else(|| {
                BittError::Invalid(format!(
                    "{}: no HTML UV layout (uvs_right.pkl, uvs.pkl, or html.safetensors with \
                     a stored layout)",
                    dir.display()
                ))
            })?
        }
    };
    let left = match dir.join("uvs_left.pkl") {
        p if p.is_file() => load_html_uvs(&p)?,
        _ => left_uv_from_right(&right, &models.right.faces, &models.left.faces)?,
    };
    for (side, uv) in [(Side::Left, left), (Side::Right, right)] {
        let model = match side {
            Side::Left => &mut models.left,
            Side::Right => &mut models.right,
        };
        if uv.faces.len() != model.faces.len() {
            return Err(BittError::Invalid(format!(
                "{}: the HTML UV layout has {} faces but the {side} hand mesh ({}) has {}",
                dir.display(),
                uv.faces.len(),
                model.source,
                model.faces.len()
            )));
        }
        model.uv = Some(uv);
    }
    Ok(())
}

/// The hand models of `hands`, with HTML's UV layouts attached when `prior` is HTML.
pub fn load_models(hands: &HandSource, prior: &PriorSource) -> Result<HandPair, BittError> {
    check_sources(hands, prior)?;
    let mut models = match hands {
        HandSource::Procedural => procedural_pair(),
        HandSource::Mano { dir } => bitt_mesh::load_model_dir(dir)?,
    };
    if let PriorSource::Html { dir } = prior {
        attach_html_uvs(&mut models, dir)?;
    }
    Ok(models)
}

/// Resamples a texture PCA onto another layout (see the [module docs](self)): each target
/// texel averages the source texels under its footprint in UV space.
pub fn resample_pca(src: &TexturePca, target: &TextureLayout) -> Result<TexturePca, BittError> {
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
                BittError::Invalid(format!(
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
    Ok(TexturePca::new(target.clone(), mean, basis, k, src.scale)?)
}

/// Builds the HTML network for the prior's component count (see the [module docs](self)).
pub fn adapt_config_to_prior(config: &mut TrainConfig, components: usize) -> Result<(), BittError> {
    config.nets.html.coefficients_per_hand = components;
    config.texture.components = components;
    config.texture.identities = config.texture.identities.max(components.div_ceil(2) + 1);
    config.validate()
}

/// The texture prior for `assets`: HTML resampled onto the assets' layout (the configuration
/// adapted to its component count), or the procedural PCA of `config.texture` (cached in
/// `cache`).
pub fn texture_model(
    config: &mut TrainConfig,
    prior: &PriorSource,
    assets: &HandAssets,
    cache: Option<&Path>,
    device: &Device,
) -> Result<TexturePca, BittError> {
    match prior {
        PriorSource::Procedural => crate::run::texture_prior(config, cache, device),
        PriorSource::Html { dir } => {
            let html = load_html_prior(dir)?;
            let pca = resample_pca(&html, &assets.layouts[1])?;
            adapt_config_to_prior(config, pca.num_components)?;
            Ok(pca)
        }
    }
}

// -------------------------------------------------------------------------------------------
// Views.

/// The pixel box `[x0, y0, x1, y1]` of both hands' projected vertices (either hand alone when
/// only one is annotated).
pub fn hands_box(hands: &TwoHandScene, models: &HandPair) -> Result<[f64; 4], BittError> {
    let posed = hands.pose_in_camera(models)?;
    let points: Vec<DVec3> = [posed.left, posed.right]
        .into_iter()
        .flatten()
        .flat_map(|h| h.vertices)
        .collect();
    let b = hands
        .pixel_box(&points)
        .ok_or_else(|| BittError::Invalid("no hand vertex is in front of the camera".into()))?;
    Ok([b.min.x, b.min.y, b.max.x, b.max.y])
}

/// The box to give [`ImageInput::fit_square`] so that its square is the reference's crop
/// (side `max(w, h) / REFERENCE_HAND_BOX_RATIO`, same centre).
pub fn reference_crop_box(b: [f64; 4]) -> [f64; 4] {
    let grow = 1.0 / REFERENCE_HAND_BOX_RATIO / (1.0 + crate::input::CROP_MARGIN);
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let half = (b[2] - b[0]).max(b[3] - b[1]) / 2.0 * grow;
    [cx - half, cy - half, cx + half, cy + half]
}

/// The smallest fraction of each hand's projected vertices that must fall inside the
/// training image: less, and the photo shows too little of that hand to texture it (or the
/// annotation belongs to another image).
pub const MIN_HAND_INSIDE: f64 = 0.5;

/// The depths (metres along the camera's axis) every vertex of a photographed hand lies
/// between: nearer than 5 cm, or farther than 20 m, is a wrong translation, not a photo.
pub const HAND_DEPTH_RANGE_M: [f64; 2] = [0.05, 20.0];

/// Checks each hand of the training view on its own: its position finite, every vertex in
/// front of the camera within [`HAND_DEPTH_RANGE_M`], and at least [`MIN_HAND_INSIDE`] of its
/// projected vertices inside the image. Errors name `source` (the annotation), the hand and
/// the problem.
pub fn check_hand_placement(
    hands: &TwoHandScene,
    models: &HandPair,
    source: &Path,
) -> Result<(), BittError> {
    let bad = |m: String| Err(BittError::Invalid(format!("{}: {m}", source.display())));
    let posed = hands
        .pose_in_camera(models)
        .map_err(|e| BittError::Invalid(format!("{}: {e}", source.display())))?;
    let (w, h) = (
        f64::from(hands.camera.width),
        f64::from(hands.camera.height),
    );
    let [near, far] = HAND_DEPTH_RANGE_M;
    for side in Side::BOTH {
        let Some(hand) = posed.get(side) else {
            continue;
        };
        let vertices = &hand.vertices;
        if vertices.is_empty() {
            continue;
        }
        if vertices.iter().any(|v| !v.is_finite()) {
            return bad(format!(
                "the {side} hand's position is not finite (its translation is out of range)"
            ));
        }
        let (zmin, zmax) = vertices
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v.z), b.max(v.z))
            });
        if zmax <= 0.0 {
            return bad(format!(
                "the {side} hand is behind the camera (depth {zmin:.3} to {zmax:.3} m)"
            ));
        }
        if zmin <= 0.0 {
            return bad(format!(
                "the {side} hand is partly behind the camera (depth {zmin:.3} to {zmax:.3} m)"
            ));
        }
        if zmin < near || zmax > far {
            return bad(format!(
                "the {side} hand lies {zmin:.3} to {zmax:.3} m from the camera; a photographed \
                 hand lies between {near} and {far} m"
            ));
        }
        let inside = vertices
            .iter()
            .filter_map(|v| hands.camera.camera_to_pixel(*v))
            .filter(|p| p.x >= -0.5 && p.x <= w - 0.5 && p.y >= -0.5 && p.y <= h - 0.5)
            .count();
        let fraction = inside as f64 / vertices.len() as f64;
        if fraction < MIN_HAND_INSIDE {
            return bad(format!(
                "only {:.0}% of the {side} hand projects into the {w}x{h} image (at least {:.0}% \
                 must): the hand is off the image, or the image and its annotation do not belong \
                 together",
                100.0 * fraction,
                100.0 * MIN_HAND_INSIDE
            ));
        }
    }
    Ok(())
}

/// The pixel box of both hands ([`hands_box`]), refused when it lies outside the image (the
/// image at `source` and its annotation do not belong together).
pub fn hands_in_image(
    hands: &TwoHandScene,
    models: &HandPair,
    source: &Path,
) -> Result<[f64; 4], BittError> {
    let b = hands_box(hands, models)
        .map_err(|e| BittError::Invalid(format!("{}: {e}", source.display())))?;
    let (w, h) = (
        f64::from(hands.camera.width),
        f64::from(hands.camera.height),
    );
    if b[2] < 0.0 || b[3] < 0.0 || b[0] > w || b[1] > h {
        return Err(BittError::Invalid(format!(
            "{}: the hands project to [{:.0}, {:.0}] - [{:.0}, {:.0}], outside the {w}x{h} \
             image: the image and its annotation do not belong together",
            source.display(),
            b[0],
            b[1],
            b[2],
            b[3]
        )));
    }
    Ok(b)
}

/// Crops an image `[3, H, W]` (with its full camera in `hands`) around the hands as the
/// reference does and resizes it to `size`.
pub fn prepare_view(
    name: &str,
    source: &Path,
    image: Vec<f32>,
    hands: &TwoHandScene,
    models: &HandPair,
    size: usize,
) -> Result<RealView, BittError> {
    let b = hands_in_image(hands, models, source)?;
    let input = ImageInput {
        image,
        mask: None,
        camera: hands.camera,
    };
    let fitted = input.fit_square(Some(reference_crop_box(b)), size)?;
    Ok(RealView {
        name: name.to_string(),
        source: source.to_path_buf(),
        image: fitted.image,
        hands: TwoHandScene {
            camera: fitted.camera,
            ..hands.clone()
        },
    })
}

/// An [`BittError::Io`] naming `image` when it is not a file (before anything is read).
///
/// # Errors
/// The missing input image.
pub fn require_image(image: &Path) -> Result<(), BittError> {
    if image.is_file() {
        return Ok(());
    }
    Err(BittError::io(
        image,
        std::io::Error::new(std::io::ErrorKind::NotFound, "input image not found"),
    ))
}

/// Reads an image, checking its size against the camera's.
pub fn read_image(path: &Path, camera: &PinholeCamera, what: &str) -> Result<Vec<f32>, BittError> {
    let img = load_image(path)?;
    if (img.width as u32, img.height as u32) != (camera.width, camera.height) {
        return Err(BittError::Invalid(format!(
            "{}: the image is {}x{}, but {what} is for a {}x{} image",
            path.display(),
            img.width,
            img.height,
            camera.width,
            camera.height
        )));
    }
    Ok(img.data)
}

/// The training view of an image and its BiTT annotation pickle (the demo `NN.jpg` +
/// `NN.pkl`): the annotation's camera is for the reference's 256 x 256 crop, so the image
/// must be 256 x 256; it is cropped around the hands and resized to `size`.
pub fn annotation_view(
    image: &Path,
    annotation: &Path,
    models: &HandPair,
    size: usize,
) -> Result<RealView, BittError> {
    require_image(image)?;
    let hands = bitt_mesh::load_bitt_annotation(annotation, (BITT_CROP_SIZE, BITT_CROP_SIZE))?;
    for side in Side::BOTH {
        if hands.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand is not annotated; BiTT needs both hands",
                annotation.display()
            )));
        }
    }
    let what = format!(
        "the camera of {} (the reference's {BITT_CROP_SIZE}x{BITT_CROP_SIZE} crop)",
        annotation.display()
    );
    let pixels = read_image(image, &hands.camera, &what)?;
    check_hand_placement(&hands, models, annotation)?;
    prepare_view("train", image, pixels, &hands, models, size)
}

/// Loads and prepares every view of a selected InterHand2.6M scene.
pub fn interhand_views(
    scene: &InterHandScene,
    models: &HandPair,
    size: usize,
) -> Result<RealScene, BittError> {
    let prep = |name: String, v: &InterHandView| -> Result<RealView, BittError> {
        let what = format!(
            "the data file's entry for image {} ({})",
            v.entry.image_id, v.entry.file_name
        );
        let pixels = read_image(&v.image_path, &v.scene.camera, &what)?;
        prepare_view(&name, &v.image_path, pixels, &v.scene, models, size)
    };
    check_hand_placement(&scene.train.scene, models, &scene.train.image_path)?;
    Ok(RealScene {
        train: prep("train".into(), &scene.train)?,
        novel_views: scene
            .novel_views
            .iter()
            .enumerate()
            .map(|(k, v)| prep(format!("view_{k:02}"), v))
            .collect::<Result<_, _>>()?,
        novel_poses: scene
            .novel_poses
            .iter()
            .enumerate()
            .map(|(k, v)| prep(format!("pose_{k:02}"), v))
            .collect::<Result<_, _>>()?,
    })
}

// -------------------------------------------------------------------------------------------
// Trainer, run record, resume.

/// A trainer for one prepared view: hand assets of `models` at the preset's texture size, the
/// prior of `prior` on their layout (the configuration adapted to it; see the
/// [module docs](self)). `device` must be an autodiff device.
pub fn real_trainer(
    view_image: &[f32],
    hands: &TwoHandScene,
    models: HandPair,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    device: &Device,
) -> Result<Trainer, BittError> {
    let mut hands = hands.clone();
    let (trainer, _) = refined_real_trainer(
        view_image, &mut hands, models, prior, config, cache, None, device,
    )?;
    Ok(trainer)
}

/// [`real_trainer`] that first refines the view's hands against its image when `refine` is
/// given (`hands` is replaced by the refined hands, same camera), returning the refinement.
#[allow(clippy::too_many_arguments)]
pub fn refined_real_trainer(
    view_image: &[f32],
    hands: &mut TwoHandScene,
    models: HandPair,
    prior: &PriorSource,
    mut config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<(Trainer, Option<Refinement>), BittError> {
    let s = config.nets.image_size;
    if [hands.camera.width, hands.camera.height] != [s as u32, s as u32] {
        return Err(BittError::Invalid(format!(
            "the training view is {}x{}; the {} preset needs {s}x{s}",
            hands.camera.width, hands.camera.height, config.preset
        )));
    }
    let assets = HandAssets::new(models, config.texture.resolution)?;
    let pca = texture_model(&mut config, prior, &assets, cache, &device.clone().inner())?;
    let refinement = match refine {
        Some(r) => {
            let done = refine_view(
                &assets,
                &pca,
                hands,
                view_image,
                None,
                r.config,
                device,
                r.observer,
                "the training view",
            )?;
            *hands = done.hands.clone();
            Some(done)
        }
        None => None,
    };
    let geometry = ViewGeometry::new(&assets, hands, device)?;
    let trainer = Trainer::new(config, assets, &pca, geometry, view_image, None, device)?;
    Ok((trainer, refinement))
}

/// Everything a fresh real run starts from: the record, the prepared views and the trainer.
#[derive(Debug)]
pub struct RealSetup {
    /// What `input.json` will hold.
    pub input: RealInput,
    /// The prepared views (novel views and poses empty for a single annotation).
    pub scene: RealScene,
    /// The trainer (its `config` possibly adapted to the prior).
    pub trainer: Trainer,
    /// The mesh refinement of the training view, when asked for (its hands are the view's).
    pub refinement: Option<Refinement>,
}

/// A fresh real run from an image and its BiTT annotation pickle.
#[allow(clippy::too_many_arguments)]
pub fn annotation_setup(
    image: &Path,
    annotation: &Path,
    hands: &HandSource,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<RealSetup, BittError> {
    let models = load_models(hands, prior)?;
    let view = annotation_view(image, annotation, &models, config.nets.image_size)?;
    let source = RealSource::Annotation {
        image: absolute(image),
        annotation: absolute(annotation),
    };
    single_view_setup(
        view, source, image, models, hands, prior, config, cache, refine, device,
    )
}

/// The setup of a run on one prepared view (`image` is its photo).
#[allow(clippy::too_many_arguments)]
fn single_view_setup(
    mut view: RealView,
    source: RealSource,
    image: &Path,
    models: HandPair,
    hands: &HandSource,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<RealSetup, BittError> {
    let (trainer, refinement) = refined_real_trainer(
        &view.image,
        &mut view.hands,
        models,
        prior,
        config,
        cache,
        refine,
        device,
    )?;
    Ok(RealSetup {
        refinement,
        input: RealInput {
            format: INPUT_FORMAT.into(),
            source,
            hands: hands.absolute(),
            prior: prior.absolute(),
            train: ViewRecord {
                source: absolute(image),
                ..ViewRecord::from(&view)
            },
            novel_views: Vec::new(),
            novel_poses: Vec::new(),
        },
        scene: RealScene {
            train: view,
            novel_views: Vec::new(),
            novel_poses: Vec::new(),
        },
        trainer,
    })
}

/// A fresh real run from a photo whose hands were fitted to its keypoints
/// ([`crate::fit::fit_photo`]; `fit.image` is the photo as fitted, `keypoints` the file).
///
/// # Errors
/// A fit without both hands, hands outside the image; as [`real_trainer`].
#[allow(clippy::too_many_arguments)]
pub fn keypoint_setup(
    fit: &crate::fit::PhotoFit,
    image: &Path,
    keypoints: &Path,
    hands: &HandSource,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<RealSetup, BittError> {
    for side in Side::BOTH {
        if fit.hands.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand has too few keypoints to be fitted; BiTT needs both hands",
                keypoints.display()
            )));
        }
    }
    let models = fit.models.clone();
    check_hand_placement(&fit.hands, &models, keypoints)?;
    let view = prepare_view(
        "train",
        image,
        fit.image.clone(),
        &fit.hands,
        &models,
        config.nets.image_size,
    )?;
    let source = RealSource::Keypoints {
        image: absolute(image),
        keypoints: absolute(keypoints),
        mirrored: fit.mirrored,
    };
    single_view_setup(
        view, source, image, models, hands, prior, config, cache, refine, device,
    )
}

/// A fresh real run from a selected InterHand2.6M scene.
#[allow(clippy::too_many_arguments)]
pub fn interhand_setup(
    scene: &InterHandScene,
    paths: &bitt_mesh::interhand::InterHandPaths,
    hands: &HandSource,
    prior: &PriorSource,
    config: TrainConfig,
    cache: Option<&Path>,
    refine: Option<MeshRefine<'_>>,
    device: &Device,
) -> Result<RealSetup, BittError> {
    let models = load_models(hands, prior)?;
    let mut views = interhand_views(scene, &models, config.nets.image_size)?;
    let (trainer, refinement) = refined_real_trainer(
        &views.train.image,
        &mut views.train.hands,
        models,
        prior,
        config,
        cache,
        refine,
        device,
    )?;
    let record = |v: &RealView| ViewRecord {
        source: absolute(&v.source),
        ..ViewRecord::from(v)
    };
    Ok(RealSetup {
        refinement,
        input: RealInput {
            format: INPUT_FORMAT.into(),
            source: RealSource::InterHand {
                root: absolute(&paths.root),
                split: paths.split.clone(),
                capture: scene.capture,
                frame: scene.train.entry.frame_idx,
                camera: scene.train.entry.camera.clone(),
            },
            hands: hands.absolute(),
            prior: prior.absolute(),
            train: record(&views.train),
            novel_views: views.novel_views.iter().map(record).collect(),
            novel_poses: views.novel_poses.iter().map(record).collect(),
        },
        scene: views,
        trainer,
    })
}

impl RealInput {
    /// Whether `dir` holds a real run (an `input.json`).
    pub fn is_real_run(dir: &Path) -> bool {
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
        crate::outputs::write_json(&dir.join(files::INPUT), self)
    }

    /// The prepared views of a real run in `dir` (exact images from `input/images.safetensors`).
    pub fn read_scene(&self, dir: &Path, size: usize) -> Result<RealScene, BittError> {
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
            .map_err(|e| BittError::corrupt(&path, format!("not a real-run input record: {e}")))?;
        if input.format != INPUT_FORMAT {
            return Err(BittError::corrupt(
                &path,
                format!("format `{}`, expected `{INPUT_FORMAT}`", input.format),
            ));
        }
        let mut input = input;
        let path = dir.join(files::IMAGES);
        let bytes = std::fs::read(&path).map_err(|e| BittError::io(&path, e))?;
        let st = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| BittError::corrupt(&path, format!("not a safetensors file: {e}")))?;
        for view in std::iter::once(&mut input.train)
            .chain(&mut input.novel_views)
            .chain(&mut input.novel_poses)
        {
            restore_exact_floats(&st, &path, &view.name, &mut view.hands)?;
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
    let mut bytes: Vec<(String, safetensors::Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    for v in views {
        bytes.push((
            v.name.clone(),
            safetensors::Dtype::F32,
            vec![3, size, size],
            v.image.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ));
        let mut hands = v.hands.clone();
        let floats: Vec<u8> = float_slots(&mut hands)
            .into_iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        bytes.push((
            format!("hands.{}", v.name),
            safetensors::Dtype::F64,
            vec![floats.len() / 8],
            floats,
        ));
    }
    let mut tensors = Vec::new();
    for (name, dtype, shape, b) in &bytes {
        let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), b)
            .map_err(|e| BittError::corrupt(path, format!("cannot encode `{name}`: {e}")))?;
        tensors.push((name.clone(), view));
    }
    let meta = std::collections::HashMap::from([(
        "format".to_string(),
        "bitt-real-input-images: per view, `NAME` [3, S, S] f32 in [0, 1] and `hands.NAME` \
         the exact f64 values of input.json's hands and camera"
            .to_string(),
    )]);
    let data = safetensors::serialize(tensors, Some(meta))
        .map_err(|e| BittError::corrupt(path, format!("cannot encode: {e}")))?;
    bitt_mesh::export::write_atomically(path, &data)?;
    Ok(())
}

/// Puts the exact floats stored for view `name` into `hands`.
fn restore_exact_floats(
    st: &safetensors::SafeTensors,
    path: &Path,
    name: &str,
    hands: &mut TwoHandScene,
) -> Result<(), BittError> {
    let key = format!("hands.{name}");
    let t = st
        .tensor(&key)
        .map_err(|_| BittError::corrupt(path, format!("`{key}` is missing")))?;
    let values: Vec<f64> = t
        .data()
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let slots = float_slots(hands);
    if t.dtype() != safetensors::Dtype::F64 || values.len() != slots.len() {
        return Err(BittError::corrupt(
            path,
            format!(
                "`{key}` is {:?} with {} values; input.json's view `{name}` has {}",
                t.dtype(),
                values.len(),
                slots.len()
            ),
        ));
    }
    if values.iter().any(|x| !x.is_finite()) {
        return Err(BittError::corrupt(
            path,
            format!("`{key}` holds non-finite values"),
        ));
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
    let st = safetensors::SafeTensors::deserialize(bytes)
        .map_err(|e| BittError::corrupt(path, format!("not a safetensors file: {e}")))?;
    let t = st
        .tensor(name)
        .map_err(|_| BittError::corrupt(path, format!("image `{name}` is missing")))?;
    if t.dtype() != safetensors::Dtype::F32 || t.shape() != [3, size, size] {
        return Err(BittError::corrupt(
            path,
            format!(
                "image `{name}` is {:?} {:?}; the run's preset needs F32 [3, {size}, {size}]",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    let v: Vec<f32> = t
        .data()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if v.iter().any(|x| !x.is_finite()) {
        return Err(BittError::corrupt(
            path,
            format!("image `{name}` holds non-finite values"),
        ));
    }
    Ok(v)
}

// -------------------------------------------------------------------------------------------
// Scores on real novel views and poses.

/// Scores of a real multi-view scene against its photographs (hands masked by the given
/// meshes' silhouettes, as the reference's `masked_img`).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RealScores {
    /// Mean over the novel views.
    pub novel_views: Option<crate::run::MeanScore>,
    /// Mean over the novel poses.
    pub novel_poses: Option<crate::run::MeanScore>,
    /// Per view: name, fine and coarse metrics.
    pub views: Vec<(String, crate::evaluate::ViewScore)>,
}

/// Silhouette masks `[H, W]` of both hands (after the shared depth test) of `hands`.
pub fn hand_masks(trainer: &Trainer, hands: &TwoHandScene) -> Result<[Vec<f32>; 2], BittError> {
    let device = trainer.view.image.device().inner();
    let geometry = ViewGeometry::new(&trainer.assets, hands, &device)?;
    let t = trainer.assets.num_texels();
    let zeros = Tensor::<2>::zeros([3, t], &device);
    let settings = RenderSettings {
        antialias: false,
        ..RenderSettings::default()
    };
    let r = geometry.render(
        &trainer.assets,
        &trainer.assets.gather(&device),
        [zeros.clone(), zeros],
        &LightValues::default().to_light(&device),
        &settings,
    )?;
    let mut masks = r.masks.into_iter().map(read);
    let (Some(l), Some(r)) = (masks.next(), masks.next()) else {
        return Err(BittError::Invalid("the render has no mask per hand".into()));
    };
    Ok([l?, r?])
}

/// Renders the trained avatar at every novel view and pose of `scene` (the estimated light
/// kept fixed in the capture's world) and scores fine and coarse renders against the
/// photographs.
pub fn score_real(trainer: &Trainer, scene: &RealScene) -> Result<RealScores, BittError> {
    let avatar = crate::evaluate::Avatar::from_trainer(trainer)?;
    let mut views = Vec::new();
    let mut score = |v: &RealView| -> Result<crate::evaluate::ViewScore, BittError> {
        let masks = hand_masks(trainer, &v.hands)?;
        let (s, _, _) = crate::evaluate::score_view(trainer, &avatar, &v.hands, &v.image, &masks)?;
        views.push((v.name.clone(), s));
        Ok(s)
    };
    let nv: Vec<_> = scene
        .novel_views
        .iter()
        .map(&mut score)
        .collect::<Result<_, _>>()?;
    let np: Vec<_> = scene
        .novel_poses
        .iter()
        .map(&mut score)
        .collect::<Result<_, _>>()?;
    let mean = |s: &[crate::evaluate::ViewScore]| {
        let fine: Vec<_> = s.iter().map(|x| x.fine).collect();
        let coarse: Vec<_> = s.iter().map(|x| x.coarse).collect();
        Some(crate::run::MeanScore {
            fine: crate::evaluate::mean_metrics(&fine)?,
            coarse: crate::evaluate::mean_metrics(&coarse)?,
            count: s.len(),
        })
    };
    Ok(RealScores {
        novel_views: mean(&nv),
        novel_poses: mean(&np),
        views,
    })
}

// -------------------------------------------------------------------------------------------
// A saved real avatar, and poses to render avatars in.

/// A real run's avatar read back from its folder (no networks needed).
#[derive(Debug, Clone)]
pub struct RealAvatar {
    /// The run's (adapted) configuration.
    pub config: TrainConfig,
    /// The run's input record.
    pub input: RealInput,
    /// Fine textures `[3, T]`, left then right.
    pub fine: [Vec<f32>; 2],
    /// The estimated light, in the training camera's frame.
    pub light: LightValues,
}

impl RealAvatar {
    /// Reads `config.json`, `input.json`, `textures/textures.safetensors` and `light.json`.
    pub fn load(dir: &Path) -> Result<Self, BittError> {
        let path = dir.join(crate::run::files::CONFIG);
        let text = std::fs::read_to_string(&path).map_err(|e| BittError::io(&path, e))?;
        let config = TrainConfig::from_json(&text, &path)?;
        let input = RealInput::read(dir)?;
        Ok(RealAvatar {
            config,
            input,
            fine: crate::run::SavedAvatar::read_fine_textures(dir)?,
            light: crate::run::SavedAvatar::read_light(dir)?,
        })
    }

    /// The hand models and assets the avatar was trained with (MANO and HTML's UV layouts
    /// are read from the folders `input.json` names).
    pub fn assets(&self) -> Result<HandAssets, BittError> {
        let models = load_models(&self.input.hands, &self.input.prior)?;
        let assets = HandAssets::new(models, self.config.texture.resolution)?;
        if self.fine[0].len() != 3 * assets.num_texels() {
            return Err(BittError::Invalid(format!(
                "the saved textures have {} values; the hands' {}x{} layout needs {}",
                self.fine[0].len(),
                self.config.texture.resolution,
                self.config.texture.resolution,
                3 * assets.num_texels()
            )));
        }
        Ok(assets)
    }

    /// The training camera (fitted to the preset's size).
    pub fn camera(&self) -> PinholeCamera {
        self.input.train.hands.camera
    }
}

/// Renders compact textures `[3, T]` (left, right) on `hands` (camera included) under
/// `light` (in that camera's frame): `[3, H, W]` on the host.
pub fn render_textures(
    assets: &HandAssets,
    textures: &[Vec<f32>; 2],
    hands: &TwoHandScene,
    light: &LightValues,
    device: &Device,
) -> Result<Vec<f32>, BittError> {
    let t = assets.num_texels();
    for tex in textures {
        if tex.len() != 3 * t {
            return Err(BittError::Invalid(format!(
                "a texture has {} values; the layout needs {}",
                tex.len(),
                3 * t
            )));
        }
    }
    let geometry = ViewGeometry::new(assets, hands, device)?;
    let tex = |v: &Vec<f32>| Tensor::<2>::from_data(TensorData::new(v.clone(), [3, t]), device);
    let r = geometry.render(
        assets,
        &assets.gather(device),
        [tex(&textures[0]), tex(&textures[1])],
        &light.to_light(device),
        &RenderSettings::default(),
    )?;
    read(r.image)
}

/// The hands of another BiTT annotation pickle, with its camera cropped around the hands
/// like a training view and resized to `size` (the annotation's intrinsics are for the image
/// beside it, `NN.jpg` / `NN.png`, else for the reference's 256 x 256 crop).
pub fn annotation_pose(
    path: &Path,
    models: &HandPair,
    size: usize,
) -> Result<TwoHandScene, BittError> {
    let image_size = ["jpg", "jpeg", "png"]
        .iter()
        .map(|ext| path.with_extension(ext))
        .find(|p| p.is_file())
        .and_then(|p| image::image_dimensions(p).ok())
        .unwrap_or((BITT_CROP_SIZE, BITT_CROP_SIZE));
    let hands = bitt_mesh::load_bitt_annotation(path, image_size)?;
    for side in Side::BOTH {
        if hands.hand(side).is_none() {
            return Err(BittError::Invalid(format!(
                "{}: the {side} hand is not annotated; the avatar needs both hands",
                path.display()
            )));
        }
    }
    let b = hands_box(&hands, models)
        .map_err(|e| BittError::Invalid(format!("{}: {e}", path.display())))?;
    let camera = fit_camera(&hands.camera, Some(reference_crop_box(b)), size)?;
    Ok(TwoHandScene { camera, ..hands })
}

/// Names of the procedural pose families (`clasp`, `interlaced`, `palm_on_back`, ...).
pub fn pose_family_names() -> Vec<String> {
    PoseFamily::ALL
        .iter()
        .filter_map(|f| serde_json::to_value(f).ok())
        .filter_map(|v| v.as_str().map(str::to_owned))
        .collect()
}

/// Parses a pose family name (`palm_on_back` or `palm-on-back`).
pub fn parse_pose_family(name: &str) -> Result<PoseFamily, BittError> {
    serde_json::from_value(serde_json::Value::String(
        name.trim().to_lowercase().replace('-', "_"),
    ))
    .map_err(|_| {
        BittError::Invalid(format!(
            "unknown procedural pose `{name}`; the families are {}",
            pose_family_names().join(", ")
        ))
    })
}

/// A two-hand pose of `family` from the synthetic generator (`seed` picks the jitter), for
/// hands of shape `betas` (left, right), seen from a camera in front of the person and
/// somewhat above, framed so the hands fill 80% of a `size x size` image.
pub fn procedural_pose(
    models: &HandPair,
    family: PoseFamily,
    betas: [&[f64]; 2],
    seed: u64,
    size: usize,
) -> Result<TwoHandScene, BittError> {
    let rig = bitt_synth::pose::Rig::new(&models.right)?;
    let mut rng = bitt_texture::procedural::noise::SplitMix64::new(seed);
    let pose = bitt_synth::pose::two_hand_pose(models, &rig, betas[1], family, &mut rng)?;
    let (mut left, mut right) = (pose.left, pose.right);
    left.betas = betas[0].to_vec();
    right.betas = betas[1].to_vec();
    let mut points = models.left.forward(&left)?.vertices;
    points.extend(models.right.forward(&right)?.vertices);
    let placement = bitt_synth::views::CameraPlacement {
        azimuth: 0.0,
        elevation: 0.5,
        distance: 0.6,
        roll: 0.0,
        fill: 0.8,
    };
    let camera = bitt_synth::views::framed_camera(&placement, DVec3::ZERO, &points, size as u32)?;
    Ok(TwoHandScene {
        left: Some(left),
        right: Some(right),
        camera,
        frame: Default::default(),
    })
}

/// `hands` seen from its camera orbited by `yaw` and `pitch` radians about the hands' centre
/// (see [`crate::run::orbit_camera`]).
pub fn orbit_hands(
    hands: &TwoHandScene,
    models: &HandPair,
    yaw: f64,
    pitch: f64,
) -> Result<TwoHandScene, BittError> {
    if yaw == 0.0 && pitch == 0.0 {
        return Ok(hands.clone());
    }
    let posed = hands.pose_in_camera(models)?;
    let all: Vec<DVec3> = [posed.left, posed.right]
        .into_iter()
        .flatten()
        .flat_map(|h| h.vertices)
        .collect();
    let center = all.iter().copied().sum::<DVec3>() / all.len().max(1) as f64;
    Ok(TwoHandScene {
        camera: crate::run::orbit_camera(&hands.camera, center, yaw, pitch),
        ..hands.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use bitt_mesh::glam::DMat3;

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

    #[test]
    fn left_uv_faces_follow_the_winding() {
        let right_faces = vec![[0, 1, 2], [2, 1, 3]];
        let left_faces = vec![[0, 2, 1], [2, 3, 1]];
        let uv = UvLayout {
            uvs: vec![bitt_mesh::glam::DVec2::ZERO; 6],
            faces: vec![[10, 11, 12], [20, 21, 22]],
        };
        let left = left_uv_from_right(&uv, &right_faces, &left_faces).unwrap();
        assert_eq!(left.faces, vec![[10, 12, 11], [20, 22, 21]]);
        let bad = vec![[0, 1, 5], [2, 3, 1]];
        assert!(left_uv_from_right(&uv, &right_faces, &bad).is_err());
    }

    #[test]
    fn sources_must_fit_together() {
        let html = PriorSource::Html {
            dir: "/x/html".into(),
        };
        let mano = HandSource::Mano {
            dir: "/x/mano".into(),
        };
        assert!(check_sources(&HandSource::Procedural, &html).is_err());
        assert!(check_sources(&mano, &PriorSource::Procedural).is_err());
        assert!(check_sources(&mano, &html).is_ok());
        assert!(check_sources(&HandSource::Procedural, &PriorSource::Procedural).is_ok());
    }

    #[test]
    fn reference_crop_has_the_reference_side() {
        let b = [10.0, 20.0, 90.0, 60.0];
        let g = reference_crop_box(b);
        // fit_square's side from g equals max(w, h) / 0.8 from b.
        let side = (g[2] - g[0]).max(g[3] - g[1]) * (1.0 + crate::input::CROP_MARGIN);
        assert!(
            (side - 80.0 / REFERENCE_HAND_BOX_RATIO).abs() < 1e-9,
            "{side}"
        );
        assert!(((g[0] + g[2]) / 2.0 - 50.0).abs() < 1e-12);
    }

    /// The procedural hands side by side, 0.7 m in front of a 200 x 120 camera.
    fn hands_before_a_small_camera() -> (HandPair, TwoHandScene) {
        let models = procedural_pair();
        let mut hands = TwoHandScene {
            left: Some(bitt_mesh::HandParams::mean_pose()),
            right: Some(bitt_mesh::HandParams::mean_pose()),
            camera: PinholeCamera::looking_down_z(300.0, 200, 120),
            frame: Default::default(),
        };
        for (side, x) in [(Side::Left, -0.07), (Side::Right, 0.07)] {
            let p = match side {
                Side::Left => hands.left.as_mut().unwrap(),
                Side::Right => hands.right.as_mut().unwrap(),
            };
            p.trans = DVec3::new(x - 0.09, -0.01, 0.7);
            p.root_rotation = DMat3::IDENTITY;
        }
        (models, hands)
    }

    #[test]
    fn crop_keeps_projections_consistent() {
        let (models, hands) = hands_before_a_small_camera();
        let image = vec![0.5f32; 3 * 200 * 120];
        let v = prepare_view("train", Path::new("x.png"), image, &hands, &models, 32).unwrap();
        assert_eq!(v.image.len(), 3 * 32 * 32);
        assert_eq!([v.hands.camera.width, v.hands.camera.height], [32, 32]);
        // A 3-D point projects consistently: the crop maps its full-frame pixel linearly.
        let b = hands_box(&hands, &models).unwrap();
        let side = (b[2] - b[0]).max(b[3] - b[1]) / REFERENCE_HAND_BOX_RATIO;
        let (x0, y0) = ((b[0] + b[2] - side) / 2.0, (b[1] + b[3] - side) / 2.0);
        let p = DVec3::new(0.01, 0.02, 0.68);
        let before = hands.camera.project(p).unwrap();
        let after = v.hands.camera.project(p).unwrap();
        let expect = (before - bitt_mesh::glam::DVec2::new(x0, y0)) * (32.0 / side);
        assert!((after - expect).length() < 1e-9, "{after} vs {expect}");
        // The hands' box fills 80% of the crop.
        let nb = hands_box(&v.hands, &models).unwrap();
        let fill = (nb[2] - nb[0]).max(nb[3] - nb[1]) / 32.0;
        assert!((fill - REFERENCE_HAND_BOX_RATIO).abs() < 1e-6, "{fill}");
        // Hands outside the image are refused.
        let mut away = hands.clone();
        away.camera.intrinsics.z_axis.x += 5000.0;
        let e = prepare_view(
            "t",
            Path::new("far.png"),
            vec![0.0; 3 * 200 * 120],
            &away,
            &models,
            32,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("far.png") && e.contains("outside"), "{e}");
    }

    /// Each hand is checked on its own: one hand off the image, far away, behind the camera
    /// or at a non-finite place is refused, naming the file, the hand and the problem, even
    /// when the other hand is fine.
    #[test]
    fn each_hand_must_be_in_front_of_the_camera_and_in_the_image() {
        let (models, hands) = hands_before_a_small_camera();
        let source = Path::new("frame.pkl");
        check_hand_placement(&hands, &models, source).unwrap();
        let moved = |offset: DVec3| {
            let mut h = hands.clone();
            let left = h.left.as_mut().unwrap();
            left.trans += offset;
            check_hand_placement(&h, &models, source)
                .unwrap_err()
                .to_string()
        };
        for (offset, expect) in [
            (DVec3::new(100.0, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(1e20, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(3e38, 0.0, 0.0), "only 0% of the left hand"),
            (DVec3::new(0.0, 0.0, -5.0), "left hand is behind the camera"),
            (DVec3::new(0.0, 0.0, -0.7), "left hand is partly behind"),
            (
                DVec3::new(0.0, 0.0, 100.0),
                "a photographed hand lies between",
            ),
            (
                DVec3::new(0.0, 0.0, 1e20),
                "a photographed hand lies between",
            ),
            (
                DVec3::new(f64::INFINITY, 0.0, 0.0),
                "left hand: a pose, shape, rotation or translation value is NaN or infinite",
            ),
            // Shifted right by most of the image: the box of both hands still overlaps it.
            (
                DVec3::new(0.55, 0.0, 0.0),
                "of the left hand projects into the 200x120",
            ),
        ] {
            let e = moved(offset);
            assert!(
                e.contains("frame.pkl") && e.contains(expect),
                "{offset}: {e}"
            );
        }
        // The check on the box of both hands alone let the last one through.
        let mut h = hands.clone();
        h.left.as_mut().unwrap().trans += DVec3::new(0.55, 0.0, 0.0);
        hands_in_image(&h, &models, source).unwrap();
    }

    #[test]
    fn pose_families_parse() {
        assert_eq!(
            parse_pose_family("palm-on-back").unwrap(),
            PoseFamily::PalmOnBack
        );
        assert_eq!(parse_pose_family("Clasp").unwrap(), PoseFamily::Clasp);
        let e = parse_pose_family("wave").unwrap_err().to_string();
        assert!(e.contains("interlaced") && e.contains("wave"), "{e}");
        let models = procedural_pair();
        let betas = vec![0.0; 10];
        let s = procedural_pose(&models, PoseFamily::Prayer, [&betas, &betas], 3, 32).unwrap();
        let b = hands_box(&s, &models).unwrap();
        assert!(
            b[0] > 0.0 && b[2] < 32.0 && b[1] > 0.0 && b[3] < 32.0,
            "{b:?}"
        );
        let turned = orbit_hands(&s, &models, 0.5, 0.0).unwrap();
        assert_ne!(turned.camera, s.camera);
    }
}
