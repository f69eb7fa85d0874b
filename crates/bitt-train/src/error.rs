//! The error type of the training core.

use bitt_stdx::FileError;

/// Everything that can go wrong preparing a view, in the forward pass, the trainer and its
/// checkpoints.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A configuration or input outside its documented range.
    #[error("{0}")]
    Invalid(String),
    /// Reading or writing a file ([`FileError::Io`]), or a file that exists but is not what
    /// it should be ([`FileError::Format`]).
    #[error(transparent)]
    File(#[from] FileError),
    /// A tensor that could not be read back from its device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
    /// A loss or output that is not finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// Training gave up after [`crate::trainer::MAX_NON_FINITE`] non-finite losses; the
    /// trainer holds the last good state (iteration `restored`), which is also the saved
    /// checkpoint, so its results can still be written.
    #[error(
        "{message}; gave up after {count} recoveries and went back to iteration {restored}, the last good state"
    )]
    RecoveryExhausted {
        /// What the last failure was.
        message: String,
        /// Recoveries made.
        count: usize,
        /// The iteration of the state the trainer now holds.
        restored: usize,
    },
    /// The run was interrupted (Ctrl-C); the last state is saved.
    #[error("interrupted at iteration {0}; the run was saved and can be resumed")]
    Interrupted(usize),
    /// From the geometry crate.
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// From the texture crate.
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// From the renderer.
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
    /// From the networks.
    #[error(transparent)]
    Nets(#[from] bitt_nets::NetsError),
    /// From the synthetic generator.
    #[error(transparent)]
    Synth(#[from] bitt_synth::SynthError),
}
