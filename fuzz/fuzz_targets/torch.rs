//! Fuzzes the torch checkpoint reader (`bitt convert-lpips` feeds it the user's `.pth`
//! files): zip archives and the legacy format must give a value or an error, never a panic,
//! a hang or a huge allocation; every tensor must be self-consistent.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::torch(data);
});
