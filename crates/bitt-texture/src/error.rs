//! The one error type of this crate.

use bitt_stdx::FileError;

/// Everything that can go wrong with layouts, texture models and texture images.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    /// A pickle could not be read.
    #[error(transparent)]
    Pickle(#[from] bitt_pickle::PickleError),
    /// Geometry (a UV layout from a hand model) was invalid.
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// A file could not be read or written, or does not hold what it should (missing key,
    /// wrong shape, ...).
    #[error(transparent)]
    File(#[from] FileError),
    /// A tensor that could not be read back from its device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
    /// Arguments that do not fit (wrong lengths, NaN, empty layouts, ...).
    #[error("{0}")]
    Invalid(String),
}
