//! Fuzzes the pickle reader: any input must give a value or an error, never a panic, an
//! overflow, a hang or a huge allocation; and every value must be self-consistent.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::from_bytes(data);
});
