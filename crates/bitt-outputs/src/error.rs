//! The error type of the output files.

use bitt_stdx::FileError;

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
