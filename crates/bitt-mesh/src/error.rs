//! The error types of this crate: [`FileError`], the file error every crate above wraps, and
//! [`MeshError`].

use std::path::PathBuf;

/// A file that could not be read or written, or that was read but does not hold what it
/// should. Every library crate's error wraps it (`File(#[from] FileError)`, shown as is), so
/// a path and its problem read the same whichever crate reports them.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
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
}

impl FileError {
    /// A [`FileError::Format`] for `path`.
    pub fn format(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        FileError::Format {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// A [`FileError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FileError::Io {
            path: path.into(),
            source,
        }
    }

    /// What is wrong, without the path (for a caller that names the file itself).
    pub fn detail(&self) -> String {
        match self {
            FileError::Io { source, .. } => source.to_string(),
            FileError::Format { detail, .. } => detail.clone(),
        }
    }
}

/// [`FileError`]'s constructors on every error that wraps one: `MeshError::format(path, ..)`,
/// `TextureError::io(path, e)`, ... (bring the trait into scope).
pub trait FileErrorExt: From<FileError> {
    /// A [`FileError::Format`] for `path`.
    fn format(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        FileError::format(path, detail).into()
    }

    /// A [`FileError::Io`] for `path`.
    fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FileError::io(path, source).into()
    }
}

impl<E: From<FileError>> FileErrorExt for E {}

/// Everything that can go wrong reading, validating, posing or writing hands.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A pickle could not be read.
    #[error(transparent)]
    Pickle(#[from] bitt_pickle::PickleError),
    /// A file could not be read or written, or does not hold what it should.
    #[error(transparent)]
    File(#[from] FileError),
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
    /// A request that cannot be met (a file missing from a folder...), said in full.
    #[error("{0}")]
    Invalid(String),
    /// What was being done (reading a file, parsing it) when `source` went wrong.
    #[error("{context}")]
    Context {
        /// What was being done.
        context: String,
        /// What went wrong.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync + 'static>,
    },
}
