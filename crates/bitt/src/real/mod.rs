//! Real data: an image with its annotation (the BiTT demo `NN.jpg` + `NN.pkl`), or a scene selected
//! from InterHand2.6M, turned into a [`Trainer`](crate::trainer::Trainer); the record a real run
//! keeps to be resumed and re-rendered; and the poses a saved avatar can be rendered in.
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
//! The trainer's layout is always [`HandAssets`](crate::assets::HandAssets)' one: the hands' UV
//! triangles rasterized at `config.texture.resolution` with a
//! [`crate::assets::TEXTURE_GUTTER`]-texel gutter. HTML's mean and basis (1024 x 1024, its own
//! texel set) are resampled onto that layout by [`resample_pca`] (in `bitt-texture`): each texel
//! averages HTML's texels under its footprint (bilinear taps over the texel's area; the nearest
//! HTML texel when none is under it). Resampling is linear, so the result is again a PCA model
//! (`mean' + basis' a` is the resampled `mean + basis a`).
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
//! Every view is cropped around both hands as the reference's data preparation does (`cut_img` with
//! `HAND_BBOX_RATIO = 0.8`: a square of side `max(box w, box h) / 0.8` centred on the projected
//! vertices' box; pixels outside the image are black) and resized to the preset's size by
//! [`ImageInput::fit_square`](crate::input::ImageInput::fit_square), which adjusts the intrinsics.
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
//!
//! # Files
//!
//! - `setup.rs`: fresh runs (annotation, keypoint fit, InterHand2.6M scene) and trainers.
//! - `record.rs`: `input.json` and `input/images.safetensors`, and resuming from them.
//! - `score.rs`: scores at novel views and poses against the photographs.
//! - `avatar.rs`: a saved real avatar and rendering textures on hands.
//! - `pose.rs`: poses to render an avatar in.
//!
//! The hand and prior sources, the photos read, checked against their hands, cropped and
//! resized, and the crop box are [`crate::input`]'s (re-exported here); the PCA resampling
//! is `bitt_texture::resample`.

mod avatar;
mod pose;
mod record;
mod score;
mod setup;

pub use crate::input::{
    HAND_DEPTH_RANGE_M, MIN_HAND_INSIDE, RealScene, RealView, annotation_view,
    check_hand_placement, interhand_views, prepare_view, read_image, require_image,
};
pub use crate::input::{
    HandSource, PriorSource, adapt_config_to_prior, attach_html_uvs, check_sources,
    left_uv_from_right, load_html_prior, load_models, sources, texture_model,
};
pub use avatar::{RealAvatar, render_textures};
pub use pose::{
    annotation_pose, orbit_hands, parse_pose_family, pose_family_names, procedural_pose,
};
pub use record::{INPUT_FORMAT, RealInput, RealSource, ViewRecord, files};
pub use score::{RealScores, hand_masks, score_real, silhouettes};
pub use setup::{
    RealRunSettings, RealSetup, annotation_setup, interhand_setup, keypoint_setup, real_trainer,
    refined_real_trainer,
};

pub use crate::input::{REFERENCE_HAND_BOX_RATIO, hands_box, hands_in_image, reference_crop_box};
pub use bitt_texture::resample::resample_pca;

/// Side of the square crops the BiTT annotation pickles' intrinsics refer to.
pub use bitt_mesh::annotation::BITT_CROP_SIZE;

use crate::input::absolute;
