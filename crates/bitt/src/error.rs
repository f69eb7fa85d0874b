//! The error type of the pipeline crate.

use bitt_stdx::FileError;

/// Everything that can go wrong in the pipeline, the trainer and the run outputs.
#[derive(Debug, thiserror::Error)]
pub enum BittError {
    /// A configuration or input outside its documented range.
    #[error("{0}")]
    Invalid(String),
    /// What was being done (an option and its file, a scene) when an error below went wrong.
    #[error(transparent)]
    Context(#[from] bitt_stdx::Context),
    /// From geometry from a photo.
    #[error(transparent)]
    Fit(#[from] bitt_fit::FitError),
    /// From the evaluation crate.
    #[error(transparent)]
    Eval(#[from] bitt_eval::EvalError),
    /// From the training core.
    #[error(transparent)]
    Train(#[from] bitt_train::TrainError),
    /// From the output files.
    #[error(transparent)]
    Output(#[from] bitt_outputs::OutputError),
    /// Reading or writing a file ([`FileError::Io`]), or a file that exists but is not what
    /// it should be ([`FileError::Format`]).
    #[error(transparent)]
    File(#[from] FileError),
    /// From the synthetic generator.
    #[error(transparent)]
    Synth(#[from] bitt_synth::SynthError),
    /// From the renderer.
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
    /// From the texture crate.
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// From the geometry crate.
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// From the networks.
    #[error(transparent)]
    Nets(#[from] bitt_nets::NetsError),
    /// From the hand detector.
    #[error(transparent)]
    Detect(#[from] bitt_detect::DetectError),
    /// A loss or output that is not finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// A tensor that could not be read back from its device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
}
