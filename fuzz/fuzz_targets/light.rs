//! Fuzzes the `--light` text (`render-avatar --light`, `figure --light`): any input gives a
//! light that renders something, or an error naming `--light`, never a panic.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::light(data);
});
