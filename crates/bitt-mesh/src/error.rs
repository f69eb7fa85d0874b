//! The one error type of this crate.

use std::path::PathBuf;

/// Everything that can go wrong reading, validating, posing or writing hands.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A pickle could not be read.
    #[error(transparent)]
    Pickle(#[from] bitt_pickle::PickleError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },
    /// A file parsed, but does not hold what it should (a missing key, a wrong shape...).
    #[error("{path}: {detail}")]
    Format {
        /// The file (or a description of the source).
        path: PathBuf,
        /// What is wrong, naming the key and the shapes involved.
        detail: String,
    },
    /// A hand model whose arrays disagree or hold non-finite values.
    #[error("invalid hand model from {source_name}: {detail}")]
    InvalidModel {
        /// Where the model came from.
        source_name: String,
        /// What is wrong.
        detail: String,
    },
    /// Parameters that cannot be posed (NaN, wrong length...).
    #[error("invalid hand parameters: {0}")]
    InvalidParams(String),
}

impl MeshError {
    /// A [`MeshError::Format`] for `path`.
    pub fn format(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        MeshError::Format {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`MeshError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        MeshError::Io {
            path: path.into(),
            source,
        }
    }
}
