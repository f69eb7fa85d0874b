//! The error type of the pipeline crate.

use std::path::PathBuf;

use bitt_mesh::FileError;

/// Everything that can go wrong in the pipeline, the trainer and the run outputs.
#[derive(Debug, thiserror::Error)]
pub enum BittError {
    /// A configuration or input outside its documented range.
    #[error("{0}")]
    Invalid(String),
    /// Reading or writing a file ([`FileError::Io`]), or a file that exists but is not what
    /// it should be ([`FileError::Format`]).
    #[error(transparent)]
    File(#[from] FileError),
    /// A loss or output that is not finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
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
    /// From the hand detector.
    #[error(transparent)]
    Detect(#[from] bitt_detect::DetectError),
    /// From the training core.
    #[error(transparent)]
    Train(#[from] bitt_train::TrainError),
    /// From the output files.
    #[error(transparent)]
    Output(#[from] bitt_outputs::OutputError),
    /// What was being done (an option and its file, a scene) when `source` went wrong.
    #[error("{context}")]
    Context {
        /// What was being done.
        context: String,
        /// What went wrong.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}

/// Says what was being done when an error happened ([`BittError::Context`]).
pub(crate) trait WithContext<T> {
    /// The error, if any, inside a [`BittError::Context`] of `context()`.
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T, BittError>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> WithContext<T> for Result<T, E> {
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T, BittError> {
        self.map_err(|e| BittError::Context {
            context: context(),
            source: Box::new(e),
        })
    }
}

impl BittError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FileError::io(path, source).into()
    }

    /// A corrupt file: one that exists but is not what it should be.
    pub fn corrupt(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        FileError::format(path, message).into()
    }
}
