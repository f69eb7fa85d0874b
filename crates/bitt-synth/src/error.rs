//! The one error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong generating, writing or reading a synthetic scene.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// Posing or validating hands failed.
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// A texture layout or texture operation failed.
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A file was read but does not hold what it should (bad JSON, a missing tensor, a wrong
    /// shape, another generator version...).
    #[error("{path}: {detail}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// A configuration value out of its range.
    #[error("invalid synthetic-scene configuration: {0}")]
    Config(String),
    /// Something that should not happen with a valid configuration (a scene that cannot be
    /// framed, a tensor that cannot be read back...).
    #[error("{0}")]
    Generate(String),
}

impl SynthError {
    /// A [`SynthError::Format`] for `path`.
    pub fn format(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        SynthError::Format {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`SynthError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        SynthError::Io {
            path: path.into(),
            source,
        }
    }
}
