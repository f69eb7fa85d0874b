//! Fuzzes the 2D keypoint reader (OpenPose, MediaPipe, plain JSON). The first byte picks the
//! options (format or guess, image size, mirrored), the rest is the file. Any input gives
//! keypoints or an error naming the file, never a panic.

#![no_main]

#[path = "../checks.rs"]
mod checks;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    checks::keypoints(data);
});
