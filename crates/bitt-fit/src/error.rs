//! The error type of this crate.

use bitt_stdx::FileError;

/// Everything that can go wrong finding, fitting and refining both hands in a photo.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// A setting, photo, keypoint set or target that the fit or refinement refuses, said in
    /// full (naming the file or option).
    #[error("{0}")]
    Invalid(String),
    /// The detector: its weights, a photo it cannot search, no hand found.
    #[error(transparent)]
    Detect(#[from] bitt_detect::DetectError),
    /// Posing the hands (the hand models, their forward pass).
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// Hands whose parameters or losses stopped being finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// Rendering the hands against the photo (refinement).
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
    /// The training core's optimiser and hand assets, which the fit and refinement share.
    #[error(transparent)]
    Train(#[from] bitt_train::TrainError),
    /// Hand parameters or renders read back from their device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
    /// A photo that does not decode.
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// A photo, mask or detection file that cannot be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The overlays drawn for the detection, fit and refinement.
    #[error(transparent)]
    Output(#[from] bitt_outputs::OutputError),
}
