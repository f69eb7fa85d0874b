//! The error type of the output files.

use std::path::PathBuf;

use bitt_mesh::FileError;

/// Everything that can go wrong drawing or writing what a user opens.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// An input outside its documented range (an image of the wrong size, a folder that
    /// is not ours).
    #[error("{0}")]
    Invalid(String),
    /// Reading or writing a file ([`FileError::Io`]), or a file that exists but is not what
    /// it should be ([`FileError::Format`]).
    #[error(transparent)]
    File(#[from] FileError),
    /// A value that is not finite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// From the geometry crate (posing, glTF and OBJ writing).
    #[error(transparent)]
    Mesh(#[from] bitt_mesh::MeshError),
    /// From the texture crate.
    #[error(transparent)]
    Texture(#[from] bitt_texture::TextureError),
    /// From the renderer.
    #[error(transparent)]
    Render(#[from] bitt_render::RenderError),
}

impl OutputError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FileError::io(path, source).into()
    }

    /// A corrupt file: one that exists but is not what it should be.
    pub fn corrupt(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        FileError::format(path, message).into()
    }
}
