//! The error type of this crate.

use bitt_stdx::FileError;

/// Everything that can go wrong measuring images, textures and trained avatars.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A setting or an input that cannot be measured (sizes that disagree, an empty
    /// selection, LPIPS weights of the wrong shape), said in full.
    #[error("{0}")]
    Invalid(String),
    /// The trainer whose avatar is rendered (its geometry, its forward pass).
    #[error(transparent)]
    Train(#[from] bitt_train::TrainError),
    /// Rendering an avatar at another view or pose.
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
    /// A score, texture or light that is not finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// An image file that does not decode (`pair_metrics`).
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// A file that cannot be read or written (images, LPIPS weights, torch checkpoints).
    #[error(transparent)]
    File(#[from] FileError),
    /// A torch checkpoint that does not unpickle (`lpips_convert`).
    #[error(transparent)]
    Pickle(#[from] bitt_pickle::PickleError),
    /// Which file or weights were being read when an error below happened.
    #[error(transparent)]
    Context(#[from] bitt_stdx::Context),
    /// A render or a score read back from its device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
}
