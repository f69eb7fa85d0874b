//! The project's own procedural skin-texture model for the procedural hand.
//!
//! BiTT's coarse texture prior is HTML, a PCA model fitted to scanned hands under a licence
//! this project cannot ship. This module makes a license-free stand-in: a generator of
//! plausible skin textures for the procedural hand ([`generate_texture`]), driven by a small
//! set of per-person parameters ([`SkinIdentity`]), and a PCA model fitted to a population of
//! generated people ([`procedural_texture_pca`]), which plays HTML's role.
//!
//! # The generator
//!
//! Every texel is shaded independently from its **rest-pose point** and **normal** on the hand
//! (the layout records each texel's face and barycentrics) and from the **skeleton** regressed
//! from the template, in the right hand's frame (the left hand's points are mapped by
//! `x -> -x`, so texel `i` of both hands sees the same noise, creases and veins). Layers:
//!
//! - **tone**: a melanin-like palette coordinate from very light to very dark skin, lower on
//!   the palm side (which side a texel is on comes from its normal against the local nail-side
//!   direction: `+y`, turned with the thumb along the thumb), with low-frequency blotches;
//!   undertone (red/yellow) and blood redness (mottled; palm, eminences, finger pads,
//!   fingertips and knuckles redder) tint it in linear light;
//! - **palm creases**: heart, head and life lines and two wrist bracelets, splines in a palm
//!   frame built from the wrist and the knuckles, jittered per person; minor creases from the
//!   ridges of an anisotropic noise; **flexion creases** across the pad side of every finger
//!   joint (double at the PIP and at the finger base);
//! - **knuckles**: darker, redder patches with curved transverse wrinkles on the back of the
//!   MCP, PIP and DIP joints;
//! - **veins**: a dorsal venous network (veins from the wrist towards the knuckle gaps, an
//!   arch, side branches), bluish, more visible on light skin;
//! - **hair**: short dark strokes scattered on a 3D grid over the back of the hand and the
//!   proximal phalanges, combed towards the fingers;
//! - **nails** on the back of the distal phalanges: pink bed, lunula, white free edge, cuticle;
//! - **freckles and moles**: scattered spots (some moles per hand, not mirrored);
//! - a fine **grain**, and the per-hand **asymmetry** noise.
//!
//! Thin features are band-limited to the texel size (lines keep their "ink", noise octaves
//! finer than two texels fade), so any resolution gives a clean texture. Randomness is a
//! built-in SplitMix64 and gradient noise ([`noise`]): everything is deterministic.
//!
//! See `docs/procedural-textures.md` for pictures and the fitted model's numbers.

mod anatomy;
mod fit;
mod generate;
mod identity;
pub mod noise;

#[cfg(test)]
mod tests;

pub use fit::{
    EvalReport, ProceduralTextureConfig, procedural_texture_model, procedural_texture_pca,
    procedural_texture_pca_with_progress,
};
pub use generate::{generate_texture, palm_side_texels};
pub use identity::SkinIdentity;
