//! The one error type of this crate.

use bitt_stdx::FileError;

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
    /// A file or folder could not be read or written, or a file was read but does not hold
    /// what it should (bad JSON, a missing tensor, a wrong shape, another generator
    /// version...).
    #[error(transparent)]
    File(#[from] FileError),
    /// A tensor that could not be read back from its device.
    #[error(transparent)]
    ReadBack(#[from] bitt_stdx::ReadBackError),
    /// A configuration value out of its range.
    #[error("invalid synthetic-scene configuration: {0}")]
    Config(String),
    /// Something that should not happen with a valid configuration (a scene that cannot be
    /// framed, a tensor that cannot be read back...).
    #[error("{0}")]
    Generate(String),
    /// One scene of a set could not be generated.
    #[error("generating scene {index} (seed {seed})")]
    Scene {
        /// Position of the scene in the set.
        index: usize,
        /// Its seed.
        seed: u64,
        /// Why.
        #[source]
        source: Box<SynthError>,
    },
}
