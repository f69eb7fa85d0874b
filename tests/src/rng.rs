//! The test kit's deterministic generator (SplitMix64), under the name the fixtures use.

pub use bitt_testkit::Rng;
