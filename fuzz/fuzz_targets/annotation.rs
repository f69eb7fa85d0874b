//! Fuzzes the two-hand annotation reader behind every `--annotation`: BiTT/InterHand
//! annotation pickles and `hands.json`, told apart by content. Any input gives a scene or an
//! error naming the file, never a panic; a scene that loads must pose (on a one-vertex model,
//! so posing stays cheap) or fail with an error.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::annotation(data);
});
