//! Fuzzes the camera values users type: `--intrinsics` (parsed, then checked against a photo
//! size) and `render-avatar --view`. Any input gives values or an error, never a panic, and
//! accepted intrinsics always make a camera.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::camera_values(data);
});
