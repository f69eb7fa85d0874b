//! Fuzzes the InterHand2.6M dataset reader: the input is the data, camera and MANO JSON
//! files joined by NUL bytes (`data \0 camera \0 mano`; JSON never holds a raw NUL). Any
//! input gives an index or an error naming a file, never a panic; every candidate's scene
//! converts or fails with an error, and selection (whose images do not exist here) fails
//! with an error.

#![no_main]

use std::path::Path;

use bitt_mesh::interhand::{InterHandDataset, InterHandPaths, InterHandSelection};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut parts = data.splitn(3, |&b| b == 0);
    let (d, c, m) = (
        parts.next().unwrap_or(&[]),
        parts.next().unwrap_or(&[]),
        parts.next().unwrap_or(&[]),
    );
    let paths = InterHandPaths::new(Path::new("/nonexistent/bitt-fuzz"), "test");
    let set = match InterHandDataset::from_json_bytes(paths, d, c, m) {
        Ok(set) => set,
        Err(e) => {
            assert!(e.to_string().contains("InterHand2.6M_test_"), "{e}");
            return;
        }
    };
    let _ = set.counts.to_string();
    for capture in set.captures() {
        for frame in set.frames(capture) {
            for entry in set.cameras(capture, frame) {
                let _ = set.scene(entry);
            }
        }
    }
    let _ = set.select(&InterHandSelection::default());
});
