//! Cross-crate tests of the BiTT workspace, and the fixture builders they share: a pickle
//! writer that emits files with the exact structure of MANO's, a deterministic RNG, and
//! real-data fixtures (annotation pickle + image, a miniature InterHand2.6M folder).

/// What each fuzz target asserts (`fuzz/checks.rs`, shared with the fuzz targets).
#[path = "../../fuzz/checks.rs"]
pub mod fuzz_checks;
pub mod fuzz_seeds;
pub mod pickle_writer;
pub mod real_fixture;
pub mod rng;
