//! Fuzzes the 2D keypoint reader (OpenPose, MediaPipe, plain JSON). The first byte picks the
//! options (format or guess, image size, mirrored), the rest is the file. Any input gives
//! keypoints or an error naming the file, never a panic.

#![no_main]

use std::path::Path;

use bitt_mesh::keypoints::{KeypointFormat, KeypointOptions, parse_keypoints};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&sel, file)) = data.split_first() else {
        return;
    };
    let options = KeypointOptions {
        format: match sel & 3 {
            0 => None,
            1 => Some(KeypointFormat::OpenPose),
            2 => Some(KeypointFormat::MediaPipe),
            _ => Some(KeypointFormat::Plain),
        },
        image_size: match (sel >> 2) & 3 {
            0 => [0, 0],
            1 => [640, 480],
            2 => [1, 1],
            _ => [u32::MAX, 3],
        },
        mirrored: sel & 16 != 0,
    };
    let path = Path::new("fuzz_keypoints.json");
    match parse_keypoints(file, path, &options) {
        Ok(k) => {
            let text = k.to_plain_json();
            let _ = k.scaled(0.5, 2.0).mirrored(640.0);
            // What the reader wrote, it reads back (no image bounds to check).
            let back = parse_keypoints(text.as_bytes(), path, &KeypointOptions::default());
            assert!(back.is_ok(), "{text}: {back:?}");
        }
        Err(e) => assert!(e.to_string().starts_with("fuzz_keypoints.json: "), "{e}"),
    }
});
