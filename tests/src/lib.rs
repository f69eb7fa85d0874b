//! Cross-crate tests of the BiTT workspace, and the fixture builders they share: a pickle
//! writer that emits files with the exact structure of MANO's, and a deterministic RNG.

pub mod pickle_writer;
pub mod rng;
