//! The four networks of BiTT (CVPR 2024, "Bi-directional Texture Reconstruction of
//! Interacting Two Hands from a Single Image") as burn modules.
//!
//! - [`albedo`]: the albedo network `A`, a U-Net from the image to an albedo image (Sec. 3.1);
//! - [`light`]: the light network `L`, an encoder to 12 light values (Sec. 3.1), and the
//!   one mapping of those to ambient / diffuse / specular colors and a location;
//! - [`html_encoder`]: the HTML network `H`, an encoder to both hands' 101 HTML
//!   coefficients (Sec. 3.2);
//! - [`btr`]: the bi-directional texture reconstructor, a 1-D U-Net over the texel vectors
//!   of both hands whose decoder mixes the hands (Sec. 3.3, eq. 3-5);
//! - [`preset`]: the named configurations `paper`, `quick` and `tiny` of all four.
//!
//! Layer choices follow the paper's supplement D and the reference implementation; at the
//! `paper` preset the parameter counts equal the reference's exactly (a unit test).
//! Every module is created on a `&Device` and runs on any burn backend. This crate knows
//! nothing about rendering, files or meshes: tensors in, tensors out.
//!
//! On flex, BTR's conv + group norm + SiLU block, its max pooling and the image networks'
//! conv + instance norm + activation run as custom operations with hand-written backward
//! passes (`fused`, through burn's `extension` feature); BTR's convolutions are matrix
//! products over shifted views ([`conv1d`]). Other backends decline the custom operations
//! and compose burn's own.
//!
//! Architecture invariant: a custom operation computes exactly the function of the burn
//! composition it replaces (tested: values and every gradient), so a model trains the same
//! on every backend. `fused/gemm.rs` holds the workspace's only `unsafe` library code.

pub mod albedo;
pub mod awake;
pub mod btr;
pub mod conv1d;
mod conv_block;
pub mod encoder;
pub mod error;
mod fused;
pub mod html_encoder;
pub mod light;
pub mod preset;

pub use albedo::{AlbedoNet, AlbedoNetConfig};
pub use btr::{Btr, BtrConfig, BtrOutput, compose_texels};
pub use conv1d::{ConvImpl, TexelConv, TexelConvConfig};
pub use encoder::{ConvEncoder, ConvEncoderConfig};
pub use error::NetsError;
pub use html_encoder::{HtmlCoefficients, HtmlEncoder, HtmlEncoderConfig};
pub use light::{LIGHT_OUTPUTS, LightNet, LightNetConfig, LightParams};
pub use preset::{BittNets, BittNetsConfig, PAPER_TEXELS, Preset, QUICK_TEXELS};

#[cfg(test)]
pub(crate) mod test_util;

#[cfg(test)]
mod tests;
