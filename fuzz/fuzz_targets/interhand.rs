//! Fuzzes the InterHand2.6M dataset reader: the input is the data, camera and MANO JSON
//! files joined by NUL bytes (`data \0 camera \0 mano`; JSON never holds a raw NUL). Any
//! input gives an index or an error naming a file, never a panic; every candidate's scene
//! converts or fails with an error, and selection (whose images do not exist here) fails
//! with an error.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::interhand(data);
});
