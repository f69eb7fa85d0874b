//! [`FileError`], the file error every crate's error wraps, and [`FileErrorExt`], its
//! constructors on those errors; [`Context`], what was being done when an error happened.

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
    /// A path this tool will not write to or replace (a folder given for a file, a file or
    /// folder that is not an earlier output of ours), said in full; it is left untouched.
    #[error("{path}: {detail}")]
    Refused {
        /// The file or folder, left untouched.
        path: PathBuf,
        /// Why it is refused and what to give instead.
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

    /// A [`FileError::Refused`] for `path`.
    pub fn refused(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        FileError::Refused {
            path: path.into(),
            detail: detail.into(),
        }
    }

    /// What is wrong, without the path (for a caller that names the file itself).
    pub fn detail(&self) -> String {
        match self {
            FileError::Io { source, .. } => source.to_string(),
            FileError::Format { detail, .. } => detail.clone(),
            FileError::Refused { detail, .. } => detail.clone(),
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

/// What was being done (an option and its file, a scene) when `source` went wrong: the
/// context every crate's error wraps (`Context(#[from] Context)`, shown transparently), so
/// the message says what was being done and the source chain what went wrong.
#[derive(Debug, thiserror::Error)]
#[error("{context}")]
pub struct Context {
    /// What was being done.
    pub context: String,
    /// What went wrong.
    #[source]
    pub source: Box<dyn std::error::Error + Send + Sync + 'static>,
}

/// Says what was being done when an error happened ([`Context`]).
pub trait WithContext<T> {
    /// The error, if any, inside a [`Context`] of `context()`.
    ///
    /// # Errors
    /// The error of `self`, in its context.
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T, Context>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> WithContext<T> for Result<T, E> {
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T, Context> {
        self.map_err(|e| Context {
            context: context(),
            source: Box::new(e),
        })
    }
}
