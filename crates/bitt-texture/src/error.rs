//! The one error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong with layouts, texture models and texture images.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// A pickle could not be read.
    #[error(transparent)]
    Pickle(#[from] bitt_pickle::PickleError),
    /// Geometry (a UV layout from a hand model) was invalid.
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A file parsed but does not hold what it should (missing key, wrong shape, ...).
    #[error("{path}: {detail}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        detail: String,
    },
    /// Arguments that do not fit (wrong lengths, NaN, empty layouts, ...).
    #[error("{0}")]
    Invalid(String),
}

impl TextureError {
    /// A [`TextureError::Format`] for `path`.
    pub fn format(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        TextureError::Format {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`TextureError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        TextureError::Io {
            path: path.into(),
            source,
        }
    }
}
