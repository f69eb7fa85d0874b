//! UV texture layouts and texture PCA models for BiTT.
//!
//! BiTT's coarse texture is HTML, a PCA model `T(a) = mean + basis a` over the compact vector
//! of a UV map's valid texels; its fine stage (BTR) works on the same compact vector for both
//! hands. This crate owns that representation: layouts ([`layout`]), PCA models ([`pca`]),
//! the HTML loaders ([`html`]), the project's own procedural skin model ([`procedural`]),
//! PCA models resampled onto another layout ([`resample`]) and texture images on disk
//! ([`image_io`]). It knows nothing about networks or rendering.
//!
//! Architecture invariant: every texture the project stores is in one compact order
//! (`[3, T]`, channel-major, the layout's texel order), and both hands' layouts have the
//! same texels in the same order: texel `i` of the left texture is texel `i` of the right,
//! which BTR's left/right symmetry relies on.
//!
//! The procedural PCA is fitted on all cores with the same result, bit for bit, for any
//! number of threads ([`FitProgress`] reports each stage).

pub mod error;
pub mod html;
pub mod image_io;
pub mod layout;
pub mod pca;
pub mod procedural;
pub mod resample;
use bitt_stdx::st;

pub use error::TextureError;
pub use html::{
    HTML_SCALE, HTML_TEXTURE_SIZE, convert_html, load_html_model, load_html_model_sized,
    load_html_uvs,
};
pub use image_io::{
    ImageDifference, PlanarImage, load_compact_texture, load_image, save_compact_texture,
    save_png8, save_png16,
};
pub use layout::{LayoutGather, TextureLayout};
pub use pca::{
    FitProgress, FitStage, NoProgress, PcaFitReport, PcaProjector, TexturePca, TexturePcaTensors,
};
pub use procedural::{
    EvalReport, ProceduralTextureConfig, SkinIdentity, generate_texture, palm_side_texels,
    procedural_texture_model, procedural_texture_pca, procedural_texture_pca_with_progress,
};

#[cfg(test)]
pub(crate) mod test_util;
