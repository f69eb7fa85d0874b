//! The error type of this crate, [`MeshError`].

use bitt_stdx::FileError;

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
